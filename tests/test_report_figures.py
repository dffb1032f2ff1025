"""The diagnosis figures and reports (bayespilot.diagnose.report, pooled.plot_runs and the
pooled report): layout and backend left to the caller, readable labels with units, no
empty or misleading panels, legends clear of the data, and the HTML tables' numbers."""

from __future__ import annotations

import dataclasses
import math
import re
import warnings
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.layout_engine import ConstrainedLayoutEngine  # noqa: E402

from bayespilot import presets  # noqa: E402
from bayespilot._labels import label, parameter_label  # noqa: E402
from bayespilot.diagnose import diagnose, diagnose_pooled, get_extension  # noqa: E402
from bayespilot.diagnose import report as R  # noqa: E402
from bayespilot.diagnose.pooled import plot_runs  # noqa: E402
from bayespilot.model import paper_model  # noqa: E402
from bayespilot.simulate import simulate  # noqa: E402


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


@pytest.fixture(scope="module")
def washout():
    """An 81.92-s FD run with a washout the base model leaves out, diagnosed without a
    bootstrap on two candidates (~10 s): washout chosen, with its profile interval and the
    describing functions; control-saturation's Delta BIC is -inf."""
    model = get_extension("motion-washout").build(paper_model())
    p = dict(presets.paper_parameters("FD"), omega_w=0.8)
    rec = simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063, seed=100).recording
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = diagnose(rec, seed=0, n_bootstrap=0, n_starts=2,
                       candidates=["motion-washout", "control-saturation"])
    assert res.physics == "motion-washout" and res.chosen.interval and "df_data" in res.arrays
    return res


@pytest.fixture(scope="module")
def pooled():
    """Two 40.96-s runs with a washout, pooled on one candidate, without a bootstrap."""
    model = get_extension("motion-washout").build(paper_model())
    p = dict(presets.paper_parameters("FD"), omega_w=0.8)
    recs = []
    for s in (200, 201):
        rec = simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063, seed=s,
                       duration=40.96).recording
        recs.append(dataclasses.replace(rec, source=f"/data/pilot3/FD_k1_run{s - 199}.csv"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return diagnose_pooled(recs, seed=0, n_bootstrap=0, n_starts=2,
                               candidates=["motion-washout"])


def _batch_dict(p: float = 1e-4):
    return {"physics": "motion-washout", "settings": {"level_per_candidate": 0.005},
            "ranking": [{"physics": "motion-washout", "p_value": p, "testable": True},
                        {"physics": "threshold-shape", "p_value": 0.5, "testable": True}]}


def _without_df(res):
    """The result as a record that is not whole forcing periods gives it: no describing
    function."""
    arrays = {k: v for k, v in res.arrays.items() if not k.startswith("df_")}
    return dataclasses.replace(res, arrays=arrays)


def _with_bootstrap(res, B: int):
    """The result with a bootstrap of B replicates: p-values k/(B+1) on the statistics."""
    where = {}
    for j, (k, e) in enumerate(res.where.items()):
        where[k] = dataclasses.replace(e, p_value=(1 + j % (B + 1)) / (B + 1))
    settings = dict(res.settings, bootstrap=dict(res.settings["bootstrap"], replicates=B))
    return dataclasses.replace(res, where=where, settings=settings)


def _fake_posterior(res):
    import arviz as az

    from bayespilot.sample import Posterior

    rng = np.random.default_rng(0)
    n = res.chosen.params["omega_w"]
    idata = az.from_dict(posterior={"omega_w": n + 0.04 * rng.standard_normal((4, 200))})
    return Posterior(idata, ("omega_w",), {"omega_w": 10.0}, True, {"likelihood": "coloured"})


def _fake_pooled_for_runs(sources):
    ranking = [SimpleNamespace(physics="motion-washout", testable=True),
               SimpleNamespace(physics="otolith-channel", testable=True)]
    runs = [{"source": s, "delta_neg_log_lik": {"motion-washout": 10.0 + j,
                                                "otolith-channel": 1.0}}
            for j, s in enumerate(sources)]
    return SimpleNamespace(ranking=ranking, runs=runs, physics="motion-washout")


# -- 1. layout: only figures made here, made with constrained layout --------------------------


def _user_figure(layout):
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 3.5), layout=layout)
    b.plot([0, 1])
    return fig, a


@pytest.mark.parametrize("layout", ["constrained", None])
def test_given_axes_keep_their_figures_layout(washout, layout):
    """On the caller's axes nothing lays out the caller's figure: a constrained figure stays
    constrained (plot_batch raised RuntimeError there: tight_layout after a colour bar), one
    without a layout engine gets none (plot_evidence and plot_candidates switched it to
    tight)."""
    calls = {
        "batch": lambda ax: R.plot_batch([("a", _batch_dict()), ("b", _batch_dict(0.3))], ax=ax),
        "evidence": lambda ax: R.plot_evidence(washout, ax=ax),
        "candidates": lambda ax: R.plot_candidates(washout, ax=ax),
        "profile": lambda ax: R.plot_profile(washout, axes=[ax]),
        "runs": lambda ax: plot_runs(_fake_pooled_for_runs(["a.csv", "b.csv"]), ax=ax),
    }
    for name, call in calls.items():
        fig, ax = _user_figure(layout)
        engine = fig.get_layout_engine()
        assert call(ax) is fig, name
        assert fig.get_layout_engine() is engine, name
        fig.canvas.draw()  # lays out without error
        plt.close(fig)


def test_given_2x2_axes_keep_their_layout(washout):
    for fn in (R.plot_frequency_response, R.plot_residuals):
        fig, axes = plt.subplots(2, 2, layout="constrained")
        assert fn(washout, axes) is fig
        assert isinstance(fig.get_layout_engine(), ConstrainedLayoutEngine)
        fig.canvas.draw()


def test_new_figures_are_constrained(washout, pooled):
    figs = [R.plot_frequency_response(washout), R.plot_residuals(washout),
            R.plot_evidence(washout), R.plot_candidates(washout), R.plot_profile(washout),
            R.plot_batch([("a", _batch_dict())]), plot_runs(pooled),
            R.plot_frequency_response(_without_df(washout))]
    for fig in figs:
        assert isinstance(fig.get_layout_engine(), ConstrainedLayoutEngine)


# -- 2. the backend is the caller's ------------------------------------------------------------


def test_report_keeps_the_callers_backend(washout):
    """With pyplot imported on another backend (Jupyter's, Qt's), drawing a diagnosis does not
    switch it to Agg: one rule for all figures, bayespilot.plots._pyplot."""
    from bayespilot import plots

    assert R._pyplot is plots._pyplot
    old = matplotlib.get_backend()
    plt.switch_backend("template")
    try:
        R.plot_candidates(washout)
        R.plot_evidence(washout)
        assert matplotlib.get_backend() == "template"
    finally:
        plt.close("all")
        plt.switch_backend(old)


# -- 3. plot_batch: no clipped label, singular, capped scale ------------------------------------


def test_batch_of_one_is_tall_enough_and_singular():
    fig = R.plot_batch([("subject01/run1", _batch_dict(1e-9))])
    assert fig.get_size_inches()[1] >= 3.5
    ax, cax = fig.axes[0], fig.axes[1]
    assert ax.get_title().startswith("1 diagnosis:")
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    box = fig.bbox
    lab = cax.yaxis.label.get_window_extent(r)
    assert lab.y0 >= box.y0 and lab.y1 <= box.y1 and lab.x1 <= box.x1  # the label whole
    # p = 1e-9 is beyond the scale's cap of 6: the colour bar says so with an arrow
    assert ax.images[0].colorbar.extend == "max"
    fig2 = R.plot_batch([("a", _batch_dict(1e-4)), ("b", _batch_dict(1e-3))])
    assert fig2.axes[0].get_title().startswith("2 diagnoses:")
    assert fig2.axes[0].images[0].colorbar.extend == "neither"


# -- 4. empty and misleading panels ---------------------------------------------------------


def test_no_describing_function_is_one_message(washout, tmp_path):
    """A record that is not whole forcing periods: one panel, one message (four empty axes
    with the message repeated before), and the report says it once, in words."""
    res = _without_df(washout)
    fig = R.plot_frequency_response(res)
    assert len(fig.axes) == 1
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert len(texts) == 1 and texts[0].startswith("No describing function")
    html = R.write_report(res, tmp_path)["html"].read_text(encoding="utf-8")
    assert html.count("No describing function") == 1
    assert 'alt="frequency_response"' not in html


def test_evidence_without_bootstrap_says_so(washout):
    fig = R.plot_evidence(washout)  # n_bootstrap=0
    ax = fig.axes[0]
    assert not ax.patches  # no empty bars
    assert any("no bootstrap p-values" in t.get_text() for t in ax.texts)


def test_evidence_lines_are_both_named_when_they_coincide(washout):
    """B = 19: the smallest possible p, 1/20, is the 0.05 line; the legend names both."""
    fig = R.plot_evidence(_with_bootstrap(washout, 19))
    ax = fig.axes[0]
    labels = [t.get_text() for t in fig.legends[0].get_texts()]  # (under the axes)
    assert "p = 0.05" in labels
    assert any(lab.startswith("smallest possible p") and "0.05" in lab for lab in labels)
    xs = sorted(line.get_xdata()[0] for line in ax.lines)
    assert xs == pytest.approx([-math.log10(0.05)] * 2)


# -- 5. labels and units ----------------------------------------------------------------------


def test_frequency_response_axes_carry_units(washout):
    fig = R.plot_frequency_response(washout)
    ylabels = [ax.get_ylabel() for ax in fig.axes]
    assert "magnitude (rad/rad)" in ylabels
    assert "magnitude (rad/(rad/s$^2$))" in ylabels
    assert ylabels.count("phase (deg)") == 2
    assert all(ax.get_xlabel() in ("", r"$\omega$ (rad/s)") for ax in fig.axes)


def test_residual_psd_is_per_rad_per_second_in_the_decision_band(washout):
    """The PSD is a density per rad/s against omega in rad/s (it integrates over omega to the
    variance), drawn to 2 omega_c with the part above omega_c shaded."""
    fig = R.plot_residuals(washout)
    ax = fig.axes[0]
    assert ax.get_xlabel() == r"$\omega$ (rad/s)"
    assert ax.get_ylabel() == "one-sided PSD (rad$^2$/(rad/s))"
    omega_c = washout.settings["noise_model"]["omega_c"]
    assert ax.get_xlim()[1] == pytest.approx(2 * omega_c)
    assert max(line.get_xdata().max() for line in ax.lines if line.get_label() == "base model"
               ) <= 2 * omega_c
    # the density's unit: the full spectrum integrates over omega to the residual's variance
    fs = 1.0 / washout.settings["dt"]
    x = washout.arrays["residual"][int(round(washout.settings["skip_seconds"] * fs)):]
    om, P = R._residual_psd(np.asarray(x, float), fs)
    assert np.sum(P) * (om[1] - om[0]) == pytest.approx(np.var(x), rel=0.05)
    # the band's edge is marked
    assert any(np.isclose(p.get_x(), omega_c) for p in ax.patches)


def test_parameter_axes_use_the_papers_notation_with_units(washout):
    model = washout.chosen.model
    want = parameter_label(model, "omega_w")
    assert "rad/s" in want
    assert R.plot_profile(washout).axes[0].get_xlabel() == want
    res = dataclasses.replace(washout, posterior=_fake_posterior(washout))
    assert R.plot_posterior(res).axes[0].get_xlabel() == want
    # a result read back from a file has no model: the catalogue entry declares the unit
    assert parameter_label(R._units_model("motion-washout"), "omega_w") == want
    # another lab's extension: the name in the paper's style, without a unit
    assert parameter_label(R._units_model("no-such-extension"), "k_x") == label("k_x")


def test_no_raw_ascii_notation_in_legends(washout):
    res = dataclasses.replace(washout, posterior=_fake_posterior(washout))
    for fig in (R.plot_profile(washout), R.plot_posterior(res)):
        texts = [t.get_text() for ax in fig.axes if ax.get_legend()
                 for t in ax.get_legend().get_texts()]
        assert texts and not any("chi2" in t or "+-" in t for t in texts)
        assert any("±1 s.e." in t for t in texts) or any(r"$\chi^2_1$" in t for t in texts)


# -- 6. legends and annotations clear of the data ----------------------------------------------


def _below(fig, ax):
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    return ax.get_legend().get_window_extent(r).y1 <= ax.get_window_extent(r).y0 + 1


def test_profile_and_posterior_legends_are_below_the_axes(washout):
    fig = R.plot_profile(washout)
    assert _below(fig, fig.axes[0])
    res = dataclasses.replace(washout, posterior=_fake_posterior(washout))
    fig = R.plot_posterior(res)
    assert _below(fig, fig.axes[0])


def test_candidates_values_are_outside_a_linear_axis(washout):
    """Each candidate's d(-ln L) and p-value in a column at the right, clear of the bars; the
    axis linear (a symlog one drew 1.06 and 3.83 close together), its ticks numbered."""
    fig = R.plot_candidates(washout)
    ax = fig.axes[0]
    assert not [t for t in ax.texts if "p =" in t.get_text()]
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    right = ax.child_axes[0]
    rows = [c for c in washout.ranking if c.testable]
    labels = [t for t in right.get_yticklabels() if "p = " in t.get_text()]
    assert len(labels) == len(rows)
    for t, c in zip(labels, rows):
        assert t.get_text().startswith(r"$\Delta$ = ")
        assert f"{c.delta_neg_log_lik:.3g}" in t.get_text() or abs(c.delta_neg_log_lik) < 1
    x1 = ax.get_window_extent(r).x1
    assert all(t.get_window_extent(r).x0 >= x1 for t in labels)
    assert max(t.get_window_extent(r).x1 for t in labels) <= fig.bbox.x1
    assert ax.get_xscale() == "linear"  # (the washout's gain is about 50)
    lo, hi = ax.get_xlim()
    assert lo <= 0 and hi >= max(c.delta_neg_log_lik for c in rows)
    shown = [t for t in ax.get_xticks() if lo <= t <= hi]
    assert len(shown) >= 4


def test_runs_are_named_by_their_files(pooled):
    fig = plot_runs(pooled)
    names = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert names == ["FD_k1_run1", "FD_k1_run2"]
    fig = plot_runs(_fake_pooled_for_runs([None, "x/a.csv", "y/a.csv"]))
    names = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert names == ["run 1", "a (run 2)", "a (run 3)"]


# -- 7. the model's describing function is where it exists --------------------------------------


def test_model_describing_functions_are_points_not_lines(washout):
    """The models' describing functions are estimates at the forcing frequencies only (the
    threshold makes the motion channel amplitude-dependent): markers, no lines between."""
    fig = R.plot_frequency_response(washout)
    for ax in fig.axes:
        for line in ax.get_lines():
            assert line.get_linestyle() == "None"


# -- 8. the HTML reports -------------------------------------------------------------------------


def test_numbers_in_the_report():
    assert R._number(-0.001, ".2f") == "0.00"
    assert R._number(-math.inf, ".1f") == "—"
    assert R._number(math.inf, ".1f") == "∞"
    assert R._number(math.nan, ".3g") == "—"
    assert R._number(None, ".3g") == "—"
    assert R._number(-1.234, ".2f") == "-1.23"


def test_single_run_report_table(washout, tmp_path):
    html = R.write_report(washout, tmp_path)["html"].read_text(encoding="utf-8")
    assert "Mismatch: <b>yes</b>" in html and "Mismatch: <b>True</b>" not in html
    html = html[:html.index("<pre>")]  # (the text summary after it is summary()'s)
    assert "-inf" not in html and "-0.00" not in html and ">nan<" not in html
    row = html[html.index("<td>control-saturation</td>"):]
    row = row[:row.index("</tr>")]
    assert "<td>—</td>" in row  # its Delta BIC does not apply
    assert '<tr style="font-weight:bold"><td>motion-washout</td>' in html
    assert html.count("<figcaption>") >= 4


def test_pooled_report_has_the_candidate_table_and_captions(pooled, tmp_path):
    html = pooled.report(tmp_path)["html"].read_text(encoding="utf-8")
    assert "<th>&Delta;BIC</th>" in html and "<td>motion-washout</td>" in html
    assert html.count("<figcaption>") >= 2
    assert f"Mismatch: <b>{'yes' if pooled.mismatch else 'no'}</b>" in html


# -- 9. figures for a paper: a page wide, legible, at the plots' resolution --------------------


def _all_new_figures(washout, pooled):
    res = dataclasses.replace(_with_bootstrap(washout, 39), posterior=_fake_posterior(washout))
    return {"frequency_response": R.plot_frequency_response(res),
            "residuals": R.plot_residuals(res), "evidence": R.plot_evidence(res),
            "candidates": R.plot_candidates(res), "profile": R.plot_profile(res),
            "posterior": R.plot_posterior(res), "runs": plot_runs(pooled),
            "batch": R.plot_batch([("a", _batch_dict(1e-9)), ("b", _batch_dict(0.3))]),
            "no describing function": R.plot_frequency_response(_without_df(res))}


def test_new_figures_are_a_page_wide_and_their_text_prints_at_7_pt(washout, pooled):
    """Printed on a 7-in column (shrunk to it when wider), no text is below 7 pt: a figure
    is at most 7.5 in wide and its smallest text rcParams' "small" (the report's were 10 in
    wide with 7-pt legends: 4.9 pt printed)."""
    from matplotlib.text import Text

    from bayespilot.plots import PAGE_WIDTH

    for name, fig in _all_new_figures(washout, pooled).items():
        width = fig.get_figwidth()
        assert width <= PAGE_WIDTH, name
        fig.canvas.draw()  # (ticks and their labels made)
        shrink = min(1.0, 7.0 / width)
        for t in fig.findobj(Text):
            if t.get_visible() and t.get_text().strip():
                assert t.get_fontsize() * shrink >= 7.0, (name, t.get_text(), t.get_fontsize())


def test_report_pngs_are_at_the_plots_resolution_and_a_page_wide(washout, tmp_path):
    from PIL import Image

    from bayespilot.cli import PLOT_DPI

    assert R.FIGURE_DPI == PLOT_DPI  # (was 110)
    res = dataclasses.replace(_with_bootstrap(washout, 19), posterior=_fake_posterior(washout))
    paths = R.write_report(res, tmp_path)
    pngs = [p for k, p in paths.items() if p.suffix == ".png"]
    assert {p.stem for p in pngs} == {"frequency_response", "residuals", "evidence",
                                      "candidates", "profile", "posterior"}
    for p in pngs:
        with Image.open(p) as im:
            assert im.info["dpi"][0] == pytest.approx(PLOT_DPI, abs=0.5), p.name
            assert im.size[0] / PLOT_DPI <= 7.5 + 1e-6, p.name


def test_report_figures_also_in_pdf_and_svg(washout, tmp_path):
    """formats= writes each figure also as PDF and SVG beside its PNG (listed, fonts TrueType
    in the PDF: journals' checks reject Type 3), the PNG still embedded in the page."""
    paths = R.write_report(washout, tmp_path, formats=("png", "pdf", "svg"))
    for name in ("residuals", "candidates", "profile"):
        assert paths[f"{name}_pdf"] == tmp_path / f"{name}.pdf" and paths[f"{name}_pdf"].is_file()
        assert paths[f"{name}_svg"].is_file() and paths[name].suffix == ".png"
    pdf = paths["candidates_pdf"].read_bytes()
    assert b"/FontFile2" in pdf and b"/Type3" not in pdf
    assert "<text" in paths["candidates_svg"].read_text(encoding="utf-8")  # text, not paths
    assert {p for p in tmp_path.iterdir()} == set(paths.values())  # the list is what is there
    with pytest.raises(ValueError, match="formats"):
        R.write_report(washout, tmp_path, formats=("png", "jpeg"))
    # the result's own report() passes them on (the PNG always, for the page)
    paths = washout.report(tmp_path / "own", formats=("pdf",))
    assert paths["residuals_pdf"].is_file() and paths["residuals"].suffix == ".png"
    assert "residuals_svg" not in paths
    # a report written again without them leaves no PDF of the earlier one behind (a stale
    # vector copy would be taken for this report's)
    again = washout.report(tmp_path / "own")
    assert set((tmp_path / "own").iterdir()) == set(again.values())
    assert not list((tmp_path / "own").glob("*.pdf"))
    with pytest.raises(ValueError, match="formats must be"):
        R.write_report(washout, tmp_path, formats=None)


# -- 10. empty figures are left out --------------------------------------------------------------


def test_empty_figures_are_neither_written_nor_listed_nor_shown(washout, tmp_path):
    """Without a bootstrap the evidence figure is an empty chart, without a describing
    function the frequency-response one a sentence: neither is written (one an earlier
    report wrote is removed), listed or embedded; the page says why in words."""
    res = _without_df(washout)  # (and n_bootstrap=0)
    # an earlier report, with both figures (a file of the user's of that name is left:
    # test_report_files)
    R.write_report(_with_bootstrap(washout, 19), tmp_path)
    assert (tmp_path / "evidence.png").is_file()
    paths = R.write_report(res, tmp_path)
    assert "evidence" not in paths and "frequency_response" not in paths
    assert not (tmp_path / "evidence.png").exists()
    assert not (tmp_path / "frequency_response.png").exists()
    assert {p for p in tmp_path.iterdir()} == set(paths.values())
    html = paths["html"].read_text(encoding="utf-8")
    alts = set(re.findall(r'<img alt="([^"]+)"', html))
    assert alts == {"residuals", "candidates", "profile"} and alts <= set(paths)
    assert "evidence.png" not in html and "frequency_response.png" not in html
    assert "No bootstrap p-values" in html and "no figure of them" in html
    assert html.count("No describing function") == 1
    # with p-values the evidence figure is there
    paths = R.write_report(_with_bootstrap(washout, 19), tmp_path)
    assert paths["evidence"].is_file()
    assert 'alt="evidence"' in paths["html"].read_text(encoding="utf-8")


# -- 11. words, not code; told apart without colour -------------------------------------------


def test_evidence_ticks_are_words_from_one_table(washout):
    fig = R.plot_evidence(_with_bootstrap(washout, 19))
    ticks = [t.get_text() for t in fig.axes[0].get_yticklabels()]
    keys = [k for k, e in washout.where.items() if math.isfinite(e.value)]
    assert set(washout.where) <= set(R.EVIDENCE_LABELS)  # every built-in statistic named
    assert ticks == [R.EVIDENCE_LABELS[k] for k in keys]
    assert R.EVIDENCE_LABELS["frequency.motion_low"] == r"motion response, $\omega < 2$ rad/s"
    for t in ticks:
        plain = re.sub(r"\$[^$]*\$", "", t)  # (outside mathtext)
        assert "_" not in plain and not re.search(r"[a-z]\.[a-z]", plain), t
    assert R._evidence_label("lab.my_statistic") == "lab: my statistic"


def test_greyscale_before_and_after_differ_by_line_style(washout):
    fig = R.plot_residuals(washout)
    after = f"with {washout.physics}"
    for ax in fig.axes:
        styles = {line.get_label(): line.get_linestyle() for line in ax.lines}
        if "base model" in styles and after in styles:
            assert styles["base model"] != styles[after], ax.get_title()
    legend = {t.get_text(): h for t, h in zip(fig.legends[0].get_texts(),
                                              fig.legends[0].legend_handles)}
    assert legend["base model"].get_linestyle() != legend[after].get_linestyle()


def test_greyscale_marked_bars_are_hatched(washout, pooled):
    res = _with_bootstrap(washout, 19)
    ax = R.plot_evidence(res).axes[0]
    keys = [k for k, e in res.where.items() if math.isfinite(e.value)]
    for bar, k in zip(ax.patches, keys):
        assert bool(bar.get_hatch()) == (res.where[k].p_value <= 0.05), k
    ax = R.plot_candidates(washout).axes[0]
    rows = [c for c in washout.ranking if c.testable]
    for bar, c in zip(ax.patches, rows):
        assert bool(bar.get_hatch()) == c.justified, c.physics
    ax = plot_runs(pooled).axes[0]
    hatches = [h.get_hatch() or "" for h in ax.get_legend().legend_handles]
    assert len(set(hatches)) == len(pooled.runs)  # each run its own hatching


def test_log_axes_label_intermediate_ticks(washout):
    """The magnitude and frequency axes span about one decade: numbered at 1, 2, 5 times a
    power of ten as plain numbers (matplotlib numbered only 10^0 and 10^1)."""
    fig = R.plot_frequency_response(washout)
    fig.canvas.draw()
    for ax in fig.axes[:2]:
        lo, hi = ax.get_ylim()
        shown = [t.get_text() for t in ax.get_yticklabels()
                 if lo <= t.get_position()[1] <= hi and t.get_text()]
        assert len(shown) >= 3 and "$" not in "".join(shown), shown
    ax = fig.axes[2]
    lo, hi = ax.get_xlim()
    shown = [t.get_text() for t in ax.get_xticklabels()
             if lo <= t.get_position()[0] <= hi and t.get_text()]
    assert {"1", "2", "5", "10"} <= set(shown), shown


def test_residual_labels_say_what_and_carry_their_power_of_ten(washout):
    fig = R.plot_residuals(washout)
    fig.canvas.draw()
    var = fig.axes[1]
    assert re.fullmatch(r"residual variance \(\$10\^\{-\d+\}\$ rad\$\^2\$\)", var.get_ylabel())
    assert var.yaxis.get_offset_text().get_text() == ""  # no floating "1e-4"
    assert max(max(line.get_ydata()) for line in var.lines) > 0.5  # in those units
    assert r"sign($i(t - \tau_\mathrm{m})$)" in fig.axes[2].get_ylabel()
    assert "sign($u$)" in fig.axes[3].get_ylabel()
    ax = R.plot_profile(washout).axes[0]
    assert ax.get_ylabel().startswith("scaled deviance $c")
    assert ax.get_title().startswith("$c$ = ") and "s.e." in ax.get_title()


def test_p_values_are_readable():
    assert R._p_text(3.4e-9) == r"$3.4\times10^{-9}$"
    assert R._p_text(0.073) == "0.073" and R._p_text(0.0) == r"$<10^{-300}$"
    assert R._p_html(3.4e-9) == "3.4&times;10<sup>-9</sup>" and R._p_html(0.5) == "0.5"
    assert R._p_html(math.nan) == "—"
    fig = R.plot_batch([("a", _batch_dict(1e-9))])
    assert "$p < 10^{-6}$" in fig.axes[1].get_ylabel()


def test_standard_error_is_hatched_under_the_posterior(washout):
    """The fit's ±1 s.e. is an unfilled hatched span at the bottom: a filled one blended with
    an interval's shading into a colour no legend entry had."""
    res = dataclasses.replace(washout, posterior=_fake_posterior(washout))
    ax = R.plot_posterior(res).axes[0]
    se = [p for p in ax.patches if p.get_label() == "±1 s.e."]
    assert len(se) == 1 and se[0].get_hatch() and not se[0].get_fill()
    assert se[0].get_zorder() == 0
    ax = R.plot_profile(washout).axes[0]
    span = [p for p in ax.patches if "interval" in p.get_label()]
    assert span and span[0].get_zorder() == 0


#: How the decision names a one-parameter test's reference (decide.lr_verdict).
_CHIBAR = "GLS likelihood-ratio test, 0.5 chi2(0) + 0.5 chi2(1) (boundary null)"


def _unregistered_file(tmp_path, level: float, entries: dict[str, tuple[str, bool | None]]):
    """The diagnosis a result file of another session holds, read back here: a
    one-parameter test of each of ``entries`` (name: (reason, boundary_null; None: a file of
    before the field)), entries of one's own not registered here."""
    import json

    from bayespilot.diagnose import DiagnosisResult
    from bayespilot.diagnose.decide import CandidateResult

    ranking = []
    for name in entries:
        with pytest.raises(ValueError):
            get_extension(name)  # not registered
        ranking.append(CandidateResult(name, True, "", 2.0, 4.0, 1, 0.03, 4.0 - math.log(4000),
                                       2.0 - 0.5 * math.log(4000), {"T_vis": 0.1},
                                       {"T_vis": 0.02}, {"T_vis": 0.1}))
    d = DiagnosisResult(False, "none", ranking, {},
                        {"params": {}, "neg_log_lik": -1.0, "vaf": 80.0}, None,
                        {"alpha": 0.01, "level_per_candidate": level, "n_tested": len(entries),
                         "skip_seconds": 5.0}, 1.0, "run.csv").to_dict()
    for c in d["ranking"]:
        c["reason"], boundary = entries[c["physics"]]
        c.pop("boundary_null", None)
        if boundary is not None:
            c["boundary_null"] = boundary
    path = tmp_path / "other_session.json"
    path.write_text(json.dumps(d))
    return DiagnosisResult.from_json(path)


def _marks(res):
    fig = R.plot_candidates(res)
    return [line.get_xdata()[0] for line in fig.axes[0].lines]


def test_candidates_mark_of_an_unregistered_entry_follows_its_files_boundary_null(tmp_path):
    """The black mark of an entry not registered where its result file is read sits at its own
    test's threshold (chi-bar-squared for a boundary null) as the file records it
    (``boundary_null``), however its ``reason`` is worded (the text used to decide it;
    audit_structure.md 7.8); written again, the file keeps it."""
    from scipy import stats

    from bayespilot.diagnose import DiagnosisResult

    level = 0.005
    edge, inner = 0.5 * stats.chi2.isf(2 * level, 1), 0.5 * stats.chi2.isf(level, 1)
    for entries in ({"my-edge": (_CHIBAR, True), "my-inner": ("GLS likelihood-ratio test, "
                                                              "chi2(1)", False)},
                    {"my-edge": ("likelihood-ratio test against the mixture at the edge", True),
                     "my-inner": ("likelihood-ratio test, chi2(1): not a boundary null", False)}):
        res = _unregistered_file(tmp_path, level, entries)
        assert [c.boundary_null for c in res.ranking] == [True, False]
        assert _marks(res) == pytest.approx([edge, inner], rel=1e-12)
        res.to_json(tmp_path / "again.json")
        again = DiagnosisResult.from_json(tmp_path / "again.json")
        assert [c["boundary_null"] for c in again.to_dict()["ranking"]] == [True, False]
        assert _marks(again) == pytest.approx([edge, inner], rel=1e-12)


def test_candidates_mark_of_a_file_written_before_boundary_null(tmp_path):
    """A result file of before the field: the boundary null is read from how the test was
    made, as the decision worded it."""
    from scipy import stats

    level = 0.005
    res = _unregistered_file(tmp_path, level, {"my-edge": (_CHIBAR, None),
                                               "my-inner": ("GLS likelihood-ratio test, chi2(1)",
                                                            None)})
    assert [c.boundary_null for c in res.ranking] == [True, False]
    assert _marks(res) == pytest.approx([0.5 * stats.chi2.isf(2 * level, 1),
                                         0.5 * stats.chi2.isf(level, 1)], rel=1e-12)
    # an old reason that says "not a boundary null" is not read as one (the words are not
    # the reference the test names)
    res = _unregistered_file(tmp_path, level, {"my-inner": (
        "likelihood-ratio test, chi2(1): not a boundary null", None)})
    assert [c.boundary_null for c in res.ranking] == [False]
    assert _marks(res) == pytest.approx([0.5 * stats.chi2.isf(level, 1)], rel=1e-12)


def test_candidates_mark_follows_a_recorded_boundary_null_over_the_catalogue(tmp_path):
    """A file's recorded boundary_null, False as well as True, decides the mark even for an
    entry registered here whose catalogue says otherwise (a file of another release or of a
    session with another definition); a result built by hand (None) asks the catalogue."""
    from bayespilot.diagnose.decide import CandidateResult

    assert get_extension("motion-washout").boundary_null
    c = CandidateResult("motion-washout", True, "GLS likelihood-ratio test, chi2(1)", 2.0,
                        4.0, 1, 0.03, 1.0, 0.5, {"omega_w": 0.3}, {"omega_w": 0.1},
                        {"omega_w": 0.3}, boundary_null=False)
    assert R._boundary_null(c) is False
    c.boundary_null = None
    assert R._boundary_null(c) is True


def test_report_neg_log_lik_of_a_perfect_fit_is_the_likelihoods_floored_value(monkeypatch):
    """The report's before/after -ln L (Eq. 4) of the chosen extension uses the likelihood's
    variance floor: a perfect fit gives its finite floored value (the inline formula failed
    on it: ln 0; audit_structure.md 7.10)."""
    from bayespilot.diagnose import locate as L
    from bayespilot.kernels._response import neg_log_lik_from_sse
    from bayespilot.likelihood import Likelihood

    model = get_extension("motion-washout").build(paper_model())
    p = dict(presets.paper_parameters("FD"), omega_w=0.8)
    rec = simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063, seed=22,
                   duration=40.96).recording
    steady = L.steady_response

    def perfect(m, recording, params):  # the extended model's response: the recording's u
        return recording.u.copy() if "omega_w" in params else steady(m, recording, params)

    monkeypatch.setattr(L, "steady_response", perfect)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = diagnose(rec, seed=0, n_bootstrap=0, n_starts=2, n_calibrate=0,
                       candidates=["motion-washout"])
    assert not [w for w in caught if "divide by zero" in str(w.message)]
    assert res.physics == "motion-washout"
    n = rec.u.size - int(round(res.settings["skip_seconds"] * rec.sample_rate_hz))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # (NotWholePeriodsWarning: the floor is all it gives)
        floor = Likelihood(paper_model(), rec).s2_floor
    want, floored = neg_log_lik_from_sse(0.0, n, floor)
    after, before = res.arrays["after_eq4_neg_log_lik"], res.arrays["before_eq4_neg_log_lik"]
    assert floored and math.isfinite(after) and after == want
    assert math.isfinite(before) and before > after
    assert res.to_dict()["chosen"]["neg_log_lik_after"] == want


# -- 9. for a paper: titles optional, column-width axes, figsize (audit_figures R1/R3/R6/R7) ----


def _titles(fig):
    """Every title text of ``fig``: its suptitle and each axes' three titles (non-empty)."""
    found = [fig._suptitle.get_text()] if fig._suptitle is not None else []
    found += [ax.get_title(loc) for ax in fig.axes for loc in ("center", "left", "right")]
    return [t for t in found if t]


def _shared():
    from bayespilot.diagnose.posterior import SharedPosterior

    grid = np.linspace(0.5, 1.1, 31)
    log_density = -0.5 * ((grid - 0.8) / 0.08) ** 2
    dens = np.exp(log_density) / (np.exp(log_density).sum() * (grid[1] - grid[0]))
    marg = {"median": 0.8, "mean": 0.8, "sd": 0.08, "interval": [0.67, 0.93], "mode": 0.8,
            "density": dens.tolist()}
    return SharedPosterior("motion-washout", ("omega_w",), [grid], log_density,
                           {"omega_w": marg}, {"omega_w": 0.8}, {"omega_w": 0.08}, 0.0,
                           {"method": "Laplace", "points": 31, "n_runs": 2}, 1.0, 2.0)


def _title_calls(washout):
    res = dataclasses.replace(_with_bootstrap(washout, 39), posterior=_fake_posterior(washout))
    batch = [("a", _batch_dict(1e-4)), ("b", _batch_dict(0.3))]
    # name -> (draw with title=..., today's title, whether the panels keep their headings)
    return {
        "frequency_response": (lambda t: R.plot_frequency_response(res, title=t),
                               "Describing functions at the forcing frequencies", True),
        "residuals": (lambda t: R.plot_residuals(res, title=t), None, True),
        "evidence": (lambda t: R.plot_evidence(res, title=t),
                     "Where the data and the base model differ", False),
        "candidates": (lambda t: R.plot_candidates(res, title=t),
                       "Candidates (decision: motion-washout)", False),
        "batch": (lambda t: R.plot_batch(batch, title=t), "2 diagnoses: every candidate's", False),
        "profile": (lambda t: R.plot_profile(res, title=t),
                    "motion-washout: profile likelihood of its new parameters", False),
        "posterior": (lambda t: R.plot_posterior(res, title=t),
                      "motion-washout: posterior of its new parameters", False),
        "shared_posterior": (lambda t: R.plot_shared_posterior(_shared(), title=t),
                             "motion-washout: posterior of the parameters shared by 2 runs",
                             False),
    }


def test_every_report_plot_takes_title_true_false_or_a_text(washout):
    """R1: title=True draws today's title, False none (the panels' headings of the 2 x 2
    figures stay: they name the panels), a str that text; anything else is refused."""
    for name, (draw, today, headings) in _title_calls(washout).items():
        default = _titles(draw(True))
        if today is not None:
            assert any(t.replace("\n", " ").startswith(today) for t in default), (name, default)
        fig = draw(False)
        none = _titles(fig)
        if headings:  # only the panels' headings, as with True less the figure's title
            assert fig._suptitle is None or not fig._suptitle.get_text(), name
            assert none == [t for t in default if t != today], name
        else:
            assert none == [], (name, none)
        mine = _titles(draw("Fig. 3"))
        assert "Fig. 3" in mine, (name, mine)
        assert today is None or not any(today in t for t in mine), name
        plt.close("all")
    with pytest.raises(TypeError, match="title must be"):
        R.plot_evidence(washout, title=1)


def test_without_titles_the_axes_take_their_room(washout):
    """R1: title=False gives the title's room to the axes (constrained layout), and a panel's
    note (the profile's scale c) moves into its legend's title, not lost."""
    res = _with_bootstrap(washout, 39)
    for draw in (lambda t: R.plot_evidence(res, title=t),
                 lambda t: R.plot_candidates(res, title=t),
                 lambda t: R.plot_profile(res, title=t)):
        tops = []
        for t in (True, False):
            fig = draw(t)
            fig.canvas.draw()
            tops.append(fig.axes[0].get_window_extent().y1 / fig.dpi)
        assert tops[1] > tops[0] + 0.1, tops  # (in: at least a line of 10-pt text)
    fig = R.plot_profile(res, title=False)
    c = washout.chosen.interval["omega_w"].scale
    assert fig.axes[0].get_legend().get_title().get_text().startswith(f"$c$ = {c:.2g}")


def _inside(box, fig, tol=1.0):
    f = fig.bbox
    return (box.x0 >= f.x0 - tol and box.x1 <= f.x1 + tol and box.y0 >= f.y0 - tol
            and box.y1 <= f.y1 + tol)


def _column_axes(w, h):
    fig = plt.figure(figsize=(w, h), layout="constrained")
    return fig, fig.add_subplot()


def test_evidence_on_column_wide_axes_keeps_axes_and_legend_inside(washout):
    """R3: on the caller's 3.5 x 3.0-in axes the legend went beside them and constrained
    layout collapsed the axes ("axes sizes collapsed to zero"): now it is under the x label,
    inside the figure, the axes at least 1 in each way; legend=False draws none."""
    res = _with_bootstrap(washout, 39)
    fig, ax = _column_axes(3.5, 3.0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        R.plot_evidence(res, ax=ax)
        fig.canvas.draw()
    leg = ax.get_legend().get_window_extent()
    assert _inside(leg, fig)
    assert _inside(ax.get_tightbbox(), fig)  # names, x label, title whole
    a = ax.get_window_extent()
    assert a.width / fig.dpi >= 1.0 and a.height / fig.dpi >= 1.0, a
    assert leg.y1 <= a.y0  # under the axes
    assert leg.y1 <= ax.xaxis.label.get_window_extent().y0 + 1  # and under the x label
    assert not [w for w in caught if "collapsed" in str(w.message)]
    fig, ax = _column_axes(3.5, 3.0)
    R.plot_evidence(res, ax=ax, legend=False)
    assert ax.get_legend() is None and not fig.legends


def test_candidates_caption_is_wrapped_to_column_wide_axes(washout):
    """R3: on the caller's 3.5 x 2.6-in axes the two-line caption was cut on both sides: now
    wrapped to the width under the axes and their labels, inside the figure; caption=False
    leaves the formula only."""
    fig, ax = _column_axes(3.5, 2.6)
    R.plot_candidates(washout, ax=ax)
    fig.canvas.draw()
    lab = ax.xaxis.label
    assert _inside(lab.get_window_extent(), fig)
    assert _inside(ax.get_tightbbox(), fig)  # and the title, the names, the p-values
    assert "black mark" in lab.get_text() and lab.get_text().count("\n") >= 2
    assert ax.get_window_extent().width / fig.dpi >= 0.5
    fig, ax = _column_axes(3.5, 2.6)
    R.plot_candidates(washout, ax=ax, caption=False)
    text = ax.get_xlabel()
    assert "black mark" not in text and "justified" not in text and r"\Delta(-\ln L)" in text
    # at a page's width the caption is its two lines, as before
    ax = R.plot_candidates(washout).axes[0]
    assert ax.get_xlabel().count("\n") == 1


def test_report_figures_take_a_figsize(washout):
    """R2/R3: figsize= sizes a new figure as given (a column's 3.5 in; the 2 x 2 figures a
    7-in page's), everything inside it; with the caller's axes it is refused."""
    res = dataclasses.replace(_with_bootstrap(washout, 39), posterior=_fake_posterior(washout))
    calls = {"frequency_response": (R.plot_frequency_response, (7.0, 5.0)),
             "residuals": (R.plot_residuals, (7.0, 6.0)), "evidence": (R.plot_evidence, (3.5, 4.0)),
             "candidates": (R.plot_candidates, (3.5, 2.6)), "profile": (R.plot_profile, (3.5, 3.2)),
             "posterior": (R.plot_posterior, (3.5, 3.2))}
    for name, (fn, size) in calls.items():
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # (no collapsed layout)
            fig = fn(res, figsize=size)
            fig.canvas.draw()
        assert tuple(fig.get_size_inches()) == pytest.approx(size), name
        for lg in fig.legends + [a.get_legend() for a in fig.axes if a.get_legend()]:
            assert _inside(lg.get_window_extent(), fig), name
        assert _inside(fig.axes[0].get_tightbbox(), fig), name
        plt.close(fig)
    fig = R.plot_batch([("a", _batch_dict())], figsize=(3.5, 3.0))
    assert tuple(fig.get_size_inches()) == pytest.approx((3.5, 3.0))
    assert tuple(R.plot_shared_posterior(_shared(), figsize=(3.5, 3.0)).get_size_inches()
                 ) == pytest.approx((3.5, 3.0))
    fig, ax = plt.subplots()
    with pytest.raises(ValueError, match="figsize"):
        R.plot_candidates(res, ax=ax, figsize=(3.5, 2.6))


def test_figures_of_a_result_read_from_json_say_it_keeps_no_signals(washout, tmp_path):
    """R6: a diagnosis read back from its JSON has no signals; the frequency-response panel
    said "the recording's forcing functions are unknown" (they were known), the residual
    figure raised KeyError and the posterior AttributeError.  Each now says the file keeps
    no signals and what to do; the figures of numbers the file keeps still draw."""
    from bayespilot.diagnose import DiagnosisResult

    path = tmp_path / "diagnosis.json"
    washout.to_json(path)
    back = DiagnosisResult.from_json(path)
    fig = R.plot_frequency_response(back)
    (msg,) = [t.get_text() for t in fig.axes[0].texts]
    assert "unknown" not in msg
    assert "read from JSON" in msg and str(path) in msg and "keeps no signals" in msg
    assert "re-run diagnose" in msg
    with pytest.raises(ValueError, match="read from JSON .*keeps no signals: re-run diagnose"):
        R.plot_residuals(back)
    with pytest.raises(ValueError, match="read from JSON .*re-run diagnose"):
        R.plot_posterior(back)
    R.plot_candidates(back), R.plot_profile(back), R.plot_evidence(back)  # (numbers: drawn)
    # a result that has its signals but no whole periods keeps its own reason
    assert "read from JSON" not in R._no_describing_function(_without_df(washout))


def test_residual_band_label_has_an_upright_subscript(washout):
    """R7: the decision band's omega_c as _labels writes a subscript (upright), not $\\omega_c$."""
    from bayespilot._labels import symbol

    fig = R.plot_residuals(washout)
    band = [t.get_text() for t in fig.legends[0].get_texts() if t.get_text().startswith("above")]
    assert band and band[0].startswith(f"above {symbol('omega_c')} = ")
    assert r"\omega_c" not in band[0]


def test_batch_chosen_box_is_seen_on_a_dark_cell():
    """T8: the chosen extension's black box had no contrast on viridis' dark cells (a large
    p); a white edge inside it now: the pixels just inside the black line are white."""
    fig = R.plot_batch([("a", _batch_dict(0.3))])  # chosen washout, p = 0.3: a dark cell
    fig.canvas.draw()
    ax = fig.axes[0]
    (box,) = [p for p in ax.patches if not p.get_fill()]
    e = box.get_window_extent()
    rgba = np.asarray(fig.canvas.buffer_rgba())
    height = rgba.shape[0]
    # 2 px inside the left and top black lines (2 pt wide at 100 dpi: 1.4 px each side)
    inside = [(int(round(e.x0 + 2.2)), int(round((e.y0 + e.y1) / 2))),
              (int(round((e.x0 + e.x1) / 2)), int(round(e.y1 - 2.2)))]
    centre = (int(round((e.x0 + e.x1) / 2)), int(round((e.y0 + e.y1) / 2)))
    assert rgba[height - centre[1], centre[0], :3].max() < 120  # the cell is dark
    for x, y in inside:
        assert rgba[height - y, x, :3].min() > 200, rgba[height - y, x]  # white


def test_batch_figure_stops_growing_at_a_page_and_its_names_do_not_overlap():
    """T8: 0.28 in per diagnosis without a cap made 60 diagnoses 18.7 in tall; now at most a
    page (9.5 in), every k-th row named where rows are narrower than a name."""
    from bayespilot.plots import PAGE_HEIGHT

    fig = R.plot_batch([(f"s{i:02d}/run1", _batch_dict(10.0 ** -(i % 7))) for i in range(60)])
    assert fig.get_figheight() <= PAGE_HEIGHT
    fig.canvas.draw()
    ax = fig.axes[0]
    boxes = sorted((t.get_window_extent() for t in ax.get_yticklabels() if t.get_text()),
                   key=lambda b: b.y0)
    assert len(boxes) >= 20  # (still most names)
    assert all(a.y1 <= b.y0 + 0.5 for a, b in zip(boxes, boxes[1:]))  # no overlap
    assert _inside(ax.get_tightbbox(), fig)
    # a short batch keeps a row per name
    fig = R.plot_batch([("a", _batch_dict()), ("b", _batch_dict(0.3))])
    assert [t.get_text() for t in fig.axes[0].get_yticklabels()] == [
        "a: motion-washout", "b: motion-washout"]


def test_report_figures_can_be_written_without_titles(washout, tmp_path, monkeypatch):
    """R1: write_report(title=False) (for ``diagnose --report --no-title``) saves every
    figure without its title; the default keeps them (the HTML report's figures)."""
    seen = {}
    save = R._png

    def spy(fig, path, formats=("png",)):
        seen[path.stem] = _titles(fig)
        return save(fig, path, formats)

    monkeypatch.setattr(R, "_png", spy)
    res = dataclasses.replace(_with_bootstrap(washout, 19), posterior=_fake_posterior(washout))
    R.write_report(res, tmp_path / "titled")
    assert "Where the data and the base model differ" in seen["evidence"]
    assert any(t.startswith("Candidates (decision") for t in seen["candidates"])
    seen.clear()
    R.write_report(res, tmp_path / "plain", title=False)
    assert set(seen) == {"frequency_response", "residuals", "evidence", "candidates", "profile",
                         "posterior"}
    for name in ("evidence", "candidates", "profile", "posterior"):
        assert seen[name] == [], (name, seen[name])
    headings = {"frequency_response": 2, "residuals": 4}  # the panels' own headings stay
    for name, k in headings.items():
        assert len(seen[name]) == k, (name, seen[name])
    with pytest.raises(TypeError, match="title must be True or False"):
        R.write_report(res, tmp_path / "x", title="Fig. 1")

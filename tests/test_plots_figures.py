"""Figures of bayespilot.plots as they reach a paper: notation, legends that leave the data
visible, honest histogram statistics, titles, output formats and printable sizes.

Every posterior here is synthetic (a few hundred draws built directly), so the module
runs in seconds; geometry is checked in display coordinates after a draw.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402
from matplotlib.text import Text  # noqa: E402

from bayespilot import presets  # noqa: E402
from bayespilot._labels import label, symbol  # noqa: E402
from bayespilot.cli import main  # noqa: E402
from bayespilot.plots import (plot_chains, plot_marginal, plot_pair,  # noqa: E402
                              plot_threshold_histograms, plot_traces)

PAPER = presets.PARAMETER_NAMES
TRUTH = presets.paper_parameters("FD")


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _posterior(names=PAPER, *, n_walkers=10, n_draws=60, centre=None, truth=None, seed=0,
               spread=0.08, model="Pool et al. (2012)", likelihood="eq4"):
    """A Posterior of Gaussian draws around ``centre`` (default Table 3 FD; relative standard
    deviation ``spread``), kept as sample keeps it (``model``: the sampled model's name)."""
    import arviz as az

    from bayespilot.sample import _META_ATTR, Posterior

    rng = np.random.default_rng(seed)
    centre = dict(TRUTH, **(centre or {}))
    post = {n: centre.get(n, 0.1) * (1.0 + spread * rng.standard_normal((n_walkers, n_draws)))
            for n in names}
    lp = rng.normal(7740.0, 2.0, (n_walkers, n_draws))
    idata = az.from_dict(posterior=post, sample_stats={"lp": lp})
    settings = {"likelihood": likelihood, "discard": 150, "thin": 7, "n_steps": 600,
                "model": model, "true_parameters": truth}
    tau = {n: 40.0 + i for i, n in enumerate(names)}
    meta = {"parameter_names": list(names), "tau": tau, "converged": False,
            "settings": settings, "seed": seed}
    idata.posterior.attrs[_META_ATTR] = json.dumps(meta)
    return Posterior(idata, tuple(names), tau, False, settings, seed)


def _results(d, *, task="FD", fn=0.2, k=1.0, method="fast", true=0.0075):
    return [{"task": task, "remnant_fraction": fn, "motion_gain": k, "threshold": True,
             "method": method, "true_params": {"delta_abs": true},
             "fit": {"params": {"delta_abs": float(x)}, "neg_log_lik": -1.0}} for x in d]


def _texts(fig):
    """Every visible, non-empty text of a drawn figure."""
    return [t for t in fig.findobj(Text) if t.get_visible() and t.get_text().strip()]


def _without_math(s: str) -> str:
    return re.sub(r"\$[^$]*\$", "", s)


def _line_points(line, per_segment=40):
    """A line's vertices in display coordinates, densified (axvline has only its two ends)."""
    xy = line.get_transform().transform(np.asarray(line.get_xydata(), float))
    if len(xy) < 2:
        return xy
    t = np.linspace(0.0, 1.0, per_segment)[:, None]
    return np.concatenate([a + t * (b - a) for a, b in zip(xy[:-1], xy[1:])])


def _inside(bbox, xy, shrink=1.0):
    x0, x1, y0, y1 = bbox.x0 + shrink, bbox.x1 - shrink, bbox.y0 + shrink, bbox.y1 - shrink
    return (xy[:, 0] > x0) & (xy[:, 0] < x1) & (xy[:, 1] > y0) & (xy[:, 1] < y1)


def _bars(ax):
    """The histogram's bars (opaque rectangles; the shaded spans are translucent)."""
    return [p for p in ax.patches if isinstance(p, Rectangle) and p.get_height() > 0
            and p.get_width() > 0 and p.get_facecolor()[3] > 0.5]


# --- 1. notation ---------------------------------------------------------------------------------
def test_posterior_plots_use_the_paper_notation_with_units():
    post = _posterior(truth={"delta_abs": 0.0075, "tau_m": 0.186, "K_m": 0.425})
    fig = plot_marginal(post, "delta_abs", truth=0.0075)
    assert fig.axes[0].get_xlabel() == r"$\delta_\mathrm{abs}$ (IPUT)"
    assert r"$\delta_\mathrm{abs}$" in fig.axes[0].get_title()

    fig = plot_pair(post, truth=post.truth)
    xl = [a.get_xlabel() for a in fig.axes if a.get_xlabel()]
    assert xl == [label("K_m", "rad/IPUT"), label("tau_m", "s"), label("delta_abs", "IPUT")]
    assert label("tau_m", "s") in [a.get_ylabel() for a in fig.axes]

    fig = plot_chains(post)
    ylabels = [a.get_ylabel() for a in fig.axes]
    assert ylabels[:-1] == [label(n, presets.PARAMETER_UNITS[n]) for n in PAPER]
    assert r"$\omega_\mathrm{nm}$ (rad/s)" in ylabels

    for f in (plot_marginal(post), plot_pair(post), plot_chains(post)):
        f.canvas.draw()
        raw = [t.get_text() for t in _texts(f) if "_" in _without_math(t.get_text())]
        assert not raw, raw


def test_a_model_gives_the_units_of_another_labs_parameters():
    from bayespilot.model import Parameter, Washout, paper_model

    model = paper_model().add_stage("vestibular", Washout("omega_w"),
                                    [Parameter("omega_w", 0.01, 10.0, 1.0, "rad/s")])
    post = _posterior((*PAPER, "omega_w"), centre={"omega_w": 0.8})
    assert plot_marginal(post, "omega_w", model=model).axes[0].get_xlabel() == \
        r"$\omega_\mathrm{w}$ (rad/s)"
    # without the model the name still reads in the notation (no unit is known)
    assert plot_marginal(post, "omega_w").axes[0].get_xlabel() == r"$\omega_\mathrm{w}$"
    assert plot_chains(post, names=("omega_w",), model=model).axes[0].get_ylabel() == \
        r"$\omega_\mathrm{w}$ (rad/s)"


def test_traces_and_histograms_use_the_same_notation():
    from bayespilot.simulate import simulate

    sim = simulate(task="FD", motion_gain=1.0, seed=1, duration=5.0)
    fig = plot_traces(sim)
    fig.canvas.draw()
    text = " ".join(t.get_text() for t in _texts(fig))
    assert symbol("delta_abs") in text and r"\delta_{abs}" not in text
    assert r"$\ddot\theta_\mathrm{m}$" in fig.axes[2].get_ylabel()

    fig = plot_threshold_histograms(_results([0.006, 0.008, 0.02]))
    assert fig.axes[0].get_xlabel() == label("delta_abs", "IPUT")
    assert symbol("F_n") in fig.axes[0].get_ylabel()


# --- 2. legends off the data ---------------------------------------------------------------------
def test_traces_canal_legend_leaves_the_canal_output_visible():
    from bayespilot.simulate import simulate

    sim = simulate(task="FT", motion_gain=0.5, remnant_fraction=0.0, seed=2, duration=5.0)
    fig = plot_traces(sim)
    fig.canvas.draw()
    canal_ax = fig.axes[3]
    leg = canal_ax.get_legend()
    assert leg is not None
    box = leg.get_window_extent()
    for line in canal_ax.get_lines():
        assert not _inside(box, _line_points(line)).any(), "legend covers the canal output"


def test_marginal_legend_does_not_hide_the_truth_or_the_histogram():
    # draws well left of the truth: the upper-right corner is where the truth line runs
    # (the audit's eq4 run on 20 s: draws 0-0.0055, truth 0.0075)
    post = _posterior(centre={"delta_abs": 0.0025}, spread=0.3)
    fig = plot_marginal(post, "delta_abs", truth=0.0075)
    fig.canvas.draw()
    ax = fig.axes[0]
    legends = [lg for lg in (ax.get_legend(), *fig.legends) if lg is not None]
    assert legends
    for lg in legends:
        box = lg.get_window_extent()
        for line in ax.get_lines():
            assert not _inside(box, _line_points(line)).any(), f"legend covers {line.get_label()}"
        for bar in _bars(ax):
            assert not box.overlaps(bar.get_window_extent()), "legend covers the histogram"


def test_marginal_on_given_axes_keeps_the_legend_inside_them():
    post = _posterior(centre={"delta_abs": 0.0025})
    fig, ax = plt.subplots()
    assert plot_marginal(post, truth=0.0075, ax=ax) is fig
    assert ax.get_legend() is not None and not fig.legends


def test_histogram_statistics_leave_the_bar_tops_visible():
    rng = np.random.default_rng(3)
    # the replication's FD, F_n = 0.2, K = 0.25 cell: bars up to the right of the panel
    d = np.concatenate([rng.uniform(0.0, 0.1, 60), rng.normal(0.07, 0.01, 40)]).clip(0, 0.1)
    four = [r for k in (0.25, 0.5, 1.0, 2.0) for r in _results(d, k=k)]  # a page-wide row
    for res in (_results(d, k=0.25), four, _grid_results(),
                _results(d, k=0.25) + _results(d[::-1], k=1.0, fn=0.3)):
        fig = plot_threshold_histograms(res)
        fig.canvas.draw()
        for ax in fig.axes:
            if any(t.get_text() == "no fits" for t in ax.texts):
                continue
            stats = [t for t in ax.texts if "N_{50" in t.get_text()]
            assert len(stats) == 1
            box = stats[0].get_window_extent()
            assert box.x0 >= ax.get_window_extent().x0, "statistics spill onto the tick labels"
            for bar in _bars(ax):
                assert not box.overlaps(bar.get_window_extent()), "statistics cover a bar"
            assert ax.get_legend() is None or not any(
                ax.get_legend().get_window_extent().overlaps(b.get_window_extent())
                for b in _bars(ax))


# --- 3. histogram statistics ---------------------------------------------------------------------
def test_single_panel_histogram_keeps_its_title_on_the_figure():
    fig = plot_threshold_histograms(_results([0.0095]))
    fig.canvas.draw()
    title = fig.get_suptitle()
    assert title
    box = fig._suptitle.get_window_extent()
    page = fig.bbox
    assert box.x0 >= page.x0 - 0.5 and box.x1 <= page.x1 + 0.5 and box.y1 <= page.y1 + 0.5
    # and its legend (with an overflow entry, the longest) too
    fig = plot_threshold_histograms(_results([0.0095, 0.2]))
    fig.canvas.draw()
    assert fig.legends
    for lg in fig.legends:
        box = lg.get_window_extent()
        assert box.x0 >= page.x0 - 0.5 and box.x1 <= page.x1 + 0.5 and box.y0 >= page.y0 - 0.5


def test_failed_fits_are_reported_and_statistics_use_the_finite_ones():
    rng = np.random.default_rng(0)
    d = np.abs(rng.normal(0.0075, 0.004, 50))
    d[::10] = np.nan
    fig = plot_threshold_histograms(_results(d, fn=0.0, k=0.25))
    ax = fig.axes[0]
    text = next(t.get_text() for t in ax.texts if "N_{50" in t.get_text())
    assert "nan" not in text.lower()
    assert re.search(r"\b5 failed\b", text)
    finite = d[np.isfinite(d)]
    assert f"{finite.mean():.4f}" in text and f"{finite.std(ddof=1):.4f}" in text
    # N50 out of every realization (Figs. 14/15: "out of 100"): a failed fit is not within 50 %
    # (the count is written only when it is not the paper's 100)
    n50 = int(np.count_nonzero(np.abs(finite - 0.0075) <= 0.5 * 0.0075))
    assert f"$N_{{50\\%}}$={n50}/50" in text
    # every finite fit is in the histogram
    assert sum(b.get_height() for b in _bars(ax)) == finite.size


def test_values_above_upper_are_counted_and_marked():
    d = [0.005, 0.007, 0.008, 0.2, 0.3, 0.15]
    fig = plot_threshold_histograms(_results(d), upper=0.1)
    ax = fig.axes[0]
    text = next(t.get_text() for t in ax.texts if "N_{50" in t.get_text())
    assert re.search(r"≥\s?0\.1: 3\b", text)
    labels = [t.get_text() for lg in (ax.get_legend(), *fig.legends) if lg is not None
              for t in lg.get_texts()]
    assert any("≥" in s for s in labels)


def test_histogram_numbers_are_those_of_campaign_summarise_without_failures():
    """What the replication prints (summary.csv) and what its figure says agree."""
    from bayespilot.campaign import summarise

    rng = np.random.default_rng(1)
    res = _results(np.abs(rng.normal(0.009, 0.005, 100)), fn=0.2, k=1.0)
    st = summarise(res)[0]
    fig = plot_threshold_histograms(res)
    text = next(t for t in fig.axes[0].texts if "N_{50" in t.get_text())
    s = text.get_text()
    assert f"{st['mu']:.4f}" in s and f"{st['sigma']:.4f}" in s
    assert st["n"] == 100 and f"$N_{{50\\%}}$={st['N50']} (paper" in s and "failed" not in s
    assert (matplotlib.colors.to_hex(text.get_color()) == matplotlib.colors.to_hex("C3")) \
        == st["flag"]
    # a flagged value is marked in the text, not by colour alone
    assert ("≠" in s) == st["flag"]


# --- 4. pair plot and chains ---------------------------------------------------------------------
def test_pair_plot_has_a_title_and_says_what_marks_the_truth():
    post = _posterior(truth={"delta_abs": 0.0075, "tau_m": 0.186, "K_m": 0.425})
    fig = plot_pair(post, truth=post.truth)
    assert fig.get_suptitle()
    labels = [t.get_text() for a in fig.axes if a.get_legend() is not None
              for t in a.get_legend().get_texts()]
    labels += [t.get_text() for lg in fig.legends for t in lg.get_texts()]
    assert any("true" in s.lower() for s in labels), labels
    # without any truth there is nothing to explain
    fig = plot_pair(post)
    assert not fig.legends and all(a.get_legend() is None for a in fig.axes)


def test_chains_autocorrelation_times_clear_the_spines():
    post = _posterior()
    fig = plot_chains(post)
    fig.canvas.draw()
    axes = fig.axes
    notes = [(a, t) for a in axes for t in a.texts if "steps" in t.get_text()]
    assert len(notes) == len(PAPER)  # one per parameter with a finite tau; none on lp
    for a, t in notes:
        box, ab = t.get_window_extent(), a.get_window_extent()
        assert not (box.y0 < ab.y1 < box.y1), "tau text straddles the top spine"
        i = axes.index(a)
        if i > 0:
            assert not box.overlaps(axes[i - 1].get_window_extent())
    title = axes[0].title.get_window_extent()
    assert not any(title.overlaps(t.get_window_extent()) for _, t in notes)


# --- 5. output formats ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def posterior_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("post") / "post.nc"
    _posterior(truth={"delta_abs": 0.0075, "K_m": 0.425, "tau_m": 0.186}).to_netcdf(path)
    return path


@pytest.mark.parametrize("fmt, magic", [("pdf", b"%PDF"), ("svg", b"<?xml")])
def test_cli_plot_writes_vector_formats(posterior_file, tmp_path, capsys, fmt, magic):
    code = main(["plot", str(posterior_file), "-o", str(tmp_path / "figs"), "--format", fmt])
    out, err = capsys.readouterr()
    assert code == 0, err
    for name in ("marginal_delta_abs", "pair", "trace"):
        data = (tmp_path / "figs" / f"{name}.{fmt}").read_bytes()
        assert data.startswith(magic)
        if fmt == "svg":
            assert b"<svg" in data[:2000]
    assert not list((tmp_path / "figs").glob("*.png"))
    assert f"pair.{fmt}" in out


def test_cli_plot_png_resolution(posterior_file, tmp_path, capsys):
    import matplotlib.image as mpimg

    code = main(["plot", str(posterior_file), "-o", str(tmp_path / "a")])
    assert code == 0
    code = main(["plot", str(posterior_file), "-o", str(tmp_path / "b"), "--dpi", "100"])
    assert code == 0
    capsys.readouterr()
    a = mpimg.imread(tmp_path / "a" / "trace.png").shape
    b = mpimg.imread(tmp_path / "b" / "trace.png").shape
    assert a[1] == pytest.approx(2 * b[1], abs=2)  # default 200 dpi
    fig = plot_chains(_posterior())
    assert b[1] == pytest.approx(fig.get_figwidth() * 100, abs=2)


@pytest.mark.parametrize("argv, message", [
    (["--format", "jpg"], "invalid choice"),
    (["--dpi", "0"], "must be >="),
])
def test_cli_plot_refuses_bad_format_options(posterior_file, tmp_path, capsys, argv, message):
    code = main(["plot", str(posterior_file), "-o", str(tmp_path / "figs"), *argv])
    err = capsys.readouterr().err
    assert code == 2 and message in err and "Traceback" not in err
    assert not (tmp_path / "figs").exists()


def test_demo_figures_use_the_cli_resolution(tmp_path):
    from bayespilot import cli, example

    assert cli.PLOT_DPI == 200
    seen = {}
    fig = plt.figure()

    def savefig(path, **kw):  # (it writes the temporary file that then replaces x.png)
        seen.update(kw, path=path)
        Path(path).write_bytes(b"")

    fig.savefig = savefig
    example._save(fig, tmp_path / "x.png")
    assert seen["dpi"] == cli.PLOT_DPI and (tmp_path / "x.png").is_file()


# --- 6. printable sizes --------------------------------------------------------------------------
def _grid_results():
    rng = np.random.default_rng(0)
    res = []
    for task in ("FD", "FT"):
        for fn in (0.0, 0.2, 0.3):
            for k in (0.25, 0.5, 1.0, 2.0):
                res += _results(np.abs(rng.normal(0.0075, 0.006, 30)), task=task, fn=fn, k=k)
    return res


def _default_figures():
    from bayespilot.recording import Recording

    post = _posterior(truth=dict(TRUTH))
    t = np.arange(500) / 100.0
    rec = Recording({"t": t, "e": np.sin(t), "u": np.cos(t), "theta_ddot_m": -np.sin(t)},
                    100.0, 1.0, "FD")
    return {"traces": plot_traces(rec, canal=0.02 * np.sin(3 * t), delta_abs=0.0075),
            "histograms": plot_threshold_histograms(_grid_results()),
            "marginal": plot_marginal(post, truth=0.0075),
            "pair8": plot_pair(post, names=PAPER, truth=post.truth),
            "pair3": plot_pair(post, truth=post.truth),
            "chains": plot_chains(post)}


def test_default_sizes_print_on_a_page():
    for name, fig in _default_figures().items():
        w, h = fig.get_size_inches()
        assert w <= 8.0 and h <= 10.0, f"{name}: {w:.1f} x {h:.1f} in"
        fig.canvas.draw()
        smallest = min(t.get_fontsize() for t in _texts(fig))
        # printed at 7 in wide the smallest text is still about 7 pt
        assert smallest * min(1.0, 7.0 / w) >= 6.5, f"{name}: {smallest} pt at {w:.1f} in"


def test_figsize_keyword_is_honoured():
    post = _posterior()
    t = np.arange(300) / 100.0
    from bayespilot.recording import Recording

    rec = Recording({"t": t, "e": np.sin(t), "u": np.cos(t), "theta_ddot_m": -np.sin(t)},
                    100.0, 1.0, "FD")
    for fig in (plot_traces(rec, figsize=(5, 4)), plot_marginal(post, figsize=(5, 4)),
                plot_pair(post, figsize=(5, 4)), plot_chains(post, figsize=(5, 4)),
                plot_threshold_histograms(_results([0.007, 0.008]), figsize=(5, 4))):
        assert tuple(fig.get_size_inches()) == (5.0, 4.0)
    fig, ax = plt.subplots()
    with pytest.raises(ValueError, match="figsize"):
        plot_marginal(post, ax=ax, figsize=(5, 4))


def test_ga_convergence_rows_take_the_fits_units():
    """A parameter of another lab's model is labelled with the unit its model declares (the
    GA figure looked units up in the paper's table only: a blank unit)."""
    from bayespilot.fit.figures import plot_ga_convergence
    from bayespilot.fit.three_step import fit_paper
    from bayespilot.model import FirstOrderLag, Parameter, paper_model
    from bayespilot.simulate import simulate

    model = paper_model().add_stage("visual", FirstOrderLag("T_x"),
                                    [Parameter("T_x", 0.001, 1.0, 0.05, "s")])
    rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.15, seed=3,
                   duration=20.48).recording
    fit = fit_paper(rec, model, seed=0, repetitions=1, n_best=1, population=8, generations=2,
                    discard=2.0)
    fig = plot_ga_convergence([fit], parameters=("T_x",))
    assert fig.axes[1].get_ylabel() == label("T_x", "s")
    plt.close(fig)


# --- arguments a user gets wrong -----------------------------------------------------------------
def test_a_single_name_is_one_parameter_in_every_plot_taking_names():
    """Audit: plot_chains(post, names="delta_abs") said "unknown parameter 'd'" (its letters)."""
    post = _posterior()
    fig = plot_chains(post, names="delta_abs")
    assert len(fig.axes) == 2 and fig.axes[0].get_ylabel() == label("delta_abs", "IPUT")
    fig = plot_pair(post, names="delta_abs")
    assert len(fig.axes) == 1
    for f in (plot_chains, plot_pair):
        with pytest.raises(TypeError, match=r"^names must be parameter names \(str\), got 3$"):
            f(post, names=["delta_abs", 3])
        with pytest.raises(TypeError, match=r"^names must be a parameter name or a sequence of "
                                            r"them, got int$"):
            f(post, names=3)


def test_threshold_histograms_say_what_they_take():
    """Audit: plot_threshold_histograms([fit]) said "'FitResult' object is not subscriptable",
    and with fit.to_dict() raised KeyError 'remnant_fraction'."""
    from bayespilot.fit.result import FitResult

    takes = (r"campaign result dicts, as bayespilot\.campaign\.load_results\(out_dir\) reads "
             r"them \(or bayespilot\.campaign\.run_job returns them\)")
    fit = FitResult.__new__(FitResult)  # the type is what matters here
    with pytest.raises(TypeError, match=rf"^results must be {takes}; results\[0\] is a "
                                        r"FitResult$"):
        plot_threshold_histograms([fit])
    with pytest.raises(TypeError, match=rf"^results must be a list of {takes}; got FitResult$"):
        plot_threshold_histograms(fit)
    with pytest.raises(TypeError, match=rf"^results must be a list of {takes}; got str 'out/' "
                                        r"\(read the folder with load_results\)$"):
        plot_threshold_histograms("out/")
    fit_dict = {"method": "fast", "threshold": True, "params": {"delta_abs": 0.01}}
    with pytest.raises(ValueError, match=rf"^results must be {takes}; results\[1\] is a dict "
                                         r"that lacks 'task', 'remnant_fraction', 'motion_gain', "
                                         r"'true_params', 'fit' \(a fit's to_dict\(\) is not a "
                                         r"campaign result\)$"):
        plot_threshold_histograms(_results([0.006]) + [fit_dict])
    # a generator of results is still taken
    fig = plot_threshold_histograms(r for r in _results([0.006, 0.008, 0.02]))
    assert len(fig.axes) == 1


# --- 7. the figure audit of 2026-11-29 -----------------------------------------------------------
def _paper_fit(*, seed=0, n_runs=4, generations=12):
    """A FitResult of the three-step procedure with made-up steps, shaped like the audit's
    Fig. 9 (FD, K_theta = 0.5): -ln L 20 000 units above its minimum at delta_abs = 0, a
    minimum at 0.0587 and a plateau 7.5 units above it from 0.064 up, where the Step II value
    and most Step I estimates lie."""
    from bayespilot.fit.result import FitResult

    rng = np.random.default_rng(seed)
    names = list(PAPER)
    grid = np.round(np.arange(0.0, 0.1 + 1e-12, 0.0005), 6)
    bottom = -31112.8
    nll = np.where(grid < 0.0587, bottom + 2.0e4 * ((0.0587 - grid) / 0.0587) ** 2,
                   bottom + 7.5 * np.clip((grid - 0.0587) / 0.0053, 0.0, 1.0))
    k = int(np.argmin(nll))
    deltas = [0.0751, 0.0693, 0.0586, 0.0946][:n_runs]
    runs = []
    for j, d in enumerate(deltas):
        x = [TRUTH[n] * (1 + 0.1 * rng.standard_normal()) for n in names]
        x[names.index("delta_abs")] = d
        hist_x = np.array([x] * (generations + 1)) * (1 + 0.05 * rng.random((generations + 1, 1)))
        hist_f = np.sort(-2.9e4 - 2e3 * rng.random(generations + 1))[::-1]
        runs.append({"x": x, "fun": float(hist_f[-1]), "history_best_x": hist_x.tolist(),
                     "history_best_fun": hist_f.tolist(),
                     "history_mean_fun": hist_f.tolist(), "n_evaluations": 100, "seed": {},
                     "settings": {}})
    params = dict(TRUTH, delta_abs=float(grid[k]))
    steps = {"step1": {"parameter_names": names, "delta_abs": 0.064, "n_best": 2,
                       "order": list(range(n_runs)), "seed": {}, "runs": runs},
             "step1_delta_abs": 0.064,
             "step2": [{"params": dict(TRUTH, delta_abs=0.064), "neg_log_lik": bottom + 7.5,
                        "start_neg_log_lik": r["fun"], "refined": True, "nfev": 5, "njev": 5,
                        "success": True, "message": ""} for r in runs],
             "step2_best": 1,
             "step3": [{"name": "delta_abs", "grid": grid.tolist(), "neg_log_lik": nll.tolist(),
                        "best": float(grid[k]), "best_neg_log_lik": float(nll[k])}],
             "iterations": [], "iterations_converged": None, "check": {}}
    return FitResult.from_dict({
        "params": params, "neg_log_lik": float(nll[k]), "vaf": 80.0, "method": "paper",
        "seed": seed, "threshold": True, "elapsed_seconds": 1.0, "source": None,
        "settings": {"model": "Pool et al. (2012)"},
        "bounds": {n: list(presets.TABLE1_BOUNDS[n]) for n in names},
        "units": dict(presets.PARAMETER_UNITS), "steps": steps})


def _fit_figures(fits):
    from bayespilot.fit.figures import (plot_ga_convergence, plot_step_one_thresholds,
                                        plot_step_three, plot_step_two)

    return {"fig6": plot_step_one_thresholds(fits), "fig7": plot_ga_convergence(fits),
            "fig8": plot_step_two(fits), "fig9": plot_step_three(fits)}


def test_fit_figures_fit_a_page_in_constrained_layout_with_no_small_fixed_fonts():
    """Audit 1 and 14: Figs. 6-9 were 3 in per panel (12 in for four fits), Fig. 8 in tight
    layout with its legend on the first panel in 7 pt."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.layout_engine import ConstrainedLayoutEngine

    small = FontProperties(size="small").get_size_in_points()
    for name, fig in _fit_figures([_paper_fit(seed=s) for s in range(4)]).items():
        w, h = fig.get_size_inches()
        assert w <= 7.5 and h <= 9.5, f"{name}: {w:.1f} x {h:.1f} in"
        assert isinstance(fig.get_layout_engine(), ConstrainedLayoutEngine), name
        fig.canvas.draw()
        for t in _texts(fig):
            assert t.get_fontsize() >= small - 1e-9, f"{name}: {t.get_text()!r} is smaller"
        # one legend above the panels, none on a panel
        assert len(fig.legends) == 1 and not any(ax.get_legend() for ax in fig.axes), name
        top = min(ax.get_window_extent().y1 for ax in fig.axes if ax.get_visible())
        assert fig.legends[0].get_window_extent().y0 >= top - 1.0, name
        # the bottom row's x tick labels do not run into each other
        for ax in fig.axes:
            assert _x_tick_labels_clear(ax), name
        plt.close(fig)


def test_fit_figures_label_neg_log_lik_in_the_paper_notation():
    """Audit 3: Fig. 8's y label was a plain "-ln L"."""
    figs = _fit_figures([_paper_fit()])
    for name in ("fig7", "fig8", "fig9"):
        assert figs[name].axes[0].get_ylabel() == r"$-\ln L$", name


def test_ga_repetitions_differ_in_line_style_not_only_colour():
    """Audit 6: Fig. 7's repetitions were blue, orange and green solid lines (grey print)."""
    fig = _fit_figures([_paper_fit()])["fig7"]
    for ax in fig.axes:
        styles = [ln.get_linestyle() for ln in ax.get_lines()]
        assert len(styles) == 3 and len(set(styles)) == 3
    handles = fig.legends[0].legend_handles
    assert len({h.get_linestyle() for h in handles}) == 3


def test_step_three_shows_the_minimum_and_the_markers():
    """Audit 7: Fig. 9's y range was set by the curve's far end (20 000 units above the
    minimum), flattening the 7.5 units between the Step II value and the minimum to a point."""
    fit = _paper_fit()
    fig = _fit_figures([fit])["fig9"]
    ax = fig.axes[0]
    lo, hi = ax.get_ylim()
    steps = fit.steps
    best = steps["step3"][0]["best_neg_log_lik"]
    step_two = next(ln for ln in ax.get_lines() if ln.get_label() == "Step II")
    y2 = float(step_two.get_ydata()[0])
    assert lo < best < y2 < hi
    # the minimum is not squashed: the Step II value stands a tenth of the axis above it
    assert (y2 - best) / (hi - lo) > 0.1
    # the open ring is drawn over the filled minimum (which shows through it)
    filled = next(ln for ln in ax.get_lines() if ln.get_label() == "Step III")
    assert step_two.get_zorder() > filled.get_zorder()
    assert step_two.get_markerfacecolor() == "none"
    # a Step I estimate off the range is marked at the top, not lost
    fig.canvas.draw()
    # whole -ln L values on the ticks, however narrow the range: no offset text
    # ("-2.615e4", as a flat scan of the docs' FD 0.25 fit had) to run into the title
    from bayespilot.fit.figures import plot_step_three

    narrow = plot_step_three([fit], span=2.0)
    narrow.canvas.draw()
    assert narrow.axes[0].yaxis.get_offset_text().get_text() == ""
    xs = np.concatenate([ln.get_xdata() for ln in ax.get_lines()
                         if ln.get_label() in ("Step I", "Step I (above the range shown)")])
    assert sorted(np.round(xs, 6)) == sorted(np.round(
        [r["x"][PAPER.index("delta_abs")] for r in steps["step1"]["runs"]], 6))
    import math

    from bayespilot.fit.figures import plot_step_three

    whole = plot_step_three([fit], span=math.inf).axes[0].get_ylim()  # the whole curve
    assert whole[1] - whole[0] > 1.9e4
    with pytest.raises(ValueError, match="span"):
        plot_step_three([fit], span=0)


def _x_tick_labels_clear(ax) -> bool:
    """Whether an axes' x tick labels (drawn) stand apart: side by side at least a quarter of
    a character apart ("0.19750.2000" touches: it reads as one number), or, turned by an
    angle, as parallel strips one text height apart."""
    labels = sorted((t for t in ax.get_xticklabels() if t.get_visible() and t.get_text()),
                    key=lambda t: t.get_window_extent().x0)
    if len(labels) < 2:
        return True
    angle = math.radians(labels[0].get_rotation())
    if abs(math.sin(angle)) < 1e-6:
        gap = 0.25 * labels[0].get_fontsize() * ax.figure.dpi / 72.0
        boxes = [t.get_window_extent() for t in labels]
        return all(b1.x0 >= b0.x1 + gap for b0, b1 in zip(boxes, boxes[1:]))
    height = labels[0].get_fontsize() * ax.figure.dpi / 72.0
    xs = [t.get_window_extent().x1 for t in labels]  # the turned labels' upper right ends
    return all(abs(b - a) * abs(math.sin(angle)) >= height for a, b in zip(xs, xs[1:]))


def test_pair_plot_bottom_tick_labels_do_not_overlap():
    """Audit 2: the demo's pair plot read "0.19750.20000.20250.2050" under tau_m."""
    post = _posterior(centre={"K_m": 0.49, "tau_m": 0.2012, "delta_abs": 0.0077}, spread=0.0069,
                      n_walkers=24, n_draws=60, seed=4)
    for kw in ({}, {"figsize": (3.5, 3.7)}, {"names": PAPER}):
        fig = plot_pair(post, **kw)
        fig.canvas.draw()
        k = int(round(len(fig.axes) ** 0.5))
        for ax in fig.axes[-k:]:
            assert len([t for t in ax.get_xticklabels() if t.get_text()]) >= 2
            assert _x_tick_labels_clear(ax), f"{kw}: tick labels overlap under {ax.get_xlabel()}"
        plt.close(fig)


def test_figure_titles_read_as_a_paper_writes():
    """Audit 3 and 15: "eq4 likelihood", "NOT converged", the recording's path in the title."""
    from bayespilot.recording import Recording

    post = _posterior()
    assert "Eq. (4) likelihood" in plot_marginal(post).axes[0].get_title().replace("\n", " ")
    assert "eq4" not in plot_pair(post)._suptitle.get_text()
    assert "Eq. (4) likelihood" in plot_pair(post)._suptitle.get_text().replace("\n", " ")
    title = plot_chains(post).axes[0].get_title(loc="left")
    assert "not converged" in title and "NOT" not in title
    fig = plot_marginal(post)
    assert "90 % HDI" in " ".join(t.get_text() for t in fig.legends[0].get_texts())
    t = np.arange(300) / 100.0
    rec = Recording({"t": t, "e": np.sin(t), "u": np.cos(t), "theta_ddot_m": -np.sin(t)},
                    100.0, 1.0, "FD", source="demo/recordings/FD_k0.5")
    assert "FD_k0.5" not in plot_traces(rec).axes[0].get_title()
    assert "demo/recordings/FD_k0.5" in plot_traces(rec, show_source=True).axes[0].get_title()


def test_marginal_density_has_the_inverse_unit():
    """Audit 12: "posterior density" without its unit."""
    post = _posterior()
    assert plot_marginal(post, "delta_abs").axes[0].get_ylabel() == "posterior density (1/IPUT)"
    assert plot_marginal(post, "tau_m").axes[0].get_ylabel() == "posterior density (1/s)"
    assert plot_marginal(post, "K_m").axes[0].get_ylabel() == "posterior density (IPUT/rad)"
    assert plot_marginal(post, "zeta_nm").axes[0].get_ylabel() == "posterior density"
    # the catalogue's compound units (the otolith gain K_ot, a rate): inverted whole
    from bayespilot.plots import _per_unit

    assert _per_unit("rad/(m/s^2)") == " ((m/s$^2$)/rad)"  # (was 1/(rad/(m/s$^2$)))
    assert _per_unit("1/s") == " (s)" and _per_unit("rad/s") == " (s/rad)"


def test_marginal_interval_median_and_an_added_span_stay_apart():
    """Audit 5: the 90 % HDI was a blue translucent span; a fit's red s.e. span on the same
    axes (the diagnosis report's) mixed with it into purple, and the median was the bars'
    blue.  Now the HDI is a bar above the histogram, the median another colour and style."""
    from matplotlib.colors import to_rgba

    post = _posterior()
    fig, ax = plt.subplots(layout="constrained")
    plot_marginal(post, "delta_abs", truth=0.0075, ax=ax)
    bars = _bars(ax)
    translucent = [p for p in ax.patches if p.get_facecolor()[3] < 0.5]
    assert not translucent, "a shaded span would mix with spans added to the axes"
    bar_colour = to_rgba(bars[0].get_facecolor())[:3]
    median = next(ln for ln in ax.get_lines() if ln.get_label().startswith("median"))
    assert to_rgba(median.get_color())[:3] != bar_colour and median.get_linestyle() != "-"
    hdi = next(ln for ln in ax.get_lines() if ln.get_label().startswith("90 % HDI"))
    lo, hi = post.credible_interval("delta_abs", 0.9)
    np.testing.assert_allclose(hdi.get_xdata(), [lo, hi])
    assert min(hdi.get_ydata()) > max(b.get_height() for b in bars)  # above every bar
    assert max(hdi.get_ydata()) < ax.get_ylim()[1]


def test_marginal_title_wraps_and_the_legend_on_given_axes_clears_the_bars():
    """Audit 8: at figsize=(3.4, 2.6) the title ran off the figure; on given axes the title
    ran over the neighbour and the legend ("best") covered bars."""
    post = _posterior()
    fig = plot_marginal(post, "zeta_nm", truth=0.22, figsize=(3.4, 2.6))
    fig.canvas.draw()
    title = fig.axes[0].title.get_window_extent()
    page = fig.bbox
    assert title.x0 >= page.x0 and title.x1 <= page.x1, "the title runs off the figure"
    fig, axs = plt.subplots(1, 2, figsize=(7, 2.8), layout="constrained")
    for ax, name in zip(axs, ("K_m", "delta_abs")):
        plot_marginal(post, name, truth=TRUTH[name], ax=ax)
    fig.canvas.draw()
    for ax in axs:
        title, box = ax.title.get_window_extent(), ax.get_window_extent()
        assert title.width <= box.width + 2.0, "the title is wider than its axes"
        legend = ax.get_legend().get_window_extent()
        for bar in _bars(ax):
            assert not legend.overlaps(bar.get_window_extent()), "the legend covers a bar"
        label = ax.xaxis.label.get_window_extent()
        assert not legend.overlaps(label), "the legend covers the x label"
    assert not axs[0].title.get_window_extent().overlaps(axs[1].title.get_window_extent())
    # a figure without a layout engine has no room under the axes: the legend stays on the
    # figure, in a corner above the bars and the HDI
    fig, ax = plt.subplots()
    plot_marginal(post, "delta_abs", truth=0.0075, ax=ax)
    fig.canvas.draw()
    legend = ax.get_legend().get_window_extent()
    assert legend.y0 >= fig.bbox.y0 and legend.y1 <= fig.bbox.y1
    for bar in _bars(ax):
        assert not legend.overlaps(bar.get_window_extent()), "the legend covers a bar"
    hdi = next(ln for ln in ax.get_lines() if ln.get_label().startswith("90 % HDI"))
    assert not legend.overlaps(hdi.get_window_extent(fig.canvas.get_renderer()))


def test_histograms_upper_auto_shows_a_tight_distribution():
    """Audit 13: with every estimate below 0.015 the [0, 0.1] axis put them in 2-5 bins."""
    rng = np.random.default_rng(5)
    d = np.abs(rng.normal(0.0075, 0.002, 100))
    res = _results(d)
    assert plot_threshold_histograms(res).axes[0].get_xlim() == (0.0, 0.1)  # the paper's
    ax = plot_threshold_histograms(res, upper="auto").axes[0]
    lo, hi = ax.get_xlim()
    assert lo == 0.0 and 1.5 * 0.0075 < hi <= 0.02 and np.quantile(d, 0.98) < hi
    assert sum(1 for b in _bars(ax) if b.get_height() > 0) >= 10
    with pytest.raises(ValueError, match="upper"):
        plot_threshold_histograms(res, upper="big")


def test_cli_replicate_takes_a_histogram_upper_limit():
    from bayespilot.cli import build_parser

    parser = build_parser()
    base = ["replicate", "--out", "x"]
    assert parser.parse_args(base).hist_upper == 0.1
    assert parser.parse_args([*base, "--hist-upper", "auto"]).hist_upper == "auto"
    assert parser.parse_args([*base, "--hist-upper", "0.03"]).hist_upper == 0.03
    with pytest.raises(Exception, match="hist-upper"):
        parser.parse_args([*base, "--hist-upper", "-1"])


def test_cli_plot_pdf_embeds_truetype_and_svg_keeps_text(posterior_file, tmp_path, capsys):
    """Audit 11: a PDF with Type 3 fonts fails AIAA's and IEEE's PDF checks; SVG text was
    drawn as paths."""
    for fmt in ("pdf", "svg"):
        code = main(["plot", str(posterior_file), "-o", str(tmp_path / fmt), "--format", fmt])
        assert code == 0, capsys.readouterr().err
    for name in ("marginal_delta_abs", "pair", "trace"):
        pdf = (tmp_path / "pdf" / f"{name}.pdf").read_bytes()
        assert b"/Subtype /Type3" not in pdf and b"/FontFile2" in pdf
        svg = (tmp_path / "svg" / f"{name}.svg").read_text()
        assert "<text" in svg and "font-family" in svg


#: The name sample records for the paper's model with the catalogue's motion washout.
WASHOUT_MODEL = "Pool et al. (2012) + SecondOrderWashout on vestibular"


def test_an_extension_posterior_has_its_units_without_a_model():
    """Audit 4: a posterior written by diagnose (omega_w) was labelled without its unit."""
    names = (*PAPER, "omega_w")
    post = _posterior(names, centre={"omega_w": 0.3}, model=WASHOUT_MODEL)
    want = label("omega_w", "rad/s")
    assert plot_marginal(post, "omega_w").axes[0].get_xlabel() == want
    assert plot_marginal(post, "omega_w").axes[0].get_ylabel() == "posterior density (s/rad)"
    assert plot_chains(post).axes[-2].get_ylabel() == want
    assert plot_pair(post, names=("delta_abs", "omega_w")).axes[-1].get_xlabel() == want
    # the paper's model (or an unknown one): Table 1's units, as before
    other = _posterior(names, centre={"omega_w": 0.3}, model="someone else's model + X")
    assert plot_marginal(other, "omega_w").axes[0].get_xlabel() == symbol("omega_w")


def test_cli_plot_of_an_extension_posterior_draws_its_parameter(tmp_path, capsys):
    names = (*PAPER, "omega_w")
    nc = tmp_path / "wash.nc"
    _posterior(names, centre={"omega_w": 0.3}, model=WASHOUT_MODEL,
               likelihood="coloured").to_netcdf(nc)
    code = main(["plot", str(nc), "-o", str(tmp_path / "figs"), "--format", "svg"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "marginal_omega_w.svg" in out
    marginal = (tmp_path / "figs" / "marginal_omega_w.svg").read_text()
    trace = (tmp_path / "figs" / "trace.svg").read_text()
    # (matplotlib writes each text into the SVG as a comment too)
    for svg in (marginal, trace):
        assert r"<!-- $\omega_\mathrm{w}$ (rad/s) -->" in svg


# --- 8. the figure audit for a journal paper (audit_figures.md, 2026-11-29) ---------------------
def _recording(seconds=3.0):
    from bayespilot.recording import Recording

    t = np.arange(int(100 * seconds)) / 100.0
    return Recording({"t": t, "e": np.sin(t), "u": np.cos(t), "theta_ddot_m": -np.sin(t)},
                     100.0, 1.0, "FD")


def _titles(fig, axes):
    """The figure's title and the titles (left, centre, right) of ``axes``, non-empty."""
    out = [fig._suptitle.get_text()] if fig._suptitle is not None else []
    out += [a.get_title(loc) for a in axes for loc in ("left", "center", "right")]
    return [t for t in out if t.strip()]


def _paper_figures(title, **kw):
    """(figure, axes whose titles are the figure's title, today's title text) per function."""
    post = _posterior()
    t = np.arange(300) / 100.0
    rec = _recording()
    out = {}
    fig = plot_marginal(post, title=title, **kw)
    out["marginal"] = (fig, fig.axes, "draws (Eq. (4) likelihood")
    fig = plot_pair(post, title=title, **kw)
    out["pair"] = (fig, fig.axes, "Posterior:")
    fig = plot_chains(post, title=title, **kw)
    out["chains"] = (fig, fig.axes[:1], "10 walkers, 600 steps, not converged")
    fig = plot_traces(rec, canal=0.02 * np.sin(3 * t), delta_abs=0.0075, title=title, **kw)
    out["traces"] = (fig, fig.axes[:1], "task FD")
    fig = plot_threshold_histograms(_results([0.006, 0.008, 0.02]), title=title, **kw)
    out["histograms"] = (fig, [], "Estimated threshold over realizations")
    return out


@pytest.mark.filterwarnings("ignore::bayespilot.sample.ConvergenceWarning")
def test_every_plot_takes_title_true_false_or_a_text():
    """Audit R1: every figure had a run-note title a paper must delete, and no option to."""
    size = {"figsize": (5.0, 4.0)}
    default = _paper_figures(True, **size)
    for name, (fig, axes, own) in default.items():
        titles = _titles(fig, axes)
        assert len(titles) == 1 and own in titles[0].replace("\n", " "), (name, titles)
    for name, (fig, axes, own) in _paper_figures(False, **size).items():
        assert _titles(fig, axes) == [], name
        # the layout takes the room: the panels reach higher than under a title
        fig.canvas.draw()
        before = default[name][0]
        before.canvas.draw()
        top = max(a.get_window_extent().y1 for a in fig.axes if a.get_visible())
        top_before = max(a.get_window_extent().y1 for a in before.axes if a.get_visible())
        assert top > top_before + 5.0, f"{name}: the panels do not use the title's room"
        # and the title's text stays available for a caption
        assert own in getattr(fig, "_bayespilot_note").replace("\n", " "), name
    for name, (fig, axes, own) in _paper_figures("Figure 3", **size).items():
        assert [t.replace("\n", " ") for t in _titles(fig, axes)] == ["Figure 3"], name
    # "" is no title too (as in the diagnosis report); anything else is refused
    assert _titles(*_paper_figures("")["chains"][:2]) == []
    post = _posterior()
    for f in (plot_marginal, plot_pair, plot_chains):
        with pytest.raises(TypeError, match="title must be True .* False .* or a str, got 1"):
            f(post, title=1)
    with pytest.raises(TypeError, match="title must be"):
        plot_traces(_recording(), title=None)
    with pytest.raises(TypeError, match="title must be"):
        plot_threshold_histograms(_results([0.006]), title=None)
    # the histograms' panels keep their K_theta headings: they name the panels
    fig = _paper_figures(False)["histograms"][0]
    assert fig.axes[0].get_title() == r"$K_\theta$ = 1"
    # a pair plot on given axes: a title only when the caller names one
    fig, axs = plt.subplots(3, 3)
    assert not plot_pair(post, ax=axs).get_suptitle()
    fig, axs = plt.subplots(3, 3)
    assert plot_pair(post, ax=axs, title="Fig. 5").get_suptitle() == "Fig. 5"


def test_an_untitled_unconverged_posterior_warns_and_keeps_its_note():
    """R1: "not converged" was in the title only; without the title the user is told."""
    import warnings

    from bayespilot.sample import ConvergenceWarning

    post = _posterior()
    assert not post.converged
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for f in (plot_marginal, plot_pair, plot_chains):
            f(post)  # the title says it: no warning
    for f in (plot_marginal, plot_pair, plot_chains):
        for title in (False, "Fig. 4"):
            with pytest.warns(ConvergenceWarning, match=r"not converged \(600 steps\).*caption"):
                fig = f(post, title=title)
            assert "not converged" in fig._bayespilot_note
    import dataclasses

    converged = dataclasses.replace(_posterior(), converged=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert "converged" in plot_chains(converged, title=False)._bayespilot_note


def test_untitled_histograms_give_the_papers_key_in_the_legend():
    """R1: "≠ and red: differs from the paper" was only in the title."""
    def legend_texts(fig):
        return [t.get_text() for lg in fig.legends for t in lg.get_texts()]

    res = _results([0.006, 0.008, 0.02], fn=0.2, k=1.0)  # a cell of Figs. 14/15
    assert not any("differs from the paper" in s for s in legend_texts(
        plot_threshold_histograms(res)))
    for title in (False, "Fig. 14"):
        fig = plot_threshold_histograms(res, title=title)
        assert any("differs from the paper" in s for s in legend_texts(fig)), title
    # a cell the paper does not have (K_theta = 3): nothing to key
    fig = plot_threshold_histograms(_results([0.006, 0.008], k=3.0), title=False)
    assert not any("paper" in s for s in legend_texts(fig))


def test_fit_figures_take_title_true_false_or_a_text():
    from bayespilot.fit.figures import (plot_ga_convergence, plot_step_one_thresholds,
                                        plot_step_three, plot_step_two)

    fits = [_paper_fit(seed=s) for s in range(2)]
    for f in (plot_step_one_thresholds, plot_ga_convergence, plot_step_two, plot_step_three):
        name = f.__name__
        fig = f(fits)
        assert not fig.get_suptitle() and [a.get_title() for a in fig.axes if a.get_title()] \
            == ["fit 1", "fit 2"], name
        fig = f(fits, title=False)
        fig.canvas.draw()
        assert _titles(fig, fig.axes) == [], name
        fig = f(fits, title="Figure 6")
        fig.canvas.draw()
        # the title at the top, heading the legend above the panels (a suptitle lay over it)
        head = fig.legends[0].get_title()
        assert head.get_text().split("\n")[0] == "Figure 6", name
        entries = [t.get_window_extent() for t in fig.legends[0].get_texts()]
        assert head.get_window_extent().y0 >= max(e.y1 for e in entries) - 1.0, name
        assert head.get_window_extent().y1 <= fig.bbox.y1 + 0.5
        assert fig.legends[0].get_window_extent().y0 >= max(
            a.get_window_extent().y1 for a in fig.axes if a.get_visible()) - 1.0, name
        # the labels a caller gives name the panels, with or without a title
        fig = f(fits, ["FD, 0.25", "FD, 0.5"], title=False)
        assert [a.get_title() for a in fig.axes if a.get_title()] == ["FD, 0.25", "FD, 0.5"]
        with pytest.raises(TypeError, match="title must be"):
            f(fits, title=0)


def test_chains_at_column_width_keep_their_texts_apart():
    """R3: at 3.5 x 6 in the title ran into the autocorrelation time and off the figure, and
    neighbouring y labels ("K_m (rad/IPUT)" over "tau_m (s)") overlapped."""
    post = _posterior()
    fig = plot_chains(post, figsize=(3.5, 6))
    fig.canvas.draw()
    page = fig.bbox
    title = [t for t in (fig._suptitle, *(fig.axes[0].title, fig.axes[0]._left_title))
             if t is not None and "not converged" in t.get_text()]
    assert len(title) == 1
    box = title[0].get_window_extent()
    assert page.x0 - 0.5 <= box.x0 and box.x1 <= page.x1 + 0.5, "the title is cut"
    notes = [t for a in fig.axes for t in a.texts if "autocorrelation time" in t.get_text()]
    assert len(notes) == len(PAPER)
    for t in notes:
        nb = t.get_window_extent()
        assert not box.overlaps(nb), "the title runs into an autocorrelation time"
        assert page.x0 - 0.5 <= nb.x0 and nb.x1 <= page.x1 + 0.5
    labels = [a.yaxis.label.get_window_extent() for a in fig.axes]
    for i, b0 in enumerate(labels):
        assert page.y0 - 0.5 <= b0.y0 and b0.y1 <= page.y1 + 0.5
        for b1 in labels[i + 1:]:
            assert not b0.overlaps(b1), "two y labels overlap"
    # in one column (aligned on the side of the axes)
    assert max(b.x1 for b in labels) - min(b.x1 for b in labels) < 1.0
    # at the default size (a page) every label keeps its unit, the log posterior its constant
    fig = plot_chains(post)
    assert [a.get_ylabel() for a in fig.axes][:-1] == [
        label(n, presets.PARAMETER_UNITS[n]) for n in PAPER]
    assert fig.axes[-1].get_ylabel().replace("\n", " ") == "log posterior (+ const.)"
    assert fig.axes[0].get_title(loc="left") == "10 walkers, 600 steps, not converged"


def test_traces_at_column_width_keep_the_share_off_the_legend():
    """R3: at 3.5 x 4.5 in "|i| > delta_abs 71 % of the time" overprinted the legend."""
    from bayespilot.simulate import simulate

    sim = simulate(task="FT", motion_gain=0.5, remnant_fraction=0.0, seed=2, duration=5.0)
    for size in ((3.5, 4.5), (7.0, 6.9)):
        fig = plot_traces(sim, figsize=size)
        fig.canvas.draw()
        canal = fig.axes[3]
        legend = canal.get_legend()
        entries = [t.get_window_extent() for t in legend.get_texts()]
        entries += [h.get_window_extent(fig.canvas.get_renderer())
                    for h in legend.legend_handles]
        share = [t for t in (canal._left_title, legend.get_title())
                 if "of the time" in t.get_text()]
        assert len(share) == 1, size
        sb = share[0].get_window_extent()
        assert not any(sb.overlaps(e) for e in entries), f"{size}: the share over the legend"
        for b in (sb, legend.get_window_extent()):
            assert fig.bbox.x0 - 0.5 <= b.x0 and b.x1 <= fig.bbox.x1 + 0.5
            # above the canal panel, below the panel above
            assert b.y0 >= canal.get_window_extent().y1 - 1.0
            assert b.y1 <= fig.axes[2].get_window_extent().y0 + 1.0
    # a page-wide figure keeps them side by side, as before
    assert canal.get_title(loc="left") and not legend.get_title().get_text()


def _column_results():
    rng = np.random.default_rng(3)
    d = np.concatenate([rng.uniform(0.0, 0.1, 60), rng.normal(0.07, 0.01, 40)]).clip(0, 0.1)
    return _results(d, k=0.25) + _results(np.abs(rng.normal(0.0075, 0.004, 100)), k=1.0)


def _statistics(ax):
    return [t for t in ax.texts if "N_{50" in t.get_text() and t.get_visible()]


def test_histograms_at_column_width_keep_statistics_off_bars_and_ticks():
    """R3: at 3.5 x 2.2 in the statistics covered the bars and a y tick label ("25≠mu")."""
    fig = plot_threshold_histograms(_column_results(), figsize=(3.5, 2.2), title=False)
    fig.canvas.draw()
    page = fig.bbox
    for ax in fig.axes:
        stats = _statistics(ax)
        assert len(stats) == 1
        box = stats[0].get_window_extent()
        for bar in _bars(ax):
            assert not box.overlaps(bar.get_window_extent()), "statistics cover a bar"
        for other in fig.axes:
            for t in (*other.get_yticklabels(), *other.get_xticklabels(), other.title,
                      other.yaxis.label):
                if t.get_visible() and t.get_text():
                    assert not box.overlaps(t.get_window_extent()), \
                        f"statistics over {t.get_text()!r}"
        assert page.x0 - 0.5 <= box.x0 and box.x1 <= page.x1 + 0.5
        assert page.y0 - 0.5 <= box.y0 and box.y1 <= page.y1 + 0.5
        # the panel is not squeezed to nothing
        assert ax.get_window_extent().height > 20
    # a page-wide figure keeps them in the corner, as before
    fig = plot_threshold_histograms(_column_results())
    fig.canvas.draw()
    for ax in fig.axes:
        box, ab = _statistics(ax)[0].get_window_extent(), ax.get_window_extent()
        assert ab.x0 <= box.x0 and box.x1 <= ab.x1 and ab.y0 <= box.y0 and box.y1 <= ab.y1


def test_histogram_statistics_go_where_asked():
    res = _column_results()
    for where, inside in (("inside", True), ("above", False)):
        fig = plot_threshold_histograms(res, stats=where)
        fig.canvas.draw()
        for ax in fig.axes:
            box, ab = _statistics(ax)[0].get_window_extent(), ax.get_window_extent()
            assert (box.y0 >= ab.y1 - 1.0) == (not inside), where
            # above: under the panel's heading
            if not inside:
                assert box.y1 <= ax.title.get_window_extent().y0 + 1.0
    fig = plot_threshold_histograms(res, stats=None)
    assert not any(_statistics(ax) for ax in fig.axes)
    with pytest.raises(ValueError, match="stats must be 'auto', 'inside', 'above' or None"):
        plot_threshold_histograms(res, stats="below")


def test_step_one_marks_a_true_value_only_when_known_and_names_a_reference():
    """R4: every Fig. 6 drew a line "true delta_abs (0.0075 IPUT)", measured data too."""
    from bayespilot.fit.figures import TRUE_THRESHOLD, plot_step_one_thresholds
    from bayespilot.fit.result import FitResult

    def dashed(fig):
        return [ln for ax in fig.axes for ln in ax.get_lines() if ln.get_linestyle() == "--"
                and ln.get_label().startswith(("true", "Groen"))]

    def legend(fig):
        return [t.get_text() for t in fig.legends[0].get_texts()]

    fits = [_paper_fit(seed=s) for s in range(2)]
    fig = plot_step_one_thresholds(fits)
    assert not dashed(fig) and not any("true" in s for s in legend(fig))
    d = symbol("delta_abs")
    # the paper's simulations (analyses/fit_procedure.py's Fig. 6): as before
    fig = plot_step_one_thresholds(fits, true_value=TRUE_THRESHOLD)
    assert f"true {d} (0.0075 IPUT)" in legend(fig)
    assert {float(ln.get_ydata()[0]) for ln in dashed(fig)} == {0.0075}
    # measured data: the passive threshold, named as such
    fig = plot_step_one_thresholds(fits, true_value=presets.DELTA_ABS_PASSIVE,
                                   reference_label="Groen et al.'s passive threshold")
    assert "Groen et al.'s passive threshold (0.00734 IPUT)" in legend(fig)
    assert not any("true" in s for s in legend(fig))
    # a fit that records its recording's truth is marked with it
    recorded = []
    for s, true in ((0, 0.006), (1, 0.009)):
        dct = _paper_fit(seed=s).to_dict()
        dct["settings"] = dict(dct["settings"], true_parameters={"delta_abs": true})
        recorded.append(FitResult.from_dict(dct))
    fig = plot_step_one_thresholds(recorded[:1] + fits[:1])
    assert [float(ln.get_ydata()[0]) for ln in dashed(fig)] == [0.006]
    assert f"true {d} (0.006 IPUT)" in legend(fig)
    fig = plot_step_one_thresholds(recorded)
    assert sorted(float(ln.get_ydata()[0]) for ln in dashed(fig)) == [0.006, 0.009]
    assert f"true {d} (each panel's)" in legend(fig)
    with pytest.raises(ValueError, match="reference_label names the line at true_value"):
        plot_step_one_thresholds(fits, reference_label="passive threshold")
    with pytest.raises(ValueError, match="true_value must be finite"):
        plot_step_one_thresholds(fits, true_value=math.nan)


def test_true_values_and_marginal_numbers_carry_quantity_and_unit():
    """T1: "truth 0.0075", "true", "median 0.01108" (no unit) beside Fig. 6's
    "true delta_abs (0.0075 IPUT)"."""
    d = symbol("delta_abs")
    post = _posterior()
    fig = plot_marginal(post, truth=0.0075)
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert f"true {d} (0.0075 IPUT)" in texts
    assert any(re.fullmatch(r"median 0\.00\d+ IPUT", s) for s in texts), texts
    assert any(re.fullmatch(r"90 % HDI \[0\.00\d+, 0\.00\d+\] IPUT", s) for s in texts), texts
    fig = plot_marginal(post, "zeta_nm", truth=0.22)  # dimensionless: no unit
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert rf"true {symbol('zeta_nm')} (0.22)" in texts
    assert any(re.fullmatch(r"median 0\.2\d*", s) for s in texts), texts
    fig = plot_threshold_histograms(_results([0.006, 0.008, 0.02]))
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert f"true {d} (0.0075 IPUT)" in texts
    assert rf"true {d} $\pm$50 %" in texts


@pytest.mark.filterwarnings("ignore::bayespilot.sample.ConvergenceWarning")
def test_marginal_without_title_at_column_width_keeps_its_labels_on_the_figure():
    """R1/R3: without the title's room above the axes, "posterior density (1/IPUT)" ran off
    the top of a 3.5 x 2.6 in figure."""
    post = _posterior()
    for title in (True, False):
        fig = plot_marginal(post, truth=0.0075, figsize=(3.5, 2.6), title=title)
        fig.canvas.draw()
        page = fig.bbox
        ax = fig.axes[0]
        lo, hi = ax.get_xlim()
        ticks = [t for t in ax.get_xticklabels() if lo <= t.get_position()[0] <= hi]
        ticks += [t for t in ax.get_yticklabels()
                  if ax.get_ylim()[0] <= t.get_position()[1] <= ax.get_ylim()[1]]
        shown = [t for t in _texts(fig) if t not in (*ax.get_xticklabels(),
                                                      *ax.get_yticklabels())]
        for t in shown + [t for t in ticks if t.get_text()]:
            b = t.get_window_extent()
            assert page.x0 - 0.5 <= b.x0 and b.x1 <= page.x1 + 0.5 and page.y0 - 0.5 <= b.y0 \
                and b.y1 <= page.y1 + 0.5, f"{title}: {t.get_text()!r} runs off the figure"
        assert fig.axes[0].get_ylabel().replace("\n", " ") == "posterior density (1/IPUT)"

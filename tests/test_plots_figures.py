"""Figures of bayespilot.plots as they reach a paper: notation, legends that leave the data
visible, honest histogram statistics, titles, output formats and printable sizes.

Every posterior here is synthetic (a few hundred draws built directly), so the module
runs in seconds; geometry is checked in display coordinates after a draw.
"""

from __future__ import annotations

import json
import re

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
               spread=0.08):
    """A Posterior of Gaussian draws around ``centre`` (default Table 3 FD; relative standard
    deviation ``spread``), kept as sample keeps it."""
    import arviz as az

    from bayespilot.sample import _META_ATTR, Posterior

    rng = np.random.default_rng(seed)
    centre = dict(TRUTH, **(centre or {}))
    post = {n: centre.get(n, 0.1) * (1.0 + spread * rng.standard_normal((n_walkers, n_draws)))
            for n in names}
    lp = rng.normal(7740.0, 2.0, (n_walkers, n_draws))
    idata = az.from_dict(posterior=post, sample_stats={"lp": lp})
    settings = {"likelihood": "eq4", "discard": 150, "thin": 7, "n_steps": 600,
                "model": "Pool et al. (2012)", "true_parameters": truth}
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
            stats = [t for t in ax.texts if "N50" in t.get_text()]
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
    text = next(t.get_text() for t in ax.texts if "N50" in t.get_text())
    assert "nan" not in text.lower()
    assert re.search(r"\b5 failed\b", text)
    finite = d[np.isfinite(d)]
    assert f"{finite.mean():.4f}" in text and f"{finite.std(ddof=1):.4f}" in text
    # N50 out of every realization (Figs. 14/15: "out of 100"): a failed fit is not within 50 %
    # (the count is written only when it is not the paper's 100)
    n50 = int(np.count_nonzero(np.abs(finite - 0.0075) <= 0.5 * 0.0075))
    assert f"N50={n50}/50" in text
    # every finite fit is in the histogram
    assert sum(b.get_height() for b in _bars(ax)) == finite.size


def test_values_above_upper_are_counted_and_marked():
    d = [0.005, 0.007, 0.008, 0.2, 0.3, 0.15]
    fig = plot_threshold_histograms(_results(d), upper=0.1)
    ax = fig.axes[0]
    text = next(t.get_text() for t in ax.texts if "N50" in t.get_text())
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
    text = next(t for t in fig.axes[0].texts if "N50" in t.get_text())
    s = text.get_text()
    assert f"{st['mu']:.4f}" in s and f"{st['sigma']:.4f}" in s
    assert st["n"] == 100 and f"N50={st['N50']} (paper" in s and "failed" not in s
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
    fig.savefig = lambda path, **kw: seen.update(kw, path=path)
    example._save(fig, tmp_path / "x.png")
    assert seen["dpi"] == cli.PLOT_DPI


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

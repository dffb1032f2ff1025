"""Figures for a paper from the command line: --no-title on every command that writes figures
(plot, diagnose --report, diagnose-batch, replicate, demo), --format (repeatable) and --dpi
on replicate, diagnose-batch and demo, and the title/figsize pass-throughs of the library
(DiagnosisResult.report, the pooled report, pooled.plot_runs, diagnose_batch), in-process
through ``bayespilot.cli.main`` with the cheapest settings the other tests use."""

from __future__ import annotations

import json
import warnings
import xml.etree.ElementTree as ET
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from bayespilot import cli, presets  # noqa: E402
from bayespilot.cli import main  # noqa: E402
from bayespilot.diagnose import NAMES  # noqa: E402
from bayespilot.io import write_recording  # noqa: E402
from bayespilot.recording import Recording  # noqa: E402
from bayespilot.simulate import simulate  # noqa: E402
from test_diagnose_batch import _run_here  # noqa: E402  (tasks run in this process)


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _svg_text(path) -> str:
    """All the text an SVG shows (it is text there: svg.fonttype 'none'), joined; a mathtext
    line is one element per glyph, its spaces no-break spaces: made plain spaces."""
    root = ET.parse(path).getroot()  # (raises on a file that is not XML)
    assert root.tag.endswith("svg")
    return "".join(e.text or "" for e in root.iter()
                   if e.tag.endswith("}text") or e.tag.endswith("}tspan")).replace("\xa0", " ")


def _is_pdf(path) -> bool:
    data = path.read_bytes()
    return data.startswith(b"%PDF-") and b"%%EOF" in data[-1024:] and b"/Type3" not in data


@pytest.fixture
def saved(monkeypatch):
    """Every figure the commands save (cli's and the library's save_figure): its path and the
    titles it carries then (the suptitle, each axes' titles)."""
    import bayespilot._figstyle as F

    real = F.save_figure
    kept = []

    def spy(fig, path, dpi=200):
        sup = fig._suptitle.get_text() if fig._suptitle is not None else ""
        axes = [t for ax in fig.axes for t in (ax.get_title("left"), ax.get_title(),
                                              ax.get_title("right")) if t]
        kept.append((str(path), sup, axes))
        return real(fig, path, dpi)

    import bayespilot.diagnose.report as R

    for module in (cli, F, R):  # (each module's own name for it, imported or not yet)
        monkeypatch.setattr(module, "save_figure", spy)
    return kept


# --- plot --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def unconverged(tmp_path_factory):
    """A posterior file of Gaussian draws around Table 3 (FD), not converged, with a truth."""
    import arviz as az

    from bayespilot.sample import _META_ATTR, Posterior

    names = presets.PARAMETER_NAMES
    centre = presets.paper_parameters("FD")
    rng = np.random.default_rng(0)
    post = {n: centre[n] * (1.0 + 0.08 * rng.standard_normal((10, 60))) for n in names}
    idata = az.from_dict(posterior=post, sample_stats={"lp": rng.normal(7740.0, 2.0, (10, 60))})
    truth = {"delta_abs": 0.0075, "K_m": 0.425, "tau_m": 0.186}
    settings = {"likelihood": "eq4", "discard": 150, "thin": 7, "n_steps": 600,
                "model": "Pool et al. (2012)", "true_parameters": truth}
    tau = {n: 40.0 + i for i, n in enumerate(names)}
    idata.posterior.attrs[_META_ATTR] = json.dumps(
        {"parameter_names": list(names), "tau": tau, "converged": False,
         "settings": settings, "seed": 0})
    path = tmp_path_factory.mktemp("post") / "post.nc"
    Posterior(idata, tuple(names), tau, False, settings, 0).to_netcdf(path)
    return path


def test_plot_no_title_writes_every_format_untitled_and_says_not_converged_once(
        unconverged, tmp_path, capsys, saved):
    # with titles (today's figures): the run note is in every figure, nothing on stderr
    code, out, err = _run(capsys, "plot", unconverged, "-o", tmp_path / "titled",
                          "--format", "svg")
    assert code == 0, err
    assert "not converged" in _svg_text(tmp_path / "titled" / "trace.svg")
    assert "600 draws" in _svg_text(tmp_path / "titled" / "marginal_delta_abs.svg")
    assert "Posterior" in _svg_text(tmp_path / "titled" / "pair.svg")
    assert "converged" not in err
    saved.clear()
    figs = tmp_path / "paper"
    code, out, err = _run(capsys, "plot", unconverged, "-o", figs, "--no-title",
                          "--format", "svg", "--format", "pdf", "--format", "png",
                          "--format", "svg", "--dpi", "100")
    assert code == 0, err
    for name in ("marginal_delta_abs", "pair", "trace"):
        text = _svg_text(figs / f"{name}.svg")
        assert "converged" not in text and "draws" not in text and "Posterior" not in text
        assert "walkers" not in text
        assert _is_pdf(figs / f"{name}.pdf")
        png = mpimg.imread(figs / f"{name}.png")
        assert png.ndim == 3
        assert f"{figs / name}.pdf" in out and f"{figs / name}.png" in out
    # the PNGs were drawn without any title either, at --dpi
    assert sorted(p for p, _, _ in saved) == sorted(
        str(figs / f"{n}.{f}") for n in ("marginal_delta_abs", "pair", "trace")
        for f in ("svg", "pdf", "png"))
    assert all(sup == "" and not axes for _, sup, axes in saved)
    from bayespilot.plots import plot_chains
    from bayespilot.sample import Posterior

    width = plot_chains(Posterior.from_netcdf(unconverged)).get_figwidth()
    assert mpimg.imread(figs / "trace.png").shape[1] == pytest.approx(100 * width, abs=2)
    # the note the titles carried: once, in the command's words, no Python warning lines
    assert err.count("has not converged") == 1, err
    assert f"{unconverged}: the chain has not converged (600 steps)" in err
    assert "--no-title" in err and "ConvergenceWarning" not in err and "_bayespilot_note" not in err


def test_plot_format_options_refuse_bad_values(unconverged, tmp_path, capsys):
    for argv, message in ((["--format", "jpg"], "invalid choice"),
                          (["--format", "png", "--format", "eps"], "invalid choice"),
                          (["--dpi", "0"], "must be >=")):
        code, out, err = _run(capsys, "plot", unconverged, "-o", tmp_path / "f", *argv)
        assert code == 2 and message in err and len(err.splitlines()) == 1
    assert not (tmp_path / "f").exists()


# --- demo ---------------------------------------------------------------------------------------
def test_demo_quick_takes_format_dpi_and_no_title(tmp_path, capsys, saved):
    # (the titled figure, the default: test_example.py; one run here, a quick demo takes 8 s)
    code, out, err = _run(capsys, "demo", "--quick", "--out", tmp_path / "n", "--no-title",
                          "--format", "pdf", "--format", "svg", "--dpi", "300", "-q")
    assert code == 0, err
    text = _svg_text(tmp_path / "n" / "traces.svg")
    assert "task FD" not in text and "81.92 s" not in text
    assert "of the time" in text  # (the canal panel's share is a panel note: kept)
    assert _is_pdf(tmp_path / "n" / "traces.pdf") and not (tmp_path / "n" / "traces.png").exists()
    assert len(saved) == 2  # (pdf and svg)
    assert all(sup == "" and all("of the time" in t for t in axes) for _, sup, axes in saved)
    code, out, err = _run(capsys, "demo", "--quick", "--out", tmp_path / "x", "--nlive", "30")
    assert code == 2 and "takes only --out, --seed, --format, --dpi and --no-title" in err


def test_demo_example_draws_its_figures_in_the_formats_asked_without_titles(tmp_path, capsys,
                                                                               saved):
    """The full demo, tiny (one 20-s run, 300 steps: not converged), through the command:
    every figure in PDF and SVG without a title, report.md showing the SVGs, the chain's
    non-convergence said once (the demo's own warning), not once per untitled figure."""
    code, out, err = _run(capsys, "demo", "--out", tmp_path / "d", "--motion-gains", "1",
                          "--duration", "20", "--max-steps", "300", "--nlive", "30",
                          "--no-title", "--format", "pdf", "--format", "svg", "-q")
    assert code == 0, err
    figures = tmp_path / "d" / "figures"
    names = ("traces", "delta_abs_FD_k1", "pair")
    assert sorted(p.name for p in figures.iterdir()) == sorted(
        f"{n}.{f}" for n in names for f in ("pdf", "svg"))
    for n in names:
        assert _is_pdf(figures / f"{n}.pdf")
        text = _svg_text(figures / f"{n}.svg")
        assert "converged" not in text and "draws" not in text and "task FD" not in text
    assert all(sup == "" and not [t for t in axes if "of the time" not in t]
               for _, sup, axes in saved)
    report = (tmp_path / "d" / "report.md").read_text()
    assert "(figures/pair.svg)" in report and ".png)" not in report
    assert err.count("reached max_steps") == 1 and "figure's title" not in err


# --- replicate ------------------------------------------------------------------------------------
def test_replicate_writes_its_histograms_in_the_formats_asked_without_title(tmp_path, capsys,
                                                                           monkeypatch):
    _run_here(monkeypatch)
    argv = ["replicate", "--realizations", "1", "--method", "fast", "--tasks", "FD",
            "--motion-gains", "1", "--remnant-fractions", "0", "--duration", "4",
            "--fit-option", "n_starts=1", "--fit-option", "profile_step=0.02", "--fits",
            "threshold"]
    code, out, err = _run(capsys, *argv, "--out", tmp_path / "r", "--format", "svg", "-q")
    assert code == 0, err
    assert "Estimated threshold" in _svg_text(tmp_path / "r" / "delta_abs_histograms.svg")
    code, out, err = _run(capsys, *argv, "--out", tmp_path / "r", "--no-title", "--format",
                          "pdf", "--format", "svg", "--format", "png", "--dpi", "60")
    assert code == 0, err
    text = _svg_text(tmp_path / "r" / "delta_abs_histograms.svg")
    assert "Estimated threshold" not in text and "Figs. 14/15" not in text
    assert _is_pdf(tmp_path / "r" / "delta_abs_histograms.pdf")
    png = mpimg.imread(tmp_path / "r" / "delta_abs_histograms.png")
    from bayespilot.campaign import load_results
    from bayespilot.plots import plot_threshold_histograms

    width = plot_threshold_histograms(load_results(tmp_path / "r"), fractions=[0.0],
                                      method="fast", title=False).get_figwidth()
    assert png.shape[1] == pytest.approx(60 * width, abs=2)
    assert "delta_abs_histograms.pdf and " in out and "delta_abs_histograms.png" in out


# --- diagnose --report ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def rec_stem(tmp_path_factory):
    """A short simulated run written as a lab would (as tests/test_cli_diagnose.py's)."""
    rec = simulate(task="FT", motion_gain=1.0, remnant_gain=0.06, seed=31, duration=30.0).recording
    meta = {k: v for k, v in rec.metadata.items() if k != "notes"}
    stem = tmp_path_factory.mktemp("diag") / "run"
    write_recording(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta),
                    stem)
    return stem


def test_diagnose_report_no_title(rec_stem, tmp_path, capsys, saved):
    rep = tmp_path / "rep"
    code, out, err = _run(capsys, "diagnose", rec_stem, "--bootstrap", "0", "--report", rep,
                          "--report-format", "svg", "--no-title")
    assert code == 0, err
    text = _svg_text(rep / "candidates.svg")
    assert "Candidates (decision" not in text and "motion-washout" in text
    assert _svg_text(rep / "residuals.svg")  # (parses)
    # the PNGs the page embeds: no title either
    pngs = [s for s in saved if s[0].endswith(".png")]
    assert {s[0].rsplit("/", 1)[1] for s in pngs} == {"candidates.png", "residuals.png"}
    assert all(sup == "" for _, sup, _ in pngs)
    assert not any(t.startswith("Candidates") for _, _, axes in pngs for t in axes)
    html = (rep / "report.html").read_text()
    assert "<h2>Candidates</h2>" in html  # (the page's headings stay)
    code, out, err = _run(capsys, "diagnose", rec_stem, "--no-title")
    assert code == 2 and "--no-title: needs --report" in err and out == ""


def test_result_reports_pass_title(monkeypatch, tmp_path):
    """DiagnosisResult.report and PooledDiagnosisResult.report hand ``title`` to the figures
    (write_report; plot_candidates, plot_runs, plot_shared_posterior)."""
    import bayespilot.diagnose.pooled as P
    import bayespilot.diagnose.report as R
    from bayespilot.diagnose import DiagnosisResult
    from bayespilot.diagnose.pooled import PooledDiagnosisResult

    seen = {}
    monkeypatch.setattr(R, "write_report", lambda res, d, **kw: seen.setdefault("single", kw))
    res = DiagnosisResult.__new__(DiagnosisResult)
    res.arrays = {}
    DiagnosisResult.report(res, tmp_path, formats=("pdf",), title=False)
    assert seen["single"] == {"formats": ("pdf",), "title": False}

    def spy(name):
        def draw(*a, title=True, **k):
            seen[name] = title
            fig, _ = plt.subplots()
            return fig
        return draw

    monkeypatch.setattr(R, "plot_candidates", spy("candidates"))
    monkeypatch.setattr(R, "plot_shared_posterior", spy("posterior"))
    monkeypatch.setattr(P, "plot_runs", spy("runs"))
    pooled = PooledDiagnosisResult.__new__(PooledDiagnosisResult)
    pooled.posterior = object()
    with pytest.raises(TypeError, match="title must be True or False"):
        PooledDiagnosisResult.report(pooled, tmp_path / "p", title="yes")
    assert not (tmp_path / "p").exists()
    monkeypatch.setattr(P.PooledDiagnosisResult, "to_json", lambda self, p: None)
    monkeypatch.setattr(P.PooledDiagnosisResult, "summary", lambda self: "")
    pooled.runs, pooled.ranking, pooled.units, pooled.physics = [], [], {}, "none"
    pooled.mismatch, pooled.settings = False, {"alpha": 0.01, "level_per_candidate": 0.005}
    paths = PooledDiagnosisResult.report(pooled, tmp_path / "p", formats=("svg",), title=False)
    assert seen["candidates"] is False and seen["runs"] is False and seen["posterior"] is False
    assert paths["runs_svg"].is_file() and paths["html"].is_file()
    PooledDiagnosisResult.report(pooled, tmp_path / "p")
    assert seen["candidates"] is True and seen["runs"] is True and seen["posterior"] is True


def _fake_pooled(n_runs=4):
    ranking = [SimpleNamespace(physics=p, testable=True) for p in NAMES[:4]]
    runs = [{"source": f"recs/s1_run{j}.csv",
             "delta_neg_log_lik": {c.physics: 10.0 + j - i for i, c in enumerate(ranking)}}
            for j in range(n_runs)]
    return SimpleNamespace(ranking=ranking, runs=runs, physics=NAMES[0])


def test_plot_runs_takes_title_and_figsize():
    from bayespilot.diagnose.pooled import plot_runs

    res = _fake_pooled()
    own = f"Each run's share (decision: {NAMES[0]})"
    assert plot_runs(res).axes[0].get_title() == own
    fig = plot_runs(res, title=False)
    assert fig.axes[0].get_title() == "" and fig._suptitle is None
    assert plot_runs(res, title="Fig. 4").axes[0].get_title() == "Fig. 4"
    with pytest.raises(TypeError, match="title must be True"):
        plot_runs(res, title=1)
    fig, ax = plt.subplots()
    with pytest.raises(ValueError, match="figsize"):
        plot_runs(res, ax=ax, figsize=(3.5, 3))
    # at a column's width: no layout warning; the legend, the title and every label on the
    # figure; the bars keep most of the width
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fig = plot_runs(res, figsize=(3.5, 3.2))
        fig.canvas.draw()
    assert tuple(fig.get_size_inches()) == (3.5, 3.2)
    r = fig.canvas.get_renderer()
    box = fig.get_tightbbox(r)
    assert box.x0 >= -0.01 and box.y0 >= -0.01 and box.x1 <= 3.51 and box.y1 <= 3.21
    ax = fig.axes[0]
    assert ax.get_position().width * 3.5 > 1.5
    assert ax.get_legend().get_window_extent(r).y1 < ax.get_window_extent(r).y0
    titles = [ax.get_title(loc) for loc in ("left", "center", "right")]
    assert own.replace(" ", "") in [t.replace("\n", "").replace(" ", "") for t in titles]


# --- diagnose-batch -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def lone(tmp_path_factory):
    """One 20-s run of subject s9, alone in its folder."""
    folder = tmp_path_factory.mktemp("lone")
    rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.15, seed=9,
                   duration=20.0).recording
    write_recording(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task,
                              {"subject": "s9"}), folder / "s9-run1")
    return folder


def test_diagnose_batch_formats_dpi_and_no_title(lone, tmp_path, capsys, monkeypatch, saved):
    _run_here(monkeypatch)
    out = tmp_path / "b"
    code, stdout, err = _run(capsys, "diagnose-batch", lone, "--out", out, "--bootstrap", "0",
                             "--reports", "--no-title", "--format", "svg", "--format", "png",
                             "--dpi", "50")
    assert code == 0, err
    text = _svg_text(out / "summary.svg")
    assert "every candidate's p-value" not in text and "s9-run1" in text
    assert not (out / "summary.pdf").exists()
    png = mpimg.imread(out / "summary.png")
    assert png.shape[1] == pytest.approx(50 * 7.5, abs=2)
    # each report: its PNGs (the page embeds them) and the SVGs beside them, untitled
    report = out / "s9-run1"
    assert (report / "candidates.png").is_file() and (report / "residuals.svg").is_file()
    assert "Candidates (decision" not in _svg_text(report / "candidates.svg")
    assert not (report / "candidates.pdf").exists()
    assert all(sup == "" and not [t for t in axes if "decision" in t or "p-value" in t]
               for _, sup, axes in saved)
    assert f"{out / 'summary.svg'}, {out / 'summary.png'}" in stdout
    # again with other figure options: the finished diagnosis's report is not redrawn (its
    # traces are not kept), and that is said; the summary in the new format alone
    code, stdout, err = _run(capsys, "diagnose-batch", lone, "--out", out, "--bootstrap", "0",
                             "--reports", "--format", "pdf")
    assert code == 0, err
    assert "1 report(s) of diagnoses finished before are left as they were drawn" in err
    assert "s9-run1" in err and not (report / "candidates.pdf").exists()
    assert (out / "summary.pdf").is_file()
    assert not (out / "summary.png").exists() and not (out / "summary.svg").exists()
    # the same options twice (the defaults: the command's --dpi is a number, the batch's
    # default None, and dpi does not reach a report): nothing said of the reports
    for _ in range(2):
        code, stdout, err = _run(capsys, "diagnose-batch", lone, "--out", tmp_path / "again",
                                 "--bootstrap", "0", "--reports")
        assert code == 0, err
    assert "left as they were drawn" not in err and "except for" not in stdout


def test_diagnose_batch_refuses_bad_figure_options_before_running(lone, tmp_path):
    from bayespilot.diagnose.batch import diagnose_batch

    for kw, error, match in (({"title": "no"}, TypeError, "title must be True or False"),
                             ({"formats": ()}, ValueError, "formats must be one or more"),
                             ({"formats": ("eps",)}, ValueError, "got eps"),
                             ({"dpi": 0}, ValueError, "dpi must be"),
                             # (the cluster options too, as run_campaign and fit_batch check
                             # them: they were found only after every recording was read)
                             ({"workers": 0}, ValueError, "workers must be a positive integer"),
                             ({"workers": 1, "scheduler": "tcp://127.0.0.1:1"}, ValueError,
                              "do not give it with scheduler"),
                             ({"connect_timeout": 0}, ValueError,
                              "connect_timeout must be a positive")):
        with pytest.raises(error, match=match):
            diagnose_batch([str(lone / "s9-run1")], tmp_path / "never", **{"workers": 1, **kw})
    assert not (tmp_path / "never").exists()


def _results(folder, n):
    """``n`` result files in ``folder`` as a batch writes them (the diagnosis as far as the
    summary reads it) and their tasks."""
    from bayespilot.diagnose.batch import DiagnoseTask

    tasks = []
    for i in range(n):
        key = f"s{i:03d}-run1"
        tasks.append(DiagnoseTask(key, (f"{key}.csv",), None, "FD", 1.0))
        d = {"physics": "none", "mismatch": False, "chosen": None,
             "settings": {"level_per_candidate": 0.002},
             "ranking": [{"physics": p, "p_value": 0.3, "testable": True} for p in NAMES]}
        (folder / f"{key}.json").write_text(json.dumps({"key": key, "diagnosis": d}))
    return tasks


@pytest.mark.parametrize("n", [40, 60, 150])
def test_batch_summary_names_every_diagnosis(tmp_path, monkeypatch, n):
    """summary.png of a batch beyond a page's diagnoses (plot_batch's own size names every
    k-th past about 55) grows so that every diagnosis is named: its SVG has every key; a
    batch a page holds keeps plot_batch's own size."""
    import bayespilot.diagnose.report as R
    from bayespilot.diagnose.batch import write_summary
    from bayespilot.plots import PAGE_HEIGHT

    real = R.plot_batch
    drawn = []

    def spy(*a, **k):
        fig = real(*a, **k)
        drawn.append((k.get("figsize"), fig.get_figheight(), len(fig.axes[0].get_yticks())))
        return fig

    monkeypatch.setattr(R, "plot_batch", spy)
    tasks = _results(tmp_path, n)
    write_summary(tasks, tmp_path)  # (diagnose_batch's call with its defaults)
    figsize, height, named = drawn[0]
    assert named == n and (tmp_path / "summary.png").is_file()
    write_summary(tasks, tmp_path, formats=("svg",), title=False)
    assert drawn[1][2] == n
    text = _svg_text(tmp_path / "summary.svg")
    assert all(f"{t.key}: none" in text for t in tasks)
    if n <= 50:
        assert figsize is None and height <= PAGE_HEIGHT
    else:
        assert PAGE_HEIGHT < height <= 60.0  # (batch.SUMMARY_MAX_HEIGHT)

"""Tests of the second mutation audit's survivors (/work/audit_mutation2.md) and of the two bugs
it found: each test fails with its mutant (or before its fix) and passes on the code.

The batch's tasks run in this process (tests/test_batch.py's ``_run_here``); the recordings are
the other test modules' fixtures (short simulated runs), imported here.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from bayespilot.batch import _condition_rows, fit_batch
# (the other modules' fixtures and helpers: tiny recordings, the batch's tasks run here, the
# cluster loop without a cluster)
from test_batch import QUIET, _run_here, recs  # noqa: F401 - recs: the fixture
from test_campaign import _stub_task, fake_cluster  # noqa: F401 - fake_cluster: the fixture
from test_report_figures import washout  # noqa: F401 - the fixture


# --- bug 1: figure_options and numpy's bool ------------------------------------------------------
def test_figure_options_take_a_numpy_bool_title():
    """numpy's bool is a bool (as plots._title_text takes it): figure_options refused it under
    numpy 2, whose type is named "bool", not "bool_"; a number or None is still refused."""
    from bayespilot._figstyle import figure_options

    assert figure_options(np.False_, "png", None) == {"title": False, "formats": ("png",),
                                                     "dpi": None}
    got = figure_options(np.bool_(True), ["svg"], 300)
    assert got["title"] is True and type(got["title"]) is bool
    for bad in (1, 0, np.int64(1), None, "yes"):
        with pytest.raises(TypeError, match="title must be True or False"):
            figure_options(bad, "png", None)


def test_fit_batch_takes_a_numpy_bool_title(recs, tmp_path, monkeypatch):
    """fit_batch(title=np.False_) runs (it was refused before the fits) and draws the summary
    figure without a title, as title=False does."""
    import matplotlib.pyplot as plt

    import bayespilot.batch as B

    _run_here(monkeypatch)
    titles = []
    real = B._plot_summary

    def spy(*args, **kwargs):
        fig = real(*args, **kwargs)
        titles.append(fig.get_suptitle())
        return fig

    monkeypatch.setattr(B, "_plot_summary", spy)
    summary = fit_batch(recs[:1], tmp_path / "out", title=np.False_, **QUIET)
    assert (summary.completed, summary.failed) == (1, 0)
    assert (tmp_path / "out" / "summary.png").is_file()
    assert titles == [""]
    plt.close("all")


# --- bug 2 and P05: plot_frequency_response's title on given axes ---------------------------------
def test_describing_functions_on_given_axes_have_no_title_of_their_own(washout):
    """The docstring: title=True draws none on given axes (the caller's figure).  The column
    loop's variable shadowed ``title``, so the default title was drawn over them; numpy's
    True is True."""
    import matplotlib.pyplot as plt

    from bayespilot.diagnose import report as R

    for title in (True, np.True_, False, ""):
        fig, axes = plt.subplots(2, 2)
        assert R.plot_frequency_response(washout, axes, title=title) is fig
        assert not fig.get_suptitle(), title
        # (the columns' headings stay: they name the panels)
        assert [axes[0, c].get_title() for c in (0, 1)] == [
            r"visual channel $H_\mathrm{v} = u/e$",
            r"motion channel $H_\mathrm{m} = u/\ddot\theta_\mathrm{m}$"]
        plt.close(fig)
    fig = R.plot_frequency_response(washout)  # (a new figure: its default title)
    assert fig.get_suptitle() == "Describing functions at the forcing frequencies"
    plt.close(fig)


def test_no_describing_function_on_given_axes_takes_only_the_callers_title(washout):
    """Without a describing function (here the result's taken out) the first given axes say
    so; a title only for a caller's str, none for True (numpy's too)."""
    import matplotlib.pyplot as plt

    from bayespilot.diagnose import report as R

    bare = dataclasses.replace(washout, arrays={k: v for k, v in washout.arrays.items()
                                                if not k.startswith("df_")})
    for title, expected in ((True, ""), (np.True_, ""), (False, ""), ("Figure 5", "Figure 5")):
        fig, axes = plt.subplots(2, 2)
        assert R.plot_frequency_response(bare, axes, title=title) is fig
        assert fig.get_suptitle() == expected, title
        assert axes[0, 0].texts[0].get_text().startswith("No describing function")
        plt.close(fig)


def test_describing_functions_on_given_axes_take_the_callers_title(washout):
    """P05: on given axes a str title is the figure's title (the caller's "Figure 5" was kept
    only because the shadowed ``title`` was a column heading, a str, too)."""
    import matplotlib.pyplot as plt

    from bayespilot.diagnose import report as R

    fig, axes = plt.subplots(2, 2)
    R.plot_frequency_response(washout, axes, title="Figure 5")
    assert fig.get_suptitle() == "Figure 5"
    plt.close(fig)


def test_numpy_true_is_true_for_the_posterior_figures():
    """np.True_ is title=True (plots._title_text takes it so): plot_pair draws no title on given
    axes (it drew its own there, as for a caller's str), and an unconverged posterior's figure
    keeps its own title, which says so: no ConvergenceWarning (it said the title was
    "replaced")."""
    import warnings

    import matplotlib.pyplot as plt

    from bayespilot.plots import plot_chains, plot_pair
    from bayespilot.sample import ConvergenceWarning
    from test_plots_figures import _posterior, _titles

    post = _posterior()
    assert not post.converged
    for title in (True, np.True_):
        fig, axes = plt.subplots(3, 3)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert plot_pair(post, ax=axes, title=title) is fig
            chains = plot_chains(post, title=title)
            assert "not converged" in " ".join(_titles(chains, chains.axes))
        assert not fig.get_suptitle(), title
    fig, axes = plt.subplots(3, 3)  # (a str: the caller's title, on given axes too)
    with pytest.warns(ConvergenceWarning, match="is replaced"):
        plot_pair(post, ax=axes, title="Figure 4")
    assert fig.get_suptitle() == "Figure 4"
    plt.close("all")


# --- P01: title="" is no title --------------------------------------------------------------------
def test_an_empty_title_is_no_title_on_the_fit_figures():
    """P01: title="" is no title, as False: here no default panel titles ("fit 1", ...)."""
    import matplotlib.pyplot as plt

    from bayespilot.fit.figures import plot_step_two
    from test_plots_figures import _paper_fit, _titles

    fits = [_paper_fit(seed=s) for s in range(2)]
    fig = plot_step_two(fits, title=True)
    fig.canvas.draw()
    assert {"fit 1", "fit 2"} <= set(_titles(fig, fig.axes))  # (the titles "" drops)
    for title in (False, ""):
        fig = plot_step_two(fits, title=title)
        fig.canvas.draw()
        assert _titles(fig, fig.axes) == [], title
    plt.close("all")


# --- F02, F05: figure_options' formats, save_figure's file name -----------------------------------
def test_figure_options_keep_each_format_once_in_order():
    """F02: a format asked twice is written once (the docstring: each once, in the order
    given)."""
    from bayespilot._figstyle import figure_options

    assert figure_options(True, ["pdf", "png", "pdf"], None)["formats"] == ("pdf", "png")
    assert figure_options(True, ("svg", "svg"), None)["formats"] == ("svg",)


def test_save_figure_names_a_path_without_a_suffix_as_savefig_does(tmp_path):
    """F05: "fig." gets the default format's suffix as matplotlib's savefig gives it
    ("fig.png"), not "fig..png"; "other" gets it too."""
    import matplotlib
    import matplotlib.pyplot as plt

    from bayespilot._figstyle import save_figure

    fig = plt.figure()
    ref, mine = tmp_path / "ref", tmp_path / "mine"
    ref.mkdir()
    mine.mkdir()
    for name in ("fig.", "other"):
        fig.savefig(ref / name)
        save_figure(fig, mine / name)
    plt.close(fig)
    fmt = matplotlib.rcParams["savefig.format"]
    assert sorted(p.name for p in mine.iterdir()) == sorted(p.name for p in ref.iterdir()) \
        == sorted([f"fig.{fmt}", f"other.{fmt}"])


def test_save_figure_writes_a_file_object_at_the_dpi_asked(tmp_path):
    """F07: a file object is written at ``dpi`` too (not at rcParams' resolution): the PNG's
    size is the figure's size times the dpi, as savefig's."""
    import io
    import struct

    import matplotlib.pyplot as plt

    from bayespilot._figstyle import save_figure

    def size(data):  # (a PNG's IHDR: width, height, big-endian, after the 16-byte header)
        assert data[:8] == b"\x89PNG\r\n\x1a\n"
        return struct.unpack(">II", data[16:24])

    fig = plt.figure(figsize=(4.0, 3.0))
    mine, ref = io.BytesIO(), io.BytesIO()
    save_figure(fig, mine, dpi=50)
    fig.savefig(ref, dpi=50, format="png")
    plt.close(fig)
    assert size(mine.getvalue()) == size(ref.getvalue()) == (200, 150)


# --- B12, B20: fit_batch's resume rule and the conditions table -----------------------------------
def test_a_json_file_of_the_key_that_is_no_fit_is_run_not_a_conflict(recs, tmp_path,
                                                                      monkeypatch):
    """B12: a <key>.json with the key but no fit (cut short; no command's result, so the
    refusal of another batch's folder leaves it) is a task to run, as _done's docstring says,
    not a ResultConflictError of "a fit from other recordings"."""
    _run_here(monkeypatch)
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.json").write_text(json.dumps({"key": "a", "settings": {"method": "fast"},
                                            "recording_digests": ["x"],
                                            "recording_metadata": [{}]}))
    summary = fit_batch(recs[:1], out, **QUIET)
    assert (summary.completed, summary.skipped, summary.failed) == (1, 0, 0)
    stored = json.loads((out / "a.json").read_text())
    assert "fit_threshold" in stored and stored["recording_digests"] != ["x"]


def _result(key, delta_abs, nll=10.0, nll_none=12.0, delta_bic=1.0):
    return {"key": key, "subject": "s1", "task": "FD", "motion_gain": 1.0,
            "fit_threshold": {"params": {"delta_abs": delta_abs}, "neg_log_lik": nll},
            "fit_none": {"neg_log_lik": nll_none},
            "information_criteria": {"delta_bic": delta_bic}}


def test_condition_statistics_of_three_runs_against_numpy():
    """B20, B34: a condition of three runs, the largest first, skewed: its median is not the
    mean, its max is not the last run's."""
    deltas = [0.010, 0.001, 0.002]
    (row,) = _condition_rows([_result(k, d) for k, d in zip("abc", deltas)])
    assert row["n_runs"] == 3
    assert row["delta_abs_median"] == np.median(deltas) == 0.002  # (the mean: 0.00433)
    assert (row["delta_abs_min"], row["delta_abs_max"]) == (min(deltas), max(deltas))


# --- C03, C08: campaign's warnings and progress bar -----------------------------------------------
def test_each_kind_counts_recordings_not_warnings():
    """C03: one recording that warned twice of one kind is one recording."""
    from bayespilot.campaign import _say_each_kind

    with pytest.warns(RuntimeWarning) as said:
        _say_each_kind({"EstimateOnBoundWarning": [("a", "K_v at its bound"),
                                                   ("a", "tau_v at its bound"),
                                                   ("b", "K_v at its bound")]},
                       "recording(s)")
    (w,) = said
    assert str(w.message).startswith(
        "EstimateOnBoundWarning in 2 recording(s) (a, b), e.g. a: K_v at its bound (2 "
        "different messages in all); ")


def test_each_kind_shows_the_message_most_recordings_share():
    """Review: the example was the first recording's alphabetically first message (a
    diagnosis without motion warns once per candidate: one candidate's h_head was shown, the
    base model's message every run shares was not)."""
    from bayespilot.campaign import _say_each_kind

    with pytest.warns(RuntimeWarning) as said:
        _say_each_kind({"SilentChannelWarning": [("a", "candidate A: h_head"),
                                                 ("a", "base: delta_abs"),
                                                 ("b", "candidate B: K_ot"),
                                                 ("b", "base: delta_abs")]},
                       "diagnosis(es)")
    (w,) = said
    assert str(w.message) == ("SilentChannelWarning in 2 diagnosis(es) (a, b), e.g. a: base: "
                              "delta_abs (3 different messages in all); each result file lists "
                              "its warnings under 'warnings'")
    with pytest.warns(RuntimeWarning) as said:  # (one message: nothing more said)
        _say_each_kind({"X": [("b", "m"), ("a", "m")]}, "fit(s)")
    assert str(said[0].message) == ("X in 2 fit(s) (a, b), e.g. a: m; each result file lists "
                                    "its warnings under 'warnings'")


def test_run_keyed_bar_counts_the_tasks_done_before(tmp_path, monkeypatch, fake_cluster):
    """C08: progress=True: the bar starts at the tasks done before this call (skipped) and
    ends at total, as the lines do."""
    import tqdm.auto

    import bayespilot.campaign as C

    bars = []

    class Spy(tqdm.auto.tqdm):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            bars.append(self)

    monkeypatch.setattr(tqdm.auto, "tqdm", Spy)
    tasks = [(f"k{x:02d}", _stub_task, (x,), {}) for x in range(2, 6)]
    done, errors = C.run_keyed(tasks, tmp_path, total=6, skipped=2, scheduler=None,
                               workers=1, progress=True, connect_timeout=1.0)
    assert (done, errors) == (4, {})
    (bar,) = bars
    assert (bar.n, bar.total) == (6, 6)


# --- K05: fit-batch's scope sentence --------------------------------------------------------------
def test_fit_batch_says_the_one_recording_an_earlier_run_left_in_the_tables(
        recs, tmp_path, monkeypatch, capsys):
    """K05/K07: the tables cover every result in DIR made with these settings; the command
    says how many an earlier run made, one among them, and nothing when all are this call's."""
    from bayespilot.cli import main

    _run_here(monkeypatch)
    out = tmp_path / "fits"
    argv = ["--out", str(out), "--method", "fast", "--workers", "1"]
    run1, run2 = recs[:2]  # (two runs of s1 at K_theta = 1: one condition)
    assert main(["fit-batch", run1, *argv]) == 0
    assert "an earlier run fitted" not in "".join(capsys.readouterr())
    assert main(["fit-batch", run2, *argv]) == 0
    said = "".join(capsys.readouterr())
    assert f"(with 1 recording an earlier run fitted in {out} with these settings)" in said
    assert main(["fit-batch", run1, run2, *argv]) == 0
    assert "an earlier run fitted" not in "".join(capsys.readouterr())  # (both this call's)


# --- S02b, S04b, S05: TrackingTask's forcing_scale check ------------------------------------------
@pytest.mark.parametrize("change", ["phase", "base_frequency", "n", "none"])
def test_a_preset_target_differing_in_one_field_only_must_drop_its_scale(change):
    """S02b, S04b, S05: a target that differs from Table 2's in its phases only (re-drawn
    phases: a lab's usual variant), its base frequency only or its lines only is not Table 2's
    forcing; Table 2's own target, rebuilt field by field, keeps the scale."""
    from bayespilot.forcing import Multisine
    from bayespilot.simulate import TrackingTask

    paper = TrackingTask.paper("FD", 1.0)
    t = paper.target
    fields = {"base_frequency": t.base_frequency, "n": np.asarray(t.n),
              "amplitude": np.asarray(t.amplitude), "phase": np.asarray(t.phase)}
    if change != "none":
        fields[change] = {"phase": fields["phase"] + 0.5,
                          "base_frequency": fields["base_frequency"] * 1.5,
                          "n": fields["n"] + 1}[change]
    mine = Multisine(fields["base_frequency"], fields["n"], fields["amplitude"],
                     fields["phase"])
    if change == "none":
        assert dataclasses.replace(paper, target=mine).forcing_scale == "paper_simulation"
        return
    with pytest.raises(ValueError, match=r"the target is not; give forcing_scale=None"):
        dataclasses.replace(paper, target=mine)
    assert dataclasses.replace(paper, target=mine, forcing_scale=None).forcing_scale is None

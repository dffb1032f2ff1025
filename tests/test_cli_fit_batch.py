"""Tests of ``bayespilot fit-batch``, the command line of :func:`bayespilot.batch.fit_batch`.

The command runs in this process (``main([...])``) with the batch's cluster loop
(``campaign.run_keyed``) replaced by one that runs the tasks here (tests/test_batch.py's
helper), on 30-s simulated
recordings fitted by the fast method: the command's part (options, refusals, exit codes,
the printed table, the files named) is what is tested; the batch itself is
tests/test_batch.py's.  The fits are checked against ``bayespilot fit`` run on the same
recording with the seed the batch recorded.
"""

from __future__ import annotations

import csv
import io
import json
import warnings

import pytest

from bayespilot.cli import main
# (the batch's tests' helpers: its tasks run in this process; its cluster loop made to fail
# the test if it starts)
from test_batch import _nothing_runs, _run_here

#: The recordings of the module's folder, by stem: (subject, K_theta, seed).
RUNS = {"s1-run1": ("s1", 1.0, 1), "s1-run2": ("s1", 1.0, 2), "s2-run1": ("s2", 0.5, 3)}


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A folder of three 30-s FD recordings with subjects: two runs of s1 at K_theta = 1,
    one of s2 at 0.5 (two conditions)."""
    d = tmp_path_factory.mktemp("recs")
    for stem, (subject, gain, seed) in RUNS.items():
        assert main(["simulate", "--subject", subject, "--motion-gain", str(gain),
                     "--remnant-fraction", "0.15", "--duration", "30", "--seed", str(seed),
                     "-o", str(d / stem), "-q"]) == 0
    return d


def _rows(text: str) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(text)))


@pytest.fixture(scope="module")
def done(folder, tmp_path_factory):
    """The folder fitted once by the command (fast method, -q): (out, exit code, stdout,
    stderr)."""
    mp = pytest.MonkeyPatch()
    out = tmp_path_factory.mktemp("fits") / "fits"
    try:
        _run_here(mp)
        cap = _Capture()
        with cap:
            code = main(["fit-batch", str(folder), "--out", str(out), "--method", "fast",
                         "--workers", "1", "-q"])
    finally:
        mp.undo()
    return out, code, cap.out, cap.err


class _Capture:
    """stdout and stderr of a block (capsys is function-scoped; the batch is run once)."""

    def __enter__(self):
        import contextlib

        self._out, self._err = io.StringIO(), io.StringIO()
        self._stack = contextlib.ExitStack()
        self._stack.enter_context(contextlib.redirect_stdout(self._out))
        self._stack.enter_context(contextlib.redirect_stderr(self._err))
        return self

    def __exit__(self, *exc):
        self._stack.close()
        self.out, self.err = self._out.getvalue(), self._err.getvalue()


def test_prints_the_per_condition_table_the_batch_wrote(done):
    out, code, stdout, err = done
    assert code == 0, err
    # -q: the table alone, exactly conditions.csv
    assert stdout == (out / "conditions.csv").read_text(encoding="utf-8")
    rows = _rows(stdout)
    assert [(r["subject"], r["task"], float(r["motion_gain"]), int(r["n_runs"]))
            for r in rows] == [("s1", "FD", 1.0, 2), ("s2", "FD", 0.5, 1)]
    assert [r["label"] for r in rows] == ["s1, FD, K_theta = 1", "s2, FD, K_theta = 0.5"]
    runs = _rows((out / "summary.csv").read_text(encoding="utf-8"))
    assert [r["key"] for r in runs] == sorted(RUNS)
    assert all(r["error"] == "" and r["decision"] == "" for r in runs)  # (no --compare)
    # the table's numbers are the runs': s1's two runs summed, its delta_abs their median
    s1 = [r for r in runs if r["subject"] == "s1"]
    assert float(rows[0]["sum_delta_neg_log_lik"]) == pytest.approx(
        sum(float(r["neg_log_lik_none"]) - float(r["neg_log_lik"]) for r in s1), rel=1e-9)
    assert float(rows[0]["sum_delta_bic"]) == pytest.approx(
        sum(float(r["delta_bic"]) for r in s1), rel=1e-9)
    assert float(rows[0]["delta_abs_median"]) == pytest.approx(
        sum(float(r["delta_abs"]) for r in s1) / 2, rel=1e-9)
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [f"{k}.json" for k in RUNS] + ["conditions.csv", "summary.csv", "summary.png"])
    assert (out / "summary.png").stat().st_size > 1000


def test_a_recorded_seed_repeats_the_fit_with_bayespilot_fit(done, folder, tmp_path):
    """The --seed help's promise: 'bayespilot fit REC --seed' with a result's settings.seed
    and the same options repeats that recording's fits, with and without threshold."""
    out, code, _, err = done
    assert code == 0, err
    result = json.loads((out / "s2-run1.json").read_text(encoding="utf-8"))
    seed = result["settings"]["seed"]
    assert result["settings"]["batch_seed"] == 0 and seed != 0
    for flags, which in (([], "fit_threshold"), (["--no-threshold"], "fit_none")):
        path = tmp_path / f"{which}.json"
        assert main(["fit", str(folder / "s2-run1"), "--method", "fast", "--seed", str(seed),
                     *flags, "--json", str(path), "-q"]) == 0
        alone = json.loads(path.read_text(encoding="utf-8"))
        assert alone["params"] == result[which]["params"], which
        assert alone["neg_log_lik"] == result[which]["neg_log_lik"], which


def test_a_rerun_skips_the_finished_and_says_where_it_wrote(done, folder, monkeypatch, capsys):
    out, code, stdout, _ = done
    assert code == 0
    _run_here(monkeypatch)
    before = {p.name: p.read_bytes() for p in out.glob("*.json")}
    assert main(["fit-batch", str(folder), "--out", str(out), "--method", "fast",
                 "--workers", "1"]) == 0
    said, err = capsys.readouterr()
    # all done: nothing fitted again (a result written again has another elapsed_seconds)
    assert {p.name: p.read_bytes() for p in out.glob("*.json")} == before
    lines = said.splitlines()
    assert lines[0].startswith("3 recording(s) to fit with and without threshold (the fast "
                               "estimator) on 1 local worker(s) -> ")
    assert lines[1].startswith("3 recordings: 0 run, 3 already done, 0 failed")
    assert "\n".join(lines[2:-1]) + "\n" == stdout  # the same table
    assert lines[-1] == (f"wrote {out / 'conditions.csv'} (one row per subject, task and "
                         f"K_theta), {out / 'summary.csv'} (one row per recording), "
                         f"{out / 'summary.png'} and one <key>.json per recording")


def test_the_summary_figure_in_the_formats_asked_for(done, folder, tmp_path, monkeypatch,
                                                     capsys):
    """--format (repeatable), --dpi and --no-title reach the summary figure; a rerun that
    asks for other formats removes the figure of a format not asked for (it showed the
    folder's results as they were)."""
    import shutil

    import matplotlib.image

    out = tmp_path / "fits"
    shutil.copytree(done[0], out)
    _run_here(monkeypatch)
    assert main(["fit-batch", str(folder), "--out", str(out), "--method", "fast", "--format",
                 "pdf", "--format", "png", "--dpi", "50", "--no-title", "--workers", "1"]) == 0
    said = capsys.readouterr().out.splitlines()[-1]
    assert said.endswith(f"{out / 'summary.csv'} (one row per recording), "
                         f"{out / 'summary.pdf'}, {out / 'summary.png'} and one <key>.json "
                         f"per recording")
    assert (out / "summary.pdf").read_bytes()[:5] == b"%PDF-"
    # 50 dpi: the figure's 4.8 x 4.0 in (two conditions) as 240 x 200 pixels
    assert matplotlib.image.imread(out / "summary.png").shape[:2] == (200, 240)
    assert main(["fit-batch", str(folder), "--out", str(out), "--method", "fast", "--format",
                 "svg", "--workers", "1", "-q"]) == 0
    assert sorted(p.name for p in out.glob("summary.*")) == ["summary.csv", "summary.svg"]


def test_a_sampling_that_fails_is_exit_1_and_the_next_run_samples_it(
        folder, tmp_path, monkeypatch, capsys):
    import functools
    import sys

    module = sys.modules["bayespilot.sample"]
    real = module.sample

    @functools.wraps(real)  # (its signature: the batch checks the options by it)
    def sample(*args, **kwargs):
        raise FloatingPointError("the chain diverged (made to fail by the test)")

    monkeypatch.setattr(module, "sample", sample)
    _run_here(monkeypatch)
    out = tmp_path / "fits"
    argv = ["fit-batch", str(folder / "s2-run1"), "--out", str(out), "--method", "fast",
            "--posterior", "--max-steps", "30", "--workers", "1", "-q"]
    assert main(argv) == 1
    err = capsys.readouterr().err.splitlines()
    assert err[-1] == (f"bayespilot: error: 1 of 1 recordings' posteriors could not be "
                       f"sampled (why: 'posterior_error' in {out}/<key>.json; their fits are "
                       f"kept); run the same command again to sample them again")
    assert any("the posterior could not be sampled for 1 recording(s) (s2-run1)" in line
               for line in err)
    monkeypatch.setattr(module, "sample", real)
    assert main(argv) == 0  # (sampled now: 30 steps, not converged, said as a warning)
    (row,) = _rows((out / "summary.csv").read_text(encoding="utf-8"))
    assert row["posterior_error"] == "" and row["delta_abs_posterior_median"] != ""
    assert (out / "s2-run1.nc").is_file()


def test_a_folder_holding_another_settings_result_is_exit_2(done, folder, monkeypatch, capsys):
    out, code, _, _ = done
    assert code == 0
    _nothing_runs(monkeypatch)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    code = main(["fit-batch", str(folder), "--out", str(out), "--method", "fast", "--seed", "3",
                 "--workers", "1", "-q"])
    stdout, err = capsys.readouterr()
    assert code == 2 and stdout == ""
    assert err.startswith(f"bayespilot: error: {out / 's1-run1.json'} holds a fit of s1-run1 "
                          f"from other settings: "), err
    assert "use another output folder or delete it" in err and len(err.splitlines()) == 1
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


@pytest.mark.parametrize("argv,said", [
    (["--noise", "ar"], "argument --noise: 'ar' (a prediction-error fit) goes with --method fast"),
    (["--method", "paper", "--noise", "ar"],
     "argument --noise: 'ar' (a prediction-error fit) goes with --method fast"),
    (["--method", "fast", "--iterate"],
     "argument --iterate: it repeats Steps II and III of --method paper"),
    (["--method", "fast", "--nlive", "50"],
     "argument --nlive: it sets the nested sampling of --compare; give --compare too, or "
     "leave --nlive out"),
    (["--compare", "--nlive", "10"], "argument --nlive: must be >= 20, got 10"),
    (["--workers", "1", "--scheduler", "tcp://127.0.0.1:9"],
     "give --scheduler (an existing cluster) or --workers (a local one), not both"),
    (["--scheduler", "tcp://host:8786/"], "not a dask scheduler address"),
    (["--method", "fast", "--max-steps", "50"],
     "argument --max-steps: it sets the chain of --posterior; give --posterior too, or leave "
     "--max-steps out"),
    (["--method", "fast", "--likelihood", "coloured"],
     "argument --likelihood: it sets the chain of --posterior; give --posterior too, or "
     "leave --likelihood out"),
    (["--posterior", "--max-steps", "0"], "argument --max-steps: must be >= 1, got 0"),
])
def test_options_that_do_not_go_together_are_exit_2(folder, tmp_path, monkeypatch, capsys,
                                                     argv, said):
    _nothing_runs(monkeypatch)
    code = main(["fit-batch", str(folder), "--out", str(tmp_path / "o"), *argv, "-q"])
    stdout, err = capsys.readouterr()
    assert code == 2 and stdout == ""
    assert err.startswith("bayespilot: error: ") and said in err, err
    assert not (tmp_path / "o").exists()


def test_fit_and_fit_batch_share_the_method_rules(folder, capsys):
    """fit's refusals are the same lines (one rule, _fit_method_rules)."""
    for argv, said in ((["--noise", "ar"], "'ar' (a prediction-error fit) goes with --method "
                                           "fast"),
                       (["--method", "fast", "--iterate"], "it repeats Steps II and III")):
        assert main(["fit", str(folder / "s1-run1"), *argv, "-q"]) == 2
        assert said in capsys.readouterr().err


def test_an_unreadable_recording_among_good_ones_is_named_and_nothing_runs(
        folder, tmp_path, monkeypatch, capsys):
    _nothing_runs(monkeypatch)
    bad = tmp_path / "broken"
    (tmp_path / "broken.csv").write_text("t,e,u\n0,1\n")
    (tmp_path / "broken.json").write_text((folder / "s1-run1.json").read_text())
    out = tmp_path / "o"
    code = main(["fit-batch", str(folder), str(bad), str(tmp_path / "missing"), "--out",
                 str(out), "--method", "fast", "-q"])
    stdout, err = capsys.readouterr()
    assert code == 2 and stdout == ""
    lines = err.splitlines()
    assert lines[0] == ("bayespilot: error: 2 of 5 recordings cannot be read; nothing was run:")
    assert str(bad) in lines[1] and str(tmp_path / "missing") in lines[2], err
    assert len(lines) == 3
    assert not out.exists()


def test_a_recording_the_tables_would_overwrite_is_refused_before_anything_runs(
        folder, tmp_path, monkeypatch, capsys):
    """conditions.csv is an output too: a recording named 'conditions' in --out is refused,
    naming it, even where its key (two stems 'conditions': a_conditions, recs_conditions)
    writes no <key>.json over its sidecar."""
    import shutil

    _nothing_runs(monkeypatch)
    for sub in ("a", "recs"):
        (tmp_path / sub).mkdir()
        for ext in (".csv", ".json"):
            shutil.copy(folder / f"s1-run{1 if sub == 'a' else 2}{ext}",
                        tmp_path / sub / f"conditions{ext}")
    recs = tmp_path / "recs"
    before = {p.name: p.read_bytes() for p in recs.iterdir()}
    code = main(["fit-batch", str(tmp_path / "a" / "conditions"), str(recs / "conditions"),
                 "--out", str(recs), "-q"])
    err = capsys.readouterr().err
    assert code == 2
    assert err == (f"bayespilot: error: argument --out: {recs / 'conditions.csv'} is the CSV "
                   f"of the recording REC {recs / 'conditions'}, which this command reads: "
                   f"writing it would destroy that input; give another file name\n")
    assert {p.name: p.read_bytes() for p in recs.iterdir()} == before


def test_a_failed_fit_is_exit_1_after_the_others_are_written(folder, tmp_path, monkeypatch,
                                                              capsys):
    import bayespilot.fit.fast as fast

    real = fast.fit_fast

    def fit_fast(rec, *args, **kwargs):
        if rec.motion_gain == 0.5:  # (s2-run1)
            raise FloatingPointError("the fit diverged (made to fail by the test)")
        return real(rec, *args, **kwargs)

    monkeypatch.setattr(fast, "fit_fast", fit_fast)
    _run_here(monkeypatch)
    out = tmp_path / "fits"
    code = main(["fit-batch", str(folder / "s1-run1"), str(folder / "s2-run1"), "--out",
                 str(out), "--method", "fast", "--workers", "1", "-q"])
    stdout, err = capsys.readouterr()
    assert code == 1
    assert err.splitlines()[-1] == (f"bayespilot: error: 1 of 2 recordings' fits failed "
                                    f"(messages in {out}/<key>.error.json); run the same "
                                    f"command again to retry them")
    assert (out / "s1-run1.json").is_file() and (out / "s2-run1.error.json").is_file()
    assert not (out / "s2-run1.json").exists()
    # the table of what finished is printed and written
    assert stdout == (out / "conditions.csv").read_text(encoding="utf-8")
    assert [(r["subject"], r["n_runs"]) for r in _rows(stdout)] == [("s1", "1")]
    runs = {r["key"]: r for r in _rows((out / "summary.csv").read_text(encoding="utf-8"))}
    assert "the fit diverged" in runs["s2-run1"]["error"] and runs["s1-run1"]["error"] == ""


def test_the_options_reach_the_batch(folder, tmp_path, monkeypatch, capsys):
    """What the command passes to fit_batch: the options as given (--nlive only with
    --compare, None when left out: the batch's default, so that a Python call's results
    resume the command's), progress lines off a terminal, and the batch's RuntimeWarnings
    (the fits' said once per kind) as the command's 'bayespilot: warning:' lines."""
    import bayespilot.batch
    from bayespilot.campaign import CampaignError

    seen = []

    def fit_batch(paths, out, **kwargs):
        seen.append((paths, out, kwargs))
        warnings.warn("EstimateOnBoundWarning in 1 recording(s) (s1-run1), e.g. s1-run1: "
                      "K_v on its bound", RuntimeWarning)
        raise CampaignError("stopped by the test")

    monkeypatch.setattr(bayespilot.batch, "fit_batch", fit_batch)
    out = tmp_path / "o"
    code = main(["fit-batch", str(folder / "s1-run1"), "--out", str(out), "--iterate",
                 "--oversample", "2", "--compare", "--nlive", "30", "--seed", "4",
                 "--workers", "1"])
    err = capsys.readouterr().err
    assert code == 1 and err.splitlines()[-1] == "bayespilot: error: stopped by the test", err
    assert ("bayespilot: warning: EstimateOnBoundWarning in 1 recording(s) (s1-run1), e.g. "
            "s1-run1: K_v on its bound") in err.splitlines()
    paths, got, kwargs = seen[0]
    assert paths == [str(folder / "s1-run1")] and str(got) == str(out)
    assert kwargs == {"method": "paper", "noise": "white", "iterate": True, "oversample": 2,
                      "compare": True, "nlive": 30, "seed": 4, "posterior": False,
                      "sample_options": None, "scheduler": None,
                      "workers": 1, "progress": "lines", "connect_timeout": 10.0,
                      "title": True, "formats": ("png",), "dpi": 200}
    main(["fit-batch", str(folder), "--out", str(out), "--method", "fast", "--noise", "ar",
          "-q"])
    paths, _, kwargs = seen[1]
    assert paths == [str(folder / s) for s in sorted(RUNS)]  # (the folder's recordings)
    assert (kwargs["method"], kwargs["noise"], kwargs["iterate"], kwargs["compare"],
            kwargs["nlive"], kwargs["seed"], kwargs["progress"], kwargs["workers"]) == (
        "fast", "ar", False, False, None, 0, False, None)
    # --posterior: only the chain's options given (the batch fills in sample's defaults,
    # those of bayespilot sample, so that a Python call's results resume the command's)
    for argv, options in ((["--likelihood", "coloured", "--max-steps", "500"],
                           {"likelihood": "coloured", "max_steps": 500}), ([], {})):
        main(["fit-batch", str(folder), "--out", str(out), "--posterior", *argv, "-q"])
        assert (seen[-1][2]["posterior"], seen[-1][2]["sample_options"]) == (True, options)


def test_a_posterior_is_the_one_bayespilot_sample_gives_with_the_recorded_seed(
        folder, tmp_path, monkeypatch, capsys):
    """--posterior: each recording's chain is `bayespilot sample REC --seed S` with the seed
    its result records and the same --max-steps (the same summary, number for number, and
    the same draws in DIR/<key>.nc); summary.csv has delta_abs's median and 90 % HDI."""
    import arviz
    import numpy as np

    _run_here(monkeypatch)
    out = tmp_path / "fits"
    rec = str(folder / "s2-run1")
    code = main(["fit-batch", rec, "--out", str(out), "--method", "fast", "--posterior",
                 "--max-steps", "30", "--workers", "1"])
    stdout, err = capsys.readouterr()
    assert code == 0, err
    lines = stdout.splitlines()
    assert lines[0].startswith("1 recording(s) to fit with and without threshold (the fast "
                               "estimator), with the posterior sampled by emcee (eq4 "
                               "likelihood, at most 30 steps), on 1 local worker(s) -> ")
    assert lines[-1].endswith("and one <key>.json and <key>.nc (its posterior) per recording")
    # the chain stopped at 30 steps: said once, as the command's warning line
    assert "bayespilot: warning: ConvergenceWarning in 1 recording(s) (s2-run1)" in err
    result = json.loads((out / "s2-run1.json").read_text(encoding="utf-8"))
    seed = result["settings"]["seed"]
    assert result["settings"]["sample_options"] == {"likelihood": "eq4", "max_steps": 30,
                                                    "min_steps": 30}
    alone = tmp_path / "alone"
    assert main(["sample", rec, "-o", str(alone) + ".nc", "--json", str(alone) + ".json",
                 "--seed", str(seed), "--max-steps", "30", "-q"]) == 0
    capsys.readouterr()
    alone_json = json.loads((tmp_path / "alone.json").read_text(encoding="utf-8"))
    summary = alone_json["summary"]
    assert result["posterior"]["summary"] == summary
    assert (result["posterior"]["converged"], result["posterior"]["steps"]) == (False, 30)
    assert (alone_json["converged"], alone_json["steps"]) == (False, 30)
    batch, single = (arviz.from_netcdf(str(f)) for f in (out / "s2-run1.nc",
                                                          tmp_path / "alone.nc"))
    for name in summary:
        np.testing.assert_array_equal(batch.posterior[name].values,
                                      single.posterior[name].values)
    (row,) = _rows((out / "summary.csv").read_text(encoding="utf-8"))
    assert float(row["delta_abs_posterior_median"]) == summary["delta_abs"]["median"]
    assert [float(row["delta_abs_posterior_hdi_low"]),
            float(row["delta_abs_posterior_hdi_high"])] == \
        summary["delta_abs"]["hdi_90"]
    assert row["converged"] == "False" and row["posterior_error"] == ""

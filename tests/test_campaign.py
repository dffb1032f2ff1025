"""Tests of bayespilot.campaign (the Monte Carlo study on dask), its CLI and its figure.

The campaign runs for real on a dask LocalCluster, with tiny fits (the fast
method, one start, a coarse profile) on 4-s runs without remnant, so the whole
file takes well under a minute.  Resumption is checked on the files: a job
that is skipped leaves its result file untouched (same mtime, same bytes).
summarise() is checked against statistics computed here with plain numpy.
"""

from __future__ import annotations

import csv
import json
import math
import time

import numpy as np
import pytest

import bayespilot
from bayespilot import presets
from bayespilot.campaign import (CampaignError, Job, load_results, paper_study, run_campaign,
                                 run_job, summarise, summary_markdown, write_summary_csv)
from bayespilot.cli import main

pytest.importorskip("distributed")

TINY = {"n_starts": 1, "profile_step": 0.02}


def _jobs(**kw):
    """Two jobs (with and without threshold) of one cell: FD, K_theta = 1, F_n = 0, 4-s run."""
    return paper_study(1, tasks=("FD",), motion_gains=(1.0,), remnant_fractions=(0.0,),
                       method="fast", duration=4.0, **dict(TINY, **kw))


def _stamp(path):
    st = path.stat()
    return st.st_mtime_ns, path.read_bytes()


# --- jobs and seeds ----------------------------------------------------------------------
def test_job_key_seeds_and_validation():
    j = Job("FD", 1.0, 0.2, 7)
    assert j.key == "FD_k1_fn0.2_r007_thr_paper"
    assert Job("FT", 0.25, 0.0, 12, False, "fast", duration=20).key == "FT_k0.25_fn0_r012_nothr_fast_T20"
    # the remnant seed depends on the cell and realization only: fits with and
    # without threshold, by either method, see the same recording
    same = [Job("FD", 1, 0.2, 7, thr, m) for thr in (True, False) for m in ("paper", "fast")]
    assert len({s.remnant_seed for s in same}) == 1 and len({s.fit_seed for s in same}) == 1
    assert j.fit_seed != j.remnant_seed
    others = [Job("FD", 1.0, 0.2, 8), Job("FT", 1.0, 0.2, 7), Job("FD", 0.75, 0.2, 7),
              Job("FD", 1.0, 0.25, 7)]
    assert j.remnant_seed not in {o.remnant_seed for o in others}
    assert Job("FD", 1.0, 0.2, 7).remnant_seed == j.remnant_seed  # deterministic
    assert Job.from_dict(json.loads(json.dumps(j.to_dict()))) == j
    with pytest.raises(ValueError, match="unknown option"):
        Job("FD", 1.0, 0.2, 0, method="fast", fit_kwargs={"repetitions": 2})
    with pytest.raises(ValueError, match="task"):
        Job("XX", 1.0, 0.2, 0)
    with pytest.raises(ValueError, match="remnant_fraction"):
        Job("FD", 1.0, 1.0, 0)
    jobs = paper_study(3)
    assert len(jobs) == 3 * 2 * 4 * 5 * 2 and len({x.key for x in jobs}) == len(jobs)


def test_table4_remnant_gains_are_the_papers():
    """remnant="table4" takes K_n from Table 4 for the cell (the paper's own gains)."""
    j = Job("FD", 0.25, 0.3, 0, remnant="table4")
    assert j.key == "FD_k0.25_fn0.3_r000_thr_paper_kn4"
    assert j.remnant_gain == 0.370  # Table 4, FD, F_n = 0.3, K_theta = 0.25
    assert Job("FT", 1.0, 0.1, 0, remnant="table4").remnant_gain == 0.057
    assert Job("FT", 1.0, 0.0, 0, remnant="table4").remnant_gain == 0.0
    assert Job("FD", 1.0, 0.2, 0).remnant_gain is None  # calibrated per realization
    # the same realization sees the same noise sequence either way
    assert j.remnant_seed == Job("FD", 0.25, 0.3, 0).remnant_seed
    assert Job.from_dict(json.loads(json.dumps(j.to_dict()))) == j
    with pytest.raises(ValueError, match="Table 4 lists no remnant gain"):
        Job("FD", 0.3, 0.2, 0, remnant="table4")
    with pytest.raises(ValueError, match="Table 4 lists no remnant gain"):
        Job("FD", 1.0, 0.15, 0, remnant="table4")
    with pytest.raises(ValueError, match="remnant must be"):
        Job("FD", 1.0, 0.2, 0, remnant="tabel4")
    jobs = paper_study(1, remnant="table4")
    assert {x.remnant for x in jobs} == {"table4"} and all(x.key.endswith("_kn4") for x in jobs)


def test_run_job_with_table4_gain_uses_it():
    from bayespilot.campaign import run_job

    job = Job("FD", 1.0, 0.2, 0, method="fast", fit_kwargs=TINY, duration=4.0, remnant="table4")
    res = run_job(job)
    assert res["K_n"] == pytest.approx(0.104)  # Table 4, FD, F_n = 0.2, K_theta = 1
    assert 0.0 < res["F_n"] < 0.6 and res["remnant"] == "table4"


def test_run_job_records_the_paper_fits_check_without_warning():
    """A study of the paper's procedure records how far short of a maximum each single pass
    stopped (the fit's check) instead of warning thousands of times in the workers."""
    import warnings

    from bayespilot.campaign import run_job
    from bayespilot.fit.result import CHECK_GAP, NotAtMaximumWarning

    job = Job("FD", 1.0, 0.0, 0, method="paper", duration=8.0,
              fit_kwargs={"repetitions": 2, "n_best": 1, "population": 8, "generations": 2})
    with warnings.catch_warnings():
        warnings.simplefilter("error", NotAtMaximumWarning)
        res = run_job(job)
    check = res["check"]
    # a 2 x 8 x 2 GA on a remnant-free run stops far short
    assert check["gap"] > CHECK_GAP and 0.0 <= check["delta_abs"] <= 0.1
    assert res["fit"]["neg_log_lik"] - check["neg_log_lik"] == pytest.approx(check["gap"])


# --- the campaign --------------------------------------------------------------------------
def test_campaign_writes_skips_and_redoes(tmp_path):
    out = tmp_path / "c"
    jobs = _jobs()
    s1 = run_campaign(jobs, out, workers=1, progress=False)
    assert (s1.total, s1.completed, s1.skipped, s1.failed) == (2, 2, 0, 0)
    paths = [out / f"{j.key}.json" for j in jobs]
    assert all(p.is_file() for p in paths)
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in paths)  # no tmp left
    for j, p in zip(jobs, paths):
        d = json.loads(p.read_text())
        assert d["key"] == j.key and d["job"] == j.to_dict() and d["threshold"] == j.threshold
        assert d["true_params"] == presets.paper_parameters("FD")
        assert d["K_n"] == 0.0 and d["F_n"] == 0.0
        assert d["fit"]["seed"] == j.fit_seed and d["remnant_seed"] == j.remnant_seed
        assert set(d["fit"]["params"]) == set(presets.PARAMETER_NAMES)
        assert "steps" not in d["fit"] and d["elapsed_seconds"] > 0
        assert "numba" in d["versions"]
    assert json.loads(paths[1].read_text())["fit"]["params"]["delta_abs"] == 0.0  # no threshold

    # same jobs again: nothing is redone, the files are untouched
    before = [_stamp(p) for p in paths]
    s2 = run_campaign(jobs, out, workers=1, progress=False)
    assert (s2.completed, s2.skipped, s2.failed) == (0, 2, 0)
    assert [_stamp(p) for p in paths] == before

    # one file deleted, plus a job that raises: only the deleted one is redone,
    # the failure is recorded and the campaign goes on
    paths[0].unlink()
    bad = Job("FD", 1.0, 0.0, 1, True, "fast", {"n_starts": 0}, duration=4.0)
    s3 = run_campaign(jobs + [bad], out, workers=1, progress=False)
    assert (s3.completed, s3.skipped, s3.failed) == (1, 1, 1)
    assert paths[0].is_file() and _stamp(paths[1]) == before[1]
    err = json.loads((out / f"{bad.key}.error.json").read_text())
    assert err["key"] == bad.key and "n_starts" in err["message"] and err["error"] == "ValueError"
    assert "n_starts" in s3.errors[bad.key]
    assert not (out / f"{bad.key}.json").exists()
    assert [r["key"] for r in load_results(out)] == sorted(j.key for j in jobs)

    # a result of the same key for other settings is not silently reused
    with pytest.raises(CampaignError, match="other settings"):
        run_campaign(_jobs(n_starts=2), out, workers=1, progress=False)


def test_unreachable_scheduler_fails_quickly(tmp_path):
    t0 = time.perf_counter()
    with pytest.raises(CampaignError, match="cannot reach the dask scheduler") as info:
        run_campaign(_jobs(), tmp_path, scheduler="tcp://127.0.0.1:9", connect_timeout=2,
                     progress=False)
    assert time.perf_counter() - t0 < 15
    assert "\n" not in str(info.value)
    with pytest.raises(ValueError, match="workers"):
        run_campaign(_jobs(), tmp_path, scheduler="tcp://127.0.0.1:9", workers=2)


def test_local_cluster_start_is_retried_once(tmp_path, monkeypatch):
    """A LocalCluster that fails to start once is retried; failing twice is one CampaignError."""
    import distributed

    real = distributed.LocalCluster
    calls = []

    def flaky(fail_times):
        def make(*args, **kwargs):
            calls.append(1)
            if len(calls) <= fail_times:
                raise AssertionError
            return real(*args, **kwargs)
        return make

    monkeypatch.setattr(distributed, "LocalCluster", flaky(2))
    with pytest.raises(CampaignError, match=r"cannot start a local dask cluster with 1 workers "
                                            r"\(AssertionError\)"):
        run_campaign(_jobs(), tmp_path / "a", workers=1, progress=False)
    assert len(calls) == 2
    calls.clear()
    monkeypatch.setattr(distributed, "LocalCluster", flaky(1))
    jobs = _jobs()[:1]
    run_campaign(jobs, tmp_path / "b", workers=1, progress=False)
    assert len(calls) == 2 and len(list((tmp_path / "b").glob("*.json"))) >= 1


# --- summarise -----------------------------------------------------------------------------
def _synthetic(task, fn, k, deltas, thr=True, method="paper", nll=None):
    nll = np.arange(len(deltas)) * -3.0 if nll is None else nll
    return [{"key": f"{task}{fn}{k}{i}{thr}{method}", "task": task, "remnant_fraction": fn,
             "motion_gain": k, "threshold": thr, "method": method,
             "true_params": {"delta_abs": 0.0075},
             "fit": {"params": {"delta_abs": float(d)}, "neg_log_lik": float(v)}}
            for i, (d, v) in enumerate(zip(deltas, nll))]


def test_summarise_against_numpy():
    rng = np.random.default_rng(5)
    inside = rng.uniform(0.00376, 0.01124, 55)             # within +-50 % of 0.0075
    outside = np.r_[rng.uniform(0.0, 0.0037, 20), rng.uniform(0.0113, 0.1, 25)]
    a = rng.permutation(np.r_[inside, outside])             # FD, 0.2, 1: paper N50 = 55
    b = rng.permutation(np.r_[inside[:30], outside, rng.uniform(0.02, 0.1, 25)])  # N50 = 30
    c = rng.uniform(0.0, 0.1, 7)                            # FD, 0.1: no paper cell
    res = (_synthetic("FD", 0.2, 1.0, a) + _synthetic("FT", 0.2, 1.0, b)
           + _synthetic("FD", 0.1, 0.5, c) + _synthetic("FD", 0.2, 1.0, np.zeros(4), thr=False)
           + _synthetic("FD", 0.3, 1.0, [0.0112]))
    rows = {(r["task"], r["F_n"], r["K_theta"], r["threshold"]): r for r in summarise(res)}
    assert len(rows) == 5

    for key, d in [(("FD", 0.2, 1.0, True), a), (("FT", 0.2, 1.0, True), b),
                   (("FD", 0.1, 0.5, True), c)]:
        r = rows[key]
        assert r["n"] == d.size
        assert r["mu"] == np.mean(d) and r["sigma"] == np.std(d, ddof=1)
        assert r["N50"] == np.sum((d >= 0.00375) & (d <= 0.01125))
        assert r["mean_neg_log_lik"] == np.mean(np.arange(d.size) * -3.0)
    assert rows[("FD", 0.2, 1.0, True)]["N50"] == 55 and rows[("FT", 0.2, 1.0, True)]["N50"] == 30
    # "within 50 %" includes its edge: 0.00375 is exactly half of 0.0075 (in binary too)
    edge, = summarise(_synthetic("FT", 0.1, 0.25, [0.00375, 0.0037499, 0.0075]))
    assert edge["N50"] == 2

    # FD 0.2 / 1: N50 equal to the paper's -> no N50 flag; mu flag by the stated formula
    r = rows[("FD", 0.2, 1.0, True)]
    pmu, psig, pn50 = presets.FIG14_15[("FD", 0.2, 1.0)]
    assert (r["paper_mu"], r["paper_sigma"], r["paper_N50"]) == (pmu, psig, pn50)
    assert r["flag_N50"] is False
    expect_mu = abs(np.mean(a) - pmu) > 2 * math.sqrt(np.var(a, ddof=1) / 100 + psig**2 / 100)
    assert r["flag_mu"] is bool(expect_mu) and r["flag"] is bool(expect_mu)
    # FT 0.2 / 1: 30 against the paper's 65, 2 sd = 2 sqrt(100 * 0.65 * 0.35) = 9.5 -> flagged
    assert rows[("FT", 0.2, 1.0, True)]["flag_N50"] is True
    assert rows[("FT", 0.2, 1.0, True)]["flag"] is True
    # no paper cell, or without threshold: no paper values, no flags
    for key in (("FD", 0.1, 0.5, True), ("FD", 0.2, 1.0, False)):
        assert rows[key]["paper_mu"] is None and rows[key]["flag"] is False
    assert rows[("FD", 0.2, 1.0, False)]["mu"] == 0.0 and rows[("FD", 0.2, 1.0, False)]["N50"] == 0
    # one realization: sigma undefined, only the N50 check (1 of 1 vs the paper's 42 %)
    one = rows[("FD", 0.3, 1.0, True)]
    assert one["n"] == 1 and math.isnan(one["sigma"]) and one["N50"] == 1
    assert one["flag_mu"] is False
    assert one["flag_N50"] is (abs(1 - 0.42) > 2 * math.sqrt(0.42 * 0.58))


def test_summary_table_and_csv(tmp_path):
    rows = summarise(_synthetic("FD", 0.2, 1.0, np.full(100, 0.0075)))
    md = summary_markdown(rows)
    assert md.count("\n") == 2 and "| 0.0088 | 0.0049 | 55 |" in md and "**N50" in md
    p = write_summary_csv(rows, tmp_path / "s.csv")
    got = list(csv.DictReader(p.open()))
    assert len(got) == 1 and got[0]["N50"] == "100" and got[0]["paper_N50"] == "55"


def test_plot_threshold_histograms():
    pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    from bayespilot.plots import plot_threshold_histograms

    rng = np.random.default_rng(1)
    res = [r for task in ("FD", "FT") for fn in (0.0, 0.1, 0.2) for k in (0.25, 1.0)
           for r in _synthetic(task, fn, k, rng.uniform(0, 0.1, 10))]
    fig = plot_threshold_histograms(res)  # F_n = 0.1 is not among the default fractions
    assert len(fig.axes) == 2 * 2 * 2
    plt.close(fig)
    # on a new figure one figure legend below the grid; on axes given, the legend goes to the
    # first panel that has fits (here not the first: it has none)
    part = [r for r in res if not (r["task"] == "FD" and r["remnant_fraction"] == 0.0
                                   and r["motion_gain"] == 0.25)]
    fig = plot_threshold_histograms(part)
    assert all(a.get_legend() is None for a in fig.axes) and len(fig.legends) == 1
    plt.close(fig)
    fig, axes = plt.subplots(4, 2)
    plot_threshold_histograms(part, ax=axes)
    assert fig.axes[0].get_legend() is None
    assert sum(a.get_legend() is not None for a in fig.axes) == 1
    plt.close(fig)
    with pytest.raises(ValueError, match="several methods"):
        plot_threshold_histograms(res + _synthetic("FD", 0.0, 1.0, [0.01], method="fast"))
    with pytest.raises(ValueError, match="no fits"):
        plot_threshold_histograms(res, fractions=(0.3,))


# --- the CLI ---------------------------------------------------------------------------------
def test_replicate_cli(tmp_path, capsys):
    out = tmp_path / "rep"
    code = main(["replicate", "--realizations", "1", "--method", "fast", "--tasks", "FD",
                 "--motion-gains", "1", "--remnant-fractions", "0", "--duration", "4",
                 "--fit-option", "n_starts=1", "--fit-option", "profile_step=0.02",
                 "--workers", "1", "--out", str(out), "-q"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert len(list(out.glob("FD_k1_fn0_r000_*_fast_kn4_T4.json"))) == 2
    rows = list(csv.DictReader((out / "summary.csv").open()))
    assert {(r["threshold"], r["n"]) for r in rows} == {("True", "1"), ("False", "1")}
    assert "paper mu" in (out / "summary.md").read_text()
    assert (out / "delta_abs_histograms.png").stat().st_size > 1000
    assert "| FD | 0 | 1 | yes | fast | 1 |" in captured.out


@pytest.mark.parametrize("argv, message", [
    (["--fit-option", "bogus=1"], "unknown option"),
    (["--tasks", "FD,XX"], "task must be FD or FT"),
    (["--remnant-fractions", "0,1.5"], "must be in [0, 1)"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:9"], "not both"),
])
def test_replicate_cli_usage_errors(tmp_path, capsys, argv, message):
    code = main(["replicate", "--out", str(tmp_path / "x"), "--method", "fast", *argv])
    err = capsys.readouterr().err
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1


def test_job_seed_refuses_an_unknown_task_or_stream():
    from bayespilot.campaign import job_seed

    assert job_seed("fit", "FT", 0.5, 0.3, 2) != job_seed("fit", "FD", 0.5, 0.3, 2)
    with pytest.raises(ValueError, match="task must be one of FD, FT, got 'XX'"):
        job_seed("fit", "XX", 0.5, 0.3, 2)
    with pytest.raises(ValueError, match="stream must be"):
        job_seed("noise", "FD", 0.5, 0.3, 2)


def test_job_takes_only_a_bool_for_iterate():
    """A fit option whose default is a bool (iterate) must be one: "False" is refused here,
    before any fit runs, not taken for its truth value."""
    assert Job("FD", 1.0, 0.2, 0, fit_kwargs={"iterate": False}).fit_kwargs == {"iterate": False}
    for bad in ("False", "true", 1, None):
        with pytest.raises(ValueError, match="iterate must be True or False"):
            Job("FD", 1.0, 0.2, 0, fit_kwargs={"iterate": bad})
        with pytest.raises(ValueError, match="iterate must be True or False"):
            paper_study(1, tasks=("FD",), motion_gains=(1.0,), remnant_fractions=(0.2,),
                        iterate=bad)


@pytest.fixture
def stopped_campaign(monkeypatch):
    """run_campaign replaced: it keeps the jobs it is given and stops (CampaignError), so a
    'replicate' command runs no fit; returns the list of jobs seen."""
    import bayespilot.campaign as campaign

    seen = []

    def stop(jobs, *args, **kwargs):
        seen.extend(jobs)
        raise CampaignError("stopped by the test")

    monkeypatch.setattr(campaign, "run_campaign", stop)
    return seen


def test_replicate_cli_first_realization_repeats_the_study_independently(tmp_path, capsys,
                                                                        stopped_campaign):
    """--first-realization K numbers the realizations from K: other keys and other seeds (an
    independent repeat of the study: its root seed is fixed), the same cells."""
    from bayespilot.campaign import job_seed

    code = main(["replicate", "--realizations", "2", "--first-realization", "100", "--tasks",
                 "FD", "--motion-gains", "1", "--remnant-fractions", "0.2", "--fits",
                 "threshold", "--method", "fast", "--out", str(tmp_path / "x"), "-q"])
    assert code == 1 and "stopped by the test" in capsys.readouterr().err
    assert [j.realization for j in stopped_campaign] == [100, 101]
    assert [j.key for j in stopped_campaign] == ["FD_k1_fn0.2_r100_thr_fast_kn4",
                                                 "FD_k1_fn0.2_r101_thr_fast_kn4"]
    first = paper_study(1, tasks=("FD",), motion_gains=(1.0,), remnant_fractions=(0.2,),
                        threshold=True, method="fast")[0]
    assert job_seed("remnant", "FD", 1.0, 0.2, 100) != job_seed("remnant", "FD", 1.0, 0.2,
                                                                first.realization)
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="first_realization must be an integer >= 0"):
            paper_study(1, first_realization=bad)
    code = main(["replicate", "--first-realization", "-1", "--out", str(tmp_path / "y")])
    assert code == 2


@pytest.mark.parametrize("value, expected", [("False", False), ("false", False),
                                             ("True", True), ("true", True), ("TRUE", True)])
def test_replicate_cli_fit_option_booleans(tmp_path, capsys, stopped_campaign, value, expected):
    """--fit-option iterate=False reaches the jobs as False (it was the string 'False', which
    ran the iterated fit); the campaign is stopped before any fit runs."""
    seen = stopped_campaign
    code = main(["replicate", "--realizations", "1", "--tasks", "FD", "--motion-gains", "1",
                 "--remnant-fractions", "0.2", "--fits", "threshold", "--out",
                 str(tmp_path / "x"), "--fit-option", f"iterate={value}", "-q"])
    assert code == 1 and "stopped by the test" in capsys.readouterr().err
    assert [j.fit_kwargs for j in seen] == [{"iterate": expected}]
    assert seen[0].fit_kwargs["iterate"] is expected


@pytest.mark.parametrize("option, flag", [("duration=10", "--duration"),
                                          ("remnant=table4", "--remnant"),
                                          ("threshold=false", "--fits"),
                                          ("method=fast", "--method"),
                                          ("tasks=FD", "--tasks"),
                                          ("motion_gains=1", "--motion-gains"),
                                          ("remnant_fractions=0.2", "--remnant-fractions"),
                                          ("realizations=2", "--realizations")])
def test_replicate_cli_refuses_a_fit_option_that_an_option_sets(tmp_path, capsys,
                                                                stopped_campaign, option, flag):
    """paper_study's own keywords are not fit options: a usage error naming the option that sets
    them (it was exit 1, 'unexpected TypeError ... please report it')."""
    code = main(["replicate", "--out", str(tmp_path / "x"), "--fit-option", option])
    err = capsys.readouterr().err
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "unexpected" not in err
    assert stopped_campaign == []
    name = option.split("=")[0]
    assert f"argument --fit-option: '{name}' is not a fit option: give {flag} instead" in err
    assert not (tmp_path / "x").exists()


def test_replicate_cli_refuses_a_non_bool_iterate(tmp_path, capsys, stopped_campaign):
    code = main(["replicate", "--out", str(tmp_path / "x"), "--fit-option", "iterate=yes"])
    err = capsys.readouterr().err
    assert code == 2 and "--fit-option: option iterate must be True or False, got 'yes'" in err
    assert stopped_campaign == []


def test_run_keyed_reports_a_lost_cluster_not_failed_tasks(tmp_path, monkeypatch):
    """Futures cancelled when the scheduler dies are not the tasks' failures: no error files
    (they read 'NoneType: None'), the finished results kept, a CampaignError to resume."""
    import distributed

    import bayespilot.campaign as C

    Fut = _FakeFuture  # (below)

    class Client:
        def submit(self, fn, *args, pure=False):
            return Fut(*fn(*args))

    monkeypatch.setattr(C, "_connect", lambda *a, **k: Client())
    monkeypatch.setattr(distributed, "as_completed", lambda futs: list(futs))
    tasks = [("a", lambda: ("finished", {"x": 1}), (), {}),
             ("b", lambda: ("cancelled", None), (), {}),
             ("c", lambda: ("lost", None), (), {})]
    with pytest.raises(C.CampaignError, match="lost the dask cluster: 2 of 3 tasks did not "
                                              "finish .1 finished and were saved.; run the "
                                              "same command again to resume"):
        C.run_keyed(tasks, tmp_path, total=3, skipped=0, scheduler=None, workers=1,
                    progress=False, connect_timeout=1.0)
    assert json.loads((tmp_path / "a.json").read_text()) == {"x": 1, "bayespilot_version":
                                                             bayespilot.__version__}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json"]


def test_a_scheduler_address_that_does_not_answer_dask_is_refused_in_time(monkeypatch):
    """A port that answers but is not a scheduler (its dashboard's) kept Client waiting past
    its timeout; a peer answering something else failed with a MemoryError."""
    import time as _time

    import bayespilot.campaign as C

    monkeypatch.setattr(C, "CONNECT_GRACE", 0.2)

    def hangs(address, timeout):
        _time.sleep(30)

    t0 = _time.perf_counter()
    with pytest.raises(C.CampaignError, match="no dask answer within 0.3 s .is it the "
                                              "scheduler's address"):
        C._client_within(hangs, "tcp://127.0.0.1:8787", 0.1)
    assert _time.perf_counter() - t0 < 5

    def garbage(address, timeout):
        raise MemoryError("Unable to allocate 3.07 EiB")

    with pytest.raises(C.CampaignError, match="cannot reach the dask scheduler at "
                                              "'tcp://x:1' within 0.1 s .something answered "
                                              "there, but not in dask's protocol") as info:
        C._client_within(garbage, "tcp://x:1", 0.1)
    assert "EiB" not in str(info.value)  # (dask's misread frame length says nothing)


# --- saving a campaign's summary; what a per-fit file holds --------------------------------
def test_campaign_summary_round_trips_through_json(tmp_path):
    """run_campaign's and diagnose_batch's CampaignSummary: to_dict is strict JSON (the folder
    as text), from_dict rebuilds an equal summary, ignoring keys of a later release and
    refusing a dict of another kind."""
    from pathlib import Path

    from bayespilot import _files
    from bayespilot.campaign import CampaignSummary

    s = CampaignSummary(5, 2, 2, 1, {"FD_k1_fn0_r001_thr_fast": "ValueError: n_starts"},
                        tmp_path / "c", 12.5, "diagnoses")
    d = s.to_dict()
    assert d["out_dir"] == str(tmp_path / "c") and d["elapsed_seconds"] == 12.5

    def reject(c):
        raise ValueError(c)

    for text in (json.dumps(d, allow_nan=False), _files.dumps(d)):  # with the version key too
        back = CampaignSummary.from_dict(json.loads(text, parse_constant=reject))
        assert back == s and isinstance(back.out_dir, Path) and str(back) == str(s)
    d["errors"]["x"] = "changed"  # a copy: the summary's own errors are left as they are
    assert "x" not in s.errors
    assert CampaignSummary.from_dict({**s.to_dict(), "new_key": 1}) == s
    with pytest.raises(ValueError, match="not a campaign summary: no completed"):
        CampaignSummary.from_dict({"total": 1})


def test_run_job_writes_seeds_as_text_and_the_fraction_reached(tmp_path):
    """Seeds up to 2**63 read back rounded by a double-only JSON reader (jq, JavaScript), so the
    per-fit dict carries exact decimal copies; F_n (the fraction reached, unlike summary.csv's
    requested F_n) has the unambiguous alias F_n_reached.  A file written before these keys
    still loads, is resumed (skipped, untouched) and summarised."""
    from bayespilot.campaign import _write_json_atomic, run_job

    job = Job("FD", 1.0, 0.2, 0, method="fast", fit_kwargs=TINY, duration=4.0)
    res = run_job(job)
    assert job.remnant_seed > 2**53 or job.fit_seed > 2**53  # the case that needs the text
    assert res["remnant_seed_text"] == str(job.remnant_seed) == str(res["remnant_seed"])
    assert res["fit_seed_text"] == str(job.fit_seed) == str(res["fit"]["seed"])
    doubles = json.loads(json.dumps(res), parse_int=float)  # as jq or JavaScript read it
    assert int(doubles["fit_seed_text"]) == job.fit_seed
    assert int(doubles["remnant_seed_text"]) == job.remnant_seed
    assert res["F_n_reached"] == res["F_n"] and res["remnant_fraction"] == 0.2

    out = tmp_path / "c"
    old = {k: v for k, v in res.items()
           if k not in ("remnant_seed_text", "fit_seed_text", "F_n_reached")}
    _write_json_atomic(out / f"{job.key}.json", old)
    before = _stamp(out / f"{job.key}.json")
    s = run_campaign([job], out, workers=1, progress=False)
    assert (s.completed, s.skipped, s.failed) == (0, 1, 0)
    assert _stamp(out / f"{job.key}.json") == before
    (back,) = load_results(out, [job])
    assert back["remnant_seed"] == job.remnant_seed and "F_n_reached" not in back
    assert summarise([back])[0]["F_n"] == 0.2  # summary.csv's F_n: the requested one


# --- the cluster: interrupts, schedulers given as objects, the workers' version ----------
class _FakeFuture:
    def __init__(self, status, value=None):
        self.status, self.value = status, value

    def result(self):
        return self.value

    def release(self):
        pass


class _FakeClient:
    """What run_keyed uses of a distributed.Client; records what is submitted."""

    def __init__(self):
        self.submitted = []

    def submit(self, fn, *args, pure=False):
        self.submitted.append(args)
        return _FakeFuture("finished", {"x": len(self.submitted)})


@pytest.fixture
def fake_cluster(monkeypatch):
    """run_keyed's connection replaced by a _FakeClient (returned) and as_completed by the list
    of futures: the cluster loop without a cluster."""
    import distributed

    import bayespilot.campaign as C

    client = _FakeClient()
    monkeypatch.setattr(C, "_connect", lambda *a, **k: client)
    monkeypatch.setattr(distributed, "as_completed", lambda futs: list(futs))
    return client


def test_ctrl_c_during_the_numba_warm_up_stops_the_campaign(tmp_path, monkeypatch, fake_cluster):
    """Ctrl-C inside a numba kernel of the warm-up reaches Python as a SystemError whose context
    is the KeyboardInterrupt: it stops the campaign (nothing submitted), it is not the
    'warming failed' warning after which the campaign ran on; another failure still is."""
    import bayespilot.campaign as C

    def interrupted(methods):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise SystemError("CPUDispatcher(<function simulate_closed_loop>) returned a result "
                              "with an exception set")

    monkeypatch.setattr(C, "_warm_numba_cache", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_campaign(_jobs(), tmp_path / "a", progress=False)
    assert fake_cluster.submitted == [] and list((tmp_path / "a").iterdir()) == []

    def caused(methods):  # the same with the interrupt as the explicit cause
        raise SystemError("returned a result with an exception set") from KeyboardInterrupt()

    monkeypatch.setattr(C, "_warm_numba_cache", caused)
    with pytest.raises(KeyboardInterrupt):
        run_campaign(_jobs(), tmp_path / "a", progress=False)
    assert fake_cluster.submitted == []

    def broken(methods):
        raise SystemError("something else")

    monkeypatch.setattr(C, "_warm_numba_cache", broken)
    with pytest.warns(RuntimeWarning, match="warming numba's cache failed .SystemError: "
                                            "something else."):
        s = run_campaign(_jobs(), tmp_path / "b", progress=False)
    assert len(fake_cluster.submitted) == 2 and s.completed == 2


def _stub_task(x):
    """A task of the cluster tests: instant, JSON-ready."""
    return {"x": x}


def _live_clients(cluster):
    """The clients connected to an in-process cluster's scheduler (not its fire-and-forget)."""
    return {c for c in cluster.scheduler.clients if c != "fire-and-forget"}


def test_scheduler_may_be_a_client_or_a_cluster_object(tmp_path):
    """run_campaign(scheduler=Client(...)) failed with 'cannot reach the dask scheduler (TypeError
    ...)': a Client is used as it is and left open, a Cluster gets a Client of its own, closed
    at the end (the cluster left running); another type is a TypeError saying what is taken."""
    import distributed

    import bayespilot.campaign as C

    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=":0") as cluster:
        with distributed.Client(cluster) as client:
            mine = _live_clients(cluster)
            done, errors = C.run_keyed([("a", _stub_task, (1,), {})], tmp_path / "a", total=1,
                                       skipped=0, scheduler=client, workers=None,
                                       progress=False, connect_timeout=10.0)
            assert (done, errors) == (1, {})
            assert json.loads((tmp_path / "a" / "a.json").read_text())["x"] == 1
            assert client.status == "running" and client.submit(_stub_task, 2).result() == {"x": 2}

            # the public function, with a tiny fit
            jobs = _jobs()[:1]
            s = run_campaign(jobs, tmp_path / "c", scheduler=client, progress=False,
                             warm_cache=False)
            assert (s.completed, s.failed) == (1, 0) and client.status == "running"

            done, errors = C.run_keyed([("b", _stub_task, (3,), {})], tmp_path / "b", total=1,
                                       skipped=0, scheduler=cluster, workers=None,
                                       progress=False, connect_timeout=10.0)
            assert (done, errors) == (1, {})
            assert json.loads((tmp_path / "b" / "b.json").read_text())["x"] == 3
            deadline = time.monotonic() + 10  # run_keyed's own client is closed, not the cluster
            while _live_clients(cluster) != mine and time.monotonic() < deadline:
                time.sleep(0.05)
            assert _live_clients(cluster) == mine
            assert client.submit(_stub_task, 4).result() == {"x": 4}
            with pytest.raises(ValueError, match="workers"):
                run_campaign(jobs, tmp_path / "c", scheduler=client, workers=1)
    with pytest.raises(CampaignError, match="the dask Client given is not connected to its "
                                            "scheduler .status 'closed'."):
        C.run_keyed([("d", _stub_task, (5,), {})], tmp_path / "d", total=1, skipped=0,
                    scheduler=client, workers=None, progress=False, connect_timeout=1.0)

    for bad in (8786, tmp_path, b"tcp://127.0.0.1:8786"):
        with pytest.raises(TypeError, match=r"scheduler must be a dask scheduler's address .a "
                                            r"str, e.g. 'tcp://host:8786'., a "
                                            r"distributed.Client, a distributed.deploy.Cluster"):
            run_campaign(_jobs(), tmp_path / "bad", scheduler=bad, progress=False)
        with pytest.raises(TypeError, match="scheduler must be"):  # (diagnose_batch's way in)
            C.run_keyed([], tmp_path / "bad", total=0, skipped=0, scheduler=bad, workers=None,
                        progress=False, connect_timeout=1.0)
    assert not (tmp_path / "bad").exists()  # refused before anything is made


def test_workers_without_this_bayespilot_are_refused_before_anything_runs(tmp_path, monkeypatch,
                                                                          capsys):
    """A worker without bayespilot exited on its first task (the campaign then waited for ever
    with no worker, or went on with fewer, silently); one with another version made results
    that contradict their own version stamp.  The workers of a scheduler given are asked
    first: those lacking it or with another version are named, nothing is submitted, and the
    CLI exits 1 with that line."""
    from importlib.metadata import PackageNotFoundError

    import distributed

    import bayespilot.campaign as C

    real_run = distributed.Client.run
    answers = {}

    def run(self, function, *args, **kwargs):
        got = real_run(self, function, *args, **kwargs)
        return {**got, **answers}

    submitted = []
    real_submit = distributed.Client.submit

    def submit(self, *args, **kwargs):
        submitted.append(args)
        return real_submit(self, *args, **kwargs)

    monkeypatch.setattr(distributed.Client, "run", run)
    monkeypatch.setattr(distributed.Client, "submit", submit)
    # (in this process, but on TCP: the command takes tcp:// addresses, not inproc://)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  protocol="tcp", host="127.0.0.1",
                                  dashboard_address=":0") as cluster:
        # the workers of this process have this version: the check passes
        done, _ = C.run_keyed([("a", _stub_task, (1,), {})], tmp_path / "ok", total=1,
                              skipped=0, scheduler=cluster, workers=None, progress=False,
                              connect_timeout=10.0)
        assert done == 1 and len(submitted) == 1
        submitted.clear()

        answers.update({"tcp://10.0.0.2:4000": PackageNotFoundError("bayespilot"),
                        "tcp://10.0.0.3:4000": "0.0.9",
                        "tcp://10.0.0.4:4000": OSError("Timed out trying to connect")})
        want = bayespilot.__version__
        for scheduler in (cluster, cluster.scheduler_address):
            # a worker that did not answer (gone, unreachable) is said, not counted as lacking
            with pytest.raises(CampaignError) as info, pytest.warns(
                    RuntimeWarning, match=r"1 dask worker\(s\) .* did not say their bayespilot "
                                          r"version \(tcp://10.0.0.4:4000: OSError: Timed out"):
                run_campaign(_jobs(), tmp_path / "c", scheduler=scheduler, progress=False)
            text = str(info.value)
            assert f"must have bayespilot {want}, as this process has: 4 worker(s), " in text
            assert ("1 without it (tcp://10.0.0.2:4000) and 1 with another version "
                    "(tcp://10.0.0.3:4000: 0.0.9)") in text
            assert f"install bayespilot=={want} in the workers' environment" in text
            assert "\n" not in text
        with distributed.Client(cluster) as client, pytest.warns(RuntimeWarning):
            with pytest.raises(CampaignError, match="1 with another version"):
                run_campaign(_jobs(), tmp_path / "c", scheduler=client, progress=False)
            assert client.status == "running"  # the caller's client is left open
        assert submitted == [] and list((tmp_path / "c").iterdir()) == []

        # the command: one line, exit 1, nothing run
        code = main(["replicate", "--out", str(tmp_path / "cli"), "--realizations", "1",
                     "--tasks", "FD", "--motion-gains", "1", "--remnant-fractions", "0",
                     "--method", "fast", "--duration", "4", "--scheduler",
                     cluster.scheduler_address])
        err = capsys.readouterr().err
        assert code == 1 and "bayespilot: error: the dask workers of the scheduler at " in err
        assert "1 with another version (tcp://10.0.0.3:4000: 0.0.9)" in err
        assert submitted == []


def test_the_client_logger_is_quiet_while_results_come_in(tmp_path, monkeypatch, caplog,
                                                          fake_cluster):
    """A lost scheduler is one line ('lost the dask cluster ...'); distributed.client's
    reconnection printed a 25-line traceback before it.  That logger is silenced while the
    results come in, left as it is when set to DEBUG, and restored afterwards, also when the
    loop ends in an error."""
    import logging

    import distributed

    import bayespilot.campaign as C

    log = logging.getLogger("distributed.client")
    heard = []

    def as_completed(futs):
        for f in list(futs):
            heard.append(log.isEnabledFor(logging.ERROR))
            log.error("Failed to reconnect to scheduler after 10.00 seconds, closing client")
            yield f

    monkeypatch.setattr(distributed, "as_completed", as_completed)
    caplog.set_level(logging.WARNING, logger="distributed.client")  # (restored at the end)
    tasks = [("a", _stub_task, (1,), {}), ("b", _stub_task, (2,), {})]
    done, _ = C.run_keyed(tasks, tmp_path, total=2, skipped=0, scheduler=None, workers=1,
                          progress=False, connect_timeout=1.0)
    assert done == 2 and heard == [False, False] and log.level == logging.WARNING
    assert not [r for r in caplog.records if r.name == "distributed.client"]

    def lost(futs):  # the loop ends in the CampaignError: the level is restored all the same
        heard.append(log.isEnabledFor(logging.ERROR))
        for f in futs:
            f.status = "lost"
        return list(futs)

    heard.clear()
    monkeypatch.setattr(distributed, "as_completed", lost)
    with pytest.raises(CampaignError, match="lost the dask cluster"):
        C.run_keyed(tasks, tmp_path, total=2, skipped=0, scheduler=None, workers=1,
                    progress=False, connect_timeout=1.0)
    assert heard == [False] and log.level == logging.WARNING

    heard.clear()  # asked for debugging: left as it is
    monkeypatch.setattr(distributed, "as_completed", as_completed)
    log.setLevel(logging.DEBUG)
    C.run_keyed(tasks, tmp_path, total=2, skipped=0, scheduler=None, workers=1,
                progress=False, connect_timeout=1.0)
    assert heard == [True, True] and log.level == logging.DEBUG


def test_run_job_says_the_workers_release_and_the_file_keeps_it(tmp_path, monkeypatch):
    """A fit made by a worker of another release said that release in ``versions`` and the
    client's in ``bayespilot_version`` (stamped when the client wrote the file): the worker's
    in both now, and the client's writer keeps it."""
    import bayespilot
    from bayespilot._files import VERSION_KEY
    from bayespilot.campaign import _write_json_atomic, run_job

    monkeypatch.setattr(bayespilot, "__version__", "0.0.9")
    monkeypatch.setattr("bayespilot.campaign._versions", lambda: {"bayespilot": "0.0.9"})
    res = run_job(Job("FD", 1.0, 0.2, 0, method="fast", fit_kwargs=TINY, duration=4.0))
    assert res[VERSION_KEY] == "0.0.9" and res["versions"]["bayespilot"] == "0.0.9"
    monkeypatch.undo()
    assert bayespilot.__version__ != "0.0.9"
    path = tmp_path / "fit.json"
    _write_json_atomic(path, res)
    assert json.loads(path.read_text())[VERSION_KEY] == "0.0.9"


def test_a_worker_running_bayespilot_from_a_source_folder_is_said_not_refused():
    """A worker that imports bayespilot from a checkout on PYTHONPATH has no installed
    version (no metadata): it was refused as one without bayespilot.  Asked again whether it
    can import it, it is named in a warning, not refused; one that cannot is refused."""
    from importlib.metadata import PackageNotFoundError, version

    from bayespilot.campaign import _check_workers

    want = version("bayespilot")

    class Client:
        def __init__(self, spec):
            self.spec = spec

        def run(self, function, *args, workers=None, on_error=None):
            if function is version:
                return {"tcp://a:1": PackageNotFoundError("bayespilot"), "tcp://b:1": want}
            assert workers == ["tcp://a:1"]
            return {"tcp://a:1": self.spec}

        def scheduler_info(self):
            return {"workers": {"tcp://a:1": {"name": "gpu-3"}}}

    with pytest.warns(RuntimeWarning, match=r"1 dask worker\(s\) of the scheduler at S import "
                                            r"bayespilot without an installed version .*"
                                            r"gpu-3 \(tcp://a:1\)"):
        _check_workers(Client("a ModuleSpec"), "S")
    with pytest.raises(CampaignError, match=r"1 without it \(gpu-3 \(tcp://a:1\)\)"):
        _check_workers(Client(None), "S")


# --- progress="lines": a batch job's log -------------------------------------------------
def test_progress_lines_say_what_finished_and_when():
    """What a line says, and when one is due (a fake clock): another 5 % finished, or a
    minute since the last line; tasks done before the run are counted, not as this run's."""
    import io

    import bayespilot.campaign as C

    stream = io.StringIO()
    lines = C._ProgressLines(40, 2, "fits", now=100.0, stream=stream)  # (5 %: every 2 tasks)
    lines.update(3, 0, now=101.0)
    assert stream.getvalue() == ""
    lines.update(4, 0, now=102.0)
    assert stream.getvalue() == ("bayespilot: 4/40 fits done, 0 failed, 2 before this run "
                                 "(0:00:02 elapsed, about 0:00:36 left)\n")
    lines.update(4, 1, now=103.0)
    lines.update(4, 2, now=104.0)
    assert stream.getvalue().splitlines()[-1] == (
        "bayespilot: 4/40 fits done, 2 failed, 2 before this run "
        "(0:00:04 elapsed, about 0:00:34 left)")
    n = len(stream.getvalue().splitlines())
    lines.beat(now=163.9)  # nothing new for a minute: a line all the same (the run is alive)
    assert len(stream.getvalue().splitlines()) == n
    lines.beat(now=164.0)
    assert stream.getvalue().splitlines()[-1].startswith("bayespilot: 4/40 fits done, 2 failed")
    fresh = C._ProgressLines(40, 0, "diagnoses", now=0.0, stream=stream)
    fresh.beat(now=60.0)
    assert stream.getvalue().splitlines()[-1] == ("bayespilot: 0/40 diagnoses done, 0 failed "
                                                  "(0:01:00 elapsed)")
    assert C._clock(3 * 3600 + 10 * 60 + 5.4) == "3:10:05"


class _FailedFuture(_FakeFuture):
    def __init__(self):
        super().__init__("error")

    def exception(self):
        return ValueError("bad input")

    def traceback(self):
        return None


def test_run_keyed_writes_progress_lines_as_tasks_finish(tmp_path, monkeypatch, capsys,
                                                         fake_cluster):
    """progress='lines': a plain line per 5 % of the tasks, counted where they finish (the
    command line polled the output folder before), failures included; no bar.  A bad
    ``progress`` is refused before anything runs."""
    import bayespilot.campaign as C

    submit = fake_cluster.submit

    def submit_or_fail(fn, *args, pure=False):  # the task of x = 7 fails
        return _FailedFuture() if args[-1] == 7 else submit(fn, *args, pure=pure)

    monkeypatch.setattr(fake_cluster, "submit", submit_or_fail)
    tasks = [(f"k{x:02d}", _stub_task, (x,), {}) for x in range(2, 40)]
    done, errors = C.run_keyed(tasks, tmp_path, total=40, skipped=2, scheduler=None,
                               workers=1, progress="lines", connect_timeout=1.0)
    assert done == 37 and list(errors) == ["k07"]
    err = capsys.readouterr().err
    said = [ln for ln in err.splitlines() if ln.startswith("bayespilot: ")]
    assert "\r" not in err and len(said) == 19, err  # (4, 6, ..., 40 of 40)
    assert said[0].startswith("bayespilot: 4/40 fits done, 0 failed, 2 before this run (")
    assert said[2].startswith("bayespilot: 7/40 fits done, 1 failed, 2 before this run (")
    assert said[-1].startswith("bayespilot: 39/40 fits done, 1 failed, 2 before this run (")
    for ok in (0, 1, np.int64(1), np.False_):  # (as before: True and False by another name)
        C._check_progress(ok)
    for bad in ("yes", 2, None):
        with pytest.raises(ValueError, match="progress must be True or 'bar'"):
            C.run_keyed(tasks, tmp_path, total=40, skipped=2, scheduler=None, workers=1,
                        progress=bad, connect_timeout=1.0)
        with pytest.raises(ValueError, match="progress must be"):
            run_campaign(_jobs(), tmp_path / "x", progress=bad)


# --- a caller's cluster: what run_keyed leaves on it, and workers that join late ----------
def test_an_asynchronous_client_is_refused(tmp_path):
    """A Client made with asynchronous=True returns coroutines where run_keyed waits for
    results: refused, saying what to give instead."""
    import asyncio

    import distributed

    import bayespilot.campaign as C

    async def main():
        async with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                            dashboard_address=":0", asynchronous=True) as cl:
            async with distributed.Client(cl, asynchronous=True) as client:
                with pytest.raises(TypeError, match="asynchronous distributed.Client"):
                    C.run_keyed([("a", _stub_task, (1,), {})], tmp_path, total=1, skipped=0,
                                scheduler=client, workers=None, progress=False,
                                connect_timeout=5.0)

    asyncio.run(main())
    assert list(tmp_path.iterdir()) == []


def _sleepy_task(x):
    import time

    time.sleep(2.0)
    return {"x": x}


def test_ctrl_c_cancels_the_tasks_left_on_a_callers_client(tmp_path, monkeypatch):
    """With a Client of the caller's (kept open), Ctrl-C in the loop left the submitted tasks
    running on the cluster: what was not collected is cancelled."""
    import time

    import distributed

    import bayespilot.campaign as C

    def interrupted(futs):
        raise KeyboardInterrupt
        yield  # (a generator, as distributed's)

    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=":0") as cluster:
        with distributed.Client(cluster) as client:
            monkeypatch.setattr(distributed, "as_completed", interrupted)
            tasks = [(k, _sleepy_task, (i,), {}) for i, k in enumerate("abc")]
            # (info keeps the traceback, so its frames' futures, as a notebook keeps the last
            # exception's: released, they were forgotten anyway)
            with pytest.raises(KeyboardInterrupt) as info:
                C.run_keyed(tasks, tmp_path, total=3, skipped=0, scheduler=client,
                            workers=None, progress=False, connect_timeout=10.0)
            time.sleep(0.5)  # (the submissions reach the scheduler after a moment)
            deadline = time.monotonic() + 5
            while cluster.scheduler.tasks and time.monotonic() < deadline:
                time.sleep(0.05)
            assert not cluster.scheduler.tasks  # (before: three tasks of 2 s each, run on)
            assert client.status == "running"  # (the caller's: left open)
            del info
    assert list(tmp_path.iterdir()) == []


def test_each_task_checks_its_workers_version(tmp_path, monkeypatch, fake_cluster):
    """A worker that joins after the start-up check (an adaptive cluster) is checked by the
    tasks it runs: another version is a WorkerVersionError (its error file says so), not a
    result of other code; without an installed version (a source folder) the task runs."""
    import bayespilot.campaign as C

    have = C._installed_version()
    assert have is not None  # (the tests run on an installed bayespilot)
    C.run_keyed([("a", _stub_task, (5,), {})], tmp_path, total=1, skipped=0, scheduler=None,
                workers=1, progress=False, connect_timeout=1.0)
    assert fake_cluster.submitted == [(have, _stub_task, 5)]  # (run as _on_this_version)
    assert C._on_this_version(have, _stub_task, 3) == {"x": 3}
    with pytest.raises(C.WorkerVersionError, match=f"has bayespilot {have}, the client 9.9.9"):
        C._on_this_version("9.9.9", _stub_task, 3)
    monkeypatch.setattr(C, "_installed_version", lambda: None)
    assert C._on_this_version("9.9.9", _stub_task, 3) == {"x": 3}


def test_the_fits_warnings_are_recorded_and_said_once(tmp_path):
    """A worker's warnings went to its stderr, one per fit (a 8-s run's stick-offset warning
    from every worker, buried the progress; on a remote cluster, lost): run_job records them
    in the result, and run_campaign says each kind once, naming the fits."""
    import warnings

    jobs = paper_study(1, tasks=("FD",), motion_gains=(1.0,), remnant_fractions=(0.2,),
                       method="fast", duration=8.0, **TINY)
    with pytest.warns(RuntimeWarning) as record:
        run_campaign(jobs, tmp_path, workers=1, progress=False)
    ours = [str(w.message) for w in record if "QuestionableRecordingWarning in" in str(w.message)]
    files = {j.key: json.loads((tmp_path / f"{j.key}.json").read_text()) for j in jobs}
    keys = sorted(k for k, d in files.items() if d["warnings"])
    assert keys and len(ours) == 1, (ours, files)
    assert ours[0].startswith(f"QuestionableRecordingWarning in {len(keys)} fit(s) "
                              f"({', '.join(keys)}), e.g. {keys[0]}: ")
    said = files[keys[0]]["warnings"]
    assert [w["category"] for w in said] == ["QuestionableRecordingWarning"]
    assert "control output u has a mean of" in said[0]["message"]
    job = next(j for j in jobs if j.key == keys[0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (none escapes run_job: the same, recorded)
        assert run_job(job)["warnings"] == said


def test_a_stopped_campaign_says_its_warnings_without_hiding_why(tmp_path, monkeypatch):
    """The fits' warnings are said when the run stops too, but with warnings made errors
    (-W error) the warning must not replace the error that stopped the run."""
    import warnings

    import bayespilot.campaign as C

    def run_keyed(tasks, out, *, to_json, **kwargs):
        to_json("k1", {"warnings": [{"category": "QuestionableRecordingWarning",
                                     "message": "offset"}]})
        raise CampaignError("lost the dask cluster: 1 of 2 tasks did not finish")

    monkeypatch.setattr(C, "run_keyed", run_keyed)
    with pytest.warns(RuntimeWarning, match="QuestionableRecordingWarning in 1 fit.s. .k1."):
        with pytest.raises(CampaignError, match="lost the dask cluster"):
            run_campaign(_jobs(), tmp_path / "a", workers=1, progress=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(CampaignError, match="lost the dask cluster"):
            run_campaign(_jobs(), tmp_path / "b", workers=1, progress=False)

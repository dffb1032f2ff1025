"""Tests of :mod:`bayespilot.batch` (``fit_batch``).

Short simulated recordings, the fast method with few starts.  Most tests run the batch's
tasks in this process (``campaign.run_keyed`` replaced, as tests/test_diagnose_batch.py
does); one runs it on a one-worker dask LocalCluster.  Every number is checked against the
same fit (or comparison) run directly here, or against sums computed here, not against
the batch's own files.
"""

from __future__ import annotations

import csv
import json
import math
import os

import numpy as np
import pytest

from bayespilot import campaign as C
from bayespilot.batch import CONDITION_FIELDS, SUMMARY_FIELDS, _plot_summary, fit_batch
from bayespilot.compare import compare, information_criteria, pool
from bayespilot.diagnose.batch import ResultConflictError, task_seed
from bayespilot.fit.fast import fit_fast
from bayespilot.io import read_recording, write_recording
from bayespilot.presets import PARAMETER_NAMES
from bayespilot.recording import Recording, RecordingError, _signals_digest
from bayespilot.simulate import simulate

#: Cheap fast fits: one start, a coarse delta_abs profile.
FAST = {"n_starts": 1, "profile_step": 0.02}
QUIET = {"method": "fast", "fit_options": FAST, "progress": False, "warm_cache": False}
#: A cheap chain: 16 walkers (the least for 8 parameters), 40 steps (not converged).
CHAIN = {"max_steps": 40, "n_walkers": 16, "check_every": 20}


def _write(folder, name, *, subject="s1", motion_gain=1.0, seed=0, duration=20.0,
           u_offset=0.0):
    """A short run written as a lab would (its metadata: the subject, no generator truth);
    ``u_offset``: that fraction of u's standard deviation added to u (a stick offset)."""
    # (a remnant gain given: F_n about 0.15, without the seconds its calibration takes)
    rec = simulate(task="FD", motion_gain=motion_gain, remnant_gain=0.07, seed=seed,
                   duration=duration).recording
    signals = dict(rec.signals)
    signals["u"] = signals["u"] + u_offset * np.std(signals["u"])
    meta = {"subject": subject} if subject is not None else {}
    os.makedirs(folder, exist_ok=True)
    write_recording(Recording(signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta),
                    folder / name)
    return str(folder / name)


def _run_here(monkeypatch):
    """fit_batch with its tasks run in this process (run_keyed replaced, no cluster): the
    same arguments the workers get; a task that raises leaves ``<key>.error.json`` (its
    context, the error's type and message), as run_keyed keeps it."""
    def run_keyed(tasks, out, *, to_json, **kwargs):
        errors = {}
        for key, fn, args, ctx in tasks:
            try:
                value = fn(*args)
            except Exception as exc:  # noqa: BLE001 - as run_keyed keeps a task's error
                errors[key] = f"{type(exc).__name__}: {exc}"
                C._write_json_atomic(out / f"{key}.error.json", {
                    "key": key, **ctx, "error": type(exc).__name__, "message": str(exc)})
                continue
            C._write_json_atomic(out / f"{key}.json", to_json(key, value))
        return len(tasks) - len(errors), errors

    monkeypatch.setattr(C, "run_keyed", run_keyed)


def _nothing_runs(monkeypatch):
    def run_keyed(*args, **kwargs):
        raise AssertionError("run_keyed was called")

    monkeypatch.setattr(C, "run_keyed", run_keyed)


@pytest.fixture(scope="module")
def recs(tmp_path_factory):
    """Two runs of subject s1 at K_theta 1 and one of s2 at 0.5, 20 s each."""
    folder = tmp_path_factory.mktemp("recs")
    return [_write(folder, "a", seed=1), _write(folder, "b", seed=2),
            _write(folder, "c", subject="s2", motion_gain=0.5, seed=3)]


def _csv(path):
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _direct(path, batch_seed):
    """The two fits of one recording run here, with the seed the batch gives it."""
    rec = read_recording(path)
    s = task_seed(batch_seed, [_signals_digest(rec)])
    return (rec, s, fit_fast(rec, threshold=True, seed=s, **FAST),
            fit_fast(rec, threshold=False, seed=s, **FAST))


def test_results_match_direct_fits(recs, tmp_path, monkeypatch):
    _run_here(monkeypatch)
    out = tmp_path / "out"
    summary = fit_batch(recs, out, seed=5, **QUIET)
    assert (summary.total, summary.completed, summary.skipped, summary.failed) == (3, 3, 0, 0)
    assert summary.what == "recordings" and summary.out_dir == out
    rows = {r["key"]: r for r in _csv(out / "summary.csv")}
    assert list(rows) == ["a", "b", "c"]
    assert list(_csv(out / "summary.csv")[0]) == list(SUMMARY_FIELDS)
    by_condition: dict[tuple, list] = {}
    for path in recs:
        key = os.path.basename(path)
        rec, s, f1, f0 = _direct(path, 5)
        got = json.loads((out / f"{key}.json").read_text())
        assert got["key"] == key and got["recording"] == path
        assert got["recording_digests"] == [_signals_digest(rec)]
        assert got["recording_metadata"][0]["motion_gain"] == rec.motion_gain
        assert (got["subject"], got["task"], got["motion_gain"]) == (
            rec.metadata["subject"], "FD", rec.motion_gain)
        assert got["settings"] == {"method": "fast", "noise": "white", "iterate": False,
                                   "oversample": 1, "compare": False, "nlive": None,
                                   "fit_options": FAST, "compare_options": {}, "seed": s,
                                   "batch_seed": 5}
        assert s != 5 and got["comparison"] is None and got["warnings"] == []
        for name, ref in (("fit_threshold", f1), ("fit_none", f0)):
            d = got[name]
            assert d["seed"] == s and d["threshold"] is ref.threshold
            assert d["params"] == pytest.approx(dict(ref.params), rel=1e-12)
            assert d["neg_log_lik"] == pytest.approx(ref.neg_log_lik, rel=1e-12)
            assert d["vaf"] == pytest.approx(ref.vaf, rel=1e-12)
            assert "steps" not in d
        # BIC by hand: 8 free parameters + the output-error variance with threshold, 7 + 1
        # without; n the samples after the 2-s start-up discard of a 20-s record
        assert f1.settings["discard"] == 2.0
        n = rec.n_samples - 200
        ic = got["information_criteria"]
        assert (ic["k_threshold"], ic["k_none"], ic["n"]) == (9, 8, n)
        assert ic == pytest.approx(information_criteria(f1.neg_log_lik, f0.neg_log_lik,
                                                        9, 8, n), rel=1e-12)
        delta_bic = (8 * math.log(n) + 2 * f0.neg_log_lik) - (9 * math.log(n)
                                                               + 2 * f1.neg_log_lik)
        assert ic["delta_bic"] == pytest.approx(delta_bic, rel=1e-10)
        row = rows[key]
        for p in PARAMETER_NAMES:
            assert float(row[p]) == pytest.approx(f1.params[p], rel=1e-12)
        assert float(row["neg_log_lik_none"]) == pytest.approx(f0.neg_log_lik, rel=1e-12)
        assert float(row["delta_bic"]) == pytest.approx(delta_bic, rel=1e-10)
        assert int(row["seed"]) == s and row["decision"] == row["error"] == ""
        assert "posterior" not in got and "posterior_error" not in got  # (not asked for)
        assert (row["delta_abs_posterior_median"] == row["delta_abs_posterior_hdi_low"]
                == row["converged"] == "")
        by_condition.setdefault((row["subject"], rec.motion_gain), []).append(
            (f1, f0, delta_bic))
    conditions = _csv(out / "conditions.csv")
    assert list(conditions[0]) == list(CONDITION_FIELDS)
    assert [(c["subject"], c["label"], int(c["n_runs"])) for c in conditions] == [
        ("s1", "s1, FD, K_theta = 1", 2), ("s2", "s2, FD, K_theta = 0.5", 1)]
    for c in conditions:
        runs = by_condition[(c["subject"], float(c["motion_gain"]))]
        deltas = [f1.params["delta_abs"] for f1, _, _ in runs]
        assert float(c["delta_abs_median"]) == pytest.approx(float(np.median(deltas)))
        assert float(c["delta_abs_min"]) == pytest.approx(min(deltas))
        assert float(c["delta_abs_max"]) == pytest.approx(max(deltas))
        assert float(c["sum_delta_neg_log_lik"]) == pytest.approx(
            sum(f0.neg_log_lik - f1.neg_log_lik for f1, f0, _ in runs), rel=1e-10)
        assert float(c["sum_delta_bic"]) == pytest.approx(sum(b for _, _, b in runs), rel=1e-10)
        assert c["log_bayes_factor"] == c["decision"] == ""
    assert (out / "summary.png").stat().st_size > 0


def test_a_failed_task_is_a_row_of_its_own_and_left_out_of_its_condition(recs, tmp_path,
                                                                          monkeypatch):
    import bayespilot.batch as B

    _run_here(monkeypatch)
    run = B._run_fit_task

    def diverging(recording, settings):  # (the task of b raises)
        if os.path.basename(recording.source) == "b":
            raise RuntimeError("the fit diverged")
        return run(recording, settings)

    monkeypatch.setattr(B, "_run_fit_task", diverging)
    out = tmp_path / "out"
    summary = fit_batch(recs[:2], out, seed=2, **QUIET)
    assert (summary.completed, summary.failed) == (1, 1) and list(summary.errors) == ["b"]
    rows = {r["key"]: r for r in _csv(out / "summary.csv")}
    assert rows["b"]["error"] == "RuntimeError: the fit diverged"
    assert rows["b"]["K_v"] == rows["b"]["delta_bic"] == "" and rows["a"]["error"] == ""
    assert int(rows["b"]["seed"]) == task_seed(2, [_signals_digest(read_recording(recs[1]))])
    (cond,) = _csv(out / "conditions.csv")
    assert int(cond["n_runs"]) == 1
    assert float(cond["delta_abs_median"]) == pytest.approx(float(rows["a"]["delta_abs"]))
    assert float(cond["sum_delta_bic"]) == pytest.approx(float(rows["a"]["delta_bic"]))
    # the next call retries it (its result replaces the error row)
    monkeypatch.setattr(B, "_run_fit_task", run)
    again = fit_batch(recs[:2], out, seed=2, **QUIET)
    assert (again.completed, again.skipped) == (1, 1)
    assert [r["error"] for r in _csv(out / "summary.csv")] == ["", ""]
    assert int(_csv(out / "conditions.csv")[0]["n_runs"]) == 2


def test_prediction_error_fits_count_the_noise_model(recs, tmp_path, monkeypatch):
    """noise='ar': k counts the AR coefficients as compare() counts a sampled AR model's,
    and n leaves out the p samples the noise model conditions on; the fit without threshold
    uses the order the fit with threshold chose (each choosing its own, the two -ln L were
    sums over other samples under other noise models)."""
    import functools

    from bayespilot import campaign

    _run_here(monkeypatch)
    asked = []  # (threshold, noise_order) of each fit the task makes
    chosen = campaign._fit_function

    def spy(method):
        @functools.wraps(chosen(method))  # (its signature: the options are checked by it)
        def fit(*args, **kw):
            asked.append((kw["threshold"], kw.get("noise_order")))
            return chosen(method)(*args, **kw)
        return fit

    monkeypatch.setattr(campaign, "_fit_function", spy)
    fit_batch(recs[:1], tmp_path / "out", noise="ar", **QUIET)
    got = json.loads((tmp_path / "out" / "a.json").read_text())
    rec = read_recording(recs[0])
    s = got["settings"]["seed"]
    assert asked == [(True, None), (False, got["fit_threshold"]["settings"]["noise"]["order"])]
    f1 = fit_fast(rec, threshold=True, seed=s, noise="ar", **FAST)
    p1 = f1.settings["noise"]["order"]
    f0 = fit_fast(rec, threshold=False, seed=s, noise="ar", noise_order=p1, **FAST)
    assert p1 >= 1 and got["settings"]["noise"] == "ar"
    assert got["fit_none"]["settings"]["noise"]["order"] == p1
    n = rec.n_samples - round(f1.settings["discard"] * rec.sample_rate_hz) - p1
    assert got["information_criteria"] == pytest.approx(
        information_criteria(f1.neg_log_lik, f0.neg_log_lik, 8 + p1 + 1, 7 + p1 + 1, n),
        rel=1e-12)
    assert got["fit_threshold"]["settings"]["noise"] == f1.settings["noise"]


def test_resume_skips_refuses_conflicts_and_keeps_earlier_rows(recs, tmp_path, monkeypatch):
    _run_here(monkeypatch)
    out = tmp_path / "out"
    fit_batch(recs[:2], out, **QUIET)
    files = {k: out / f"{k}.json" for k in ("a", "b")}
    before = {k: (f.read_bytes(), f.stat().st_mtime_ns) for k, f in files.items()}
    # an error file of a task that failed before: retried
    (out / "c.error.json").write_text(json.dumps({"key": "c", "error": "RuntimeError"}))
    again = fit_batch(recs, out, **QUIET)
    assert (again.total, again.completed, again.skipped) == (3, 1, 2)
    assert {k: (f.read_bytes(), f.stat().st_mtime_ns) for k, f in files.items()} == before
    assert "fit_threshold" in json.loads((out / "c.json").read_text())
    # other settings under the same keys: refused, naming the key and what differs; nothing runs
    _nothing_runs(monkeypatch)
    with pytest.raises(ResultConflictError, match=r"a\.json holds a fit of a from other "
                                                  r"settings: fit_options"):
        fit_batch(recs[:1], out, **{**QUIET, "fit_options": {"n_starts": 2}})
    with pytest.raises(ResultConflictError, match="batch_seed 0 there, 1 here"):
        fit_batch(recs[:1], out, seed=1, **QUIET)
    # another recording under the key a (another folder, the same stem)
    other = tmp_path / "other"
    with pytest.raises(ResultConflictError, match=r"holds a fit of a from other recordings"):
        fit_batch([_write(other, "a", seed=9)], out, **QUIET)
    # the same signals, K_theta corrected in the sidecar: another recording for the fit
    rec = read_recording(recs[0])
    write_recording(Recording(rec.signals, rec.sample_rate_hz, 0.75, rec.task,
                              dict(rec.metadata)), tmp_path / "fixed" / "a")
    with pytest.raises(ResultConflictError, match=r"the same signals with other sidecar "
                                                  r"values, which the fit reads \(motion_gain "
                                                  r"1.0 there, 0.75 here\)"):
        fit_batch([str(tmp_path / "fixed" / "a")], out, **QUIET)
    # refused before any task ran, with a new recording beside it
    with pytest.raises(ResultConflictError):
        fit_batch([_write(other, "new", seed=8), str(tmp_path / "fixed" / "a")], out, **QUIET)
    assert not (out / "new.json").exists()
    # a later call on one recording keeps the rows of the others made with these settings;
    # results made with other settings (under other keys) are left out
    _run_here(monkeypatch)
    fit_batch([_write(other, "d", seed=4)], out, seed=1, **QUIET)
    fit_batch(recs[2:], out, **QUIET)
    assert [r["key"] for r in _csv(out / "summary.csv")] == ["a", "b", "c"]
    assert [int(c["n_runs"]) for c in _csv(out / "conditions.csv")] == [2, 1]


def test_unreadable_and_unfittable_recordings_are_named_and_nothing_runs(recs, tmp_path,
                                                                        monkeypatch):
    _nothing_runs(monkeypatch)
    broken = tmp_path / "broken.csv"
    broken.write_text("not,a\nrecording,at all\n")
    out = tmp_path / "out"
    with pytest.raises(RecordingError, match="2 of 3 recordings cannot be read") as err:
        fit_batch([recs[0], str(tmp_path / "nope"), str(broken)], out, **QUIET)
    assert "nope" in str(err.value) and "broken" in str(err.value)
    short = _write(tmp_path, "short", seed=4, duration=0.3)
    with pytest.raises(ValueError, match=r"1 of 2 recordings cannot be fitted(.|\n)*short"):
        fit_batch([recs[0], short], out, **QUIET)
    rec = read_recording(recs[0])
    write_recording(rec, tmp_path / "copy")
    with pytest.raises(ValueError, match="same recording under two names"):
        fit_batch([recs[0], str(tmp_path / "copy")], out, **QUIET)
    assert not out.exists()
    # an output folder that cannot be made (a file there): said before anything runs
    out.write_text("")
    with pytest.raises(C.CampaignError, match="cannot write in the output folder"):
        fit_batch(recs[:1], out, **QUIET)


@pytest.mark.parametrize("options, said", [
    ({"method": "paper", "noise": "ar"}, r"noise='ar' \(a prediction-error fit\) goes with "
                                         r"method='fast'"),
    ({"iterate": True}, "iterate=True repeats Steps II and III of method='paper'"),
    ({"nlive": 30}, "give it with compare=True"),
    ({"compare_options": {"runs": 1}}, "give them with compare=True"),
    ({"compare": True, "nlive": 5}, "nlive must be"),
    ({"compare": True, "compare_options": {"seed": 1}}, "'seed' is not an option"),
    ({"fit_options": {"population": 8}}, "unknown option"),
    ({"fit_options": {"noise": "ar"}}, "give noise as fit_batch's own"),
    ({"oversample": 0}, "oversample"),
    ({"seed": -1}, "seed must be an integer >= 0"),
    ({"workers": 0}, "workers must be a positive integer, got 0"),
    ({"workers": 1, "scheduler": "tcp://127.0.0.1:1"}, "got 1 with a scheduler"),
    ({"connect_timeout": 0}, "connect_timeout must be a positive number"),
    ({"progress": "dots"}, "progress"),
    ({"posterior": "yes"}, "posterior must be True or False"),
    ({"sample_options": {"max_steps": 50}}, "give them with posterior=True"),
    ({"posterior": True, "sample_options": {"init": {"K_v": 1.0}}},
     "'init' is not an option of sample"),
    ({"posterior": True, "sample_options": {"seed": 1}}, "'seed' is not an option of sample"),
    ({"posterior": True, "sample_options": {"walkers": 16}}, "'walkers' is not an option"),
    ({"posterior": True, "sample_options": {"likelihood": "white"}}, "likelihood must be one of"),
    ({"posterior": True, "sample_options": {"max_steps": 0}}, "max_steps must be an integer >= 1"),
    ({"posterior": True, "sample_options": {"max_steps": 50, "min_steps": 60}},
     r"min_steps \(60\) must not exceed max_steps \(50\)"),
])
def test_bad_settings_are_refused(recs, tmp_path, monkeypatch, options, said):
    _nothing_runs(monkeypatch)
    with pytest.raises(ValueError, match=said):
        fit_batch(recs[:1], tmp_path / "out", **{**QUIET, **options})


def test_warnings_are_recorded_and_said_once(tmp_path, monkeypatch):
    _run_here(monkeypatch)
    off = _write(tmp_path, "off", seed=6, u_offset=0.5)  # a stick offset: each fit warns
    with pytest.warns(RuntimeWarning, match=r"QuestionableRecordingWarning in 1 recording\(s\) "
                                            r"\(off\)") as said:
        fit_batch([off], tmp_path / "out", **QUIET)
    assert len([w for w in said if "QuestionableRecordingWarning in" in str(w.message)]) == 1
    got = json.loads((tmp_path / "out" / "off.json").read_text())["warnings"]
    offset = [w for w in got if "mean of" in w["message"]]
    assert len(offset) == 1 and offset[0]["category"] == "QuestionableRecordingWarning"
    assert "the control output u has a mean" in offset[0]["message"]


def test_compare_per_run_and_pooled(recs, tmp_path, monkeypatch):
    _run_here(monkeypatch)
    out = tmp_path / "out"
    nested = {"savage_dickey_samples": False, "runs": 1}
    fit_batch(recs[:2], out, compare=True, nlive=30, compare_options=nested, **QUIET)
    got = {k: json.loads((out / f"{k}.json").read_text()) for k in ("a", "b")}
    assert got["a"]["settings"]["nlive"] == 30 and got["a"]["settings"]["compare"] is True
    rec = read_recording(recs[0])
    direct = compare(rec, seed=got["a"]["settings"]["seed"], nlive=30, **nested)
    assert got["a"]["comparison"]["log_bayes_factor"] == pytest.approx(
        direct.log_bayes_factor, rel=1e-9)
    assert got["a"]["comparison"]["decision"] == direct.decision
    rows = {r["key"]: r for r in _csv(out / "summary.csv")}
    for k in ("a", "b"):
        assert float(rows[k]["log_bayes_factor"]) == pytest.approx(
            got[k]["comparison"]["log_bayes_factor"])
        assert rows[k]["decision"] == got[k]["comparison"]["decision"]
    (cond,) = _csv(out / "conditions.csv")
    lbf = [got[k]["comparison"]["log_bayes_factor"] for k in ("a", "b")]
    err = [got[k]["comparison"]["log_bayes_factor_err"] for k in ("a", "b")]
    assert float(cond["log_bayes_factor"]) == pytest.approx(sum(lbf))
    assert float(cond["log_bayes_factor_err"]) == pytest.approx(math.hypot(*err))
    ref = pool([got[k]["comparison"] for k in ("a", "b")], label="s1, FD, K_theta = 1")
    assert cond["decision"] == ref.decision and cond["label"] == ref.label


def test_summary_figure_marks_each_run():
    """Each run a point (its fit), marked by delta_bic's sign, the runs of a condition side
    by side (0.15 apart, in key order) in its column, and a run's posterior 90 % HDI (where
    it was sampled) an error bar from its low to its high end."""
    rows = [{"key": k, "subject": "s1", "task": "FD", "motion_gain": g, "delta_abs": d,
             "delta_bic": b, "decision": "", "error": "",
             "delta_abs_posterior_hdi_low": lo, "delta_abs_posterior_hdi_high": hi}
            for k, g, d, b, lo, hi in (("a", 1.0, 0.01, 5.0, 0.008, 0.0105),
                                       ("b", 1.0, 0.002, -1.0, "", ""),
                                       ("c", 0.5, 0.007, 3.0, 0.0072, 0.009))]
    rows.append({"key": "e", "error": "RuntimeError: x"})
    conditions = [{"subject": "s1", "task": "FD", "motion_gain": g,
                   "label": f"s1, FD, K_theta = {g:g}"} for g in (0.5, 1.0)]
    from matplotlib.collections import PathCollection

    fig = _plot_summary(rows, conditions)
    try:
        ax = fig.axes[0]
        points = {c.get_label(): c.get_offsets().tolist() for c in ax.collections
                  if isinstance(c, PathCollection)}  # (the scatters; the bars are lines)
        assert points == {r"$\Delta$BIC > 0 (threshold)": [[0.925, 0.01], [0, 0.007]],
                          r"$\Delta$BIC $\leq$ 0 (none)": [[1.075, 0.002]]}
        (bars,) = ax.containers
        assert bars.get_label() == "posterior 90 % HDI"
        (segments,) = [c.get_segments() for c in bars.lines[2]]
        assert np.allclose(np.array(segments), [[[0.925, 0.008], [0.925, 0.0105]],
                                                [[0, 0.0072], [0, 0.009]]], rtol=1e-12)
        assert [t.get_text() for t in ax.get_xticklabels()] == [
            r"s1, FD, $K_\theta$ = 0.5", r"s1, FD, $K_\theta$ = 1"]
        assert "delta" in ax.get_ylabel() and "IPUT" in ax.get_ylabel()
        assert ax.get_title() == "The threshold of 3 runs in 2 conditions"
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)
    for title, said in ((False, ""), ("Fig. 3", "Fig. 3")):  # (none; one's own)
        assert _plot_summary(rows[:1], conditions[1:], title=title).axes[0].get_title() == said
    with pytest.raises(TypeError, match="title must be True"):
        _plot_summary(rows, conditions, title=None)


def test_on_a_local_cluster(recs, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.error.json").write_text(json.dumps({"key": "a", "error": "RuntimeError"}))
    with pytest.warns(RuntimeWarning, match="ConvergenceWarning in 1 recording"):
        summary = fit_batch(recs[:1], out, workers=1, posterior=True, sample_options=CHAIN,
                            **QUIET)
    assert (summary.total, summary.completed, summary.failed) == (1, 1, 0)
    assert not (out / "a.error.json").exists()  # retried, and its error file removed
    got = json.loads((out / "a.json").read_text())
    _, s, f1, f0 = _direct(recs[0], 0)
    assert got["settings"]["seed"] == s
    assert got["fit_threshold"]["neg_log_lik"] == pytest.approx(f1.neg_log_lik, rel=1e-9)
    assert got["fit_none"]["neg_log_lik"] == pytest.approx(f0.neg_log_lik, rel=1e-9)
    assert got["host"] and got["versions"]["bayespilot"]
    # the posterior came back from the worker (pickled) and was written here
    from bayespilot.sample import Posterior

    written = Posterior.from_netcdf(out / "a.nc")
    assert written.seed == s and written.idata.posterior.sizes["chain"] == 16
    assert got["posterior"]["summary"] == _as_stored(written.summary())


def _as_stored(x):
    """``x`` as a result file holds it: NaN (and infinities) as None, tuples as lists."""
    if isinstance(x, dict):
        return {k: _as_stored(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_as_stored(v) for v in x]
    return None if isinstance(x, float) and not math.isfinite(x) else x


def _sampled_here(path, batch_seed):
    """The chain of one recording run here with sample() (CHAIN's options written out, and
    min_steps = max_steps as ``bayespilot sample --max-steps 40`` sets it), with the seed the
    batch gives it."""
    import warnings

    from bayespilot.model import paper_model
    from bayespilot.sample import sample

    rec = read_recording(path)
    s = task_seed(batch_seed, [_signals_digest(rec)])
    with warnings.catch_warnings():  # (40 steps: not converged, said)
        warnings.simplefilter("ignore")
        return s, sample(rec, paper_model(threshold=True), seed=s, progress=False,
                         max_steps=40, min_steps=40, n_walkers=16, check_every=20)


def test_the_posterior_is_sample_run_with_the_recorded_seed(recs, tmp_path, monkeypatch):
    import arviz

    from bayespilot.sample import Posterior

    _run_here(monkeypatch)
    out = tmp_path / "out"
    with pytest.warns(RuntimeWarning, match=r"ConvergenceWarning in 2 recording\(s\) \(a, b\)"):
        summary = fit_batch(recs[:2], out, posterior=True, sample_options=CHAIN, **QUIET)
    assert (summary.completed, summary.failed) == (2, 0)
    rows = {r["key"]: r for r in _csv(out / "summary.csv")}
    for path in recs[:2]:
        key = os.path.basename(path)
        got = json.loads((out / f"{key}.json").read_text())
        s, direct = _sampled_here(path, 0)
        assert got["settings"]["seed"] == s and got["settings"]["posterior"] is True
        assert got["settings"]["sample_options"] == {"likelihood": "eq4", "max_steps": 40,
                                                     "min_steps": 40, "n_walkers": 16,
                                                     "check_every": 20}
        # the fits are the batch's as without the posterior
        _, _, f1, _ = _direct(path, 0)
        assert got["fit_threshold"]["neg_log_lik"] == pytest.approx(f1.neg_log_lik, rel=1e-12)
        # the same chain, number for number: the summary bayespilot sample --json writes
        assert set(direct.summary()) == set(PARAMETER_NAMES)
        assert got["posterior"]["summary"] == _as_stored(direct.summary())
        assert (got["posterior"]["converged"], got["posterior"]["steps"]) == (False, 40)
        assert got["posterior"]["file"] == f"{key}.nc"
        assert any(w["category"] == "ConvergenceWarning" for w in got["warnings"])
        # the draws, read back with arviz (and as a Posterior)
        idata = arviz.from_netcdf(str(out / f"{key}.nc"))
        n_draws = direct.idata.posterior.sizes["draw"]
        assert n_draws > 0 and idata.posterior["delta_abs"].shape == (16, n_draws)
        for name in PARAMETER_NAMES:
            np.testing.assert_array_equal(idata.posterior[name].values,
                                          direct.idata.posterior[name].values)
        back = Posterior.from_netcdf(out / f"{key}.nc")
        assert back.seed == s and back.converged is False
        # summary.csv: delta_abs's median and 90 % HDI
        median = direct.summary()["delta_abs"]["median"]
        low, high = direct.credible_interval("delta_abs", 0.9)
        row = rows[key]
        assert float(row["delta_abs_posterior_median"]) == median
        assert (float(row["delta_abs_posterior_hdi_low"]),
                float(row["delta_abs_posterior_hdi_high"])) == (low, high)
        assert low < median < high
        assert row["converged"] == "False" and row["posterior_error"] == row["error"] == ""
    # conditions.csv has nothing of the posteriors (module docs: not pooled)
    assert list(_csv(out / "conditions.csv")[0]) == list(CONDITION_FIELDS)


def test_a_sampling_that_fails_is_recorded_and_the_fits_kept(recs, tmp_path, monkeypatch):
    import functools
    import sys

    module = sys.modules["bayespilot.sample"]
    real = module.sample

    @functools.wraps(real)  # (its signature: the batch checks the options by it)
    def sample(recording, *args, **kwargs):  # (b's chain fails)
        if os.path.basename(recording.source) == "b":
            raise FloatingPointError("the chain diverged (made to fail by the test)")
        return real(recording, *args, **kwargs)

    monkeypatch.setattr(module, "sample", sample)
    _run_here(monkeypatch)
    out = tmp_path / "out"
    out.mkdir()
    (out / "b.nc").write_bytes(b"an earlier posterior of b")  # (not this result's: removed)
    with pytest.warns(RuntimeWarning, match=r"the posterior could not be sampled for 1 "
                                            r"recording\(s\) \(b\), e.g. b: FloatingPointError: "
                                            r"the chain diverged \(made to fail by the test\); "
                                            r"their fits are kept"):
        summary = fit_batch(recs[:2], out, posterior=True, sample_options=CHAIN, **QUIET)
    assert (summary.completed, summary.failed) == (2, 0)
    got = json.loads((out / "b.json").read_text())
    assert got["posterior"] is None
    assert got["posterior_error"] == ("FloatingPointError: the chain diverged (made to fail by "
                                      "the test)")
    _, s, f1, f0 = _direct(recs[1], 0)
    assert got["settings"]["seed"] == s
    for name, ref in (("fit_threshold", f1), ("fit_none", f0)):
        assert got[name]["params"] == pytest.approx(dict(ref.params), rel=1e-12)
        assert got[name]["neg_log_lik"] == pytest.approx(ref.neg_log_lik, rel=1e-12)
    assert not (out / "b.nc").exists() and (out / "a.nc").is_file()
    assert "posterior_error" not in json.loads((out / "a.json").read_text())
    rows = {r["key"]: r for r in _csv(out / "summary.csv")}
    assert rows["b"]["posterior_error"] == got["posterior_error"] and rows["b"]["error"] == ""
    assert rows["b"]["delta_abs_posterior_median"] == rows["b"]["converged"] == ""
    assert float(rows["b"]["delta_abs"]) == pytest.approx(f1.params["delta_abs"], rel=1e-12)
    assert (rows["a"]["posterior_error"] == ""
            and rows["a"]["delta_abs_posterior_median"] != "")
    assert int(_csv(out / "conditions.csv")[0]["n_runs"]) == 2  # (b's fits count)
    # the next call samples b again (its fits again too, the same), not a
    sampled = []

    @functools.wraps(real)
    def again(recording, *args, **kwargs):
        sampled.append(os.path.basename(recording.source))
        return real(recording, *args, **kwargs)

    monkeypatch.setattr(module, "sample", again)
    with pytest.warns(RuntimeWarning, match="ConvergenceWarning in 1 recording"):
        again = fit_batch(recs[:2], out, posterior=True, sample_options=CHAIN, **QUIET)
    assert (again.completed, again.skipped, sampled) == (1, 1, ["b"])
    now = json.loads((out / "b.json").read_text())
    assert "posterior_error" not in now and now["posterior"]["file"] == "b.nc"
    assert (now["fit_threshold"]["params"], now["fit_threshold"]["neg_log_lik"]) == (
        got["fit_threshold"]["params"], got["fit_threshold"]["neg_log_lik"])
    assert (out / "b.nc").is_file()
    assert [r["posterior_error"] for r in _csv(out / "summary.csv")] == ["", ""]


def test_resume_compares_the_posterior_settings(recs, tmp_path, monkeypatch):
    _run_here(monkeypatch)
    out = tmp_path / "out"
    fit_batch(recs[:1], out, **QUIET)  # (without the posterior)
    _nothing_runs(monkeypatch)
    with pytest.raises(ResultConflictError, match=r"a\.json holds a fit of a from other "
                                                  r"settings: posterior not set there, True here, "
                                                  r"sample_options not set there, \{'likelihood'"):
        fit_batch(recs[:1], out, posterior=True, sample_options=CHAIN, **QUIET)
    # made with it: the same options (sample's defaults written out or not) are done ...
    _run_here(monkeypatch)
    post = tmp_path / "post"
    fit_batch(recs[:1], post, posterior=True, sample_options=CHAIN, **QUIET)
    files = [post / "a.json", post / "a.nc"]
    before = [(f.read_bytes(), f.stat().st_mtime_ns) for f in files]
    again = fit_batch(recs[:1], post, posterior=True,
                      sample_options={**CHAIN, "likelihood": "eq4", "min_steps": 40}, **QUIET)
    assert (again.completed, again.skipped) == (0, 1)
    assert [(f.read_bytes(), f.stat().st_mtime_ns) for f in files] == before
    # ... other options, or none, are not
    _nothing_runs(monkeypatch)
    with pytest.raises(ResultConflictError, match=r"other settings: sample_options .*"
                                                  r"'max_steps': 60"):
        fit_batch(recs[:1], post, posterior=True, sample_options={**CHAIN, "max_steps": 60},
                  **QUIET)
    with pytest.raises(ResultConflictError, match=r"other settings: posterior True there, not set "
                                                  r"here"):
        fit_batch(recs[:1], post, **QUIET)
    # a result whose posterior file is gone is run again
    (post / "a.nc").unlink()
    _run_here(monkeypatch)
    again = fit_batch(recs[:1], post, posterior=True, sample_options=CHAIN, **QUIET)
    assert (again.completed, again.skipped) == (1, 0) and (post / "a.nc").is_file()


def test_the_tables_count_each_run_once_and_say_what_they_leave_out(recs, tmp_path,
                                                                     monkeypatch):
    """Review of the day: a recording under a new key (moved: its folder name now in its
    key) left its old <key>.json in the folder, and conditions.csv counted the run twice;
    a subject corrected in the sidecar kept the run in its old condition; a run with other
    settings cut the tables to its rows without a word; and with no result left, an old
    summary.png stayed."""
    import shutil
    import warnings

    from bayespilot.diagnose.batch import SummaryScopeWarning

    _run_here(monkeypatch)
    out = tmp_path / "out"
    fit_batch(recs[:2], out, **QUIET)  # a, b: subject s1
    # b moved to a folder whose stem clashes with another b: its key is now <parent>_b
    moved = tmp_path / "x"
    moved.mkdir()
    for ext in (".csv", ".json"):
        shutil.copy(recs[1] + ext, moved / ("b" + ext))
    other = _write(tmp_path / "y", "b", seed=7)  # another run, also stem b
    with pytest.warns(SummaryScopeWarning, match=r"1 result file\(s\) .* hold a recording "
                      r"that another key holds too .*\(b\)"):
        fit_batch([recs[0], str(moved / "b"), other], out, **QUIET)
    rows = _csv(out / "summary.csv")
    assert sorted(r["key"] for r in rows) == ["a", "x_b", "y_b"]
    (cond,) = _csv(out / "conditions.csv")
    assert int(cond["n_runs"]) == 3  # a, x_b (= the old b) and y_b: each once
    want = math.fsum(float(r["delta_bic"]) for r in rows)
    assert float(cond["sum_delta_bic"]) == pytest.approx(want, rel=1e-12)
    # a's subject corrected in its sidecar: no refit, a's row in its new condition
    side = json.loads(open(recs[0] + ".json").read())
    fixed = tmp_path / "z"
    fixed.mkdir()
    shutil.copy(recs[0] + ".csv", fixed / "a.csv")
    (fixed / "a.json").write_text(json.dumps({**side, "subject": "s9"}))
    before = json.loads((out / "a.json").read_text())
    again = fit_batch([str(fixed / "a"), str(moved / "b"), other], out, **QUIET)
    assert (again.completed, again.skipped) == (0, 3)
    after = json.loads((out / "a.json").read_text())
    assert after["subject"] == "s9" and after["fit_threshold"] == before["fit_threshold"]
    conds = {r["subject"]: int(r["n_runs"]) for r in _csv(out / "conditions.csv")}
    assert conds == {"s1": 2, "s9": 1}
    # other settings in the same folder: their rows only, and said
    with pytest.warns(SummaryScopeWarning, match=r"4 result file\(s\) .* made with other "
                      r"settings are left out"):
        fit_batch([recs[2]], out, **dict(QUIET, seed=5))
    assert [r["key"] for r in _csv(out / "summary.csv")] == ["c"]
    # no result with these settings: no figure of other results left behind
    png = out / "summary.png"
    assert png.is_file()
    empty = tmp_path / "empty"
    fit_batch([recs[2]], empty, **QUIET)
    (empty / "c.json").unlink()
    shutil.copy(png, empty / "summary.png")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SummaryScopeWarning)
        from bayespilot.batch import _batch_settings, _write_summaries

        _write_summaries(empty, _batch_settings(json.loads((out / "c.json").read_text())))
    assert not (empty / "summary.png").exists()
    assert _csv(empty / "conditions.csv") == []


def test_prediction_error_fits_are_compared_under_their_noise_model(recs):
    """noise='ar' with compare: the comparison's likelihood is compare's AR output-error one
    (recorded in the settings, so the command and a Python call resume each other), unless
    given; with white noise compare's default (Eq. 4) stays."""
    from bayespilot.batch import _options

    ar = _options("fast", "ar", False, 1, True, None, None, None)
    assert ar["compare_options"] == {"likelihood": "coloured"}
    given = _options("fast", "ar", False, 1, True, None, None, {"likelihood": "eq4"})
    assert given["compare_options"] == {"likelihood": "eq4"}
    assert _options("fast", "white", False, 1, True, None, None, None)["compare_options"] == {}

"""Tests of :mod:`bayespilot.diagnose.batch` and ``bayespilot diagnose-batch``.

The batch runs for real on a one-worker dask LocalCluster, on short simulated
recordings with few candidates; each result is checked against the same
diagnosis run directly in this process (the reference), not against itself.
"""

from __future__ import annotations

import csv
import json
import math
import os

import pytest

from bayespilot.campaign import CampaignError
from bayespilot.cli import main
from bayespilot.diagnose import diagnose, diagnose_pooled
from bayespilot.diagnose.batch import (ResultConflictError, batch_summary_rows, diagnose_batch,
                                       plan_batch, task_seed)
from bayespilot.io import read_recording, write_recording
from bayespilot.recording import (QuestionableRecordingWarning, Recording, RecordingError,
                                  _signals_digest)
from bayespilot.simulate import simulate

#: What a 20-s record is told when read (a QuestionableRecordingWarning), not refused.
SHORT = r"the record is 20 s long, much shorter than the 81\.92 s runs of Pool et al\. \(2012\)"
OPTIONS = {"n_bootstrap": 0, "candidates": ["motion-washout", "time-varying-gains"]}


def _write(folder, name, *, subject, motion_gain=1.0, seed=0, duration=20.0):
    """A short run written as a lab would (its metadata: the subject, no generator truth)."""
    rec = simulate(task="FD", motion_gain=motion_gain, remnant_fraction=0.15, seed=seed,
                   duration=duration).recording
    meta = {"subject": subject} if subject is not None else {}
    stem = folder / name
    write_recording(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta),
                    stem)
    return str(stem)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    folder = tmp_path_factory.mktemp("recs")
    return [_write(folder, "s1-run1", subject="s1", seed=1),
            _write(folder, "s1-run2", subject="s1", seed=2),
            _write(folder, "s2-run1", subject="s2", motion_gain=0.75, seed=3)]


@pytest.fixture(scope="module")
def lone_folder(tmp_path_factory):
    """A folder with one recording (and nothing else a reader could take for one)."""
    folder = tmp_path_factory.mktemp("lone")
    _write(folder, "s9-run1", subject="s9", seed=9)
    (folder / "notes.txt").write_text("not a recording")
    return folder


def _read_all(paths):
    with pytest.warns(QuestionableRecordingWarning, match=SHORT) as said:  # said, not refused
        recs = [read_recording(p) for p in paths]
    assert len(said) == len(paths)  # one per recording, naming it
    assert [str(w.message).split(": ")[0] for w in said] == [str(p) for p in paths]
    return recs


def test_plan_keys_and_groups(recordings, tmp_path):
    recs = _read_all(recordings)
    alone = plan_batch(recordings, recs)
    assert [t.key for t in alone] == ["s1-run1", "s1-run2", "s2-run1"]
    assert [t.subject for t in alone] == ["s1", "s1", "s2"] and not any(t.pooled for t in alone)
    pooled = plan_batch(recordings, recs, pool=True)
    assert [(t.key, t.paths) for t in pooled] == [
        ("s1_FD_k1", tuple(recordings[:2])), ("s2_FD_k0.75", (recordings[2],))]
    assert pooled[0].pooled and not pooled[1].pooled
    # given in another order, a pooled task's runs are the same, in the files' order (run j is
    # seeded s + j from the task's seed s: the paths' order changed the bootstrap's draws)
    assert plan_batch(recordings[::-1], recs[::-1], pool=True) == pooled
    # the same stem in two folders: the folder goes into the key; the same file twice: refused
    other = str(tmp_path / "elsewhere" / "s1-run1")
    keys = [t.key for t in plan_batch([recordings[0], other], recs[:1] * 2)]
    assert keys == [f"{os.path.basename(os.path.dirname(recordings[0]))}_s1-run1",
                    "elsewhere_s1-run1"]
    with pytest.raises(ValueError, match="same result name"):
        plan_batch([recordings[0]] * 2, recs[:1] * 2)
    with pytest.raises(ValueError, match="same recording twice"):
        plan_batch([recordings[0]] * 2, recs[:1] * 2, pool=True)
    nosubject = Recording(recs[0].signals, recs[0].sample_rate_hz, recs[0].motion_gain,
                          recs[0].task, {})
    with pytest.raises(ValueError, match="no 'subject'"):
        plan_batch(["a"], [nosubject], pool=True)
    named = [Recording(recs[0].signals, recs[0].sample_rate_hz, recs[0].motion_gain,
                       recs[0].task, {"subject": s}) for s in ("a b", "a-b")]
    with pytest.raises(ValueError, match="subjects whose names give the same result name"):
        plan_batch(["x", "y"], named, pool=True)


def test_batch_matches_direct_diagnoses_and_resumes(recordings, tmp_path):
    out = tmp_path / "b"
    s1 = diagnose_batch(recordings, out, pool=True, seed=3, workers=1, progress=False,
                        warm_cache=False, **OPTIONS)
    assert (s1.total, s1.completed, s1.skipped, s1.failed) == (2, 2, 0, 0)
    assert "2 diagnoses: 2 run" in str(s1)
    recs = _read_all(recordings)
    # each diagnosis with its own seed, drawn from the batch's and its recordings' content
    seeds = {"s1_FD_k1": task_seed(3, [_signals_digest(r) for r in recs[:2]]),
             "s2_FD_k0.75": task_seed(3, [_signals_digest(recs[2])])}
    assert len(set(seeds.values()) | {3}) == 3
    direct = {"s1_FD_k1": diagnose_pooled(recs[:2], seed=seeds["s1_FD_k1"], **OPTIONS),
              "s2_FD_k0.75": diagnose(recs[2], seed=seeds["s2_FD_k0.75"], **OPTIONS)}
    for key, ref in direct.items():
        got = json.loads((out / f"{key}.json").read_text())
        assert got["key"] == key and got["settings"]["seed"] == seeds[key]
        assert got["settings"]["batch_seed"] == 3
        d = got["diagnosis"]
        assert d["settings"]["seed"] == seeds[key]
        assert d["physics"] == ref.physics
        for a, b in zip(d["ranking"], ref.ranking):
            assert a["physics"] == b.physics
            assert a["delta_neg_log_lik"] == pytest.approx(b.delta_neg_log_lik, rel=1e-6,
                                                           abs=1e-6)
    rows = list(csv.DictReader((out / "summary.csv").open()))
    assert [(r["key"], r["n_runs"], r["physics"], r["seed"]) for r in rows] == [
        ("s1_FD_k1", "2", direct["s1_FD_k1"].physics, str(seeds["s1_FD_k1"])),
        ("s2_FD_k0.75", "1", direct["s2_FD_k0.75"].physics, str(seeds["s2_FD_k0.75"]))]
    for r in rows:  # the nearest miss, from the direct diagnosis's ranking
        p_min, name = min((c.p_value, c.physics) for c in direct[r["key"]].ranking
                          if math.isfinite(c.p_value))
        assert r["smallest_p_candidate"] == name
        assert float(r["smallest_p_value"]) == pytest.approx(p_min, rel=1e-5)

    # again: nothing redone, files untouched; other settings in the same folder: refused
    stamp = [(out / f"{k}.json").stat().st_mtime_ns for k in direct]
    s2 = diagnose_batch(recordings, out, pool=True, seed=3, workers=1, progress=False,
                        **OPTIONS)
    assert (s2.completed, s2.skipped) == (0, 2)
    assert [(out / f"{k}.json").stat().st_mtime_ns for k in direct] == stamp
    with pytest.raises(CampaignError, match="from other settings: batch_seed 3 there, 4 here; "):
        diagnose_batch(recordings, out, pool=True, seed=4, workers=1, progress=False,
                       **OPTIONS)


def test_summary_reports_an_error_file(recordings, tmp_path):
    recs = _read_all(recordings[:1])
    tasks = plan_batch(recordings[:1], recs)
    (tmp_path / "s1-run1.error.json").write_text(json.dumps(
        {"key": "s1-run1", "error": "RuntimeError", "message": "worker lost"}))
    (row,) = batch_summary_rows(tasks, tmp_path)
    assert row["error"] == "RuntimeError: worker lost" and row["physics"] == ""
    assert row["smallest_p_value"] == ""


def test_bad_input_runs_nothing(recordings, tmp_path):
    out = tmp_path / "never"
    with pytest.raises(RecordingError, match=r"(?s)1 of 2 recordings cannot be read.*nope"):
        diagnose_batch([recordings[0], str(tmp_path / "nope")], out, workers=1)
    with pytest.raises(ValueError, match="noise_passes"):
        diagnose_batch(recordings[:1], out, noise_passes=7, workers=1)
    with pytest.raises(ValueError, match="seed"):
        diagnose_batch(recordings[:1], out, seed=-1, workers=1)
    assert not out.exists()


def test_cli_folder_and_errors(lone_folder, tmp_path, capsys):
    folder = str(lone_folder)
    out = tmp_path / "cli"
    code = main(["diagnose-batch", folder, "--out", str(out), "--bootstrap", "0",
                 "--workers", "1", "--reports", "-q"])
    stdout, err = capsys.readouterr()
    assert code == 0, err
    lines = stdout.splitlines()
    assert lines[0].startswith("key,n_runs,subject,task,motion_gain,physics")
    assert len(lines) == 2 and lines[1].startswith("s9-run1,1,s9,FD,1.0,")
    assert [p.name for p in out.glob("*.json")] == ["s9-run1.json"]
    assert (out / "s9-run1" / "report.html").stat().st_size > 1000
    assert (out / "summary.png").stat().st_size > 1000
    assert "warning: " in err and "20 s long" in err
    for argv, message in (([str(tmp_path / "nope")], "cannot be read"),
                          ([str(tmp_path)], "a folder without recordings"),
                          ([folder, "--workers", "1", "--scheduler", "tcp://127.0.0.1:9"],
                           "not both")):
        code = main(["diagnose-batch", *argv, "--out", str(tmp_path / "x"), "-q"])
        err = capsys.readouterr().err
        assert code == 2 and message in err, err


def test_plot_batch_cells():
    """The figure's cells are -log10 p of each candidate; untested ones are masked."""
    import matplotlib.pyplot as plt

    from bayespilot.diagnose import NAMES
    from bayespilot.diagnose.report import plot_batch

    level = {"level_per_candidate": 0.002}
    d1 = {"physics": "motion-washout", "settings": level,
          "ranking": [{"physics": "motion-washout", "p_value": 1e-4, "testable": True},
                      {"physics": "otolith-channel", "p_value": None, "testable": False},
                      {"physics": "threshold-shape", "p_value": 0.5, "testable": True}]}
    d2 = {"physics": "none", "settings": level,
          "ranking": [{"physics": "time-varying-gains", "p_value": 0.01, "testable": True}]}
    fig = plot_batch([("a", d1), ("b", d2)])
    ax = fig.axes[0]
    z = ax.images[0].get_array()
    assert z[0, NAMES.index("motion-washout")] == pytest.approx(4.0)
    assert z[0, NAMES.index("threshold-shape")] == pytest.approx(-math.log10(0.5))
    assert z[1, NAMES.index("time-varying-gains")] == pytest.approx(2.0)
    assert z.mask[0, NAMES.index("otolith-channel")] and z.mask[1, 0]
    assert len(ax.patches) == 1  # the chosen washout's box
    assert len([ln for ln in ax.lines if ln.get_marker() == "."]) == 1  # below the level
    assert [t.get_text() for t in ax.get_yticklabels()] == ["a: motion-washout", "b: none"]
    plt.close(fig)


def test_task_posterior_pooled_and_a_failure_kept(tmp_path, monkeypatch):
    """posterior=True: a pooled task carries the shared parameters' grid posterior, the same as
    shared_posterior run here on a direct diagnosis, and summary.csv's cell reads it; a single
    run whose sampling fails keeps its diagnosis with the error recorded."""
    import bayespilot.diagnose as dg
    from bayespilot import presets
    from bayespilot.diagnose import get_extension, shared_posterior
    from bayespilot.diagnose.batch import DiagnoseTask, run_diagnose_task
    from bayespilot.model import paper_model

    model = get_extension("motion-washout").build(paper_model())
    p = dict(presets.paper_parameters("FD"), omega_w=0.8)
    recs = [simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063, seed=s,
                     duration=40.96).recording for s in (22, 23)]
    opts = {"n_bootstrap": 0, "candidates": ["motion-washout"], "seed": 0}
    task = DiagnoseTask("s1_FD_k1", ("a", "b"), "s1", "FD", 1.0)
    # (on a coarse grid, here and in the task: the grid's points are the posterior's cost,
    # and what is tested is that the task's is the direct call's)
    monkeypatch.setattr(dg, "shared_posterior",
                        lambda res, recs, **k: shared_posterior(res, recs, n_grid=5, **k))
    res, _ = run_diagnose_task(task, recs, dict(opts, posterior=True))
    ref = diagnose_pooled(recs, **opts)
    shared_posterior(ref, recs, n_grid=5)
    assert res.posterior.grid[0].size == 5
    assert res.physics == ref.physics == "motion-washout"
    got, want = res.posterior.marginals["omega_w"], ref.posterior.marginals["omega_w"]
    assert got["median"] == pytest.approx(want["median"], rel=1e-9)
    assert got["interval"] == pytest.approx(want["interval"], rel=1e-9)
    (tmp_path / "s1_FD_k1.json").write_text(json.dumps({"key": task.key,
                                                        "diagnosis": res.to_dict()}))
    row = batch_summary_rows([task], tmp_path)[0]
    assert json.loads(row["posterior"]) == {"omega_w": [got["median"], *got["interval"]]}

    def fail(*a, **k):
        raise RuntimeError("the chain diverged")

    monkeypatch.setattr(dg, "sample_chosen", fail)
    one = DiagnoseTask("a", ("a",), "s1", "FD", 1.0)
    res1, _ = run_diagnose_task(one, recs[:1], dict(opts, posterior=True))
    assert res1.physics == "motion-washout" and res1.posterior is None
    assert res1.settings["posterior_error"] == "RuntimeError: the chain diverged"
    with pytest.raises(ValueError, match="posterior"):
        diagnose_batch(["x"], tmp_path / "o", posterior="yes")


@pytest.fixture(scope="module")
def done_without_reports(tmp_path_factory):
    """A folder of one recording, and a batch of it run by the CLI without --reports."""
    folder = tmp_path_factory.mktemp("done")
    stem = _write(folder, "s7-run1", subject="s7", seed=7)
    out = tmp_path_factory.mktemp("done-out") / "out"
    code = main(["diagnose-batch", str(folder), "--out", str(out), "--bootstrap", "0",
                 "--workers", "1", "-q"])
    assert code == 0
    assert (out / "s7-run1.json").is_file() and not (out / "s7-run1").exists()
    return folder, stem, out


def test_cli_reports_on_a_finished_batch_says_none_were_written(done_without_reports, capsys):
    """--reports on a folder whose diagnoses finished without: nothing is redone, no report can
    be made from <key>.json, and the command says so (it said '... with its report in
    <key>/')."""
    folder, stem, out = done_without_reports
    capsys.readouterr()
    before = (out / "s7-run1.json").stat().st_mtime_ns
    code = main(["diagnose-batch", str(folder), "--out", str(out), "--bootstrap", "0",
                 "--workers", "1", "--reports"])
    stdout, err = capsys.readouterr()
    assert code == 0, err
    assert "1 diagnosis: 0 run, 1 already done" in stdout
    assert (out / "s7-run1.json").stat().st_mtime_ns == before and not (out / "s7-run1").exists()
    (warning,) = [ln for ln in err.splitlines() if "report" in ln]
    assert warning.startswith("bayespilot: warning: 1 diagnosis finished before, without a "
                              "report, is not redone and gets no report")
    assert "(s7-run1)" in warning and "delete its <key>.json and run again" in warning
    wrote = stdout.splitlines()[-1]
    assert wrote.startswith("wrote ") and "except for the diagnoses finished before" in wrote
    assert not wrote.endswith("with its report in <key>/")


def test_resume_compares_resolved_recordings_and_defaults(done_without_reports, tmp_path):
    """The same recording as its .csv or .json path (the CLI stored the stem), and a Python
    call leaving alpha, n_calibrate (and seed) at their defaults where the CLI stored them:
    the finished diagnosis is taken, not refused as 'from other recordings or settings'."""
    folder, stem, out = done_without_reports
    stored = json.loads((out / "s7-run1.json").read_text())
    assert stored["recordings"] == [stem] and stored["settings"]["alpha"] == 0.01
    before = (out / "s7-run1.json").stat().st_mtime_ns
    for path in (f"{stem}.csv", f"{stem}.json", os.path.relpath(stem)):
        with pytest.warns(QuestionableRecordingWarning, match=SHORT):  # the 20-s record, said
            s = diagnose_batch([path], out, n_bootstrap=0, alpha=None, progress=False,
                               warm_cache=False)
        assert (s.total, s.completed, s.skipped) == (1, 0, 1)
    assert (out / "s7-run1.json").stat().st_mtime_ns == before
    # the whole catalogue named explicitly, in its order, is candidates=None (the CLI's)
    from bayespilot.diagnose import NAMES
    with pytest.warns(QuestionableRecordingWarning, match=SHORT):
        s = diagnose_batch([stem], out, n_bootstrap=0, candidates=list(NAMES), progress=False,
                           warm_cache=False)
    assert (s.total, s.completed, s.skipped) == (1, 0, 1)
    with pytest.raises(CampaignError, match="from other settings: candidates"):
        diagnose_batch([stem], out, n_bootstrap=0, candidates=list(NAMES)[:-1], progress=False)
    # reports=True on it: named by a warning, nothing written
    with pytest.warns(UserWarning, match=r"1 diagnosis finished before.*\(s7-run1\)"):
        diagnose_batch([f"{stem}.csv"], out, n_bootstrap=0, reports=True, progress=False)
    assert not (out / "s7-run1").exists()
    # other settings or another recording are still refused, saying which
    with pytest.raises(CampaignError, match="from other settings: alpha 0.01 there, 0.05 here"):
        diagnose_batch([stem], out, n_bootstrap=0, alpha=0.05, progress=False)
    other = _write(tmp_path, "s7-run1", subject="s7", seed=8)  # the same key, another file
    with pytest.raises(CampaignError, match="from other recordings;"):
        diagnose_batch([other], out, n_bootstrap=0, progress=False)
    # the same recording by its content: results made in another working folder, or with
    # the recordings since moved (their stored paths no longer resolve), still resume
    assert len(stored["recording_digests"]) == 1
    moved = tmp_path / "moved"
    moved.mkdir()
    (moved / "s7-run1.json").write_text(json.dumps(dict(stored, recordings=["old/s7-run1"])))
    with pytest.warns(QuestionableRecordingWarning, match=SHORT):
        s = diagnose_batch([stem], moved, n_bootstrap=0, progress=False, warm_cache=False)
    assert (s.total, s.completed, s.skipped) == (1, 0, 1)
    # one recording named twice (both files of it, as a glob gives them) is diagnosed once
    with pytest.warns(QuestionableRecordingWarning, match=SHORT):
        s = diagnose_batch([f"{stem}.csv", f"{stem}.json", stem], out, n_bootstrap=0,
                           progress=False, warm_cache=False)
    assert (s.total, s.skipped) == (1, 1)


def test_output_folder_that_cannot_be_written_in_is_refused_before_computing(recordings,
                                                                             tmp_path,
                                                                             monkeypatch):
    """A folder that exists but refuses files: said before the first diagnosis (it was said
    when the first result was written, after the cluster's start and a diagnosis)."""
    import bayespilot.diagnose.batch as B

    def no_run(*a, **k):
        raise AssertionError("a diagnosis started")

    monkeypatch.setattr(B, "run_diagnose_task", no_run)
    out = tmp_path / "ro"
    out.mkdir()
    real = B.replacing

    def refused(path):
        if path.name == ".bayespilot-write-check":
            raise PermissionError(13, "Permission denied")
        return real(path)

    monkeypatch.setattr(B, "replacing", refused)
    with pytest.warns(QuestionableRecordingWarning, match=SHORT), \
            pytest.raises(CampaignError, match="ro: cannot write in the output folder"):
        diagnose_batch(recordings[:1], out, n_bootstrap=0, progress=False)


def test_cli_refuses_a_csv_without_its_sidecar_in_a_folder(lone_folder, tmp_path, capsys):
    """recording-format.md: a CSV without its JSON is not a recording; a folder holding one
    was diagnosed without it, silently."""
    import shutil

    folder = tmp_path / "recs"
    shutil.copytree(lone_folder, folder)
    (folder / "s9-run2.csv").write_text((folder / "s9-run1.csv").read_text())
    code = main(["diagnose-batch", str(folder), "--out", str(tmp_path / "o"), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and "s9-run2.csv without its JSON sidecar" in err, err
    assert not (tmp_path / "o").exists()


def test_summary_json_cells_are_standard_json():
    """A run's posterior without an HDI (a missing number) is null in the summary's JSON cell,
    not Python's NaN token that strict JSON readers (R's jsonlite, JavaScript) refuse."""
    from bayespilot.diagnose.batch import _posterior_cell

    d = {"posterior": {"params": {"w_soft": {"median": 0.2}}}}
    cell = _posterior_cell(d, {"params": {"w_soft": 0.21}})

    def refuse(token):
        raise ValueError(token)

    assert json.loads(cell, parse_constant=refuse) == {"w_soft": [0.2, None, None]}


def test_summary_covers_every_diagnosis_in_the_folder_made_with_these_settings(
        done_without_reports, tmp_path, capsys):
    """A rerun on a subset of the recordings into the same folder: summary.csv kept only this
    run's keys while the others' <key>.json stayed.  It now covers every diagnosis there made
    with these settings (an earlier run's result or error file), sorted by key, and names the
    ones made with other settings, left out."""
    import shutil
    import warnings

    from bayespilot.diagnose.batch import SummaryScopeWarning

    folder, stem, done = done_without_reports
    out = tmp_path / "out"
    out.mkdir()
    shutil.copy(done / "s7-run1.json", out / "s7-run1.json")
    mine = json.loads((done / "s7-run1.json").read_text())
    assert mine["condition"] == {"subject": "s7", "task": "FD", "motion_gain": 1.0}

    def put(name, **changes):
        (out / name).write_text(json.dumps({**mine, **changes}))

    put("s8-run1.json", key="s8-run1", recordings=["elsewhere/s8-run1"],
        recording_digests=["0" * 64],
        condition={"subject": "s8", "task": "FT", "motion_gain": 0.5})
    old = {k: v for k, v in mine.items() if k != "condition"}  # made before it was recorded
    (out / "s5-run1.json").write_text(json.dumps(dict(old, key="s5-run1")))
    put("other.json", key="other", settings=dict(mine["settings"], alpha=0.05))
    (out / "s6-run1.error.json").write_text(json.dumps(
        {"key": "s6-run1", "recordings": ["gone/s6-run1"], "settings": mine["settings"],
         "error": "RuntimeError", "message": "worker lost"}))
    (out / "notes.json").write_text(json.dumps({"a": 1}))  # not a batch's file: passed over

    scope = (f"{out} holds 1 diagnosis made with other settings (other), left out of "
             f"summary.csv: it covers the diagnoses made with this batch's settings")
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        s = diagnose_batch([stem], out, n_bootstrap=0, progress=False, warm_cache=False)
    assert (s.total, s.completed, s.skipped) == (1, 0, 1)
    assert [str(w.message) for w in said if w.category is SummaryScopeWarning] == [scope]
    rows = list(csv.DictReader((out / "summary.csv").open()))
    assert [(r["key"], r["subject"], r["task"], r["motion_gain"]) for r in rows] == [
        ("s5-run1", "", "", ""), ("s6-run1", "", "", ""), ("s7-run1", "s7", "FD", "1.0"),
        ("s8-run1", "s8", "FT", "0.5")]
    assert rows[1]["error"] == "RuntimeError: worker lost" and rows[1]["physics"] == ""
    physics = mine["diagnosis"]["physics"]
    assert [r["physics"] for r in rows if r["key"] != "s6-run1"] == [physics] * 3

    # the command says which rows an earlier run made, and warns of the one left out
    capsys.readouterr()
    code = main(["diagnose-batch", str(folder), "--out", str(out), "--bootstrap", "0",
                 "--workers", "1"])
    stdout, err = capsys.readouterr()
    assert code == 0, err
    assert f"bayespilot: warning: {scope}" in err.splitlines()
    lines = stdout.splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("key,n_runs,"))
    assert [ln.split(",")[0] for ln in lines[head + 1:-1]] == ["s5-run1", "s6-run1", "s7-run1",
                                                               "s8-run1"]
    assert lines[-1] == (f"wrote {out / 'summary.csv'} (with 3 diagnoses an earlier run made "
                         f"in {out} with these settings), {out / 'summary.png'} and one "
                         f"<key>.json per diagnosis")


def test_cli_a_diagnosis_from_other_settings_is_a_usage_error(done_without_reports, capsys):
    """A key's result made with other settings is bad input (exit 2, the same one line); it
    exited 1 as a failure of the run."""
    from bayespilot.diagnose.batch import ResultConflictError

    folder, stem, out = done_without_reports
    capsys.readouterr()
    code = main(["diagnose-batch", str(folder), "--out", str(out), "--bootstrap", "0",
                 "--seed", "5", "--workers", "1", "-q"])
    stdout, err = capsys.readouterr()
    assert code == 2 and stdout == ""
    assert [ln for ln in err.splitlines() if "warning" not in ln] == [
        f"bayespilot: error: {out / 's7-run1.json'} holds a diagnosis of s7-run1 from other "
        f"settings: batch_seed 0 there, 5 here; use another output folder or delete it"]
    assert issubclass(ResultConflictError, CampaignError)  # (Python callers catch it as before)
    with pytest.warns(QuestionableRecordingWarning, match=SHORT), \
            pytest.raises(ValueError, match="from other settings: batch_seed 0 there, 5 here;"):
        diagnose_batch([stem], out, n_bootstrap=0, seed=5, progress=False)


def test_pooling_one_recording_under_two_names_is_refused_up_front(lone_folder, tmp_path,
                                                                     capsys):
    """Two files with the same signals in one condition: refused when the recordings are read,
    naming both (it failed on the worker, exit 1, with a raw 'ValueError:' and the advice to
    run the same command again)."""
    import shutil

    folder = tmp_path / "recs"
    shutil.copytree(lone_folder, folder)
    for ext in (".csv", ".json"):
        shutil.copy(folder / f"s9-run1{ext}", folder / f"s9-copy{ext}")
    code = main(["diagnose-batch", str(folder), "--out", str(tmp_path / "o"), "--pool",
                 "--workers", "1", "-q"])
    err = capsys.readouterr().err.splitlines()
    assert code == 2
    assert err[-1] == (f"bayespilot: error: the same recording under two names in one pooled "
                       f"condition: {folder / 's9-copy'} and {folder / 's9-run1'} hold the same "
                       f"signals (pooling them would count one run's evidence twice); give "
                       f"each run once")
    assert all(ln.startswith("bayespilot: warning: ") for ln in err[:-1])  # (the 20-s records)
    assert not (tmp_path / "o").exists()


def test_a_base_fit_on_a_bound_is_said_by_the_batch_as_a_base_fit_warning(recordings, tmp_path,
                                                                          monkeypatch):
    """The batch said every note its diagnoses kept as a plain EvidenceWarning, so a filter
    on BaseFitWarning never saw a batch's: a note of a base fit on a bound (the text its
    kept ``base_at_bounds`` makes, a single run's settings or a pooled run's) is said as a
    BaseFitWarning, the others as EvidenceWarning.  In this process (run_keyed replaced, no
    cluster), with hand-made Eq. 4 fits on omega_nm's upper bound for s1-run1 and s2-run1."""
    import warnings

    from bayespilot import campaign as C
    from bayespilot import presets
    from bayespilot.diagnose import BaseFitWarning, EvidenceWarning
    from bayespilot.fit import fast
    from bayespilot.fit.result import FitResult

    def fit_fast(rec, model, **kwargs):
        on = any(s in str(rec.source) for s in ("s1-run1", "s2-run1"))
        p = dict(presets.paper_parameters("FD"), **({"omega_nm": 30.0} if on else {}))
        return FitResult(p, -1.0e4, 80.0, "fast", 0, True, bounds=dict(presets.TABLE1_BOUNDS))

    def run_keyed(tasks, out, *, to_json, **kwargs):
        for key, fn, args, _ in tasks:
            C._write_json_atomic(out / f"{key}.json", to_json(key, fn(*args)))
        return len(tasks), {}

    monkeypatch.setattr(fast, "fit_fast", fit_fast)
    monkeypatch.setattr(C, "run_keyed", run_keyed)
    out = tmp_path / "b"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = diagnose_batch(recordings, out, pool=True, seed=0, progress=False,
                           warm_cache=False, **OPTIONS)
    assert (s.completed, s.failed) == (2, 0)
    bound = [w for w in caught if "the base fit has omega_nm = 30" in str(w.message)]
    assert bound and all(w.category is BaseFitWarning for w in bound)
    named = " ".join(str(w.message).split(": ")[0] for w in bound)
    assert "s1_FD_k1" in named and "s2_FD_k0.75" in named
    plain = [w for w in caught if issubclass(w.category, EvidenceWarning) and w not in bound]
    assert plain and all(w.category is EvidenceWarning for w in plain)  # (the 20-s records')
    pooled = json.loads((out / "s1_FD_k1.json").read_text())["diagnosis"]
    one = json.loads((out / "s2_FD_k0.75.json").read_text())["diagnosis"]
    assert pooled["runs"][0]["base_at_bounds"][0]["parameter"] == "omega_nm"
    assert "base_at_bounds" not in pooled["runs"][1]
    assert one["settings"]["base_at_bounds"][0]["parameter"] == "omega_nm"


# --- each diagnosis its own seed ----------------------------------------------------------------
def _run_here(monkeypatch):
    """diagnose_batch with its tasks run in this process (run_keyed replaced, no cluster): the
    same arguments the workers get, a few seconds a batch."""
    from bayespilot import campaign as C

    def run_keyed(tasks, out, *, to_json, **kwargs):
        for key, fn, args, _ in tasks:
            C._write_json_atomic(out / f"{key}.json", to_json(key, fn(*args)))
        return len(tasks), {}

    monkeypatch.setattr(C, "run_keyed", run_keyed)


@pytest.fixture(scope="module")
def twins(tmp_path_factory):
    """Two 40.96-s runs a and b (the shortest of the paper's forcing that a bootstrap can
    simulate), and a2: a with one sample of its control moved by 1e-9 (another recording by
    its content, the same fit within rounding)."""
    folder = tmp_path_factory.mktemp("twins")
    a = _write(folder, "a", subject="s1", seed=11, duration=40.96)
    b = _write(folder, "b", subject="s2", seed=12, duration=40.96)
    rec = read_recording(a)
    signals = {k: v.copy() for k, v in rec.signals.items()}
    signals["u"][500] += 1e-9
    write_recording(Recording(signals, rec.sample_rate_hz, rec.motion_gain, rec.task,
                              dict(rec.metadata)), folder / "a2")
    return a, b, str(folder / "a2")


#: Cheap settings with a bootstrap (its replicates are what the seeds are for; one is enough
#: to tell two seeds' draws apart).
BOOT = {"n_bootstrap": 1, "candidates": ["motion-washout"], "progress": False,
        "warm_cache": False}
#: Without it, for what the seeds do not change.
NOBOOT = dict(BOOT, n_bootstrap=0)


def _result(out, key):
    return json.loads((out / f"{key}.json").read_text())


def _null_means(d):
    return {k: e["null_mean"] for k, e in d["where"].items()
            if isinstance(e.get("null_mean"), float)}


def test_each_diagnosis_of_a_batch_draws_its_own_bootstrap(twins, tmp_path, monkeypatch):
    """Every diagnosis of a batch ran with the batch's seed, so two recordings' bootstraps
    drew the same normal sequences: a and a2 (one sample apart) got the same replicates to
    1e-6.  Now each has its own seed, task_seed(batch seed, its signals' digest), and their
    replicates differ as independent draws do; each result records the seed it ran with,
    and diagnose(recording, seed=that) repeats it."""
    a, b, a2 = twins
    _run_here(monkeypatch)
    out = tmp_path / "out"
    diagnose_batch([a, a2], out, seed=0, **BOOT)
    ra, ra2 = _result(out, "a"), _result(out, "a2")
    rec_a, rec_a2 = read_recording(a), read_recording(a2)
    want = task_seed(0, [_signals_digest(rec_a)]), task_seed(0, [_signals_digest(rec_a2)])
    assert (ra["settings"]["seed"], ra2["settings"]["seed"]) == want and want[0] != want[1]
    # one digest given alone is that recording's, not a list of its characters
    assert task_seed(0, _signals_digest(rec_a)) == want[0]
    for bad in (-1, "0", 1.0, True, None):
        with pytest.raises(ValueError, match="seed must be an integer >= 0"):
            task_seed(bad, [_signals_digest(rec_a)])
    assert ra["settings"]["batch_seed"] == ra2["settings"]["batch_seed"] == 0
    assert ra["diagnosis"]["settings"]["seed"] == want[0]
    null_a, null_a2 = _null_means(ra["diagnosis"]), _null_means(ra2["diagnosis"])
    assert len(null_a) >= 5 and null_a.keys() == null_a2.keys()
    # the statistics themselves agree (the same run within 1e-9), their replicates do not
    for k in null_a:
        assert ra["diagnosis"]["where"][k]["value"] == pytest.approx(
            ra2["diagnosis"]["where"][k]["value"], rel=1e-4, abs=1e-9), k
    apart = [k for k in null_a if null_a[k] != pytest.approx(null_a2[k], rel=1e-3)]
    assert len(apart) >= len(null_a) - 1, (null_a, null_a2)
    # (that the recorded seed repeats a diagnosis exactly, so that one seed for both, the old
    # batch's, drew the same replicates: test_batch_matches_direct_diagnoses_and_resumes,
    # against diagnoses run directly with the recorded seeds)


def test_a_diagnosis_seed_depends_on_its_recordings_alone(twins, tmp_path, monkeypatch):
    """A diagnosis's seed, and so its result, is the same whichever other recordings are in
    the batch and in whatever order the paths come: a in {a, a2} and in {b, a}; a pooled
    condition's seed is task_seed of its runs' digests, in any order."""
    a, b, a2 = twins
    _run_here(monkeypatch)
    diagnose_batch([a, a2], tmp_path / "one", seed=5, **NOBOOT)
    diagnose_batch([b, a], tmp_path / "two", seed=5, **NOBOOT)
    first, second = _result(tmp_path / "one", "a"), _result(tmp_path / "two", "a")
    recs = {p: read_recording(p) for p in (a, b, a2)}
    digest = {p: _signals_digest(r) for p, r in recs.items()}
    assert first["settings"]["seed"] == second["settings"]["seed"] == task_seed(5, [digest[a]])
    assert _result(tmp_path / "two", "b")["settings"]["seed"] == task_seed(5, [digest[b]])
    one, two = first["diagnosis"], second["diagnosis"]
    assert one["base"] == two["base"] and one["ranking"] == two["ranking"]
    # pooled (a and a2 are s1's runs, b s2's alone): the condition's seed from its runs'
    # digests in any order, its own; b's, alone in its condition, is b's seed above
    diagnose_batch([a2, b, a], tmp_path / "pooled", pool=True, seed=5, **NOBOOT)
    s1, s2 = _result(tmp_path / "pooled", "s1_FD_k1"), _result(tmp_path / "pooled", "s2_FD_k1")
    assert s1["settings"]["seed"] == task_seed(5, [digest[a2], digest[a]])
    assert s1["settings"]["seed"] not in {5, task_seed(5, [digest[a]]),
                                          task_seed(5, [digest[a2]])}
    alone_b = _result(tmp_path / "two", "b")
    assert s2["settings"]["seed"] == alone_b["settings"]["seed"]
    assert s2["diagnosis"]["ranking"] == alone_b["diagnosis"]["ranking"]


def test_resume_by_batch_seed_and_results_of_the_old_seeding_refused(twins, tmp_path,
                                                                      monkeypatch):
    """The same batch again skips what is done; another batch seed is refused, saying so (not
    'seed <one diagnosis's> there'); a result written when every diagnosis ran with the
    batch's seed itself (its settings record no batch_seed) is refused by name rather than
    taken as done and mixed with diagnoses seeded each its own."""
    import warnings

    from bayespilot.diagnose.batch import SummaryScopeWarning

    a, b, a2 = twins
    _run_here(monkeypatch)
    out = tmp_path / "out"
    s = diagnose_batch([a], out, seed=2, **NOBOOT)
    assert (s.completed, s.skipped) == (1, 0)
    stamp = (out / "a.json").stat().st_mtime_ns
    s = diagnose_batch([b, a], out, seed=2, **NOBOOT)  # a subset again, with another one
    assert (s.total, s.completed, s.skipped) == (2, 1, 1)
    assert (out / "a.json").stat().st_mtime_ns == stamp
    rows = list(csv.DictReader((out / "summary.csv").open()))
    assert [(r["key"], r["seed"]) for r in rows] == [
        ("a", str(_result(out, "a")["settings"]["seed"])),
        ("b", str(_result(out, "b")["settings"]["seed"]))]
    with pytest.raises(ResultConflictError, match=r"\.json holds a diagnosis of a from other "
                                                  r"settings: batch_seed 2 there, 3 here; use"):
        diagnose_batch([a], out, seed=3, **NOBOOT)
    # a result of the old seeding: settings["seed"] the batch's, no batch_seed
    stored = _result(out, "a")
    settings = {k: v for k, v in stored["settings"].items() if k != "batch_seed"}
    (out / "a.json").write_text(json.dumps(dict(stored, settings=dict(settings, seed=2))))
    with pytest.raises(ResultConflictError, match=(
            r"holds 1 diagnosis of this batch's keys \(a\) made by an earlier bayespilot, "
            r"which ran every diagnosis of a batch with the batch's seed itself \(the seed "
            r"2 recorded, no batch_seed\); .* delete its <key>.json to redo it")):
        diagnose_batch([b, a], out, seed=2, **NOBOOT)
    assert "batch_seed" not in _result(out, "a")["settings"]  # (not redone, not mixed)
    # one of another key: left out of the summary, named as made with other settings
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        s = diagnose_batch([b], out, seed=2, **NOBOOT)
    assert (s.completed, s.skipped) == (0, 1)
    scope = [str(w.message) for w in said if w.category is SummaryScopeWarning]
    assert len(scope) == 1 and "made with other settings (a)" in scope[0]
    assert [r["key"] for r in csv.DictReader((out / "summary.csv").open())] == ["b"]


# --- what the diagnosis reads of a sidecar, compared on resume ----------------------------------
def _stub_batch(monkeypatch):
    """diagnose_batch with no diagnosis at all: each pending task's result file is what the batch
    records of how it was made (its context) and a placeholder diagnosis, and no summary is
    drawn; what is tested is which tasks count as done (milliseconds a batch)."""
    from bayespilot import campaign as C
    import bayespilot.diagnose.batch as B

    ran = []

    def run_keyed(tasks, out, **kwargs):
        for key, _, _, context in tasks:
            ran.append(key)
            C._write_json_atomic(out / f"{key}.json",
                                 {"key": key, **context, "diagnosis": {"physics": "none"}})
        return len(tasks), {}

    monkeypatch.setattr(C, "run_keyed", run_keyed)
    monkeypatch.setattr(B, "write_summary", lambda tasks, out, **figure: None)
    return ran


def _edit_sidecar(stem, **values):
    """The recording's JSON sidecar with ``values`` set (None: the key removed); its CSV, the
    signals, unchanged."""
    path = f"{stem}.json"
    with open(path, encoding="utf-8") as fh:
        meta = json.load(fh)
    for k, v in values.items():
        if v is None:
            meta.pop(k, None)
        else:
            meta[k] = v
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(meta, fh)


def test_resume_view_tells_apart_one_run_under_two_motion_gains():
    """The audit's check (audit_structure.md 7.2): the same signals with K_theta 0.5 and 1.0
    gave equal resume views; they differ now, and the seed (of the signals alone) does not."""
    from bayespilot.diagnose import batch as B

    rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.15, seed=1,
                   duration=5.0).recording
    recs = {k: Recording(rec.signals, rec.sample_rate_hz, k, rec.task, rec.metadata)
            for k in (0.5, 1.0)}
    task = plan_batch(["r"], [recs[1.0]])[0]
    digests = {"r": _signals_digest(recs[1.0])}
    assert _signals_digest(recs[0.5]) == digests["r"]
    opts = {"seed": 0, "noise_passes": 1}
    made = {k: B._settings(task, opts, digests, {"r": B._recording_metadata(r)})
            for k, r in recs.items()}
    views = {k: B._resume_view(m, {}, by_content=True, metadata=True) for k, m in made.items()}
    assert views[0.5] != views[1.0]
    assert made[0.5]["recording_metadata"][0]["motion_gain"] == 0.5
    assert made[0.5]["settings"]["seed"] == made[1.0]["settings"]["seed"]
    assert "motion_gain 0.5 there, 1.0 here" in B._differs(views[0.5], views[1.0])


def test_a_sidecar_corrected_since_is_not_taken_as_done(tmp_path, monkeypatch):
    """A recording whose sidecar's motion_gain (K_theta, which every theta_m channel, the
    otolith entry and the bootstrap's loop use) was corrected after its diagnosis: the batch
    run again took the old diagnosis as done (only the signals' digest was compared).  It is
    refused now as a changed recording is, saying what changed; so is another sidecar value
    the diagnosis reads (control_gain, the plant, the forcing), while one it does not read
    (subject, notes) still resumes, and the diagnosis's seed stays that of the signals."""
    ran = _stub_batch(monkeypatch)
    stem = _write(tmp_path, "s5-run1", subject="s5", motion_gain=1.0, seed=5)
    out = tmp_path / "out"
    s = diagnose_batch([stem], out, **NOBOOT)
    assert (s.completed, s.skipped) == (1, 0) and ran == ["s5-run1"]
    seed = _result(out, "s5-run1")["settings"]["seed"]
    assert diagnose_batch([stem], out, **NOBOOT).skipped == 1
    _edit_sidecar(stem, motion_gain=0.5)
    with pytest.raises(ResultConflictError, match=(
            r"holds a diagnosis of s5-run1 from the same signals with other sidecar values, "
            r"which the diagnosis reads \(motion_gain 1\.0 there, 0\.5 here\); use another "
            r"output folder or delete it")):
        diagnose_batch([stem], out, **NOBOOT)
    assert ran == ["s5-run1"]  # (not redone behind the user's back either)
    assert _result(out, "s5-run1")["recording_metadata"] == [
        {"sample_rate_hz": 100.0, "motion_gain": 1.0, "task": "FD"}]
    # deleted, it is redone with the corrected K_theta and the same seed (the signals')
    (out / "s5-run1.json").unlink()
    assert diagnose_batch([stem], out, **NOBOOT).completed == 1
    redone = _result(out, "s5-run1")
    assert redone["recording_metadata"][0]["motion_gain"] == 0.5
    assert redone["settings"]["seed"] == seed
    # what the diagnosis reads besides K_theta: the loop's control_gain, the plant
    _edit_sidecar(stem, control_gain=0.8)
    with pytest.raises(ResultConflictError, match=r"control_gain not given there, 0\.8 here"):
        diagnose_batch([stem], out, **NOBOOT)
    _edit_sidecar(stem, control_gain=None, controlled_element={"num": [2.0], "den": [1, 0, 0]})
    with pytest.raises(ResultConflictError, match=r"controlled_element not given there, given "
                                                  r"here\); use another output folder"):
        diagnose_batch([stem], out, **NOBOOT)
    forcing = simulate(task="FD", duration=5.0, seed=0).recording.metadata["forcing"]
    _edit_sidecar(stem, controlled_element=None, forcing=json.loads(json.dumps(forcing)))
    with pytest.raises(ResultConflictError, match=r"\(forcing not given there, given here\)"):
        diagnose_batch([stem], out, **NOBOOT)
    # ... but the forcing as the diagnosis reads it: lines written as 6.0, or a key of the
    # lab's own inside the forcing object (unknown keys are ignored), resume
    (out / "s5-run1.json").unlink()
    assert diagnose_batch([stem], out, **NOBOOT).completed == 1
    f = json.loads(json.dumps(forcing))
    f["target"]["n"] = [float(n) for n in f["target"]["n"]]
    f["lab_note"] = "sines from the 2011 set"
    _edit_sidecar(stem, forcing=f)
    assert diagnose_batch([stem], out, **NOBOOT).skipped == 1
    f["target"]["amplitude"][0] *= 2  # what it reads: refused
    _edit_sidecar(stem, forcing=f)
    with pytest.raises(ResultConflictError, match=r"\(forcing changed\)"):
        diagnose_batch([stem], out, **NOBOOT)
    (out / "s5-run1.json").unlink()
    _edit_sidecar(stem, forcing=None)
    assert diagnose_batch([stem], out, **NOBOOT).completed == 1
    # what it does not read: resumed
    _edit_sidecar(stem, controlled_element=None, subject="s5b", notes="re-labelled")
    assert diagnose_batch([stem], out, **NOBOOT).skipped == 1 and len(ran) == 4


def test_a_pooled_run_corrected_since_is_named(tmp_path, monkeypatch):
    """Pooled: a condition whose key is unchanged (K_theta 1 and 1.0000001 are both k1) but one
    of whose runs' sidecars changed is refused, naming that run."""
    _stub_batch(monkeypatch)
    runs = [_write(tmp_path, f"s6-run{j}", subject="s6", seed=60 + j) for j in (1, 2)]
    out = tmp_path / "out"
    assert diagnose_batch(runs, out, pool=True, **NOBOOT).completed == 1
    assert diagnose_batch(runs, out, pool=True, **NOBOOT).skipped == 1
    for stem in runs:
        _edit_sidecar(stem, motion_gain=1.0000001)
    with pytest.raises(ResultConflictError, match=(
            r"diagnosis of s6_FD_k1 from the same signals with other sidecar values, which the "
            r"diagnosis reads \(.*s6-run1: motion_gain 1\.0 there, 1\.0000001 here; .*s6-run2: "
            r"motion_gain 1\.0 there, 1\.0000001 here\)")):
        diagnose_batch(runs, out, pool=True, **NOBOOT)


def test_results_made_before_the_sidecar_was_recorded_resume_as_before(tmp_path, monkeypatch):
    """A result written before recording_metadata was recorded resumes on its signals and
    settings as it did (no batch redone for it), except where what it does record of the
    sidecar, its condition's task and K_theta, says the recording changed since; one that
    records neither resumes as before whatever the sidecar says."""
    ran = _stub_batch(monkeypatch)
    stem = _write(tmp_path, "s8-run1", subject="s8", motion_gain=1.0, seed=8)
    out = tmp_path / "out"
    diagnose_batch([stem], out, **NOBOOT)
    stored = _result(out, "s8-run1")
    old = {k: v for k, v in stored.items() if k != "recording_metadata"}
    assert old["condition"] == {"subject": "s8", "task": "FD", "motion_gain": 1.0}
    (out / "s8-run1.json").write_text(json.dumps(old))
    _edit_sidecar(stem, control_gain=0.8)  # (not recorded by an old result: not compared)
    s = diagnose_batch([stem], out, **NOBOOT)
    assert (s.completed, s.skipped) == (0, 1) and ran == ["s8-run1"]
    assert "recording_metadata" not in _result(out, "s8-run1")  # (kept as it was)
    _edit_sidecar(stem, motion_gain=0.5)
    with pytest.raises(ResultConflictError, match=r"other sidecar values, which the diagnosis "
                                                  r"reads \(motion_gain 1\.0 there, 0\.5 here\)"):
        diagnose_batch([stem], out, **NOBOOT)
    # older still: no condition either (nor digests): the signals (the files) alone, as before
    older = {k: v for k, v in old.items() if k not in ("condition", "recording_digests")}
    (out / "s8-run1.json").write_text(json.dumps(older))
    s = diagnose_batch([stem], out, **NOBOOT)
    assert (s.completed, s.skipped) == (0, 1) and ran == ["s8-run1"]


# --- HPC audit 4 and 9: the worker's provenance, the notes' keys sorted --------------------------
def _elsewhere(monkeypatch):
    """diagnose_batch with its tasks run in this process as on another machine ("worker-7",
    bayespilot 0.0.9), finishing in the reverse order of the batch's keys; the results are
    written afterwards, outside it, as the client writes them."""
    import platform

    import bayespilot
    from bayespilot import campaign as C

    def run_keyed(tasks, out, *, to_json, **kwargs):
        done = []
        with monkeypatch.context() as worker:
            worker.setattr(platform, "node", lambda: "worker-7")
            worker.setattr(C, "_versions", lambda: {"python": "3.x", "bayespilot": "0.0.9"})
            worker.setattr(bayespilot, "__version__", "0.0.9")
            for key, fn, args, _ in reversed(tasks):
                done.append((key, fn(*args)))
        for key, value in done:
            C._write_json_atomic(out / f"{key}.json", to_json(key, value))
        return len(tasks), {}

    monkeypatch.setattr(C, "run_keyed", run_keyed)


def _stub_base_fit(monkeypatch):
    """The base fit replaced by the paper's parameters (the batch's plumbing is tested)."""
    from bayespilot import presets
    from bayespilot.fit import fast
    from bayespilot.fit.result import FitResult

    monkeypatch.setattr(fast, "fit_fast", lambda rec, model, **kw: FitResult(
        dict(presets.paper_parameters("FD")), -1.0e4, 80.0, "fast", 0, True,
        bounds=dict(presets.TABLE1_BOUNDS)))


def test_results_say_which_worker_and_release_made_them(recordings, tmp_path, monkeypatch):
    """host and versions were the client's (to_json, in the process writing the files): a
    diagnosis made by a bayespilot 0.0.9 worker said 0.1.0 and the client's machine.  Now the
    worker's, and bayespilot_version is the worker's release too (not a contradiction)."""
    import platform

    _stub_base_fit(monkeypatch)
    _elsewhere(monkeypatch)
    out = tmp_path / "b"
    with pytest.warns(QuestionableRecordingWarning, match=SHORT):
        s = diagnose_batch(recordings[:2], out, progress=False, warm_cache=False, **OPTIONS)
    assert (s.completed, s.failed) == (2, 0)
    assert platform.node() != "worker-7"
    for key in ("s1-run1", "s1-run2"):
        got = json.loads((out / f"{key}.json").read_text())
        assert got["host"] == "worker-7"
        assert got["versions"] == {"python": "3.x", "bayespilot": "0.0.9"}
        assert got["bayespilot_version"] == "0.0.9"


def test_batch_notes_name_the_diagnoses_in_key_order(recordings, tmp_path, monkeypatch):
    """A note several diagnoses kept named them in the order they finished ("run2, run1,
    run3" on a cluster): sorted now, whatever the order."""
    import warnings

    from bayespilot.diagnose import EvidenceWarning

    _stub_base_fit(monkeypatch)
    _elsewhere(monkeypatch)  # (finishing s2-run1 first, s1-run1 last)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        diagnose_batch(recordings, tmp_path / "b", progress=False, warm_cache=False, **OPTIONS)
    notes = [str(w.message) for w in caught if issubclass(w.category, EvidenceWarning)
             and str(w.message).startswith("3 diagnoses (")]
    assert notes, [str(w.message) for w in caught]
    assert all(n.startswith("3 diagnoses (s1-run1, s1-run2, s2-run1): ") for n in notes), notes
    assert notes == sorted(notes, key=lambda n: n.split("): ", 1)[1])

"""The commands' outputs do not destroy what they should not (audit_outputs.md, 2.1, 2.2,
1.3, 3.4 and two of section 6).

- fit-batch and diagnose-batch each refuse a folder holding the other's results (or a
  ``summary.csv`` they did not write): one replaced the other's ``<key>.json`` and
  summary without a word, exit 0.
- ``--json``/``-o`` (and a batch's ``--out`` files) refuse a file of an existing recording
  (its sidecar, its CSV, a .mat file): ``fit rec --json recs/s2-run1.csv`` replaced a lab's
  measurement with a fit; a result of the command itself is still replaced on a rerun.
- summary.csv's posterior columns are named apart from conditions.csv's ``delta_abs_median``.
- a batch result records the forcing's line multiples as the integers the recording format
  has, and results written with them as floats still resume.
- ``loglik --params`` given another of bayespilot's files says what it is.

The batches run in this process (``campaign.run_keyed`` replaced: tests/test_batch.py's
helpers) on 20-s simulated recordings; the refusals are checked to leave every file as it
was and to run nothing.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import warnings

import pytest

from bayespilot import campaign as C
from bayespilot.batch import CONDITION_FIELDS, SUMMARY_FIELDS, _summary_row, fit_batch
from bayespilot.cli import main
from bayespilot.diagnose.batch import ResultConflictError, _recording_metadata, diagnose_batch
from bayespilot.io import read_recording, write_recording
from bayespilot.recording import Recording
from bayespilot.simulate import simulate
from test_batch import FAST, _run_here

#: fit_batch's cheap settings (tests/test_batch.py's), diagnose_batch's (no bootstrap, one
#: candidate: seconds).
FITS = {"method": "fast", "fit_options": FAST, "progress": False, "warm_cache": False}
DIAGNOSES = {"n_bootstrap": 0, "candidates": ["motion-washout"], "progress": False,
             "warm_cache": False}


def _write(folder, name, *, subject, seed):
    """A 20-s FD run written as a lab would: the simulated run's task description (forcing,
    plant, control gain) and a subject, no generator truth (no "simulation" block)."""
    rec = simulate(task="FD", motion_gain=1.0, remnant_gain=0.07, seed=seed,
                   duration=20.0).recording
    os.makedirs(folder, exist_ok=True)
    write_recording(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task,
                              dict(rec.metadata, subject=subject)), folder / name)
    return str(folder / name)


@pytest.fixture(scope="module")
def recs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("recs")
    return [_write(folder, "a", subject="s1", seed=1), _write(folder, "b", subject="s1", seed=2)]


def _batch(tmp_path_factory, run):
    mp = pytest.MonkeyPatch()
    try:
        _run_here(mp)
        return run(tmp_path_factory.mktemp("batch"))
    finally:
        mp.undo()


@pytest.fixture(scope="module")
def fitted(recs, tmp_path_factory):
    """A folder fit_batch wrote (both recordings)."""
    def run(folder):
        out = folder / "fb"
        assert fit_batch(recs, out, seed=1, **FITS).completed == 2
        return out

    return _batch(tmp_path_factory, run)


@pytest.fixture(scope="module")
def diagnosed(recs, tmp_path_factory):
    """A folder diagnose_batch wrote (both recordings)."""
    def run(folder):
        out = folder / "db"
        with warnings.catch_warnings():  # (a 20-s record: questionable, said)
            warnings.simplefilter("ignore")
            assert diagnose_batch(recs, out, seed=1, **DIAGNOSES).completed == 2
        return out

    return _batch(tmp_path_factory, run)


def _nothing_runs(monkeypatch):
    """The batches' cluster loop made to fail the test if it is given a task to run."""
    def run_keyed(tasks, *args, **kwargs):
        if tasks:
            raise AssertionError(f"run_keyed was given {len(tasks)} task(s)")
        return 0, {}

    monkeypatch.setattr(C, "run_keyed", run_keyed)


def _files(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


def _copy(folder, tmp_path):
    dst = tmp_path / folder.name
    shutil.copytree(folder, dst)
    return dst


# --- 2.1: fit-batch and diagnose-batch into each other's folders ------------------------------
def test_the_folders_are_what_each_batch_wrote(fitted, diagnosed):
    """(The premise: each folder holds its command's results and summary under the same keys:
    a run of the other into it replaced them, exit 0.)"""
    for out, mark in ((fitted, "fit_threshold"), (diagnosed, "diagnosis")):
        for key in ("a", "b"):
            stored = json.loads((out / f"{key}.json").read_text())
            assert stored["key"] == key and mark in stored
        assert (out / "summary.csv").is_file() and (out / "summary.png").is_file()


def test_fit_batch_refuses_a_folder_of_diagnoses_and_runs_nothing(recs, diagnosed, tmp_path,
                                                                   monkeypatch):
    out = _copy(diagnosed, tmp_path)
    before = _files(out)
    _nothing_runs(monkeypatch)
    with pytest.raises(ResultConflictError, match=(
            rf"^{out} holds 2 result file\(s\) of 'bayespilot diagnose-batch' "
            r"\(bayespilot\.diagnose\.batch\.diagnose_batch: a diagnosis each, with "
            r"\"diagnosis\" where fit-batch's have \"fit_threshold\"\): a\.json, b\.json and "
            r"summary\.csv of 'bayespilot diagnose-batch': fit-batch would mix its <key>\.json "
            r"results with theirs \(neither command could resume the folder\) and replace that "
            r"summary\.csv with its own; use another output folder \(--out\) for fit-batch; nothing was run$")):
        fit_batch(recs, out, **FITS)
    assert _files(out) == before


def test_diagnose_batch_refuses_a_folder_of_fits_and_runs_nothing(recs, fitted, tmp_path,
                                                                  monkeypatch):
    out = _copy(fitted, tmp_path)
    before = _files(out)
    _nothing_runs(monkeypatch)
    with pytest.raises(ResultConflictError, match=(
            rf"^{out} holds 2 result file\(s\) of 'bayespilot fit-batch' "
            r"\(bayespilot\.batch\.fit_batch: a fit each, with \"fit_threshold\" where "
            r"diagnose-batch's have \"diagnosis\"\): a\.json, b\.json and summary\.csv of "
            r"'bayespilot fit-batch': diagnose-batch would mix")):
        diagnose_batch(recs, out, **DIAGNOSES)
    assert _files(out) == before


def test_one_result_of_the_other_batch_among_others_is_refused(recs, fitted, diagnosed,
                                                                tmp_path, monkeypatch):
    """Under a key the batch does not have (its summary would still be replaced), or as an
    error file; and the other's summary.csv alone (its results moved away)."""
    _nothing_runs(monkeypatch)
    out = tmp_path / "mixed"
    out.mkdir()
    stored = json.loads((diagnosed / "a.json").read_text())
    (out / "zz.json").write_text(json.dumps({**stored, "key": "zz"}))
    with pytest.raises(ResultConflictError, match=r"holds 1 result file\(s\) of 'bayespilot "
                                                  r"diagnose-batch' .*: zz\.json: fit-batch "
                                                  r"would mix its <key>\.json results with "
                                                  r"theirs \(neither command could resume the "
                                                  r"folder\); use another"):
        fit_batch(recs, out, **FITS)
    (out / "zz.json").unlink()
    context = {k: v for k, v in json.loads((fitted / "a.json").read_text()).items()
               if k in ("recording", "recording_digests", "recording_metadata", "subject",
                        "task", "motion_gain", "settings")}
    (out / "zz.error.json").write_text(json.dumps(
        {"key": "zz", **context, "error": "RuntimeError", "message": "x"}))
    with pytest.raises(ResultConflictError, match=r"of 'bayespilot fit-batch' .*: "
                                                  r"zz\.error\.json: diagnose-batch would mix"):
        diagnose_batch(recs, out, **DIAGNOSES)
    (out / "zz.error.json").unlink()
    shutil.copy(diagnosed / "summary.csv", out / "summary.csv")
    with pytest.raises(ResultConflictError, match=(
            rf"^{out} holds summary\.csv of 'bayespilot diagnose-batch': fit-batch would "
            r"replace that summary\.csv with its own; use another")):
        fit_batch(recs, out, **FITS)
    (out / "summary.csv").write_text("subject,weight\ns1,70\n")  # (a lab's own table)
    with pytest.raises(ResultConflictError, match=r"holds a summary\.csv that no bayespilot "
                                                  r"batch wrote \(its columns are not "
                                                  r"diagnose-batch's\)"):
        diagnose_batch(recs, out, **DIAGNOSES)
    assert (out / "summary.csv").read_text() == "subject,weight\ns1,70\n"


def test_each_batch_still_resumes_in_its_own_folder(recs, fitted, diagnosed, tmp_path,
                                                    monkeypatch):
    _nothing_runs(monkeypatch)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert diagnose_batch(recs, _copy(diagnosed, tmp_path), seed=1,
                              **DIAGNOSES).skipped == 2
    assert fit_batch(recs, _copy(fitted, tmp_path), seed=1, **FITS).skipped == 2


@pytest.mark.parametrize("command", ["fit-batch", "diagnose-batch"])
def test_the_commands_refuse_each_others_folder_exit_2(recs, fitted, diagnosed, tmp_path,
                                                       monkeypatch, capsys, command):
    other = diagnosed if command == "fit-batch" else fitted
    out = _copy(other, tmp_path)
    before = _files(out)
    _nothing_runs(monkeypatch)
    options = ["--method", "fast"] if command == "fit-batch" else ["--bootstrap", "0"]
    code = main([command, *recs, "--out", str(out), *options, "--workers", "1", "-q"])
    stdout, err = capsys.readouterr()
    wrote = "diagnose-batch" if command == "fit-batch" else "fit-batch"
    assert code == 2 and stdout == ""
    assert err.startswith(f"bayespilot: error: {out} holds 2 result file(s) of 'bayespilot "
                          f"{wrote}' "), err
    assert "a.json, b.json" in err
    assert err.endswith(f"use another output folder (--out) for {command}; nothing was "
                        f"run\n"), err
    assert _files(out) == before


# --- 2.2: an output that is a file of a recording ---------------------------------------------
@pytest.fixture()
def lab(recs, tmp_path):
    """A copy of a recording (the lab's measurement, not read by the command) and its bytes."""
    folder = tmp_path / "lab"
    folder.mkdir()
    for ext in (".csv", ".json"):
        shutil.copy(recs[1] + ext, folder / f"run7{ext}")
    return folder / "run7", _files(folder)


def _nothing_computed(monkeypatch):
    import bayespilot.compare
    import bayespilot.diagnose
    import bayespilot.fit.fast
    import bayespilot.sample

    def ran(*args, **kwargs):
        raise AssertionError("the command computed")

    for module, name in ((bayespilot.fit.fast, "fit_fast"), (bayespilot.sample, "sample"),
                         (bayespilot.compare, "compare"), (bayespilot.diagnose, "diagnose")):
        monkeypatch.setattr(module, name, ran)


@pytest.mark.parametrize("argv", [
    ["fit", "{rec}", "--method", "fast", "--json", "{out}"],
    ["sample", "{rec}", "-o", "{tmp}/post.nc", "--json", "{out}"],
    ["compare", "{rec}", "--json", "{out}"],
    ["diagnose", "{rec}", "--bootstrap", "0", "--json", "{out}"],
])
@pytest.mark.parametrize("part", [".json", ".csv"])
def test_a_json_output_onto_a_recording_is_exit_2_and_nothing_runs(recs, lab, tmp_path,
                                                                    monkeypatch, capsys,
                                                                    argv, part):
    stem, before = lab
    _nothing_computed(monkeypatch)
    target = f"{stem}{part}"
    code = main([a.format(rec=recs[0], out=target, tmp=tmp_path) for a in argv] + ["-q"])
    stdout, err = capsys.readouterr()
    assert code == 2 and stdout == ""
    said = ("the JSON sidecar of a recording (its \"format\" is the recording format's)"
            if part == ".json" else
            f"the CSV of the recording {stem} (its sidecar {stem}.json is a recording's)")
    assert err == (f"bayespilot: error: argument --json: {target} is {said}: a measurement, "
                   f"which writing there would destroy; give another file name\n")
    assert _files(stem.parent) == before
    assert not (tmp_path / "post.nc").exists()


def test_a_mat_file_is_not_written_over(recs, tmp_path, monkeypatch, capsys):
    _nothing_computed(monkeypatch)
    mat = tmp_path / "run9.mat"
    mat.write_bytes(b"MATLAB 5.0 MAT-file, a lab's run")
    assert main(["fit", recs[0], "--method", "fast", "--json", str(mat), "-q"]) == 2
    assert "is a .mat file, a recording as bayespilot reads one" in capsys.readouterr().err
    assert mat.read_bytes() == b"MATLAB 5.0 MAT-file, a lab's run"


def test_a_batch_table_onto_a_recording_in_its_folder_is_exit_2(recs, lab, monkeypatch,
                                                                 capsys):
    """A recording named 'summary' in --out that the batch does not read: its summary.csv."""
    stem, _ = lab
    for ext in (".csv", ".json"):
        os.replace(f"{stem}{ext}", stem.parent / f"summary{ext}")
    before = _files(stem.parent)
    _nothing_runs(monkeypatch)
    code = main(["fit-batch", recs[0], "--out", str(stem.parent), "--method", "fast", "-q"])
    err = capsys.readouterr().err
    assert code == 2
    assert err == (f"bayespilot: error: argument --out: {stem.parent / 'summary.csv'} is the "
                   f"CSV of the recording {stem.parent / 'summary'} (its sidecar "
                   f"{stem.parent / 'summary.json'} is a recording's): a measurement, which "
                   f"writing there would destroy; use another --out folder\n")
    assert _files(stem.parent) == before


def test_the_quick_demo_does_not_replace_a_lab_recording(recs, tmp_path, monkeypatch, capsys):
    import bayespilot.cli as cli

    def ran(*args, **kwargs):
        raise AssertionError("the demo simulated")

    monkeypatch.setattr(cli, "_simulate_and_write", ran)
    for ext in (".csv", ".json"):
        shutil.copy(recs[0] + ext, tmp_path / f"recording{ext}")
    before = _files(tmp_path)
    assert main(["demo", "--quick", "--out", str(tmp_path), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"bayespilot: error: argument --out: {tmp_path / 'recording.csv'} "
                          f"and {tmp_path / 'recording.json'} are not a recording "
                          f"'bayespilot simulate' wrote"), err
    assert err.endswith("give another folder\n")
    assert _files(tmp_path) == before


def test_the_full_demo_does_not_replace_a_lab_recording(recs, tmp_path, monkeypatch, capsys):
    """Review: the quick demo refused a lab's recording at its name, the full one replaced
    ``recordings/FD_k1.csv``; a demo's own (with its ``simulation`` block, or in a folder with
    the demo's report.md, written before it kept that block) is replaced as a rerun does."""
    import bayespilot.simulate as S

    def ran(*args, **kwargs):
        raise AssertionError("the demo simulated")

    monkeypatch.setattr(S, "simulate", ran)
    folder = tmp_path / "recordings"
    folder.mkdir()
    for ext in (".csv", ".json"):
        shutil.copy(recs[0] + ext, folder / f"FD_k0.75{ext}")
    before = _files(folder)
    argv = ["demo", "--out", str(tmp_path), "--motion-gains", "1,0.75", "-q"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err == (f"bayespilot: error: argument --out: {folder / 'FD_k0.75.csv'} and "
                   f"{folder / 'FD_k0.75.json'} are not a recording the demo wrote (no "
                   f"\"simulation\" in a sidecar, no report.md in {tmp_path}): the demo would "
                   "replace it; give another folder\n")
    assert _files(folder) == before and sorted(p.name for p in tmp_path.iterdir()) == [
        "recordings"]
    (tmp_path / "report.md").write_text("# another report\n")  # (not the demo's)
    assert main(argv) == 2
    capsys.readouterr()
    (tmp_path / "report.md").write_text("# bayespilot worked example\n\nan earlier demo's\n")
    assert main(argv) == 1
    assert "unexpected AssertionError: the demo simulated" in capsys.readouterr().err

    # (review: any ValueError of the demo's run was said as a fault of --out, exit 2)
    def fails(*args, **kwargs):
        raise ValueError("a fault of the run")

    monkeypatch.setattr(S, "simulate", fails)
    assert main(["demo", "--out", str(tmp_path / "fresh"), "-q"]) == 1
    assert capsys.readouterr().err.startswith(
        "bayespilot: error: unexpected ValueError: a fault of the run")


def test_replicate_does_not_replace_a_batch_summary(fitted, diagnosed, tmp_path, monkeypatch,
                                                    capsys):
    """replicate refuses what the batches refuse: another batch's summary, its results
    without their summary (an interrupted run's: replicate's files among them made that batch
    refuse its own folder), and a summary.csv of one's own."""
    import bayespilot.campaign

    def ran(*args, **kwargs):
        raise AssertionError("the study ran")

    monkeypatch.setattr(bayespilot.campaign, "run_campaign", ran)
    argv = ["replicate", "--realizations", "1", "--method", "fast", "--workers", "1", "-q"]
    out = _copy(fitted, tmp_path)
    before = _files(out)
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"bayespilot: error: argument --out: {out} holds 2 result file(s) "
                          f"of 'bayespilot fit-batch'"), err
    assert err.endswith("use another output folder (--out) for replicate; nothing was run\n")
    assert _files(out) == before
    results = tmp_path / "results"
    shutil.copytree(diagnosed, results)
    (results / "summary.csv").unlink()
    assert main([*argv, "--out", str(results)]) == 2
    assert "of 'bayespilot diagnose-batch'" in capsys.readouterr().err
    own = tmp_path / "own"
    own.mkdir()
    (own / "summary.csv").write_text("subject,score\ns1,3\n")
    assert main([*argv, "--out", str(own)]) == 2
    assert "a summary.csv that no bayespilot batch wrote" in capsys.readouterr().err
    assert (own / "summary.csv").read_text() == "subject,score\ns1,3\n"


def test_run_campaign_refuses_a_folder_of_batch_results(fitted, diagnosed, tmp_path,
                                                         monkeypatch):
    """Review: the Python run_campaign (replicate's function) took fit-batch's <key>.json
    under a job's key for "not done" and replaced it; a summary.csv of the caller's own is
    left to it (run_campaign writes none)."""
    from bayespilot.campaign import paper_study, run_campaign

    jobs = paper_study(1, tasks=("FD",), motion_gains=(1.0,), remnant_fractions=(0.2,),
                       method="fast", duration=5.0, n_starts=1)
    _nothing_runs(monkeypatch)
    for folder, by in ((fitted, "fit-batch"), (diagnosed, "diagnose-batch")):
        out = _copy(folder, tmp_path / by)
        stored = json.loads((out / "a.json").read_text())  # (a result under a job's key)
        (out / f"{jobs[0].key}.json").write_text(json.dumps(dict(stored, key=jobs[0].key)))
        before = _files(out)
        with pytest.raises(ResultConflictError, match=(
                rf"^{out} holds 3 result file\(s\) of 'bayespilot {by}' .*: replicate would "
                r"mix its <key>\.json results with theirs \(neither command could resume the "
                r"folder\); use another output folder")):
            run_campaign(jobs, out, workers=1, progress=False, warm_cache=False)
        assert _files(out) == before
    own = tmp_path / "own"
    own.mkdir()
    (own / "summary.csv").write_text("subject,score\ns1,3\n")
    with pytest.raises(AssertionError, match=f"run_keyed was given {len(jobs)} task"):
        run_campaign(jobs, own, workers=1, progress=False, warm_cache=False)


def test_a_fit_written_again_replaces_the_earlier_one(recs, tmp_path, capsys):
    """A result of the command itself is not a recording: a rerun replaces it."""
    from bayespilot.fit.fast import fit_fast

    out = tmp_path / "fit.json"
    out.write_text(json.dumps({"params": {"K_v": 1.0}, "neg_log_lik": 0.0, "vaf": 0.0,
                               "method": "fast"}))
    assert main(["fit", recs[0], "--method", "fast", "--seed", "4", "--json", str(out),
                 "-q"]) == 0
    capsys.readouterr()
    direct = fit_fast(read_recording(recs[0]), seed=4)
    got = json.loads(out.read_text())
    assert got["params"] == pytest.approx(dict(direct.params), rel=1e-12)
    assert got["neg_log_lik"] == pytest.approx(direct.neg_log_lik, rel=1e-12)


# --- 1.3: summary.csv's posterior columns are not conditions.csv's ----------------------------
def test_the_posterior_columns_are_named_apart_from_the_conditions_table(fitted):
    header = next(csv.reader(open(fitted / "summary.csv", encoding="utf-8")))
    assert header == list(SUMMARY_FIELDS)
    posterior = ["delta_abs_posterior_median", "delta_abs_posterior_hdi_low",
                 "delta_abs_posterior_hdi_high"]
    assert all(c in header for c in posterior)
    # joined on the condition, the two tables share no delta_abs column
    shared = set(SUMMARY_FIELDS) & set(CONDITION_FIELDS)
    assert not {c for c in shared if c.startswith("delta_abs")}
    # a row of a sampled result: the posterior's median and HDI under those names, and the
    # median of the fits of conditions.csv is not among them
    stored = json.loads((fitted / "a.json").read_text())
    stored["posterior"] = {"summary": {"delta_abs": {"median": 0.0081,
                                                     "hdi_90": [0.0062, 0.0097]}},
                           "converged": True}
    row = _summary_row(stored)
    assert [row[c] for c in posterior] == [0.0081, 0.0062, 0.0097]
    assert "delta_abs_median" not in row


# --- 3.4: the forcing's line multiples stay integers ------------------------------------------
def test_the_forcing_lines_are_integers_and_old_results_still_resume(recs, fitted, tmp_path,
                                                                     monkeypatch):
    sidecar = json.loads(open(recs[0] + ".json", encoding="utf-8").read())
    for part in ("target", "disturbance"):
        lines = sidecar["forcing"][part]["n"]
        assert lines and all(type(n) is int for n in lines)
        meta = _recording_metadata(read_recording(recs[0]))["forcing"][part]
        assert meta["n"] == lines and all(type(n) is int for n in meta["n"])
    stored = json.loads((fitted / "a.json").read_text())
    assert stored["recording_metadata"][0]["forcing"]["target"]["n"] == \
        sidecar["forcing"]["target"]["n"]
    assert all(type(n) is int for n in stored["recording_metadata"][0]["forcing"]["target"]["n"])
    # a result written before (the lines as 6.0, 9.0, ...) resumes: not redone, not refused
    out = _copy(fitted, tmp_path)
    for key in ("a", "b"):
        old = json.loads((out / f"{key}.json").read_text())
        for part in ("target", "disturbance"):
            f = old["recording_metadata"][0]["forcing"][part]
            f["n"] = [float(n) for n in f["n"]]
        (out / f"{key}.json").write_text(json.dumps(old))
    assert '"n": [6.0, 9.0' in (out / "a.json").read_text()
    _nothing_runs(monkeypatch)
    assert fit_batch(recs, out, seed=1, **FITS).skipped == 2


# --- section 6: loglik --params given another kind of file ------------------------------------
@pytest.mark.parametrize("which, said", [
    ("diagnosis", "is a diagnosis ('bayespilot diagnose --json'), not a parameter file"),
    ("diagnose-batch", "is a result of 'bayespilot diagnose-batch' (a diagnosis), not a "
                       "parameter file"),
    ("fit-batch", "is a result of 'bayespilot fit-batch' (its fits are under "
                  "\"fit_threshold\" and \"fit_none\"; 'bayespilot fit REC --json' writes one "
                  "fit's file), not a parameter file"),
    ("sidecar", "is a recording's JSON sidecar, not a parameter file"),
    ("posterior", "is a posterior's summary ('bayespilot sample --json': statistics per "
                  "parameter), not a parameter file"),
])
def test_loglik_says_what_a_params_file_of_another_kind_is(recs, fitted, diagnosed, tmp_path,
                                                           capsys, which, said):
    files = {"diagnose-batch": diagnosed / "a.json", "fit-batch": fitted / "a.json",
             "sidecar": recs[1] + ".json"}
    if which == "diagnosis":
        path = tmp_path / "diag.json"
        path.write_text(json.dumps(json.loads((diagnosed / "a.json").read_text())["diagnosis"]))
    elif which == "posterior":  # (what sample --json writes: its table under "summary")
        path = tmp_path / "post.json"
        table = {"mean": 1.0, "median": 1.0, "hdi_90": [0.9, 1.1], "r_hat": 1.0,
                 "ess_bulk": 400.0, "ess_tail": 400.0, "tau": 50.0}
        path.write_text(json.dumps({"summary": {"K_v": table, "delta_abs": table},
                                    "converged": True, "steps": 1000, "seed": 0}))
    else:
        path = files[which]
    assert main(["loglik", recs[0], "--params", str(path)]) == 2
    err = capsys.readouterr().err
    assert err == (f"bayespilot: error: {path}: {said}: give a JSON object of parameter values "
                   f"by name (K_v, T_vl, tau_v, K_m, tau_m, omega_nm, zeta_nm, delta_abs), e.g. "
                   f"{{\"K_v\": 1.057}}, or a fit's result ('bayespilot fit --json')\n")
    assert "unknown" not in err

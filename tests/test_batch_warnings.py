"""What fit-batch and diagnose-batch say at scale, and the order of a pooled condition's runs.

- The warnings of a diagnosis on a worker are recorded in its result (``warnings``) and said
  once per kind, naming the diagnoses (scale audit 2: a dask worker printed each raw, 171
  lines for 24 recordings).
- The QuestionableRecordingWarning of reading the recordings is said once per reason,
  naming how many recordings and which (scale audit 3: once per recording, on every call).
- diagnose-batch names every recording it cannot use, once each (scale audit 5).
- A pooled condition's runs are in the order of their signals' digests, so the same
  recordings under other names give the same diagnosis (seeds audit 1), and a folder of
  results made with the order of the files still resumes.

The batches run their tasks in this process (``campaign.run_keyed`` replaced, no cluster);
every number is checked against the same computation run here.
"""

from __future__ import annotations

import json
import re
import shutil
import warnings

import pytest

from bayespilot import campaign as C
from bayespilot.batch import fit_batch
from bayespilot.cli import main
from bayespilot.diagnose import diagnose, diagnose_pooled
from bayespilot.diagnose.batch import diagnose_batch, plan_batch, task_seed
from bayespilot.io import read_recording, write_recording
from bayespilot.recording import QuestionableRecordingWarning, Recording, _signals_digest
from bayespilot.simulate import simulate


def _write(folder, name, *, subject="s1", motion_gain=1.0, seed=0, duration=20.0):
    rec = simulate(task="FD", motion_gain=motion_gain, remnant_gain=0.07, seed=seed,
                   duration=duration).recording
    folder.mkdir(parents=True, exist_ok=True)
    write_recording(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task,
                              {"subject": subject}), folder / name)
    return str(folder / name)


def _run_here(monkeypatch):
    """The batch's tasks run in this process, as the workers run them; returns the keys run."""
    ran = []

    def run_keyed(tasks, out, *, to_json, **kwargs):
        for key, fn, args, _ in tasks:
            ran.append(key)
            C._write_json_atomic(out / f"{key}.json", to_json(key, fn(*args)))
        return len(tasks), {}

    monkeypatch.setattr(C, "run_keyed", run_keyed)
    return ran


def _nothing_runs(monkeypatch):
    def run_keyed(*args, **kwargs):
        raise AssertionError("run_keyed was called")

    monkeypatch.setattr(C, "run_keyed", run_keyed)


def _caught(fn, *args, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        value = fn(*args, **kwargs)
    return value, caught


SHORT = "s long, much shorter than the 81.92 s runs of Pool et al. (2012)"
FAST = {"method": "fast", "fit_options": {"n_starts": 1, "profile_step": 0.02},
        "progress": False, "warm_cache": False}
CHEAP = {"n_bootstrap": 0, "candidates": ["motion-washout", "time-varying-gains"],
         "progress": False, "warm_cache": False}


# --- scale 2: a diagnosis's warnings on the worker ------------------------------------------------
def test_diagnose_batch_records_the_workers_warnings_and_says_each_kind_once(tmp_path,
                                                                            monkeypatch):
    _run_here(monkeypatch)
    paths = [_write(tmp_path / "recs", name, motion_gain=0.0, seed=s)
             for name, s in (("k0a", 1), ("k0b", 2))]
    paths.append(_write(tmp_path / "recs", "k1", seed=3))
    out = tmp_path / "out"
    _, caught = _caught(diagnose_batch, paths, out, seed=2, **CHEAP)
    # nothing of the diagnoses' own reaches the caller raw: one line per kind, naming them
    assert not [w for w in caught if w.category.__name__ == "SilentChannelWarning"]
    said = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    assert len(said) == 1, said
    assert said[0].startswith("SilentChannelWarning in 2 diagnosis(es) (k0a, k0b), e.g. k0a: "
                              "the vestibular channel's input (theta_ddot_m) is zero")
    # each result lists what its diagnosis, run here with the same seed, warned, once each
    options = {k: CHEAP[k] for k in ("n_bootstrap", "candidates")}
    for p, key in zip(paths, ("k0a", "k0b", "k1")):
        with warnings.catch_warnings(record=True) as direct:
            warnings.simplefilter("always")
            rec = read_recording(p)
            del direct[:]
            diagnose(rec, seed=task_seed(2, [_signals_digest(rec)]), **options)
        want = []
        for w in direct:
            entry = {"category": w.category.__name__, "message": str(w.message)}
            if w.category.__name__ != "EvidenceWarning" and entry not in want:
                want.append(entry)
        got = json.loads((out / f"{key}.json").read_text())["warnings"]
        assert got == want
        assert bool(got) == (key != "k1")


# --- scale 3: the warnings of reading the recordings ----------------------------------------------
def test_fit_batch_says_a_reason_of_reading_once_for_all_its_recordings(tmp_path, monkeypatch):
    _run_here(monkeypatch)
    paths = [_write(tmp_path / "recs", n, seed=s) for n, s in (("c", 1), ("a", 2), ("b", 3))]
    paths.append(_write(tmp_path / "recs", "long", seed=4, duration=25.0))
    out = tmp_path / "out"
    for _ in range(2):  # the first call, and again with nothing to fit
        _, caught = _caught(fit_batch, paths, out, **FAST)
        said = [str(w.message) for w in caught
                if issubclass(w.category, QuestionableRecordingWarning)]
        # one warning for the reason, without a path, naming how many recordings and which;
        # the numbers differ (20 and 25 s): one recording's text given
        folder = str(tmp_path / "recs")
        assert said == [f"4 of 4 recordings ({folder}/a, {folder}/b, {folder}/c, ... (4 in "
                        f"all)), e.g. {folder}/a: the record is 20 {SHORT}; the estimates (of "
                        f"delta_abs above all) will be far less certain"]
    # the same reason alone: said once as it is; a recording alone: as read_recording says it
    # (the fits are not what is tested here: none is run)
    monkeypatch.setattr(C, "run_keyed", lambda tasks, out, **kw: (0, {}))
    _, caught = _caught(fit_batch, paths[:3], tmp_path / "out3", **FAST)
    said = [str(w.message) for w in caught if issubclass(w.category, QuestionableRecordingWarning)]
    assert said == [f"3 of 3 recordings ({folder}/a, {folder}/b, {folder}/c): the record is "
                    f"20 {SHORT}; the estimates (of delta_abs above all) will be far less "
                    f"certain"]
    _, caught = _caught(fit_batch, paths[:1], tmp_path / "out1", **FAST)
    with warnings.catch_warnings(record=True) as direct:
        warnings.simplefilter("always")
        read_recording(paths[0])
    assert ([str(w.message) for w in caught if w.category is QuestionableRecordingWarning]
            == [str(w.message) for w in direct])


def test_cli_fit_batch_prints_a_reason_of_reading_once(tmp_path, monkeypatch, capsys):
    folder = tmp_path / "recs"
    for n, s in (("a", 1), ("b", 2), ("c", 3), ("d", 4), ("e", 5)):
        _write(folder, n, seed=s)
    # (the fits are not what is tested: none is run)
    monkeypatch.setattr(C, "run_keyed", lambda tasks, out, **kw: (0, {}))
    code = main(["fit-batch", str(folder), "--out", str(tmp_path / "out"), "--method", "fast",
                 "--workers", "1", "-q"])
    err = capsys.readouterr().err
    assert code == 0, err
    lines = [line for line in err.splitlines() if "the record is" in line]
    assert lines == [f"bayespilot: warning: 5 of 5 recordings ({folder}/a, {folder}/b, "
                     f"{folder}/c, ... (5 in all)): the record is 20 {SHORT}; the estimates "
                     f"(of delta_abs above all) will be far less certain"]


def test_diagnose_batch_says_a_reason_of_reading_once(tmp_path, monkeypatch):
    _run_here(monkeypatch)
    paths = [_write(tmp_path / "recs", n, seed=s) for n, s in (("a", 1), ("b", 2))]
    _, caught = _caught(diagnose_batch, paths, tmp_path / "out", **CHEAP)
    said = [str(w.message) for w in caught if issubclass(w.category, QuestionableRecordingWarning)]
    folder = str(tmp_path / "recs")
    assert said == [f"2 of 2 recordings ({folder}/a, {folder}/b): the record is 20 {SHORT}; "
                    f"the estimates (of delta_abs above all) will be far less certain"]


# --- scale 5: every recording diagnose-batch cannot use, named once -------------------------------
def test_diagnose_batch_names_every_recording_it_cannot_use(tmp_path, monkeypatch):
    _nothing_runs(monkeypatch)
    ok = _write(tmp_path / "recs", "ok", seed=1)
    short = [_write(tmp_path / "recs", n, seed=s, duration=8.0) for n, s in (("x", 2), ("y", 3))]
    out = tmp_path / "out"
    with pytest.raises(ValueError) as err:
        _caught(diagnose_batch, [short[0], ok, short[1]], out, **CHEAP)
    lines = str(err.value).splitlines()
    assert lines[0] == "2 of 3 recordings cannot be diagnosed with these settings; nothing was run:"
    assert lines[1:] == [f"  the recording {p} is 8 s long: too short to leave out the first 5 s "
                         f"(skip_seconds) and keep more than as much; it needs more than 10 s"
                         for p in short]
    assert not out.exists()
    # a bad setting is the setting's error, not one per recording
    with pytest.raises(ValueError, match=r"^noise_passes must be an integer in \[1, \d+\], "
                                         r"got 7$"):
        _caught(diagnose_batch, [short[0], ok], out, noise_passes=7, **CHEAP)


# --- seeds 1: a pooled condition's runs in the order of their content -----------------------------
POOL = {"pool": True, "seed": 3, "n_bootstrap": 1, "candidates": ["motion-washout"],
        "progress": False, "warm_cache": False}


@pytest.fixture(scope="module")
def swapped(tmp_path_factory):
    """Two runs of s1 at K_theta 1, under names whose order is that of their digests
    (``orig``) and under the other's names (``renamed``), whose order is the reverse."""
    base = tmp_path_factory.mktemp("pool")
    w1 = _write(base / "src", "w1", seed=1)
    w2 = _write(base / "src", "w2", seed=2)
    low, high = sorted((w1, w2), key=lambda p: _signals_digest(read_recording(p)))
    for folder, names in (("orig", ("r1", "r2")), ("renamed", ("r2", "r1"))):
        (base / folder).mkdir()
        for src, name in zip((low, high), names):
            for ext in (".csv", ".json"):
                shutil.copy(src + ext, base / folder / (name + ext))
    return base, [read_recording(p) for p in (low, high)]


def test_plan_batch_orders_a_conditions_runs_by_their_content(swapped):
    base, (low, high) = swapped
    for folder in ("orig", "renamed"):
        paths = [str(base / folder / n) for n in ("r1", "r2")]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            recs = [read_recording(p) for p in paths]
        for given in (paths, paths[::-1]):
            by = dict(zip(paths, recs))
            (task,) = plan_batch(given, [by[p] for p in given], pool=True)
            assert [_signals_digest(by[p]) for p in task.paths] == [
                _signals_digest(low), _signals_digest(high)]


def test_a_pooled_diagnosis_does_not_depend_on_the_runs_names(swapped, tmp_path, monkeypatch):
    base, (low, high) = swapped
    _run_here(monkeypatch)
    got = {}
    for folder in ("orig", "renamed"):
        out = tmp_path / folder
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            diagnose_batch([str(base / folder / n) for n in ("r1", "r2")], out, **POOL)
        got[folder] = json.loads((out / "s1_FD_k1.json").read_text())
    seed = task_seed(3, [_signals_digest(low), _signals_digest(high)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = diagnose_pooled([low, high], seed=seed, n_bootstrap=1,
                              candidates=["motion-washout"])
    for folder, res in got.items():
        assert res["recording_digests"] == [_signals_digest(low), _signals_digest(high)]
        (c,) = res["diagnosis"]["ranking"]
        (r,) = ref.ranking
        assert (c["p_value"], c["delta_neg_log_lik"]) == (r.p_value, r.delta_neg_log_lik), folder
    assert _without_paths(got["orig"]["diagnosis"]) == _without_paths(got["renamed"]["diagnosis"])


def _without_paths(obj):
    """A result's dict without where its recordings lie (``source``) and its timings."""
    if isinstance(obj, dict):
        return {k: _without_paths(v) for k, v in obj.items()
                if k != "source" and not k.endswith("seconds")}
    if isinstance(obj, list):
        return [_without_paths(v) for v in obj]
    return obj


def test_a_pooled_result_made_in_the_files_order_resumes(swapped, tmp_path, monkeypatch):
    """The code before recorded a pooled condition's runs (and their digests and sidecars) in
    the order of their files: in ``renamed`` the reverse of their digests'.  Such a result is
    taken as done, not redone or refused."""
    base, _ = swapped
    paths = [str(base / "renamed" / n) for n in ("r1", "r2")]
    out = tmp_path / "out"
    _run_here(monkeypatch)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        diagnose_batch(paths, out, **POOL)
    stored = json.loads((out / "s1_FD_k1.json").read_text())
    assert [p.split("/")[-1] for p in stored["recordings"]] == ["r2", "r1"]  # by content
    old = {**stored, **{k: stored[k][::-1] for k in ("recordings", "recording_digests",
                                                   "recording_metadata")}}
    assert [p.split("/")[-1] for p in old["recordings"]] == ["r1", "r2"]  # by file
    C._write_json_atomic(out / "s1_FD_k1.json", old)
    before = (out / "s1_FD_k1.json").read_bytes()
    ran = _run_here(monkeypatch)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        summary = diagnose_batch(paths, out, **POOL)
    assert (summary.completed, summary.skipped, summary.failed) == (0, 1, 0) and ran == []
    assert (out / "s1_FD_k1.json").read_bytes() == before
    row = (out / "summary.csv").read_text().splitlines()[1]
    assert re.match(r"s1_FD_k1,2,s1,FD,1\.0,", row)


def test_cli_diagnose_batch_prints_the_workers_warnings_one_line_each(tmp_path, monkeypatch,
                                                                      capsys):
    """The batch's grouped RuntimeWarning came out in Python's two-line format
    ("/.../bayespilot:8: RuntimeWarning: ..." and "sys.exit(main())"), as fit-batch's did not."""
    import functools

    import bayespilot.diagnose.batch as B

    _run_here(monkeypatch)
    # (two entries, not the whole catalogue: what is tested is how the CLI says the warning)
    monkeypatch.setattr(B, "diagnose_batch", functools.partial(
        B.diagnose_batch, candidates=CHEAP["candidates"]))
    folder = tmp_path / "recs"
    for n, s in (("k0a", 1), ("k0b", 2)):
        _write(folder, n, motion_gain=0.0, seed=s)
    code = main(["diagnose-batch", str(folder), "--out", str(tmp_path / "out"), "--bootstrap",
                 "0", "--workers", "1", "-q"])
    err = capsys.readouterr().err
    assert code == 0, err
    lines = [line for line in err.splitlines() if "SilentChannelWarning" in line]
    assert len(lines) == 1 and lines[0].startswith(
        "bayespilot: warning: SilentChannelWarning in 2 diagnosis(es) (k0a, k0b), e.g. k0a: "), err
    assert "RuntimeWarning" not in err and "sys.exit" not in err
    # (in the command's words: a command-line user cannot call model.fix)
    assert ("the record says nothing about them, and the values given for them are not "
            "estimates") in lines[0], lines[0]
    assert "model.fix" not in err


def test_plan_batch_refuses_digests_without_a_path(swapped):
    """(Its new keyword: a mapping that lacks a path raised a bare KeyError of the path.)"""
    base, recs = swapped
    paths = [str(base / "orig" / n) for n in ("r1", "r2")]
    with pytest.raises(ValueError, match=r"^digests has no digest of .* \(1 of 2 paths\): give "
                                         r"one per path, or none$"):
        plan_batch(paths, recs, pool=True, digests={paths[0]: "0" * 64})

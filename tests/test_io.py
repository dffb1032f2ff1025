"""Tests of bayespilot.io: reading, writing and refusing recordings on disk."""

from __future__ import annotations

import doctest
import hashlib
import json
import os
import re
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.io

import bayespilot.io as bio
from bayespilot.io import FORMAT, read_mat, read_recording, write_recording
from bayespilot.recording import Recording, RecordingError

DATA = Path(__file__).parent / "data"
MALFORMED = DATA / "malformed"
VALID = DATA / "valid"


def _rec(n: int = 50, rate: float = 100.0, seed: int = 0, **metadata) -> Recording:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    signals = {
        "t": t,
        "u": rng.normal(size=n) * 0.1,
        "e": rng.normal(size=n) * np.pi,          # many digits
        "theta_ddot_m": rng.normal(size=n) * 1e-7,  # small exponents
        "f_d": rng.normal(size=n) * 1e12,
        "stick_force": rng.normal(size=n),        # unknown column
    }
    return Recording(signals, rate, 0.75, "FT", metadata)


# ---------------------------------------------------------------------------
# the malformed corpus: one case, one message naming the file
# ---------------------------------------------------------------------------
CASES = [
    # (path given to read_recording, file named in the message, message regex)
    ("missing_column.csv", "missing_column.csv", r"missing required column\(s\): u"),
    ("nan_value.csv", "nan_value.csv", r"NaN in column 'e' at line 6 \(values must be finite\)"),
    ("inf_value.csv", "inf_value.csv", r"infinite value 'inf' in column 'u' at line 8"),
    ("non_numeric.csv", "non_numeric.csv",
     r"non-numeric value 'abc' in column 'theta_ddot_m' at line 5"),
    ("empty_value", "empty_value.csv", r"empty value in column 'u' at line 4"),
    ("nonuniform_t.csv", "nonuniform_t.csv", r"t is not uniformly spaced \(step 0\.015 s at sample 6\)"),
    ("rate_mismatch.json", "rate_mismatch.csv",
     r"t has a step of 0\.02 s, which disagrees with sample_rate_hz = 100"),
    ("t_not_zero", "t_not_zero.csv", r"t must start at 0, starts at 1\.0"),
    ("no_sidecar.csv", "no_sidecar.csv", r"no sidecar .*no_sidecar\.json found"),
    ("no_sidecar", "no_sidecar.csv", r"no sidecar .*no_sidecar\.json found"),
    ("no_csv.json", "no_csv.json", r"no signals file .*no_csv\.csv found"),
    ("no_csv", "no_csv.json", r"no signals file .*no_csv\.csv found"),
    ("broken_json.csv", "broken_json.json",
     r"is not valid JSON \(Expecting ',' delimiter at line 5 column 3\)"),
    ("json_not_object", "json_not_object.json",
     r"must hold a JSON object at the top level, got an array"),
    ("missing_key.csv", "missing_key.json", r"missing required key\(s\): motion_gain"),
    ("empty_csv.csv", "empty_csv.csv", r"file is empty \(expected a header row and data rows\)"),
    ("empty_json.csv", "empty_json.json", r"file is empty \(expected a JSON object\)"),
    ("header_only.csv", "header_only.csv", r"header only, no data rows"),
    ("unknown_format.csv", "unknown_format.json",
     r"unknown format 'bayespilot-recording/2' \(expected 'bayespilot-recording/1'\)"),
    ("short_row.csv", "short_row.csv", r"line 6 has 3 fields, expected 7 .*equal length"),
    ("long_row.csv", "long_row.csv", r"line 4 has 8 fields, expected 7 .*equal length"),
    ("duplicate_column.csv", "duplicate_column.csv", r"duplicate column name 'e' in the header"),
    ("ce_and_gain.csv", "ce_and_gain.json",
     r"give either controlled_element or controlled_element_gain, not both"),
    ("ce_not_numbers.csv", "ce_not_numbers.json",
     r"controlled_element\.num\[0\] must be a finite number, got '4'"),
    ("forcing_unequal.csv", "forcing_unequal.json",
     r"forcing\.target arrays have unequal lengths \(n: 3, amplitude: 2, phase: 3\)"),
    ("bad_task.csv", "bad_task.json", r"task must be one of 'FD', 'FT', 'other', got 'fd'"),
    ("nan_in_json.csv", "nan_in_json.json", r"is not valid JSON \(NaN is not allowed"),
    ("does_not_exist.csv", "does_not_exist.csv", r"file not found$"),
    ("does_not_exist.json", "does_not_exist.json", r"file not found$"),
    ("does_not_exist", "does_not_exist",
     r"file not found \(looked for .*does_not_exist\.csv and .*does_not_exist\.json\)"),
    ("does_not_exist.mat", "does_not_exist.mat", r"file not found$"),
]


@pytest.mark.parametrize("given, named, pattern", CASES, ids=[c[0] for c in CASES])
def test_malformed_corpus(given, named, pattern):
    path = MALFORMED / given
    with pytest.raises(RecordingError) as info:
        read_recording(path)
    msg = str(info.value)
    assert re.fullmatch(re.escape(str(MALFORMED / named)) + ": " + pattern + r".*", msg), msg
    assert "\n" not in msg
    assert isinstance(info.value, ValueError)


def test_every_corpus_file_is_used_and_listed():
    listed = (MALFORMED / "README.md").read_text()
    stems = {p.stem for p in MALFORMED.iterdir() if p.suffix in (".csv", ".json")}
    used = {Path(c[0]).stem for c in CASES}
    assert stems <= used
    for stem in stems | {"does_not_exist"}:
        assert f"`{stem}" in listed, stem


def test_malformed_accepts_str_paths():
    with pytest.raises(RecordingError, match=r"missing_column\.csv: missing required column"):
        read_recording(str(MALFORMED / "missing_column.csv"))


def test_path_type_checked():
    with pytest.raises(TypeError, match="path must be a str or os.PathLike"):
        read_recording(42)
    with pytest.raises(TypeError, match="recording must be a Recording"):
        write_recording({"t": [0, 1]}, "x")


# ---------------------------------------------------------------------------
# more refusals, built in tmp_path
# ---------------------------------------------------------------------------
def _pair(tmp_path: Path, csv_text: str, meta: dict | str | None = None, name: str = "run") -> Path:
    (tmp_path / f"{name}.csv").write_text(csv_text)
    if meta is None:
        meta = {"format": FORMAT, "sample_rate_hz": 10, "motion_gain": 0, "task": "other"}
    text = meta if isinstance(meta, str) else json.dumps(meta)
    (tmp_path / f"{name}.json").write_text(text)
    return tmp_path / name


GOOD_CSV = "t,e,u,theta_ddot_m\n0,1,2,3\n0.1,1,2,3\n0.2,1,2,3\n"


@pytest.mark.parametrize("cell, pattern", [
    ("1_0", r"non-numeric value '1_0' in column 'u' at line 3"),
    ("0x10", r"non-numeric value '0x10'"),
    ("1e999", r"infinite value '1e999' in column 'u' at line 3 \(overflows"),
    ("-Infinity", r"infinite value '-Infinity'"),
    ("NAN", r"NaN in column 'u' at line 3"),
    ("1,5", r"line 3 has 5 fields, expected 4"),
    (" ", r"empty value in column 'u' at line 3"),
    ("\u0661", r"non-numeric value"),  # an Arabic-Indic digit, which float() accepts
])
def test_bad_cells(tmp_path, cell, pattern):
    stem = _pair(tmp_path, GOOD_CSV.replace("0.1,1,2,3", f"0.1,1,{cell},3"))
    with pytest.raises(RecordingError, match=re.escape(str(stem) + ".csv: ") + pattern):
        read_recording(stem)


@pytest.mark.parametrize("meta, pattern", [
    ({"sample_rate_hz": "10"}, r"sample_rate_hz must be a positive finite number, got '10'"),
    ({"sample_rate_hz": 0}, r"sample_rate_hz must be a positive finite number, got 0"),
    ({"motion_gain": -1}, r"motion_gain must be a finite number >= 0, got -1"),
    ({"motion_gain": True}, r"motion_gain must be a finite number >= 0, got True"),
    ({"format": 1}, r"unknown format 1 \(expected"),
    ({"run": 1.5}, r"run must be an integer, got 1.5"),
    ({"subject": 7}, r"subject must be a string, got 7"),
    ({"control_gain": "x"}, r"control_gain must be a finite number"),
    ({"controlled_element": [4, 1]}, r"controlled_element must be an object with arrays num and den"),
    ({"controlled_element": {"num": [4]}}, r"controlled_element has no 'den' array"),
    ({"controlled_element": {"num": [4], "den": [0, 0]}}, r"controlled_element.den is all zeros"),
    ({"forcing": {"target": {}}}, r"forcing has no base_frequency"),
    ({"forcing": {"base_frequency": 0.1, "target": {"n": [1], "amplitude": [1], "phase": [0]}}},
     r"forcing has no 'disturbance' object"),
    ({"forcing": {"base_frequency": 0.1, "target": {"n": [1.5], "amplitude": [1], "phase": [0]},
                  "disturbance": {"n": [1], "amplitude": [1], "phase": [0]}}},
     r"forcing.target.n\[0\] must be an integer, got 1.5"),
    ({"forcing": {"base_frequency": 0.1, "target": {"n": [1], "amplitude": [1], "phase": [0]},
                  "disturbance": {"n": [2, 0], "amplitude": [1, 1], "phase": [0, 0]}}},
     r"forcing.disturbance.n must hold integers >= 1 \(multiples of base_frequency\), got 0"),
    ({"forcing": {"base_frequency": 0.1, "target": {"n": [1], "amplitude": 1, "phase": [0]},
                  "disturbance": {"n": [1], "amplitude": [1], "phase": [0]}}},
     r"forcing.target.amplitude must be an array of numbers, got an integer"),
])
def test_bad_metadata(tmp_path, meta, pattern):
    base = {"format": FORMAT, "sample_rate_hz": 10, "motion_gain": 0, "task": "other"}
    stem = _pair(tmp_path, GOOD_CSV, {**base, **meta})
    with pytest.raises(RecordingError, match=re.escape(str(stem) + ".json: ") + pattern):
        read_recording(stem)


def test_duplicate_json_key_refused(tmp_path):
    text = '{"format": "%s", "sample_rate_hz": 10, "motion_gain": 0, "task": "FD", "task": "FT"}' % FORMAT
    stem = _pair(tmp_path, GOOD_CSV, text)
    with pytest.raises(RecordingError, match=r"run\.json: is not valid JSON \(duplicate key 'task'\)"):
        read_recording(stem)


def test_csv_not_utf8_refused(tmp_path):
    stem = _pair(tmp_path, GOOD_CSV)
    (tmp_path / "run.csv").write_bytes(b"t,e,u,theta_ddot_m,\xff\n0,1,2,3,4\n")
    with pytest.raises(RecordingError, match=r"run\.csv: is not UTF-8 text"):
        read_recording(stem)


def test_directory_refused(tmp_path):
    (tmp_path / "run.csv").mkdir()
    (tmp_path / "run.json").write_text(json.dumps(
        {"format": FORMAT, "sample_rate_hz": 10, "motion_gain": 0, "task": "FD"}))
    with pytest.raises(RecordingError, match=r"run\.csv: is a directory"):
        read_recording(tmp_path / "run.csv")


def test_lenient_but_exact_csv_details(tmp_path):
    # order of columns free, blanks around cells and names, BOM, CRLF, trailing blank line
    text = "\ufeff u , t,theta_ddot_m,e\r\n2, 0 ,3,1\r\n2,0.1,3,1\r\n2,0.2,3,1\r\n\r\n"
    stem = _pair(tmp_path, text)
    rec = read_recording(stem)
    assert list(rec.signals) == ["u", "t", "theta_ddot_m", "e"]
    assert np.array_equal(rec.t, [0, 0.1, 0.2])
    assert rec.source == str(stem)


def test_blank_line_in_the_middle_refused(tmp_path):
    stem = _pair(tmp_path, GOOD_CSV.replace("0.1,1,2,3\n", "0.1,1,2,3\n\n"))
    with pytest.raises(RecordingError, match=r"run\.csv: line 4 is blank"):
        read_recording(stem)


# ---------------------------------------------------------------------------
# the valid recording
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("given", ["tiny", "tiny.csv", "tiny.json"])
def test_read_valid_tiny(given):
    rec = read_recording(VALID / given)
    assert rec.n_samples == 10
    assert rec.sample_rate_hz == 100.0 and rec.motion_gain == 1.0 and rec.task == "FD"
    assert list(rec.signals) == ["t", "e", "u", "theta_ddot_m", "theta", "f_t", "f_d", "stick_force"]
    assert np.array_equal(rec["stick_force"], [float(f"{1.5 + 0.1 * i:.3f}") for i in range(10)])
    assert np.array_equal(rec.t, np.arange(10) / 100.0)
    assert rec.metadata["lab_session"] == "A-17"
    assert rec.metadata["run"] == 3 and rec.metadata["subject"] == "S07"
    assert rec.metadata["forcing"]["target"]["n"] == [6, 13, 27]
    assert set(rec.metadata) == {"subject", "run", "controlled_element_gain", "control_gain",
                                 "forcing", "notes", "lab_session"}
    assert rec.source == str(VALID / "tiny")
    assert rec.u.dtype == np.float64


# ---------------------------------------------------------------------------
# round trips
# ---------------------------------------------------------------------------
def _assert_same(a: Recording, b: Recording) -> None:
    assert set(a.signals) == set(b.signals)  # the writer puts t, e, u, theta_ddot_m first
    for name in a.signals:
        assert np.array_equal(a[name], b[name]), name
        assert np.array_equal(np.signbit(a[name]), np.signbit(b[name])), name
    assert a.sample_rate_hz == b.sample_rate_hz
    assert a.motion_gain == b.motion_gain
    assert a.task == b.task
    assert dict(a.metadata) == dict(b.metadata)


META = {
    "subject": "Sü 1, \"quoted\"",
    "run": 12,
    "controlled_element": {"num": [4.0], "den": [1.0, 0.0, 0.0]},
    "control_gain": 0.1 + 0.2,
    "forcing": {"base_frequency": 2 * np.pi / 81.92,
                "target": {"n": [6, 13, 27], "amplitude": [0.1 / 3, 1e-300, 5e-324], "phase": [1.0, -2.0, 3.0]},
                "disturbance": {"n": [5], "amplitude": [0.4], "phase": [-0.7]}},
    "notes": "line one\nline two",
    "unknown_key": {"nested": [1, "two", None, True, {"x": 1.5}]},
}


@pytest.mark.parametrize("given", ["out/run", "out/run.csv", "out/run.json", "a/b/run.v2"])
def test_round_trip_exact(tmp_path, given):
    rec = _rec(**META)
    target = tmp_path / given
    csv_path, json_path = write_recording(rec, target)
    assert csv_path.name.endswith(".csv") and json_path.name.endswith(".json")
    assert csv_path.with_suffix("") == json_path.with_suffix("")
    for p in (csv_path, json_path, csv_path.with_suffix(""), str(json_path)):
        back = read_recording(p)
        _assert_same(rec, back)
    assert back.metadata["unknown_key"] == META["unknown_key"]
    assert "stick_force" in back


def test_column_order_and_format(tmp_path):
    t = np.arange(3) / 4.0
    rec = Recording({"zeta": t, "theta_ddot_m": t, "u": -t, "f_t": t, "e": t, "t": t}, 4.0, 0.0, "FD")
    csv_path, json_path = write_recording(rec, tmp_path / "r")
    lines = csv_path.read_text().splitlines()
    assert lines[0] == "t,e,u,theta_ddot_m,zeta,f_t"
    assert lines[1] == "0.0,0.0,-0.0,0.0,0.0,0.0"
    doc = json.loads(json_path.read_text())
    assert list(doc)[:4] == ["format", "sample_rate_hz", "motion_gain", "task"]
    assert doc["format"] == FORMAT


def test_round_trip_random_values_exact(tmp_path):
    rng = np.random.default_rng(1)
    n = 2000
    vals = rng.standard_normal(n) * 10.0 ** rng.integers(-300, 300, n)
    rec = Recording({"t": np.arange(n) / 1000.0, "e": vals, "u": -vals, "theta_ddot_m": vals[::-1]},
                    1000.0, 1.0, "other")
    write_recording(rec, tmp_path / "r")
    _assert_same(rec, read_recording(tmp_path / "r"))


@pytest.mark.parametrize("name", ["a,b", 'say "hi"', "ü"])
def test_round_trip_odd_column_names(tmp_path, name):
    # quoted header names take the careful (pure Python) reader: still exact
    rec = _rec().with_signals(**{name: np.linspace(-1, 1, 50) / 3})
    write_recording(rec, tmp_path / "r")
    back = read_recording(tmp_path / "r")
    _assert_same(rec, back)
    assert list(back.signals)[-1] == name


def test_read_write_read_valid_tiny(tmp_path):
    rec = read_recording(VALID / "tiny")
    write_recording(rec, tmp_path / "tiny")
    _assert_same(rec, read_recording(tmp_path / "tiny"))


def test_write_overwrites_existing_pair(tmp_path):
    write_recording(_rec(seed=1), tmp_path / "r")
    rec2 = _rec(seed=2, n=20)
    write_recording(rec2, tmp_path / "r")
    _assert_same(rec2, read_recording(tmp_path / "r"))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv", "r.json"]


def test_write_accepts_numpy_metadata(tmp_path):
    rec = _rec(run=np.int64(4), gains=np.array([1.0, 2.5]), scale=np.float32(0.5))
    write_recording(rec, tmp_path / "r")
    back = read_recording(tmp_path / "r")
    assert back.metadata == {"run": 4, "gains": [1.0, 2.5], "scale": 0.5}


@pytest.mark.parametrize("kwargs, signals, pattern", [
    ({"lab_value": float("nan")}, {},
     r"r\.json: metadata metadata\.lab_value is nan, which JSON cannot hold"),
    ({"task": "FT"}, {}, r"r\.json: metadata reuses required key\(s\) task"),
    ({"obj": object()}, {}, r"r\.json: metadata metadata\.obj of type object cannot be written"),
    ({}, {" x": np.zeros(50)}, r"r\.csv: column name ' x' cannot be written"),
])
def test_write_refuses_what_the_reader_would_refuse(tmp_path, kwargs, signals, pattern):
    rec = _rec(**kwargs).with_signals(**signals) if signals else _rec(**kwargs)
    with pytest.raises(RecordingError, match=pattern):
        write_recording(rec, tmp_path / "r")
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------
# a Recording built in Python is held to what a file is
# ---------------------------------------------------------------------------
def _signals(n: int = 50, rate: float = 100.0) -> dict[str, np.ndarray]:
    t = np.arange(n) / rate
    return {"t": t, "e": np.sin(t), "u": np.cos(t), "theta_ddot_m": 0 * t}


def test_recording_refuses_complex_signal():
    sig = _signals()
    sig["e"] = sig["e"] + 1j * sig["u"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(RecordingError, match=r"^run7: column 'e' is complex; only real values"):
            Recording(sig, 100.0, 1.0, "FD", source="run7")
    assert caught == []                                 # refused, not cast with a ComplexWarning


def test_recording_refuses_text_and_booleans_for_numbers():
    """A rate or K_theta given as text or a bool, a column of text or booleans: refused (they
    were read as the number they happened to convert to)."""
    sig = _signals()
    for rate in ("100", True):
        with pytest.raises(RecordingError, match=f"sample_rate_hz must be a number, got {rate!r}"):
            Recording(sig, rate, 1.0, "FD")
    with pytest.raises(RecordingError, match="motion_gain must be a number, got True"):
        Recording(sig, 100.0, True, "FD")
    with pytest.raises(RecordingError, match="column 'e' holds text, not numbers"):
        Recording(dict(sig, e=sig["e"].astype(str)), 100.0, 1.0, "FD")
    with pytest.raises(RecordingError, match="column 'u' holds booleans, not numbers"):
        Recording(dict(sig, u=sig["u"] > 0), 100.0, 1.0, "FD")
    assert Recording(sig, np.float32(100.0), np.int64(1), "FD").sample_rate_hz == 100.0


@pytest.mark.parametrize("meta, pattern", [
    ({"controlled_element_gain": float("nan")}, r"controlled_element_gain must be a finite number, got nan"),
    ({"control_gain": "abc"}, r"control_gain must be a finite number, got 'abc'"),
    ({"control_gain": np.float32(np.inf)}, r"control_gain must be a finite number, got inf"),
    ({"controlled_element": {"num": [1.0], "den": [0, 0]}}, r"controlled_element\.den is all zeros"),
    ({"controlled_element": {"num": [], "den": [1, 0, 0]}}, r"controlled_element\.num is empty"),
    ({"controlled_element": {"num": [4.0], "den": [1, 0, 0]}, "controlled_element_gain": 4.0},
     r"give either controlled_element or controlled_element_gain, not both"),
    ({"run": "three"}, r"run must be an integer, got 'three'"),
    ({"notes": float("nan")}, r"notes must be a string, got nan"),
    ({"forcing": {"base_frequency": 0.1, "target": {"n": [1], "amplitude": [1, 2], "phase": [0]},
                  "disturbance": {"n": [1], "amplitude": [1], "phase": [0]}}},
     r"forcing\.target arrays have unequal lengths \(n: 1, amplitude: 2, phase: 1\)"),
    (None, r"metadata must be a mapping of key to value, got NoneType"),
])
def test_recording_refuses_out_of_range_metadata(meta, pattern):
    with pytest.raises(RecordingError, match=r"^lab/run1: " + pattern):
        Recording(_signals(), 100.0, 1.0, "FD", meta, source="lab/run1")


def test_recording_metadata_check_is_the_readers(tmp_path):
    """The same metadata is refused with the same message in memory and in a file."""
    meta = {"controlled_element": {"num": [1.0], "den": [0.0, 0.0]}}
    with pytest.raises(RecordingError) as in_memory:
        Recording(_signals(), 100.0, 1.0, "FD", meta)
    stem = _pair(tmp_path, GOOD_CSV, {"format": FORMAT, "sample_rate_hz": 10, "motion_gain": 0,
                                      "task": "other", **meta})
    with pytest.raises(RecordingError) as on_disk:
        read_recording(stem)
    assert str(on_disk.value) == f"{stem}.json: {in_memory.value}"


def test_recording_accepts_numpy_and_tuple_metadata():
    meta = {"control_gain": np.float32(0.69), "run": np.int64(3), "subject": np.str_("S1"),
            "controlled_element": {"num": (4.0,), "den": np.array([1.0, 1.0, 0.0])},
            "forcing": {"base_frequency": np.float64(0.0767),
                        "target": {"n": np.array([6.0, 13.0]), "amplitude": (0.5, 0.3),
                                   "phase": np.zeros(2, np.float32)},
                        "disturbance": {"n": [5], "amplitude": [0.4], "phase": [-0.7]}},
            "lab": object()}
    rec = Recording(_signals(), 100.0, 1.0, "FD", meta)
    assert rec.metadata["lab"] is meta["lab"]           # kept as given, unknown keys unchecked
    assert rec.control_gain == pytest.approx(0.69)
    num, den = rec.controlled_element
    assert num.tolist() == [4.0] and den.tolist() == [1.0, 1.0, 0.0]


# t saved in single precision, as MATLAB often saves it: an 81.92-s run at 100 Hz
_N32 = 8192


def _t32() -> np.ndarray:
    return (np.arange(_N32) / 100.0).astype(np.float32)


def _with_t(t: np.ndarray) -> dict[str, np.ndarray]:
    x = np.sin(np.arange(t.size) / 50.0)
    return {"t": t, "e": x, "u": 0.5 * x, "theta_ddot_m": x}


def test_float32_t_accepted():
    t = _t32()
    assert np.max(np.abs(np.diff(t.astype(float)) - 0.01)) > 1e-4 * 0.01  # beyond the old rule
    rec = Recording(_with_t(t), 100.0, 1.0, "FD")
    assert abs(rec.dt - 0.01) < 1e-9
    assert abs(np.mean(np.diff(rec.t)) - 0.01) < 1e-9
    assert np.array_equal(rec.t, t.astype(np.float64))


def test_float32_t_accepted_from_mat(tmp_path):
    t = _t32()
    scipy.io.savemat(tmp_path / "f32.mat", {**_with_t(t), "sample_rate_hz": 100.0,
                                            "motion_gain": 1.0, "task": "FD"})
    rec = read_mat(tmp_path / "f32.mat")
    assert rec.n_samples == _N32 and abs(rec.dt - 0.01) < 1e-9


def _dropped(t):
    return np.delete(t, 4000)


def _one_shifted(t):
    t = t.astype(np.float64)
    t[4000] += 0.01 * 0.01                              # 1 % of dt, one sample
    return t


def _jittered(t):
    return t.astype(np.float64) + np.r_[0.0, np.random.default_rng(3).uniform(-1e-4, 1e-4, t.size - 1)]


def _repeated(t):
    t = t.copy()
    t[4000] = t[3999]
    return t


@pytest.mark.parametrize("spoil", [_dropped, _one_shifted, _jittered, _repeated])
def test_float32_t_still_refused_when_not_uniform(spoil):
    with pytest.raises(RecordingError, match=r"t is not uniformly spaced \(step .* s at sample \d+\)"):
        Recording(_with_t(spoil(_t32())), 100.0, 1.0, "FD")


def test_write_refuses_mat_path(tmp_path):
    with pytest.raises(RecordingError, match=r"r\.mat: write_recording writes the CSV \+ JSON pair"):
        write_recording(_rec(), tmp_path / "r.mat")


def test_write_refuses_a_folder_for_a_stem(tmp_path):
    """``write_recording(rec, "out/")`` wrote out.csv and out.json beside the folder."""
    (tmp_path / "out").mkdir()
    with pytest.raises(RecordingError, match=r"out/: a folder; give the recording's stem in it "
                                             r"\(.*out/NAME, written as NAME\.csv and NAME\.json\)"):
        write_recording(_rec(), f"{tmp_path}/out/")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # nothing written
    # a stem that is also a folder's name is a stem: out.csv and out.json beside the folder
    csv_path, _ = write_recording(_rec(), tmp_path / "out")
    assert csv_path == tmp_path / "out.csv"


# ---------------------------------------------------------------------------
# atomic writes
# ---------------------------------------------------------------------------
def _snapshot(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


@pytest.mark.parametrize("previous", [True, False])
def test_second_replace_fails_leaves_previous_pair(tmp_path, monkeypatch, previous):
    old = _rec(seed=1)
    if previous:
        write_recording(old, tmp_path / "r")
    before = _snapshot(tmp_path)
    real_replace = os.replace
    calls = []

    def flaky_replace(src, dst):
        calls.append((Path(src), Path(dst)))
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        return real_replace(src, dst)

    monkeypatch.setattr(bio.os, "replace", flaky_replace)
    with pytest.raises(OSError, match="No space left"):
        write_recording(_rec(seed=2, n=30), tmp_path / "r")
    monkeypatch.undo()
    assert calls[0][1].name == "r.csv" and calls[1][1].name == "r.json"  # JSON last
    assert _snapshot(tmp_path) == before  # previous pair intact, no temporaries left
    if previous:
        _assert_same(old, read_recording(tmp_path / "r"))


def test_json_dump_fails_leaves_previous_pair(tmp_path, monkeypatch):
    write_recording(_rec(seed=1), tmp_path / "r")
    before = _snapshot(tmp_path)

    def broken_dumps(*args, **kwargs):
        raise RuntimeError("serialiser exploded")

    monkeypatch.setattr(bio.json, "dumps", broken_dumps)
    with pytest.raises(RuntimeError, match="serialiser exploded"):
        write_recording(_rec(seed=2), tmp_path / "r")
    monkeypatch.undo()
    assert _snapshot(tmp_path) == before


def test_failure_while_writing_temporaries_cleans_up(tmp_path, monkeypatch):
    write_recording(_rec(seed=1), tmp_path / "r")
    before = _snapshot(tmp_path)
    real_fsync = os.fsync
    calls = []

    def flaky_fsync(fd):
        calls.append(fd)
        if len(calls) == 2:  # the JSON temporary
            raise OSError(5, "Input/output error")
        return real_fsync(fd)

    monkeypatch.setattr(bio.os, "fsync", flaky_fsync)
    with pytest.raises(OSError, match="Input/output error"):
        write_recording(_rec(seed=2), tmp_path / "r")
    monkeypatch.undo()
    assert _snapshot(tmp_path) == before


def test_written_files_honour_umask(tmp_path):
    old = os.umask(0o022)
    try:
        csv_path, json_path = write_recording(_rec(), tmp_path / "r")
    finally:
        os.umask(old)
    if os.name == "posix":
        assert csv_path.stat().st_mode & 0o777 == 0o644
        assert json_path.stat().st_mode & 0o777 == 0o644


# ---------------------------------------------------------------------------
# reading never changes files
# ---------------------------------------------------------------------------
def _fingerprint(paths):
    return {p: (p.stat().st_mtime_ns, p.stat().st_size, hashlib.sha256(p.read_bytes()).hexdigest())
            for p in paths}


def test_reading_never_changes_files(tmp_path):
    shutil.copytree(DATA, tmp_path / "data")
    files = sorted(p for p in (tmp_path / "data").rglob("*") if p.is_file())
    names_before = sorted(p.name for p in (tmp_path / "data").rglob("*"))
    before = _fingerprint(files)
    for p in files:
        if p.suffix in (".csv", ".json"):
            for given in (p, p.with_suffix("")):
                try:
                    read_recording(given)
                except RecordingError:
                    pass
    assert _fingerprint(files) == before
    assert sorted(p.name for p in (tmp_path / "data").rglob("*")) == names_before


def test_reading_mat_never_changes_file(tmp_path):
    path = tmp_path / "r.mat"
    scipy.io.savemat(path, _mat_dict(_rec()))
    before = _fingerprint([path])
    read_recording(path)
    read_mat(path)
    assert _fingerprint([path]) == before
    assert [p.name for p in tmp_path.iterdir()] == ["r.mat"]


# ---------------------------------------------------------------------------
# MATLAB
# ---------------------------------------------------------------------------
def _mat_dict(rec: Recording, column: bool = False) -> dict:
    d = {name: (v[:, None] if column else v) for name, v in rec.signals.items()}
    d.update(sample_rate_hz=rec.sample_rate_hz, motion_gain=rec.motion_gain, task=rec.task)
    return d


@pytest.mark.parametrize("column", [False, True])
@pytest.mark.parametrize("in_struct", [False, True])
def test_mat_round_trip(tmp_path, column, in_struct):
    meta = {"subject": "S07", "run": 3.0, "notes": "from MATLAB",
            "controlled_element": {"num": 4.0, "den": np.array([1.0, 0.0, 0.0])},
            "forcing": {"base_frequency": 0.1534,
                        "target": {"n": np.array([6.0, 13.0]), "amplitude": np.array([0.5, 0.3]),
                                   "phase": np.array([1.2, -0.4])},
                        "disturbance": {"n": 5.0, "amplitude": 0.4, "phase": -0.7}},
            "lab_session": "A-17"}
    rec = _rec()
    d = _mat_dict(rec, column=column)
    if in_struct:
        d["metadata"] = {**meta, "motion_gain": d.pop("motion_gain"), "task": d.pop("task")}
    else:
        d.update(meta)
    path = tmp_path / "run.mat"
    scipy.io.savemat(path, d)
    for back in (read_mat(path), read_recording(path), read_recording(str(path))):
        assert list(back.signals) == list(rec.signals)
        for name in rec.signals:
            assert np.array_equal(rec[name], back[name]), name
        assert back.sample_rate_hz == rec.sample_rate_hz
        assert back.motion_gain == rec.motion_gain and back.task == rec.task
        assert back.source == str(tmp_path / "run")
        m = back.metadata
        assert m["run"] == 3 and isinstance(m["run"], int)
        assert m["subject"] == "S07" and m["lab_session"] == "A-17"
        assert m["controlled_element"] == {"num": [4.0], "den": [1.0, 0.0, 0.0]}
        assert m["forcing"]["target"]["n"] == [6, 13]
        assert m["forcing"]["disturbance"] == {"n": [5], "amplitude": [0.4], "phase": [-0.7]}
        num, den = back.controlled_element
        assert np.array_equal(num, [4.0]) and np.array_equal(den, [1.0, 0.0, 0.0])
    # and on to CSV + JSON, exactly
    write_recording(back, tmp_path / "converted")
    _assert_same(back, read_recording(tmp_path / "converted"))


def test_mat_reached_through_stem(tmp_path):
    scipy.io.savemat(tmp_path / "run.mat", _mat_dict(_rec()))
    assert read_recording(tmp_path / "run").n_samples == 50


def test_mat_missing_sample_rate_refused(tmp_path):
    d = _mat_dict(_rec())
    del d["sample_rate_hz"]
    path = tmp_path / "run.mat"
    scipy.io.savemat(path, d)
    with pytest.raises(RecordingError, match=re.escape(str(path)) + r": no sample_rate_hz variable "
                                             r"\(the sample rate is never guessed from t\)"):
        read_recording(path)


@pytest.mark.parametrize("change, pattern", [
    (lambda d: d.pop("u"), r"missing required variable\(s\): u"),
    (lambda d: d.pop("t"), r"missing required variable\(s\): t"),
    (lambda d: d.pop("task"), r"missing required variable\(s\): task"),
    (lambda d: d.update(u=np.zeros(49)), r"variable 'u' must be a numeric vector with one value per "
                                         r"sample of t \(50\), got shape \(49,\)"),
    (lambda d: d.update(task="fd"), r"task must be one of"),
    (lambda d: d.update(format="other/1"), r"unknown format 'other/1'"),
    (lambda d: d.update(metadata={"task": "FD"}), r"metadata key 'task' is given both as a variable "
                                                  r"and in the 'metadata' struct"),
    (lambda d: d.update(e=np.full(50, np.nan)), r"column 'e' has a non-finite value"),
    (lambda d: d.update(sample_rate_hz=50.0), r"t has a step of 0\.01 s, which disagrees with"),
    (lambda d: d.update(z=np.ones(50) * 1j), r"variable 'z' is complex"),
])
def test_mat_refusals(tmp_path, change, pattern):
    d = _mat_dict(_rec())
    change(d)
    path = tmp_path / "run.mat"
    scipy.io.savemat(path, d)
    with pytest.raises(RecordingError, match=re.escape(str(path)) + ": " + pattern):
        read_mat(path)


def test_mat_other_variables_kept(tmp_path):
    d = _mat_dict(_rec())
    d.update(force=np.arange(50.0), gains=np.array([1.0, 2.0]), matrix=np.ones((2, 3)), label="x")
    path = tmp_path / "run.mat"
    scipy.io.savemat(path, d)
    rec = read_mat(path)
    assert np.array_equal(rec["force"], np.arange(50.0))
    assert rec.metadata == {"gains": [1.0, 2.0], "matrix": [[1.0] * 3] * 2, "label": "x"}


def test_not_a_mat_file_refused(tmp_path):
    path = tmp_path / "run.mat"
    path.write_bytes(b"this is not a MATLAB file at all, just text " * 4)
    with pytest.raises(RecordingError, match=re.escape(str(path)) + r": is not a readable MATLAB \.mat file"):
        read_recording(path)


def test_hdf5_mat_refused(tmp_path):
    path = tmp_path / "run.mat"
    # a v7.3 header: loadmat recognises it and refuses with NotImplementedError
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."
    path.write_bytes(header.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM" + b"\x00" * 512)
    with pytest.raises(RecordingError, match=re.escape(str(path)) + r": MATLAB v7\.3 \(HDF5\) files are not supported"):
        read_mat(path)


def test_doctests():
    result = doctest.testmod(bio, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0


# ---------------------------------------------------------------------------
# a path that names something else than a recording; common lab mistakes
# ---------------------------------------------------------------------------
WHAT = r" \(a recording is NAME\.csv with NAME\.json, or a \.mat file\)$"


@pytest.mark.parametrize("name", ["post.nc", "fig.png", "data.h5", "run"])
def test_an_existing_file_that_is_not_a_recording_is_not_file_not_found(tmp_path, name):
    (tmp_path / name).write_bytes(b"\x89HDF\r\n")
    with pytest.raises(RecordingError, match=re.escape(str(tmp_path / name)) + ": not a recording"
                       + WHAT):
        read_recording(tmp_path / name)


def test_a_folder_is_not_a_recording(tmp_path, monkeypatch):
    lab = tmp_path / "lab"
    lab.mkdir()
    for given in (str(lab) + "/", str(lab), lab):
        with pytest.raises(RecordingError, match=re.escape(str(given)) + ": a folder, not a "
                                                  "recording" + WHAT):
            read_recording(given)
    monkeypatch.chdir(lab)
    with pytest.raises(RecordingError, match=r"^\.: a folder, not a recording" + WHAT):
        read_recording(".")
    with pytest.raises(RecordingError, match=r"path must name a file, got ''"):
        read_recording("")
    # a folder that is not there (a console audit: "recordings/" read as a missing stem)
    with pytest.raises(RecordingError, match=r"^recordings/: no such folder$"):
        read_recording("recordings/")


def test_a_stem_that_is_also_a_folder_still_reads_its_pair(tmp_path):
    _pair(tmp_path, GOOD_CSV)
    (tmp_path / "run").mkdir()
    assert read_recording(tmp_path / "run").n_samples == 3
    with pytest.raises(RecordingError, match=r"run/: a folder, not a recording"):
        read_recording(str(tmp_path / "run") + "/")


@pytest.mark.parametrize("text, pattern", [
    ("t;e;u;theta_ddot_m\n0;1;2;3\n0.1;1;2;3\n",
     r"missing required column\(s\): t, e, u, theta_ddot_m \(the header reads "
     r"'t;e;u;theta_ddot_m': the format is comma-separated, not separated by ';'"),
    ("t;e;u;theta_ddot_m\n0;1,5;2;3\n0,1;1,5;2;3\n",  # decimal commas
     r"missing required column\(s\): .*the format is comma-separated, not separated by ';', "
     r"with '\.' as the decimal point\)$"),
    ("t\te\tu\ttheta_ddot_m\n0\t1\t2\t3\n", r"missing required column\(s\): .*not separated by tabs"),
    ("# lab 3, 2024-05-01\n" + GOOD_CSV,
     r"missing required column\(s\): t, e, u, theta_ddot_m \(the first line reads "
     r"'# lab 3, 2024-05-01': the format has no comment lines"),
    ("# " + GOOD_CSV, r"missing required column\(s\): t \(the first line reads '# t,e,u"),
    ("t,e,u,theta_ddotm\n0,1,2,3\n0.1,1,2,3\n",
     r"missing required column\(s\): theta_ddot_m \(misspelled\? the header has 'theta_ddotm' "
     r"for theta_ddot_m\)$"),
    ("t,e,u,theta_ddot_m\n0,1,2,3\n# paused\n0.1,1,2,3\n",
     r"line 3 has 1 field, expected 4 \(a comment line\? the format has none\)$"),
])
def test_csv_mistakes_get_a_hint(tmp_path, text, pattern):
    stem = _pair(tmp_path, text)
    with pytest.raises(RecordingError, match=re.escape(str(stem) + ".csv: ") + pattern):
        read_recording(stem)


@pytest.mark.parametrize("factor, hint", [(1000.0, "t in ms"), (10.0, "t counts samples")])
def test_t_in_ms_or_samples_gets_a_hint(tmp_path, factor, hint):
    t = np.arange(5) * 0.1 * factor
    text = "t,e,u,theta_ddot_m\n" + "".join(f"{v!r},1,2,3\n" for v in t.tolist())
    stem = _pair(tmp_path, text)
    step = f"{0.1 * factor:g}"
    with pytest.raises(RecordingError, match=re.escape(
            f"run.csv: t has a step of {step} s, which disagrees with sample_rate_hz = 10 "
            f"(step 0.1 s; {hint}? the format wants seconds)")):
        read_recording(stem)
    # no hint where the step is just wrong
    stem = _pair(tmp_path, "t,e,u,theta_ddot_m\n0,1,2,3\n0.2,1,2,3\n0.4,1,2,3\n")
    with pytest.raises(RecordingError, match=r"\(step 0\.1 s\)$"):
        read_recording(stem)


def test_every_bad_key_is_named_in_one_message(tmp_path):
    base = {"format": FORMAT, "sample_rate_hz": 10, "motion_gain": 0, "task": "other"}
    stem = _pair(tmp_path, GOOD_CSV, {**base, "subject": 3, "run": "x", "task": "fd"})
    with pytest.raises(RecordingError, match=re.escape(
            str(stem) + ".json: task must be one of 'FD', 'FT', 'other', got 'fd'; subject must be "
            "a string, got 3; run must be an integer, got 'x'") + "$"):
        read_recording(stem)


def test_a_misspelled_required_key_is_pointed_out(tmp_path):
    meta = {"format": FORMAT, "sample_rate": 10, "motion_gian": 0, "task": "other", "lab": "x"}
    stem = _pair(tmp_path, GOOD_CSV, meta)
    with pytest.raises(RecordingError, match=re.escape(
            "run.json: missing required key(s): sample_rate_hz, motion_gain (misspelled? the file "
            "has 'sample_rate' for sample_rate_hz, 'motion_gian' for motion_gain)") + "$"):
        read_recording(stem)


@pytest.mark.parametrize("plant, pattern", [
    ({"controlled_element": {"num": [0], "den": [1, 0, 0]}},
     r"controlled_element\.num is all zeros \(\[0\]\): a plant that is zero, which the stick "
     r"could not move$"),
    ({"controlled_element": {"num": [1, 0, 0], "den": [1, 1]}},
     r"controlled_element is improper \(num \[1, 0, 0\] of degree 2 over den \[1, 1\] of degree "
     r"1\): a plant's num must not be of higher degree than its den"),
    ({"controlled_element": {"num": [0, 1, 0], "den": [0, 0, 1]}},
     r"controlled_element is improper \(num \[0, 1, 0\] of degree 1 over den \[0, 0, 1\] of "
     r"degree 0\)"),
    ({"controlled_element_gain": 0}, r"controlled_element_gain is 0: a plant that is zero"),
])
def test_a_zero_or_improper_plant_is_refused(tmp_path, plant, pattern):
    base = {"format": FORMAT, "sample_rate_hz": 10, "motion_gain": 0, "task": "other"}
    stem = _pair(tmp_path, GOOD_CSV, {**base, **plant})
    with pytest.raises(RecordingError, match=re.escape(str(stem) + ".json: ") + pattern):
        read_recording(stem)
    with pytest.raises(RecordingError, match=pattern):  # and in Python, as for a file
        _rec(**plant)


@pytest.mark.parametrize("plant", [{"num": [1.5], "den": [1, 0]}, {"num": [2, 1], "den": [1, 3]},
                                   {"num": [0, 4], "den": [1, 0, 0]}])
def test_proper_plants_of_any_relative_degree_are_read(tmp_path, plant):
    base = {"format": FORMAT, "sample_rate_hz": 10, "motion_gain": 0, "task": "other"}
    stem = _pair(tmp_path, GOOD_CSV, {**base, "controlled_element": plant})
    assert read_recording(stem).metadata["controlled_element"] == plant

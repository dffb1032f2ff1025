"""Tests of ``bayespilot diagnose`` (the command of issue 5), in-process through ``main``."""

from __future__ import annotations

import json

import pytest

from bayespilot.cli import main
from bayespilot.diagnose import NAMES
from bayespilot.io import write_recording
from bayespilot.recording import Recording
from bayespilot.simulate import simulate


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def rec_stem(tmp_path_factory):
    """A short simulated run written as a lab would: the generator's truth is not in it."""
    rec = simulate(task="FT", motion_gain=1.0, remnant_gain=0.06, seed=31, duration=30.0).recording
    meta = {k: v for k, v in rec.metadata.items() if k != "notes"}
    rec = Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta)
    stem = tmp_path_factory.mktemp("diag") / "run"
    write_recording(rec, stem)
    return stem


def test_diagnose_json_and_report(rec_stem, tmp_path, capsys):
    out = tmp_path / "d.json"
    rep = tmp_path / "report"
    code, stdout, err = _run(capsys, "diagnose", rec_stem, "--json", out, "--report", rep,
                             "--bootstrap", "0", "--seed", "1")
    assert code == 0, err
    assert "decision:" in stdout
    d = json.loads(out.read_text())
    assert isinstance(d["mismatch"], bool)
    assert d["physics"] in (*NAMES, "none")
    assert d["physics"] == "none"  # a correct-model run
    assert [r["physics"] for r in d["ranking"]] and len(d["ranking"]) == len(NAMES)
    for r in d["ranking"]:
        assert {"physics", "delta_neg_log_lik", "p_value", "params"} <= set(r)
    assert "time.nonstationarity" in d["where"]
    html = (rep / "report.html").read_text()
    assert "data:image/png;base64," in html and "<img" in html
    for name in ("frequency_response.png", "residuals.png", "evidence.png", "candidates.png",
                 "diagnosis.json"):
        assert (rep / name).stat().st_size > 0


def test_diagnose_missing_recording_is_a_usage_error(tmp_path, capsys):
    code, out, err = _run(capsys, "diagnose", tmp_path / "nothing")
    assert code == 2
    assert err.startswith("bayespilot: error:") and err.count("\n") == 1
    assert "Traceback" not in err


def test_diagnose_bad_option_is_a_usage_error(rec_stem, capsys):
    code, out, err = _run(capsys, "diagnose", rec_stem, "--bootstrap", "-3")
    assert code == 2 and "bootstrap" in err


def test_diagnose_unwritable_json_is_a_failure(rec_stem, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    code, out, err = _run(capsys, "diagnose", rec_stem, "--bootstrap", "0",
                          "--json", blocker / "sub" / "d.json")
    assert code == 1 and err.startswith("bayespilot: error:")


def test_diagnose_several_runs_pools_them(rec_stem, tmp_path, capsys):
    rec = simulate(task="FT", motion_gain=1.0, remnant_gain=0.06, seed=32, duration=30.0).recording
    meta = {k: v for k, v in rec.metadata.items() if k != "notes"}
    stem2 = tmp_path / "run2"
    write_recording(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta),
                    stem2)
    out = tmp_path / "pooled.json"
    code, stdout, err = _run(capsys, "diagnose", rec_stem, stem2, "--json", out,
                             "--bootstrap", "0", "--report", tmp_path / "rep")
    assert code == 0, err
    assert "2 runs pooled" in stdout
    d = json.loads(out.read_text())
    assert d["pooled"] is True and d["n_runs"] == 2 and d["physics"] == "none"
    assert len(d["runs"]) == 2 and len(d["ranking"]) == len(NAMES)
    assert (tmp_path / "rep" / "runs.png").stat().st_size > 0

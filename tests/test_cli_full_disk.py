"""The command line's check, before a long computation, that an output can be written refuses
a full disk: it wrote an empty probe, which a full disk accepts, and the computation ran only
to fail at the end (the audit of full disks, F5).  A full disk is emulated: every write of
data fails with ENOSPC, an empty file is still made, as on a file system with no free block.
"""

from __future__ import annotations

import errno
import pathlib

import pytest

from bayespilot.cli import main
from bayespilot.io import write_recording
from bayespilot.simulate import simulate


@pytest.fixture()
def run(tmp_path):
    stem = tmp_path / "in" / "run"
    write_recording(simulate(task="FD", motion_gain=1.0, remnant_fraction=0.1, seed=1,
                             duration=10.0).recording, stem)
    return stem


@pytest.fixture()
def full_disk(monkeypatch, tmp_path):
    """Writes of data under tmp_path/'full' fail with ENOSPC; empty files are made."""
    full = tmp_path / "full"
    full.mkdir()
    real = pathlib.Path.write_bytes

    def write_bytes(self, data):
        if str(self).startswith(str(full)) and len(data):
            open(self, "wb").close()  # (the file is made, its block is refused)
            raise OSError(errno.ENOSPC, "No space left on device", str(self))
        return real(self, data)

    monkeypatch.setattr(pathlib.Path, "write_bytes", write_bytes)
    return full


@pytest.mark.parametrize("command, what", [
    (["fit", "--method", "fast", "--json"], "fit"),
    (["sample", "--max-steps", "10", "-o"], "posterior"),
    (["compare", "--json"], "comparison"),
    (["diagnose", "--bootstrap", "0", "--json"], "diagnosis")])
def test_a_full_disk_is_refused_before_the_computation(command, what, run, full_disk, capsys,
                                                       monkeypatch):
    import bayespilot.compare
    import bayespilot.diagnose
    import bayespilot.fit.fast
    import bayespilot.sample

    def ran(*a, **k):
        raise AssertionError("the computation ran")

    for mod, name in ((bayespilot.fit.fast, "fit_fast"), (bayespilot.sample, "sample"),
                      (bayespilot.compare, "compare"), (bayespilot.diagnose, "diagnose")):
        monkeypatch.setattr(mod, name, ran)
    out = full_disk / ("x.nc" if command[0] == "sample" else "x.json")
    code = main([command[0], str(run), *command[1:], str(out), "-q"])
    err = capsys.readouterr().err
    assert code == 1, err
    assert err.splitlines()[-1] == (f"bayespilot: error: {out}: cannot write the {what} (No "
                                    f"space left on device)")
    assert "warning" in err.splitlines()[0]  # (the short record's: the only other line)
    assert list(full_disk.iterdir()) == []  # (the probe removed, though its write failed)


def test_a_report_folder_on_a_full_disk_is_refused_before_the_diagnosis(run, full_disk, capsys,
                                                                         monkeypatch):
    """diagnose --report: the folder was only made (mkdir passes on a full disk) and the
    diagnosis ran; now a block is written in it first."""
    import bayespilot.diagnose

    def ran(*a, **k):
        raise AssertionError("the computation ran")

    monkeypatch.setattr(bayespilot.diagnose, "diagnose", ran)
    report = full_disk / "rep"
    code = main(["diagnose", str(run), "--bootstrap", "0", "--report", str(report), "-q"])
    err = capsys.readouterr().err
    assert code == 1, err
    assert err.splitlines()[-1] == (f"bayespilot: error: {report / 'report.html'}: cannot write "
                                    "the report (No space left on device)")
    assert list(report.iterdir()) == []

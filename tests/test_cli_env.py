"""The ``bayespilot`` command in unusual environments (findings of the environment audit).

An output option that names one of the command's inputs, a standard output that goes away
or fails, a non-UTF-8 standard output, a closed standard error, Ctrl-C inside a numba
kernel, arviz that cannot be imported, and output paths that are empty, end in a slash or
start with ``~``.  The commands run in-process through ``main([...])``; what needs a real
process (pipes, environment variables, a closed file descriptor) runs ``python -m
bayespilot.cli``.  Computations are replaced by stubs where the test is about what happens
around them.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from bayespilot import cli
from bayespilot.cli import main

PARAMS = {"K_v": 1.057, "T_vl": 0.409, "tau_v": 0.279, "K_m": 0.532, "tau_m": 0.203,
          "omega_nm": 12.0, "zeta_nm": 0.22, "delta_abs": 0.0075}


def _run(capsys, *argv):
    """main(argv) -> (exit code, stdout, stderr)."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _process(*argv, env=None, **kwargs) -> subprocess.CompletedProcess:
    """``python -m bayespilot.cli ARGV`` in a real process, bytes in and out."""
    base = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    base["NUMBA_NUM_THREADS"] = "1"
    base.update(env or {})
    return subprocess.run([sys.executable, "-m", "bayespilot.cli", *map(str, argv)],
                          env=base, stdin=subprocess.DEVNULL, timeout=300, **kwargs)


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """A folder with a 20-s recording (run.csv + run.json) and params.json."""
    d = tmp_path_factory.mktemp("lab")
    assert main(["simulate", "--seed", "1", "--duration", "20", "--remnant-fraction", "0.2",
                 "-q", "-o", str(d / "run")]) == 0
    (d / "params.json").write_text(json.dumps(PARAMS))
    return d


@pytest.fixture
def rc(lab, tmp_path):
    """A fresh copy of ``lab`` (the tests try to overwrite its files)."""
    for name in ("run.csv", "run.json", "params.json"):
        (tmp_path / name).write_bytes((lab / name).read_bytes())
    return tmp_path


class _StubFit:
    """What _cmd_fit uses of a FitResult: the fit itself is not what these tests are about."""
    neg_log_lik = -1.0

    def summary(self) -> str:
        return "fit of Versuchsperson M\u00fcller: -ln L = -1"

    def to_json(self, path) -> None:
        Path(path).write_text('{"stub": true}\n', encoding="utf-8")


@pytest.fixture
def stub_fit(monkeypatch):
    import bayespilot.fit.fast

    monkeypatch.setattr(bayespilot.fit.fast, "fit_fast", lambda *a, **k: _StubFit())


# --- 1: an output that is one of the inputs ---------------------------------------------------
@pytest.mark.parametrize("target", ["run.json", "run.csv", "./run.json"])
def test_fit_json_cannot_overwrite_the_recording(capsys, rc, stub_fit, target):
    before = {n: (rc / n).read_bytes() for n in ("run.csv", "run.json")}
    code, _, err = _run(capsys, "fit", rc / "run", "--method", "fast", "-q",
                        "--json", f"{rc}/{target}")
    assert code == 2, err
    assert err.startswith("bayespilot: error: argument --json: ") and "REC" in err, err
    assert {n: (rc / n).read_bytes() for n in before} == before


def test_a_link_to_the_recording_is_the_recording(capsys, rc, stub_fit):
    (rc / "link.json").symlink_to(rc / "run.json")
    os.link(rc / "run.csv", rc / "hard.csv")
    for target in ("link.json", "hard.csv"):
        code, _, err = _run(capsys, "fit", rc / "run.csv", "--method", "fast", "-q",
                            "--json", rc / target)
        assert code == 2 and "argument --json" in err, err


def test_simulate_cannot_overwrite_its_params_file(capsys, rc):
    before = (rc / "params.json").read_bytes()
    code, _, err = _run(capsys, "simulate", "--params", rc / "params.json", "--duration", "20",
                        "-o", rc / "params")
    assert code == 2
    assert "argument -o/--output" in err and "--params" in err, err
    assert (rc / "params.json").read_bytes() == before and not (rc / "params.csv").exists()


@pytest.mark.parametrize("argv", [
    ["diagnose", "{rc}/run", "--json", "{rc}/run.json"],
    ["diagnose", "{rc}/run", "--report", "{rc}", "--posterior", "{rc}/x.nc"],  # no clash
    ["sample", "{rc}/run", "-o", "{rc}/p.nc", "--json", "{rc}/run.json"],
    ["sample", "{rc}/run", "-o", "{rc}/p.nc", "--backend", "{rc}/run.csv"],
    ["sample", "{rc}/run", "-o", "{rc}/p.nc", "--json", "{rc}/p.nc"],
    ["compare", "{rc}/run", "--json", "{rc}/run.csv"],
    ["compare", "{rc}/run", "--posterior", "{rc}/post.nc", "--json", "{rc}/post.nc"],
    ["plot", "{rc}/trace.png", "-o", "{rc}"],
    ["diagnose-batch", "{rc}/run", "--out", "{rc}"],
])
def test_every_command_refuses_to_overwrite_an_input(capsys, rc, monkeypatch, argv):
    """Refused before anything runs: the computations are made to fail if they start."""
    import bayespilot.compare
    import bayespilot.diagnose
    import bayespilot.diagnose.batch
    import bayespilot.sample

    def started(*a, **k):
        raise AssertionError("the computation started")

    for module, name in ((bayespilot.diagnose, "diagnose"), (bayespilot.sample, "sample"),
                         (bayespilot.compare, "compare"),
                         (bayespilot.diagnose.batch, "diagnose_batch")):
        monkeypatch.setattr(module, name, started)
    (rc / "post.nc").write_bytes(b"x")
    (rc / "trace.png").write_bytes(b"x")
    before = {p.name: p.read_bytes() for p in rc.iterdir()}
    argv = [a.format(rc=rc) for a in argv]
    code, _, err = _run(capsys, *argv)
    if argv[0] == "diagnose" and "--report" in argv:
        # the report's files are not the recording's: accepted, and stopped at the computation
        assert code == 1 and "the computation started" in err, err
        return
    assert code == 2, err
    assert err.startswith("bayespilot: error: argument ") and "give" in err, err
    assert {p.name: p.read_bytes() for p in rc.iterdir() if p.name in before} == before


def _no_batch(monkeypatch):
    import bayespilot.diagnose.batch

    def started(*a, **k):
        raise AssertionError("the computation started")

    monkeypatch.setattr(bayespilot.diagnose.batch, "diagnose_batch", started)


def test_batch_guard_checks_the_files_the_batch_writes(capsys, rc, monkeypatch, tmp_path):
    """The guard takes the batch's keys (plan_batch): two recordings of one stem are keyed
    by folder (a_run, out_run), so `a/run out/run --out out` writes nothing over out/run.json
    and is taken; a recording whose sidecar is a result file is still refused."""
    _no_batch(monkeypatch)
    for folder in ("a", "out"):
        (tmp_path / folder).mkdir()
        for name in ("run.csv", "run.json"):
            (tmp_path / folder / name).write_bytes((rc / name).read_bytes())
    code, _, err = _run(capsys, "diagnose-batch", tmp_path / "a" / "run",
                        tmp_path / "out" / "run", "--out", tmp_path / "out", "-q")
    assert code == 1 and "the computation started" in err, err
    # out/a_run.json (the key of a/run) is the sidecar of the recording out/a_run
    for name in ("run.csv", "run.json"):
        (tmp_path / "out" / name).rename(tmp_path / "out" / name.replace("run", "a_run"))
    code, _, err = _run(capsys, "diagnose-batch", tmp_path / "a" / "run",
                        tmp_path / "out" / "a_run", "--out", tmp_path / "out", "-q")
    assert code == 2, err
    assert f"argument --out: {tmp_path / 'out' / 'a_run.json'} is the JSON sidecar" in err, err
    # with --reports, the report's files in <key>/ too
    code, _, err = _run(capsys, "diagnose-batch", tmp_path / "a" / "run", "--out",
                        tmp_path / "a" / "x", "--reports", "-q")
    assert code == 1 and "the computation started" in err, err
    (tmp_path / "a" / "x" / "run").mkdir(parents=True)
    for name in ("diagnosis.csv", "diagnosis.json"):
        (tmp_path / "a" / "x" / "run" / name).write_bytes((rc / name.replace("diagnosis",
                                                                             "run")).read_bytes())
    code, _, err = _run(capsys, "diagnose-batch", tmp_path / "a" / "run",
                        tmp_path / "a" / "x" / "run" / "diagnosis", "--out", tmp_path / "a" / "x",
                        "--reports", "-q")
    assert code == 2 and "argument --out" in err and "diagnosis.json" in err, err


def test_report_files_are_the_reports_figures(tmp_path):
    """The guard's report files come from report.FIGURES, which both reports' figures must be
    in (write_report and PooledDiagnosisResult.report pass them through report._listed): a
    figure added to a report but not to the list is refused before anything is written."""
    from bayespilot.diagnose import report

    names = {p.name for p in cli._report_files(tmp_path)}
    assert {"diagnosis.json", "report.html", report.MANIFEST} <= names
    assert {f"{f}.{fmt}" for f in report.FIGURES for fmt in report.FORMATS} <= names
    assert report._listed({"candidates": None, "runs": None}) == {"candidates": None,
                                                                  "runs": None}
    with pytest.raises(ValueError, match="not in FIGURES"):
        report._listed({"candidates": None, "new_figure": None})


def test_refuse_overwriting_unit(tmp_path):
    (tmp_path / "a.json").write_text("{}")
    cli._refuse_overwriting([("--json", tmp_path / "b.json")],
                            [("the --params file", tmp_path / "a.json"), ("x", None)])
    with pytest.raises(cli.UsageError, match="argument --json: .*the --params file"):
        cli._refuse_overwriting([("--json", tmp_path / "sub" / ".." / "a.json")],
                                [("the --params file", tmp_path / "a.json")])
    assert [p for _, p in cli._code_files(["motion-washout", "my.py:X"], "--with")] == \
        [Path("my.py")]


def test_recording_files_are_the_ones_read(tmp_path):
    """The guard's files are io._resolve's: a suffix's case kept (up.CSV is read as up.CSV,
    not up.csv), a stem's three candidates, nothing for a spec that is no recording."""
    from bayespilot import io as recording_io

    for spec in ("d/run.v2.CSV", "d/run.JSON", "d/run.Mat"):
        _, _, first, second = recording_io._resolve(Path(spec))
        assert [p for _, p in cli._recording_files(spec)] == list(dict.fromkeys([first, second]))
    assert [p.name for _, p in cli._recording_files("d/run.v2.CSV")] == ["run.v2.CSV",
                                                                         "run.v2.json"]
    (tmp_path / "run.csv").write_text("")
    names = [p.name for _, p in cli._recording_files(str(tmp_path / "run"))]
    assert names == ["run.csv", "run.json", "run.mat"]
    assert cli._recording_files(str(tmp_path / "nothere")) == []  # (the read says so)


def _case_sensitive(folder: Path) -> bool:
    (folder / "case.probe").write_text("")
    try:
        return not (folder / "CASE.PROBE").exists()
    finally:
        (folder / "case.probe").unlink()


def test_an_upper_case_suffix_is_guarded_as_read(capsys, rc, stub_fit):
    """fit up.CSV --json up.CSV replaced the recording (the guard protected up.csv); on a
    case-sensitive disk --json up.csv is another file and is written."""
    (rc / "run.csv").rename(rc / "up.CSV")
    (rc / "run.json").rename(rc / "up.json")
    before = (rc / "up.CSV").read_bytes()
    code, _, err = _run(capsys, "fit", rc / "up.CSV", "--method", "fast", "-q",
                        "--json", rc / "up.CSV")
    assert code == 2 and "argument --json" in err and "REC" in err, err
    assert (rc / "up.CSV").read_bytes() == before
    if not _case_sensitive(rc):
        pytest.skip("a case-insensitive disk: up.csv is up.CSV")
    code, _, err = _run(capsys, "fit", rc / "up.CSV", "--method", "fast", "-q",
                        "--json", rc / "up.csv")
    assert code == 0, err
    assert (rc / "up.CSV").read_bytes() == before
    assert json.loads((rc / "up.csv").read_text()) == {"stub": True}


# --- 2 and 10: a standard output that goes away or fails ----------------------------------
class _Broken:
    """A standard output whose reader is gone (or, with ``error``, a full disk)."""

    def __init__(self, error=BrokenPipeError(32, "Broken pipe")):
        self.error = error

    def write(self, text):
        raise self.error

    def flush(self):
        raise self.error


def test_fit_writes_its_json_when_stdout_goes_away(rc, stub_fit, monkeypatch):
    monkeypatch.setattr(sys, "stdout", _Broken())
    code = main(["fit", str(rc / "run"), "--method", "fast", "--json", str(rc / "f.json")])
    monkeypatch.undo()
    assert code == 0
    assert json.loads((rc / "f.json").read_text()) == {"stub": True}


def test_fit_writes_its_json_when_stdout_is_full(rc, stub_fit, monkeypatch, capsys):
    full = _Broken(OSError(28, "No space left on device"))
    monkeypatch.setattr(sys, "stdout", full)
    code = main(["fit", str(rc / "run"), "--method", "fast", "--json", str(rc / "f.json")])
    monkeypatch.undo()
    err = capsys.readouterr().err
    assert code == 1
    assert err.strip().splitlines()[-1] == ("bayespilot: error: cannot write to standard output "
                                           "(No space left on device)"), err
    assert json.loads((rc / "f.json").read_text()) == {"stub": True}


def test_a_failing_file_write_still_prints_the_summary(rc, stub_fit, capsys, monkeypatch):
    """The summary comes before the file: it is on the screen when the file cannot be
    written (the reason for that order, kept)."""
    def fails(self, path):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(_StubFit, "to_json", fails)
    code, out, err = _run(capsys, "fit", rc / "run", "--method", "fast", "--json", rc / "f.json")
    assert code == 1 and "-ln L = -1" in out and "cannot write the fit" in err


@pytest.mark.parametrize("unbuffered", ["1", ""])
def test_closed_pipe_real_process(tmp_path, unbuffered):
    """`bayespilot simulate ... | true`: a block-buffered stdout failed at the interpreter's
    exit ("Exception ignored ... BrokenPipeError", exit 120); an unbuffered one is quiet."""
    env = {"PYTHONUNBUFFERED": unbuffered} if unbuffered else {}
    proc = subprocess.Popen([sys.executable, "-m", "bayespilot.cli", "simulate", "-o",
                             str(tmp_path / "run"), "--duration", "20", "--seed", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            stdin=subprocess.DEVNULL,
                            env={**{k: v for k, v in os.environ.items()
                                    if k != "PYTHONUNBUFFERED"}, "NUMBA_NUM_THREADS": "1",
                                 **env})
    proc.stdout.close()  # the reader is gone before anything is written
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == 0, err
    assert err == "", err
    assert (tmp_path / "run.csv").is_file() and (tmp_path / "run.json").is_file()


def test_full_disk_on_stdout_real_process(tmp_path):
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full")
    with open("/dev/full", "wb") as full:
        proc = _process("simulate", "-o", tmp_path / "run", "--duration", "20", "--seed", "1",
                        stdout=full, stderr=subprocess.PIPE)
    err = proc.stderr.decode()
    assert proc.returncode == 1, err
    assert err == ("bayespilot: error: cannot write to standard output (No space left on "
                   "device)\n"), err
    assert (tmp_path / "run.csv").is_file() and (tmp_path / "run.json").is_file()


# --- 5: a standard output that cannot encode a path --------------------------------------
def test_ascii_stdout_and_a_non_ascii_path(tmp_path, rc, stub_fit, capsys, monkeypatch):
    out = tmp_path / "Versuchsperson M\u00fcller" / "Lauf 1"
    proc = _process("simulate", "--seed", "1", "--duration", "20", "-o", out,
                    env={"PYTHONIOENCODING": "ascii"}, capture_output=True)
    assert proc.returncode == 0, proc.stderr.decode()
    assert b"M\\xfcller" in proc.stdout
    # in-process: the fit's summary names the recording; the JSON is still written
    import io

    ascii_out = io.TextIOWrapper(io.BytesIO(), encoding="ascii")
    monkeypatch.setattr(sys, "stdout", ascii_out)
    code = main(["fit", str(rc / "run"), "--method", "fast", "--json", str(rc / "f.json")])
    monkeypatch.undo()
    assert code == 0, capsys.readouterr().err
    assert b"M\\xfcller" in ascii_out.buffer.getvalue()
    assert (rc / "f.json").is_file()


@pytest.mark.parametrize("errors", ["strict", "surrogateescape"])
def test_main_leaves_stdout_as_it_found_it(monkeypatch, errors):
    """An in-process caller's stdout keeps its error handler (main switched a strict one to
    backslashreplace for good, and any other one too)."""
    import io

    out = io.TextIOWrapper(io.BytesIO(), encoding="ascii", errors=errors)
    monkeypatch.setattr(sys, "stdout", out)
    code = main(["--version"])
    monkeypatch.undo()
    assert code == 0
    assert sys.stdout is not out and out.errors == errors
    assert out.buffer.getvalue().startswith(b"bayespilot ")


def test_main_leaves_the_real_stdout_as_it_found_it(capsys):
    if not hasattr(sys.stdout, "reconfigure"):
        pytest.skip("this stdout cannot be reconfigured")
    before = sys.stdout.errors
    assert main(["--version"]) == 0
    assert sys.stdout.errors == before


def test_surrogateescape_stdout_writes_the_paths_bytes(tmp_path, monkeypatch):
    """The C locale's stdout (ascii, surrogateescape) writes a path from argv back as its
    bytes (the terminal shows M\u00fcller), not as backslash escapes of the surrogates."""
    import io

    out = io.TextIOWrapper(io.BytesIO(), encoding="ascii", errors="surrogateescape")
    monkeypatch.setattr(sys, "stdout", out)
    name = b"M\xc3\xbcller".decode("ascii", "surrogateescape")  # argv under LC_ALL=C
    code = main(["simulate", "--seed", "1", "--duration", "20", "-o", str(tmp_path / name / "run")])
    out.flush()
    monkeypatch.undo()
    assert code == 0
    written = out.buffer.getvalue()
    assert b"M\xc3\xbcller" in written and b"\\udc" not in written, written
    assert (tmp_path / "M\u00fcller" / "run.csv").is_file()


# --- 7: Ctrl-C inside a numba kernel ----------------------------------------------------
def _numba_interrupt(*args, **kwargs):
    """What numba raises on Ctrl-C in a kernel: a SystemError, the KeyboardInterrupt in its
    chain (here two levels down, as seen: KeyboardInterrupt -> SystemError -> SystemError)."""
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise SystemError("_numba_unpickle returned a result with an exception set")
    except SystemError as exc:
        raise SystemError("CPUDispatcher(<function jacobian>) returned a result with an "
                          "exception set") from exc


def test_interrupted_sees_the_chain():
    with pytest.raises(SystemError) as info:
        _numba_interrupt()
    assert cli._interrupted(info.value)
    assert cli._interrupted(KeyboardInterrupt())
    assert not cli._interrupted(SystemError("x"))
    a = ValueError("a")
    b = ValueError("b")
    a.__context__, b.__context__ = b, a  # a cycle ends
    assert not cli._interrupted(a)


def test_numba_interrupt_is_an_interrupt(capsys, monkeypatch):
    monkeypatch.setattr(cli, "_cmd_loglik", _numba_interrupt)
    code, _, err = _run(capsys, "loglik", "run", "--params", "params.json")
    assert code == 130 and err == "bayespilot: interrupted\n", err


# --- 9: arviz cannot be imported ---------------------------------------------------------
@pytest.fixture
def no_arviz(monkeypatch):
    import bayespilot.sample

    def fails():
        raise OSError(30, "Read-only file system", "/home/ro/.cache/arviz")

    monkeypatch.setattr(bayespilot.sample, "_arviz", fails)


def test_plot_does_not_blame_the_posterior_for_arviz(capsys, tmp_path, no_arviz):
    (tmp_path / "post.nc").write_bytes(b"\x89HDF\r\n\x1a\n")
    code, _, err = _run(capsys, "plot", tmp_path / "post.nc", "-o", tmp_path / "plots")
    assert code == 1, err
    assert "cannot import arviz" in err and "HOME" in err and "post.nc" not in err, err


def test_sample_does_not_blame_a_backend_for_arviz(capsys, rc, no_arviz, monkeypatch):
    import bayespilot.sample

    monkeypatch.setattr(bayespilot.sample, "sample", lambda *a, **k: pytest.fail("sampled"))
    code, _, err = _run(capsys, "sample", rc / "run", "-o", rc / "p.nc", "--max-steps", "20",
                        "-q")
    assert code == 1, err
    assert "cannot import arviz" in err and "backend" not in err and "None" not in err, err


def test_sample_oserror_without_backend_is_not_the_backends(capsys, rc, monkeypatch):
    import bayespilot.sample

    def fails(*a, **k):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(bayespilot.sample, "sample", fails)
    code, _, err = _run(capsys, "sample", rc / "run", "-o", rc / "p.nc", "-q")
    assert code == 1 and "backend" not in err and "None" not in err, err


# --- 11, 12 and suggestion 1: output paths ------------------------------------------------
def test_json_ending_in_a_slash_is_a_folder(capsys, rc, stub_fit):
    code, _, err = _run(capsys, "fit", rc / "run", "--method", "fast", "-q",
                        "--json", f"{rc}/nd/")
    assert code == 2 and "is a folder" in err, err
    assert not (rc / "nd").exists()


@pytest.mark.parametrize("argv,option", [
    (["fit", "run", "--json", ""], "--json"),
    (["diagnose", "run", "--report", ""], "--report"),
    (["diagnose", "run", "--json", ""], "--json"),
    (["diagnose", "run", "--posterior", ""], "--posterior"),
    (["plot", "post.nc", "-o", ""], "-o/--output"),
    (["sample", "run", "-o", ""], "-o/--output"),
    (["sample", "run", "-o", "p.nc", "--backend", ""], "--backend"),
    (["simulate", "-o", ""], "-o/--output"),
    (["compare", "run", "--json", ""], "--json"),
])
def test_an_empty_output_path_is_refused(capsys, argv, option):
    code, _, err = _run(capsys, *argv)
    assert code == 2
    assert err.startswith(f"bayespilot: error: argument {option}: an empty path"), err


def test_tilde_is_expanded(capsys, rc, stub_fit, monkeypatch, tmp_path):
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(rc)
    code, _, err = _run(capsys, "fit", "run", "--method", "fast", "-q", "--json=~/fit.json")
    assert code == 0, err
    assert (home / "fit.json").is_file() and not (rc / "~").exists()


# --- 15: standard error closed ------------------------------------------------------------
def test_closed_stderr_does_not_write_into_stdout(tmp_path):
    """`bayespilot ... 2>&-`: Python starts with sys.stderr None."""
    proc = _process("fit", tmp_path / "missing", "--method", "fast", stdout=subprocess.PIPE,
                    preexec_fn=lambda: os.close(2))
    assert proc.returncode == 2
    assert proc.stdout == b""


def test_closed_stderr_in_process(capsys, monkeypatch):
    monkeypatch.setattr(sys, "stderr", None)
    code = main(["fit", "missing-recording", "--method", "fast"])
    restored = sys.stderr is None
    monkeypatch.undo()
    out, _ = capsys.readouterr()
    assert code == 2 and out == "" and restored


def test_simulate_replaces_a_simulated_recording_but_not_a_labs(capsys, rc):
    """A lab's recording at -o's stem is a measurement that cannot be made again: refused
    (exit 2, both files unchanged) unless --force; a simulated one is replaced, as before."""
    argv = ("simulate", "--seed", "2", "--duration", "20", "-q", "-o", rc / "run")
    simulated = (rc / "run.csv").read_bytes()
    assert _run(capsys, *argv)[0] == 0  # the fixture's run is simulated: replaced
    assert (rc / "run.csv").read_bytes() != simulated
    # a lab's sidecar (no "simulation"), and a CSV without a sidecar
    side = json.loads((rc / "run.json").read_text())
    del side["simulation"]
    (rc / "run.json").write_text(json.dumps(side))
    before = {n: (rc / n).read_bytes() for n in ("run.csv", "run.json")}
    code, _, err = _run(capsys, *argv)
    assert code == 2 and "--force" in err
    assert "are not a recording 'bayespilot simulate' wrote (no \"simulation\"" in err
    assert {n: (rc / n).read_bytes() for n in before} == before
    (rc / "run.json").unlink()
    code, _, err = _run(capsys, *argv)
    assert code == 2 and f"{rc / 'run.csv'} is not a recording 'bayespilot simulate'" in err
    assert (rc / "run.csv").read_bytes() == before["run.csv"]
    # --force replaces it: the files are those of a fresh simulation with that seed
    assert _run(capsys, *argv, "--force")[0] == 0
    assert _run(capsys, *argv[:-1], rc / "fresh")[0] == 0
    assert (rc / "run.csv").read_bytes() == (rc / "fresh.csv").read_bytes()


# --- HPC audit 8/9: --scheduler checked when parsed ------------------------------------------
@pytest.mark.parametrize("command", [["replicate"], ["diagnose-batch", "rec"]])
@pytest.mark.parametrize("address,said", [
    ("", "an empty address"),
    ("tcp://host:8786/", "not a dask scheduler address (tcp://HOST:PORT"),
    ("tcp://host", "not a dask scheduler address (tcp://HOST:PORT"),
    ("host", "not a dask scheduler address (tcp://HOST:PORT"),
    ("tcp://host:http", "not a dask scheduler address (tcp://HOST:PORT"),
    ("tcp://host:70000", "not a dask scheduler address (tcp://HOST:PORT"),
    ("bogus://x", "not a dask scheduler address (tcp://HOST:PORT"),
    ("bogus://x:8786", "not a dask scheduler address: unknown scheme 'bogus'"),
    ("TCP://x:8786", "not a dask scheduler address: unknown scheme 'TCP'"),
])
def test_a_bad_scheduler_address_is_a_usage_error(capsys, monkeypatch, tmp_path, command,
                                                  address, said):
    """`--scheduler ""` was taken as a local cluster by the header and as an address by the run
    (which failed after 10 s); a trailing slash or a missing port failed in distributed ("invalid
    literal for int()"), and on a folder whose jobs were all done not at all (exit 0).  Now
    refused when parsed: exit 2, one line, nothing run, no output folder."""
    import bayespilot.campaign
    import bayespilot.diagnose.batch

    def started(*a, **k):
        raise AssertionError("the computation started")

    monkeypatch.setattr(bayespilot.campaign, "run_campaign", started)
    monkeypatch.setattr(bayespilot.diagnose.batch, "diagnose_batch", started)
    code, out, err = _run(capsys, *command, "--out", tmp_path / "o", "--scheduler", address)
    assert code == 2, err
    assert err.startswith(f"bayespilot: error: argument --scheduler: {said}"), err
    assert len(err.splitlines()) == 1 and out == ""
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("address", ["tcp://10.0.0.5:8786", "127.0.0.1:8786", "tcp://[::1]:8786",
                                     "tls://node-01.cluster.example:8786", "ws://h_1:80",
                                     "ucx://10.0.0.5:13337", "tcp://[fe80::1%eth0]:8786"])
def test_scheduler_addresses_dask_takes_are_taken(address):
    assert cli._scheduler_address(address) == address


def test_scheduler_address_check_agrees_with_distributed():
    """What the check refuses, distributed cannot connect to either (a ValueError from its
    parser or an unknown scheme); what it takes, distributed parses."""
    from distributed.comm import parse_address, parse_host_port
    from distributed.comm.registry import get_backend

    for good in ("tcp://10.0.0.5:8786", "127.0.0.1:8786", "tcp://[::1]:8786", "tls://h:1"):
        cli._scheduler_address(good)
        scheme, loc = parse_address(good)
        get_backend(scheme)
        parse_host_port(loc)
    for bad in ("tcp://host:8786/", "tcp://host", "bogus://x:1"):
        with pytest.raises(Exception):
            cli._scheduler_address(bad)
        with pytest.raises(ValueError):
            scheme, loc = parse_address(bad)
            get_backend(scheme)
            parse_host_port(loc)


# --- HPC audit 5: progress lines when stderr is not a terminal --------------------------------
def _stopped():
    """What the fake cluster runs of the tests below end in: the run stops, as a lost cluster
    would (exit 1, after the progress setting was seen)."""
    from bayespilot.campaign import CampaignError

    raise CampaignError("stopped by the test")


@pytest.mark.parametrize("terminal,quiet,progress", [(False, False, "lines"), (True, False, True),
                                                     (False, True, False)])
def test_replicate_asks_for_progress_lines_when_stderr_is_not_a_terminal(
        capsys, monkeypatch, tmp_path, terminal, quiet, progress):
    """A batch job's log (stderr not a terminal, the bar off) had the header, then nothing
    until the end; now run_campaign is asked for plain lines there (run_keyed writes them as
    the fits finish: test_campaign), for the bar on a terminal, for neither with --quiet."""
    import bayespilot.campaign

    seen = {}

    def run_campaign(jobs, out, *, progress, **kwargs):
        seen["progress"] = progress
        _stopped()

    monkeypatch.setattr(bayespilot.campaign, "run_campaign", run_campaign)
    monkeypatch.setattr(cli.sys.stderr, "isatty", lambda: terminal, raising=False)
    code, _, err = _run(capsys, "replicate", "--realizations", "2", "--tasks", "FD",
                        "--motion-gains", "1", "--remnant-fractions", "0.2", "--method", "fast",
                        "--out", tmp_path / "o", *(["-q"] if quiet else []))
    assert code == 1 and "stopped by the test" in err, err
    assert seen["progress"] == progress and type(seen["progress"]) is type(progress)


def test_diagnose_batch_asks_for_progress_lines(capsys, monkeypatch, rc):
    """The same for diagnose-batch (stderr is not a terminal under pytest's capture)."""
    import bayespilot.diagnose.batch

    seen = {}

    def diagnose_batch(paths, out, *, progress, **kw):
        seen["progress"] = progress
        _stopped()

    monkeypatch.setattr(bayespilot.diagnose.batch, "diagnose_batch", diagnose_batch)
    code, _, err = _run(capsys, "diagnose-batch", rc / "run", "--out", rc / "o")
    assert code == 1 and "stopped by the test" in err, err
    assert seen["progress"] == "lines"


def test_replicate_says_the_campaigns_warnings_as_its_lines(capsys, monkeypatch, tmp_path):
    """run_campaign's RuntimeWarnings (the fits' warnings said once per kind, workers that did
    not say their version) are the command's 'bayespilot: warning:' lines, not Python's
    '<file>:<line>: RuntimeWarning:' display."""
    import warnings

    import bayespilot.campaign

    def run_campaign(jobs, out, **kwargs):
        warnings.warn("QuestionableRecordingWarning in 2 fit(s) (a, b), e.g. a: offset",
                      RuntimeWarning)
        _stopped()

    monkeypatch.setattr(bayespilot.campaign, "run_campaign", run_campaign)
    code, _, err = _run(capsys, "replicate", "--realizations", "1", "--tasks", "FD",
                        "--motion-gains", "1", "--remnant-fractions", "0.2", "--method", "fast",
                        "--out", tmp_path / "o")
    assert code == 1 and "stopped by the test" in err, err
    assert ("bayespilot: warning: QuestionableRecordingWarning in 2 fit(s) (a, b), e.g. a: "
            "offset\n") in err and "RuntimeWarning" not in err, err


def test_scheduler_file_is_read_for_the_address(capsys, monkeypatch, tmp_path):
    """--scheduler-file FILE (dask scheduler --scheduler-file, dask-mpi, dask-jobqueue): the
    address is read from the JSON, waited for while the scheduler starts; a missing file is
    exit 1 after --connect-timeout, a file without an address exit 2, --workers beside it
    exit 2."""
    import threading

    import bayespilot.campaign

    seen = {}

    def run_campaign(jobs, out, *, scheduler, **kwargs):
        seen["scheduler"] = scheduler
        _stopped()

    monkeypatch.setattr(bayespilot.campaign, "run_campaign", run_campaign)
    base = ["replicate", "--realizations", "1", "--tasks", "FD", "--motion-gains", "1",
            "--remnant-fractions", "0.2", "--method", "fast", "--out", tmp_path / "o"]
    f = tmp_path / "scheduler.json"
    later = threading.Timer(0.3, lambda: f.write_text(
        '{"type": "Scheduler", "address": "tcp://10.0.0.5:8786", "workers": {}}'))
    later.start()
    code, _, err = _run(capsys, *base, "--scheduler-file", f, "--connect-timeout", "10")
    later.join()
    assert code == 1 and "stopped by the test" in err and seen["scheduler"] == "tcp://10.0.0.5:8786"
    seen.clear()
    code, _, err = _run(capsys, *base, "--scheduler-file", tmp_path / "none.json",
                        "--connect-timeout", "0.2")
    assert code == 1 and "none.json: no scheduler file after 0.2 s" in err and not seen, err
    (tmp_path / "bad.json").write_text('{"address": "tcp://host/"}')
    code, _, err = _run(capsys, *base, "--scheduler-file", tmp_path / "bad.json",
                        "--connect-timeout", "0.2")
    assert code == 2 and "bad.json: not a dask scheduler address" in err and not seen, err
    code, _, err = _run(capsys, *base, "--scheduler-file", f, "--workers", "2")
    assert code == 2 and "give --scheduler-file (an existing cluster) or --workers" in err


def test_a_scheduler_file_without_an_address_is_refused_at_once(capsys, monkeypatch, tmp_path):
    """A file that parses but holds no address (or is not a JSON object) is not a scheduler
    file: refused at once (it was read again until --connect-timeout ran out)."""
    import time

    def no_wait(seconds):
        raise AssertionError("waited for a file that is there")

    monkeypatch.setattr(time, "sleep", no_wait)
    base = ["replicate", "--realizations", "1", "--tasks", "FD", "--out", tmp_path / "o",
            "--connect-timeout", "300"]
    for text in ('{"type": "Scheduler"}', '["tcp://10.0.0.5:8786"]'):
        (tmp_path / "s.json").write_text(text)
        code, _, err = _run(capsys, *base, "--scheduler-file", tmp_path / "s.json")
        assert code == 2 and "s.json: not a dask scheduler file (KeyError: 'address')" in err, err

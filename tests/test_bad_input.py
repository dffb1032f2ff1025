"""Bad input, everywhere a user can give it.

A corpus over every command of the ``bayespilot`` CLI and the main public
functions: missing files, unreadable or inconsistent recordings
(``tests/data/malformed``), misspelled or out-of-range parameters, priors
outside the bounds, an unreachable dask scheduler.  The CLI must exit with 1
or 2 and one line ``bayespilot: error: ...`` on stderr, without a traceback;
the functions must raise a specific exception whose message names the
problem.  Also here: the warnings for questionable (valid but unusual)
recordings, and the CLI's help, version and exit-code conventions.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from scipy import stats

from bayespilot import presets
from bayespilot.cli import build_parser, main
from bayespilot.io import read_mat, read_recording, write_recording
from bayespilot.recording import (QuestionableRecordingWarning, Recording, RecordingError,
                                  questionable)

MALFORMED = Path(__file__).parent / "data" / "malformed"
CASES = sorted({p.name.split(".")[0] for p in MALFORMED.iterdir() if p.suffix in (".csv", ".json")})


def _run(capsys, *argv):
    """main(argv) -> (exit code, stdout, stderr)."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _one_error_line(err: str, out: str = "") -> str:
    """The single 'bayespilot: error: ...' line of stderr (asserting there is exactly one)."""
    assert "Traceback" not in err and "Traceback" not in out
    errors = [line for line in err.splitlines() if line.startswith("bayespilot: error: ")]
    others = [line for line in err.splitlines()
              if line.strip() and not line.startswith(("bayespilot: error: ",
                                                       "bayespilot: warning: "))]
    assert len(errors) == 1 and not others, err
    return errors[0]


def _recording(duration: float, rate: float = 100.0, **meta) -> Recording:
    t = np.arange(int(round(duration * rate))) / rate
    x = np.sin(2 * np.pi * 0.3 * t)
    return Recording({"t": t, "e": x, "u": 0.5 * x, "theta_ddot_m": np.cos(t)}, rate, 1.0, "FD",
                     meta)


@pytest.fixture(scope="module")
def run10(tmp_path_factory):
    """A 10-s simulated FD run on disk (valid, but shorter than the paper's: it warns)."""
    d = tmp_path_factory.mktemp("run")
    assert main(["simulate", "--duration", "10", "--seed", "1", "--remnant-fraction", "0.1",
                 "-o", str(d / "run"), "-q"]) == 0
    return d / "run"


@pytest.fixture(scope="module")
def params(tmp_path_factory):
    p = tmp_path_factory.mktemp("params") / "fd.json"
    p.write_text(json.dumps(presets.paper_parameters("FD")))
    return p


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


# --- every command: help, unknown options, missing arguments -------------------------------
def _subcommands() -> list[str]:
    parser = build_parser()
    for action in parser._actions:  # argparse keeps the subparsers here
        if isinstance(action, argparse._SubParsersAction):
            return sorted(action.choices)
    raise AssertionError("the CLI has no subcommands")


def test_the_commands_we_know_are_there():
    assert {"simulate", "loglik", "fit", "demo", "replicate"} <= set(_subcommands())


@pytest.mark.parametrize("command", _subcommands())
def test_every_command_has_help_with_examples(command, capsys):
    code, out, err = _run(capsys, command, "--help")
    assert code == 0 and not err
    assert "Examples:" in out
    assert "--quiet" in out and "--verbose" in out


@pytest.mark.parametrize("command", _subcommands())
def test_every_command_refuses_an_unknown_option(command, capsys):
    code, out, err = _run(capsys, command, "--no-such-option")
    assert code == 2
    line = _one_error_line(err, out)
    assert "--no-such-option" in line or "required" in line


def test_top_level_help_documents_exit_codes_and_version(capsys):
    code, out, _ = _run(capsys, "--help")
    assert code == 0
    assert "Exit codes" in out
    for text in ("0  success", "1  ", "2  bad input or usage", "--version", "--quiet", "--verbose"):
        assert text in out
    code, out, _ = _run(capsys, "--version")
    assert code == 0 and out.startswith("bayespilot ")


@pytest.mark.parametrize("argv", [[], ["fitt"], ["-q", "-v", "demo"], ["--verbose", "--quiet"]],
                         ids=["no command", "misspelled command", "quiet and verbose",
                              "quiet and verbose, no command"])
def test_usage_errors_exit_2(argv, capsys):
    code, out, err = _run(capsys, *argv)
    assert code == 2
    _one_error_line(err, out)


# --- recordings that cannot be read ------------------------------------------------------------
@pytest.mark.parametrize("case", CASES)
def test_cli_refuses_each_malformed_recording(case, params, capsys):
    for argv in (["fit", MALFORMED / case, "--method", "fast"],
                 ["loglik", MALFORMED / case, "--params", params]):
        code, out, err = _run(capsys, *argv)
        assert code == 2, (argv, err)
        line = _one_error_line(err, out)
        assert case in line  # names the file


@pytest.mark.parametrize("case", CASES)
def test_api_refuses_each_malformed_recording(case):
    with pytest.raises(RecordingError, match=case):
        read_recording(MALFORMED / case)


def _cli_bad(d: Path, run: Path, p: Path) -> dict[str, tuple[list, int, str]]:
    """name -> (argv, exit code, text the one error line must contain)."""
    not_mat = _write(d / "not.mat", "this is not a MATLAB file\n")
    kvv = _write(d / "kvv.json", '{"K_vv": 1.0}')
    wide = _write(d / "wide.json", json.dumps({**presets.paper_parameters("FD"), "zeta_nm": 5.0}))
    (d / "adir").mkdir(exist_ok=True)
    (d / "afile").write_text("")
    # the posterior commands, where they exist (they are being added to the CLI)
    optional = {
        "sample": {"sample: missing recording": (["sample", d / "nothere", "-o", d / "p.nc"], 2,
                                                 "file not found"),
                   "sample: malformed recording": (["sample", MALFORMED / "nan_value", "-o",
                                                    d / "p.nc"], 2, "NaN in column 'e'"),
                   "sample: unknown likelihood": (["sample", run, "-o", d / "p.nc",
                                                   "--likelihood", "eq5"], 2, "--likelihood"),
                   # (refused before the maximum-likelihood fit, which it followed)
                   "sample: backend in a folder that cannot be made": (
                       ["sample", run, "-o", d / "p.nc", "--max-steps", "10", "--backend",
                        Path(f"{run}.csv") / "b.h5"], 1,
                       "cannot write the sampler's backend file")},
        "compare": {"compare: missing recording": (["compare", d / "nothere"], 2,
                                                   "file not found"),
                    "compare: malformed recording": (["compare", MALFORMED / "inf_value"], 2,
                                                     "infinite value"),
                    "compare: missing posterior": (["compare", run, "--posterior",
                                                    d / "none.nc"], 2, "not found")},
        "plot": {"plot: missing posterior": (["plot", d / "none.nc", "-o", d / "plots"], 2,
                                             "not found"),
                 "plot: a recording, not a posterior": (["plot", f"{run}.json", "-o",
                                                         d / "plots"], 2, "not a netCDF")},
        "diagnose": {"diagnose: missing recording": (["diagnose", d / "nothere"], 2,
                                                     "not found"),
                     "diagnose: malformed recording": (["diagnose", MALFORMED / "t_not_zero"],
                                                       2, "t must start at 0")},
    }
    commands = set(_subcommands())
    extra = {k: v for command, cases in optional.items() if command in commands
             for k, v in cases.items()}
    return extra | {
        # missing files
        "fit: missing recording": (["fit", d / "nothere"], 2, "file not found"),
        "loglik: missing recording": (["loglik", d / "nothere", "--params", p], 2, "not found"),
        "loglik: missing parameter file": (["loglik", run, "--params", d / "none.json"], 2,
                                           "parameter file not found"),
        "simulate: missing parameter file": (["simulate", "-o", d / "x", "--params",
                                              d / "none.json"], 2, "not found"),
        "loglik: recording is a directory": (["loglik", d / "adir", "--params", p], 2, "adir"),
        "fit: not a MATLAB file": (["fit", not_mat], 2, "not a readable MATLAB"),
        "loglik: sidecar given as parameters": (["loglik", run, "--params", f"{run}.json"], 2,
                                                "is a recording's JSON sidecar, not a "
                                                "parameter file"),
        # misspelled and out-of-range parameters
        "simulate: misspelled parameter": (["simulate", "-o", d / "x", "--params", kvv], 2,
                                           "unknown parameter name(s) 'K_vv'"),
        "loglik: misspelled parameter": (["loglik", run, "--params", kvv], 2, "'K_vv'"),
        "loglik: parameter out of range": (["loglik", run, "--params", wide], 2,
                                           "zeta_nm = 5 is outside its range"),
        "simulate: negative motion gain": (["simulate", "-o", d / "x", "--motion-gain", "-1"], 2,
                                           "--motion-gain"),
        "simulate: remnant fraction 1": (["simulate", "-o", d / "x", "--remnant-fraction", "1"],
                                         2, "--remnant-fraction"),
        "simulate: unknown task": (["simulate", "-o", d / "x", "--task", "FX"], 2, "--task"),
        "fit: unknown method": (["fit", run, "--method", "slow"], 2, "--method"),
        "fit: negative seed": (["fit", run, "--seed", "-3"], 2, "--seed"),
        "fit: --iterate with fast": (["fit", run, "--method", "fast", "--iterate"], 2,
                                     "--iterate"),
        "demo: seed not a number": (["demo", "--seed", "x"], 2, "--seed"),
        "loglik: unknown initial": (["loglik", run, "--params", p, "--initial", "cold"], 2,
                                    "--initial"),
        "replicate: no realizations": (["replicate", "--out", d / "r", "--realizations", "0"], 2,
                                       "--realizations"),
        "replicate: unknown task": (["replicate", "--out", d / "r", "--tasks", "FD,FX"], 2,
                                    "--tasks"),
        "replicate: negative motion gain": (["replicate", "--out", d / "r", "--motion-gains",
                                             "1,-0.5"], 2, "--motion-gains"),
        "replicate: misspelled fit option": (["replicate", "--out", d / "r", "--fit-option",
                                              "repetitons=2"], 2, "'repetitons'"),
        "replicate: scheduler and workers": (["replicate", "--out", d / "r", "--scheduler",
                                              "tcp://127.0.0.1:1", "--workers", "2"], 2,
                                             "not both"),
        # outputs that cannot be written: the run fails (exit 1)
        "simulate: output below a file": (["simulate", "-o", d / "afile" / "x", "--duration",
                                           "2"], 1, "cannot write the recording"),
        "demo: output dir is a file": (["demo", "--out", d / "afile"], 1,
                                       "cannot write the example"),
    }


def _cli_case_names() -> list[str]:
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        return sorted(_cli_bad(Path(d), Path(d) / "run", Path(d) / "p.json"))


@pytest.mark.parametrize("case", _cli_case_names())
def test_cli_bad_input_is_one_clear_line(case, run10, params, tmp_path, capsys):
    argv, expected_code, expected = _cli_bad(tmp_path, run10, params)[case]
    code, out, err = _run(capsys, *argv)
    assert code == expected_code, err
    assert expected in _one_error_line(err, out)
    assert not (tmp_path / "x.csv").exists()


def test_fit_json_to_a_directory_fails_with_one_line(run10, tmp_path, capsys):
    (tmp_path / "adir").mkdir()
    code, out, err = _run(capsys, "fit", run10, "--method", "fast", "--json", tmp_path / "adir",
                          "-q")
    assert code == 2  # refused before the fit, as sample, compare and diagnose refuse
    line = _one_error_line(err, out)
    assert "adir: is a folder; give a file name for the fit" in line and "Errno" not in line


# --- an unreachable dask scheduler -----------------------------------------------------------
def test_cli_unreachable_scheduler_fails_with_one_line(tmp_path):
    # a subprocess with a generous limit, so that a hang fails the test instead of the CI run
    proc = subprocess.run(
        [sys.executable, "-m", "bayespilot.cli", "replicate", "--realizations", "1", "--tasks",
         "FD", "--motion-gains", "1", "--remnant-fractions", "0", "--method", "fast",
         "--duration", "5", "--out", str(tmp_path / "r"), "--scheduler", "tcp://127.0.0.1:1",
         "--connect-timeout", "1", "-q"],
        capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert proc.returncode == 1, proc.stderr
    line = _one_error_line(proc.stderr, proc.stdout)
    assert "cannot reach the dask scheduler at 'tcp://127.0.0.1:1'" in line
    assert not list((tmp_path / "r").glob("*.json"))


@pytest.mark.parametrize("address", ["tcp://127.0.0.1:1", "not-an-address::"])
def test_api_unreachable_scheduler_raises_campaign_error(address, tmp_path):
    from bayespilot.campaign import CampaignError, paper_study, run_campaign

    jobs = paper_study(1, tasks=("FD",), motion_gains=(1.0,), remnant_fractions=(0.0,),
                       method="fast", duration=5)
    with pytest.raises(CampaignError, match="cannot reach the dask scheduler"):
        run_campaign(jobs, tmp_path / "r", scheduler=address, connect_timeout=1, progress=False,
                     warm_cache=False)


# --- the public functions ---------------------------------------------------------------------
def _sim_params():
    return presets.paper_parameters("FD")


def _api_cases():
    from bayespilot.campaign import Job, paper_study, run_campaign
    from bayespilot.fit.fast import fit_fast
    from bayespilot.fit.three_step import fit_paper
    from bayespilot.likelihood import Likelihood, neg_log_lik
    from bayespilot.model import paper_model
    from bayespilot.plots import plot_traces
    from bayespilot.sample import sample
    from bayespilot.simulate import simulate

    rec = _recording(2.0)
    quick = dict(progress=False, max_steps=10, min_steps=5, check_every=5, n_walkers=18)
    truth = _sim_params()
    extra = {}
    if importlib.util.find_spec("bayespilot.compare") is not None:
        from bayespilot.compare import compare, nested_evidence

        extra |= {
            "compare: path instead of Recording": (lambda: compare("out/run"), TypeError,
                                                   "must be a Recording"),
            "compare: unknown likelihood": (lambda: compare(rec, likelihood="eq5"), ValueError,
                                            "likelihood must be one of"),
            "nested_evidence: empty prior box": (lambda: nested_evidence(lambda x: 0.0, [1.0],
                                                                         [0.0]),
                                                 ValueError, "lower < upper"),
        }
    if importlib.util.find_spec("bayespilot.diagnose") is not None:
        from bayespilot.diagnose import diagnose

        extra["diagnose: path instead of Recording"] = (lambda: diagnose("out/run"), TypeError,
                                                        "must be a Recording")
    return extra | {
        "read_recording: not a path": (lambda: read_recording(123), TypeError, "str or os.PathLike"),
        "read_recording: missing": (lambda: read_recording("/nonexistent/run"), RecordingError,
                                    "file not found"),
        "read_mat: missing": (lambda: read_mat("/nonexistent/run.mat"), RecordingError,
                              "file not found"),
        "Recording: NaN": (lambda: Recording({"t": [0, .01], "e": [0, np.nan], "u": [0, 0],
                                              "theta_ddot_m": [0, 0]}, 100.0, 1.0),
                           RecordingError, "non-finite"),
        "Recording: missing column": (lambda: Recording({"t": [0, .01], "e": [0, 0]}, 100.0, 1.0),
                                      RecordingError, "missing required column"),
        "Recording: unknown task": (lambda: Recording(rec.signals, 100.0, 1.0, "XY"),
                                    RecordingError, "task must be one of"),
        "Recording: rate disagrees with t": (lambda: Recording(rec.signals, 50.0, 1.0),
                                             RecordingError, "disagrees with sample_rate_hz"),
        "write_recording: .mat output": (lambda: write_recording(rec, "/tmp/x.mat"),
                                         RecordingError, ".mat"),
        "paper_parameters: unknown task": (lambda: presets.paper_parameters("XX"), ValueError,
                                           "task must be"),
        "simulate: misspelled parameter": (lambda: simulate(params={"K_vv": 1.0}, duration=2),
                                           ValueError, "unknown parameter(s) 'K_vv'"),
        "simulate: NaN parameter": (lambda: simulate(params={"K_v": float("nan")}, duration=2),
                                    ValueError, "K_v must be finite"),
        "simulate: remnant fraction 1.5": (lambda: simulate(remnant_fraction=1.5, duration=2),
                                           ValueError, "remnant_fraction"),
        "simulate: negative duration": (lambda: simulate(duration=-1), ValueError, "duration"),
        "model.fix: misspelled": (lambda: paper_model().fix(K_vv=1.0), ValueError, "'K_vv'"),
        "neg_log_lik: misspelled": (lambda: neg_log_lik(paper_model(), rec, {**truth, "K_vv": 1}),
                                    ValueError, "'K_vv'"),
        "Likelihood: wrong vector length": (lambda: Likelihood(paper_model(), rec)
                                            .neg_log_lik([1.0, 2.0]), ValueError, "expected 8"),
        "Likelihood: misspelled initial": (lambda: Likelihood(paper_model(), rec,
                                                              initial="periodc"),
                                           ValueError, "initial must be one of"),
        "Likelihood: path instead of Recording": (lambda: Likelihood(paper_model(), "out/run"),
                                                  TypeError, "must be a Recording"),
        "fit_fast: path instead of Recording": (lambda: fit_fast("out/run"), TypeError,
                                                "must be a Recording"),
        "fit_fast: no starts": (lambda: fit_fast(rec, n_starts=0), ValueError, "n_starts"),
        "fit_paper: n_best > repetitions": (lambda: fit_paper(rec, repetitions=2, n_best=3),
                                            ValueError, "n_best"),
        "sample: prior for a misspelled name": (
            lambda: sample(rec, init=truth, prior={"K_vv": stats.norm(1, 0.1)}, **quick),
            ValueError, "unknown parameter(s) 'K_vv'"),
        "sample: prior outside the bounds": (
            lambda: sample(rec, init=truth, prior={"delta_abs": stats.uniform(0.2, 0.1)}, **quick),
            ValueError, "outside the bounds of delta_abs"),
        "sample: prior not a distribution": (
            lambda: sample(rec, init=truth, prior={"K_v": 3.0}, **quick), TypeError,
            "scipy.stats distribution"),
        "sample: misspelled init": (lambda: sample(rec, init={"K_vv": 1.0}, **quick), ValueError,
                                    "'K_vv'"),
        "sample: unknown likelihood": (lambda: sample(rec, init=truth, likelihood="eq5", **quick),
                                       ValueError, "likelihood must be one of"),
        "Job: misspelled fit option": (lambda: Job("FD", 1.0, 0.2, 0,
                                                   fit_kwargs={"repetitons": 2}),
                                       ValueError, "'repetitons'"),
        "Job: remnant fraction 1": (lambda: Job("FD", 1.0, 1.0, 0), ValueError,
                                    "remnant_fraction"),
        "paper_study: no realizations": (lambda: paper_study(0), ValueError, "realizations"),
        "run_campaign: zero workers": (lambda: run_campaign([], "/tmp/unused", workers=0),
                                       ValueError, "workers"),
        "plot_traces: path instead of Recording": (lambda: plot_traces("out/run"), TypeError,
                                                   "Recording"),
    }


@pytest.mark.parametrize("case", sorted(_api_cases()))
def test_api_bad_input_raises_a_specific_exception(case):
    call, exc_type, text = _api_cases()[case]
    with pytest.raises(exc_type) as info:
        call()
    assert text in str(info.value)
    assert str(info.value).count("\n") == 0  # one line


# --- questionable recordings: read, with a warning ------------------------------------------------
def test_short_recording_warns_with_the_reason_at_the_callers_line(tmp_path):
    write_recording(_recording(10.0), tmp_path / "short")
    with pytest.warns(QuestionableRecordingWarning, match="10 s long, much shorter than the "
                                                          "81.92 s") as caught:
        rec = read_recording(tmp_path / "short")
    assert rec.n_samples == 1000  # still read
    assert caught[0].filename == __file__
    assert str(tmp_path / "short") in str(caught[0].message)


def test_low_sample_rate_warns(tmp_path):
    write_recording(_recording(60.0, rate=40.0), tmp_path / "slow")
    with pytest.warns(QuestionableRecordingWarning, match="40 Hz, under 50 Hz"):
        read_recording(tmp_path / "slow")


def test_short_and_slow_mat_file_warns_twice(tmp_path):
    r = _recording(20.0, rate=25.0)
    scipy.io.savemat(tmp_path / "run.mat", {**{k: v for k, v in r.signals.items()},
                                            "sample_rate_hz": 25.0, "motion_gain": 1.0,
                                            "task": "FD"})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        read_recording(tmp_path / "run.mat")
    messages = [str(w.message) for w in caught if w.category is QuestionableRecordingWarning]
    assert len(messages) == 2
    assert any("20 s long" in m for m in messages) and any("25 Hz" in m for m in messages)


@pytest.mark.parametrize("duration,rate", [(30.0, 100.0), (81.92, 100.0), (60.0, 50.0)])
def test_ordinary_recordings_do_not_warn(duration, rate, tmp_path):
    write_recording(_recording(duration, rate), tmp_path / "ok")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        read_recording(tmp_path / "ok")
    assert not [w for w in caught if w.category is QuestionableRecordingWarning]
    assert questionable(_recording(duration, rate)) == []


def test_cli_prints_the_warning_as_one_line_and_goes_on(run10, params, capsys):
    code, out, err = _run(capsys, "loglik", run10, "--params", params, "-q")
    assert code == 0 and out.startswith("-ln L = ")
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bayespilot: warning: ")
    assert "10 s long" in lines[0]


# --- a file or folder that is not a recording, at the CLI ------------------------------------------
@pytest.mark.parametrize("name, folder", [("post.nc", False), ("fig.png", False),
                                          ("lab/", True), (".", True)])
def test_cli_says_what_is_not_a_recording(name, folder, params, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "lab").mkdir()
    (tmp_path / "post.nc").write_bytes(b"\x89HDF\r\n\x1a\n")
    (tmp_path / "fig.png").write_bytes(b"\x89PNG\r\n\x1a\n")
    code, out, err = _run(capsys, "loglik", name, "--params", params)
    assert code == 2
    what = "a folder, not a recording" if folder else "not a recording"
    assert _one_error_line(err, out) == (
        f"bayespilot: error: {name}: {what} (a recording is NAME.csv with NAME.json, or a .mat "
        f"file)")


# --- sidecars that contradict their data or look mistyped: read, with a warning --------------------
def _questionable_reasons(tmp_path, rec: Recording) -> list[str]:
    write_recording(rec, tmp_path / "lab")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        read_recording(tmp_path / "lab")
    return [str(w.message) for w in caught if w.category is QuestionableRecordingWarning]


def _with(rec: Recording, motion_gain: float | None = None, **meta) -> Recording:
    return Recording(rec.signals, rec.sample_rate_hz,
                     rec.motion_gain if motion_gain is None else motion_gain, rec.task,
                     {**rec.metadata, **meta})


def test_motion_gain_0_with_a_moving_motion_column_warns(tmp_path):
    rec = _with(_recording(60.0), motion_gain=0.0)
    with pytest.warns(QuestionableRecordingWarning,
                      match=r"lab: the motion column moves although motion_gain is 0 \(no motion, "
                            r"in the recording format\): max \|theta_ddot_m\| = 1 rad/s\^2"):
        read_recording(write_recording(rec, tmp_path / "lab")[0])
    # no motion, no motion column: nothing to say
    still = rec.with_signals(theta_ddot_m=np.zeros(rec.n_samples))
    assert questionable(still) == [] and _questionable_reasons(tmp_path, still) == []


@pytest.mark.parametrize("gain, effect", [(-0.69, "would move the controlled element the "
                                                  "opposite way"),
                                          (0.0, "would not move the controlled element")])
def test_a_control_gain_that_is_not_positive_warns(tmp_path, gain, effect):
    rec = _with(_recording(60.0), control_gain=gain)
    with pytest.warns(QuestionableRecordingWarning, match=re.escape(
            f"control_gain (K_delta_u) is {gain:g}, not positive (the paper's is 0.69): the stick "
            f"{effect}")):
        back = read_recording(write_recording(rec, tmp_path / "lab")[0])
    assert back.control_gain == gain  # read as given


def test_a_misspelled_optional_key_warns_with_the_key_it_resembles(tmp_path):
    rec = _with(_recording(60.0), controlled_elment={"num": [4.0], "den": [1.0, 0.0, 0.0]})
    with pytest.warns(QuestionableRecordingWarning, match=re.escape(
            "unknown key 'controlled_elment' (did you mean 'controlled_element'?)")):
        back = read_recording(write_recording(rec, tmp_path / "lab")[0])
    assert "controlled_elment" in back.metadata  # kept, as the format says
    assert _questionable_reasons(tmp_path, _with(_recording(60.0), Subject="S1")) == [
        f"{tmp_path / 'lab'}: unknown key 'Subject' (did you mean 'subject'?): it is kept but "
        f"ignored, as the recording format does with unknown keys"]


def test_a_labs_own_keys_do_not_warn(tmp_path):
    rec = _with(_recording(60.0), subject_id="S1", run_id=3, lab_run=2, forcing_file="f.mat",
                control_mode="pitch", simulation={"seed": 1}, date="2024-05-01", subject="S1",
                run=3, notes="x", controlled_element={"num": [1.5], "den": [1.0, 0.0]})
    assert questionable(rec) == [] and _questionable_reasons(tmp_path, rec) == []


# --- columns that contradict each other: signs, an offset in e, spikes in u, a biased motion -------
_NEW_CHECKS = ("looks inverted", "e has an offset", "of u jump away", "theta_ddot_m looks biased")


def _new_reasons(rec: Recording) -> list[str]:
    """The reasons of questionable() from the column checks (not a short record's, say)."""
    return [r for r in questionable(rec) if any(k in r for k in _NEW_CHECKS)]


def _lab_task(rate: float = 50.0):
    """The other lab's task of docs/model.md: K/(s (s + 2)), K_delta_u 1, 40.96 s."""
    from bayespilot.forcing import Multisine
    from bayespilot.simulate import TrackingTask

    T = 40.96
    w0 = 2 * np.pi / T
    rng = np.random.default_rng(1)
    ft = Multisine(w0, [3, 7, 13, 23, 37, 61], [0.03, 0.02, 0.012, 0.006, 0.004, 0.003],
                   rng.uniform(0, 2 * np.pi, 6))
    fd = Multisine(w0, [4, 8, 14, 24, 38, 62], [0.004, 0.006, 0.01, 0.015, 0.02, 0.025],
                   rng.uniform(0, 2 * np.pi, 6))
    return TrackingTask(ft, fd, motion_gain=1.0, controlled_element=([8.0], [1.0, 2.0, 0.0]),
                        control_gain=1.0, sample_rate_hz=rate, duration=T, run_in=T / 2)


_LAB_PILOT = dict(K_v=0.8, T_vl=0.3, tau_v=0.25, K_m=0.4, tau_m=0.2, omega_nm=11.0,
                  zeta_nm=0.25, delta_abs=0.004)


@pytest.fixture(scope="module")
def clean_runs():
    """Clean simulated runs: the paper's FD and FT tasks at 50 to 1000 Hz, with and without
    remnant, short and not whole periods, no motion, a washout in the pilot, another lab's
    plant (whose e does not average out: mean 0.21 of std(e) over its 40.96 s)."""
    import dataclasses

    from bayespilot import diagnose
    from bayespilot.model import paper_model
    from bayespilot.simulate import TrackingTask, simulate

    def paper(task, rate, **kw):
        return dataclasses.replace(TrackingTask.paper(task, kw.pop("motion_gain", 1.0)),
                                   sample_rate_hz=rate)

    washout = diagnose.get_extension("motion-washout").build(paper_model())
    return {
        "FD 100 Hz 30 s F_n 0.15": simulate(task="FD", remnant_fraction=0.15, seed=1,
                                            duration=30.0).recording,
        "FT 100 Hz 23.7 s F_n 0.3": simulate(task="FT", remnant_fraction=0.3, seed=2,
                                             duration=23.7).recording,
        "FD 50 Hz 20 s no remnant": simulate(task=paper("FD", 50.0), seed=3,
                                             duration=20.0).recording,
        "FT 1000 Hz 10 s": simulate(task=paper("FT", 1000.0), remnant_gain=0.1, seed=4,
                                    duration=10.0).recording,
        "FD no motion": simulate(task="FD", motion_gain=0.0, remnant_fraction=0.05, seed=5,
                                 duration=30.0).recording,
        "FD washout pilot": simulate(washout, task="FD", remnant_fraction=0.15, seed=6,
                                     duration=30.0).recording,
        "other lab": simulate(params=_LAB_PILOT, task=_lab_task(), remnant_gain=0.17,
                              seed=2).recording,
    }


def _logged_through(rec: Recording, num, den) -> Recording:
    """rec with theta_ddot_m as a lab logs it after a filter (a washout), discretised."""
    from scipy import signal

    b, a = signal.bilinear(num, den, fs=rec.sample_rate_hz)
    return rec.with_signals(theta_ddot_m=signal.lfilter(b, a, rec.theta_ddot_m))


def _variants(rec: Recording) -> dict[str, Recording]:
    """Clean variants a lab makes: u clipped at the stops, u quantised by an 8-bit converter,
    the motion logged after a washout (omega_w 1 rad/s)."""
    sd = float(np.std(rec.u))
    q = 1.0 / 2 ** 8
    return {"clipped u": rec.with_signals(u=np.clip(rec.u, -sd, sd)),
            "8-bit u": rec.with_signals(u=np.round(rec.u / q) * q),
            "washout-logged motion": _logged_through(rec, [1, 0, 0], [1, 1.4, 1.0])}


def test_clean_recordings_raise_none_of_the_column_checks(clean_runs, tmp_path):
    for name, rec in clean_runs.items():
        assert _new_reasons(rec) == [], name
        for what, variant in _variants(rec).items():
            assert _new_reasons(variant) == [], f"{name}, {what}"
    # and the shipped ones: tests/data/valid, the example's washout run
    root = Path(__file__).parent.parent
    for stem in (Path(__file__).parent / "data" / "valid" / "tiny",
                 root / "analyses" / "results" / "diagnose" / "example" / "washout_run"):
        if stem.with_suffix(".csv").exists():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", QuestionableRecordingWarning)
                assert _new_reasons(read_recording(stem)) == [], stem


@pytest.mark.parametrize("run", ["FD 100 Hz 30 s F_n 0.15", "FT 100 Hz 23.7 s F_n 0.3",
                                 "other lab"])
@pytest.mark.parametrize("column, identity", [
    ("e", "e = f_t - theta"),
    ("u", "theta = G(s) (K_delta_u u + f_d)"),
    ("theta_ddot_m", "theta_ddot_m = K_theta theta''"),
])
def test_a_column_of_the_wrong_sign_is_named(clean_runs, run, column, identity):
    rec = clean_runs[run]
    flipped = rec.with_signals(**{column: -rec[column]})
    reasons = _new_reasons(flipped)
    assert len(reasons) == 1, reasons
    culprit = {"theta_ddot_m": "theta_ddot_m or of theta"}.get(column, column)
    assert reasons[0].startswith(f"the sign of {culprit} looks inverted: {identity}")
    assert re.search(r"\) = [+-][01]\.\d\d, but holds with \S+( \(or \S+\))? turned round "
                     r"\(correlation \+(0\.9\d|1\.00)\)", reasons[0]), reasons[0]


def test_a_flipped_theta_is_named_by_every_identity_it_is_in(clean_runs):
    rec = clean_runs["FD 100 Hz 30 s F_n 0.15"]
    reasons = _new_reasons(rec.with_signals(theta=-rec["theta"]))
    assert [r.split(":")[0] for r in reasons] == [
        "the sign of theta looks inverted", "the sign of theta_ddot_m or of theta looks inverted",
        "the sign of theta looks inverted"]
    # a motion system whose sign convention turned theta and its acceleration round together
    both = rec.with_signals(theta=-rec["theta"], theta_ddot_m=-rec.theta_ddot_m)
    assert [r.split(":")[0] for r in _new_reasons(both)] == [
        "the sign of theta looks inverted"] * 2


def test_the_sign_checks_need_their_columns(clean_runs):
    rec = clean_runs["FD 100 Hz 30 s F_n 0.15"]
    bare = Recording({k: rec[k] for k in ("t", "e", "u", "theta_ddot_m")}, rec.sample_rate_hz,
                     rec.motion_gain, rec.task, rec.metadata)
    assert _new_reasons(bare.with_signals(e=-rec.e, u=-rec.u)) == []
    # no motion: theta_ddot_m all zeros says nothing of a sign
    still = clean_runs["FD no motion"]
    assert not np.any(still.theta_ddot_m) and _new_reasons(still) == []


def test_a_flipped_column_warns_when_read_and_at_the_cli(clean_runs, params, tmp_path, capsys):
    rec = clean_runs["FD 100 Hz 30 s F_n 0.15"]
    write_recording(rec.with_signals(e=-rec.e), tmp_path / "lab")
    with pytest.warns(QuestionableRecordingWarning, match=re.escape(
            f"{tmp_path / 'lab'}: the sign of e looks inverted: e = f_t - theta (the format's "
            f"definition of e) fails, corr(e, f_t - theta) = -1.00, but holds with e turned "
            f"round (correlation +1.00)")):
        read_recording(tmp_path / "lab")
    code, out, err = _run(capsys, "loglik", tmp_path / "lab", "--params", params, "-q")
    assert code == 0
    assert any(line.startswith("bayespilot: warning: ") and "sign of e looks inverted" in line
               for line in err.splitlines()), err


@pytest.mark.parametrize("run", ["FD 100 Hz 30 s F_n 0.15", "FT 100 Hz 23.7 s F_n 0.3",
                                 "other lab"])
def test_an_offset_in_e_warns(clean_runs, run):
    rec = clean_runs[run]
    sd = float(np.std(rec.e))
    reasons = _new_reasons(rec.with_signals(e=rec.e + 0.3 * sd))
    assert len(reasons) == 1 and reasons[0].startswith(
        "e has an offset: e - (f_t - theta), which the format defines as 0, has a mean of "), reasons
    assert "0.30 of e's standard deviation" in reasons[0]
    assert reasons[0].endswith("; remove it from e"), reasons[0]
    assert _new_reasons(rec.with_signals(e=rec.e - 0.1 * sd)) == []


@pytest.mark.parametrize("run", ["FD 100 Hz 30 s F_n 0.15", "FD washout pilot"])
def test_a_theta_or_f_t_about_another_zero_is_not_an_offset_in_e(clean_runs, run):
    """theta logged about a trim attitude gives e - (f_t - theta) a mean too (0.005 rad is 0.35
    of std(e) ~ 0.014 here), but e is centred already: removing the mean from e would damage it,
    and theta's zero does the model no harm, so nothing is said.  (On a short run whose e does
    not average out, mean(e) 0.3-0.4 of std(e), a small trim of the sign of e's mean can still
    be taken for an offset in e: docs/recording-format.md.)"""
    rec = clean_runs[run]
    for trim in (0.005, -0.005, 0.02, -0.02):
        assert _new_reasons(rec.with_signals(theta=rec["theta"] + trim)) == [], trim
        assert _new_reasons(rec.with_signals(f_t=rec["f_t"] - trim)) == [], trim
    sd = float(np.std(rec.e))  # while an offset in e itself still warns, either sign
    for off in (0.3 * sd, -0.3 * sd):
        reasons = _new_reasons(rec.with_signals(e=rec.e + off))
        assert len(reasons) == 1 and reasons[0].startswith("e has an offset"), (off, reasons)


def test_spikes_in_u_warn_with_their_number_and_times(clean_runs):
    for name in ("FD 100 Hz 30 s F_n 0.15", "FT 1000 Hz 10 s", "FD 50 Hz 20 s no remnant"):
        rec = clean_runs[name]
        u = np.array(rec.u)
        k = rec.n_samples // 2
        u[k] += 50 * np.std(rec.u)
        reasons = _new_reasons(rec.with_signals(u=u))
        assert len(reasons) == 1 and reasons[0].startswith(
            "1 sample(s) of u jump away from their neighbours (spikes)"), (name, reasons)
        assert f"at t = {rec.t[k]:.6g} s" in reasons[0]
    rec = clean_runs["FD 100 Hz 30 s F_n 0.15"]
    u = np.array(rec.u)
    at = np.arange(200, 2800, 130)  # 20 samples, 5 sd(u) each
    u[at] -= 5 * np.std(rec.u)
    reasons = _new_reasons(rec.with_signals(u=u))
    assert len(reasons) == 1 and reasons[0].startswith("20 sample(s) of u jump away"), reasons
    assert "at t = 2, 3.3, 4.6, 5.9, 7.2, ... s" in reasons[0]


def _pulse_train(rec: Recording, width: float, seed: int, omega_nm: float = 30.0,
                 zeta_nm: float = 0.2) -> np.ndarray:
    """A u for rec of a pilot who pulses the stick: rectangular pulses of ``width`` s, random
    sign and size, every 0.7-2 s, through a fast neuromuscular system (omega_nm, zeta_nm)
    at 1000 Hz, with a little noise, sampled at rec's rate; u sits near 0 between pulses."""
    from scipy import signal

    fs = 1000.0
    t = np.arange(int(rec.duration * fs)) / fs
    rng = np.random.default_rng(seed)
    cmd = np.zeros_like(t)
    t0 = 0.5
    while t0 < rec.duration - 1:
        k0 = int(t0 * fs)
        cmd[k0:k0 + int(width * fs)] = rng.choice([-1, 1]) * rng.uniform(0.5, 1.5)
        t0 += rng.uniform(0.7, 2.0)
    b, a = signal.bilinear([omega_nm ** 2], [1, 2 * zeta_nm * omega_nm, omega_nm ** 2], fs=fs)
    u = signal.lfilter(b, a, cmd) + 0.01 * rng.normal(size=t.size)
    step = int(round(fs / rec.sample_rate_hz))
    return 0.03 * u[::step][:rec.n_samples]


def test_pulses_of_the_stick_are_not_spikes(clean_runs):
    """The 2-standard-deviation condition takes the larger of std(u) and its MAD estimate: on
    a pulse train u sits near 0 between pulses and the MAD estimate alone collapsed (22 to 28
    samples of each of these three were spikes)."""
    rec = clean_runs["FD 50 Hz 20 s no remnant"]
    for seed in range(3):
        u = _pulse_train(rec, 0.1, seed)
        assert _new_reasons(rec.with_signals(u=u)) == [], seed
        k = rec.n_samples // 2  # a real spike in such a u is still one
        u[k] += 10 * np.std(u)
        reasons = _new_reasons(rec.with_signals(u=u))
        assert len(reasons) == 1 and reasons[0].startswith("1 sample(s) of u jump away"), reasons


def test_spikes_are_not_checked_below_the_low_sample_rate(clean_runs):
    """Under LOW_SAMPLE_RATE_HZ a pulse through the neuromuscular system is a sample or two
    wide, 5-6 standard deviations from its neighbours' median (42 to 63 samples of each of
    these three were spikes, with either estimate of the standard deviation): no spike check
    there (the low rate is warned of instead)."""
    from bayespilot.recording import LOW_SAMPLE_RATE_HZ

    rec = clean_runs["FD 100 Hz 30 s F_n 0.15"]
    slow = Recording({k: np.asarray(v)[::5] for k, v in rec.signals.items()}, 20.0,
                     rec.motion_gain, rec.task, rec.metadata)
    assert slow.sample_rate_hz < LOW_SAMPLE_RATE_HZ
    for seed in range(3):
        reasons = questionable(slow.with_signals(u=_pulse_train(slow, 0.05, seed)))
        assert [r for r in reasons if "of u jump away" in r] == [], seed
        assert any(r.startswith("the sample rate is 20 Hz") for r in reasons)


def _bare(rec: Recording) -> Recording:
    """rec with only the required columns (no theta to check the motion against)."""
    return Recording({k: rec[k] for k in ("t", "e", "u", "theta_ddot_m")}, rec.sample_rate_hz,
                     rec.motion_gain, rec.task, rec.metadata)


@pytest.mark.parametrize("run", ["FD 100 Hz 30 s F_n 0.15", "FD washout pilot", "other lab"])
@pytest.mark.parametrize("share", [0.03, -0.03])
def test_a_bias_in_theta_ddot_m_warns(clean_runs, run, share):
    """A constant in theta_ddot_m makes its running integral, the pitch rate, a ramp: the canal
    model takes it for a sustained rotation (1 % of std(theta_ddot_m) took the fast fit's K_m
    from 0.52 to 0.40 on a simulated 81.92-s FD run).  Seen with or without theta."""
    rec = clean_runs[run]
    a = rec.theta_ddot_m
    b = share * float(np.std(a))
    for biased in (rec.with_signals(theta_ddot_m=a + b), _bare(rec).with_signals(
            theta_ddot_m=a + b)):
        reasons = _new_reasons(biased)
        assert len(reasons) == 1 and reasons[0].startswith(
            "theta_ddot_m looks biased: it has a constant part of about "), reasons
        m = re.search(r"about (\S+) rad/s\^2 \((\S+)% of its standard deviation .*drifts by "
                      r"(\S+) rad/s over the (\S+)-s run, (\S+) times that rate's spread",
                      reasons[0])
        assert m, reasons[0]
        est, pct, drift, T, ratio = (float(x) for x in m.groups())
        assert est == pytest.approx(b, rel=0.15)
        assert pct == pytest.approx(100 * abs(share), rel=0.15)
        assert drift == pytest.approx(b * rec.duration, rel=0.15) and T == pytest.approx(
            rec.duration, rel=1e-3)
        assert ratio > 0.75
        assert reasons[0].endswith("if the lab knows it is a sensor or logging bias, remove it "
                                   "(subtract the mean of theta_ddot_m over whole periods of "
                                   "the forcing, or the estimate above) before fitting")
        # the estimate removed, as the warning says: silent again
        assert _new_reasons(biased.with_signals(theta_ddot_m=a + b - est)) == []


def test_a_bias_in_theta_ddot_m_warns_when_read(clean_runs, tmp_path):
    rec = clean_runs["FD 100 Hz 30 s F_n 0.15"]
    a = rec.theta_ddot_m
    write_recording(rec.with_signals(theta_ddot_m=a + 0.01 * np.std(a)), tmp_path / "lab")
    with pytest.warns(QuestionableRecordingWarning, match=re.escape(
            f"{tmp_path / 'lab'}: theta_ddot_m looks biased: it has a constant part of about ")):
        read_recording(tmp_path / "lab")


def test_a_constant_motion_column_is_a_bias_and_no_motion_is_not(clean_runs, tmp_path):
    rec = clean_runs["FD 100 Hz 30 s F_n 0.15"]
    const = rec.with_signals(theta_ddot_m=np.full(rec.n_samples, 0.01))
    reasons = _new_reasons(const)
    assert len(reasons) == 1 and "(all of it: the column is constant)" in reasons[0], reasons
    # no motion: theta_ddot_m all zeros, or motion_gain 0 (whose moving column the motion_gain
    # check names; the motion of a run without motion is not judged for a bias)
    assert _new_reasons(rec.with_signals(theta_ddot_m=np.zeros(rec.n_samples))) == []
    still = clean_runs["FD no motion"]
    assert _new_reasons(still) == [] and _questionable_reasons(tmp_path, still) == []
    off = _with(const, motion_gain=0.0)
    assert _new_reasons(off) == []
    assert [r for r in questionable(off) if "moves although motion_gain is 0" in r]


def test_noise_in_theta_ddot_m_is_not_a_bias(clean_runs):
    """White noise in a logged (measured) theta_ddot_m makes its integral wander too (its drift
    ratio passes BIAS_DRIFT on these), but no estimate of a bias stands out from it (z < 1):
    nothing is said.  A bias still does, noise or not."""
    from bayespilot.recording import BIAS_DRIFT, _motion_bias_statistics

    for run, level in (("other lab", 0.3), ("other lab", 1.0)):
        rec = clean_runs[run]
        a = rec.theta_ddot_m
        noisy = a + level * np.std(a) * np.random.default_rng(1).normal(size=a.size)
        assert _motion_bias_statistics(rec.with_signals(theta_ddot_m=noisy))["ratio"] \
            > BIAS_DRIFT
        assert _new_reasons(rec.with_signals(theta_ddot_m=noisy)) == [], run
        biased = rec.with_signals(theta_ddot_m=noisy + 0.3 * level * np.std(a))
        assert [r for r in _new_reasons(biased) if "looks biased" in r], run


@pytest.mark.parametrize("run", ["FT 1000 Hz 10 s", "FD 50 Hz 20 s no remnant",
                                 "FT 100 Hz 23.7 s F_n 0.3"])
def test_short_records_are_not_judged_for_a_bias(clean_runs, run):
    """Under BIAS_MIN_S the rate's slowest lines do not average out (clean 10-s runs: drift
    ratio up to 0.98; 20-s windows of clean runs: 0.65): a record that short is not judged
    (its shortness is warned of), though the bias still harms it."""
    rec = clean_runs[run]
    a = rec.theta_ddot_m
    reasons = questionable(rec.with_signals(theta_ddot_m=a + 0.03 * np.std(a)))
    assert [r for r in reasons if "looks biased" in r] == []
    assert any(f"{rec.duration:g} s long" in r for r in reasons)


def test_the_paper_runs_and_the_examples_are_not_biased():
    """The runs the example makes (FD, K_theta 0.5 and 1, F_n 0.15, seeds 0 and 1, 81.92 s,
    and its 20-s doctest run); the shipped recordings are in
    test_clean_recordings_raise_none_of_the_column_checks."""
    from bayespilot.simulate import simulate

    for kt, seed, duration in ((0.5, 0, None), (1.0, 1, None), (1.0, 0, 20.0)):  # (20 s: silent)
        rec = simulate(task="FD", motion_gain=kt, remnant_fraction=0.15, seed=seed,
                       duration=duration).recording
        assert _new_reasons(rec) == [], (kt, seed)
        a = rec.theta_ddot_m  # and 1 % of bias is caught on the long ones
        found = [r for r in _new_reasons(rec.with_signals(theta_ddot_m=a + 0.01 * np.std(a)))
                 if "looks biased" in r]
        assert duration or len(found) == 1, (kt, seed, found)


def test_the_column_checks_run_with_one_blas_thread(clean_runs):
    """Their dot products and least squares span the whole record; multi-threaded BLAS only
    slows them (a 1000-Hz 81.92-s run: questionable() 224-242 ms on a busy 2-core machine with
    two threads, 18 ms with one).  The caller's own setting is back afterwards."""
    from threadpoolctl import threadpool_info, threadpool_limits

    from bayespilot import recording

    def blas_threads():
        return {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}

    if not blas_threads():  # pragma: no cover - numpy without a BLAS threadpoolctl sees
        pytest.skip("no BLAS library that threadpoolctl can limit")
    seen = []
    corr = recording._corr

    def spy(a, b):
        seen.append(blas_threads())
        return corr(a, b)

    rec = clean_runs["FD 100 Hz 30 s F_n 0.15"]
    with threadpool_limits(limits=2, user_api="blas"):
        try:
            recording._corr = spy
            questionable(rec)
        finally:
            recording._corr = corr
        assert blas_threads() == {2}
    assert seen and all(s == {1} for s in seen), seen


def test_importing_recording_imports_no_threadpoolctl():
    code = ("import sys, bayespilot.recording; "
            "print(sorted(m for m in ('threadpoolctl', 'scipy') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]", out

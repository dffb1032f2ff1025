"""Tests of the ``bayespilot`` command (bayespilot.cli) and of bayespilot.plots.

The commands run in-process through ``main([...])``; one smoke test runs the
installed console script.  Numbers printed by the CLI are checked against the
library functions called directly, and simulated files against identities
that hold independently of the simulator (e = f_t - theta; f_t rebuilt from
the forcing in the JSON sidecar).
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sysconfig
from pathlib import Path

import numpy as np
import pytest

import bayespilot
from bayespilot import presets
from bayespilot.cli import main
from bayespilot.io import read_recording
from bayespilot.likelihood import Likelihood, neg_log_lik
from bayespilot.model import paper_model
from bayespilot.recording import Recording

README = Path(__file__).resolve().parents[1] / "README.md"
NUMBER = r"(-?\d+(?:\.\d+)?(?:[eE][+-]?\d+)?)"


def _run(capsys, *argv):
    """main(argv) -> (exit code, stdout, stderr)."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _write_json(path: Path, obj) -> Path:
    path.write_text(json.dumps(obj))
    return path


def _loglik_value(out: str) -> float:
    m = re.match(r"-ln L = (\S+)$", out.splitlines()[0])
    assert m, out
    return float(m.group(1))


@pytest.fixture(scope="module")
def ft_run(tmp_path_factory):
    """A 10 s FT run at K_theta = 0.5, F_n = 0.2, seed 3, written by the CLI."""
    d = tmp_path_factory.mktemp("ft")
    code = main(["simulate", "--task", "FT", "--motion-gain", "0.5", "--remnant-fraction", "0.2",
                 "--seed", "3", "--duration", "10", "-o", str(d / "run"), "-q"])
    assert code == 0
    return d / "run"


@pytest.fixture(scope="module")
def ft_params(tmp_path_factory):
    return _write_json(tmp_path_factory.mktemp("p") / "ft.json", presets.paper_parameters("FT"))


# --- simulate -------------------------------------------------------------------------
def test_simulate_writes_a_valid_pair(tmp_path, capsys):
    code, out, err = _run(capsys, "simulate", "--task", "FT", "--motion-gain", "0.5",
                          "--remnant-fraction", "0.2", "--seed", "3", "--duration", "10",
                          "-o", tmp_path / "out" / "run")
    assert code == 0, err
    assert (tmp_path / "out" / "run.csv").is_file() and (tmp_path / "out" / "run.json").is_file()
    # one summary line with the path, K_n and F_n
    assert len(out.splitlines()) == 1
    assert str(tmp_path / "out" / "run.csv") in out
    kn = float(re.search(r"K_n = " + NUMBER, out).group(1))
    fn = float(re.search(r"F_n = " + NUMBER, out).group(1))
    assert kn > 0 and fn == pytest.approx(0.2, abs=1e-3)

    rec = read_recording(tmp_path / "out" / "run")
    assert rec.task == "FT" and rec.motion_gain == 0.5
    assert rec.n_samples == 1000 and rec.sample_rate_hz == 100.0
    # an identity independent of the simulator: e = f_t - theta
    np.testing.assert_allclose(rec.e, rec["f_t"] - rec["theta"], rtol=0, atol=1e-12)
    # the truth travels with the file
    sim = rec.metadata["simulation"]
    assert sim["seed"] == 3 and sim["parameters"] == presets.paper_parameters("FT")
    assert sim["remnant_fraction"] == pytest.approx(0.2, abs=1e-3)


def test_simulated_forcing_columns_match_the_sidecar(ft_run):
    rec = read_recording(ft_run)
    forcing = json.loads(Path(f"{ft_run}.json").read_text())["forcing"]
    w0 = forcing["base_frequency"]
    for name, column in (("target", "f_t"), ("disturbance", "f_d")):
        part = forcing[name]
        expected = sum(a * np.sin(w0 * n * rec.t + p)
                       for n, a, p in zip(part["n"], part["amplitude"], part["phase"]))
        np.testing.assert_allclose(rec[column], expected, rtol=0, atol=1e-12, err_msg=column)


def test_simulate_same_seed_same_files(tmp_path, capsys):
    common = ["simulate", "--task", "FD", "--remnant-fraction", "0.1", "--duration", "10", "-q"]
    for stem, seed in (("a", 5), ("b", 5), ("c", 6)):
        assert _run(capsys, *common, "--seed", seed, "-o", tmp_path / stem)[0] == 0
    for ext in (".csv", ".json"):
        assert (tmp_path / f"a{ext}").read_bytes() == (tmp_path / f"b{ext}").read_bytes()
    assert (tmp_path / "a.csv").read_bytes() != (tmp_path / "c.csv").read_bytes()


def test_simulate_writes_the_subject_that_a_pooled_batch_groups_by(tmp_path, capsys):
    """diagnose-batch --pool groups runs by the sidecar's subject, which simulate could not
    write: a newcomer following the docs had to edit the JSON by hand."""
    from bayespilot.diagnose.batch import plan_batch

    stems = [tmp_path / f"s1-run{k}" for k in (1, 2)]
    for k, stem in enumerate(stems):
        assert _run(capsys, "simulate", "--duration", "10", "--seed", k, "--subject", "S1",
                    "-q", "-o", stem)[0] == 0
    recs = [read_recording(s) for s in stems]
    assert [r.metadata["subject"] for r in recs] == ["S1", "S1"]
    (task,) = plan_batch([str(s) for s in stems], recs, pool=True)
    assert task.key == "S1_FD_k1" and len(task.paths) == 2
    for bad in ("", " S1", "a/b"):
        code, _, err = _run(capsys, "simulate", "--subject", bad, "-o", tmp_path / "x")
        assert code == 2 and "argument --subject" in err
    assert not (tmp_path / "x.csv").exists()


def test_simulate_without_remnant(tmp_path, capsys):
    code, out, _ = _run(capsys, "simulate", "--remnant-fraction", "0", "--duration", "10",
                        "-o", tmp_path / "r")
    assert code == 0 and "K_n = 0," in out and "F_n = 0.000" in out


def test_simulate_params_override(tmp_path, capsys):
    override = {"K_m": 0.2, "delta_abs": 0.02}
    pfile = _write_json(tmp_path / "mine.json", override)
    common = ["simulate", "--task", "FD", "--remnant-fraction", "0.2", "--seed", "1",
              "--duration", "10", "-q"]
    assert _run(capsys, *common, "--params", pfile, "-o", tmp_path / "mine-run")[0] == 0
    assert _run(capsys, *common, "-o", tmp_path / "paper")[0] == 0
    rec = read_recording(tmp_path / "mine-run")
    truth = dict(presets.paper_parameters("FD"), **override)
    assert rec.metadata["simulation"]["parameters"] == truth
    assert not np.array_equal(rec.u, read_recording(tmp_path / "paper").u)
    # the data carry the override: the true parameters fit better than Table 3's
    model = paper_model()
    assert neg_log_lik(model, rec, truth) < neg_log_lik(model, rec, presets.paper_parameters("FD"))


def test_simulate_divergence_is_a_runtime_failure(tmp_path, capsys):
    pfile = _write_json(tmp_path / "wild.json", {"K_v": 10, "K_m": 10, "tau_v": 1, "tau_m": 1})
    code, out, err = _run(capsys, "simulate", "--params", pfile, "--duration", "10",
                          "-o", tmp_path / "x")
    assert code == 1
    assert err.startswith("bayespilot: error: ") and "diverged" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "x.csv").exists()


# --- loglik -----------------------------------------------------------------------------
def test_loglik_equals_library(ft_run, ft_params, capsys):
    rec = read_recording(ft_run)
    truth = presets.paper_parameters("FT")
    code, out, err = _run(capsys, "loglik", ft_run, "--params", ft_params)
    assert code == 0, err
    lines = out.splitlines()
    # the run is not whole forcing periods: its first 2 s are left out, as the fitters do
    assert len(lines) == 3 and lines[2] == ("(the first 2 s left out: the record is not a "
                                            "whole number of forcing periods)")
    lik = Likelihood(paper_model(), rec, discard=2.0)
    assert _loglik_value(out) == lik.neg_log_lik(truth)
    vaf = float(re.match(r"VAF = " + NUMBER + " %", lines[1]).group(1))
    assert vaf == pytest.approx(lik.vaf(truth), abs=0.006)

    # the .csv path, --no-threshold, --initial rest (no wrap: nothing left out) and --quiet
    code, out, _ = _run(capsys, "loglik", f"{ft_run}.csv", "--params", ft_params,
                        "--no-threshold", "--initial", "rest", "-q")
    assert code == 0 and len(out.splitlines()) == 1
    assert _loglik_value(out) == neg_log_lik(paper_model(threshold=False), rec, truth,
                                             initial="rest")


def test_loglik_no_threshold_needs_no_delta(ft_run, tmp_path, capsys):
    seven = {k: v for k, v in presets.paper_parameters("FT").items() if k != "delta_abs"}
    pfile = _write_json(tmp_path / "seven.json", seven)
    code, out, _ = _run(capsys, "loglik", ft_run, "--params", pfile, "--no-threshold")
    assert code == 0
    assert _loglik_value(out) == Likelihood(paper_model(threshold=False), read_recording(ft_run),
                                            discard=2.0).neg_log_lik(seven)


# --- bad input --------------------------------------------------------------------------
BAD = {
    "missing recording": (lambda d, run, p: ["loglik", d / "nope", "--params", p],
                          "file not found"),
    "missing params file": (lambda d, run, p: ["loglik", run, "--params", d / "nope.json"],
                            "not found"),
    "malformed params JSON": (lambda d, run, p: ["loglik", run, "--params",
                                                 _text(d / "bad.json", '{"K_v": 1.0,')],
                              "not valid JSON"),
    "params not an object": (lambda d, run, p: ["simulate", "-o", d / "x", "--params",
                                                _text(d / "list.json", "[1, 2]")],
                             "JSON object"),
    "unknown parameter": (lambda d, run, p: ["simulate", "-o", d / "x", "--params",
                                             _text(d / "unk.json", '{"K_x": 1}')],
                          "unknown parameter name(s) 'K_x'; valid names are K_v, T_vl"),
    "missing parameter": (lambda d, run, p: ["loglik", run, "--params",
                                             _text(d / "one.json", '{"K_v": 1}')],
                          "missing parameter(s) T_vl, tau_v"),
    "parameter out of range": (lambda d, run, p: ["simulate", "-o", d / "x", "--params",
                                                  _text(d / "big.json", '{"omega_nm": 50}')],
                               "outside its range"),
    "parameter not a number": (lambda d, run, p: ["simulate", "-o", d / "x", "--params",
                                                  _text(d / "str.json", '{"K_v": "1"}')],
                               "must be a finite number"),
    "negative remnant fraction": (lambda d, run, p: ["simulate", "-o", d / "x",
                                                     "--remnant-fraction", "-0.1"],
                                  "--remnant-fraction"),
    "negative motion gain": (lambda d, run, p: ["simulate", "-o", d / "x", "--motion-gain", "-1"],
                             "--motion-gain"),
    "missing sidecar": (lambda d, run, p: ["loglik", _lone_csv(d, run), "--params", p],
                        "no sidecar"),
    "invalid recording": (lambda d, run, p: ["loglik", _nan_csv(d, run), "--params", p],
                          "NaN in column 'u'"),
    "unknown command": (lambda d, run, p: ["fitt"], "invalid choice"),
}


def _text(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _lone_csv(d: Path, run: Path) -> Path:
    shutil.copy(f"{run}.csv", d / "lone.csv")
    return d / "lone.csv"


def _nan_csv(d: Path, run: Path) -> Path:
    shutil.copy(f"{run}.json", d / "nan.json")
    lines = Path(f"{run}.csv").read_text().splitlines()
    header = lines[0].split(",")
    row = lines[5].split(",")
    row[header.index("u")] = "nan"
    lines[5] = ",".join(row)
    (d / "nan.csv").write_text("\n".join(lines) + "\n")
    return d / "nan"


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_is_one_line_and_exit_2(case, ft_run, ft_params, tmp_path, capsys):
    make_argv, expected = BAD[case]
    code, out, err = _run(capsys, *make_argv(tmp_path, ft_run, ft_params))
    assert code == 2
    assert "Traceback" not in err and "Traceback" not in out
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("bayespilot: error: ")
    assert expected in lines[0]
    assert not (tmp_path / "x.csv").exists()


# --- demo -------------------------------------------------------------------------------
def test_demo_writes_plot_and_recording(tmp_path, capsys):
    code, out, err = _run(capsys, "demo", "--quick", "--out", tmp_path / "demo", "--seed", "2")
    assert code == 0, err
    png = tmp_path / "demo" / "traces.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
    rec = read_recording(tmp_path / "demo" / "recording")
    assert (rec.task, rec.motion_gain, rec.n_samples) == ("FD", 1.0, 8192)
    assert rec.metadata["simulation"]["remnant_fraction"] == pytest.approx(0.2, abs=1e-3)
    truth = presets.paper_parameters("FD")
    with_thr = float(re.search(r"with threshold \(delta_abs = 0.0075\): " + NUMBER, out).group(1))
    without = float(re.search(r"without threshold \(delta_abs = 0\): +" + NUMBER, out).group(1))
    assert with_thr == pytest.approx(neg_log_lik(paper_model(), rec, truth), abs=0.006)
    assert without == pytest.approx(neg_log_lik(paper_model(threshold=False), rec, truth),
                                    abs=0.006)
    assert re.search(r"VAF with threshold: " + NUMBER + " %", out)


# --- help and version -------------------------------------------------------------------
@pytest.mark.parametrize("command", [[], ["simulate"], ["loglik"], ["demo"]])
def test_help_exits_0_with_example(command, capsys):
    code, out, _ = _run(capsys, *command, "--help")
    assert code == 0
    assert "Example" in out
    if not command:
        assert "Exit codes" in out and "simulate" in out and "loglik" in out


def test_help_documents_every_option(capsys):
    for command, options in {"simulate": ["--task", "--motion-gain", "--remnant-fraction",
                                          "--remnant-gain", "--seed", "--duration", "--params",
                                          "--sample-rate", "--output"],
                             "loglik": ["--params", "--no-threshold", "--initial"],
                             "demo": ["--out", "--seed"]}.items():
        _, out, _ = _run(capsys, command, "--help")
        for option in options:
            assert option in out, (command, option)


def test_version_in_process(capsys):
    code, out, _ = _run(capsys, "--version")
    assert code == 0 and out.strip() == f"bayespilot {bayespilot.__version__}"


def test_installed_console_script_version():
    script = Path(sysconfig.get_path("scripts")) / "bayespilot"
    exe = str(script) if script.exists() else shutil.which("bayespilot")
    assert exe, "the bayespilot console script is not installed (pip install .)"
    proc = subprocess.run([exe, "--version"], capture_output=True, text=True, timeout=60,
                          stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"bayespilot {bayespilot.__version__}"


def test_quiet_and_verbose_conflict(capsys):
    code, _, err = _run(capsys, "-q", "-v", "demo")
    assert code == 2 and "not both" in err


# --- plots --------------------------------------------------------------------------------
def _tiny() -> Recording:
    t = np.arange(200) / 100.0
    return Recording({"t": t, "e": np.sin(t), "u": np.cos(t), "theta_ddot_m": -np.sin(t)},
                     100.0, 1.0, "FD")


def test_plot_traces_uses_given_axes():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bayespilot.plots import plot_traces

    fig, axes = plt.subplots(4, 1)
    try:
        canal = np.linspace(-0.02, 0.02, 200)
        assert plot_traces(_tiny(), canal=canal, delta_abs=0.0075, ax=axes) is fig
        assert [len(a.lines) for a in axes] == [1, 1, 1, 3]  # i and the two band edges
        with pytest.raises(ValueError, match="ax must hold 4 axes"):
            plot_traces(_tiny(), canal=canal, ax=axes[:3])
        with pytest.raises(ValueError, match="give canal too"):
            plot_traces(_tiny(), delta_abs=0.01)
        with pytest.raises(ValueError, match="one value per sample"):
            plot_traces(_tiny(), canal=canal[:10])
        with pytest.raises(ValueError, match=">= 0"):
            plot_traces(_tiny(), canal=canal, delta_abs=-1.0)
        with pytest.raises(TypeError, match="Recording or Simulation"):
            plot_traces({"t": [0, 1]})
    finally:
        plt.close("all")


def test_plot_traces_new_figure_has_three_panels_without_canal():
    import matplotlib.pyplot as plt

    from bayespilot.plots import plot_traces

    fig = plot_traces(_tiny())
    try:
        assert len(fig.axes) == 3
    finally:
        plt.close(fig)


# --- README -------------------------------------------------------------------------------
def test_readme_python_example_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the example writes out/example.csv + .json
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert blocks, "README.md has no python example"
    namespace: dict = {}
    exec(compile(blocks[0], str(README), "exec"), namespace)  # noqa: S102 - our own README


# --- records too short, demo --quick (review 4) -----------------------------------------------
def _first_samples(run: Path, n: int, out: Path) -> Path:
    """The first ``n`` samples of a recording, written as a recording of their own."""
    from bayespilot.io import write_recording

    rec = read_recording(run)
    signals = {k: np.asarray(v)[:n] for k, v in rec.signals.items()}
    write_recording(Recording(signals, rec.sample_rate_hz, rec.motion_gain, rec.task, {}), out)
    return out


def test_loglik_on_a_record_shorter_than_the_delays_says_so(ft_run, ft_params, tmp_path,
                                                             capsys):
    """-ln L is +inf when a channel's delay is not shorter than the record by more than 4
    samples: the command says the record is too short and how long it must be (exit 2), not
    that the model is unstable at parameters that are stable."""
    truth = presets.paper_parameters("FT")
    name = max(("tau_v", "tau_m"), key=lambda k: truth[k])
    dt = read_recording(ft_run).dt
    need = next(n for n in range(1, 1000) if truth[name] / dt < n - 4)  # delay + 4 samples
    recs = {n: _first_samples(ft_run, n, tmp_path / f"n{n}") for n in (3, need - 1, need)}
    # the library: +inf below the length, finite from it on
    assert neg_log_lik(paper_model(), read_recording(recs[need - 1]), truth) == np.inf
    assert np.isfinite(neg_log_lik(paper_model(), read_recording(recs[need]), truth))
    for n in (3, need - 1):
        code, out, err = _run(capsys, "loglik", recs[n], "--params", ft_params)
        assert code == 2 and out == ""
        (line,) = [ln for ln in err.splitlines() if ln.startswith("bayespilot: error:")]
        assert "unstable" not in err
        assert f"{recs[n]}: the record is too short for the pilot model: {n} sample(s)" in line
        assert f"{name} = {truth[name]:g} s needs at least {need}" in line
    code, out, err = _run(capsys, "loglik", recs[need], "--params", ft_params)
    assert code == 0, err
    assert _loglik_value(out) == neg_log_lik(paper_model(), read_recording(recs[need]), truth)


@pytest.mark.parametrize("extra, named", [
    (["--task", "FT"], "drop --task or --quick"),
    (["--nlive", "5", "--likelihood", "eq4"], "drop --nlive, --likelihood or --quick"),
    (["--motion-gains", "0.5", "--duration", "10", "--max-steps", "10"],
     "drop --motion-gains, --duration, --max-steps or --quick"),
])
def test_demo_quick_refuses_the_full_demos_options(extra, named, tmp_path, capsys):
    """--quick is a fixed check (docs/cli.md): the full demo's options with it are a usage
    error naming them, not silently ignored."""
    code, out, err = _run(capsys, "demo", "--quick", "--out", tmp_path / "d", *extra)
    assert code == 2 and out == ""
    assert err.startswith("bayespilot: error: argument --quick:") and named in err
    assert not (tmp_path / "d").exists()


def test_demo_passes_only_the_options_given(tmp_path, capsys, monkeypatch):
    """Without --quick the options reach run_example; those not given take its defaults."""
    import bayespilot.example as example

    calls = []

    def fake(out, **kwargs):
        calls.append(kwargs)
        return Path(out) / "report.md"

    monkeypatch.setattr(example, "run_example", fake)
    assert _run(capsys, "demo", "--out", tmp_path / "d", "-q")[0] == 0
    assert _run(capsys, "demo", "--out", tmp_path / "d", "--task", "FT", "--nlive", "20",
                "--motion-gains", "1", "-q")[0] == 0
    figure = {"formats": ("png",), "dpi": 200, "title": True}  # (run_example's own, in effect)
    strip = [{k: v for k, v in c.items() if k not in ("progress", "say", *figure)} for c in calls]
    assert strip == [{"seed": 0}, {"seed": 0, "task": "FT", "nlive": 20, "motion_gains": (1.0,)}]
    assert all({k: c[k] for k in figure} == figure for c in calls)


def test_demo_warnings_are_one_line_each(tmp_path, capsys, monkeypatch):
    """A sampler's warning during the demo is one 'bayespilot: warning:' line (docs/cli.md),
    said once however often it is raised; it was Python's two-line display with a path."""
    import warnings

    import bayespilot.example as example
    from bayespilot.sample import ConvergenceWarning

    def fake(out, **kwargs):
        for _ in range(2):
            warnings.warn("the chain reached max_steps = 10", ConvergenceWarning)
        return Path(out) / "report.md"

    monkeypatch.setattr(example, "run_example", fake)
    code, out, err = _run(capsys, "demo", "--out", tmp_path / "d", "-q")
    assert code == 0
    assert err.splitlines() == ["bayespilot: warning: the chain reached max_steps = 10"]


def test_fit_of_a_run_without_motion_says_so_once(tmp_path, capsys):
    """A recording without motion: the motion channel's parameters are named in one
    'bayespilot: warning:' line (the fit builds two likelihoods; Python showed two warnings)."""
    from bayespilot.io import write_recording
    from bayespilot.simulate import simulate

    rec = simulate(task="FD", motion_gain=0.0, remnant_fraction=0.05, seed=2,
                   duration=30.0).recording
    write_recording(rec, tmp_path / "still")
    code, out, err = _run(capsys, "fit", tmp_path / "still", "--method", "fast")
    assert code == 0 and "-ln L" in out
    (line,) = [ln for ln in err.splitlines() if "warning" in ln]
    assert line.startswith("bayespilot: warning: the vestibular channel's input "
                           "(theta_ddot_m) is zero throughout the record")


def test_a_stick_offset_is_one_warning_line(ft_run, tmp_path, capsys):
    """The fit's offset warning (a UserWarning) was Python's two-line display naming the
    bayespilot script, and `sample`, which prints only RuntimeWarnings, dropped it."""
    import warnings

    from bayespilot.cli import _said_to_user
    from bayespilot.io import write_recording
    from bayespilot.recording import QuestionableRecordingWarning

    rec = read_recording(ft_run)
    write_recording(rec.with_signals(u=rec.u + 3.0 * float(np.std(rec.u))), tmp_path / "off")
    code, out, err = _run(capsys, "fit", tmp_path / "off", "--method", "fast", "-q")
    lines = err.strip().splitlines()
    assert code == 0 and lines, err
    offset = [ln for ln in lines if "the control output u has a mean of" in ln]
    assert len(offset) == 1 and offset[0].startswith("bayespilot: warning: ")
    assert all(ln.startswith("bayespilot: warning: ") for ln in lines)
    # what sample, compare and diagnose --posterior print of the warnings they record
    said = warnings.WarningMessage("m", QuestionableRecordingWarning, "f", 1)
    assert _said_to_user(said)
    assert not _said_to_user(warnings.WarningMessage("m", UserWarning, "f", 1))


def test_output_piped_to_a_reader_that_goes_away_is_not_an_error(tmp_path):
    """`bayespilot fit run | head`: the reader closes the pipe before the summary is written.
    That ended in 'unexpected BrokenPipeError ... please report it', exit 1; now quietly 0."""
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "bayespilot.cli", "simulate", "-o",
                             str(tmp_path / "run"), "--duration", "5", "--seed", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            stdin=subprocess.DEVNULL)
    proc.stdout.close()  # the reader is gone before anything is written
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 0, err
    assert "BrokenPipeError" not in err and "unexpected" not in err


def test_command_defaults_are_the_librarys():
    """The command line restates the library's defaults as literals (so that --help shows
    them without importing the library); each must be the function's own default."""
    import inspect

    from bayespilot.campaign import run_campaign
    from bayespilot.cli import build_parser
    from bayespilot.compare import compare
    from bayespilot.diagnose import diagnose, diagnose_pooled
    from bayespilot.diagnose.batch import diagnose_batch
    from bayespilot.sample import sample

    def default(fn, name):
        return inspect.signature(fn).parameters[name].default

    def parsed(*argv):
        return vars(build_parser().parse_args(list(argv)))

    d = parsed("diagnose", "run")
    for fn in (diagnose, diagnose_pooled):
        assert (d["alpha"], d["bootstrap"], d["calibrate"], d["noise_passes"]) == (
            default(fn, "alpha"), default(fn, "n_bootstrap"), default(fn, "n_calibrate"),
            default(fn, "noise_passes")), fn.__name__
    b = parsed("diagnose-batch", "run", "--out", "o")
    assert b["connect_timeout"] == default(diagnose_batch, "connect_timeout")
    if "connect_timeout" in inspect.signature(run_campaign).parameters:
        assert b["connect_timeout"] == default(run_campaign, "connect_timeout")
    assert parsed("sample", "run", "-o", "p.nc")["max_steps"] == default(sample, "max_steps")
    assert parsed("compare", "run")["nlive"] == default(compare, "nlive")

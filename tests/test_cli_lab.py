"""The command line as another lab uses it (an outside audit): a fit's JSON as a parameter file,
other sample rates, a file that is not a posterior, a run without motion.

The commands run in-process through ``main([...])``; numbers are checked against the library
called directly.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from bayespilot import presets
from bayespilot.cli import main
from bayespilot.fit.result import FitResult
from bayespilot.io import read_recording, write_recording
from bayespilot.simulate import TrackingTask, simulate
from test_cli import _loglik_value, _run  # (the command-line tests' helpers)


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A 10-s FT run (K_theta = 0.5, F_n = 0.2) and its fast fit's JSON, both by the CLI."""
    d = tmp_path_factory.mktemp("lab")
    assert main(["simulate", "--task", "FT", "--motion-gain", "0.5", "--remnant-fraction", "0.2",
                 "--seed", "3", "--duration", "10", "-o", str(d / "run"), "-q"]) == 0
    assert main(["fit", str(d / "run"), "--method", "fast", "--json", str(d / "fit.json"),
                 "-q"]) == 0
    return d / "run", d / "fit.json"


# --- 1. a fit's JSON as --params ----------------------------------------------------------
def test_loglik_takes_a_fits_json(fitted, tmp_path, capsys):
    """fit --json then loglik --params: the fit's params are taken (they were refused as 12
    unknown names), the same -ln L as from a file of the params alone."""
    run, fit_json = fitted
    params = json.loads(fit_json.read_text())["params"]
    flat = tmp_path / "flat.json"
    flat.write_text(json.dumps(params))
    code, out, err = _run(capsys, "loglik", run, "--params", fit_json, "-v")
    assert code == 0, err
    assert f"{fit_json}: a fit's result (fast method, with threshold, of {run}): its params " \
           "are taken" in err
    code2, out2, _ = _run(capsys, "loglik", run, "--params", flat)
    assert code2 == 0 and _loglik_value(out) == _loglik_value(out2)
    # the fit's own -ln L, at its own discard (the first 2 s of a record not whole periods)
    assert _loglik_value(out) == pytest.approx(FitResult.from_json(fit_json).neg_log_lik,
                                               rel=1e-9)


def test_loglik_no_threshold_ignores_a_fits_delta_abs(fitted, capsys):
    run, fit_json = fitted
    code, out, err = _run(capsys, "loglik", run, "--params", fit_json, "--no-threshold", "-v")
    assert code == 0, err
    assert ("--no-threshold: delta_abs from the parameter file is ignored (held at 0, as fit "
            "--no-threshold holds every threshold)") in err
    code, out_q, err_q = _run(capsys, "loglik", run, "--params", fit_json, "--no-threshold")
    assert code == 0 and "ignored" not in err_q  # (said with -v only)


def test_simulate_takes_a_fits_params(fitted, tmp_path, capsys):
    run, fit_json = fitted
    params = json.loads(fit_json.read_text())["params"]
    code, out, err = _run(capsys, "simulate", "--task", "FT", "--params", fit_json,
                          "--duration", "10", "-o", tmp_path / "again", "-q")
    assert code == 0, err
    truth = json.loads((tmp_path / "again.json").read_text())["simulation"]["parameters"]
    assert truth == pytest.approx(params, rel=0, abs=0)


def test_a_params_object_that_is_not_a_whole_fit_says_what_is_read(fitted, tmp_path, capsys):
    """A file with 'params' but not the rest of a fit's result (neg_log_lik, vaf, method) is
    not taken for one: refused, saying what a fit's file has."""
    _, fit_json = fitted
    cut = tmp_path / "cut.json"
    cut.write_text(json.dumps({"params": json.loads(fit_json.read_text())["params"]}))
    code, out, err = _run(capsys, "loglik", fitted[0], "--params", cut)
    assert code == 2 and err.count("\n") == 1
    assert err.startswith(f"bayespilot: error: {cut}: unknown parameter name(s) 'params'; "
                          "valid names are K_v, T_vl")
    assert err.rstrip().endswith("(a fit's result, as 'bayespilot fit --json' writes it, is "
                                 "read by its params when it has params, neg_log_lik, vaf, "
                                 "method)")
    # a fit's params are checked as any file's: a value outside Table 1 is refused
    bad = json.loads(fit_json.read_text())
    bad["params"]["omega_nm"] = 50.0
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    code, out, err = _run(capsys, "loglik", fitted[0], "--params", tmp_path / "bad.json")
    assert code == 2 and "omega_nm = 50 is outside its range [5, 30] rad/s" in err, err


# --- 2. simulate --sample-rate ------------------------------------------------------------
@pytest.mark.parametrize("rate", [50.0, 120.0])
def test_simulate_sample_rate(rate, tmp_path, capsys):
    code, out, err = _run(capsys, "simulate", "--sample-rate", f"{rate:g}", "--duration", "20",
                          "--remnant-fraction", "0.1", "--seed", "4", "-o", tmp_path / "r")
    assert code == 0, err
    assert f"20 s at {rate:g} Hz, seed 4" in out
    rec = read_recording(tmp_path / "r")
    assert rec.sample_rate_hz == rate and rec.n_samples == int(round(20 * rate))
    ref = simulate(task=TrackingTask.paper("FD", 1.0, sample_rate_hz=rate),
                   remnant_fraction=0.1, seed=4, duration=20.0).recording
    for name in ("e", "u", "theta_ddot_m"):
        np.testing.assert_allclose(rec[name], ref[name], rtol=1e-12, atol=1e-12)


def test_simulate_default_rate_is_the_papers(tmp_path, capsys):
    code, out, err = _run(capsys, "simulate", "--duration", "10", "--seed", "1", "-o",
                          tmp_path / "r", "-q")
    assert code == 0, err
    rec = read_recording(tmp_path / "r")
    assert rec.sample_rate_hz == presets.SAMPLE_RATE_HZ == 100.0
    ref = simulate(task="FD", seed=1, duration=10.0).recording
    np.testing.assert_allclose(rec.u, ref.u, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("argv, message", [
    (["--sample-rate", "5"], "argument --sample-rate: the target's line n = 213 at 2.6001 Hz "
                             "(16.3369 rad/s) is at or above the Nyquist frequency 2.5 Hz of "
                             "the 5-Hz recording: it would be recorded aliased; give "
                             "--sample-rate above 5.2002 Hz"),
    (["--sample-rate", "0"], "argument --sample-rate: must be > 0, got 0"),
    (["--sample-rate", "nan"], "argument --sample-rate: expected a finite number, got 'nan'"),
    (["--sample-rate", "50", "--duration", "0.03"],
     "argument --duration: 0.03 s is shorter than 2 samples at 50 Hz"),
])
def test_simulate_bad_sample_rate_is_a_usage_error(argv, message, tmp_path, capsys):
    code, out, err = _run(capsys, "simulate", *argv, "-o", tmp_path / "r")
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith(f"bayespilot: error: {message}")
    assert not (tmp_path / "r.csv").exists()


# --- 4. plot on a file that is not a posterior --------------------------------------------
def test_plot_on_a_wrong_file_names_the_command(fitted, tmp_path, capsys):
    _, fit_json = fitted
    code, out, err = _run(capsys, "plot", fit_json, "-o", tmp_path / "figs")
    assert code == 2 and err.count("\n") == 1
    assert err.startswith(f"bayespilot: error: {fit_json}: not a netCDF file written by "
                          "'bayespilot sample' (or Posterior.to_netcdf)")


def test_plot_on_another_programs_netcdf_names_the_command(tmp_path, capsys):
    import xarray as xr

    nc = tmp_path / "other.nc"
    xr.Dataset({"x": ("t", np.arange(3.0))}).to_netcdf(nc)
    code, out, err = _run(capsys, "plot", nc, "-o", tmp_path / "figs")
    assert code == 2 and err.count("\n") == 1
    assert "written by 'bayespilot sample' (or Posterior.to_netcdf)" in err, err


# --- 5. a run without motion --------------------------------------------------------------
SILENT = ("bayespilot: warning: the vestibular channel's input (theta_ddot_m) is zero "
          "throughout the record, so its parameters (tau_m, K_m, delta_abs) are not "
          "identified: the record says nothing about them, and the values given for them are "
          "not estimates")


@pytest.fixture(scope="module")
def still(tmp_path_factory):
    rec = simulate(task="FD", motion_gain=0.0, remnant_fraction=0.05, seed=2,
                   duration=30.0).recording
    stem = tmp_path_factory.mktemp("still") / "still"
    write_recording(rec, stem)
    return stem


def test_fit_without_motion_marks_the_motion_channel_not_identified(still, tmp_path, capsys):
    out_json = tmp_path / "fit.json"
    code, out, err = _run(capsys, "fit", still, "--method", "fast", "--json", out_json)
    assert code == 0, err
    assert [ln for ln in err.splitlines() if "warning" in ln] == [SILENT]
    rows = {ln.split()[0]: ln for ln in out.splitlines()
            if ln.split() and ln.split()[0] in presets.TABLE1_BOUNDS}
    for name in ("K_m", "tau_m", "delta_abs"):
        assert rows[name].endswith("(not identified)") and "*" not in rows[name]
    for name in ("K_v", "T_vl", "tau_v", "omega_nm", "zeta_nm"):
        assert "not identified" not in rows[name]
    assert ("not identified: K_m, tau_m, delta_abs: their channel's input is zero throughout "
            "the record (e.g. a run without motion), so the record says nothing about them; "
            "their values are where the fit stopped, not estimates") in out
    assert "on a bound of the search box: tau_m" not in out  # (not a bound's estimate either)
    fit = FitResult.from_json(out_json)
    assert fit.settings["unidentified"] == ["K_m", "tau_m", "delta_abs"]
    assert "K_m" in fit.summary() and fit.summary().count("(not identified)") == 3


def test_fit_without_motion_and_threshold_marks_two(still, capsys):
    code, out, err = _run(capsys, "fit", still, "--method", "fast", "--no-threshold", "-q")
    assert code == 0, err
    assert "not identified: K_m, tau_m: their channel's input" in out
    (delta,) = [ln for ln in out.splitlines() if ln.startswith("delta_abs")]
    assert delta.endswith("(fixed)")


def test_fit_with_motion_marks_nothing(fitted, capsys):
    run, fit_json = fitted
    assert "unidentified" not in FitResult.from_json(fit_json).settings
    assert "not identified" not in FitResult.from_json(fit_json).summary()

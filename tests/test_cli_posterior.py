"""The ``bayespilot sample``, ``compare`` and ``plot`` commands (in-process through ``main``).

Short simulated recordings and short chains: these check the plumbing (files,
JSON keys, exit codes, one-line errors), and that the numbers the commands
write are the ones the library gives for the same file.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bayespilot.cli import main
from bayespilot.sample import Posterior


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A 10 s FD run at K_theta = 1, F_n = 0.1, delta_abs = 0.03, written by the CLI, and its
    posterior from a short 'bayespilot sample' (not converged: it warns and still writes)."""
    d = tmp_path_factory.mktemp("post")
    (d / "params.json").write_text(json.dumps({"delta_abs": 0.03}))
    assert main(["simulate", "--task", "FD", "--motion-gain", "1", "--remnant-fraction", "0.1",
                 "--seed", "4", "--duration", "10", "--params", str(d / "params.json"),
                 "-o", str(d / "run"), "-q"]) == 0
    return d


@pytest.fixture(scope="module")
def sampled(run_dir):
    code = main(["sample", str(run_dir / "run"), "-o", str(run_dir / "post.nc"), "--json",
                 str(run_dir / "summary.json"), "--seed", "2", "--max-steps", "300", "-q"])
    return code, run_dir / "post.nc", run_dir / "summary.json"


def test_sample_writes_netcdf_and_summary(sampled):
    code, nc, js = sampled
    assert code == 0 and nc.exists() and js.exists()
    post = Posterior.from_netcdf(nc)
    stored = json.loads(js.read_text())
    summary = stored["summary"]
    names = ("K_v", "T_vl", "tau_v", "K_m", "tau_m", "omega_nm", "zeta_nm", "delta_abs")
    assert tuple(summary) == names == post.parameter_names  # (no version key among them)
    import emcee

    import bayespilot
    # outputs audit 4.1: whether the chain converged, and of what, beside the table
    assert stored["converged"] is post.converged and stored["steps"] == 300
    assert (stored["file"], stored["seed"], stored["likelihood"]) == (str(nc), 2, "eq4")
    # (what sample() needs to run the chain again: the CLI's min_steps is min(1000, max))
    assert (stored["max_steps"], stored["min_steps"]) == (300, 300)
    assert stored["recording"] == post.settings["recording"] == str(nc.parent / "run")
    assert len(stored["recording_sha256"]) == 64 and stored["model"] == "Pool et al. (2012)"
    assert stored["bayespilot_version"] == bayespilot.__version__
    attrs = post.idata.posterior.attrs
    assert attrs["bayespilot_version"] == bayespilot.__version__
    assert attrs["inference_library_version"] == emcee.__version__
    for n in names:
        d = summary[n]
        lo, hi = d["hdi_90"]
        assert lo <= d["median"] <= hi
        assert d["mean"] == pytest.approx(float(np.mean(post.draws(n))))
        assert math.isfinite(d["r_hat"]) and d["ess_bulk"] > 0
    # settings and the simulation's truth travel in the netCDF attributes
    attrs = post.idata.posterior.attrs
    assert attrs["likelihood"] == "eq4" and attrs["n_steps"] == 300
    assert attrs["true_delta_abs"] == pytest.approx(0.03)
    assert post.truth["delta_abs"] == pytest.approx(0.03)
    assert "lp" in post.idata.sample_stats


def test_sample_warns_when_not_converged(run_dir, capsys):
    code, out, err = _run(capsys, "sample", run_dir / "run", "-o", run_dir / "p2.nc",
                          "--max-steps", "60", "--likelihood", "coloured", "-q")
    assert code == 0
    # named by the recording, as the other warnings are
    assert f"warning: {run_dir / 'run'}: the chain reached max_steps = 60" in err
    # no backend given: the advice is not to resume one
    assert err.count("to run longer, raise max_steps (bayespilot sample --max-steps), or give a "
                     "backend (bayespilot sample --backend FILE.h5) to be able to resume\n") == 1
    assert "same backend" not in err
    assert "Traceback" not in err
    post = Posterior.from_netcdf(run_dir / "p2.nc")
    # the default coloured likelihood re-fits its AR model (order by BIC at the initial fit)
    # at every parameter vector: nothing but the pilot parameters is sampled
    assert post.parameter_names[-1] == "delta_abs" and not post.converged
    assert post.settings["ar"] == "profiled" and post.settings["noise"] is None
    assert post.settings["ar_order"] >= 1


def test_sample_coloured_with_sampled_ar(run_dir, capsys):
    code, out, err = _run(capsys, "sample", run_dir / "run", "-o", run_dir / "p3.nc",
                          "--max-steps", "40", "--likelihood", "coloured", "--ar", "sampled",
                          "--ar-order", "3", "-q")
    assert code == 0, err
    post = Posterior.from_netcdf(run_dir / "p3.nc")
    assert post.parameter_names[-3:] == ("pacf_1", "pacf_2", "pacf_3")


def test_plot_writes_three_figures(sampled, tmp_path, capsys):
    _, nc, _ = sampled
    code, out, err = _run(capsys, "plot", nc, "-o", tmp_path / "figs")
    assert code == 0, err
    for name in ("marginal_delta_abs.png", "pair.png", "trace.png"):
        png = tmp_path / "figs" / name
        assert png.exists() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "true delta_abs = 0.03 marked" in out


def test_compare_json(sampled, run_dir, tmp_path, capsys):
    _, nc, _ = sampled
    out_json = tmp_path / "cmp.json"
    code, out, err = _run(capsys, "compare", run_dir / "run", "--json", out_json, "--seed", "1",
                          "--nlive", "40", "--posterior", nc)
    assert code == 0, err
    d = json.loads(out_json.read_text())
    assert d["log_bayes_factor"] == pytest.approx(d["log_evidence_threshold"]
                                                  - d["log_evidence_none"])
    assert d["log_bayes_factor_err"] > 0
    assert d["decision"] in ("threshold", "none", "inconclusive")
    # a threshold of 0.03 IPUT at K_theta = 1: the data say so even on 10 s
    assert d["decision"] == "threshold" and d["delta_aic"] > 0
    assert d["savage_dickey_valid"] is False  # no draws near 0
    assert "decision: threshold" in out
    # outputs audit 4.4: which posterior the Savage-Dickey check read
    post = d["settings"]["posterior"]
    assert (post["given"], post["seed"], post["file"]) == (True, 2, str(nc))


def test_compare_refuses_the_posterior_of_another_recording(sampled, run_dir, capsys):
    """Audit: 'compare a --posterior pb.nc' with pb.nc sampled on recording b took b's draws
    (and, coloured, its AR model) and printed a wrong ln BF without a word."""
    _, nc, _ = sampled
    assert main(["simulate", "--task", "FD", "--motion-gain", "1", "--remnant-fraction", "0.1",
                 "--seed", "5", "--duration", "10", "-o", str(run_dir / "other"), "-q"]) == 0
    capsys.readouterr()
    code, out, err = _run(capsys, "compare", run_dir / "other", "--nlive", "40", "--posterior",
                          nc, "-q")
    assert f"the posterior was sampled on another recording ({run_dir / 'run'}) than the one " \
           f"compared ({run_dir / 'other'}): their contents differ; sample the posterior of " \
           f"{run_dir / 'other'}, or give none" in err
    assert out == "" and "Traceback" not in err
    assert code == 2  # bad input (compare's ValueError), as sample's


@pytest.mark.parametrize("argv, message", [
    (["sample", "{d}/missing", "-o", "{d}/x.nc"], "not found"),
    (["sample", "{d}/run", "-o", "{d}/x.txt"], "must end in .nc"),
    (["sample", "{d}/run", "-o", "{d}/x.nc", "--likelihood", "white"], "invalid choice"),
    (["sample", "{d}/run", "-o", "{d}/x.nc", "--max-steps", "0"], "must be >= 1"),
    (["sample", "{d}/run", "-o", "{d}/x.nc", "--likelihood", "coloured", "--ar-order", "0"],
     "argument --ar-order: 0 with --ar profiled"),
    (["compare", "{d}/missing"], "not found"),
    (["compare", "{d}/run", "--posterior", "{d}/params.json"], "not a netCDF"),
    (["compare", "{d}/run", "--nlive", "5"], "must be >= 20"),
    (["plot", "{d}/missing.nc", "-o", "{d}/figs"], "posterior file not found"),
    (["plot", "{d}/params.json", "-o", "{d}/figs"], "not a netCDF"),
    (["plot", "{d}", "-o", "{d}/figs"], "is a directory"),
    (["plot", "{d}/run.csv"], "required"),
])
def test_bad_input_is_one_line_exit_2(run_dir, capsys, argv, message):
    code, out, err = _run(capsys, *[a.format(d=run_dir) for a in argv])
    assert code == 2
    errors = [line for line in err.splitlines() if line.startswith("bayespilot: error:")]
    assert len(errors) == 1 and message in errors[0] and "Traceback" not in err


def test_netcdf_of_another_program_is_bad_input(run_dir, tmp_path, capsys):
    """A valid netCDF file that 'bayespilot sample' did not write."""
    import xarray as xr

    nc = tmp_path / "other.nc"
    xr.Dataset({"x": ("t", np.arange(3.0))}).to_netcdf(nc)
    code, out, err = _run(capsys, "plot", nc, "-o", tmp_path / "figs")
    assert code == 2 and "bayespilot: error:" in err and err.count("\n") == 1


@pytest.mark.parametrize("argv, what", [
    (["sample", "{d}/run", "-o", "{f}/p.nc"], "posterior"),
    (["sample", "{d}/run", "-o", "{t}/p.nc", "--json", "{f}/s.json"], "summary"),
    (["compare", "{d}/run", "--json", "{f}/c.json"], "comparison"),
    (["diagnose", "{d}/run", "--json", "{f}/d.json"], "diagnosis"),
    (["diagnose", "{d}/run", "--report", "{f}"], "report"),
])
def test_an_unwritable_output_is_refused_before_the_computation(run_dir, tmp_path, capsys,
                                                                 monkeypatch, argv, what):
    """An output path through a file: one line naming it, exit 1, before anything is computed
    (sample wrote its file after hours of sampling and lost them; the message said 'File
    exists')."""
    import bayespilot.compare
    import bayespilot.diagnose
    import bayespilot.sample

    def never(*a, **k):
        raise AssertionError("computed before the output was checked")

    for mod, name in ((bayespilot.sample, "sample"), (bayespilot.compare, "compare"),
                      (bayespilot.diagnose, "diagnose")):
        monkeypatch.setattr(mod, name, never)
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    code, out, err = _run(capsys, *[a.format(d=run_dir, f=blocker, t=tmp_path) for a in argv])
    assert code == 1 and out == ""
    line = err.splitlines()[-1]  # (after the 10-s record's warning)
    assert line.startswith("bayespilot: error: ") and f"cannot write the {what}" in line
    assert f"{blocker} is a file, not a folder" in line


def test_compare_json_goes_through_the_atomic_write(run_dir, tmp_path, capsys, monkeypatch):
    """compare --json over an old file whose write fails (a full disk): one error line and the
    old file kept (it was written in place, and a full disk left half a file)."""
    import bayespilot._files as files

    out_json = tmp_path / "cmp.json"
    out_json.write_text('{"old": 1}')

    def full_disk(path, text):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(files, "write_text_atomic", full_disk)
    code, out, err = _run(capsys, "compare", run_dir / "run", "--json", out_json, "--seed", "1",
                          "--nlive", "20", "--no-savage-dickey")
    assert code == 1 and err.splitlines()[-1] == (f"bayespilot: error: {out_json}: cannot write "
                                                  f"(No space left on device)")
    assert out_json.read_text() == '{"old": 1}'

"""``--with PHYSICS``: fit, loglik, sample and compare on the paper's model extended by a
catalogue entry of ``diagnose`` (the API took an extended model; the command line did not).

The commands run in-process through ``main([...])``; numbers are checked against the library
called directly with the entry's ``build``.
"""

from __future__ import annotations

import json

import pytest

from bayespilot.cli import main
from bayespilot.diagnose import get_extension
from bayespilot.fit.fast import fit_fast
from bayespilot.fit.result import FitResult
from bayespilot.io import read_recording, write_recording
from bayespilot.model import DeadZone, Parameter, paper_model
from bayespilot.recording import Recording
from test_cli import _loglik_value, _run  # (the command-line tests' helpers)

ENTRY_FILE = '''
from bayespilot.diagnose import get_extension
import dataclasses
MY_WASHOUT = dataclasses.replace(get_extension("motion-washout"), name="my-washout")
'''


@pytest.fixture(autouse=True)
def _registry_restored():
    """An entry of one's own that a command registered (``--with FILE.py:NAME``) is removed
    after the test: the registry is the process's, and an entry left there became a
    candidate of every later diagnosis in the same test worker."""
    from bayespilot.diagnose.catalogue import registered_extensions, unregister_extension

    before = {e.name for e in registered_extensions()}
    yield
    for e in registered_extensions():
        if e.name not in before:
            unregister_extension(e.name)


@pytest.fixture(scope="module")
def washout_fit(tmp_path_factory):
    """A 10-s FT run (K_theta = 1, F_n = 0.15) and its fast fit with the washout, by the CLI."""
    d = tmp_path_factory.mktemp("with")
    assert main(["simulate", "--task", "FT", "--motion-gain", "1", "--remnant-fraction", "0.15",
                 "--seed", "4", "--duration", "10", "-o", str(d / "run"), "-q"]) == 0
    assert main(["fit", str(d / "run"), "--method", "fast", "--with", "motion-washout",
                 "--json", str(d / "fit.json"), "-q"]) == 0
    return d / "run", d / "fit.json"


def test_fit_with_an_entry_is_the_librarys_fit_of_the_built_model(washout_fit, capsys):
    run, fit_json = washout_fit
    model = get_extension("motion-washout").build(paper_model())
    direct = fit_fast(read_recording(run), model, seed=0)
    saved = FitResult.from_json(fit_json)
    assert tuple(saved.params) == tuple(model.all_names)  # omega_w (and the fixed zeta_w) included
    assert saved.params["zeta_w"] == 0.7
    for k, v in direct.params.items():
        assert saved.params[k] == pytest.approx(v, rel=1e-12), k
    assert saved.neg_log_lik == pytest.approx(direct.neg_log_lik, rel=1e-12)
    # the summary says which model was fitted
    assert f"model: {model.name}" in saved.summary()
    assert "model:" not in fit_fast(read_recording(run), paper_model(), seed=0).summary()


def test_loglik_with_an_entry_takes_the_extended_fit(washout_fit, capsys):
    run, fit_json = washout_fit
    code, out, err = _run(capsys, "loglik", run, "--params", fit_json, "--with", "motion-washout")
    assert code == 0, err
    assert _loglik_value(out) == pytest.approx(FitResult.from_json(fit_json).neg_log_lik,
                                               rel=1e-9)
    # without --with, the new names are refused with the option that gives them
    code, out, err = _run(capsys, "loglik", run, "--params", fit_json)
    assert code == 2 and out == ""
    assert "unknown fit's parameter name(s) 'omega_w', 'zeta_w'" in err
    assert "(omega_w, zeta_w: give --with motion-washout)" in err


def test_an_entry_of_ones_own_by_file(washout_fit, tmp_path, capsys):
    run, fit_json = washout_fit
    entry = tmp_path / "my_entries.py"
    entry.write_text(ENTRY_FILE)
    code, out, err = _run(capsys, "loglik", run, "--params", fit_json,
                          "--with", f"{entry}:MY_WASHOUT")
    assert code == 0, err
    assert _loglik_value(out) == pytest.approx(FitResult.from_json(fit_json).neg_log_lik,
                                               rel=1e-9)


@pytest.mark.parametrize("spec, message", [
    ("control-saturation", "argument --with: control-saturation is fitted by the censored "
                           "likelihood, which only 'bayespilot diagnose' has"),
    ("washout", "argument --with: unknown extension 'washout'; the catalogue has "
                "motion-system-dynamics, motion-washout"),
    ("nofile.py:X", "argument --with: nofile.py:X: no file nofile.py"),
])
def test_an_entry_that_cannot_be_used_is_refused(washout_fit, spec, message, capsys):
    run, _ = washout_fit
    code, out, err = _run(capsys, "fit", run, "--method", "fast", "--with", spec)
    assert code == 2 and out == ""
    assert message in err
    assert "register_extension" not in err  # (the command's words: FILE.py:NAME)


def test_an_entry_the_recording_lacks_a_column_for_is_refused(washout_fit, tmp_path, capsys):
    run, _ = washout_fit
    rec = read_recording(run)
    bare = tmp_path / "bare"
    signals = {k: v for k, v in rec.signals.items() if k != "theta"}
    write_recording(Recording(signals, rec.sample_rate_hz, rec.motion_gain, rec.task,
                              rec.metadata), bare)
    code, out, err = _run(capsys, "fit", bare, "--method", "fast", "--with", "otolith-channel")
    assert code == 2 and out == ""
    assert "argument --with: otolith-channel needs the recording column(s) theta" in err


def test_sample_with_an_entry_and_its_plot(washout_fit, tmp_path, capsys):
    run, _ = washout_fit
    post = tmp_path / "post.nc"
    code, out, err = _run(capsys, "sample", run, "--with", "motion-washout", "--max-steps", "60",
                          "-o", post, "--json", tmp_path / "post.json", "-q")
    assert code == 0, err
    summary = json.loads((tmp_path / "post.json").read_text())["summary"]
    assert "omega_w" in summary and "zeta_w" not in summary  # (fixed: not sampled)
    code, out, err = _run(capsys, "plot", post, "-o", tmp_path / "plots", "-q")
    assert code == 0, err
    assert (tmp_path / "plots" / "marginal_omega_w.png").is_file()


def test_simulate_with_an_entry_is_the_librarys_simulation(tmp_path, capsys):
    """simulate --with: the run of the built model, sample for sample, with the entry's
    parameter in the sidecar's truth (what the diagnosis walk-through's recording is)."""
    from bayespilot import presets
    from bayespilot.simulate import simulate

    params = tmp_path / "washout.json"
    params.write_text('{"omega_w": 0.3}')
    code, out, err = _run(capsys, "simulate", "--task", "FD", "--motion-gain", "1",
                          "--remnant-gain", "0.063", "--seed", "777", "--duration", "20",
                          "--with", "motion-washout", "--params", params, "-o", tmp_path / "w")
    assert code == 0, err
    truth = dict(presets.paper_parameters("FD"), omega_w=0.3)
    sim = simulate(get_extension("motion-washout").build(paper_model()), truth, task="FD",
                   motion_gain=1.0, remnant_gain=0.063, seed=777, duration=20.0)
    rec = read_recording(tmp_path / "w")
    for k in ("e", "u", "theta_ddot_m", "theta"):
        assert (rec[k] == sim.recording[k]).all(), k
    written = json.loads((tmp_path / "w.json").read_text())["simulation"]["parameters"]
    assert written["omega_w"] == 0.3 and written["zeta_w"] == 0.7


def test_simulate_with_an_entry_needs_its_truth(tmp_path, capsys):
    code, out, err = _run(capsys, "simulate", "--task", "FD", "--with", "otolith-channel",
                          "-o", tmp_path / "o")
    assert code == 2 and out == "" and not (tmp_path / "o.csv").exists()
    assert ("argument --with: give the true value of K_ot in [-5, 5] rad/(m/s^2), h_head in "
            "[-3, 3] m in --params") in err


def test_simulate_with_control_saturation_clips_the_control(tmp_path, capsys):
    params = tmp_path / "sat.json"
    params.write_text('{"u_max": 0.02}')
    code, out, err = _run(capsys, "simulate", "--task", "FD", "--remnant-fraction", "0.1",
                          "--duration", "20", "--with", "control-saturation", "--params", params,
                          "-o", tmp_path / "s", "-q")
    assert code == 0, err
    u = read_recording(tmp_path / "s").u
    assert abs(u).max() == 0.02 and (abs(u) == 0.02).sum() > 10  # flat tops at the limit


def _paper(task: str) -> dict:
    from bayespilot import presets

    return dict(presets.paper_parameters(task))


@pytest.mark.parametrize("argv", [
    ["loglik", "{run}", "--params", "{params}", "--no-threshold", "--with", "threshold-shape"],
    ["fit", "{run}", "--method", "fast", "--no-threshold", "--with", "threshold-shape"],
])
def test_threshold_shape_without_threshold_is_refused(washout_fit, tmp_path, capsys,
                                                      monkeypatch, argv):
    """--no-threshold's model removes the soft dead zone (it is not the identity at
    delta_abs = 0), which leaves the paper's model without threshold: the entry would do
    nothing, and is refused before anything runs."""
    import bayespilot.fit.fast

    def started(*a, **k):
        raise AssertionError("the computation started")

    monkeypatch.setattr(bayespilot.fit.fast, "fit_fast", started)
    run, _ = washout_fit
    params = tmp_path / "soft.json"
    params.write_text(json.dumps({**_paper("FT"), "w_soft": 0.01}))
    code, out, err = _run(capsys, *[a.format(run=run, params=params) for a in argv])
    assert code == 2 and out == "", err
    assert ("argument --with: threshold-shape with --no-threshold: the model without "
            "threshold removes its SoftDeadZone on vestibular") in err, err


def test_compare_with_threshold_shape_weighs_it_against_the_linear_model(
        washout_fit, capsys, monkeypatch):
    """compare --with threshold-shape: the soft dead zone's model against its model without
    threshold, the linear one (compare builds it; it was refused while "without threshold"
    meant delta_abs held at 0)."""
    import bayespilot.compare
    from bayespilot.cli import CommandFailed
    from bayespilot.fit.three_step import _model_for

    seen = []

    def compare(rec, model, **kwargs):
        seen.append(model)
        raise CommandFailed("stopped by the test")

    monkeypatch.setattr(bayespilot.compare, "compare", compare)
    run, _ = washout_fit
    code, _, err = _run(capsys, "compare", run, "--with", "threshold-shape")
    assert code == 1 and err.splitlines()[-1] == "bayespilot: error: stopped by the test", err
    (model,) = seen
    assert "w_soft" in model.parameter_names and model.has_threshold
    none = _model_for(model, threshold=False)
    assert "w_soft" not in none.all_names and "delta_abs" not in none.all_names


def test_threshold_shape_with_a_free_threshold_is_taken(washout_fit, tmp_path, capsys):
    run, _ = washout_fit
    params = tmp_path / "soft.json"
    params.write_text(json.dumps({**_paper("FT"), "w_soft": 0.01}))
    code, out, err = _run(capsys, "loglik", run, "--params", params, "--with", "threshold-shape")
    assert code == 0, err
    assert _loglik_value(out) < 0


def test_loglik_loads_a_file_of_ones_own_once(washout_fit, tmp_path, capsys):
    """The model is built once: the file ran twice (for the model, then for the columns)."""
    run, fit_json = washout_fit
    entry = tmp_path / "loud.py"
    entry.write_text(ENTRY_FILE + 'print("loading loud.py")\n')
    code, out, err = _run(capsys, "loglik", run, "--params", fit_json,
                          "--with", f"{entry}:MY_WASHOUT")
    assert code == 0, err
    assert out.count("loading loud.py") == 1, out


VISUAL_DEAD_ZONE = '''
import dataclasses
from bayespilot.diagnose import get_extension
from bayespilot.model import DeadZone, Parameter


def _build(model):
    return model.with_nonlinearity("visual", DeadZone("delta_vis"),
                                   [Parameter("delta_vis", 0.0, 0.1, 0.0, "rad")])


VIS_DZ = dataclasses.replace(get_extension("motion-washout"), name="visual-dead-zone",
                             build=_build, new_parameters=("delta_vis",), starts=())
'''


def test_loglik_without_threshold_is_the_model_fit_without_threshold_fits(
        washout_fit, tmp_path, capsys):
    """loglik --no-threshold --with an entry that adds a second dead zone (delta_vis)
    evaluates the model fit --no-threshold fits, without_threshold()'s: delta_vis held at 0
    with delta_abs (it built paper_model(threshold=False) and then the entry, so delta_vis
    was read from the parameter file and the two commands' "no threshold" models differed)."""
    from bayespilot.likelihood import Likelihood

    run, _ = washout_fit
    entry = tmp_path / "vis.py"
    entry.write_text(VISUAL_DEAD_ZONE)
    params = tmp_path / "p.json"
    params.write_text(json.dumps({**_paper("FT"), "delta_vis": 0.02}))
    code, out, err = _run(capsys, "loglik", run, "--params", params, "--no-threshold",
                          "--with", f"{entry}:VIS_DZ")
    assert code == 0, err
    # (said without -v: a second threshold held at 0 is not the one the option names)
    assert ("bayespilot: warning: --no-threshold: delta_abs, delta_vis from the parameter file are ignored (held "
            "at 0, as fit --no-threshold holds every threshold)") in err
    rec = read_recording(run)
    model = paper_model().with_nonlinearity(
        "visual", DeadZone("delta_vis"), [Parameter("delta_vis", 0.0, 0.1, 0.0, "rad")])
    held = dict(_paper("FT"), delta_abs=0.0, delta_vis=0.0)
    from bayespilot.likelihood import _startup_default

    skip = _startup_default(rec, "periodic")
    want = Likelihood(model, rec, discard=skip).neg_log_lik(held)
    assert _loglik_value(out) == pytest.approx(want, rel=1e-12)
    assert want != pytest.approx(Likelihood(model, rec, discard=skip).neg_log_lik(
        dict(held, delta_vis=0.02)), rel=1e-6)

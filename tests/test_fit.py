"""Maximum-likelihood fitting: exact Jacobians, Steps II and III, the three-step driver, the fast estimator."""

import json
import re

import numpy as np
import pytest

import bayespilot
from bayespilot.cli import main
from bayespilot.fit.fast import fit_fast
from bayespilot.fit.gauss_newton import refine
from bayespilot.fit.result import FitResult
from bayespilot.fit.scan import scan_parameter
from bayespilot.fit.three_step import fit_paper
from bayespilot.io import read_recording, write_recording
from bayespilot.likelihood import Likelihood
from bayespilot.model import Parameter, Washout, paper_model
from bayespilot.simulate import simulate


@pytest.fixture(scope="module")
def sim():
    return simulate(task="FD", motion_gain=1.0, remnant_fraction=0.15, seed=21, duration=30.0)


@pytest.mark.parametrize("initial", ["periodic", "rest"])
def test_jacobian_matches_central_differences(sim, initial):
    model = paper_model().add_stage("vestibular", Washout(), [Parameter("omega_w", 0.01, 10, 0.3)])
    lik = Likelihood(model, sim.recording, initial=initial)
    p = dict(sim.params, tau_v=0.2834, tau_m=0.1977, omega_w=0.3)
    y, J = lik.jacobian(p)
    assert np.array_equal(np.isfinite(J), np.ones_like(J, bool))
    np.testing.assert_allclose(y, lik.response(p), rtol=0, atol=1e-12 * np.std(y))
    for j, name in enumerate(model.parameter_names):
        h = 1e-6 * max(abs(p[name]), 1e-3)
        fd = (lik.response(dict(p, **{name: p[name] + h}))
              - lik.response(dict(p, **{name: p[name] - h}))) / (2 * h)
        assert np.max(np.abs(fd - J[:, j])) < 1e-6 * np.max(np.abs(fd)), name


def test_jacobian_refuses_unknown_names(sim):
    with pytest.raises(ValueError, match="unknown parameter"):
        Likelihood(paper_model(), sim.recording).jacobian(sim.params, ["K_x"])


def test_gauss_newton_recovers_truth_without_remnant():
    """F_n = 0: from a 10 % perturbed start, Step II reaches the optimum at the truth.

    The full 81.92 s record is one period of the forcing; the remaining offset
    (<= 0.22 %) is the likelihood's 100 Hz discretisation error.
    """
    s = simulate(task="FT", motion_gain=1.0, seed=0)
    lik = Likelihood(paper_model(), s.recording)
    start = {k: v * (1.1 if k != "delta_abs" else 1.0) for k, v in s.params.items()}
    r = refine(lik, start)
    assert r.neg_log_lik < r.start_neg_log_lik
    assert r.params["delta_abs"] == s.params["delta_abs"]  # held
    from_truth = refine(lik, s.params)
    assert r.neg_log_lik == pytest.approx(from_truth.neg_log_lik, rel=1e-9)
    for k in ("K_v", "T_vl", "tau_v", "K_m", "tau_m", "omega_nm", "zeta_nm"):
        assert r.params[k] == pytest.approx(s.params[k], rel=5e-3), k


def test_scan_minimum_is_the_grid_argmin(sim):
    lik = Likelihood(paper_model(), sim.recording)
    sc = scan_parameter(lik, sim.params, step=5e-4)
    assert sc.grid.size == 201 and sc.grid[0] == 0.0 and sc.grid[-1] == pytest.approx(0.1)
    one = [lik.neg_log_lik(dict(sim.params, delta_abs=d)) for d in sc.grid[::40]]
    np.testing.assert_allclose(sc.neg_log_lik[::40], one, rtol=1e-12)
    assert sc.best_neg_log_lik == np.min(sc.neg_log_lik)
    # the minimiser, from a plain loop over the grid: 0.0055 (index 11; the next best, index
    # 12, is 0.23 higher in -ln L), the grid point of the minimum, not a neighbour
    loop = np.array([lik.neg_log_lik(dict(sim.params, delta_abs=d)) for d in sc.grid])
    k = int(np.argmin(loop))
    assert k == 11 and sc.grid[k] == pytest.approx(0.0055, abs=1e-15)
    assert sc.best == sc.grid[k] and sc.best_neg_log_lik == pytest.approx(loop[k], rel=1e-12)
    with pytest.raises(ValueError, match="not a free parameter"):
        scan_parameter(Likelihood(paper_model(threshold=False), sim.recording), sim.params)


def _content_sha256(recording):
    """The recording's content digest, written out here (hashlib alone): the sha256 of the
    hex sha256 of its signals (sorted names, float64 bytes), then of (fs, K_theta)."""
    import hashlib

    inner = hashlib.sha256()
    for name in sorted(recording.signals):
        inner.update(name.encode())
        inner.update(np.asarray(recording.signals[name], dtype=np.float64).tobytes())
    outer = hashlib.sha256(inner.hexdigest().encode())
    outer.update(repr((float(recording.sample_rate_hz), float(recording.motion_gain))).encode())
    return outer.hexdigest()


def test_fast_fit_recovers_threshold_and_is_never_worse_with_it(sim):
    with_t = fit_fast(sim.recording, seed=0, n_starts=3, profile_step=0.005)
    without = fit_fast(sim.recording, seed=0, n_starts=3, threshold=False)
    assert with_t.neg_log_lik <= without.neg_log_lik + 1e-9
    assert without.params["delta_abs"] == 0.0 and not without.threshold
    assert with_t.params["delta_abs"] == pytest.approx(0.0075, abs=0.003)
    # the 30-s record is not whole periods of the forcing: the fit leaves its start-up out
    assert with_t.settings["discard"] == 2.0
    # outputs audit 4.3: which recording, by content (the digest sample and compare record)
    assert with_t.settings["recording_sha256"] == _content_sha256(sim.recording)
    lik = Likelihood(paper_model(), sim.recording, discard=with_t.settings["discard"])
    # on 30 s of data K_v and the motion channel trade off; the optimum is at least the truth's
    assert with_t.neg_log_lik <= lik.neg_log_lik(sim.params)
    assert lik.neg_log_lik(with_t.params) == pytest.approx(with_t.neg_log_lik, rel=1e-12)


def test_fast_fit_profile_grid_ends_at_the_bound(sim):
    """A profile step that does not divide delta_abs's range ends the grid at the bound (the
    grid went on to 0.12, beyond the 0.1 bound); every profile point's fit is within it."""
    f = fit_fast(sim.recording, seed=0, n_starts=1, profile_step=0.06)
    assert f.steps["profile_grid"] == pytest.approx([0.0, 0.06, 0.1], abs=1e-15)
    assert 0.0 <= f.params["delta_abs"] <= 0.1


def test_paper_fit_small_is_reproducible_and_serialises(sim, tmp_path):
    kw = dict(seed=4, repetitions=3, n_best=2, population=40, generations=15)
    a = fit_paper(sim.recording, **kw)
    b = fit_paper(sim.recording, **kw)
    assert a.params == b.params and a.neg_log_lik == b.neg_log_lik
    assert a.settings["recording_sha256"] == _content_sha256(sim.recording)
    steps = a.steps
    assert len(steps["step1"]["runs"]) == 3 and len(steps["step2"]) == 3
    # Step I delta_abs: mean of the 2 best GA runs
    runs = steps["step1"]["runs"]
    funs = [r["fun"] for r in runs]
    best2 = np.argsort(funs)[:2]
    names = paper_model().parameter_names
    assert steps["step1_delta_abs"] == pytest.approx(
        np.mean([runs[i]["x"][names.index("delta_abs")] for i in best2]))
    # Step II held delta_abs at that value; Step III scanned it
    assert all(r["params"]["delta_abs"] == steps["step1_delta_abs"] for r in steps["step2"])
    assert a.params["delta_abs"] == steps["step3"][0]["best"]
    # ... at the minimiser of the scan's own grid, and -ln L there is the fit's, recomputed
    scan = steps["step3"][0]
    nll = np.array([np.inf if v is None else v for v in scan["neg_log_lik"]])
    assert a.params["delta_abs"] == scan["grid"][int(np.argmin(nll))]
    lik = Likelihood(paper_model(), sim.recording, discard=a.settings["discard"])
    assert lik.neg_log_lik(a.params) == pytest.approx(a.neg_log_lik, rel=1e-12)
    assert a.neg_log_lik <= min(r["neg_log_lik"] for r in steps["step2"]) + 1e-9
    path = a.to_json(tmp_path / "fit.json")
    back = FitResult.from_json(path)
    assert back.params == a.params and back.neg_log_lik == a.neg_log_lik
    assert "K_v" in a.summary() and "-ln L" in a.summary()
    # Figs. 6-9 from the fit and from its JSON copy: the plotted points are the steps' numbers
    import matplotlib.pyplot as plt

    from bayespilot.fit.figures import (plot_ga_convergence, plot_step_one_thresholds,
                                        plot_step_three, plot_step_two)

    fig = plot_step_two([a, back], labels=["a", "back"])
    assert len(fig.axes) == 2
    for ax in fig.axes:
        grey, black = ax.get_lines()[:2]
        np.testing.assert_allclose(grey.get_ydata(), funs)
        np.testing.assert_allclose(black.get_ydata(), [r["neg_log_lik"] for r in steps["step2"]])
    fig3 = plot_step_three([back])
    xs = np.concatenate([ln.get_xdata() for ln in fig3.axes[0].get_lines()])
    assert a.params["delta_abs"] in xs
    for f in (fig, fig3, plot_step_one_thresholds([a]), plot_ga_convergence([a])):
        plt.close(f)
    for plot in (plot_step_two, plot_step_three):
        with pytest.raises(ValueError, match="no fits"):
            plot([])
    for plot in (plot_step_two, plot_step_three, plot_ga_convergence):
        with pytest.raises(ValueError, match="1 labels for 2 fits"):
            plot([a, back], labels=["a"])


def test_iterated_steps_two_and_three_reach_the_optimum_the_single_pass_misses():
    """F_n = 0, FD, K_theta = 1 (the full record): a small GA leaves Step I far off
    (delta_abs 0.08); one pass of Steps II-III stops near it, the iterated passes
    end within one scan step (1e-4 IPUT) of the truth, at the -ln L that
    Gauss-Newton from the truth reaches with delta_abs held at that grid value.
    (The remnant-free likelihood is so sharp that one grid step costs thousands
    of units: the scan's resolution, not the iteration, limits it there.)"""
    s = simulate(task="FD", motion_gain=1.0, seed=0)
    kw = dict(seed=0, repetitions=3, n_best=2, population=40, generations=15)
    one = fit_paper(s.recording, **kw)
    it = fit_paper(s.recording, iterate=True, **kw)
    assert one.steps["step1_delta_abs"] > 0.05 and one.params["delta_abs"] > 0.05
    assert it.steps["iterations_converged"] is True and len(it.steps["iterations"]) > 5
    assert it.params["delta_abs"] == pytest.approx(0.0075, abs=1.5e-4)
    lik = Likelihood(paper_model(), s.recording)
    at_truth = refine(lik, dict(s.params, delta_abs=it.params["delta_abs"]),
                      hold=("delta_abs",)).neg_log_lik
    assert it.neg_log_lik <= at_truth + 1.0
    assert one.neg_log_lik > at_truth + 1e4  # tens of thousands of units short
    fun = [r["neg_log_lik"] for r in it.steps["iterations"]]
    assert all(b <= a + 1e-6 for a, b in zip(fun, fun[1:]))
    # Fig. 9 of the last pass marks the final delta_abs; the first pass's (the default) does not
    import matplotlib.pyplot as plt

    from bayespilot.fit.figures import plot_step_three
    for scan, want in ((-1, it.params["delta_abs"]), (0, it.steps["step3"][0]["best"])):
        fig = plot_step_three([it], scan=scan)
        (filled,) = [ln for ln in fig.axes[0].get_lines() if ln.get_label() == "Step III"]
        assert filled.get_xdata()[0] == want
        plt.close(fig)
    assert it.steps["step3"][0]["best"] > 0.05
    for bad in (len(it.steps["step3"]), True, 0.0):
        with pytest.raises(ValueError, match="scan"):
            plot_step_three([it], scan=bad)
    with pytest.warns(RuntimeWarning, match="raise max_iterations"):
        short = fit_paper(s.recording, iterate=True, max_iterations=3, **kw)
    assert short.steps["iterations_converged"] is False


def test_paper_fit_without_threshold_has_no_step_three(sim):
    f = fit_paper(sim.recording, threshold=False, seed=1, repetitions=2, n_best=1,
                  population=20, generations=5)
    assert f.params["delta_abs"] == 0.0 and f.steps["step3"] == []


def test_fit_rejects_bad_settings(sim):
    with pytest.raises(ValueError, match="n_best"):
        fit_paper(sim.recording, repetitions=2, n_best=3)
    with pytest.raises(TypeError, match="Recording"):
        fit_paper("not a recording")
    with pytest.raises(ValueError, match="n_starts"):
        fit_fast(sim.recording, n_starts=0)
    with pytest.raises(ValueError, match="noise_order is the order of the AR model"):
        fit_fast(sim.recording, noise_order=3)  # was ignored


def test_fits_take_only_a_bool_for_threshold(sim):
    """threshold="no" was taken for its truth value: a fit WITH a threshold.  Refused by both
    fitters as fit_paper refuses such an iterate, before any fitting."""
    for fit in (fit_fast, fit_paper):
        for bad in ("no", "False", 0, None):
            with pytest.raises(ValueError, match=f"threshold must be True or False, got "
                                                 f"{re.escape(repr(bad))}"):
                fit(sim.recording, threshold=bad, seed=0)
    f = fit_fast(sim.recording, threshold=np.bool_(False), seed=0, n_starts=1)
    assert f.threshold is False and f.params["delta_abs"] == 0.0


def test_fits_check_discard_and_the_grid_steps_before_fitting(sim):
    """discard beyond the record got a RecordingError about 0 samples, not the likelihood's
    range error that discard=-1 gets; a scan_step or profile_step beyond delta_abs's range
    (0.1) was accepted and scanned delta_abs = 0 only (fit_paper reported 0.0)."""
    half = r"discard must be a number of seconds in \[0, 15\] \(half the record\), got "
    for fit in (fit_fast, fit_paper):
        for bad in (100, -1, 15.5, float("nan"), True, "2"):
            with pytest.raises(ValueError, match=half + re.escape(repr(bad))):
                fit(sim.recording, discard=bad, seed=0)
        with pytest.raises(ValueError, match=r"scan_step must not exceed the range of "
                                             r"delta_abs's bounds \(\[0, 0.1\]: 0.1\), got 1.0"):
            fit(sim.recording, scan_step=1.0, seed=0)
        for bad in (0, -1e-4, float("nan"), "1e-4"):
            with pytest.raises(ValueError, match=f"scan_step must be a positive number, got "
                                                 f"{re.escape(repr(bad))}"):
                fit(sim.recording, scan_step=bad, seed=0)
    with pytest.raises(ValueError, match=r"profile_step must not exceed the range of delta_abs's "
                                         r"bounds \(\[0, 0.1\]: 0.1\), got 0.25"):
        fit_fast(sim.recording, profile_step=0.25, seed=0)
    with pytest.raises(ValueError, match=r"scan_step must not exceed profile_step \(0.01\), "
                                         r"got 0.02: the final scan refines"):
        fit_fast(sim.recording, profile_step=0.01, scan_step=0.02, seed=0)
    # a custom model's bounds: the range is its own
    import dataclasses

    m = paper_model()
    narrow = dataclasses.replace(m, parameters=tuple(
        dataclasses.replace(p, upper=0.02, default=0.01) if p.name == "delta_abs" else p
        for p in m.parameters))
    with pytest.raises(ValueError, match=r"\(\[0, 0.02\]: 0.02\), got 0.03"):
        fit_fast(sim.recording, narrow, profile_step=0.03, seed=0)
    # the whole range is still a step
    f = fit_fast(sim.recording, seed=0, n_starts=1, profile_step=0.1, scan_step=0.1)
    assert f.steps["profile_grid"] == [0.0, 0.1]


def _small_fit(**kw):
    d = dict(params={"K_v": 1.5, "delta_abs": 0.01}, neg_log_lik=-100.0, vaf=90.0,
             method="fast", seed=0, threshold=True,
             settings={"n_starts": 1, "noise": None, "unidentified": ["K_m"]},
             steps={"scan": {"grid": [0.0, 0.01], "best": 0.01}, "starts": [{"x": [1.0]}]},
             elapsed=1.0, source="run", bounds={"K_v": (0.0, 10.0), "delta_abs": (0.0, 0.1)},
             units={"K_v": "-", "delta_abs": "IPUT"})
    d.update(kw)
    return FitResult(**d)


def test_a_fit_result_cannot_be_changed_in_place(tmp_path):
    """fit.params["K_v"] = 999 changed the fit: to_json saved 999 and from_json then reported
    K_v beyond its bound.  Its dicts (and the lists in them) refuse, at every depth, through
    every way a fit is made again (JSON, pickle, deepcopy, dataclasses.replace); copies of
    them are the caller's to edit."""
    import copy
    import dataclasses
    import pickle

    said = r"cannot be changed in place: copy them \(dict\(fit.params\), fit.to_dict\(\)\)"
    src = {"n_starts": 1, "noise": None, "unidentified": ["K_m"]}
    fit = _small_fit(settings=src)
    src["n_starts"] = 2
    src["unidentified"].append("tau_m")  # the caller's dict, not the fit's
    assert fit.settings == {"n_starts": 1, "noise": None, "unidentified": ["K_m"]}
    path = tmp_path / "f.json"
    fit.to_json(path)
    back = FitResult.from_json(path)
    again = dataclasses.replace(fit, params={"K_v": 2.0, "delta_abs": 0.0})
    assert again.params == {"K_v": 2.0, "delta_abs": 0.0} and fit.params["K_v"] == 1.5
    for f in (fit, back, pickle.loads(pickle.dumps(fit)), copy.deepcopy(fit), copy.copy(fit),
              again, FitResult.from_dict(fit.to_dict())):
        for change in (lambda: f.params.__setitem__("K_v", 999.0),
                       lambda: f.params.update(K_v=999.0),
                       lambda: f.params.pop("K_v"),
                       lambda: f.settings.setdefault("extra", 1),
                       lambda: f.settings["unidentified"].append("K_v"),
                       lambda: f.steps["scan"].__setitem__("best", 0.05),
                       lambda: f.steps["scan"]["grid"].__setitem__(0, 1.0),
                       lambda: f.steps["starts"][0]["x"].append(2.0),
                       lambda: f.bounds.__setitem__("K_v", (0.0, 100.0)),
                       lambda: f.units.clear()):
            with pytest.raises(TypeError, match=said):
                change()
        assert f.params == {"K_v": 1.5, "delta_abs": 0.01} or f is again
        assert f.steps["scan"] == {"grid": [0.0, 0.01], "best": 0.01}
        assert f.bounds["K_v"] == (0.0, 10.0) and f.units["K_v"] == "-"
    assert json.loads(path.read_text())["params"]["K_v"] == 1.5 and back.at_bounds == {}
    # copies are plain and editable, at every depth, and leave the fit alone
    mine = dict(fit.params)
    mine["K_v"] = 999.0
    d = fit.to_dict()
    d["params"]["K_v"] = 3.0
    d["settings"]["unidentified"].append("K_v")
    d["steps"]["scan"]["grid"][0] = 1.0
    d["bounds"]["K_v"][1] = 100.0
    d["units"]["K_v"] = "deg"
    deep = copy.deepcopy(fit.steps)
    deep["starts"][0]["x"].append(2.0)
    assert type(deep["starts"]) is list and type(deep["starts"][0]) is dict
    assert fit.params["K_v"] == 1.5 and fit.settings["unidentified"] == ["K_m"]
    assert fit.steps["scan"]["grid"] == [0.0, 0.01] and fit.steps["starts"][0]["x"] == [1.0]
    written = json.loads(path.read_text())
    assert written.pop("bayespilot_version") == bayespilot.__version__
    assert fit.to_dict() == FitResult.from_dict(fit.to_dict()).to_dict() == written
    # the read-only dicts are still dicts: JSON, ** and comparison as before
    assert isinstance(fit.params, dict) and dict(**fit.params) == fit.params
    assert json.loads(json.dumps(fit.steps)) == {"scan": {"grid": [0.0, 0.01], "best": 0.01},
                                                 "starts": [{"x": [1.0]}]}


def test_from_dict_names_a_value_that_is_not_a_number(tmp_path):
    """A bad number raised "could not convert string to float: 'abc'" without saying where."""
    good = _small_fit().to_dict()
    for key, value, said in (
            ("params", {"K_v": "abc"}, r"params\['K_v'\] is 'abc', not a number \(or null\)"),
            ("neg_log_lik", "x", r"neg_log_lik is 'x', not a number"),
            ("vaf", [1], r"vaf is \[1\], not a number"),
            ("elapsed_seconds", {}, r"elapsed_seconds is \{\}, not a number"),
            ("bounds", {"K_v": [0, "ten"]}, r"bounds\['K_v'\]\[1\] is 'ten', not a number"),
            ("bounds", {"K_v": 10}, r"bounds\['K_v'\] is 10, not \[lower, upper\]"),
            ("params", None, r"params is null, not an object of name: value"),
            ("units", ["-"], r"units is a list, not an object of name: value")):
        d = dict(good, **{key: value})
        with pytest.raises(ValueError, match="^not a fit result: " + said):
            FitResult.from_dict(d)
        path = tmp_path / "bad.json"
        path.write_text(json.dumps(d))
        with pytest.raises(ValueError, match=re.escape(f"{path}: not a fit result: ") + said):
            FitResult.from_json(path)
    # null is NaN, as written for a non-finite number
    assert np.isnan(FitResult.from_dict(dict(good, vaf=None)).vaf)


def test_fits_refuse_a_recording_with_nothing_to_fit(sim):
    """Too few samples for the parameters, or a constant u: refused before fitting (they gave
    -ln L = inf or a VAF of -inf without a word)."""
    from bayespilot.recording import Recording

    rec = sim.recording
    short = Recording({k: v[:32] for k, v in rec.signals.items()}, rec.sample_rate_hz, 1.0)
    for fit in (fit_fast, fit_paper):
        with pytest.raises(ValueError, match="32 samples; a fit of 8 parameters needs more "
                                             "than 32"):
            fit(short, seed=0)
    with pytest.raises(ValueError, match="7 parameters needs more than 28"):
        fit_fast(Recording({k: v[:28] for k, v in rec.signals.items()}, rec.sample_rate_hz, 1.0),
                 threshold=False)
    with pytest.raises(ValueError, match=r"u is constant \(0\): there is nothing to fit"):
        fit_fast(rec.with_signals(u=np.zeros(rec.n_samples)), seed=0, discard=0.0)
    cut = rec.with_signals(u=np.concatenate([rec.u[:300], np.full(rec.n_samples - 300, 0.5)]))
    with pytest.raises(ValueError, match=r"constant \(0.5\) after the first 4 s"):
        fit_fast(cut, seed=0, noise="ar", discard=4.0)
    # None: as fit_fast, 2 s on this 30-s record cut mid-period (0 on whole periods)
    small = dict(seed=0, repetitions=1, n_best=1, generations=2, population=10)
    assert fit_paper(rec, discard=None, **small).settings["discard"] == 2.0
    assert fit_paper(rec, **small).settings["discard_reason"] == fit_fast(
        rec, seed=0, n_starts=1, profile_step=0.05).settings["discard_reason"]


def test_cli_fit_json(sim, tmp_path, capsys):
    write_recording(sim.recording, tmp_path / "run")
    out = tmp_path / "fit.json"
    code = main(["fit", str(tmp_path / "run"), "--method", "fast", "--seed", "3", "--json",
                 str(out), "-q"])
    assert code == 0
    d = json.loads(out.read_text())
    assert set(d["params"]) == set(paper_model().parameter_names)
    assert d["method"] == "fast" and d["seed"] == 3
    assert np.isfinite(d["neg_log_lik"]) and 0 < d["vaf"] <= 100
    assert d["settings"]["recording_sha256"] == _content_sha256(read_recording(tmp_path / "run"))
    assert main(["fit", str(tmp_path / "missing")]) == 2


def test_fast_prediction_error_fit(sim):
    """noise="ar": the AR model is the BIC fit of the final residual; -ln L is that whitened
    likelihood at the returned parameters; the threshold is still found."""
    from bayespilot.noise import ARNoise

    f = fit_fast(sim.recording, seed=0, n_starts=3, profile_step=0.005, noise="ar", discard=2.0)
    nz = f.settings["noise"]
    assert nz["kind"] == "ar" and nz["order"] >= 1 and f.settings["discard"] == 2.0
    lik = Likelihood(paper_model(), sim.recording, discard=2.0, noise=ARNoise(nz["a"]))
    assert lik.neg_log_lik(f.params) == pytest.approx(f.neg_log_lik, rel=1e-12)
    assert f.params["delta_abs"] == pytest.approx(0.0075, abs=0.003)
    # the AR model was re-estimated at the refined parameters' starting point (the profile's
    # best), so re-estimating it at the final parameters changes it little
    white = Likelihood(paper_model(), sim.recording, discard=2.0)
    again = ARNoise.from_residual(white.residual(f.params)[white.used], order=len(nz["a"]))
    assert np.max(np.abs(again.a - np.array(nz["a"]))) < 0.05
    with pytest.raises(ValueError, match="noise must be"):
        fit_fast(sim.recording, noise="pink")
    with pytest.raises(ValueError, match="noise_order"):
        fit_fast(sim.recording, noise="ar", noise_order=-1)


def test_prediction_error_fit_leaves_the_start_out_by_default():
    """noise="ar" without discard leaves 2 s out (likelihood.coloured_discard: min(2 s, a quarter
    of the record)), as sample, compare and the CLI do:
    from 0 s the whitened start-up transient drew this full FD run's fit to T_vl 0.007 and
    tau_v 0.030 (truth 0.409, 0.279); the white fit still leaves nothing out."""
    rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=1).recording
    f = fit_fast(rec, seed=0, n_starts=4, profile_step=0.01, noise="ar")
    assert f.settings["discard"] == 2.0
    assert f.params["T_vl"] == pytest.approx(0.409, rel=0.1)
    assert f.params["tau_v"] == pytest.approx(0.279, rel=0.1)
    assert fit_fast(rec, seed=0, n_starts=1, threshold=False).settings["discard"] == 0.0
    # a record shorter than 8 s: a quarter of it (2 s of 2.5 was refused as over half)
    short = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=1,
                     duration=2.5).recording
    f = fit_fast(short, seed=0, n_starts=1, profile_step=0.05, noise="ar", noise_order=2)
    assert f.settings["discard"] == 0.625


def test_cli_fit_prediction_error(sim, tmp_path, capsys):
    write_recording(sim.recording, tmp_path / "run")
    out = tmp_path / "pem.json"
    assert main(["fit", str(tmp_path / "run"), "--method", "fast", "--noise", "ar", "--json",
                 str(out), "-q"]) == 0
    assert json.loads(out.read_text())["settings"]["noise"]["kind"] == "ar"
    assert main(["fit", str(tmp_path / "run"), "--noise", "ar"]) == 2  # not with --method paper
    assert "--method fast" in capsys.readouterr().err


def test_summary_labels_the_whitened_neg_log_lik():
    """A fit with a noise model (settings["noise"]) has the -ln L of its whitened residual, not
    comparable with Eq. 4's: its summary says so on the -ln L line (an audit: the line read as
    Eq. 4's); a fit without one keeps the plain label."""
    from bayespilot.presets import paper_parameters

    params = dict(paper_parameters("FD"))
    noise = {"kind": "ar", "order": 1, "a": [0.5]}
    pem = FitResult(params, -123.456, 80.0, "fast", 0, True, {"noise": noise, "discard": 2.0})
    white = FitResult(params, -123.456, 80.0, "fast", 0, True, {"noise": None})
    (line,) = [ln for ln in pem.summary().splitlines() if "VAF = " in ln]
    assert line.startswith("-ln L (AR-whitened residual) = -123.456   VAF = 80.00 %")
    (line,) = [ln for ln in white.summary().splitlines() if "VAF = " in ln]
    assert line.startswith("-ln L = -123.456   VAF = 80.00 %")
    assert "whitened" not in white.summary()


def test_paper_fit_takes_only_a_bool_for_iterate(sim):
    """iterate="False" (what --fit-option iterate=False used to pass) is refused, not taken
    for its truth value (True: the iterated procedure)."""
    small = dict(seed=0, repetitions=1, n_best=1, population=4, generations=1)
    for bad in ("False", "true", 0, 1, None):
        with pytest.raises(ValueError, match="iterate must be True or False"):
            fit_paper(sim.recording, iterate=bad, **small)
    f = fit_paper(sim.recording, iterate=np.bool_(False), **small)
    assert f.settings["iterate"] is False and f.steps["iterations"] == []
    assert f.steps["iterations_converged"] is None and len(f.steps["step3"]) == 1


def test_cli_fit_of_a_short_record(sim, tmp_path, capsys):
    """--noise ar leaves 2 s out, a quarter of a record under 8 s, as fit_fast does (a 3-s
    record was refused); a record too short for any fit is a usage error naming it and the
    samples needed (not 'unexpected ValueError ... please report it')."""
    short = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.15, seed=21, duration=3.0)
    write_recording(short.recording, tmp_path / "short")
    code = main(["fit", str(tmp_path / "short"), "--method", "fast", "--noise", "ar", "-q",
                 "--json", str(tmp_path / "f.json")])
    assert code == 0, capsys.readouterr().err
    assert json.loads((tmp_path / "f.json").read_text())["settings"]["discard"] == 0.75
    tiny = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.15, seed=21, duration=0.3)
    write_recording(tiny.recording, tmp_path / "tiny")
    for extra in (["--method", "fast", "--noise", "ar"], ["--method", "paper"]):
        code = main(["fit", str(tmp_path / "tiny"), *extra, "-q"])
        err = capsys.readouterr().err
        assert code == 2, err
        (line,) = [ln for ln in err.splitlines() if ln.startswith("bayespilot: error:")]
        assert "a fit of 8 parameters needs more than 32" in line
        assert "unexpected" not in err and "report it" not in err


def test_a_threshold_of_another_name_is_fitted_with_a_warning(sim):
    """The fitters scan only a threshold named delta_abs: a dead zone named otherwise is fitted
    as an ordinary parameter (K_m 1.03 against 0.55, -ln L 313 worse in an audit), so both
    fitters say so, at the user's line, before they fit."""
    import warnings

    from bayespilot.model import DeadZone

    renamed = paper_model().with_nonlinearity(
        "vestibular", DeadZone("delta_pitch"), [Parameter("delta_pitch", 0.0, 0.1, 0.0075)])
    assert "delta_abs" not in renamed.all_names and renamed.has_threshold
    for fit in (fit_fast, fit_paper):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("error", UserWarning)  # stops the fit at the warning
            with pytest.raises(UserWarning, match="delta_pitch is fitted as an ordinary"):
                fit(sim.recording, renamed, seed=0)
        assert not caught
    from bayespilot.fit.three_step import _warn_unnamed_threshold

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _warn_unnamed_threshold(renamed)
        _warn_unnamed_threshold(paper_model())  # the paper's threshold and a fixed one: silent
        _warn_unnamed_threshold(renamed.fix(delta_pitch=0.0))
    assert [w.filename for w in caught] == [__file__]


@pytest.fixture(scope="module")
def in_degrees(sim):
    """The fixture's run with u in degrees instead of radians: the Table 1 box holds K_v to 10
    (about 57 times the 0.97 the run needs)."""
    return sim.recording.with_signals(u=np.degrees(sim.recording.u))


def test_an_estimate_on_a_bound_is_flagged_and_warned_once(sim, in_degrees, tmp_path):
    """u in degrees: fit_fast stopped K_v on its upper bound 10 and moved the others to make
    up for it (an audit: delta_abs 0, tau_m 0.87, VAF 72 against 81 %) without a word.  Now
    the result names the parameter (at_bounds, kept through JSON), the summary marks it, and
    the fit warns once, at the user's line, of the bound and of the units."""
    import warnings

    from bayespilot.fit.result import EstimateOnBoundWarning

    kw = dict(seed=0, n_starts=4, profile_step=0.01)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit = fit_fast(in_degrees, **kw)
    bound = [w for w in caught if issubclass(w.category, EstimateOnBoundWarning)]
    assert len(bound) == 1 and bound[0].filename == __file__
    text = str(bound[0].message)
    assert "K_v = 10 on its upper bound (10)" in text and "delta_abs" not in text
    assert "Table 1" in text and "units" in text
    assert fit.params["K_v"] == pytest.approx(10.0, rel=1e-9)
    assert fit.at_bounds["K_v"] == "upper"
    assert fit.bounds["K_v"] == (0.0, 10.0) and fit.units["K_m"] == "rad/IPUT"
    lines = fit.summary().splitlines()
    (kv,) = [ln for ln in lines if ln.startswith("K_v ")]
    assert kv.split()[1] == "10*"
    assert any(ln.startswith("* on a bound of the search box: K_v (upper 10)") for ln in lines)
    assert "may not suit the recording's units" in fit.summary()
    back = FitResult.from_json(fit.to_json(tmp_path / "fit.json"))
    assert back.at_bounds == fit.at_bounds and back.bounds == fit.bounds
    assert back.summary() == fit.summary()
    # a fit saved before the bounds were kept: the paper's model has Table 1's
    old = {k: v for k, v in fit.to_dict().items() if k not in ("bounds", "units")}
    assert FitResult.from_dict(old).at_bounds == fit.at_bounds
    assert FitResult.from_dict(dict(old, settings={"model": "my lab"})).at_bounds == {}
    # in radians nothing is on a bound but (perhaps) delta_abs = 0, the answer "no threshold"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        good = fit_fast(sim.recording, **kw)
        nothr = fit_fast(sim.recording, threshold=False, **kw)
    assert not [w for w in caught if issubclass(w.category, EstimateOnBoundWarning)]
    assert set(good.at_bounds) <= {"delta_abs"} and nothr.at_bounds == {}
    assert nothr.fixed == ("delta_abs",) and "delta_abs" not in nothr.bounds
    # delta_abs = 0 is marked, named as "no threshold", and not warned of
    zero = FitResult.from_dict(dict(good.to_dict(), params=dict(good.params, delta_abs=0.0)))
    assert zero.at_bounds == {"delta_abs": "lower"}
    assert "delta_abs (lower 0: no threshold)" in zero.summary()
    assert "may not suit" not in zero.summary()
    # the paper's Step II is unconstrained: an estimate past a bound counts, said as such
    past = FitResult.from_dict(dict(good.to_dict(), params=dict(good.params, tau_m=-1.0)))
    assert past.at_bounds["tau_m"] == "lower" and "tau_m (beyond lower 0)" in past.summary()


def test_the_bound_warning_is_for_the_users_call_not_the_packages_loops(in_degrees):
    """The package's own callers (diagnose, compare, campaigns, the calibration replicates,
    the example, the command line) fit in loops and keep the flag to the result: a fit called
    from a file of the package does not warn; fit_paper warns as fit_fast does."""
    import warnings

    from bayespilot._caller import _PACKAGE
    from bayespilot.fit.result import EstimateOnBoundWarning

    ns: dict = {}
    exec(compile("def call(f, *a, **k):\n    return f(*a, **k)\n",
                 str(_PACKAGE / "campaign.py"), "exec"), ns)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        inner = ns["call"](fit_fast, in_degrees, seed=0, n_starts=4, profile_step=0.01)
    assert inner.at_bounds.get("K_v") == "upper"
    assert not [w for w in caught if issubclass(w.category, EstimateOnBoundWarning)]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        paper = fit_paper(in_degrees, seed=0, repetitions=2, n_best=1, population=20,
                          generations=5)
    assert paper.at_bounds.get("K_v") == "upper"
    bound = [w for w in caught if issubclass(w.category, EstimateOnBoundWarning)]
    assert len(bound) == 1 and bound[0].filename == __file__ and "K_v" in str(bound[0].message)


def test_summary_and_labels_take_the_units_of_the_models_parameters(sim):
    """A parameter of the user's own (here a visual lag in s) printed a blank unit, and only
    delta_abs was ever marked (fixed): the summary and the plots' labels now take the units
    the model declares, and every fixed parameter is marked."""
    import warnings

    from bayespilot.model import FirstOrderLag
    from bayespilot.plots import _param_label

    model = paper_model().add_stage("visual", FirstOrderLag("T_vis"), [
        Parameter("T_vis", 0.0, 0.5, 0.05, "s", "visual lag")]).fix(zeta_nm=0.3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = fit_fast(sim.recording, model, threshold=False, seed=0, n_starts=2)
    rows = {ln.split()[0]: ln for ln in fit.summary().splitlines()[3:-1] if ln[:1].isalpha()}
    assert rows["T_vis"].split()[2] == "s" and rows["K_m"].split()[2] == "rad/IPUT"
    assert rows["zeta_nm"].endswith("(fixed)") and rows["delta_abs"].endswith("(fixed)")
    assert not rows["K_v"].endswith("(fixed)")
    assert fit.fixed == ("zeta_nm", "delta_abs") and "T_vis" in fit.bounds
    back = FitResult.from_dict(fit.to_dict())
    assert back.summary() == fit.summary()
    assert _param_label("T_vis", back) == _param_label("T_vis", model) != _param_label("T_vis")
    assert "(s)" in _param_label("T_vis", back)
    # without units recorded (an older file) the paper's parameters keep Table 1's
    old = FitResult.from_dict({k: v for k, v in fit.to_dict().items() if k != "units"})
    assert "rad/IPUT" in old.summary()


def test_an_offset_in_u_is_warned_of_before_fitting(sim):
    """The model takes u as zero-mean about the trim: +0.02 rad on u moved delta_abs 0.0097 ->
    0.0148 and K_m 0.60 -> 0.67 in an audit while the VAF (about the mean) hid it.  A mean of
    u that is a sizeable fraction of its spread is warned of, at the user's line, before the
    fit; the package's own runs stay silent."""
    import warnings

    from bayespilot.fit.three_step import OFFSET_RATIO, _check_fittable
    from bayespilot.recording import QuestionableRecordingWarning

    rec = sim.recording
    shifted = rec.with_signals(u=rec.u + 0.02)  # |mean|/std 0.54-0.56
    for fit in (fit_fast, fit_paper):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("error", QuestionableRecordingWarning)  # stops the fit
            with pytest.raises(QuestionableRecordingWarning,
                               match=r"u has a mean of 0.02\d*, 0.5\d of its standard "
                                     r"deviation .*zero-mean.*remove the stick offset"):
                fit(shifted, seed=0)
        assert not caught
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _check_fittable(rec, paper_model(), 0.0)
        _check_fittable(rec.with_signals(u=rec.u + 0.5 * OFFSET_RATIO * rec.u.std()),
                        paper_model(), 0.0)
        _check_fittable(shifted, paper_model(), 2.0)
    assert len(caught) == 1 and "after the first 2 s" in str(caught[0].message)
    assert caught[0].filename == __file__


def test_a_paper_fit_that_stops_short_of_the_maximum_says_so(tmp_path):
    """FD, F_n = 0.2, seed 3: the paper's single pass ended at delta_abs 0.0386, -ln L 635
    above the maximum the fast method finds (0.0076), without a word.  Gauss-Newton with
    delta_abs free from the pass's result reaches that maximum; the fit keeps the paper's
    estimate, records the check and warns, and its summary says so.  Iterated, no warning."""
    import warnings

    from bayespilot.fit.result import CHECK_GAP, NotAtMaximumWarning

    rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=3).recording
    with pytest.warns(NotAtMaximumWarning, match=r"stopped 63\d\.\d short") as got:
        fit = fit_paper(rec, seed=0)
    assert got[0].filename == __file__
    assert fit.params["delta_abs"] == pytest.approx(0.0386, abs=1e-4)  # the paper's, kept
    check = fit.steps["check"]
    fast = fit_fast(rec, seed=0)
    assert check["neg_log_lik"] == pytest.approx(fast.neg_log_lik, abs=1.0)
    assert check["params"]["delta_abs"] == pytest.approx(fast.params["delta_abs"], abs=5e-4)
    assert check["gap"] == pytest.approx(fit.neg_log_lik - check["neg_log_lik"], rel=1e-12)
    lik = Likelihood(paper_model(), rec)
    assert lik.neg_log_lik(check["params"]) == pytest.approx(check["neg_log_lik"], rel=1e-12)
    assert "not at a maximum" in fit.summary()
    back = FitResult.from_json(fit.to_json(tmp_path / "fit.json"))
    assert back.steps["check"]["gap"] == check["gap"] and "not at a maximum" in back.summary()
    with warnings.catch_warnings():
        warnings.simplefilter("error", NotAtMaximumWarning)
        it = fit_paper(rec, seed=0, iterate=True)
    assert it.steps["check"]["gap"] < CHECK_GAP and "not at a maximum" not in it.summary()
    assert fit_paper(rec, seed=0, threshold=False).steps["check"] is None


def test_no_bound_warning_for_a_silent_channels_parameters():
    """A run without motion leaves the motion channel's parameters unidentified (the
    SilentChannelWarning says so): one of them ending on a bound is not the bound warning's
    "the units may not suit" case, and it is not warned of again; it is still marked."""
    import warnings

    from bayespilot.fit.result import EstimateOnBoundWarning
    from bayespilot.likelihood import SilentChannelWarning

    from bayespilot.fit.three_step import _warn_on_bounds

    rec = simulate(task="FD", motion_gain=0.0, remnant_fraction=0.05, seed=2).recording
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit = fit_fast(rec, seed=0, n_starts=2, profile_step=0.05)
    kinds = {w.category for w in caught}
    assert SilentChannelWarning in kinds and EstimateOnBoundWarning not in kinds
    # marked all the same; which of the channel's parameters the optimiser leaves on a bound
    # is arbitrary (nothing identifies them): tau_m on one machine, K_m on another
    motion = set(fit.at_bounds) - {"delta_abs"}
    assert motion and motion <= {"K_m", "tau_m"}, fit.at_bounds
    # the fitter records them as not identified (not only the command line), and its summary
    # marks them instead of the bound
    assert fit.settings["unidentified"] == ["K_m", "tau_m", "delta_abs"]
    assert fit.summary().count("(not identified)") == 3 and "on a bound" not in fit.summary()
    with pytest.warns(EstimateOnBoundWarning, match="|".join(sorted(motion))):
        _warn_on_bounds(fit)  # (without the likelihood, the record's silence unknown)


def test_a_labs_own_threshold_block_is_a_threshold_by_its_declaration(sim):
    """A lab's nonlinearity names its thresholds (``Nonlinearity.thresholds``), in a channel or
    on the output: the model then has a threshold, fit_fast warns that it is not scanned and
    the fit reads "with threshold".  An audit's asymmetric dead zone was "without threshold" and unwarned, since
    only the DeadZone and SoftDeadZone classes were recognised."""
    import warnings
    from dataclasses import dataclass

    from bayespilot.kernels import _blocks as B
    from bayespilot.model import Nonlinearity
    from bayespilot.fit.three_step import _warn_unnamed_threshold

    @dataclass(frozen=True)
    class LabDeadZone(Nonlinearity):  # the kernels' dead zone under a lab's class
        half_width: str = "delta_lab"
        kind = B.NL_DEADZONE

        @property
        def parameters(self):
            return (self.half_width,)

        @property
        def thresholds(self):
            return (self.half_width,)

    @dataclass(frozen=True)
    class Unmarked(LabDeadZone):  # the same block, its threshold not declared
        @property
        def thresholds(self):
            return ()

    par = [Parameter("delta_lab", 0.0, 0.1, 0.0075)]
    lab = paper_model().with_nonlinearity("vestibular", LabDeadZone(), par)
    unmarked = paper_model().with_nonlinearity("vestibular", Unmarked(), par)
    assert lab.has_threshold and not unmarked.has_threshold
    assert not lab.fix(delta_lab=0.0).has_threshold and lab.fix(delta_lab=0.01).has_threshold
    # on the model's output too (the threshold-free paper model plus a dead zone on u)
    on_u = paper_model(threshold=False).with_output(
        LabDeadZone("u_dead"), [Parameter("u_dead", 0.0, 0.1, 0.001)])
    assert on_u.has_threshold and not paper_model(threshold=False).has_threshold
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _warn_unnamed_threshold(unmarked)
        _warn_unnamed_threshold(on_u)
    assert [str(w.message).split(" is fitted")[0] for w in caught] == ["the threshold u_dead"]
    with pytest.warns(UserWarning, match="the threshold delta_lab is fitted as an ordinary"):
        fit = fit_fast(sim.recording, lab, n_starts=2, seed=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        plain = fit_fast(sim.recording, unmarked, n_starts=2, seed=0)
    assert not [w for w in caught if "fitted as an ordinary" in str(w.message)]
    assert fit.threshold and "with threshold" in fit.summary()
    assert not plain.threshold and "without threshold" in plain.summary()
    assert fit.neg_log_lik == plain.neg_log_lik  # the same computation either way


def test_the_fast_fit_finds_a_threshold_ridge_narrower_than_its_grids():
    """Noise-free FD with the motion halved: the likelihood's ridge in delta_abs (truth half
    the paper's, 0.00375, with K_m doubled) is narrower than the profile and scan grids, which
    ended at 0.0046 and K_m 1.108, 15256 in -ln L above the truth (an audit).  The last,
    joint step reaches the truth's -ln L."""
    from bayespilot.presets import paper_parameters
    from bayespilot.recording import Recording

    truth = paper_parameters("FD")
    rec = simulate(params=truth, task="FD", motion_gain=1.0, seed=0, duration=60.0).recording
    half = Recording(dict(rec.signals, theta_ddot_m=rec.signals["theta_ddot_m"] * 0.5),
                     rec.sample_rate_hz, 0.5, rec.task, rec.metadata, "half")
    fit = fit_fast(half, seed=0)
    joint = fit.steps["joint"]
    assert joint["gap"] > 1000
    assert fit.params["delta_abs"] == pytest.approx(0.00375, rel=0.01)
    assert fit.params["K_m"] == pytest.approx(2 * truth["K_m"], rel=0.01)
    lik = Likelihood(paper_model(), half, discard=fit.settings["discard"])
    equivalent = dict(truth, K_m=2 * truth["K_m"], delta_abs=truth["delta_abs"] / 2)
    assert fit.neg_log_lik <= lik.neg_log_lik(equivalent) + 1e-6
    assert fit.neg_log_lik == pytest.approx(joint["neg_log_lik"], rel=1e-12)


def test_joint_refine_refuses_what_is_not_a_fit(sim):
    from bayespilot.fit.gauss_newton import joint_refine

    with pytest.raises(TypeError, match="must be a Likelihood"):
        joint_refine("lik", dict(sim.params), 0.0)
    lik = Likelihood(paper_model(), sim.recording, discard=2.0)
    with pytest.raises(ValueError, match="params lacks T_vl, tau_v"):
        joint_refine(lik, {"K_v": 1.0}, 0.0)
    got = joint_refine(lik, dict(sim.params), lik.neg_log_lik(sim.params))
    # from the truth the joint maximum is no worse, and its gap is the drop to it
    assert got["gap"] == pytest.approx(lik.neg_log_lik(sim.params) - got["neg_log_lik"])
    assert got["neg_log_lik"] == pytest.approx(lik.neg_log_lik(got["params"]), rel=1e-12)


def test_step_two_keeps_its_lowest_refinement_and_step_three_starts_there():
    """Step II refines every GA run and keeps the one with the lowest -ln L (Section III.A);
    Step III scans delta_abs from exactly its parameters.  On this run the first GA run's
    refinement is not the best (with the small test's seed it was, so keeping the first
    passed every test)."""
    sim = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.15, seed=21, duration=30.0)
    a = fit_paper(sim.recording, seed=5, repetitions=3, n_best=2, population=40, generations=15)
    s2 = [r["neg_log_lik"] for r in a.steps["step2"]]
    k = int(np.argmin(s2))
    assert k != 0 and min(s2) < s2[0] - 10  # the choice matters here
    assert a.steps["step2_best"] == k
    best = a.steps["step2"][k]["params"]
    assert ({n: v for n, v in a.params.items() if n != "delta_abs"}
            == {n: v for n, v in best.items() if n != "delta_abs"})

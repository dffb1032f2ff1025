"""compare and diagnose on models and labs unlike the paper's (audit of extending bayespilot).

References are independent of the code under test: the simulator's own signal before the
dead zone (``sim.channels[...]["pre"]``, integrated on a finer step) for the plateau
onset, ``np.quantile``; the maximum-likelihood fit of the paper's linear model
(``fit_fast(threshold=False)``) for the soft threshold's null; a diagnosis of the same
recording with u rescaled (docs/fitting.md) for the widened bounds.
"""

from __future__ import annotations

import dataclasses
import json
import warnings

import numpy as np
import pytest

from bayespilot.compare import compare, plateau_onset, threshold_input_max
from bayespilot.diagnose import BaseFitWarning, DiagnosisResult, Extension, diagnose
from bayespilot.diagnose import catalogue as C
from bayespilot.diagnose.catalogue import get_extension, register_extension
from bayespilot.fit.fast import fit_fast
from bayespilot.forcing import Multisine
from bayespilot.model import Channel, DeadZone, Parameter, PilotModel, Saturation, paper_model
from bayespilot.model import semicircular_canal
from bayespilot.presets import paper_parameters
from bayespilot.simulate import TrackingTask, simulate


# --- compare: the model without threshold (extension finding 2) --------------------------------
def test_compare_soft_threshold_null_is_the_linear_model():
    """The soft dead zone's "without threshold" has no w_soft and fits as the linear model:
    its ML -ln L is fit_fast(threshold=False)'s on the paper's model (was the soft dead zone
    at delta_abs = 0, w_soft free, 300 ln L units better than linear on a crisp threshold)."""
    soft = get_extension("threshold-shape").build(paper_model())
    rec = simulate(task="FD", remnant_fraction=0.1, seed=3, duration=20.48).recording
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lin = fit_fast(rec, paper_model(), threshold=False, seed=0, n_starts=2)
        c = compare(rec, soft, nlive=40, dlogz=1.0, runs=1, seed=0,
                    savage_dickey_samples=False)
    ic = c.information_criteria
    assert "w_soft" not in ic["ml_none"] and "w_soft" in ic["ml_threshold"]
    assert ic["k_none"] == ic["k_threshold"] - 2  # delta_abs and w_soft
    assert ic["neg_log_lik_none"] == pytest.approx(lin.neg_log_lik, abs=0.05)
    assert c.settings["discard_seconds"] == lin.settings["discard"]


# --- compare: the plateau guard (extension finding 5) ------------------------------------------
def _composed():
    """DZ(x) = x - clip(x, delta_abs): a linear motion channel minus a clipped copy."""
    base = paper_model()
    vis = base.channels[0]
    lin = Channel("vest_lin", "theta_ddot_m", delay="tau_m", gain=("K_m",),
                  stages=(semicircular_canal(),), sign=-1.0)
    sat = Channel("vest_sat", "theta_ddot_m", delay="tau_m", gain=("K_m",),
                  stages=(semicircular_canal(),), nonlinearity=Saturation("delta_abs"), sign=1.0)
    return PilotModel((vis, lin, sat), base.parameters, name="composed DZ")


def test_plateau_onset_soft_and_composed_dead_zones():
    """A SoftDeadZone and a composed dead zone on delta_abs have the paper's dead zone's
    input: the simulator's canal output (was None for both)."""
    sim = simulate(task="FD", remnant_fraction=0.05, seed=5)
    pre = np.abs(sim.channels["vestibular"]["pre"])
    rec = sim.recording
    soft = get_extension("threshold-shape").build(paper_model())
    for m in (soft, _composed()):
        assert plateau_onset(m, rec) == pytest.approx(np.quantile(pre, 0.99), rel=2e-3)
        assert threshold_input_max(m, rec) == pytest.approx(pre.max(), rel=2e-3)
    assert plateau_onset(soft, rec) == plateau_onset(paper_model(), rec)


@pytest.mark.parametrize("name, extra", [("motion-washout", {"omega_w": 0.5}),
                                         ("motion-system-dynamics", {"omega_ms": 8.0})])
def test_plateau_onset_after_parametric_stages(name, extra):
    """Behind a washout or a platform the dead zone's input is computed at the given
    parameters: against the simulator's input to its dead zone (was None)."""
    m = get_extension(name).build(paper_model())
    truth = dict(paper_parameters("FD"), **extra)
    sim = simulate(m, truth, task="FD", remnant_fraction=0.05, seed=5)
    pre = np.abs(sim.channels["vestibular"]["pre"])
    onset = plateau_onset(m, sim.recording, params=truth)
    assert onset == pytest.approx(np.quantile(pre, 0.99), rel=2e-3)
    assert threshold_input_max(m, sim.recording, params=truth) == pytest.approx(pre.max(),
                                                                                 rel=2e-3)
    # a washout moves it: the paper's canal output alone is another level
    assert abs(onset - plateau_onset(paper_model(), sim.recording)) > 0.01 * onset
    assert plateau_onset(m, sim.recording) is None  # free stages, no values: not computed


def test_compare_plateau_guard_behind_a_washout():
    """compare computes the guard at its ML point with threshold (was None, silently)."""
    m = get_extension("motion-washout").build(paper_model())
    truth = dict(paper_parameters("FD"), delta_abs=0.03, omega_w=0.5)
    rec = simulate(m, truth, task="FD", remnant_fraction=0.05, seed=1,
                   duration=20.48).recording
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c = compare(rec, m, nlive=40, dlogz=1.0, runs=1, seed=0, savage_dickey_samples=False)
    ml = c.information_criteria["ml_threshold"]
    assert c.settings["plateau_guard"] == "applied"
    assert c.settings["plateau_onset"] == pytest.approx(plateau_onset(m, rec, params=ml),
                                                        rel=1e-12)
    assert c.settings["max_threshold_input"] == pytest.approx(
        threshold_input_max(m, rec, params=ml), rel=1e-12)
    assert c.plateau_probability is not None and 0.0 <= c.plateau_probability <= 1.0
    assert "plateau guard" not in c.summary()


def test_compare_says_when_the_plateau_guard_is_not_applied(monkeypatch):
    """delta_abs read by dead zones on two channels: no one input, so no guard, and the
    result says so (was a silent None); a decision for the threshold, which the guard would
    have weighed, says so in its note (the decision made "threshold" here: on these data it
    is "none", ln BF -7)."""
    import bayespilot.compare as cmp

    monkeypatch.setattr(cmp, "_guarded_decision", lambda *a, **k: ("threshold", ""))
    base = paper_model()
    vis = dataclasses.replace(base.channels[0], nonlinearity=DeadZone("delta_abs"))
    m = PilotModel((vis, base.channels[1]), base.parameters, name="two dead zones")
    rec = simulate(params=dict(paper_parameters("FD"), delta_abs=0.03), task="FD",
                   remnant_fraction=0.05, seed=1, duration=20.48).recording
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c = compare(rec, m, nlive=40, dlogz=1.0, runs=1, seed=0, savage_dickey_samples=False)
    assert c.plateau_probability is None and c.settings["plateau_onset"] is None
    guard = c.settings["plateau_guard"]
    assert guard.startswith("not applied: ") and "2 channels (visual, vestibular)" in guard
    assert f"plateau guard {guard}" in c.summary()
    assert c.decision == "threshold"
    assert c.settings["decision_note"] == f"plateau guard {guard}"
    assert plateau_onset(m, rec) is None
    # both dead zones read delta_abs, which the null holds at 0: nothing else held
    assert c.settings["null_also_zeroes"] == []


def test_the_null_says_how_it_differs_from_delta_abs_at_zero():
    """compare's Savage-Dickey check reads the posterior at delta_abs = 0 of the model with
    threshold: not the null when the null removed a block (a soft dead zone, its w_soft fixed
    too: the check looked for lost free parameters only) or held another threshold at 0 (a
    second dead zone's), and the summary says when the null zeroes more than delta_abs."""
    from bayespilot.compare import Comparison, _null_differences
    from bayespilot.model import SoftDeadZone

    p = paper_model()
    assert _null_differences(p, p.without_threshold()) == ([], [])
    soft = p.with_nonlinearity("vestibular", SoftDeadZone("delta_abs", "w_soft"),
                               [Parameter("w_soft", 1e-5, 0.05, 0.002, "IPUT")])
    fixed = soft.fix(w_soft=0.002)
    assert _null_differences(fixed, fixed.without_threshold()) == (
        ["SoftDeadZone on vestibular"], [])
    two = p.with_nonlinearity("visual", DeadZone("delta_vis"),
                              [Parameter("delta_vis", 0.0, 0.1, 0.0, "rad")])
    assert _null_differences(two, two.without_threshold()) == ([], ["delta_vis"])
    # the summary's line, from the settings a comparison records (the other fields stand-ins)
    import types

    ev = types.SimpleNamespace(log_z=0.0, log_z_err=0.1, settings={"nlive": 40})
    ic = dict(neg_log_lik_threshold=0.0, neg_log_lik_none=0.0, delta_aic=0.0, delta_bic=0.0)
    lines = [Comparison(1.0, 0.1, "none", ev, ev, None, ic, {"null_also_zeroes": zeroed}, 0,
                        1.0, None, None).summary().splitlines() for zeroed in ([], ["delta_vis"])]
    line = ("  the model without threshold also holds delta_vis at 0: ln BF weighs these "
            "thresholds and delta_abs together")
    assert line in lines[1] and lines[0] == [x for x in lines[1] if x != line]


# --- diagnose: another lab's bounds (extension finding 1; outputs 1.2) --------------------------
def _wide_lab():
    """docs/fitting.md's 0.08/s^2 task flown with K_v 15 (outside Table 1's [0, 10])."""
    T, fs = 60.0, 50.0
    w0 = 2 * np.pi / T
    rng = np.random.default_rng(11)
    ft = Multisine(w0, [2, 5, 9, 14, 22, 33, 51, 75],
                   [0.04, 0.035, 0.025, 0.015, 0.008, 0.005, 0.003, 0.002],
                   rng.uniform(0, 2 * np.pi, 8))
    fd = Multisine(w0, [3, 7, 12, 25, 40, 64], [0.002, 0.004, 0.008, 0.015, 0.025, 0.04],
                   rng.uniform(0, 2 * np.pi, 6))
    task = TrackingTask(ft, fd, motion_gain=0.5, controlled_element=([0.08], [1.0, 0.0, 0.0]),
                        control_gain=1.0, sample_rate_hz=fs, duration=T, run_in=T / 2)
    truth = dict(K_v=15.0, T_vl=0.5, tau_v=0.22, K_m=2.625, tau_m=0.18, omega_nm=10.0,
                 zeta_nm=0.3, delta_abs=0.006)
    m = paper_model()
    wide = dataclasses.replace(m, parameters=tuple(
        dataclasses.replace(p, upper=50.0) if p.name in ("K_v", "K_m") else p
        for p in m.parameters))
    return wide, simulate(wide, params=truth, task=task, remnant_fraction=0.15, seed=5).recording


@pytest.fixture(scope="module")
def wide_lab():
    return _wide_lab()


def test_diagnose_keeps_the_bounds_of_a_wide_base_fit(wide_lab):
    """A base_fit made with K_v, K_m up to 50 is refitted within those bounds (was clipped
    to Table 1's 10, which named a motion-system-dynamics that is not there); the answer is
    the rescaled recording's (u / 10, Table 1's bounds, docs/fitting.md); the base block
    says what samples its -ln L is over."""
    wide, rec = wide_lab
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = fit_fast(rec, wide, seed=0, discard=2.0)
        res = diagnose(rec, seed=0, n_bootstrap=0, base_fit=fit,
                       candidates=["motion-system-dynamics", "motion-washout"])
        ref = diagnose(rec.with_signals(u=rec.u / 10.0), seed=0, n_bootstrap=0,
                       candidates=["motion-system-dynamics", "motion-washout"])
    assert res.settings["base_bounds"] == {"K_v": [0.0, 50.0], "K_m": [0.0, 50.0]}
    assert res.base_model.parameter("K_v").upper == 50.0
    assert res.base["gls_params"]["K_v"] == pytest.approx(
        10.0 * ref.base["gls_params"]["K_v"], rel=0.02)
    assert res.base["gls_params"]["K_v"] > 12.0
    assert res.physics == ref.physics == "none"
    assert "base_at_bounds" not in res.settings
    # -ln L over the samples the fit used: 2 s left out, as the file and summary say
    assert res.base["discard_seconds"] == 2.0 and res.base["n"] == rec.n_samples - 100
    assert "-ln L (Eq. 4) = " in res.summary() and "(after the first 2 s, N = 2900)" \
        in res.summary()
    assert "K_v in [0, 50], K_m in [0, 50]" in res.summary()
    back = DiagnosisResult.from_dict(json.loads(res.to_json()))
    assert back.base["n"] == 2900 and back.summary() == res.summary()
    # diagnose's own base fit: the whole record
    assert ref.base["discard_seconds"] == 0.0 and ref.base["n"] == rec.n_samples
    assert f"(whole record, N = {rec.n_samples})" in ref.summary()


def test_diagnose_without_base_fit_names_the_rescale(wide_lab, tmp_path):
    """Table 1's bounds stop K_v at 10: the BaseFitWarning says to rescale u (it blamed the
    recording or missing physics only); the report's base line says "whole record"."""
    _, rec = wide_lab
    with pytest.warns(BaseFitWarning) as caught:
        res = diagnose(rec, seed=0, n_bootstrap=0, candidates=["motion-washout"])
    text = " ".join(str(w.message) for w in caught if issubclass(w.category, BaseFitWarning))
    assert "K_v = 10 on its upper bound" in text
    assert "rescale u" in text and "rec.with_signals(u=rec.u / c)" in text
    html = res.report(tmp_path)["html"].read_text()
    assert f"(Eq. 4) = {res.base['neg_log_lik']:.2f} (whole record, N = {rec.n_samples})" \
        in html


def test_diagnose_refuses_a_base_fit_outside_the_bounds_it_cannot_know(wide_lab):
    """A fit that records no bounds (a file of another model saved before bounds were
    recorded) with K_v = 15 outside Table 1: refused at once, saying to rescale u."""
    from bayespilot.fit.result import FitResult

    _, rec = wide_lab
    params = dict(paper_parameters("FD"), K_v=15.0)
    fit = FitResult(params, -1000.0, 85.0, "fast", 0, True, settings={"model": "my lab's model"})
    assert fit.bounds == {}
    with pytest.raises(ValueError, match=r"K_v = 15 outside \[0, 10\].*[Rr]escale u"):
        diagnose(rec, seed=0, n_bootstrap=0, base_fit=fit, candidates=["motion-washout"])


# --- diagnose: an entry's needs (extension finding 6) -------------------------------------------
def _attitude(m):
    return m.add_channel(Channel("attitude", "theta_m", delay="tau_a", gain=("K_a",),
                                 sign=-1.0),
                         [Parameter("K_a", -5, 5, 0.0), Parameter("tau_a", 0, 1, 0.2, "s")])


def _attitude_entry(needs=()):
    return Extension("attitude", "attitude feedback", "low-frequency motion",
                     ("frequency.motion_low",), _attitude, ("K_a", "tau_a"),
                     ({"K_a": 0.1},), needs=needs)


def test_register_extension_checks_needs_against_the_model():
    """An entry whose channel reads theta_m without needs=("theta",) is refused, naming the
    entry and its needs (it crashed diagnose after the base fit and bootstrap)."""
    with pytest.raises(ValueError, match=r"extension 'attitude'.*'theta'.*needs=\(\).*"
                                         r"needs=\('theta',\)"):
        register_extension(_attitude_entry())
    assert "attitude" not in C.candidate_names()
    try:
        assert register_extension(_attitude_entry(("theta",))).needs == ("theta",)
    finally:
        C._REGISTERED.pop("attitude", None)


def test_diagnose_checks_needs_before_the_base_fit(monkeypatch):
    """An entry in the registry without register_extension's check: refused before any fit
    (was a ValueError of the likelihood after the base fit, naming neither)."""
    rec = simulate(task="FD", remnant_fraction=0.1, seed=1, duration=20.48).recording
    monkeypatch.setitem(C._REGISTERED, "attitude", _attitude_entry())

    def no_fit(*a, **k):  # the check must come first
        raise AssertionError("the base fit ran")

    monkeypatch.setattr("bayespilot.fit.fast.fit_fast", no_fit)
    with pytest.raises(ValueError, match=r"extension 'attitude'.*needs=\(\)"):
        diagnose(rec, seed=0, n_bootstrap=0, candidates=["motion-washout", "attitude"])

"""Numerical edges found by the numerical-robustness audit: records too short for the delay
bounds (F2), the Savage-Dickey density of a narrow posterior (F10), the verbal label of an
unidentified threshold, and the periodic start of a slow second-order stage (F9)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bayespilot.fit.fast import fit_fast
from bayespilot.fit.three_step import _check_fittable, fit_paper
from bayespilot.likelihood import Likelihood
from bayespilot.model import paper_model
from bayespilot.presets import paper_parameters
from bayespilot.recording import Recording, RecordingError


def _first(rec: Recording, n: int) -> Recording:
    return Recording({k: np.asarray(v)[:n] for k, v in rec.signals.items()}, rec.sample_rate_hz,
                     rec.motion_gain, rec.task, {}, source=f"first{n}")


# --- F2: a record shorter than a delay bound ------------------------------------------------
@pytest.mark.parametrize("oversample, fixed, channel, need", [
    (1, {}, "visual", 105),
    # the vestibular channel at 8 times the rate, the visual delay fixed at 0.1 s
    (8, {"tau_v": 0.1}, "vestibular", 101),
])
def test_fitters_refuse_a_record_shorter_than_the_delay_bounds(fd_rec, oversample, fixed,
                                                                channel, need):
    """The length the refusal names is the kernel's own: with every free delay at its upper
    bound, -ln L is +inf one sample below it and finite at it (1 s at 100 Hz is 100 samples,
    800 at 8 x 100 Hz, plus the 4-sample margin).  Before, fit_fast returned -ln L = inf (or
    garbage parameters) on such a record without a message."""
    model = paper_model(oversample=oversample).fix(**fixed)
    at_bound = dict(paper_parameters("FD"))
    for name in ("tau_v", "tau_m"):
        at_bound[name] = model.parameter(name).upper
    first_finite = next(n for n in range(33, 1000)
                        if np.isfinite(Likelihood(model, _first(fd_rec, n), discard=0.0)
                                       .neg_log_lik(at_bound)))
    assert first_finite == need
    short = _first(fd_rec, need - 1)
    with pytest.raises(RecordingError, match=rf"first{need - 1}: the record is too short for "
                       rf"the pilot model: {need - 1} sample\(s\) .*the {channel} channel's "
                       rf"delay .* needs at least {need} "):
        fit_fast(short, model, seed=0, n_starts=1, discard=0.0)
    with pytest.raises(RecordingError, match=rf"needs at least {need} "):
        fit_paper(short, model, seed=0, repetitions=1, n_best=1, discard=0.0)
    _check_fittable(_first(fd_rec, need), model, 0.0)  # long enough: accepted
    # fixed delays are checked at their values, not at their bounds
    _check_fittable(short, model.fix(tau_v=0.2, tau_m=0.3), 0.0)


# --- F10: Savage-Dickey on a posterior narrower than the KDE grid ----------------------------
@pytest.mark.parametrize("scale", [1e-2, 1e-5, 1e-9])
@pytest.mark.parametrize("lower, upper", [(0.0, 0.1), (1.0, 3.0)])
def test_savage_dickey_on_a_narrow_posterior_is_right(scale, lower, upper):
    """Half-normal draws of scale s from ``lower`` and a uniform prior on [lower, upper]: the
    posterior density at lower is 2 / (s sqrt(2 pi)), so ln BF = -ln(upper - lower) - ln of it.
    Before, scales of 1e-5 and 1e-9 on [0, 0.1] came out 0.5 and 2.6 nats off, as valid."""
    from bayespilot.compare import savage_dickey

    x = lower + np.abs(np.random.default_rng(0).normal(0.0, scale, 20000))
    truth = -np.log(upper - lower) - np.log(2.0 / (scale * np.sqrt(2.0 * np.pi)))
    sd = savage_dickey(x, lower=lower, upper=upper)
    assert sd.valid, sd.reason
    assert sd.log_bayes_factor == pytest.approx(truth, abs=0.1)


def test_savage_dickey_flags_a_spike_it_cannot_resolve():
    """99.5 % of the draws within 1e-7 of 0 and 0.5 % spread over [0, 0.1]: the density at 0
    is 0.995 * 2 / (1e-7 sqrt(2 pi)) (ln BF -13.6); the KDE's grid over the draws' range cannot
    resolve it, and the estimate (before: -8.5, valid) is flagged instead."""
    from bayespilot.compare import savage_dickey

    rng = np.random.default_rng(0)
    x = np.r_[np.abs(rng.normal(0.0, 1e-7, 19900)), rng.uniform(0.0, 0.1, 100)]
    sd = savage_dickey(x)
    assert not sd.valid and sd.log_bayes_factor is None
    assert "narrower than the grid resolves" in sd.reason


# --- port audit 12: the verbal label of a threshold the record does not identify -------------
def test_compare_without_motion_does_not_favour_a_model():
    """K_theta = 0: the motion channel's input is zero, delta_abs is not identified and the two
    models are the same, so ln BF (+1.30 here) is sampling noise: the label says "not
    identified" (before: "(substantial, favours threshold)" on the lab's record), the decision
    is inconclusive with the reason, and the JSON favours neither."""
    import warnings

    from bayespilot.compare import Comparison, compare
    from bayespilot.likelihood import SilentChannelWarning
    from bayespilot.simulate import simulate

    rec = simulate(task="FD", motion_gain=0.0, remnant_fraction=0.03, seed=1,
                   duration=10).recording
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SilentChannelWarning)
        c = compare(rec, nlive=30, seed=0, savage_dickey_samples=False)
    assert abs(c.log_bayes_factor) > 1.15  # past "barely worth mentioning": a label would favour
    for summary in (c.summary(), Comparison.from_dict(c.to_dict()).summary()):
        (line,) = [ln for ln in summary.splitlines() if "ln BF =" in ln and "Savage" not in ln]
        assert "(not identified)  -> decision: inconclusive (delta_abs is not identified" in line
        assert "favours" not in line
    assert c.decision == "inconclusive" and c.to_dict()["favours"] == "neither"
    assert c.settings["threshold_identified"] is False


# --- F9: the periodic start of a slow second-order stage ---------------------------------------
def _multisine(n: int, dt: float, seed: int) -> np.ndarray:
    """A sum of sines with whole periods in n samples (0.3 to 16 rad/s on 20.48 s): periodic."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    ks = np.array([1, 3, 5, 11, 17, 29, 43, 67, 101, 163, 251, 409])
    ph = rng.uniform(0.0, 2.0 * np.pi, ks.size)
    return np.sum(np.sin(2.0 * np.pi * ks[:, None] * t / (n * dt) + ph[:, None])
                  / np.sqrt(ks)[:, None], axis=0)


def _periodic_reference(b, a, x):
    """The exact periodic steady state of the filter b/a on one period x, by the DFT, and
    the filter's frequency response on the DFT's frequencies."""
    from scipy import signal

    w = 2.0 * np.pi * np.fft.rfftfreq(x.size)
    _, H = signal.freqz(b, a, worN=w)
    return np.fft.irfft(H * np.fft.rfft(x), x.size), w


def _stage(kind, p0, p1, dt, dp0=0.0, dp1=0.0):
    from bayespilot.kernels import _blocks as B
    from bayespilot.kernels._sensitivity import stage_tf_tangent, tustin_tangent

    c = B.stage_tf(kind, p0, p1, np.zeros(6))
    dc = stage_tf_tangent(kind, p0, p1, dp0, dp1)
    return B.tustin(*c, dt), tustin_tangent(*c, *dc, dt)


@pytest.mark.parametrize("fs", [100.0, 1000.0])
@pytest.mark.parametrize("omega, zeta", [(0.02, 0.2), (0.02, 0.7), (0.02, 2.0), (0.5, 0.7)])
def test_second_order_washout_starts_in_its_periodic_steady_state(fs, omega, zeta):
    """The stage's output equals the exact periodic steady state (the DFT of the input times
    the frequency response of the same Tustin coefficients).  Before, a washout at the
    catalogue's 0.02 rad/s was off by 2e-3 to 2e-2 of its output's spread on 20.48 s at
    1 kHz (1e-5 at 100 Hz): the periodic state was solved in companion coordinates."""
    from bayespilot.kernels import _blocks as B
    from bayespilot.kernels._response import _filter_biquad

    n = int(round(20.48 * fs))
    x = _multisine(n, 1.0 / fs, 0)
    (B0, B1, B2, A1, A2), _ = _stage(B.STAGE_HIGHPASS2, omega, zeta, 1.0 / fs)
    out = np.empty(n)
    _filter_biquad(x, B0, B1, B2, A1, A2, True, 0, out)
    ref, _ = _periodic_reference([B0, B1, B2], [1.0, A1, A2], x)
    assert np.max(np.abs(out - ref)) / np.std(ref) < 1e-8


@pytest.mark.parametrize("fs", [100.0, 1000.0])
@pytest.mark.parametrize("omega, zeta", [(0.02, 0.2), (0.02, 0.7), (0.5, 0.7)])
def test_second_order_washout_tangent_is_the_periodic_steady_state_of_the_derivative(
        fs, omega, zeta):
    """The stage's tangent (the Jacobian path) equals the exact derivative of the periodic
    steady state: Y = H X gives dY = H dX + dH X, dH = (dB A - B dA) / A^2, by the DFT, along
    a direction that moves omega, zeta and the input at once.  Before: off by up to 150 % of
    the largest d u_hat / d omega_w at 0.02 rad/s and 1 kHz."""
    from scipy import signal

    from bayespilot.kernels import _blocks as B
    from bayespilot.kernels._sensitivity import _filter_tangent

    n = int(round(20.48 * fs))
    x, dx = _multisine(n, 1.0 / fs, 0), 0.3 * _multisine(n, 1.0 / fs, 1)
    (B0, B1, B2, A1, A2), (dB0, dB1, dB2, dA1, dA2) = _stage(
        B.STAGE_HIGHPASS2, omega, zeta, 1.0 / fs, dp0=omega, dp1=0.5 * zeta)
    y, dy = np.empty(n), np.empty(n)
    _filter_tangent(x, dx, B0, B1, B2, A1, A2, dB0, dB1, dB2, dA1, dA2, True, 0, y, dy)
    yref, w = _periodic_reference([B0, B1, B2], [1.0, A1, A2], x)
    _, Bz = signal.freqz([B0, B1, B2], [1.0], worN=w)
    _, Az = signal.freqz([1.0, A1, A2], [1.0], worN=w)
    _, dBz = signal.freqz([dB0, dB1, dB2], [1.0], worN=w)
    _, dAz = signal.freqz([0.0, dA1, dA2], [1.0], worN=w)
    dyref = np.fft.irfft(Bz / Az * np.fft.rfft(dx) + (dBz * Az - Bz * dAz) / Az**2
                         * np.fft.rfft(x), n)
    assert np.max(np.abs(y - yref)) / np.std(yref) < 1e-8
    assert np.max(np.abs(dy - dyref)) / np.max(np.abs(dyref)) < 1e-7


@pytest.mark.parametrize("fs", [100.0, 1000.0])
def test_washout_jacobian_agrees_with_finite_differences(fs):
    """Through the whole chain (Likelihood.jacobian) at the catalogue's lower bound
    omega_w = 0.02: the exact Jacobian in omega_w and zeta_w agrees with central differences
    of the response, steps of 1e-2 of the value (smaller steps at 1 kHz meet the rounding of
    the Tustin denominator's 1 + A1 + A2, about 4e-10 there: the differences lose digits
    below 1e-3; the exact check is the tangent test above).  Before, d u_hat / d omega_w was
    off by up to 150 % at 1 kHz."""
    import warnings

    from bayespilot.model import Parameter, SecondOrderWashout

    n = int(round(20.48 * fs))
    dt = 1.0 / fs
    signals = {"t": np.arange(n) * dt, "e": 0.02 * _multisine(n, dt, 2),
               "theta_ddot_m": 0.5 * _multisine(n, dt, 3), "u": 0.05 * _multisine(n, dt, 4)}
    rec = Recording(signals, fs, 1.0, "FD", {}, source="multisine")
    model = paper_model().add_stage(
        "vestibular", SecondOrderWashout("omega_w", "zeta_w"),
        [Parameter("omega_w", 0.02, 5.0, 0.5, "rad/s"), Parameter("zeta_w", 0.2, 2.0, 0.7)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        lik = Likelihood(model, rec, discard=0.0)
        for zeta in (0.2, 0.7):
            # delta_abs 0: no dead-zone corners for the differences to step across
            p = dict(paper_parameters("FD"), omega_w=0.02, zeta_w=zeta, delta_abs=0.0)
            _, J = lik.jacobian(p, ["omega_w", "zeta_w"])
            for j, name in enumerate(("omega_w", "zeta_w")):
                h = 1e-2 * p[name]
                num = (lik.response(dict(p, **{name: p[name] + h}))
                       - lik.response(dict(p, **{name: p[name] - h}))) / (2.0 * h)
                assert np.max(np.abs(J[:, j] - num)) / np.max(np.abs(num)) < 1e-5, (zeta, name)


def test_a_pool_leaves_out_recordings_that_do_not_identify_the_threshold():
    """compare() of a recording without motion input decides inconclusive ('not identified'),
    but pool() summed its ln BF (sampling noise: the two models are the same there) into the
    condition's decision.  Such recordings are left out of it; with none left, inconclusive
    and labelled 'not identified'."""
    from bayespilot.compare import PooledComparison, pool

    def one(lbf, identified=True):
        return {"log_bayes_factor": lbf, "log_bayes_factor_err": 1.0,
                "settings": {"threshold_identified": identified}}

    p = pool([one(10.0), one(10.0), one(-30.0, identified=False)])
    assert p.log_bayes_factor == -10.0 and p.n_unidentified == 1  # (the sum as before)
    assert p.decision == "threshold" and p.decision_note == ""
    assert (p.decided_log_bayes_factor, p.decided_log_bayes_factor_err) == (20.0, math.sqrt(2))
    assert p.decisions == {"threshold": 2, "none": 0, "inconclusive": 1}  # (not its noise's)
    assert ("sum ln BF = -10.00 +- 1.73 (1 without input to delta_abs's channel left out: "
            "+20.00 +- 1.41 over the other 2) (decisive, favours threshold)  -> decision: "
            "threshold;") in p.summary()
    # a guard counts the recordings that decide: the unidentified one on the plateau is not
    on = dict(one(10.0), plateau_probability=0.9)
    g = pool([on, one(-1.0), dict(one(0.0, identified=False), plateau_probability=0.9)])
    assert g.decision == "inconclusive" and g.decision_note.startswith("1 of 2 recordings")
    q = pool([one(3.0, identified=False), one(2.0, identified=False)])
    assert q.decision == "inconclusive" and q.n_unidentified == 2
    assert "(not identified)" in q.summary() and "favours" not in q.summary()
    assert "not identified in any of the 2 recordings" in q.decision_note
    r = pool([one(10.0), one(12.0)])
    assert r.decision == "threshold" and r.n_unidentified == 0 and r.decision_note == ""
    old = {k: v for k, v in r.to_dict().items() if k != "n_unidentified"}  # a file of before
    assert PooledComparison.from_dict(old).n_unidentified == 0

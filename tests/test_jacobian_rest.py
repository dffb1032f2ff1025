"""initial="rest" with negative delays: one response convention on every path.

A negative delay (which an unconstrained Gauss-Newton step can reach) reads the
channel's signal ahead, so the delayed signal is non-zero from t = tau < 0 on.
From rest, u_hat is the zero-state response: H_nm responds to the delayed
signal from where it starts (a lead-in before the record), on every path: the
general response, the modulated channels, the oversampled ones, the fused -ln L
and the exact Jacobian.  These tests failed when the Jacobian's tangent started
the delayed history from zero at t = 0 while the response read it.
"""

import numpy as np
import pytest

from bayespilot.kernels import _response as R
from bayespilot.likelihood import Likelihood
from bayespilot.model import LinearDrift, Parameter, paper_model
from bayespilot.simulate import simulate

#: Delays of -2.34 and -4.67 samples at 100 Hz (not integers, also on a 4x fine grid).
NEGATIVE = dict(tau_v=-0.0234, tau_m=-0.0467)


@pytest.fixture(scope="module")
def sim():
    return simulate(task="FD", motion_gain=1.0, remnant_fraction=0.15, seed=21, duration=20.0)


def _models():
    pm = paper_model()
    drift = [Parameter("drift", -1.0, 1.0, 0.0)]
    return {
        "paper": (pm, {}),
        "drift": (pm.with_modulation("visual", LinearDrift(), drift), {"drift": 0.3}),
        "oversampled": (pm.with_oversampling(4), {}),
        "oversampled_drift": (pm.with_oversampling(4, ["visual", "vestibular"])
                              .with_modulation("vestibular", LinearDrift(), drift),
                              {"drift": -0.2}),
    }


@pytest.mark.parametrize("name", list(_models()))
@pytest.mark.parametrize("delays", [NEGATIVE, dict(tau_v=-0.123, tau_m=0.1977),
                                    dict(tau_v=0.1534, tau_m=-0.0131)])
def test_rest_negative_delay_jacobian_matches_response(sim, name, delays):
    model, extra = _models()[name]
    lik = Likelihood(model, sim.recording, initial="rest")
    p = dict(sim.params, **delays, **extra)
    y, J = lik.jacobian(p)
    r = lik.response(p)
    assert np.all(np.isfinite(J))
    np.testing.assert_allclose(y, r, rtol=0, atol=1e-12 * np.std(r))
    for j, pname in enumerate(model.parameter_names):
        h = 1e-6 * max(abs(p[pname]), 1e-3)
        fd = (lik.response(dict(p, **{pname: p[pname] + h}))
              - lik.response(dict(p, **{pname: p[pname] - h}))) / (2 * h)
        assert np.max(np.abs(fd - J[:, j])) < 1e-6 * np.max(np.abs(fd)), pname


@pytest.mark.parametrize("name", ["paper", "oversampled"])
@pytest.mark.parametrize("delays", [NEGATIVE, dict(tau_v=-0.123, tau_m=0.1977)])
def test_rest_negative_delay_is_the_zero_state_response(sim, name, delays):
    """The rest response equals the periodic kernel run on the record padded with long
    runs of zeros either side (there the H_nm warm-up sees only zeros, so the run is the
    zero-state response), except in the last few samples, where rest holds the last value."""
    model, extra = _models()[name]
    lik = Likelihood(model, sim.recording, initial="rest")
    p = dict(sim.params, **delays, **extra)
    r = lik.response(p)
    pad = 1500
    z = np.zeros((lik.X.shape[0], pad))
    Xp = np.ascontiguousarray(np.concatenate([z, lik.X, z], axis=1))
    yp, ok = R.response(lik._theta(p), Xp, *lik._args(), lik.dt, True, lik.warm)
    assert ok
    k = lik.n - 20
    np.testing.assert_allclose(r[:k], yp[pad:pad + k], rtol=0, atol=1e-12 * np.std(r))


def test_rest_negative_delay_likelihood_paths_agree_and_are_continuous(sim):
    model = paper_model()
    lik = Likelihood(model, sim.recording, initial="rest")
    p = dict(sim.params, **NEGATIVE)
    r = lik.response(p)
    n = lik.n
    nll = lik.neg_log_lik(p)
    assert nll == pytest.approx(n / 2 * np.log(np.mean((sim.recording.u - r) ** 2)) + n / 2,
                                rel=1e-12)
    rows = np.array([model.free_vector(p), model.free_vector(sim.params)])
    np.testing.assert_allclose(lik.batch(rows), [nll, lik.neg_log_lik(sim.params)], rtol=1e-12)
    # a delay through zero moves -ln L continuously (no start-up jump below zero)
    for name in ("tau_v", "tau_m"):
        lo = lik.neg_log_lik(dict(sim.params, **{name: -1e-9}))
        hi = lik.neg_log_lik(dict(sim.params, **{name: 1e-9}))
        assert abs(lo - hi) < 1e-4, name

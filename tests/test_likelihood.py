"""The Eq. 4 likelihood and its numba kernels against independent references.

References: ``tests/naive.py`` (plain NumPy/SciPy, cascaded Tustin filters
and ``np.interp`` delays, written from the model equations) and, for the
model without threshold, one ``scipy.signal.dlsim`` LTI system per input.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import signal

import naive
from conftest import make_rng
from bayespilot import presets
from bayespilot.likelihood import (Likelihood, PerfectFitWarning, model_response, neg_log_lik,
                                   vaf)
from bayespilot.model import paper_model
from bayespilot.recording import Recording

INITIALS = ("rest", "periodic")

FD = dict(presets.TABLE3["FD"])
FT = dict(presets.TABLE3["FT"])

#: Parameter vectors that exercise the kernel's branches.
CASES = {
    "table3": FD,
    "fractional_delays": dict(FD, tau_v=0.23456, tau_m=0.18171),
    "no_threshold": dict(FD, tau_v=0.31234, tau_m=0.12345, delta_abs=0.0),
    "sub_sample_delays": dict(FD, tau_v=0.0037, tau_m=0.0091),
    "zero_delays": dict(FD, tau_v=0.0, tau_m=0.0),
    "large_threshold": dict(FD, delta_abs=0.05, tau_m=0.4567),
    "other_dynamics": dict(K_v=2.5, T_vl=0.0, tau_v=0.7503, K_m=3.1, tau_m=0.9991,
                           omega_nm=27.3, zeta_nm=0.93, delta_abs=0.002),
    "light_damping": dict(FD, omega_nm=5.2, zeta_nm=0.03, tau_v=0.0999),
}


def _naive(rec, params, initial, warm, **kw):
    return naive.naive_response(params, rec.e, rec.theta_ddot_m, rec.dt, initial, warm, **kw)


def _naive_nll(rec, params, initial, warm):
    return naive.naive_neg_log_lik(params, rec.u, rec.e, rec.theta_ddot_m, rec.dt, initial, warm)


def _with_u(rec: Recording, u: np.ndarray) -> Recording:
    signals = dict(rec.signals)
    signals["u"] = u
    return Recording(signals, rec.sample_rate_hz, rec.motion_gain, rec.task, rec.metadata)


# --- the reference itself ----------------------------------------------------------
def test_naive_reference_agrees_with_lti_reference(fd_rec):
    """The two references (cascade vs one LTI system per input) agree at delta_abs = 0."""
    rec = fd_rec
    p = CASES["no_threshold"]
    a = _naive(rec, p, "rest", 0)
    b = naive.linear_reference(p, rec.e, rec.theta_ddot_m, rec.dt)
    assert np.max(np.abs(a - b)) < 1e-9 * np.std(a)


# --- response: kernel == naive -------------------------------------------------------
@pytest.mark.parametrize("initial", INITIALS)
@pytest.mark.parametrize("case", sorted(CASES))
def test_response_matches_naive(fd_rec, model, initial, case):
    rec = fd_rec
    lik = Likelihood(model, rec, initial=initial)
    params = CASES[case]
    got = lik.response(params)
    ref = _naive(rec, params, initial, lik.warm)
    assert np.all(np.isfinite(got))
    assert np.max(np.abs(got - ref)) < 1e-10 * np.std(ref)


@pytest.mark.parametrize("initial", INITIALS)
def test_response_matches_naive_ft(ft_rec, model, initial):
    rec = ft_rec
    lik = Likelihood(model, rec, initial=initial)
    for params in (FT, dict(FT, tau_v=0.2555, tau_m=0.0042, delta_abs=0.0)):
        ref = _naive(rec, params, initial, lik.warm)
        assert np.max(np.abs(lik.response(params) - ref)) < 1e-10 * np.std(ref)


@pytest.mark.parametrize("warmup", [0.0, 0.013, 2.0, 12.5, 20.0, 45.0])
def test_periodic_warmup_lengths(fd_rec, model, warmup):
    rec = fd_rec
    lik = Likelihood(model, rec, initial="periodic", warmup=warmup)
    assert lik.warm == min(rec.n_samples, round(warmup * rec.sample_rate_hz))
    params = CASES["fractional_delays"]
    ref = _naive(rec, params, "periodic", lik.warm)
    assert np.max(np.abs(lik.response(params) - ref)) < 1e-10 * np.std(ref)


def test_simulation_truth_is_close(fd_sim, model):
    """Sanity: at the true parameters the open-loop response explains u minus the remnant."""
    rec = fd_sim.recording
    lik = Likelihood(model, rec, initial="rest")
    u_hat = lik.response(fd_sim.params)
    # after the 5 s start-up transient of the rest initial condition: the
    # simulator's continuous RK4 loop and the Tustin likelihood agree closely
    k0 = int(5.0 * rec.sample_rate_hz)
    assert vaf((rec.u - fd_sim.remnant)[k0:], u_hat[k0:]) > 99.9


def test_channel_inputs_follow_documented_initial_state(fd_sim, fd_rec, model):
    """Rest: canal from zero state.  Periodic without theta: canal over the record tiled x3."""
    for rec in (fd_sim.recording, fd_rec):
        X = Likelihood(model, rec, initial="rest").X
        assert np.array_equal(X[0], rec.e)
        assert np.max(np.abs(X[1] - naive.canal(rec.theta_ddot_m, rec.dt, "rest"))) \
            < 1e-12 * np.std(X[1])
    X = Likelihood(model, fd_rec, initial="periodic").X
    assert np.max(np.abs(X[1] - naive.canal(fd_rec.theta_ddot_m, fd_rec.dt, "periodic"))) \
        < 1e-12 * np.std(X[1])


@pytest.mark.parametrize("case", ["table3", "fractional_delays", "sub_sample_delays"])
def test_kernel_matches_naive_on_the_likelihoods_channel_inputs(fd_sim, model, case):
    """Periodic mode with a theta column: whatever canal start the likelihood chose, the
    rest of the chain (dead zone, delays, H_nm warm start) is the naive one."""
    rec = fd_sim.recording
    lik = Likelihood(model, rec, initial="periodic")
    params = CASES[case]
    ref = _naive(rec, params, "periodic", lik.warm, canal_output=lik.X[1])
    assert np.max(np.abs(lik.response(params) - ref)) < 1e-10 * np.std(ref)


# --- -ln L ---------------------------------------------------------------------------------
@pytest.mark.parametrize("initial", INITIALS)
def test_neg_log_lik_matches_naive(fd_sim, fd_rec, ft_sim, ft_rec, model, initial):
    for sim, rec in ((fd_sim, fd_rec), (ft_sim, ft_rec)):
        lik = Likelihood(model, rec, initial=initial)
        for params in (*CASES.values(), sim.params):
            got = lik.neg_log_lik(params)
            ref = _naive_nll(rec, params, initial, lik.warm)
            assert got == pytest.approx(ref, rel=1e-9, abs=0)


def test_neg_log_lik_formula(fd_sim, model):
    """N/2 ln(mean eps^2) + N/2, from the residual the class itself reports."""
    lik = Likelihood(model, fd_sim.recording)
    eps = lik.residual(FD)
    n = eps.size
    assert lik.neg_log_lik(FD) == pytest.approx(0.5 * n * np.log(np.mean(eps**2)) + 0.5 * n,
                                                rel=1e-13)
    assert vaf(fd_sim.recording.u, lik.response(FD)) == lik.vaf(FD)
    # VAF = 100 (1 - var(u - u_hat) / var(u)) with u_hat from the naive twin (on the
    # likelihood's canal output, as the theta column sets it): 75.985 %
    u = fd_sim.recording.u
    u_hat = _naive(fd_sim.recording, FD, "periodic", lik.warm, canal_output=lik.X[1])
    ref = 100.0 * (1.0 - np.var(u - u_hat) / np.var(u))
    assert ref == pytest.approx(75.985, abs=1e-3)
    assert lik.vaf(FD) == pytest.approx(ref, rel=1e-12)


def test_module_functions(fd_sim, model):
    rec = fd_sim.recording
    lik = Likelihood(model, rec, initial="rest")
    assert np.array_equal(model_response(model, rec, FD, initial="rest"), lik.response(FD))
    assert neg_log_lik(model, rec, FD, initial="rest") == lik.neg_log_lik(FD)


def test_free_vector_and_mapping_agree(fd_sim, model):
    lik = Likelihood(model, fd_sim.recording)
    vec = model.free_vector(CASES["fractional_delays"])
    assert lik.neg_log_lik(vec) == lik.neg_log_lik(CASES["fractional_delays"])


# --- batch ---------------------------------------------------------------------------------
@pytest.mark.parametrize("initial", INITIALS)
def test_batch_equals_loop_bit_for_bit(fd_sim, model, initial):
    lik = Likelihood(model, fd_sim.recording, initial=initial)
    lo, hi = model.bounds
    pop = make_rng(37).uniform(lo, hi, size=(37, model.n_free))
    got = lik.batch(pop)
    loop = np.array([lik.neg_log_lik(row) for row in pop])
    assert np.all(np.isfinite(got))
    assert np.array_equal(got, loop)
    out = np.empty(37)
    assert lik.batch(pop, out=out) is out
    assert np.array_equal(out, loop)
    # one row, and a non-contiguous view
    assert np.array_equal(lik.batch(pop[:1]), loop[:1])
    assert np.array_equal(lik.batch(pop[::2]), loop[::2])


@pytest.mark.parametrize("initial", INITIALS)
def test_batch_equals_loop_on_extended_models(fd_sim, model, initial):
    """The batch fills the rows of theta-independent channels once per thread buffer
    (``fill_plain_rows``); with two such channels (the n-channel recursion) or a
    parametric stage on the visual one (no longer theta-independent), it must still
    equal the single evaluation bit for bit."""
    from bayespilot.model import Channel, Parameter, Washout

    extra = model.add_channel(Channel("extra", "e", delay="tau_x", gain=("K_x",)),
                              [Parameter("K_x", -5.0, 5.0, 0.3), Parameter("tau_x", 0.0, 1.0, 0.15)])
    washout = model.add_stage("visual", Washout("omega_w"),
                              [Parameter("omega_w", 0.01, 10.0, 0.3)])
    for m, seed in ((extra, 41), (washout, 42)):
        lik = Likelihood(m, fd_sim.recording, initial=initial)
        lo, hi = m.bounds
        pop = make_rng(seed).uniform(lo, hi, size=(23, m.n_free))
        loop = np.array([lik.neg_log_lik(row) for row in pop])
        assert np.all(np.isfinite(loop))
        assert np.array_equal(lik.batch(pop), loop)


def test_batch_threshold_free_model(fd_sim):
    m7 = paper_model(threshold=False)
    lik = Likelihood(m7, fd_sim.recording)
    lo, hi = m7.bounds
    pop = make_rng(7).uniform(lo, hi, size=(9, 7))
    assert np.array_equal(lik.batch(pop), [lik.neg_log_lik(r) for r in pop])


def test_batch_unstable_and_nan_rows_give_inf(fd_sim, model):
    lik = Likelihood(model, fd_sim.recording)
    good = model.free_vector(FD)
    names = model.parameter_names
    unstable = good.copy()
    unstable[names.index("zeta_nm")] = -1.0
    unstable[names.index("omega_nm")] = 30.0
    nan_row = good.copy()
    nan_row[names.index("K_m")] = np.nan
    inf_row = good.copy()
    inf_row[names.index("K_v")] = np.inf
    out = lik.batch(np.vstack([good, unstable, nan_row, inf_row]))
    assert np.isfinite(out[0])
    assert np.all(np.isposinf(out[1:])), out
    assert lik.neg_log_lik(unstable) == np.inf
    assert np.all(np.isnan(lik.response(unstable)))


@pytest.mark.parametrize("zeta", [-0.05, -0.5, -1e-6])
def test_mildly_unstable_row_gives_inf(fd_sim, model, zeta):
    """Instability is detected from the poles, not only when the response overflows."""
    lik = Likelihood(model, fd_sim.recording)
    row = model.free_vector(dict(FD, zeta_nm=zeta))
    assert np.isposinf(lik.batch(row[None])[0])
    assert lik.neg_log_lik(row) == np.inf
    naive_val = naive.naive_neg_log_lik(dict(FD, zeta_nm=zeta), lik.u, lik.X[0],
                                        fd_sim.recording.theta_ddot_m, lik.dt, "rest")
    assert np.isfinite(naive_val)  # the overflow test alone would not have caught it


# --- perfect fit ---------------------------------------------------------------------------
@pytest.mark.parametrize("initial", INITIALS)
def test_perfect_fit_is_finite_and_warns(fd_sim, model, initial):
    rec = fd_sim.recording
    u_model = Likelihood(model, rec, initial=initial).response(FD)
    lik = Likelihood(model, _with_u(rec, u_model), initial=initial)
    with pytest.warns(PerfectFitWarning):
        val = lik.neg_log_lik(FD)
    assert np.isfinite(val)
    n = rec.n_samples
    floor = 1e-24 * np.mean(u_model**2) + 1e-300
    assert val == pytest.approx(0.5 * n * np.log(floor) + 0.5 * n, rel=1e-12)
    batch = lik.batch(model.free_vector(FD)[None])
    assert np.isfinite(batch[0]) and batch[0] == val
    # an imperfect fit does not warn
    with warnings.catch_warnings():
        warnings.simplefilter("error", PerfectFitWarning)
        assert lik.neg_log_lik(dict(FD, K_v=1.06)) > val


# --- continuity in the delays -------------------------------------------------------
@pytest.mark.parametrize("initial", INITIALS)
@pytest.mark.parametrize("name", ["tau_v", "tau_m"])
def test_continuous_in_delay(fd_sim, model, initial, name):
    lik = Likelihood(model, fd_sim.recording, initial=initial)
    dt = fd_sim.recording.dt
    center = FD[name]
    # a fine grid across three sample boundaries
    grid = np.linspace(np.floor(center / dt) * dt - 0.5 * dt, np.floor(center / dt) * dt + 2.5 * dt,
                       151)
    vals = np.array([lik.neg_log_lik(dict(FD, **{name: t})) for t in grid])
    steps = np.abs(np.diff(vals))
    span = vals.max() - vals.min()
    assert span > 0
    # a jump at a sample boundary would be of order span / 3; smooth steps are ~span / 150
    assert steps.max() < 0.05 * span
    # straddling each boundary by +-1e-9 s changes -ln L by ~ slope * 2e-9 only
    for k in range(3):
        tb = (np.floor(center / dt) + k) * dt
        lo = lik.neg_log_lik(dict(FD, **{name: tb - 1e-9}))
        hi = lik.neg_log_lik(dict(FD, **{name: tb + 1e-9}))
        assert abs(hi - lo) < 1e-3


def test_continuous_at_zero_delay(fd_sim, model):
    lik = Likelihood(model, fd_sim.recording, initial="rest")
    a = lik.neg_log_lik(dict(FD, tau_m=0.0))
    b = lik.neg_log_lik(dict(FD, tau_m=1e-9))
    assert abs(a - b) < 1e-3


# --- the model without threshold -------------------------------------------------------
@pytest.mark.parametrize("initial", INITIALS)
def test_threshold_free_model_equals_full_model_at_zero(fd_sim, initial):
    rec = fd_sim.recording
    full = Likelihood(paper_model(), rec, initial=initial)
    free = Likelihood(paper_model(threshold=False), rec, initial=initial)
    p7 = {k: v for k, v in CASES["fractional_delays"].items() if k != "delta_abs"}
    assert np.array_equal(free.response(p7), full.response(dict(p7, delta_abs=0.0)))
    assert free.neg_log_lik(p7) == full.neg_log_lik(dict(p7, delta_abs=0.0))
    # delta_abs given to the threshold-free model is ignored (it is fixed)
    assert free.neg_log_lik(dict(p7, delta_abs=0.05)) == free.neg_log_lik(p7)


@pytest.mark.parametrize("case", ["no_threshold", "fractional_delays", "sub_sample_delays",
                                  "zero_delays", "other_dynamics"])
def test_threshold_free_model_equals_scipy_lti(fd_sim, case):
    """python-control style: the nonlinear kernel on a linear case == scipy's LTI solver."""
    rec = fd_sim.recording
    m7 = paper_model(threshold=False)
    p = {k: v for k, v in CASES[case].items() if k != "delta_abs"}
    got = Likelihood(m7, rec, initial="rest").response(p)
    ref = naive.linear_reference(dict(p, delta_abs=0.0), rec.e, rec.theta_ddot_m, rec.dt)
    assert np.max(np.abs(got - ref)) < 1e-9 * np.std(ref)


def test_threshold_above_canal_output_leaves_visual_channel_only(fd_sim, model):
    rec = fd_sim.recording
    lik = Likelihood(model, rec, initial="rest")
    i_max = np.max(np.abs(naive.canal(rec.theta_ddot_m, rec.dt, "rest")))
    got = lik.response(dict(FD, delta_abs=i_max * 1.0001))
    ref = naive.linear_reference(dict(FD, K_m=0.0), rec.e, rec.theta_ddot_m, rec.dt)
    assert np.max(np.abs(got - ref)) < 1e-9 * np.std(ref)


# --- input validation -------------------------------------------------------------------
def test_batch_shape_errors(fd_sim, model):
    lik = Likelihood(model, fd_sim.recording)
    with pytest.raises(ValueError, match=r"\(M, 8\)"):
        lik.batch(np.zeros((3, 7)))
    with pytest.raises(ValueError, match=r"\(M, 8\)"):
        lik.batch(np.zeros(8))
    with pytest.raises(ValueError, match=r"\(M, 7\)"):
        Likelihood(paper_model(threshold=False), fd_sim.recording).batch(np.zeros((2, 8)))
    # out is written by the kernels as given: one of another size was written out of bounds
    free = np.tile(model.free_vector(presets.paper_parameters("FD")), (5, 1))
    for bad in (np.empty(1), np.empty(6), np.empty(5, dtype=np.float32), np.empty((5, 1)),
                np.empty(10)[::2], [0.0] * 5):
        with pytest.raises(ValueError, match=r"out must be a writeable C-contiguous float64 "
                                             r"array of shape \(5,\)"):
            lik.batch(free, out=bad)
    out = np.empty(5)
    assert lik.batch(free, out=out) is out and np.all(np.isfinite(out))


def test_parameter_name_errors(fd_sim, model):
    lik = Likelihood(model, fd_sim.recording)
    with pytest.raises(ValueError, match=r"'K_vv'.*K_v, T_vl, tau_v, K_m, tau_m, omega_nm"):
        lik.neg_log_lik(dict(FD, K_vv=1.0))
    with pytest.raises(ValueError, match="delta_abs"):
        lik.response({"dela_abs": 0.01})


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_parameter_errors(fd_sim, model, bad):
    lik = Likelihood(model, fd_sim.recording)
    with pytest.raises(ValueError, match="finite"):
        lik.neg_log_lik(dict(FD, tau_v=bad))
    vec = model.free_vector(FD)
    vec[2] = bad
    with pytest.raises(ValueError, match="finite"):
        lik.neg_log_lik(vec)


def test_other_argument_errors(fd_sim, model):
    rec = fd_sim.recording
    with pytest.raises(ValueError, match="initial"):
        Likelihood(model, rec, initial="steady")
    with pytest.raises(ValueError, match="warmup"):
        Likelihood(model, rec, warmup=-1.0)
    with pytest.raises(TypeError):
        Likelihood(model, rec.signals)
    with pytest.raises(ValueError, match="expected 8"):
        Likelihood(model, rec).neg_log_lik(np.ones(7))


# --- a discarded lead-in -------------------------------------------------------------
@pytest.mark.parametrize("discard", [0.01, 0.02, 0.5, 1.99, 2.0])
def test_discarded_lead_in_matches_naive_tail(fd_rec, model, discard):
    """Eq. 4 over the samples after the lead-in, from the naive full-record response.

    Odd and even sample counts (0.01 s = 1 sample) exercise the snapshot in the
    two-sample recursion; the batch must agree with the single evaluation.
    """
    rec = fd_rec
    lik = Likelihood(model, rec, discard=discard)
    skip = int(round(discard * rec.sample_rate_hz))
    assert lik.skip == skip and lik.used == slice(skip, None)
    for params in (FD, CASES["fractional_delays"], CASES["other_dynamics"]):
        eps = (rec.u - _naive(rec, params, "periodic", lik.warm))[skip:]
        n = eps.size
        ref = 0.5 * n * np.log(np.mean(eps**2)) + 0.5 * n
        got = lik.neg_log_lik(params)
        assert got == pytest.approx(ref, rel=1e-9, abs=0)
        assert lik.batch(model.free_vector(params)[None, :])[0] == got
    assert lik.vaf(FD) == vaf(rec.u[skip:], lik.response(FD)[skip:])
    u, u_hat = rec.u[skip:], _naive(rec, FD, "periodic", lik.warm)[skip:]
    assert lik.vaf(FD) == pytest.approx(100.0 * (1.0 - np.var(u - u_hat) / np.var(u)), rel=1e-12)


def test_discarded_lead_in_on_general_paths(fd_sim, model):
    """Three channels (recursion over n channels) and a gain drift (the unfused path)."""
    from bayespilot.kernels import _coloured as C
    from bayespilot.model import Channel, LinearDrift, Parameter

    rec = fd_sim.recording
    extra = model.add_channel(Channel("extra", "e", delay="tau_x", gain=("K_x",)),
                              [Parameter("K_x", -5.0, 5.0, 0.3), Parameter("tau_x", 0.0, 1.0, 0.15)])
    drift = model.with_modulation("visual", LinearDrift("g_v"), [Parameter("g_v", -1.0, 1.0, 0.1)])
    for m in (extra, drift):
        full = Likelihood(m, rec)
        cut = Likelihood(m, rec, discard=1.23)
        p = m.defaults
        eps = full.residual(p)[cut.skip:]
        n = eps.size
        assert cut.neg_log_lik(p) == pytest.approx(0.5 * n * np.log(np.mean(eps**2)) + 0.5 * n,
                                                   rel=1e-11)
        # the coloured likelihood with p = 0 is Eq. 4 over the same samples
        out, fl = np.empty(1), np.zeros(1, dtype=np.bool_)
        C.neg_log_lik_coloured_batch(m.free_vector(p)[None, :], m.n_free, m.free_index,
                                     m.full_vector(), cut.X, cut.u, *cut._args(), cut.dt,
                                     cut.periodic, cut.warm, cut.s2_floor, 1, out, fl, cut.skip)
        assert out[0] == pytest.approx(cut.neg_log_lik(p), rel=1e-11)


def test_discard_is_validated(fd_sim, model):
    for bad in (-0.1, float("nan"), 1e6, "2", True):
        with pytest.raises(ValueError, match="discard"):
            Likelihood(model, fd_sim.recording, discard=bad)


# --- an AR noise model (prediction-error criterion) ------------------------------------------
def _naive_whitened_nll(eps, a):
    """Eq. 4 on w_k = eps_k - sum_j a_j eps_{k-j}, k >= p: plain NumPy, loop over lags."""
    p = len(a)
    w = eps[p:].copy()
    for j in range(1, p + 1):
        w -= a[j - 1] * eps[p - j:len(eps) - j]
    n = w.size
    return 0.5 * n * np.log(np.mean(w**2)) + 0.5 * n


@pytest.mark.parametrize("discard", [0.0, 1.37])
def test_whitened_likelihood_matches_naive(fd_rec, model, discard):
    from bayespilot.noise import ARNoise

    rec = fd_rec
    a = np.array([1.6, -0.9, 0.2, 0.05])
    lik = Likelihood(model, rec, discard=discard, noise=ARNoise(a))
    skip = lik.skip
    assert lik.n_terms == rec.n_samples - skip - a.size
    rows = []
    for params in (FD, CASES["fractional_delays"], CASES["other_dynamics"], CASES["no_threshold"]):
        eps = (rec.u - _naive(rec, params, "periodic", lik.warm))[skip:]
        ref = _naive_whitened_nll(eps, a)
        got = lik.neg_log_lik(params)
        assert got == pytest.approx(ref, rel=1e-9, abs=0)
        # the Gauss-Newton residual is the same whitened series
        r = lik.fit_residual(params)
        assert r.size == lik.n_terms
        assert 0.5 * r.size * np.log(np.mean(r**2)) + 0.5 * r.size == pytest.approx(got, rel=1e-12)
        rows.append(model.free_vector(params))
    batch = lik.batch(np.array(rows))
    np.testing.assert_array_equal(batch, [lik.neg_log_lik(model.as_dict(x)) for x in rows])
    # an order-0 noise model is Eq. 4
    white = Likelihood(model, rec, discard=discard, noise=ARNoise([]))
    assert white.neg_log_lik(FD) == Likelihood(model, rec, discard=discard).neg_log_lik(FD)


def test_whitened_jacobian_matches_finite_differences(fd_sim, model):
    from bayespilot.noise import ARNoise

    rec = fd_sim.recording
    lik = Likelihood(model, rec, discard=0.5, noise=ARNoise([1.2, -0.4]))
    names = ("K_v", "tau_v", "K_m", "omega_nm")
    p = dict(CASES["fractional_delays"])
    J = lik.fit_jacobian(p, names)
    assert J.shape == (lik.n_terms, len(names))
    for k, name in enumerate(names):
        h = 1e-6 * max(1.0, abs(p[name]))
        d = (lik.fit_residual(dict(p, **{name: p[name] + h}))
             - lik.fit_residual(dict(p, **{name: p[name] - h}))) / (2 * h)
        np.testing.assert_allclose(J[:, k], d, rtol=1e-5, atol=1e-7 * np.abs(d).max())


def test_noise_model_is_validated(fd_sim, model):
    from bayespilot.noise import ARNoise

    with pytest.raises(TypeError, match="noise"):
        Likelihood(model, fd_sim.recording, noise=[0.5])
    with pytest.raises(ValueError, match="finite"):
        ARNoise([0.5, np.nan])
    short = fd_sim.recording.n_samples // 4
    with pytest.raises(ValueError, match="noise model needs"):
        Likelihood(model, fd_sim.recording, noise=ARNoise(np.zeros(short)))


def test_likelihood_of_a_recording_with_float32_time():
    """t stored in single precision (uniform only to its precision) gives the same -ln L as the
    float64 t: the model runs on the uniform grid (scipy's impulse response refused the
    float32 steps)."""
    from bayespilot.model import paper_model
    from bayespilot.recording import Recording
    from bayespilot.simulate import simulate

    sim = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=4, duration=81.92)
    rec = sim.recording
    sig = dict(rec.signals, t=rec.t.astype(np.float32))
    rec32 = Recording(sig, rec.sample_rate_hz, rec.motion_gain, rec.task, dict(rec.metadata))
    assert not np.array_equal(np.diff(rec32.t), np.diff(rec.t))
    a = Likelihood(paper_model(), rec).neg_log_lik(sim.params)
    b = Likelihood(paper_model(), rec32).neg_log_lik(sim.params)
    assert b == pytest.approx(a, abs=1e-6)


def test_a_stage_at_its_identity_limit_is_the_identity():
    """A first-order lag at T = 0 is a gain of 1 and a first-order washout at omega = 0 is
    s / s = 1: the likelihood equals the model's without the stage (the discretisation gave
    them a pole on the unit circle, so -ln L was inf), and the lag is continuous there."""
    from bayespilot.model import FirstOrderLag, Parameter, Washout, paper_model
    from bayespilot.presets import paper_parameters
    from bayespilot.simulate import simulate

    truth = paper_parameters("FD")
    rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=2,
                   duration=8.0).recording
    base = Likelihood(paper_model(), rec).neg_log_lik(truth)
    lag = paper_model().add_stage("visual", FirstOrderLag(), [Parameter("T_lag", 0.0, 1.0, 0.0)])
    lik = Likelihood(lag, rec)
    assert lik.neg_log_lik(dict(truth, T_lag=0.0)) == pytest.approx(base, abs=1e-8)
    assert lik.neg_log_lik(dict(truth, T_lag=1e-9)) == pytest.approx(base, abs=1e-5)
    assert lik.batch(np.array([lag.free_vector(dict(truth, T_lag=0.0))]))[0] == pytest.approx(
        base, abs=1e-8)
    wash = paper_model().add_stage("vestibular", Washout(),
                                   [Parameter("omega_w", 0.0, 1.0, 0.0)])
    assert Likelihood(wash, rec).neg_log_lik(dict(truth, omega_w=0.0)) == pytest.approx(
        base, abs=1e-8)


def test_batch_refuses_complex_parameter_vectors():
    from bayespilot.model import paper_model
    from bayespilot.presets import paper_parameters
    from bayespilot.simulate import simulate

    rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=2,
                   duration=8.0).recording
    model = paper_model()
    lik = Likelihood(model, rec)
    row = model.free_vector(paper_parameters("FD"))
    assert np.isfinite(lik.batch(np.array([row]))[0])
    with pytest.raises(ValueError, match="complex"):
        lik.batch(np.array([row + 1e-3j]))


def test_a_channel_without_input_is_said_to_leave_its_parameters_unidentified():
    """A run without motion (K_theta = 0): theta_ddot_m is zero, and the motion channel's own
    free parameters are named (a fit returned K_m 1.13, delta_abs 0.07 without a word);
    the shared neuromuscular ones are not; fixed, or with motion, nothing is said."""
    from bayespilot.likelihood import SilentChannelWarning
    from bayespilot.simulate import simulate

    still = simulate(task="FD", motion_gain=0.0, remnant_fraction=0.05, seed=2,
                     duration=10.0).recording
    with pytest.warns(SilentChannelWarning) as got:
        Likelihood(paper_model(), still)
    (w,) = [x for x in got if x.category is SilentChannelWarning]  # (10 s: not whole periods)
    assert "vestibular channel's input (theta_ddot_m) is zero" in str(w.message)
    assert "its parameters (tau_m, K_m, delta_abs) are not identified" in str(w.message)
    assert "omega_nm" not in str(w.message)
    moving = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.05, seed=2,
                      duration=10.0).recording
    with warnings.catch_warnings():
        warnings.simplefilter("error", SilentChannelWarning)
        Likelihood(paper_model(), moving)
        Likelihood(paper_model().fix(K_m=0.0, tau_m=0.2, delta_abs=0.0), still)


def test_canal_start_without_theta_is_that_with_theta(fd_sim, fd_rec):
    """Without a theta column the canal starts from the pitch rate whose integrated
    acceleration has a zero mean over the record: its output is within 2 % of the canal
    output's spread of the one started from theta's rate (tiling the record as if periodic,
    as before, was 137 % off on this 20-s run)."""
    with_theta = Likelihood(paper_model(), fd_sim.recording).X[1]
    without = Likelihood(paper_model(), fd_rec).X[1]
    assert np.max(np.abs(with_theta - without)) < 0.02 * np.std(with_theta)
    b, a = signal.bilinear(*naive.canal_tf(), fs=1.0 / fd_rec.dt)
    tiled = signal.lfilter(b, a, np.tile(fd_rec.theta_ddot_m, 3))[-fd_rec.n_samples:]
    assert np.max(np.abs(with_theta - tiled)) > 1.0 * np.std(with_theta)



def _with_theta(rec: Recording, theta: np.ndarray) -> Recording:
    return Recording(dict(rec.signals, theta=theta), rec.sample_rate_hz, rec.motion_gain,
                     rec.task, rec.metadata)


def test_canal_start_from_a_noisy_theta_is_the_clean_ones(fd_sim, fd_rec):
    """A noisy pitch sensor (2e-4 rad rms, 0.011 deg) made the three-point difference of
    theta at t = 0 several times the pitch rate (0.060 rad/s where it was 0.019 on an audit's
    run; the fast fit's K_m 20 % low); theta is checked against theta_ddot_m over the first
    second and the least-squares rate taken.  A clean theta keeps the three-point rate
    exactly (the results of clean recordings do not move), and a theta of the other sign,
    which theta_ddot_m contradicts, is turned round."""
    from bayespilot.likelihood import _pitch_rate_at_start

    rec = fd_sim.recording
    th = np.asarray(rec["theta"])
    three_point = rec.motion_gain * (-3.0 * th[0] + 4.0 * th[1] - th[2]) / (2.0 * rec.dt)
    assert _pitch_rate_at_start(rec) == three_point
    noisy = _with_theta(rec, th + make_rng(3).normal(0.0, 2e-4, th.size))
    th_n = np.asarray(noisy["theta"])
    naive_rate = rec.motion_gain * (-3.0 * th_n[0] + 4.0 * th_n[1] - th_n[2]) / (2.0 * rec.dt)
    error = abs(_pitch_rate_at_start(noisy) - three_point)
    assert error < 2e-4  # rad/s; the pitch rate's rms is about 0.03
    assert abs(naive_rate - three_point) > 20 * error  # what the difference alone gave
    canal = Likelihood(paper_model(), rec).X[1]
    assert np.max(np.abs(Likelihood(paper_model(), noisy).X[1] - canal)) < 0.01 * np.std(canal)
    flipped = _with_theta(rec, -th)
    assert _pitch_rate_at_start(flipped) == three_point  # (not -three_point)
    # a constant bias of the logged acceleration (10 % of its sd) leaves theta's rate as it
    # is (the check's t^2 term takes it up; without it the columns disagreed)
    a = np.asarray(rec.theta_ddot_m)
    biased = Recording(dict(rec.signals, theta_ddot_m=a + 0.1 * a.std()), rec.sample_rate_hz,
                       rec.motion_gain, rec.task, rec.metadata)
    assert _pitch_rate_at_start(biased) == three_point
    assert _pitch_rate_at_start(fd_rec) != three_point  # (theta is what tells them apart)

# --- records that are not whole periods of the forcing ----------------------------------------
def test_whole_periods_is_read_from_the_forcing_or_its_columns():
    """From the sidecar's forcing (lines against the record length), else from f_t and f_d
    (smooth across the wrap, as the diagnosis reads them), else not known."""
    from bayespilot.likelihood import whole_periods
    from bayespilot.simulate import simulate

    for duration, whole in ((81.92, True), (30.0, False)):
        rec = simulate(task="FD", motion_gain=1.0, seed=1, duration=duration).recording
        assert whole_periods(rec) is whole
        meta = {k: v for k, v in rec.metadata.items() if k != "forcing"}
        cols = Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta)
        assert whole_periods(cols) is whole
        bare = Recording({k: v for k, v in rec.signals.items() if k not in ("f_t", "f_d")},
                         rec.sample_rate_hz, rec.motion_gain, rec.task, meta)
        assert whole_periods(bare) is None


def test_either_forcing_column_tells_and_an_unknown_record_loses_its_start_up():
    """The format makes f_t and f_d optional: a 60-s FT run (the forcing's period is 81.92 s)
    with f_d alone read as "not known" and was fitted from 0 s, K_v -1.7 %, T_vl +2.1 %,
    K_m -1.9 % off the remnant-free truth; f_d alone now tells, and a record with neither
    (nor a forcing in its sidecar) has its first 2 s left out too, with the reason said:
    every parameter within 0.3 %."""
    from bayespilot.fit.fast import fit_fast
    from bayespilot.likelihood import (STARTUP_REASON, STARTUP_REASON_UNKNOWN,
                                       _startup_default, whole_periods)
    from bayespilot.simulate import simulate

    sim = simulate(task="FT", motion_gain=1.0, remnant_fraction=0.0, seed=5, duration=60.0)
    rec = sim.recording
    meta = {k: v for k, v in rec.metadata.items() if k != "forcing"}

    def without(*cols):
        return Recording({k: v for k, v in rec.signals.items() if k not in cols},
                         rec.sample_rate_hz, rec.motion_gain, rec.task, meta)

    assert whole_periods(without("f_t")) is False and whole_periods(without("f_d")) is False
    whole = simulate(task="FT", motion_gain=1.0, remnant_fraction=0.0, seed=5).recording
    assert whole_periods(Recording({k: v for k, v in whole.signals.items() if k != "f_t"},
                                   whole.sample_rate_hz, whole.motion_gain, whole.task,
                                   meta)) is True
    bare = without("f_t", "f_d")
    assert whole_periods(bare) is None and _startup_default(bare, "periodic") == 2.0
    assert _startup_default(bare, "rest") == 0.0
    for r, reason in ((without("f_t"), STARTUP_REASON), (bare, STARTUP_REASON_UNKNOWN)):
        fit = fit_fast(r, seed=0)
        assert fit.settings["discard"] == 2.0 and fit.settings["discard_reason"] == reason
        for k in ("K_v", "T_vl", "zeta_nm", "K_m"):
            assert fit.params[k] == pytest.approx(sim.params[k], rel=3e-3), k
    assert "not known" in fit.summary()


def test_coloured_discard_is_one_rule_for_the_fitter_the_sampler_and_the_evidence():
    """The default lead-in with an AR ("coloured") noise model was min(2 s, a quarter of the
    record) in fit_fast but a flat 2 s in sample, compare, evidence and the diagnosis's Bayes
    factors: on a 3-s record fit_fast left 0.75 s out and sample refused its own 2 s ("discard
    must be ... in [0, 1.5]"); on 4-8-s records the two weighed different samples.  Now one
    rule, in the likelihood, 2 s exactly on every record of 8 s or more (unchanged)."""
    import bayespilot.likelihood as L
    import bayespilot.sample as S
    from bayespilot.simulate import simulate

    assert S.COLOURED_DISCARD == L.COLOURED_DISCARD == 2.0  # still importable from sample
    for duration, want in ((None, 2.0), (20.0, 2.0), (8.0, 2.0), (6.0, 1.5), (3.0, 0.75)):
        rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=1,
                       **({} if duration is None else {"duration": duration})).recording
        assert L.coloured_discard(rec) == want, duration  # exactly
        assert S._default_discard(rec, "coloured") == want, duration  # sample, compare, evidence
        assert L._coloured_default(rec.duration) == want, duration  # fit_fast(noise="ar")


@pytest.mark.parametrize("name", ["whole_periods", "startup_discard", "coloured_discard"])
def test_the_start_up_helpers_refuse_what_is_not_a_recording(name):
    """A path or a dict was read as far as its first attribute (AttributeError: 'str' object
    has no attribute 'n_samples'); now a TypeError names what it wants."""
    import bayespilot.likelihood as L

    with pytest.raises(TypeError, match="recording must be a Recording, got str"):
        getattr(L, name)("run1.csv")


def test_a_periodic_start_on_a_record_of_part_periods_warns_at_the_callers_line():
    """initial="periodic" wraps a 30-s record (the forcing's period is 81.92 s) across its cut:
    the first eighth of the residual at the true parameters was 0.39 std(u) without remnant
    (<= 0.004 elsewhere), without a word.  Now a NotWholePeriodsWarning says so and what to
    do; discard=2 silences it, and a whole 81.92-s record never raised it."""
    from bayespilot.likelihood import NotWholePeriodsWarning
    from bayespilot.simulate import simulate

    sim = simulate(task="FD", motion_gain=1.0, seed=3, duration=30.0)
    with pytest.warns(NotWholePeriodsWarning) as got:
        Likelihood(paper_model(), sim.recording)
    (w,) = [x for x in got if x.category is NotWholePeriodsWarning]
    assert w.filename == __file__
    assert "not a whole number of periods" in str(w.message) and "discard=2" in str(w.message)
    eps = Likelihood(paper_model(), sim.recording, discard=2.0).residual(sim.params)
    n = sim.recording.n_samples // 8
    assert np.std(eps[:n]) > 30 * np.std(eps[n:])  # what it warns about
    with warnings.catch_warnings():
        warnings.simplefilter("error", NotWholePeriodsWarning)
        Likelihood(paper_model(), sim.recording, discard=2.0)
        Likelihood(paper_model(), sim.recording, initial="rest")
        Likelihood(paper_model(), simulate(task="FD", motion_gain=1.0, seed=3).recording)


def test_fit_fast_leaves_the_start_up_of_a_record_of_part_periods_out():
    """A remnant-free 40-s FT run: from 0 s the fast fit ended at K_v +6 %, T_vl -10 %,
    zeta_nm +11 % off the truth; its default now leaves the start-up (2 s) out, says so in
    its settings and recovers every parameter within 0.5 %.  On whole periods it keeps 0."""
    from bayespilot.fit.fast import fit_fast
    from bayespilot.likelihood import NotWholePeriodsWarning
    from bayespilot.simulate import simulate

    sim = simulate(task="FT", motion_gain=1.0, remnant_fraction=0.0, seed=5, duration=40.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", NotWholePeriodsWarning)
        fit = fit_fast(sim.recording, seed=0)
    assert fit.settings["discard"] == 2.0 and "whole number" in fit.settings["discard_reason"]
    for name, true in sim.params.items():
        assert fit.params[name] == pytest.approx(true, rel=5e-3, abs=1e-4), name
    whole = simulate(task="FT", motion_gain=1.0, remnant_fraction=0.1, seed=5).recording
    fit = fit_fast(whole, seed=0, n_starts=1, profile_step=0.05)
    assert fit.settings["discard"] == 0.0 and "discard_reason" not in fit.settings

"""Slow, obviously-correct NumPy/SciPy twins of the likelihood kernels.

Written from the model equations (Pool et al. 2012, Fig. 4 and Eq. 2-4), not
from ``bayespilot/kernels``:

    u_hat = H_nm(s) [ K_v (1 + T_vl s) e^{-tau_v s} e
                      - K_m e^{-tau_m s} DZ(H_scc(s) theta_ddot_m, delta_abs) ]

    H_nm  = w^2 / (s^2 + 2 z w s + w^2)
    H_scc = K_scc (1 + T1 s) / (1 + T2 s)
    DZ(x, d) = sign(x) max(|x| - d, 0)

Every transfer function is discretised with ``scipy.signal.bilinear`` (Tustin)
at the sample rate and run with ``scipy.signal.lfilter``; the delays are
``numpy.interp`` of the (post-dead-zone) channel signal at t - tau.

Initial conditions, as documented for :class:`bayespilot.likelihood.Likelihood`:

``"rest"``
    every filter starts from zero state and every signal is 0 before t = 0
    (the delayed signal interpolates linearly between 0 at t = -dt and x[0]).
``"periodic"``
    the record is one period of a periodic signal: the canal filter runs
    from rest plus its response to the pitch rate at t = 0 (the rate whose
    integrated acceleration has zero mean over the record; :func:`canal`,
    the same start as the package's without a theta column); delays read across the
    start from the end of the record (``np.interp(..., period=T)``); every
    other recursion (parametric stages, H_nm) starts from zero state ``warm``
    samples before t = 0, reading the periodically extended input.

Only plain NumPy and SciPy are used; this module must never import from
``bayespilot.kernels``.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

K_SCC = 5.97
T_SCC1 = 0.11
T_SCC2 = 5.9

PARAMETER_NAMES = ("K_v", "T_vl", "tau_v", "K_m", "tau_m", "omega_nm", "zeta_nm", "delta_abs")


def canal_tf():
    """(num, den) of the reduced canal model, Eq. 1, in powers of s."""
    return [K_SCC * T_SCC1, K_SCC], [T_SCC2, 1.0]


def dead_zone(x, d):
    """sign(x) max(|x| - d, 0)."""
    return np.sign(x) * np.maximum(np.abs(x) - d, 0.0)


def delay(x, tau, dt, initial):
    """x(t - tau) on the sample grid, linear interpolation between samples."""
    n = x.size
    t = np.arange(n) * dt
    if initial == "rest":
        # x = 0 before t = 0: add the sample x(-dt) = 0 and interpolate.
        return np.interp(t - tau, np.r_[-dt, t], np.r_[0.0, x], left=0.0)
    return np.interp(t - tau, t, x, period=n * dt)


def periodic_filter(b, a, x, warm):
    """Direct form I filter b/a of a periodic x, from zero state ``warm`` samples before t = 0.

    The numerator part reads the periodically extended input (so it sees the
    true past samples); only the recursion (the denominator) starts from zero.
    """
    b = np.asarray(b, float) / a[0]
    a = np.asarray(a, float) / a[0]
    n = x.size
    nb = b.size - 1
    idx = np.arange(-warm - nb, n)
    ext = np.take(x, idx, mode="wrap")
    fir = signal.lfilter(b, [1.0], ext)[nb:]   # samples -warm .. n-1
    return signal.lfilter([1.0], a, fir)[warm:]


def steady_filter(b, a, x):
    """Filter b/a of a periodic x in its periodic steady state: x repeated until the
    start-up transient has decayed below 1e-17 of itself, the last period kept."""
    b = np.asarray(b, float) / a[0]
    a = np.asarray(a, float) / a[0]
    n = x.size
    rho = max(np.abs(np.roots(a))) if a.size > 1 else 0.0
    periods = 2 if rho == 0 else 2 + int(np.ceil(np.log(1e-17) / (n * np.log(rho))))
    return signal.lfilter(b, a, np.tile(x, periods))[-n:]


def filt(num, den, x, dt, initial, warm):
    """Tustin discretisation of num/den applied to x under the given initial condition."""
    b, a = signal.bilinear(num, den, fs=1.0 / dt)
    if initial == "rest":
        return signal.lfilter(b, a, x)
    return periodic_filter(b, a, x, warm)


def canal(theta_ddot_m, dt, initial):
    """Canal output i (IPUT): Tustin H_scc from rest; in periodic mode (a recording without
    theta) plus the canal's response to the pitch rate at t = 0 as an impulse just before
    the record, the rate r0 whose trapezoid-integrated acceleration r0 + int a has zero mean
    over the record; the impulse response of H_scc's strictly proper part,
    K (1 - T1/T2) / (T2 s + 1), is (K (1 - T1/T2) / T2) exp(-t / T2)."""
    b, a = signal.bilinear(*canal_tf(), fs=1.0 / dt)
    x = np.asarray(theta_ddot_m, float)
    i = signal.lfilter(b, a, x)
    if initial == "rest":
        return i
    t = np.arange(x.size) * dt
    rate = np.r_[0.0, np.cumsum((x[1:] + x[:-1]) / 2.0)] * dt
    r0 = -rate.mean()
    tail = K_SCC * (1.0 - T_SCC1 / T_SCC2) / T_SCC2 * np.exp(-t / T_SCC2)
    return i + r0 * tail


def channel_signals(params, e, theta_ddot_m, dt, initial="rest", warm=0, extra_vestibular=(),
                    canal_output=None):
    """The two delayed channel signals entering K (1 + T s) H_nm, and the canal output.

    ``extra_vestibular`` is a sequence of callables ``f(params) -> (num, den)``
    of continuous transfer functions applied to the canal output before the
    dead zone (the hook for model extensions such as a washout).  ``canal_output``
    replaces the canal model's output i (to test the rest of the chain on
    given channel inputs).
    """
    if canal_output is None:
        i = canal(np.asarray(theta_ddot_m, float), dt, initial)
    else:
        i = np.asarray(canal_output, float)
    x = i
    for make in extra_vestibular:
        num, den = make(params)
        if initial == "rest":
            x = filt(num, den, x, dt, initial, warm)
        else:  # a parametric stage starts from its periodic steady state
            x = steady_filter(*signal.bilinear(num, den, fs=1.0 / dt), x)
    o = dead_zone(x, params["delta_abs"])
    d_v = delay(np.asarray(e, float), params["tau_v"], dt, initial)
    d_m = delay(o, params["tau_m"], dt, initial)
    return d_v, d_m, i


def naive_response(params, e, theta_ddot_m, dt, initial="rest", warm=500, extra_vestibular=(),
                   canal_output=None):
    """u_hat of the paper's pilot model at ``params`` (a dict by name).

    Parameters
    ----------
    params : dict
        K_v, T_vl, tau_v, K_m, tau_m, omega_nm, zeta_nm, delta_abs.
    e, theta_ddot_m : ndarray
        The measured inputs.
    dt : float
        Sample interval, s.
    initial : {"rest", "periodic"}
    warm : int
        Samples of warm-up of the recursions in periodic mode (<= len(e)).
    extra_vestibular : sequence of callables
        Extra linear stages after the canal model (see :func:`channel_signals`).
    canal_output : ndarray, optional
        Use this canal output i instead of filtering ``theta_ddot_m``.
    """
    if initial not in ("rest", "periodic"):
        raise ValueError(initial)
    n = len(e)
    if initial == "periodic" and not 0 <= warm <= n:
        raise ValueError("naive periodic mode needs 0 <= warm <= len(e)")
    d_v, d_m, _ = channel_signals(params, e, theta_ddot_m, dt, initial, warm, extra_vestibular,
                                  canal_output)
    w, z = params["omega_nm"], params["zeta_nm"]
    den = [1.0, 2.0 * z * w, w * w]
    K_v, T_vl, K_m = params["K_v"], params["T_vl"], params["K_m"]
    fs = 1.0 / dt
    b_v, a = signal.bilinear([K_v * T_vl * w * w, K_v * w * w], den, fs=fs)
    b_m, a_m = signal.bilinear([-K_m * w * w], den, fs=fs)
    assert np.allclose(a, a_m, rtol=0, atol=1e-15)
    if initial == "rest":
        return signal.lfilter(b_v, a, d_v) + signal.lfilter(b_m, a, d_m)
    # Periodic: one H_nm recursion on the combined numerator output, warmed up
    # on the last ``warm`` samples (numerators read the wrapped signals).
    nb = max(len(b_v), len(b_m)) - 1
    idx = np.arange(-warm - nb, n)
    fir = (signal.lfilter(b_v, [1.0], np.take(d_v, idx, mode="wrap"))
           + signal.lfilter(b_m, [1.0], np.take(d_m, idx, mode="wrap")))[nb:]
    return signal.lfilter([1.0], a, fir)[warm:]


def naive_neg_log_lik(params, u, e, theta_ddot_m, dt, initial="rest", warm=500,
                      extra_vestibular=(), canal_output=None):
    """-ln L of Eq. 4 with s2 = mean(eps^2) (floored at 1e-24 mean(u^2) + 1e-300).

    Returns +inf when the response is not finite.
    """
    u = np.asarray(u, float)
    with np.errstate(all="ignore"):
        u_hat = naive_response(params, e, theta_ddot_m, dt, initial, warm, extra_vestibular,
                               canal_output)
        if not np.all(np.isfinite(u_hat)):
            return np.inf
        s2 = np.mean((u - u_hat) ** 2)
    s2 = max(s2, 1e-24 * np.mean(u**2) + 1e-300)
    n = u.size
    return 0.5 * n * np.log(s2) + 0.5 * n


def linear_reference(params, e, theta_ddot_m, dt):
    """The delta_abs = 0 model from rest as ONE LTI system per input (scipy.signal.dlsim).

    Independent of :func:`naive_response`: each input path is a single
    discrete transfer function (products formed in continuous time, then
    ``cont2discrete(method="bilinear")``), the whole-sample part m of the
    delay shifts the input, and the fraction f is the FIR (1 - f) + f z^-1
    convolved into the numerator.
    """
    w, z = params["omega_nm"], params["zeta_nm"]
    den_nm = np.array([1.0, 2.0 * z * w, w * w])
    num_v = params["K_v"] * w * w * np.array([params["T_vl"], 1.0])
    cn, cd = canal_tf()
    num_m = -params["K_m"] * w * w * np.asarray(cn)
    den_m = np.polymul(cd, den_nm)
    out = np.zeros(len(e))
    for num, den, x, tau in ((num_v, den_nm, e, params["tau_v"]),
                             (num_m, den_m, theta_ddot_m, params["tau_m"])):
        num = np.trim_zeros(np.asarray(num, float), "f")  # e.g. T_vl = 0
        if num.size == 0:  # a zero gain: this path contributes nothing
            continue
        bd, ad, _ = signal.cont2discrete((num, den), dt, method="bilinear")
        bd = np.ravel(bd)
        m = int(np.floor(tau / dt))
        f = tau / dt - m
        # whole samples of delay: shift the input (zeros before t = 0) ...
        x = np.r_[np.zeros(m), np.asarray(x, float)][: len(e)]
        # ... and the fraction f: the FIR (1 - f) + f z^-1 in the numerator
        bd = np.convolve(bd, [1.0 - f, f])
        ad = np.r_[ad, 0.0]  # same degree as the numerator, in powers of z
        _, y = signal.dlsim((bd, ad, dt), x)
        out += np.ravel(y)
    return out

"""Open-loop pilot-model response u_hat and the Eq. 4 likelihood, in numba.

The model is driven by the recorded channel inputs (already passed through the
channels' fixed linear stages, e.g. the canal model) at the recording's rate:

    per channel c:  x_c -> parametric stages (Tustin) -> nonlinearity -> q_c
                    d_c(t) = g_c(t) q_c(t - tau_c)           (linear interpolation)
    u_hat = out_nl( sum_c  K_c (1 + T_c s) H_nm(s) d_c )    (Tustin, one recursion)

A channel with ``oversample`` M > 1 runs its path after the parametric
stages at M times the rate and is folded back to the recording's rate
(``kernels/_oversample.py``).

Initial conditions (``periodic``): the forcing functions are periodic in the
record length, so the record is treated as one period: delays read across the
start from the end of the record, and the model starts in periodic steady
state as the pilot, who was already tracking, did: the H_nm recursion (fast)
is first run over the last ``warm`` samples; a parametric stage, which can be
slow, starts from its exact periodic state (:func:`periodic_state`).  With ``periodic=False`` the model
starts from rest (zero state, zero input before t = 0): the zero-state response, every
block at rest until its input becomes non-zero.  A negative delay (tau_c < 0, which an
unconstrained fit step can reach) reads q_c ahead, so d_c is non-zero from t = tau_c < 0 on
and H_nm responds to it from there: the recursion then runs over a lead-in of
:func:`lead_in` samples before the record, from rest, so that the delay stays a pure
time shift (as it is in the periodic case) and every path (the fused -ln L falls back to
:func:`response_into` here, the modulated channels, the oversampled ones and the tangents
of ``kernels/_sensitivity.py``) computes the same u_hat.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .._jit import njit, pjit
from . import _oversample as OV
from ._blocks import (MOD_NONE, NL_DEADZONE, NL_NONE, STAGE_FIXED, STAGE_NONE, modulation,
                      nonlinearity, param_or, stable, stage_tf, tustin)

# Layout of the plan's integer channel table (one row per channel).
CH_NL_KIND, CH_NL_P0, CH_NL_P1, CH_DELAY, CH_GAIN0, CH_GAIN1, CH_LEAD, CH_MOD_KIND, \
    CH_MOD_P0, CH_NSTAGES, CH_SOURCE, CH_OVERSAMPLE = range(12)
CH_NFIELDS = 12
# Float channel table.
CHF_GAIN_CONST, CHF_SIGN = range(2)
CHF_NFIELDS = 2
# Output table.
OUT_OMEGA, OUT_ZETA, OUT_NL_KIND, OUT_NL_P0, OUT_NL_P1 = range(5)
OUT_NFIELDS = 5
#: A channel's delay must be shorter than its signal by more than this many samples (at the
#: channel's rate): the interpolated delay reads up to that far back.  -ln L is +inf
#: otherwise; the command line tells a record too short for the delays by the same rule.
DELAY_MARGIN = 4


@njit
def _power_minus_identity(D, n):
    """M**n - I for M = I + D, by binary powering on E_m = M**m - I: E_2m = 2 E_m + E_m E_m
    and E_m+1 = E_m + D + E_m D.  I + (something small) is never formed, so a D of small
    entries (poles near z = 1, in the scaled coordinates of :func:`_delta_scale`) keeps its
    digits, where M**n by repeated squaring of M itself lost them."""
    d = D.shape[0]
    E = np.zeros((d, d))
    bit = 1
    while bit * 2 <= n:
        bit *= 2
    while bit > 0:
        E = 2.0 * E + E @ E
        if n & bit:
            E = E + D + E @ D
        bit >>= 1
    return E


@njit
def _delta_scale(A1, A2):
    """(c0, h) of the scaled delta coordinates of the recursion y_k = in_k - A1 y_k-1 - A2 y_k-2.

    In the state (y_k, (y_k - y_k-1) / h) the homogeneous step is I + D with
    D = [[-c0, A2 h], [-c0 / h, A2 - 1]], c0 = 1 + A1 + A2 = (1 - p1)(1 - p2) > 0 for poles
    p1, p2 inside the unit circle.  With h = sqrt(c0) (at most 1) D's entries are of the size
    of 1 - p (omega dt for a stage of omega rad/s near z = 1) and its eigenvectors are
    well apart; in the companion coordinates (y_k-1, y_k-2) the two eigenvectors of a pole
    pair near z = 1 are almost parallel.  (1 + A1) + A2 is exact in floating point where it
    matters, poles near z = 1: 1 + A1 is exact for A1 in [-2, -0.5] (Sterbenz), and so is
    the sum when 1 + A1 is within a factor 2 of -A2 (not for every A2 in [0.5, 1]).
    """
    c0 = (1.0 + A1) + A2
    h = math.sqrt(c0) if c0 > 0.0 else 1.0
    if h > 1.0:
        h = 1.0
    return c0, h


@njit
def _solve_periodic(D, r, n):
    """z with z = (I + D)**n z + r, i.e. -((I + D)**n - I) z = r; NaN if that is singular."""
    A = -_power_minus_identity(D, n)
    det = np.linalg.det(A)
    if not abs(det) > 1e-300:
        return np.full(r.shape[0], np.nan)
    return np.linalg.solve(A, r)


@njit
def periodic_state(A1, A2, y1, v1, n):
    """The start (y_-1, y_-2) of the periodic steady state of the recursion
    y_k = in_k - A1 y_k-1 - A2 y_k-2 over a period of n samples whose zero-state run ends at
    y_n-1 = ``y1`` with v_n-1 = y_n-1 - y_n-2 = ``v1`` (given, not formed: the difference
    of two large y loses the digits that matter): the state z with z = T**n z + r.

    Solved in the scaled delta coordinates of :func:`_delta_scale`, where I - T**n is well
    conditioned and is computed without cancellation (:func:`_power_minus_identity`), not in
    the companion coordinates, where a pole pair near z = 1 (a second-order washout of
    0.02 rad/s at 1 kHz) left 2-12 % of the stage output wrong.  Returns NaN (both) when
    I - T**n is singular (a pole on the unit circle).
    """
    c0, h = _delta_scale(A1, A2)
    D = np.array([[-c0, A2 * h], [-c0 / h, A2 - 1.0]])
    z = _solve_periodic(D, np.array([y1, v1 / h]), n)
    return z[0], z[0] - h * z[1]


@njit
def periodic_state_tangent(A1, A2, dA1, dA2, y1, v1, dy1, dv1, n):
    """:func:`periodic_state` of the recursion and of its tangent along (dA1, dA2) together:
    the start (y_-1, y_-2, dy_-1, dy_-2) from the zero-state run's end (``y1``, ``v1``,
    ``dy1``, ``dv1``: the values and their last differences), in the same scaled delta
    coordinates (h held fixed: a change of coordinates, not of the recursion).  The
    tangent's step adds -dc0 y_k-1 + dA2 (y_k-1 - y_k-2), with dc0 = dA1 + dA2.  NaN (all
    four) when singular."""
    c0, h = _delta_scale(A1, A2)
    dc0 = dA1 + dA2
    D = np.zeros((4, 4))
    D[0, 0] = -c0
    D[0, 1] = A2 * h
    D[1, 0] = -c0 / h
    D[1, 1] = A2 - 1.0
    D[2, 0] = -dc0
    D[2, 1] = dA2 * h
    D[3, 0] = -dc0 / h
    D[3, 1] = dA2
    D[2, 2] = -c0
    D[2, 3] = A2 * h
    D[3, 2] = -c0 / h
    D[3, 3] = A2 - 1.0
    z = _solve_periodic(D, np.array([y1, v1 / h, dy1, dv1 / h]), n)
    return z[0], z[0] - h * z[1], z[2], z[2] - h * z[3]


@njit
def _filter_biquad(x, B0, B1, B2, A1, A2, periodic, warm, out):
    """Direct-form-I biquad of x into out, from its exact periodic steady state or from rest.

    Periodic: x is one period, so its history before k = 0 is its end, and
    the output's two states are solved for exactly (:func:`periodic_state`),
    not warmed up over ``warm`` samples: a parametric stage can be slow (a
    washout at 0.02 rad/s has a 70-s time constant) and a warm-up would leave
    its start-up transient in u_hat.  ``warm`` is unused and kept for the
    common signature.
    """
    n = x.shape[0]
    x1 = 0.0
    x2 = 0.0
    y1 = 0.0
    y2 = 0.0
    if periodic and n >= 2:
        # zero-state response over one period, with the periodic input history, in delta
        # form (y_k and v_k = y_k - y_k-1: v_k = in_k - c0 y_k-1 + A2 v_k-1), so that the
        # end's v, which the periodic state needs, is not the difference of two large y
        x1 = x[n - 1]
        x2 = x[n - 2]
        c0 = (1.0 + A1) + A2
        v1 = 0.0
        for k in range(n):
            xk = x[k]
            vk = B0 * xk + B1 * x1 + B2 * x2 - c0 * y1 + A2 * v1
            x2 = x1
            x1 = xk
            y1 = y1 + vk
            v1 = vk
        y1, y2 = periodic_state(A1, A2, y1, v1, n)
        x1 = x[n - 1]
        x2 = x[n - 2]
    for k in range(n):
        xk = x[k]
        yk = B0 * xk + B1 * x1 + B2 * x2 - A1 * y1 - A2 * y2
        x2 = x1
        x1 = xk
        y2 = y1
        y1 = yk
        out[k] = yk


@njit
def _tap(src, j, n, periodic):
    """src[j] with periodic wrap, or rest (0 before the start, last value after the end)."""
    if periodic:
        j = j % n
        return src[j]
    if j < 0:
        return 0.0
    if j >= n:
        return src[n - 1]
    return src[j]


@njit
def _accumulate_delayed(v, src, m, c0, c1, c2, c3, periodic):
    """v[k] += c0 src[k-m] + c1 src[k-m-1] + c2 src[k-m-2] + c3 src[k-m-3].

    The fractional delay (linear interpolation) and the Tustin numerator of the
    channel fold into these four taps.  The bulk of the record has no
    wrap-around and runs as a branch-free loop that LLVM vectorises.
    """
    n = src.shape[0]
    lo = m + 3
    if lo < 0:
        lo = 0
    hi = n + m
    if hi > n:
        hi = n
    if lo > hi:
        lo = hi
    for k in range(0, lo):
        j = k - m
        v[k] += (c0 * _tap(src, j, n, periodic) + c1 * _tap(src, j - 1, n, periodic)
                 + c2 * _tap(src, j - 2, n, periodic) + c3 * _tap(src, j - 3, n, periodic))
    # views indexed by the loop counter: no negative-index wrap-around selects
    sv = src[lo - m - 3:]  # sv[i + 3] is src[lo + i - m]; lo - m - 3 >= 0 here
    vv = v[lo:]
    for i in range(hi - lo):
        vv[i] += c0 * sv[i + 3] + c1 * sv[i + 2] + c2 * sv[i + 1] + c3 * sv[i]
    for k in range(max(hi, lo), n):
        j = k - m
        v[k] += (c0 * _tap(src, j, n, periodic) + c1 * _tap(src, j - 1, n, periodic)
                 + c2 * _tap(src, j - 2, n, periodic) + c3 * _tap(src, j - 3, n, periodic))


@njit
def _accumulate_modulated(v, src, m, f, B0, B1, B2, mod_kind, mod_p, periodic, pre=0):
    """Like _accumulate_delayed, for a channel whose gain is modulated in time.

    ``pre`` (rest only): ``src`` and ``v`` start with a lead-in of ``pre`` samples before the
    record (:func:`lead_in`), so sample k is at the record's time k - pre."""
    n = src.shape[0]
    d1 = 0.0
    d2 = 0.0
    start = -2 if periodic else 0
    for k in range(start, n):
        j = k - m
        dk = (1.0 - f) * _tap(src, j, n, periodic) + f * _tap(src, j - 1, n, periodic)
        frac = ((k + n) % n) / n if periodic else (k - pre) / (n - pre)
        dk *= modulation(mod_kind, frac, mod_p)
        if k >= 0:
            v[k] += B0 * dk + B1 * d1 + B2 * d2
        d2 = d1
        d1 = dk


@njit
def lead_in(theta, ch_int, dt, n):
    """Samples of lead-in the recording-rate channels need when starting from rest: the
    largest -m over channels with a negative delay of m + f samples (0 if none).

    A channel's d_c is non-zero from sample m on (q_c is zero before the start), so the
    recursion through H_nm, from rest at sample -lead_in, is the zero-state response.
    Delays out of range are left to the caller's check."""
    P = 0
    for c in range(ch_int.shape[0]):
        if oversampling(ch_int, c) > 1:
            continue  # its own recursion and lead-in (fine_lead_in)
        dd = theta[ch_int[c, CH_DELAY]] / dt
        if abs(dd) < n - DELAY_MARGIN:
            m = int(math.floor(dd))
            if -m > P:
                P = -m
    return P


@njit
def fine_lead_in(m, M):
    """Lead-in (samples at the recording's rate) of an oversampled channel from rest with a
    delay of m fine samples: its fine input is non-zero from fine sample m - M on (the
    interval before the start is interpolated from rest), and the decimated recursion at
    sample k - P starts from rest when none of it lies at or before fine sample -(P + 1) M."""
    return -(m // M) if m < 0 else 0


@njit
def _with_lead_in(src, pre):
    """``src`` after ``pre`` zeros (rest before the start)."""
    out = np.zeros(src.shape[0] + pre)
    out[pre:] = src
    return out


@njit
def oversampling(ch_int, c):
    """The channel's oversampling factor M (1: the recording's rate)."""
    M = ch_int[c, CH_OVERSAMPLE]
    return M if M > 1 else 1


@njit
def any_oversampled(ch_int):
    """True if some channel runs at a multiple of the recording's rate."""
    for c in range(ch_int.shape[0]):
        if oversampling(ch_int, c) > 1:
            return True
    return False


@njit
def work_length(ch_int, n):
    """Length of the ``v`` work buffer :func:`response_into` needs: n, and for oversampled
    channels three more records (4 n)."""
    return 4 * n if any_oversampled(ch_int) else n


@njit
def response_into(theta, X, ch_int, ch_float, st_int, st_const, out_int, dt, periodic, warm,
                  y, q, v):
    """Pilot-model response for full parameter vector ``theta`` into ``y``.

    ``q`` is a work buffer of the record's length, ``v`` one of
    :func:`work_length` (the record's length unless a channel is
    oversampled; a shorter ``v`` makes this allocate one per call).  Returns
    False if the response is not finite (an unstable or degenerate parameter
    vector).
    """
    n = X.shape[1]
    if not any_oversampled(ch_int):
        return _response_core(theta, X, ch_int, ch_float, st_int, st_const, out_int, dt,
                              periodic, warm, y, q, v, v[:0], v[:0], v[:0])
    need = work_length(ch_int, n)
    if v.shape[0] < need:
        v = np.empty(need)
    return _response_core(theta, X, ch_int, ch_float, st_int, st_const, out_int, dt, periodic,
                          warm, y, q, v[:n], v[n:2 * n], v[2 * n:3 * n], v[3 * n:4 * n])


@njit
def _response_core(theta, X, ch_int, ch_float, st_int, st_const, out_int, dt, periodic, warm,
                   y, q, v, w, b, fb):
    """:func:`response_into` with its buffers: ``v`` (n), and for oversampled channels ``w``
    (n, their share of u_hat), ``b`` (n, a channel's folded input) and ``fb`` (n, its
    nonlinearity's output at the recording's rate)."""
    n_ch = X.shape[0]
    n = X.shape[1]
    wn = theta[out_int[OUT_OMEGA]]
    zn = theta[out_int[OUT_ZETA]]
    w2 = wn * wn
    # Common Tustin denominator of H_nm (numerator differs per channel).
    _, _, _, A1, A2 = tustin(w2, 0.0, 0.0, w2, 2.0 * zn * wn, 1.0, dt)
    if not stable(A1, A2):
        return False  # an unstable (or marginal) H_nm is no pilot: -ln L = +inf
    # rest with a negative delay: v (and the recursion) start pre samples before the record
    pre = 0 if periodic else lead_in(theta, ch_int, dt, n)
    vv = v
    if pre > 0:
        vv = np.zeros(n + pre)
    else:
        for k in range(n):
            v[k] = 0.0
    fine = w.shape[0] > 0
    for k in range(w.shape[0]):
        w[k] = 0.0
    for c in range(n_ch):
        src = X[c]
        nst = ch_int[c, CH_NSTAGES]
        for s in range(nst):
            kind = st_int[c, s, 0]
            if kind == STAGE_FIXED or kind == STAGE_NONE:
                continue  # fixed stages are already applied to X
            b0, b1, b2, a0, a1, a2 = stage_tf(kind, param_or(theta, st_int[c, s, 1], 0.0),
                                              param_or(theta, st_int[c, s, 2], 0.0),
                                              st_const[c, s])
            sB0, sB1, sB2, sA1, sA2 = tustin(b0, b1, b2, a0, a1, a2, dt)
            if not stable(sA1, sA2):
                return False
            _filter_biquad(src, sB0, sB1, sB2, sA1, sA2, periodic, warm, q)
            src = q
        gain = ch_float[c, CHF_GAIN_CONST] * ch_float[c, CHF_SIGN] \
            * param_or(theta, ch_int[c, CH_GAIN0], 1.0) * param_or(theta, ch_int[c, CH_GAIN1], 1.0)
        lead = param_or(theta, ch_int[c, CH_LEAD], 0.0)
        kg = gain * w2
        nl = ch_int[c, CH_NL_KIND]
        mod_kind = ch_int[c, CH_MOD_KIND]
        M = oversampling(ch_int, c)
        if M > 1:
            # this channel at M times the rate, folded back (kernels/_oversample.py)
            dtf = dt / M
            B0, B1, B2, fA1, fA2 = tustin(kg, kg * lead, 0.0, w2, 2.0 * zn * wn, 1.0, dtf)
            dd = theta[ch_int[c, CH_DELAY]] / dtf
            if not (abs(dd) < n * M - DELAY_MARGIN):
                return False
            m = int(math.floor(dd))
            K, _, A1p, A2p, _, _ = OV.coefficients(fA1, fA2, B0, B1, B2, dd - m, M,
                                                   0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            pc = 0 if periodic else fine_lead_in(m, M)
            if pc > 0:
                # rest, negative delay: its recursion from rest pc samples before the record
                bx = np.empty(n + pc)
                OV.fold_channel(_with_lead_in(src, pc), M, m, K, periodic, nl,
                                param_or(theta, ch_int[c, CH_NL_P0], 0.0),
                                param_or(theta, ch_int[c, CH_NL_P1], 0.0), np.empty(n + pc), bx)
                if mod_kind != MOD_NONE:
                    OV.modulate(bx, mod_kind, param_or(theta, ch_int[c, CH_MOD_P0], 0.0), 0.0, bx,
                                False, pc)
                wx = np.zeros(n + pc)
                f1, f2 = OV.recursion_add(bx, A1p, A2p, periodic, warm, wx)
                for k in range(n):
                    w[k] += wx[pc + k]
            else:
                OV.fold_channel(src, M, m, K, periodic, nl,
                                param_or(theta, ch_int[c, CH_NL_P0], 0.0),
                                param_or(theta, ch_int[c, CH_NL_P1], 0.0), fb, b)
                if mod_kind != MOD_NONE:
                    OV.modulate(b, mod_kind, param_or(theta, ch_int[c, CH_MOD_P0], 0.0), 0.0, b,
                                False)
                f1, f2 = OV.recursion_add(b, A1p, A2p, periodic, warm, w)
            if not (math.isfinite(f1) and math.isfinite(f2)):
                return False
            continue
        if nl == NL_DEADZONE:
            dz = param_or(theta, ch_int[c, CH_NL_P0], 0.0)
            for k in range(n):
                xk = src[k]
                a = abs(xk) - dz
                a = a if a > 0.0 else 0.0
                q[k] = a if xk >= 0.0 else -a
            src = q
        elif nl != NL_NONE:
            p0 = param_or(theta, ch_int[c, CH_NL_P0], 0.0)
            p1 = param_or(theta, ch_int[c, CH_NL_P1], 0.0)
            for k in range(n):
                q[k] = nonlinearity(nl, src[k], p0, p1)
            src = q
        B0, B1, B2, _, _ = tustin(kg, kg * lead, 0.0, w2, 2.0 * zn * wn, 1.0, dt)
        dd = theta[ch_int[c, CH_DELAY]] / dt
        if not (abs(dd) < n - DELAY_MARGIN):
            return False
        m = int(math.floor(dd))
        f = dd - m
        if pre > 0:
            src = _with_lead_in(src, pre)  # v and src both start pre samples early: same m
        if mod_kind == MOD_NONE:
            _accumulate_delayed(vv, src, m, B0 * (1.0 - f), B0 * f + B1 * (1.0 - f),
                                B1 * f + B2 * (1.0 - f), B2 * f, periodic)
        else:
            _accumulate_modulated(vv, src, m, f, B0, B1, B2, mod_kind,
                                  param_or(theta, ch_int[c, CH_MOD_P0], 0.0), periodic, pre)
    # The common recursion through H_nm, added to the oversampled channels' share
    for k in range(n):
        y[k] = w[k] if fine else 0.0
    if pre > 0:
        yx = np.zeros(n + pre)
        y1, y2 = OV.recursion_add(vv, A1, A2, periodic, warm, yx)
        for k in range(n):
            y[k] += yx[pre + k]
    else:
        y1, y2 = OV.recursion_add(v, A1, A2, periodic, warm, y)
    out_nl = out_int[OUT_NL_KIND]
    if out_nl != NL_NONE:
        o0 = param_or(theta, out_int[OUT_NL_P0], 0.0)
        o1 = param_or(theta, out_int[OUT_NL_P1], 0.0)
        for k in range(n):
            y[k] = nonlinearity(out_nl, y[k], o0, o1)
    return math.isfinite(y1) and math.isfinite(y2)


@njit
def neg_log_lik_from_sse(sse, n, s2_floor):
    """Eq. 4 with the output-error variance profiled out: N/2 ln(sse/N) + N/2.

    The variance is floored at ``s2_floor`` so a perfect fit gives a finite
    value instead of -inf.  Returns (value, floored).
    """
    if not math.isfinite(sse):
        return np.inf, False
    s2 = sse / n
    floored = False
    if s2 < s2_floor:
        s2 = s2_floor
        floored = True
    return 0.5 * n * math.log(s2) + 0.5 * n, floored


@njit
def _fill_pads(row, n, pad, periodic):
    """Given row[pad:pad+n] = signal, fill the pads: wrapped (periodic) or rest.

    ``pad <= n`` (see :func:`padding`), so each pad is one slice of the signal.
    """
    if periodic:
        row[:pad] = row[n:n + pad]  # the last pad samples of the signal
        row[pad + n:pad + n + pad] = row[pad:pad + pad]  # its first pad samples
    else:
        row[:pad] = 0.0
        row[pad + n:pad + n + pad] = row[pad + n - 1]


@njit(fastmath={"contract"})
def _recursion_2(q0, q1, o0, o1, a0, a1, a2, a3, b0, b1, b2, b3, u, A1, A2, periodic, warm, n,
                 skip=0):
    """Two-channel fused loop: v_k from 4 taps per channel, y_k = v_k - A1 y_{k-1} - A2 y_{k-2}.

    Speed is the point of this kernel (the GA and emcee call it ~10^5-10^6 times
    per data set), so two exceptions to the package's jit defaults are made
    here: ``contract`` lets LLVM fuse multiply-adds (no reassociation, results
    stay deterministic), and the recursion runs two samples per step with the
    exact look-ahead form

        y_k     = v_k - A1 y_{k-1} - A2 y_{k-2}
        y_{k+1} = (v_{k+1} - A1 v_k) + (A1^2 - A2) y_{k-1} + A1 A2 y_{k-2},

    which halves the loop-carried dependency chain per sample.

    The taps are read through views that start three samples before the
    first one used, so every index is ``k + const`` with ``k`` a non-negative
    loop counter: numba then emits no negative-index wrap-around select per
    load, which made the loop 1.4x faster (same arithmetic, same bits).

    The residuals of the first ``skip`` samples are left out of the returned
    sum (a snapshot of the running sum is taken after the pair that holds
    sample ``skip - 1``, so the loop stays branch-light).
    """
    C1 = A1 * A1 - A2
    C2 = A1 * A2
    p = q0[o0 - 3:]  # p[k + 3] is q0[o0 + k]; o0 >= 3 (the caller's padding)
    s = q1[o1 - 3:]
    y1 = 0.0
    y2 = 0.0
    if periodic:
        start = n - warm if warm < n else 0
        for k in range(start, n):
            vk = (a0 * p[k + 3] + a1 * p[k + 2] + a2 * p[k + 1] + a3 * p[k]
                  + b0 * s[k + 3] + b1 * s[k + 2] + b2 * s[k + 1] + b3 * s[k])
            yk = (vk - A2 * y2) - A1 * y1
            y2 = y1
            y1 = yk
    sse = 0.0
    sse1 = 0.0
    snap = 0.0
    half = n // 2
    h_snap = (skip - 1) // 2 if skip > 0 else -1
    for h in range(half):
        k = 2 * h
        vk = (a0 * p[k + 3] + a1 * p[k + 2] + a2 * p[k + 1] + a3 * p[k]
              + b0 * s[k + 3] + b1 * s[k + 2] + b2 * s[k + 1] + b3 * s[k])
        vn = (a0 * p[k + 4] + a1 * p[k + 3] + a2 * p[k + 2] + a3 * p[k + 1]
              + b0 * s[k + 4] + b1 * s[k + 3] + b2 * s[k + 2] + b3 * s[k + 1])
        yk = (vk - A2 * y2) - A1 * y1
        yn = ((vn - A1 * vk) + C2 * y2) + C1 * y1
        y2 = yk
        y1 = yn
        r = u[k] - yk
        rn = u[k + 1] - yn
        sse += r * r
        sse1 += rn * rn
        if h == h_snap:
            snap = sse + sse1 - (rn * rn if skip % 2 == 1 else 0.0)
    for k in range(2 * half, n):
        vk = (a0 * p[k + 3] + a1 * p[k + 2] + a2 * p[k + 1] + a3 * p[k]
              + b0 * s[k + 3] + b1 * s[k + 2] + b2 * s[k + 1] + b3 * s[k])
        yk = (vk - A2 * y2) - A1 * y1
        y2 = y1
        y1 = yk
        r = u[k] - yk
        sse += r * r
    return (sse + sse1) - snap, y1, y2


@njit
def _recursion_n(Qp, ms, taps, pad, u, A1, A2, periodic, warm, n, skip=0):
    """Any number of channels (see _recursion_2)."""
    n_ch = Qp.shape[0]
    y1 = 0.0
    y2 = 0.0
    start = (n - warm if warm < n else 0) if periodic else n
    sse = 0.0
    for kk in range(start, n + n):
        k = kk if kk < n else kk - n
        vk = 0.0
        for c in range(n_ch):
            j = pad + k - ms[c]
            vk += (taps[c, 0] * Qp[c, j] + taps[c, 1] * Qp[c, j - 1]
                   + taps[c, 2] * Qp[c, j - 2] + taps[c, 3] * Qp[c, j - 3])
        yk = (vk - A2 * y2) - A1 * y1
        y2 = y1
        y1 = yk
        if kk >= n + skip:
            r = u[k] - yk
            sse += r * r
    return sse, y1, y2


@njit
def _plain_channel(c, ch_int, st_int):
    """True if channel ``c``'s signal does not depend on theta: no parametric stage, no
    nonlinearity (the paper's visual channel).  Its padded row is then the same for
    every parameter vector."""
    if ch_int[c, CH_NL_KIND] != NL_NONE:
        return False
    for s in range(ch_int[c, CH_NSTAGES]):
        kind = st_int[c, s, 0]
        if kind != STAGE_FIXED and kind != STAGE_NONE:
            return False
    return True


@njit
def fill_plain_rows(X, ch_int, st_int, Qp, pad, periodic):
    """Write the padded rows of the theta-independent channels into ``Qp`` once, so that
    :func:`_fused_nll` called with ``prefilled=True`` skips copying them per evaluation."""
    n = X.shape[1]
    for c in range(X.shape[0]):
        if _plain_channel(c, ch_int, st_int):
            Qp[c, pad:pad + n] = X[c]
            _fill_pads(Qp[c], n, pad, periodic)


@njit
def _fused_nll(theta, X, u, ch_int, ch_float, st_int, st_const, out_int, dt, periodic, warm,
               s2_floor, Qp, pad, q, skip=0, prefilled=False):
    """-ln L in one fused pass: per-channel taps, H_nm recursion and residual sum together.

    Handles models without gain modulation, oversampled channels or output
    nonlinearity whose delays fit the padding; returns (value, floored, handled) and handled=False
    otherwise, so the caller falls back to the general ``response_into`` path.
    The arithmetic is that of ``response_into`` regrouped into one loop, so
    the FIR work of the channels overlaps the latency of the recursion.
    The rows of the theta-independent channels come from
    :func:`fill_plain_rows`, here unless ``prefilled`` says the caller did it.
    """
    n_ch = X.shape[0]
    n = X.shape[1]
    if out_int[OUT_NL_KIND] != NL_NONE or any_oversampled(ch_int):
        return np.inf, False, False
    wn = theta[out_int[OUT_OMEGA]]
    zn = theta[out_int[OUT_ZETA]]
    w2 = wn * wn
    _, _, _, A1, A2 = tustin(w2, 0.0, 0.0, w2, 2.0 * zn * wn, 1.0, dt)
    if not stable(A1, A2):
        return np.inf, False, True
    taps = np.empty((n_ch, 4))
    ms = np.empty(n_ch, dtype=np.int64)
    if not prefilled:
        fill_plain_rows(X, ch_int, st_int, Qp, pad, periodic)
    for c in range(n_ch):
        if ch_int[c, CH_MOD_KIND] != MOD_NONE:
            return np.inf, False, False
        dd = theta[ch_int[c, CH_DELAY]] / dt
        if not (abs(dd) < pad - DELAY_MARGIN):
            return np.inf, False, False
        m = int(math.floor(dd))
        if m < 0 and not periodic:
            return np.inf, False, False  # rest, negative delay: lead-in (response_into)
        f = dd - m
        ms[c] = m
        gain = ch_float[c, CHF_GAIN_CONST] * ch_float[c, CHF_SIGN] \
            * param_or(theta, ch_int[c, CH_GAIN0], 1.0) * param_or(theta, ch_int[c, CH_GAIN1], 1.0)
        lead = param_or(theta, ch_int[c, CH_LEAD], 0.0)
        kg = gain * w2
        B0, B1, B2, _, _ = tustin(kg, kg * lead, 0.0, w2, 2.0 * zn * wn, 1.0, dt)
        taps[c, 0] = B0 * (1.0 - f)
        taps[c, 1] = B0 * f + B1 * (1.0 - f)
        taps[c, 2] = B1 * f + B2 * (1.0 - f)
        taps[c, 3] = B2 * f
        if _plain_channel(c, ch_int, st_int):
            continue  # its row is written once, by fill_plain_rows
        # channel signal (stages, nonlinearity) into the padded buffer
        src = X[c]
        for s in range(ch_int[c, CH_NSTAGES]):
            kind = st_int[c, s, 0]
            if kind == STAGE_FIXED or kind == STAGE_NONE:
                continue
            b0, b1, b2, a0, a1, a2 = stage_tf(kind, param_or(theta, st_int[c, s, 1], 0.0),
                                              param_or(theta, st_int[c, s, 2], 0.0),
                                              st_const[c, s])
            sB0, sB1, sB2, sA1, sA2 = tustin(b0, b1, b2, a0, a1, a2, dt)
            if not stable(sA1, sA2):
                return np.inf, False, True
            _filter_biquad(src, sB0, sB1, sB2, sA1, sA2, periodic, warm, q)
            src = q
        nl = ch_int[c, CH_NL_KIND]
        row = Qp[c]
        body = row[pad:pad + n]  # indexed by the loop counter: no wrap-around selects
        if nl == NL_DEADZONE:
            dz = param_or(theta, ch_int[c, CH_NL_P0], 0.0)
            for k in range(n):
                xk = src[k]
                a = abs(xk) - dz
                a = a if a > 0.0 else 0.0
                body[k] = a if xk >= 0.0 else -a
        elif nl != NL_NONE:
            p0 = param_or(theta, ch_int[c, CH_NL_P0], 0.0)
            p1 = param_or(theta, ch_int[c, CH_NL_P1], 0.0)
            for k in range(n):
                body[k] = nonlinearity(nl, src[k], p0, p1)
        else:
            body[:] = src
        _fill_pads(row, n, pad, periodic)
    if n_ch == 2:
        # The paper's model (visual + vestibular): scalar taps in registers.
        sse, y1, y2 = _recursion_2(Qp[0], Qp[1], pad + 0 - ms[0], pad + 0 - ms[1],
                                   taps[0, 0], taps[0, 1], taps[0, 2], taps[0, 3],
                                   taps[1, 0], taps[1, 1], taps[1, 2], taps[1, 3],
                                   u, A1, A2, periodic, warm, n, skip)
    else:
        sse, y1, y2 = _recursion_n(Qp, ms, taps, pad, u, A1, A2, periodic, warm, n, skip)
    if not (math.isfinite(y1) and math.isfinite(y2)):
        return np.inf, False, True
    val, fl = neg_log_lik_from_sse(sse, n - skip, s2_floor)
    return val, fl, True


def padding(n, dt, max_delay=1.5):
    """Padding (samples) of the fused path's channel buffer: delays up to ``max_delay`` s."""
    return int(min(n, math.ceil(max_delay / dt) + 8))


@njit
def neg_log_lik_one(theta, X, u, ch_int, ch_float, st_int, st_const, out_int, dt, periodic, warm,
                    s2_floor, y, q, v, Qp, pad, skip=0, prefilled=False):
    """-ln L (Eq. 4) for one full parameter vector; returns (value, floored).

    ``Qp`` is a (n_channels, n + 2 pad) work buffer for the fused path; with
    ``prefilled`` its theta-independent rows already hold their padded signal
    (:func:`fill_plain_rows`, done once per buffer by the batch).  The model runs over the whole record; the first ``skip`` samples are left out
    of Eq. 4 (N = n - skip).
    """
    val, fl, handled = _fused_nll(theta, X, u, ch_int, ch_float, st_int, st_const, out_int, dt,
                                  periodic, warm, s2_floor, Qp, pad, q, skip, prefilled)
    if handled:
        return val, fl
    ok = response_into(theta, X, ch_int, ch_float, st_int, st_const, out_int, dt, periodic,
                       warm, y, q, v)
    if not ok:
        return np.inf, False
    sse = 0.0
    for k in range(skip, u.shape[0]):
        r = u[k] - y[k]
        sse += r * r
    return neg_log_lik_from_sse(sse, u.shape[0] - skip, s2_floor)


@pjit
def neg_log_lik_batch(free, free_idx, base, X, u, ch_int, ch_float, st_int, st_const, out_int,
                      dt, periodic, warm, s2_floor, n_chunks, pad, out, floored, skip=0):
    """-ln L for every row of ``free`` (free parameters), in parallel over rows.

    Rows are dealt to ``n_chunks`` threads in turn, so each thread allocates
    its work buffers once (prange over independent parameter
    vectors, never over time steps).
    """
    m = free.shape[0]
    n = u.shape[0]
    for ch in numba.prange(n_chunks):
        y = np.empty(n)
        q = np.empty(n)
        v = np.empty(work_length(ch_int, n))
        Qp = np.empty((X.shape[0], n + 2 * pad))
        fill_plain_rows(X, ch_int, st_int, Qp, pad, periodic)
        theta = base.copy()
        # rows interleaved over threads: unstable rows return at once, so
        # contiguous blocks would leave one thread idle
        for r in range(ch, m, n_chunks):
            for j in range(free_idx.shape[0]):
                theta[free_idx[j]] = free[r, j]
            val, fl = neg_log_lik_one(theta, X, u, ch_int, ch_float, st_int, st_const, out_int,
                                      dt, periodic, warm, s2_floor, y, q, v, Qp, pad, skip,
                                      True)
            out[r] = val
            floored[r] = fl


@njit
def response(theta, X, ch_int, ch_float, st_int, st_const, out_int, dt, periodic, warm):
    """Allocate and return (u_hat, ok)."""
    n = X.shape[1]
    y = np.empty(n)
    q = np.empty(n)
    v = np.empty(work_length(ch_int, n))
    ok = response_into(theta, X, ch_int, ch_float, st_int, st_const, out_int, dt, periodic,
                       warm, y, q, v)
    return y, ok

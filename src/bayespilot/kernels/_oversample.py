"""A channel run at M times the recording's rate, folded back to the recording's rate.

A channel with ``oversample`` M > 1 (``ch_int[c, CH_OVERSAMPLE]``, see
:attr:`bayespilot.model.Channel.oversample`) computes its path after the
parametric stages on a fine grid of M points per sample interval:

    x_f = the stage output x interpolated linearly to t = (k + j / M) dt
    d_f = NL(x_f)                         the nonlinearity (dead zone) there
    v_f = sum_t c_t d_f[i - m - t]        delay m + f (fine samples), Tustin numerator at dt / M
    y_f = v_f - A1 y_f[i-1] - A2 y_f[i-2] its own H_nm, Tustin at dt / M

and adds y_f at every M-th point (i = k M) to u_hat.  A gain modulation (a
drift over the run) multiplies the channel's folded input below at each
output sample's time (:func:`modulate`).  A sampled dead zone is
the largest discretisation error of the paper's model (``docs/posteriors.md``):
between samples the dead zone's output is not the straight line the 100-Hz
model assumes, and that error sits exactly where the threshold's information
is.  The fine path removes it.

Speed (why this is written out rather than a loop over the fine grid): the
fine recursion is a chain of dependent multiply-adds M times longer than the
record.  With the state s_i = (y_i, y_{i-1}) and its one-step map T,

    s_{kM} = T^M s_{(k-1)M} + sum_{j=1..M} T^{M-j} e1 v_f[(k-1)M + j],

and by Cayley-Hamilton the decimated output y_k = y_f[kM] obeys a scalar
recursion at the recording's rate,

    y_k = tr(P) y_{k-1} - det(P) y_{k-2} + v'_k,   P = T^M,

whose input v'_k is one FIR of 2M + 3 taps ``K`` on d_f, read at every M-th
point (:func:`coefficients` derives K from T, the numerator and the delay's
fraction).  And d_f itself need not be built: where the interpolated input
stays on one linear piece of the nonlinearity over a sample interval, d_f
there is the linear interpolation of D = NL(x) at the recording's rate, so
the FIR becomes 4-5 taps on D (:func:`coarse_taps`), plus corrections
d_f - interp(D) in the few intervals where the input crosses a corner of the
dead zone (:func:`fold_channel`; every interval for a smooth nonlinearity).
Exact in real arithmetic; the cost is that of one more channel at the
recording's rate, the corners, and one more recursion.

Each routine has a tangent twin for the Jacobians (``kernels/_sensitivity.py``)
that runs the same arithmetic with derivatives alongside, so the response and
its Jacobian agree to round-off.  Periodic records wrap (the fine signal, the
FIR's taps) and the recursion is warmed up over the record's last ``warm``
samples from rest, as the recording-rate recursion is.
"""

from __future__ import annotations

import numpy as np

from .._jit import njit
from ._blocks import (NL_DEADZONE, NL_NONE, NL_SATURATION, modulation,
                      modulation_slope, nonlinearity, nonlinearity_tangent)


@njit
def coefficients(A1, A2, B0, B1, B2, f, M, dA1, dA2, dB0, dB1, dB2, df):
    """The FIR ``K`` (2M + 3 taps) and recursion (A1', A2') of the decimated fine channel, and
    their derivatives along the tangent (dA1, dA2, dB0, dB1, dB2, df) of the fine Tustin
    coefficients and the delay's fraction.

    Returns (K, dK, A1p, A2p, dA1p, dA2p).
    """
    # taps of the fractional delay and the numerator on d_f, and their tangent
    c = np.array([B0 * (1.0 - f), B0 * f + B1 * (1.0 - f), B1 * f + B2 * (1.0 - f), B2 * f])
    dc = np.array([dB0 * (1.0 - f) - B0 * df, dB0 * f + dB1 * (1.0 - f) + (B0 - B1) * df,
                   dB1 * f + dB2 * (1.0 - f) + (B1 - B2) * df, dB2 * f + B2 * df])
    # g_j = T^{M-j} e1 (j = 1..M), T = [[-A1, -A2], [1, 0]]
    g0 = np.empty(M + 1)
    g1 = np.empty(M + 1)
    dg0 = np.empty(M + 1)
    dg1 = np.empty(M + 1)
    g0[M] = 1.0
    g1[M] = 0.0
    dg0[M] = 0.0
    dg1[M] = 0.0
    for j in range(M - 1, 0, -1):
        g0[j] = -A1 * g0[j + 1] - A2 * g1[j + 1]
        dg0[j] = -dA1 * g0[j + 1] - dA2 * g1[j + 1] - A1 * dg0[j + 1] - A2 * dg1[j + 1]
        g1[j] = g0[j + 1]
        dg1[j] = dg0[j + 1]
    # P = T^M
    p00, p01, p10, p11 = 1.0, 0.0, 0.0, 1.0
    d00, d01, d10, d11 = 0.0, 0.0, 0.0, 0.0
    for _ in range(M):
        d00, d01, d10, d11 = (-dA1 * p00 - dA2 * p10 - A1 * d00 - A2 * d10,
                              -dA1 * p01 - dA2 * p11 - A1 * d01 - A2 * d11, d00, d01)
        p00, p01, p10, p11 = -A1 * p00 - A2 * p10, -A1 * p01 - A2 * p11, p00, p01
    # v'_k = a_k - p11 a_{k-1} + p01 b_{k-1}, a_k = sum_j g0_j v_f[kM - (M - j)]: as taps e_s
    # on v_f[kM - s], s = 0 .. 2M - 1
    e = np.empty(2 * M)
    de = np.empty(2 * M)
    for s in range(M):
        e[s] = g0[M - s]
        de[s] = dg0[M - s]
        j = M - s
        e[M + s] = -p11 * g0[j] + p01 * g1[j]
        de[M + s] = -d11 * g0[j] - p11 * dg0[j] + d01 * g1[j] + p01 * dg1[j]
    L = 2 * M + 3
    K = np.zeros(L)
    dK = np.zeros(L)
    for s in range(2 * M):
        for t in range(4):
            K[s + t] += e[s] * c[t]
            dK[s + t] += de[s] * c[t] + e[s] * dc[t]
    A1p = -(p00 + p11)
    A2p = p00 * p11 - p01 * p10
    dA1p = -(d00 + d11)
    dA2p = d00 * p11 + p00 * d11 - d01 * p10 - p01 * d10
    return K, dK, A1p, A2p, dA1p, dA2p


@njit
def coarse_taps(K, M, m):
    """The fine FIR on the linear interpolation of a coarse signal D, as taps on D itself.

    With m = mq M + mr (0 <= mr < M), the fine point i = (k - mq) M - o,
    o = mr + l, lies a = ceil(o / M) intervals before k - mq, at j = a M - o
    points into its interval, where the interpolation is
    (1 - j / M) D_{k - mq - a} + (j / M) D_{k - mq - a + 1}.  So
    ``sum_l K_l L_f[k M - m - l] = sum_r Q_r D_{k - mq - r}``.  Returns (Q, mq).
    """
    L = K.shape[0]
    mq = m // M
    mr = m - mq * M
    Q = np.zeros((mr + L - 1 + M - 1) // M + 1)
    for l in range(L):
        o = mr + l
        a = (o + M - 1) // M
        j = a * M - o
        Q[a] += K[l] * (1.0 - j / M)
        if j > 0:
            Q[a - 1] += K[l] * (j / M)
    return Q, mq


@njit
def _at(D, q, n, periodic):
    """D[q] with periodic wrap, or rest (0 before the start, the last value after the end)."""
    if periodic:
        return D[(q % n + n) % n]
    if q < 0:
        return 0.0
    if q >= n:
        return D[n - 1]
    return D[q]


@njit
def coarse_fir(D, Q, mq, periodic, out):
    """``out[k] = sum_r Q_r D[k - mq - r]`` (wrapped, or rest), summed in the order of r."""
    n = D.shape[0]
    R = Q.shape[0]
    lo = mq + R - 1  # from here on every index is >= 0 ...
    hi = n + mq      # ... and below n
    lo = min(max(lo, 0), n)
    hi = min(max(hi, lo), n)
    for k in range(lo):
        acc = 0.0
        for r in range(R):
            acc += Q[r] * _at(D, k - mq - r, n, periodic)
        out[k] = acc
    # the bulk one tap at a time: independent over k, so it vectorises
    ov = out[lo:hi]
    for kk in range(hi - lo):
        ov[kk] = 0.0
    for r in range(R):
        qr = Q[r]
        Dv = D[lo - mq - r:]  # Dv[kk] is D[lo + kk - mq - r]
        for kk in range(hi - lo):
            ov[kk] += qr * Dv[kk]
    for k in range(hi, n):
        acc = 0.0
        for r in range(R):
            acc += Q[r] * _at(D, k - mq - r, n, periodic)
        out[k] = acc


@njit
def nl_record(nl, x, p0, p1, D):
    """``D = NL(x)`` sample by sample (the dead zone written out: the generic call is slow)."""
    if nl == NL_DEADZONE:
        for k in range(x.shape[0]):
            xk = x[k]
            a = abs(xk) - p0
            a = a if a > 0.0 else 0.0
            D[k] = a if xk > 0.0 else -a
    elif nl == NL_NONE:
        D[:] = x
    else:
        for k in range(x.shape[0]):
            D[k] = nonlinearity(nl, x[k], p0, p1)


@njit
def _piece(nl, x, p0):
    """Which linear piece of ``nl`` x lies on (-1, 0, 1), without branches; a smooth ``nl``
    (the soft dead zone) has none, so every sample is its own piece (see :func:`fold_channel`)."""
    if nl == NL_DEADZONE or nl == NL_SATURATION:
        return np.int64(x > p0) - np.int64(x < -p0)
    return np.int64(0)


@njit
def _piecewise(nl):
    """True if ``nl`` is linear or piecewise linear (corrections only where a piece ends)."""
    return nl == NL_NONE or nl == NL_DEADZONE or nl == NL_SATURATION


@njit
def fold_channel(src, M, m, K, periodic, nl, p0, p1, D, out):
    """``out[k] = sum_l K_l d_f[k M - m - l]``, d_f = NL(x_f) on the fine grid, computed
    as the coarse FIR of D = NL(src) plus corrections in the intervals where NL is not
    linear along the interpolation (``D`` is a work buffer of the record's length)."""
    n = src.shape[0]
    L = K.shape[0]
    nl_record(nl, src, p0, p1, D)
    Q, mq = coarse_taps(K, M, m)
    coarse_fir(D, Q, mq, periodic, out)
    if nl == NL_NONE:
        return
    every = not _piecewise(nl)
    # rest: the interval before the start too, from x = 0 (its D is NL(0) = 0)
    first = 0 if periodic else -1
    r1 = _piece(nl, src[0] if periodic else 0.0, p0)
    for q in range(first, n):
        x0 = src[q] if q >= 0 else 0.0
        r0 = r1
        if q + 1 < n:
            x1 = src[q + 1]
            D1 = D[q + 1]
        elif periodic:
            x1 = src[0]
            D1 = D[0]
        else:
            continue  # rest: held after the end, linear
        r1 = _piece(nl, x1, p0)
        if r0 == r1 and not every:
            continue  # one linear piece: the interpolation of D is exact
        D0 = D[q] if q >= 0 else 0.0
        dx = x1 - x0
        for j in range(1, M):
            e = nonlinearity(nl, x0 + (j / M) * dx, p0, p1) - ((1.0 - j / M) * D0 + (j / M) * D1)
            if e == 0.0:
                continue
            i = q * M + j  # contributes K_l e to out[k] for l = k M - m - i in [0, L)
            k0 = (i + m + M - 1) // M
            for k in range(k0, (i + m + L - 1) // M + 1):
                kw = k
                if kw >= n or kw < 0:
                    if not periodic:
                        continue  # rest: no output outside the record
                    kw = (kw % n + n) % n
                out[kw] += K[k * M - m - i] * e
    return


@njit
def fold_channel_tangent(src, dsrc, M, m, K, dK, periodic, nl, p0, p1, dp0, dp1, D, dD, out,
                         dout):
    """:func:`fold_channel` and its tangent along (dsrc, dK, dp0, dp1); the same arithmetic
    for ``out``, so the two agree to the bit."""
    n = src.shape[0]
    L = K.shape[0]
    nl_record(nl, src, p0, p1, D)
    for k in range(n):
        dD[k] = dsrc[k] if nl == NL_NONE else nonlinearity_tangent(nl, src[k], p0, p1, dsrc[k],
                                                                   dp0, dp1)
    Q, mq = coarse_taps(K, M, m)
    dQ, _ = coarse_taps(dK, M, m)
    coarse_fir(D, Q, mq, periodic, out)
    for k in range(n):  # d(sum Q D) = sum dQ D + Q dD
        acc = 0.0
        for r in range(Q.shape[0]):
            q = k - mq - r
            acc += dQ[r] * _at(D, q, n, periodic) + Q[r] * _at(dD, q, n, periodic)
        dout[k] = acc
    if nl == NL_NONE:
        return
    every = not _piecewise(nl)
    first = 0 if periodic else -1
    r1 = _piece(nl, src[0] if periodic else 0.0, p0)
    for q in range(first, n):
        x0 = src[q] if q >= 0 else 0.0
        t0 = dsrc[q] if q >= 0 else 0.0
        r0 = r1
        if q + 1 < n:
            x1 = src[q + 1]
            t1 = dsrc[q + 1]
            D1 = D[q + 1]
            dD1 = dD[q + 1]
        elif periodic:
            x1 = src[0]
            t1 = dsrc[0]
            D1 = D[0]
            dD1 = dD[0]
        else:
            continue
        r1 = _piece(nl, x1, p0)
        if r0 == r1 and not every:
            continue
        D0 = D[q] if q >= 0 else 0.0
        dD0 = dD[q] if q >= 0 else 0.0
        dx = x1 - x0
        for j in range(1, M):
            x = x0 + (j / M) * dx
            e = nonlinearity(nl, x, p0, p1) - ((1.0 - j / M) * D0 + (j / M) * D1)
            de = (nonlinearity_tangent(nl, x, p0, p1, t0 + (j / M) * (t1 - t0), dp0, dp1)
                  - ((1.0 - j / M) * dD0 + (j / M) * dD1))
            i = q * M + j
            k0 = (i + m + M - 1) // M
            for k in range(k0, (i + m + L - 1) // M + 1):
                kw = k
                if kw >= n or kw < 0:
                    if not periodic:
                        continue
                    kw = (kw % n + n) % n
                l = k * M - m - i
                if e != 0.0:
                    out[kw] += K[l] * e
                dout[kw] += dK[l] * e + K[l] * de


@njit
def modulate(v, mod_kind, mp, dmp, dv, tangent, pre=0):
    """The channel's gain modulation on its folded input, at the output sample's time
    (``v *= g(k / n)``; with ``tangent``, ``dv = g dv + dg v`` first).

    ``pre``: ``v`` starts ``pre`` samples before the record (a lead-in from rest, see
    ``_response.lead_in``), so its sample k is at the record's time k - pre (g
    held at its start value before the start) and the record has v.shape[0] - pre samples."""
    n = v.shape[0]
    for k in range(n):
        frac = (k - pre) / (n - pre)
        g = modulation(mod_kind, frac, mp)
        if tangent:
            dg = dmp * modulation_slope(mod_kind, frac)
            dv[k] = g * dv[k] + dg * v[k]
        v[k] = g * v[k]


@njit
def recursion_add(v, A1, A2, periodic, warm, w):
    """y_k = v_k - A1 y_{k-1} - A2 y_{k-2}, warmed up over the last ``warm`` samples when
    periodic, added to ``w``.  Returns the last two states (for a finiteness check).

    ``(v - A2 y2) - A1 y1`` keeps one multiply-add on the loop-carried path.  The
    recording-rate H_nm recursion of ``_response.response_into`` is this one too."""
    n = v.shape[0]
    y1 = 0.0
    y2 = 0.0
    if periodic:
        start = n - warm if warm < n else 0
        for k in range(start, n):
            yk = (v[k] - A2 * y2) - A1 * y1
            y2 = y1
            y1 = yk
    for k in range(n):
        yk = (v[k] - A2 * y2) - A1 * y1
        y2 = y1
        y1 = yk
        w[k] += yk
    return y1, y2


@njit
def recursion_add_tangent(v, dv, A1, A2, dA1, dA2, periodic, warm, w, dw):
    """:func:`recursion_add` and its tangent.  Returns (y1, dy1), the last states."""
    n = v.shape[0]
    y1 = 0.0
    y2 = 0.0
    t1 = 0.0
    t2 = 0.0
    start = n
    if periodic:
        start = n - warm if warm < n else 0
    for kk in range(start, n + n):
        k = kk if kk < n else kk - n
        yk = (v[k] - A2 * y2) - A1 * y1
        tk = dv[k] - dA1 * y1 - dA2 * y2 - A1 * t1 - A2 * t2
        y2 = y1
        y1 = yk
        t2 = t1
        t1 = tk
        if kk >= n:
            w[k] += yk
            dw[k] += tk
    return y1, t1

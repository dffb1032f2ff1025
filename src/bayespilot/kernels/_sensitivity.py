"""Exact parameter sensitivities of the pilot-model response (forward mode).

``response_tangent`` runs the same discrete computation as
``_response.response_into`` and, alongside it, its derivative along one
direction ``dtheta`` of the full parameter vector: the discrete-time
sensitivity equations of every block (Tustin coefficients, stage filters,
nonlinearity, fractional delay, H_nm recursion).  The Jacobian of u_hat with
respect to a set of parameters is one tangent run per parameter.  These are
the derivatives of the computation the likelihood actually performs, exact to
round-off (no finite differences); where the computation is not
differentiable (a delay at an integer number of samples, the dead zone's
corners) they are the one-sided derivative from above.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import njit
from . import _oversample as OV
from ._blocks import (MOD_NONE, NL_NONE, STAGE_FIXED, STAGE_HIGHPASS1, STAGE_HIGHPASS2,
                      STAGE_LOWPASS1, STAGE_LOWPASS2, STAGE_NONE, modulation, modulation_slope,
                      nonlinearity,
                      nonlinearity_tangent, param_or, stable, stage_tf, tustin)
from ._response import (_tap, _with_lead_in, any_oversampled, fine_lead_in, lead_in,
                        oversampling, periodic_state_tangent, CH_DELAY, CH_GAIN0, CH_GAIN1, CH_LEAD, CH_MOD_KIND, CH_MOD_P0,
                        CH_NL_KIND, CH_NL_P0, CH_NL_P1, CH_NSTAGES, CHF_GAIN_CONST, CHF_SIGN,
                        OUT_NL_KIND, OUT_NL_P0, OUT_NL_P1, OUT_OMEGA, OUT_ZETA)


@njit
def _dparam(dtheta, idx):
    return 0.0 if idx < 0 else dtheta[idx]


@njit
def stage_tf_tangent(kind, p0, p1, dp0, dp1):
    """Derivative of ``stage_tf`` coefficients (b0, b1, b2, a0, a1, a2) along (dp0, dp1)."""
    if kind == STAGE_HIGHPASS1:
        return 0.0, 0.0, 0.0, dp0, 0.0, 0.0
    if kind == STAGE_LOWPASS2:
        dw2 = 2.0 * p0 * dp0
        return dw2, 0.0, 0.0, dw2, 2.0 * (dp1 * p0 + p1 * dp0), 0.0
    if kind == STAGE_LOWPASS1:
        return 0.0, 0.0, 0.0, 0.0, dp0, 0.0
    if kind == STAGE_HIGHPASS2:
        return 0.0, 0.0, 0.0, 2.0 * p0 * dp0, 2.0 * (dp1 * p0 + p1 * dp0), 0.0
    return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0


@njit
def tustin_tangent(b0, b1, b2, a0, a1, a2, db0, db1, db2, da0, da1, da2, dt):
    """Derivative of ``tustin`` (B0, B1, B2, A1, A2) along the coefficient tangent."""
    c = 2.0 / dt
    if a2 == 0.0 and b2 == 0.0:
        d0 = a1 * c + a0
        dd0 = da1 * c + da0
        n0 = b1 * c + b0
        n1 = b0 - b1 * c
        d1 = a0 - a1 * c
        dn0 = db1 * c + db0
        dn1 = db0 - db1 * c
        dd1 = da0 - da1 * c
        return ((dn0 * d0 - n0 * dd0) / (d0 * d0), (dn1 * d0 - n1 * dd0) / (d0 * d0), 0.0,
                (dd1 * d0 - d1 * dd0) / (d0 * d0), 0.0)
    c2 = c * c
    d0 = a2 * c2 + a1 * c + a0
    d1 = 2.0 * (a0 - a2 * c2)
    d2 = a2 * c2 - a1 * c + a0
    n0 = b2 * c2 + b1 * c + b0
    n1 = 2.0 * (b0 - b2 * c2)
    n2 = b2 * c2 - b1 * c + b0
    dd0 = da2 * c2 + da1 * c + da0
    dd1 = 2.0 * (da0 - da2 * c2)
    dd2 = da2 * c2 - da1 * c + da0
    dn0 = db2 * c2 + db1 * c + db0
    dn1 = 2.0 * (db0 - db2 * c2)
    dn2 = db2 * c2 - db1 * c + db0
    q = d0 * d0
    return ((dn0 * d0 - n0 * dd0) / q, (dn1 * d0 - n1 * dd0) / q, (dn2 * d0 - n2 * dd0) / q,
            (dd1 * d0 - d1 * dd0) / q, (dd2 * d0 - d2 * dd0) / q)


@njit
def _filter_tangent(x, dx, B0, B1, B2, A1, A2, dB0, dB1, dB2, dA1, dA2, periodic, warm, y, dy):
    """A biquad and its tangent: y = F(x), dy = F(dx) + (dF) x.

    Periodic: the four output states (y and dy, two each) start from their
    exact periodic steady state, as in ``_response._filter_biquad``.
    """
    n = x.shape[0]
    x1 = 0.0
    x2 = 0.0
    y1 = 0.0
    y2 = 0.0
    dx1 = 0.0
    dx2 = 0.0
    dy1 = 0.0
    dy2 = 0.0
    if periodic and n >= 2:
        # the zero-state run in delta form, as in _response._filter_biquad (v = y_k - y_k-1
        # and its tangent dv): v_k = in_k - c0 y_k-1 + A2 v_k-1, and along the tangent
        # dv_k = din_k - dc0 y_k-1 + dA2 v_k-1 - c0 dy_k-1 + A2 dv_k-1
        x1, x2, dx1, dx2 = x[n - 1], x[n - 2], dx[n - 1], dx[n - 2]
        c0 = (1.0 + A1) + A2
        dc0 = dA1 + dA2
        v1 = 0.0
        dv1 = 0.0
        for k in range(n):
            xk = x[k]
            dxk = dx[k]
            vk = B0 * xk + B1 * x1 + B2 * x2 - c0 * y1 + A2 * v1
            dvk = (dB0 * xk + dB1 * x1 + dB2 * x2 - dc0 * y1 + dA2 * v1
                   + B0 * dxk + B1 * dx1 + B2 * dx2 - c0 * dy1 + A2 * dv1)
            x2, x1, y1, v1 = x1, xk, y1 + vk, vk
            dx2, dx1, dy1, dv1 = dx1, dxk, dy1 + dvk, dvk
        y1, y2, dy1, dy2 = periodic_state_tangent(A1, A2, dA1, dA2, y1, v1, dy1, dv1, n)
        x1, x2, dx1, dx2 = x[n - 1], x[n - 2], dx[n - 1], dx[n - 2]
    for k in range(n):
        xk = x[k]
        dxk = dx[k]
        yk = B0 * xk + B1 * x1 + B2 * x2 - A1 * y1 - A2 * y2
        dyk = (dB0 * xk + dB1 * x1 + dB2 * x2 - dA1 * y1 - dA2 * y2
               + B0 * dxk + B1 * dx1 + B2 * dx2 - A1 * dy1 - A2 * dy2)
        x2, x1, y2, y1 = x1, xk, y1, yk
        dx2, dx1, dy2, dy1 = dx1, dxk, dy1, dyk
        y[k] = yk
        dy[k] = dyk


@njit
def _accumulate_tangent(v, dv, src, dsrc, m, f, df, B0, B1, B2, dB0, dB1, dB2, mod_kind, mp,
                        dmp, periodic, pre=0):
    """The channel's delayed, gain-modulated Tustin numerator into ``v`` and its tangent into
    ``dv`` (``_response._accumulate_delayed`` / ``_accumulate_modulated`` with derivatives).

    ``pre`` (rest only): the arrays start with a lead-in of ``pre`` samples before the record
    (``_response.lead_in``), so sample k is at the record's time k - pre."""
    n = src.shape[0]
    d1 = 0.0
    d2 = 0.0
    t1 = 0.0
    t2 = 0.0
    start = -2 if periodic else 0
    for k in range(start, n):
        j = k - m
        sa = _tap(src, j, n, periodic)
        sb = _tap(src, j - 1, n, periodic)
        dsa = _tap(dsrc, j, n, periodic)
        dsb = _tap(dsrc, j - 1, n, periodic)
        dk = (1.0 - f) * sa + f * sb
        tk = (1.0 - f) * dsa + f * dsb + df * (sb - sa)
        if mod_kind != MOD_NONE:
            frac = ((k + n) % n) / n if periodic else (k - pre) / (n - pre)
            g = modulation(mod_kind, frac, mp)
            dg = dmp * modulation_slope(mod_kind, frac)
            tk = g * tk + dg * dk
            dk = g * dk
        if k >= 0:
            v[k] += B0 * dk + B1 * d1 + B2 * d2
            dv[k] += dB0 * dk + dB1 * d1 + dB2 * d2 + B0 * tk + B1 * t1 + B2 * t2
        d2 = d1
        d1 = dk
        t2 = t1
        t1 = tk


@njit
def response_tangent(theta, dtheta, X, ch_int, ch_float, st_int, st_const, out_int, dt, periodic,
                     warm, y, dy):
    """u_hat into ``y`` and its derivative along ``dtheta`` into ``dy``; False if unstable."""
    n_ch = X.shape[0]
    n = X.shape[1]
    wn = theta[out_int[OUT_OMEGA]]
    zn = theta[out_int[OUT_ZETA]]
    dwn = _dparam(dtheta, out_int[OUT_OMEGA])
    dzn = _dparam(dtheta, out_int[OUT_ZETA])
    w2 = wn * wn
    dw2 = 2.0 * wn * dwn
    a1c = 2.0 * zn * wn
    da1c = 2.0 * (dzn * wn + zn * dwn)
    _, _, _, A1, A2 = tustin(w2, 0.0, 0.0, w2, a1c, 1.0, dt)
    if not stable(A1, A2):
        return False
    _, _, _, dA1, dA2 = tustin_tangent(w2, 0.0, 0.0, w2, a1c, 1.0, dw2, 0.0, 0.0, dw2, da1c, 0.0, dt)
    # rest with a negative delay: v, dv and the recursion start pre samples before the record
    pre = 0 if periodic else lead_in(theta, ch_int, dt, n)
    v = np.zeros(n + pre)
    dv = np.zeros(n + pre)
    q = np.empty(n)
    dq = np.empty(n)
    q2 = np.empty(n)
    dq2 = np.empty(n)
    zero = np.zeros(n)
    fine = any_oversampled(ch_int)
    wf = np.zeros(n if fine else 1)  # the oversampled channels' share of u_hat ...
    dwf = np.zeros(n if fine else 1)  # ... and of its tangent
    D = np.empty(n if fine else 1)  # their dead-zone output at the recording's rate ...
    dD = np.empty(n if fine else 1)  # ... and its tangent
    for c in range(n_ch):
        src = X[c]
        dsrc = zero
        nst = ch_int[c, CH_NSTAGES]
        for s in range(nst):
            kind = st_int[c, s, 0]
            if kind == STAGE_FIXED or kind == STAGE_NONE:
                continue
            i0 = st_int[c, s, 1]
            i1 = st_int[c, s, 2]
            p0 = param_or(theta, i0, 0.0)
            p1 = param_or(theta, i1, 0.0)
            b0, b1, b2, a0, a1, a2 = stage_tf(kind, p0, p1, st_const[c, s])
            db0, db1, db2, da0, da1, da2 = stage_tf_tangent(kind, p0, p1, _dparam(dtheta, i0),
                                                            _dparam(dtheta, i1))
            sB0, sB1, sB2, sA1, sA2 = tustin(b0, b1, b2, a0, a1, a2, dt)
            if not stable(sA1, sA2):
                return False
            tB0, tB1, tB2, tA1, tA2 = tustin_tangent(b0, b1, b2, a0, a1, a2, db0, db1, db2,
                                                     da0, da1, da2, dt)
            _filter_tangent(src, dsrc, sB0, sB1, sB2, sA1, sA2, tB0, tB1, tB2, tA1, tA2,
                            periodic, warm, q2, dq2)
            for k in range(n):
                q[k] = q2[k]
                dq[k] = dq2[k]
            src = q
            dsrc = dq
        ig0 = ch_int[c, CH_GAIN0]
        ig1 = ch_int[c, CH_GAIN1]
        g0 = param_or(theta, ig0, 1.0)
        g1 = param_or(theta, ig1, 1.0)
        cst = ch_float[c, CHF_GAIN_CONST] * ch_float[c, CHF_SIGN]
        gain = cst * g0 * g1
        dgain = cst * (_dparam(dtheta, ig0) * g1 + g0 * _dparam(dtheta, ig1))
        il = ch_int[c, CH_LEAD]
        lead = param_or(theta, il, 0.0)
        dlead = _dparam(dtheta, il)
        kg = gain * w2
        dkg = dgain * w2 + gain * dw2
        nl = ch_int[c, CH_NL_KIND]
        i0 = ch_int[c, CH_NL_P0]
        i1 = ch_int[c, CH_NL_P1]
        p0 = param_or(theta, i0, 0.0)
        p1 = param_or(theta, i1, 0.0)
        dp0 = _dparam(dtheta, i0)
        dp1 = _dparam(dtheta, i1)
        mod_kind = ch_int[c, CH_MOD_KIND]
        imod = ch_int[c, CH_MOD_P0]
        mp = param_or(theta, imod, 0.0)
        dmp = _dparam(dtheta, imod)
        idl = ch_int[c, CH_DELAY]
        M = oversampling(ch_int, c)
        if M > 1:
            # as _response.response_into runs it (kernels/_oversample.py), with tangents
            dtf = dt / M
            B0, B1, B2, fA1, fA2 = tustin(kg, kg * lead, 0.0, w2, a1c, 1.0, dtf)
            dB0, dB1, dB2, fdA1, fdA2 = tustin_tangent(kg, kg * lead, 0.0, w2, a1c, 1.0, dkg,
                                                       dkg * lead + kg * dlead, 0.0, dw2, da1c,
                                                       0.0, dtf)
            dd = theta[idl] / dtf
            if not (abs(dd) < n * M - 4):
                return False
            m = int(math.floor(dd))
            K, dK, A1p, A2p, dA1p, dA2p = OV.coefficients(fA1, fA2, B0, B1, B2, dd - m, M,
                                                          fdA1, fdA2, dB0, dB1, dB2,
                                                          _dparam(dtheta, idl) / dtf)
            pc = 0 if periodic else fine_lead_in(m, M)
            if pc > 0:
                # rest, negative delay: as _response.response_into, from rest pc samples early
                bx = np.empty(n + pc)
                dbx = np.empty(n + pc)
                OV.fold_channel_tangent(_with_lead_in(src, pc), _with_lead_in(dsrc, pc), M,
                                        m, K, dK, periodic, nl, p0, p1, dp0, dp1,
                                        np.empty(n + pc), np.empty(n + pc), bx, dbx)
                if mod_kind != MOD_NONE:
                    OV.modulate(bx, mod_kind, mp, dmp, dbx, True, pc)
                wx = np.zeros(n + pc)
                dwx = np.zeros(n + pc)
                f1, df1 = OV.recursion_add_tangent(bx, dbx, A1p, A2p, dA1p, dA2p, periodic, warm,
                                                   wx, dwx)
                for k in range(n):
                    wf[k] += wx[pc + k]
                    dwf[k] += dwx[pc + k]
            else:
                OV.fold_channel_tangent(src, dsrc, M, m, K, dK, periodic, nl, p0, p1, dp0, dp1,
                                        D, dD, q2, dq2)
                if mod_kind != MOD_NONE:
                    OV.modulate(q2, mod_kind, mp, dmp, dq2, True)
                f1, df1 = OV.recursion_add_tangent(q2, dq2, A1p, A2p, dA1p, dA2p, periodic, warm,
                                                   wf, dwf)
            if not (math.isfinite(f1) and math.isfinite(df1)):
                return False
            continue
        if nl != NL_NONE:
            for k in range(n):
                xk = src[k]
                q2[k] = nonlinearity(nl, xk, p0, p1)
                dq2[k] = nonlinearity_tangent(nl, xk, p0, p1, dsrc[k], dp0, dp1)
            for k in range(n):
                q[k] = q2[k]
                dq[k] = dq2[k]
            src = q
            dsrc = dq
        B0, B1, B2, _, _ = tustin(kg, kg * lead, 0.0, w2, a1c, 1.0, dt)
        dB0, dB1, dB2, _, _ = tustin_tangent(kg, kg * lead, 0.0, w2, a1c, 1.0,
                                             dkg, dkg * lead + kg * dlead, 0.0, dw2, da1c, 0.0, dt)
        dd = theta[idl] / dt
        if not (abs(dd) < n - 4):
            return False
        m = int(math.floor(dd))
        if pre > 0:
            src = _with_lead_in(src, pre)  # v and src both start pre samples early: same m
            dsrc = _with_lead_in(dsrc, pre)
        _accumulate_tangent(v, dv, src, dsrc, m, dd - m, _dparam(dtheta, idl) / dt, B0, B1,
                            B2, dB0, dB1, dB2, mod_kind, mp, dmp, periodic, pre)
    for k in range(n):
        y[k] = 0.0
        dy[k] = 0.0
    if pre > 0:
        yx = np.zeros(n + pre)
        dyx = np.zeros(n + pre)
        y1, dy1 = OV.recursion_add_tangent(v, dv, A1, A2, dA1, dA2, periodic, warm, yx, dyx)
        for k in range(n):
            y[k] = yx[pre + k]
            dy[k] = dyx[pre + k]
    else:
        y1, dy1 = OV.recursion_add_tangent(v, dv, A1, A2, dA1, dA2, periodic, warm, y, dy)
    if fine:
        for k in range(n):
            y[k] += wf[k]
            dy[k] += dwf[k]
    out_nl = out_int[OUT_NL_KIND]
    if out_nl != NL_NONE:
        i0 = out_int[OUT_NL_P0]
        i1 = out_int[OUT_NL_P1]
        o0 = param_or(theta, i0, 0.0)
        o1 = param_or(theta, i1, 0.0)
        do0 = _dparam(dtheta, i0)
        do1 = _dparam(dtheta, i1)
        for k in range(n):
            dy[k] = nonlinearity_tangent(out_nl, y[k], o0, o1, dy[k], do0, do1)
            y[k] = nonlinearity(out_nl, y[k], o0, o1)
    return math.isfinite(y1) and math.isfinite(dy1)


@njit
def jacobian(theta, cols, X, ch_int, ch_float, st_int, st_const, out_int, dt, periodic, warm):
    """(u_hat, J) with J[:, j] = d u_hat / d theta[cols[j]]; ok flag."""
    n = X.shape[1]
    y = np.empty(n)
    J = np.empty((n, cols.shape[0]))
    dy = np.empty(n)
    dtheta = np.zeros(theta.shape[0])
    ok = True
    for j in range(cols.shape[0]):
        dtheta[:] = 0.0
        dtheta[cols[j]] = 1.0
        ok = response_tangent(theta, dtheta, X, ch_int, ch_float, st_int, st_const, out_int, dt,
                              periodic, warm, y, dy) and ok
        for k in range(n):
            J[k, j] = dy[k]
    return y, J, ok

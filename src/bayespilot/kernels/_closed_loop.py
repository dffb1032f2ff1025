"""Closed-loop simulation of the tracking task (Fig. 2) with a pilot model plan.

Fixed-step RK4 at a step h finer than the recording's (so that fitting
synthetic data is not the same discrete computation that generated it).
All linear blocks are integrated in continuous-time state-space form
(``biquad_ss``); delays read a history of each channel's post-nonlinearity
signal with linear interpolation (between the last stored step and the
current stage value when tau < h), so results are continuous in tau.

State layout: plant states, then per channel 2 states per stage, then per
channel 2 states of K_c (1 + T_c s) H_nm(s) in controllable canonical form:
z1' = z2, z2' = -w^2 z1 - 2 zeta w z2 + in_c, out_c = w^2 (z1 + T_c z2).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import njit
from ._blocks import (MOD_NONE, NL_NONE, STAGE_NONE, biquad_ss, modulation, nonlinearity,
                      param_or, stage_tf)
from ._response import (CH_DELAY, CH_GAIN0, CH_GAIN1, CH_LEAD, CH_MOD_KIND, CH_MOD_P0,
                        CH_NL_KIND, CH_NL_P0, CH_NL_P1, CH_NSTAGES, CH_SOURCE, CHF_GAIN_CONST,
                        CHF_SIGN, OUT_NL_KIND, OUT_NL_P0, OUT_NL_P1, OUT_OMEGA, OUT_ZETA)

SRC_E, SRC_THETA_DDOT_M, SRC_THETA_M, SRC_THETA = 0, 1, 2, 3
# Columns of the per-step output table ``sig``.
SIG_E, SIG_U, SIG_THDDM, SIG_THETA, SIG_FT, SIG_FD = range(6)
N_SIG = 6


@njit
def _derivs(t, x, jh, frac_h, ft, fd, nrem, Ap, Bp, C0, C2, D2, k_du, k_theta, ch_int, ch_float,
            stss, theta, out_int, gains, leads, mods, taus, hist, k_now, h, t_meas0, t_meas,
            dx, sig, xpre, qcur):
    """Derivative of the closed-loop state at time t; fills sig, xpre and qcur.

    ``jh`` indexes the half-step forcing/remnant tables at t; ``frac_h`` is the
    fraction of a half step beyond it (0 for the tabulated times).
    """
    npl = Ap.shape[0]
    n_ch = ch_int.shape[0]
    nst_max = stss.shape[1]
    wn = theta[out_int[OUT_OMEGA]]
    zn = theta[out_int[OUT_ZETA]]
    w2 = wn * wn
    base_nm = npl + n_ch * 2 * nst_max
    # pilot output from the H_nm states (no feedthrough) plus remnant
    ulin = 0.0
    for c in range(n_ch):
        z1 = x[base_nm + 2 * c]
        z2 = x[base_nm + 2 * c + 1]
        ulin += w2 * (z1 + leads[c] * z2)
    n_t = nrem[jh] + frac_h * (nrem[jh + 1] - nrem[jh])
    u = ulin + n_t
    onl = out_int[OUT_NL_KIND]
    if onl != NL_NONE:
        u = nonlinearity(onl, u, param_or(theta, out_int[OUT_NL_P0], 0.0),
                         param_or(theta, out_int[OUT_NL_P1], 0.0))
    f_t = ft[jh] + frac_h * (ft[jh + 1] - ft[jh])
    f_d = fd[jh] + frac_h * (fd[jh + 1] - fd[jh])
    delta = k_du * u + f_d
    th = 0.0
    thdd = D2 * delta
    for i in range(npl):
        th += C0[i] * x[i]
        thdd += C2[i] * x[i]
        acc = Bp[i] * delta
        for j in range(npl):
            acc += Ap[i, j] * x[j]
        dx[i] = acc
    e = f_t - th
    sig[SIG_E] = e
    sig[SIG_U] = u
    sig[SIG_THDDM] = k_theta * thdd
    sig[SIG_THETA] = th
    sig[SIG_FT] = f_t
    sig[SIG_FD] = f_d
    for c in range(n_ch):
        src = ch_int[c, CH_SOURCE]
        if src == SRC_E:
            s_in = e
        elif src == SRC_THETA_DDOT_M:
            s_in = k_theta * thdd
        elif src == SRC_THETA_M:
            s_in = k_theta * th
        else:
            s_in = th
        b0 = npl + c * 2 * nst_max
        for s in range(ch_int[c, CH_NSTAGES]):
            order = stss[c, s, 0]
            al0 = stss[c, s, 1]
            al1 = stss[c, s, 2]
            c0 = stss[c, s, 3]
            c1 = stss[c, s, 4]
            d = stss[c, s, 5]
            x1 = x[b0 + 2 * s]
            x2 = x[b0 + 2 * s + 1]
            if order == 2.0:
                dx[b0 + 2 * s] = x2
                dx[b0 + 2 * s + 1] = -al0 * x1 - al1 * x2 + s_in
                s_in = c0 * x1 + c1 * x2 + d * s_in
            elif order == 1.0:
                dx[b0 + 2 * s] = -al0 * x1 + s_in
                dx[b0 + 2 * s + 1] = 0.0
                s_in = c0 * x1 + d * s_in
            else:
                dx[b0 + 2 * s] = 0.0
                dx[b0 + 2 * s + 1] = 0.0
                s_in = d * s_in
        for s in range(ch_int[c, CH_NSTAGES], nst_max):
            dx[b0 + 2 * s] = 0.0
            dx[b0 + 2 * s + 1] = 0.0
        xpre[c] = s_in
        nl = ch_int[c, CH_NL_KIND]
        if nl != NL_NONE:
            s_in = nonlinearity(nl, s_in, param_or(theta, ch_int[c, CH_NL_P0], 0.0),
                                param_or(theta, ch_int[c, CH_NL_P1], 0.0))
        qcur[c] = s_in
    # delayed channel signals drive the H_nm states
    for c in range(n_ch):
        td = t - taus[c]
        p = td / h
        if p < 0.0:
            qd = 0.0  # at rest before the start of the simulation
        elif p >= k_now:
            t_k = k_now * h
            span = t - t_k
            if span > 0.0:
                qd = hist[c, k_now] + (td - t_k) / span * (qcur[c] - hist[c, k_now])
            else:
                qd = qcur[c]
        else:
            kk = int(p)
            fr = p - kk
            qd = hist[c, kk] + fr * (hist[c, kk + 1] - hist[c, kk])
        g = gains[c]
        mk = ch_int[c, CH_MOD_KIND]
        if mk != MOD_NONE:
            g *= modulation(mk, (t - t_meas0) / t_meas, mods[c])
        z1 = x[base_nm + 2 * c]
        z2 = x[base_nm + 2 * c + 1]
        dx[base_nm + 2 * c] = z2
        dx[base_nm + 2 * c + 1] = -w2 * z1 - 2.0 * zn * wn * z2 + g * qd


@njit
def simulate_closed_loop(theta, ch_int, ch_float, st_int, st_const, out_int, Ap, Bp, C0, C2, D2,
                         k_du, k_theta, ft, fd, nrem, h, n_steps, decim, k_start, t_meas):
    """Integrate the loop for ``n_steps`` steps of ``h``; record every ``decim``-th from ``k_start``.

    ``ft``, ``fd``, ``nrem`` are tabulated at half steps (length 2 n_steps + 2).
    Returns (sig, xpre, qpost, ok): recorded signals (n_rec, N_SIG), each
    channel's pre- and post-nonlinearity signal (n_ch, n_rec), and False if
    the loop diverged.
    """
    npl = Ap.shape[0]
    n_ch = ch_int.shape[0]
    nst_max = st_int.shape[1]
    nx = npl + n_ch * (2 * nst_max + 2)
    stss = np.zeros((n_ch, nst_max, 6))
    gains = np.empty(n_ch)
    leads = np.empty(n_ch)
    mods = np.empty(n_ch)
    taus = np.empty(n_ch)
    for c in range(n_ch):
        for s in range(ch_int[c, CH_NSTAGES]):
            kind = st_int[c, s, 0]
            if kind == STAGE_NONE:
                continue
            b0, b1, b2, a0, a1, a2 = stage_tf(kind, param_or(theta, st_int[c, s, 1], 0.0),
                                              param_or(theta, st_int[c, s, 2], 0.0),
                                              st_const[c, s])
            order, al0, al1, c0, c1, d = biquad_ss(b0, b1, b2, a0, a1, a2)
            stss[c, s, 0] = order
            stss[c, s, 1] = al0
            stss[c, s, 2] = al1
            stss[c, s, 3] = c0
            stss[c, s, 4] = c1
            stss[c, s, 5] = d
        gains[c] = ch_float[c, CHF_GAIN_CONST] * ch_float[c, CHF_SIGN] \
            * param_or(theta, ch_int[c, CH_GAIN0], 1.0) * param_or(theta, ch_int[c, CH_GAIN1], 1.0)
        leads[c] = param_or(theta, ch_int[c, CH_LEAD], 0.0)
        mods[c] = param_or(theta, ch_int[c, CH_MOD_P0], 0.0)
        taus[c] = theta[ch_int[c, CH_DELAY]]
    n_rec = (n_steps - k_start) // decim
    sig_rec = np.zeros((n_rec, 6))
    xpre_rec = np.zeros((n_ch, n_rec))
    q_rec = np.zeros((n_ch, n_rec))
    hist = np.zeros((n_ch, n_steps + 1))
    x = np.zeros(nx)
    xs = np.empty(nx)
    k1 = np.empty(nx)
    k2 = np.empty(nx)
    k3 = np.empty(nx)
    k4 = np.empty(nx)
    sig = np.empty(6)
    xpre = np.empty(n_ch)
    qcur = np.empty(n_ch)
    t_meas0 = k_start * h
    # q at t = 0 from the rest state
    _derivs(0.0, x, 0, 0.0, ft, fd, nrem, Ap, Bp, C0, C2, D2, k_du, k_theta, ch_int, ch_float,
            stss, theta, out_int, gains, leads, mods, taus, hist, 0, h, t_meas0, t_meas, k1,
            sig, xpre, qcur)
    for c in range(n_ch):
        hist[c, 0] = qcur[c]
    ok = True
    r = 0
    for k in range(n_steps):
        t = k * h
        # record the state at the start of this step
        if k >= k_start and (k - k_start) % decim == 0 and r < n_rec:
            _derivs(t, x, 2 * k, 0.0, ft, fd, nrem, Ap, Bp, C0, C2, D2, k_du, k_theta, ch_int,
                    ch_float, stss, theta, out_int, gains, leads, mods, taus, hist, k, h,
                    t_meas0, t_meas, k1, sig, xpre, qcur)
            for j in range(6):
                sig_rec[r, j] = sig[j]
            for c in range(n_ch):
                xpre_rec[c, r] = xpre[c]
                q_rec[c, r] = qcur[c]
            r += 1
        else:
            _derivs(t, x, 2 * k, 0.0, ft, fd, nrem, Ap, Bp, C0, C2, D2, k_du, k_theta, ch_int,
                    ch_float, stss, theta, out_int, gains, leads, mods, taus, hist, k, h,
                    t_meas0, t_meas, k1, sig, xpre, qcur)
        for i in range(nx):
            xs[i] = x[i] + 0.5 * h * k1[i]
        _derivs(t + 0.5 * h, xs, 2 * k + 1, 0.0, ft, fd, nrem, Ap, Bp, C0, C2, D2, k_du, k_theta,
                ch_int, ch_float, stss, theta, out_int, gains, leads, mods, taus, hist, k, h,
                t_meas0, t_meas, k2, sig, xpre, qcur)
        for i in range(nx):
            xs[i] = x[i] + 0.5 * h * k2[i]
        _derivs(t + 0.5 * h, xs, 2 * k + 1, 0.0, ft, fd, nrem, Ap, Bp, C0, C2, D2, k_du, k_theta,
                ch_int, ch_float, stss, theta, out_int, gains, leads, mods, taus, hist, k, h,
                t_meas0, t_meas, k3, sig, xpre, qcur)
        for i in range(nx):
            xs[i] = x[i] + h * k3[i]
        _derivs(t + h, xs, 2 * k + 2, 0.0, ft, fd, nrem, Ap, Bp, C0, C2, D2, k_du, k_theta,
                ch_int, ch_float, stss, theta, out_int, gains, leads, mods, taus, hist, k, h,
                t_meas0, t_meas, k4, sig, xpre, qcur)
        for i in range(nx):
            x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        # store q at the new time from the new state
        _derivs(t + h, x, 2 * k + 2, 0.0, ft, fd, nrem, Ap, Bp, C0, C2, D2, k_du, k_theta, ch_int,
                ch_float, stss, theta, out_int, gains, leads, mods, taus, hist, k + 1, h,
                t_meas0, t_meas, k4, sig, xpre, qcur)
        for c in range(n_ch):
            hist[c, k + 1] = qcur[c]
        if not math.isfinite(x[0]) or abs(x[0]) > 1e6:
            ok = False
            break
    return sig_rec, xpre_rec, q_rec, ok

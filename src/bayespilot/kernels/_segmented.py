"""Eq. 4 for the paper's two-channel model, eight record segments at a time (SIMD lanes).

The fused kernel (:func:`._response._fused_nll`) walks the record once per
parameter vector; its second-order recursion y_k = v_k - A1 y_{k-1} - A2 y_{k-2}
is a chain of dependent multiply-adds, so one evaluation is bound by the
latency of that chain (several clock cycles per sample) and leaves most of
the CPU's arithmetic units idle.  This kernel cuts each vector's record
(n samples) into ``L = 8`` segments of ``S = n / 8`` samples and runs them
side by side, one per lane of an 8-wide vector (:mod:`._simd`):

* the theta-independent inputs are laid out once (:func:`build_layout`) so that
  row ``s``, lane ``l`` holds sample ``l S + s`` (with a periodic halo of
  ``H`` rows either side, so a delay of ``m`` samples is a row offset):

      P = e_k + 2 e_{k-1} + e_{k-2},   Q = e_k - e_{k-2}     (plain channel, "visual")
      I = the channel input of the dead-zone channel ("vestibular": canal output)
      U = u

* per step of a lane (:func:`_lanes`), with the Tustin numerators of H_nm
  b0 [1 2 1] + b1 [1 0 -1] (plain channel: gain and lead) and g [1 2 1]
  (dead-zone channel), and the fractional delays f_v, f_m:

      X_j = b0 P_j + b1 Q_j,        v_e = X_j + f_v (X_{j-1} - X_j)
      o = I - clamp(I, -dz, dz),    S0_j = o_j + 2 o_{j-1} + o_{j-2}
      v = v_e + g (1 - f_m) S0_j + g f_m S0_{j-1}
      y = (v - A2 y2) - A1 y1,      r = u - y:   sum r^2, sum r phi[s], sum r phi[s-1]

  each lane starting from a zero state;

* the true (periodic, warmed-up) run is y = y0 + a phi1 + b phi2 in each
  lane, where y0 is the lane's zero-start run, (a, b) the true state at the
  lane's start and phi1, phi2 the homogeneous responses to the two initial
  states (phi2[s] = -A2 phi1[s-1]; :func:`_phi_group`, 16 vectors at once).
  :func:`_combine` chains the lanes' end states through the 2 x 2
  homogeneous map (first over the warm-up, exactly as ``_recursion_2`` runs
  it: from zero state ``warm`` samples before the end), and corrects each
  lane's sum of squares for its start state:
  sum (r0 - a phi1 - b phi2)^2 = sum r0^2 - 2 a sum r0 phi1 - 2 b sum r0 phi2
  + a^2 sum phi1^2 + 2 a b sum phi1 phi2 + b^2 sum phi2^2.

The result is the fused kernel's to round-off, not to the bit (measured: at
most 2.8e-12 relative in -ln L over ~10^4 rows, the tests allow 1e-11).
Each row's round-off is estimated (:func:`_accurate`); where the corrections
cancel so much that it would exceed ``NLL_TOL`` relative in -ln L (a nearly
perfect fit, as with remnant-free data, or -ln L near zero), the lanes are
run a second time from their true start states, which the first pass found,
and the sum of squares is summed directly.  Rows that even this leaves
uncertain (perfect fits), and rows outside what the layout covers (a delay
beyond the padding, a negative or NaN dead zone, a non-finite sum), are
recomputed exactly by :func:`._response.neg_log_lik_one`.  Rows are taken in
groups of ``G`` from a shared atomic counter, so a thread whose core is busy
with another process simply takes fewer groups; each row's value depends on
that row alone, so batch size, row order and thread count change no bit.

Portability: the vector code is generic LLVM IR.  With AVX-512 a vector is one
register (and the dead zone one ``VRANGEPD`` where AVX-512DQ is there); with
AVX2 and FMA it is two registers and the dead zone a compare-and-select, with
the same values to the bit.  Elsewhere (no AVX2, not x86) :data:`ENABLED` is
False by default and the likelihood uses the fused scalar kernel; forced on
(``BAYESPILOT_KERNEL=segmented``) the kernel still runs correctly, slowly.

The Python side (eligibility, the layout, the choice at import) is
:func:`plan_channels`, :func:`build_layout` and :data:`ENABLED`;
:class:`bayespilot.likelihood.Likelihood` uses them.
"""

from __future__ import annotations

import math
import os
import warnings
from typing import NamedTuple

import numba
import numpy as np

from .._jit import njit, pjit
from . import _response as R
from ._blocks import (MOD_NONE, NL_DEADZONE, NL_NONE, STAGE_FIXED, STAGE_NONE, param_or, stable,
                      tustin)
from ._simd import (W, atomic_fetch_add, target_features, vadd, vbcast, vbload, vclamp_abs, vfma,
                    vfnma, vload, vmul, vstore, vsub, vzero)

__all__ = ["AVAILABLE", "ENABLED", "CHOICE", "REASON", "Layout", "plan_channels", "build_layout",
           "neg_log_lik_segmented_batch", "neg_log_lik_segmented_one"]

#: Segments per vector (one per SIMD lane).
L = W
#: Vectors per group whose homogeneous responses are computed together (two vectors' worth).
G = 2 * W
#: Steps the channel arithmetic runs ahead of the recursion (software pipelining).
AHEAD = 4
#: Halo rows beyond the padding: the look-ahead plus the three rows read before the start.
HALO_EXTRA = 8
#: Shortest segment the layout is built for.
MIN_SEGMENT = 16
#: Round-off of a lane sum over S samples, per unit of the magnitudes summed and per
#: sqrt(S): the corrected sum of squares is taken to be accurate to about
#: ROUND sqrt(S) x (the size of the terms it adds up).  Measured worst case over ~10^4
#: rows of the paper's model (S = 1024): 7.7e-15 = 2.4e-16 sqrt(S).
ROUND = 4e-16
#: Largest estimated relative round-off of -ln L a pass may return (:func:`_accurate`).
#: The estimates are within a factor 1.4 of the measured differences from the fused
#: kernel, so the values returned are within about 3e-12 of it (measured: 2.8e-12),
#: against the 1e-11 the tests allow.
NLL_TOL = 2e-12
#: Factor on the recursion's round-off in a directly computed sum of squares (see
#: :func:`_direct_size`): over ~10^4 rows (the paper's model on FD and FT recordings
#: with F_n = 0, 0.1, 0.2, damping down to 1e-4) the measured differences needed at most
#: 5.4, most rows under 3.
AMP = 4.0

#: Coefficient table columns (per row of a group).
_A1, _A2, _B0, _B1, _FV, _G0, _G1, _DZ, _MV, _MM = range(10)
_NCOEF = 10
#: Row status from :func:`_coefficients`.
_FAST, _UNSTABLE, _GENERAL = 0, 1, 2


# --- the choice at import ------------------------------------------------------------------
def _choose() -> tuple[bool, bool, str, str]:
    """(available, enabled, choice, reason) from the target CPU and ``BAYESPILOT_KERNEL``."""
    feats = target_features()
    if "avx512f" in feats:
        dz = "VRANGEPD" if "avx512dq" in feats else "compare-and-select"
        available, why = True, ("target has AVX-512F: one 8-wide register per vector, dead "
                                f"zone by {dz}")
    elif "avx2" in feats and "fma" in feats:
        available, why = True, ("target has AVX2 and FMA but no AVX-512: two 4-wide registers "
                                "per vector, dead zone by compare-and-select")
    else:
        available, why = False, "target has neither AVX-512F nor AVX2 with FMA"
    choice = os.environ.get("BAYESPILOT_KERNEL", "auto").strip().lower() or "auto"
    if choice not in ("auto", "scalar", "segmented"):
        warnings.warn(f"BAYESPILOT_KERNEL={choice!r} is not one of auto, scalar, segmented; "
                      "using auto", RuntimeWarning, stacklevel=2)
        choice = "auto"
    if choice == "scalar":
        return available, False, choice, "BAYESPILOT_KERNEL=scalar: the fused scalar kernel"
    if choice == "segmented":
        return available, True, choice, f"BAYESPILOT_KERNEL=segmented ({why})"
    if available:
        return True, True, choice, why
    return False, False, choice, why + ": the fused scalar kernel"


#: AVAILABLE: True if numba's target CPU has wide vectors with fused multiply-add
#: (AVX-512F, or AVX2 and FMA), for which this kernel is faster than the fused scalar one.
#: ENABLED: whether :class:`~bayespilot.likelihood.Likelihood` uses this kernel for the
#: models it covers; by default exactly when AVAILABLE.  ``BAYESPILOT_KERNEL=scalar`` in
#: the environment (read at import) forces the fused scalar kernel,
#: ``BAYESPILOT_KERNEL=segmented`` this one on any CPU (LLVM lowers the vector code for
#: it; correct everywhere, slow where ``llvm.fma`` is a library call).  A Likelihood
#: reads ENABLED when it is made, so setting it later affects new instances only.
#: REASON says why, in words.
AVAILABLE, ENABLED, CHOICE, REASON = _choose()


# --- Python side: eligibility and the layout ----------------------------------------------------
class Layout(NamedTuple):
    """The theta-independent inputs in segment layout (see the module docstring).

    ``P``, ``Q``, ``I``: (S + 2 H) x L, flattened, row r holding samples
    l S + r - H (mod n); ``U``: S x L; ``uu`` = sum u^2.  ``cv`` is the plain channel, ``cm``
    the dead-zone (or plain, lead-free) channel.
    """

    P: np.ndarray
    Q: np.ndarray
    I: np.ndarray  # noqa: E741
    U: np.ndarray
    uu: float
    S: int
    H: int
    cv: int
    cm: int


def _theta_free_channel(plan, c: int) -> bool:
    """No parametric stage and no gain modulation (the channel input is the recorded one)."""
    if plan.ch_int[c, R.CH_MOD_KIND] != MOD_NONE:
        return False
    for s in range(plan.ch_int[c, R.CH_NSTAGES]):
        if plan.st_int[c, s, 0] not in (STAGE_FIXED, STAGE_NONE):
            return False
    return True


def plan_channels(plan) -> tuple[int, int] | None:
    """(cv, cm) if the model is one this kernel computes, else None.

    Two channels without parametric stages or gain modulation, one of them
    plain (no nonlinearity; it may have a lead), the other plain or with a
    dead zone and without a lead; no output nonlinearity; no channel
    oversampled.
    """
    ch = plan.ch_int
    if ch.shape[0] != 2 or plan.out_int[R.OUT_NL_KIND] != NL_NONE or R.any_oversampled(ch):
        return None
    if not (_theta_free_channel(plan, 0) and _theta_free_channel(plan, 1)):
        return None
    for cv, cm in ((0, 1), (1, 0)):
        if ch[cv, R.CH_NL_KIND] == NL_NONE and ch[cm, R.CH_NL_KIND] in (NL_NONE, NL_DEADZONE) \
                and ch[cm, R.CH_LEAD] < 0:
            return cv, cm
    return None


def _aligned(a: np.ndarray, align: int = 64) -> np.ndarray:
    """A C-contiguous copy of ``a`` whose data start on an ``align``-byte boundary."""
    a = np.ascontiguousarray(a, dtype=np.float64)
    buf = np.empty(a.size + align // 8, dtype=np.float64)
    off = (-buf.ctypes.data % align) // 8
    out = buf[off:off + a.size].reshape(a.shape)
    out[...] = a
    return out


def build_layout(X: np.ndarray, u: np.ndarray, cv: int, cm: int, pad: int) -> Layout | None:
    """The segment layout of the channel inputs ``X`` and the output ``u`` (periodic).

    ``pad`` is the fused path's padding (:func:`._response.padding`): delays up
    to ``pad - 4`` samples are covered.  Returns None when the record cannot be
    cut into ``L`` equal segments of at least ``MIN_SEGMENT`` samples.
    """
    n = u.shape[0]
    if n % L or n // L < MIN_SEGMENT:
        return None
    S = n // L
    H = pad + HALO_EXTRA
    e = X[cv]
    P = e + 2.0 * np.roll(e, 1) + np.roll(e, 2)
    Q = e - np.roll(e, 2)
    pos = (np.arange(L)[None, :] * S + np.arange(S + 2 * H)[:, None] - H) % n
    return Layout(_aligned(P[pos].ravel()), _aligned(Q[pos].ravel()),
                  _aligned(X[cm][pos].ravel()), _aligned(u.reshape(L, S).T.ravel()),
                  float(np.dot(u, u)), S, H, cv, cm)


# --- numba: per row ------------------------------------------------------------------------------
@njit
def _coefficients(theta, ch_int, ch_float, out_int, dt, pad, cv, cm, cfs, j):
    """Fill ``cfs[j]`` (see the ``_A1``.. columns) for one full parameter vector; return the
    status: ``_FAST``, ``_UNSTABLE`` (H_nm not stable: -ln L = +inf) or ``_GENERAL`` (a
    delay beyond the padding, a negative or NaN dead zone: the exact path decides).
    (One return statement: numba then drops the reference counting of the arrays passed.)"""
    wn = theta[out_int[R.OUT_OMEGA]]
    zn = theta[out_int[R.OUT_ZETA]]
    w2 = wn * wn
    a1 = 2.0 * zn * wn
    _, _, _, A1, A2 = tustin(w2, 0.0, 0.0, w2, a1, 1.0, dt)
    status = _FAST if stable(A1, A2) else _UNSTABLE
    c = 2.0 / dt
    d0 = c * c + a1 * c + w2
    for k in range(2):
        ch = cv if k == 0 else cm
        dd = theta[ch_int[ch, R.CH_DELAY]] / dt
        if not (abs(dd) < pad - 4):
            if status == _FAST:
                status = _GENERAL
            dd = 0.0
        m = math.floor(dd)
        f = dd - m
        gain = ch_float[ch, R.CHF_GAIN_CONST] * ch_float[ch, R.CHF_SIGN] \
            * param_or(theta, ch_int[ch, R.CH_GAIN0], 1.0) \
            * param_or(theta, ch_int[ch, R.CH_GAIN1], 1.0)
        kg = gain * w2
        if k == 0:
            lead = param_or(theta, ch_int[ch, R.CH_LEAD], 0.0)
            cfs[j, _B0] = kg / d0
            cfs[j, _B1] = kg * lead * c / d0
            cfs[j, _FV] = f
            cfs[j, _MV] = m
        else:
            g = kg / d0
            cfs[j, _G0] = g * (1.0 - f)
            cfs[j, _G1] = g * f
            cfs[j, _MM] = m
    dz = 0.0
    if ch_int[cm, R.CH_NL_KIND] == NL_DEADZONE:
        dz = param_or(theta, ch_int[cm, R.CH_NL_P0], 0.0)
    if not (dz >= 0.0) and status == _FAST:
        status = _GENERAL
    cfs[j, _DZ] = dz
    # the homogeneous response of a row that is not computed here is 0 (phi_group)
    cfs[j, _A1] = A1 if status == _FAST else 0.0
    cfs[j, _A2] = A2 if status == _FAST else 0.0
    return status


@njit
def _phi_group(cfs, S, phiT, gs):
    """Homogeneous response phi1 (from the state (y_{-1}, y_{-2}) = (1, 0)) of the G
    vectors of a group, SIMD across vectors: ``phiT[(s + 2) G + g]`` = phi1[s] of vector
    g for s = -2 .. S - 1, and over s = 0 .. S - 1 the sums ``gs[0, g]`` = sum phi1[s]^2,
    ``gs[1, g]`` = sum phi1[s] phi1[s-1], ``gs[2, g]`` = sum phi1[s-1]^2.

    Each lane's arithmetic depends on its own vector only, so a vector's values do not
    depend on the group it is computed in."""
    na1 = np.empty(G)
    na2 = np.empty(G)
    for g in range(G):
        na1[g] = -cfs[g, _A1]
        na2[g] = -cfs[g, _A2]
    nA1a = vload(na1, 0)
    nA1b = vload(na1, W)
    nA2a = vload(na2, 0)
    nA2b = vload(na2, W)
    p1a = vbcast(1.0)
    p1b = vbcast(1.0)
    p2a = vzero()
    p2b = vzero()
    vstore(phiT, 0, p2a)
    vstore(phiT, W, p2b)
    vstore(phiT, G, p1a)
    vstore(phiT, G + W, p1b)
    g11a = vzero()
    g11b = vzero()
    g12a = vzero()
    g12b = vzero()
    g22a = vzero()
    g22b = vzero()
    for s in range(S):
        fa = vfma(nA1a, p1a, vmul(nA2a, p2a))
        fb = vfma(nA1b, p1b, vmul(nA2b, p2b))
        vstore(phiT, (s + 2) * G, fa)
        vstore(phiT, (s + 2) * G + W, fb)
        g11a = vfma(fa, fa, g11a)
        g11b = vfma(fb, fb, g11b)
        g12a = vfma(fa, p1a, g12a)
        g12b = vfma(fb, p1b, g12b)
        g22a = vfma(p1a, p1a, g22a)
        g22b = vfma(p1b, p1b, g22b)
        p2a = p1a
        p2b = p1b
        p1a = fa
        p1b = fb
    vstore(gs, 0, g11a)
    vstore(gs, W, g11b)
    vstore(gs, G, g12a)
    vstore(gs, G + W, g12b)
    vstore(gs, 2 * G, g22a)
    vstore(gs, 2 * G + W, g22b)


@njit(inline="always")
def _inputs(P, Q, I, kp, ki, vb0, vb1, vf, vg0, vg1, vdz, X1, o1, m0, S1):
    """One row of the channel arithmetic: the H_nm input v of the row at ``kp`` (P, Q,
    delayed) and ``ki`` (I, delayed), with the carried values of the previous row.
    Returns (v, X, o, o + o_prev, S0).  ``inline="always"`` (numba inlines it before
    compiling): the kernel's loop stays one block of vector code, and no ``V8`` value
    crosses a function boundary."""
    X0 = vfma(vb1, vload(Q, kp), vmul(vb0, vload(P, kp)))
    ve = vfma(vf, vsub(X1, X0), X0)
    x = vload(I, ki)
    o0 = vsub(x, vclamp_abs(x, vdz))
    mn = vadd(o0, o1)
    S0 = vadd(mn, m0)
    v = vfma(vg1, S1, vfma(vg0, S0, ve))
    return v, X0, o0, mn, S0


@njit
def _lanes(P, Q, I, U, bp, bi, S, b0, b1, fv, g0, g1, A1, A2, dz, from_start, start, sw, st,
           phiT, g):
    """Runs of the L segments of one vector, SIMD across segments: from a zero state, or
    with ``from_start`` from the states in ``start`` (2 x L: y_{-1}, y_{-2} of each).

    P and Q rows are read from flat offset ``bp`` (row 0 of the delayed plain channel),
    I rows from ``bi``.  Writes into ``st`` (8 x L): the end states y1, y2, the sums
    r^2, r phi1[s], r phi1[s-1] (phi of vector ``g`` in ``phiT``), and the state before
    step ``sw`` (where the warm-up starts).  The channel arithmetic runs ``AHEAD`` = 4
    rows ahead of the recursion, so the recursion's two dependent multiply-adds per row
    are the only chain.
    """
    vb0 = vbcast(b0)
    vb1 = vbcast(b1)
    vf = vbcast(fv)
    vg0 = vbcast(g0)
    vg1 = vbcast(g1)
    vA1 = vbcast(A1)
    vA2 = vbcast(A2)
    vdz = vbcast(dz)
    # the three rows before the start
    X1 = vfma(vb1, vload(Q, bp - L), vmul(vb0, vload(P, bp - L)))
    x = vload(I, bi - L)
    o1 = vsub(x, vclamp_abs(x, vdz))
    x = vload(I, bi - 2 * L)
    o2 = vsub(x, vclamp_abs(x, vdz))
    x = vload(I, bi - 3 * L)
    o3 = vsub(x, vclamp_abs(x, vdz))
    m0 = vadd(o1, o2)
    S1 = vadd(m0, vadd(o2, o3))
    # the look-ahead: the inputs of rows 0 .. AHEAD - 1
    vq0, X1, o1, m0, S1 = _inputs(P, Q, I, bp, bi, vb0, vb1, vf, vg0, vg1, vdz, X1, o1, m0, S1)
    vq1, X1, o1, m0, S1 = _inputs(P, Q, I, bp + L, bi + L, vb0, vb1, vf, vg0, vg1, vdz,
                                  X1, o1, m0, S1)
    vq2, X1, o1, m0, S1 = _inputs(P, Q, I, bp + 2 * L, bi + 2 * L, vb0, vb1, vf, vg0, vg1, vdz,
                                  X1, o1, m0, S1)
    vq3, X1, o1, m0, S1 = _inputs(P, Q, I, bp + 3 * L, bi + 3 * L, vb0, vb1, vf, vg0, vg1, vdz,
                                  X1, o1, m0, S1)
    y1 = vload(start, 0) if from_start else vzero()
    y2 = vload(start, L) if from_start else vzero()
    ss = vzero()
    c1 = vzero()
    c2 = vzero()
    for part in range(2):
        lo = 0 if part == 0 else sw
        hi = sw if part == 0 else S
        if part == 1:
            vstore(st, 5 * L, y1)
            vstore(st, 6 * L, y2)
        for s in range(lo, hi):
            k = s * L
            kd = k + AHEAD * L
            f1 = vbload(phiT, (s + 2) * G + g)
            f0 = vbload(phiT, (s + 1) * G + g)
            vn, X1, o1, m0, S1 = _inputs(P, Q, I, bp + kd, bi + kd, vb0, vb1, vf, vg0, vg1, vdz,
                                         X1, o1, m0, S1)
            t = vfnma(vA2, y2, vq0)
            y2 = y1
            y1 = vfnma(vA1, y1, t)
            r = vsub(vload(U, k), y1)
            ss = vfma(r, r, ss)
            c1 = vfma(r, f1, c1)
            c2 = vfma(r, f0, c2)
            vq0 = vq1
            vq1 = vq2
            vq2 = vq3
            vq3 = vn
    vstore(st, 0, y1)
    vstore(st, L, y2)
    vstore(st, 2 * L, ss)
    vstore(st, 3 * L, c1)
    vstore(st, 4 * L, c2)


@njit
def _transfer(phiT, g, A2, t, a, b):
    """The state (y_{t-1}, y_{t-2}) after t >= 1 zero-input steps from (y_{-1}, y_{-2}) =
    (a, b): a phi1 + b phi2 with phi2[s] = -A2 phi1[s-1] (phi1[-1] = 1, phi1[-2] = 0)."""
    p1 = phiT[(t + 1) * G + g]      # phi1[t-1]
    p2 = phiT[t * G + g]            # phi1[t-2]
    p3 = phiT[(t - 1) * G + g]      # phi1[t-3]
    return a * p1 - b * (A2 * p2), a * p2 - b * (A2 * p3)


@njit
def _combine(st, phiT, g, gs, S, A2, n, warm, start):
    """(sse, size): the sum of squared residuals of the periodic run warmed up over the
    last ``warm`` samples (as ``_recursion_2``), from the lanes' zero-start sums in
    ``st`` (8 x L), and the sum of the magnitudes of the terms it adds up (its round-off
    is about eps x size).  The true start state of each lane goes to ``start`` (2 x L)."""
    g11 = gs[0, g]
    g12 = -A2 * gs[1, g]
    g22 = A2 * A2 * gs[2, g]
    a = 0.0
    b = 0.0
    if warm > 0:
        # the run that starts from rest at sample n - warm, to the end of the record
        p0 = n - warm
        lw = p0 // S
        sw = p0 - lw * S
        if sw == 0:
            a = st[0, lw]
            b = st[1, lw]
        else:
            ta, tb = _transfer(phiT, g, A2, S - sw, st[5, lw], st[6, lw])
            a = st[0, lw] - ta
            b = st[1, lw] - tb
        for l in range(lw + 1, L):  # noqa: E741
            ta, tb = _transfer(phiT, g, A2, S, a, b)
            a = st[0, l] + ta
            b = st[1, l] + tb
    sse = 0.0
    size = 0.0
    for l in range(L):  # noqa: E741
        start[0, l] = a
        start[1, l] = b
        t1 = a * st[3, l]
        t2 = A2 * b * st[4, l]
        q11 = a * a * g11
        q12 = 2.0 * a * b * g12
        q22 = b * b * g22
        sse += st[2, l] - 2.0 * (t1 - t2) + q11 + q12 + q22
        size += st[2, l] + 2.0 * (abs(t1) + abs(t2)) + q11 + abs(q12) + q22
        ta, tb = _transfer(phiT, g, A2, S, a, b)
        a = st[0, l] + ta
        b = st[1, l] + tb
    return sse, size


@njit
def _accurate(sse, size, n, S):
    """True if -ln L = n/2 (ln(sse / n) + 1) from this ``sse`` is within ``NLL_TOL``
    relative, its round-off being about ROUND sqrt(S) size / sse relative in sse, i.e.
    that over |ln(sse / n) + 1| in -ln L.  False for a non-finite or non-positive sse
    (NaN parameters, overflow, a perfect fit): the exact path decides those."""
    if not (sse > 0.0 and math.isfinite(sse)):
        return False
    return sse * abs(math.log(sse / n) + 1.0) * NLL_TOL >= ROUND * math.sqrt(S) * size


@njit
def _aligned_empty(size):
    """An uninitialised float64 array of ``size`` whose data start on a 64-byte boundary."""
    buf = np.empty(size + 8)
    off = ((-buf.ctypes.data) % 64) // 8
    return buf[off:off + size]


@njit
def _direct_size(sse, uu, A1, A2, S):
    """The size to put in :func:`_accurate` for a sum of squares computed directly (the
    second pass: no cancellation).  Its round-off is the summation's, ROUND sqrt(S) sse,
    plus that of the recursion: rounding errors of relative size eps in y (whose size is
    about that of u where the fit is good, sqrt(max(sum u^2, sse)) overall) carried on
    with the energy gain of H_nm's poles, sum h^2 = (1 + A2) / ((1 - A2) ((1 + A2)^2 -
    A1^2)), so sse moves by about 2 eps sqrt(gain max(sum u^2, sse) sse)."""
    gain = (1.0 + A2) / ((1.0 - A2) * ((1.0 + A2) * (1.0 + A2) - A1 * A1))
    return sse + AMP * math.sqrt(gain * max(uu, sse) * sse / S)


@njit
def _rows(free, free_idx, base, P, Q, I, U, uu, S, H, cv, cm, X, u, ch_int, ch_float, st_int,
          st_const, out_int, dt, warm, s2_floor, pad, counter, out, floored):
    """-ln L of the rows of ``free`` this thread takes, G at a time, from ``counter``."""
    m = free.shape[0]
    n = u.shape[0]
    sw = (n - warm) % S if warm > 0 else 0
    st = np.zeros((8, L))
    start = np.zeros((2, L))
    phiT = _aligned_empty((S + 2) * G)  # written with full-vector stores
    gs = np.empty((3, G))
    cfs = np.zeros((G, _NCOEF))
    stat = np.empty(G, dtype=np.int64)
    rows = np.empty(G, dtype=np.int64)
    theta = base.copy()
    # the exact path's buffers, made when a row first needs them
    have_general = False
    y = np.empty(0)
    q = np.empty(0)
    v = np.empty(0)
    Qp = np.empty((0, 0))
    # (The per-row code below calls only functions with one exit and no array views: a
    # call that passes arrays otherwise costs two atomic reference-count updates per
    # array, which were 7 % of the batch.)
    while True:
        r0 = atomic_fetch_add(counter, 0, 1) * G
        if r0 >= m:
            break
        ng = min(G, m - r0)
        for j in range(ng):
            r = r0 + j
            rows[j] = r
            for i in range(free_idx.shape[0]):
                theta[free_idx[i]] = free[r, i]
            stat[j] = _coefficients(theta, ch_int, ch_float, out_int, dt, pad, cv, cm, cfs, j)
        for j in range(ng, G):
            cfs[j, _A1] = 0.0
            cfs[j, _A2] = 0.0
        _phi_group(cfs, S, phiT, gs)
        for j in range(ng):
            r = rows[j]
            floored[r] = False
            if stat[j] == _UNSTABLE:
                out[r] = np.inf
                continue
            if stat[j] == _FAST:
                A1 = cfs[j, _A1]
                A2 = cfs[j, _A2]
                bp = (H - int(cfs[j, _MV])) * L
                bi = (H - int(cfs[j, _MM])) * L
                b0 = cfs[j, _B0]
                b1 = cfs[j, _B1]
                fv = cfs[j, _FV]
                g0 = cfs[j, _G0]
                g1 = cfs[j, _G1]
                dz = cfs[j, _DZ]
                # the first pass, from zero states
                _lanes(P, Q, I, U, bp, bi, S, b0, b1, fv, g0, g1, A1, A2, dz, False, start, sw,
                       st, phiT, j)
                sse, size = _combine(st, phiT, j, gs, S, A2, n, warm, start)
                ok = _accurate(sse, size, n, S)
                if not ok and math.isfinite(size) and math.isfinite(start[0, 0]) \
                        and math.isfinite(start[1, 0]):
                    # its corrections cancel too much: a second pass from the true start
                    # states the first one found, summed directly
                    _lanes(P, Q, I, U, bp, bi, S, b0, b1, fv, g0, g1, A1, A2, dz, True, start,
                           0, st, phiT, j)
                    sse = 0.0
                    for l in range(L):  # noqa: E741
                        sse += st[2, l]
                    ok = _accurate(sse, _direct_size(sse, uu, A1, A2, S), n, S)
                if ok:
                    val, fl = R.neg_log_lik_from_sse(sse, n, s2_floor)
                    out[r] = val
                    floored[r] = fl
                    continue
            # the exact path: a near-perfect fit, or a row outside the layout
            if not have_general:
                y = np.empty(n)
                q = np.empty(n)
                v = np.empty(n)
                Qp = np.empty((X.shape[0], n + 2 * pad))
                R.fill_plain_rows(X, ch_int, st_int, Qp, pad, True)
                have_general = True
            for i in range(free_idx.shape[0]):
                theta[free_idx[i]] = free[r, i]
            val, fl = R.neg_log_lik_one(theta, X, u, ch_int, ch_float, st_int, st_const, out_int,
                                        dt, True, warm, s2_floor, y, q, v, Qp, pad, 0, True)
            out[r] = val
            floored[r] = fl


@pjit
def neg_log_lik_segmented_batch(free, free_idx, base, P, Q, I, U, uu, S, H, cv, cm, X, u,
                                ch_int, ch_float, st_int, st_const, out_int, dt, warm, s2_floor,
                                pad, n_chunks, out, floored):
    """-ln L (Eq. 4, periodic, whole record) of every row of ``free``, on ``n_chunks`` threads.

    ``P`` .. ``cm`` are a :class:`Layout`; the rest as
    :func:`._response.neg_log_lik_batch`.  Each thread takes groups of G rows from a
    shared counter until none is left.
    """
    counter = np.zeros(1, dtype=np.int64)
    for ch in numba.prange(n_chunks):
        _rows(free, free_idx, base, P, Q, I, U, uu, S, H, cv, cm, X, u, ch_int, ch_float,
              st_int, st_const, out_int, dt, warm, s2_floor, pad, counter, out, floored)


@njit
def neg_log_lik_segmented_one(theta, P, Q, I, U, uu, S, H, cv, cm, X, u, ch_int, ch_float,
                              st_int, st_const, out_int, dt, warm, s2_floor, pad):
    """(value, floored) for one full parameter vector: the batch's arithmetic on one row,
    so the value is the batch's to the bit."""
    free = theta.reshape((1, theta.shape[0]))
    idx = np.arange(theta.shape[0])
    out = np.empty(1)
    floored = np.zeros(1, dtype=np.bool_)
    _rows(free, idx, theta, P, Q, I, U, uu, S, H, cv, cm, X, u, ch_int, ch_float, st_int,
          st_const, out_int, dt, warm, s2_floor, pad, np.zeros(1, dtype=np.int64), out, floored)
    return out[0], floored[0]

"""The coloured-residual likelihood: output error whitened by an AR(p) model, in numba.

The output error eps = u - u_hat(theta) is modelled as a stationary AR(p) process

    eps_k = sum_{j=1..p} a_j eps_{k-j} + w_k,        w_k ~ N(0, s2) white,

and the likelihood is the conditional one (the first p samples are conditioned
on, not modelled), with the innovation variance s2 profiled out:

    -ln L = (N - p)/2 ln( mean_{k >= p} w_k^2 ) + (N - p)/2.

With p = 0 this is Eq. 4 exactly.  The AR coefficients are not sampled
directly: the sampler works on the partial autocorrelations r_j in (-1, 1),
which the Levinson-Durbin (step-up) recursion maps one-to-one onto the
stationary AR(p) models (Barndorff-Nielsen & Schou 1973, Monahan 1984):

    a^(k)_k = r_k,   a^(k)_j = a^(k-1)_j - r_k a^(k-1)_{k-j}   (j < k).

With the AR model *profiled* (``neg_log_lik_profiled_*``) the coefficients
are not parameters at all: at every theta they are the least-squares AR(p)
fit to that theta's output error, so -ln L is the minimum over a of the
expression above.  Holding a fitted AR model fixed ignores that in closed
loop the remnant also drives the model's inputs, so the pilot's gains and
the noise model share information (Ljung, *System Identification*, 2nd ed.,
Sec. 13.4); maximising the noise model out restores that coupling to first
order at the cost of p + 1 lagged sums per evaluation.

u_hat comes from :func:`._response.response_into` (the general path), so every
model the package can compile can be sampled with either likelihood.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .._jit import njit, pjit
from ._response import neg_log_lik_from_sse, response_into, work_length


@njit
def pacf_to_ar(r, a, work):
    """AR coefficients ``a`` (length p) of the stationary model with partial autocorrelations ``r``.

    ``work`` is a buffer of length p.  Levinson-Durbin step-up recursion; no
    check that |r_j| < 1 (the caller does it).
    """
    p = r.shape[0]
    for k in range(p):
        rk = r[k]
        for j in range(k):
            work[j] = a[j] - rk * a[k - 1 - j]
        for j in range(k):
            a[j] = work[j]
        a[k] = rk


@njit
def whitened_sse(u, y, a, skip=0):
    """sum_{k >= skip + p} w_k^2 with eps = u - y and w_k = eps_k - sum_j a_j eps_{k-j}.

    Overwrites ``y`` with eps (the caller's work buffer), so each eps is
    formed once rather than p + 1 times.
    """
    n = u.shape[0]
    for k in range(skip, n):
        y[k] = u[k] - y[k]
    return whitened_sum(y, skip, n, a)


@njit
def load_row(theta, free, r, free_idx):
    """Put row ``r`` of ``free`` into ``theta`` at ``free_idx``; False if any value is not finite."""
    finite = True
    for j in range(free_idx.shape[0]):
        x = free[r, j]
        finite = finite and math.isfinite(x)
        theta[free_idx[j]] = x
    return finite


@njit
def whitened_sum(e, lo, n, a):
    """sum_{k >= lo + p} w_k^2 with w_k = e_k - sum_j a_j e_{k-1-j} (``e`` left unchanged)."""
    p = a.shape[0]
    sse = 0.0
    for k in range(lo + p, n):
        w = e[k]
        for j in range(p):
            # k - 1 - j >= lo >= 0: an unsigned index spares numba's negative-index
            # wrap-around select on every load (1.5x faster, same arithmetic)
            w -= a[j] * e[np.uint64(k - 1 - j)]
        sse += w * w
    return sse


@njit
def _lagged_sums(e, lo, n, p, acc):
    """acc[l] = sum_{t=lo}^{n-1-l} e_t e_{t+l} for l = 0..p, each summed in t order.

    Four lags at a time in register accumulators, through views indexed by
    the loop counter: accumulators in ``acc`` itself went through memory on
    every update, and signed offsets cost a wrap-around select per load (2x
    slower; the sums are the same to the last bit).
    """
    hi = n - p
    ev = e[lo:]
    for l0 in range(0, p + 1, 4):
        nb = min(4, p + 1 - l0)
        el = e[lo + l0:]
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        s3 = 0.0
        if nb == 4:
            for i in range(hi - lo):
                et = ev[i]
                s0 += et * el[i]
                s1 += et * el[i + 1]
                s2 += et * el[i + 2]
                s3 += et * el[i + 3]
        else:
            for i in range(hi - lo):
                et = ev[i]
                s0 += et * el[i]
                if nb > 1:
                    s1 += et * el[i + 1]
                if nb > 2:
                    s2 += et * el[i + 2]
        acc[l0] = s0
        if nb > 1:
            acc[l0 + 1] = s1
        if nb > 2:
            acc[l0 + 2] = s2
        if nb > 3:
            acc[l0 + 3] = s3
    # the last p samples, whose later lags run past the end
    for t in range(max(lo, hi), n):
        et = e[t]
        for l in range(n - t):
            acc[l] += et * e[t + l]


@njit
def profiled_ar_sse(e, lo, n, p, acc, A, b):
    """min over a of sum_{k >= lo + p} (e_k - sum_j a_j e_{k-1-j})^2: the residual sum of
    squares of the least-squares (covariance-method) AR(p) fit to ``e[lo:n]``.

    ``acc`` (length p + 1), ``A`` (p x p) and ``b`` (p) are work buffers; on
    return ``b[:p]`` holds the coefficients.  The normal equations come from
    the p + 1 lagged sums over the whole segment, less their few end terms,
    so the cost is (p + 1) passes' worth of multiply-adds, done in one pass
    with independent accumulators.  A
    relative ridge of 1e-12 on the diagonal keeps a degenerate segment (a
    perfect fit) finite; the Cholesky solve is written out because p is at
    most a few tens and a LAPACK call per evaluation would cost more.
    """
    m = n - lo
    # R(l) = sum_{t=0}^{m-1-l} e_t e_{t+l}
    _lagged_sums(e, lo, n, p, acc)
    # A_ij = sum_{k=p}^{m-1} e_{k-1-i} e_{k-1-j} (offsets from lo); with i <= j, l = j - i:
    # R(l) less the terms t < p - 1 - j and t > m - 2 - j
    for i in range(p):
        for j in range(i, p):
            l = j - i
            s = acc[l]
            for t in range(0, p - 1 - j):
                s -= e[lo + t] * e[lo + t + l]
            for t in range(m - 1 - j, m - l):
                s -= e[lo + t] * e[lo + t + l]
            A[i, j] = s
            A[j, i] = s
    # b_i = sum_{k=p}^{m-1} e_k e_{k-1-i}: R(i + 1) less the terms t < p - 1 - i
    for i in range(p):
        s = acc[i + 1]
        for t in range(0, p - 1 - i):
            s -= e[lo + t] * e[lo + t + i + 1]
        b[i] = s
    yy = acc[0]
    for t in range(p):
        yy -= e[lo + t] * e[lo + t]
    if p == 0:
        return yy if yy > 0.0 else 0.0
    ridge = 1e-12 * acc[0] + 1e-300
    # Cholesky A = L L^T in place (lower triangle); yy is the fallback if A is not positive
    for j in range(p):
        d = A[j, j] + ridge
        for k in range(j):
            d -= A[j, k] * A[j, k]
        if not (d > 0.0):
            return yy if yy > 0.0 else 0.0
        d = math.sqrt(d)
        A[j, j] = d
        for i in range(j + 1, p):
            s = A[i, j]
            for k in range(j):
                s -= A[i, k] * A[j, k]
            A[i, j] = s / d
    # a = L^-T L^-1 b (into b)
    for i in range(p):
        s = b[i]
        for k in range(i):
            s -= A[i, k] * b[k]
        b[i] = s / A[i, i]
    for i in range(p - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, p):
            s -= A[k, i] * b[k]
        b[i] = s / A[i, i]
    # The sum of squares of the whitened residual itself, not yy - b'A^-1 b: the lags of a
    # remnant sampled at 100 Hz are nearly collinear, and that difference of two nearly equal
    # numbers lost 5 digits; the sum of squares is stationary in a, so the error of a from
    # the normal equations enters it only to second order.
    return whitened_sum(e, lo, n, b[:p])


@njit
def neg_log_lik_profiled_one(theta, p, X, u, ch_int, ch_float, st_int, st_const, out_int, dt,
                             periodic, warm, s2_floor, y, q, v, acc, A, b, skip=0):
    """-ln L of an AR(p) output error with the AR coefficients profiled out, for one ``theta``.

    As :func:`neg_log_lik_whitened_one`, with the whitening filter the
    least-squares AR(p) fit to this theta's output error over k >= skip
    (:func:`profiled_ar_sse`).  ``acc``, ``A``, ``b`` are work buffers of
    sizes p + 1, (p, p), p.
    """
    n = u.shape[0]
    if n <= skip + 4 * p:
        return np.inf, False
    ok = response_into(theta, X, ch_int, ch_float, st_int, st_const, out_int, dt, periodic,
                       warm, y, q, v)
    if not ok:
        return np.inf, False
    for k in range(skip, n):
        y[k] = u[k] - y[k]
    sse = profiled_ar_sse(y, skip, n, p, acc, A, b)
    return neg_log_lik_from_sse(sse, n - skip - p, s2_floor)


@pjit
def neg_log_lik_profiled_batch(free, free_idx, base, p, X, u, ch_int, ch_float, st_int,
                               st_const, out_int, dt, periodic, warm, s2_floor, n_chunks, out,
                               floored, skip=0):
    """-ln L with the AR(p) model profiled out, for every row of ``free``, in parallel over rows.

    Rows are dealt to ``n_chunks`` threads in turn (as ``neg_log_lik_whitened_batch``).
    """
    m = free.shape[0]
    n = u.shape[0]
    for ch in numba.prange(n_chunks):
        y = np.empty(n)
        q = np.empty(n)
        v = np.empty(work_length(ch_int, n))
        acc = np.empty(p + 1)
        A = np.empty((max(p, 1), max(p, 1)))
        b = np.empty(max(p, 1))
        theta = base.copy()
        for r in range(ch, m, n_chunks):
            if not load_row(theta, free, r, free_idx):
                out[r] = np.inf
                floored[r] = False
                continue
            val, fl = neg_log_lik_profiled_one(theta, p, X, u, ch_int, ch_float, st_int,
                                               st_const, out_int, dt, periodic, warm, s2_floor,
                                               y, q, v, acc, A, b, skip)
            out[r] = val
            floored[r] = fl


@njit
def neg_log_lik_whitened_one(theta, a, X, u, ch_int, ch_float, st_int, st_const, out_int, dt,
                             periodic, warm, s2_floor, y, q, v, skip=0):
    """-ln L of an output error with the fixed AR(p) model ``a``, for one full ``theta``.

    Eq. 4 on the whitened residual w_k = eps_k - sum_j a_j eps_{k-j} over
    k >= skip + p (conditional on the p samples before).  ``y``, ``q``, ``v``
    are work buffers of the record's length.  Returns (value, floored); +inf
    for an unstable ``theta`` or a non-finite result.
    """
    n = u.shape[0]
    p = a.shape[0]
    if n <= skip + p:
        return np.inf, False
    ok = response_into(theta, X, ch_int, ch_float, st_int, st_const, out_int, dt, periodic,
                       warm, y, q, v)
    if not ok:
        return np.inf, False
    sse = whitened_sse(u, y, a, skip)
    return neg_log_lik_from_sse(sse, n - skip - p, s2_floor)


@pjit
def neg_log_lik_whitened_batch(free, free_idx, base, a, X, u, ch_int, ch_float, st_int,
                               st_const, out_int, dt, periodic, warm, s2_floor, n_chunks, out,
                               floored, skip=0):
    """-ln L with the fixed AR model ``a`` for every row of ``free``, in parallel over rows.

    Rows are dealt to ``n_chunks`` threads in turn (as ``_response.neg_log_lik_batch``);
    each thread allocates its work buffers once.
    """
    m = free.shape[0]
    n = u.shape[0]
    for ch in numba.prange(n_chunks):
        y = np.empty(n)
        q = np.empty(n)
        v = np.empty(work_length(ch_int, n))
        theta = base.copy()
        for r in range(ch, m, n_chunks):
            if not load_row(theta, free, r, free_idx):
                out[r] = np.inf
                floored[r] = False
                continue
            val, fl = neg_log_lik_whitened_one(theta, a, X, u, ch_int, ch_float, st_int,
                                               st_const, out_int, dt, periodic, warm, s2_floor,
                                               y, q, v, skip)
            out[r] = val
            floored[r] = fl


@njit
def neg_log_lik_coloured_one(theta, r, X, u, ch_int, ch_float, st_int, st_const, out_int, dt,
                             periodic, warm, s2_floor, y, q, v, a, work, skip=0):
    """-ln L of the AR(p)-coloured output error for one full parameter vector ``theta``.

    ``r`` holds the p partial autocorrelations; ``y``, ``q``, ``v`` are work
    buffers of the record's length, ``a`` and ``work`` of length p.  The first
    ``skip`` samples are left out (the likelihood conditions on the next p).  Returns
    (value, floored); the value is +inf for an unstable ``theta``, a partial
    autocorrelation outside (-1, 1), or a non-finite result.
    """
    p = r.shape[0]
    for j in range(p):
        if not (abs(r[j]) < 1.0):
            return np.inf, False
    pacf_to_ar(r, a, work)
    return neg_log_lik_whitened_one(theta, a, X, u, ch_int, ch_float, st_int, st_const, out_int,
                                    dt, periodic, warm, s2_floor, y, q, v, skip)


@pjit
def neg_log_lik_coloured_batch(rows, n_model, free_idx, base, X, u, ch_int, ch_float, st_int,
                               st_const, out_int, dt, periodic, warm, s2_floor, n_chunks, out,
                               floored, skip=0):
    """-ln L (coloured residual) for every row of ``rows``, in parallel over rows.

    Each row is [free pilot parameters (``n_model`` of them, in the order of
    ``free_idx``), r_1, ..., r_p].  Rows are split into ``n_chunks`` contiguous
    chunks, one per thread, which allocate their work buffers once (prange over
    independent parameter vectors, never over time steps).
    """
    m = rows.shape[0]
    n = u.shape[0]
    p = rows.shape[1] - n_model
    for ch in numba.prange(n_chunks):
        lo = (ch * m) // n_chunks
        hi = ((ch + 1) * m) // n_chunks
        y = np.empty(n)
        q = np.empty(n)
        v = np.empty(work_length(ch_int, n))
        a = np.empty(p)
        work = np.empty(p)
        r = np.empty(p)
        theta = base.copy()
        for i in range(lo, hi):
            finite = True
            for j in range(n_model):
                x = rows[i, j]
                finite = finite and math.isfinite(x)
                theta[free_idx[j]] = x
            for j in range(p):
                r[j] = rows[i, n_model + j]
            if not finite:
                out[i] = np.inf
                floored[i] = False
                continue
            val, fl = neg_log_lik_coloured_one(theta, r, X, u, ch_int, ch_float, st_int,
                                               st_const, out_int, dt, periodic, warm, s2_floor,
                                               y, q, v, a, work, skip)
            out[i] = val
            floored[i] = fl

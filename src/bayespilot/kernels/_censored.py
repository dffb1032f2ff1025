"""The censored (Tobit) output-error likelihood for a clipped control signal, in numba.

Samples of u at the device's travel limit are censored: the pilot's command
u* = u_hat + eps was at least the upper limit (or at most the lower one), so
such a sample contributes the probability of that event instead of a density:

    -ln L = sum_{free k}  [ ln(sigma) + ln(2 pi)/2 + (u_k - u_hat_k)^2 / (2 sigma^2) ]
          - sum_{upper k} ln Phi_c((hi - u_hat_k) / sigma)
          - sum_{lower k} ln Phi  ((lo - u_hat_k) / sigma)

with eps ~ N(0, sigma^2) independent (Tobin 1958).  ``flags`` marks each
sample: 0 observed, +1 censored at ``hi``, -1 censored at ``lo``.

The normal tail is written with ``math.erfc`` and, far in the tail where erfc
underflows, with the asymptotic series of the Mills ratio; scipy.special is
not callable from numba, which is why these few lines are our own (they are
tested against ``scipy.stats.norm.logsf``).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import njit

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)
_SQRT2 = math.sqrt(2.0)


@njit
def log_sf(z):
    """ln(1 - Phi(z)), the log upper tail of the standard normal, accurate for any z."""
    if z < 25.0:
        return math.log(0.5 * math.erfc(z / _SQRT2))
    # asymptotic: sf(z) = phi(z)/z (1 - 1/z^2 + 3/z^4 - 15/z^6 ...)
    z2 = z * z
    return -0.5 * z2 - _LOG_SQRT_2PI - math.log(z) + math.log1p(-1.0 / z2 + 3.0 / (z2 * z2)
                                                                 - 15.0 / (z2 * z2 * z2))


@njit
def mills(z):
    """phi(z) / (1 - Phi(z)), the inverse Mills ratio, accurate for any z."""
    if z < 25.0:
        sf = 0.5 * math.erfc(z / _SQRT2)
        return math.exp(-0.5 * z * z - _LOG_SQRT_2PI) / sf
    z2 = z * z
    return z / (1.0 - 1.0 / z2 + 3.0 / (z2 * z2) - 15.0 / (z2 * z2 * z2))


@njit
def censored_nll(u, y, flags, lo, hi, sigma, grad_y):
    """-ln L of the censored model and its derivative with respect to each u_hat_k.

    Parameters
    ----------
    u, y : 1-D arrays
        Recorded control and model output u_hat.
    flags : 1-D int array
        0 observed, +1 censored at ``hi``, -1 censored at ``lo``.
    lo, hi : float
        Limits.
    sigma : float
        Standard deviation of the output error (> 0).
    grad_y : 1-D array
        Filled with d(-ln L)/d u_hat_k.

    Returns
    -------
    (value, d_value/d_sigma)
    """
    n = u.shape[0]
    val = 0.0
    dsig = 0.0
    inv = 1.0 / sigma
    lsig = math.log(sigma)
    for k in range(n):
        f = flags[k]
        if f == 0:
            r = (u[k] - y[k]) * inv
            val += lsig + _LOG_SQRT_2PI + 0.5 * r * r
            grad_y[k] = -r * inv
            dsig += inv - r * r * inv
        elif f > 0:
            z = (hi - y[k]) * inv
            val -= log_sf(z)
            lam = mills(z)
            # d/dy -ln sf(z) = lam dz/dy = -lam / sigma ; d/dsigma = lam * (-z / sigma)
            grad_y[k] = -lam * inv
            dsig -= lam * z * inv
        else:
            z = (y[k] - lo) * inv   # Phi((lo - y)/sigma) = sf((y - lo)/sigma)
            val -= log_sf(z)
            lam = mills(z)
            grad_y[k] = lam * inv
            dsig -= lam * z * inv
    return val, dsig


def censored_neg_log_lik(u: np.ndarray, y: np.ndarray, flags: np.ndarray, lo: float, hi: float,
                         sigma: float) -> tuple[float, np.ndarray, float]:
    """Python entry: (-ln L, d/d u_hat, d/d sigma) of :func:`censored_nll`."""
    g = np.empty(u.shape[0])
    v, ds = censored_nll(np.ascontiguousarray(u, dtype=float), np.ascontiguousarray(y, dtype=float),
                         np.ascontiguousarray(flags, dtype=np.int64), float(lo), float(hi),
                         float(sigma), g)
    return float(v), g, float(ds)

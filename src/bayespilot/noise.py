"""Models of the output error: white (Eq. 4) or an autoregressive process.

In closed-loop tracking the output error eps = u - u_hat(theta) at the true
parameters is the pilot's remnant (Eq. 6), a fourth-order low-pass process
that is far from white at 100 Hz.  Eq. 4 treats its samples as independent.
Two things follow, both measured in ``docs/posteriors.md``:

* the intervals from Eq. 4 are several times too narrow, and
* the estimates are biased: the remnant also drives the error e that the
  model takes as a noise-free input, and an output-error fit with a wrong
  (white) noise model is not consistent in closed loop.

A prediction-error fit with a noise model that can represent the remnant's
spectrum is consistent in closed loop (Ljung, *System Identification*, 2nd
ed., Sec. 13.4, the "direct approach").  :class:`ARNoise` is that noise model:
eps_k = sum_j a_j eps_{k-j} + w_k with white innovations w, so the
likelihood is Eq. 4 applied to the whitened residual w = A(q) eps,

    -ln L = (N - p)/2 ln( mean_{k >= p} w_k^2 ) + (N - p)/2,

conditional on the first p samples.  :class:`~bayespilot.likelihood.Likelihood`
takes it as ``noise=``; the fitters and the sampler then work on the
whitened residual unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
from scipy import signal

from ._blas import one_blas_thread

__all__ = ["ARNoise", "fit_ar", "MAX_AR_ORDER"]

#: Largest AR order :func:`fit_ar` and :meth:`ARNoise.from_residual` try by default.
MAX_AR_ORDER = 30


@one_blas_thread
def fit_ar(x: np.ndarray, *, max_order: int = MAX_AR_ORDER, order: int | None = None
           ) -> np.ndarray:
    """AR(p) coefficients of a series by least squares, the order chosen by BIC.

    Least squares on the lagged series (the covariance method) rather than
    Yule-Walker: the remnant's spectrum spans tens of dB and its first
    partial autocorrelation is about 0.997 at 100 Hz, where Yule-Walker
    estimates are badly biased.

    Parameters
    ----------
    x : ndarray
        The series (1-D, finite).  Its mean is removed first.
    max_order : int
        Largest order tried (orders 1..max_order).
    order : int, optional
        Use this order instead of choosing one (0 gives no coefficients).

    Returns
    -------
    a : ndarray, shape (p,)
        x_k = sum_j a_j x_{k-j} + w_k.

    Raises
    ------
    ValueError
        A series that is not finite and 1-D; ``order`` or ``max_order`` not an
        integer, ``max_order`` < 1; or an order of a quarter of the series'
        length or more.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> w = rng.standard_normal(20000)
    >>> x = np.zeros_like(w)
    >>> for k in range(2, w.size): x[k] = 1.2 * x[k - 1] - 0.5 * x[k - 2] + w[k]
    >>> np.round(fit_ar(x, order=2), 1)
    array([ 1.2, -0.5])
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 1 or not np.all(np.isfinite(x)):
        raise ValueError("x must be a finite 1-D array")
    if x.size == 0:
        raise ValueError("x is empty: an AR model needs a series")
    for name, v in (("max_order", max_order), ("order", order)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer))):
            raise ValueError(f"{name} must be an integer, got {v!r}")
    if order is None and max_order < 1:
        raise ValueError(f"max_order must be >= 1, got {max_order}")
    x = x - x.mean()
    n = x.size
    orders = [int(order)] if order is not None else list(range(1, int(max_order) + 1))
    if orders[0] < 0:
        raise ValueError(f"AR order must be >= 0, got {orders[0]}")
    if orders[-1] >= n // 4:  # (an order of a quarter of the series or more)
        raise ValueError(f"an AR({orders[-1]}) model needs at least {4 * (orders[-1] + 1)} "
                         f"samples, got {n}" + ("" if order is not None else
                                                " (give a smaller max_order)"))
    if orders == [0]:
        return np.zeros(0)
    pmax = orders[-1]
    lagged = np.column_stack([x[pmax - j - 1:n - j - 1] for j in range(pmax)])
    y = x[pmax:]
    best = (math.inf, np.zeros(0))
    for p in orders:
        a, *_ = np.linalg.lstsq(lagged[:, :p], y, rcond=None)
        s2 = float(np.mean((y - lagged[:, :p] @ a) ** 2))
        if not s2 > 0:
            break
        bic = y.size * math.log(s2) + p * math.log(y.size)
        if bic < best[0]:
            best = (bic, a)
    return np.asarray(best[1])


@dataclass(frozen=True, eq=False)
class ARNoise:
    """An AR(p) model of the output error, used to whiten it.

    Parameters
    ----------
    a : array_like, shape (p,)
        eps_k = sum_{j=1..p} a_j eps_{k-j} + w_k.  p = 0 is white noise (Eq. 4).

    Notes
    -----
    Whitening is the FIR filter A(q) = 1 - sum_j a_j q^-j, stable whatever the
    coefficients, so the model need not be stationary to be used.

    Examples
    --------
    >>> noise = ARNoise([0.9])
    >>> noise.whiten(np.array([1.0, 1.0, 1.0]))
    array([0.1, 0.1])
    """

    a: np.ndarray

    def __post_init__(self) -> None:
        a = np.array(self.a, dtype=float)
        if a.ndim > 1:
            raise ValueError(f"AR coefficients must be a 1-D sequence, got shape {a.shape}")
        a = a.reshape(-1)
        if not np.all(np.isfinite(a)):
            raise ValueError("AR coefficients must be finite")
        a.setflags(write=False)
        object.__setattr__(self, "a", a)

    @property
    def order(self) -> int:
        """p, the number of coefficients."""
        return int(self.a.size)

    @classmethod
    def from_residual(cls, eps: np.ndarray, *, order: int | None = None,
                      max_order: int = MAX_AR_ORDER) -> "ARNoise":
        """The AR model of a residual by least squares, order by BIC (see :func:`fit_ar`).

        Parameters
        ----------
        eps : ndarray
            The residual (1-D, finite), e.g. :meth:`Likelihood.residual
            <bayespilot.likelihood.Likelihood.residual>` at a fit.
        order : int, optional
            Use this order instead of choosing one by BIC (0: white noise).
        max_order : int, default :data:`MAX_AR_ORDER`
            Largest order tried when ``order`` is not given.

        Returns
        -------
        ARNoise

        Raises
        ------
        ValueError
            As :func:`fit_ar`.
        """
        return cls(fit_ar(eps, order=order, max_order=max_order))

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """w = A(q) x along the first axis, without the first p values (which it conditions on).

        Parameters
        ----------
        x : ndarray, shape (N, ...)
            A series along the first axis (e.g. a residual, or the columns of
            a Jacobian).

        Returns
        -------
        ndarray, shape (N - p, ...)
            The whitened series, in the units of ``x``.

        Raises
        ------
        ValueError
            If ``x`` has p samples or fewer.
        """
        x = np.asarray(x, dtype=float)
        p = self.order
        if x.shape[0] <= p:
            raise ValueError(f"need more than {p} samples to whiten with an AR({p}) model")
        return signal.lfilter(np.concatenate([[1.0], -self.a]), [1.0], x, axis=0)[p:]

    def to_dict(self) -> dict[str, Any]:
        """The model as JSON-ready data: ``{"kind": "ar", "order": p, "a": [a_1, ..., a_p]}``."""
        return {"kind": "ar", "order": self.order, "a": [float(v) for v in self.a]}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "ARNoise":
        """The model :meth:`to_dict` wrote.

        Parameters
        ----------
        d : mapping
            ``{"kind": "ar", "a": [...]}``, optionally with ``"order"``.

        Returns
        -------
        ARNoise

        Raises
        ------
        ValueError
            If ``d`` is not such a mapping, its ``order`` is not the number of
            coefficients, or a coefficient is not finite.
        """
        if not isinstance(d, Mapping) or d.get("kind") != "ar" or "a" not in d:
            raise ValueError(f"not an AR noise model: {d!r}")
        noise = cls(d["a"])
        if "order" in d and d["order"] != noise.order:
            raise ValueError(f"AR noise model of order {d['order']!r} with {noise.order} "
                             f"coefficients: {d!r}")
        return noise

    def __repr__(self) -> str:
        return f"ARNoise(order={self.order})"

"""Posterior sampling of the pilot-model parameters with emcee.

:func:`sample` draws from

    p(theta, r | u)  ~  p(theta) p(r) L(theta, r)

with an affine-invariant ensemble sampler (``emcee.EnsembleSampler``, all
walkers of a half-step evaluated in one parallel batched call), where L is
either

``"eq4"``
    the paper's Eq. 4: white output error, variance profiled out
    (:meth:`bayespilot.likelihood.Likelihood.batch`); or
``"coloured"``
    the output error as an AR(p) process whose innovations are white,
    conditional on the first p samples, innovation variance profiled out
    (:mod:`bayespilot.noise`, ``kernels/_coloured.py``).  By default
    (``ar="profiled"``) the AR model (order by BIC at the initial fit, a
    prediction-error maximum-likelihood fit, :func:`~bayespilot.fit.fast.fit_fast`
    with ``noise="ar"``; or ``ar_order``) is re-estimated by least squares
    from the output error at every parameter vector, i.e. maximised out (a
    profile likelihood; the Laplace determinant of integrating it out is
    neglected).  With ``ar="fixed"`` the AR model is estimated once, from
    the residual of that fit, and held fixed while the pilot parameters are
    sampled (a plug-in, empirical-Bayes noise model: the remnant needs an
    order near 10 at 100 Hz, which would more than double the sampled
    dimensions); this is the likelihood of :mod:`bayespilot.compare`, which
    needs a density to integrate.  In closed loop the remnant also drives
    the model's inputs, so a noise model held fixed makes the gains'
    intervals too narrow; profiling widens them where that coupling is, and
    the calibration study in ``docs/posteriors.md`` finds it within binomial
    error of nominal for every pilot parameter, which is why it is the
    default.  With ``ar="sampled"`` a low-order AR model is sampled with the
    rest through its partial autocorrelations ``pacf_1 ... pacf_p`` in
    (-1, 1), which keeps it stationary; two lags cannot whiten this remnant,
    and the same study shows its intervals overconfident.
    The first ``discard`` seconds (2 by default) are left out of the
    coloured likelihood: the model's start-up error there is not remnant.

Priors: uniform on the model bounds (Table 1) and, for ``ar="sampled"``,
uniform(-0.99, 0.99) on the partial autocorrelations, unless given.  The run stops when the chain is longer
than ``tau_factor`` integrated autocorrelation times and the estimate of tau
has settled (emcee's documented recipe), or at ``max_steps`` with a
:class:`ConvergenceWarning`.  The result is a :class:`Posterior` holding an
ArviZ ``InferenceData`` (burn-in of 2 max(tau) dropped, thinned by min(tau)/2).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import threading
import time
import types
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numba
import numpy as np

from . import _files
from ._html import SummaryHTML
from ._interrupt import interrupt_between_steps
from .fit.result import FitResult
from .kernels import _coloured as C
from .likelihood import (COLOURED_DISCARD, Likelihood, _checked_discard, _startup_default,
                         coloured_discard)
from .model import PilotModel, paper_model
from .noise import MAX_AR_ORDER, ARNoise
from .recording import Recording, _recording_digest
from ._blas import one_blas_thread
from ._caller import warn_at_caller
from ._seeds import resolve_seed

__all__ = ["sample", "Posterior", "ConvergenceWarning", "LIKELIHOODS", "AR_MODES", "PACF_BOUND",
           "COLOURED_DISCARD", "pacf_names", "pacf_from_residual"]

#: Likelihoods :func:`sample` can use.
LIKELIHOODS = ("eq4", "coloured")
#: How the coloured likelihood treats its AR model: estimated once and held, sampled, or
#: re-estimated (profiled out) at every parameter vector.
AR_MODES = ("fixed", "sampled", "profiled")
# COLOURED_DISCARD (imported above, re-exported here): the cap of the coloured likelihood's
# default discard, :func:`~bayespilot.likelihood.coloured_discard` (min(2 s, a quarter of
# the record)); it lives in bayespilot.likelihood with the rule.
#: What a posterior under Eq. 4 (the default, the paper's likelihood) says below its table:
#: measured in docs/posteriors.md, "A held-out check".
EQ4_POSTERIOR_NOTE = (
    "note: Eq. 4 treats the remnant, which is coloured, as white: on closed-loop recordings "
    "these intervals are several times too narrow (docs/posteriors.md, 'A held-out check'); "
    "the coloured likelihood gives calibrated ones (likelihood='coloured'; bayespilot sample "
    "--likelihood coloured)")

#: Default prior on each partial autocorrelation: uniform(-PACF_BOUND, PACF_BOUND).
PACF_BOUND = 0.99
#: Half-width of the initial ball of walkers, as a fraction of each parameter's bound range.
BALL_FRACTION = 1e-3
_ARVIZ_WARNING = r"\s*ArviZ is undergoing a major refactor"
_BACKEND_GROUP = "mcmc"
_FINGERPRINT_ATTR = "bayespilot_fingerprint"
_TAU_ATTR = "bayespilot_last_tau"
_META_ATTR = "bayespilot_posterior"


def _default_discard(recording: Recording, likelihood: str) -> float:
    """The seconds :func:`sample`, :func:`bayespilot.compare.compare` and
    :func:`bayespilot.compare.evidence` leave out by default, as
    :func:`~bayespilot.fit.fast.fit_fast` does:
    :func:`~bayespilot.likelihood.coloured_discard` (min(2 s, a quarter of the record)) for
    ``"coloured"``; for ``"eq4"`` the start-up of a record not known to be whole periods
    (0 on whole periods)."""
    return coloured_discard(recording) if likelihood == "coloured" else \
        _startup_default(recording, "periodic")


class ConvergenceWarning(RuntimeWarning):
    """The chain reached ``max_steps`` before the autocorrelation criterion was met.

    ``tau`` holds the last estimate of the integrated autocorrelation times and
    ``n_steps`` the chain length, so a caller can decide how much longer to run.

    Parameters
    ----------
    message : str
        The warning's text.
    tau : ndarray or None, optional
        The last estimate of the integrated autocorrelation time per sampled
        parameter, in steps (vector order); None if there was none.
    n_steps : int, default 0
        Steps the chain ran.
    """

    def __init__(self, message: str, tau: np.ndarray | None = None, n_steps: int = 0) -> None:
        super().__init__(message)
        self.tau = tau
        self.n_steps = n_steps


def _arviz():
    """arviz, imported without its import-time FutureWarning about the 1.0 refactor."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=_ARVIZ_WARNING, category=FutureWarning)
        import arviz

    return arviz


def pacf_names(order: int) -> tuple[str, ...]:
    """Names of the partial autocorrelations of an AR(order) residual model.

    Parameters
    ----------
    order : int
        The AR order p (not checked: 0 or less gives no names).

    Returns
    -------
    tuple of str
        ``("pacf_1", ..., "pacf_p")``, the names the sampled partial
        autocorrelations have in a :class:`Posterior`.
    """
    return tuple(f"pacf_{j}" for j in range(1, order + 1))


def pacf_from_residual(eps: np.ndarray, order: int) -> np.ndarray:
    """Partial autocorrelations r_1..r_order of ``eps`` (Yule-Walker, Durbin-Levinson).

    Uses the biased sample autocovariance, so |r_j| < 1 (the Yule-Walker AR
    model is stationary).  Plain NumPy.

    Parameters
    ----------
    eps : array_like, shape (n,)
        The residual (output error), finite; its mean is removed first.
    order : int
        Number of partial autocorrelations, 0 <= order < n.

    Returns
    -------
    ndarray, shape (order,)
        r_1 ... r_order (the reflection coefficients of the Durbin-Levinson
        recursion).  All zero when ``eps`` is constant; a coefficient whose
        recursion denominator is not positive, and those after it, are 0.

    Raises
    ------
    ValueError
        If ``eps`` is not a finite 1-D array, or ``order`` is not an integer
        in [0, n - 1].

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> w = rng.standard_normal(20000)
    >>> x = np.empty_like(w); x[0] = w[0]
    >>> for k in range(1, w.size): x[k] = 0.6 * x[k - 1] + w[k]
    >>> bool(abs(pacf_from_residual(x, 2)[0] - 0.6) < 0.02)
    True
    """
    eps = np.asarray(eps, dtype=float)
    if eps.ndim != 1 or not np.all(np.isfinite(eps)):
        raise ValueError("eps must be a finite 1-D array")
    if not isinstance(order, (int, np.integer)) or order < 0 or order >= eps.size:
        raise ValueError(f"order must be an integer in [0, {eps.size - 1}], got {order!r}")
    x = eps - eps.mean()
    n = x.size
    c = np.array([x[: n - k] @ x[k:] / n for k in range(order + 1)])
    r = np.zeros(order)
    if not c[0] > 0:
        return r
    rho = c / c[0]
    a = np.zeros(0)
    for k in range(1, order + 1):
        den = 1.0 - a @ rho[1:k]
        kk = (rho[k] - a @ rho[k - 1:0:-1]) / den if den > 0 else 0.0
        a = np.concatenate([a - kk * a[::-1], [kk]])
        r[k - 1] = kk
    return r


# --- the posterior ---------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Posterior(SummaryHTML):
    """Posterior draws of the pilot parameters (and AR partial autocorrelations).

    Attributes
    ----------
    idata : arviz.InferenceData
        ``posterior``: one variable per parameter, dims (chain = walker, draw),
        burn-in (2 max tau) dropped and thinned by min(tau)/2; ``sample_stats``:
        ``lp`` (log posterior) and ``acceptance`` (fraction of accepted
        proposals per walker over the thinning window ending at each draw).
        The settings are in the groups' attrs.
    parameter_names : tuple of str
        Sampled parameters, in vector order (pilot parameters, then pacf_j).
    tau : dict
        Integrated autocorrelation time (steps) per parameter, at the end.
    converged : bool
        Whether the autocorrelation criterion was met before ``max_steps``.
    settings : dict
        Every setting of the run, and its bookkeeping (steps, discard, thin,
        acceptance, timing, the initial point).
    seed : int or None
        The seed used (drawn from fresh entropy when ``seed=None`` was
        given); None in results saved before it was recorded.
    """

    _html_text = "__str__"  # (a notebook shows its printed account)

    idata: Any
    parameter_names: tuple[str, ...]
    tau: dict[str, float]
    converged: bool
    settings: dict[str, Any] = field(default_factory=dict)
    seed: int | None = None

    def _check_name(self, name: str) -> None:
        if name not in self.parameter_names:
            raise ValueError(f"unknown parameter {name!r}; sampled: {', '.join(self.parameter_names)}")

    def draws(self, name: str) -> np.ndarray:
        """All retained draws of ``name``, walkers concatenated (1-D).

        Parameters
        ----------
        name : str
            A sampled parameter (one of :attr:`parameter_names`).

        Returns
        -------
        ndarray, shape (n_walkers * n_draws,)
            The draws in the parameter's unit, walker by walker.

        Raises
        ------
        ValueError
            If ``name`` was not sampled.

        Notes
        -----
        A copy: changing it leaves the posterior as it is.
        """
        self._check_name(name)
        return np.array(self.idata.posterior[name].values, dtype=float).ravel()

    def credible_interval(self, name: str, prob: float = 0.9) -> tuple[float, float]:
        """Highest-density interval of ``name`` holding ``prob`` of the posterior (arviz.hdi).

        Parameters
        ----------
        name : str
            A sampled parameter (one of :attr:`parameter_names`).
        prob : float, default 0.9
            Posterior probability inside the interval, in (0, 1).

        Returns
        -------
        (float, float)
            Lower and upper end, in the parameter's unit.

        Raises
        ------
        ValueError
            If ``name`` was not sampled or ``prob`` is not in (0, 1).
        """
        self._check_name(name)
        if not (isinstance(prob, (int, float)) and 0.0 < prob < 1.0):
            raise ValueError(f"prob must be in (0, 1), got {prob!r}")
        az = _arviz()
        lo, hi = az.hdi(self.draws(name), hdi_prob=float(prob))
        return float(lo), float(hi)

    def summary(self) -> dict[str, dict[str, Any]]:
        """Per parameter: mean, median, hdi_90 [low, high], r_hat, ess_bulk, ess_tail (arviz)
        and tau, the integrated autocorrelation time of the chain in steps (emcee).

        r_hat and the ESS treat each walker as a chain, as ``arviz.from_emcee``
        does; walkers of one ensemble are not independent, so r_hat is a
        consistency check, not a proof of convergence (see ``converged``).
        """
        az = _arviz()
        post = self.idata.posterior
        hdi = az.hdi(self.idata, hdi_prob=0.9)
        rhat = az.rhat(self.idata)
        ess = az.ess(self.idata, method="bulk")
        ess_tail = az.ess(self.idata, method="tail")
        out = {}
        for n in self.parameter_names:
            x = np.asarray(post[n].values, dtype=float)
            lo, hi = (float(v) for v in np.asarray(hdi[n].values))
            out[n] = {"mean": float(x.mean()), "median": float(np.median(x)),
                      "hdi_90": [lo, hi], "r_hat": float(rhat[n].values),
                      "ess_bulk": float(ess[n].values), "ess_tail": float(ess_tail[n].values),
                      "tau": float(self.tau.get(n, math.nan))}
        return out

    @property
    def truth(self) -> dict[str, float]:
        """The true parameters when the recording carried them (a simulation), else {}."""
        return dict(self.settings.get("true_parameters") or {})

    def to_netcdf(self, path: str | os.PathLike) -> Path:
        """Write the InferenceData (with everything needed by :meth:`from_netcdf`) to ``path``.

        The posterior's fields as they are now (``parameter_names``, ``tau``,
        ``converged``, ``settings``, ``seed``; a changed setting included) are
        written in the groups' attributes, as :func:`sample` writes them, in
        place of those the InferenceData was given when the chain ended.
        ``idata`` itself is not changed.

        Parameters
        ----------
        path : str or os.PathLike
            The file to write (netCDF-4); an existing file is replaced only
            once the new one is written.

        Returns
        -------
        Path
            ``path``.

        Raises
        ------
        OSError
            If the file cannot be written (a full disk, ``path`` a folder); the old file is
            kept and no temporary file is left.

        Notes
        -----
        The file is built in memory (:func:`_netcdf_image`) and its bytes written with
        :func:`~bayespilot._files.replacing`: HDF5 writing straight to a full disk failed
        part-way (h5py RuntimeErrors, multi-line messages, a segmentation fault).
        """
        from ._files import replacing

        meta = {"parameter_names": list(self.parameter_names), "tau": dict(self.tau),
                "converged": bool(self.converged), "settings": dict(self.settings or {}),
                "seed": self.seed}
        # a shallow copy of each group: the draws are shared, the attributes are its own
        az = _arviz()
        idata = az.InferenceData(**{g: getattr(self.idata, g).copy(deep=False)
                                    for g in self.idata.groups()})
        _set_meta_attrs(idata, meta)
        image = _netcdf_image(idata)
        with replacing(path) as tmp:  # the old file is kept if the write fails
            tmp.write_bytes(image)
        return Path(path)

    @classmethod
    def from_netcdf(cls, path: str | os.PathLike) -> "Posterior":
        """Read a file written by :meth:`to_netcdf`.

        Parameters
        ----------
        path : str or os.PathLike
            The netCDF file.

        Returns
        -------
        Posterior

        Raises
        ------
        FileNotFoundError
            If there is no such file.
        ValueError
            If the file is not netCDF, or not written by :meth:`to_netcdf`.
        """
        az = _arviz()
        if not Path(path).is_file():
            raise FileNotFoundError(f"{path}: no such file")
        try:
            idata = az.from_netcdf(str(path))
        except (OSError, ValueError) as exc:  # h5py: "file signature not found", ...
            raise ValueError(f"{path}: not a netCDF file written by Posterior.to_netcdf "
                             f"({exc})") from None
        try:
            meta = json.loads(idata.posterior.attrs[_META_ATTR])
        except KeyError:
            raise ValueError(f"{path}: not written by bayespilot.sample (no {_META_ATTR!r} "
                             "attribute on the posterior group)") from None
        settings = dict(meta["settings"])
        if "tau_history" in settings:  # [[iteration, max tau], ...]; max tau null when NaN
            settings["tau_history"] = [[int(it), _files.number(t)]
                                       for it, t in settings["tau_history"]]
        return cls(idata, tuple(meta["parameter_names"]), _files.numbers(meta["tau"]),
                   bool(meta["converged"]), settings, meta["seed"])

    def __repr__(self) -> str:
        """One line (the dataclass's would print the whole InferenceData and settings)."""
        try:
            sizes = self.idata.posterior.sizes
            n_walkers, n_draws = int(sizes["chain"]), int(sizes["draw"])
            draws = f", {n_walkers * n_draws} draws ({n_walkers} walkers x {n_draws})"
        except Exception:  # an idata without the usual dims: still a repr
            draws = ""
        names = tuple(self.parameter_names)
        shown = (", ".join(names) if len(names) <= 4
                 else f"{', '.join(names[:3])}, ..., {names[-1]}")
        return (f"<Posterior: {len(names)} parameters ({shown}){draws}, "
                f"{(self.settings or {}).get('likelihood', '?')} likelihood, "
                f"{'converged' if self.converged else 'NOT converged'}, seed {self.seed}>")

    def __str__(self) -> str:
        s = self.summary()
        lines = [f"bayespilot posterior ({self.settings.get('likelihood')} likelihood, "
                 f"{'converged' if self.converged else 'NOT converged'}, seed {self.seed})",
                 f"{'parameter':<10} {'mean':>10} {'median':>10} {'hdi 90%':>23} "
                 f"{'r_hat':>6} {'ess_bulk':>8} {'tau':>7}"]
        for n, d in s.items():
            lines.append(f"{n:<10} {d['mean']:>10.4g} {d['median']:>10.4g} "
                         f"[{d['hdi_90'][0]:>10.4g},{d['hdi_90'][1]:>10.4g}] "
                         f"{d['r_hat']:>6.3f} {d['ess_bulk']:>8.0f} {self.tau[n]:>7.1f}")
        if self.settings.get("likelihood") == "eq4":
            lines.append(EQ4_POSTERIOR_NOTE)
        return "\n".join(lines)


# --- priors ----------------------------------------------------------------------------
def _describe(dist) -> str:
    if callable(dist) and not hasattr(dist, "logpdf"):
        return f"callable {getattr(dist, '__qualname__', type(dist).__name__)}"
    name = getattr(getattr(dist, "dist", None), "name", type(dist).__name__)
    args = ", ".join([*(f"{a:g}" if isinstance(a, (int, float)) else repr(a) for a in dist.args),
                      *(f"{k}={v:g}" if isinstance(v, (int, float)) else f"{k}={v!r}"
                        for k, v in dist.kwds.items())])
    return f"{name}({args})"


class _Prior:
    """Vectorised log-prior on rows [free pilot parameters, pacf_1..pacf_p].

    ``box`` is where the likelihood is defined (model bounds; (-1, 1) for the
    partial autocorrelations); every prior is truncated to it.
    """

    def __init__(self, names, box_lo, box_hi, default_lo, default_hi, spec) -> None:
        self.names = tuple(names)
        self.box_lo = np.asarray(box_lo, float)
        self.box_hi = np.asarray(box_hi, float)
        self.callable = None
        self.dists: dict[int, Any] = {}
        lo = np.asarray(default_lo, float).copy()
        hi = np.asarray(default_hi, float).copy()
        if spec is None:  # (the PACF terms named only where there are some: coloured)
            pacf = any(n.startswith("pacf_") for n in self.names)
            self.description = "uniform on the model bounds" + (
                f"; uniform(-{PACF_BOUND}, {PACF_BOUND}) on pacf_j" if pacf else "")
        elif isinstance(spec, Mapping):
            unknown = [k for k in spec if k not in self.names]
            if unknown:
                raise ValueError(f"prior for unknown parameter(s) {', '.join(map(repr, unknown))}; "
                                 f"sampled parameters: {', '.join(self.names)}")
            desc = []
            for k, dist in spec.items():
                i = self.names.index(k)
                if not (hasattr(dist, "logpdf") and hasattr(dist, "cdf") and hasattr(dist, "support")):
                    raise TypeError(f"prior for {k} must be a frozen continuous scipy.stats "
                                    f"distribution (e.g. scipy.stats.uniform(0, 1)), got "
                                    f"{type(dist).__name__}")
                s_lo, s_hi = (float(v) for v in dist.support())
                mass = float(dist.cdf(self.box_hi[i]) - dist.cdf(self.box_lo[i]))
                if not (s_lo < self.box_hi[i] and s_hi > self.box_lo[i] and mass > 0):
                    raise ValueError(f"prior for {k} has support [{s_lo:g}, {s_hi:g}], outside the "
                                     f"bounds of {k}, [{self.box_lo[i]:g}, {self.box_hi[i]:g}]: "
                                     "it has no probability where the model is defined")
                self.dists[i] = dist
                lo[i] = max(s_lo, self.box_lo[i])
                hi[i] = min(s_hi, self.box_hi[i])
                desc.append(f"{k} ~ {_describe(dist)}")
            self.description = "; ".join(desc) + " (truncated to the bounds); uniform otherwise"
        elif callable(spec):
            self.callable = spec
            lo, hi = self.box_lo.copy(), self.box_hi.copy()
            self.description = f"{_describe(spec)} on the bounds"
        else:
            raise TypeError("prior must be None, a mapping of parameter name to a frozen "
                            f"scipy.stats distribution, or a callable; got {type(spec).__name__}")
        self.lo = lo
        self.hi = hi
        free = [i for i in range(len(self.names)) if i not in self.dists]
        self._uniform = np.array(free, dtype=np.int64)
        self._const = -float(np.sum(np.log(hi[free] - lo[free]))) if self.callable is None else 0.0

    def inside(self, X: np.ndarray) -> np.ndarray:
        """Rows strictly inside the support (open at pacf +-1)."""
        return np.all((X >= self.lo) & (X <= self.hi), axis=1) & np.all(np.abs(X) < np.inf, axis=1)

    def __call__(self, X: np.ndarray) -> np.ndarray:
        X = np.atleast_2d(X)
        out = np.where(self.inside(X), self._const, -np.inf)
        for i, dist in self.dists.items():
            ok = np.isfinite(out)
            if ok.any():
                out[ok] += dist.logpdf(X[ok, i])
        if self.callable is not None:
            for r in np.flatnonzero(np.isfinite(out)):
                try:
                    v = float(self.callable(X[r].copy()))
                except (TypeError, ValueError) as exc:
                    raise ValueError(f"the prior callable must return a number: {exc}") from exc
                out[r] += v
        out[np.isnan(out)] = -np.inf
        return out

    def center(self, x: np.ndarray) -> np.ndarray:
        """``x`` moved, where the prior is zero there, to the prior's median (clipped to the support)."""
        x = np.array(x, dtype=float)
        for i, dist in self.dists.items():
            if not np.isfinite(dist.logpdf(x[i])) or not (self.lo[i] <= x[i] <= self.hi[i]):
                x[i] = float(np.clip(dist.median(), self.lo[i], self.hi[i]))
        return np.clip(x, self.lo, self.hi)


# --- the target --------------------------------------------------------------------------
class _LogPosterior:
    """log p(rows | u) for an (M, ndim) array, all rows in one parallel kernel call."""

    def __init__(self, lik: Likelihood, order: int, prior: _Prior, profiled: int = 0) -> None:
        self.lik = lik
        self.order = order
        self.profiled = int(profiled)
        self.prior = prior
        self.n_model = lik.model.n_free
        self.free_idx = lik.model.free_index
        self.base = lik.model.full_vector()
        self.n_calls = 0
        self.n_rows = 0

    def neg_log_lik(self, rows: np.ndarray) -> np.ndarray:
        rows = np.ascontiguousarray(rows, dtype=float)
        if self.order == 0 and not self.profiled:
            return self.lik.batch(rows)
        m = rows.shape[0]
        out = np.empty(m)
        floored = np.zeros(m, dtype=np.bool_)
        lik = self.lik
        n_chunks = max(1, min(m, numba.get_num_threads()))
        if self.profiled:
            C.neg_log_lik_profiled_batch(rows, self.free_idx, self.base, self.profiled, lik.X,
                                         lik.u, *lik._args(), lik.dt, lik.periodic, lik.warm,
                                         lik.s2_floor, n_chunks, out, floored, lik.skip)
            out[~np.isfinite(out)] = np.inf
            return out
        C.neg_log_lik_coloured_batch(rows, self.n_model, self.free_idx, self.base, lik.X, lik.u,
                                     *lik._args(), lik.dt, lik.periodic, lik.warm, lik.s2_floor,
                                     n_chunks, out, floored, lik.skip)
        out[~np.isfinite(out)] = np.inf
        return out

    def __call__(self, X: np.ndarray) -> np.ndarray:
        X = np.atleast_2d(np.asarray(X, dtype=float))
        lp = self.prior(X)
        ok = np.isfinite(lp)
        out = np.full(X.shape[0], -np.inf)
        if ok.any():
            self.n_calls += 1
            self.n_rows += int(ok.sum())
            out[ok] = lp[ok] - self.neg_log_lik(X[ok])
        out[~np.isfinite(out)] = -np.inf
        return out


# --- the sampler loop --------------------------------------------------------------------
@dataclass
class _Run:
    sampler: Any
    tau: np.ndarray
    converged: bool
    n_steps: int
    history: list
    start_iteration: int


def _autocorr(sampler) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.asarray(sampler.get_autocorr_time(tol=0), dtype=float)


def _criterion(tau, old_tau, iteration, *, min_steps, tau_factor, tau_rtol) -> bool:
    if not (np.all(np.isfinite(tau)) and np.all(tau > 0)):
        return False
    return bool(iteration >= min_steps and np.all(tau_factor * tau < iteration)
                and np.all(np.abs(old_tau - tau) / tau < tau_rtol))


def _run_emcee(log_prob: Callable[[np.ndarray], np.ndarray], p0: np.ndarray | None, *,
               n_walkers: int, ndim: int, max_steps: int, min_steps: int, check_every: int,
               tau_factor: float, tau_rtol: float, random_state=None, progress: bool = False,
               backend=None) -> _Run:
    """Run emcee until the autocorrelation criterion holds or ``max_steps`` (see :func:`sample`).

    ``log_prob`` takes an (M, ndim) array and returns M values (vectorised).
    ``p0`` is the initial ensemble, ignored when ``backend`` already holds a
    chain (the run continues from its last state and saved random state).
    ``random_state`` (a ``RandomState.get_state()`` tuple) seeds a fresh run.
    """
    import emcee

    sampler = emcee.EnsembleSampler(n_walkers, ndim, log_prob, vectorize=True, backend=backend)
    start = int(sampler.iteration)
    old_tau = np.full(ndim, np.inf)
    if start == 0:
        if p0 is None:
            raise ValueError("an initial ensemble is needed to start a new chain")
        if random_state is not None:
            sampler.random_state = random_state
        state = p0
    else:
        state = sampler.get_last_sample()
        if backend is not None:
            old_tau = _read_backend_tau(backend, ndim, old_tau)
    history: list = []
    converged = False
    remaining = max_steps - start
    if remaining > 0:
        gen = sampler.sample(state, iterations=remaining, progress=progress)
        # (a Ctrl-C at the end of a step: inside emcee's call of log_prob its wrapper printed
        # the ensemble and a traceback; a backend then holds the whole last step)
        with interrupt_between_steps() as check_interrupt:
            try:
                for _ in gen:
                    check_interrupt()
                    it = sampler.iteration
                    if it % check_every:
                        continue
                    tau = _autocorr(sampler)
                    history.append([int(it), float(np.max(tau))])
                    converged = _criterion(tau, old_tau, it, min_steps=min_steps,
                                           tau_factor=tau_factor, tau_rtol=tau_rtol)
                    old_tau = tau
                    if backend is not None:
                        _write_backend_attr(backend, _TAU_ATTR, tau)
                    if converged:
                        break
            finally:
                gen.close()
            check_interrupt()  # (pressed during the last step)
    n = int(sampler.iteration)
    if not converged:
        tau = _autocorr(sampler)
        if not history or history[-1][0] != n:
            converged = _criterion(tau, old_tau, n, min_steps=min_steps, tau_factor=tau_factor,
                                   tau_rtol=tau_rtol)
            history.append([n, float(np.max(tau))])
    else:
        tau = old_tau
    return _Run(sampler, np.asarray(tau, float), converged, n, history, start)


# --- HDF5 backend bookkeeping -------------------------------------------------------------
def _write_backend_attr(backend, key: str, value) -> None:
    import h5py

    with h5py.File(backend.filename, "a") as f:
        f[backend.name].attrs[key] = value


def _read_backend_tau(backend, ndim, default):
    import h5py

    with h5py.File(backend.filename, "r") as f:
        v = f[backend.name].attrs.get(_TAU_ATTR)
    v = None if v is None else np.asarray(v, float)
    return v if (v is not None and v.shape == (ndim,)) else default


#: Fingerprint keys added after chains were first written (such a chain lacks them).
_FINGERPRINT_ADDED = ("support",)


def _open_backend(path, fingerprint: dict, n_walkers: int, ndim: int):
    """An emcee HDFBackend at ``path``; (backend, resuming).  Raises if it holds another run."""
    import h5py
    from emcee.backends import HDFBackend

    if Path(path).exists() and not (Path(path).is_file() and h5py.is_hdf5(str(path))):
        raise ValueError(f"backend {path} is not an HDF5 file; give another path (.h5) or "
                         "delete the file")
    backend = HDFBackend(str(path), name=_BACKEND_GROUP)
    if not backend.initialized:
        return backend, False
    with h5py.File(str(path), "r") as f:
        g = f[_BACKEND_GROUP]
        stored = g.attrs.get(_FINGERPRINT_ATTR)
        iteration = int(g.attrs.get("iteration", 0))
    if stored is None:
        raise ValueError(f"backend {path} holds an emcee chain not written by bayespilot.sample; "
                         "give another path or delete the file")
    stored = json.loads(stored)
    # a chain written before a key was added to the fingerprint is not refused for lacking it
    diff = sorted(k for k in set(stored) | set(fingerprint) if stored.get(k) != fingerprint.get(k)
                  and not (k in _FINGERPRINT_ADDED and k not in stored))
    if backend.shape != (n_walkers, ndim):
        diff.append(f"shape {tuple(backend.shape)} != {(n_walkers, ndim)}")
    if diff:
        raise ValueError(f"backend {path} holds a chain of a different run (differs in: "
                         f"{', '.join(diff)}); give another path or delete the file to start over")
    return backend, iteration > 0


def _stored_fingerprint(path) -> dict | None:
    """The fingerprint a bayespilot chain in the HDF5 file ``path`` was written with, if any."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        import h5py

        with h5py.File(str(path), "r") as f:
            g = f.get(_BACKEND_GROUP)
            stored = None if g is None else g.attrs.get(_FINGERPRINT_ATTR)
            iteration = 0 if g is None else int(g.attrs.get("iteration", 0))
    except OSError:
        return None  # not HDF5: _open_backend says so
    return json.loads(stored) if stored is not None and iteration > 0 else None


def _fingerprint(recording: Recording, model: PilotModel, names, likelihood: str, order: int,
                 prior: _Prior, n_walkers: int, lik: Likelihood, profiled: int = 0) -> dict:
    h = hashlib.sha256()
    for arr in (lik.u, lik.X):
        h.update(np.ascontiguousarray(arr, dtype=float).tobytes())
    h.update(repr((recording.sample_rate_hz, recording.motion_gain)).encode())
    return {"recording_sha256": h.hexdigest(), "model": model.name,
            "parameter_names": list(names), "fixed": {k: float(v) for k, v in model.fixed.items()},
            # the prior's support: the model's bounds (a same-named model with other bounds is
            # another run) and a mapping prior's truncation
            "support": [[float(a), float(b)] for a, b in zip(prior.lo, prior.hi)],
            "likelihood": likelihood, "ar_order": order, "prior": prior.description,
            "n_walkers": n_walkers, "discard_seconds": lik.discard,
            "noise": None if lik.noise is None else lik.noise.to_dict(),
            **({"profiled_ar_order": profiled} if profiled else {})}


# --- the chain as InferenceData ----------------------------------------------------------------
def _meta_attrs(meta: Mapping[str, Any]) -> dict[str, Any]:
    """The attributes of a posterior's groups that hold ``meta`` (``parameter_names``,
    ``tau``, ``converged``, ``settings``, ``seed``): :data:`_META_ATTR`, the JSON that
    :meth:`Posterior.from_netcdf` reads back, and, for other netCDF readers, each scalar
    setting, ``true_<name>`` for each true parameter and ``converged`` (0 or 1) on their own;
    with :data:`~bayespilot._files.VERSION_KEY`, the release that wrote them."""
    from . import __version__

    # Standard JSON (non-finite numbers as null, as every result file of the project), which
    # strict parsers outside Python read; from_netcdf makes tau's nulls NaN again.
    attrs: dict[str, Any] = {_files.VERSION_KEY: __version__, _META_ATTR: _files.dumps(meta)}
    for k, v in meta["settings"].items():
        if isinstance(v, (str, int, float)) and not isinstance(v, bool):
            attrs[k] = v
        elif isinstance(v, bool):
            attrs[k] = int(v)
    for k, v in (meta["settings"].get("true_parameters") or {}).items():
        attrs[f"true_{k}"] = float(v)
    attrs["converged"] = int(meta["converged"])
    return attrs


def _set_meta_attrs(idata, meta: Mapping[str, Any]) -> None:
    """Write :func:`_meta_attrs` of ``meta`` on ``idata``'s posterior and sample_stats groups
    (:func:`_to_idata` and :meth:`Posterior.to_netcdf`), first removing those of the meta they
    held before (a setting since removed must not stay behind as an attribute)."""
    new = _meta_attrs(meta)
    for name in ("posterior", "sample_stats"):
        group = getattr(idata, name, None)
        if group is None:
            continue
        stale: set[str] = set()
        if _META_ATTR in group.attrs:
            try:
                stale = set(_meta_attrs(json.loads(group.attrs[_META_ATTR])))
            except (ValueError, KeyError, TypeError, AttributeError):
                pass  # not a meta this release can read: its attributes are overwritten only
        for k in stale - set(new) - {_files.VERSION_KEY}:
            group.attrs.pop(k, None)
        group.attrs.update(new)


#: Serialises :func:`_netcdf_image`'s change of dask's (process-wide) scheduler setting.
_NETCDF_LOCK = threading.Lock()


def _netcdf_image(idata) -> bytes:
    """``idata`` as the bytes of a netCDF-4 file, built in memory (for
    :meth:`Posterior.to_netcdf`).

    The file ``InferenceData.to_netcdf`` writes (engine h5netcdf): its attributes, then each
    group in order, zlib on the variables of a numeric dtype; the same groups, variables,
    attributes, dtypes, chunks and filters, and the same bytes run to run.  Only the bytes
    are then written to disk, by plain Python: HDF5 writing a file itself failed part-way
    on a full disk (h5py RuntimeErrors, messages of several lines, a segmentation fault
    when the file was closed) and left its temporary file.

    The write runs under dask's synchronous scheduler: xarray locks the file it writes
    with a lock of the current scheduler, which under a dask.distributed client (fit-batch
    writes each posterior in the client's process) is the cluster's, named by the target,
    and the cluster cannot name an in-memory file ("RuntimeError: Semaphore or Lock ... not
    known"); this process's own lock is the right one for its own buffer.
    """
    import io

    import dask
    import xarray as xr

    def compressible(dtype) -> bool:  # (arviz's rule for its default compression)
        if dtype.kind == "V":
            return all(compressible(d) for d, *_ in dtype.fields.values())
        return dtype.kind in "biufcS"

    buf = io.BytesIO()
    mode = "w"
    attrs = dict(getattr(idata, "_attrs", None) or {})
    # (dask's config is the process's: two threads writing at once left it synchronous)
    with _NETCDF_LOCK, dask.config.set(scheduler="synchronous"):
        if attrs:
            xr.Dataset(attrs=attrs).to_netcdf(buf, mode=mode, engine="h5netcdf", group="/")
            mode = "a"
        for name in idata.groups():
            data = getattr(idata, name)
            encoding = {v: {"zlib": True} for v, x in data.variables.items()
                        if compressible(x.dtype)}
            data.to_netcdf(buf, mode=mode, group=f"/{name}", engine="h5netcdf",
                           encoding=encoding)
            mode = "a"
    if mode == "w":  # no groups, no attributes: an empty netCDF file, as arviz writes
        import h5netcdf

        h5netcdf.File(buf, mode="w").close()
    return buf.getvalue()


def _to_idata(sampler, names, tau: np.ndarray, meta: dict,
              units: Mapping[str, str] | None = None):
    chain = np.asarray(sampler.get_chain(), dtype=float)  # (steps, walkers, ndim)
    lp = np.asarray(sampler.get_log_prob(), dtype=float)
    n = chain.shape[0]
    finite = tau[np.isfinite(tau) & (tau > 0)]
    tmax = float(finite.max()) if finite.size else 1.0
    tmin = float(finite.min()) if finite.size else 1.0
    discard = int(min(int(2 * tmax), n // 2))
    thin = max(1, int(0.5 * tmin))
    moved = np.zeros(chain.shape[:2])
    moved[1:] = np.any(chain[1:] != chain[:-1], axis=2)
    moved[0] = np.nan  # the first step's proposal is not recorded against p0
    cum = np.nancumsum(moved, axis=0)
    idx = np.arange(discard, n, thin)
    lo = np.maximum(idx - thin, 0)
    width = np.maximum(idx - lo, 1)
    acc = (cum[idx] - cum[lo]) / width[:, None]
    if idx.size and idx[0] == 0:
        acc[0] = np.nan
    posterior = {nm: chain[idx, :, i].T.copy() for i, nm in enumerate(names)}
    stats = {"lp": lp[idx].T.copy(), "acceptance": acc.T.copy()}
    meta = dict(meta)
    meta["settings"] = dict(meta["settings"], discard=discard, thin=thin, n_draws=int(idx.size))
    import emcee

    az = _arviz()
    with warnings.catch_warnings():
        # arviz guesses the axes were swapped when there are more chains than draws; here
        # they are not (walkers first, by construction above), so its warning would mislead
        warnings.filterwarnings("ignore", message="More chains", category=UserWarning)
        idata = az.from_dict(posterior=posterior, sample_stats=stats)
    for group in (idata.posterior, idata.sample_stats):
        group.attrs.update({"inference_library": "emcee",
                            "inference_library_version": emcee.__version__})
    _set_meta_attrs(idata, meta)
    # CF-style units of each variable (the model's notation: "-" is dimensionless), for
    # netCDF readers; Posterior.from_netcdf does not need them
    for nm, unit in (units or {}).items():
        if nm in idata.posterior:
            idata.posterior[nm].attrs["units"] = unit
    return idata, meta


# --- the public entry point ----------------------------------------------------------------------
def _true_parameters(recording: Recording, names) -> dict[str, float] | None:
    """The true parameters a simulated recording carries in its metadata
    (``simulation.parameters``, as ``bayespilot simulate`` writes), restricted to ``names``."""
    sim = recording.metadata.get("simulation") if isinstance(recording.metadata, Mapping) else None
    par = sim.get("parameters") if isinstance(sim, Mapping) else None
    if not isinstance(par, Mapping):
        return None
    out = {}
    for k, v in par.items():
        if k in names and isinstance(v, (int, float)) and not isinstance(v, bool) \
                and math.isfinite(float(v)):
            out[k] = float(v)
    return out or None


def likelihood_options(model: PilotModel | None, likelihood: str, ar: str,
                       ar_order: int | None, modes: tuple[str, ...] = AR_MODES
                       ) -> tuple[PilotModel, int]:
    """Validate the likelihood settings shared by :func:`sample` and :mod:`bayespilot.compare`.

    Returns the model (default: the paper's) and p, the number of sampled
    partial autocorrelations (0 unless ``likelihood="coloured"`` with
    ``ar="sampled"``, where it is ``ar_order`` or 2; a profiled AR model is not sampled).
    """
    model = paper_model() if model is None else model
    if not isinstance(model, PilotModel):
        raise TypeError(f"model must be a PilotModel, got {type(model).__name__}")
    if likelihood not in LIKELIHOODS:
        raise ValueError(f"likelihood must be one of {LIKELIHOODS}, got {likelihood!r}")
    if ar not in modes:
        raise ValueError(f"ar must be one of {modes}, got {ar!r}")
    sampled = likelihood == "coloured" and ar == "sampled"
    if ar_order is not None:
        _check_int("ar_order", ar_order, 1 if sampled else 0)
        if not sampled and ar_order > MAX_AR_ORDER:
            raise ValueError(f"ar_order must be at most {MAX_AR_ORDER}, got {ar_order}")
        if likelihood == "coloured" and ar == "profiled" and ar_order == 0:
            raise ValueError("ar_order=0 with ar='profiled': a profiled AR model needs an order "
                             ">= 1 (its coefficients are what is re-fitted at every parameter "
                             "vector); use ar_order=None for the order chosen by BIC, or "
                             "likelihood='eq4' for white output error")
    return model, ((2 if ar_order is None else int(ar_order)) if sampled else 0)


def _check_int(name, v, lo):
    if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < lo:
        raise ValueError(f"{name} must be an integer >= {lo}, got {v!r}")
    return int(v)


def _check_pos(name, v):
    if not (isinstance(v, (int, float, np.floating)) and not isinstance(v, bool)
            and math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a positive number, got {v!r}")
    return float(v)


def _initial_ensemble(center, prior: _Prior, logpost: _LogPosterior, n_walkers: int,
                      rng: np.random.Generator) -> np.ndarray:
    """Walkers in a ball of BALL_FRACTION of the support around ``center``, all with finite log p."""
    lo, hi = prior.lo, prior.hi
    width = BALL_FRACTION * (hi - lo)
    c = np.clip(center, lo + width, hi - width)
    p0 = np.empty((n_walkers, c.size))
    todo = np.arange(n_walkers)
    for _ in range(100):
        x = c + width * rng.standard_normal((todo.size, c.size))
        x = np.where(x < lo, 2 * lo - x, x)  # reflect at the bounds
        x = np.where(x > hi, 2 * hi - x, x)
        x = np.clip(x, lo, hi)
        p0[todo] = x
        bad = ~np.isfinite(logpost(x))
        todo = todo[bad]
        if todo.size == 0:
            return p0
    why = ""
    row = np.asarray(center, dtype=float)[None, :]
    if np.isfinite(prior(row)[0]) and not np.isfinite(logpost(row)[0]):
        # (the init itself is unstable: the loop or a block; perhaps every vector in the box is)
        why = ("; the init itself has a non-finite likelihood (-ln L = +inf: its parameters "
               "make the closed loop or a block unstable), and if no parameter vector within "
               "the bounds is stable (fit_fast says so: 'no start gave a finite likelihood'), no "
               "init will do: check the blocks' bounds")
    raise RuntimeError(f"could not place {todo.size} of {n_walkers} walkers where the posterior is "
                       f"positive around the initial point; give a better init{why}")


@one_blas_thread
def sample(recording: Recording, model: PilotModel | None = None, *, likelihood: str = "eq4",
           ar: str = "profiled", ar_order: int | None = None, noise: ARNoise | None = None,
           discard: float | None = None,
           init: FitResult | Mapping[str, float] | None = None,
           n_walkers: int | None = None, max_steps: int = 20000, min_steps: int = 1000,
           check_every: int = 500, tau_factor: float = 50.0, tau_rtol: float = 0.05,
           seed: int | None = None, progress: bool = True,
           backend: str | os.PathLike | None = None,
           prior: Mapping[str, Any] | Callable[[np.ndarray], float] | None = None) -> Posterior:
    """Sample the posterior of the pilot parameters with emcee (see module docs).

    Parameters
    ----------
    recording : Recording
    model : PilotModel, optional
        Default :func:`~bayespilot.model.paper_model` (with threshold).
    likelihood : {"eq4", "coloured"}
        White output error (Eq. 4) or AR-coloured output error (module docs).
    ar : {"profiled", "fixed", "sampled"}
        ``"coloured"`` only: the AR model re-estimated at every parameter
        vector (default), estimated once and held fixed, or sampled with the
        pilot parameters (module docs).
    ar_order : int, optional
        p of the AR model (``"coloured"`` only).  Default: chosen by BIC (up to
        :data:`~bayespilot.noise.MAX_AR_ORDER`) for ``ar="fixed"`` and
        ``"profiled"`` (at the initial fit; at least 1 for ``"profiled"``),
        2 for ``ar="sampled"``.  0 (white) is refused with ``ar="profiled"``.
    noise : ARNoise, optional
        ``"coloured"`` with ``ar="fixed"`` only: use this AR model rather than
        estimating one (e.g. to judge several runs by one noise model).
    discard : float, optional
        Seconds at the start left out of the likelihood (see
        :class:`~bayespilot.likelihood.Likelihood`).  Default 0 for ``"eq4"``
        (the paper's Eq. 4) and
        :func:`~bayespilot.likelihood.coloured_discard` (min(2 s, a quarter
        of the record), as :func:`~bayespilot.fit.fast.fit_fast` with
        ``noise="ar"``) for ``"coloured"``; for ``"eq4"`` on a record not known to be a whole number of forcing
        periods, :func:`~bayespilot.likelihood.startup_discard` (2 s), as
        :func:`~bayespilot.fit.fast.fit_fast` does.
    init : FitResult or mapping, optional
        Centre of the initial ball.  Default: :func:`~bayespilot.fit.fast.fit_fast`
        with ``seed``: a prediction-error fit (``noise="ar"``, or with the
        given ``noise``) for ``"coloured"`` with ``ar="fixed"`` or
        ``"profiled"``; the white Eq. 4 fit for ``"eq4"`` and for
        ``ar="sampled"``.
        For ``ar="fixed"`` the AR model is the one of a ``FitResult`` that has
        one (``settings["noise"]``), else estimated from the residual at
        ``init``; for ``ar="sampled"`` the partial autocorrelations start at
        their Yule-Walker estimate from that residual.
    n_walkers : int, optional
        Default 4 x the number of sampled parameters (at least 2 x).
    max_steps, min_steps, check_every : int
        Hard limit on the chain length; no stop before ``min_steps``; the
        autocorrelation time is estimated every ``check_every`` steps.
    tau_factor, tau_rtol : float
        Stop when the chain is longer than ``tau_factor`` x every integrated
        autocorrelation time and each changed by less than ``tau_rtol``
        (relative) since the previous check.
    seed : int, optional
        Seeds the initial fit, the initial ball and the sampler's moves: the
        same seed gives the same chain, bit for bit, on the same machine
        (whatever the number of numba or BLAS threads: each parameter
        vector's likelihood is computed by one thread; another CPU may round
        differently).  None draws one from fresh entropy; the seed used is
        recorded in the result (``seed``) and repeats the chain.
    progress : bool
        Show emcee's tqdm progress bar.
    backend : path, optional
        An emcee HDF5 file.  If it exists and holds a chain of this same run
        (recording, model, likelihood, prior, walkers), sampling resumes from
        its last state (``max_steps`` counts the steps already stored);
        another run's file raises ValueError.
    prior : mapping or callable, optional
        Name -> frozen ``scipy.stats`` distribution for some parameters (the
        others keep the default), truncated to the model bounds (Table 1;
        (-1, 1) for ``pacf_j``); or a callable giving the log-prior density
        (up to a constant) of one sampled vector, on the bounds.  Default:
        uniform on the bounds, uniform(-0.99, 0.99) on each ``pacf_j``.

    Returns
    -------
    Posterior
        Its ``settings`` hold every setting and ``recording_sha256``, the
        digest of the recording's content, by which
        :func:`bayespilot.compare.compare` tells whether it was sampled on
        the recording being compared.

    Raises
    ------
    ValueError
        Bad settings (among them ``ar_order=0`` with ``ar="profiled"``: a
        profiled AR model has an order of at least 1), a prior for an
        unknown parameter or with no probability inside that parameter's
        bounds, a backend file of another run, or a mapping ``init`` with a
        parameter the model does not have or one outside its bounds (a
        FitResult's estimates are moved onto the bounds instead: the paper's
        unbounded Gauss-Newton step can leave one just outside).
    TypeError
        ``recording``/``model``/``init``/``prior`` of the wrong type.

    Warns
    -----
    ConvergenceWarning
        The run reached ``max_steps`` before the criterion held; the message
        names the recording (its ``source``, when it has one) and says how to
        run longer (with a ``backend``: again with a larger
        ``max_steps``, which resumes the chain; without: a larger
        ``max_steps``, or a backend to be able to resume).

    Examples
    --------
    >>> from bayespilot.simulate import simulate
    >>> sim = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=1, duration=20)
    >>> post = sample(sim.recording, init=sim.params, n_walkers=16, max_steps=600,
    ...               min_steps=100, check_every=200, seed=0, progress=False)  # doctest: +SKIP
    >>> post.summary()["K_v"]["hdi_90"]  # doctest: +SKIP
    """
    t0 = time.perf_counter()
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    model, order = likelihood_options(model, likelihood, ar, ar_order)
    profiled_ar = likelihood == "coloured" and ar == "profiled"
    fixed_ar = likelihood == "coloured" and ar == "fixed"
    if noise is not None and profiled_ar:
        raise ValueError("noise is an ARNoise for ar='fixed' only; ar='profiled' (the "
                         "default) estimates the AR model at every parameter vector: pass "
                         "ar='fixed' to sample with this one")
    if noise is not None and not (fixed_ar and isinstance(noise, ARNoise)):
        raise ValueError("noise is an ARNoise for likelihood='coloured' with ar='fixed' only, "
                         f"got {type(noise).__name__} with likelihood={likelihood!r}, ar={ar!r}")
    discard = _checked_discard(recording, _default_discard(recording, likelihood)
                               if discard is None else discard)
    max_steps = _check_int("max_steps", max_steps, 1)
    min_steps = _check_int("min_steps", min_steps, 0)
    check_every = _check_int("check_every", check_every, 1)
    if min_steps > max_steps:
        raise ValueError(f"min_steps ({min_steps}) must not exceed max_steps ({max_steps})")
    tau_factor = _check_pos("tau_factor", tau_factor)
    tau_rtol = _check_pos("tau_rtol", tau_rtol)
    seed = resolve_seed(seed)  # None: a fresh one, recorded (the starting fit's too)
    if init is not None and not isinstance(init, (FitResult, Mapping)):
        raise TypeError(f"init must be a FitResult or a mapping of parameters, got {type(init).__name__}")
    if isinstance(init, Mapping):
        _check_init(model, init)

    names = model.parameter_names + pacf_names(order)
    ndim = len(names)
    n_walkers = 4 * ndim if n_walkers is None else _check_int("n_walkers", n_walkers, 2 * ndim)
    m_lo, m_hi = model.bounds
    box_lo = np.concatenate([m_lo, np.full(order, -1.0)])
    box_hi = np.concatenate([m_hi, np.full(order, 1.0)])
    def_lo = np.concatenate([m_lo, np.full(order, -PACF_BOUND)])
    def_hi = np.concatenate([m_hi, np.full(order, PACF_BOUND)])
    pri = _Prior(names, box_lo, box_hi, def_lo, def_hi, prior)
    if pri.callable is not None:
        # open at the stationarity limit |r| = 1
        pri.lo[len(m_lo):] = np.nextafter(-1.0, 0.0)
        pri.hi[len(m_lo):] = np.nextafter(1.0, 0.0)

    ss = np.random.SeedSequence(seed)
    ball_ss, mcmc_ss = ss.spawn(2)
    init_how = "given" if init is not None else None
    profiled = 0  # the order of a profiled AR model (0: none)
    if (fixed_ar or profiled_ar) and noise is None:
        stored = _stored_fingerprint(backend) if backend is not None else None
        if stored is not None and stored.get("noise"):
            noise = ARNoise.from_dict(stored["noise"])  # resuming: the chain's own noise model
        elif profiled_ar and stored is not None and stored.get("profiled_ar_order"):
            profiled = int(stored["profiled_ar_order"])  # resuming: the chain's own order
        else:
            if init is None:
                from .fit.fast import fit_fast

                init = fit_fast(recording, model, seed=seed, noise="ar", noise_order=ar_order,
                                discard=discard)
                init_how = "fit_fast"
            noise = _noise_at(init, model, recording, discard, ar_order)
            if profiled_ar:
                # the initial AR model gives the order (BIC unless given) and nothing else
                profiled, noise = max(1, noise.order), None
    lik = Likelihood(model, recording, discard=discard, noise=noise)
    if profiled and lik.n - lik.skip <= 4 * profiled:
        raise ValueError(f"an AR({profiled}) noise model needs more than {4 * profiled} samples "
                         f"after the discarded lead-in, this record has {lik.n - lik.skip}")
    logpost = _LogPosterior(lik, order, pri, profiled)

    settings: dict[str, Any] = {
        "true_parameters": _true_parameters(recording, names),
        "likelihood": likelihood, "ar": ar if likelihood == "coloured" else None,
        "ar_order": noise.order if noise is not None else (profiled or order),
        "discard_seconds": discard,
        "noise": None if noise is None else noise.to_dict(), "n_walkers": n_walkers,
        "max_steps": max_steps, "min_steps": min_steps, "check_every": check_every,
        "tau_factor": tau_factor, "tau_rtol": tau_rtol, "prior": pri.description,
        "backend": None if backend is None else str(backend), "model": model.name,
        "fixed": {k: float(v) for k, v in model.fixed.items()},
        "recording": recording.source or "", "recording_sha256": _recording_digest(recording),
        "entropy": str(ss.entropy),
        "numba_threads": int(numba.get_num_threads())}

    bk, resuming, fp = None, False, None
    if backend is not None:
        fp = _fingerprint(recording, model, names, likelihood, order, pri, n_walkers, lik, profiled)
        bk, resuming = _open_backend(backend, fp, n_walkers, ndim)

    p0 = None
    if resuming:
        settings["init"] = "resumed"
    else:
        if init is None:
            from .fit.fast import fit_fast

            init = fit_fast(recording, model, seed=seed, discard=discard, noise=noise)
            init_how = "fit_fast"
        settings["init"] = init_how
        params = dict(init.params) if isinstance(init, FitResult) else dict(init)
        given_r = {k: params.pop(k) for k in list(params) if k.startswith("pacf_")}
        centre_model = model.free_vector(params)
        centre_model = np.clip(centre_model, m_lo, m_hi)
        if order and set(pacf_names(order)) <= set(given_r):
            r0 = np.array([float(given_r[k]) for k in pacf_names(order)])
        elif order:
            eps = lik.residual(model.as_dict(centre_model))[lik.used]
            r0 = pacf_from_residual(eps, order) if np.all(np.isfinite(eps)) else np.zeros(order)
        else:
            r0 = np.zeros(0)
        centre = pri.center(np.concatenate([centre_model, r0]))
        settings["init_point"] = {n: float(v) for n, v in zip(names, centre)}
        p0 = _initial_ensemble(centre, pri, logpost, n_walkers,
                               np.random.default_rng(ball_ss))

    rs = np.random.RandomState(np.random.MT19937(mcmc_ss)).get_state()
    if bk is not None and not resuming:
        bk.reset(n_walkers, ndim)  # a new (or emptied) chain, tagged with this run
        _write_backend_attr(bk, _FINGERPRINT_ATTR, json.dumps(fp))
    run = _run_emcee(logpost, p0, n_walkers=n_walkers, ndim=ndim, max_steps=max_steps,
                     min_steps=min_steps, check_every=check_every, tau_factor=tau_factor,
                     tau_rtol=tau_rtol, random_state=rs, progress=progress, backend=bk)
    if not run.converged:
        where = f"{recording.source}: " if recording.source else ""
        warn_at_caller(ConvergenceWarning(
            f"{where}the chain reached max_steps = {max_steps} before it was {tau_factor:g} "
            f"autocorrelation times long with a settled tau (max tau = "
            f"{np.nanmax(run.tau) if np.any(np.isfinite(run.tau)) else float('nan'):.0f} steps); "
            f"the posterior is a rough estimate: {_run_longer(backend, max_steps)}",
            run.tau, run.n_steps))
    acc = np.asarray(run.sampler.acceptance_fraction, float)
    settings.update({"n_steps": run.n_steps, "resumed_from": run.start_iteration,
                     "tau_history": run.history, "acceptance_fraction": float(np.mean(acc)),
                     "log_prob_calls": logpost.n_calls, "likelihood_evaluations": logpost.n_rows,
                     "elapsed_seconds": time.perf_counter() - t0})
    tau = {n: float(t) for n, t in zip(names, run.tau)}
    meta = {"parameter_names": list(names), "tau": tau, "converged": bool(run.converged),
            "settings": settings, "seed": seed}
    # the AR model's partial autocorrelations are dimensionless
    units = {n: (model.parameter(n).unit if n in model.parameter_names else "-") for n in names}
    idata, meta = _to_idata(run.sampler, names, run.tau, meta, units)
    return Posterior(idata, tuple(names), tau, bool(run.converged), meta["settings"], seed)


def _run_longer(backend, max_steps: int) -> str:
    """The advice of the not-converged warning: how to run longer, in the API's words with
    the command's beside them (the CLI prints the warning as it is)."""
    if backend is None:
        return ("to run longer, raise max_steps (bayespilot sample --max-steps), or give a "
                "backend (bayespilot sample --backend FILE.h5) to be able to resume")
    return (f"to run longer, run again with the same backend ({backend}) and a max_steps "
            f"(bayespilot sample --max-steps) above {max_steps}: the chain resumes from its "
            "last step (max_steps counts the steps already stored)")


def _check_init(model: PilotModel, init: Mapping[str, float]) -> None:
    """Refuse a starting point with a model parameter outside its bounds (the prior's
    support): moved to the bound without a word, the chain would start somewhere the user
    did not ask for.  Unknown names and non-finite values are refused by the model."""
    given = {k: v for k, v in init.items() if not str(k).startswith("pacf_")}
    x = model.free_vector(given)
    for name, v, lo, hi in zip(model.parameter_names, x, *model.bounds):
        if name in given and not lo <= v <= hi:
            raise ValueError(f"init: {name} = {v:g} is outside its bounds [{lo:g}, {hi:g}] "
                             "(the prior's support)")


def _noise_at(init, model: PilotModel, recording: Recording, discard: float,
              order: int | None) -> ARNoise:
    """The AR noise model of ``init``: its own if it is a fit that has one, else estimated
    from the residual at its parameters (order by BIC unless given)."""
    if isinstance(init, FitResult) and isinstance(init.settings.get("noise"), Mapping) \
            and (order is None or init.settings["noise"].get("order") == order):
        return ARNoise.from_dict(init.settings["noise"])
    params = dict(init.params) if isinstance(init, FitResult) else dict(init)
    params = {k: v for k, v in params.items() if not k.startswith("pacf_")}
    lik = Likelihood(model, recording, discard=discard)
    centre = np.clip(model.free_vector(params), *model.bounds)
    eps = lik.residual(model.as_dict(centre))[lik.used]
    if not np.all(np.isfinite(eps)):
        raise ValueError("the model is unstable at init; give a starting point where it is not")
    return ARNoise.from_residual(eps, order=order)


class _CallableModule(types.ModuleType):
    """This module, callable: ``bayespilot.sample(...)`` is :func:`sample`."""

    def __call__(self, *args, **kwargs):
        return sample(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule

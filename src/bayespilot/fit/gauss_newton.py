"""Step II: unconstrained Gauss-Newton refinement with exact Jacobians.

The residual is eps = u - u_hat(theta); minimising sum(eps^2) minimises the
profiled Eq. 4 (N/2 ln(mean eps^2) + N/2 is increasing in the sum).  The
optimiser is ``scipy.optimize.least_squares(method="lm")`` (Levenberg-
Marquardt: Gauss-Newton with a trust region), unconstrained as in the paper;
the Jacobian comes from the forward sensitivity equations of the discrete
model (:meth:`bayespilot.likelihood.Likelihood.jacobian`), not finite
differences.  With a noise model in the likelihood the residual is the
whitened one (:meth:`~bayespilot.likelihood.Likelihood.fit_residual`), which
makes this a prediction-error fit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np
from scipy import optimize

from ..likelihood import Likelihood
from .._blas import one_blas_thread

__all__ = ["RefineResult", "joint_refine", "refine"]


@dataclass(frozen=True)
class RefineResult:
    """One Gauss-Newton refinement.

    Attributes
    ----------
    params : dict
        All free parameters of the model after refinement (held ones unchanged).
    neg_log_lik, start_neg_log_lik : float
        -ln L after and before.
    refined : tuple of str
        The parameters that were optimised.
    nfev, njev : int
        Residual and Jacobian evaluations the optimiser made.
    success : bool
        The optimiser's convergence flag (:func:`scipy.optimize.least_squares`).
    message : str
        The optimiser's reason for stopping.
    extra : dict, default {}
        Further details a caller may attach; :func:`refine` leaves it empty
        and :meth:`to_dict` does not write it.
    """

    params: dict[str, float]
    neg_log_lik: float
    start_neg_log_lik: float
    refined: tuple[str, ...]
    nfev: int
    njev: int
    success: bool
    message: str
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of every attribute except ``extra`` (``refined`` as a list)."""
        return {"params": dict(self.params), "neg_log_lik": self.neg_log_lik,
                "start_neg_log_lik": self.start_neg_log_lik, "refined": list(self.refined),
                "nfev": self.nfev, "njev": self.njev, "success": self.success,
                "message": self.message}


@one_blas_thread
def refine(likelihood: Likelihood, start: Mapping[str, float], *, hold: Sequence[str] = ("delta_abs",),
           max_nfev: int = 200, xtol: float = 1e-10, ftol: float = 1e-10,
           bounded: bool = False) -> RefineResult:
    """Refine all free parameters except ``hold`` by unconstrained Gauss-Newton (LM).

    Parameters
    ----------
    likelihood : Likelihood
    start : mapping
        Starting values of the free parameters, by name.
    hold : sequence of str
        Free parameters kept at their start value (the paper holds delta_abs,
        whose derivative is unreliable).  Names the model does not estimate
        are ignored.
    max_nfev : int
        Cap on residual evaluations.
    xtol, ftol : float
        Tolerances on the step and on the relative change of the cost
        (:func:`scipy.optimize.least_squares`).
    bounded : bool
        False (the paper's Step II): unconstrained Levenberg-Marquardt.  True:
        trust-region reflective within the parameter bounds (used by the fast
        estimator, whose starts are spread over the whole box).

    Returns
    -------
    RefineResult
        The refined parameters, -ln L before and after, and the optimiser's report.

    Raises
    ------
    ValueError
        If every free parameter is held.
    """
    model = likelihood.model
    start_full = dict(model.as_dict(model.free_vector(start)))
    names = tuple(n for n in model.parameter_names if n not in set(hold))
    if not names:
        raise ValueError("nothing to refine: every free parameter is held")
    # The residual Eq. 4 sums (the samples kept, whitened when the likelihood has a noise model).
    m = likelihood.n_terms
    big = 1e3 * (float(np.std(likelihood.u)) + 1e-300)

    def params_of(x):
        p = dict(start_full)
        p.update(zip(names, (float(v) for v in x)))
        return p

    def residual(x):
        r = likelihood.fit_residual(params_of(x))
        if not np.all(np.isfinite(r)):
            return np.full(m, big)
        return r

    def jac(x):
        J = likelihood.fit_jacobian(params_of(x), names)
        if not np.all(np.isfinite(J)):
            return np.zeros((m, len(names)))
        return J

    x0 = np.array([start_full[n] for n in names])
    f0 = likelihood.neg_log_lik(start_full)
    if bounded:
        lo = np.array([model.parameter(n).lower for n in names])
        hi = np.array([model.parameter(n).upper for n in names])
        x0 = np.clip(x0, lo, hi)
        sol = optimize.least_squares(residual, x0, jac=jac, method="trf", bounds=(lo, hi),
                                     max_nfev=max_nfev, xtol=xtol, ftol=ftol)
    else:
        sol = optimize.least_squares(residual, x0, jac=jac, method="lm", max_nfev=max_nfev,
                                     xtol=xtol, ftol=ftol)
    p = params_of(sol.x)
    f = likelihood.neg_log_lik(p)
    if not np.isfinite(f) or f > f0:  # never return something worse than the start
        p, f = start_full, f0
    return RefineResult(p, float(f), float(f0), names, int(sol.nfev), int(sol.njev or 0),
                        bool(sol.success), str(sol.message))


def joint_refine(likelihood: Likelihood, params: Mapping[str, float], neg_log_lik: float
                 ) -> dict[str, Any] | None:
    """Gauss-Newton (bounded, delta_abs free) from a fit that placed delta_abs by a grid: where
    it ends and how far below ``neg_log_lik`` (``gap``), or None if it fails.

    Parameters
    ----------
    likelihood : Likelihood
        The fit's likelihood.
    params : mapping of str to float
        The fit's estimate (every free parameter).
    neg_log_lik : float
        Its -ln L.

    Returns
    -------
    dict or None
        ``{"neg_log_lik", "params", "gap"}``, ``gap`` = max(0, ``neg_log_lik`` - the end's);
        None if the refinement raised or ended at a non-finite -ln L.

    Raises
    ------
    TypeError
        ``likelihood`` is not a Likelihood.
    ValueError
        ``params`` lacks a free parameter of the likelihood's model (refine would start it
        at its default without a word).

    Notes
    -----
    The fitters hold delta_abs in Gauss-Newton and place it by a scan with the other
    parameters fixed (the paper's Step III), which stops short where the ridge of the
    likelihood in delta_abs is narrower than the grid or leans on K_m.  ``fit_paper`` reports
    the gap (its estimate is the paper's); ``fit_fast`` takes the end point when the gap
    exceeds :data:`~bayespilot.fit.result.CHECK_GAP`.  About 0.05 s.
    """
    if not isinstance(likelihood, Likelihood):
        raise TypeError(f"likelihood must be a Likelihood, got {type(likelihood).__name__}")
    missing = [n for n in likelihood.model.parameter_names if n not in params]
    if missing:
        raise ValueError(f"params lacks {', '.join(missing)}: give the fit's estimate of every "
                         "free parameter")
    try:
        r = refine(likelihood, params, hold=(), bounded=True)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError):
        return None
    if not np.isfinite(r.neg_log_lik):
        return None
    return {"neg_log_lik": float(r.neg_log_lik), "params": dict(r.params),
            "gap": float(max(0.0, neg_log_lik - r.neg_log_lik))}

"""A fast estimator beside the paper's: multi-start least squares and a profile over delta_abs.

All refinements are bounded least squares (trust-region reflective, exact
Jacobians) within the Table 1 bounds: started anywhere in the box, an
unconstrained step can reach negative delays, which the periodic likelihood
reads as looking ahead.

1. Multi-start: Gauss-Newton on the model without
   threshold from ``n_starts`` Latin-hypercube points in the Table 1 bounds
   (scipy.stats.qmc), keeping the best.
2. Profile: delta_abs stepped over [0, upper] on a coarse grid; at each value
   the other parameters are refined, warm-started from the previous grid
   point (continuation) and from the threshold-free optimum.
3. The best profile point is refined, then delta_abs is scanned at the Step III
   resolution and the other parameters refined once more.

Because the profile contains delta_abs = 0 (the model without threshold) and
the final answer is the best point seen, a fit with threshold is never worse
than the fit without one.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.stats import qmc

from ..likelihood import Likelihood
from ..model import PilotModel
from ..recording import Recording
from .gauss_newton import refine
from .result import FitResult
from .scan import scan_parameter
from .three_step import _model_for

__all__ = ["fit_fast"]


def fit_fast(recording: Recording, model: PilotModel | None = None, *, threshold: bool = True,
             seed: int | None = None, n_starts: int = 8, profile_step: float = 0.0025,
             scan_step: float = 1e-4, initial: str = "periodic",
             discard: float = 0.0) -> FitResult:
    """Fit by multi-start Gauss-Newton and a profile over delta_abs (see module docs).

    Parameters
    ----------
    recording : Recording
    model : PilotModel, optional
    threshold : bool
    seed : int, optional
        Seeds the Latin-hypercube starts.
    n_starts : int
        Starting points of the threshold-free fit.
    profile_step : float
        Coarse grid step of the delta_abs profile, IPUT.
    scan_step : float
        Final scan resolution, IPUT.
    initial : {"periodic", "rest"}

    Returns
    -------
    FitResult

    Examples
    --------
    >>> from bayespilot.simulate import simulate
    >>> rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.1, seed=1, duration=20).recording
    >>> fit = fit_fast(rec, seed=0, n_starts=2, profile_step=0.02)
    >>> fit.method
    'fast'
    """
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    if not isinstance(n_starts, (int, np.integer)) or n_starts < 1:
        raise ValueError(f"n_starts must be a positive integer, got {n_starts!r}")
    if not (profile_step > 0 and scan_step > 0):
        raise ValueError("profile_step and scan_step must be positive")
    t0 = time.perf_counter()
    model = _model_for(model, threshold)
    has_delta = "delta_abs" in model.parameter_names
    base = model.fix(delta_abs=0.0) if has_delta else model
    lik0 = Likelihood(base, recording, initial=initial, discard=discard)
    lo, hi = base.bounds
    starts = qmc.scale(qmc.LatinHypercube(d=lo.size, seed=seed).random(n_starts), lo, hi)
    runs = [refine(lik0, base.as_dict(x), hold=(), bounded=True) for x in starts]
    best0 = min(runs, key=lambda r: r.neg_log_lik)
    stages = {"starts": [r.to_dict() for r in runs]}
    if not has_delta:
        p, f = best0.params, best0.neg_log_lik
        full = model.as_dict(model.full_vector(p), full=True)
        return FitResult(full, f, lik0.vaf(p), "fast", seed, False,
                         {"n_starts": n_starts, "initial": initial, "discard": discard,
                          "model": model.name},
                         stages, time.perf_counter() - t0, recording.source)

    lik = Likelihood(model, recording, initial=initial, discard=discard)
    upper = model.parameter("delta_abs").upper
    grid = np.arange(0.0, upper + 0.5 * profile_step, profile_step)
    prof = []
    prev = dict(best0.params, delta_abs=0.0)
    for d in grid:
        cands = [refine(lik, dict(prev, delta_abs=float(d)), bounded=True),
                 refine(lik, dict(best0.params, delta_abs=float(d)), bounded=True)]
        r = min(cands, key=lambda c: c.neg_log_lik)
        prof.append(r)
        prev = dict(r.params)
    k = int(np.argmin([r.neg_log_lik for r in prof]))
    params, fun = dict(prof[k].params), prof[k].neg_log_lik
    lo_d = max(0.0, grid[k] - profile_step)
    hi_d = min(upper, grid[k] + profile_step)
    sc = scan_parameter(lik, params, "delta_abs", lower=lo_d, upper=hi_d, step=scan_step)
    if sc.best_neg_log_lik < fun:
        params["delta_abs"], fun = sc.best, sc.best_neg_log_lik
    r = refine(lik, params, bounded=True)
    if r.neg_log_lik < fun:
        params, fun = dict(r.params), r.neg_log_lik
    stages.update({"profile_grid": grid.tolist(),
                   "profile_neg_log_lik": [p.neg_log_lik for p in prof],
                   "scan": sc.to_dict()})
    full = model.as_dict(model.full_vector(params), full=True)
    settings = {"n_starts": n_starts, "profile_step": profile_step, "scan_step": scan_step,
                "initial": initial, "discard": discard, "model": model.name}
    return FitResult(full, float(fun), lik.vaf(params), "fast", seed, True, settings, stages,
                     time.perf_counter() - t0, recording.source)

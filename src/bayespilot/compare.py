"""Bayesian model comparison: the pilot model with and without the threshold.

:func:`compare` weighs the paper's model (``delta_abs`` free on [0, 0.1]
IPUT, Table 1) against the same model with ``delta_abs = 0`` on one
recording, three ways:

1. **Log Bayes factor from nested sampling** (dynesty).  The evidence
   Z = integral of L(theta) p(theta) is computed for each model with priors
   uniform on the model bounds (Table 1), the same as the defaults of
   :func:`bayespilot.sample.sample`, and

       ln BF = ln Z(threshold) - ln Z(none),

   with the uncertainty sqrt(err_1^2 + err_2^2) from dynesty's ``logzerr``
   of each run.  Under Eq. 4 the output-error variance s^2 is marginalised
   with the Jeffreys prior p(s) ~ 1/s, which gives
   -ln L = N/2 ln(sum eps^2) + const: the profiled form of Eq. 4 up to a
   constant that is the same for both models (same N), so it cancels in the
   Bayes factor (the improper prior is shared by both models, which is what
   makes the ratio well defined).  ``likelihood="coloured"`` uses the AR
   output-error model of :mod:`bayespilot.sample`: by default (``ar="fixed"``)
   one AR model, estimated from a prediction-error fit of the model with
   threshold (:func:`~bayespilot.fit.fast.fit_fast`, ``noise="ar"``), whitens
   the residual of both models, so that both are judged by the same noise
   model; with ``ar="sampled"`` the partial autocorrelations are uniform on
   (-0.99, 0.99) in both models.

2. **Savage-Dickey ratio** from an emcee posterior of the model with
   threshold: for nested models whose other priors do not depend on
   ``delta_abs``, BF(none : threshold) = p(delta_abs = 0 | data) / p(delta_abs = 0).
   0 is the lower bound of the prior, so the posterior density at 0 is a
   density at a boundary; it is estimated with arviz's boundary-corrected
   (reflection) kernel density estimate.  It is a valid cross-check only
   where the prior of ``delta_abs`` starts at 0 and the posterior has
   enough draws near 0 to estimate a density there; otherwise the result
   says so and gives, where it can, a lower bound on ln BF.

   Nested sampling can fail on this likelihood: for delta_abs above most
   of |i| the dead zone switches the motion channel off, a broad plateau
   that holds much prior volume, and a run may find the main mode late or
   not at all, which lowers ln Z.  So the model with threshold is run
   ``runs`` times (default 2, each with its own seed); runs whose best ln L
   is below the best ln L without threshold (impossible for the nested
   model) are replaced, runs whose ln Z is far below the others are
   dropped, and the rest are averaged (:func:`robust_evidence`).

3. **Information criteria** from the maximum-likelihood fits:
   AIC = 2k + 2(-ln L), BIC = k ln n + 2(-ln L), with k counting the output
   error variance (and the AR coefficients where they are estimated; a fixed
   noise model's are not counted) and -ln L as Eq. 4 writes it (no 2 pi
   constant): only the differences between the models are meaningful, and
   neither choice changes them.  ``delta_aic`` and
   ``delta_bic`` are (none - threshold): positive favours the threshold.

Decisions (:func:`decide`) use Jeffreys' scale on ln BF (Jeffreys 1961,
Appendix B; in natural logs): |ln BF| < ln 10^(1/2) = 1.15 "barely worth
mentioning", < ln 10 = 2.30 "substantial", < ln 10^(3/2) = 3.45 "strong",
< ln 100 = 4.61 "very strong", beyond "decisive".  A decision for a model
needs at least "strong" evidence (|ln BF| > ln 10) that holds with the
estimate's uncertainty: ln BF - 2 err > ln 10 gives ``"threshold"``,
ln BF + 2 err < -ln 10 gives ``"none"``, anything else ``"inconclusive"``.
Two guards follow (:func:`_guarded_decision`), both found on the Fig. 11
study (docs/comparison.md):

- The plateau.  With uniform priors the plateau above max|i| holds a large
  share of the prior volume of the model with threshold (K_m and tau_m are
  free there and change nothing).  Where the motion channel adds little to
  the fit (small K_theta) that volume alone gives ln BF of +2 to +4 with no
  threshold in the data: the Bayes factor then weighs "motion channel off"
  against "motion channel on, linear", not a threshold.  So a "threshold"
  decision needs the posterior probability of the plateau to be at most
  :data:`PLATEAU_LEVEL`; otherwise it is "inconclusive".  The plateau
  starts where the dead zone passes fewer than :data:`PLATEAU_ACTIVE_FRACTION`
  of the samples (:func:`plateau_onset`), not at max|i|: a threshold that
  lets through a handful of peaks of |i| (with a large K_m) fits a few
  remnant events, not a perception threshold, and gave a false "threshold"
  on Fig. 11 data simulated without one
  (:attr:`Comparison.plateau_probability` is P(delta_abs >= onset)).  The
  dead zone's input is taken at the maximum-likelihood point with threshold
  (stages with free parameters before it, a washout or a platform, at their
  estimates; a SoftDeadZone as a dead zone of its ``delta_abs``); where it
  cannot be computed the guard is not applied, and the result says so.
- A lost mode.  If every run with threshold missed the main mode, ln Z with
  threshold and so ln BF are only lower bounds: they can support
  "threshold" but not "none".

:func:`pool` combines recordings of one condition: the sum of the log Bayes
factors (all recordings with a threshold against all without, each with its
own parameters; errors in quadrature), decided on the same scale, and a
paired test across recordings (a one-sample t-test of the per-recording
ln BF, i.e. a paired t-test of ln Z with against without threshold, and a
Wilcoxon signed-rank test).
"""

from __future__ import annotations

import copy
import math
import os
import re
import sys
import time
import types
import warnings
from dataclasses import MISSING, asdict, dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

import numpy as np

from ._files import (WrongKind, dataclass_fields, dumps, nan_for_null, number, numbers,
                     read_result, require_keys, write_text_atomic)
from ._html import SummaryHTML
from ._interrupt import interrupt_between_steps
from ._seeds import resolve_seed
from .likelihood import Likelihood
from .model import PilotModel, paper_model
from .noise import ARNoise
from .sample import _default_discard, likelihood_options
from .recording import Recording, _recording_digest
from ._blas import one_blas_thread
from ._caller import warn_at_caller

if TYPE_CHECKING:  # pragma: no cover
    from .sample import Posterior

#: The AR treatments the evidence supports (a profiled AR model is :func:`sample`'s only:
#: a profile likelihood is not a density to integrate for ln Z).
EVIDENCE_AR_MODES = ("fixed", "sampled")

__all__ = ["Evidence", "SavageDickey", "Comparison", "PooledComparison", "nested_evidence",
           "evidence", "savage_dickey", "savage_dickey_from_posterior", "information_criteria",
           "decide", "jeffreys_category", "compare", "pool", "JEFFREYS", "DECISION_LEVEL",
           "DECISION_Z", "THRESHOLD", "threshold_input_max", "plateau_onset", "PLATEAU_LEVEL",
           "PLATEAU_ACTIVE_FRACTION", "robust_evidence", "log_likelihood_at"]

#: The nested parameter: the model without threshold has it fixed at 0 (a DeadZone's; a
#: threshold not the identity at 0, a SoftDeadZone, is removed: :func:`compare`).
THRESHOLD = "delta_abs"
#: Jeffreys' scale (1961, Appendix B) in natural logs: (upper end of |ln BF|, category).
JEFFREYS = ((0.5 * math.log(10.0), "barely worth mentioning"),
            (math.log(10.0), "substantial"),
            (1.5 * math.log(10.0), "strong"),
            (2.0 * math.log(10.0), "very strong"),
            (math.inf, "decisive"))
#: |ln BF| a decision needs: Jeffreys' "strong" (BF > 10).
DECISION_LEVEL = math.log(10.0)
#: Standard errors of ln BF by which it must clear DECISION_LEVEL.
DECISION_Z = 2.0
DECISIONS = ("threshold", "none", "inconclusive")
#: The threshold model's best ln L may fall this far below the no-threshold model's before
#: :func:`compare` concludes that its nested-sampling run lost the main mode and reruns it.
MODE_TOLERANCE = 2.0
#: Extra runs (each with a new seed) :func:`compare` makes to replace runs that lost the mode.
MAX_RERUNS = 2
#: Posterior probability (model with threshold) of ``delta_abs`` above the plateau onset
#: (:func:`plateau_onset`) beyond which the evidence for the threshold is evidence for a
#: switched-off or nearly silent motion channel (see :func:`compare`).
PLATEAU_LEVEL = 0.5
#: The plateau starts at the level of |i| that the dead zone's input exceeds in only this
#: fraction of the samples (1 %: under 0.82 s of an 81.92 s run), see :func:`plateau_onset`.
PLATEAU_ACTIVE_FRACTION = 0.01


def _check_int(name: str, v, lo: int) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
        raise ValueError(f"{name} must be an integer >= {lo}, got {v!r}")
    return int(v)


def _check_pos(name: str, v) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.floating)) or not (
            math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a positive number, got {v!r}")
    return float(v)


# --- decisions -----------------------------------------------------------------------------
def jeffreys_category(log_bf: float) -> str:
    """Jeffreys' name for the strength of evidence |ln BF| (see :data:`JEFFREYS`).

    Parameters
    ----------
    log_bf : float
        A log Bayes factor (natural log), of either sign: only |ln BF| counts.

    Returns
    -------
    str
        "barely worth mentioning" (|ln BF| < ln 10^(1/2) = 1.15),
        "substantial" (< ln 10 = 2.30), "strong" (< ln 10^(3/2) = 3.45),
        "very strong" (< ln 100 = 4.61) or "decisive" (beyond, infinity
        included).

    Raises
    ------
    ValueError
        If ``log_bf`` is not an int or float (numpy floats included) or is NaN.

    Examples
    --------
    >>> jeffreys_category(3.0)
    'strong'
    >>> jeffreys_category(-0.5)
    'barely worth mentioning'
    """
    if isinstance(log_bf, bool) or not isinstance(log_bf, (int, float, np.integer, np.floating)) \
            or math.isnan(log_bf):
        raise ValueError(f"log_bf must be a number, got {log_bf!r}")
    a = abs(float(log_bf))
    for upper, name in JEFFREYS:
        if a < upper:
            return name
    return JEFFREYS[-1][1]


def decide(log_bf: float, err: float = 0.0, *, level: float = DECISION_LEVEL,
           z: float = DECISION_Z) -> str:
    """``"threshold"``, ``"none"`` or ``"inconclusive"`` from ln BF (threshold : none).

    ``"threshold"`` if ln BF - z err > level, ``"none"`` if ln BF + z err < -level,
    else ``"inconclusive"`` (defaults: Jeffreys' "strong", BF > 10, at 2 standard
    errors).

    Parameters
    ----------
    log_bf : float
        ln BF of the model with threshold against the model without
        (positive favours the threshold).
    err : float, default 0.0
        Standard error of ``log_bf``, >= 0 (0: take ``log_bf`` as exact).
    level : float, default :data:`DECISION_LEVEL`
        |ln BF| a decision needs, >= 0 (ln 10 = 2.30, Jeffreys' "strong").
    z : float, default :data:`DECISION_Z`
        Standard errors by which ``log_bf`` must clear ``level``, >= 0 (2).

    Returns
    -------
    str
        ``"threshold"``, ``"none"`` or ``"inconclusive"``.

    Raises
    ------
    ValueError
        If an argument is not an int or float (numpy floats included, bool
        excluded) or is NaN, or if ``err``, ``level`` or ``z`` is negative.

    Examples
    --------
    >>> decide(8.0, 1.0), decide(-3.0, 0.2), decide(3.0, 1.0)
    ('threshold', 'none', 'inconclusive')
    """
    for name, v in (("log_bf", log_bf), ("err", err), ("level", level), ("z", z)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                or math.isnan(v):
            raise ValueError(f"{name} must be a number, got {v!r}")
    if err < 0 or level < 0 or z < 0:
        raise ValueError("err, level and z must be >= 0")
    if log_bf - z * err > level:
        return "threshold"
    if log_bf + z * err < -level:
        return "none"
    return "inconclusive"


def _favours(log_bf: float) -> str:
    """The model ln BF points to: "threshold", "none", or "neither" while |ln BF| is "barely
    worth mentioning" (Jeffreys) or NaN."""
    if not abs(log_bf) >= JEFFREYS[0][0]:
        return "neither"
    return "threshold" if log_bf > 0 else "none"


def _decision_reason(log_bf: float, err: float, decision: str, note: str = "", *,
                     level: float = DECISION_LEVEL, z: float = DECISION_Z) -> str:
    """Why ``decision`` is not the model ln BF points to (:func:`_favours`), "" when it is.

    ``note`` is a guard's reason (``decision_note``), given precedence; without one, an
    "inconclusive" on an ln BF that points one way is explained by :func:`decide`'s rule:
    ln BF short of ``level``, or not clear of it by ``z`` standard errors.
    """
    if note:
        return note
    fav = _favours(log_bf)
    if decision != "inconclusive" or fav == "neither":
        return ""
    ln10 = math.isclose(level, DECISION_LEVEL)
    lev = f"ln 10 = {level:.2f}" if ln10 else f"{level:.2f}"
    if abs(log_bf) <= level:
        return f"|ln BF| is not above {lev}" + (": a decision needs Jeffreys' \"strong\" "
                                                 "evidence (BF > 10)" if ln10 else "")
    if fav == "threshold":
        return (f"not strong beyond its error: ln BF - {z:g} x {err:.2f} = "
                f"{log_bf - z * err:+.2f} is not above {lev}")
    return (f"not strong beyond its error: ln BF + {z:g} x {err:.2f} = {log_bf + z * err:+.2f} "
            f"is not below -{lev.replace(' = ', ' = -')}")


def _verdict(log_bf: float, err: float, decision: str, note: str = "", *,
             level: float = DECISION_LEVEL, z: float = DECISION_Z,
             identified: bool = True) -> str:
    """"(<Jeffreys category>, favours <model>) -> decision: <decision> (<why>)" of the
    summaries; the reason whenever the decision is not the model ln BF points to.  With a
    threshold the record does not identify (``identified=False``: the two models are the same
    on it, and ln BF is sampling noise) the label is "(not identified)", favouring neither."""
    why = _decision_reason(log_bf, err, decision, note, level=level, z=z)
    label = (f"{jeffreys_category(log_bf)}, favours {_favours(log_bf)}" if identified
             else "not identified")
    return f"({label})  -> decision: {decision}" + (f" ({why})" if why else "")


# --- nested sampling -------------------------------------------------------------------------
@dataclass(frozen=True)
class Evidence:
    """The evidence of one model from one dynesty run.

    Attributes
    ----------
    log_z, log_z_err : float
        ln Z and dynesty's estimate of its standard error.
    information : float
        The information H (nats) of the posterior relative to the prior.
    max_log_lik : float
        The largest ln L met.
    best : dict
        The parameters at ``max_log_lik``.
    mean : dict
        Posterior mean of each parameter (importance-weighted samples).
    parameter_names : tuple of str
        The sampled parameters, in vector order.
    n_calls, n_iter : int
        Likelihood evaluations and nested-sampling iterations.
    elapsed : float
        Wall time, s.
    settings : dict
        nlive, dlogz, sample, bound, seed, the bounds.
    samples, weights : ndarray or None
        The nested-sampling draws, shape (n, n_parameters), and their
        normalised importance weights, for posterior probabilities such as
        :attr:`Comparison.plateau_probability`.  Kept in memory only: not in
        :meth:`to_dict` (None after :meth:`from_dict`).
    """

    log_z: float
    log_z_err: float
    information: float
    max_log_lik: float
    best: dict[str, float]
    mean: dict[str, float]
    parameter_names: tuple[str, ...]
    n_calls: int
    n_iter: int
    elapsed: float
    settings: dict[str, Any] = field(default_factory=dict)
    samples: np.ndarray | None = field(default=None, repr=False, compare=False)
    weights: np.ndarray | None = field(default=None, repr=False, compare=False)

    def probability(self, name: str, lower: float) -> float | None:
        """Posterior probability that parameter ``name`` is >= ``lower`` (None without samples).

        Parameters
        ----------
        name : str
            A parameter of :attr:`parameter_names`.
        lower : float
            The level, in the parameter's unit.

        Returns
        -------
        float or None
            The importance-weighted fraction of the nested-sampling draws at
            or above ``lower``; None when the draws are not kept (after
            :meth:`from_dict`).

        Raises
        ------
        ValueError
            If ``name`` is not a parameter of the run (with draws kept).
        """
        if self.samples is None or self.weights is None:
            return None
        col = self.parameter_names.index(name)
        return float(np.sum(self.weights[self.samples[:, col] >= lower]))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of every attribute except ``samples`` and ``weights``."""
        d = {k: v for k, v in self.__dict__.items() if k not in ("samples", "weights")}
        d["best"], d["mean"] = dict(self.best), dict(self.mean)
        d["settings"] = copy.deepcopy(self.settings)
        d["parameter_names"] = list(self.parameter_names)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Evidence":
        """The evidence a :meth:`to_dict` holds (a null number is NaN; no draws).

        Parameters
        ----------
        d : mapping
            A :meth:`to_dict`, as read from JSON; ``samples`` and ``weights``
            are ignored if present.

        Returns
        -------
        Evidence
            With ``samples`` and ``weights`` None; ``best`` and ``mean`` with
            NaN for null.  A key an Evidence does not have (a field of a later
            release) is ignored.

        Raises
        ------
        bayespilot._files.WrongKind
            A ValueError: ``d`` lacks a field without a default (the message
            names it).
        """
        d = nan_for_null(cls, dataclass_fields(
            cls, {k: v for k, v in d.items() if k not in ("samples", "weights")},
            "a nested-sampling evidence"))
        d["parameter_names"] = tuple(d["parameter_names"])
        d["best"], d["mean"] = numbers(d["best"]), numbers(d["mean"])
        return cls(**d)


#: dynesty's sampling methods and bounding methods (checked before a run, with their names).
DYNESTY_SAMPLES = ("auto", "unif", "rwalk", "slice", "rslice")
DYNESTY_BOUNDS = ("none", "single", "multi", "balls", "cubes")


def nested_evidence(log_likelihood: Callable[[np.ndarray], float],
                    lower: Sequence[float] | np.ndarray, upper: Sequence[float] | np.ndarray,
                    *, names: Sequence[str] | None = None,
                    nlive: int = 200, dlogz: float = 0.5, sample: str = "rwalk",
                    bound: str = "multi", seed: int | None = None,
                    progress: bool = False) -> Evidence:
    """ln Z of ``log_likelihood`` under a prior uniform on the box [lower, upper] (dynesty).

    Parameters
    ----------
    log_likelihood : callable
        ln L of one parameter vector (a float; -inf where the model is not
        defined, e.g. unstable).
    lower, upper : sequence of float
        Finite bounds, lower < upper, one per parameter.
    names : sequence of str, optional
        Parameter names (default x0, x1, ...).
    nlive : int
        Live points (the error of ln Z falls as sqrt(H / nlive)).
    dlogz : float
        Stop when the remaining evidence is below this (dynesty's criterion).
    sample, bound : str
        dynesty's sampling method and bounding scheme.
    seed : int, optional
        Seeds dynesty's ``rstate`` (a numpy Generator): same seed, same run.
        None draws one from fresh entropy, recorded in ``settings["seed"]``.
    progress : bool
        dynesty's progress line.

    Returns
    -------
    Evidence

    Examples
    --------
    A unit Gaussian likelihood (integral 1) in the box [-10, 10]^2 has
    Z = 1/400:

    >>> ll = lambda x: -0.5 * float(x @ x) - math.log(2 * math.pi)
    >>> ev = nested_evidence(ll, [-10, -10], [10, 10], nlive=100, seed=1)
    >>> bool(abs(ev.log_z - math.log(1 / 400)) < 4 * ev.log_z_err)
    True
    """
    import dynesty

    lo = np.asarray(lower, dtype=float)
    hi = np.asarray(upper, dtype=float)
    if lo.ndim != 1 or lo.shape != hi.shape or lo.size == 0:
        raise ValueError("lower and upper must be 1-D sequences of the same length >= 1")
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo < hi)):
        raise ValueError("the prior box needs finite lower < upper in every dimension")
    names = tuple(f"x{i}" for i in range(lo.size)) if names is None else tuple(names)
    if len(names) != lo.size:
        raise ValueError(f"names has {len(names)} entries for {lo.size} parameters")
    if not callable(log_likelihood):
        raise TypeError("log_likelihood must be callable")
    nlive = _check_int("nlive", nlive, 2 * lo.size + 2)
    dlogz = _check_pos("dlogz", dlogz)
    for what, value, choices in (("sample", sample, DYNESTY_SAMPLES),
                                 ("bound", bound, DYNESTY_BOUNDS)):
        if value not in choices:
            raise ValueError(f"{what} must be one of {', '.join(map(repr, choices))} "
                             f"(dynesty's), got {value!r}")
    seed = resolve_seed(seed)  # None: a fresh one, recorded in the settings
    width = hi - lo
    n_calls = 0

    def prior_transform(u):
        return lo + u * width

    def loglike(x):
        nonlocal n_calls
        n_calls += 1
        v = float(log_likelihood(x))
        if math.isnan(v) or v == math.inf:
            return -math.inf
        return v

    t0 = time.perf_counter()
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    sampler = dynesty.NestedSampler(loglike, prior_transform, lo.size, nlive=nlive,
                                    sample=sample, bound=bound, rstate=rng)
    # A Ctrl-C at the end of an iteration, raised from print_func (called between them,
    # outside dynesty's wrapper of loglike, which printed the point and a traceback first);
    # so print_func is always called, and draws dynesty's own progress bar when asked to.
    from dynesty.utils import print_fn

    pbar = None
    if progress:
        from tqdm.auto import tqdm

        pbar = tqdm()
    with interrupt_between_steps() as check_interrupt:
        def print_func(results, niter, ncall, **kwargs):
            check_interrupt()
            if pbar is not None:
                print_fn(results, niter, ncall, pbar=pbar, **kwargs)

        try:
            sampler.run_nested(dlogz=dlogz, print_progress=True, print_func=print_func)
        finally:
            if pbar is not None:
                pbar.close()
        check_interrupt()
    res = sampler.results
    logz = float(res["logz"][-1])
    logz_err = float(res["logzerr"][-1])
    info = float(res["information"][-1])
    logl = np.asarray(res["logl"], float)
    samples = np.asarray(res["samples"], float)
    w = np.exp(np.asarray(res["logwt"], float) - logz)
    w = w / w.sum()
    ib = int(np.argmax(logl))
    settings = {"nlive": nlive, "dlogz": dlogz, "sample": sample, "bound": bound, "seed": seed,
                "lower": lo.tolist(), "upper": hi.tolist(), "dynesty": dynesty.__version__}
    return Evidence(logz, logz_err, info, float(logl[ib]),
                    {n: float(v) for n, v in zip(names, samples[ib])},
                    {n: float(v) for n, v in zip(names, w @ samples)}, names, int(n_calls),
                    int(res["niter"]), time.perf_counter() - t0, settings, samples, w)


def _check_noise(noise):
    if noise is not None and not isinstance(noise, ARNoise):
        raise TypeError(f"noise must be None or an ARNoise, got {type(noise).__name__}")
    return noise


def log_likelihood_at(model: PilotModel, recording: Recording, params: Mapping[str, float],
                      *, noise: ARNoise | None = None, discard: float = 0.0) -> float:
    """ln L of ``model`` at ``params`` under the likelihood :func:`evidence` integrates.

    Parameters
    ----------
    model : PilotModel
    recording : Recording
    params : mapping
        Values of the model's free parameters (others are ignored); clipped
        to the model's bounds.
    noise : ARNoise, optional
        The fixed AR model of ``likelihood="coloured", ar="fixed"``; None: Eq. 4.
    discard : float, default 0
        Seconds at the start left out.  The default is 0, not :func:`evidence`'s
        (:func:`~bayespilot.likelihood.coloured_discard`, min(2 s, a quarter
        of the record), for ``"coloured"``;
        :func:`~bayespilot.likelihood.startup_discard` for ``"eq4"`` on a record
        not known to be a whole number of forcing periods): to evaluate the
        likelihood an :func:`evidence` or :func:`compare` integrated, pass the
        ``discard`` it used (``settings["discard_seconds"]``).

    Returns
    -------
    float
        ln L, or ``-inf`` where the closed loop is unstable.

    Raises
    ------
    TypeError
        ``model``, ``recording`` or ``noise`` of the wrong type.
    """
    if not isinstance(model, PilotModel):
        raise TypeError(f"model must be a PilotModel, got {type(model).__name__}")
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    if noise is not None and not isinstance(noise, ARNoise):
        raise TypeError(f"noise must be an ARNoise or None, got {type(noise).__name__}")
    nll = _NegLogLik(model, recording, 0, noise, discard)
    x = np.clip(model.free_vector({k: v for k, v in params.items()
                                   if k in model.parameter_names}), *model.bounds)
    v = nll(x)
    return -v if math.isfinite(v) else -math.inf


class _NegLogLik:
    """-ln L of one vector [free pilot parameters, pacf_1..pacf_p] (Eq. 4 or AR-coloured)."""

    def __init__(self, model: PilotModel, recording: Recording, order: int,
                 noise: ARNoise | None = None, discard: float = 0.0) -> None:
        from .sample import PACF_BOUND, _LogPosterior, _Prior, pacf_names

        self.lik = Likelihood(model, recording, noise=noise, discard=discard)
        self.order = order
        self.names = model.parameter_names + pacf_names(order)
        lo, hi = model.bounds
        self.lower = np.concatenate([lo, np.full(order, -PACF_BOUND)])
        self.upper = np.concatenate([hi, np.full(order, PACF_BOUND)])
        prior = _Prior(self.names, np.concatenate([lo, np.full(order, -1.0)]),
                       np.concatenate([hi, np.full(order, 1.0)]), self.lower, self.upper, None)
        self._lp = _LogPosterior(self.lik, order, prior)
        self._row = np.empty((1, len(self.names)))

    def __call__(self, x: np.ndarray) -> float:
        self._row[0] = x
        return float(self._lp.neg_log_lik(self._row)[0])

    def log_lik(self, x: np.ndarray) -> float:
        return -self(x)

    @property
    def n(self) -> int:
        return self.lik.n_terms - self.order


@one_blas_thread
def evidence(recording: Recording, model: PilotModel | None = None, *, likelihood: str = "eq4",
             ar: str = "fixed", ar_order: int | None = None, noise: ARNoise | None = None,
             discard: float | None = None, nlive: int = 200, dlogz: float = 0.5,
             sample: str = "rwalk", seed: int | None = None,
             progress: bool = False) -> Evidence:
    """ln Z of ``model`` on ``recording`` with priors uniform on the model bounds (dynesty).

    Parameters
    ----------
    recording : Recording
    model : PilotModel, optional
        Default :func:`~bayespilot.model.paper_model` (with threshold).
    likelihood : {"eq4", "coloured"}
        As in :func:`bayespilot.sample.sample` (variance marginalised with the
        Jeffreys prior; see the module docs).
    ar : {"fixed", "sampled"}
        For ``"coloured"``: the AR model ``noise`` held fixed, or sampled.
    ar_order : int, optional
        For ``"coloured"``: the order of the AR model (``ar="sampled"``: its
        partial autocorrelations are uniform on (-0.99, 0.99); default 2;
        ``ar="fixed"``: the order estimated when ``noise`` is not given).
    noise : ARNoise, optional
        For ``"coloured"`` with ``ar="fixed"``: the AR model.  Default: estimated
        from a prediction-error fit of ``model`` (:func:`~bayespilot.fit.fast.fit_fast`).
    discard : float, optional
        Seconds at the start left out of the likelihood.  Default as
        :func:`compare`'s: :func:`~bayespilot.likelihood.coloured_discard`
        (min(2 s, a quarter of the record), as
        :func:`~bayespilot.fit.fast.fit_fast` with ``noise="ar"``) for
        ``"coloured"``; for ``"eq4"`` 0 on a record of whole forcing periods,
        else :func:`~bayespilot.likelihood.startup_discard` (2 s).  (It was 0
        for both, so that ``evidence`` and ``compare`` weighed different
        samples of one record.)
    nlive, dlogz, sample, seed, progress
        See :func:`nested_evidence`.

    Returns
    -------
    Evidence
    """
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    model, order = likelihood_options(model, likelihood, ar, ar_order, EVIDENCE_AR_MODES)
    if discard is None:
        discard = _default_discard(recording, likelihood)
    if noise is not None and not (likelihood == "coloured" and ar == "fixed"):
        raise ValueError(f"noise is the AR model of likelihood='coloured' with ar='fixed' only; "
                         f"with likelihood={likelihood!r}, ar={ar!r} it would be ignored")
    noise = _check_noise(noise) if likelihood == "coloured" and ar == "fixed" else None
    if likelihood == "coloured" and ar == "fixed" and noise is None:
        noise = _fit_noise(recording, model, seed, ar_order, discard)
    nll = _NegLogLik(model, recording, order, noise, discard)
    ev = nested_evidence(nll.log_lik, nll.lower, nll.upper, names=nll.names, nlive=nlive,
                         dlogz=dlogz, sample=sample, seed=seed, progress=progress)
    ev.settings.update({"likelihood": likelihood, "ar": ar, "ar_order": order,
                        "noise": None if noise is None else noise.to_dict(),
                        "discard_seconds": discard, "model": model.name,
                        "fixed": {k: float(v) for k, v in model.fixed.items()}})
    return ev


# --- Savage-Dickey ------------------------------------------------------------------------------
@dataclass(frozen=True)
class SavageDickey:
    """A Savage-Dickey estimate of ln BF (threshold : none) from posterior draws.

    Attributes
    ----------
    log_bayes_factor : float or None
        ln p(0) - ln p(0 | data); None when not valid.
    valid : bool
        Whether the estimate can be used (see ``reason``).
    reason : str
        Why it is or is not valid.
    lower_bound : float or None
        When the posterior has too few draws near 0 for a density there: a
        lower bound on ln BF, assuming the posterior density does not fall
        on the way from 0 to the 10th-smallest draw.
    prior_density, posterior_density : float
        At the nested value (0).  posterior_density from arviz's
        boundary-corrected KDE.
    bandwidth : float
        KDE bandwidth.
    n_draws, n_near : int
        Draws used, and draws within two bandwidths of 0.
    """

    log_bayes_factor: float | None
    valid: bool
    reason: str
    lower_bound: float | None
    prior_density: float
    posterior_density: float
    bandwidth: float
    n_draws: int
    n_near: int

    def to_dict(self) -> dict[str, Any]:
        """Every attribute by name (:func:`dataclasses.asdict`)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "SavageDickey":
        """The estimate a :meth:`to_dict` holds, as read from JSON.

        A null float is NaN (:func:`~bayespilot._files.dumps` wrote a
        non-finite number as null), except where None is what the field
        means: ``log_bayes_factor`` of an estimate that is not valid and
        ``lower_bound`` stay None.  A key a SavageDickey does not have (a
        field of a later release) is ignored.

        Parameters
        ----------
        d : mapping
            A :meth:`to_dict`.

        Returns
        -------
        SavageDickey

        Raises
        ------
        bayespilot._files.WrongKind
            A ValueError: ``d`` lacks a field (the message names it).
        """
        d = nan_for_null(cls, dataclass_fields(cls, d, "a Savage-Dickey estimate"))
        valid = bool(d["valid"])
        lbf = d["log_bayes_factor"]
        # None is what an estimate that is not valid has; a valid one was a number (a null
        # there is a non-finite one).  A lower bound that is null was not computed.
        d["log_bayes_factor"] = None if lbf is None and not valid else number(lbf)
        d["lower_bound"] = None if d["lower_bound"] is None else number(d["lower_bound"])
        return cls(**{**d, "valid": valid})


#: Largest KDE grid of :func:`savage_dickey` (points).
_SD_GRID_MAX = 2**16
#: :func:`savage_dickey` is valid only with a KDE bandwidth of at least this many grid steps:
#: half-normal draws (2000 to 200000 of them) gave ln p(0) within 0.1 of the truth down to
#: half a step, and 0.15 to 3 nats too high below a third.
_SD_MIN_BW_STEPS = 0.5


def savage_dickey(draws: Sequence[float] | np.ndarray, *, lower: float = 0.0, upper: float = 0.1,
                  prior_density: float | None = None, min_near: int = 50) -> SavageDickey:
    """Savage-Dickey ln BF (free : fixed at ``lower``) from draws of a parameter on [lower, upper].

    The nested value is the prior's lower bound, so the posterior density is
    estimated there with a boundary-corrected KDE (arviz, reflection at the
    bounds) on [lower, upper], with about 16 grid points per standard deviation of
    the draws.  A posterior too narrow for that within 2**16 points has its KDE on
    [lower, lower + 2 (max(draws) - lower)] instead; when the bandwidth is still
    under half a grid step (draws piled up at ``lower`` with a few far away), the
    estimate is not valid.

    Parameters
    ----------
    draws : array_like
        Posterior draws of the one parameter, all in [lower, upper]; any shape
        (e.g. chains x draws), flattened.
    lower, upper : float
        The prior's support; the nested model fixes the parameter at ``lower``.
    prior_density : float, optional
        Prior density at ``lower``; default 1 / (upper - lower) (uniform).
    min_near : int
        The estimate is valid only with at least this many draws within two
        KDE bandwidths of ``lower``.

    Returns
    -------
    SavageDickey

    Examples
    --------
    Draws piled up at the boundary (a half-normal of scale 0.01 on [0, 0.1])
    have the density 2 / (0.01 sqrt(2 pi)) = 79.8 at 0, so ln BF
    = ln(10 / 79.8) = -2.08 (the KDE smooths the peak a little):

    >>> x = np.abs(np.random.default_rng(0).normal(0, 0.01, 20000))
    >>> sd = savage_dickey(x)
    >>> sd.valid, round(sd.log_bayes_factor, 1)
    (True, -2.0)
    """
    from .sample import _arviz

    x = np.asarray(draws, dtype=float).ravel()
    for name, v in (("lower", lower), ("upper", upper)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating)) or not math.isfinite(v):
            raise ValueError(f"{name} must be a finite number, got {v!r}")
    if not lower < upper:
        raise ValueError(f"need lower < upper, got [{lower}, {upper}]")
    if x.size < 10 or not np.all(np.isfinite(x)):
        raise ValueError("draws must be at least 10 finite numbers")
    if np.any(x < lower) or np.any(x > upper):
        raise ValueError(f"draws must lie in the prior's support [{lower:g}, {upper:g}]")
    p0 = 1.0 / (upper - lower) if prior_density is None else _check_pos("prior_density",
                                                                        prior_density)
    min_near = _check_int("min_near", min_near, 1)
    if np.ptp(x) == 0:
        # no spread, no density to estimate (arviz's KDE returns no bandwidth for it)
        return SavageDickey(None, False, f"the {x.size} draws are all {x[0]:g} (a stuck chain?): "
                            "no posterior density to estimate", None, p0, math.nan, math.nan,
                            int(x.size), int(np.sum(x == lower)))
    az = _arviz()

    def wanted(hi: float) -> int:  # grid points for 16 per standard deviation on [lower, hi]
        return 2 ** math.ceil(math.log2(16 * (hi - lower) / max(np.std(x), 1e-12 * (hi - lower))))

    # A posterior narrower than the 2**16 points on [lower, upper] resolve (a grid step
    # coarser than the KDE's bandwidth) had its density at lower overestimated by up to 2.6
    # nats, as valid: its KDE is then made on [lower, hi], the draws' range and as much again
    # (room for the reflection at hi, which does not reach lower), at the same 16 points per
    # standard deviation.  Wider posteriors keep [lower, upper].
    hi = upper
    if wanted(upper) > _SD_GRID_MAX:
        hi = min(upper, lower + 2.0 * (float(np.max(x)) - lower))
    grid_len = int(min(_SD_GRID_MAX, max(512, wanted(hi))))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        grid, pdf, bw = az.kde(x, bound_correction=True, custom_lims=(lower, hi),
                               grid_len=grid_len, bw_return=True)
    dens = float(pdf[0])
    n_near = int(np.sum(x <= lower + 2.0 * bw))
    ln_prior = math.log(p0)
    step = (hi - lower) / grid_len
    if n_near >= min_near and dens > 0 and not bw >= _SD_MIN_BW_STEPS * step:
        # (draws piled up at lower with a few far away: the grid cannot be narrowed to them)
        return SavageDickey(None, False, f"the KDE bandwidth {bw:.3g} is under "
                            f"{_SD_MIN_BW_STEPS:g} of its grid's step {step:.3g} on [{lower:g}, "
                            f"{hi:g}]: the posterior near {lower:g} is narrower than the grid "
                            "resolves, so its density there cannot be estimated from these "
                            "draws; use the nested-sampling ln BF", None, p0, dens, float(bw),
                            int(x.size), n_near)
    if n_near >= min_near and dens > 0:
        return SavageDickey(ln_prior - math.log(dens), True,
                            f"{n_near} of {x.size} draws within 2 bandwidths of {lower:g}",
                            None, p0, dens, float(bw), int(x.size), n_near)
    k = min(10, x.size)
    xk = float(np.sort(x)[k - 1]) - lower
    lb = ln_prior - math.log(k / (x.size * xk)) if xk > 0 else None
    reason = (f"only {n_near} of {x.size} draws within 2 bandwidths ({2 * bw:.3g}) of {lower:g}: "
              "the posterior density there is too small to estimate from these draws")
    return SavageDickey(None, False, reason, lb, p0, dens, float(bw), int(x.size), n_near)


def savage_dickey_from_posterior(posterior: Posterior, model: PilotModel | None = None,
                                 min_near: int = 50) -> SavageDickey:
    """:func:`savage_dickey` for ``delta_abs`` from a :class:`~bayespilot.sample.Posterior`.

    Valid only if the posterior was sampled with the default prior (uniform on
    the bounds), the prior's lower bound on ``delta_abs`` is 0 (the model
    without threshold), and enough draws lie near 0.  An invalid case comes
    back with ``valid=False`` and the reason, not an exception.

    Parameters
    ----------
    posterior : Posterior
        Draws of the model with threshold (:func:`~bayespilot.sample.sample`);
        ``delta_abs`` must be among its sampled parameters.  Whether its prior
        was the default is read from ``posterior.settings["prior"]``.
    model : PilotModel, optional
        The model whose bounds on ``delta_abs`` are the prior's support
        [lower, upper], IPUT: the model the posterior was sampled with.
        Default :func:`~bayespilot.model.paper_model` ([0, 0.1], Table 1).
    min_near : int, default 50
        The estimate is valid only with at least this many draws within two
        KDE bandwidths of 0 (see :func:`savage_dickey`).

    Returns
    -------
    SavageDickey
        ``log_bayes_factor`` is ln BF (threshold : none), None when not valid.
        For a non-default prior or a prior whose lower bound is not 0 the
        densities and the bandwidth are NaN and ``n_near`` is 0.

    Raises
    ------
    TypeError
        If ``posterior`` is not a :class:`~bayespilot.sample.Posterior`.
    ValueError
        If ``delta_abs`` was not sampled, or (from :func:`savage_dickey`) there
        are fewer than 10 draws, a draw is not finite or lies outside the
        bounds of ``delta_abs`` in ``model``, or ``min_near`` is not an
        integer >= 1.
    KeyError
        If ``model`` has no parameter ``delta_abs``.
    """
    from .sample import Posterior

    if not isinstance(posterior, Posterior):
        raise TypeError(f"posterior must be a bayespilot.sample.Posterior, got "
                        f"{type(posterior).__name__}")
    model = paper_model() if model is None else model
    if THRESHOLD not in posterior.parameter_names:
        raise ValueError(f"the posterior has no {THRESHOLD!r} (sampled: "
                         f"{', '.join(posterior.parameter_names)})")
    par = model.parameter(THRESHOLD)
    x = posterior.draws(THRESHOLD)

    def invalid(reason: str) -> SavageDickey:
        return SavageDickey(None, False, reason, None, math.nan, math.nan, math.nan, int(x.size), 0)

    prior = str(posterior.settings.get("prior", ""))
    if f"{THRESHOLD} ~" in prior or prior.startswith("callable"):
        return invalid(f"the posterior was sampled with a non-default prior ({prior}); "
                       "Savage-Dickey here assumes delta_abs uniform on its bounds")
    if par.lower != 0.0:
        return invalid(f"the prior of {THRESHOLD} is on [{par.lower:g}, {par.upper:g}], which "
                       "does not contain the nested value 0 at its lower bound")
    return savage_dickey(x, lower=par.lower, upper=par.upper, min_near=min_near)


# --- information criteria ---------------------------------------------------------------------
def information_criteria(neg_log_lik_threshold: float, neg_log_lik_none: float, k_threshold: int,
                         k_none: int, n: int) -> dict[str, float | int]:
    """AIC and BIC of both models from their maximum-likelihood -ln L.

    ``k_*`` count every estimated parameter, the output-error variance
    included; ``n`` is the number of samples the likelihood uses.
    ``delta_aic``/``delta_bic`` are (none - threshold): positive favours the
    threshold.  ``log_bayes_factor_bic`` = delta_bic / 2 is the BIC
    (Schwarz) approximation of ln BF.

    Parameters
    ----------
    neg_log_lik_threshold : float
        -ln L at the maximum-likelihood fit of the model with threshold.
    neg_log_lik_none : float
        -ln L at the maximum-likelihood fit of the model without threshold.
    k_threshold : int
        Estimated parameters of the model with threshold, >= 1.
    k_none : int
        Estimated parameters of the model without threshold, >= 1.
    n : int
        Samples the likelihood uses, >= 1.

    Returns
    -------
    dict
        The inputs (``neg_log_lik_threshold``, ``neg_log_lik_none``,
        ``k_threshold``, ``k_none``, ``n``; the counts as int, the rest
        float) and ``aic_threshold``, ``aic_none``, ``bic_threshold``,
        ``bic_none``, ``delta_aic``, ``delta_bic`` and
        ``log_bayes_factor_bic``.

    Raises
    ------
    ValueError
        If a -ln L is not an int or float (numpy floats included) or is NaN,
        or ``k_threshold``, ``k_none`` or ``n`` is not an integer >= 1.

    Examples
    --------
    >>> ic = information_criteria(-100.0, -95.0, 9, 8, 1000)
    >>> ic["delta_aic"], round(ic["delta_bic"], 3)
    (8.0, 3.092)
    """
    for name, v in (("neg_log_lik_threshold", neg_log_lik_threshold),
                    ("neg_log_lik_none", neg_log_lik_none)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                or math.isnan(v):
            raise ValueError(f"{name} must be a number, got {v!r}")
    k1 = _check_int("k_threshold", k_threshold, 1)
    k0 = _check_int("k_none", k_none, 1)
    n = _check_int("n", n, 1)
    aic1, aic0 = 2 * k1 + 2 * neg_log_lik_threshold, 2 * k0 + 2 * neg_log_lik_none
    bic1, bic0 = k1 * math.log(n) + 2 * neg_log_lik_threshold, k0 * math.log(n) + 2 * neg_log_lik_none
    return {"neg_log_lik_threshold": float(neg_log_lik_threshold),
            "neg_log_lik_none": float(neg_log_lik_none), "k_threshold": k1, "k_none": k0, "n": n,
            "aic_threshold": float(aic1), "aic_none": float(aic0), "bic_threshold": float(bic1),
            "bic_none": float(bic0), "delta_aic": float(aic0 - aic1),
            "delta_bic": float(bic0 - bic1), "log_bayes_factor_bic": float((bic0 - bic1) / 2)}


def _ml(nll: _NegLogLik, start: Mapping[str, float], threshold: bool) -> tuple[float, dict]:
    """Maximum-likelihood -ln L from ``start`` (dynesty's best point): bounded Gauss-Newton
    (Eq. 4 only; the pilot parameters with delta_abs held) and, with threshold, a scan of
    delta_abs over its bounds at 1e-4 and a second refinement."""
    from .fit.gauss_newton import refine

    x = np.array([start[n] for n in nll.names])
    best_v, best_x = nll(x), x.copy()
    model = nll.lik.model
    if nll.order:
        return best_v, dict(zip(nll.names, best_x.tolist()))

    def polish(x0):
        r = refine(nll.lik, dict(zip(nll.names, x0)), hold=(THRESHOLD,), bounded=True)
        return float(r.neg_log_lik), np.array([r.params[n] for n in nll.names])

    rounds = 2 if threshold else 1
    for _ in range(rounds):
        v, xr = polish(best_x)
        if v < best_v:
            best_v, best_x = v, xr
        if threshold:
            j = nll.names.index(THRESHOLD)
            par = model.parameter(THRESHOLD)
            grid = np.arange(par.lower, par.upper + 0.5e-4, 1e-4)
            rows = np.repeat(best_x[None, :], grid.size, axis=0)
            rows[:, j] = grid
            vals = nll.lik.batch(rows)
            i = int(np.argmin(vals))
            if vals[i] < best_v:
                best_v, best_x = float(vals[i]), rows[i].copy()
    return float(best_v), dict(zip(nll.names, best_x.tolist()))


def robust_evidence(run: Callable[[int], Evidence], n_runs: int,
                    reference_max_log_lik: float) -> tuple[Evidence, list, bool]:
    """ln Z of a model from ``n_runs`` nested-sampling runs that agree.

    A run whose best ln L is more than :data:`MODE_TOLERANCE` below
    ``reference_max_log_lik`` lost the main mode and is dropped, and another
    run is made (at most :data:`MAX_RERUNS` extra).  Of the runs kept, those
    whose ln Z lies more than 3 combined standard errors below the highest
    are dropped too: the failure of nested sampling on this likelihood is to
    find the main mode late, which only ever lowers ln Z.  The rest are
    combined by inverse-variance weighting; the error is the larger of the
    weighted one and the standard error of their spread.

    Parameters
    ----------
    run : callable
        ``run(attempt) -> Evidence``: one nested-sampling run with its own
        seed (e.g. :func:`evidence` with ``seed=s1 + attempt`` for an ``s1``
        spawned from the call's seed, as :func:`compare` does, or
        ``bayespilot._seeds.stream_seed(s1, attempt)``).
    n_runs : int
        Runs to combine.
    reference_max_log_lik : float
        A ln L the model is known to reach: the model without threshold's
        best (which the model with threshold nests), or a fit's.

    Returns
    -------
    (Evidence, list of dict, bool)
        The combined evidence, a record of every run (``used``, ``why``),
        and whether any run passed the mode check (if not, the Evidence is the
        last run's, a lower bound).
    """
    if isinstance(n_runs, bool) or not isinstance(n_runs, (int, np.integer)) or n_runs < 1:
        raise ValueError(f"n_runs must be an integer >= 1, got {n_runs!r}")
    kept: list[Evidence] = []
    made: list[Evidence] = []
    record: list[dict] = []
    attempt = 0
    while len(kept) < n_runs and attempt < n_runs + MAX_RERUNS:
        ev = run(attempt)
        made.append(ev)
        attempt += 1
        entry = {"attempt": attempt, "seed": ev.settings.get("seed"), "log_z": ev.log_z,
                 "log_z_err": ev.log_z_err, "max_log_lik": ev.max_log_lik,
                 "information": ev.information, "used": True, "why": ""}
        record.append(entry)
        if ev.max_log_lik < reference_max_log_lik - MODE_TOLERANCE:
            entry.update(used=False, why="lost the main mode (best ln L below the model "
                                         "without threshold)")
            continue
        kept.append(ev)
    if not kept:
        return ev, record, False
    top = max(kept, key=lambda e: e.log_z)
    good = []
    for ev, entry in zip(kept, [e for e in record if e["used"]]):
        if ev.log_z < top.log_z - 3.0 * math.hypot(ev.log_z_err, top.log_z_err):
            entry.update(used=False, why="ln Z more than 3 standard errors below the highest run "
                                         "(found the main mode late)")
        else:
            good.append(ev)
    # inverse-variance weights; an error reported as 0 (a degenerate run) is floored, so that
    # it weighs most instead of dividing by zero
    w = np.array([1.0 / max(e.log_z_err, 1e-9) ** 2 for e in good])
    z = np.array([e.log_z for e in good])
    log_z = float(w @ z / w.sum())
    err = float(math.sqrt(1.0 / w.sum()))
    if len(good) > 1:
        err = max(err, float(np.std(z, ddof=1) / math.sqrt(len(good))))
    settings = dict(top.settings, runs=record, seed=good[0].settings.get("seed"))
    with_draws = [e for e in good if e.samples is not None]
    samples = weights = None
    if with_draws:  # each run's posterior counts equally
        samples = np.concatenate([e.samples for e in with_draws])
        weights = np.concatenate([e.weights / len(with_draws) for e in with_draws])
    combined = Evidence(log_z, err, float(np.mean([e.information for e in good])),
                        float(max(e.max_log_lik for e in good)), top.best, top.mean,
                        top.parameter_names, int(sum(e.n_calls for e in made)),
                        int(sum(e.n_iter for e in made)), float(sum(e.elapsed for e in made)),
                        settings, samples, weights)
    return combined, record, True


# --- one recording ---------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Comparison(SummaryHTML):
    """Threshold against no threshold on one recording (see :func:`compare`).

    Attributes
    ----------
    log_bayes_factor, log_bayes_factor_err : float
        ln Z(threshold) - ln Z(none) and its standard error.
    decision : {"threshold", "none", "inconclusive"}
        :func:`decide` on the ln BF, with the plateau guard below.
    evidence_threshold, evidence_none : Evidence
        The nested-sampling runs of the models with and without threshold.
    savage_dickey : SavageDickey or None
        The check from the threshold model's posterior draws; None if not
        computed.
    information_criteria : dict
        From :func:`information_criteria`, plus the ML parameters.
    settings : dict
        Every setting of the comparison.
    seed : int or None
        The seed used.
    elapsed : float
        Wall time, s.
    source : str or None
        The recording compared on.
    plateau_probability : float or None
        Posterior probability, under the model with threshold, that
        ``delta_abs`` is at or above the plateau onset (:func:`plateau_onset`),
        where the dead zone passes less than 1 % of the samples or switches
        the motion channel off.  Above
        :data:`PLATEAU_LEVEL` a "threshold" decision is made "inconclusive"
        (``settings["decision_note"]`` says why).  None where the guard could
        not be applied (``settings["plateau_guard"]`` is then "not applied:
        <reason>", said in :meth:`summary`, and in ``decision_note`` of a
        "threshold" decision; see :func:`compare`).
    """

    log_bayes_factor: float
    log_bayes_factor_err: float
    decision: str
    evidence_threshold: Evidence
    evidence_none: Evidence
    savage_dickey: SavageDickey | None
    information_criteria: dict[str, Any]
    settings: dict[str, Any] = field(default_factory=dict)
    seed: int | None = None
    elapsed: float = math.nan
    source: str | None = None
    plateau_probability: float | None = None

    @property
    def category(self) -> str:
        """Jeffreys' name for the strength of the evidence."""
        return jeffreys_category(self.log_bayes_factor)

    @property
    def threshold_identified(self) -> bool:
        """False when the record does not identify ``delta_abs`` (its channel's input is zero
        throughout: the two models are the same on it; ``settings["threshold_identified"]``,
        True for a comparison saved before it was recorded)."""
        s = self.settings if isinstance(self.settings, Mapping) else {}
        return s.get("threshold_identified", True) is not False

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the keys of the CLI's ``--json``); a copy: changing it leaves the
        comparison as it is."""
        ic = copy.deepcopy(self.information_criteria)
        sd = self.savage_dickey
        return {
            "log_bayes_factor": self.log_bayes_factor,
            "log_bayes_factor_err": self.log_bayes_factor_err,
            "decision": self.decision,
            "decision_note": self.settings.get("decision_note", ""),
            "plateau_probability": self.plateau_probability,
            "jeffreys_category": self.category,
            "favours": _favours(self.log_bayes_factor) if self.threshold_identified
            else "neither",
            "log_evidence_threshold": self.evidence_threshold.log_z,
            "log_evidence_threshold_err": self.evidence_threshold.log_z_err,
            "log_evidence_none": self.evidence_none.log_z,
            "log_evidence_none_err": self.evidence_none.log_z_err,
            "savage_dickey_log_bayes_factor": None if sd is None else sd.log_bayes_factor,
            "savage_dickey_valid": None if sd is None else sd.valid,
            "savage_dickey": None if sd is None else sd.to_dict(),
            "delta_aic": ic["delta_aic"], "delta_bic": ic["delta_bic"],
            "information_criteria": ic,
            "evidence_threshold": self.evidence_threshold.to_dict(),
            "evidence_none": self.evidence_none.to_dict(),
            "settings": copy.deepcopy(self.settings), "seed": self.seed,
            "elapsed_seconds": self.elapsed,
            "source": self.source,
        }

    def to_json(self, path: str | os.PathLike | None = None) -> str | Path:
        """The :meth:`to_dict` as JSON text, or written to ``path`` (parents created).

        Non-finite numbers are written as null (NaN again after
        :meth:`from_json`).

        Parameters
        ----------
        path : str or os.PathLike, optional
            The file to write; an existing one is replaced only once the new
            one is written.  None: return the text.

        Returns
        -------
        str or Path
            The JSON text, or ``path`` when given.
        """
        text = dumps(self.to_dict())
        return text if path is None else write_text_atomic(path, text)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Comparison":
        """The comparison a :meth:`to_dict` holds (a null number is NaN; the evidences
        without their draws).

        Parameters
        ----------
        d : mapping
            A :meth:`to_dict`, as read from JSON.

        Returns
        -------
        Comparison

        Raises
        ------
        ValueError
            ``d`` lacks what a comparison's dict has (``log_bayes_factor``,
            ``log_bayes_factor_err``, ``decision``, the two evidences,
            ``information_criteria``), or an evidence or ``savage_dickey``
            lacks a field (the message names what is missing): another kind of
            file.  A key of a later release is ignored.

        Notes
        -----
        A null number is NaN in the numbers of ``information_criteria`` (all
        but the counts ``k_threshold``, ``k_none`` and ``n``, and in the
        ``ml_*`` parameter dicts), the evidences' ``best`` and ``mean``, and
        ``savage_dickey`` (see :meth:`SavageDickey.from_dict`).
        ``plateau_probability`` is NaN for a null only where one was computed
        (``settings["plateau_onset"]`` is not None, as :func:`compare`
        makes it); otherwise None, not computed.
        """
        require_keys(d, ("log_bayes_factor", "log_bayes_factor_err", "decision",
                         "evidence_threshold", "evidence_none", "information_criteria"),
                     "a comparison")
        settings = dict(d.get("settings") or {})

        def part(key, from_dict):  # the message says which part lacks a field
            try:
                return from_dict(d[key])
            except WrongKind as exc:
                raise WrongKind(f"{key}: {exc}") from None

        sd = None if d.get("savage_dickey") is None else part("savage_dickey",
                                                              SavageDickey.from_dict)
        pp = d.get("plateau_probability")
        if pp is not None or settings.get("plateau_onset") is not None:
            # compare computes a probability wherever there is a plateau onset, so a null
            # there was a number (NaN); before that field existed, or without an onset, None
            pp = number(pp)
        return cls(number(d["log_bayes_factor"]), number(d["log_bayes_factor_err"]),
                   d["decision"], part("evidence_threshold", Evidence.from_dict),
                   part("evidence_none", Evidence.from_dict), sd,
                   _information_criteria_from_dict(d["information_criteria"]),
                   settings, d.get("seed"), number(d.get("elapsed_seconds")), d.get("source"),
                   pp)

    @classmethod
    def from_json(cls, path: str | os.PathLike) -> "Comparison":
        """The comparison a :meth:`to_json` file holds.

        Parameters
        ----------
        path : str or os.PathLike
            The JSON file.

        Returns
        -------
        Comparison

        Raises
        ------
        FileNotFoundError
            No file at ``path``.
        ValueError
            The file is not JSON, or not a comparison's (the message names it).
        """
        return read_result(path, cls.from_dict, "a Comparison")

    def summary(self) -> str:
        """A few lines for people."""
        ic = self.information_criteria
        e1, e0 = self.evidence_threshold, self.evidence_none
        sd = self.savage_dickey
        if sd is None:
            sd_line = "Savage-Dickey: not computed"
        elif sd.valid:
            sd_line = f"Savage-Dickey ln BF = {sd.log_bayes_factor:+.2f} ({sd.reason})"
        else:
            lb = "" if sd.lower_bound is None else f"; ln BF > {sd.lower_bound:.1f}"
            sd_line = f"Savage-Dickey: not valid ({sd.reason}{lb})"
        post = self.settings.get("posterior") if isinstance(self.settings, Mapping) else None
        guard = self.settings.get("plateau_guard") if isinstance(self.settings, Mapping) else None
        also = (self.settings.get("null_also_zeroes") or []) if isinstance(self.settings,
                                                                           Mapping) else []
        if sd is not None and isinstance(post, Mapping) and post.get("converged") is False:
            steps = post.get("n_steps")
            sd_line += ("\n  Savage-Dickey posterior: not converged"
                        f"{'' if steps is None else f' after {steps} steps'}, so the check "
                        "above is rough")
        return "\n".join([
            f"threshold vs none ({self.settings.get('likelihood')} likelihood"
            f"{', ' + self.source if self.source else ''}):",
            f"  ln BF = {self.log_bayes_factor:+.2f} +- {self.log_bayes_factor_err:.2f}  "
            + _verdict(self.log_bayes_factor, self.log_bayes_factor_err, self.decision,
                       self.settings.get("decision_note") or "",
                       level=self.settings.get("decision_level", DECISION_LEVEL),
                       z=self.settings.get("decision_z", DECISION_Z),
                       identified=self.threshold_identified),
            f"  ln Z threshold = {e1.log_z:.2f} +- {e1.log_z_err:.2f}, none = {e0.log_z:.2f} +- "
            f"{e0.log_z_err:.2f} (dynesty, nlive {e1.settings.get('nlive')})",
            f"  {sd_line}",
            f"  -ln L (ML) threshold = {ic['neg_log_lik_threshold']:.2f}, none = "
            f"{ic['neg_log_lik_none']:.2f}; dAIC = {ic['delta_aic']:+.2f}, dBIC = "
            f"{ic['delta_bic']:+.2f} (none - threshold; > 0 favours threshold)",
            *([f"  plateau guard {guard}"] if isinstance(guard, str)
              and guard.startswith("not applied") else []),
            *([f"  the model without threshold also holds {', '.join(also)} at 0: ln BF "
               f"weighs these thresholds and delta_abs together"] if also else []),
            *([f"  {EQ4_COMPARISON_NOTE}"] if self.settings.get("likelihood") == "eq4" else []),
            f"  {self.elapsed:.1f} s"])

    def __str__(self) -> str:
        return self.summary()

    def __repr__(self) -> str:
        """One line (the dataclass's would print both evidences and every setting)."""
        n = self.settings.get("n_samples") if isinstance(self.settings, Mapping) else None
        return (f"<Comparison: ln BF = {_num(self.log_bayes_factor, '+.2f')} +- "
                f"{_num(self.log_bayes_factor_err, '.2f')} -> {self.decision}"
                f"{'' if n is None else f', N = {n}'}{_source(self.source)}>")


#: What :meth:`Comparison.summary` says of a comparison under Eq. 4 (the default, the paper's
#: likelihood): measured in docs/comparison.md, "Which likelihood".
EQ4_COMPARISON_NOTE = (
    "note: Eq. 4 treats the remnant, which is coloured, as white, and inflates ln BF on "
    "closed-loop recordings: it can decide 'threshold' on recordings without one "
    "(docs/comparison.md, 'Which likelihood'); decide with the coloured likelihood "
    "(likelihood='coloured'; bayespilot compare --likelihood coloured)")

#: The counts among :func:`information_criteria`'s entries (ints; every other entry is a float
#: or, ``ml_*``, a dict of floats).
_IC_COUNTS = ("k_threshold", "k_none", "n")


def _information_criteria_from_dict(ic: Mapping[str, Any]) -> dict[str, Any]:
    """:attr:`Comparison.information_criteria` as a file holds it, with NaN for each null
    number (the counts are kept as they are; an entry that is not a number, null or an
    ``ml_*`` dict, e.g. one of a later release, too)."""
    out: dict[str, Any] = {}
    for k, v in ic.items():
        if k in _IC_COUNTS:
            out[k] = v
        elif isinstance(v, Mapping):
            out[k] = numbers(v) if k.startswith("ml_") else dict(v)
        elif v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)) \
                or (isinstance(v, str) and v in ("inf", "-inf")):
            out[k] = number(v)
        else:
            out[k] = v
    return out


def _num(v, spec: str) -> str:
    """``format(v, spec)``, or ``str(v)`` for what is not a number (a repr must not raise)."""
    try:
        return format(float(v), spec)
    except (TypeError, ValueError):
        return str(v)


def _source(source) -> str:
    """``", <source>"`` for a one-line repr, a long path cut to its end; "" without one."""
    if not source:
        return ""
    text = str(source)
    return f", {text if len(text) <= 60 else '...' + text[-57:]}"


#: sample()'s arguments that compare sets itself (the recording, the model, the likelihood
#: of the comparison, the starting point and the seed): not taken from ``sample_options``.
_SET_BY_COMPARE = ("recording", "model", "likelihood", "ar", "ar_order", "noise", "discard",
                   "init", "seed")


def _check_sample_options(options: Mapping[str, Any]) -> None:
    """Refuse, before any nested sampling, ``sample_options`` that :func:`sample` would refuse
    at the end (a misspelt keyword) or that :func:`compare` sets itself."""
    import inspect

    from .sample import sample as run_sample

    known = set(inspect.signature(run_sample).parameters)
    unknown = sorted(set(options) - known)
    if unknown:
        raise TypeError(f"sample_options: {', '.join(map(repr, unknown))} not keyword(s) of "
                        f"sample(); it takes {', '.join(sorted(known - set(_SET_BY_COMPARE)))}")
    taken = sorted(set(options) & set(_SET_BY_COMPARE))
    if taken:
        raise ValueError(f"sample_options: {', '.join(map(repr, taken))} set by compare itself "
                         "(its own argument, or the maximum-likelihood start and a seed "
                         "drawn from its seed)")


def _linear_twin(model: PilotModel, c: int) -> bool:
    """Whether channel ``c`` (a saturation) has a twin without nonlinearity and of the other
    sign, alike in all else: the two make a dead zone, x - clip(x) (a composed dead zone)."""
    import dataclasses

    ch = model.channels[c]
    for k, other in enumerate(model.channels):
        if k != c and other.nonlinearity is None and dataclasses.replace(
                ch, name=other.name, nonlinearity=None, sign=-ch.sign,
                oversample=other.oversample) == other:
            return True
    return False


def _threshold_channel(model: PilotModel) -> tuple[int | None, str]:
    """``(c, "")``: channel ``c``'s nonlinearity is the dead zone on ``delta_abs`` whose input
    sets the plateau (a :class:`~bayespilot.model.DeadZone`, a
    :class:`~bayespilot.model.SoftDeadZone`, taken as a dead zone of its ``delta``, or the
    :class:`~bayespilot.model.Saturation` on ``delta_abs`` of a dead zone composed as a linear
    channel minus its clipped copy); ``(None, why)`` where there is no such one channel."""
    from .model import DeadZone, Saturation, SoftDeadZone

    out = model.output
    if out is not None and THRESHOLD in out.parameters:
        return None, (f"{THRESHOLD} is a parameter of the model output's "
                      f"{type(out).__name__}, not of a channel's dead zone")
    owners = [c for c, ch in enumerate(model.channels)
              if ch.nonlinearity is not None and THRESHOLD in ch.nonlinearity.parameters]
    if not owners:
        return None, f"no channel's nonlinearity reads {THRESHOLD}"
    if len(owners) > 1:
        return None, (f"{THRESHOLD} is read by the nonlinearities of "
                      f"{len(owners)} channels ("
                      f"{', '.join(model.channels[c].name for c in owners)}), whose inputs differ")
    c = owners[0]
    ch = model.channels[c]
    nl = ch.nonlinearity
    if isinstance(nl, (DeadZone, SoftDeadZone)) and nl.delta == THRESHOLD:
        return c, ""
    if isinstance(nl, Saturation) and nl.limit == THRESHOLD and _linear_twin(model, c):
        return c, ""
    return None, (f"{THRESHOLD} is read by the {ch.name} channel's {type(nl).__name__}, "
                  "which is not a dead zone on it (a DeadZone, a SoftDeadZone, or the "
                  "Saturation of a dead zone composed as a linear channel minus its clipped "
                  "copy)")


def _threshold_input(model: PilotModel, recording: Recording,
                     params: Mapping[str, float] | None = None) -> tuple[np.ndarray | None, str]:
    """(|i|, "") with |i| the magnitude of the input of the dead zone on ``delta_abs``
    (:func:`_threshold_channel`) over the recording, or (None, why it is not computed).

    The channel's source through its fixed stages
    (:func:`~bayespilot.likelihood.channel_inputs`), then through its stages with free
    parameters at ``params`` by the likelihood's own recursion (Tustin's rule at the
    recording's rate, from its exact periodic steady state, ``initial="periodic"``).
    Without ``params`` a channel with such stages gives None."""
    from .kernels._blocks import stage_tf, tustin
    from .kernels._response import _filter_biquad
    from .likelihood import channel_inputs
    from .model import FixedFilter

    c, why = _threshold_channel(model)
    if c is None:
        return None, why
    ch = model.channels[c]
    free = [st for st in ch.stages if not isinstance(st, FixedFilter)]
    if free and params is None:
        return None, (f"the {ch.name} channel's dead zone follows stages with free parameters "
                      f"({', '.join(type(st).__name__ for st in free)}), and no parameter "
                      "values were given to compute its input at")
    x = channel_inputs(model, recording)[c]
    if free:
        values = model.as_dict(model.full_vector(
            {k: v for k, v in params.items() if k in model.all_names}), full=True)
        const = np.zeros(6)
        for st in free:
            ps = [values[n] for n in st.parameters]
            coef = stage_tf(st.kind, ps[0] if ps else 0.0, ps[1] if len(ps) > 1 else 0.0, const)
            out = np.empty_like(x)
            _filter_biquad(np.ascontiguousarray(x), *tustin(*coef, recording.dt), True, 0, out)
            x = out
    return np.abs(x), ""


def threshold_input_max(model: PilotModel, recording: Recording,
                        params: Mapping[str, float] | None = None) -> float | None:
    """max|i| of the input of the dead zone on ``delta_abs`` over the recording.

    For ``delta_abs`` at or above this value the dead zone passes nothing and
    the channel is switched off: the plateau of the likelihood.  The dead
    zone is a :class:`~bayespilot.model.DeadZone` on ``delta_abs``, a
    :class:`~bayespilot.model.SoftDeadZone` on it (taken as a dead zone of
    its ``delta``), or the :class:`~bayespilot.model.Saturation` on it of a
    dead zone composed as a linear channel minus its clipped copy.  None when
    no single channel has one, or when its channel has stages with free
    parameters (a washout, a motion system) and ``params`` is not given.

    Parameters
    ----------
    model : PilotModel
        The model; the dead zone's input is its channel's source passed
        through the channel's stages (for the paper's model, the canal
        output i of theta_ddot_m).
    recording : Recording
        The run, with the likelihood's default start-up treatment
        (``initial="periodic"``, :func:`~bayespilot.likelihood.channel_inputs`).
    params : mapping, optional
        Parameter values (by name; others at their defaults or fixed
        values) at which the stages with free parameters are computed, e.g.
        the maximum-likelihood point (:func:`compare` gives its own).  Not
        needed for fixed stages.

    Returns
    -------
    float or None
        max|i| over the recording, in the units of the dead zone's input
        (IPUT for the paper's model), or None as above.

    Raises
    ------
    ValueError
        If the dead zone's input is computed and a channel of ``model``
        needs the ``theta`` column, which ``recording`` does not have; or
        ``params`` names a parameter the model does not have.
    """
    i, _ = _threshold_input(model, recording, params)
    return None if i is None else float(np.max(i))


def plateau_onset(model: PilotModel, recording: Recording,
                  active_fraction: float = PLATEAU_ACTIVE_FRACTION,
                  params: Mapping[str, float] | None = None) -> float | None:
    """The ``delta_abs`` above which the dead zone passes under ``active_fraction`` of the samples.

    The (1 - ``active_fraction``) quantile of |i|, the input of the dead zone,
    over the recording.  Above it the motion channel acts on a few peaks
    only (at 0.01, under 82 of 8192 samples), which a large K_m can turn into
    a fit of a few remnant events; at max|i| (``active_fraction`` = 0) it is
    switched off.  :func:`compare` treats both as the plateau.  None where
    :func:`threshold_input_max` is None.

    Parameters
    ----------
    model : PilotModel
    recording : Recording
    active_fraction : float
        Fraction of the samples, in [0, 1).
    params : mapping, optional
        As in :func:`threshold_input_max`: the values at which stages with
        free parameters before the dead zone are computed.

    Returns
    -------
    float or None
    """
    if not 0.0 <= active_fraction < 1.0:
        raise ValueError(f"active_fraction must be in [0, 1), got {active_fraction!r}")
    i, _ = _threshold_input(model, recording, params)
    return None if i is None else float(np.quantile(i, 1.0 - active_fraction))


def _silent_threshold(lik: Likelihood) -> str | None:
    """"<channel> channel's input (<source>)" of the channel whose input is zero throughout
    ``lik``'s record and that owns the threshold (it is then not identified), or None."""
    from .likelihood import _silent_channels

    for ch, own in _silent_channels(lik.model, lik.X):
        if THRESHOLD in own:
            return f"{ch.name} channel's input ({ch.source})"
    return None


def _guarded_decision(log_bf: float, err: float, mode_ok: bool, plateau: float | None,
                      onset: float | None = None, silent: str | None = None) -> tuple[str, str]:
    """:func:`decide`, then three guards; returns (decision, why it was changed or "").

    ``silent``: the channel (its name and input) whose input is zero throughout the record,
    so that the threshold is not identified and the two models are the same: "inconclusive",
    whatever ln BF's sampling noise says."""
    d = decide(log_bf, err)
    if silent is not None:
        return "inconclusive", (f"{THRESHOLD} is not identified: the {silent} is zero "
                                "throughout the record, so the two models are the same on it")
    if d == "none" and not mode_ok:
        return "inconclusive", ("every nested-sampling run with threshold lost the main mode, so "
                                "ln BF is only a lower bound and cannot favour 'none'")
    if d == "threshold" and plateau is not None and plateau > PLATEAU_LEVEL:
        where = "the plateau" if onset is None else f"{onset:.4g}"
        return "inconclusive", (f"P(delta_abs >= {where}) = {plateau:.2f}: above it the dead zone "
                                f"passes under {PLATEAU_ACTIVE_FRACTION:.0%} of the samples or "
                                "switches the motion channel off, which a threshold, a few fitted "
                                "remnant peaks and an unused channel explain alike")
    return d, ""


def _check_posterior(posterior: Posterior, recording: Recording, model: PilotModel,
                     likelihood: str, ar: str, ar_order: int | None, discard: float) -> None:
    """Refuse (ValueError) a posterior :func:`compare` cannot use: sampled on another recording
    (by ``settings["recording_sha256"]``), of another model, or, under the same likelihood,
    with another lead-in left out or (its AR model serving the comparison) another AR order.
    A posterior saved before the recording's digest was recorded is used with a warning.

    A posterior under the other likelihood is not refused: its Savage-Dickey estimate is
    marked not valid, and its AR model is not used.
    """
    s = posterior.settings or {}
    here = recording.source or "the recording compared"
    there = s.get("recording") or "an unnamed recording"
    stored = s.get("recording_sha256")
    if stored is None:
        warn_at_caller(f"the posterior (sampled on {there}) was saved before bayespilot "
                       "recorded the digest of the recording it was sampled on: whether it was "
                       f"sampled on {here} cannot be checked; it is used as it is",
                       RuntimeWarning)
    elif stored != _recording_digest(recording):
        if there == here:
            raise ValueError(f"the posterior was sampled on {there} as it was then: the content "
                             f"of {here} is not the same now (signals, sample rate or "
                             "K_theta differ); sample its posterior again, or give none")
        raise ValueError(f"the posterior was sampled on another recording ({there}) than the "
                         f"one compared ({here}): their contents differ; sample the posterior "
                         f"of {here}, or give none")
    what = s.get("model")
    if what is not None and what != model.name:
        hint = (" (the sample command's --oversample is part of the model: give the "
                "comparison the same)" if re.search(r", \d+x ", f"{what} {model.name}") else "")
        raise ValueError(f"the posterior is of the model {what!r}, the comparison of "
                         f"{model.name!r}; sample the posterior of {model.name!r}, or give "
                         f"none{hint}")
    fixed = s.get("fixed")
    if fixed is not None and {k: float(v) for k, v in fixed.items()} != \
            {k: float(v) for k, v in model.fixed.items()}:
        def show(d):
            return ", ".join(f"{k} = {float(v):g}" for k, v in sorted(d.items())) or "nothing"

        raise ValueError(f"the posterior's model holds {show(fixed)} fixed, the comparison's "
                         f"{show(model.fixed)}; sample the posterior of the compared model, "
                         "or give none")
    sampled = tuple(n for n in posterior.parameter_names if not n.startswith("pacf_"))
    if sampled != tuple(model.parameter_names):
        raise ValueError(f"the posterior sampled {', '.join(sampled)}; the compared model's "
                         f"free parameters are {', '.join(model.parameter_names)}; sample the "
                         "posterior of the compared model, or give none")
    if s.get("likelihood") != likelihood:
        return  # Savage-Dickey marked not valid; the posterior's AR model not used
    left_out = s.get("discard_seconds")
    if left_out is not None and not math.isclose(float(left_out), discard, abs_tol=1e-9):
        raise ValueError(f"the posterior left the first {float(left_out):g} s of the record out "
                         f"of its likelihood, the comparison {discard:g} s; compare with "
                         f"discard={float(left_out):g}, or give a posterior sampled with "
                         f"discard={discard:g}")
    noise = s.get("noise")
    if likelihood == "coloured" and ar == "fixed" and isinstance(noise, Mapping) \
            and ar_order is not None and ARNoise.from_dict(noise).order != ar_order:
        raise ValueError(f"the posterior's AR noise model, which the comparison takes over, is "
                         f"of order {ARNoise.from_dict(noise).order}, not ar_order = {ar_order} "
                         "(--ar-order); leave ar_order out, or give a posterior sampled with it")


def _fit_noise(recording: Recording, model: PilotModel, seed, order, discard) -> ARNoise:
    """The AR model of a prediction-error fit of ``model`` (:func:`~bayespilot.fit.fast.fit_fast`)."""
    from .fit.fast import fit_fast

    fit = fit_fast(recording, model, seed=seed, noise="ar", noise_order=order, discard=discard)
    return ARNoise.from_dict(fit.settings["noise"])


@one_blas_thread
def compare(recording: Recording, model: PilotModel | None = None, *, likelihood: str = "eq4",
            ar: str = "fixed", ar_order: int | None = None, discard: float | None = None,
            nlive: int = 200, dlogz: float = 0.5, sample: str = "rwalk",
            runs: int = 2, seed: int | None = None, posterior: Any = None,
            savage_dickey_samples: bool = True, sample_options: Mapping[str, Any] | None = None,
            progress: bool = False) -> Comparison:
    """Compare the model with threshold against the same model without it.

    Parameters
    ----------
    recording : Recording
    model : PilotModel, optional
        The model with a free ``delta_abs`` (default: the paper's).  The model
        without threshold is the one the fitters use for ``threshold=False``:
        ``delta_abs`` held at 0 for a :class:`~bayespilot.model.DeadZone`
        (``model.fix(delta_abs=0)``, the paper's nested model); a threshold
        that is not the identity at ``delta_abs = 0`` (a
        :class:`~bayespilot.model.SoftDeadZone`) is removed, its other
        parameters (``w_soft``) with it.  The Savage-Dickey check is then
        marked not valid (the null is not ``delta_abs = 0`` of the model
        with threshold).
    likelihood : {"eq4", "coloured"}
    ar : {"fixed", "sampled"}, default "fixed"
        For ``"coloured"``: the AR model held fixed (one, from a
        prediction-error fit of the model with threshold, serves both
        models) or sampled with the pilot parameters, as in
        :func:`bayespilot.sample.sample`.  ``"profiled"`` (the default of
        :func:`~bayespilot.sample.sample`) is refused: the evidence needs a
        density to integrate.
    ar_order : int, optional
        For ``"coloured"``: the order of the AR model, as in
        :func:`bayespilot.sample.sample`.
    discard : float, optional
        Seconds at the start left out of the likelihood; default 0 for
        ``"eq4"``, :func:`~bayespilot.likelihood.coloured_discard` (min(2 s,
        a quarter of the record)) for ``"coloured"``; for ``"eq4"`` on a
        record not known to be a whole number of forcing periods,
        :func:`~bayespilot.likelihood.startup_discard` (2 s), as
        :func:`~bayespilot.fit.fast.fit_fast` does.
    nlive, dlogz, sample
        dynesty settings (:func:`nested_evidence`).
    runs : int
        Independent nested-sampling runs of the model with threshold, combined
        by :func:`robust_evidence` (the model without threshold runs once;
        see the module docs).
    seed : int, optional
        Seeds the nested-sampling runs (and the emcee run, if one is made).
        None draws one from fresh entropy; the seed used is recorded in the
        result (``seed``) and repeats the comparison.
    posterior : Posterior, optional
        An emcee posterior of ``model`` on this recording for the
        Savage-Dickey cross-check.  For ``"coloured"`` with ``ar="fixed"`` its
        AR model is used for the comparison too, but only if it was sampled
        with ``likelihood="coloured", ar="fixed"`` (it holds one,
        ``settings["noise"]``); a posterior sampled with ``ar="profiled"``
        (:func:`~bayespilot.sample.sample`'s default) or ``"sampled"`` has
        none, and the comparison fits its own.  It must have been sampled on
        this recording (``settings["recording_sha256"]``; one saved before that
        was recorded is used with a RuntimeWarning), of ``model``, and, under
        the same likelihood, with the same ``discard`` (and an AR model of
        ``ar_order``, if given); under the other likelihood its Savage-Dickey
        estimate is marked not valid.  If None and ``savage_dickey_samples``,
        one is sampled (:func:`bayespilot.sample.sample`, under the
        comparison's likelihood, ``sample_options`` passed on), started from
        the maximum-likelihood point with threshold
        (``information_criteria["ml_threshold"]``): the nested sampler's
        best point polished by bounded Gauss-Newton and a scan of delta_abs
        (left as it is with ``ar="sampled"``), or the maximum without
        threshold at delta_abs = 0 when that is higher.
    savage_dickey_samples : bool
        False: no Savage-Dickey unless ``posterior`` is given.
    sample_options : mapping, optional
        Extra keyword arguments of :func:`~bayespilot.sample.sample`.
    progress : bool

    Returns
    -------
    Comparison
        With the plateau guard (module docs) computed from the dead zone's
        input at the maximum-likelihood point with threshold
        (:func:`plateau_onset` with ``params``; a SoftDeadZone taken as a
        dead zone of its ``delta_abs``, stages with free parameters before it
        at their estimates).  Where it cannot be computed (``delta_abs`` on
        the output, on several channels, or on a block that is not a dead
        zone) ``plateau_probability`` is None, ``settings["plateau_guard"]``
        says "not applied: <reason>", the summary says so, and a "threshold"
        decision's ``decision_note`` is "plateau guard not applied: <reason>".

    Raises
    ------
    ValueError
        If the model has no free ``delta_abs``, bad settings, or a
        ``posterior`` sampled on another recording, of another model, or with
        another ``discard`` or AR order (the message says which).
    TypeError
        Wrong argument types.

    Warns
    -----
    RuntimeWarning
        A ``posterior`` saved before the recording's digest was recorded
        (whether it belongs to this recording cannot be checked), or nested
        sampling that missed the main mode in every run (named by the
        recording's ``source``).
    bayespilot.sample.ConvergenceWarning
        The posterior sampled for the Savage-Dickey check reached its
        ``max_steps`` before it converged: the check is rough (the summary
        says so too).  Other warnings of that sampling are warned again
        as they were, each once, at the line that called :func:`compare`.

    Examples
    --------
    >>> from bayespilot.simulate import simulate
    >>> rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.05, seed=1,
    ...                duration=10).recording
    >>> c = compare(rec, nlive=50, seed=0, savage_dickey_samples=False)  # doctest: +SKIP
    >>> c.decision  # doctest: +SKIP
    'threshold'
    """
    t0 = time.perf_counter()
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    model, order = likelihood_options(model, likelihood, ar, ar_order, EVIDENCE_AR_MODES)
    if discard is None:
        discard = _default_discard(recording, likelihood)
    if THRESHOLD not in model.parameter_names:
        raise ValueError(f"the model has no free {THRESHOLD!r} to compare against 0 "
                         f"(free: {', '.join(model.parameter_names)})")
    seed = resolve_seed(seed)  # None: a fresh one, recorded in the result
    runs = _check_int("runs", runs, 1)
    if sample_options is not None and not isinstance(sample_options, Mapping):
        raise TypeError("sample_options must be a mapping of keyword arguments of sample()")
    _check_sample_options(sample_options or {})
    # the threshold model's evidence needs the most live points: checked here, not after the
    # model without threshold has had its run
    nlive = _check_int("nlive", nlive, 2 * (model.n_free + order) + 2)
    if posterior is not None:
        from .sample import Posterior

        if not isinstance(posterior, Posterior):
            raise TypeError(f"posterior must be a bayespilot.sample.Posterior, got "
                            f"{type(posterior).__name__}")
        _check_posterior(posterior, recording, model, likelihood, ar, ar_order, discard)
    from .fit.three_step import _model_for

    none_model = _model_for(model, threshold=False)  # the threshold removed, not made soft
    # the model with threshold at the null: delta_abs = 0, unless the null removed a block (a
    # SoftDeadZone: no such point, the limit w -> 0) or held other thresholds at 0 too
    removed, zeroed = _null_differences(model, none_model)
    not_nested = "; ".join([*([f"it has no {', '.join(removed)}"] if removed else []),
                            *([f"it holds {', '.join(zeroed)} at 0 too"] if zeroed else [])])
    ss = np.random.SeedSequence(seed)
    s1, s0, s_mc = (int(s.generate_state(1)[0]) for s in ss.spawn(3))
    noise = None
    if likelihood == "coloured" and ar == "fixed":  # one noise model for both
        given = posterior.settings.get("noise") if posterior is not None else None
        if isinstance(given, Mapping) and posterior.settings.get("likelihood") == "coloured":
            noise = ARNoise.from_dict(given)  # the posterior's, so that all three agree
        else:
            noise = _fit_noise(recording, model, s_mc, ar_order, discard)
    lik_opts = dict(likelihood=likelihood, ar=ar, ar_order=ar_order, noise=noise, discard=discard)
    ev0 = evidence(recording, none_model, **lik_opts, nlive=nlive, dlogz=dlogz, sample=sample,
                   seed=s0, progress=progress)

    def run_threshold(attempt: int) -> Evidence:
        return evidence(recording, model, **lik_opts, nlive=nlive, dlogz=dlogz, sample=sample,
                        seed=s1 + attempt, progress=progress)

    ev1, reruns, mode_ok = robust_evidence(run_threshold, runs, ev0.max_log_lik)
    log_bf = ev1.log_z - ev0.log_z
    err = math.hypot(ev1.log_z_err, ev0.log_z_err)

    # maximum likelihood, for the information criteria
    nll1 = _NegLogLik(model, recording, order, noise, discard)
    nll0 = _NegLogLik(none_model, recording, order, noise, discard)
    v0, p0 = _ml(nll0, ev0.best, threshold=False)
    start1 = dict(ev1.best)
    v1, p1 = _ml(nll1, start1, threshold=True)
    nested_start = dict(p0, **{THRESHOLD: 0.0})
    for n in nll1.names:  # a parameter the null has not (w_soft): at its bound nearest to it
        nested_start.setdefault(n, model.parameter(n).lower)
    v_nested = nll1(np.array([nested_start[n] for n in nll1.names]))
    if v_nested < v1:  # the model with threshold contains the one without
        v1, p1 = _ml(nll1, nested_start, threshold=True)
        v1, p1 = min((v1, p1), (v_nested, nested_start), key=lambda t: t[0])
    ic = information_criteria(v1, v0, len(nll1.names) + 1, len(nll0.names) + 1, nll1.n)
    ic["ml_threshold"] = p1
    ic["ml_none"] = p0

    sd = None
    # (whether the Savage-Dickey posterior was given or sampled here, and its seed)
    post_info: dict[str, Any] = {} if posterior is None else {"given": True,
                                                              "seed": posterior.seed}
    if posterior is None and savage_dickey_samples:
        from .sample import ConvergenceWarning, sample as run_sample

        opts = {"max_steps": 5000, "min_steps": 500, "check_every": 250, "progress": progress}
        opts.update(sample_options or {})
        init = dict(p1)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            posterior = run_sample(recording, model, **lik_opts, init=init, seed=s_mc, **opts)
        post_info.update(given=False, seed=posterior.seed,
                         warnings=_reissue(caught, recording.source, opts["max_steps"]))
    if posterior is not None:
        sd = savage_dickey_from_posterior(posterior, model)
        if not_nested:
            sd = SavageDickey(None, False, f"the model without threshold is not the model with "
                              f"threshold at {THRESHOLD} = 0 ({not_nested}), so the posterior "
                              f"density there tests another null", None,
                              sd.prior_density, sd.posterior_density, sd.bandwidth, sd.n_draws,
                              sd.n_near)
        elif posterior.settings.get("likelihood") != likelihood:
            sd = SavageDickey(None, False, f"the posterior used the "
                              f"{posterior.settings.get('likelihood')!r} likelihood, the "
                              f"comparison {likelihood!r}", None, sd.prior_density,
                              sd.posterior_density, sd.bandwidth, sd.n_draws, sd.n_near)
        post_info.update({"converged": bool(posterior.converged),
                          "n_steps": posterior.settings.get("n_steps"),
                          "n_draws": int(posterior.draws(THRESHOLD).size)})
    settings = {"likelihood": likelihood, "ar": ar, "ar_order": order,
                "noise": None if noise is None else noise.to_dict(), "discard_seconds": discard,
                "nlive": nlive, "dlogz": dlogz,
                "sample": sample, "model": model.name, "decision_level": DECISION_LEVEL,
                "decision_z": DECISION_Z, "runs": runs, "n_samples": recording.n_samples,
                "posterior": post_info or None, "entropy": str(ss.entropy),
                "threshold_runs": reruns, "mode_check": bool(mode_ok),
                "recording": recording.source or "",
                "recording_sha256": _recording_digest(recording)}
    if not mode_ok:
        where = f"{recording.source}: " if recording.source else ""
        warn_at_caller(f"{where}the nested sampler's best ln L with threshold ({ev1.max_log_lik:.1f}) is "
                       f"below that without ({ev0.max_log_lik:.1f}) in all {len(reruns)} runs: "
                       "they missed the main mode, so ln BF is too low; rerun with more nlive",
                       RuntimeWarning)
    # the plateau: the dead zone's input at the maximum-likelihood point with threshold
    i, no_guard = _threshold_input(model, recording, p1)
    i_max = None if i is None else float(np.max(i))
    onset = None if i is None else float(np.quantile(i, 1.0 - PLATEAU_ACTIVE_FRACTION))
    plateau = None if onset is None else ev1.probability(THRESHOLD, onset)
    silent = _silent_threshold(nll1.lik)
    decision, why = _guarded_decision(log_bf, err, mode_ok, plateau, onset, silent)
    guard = "applied" if i is not None else f"not applied: {no_guard}"
    if i is None and decision == "threshold" and not why:
        # the guard would have had its say on this decision: the note says it had none
        why = f"plateau guard not applied: {no_guard}"
    settings.update(max_threshold_input=i_max, plateau_onset=onset,
                    plateau_active_fraction=PLATEAU_ACTIVE_FRACTION, decision_note=why,
                    threshold_identified=silent is None, plateau_guard=guard,
                    model_none=none_model.name, null_also_zeroes=zeroed)
    return Comparison(float(log_bf), float(err), decision, ev1, ev0, sd, ic, settings,
                      seed, time.perf_counter() - t0, recording.source, plateau)


def _null_differences(model: PilotModel, none_model: PilotModel
                      ) -> tuple[list[str], list[str]]:
    """How the model without threshold (``none_model``, :meth:`PilotModel.without_threshold`)
    differs from ``model`` at delta_abs = 0: the blocks it removed ("SoftDeadZone on
    vestibular") and the other thresholds it holds at 0 (names), each empty for the paper's
    model, whose null is exactly delta_abs = 0."""
    removed = [f"{type(c.nonlinearity).__name__} on {c.name}"
               for c, c0 in zip(model.channels, none_model.channels)
               if c.nonlinearity is not None and c0.nonlinearity is None]
    if model.output is not None and none_model.output is None:
        removed.append(f"{type(model.output).__name__} on the output")
    zeroed = sorted(k for k, v in none_model.fixed.items()
                    if k != THRESHOLD and model.fixed.get(k) != v)
    return removed, zeroed


def _reissue(caught, source: str | None, max_steps: int) -> list[str]:
    """The warnings recorded while :func:`compare` sampled the Savage-Dickey posterior,
    warned again at the user's line, each once; their texts, for ``settings["posterior"]``.

    A :class:`~bayespilot.sample.ConvergenceWarning` is worded for the comparison: the
    chain is the Savage-Dickey check's, and the comparison has no ``max_steps`` of its own
    (``sample_options`` has, and a converged ``posterior`` can be given instead).
    """
    from .sample import ConvergenceWarning

    texts: list[str] = []
    seen: set[tuple[type, str]] = set()
    for w in caught:
        message = w.message
        if issubclass(w.category, ConvergenceWarning):
            tau = getattr(message, "tau", None)
            finite = [] if tau is None else [t for t in np.ravel(tau) if np.isfinite(t)]
            where = f"{source}: " if source else ""
            message = ConvergenceWarning(
                f"{where}the posterior sampled for the Savage-Dickey check did not converge "
                f"(the chain reached max_steps = {max_steps} before it was long enough; max "
                f"tau = {max(finite) if finite else math.nan:.0f} steps): the Savage-Dickey "
                "ln BF is a rough check; to run longer, raise sample_options['max_steps'], "
                "or give a converged posterior (posterior=, or bayespilot compare "
                "--posterior POST.nc from bayespilot sample)",
                tau, getattr(message, "n_steps", 0))
        key = (type(message) if isinstance(message, Warning) else w.category, str(message))
        if key in seen:
            continue
        seen.add(key)
        texts.append(str(message))
        if isinstance(message, Warning):
            warn_at_caller(message)
        else:
            warn_at_caller(str(message), w.category)
    return texts


# --- pooling -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PooledComparison(SummaryHTML):
    """Threshold against none over recordings of one condition (see :func:`pool`).

    Attributes
    ----------
    n : int
        Number of recordings pooled.
    log_bayes_factor, log_bayes_factor_err : float
        Sum of the per-recording ln BF, errors in quadrature.
    decision : str
        :func:`decide` on the sum over the recordings that identify the
        threshold (``decided_log_bayes_factor``: all of them, unless some
        have no input to its channel), with the guards of :func:`compare`: a
        "threshold" must also hold on the sum over the recordings whose
        ``plateau_probability`` is at most :data:`PLATEAU_LEVEL`, and a
        "none" on the sum over those whose nested sampling kept the main
        mode; otherwise "inconclusive".
    decisions : dict
        Count of per-recording decisions.
    mean_log_bayes_factor : float
        Mean of the per-recording ln BF.
    t_statistic, t_pvalue : float
        One-sample t-test of the per-recording ln BF against 0 (= paired
        t-test of ln Z with against without threshold); NaN for n < 2 or when
        every ln BF is the same (no spread to test against).
    wilcoxon_statistic, wilcoxon_pvalue : float
        Wilcoxon signed-rank test of the same; NaN for n < 2 or when every
        ln BF is 0.
    label : str
        The condition's name, e.g. ``"FD, K_theta = 1"``.
    decision_note : str
        Why a guard changed the decision ("" if none did).
    n_unidentified : int
        Recordings that do not identify the threshold (its channel has no
        input: ``settings["threshold_identified"]`` False): left out of the
        decision, which is "inconclusive" when none is left (0 in files
        written before).
    decided_log_bayes_factor, decided_log_bayes_factor_err : float
        The sum the decision is made on: over the recordings that identify
        the threshold (the same as ``log_bayes_factor`` when all do; NaN when
        none does, and in files written before).
    likelihood : str
        The pooled comparisons' likelihood (``settings["likelihood"]``):
        ``"eq4"`` or ``"coloured"``, ``"mixed"`` when they differ, ``""``
        when none records it (and in files written before).  Under Eq. 4 the
        summary says that its ln BF, and so their sum, is inflated.
    """

    n: int
    log_bayes_factor: float
    log_bayes_factor_err: float
    decision: str
    decisions: dict[str, int]
    mean_log_bayes_factor: float
    t_statistic: float
    t_pvalue: float
    wilcoxon_statistic: float
    wilcoxon_pvalue: float
    label: str = ""
    decision_note: str = ""
    n_unidentified: int = 0
    decided_log_bayes_factor: float = math.nan
    decided_log_bayes_factor_err: float = math.nan
    likelihood: str = ""

    def to_dict(self) -> dict[str, Any]:
        """Every attribute by name (:func:`dataclasses.asdict`)."""
        return asdict(self)

    def to_json(self, path: str | os.PathLike | None = None) -> str | Path:
        """The :meth:`to_dict` as JSON text, or written to ``path`` (parents created).

        Non-finite numbers (a NaN p-value) are written as null (NaN again
        after :meth:`from_json`).

        Parameters
        ----------
        path : str or os.PathLike, optional
            The file to write; an existing one is replaced only once the new
            one is written.  None: return the text.

        Returns
        -------
        str or Path
            The JSON text, or ``path`` when given.
        """
        text = dumps(self.to_dict())
        return text if path is None else write_text_atomic(path, text)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "PooledComparison":
        """The pooled comparison a :meth:`to_dict` holds (a null number is NaN).

        Parameters
        ----------
        d : mapping
            A :meth:`to_dict`, as read from JSON; keys that are not
            attributes are ignored.

        Returns
        -------
        PooledComparison

        Raises
        ------
        ValueError
            ``d`` lacks an attribute without a default: another kind of result.
        """
        require_keys(d, (f.name for f in fields(cls)
                         if f.default is MISSING and f.default_factory is MISSING),
                     "a pooled comparison")
        return cls(**nan_for_null(cls, {k: d[k] for k in (f.name for f in fields(cls))
                                       if k in d}))

    @classmethod
    def from_json(cls, path: str | os.PathLike) -> "PooledComparison":
        """The pooled comparison a :meth:`to_json` file holds.

        Parameters
        ----------
        path : str or os.PathLike
            The JSON file.

        Returns
        -------
        PooledComparison

        Raises
        ------
        FileNotFoundError
            No file at ``path``.
        ValueError
            The file is not JSON, or not a pooled comparison's (the message
            names it).
        """
        return read_result(path, cls.from_dict, "a PooledComparison")

    def __str__(self) -> str:
        return self.summary()

    def __repr__(self) -> str:
        """One line: the condition, the number of recordings, the sum ln BF and the decision."""
        return (f"<PooledComparison: {self.label + ', ' if self.label else ''}{self.n} "
                f"recordings, sum ln BF = {_num(self.log_bayes_factor, '+.2f')} +- "
                f"{_num(self.log_bayes_factor_err, '.2f')} -> {self.decision}>")

    def summary(self) -> str:
        """One line for people: the sum ln BF and decision, the per-recording counts, the tests;
        under Eq. 4 a second, :data:`EQ4_COMPARISON_NOTE` (a sum of inflated ln BFs decided
        'threshold' on 20 held-out recordings without one: docs/comparison.md)."""
        counts = ", ".join(f"{k} {self.decisions.get(k, 0)}" for k in DECISIONS)
        lbf, err = self.log_bayes_factor, self.log_bayes_factor_err
        head = f"sum ln BF = {lbf:+.2f} +- {err:.2f} "
        if 0 < self.n_unidentified < self.n:  # (the decision's sum: the others')
            lbf, err = self.decided_log_bayes_factor, self.decided_log_bayes_factor_err
            head += (f"({self.n_unidentified} without input to {THRESHOLD}'s channel left "
                     f"out: {lbf:+.2f} +- {err:.2f} over the other "
                     f"{self.n - self.n_unidentified}) ")
        return (f"{self.label + ': ' if self.label else ''}{self.n} "
                f"recording{'' if self.n == 1 else 's'}, " + head
                + _verdict(lbf, err, self.decision, self.decision_note,
                           identified=self.n_unidentified < self.n)
                + f"; per recording: {counts}; " + self._tests()
                + (f"\n  {EQ4_COMPARISON_NOTE}" if self.likelihood in ("eq4", "mixed") else ""))

    def _tests(self) -> str:
        """The paired tests for :meth:`summary`, or why there are none."""
        if self.n < 2:
            return "no paired test (one recording: no spread across recordings to test)"
        if math.isnan(self.t_pvalue) and math.isnan(self.wilcoxon_pvalue):
            return "no paired test (every recording has ln BF = 0)"
        t = (f"paired t = {self.t_statistic:.2f} (p = {self.t_pvalue:.3g})"
             if not math.isnan(self.t_pvalue) else
             "no paired t-test (every recording has the same ln BF: no spread)")
        return f"{t}, Wilcoxon p = {self.wilcoxon_pvalue:.3g}"


def pool(results: Sequence[Comparison | Mapping[str, Any]], *, label: str = "") -> PooledComparison:
    """Pool per-recording comparisons of one condition.

    Parameters
    ----------
    results : sequence of Comparison or of their ``to_dict()``
    label : str
        A name for the condition, e.g. ``"FD, K_theta = 1"``.

    Returns
    -------
    PooledComparison

    Raises
    ------
    ValueError
        ``results`` is empty, holds one Comparison twice, or two comparisons
        of the same recording (by ``settings["recording_sha256"]``, recorded
        by :func:`compare`): each recording counts once.  Or two comparisons test
        different hypotheses (``settings["model"]``, ``"model_none"`` or
        ``"null_also_zeroes"`` differ): a pool sums the ln BFs of one test.
    TypeError
        A result is neither a Comparison nor a mapping with
        ``log_bayes_factor``.

    Notes
    -----
    One recording has no spread across recordings: its t and Wilcoxon tests
    are NaN, and :meth:`PooledComparison.summary` says "no paired test"
    instead of printing them.  A recording that does not identify the
    threshold (``settings["threshold_identified"]`` False: no input to its
    channel, so that its ln BF is sampling noise) is in the sum and the
    tests but not in the decision (``n_unidentified``,
    ``decided_log_bayes_factor``); with none left the decision is
    "inconclusive".

    Examples
    --------
    >>> r = [{"log_bayes_factor": v, "log_bayes_factor_err": 0.5} for v in (5.0, 7.0, 6.0)]
    >>> p = pool(r)
    >>> p.log_bayes_factor, p.decision
    (18.0, 'threshold')
    """
    from scipy import stats

    if isinstance(results, (Comparison, Mapping)) or not len(results):
        raise ValueError("results must be a non-empty sequence of comparisons")
    lbf, err, dec, on_plateau, lost_mode, unidentified = [], [], [], [], [], []
    likelihoods: set[str] = set()
    first_of: dict[Any, int] = {}  # a Comparison (by identity) or a recording's digest: index
    tests: list[tuple[dict[str, Any], int]] = []  # each recorded test, with its index
    for i, r in enumerate(results):
        d = r.to_dict() if isinstance(r, Comparison) else r
        if not isinstance(d, Mapping) or "log_bayes_factor" not in d:
            raise TypeError("each result must be a Comparison or a mapping with "
                            "'log_bayes_factor' and 'log_bayes_factor_err'")
        _check_once(i, r, d, first_of, results)
        _check_same_test(i, d, tests, results)
        lbf.append(float(d["log_bayes_factor"]))
        err.append(float(d.get("log_bayes_factor_err", 0.0)))
        settings = d.get("settings") or {}
        if settings.get("likelihood"):
            likelihoods.add(str(settings["likelihood"]))
        unidentified.append(settings.get("threshold_identified") is False)
        dec.append(d.get("decision") or ("inconclusive" if unidentified[-1]
                                         else decide(lbf[-1], err[-1])))
        pp = d.get("plateau_probability")
        on_plateau.append(pp is not None and pp > PLATEAU_LEVEL)
        lost_mode.append(settings.get("mode_check") is False)
    x = np.array(lbf)
    total, total_err = float(x.sum()), float(math.sqrt(np.sum(np.square(err))))
    t = p = w = wp = math.nan
    if x.size >= 2:
        if np.ptp(x) > 0:
            t, p = (float(v) for v in stats.ttest_1samp(x, 0.0))
        if np.any(x != 0):
            wres = stats.wilcoxon(x)
            w, wp = float(wres.statistic), float(wres.pvalue)
    counts = {k: int(sum(1 for d in dec if d == k)) for k in DECISIONS}
    # a recording without input to the threshold's channel says nothing about it (its ln BF
    # is sampling noise, the two models being the same there): left out of the decision
    ident = ~np.array(unidentified)

    def on(keep: Any) -> tuple[float, float]:
        k = np.asarray(keep) & ident
        return float(x[k].sum()), float(math.sqrt(np.sum(np.square(np.array(err)[k]))))

    def holds(keep: list[bool]) -> bool:
        return bool((np.array(keep) & ident).any()) and decide(*on(keep)) == decision

    n_out, n_in = int((~ident).sum()), int(ident.sum())
    decided = on(ident) if n_in else (math.nan, math.nan)
    note = ""
    if not n_in:
        decision, note = "inconclusive", (f"{THRESHOLD} is not identified in any of the "
                                          f"{x.size} recordings (its channel has no input): "
                                          "the two models are the same on them")
    else:
        decision = decide(*decided)
    plateau_in = int(sum(np.array(on_plateau) & ident))
    lost_in = int(sum(np.array(lost_mode) & ident))
    if decision == "threshold" and plateau_in and not holds([not v for v in on_plateau]):
        decision, note = "inconclusive", (f"{plateau_in} of {n_in} recordings favour the "
                                          "threshold through the plateau (motion channel off or "
                                          "passing under 1 % of the samples); the others do not "
                                          "decide for it")
    elif decision == "none" and lost_in and not holds([not v for v in lost_mode]):
        decision, note = "inconclusive", (f"in {lost_in} of {n_in} recordings nested "
                                          "sampling lost the main mode; the others do not decide "
                                          "for 'none'")
    likelihood = (likelihoods.pop() if len(likelihoods) == 1 else
                  "mixed" if likelihoods else "")
    return PooledComparison(int(x.size), total, total_err, decision, counts,
                            float(x.mean()), t, p, w, wp, label, note, n_out, *decided,
                            likelihood=likelihood)


def _result_name(results: Sequence[Any], k: int) -> str:
    """How pool's messages name ``results[k]``: "results[k]", with its source if it has one."""
    r = results[k]
    src = r.source if isinstance(r, Comparison) else r.get("source")
    return f"results[{k}]" + (f" ({src})" if src else "")


def _check_once(i: int, r: Any, d: Mapping[str, Any], first_of: dict[Any, int],
                results: Sequence[Any]) -> None:
    """Refuse (ValueError) ``results[i]`` if an earlier result is the same Comparison object
    or a comparison of the same recording (by ``settings["recording_sha256"]``): a pool
    counts each recording once.  Records ``r`` in ``first_of``."""
    def name(k: int) -> str:
        return _result_name(results, k)

    if isinstance(r, Comparison):
        if ("object", id(r)) in first_of:
            raise ValueError(f"results[{first_of['object', id(r)]}] and results[{i}] are the "
                             f"same Comparison{f' (of {r.source})' if r.source else ''}: a pool "
                             "counts each recording once; give each comparison once")
        first_of["object", id(r)] = i
    settings = d.get("settings")
    digest = settings.get("recording_sha256") if isinstance(settings, Mapping) else None
    if digest:
        if ("recording", digest) in first_of:
            j = first_of["recording", digest]
            raise ValueError(f"{name(j)} and {name(i)} are comparisons of the same recording "
                             f"(recording_sha256 {digest[:12]}...): a pool counts each "
                             "recording once; keep one of them")
        first_of["recording", digest] = i


def _check_same_test(i: int, d: Mapping[str, Any], tests: list[tuple[dict[str, Any], int]],
                     results: Sequence[Any]) -> None:
    """Refuse (ValueError) ``results[i]`` if it tests the threshold of another model, or
    against another null, than an earlier comparison (``tests``: each that records its test,
    with its index; ``results[i]``'s is added): a pool sums ln BFs of one hypothesis.  A
    comparison records its ``settings["model"]``, ``"model_none"`` and
    ``"null_also_zeroes"`` (the other thresholds its null holds at 0); each pair is compared
    on what both record (an older one, its model alone), and one that records none (a
    hand-made mapping) is not checked."""
    settings = d.get("settings")
    if not isinstance(settings, Mapping):
        return
    test = {k: settings[k] for k in ("model", "model_none") if settings.get(k) is not None}
    if settings.get("model_none") is not None or "null_also_zeroes" in settings:
        test["null_also_zeroes"] = sorted(settings.get("null_also_zeroes") or [])
    if not test:
        return
    for ref, j in tests:
        if not any(test[k] != ref[k] for k in test if k in ref):
            continue
        def what(t: Mapping[str, Any]) -> str:
            also = t.get("null_also_zeroes") or []
            null = f" against {t['model_none']!r}" if t.get("model_none") else ""
            return (f"model {t.get('model')!r}{null}"
                    + (f" (its null also holds {', '.join(also)} at 0)" if also else ""))

        raise ValueError(f"{_result_name(results, j)} tests {what(ref)} but "
                         f"{_result_name(results, i)} tests {what(test)}: a "
                         "pool sums the ln BFs of one hypothesis; pool the comparisons of "
                         "each model apart")
    tests.append((test, i))


class _CallableModule(types.ModuleType):
    """This module, callable: ``bayespilot.compare(...)`` is :func:`compare`."""

    def __call__(self, *args, **kwargs):
        return compare(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule

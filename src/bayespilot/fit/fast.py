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
4. Gauss-Newton with delta_abs free from there (``joint_refine``); its end is
   taken if it is more than ``CHECK_GAP`` (1.92) better in -ln L, where a
   ridge narrower than the grids was missed (little remnant);
   ``steps["joint"]`` records it.

Because the profile contains delta_abs = 0 (the model without threshold) and
the final answer is the best point of steps 2-3 (or step 4's end, when taken),
a fit with threshold is never worse than the fit without one.  Step 4's end is
taken only beyond ``CHECK_GAP``, the drop of -ln L at the edge of a 95 %
profile interval: closer than that the two points are inside each other's
interval, and the estimate stays the grids' (which keeps it from hanging on a
Gauss-Newton step across the dead zone's kink).

With ``noise="ar"`` the fit is a prediction-error fit (:mod:`bayespilot.noise`):
after the multi-start of step 1 on Eq. 4, an AR model of that fit's residual
(order by BIC) whitens the residual, step 1 is repeated from the same starts
and from the Eq. 4 optimum on the whitened likelihood, steps 2-4 follow on
it, and the AR model is re-estimated once at the end and the parameters
refined with it.  In closed loop this removes the bias of the output-error
fit (measured in ``docs/posteriors.md``); it costs about twice the time.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.stats import qmc

from ..likelihood import (Likelihood, _checked_discard, _coloured_default, _startup_default,
                          _startup_reason)
from ..model import PilotModel
from ..noise import MAX_AR_ORDER, ARNoise
from ..recording import Recording, _recording_digest
from .gauss_newton import joint_refine, refine
from .result import CHECK_GAP, FitResult
from .scan import scan_parameter
from .three_step import (_check_bool, _check_fittable, _check_steps, _model_for,
                         _refuse_unstable_everywhere, _unidentified_settings, _warn_on_bounds)
from .._blas import one_blas_thread
from .._seeds import resolve_seed

__all__ = ["fit_fast"]


@one_blas_thread
def fit_fast(recording: Recording, model: PilotModel | None = None, *, threshold: bool = True,
             seed: int | None = None, n_starts: int = 8, profile_step: float = 0.0025,
             scan_step: float = 1e-4, initial: str = "periodic",
             discard: float | None = None, noise: ARNoise | str | None = None,
             noise_order: int | None = None) -> FitResult:
    """Fit by multi-start Gauss-Newton and a profile over delta_abs (see module docs).

    Parameters
    ----------
    recording : Recording
    model : PilotModel, optional
    threshold : bool
        False fits the model without threshold
        (:meth:`~bayespilot.model.PilotModel.without_threshold`: delta_abs = 0
        for the paper's dead zone; a soft dead zone removed with its w_soft);
        a ``model`` without a threshold has none either way.  True or False only (a
        string such as ``"no"`` is refused, not taken for its truth value).
    seed : int, optional
        Seeds the Latin-hypercube starts; the same seed gives the same fit.
        None draws one from fresh entropy; the seed used is
        recorded in the result (``seed``) and repeats the run.
    n_starts : int
        Starting points of the threshold-free fit.
    profile_step : float
        Coarse grid step of the delta_abs profile, IPUT: positive and at most
        the range of delta_abs's bounds (0.1 in Table 1).
    scan_step : float
        Final scan resolution, IPUT: positive and at most ``profile_step``
        (the scan spans one profile step either side of the profile's best
        point).
    initial : {"periodic", "rest"}
    discard : float, optional
        Seconds at the start left out of the likelihood
        (:class:`~bayespilot.likelihood.Likelihood`).  Default: 0 for the
        white output error, :func:`~bayespilot.likelihood.coloured_discard`
        (min(2 s, a quarter of the record), as
        :func:`~bayespilot.sample.sample` and
        :func:`~bayespilot.compare.evidence` leave out with
        ``likelihood="coloured"``) with an AR noise model, whose whitening
        filter would otherwise
        amplify the model's start-up transient (from 0 s, a prediction-error
        fit of an 81.92-s FD run ended at T_vl 0.007 and tau_v 0.030 against
        the truth's 0.409 and 0.279).  With the white output error and
        ``initial="periodic"``, a record not known to be a whole number of
        forcing periods (:func:`~bayespilot.likelihood.whole_periods` False,
        e.g. a 40-s run of the paper's 81.92-s forcing, or None: no forcing
        in the sidecar, no f_t or f_d column) gets
        :func:`~bayespilot.likelihood.startup_discard` (2 s) too, and
        ``settings["discard_reason"]`` says why: from 0 s the periodic start
        wraps the cut, which took a remnant-free 40-s FT fit to K_v +6 %,
        T_vl -10 %, zeta_nm +11 %.  Records of whole periods keep 0.
    noise : None, "ar" or ARNoise
        The output-error model: None, white (Eq. 4, the paper's); ``"ar"``, an
        AR model estimated from the data (see module docs); or a given
        :class:`~bayespilot.noise.ARNoise`, held fixed.
    noise_order : int, optional
        Order of the ``"ar"`` model (default: chosen by BIC up to
        :data:`~bayespilot.noise.MAX_AR_ORDER`).

    Returns
    -------
    FitResult

    Raises
    ------
    TypeError
        ``recording`` is not a Recording, or ``model`` not a PilotModel.
    ValueError
        A bad setting (``threshold`` not a bool, ``n_starts``, the steps,
        ``discard`` outside [0, half the record], ``noise``, ``noise_order``
        without ``noise="ar"``), or a recording with no more than four samples
        per free parameter after ``discard`` or a constant u, or (``noise="ar"``)
        fewer than 4 (p + 1) samples after ``discard`` for the AR(p) model (p up
        to :data:`~bayespilot.noise.MAX_AR_ORDER` by BIC: 124 samples); the
        recording's problems are a :class:`~bayespilot.recording.RecordingError`
        naming the shortest record that would do.  Also when no start gave a
        finite likelihood (every Latin-hypercube start and its refinement made
        the closed loop or a block unstable: check the blocks' bounds).

    Warns
    -----
    EstimateOnBoundWarning
        A parameter other than delta_abs ended on a bound of its search box
        (:attr:`~bayespilot.fit.result.FitResult.at_bounds`), when called from
        outside the package.
    QuestionableRecordingWarning
        The mean of u over the fitted samples is more than
        :data:`~bayespilot.fit.three_step.OFFSET_RATIO` of its standard
        deviation (a stick offset; u is taken as zero-mean about the trim).
    UserWarning
        The model has a free dead-zone threshold not named ``delta_abs``: it
        is fitted as an ordinary parameter, without the threshold profile.

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
    threshold = _check_bool("threshold", threshold)
    if not (noise is None or noise == "ar" or isinstance(noise, ARNoise)):
        raise ValueError(f"noise must be None, 'ar' or an ARNoise, got {noise!r}")
    if noise_order is not None and (isinstance(noise_order, bool)
                                    or not isinstance(noise_order, (int, np.integer))
                                    or not 0 <= noise_order <= MAX_AR_ORDER):
        raise ValueError(f"noise_order must be an integer in [0, {MAX_AR_ORDER}], "
                         f"got {noise_order!r}")
    if noise_order is not None and noise != "ar":
        raise ValueError(f"noise_order is the order of the AR model that noise='ar' estimates; "
                         f"with noise={'None' if noise is None else 'an ARNoise'} it has none "
                         f"(got noise_order={noise_order!r})")
    seed = resolve_seed(seed)  # None: a fresh one, recorded in the result
    discard_reason = None  # why the default discard is not 0 where it was picked for that
    default_discard = discard is None
    if discard is None:
        discard = 0.0 if noise is None else _coloured_default(recording.duration)
        if discard == 0.0:
            # a record cut mid-period (or not known to be whole): the periodic start wraps the cut
            # (NotWholePeriodsWarning); 0 on whole periods, as before
            discard = _startup_default(recording, initial)
            if discard:
                discard_reason = _startup_reason(recording)
    t0 = time.perf_counter()
    model = _model_for(model, threshold)
    _check_steps(model, profile_step=profile_step, scan_step=scan_step)
    if scan_step > profile_step:
        raise ValueError(f"scan_step must not exceed profile_step ({profile_step!r}), got "
                         f"{scan_step!r}: the final scan refines the profile's best point "
                         f"within one profile step either side")
    discard = _checked_discard(recording, discard)
    _check_fittable(recording, model, discard)
    if noise == "ar":
        _check_ar_fittable(recording, discard, noise_order, default_discard)
    has_delta = "delta_abs" in model.parameter_names
    base = model._fixed(delta_abs=0.0) if has_delta else model
    given = noise if isinstance(noise, ARNoise) else None
    lik0 = Likelihood(base, recording, initial=initial, discard=discard, noise=given)
    lo, hi = base.bounds
    starts = qmc.scale(qmc.LatinHypercube(d=lo.size, seed=seed).random(n_starts), lo, hi)
    runs = [refine(lik0, base.as_dict(x), hold=(), bounded=True) for x in starts]
    best0 = min(runs, key=lambda r: r.neg_log_lik)
    _refuse_unstable_everywhere(base, float(best0.neg_log_lik),
                                f"{n_starts} Latin-hypercube start{'' if n_starts == 1 else 's'}"
                                " and their refinements")
    stages = {"starts": [r.to_dict() for r in runs]}
    if noise == "ar":
        # Prediction error: whiten by an AR model of the Eq. 4 fit's residual and start again
        # (the Eq. 4 optimum can sit in another basin of the delays, e.g. tau_m).
        given = _ar_at(lik0, best0.params, noise_order)
        lik0 = Likelihood(base, recording, initial=initial, discard=discard, noise=given)
        runs = [refine(lik0, base.as_dict(x), hold=(), bounded=True)
                for x in [*starts, base.free_vector(best0.params)]]
        best0 = min(runs, key=lambda r: r.neg_log_lik)
        stages["starts_whitened"] = [r.to_dict() for r in runs]
    settings = {"n_starts": n_starts, "initial": initial, "discard": discard,
                "model": model.name, "noise": None if given is None else given.to_dict(),
                "recording_sha256": _recording_digest(recording)}
    if discard_reason is not None:
        settings["discard_reason"] = discard_reason
    if not has_delta:
        p, f = best0.params, best0.neg_log_lik
        if noise == "ar":
            p, f, given = _final_ar(base, recording, initial, discard, p, noise_order)
            settings["noise"] = given.to_dict()
        full = model.as_dict(model.full_vector(p), full=True)
        _unidentified_settings(settings, lik0)
        fit = FitResult(full, f, lik0.vaf(p), "fast", seed, model.has_threshold, settings,
                        stages, time.perf_counter() - t0, recording.source,
                        **FitResult._declared(model))
        _warn_on_bounds(fit, lik0)
        return fit

    lik = Likelihood(model, recording, initial=initial, discard=discard, noise=given)
    upper = model.parameter("delta_abs").upper
    # a step that does not divide the bound: no grid point beyond the bound (the last is the
    # bound itself when the remainder is at least half a step; the final scan reaches it)
    grid = np.unique(np.minimum(np.arange(0.0, upper + 0.5 * profile_step, profile_step),
                                upper))
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
    # The grids can miss a ridge in delta_abs narrower than their steps: with little remnant
    # (an audit: noise-free FD at half the motion, delta_abs 0.0046 against 0.00375 and -ln L
    # 15256 above the joint maximum; F_n 0.05: 8.4 above).  Gauss-Newton with delta_abs free
    # from here finds it; its end is taken only beyond CHECK_GAP, so that on an ordinary record
    # the estimate stays the scan's (F_n 0.2: gaps of 0.001-0.07).
    joint = joint_refine(lik, params, fun)
    if joint is not None and joint["gap"] > CHECK_GAP:
        params, fun = joint["params"], joint["neg_log_lik"]
    stages["joint"] = joint
    if noise == "ar":
        params, fun, given = _final_ar(model, recording, initial, discard, params, noise_order)
        settings["noise"] = given.to_dict()
    stages.update({"profile_grid": grid.tolist(),
                   "profile_neg_log_lik": [p.neg_log_lik for p in prof],
                   "scan": sc.to_dict()})
    full = model.as_dict(model.full_vector(params), full=True)
    settings.update({"profile_step": profile_step, "scan_step": scan_step})
    _unidentified_settings(settings, lik)
    fit = FitResult(full, float(fun), lik.vaf(params), "fast", seed, True, settings, stages,
                    time.perf_counter() - t0, recording.source, **FitResult._declared(model))
    _warn_on_bounds(fit, lik)
    return fit


def _check_ar_fittable(recording: Recording, discard: float, order: int | None,
                       default_discard: bool) -> None:
    """Refuse (RecordingError), before fitting, a record too short for the AR noise model of
    ``noise="ar"``: an AR(p) model needs at least 4 (p + 1) residuals after ``discard``, with p
    up to :data:`~bayespilot.noise.MAX_AR_ORDER` when the order is chosen by BIC.  The message
    names the shortest record that has them (with the default lead-in,
    :func:`~bayespilot.likelihood.coloured_discard`, when ``default_discard``)."""
    from ..recording import RecordingError

    p = MAX_AR_ORDER if order is None else int(order)
    need = 4 * (p + 1)
    rate = recording.sample_rate_hz

    def skipped(n: int) -> int:
        d = _coloured_default(n / rate) if default_discard else discard
        return int(round(d * rate)) if d else 0

    have = recording.n_samples - skipped(recording.n_samples)
    if have >= need:
        return
    n = need
    while n - skipped(n) < need:
        n += 1
    what = (f"an AR noise model of order up to {p} (chosen by BIC)" if order is None
            else f"an AR({p}) noise model")
    raise RecordingError(
        f"{recording.source or 'the recording'}: {recording.duration:g} s, {have} samples"
        f"{f' after the first {discard:g} s' if skipped(recording.n_samples) else ''}; "
        f"{what} needs at least {need} there, a record of at least {n / rate:g} s"
        + ("" if default_discard else f" with the first {discard:g} s left out"))


def _ar_at(lik: Likelihood, params, order: int | None) -> ARNoise:
    """The AR model (order by BIC unless given) of the output error at ``params``."""
    eps = lik.residual(params)[lik.used]
    return ARNoise.from_residual(eps, order=order)


def _final_ar(model: PilotModel, recording: Recording, initial: str, discard: float, params,
              order: int | None):
    """Re-estimate the AR model at ``params`` and refine the pilot parameters with it held.

    Returns (params, -ln L, noise); -ln L is on the final noise model's likelihood.
    """
    white = Likelihood(model, recording, initial=initial, discard=discard)
    noise = _ar_at(white, params, order)
    lik = Likelihood(model, recording, initial=initial, discard=discard, noise=noise)
    r = refine(lik, params, bounded=True)
    return dict(r.params), float(r.neg_log_lik), noise

"""The paper's three-step maximum-likelihood fit (Section III.A, Fig. 5 of Pool et al. 2012).

Step I   genetic algorithm on all parameters within the Table 1 bounds, run
         ``repetitions`` times; the Step I delta_abs is the mean over the
         ``n_best`` runs with the lowest -ln L (:func:`bayespilot.fit.genetic.step_one`).
Step II  every Step I result is refined by unconstrained Gauss-Newton with
         delta_abs held at the Step I estimate (:func:`bayespilot.fit.gauss_newton.refine`);
         the lowest -ln L is kept.
Step III -ln L over delta_abs on [0, 0.1] with the Step II parameters fixed;
         the minimiser is the final delta_abs (:func:`bayespilot.fit.scan.scan_parameter`).
         With ``iterate=True`` Steps II and III repeat until nothing changes.

Without threshold the same procedure runs on the model without threshold
(:meth:`~bayespilot.model.PilotModel.without_threshold`: the paper's with delta_abs
fixed at 0; Step III is then empty).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..likelihood import (Likelihood, _checked_discard, _startup_default, _startup_reason,
                          _unidentified)
from ..model import PilotModel, paper_model
from ..recording import OFFSET_RATIO as _OFFSET_RATIO, Recording, _recording_digest
from .gauss_newton import joint_refine, refine
from .result import CHECK_GAP, FitResult, NotAtMaximumWarning
from .scan import scan_parameter
from .._blas import one_blas_thread
from .._seeds import resolve_seed

__all__ = ["fit_paper"]


def _model_for(model: PilotModel | None, threshold: bool) -> PilotModel:
    """The model a fit with or without threshold fits: ``model`` (default the paper's), or
    without threshold :meth:`~bayespilot.model.PilotModel.without_threshold` (a dead zone's
    ``delta_abs`` held at 0, the paper's construction; another threshold nonlinearity, as
    a soft dead zone, removed with its own parameters)."""
    if model is None:
        return paper_model(threshold=threshold)
    if not isinstance(model, PilotModel):
        raise TypeError(f"model must be a PilotModel, got {type(model).__name__}")
    if not threshold:
        return model.without_threshold()
    return model


def _refuse_unstable_everywhere(model: PilotModel, fun: float, tried: str) -> None:
    """Raise ValueError if ``fun``, the best -ln L a fitter found, is not finite: every
    parameter vector it tried (``tried``, e.g. "8 Latin-hypercube starts") made the closed loop
    or a block unstable (-ln L = +inf), and a FitResult of random parameters at -ln L = inf
    would be returned without a word.  The message names the stage and H_nm parameters whose
    bounds reach below 0 (a time constant, frequency or damping of the wrong sign), the
    usual cause."""
    if math.isfinite(fun):
        return
    blocks = [st for c in model.channels for st in c.stages]
    names = [model.omega_nm, model.zeta_nm] + [n for st in blocks for n in st.parameters]
    below = [f"{p.name} in [{p.lower:g}, {p.upper:g}]" for p in model.parameters
             if p.name in names and p.name in model.parameter_names and p.lower < 0]
    hint = (f" ({'; '.join(below)}: a time constant, frequency or damping below 0 is an "
            "unstable block)" if below else "")
    raise ValueError(f"no start gave a finite likelihood: every parameter vector tried "
                     f"({tried}) made the closed loop or a block of {model.name!r} unstable "
                     f"(-ln L = +inf); check the blocks' bounds{hint}")


def _check_bool(name: str, value: Any) -> bool:
    """``value`` as a bool, or a ValueError naming ``name``: True or False only (numpy's too),
    since a string such as ``"no"`` or ``"False"`` has the truth value True."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def _check_steps(model: PilotModel, **steps: Any) -> None:
    """Refuse (ValueError, naming the setting and its value) a delta_abs grid step that is not
    a positive number, or that exceeds the range of delta_abs's bounds: a grid over [lower,
    upper] in such steps holds at most its ends (over twice the range, the single point
    ``lower``: delta_abs = 0, "no threshold", whatever the data say), so that the scan and
    the fast method's profile say nothing about the threshold.  Only the positivity
    check for a model without delta_abs."""
    declared = {p.name: p for p in model.parameters}
    par = declared.get("delta_abs")
    for name, v in steps.items():
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                or not v > 0:
            raise ValueError(f"{name} must be a positive number, got {v!r}")
        if par is not None and v > par.upper - par.lower:
            raise ValueError(f"{name} must not exceed the range of delta_abs's bounds "
                             f"([{par.lower:g}, {par.upper:g}]: {par.upper - par.lower:g}), got "
                             f"{v!r}: a grid over them in such steps has no point inside them")


def _too_short_for_delays(model: PilotModel, recording: Recording,
                          params: Mapping[str, float] | None = None) -> str | None:
    """Why ``recording`` is too short for ``model``'s delays, or None: the one rule, used by
    the fitters (:func:`_check_fittable`) and the command line's ``loglik``.

    The likelihood needs each channel's time delay to be shorter than the record by more
    than ``kernels._response.DELAY_MARGIN`` (4) samples (at the channel's rate: the
    recording's, times its ``oversample``); otherwise -ln L is +inf, as for an unstable
    model.  With ``params`` (values by name) the delays are those values; with None each
    free delay is taken at the larger magnitude of its bounds, the furthest a fit may take
    it (a fixed one at its value): a record too short there leaves part of the search box at
    +inf, and starts there never leave it.
    """
    from ..kernels._response import DELAY_MARGIN  # (the kernel's own rule)

    at_bound = params is None
    values = model.as_dict(model.full_vector(params), full=True)
    dt = recording.dt
    n = recording.n_samples
    for ch in model.channels:
        if at_bound and ch.delay not in model.fixed:
            par = model.parameter(ch.delay)
            tau = max(abs(float(par.lower)), abs(float(par.upper)))
        else:
            tau = abs(values[ch.delay])
        m = ch.oversample
        steps = tau / (dt / m)  # the delay in samples at the channel's rate, as the kernel has it
        if not steps < n * m - DELAY_MARGIN:
            need = max(n + 1, int(math.floor((steps + DELAY_MARGIN) / m)))
            while not steps < need * m - DELAY_MARGIN:
                need += 1
            where = recording.source or ("the recording" if at_bound else "this recording")
            said = (f"a fit may take the {ch.name} channel's delay {ch.delay} up to its bound "
                    f"{tau:g} s, which" if at_bound
                    else f"the {ch.name} channel's delay {ch.delay} = {tau:g} s")
            hint = (f"; use a longer record, or (in Python) fix {ch.delay} at a value the "
                    f"record can hold (model.fix({ch.delay}=...))" if at_bound else "")
            return (f"{where}: the record is too short for the pilot model: {n} sample(s) "
                    f"({recording.duration:g} s), and {said} needs at least {need} "
                    f"({need * dt:g} s at {recording.sample_rate_hz:g} Hz){hint}")
    return None


def _check_fittable(recording: Recording, model: PilotModel, discard: float) -> None:
    """Refuse a recording a fit cannot say anything about (a RecordingError, a ValueError
    the CLI reports as bad input), before fitting: fewer samples
    after ``discard`` than four per free parameter, a record shorter than a channel's delay
    may reach within the bounds (:func:`_too_short_for_delays`: -ln L is +inf there), or a
    control output u that is constant over them (nothing to fit; the VAF is undefined).
    Fitted anyway, they gave an infinite -ln L, garbage parameters or a VAF of -inf without
    a word."""
    from ..recording import RecordingError

    skip = int(round(float(discard) / recording.dt)) if discard else 0
    u = np.asarray(recording.u, dtype=float)[skip:]
    need = 4 * model.n_free
    if u.size <= need:
        raise RecordingError(f"{recording.source or 'the recording'}: {u.size} samples"
                         f"{f' after the first {discard:g} s' if skip else ''}; a fit of "
                         f"{model.n_free} parameters needs more than {need}")
    if not np.ptp(u) > 0:
        raise RecordingError(f"{recording.source or 'the recording'}: the control output u is "
                         f"constant ({u[0]:g}){f' after the first {discard:g} s' if skip else ''}"
                         ": there is nothing to fit")
    short = _too_short_for_delays(model, recording)
    if short is not None:
        raise RecordingError(short)
    _warn_offset(recording, u, skip, discard)
    _warn_unnamed_threshold(model)


#: |mean(u)| / std(u) over the fitted samples above which a fit warns of an offset in u.
#: The package's own records stay far below it: simulated FD and FT runs (K_theta 0, 0.5, 1;
#: F_n 0, 0.05, 0.1, 0.2, 0.3; seeds 0-5, 0-9 for FD without motion; 81.92, 40 and 30 s;
#: from 0 s and from 2 s; 472 records) reached at most 0.052 (30 s; 0.036 on 40 s, 0.023 on
#: 81.92 s; medians 0.008-0.03), the example's washout run (analyses/results/diagnose/example)
#: 0.0005.  A stick
#: offset of 0.02 rad on a simulated FD run (std(u) 0.032 rad: ratio 0.63) moved delta_abs
#: from 0.0097 to 0.0148 and K_m from 0.60 to 0.67 while the VAF hid it (80.9 -> 80.5 %); at
#: 0.2 an offset of a fifth of u's spread is warned of, four times the simulated maximum.
#: The same ratio is applied to an offset in e, by
#: :func:`bayespilot.recording.questionable` when the recording is read (against
#: f_t - theta, since e's own mean does not average out over a run as u's does).
OFFSET_RATIO = _OFFSET_RATIO


def _warn_offset(recording: Recording, u: np.ndarray, skip: int, discard: float) -> None:
    """Warn (QuestionableRecordingWarning) of a control output u whose mean over the fitted
    samples is a sizeable fraction of its standard deviation.  The model takes u as zero-mean
    about the trim: Eq. 4 keeps an offset in the residual, and the threshold and motion gain
    move to make up for part of it, while the VAF (about the mean) does not show it."""
    from .._caller import warn_at_caller
    from ..recording import QuestionableRecordingWarning

    mean, std = float(np.mean(u)), float(np.std(u))
    if abs(mean) > OFFSET_RATIO * std:
        warn_at_caller(f"{recording.source or 'the recording'}: the control output u has a "
                       f"mean of {mean:.3g}, {abs(mean) / std:.2f} of its standard deviation "
                       f"{std:.3g}{f' after the first {discard:g} s' if skip else ''}: the "
                       "model takes u as zero-mean about the trim, so an offset biases the "
                       "fit (delta_abs, K_m) while the VAF does not show it; remove the stick "
                       "offset (u - mean(u), or the trim) before fitting",
                       QuestionableRecordingWarning)


def _warn_unnamed_threshold(model: PilotModel) -> None:
    """Warn of a free dead-zone threshold not named ``delta_abs``: the fitters scan and
    profile the threshold by that name (the paper's third step), so such a one is fitted as an
    ordinary parameter and can stop far from its optimum (another K_m, -ln L worse)."""
    from .._caller import warn_at_caller

    blocks = [c.nonlinearity for c in model.channels] + [model.output]
    names = sorted({name for b in blocks if b is not None for name in b.thresholds
                    if name != "delta_abs" and name not in model.fixed})
    if names:
        warn_at_caller(f"the threshold {', '.join(names)} is fitted as an ordinary "
                       "parameter, without the threshold scan: the fitters scan only a "
                       "threshold named delta_abs (name it so to have it scanned)", UserWarning)


def _warn_on_bounds(fit: FitResult, lik: Likelihood | None = None) -> None:
    """One EstimateOnBoundWarning, at the user's line, naming the parameters other than
    delta_abs that ended on a bound of the search box (:attr:`FitResult.at_bounds`; delta_abs
    = 0 is the answer "no threshold").  Only for a fit the user's own code called: the
    package's loops (diagnose, compare, campaigns, the calibration replicates, the example)
    and its command line, whose summary marks them, keep it to the result."""
    import sys
    from pathlib import Path

    from .._caller import _PACKAGE, warn_at_caller
    from .result import EstimateOnBoundWarning

    # (a silent channel's parameters, e.g. the motion channel's on a run without motion, are
    # unidentified, not stopped by a bound: SilentChannelWarning has said so)
    quiet = {"delta_abs"} | (_unidentified(lik) if lik is not None else set())
    edge = {k: side for k, side in fit.at_bounds.items() if k not in quiet}
    if not edge:
        return
    # the first frame outside the fitters (and the BLAS-limit wrapper) is the fit's caller
    inside = {Path(__file__).resolve(), Path(__file__).resolve().with_name("fast.py"),
              _PACKAGE / "_blas.py"}
    frame = sys._getframe(1)
    while frame is not None and Path(frame.f_code.co_filename).resolve() in inside:
        frame = frame.f_back
    if frame is not None and Path(frame.f_code.co_filename).resolve().is_relative_to(_PACKAGE):
        return
    said, why = [], {}
    for k, side in edge.items():
        where, bound = fit._edge_text(k, side)
        said.append(f"{k} = {fit.params[k]:g} {where} its {side} bound ({bound:g})")
        why[where] = ("the bound, not the data, stopped the fit there and the other estimates "
                      "moved to make up for it" if where == "on" else
                      "the unconstrained Step II left the search box")
    warn_at_caller(f"{', '.join(said)}: {'; '.join(why.values())}; the bounds (Table 1 for "
                   "the paper's parameters) may not suit the recording's units (SI, angles in "
                   "radians: u in degrees puts K_v on 10) or the model (FitResult.at_bounds)",
                   EstimateOnBoundWarning)


@one_blas_thread
def fit_paper(recording: Recording, model: PilotModel | None = None, *, threshold: bool = True,
              seed: int | None = None, repetitions: int = 20, n_best: int = 5,
              population: int = 160, generations: int = 100, p_crossover: float = 0.7,
              p_mutation: float = 0.01, bits: int = 20, scan_step: float = 1e-4,
              iterate: bool = False, max_iterations: int = 50, initial: str = "periodic",
              discard: float | None = None,
              progress: bool = False) -> FitResult:
    """Fit a pilot model to a recording with the paper's three-step procedure.

    Parameters
    ----------
    recording : Recording
    model : PilotModel, optional
        Default :func:`~bayespilot.model.paper_model`.
    threshold : bool
        False fits the model without threshold
        (:meth:`~bayespilot.model.PilotModel.without_threshold`: delta_abs = 0
        for the paper's dead zone; a soft dead zone removed with its w_soft).
        True or False only, as ``iterate``.
    seed : int, optional
        Seeds the genetic algorithm; the same seed gives the same fit.
        None draws one from fresh entropy; the seed used is
        recorded in the result (``seed``) and repeats the run.
    repetitions, n_best : int
        Step I: GA runs per data set, and how many of the best give delta_abs.
    population, generations, p_crossover, p_mutation, bits
        The GA settings (the paper's by default).
    scan_step : float
        Step III resolution in IPUT: positive, and at most the range of
        delta_abs's bounds (0.1 in Table 1), or the scan's grid would hold
        no value inside them.
    iterate : bool
        True or False (nothing else: a string such as ``"False"`` is refused,
        not taken for its truth value).  True repeats Steps II and III until
        delta_abs and -ln L no longer change
        (not the paper's procedure, which makes one pass).  Each pass moves
        delta_abs only part of the way, because the other parameters (K_m
        above all) were refined for the previous value: from a Step I
        delta_abs of 0.08 on a remnant-free FD record it takes about 20
        passes to reach the optimum at 0.0076, where one pass stops at 0.066
        (``tests/test_fit.py``).  ``steps["iterations_converged"]`` says whether
        it stopped because nothing changed.
    max_iterations : int
        At most this many passes with ``iterate``; a warning if they run out.
    initial : {"periodic", "rest"}
        Initial-condition treatment of the likelihood.
    discard : float or None
        Seconds at the start left out of Eq. 4 (see :class:`~bayespilot.likelihood.Likelihood`).
        None (default): 0, the paper's choice, on a record of whole forcing periods (the
        paper's 81.92 s); with ``initial="periodic"`` on a record not known to be whole
        periods (:func:`~bayespilot.likelihood.whole_periods` False or None),
        :func:`~bayespilot.likelihood.startup_discard` (2 s), as
        :func:`~bayespilot.fit.fast.fit_fast` does, so that the two methods fit the same
        samples (``settings["discard_reason"]`` says why).
    progress : bool
        Show a progress bar over the GA repetitions.

    Returns
    -------
    FitResult

    Raises
    ------
    TypeError
        ``recording`` is not a Recording, or ``model`` not a PilotModel.
    ValueError
        ``repetitions``, ``n_best`` or ``max_iterations`` not a positive
        integer, ``n_best > repetitions``, ``scan_step`` not positive or
        beyond the range of delta_abs's bounds, ``threshold`` or ``iterate``
        not a bool, ``discard`` outside [0, half the record], a setting the
        likelihood refuses, or a recording with no more than four samples per
        free parameter or a constant u; or no start gave a finite likelihood
        (every parameter vector Step I tried made the closed loop or a block
        unstable: check the blocks' bounds).

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
    NotAtMaximumWarning
        With delta_abs estimated, the result is more than
        :data:`~bayespilot.fit.result.CHECK_GAP` in -ln L above the maximum
        that Gauss-Newton with delta_abs free reaches from it
        (``steps["check"]``): the paper's single pass of Steps II and III
        stopped short (``iterate=True``, or :func:`~bayespilot.fit.fast.fit_fast`,
        reaches it).
    RuntimeWarning
        With ``iterate``, Steps II and III still changed delta_abs or -ln L
        after ``max_iterations`` passes (``steps["iterations_converged"]`` is
        False).
    UserWarning
        The model has a free dead-zone threshold not named ``delta_abs``: it
        is fitted as an ordinary parameter, without the threshold scan.

    Examples
    --------
    >>> from bayespilot.simulate import simulate
    >>> rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.1, seed=1, duration=20).recording
    >>> fit = fit_paper(rec, seed=0, repetitions=2, n_best=1, generations=5, population=20)
    >>> sorted(fit.params)[:3]
    ['K_m', 'K_v', 'T_vl']
    """
    from .genetic import step_one

    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    for name, v in (("repetitions", repetitions), ("n_best", n_best), ("max_iterations", max_iterations)):
        if not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name} must be a positive integer, got {v!r}")
    iterate = _check_bool("iterate", iterate)
    threshold = _check_bool("threshold", threshold)
    if n_best > repetitions:
        raise ValueError(f"n_best ({n_best}) cannot exceed repetitions ({repetitions})")
    seed = resolve_seed(seed)  # None: a fresh one, recorded in the result
    t0 = time.perf_counter()
    model = _model_for(model, threshold)
    _check_steps(model, scan_step=scan_step)
    discard_reason = None
    if discard is None:  # 0 on whole periods; otherwise as fit_fast
        discard = _startup_default(recording, initial)
        if discard:
            discard_reason = _startup_reason(recording)
    discard = _checked_discard(recording, discard)
    _check_fittable(recording, model, discard)
    lik = Likelihood(model, recording, initial=initial, discard=discard)
    has_delta = "delta_abs" in model.parameter_names

    s1 = step_one(lik, repetitions=repetitions, n_best=n_best, seed=seed, progress=progress,
                  population=population, generations=generations, p_crossover=p_crossover,
                  p_mutation=p_mutation, bits=bits)
    _refuse_unstable_everywhere(model, float(np.min(s1.funs)),
                                f"Step I: {repetitions} genetic-algorithm run"
                                f"{'' if repetitions == 1 else 's'}, population {population}, "
                                f"{generations} generations")
    delta1 = s1.delta_abs if has_delta else None

    step2 = []
    for run in s1.runs:
        start = model.as_dict(run.x)
        if has_delta:
            start["delta_abs"] = delta1
        step2.append(refine(lik, start, hold=("delta_abs",)))
    k_best = int(np.argmin([r.neg_log_lik for r in step2]))
    params = dict(step2[k_best].params)
    fun = step2[k_best].neg_log_lik

    scans: list[dict[str, Any]] = []
    iterations = []
    converged = None
    if has_delta:
        for it in range(max_iterations if iterate else 1):
            sc = scan_parameter(lik, params, "delta_abs", step=scan_step)
            scans.append(sc.to_dict())
            moved = abs(sc.best - params["delta_abs"])
            params["delta_abs"] = sc.best
            fun = sc.best_neg_log_lik
            if not iterate:
                break
            r = refine(lik, params, hold=("delta_abs",))
            iterations.append(r.to_dict())
            improved = fun - r.neg_log_lik
            params, fun = dict(r.params), r.neg_log_lik
            if it > 0 and moved < 0.5 * scan_step and improved < 1e-6 * max(1.0, abs(fun)):
                converged = True
                break
        else:
            if iterate:
                converged = False
                from .._caller import warn_at_caller  # (fit_paper is wrapped: not stacklevel)

                warn_at_caller(f"Steps II and III still changed delta_abs or -ln L after "
                               f"{max_iterations} pass{'' if max_iterations == 1 else 'es'}; "
                               "raise max_iterations", RuntimeWarning)

    # Not part of the paper's procedure, whose estimate is kept: a check of it (FD, F_n 0.2,
    # seed 3: the single pass ends at delta_abs 0.0386, 635 in -ln L above the 0.0078 this
    # reaches, the fast method's maximum).
    check = joint_refine(lik, params, fun) if has_delta else None

    _refuse_unstable_everywhere(model, float(fun), "Steps II and III, from Step I's runs")
    full = dict(model.as_dict(model.full_vector(params), full=True))
    settings = {"repetitions": repetitions, "n_best": n_best, "population": population,
                "generations": generations, "p_crossover": p_crossover, "p_mutation": p_mutation,
                "bits": bits, "scan_step": scan_step, "iterate": iterate,
                "max_iterations": max_iterations, "initial": initial, "discard": discard,
                "model": model.name, "recording_sha256": _recording_digest(recording)}
    if discard_reason is not None:
        settings["discard_reason"] = discard_reason
    _unidentified_settings(settings, lik)
    steps = {"step1": s1.to_dict(), "step1_delta_abs": delta1,
             "step2": [r.to_dict() for r in step2], "step2_best": k_best,
             "step3": scans, "iterations": iterations, "iterations_converged": converged,
             "check": check}
    fit = FitResult(full, float(fun), lik.vaf(params), "paper", seed,
                    has_delta or model.has_threshold, settings, steps,
                    time.perf_counter() - t0, recording.source, **FitResult._declared(model))
    _warn_on_bounds(fit, lik)
    if check is not None and check["gap"] > CHECK_GAP:
        from .._caller import warn_at_caller  # (fit_paper is wrapped: not stacklevel)

        where = f"{recording.source}: " if recording.source else ""
        warn_at_caller(f"{where}the paper's three-step fit stopped {check['gap']:.1f} short of a "
                       f"maximum of ln L: Gauss-Newton with delta_abs free reaches -ln L = "
                       f"{check['neg_log_lik']:.3f} from it, at delta_abs "
                       f"{check['params']['delta_abs']:.4g} against the fit's "
                       f"{params['delta_abs']:.4g} (steps['check']); iterate=True repeats "
                       f"Steps II and III toward it, the fast method finds it directly",
                       NotAtMaximumWarning)
    return fit


def _unidentified_settings(settings: dict, lik: Likelihood) -> None:
    """Record in ``settings["unidentified"]`` (in the model's order) the free parameters the
    record does not identify, a silent channel's own (the motion channel's on a run without
    motion: the SilentChannelWarning's); the result's summary marks them.  Nothing if none."""
    silent = _unidentified(lik)
    names = [k for k in lik.model.parameter_names if k in silent]
    if names:
        settings["unidentified"] = names

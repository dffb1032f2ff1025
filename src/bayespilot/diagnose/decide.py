"""Fit the base model and every catalogue extension, test each, rank them, decide.

The decision likelihood
-----------------------
Eq. 4 treats the N = 8192 samples of the output error as independent.  They
are not: the remnant is a fourth-order low-pass process (Eq. 6), so
neighbouring samples are almost equal, and a likelihood-ratio test on Eq. 4
counts every sample as new information.  On correct-model data it flags
almost everything (hugely anti-conservative).

The default decision likelihood is therefore generalised least squares with
an AR noise model (a prediction-error likelihood, :class:`Whitened`):

1. the base model is fitted by Eq. 4 (the fast estimator);
2. its residual, after the first seconds (the likelihood's start-up
   transient), is low-passed at 25 rad/s by a causal FIR filter and
   decimated to a Nyquist frequency of about 60 rad/s, and an AR(p) model of
   it is estimated (least squares, order by BIC; :func:`noise_model`) and
   held fixed;
3. the base model and each extension are re-fitted by least squares on the
   reduced and pre-whitened residual w = A(q) reduce(u - u_hat(theta)), with
   the exact Jacobians of the model passed through the same filters;
4. 2 (-ln L_base - -ln L_ext) is compared with chi2(df), df = the number of
   parameters the extension adds, at the family-wise level ``alpha`` split
   over the candidates tested (Bonferroni).  -ln L_base is the base model's
   best fit found: the base model is also refitted from every extension's
   fit with the extension taken out (:func:`null_refit`), because an
   extension can carry the fit into a better basin of the *base* model
   (another delta_abs), which is not physics;
5. optionally (``diagnose(n_calibrate=B)``) the chosen candidate's test is
   calibrated by a parametric bootstrap of the base model
   (:mod:`bayespilot.diagnose.calibrate`), whose p-value replaces the
   asymptotic one when the reference proves anti-conservative on the
   recording at hand.

Why the low-pass: the likelihood runs the pilot model at the recording's
100 Hz (Tustin, interpolated delays) while the pilot (or the simulator, at
1 kHz) is continuous.  That discretisation error is tiny in every band (at
F_n = 0.2 its power is 300-1000 times below the remnant's from 0 to 50 Hz),
but it is deterministic and coherent over thousands of samples, and
whitening weights it where the remnant is weakest.  Whitened over the whole
band it adds a noncentrality of 1-22 (median 5; most at low remnant)
to a likelihood-ratio statistic, which an extension that shapes the
high frequencies (the platform's bandwidth, a soft threshold) fits on
correct-model data: on the full band (``omega_c = inf``) the proof study's
controls gained 0.9 in -ln L for the platform (the null's mean is 0.25) and
raised false alarms.  Low-passed at 25 rad/s the error's noncentrality is
0.01-0.15 (at 50 rad/s up to 2.6); ``analyses/prove_diagnose.py
--model-error`` measures it.  Why not
a frequency-domain (Whittle) version: the record after the skipped start is
not a whole number of forcing periods, so the forcing lines leak into their
neighbours, which a drifting gain fits (tried; false alarms).

For boundary nulls (a bandwidth going to infinity, a corner width going to
zero) chi2(df) is conservative; for parameters unidentified under the null
(the otolith head height when its gain is 0) it is an approximation.  The
false-alarm rate is measured on simulated correct-model recordings in
``analyses/prove_diagnose.py`` (see ``docs/diagnose-evidence.md``).

``control-saturation`` is tested differently: flat tops (exact repeats of
the extreme value) have probability zero under every continuous-noise model,
so their presence decides it (its calibrated p-value is that of the flat-top
statistic, see :mod:`bayespilot.diagnose.locate`), and the extension is
fitted by the censored likelihood (:mod:`bayespilot.kernels._censored`),
whose improvement over the base parameters is reported.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from scipy import linalg, optimize, signal, stats

from .._files import number, numbers
from ..likelihood import Likelihood
from ..model import PilotModel
from ..noise import MAX_AR_ORDER, fit_ar
from ..recording import Recording
from .catalogue import Extension, get_extension

__all__ = ["fit_ar", "NoiseModel", "noise_model", "Whitened", "FitSummary", "CandidateResult",
           "fit_base_gls", "scan_threshold", "threshold_starts", "own_noise", "final_fit",
           "report_final_fit",
           "fit_candidate", "guide_fits", "refine_threshold", "null_refit", "null_refit_from",
           "lr_p_value", "critical_value", "LRVerdict", "lr_verdict", "retest", "flat_tops",
           "fit_censored"]

#: How the chosen extension's reported fit is made (:func:`report_final_fit`).
FINAL_FIT = ("refitted after the test: AR noise model re-estimated from the extended model's "
             "residual, the fit also started from eight values of delta_abs, delta_abs "
             "rescanned, three times")

#: Cut-off of the decision likelihood's low-pass, rad/s.
OMEGA_C = 25.0

#: Span of the decision low-pass's FIR kernel, s: 61 taps at the paper's 100 Hz.  Above
#: 100 Hz the number of taps follows the sample rate (:func:`_fir_numtaps`), so that the
#: filter's response in Hz, its start-up (the first 0.6 s of the filtered series) and its
#: group delay (0.3 s) are those at 100 Hz; a fixed 61 taps widened the transition band
#: with the rate (gain at 2 omega_c: -63 dB at 100 Hz, -27 dB at 200 Hz, -1.6 dB at
#: 1 kHz, where the decimation by 50 then aliased the residual's high band).
FIR_SPAN = 0.6

#: Fewest taps of the decision low-pass (those at 100 Hz).  Below 100 Hz the 61 taps are
#: kept, so results there are as before: their transition band is narrower than at 100 Hz
#: (at 50 Hz -59 dB at 2 omega_c, -64 dB above the decimated Nyquist frequency).  The
#: 31 taps of a 0.6-s kernel at 50 Hz moved single 50-Hz washout runs' p-values either
#: way (once from 2e-4 to 0.02, a detection lost).
FIR_MIN_TAPS = 61


@dataclass(frozen=True, eq=False)  # by identity: == on its arrays raised ValueError
class NoiseModel:
    """How the decision likelihood pre-whitens: low-pass, decimate, AR filter.

    Compared by identity: ``==`` is True only for the same object (a copy,
    e.g. pickled and read back, is not equal; compare ``fir`` and ``ar`` with
    ``numpy.array_equal``), and it is hashed by identity.  Its repr gives the
    numbers of taps and AR coefficients, not the arrays.

    Attributes
    ----------
    fir : ndarray
        Causal FIR low-pass taps (scipy.signal.firwin), cut-off ``omega_c``.
    decimation : int
        Every ``decimation``-th filtered sample is kept.
    ar : ndarray
        AR coefficients of the filtered, decimated residual.
    skip : int
        Samples at the start of the record left out.
    omega_c : float
        Cut-off of the low-pass, rad/s.
    """

    fir: np.ndarray
    decimation: int
    ar: np.ndarray
    skip: int
    omega_c: float

    def __repr__(self) -> str:
        """One line (the dataclass's printed every FIR tap and AR coefficient)."""
        return (f"NoiseModel(omega_c={self.omega_c:g}, decimation={self.decimation}, "
                f"fir_taps={np.size(self.fir)}, ar_order={np.size(self.ar)}, skip={self.skip})")

    def reduce(self, x: np.ndarray) -> np.ndarray:
        """Low-pass (causal) and decimate along the first axis, after ``skip``.

        Parameters
        ----------
        x : ndarray, shape (N, ...)
            A series at the recording's rate along the first axis (a
            residual, or the columns of a Jacobian).

        Returns
        -------
        ndarray
            ``x`` filtered by :attr:`fir` from its first sample (at rest
            before it), then every ``decimation``-th sample from sample
            ``skip`` on; in the units of ``x``.
        """
        return signal.lfilter(self.fir, [1.0], x, axis=0)[self.skip::self.decimation]

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """A(q) applied to the reduced series; the first p values dropped.

        Parameters
        ----------
        x : ndarray, shape (N, ...)
            A series at the recording's rate along the first axis.

        Returns
        -------
        ndarray
            w = A(q) :meth:`reduce` (x) without its first p = ``ar.size``
            values, in the units of ``x``.
        """
        p = self.ar.size
        return signal.lfilter(np.concatenate([[1.0], -self.ar]), [1.0], self.reduce(x),
                              axis=0)[p:]

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready description: ``omega_c`` (rad/s; None for no low-pass),
        ``decimation``, ``fir_taps``, ``ar_order`` and ``skip_samples`` (not the
        coefficients)."""
        return {"omega_c": self.omega_c if math.isfinite(self.omega_c) else None,
                "decimation": self.decimation, "fir_taps": self.fir.size,
                "ar_order": int(self.ar.size), "skip_samples": self.skip}


def _fir_numtaps(fs: float) -> int:
    """Taps of the decision low-pass at ``fs`` Hz: odd, spanning :data:`FIR_SPAN` seconds,
    at least :data:`FIR_MIN_TAPS` (61 at 100 Hz and below, 121 at 200, 601 at 1000)."""
    return max(FIR_MIN_TAPS, 2 * int(round(0.5 * FIR_SPAN * fs)) + 1)


def _lowpass(omega_c: float, fs: float) -> tuple[np.ndarray, int]:
    """The decision likelihood's low-pass taps and decimation at ``fs`` Hz.

    Causal windowed-sinc FIR (scipy.signal.firwin, Hamming) with cut-off
    ``omega_c`` rad/s and :func:`_fir_numtaps` taps, and the decimation that
    leaves a Nyquist frequency of about 2.5 ``omega_c``; ``omega_c = inf``:
    one unit tap and no decimation.  At 100 Hz the taps are exactly
    ``firwin(61, f_c, fs=100)``.

    Raises
    ------
    ValueError
        ``omega_c`` is finite and at 0.45 of the sampling frequency or above.
    """
    if math.isinf(omega_c):
        return np.ones(1), 1
    f_c = omega_c / (2 * np.pi)
    if not f_c < 0.45 * fs:
        raise ValueError(f"omega_c = {omega_c:g} rad/s is too close to the Nyquist "
                         f"frequency (inf keeps the whole band)")
    fir = signal.firwin(_fir_numtaps(fs), f_c, fs=fs)
    decim = max(1, int(math.floor(fs / (2.0 * 2.5 * f_c))))
    return fir, decim


def noise_model(eps: np.ndarray, dt: float, *, skip: int = 0, omega_c: float = OMEGA_C,
                max_order: int = MAX_AR_ORDER, order: int | None = None) -> NoiseModel:
    """The decision likelihood's noise model, estimated from a (base-model) residual.

    With a finite ``omega_c`` the residual is low-passed at ``omega_c`` by a
    causal FIR filter spanning :data:`FIR_SPAN` (0.6 s: 61 taps at 100 Hz,
    601 at 1 kHz, so that its response in Hz is the same at every rate from
    100 Hz up; 61 taps below 100 Hz, :data:`FIR_MIN_TAPS`) and decimated so
    that the new Nyquist frequency is about 2.5 omega_c; ``omega_c =
    math.inf`` keeps the whole band (no filter, no decimation).  The filter
    starts from rest at the first sample, so its start-up transient is the
    first ``fir.size - 1`` samples of the filtered series (0.6 s from 100 Hz
    up, 1.2 s at 50 Hz): a ``skip`` of at least that (``diagnose``'s is 5 s)
    leaves it out.  An AR model of
    the reduced residual (least squares, order by BIC, :func:`fit_ar`, unless
    ``order`` is given) is the noise model.

    Parameters
    ----------
    eps : ndarray
        The residual u - u_hat of a fit, one value per sample (1-D, finite), rad.
    dt : float
        Sample interval of the recording, s.
    skip : int
        Samples at the start of the record left out of the AR estimate, and of
        every likelihood under this noise model (``NoiseModel.skip``).
    omega_c : float
        Cut-off of the low-pass, rad/s (default :data:`OMEGA_C`, 25);
        ``math.inf`` keeps the whole band.
    max_order : int
        Largest AR order tried (default :data:`bayespilot.noise.MAX_AR_ORDER`),
        and at most a fifth of the reduced residual's length.
    order : int, optional
        Take this AR order instead of the one BIC chooses (0: no AR filter).

    Returns
    -------
    NoiseModel
        The low-pass taps and decimation (one tap and 1 for the whole band),
        the AR coefficients, ``skip`` and ``omega_c``.

    Raises
    ------
    ValueError
        ``omega_c`` is not a positive number, or is finite and at 0.45 of the
        sampling frequency or above; the residual is not finite, or ``order``
        is a quarter of the reduced residual's length or more
        (:func:`fit_ar`).
    """
    if not (isinstance(omega_c, (int, float, np.integer, np.floating)) and omega_c > 0):
        raise ValueError(f"omega_c must be a positive number of rad/s (inf: the whole band), "
                         f"got {omega_c!r}")
    fir, decim = _lowpass(omega_c, 1.0 / dt)
    nm = NoiseModel(fir, decim, np.zeros(0), int(skip), float(omega_c))
    red = nm.reduce(np.asarray(eps, float))
    ar = fit_ar(red, max_order=min(max_order, red.size // 5), order=order)
    return NoiseModel(fir, decim, ar, int(skip), float(omega_c))


def reestimate(noise: NoiseModel, eps: np.ndarray) -> NoiseModel:
    """The same low-pass, decimation and AR order, the AR coefficients refitted to ``eps``."""
    ar = fit_ar(noise.reduce(np.asarray(eps, float)), order=noise.ar.size)
    return NoiseModel(noise.fir, noise.decimation, ar, noise.skip, noise.omega_c)


def refit_with_noise(model: PilotModel, recording: Recording, fit: "FitSummary",
                     noise: NoiseModel, names: Sequence[str], rounds: int = 2
                     ) -> tuple["FitSummary", NoiseModel]:
    """Profile the noise model too: refit the AR coefficients to the fit's residual and the
    parameters ``names`` under them, ``rounds`` times (a prediction-error fit in which the
    noise model is estimated with the pilot model rather than held at the base model's).

    Without this the AR model of the *base* residual whitens whatever the base model misses
    as if it were remnant, which takes power from the test of an extension.
    """
    lik = Likelihood(model, recording)
    for _ in range(rounds):
        eps = lik.residual(fit.params)
        if not np.all(np.isfinite(eps)):
            break
        noise = reestimate(noise, eps)
        fit = _gls_refine(Whitened(model, recording, noise), fit.params, names)
    return fit, noise


class Whitened:
    """The GLS (pre-whitened) output-error likelihood of a model on a recording.

    With eps = u - u_hat(theta), the residual is reduced (low-passed and
    decimated) and whitened by the fixed :class:`NoiseModel`,
    w = A(q) reduce(eps), and

        -ln L = m/2 ln(mean w^2) + m/2

    over its m values (conditional likelihood, noise level profiled out).
    Every step is linear, so the exact Jacobian of u_hat goes through the
    same filters.  This is the prediction-error criterion with an AR noise
    model, which (unlike Eq. 4's output error) stays consistent in the closed
    loop when the noise model is right.

    Parameters
    ----------
    model : PilotModel
    recording : Recording
    noise : NoiseModel
        Its ``skip`` leaves out the start of the record: the likelihood's
        periodic start-up (``docs/model.md``) leaves a transient of a few
        seconds in u_hat when the record is not periodic (remnant), up to the
        size of the remnant itself; an extension that changes the start of the
        run (a drifting gain) would otherwise fit it.
    """

    def __init__(self, model: PilotModel, recording: Recording, noise: NoiseModel) -> None:
        if not isinstance(noise, NoiseModel):
            raise TypeError(f"noise must be a NoiseModel, got {type(noise).__name__}")
        self.model = model
        self.lik = Likelihood(model, recording)
        self.noise = noise
        self.u = self.lik.u
        if noise.skip >= self.lik.n - 64 * noise.decimation:
            raise ValueError(f"the recording ({self.lik.n} samples) is too short to skip "
                             f"{noise.skip} samples")
        self.m = self.whiten(self.u).size

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """The whitened, reduced series (along the first axis).

        Parameters
        ----------
        x : ndarray, shape (n_samples, ...)
            A series at the recording's rate (a residual, or the columns of a
            Jacobian).

        Returns
        -------
        ndarray, shape (m, ...)
            :meth:`NoiseModel.whiten` of ``x``.
        """
        return self.noise.whiten(x)

    def neg_log_lik(self, params: Mapping[str, float]) -> float:
        """GLS -ln L at ``params`` (+inf if the model is unstable there).

        Parameters
        ----------
        params : mapping of str to float
            Values by name; free parameters not given take the model's
            defaults.

        Returns
        -------
        float
            m/2 ln(mean w^2) + m/2 (the mean floored at 1e-300), or +inf.
        """
        y = self.lik.response(params)
        if not np.all(np.isfinite(y)):
            return math.inf
        w = self.whiten(self.u - y)
        return 0.5 * self.m * math.log(max(float(np.mean(w * w)), 1e-300)) + 0.5 * self.m


@dataclass(eq=False)  # by identity: == on its arrays would be ambiguous
class FitSummary:
    """A GLS (or censored) fit: parameters, -ln L, covariance of the refined parameters.

    Attributes
    ----------
    params : dict of str to float
        Every free parameter of the fitted model at the fit.
    neg_log_lik : float
        -ln L of the fit on the decision (GLS) likelihood; NaN for a start
        that was not evaluated.
    refined : tuple of str
        The parameters that were optimised (the others held).
    cov : ndarray, shape (len(refined), len(refined))
        Their covariance, in the parameters' units squared: s2 (J^T J)^+
        from the whitened residual's Jacobian J for a GLS fit, the inverse
        Hessian scaled for the residual's correlation for a censored one
        (empty when nothing was refined).
    nfev : int, default 0
        Residual evaluations the optimiser made.
    """

    params: dict[str, float]
    neg_log_lik: float
    refined: tuple[str, ...]
    cov: np.ndarray
    nfev: int = 0

    @property
    def stderr(self) -> dict[str, float]:
        """Standard error of each refined parameter, sqrt of the covariance's diagonal, in the
        parameter's unit."""
        d = np.sqrt(np.clip(np.diag(self.cov), 0, None)) if self.cov.size else np.zeros(0)
        return {n: float(s) for n, s in zip(self.refined, d)}


def _gls_refine(wl: Whitened, start: Mapping[str, float], names: Sequence[str], *,
                max_nfev: int = 60) -> FitSummary:
    """Bounded least squares on the whitened residual (trust-region reflective, exact Jacobian)."""
    model = wl.model
    base = dict(model.as_dict(model.free_vector(start)))
    names = tuple(names)
    lo = np.array([model.parameter(n).lower for n in names])
    hi = np.array([model.parameter(n).upper for n in names])
    big = 1e3 * (float(np.std(wl.u)) + 1e-300)

    def params_of(x):
        p = dict(base)
        p.update(zip(names, (float(v) for v in x)))
        return p

    def resid(x):
        y = wl.lik.response(params_of(x))
        if not np.all(np.isfinite(y)):
            return np.full(wl.m, big)
        return wl.whiten(wl.u - y)

    def jac(x):
        _, J = wl.lik.jacobian(params_of(x), names)
        if not np.all(np.isfinite(J)):
            return np.zeros((wl.m, len(names)))
        return -wl.whiten(J)

    x0 = np.clip(np.array([base[n] for n in names]), lo, hi)
    # keep the start strictly inside for the reflective method
    span = hi - lo
    x0 = np.clip(x0, lo + 1e-9 * span, hi - 1e-9 * span)
    sol = optimize.least_squares(resid, x0, jac=jac, bounds=(lo, hi), method="trf",
                                 x_scale="jac", max_nfev=max_nfev, xtol=1e-8, ftol=1e-9)
    p = params_of(sol.x)
    f = wl.neg_log_lik(p)
    f0 = wl.neg_log_lik(params_of(x0))
    if not np.isfinite(f) or f > f0:
        p, f = params_of(x0), f0
        Jw = jac(x0)
        r = resid(x0)
    else:
        Jw = sol.jac
        r = sol.fun
    s2 = float(np.mean(r * r))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cov = s2 * linalg.pinvh(Jw.T @ Jw)
    return FitSummary(p, float(f), names, cov, int(sol.nfev))


def fit_base_gls(model: PilotModel, recording: Recording, start: Mapping[str, float],
                 noise: NoiseModel, *, delta_step: float = 5e-4) -> tuple[Whitened, FitSummary]:
    """GLS fit of the base model: refine, scan delta_abs under GLS, refine again.

    delta_abs is scanned (not refined by Gauss-Newton: the crisp dead zone's
    derivative is unreliable), on [0, upper] in steps of ``delta_step``.

    Parameters
    ----------
    model : PilotModel
        The base model (:func:`~bayespilot.model.paper_model`).
    recording : Recording
    start : mapping of str to float
        Starting parameters by name (e.g. the Eq. 4 fit's; those not given
        start at the model's defaults); delta_abs is held at its value here
        in the first refinement.
    noise : NoiseModel
        The decision likelihood's noise model (:func:`noise_model`), held.
    delta_step : float
        Step of the delta_abs grid, IPUT.

    Returns
    -------
    wl : Whitened
        The GLS likelihood of ``model`` on ``recording`` under ``noise``.
    fit : FitSummary
        The fit: -ln L on the decision likelihood; ``refined`` the free
        parameters except delta_abs, with their covariance.

    Raises
    ------
    TypeError
        ``noise`` is not a NoiseModel.
    ValueError
        The recording is too short to skip ``noise.skip`` samples, or
        ``start`` names a parameter the model does not have.
    """
    wl = Whitened(model, recording, noise)
    names = tuple(n for n in model.parameter_names if n != "delta_abs")
    return wl, scan_threshold(wl, _gls_refine(wl, start, names), names, delta_step=delta_step)


def scan_threshold(wl: Whitened, fit: FitSummary, names: Sequence[str], *,
                   delta_step: float = 5e-4) -> FitSummary:
    """``fit`` with delta_abs scanned under GLS on [0, upper] and the parameters ``names``
    refined again from the grid's best value, when that is better (else ``fit`` itself).

    A grid, not Gauss-Newton: the crisp dead zone's derivative in delta_abs
    is unreliable.  A model without delta_abs returns ``fit`` unchanged.

    Parameters
    ----------
    wl : Whitened
        The GLS likelihood to scan under; its model's bounds of delta_abs
        bound the grid.
    fit : FitSummary
        A fit under ``wl``: its other parameters are held on the grid.
    names : sequence of str
        The parameters refined from the grid's best value (delta_abs is held
        there unless it is one of them).
    delta_step : float
        Step of the grid, IPUT.

    Returns
    -------
    FitSummary
        The refit from the grid's best value when its -ln L is below
        ``fit``'s, else ``fit`` itself.

    Raises
    ------
    TypeError
        ``wl`` is not a :class:`Whitened` likelihood.
    """
    if not isinstance(wl, Whitened):
        raise TypeError(f"wl must be a Whitened likelihood, got {type(wl).__name__}")
    model = wl.model
    if "delta_abs" not in model.parameter_names:
        return fit
    upper = model.parameter("delta_abs").upper
    grid = np.arange(0.0, upper + 0.5 * delta_step, delta_step)
    vals = np.array([wl.neg_log_lik(dict(fit.params, delta_abs=float(d))) for d in grid])
    k = int(np.argmin(vals))
    if vals[k] < fit.neg_log_lik:
        new = _gls_refine(wl, dict(fit.params, delta_abs=float(grid[k])), names)
        if new.neg_log_lik < fit.neg_log_lik:
            return new
    return fit


#: Starts of delta_abs for :func:`threshold_starts`, IPUT (the scan's units; values above
#: delta_abs's upper bound are left out).
THRESHOLD_STARTS = tuple(np.round(np.arange(1, 9) * 0.0025, 4))


def threshold_starts(wl: Whitened, fit: FitSummary, names: Sequence[str], *,
                     scan: bool = True, starts: Sequence[float] = THRESHOLD_STARTS
                     ) -> FitSummary:
    """The best of ``fit`` and refits from other values of delta_abs.

    For each start (a value of delta_abs) the parameters ``names`` are
    refined with delta_abs held there (or from there, when ``names`` holds
    delta_abs), then delta_abs is scanned (with ``scan``).  A grid of starts,
    like the paper's own threshold scan: -ln L is not smooth enough in
    delta_abs for a gradient method to cross between basins.

    The crisp dead zone makes -ln L piecewise smooth in delta_abs, and the
    other parameters adapt to a wrong threshold: a fit that starts from one
    basin (the test's, at the base model's delta_abs) can stay there while a
    scan at its parameters keeps the wrong delta_abs.  On 40 closed-loop runs
    with a 0.8-rad/s washout, fitted on the whole band with the vestibular
    channel at 8x, the reported fit sat 1.6-17 units of -ln L above a fit
    made from the truth in 8 (its delta_abs 0.001-0.0105, the true 0.0075);
    with these starts (in every round of :func:`final_fit`) each of the 8
    reaches that fit's -ln L or a better one (``docs/diagnose-evidence.md``,
    *The reported fit*).  A model without delta_abs returns ``fit``.

    Parameters
    ----------
    wl : Whitened
        The GLS likelihood of the fits.
    fit : FitSummary
        A fit under ``wl``; each start is its parameters with delta_abs
        replaced.
    names : sequence of str
        The parameters refined from each start.
    scan : bool
        Scan delta_abs (:func:`scan_threshold`) after each refinement.
    starts : sequence of float
        The values of delta_abs to start from, IPUT (default
        :data:`THRESHOLD_STARTS`: 0.0025 to 0.02 in steps of 0.0025); those
        outside [0, delta_abs's upper bound] are skipped.

    Returns
    -------
    FitSummary
        The refit with the lowest -ln L when that is more than 1e-6 below
        ``fit``'s, else ``fit`` itself.

    Raises
    ------
    TypeError
        ``wl`` is not a :class:`Whitened` likelihood.
    ValueError
        A start that is not a finite number.
    """
    if not isinstance(wl, Whitened):
        raise TypeError(f"wl must be a Whitened likelihood, got {type(wl).__name__}")
    starts = tuple(starts)
    if not all(isinstance(d, (int, float, np.integer, np.floating)) and math.isfinite(d)
               for d in starts):
        raise ValueError(f"starts must be finite values of delta_abs, got {starts!r}")
    model = wl.model
    if "delta_abs" not in model.parameter_names:
        return fit
    upper = model.parameter("delta_abs").upper
    best = fit
    for d in starts:
        if not 0.0 <= d <= upper:
            continue
        p = dict(fit.params, delta_abs=float(d))
        trial = _gls_refine(wl, p, names)
        if scan:
            trial = scan_threshold(wl, trial, names)
        if trial.neg_log_lik < best.neg_log_lik - 1e-6:
            best = trial
    return best


def own_noise(model: PilotModel, recording: Recording, params: Mapping[str, float],
              noise: NoiseModel) -> NoiseModel:
    """The noise model estimated again from ``model``'s residual at ``params`` (AR order by
    BIC; ``noise``'s low-pass, decimation and skip), or ``noise`` itself where the model's
    response is not finite.

    Parameters
    ----------
    model : PilotModel
        The model whose residual is taken (e.g. the extended one).
    recording : Recording
        The recording (the low-pass is designed again from ``noise.omega_c``
        at its sample interval).
    params : mapping of str to float
        ``model``'s parameters at which the residual is taken.
    noise : NoiseModel
        The noise model to re-estimate: its ``omega_c`` and ``skip`` are kept.

    Returns
    -------
    NoiseModel
        The new noise model, or ``noise`` itself (the same object) where the
        residual is not finite.

    Raises
    ------
    TypeError
        ``noise`` is not a NoiseModel.
    """
    if not isinstance(noise, NoiseModel):
        raise TypeError(f"noise must be a NoiseModel, got {type(noise).__name__}")
    eps = Likelihood(model, recording).residual(params)
    if not np.all(np.isfinite(eps)):
        return noise
    return noise_model(eps, recording.dt, skip=noise.skip, omega_c=noise.omega_c)


def final_fit(ext: Extension, base_model: PilotModel, recording: Recording, fit: FitSummary,
              noise: NoiseModel, *, rounds: int = 3) -> tuple[FitSummary, NoiseModel]:
    """The fit of a chosen extension that is reported: its own noise model, delta_abs rescanned.

    The test holds two things at the base model's values, as it must (both
    models under one likelihood): the AR noise model, estimated from the base
    model's residual, and delta_abs, scanned by the base fit.  Both are wrong
    for the extended model when the base model misses something: the base
    residual carries the misfit, which its AR model whitens as if it were
    remnant, and the base model's delta_abs is biased by it.  Here, ``rounds``
    times: the AR model is estimated again from the extended model's
    residual (order by BIC, the same low-pass and decimation), the extended
    model is refitted under it, also from other values of delta_abs
    (:func:`threshold_starts`, the best kept), and its delta_abs scanned
    again (:func:`scan_threshold`, repeated until the scan keeps delta_abs;
    an entry that refines delta_abs refines it with the rest instead).  On 160
    closed-loop runs with a 6-rad/s platform (``analyses/prove_diagnose.py
    --final-fit-check``) the bandwidth's mean went from 6.32 to 6.08 rad/s
    and its spread from 0.58 to 0.39, delta_abs from 0.0106 +- 0.0034 to
    0.0079 +- 0.0015 (true 0.0075); with a washout at 0.8 rad/s, delta_abs
    from 0.0030 +- 0.0036 to 0.0076 +- 0.0016 and omega_w's spread from
    0.083 to 0.066.  But this fit's own standard errors are then too small
    (omega_w's 1.4 times: in the closed loop the dead zone gives the
    estimates a heavy tail that the local curvature does not see);
    :meth:`CandidateResult.report_fit` reports its
    estimates with the test's standard errors, which cover them
    (``docs/diagnose-evidence.md``, *The reported fit*).

    Parameters
    ----------
    ext : Extension
        The chosen catalogue entry (fitted by GLS).
    base_model : PilotModel
        The base model it extends.
    recording : Recording
    fit : FitSummary
        The extended model's fit in the test (the start).
    noise : NoiseModel
        The test's noise model: its low-pass, decimation and skip are kept.
    rounds : int
        How often the noise model is estimated again.

    Returns
    -------
    fit : FitSummary
        ``refined``: the extended model's parameters except delta_abs
        (unless the entry refines it), with their covariance under ...
    noise : NoiseModel
        ... this noise model, the last one estimated.  The test's -ln L are
        not changed by any of it.
    """
    if not (isinstance(rounds, (int, np.integer)) and rounds >= 1):
        raise ValueError(f"rounds must be an integer >= 1, got {rounds!r}")
    if not isinstance(ext, Extension) or ext.likelihood != "gls":
        raise ValueError(f"ext must be a catalogue Extension fitted by GLS, got {ext!r}")
    model = ext.build(base_model)
    names = tuple(n for n in model.parameter_names
                  if ext.refine_threshold or n != "delta_abs")
    for _ in range(rounds):
        new = own_noise(model, recording, fit.params, noise)
        if new is noise:
            break  # the model's response is not finite at the fit
        noise = new
        wl = Whitened(model, recording, noise)
        fit = threshold_starts(wl, _gls_refine(wl, fit.params, names), names,
                               scan=not ext.refine_threshold)
        for _ in range(0 if ext.refine_threshold else 4):
            # scan again until delta_abs is the grid's best at the refined parameters
            was = fit.params.get("delta_abs")
            fit = scan_threshold(wl, fit, names)
            if fit.params.get("delta_abs") == was:
                break
    return fit, noise


def report_final_fit(chosen: "CandidateResult", base_model: PilotModel, recording: Recording,
                     noise: NoiseModel, *, intervals: bool = True) -> None:
    """Make ``chosen``'s reported fit: :func:`final_fit` from its test's fit, then (with
    ``intervals``) the profile-likelihood intervals of its new parameters, which may move
    the fit to a better point (:func:`bayespilot.diagnose.profile.profile_intervals`); the
    test's statistics and standard errors are kept (:meth:`CandidateResult.report_fit`).

    Parameters
    ----------
    chosen : CandidateResult
        A catalogue entry fitted by GLS, with its test's fit.
    base_model : PilotModel
    recording : Recording
    noise : NoiseModel
        The test's noise model.
    intervals : bool
        Make the profile intervals (``chosen.interval``).
    """
    from .profile import profile_intervals

    ext = get_extension(chosen.physics)
    if chosen.fit is None:
        raise ValueError(f"{chosen.physics} has no fit to refine")
    fit, own = final_fit(ext, base_model, recording, chosen.fit, noise)
    found: dict[str, Any] = {}
    if intervals:
        fit, found = profile_intervals(Whitened(ext.build(base_model), recording, own), fit,
                                       ext.new_parameters, fit.refined,
                                       scan=not ext.refine_threshold, test_stderr=chosen.stderr)
    chosen.report_fit(fit, own, FINAL_FIT)
    chosen.interval = found


def json_number(x: float) -> float | str | None:
    """A number as a diagnosis file writes it: finite as a float, NaN (missing) as None,
    infinities as ``"inf"``/``"-inf"`` (an exact flat top's infinite delta BIC is a finding,
    not a missing value; standard JSON has no Infinity).  :func:`bayespilot._files.number`
    reads all three back.

    Parameters
    ----------
    x : float
        The number (a numpy scalar or an int is taken as a float).

    Returns
    -------
    float, str or None
    """
    x = float(x)
    return x if math.isfinite(x) else (None if math.isnan(x) else ("inf" if x > 0 else "-inf"))


@dataclass(eq=False)  # by identity: == on its arrays would be ambiguous
class CandidateResult:
    """The test of one catalogue extension against the base model.

    Attributes
    ----------
    physics : str
        Catalogue name.
    testable : bool
        False when the recording lacks what it needs (e.g. no ``theta`` column).
    reason : str
        Why it is not testable, or how it was tested.
    delta_neg_log_lik : float
        -ln L(base) - -ln L(extension) on the decision likelihood (>= 0).
    statistic : float
        2 delta_neg_log_lik (GLS) or the flat-top count (saturation).
    df : int
    p_value : float
        The test's p-value.  On the GLS likelihood the asymptotic one
        (:func:`lr_p_value`: chi2(df), or the chi-bar-squared mixture for a
        one-parameter boundary null), unless the test was calibrated (with
        ``n_calibrate > 0``, the test of each candidate chosen in turn;
        ``calibration`` is then not None): then the calibrated one,
        ``calibration.p_value`` (the reference's at the statistic over
        max(1, scale)).  For saturation the flat-top test's (never
        calibrated).
    delta_bic : float
        BIC(base) - BIC(extension); > 0 favours the extension.
    log_bayes_factor : float
        ln BF(extension : base) ~ delta_bic / 2 (Schwarz approximation).
    params : dict
        The extension's new parameters at the fit.
    stderr : dict
        Their standard errors (and those of the other refined parameters).
    all_params : dict
        Every parameter of the extended model at the fit.
    signature_score : float
        How strongly the located evidence shows this entry's signature
        (max of -log10 p over its signature keys; 0 when nothing is located).
    justified : bool
        p_value < the per-candidate level.
    fit : FitSummary or None
        The extension's fit behind the test (after :meth:`report_fit`, the
        reported one); for a pooled test only the pooled -ln L.  None when
        no fit was made (not testable, the fit failed) and after
        :meth:`from_dict`.
    model : PilotModel or None
        The extended model that was fitted; None as for ``fit``.
    calibration : Calibration or None
        The parametric bootstrap's calibration of this test
        (:mod:`bayespilot.diagnose.calibrate`), when it was made; ``p_value``
        is then its calibrated p-value.
    refit : dict or None
        For the chosen extension: how its reported estimates (``params``,
        ``all_params``) were made (:func:`final_fit`), the test's estimates
        (``test_params``), the refit's own standard errors (``own_stderr``:
        too small on repeated closed-loop runs, so ``stderr`` stays the
        test's; ``docs/diagnose-evidence.md``, *The reported fit*) and its noise model.
    noise : NoiseModel, list of NoiseModel or None
        The noise model of the reported fit (one per run for a pooled
        diagnosis), once :meth:`report_fit` or :meth:`record_refit` has set it.
    interval : dict
        Profile-likelihood intervals of the new parameters
        (:class:`~bayespilot.diagnose.profile.ProfileInterval`), for the
        chosen extension of a single-run diagnosis; empty otherwise.
    boundary_null : bool or None
        Whether the base model is the extension at the edge of its parameter
        range (its catalogue entry's ``boundary_null`` when it was tested,
        :func:`lr_verdict`): with ``df`` 1 the test's reference was the
        chi-bar-squared mixture (:func:`lr_p_value`, :func:`critical_value`).
        Kept in the result file, so a file of an entry not registered where
        it is read still says which test decided.  None: not recorded (a
        result built by hand); the report then asks the catalogue.
    """

    physics: str
    testable: bool
    reason: str = ""
    delta_neg_log_lik: float = 0.0
    statistic: float = 0.0
    df: int = 0
    p_value: float = 1.0
    delta_bic: float = -math.inf
    log_bayes_factor: float = -math.inf
    params: dict[str, float] = field(default_factory=dict)
    stderr: dict[str, float] = field(default_factory=dict)
    all_params: dict[str, float] = field(default_factory=dict)
    signature_score: float = 0.0
    justified: bool = False
    fit: Any = None
    model: Any = None
    calibration: Any = None
    refit: dict[str, Any] | None = None
    noise: Any = None
    interval: dict[str, Any] = field(default_factory=dict)
    boundary_null: bool | None = None

    def __repr__(self) -> str:
        """One line: the test's outcome and the new parameters (the dataclass's printed the
        fit's covariance, the model and the noise model's taps, thousands of characters)."""
        def g(x):  # never raises: a repr of a half-built or hand-made result
            try:
                return f"{float(x):.4g}"
            except (TypeError, ValueError):
                return repr(x)

        if not self.testable:
            return (f"CandidateResult(physics={self.physics!r}, testable=False, "
                    f"reason={self.reason!r})")
        params = ", ".join(f"{k!r}: {g(v)}" for k, v in self.params.items())
        return (f"CandidateResult(physics={self.physics!r}, justified={self.justified}, "
                f"p_value={g(self.p_value)}{', calibrated=True' if self.calibration else ''}, "
                f"delta_neg_log_lik={g(self.delta_neg_log_lik)}, delta_bic={g(self.delta_bic)}, "
                f"params={{{params}}})")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of the attributes except ``fit``, ``model`` and ``noise`` (the
        calibration and intervals by their own ``to_dict``; NaN as None, infinities as
        ``"inf"``/``"-inf"``: :func:`json_number`)."""
        num = json_number
        return {"physics": self.physics, "testable": self.testable, "reason": self.reason,
                "delta_neg_log_lik": num(self.delta_neg_log_lik), "statistic": num(self.statistic),
                "df": self.df, "p_value": num(self.p_value), "delta_bic": num(self.delta_bic),
                "log_bayes_factor": num(self.log_bayes_factor),
                "params": {k: num(v) for k, v in self.params.items()},
                "stderr": {k: num(v) for k, v in self.stderr.items()},
                "all_params": {k: num(v) for k, v in self.all_params.items()},
                "signature_score": num(self.signature_score), "justified": self.justified,
                "calibration": None if self.calibration is None else self.calibration.to_dict(),
                "refit": None if self.refit is None else {
                    k: ({n: num(x) for n, x in v.items()} if k in ("test_params", "own_stderr")
                        else v)
                    for k, v in self.refit.items()},
                "interval": {k: v.to_dict() for k, v in self.interval.items()},
                "boundary_null": self.boundary_null}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "CandidateResult":
        """The CandidateResult a :meth:`to_dict` holds, as a result file keeps it: its
        numbers, calibration and profile intervals, without the fit, the extended model and
        the noise model objects (``fit``, ``model`` and ``noise`` are None; the reported
        fit's noise model stays in ``refit["noise_model"]`` as a dict).

        Parameters
        ----------
        d : mapping
            A :meth:`to_dict`, as read from JSON; only ``physics`` and
            ``testable`` are required (the others take their defaults).  A
            file written before ``boundary_null`` was kept has none: it is
            then read from how the test was made (``reason``, the
            chi-bar-squared reference :func:`lr_verdict` names).

        Returns
        -------
        CandidateResult

        Raises
        ------
        KeyError
            If ``physics`` or ``testable`` is missing.
        """
        from .calibrate import Calibration
        from .profile import ProfileInterval

        refit = d.get("refit")
        if refit is not None:
            refit = {k: (numbers(v) if k in ("test_params", "own_stderr") else v)
                     for k, v in refit.items()}
        cal = d.get("calibration")
        boundary = d.get("boundary_null")
        if "boundary_null" not in d:  # a file written before the field: how its test was
            # made says it (null: not recorded, a result built by hand, stays None)
            boundary = int(d.get("df", 0)) == 1 and _MIXTURE_TEXT in (d.get("reason") or "")
        return cls(d["physics"], bool(d["testable"]), d.get("reason", ""),
                   *(number(d.get(k, default)) for k, default in (
                       ("delta_neg_log_lik", 0.0), ("statistic", 0.0))),
                   int(d.get("df", 0)), number(d.get("p_value", 1.0)),
                   number(d.get("delta_bic", "-inf")), number(d.get("log_bayes_factor", "-inf")),
                   numbers(d.get("params")), numbers(d.get("stderr")),
                   numbers(d.get("all_params")), number(d.get("signature_score", 0.0)),
                   bool(d.get("justified", False)),
                   calibration=None if cal is None else Calibration.from_dict(cal), refit=refit,
                   interval={k: ProfileInterval.from_dict(k, v)
                             for k, v in (d.get("interval") or {}).items()},
                   boundary_null=None if boundary is None else bool(boundary))

    def report_fit(self, fit: "FitSummary", noise: "NoiseModel", how: str) -> None:
        """Report the estimates of ``fit`` (of this candidate's extended model) instead of
        the test's; the test's statistics and standard errors are kept (measured to cover
        the reported estimates where the refit's own do not), the test's estimates and the
        refit's standard errors move to ``refit``.

        Changes this result in place: ``params``, ``all_params``, ``fit``,
        ``refit`` and ``noise``.

        Parameters
        ----------
        fit : FitSummary
            A fit of this candidate's extended model (:attr:`model`), e.g. by
            :func:`final_fit`.
        noise : NoiseModel
            The noise model ``fit`` was made with.
        how : str
            How the fit was made, recorded in ``refit["how"]``.
        """
        self.record_refit(fit.params, fit.stderr, noise, how,
                          [self.all_params.get("delta_abs"), fit.params.get("delta_abs")])
        if self.model is not None:
            self.all_params = dict(self.model.as_dict(self.model.full_vector(fit.params),
                                                      full=True))
        self.fit = fit

    def record_refit(self, params: Mapping[str, float], own_stderr: Mapping[str, float],
                     noise: Any, how: str, delta_abs: list, **more: Any) -> None:
        """The part of :meth:`report_fit` a pooled diagnosis shares: the new parameters'
        estimates from ``params``, the test's and the refit's standard errors kept in
        ``refit`` with ``how``, ``delta_abs`` (before, after) and ``more``; ``noise`` (a
        NoiseModel, or one per run) stored.

        Changes this result in place: ``params``, ``refit`` and ``noise``.

        Parameters
        ----------
        params : mapping of str to float
            The refit's estimates, by name; those of this candidate's new
            parameters (the keys of ``params`` already set) are taken.
        own_stderr : mapping of str to float
            The refit's own standard errors, by name.
        noise : NoiseModel or list of NoiseModel
            The refit's noise model, or one per run (pooled).
        how : str
            How the refit was made.
        delta_abs : list
            delta_abs before and after the refit, IPUT (None where the model
            has none).
        **more : Any
            Further entries of ``refit``.
        """
        noises = noise if isinstance(noise, list) else None
        self.refit = {"how": how, "test_params": dict(self.params),
                      "own_stderr": {n: float(v) for n, v in own_stderr.items()},
                      "noise_model": ([nz.to_dict() for nz in noises] if noises is not None
                                      else noise.to_dict()),
                      "delta_abs": delta_abs, **more}
        self.params = {n: float(params[n]) for n in self.params}
        self.noise = noise


def lr_p_value(stat: float, ext: Extension) -> float:
    """p-value of the likelihood-ratio statistic ``stat`` = 2 d(-ln L) for extension ``ext``.

    chi2(df); for a one-parameter boundary null the chi-bar-squared mixture
    0.5 chi2(0) + 0.5 chi2(1) (Self & Liang 1987).

    Parameters
    ----------
    stat : float
        The likelihood-ratio statistic 2 (-ln L_base - -ln L_ext), >= 0.
    ext : Extension
        The extension tested: its ``df`` and ``boundary_null``.

    Returns
    -------
    float
        The asymptotic p-value, P(T >= ``stat``) under the null: chi2(df)'s
        survival function at ``stat``; for a one-parameter boundary null
        half of chi2(1)'s for ``stat > 0`` and 1 at ``stat = 0`` (the
        mixture's point mass at 0 counts); 1 for an entry without new
        parameters (df = 0).
    """
    p = float(stats.chi2.sf(stat, ext.df)) if ext.df > 0 else 1.0
    if ext.boundary_null and ext.df == 1 and stat > 0:
        return 0.5 * p
    return p


def critical_value(df: int, boundary_null: bool, level: float) -> float:
    """The likelihood-ratio statistic 2 d(-ln L) at which :func:`lr_p_value` reaches ``level``.

    Parameters
    ----------
    df : int
        The test's degrees of freedom (>= 1).
    boundary_null : bool
        Whether the null is on a boundary (:attr:`CandidateResult.boundary_null`,
        the catalogue entry's): with ``df`` 1 the chi-bar-squared mixture's
        quantile, chi2(1)'s at twice ``level``.
    level : float
        The level (per candidate).

    Returns
    -------
    float
        chi2(df)'s upper ``level`` quantile; for a one-parameter boundary null
        chi2(1)'s upper ``2 level`` quantile.
    """
    return float(stats.chi2.isf(2.0 * level if boundary_null and df == 1 else level, df))


#: How a test with the chi-bar-squared reference is named in its ``reason``
#: (:func:`lr_verdict`) ...
_BOUNDARY_TEXT = "boundary null"
#: ... and the reference itself, which files written before ``boundary_null`` was kept are
#: read by (:meth:`CandidateResult.from_dict`; not the words "boundary null", which a
#: reason of one's own can hold as "not a boundary null")
_MIXTURE_TEXT = "0.5 chi2(0) + 0.5 chi2(1)"


@dataclass(frozen=True)
class LRVerdict:
    """The likelihood-ratio test of one extension against the base model (:func:`lr_verdict`).

    Attributes
    ----------
    delta_neg_log_lik : float
        d = -ln L(base) - -ln L(extension), >= 0.
    statistic : float
        2 d.
    df : int
    p_value : float
        :func:`lr_p_value` at ``statistic``.
    delta_bic : float
        ``statistic`` - df ln m.
    how : str
        How the test was made (a :class:`CandidateResult`'s ``reason``).
    boundary_null : bool
        The catalogue entry's ``boundary_null``.
    """

    delta_neg_log_lik: float
    statistic: float
    df: int
    p_value: float
    delta_bic: float
    how: str
    boundary_null: bool

    def result(self, physics: str, params: Mapping[str, float], stderr: Mapping[str, float],
               all_params: Mapping[str, float]) -> "CandidateResult":
        """The testable :class:`CandidateResult` of this test (log Bayes factor delta_bic / 2).

        Parameters
        ----------
        physics : str
            The catalogue name tested.
        params : mapping of str to float
            The extension's new parameters at the fit.
        stderr : mapping of str to float
            Their standard errors (and those of the other refined parameters).
        all_params : mapping of str to float
            Every parameter of the extended model at the fit.

        Returns
        -------
        CandidateResult
        """
        return CandidateResult(physics, True, self.how,
                               delta_neg_log_lik=self.delta_neg_log_lik,
                               statistic=self.statistic, df=self.df, p_value=self.p_value,
                               delta_bic=self.delta_bic, log_bayes_factor=self.delta_bic / 2.0,
                               params=dict(params), stderr=dict(stderr),
                               all_params=dict(all_params), boundary_null=self.boundary_null)


def lr_verdict(ext: Extension, d: float, m: float | None = None, *, penalty: float | None = None,
               test: str = "GLS likelihood-ratio test") -> LRVerdict:
    """The likelihood-ratio test of ``ext`` for an improvement ``d`` in -ln L.

    The one place a GLS candidate's statistic, p-value, delta BIC and the
    description of its test are made (single-run, pooled, :func:`retest`).

    Parameters
    ----------
    ext : Extension
        The extension tested: its ``df`` and ``boundary_null``.
    d : float
        -ln L(base) - -ln L(extension), >= 0.
    m : float, optional
        The number of (whitened) samples of the BIC penalty df ln m.
    penalty : float, optional
        The BIC penalty itself, instead of ``m`` (a test made again against
        another reference keeps its own).
    test : str
        The first part of ``how``; the reference distribution follows.

    Returns
    -------
    LRVerdict

    Raises
    ------
    ValueError
        Neither ``m`` nor ``penalty`` given.
    """
    if penalty is None:
        if m is None:
            raise ValueError("lr_verdict needs m or penalty")
        penalty = ext.df * math.log(m)
    stat = 2.0 * d
    mixture = ext.boundary_null and ext.df == 1
    reference = f"{_MIXTURE_TEXT} ({_BOUNDARY_TEXT})" if mixture else f"chi2({ext.df})"
    return LRVerdict(d, stat, ext.df, lr_p_value(stat, ext), stat - penalty,
                     f"{test}, {reference}", bool(ext.boundary_null))


def fit_candidate(ext: Extension, base_model: PilotModel, recording: Recording,
                  base: FitSummary, noise: NoiseModel, *, profile_noise: bool = False,
                  extra_starts: Sequence[Mapping[str, float]] = ()
                  ) -> tuple[CandidateResult, Whitened | None]:
    """Fit one GLS extension from the base fit (multi-start over its new parameters) and test it.

    ``profile_noise``: re-estimate the AR coefficients at the extension's fit
    (:func:`refit_with_noise`); ``base`` must then have been profiled the same way.
    ``extra_starts``: more starting points, each a full parameter set of the
    extended model (e.g. its fit on the low-passed band, :func:`guide_fits`).

    Parameters
    ----------
    ext : Extension
        The catalogue entry to test, one fitted by GLS (not checked here).
    base_model : PilotModel
        The base model it extends.
    recording : Recording
    base : FitSummary
        The base model's GLS fit: the reference -ln L of the test, and every
        start's parameters (the new ones from each of ``ext.starts``).
    noise : NoiseModel
        The decision likelihood's noise model, that of ``base``.
    profile_noise : bool
        See above.
    extra_starts : sequence of mapping of str to float
        See above; ``base``'s parameters fill what a start does not give,
        names the extended model does not have are ignored.

    Returns
    -------
    result : CandidateResult
        The test: d(-ln L) (>= 0), statistic, p-value (:func:`lr_p_value`),
        delta BIC, the new parameters' estimates and every refined
        parameter's standard error, ``fit`` and ``model`` set.  Not testable
        (``testable`` False, why in ``reason``) when the recording lacks a
        column the entry needs or the fit failed from every start.
    wl : Whitened or None
        The extended model's GLS likelihood of the fits (under the
        re-estimated noise model with ``profile_noise``); None when the
        recording lacks a column the entry needs.

    Raises
    ------
    TypeError
        ``noise`` is not a NoiseModel.
    ValueError
        The recording is too short to skip ``noise.skip`` samples.
    """
    missing = [c for c in ext.needs if c not in recording]
    if missing:
        return CandidateResult(ext.name, False, f"needs the recording column(s) {', '.join(missing)}",
                               df=ext.df), None
    model = ext.build(base_model)
    wl = Whitened(model, recording, noise)
    names = tuple(n for n in model.parameter_names
                  if ext.refine_threshold or n != "delta_abs")
    best: FitSummary | None = None
    starts = []
    for st in ext.starts or ({},):
        start = dict(base.params)
        start.update(st)
        starts.append(start)
    starts += [dict(base.params, **{k: v for k, v in es.items() if k in model.parameter_names})
               for es in extra_starts]
    for start in starts:
        try:
            f = _gls_refine(wl, start, names)
        except (ValueError, np.linalg.LinAlgError):
            continue
        if best is None or f.neg_log_lik < best.neg_log_lik:
            best = f
    if best is None:
        return CandidateResult(ext.name, False, "the fit failed from every start", df=ext.df), wl
    if profile_noise:
        best, noise = refit_with_noise(model, recording, best, noise, names)
        wl = Whitened(model, recording, noise)
    verdict = lr_verdict(ext, max(0.0, base.neg_log_lik - best.neg_log_lik), wl.m)
    res = verdict.result(ext.name, {n: best.params[n] for n in ext.new_parameters}, best.stderr,
                         model.as_dict(model.full_vector(best.params), full=True))
    res.fit = best
    res.model = model
    return res, wl


def low_band_base(base_model: PilotModel, recording: Recording, start: Mapping[str, float],
                  skip: int) -> tuple[NoiseModel, FitSummary]:
    """The noise model and GLS base fit on the band low-passed at :data:`OMEGA_C`, from ``start``
    (the low-band reference of :func:`guide_fits` and of the pooled guide)."""
    lik0 = Likelihood(base_model, recording)
    noise = noise_model(lik0.residual(start), recording.dt, skip=skip, omega_c=OMEGA_C)
    _, base = fit_base_gls(base_model, recording, start, noise)
    return noise, base


def guide_fits(names: Sequence[str], base_model: PilotModel, recording: Recording,
               start: Mapping[str, float], skip: int, get: Callable[[str], Extension]
               ) -> dict[str, dict[str, float]]:
    """Each extension fitted on the band low-passed at :data:`OMEGA_C`: starts for a wider band.

    On the whole band the likelihood is sharp in the delays (the phase of
    e^{-s tau} at tens of rad/s) and has local optima that the low-passed
    likelihood smooths over: an extension fitted on the whole band from the
    base model's parameters can stop in one (a 6-rad/s platform, fitted at
    55 rad/s with the truth 30 units worse there, in the proof study), where
    on the low-passed band it reaches the truth.  Its low-band optimum is
    then a start for the whole-band fit.  ``get`` maps a name to its
    :class:`~bayespilot.diagnose.catalogue.Extension`; entries not fitted by
    GLS are left out.  Returns name -> the extended model's parameters.

    Parameters
    ----------
    names : sequence of str
        The catalogue names to fit.
    base_model : PilotModel
        The base model they extend.
    recording : Recording
    start : mapping of str to float
        The base model's parameters (e.g. its Eq. 4 fit): the low-band noise
        model is estimated from the residual there and the low-band GLS base
        fit starts there (:func:`low_band_base`).
    skip : int
        Samples at the start of the record left out of the likelihood.
    get : callable
        ``get(name) -> Extension`` (:func:`~bayespilot.diagnose.catalogue.get_extension`).

    Returns
    -------
    dict of str to dict of str to float
        Name -> the extended model's parameters at its low-band fit, for the
        GLS entries with a fit (an entry not testable on the recording, or
        whose fit failed from every start, is left out too).

    Raises
    ------
    ValueError
        The residual at ``start`` is not finite, or the recording is too
        short to skip ``skip`` samples or sampled too slowly for the
        low-pass at :data:`OMEGA_C` (:func:`noise_model`, :class:`Whitened`).
    """
    noise, base = low_band_base(base_model, recording, start, skip)
    refined = None
    out: dict[str, dict[str, float]] = {}
    for name in names:
        ext = get(name)
        if ext.likelihood != "gls":
            continue
        ref = base
        if ext.refine_threshold:
            refined = refined or refine_threshold(base_model, recording, base, noise)
            ref = refined
        res, _ = fit_candidate(ext, base_model, recording, ref, noise)
        if res.fit is not None:
            out[name] = dict(res.fit.params)
    return out


def refine_threshold(model: PilotModel, recording: Recording, base: FitSummary,
                     noise: NoiseModel) -> FitSummary:
    """The GLS base fit with delta_abs refined too (from the scan's value), never worse.

    The reference of an extension that refines delta_abs (``threshold-shape``):
    against the scanned base, the continuous refinement of delta_abs alone
    improved correct-model fits by about 0.2 in -ln L per run (twice the
    chi-bar-squared null's mean in the single-run proof study's controls).

    Parameters
    ----------
    model : PilotModel
        The base model.
    recording : Recording
    base : FitSummary
        Its GLS fit with delta_abs scanned (:func:`fit_base_gls`): the start.
    noise : NoiseModel
        The decision likelihood's noise model.

    Returns
    -------
    FitSummary
        The fit with every free parameter refined, delta_abs included, when
        its -ln L is below ``base``'s, else ``base`` itself.

    Raises
    ------
    TypeError
        ``noise`` is not a NoiseModel.
    ValueError
        The recording is too short to skip ``noise.skip`` samples.
    """
    wl = Whitened(model, recording, noise)
    fit = _gls_refine(wl, base.params, model.parameter_names)
    return fit if fit.neg_log_lik < base.neg_log_lik else base


def null_refit(ext: Extension, base_model: PilotModel, recording: Recording,
               candidate: CandidateResult, noise: NoiseModel) -> FitSummary | None:
    """The base model refitted from an extension's fit with the extension taken out.

    The likelihood-ratio statistic needs the base model's *best* fit.  The
    base fit scans delta_abs at the other parameters' values and refines
    them locally; where the likelihood has two basins (a threshold near the
    edge of what the canal output reaches, or a likelihood sharp in delta_abs,
    as on the whole band with an oversampled motion channel) an extension
    can reach the other basin through its new parameter and end at the
    base model (a corner width at its lower bound, 1e-5 IPUT), so that the
    basin, not the physics, makes its "improvement": on the whole band at 8x
    that raised 17 false alarms on 48 controls, the soft corner's fit
    mostly near w_soft = 1e-5 and better by 4.5-41 in -ln L.  Starting the base model from the
    extension's parameters (its new ones dropped: the extended model at
    their null values is the base model) finds that basin for the base
    model too.  Returns ``None`` when there is nothing to refit from (below).

    Parameters
    ----------
    ext : Extension
        The candidate's catalogue entry.
    base_model : PilotModel
        The base model it extends.
    recording : Recording
    candidate : CandidateResult
        The candidate's test, with its fit (``candidate.fit``).
    noise : NoiseModel
        The decision likelihood's noise model (the test's).

    Returns
    -------
    FitSummary or None
        The base model's GLS fit from the candidate's parameters
        (:func:`null_refit_from`), not necessarily better than the base fit;
        None when the candidate has no fit, is not testable or not fitted by
        GLS, or the refit failed.

    Raises
    ------
    TypeError
        ``noise`` is not a NoiseModel.
    """
    fit = candidate.fit
    if fit is None or not candidate.testable or ext.likelihood != "gls":
        return None
    return null_refit_from(ext, base_model, recording, fit.params, noise)


def null_refit_from(ext: Extension, base_model: PilotModel, recording: Recording,
                    params: Mapping[str, float], noise: NoiseModel) -> FitSummary | None:
    """:func:`null_refit` from the extended model's parameters ``params`` (its new ones ignored).

    Parameters
    ----------
    ext : Extension
        The extension ``params`` are of: delta_abs is refined with the rest
        if it refines it (``refine_threshold``), else held.
    base_model : PilotModel
        The base model it extends.
    recording : Recording
    params : mapping of str to float
        The extended model's parameters by name; the base model's among them
        are the start (any it lacks start at the model's defaults).
    noise : NoiseModel
        The decision likelihood's noise model.

    Returns
    -------
    FitSummary or None
        The base model's GLS fit from there; None when it raised ValueError
        (e.g. a recording too short to skip ``noise.skip`` samples) or
        LinAlgError.

    Raises
    ------
    TypeError
        ``noise`` is not a NoiseModel.
    """
    start = {n: params[n] for n in base_model.parameter_names if n in params}
    names = tuple(n for n in base_model.parameter_names
                  if ext.refine_threshold or n != "delta_abs")
    try:
        return _gls_refine(Whitened(base_model, recording, noise), start, names)
    except (ValueError, np.linalg.LinAlgError):
        return None


def retest(res: CandidateResult, ext: Extension, reference: float) -> CandidateResult:
    """``res`` tested again against a better reference -ln L of the base model (in place).

    Parameters
    ----------
    res : CandidateResult
        A candidate's test, with its fit.
    ext : Extension
        Its catalogue entry.
    reference : float
        The base model's -ln L on the decision likelihood to test against
        (e.g. its best fit found by :func:`null_refit`).

    Returns
    -------
    CandidateResult
        ``res`` itself.  When ``reference`` gives a smaller improvement than
        its test's, its ``delta_neg_log_lik``, ``statistic``, ``p_value``,
        ``delta_bic`` and ``log_bayes_factor`` are computed again (the same
        df ln m penalty); ``justified`` is not (the decision sets it).  Left
        as it was when ``reference`` is not better, or it has no fit, is not
        testable or not fitted by GLS.
    """
    if res.fit is None or not res.testable or ext.likelihood != "gls":
        return res
    d = max(0.0, reference - res.fit.neg_log_lik)
    if d >= res.delta_neg_log_lik:
        return res
    v = lr_verdict(ext, d, penalty=res.statistic - res.delta_bic)  # the same df ln m penalty
    res.delta_neg_log_lik, res.statistic, res.p_value = v.delta_neg_log_lik, v.statistic, v.p_value
    res.delta_bic, res.log_bayes_factor = v.delta_bic, v.delta_bic / 2.0
    res.boundary_null = v.boundary_null
    return res


# --- control saturation -------------------------------------------------------------------
def flat_tops(u: np.ndarray, *, min_run: int = 3, rtol: float = 1e-9) -> dict[str, Any]:
    """Samples of u at its extreme values in runs of at least ``min_run`` equal samples.

    Parameters
    ----------
    u : ndarray
        The control signal.
    min_run : int
        Shortest run of equal extreme samples counted as a flat top.
    rtol : float
        A sample is at an extreme value within ``rtol * max|u|`` of it (a
        quantised u is not widened here: its exact repeats are judged by the
        caller, ``diagnose._saturation``).

    Returns
    -------
    dict with ``flags`` (int array: +1 at the upper flat tops, -1 at the
    lower, 0 elsewhere), ``hi``, ``lo`` (the extreme values), ``n_samples``
    (flagged samples), ``n_runs``.
    """
    u = np.asarray(u, dtype=float)
    if u.ndim != 1 or u.size < min_run:
        raise ValueError("u must be 1-D with at least min_run samples")
    tol = rtol * float(np.max(np.abs(u)) + 1e-300)
    flags = np.zeros(u.size, dtype=np.int64)
    n_runs = 0
    for sgn, ext in ((1, float(np.max(u))), (-1, float(np.min(u)))):
        at = np.abs(u - ext) <= tol
        # runs of consecutive True
        d = np.diff(np.concatenate([[0], at.view(np.int8), [0]]))
        starts = np.flatnonzero(d == 1)
        ends = np.flatnonzero(d == -1)
        for s, e in zip(starts, ends):
            if e - s >= min_run:
                flags[s:e] = sgn
                n_runs += 1
    return {"flags": flags, "hi": float(np.max(u)), "lo": float(np.min(u)),
            "n_samples": int(np.count_nonzero(flags)), "n_runs": n_runs}


def _long_run_factor(ar: np.ndarray, eps: np.ndarray) -> float:
    """Long-run variance of an AR residual over its variance (>= 1 for positive correlation)."""
    a = np.asarray(ar, float)
    w = signal.lfilter(np.concatenate([[1.0], -a]), [1.0], eps)[a.size:]
    s1 = 1.0 - a.sum()
    if abs(s1) < 1e-12:
        return 1.0
    return float(max(1.0, np.var(w) / s1**2 / np.var(eps)))


def fit_censored(base_model: PilotModel, recording: Recording, start: Mapping[str, float],
                 tops: Mapping[str, Any]) -> tuple[FitSummary, float, float]:
    """Censored-likelihood (Tobit) fit of the pilot parameters to a clipped control.

    The model output is the unclipped command u_hat; samples flagged in
    ``tops`` are censored at the limits.  Returns (fit, -ln L at the start
    parameters with sigma profiled, sigma at the fit).  The covariance is
    the inverse Hessian of -ln L times the residual's long-run variance factor
    (from an AR model of the residual, :func:`fit_ar`): the Tobit likelihood
    treats samples as independent, and the factor approximately accounts for
    their correlation.

    Parameters
    ----------
    base_model : PilotModel
        The base model (its parameters except delta_abs are fitted).
    recording : Recording
    start : mapping of str to float
        The start parameters (e.g. the GLS base fit's); delta_abs is held at
        its value here.
    tops : mapping
        :func:`flat_tops` of the recording's u: ``flags`` (+1 and -1 at the
        censored samples, at the upper and lower limit), ``hi`` and ``lo``
        (the limits, rad).

    Returns
    -------
    fit : FitSummary
        The pilot parameters at the fit, -ln L of the censored likelihood
        (never above the start's), ``refined`` the parameters except
        delta_abs with their scaled covariance.
    neg_log_lik_start : float
        -ln L at ``start``, sigma profiled.
    sigma : float
        The noise standard deviation at the fit, rad.
    """
    from ..kernels._censored import censored_neg_log_lik

    lik = Likelihood(base_model, recording)
    names = tuple(n for n in base_model.parameter_names if n != "delta_abs")
    base = dict(base_model.as_dict(base_model.free_vector(start)))
    flags = np.asarray(tops["flags"], dtype=np.int64)
    lo_lim, hi_lim = float(tops["lo"]), float(tops["hi"])
    u = lik.u
    lo = np.array([base_model.parameter(n).lower for n in names] + [-30.0])
    hi = np.array([base_model.parameter(n).upper for n in names] + [5.0])

    def params_of(x):
        p = dict(base)
        p.update(zip(names, (float(v) for v in x[:-1])))
        return p

    def fun(x):
        p = params_of(x)
        y, J = lik.jacobian(p, names)
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(J))):
            return 1e30, np.zeros_like(x)
        sig = math.exp(x[-1])
        v, gy, ds = censored_neg_log_lik(u, y, flags, lo_lim, hi_lim, sig)
        g = np.concatenate([J.T @ gy, [ds * sig]])
        return v, g

    y0 = lik.response(base)
    free = flags == 0
    s0 = float(np.std((u - y0)[free])) + 1e-300
    x0 = np.concatenate([[base[n] for n in names], [math.log(s0)]])
    x0 = np.clip(x0, lo, hi)
    # -ln L at the start parameters, sigma profiled
    prof = optimize.minimize_scalar(lambda ls: fun(np.concatenate([x0[:-1], [ls]]))[0],
                                    bounds=(math.log(s0) - 3, math.log(s0) + 3), method="bounded")
    f_start = float(prof.fun)
    x0[-1] = prof.x
    sol = optimize.minimize(fun, x0, jac=True, method="L-BFGS-B", bounds=list(zip(lo, hi)),
                            options={"maxiter": 100})
    x = sol.x if sol.fun <= f_start else x0
    fval = float(min(sol.fun, f_start))
    # Hessian by central differences of the analytic gradient
    k = x.size
    H = np.empty((k, k))
    for j in range(k):
        h = 1e-4 * max(abs(x[j]), 1e-2)
        xp = x.copy()
        xm = x.copy()
        xp[j] += h
        xm[j] -= h
        H[:, j] = (fun(xp)[1] - fun(xm)[1]) / (2 * h)
    H = 0.5 * (H + H.T)
    eps = u - lik.response(params_of(x))
    ar = fit_ar(eps[free], max_order=20)
    factor = _long_run_factor(ar, eps[free]) if ar.size else 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cov = linalg.pinvh(H)[:-1, :-1] * factor
    fit = FitSummary(params_of(x), fval, names, cov, int(sol.nfev))
    return fit, f_start, math.exp(x[-1])

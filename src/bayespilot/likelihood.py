"""The time-domain likelihood of Eq. 4: a pilot model driven by a recording's inputs.

-ln L(theta) = N/2 ln s2(theta) + 1/(2 s2(theta)) sum_k eps(k|theta)^2,  eps = u - u_hat(theta)

with the output-error variance s2 profiled out (s2 = mean eps^2), which gives
N/2 ln(mean eps^2) + N/2.  u_hat is simulated from the MEASURED e and
theta_ddot_m at the recording's rate (Tustin discretisation, fractional
delays by linear interpolation; see ``kernels/_response.py``).

:class:`Likelihood` binds a model to a recording once (it precomputes the
channel inputs, e.g. the canal output i) and then evaluates single parameter
vectors or whole populations (:meth:`Likelihood.batch`, parallel over the
population), which is what the genetic algorithm and emcee call.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Mapping, Sequence

import numba
import numpy as np
from scipy import signal

from ._caller import warn_at_caller
from .forcing import columns_whole_periods, whole_periods_frequency
from .kernels import _coloured as C
from .kernels import _response as R
from .kernels import _segmented as SEG
from .model import FixedFilter, PilotModel
from .noise import ARNoise
from .recording import Recording, _columns_motion_gain

__all__ = ["Likelihood", "PerfectFitWarning", "SilentChannelWarning", "NotWholePeriodsWarning",
           "STARTUP_DISCARD", "COLOURED_DISCARD", "channel_inputs", "neg_log_lik",
           "model_response", "vaf", "whole_periods", "startup_discard", "coloured_discard"]

INITIAL_CONDITIONS = ("periodic", "rest")


class PerfectFitWarning(RuntimeWarning):
    """The model reproduces u to round-off, so s2 was floored and -ln L is a bound."""


class SilentChannelWarning(RuntimeWarning):
    """A channel's input is zero throughout the record, so its free parameters (e.g. the
    motion channel's K_m, tau_m, delta_abs on a run without motion) are not identified."""


class NotWholePeriodsWarning(RuntimeWarning):
    """``initial="periodic"`` on a record that is not a whole number of forcing periods, with
    less than the model's start-up (:func:`startup_discard`) left out of Eq. 4.

    The periodic start treats the record as one period of the forcing: the delays wrap
    across t = 0 and the neuromuscular filter is warmed up on the record's last seconds.
    A record cut mid-period jumps there, and the first 1-2 s of the residual are large even
    at the true parameters, which moves the estimates (a 40-s FT run without remnant,
    Gauss-Newton from the truth: K_v +6 %, T_vl -10 %, zeta_nm +11 %; with ``discard=2``
    all within 0.2 %).
    """


#: Seconds of a record's start that carry the model's start-up (the neuromuscular filter and
#: the delays) when its state at t = 0 is not known: what :func:`startup_discard` leaves out.
STARTUP_DISCARD = 2.0
#: Seconds of a record's start left out by default with an AR ("coloured") noise model, at most
#: a quarter of the record: what :func:`coloured_discard` leaves out.  The same start-up as
#: :data:`STARTUP_DISCARD` (one constant), which the whitening filter would amplify.
COLOURED_DISCARD = STARTUP_DISCARD


def whole_periods(recording: Recording) -> bool | None:
    """Whether a recording is known to hold a whole number of periods of its forcing functions.

    What ``initial="periodic"`` assumes (:class:`Likelihood`): a record of whole
    periods continues smoothly from its end to its start.

    Parameters
    ----------
    recording : Recording
        Read from its metadata's ``forcing`` (``base_frequency`` and the
        ``target`` and ``disturbance`` lines ``n``) if it has one: whole
        periods when one base frequency puts every line with a nonzero
        amplitude on a whole number of cycles of the record (n_samples * dt)
        and moves none by more than :data:`~bayespilot.forcing.SNAP_TOLERANCE`
        (0.05) cycle (a rounded base frequency, as printed in a paper, counts):
        :func:`~bayespilot.forcing.whole_periods_frequency`, the rule
        :func:`~bayespilot.diagnose.locate.forcing_of` reads it by.  Else from
        its ``f_t`` and ``f_d`` columns, either or both
        (:func:`~bayespilot.forcing.columns_whole_periods`, as the diagnosis
        reads them): whole periods when each it has that is not zero
        throughout continues smoothly from its last sample to its first (its
        second differences across the wrap no larger than 3 times the largest
        inside the record).

    Returns
    -------
    bool or None
        True or False; None when it is not known (no forcing in the
        metadata, neither an f_t nor an f_d column, or forcing functions that
        are zero throughout).

    Raises
    ------
    TypeError
        If ``recording`` is not a :class:`~bayespilot.recording.Recording`.

    Examples
    --------
    >>> from bayespilot.simulate import simulate
    >>> whole_periods(simulate(task="FD", motion_gain=1.0, seed=1).recording)  # 81.92 s
    True
    >>> whole_periods(simulate(task="FD", motion_gain=1.0, seed=1, duration=40).recording)
    False
    """
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    T = recording.n_samples * recording.dt
    meta = recording.metadata.get("forcing")
    if isinstance(meta, Mapping):
        try:
            w0 = float(meta["base_frequency"])
            n, a = (np.concatenate([np.asarray(meta[k][arr], dtype=float).ravel()
                                    for k in ("target", "disturbance")])
                    for arr in ("n", "amplitude"))
        except (KeyError, TypeError, ValueError, IndexError):
            n = a = None  # a malformed sidecar: read the columns, if any
        if n is not None and n.shape == a.shape and math.isfinite(w0) and w0 > 0:
            if not np.any(a != 0.0):
                return None
            return whole_periods_frequency(w0, n, a, T) is not None
    # (either column alone tells: the format makes both optional, and a record cut mid-period
    # cuts both)
    return columns_whole_periods([recording[k] for k in ("f_t", "f_d") if k in recording])


def startup_discard(recording: Recording) -> float:
    """Seconds of the model's start-up: :data:`STARTUP_DISCARD` (2 s), at most a quarter of
    the record.

    What :func:`~bayespilot.fit.fast.fit_fast` leaves out of Eq. 4 by default on a
    record that is not whole periods of the forcing (:func:`whole_periods`), and the
    least ``discard`` with which :class:`Likelihood` does not warn about one.

    Parameters
    ----------
    recording : Recording

    Returns
    -------
    float
        min(2, duration / 4), s.

    Raises
    ------
    TypeError
        If ``recording`` is not a :class:`~bayespilot.recording.Recording`.
    """
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    return _coloured_default(recording.duration)  # (the one formula, below)


def coloured_discard(recording: Recording) -> float:
    """Seconds left out by default with an AR ("coloured") noise model: the model's start-up,
    :func:`startup_discard` (min(2 s, a quarter of the record)), on every record, of whole
    periods or not (the whitening filter amplifies the start-up transient wherever it is).

    The one rule of the default ``discard`` of :func:`~bayespilot.fit.fast.fit_fast` with
    ``noise="ar"`` or an :class:`~bayespilot.noise.ARNoise`, of
    :func:`~bayespilot.sample.sample`, :func:`~bayespilot.compare.evidence` and
    :func:`~bayespilot.compare.compare` with ``likelihood="coloured"``, and of the
    diagnosis's Bayes factors (:mod:`bayespilot.diagnose.nested`).

    Parameters
    ----------
    recording : Recording
        Its duration caps the lead-in.

    Returns
    -------
    float
        ``startup_discard(recording)``, s: 2 on every record of 8 s or more.

    Examples
    --------
    >>> from bayespilot.simulate import simulate
    >>> coloured_discard(simulate(task="FD", motion_gain=1.0, seed=1).recording)  # 81.92 s
    2.0
    >>> coloured_discard(simulate(task="FD", motion_gain=1.0, seed=1, duration=3).recording)
    0.75
    """
    return startup_discard(recording)  # (its TypeError for what is not a Recording)


def _coloured_default(duration: float) -> float:
    """:func:`startup_discard` and :func:`coloured_discard` of a record of ``duration``
    seconds, min(2 s, a quarter of it): the one formula (also what
    :func:`~bayespilot.fit.fast.fit_fast` asks of records it has not got, to name the shortest
    one an AR model fits)."""
    return min(STARTUP_DISCARD, duration / 4)


def _checked_discard(recording: Recording, discard: object) -> float:
    """``discard`` as a float, or a ValueError: a number of seconds in [0, half the record],
    what :class:`Likelihood` takes (the fitters and the sampler check it first, before they
    count the samples after it)."""
    if isinstance(discard, bool) or not isinstance(discard, (int, float, np.integer, np.floating)) \
            or not (math.isfinite(discard) and 0 <= discard <= recording.duration / 2):
        raise ValueError(f"discard must be a number of seconds in [0, {recording.duration / 2:g}] "
                         f"(half the record), got {discard!r}")
    return float(discard)


#: Where in bayespilot a :class:`Likelihood` is built on records whose start-up is handled
#: otherwise, so that :class:`NotWholePeriodsWarning` would only be noise, as (path under the
#: package, function name or None for any): the diagnosis leaves its first ``skip_seconds``
#: (5 s) out of every statistic and refit, and warns about a record that is not whole periods
#: itself (an EvidenceWarning); the campaign's numba warm-up fits a 2-s record only to compile
#: the kernels.  Read from the call stack because the diagnosis builds likelihoods in a dozen
#: places, some reached from a result's methods after diagnose() has returned.
_HANDLE_STARTUP = (("diagnose", None), ("campaign.py", "_warm_numba_cache"))


def _called_from_handling_startup() -> bool:
    """True if a frame of the call stack is in one of :data:`_HANDLE_STARTUP`."""
    from ._caller import _PACKAGE

    where = [(_PACKAGE / sub, name) for sub, name in _HANDLE_STARTUP]
    frame = sys._getframe(1)
    while frame is not None:
        path = Path(frame.f_code.co_filename).resolve()
        if any(path.is_relative_to(d) and name in (None, frame.f_code.co_name)
               for d, name in where):
            return True
        frame = frame.f_back
    return False


#: Why a fitter's default left the start-up out (its ``settings["discard_reason"]``): a record
#: known not to be whole periods of its forcing (:func:`whole_periods` False) ...
STARTUP_REASON = "start-up left out: the record is not a whole number of forcing periods"
#: ... or one of which that is not known (None): without a forcing in the sidecar or an f_t or
#: f_d column a cut record cannot be told from a whole one, and 2 s fewer samples cost less
#: than the 10 % biases of a cut record's start-up wrapped across its cut.
STARTUP_REASON_UNKNOWN = ("start-up left out: whether the record is a whole number of forcing "
                          "periods is not known (no forcing in its sidecar, no f_t or f_d "
                          "column)")


def _startup_default(recording: Recording, initial: str) -> float:
    """The discard a fitter's default picks with the white output error: :func:`startup_discard`
    for ``initial="periodic"`` on a record not known to be whole periods, else 0 (whole
    periods, as the paper's records).  The same for every caller: the diagnosis, which
    leaves out its own start, passes ``discard=0`` explicitly."""
    if (initial != "periodic" or recording.duration < STARTUP_DISCARD
            or whole_periods(recording) is True):
        return 0.0
    return startup_discard(recording)


def _startup_reason(recording: Recording) -> str:
    """:data:`STARTUP_REASON` or :data:`STARTUP_REASON_UNKNOWN`, as ``recording`` is."""
    return STARTUP_REASON if whole_periods(recording) is False else STARTUP_REASON_UNKNOWN


def _startup_matters(recording: Recording) -> bool:
    """True if ``recording`` is known not to be whole periods and no shorter than the start-up
    (:data:`STARTUP_DISCARD`; in a shorter one no discard separates the start-up from the rest)."""
    return recording.duration >= STARTUP_DISCARD and whole_periods(recording) is False


def _warn_not_whole_periods(recording: Recording, discard: float) -> None:
    """One :class:`NotWholePeriodsWarning` at the user's line, if ``recording`` is known not
    to be whole periods and ``discard`` leaves less than the start-up out (``initial`` is
    ``"periodic"``; the caller checks)."""
    need = startup_discard(recording)
    if discard >= need - 1e-9 or not _startup_matters(recording):
        return
    if _called_from_handling_startup():
        return
    where = f"{recording.source}: " if recording.source else ""
    warn_at_caller(f"{where}the {recording.duration:g}-s record is not a whole number of periods "
                   f"of its forcing functions, but initial='periodic' treats it as one: the "
                   f"model's start-up wraps across the cut, so the first seconds of the "
                   f"residual are large even at the true parameters and the estimates are "
                   f"biased (10 % and more on 30-60-s runs); leave the start-up out of Eq. 4 "
                   f"with discard={need:g} (s) (initial='rest' avoids the wrap, but without a "
                   f"discard still leaves biases of 1-2 %), or cut the record to whole periods",
                   NotWholePeriodsWarning)


def _silent_channels(model: PilotModel, X: np.ndarray) -> list[tuple[object, list[str]]]:
    """(channel, its own parameters) of each channel whose input row of ``X`` is all zero
    (its own: not shared with another channel, as the neuromuscular ones are)."""
    out = []
    for c, ch in enumerate(model.channels):
        if np.any(X[c] != 0.0):
            continue
        others = {q for k, o in enumerate(model.channels) if k != c for q in o.parameter_names}
        out.append((ch, [q for q in dict.fromkeys(ch.parameter_names) if q not in others]))
    return out


def _unidentified(lik: "Likelihood") -> set[str]:
    """The parameters a likelihood's record does not identify: a silent channel's own."""
    return {q for _, own in _silent_channels(lik.model, lik.X) for q in own}


def _warn_silent_channels(model: PilotModel, X: np.ndarray) -> None:
    """One warning per channel whose input row of ``X`` is all zero and that has free
    parameters of its own (shared ones, such as the neuromuscular ones, are identified by the
    other channels)."""
    free = set(model.parameter_names)
    for ch, own in _silent_channels(model, X):
        if any(q in free for q in own):  # (all named, so that the message is one per channel)
            # (at the user's call: a fit builds several likelihoods, said once for its line)
            warn_at_caller(f"the {ch.name} channel's input ({ch.source}) is zero throughout "
                           f"the record, so its parameters ({', '.join(own)}) are not "
                           f"identified: fix them (model.fix) or use a model without the "
                           f"channel", SilentChannelWarning)


def _warn_perfect_fit() -> None:
    warn_at_caller("the model reproduces u to round-off; the output-error variance was "
                   "floored, so -ln L is a finite bound, not an optimum", PerfectFitWarning)


def _source_signal(recording: Recording, source: str) -> np.ndarray:
    if source == "e":
        return recording.e
    if source == "theta_ddot_m":
        return recording.theta_ddot_m
    if source in ("theta_m", "theta"):
        if "theta" not in recording:
            raise ValueError(f"{recording.source or 'recording'}: the model needs the 'theta' "
                             f"column (source {source!r}), which this recording does not have")
        th = recording["theta"]
        return th * recording.motion_gain if source == "theta_m" else th
    raise ValueError(f"unknown source {source!r}")


#: Seconds at the start over which a recorded theta is checked against theta_ddot_m.
RATE_WINDOW = 1.0


def _pitch_rate_at_start(recording: Recording) -> float | None:
    """K_theta * d(theta)/dt at t = 0: from the recorded theta (second-order one-sided
    difference); without theta, from theta_ddot_m, as the rate that gives the integrated
    acceleration a zero mean over the record (the pitch attitude is held near zero, so its
    rate averages (theta(T) - theta(0)) / T, a few thousandths of the rate's own scale).

    Without theta the record used to be tiled as if periodic; on a 30-s FD run (not whole
    periods) that gave K_m 0.655 where the fit with theta gave 0.698 (this estimate: 0.6975).

    When theta_ddot_m = c theta'' holds over the record with c off the sidecar's K_theta
    (:func:`~bayespilot.recording._columns_motion_gain`, which
    :func:`~bayespilot.recording.questionable` warns of), K_theta theta' is not the rate
    theta_ddot_m presents, and c is taken for K_theta here (a sidecar K_theta of 1 for 0.5
    made the fast fit's K_m 0.244, tau_m 0.06 and delta_abs 0.027 for 0.346, 0.200 and
    0.0025 on the port audit's 2/s^2 run).  A recorded theta is then checked against
    theta_ddot_m over the first :data:`RATE_WINDOW` seconds
    (:func:`_rate_by_least_squares`).  Where the two agree but the difference does
    not (a noisy or coarsely quantised theta sensor: 2e-4 rad of noise made it 0.060 rad/s
    where the rate was 0.019, and the fast fit's K_m 20 % low), the least-squares rate is
    taken.  Where they agree only with theta turned round (theta logged with the other
    sign: the fast fit's K_m 21 % low), the rate of -theta: theta_ddot_m is what drives the
    canal model.  Where they disagree either way (motion logged after a washout or a
    platform filter), the rate from theta_ddot_m alone, as without theta: theta_ddot_m is
    what drives the canal model, and that estimate does not depend on K_theta (it used to
    be K_theta theta's rate, which followed a wrong sidecar K_theta).  On a recording whose
    columns agree, the difference is kept as it is: the results of a recording with a
    clean theta do not change.
    """
    if recording.n_samples < 3:
        return None
    a = np.asarray(recording.theta_ddot_m, dtype=float)
    if "theta" not in recording:
        return _rate_from_acceleration(a, recording.dt)
    K = recording.motion_gain
    th = np.asarray(recording["theta"], dtype=float)
    if K > 0:
        # theta_ddot_m = c theta'' over the record with c off K_theta: the sidecar's
        # motion_gain is not the run's (questionable() says so), and K_theta theta' is not the
        # rate theta_ddot_m presents, while the first second's check below can pass with it (a
        # theta that is nearly a parabola there: the audit's 2/s^2 run, K_m 0.244 for 0.346);
        # the columns' c is the K_theta that theta_ddot_m presents
        K = _columns_motion_gain(recording) or K
    rate = K * (-3.0 * th[0] + 4.0 * th[1] - th[2]) / (2.0 * recording.dt)
    if not K > 0:  # no motion: nothing to check theta against
        return rate
    for sign in (1.0, -1.0):
        fitted = _rate_by_least_squares(sign * th, a / K, recording.dt)
        if fitted is None:
            return rate
        rate_ls, stderr, agree, scale = fitted
        if not agree:
            continue
        rate_ls, stderr, scale = K * rate_ls, K * stderr, K * scale
        # (the difference stays where it is within its own small error: the results of a
        # recording whose theta is clean do not change; 50 Hz, the lowest rate tried, gave
        # 0.2 % of the rate's scale, a noisy sensor 60 % and more)
        return rate_ls if abs(sign * rate - rate_ls) > max(3.0 * stderr, 0.02 * scale) \
            else sign * rate
    # neither sign agrees (motion logged after a filter; a K_theta off theta_ddot_m's that
    # the whole-record check above could not judge): K_theta times theta's rate is not the
    # rate theta_ddot_m presents, so the rate from theta_ddot_m alone, as without theta
    return _rate_from_acceleration(a, recording.dt)


def _cumulative(x: np.ndarray, dt: float) -> np.ndarray:
    """The trapezoidal integral of ``x`` from its first sample, at every sample."""
    return np.concatenate([[0.0], np.cumsum(0.5 * (x[1:] + x[:-1]))]) * dt


def _rate_from_acceleration(a: np.ndarray, dt: float) -> float:
    """The start rate that gives the integrated acceleration ``a`` a zero mean over the record."""
    return -float(np.mean(_cumulative(a, dt)))


def _rate_by_least_squares(theta: np.ndarray, acc: np.ndarray, dt: float
                           ) -> tuple[float, float, bool, float] | None:
    """d(theta)/dt at t = 0 from the first :data:`RATE_WINDOW` s of ``theta``, given its
    second derivative ``acc`` (theta_ddot_m / K_theta): theta(t) - D(t) = theta_0 + r t
    + c t^2 by least squares, D the acceleration integrated twice (trapezoidal) from rest
    (c takes up a constant bias of the logged acceleration: 10 % of its sd made the fit
    without it disagree).

    Returns (r, its standard error, whether theta and ``acc`` agree, the rms of the
    differenced theta over the record), or None when the window is too short to tell.
    They agree when the fit explains at least 99 % of theta's variance over the window
    (a noisy theta sensor: 99.9 %; theta of the other sign: none of it).
    """
    n = int(min(theta.size, round(RATE_WINDOW / dt) + 1))
    if n < 6:
        return None
    y = theta[:n] - _cumulative(_cumulative(acc[:n], dt), dt)
    t = np.arange(n) * dt
    X = np.column_stack([np.ones(n), t, t * t])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    res = y - X @ coef
    spread = theta[:n] - theta[:n].mean()
    total = float(spread @ spread)
    if not total > 0:
        return None
    stderr = float(np.sqrt(res @ res / (n - 3) * np.linalg.inv(X.T @ X)[1, 1]))
    agree = float(res @ res) <= 0.01 * total
    return float(coef[1]), stderr, agree, float(np.std(np.diff(theta)) / dt)


def _impulse_tail(num, den, t: np.ndarray) -> np.ndarray:
    """Impulse response of the strictly proper part of num/den at times t (continuous, exact)."""
    num = np.atleast_1d(np.asarray(num, float))
    den = np.atleast_1d(np.asarray(den, float))
    num = np.concatenate([np.zeros(den.size - num.size), num])
    d = num[0] / den[0]
    sp = num - d * den
    sp = np.trim_zeros(sp, "f")
    if sp.size == 0:
        return np.zeros_like(t)
    _, y = signal.impulse((sp, den), T=t)
    return y


def channel_inputs(model: PilotModel, recording: Recording, initial: str = "periodic") -> np.ndarray:
    """The recorded source of each channel passed through its fixed stages.

    Parameters
    ----------
    model : PilotModel
    recording : Recording
    initial : {"periodic", "rest"}
        ``"rest"`` starts the filters from zero state.  ``"periodic"`` starts
        them in the state the run-in left them in: for a channel on
        ``theta_ddot_m`` of a recording with a ``theta`` column, the fixed
        stages (the canal model, whose 5.9 s time constant would otherwise
        leave a transient over the first ~20 s) start as if the pitch rate at
        t = 0, K_theta dtheta/dt, had been built up by an impulse just before
        the record (without a ``theta`` column, the rate whose integrated
        ``theta_ddot_m`` has a zero mean over the record); other channels'
        fixed stages treat the record as one period of a periodic signal
        (two extra periods of warm-up).

    Returns
    -------
    ndarray, shape (n_channels, n_samples)
    """
    if initial not in INITIAL_CONDITIONS:
        raise ValueError(f"initial must be one of {INITIAL_CONDITIONS}, got {initial!r}")
    n = recording.n_samples
    X = np.empty((len(model.channels), n))
    rate0 = _pitch_rate_at_start(recording) if initial == "periodic" else None
    for c, ch in enumerate(model.channels):
        x = np.asarray(_source_signal(recording, ch.source), dtype=float)
        fixed = [st for st in ch.stages if isinstance(st, FixedFilter)]
        if fixed:
            num, den = np.array([1.0]), np.array([1.0])
            for st in fixed:
                num, den = np.polymul(num, st.num), np.polymul(den, st.den)
            # The same Tustin rule as the kernels' parametric stages.
            b, a = signal.bilinear(num, den, fs=recording.sample_rate_hz)
            if initial == "rest":
                x = signal.lfilter(b, a, x)
            elif ch.source == "theta_ddot_m" and rate0 is not None:
                # the uniform grid (t may be stored in float32, uniform only to its precision)
                grid = np.arange(n) * recording.dt
                x = signal.lfilter(b, a, x) + rate0 * _impulse_tail(num, den, grid)
            else:
                x = signal.lfilter(b, a, np.tile(x, 3))[-n:]
        X[c] = x
    return X


class Likelihood:
    """Eq. 4 for one model and one recording, evaluated fast and in batches.

    Parameters
    ----------
    model : PilotModel
    recording : Recording
    initial : {"periodic", "rest"}, default "periodic"
        How the model's start-up is treated (see module docs and
        ``docs/faithfulness.md``).  ``"periodic"`` treats the record as one
        period of the forcing functions, which is right for a record of whole
        periods (the paper's 81.92 s); on one that is not
        (:func:`whole_periods`), leave the start-up out with ``discard``
        (:func:`startup_discard`, 2 s).
    warmup : float, default 5.0
        Seconds of the record's end used to warm up each recursion when
        ``initial="periodic"``.
    discard : float, default 0.0
        Seconds at the start of the record left out of Eq. 4 (the model still
        runs from t = 0; N in Eq. 4 becomes the number of samples kept).  The
        paper uses the whole record (0, the default).  With remnant, the
        model's short-memory state at t = 0 (H_nm and the delays) is not
        known, and the first 1-2 s of the residual carry that start-up error;
        ``discard=2`` removes it (``docs/faithfulness.md``, part E).  At most
        half the record.
    noise : ARNoise, optional
        A model of the output error.  None (default): white, Eq. 4 as the
        paper has it.  An :class:`~bayespilot.noise.ARNoise`: Eq. 4 applied
        to the whitened residual w = A(q) eps, conditional on its first p
        samples (a prediction-error criterion; see :mod:`bayespilot.noise`
        for why closed-loop data need it).  Everything that uses the
        likelihood (:meth:`neg_log_lik`, :meth:`batch`, and through
        :meth:`fit_residual` and :meth:`fit_jacobian` the Gauss-Newton
        fitters) then works on w.

    Warns
    -----
    SilentChannelWarning
        A channel's input is zero throughout the record (a run without
        motion): its own parameters are not identified by it.
    NotWholePeriodsWarning
        ``initial="periodic"`` on a record known not to be whole periods of
        the forcing (:func:`whole_periods` False) and at least 2 s long, with
        ``discard`` below :func:`startup_discard`.  Not issued inside
        :func:`~bayespilot.diagnose.diagnose`, which leaves out its own
        start (``skip_seconds``) and warns about such records itself.

    Examples
    --------
    >>> from bayespilot.model import paper_model
    >>> from bayespilot.simulate import simulate
    >>> rec = simulate(paper_model(), task="FD", motion_gain=1.0, seed=1, duration=10.0).recording
    >>> lik = Likelihood(paper_model(), rec)
    >>> bool(lik.neg_log_lik(paper_model().defaults) < 0)
    True
    """

    def __init__(self, model: PilotModel, recording: Recording, *, initial: str = "periodic",
                 warmup: float = 5.0, discard: float = 0.0,
                 noise: ARNoise | None = None) -> None:
        if not isinstance(model, PilotModel):
            raise TypeError(f"model must be a PilotModel, got {type(model).__name__}")
        if not isinstance(recording, Recording):
            raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
        if not (math.isfinite(warmup) and warmup >= 0):
            raise ValueError(f"warmup must be a finite number of seconds >= 0, got {warmup!r}")
        _checked_discard(recording, discard)
        if noise is not None and not isinstance(noise, ARNoise):
            raise TypeError(f"noise must be None or an ARNoise, got {type(noise).__name__}")
        self.model = model
        self.recording = recording
        self.initial = initial
        self.X = np.ascontiguousarray(channel_inputs(model, recording, initial))
        if initial == "periodic":
            _warn_not_whole_periods(recording, float(discard))
        _warn_silent_channels(model, self.X)
        self.u = np.ascontiguousarray(recording.u, dtype=float)
        self.dt = recording.dt
        self.n = recording.n_samples
        self.warm = int(min(self.n, round(warmup * recording.sample_rate_hz)))
        self.periodic = initial == "periodic"
        self.pad = R.padding(self.n, self.dt)
        self.discard = float(discard)
        #: Samples at the start left out of Eq. 4, and the slice of the samples kept.
        self.skip = int(round(discard * recording.sample_rate_hz))
        self.used = slice(self.skip, None)
        self.noise = noise
        #: AR coefficients of the noise model (empty: white, Eq. 4).
        self._a = np.ascontiguousarray(noise.a if noise is not None else np.zeros(0))
        if self.n - self.skip <= 4 * self._a.size:
            raise ValueError(f"an AR({self._a.size}) noise model needs more than "
                             f"{4 * self._a.size} samples after the discarded lead-in, "
                             f"this record has {self.n - self.skip}")
        # Floor of the output-error variance: a residual 1e-12 of rms(u).
        self.s2_floor = 1e-24 * float(np.mean(self.u**2)) + 1e-300
        self._plan = model.plan
        self._base = model.full_vector()
        self._free_idx = model.free_index
        #: The layout and arguments of the segmented SIMD kernel, or None (see :attr:`segmented`).
        self._seg_args = self._segmented_args() if SEG.ENABLED else None

    def __repr__(self) -> str:
        noise = "white" if self.noise is None else f"AR({self._a.size})"
        where = f", {self.recording.source}" if self.recording.source else ""
        return (f"<Likelihood: {self.model.name}, {self.model.n_free} free parameters, "
                f"N = {self.n} at {self.recording.sample_rate_hz:g} Hz, "
                f"initial={self.initial!r}, discard {self.discard:g} s, {noise} noise{where}>")

    @property
    def segmented(self) -> bool:
        """True if :meth:`neg_log_lik` and :meth:`batch` use the segmented SIMD kernel
        (``kernels/_segmented.py``).

        Decided when the likelihood is made: the CPU has AVX-512, or AVX2 and
        FMA (``kernels._segmented.ENABLED``; ``BAYESPILOT_KERNEL=scalar`` or
        ``=segmented`` in the environment overrides it), and the model and
        settings are the paper's kind: two channels without parametric stages or gain
        modulation, one plain and one plain or with a dead zone and no lead, no
        output nonlinearity, ``initial="periodic"``, no discarded lead-in, no
        noise model, and a record of 8 equal segments.  Otherwise the fused
        scalar kernel computes the same values to round-off.
        """
        return self._seg_args is not None

    def _segmented_args(self) -> tuple | None:
        """The segmented kernel's constant arguments (layout built once), or None if the
        model or settings are outside what it computes."""
        if not self.periodic or self.skip != 0 or self._a.size:
            return None
        channels = SEG.plan_channels(self._plan)
        if channels is None:
            return None
        lay = SEG.build_layout(self.X, self.u, *channels, self.pad)
        if lay is None:
            return None
        p = self._plan
        return (lay.P, lay.Q, lay.I, lay.U, lay.uu, lay.S, lay.H, lay.cv, lay.cm, self.X,
                self.u,
                p.ch_int, p.ch_float, p.st_int, p.st_const, p.out_int, self.dt, self.warm,
                self.s2_floor, self.pad)

    # -- helpers ---------------------------------------------------------------
    def _theta(self, params) -> np.ndarray:
        return self.model.full_vector(params)

    def _args(self):
        p = self._plan
        return (p.ch_int, p.ch_float, p.st_int, p.st_const, p.out_int)

    # -- single evaluations ----------------------------------------------------
    def response(self,
                 params: Mapping[str, float] | Sequence[float] | np.ndarray | None
                 ) -> np.ndarray:
        """Model output u_hat at ``params`` (by name, or the free vector in order).

        Parameters
        ----------
        params : mapping of str to float, sequence of float, ndarray or None
            (None: the model's defaults)
            Values by name (free parameters not given take the model's
            defaults) or the free-parameter vector in ``model.parameter_names``
            order.

        Returns
        -------
        ndarray, shape (n_samples,)
            u_hat over the whole record, in the units of u (rad); all NaN when
            the parameter vector is unstable.
        """
        theta = self._theta(params)
        y, ok = R.response(theta, self.X, *self._args(), self.dt, self.periodic, self.warm)
        if not ok:
            y[:] = np.nan
        return y

    def residual(self,
                 params: Mapping[str, float] | Sequence[float] | np.ndarray | None
                 ) -> np.ndarray:
        """Output error eps = u - u_hat over the whole record (Eq. 4 uses ``eps[self.used]``).

        Parameters
        ----------
        params : mapping of str to float, sequence of float, ndarray or None
            (None: the model's defaults)
            Values by name (free parameters not given take the model's
            defaults) or the free-parameter vector in ``model.parameter_names``
            order.

        Returns
        -------
        ndarray, shape (n_samples,)
            eps, rad; all NaN when the parameter vector is unstable.
        """
        return self.u - self.response(params)

    @property
    def n_terms(self) -> int:
        """N of Eq. 4: the samples kept, less the p a noise model conditions on."""
        return self.n - self.skip - self._a.size

    def fit_residual(self,
                     params: Mapping[str, float] | Sequence[float] | np.ndarray | None
                     ) -> np.ndarray:
        """The residual whose sum of squares -ln L is increasing in: eps over the samples
        kept, whitened by the noise model if there is one (length :attr:`n_terms`).

        Parameters
        ----------
        params : mapping of str to float, sequence of float, ndarray or None
            (None: the model's defaults)
            Values by name (free parameters not given take the model's
            defaults) or the free-parameter vector in ``model.parameter_names``
            order.

        Returns
        -------
        ndarray, shape (n_terms,)
            eps[``used``] (white noise) or w = A(q) eps[``used``] without its
            first p samples (AR(p) noise model), rad.
        """
        eps = self.residual(params)[self.used]
        return eps if self.noise is None else self.noise.whiten(eps)

    def fit_jacobian(self, params: Mapping[str, float] | Sequence[float] | np.ndarray | None,
                     names: Sequence[str] | None = None) -> np.ndarray:
        """d :meth:`fit_residual` / d parameter, shape (:attr:`n_terms`, len(names)), exact
        (the model's sensitivities, passed through the same whitening filter).

        Parameters
        ----------
        params : mapping of str to float, sequence of float, ndarray or None
            (None: the model's defaults)
            Values by name (free parameters not given take the model's
            defaults) or the free-parameter vector in ``model.parameter_names``
            order.
        names : sequence of str, optional
            Parameters to differentiate by (default: the free parameters, in
            ``model.parameter_names`` order).

        Returns
        -------
        ndarray, shape (n_terms, len(names))
            -d u_hat / d parameter over the samples kept, whitened like
            :meth:`fit_residual`; NaN where the parameter vector is unstable.

        Raises
        ------
        ValueError
            If ``names`` holds a parameter the model does not have.
        """
        J = -self.jacobian(params, names)[1][self.used]
        return J if self.noise is None else self.noise.whiten(J)

    def neg_log_lik(self,
                    params: Mapping[str, float] | Sequence[float] | np.ndarray | None
                    ) -> float:
        """-ln L (Eq. 4, s2 profiled); +inf for an unstable parameter vector.

        Computed by the same routine as :meth:`batch` (one row), so the two
        agree to the bit.

        Parameters
        ----------
        params : mapping of str to float, sequence of float, ndarray or None
            (None: the model's defaults)
            Values by name (free parameters not given take the model's
            defaults) or the free-parameter vector in ``model.parameter_names``
            order.

        Returns
        -------
        float
            N/2 ln(mean w^2) + N/2 over the :attr:`n_terms` terms (w = eps
            without a noise model), or +inf.

        Warns
        -----
        PerfectFitWarning
            The residual is at round-off level: the variance is then floored
            and the value is a finite bound.
        """
        theta = self._theta(params)
        if self._seg_args is not None:
            # the batch's routine on one row: the same value to the bit
            val, floored = SEG.neg_log_lik_segmented_one(theta, *self._seg_args)
            if floored:
                _warn_perfect_fit()
            return float(val)
        y = np.empty(self.n)
        q = np.empty(self.n)
        v = np.empty(R.work_length(self._plan.ch_int, self.n))
        if self._a.size:
            val, floored = C.neg_log_lik_whitened_one(theta, self._a, self.X, self.u,
                                                      *self._args(), self.dt, self.periodic,
                                                      self.warm, self.s2_floor, y, q, v,
                                                      self.skip)
        else:
            Qp = np.empty((self.X.shape[0], self.n + 2 * self.pad))
            val, floored = R.neg_log_lik_one(theta, self.X, self.u, *self._args(), self.dt,
                                             self.periodic, self.warm, self.s2_floor, y, q, v,
                                             Qp, self.pad, self.skip)
        if floored:
            _warn_perfect_fit()
        return float(val)

    def vaf(self, params: Mapping[str, float] | Sequence[float] | np.ndarray | None) -> float:
        """Variance accounted for, 1 - var(eps)/var(u), in percent, over the samples Eq. 4 uses.

        Parameters
        ----------
        params : mapping of str to float, sequence of float, ndarray or None
            (None: the model's defaults)
            Values by name (free parameters not given take the model's
            defaults) or the free-parameter vector in ``model.parameter_names``
            order.

        Returns
        -------
        float
            VAF, %; NaN when the parameter vector is unstable.
        """
        return vaf(self.u[self.used], self.response(params)[self.used])

    def jacobian(self, params: Mapping[str, float] | Sequence[float] | np.ndarray | None,
                 names: Sequence[str] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Model output and its exact derivatives with respect to parameters.

        Parameters
        ----------
        params : mapping of str to float, sequence of float, ndarray or None
            (None: the model's defaults)
            Values by name (free parameters not given take the model's
            defaults) or the free-parameter vector in ``model.parameter_names``
            order.
        names : sequence of str, optional
            Parameters to differentiate by (default: the free parameters, in
            ``model.parameter_names`` order).

        Returns
        -------
        u_hat : ndarray, shape (N,)
        J : ndarray, shape (N, len(names))
            d u_hat / d parameter, from the forward sensitivity equations of the
            discrete model (``kernels/_sensitivity.py``), not finite differences.
            NaN where the parameter vector is unstable.
        """
        from .kernels import _sensitivity as S

        theta = self._theta(params)
        names = self.model.parameter_names if names is None else tuple(names)
        full = self.model.all_names
        unknown = [n for n in names if n not in full]
        if unknown:
            raise ValueError(f"unknown parameter(s) {unknown}; this model has {', '.join(full)}")
        cols = np.array([full.index(n) for n in names], dtype=np.int64)
        y, J, ok = S.jacobian(theta, cols, self.X, *self._args(), self.dt, self.periodic, self.warm)
        if not ok:
            y[:] = np.nan
            J[:] = np.nan
        return y, J

    # -- populations -------------------------------------------------------------
    def batch(self, free: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """-ln L for every row of ``free`` (free-parameter vectors, shape (M, n_free)).

        Runs in parallel over rows on numba's threads.  Non-finite or unstable
        rows give +inf.  Each row's value is that of :meth:`neg_log_lik` to the
        bit, whatever the batch size, row order or thread count.  With
        :attr:`segmented` the segmented SIMD kernel computes it (about ten
        times faster per row than the fused scalar kernel with AVX-512, twice
        with AVX2; equal to it to round-off).

        Parameters
        ----------
        free : ndarray, shape (M, n_free)
            Free-parameter vectors in ``model.parameter_names`` order.
        out : ndarray, shape (M,), optional
            Where to write the values (float64, C-contiguous, writeable); a new
            array when not given.

        Returns
        -------
        ndarray, shape (M,)
            ``out`` (or the new array) holding -ln L of each row.

        Raises
        ------
        ValueError
            ``free`` is complex or of another shape, or ``out`` is not a
            writeable C-contiguous float64 array of shape (M,) (the kernels
            write into it as given: any other would be written out of bounds
            or lose precision).
        """
        if np.iscomplexobj(free):
            raise ValueError("free must be real parameter vectors, got complex values")
        free = np.ascontiguousarray(free, dtype=float)
        if free.ndim != 2 or free.shape[1] != self.model.n_free:
            raise ValueError(f"free must have shape (M, {self.model.n_free}) "
                             f"({', '.join(self.model.parameter_names)}), got {free.shape}")
        m = free.shape[0]
        if out is None:
            out = np.empty(m)
        elif not (isinstance(out, np.ndarray) and out.shape == (m,) and out.dtype == np.float64
                  and out.flags.c_contiguous and out.flags.writeable):
            got = (f"shape {out.shape}, dtype {out.dtype}" if isinstance(out, np.ndarray)
                   else type(out).__name__)
            raise ValueError(f"out must be a writeable C-contiguous float64 array of shape "
                             f"({m},), one value per row of free; got {got}")
        floored = np.zeros(m, dtype=np.bool_)
        n_chunks = max(1, min(m, numba.get_num_threads()))
        if self._seg_args is not None:
            SEG.neg_log_lik_segmented_batch(free, self._free_idx, self._base, *self._seg_args,
                                            n_chunks, out, floored)
        elif self._a.size:
            C.neg_log_lik_whitened_batch(free, self._free_idx, self._base, self._a, self.X,
                                         self.u, *self._args(), self.dt, self.periodic,
                                         self.warm, self.s2_floor, n_chunks, out, floored,
                                         self.skip)
        else:
            R.neg_log_lik_batch(free, self._free_idx, self._base, self.X, self.u, *self._args(),
                                self.dt, self.periodic, self.warm, self.s2_floor, n_chunks,
                                self.pad, out, floored, self.skip)
        out[~np.isfinite(out)] = np.inf
        return out


def model_response(model: PilotModel, recording: Recording,
                   params: Mapping[str, float] | Sequence[float] | np.ndarray | None, *,
                   initial: str = "periodic") -> np.ndarray:
    """Model output u_hat for ``recording`` at ``params`` (see :class:`Likelihood`).

    Parameters
    ----------
    model : PilotModel
        The pilot model (e.g. :func:`~bayespilot.model.paper_model`).
    recording : Recording
        The run whose measured inputs (e and theta_ddot_m; theta where a
        channel needs it) drive the model.
    params : mapping of str to float, sequence of float, ndarray or None
        Where to evaluate: values by name (free parameters not given take the
        model's defaults; values given for fixed parameters are ignored), or
        the free-parameter vector in ``model.parameter_names`` order (K_v,
        T_vl, tau_v, K_m, tau_m, omega_nm, zeta_nm, delta_abs for the paper's
        model), or None for the model's defaults.
    initial : {"periodic", "rest"}, default "periodic"
        How the model's start-up is treated (see :class:`Likelihood` and
        :func:`channel_inputs`).

    Returns
    -------
    ndarray, shape (n_samples,)
        u_hat at the recording's samples, in the units of u (rad); all NaN
        when the parameter vector is unstable.

    Raises
    ------
    TypeError
        If ``model`` is not a PilotModel or ``recording`` not a Recording.
    ValueError
        If ``initial`` is not "periodic" or "rest", ``params`` names an
        unknown parameter, has the wrong length or a value that is not a
        finite number, or the model needs the ``theta`` column and the
        recording has none.
    """
    return Likelihood(model, recording, initial=initial).response(params)


def neg_log_lik(model: PilotModel, recording: Recording,
                params: Mapping[str, float] | Sequence[float] | np.ndarray | None, *,
                initial: str = "periodic") -> float:
    """-ln L of Eq. 4 for ``recording`` at ``params`` (see :class:`Likelihood`).

    Parameters
    ----------
    model : PilotModel
        The pilot model (e.g. :func:`~bayespilot.model.paper_model`).
    recording : Recording
        The run whose measured inputs (e and theta_ddot_m; theta where a
        channel needs it) drive the model.
    params : mapping of str to float, sequence of float, ndarray or None
        Where to evaluate: values by name (free parameters not given take the
        model's defaults; values given for fixed parameters are ignored), or
        the free-parameter vector in ``model.parameter_names`` order (K_v,
        T_vl, tau_v, K_m, tau_m, omega_nm, zeta_nm, delta_abs for the paper's
        model), or None for the model's defaults.
    initial : {"periodic", "rest"}, default "periodic"
        How the model's start-up is treated (see :class:`Likelihood` and
        :func:`channel_inputs`).

    Returns
    -------
    float
        -ln L = N/2 ln(mean eps^2) + N/2 over the whole record (white output
        error, s2 profiled out); +inf for an unstable parameter vector.

    Raises
    ------
    TypeError
        If ``model`` is not a PilotModel or ``recording`` not a Recording.
    ValueError
        If ``initial`` is not "periodic" or "rest", ``params`` names an
        unknown parameter, has the wrong length or a value that is not a
        finite number, or the model needs the ``theta`` column and the
        recording has none.

    Warns
    -----
    PerfectFitWarning
        When the model reproduces u to round-off: the variance is floored
        and the value is a finite bound.

    Examples
    --------
    >>> from bayespilot.model import paper_model
    >>> from bayespilot.simulate import simulate
    >>> rec = simulate(paper_model(), task="FT", motion_gain=1.0, seed=2, duration=10.0).recording
    >>> value = neg_log_lik(paper_model(), rec, paper_model().defaults)
    """
    return Likelihood(model, recording, initial=initial).neg_log_lik(params)


def vaf(u: np.ndarray, u_hat: np.ndarray) -> float:
    """Variance accounted for, 100 (1 - var(u - u_hat) / var(u)), percent.

    Parameters
    ----------
    u : array_like
        The measured control output.
    u_hat : array_like
        The model output, the same shape as ``u`` (or broadcastable to it).

    Returns
    -------
    float
        VAF in percent: 100 for a perfect fit, lower (negative too) for
        worse ones.  The variances are about the means (numpy's ``var``), so
        a constant offset between ``u`` and ``u_hat`` does not lower it;
        not finite when ``u`` is constant.
    """
    u = np.asarray(u, float)
    u_hat = np.asarray(u_hat, float)
    return float(100.0 * (1.0 - np.var(u - u_hat) / np.var(u)))

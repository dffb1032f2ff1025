"""Simulate the closed-loop tracking task (Fig. 2) with a pilot model, to a Recording.

The task (controlled element, control gain, forcing functions, motion gain,
sample rate, duration) is a :class:`TrackingTask`; :meth:`TrackingTask.paper`
is the preset of Pool et al. (2012).  :func:`simulate` integrates the loop at
``oversample`` times the recording rate (by default at 1 kHz or finer,
:func:`integration_steps`: 10 steps a sample at the paper's 100 Hz) after a
run-in, adds remnant per Eq. 6
with K_n set directly or calibrated to a remnant fraction F_n (Eq. 7), and
returns a :class:`Simulation` holding the Recording and the hidden truth.

Remnant white-noise convention: w is white noise whose two-sided power
spectral density is ``noise_psd`` (rad^2 s).  The default,
:data:`NOISE_PSD` = 0.01, is the same as unit-variance samples at 100 Hz
(MATLAB's ``randn`` at the paper's rate), the convention that reproduces the
remnant gains of Table 4 (see ``docs/faithfulness.md``).  It is a physical
density, so a remnant gain K_n means the same remnant at any recording rate
(the default was ``1 / sample_rate_hz`` before, which made K_n's remnant
shrink as 1/sqrt(rate) at other rates).
"""

from __future__ import annotations

import math
import numbers
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from scipy import optimize, signal

from . import presets
from ._files import json_ready
from ._seeds import resolve_seed
from .forcing import Multisine, above_nyquist
from .kernels import _closed_loop as CL
from .model import PilotModel, _parameter_value, paper_model
from .recording import Recording

__all__ = ["TrackingTask", "Simulation", "simulate", "remnant", "calibrate_remnant_gain",
           "remnant_fraction", "NOISE_PSD", "integration_steps"]

#: Default two-sided PSD of the remnant's white noise, rad^2 s: unit-variance samples at the
#: paper's 100 Hz (Table 4's remnant gains), the same density at any recording rate.
NOISE_PSD = 0.01

#: The default integration rate, Hz: the paper's 10 steps a sample at 100 Hz.
INTEGRATION_HZ = 1000.0


def integration_steps(sample_rate_hz: float) -> int:
    """Integration steps per recorded sample by default: the fewest (at least 2) that make
    the step at most 1 ms (:data:`INTEGRATION_HZ`).

    Parameters
    ----------
    sample_rate_hz : float
        The recording's sample rate, Hz.

    Returns
    -------
    int
        10 at the paper's 100 Hz, 20 at 50 Hz, 2 at 1 kHz (a fixed 10 integrated a 1-kHz
        task at 10 kHz, five times the work the same accuracy needs).

    Examples
    --------
    >>> integration_steps(100.0), integration_steps(60.0), integration_steps(1000.0)
    (10, 17, 2)
    """
    return max(2, math.ceil(INTEGRATION_HZ / sample_rate_hz - 1e-9))


@dataclass(frozen=True, eq=False)
class TrackingTask:
    """A compensatory tracking task with motion feedback (Fig. 2).

    Parameters
    ----------
    target, disturbance : Multisine
        f_t (rad) and f_d (rad, inserted before the controlled element);
        every line of nonzero amplitude below the Nyquist frequency,
        ``sample_rate_hz / 2`` (a line at or above it would be recorded
        aliased).
    motion_gain : float
        K_theta (0 = no motion).
    controlled_element : (num, den)
        delta -> theta transfer function in powers of s, highest first;
        strictly proper with relative degree >= 2: the simulator makes
        theta_ddot (the motion cue) from the plant's state and input, so it
        must not depend on the derivative of the input.  A plant of lower
        relative degree can be run with a fast extra pole, e.g. K/s as
        K/(s (0.01 s + 1)).  Default K_c / s^2 with K_c = 4.
    control_gain : float
        K_delta_u.
    sample_rate_hz : float
        Rate of the recording.
    duration : float
        Measurement time T0, s.
    run_in : float
        Simulated time before the measurement window starts, s.
    task : {"FD", "FT", "other"}
        Label written to the recording.
    forcing_scale : str, float or None, default None
        The amplitude scale :meth:`paper` applied to Table 2 (a key of
        :data:`bayespilot.presets.FORCING_SCALE` or a number), which
        :func:`simulate` records in its settings; None for forcing functions
        of your own, whose amplitudes are as given.

    Raises
    ------
    ValueError
        On a non-finite or out-of-range number, an unknown task label, a
        controlled element of relative degree below 2, a forcing line at
        or above the Nyquist frequency, or a ``forcing_scale`` that is
        neither None, a key of ``FORCING_SCALE`` nor a number >= 0, or
        that (task FD or FT) does not give this target and disturbance
        (``dataclasses.replace(TrackingTask.paper(...), target=mine)`` needs
        ``forcing_scale=None`` too).
    """

    target: Multisine
    disturbance: Multisine
    motion_gain: float = 1.0
    controlled_element: tuple = ((presets.K_C,), (1.0, 0.0, 0.0))
    control_gain: float = presets.K_DU
    sample_rate_hz: float = presets.SAMPLE_RATE_HZ
    duration: float = presets.T0
    run_in: float = presets.T0 / 2
    task: str = "other"
    forcing_scale: str | float | None = None

    def __post_init__(self) -> None:
        for name in ("motion_gain", "control_gain", "sample_rate_hz", "duration", "run_in"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number, got {v!r}")
        if self.motion_gain < 0:
            raise ValueError(f"motion_gain must be >= 0, got {self.motion_gain}")
        if self.sample_rate_hz <= 0 or self.duration <= 0 or self.run_in < 0:
            raise ValueError("sample_rate_hz and duration must be > 0 and run_in >= 0")
        if self.task not in ("FD", "FT", "other"):
            raise ValueError(f"task must be 'FD', 'FT' or 'other', got {self.task!r}")
        scale = self.forcing_scale
        if isinstance(scale, numbers.Real) and not isinstance(scale, (bool, np.bool_)) \
                and math.isfinite(scale) and scale >= 0:
            object.__setattr__(self, "forcing_scale", float(scale))
        elif not (scale is None or (isinstance(scale, str) and scale in presets.FORCING_SCALE)):
            raise ValueError(f"forcing_scale must be None, one of {sorted(presets.FORCING_SCALE)} "
                             f"or a number >= 0, got {scale!r}")
        num, den = self.controlled_element
        num = np.atleast_1d(np.asarray(num, float))
        den = np.atleast_1d(np.asarray(den, float))
        num = np.trim_zeros(num, "f") if np.any(num) else np.array([0.0])
        den = np.trim_zeros(den, "f")
        if den.size == 0:
            raise ValueError(f"controlled_element needs a denominator, got den={den.tolist()}")
        degree = den.size - num.size
        if degree < 2:
            fast = den
            for _ in range(2 - degree):
                fast = np.polymul(fast, [0.01, 1.0])
            raise ValueError(
                f"controlled_element must be strictly proper with relative degree >= 2, got "
                f"num={num.tolist()}, den={den.tolist()} (relative degree {degree}): the "
                f"simulator makes the motion cue theta_ddot_m = K_theta theta_ddot from the "
                f"plant's state and its input delta, which is exact only when theta_dot does "
                f"not depend on delta directly (theta_ddot of a lower relative degree needs "
                f"the derivative of delta, that is of the pilot's output and of f_d). Add a "
                f"fast pole far above the task's frequencies, e.g. K/s as K/(s (0.01 s + 1)): "
                f"controlled_element=({num.tolist()}, {[float(f'{x:.6g}') for x in fast]})")
        for name in ("target", "disturbance"):
            f = getattr(self, name)
            high = above_nyquist(f.frequencies, f.amplitude, self.sample_rate_hz)
            if high.size:
                i = high[np.argmax(f.frequencies[high])]
                w = float(f.frequencies[i])
                raise ValueError(
                    f"the {name}'s line n = {int(f.n[i])} at {w / (2 * math.pi):.6g} Hz "
                    f"({w:.6g} rad/s) is at or above the Nyquist frequency "
                    f"{self.sample_rate_hz / 2:g} Hz of the {self.sample_rate_hz:g}-Hz "
                    f"recording: it would be recorded aliased; raise sample_rate_hz above "
                    f"{w / math.pi:.6g} Hz or leave the line out"
                    + (f" ({high.size} of its lines are at or above the Nyquist frequency)"
                       if high.size > 1 else ""))
        object.__setattr__(self, "controlled_element", (tuple(num), tuple(den)))
        self._check_forcing_scale()

    def _check_forcing_scale(self) -> None:
        """Refuse a ``forcing_scale`` that does not describe this task's forcing functions.

        ``dataclasses.replace(TrackingTask.paper("FD"), target=mine)`` kept the paper's
        scale, which :func:`simulate` then recorded for a forcing that is not Table 2's.
        Checked for the paper's tasks (FD, FT), the only ones a scale is defined for.
        """
        scale = self.forcing_scale
        if scale is None or self.task not in ("FD", "FT"):
            return
        ft, fd = presets.paper_forcing(self.task, scale)
        for name, mine, table in (("target", self.target, ft), ("disturbance", self.disturbance, fd)):
            same = (mine.base_frequency == table.base_frequency
                    and np.array_equal(mine.n, table.n)
                    and np.allclose(mine.amplitude, table.amplitude, rtol=1e-12, atol=0.0)
                    and np.allclose(mine.phase, table.phase, rtol=1e-12, atol=0.0))
            if not same:
                raise ValueError(
                    f"forcing_scale={scale!r} says the forcing functions are Table 2's for task "
                    f"{self.task} at that scale, but the {name} is not; give forcing_scale=None "
                    f"for forcing functions of your own (dataclasses.replace(task, {name}=..., "
                    f"forcing_scale=None))")

    @classmethod
    def paper(cls, task: str = "FD", motion_gain: float = 1.0,
              scale: str | float = "paper_simulation", **kwargs: Any) -> "TrackingTask":
        """The task of Pool et al. (2012): Table 2 forcing with the FD/FT scaling, K_c/s^2.

        Parameters
        ----------
        task : {"FD", "FT"}
        motion_gain : float
            K_theta.
        scale : str or float
            Forcing amplitude scale, see :func:`bayespilot.presets.paper_forcing`;
            kept as the task's ``forcing_scale``.
        **kwargs
            Overrides of the other fields (e.g. ``duration``).

        Returns
        -------
        TrackingTask
        """
        ft, fd = presets.paper_forcing(task, scale)
        return cls(ft, fd, motion_gain=float(motion_gain), task=task, forcing_scale=scale,
                   **kwargs)

    @property
    def n_samples(self) -> int:
        """Samples in the measurement window, round(duration * sample_rate_hz)."""
        return int(round(self.duration * self.sample_rate_hz))

    def metadata(self) -> dict[str, Any]:
        """Recording-format metadata describing this task."""
        num, den = self.controlled_element
        meta: dict[str, Any] = {"control_gain": self.control_gain}
        if len(num) == 1 and tuple(den) == (1.0, 0.0, 0.0):
            meta["controlled_element_gain"] = num[0]
        else:
            meta["controlled_element"] = {"num": list(num), "den": list(den)}
        # The recording's t = 0 is simulation time run_in: shift the phases so the
        # sidecar's multisines equal the recorded f_t and f_d at the recording's t.
        meta["forcing"] = {"base_frequency": self.target.base_frequency,
                           "target": _shifted(self.target, self.run_in).to_dict(),
                           "disturbance": _shifted(self.disturbance, self.run_in).to_dict()}
        return meta


def _shifted(f: Multisine, dt: float) -> Multisine:
    """The multisine g with g(t) = f(t + dt)."""
    return Multisine(f.base_frequency, f.n, f.amplitude,
                     np.mod(f.phase + f.frequencies * dt, 2 * np.pi))


@dataclass(frozen=True, eq=False)
class Simulation:
    """Result of :func:`simulate`.

    Attributes
    ----------
    recording : Recording
        What a lab would have recorded (t, e, u, theta_ddot_m, theta, f_t, f_d).
    params : dict
        The true pilot parameters, by name.
    remnant : ndarray
        The remnant n added to u, at the recording's samples.
    channels : dict
        Per channel name, ``"pre"`` (input of the nonlinearity, e.g. the canal
        output i) and ``"post"`` (its output, e.g. o) at the recording's samples.
    remnant_gain, remnant_fraction : float
        K_n used and the F_n = var(n) / var(u) it gave.
    seed : int
        The seed used (drawn from fresh entropy when ``seed=None`` was given).
    settings : dict
    """

    recording: Recording
    params: dict[str, float]
    remnant: np.ndarray
    channels: dict[str, dict[str, np.ndarray]]
    remnant_gain: float
    remnant_fraction: float
    seed: int | None
    settings: dict[str, Any] = field(default_factory=dict)

    def recording_with_truth(self) -> Recording:
        """The recording with the truth in its metadata, under ``"simulation"``.

        ``metadata["simulation"]`` holds ``parameters`` (the true parameters),
        ``seed``, ``remnant_gain``, ``remnant_fraction``, ``T_n``,
        ``settings`` (:attr:`settings`: the integration's oversampling, the
        run-in, the noise convention, the forcing scale, the fraction asked
        for; what a replay needs beside the seed) and ``bayespilot_version``
        (the release that simulated it: the data depend on the simulator's
        code; a sidecar without it, of an older release, reads the same;
        ``docs/recording-format.md``): what ``bayespilot
        simulate`` writes, so that a posterior of the recording shows the
        truth (``Posterior.truth``) and the file keeps it.  The diagnosis
        never reads it.

        Returns
        -------
        Recording
        """
        from . import __version__
        from ._files import VERSION_KEY

        meta = dict(self.recording.metadata)
        meta["simulation"] = {"parameters": {k: float(v) for k, v in self.params.items()},
                              "seed": None if self.seed is None else int(self.seed),
                              "remnant_gain": float(self.remnant_gain),
                              "remnant_fraction": float(self.remnant_fraction),
                              "T_n": self.settings.get("T_n"),
                              "settings": json_ready(dict(self.settings)),
                              VERSION_KEY: __version__}
        return replace(self.recording, metadata=meta)

    def write(self, path: str | os.PathLike) -> tuple[Path, Path]:
        """Write :meth:`recording_with_truth` as ``path.csv`` + ``path.json``
        (:func:`bayespilot.io.write_recording`; ``write_recording(sim.recording, ...)``
        leaves the truth out).

        Parameters
        ----------
        path : str or path-like
            The files' common path, without or with ``.csv``.

        Returns
        -------
        (Path, Path)
            The CSV and the JSON sidecar written.
        """
        from .io import write_recording

        return write_recording(self.recording_with_truth(), path)


def remnant(n_samples: int, dt: float, gain: float, T_n: float, rng: np.random.Generator,
            noise_psd: float) -> np.ndarray:
    """Remnant n = K_n / (T_n s + 1)^4 w (Eq. 6) on a grid of step ``dt``.

    w is held constant over each step with variance ``noise_psd / dt`` (white
    noise of two-sided PSD ``noise_psd``); the filter is discretised exactly
    for such held input (zero-order hold), and started in its stationary state
    by a run-in of 40 T_n.

    Parameters
    ----------
    n_samples : int
        Number of samples returned.
    dt : float
        Grid step, s.
    gain : float
        K_n; 0 returns zeros without drawing from ``rng``.
    T_n : float
        Time constant of the fourth-order filter, s (Table 3: 0.0578 s FD,
        0.0645 s FT).
    rng : numpy.random.Generator
        Source of w: ``n_samples + ceil(40 T_n / dt) + 8`` standard normal
        draws (the run-in included).
    noise_psd : float
        Two-sided power spectral density of w, rad^2 s (:func:`simulate`'s
        default is :data:`NOISE_PSD`, 0.01).

    Returns
    -------
    ndarray, shape (n_samples,)
        n at t = 0, dt, 2 dt, ..., in the units of u (rad).

    Notes
    -----
    The arguments are not checked: ``T_n`` and ``dt`` must be positive and
    ``noise_psd`` >= 0.
    """
    if gain == 0.0:
        return np.zeros(n_samples)
    num = [gain]
    den = np.poly(np.full(4, -1.0 / T_n)) * T_n**4
    bd, ad, _ = signal.cont2discrete((num, den), dt, method="zoh")
    bd = np.ravel(bd)
    extra = int(math.ceil(40 * T_n / dt)) + 8
    w = rng.standard_normal(n_samples + extra) * math.sqrt(noise_psd / dt)
    return signal.lfilter(bd, ad, w)[extra:]


def remnant_fraction(n: np.ndarray, u: np.ndarray) -> float:
    """F_n = var(n) / var(u), Eq. 7.

    Parameters
    ----------
    n : array_like
        The remnant added to the control output, rad.
    u : array_like
        The control output (remnant included), rad.

    Returns
    -------
    float
        F_n, the ratio of the variances about the means (numpy's ``var``);
        not finite when ``u`` is constant.
    """
    return float(np.var(n) / np.var(u))


def _plant_ss(task: TrackingTask):
    num, den = task.controlled_element
    A, Bm, C, D = signal.tf2ss(num, den)
    Bv = Bm[:, 0]
    Cv = C[0]
    C2 = Cv @ A @ A
    D2 = float(Cv @ A @ Bv)
    return (np.ascontiguousarray(A), np.ascontiguousarray(Bv), np.ascontiguousarray(Cv),
            np.ascontiguousarray(C2), D2)


#: The growth test of :func:`simulate` (a loop diverging too slowly for the kernel's limit
#: on its states): the record is cut in :data:`GROWTH_WINDOWS` equal windows, and the loop
#: is taken to diverge when the rms of u rises from each window to the next, is over
#: :data:`GROWTH_RATIO` times higher in the last window than in the first, and still rises
#: in the last step by at least :data:`GROWTH_STEADY` times the mean factor of a step (a
#: diverging loop grows by a steady factor; a start-up from rest slows down).  Records
#: whose windows would be shorter than :data:`GROWTH_MIN_WINDOW` s are not judged.
GROWTH_WINDOWS = 4
GROWTH_RATIO = 10.0
GROWTH_STEADY = 0.8
GROWTH_MIN_WINDOW = 5.0


def _growth(u: np.ndarray, sample_rate_hz: float) -> np.ndarray | None:
    """rms of u about zero in each of :data:`GROWTH_WINDOWS` equal windows of the record
    (None if the windows are shorter than :data:`GROWTH_MIN_WINDOW` s)."""
    m = u.size // GROWTH_WINDOWS
    if m < 2 or m < GROWTH_MIN_WINDOW * sample_rate_hz * (1 - 1e-9):
        return None
    w = np.asarray(u[:m * GROWTH_WINDOWS], float).reshape(GROWTH_WINDOWS, m)
    return np.sqrt(np.mean(w * w, axis=1))


def _diverging(u: np.ndarray, sample_rate_hz: float) -> str | None:
    """Why the recorded u shows a diverging loop (the growth test), or None."""
    r = _growth(u, sample_rate_hz)
    if r is None or not (np.all(r[1:] > r[:-1]) and r[-1] > GROWTH_RATIO * r[0]):
        return None
    total = r[-1] / r[0]
    if r[-1] / r[-2] < GROWTH_STEADY * total ** (1.0 / (GROWTH_WINDOWS - 1)):
        return None
    return (f"the rms of u grows {total:.3g} times over the record, window after window "
            f"({', '.join(f'{x:.3g}' for x in r)} rad in its {GROWTH_WINDOWS} "
            f"{u.size // GROWTH_WINDOWS / sample_rate_hz:g}-s windows)")


def _run(model: PilotModel, theta: np.ndarray, task: TrackingTask, n_fine: np.ndarray,
         oversample: int):
    fs = task.sample_rate_hz
    h = 1.0 / (fs * oversample)
    n_rec = task.n_samples
    k_start = int(round(task.run_in / h))
    n_steps = k_start + n_rec * oversample
    t_half = np.arange(2 * n_steps + 2) * (h / 2)
    ft = task.target(t_half)
    fd = task.disturbance(t_half)
    # remnant tabulated at half steps by linear interpolation of the fine grid
    nrem = np.interp(t_half, np.arange(n_fine.size) * h, n_fine)
    A, Bv, C0, C2, D2 = _plant_ss(task)
    p = model.plan
    sig, xpre, qpost, ok = CL.simulate_closed_loop(
        theta, p.ch_int, p.ch_float, p.st_int, p.st_const, p.out_int, A, Bv, C0, C2, D2,
        float(task.control_gain), float(task.motion_gain), ft, fd, nrem, h, n_steps,
        oversample, k_start, task.duration)
    return sig, xpre, qpost, ok, h, k_start


def simulate(model: PilotModel | None = None, params: Mapping[str, float] | None = None, *,
             task: str | TrackingTask = "FD", motion_gain: float | None = None,
             remnant_fraction: float | None = None, remnant_gain: float | None = None,
             T_n: float | None = None, seed: int | None = 0, oversample: int | None = None,
             duration: float | None = None, noise_psd: float | None = None,
             forcing_scale: str | float | None = None) -> Simulation:
    """Simulate one run of the closed-loop tracking task.

    Parameters
    ----------
    model : PilotModel, optional
        Default :func:`~bayespilot.model.paper_model`.
    params : mapping, optional
        Pilot parameters by name; missing ones take Table 3 values for the
        task (FD/FT) or the model's defaults.  Every value must lie within
        the parameter's bounds (Table 1 for the paper's model).
    task : {"FD", "FT"} or TrackingTask
        The paper's task preset, or a task of your own.  The recording
        starts at the integration step nearest to its ``run_in``.
    motion_gain : float, optional
        K_theta of a preset task name (default 1); a TrackingTask carries its
        own, and giving one beside it is refused.
    remnant_fraction : float, optional
        F_n in [0, 1): K_n is calibrated so that var(n)/var(u) = F_n on this
        realization (Eq. 7).  0 means no remnant.
    remnant_gain : float, optional
        K_n directly (exclusive with ``remnant_fraction``).
    T_n : float, optional
        Remnant filter time constant; default Table 3 for FD/FT, else 0.06 s.
    seed : int or None
        Seed of the remnant noise (numpy Generator); the same seed gives the
        same run, bit for bit.  None draws one from fresh entropy; the seed
        used is recorded in the result (``seed``, the recording's notes).
    oversample : int, optional
        Integration steps per recorded sample (>= 2); default
        :func:`integration_steps` of the task's rate (10 at 100 Hz).
    duration : float, optional
        Measurement time (default the task's, 81.92 s).
    noise_psd : float, optional
        Two-sided PSD of the remnant's white noise, rad^2 s; default
        :data:`NOISE_PSD` (0.01: unit-variance samples at 100 Hz) at every
        recording rate.
    forcing_scale : str or float, optional
        Amplitude scale of a preset task's forcing functions (default
        ``"paper_simulation"``; see :meth:`TrackingTask.paper`); refused
        beside a TrackingTask, as ``motion_gain`` is.  The scale applied is
        recorded in ``settings["forcing_scale"]``: for a TrackingTask its
        ``forcing_scale`` (that of :meth:`TrackingTask.paper`; None for
        forcing functions of your own, whose amplitudes are as given).

    Returns
    -------
    Simulation

    Raises
    ------
    ValueError
        On a bad argument (task name, ``remnant_fraction`` outside [0, 1),
        both remnant settings, ``oversample`` < 2, a non-positive
        ``duration``, ``T_n`` or ``noise_psd``), an unknown, complex or
        non-finite parameter, a parameter value (a fixed one included)
        outside the model's bounds (e.g. a negative delay or threshold: the
        likelihood would read future samples where the simulator
        extrapolates), or a remnant fraction the loop cannot reach.
    TypeError
        If ``model`` is not a PilotModel or ``task`` neither a str nor a
        TrackingTask.
    RuntimeError
        If the closed loop diverges for these parameters: a state of the
        plant passes 1e6 in the run, or the recorded u grows as only a
        diverging loop's does (below).

    Notes
    -----
    The growth test.  A loop that diverges slowly (e.g. the FD task with
    K_v = 2.7, whose u grows about 2.3 times every 10 s) stays under the
    kernel's limit of 1e6 over a whole run.  The record is therefore cut into
    four equal windows, and the loop is taken to diverge when the rms of u
    about zero rises from each window to the next, ends over 10 times higher
    than it began, and still rises in the last step by at least 0.8 times the
    mean factor of a step (exponential growth is steady; a start-up from rest
    with ``run_in=0`` slows down, and growth as any power of the time since
    rest does not pass).  Records shorter than 20 s (windows under 5 s) are not judged.  On
    stable loops the rise from the first window to the last stays below 1.8
    on the paper's tasks (FD and FT, K_theta 0 to 1, F_n 0 to 0.3, records of
    20 to 81.92 s) and below 4.5 from rest, so the test leaves every stable
    run as it was; a loop diverging slowly enough not to rise tenfold over the
    record is not caught (FD with K_v = 2.62 to 2.65 over 81.92 s, K_v = 2.7
    over 20 s).

    Examples
    --------
    >>> sim = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=3, duration=20.0)
    >>> sim.recording.n_samples
    2000
    >>> round(sim.remnant_fraction, 3)
    0.2
    """
    model = paper_model() if model is None else model
    if not isinstance(model, PilotModel):
        raise TypeError(f"model must be a PilotModel, got {type(model).__name__}")
    if params is not None and not isinstance(params, Mapping):
        raise TypeError(f"params must be a mapping of parameter values by name (e.g. "
                        f"{{'K_v': 0.1}}), got {type(params).__name__}")
    if isinstance(task, TrackingTask) and (motion_gain is not None or forcing_scale is not None):
        given = ", ".join(n for n, v in (("motion_gain", motion_gain),
                                         ("forcing_scale", forcing_scale)) if v is not None)
        raise ValueError(f"{given} set(s) the paper's preset task; the TrackingTask given "
                         f"carries its own (K_theta = {task.motion_gain:g}): build the task with "
                         f"what you want (e.g. TrackingTask.paper(..., motion_gain=...))")
    motion_gain = 1.0 if motion_gain is None else motion_gain
    if isinstance(task, str):
        forcing_scale = "paper_simulation" if forcing_scale is None else forcing_scale
        if task not in ("FD", "FT"):
            raise ValueError(f"task must be 'FD', 'FT' or a TrackingTask, got {task!r}")
        tt = TrackingTask.paper(task, motion_gain, scale=forcing_scale)
    elif isinstance(task, TrackingTask):
        tt = task
    else:
        raise TypeError(f"task must be 'FD', 'FT' or a TrackingTask, got {type(task).__name__}")
    if duration is not None:
        if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
            raise ValueError(f"duration must be a positive number of seconds, got {duration!r}")
        tt = replace(tt, duration=float(duration))
    if oversample is None:
        oversample = integration_steps(tt.sample_rate_hz)
    if isinstance(oversample, bool) or not isinstance(oversample, (int, np.integer)) \
            or oversample < 2:
        raise ValueError(f"oversample must be an integer >= 2, got {oversample!r}")
    if remnant_fraction is not None and remnant_gain is not None:
        raise ValueError("give remnant_fraction or remnant_gain, not both")
    if remnant_fraction is not None and not (0.0 <= remnant_fraction < 1.0):
        raise ValueError(f"remnant_fraction must be in [0, 1), got {remnant_fraction!r}")
    if remnant_gain is not None and not (math.isfinite(remnant_gain) and remnant_gain >= 0):
        raise ValueError(f"remnant_gain must be a finite number >= 0, got {remnant_gain!r}")
    values: dict[str, float] = {}
    if tt.task in presets.TABLE3:
        values.update({k: v for k, v in presets.TABLE3[tt.task].items() if k in model.all_names})
    if params is not None:
        values.update(params)
    theta = model.full_vector({k: v for k, v in values.items()})
    for k in model.fixed:
        if params is not None and k in params:
            theta[model.all_names.index(k)] = _parameter_value(k, params[k])
    for p, x in zip(model.parameters, theta):
        if not p.lower <= x <= p.upper:
            raise ValueError(f"parameter {p.name} = {x:g} is outside its bounds "
                             f"[{p.lower:g}, {p.upper:g}]")
    if T_n is None:
        T_n = presets.TABLE3_T_N.get(tt.task, 0.06)
    if not (math.isfinite(T_n) and T_n > 0):
        raise ValueError(f"T_n must be positive, got {T_n!r}")
    psd = NOISE_PSD if noise_psd is None else float(noise_psd)
    if not (math.isfinite(psd) and psd > 0):
        raise ValueError(f"noise_psd must be positive, got {noise_psd!r}")

    seed = resolve_seed(seed)  # None: a fresh one, recorded in the result and its notes
    rng = np.random.default_rng(seed)
    h = 1.0 / (tt.sample_rate_hz * oversample)
    k_start = int(round(tt.run_in / h))
    if not math.isclose(k_start * h, tt.run_in, rel_tol=1e-12, abs_tol=1e-12):
        # The loop records from its step k_start: start the remnant and the
        # metadata's phase shift there too.
        tt = replace(tt, run_in=k_start * h)
    n_fine_len = k_start + tt.n_samples * oversample + 2
    unit = remnant(n_fine_len, h, 1.0, T_n, rng, psd)  # remnant for K_n = 1

    def run(kn):
        sig, xpre, qpost, ok, _, _ = _run(model, theta, tt, kn * unit, oversample)
        why = "the plant's state passed 1e6" if not ok else \
            _diverging(sig[:, CL.SIG_U], tt.sample_rate_hz)
        if why is not None:
            raise RuntimeError("the closed loop diverged for these parameters "
                               f"({model.as_dict(theta, full=True)}): {why}")
        n = kn * np.interp(np.arange(tt.n_samples) / tt.sample_rate_hz + tt.run_in,
                           np.arange(unit.size) * h, unit)
        return sig, xpre, qpost, n

    if remnant_gain is not None:
        kn = float(remnant_gain)
        sig, xpre, qpost, n = run(kn)
    elif remnant_fraction:
        kn, (sig, xpre, qpost, n) = _calibrate(run, remnant_fraction)
    else:
        kn = 0.0
        sig, xpre, qpost, n = run(0.0)
    u = sig[:, CL.SIG_U]
    fn = remnant_fraction_value = float(np.var(n) / np.var(u)) if kn > 0 else 0.0
    t = np.arange(tt.n_samples) / tt.sample_rate_hz
    signals = {"t": t, "e": sig[:, CL.SIG_E], "u": u, "theta_ddot_m": sig[:, CL.SIG_THDDM],
               "theta": sig[:, CL.SIG_THETA], "f_t": sig[:, CL.SIG_FT], "f_d": sig[:, CL.SIG_FD]}
    meta = tt.metadata()
    meta["notes"] = (f"simulated by bayespilot: seed={seed}, K_n={kn:.6g}, T_n={T_n:g}, "
                     f"F_n={fn:.4f}, oversample={oversample}")
    rec = Recording(signals, tt.sample_rate_hz, tt.motion_gain, tt.task, meta,
                    source=f"simulation(seed={seed})")
    chans = {c.name: {"pre": xpre[i].copy(), "post": qpost[i].copy()}
             for i, c in enumerate(model.channels)}
    settings = {"oversample": oversample, "T_n": T_n, "noise_psd": psd, "run_in": tt.run_in,
                "duration": tt.duration, "forcing_scale": tt.forcing_scale,
                "requested_remnant_fraction": remnant_fraction}
    return Simulation(rec, model.as_dict(theta, full=True), n, chans, kn, remnant_fraction_value,
                      seed, settings)


def _calibrate(run, target: float):
    """K_n giving var(n)/var(u) = target on this noise realisation.

    F_n(K_n) is measured on the actual closed loop (the dead zone included:
    more remnant opens the threshold and changes the loop, so a linear
    estimate is only the starting guess) and solved with Brent's method on a
    bracket that is widened until it holds the target.
    """
    def frac(k):
        out = run(k)
        return float(np.var(out[3]) / np.var(out[0][:, CL.SIG_U])) - target, out

    # Starting guess from var(u) ~ a + b K^2 (linear loop): F = K^2 v / (a + b K^2).
    sig0, _, _, n_unit = run(1.0)
    a = float(np.var(run(0.0)[0][:, CL.SIG_U]))
    v = float(np.var(n_unit))
    b = max(float(np.var(sig0[:, CL.SIG_U])) - a, 1e-30)
    k0 = math.sqrt(target * a / (v - target * b)) if v > target * b else math.sqrt(a / v)
    lo, hi = k0, k0
    f_lo, _ = frac(lo)
    f_hi = f_lo
    for _ in range(40):
        if f_lo <= 0.0:
            break
        hi, f_hi = lo, f_lo
        lo /= 1.5
        f_lo, _ = frac(lo)
    for _ in range(40):
        if f_hi >= 0.0:
            break
        try:
            f_next, _ = frac(hi * 1.5)
        except RuntimeError:  # a remnant so large that the loop's states pass the kernel's limit
            break
        if f_next - f_hi < 1e-6:
            # F_n levels off below the target: where the remnant dominates u, var(n)/var(u)
            # tends to a limit of the closed loop (e.g. about 0.09 without motion feedback)
            break
        lo, f_lo = hi, f_hi
        hi, f_hi = hi * 1.5, f_next
    if f_hi < 0.0 or f_lo > 0.0:
        raise ValueError(f"remnant fraction {target} cannot be reached in this closed loop "
                         f"(F_n stays at {f_hi + target:.3f} or below up to K_n = {hi:.3g})")
    if f_hi == 0.0:
        lo = hi
    k = lo if f_lo == 0.0 else optimize.brentq(lambda x: frac(x)[0], lo, hi, xtol=1e-7, rtol=1e-6)
    return k, run(k)


def calibrate_remnant_gain(remnant_fraction: float, *, task: str | TrackingTask = "FD",
                           motion_gain: float | None = None,
                           model: PilotModel | None = None, params: Mapping[str, float] | None = None,
                           seeds: range | list[int] = range(10), **kwargs: Any) -> tuple[float, np.ndarray]:
    """K_n that gives ``remnant_fraction`` on average over several realizations.

    Returns the mean K_n over ``seeds`` and the per-seed values (each seed
    calibrated on its own realization), the quantity Table 4 lists.

    Parameters
    ----------
    remnant_fraction : float
        F_n in [0, 1) to reach on each realization (Eq. 7); 0 gives K_n = 0.
    task : {"FD", "FT"} or TrackingTask, default "FD"
        The paper's task preset, or a task of your own (see :func:`simulate`).
    motion_gain : float, optional
        K_theta of a preset task name (default 1; see :func:`simulate`).
    model : PilotModel, optional
        Default :func:`~bayespilot.model.paper_model`.
    params : mapping of str to float, optional
        Pilot parameters by name; missing ones take Table 3 values for the
        task (FD/FT) or the model's defaults.
    seeds : range or list of int, default range(10)
        Remnant seeds, one realization each (``seed`` of :func:`simulate`).
    **kwargs
        Further keyword arguments of :func:`simulate` (``T_n``,
        ``oversample``, ``duration``, ``noise_psd``, ``forcing_scale``).

    Returns
    -------
    mean_gain : float
        The mean K_n over ``seeds``.
    gains : ndarray, shape (len(seeds),)
        K_n calibrated on each seed's realization, in the order of ``seeds``.

    Raises
    ------
    ValueError
        If :func:`simulate` refuses the arguments (e.g. ``remnant_fraction``
        outside [0, 1), a task name other than "FD" or "FT", or
        ``remnant_gain`` among ``kwargs``), the fraction cannot be reached
        in the closed loop, or ``seeds`` is empty.
    TypeError
        If ``model`` is not a PilotModel or ``task`` is neither a str nor a
        TrackingTask.
    RuntimeError
        If the closed loop diverges for these parameters.
    """
    seeds = list(seeds)
    if not seeds:
        raise ValueError("seeds is empty: give at least one remnant seed to average over")
    gains = np.array([simulate(model, params, task=task, motion_gain=motion_gain,
                               remnant_fraction=remnant_fraction, seed=s, **kwargs).remnant_gain
                      for s in seeds])
    return float(gains.mean()), gains

"""Multisine forcing functions (Eq. 5 of Pool et al. 2012).

f(t) = sum_i A(i) sin(omega_0 n(i) t + phi(i))
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = ["Multisine", "SNAP_TOLERANCE", "EXACT_TOLERANCE", "whole_periods_frequency",
           "columns_whole_periods", "above_nyquist"]


def _is_complex(x: Any) -> bool:
    """True if ``x`` (a number or array_like) holds complex values."""
    arr = np.asarray(x)
    if arr.dtype == object:
        return any(np.iscomplexobj(v) for v in arr.flat)
    return arr.dtype.kind == "c"


@dataclass(frozen=True, eq=False)
class Multisine:
    """A sum of sinusoids at integer multiples of a base frequency.

    Parameters
    ----------
    base_frequency : float
        omega_0 = 2 pi / T0, rad/s.
    n : array_like of int
        Integer multiples n(i) >= 1 of the base frequency (integer-valued
        floats such as 3.0 are accepted and stored as int).
    amplitude : array_like of float
        A(i), rad.
    phase : array_like of float
        phi(i), rad.

    Raises
    ------
    ValueError
        If a value is complex, ``n``, ``amplitude`` and ``phase`` are not 1-D
        of equal length or not finite, an ``n`` is not an integer >= 1, or
        ``base_frequency`` is not a positive number.

    Examples
    --------
    >>> f = Multisine(0.5, [1, 2], [1.0, 0.5], [0.0, 0.0])
    >>> float(f(np.array([0.0]))[0])
    0.0
    """

    base_frequency: float
    n: np.ndarray
    amplitude: np.ndarray
    phase: np.ndarray

    def __post_init__(self) -> None:
        for name in ("base_frequency", "n", "amplitude", "phase"):
            if _is_complex(getattr(self, name)):
                raise ValueError(f"{name} must be real, got complex values: {getattr(self, name)!r}")
        if np.asarray(self.n).dtype.kind == "b":
            raise ValueError(f"n must hold integers >= 1, got booleans {self.n!r}")
        n = np.atleast_1d(np.asarray(self.n, dtype=float))
        a = np.atleast_1d(np.asarray(self.amplitude, dtype=float))
        p = np.atleast_1d(np.asarray(self.phase, dtype=float))
        if not (n.shape == a.shape == p.shape) or n.ndim != 1:
            raise ValueError(
                f"n, amplitude and phase must be 1-D of equal length, got shapes "
                f"{n.shape}, {a.shape}, {p.shape}"
            )
        if not (np.all(np.isfinite(n)) and np.all(np.isfinite(a)) and np.all(np.isfinite(p))):
            raise ValueError("n, amplitude and phase must be finite")
        bad = n[(n != np.round(n)) | (n < 1)]
        if bad.size:
            raise ValueError(f"n must hold integers >= 1 (multiples of the base frequency), "
                             f"got {bad.tolist()}")
        try:
            w0 = float(self.base_frequency)
        except (TypeError, ValueError):
            raise ValueError(f"base_frequency must be a positive number, got {self.base_frequency!r}") from None
        if not np.isfinite(w0) or w0 <= 0:
            raise ValueError(f"base_frequency must be positive, got {self.base_frequency!r}")
        object.__setattr__(self, "n", n.astype(np.int64))
        object.__setattr__(self, "amplitude", a)
        object.__setattr__(self, "phase", p)
        object.__setattr__(self, "base_frequency", w0)

    @property
    def frequencies(self) -> np.ndarray:
        """omega_0 n(i), rad/s."""
        return self.base_frequency * self.n

    def scaled(self, factor: float) -> "Multisine":
        """The same signal with every amplitude multiplied by ``factor``.

        Parameters
        ----------
        factor : float
            The scale on the amplitudes (dimensionless).

        Returns
        -------
        Multisine
        """
        return Multisine(self.base_frequency, self.n, self.amplitude * factor, self.phase)

    def __call__(self, t: np.ndarray, derivative: int = 0) -> np.ndarray:
        """Evaluate f, or its ``derivative``-th time derivative, at times ``t``.

        Parameters
        ----------
        t : ndarray
            Times, s.
        derivative : int, default 0
            Order k of the time derivative (0: f itself).

        Returns
        -------
        ndarray
            d^k f / dt^k at ``t`` (same shape), in the amplitudes' unit per s^k.
        """
        t = np.asarray(t, dtype=float)
        w = self.frequencies
        arg = np.multiply.outer(t, w) + self.phase
        # d^k/dt^k sin(x) = sin(x + k pi / 2)
        return (np.sin(arg + derivative * np.pi / 2) * (self.amplitude * w**derivative)).sum(axis=-1)

    def to_dict(self) -> dict[str, Any]:
        """The ``n``, ``amplitude``, ``phase`` lists of the recording format."""
        return {"n": self.n.tolist(), "amplitude": self.amplitude.tolist(),
                "phase": self.phase.tolist()}

    @classmethod
    def from_dict(cls, base_frequency: float, d: Mapping[str, Any]) -> "Multisine":
        """Build from a ``forcing.target`` or ``forcing.disturbance`` object.

        Parameters
        ----------
        base_frequency : float
            omega_0, rad/s (the recording format's ``forcing.base_frequency``).
        d : mapping
            ``n``, ``amplitude`` and ``phase`` lists (:meth:`to_dict`).

        Returns
        -------
        Multisine

        Raises
        ------
        KeyError
            If ``n``, ``amplitude`` or ``phase`` is missing.
        ValueError
            If the lists are invalid (see :class:`Multisine`).
        """
        return cls(base_frequency, d["n"], d["amplitude"], d["phase"])

    @classmethod
    def zero(cls, base_frequency: float = 1.0) -> "Multisine":
        """A signal that is 0 everywhere.

        Parameters
        ----------
        base_frequency : float, default 1.0
            omega_0, rad/s.

        Returns
        -------
        Multisine
            One line (n = 1) of amplitude 0.
        """
        return cls(base_frequency, [1.0], [0.0], [0.0])


#: A forcing line within this many cycles (over the record) of a whole number of cycles counts
#: as whole periods: a sidecar's base frequency that puts every line this close is snapped to
#: the nearest that puts them on the record's DFT bins (a rounded value, as printed in a
#: paper), by :func:`whole_periods_frequency`, the one rule of
#: :func:`bayespilot.likelihood.whole_periods` and :func:`bayespilot.diagnose.locate.forcing_of`;
#: a line off by more is not a bin.  (0.05 cycle off its bin keeps 99.6 % of its amplitude
#: there.)
SNAP_TOLERANCE = 0.05
#: A base frequency that puts every forcing line within this many cycles (over the record) of a
#: whole number of cycles is taken as it is (:func:`whole_periods_frequency` does not snap it).
EXACT_TOLERANCE = 1e-3


def above_nyquist(frequencies: Any, amplitude: Any, sample_rate_hz: float) -> np.ndarray:
    """The indices of the lines of nonzero amplitude at or above the Nyquist frequency.

    The one rule of :class:`~bayespilot.simulate.TrackingTask` and the recording reader:
    such a line cannot be sampled at ``sample_rate_hz`` (it would be recorded aliased).  A
    relative 1e-12 below pi * rate counts as at it (a line exactly at Nyquist computed from
    n times a rounded base frequency).

    Parameters
    ----------
    frequencies : array_like
        The lines' frequencies, rad/s.
    amplitude : array_like
        Their amplitudes (a line of zero amplitude is not in the signal: not counted).
    sample_rate_hz : float
        The sample rate, Hz.

    Returns
    -------
    numpy.ndarray
        Indices into ``frequencies``, ascending.

    Raises
    ------
    ValueError
        ``sample_rate_hz`` not a positive finite number, or ``frequencies``
        and ``amplitude`` not 1-D arrays of one length.
    """
    if not (isinstance(sample_rate_hz, (int, float, np.integer, np.floating))
            and not isinstance(sample_rate_hz, bool) and math.isfinite(sample_rate_hz)
            and sample_rate_hz > 0):
        raise ValueError(f"sample_rate_hz must be a positive finite number, got "
                         f"{sample_rate_hz!r}")
    w = np.asarray(frequencies, dtype=float)
    a = np.asarray(amplitude, dtype=float)
    if w.ndim != 1 or w.shape != a.shape:
        raise ValueError(f"frequencies and amplitude must be 1-D arrays of one length, got "
                         f"shapes {w.shape} and {a.shape}")
    return np.flatnonzero((w >= math.pi * float(sample_rate_hz) * (1 - 1e-12)) & (a != 0))


def whole_periods_frequency(base_frequency: float, n: Any, amplitude: Any,
                            duration: float) -> float | None:
    """The base frequency at which a ``duration``-s record holds whole periods of forcing lines.

    The one rule of "whole periods of the forcing" read from a sidecar, of
    :func:`bayespilot.likelihood.whole_periods` (the start-up discard) and of
    :func:`bayespilot.diagnose.locate.forcing_of` (the frequency evidence).  The lines
    n(i) omega_0 sum to a signal of period 2 pi / (g omega_0), g the greatest common divisor
    of the n: the record holds whole periods of it when one base frequency omega near
    omega_0 makes the record j >= 1 such periods, T = 2 pi j / (g omega), and moves no line
    by more than :data:`SNAP_TOLERANCE` cycle (a rounded omega_0, as printed in a paper).
    Each line within 0.05 cycle of whole cycles at omega_0, but at no common omega, is not
    whole periods (the lines' own roundings contradict their base frequency).

    Only the lines of nonzero amplitude count (one of zero amplitude is not in the signal);
    with none, every line given counts.

    Parameters
    ----------
    base_frequency : float
        omega_0, rad/s (> 0).
    n : array_like of int
        The lines' multiples of ``base_frequency``, of the target and the disturbance together.
    amplitude : array_like of float
        Their amplitudes (the same length as ``n``).
    duration : float
        The record's length, n_samples * dt, s (> 0).

    Returns
    -------
    float or None
        ``base_frequency`` itself when it puts every counted line within
        :data:`EXACT_TOLERANCE` (1e-3) cycle of its whole cycles, else the nearest base
        frequency that puts them on whole cycles when that moves none by more than
        :data:`SNAP_TOLERANCE` (0.05) cycle; None when the record does not hold whole
        periods (or is shorter than half of one).

    Raises
    ------
    ValueError
        If ``n`` and ``amplitude`` differ in length, or ``base_frequency`` or ``duration``
        is not a positive finite number.

    Examples
    --------
    >>> w0 = 2 * np.pi / 81.92
    >>> whole_periods_frequency(w0, [5, 6], [1.0, 1.0], 81.92) == w0
    True
    >>> round(whole_periods_frequency(0.0767, [5, 211], [1.0, 1.0], 81.92), 6)  # as printed
    0.076699
    >>> whole_periods_frequency(w0, [5, 6], [1.0, 1.0], 40.0) is None
    True
    """
    w0, T = float(base_frequency), float(duration)
    if not (math.isfinite(w0) and w0 > 0 and math.isfinite(T) and T > 0):
        raise ValueError(f"base_frequency and duration must be positive finite numbers, got "
                         f"{base_frequency!r} and {duration!r}")
    n = np.abs(np.rint(np.asarray(n, dtype=float).ravel()))
    a = np.asarray(amplitude, dtype=float).ravel()
    if n.shape != a.shape:
        raise ValueError(f"n and amplitude must have the same length, got {n.size} and {a.size}")
    if np.any(a != 0.0):
        n = n[a != 0.0]
    n = n[n != 0.0]  # (a constant is whole periods of any record)
    if n.size == 0:
        return w0
    m = w0 * T / (2 * np.pi)  # base periods in the record
    g = int(np.gcd.reduce(n.astype(np.int64)))  # the signal's period is 2 pi / (g w0)
    j = int(np.rint(m * g))  # whole periods of the signal in the record
    if j < 1:
        return None
    off = float(np.max(n * abs(m - j / g)))  # each line's distance from its bin at j / g
    if off <= EXACT_TOLERANCE:
        return w0
    if off <= SNAP_TOLERANCE:
        return 2 * np.pi * j / (g * T)
    return None


def columns_whole_periods(columns: Sequence[Any]) -> bool | None:
    """Whether recorded forcing columns (``f_t``, ``f_d``: either or both) are whole periods.

    The one rule of "whole periods" read from the columns, of
    :func:`bayespilot.likelihood.whole_periods` and of
    :func:`bayespilot.diagnose.locate.forcing_of`: each column that is not zero throughout
    continues smoothly from its last sample to its first (its second differences across
    the wrap no larger than 3 times the largest inside the record); a record cut
    mid-period cuts every forcing function, so either column alone tells.

    Parameters
    ----------
    columns : sequence of array_like
        The forcing columns the record has.

    Returns
    -------
    bool or None
        None when there is none, or every one is zero throughout (not known).
    """
    cols = [np.asarray(x, dtype=float) for x in columns]
    cols = [x for x in cols if np.any(x != 0.0)]
    if not cols:
        return None
    return all(_wraps_smoothly(x) for x in cols)


def _wraps_smoothly(x: np.ndarray) -> bool:
    """True if ``x`` continues smoothly from its last sample to its first, as a record of whole
    periods does: the second differences across the wrap are no larger than 3 times the
    largest inside the record (a record cut mid-period jumps there)."""
    x = np.asarray(x, dtype=float)
    if x.size < 4:
        return False
    inside = np.max(np.abs(np.diff(x, 2)))
    wrap = max(abs(x[1] - 2 * x[0] + x[-1]), abs(x[0] - 2 * x[-1] + x[-2]))
    return bool(wrap <= 3.0 * inside + 1e-12 * np.max(np.abs(x)))

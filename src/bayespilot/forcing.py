"""Multisine forcing functions (Eq. 5 of Pool et al. 2012).

f(t) = sum_i A(i) sin(omega_0 n(i) t + phi(i))
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

__all__ = ["Multisine", "SNAP_TOLERANCE"]


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
#: as whole periods: the diagnosis snaps a sidecar's base frequency that puts every line this
#: close to the nearest that puts them on the record's DFT bins (a rounded value, as printed in
#: a paper), and :func:`bayespilot.likelihood.whole_periods` reads a record so; a line off by
#: more is not a bin.  (0.05 cycle off its bin keeps 99.6 % of its amplitude there.)
SNAP_TOLERANCE = 0.05


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

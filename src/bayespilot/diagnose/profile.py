"""Profile-likelihood intervals of the chosen extension's new parameters.

A Wald interval (estimate +- 1.645 standard errors) assumes the likelihood is
quadratic in the parameter.  Two catalogue entries break that on single runs:
the soft threshold's corner width w_soft, bounded at 0.05 IPUT and traded
off against the crisp threshold delta_abs (on 160 runs at w_soft = 0.045 its
Wald interval held the truth in 69 %, the profile interval in 88 %;
``docs/diagnose-evidence.md``, *The profile-likelihood interval*), and, less,
the otolith's head height (76 % and 81 %).
The profile likelihood follows the ridge: each parameter is held at values
stepped out from the reported estimate, every other parameter refitted
(continuation from the neighbouring point), until -ln L has risen well past
chi2_1(level) / 2 (:data:`STOP`) or the bound is reached.  The interval is
the hull of the points below that level (the soft threshold's profile can
dip below it twice).  A point that fits better than the reported fit makes
the fit again from there (19 of those 160 runs; 26 of 160 with a 6-rad/s
platform, by about 0.4 standard errors).

The reported fit's own noise model gives standard errors that are too
small on closed-loop runs (``docs/diagnose-evidence.md``, *The reported
fit*); what is reported are the test's, which cover.  The profile's
deviance is scaled by the same ratio, (own s.e. / test s.e.)^2 when that is
below 1, so that where the profile is quadratic the interval is the
reported Wald interval; where it is not, it has the profile's shape.  This
is the magnitude adjustment of a likelihood-ratio statistic for a
misspecified likelihood (Chandler & Bate 2007, Biometrika 94(1)).

It is written here, not taken from a library: the profile's points are
constrained refits of the decision likelihood (:mod:`bayespilot.diagnose.decide`),
which no general-purpose profiler knows how to make.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np
from scipy import stats

from .._files import number
from .decide import FitSummary, Whitened, _gls_refine, scan_threshold

__all__ = ["ProfileInterval", "profile_interval", "profile_intervals", "LEVEL", "STEPS", "STOP",
           "BETTER_TOL"]

#: Coverage of the reported profile intervals.
LEVEL = 0.90
#: Where the profile is evaluated on each side of the estimate, in half standard errors
#: (the reported s.e.): close in for the crossing of a quadratic profile (near 3.3), growing
#: so that a flat one reaches its bound in a few more refits.
STEPS = (1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0)
#: Each side's stepping stops where the scaled deviance exceeds this many times the
#: interval's chi2_1 quantile (or at the bound, or after the last step).
STOP = 4.0
#: A profile point better than the reported fit by more than this (-ln L) means the reported
#: fit was not the maximum: the fit is made again from that point.
BETTER_TOL = 0.01


@dataclass(eq=False)
class ProfileInterval:
    """The profile-likelihood interval of one parameter.

    Attributes
    ----------
    name : str
        The parameter.
    level : float
        Its coverage (0.9: 90 %).
    lower, upper : float
        The interval's ends, in the parameter's unit.
    lower_open, upper_open : bool
        True where the profile had not risen far enough by its last step (short
        of the parameter's bound): the interval reaches at least that far.  An
        end at the bound is closed.
    scale : float
        The factor on the deviance, (own s.e. / test s.e.)^2 capped at 1.
    values, deviance : ndarray
        The profile's points (sorted) and their scaled deviance from the fit.
    """

    name: str
    level: float
    lower: float
    upper: float
    lower_open: bool = False
    upper_open: bool = False
    scale: float = 1.0
    values: np.ndarray = field(default_factory=lambda: np.zeros(0))
    deviance: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def quantile(self) -> float:
        """The chi2_1 quantile at ``level`` the scaled deviance stays below inside."""
        return float(stats.chi2.ppf(self.level, 1))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of the attributes except ``name`` (arrays as lists)."""
        return {"level": self.level, "lower": float(self.lower), "upper": float(self.upper),
                "lower_open": self.lower_open, "upper_open": self.upper_open,
                "scale": float(self.scale), "values": [float(v) for v in self.values],
                "deviance": [float(d) for d in self.deviance]}

    @classmethod
    def from_dict(cls, name: str, d: Mapping[str, Any]) -> "ProfileInterval":
        """The interval of parameter ``name`` that a :meth:`to_dict` holds (the dict is keyed
        by the name and does not repeat it).

        Parameters
        ----------
        name : str
            The parameter (the key the dict is stored under).
        d : mapping
            A :meth:`to_dict`, as read from JSON (a null number is NaN); only
            ``level``, ``lower`` and ``upper`` are required.

        Returns
        -------
        ProfileInterval

        Raises
        ------
        KeyError
            If ``level``, ``lower`` or ``upper`` is missing.
        """
        return cls(name, number(d["level"]), number(d["lower"]), number(d["upper"]),
                   bool(d.get("lower_open", False)), bool(d.get("upper_open", False)),
                   number(d.get("scale", 1.0)),
                   np.array([number(v) for v in d.get("values", ())], dtype=float),
                   np.array([number(v) for v in d.get("deviance", ())], dtype=float))

    def __str__(self) -> str:
        lo = f"{'<=' if self.lower_open else ''}{self.lower:.4g}"
        hi = f"{'>=' if self.upper_open else ''}{self.upper:.4g}"
        return f"[{lo}, {hi}]"


def _crossing(v0: float, d0: float, v1: float, d1: float, q: float) -> float:
    """Where the deviance, linear between (v0, d0 <= q) and (v1, d1 > q), reaches q."""
    return v0 + (v1 - v0) * (q - max(d0, 0.0)) / (d1 - max(d0, 0.0))


def profile_interval(wl: Whitened, fit: FitSummary, name: str, names: Sequence[str], *,
                     scan: bool, step: float, scale: float = 1.0,
                     level: float = LEVEL) -> tuple[ProfileInterval, FitSummary | None]:
    """The profile-likelihood interval of ``name`` under ``wl`` from the fit ``fit``.

    Parameters
    ----------
    wl : Whitened
        The likelihood of the reported fit.
    fit : FitSummary
        The reported fit (its maximum).
    name : str
        The parameter profiled.
    names : sequence of str
        The parameters the fit refines; all but ``name`` are refitted at each point.
    scan : bool
        Scan delta_abs again at each point (an entry that does not refine it).
    step : float
        Half a standard error of ``name``: the unit of :data:`STEPS`.
    scale : float
        Factor on the deviance (0 < scale <= 1 widens).
    level : float
        Coverage, in (0, 1).

    Returns
    -------
    interval : ProfileInterval
    better : FitSummary or None
        A fit better than ``fit`` by more than :data:`BETTER_TOL`, freely refitted from the
        profile's best point, when the profile found one (the interval is then relative to
        ``fit`` and should be made again from ``better``).
    """
    if not isinstance(wl, Whitened):
        raise TypeError(f"wl must be a Whitened likelihood, got {type(wl).__name__}")
    if name not in names or name not in fit.params:
        raise ValueError(f"{name!r} is not one of the fit's refined parameters "
                         f"({', '.join(names)})")
    if not 0 < level < 1:
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    if not (math.isfinite(step) and step > 0):
        raise ValueError(f"step must be a positive number, got {step!r}")
    if not 0 < scale <= 1:
        raise ValueError(f"scale must be in (0, 1], got {scale!r}")
    model = wl.model
    par = model.parameter(name)
    held = tuple(n for n in names if n != name)
    est = float(fit.params[name])
    q = float(stats.chi2.ppf(level, 1))
    points = [(est, fit.neg_log_lik, fit)]
    ends: dict[int, tuple[float, bool]] = {}
    for side, bound in ((-1, par.lower), (1, par.upper)):
        prev, at_bound, side_points = fit, est == bound, [(est, 0.0)]
        for k in STEPS:
            if at_bound:
                break
            v = est + side * k * step
            at_bound = side * (v - bound) >= 0
            v = bound if at_bound else v
            f = _gls_refine(wl, dict(prev.params, **{name: v}), held)
            if scan:
                f = scan_threshold(wl, f, held)
            points.append((v, f.neg_log_lik, f))
            prev = f
            d = 2.0 * (f.neg_log_lik - fit.neg_log_lik) * scale
            side_points.append((v, d))
            if d > STOP * q:
                break
        # the farthest point inside; the profile may dip below q again past a first
        # crossing (the soft threshold's is bimodal in w_soft), so the interval is the hull
        j = max(i for i, (_, d) in enumerate(side_points) if d <= q)
        if j + 1 < len(side_points):
            ends[side] = (_crossing(*side_points[j], *side_points[j + 1], q), False)
        else:
            # not risen by the bound: the bound closes the interval; by the last step: open
            ends[side] = (side_points[j][0], not at_bound)
    points.sort(key=lambda p: p[0])
    values = np.array([p[0] for p in points])
    dev = 2.0 * (np.array([p[1] for p in points]) - fit.neg_log_lik) * scale
    interval = ProfileInterval(name, level, ends[-1][0], ends[1][0], ends[-1][1], ends[1][1],
                               scale, values, dev)
    best = min(points, key=lambda p: p[1])
    better = None
    if best[1] < fit.neg_log_lik - BETTER_TOL:
        better = _gls_refine(wl, best[2].params, names)
        if scan:
            better = scan_threshold(wl, better, names)  # neither is ever worse than its start
    return interval, better


def profile_intervals(wl: Whitened, fit: FitSummary, parameters: Sequence[str],
                      names: Sequence[str], *, scan: bool, test_stderr: Mapping[str, float],
                      level: float = LEVEL,
                      max_restarts: int = 2) -> tuple[FitSummary, dict[str, ProfileInterval]]:
    """Profile intervals of every one of ``parameters``, the fit made again from a better
    point when a profile finds one (at most ``max_restarts`` times; a better point found after
    that is not taken).

    Parameters
    ----------
    wl : Whitened
        The likelihood of the reported fit.
    fit : FitSummary
        The reported fit.
    parameters : sequence of str
        The parameters profiled (the extension's new ones).
    names : sequence of str
        The parameters the fit refines.
    scan : bool
        Scan delta_abs again at each point.
    test_stderr : mapping
        The reported (the test's) standard errors: the step and, with the fit's own, the
        deviance's scale.
    level : float
    max_restarts : int

    Returns
    -------
    fit : FitSummary
        ``fit``, or the better one a profile found.
    intervals : dict
        Parameter name -> :class:`ProfileInterval`.
    """
    if not (isinstance(max_restarts, (int, np.integer)) and max_restarts >= 0):
        raise ValueError(f"max_restarts must be an integer >= 0, got {max_restarts!r}")
    model = wl.model
    restarts = 0
    while True:
        own = fit.stderr
        intervals, better = {}, None
        for name in parameters:
            se = float(test_stderr.get(name, math.nan))
            se_own = float(own.get(name, math.nan))
            has, has_own = (math.isfinite(x) and x > 0 for x in (se, se_own))
            # without the test's standard error: steps of the fit's own, unscaled (or a
            # twentieth of the bounds' span)
            scale = min(1.0, (se_own / se) ** 2) if has and has_own else 1.0
            if not has:
                par = model.parameter(name)
                se = se_own if has_own else (par.upper - par.lower) / 20.0
            iv, better = profile_interval(wl, fit, name, names, scan=scan, step=se / 2.0,
                                          scale=scale, level=level)
            intervals[name] = iv
            if better is not None and restarts < max_restarts:
                break  # the intervals are made again from the better fit
        if better is None or restarts == max_restarts:
            return fit, intervals
        fit, restarts = better, restarts + 1

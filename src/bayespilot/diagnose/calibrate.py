"""Calibrate a candidate's likelihood-ratio test by a parametric bootstrap of the base model.

The decision's p-values (:func:`bayespilot.diagnose.decide.lr_p_value`) are
asymptotic: chi2(df), or the chi-bar-squared mixture for a boundary null.
Measured on simulated correct-model runs they hold for most entries, but not
for all (``docs/diagnose-evidence.md``): the washout's statistic has a heavier tail
(0.095 of 200 pooled controls below 0.05, 0.062 of 1200 single runs), and the
drift's in a condition where K_m is weakly identified.  This module measures
the null distribution of one candidate's statistic on the recording at hand:

1. each run's base model, at its GLS fit, is simulated in the closed loop of
   the recording's task with a remnant of the level and colour of its own
   residual (the generator of the located evidence's null,
   :func:`bayespilot.diagnose.locate.bootstrap`): B replicates on which the
   base model is true;
2. on each replicate the decision is retraced for that candidate: the base
   model fitted by Eq. 4 (the fast fit, as for the recording), the noise
   model estimated from its residual, the base model refitted by GLS, the
   extension fitted from it (all runs together for a pooled diagnosis) and
   the base model refitted from the extension's fit (the test is against the
   best base fit found, as on the data);
3. the replicates' mean improvement over the asymptotic reference's mean
   (0.25 for a one-parameter boundary null, df/2 otherwise) is the scale c
   of the statistic's null distribution, and the calibrated p-value is the
   reference's at 2 d(-ln L) / max(1, c): a Bartlett-type correction
   estimated by bootstrap (Bartlett 1937; Rocke 1989, JASA 84, 598).

Why a scale and not the replicates' empirical p-value: the decision's level
per candidate is about 0.002 (0.01 over five or six candidates), which an
empirical p-value from B replicates cannot go below 1 / (B + 1) without
hundreds of refits; the mean of B = 39 replicates fixes c to about
+-15 % (two-parameter entries) to +-35 % (boundary nulls).  c is never taken
below 1, so that the noise of its estimate cannot make a test more liberal
than the asymptotic one.

Measured (``docs/diagnose-evidence.md``, *Calibration, measured*): it removes
both false alarms of the pooled proof studies (a washout at p 6.9e-4, scale
1.39; a drift at p 1.9e-4 over eight runs, scale 1.36), and on correct-model
runs its scales reproduce the null studies' (washout about 1.3-1.5, platform
0.6).  It is off by default (``n_calibrate=0``): on the single-run proof
study (224 cases, B = 39) it left the controls' false alarms at 0 of 48 and
took 4 of the 67 concealed cases named to ``none`` (every decision it
changed had an asymptotic p within a factor of ten of the level), at about
2 s per replicate and run.  It pays where the asymptotic tails are heavier:
pooled, and for a false alarm that would be costly.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from .._files import number
from .catalogue import Extension

__all__ = ["Calibration", "reference_mean", "calibrate_candidate"]


@dataclass(eq=False)
class Calibration:
    """A candidate's test calibrated by the parametric bootstrap of the base model.

    Attributes
    ----------
    physics : str
        Catalogue name.
    replicates : int
        Replicates whose closed loop and fits succeeded.
    null_mean : float
        Mean -ln L improvement of the extension over the base model on them.
    reference_mean : float
        The asymptotic reference's mean (0.25 or df/2).
    scale : float
        ``null_mean / reference_mean``: c > 1 means the asymptotic test is
        anti-conservative on this recording.
    p_nominal : float
        The asymptotic p-value of the observed statistic.
    p_value : float
        The reference's p-value at ``statistic / max(1, scale)``.
    p_empirical : float
        (1 + #replicates at least as large) / (B + 1): a coarse check that
        cannot go below 1 / (B + 1).
    statistics : ndarray
        The replicates' -ln L improvements.
    """

    physics: str
    replicates: int
    null_mean: float
    reference_mean: float
    scale: float
    p_nominal: float
    p_value: float
    p_empirical: float
    statistics: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of the attributes (``statistics`` as a list)."""
        return {"physics": self.physics, "replicates": self.replicates,
                "null_mean": self.null_mean, "reference_mean": self.reference_mean,
                "scale": self.scale, "p_nominal": self.p_nominal, "p_value": self.p_value,
                "p_empirical": self.p_empirical,
                "statistics": [float(x) for x in self.statistics]}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Calibration":
        """The Calibration a :meth:`to_dict` holds.

        Parameters
        ----------
        d : dict
            A :meth:`to_dict`, as read from JSON (a null number is NaN);
            ``physics`` and ``replicates`` are required.

        Returns
        -------
        Calibration

        Raises
        ------
        KeyError
            If ``physics`` or ``replicates`` is missing.
        """
        return cls(d["physics"], int(d["replicates"]),
                   *(number(d.get(k)) for k in ("null_mean", "reference_mean", "scale",
                                                "p_nominal", "p_value", "p_empirical")),
                   np.array([number(x) for x in d.get("statistics", ())], dtype=float))


def reference_mean(ext: Extension) -> float:
    """Mean of d(-ln L) under the asymptotic reference of :func:`decide.lr_p_value`.

    Parameters
    ----------
    ext : Extension
        The catalogue entry whose test is calibrated (its ``df`` and
        ``boundary_null``).

    Returns
    -------
    float
        0.25 for a one-parameter boundary null (0.5 chi2(0) + 0.5 chi2(1),
        whose mean 0.5 is halved from 2 d(-ln L) to d(-ln L)), else df / 2;
        0 for an entry without new parameters (``control-saturation``).
    """
    if ext.boundary_null and ext.df == 1:
        return 0.25  # 0.5 chi2(0) + 0.5 chi2(1), halved
    return ext.df / 2.0


def _generator(run, recording):
    """(task, K_n, T_n) of the run's parametric bootstrap, or None without a forcing."""
    from . import locate as L

    if run.forcing is None:
        return None
    info = run.boot_info or {}
    if "K_n" in info and "T_n" in info:
        K_n, T_n = info["K_n"], info["T_n"]
    else:
        eps = run.lik0.residual(run.base.params)
        K_n, T_n = L.remnant_like(eps[run.skip:], recording.dt)
    return L.task_of(recording, run.forcing), float(K_n), float(T_n)


def _replicate(run, recording, gen, seed: int, n_starts: int):
    """One replicate of one run: its recording and its base stages, or None if it diverges.

    The base stages are :func:`diagnose`'s: the fast Eq. 4 fit (``n_starts``
    starts), the noise model from *its* residual (and the diagnosis' further
    ``noise_passes``), the GLS base fit.  Taking
    the noise model from the residual at the generating parameters instead
    (the remnant itself) is not the same test: in the closed loop the Eq. 4
    fit absorbs part of the remnant, and the AR model of its residual then
    under-weights the lowest frequencies, where a washout acts (on a pooled
    control of four runs, the same 20 remnants gave the washout a null mean
    of 0.37 retraced this way and 0.26 the other way).
    """
    from ..fit.fast import fit_fast
    from ..likelihood import Likelihood
    from ..simulate import simulate
    from . import _base_gls

    task, K_n, T_n = gen
    try:
        sim = simulate(run.base_model, run.base.params, task=task, remnant_gain=K_n, T_n=T_n,
                       seed=seed)
    except RuntimeError:
        return None
    rec = sim.recording
    fit = fit_fast(rec, run.base_model, seed=seed, n_starts=n_starts, profile_step=0.005,
                   discard=0.0)  # as diagnose's base fit: the run's skip leaves the start out
    start = {k: v for k, v in fit.params.items() if k in run.base_model.parameter_names}
    if not np.all(np.isfinite(Likelihood(run.base_model, rec).residual(start))):
        return None
    lik0, noise, base = _base_gls(rec, run.base_model, start, skip=run.skip,
                                  omega_c=run.noise.omega_c, noise_passes=run.noise_passes)
    return rec, dataclasses.replace(run, base=base, noise=noise, lik0=lik0, base_fit=fit)


def _single_statistic(ext: Extension, rec, run) -> float:
    """The candidate's d(-ln L) on one replicate run, as :func:`diagnose` computes it."""
    from . import decide as D

    ref = run.base
    if ext.refine_threshold:
        ref = D.refine_threshold(run.base_model, rec, run.base, run.noise)
    res, _ = D.fit_candidate(ext, run.base_model, rec, ref, run.noise)
    if res.fit is None:
        return math.nan
    best = min(ref.neg_log_lik, run.base.neg_log_lik)
    got = D.null_refit(ext, run.base_model, rec, res, run.noise)
    if got is not None:
        best = min(best, got.neg_log_lik)
    return max(0.0, best - res.fit.neg_log_lik)


def _pooled_statistic(ext: Extension, recs, runs) -> float:
    """The candidate's pooled d(-ln L) on one replicate set, as :func:`diagnose_pooled` does."""
    from .pooled import _pooled_candidate, _pooled_null, _refined_base

    refined = _refined_base(runs, recs) if ext.refine_threshold else None
    res, extra = _pooled_candidate(ext, runs, recs, refined)
    if extra is None or res.fit is None:
        return math.nan
    ref = float(sum(r.base.neg_log_lik for r in runs))
    best = _pooled_null([ext.name], {ext.name: extra[0]}, runs, recs)
    ref = min(ref, float(sum(b.neg_log_lik for b in best)))
    if refined is not None:
        ref = min(ref, refined[0])
    return max(0.0, ref - res.fit.neg_log_lik)


def calibrate_candidate(ext: Extension, runs: Sequence[Any], recordings: Sequence[Any],
                        statistic: float, *, n_replicates: int = 39,
                        seed: int | np.random.SeedSequence | None = 0, n_starts: int = 4,
                        progress: Callable[[int], None] | None = None) -> Calibration | None:
    """Calibrate the test of ``ext`` on these runs by a parametric bootstrap of the base model.

    Parameters
    ----------
    ext : Extension
        A GLS catalogue entry (not ``control-saturation``, whose flat tops decide).
    runs : sequence
        The diagnosis' per-run first stages (``bayespilot.diagnose._Run``) with
        the base fit the test was made against; one run for :func:`diagnose`,
        all of them for :func:`diagnose_pooled`.
    recordings : sequence of Recording
        The runs' recordings.
    statistic : float
        The observed d(-ln L) of the extension over the base model.
    n_replicates : int
        Bootstrap replicates B (each: one closed-loop simulation per run and
        the candidate's fits).
    seed : int, SeedSequence or None
        Seeds the replicates' remnants (and their base fits' starts).
    n_starts : int
        Starts of each replicate's Eq. 4 fit, as in the diagnosis.
    progress : callable, optional
        Called with 1 after each replicate (a progress bar's ``update``).

    Returns
    -------
    Calibration or None
        None when a run has no forcing to simulate (the asymptotic test stands)
        or no replicate succeeded.

    Raises
    ------
    ValueError
        If ``ext`` is not tested by the GLS likelihood, ``n_replicates`` is not
        a positive integer, or ``runs`` and ``recordings`` are not one each,
        at least one.
    """
    from . import decide as D

    if ext.likelihood != "gls":
        raise ValueError(f"{ext.name} is not tested by the GLS likelihood")
    if not isinstance(n_replicates, (int, np.integer)) or n_replicates < 1:
        raise ValueError(f"n_replicates must be a positive integer, got {n_replicates!r}")
    runs, recordings = list(runs), list(recordings)
    if not runs or len(runs) != len(recordings):
        raise ValueError(f"need one recording per run, at least one: got {len(runs)} runs and "
                         f"{len(recordings)} recordings")
    gens = [_generator(run, rec) for run, rec in zip(runs, recordings)]
    if any(g is None for g in gens):
        return None
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    seeds = ss.generate_state(n_replicates * len(runs)).reshape(n_replicates, len(runs))
    stats = []
    for b in range(n_replicates):
        reps = [_replicate(run, rec, g, int(s), n_starts)
                for run, rec, g, s in zip(runs, recordings, gens, seeds[b])]
        if any(r is None for r in reps):
            stats.append(math.nan)
        else:
            recs_b = [r[0] for r in reps]
            runs_b = [r[1] for r in reps]
            try:
                stats.append(_single_statistic(ext, recs_b[0], runs_b[0]) if len(runs) == 1
                             else _pooled_statistic(ext, recs_b, runs_b))
            except (ValueError, np.linalg.LinAlgError):
                stats.append(math.nan)
        if progress is not None:
            progress(1)
    d = np.asarray(stats, float)
    d = d[np.isfinite(d)]
    if d.size == 0:
        return None
    ref = reference_mean(ext)
    scale = float(d.mean() / ref)
    stat = 2.0 * float(statistic)
    return Calibration(ext.name, int(d.size), float(d.mean()), ref, scale,
                       D.lr_p_value(stat, ext), D.lr_p_value(stat / max(1.0, scale), ext),
                       float((1 + np.sum(d >= statistic)) / (d.size + 1)), d)

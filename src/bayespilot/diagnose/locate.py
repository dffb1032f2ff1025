"""Locate a model mismatch: where a recording and its fitted model differ.

Every piece of evidence is a scalar statistic of the residual eps = u - u_hat
at the fitted parameters, with a significance calibrated by a parametric
bootstrap (:func:`bootstrap`): the fitted model is simulated in closed loop
with a remnant whose level and colour match the fitted residual (Eq. 6 with
K_n and T_n estimated from it, :func:`remnant_like`), each replicate is
refitted as the recording was (``refit``; :func:`bayespilot.diagnose.diagnose`
refits the GLS base fit from the generating parameters, about 0.15 s a
replicate), and the same statistic is computed on the replicate's residual at
its own fit.  Without the refit the replicates' residuals are those at fixed
parameters, larger at the forcing frequencies than a fitted one, and the
p-values conservative.  p = (1 + #{replicates >= observed}) / (B + 1).

Keys of the evidence (see :data:`EVIDENCE`):

frequency
    ``frequency.visual``, ``frequency.motion_low``, ``frequency.motion_high``:
    the two-input multisine describing-function estimate
    (:func:`describing_function`) of the residual, i.e. the difference between
    the nonparametric visual / motion-channel frequency responses from u and
    those of the model (the estimator is linear in u), relative to the model's;
    ``frequency.power_target``, ``frequency.power_disturbance``: residual
    power at the target / disturbance frequencies over the power at the
    neighbouring remnant-only frequencies.
time
    ``time.variance_drift`` (slope of the log residual variance over segments
    of the run), ``time.nonstationarity`` (spread of the segment log
    variances), ``time.gain_drift_visual`` and ``time.gain_drift_motion``
    (slopes of the per-segment least-squares corrections of K_v and K_m).
amplitude
    ``amplitude.canal`` (residual conditioned on the delayed canal output
    |i(t - tau_m)|: the threshold region), ``amplitude.control`` (on |u|: the
    limits), ``amplitude.motion`` (on |theta_ddot_m|), ``amplitude.flat_tops``
    (samples in runs of equal extreme u).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Mapping

import numpy as np
from scipy import integrate, optimize

from .._files import number
from ..forcing import (EXACT_TOLERANCE, SNAP_TOLERANCE, Multisine, columns_whole_periods,
                       whole_periods_frequency)
from ..likelihood import Likelihood
from ..model import PilotModel
from ..recording import Recording

if TYPE_CHECKING:
    from ..simulate import TrackingTask

__all__ = ["Forcing", "forcing_of", "describing_function", "statistics", "remnant_like",
           "task_of", "bootstrap", "Evidence", "EVIDENCE", "N_SEGMENTS", "EvidenceWarning",
           "BaseFitWarning", "SNAP_TOLERANCE"]

#: Evidence keys and what each measures.
EVIDENCE = {
    "frequency.visual": "visual-channel describing function: departure from the model's",
    "frequency.motion_low": "motion-channel describing function below 2 rad/s: departure",
    "frequency.motion_high": "motion-channel describing function at 2 rad/s and above: departure",
    "frequency.power_target": "residual power at the target frequencies / remnant-only neighbours",
    "frequency.power_disturbance": "residual power at the disturbance frequencies / neighbours",
    "time.variance_drift": "trend of the residual's log variance over the run",
    "time.nonstationarity": "spread of the residual's log variance over segments",
    "time.gain_drift_visual": "trend of local K_v corrections over segments",
    "time.gain_drift_motion": "trend of local K_m corrections over segments",
    "amplitude.canal": "residual conditioned on |i(t - tau_m)| (threshold region)",
    "amplitude.control": "residual conditioned on |u| (control limits)",
    "amplitude.motion": "residual variance conditioned on |theta_ddot_m|",
    "amplitude.flat_tops": "samples of u in runs at its extreme values",
}
#: Segments of the run for the time evidence.
N_SEGMENTS = 8
#: Boundary between the low and high frequencies of the motion-channel evidence, rad/s.
OMEGA_SPLIT = 2.0
#: Relative RMS difference between a sidecar's forcing function (evaluated at the recording's
#: ``t``) and its ``f_t`` or ``f_d`` column above which :func:`forcing_of` notes that they
#: disagree: far above a column written at float precision (the package's own simulated
#: recordings differ by about 1e-13) or rounded to a few digits (about 1e-3), below a
#: forcing function of half or twice the amplitude (0.5) or with its phases wrong.
FORCING_MISMATCH = 0.05
#: What to give for the frequency evidence (the end of an EvidenceWarning).
GIVE_FORCING = ("give the forcing (base_frequency, target, disturbance) in the sidecar, or f_t "
                "and f_d columns")


class EvidenceWarning(UserWarning):
    """The located evidence of a diagnosis is incomplete, or was read with an assumption.

    Issued by :func:`bayespilot.diagnose.diagnose` (and
    :func:`~bayespilot.diagnose.diagnose_pooled`), once per gap and
    recording, before the base fit: the bootstrap that gives the evidence its
    p-values was skipped (no forcing functions known, a plant the simulator
    cannot run), part of the frequency evidence is missing (forcing lines
    that are not whole cycles of the record, a forcing function that is zero
    throughout), a sidecar's base frequency was snapped to the record's DFT
    bins (:data:`SNAP_TOLERANCE`), a sidecar's forcing that disagrees with
    the recording's ``f_t``/``f_d`` columns (:data:`FORCING_MISMATCH`), a
    forcing with no line on one side of the motion evidence's split
    (:data:`OMEGA_SPLIT`), or the bootstrap simulates the recording
    format's default plant for a task ``"other"`` that gives none; and, with
    ``n_calibrate``, once more when the calibration is skipped for the same
    reason as the bootstrap.  After the bootstrap, once when fewer of its
    replicates survived than were asked for (their closed loop diverged or
    their refit failed; ``settings["bootstrap"]["dropped"]``): the p-values
    are then coarser, or all missing.  The message says why and, where there
    is one, what to provide.  The diagnosis goes on without what is missing,
    and the result's ``settings["evidence_notes"]`` keeps the messages.
    """


class BaseFitWarning(EvidenceWarning):
    """The base fit a diagnosis starts from has a pilot parameter on a bound of its search box.

    Issued by :func:`bayespilot.diagnose.diagnose` (and
    :func:`~bayespilot.diagnose.diagnose_pooled`, per run) once per recording,
    after the base fit, naming the parameters and their values
    (``settings["base_at_bounds"]``, a pooled run's ``runs[j]["base_at_bounds"]``;
    the message is also kept in ``settings["evidence_notes"]``, a pooled run's
    ``runs[j]["evidence_notes"]``), and by
    :func:`~bayespilot.diagnose.batch.diagnose_batch` once per text for its
    diagnoses.  Not for ``delta_abs = 0`` (the answer
    "no threshold"), nor for a parameter fixed or not identified.  The
    decision is made as ever, but an extension named from such a base fit may
    be making up for a recording problem (a sign or unit convention of u, e
    or theta, an offset) rather than for missing physics.  A subclass of
    :class:`EvidenceWarning`, so that what handles those handles it too.
    """


@dataclass(frozen=True)
class Forcing:
    """The forcing functions of a recording as the estimators need them.

    Attributes
    ----------
    target, disturbance : Multisine
        f_t and f_d at the recording's time axis.
    k_target, k_disturbance : ndarray of int
        Their DFT bins in the record (None if not whole periods).
    f_t, f_d : ndarray
        The signals at the recording's samples.
    notes : tuple of str
        What the estimators should know about them, one sentence each: a
        base frequency snapped to the record's DFT bins, why the lines are
        not bins or not separate (no frequency evidence), a sidecar's forcing
        that disagrees with the ``f_t``/``f_d`` columns, a forcing function
        that is zero throughout (no two-input estimate), a forcing with every
        line on one side of :data:`OMEGA_SPLIT` (no ``frequency.motion_low``
        or ``frequency.motion_high``).  :func:`bayespilot.diagnose.diagnose`
        issues each as an :class:`EvidenceWarning`.
    """

    target: Multisine
    disturbance: Multisine
    k_target: np.ndarray | None
    k_disturbance: np.ndarray | None
    f_t: np.ndarray
    f_d: np.ndarray
    notes: tuple[str, ...] = ()

    @property
    def frequencies(self) -> np.ndarray:
        """All forcing frequencies, rad/s."""
        return np.concatenate([self.target.frequencies, self.disturbance.frequencies])

    @property
    def periodic(self) -> bool:
        """True if every forcing frequency is a DFT bin of the record."""
        return self.k_target is not None and self.k_disturbance is not None

    @property
    def zero(self) -> tuple[str, ...]:
        """The forcing functions that are zero throughout the record ("f_t", "f_d")."""
        return tuple(name for name, x in (("f_t", self.f_t), ("f_d", self.f_d))
                     if not np.any(x))

    @property
    def two_input(self) -> bool:
        """True if the two-input describing-function estimate can be made: every forcing
        frequency a DFT bin of the record and neither forcing function zero throughout."""
        return self.periodic and not self.zero


def _multisine_from_signal(x: np.ndarray, dt: float) -> Multisine:
    """A multisine from a periodic signal: its DFT lines above 1e-3 of the largest."""
    n = x.size
    X = np.fft.rfft(x)
    mag = np.abs(X)
    mag[0] = 0.0
    k = np.flatnonzero(mag > 1e-3 * mag.max()) if mag.max() > 0 else np.array([1])
    w0 = 2 * np.pi / (n * dt)
    amp = 2 * mag[k] / n
    phase = np.angle(X[k]) + np.pi / 2
    return Multisine(w0, k, amp, phase)


def forcing_of(recording: Recording) -> Forcing | None:
    """The recording's forcing functions: from its sidecar (``forcing``) or its f_t/f_d columns.

    Returns None when neither is available.  Only the task description is
    read, never the ``simulation`` key (what generated a simulated run).

    Parameters
    ----------
    recording : Recording
        Its metadata's ``forcing`` (``base_frequency``, rad/s, and the
        ``target`` and ``disturbance`` multisines), else its ``f_t`` and
        ``f_d`` columns, each taken as a multisine of its DFT lines above
        1e-3 of the largest.  From the columns, the bins are kept only when
        both columns wrap smoothly from their end to their start (whole
        periods) and the two sets of lines are disjoint (separate
        frequencies, as the two-input estimate needs): a record cut
        mid-period smears each column over hundreds of lines that the two
        share.

    Returns
    -------
    Forcing or None
        The target and disturbance multisines, their DFT bins in the record
        (each None unless every frequency is a whole number of cycles of the
        record and the target's lines and the disturbance's are separate) and
        the signals at the samples (the columns where the recording has them,
        else the multisines evaluated); None when neither source is
        available.  Its ``notes`` say why the frequencies are not bins, that a
        sidecar's forcing and the columns disagree, that a forcing function
        is zero throughout, or that the motion evidence has no line on one
        side of :data:`OMEGA_SPLIT`.

    Notes
    -----
    Whole periods are decided by the rule of
    :func:`bayespilot.likelihood.whole_periods` (the start-up discard), so
    the two never disagree about a record: from a sidecar,
    :func:`~bayespilot.forcing.whole_periods_frequency`, from the columns,
    :func:`~bayespilot.forcing.columns_whole_periods`.  A sidecar's
    frequencies are bins when one base frequency puts every line of nonzero
    amplitude on whole cycles of the record: the sidecar's own when it puts
    them within 1e-3 cycle; one that puts every line within
    :data:`SNAP_TOLERANCE` (0.05) cycle of whole cycles, as a rounded value
    does (the paper prints 0.0767 rad/s for 2 pi / 81.92 s), is taken as the
    nearest one that puts them on bins, and a note says so: a line 0.05 cycle
    off its bin keeps 99.6 % of its amplitude there.  A line of zero
    amplitude is not in the signal: it does not decide, and is left out of
    the multisine when it is not on a bin.

    A sidecar's forcing is read as the task's, as before, but when the
    recording also has ``f_t`` or ``f_d`` columns each is compared with the
    sidecar's multisine evaluated at ``t`` (at the snapped base frequency,
    if snapped): a relative RMS difference (over the larger of the two RMS
    values) above :data:`FORCING_MISMATCH` is noted, naming the column and
    the difference.  A sidecar whose target and disturbance share a line of
    the record (both with nonzero amplitude) gives no bins, as columns that
    share one do: the two-input estimate at a shared line would divide by
    one forcing function while both excite the loop there.
    """
    meta = recording.metadata.get("forcing")
    t = recording.t
    if isinstance(meta, Mapping):
        w0 = float(meta["base_frequency"])
        ft = Multisine.from_dict(w0, meta["target"])
        fd = Multisine.from_dict(w0, meta["disturbance"])
    elif "f_t" in recording and "f_d" in recording:
        ft = _multisine_from_signal(recording["f_t"], recording.dt)
        fd = _multisine_from_signal(recording["f_d"], recording.dt)
    else:
        return None
    T = recording.n_samples * recording.dt
    notes = []
    if isinstance(meta, Mapping):
        ft, fd, kk, note = _on_bins(ft, fd, T)
        if note:
            notes.append(note)
        note = _sidecar_against_columns(recording, ft, fd)
        if note:
            notes.append(note)
        if kk[0] is not None:
            shared = np.intersect1d(kk[0][ft.amplitude != 0], kk[1][fd.amplitude != 0])
            if shared.size:
                kk = [None, None]
                lines = ", ".join(f"{k * 2 * np.pi / T:.4g}" for k in shared)
                notes.append(f"the frequency evidence (frequency.*) is missing: the sidecar's "
                             f"forcing target and disturbance share {shared.size} DFT line(s) "
                             f"of the {T:g}-s record (at {lines} rad/s), and the describing "
                             f"functions need forcing functions at separate frequencies; give "
                             f"each line to one forcing function (or check the forcing's n "
                             f"against the experiment's)")
    else:
        # lines read from the columns are DFT bins by construction, so whether the record is
        # whole periods is read from the columns themselves (the rule of whole_periods); the
        # two-input estimate needs more: separate frequencies (a line of zero amplitude, the
        # placeholder of a column zero throughout, is no frequency of the signal)
        whole = columns_whole_periods([recording["f_t"], recording["f_d"]])
        shared = np.intersect1d(ft.n[ft.amplitude != 0], fd.n[fd.amplitude != 0]).size
        kk = [ft.n.copy(), fd.n.copy()]
        if whole is None:
            kk = [None, None]
            notes.append("the frequency evidence (frequency.*) is missing: the f_t and f_d "
                         "columns are zero throughout the record")
        elif not whole or shared:
            kk = [None, None]
            why = ("do not continue smoothly from the record's end to its start (not whole "
                   "periods)" if not whole else f"share {shared} DFT line(s)")
            notes.append(f"the frequency evidence (frequency.*) is missing: the f_t and f_d "
                         f"columns {why}, and the describing functions need whole periods of "
                         f"forcing functions at separate frequencies; give the forcing "
                         f"in the sidecar, or cut the record to whole periods")
    f_t = np.asarray(recording["f_t"] if "f_t" in recording else ft(t))
    f_d = np.asarray(recording["f_d"] if "f_d" in recording else fd(t))
    out = Forcing(ft, fd, kk[0], kk[1], f_t, f_d)
    if out.periodic and out.zero:
        which = " and ".join({"f_t": "the target f_t", "f_d": "the disturbance f_d"}[z]
                             for z in out.zero)
        only = {("f_d",): " (target only)", ("f_t",): " (disturbance only)"}.get(out.zero, "")
        power = " and ".join(f"frequency.power_{'target' if z == 'f_t' else 'disturbance'}"
                             for z in out.zero)
        notes.append(f"{which} {'is' if len(out.zero) == 1 else 'are'} zero throughout the "
                     f"record{only}: the two-input describing-function estimate needs both "
                     f"forcing functions, so frequency.visual, frequency.motion_low and "
                     f"frequency.motion_high are missing, and {power} (no forced lines)")
    if out.two_input:
        note = _split_note(out)
        if note:
            notes.append(note)
    return dataclasses.replace(out, notes=tuple(notes)) if notes else out


def _sidecar_against_columns(recording: Recording, ft: Multisine, fd: Multisine) -> str | None:
    """The note when a sidecar's forcing (``ft``, ``fd``, as read) and the recording's
    ``f_t``/``f_d`` columns disagree (relative RMS difference above :data:`FORCING_MISMATCH`,
    over the larger of the two RMS values), or None (they agree, or there is no column)."""
    said = []
    for col, f, name in (("f_t", ft, "target"), ("f_d", fd, "disturbance")):
        if col not in recording:
            continue
        x, c = f(recording.t), np.asarray(recording[col], float)
        scale = max(float(np.sqrt(np.mean(x ** 2))), float(np.sqrt(np.mean(c ** 2))))
        diff = float(np.sqrt(np.mean((x - c) ** 2))) / scale if scale > 0 else 0.0
        if diff > FORCING_MISMATCH:
            ratio = (float(np.sqrt(np.mean(x ** 2)) / np.sqrt(np.mean(c ** 2)))
                     if np.any(c) else math.inf)
            said.append(f"the {name} differs from the {col} column by {100 * diff:.3g} % "
                        f"RMS (its RMS {ratio:.3g} times the column's)")
    if not said:
        return None
    return (f"the sidecar's forcing does not match the recording's columns: "
            f"{' and '.join(said)}, evaluated at t (more than {100 * FORCING_MISMATCH:g} %); "
            f"the diagnosis reads the sidecar's (its lines for the frequency evidence, the "
            f"bootstrap's forcing), so check the forcing's base_frequency, amplitudes and phases "
            f"(and the columns' units) against the experiment's")


def _split_note(forcing: Forcing) -> str | None:
    """The note when every forcing line (of nonzero amplitude) lies on one side of
    :data:`OMEGA_SPLIT`, so that ``frequency.motion_low`` or ``frequency.motion_high`` has no
    line and is missing; None otherwise."""
    w = np.concatenate([f.frequencies[f.amplitude != 0]
                        for f in (forcing.target, forcing.disturbance)])
    if w.size == 0:
        return None
    low = w < OMEGA_SPLIT
    if np.all(low):
        gone, where, kept = "frequency.motion_high", f"below {OMEGA_SPLIT:g} rad/s", "low"
    elif not np.any(low):
        gone, where, kept = "frequency.motion_low", f"at or above {OMEGA_SPLIT:g} rad/s", "high"
    else:
        return None
    return (f"{gone} is missing: every forcing line is {where} ({w.min():.3g} to {w.max():.3g} "
            f"rad/s), and the motion-channel evidence is split at a fixed {OMEGA_SPLIT:g} rad/s "
            f"(OMEGA_SPLIT); frequency.motion_{kept} covers the motion channel at every line")


def _on_bins(ft: Multisine, fd: Multisine, T: float
             ) -> tuple[Multisine, Multisine, list, str | None]:
    """A sidecar's forcing on the DFT bins of a record of ``T`` s, by the one rule of whole
    periods (:func:`~bayespilot.forcing.whole_periods_frequency`): ``(ft, fd, kk, note)``.

    Whole periods: ``kk`` the bins of the lines, at the base frequency snapped to them when
    it is not exact (the note says so; None otherwise); a line of zero amplitude that is
    not on a bin there is left out (it is not in the signal, and has no bin).  Not whole
    periods: ``kk`` None and the note says why."""
    w0 = ft.base_frequency
    n = np.concatenate([ft.n, fd.n])
    a = np.concatenate([ft.amplitude, fd.amplitude])
    counted = a != 0 if np.any(a != 0) else np.ones(a.size, bool)  # (the rule's lines)
    ws = whole_periods_frequency(w0, n, a, T)
    if ws is not None:
        out, kk = [], []
        for f in (ft, fd):
            k = f.n * (ws * T / (2 * np.pi))
            keep = (f.amplitude != 0) | (np.abs(k - np.rint(k)) <= EXACT_TOLERANCE)
            if ws != w0 or not np.all(keep):
                f = Multisine(ws, f.n[keep], f.amplitude[keep], f.phase[keep])
            out.append(f)
            kk.append(np.rint(k[keep]).astype(int))
        note = None
        if ws != w0:
            off = float(np.max(n[counted] * abs(w0 - ws) * T / (2 * np.pi)))
            note = (f"forcing.base_frequency {w0:.6g} rad/s puts the forcing lines up to "
                    f"{off:.2g} cycle off whole cycles of the {T:g}-s record (a rounded "
                    f"value?); taken as {ws:.8g} rad/s, the nearest that puts them on the "
                    f"record's DFT bins")
        return out[0], out[1], kk, note
    m = w0 * T / (2 * np.pi)  # base periods in the record
    g = int(np.gcd.reduce(n[counted]))
    period = 2 * np.pi / (g * w0)  # of the forcing functions' sum
    cure = ("give the exact base_frequency, or cut the record to whole periods"
            if T >= period else f"the record is shorter than one period of the forcing "
                                f"({period:.4g} s)")
    k = n * m
    dist = np.where(counted, np.abs(k - np.rint(k)), -1.0)
    i = int(np.argmax(dist))
    if dist[i] > SNAP_TOLERANCE:
        name = "target" if i < ft.n.size else "disturbance"
        why = (f"the {name} line n = {n[i]} ({n[i] * w0:.4g} rad/s) is {dist[i]:.2g} cycle off "
               f"a whole number of cycles of the {T:g}-s record")
    else:  # each line near whole cycles, but at no one base frequency
        why = (f"the {T:g}-s record is {T / period:.4g} periods ({period:.4g} s) of the "
               f"forcing functions, not a whole number (no one base frequency puts every "
               f"line within {SNAP_TOLERANCE:g} cycle of whole cycles)")
    note = (f"the frequency evidence (frequency.*) is missing: {why} (forcing.base_frequency "
            f"{w0:.6g} rad/s), and the describing functions need whole periods; {cure}")
    return ft, fd, [None, None], note


def describing_function(u: np.ndarray, e: np.ndarray, m: np.ndarray, forcing: Forcing
                        ) -> dict[str, np.ndarray]:
    """Two-input multisine estimate of the visual and motion-channel frequency responses.

    The pilot's control is u = H_v e + H_m m (+ remnant), m = theta_ddot_m.
    The target excites the loop at its frequencies and the disturbance at
    others, so at each forcing frequency there is one equation per forcing
    function: at a disturbance frequency
    U/F_d = H_v E/F_d + H_m M/F_d from the data there, and the same with the
    closed-loop ratios U/F_t, E/F_t, M/F_t interpolated from the neighbouring
    target frequencies (the ratios are smooth in frequency; the signals'
    spectra are not).  Two equations, two unknowns (van Paassen & Mulder
    1998; Zaal et al. 2009).  Interpolation is linear in log frequency on the
    real and imaginary parts, constant beyond the ends (``numpy.interp``).

    Parameters
    ----------
    u, e, m : ndarray
        Control (or any signal the estimator should explain, e.g. a residual),
        error and motion, over whole periods of the forcing.
    forcing : Forcing
        With DFT bins and neither forcing function zero (``forcing.two_input``).

    Returns
    -------
    dict with ``omega`` (rad/s, sorted), ``H_v``, ``H_m`` (complex),
    ``at`` ("t" or "d": which forcing function's frequency).

    Raises
    ------
    ValueError
        If the record does not hold whole periods of the forcing functions, or
        one of them is zero throughout.
    """
    if not forcing.periodic:
        raise ValueError("the describing-function estimate needs whole periods of the forcing "
                         "functions in the record")
    if forcing.zero:
        raise ValueError(f"the two-input describing-function estimate needs both forcing "
                         f"functions; {' and '.join(forcing.zero)} "
                         f"{'is' if len(forcing.zero) == 1 else 'are'} zero throughout the record")
    U, E, M = (np.fft.rfft(np.asarray(x, float)) for x in (u, e, m))
    Ft, Fd = np.fft.rfft(forcing.f_t), np.fft.rfft(forcing.f_d)
    kt, kd = forcing.k_target, forcing.k_disturbance
    wt, wd = forcing.target.frequencies, forcing.disturbance.frequencies
    # a line a sidecar lists with zero amplitude is not in the signal: no input to divide by
    # (the ratios there would be noise over ~0), so it gives no equation
    live_t, live_d = forcing.target.amplitude != 0, forcing.disturbance.amplitude != 0
    kt, wt, kd, wd = kt[live_t], wt[live_t], kd[live_d], wd[live_d]

    def ratios(k, F):
        return U[k] / F[k], E[k] / F[k], M[k] / F[k]

    def interp(w_to, w_from, z):
        lw, lf = np.log(w_to), np.log(w_from)
        order = np.argsort(lf)
        return (np.interp(lw, lf[order], z.real[order]) + 1j * np.interp(lw, lf[order], z.imag[order]))

    rt = ratios(kt, Ft)
    rd = ratios(kd, Fd)
    out_w, out_v, out_m, at = [], [], [], []
    for w_here, r_here, w_other, r_other, tag in ((wd, rd, wt, rt, "d"), (wt, rt, wd, rd, "t")):
        ro = [interp(w_here, w_other, z) for z in r_other]
        for j in range(w_here.size):
            A = np.array([[r_here[1][j], r_here[2][j]], [ro[1][j], ro[2][j]]])
            b = np.array([r_here[0][j], ro[0][j]])
            try:
                hv, hm = np.linalg.solve(A, b)
            except np.linalg.LinAlgError:
                hv, hm = np.nan + 0j, np.nan + 0j
            out_w.append(w_here[j])
            out_v.append(hv)
            out_m.append(hm)
            at.append(tag)
    order = np.argsort(out_w)
    return {"omega": np.asarray(out_w)[order], "H_v": np.asarray(out_v)[order],
            "H_m": np.asarray(out_m)[order], "at": np.asarray(at)[order]}


def steady_response(model: PilotModel, recording: Recording, params: Mapping[str, float]
                    ) -> np.ndarray:
    """The model's u_hat in periodic steady state: computed over the record tiled twice.

    The likelihood warms its recursions up over the last 5 s only, so a slow
    stage (a washout) starts with a transient; for the describing functions
    (whole periods, no samples left out) the second of two tiled periods is
    used instead.
    """
    n = recording.n_samples
    sig = {k: np.tile(v, 2) for k, v in recording.signals.items()}
    sig["t"] = np.arange(2 * n) * recording.dt
    rec2 = Recording(sig, recording.sample_rate_hz, recording.motion_gain, recording.task,
                     recording.metadata, recording.source)
    return Likelihood(model, rec2).response(params)[n:]


# --- the statistics ------------------------------------------------------------------------
def _slope(y: np.ndarray) -> float:
    x = np.linspace(-0.5, 0.5, y.size)
    return float(np.polyfit(x, y, 1)[0]) if y.size > 1 else 0.0


def _binned(eps: np.ndarray, x: np.ndarray, edges_q=(0.0, 0.5, 0.8, 0.95, 0.99, 1.0),
            sign: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Residual mean (times sign) and variance in quantile bins of |x|."""
    ax = np.abs(x)
    edges = np.quantile(ax, edges_q)
    edges[-1] = np.inf
    idx = np.clip(np.searchsorted(edges, ax, side="right") - 1, 0, len(edges_q) - 2)
    s = np.sign(x) if sign is None else sign
    nb = len(edges_q) - 1
    mean = np.zeros(nb)
    var = np.zeros(nb)
    cnt = np.zeros(nb)
    for b in range(nb):
        sel = idx == b
        cnt[b] = sel.sum()
        if cnt[b]:
            mean[b] = float(np.mean(eps[sel] * s[sel]))
            var[b] = float(np.var(eps[sel]))
    centre = np.array([np.median(ax[idx == b]) if cnt[b] else np.nan for b in range(nb)])
    return {"centre": centre, "mean": mean, "var": var, "count": cnt}


def statistics(recording: Recording, model: PilotModel, params: Mapping[str, float],
               forcing: Forcing | None, *, skip: int = 0, u: np.ndarray | None = None,
               with_arrays: bool = False) -> dict[str, Any]:
    """Every located statistic of a recording at the fitted ``params`` (see module docs).

    Parameters
    ----------
    recording : Recording
    model : PilotModel
        The base model (the paper's two channels, ``visual`` and ``vestibular``).
    params : mapping
        Fitted parameters.
    forcing : Forcing or None
        Frequency evidence is left out without it (or without whole periods);
        the visual and motion describing-function evidence also when one
        forcing function is zero throughout (``forcing.two_input``).
    skip : int
        Samples at the start left out of the time and amplitude evidence (the
        likelihood's start-up transient).
    u : ndarray, optional
        Use this control instead of the recording's (for quantised replicates).
    with_arrays : bool
        Also return the arrays behind the statistics (for plots).

    Returns
    -------
    dict
        ``values`` (key -> float; NaN where not available) and, with
        ``with_arrays``, ``arrays``.
    """
    lik = Likelihood(model, recording)
    uu = lik.u if u is None else np.asarray(u, float)
    y = lik.response(params)
    eps = uu - y
    names = [c.name for c in model.channels]
    p = dict(params)
    # per-channel contributions (the model is linear in the channel gains)
    contrib = {}
    for c in model.channels:
        if not c.gain:
            continue
        others = {c2.gain[0]: 0.0 for c2 in model.channels if c2 is not c and c2.gain
                  and c2.gain[0] != c.gain[0]}
        contrib[c.name] = lik.response(dict(p, **others))
    values: dict[str, float] = {k: math.nan for k in EVIDENCE}
    arrays: dict[str, Any] = {}
    n = eps.size
    # -- frequency
    if forcing is not None and forcing.periodic:
        if forcing.two_input:  # (a forcing function zero throughout: no two-input estimate)
            y_ss = steady_response(model, recording, params)
            df_res = describing_function(uu - y_ss, recording.e, recording.theta_ddot_m, forcing)
            df_mod = describing_function(y_ss, recording.e, recording.theta_ddot_m, forcing)
            w = df_res["omega"]
            low = w < OMEGA_SPLIT

            def rel(dh, hm, sel):
                if not np.any(sel):  # (no line on this side of OMEGA_SPLIT: forcing_of's note)
                    return math.nan
                den = float(np.mean(np.abs(hm[sel]) ** 2))
                return float(np.mean(np.abs(dh[sel]) ** 2) / den) if den > 0 else math.nan

            values["frequency.visual"] = rel(df_res["H_v"], df_mod["H_v"], np.ones(w.size, bool))
            values["frequency.motion_low"] = rel(df_res["H_m"], df_mod["H_m"], low)
            values["frequency.motion_high"] = rel(df_res["H_m"], df_mod["H_m"], ~low)
        P = np.abs(np.fft.rfft(eps)) ** 2
        # the lines in the signal: one listed with zero amplitude (a zero forcing function's
        # placeholder), or of a forcing function zero throughout the record, is not forced;
        # a forcing function without any gives NaN
        kt, kd = (np.asarray(k)[(f.amplitude != 0) & (col not in forcing.zero)]
                  for k, f, col in ((forcing.k_target, forcing.target, "f_t"),
                                    (forcing.k_disturbance, forcing.disturbance, "f_d")))
        forced = np.zeros(P.size, bool)
        forced[kt] = True
        forced[kd] = True
        forced[0] = True

        def power_ratio(ks):
            num, den = 0.0, 0.0
            for k in ks:
                nb = [j for j in range(k - 4, k + 5) if 0 < j < P.size and not forced[j]]
                num += P[k]
                den += float(np.mean(P[nb])) if nb else 0.0
            return num / den if den > 0 else math.nan

        values["frequency.power_target"] = power_ratio(kt)
        values["frequency.power_disturbance"] = power_ratio(kd)
        if with_arrays and forcing.two_input:
            arrays["df_residual"] = df_res
            arrays["df_model"] = df_mod
            arrays["df_data"] = describing_function(uu, recording.e, recording.theta_ddot_m,
                                                    forcing)
    # -- time
    seg = np.array_split(np.arange(skip, n), N_SEGMENTS)
    logv = np.array([math.log(max(float(np.var(eps[s])), 1e-300)) for s in seg])
    values["time.variance_drift"] = abs(_slope(logv))
    values["time.nonstationarity"] = float(np.std(logv))
    corr = {}
    for key, ch in (("visual", "visual"), ("motion", "vestibular")):
        if ch not in contrib:
            continue
        cs = []
        for s in seg:
            X = np.column_stack([contrib[c][s] for c in contrib])
            coef, *_ = np.linalg.lstsq(X, eps[s], rcond=None)
            cs.append(coef[list(contrib).index(ch)])
        corr[key] = np.asarray(cs)
        values[f"time.gain_drift_{key}"] = abs(_slope(corr[key]))
    # -- amplitude
    sl = slice(skip, n)
    e_s = eps[sl]
    if "vestibular" in names:
        X = lik.X[names.index("vestibular")]
        shift = int(round(p.get("tau_m", 0.0) / recording.dt))
        i_d = np.roll(X, shift)[sl]
        b = _binned(e_s, i_d, edges_q=(0.0, 0.2, 0.4, 0.6, 0.8, 0.9, 1.0))
        values["amplitude.canal"] = float(np.sum(b["count"] * b["mean"] ** 2) / np.var(e_s))
        arrays["amp_canal"] = b
        arrays["canal_delayed"] = i_d
    b = _binned(e_s, uu[sl])
    values["amplitude.control"] = float(np.sum(b["count"] * b["mean"] ** 2) / np.var(e_s))
    arrays["amp_control"] = b
    arrays["u_after_cond"] = uu[sl]
    b = _binned(e_s, recording.theta_ddot_m[sl])
    rv = b["var"] / np.var(e_s)
    values["amplitude.motion"] = float(np.sum(np.log(np.maximum(rv, 1e-12)) ** 2))
    arrays["amp_motion"] = b
    from .decide import flat_tops

    values["amplitude.flat_tops"] = float(flat_tops(uu)["n_samples"])
    out: dict[str, Any] = {"values": values}
    if with_arrays:
        arrays["segments_logvar"] = logv
        arrays["segments_gain"] = corr
        arrays["residual"] = eps
        arrays["u_hat"] = y
        out["arrays"] = arrays
    return out


# --- the bootstrap -------------------------------------------------------------------------
def _remnant_acf(T: float, lags: np.ndarray, dt: float) -> np.ndarray:
    """Normalised autocorrelation of K / (T s + 1)^4 white noise at ``lags`` samples."""
    # R(tau) = int_0^inf cos(w tau) / (1 + w^2 T^2)^4 dw, numerically (scipy.integrate)
    w = np.linspace(0.0, 60.0 / T, 6001)
    S = 1.0 / (1.0 + (w * T) ** 2) ** 4
    R = integrate.simpson(np.cos(np.outer(lags * dt, w)) * S, x=w, axis=1)
    R0 = integrate.simpson(S, x=w)
    return R / R0


def remnant_like(eps: np.ndarray, dt: float) -> tuple[float, float]:
    """(K_n, T_n) of an Eq. 6 remnant with the level and colour of a residual.

    T_n matches the residual's autocorrelation over the first 0.6 s of lags
    (bounded scalar minimisation); K_n then matches its variance, using
    var(n) = K_n^2 psd 5 / (32 T_n) for white noise of two-sided PSD
    psd = :data:`~bayespilot.simulate.NOISE_PSD` (the simulator's default, at
    every sample rate) through 1 / (T_n s + 1)^4.

    Parameters
    ----------
    eps : ndarray
        The residual (1-D; its mean is removed here), rad.
    dt : float
        Sample interval, s.

    Returns
    -------
    K_n : float
        The remnant's gain, in the units of ``eps``.
    T_n : float
        Its filter's time constant, s, in [0.005, 0.5].
    """
    x = np.asarray(eps, float) - np.mean(eps)
    n = x.size
    L = max(2, int(round(0.6 / dt)))
    lags = np.arange(1, L + 1)
    c0 = float(x @ x) / n
    acf = np.array([x[: n - k] @ x[k:] / n for k in lags]) / c0
    res = optimize.minimize_scalar(lambda T: float(np.sum((_remnant_acf(T, lags, dt) - acf) ** 2)),
                                   bounds=(0.005, 0.5), method="bounded", options={"xatol": 1e-4})
    T_n = float(res.x)
    from ..simulate import NOISE_PSD

    K_n = math.sqrt(c0 / (NOISE_PSD * 5.0 / (32.0 * T_n)))
    return K_n, T_n


def task_of(recording: Recording, forcing: Forcing) -> TrackingTask:
    """The :class:`~bayespilot.simulate.TrackingTask` a recording describes (for replicates).

    Parameters
    ----------
    recording : Recording
        Its task name, controlled element, K_theta, control gain, sample rate
        and duration are the task's.
    forcing : Forcing
        Its forcing functions (:func:`forcing_of`).

    Returns
    -------
    TrackingTask
        The task with a run-in of half the recording's duration, the
        forcing's phases moved back by the run-in so that the simulated
        record after it lines up with the recording's time axis.
    """
    from ..simulate import TrackingTask

    run_in = 0.5 * recording.duration

    def back(f: Multisine) -> Multisine:  # g(t_sim) = f(t_sim - run_in)
        return Multisine(f.base_frequency, f.n, f.amplitude,
                         np.mod(f.phase - f.frequencies * run_in, 2 * np.pi))

    num, den = recording.controlled_element
    return TrackingTask(back(forcing.target), back(forcing.disturbance),
                        motion_gain=recording.motion_gain,
                        controlled_element=(tuple(num), tuple(den)),
                        control_gain=recording.control_gain,
                        sample_rate_hz=recording.sample_rate_hz, duration=recording.duration,
                        run_in=run_in, task=recording.task)


#: Most levels a quantised u spans (a 24-bit converter's); a finer "step" is full precision.
_MAX_LEVELS = 2.0**24
#: A sample is on the grid within this fraction of a step.
_GRID_TOL = 1e-3
#: Least fraction of the samples on the grid for u to count as quantised (a few padded or
#: glitched samples off it do not make a quantised u full precision).
_GRID_SHARE = 0.99


def _on_grid(v: np.ndarray, w: np.ndarray, q: float) -> tuple[float, np.ndarray] | None:
    """The grid of step ``q`` through most of the distinct values ``v`` (seen ``w`` times):
    ``(anchor, on)``: the grid's phase the weighted median of the values' in their densest
    phase bin, ``on`` the values within :data:`_GRID_TOL` steps of it, ``anchor`` the most
    frequent of those; None if fewer than :data:`_GRID_SHARE` of the samples are on it, or of the samples
    other than those of the most frequent value (a u at rest at one value 99 % of the time
    is on any grid through it).

    (The phase is not the most frequent value's: on a sparsely used grid, ten padded zeros
    just off it can be seen more often than any level of it.)
    """
    nb = int(0.5 / _GRID_TOL)  # phase bins two tolerances wide
    ph = np.mod((v - v[0]) / q, 1.0)
    h = np.bincount(np.minimum((ph * nb).astype(np.int64), nb - 1), weights=w, minlength=nb)
    c = (int(np.argmax(h + np.roll(h, 1) + np.roll(h, -1))) + 0.5) / nb  # (a split cluster)
    rel = np.mod(ph - c + 0.5, 1.0) - 0.5
    near = np.abs(rel) <= 1.5 / nb
    o = np.argsort(rel[near])
    cum = np.cumsum(w[near][o])
    phi = c + float(rel[near][o][np.searchsorted(cum, 0.5 * cum[-1])])
    on = np.abs(np.mod(ph - phi + 0.5, 1.0) - 0.5) < _GRID_TOL
    n, n_on, top = float(w.sum()), float(w[on].sum()), int(np.argmax(w))
    if n_on < _GRID_SHARE * n or \
            n_on - on[top] * float(w[top]) < _GRID_SHARE * (n - float(w[top])):
        return None
    return float(v[on][np.argmax(w[on])]), on


def _grid(u: np.ndarray) -> tuple[float, float]:
    """The recording's quantisation grid of u: ``(step, offset)``, the values being
    ``offset + k * step``; ``(0.0, 0.0)`` if u is recorded at full precision.

    The step is the commonest difference between adjacent distinct values (each counted by
    how often the rarer of the two is seen, so that a few off-grid values do not outvote the
    grid), or a whole fraction of it where a sparsely used grid skips levels; u is quantised
    when at least 99 % of its samples lie on a grid of that step (within 1e-3 of a step).  So
    the grid counts whether or not it passes through 0 (an ADC's u after ``u - mean(u)``, or
    with a trim), and a few samples off it (zero padding on an offset grid, a glitch) do not
    make u full precision.  A continuous u, clipped or not, has no difference that repeats,
    or far fewer than 99 % of its samples on the grid of one that does.
    """
    x = np.asarray(u, dtype=float).ravel()
    if x.size < 3 or not np.all(np.isfinite(x)):
        return 0.0, 0.0
    v, w = np.unique(x, return_counts=True)
    if v.size < 3:
        return 0.0, 0.0
    dv = np.diff(v)
    o = np.argsort(dv)
    d, wd = dv[o], np.minimum(w[:-1], w[1:])[o]
    idx = np.arange(d.size)
    end = np.searchsorted(d, d * (1.0 + _GRID_TOL), side="right")  # equal within tolerance
    if int(np.max(end - idx)) < 2:
        return 0.0, 0.0  # no difference repeats
    cw = np.concatenate([[0], np.cumsum(wd)])
    i = int(np.argmax(cw[end] - cw[idx]))
    j = int(np.flatnonzero(end - idx >= 2)[0])
    # the commonest difference, or a whole fraction of it (a sparse grid's commonest may
    # span some steps); last, the smallest that repeats (a grid too sparse for either)
    steps = [float(np.median(d[i:end[i]])) / k for k in range(1, 17)]
    for q in steps + [float(np.median(d[j:end[j]]))]:
        r = dv / q
        m = np.rint(r)
        fit = (np.abs(r - m) < _GRID_TOL) & (m >= 1)
        if not np.any(fit):
            continue
        q = float(dv[fit].sum() / m[fit].sum())  # from all its differences (less rounding)
        grid = _on_grid(v, w, q)
        if grid is None:
            continue
        anchor, on = grid
        lo, hi = float(v[on][0]), float(v[on][-1])
        if (hi - lo) / q > _MAX_LEVELS:
            return 0.0, 0.0
        if hi > lo:  # the step from the span of the values on the grid
            q = (hi - lo) / float(np.rint((hi - lo) / q))
        offset = float(anchor - q * np.rint(anchor / q))  # in [-q/2, q/2]
        return q, offset
    return 0.0, 0.0


def _quantum(u: np.ndarray) -> float:
    """The recording's quantisation step of u (0 if it is recorded at full precision);
    shift-invariant (:func:`_grid`)."""
    return _grid(u)[0]


def bootstrap(recording: Recording, model: PilotModel, params: Mapping[str, float],
              forcing: Forcing, eps: np.ndarray, *, n_replicates: int = 39, seed: int | None = 0,
              skip: int = 0,
              refit: Callable[[Recording], Mapping[str, float]] | None = None,
              progress: Callable[[int], Any] | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Null distribution of every statistic from the fitted model with its own remnant.

    Parameters
    ----------
    recording, model, params
        The recording and the model at its fit (the generator of the replicates).
    forcing : Forcing
        The recording's forcing functions (:func:`forcing_of`).
    eps : ndarray
        The fitted residual, whose level and colour the replicates' remnant takes.
    n_replicates : int
        Replicates B.
    seed : int or None
        Seeds the replicates' remnants.
    skip : int
        Samples left out at the start.
    refit : callable, optional
        ``refit(replicate) -> params``: fits the model to a replicate as the
        recording was fitted; each replicate's statistics are then at its own
        fit.  None: at ``params`` (conservative, see the module notes).
    progress : callable, optional
        Called with 1 after each replicate (a progress bar's ``update``).

    Returns
    -------
    (dict, dict)
        Key -> array of the replicate values; the remnant settings
        (``K_n``, ``T_n``, ``quantum``, ``replicates``, ``refitted``, and
        ``dropped`` and ``diverged``: replicates left out, and of those, the
        ones whose closed loop diverged).  Replicates whose closed loop
        diverges, or whose refit fails, are dropped (the caller says so).
    """
    from ..simulate import simulate

    K_n, T_n = remnant_like(eps[skip:], recording.dt)
    task = task_of(recording, forcing)
    q, q_offset = _grid(recording.u)
    seeds = np.random.SeedSequence(seed).generate_state(max(n_replicates, 1))
    out: dict[str, list[float]] = {k: [] for k in EVIDENCE}
    diverged = 0
    for b in range(n_replicates):
        if progress is not None and b > 0:
            progress(1)  # (the replicate before, kept or dropped)
        try:
            sim = simulate(model, params, task=task, remnant_gain=K_n, T_n=T_n,
                           seed=int(seeds[b]))
        except RuntimeError:
            diverged += 1
            continue
        rep = sim.recording
        # quantised on the recording's grid (its offset too: the flat-top count is
        # shift-invariant, the replicate's rounding then is the recording's); the few
        # recorded samples _grid allows off it (padding, a glitch) are not copied: inside
        # u's range they are in no run at an extreme, and a lone glitch beyond it only
        # takes that side's runs from the recording's count (conservative)
        u = np.round((rep.u - q_offset) / q) * q + q_offset if q > 0 else None
        at = params
        if refit is not None:
            # (fitted to the unquantised replicate: a quantum of the recording's size moves
            # the fit far less than the remnant does)
            try:
                at = refit(rep)
            except (ValueError, np.linalg.LinAlgError):
                continue
        vals = statistics(rep, model, at, forcing, skip=skip, u=u)["values"]
        for k, v in vals.items():
            out[k].append(v)
    if progress is not None and n_replicates > 0:
        progress(1)
    kept = len(out["time.nonstationarity"])
    return ({k: np.asarray(v, float) for k, v in out.items()},
            {"K_n": K_n, "T_n": T_n, "quantum": q, "replicates": kept,
             "refitted": refit is not None, "dropped": n_replicates - kept,
             "diverged": diverged})


@dataclass
class Evidence:
    """One located statistic with its bootstrap calibration.

    Attributes
    ----------
    key : str
        The statistic's name (a key of :data:`EVIDENCE`).
    value : float
        Its value on the recording (NaN if it could not be computed).
    null_mean, null_sd : float
        Mean and standard deviation of its bootstrap replicates under the
        fitted base model; NaN without replicates (the sd also with one).
    p_value : float
        One-sided bootstrap p-value, (1 + #{replicates >= value}) /
        (replicates + 1); NaN without replicates.
    description : str
        What the statistic measures, one sentence.
    replicates : int, default 0
        Finite bootstrap replicates used.
    """

    key: str
    value: float
    null_mean: float = math.nan
    null_sd: float = math.nan
    p_value: float = math.nan
    description: str = ""
    replicates: int = 0

    @property
    def z(self) -> float:
        """(value - null_mean) / null_sd, in null standard deviations; NaN without a spread."""
        if not (self.null_sd > 0):
            return math.nan
        return (self.value - self.null_mean) / self.null_sd

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of the attributes and :attr:`z` (a non-finite number as None)."""
        def num(x):
            return float(x) if math.isfinite(x) else None
        return {"key": self.key, "value": num(self.value), "null_mean": num(self.null_mean),
                "null_sd": num(self.null_sd), "z": num(self.z), "p_value": num(self.p_value),
                "replicates": self.replicates, "description": self.description}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Evidence":
        """The Evidence a :meth:`to_dict` holds (``z`` is computed, not read).

        Parameters
        ----------
        d : mapping
            A :meth:`to_dict`, as read from JSON (a null number is NaN); only
            ``key`` and ``value`` are required.

        Returns
        -------
        Evidence

        Raises
        ------
        KeyError
            If ``key`` or ``value`` is missing.
        """
        return cls(d["key"], number(d["value"]), number(d.get("null_mean")),
                   number(d.get("null_sd")), number(d.get("p_value")),
                   d.get("description", ""), int(d.get("replicates", 0)))


def calibrate(values: Mapping[str, float], null: Mapping[str, np.ndarray] | None
              ) -> dict[str, Evidence]:
    """Evidence objects: each value against its bootstrap replicates."""
    ev = {}
    for k, v in values.items():
        e = Evidence(k, float(v), description=EVIDENCE.get(k, ""))
        if null is not None and math.isfinite(v):
            r = np.asarray(null.get(k, []), float)
            r = r[np.isfinite(r)]
            if r.size:
                e.null_mean = float(r.mean())
                e.null_sd = float(r.std(ddof=1)) if r.size > 1 else math.nan
                e.p_value = float((1 + np.sum(r >= v)) / (r.size + 1))
                e.replicates = int(r.size)
        ev[k] = e
    return ev

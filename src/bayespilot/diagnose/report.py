"""Show a diagnosis: PNG figures, a self-contained HTML report and a JSON summary.

Every plotting function takes a result (a single-run
:class:`~bayespilot.diagnose.DiagnosisResult`; :func:`plot_candidates` also a pooled
one, :func:`plot_shared_posterior` a ``SharedPosterior``, :func:`plot_batch` the
diagnoses' dicts) and optional axes, and returns the figure (it never calls
``plt.show()``); :func:`write_report` writes them all.  A figure made here uses
matplotlib's constrained layout; on axes the caller gives, the caller's figure and its
layout are left as they are.
"""

from __future__ import annotations

import base64
import html
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from .._files import write_text_atomic
from .._labels import parameter_label
from ..plots import _pyplot  # (one backend rule for every figure; batch.py imports it here)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from . import DiagnosisResult
    from .pooled import PooledDiagnosisResult
    from .posterior import SharedPosterior

__all__ = ["plot_frequency_response", "plot_residuals", "plot_evidence", "plot_candidates",
           "plot_posterior", "plot_profile", "plot_shared_posterior", "plot_batch",
           "write_report"]


def _subplots(*args, **kwargs):
    """A new figure and its axes, laid out by matplotlib's constrained layout."""
    return _pyplot().subplots(*args, layout="constrained", **kwargs)


#: Length of a Welch segment of the residual spectrum, s (1024 samples at the paper's
#: 100 Hz): the spectrum's lowest frequency, 2 pi / 10.24 = 0.61 rad/s, is the same at
#: every sample rate (a fixed 1024 samples started it at 6.1 rad/s at 1 kHz).
WELCH_SECONDS = 10.24

#: Units of the describing functions' magnitudes: u and e in rad, theta_ddot_m in rad/s^2.
H_V_UNIT = "rad/rad"
H_M_UNIT = "rad/(rad/s$^2$)"


def _sample_interval(result: DiagnosisResult, recording: Any = None) -> float:
    """The recording's sample interval, s: the result's ``settings["dt"]``, else the
    ``recording``'s (never an assumed rate)."""
    dt = result.settings.get("dt") if result.settings else None
    if dt is None and recording is not None:
        dt = recording.dt
    if dt is None or not (math.isfinite(dt) and dt > 0):
        raise ValueError("the result's settings have no sample interval ('dt'): pass the "
                         "recording it was diagnosed on (recording=...)")
    return float(dt)


def _residual_psd(x: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """One-sided Welch PSD of a residual (rad) in segments of :data:`WELCH_SECONDS` (at most
    the record), without the zero frequency: omega (rad/s) and the density per rad/s,
    rad^2/(rad/s) (scipy's per-Hz density divided by 2 pi, so that it integrates over omega
    to the variance)."""
    from scipy import signal

    nperseg = max(1, min(int(round(WELCH_SECONDS * fs)), x.size))
    f, P = signal.welch(x, fs=fs, nperseg=nperseg)
    return 2 * np.pi * f[1:], P[1:] / (2 * np.pi)


def _decision_band(result: DiagnosisResult) -> float:
    """The decision likelihood's low-pass cut-off omega_c, rad/s (inf: the whole band)."""
    from .decide import OMEGA_C

    nm = (result.settings or {}).get("noise_model")
    if isinstance(nm, Mapping) and "omega_c" in nm:
        w = nm["omega_c"]
        return math.inf if w is None else float(w)
    noise = result.arrays.get("noise")
    w = getattr(noise, "omega_c", None)
    return float(w) if w is not None else OMEGA_C


def _align(phase: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Shift an unwrapped phase (deg) by whole turns to lie closest to ``ref``."""
    k = np.round(np.nanmedian(ref - phase) / 360.0)
    return phase + 360.0 * k


def _no_describing_function(result: DiagnosisResult) -> str:
    """Why a result has no describing function, in a sentence (for the figure and the report)."""
    arr = result.arrays
    if arr.get("forcing_frequencies") is None:
        why = "the recording's forcing functions are unknown"
    else:
        why = ("the record is not whole periods of the forcing functions, or one of them is "
               "zero throughout")
    n, dt = np.size(arr.get("residual", ())), (result.settings or {}).get("dt")
    length = f" (this record: {n * dt:g} s)" if n and dt else ""
    return (f"No describing function: {why}{length}. The two-input estimate needs both "
            f"forcing functions over whole periods of the record (81.92 s for the paper's).")


def plot_frequency_response(result: DiagnosisResult, axes: Any = None) -> Figure:
    """Visual and motion-channel describing functions: data, base model, extended model.

    Parameters
    ----------
    result : DiagnosisResult
        A single-run diagnosis: the describing functions at the forcing
        frequencies of the data and of the base model, and of the extended
        model when an extension was chosen (``result.arrays``).  The models'
        are the same two-input estimate made from the model's simulated
        control output, so they exist only at the forcing frequencies and are
        drawn as markers there (the motion channel's threshold makes it
        depend on the signal's amplitude: there is no one curve between).
    axes : array of matplotlib Axes, optional
        Four axes, taken as 2 x 2 (rows: magnitude, phase in deg; columns:
        visual H_v = u/e in rad/rad, motion H_m = u/theta_ddot_m in
        rad/(rad/s^2)); default: a new figure.

    Returns
    -------
    matplotlib.figure.Figure
        The figure of the axes.  Without a describing function (forcing
        functions unknown, not whole periods of the record, or one zero
        throughout) a new figure is one short panel saying so; on given axes
        the first says so and the others are blank.
    """
    from matplotlib.lines import Line2D

    arr = result.arrays
    if "df_data" not in arr:
        msg = _no_describing_function(result)
        if axes is None:
            fig, ax = _subplots(figsize=(8, 1.6))
            rest = []
        else:
            flat = list(np.ravel(axes))
            fig, ax, rest = flat[0].figure, flat[0], flat[1:]
        for a in (ax, *rest):
            a.set_axis_off()
        ax.text(0.5, 0.5, msg, ha="center", va="center", transform=ax.transAxes, wrap=True,
                fontsize=9)
        return fig
    created = axes is None
    if created:
        fig, axes = _subplots(2, 2, figsize=(10, 7), sharex=True)
    else:
        fig = np.ravel(axes)[0].figure
    axes = np.asarray(axes).reshape(2, 2)
    d, mb = arr["df_data"], arr["df_model"]
    ma = arr.get("df_after")
    w = d["omega"]
    data_kw = dict(ls="none", marker="o", ms=4, color="k")
    base_kw = dict(ls="none", marker="s", ms=6, mfc="none", mec="C0", mew=1.2)
    after_kw = dict(ls="none", marker="^", ms=6, mfc="none", mec="C3", mew=1.2)
    for col, key, title, unit in (
            (0, "H_v", r"visual channel $H_\mathrm{v} = u/e$", H_V_UNIT),
            (1, "H_m", r"motion channel $H_\mathrm{m} = u/\ddot\theta_\mathrm{m}$", H_M_UNIT)):
        ax_m, ax_p = axes[0, col], axes[1, col]
        ax_m.loglog(w, np.abs(d[key]), **data_kw)
        ax_m.loglog(w, np.abs(mb[key]), **base_kw)
        ph_d = np.degrees(np.unwrap(np.angle(d[key])))
        ax_p.semilogx(w, ph_d, **data_kw)
        ax_p.semilogx(w, _align(np.degrees(np.unwrap(np.angle(mb[key]))), ph_d), **base_kw)
        if ma is not None:
            ax_m.loglog(w, np.abs(ma[key]), **after_kw)
            ax_p.semilogx(w, _align(np.degrees(np.unwrap(np.angle(ma[key]))), ph_d), **after_kw)
        ax_m.set_title(title, fontsize=10)
        ax_m.set_ylabel(f"magnitude ({unit})")
        ax_p.set_ylabel("phase (deg)")
        ax_p.set_xlabel(r"$\omega$ (rad/s)")
        ax_m.grid(True, which="both", alpha=0.3)
        ax_p.grid(True, which="both", alpha=0.3)
    handles = [Line2D([], [], **data_kw, label="data (two-input multisine estimate)"),
               Line2D([], [], **base_kw, label="base model (same estimate, model output)")]
    if ma is not None:
        handles.append(Line2D([], [], **after_kw, label=f"with {result.physics}"))
    if created:
        fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=8)
        fig.suptitle("Describing functions at the forcing frequencies", fontsize=11)
    else:
        axes[0, 0].legend(handles=handles, fontsize=7)
    return fig


def plot_residuals(result: DiagnosisResult, axes: Any = None, *, recording: Any = None
                   ) -> Figure:
    """Residual before and after: spectrum, variance over the run, against |i| and |u|.

    Parameters
    ----------
    result : DiagnosisResult
        A single-run diagnosis: the base model's residual and, when an
        extension was chosen, the extended model's (``result.arrays``), each
        after the first ``skip_seconds``.
    axes : array of matplotlib Axes, optional
        Four axes, taken as 2 x 2: the residual's one-sided PSD (Welch), in
        rad^2/(rad/s) against omega in rad/s, with the forcing frequencies
        marked; its variance over eight segments of the run; and its mean
        times sign conditioned on |i(t - tau_m)| (IPUT) and on |u| (rad);
        default: a new figure.  The PSD is averaged over segments of
        :data:`WELCH_SECONDS` (10.24 s, at most the record), so its lowest
        frequency, 2 pi / 10.24 rad/s, is the same at every sample rate; it
        is drawn up to twice the decision likelihood's cut-off omega_c
        (``settings["noise_model"]``, 25 rad/s by default), the part above
        omega_c, which the decision does not use, shaded.
    recording : Recording, optional
        The recording diagnosed: its sample interval is used when the
        result's ``settings`` have none (``diagnose`` always records it).

    Returns
    -------
    matplotlib.figure.Figure
        The figure of the axes; a conditioned panel without its statistic is
        hidden.

    Raises
    ------
    ValueError
        Neither ``result.settings["dt"]`` nor ``recording`` gives the
        sample interval.
    """
    from matplotlib.lines import Line2D

    arr = result.arrays
    if axes is None:
        fig, axes = _subplots(2, 2, figsize=(10, 7))
    else:
        fig = np.ravel(axes)[0].figure
    axes = np.asarray(axes).reshape(2, 2)
    fs = 1.0 / _sample_interval(result, recording)
    skip = int(round(result.settings["skip_seconds"] * fs))
    before = arr["residual"][skip:]
    after = arr.get("after_residual")
    after = after[skip:] if after is not None else None
    omega_c = _decision_band(result)
    w_max = 2.0 * omega_c if math.isfinite(omega_c) else math.inf
    ax = axes[0, 0]
    handles = []
    for x, lab, st in ((before, "base model", "C0-"), (after, f"with {result.physics}", "C3-")):
        if x is None:
            continue
        om, P = _residual_psd(np.asarray(x, float), fs)
        keep = om <= w_max
        handles += ax.loglog(om[keep], P[keep], st, lw=1, label=lab)
    ff = arr.get("forcing_frequencies")
    if ff is not None:
        for w in ff[0]:
            ax.axvline(w, color="0.6", lw=0.6, ls=":")
        for w in ff[1]:
            ax.axvline(w, color="0.75", lw=0.6, ls="--")
        handles += [Line2D([], [], color="0.6", lw=0.8, ls=":", label="target frequencies"),
                    Line2D([], [], color="0.75", lw=0.8, ls="--",
                           label="disturbance frequencies")]
    if math.isfinite(omega_c):
        ax.axvspan(omega_c, w_max, color="0.5", alpha=0.15, lw=0)
        ax.set_xlim(right=w_max)
        handles.append(Line2D([], [], color="0.5", alpha=0.3, lw=6,
                              label=rf"above $\omega_c$ = {omega_c:g} rad/s: not in the "
                                    "decision"))
    ax.set_xlabel(r"$\omega$ (rad/s)")
    ax.set_ylabel("one-sided PSD (rad$^2$/(rad/s))")
    ax.set_title("residual spectrum", fontsize=10)
    ax.legend(handles=handles, fontsize=7, loc="lower left")
    ax = axes[0, 1]
    nseg = 8
    for x, lab, st in ((before, "base model", "C0o-"), (after, f"with {result.physics}", "C3s-")):
        if x is None:
            continue
        v = [np.var(s) for s in np.array_split(x, nseg)]
        ax.plot(np.arange(nseg) + 1, v, st, label=lab)
    ax.set_xlabel(f"segment of the run (eighths, after the first {result.settings['skip_seconds']:g} s)")
    ax.set_ylabel("residual variance (rad$^2$)")
    ax.set_title("residual over the run", fontsize=10)
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-2, 3))
    for ax, key, lab, what in ((axes[1, 0], "amp_canal", r"$|i(t - \tau_\mathrm{m})|$ (IPUT)",
                                r"$|i(t - \tau_\mathrm{m})|$"),
                               (axes[1, 1], "amp_control", "$|u|$ (rad)", "$|u|$")):
        b = arr.get(key)
        if b is None:
            ax.set_visible(False)
            continue
        ax.plot(b["centre"], b["mean"], "C0o-", label="base model")
        if after is not None:
            from .locate import _binned

            # same conditioning variable, the after-residual
            src = arr["canal_delayed"] if key == "amp_canal" else arr["u_after_cond"]
            bb = _binned(after, src, edges_q=(0.0, 0.2, 0.4, 0.6, 0.8, 0.9, 1.0)
                         if key == "amp_canal" else (0.0, 0.5, 0.8, 0.95, 0.99, 1.0))
            ax.plot(bb["centre"], bb["mean"], "C3s-", label=f"with {result.physics}")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_xlabel(lab)
        ax.set_ylabel("mean residual × sign (rad)")
        ax.set_title(f"residual conditioned on {what}", fontsize=10)
    axes[0, 1].legend(fontsize=8)
    return fig


def plot_evidence(result: DiagnosisResult, ax: Any = None) -> Figure:
    """-log10 of each located statistic's bootstrap p-value.

    Parameters
    ----------
    result : DiagnosisResult
        A single-run diagnosis: its located evidence (``result.where``) and
        the bootstrap's size.
    ax : matplotlib Axes, optional
        Default: a new figure.

    Returns
    -------
    matplotlib.figure.Figure
        One bar per statistic with a finite value (red at p <= 0.05), "n/a"
        where its p-value is not a finite positive number, p = 0.05 dashed
        and the smallest p the bootstrap of B replicates can give,
        1 / (B + 1), as a wide grey line (both in the legend; at B = 19 they
        are the same).  Without a bootstrap (``n_bootstrap=0``, or skipped)
        the axes say "no bootstrap p-values" and draw no bars.
    """
    from matplotlib.lines import Line2D

    if ax is None:
        fig, ax = _subplots(figsize=(8, 4.8))
    else:
        fig = ax.figure
    keys = [k for k, e in result.where.items() if math.isfinite(e.value)]
    p = [result.where[k].p_value for k in keys]
    ok = [math.isfinite(x) and x > 0 for x in p]
    B = int((result.settings.get("bootstrap") or {}).get("replicates", 0) or 0)
    ax.set_yticks(range(len(keys)))
    ax.set_yticklabels(keys, fontsize=8)
    ax.set_ylim(len(keys) - 0.5, -0.5)
    ax.set_title("Where the data and the base model differ", fontsize=10)
    if not any(ok):
        why = (result.settings.get("bootstrap") or {}).get("skipped")
        ax.text(0.5, 0.5, "no bootstrap p-values: the located statistics were not tested\n"
                + (f"({why})" if why else "(diagnose(n_bootstrap=0), --bootstrap 0)"),
                ha="center", va="center", transform=ax.transAxes, fontsize=9, wrap=True,
                bbox=dict(fc="white", ec="0.6"))
        ax.set_xticks([])
        ax.set_xlabel(r"$-\log_{10} p$ (no parametric bootstrap)")
        return fig
    val = [-math.log10(x) if good else 0.0 for x, good in zip(p, ok)]
    crit = -math.log10(0.05)
    ax.barh(range(len(keys)), val,
            color=["C3" if good and x <= 0.05 else "C0" for x, good in zip(p, ok)])
    for i, good in enumerate(ok):
        if not good:
            ax.text(0.02, i, "n/a", va="center", fontsize=7, color="0.3",
                    transform=ax.get_yaxis_transform())
    handles = []
    if B:
        floor = math.log10(B + 1)
        ax.axvline(floor, color="0.6", lw=5, alpha=0.5, solid_capstyle="butt")
        handles.append(Line2D([], [], color="0.6", lw=5, alpha=0.5,
                              label=f"smallest possible p, 1/(B + 1) = {1 / (B + 1):.2g}"))
    ax.axvline(crit, color="k", ls="--", lw=1)
    handles.insert(0, Line2D([], [], color="k", ls="--", lw=1, label="p = 0.05"))
    ax.set_xlim(0, 1.1 * max(max(val), crit, math.log10(B + 1) if B else 0.0))
    ax.legend(handles=handles, fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.set_xlabel(rf"$-\log_{{10}}\,p$ (parametric bootstrap, B = {B}; red: p $\leq$ 0.05)")
    return fig


def _figure_and_axes(ax: Any = None, figsize=(8, 4)):
    """``(figure, axes)``: the given axes and their figure, or a new (constrained-layout)
    figure of ``figsize``."""
    if ax is None:
        return _subplots(figsize=figsize)
    return ax.figure, ax


def _p_text(p: float) -> str:
    """A p-value as the figures and the report write it."""
    if p is None or not math.isfinite(p):
        return "—"
    return "0" if p == 0 else f"{p:.2g}"


def plot_candidates(result: DiagnosisResult | PooledDiagnosisResult, ax: Any = None
                    ) -> Figure:
    """Fit improvement of each candidate on the decision likelihood, with the test's threshold.

    Parameters
    ----------
    result : DiagnosisResult or PooledDiagnosisResult
        A diagnosis, single-run or pooled: its testable candidates
        (``result.ranking``) and the level per candidate.
    ax : matplotlib Axes, optional
        Default: a new figure.

    Returns
    -------
    matplotlib.figure.Figure
        One bar per testable candidate, d(-ln L) (red: justified; a symlog
        axis when the largest bar or threshold is above 10, else linear), its
        p-value in a column at the right, and for an entry with new
        parameters a black mark at the d(-ln L) its test needs at the level
        per candidate: half the chi2(df) quantile at the level, or for a
        one-parameter boundary null (chi-bar-squared: the p-value halved)
        half the chi2(1) quantile at twice the level; times the bootstrap's
        scale where the test was calibrated and the scale is above 1.
        The marks are the axes' only lines.
    """
    from matplotlib import ticker
    from scipy import stats

    fig, ax = _figure_and_axes(ax)
    rows = [c for c in result.ranking if c.testable]
    level = result.settings["level_per_candidate"]
    names = [c.physics for c in rows]
    d = [c.delta_neg_log_lik for c in rows]
    ax.barh(range(len(rows)), d, color=["C3" if c.justified else "C0" for c in rows])
    crits = []
    for i, c in enumerate(rows):
        if c.df > 0:
            # the threshold of the test that decided (decide.lr_p_value, calibrate.Calibration)
            boundary = _boundary_null(c)
            crit = 0.5 * stats.chi2.isf(2.0 * level if boundary else level, c.df)
            if c.calibration is not None:
                crit *= max(1.0, c.calibration.scale)
            crits.append(crit)
            ax.plot([crit, crit], [i - 0.4, i + 0.4], "k-", lw=2)
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels(names, fontsize=8)
    ax.set_ylim(len(rows) - 0.5, -0.5)
    top = max([0.0, *(x for x in d if math.isfinite(x)), *crits])
    if top > 10:
        ax.set_xscale("symlog", linthresh=1.0)
        ax.set_xlim(min(0.0, *(x for x in d if math.isfinite(x))), top * 1.6)
        ax.xaxis.set_major_locator(ticker.SymmetricalLogLocator(base=10, linthresh=1.0,
                                                                subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_minor_locator(ticker.NullLocator())
        ax.xaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    ax.grid(True, axis="x", alpha=0.3)
    ax.set_axisbelow(True)
    # the p-values as a column at the right, clear of the bars and the marks
    right = ax.secondary_yaxis("right")
    right.set_yticks(range(len(rows)))
    right.set_yticklabels([f"p = {_p_text(c.p_value)}" for c in rows], fontsize=8)
    right.tick_params(length=0)
    ax.set_xlabel(r"$\Delta(-\ln L) = -\ln L_\mathrm{base} - (-\ln L_\mathrm{extension})$"
                  "\nblack mark: what the test needs at the level per candidate "
                  f"({level:.2g}); red: justified", fontsize=9)
    ax.set_title(f"Candidates (decision: {result.physics})", fontsize=10)
    return fig


def _boundary_null(c: Any) -> bool:
    """Whether candidate ``c``'s test had the chi-bar-squared reference of a one-parameter
    boundary null: its catalogue entry says so; an entry not registered here (a result file
    of another session's own entry) is read from how its test was made (``reason``)."""
    from .catalogue import get_extension

    if c.df != 1:
        return False
    try:
        return bool(get_extension(c.physics).boundary_null)
    except ValueError:
        return "boundary null" in (c.reason or "")


def plot_batch(diagnoses: Sequence[tuple[str, Mapping[str, Any]]], ax: Any = None) -> Figure:
    """Every candidate's p-value in every diagnosis of a batch, at a glance.

    Parameters
    ----------
    diagnoses : sequence of (str, dict)
        ``(key, diagnosis)`` with ``diagnosis`` as ``DiagnosisResult.to_dict()``
        (or the pooled one) writes it.
    ax : matplotlib Axes, optional
        Default: a new figure, at least 3.6 in tall (its colour bar's label
        whole) and 0.28 in more per diagnosis.

    Returns
    -------
    matplotlib.figure.Figure
        One row per diagnosis, one column per catalogue entry (the built-in
        ones, then any other a diagnosis tested, in the order first met: an
        entry of one's own, registered or not), coloured by
        -log10 p up to 6 (where a p is below 1e-6, an arrow on the colour bar
        says the scale is capped there; grey: not
        testable on that recording); a dot where p is below the decision's
        level per candidate (the white line on the colour bar), a box around
        the chosen extension, the decision at the left.
    """
    from .catalogue import NAMES

    plt = _pyplot()
    n = len(diagnoses)
    names = list(NAMES)  # then the entries of one's own the diagnoses tested
    for _, d in diagnoses:
        names += [c["physics"] for c in d["ranking"] if c["physics"] not in names]
    if ax is None:
        fig, ax = _subplots(figsize=(8.5 + 0.9 * (len(names) - len(NAMES)),
                                     min(max(3.6, 1.9 + 0.28 * n), 60.0)))
    else:
        fig = ax.figure
    z = np.full((n, len(names)), np.nan)
    for i, (_, d) in enumerate(diagnoses):
        level = d["settings"]["level_per_candidate"]
        for c in d["ranking"]:
            p = c.get("p_value")
            if isinstance(p, (int, float)) and c.get("testable", True):
                j = names.index(c["physics"])
                z[i, j] = -math.log10(max(p, 1e-16))
                if p < level:
                    ax.plot(j, i, "k.", ms=5)
        if d["physics"] in names:
            j = names.index(d["physics"])
            ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, ec="k", lw=2))
    cmap = plt.get_cmap("viridis").with_extremes(bad="0.85")
    im = ax.imshow(np.ma.masked_invalid(z), aspect="auto", cmap=cmap, vmin=0, vmax=6,
                   interpolation="nearest")
    capped = bool(np.any(z[np.isfinite(z)] > 6))
    # a bar about 0.15 in wide however tall the axes (matplotlib's default aspect of 20 made
    # it 0.6 in wide beside 40 diagnoses)
    tall = fig.get_size_inches()[1] * ax.get_position().height
    cb = fig.colorbar(im, ax=ax, extend="max" if capped else "neither", pad=0.02,
                      aspect=max(20.0, tall / 0.15),
                      label=r"$-\log_{10} p$" + (" (arrow: p < 1e-6)" if capped else ""))
    levels = [d["settings"]["level_per_candidate"] for _, d in diagnoses]
    if levels:  # the decision's level per candidate (the median, should they differ)
        cb.ax.axhline(-math.log10(float(np.median(levels))), color="w", lw=2)
    ax.set_xticks(range(len(names)))
    ax.set_xticklabels(names, rotation=30, ha="right", fontsize=8)
    ax.set_yticks(range(n))
    ax.set_yticklabels([f"{k}: {d['physics']}" for k, d in diagnoses], fontsize=7)
    ax.set_title(f"{n} {'diagnosis' if n == 1 else 'diagnoses'}: every candidate's p-value\n"
                 "dot: below the level per candidate (white line); box: chosen; grey: not "
                 "testable", fontsize=9)
    return fig


def _axes_row(n: int, axes: Any = None, height: float = 4.2):
    """(figure, n axes in a row): new ones (constrained layout), or the given ones'."""
    if axes is None:
        fig, axes = _subplots(1, n, figsize=(4.8 * n, height), squeeze=False)
        return fig, axes[0]
    axes = np.atleast_1d(axes)
    return axes[0].figure, axes


def _units_model(physics: str, model: Any = None) -> Any:
    """A model that declares the units of ``physics``'s new parameters: ``model`` when given,
    else the catalogue entry built on the paper's model; None if neither can be had (another
    lab's extension read back from a file): the labels then have no units."""
    if model is not None:
        return model
    try:
        from ..model import paper_model
        from .catalogue import get_extension

        return get_extension(physics).build(paper_model())
    except Exception:  # an unknown name, a build that needs more: labels without units
        return None


def _legend_below(ax, ncols: int = 2) -> None:
    """The axes' legend under them, clear of the data (constrained layout makes room)."""
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncols=ncols,
              frameon=False)


def _mark_fit(ax, value: float, stderr: float, label: str) -> None:
    """A maximum-likelihood fit and its ±1 standard error on a marginal's axes."""
    ax.axvline(value, color="C3", ls="--", lw=1, label=label)
    if math.isfinite(stderr):
        ax.axvspan(value - stderr, value + stderr, color="C3", alpha=0.12, label="±1 s.e.")


def plot_posterior(result: DiagnosisResult, axes: Any = None) -> Figure:
    """Marginal posteriors of the chosen extension's new parameters, with the maximum-likelihood
    fit and its ±1 standard error (from the decision likelihood) marked, and its
    profile-likelihood interval where it was made.

    Parameters
    ----------
    result : DiagnosisResult
        A single-run diagnosis with a chosen extension whose posterior has
        been sampled (``result.posterior``,
        :func:`~bayespilot.diagnose.sample_chosen`).
    axes : sequence of matplotlib Axes, optional
        One per new parameter of the chosen extension that the posterior
        has, in a row; default: a new figure.

    Returns
    -------
    matplotlib.figure.Figure
        Each panel's x axis is the parameter in the paper's notation with
        its unit (the extended model's), its legend under the axes.
    """
    from ..plots import plot_marginal

    post, chosen = result.posterior, result.chosen
    names = [n for n in chosen.params if n in post.parameter_names]
    fig, axes = _axes_row(len(names), axes)
    model = _units_model(chosen.physics, getattr(chosen, "model", None))
    for ax, n in zip(axes, names):
        plot_marginal(post, n, ax=ax)
        _mark_fit(ax, chosen.params[n], chosen.stderr.get(n, math.nan),
                  "ML fit (decision likelihood)")
        iv = chosen.interval.get(n)
        if iv is not None:
            for k, end in enumerate((iv.lower, iv.upper)):
                ax.axvline(end, color="C3", ls=":", lw=1.2,
                           label=f"{100 * iv.level:.0f} % profile interval" if k == 0 else None)
        ax.set_xlabel(parameter_label(model, n))
        ax.set_title(f"{post.draws(n).size} draws ("
                     f"{'converged' if post.converged else 'not converged'})", fontsize=8)
        _legend_below(ax)
    fig.suptitle(f"{chosen.physics}: posterior of its new parameters", fontsize=10)
    return fig


def plot_profile(result: DiagnosisResult, axes: Any = None) -> Figure:
    """The profile likelihood of each of the chosen extension's new parameters
    (``result.chosen.interval``, :mod:`bayespilot.diagnose.profile`): the scaled deviance at
    the profile's points, the level it must stay below, the interval and the reported fit.

    Parameters
    ----------
    result : DiagnosisResult
        A single-run diagnosis whose chosen extension has profile intervals
        (``diagnose(refit=True, intervals=True)``, the default).
    axes : sequence of matplotlib Axes, optional
        One per parameter with an interval, in a row; default: a new figure.

    Returns
    -------
    matplotlib.figure.Figure
        Each panel's x axis is the parameter in the paper's notation with
        its unit, its legend under the axes.

    Raises
    ------
    ValueError
        No extension was chosen, or it has no profile intervals (a pooled
        diagnosis, ``diagnose(intervals=False)``).
    """
    chosen = result.chosen
    if chosen is None or not chosen.interval:
        raise ValueError("the diagnosis has no profile intervals (no extension chosen, a pooled "
                         "diagnosis, or diagnose(intervals=False))")
    names = list(chosen.interval)
    fig, axes = _axes_row(len(names), axes)
    model = _units_model(chosen.physics, getattr(chosen, "model", None))
    for ax, n in zip(axes, names):
        iv = chosen.interval[n]
        ok = np.isfinite(iv.deviance)
        ax.plot(iv.values[ok], iv.deviance[ok], "o-", color="C0", ms=3, lw=1,
                label="scaled deviance (profile)")
        q = iv.quantile
        ax.axhline(q, color="0.4", ls=":", lw=1,
                   label=rf"$\chi^2_1$ {100 * iv.level:.0f} % quantile")
        ax.axvspan(iv.lower, iv.upper, color="C0", alpha=0.12,
                   label=f"{100 * iv.level:.0f} % interval {iv}")
        ax.axvline(chosen.params[n], color="C3", ls="--", lw=1, label="reported fit")
        ax.set_ylim(-0.05 * q, 3 * q)
        ax.set_xlabel(parameter_label(model, n))
        ax.set_ylabel(r"$2\,\Delta(-\ln L)$ × scale")
        _legend_below(ax)
    fig.suptitle(f"{chosen.physics}: profile likelihood of its new parameters", fontsize=10)
    return fig


def plot_shared_posterior(post: SharedPosterior, axes: Any = None) -> Figure:
    """The marginal posteriors of a pooled diagnosis's shared parameters
    (:func:`~bayespilot.diagnose.shared_posterior`), with the pooled fit and its ±1 standard
    error and the central 90 % interval marked.

    Parameters
    ----------
    post : SharedPosterior
        The posterior :func:`~bayespilot.diagnose.shared_posterior` returned
        (also a pooled diagnosis's ``posterior``).
    axes : sequence of matplotlib Axes, optional
        One per shared parameter, in a row; default: a new figure.

    Returns
    -------
    matplotlib.figure.Figure
        Each panel's x axis is the parameter in the paper's notation with
        the unit its catalogue entry declares, its legend under the axes.
    """
    names = list(post.names)
    fig, axes = _axes_row(len(names), axes)
    model = _units_model(post.physics)
    for a, (ax, n) in enumerate(zip(axes, names)):
        g, m = post.grid[a], np.asarray(post.marginals[n]["density"])
        ax.plot(g, m, color="C0", lw=1.5, label="posterior (grid, Laplace)")
        lo, hi = post.marginals[n]["interval"]
        inside = (g >= lo) & (g <= hi)
        ax.fill_between(g[inside], m[inside], color="C0", alpha=0.2, label="central 90 %")
        _mark_fit(ax, post.ml[n], post.stderr.get(n, math.nan), "pooled ML fit")
        ax.set_xlabel(parameter_label(model, n))
        ax.set_ylabel("posterior density")
        _legend_below(ax)
    fig.suptitle(f"{post.physics}: posterior of the parameters shared by "
                 f"{post.settings['n_runs']} runs", fontsize=10)
    return fig


def _png(fig, path: Path) -> Path:
    plt = _pyplot()
    try:
        fig.savefig(path, dpi=110)
    finally:
        plt.close(fig)
    return path


def _number(x: Any, fmt: str, missing: str = "—") -> str:
    """``x`` formatted by ``fmt`` for the report: ``missing`` when it is not a number, NaN
    or -inf (a statistic not computed), "∞" for +inf, and never a negative zero ("-0.00"
    reads "0.00")."""
    try:
        x = float(x)
    except (TypeError, ValueError):
        return missing
    if x == math.inf:
        return "∞"
    if not math.isfinite(x):
        return missing
    s = format(x, fmt)
    if s.startswith("-") and float(s) == 0.0:
        s = s[1:]
    return s


def _yes_no(flag: Any) -> str:
    return "yes" if flag else "no"


def _candidate_table(ranking: Sequence[Any]) -> str:
    """The candidates' HTML table of a report (single-run or pooled): one row per candidate,
    a justified one bold; "—" where a number does not apply (a censored fit's Delta BIC)."""
    rows = []
    for c in ranking:
        if not c.testable:
            rows.append(f"<tr><td>{html.escape(c.physics)}</td><td colspan=5>not tested: "
                        f"{html.escape(c.reason)}</td></tr>")
            continue
        interval = getattr(c, "interval", None) or {}
        ps = ", ".join(f"{html.escape(k)} = {_number(v, '.4g')} &plusmn; "
                       f"{_number(c.stderr.get(k), '.2g')}"
                       + (f" ({100 * interval[k].level:.0f} % profile interval "
                          f"{html.escape(str(interval[k]))})" if k in interval else "")
                       for k, v in c.params.items())
        if not ps and c.reason:  # no fit to show (control-saturation without flat tops)
            ps = html.escape(c.reason)
        bold = ' style="font-weight:bold"' if c.justified else ''  # a justified candidate: bold
        rows.append(f"<tr{bold}>"
                    f"<td>{html.escape(c.physics)}</td>"
                    f"<td>{_number(c.delta_neg_log_lik, '.2f')}</td>"
                    f"<td>{_number(c.p_value, '.3g')}</td>"
                    f"<td>{_number(c.delta_bic, '.1f')}</td>"
                    f"<td>{_number(c.signature_score, '.2f')}</td><td>{ps}</td></tr>")
    return ("<table><tr><th>physics</th><th>&Delta;(-ln L)</th><th>p</th><th>&Delta;BIC</th>"
            "<th>signature</th><th>parameters</th></tr>\n" + "\n".join(rows) + "</table>\n"
            "<p><small>Bold: justified at the level per candidate. &mdash;: not computed "
            "(no fit was made).</small></p>")


def _img(path: Path, caption: str = "") -> str:
    """A PNG embedded in the page, with its caption."""
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
    return (f'<figure style="margin:0 0 1em 0"><img alt="{html.escape(Path(path).stem)}" '
            f'src="data:image/png;base64,{data}" style="max-width:100%">{cap}</figure>')


#: The style of both reports' pages.
_STYLE = ("body{font-family:sans-serif;max-width:1000px;margin:auto}"
          "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 6px;"
          "font-size:90%}figcaption{font-size:85%;color:#444}")


def write_report(result: DiagnosisResult, directory: str | Path, *, recording: Any = None
                 ) -> dict[str, Path]:
    """Write the figures, ``report.html`` and ``diagnosis.json`` to ``directory``.

    Parameters
    ----------
    result : DiagnosisResult
        A single-run diagnosis (a pooled one writes its own report,
        :meth:`PooledDiagnosisResult.report`).
    directory : str or Path
        Created, with its parents, if missing; files of the same names in it
        are replaced.
    recording : Recording, optional
        The recording diagnosed, for a result without its sample interval
        (:func:`plot_residuals`).

    Returns
    -------
    dict of str to Path
        The files by name: ``frequency_response``, ``residuals``,
        ``evidence`` and ``candidates`` (PNG), ``profile`` (PNG, when the
        chosen extension has profile intervals), ``posterior`` (PNG, when
        ``result.posterior`` is set), ``json`` (``diagnosis.json``,
        :meth:`DiagnosisResult.to_json`) and ``html`` (``report.html``, the
        figures embedded).  Without a describing function (a record that is
        not whole periods of the forcing) ``frequency_response.png`` says so
        and the page says it in words instead of showing it.

    Raises
    ------
    OSError
        ``directory`` cannot be created or a file in it written.
    ValueError
        Neither ``result.settings["dt"]`` nor ``recording`` gives the sample
        interval (:func:`plot_residuals`; a result of ``diagnose`` has it).
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "frequency_response": _png(plot_frequency_response(result), out / "frequency_response.png"),
        "residuals": _png(plot_residuals(result, recording=recording), out / "residuals.png"),
        "evidence": _png(plot_evidence(result), out / "evidence.png"),
        "candidates": _png(plot_candidates(result), out / "candidates.png"),
    }
    chosen = getattr(result, "chosen", None)
    if chosen is not None and chosen.interval:
        paths["profile"] = _png(plot_profile(result), out / "profile.png")
    post = getattr(result, "posterior", None)
    if post is not None:
        paths["posterior"] = _png(plot_posterior(result), out / "posterior.png")
    paths["json"] = out / "diagnosis.json"
    result.to_json(paths["json"])

    physics = html.escape(result.physics)
    after = f" and with {physics}" if chosen is not None else ""
    tested = [e for e in result.where.values() if math.isfinite(e.value)]
    ev = "".join(f"<tr><td>{html.escape(k)}</td><td>{html.escape(e.description)}</td>"
                 f"<td>{_number(e.value, '.4g')}</td><td>{_number(e.p_value, '.3f')}</td></tr>"
                 for k, e in result.where.items() if math.isfinite(e.value))
    no_p = "" if any(math.isfinite(e.p_value) for e in tested) else (
        "<p>No bootstrap p-values: the located statistics were not tested "
        "(diagnose(n_bootstrap=0), or the bootstrap was skipped).</p>")
    if "df_data" in result.arrays:
        freq = _img(paths["frequency_response"],
                    f"Describing functions u/e (visual) and u/theta_ddot_m (motion) at the "
                    f"forcing frequencies: the data's two-input estimate (dots), the same "
                    f"estimate from the base model's output{after}.")
    else:
        freq = f"<p>{html.escape(_no_describing_function(result))}</p>"
    from . import _calibration_lines

    cal = "".join(f"<p>{html.escape(line)}</p>" for line in _calibration_lines(result.ranking)
                  if line)
    bf = getattr(result, "bayes_factor", None)
    bf_html = "" if bf is None else (
        f"<h2>Bayes factor</h2><p>{html.escape(bf.summary_line())}: ln Z(extended) = "
        f"{bf.extended.log_z:.2f}, ln Z(base) = {bf.base.log_z:.2f}; priors uniform on the "
        f"bounds (new parameters: "
        f"{html.escape(', '.join(f'{k} in [{lo:g}, {hi:g}]' for k, (lo, hi) in bf.prior.items()))}"
        f"); {bf.settings['runs']} nested-sampling runs per model, {bf.settings['nlive']} live "
        f"points. The decision is the likelihood-ratio test's.</p>")
    omega_c = _decision_band(result)
    band = (f"the decision's band, up to omega_c = {omega_c:g} rad/s, unshaded"
            if math.isfinite(omega_c) else "the decision uses the whole band")
    title = f"bayespilot diagnosis: {physics}"
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>{_STYLE}</style></head><body>
<h1>{title}</h1>
<p>Recording: {html.escape(str(result.source))}. Mismatch: <b>{_yes_no(result.mismatch)}</b>.
Base model: -ln L (Eq. 4) = {result.base['neg_log_lik']:.2f}, VAF = {result.base['vaf']:.2f} %.
Decision at family-wise level alpha = {result.settings['alpha']:g}
({result.settings['level_per_candidate']:.2g} per candidate). Time {result.elapsed:.1f} s.</p>
<h2>Candidates</h2>
{_candidate_table(result.ranking)}
{cal}
{_img(paths['candidates'], "Improvement of the decision likelihood by each candidate; the black "
      "mark is what its test needs, the p-values are at the right.")}
{bf_html}
<h2>Where</h2>
<table><tr><th>evidence</th><th>what</th><th>value</th><th>bootstrap p</th></tr>{ev}</table>
{no_p}
{_img(paths['evidence'], "-log10 of each located statistic's parametric-bootstrap p-value.")}
<h2>Frequency responses</h2>{freq}
<h2>Residuals before and after</h2>
{_img(paths['residuals'], f"Residual u - u_hat of the base model{after}: its spectrum ({band}), "
      "its variance over the run, and its mean times sign against the canal output and the "
      "control.")}
{f"<h2>Profile likelihood of the new parameters</h2>{_img(paths['profile'], 'Scaled deviance along each new parameter, the level it must stay below, the interval and the reported fit.')}" if "profile" in paths else ""}
{f"<h2>Posterior of the extended model</h2>{_img(paths['posterior'], 'Marginal posterior of each new parameter with the maximum-likelihood fit and its standard error.')}" if post is not None else ""}
<pre>{html.escape(result.summary())}</pre>
</body></html>
"""
    paths["html"] = write_text_atomic(out / "report.html", page)
    return paths

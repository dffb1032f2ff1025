"""Show a diagnosis: PNG figures, a self-contained HTML report and a JSON summary.

Every plotting function takes a result (a single-run
:class:`~bayespilot.diagnose.DiagnosisResult`; :func:`plot_candidates` also a pooled
one, :func:`plot_shared_posterior` a ``SharedPosterior``, :func:`plot_batch` the
diagnoses' dicts) and optional axes, and returns the figure (it never calls
``plt.show()``); :func:`write_report` writes them all.  A figure made here uses
matplotlib's constrained layout; on axes the caller gives, the caller's figure and its
layout are left as they are.

For a paper each takes ``title=`` (True: the figure's own title, as the report draws it;
False: none, the axes taking its room; a str: that text) and ``figsize=`` (a new figure's
size, as given: a 3.5-in column's); on a column's width, or the caller's narrow axes,
titles, captions and legends are wrapped or placed to stay inside the figure.  A result
read back from JSON keeps no signals: the figures drawn from them say so.
"""

from __future__ import annotations

import base64
import hashlib
import html
import json
import math
import os
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterator, Mapping, Sequence

import numpy as np

from .._files import dumps, write_text_atomic
from .._labels import parameter_label, symbol
from .._figstyle import PLOT_DPI, PLOT_FORMATS, save_figure
from ..plots import PAGE_WIDTH, _figsize, _title_text, _wrap
from ..plots import _pyplot  # (one backend rule for every figure; batch.py imports it here)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from . import DiagnosisResult
    from .pooled import PooledDiagnosisResult
    from .posterior import SharedPosterior

__all__ = ["plot_frequency_response", "plot_residuals", "plot_evidence", "plot_candidates",
           "plot_posterior", "plot_profile", "plot_shared_posterior", "plot_batch",
           "write_report"]


#: Resolution of the report's PNG figures, dots per inch: what ``bayespilot plot`` saves at,
#: enough for a figure printed at its size.
FIGURE_DPI = PLOT_DPI

#: Short words for each located statistic (``result.where``'s keys), for the evidence
#: figure's axis; a key not here (another lab's statistic) is shown as its words, "." and
#: "_" read as ": " and " ".
EVIDENCE_LABELS = {
    "frequency.visual": "visual response",
    "frequency.motion_low": r"motion response, $\omega < 2$ rad/s",
    "frequency.motion_high": r"motion response, $\omega \geq 2$ rad/s",
    "frequency.power_target": "residual power, target freq.",
    "frequency.power_disturbance": "residual power, disturbance freq.",
    "time.variance_drift": "residual variance trend",
    "time.nonstationarity": "residual variance spread",
    "time.gain_drift_visual": f"visual gain {symbol('K_v')} drift",
    "time.gain_drift_motion": f"motion gain {symbol('K_m')} drift",
    "amplitude.canal": f"residual vs. $|i(t - {symbol('tau_m')[1:-1]})|$",
    "amplitude.control": r"residual vs. $|u|$",
    "amplitude.motion": r"variance vs. $|\ddot\theta_\mathrm{m}|$",
    "amplitude.flat_tops": "flat tops of $u$",
}


def _evidence_label(key: str) -> str:
    """A located statistic's short words (:data:`EVIDENCE_LABELS`)."""
    if key in EVIDENCE_LABELS:
        return EVIDENCE_LABELS[key]
    return key.replace(".", ": ", 1).replace("_", " ")


def _delta_format(x: float) -> str:
    """The format of a candidate's improvement of -ln L in the candidates figure: three
    significant digits, whole numbers from 100 up, two decimals below 1."""
    return ".0f" if abs(x) >= 100 else (".3g" if abs(x) >= 1 else ".2f")


def _subplots(*args, figsize: tuple[float, float] = (PAGE_WIDTH, 4.0), tall: bool = False,
              given: Any = None, **kwargs):
    """A new figure and its axes, laid out by matplotlib's constrained layout, at most a
    paper's page (:func:`bayespilot.plots._figsize`); ``tall``: only its width capped (a
    batch's summary, a row per diagnosis); ``given``: the caller's ``figsize=`` (width,
    height in inches), used as it is (ValueError for one that is not two positive
    numbers)."""
    if given is not None:
        w, h = _figsize(given, None, figsize)
    else:
        w, h = _figsize(None, None, figsize)
        h = figsize[1] if tall else h
    return _pyplot().subplots(*args, layout="constrained", figsize=(w, h), **kwargs)


def _no_figsize_with(figsize: Any, axes: Any) -> None:
    """ValueError when ``figsize`` (the size of a new figure) comes with the caller's axes."""
    if figsize is not None and axes is not None:
        raise ValueError("figsize sizes a new figure; it cannot be given with ax/axes")


def _columns(handles: Sequence[Any], fig: Any, ncols: int, figsize: Any = None) -> int:
    """How many of at most ``ncols`` columns a legend of ``handles`` under a new figure
    takes: ``ncols`` at the figure's own size, fewer where they would not fit the width the
    caller gave (``figsize``: a column's width)."""
    from ..plots import _legend_columns

    if figsize is None:
        return ncols
    return _legend_columns([h.get_label() for h in handles], fig.get_figwidth(), ncols)


def _fig_title(fig: Any, text: str | None) -> None:
    """``text`` as the figure's title (:func:`_suptitle`: wrapped to its width); none for
    None."""
    if text:
        _suptitle(fig, text)


def _text_span(ax: Any) -> tuple[float, str]:
    """Where a text over or under ``ax`` (its title, its x label, a legend) goes, and how
    wide (in) it can be, to stay over the axes and their tick labels (the axes' own part of
    the figure: a neighbour's is left alone) and inside the figure, as the figure is laid
    out now: ``(width, "center")``, centred on the axes; or, where tick labels on one side
    leave a centred text much less room than there is (the evidence's statistic names at a
    column's width), ``(width, "right")``, aligned with the axes' right end and running
    over the labels on the left (``"left"``, the other way round).  Measured with the title
    and x label empty (set them after)."""
    fig = ax.figure
    fig.draw_without_rendering()  # (lays a constrained figure out)
    a = ax.get_window_extent()
    box = ax.get_tightbbox()
    fb = fig.bbox
    lo = max(min(box.x0, a.x0), fb.x0)
    hi = min(max(box.x1, a.x1), fb.x1)
    c = 0.5 * (a.x0 + a.x1)
    centred = max(2.0 * min(c - lo, hi - c), 0.0)
    if centred >= 0.7 * (hi - lo):
        return centred / fig.dpi, "center"
    if c - lo > hi - c:
        return max(min(a.x1, fb.x1) - lo, 0.0) / fig.dpi, "right"
    return max(hi - max(a.x0, fb.x0), 0.0) / fig.dpi, "left"


def _fit_text(fig: Any, text: str, width: float, size: Any) -> str:
    """``text`` broken into lines that fit ``width`` inches at font ``size`` as ``fig`` draws
    them (measured): each of its own lines is left whole where it fits, else wrapped
    (:func:`bayespilot.plots._wrap`, mathtext spans kept whole) at the most characters that
    fit."""
    from matplotlib.text import Text

    from ..plots import _points

    pts = _points(size)

    def wide(s: str) -> float:
        t = Text(0, 0, s, fontsize=pts, figure=fig)
        return t.get_window_extent().width / fig.dpi

    lines = []
    for line in text.split("\n"):
        if wide(line) <= width:
            lines.append(line)
            continue
        # _wrap guesses 0.58 em a character, more than most: from wider down until it fits
        w = 1.4 * width
        wrapped = _wrap(line, w, pts)
        while w > 0.3 * width and wide(wrapped) > width:
            w *= 0.9
            wrapped = _wrap(line, w, pts)
        lines.append(wrapped)
    return "\n".join(lines)


def _readable_log_axis(ax: Any, which: str) -> None:
    """Label the log ``which`` ("x" or "y") axis of ``ax`` with plain numbers, at 1, 2 and 5
    times each power of ten where it spans under three decades (matplotlib labels only the
    decades: two labels on most of the report's axes), else at the decades."""
    from matplotlib import ticker

    lo, hi = sorted(ax.get_xlim() if which == "x" else ax.get_ylim())
    axis = ax.xaxis if which == "x" else ax.yaxis
    if not (lo > 0 and math.isfinite(hi)):
        return
    subs = (1.0, 2.0, 5.0) if math.log10(hi / lo) < 3 else (1.0,)
    axis.set_major_locator(ticker.LogLocator(base=10, subs=subs))
    axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(ticker.NullFormatter())


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


def _read_from_json(result: Any) -> str | None:
    """Where a result read back from JSON came from, in words ("diagnosis.json", "a dict");
    None for one ``diagnose`` returned (it has its signals)."""
    where = getattr(result, "arrays", {}).get("from_json")
    if not where:
        return None
    return "a dict" if where is True else str(where)


def _no_signals(result: Any, what: str) -> str:
    """The message of a figure that needs the signals a result file does not keep: ``what``
    (the figure) cannot be drawn from this result, read from JSON."""
    return (f"No {what}: this diagnosis was read from JSON ({_read_from_json(result)}), which "
            f"keeps no signals: re-run diagnose (or draw it from the DiagnosisResult diagnose "
            f"returns).")


def _no_describing_function(result: DiagnosisResult) -> str:
    """Why a result has no describing function, in a sentence (for the figure and the report)."""
    arr = result.arrays
    if _read_from_json(result) is not None:  # (the forcing was known: the file keeps no signals)
        return _no_signals(result, "describing function")
    if arr.get("forcing_frequencies") is None:
        why = "the recording's forcing functions are unknown"
    else:
        why = ("the record is not whole periods of the forcing functions, or one of them is "
               "zero throughout")
    n, dt = np.size(arr.get("residual", ())), (result.settings or {}).get("dt")
    length = f" (this record: {n * dt:g} s)" if n and dt else ""
    return (f"No describing function: {why}{length}. The two-input estimate needs both "
            f"forcing functions over whole periods of the record (81.92 s for the paper's).")


def _notes_html(notes: Sequence[tuple[str, str]]) -> str:
    """The evidence notes (the EvidenceWarnings a diagnosis kept in ``evidence_notes``) as a
    section of the page: ``(run, note)`` pairs, ``run`` "" for a single run; "" without any."""
    if not notes:
        return ""
    items = "".join(f"<li>{f'<b>{html.escape(run)}</b>: ' if run else ''}{html.escape(note)}"
                    f"</li>" for run, note in notes)
    return ("<h2>Notes on the evidence</h2><p>What the diagnosis could not use, or read with "
            f"an assumption (its EvidenceWarnings):</p><ul>{items}</ul>")


def plot_frequency_response(result: DiagnosisResult, axes: Any = None, *,
                            title: bool | str = True,
                            figsize: tuple[float, float] | None = None) -> Figure:
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
    title : bool or str, optional
        True (default): a new figure's title, "Describing functions at the
        forcing frequencies" (none on given axes); False: no title, the
        panels taking its room; a str: that text as the figure's title.
        The two columns' headings (visual, motion channel) stay: they name
        the panels.
    figsize : (float, float), optional
        Width and height (in) of a new figure, as given (default 7.5 x 6,
        one short panel without a describing function); not with ``axes``.

    Returns
    -------
    matplotlib.figure.Figure
        The figure of the axes.  Without a describing function (forcing
        functions unknown, not whole periods of the record, or one zero
        throughout; a result read from JSON, which keeps no signals) a new
        figure is one short panel saying so; on given axes the first says so
        and the others are blank.

    Raises
    ------
    ValueError
        ``figsize`` given with ``axes``, or not two positive numbers.
    """
    from matplotlib.lines import Line2D

    _no_figsize_with(figsize, axes)
    text = _title_text(title, "Describing functions at the forcing frequencies")
    arr = result.arrays
    if "df_data" not in arr:
        msg = _no_describing_function(result)
        if axes is None:
            fig, ax = _subplots(figsize=(PAGE_WIDTH, 1.6), given=figsize)
            rest = []
        else:
            flat = list(np.ravel(axes))
            fig, ax, rest = flat[0].figure, flat[0], flat[1:]
        for a in (ax, *rest):
            a.set_axis_off()
        ax.text(0.5, 0.5, msg, ha="center", va="center", transform=ax.transAxes, wrap=True)
        if isinstance(title, str):  # (the caller's title; True, numpy's too: none, as before)
            _fig_title(fig, text)
        return fig
    created = axes is None
    if created:
        fig, axes = _subplots(2, 2, figsize=(PAGE_WIDTH, 6.0), sharex=True, given=figsize)
    else:
        fig = np.ravel(axes)[0].figure
    axes = np.asarray(axes).reshape(2, 2)
    d, mb = arr["df_data"], arr["df_model"]
    ma = arr.get("df_after")
    w = d["omega"]
    data_kw = dict(ls="none", marker="o", ms=4, color="k")
    base_kw = dict(ls="none", marker="s", ms=6, mfc="none", mec="C0", mew=1.2)
    after_kw = dict(ls="none", marker="^", ms=6, mfc="none", mec="C3", mew=1.2)
    for col, key, heading, unit in (  # (not `title`: the caller's is read below)
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
        ax_m.set_title(heading, fontsize="medium")
        ax_m.set_ylabel(f"magnitude ({unit})")
        ax_p.set_ylabel("phase (deg)")
        ax_p.set_xlabel(r"$\omega$ (rad/s)")
        ax_m.grid(True, which="both", alpha=0.3)
        ax_p.grid(True, which="both", alpha=0.3)
        _readable_log_axis(ax_m, "y")
        for a in (ax_m, ax_p):
            _readable_log_axis(a, "x")
    handles = [Line2D([], [], **data_kw, label="data (two-input multisine estimate)"),
               Line2D([], [], **base_kw, label="base model (same estimate, model output)")]
    if ma is not None:
        handles.append(Line2D([], [], **after_kw, label=f"with {result.physics}"))
    if created:
        fig.legend(handles=handles, loc="outside lower center",
                   ncols=_columns(handles, fig, 2, figsize), fontsize="small", frameon=False)
    else:
        axes[0, 0].legend(handles=handles, fontsize="small")
    # (given axes: a title only when the caller names one; numpy's True is True)
    if created or isinstance(title, str):
        _fig_title(fig, text)
    return fig


def plot_residuals(result: DiagnosisResult, axes: Any = None, *, recording: Any = None,
                   title: bool | str = True, figsize: tuple[float, float] | None = None
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
    title : bool or str, optional
        A str: that text as the figure's title; True (default) or False:
        none (the figure has no title of its own, as before).  The four
        panels' headings stay: they name the panels.
    figsize : (float, float), optional
        Width and height (in) of a new figure, as given (default 7.5 x 6.5);
        not with ``axes``.

    Returns
    -------
    matplotlib.figure.Figure
        The figure of the axes; a conditioned panel without its statistic is
        hidden.

    Raises
    ------
    ValueError
        Neither ``result.settings["dt"]`` nor ``recording`` gives the
        sample interval; the result was read from JSON, which keeps no
        signals (re-run diagnose); ``figsize`` given with ``axes``, or not
        two positive numbers.
    """
    from matplotlib.lines import Line2D

    _no_figsize_with(figsize, axes)
    text = _title_text(title, None)
    arr = result.arrays
    if "residual" not in arr:
        if _read_from_json(result) is not None:
            raise ValueError(_no_signals(result, "residual figure"))
        raise ValueError("the diagnosis has no residual (result.arrays['residual']): draw the "
                         "figure from the DiagnosisResult diagnose returns")
    created = axes is None
    if created:
        fig, axes = _subplots(2, 2, figsize=(PAGE_WIDTH, 6.5), given=figsize)
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
    # before and after differ by line style too (solid, dashed): told apart in greyscale
    for x, lab, st in ((before, "base model", "C0-"), (after, f"with {result.physics}", "C3--")):
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
                              label=rf"above $\omega_\mathrm{{c}}$ = {omega_c:g} rad/s: not "
                                    "in the decision"))
    ax.set_xlabel(r"$\omega$ (rad/s)")
    ax.set_ylabel("one-sided PSD (rad$^2$/(rad/s))")
    ax.set_title("residual spectrum", fontsize="medium")
    _readable_log_axis(ax, "x")
    ax = axes[0, 1]
    nseg = 8
    var = [(x, lab, st, [np.var(s) for s in np.array_split(x, nseg)])
           for x, lab, st in ((before, "base model", "C0o-"),
                              (after, f"with {result.physics}", "C3s--")) if x is not None]
    # the variance in a power of ten named in the label, not matplotlib's floating offset
    top = max((max(v) for *_, v in var), default=0.0)
    e = int(math.floor(math.log10(top))) if top > 0 and math.isfinite(top) else 0
    e = 0 if -1 <= e <= 2 else e
    for x, lab, st, v in var:
        ax.plot(np.arange(nseg) + 1, np.asarray(v) / 10.0 ** e, st, label=lab)
    ax.set_xlabel(f"eighth of the run (after the first {result.settings['skip_seconds']:g} s)")
    ax.set_ylabel("residual variance (" + (f"$10^{{{e}}}$ " if e else "") + "rad$^2$)")
    ax.set_title("residual over the run", fontsize="medium")
    for ax, key, lab, what, sign in (
            (axes[1, 0], "amp_canal", r"$|i(t - \tau_\mathrm{m})|$ (IPUT)",
             r"$|i(t - \tau_\mathrm{m})|$", r"$i(t - \tau_\mathrm{m})$"),
            (axes[1, 1], "amp_control", "$|u|$ (rad)", "$|u|$", "$u$")):
        b = arr.get(key)
        if b is None:
            ax.set_visible(False)
            continue
        ax.plot(b["centre"], b["mean"], "C0o-", label="base model")  # (as in the spectrum)
        if after is not None:
            from .locate import _binned

            # same conditioning variable, the after-residual
            src = arr["canal_delayed"] if key == "amp_canal" else arr["u_after_cond"]
            bb = _binned(after, src, edges_q=(0.0, 0.2, 0.4, 0.6, 0.8, 0.9, 1.0)
                         if key == "amp_canal" else (0.0, 0.5, 0.8, 0.95, 0.99, 1.0))
            ax.plot(bb["centre"], bb["mean"], "C3s--", label=f"with {result.physics}")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_xlabel(lab)
        # (locate._binned: the residual times the sign of the variable it is binned by)
        ax.set_ylabel(f"mean of residual × sign({sign})\n(rad)")
        ax.set_title(f"residual conditioned on {what}", fontsize="medium")
    if created:  # one legend for the four panels, under them
        lines = [Line2D([], [], color="C0", ls="-", marker="o", label="base model")]
        if after is not None:
            lines.append(Line2D([], [], color="C3", ls="--", marker="s",
                                label=f"with {result.physics}"))
        handles = lines + [h for h in handles if h.get_label() not in
                           ("base model", f"with {result.physics}")]
        fig.legend(handles=handles, loc="outside lower center",
                   ncols=_columns(handles, fig, 3, figsize), fontsize="small", frameon=False)
    else:
        axes[0, 0].legend(handles=handles, fontsize="small", loc="lower left")
        axes[0, 1].legend(fontsize="small")
    _fig_title(fig, text)
    return fig


def plot_evidence(result: DiagnosisResult, ax: Any = None, *, title: bool | str = True,
                  legend: bool = True, figsize: tuple[float, float] | None = None) -> Figure:
    """-log10 of each located statistic's bootstrap p-value.

    Parameters
    ----------
    result : DiagnosisResult
        A single-run diagnosis: its located evidence (``result.where``) and
        the bootstrap's size.
    ax : matplotlib Axes, optional
        Default: a new figure.
    title : bool or str, optional
        True (default): "Where the data and the base model differ"; False:
        no title, the axes taking its room; a str: that text.  A title is
        wrapped to the width over the axes and their labels.
    legend : bool, optional
        False: no legend (the lines and the red bars explained in the
        caption instead).
    figsize : (float, float), optional
        Width and height (in) of a new figure, as given (default 7.5 x 4.6);
        not with ``ax``.

    Returns
    -------
    matplotlib.figure.Figure
        One bar per statistic with a finite value, named in words
        (:data:`EVIDENCE_LABELS`; red and hatched at p <= 0.05), "n/a"
        where its p-value is not a finite positive number, p = 0.05 dashed
        and the smallest p the bootstrap of B replicates can give,
        1 / (B + 1), as a wide grey line (both in the legend; at B = 19 they
        are the same).  Without a bootstrap (``n_bootstrap=0``, or skipped)
        the axes say "no bootstrap p-values" and draw no bars
        (:func:`write_report` then leaves the figure out).  The legend is
        under the axes: on a new figure the figure's, on given axes the
        axes' own, under their x label (the figure's layout, when it has
        one, makes room; beside the axes it took the room of a column-wide
        figure's axes).  The x label is wrapped to the width under the axes
        and their labels.

    Raises
    ------
    ValueError
        ``figsize`` given with ``ax``, or not two positive numbers.
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    _no_figsize_with(figsize, ax)
    text = _title_text(title, "Where the data and the base model differ")
    created = ax is None
    if created:
        fig, ax = _subplots(figsize=(PAGE_WIDTH, 4.6), given=figsize)
    else:
        fig = ax.figure
    keys = [k for k, e in result.where.items() if math.isfinite(e.value)]
    p = [result.where[k].p_value for k in keys]
    ok = [math.isfinite(x) and x > 0 for x in p]
    B = int((result.settings.get("bootstrap") or {}).get("replicates", 0) or 0)
    ax.set_yticks(range(len(keys)))
    ax.set_yticklabels([_evidence_label(k) for k in keys], fontsize="small")
    ax.set_ylim(len(keys) - 0.5, -0.5)
    if not any(ok):
        why = (result.settings.get("bootstrap") or {}).get("skipped")
        ax.text(0.5, 0.5, "no bootstrap p-values: the located statistics were not tested\n"
                + (f"({why})" if why else "(diagnose(n_bootstrap=0), --bootstrap 0)"),
                ha="center", va="center", transform=ax.transAxes, wrap=True,
                bbox=dict(fc="white", ec="0.6"))
        ax.set_xticks([])
        _label_axes(ax, text, r"$-\log_{10} p$ (no parametric bootstrap)")
        return fig
    val = [-math.log10(x) if good else 0.0 for x, good in zip(p, ok)]
    crit = -math.log10(0.05)
    # p <= 0.05: red and hatched (told apart in greyscale too)
    low = [good and x <= 0.05 for x, good in zip(p, ok)]
    bars = ax.barh(range(len(keys)), val, color=["C3" if s else "C0" for s in low])
    for bar, s in zip(bars, low):
        if s:
            bar.set(hatch="///", edgecolor="w", linewidth=0)
    for i, good in enumerate(ok):
        if not good:
            ax.text(0.02, i, "n/a", va="center", fontsize="small", color="0.3",
                    transform=ax.get_yaxis_transform())
    handles = [Patch(fc="C3", hatch="///", ec="w", lw=0, label="p ≤ 0.05")] if any(low) else []
    if B:
        floor = math.log10(B + 1)
        ax.axvline(floor, color="0.6", lw=5, alpha=0.5, solid_capstyle="butt")
        handles.append(Line2D([], [], color="0.6", lw=5, alpha=0.5,
                              label=f"smallest possible p, 1/(B + 1) = {1 / (B + 1):.2g}"))
    ax.axvline(crit, color="k", ls="--", lw=1)
    handles.insert(0, Line2D([], [], color="k", ls="--", lw=1, label="p = 0.05"))
    ax.set_xlim(0, 1.1 * max(max(val), crit, math.log10(B + 1) if B else 0.0))
    _label_axes(ax, text, rf"$-\log_{{10}}\,p$ (parametric bootstrap, B = {B})")
    if not legend:
        return fig
    if created:
        fig.legend(handles=handles, loc="outside lower center",
                   ncols=_columns(handles, fig, len(handles), figsize), fontsize="small",
                   frameon=False)
    else:  # under the x label, as on a new figure (beside the axes it took a column's room)
        _legend_under(ax, handles)
    return fig


def _label_axes(ax: Any, title: str | None, xlabel: str, size: Any = "medium") -> None:
    """Set ``ax``'s ``title`` (font ``size``; none for None) and ``xlabel``, each wrapped to
    the width over and under the axes and their tick labels, centred or aligned with one end
    of the axes (:func:`_text_span`): a figure of a column's width, or the caller's narrow
    axes, does not cut them."""
    ax.set_title("")
    ax.set_xlabel("")
    span, loc = _text_span(ax)
    fig = ax.figure
    if title:
        ax.set_title(_fit_text(fig, title, span, size), fontsize=size, loc=loc)
    ax.set_xlabel(_fit_text(fig, xlabel, span, _pyplot().rcParams["axes.labelsize"]), loc=loc)


def _legend_under(ax: Any, handles: Sequence[Any] | None = None, ncols: int | None = None,
                  title: str | None = None) -> Any:
    """The legend of ``handles`` (default: the axes' labelled artists) under ``ax``, below
    its x label (clear of the data; a figure's constrained layout makes room), a fixed
    distance below the axes so that a new layout keeps it there (one placed at a fraction
    of the axes' height moved with it, and a column-wide figure's layout did not settle:
    the legend ended outside the figure); centred, or aligned with one end of the axes
    (:func:`_text_span`), in ``ncols`` columns or, by default, as many as fit."""
    from matplotlib.transforms import ScaledTranslation

    from ..plots import _legend_columns

    fig = ax.figure
    if handles is None:
        handles, _ = ax.get_legend_handles_labels()
    width, loc = _text_span(ax)  # (also lays the figure out: the x label's place)
    below = ax.xaxis.get_tightbbox()
    drop = 0.05 if below is None else max(0.0, ax.get_window_extent().y0 - below.y0) / fig.dpi
    trans = ax.transAxes + ScaledTranslation(0.0, -(drop + 0.03), fig.dpi_scale_trans)
    labels = [h.get_label() for h in handles]
    return ax.legend(handles=handles, loc=f"upper {loc}",
                     bbox_to_anchor=({"center": 0.5, "right": 1.0, "left": 0.0}[loc], 0.0),
                     bbox_transform=trans, borderaxespad=0.0,
                     ncols=ncols or _legend_columns(labels, width, len(labels)),
                     fontsize="small", frameon=False, title=title, title_fontsize="small")


def _figure_and_axes(ax: Any = None, figsize=(PAGE_WIDTH, 3.6), given: Any = None):
    """``(figure, axes)``: the given axes and their figure, or a new (constrained-layout)
    figure of ``figsize`` (at most a page wide), or of ``given`` (the caller's, as it is)."""
    _no_figsize_with(given, ax)
    if ax is None:
        return _subplots(figsize=figsize, given=given)
    return ax.figure, ax


def _p_parts(p: float) -> tuple[str, int | None]:
    """A p-value's mantissa and power of ten as written (``("3.4", -9)``; ``("0.012", None)``
    from 0.001 up; ``("<", -300)`` for a p that underflowed to 0)."""
    if p == 0:
        return "<", -300
    if p >= 1e-3:
        return f"{p:.2g}", None
    m, e = f"{p:.1e}".split("e")
    return m, int(e)


def _p_text(p: float) -> str:
    r"""A p-value as the figures write it (mathtext): 0.073, $3.4\times10^{-9}$,
    $<10^{-300}$ (one that underflowed to 0); "—" when it is not a number."""
    if p is None or not math.isfinite(p):
        return "—"
    m, e = _p_parts(p)
    if e is None:
        return m
    return rf"$<10^{{{e}}}$" if m == "<" else rf"${m}\times10^{{{e}}}$"


def _p_html(p: Any) -> str:
    """A p-value as the report's tables write it: 0.073, 3.4&times;10<sup>-9</sup>."""
    try:
        p = float(p)
    except (TypeError, ValueError):
        return "—"
    if not math.isfinite(p):
        return "—"
    m, e = _p_parts(p)
    if e is None:
        return _number(p, ".3g")
    return f"&lt;10<sup>{e}</sup>" if m == "<" else f"{m}&times;10<sup>{e}</sup>"


def plot_candidates(result: DiagnosisResult | PooledDiagnosisResult, ax: Any = None, *,
                    title: bool | str = True, caption: bool = True,
                    figsize: tuple[float, float] | None = None) -> Figure:
    """Fit improvement of each candidate on the decision likelihood, with the test's threshold.

    Parameters
    ----------
    result : DiagnosisResult or PooledDiagnosisResult
        A diagnosis, single-run or pooled: its testable candidates
        (``result.ranking``) and the level per candidate.
    ax : matplotlib Axes, optional
        Default: a new figure.
    title : bool or str, optional
        True (default): "Candidates (decision: <the decision>)"; False: no
        title, the axes taking its room; a str: that text.
    caption : bool, optional
        True (default): under the x label's formula, the key "black mark:
        what the test needs at the level per candidate (<level>); red,
        hatched: justified"; False: the formula only (the key then belongs
        in the paper's caption).  Both are wrapped to the width under the
        axes and their labels.
    figsize : (float, float), optional
        Width and height (in) of a new figure, as given (default 7.5 x 3.6);
        not with ``ax``.

    Returns
    -------
    matplotlib.figure.Figure
        One bar per testable candidate, d(-ln L) on a linear axis (red and
        hatched: justified), its value and p-value (0.073, 3.4 x 10^-9) in a
        column at the right, and for an entry with new
        parameters a black mark at the d(-ln L) its test needs at the level
        per candidate: half the chi2(df) quantile at the level, or for a
        one-parameter boundary null (chi-bar-squared: the p-value halved)
        half the chi2(1) quantile at twice the level; times the bootstrap's
        scale where the test was calibrated and the scale is above 1.
        The marks are the axes' only lines.

    Raises
    ------
    ValueError
        ``figsize`` given with ``ax``, or not two positive numbers.
    """
    from .decide import critical_value

    fig, ax = _figure_and_axes(ax, given=figsize)
    text = _title_text(title, f"Candidates (decision: {result.physics})")
    rows = [c for c in result.ranking if c.testable]
    level = result.settings["level_per_candidate"]
    names = [c.physics for c in rows]
    d = [c.delta_neg_log_lik for c in rows]
    bars = ax.barh(range(len(rows)), d, color=["C3" if c.justified else "C0" for c in rows])
    for bar, c in zip(bars, rows):
        if c.justified:  # (hatched: told apart in greyscale too)
            bar.set(hatch="///", edgecolor="w", linewidth=0)
    crits = []
    for i, c in enumerate(rows):
        if c.df > 0:
            # the threshold of the test that decided (decide.lr_p_value, calibrate.Calibration)
            crit = 0.5 * critical_value(c.df, _boundary_null(c), level)
            if c.calibration is not None:
                crit *= max(1.0, c.calibration.scale)
            crits.append(crit)
            ax.plot([crit, crit], [i - 0.4, i + 0.4], "k-", lw=2)
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels(names, fontsize="small")
    ax.set_ylim(len(rows) - 0.5, -0.5)
    # a linear axis (a symlog one drew 1.06 and 3.83 close together): the values are written
    # in the column at the right, so a bar beside a censored fit's large gain is still read
    finite = [x for x in d if math.isfinite(x)]
    top = max([0.0, *finite, *crits])
    ax.set_xlim(min([0.0, *finite]) * 1.05, 1.05 * top if top > 0 else 1.0)
    ax.grid(True, axis="x", alpha=0.3)
    ax.set_axisbelow(True)
    # the values and p-values as a column at the right, clear of the bars and the marks
    right = ax.secondary_yaxis("right")
    right.set_yticks(range(len(rows)))
    # (a censored fit's gain of thousands as 1234, not 1.23e+03)
    right.set_yticklabels([rf"$\Delta$ = {_number(x, _delta_format(x))}, "
                           f"p = {_p_text(c.p_value)}" for x, c in zip(d, rows)], fontsize="small")
    right.tick_params(length=0)
    # (two spans, so that a narrow axes' label breaks between them)
    xlabel = r"$\Delta(-\ln L) = -\ln L_\mathrm{base}$ $-\,(-\ln L_\mathrm{extension})$"
    if caption:
        xlabel += ("\nblack mark: what the test needs at the level per candidate "
                   f"({level:.2g}); red, hatched: justified")
    _label_axes(ax, text, xlabel)
    return fig


def _boundary_null(c: Any) -> bool:
    """Whether candidate ``c``'s test had the chi-bar-squared reference of a one-parameter
    boundary null: as its test recorded it (``c.boundary_null``, kept in its result file, so
    also for a file of another session's own entry, not registered here; a file written
    before the field is read from how its test was made, ``reason``, by
    :meth:`CandidateResult.from_dict`), or, for a result made without it, as its catalogue
    entry says."""
    from .catalogue import get_extension

    if c.df != 1:
        return False
    recorded = getattr(c, "boundary_null", None)
    if recorded is not None:  # as the test recorded it, either way
        return bool(recorded)
    try:
        return bool(get_extension(c.physics).boundary_null)
    except ValueError:
        return False


def plot_batch(diagnoses: Sequence[tuple[str, Mapping[str, Any]]], ax: Any = None, *,
               title: bool | str = True, figsize: tuple[float, float] | None = None) -> Figure:
    """Every candidate's p-value in every diagnosis of a batch, at a glance.

    Parameters
    ----------
    diagnoses : sequence of (str, dict)
        ``(key, diagnosis)`` with ``diagnosis`` as ``DiagnosisResult.to_dict()``
        (or the pooled one) writes it.
    ax : matplotlib Axes, optional
        Default: a new figure, a page (7.5 in) wide, at least 3.6 in tall
        (its colour bar's label whole) and 0.28 in more per diagnosis, up
        to a page's height (9.5 in: 27 diagnoses); more diagnoses share it,
        every k-th named where their rows are too narrow for each name.
    title : bool or str, optional
        True (default): "<n> diagnoses: every candidate's p-value" and the
        key (dot, box, grey) under it; False: none, the axes taking its
        room (the key then belongs in the caption); a str: that text.
    figsize : (float, float), optional
        Width and height (in) of a new figure, as given; not with ``ax``.

    Returns
    -------
    matplotlib.figure.Figure
        One row per diagnosis, one column per catalogue entry (the built-in
        ones, then any other a diagnosis tested, in the order first met: an
        entry of one's own, registered or not), coloured by
        -log10 p up to 6 (where a p is below 1e-6, an arrow on the colour bar
        says the scale is capped there; grey: not
        testable on that recording); a dot where p is below the decision's
        level per candidate (the white line on the colour bar), a black box
        with a white edge (seen on dark cells and light ones) around the
        chosen extension, the decision at the left.

    Raises
    ------
    ValueError
        ``figsize`` given with ``ax``, or not two positive numbers.
    """
    from matplotlib import patheffects

    from ..plots import PAGE_HEIGHT
    from .catalogue import NAMES

    plt = _pyplot()
    n = len(diagnoses)
    names = list(NAMES)  # then the entries of one's own the diagnoses tested
    for _, d in diagnoses:
        names += [c["physics"] for c in d["ranking"] if c["physics"] not in names]
    _no_figsize_with(figsize, ax)
    if ax is None:
        # at most a page wide (_subplots), as tall as the diagnoses need up to a page
        fig, ax = _subplots(figsize=(PAGE_WIDTH, min(max(3.6, 1.9 + 0.28 * n), PAGE_HEIGHT)),
                            tall=True, given=figsize)
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
            # black, with a white edge either side: seen on viridis' dark cells too
            ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, ec="k", lw=2,
                                       path_effects=[patheffects.withStroke(linewidth=4.5,
                                                                            foreground="w")]))
    cmap = plt.get_cmap("viridis").with_extremes(bad="0.85")
    im = ax.imshow(np.ma.masked_invalid(z), aspect="auto", cmap=cmap, vmin=0, vmax=6,
                   interpolation="nearest")
    capped = bool(np.any(z[np.isfinite(z)] > 6))
    # a bar about 0.15 in wide however tall the axes (matplotlib's default aspect of 20 made
    # it 0.6 in wide beside 40 diagnoses)
    tall = fig.get_size_inches()[1] * ax.get_position().height
    cb = fig.colorbar(im, ax=ax, extend="max" if capped else "neither", pad=0.02,
                      aspect=max(20.0, tall / 0.15),
                      label=r"$-\log_{10} p$" + (r" (arrow: $p < 10^{-6}$)" if capped else ""))
    levels = [d["settings"]["level_per_candidate"] for _, d in diagnoses]
    if levels:  # the decision's level per candidate (the median, should they differ)
        cb.ax.axhline(-math.log10(float(np.median(levels))), color="w", lw=2)
    ax.set_xticks(range(len(names)))
    ax.set_xticklabels(names, rotation=30, ha="right", fontsize="small")
    # every k-th diagnosis named where a row is narrower than a name (0.14 in at 8.3 pt)
    row = ax.get_position().height * fig.get_figheight() / max(n, 1)
    k = max(1, math.ceil(0.14 / row)) if row > 0 else 1
    ax.set_yticks(range(0, n, k))
    ax.set_yticklabels([f"{key}: {d['physics']}" for key, d in list(diagnoses)[::k]],
                       fontsize="small")
    text = _title_text(title, f"{n} {'diagnosis' if n == 1 else 'diagnoses'}: every "
                              "candidate's p-value\ndot: below the level per candidate (white "
                              "line); box: chosen; grey: not testable")
    if text:
        ax.set_title(text, fontsize="medium")
    return fig


def _axes_row(n: int, axes: Any = None, height: float = 4.2, given: Any = None):
    """(figure, n axes in a row): new ones (constrained layout, at most a page wide, or of
    ``given``, the caller's figsize, as it is), or the given ones'."""
    _no_figsize_with(given, axes)
    if axes is None:
        fig, axes = _subplots(1, n, figsize=(4.8 * n, height), squeeze=False, given=given)
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


def _suptitle(fig, text: str) -> None:
    """The figure's title, broken into lines that fit its width (a one-panel figure is
    4.8 in wide: a catalogue name and a phrase did not fit on one line)."""
    from ..plots import _points, _wrap

    size = _points(_pyplot().rcParams["figure.titlesize"])
    fig.suptitle(_wrap(text, 0.95 * fig.get_figwidth(), size))


def _legend_below(ax, ncols: int = 2, title: str | None = None) -> None:
    """The axes' legend under them, clear of the data (constrained layout makes room), in
    one column under an axes narrower than 4 in; ``title``: the legend's (a panel's note
    when the figure is drawn without titles)."""
    width = ax.get_position().width * ax.figure.get_figwidth()
    _legend_under(ax, ncols=ncols if width >= 4.0 else 1, title=title)


def _panel_note(ax: Any, note: str, title: Any) -> str | None:
    """A panel's note (its draws, its scale c): the panel's title when the figure has titles
    (``title`` True or a str: None returned); without (False) ``note`` returned, for its
    legend's title (kept: the panel needs it), and the panel's title cleared."""
    if _title_text(title, "titled") is None:
        ax.set_title("")
        return note
    ax.set_title(note, fontsize="small")
    return None


def _mark_fit(ax, value: float, stderr: float, label: str) -> None:
    """A maximum-likelihood fit (red dashed line) and its ±1 standard error (a red-hatched
    span, unfilled, under everything: a filled one blended with an interval's shading into
    a colour no legend entry had)."""
    ax.axvline(value, color="C3", ls="--", lw=1, label=label)
    if math.isfinite(stderr):
        ax.axvspan(value - stderr, value + stderr, fill=False, hatch="///", edgecolor="C3",
                   alpha=0.5, lw=0, zorder=0, label="±1 s.e.")


def plot_posterior(result: DiagnosisResult, axes: Any = None, *, title: bool | str = True,
                   figsize: tuple[float, float] | None = None) -> Figure:
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
    title : bool or str, optional
        True (default): the figure's title "<extension>: posterior of its
        new parameters" and each panel's draws ("800 draws (converged)");
        False: no titles, the panels taking their room (each panel's draws
        become its legend's title); a str: that text as the figure's title.
    figsize : (float, float), optional
        Width and height (in) of a new figure, as given (default 4.8 in wide
        per panel, at most 7.5, by 4.2); not with ``axes``.

    Returns
    -------
    matplotlib.figure.Figure
        Each panel's x axis is the parameter in the paper's notation with
        its unit (the extended model's), its legend under the axes.

    Raises
    ------
    ValueError
        The diagnosis has no posterior (no extension chosen, or not sampled:
        :func:`~bayespilot.diagnose.sample_chosen`; a result read from JSON
        keeps only its summary, not the draws); ``figsize`` given with
        ``axes``, or not two positive numbers.
    """
    from ..plots import plot_marginal

    post, chosen = result.posterior, result.chosen
    if post is None or chosen is None:
        if _read_from_json(result) is not None:
            raise ValueError(f"No posterior to draw: this diagnosis was read from JSON "
                             f"({_read_from_json(result)}), which keeps the posterior's "
                             f"summary, not its draws: re-run diagnose and sample_chosen (or "
                             f"draw it from the DiagnosisResult they return)")
        raise ValueError("the diagnosis has no posterior: no extension was chosen, or its "
                         "posterior was not sampled (sample_chosen)")
    text = _title_text(title, f"{chosen.physics}: posterior of its new parameters")
    names = [n for n in chosen.params if n in post.parameter_names]
    fig, axes = _axes_row(len(names), axes, given=figsize)
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
        note = _panel_note(ax, f"{post.draws(n).size} draws ("
                           f"{'converged' if post.converged else 'not converged'})", title)
        _legend_below(ax, title=note)
    _fig_title(fig, text)
    return fig


def plot_profile(result: DiagnosisResult, axes: Any = None, *, title: bool | str = True,
                 figsize: tuple[float, float] | None = None) -> Figure:
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
    title : bool or str, optional
        True (default): the figure's title "<extension>: profile likelihood
        of its new parameters" and each panel's scale c ("c = 0.52: (own
        s.e. / test's s.e.)^2, at most 1"); False: no titles, the panels
        taking their room (each panel's c becomes its legend's title); a
        str: that text as the figure's title.
    figsize : (float, float), optional
        Width and height (in) of a new figure, as given (default 4.8 in wide
        per panel, at most 7.5, by 4.2); not with ``axes``.

    Returns
    -------
    matplotlib.figure.Figure
        Each panel's x axis is the parameter in the paper's notation with
        its unit, its legend under the axes.

    Raises
    ------
    ValueError
        No extension was chosen, or it has no profile intervals (a pooled
        diagnosis, ``diagnose(intervals=False)``); ``figsize`` given with
        ``axes``, or not two positive numbers.
    """
    chosen = result.chosen
    if chosen is None or not chosen.interval:
        raise ValueError("the diagnosis has no profile intervals (no extension chosen, a pooled "
                         "diagnosis, or diagnose(intervals=False))")
    text = _title_text(title, f"{chosen.physics}: profile likelihood of its new parameters")
    names = list(chosen.interval)
    fig, axes = _axes_row(len(names), axes, given=figsize)
    model = _units_model(chosen.physics, getattr(chosen, "model", None))
    for ax, n in zip(axes, names):
        iv = chosen.interval[n]
        ok = np.isfinite(iv.deviance)
        ax.plot(iv.values[ok], iv.deviance[ok], "o-", color="C0", ms=3, lw=1,
                label="scaled deviance (profile)")
        q = iv.quantile
        ax.axhline(q, color="0.4", ls=":", lw=1,
                   label=rf"$\chi^2_1$ {100 * iv.level:.0f} % quantile")
        ax.axvspan(iv.lower, iv.upper, color="C0", alpha=0.12, lw=0, zorder=0,
                   label=f"{100 * iv.level:.0f} % interval {iv}")
        ax.axvline(chosen.params[n], color="C3", ls="--", lw=1, label="reported fit")
        ax.set_ylim(-0.05 * q, 3 * q)
        ax.set_xlabel(parameter_label(model, n))
        # the deviance scaled as the test's standard errors ask (profile.py): c says by what
        ax.set_ylabel(r"scaled deviance $c \cdot 2\,\Delta(-\ln L)$")
        note = _panel_note(ax, rf"$c$ = {iv.scale:.2g}: (own s.e. / test's s.e.)$^2$, at "
                               "most 1", title)
        _legend_below(ax, title=note)
    _fig_title(fig, text)
    return fig


def plot_shared_posterior(post: SharedPosterior, axes: Any = None, *,
                          title: bool | str = True,
                          figsize: tuple[float, float] | None = None) -> Figure:
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
    title : bool or str, optional
        True (default): the figure's title "<extension>: posterior of the
        parameters shared by <n> runs"; False: none, the panels taking its
        room; a str: that text.
    figsize : (float, float), optional
        Width and height (in) of a new figure, as given (default 4.8 in wide
        per panel, at most 7.5, by 4.2); not with ``axes``.

    Returns
    -------
    matplotlib.figure.Figure
        Each panel's x axis is the parameter in the paper's notation with
        the unit its catalogue entry declares, its legend under the axes.

    Raises
    ------
    ValueError
        ``figsize`` given with ``axes``, or not two positive numbers.
    """
    from ..plots import _param_unit, _per_unit

    text = _title_text(title, f"{post.physics}: posterior of the parameters shared by "
                              f"{post.settings['n_runs']} runs")
    names = list(post.names)
    fig, axes = _axes_row(len(names), axes, given=figsize)
    model = _units_model(post.physics)
    for a, (ax, n) in enumerate(zip(axes, names)):
        g, m = post.grid[a], np.asarray(post.marginals[n]["density"])
        ax.plot(g, m, color="C0", lw=1.5, label="posterior (grid, Laplace)")
        lo, hi = post.marginals[n]["interval"]
        inside = (g >= lo) & (g <= hi)
        ax.fill_between(g[inside], m[inside], color="C0", alpha=0.2, lw=0, zorder=0,
                        label="central 90 %")
        _mark_fit(ax, post.ml[n], post.stderr.get(n, math.nan), "pooled ML fit")
        ax.set_xlabel(parameter_label(model, n))
        ax.set_ylabel("posterior density" + _per_unit(_param_unit(n, model)))
        _legend_below(ax)
    _fig_title(fig, text)
    return fig


#: The formats :func:`write_report` can write its figures in, besides the PNG it embeds.
FORMATS = PLOT_FORMATS


def _checked_formats(formats: str | Sequence[str]) -> tuple[str, ...]:
    """``formats`` as a tuple starting with "png" (the page embeds the PNGs), each once;
    ValueError for a name not in :data:`FORMATS` (or not a name at all)."""
    if isinstance(formats, str):
        formats = [formats]
    try:
        formats = tuple(dict.fromkeys(("png", *formats)))
    except TypeError:
        raise ValueError(f"formats must be names among {', '.join(FORMATS)}, got "
                         f"{formats!r}") from None
    bad = [f for f in formats if f not in FORMATS]
    if bad:
        raise ValueError(f"formats must be among {', '.join(FORMATS)}, got {bad[0]!r}")
    return formats


#: The file in a report's folder that lists the figure files the report wrote, each with
#: its SHA-256.  A later report removes a figure it does not write again (stale, of another
#: diagnosis) only when it is listed here and unchanged: a file of the user's that has a
#: figure's name (``paper/posterior.pdf``) is never removed.  A file of its own, not a key
#: of ``diagnosis.json``: that is the diagnosis (the result file ``--json`` writes), both
#: reports' result writers would have to know of their figures, and it is written after
#: them, while this list is kept up to date figure by figure.  Hidden: bookkeeping.
MANIFEST = ".bayespilot-report.json"

#: The name of every figure a report can write (``<name>.<format>`` in its folder): a
#: single run's (:func:`write_report`) and a pooled diagnosis's
#: (:meth:`~bayespilot.diagnose.pooled.PooledDiagnosisResult.report`).  The one list:
#: both reports' figures must be in it (:func:`_listed` refuses another name) and
#: ``bayespilot diagnose --report`` guards these files, so that no figure of a report is
#: written over a file the command reads for want of being listed there.
FIGURES = ("frequency_response", "residuals", "evidence", "candidates", "profile",
           "posterior", "runs")


def _listed(figures: Mapping[str, Any]) -> Mapping[str, Any]:
    """``figures`` (a report's, name -> how to draw it) once each name is in
    :data:`FIGURES`; ValueError, before anything is written, for one that is not (its file
    would escape ``bayespilot diagnose --report``'s overwrite guard)."""
    unknown = [name for name in figures if name not in FIGURES]
    if unknown:
        raise ValueError(f"figure(s) {', '.join(unknown)} not in FIGURES: add them there")
    return figures


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _is_figure_file(name: Any) -> bool:
    """Whether a manifest's entry is a plain figure file name (``<name>.<format>``, in the
    folder itself): an edited or damaged manifest cannot make a report remove anything
    else (``../x``, ``report.html``)."""
    return (isinstance(name, str) and name == Path(name).name and "/" not in name
            and "\\" not in name and not name.startswith(".")
            and Path(name).suffix[1:] in FORMATS)


def _earlier_figures(out: Path, figures: Mapping[str, Any]) -> dict[str, str]:
    """The figure files an earlier report in ``out`` wrote (file name -> SHA-256), which a
    report may remove: those its :data:`MANIFEST` lists; nothing when the manifest cannot
    be read.  A folder without one (new, or a report of a release before the manifest):
    only a PNG of one of ``figures`` whose bytes ``out/report.html`` embeds, a page of this
    package's; that image is provably an earlier report's figure, and the page that shows
    it is being replaced.  Its PDF and SVG copies, which no page embeds, are left."""
    try:
        files = json.loads((out / MANIFEST).read_text(encoding="utf-8"))["files"]
        return {n: h for n, h in files.items() if _is_figure_file(n) and isinstance(h, str)}
    except FileNotFoundError:
        pass
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}  # unreadable: nothing is provably ours
    try:
        page = (out / "report.html").read_text(encoding="utf-8", errors="replace")
    except OSError:
        return {}
    if "<title>bayespilot " not in page:
        return {}
    found = {}
    for name in figures:
        png = out / f"{name}.png"
        try:
            data = png.read_bytes()
        except OSError:
            continue
        if f'base64,{base64.b64encode(data).decode("ascii")}"' in page:
            found[png.name] = hashlib.sha256(data).hexdigest()
    return found


def _remove_if_unchanged(path: Path, digest: str) -> None:
    """Remove ``path`` if it is a file (not a link) whose SHA-256 is ``digest``: the figure
    an earlier report wrote, not a file put in its place since."""
    try:
        if path.is_symlink() or not path.is_file() or _digest(path) != digest:
            return
    except OSError:
        return
    path.unlink(missing_ok=True)


def _write_figures(figures: Mapping[str, Any], out: Path,
                   formats: Sequence[str]) -> dict[str, Path]:
    """Draw and save each of ``figures`` (name -> a function drawing it, or None for a figure
    with nothing to draw) as ``out/<name>.png`` and its other ``formats`` beside it; the
    files by name (``<name>``, ``<name>_pdf``, ..., and ``manifest``, :data:`MANIFEST`).

    A figure file an earlier report wrote and this one does not (a figure or format not
    drawn now, of another diagnosis) is removed, so the folder holds only this report's
    figures; only one the earlier report's :data:`MANIFEST` lists (or, without a manifest,
    one its page embeds: :func:`_earlier_figures`), and only if unchanged since.  Any other
    file of a figure's name is the user's and is left.  Each figure is written atomically
    (:func:`~bayespilot._figstyle.save_figure`), and the manifest is rewritten after each
    one, so that an interrupted report leaves a manifest that lists every file of ours.
    """
    earlier = _earlier_figures(out, figures)
    manifest = out / MANIFEST
    paths: dict[str, Path] = {}
    written: dict[str, str] = {}
    for name, draw in figures.items():
        if draw is None:
            continue
        png = out / f"{name}.png"
        paths[name] = _png(draw(), png, formats)
        for fmt in formats[1:]:
            paths[f"{name}_{fmt}"] = png.with_suffix(f".{fmt}")
        for fmt in formats:
            f = png.with_suffix(f".{fmt}")
            written[f.name] = _digest(f)
        _write_manifest(manifest, {**earlier, **written})
    for name, digest in earlier.items():
        if name not in written:
            _remove_if_unchanged(out / name, digest)
    paths["manifest"] = _write_manifest(manifest, written)
    return paths


def _write_manifest(path: Path, files: Mapping[str, str]) -> Path:
    """Write the :data:`MANIFEST` ``path``: ``files`` (file name -> SHA-256), atomically."""
    return write_text_atomic(path, dumps({"what": "the figure files a bayespilot report "
                                          "wrote here (a later report removes only these)",
                                          "files": dict(sorted(files.items()))}))


def _remove_summary_figures(out: Path) -> None:
    """Remove a batch's ``out/summary.<format>`` (each of :data:`FORMATS`), before its
    tables are rewritten: a write that then fails (a full disk) leaves tables without a
    figure, never beside one of other results (:func:`_write_summary_figure` writes the
    new one after the tables)."""
    for fmt in FORMATS:
        with suppress(FileNotFoundError):
            (out / f"summary.{fmt}").unlink()


def _write_summary_figure(draw: Any, out: Path, formats: Sequence[str],
                          dpi: int | None = None) -> None:
    """A batch's ``out/summary.<format>`` for each of ``formats`` (diagnose-batch's and
    fit-batch's): the figure ``draw()`` returns (``draw`` None: nothing to draw now), at
    ``dpi`` (default :data:`FIGURE_DPI`), closed even when saving fails; a summary figure of
    a format not asked for, or of nothing now, is removed (it showed other results)."""
    from contextlib import suppress

    for fmt in FORMATS:
        if fmt not in formats or draw is None:
            with suppress(FileNotFoundError):
                (out / f"summary.{fmt}").unlink()
    if draw is None:
        return
    fig = draw()
    try:
        for fmt in formats:
            save_figure(fig, out / f"summary.{fmt}", FIGURE_DPI if dpi is None else dpi)
    finally:
        _pyplot().close(fig)


def _png(fig, path: Path, formats: Sequence[str] = ("png",)) -> Path:
    """Save ``fig`` as the PNG ``path`` at :data:`FIGURE_DPI` (and in each other of
    ``formats`` beside it, of the same stem: fonts embedded as TrueType in a PDF, text kept
    as text in an SVG), close it, and return ``path``."""
    try:
        for fmt in dict.fromkeys(("png", *formats)):
            save_figure(fig, path.with_suffix(f".{fmt}"), FIGURE_DPI)
    finally:
        _pyplot().close(fig)
    return path


def _has_p_values(result: DiagnosisResult) -> bool:
    """Whether any located statistic has a bootstrap p-value to draw (:func:`plot_evidence`
    draws bars only then)."""
    return any(math.isfinite(e.value) and math.isfinite(e.p_value) and e.p_value > 0
               for e in result.where.values())


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


def _candidate_table(ranking: Sequence[Any], units: Mapping[str, str] | None = None) -> str:
    """The candidates' HTML table of a report (single-run or pooled): one row per candidate,
    a justified one bold; "—" where a number does not apply (a censored fit's Delta BIC);
    each parameter with its unit from ``units`` (none for "-" or an unknown one)."""
    units = units or {}

    def unit(k):
        u = units.get(k)
        return "" if not u or u == "-" else f" {html.escape(u)}"

    rows = []
    for c in ranking:
        if not c.testable:
            rows.append(f"<tr><td>{html.escape(c.physics)}</td><td colspan=5>not tested: "
                        f"{html.escape(c.reason)}</td></tr>")
            continue
        interval = getattr(c, "interval", None) or {}
        ps = ", ".join(f"{html.escape(k)} = {_number(v, '.4g')} &plusmn; "
                       f"{_number(c.stderr.get(k), '.2g')}{unit(k)}"
                       + (f" ({100 * interval[k].level:.0f} % profile interval "
                          f"{html.escape(str(interval[k]))})" if k in interval else "")
                       for k, v in c.params.items())
        if not ps and c.reason:  # no fit to show (control-saturation without flat tops)
            ps = html.escape(c.reason)
        bold = ' style="font-weight:bold"' if c.justified else ''  # a justified candidate: bold
        rows.append(f"<tr{bold}>"
                    f"<td>{html.escape(c.physics)}</td>"
                    f"<td>{_number(c.delta_neg_log_lik, '.2f')}</td>"
                    f"<td>{_p_html(c.p_value)}</td>"
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


#: The files of a report that describe one diagnosis as a whole (the page and its JSON):
#: removed when a report fails part-way (:func:`_whole_report`).
_REPORT_WHOLE = ("report.html", "diagnosis.json")


def _folder_state(out: Path) -> dict[str, tuple[int, int]]:
    """Each file in ``out`` (name -> inode, mtime in ns): an atomic write changes its entry
    (a new inode), a failed one leaves none behind."""
    try:
        with os.scandir(out) as entries:
            return {e.name: (e.inode(), e.stat(follow_symlinks=False).st_mtime_ns)
                    for e in entries}
    except OSError:
        return {}


@contextmanager
def _whole_report(out: Path) -> Iterator[set[str]]:
    """Within: write a report's files in ``out``, adding the name of each of
    :data:`_REPORT_WHOLE` written to the yielded set.

    A failure part-way (a full disk, an interrupt, a figure that cannot be drawn) after a
    file in ``out`` changed leaves the folder mixed: new figures beside the page and
    ``diagnosis.json`` of the earlier report.  So the earlier ``report.html`` and
    ``diagnosis.json`` (those not written by this report) are removed, and an OSError says
    that the report in ``out`` is incomplete (one line; its kind and errno kept).  A failure
    before anything changed leaves the earlier report whole, and the exception as it was.
    """
    before = _folder_state(out)
    written: set[str] = set()
    try:
        yield written
    except BaseException as exc:
        if _folder_state(out) == before:  # (nothing written: the earlier report is whole)
            raise
        for name in _REPORT_WHOLE:
            if name not in written:
                with suppress(OSError):
                    (out / name).unlink()
        if not isinstance(exc, OSError):
            raise
        reason = " ".join(str(exc.strerror or exc).split())
        raise OSError(exc.errno, f"{reason}; the report in {out} is incomplete, without "
                                 f"report.html: run again once it can be written",
                      exc.filename) from exc


def write_report(result: DiagnosisResult, directory: str | Path, *, recording: Any = None,
                 formats: Sequence[str] = ("png",), title: bool = True) -> dict[str, Path]:
    """Write the figures, ``report.html`` and ``diagnosis.json`` to ``directory``.

    Parameters
    ----------
    result : DiagnosisResult
        A single-run diagnosis (a pooled one writes its own report,
        :meth:`PooledDiagnosisResult.report`).
    directory : str or Path
        Created, with its parents, if missing; files of the same names in it
        are replaced.  A figure file an earlier report wrote there and this
        one does not is removed; any other file is left, also one of a
        figure's name (``posterior.pdf`` of the user's): see ``manifest``.
    recording : Recording, optional
        The recording diagnosed, for a result without its sample interval
        (:func:`plot_residuals`).
    formats : sequence of str, optional
        Each figure is written as a PNG (at :data:`FIGURE_DPI`, embedded in
        the page) and also, beside it, in each other format of these
        (:data:`FORMATS`: ``"pdf"``, ``"svg"``), for a paper.
    title : bool, optional
        True (default): each figure with its own title; False: the figures
        without titles (``title=False`` of each plot function: for a paper,
        whose captions say it); the page's headings and captions stay.

    Returns
    -------
    dict of str to Path
        The files written, by name: ``frequency_response``, ``residuals``,
        ``evidence`` and ``candidates`` (PNG), ``profile`` (PNG, when the
        chosen extension has profile intervals), ``posterior`` (PNG, when
        ``result.posterior`` is set), each figure's other formats as
        ``<name>_pdf`` and ``<name>_svg``, ``json`` (``diagnosis.json``,
        :meth:`DiagnosisResult.to_json`), ``html`` (``report.html``, the
        figures embedded, and under "Notes on the evidence" each of the
        diagnosis's EvidenceWarnings, ``settings["evidence_notes"]``) and ``manifest`` (:data:`MANIFEST`, the hidden
        list of the figure files written, with their SHA-256: a later report
        removes a stale figure only if this list has it and it is unchanged;
        in a folder without one, of a release before it, only a stale PNG
        that the old ``report.html`` embeds).  A figure that would be empty
        is not written (one an earlier report left is removed, as above) and
        the page says why in words: ``frequency_response`` without a
        describing function (a record that is not whole periods of the
        forcing), ``evidence`` without bootstrap p-values
        (``n_bootstrap=0``, or the bootstrap skipped).

        The figures are written first, each atomically (a temporary file,
        then renamed: an interrupt leaves the old file or the new one), then
        ``diagnosis.json``, then ``report.html``: a new page always comes
        with its own figures.  A failure part-way (a full disk) removes the
        earlier report's ``report.html`` and ``diagnosis.json``, so that no
        page or JSON of another diagnosis stays beside the new figures; a
        failure before any file changed leaves the earlier report whole.

    Raises
    ------
    OSError
        ``directory`` cannot be created or a file in it written; after a
        failure part-way its message ends by saying that the report in
        ``directory`` is incomplete (no ``report.html``).
    ValueError
        Neither ``result.settings["dt"]`` nor ``recording`` gives the sample
        interval (:func:`plot_residuals`; a result of ``diagnose`` has it), or
        ``formats`` names one not in :data:`FORMATS`.
    TypeError
        ``title`` is not True or False.
    """
    formats = _checked_formats(formats)
    if not isinstance(title, (bool, np.bool_)):
        raise TypeError(f"title must be True or False, got {title!r}")
    t = bool(title)
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    chosen = getattr(result, "chosen", None)
    post = getattr(result, "posterior", None)
    figures = {  # name: how to draw it, or None: it would be empty (not written)
        "frequency_response": (lambda: plot_frequency_response(result, title=t))
        if "df_data" in result.arrays else None,
        "residuals": lambda: plot_residuals(result, recording=recording, title=t),
        "evidence": (lambda: plot_evidence(result, title=t)) if _has_p_values(result) else None,
        "candidates": lambda: plot_candidates(result, title=t),
    }
    if chosen is not None and chosen.interval:
        figures["profile"] = lambda: plot_profile(result, title=t)
    if post is not None:
        figures["posterior"] = lambda: plot_posterior(result, title=t)
    if chosen is None or not chosen.interval:
        figures["profile"] = None  # (one left from an earlier report is removed)
    if post is None:
        figures["posterior"] = None
    with _whole_report(out) as written:
        paths = _write_report_files(result, out, figures, formats, post, written)
    return paths


def _write_report_files(result: DiagnosisResult, out: Path, figures: Mapping[str, Any],
                        formats: Sequence[str], post: Any, written: set[str]) -> dict[str, Path]:
    """The files of :func:`write_report` (``figures``: name -> how to draw it, or None),
    each name added to ``written`` once written (:func:`_whole_report`)."""
    chosen = getattr(result, "chosen", None)
    # no empty placeholder, nor a figure left from an earlier report; the figures first,
    # the page last (an interrupted report never has a new page beside old figures)
    paths = _write_figures(_listed(figures), out, formats)
    paths["json"] = out / "diagnosis.json"
    result.to_json(paths["json"])
    written.add(paths["json"].name)

    physics = html.escape(result.physics)
    after = f" and with {physics}" if chosen is not None else ""
    ev = "".join(f"<tr><td>{html.escape(k)}</td><td>{html.escape(e.description)}</td>"
                 f"<td>{_number(e.value, '.4g')}</td><td>{_number(e.p_value, '.3f')}</td></tr>"
                 for k, e in result.where.items() if math.isfinite(e.value))
    no_p = "" if "evidence" in paths else (
        "<p>No bootstrap p-values: the located statistics were not tested "
        "(diagnose(n_bootstrap=0), or the bootstrap was skipped), so there is no figure of "
        "them.</p>")
    if "frequency_response" in paths:
        freq = _img(paths["frequency_response"],
                    f"Describing functions u/e (visual) and u/theta_ddot_m (motion) at the "
                    f"forcing frequencies: the data's two-input estimate (dots), the same "
                    f"estimate from the base model's output{after}.")
    else:
        freq = f"<p>{html.escape(_no_describing_function(result))}</p>"
    from . import _base_over, _calibration_lines

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
    from .. import __version__

    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>{_STYLE}</style></head><body>
<h1>{title}</h1>
<p>Recording: {html.escape(str(result.source))}. Mismatch: <b>{_yes_no(result.mismatch)}</b>.
Base model: -ln L (Eq. 4) = {result.base['neg_log_lik']:.2f}{_base_over(result.base)}, VAF = {result.base['vaf']:.2f} %.
Decision at family-wise level alpha = {result.settings['alpha']:g}
({result.settings['level_per_candidate']:.2g} per candidate). Time {result.elapsed:.1f} s.</p>
{_notes_html([("", n) for n in (result.settings or {}).get("evidence_notes", ())])}
<h2>Candidates</h2>
{_candidate_table(result.ranking, result.units)}
{cal}
{_img(paths['candidates'], "Improvement of the decision likelihood by each candidate; the black "
      "mark is what its test needs, the p-values are at the right.")}
{bf_html}
<h2>Where</h2>
<table><tr><th>evidence</th><th>what</th><th>value</th><th>bootstrap p</th></tr>{ev}</table>
{no_p}
{_img(paths['evidence'], "-log10 of each located statistic's parametric-bootstrap p-value.")
 if "evidence" in paths else ""}
<h2>Frequency responses</h2>{freq}
<h2>Residuals before and after</h2>
{_img(paths['residuals'], f"Residual u - u_hat of the base model{after}: its spectrum ({band}), "
      "its variance over the run, and its mean times sign against the canal output and the "
      "control.")}
{f"<h2>Profile likelihood of the new parameters</h2>{_img(paths['profile'], 'Scaled deviance along each new parameter (twice the rise of -ln L times c = (standard error of the fit / standard error of the test)^2, at most 1, so that a quadratic profile gives the reported standard error), the level it must stay below, the interval and the reported fit.')}" if "profile" in paths else ""}
{f"<h2>Posterior of the extended model</h2>{_img(paths['posterior'], 'Marginal posterior of each new parameter with the maximum-likelihood fit and its standard error.')}" if post is not None else ""}
<pre>{html.escape(result.summary())}</pre>
<p>Report written by bayespilot {__version__}.</p>
</body></html>
"""
    paths["html"] = write_text_atomic(out / "report.html", page)
    written.add(paths["html"].name)
    return paths

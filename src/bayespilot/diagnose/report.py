"""Show a diagnosis: PNG figures, a self-contained HTML report and a JSON summary.

Every plotting function takes a result (a single-run
:class:`~bayespilot.diagnose.DiagnosisResult`; :func:`plot_candidates` also a pooled
one, :func:`plot_shared_posterior` a ``SharedPosterior``, :func:`plot_batch` the
diagnoses' dicts) and optional axes, and returns the figure (it never calls
``plt.show()``); :func:`write_report` writes them all.
"""

from __future__ import annotations

import base64
import html
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from .._files import write_text_atomic

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from . import DiagnosisResult
    from .pooled import PooledDiagnosisResult
    from .posterior import SharedPosterior

__all__ = ["plot_frequency_response", "plot_residuals", "plot_evidence", "plot_candidates",
           "plot_posterior", "plot_profile", "plot_shared_posterior", "plot_batch",
           "write_report"]


def _pyplot():
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "pdf", "svg", "ps", "cairo"):
        try:
            matplotlib.use("Agg")
        except Exception:  # a backend already in use elsewhere; plotting still works
            pass
    import matplotlib.pyplot as plt

    return plt


#: Length of a Welch segment of the residual spectrum, s (1024 samples at the paper's
#: 100 Hz): the spectrum's lowest frequency, 2 pi / 10.24 = 0.61 rad/s, is the same at
#: every sample rate (a fixed 1024 samples started it at 6.1 rad/s at 1 kHz).
WELCH_SECONDS = 10.24


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
    """Welch PSD of a residual in segments of :data:`WELCH_SECONDS` (at most the record),
    without the zero frequency: omega (rad/s) and the PSD."""
    from scipy import signal

    nperseg = max(1, min(int(round(WELCH_SECONDS * fs)), x.size))
    f, P = signal.welch(x, fs=fs, nperseg=nperseg)
    return 2 * np.pi * f[1:], P[1:]


def _align(phase: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Shift an unwrapped phase (deg) by whole turns to lie closest to ``ref``."""
    k = np.round(np.nanmedian(ref - phase) / 360.0)
    return phase + 360.0 * k


def plot_frequency_response(result: DiagnosisResult, axes: Any = None) -> Figure:
    """Visual and motion-channel describing functions: data, base model, extended model.

    Parameters
    ----------
    result : DiagnosisResult
        A single-run diagnosis: the describing functions at the forcing
        frequencies of the data and of the base model, and of the extended
        model when an extension was chosen (``result.arrays``).
    axes : array of matplotlib Axes, optional
        Four axes, taken as 2 x 2 (rows: magnitude, phase in deg; columns:
        visual H_v per rad of e, motion H_m per rad/s^2 of theta_ddot_m);
        default: a new figure.

    Returns
    -------
    matplotlib.figure.Figure
        The figure of the axes.  Without forcing functions over whole periods
        of the record the axes say so and show nothing else.
    """
    plt = _pyplot()
    arr = result.arrays
    if axes is None:
        fig, axes = plt.subplots(2, 2, figsize=(10, 6.5), sharex=True)
    else:
        fig = np.ravel(axes)[0].figure
    axes = np.asarray(axes).reshape(2, 2)
    if "df_data" not in arr:
        for ax in axes.ravel():
            ax.text(0.5, 0.5, "no describing function: the forcing functions are unknown,\n"
                    "not whole periods of the record, or one is zero throughout",
                    ha="center", va="center", transform=ax.transAxes)
        return fig
    d, mb = arr["df_data"], arr["df_model"]
    ma = arr.get("df_after")
    w = d["omega"]
    for col, key, label in ((0, "H_v", "visual H_v (per rad of e)"),
                            (1, "H_m", "motion H_m (per rad/s^2 of theta_ddot_m)")):
        ax_m, ax_p = axes[0, col], axes[1, col]
        ax_m.loglog(w, np.abs(d[key]), "ko", ms=4, label="data (two-input multisine estimate)")
        ax_m.loglog(w, np.abs(mb[key]), "C0-", label="base model")
        ph_d = np.degrees(np.unwrap(np.angle(d[key])))
        ax_p.semilogx(w, ph_d, "ko", ms=4)
        ax_p.semilogx(w, _align(np.degrees(np.unwrap(np.angle(mb[key]))), ph_d), "C0-")
        if ma is not None:
            ax_m.loglog(w, np.abs(ma[key]), "C3--", label=f"with {result.physics}")
            ax_p.semilogx(w, _align(np.degrees(np.unwrap(np.angle(ma[key]))), ph_d), "C3--")
        ax_m.set_title(label)
        ax_m.set_ylabel("magnitude")
        ax_p.set_ylabel("phase, deg")
        ax_p.set_xlabel("omega, rad/s")
        ax_m.grid(True, which="both", alpha=0.3)
        ax_p.grid(True, which="both", alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Describing functions at the forcing frequencies")
    fig.tight_layout()
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
        Four axes, taken as 2 x 2: the residual's PSD (Welch) with the
        forcing frequencies marked, its variance over eight segments of the
        run, and its mean times sign conditioned on |i(t - tau_m)| (IPUT) and
        on |u| (rad); default: a new figure.  The PSD is averaged over
        segments of :data:`WELCH_SECONDS` (10.24 s, at most the record), so
        its lowest frequency, 2 pi / 10.24 rad/s, is the same at every
        sample rate.
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
    plt = _pyplot()
    arr = result.arrays
    if axes is None:
        fig, axes = plt.subplots(2, 2, figsize=(10, 6.5))
    else:
        fig = np.ravel(axes)[0].figure
    axes = np.asarray(axes).reshape(2, 2)
    fs = 1.0 / _sample_interval(result, recording)
    skip = int(round(result.settings["skip_seconds"] * fs))
    before = arr["residual"][skip:]
    after = arr.get("after_residual")
    after = after[skip:] if after is not None else None
    ax = axes[0, 0]
    for x, lab, st in ((before, "base model", "C0-"), (after, f"with {result.physics}", "C3-")):
        if x is None:
            continue
        om, P = _residual_psd(np.asarray(x, float), fs)
        ax.loglog(om, P, st, lw=1, label=lab)
    ff = arr.get("forcing_frequencies")
    if ff is not None:
        for w in ff[0]:
            ax.axvline(w, color="0.7", lw=0.5, ls=":")
        for w in ff[1]:
            ax.axvline(w, color="0.85", lw=0.5, ls="--")
    ax.set_xlabel("omega, rad/s")
    ax.set_ylabel("residual PSD")
    ax.set_title("residual spectrum (dotted: target, dashed: disturbance)")
    ax.legend(fontsize=8)
    ax = axes[0, 1]
    nseg = 8
    for x, lab, st in ((before, "base model", "C0o-"), (after, f"with {result.physics}", "C3s-")):
        if x is None:
            continue
        v = [np.var(s) for s in np.array_split(x, nseg)]
        ax.plot(np.arange(nseg) + 1, v, st, label=lab)
    ax.set_xlabel("segment of the run")
    ax.set_ylabel("residual variance")
    ax.set_title("residual over the run")
    for ax, key, lab in ((axes[1, 0], "amp_canal", "|i(t - tau_m)|, IPUT"),
                         (axes[1, 1], "amp_control", "|u|, rad")):
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
        ax.set_ylabel("mean residual x sign")
        ax.set_title(f"residual conditioned on {lab.split(',')[0]}")
    axes[1, 0].legend(fontsize=8)
    fig.tight_layout()
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
        One bar per statistic with a finite value (red at -log10 p >= 1.3;
        0 where p is not a finite positive number, as without a bootstrap),
        p = 0.05 dashed and the smallest p the bootstrap can give,
        1 / (B + 1), dotted.
    """
    plt = _pyplot()
    if ax is None:
        fig, ax = plt.subplots(figsize=(8, 4.5))
    else:
        fig = ax.figure
    keys = [k for k, e in result.where.items() if math.isfinite(e.value)]
    p = [result.where[k].p_value for k in keys]
    val = [-math.log10(x) if math.isfinite(x) and x > 0 else 0.0 for x in p]
    ax.barh(range(len(keys)), val, color=["C3" if v >= 1.3 else "C0" for v in val])
    ax.set_yticks(range(len(keys)))
    ax.set_yticklabels(keys, fontsize=8)
    ax.invert_yaxis()
    B = result.settings["bootstrap"].get("replicates", 0)
    if B:
        ax.axvline(math.log10(B + 1), color="0.5", ls=":", lw=1)
    ax.axvline(-math.log10(0.05), color="k", ls="--", lw=0.8)
    ax.set_xlabel(f"-log10 p (parametric bootstrap, B = {B}; dashed: p = 0.05, dotted: "
                  f"smallest possible)")
    ax.set_title("Where the data and the base model differ")
    fig.tight_layout()
    return fig


def _figure_and_axes(ax: Any = None, figsize=(8, 4)):
    """``(figure, axes)``: the given axes and their figure, or a new figure of ``figsize``."""
    if ax is None:
        return _pyplot().subplots(figsize=figsize)
    return ax.figure, ax


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
        One bar per testable candidate, d(-ln L) on a symlog axis (red:
        justified), its p-value beside it, and for an entry with new
        parameters a black mark at the d(-ln L) its test needs at the level
        per candidate: half the chi2(df) quantile at the level, or for a
        one-parameter boundary null (chi-bar-squared: the p-value halved)
        half the chi2(1) quantile at twice the level; times the bootstrap's
        scale where the test was calibrated and the scale is above 1.
    """
    from scipy import stats

    from .catalogue import get_extension

    fig, ax = _figure_and_axes(ax)
    rows = [c for c in result.ranking if c.testable]
    level = result.settings["level_per_candidate"]
    names = [c.physics for c in rows]
    d = [c.delta_neg_log_lik for c in rows]
    ax.barh(range(len(rows)), d, color=["C3" if c.justified else "C0" for c in rows])
    for i, c in enumerate(rows):
        if c.df > 0:
            # the threshold of the test that decided (decide.lr_p_value, calibrate.Calibration)
            boundary = get_extension(c.physics).boundary_null and c.df == 1
            crit = 0.5 * stats.chi2.isf(2.0 * level if boundary else level, c.df)
            if c.calibration is not None:
                crit *= max(1.0, c.calibration.scale)
            ax.plot([crit, crit], [i - 0.4, i + 0.4], "k-", lw=2)
        p = "0" if c.p_value == 0 else f"{c.p_value:.2g}"
        ax.text(max(d[i], 0) * 1.02 + 0.1, i, f"p = {p}", va="center", fontsize=8)
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels(names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xscale("symlog", linthresh=1.0)
    ax.set_xlabel("-ln L(base) - -ln L(extension) (black: threshold of the test)")
    ax.set_title(f"Candidates (decision: {result.physics})")
    fig.tight_layout()
    return fig


def plot_batch(diagnoses: Sequence[tuple[str, Mapping[str, Any]]], ax: Any = None) -> Figure:
    """Every candidate's p-value in every diagnosis of a batch, at a glance.

    Parameters
    ----------
    diagnoses : sequence of (str, dict)
        ``(key, diagnosis)`` with ``diagnosis`` as ``DiagnosisResult.to_dict()``
        (or the pooled one) writes it.
    ax : matplotlib Axes, optional

    Returns
    -------
    matplotlib.figure.Figure
        One row per diagnosis, one column per catalogue entry, coloured by
        -log10 p (grey: not testable on that recording); a dot where p is
        below the decision's level per candidate, a box around the chosen
        extension, the decision at the right.
    """
    from .catalogue import NAMES

    plt = _pyplot()
    n = len(diagnoses)
    if ax is None:
        fig, ax = plt.subplots(figsize=(8.5, min(1.6 + 0.28 * n, 60.0)))
    else:
        fig = ax.figure
    z = np.full((n, len(NAMES)), np.nan)
    for i, (_, d) in enumerate(diagnoses):
        level = d["settings"]["level_per_candidate"]
        for c in d["ranking"]:
            p = c.get("p_value")
            if c["physics"] in NAMES and isinstance(p, (int, float)) and c.get("testable", True):
                j = NAMES.index(c["physics"])
                z[i, j] = -math.log10(max(p, 1e-16))
                if p < level:
                    ax.plot(j, i, "k.", ms=5)
        if d["physics"] in NAMES:
            j = NAMES.index(d["physics"])
            ax.add_patch(plt.Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, ec="k", lw=2))
    cmap = plt.get_cmap("viridis").with_extremes(bad="0.85")
    im = ax.imshow(np.ma.masked_invalid(z), aspect="auto", cmap=cmap, vmin=0, vmax=6,
                   interpolation="nearest")
    cb = fig.colorbar(im, ax=ax, label="-log10 p (dot: below the level; box: chosen)",
                      shrink=0.8)
    levels = [d["settings"]["level_per_candidate"] for _, d in diagnoses]
    if levels:  # the decision's level per candidate (the median, should they differ)
        cb.ax.axhline(-math.log10(float(np.median(levels))), color="w", lw=2)
    ax.set_xticks(range(len(NAMES)))
    ax.set_xticklabels(NAMES, rotation=30, ha="right", fontsize=8)
    ax.set_yticks(range(n))
    ax.set_yticklabels([f"{k}: {d['physics']}" for k, d in diagnoses], fontsize=7)
    ax.set_title(f"{n} diagnoses: every candidate's p-value")
    fig.tight_layout()
    return fig


def _axes_row(n: int, axes: Any = None):
    """(figure, n axes in a row): new ones, or the given ones'."""
    if axes is None:
        plt = _pyplot()
        fig, axes = plt.subplots(1, n, figsize=(4.5 * n, 3.4), squeeze=False)
        return fig, axes[0]
    axes = np.atleast_1d(axes)
    return axes[0].figure, axes


def _mark_fit(ax, value: float, stderr: float, label: str) -> None:
    """A maximum-likelihood fit and its +-1 standard error on a marginal's axes."""
    ax.axvline(value, color="C3", ls="--", lw=1, label=label)
    if math.isfinite(stderr):
        ax.axvspan(value - stderr, value + stderr, color="C3", alpha=0.12, label="+-1 s.e.")


def plot_posterior(result: DiagnosisResult, axes: Any = None) -> Figure:
    """Marginal posteriors of the chosen extension's new parameters, with the maximum-likelihood
    fit and its +-1 standard error (from the decision likelihood) marked, and its
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
    """
    from ..plots import plot_marginal

    post, chosen = result.posterior, result.chosen
    names = [n for n in chosen.params if n in post.parameter_names]
    fig, axes = _axes_row(len(names), axes)
    for ax, n in zip(axes, names):
        plot_marginal(post, n, ax=ax)
        _mark_fit(ax, chosen.params[n], chosen.stderr.get(n, math.nan),
                  "ML fit (decision likelihood)")
        iv = chosen.interval.get(n)
        if iv is not None:
            for k, end in enumerate((iv.lower, iv.upper)):
                ax.axvline(end, color="C3", ls=":", lw=1.2,
                           label=f"{100 * iv.level:.0f} % profile interval" if k == 0 else None)
        ax.legend(fontsize=7)
    fig.suptitle(f"{chosen.physics}: posterior of its new parameters", fontsize=9)
    fig.tight_layout()
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
    for ax, n in zip(axes, names):
        iv = chosen.interval[n]
        ok = np.isfinite(iv.deviance)
        ax.plot(iv.values[ok], iv.deviance[ok], "o-", color="C0", ms=3, lw=1,
                label="scaled deviance (profile)")
        q = iv.quantile
        ax.axhline(q, color="0.4", ls=":", lw=1, label=f"chi2_1 {100 * iv.level:.0f} %")
        ax.axvspan(iv.lower, iv.upper, color="C0", alpha=0.12,
                   label=f"{100 * iv.level:.0f} % interval {iv}")
        ax.axvline(chosen.params[n], color="C3", ls="--", lw=1, label="reported fit")
        ax.set_ylim(-0.05 * q, 3 * q)
        ax.set_xlabel(n)
        ax.set_ylabel("2 d(-ln L) x scale")
        ax.legend(fontsize=7)
    fig.suptitle(f"{chosen.physics}: profile likelihood of its new parameters", fontsize=9)
    fig.tight_layout()
    return fig


def plot_shared_posterior(post: SharedPosterior, axes: Any = None) -> Figure:
    """The marginal posteriors of a pooled diagnosis's shared parameters
    (:func:`~bayespilot.diagnose.shared_posterior`), with the pooled fit and its +-1 standard
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
    """
    names = list(post.names)
    fig, axes = _axes_row(len(names), axes)
    for a, (ax, n) in enumerate(zip(axes, names)):
        g, m = post.grid[a], np.asarray(post.marginals[n]["density"])
        ax.plot(g, m, color="C0", lw=1.5, label="posterior (grid, Laplace)")
        lo, hi = post.marginals[n]["interval"]
        inside = (g >= lo) & (g <= hi)
        ax.fill_between(g[inside], m[inside], color="C0", alpha=0.2, label="central 90 %")
        _mark_fit(ax, post.ml[n], post.stderr.get(n, math.nan), "pooled ML fit")
        ax.set_xlabel(n)
        ax.set_ylabel("density")
        ax.legend(fontsize=7)
    fig.suptitle(f"{post.physics}: posterior of the parameters shared by "
                 f"{post.settings['n_runs']} runs", fontsize=9)
    fig.tight_layout()
    return fig


def _png(fig, path: Path) -> Path:
    plt = _pyplot()
    try:
        fig.savefig(path, dpi=110)
    finally:
        plt.close(fig)
    return path


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
        figures embedded).

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

    def img(p):
        data = base64.b64encode(Path(p).read_bytes()).decode("ascii")
        return f'<img alt="{p.stem}" src="data:image/png;base64,{data}" style="max-width:100%">'

    rows = []
    for c in result.ranking:
        if not c.testable:
            rows.append(f"<tr><td>{html.escape(c.physics)}</td><td colspan=5>not tested: "
                        f"{html.escape(c.reason)}</td></tr>")
            continue
        ps = ", ".join(f"{k} = {v:.4g} &plusmn; {c.stderr.get(k, math.nan):.2g}"
                       + (f" ({100 * c.interval[k].level:.0f} % profile interval "
                          f"{html.escape(str(c.interval[k]))})"
                          if k in c.interval else "")
                       for k, v in c.params.items())
        bold = ' style="font-weight:bold"' if c.justified else ''  # a justified candidate: bold
        rows.append(f"<tr{bold}>"
                    f"<td>{html.escape(c.physics)}</td><td>{c.delta_neg_log_lik:.2f}</td>"
                    f"<td>{c.p_value:.3g}</td><td>{c.delta_bic:.1f}</td>"
                    f"<td>{c.signature_score:.2f}</td><td>{ps}</td></tr>")
    ev = "".join(f"<tr><td>{html.escape(k)}</td><td>{html.escape(e.description)}</td>"
                 f"<td>{e.value:.4g}</td><td>{'' if not math.isfinite(e.p_value) else f'{e.p_value:.3f}'}</td></tr>"
                 for k, e in result.where.items() if math.isfinite(e.value))
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
    title = f"bayespilot diagnosis: {html.escape(result.physics)}"
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:3px 6px;font-size:90%}}</style></head><body>
<h1>{title}</h1>
<p>Recording: {html.escape(str(result.source))}. Mismatch: <b>{result.mismatch}</b>.
Base model: -ln L (Eq. 4) = {result.base['neg_log_lik']:.2f}, VAF = {result.base['vaf']:.2f} %.
Decision at family-wise level alpha = {result.settings['alpha']:g}
({result.settings['level_per_candidate']:.2g} per candidate). Time {result.elapsed:.1f} s.</p>
<h2>Candidates</h2>
<table><tr><th>physics</th><th>&Delta;(-ln L)</th><th>p</th><th>&Delta;BIC</th><th>signature</th><th>parameters</th></tr>
{''.join(rows)}</table>
{cal}
{img(paths['candidates'])}
{bf_html}
<h2>Where</h2>
<table><tr><th>evidence</th><th>what</th><th>value</th><th>bootstrap p</th></tr>{ev}</table>
{img(paths['evidence'])}
<h2>Frequency responses</h2>{img(paths['frequency_response'])}
<h2>Residuals before and after</h2>{img(paths['residuals'])}
{f"<h2>Profile likelihood of the new parameters</h2>{img(paths['profile'])}" if "profile" in paths else ""}
{f"<h2>Posterior of the extended model</h2>{img(paths['posterior'])}" if post is not None else ""}
<pre>{html.escape(result.summary())}</pre>
</body></html>
"""
    paths["html"] = write_text_atomic(out / "report.html", page)
    return paths

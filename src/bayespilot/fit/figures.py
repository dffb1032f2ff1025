"""Figures of the three-step procedure, in the style of Figs. 6-9 of Pool et al. (2012).

Each function takes :class:`~bayespilot.fit.result.FitResult` objects from
:func:`~bayespilot.fit.three_step.fit_paper` (or read back with
``FitResult.from_json``: everything is drawn from ``result.steps``) and
returns a matplotlib Figure, at most :data:`~bayespilot.plots.PAGE_WIDTH`
(7.5 in) wide unless ``figsize=`` says otherwise, in constrained layout with
one legend above the panels, its text in matplotlib's default sizes (for a
vector copy with TrueType fonts, which journals' PDF checks want, save it
within ``matplotlib.rc_context(bayespilot.plots.VECTOR_TEXT)``).  Each takes ``title=``
as every figure of the package does: True (default) as always (no figure title, panels
titled), False no title and no default panel titles ("fit 1"), a str a title heading the
legend.

- :func:`plot_step_one_thresholds` (Fig. 6): the Step I delta_abs of every GA
  repetition, in ascending order of -ln L, one panel per condition; the true
  delta_abs only where it is known (``true_value=``, or recorded in the fits),
  or another reference named as such (``reference_label=``).
- :func:`plot_ga_convergence` (Fig. 7): -ln L and chosen parameters of the
  best-so-far individual over the GA generations, for a few repetitions.
- :func:`plot_step_two` (Fig. 8): -ln L of each repetition after Step I
  (grey) and after the Gauss-Newton refinement of Step II (black), the kept
  one circled.
- :func:`plot_step_three` (Fig. 9): -ln L along delta_abs with the Step II
  parameters fixed, the Step I estimates as crosses, the Step II value and the
  final minimum as vertical lines.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Sequence

import numpy as np

from .._labels import symbol
from ..presets import TABLE3
from ..plots import (_figsize, _legend_columns, _new_figure, _param_label, _pyplot, _title_text,
                     _wrap)
from .result import FitResult

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["plot_step_one_thresholds", "plot_ga_convergence", "plot_step_two", "plot_step_three"]

#: The true delta_abs of the paper's simulations (Table 3), IPUT: ``true_value=`` of
#: :func:`plot_step_one_thresholds` for fits of them (it draws no line by default: a fit
#: does not record the truth of its recording).  The paper's Fig. 6, of measured data, draws
#: Groen et al.'s passive threshold instead, ``presets.DELTA_ABS_PASSIVE`` = 0.00734 IPUT,
#: with ``reference_label=``.
TRUE_THRESHOLD = TABLE3["FD"]["delta_abs"]
#: -ln L as the axes show it.
_NLL = r"$-\ln L$"
#: Line styles of the GA repetitions of Fig. 7 (with their colours: apart in grey print too).
_STYLES = ("-", "--", ":", "-.")


def _paper_fit(result: FitResult, what: str) -> dict:
    if not isinstance(result, FitResult):
        raise TypeError(f"{what} needs a FitResult, got {type(result).__name__}")
    steps = result.steps or {}
    if result.method != "paper" or "step1" not in steps:
        raise ValueError(f"{what} needs a fit by the paper's three-step procedure "
                         f"(method 'paper' with its steps); got method {result.method!r}")
    return steps


def _grid(n: int, ncols: int | None = None):
    ncols = ncols or min(n, 4)
    nrows = int(np.ceil(n / ncols))
    return nrows, ncols


def _panels(nrows: int, ncols: int, width: float, height: float, figsize, *,
            integer_x: bool = False, **kw):
    """A new figure of nrows x ncols panels, each ``width`` x ``height`` in by default, at
    most a page wide (:func:`bayespilot.plots._figsize`; ``figsize`` overrides); x ticks on
    whole numbers only if ``integer_x`` (repetitions, generations)."""
    from matplotlib.ticker import MaxNLocator

    size = _figsize(figsize, None, (width * ncols + 0.6, height * nrows + 0.6))
    fig, axes = _new_figure(nrows, ncols, size, squeeze=False, **kw)
    # narrow panels: fewer round ticks (about one x tick label per 0.55 in)
    nbins = max(2, min(5, int((size[0] - 0.8) / ncols / 0.55)))
    steps = [1, 2, 2.5, 5, 10]
    for ax in axes.flat:
        ax.yaxis.set_major_locator(MaxNLocator(5, steps=steps))
        ax.xaxis.set_major_locator(MaxNLocator(nbins, steps=steps, integer=integer_x))
    return fig, axes


def _finish(fig, axes) -> None:
    """The x tick labels of the bottom row turned where they would still overlap."""
    from ..plots import _unclash_ticks

    _unclash_ticks(fig, [ax for ax in np.asarray(axes).flat if ax.get_visible()
                         and any(t.get_visible() for t in ax.get_xticklabels())])


def _panel_title(labels: Sequence[str] | None, k: int, default: str, title) -> str | None:
    """Panel ``k``'s title: its label when ``labels`` are given, else ``default`` ("fit 1"),
    which ``title=False`` leaves out."""
    if labels is not None:
        return labels[k]
    return None if _title_text(title, default) is None else default  # (False or "": none)


def _legend_above(fig, handles, labels, ncols: int, *, title=True,
                  legend_title: str | None = None):
    """One legend above the panels (constrained layout makes room), headed by a str ``title``
    (the figure's title: a suptitle would lie over the legend, as constrained layout gives
    the top margin to the taller of the two, not to both), wrapped to the figure's width,
    above the legend's own ``legend_title`` if it has one."""
    heading = _title_text(title, None)
    kw = {}
    if heading:
        heading = _wrap(heading, fig.get_figwidth() - 0.3, 10.0)
        kw = {"title": f"{heading}\n{legend_title}" if legend_title else heading,
              "title_fontsize": "medium"}
    elif legend_title:
        kw = {"title": legend_title, "title_fontsize": "small"}
    legend = fig.legend(handles, labels, loc="outside upper center",
                        ncols=_legend_columns(labels, fig.get_figwidth(), ncols),
                        fontsize="small", frameon=False, **kw)
    legend.get_title().set_multialignment("center")
    return legend


def plot_step_one_thresholds(results: Sequence[FitResult], labels: Sequence[str] | None = None, *,
                             ncols: int | None = None,
                             true_value: float | None = None,
                             reference_label: str | None = None,
                             figsize: tuple[float, float] | None = None,
                             title: bool | str = True) -> Figure:
    """Fig. 6: the Step I delta_abs of every repetition, ordered by -ln L.

    Parameters
    ----------
    results : sequence of FitResult, or sequence of sequences of FitResult
        One entry per panel (condition). An entry may itself be a list of fits
        (the paper's five runs per condition), drawn as separate lines.
        One legend above the panels names the lines and the true value.
    labels : sequence of str, optional
        Panel titles (default "fit 1", "fit 2", ... as in Figs. 7-9, or
        "condition 1", ... for panels of several fits).
    ncols : int, optional
        Panels per row (default up to 4).
    true_value : float, optional
        A delta_abs (IPUT) drawn in every panel as a dashed black horizontal
        line named in the legend: "true delta_abs (value IPUT)", the
        truth of simulated recordings (the paper's simulations, Table 3:
        :data:`TRUE_THRESHOLD`, 0.0075), or, with ``reference_label``,
        another reference.  Default: the true delta_abs a fit records in
        ``settings["true_parameters"]`` where every fit of a panel records
        the same one, else no line (a fit as
        :func:`~bayespilot.fit.three_step.fit_paper` makes it
        records none: the truth of a measured recording is not known).
    reference_label : str, optional
        What the line at ``true_value`` is, when it is not a true value:
        the legend reads "reference_label (value IPUT)".  For measured
        data as in the paper's Fig. 6, Groen et al.'s passive threshold:
        ``true_value=presets.DELTA_ABS_PASSIVE,
        reference_label="Groen et al.'s passive threshold"``.
    figsize : (float, float), optional
        Size of the figure, inches (default 3 in per panel and 2.6 in per
        row, at most 7.5 in wide).
    title : bool or str, default True
        True: as the figure has always been, no figure title and each
        panel titled (its label, else "fit 1", ...); False (or ""): no
        figure title and no default panel titles, the panels taking their
        room (titles given by ``labels`` stay: they name the panels); a
        str: that text as the figure's title, heading the legend above the
        panels.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If an entry of ``results`` is not a FitResult, or ``title`` is
        neither a bool nor a str.
    ValueError
        If ``results`` is empty, ``labels`` is not one per panel, a fit is
        not by the paper's three-step procedure, ``true_value`` is not a
        finite number, or ``reference_label`` is empty or given without
        ``true_value``.
    """
    panels = [r if isinstance(r, (list, tuple)) else [r] for r in results]
    if not panels:
        raise ValueError("no fits to plot")
    if labels is not None and len(labels) != len(panels):
        raise ValueError(f"{len(labels)} labels for {len(panels)} panels")
    _title_text(title, None)  # (checked before a figure is made)
    if true_value is not None:
        try:
            true_value = float(true_value)
        except (TypeError, ValueError):
            raise ValueError(f"true_value must be a number (IPUT), got {true_value!r}") from None
        if not math.isfinite(true_value):
            raise ValueError(f"true_value must be finite, got {true_value!r}")
    if reference_label is not None:
        if not isinstance(reference_label, str) or not reference_label.strip():
            raise ValueError(f"reference_label must be a non-empty str, got {reference_label!r}")
        if true_value is None:
            raise ValueError("reference_label names the line at true_value; give its value too "
                             "(for Groen et al.'s passive threshold: true_value="
                             "presets.DELTA_ABS_PASSIVE)")
    d = symbol("delta_abs")
    if true_value is not None:
        lines = [true_value] * len(panels)
        line_label = f"{reference_label or f'true {d}'} ({true_value:g} IPUT)"
    else:  # the truth the fits record, where they do (simulations)
        lines = [_recorded_truth(fits) for fits in panels]
        known = {v for v in lines if v is not None}
        line_label = (f"true {d} ({known.pop():g} IPUT)" if len(known) == 1
                      else f"true {d} (each panel's)")
    nrows, ncols = _grid(len(panels), ncols)
    fig, axes = _panels(nrows, ncols, 3.0, 2.6, figsize, integer_x=True, sharey=True)
    several = any(len(f) > 1 for f in panels)
    for k, (ax, fits) in enumerate(zip(axes.flat, panels)):
        for j, fit in enumerate(fits):
            s1 = _paper_fit(fit, "plot_step_one_thresholds")["step1"]
            i = s1["parameter_names"].index("delta_abs")
            funs = np.array([r["fun"] for r in s1["runs"]])
            deltas = np.array([r["x"][i] for r in s1["runs"]])
            order = np.argsort(funs, kind="stable")
            ax.plot(np.arange(1, len(order) + 1), deltas[order], marker="os^Dv"[j % 5],
                    ls=_STYLES[j % len(_STYLES)], ms=3, lw=0.8,
                    label=f"run {j + 1}" if len(fits) > 1 else "Step I estimate")
        if lines[k] is not None:
            # the package's mark of a true value (or the reference named): a dashed black line
            ax.axhline(lines[k], color="k", ls="--", lw=0.9, zorder=0, label=line_label)
        head = _panel_title(labels, k, f"{'condition' if several else 'fit'} {k + 1}", title)
        if head:
            ax.set_title(head, fontsize="medium")
        if ncols == 1:
            ax.set_xlabel(f"GA repetition (ascending {_NLL})")
        if k % ncols == 0:
            ax.set_ylabel(r"$\hat{\delta}_\mathrm{abs}$ after Step I (IPUT)")
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    if ncols > 1:  # (one label for the panels side by side: each would overrun its panel)
        fig.supxlabel(f"GA repetition (ascending {_NLL})", fontsize="medium")
    # one legend for every panel, above them (the panels with most runs name them all, and
    # the line where one is drawn)
    widest = max(range(len(panels)), key=lambda k: (len(panels[k]), lines[k] is not None))
    handles, names = axes.flat[widest].get_legend_handles_labels()
    if line_label not in names and any(v is not None for v in lines):
        k = next(k for k, v in enumerate(lines) if v is not None)
        h, n = axes.flat[k].get_legend_handles_labels()
        handles.append(h[n.index(line_label)])
        names.append(line_label)
    _legend_above(fig, handles, names, 4, title=title)
    _finish(fig, axes[-1])
    return fig


def _recorded_truth(fits: Sequence[FitResult]) -> float | None:
    """The true delta_abs the fits record (``settings["true_parameters"]``, as a simulated
    recording's truth is kept), when every one records the same finite value; else None."""
    values = set()
    for fit in fits:
        true = (getattr(fit, "settings", None) or {}).get("true_parameters") or {}
        v = true.get("delta_abs") if hasattr(true, "get") else None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            return None
        values.add(float(v))
    return values.pop() if len(values) == 1 else None


def plot_ga_convergence(results: Sequence[FitResult], labels: Sequence[str] | None = None, *,
                        parameters: Sequence[str] = ("K_v", "K_m", "tau_m", "delta_abs"),
                        repetitions: int = 3,
                        figsize: tuple[float, float] | None = None,
                        title: bool | str = True) -> Figure:
    """Fig. 7: the best-so-far individual over the GA generations.

    Rows are -ln L and ``parameters``; columns are the fits (conditions); each
    panel shows ``repetitions`` GA runs as separate lines, repetition j in
    the same colour and line style (solid, dashed, dotted, dash-dotted) in
    every panel, named by one legend above the panels.

    Parameters
    ----------
    results : sequence of FitResult
        Fits by :func:`~bayespilot.fit.three_step.fit_paper` (method
        ``"paper"``, with its steps), one column each.
    labels : sequence of str, optional
        Column titles, one per fit (default "fit 1", "fit 2", ...).
    parameters : sequence of str
        Parameters drawn below -ln L, one row each, as the best-so-far
        individual's values; each must have been estimated in Step I.
        Default K_v, K_m, tau_m and delta_abs.
    repetitions : int, default 3
        GA runs drawn per fit: the first ones in repetition order (not the
        best), or all of them if the fit has fewer.
    figsize : (float, float), optional
        Size of the figure, inches (default 3 in per column and 1.7 in per
        row, at most 7.5 x 9.5 in).
    title : bool or str, default True
        As for :func:`plot_step_one_thresholds`.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If an entry of ``results`` is not a FitResult, or ``title`` is
        neither a bool nor a str.
    ValueError
        If ``results`` is empty, ``repetitions`` < 1, ``labels`` is not one per
        fit, a fit is not by the paper's three-step procedure, or a name in
        ``parameters`` was not estimated in Step I (delta_abs in a fit
        without threshold).
    """
    plt = _pyplot()
    results = list(results)
    if not results:
        raise ValueError("no fits to plot")
    if repetitions < 1:
        raise ValueError(f"repetitions must be >= 1, got {repetitions}")
    _check_labels(labels, len(results))
    _title_text(title, None)  # (checked before a figure is made)
    rows = [_NLL, *(_param_label(p, results[0]) for p in parameters)]  # its model's units
    fig, axes = _panels(len(rows), len(results), 3.0, 1.7, figsize, integer_x=True,
                        sharex=True)
    drawn = 0
    for c, fit in enumerate(results):
        s1 = _paper_fit(fit, "plot_ga_convergence")["step1"]
        names = s1["parameter_names"]
        missing = [p for p in parameters if p not in names]
        if missing:
            raise ValueError(f"parameter(s) {missing} not estimated in Step I ({', '.join(names)})")
        for j, run in enumerate(s1["runs"][:repetitions]):
            hx = np.asarray(run["history_best_x"])
            gen = np.arange(hx.shape[0])
            # repetition j has one colour in every column: one legend names them all (the
            # default cycle up to 10, then a colour map, whose colours do not repeat)
            color = (f"C{j}" if repetitions <= 10
                     else plt.cm.viridis(j / max(1, repetitions - 1)))
            style = {"lw": 1.2, "color": color, "ls": _STYLES[j % len(_STYLES)]}
            axes[0, c].plot(gen, run["history_best_fun"], label=f"GA repetition {j + 1}",
                            **style)
            for r, p in enumerate(parameters, start=1):
                axes[r, c].plot(gen, hx[:, names.index(p)], **style)
        drawn = max(drawn, min(repetitions, len(s1["runs"])))
        head = _panel_title(labels, c, f"fit {c + 1}", title)
        if head:
            axes[0, c].set_title(head, fontsize="medium")
        axes[-1, c].set_xlabel("GA generation")
    for r, name in enumerate(rows):
        axes[r, 0].set_ylabel(name)
    handles, names = next(ax for ax in axes[0]
                          if len(ax.get_lines()) == drawn).get_legend_handles_labels()
    _legend_above(fig, handles, names, len(names), title=title,
                  legend_title="best-so-far individual of")
    _finish(fig, axes[-1])
    return fig


def _check_labels(labels: Sequence[str] | None, n: int) -> None:
    """One label per column, or none."""
    if labels is not None and len(labels) != n:
        raise ValueError(f"{len(labels)} labels for {n} fits")


def _one_row(results: Sequence[FitResult], labels: Sequence[str] | None = None,
             figsize: tuple[float, float] | None = None, height: float = 2.8,
             integer_x: bool = False, title: bool | str = True):
    """The fits as a list and a figure with one panel per fit in a row (Figs. 8 and 9)."""
    results = list(results)
    if not results:
        raise ValueError("no fits to plot")
    _check_labels(labels, len(results))
    _title_text(title, None)  # (checked before a figure is made)
    fig, axes = _panels(1, len(results), 3.0, height, figsize, integer_x=integer_x)
    return results, fig, axes


def plot_step_two(results: Sequence[FitResult], labels: Sequence[str] | None = None, *,
                  figsize: tuple[float, float] | None = None,
                  title: bool | str = True) -> Figure:
    """Fig. 8: -ln L per repetition after Step I (grey) and Step II (black).

    Parameters
    ----------
    results : sequence of FitResult
        Fits by :func:`~bayespilot.fit.three_step.fit_paper` (method
        ``"paper"``, with its steps), one panel each, in a row.  In each panel
        the repetitions are in run order, and the Step II refinement kept
        (the lowest -ln L) is circled.
    labels : sequence of str, optional
        Panel titles, one per fit (default "fit 1", "fit 2", ...).
    figsize : (float, float), optional
        Size of the figure, inches (default 3 in per panel, at most 7.5 in
        wide).
    title : bool or str, default True
        As for :func:`plot_step_one_thresholds`.

    Returns
    -------
    matplotlib.figure.Figure
        One legend above the panels names the markers.

    Raises
    ------
    TypeError
        If an entry of ``results`` is not a FitResult, or ``title`` is
        neither a bool nor a str.
    ValueError
        If ``results`` is empty, ``labels`` is not one per fit, or a fit is
        not by the paper's three-step procedure.
    """
    from matplotlib.lines import Line2D

    results, fig, axes = _one_row(results, labels, figsize, integer_x=True, title=title)
    for c, (ax, fit) in enumerate(zip(axes[0], results)):
        steps = _paper_fit(fit, "plot_step_two")
        before = np.array([r["fun"] for r in steps["step1"]["runs"]])
        after = np.array([r["neg_log_lik"] for r in steps["step2"]])
        k = np.arange(1, len(before) + 1)
        ax.plot(k, before, "s", color="0.65", ms=4, label="Step I")
        ax.plot(k, after, "s", color="k", ms=4, label="Step II")
        best = steps["step2_best"]
        # a ring around the kept square (a filled circle would hide it)
        ax.plot(k[best], after[best], "o", mfc="none", mec="k", mew=1.2, ms=10, label="kept",
                zorder=3)
        head = _panel_title(labels, c, f"fit {c + 1}", title)
        if head:
            ax.set_title(head, fontsize="medium")
        ax.set_xlabel("GA repetition")
        if c == 0:
            ax.set_ylabel(_NLL)
    handles = [Line2D([], [], ls="none", marker="s", color="0.65", ms=4),
               Line2D([], [], ls="none", marker="s", color="k", ms=4),
               Line2D([], [], ls="none", marker="o", mfc="none", mec="k", mew=1.2, ms=10)]
    _legend_above(fig, handles, ["after Step I (GA)", "after Step II (Gauss-Newton)",
                                 "Step II refinement kept (lowest " + _NLL + ")"], 3,
                  title=title)
    _finish(fig, axes[0])
    return fig


def plot_step_three(results: Sequence[FitResult],
                    labels: Sequence[str] | None = None, *, scan: int = 0,
                    span: float | None = None,
                    figsize: tuple[float, float] | None = None,
                    title: bool | str = True) -> Figure:
    """Fig. 9: -ln L along delta_abs (Step II parameters fixed) with the estimates marked.

    The Step I estimates of each repetition are crosses on the curve, the
    Step II value (the mean of the best Step I runs) an open ring and a
    dashed vertical line, the scan's minimum a filled circle (inside the
    ring where they coincide) and a solid vertical line; one legend above
    the panels names them.

    The y axis shows the curve from its minimum up to ``span`` units of
    -ln L above it: far from the minimum -ln L is tens of thousands of units
    higher, which would flatten the minimum, where the estimates lie, to a
    point.  A Step I estimate off that range is a triangle at the top edge.

    Parameters
    ----------
    results : sequence of FitResult
        Fits with threshold by :func:`~bayespilot.fit.three_step.fit_paper`
        (method ``"paper"``, with its steps), one panel each, in a row.
    labels : sequence of str, optional
        Panel titles, one per fit (default "fit 1", "fit 2", ...).
    scan : int
        Which Step III scan of each fit to draw, as a list index: 0 (default)
        the first, as in the paper's Fig. 9; -1 the last pass of a fit made
        with ``iterate=True``, whose minimum is the fit's final delta_abs.
    span : float, optional
        How far above each curve's minimum the y axis reaches, in units of
        -ln L.  Default: three times the rise from the minimum to the Step II
        value, or twice the median rise to the Step I estimates if more, and
        at least 2 units; ``math.inf``: the whole curve.
    figsize : (float, float), optional
        Size of the figure, inches (default 3 in per panel, at most 7.5 in
        wide).
    title : bool or str, default True
        As for :func:`plot_step_one_thresholds`.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If an entry of ``results`` is not a FitResult, or ``title`` is
        neither a bool nor a str.
    ValueError
        If ``results`` is empty, ``labels`` is not one per fit, a fit is not
        by the paper's three-step procedure, a fit has no Step III scan
        (fitted without threshold), ``scan`` is not an index of every
        fit's scans, or ``span`` is not a positive number.

    Notes
    -----
    The crosses and the open circle are placed on the drawn curve by linear
    interpolation of its -ln L.  On a later pass's curve they mark where the
    first pass's estimates lie; the other parameters have moved since, so
    they need not sit at the first pass's values of -ln L.
    """
    if isinstance(scan, bool) or not isinstance(scan, (int, np.integer)):
        raise ValueError(f"scan must be an integer index (0 the first, -1 the last), "
                         f"got {scan!r}")
    if span is not None and (isinstance(span, bool) or not isinstance(span, (int, float))
                             or not span > 0):
        raise ValueError(f"span must be a positive number (units of -ln L) or math.inf, "
                         f"got {span!r}")
    results = list(results)  # (once: a generator is read once)
    chosen = []
    for fit in results:  # checked before a figure is made
        steps = _paper_fit(fit, "plot_step_three")
        if not steps.get("step3"):
            raise ValueError("this fit has no Step III scan (fitted without threshold?)")
        if not -len(steps["step3"]) <= scan < len(steps["step3"]):
            raise ValueError(f"scan={scan} but a fit has {len(steps['step3'])} Step III "
                             f"scan(s)")
        chosen.append((steps, steps["step3"][scan]))
    from matplotlib.lines import Line2D

    # (room above the panels for the legend's four lines)
    results, fig, axes = _one_row(results, labels, figsize, height=3.3, title=title)
    off_scale = False
    for c, (ax, (steps, one)) in enumerate(zip(axes[0], chosen)):
        scan_c = one
        grid = np.asarray(scan_c["grid"], dtype=float)
        nll = np.array([np.nan if v is None else v for v in scan_c["neg_log_lik"]], dtype=float)
        ax.plot(grid, nll, "k-", lw=1, label="Step III scan")
        s1 = steps["step1"]
        i = s1["parameter_names"].index("delta_abs")
        d1 = np.array([r["x"][i] for r in s1["runs"]])
        y1 = np.interp(d1, grid, nll)
        d2 = steps["step1_delta_abs"]
        y2 = float(np.interp(d2, grid, nll))
        lo, hi = _zoom(nll, y2, y1, span)
        inside = y1 <= hi
        ax.plot(d1[inside], y1[inside], "x", color="0.4", ms=6, mew=1.2, label="Step I")
        if not inside.all():  # off the range shown: a triangle at the top edge
            off_scale = True
            ax.plot(d1[~inside], np.full((~inside).sum(), hi), "^", color="0.4", ms=6,
                    clip_on=False, zorder=3, label="Step I (above the range shown)")
        ax.axvline(d2, color="k", lw=0.8, ls="--")
        ax.axvline(scan_c["best"], color="k", lw=0.8)
        ax.plot(scan_c["best"], scan_c["best_neg_log_lik"], "ko", ms=5, zorder=3,
                label="Step III")
        # the ring on top: a filled circle at the same place shows inside it
        ax.plot(d2, y2, "o", mfc="none", mec="k", mew=1.2, ms=10, zorder=4, label="Step II")
        if math.isfinite(lo) and math.isfinite(hi) and hi > lo:
            ax.set_ylim(lo, hi)
        # whole values of -ln L on the ticks: a range of a few units about -26 157 otherwise
        # gets an offset text ("-2.615e4") that runs into the panel's title
        ax.ticklabel_format(axis="y", useOffset=False, style="plain")
        head = _panel_title(labels, c, f"fit {c + 1}", title)
        if head:
            ax.set_title(head, fontsize="medium")
        ax.set_xlabel(_param_label("delta_abs"))
        if c == 0:
            ax.set_ylabel(_NLL)
    d = symbol("delta_abs")
    handles = [Line2D([], [], color="k", lw=1, label=f"{_NLL} along {d}, Step II parameters "
                                                      "held"),
               Line2D([], [], ls="none", marker="x", color="0.4", ms=6, mew=1.2,
                      label=f"Step I estimates of {d}"),
               Line2D([], [], color="k", lw=0.8, ls="--", marker="o", mfc="none", mec="k",
                      mew=1.2, ms=10, label=f"Step II {d} (mean of the best Step I runs)"),
               Line2D([], [], color="k", lw=0.8, marker="o", ms=5,
                      label="Step III minimum of the scan")]
    if off_scale:
        handles.insert(2, Line2D([], [], ls="none", marker="^", color="0.4", ms=6,
                                 label="Step I estimates above the range shown"))
    _legend_above(fig, handles, [h.get_label() for h in handles], 2, title=title)
    _finish(fig, axes[0])
    return fig


def _zoom(nll: np.ndarray, at_step_two: float, at_step_one: np.ndarray,
          span: float | None) -> tuple[float, float]:
    """The y range of a Fig. 9 panel: from a little below the curve's minimum to ``span``
    above it (default: see :func:`plot_step_three`)."""
    ok = np.isfinite(nll)
    if not ok.any():
        return math.nan, math.nan
    bottom = float(np.min(nll[ok]))
    if span is None:
        rises = [2.0]
        if math.isfinite(at_step_two):
            rises.append(3.0 * (at_step_two - bottom))
        one = np.asarray(at_step_one, float)
        if np.isfinite(one).any():
            rises.append(2.0 * float(np.median(one[np.isfinite(one)]) - bottom))
        span = max(rises)
    top = min(bottom + span, float(np.max(nll[ok])))
    if not top > bottom:
        top = bottom + 1.0
    pad = 0.06 * (top - bottom)
    return bottom - pad, top + pad

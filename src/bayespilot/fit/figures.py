"""Figures of the three-step procedure, in the style of Figs. 6-9 of Pool et al. (2012).

Each function takes :class:`~bayespilot.fit.result.FitResult` objects from
:func:`~bayespilot.fit.three_step.fit_paper` (or read back with
``FitResult.from_json``: everything is drawn from ``result.steps``) and
returns a matplotlib Figure.

- :func:`plot_step_one_thresholds` (Fig. 6): the Step I delta_abs of every GA
  repetition, in ascending order of -ln L, one panel per condition.
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

from typing import TYPE_CHECKING, Sequence

import numpy as np

from .._labels import symbol
from ..plots import _legend_columns, _param_label, _pyplot
from .result import FitResult

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["plot_step_one_thresholds", "plot_ga_convergence", "plot_step_two", "plot_step_three"]

#: Groen et al.'s passive pitch threshold, the line of Fig. 6, IPUT (= the paper's true value).
PASSIVE_THRESHOLD = 0.0075
#: -ln L as the axes show it.
_NLL = r"$-\ln L$"


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


def plot_step_one_thresholds(results: Sequence[FitResult], labels: Sequence[str] | None = None, *,
                             ncols: int | None = None,
                             true_value: float | None = PASSIVE_THRESHOLD) -> Figure:
    """Fig. 6: the Step I delta_abs of every repetition, ordered by -ln L.

    Parameters
    ----------
    results : sequence of FitResult, or sequence of sequences of FitResult
        One entry per panel (condition). An entry may itself be a list of fits
        (the paper's five runs per condition), drawn as separate lines.
        One legend above the panels names the lines and the true value.
    labels : sequence of str, optional
        Panel titles.
    ncols : int, optional
        Panels per row (default up to 4).
    true_value : float or None
        The true delta_abs, a dashed black horizontal line named in the
        legend (default Groen et al.'s 0.0075 IPUT, the paper's true value);
        None for no line.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _pyplot()
    panels = [r if isinstance(r, (list, tuple)) else [r] for r in results]
    if not panels:
        raise ValueError("no fits to plot")
    if labels is not None and len(labels) != len(panels):
        raise ValueError(f"{len(labels)} labels for {len(panels)} panels")
    nrows, ncols = _grid(len(panels), ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.0 * ncols, 2.6 * nrows + 0.3),
                             sharey=True, squeeze=False, layout="constrained")
    for k, (ax, fits) in enumerate(zip(axes.flat, panels)):
        for j, fit in enumerate(fits):
            s1 = _paper_fit(fit, "plot_step_one_thresholds")["step1"]
            i = s1["parameter_names"].index("delta_abs")
            funs = np.array([r["fun"] for r in s1["runs"]])
            deltas = np.array([r["x"][i] for r in s1["runs"]])
            order = np.argsort(funs, kind="stable")
            ax.plot(np.arange(1, len(order) + 1), deltas[order], "o-", ms=3, lw=0.8,
                    label=f"run {j + 1}" if len(fits) > 1 else "Step I estimate")
        if true_value is not None:
            # the package's mark of a true value: a dashed black line
            ax.axhline(true_value, color="k", ls="--", lw=0.9, zorder=0,
                       label=f"true {symbol('delta_abs')} ({true_value:g} IPUT)")
        ax.set_title(labels[k] if labels is not None else f"condition {k + 1}", fontsize=9)
        ax.set_xlabel(f"GA repetition (ascending {_NLL})")
        if k % ncols == 0:
            ax.set_ylabel(r"$\hat{\delta}_\mathrm{abs}$ after Step I (IPUT)")
    for ax in list(axes.flat)[len(panels):]:
        ax.set_visible(False)
    # one legend for every panel, above them (the panels with most runs name them all)
    widest = max(range(len(panels)), key=lambda k: len(panels[k]))
    handles, names = axes.flat[widest].get_legend_handles_labels()
    fig.legend(handles, names, loc="outside upper center",
               ncol=_legend_columns(names, fig.get_figwidth(), 4), fontsize="small",
               frameon=False)
    return fig


def plot_ga_convergence(results: Sequence[FitResult], labels: Sequence[str] | None = None, *,
                        parameters: Sequence[str] = ("K_v", "K_m", "tau_m", "delta_abs"),
                        repetitions: int = 3) -> Figure:
    """Fig. 7: the best-so-far individual over the GA generations.

    Rows are -ln L and ``parameters``; columns are the fits (conditions); each
    panel shows ``repetitions`` GA runs as separate lines, repetition j in
    the same colour in every panel, named by one legend above the panels.

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

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If an entry of ``results`` is not a FitResult.
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
    rows = [_NLL, *(_param_label(p, results[0]) for p in parameters)]  # its model's units
    fig, axes = plt.subplots(len(rows), len(results),
                             figsize=(3.0 * len(results), 1.7 * len(rows) + 0.3),
                             sharex=True, squeeze=False, layout="constrained")
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
            axes[0, c].plot(gen, run["history_best_fun"], lw=1, color=color,
                            label=f"GA repetition {j + 1}")
            for r, p in enumerate(parameters, start=1):
                axes[r, c].plot(gen, hx[:, names.index(p)], lw=1, color=color)
        drawn = max(drawn, min(repetitions, len(s1["runs"])))
        axes[0, c].set_title(labels[c] if labels is not None else f"fit {c + 1}", fontsize=9)
        axes[-1, c].set_xlabel("GA generation")
    for r, name in enumerate(rows):
        axes[r, 0].set_ylabel(name)
    handles, names = next(ax for ax in axes[0]
                          if len(ax.get_lines()) == drawn).get_legend_handles_labels()
    fig.legend(handles, names, loc="outside upper center",
               ncol=_legend_columns(names, fig.get_figwidth(), len(names)), fontsize="small",
               frameon=False, title="best-so-far individual of", title_fontsize="small")
    return fig


def _check_labels(labels: Sequence[str] | None, n: int) -> None:
    """One label per column, or none."""
    if labels is not None and len(labels) != n:
        raise ValueError(f"{len(labels)} labels for {n} fits")


def _one_row(results: Sequence[FitResult], labels: Sequence[str] | None = None):
    """The fits as a list and a figure with one panel per fit in a row (Figs. 8 and 9)."""
    results = list(results)
    if not results:
        raise ValueError("no fits to plot")
    _check_labels(labels, len(results))
    fig, axes = _pyplot().subplots(1, len(results), figsize=(3.0 * len(results), 2.8),
                                   squeeze=False)
    return results, fig, axes


def plot_step_two(results: Sequence[FitResult], labels: Sequence[str] | None = None) -> Figure:
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

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If an entry of ``results`` is not a FitResult.
    ValueError
        If ``results`` is empty, ``labels`` is not one per fit, or a fit is
        not by the paper's three-step procedure.
    """
    results, fig, axes = _one_row(results, labels)
    for c, (ax, fit) in enumerate(zip(axes[0], results)):
        steps = _paper_fit(fit, "plot_step_two")
        before = np.array([r["fun"] for r in steps["step1"]["runs"]])
        after = np.array([r["neg_log_lik"] for r in steps["step2"]])
        k = np.arange(1, len(before) + 1)
        ax.plot(k, before, "s", color="0.65", ms=4, label="Step I")
        ax.plot(k, after, "s", color="k", ms=4, label="Step II")
        best = steps["step2_best"]
        ax.plot(k[best], after[best], "o", mfc="white", mec="k", ms=9, label="kept")
        ax.set_title(labels[c] if labels is not None else f"fit {c + 1}", fontsize=9)
        ax.set_xlabel("GA repetition")
        if c == 0:
            ax.set_ylabel("-ln L")
            ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def plot_step_three(results: Sequence[FitResult],
                    labels: Sequence[str] | None = None, *, scan: int = 0) -> Figure:
    """Fig. 9: -ln L along delta_abs (Step II parameters fixed) with the estimates marked.

    The Step I estimates of each repetition are crosses on the curve, the
    Step II value (the mean of the best Step I runs) an open circle and a
    dashed vertical line, the scan's minimum a filled circle and a solid
    vertical line; one legend above the panels names them.

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

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If an entry of ``results`` is not a FitResult.
    ValueError
        If ``results`` is empty, ``labels`` is not one per fit, a fit is not
        by the paper's three-step procedure, a fit has no Step III scan
        (fitted without threshold), or ``scan`` is not an index of every
        fit's scans.

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

    if not results:
        raise ValueError("no fits to plot")
    _check_labels(labels, len(results))
    # (as _one_row's, with room above the panels for the legend)
    fig, axes = _pyplot().subplots(1, len(results), figsize=(3.0 * len(results), 3.3),
                                   squeeze=False, layout="constrained")
    for c, (ax, (steps, one)) in enumerate(zip(axes[0], chosen)):
        scan_c = one
        grid = np.asarray(scan_c["grid"], dtype=float)
        nll = np.array([np.nan if v is None else v for v in scan_c["neg_log_lik"]], dtype=float)
        ax.plot(grid, nll, "k-", lw=1, label="Step III scan")
        s1 = steps["step1"]
        i = s1["parameter_names"].index("delta_abs")
        d1 = np.array([r["x"][i] for r in s1["runs"]])
        ax.plot(d1, np.interp(d1, grid, nll), "x", color="0.4", ms=6, label="Step I")
        d2 = steps["step1_delta_abs"]
        ax.axvline(d2, color="k", lw=0.8, ls="--")
        ax.plot(d2, np.interp(d2, grid, nll), "o", mfc="white", mec="k", ms=7, label="Step II")
        ax.axvline(scan_c["best"], color="k", lw=0.8)
        ax.plot(scan_c["best"], scan_c["best_neg_log_lik"], "ko", ms=6, label="Step III")
        ax.set_title(labels[c] if labels is not None else f"fit {c + 1}", fontsize=9)
        ax.set_xlabel(_param_label("delta_abs"))
        if c == 0:
            ax.set_ylabel(_NLL)
    d = symbol("delta_abs")
    handles = [Line2D([], [], color="k", lw=1, label=f"{_NLL} along {d}, Step II parameters "
                                                      "held"),
               Line2D([], [], ls="none", marker="x", color="0.4", ms=6,
                      label=f"Step I estimates of {d}"),
               Line2D([], [], color="k", lw=0.8, ls="--", marker="o", mfc="white", mec="k",
                      ms=7, label=f"Step II {d} (mean of the best Step I runs)"),
               Line2D([], [], color="k", lw=0.8, marker="o", ms=6,
                      label="Step III minimum of the scan")]
    fig.legend(handles=handles, loc="outside upper center",
               ncol=_legend_columns([h.get_label() for h in handles], fig.get_figwidth(), 2),
               fontsize="small", frameon=False)
    return fig

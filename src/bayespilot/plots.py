"""Figures of recordings and results.

Every function here takes results (a :class:`~bayespilot.recording.Recording`,
a :class:`~bayespilot.simulate.Simulation`, arrays), draws on the axes it is
given or on a new figure, and returns the figure.  Nothing here calls
``plt.show()``; matplotlib is imported only when a figure is drawn, so
``import bayespilot`` stays cheap.

Parameters are labelled in the paper's notation with their units
(:mod:`bayespilot._labels`).  A new figure is at most :data:`PAGE_WIDTH` x
:data:`PAGE_HEIGHT` inches (panels shrink as they multiply; ``figsize=``
overrides), in constrained layout, with its legends outside the plotted data.

Every figure takes ``title=``: True (default) its own title (the run: draws, likelihood,
convergence; task and duration), False (or "") none, the panels taking its room (for a
paper, whose caption says it), a str that text instead.  The own title's text is kept on the
returned figure, whatever ``title``, as ``fig._bayespilot_note`` (:data:`NOTE_ATTR`); a
posterior figure without it warns (:class:`~bayespilot.sample.ConvergenceWarning`) when the
chain has not converged.  The diagnosis report's figures take ``title=`` alike.
"""

from __future__ import annotations

import math
import os
import sys
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from . import _figstyle
from .recording import Recording
from .simulate import Simulation

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

    from .sample import Posterior

__all__ = ["plot_traces", "plot_threshold_histograms"]

#: Default figures are at most this wide (in), a full page of a paper, so that their text
#: (:data:`SMALLEST_FONT` pt or more) prints at about its size; ``figsize=`` gives another.
PAGE_WIDTH = 7.5
#: ... and at most this tall (in).
PAGE_HEIGHT = 9.5
#: The smallest text (pt) in a figure drawn here.
SMALLEST_FONT = 7.0
#: How a saved figure keeps its text: ``matplotlib.rc_context(VECTOR_TEXT)`` around
#: ``savefig`` gives a PDF with TrueType fonts and an SVG with text (``_figstyle``'s).
VECTOR_TEXT = _figstyle.VECTOR_TEXT


def _pyplot():
    """matplotlib.pyplot, on the Agg backend when there is no display to draw on and no
    backend was chosen, or when it is first imported off the main thread (a batch's report
    drawn in a dask worker's thread, where a GUI backend cannot run); a backend already in use
    is kept, and so is one chosen by ``MPLBACKEND`` or matplotlibrc (Jupyter's kernel picks
    its inline backend through ``MPLBACKEND``, also on a headless server)."""
    import threading

    import matplotlib

    headless = (sys.platform.startswith("linux")
                and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"))
    # (rcParams._get_backend_or_none is matplotlib's own test for "chosen"; absent: not known)
    chosen = os.environ.get("MPLBACKEND") or getattr(
        matplotlib.rcParams, "_get_backend_or_none", lambda: None)()
    worker = threading.current_thread() is not threading.main_thread()
    if ((headless and not chosen) or worker) and "matplotlib.pyplot" not in sys.modules:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _figsize(figsize: Any, ax: Any, default: tuple[float, float]) -> tuple[float, float]:
    """The size of a new figure: ``figsize`` as given, else ``default`` capped at a page."""
    if figsize is None:
        return min(default[0], PAGE_WIDTH), min(default[1], PAGE_HEIGHT)
    if ax is not None:
        raise ValueError("figsize sizes a new figure; it cannot be given with ax")
    try:
        w, h = (float(v) for v in figsize)
    except (TypeError, ValueError):
        raise ValueError(f"figsize must be (width, height) in inches, got {figsize!r}") from None
    if not (math.isfinite(w) and math.isfinite(h) and w > 0 and h > 0):
        raise ValueError(f"figsize must be two positive numbers (inches), got {figsize!r}")
    return w, h


def _title_text(title: Any, default: str | None) -> str | None:
    """The title a figure is drawn with (the ``title=`` convention of every plot function, the
    diagnosis report's too): ``default`` for True (today's title), none for False (or ""), the
    text itself for a str; TypeError for anything else."""
    if isinstance(title, (bool, np.bool_)):
        return default if title else None
    if isinstance(title, str):
        return title or None
    raise TypeError(f"title must be True (the figure's own title), False (none) or a str, got "
                    f"{title!r}")


#: The attribute of a returned figure that keeps its run note (what its own title says: draws,
#: likelihood, convergence; task and duration), whatever ``title=`` was: for a caption.
NOTE_ATTR = "_bayespilot_note"


def _keep_note(fig, note: str) -> None:
    """Keep ``note`` (the figure's own title, as it reads without mathtext) on ``fig`` as
    :data:`NOTE_ATTR`, for a caption when the title is off or replaced."""
    setattr(fig, NOTE_ATTR, note)


def _warn_untitled(posterior, title: Any, what: str) -> None:
    """A ConvergenceWarning when the title that says "not converged" is off or replaced
    (``title`` not True) and the posterior has not converged: the reader of the figure no
    longer sees it, the user is told to say it in the caption."""
    if (isinstance(title, (bool, np.bool_)) and title) or posterior.converged:
        return  # (numpy's True too: the figure's own title, which says it)
    from ._caller import warn_at_caller
    from .sample import ConvergenceWarning

    tau = np.array([v for v in posterior.tau.values() if v is not None], dtype=float)
    n_steps = posterior.settings.get("n_steps", 0)
    shown = "off" if _title_text(title, None) is None else "replaced"
    warn_at_caller(ConvergenceWarning(
        f"{what}: the posterior has not converged ({n_steps} steps); the figure's title, "
        f"which says so, is {shown} (title={title!r}): say it in the caption (the figure's "
        f"{NOTE_ATTR} attribute keeps the title's text)", tau, int(n_steps or 0)))


def _new_figure(nrows: int, ncols: int, size: tuple[float, float], **kw):
    """plt.subplots in constrained layout (it makes room for legends outside the axes)."""
    plt = _pyplot()
    return plt.subplots(nrows, ncols, figsize=size, layout="constrained", **kw)


def _param_label(name: str, model: Any = None) -> str:
    """A parameter's axis label: the paper's notation with its unit (:mod:`._labels`).

    The unit is the one ``model`` declares (``model`` a PilotModel, or a FitResult, which
    keeps its model's units).  Without a model (a Posterior keeps only its model's name) the
    paper's parameters have Table 1's units, a partial autocorrelation ``pacf_j`` none, and
    another lab's parameter its symbol without a unit.
    """
    from ._labels import label

    return label(name, _param_unit(name, model))


def _param_unit(name: str, model: Any = None) -> str | None:
    """The unit of ``name`` as :func:`_param_label` writes it (None or ``"-"``: none)."""
    from . import presets

    units = getattr(model, "units", None)  # a FitResult's: as its model declared them
    if isinstance(units, Mapping) and name in units:
        return units[name]
    if model is not None:
        try:
            return model.parameter(name).unit
        except (KeyError, ValueError, AttributeError):
            pass
    if name.startswith("pacf_"):
        return "-"
    return presets.PARAMETER_UNITS.get(name)


def _per_unit(unit: str | None) -> str:
    """``" (1/unit)"``, the unit of a density over a parameter in ``unit`` ("" for none):
    "s" -> " (1/s)", "rad/IPUT" -> " (IPUT/rad)", "rad/s^2" -> " (s$^2$/rad)", "1/s" ->
    " (s)", "rad/(m/s^2)" -> " ((m/s$^2$)/rad)"."""
    from ._labels import unit_text

    if not unit or unit == "-":
        return ""
    num, slash, den = unit.partition("/")
    whole = den.startswith("(") and den.endswith(")") and den.count("(") == 1
    if slash and num == "1" and ("/" not in den or whole):
        inverse = den[1:-1] if whole else den
    elif slash and ("/" not in den or whole) and " " not in num and " " not in den:
        inverse = f"{den}/{num}"
    else:
        inverse = f"1/{unit}" if not any(c in unit for c in " /*") else f"1/({unit})"
    return f" ({unit_text(inverse)})"


def _posterior_model(posterior: Any, model: Any = None) -> Any:
    """The model that declares the units of ``posterior``'s parameters: ``model`` when given;
    else, for a posterior of a catalogue extension of the paper's model (one written by
    ``bayespilot diagnose``, whose settings name the model it sampled), that extension built
    on the paper's model, as the diagnosis report labels it; else None (Table 1's units)."""
    if model is not None:
        return model
    name = (getattr(posterior, "settings", None) or {}).get("model")
    if not isinstance(name, str) or " + " not in name:
        return None  # the paper's model, or a model whose name says nothing
    try:
        from .diagnose.catalogue import candidate_names
        from .diagnose.report import _units_model  # (the report's labels: the same model)
    except Exception:  # the diagnose module unavailable: Table 1's units
        return None
    for physics in candidate_names():
        built = _units_model(physics)  # (None: an entry that needs more than the paper's)
        if built is not None and built.name == name:
            return built
    return None


def _wrap(text: str, width_in: float, fontsize: float) -> str:
    """``text`` broken into lines that fit ``width_in`` inches at ``fontsize`` pt (mathtext
    spans are kept whole)."""
    import re
    import textwrap

    chars = max(16, int(width_in * 72.0 / (0.58 * fontsize)))
    # a mathtext span is one word as long as what it shows ($\delta_\mathrm{abs}$: about 4
    # characters, not 20), and "Eq. (4)" is not broken either
    spans: list[str] = []

    def hide(m) -> str:
        spans.append(m.group(0))
        shown = re.sub(r"[{}_^ ]", "", re.sub(r"\\[A-Za-z]+", "x", m.group(0)[1:-1]))
        return ("\ue000" if len(spans) % 2 else "\ue001") * max(1, len(shown) - 1)

    hidden = re.sub(r"\$[^$]*\$", hide, text.replace("Eq. (", "Eq.\0("))
    wrapped = textwrap.fill(hidden, chars, break_long_words=False)
    shown = iter(spans)
    return re.sub("\ue000+|\ue001+", lambda m: next(shown), wrapped).replace("\0", " ")


def _legend_below(fig, handles, labels, ncols: int):
    """A figure legend under the axes of a figure made here (constrained layout makes room),
    in at most ``ncols`` columns, fewer where the entries would not fit the figure's width."""
    return fig.legend(handles, labels, loc="outside lower center",
                      ncols=_legend_columns(labels, fig.get_figwidth(), ncols),
                      fontsize="small", frameon=False)


def _legend_columns(labels: Sequence[str], width: float, ncols: int) -> int:
    """How many of at most ``ncols`` columns of legend entries fit ``width`` inches."""
    from matplotlib.font_manager import FontProperties

    size = FontProperties(size="small").get_size_in_points()
    # an entry: its handle and padding (about 0.55 in) and its text (0.6 em a character)
    widths = [0.55 + 0.6 * size * len(str(s)) / 72.0 for s in labels]
    ncols = max(1, min(ncols, len(labels)))
    while ncols > 1 and sum(sorted(widths)[-ncols:]) > width - 0.2:
        ncols -= 1
    return ncols


def plot_traces(recording: Recording | Simulation, *, canal: Sequence[float] | np.ndarray | None = None,
                delta_abs: float | None = None, ax: Sequence[Any] | None = None,
                figsize: tuple[float, float] | None = None, show_source: bool = False,
                title: bool | str = True) -> Figure:
    """Plot a run's signals over time: e, u, theta_ddot_m and, if given, the canal output i.

    Parameters
    ----------
    recording : Recording or Simulation
        The run.  For a Simulation, ``canal`` defaults to its vestibular canal
        output (``channels["vestibular"]["pre"]``) and ``delta_abs`` to its
        true threshold.
    canal : array_like, optional
        The semicircular-canal output i (IPUT), one value per sample; adds a
        fourth panel.
    delta_abs : float, optional
        Threshold (IPUT, >= 0) drawn as a band +-delta_abs on the canal panel;
        needs ``canal``.  Its legend, with the share of the time |i| exceeds
        it, is above the canal panel of a new figure (where it hides no data;
        the share beside the legend, or as its title where they would overlap,
        as in a figure 3.5 in wide) and where it covers least on given axes.
    ax : sequence of matplotlib Axes, optional
        One axes per panel (3 without ``canal``, 4 with it).  Default: a new
        figure.
    figsize : (float, float), optional
        Size of the new figure, inches (default 7 in wide, 1.55 in per panel);
        not with ``ax``.
    show_source : bool, default False
        Start the title with the recording's file (``recording.source``);
        by default the title names only the task, K_theta and the duration,
        as a paper's figure would.
    title : bool or str, default True
        True: the title above the first panel (task, K_theta, duration);
        False (or ""): no title, the panels taking its room (a paper's
        figure, its caption saying what the title did); a str: that text
        as the title.  The title's own text is kept, whatever ``title``,
        in the figure's attribute ``_bayespilot_note``
        (:data:`NOTE_ATTR`), for a caption.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If ``recording`` is neither a Recording nor a Simulation, or
        ``title`` is neither a bool nor a str.
    ValueError
        If ``canal`` is not a finite 1-D array with one value per sample,
        ``delta_abs`` is negative, not finite or given without ``canal``,
        ``ax`` has the wrong number of axes, or ``figsize`` is given with
        ``ax`` or is not two positive numbers.

    Examples
    --------
    >>> from bayespilot.simulate import simulate
    >>> sim = simulate(task="FD", motion_gain=1.0, seed=1, duration=5.0)
    >>> fig = plot_traces(sim.recording, canal=sim.channels["vestibular"]["pre"], delta_abs=0.0075)
    >>> len(fig.axes)
    4
    """
    from ._labels import label, symbol

    if isinstance(recording, Simulation):
        sim = recording
        recording = sim.recording
        if canal is None and "vestibular" in sim.channels:
            canal = sim.channels["vestibular"]["pre"]
            if delta_abs is None:
                delta_abs = sim.params.get("delta_abs")
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording or Simulation, got {type(recording).__name__}")
    _title_text(title, None)  # (checked before a figure is made)
    if canal is not None:
        canal = np.asarray(canal, dtype=float)
        if canal.shape != (recording.n_samples,):
            raise ValueError(f"canal must have one value per sample, shape ({recording.n_samples},), "
                             f"got {canal.shape}")
        if not np.all(np.isfinite(canal)):
            raise ValueError("canal must be finite")
    if delta_abs is not None:
        if canal is None:
            raise ValueError("delta_abs is drawn on the canal panel; give canal too")
        try:
            delta_abs = float(delta_abs)
        except (TypeError, ValueError):
            raise ValueError(f"delta_abs must be a number, got {delta_abs!r}") from None
        if not (math.isfinite(delta_abs) and delta_abs >= 0):
            raise ValueError(f"delta_abs must be a finite number >= 0, got {delta_abs!r}")

    panels = [(recording.e, label("e", "rad"), "tracking error"),
              (recording.u, label("u", "rad"), "control output"),
              (recording.theta_ddot_m, r"$\ddot\theta_\mathrm{m}$ (rad/s$^2$)",
               "motion acceleration")]
    if canal is not None:
        panels.append((canal, label("i", "IPUT"), "canal output"))

    if ax is None:
        size = _figsize(figsize, ax, (7.0, 1.55 * len(panels) + 0.7))
        fig, axes = _new_figure(len(panels), 1, size, sharex=True)
        axes = list(np.atleast_1d(axes))
    else:
        _figsize(figsize, ax, (0.0, 0.0))
        axes = list(np.atleast_1d(np.asarray(ax, dtype=object)))
        if len(axes) != len(panels):
            raise ValueError(f"ax must hold {len(panels)} axes (one per panel: "
                             f"{', '.join(p[2] for p in panels)}), got {len(axes)}")
        fig = axes[0].figure

    t = recording.t
    for a, (y, ylabel, _) in zip(axes, panels):
        a.plot(t, y, lw=0.7, color="C0")
        a.set_ylabel(ylabel)
        a.grid(True, lw=0.3, alpha=0.6)
    if canal is not None and delta_abs is not None:
        a = axes[3]
        d = symbol("delta_abs")
        a.axhspan(-delta_abs, delta_abs, color="C3", alpha=0.2, lw=0,
                  label=rf"$\pm${d} = $\pm${delta_abs:g} IPUT")
        for level in (-delta_abs, delta_abs):
            a.axhline(level, color="C3", lw=0.6, ls="--")
        above = float(np.mean(np.abs(canal) > delta_abs))
        share = rf"$|i| > {d.strip('$')}$ {100 * above:.0f} % of the time"
        if ax is None:
            # above the panel, right of the share: nothing of the signal is under them
            shared = a.set_title(share, loc="left", fontsize="small")
            legend = a.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), borderaxespad=0.2,
                              fontsize="small", frameon=False)
        else:
            a.legend(loc="best", fontsize="small", title=share, title_fontsize="small")
    axes[-1].set_xlabel("$t$ (s)")
    axes[-1].set_xlim(t[0], t[-1])
    src = f"{recording.source}: " if show_source and recording.source else ""
    own = (f"{src}task {recording.task}, $K_\\theta$ = {recording.motion_gain:g}, "
           f"{recording.duration:g} s")
    _keep_note(fig, own)
    text = _title_text(title, own)
    if text:
        axes[0].set_title(_wrap(text, fig.get_figwidth() - 0.8, 10.0) if ax is None else text)
    if ax is None and canal is not None and delta_abs is not None:
        # a narrow figure (a column, 3.5 in): the share and the legend side by side overlap;
        # the share then heads the legend instead
        fig.draw_without_rendering()
        if shared.get_window_extent().x1 > legend.get_window_extent().x0:
            a.set_title("", loc="left")
            legend.remove()
            a.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), borderaxespad=0.2,
                     fontsize="small", frameon=False, title=share, title_fontsize="small",
                     alignment="right")
    return fig


def plot_threshold_histograms(results: Sequence[Any], *, fractions: Sequence[float] = (0.0, 0.2, 0.3),
                              method: str | None = None, bins: int = 40,
                              upper: float | str = 0.1, ax: Any = None,
                              figsize: tuple[float, float] | None = None,
                              stats: str | None = "auto", title: bool | str = True) -> Figure:
    """Histograms of the estimated threshold over realizations, after Figs. 14 and 15.

    One panel per (task, F_n, K_theta) cell present in ``results`` (rows:
    task and F_n; columns: K_theta), for the fits with threshold.  Each panel
    shows the histogram of the final delta_abs on [0, ``upper``], the true
    value (dashed line) and the +-50 % margins around it (shaded), with our
    mu, sigma and N50 and, where Figs. 14/15 have the cell, the paper's
    ("paper mu, sigma" and "(paper N50)"; the text is red where they
    differ, by :func:`bayespilot.campaign.summarise`'s flags).

    A fit whose delta_abs is not finite (a failed fit) is counted as
    "k failed" and left out of the histogram, mu and sigma, which are those of
    the finite fits; N50 counts the fits within +-50 % out of *every*
    realization of the cell, failed ones included, as the paper's "number of
    realizations out of 100" does (a failed fit is not within 50 %).
    Without failed fits every number is :func:`~bayespilot.campaign.summarise`'s.
    Fits at or above ``upper`` are drawn, hatched, in the last bin and
    counted in the panel ("≥ upper: n").  The statistics sit in the top
    right corner above the bars (the y axis is extended to make room), or
    above the panel where that corner is too small (``stats``).

    Parameters
    ----------
    results : sequence of dict
        Result dicts of :func:`bayespilot.campaign.run_job` (as from
        :func:`bayespilot.campaign.load_results`); fits without threshold are
        ignored.
    fractions : sequence of float
        The remnant fractions F_n to show (Figs. 14/15: 0, 0.2 and 0.3).
    method : {"paper", "fast"}, optional
        Which fits to show; needed when ``results`` holds both.
    bins : int
        Histogram bins on [0, ``upper``].
    upper : float or "auto"
        Right end of the delta_abs axis, IPUT.  Default 0.1, the Table 1
        bound and the axis of the paper's Figs. 10, 14 and 15 (whose bins
        are 0.005 IPUT: ``bins=20``).  ``"auto"``: a round number just above
        nearly all estimates (their 98th percentile) and the +50 % margin, so
        that the shape of a tight distribution shows (fits above it are
        counted in the last bin, as above ``upper``).
    ax : array of matplotlib Axes, optional
        One axes per panel (rows x columns as above, or flat in that order).
        Default: a new figure.
    figsize : (float, float), optional
        Size of the new figure, inches (default: 2.3 in per column and 1.75 in
        per row, at most 7.5 x 9.5 in); not with ``ax``.
    stats : {"auto", "inside", "above"} or None, default "auto"
        Where each panel's statistics go: "inside", in its top right corner,
        the y axis raised until they clear the bars; "above", over the panel,
        left-aligned, under its K_theta heading; "auto", inside unless that
        would cover bars or tick labels (a small panel, as in a figure 3.5 in
        wide), then above (every panel alike); None: none (a table gives
        them: :func:`bayespilot.campaign.summarise`).
    title : bool or str, default True
        True: the figure's title (method, Figs. 14/15, the key "≠ and red:
        differs from the paper"); False (or ""): no title, the panels taking
        its room, and the key, where a panel has the paper's values, an
        entry of the legend; a str: that text as the title (the key in the
        legend too).  The panels' K_theta headings stay: they name the
        panels.  The title's own text is kept, whatever ``title``, in the
        figure's attribute ``_bayespilot_note`` (:data:`NOTE_ATTR`).

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If ``results`` is not a sequence of dicts (a FitResult, a folder's
        name: read it with :func:`bayespilot.campaign.load_results`), or
        ``title`` is neither a bool nor a str.
    ValueError
        If a dict in ``results`` is not a campaign result (a fit's
        ``to_dict()``), no fit with threshold at the requested ``fractions`` is in
        ``results``, several methods are present and ``method`` is not given,
        ``ax`` has the wrong number of axes, ``figsize`` is given with
        ``ax`` or is not two positive numbers, or ``stats`` is not one of
        the places above.

    Examples
    --------
    >>> res = [{"task": "FD", "remnant_fraction": 0.2, "motion_gain": 1.0, "threshold": True,
    ...         "method": "fast", "true_params": {"delta_abs": 0.0075},
    ...         "fit": {"params": {"delta_abs": d}, "neg_log_lik": -1.0}}
    ...        for d in (0.006, 0.008, 0.02)]
    >>> fig = plot_threshold_histograms(res)
    >>> len(fig.axes)
    1
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from ._labels import symbol
    from .campaign import summarise

    if isinstance(bins, bool) or not isinstance(bins, (int, np.integer)) or bins < 1:
        raise ValueError(f"bins must be a positive integer, got {bins!r}")
    if not (upper == "auto" if isinstance(upper, str) else
            isinstance(upper, (int, float)) and not isinstance(upper, bool)
            and math.isfinite(upper) and upper > 0):
        raise ValueError(f"upper must be a positive number or 'auto', got {upper!r}")
    if stats not in ("auto", "inside", "above", None):
        raise ValueError(f"stats must be 'auto', 'inside', 'above' or None, got {stats!r}")
    _title_text(title, None)  # (checked before a figure is made)
    results = _campaign_results(results)
    wanted = [float(f) for f in fractions]
    sel = [r for r in results if bool(r["threshold"])
           and any(abs(float(r["remnant_fraction"]) - f) < 1e-9 for f in wanted)]
    methods = sorted({r["method"] for r in sel})
    if method is not None:
        sel = [r for r in sel if r["method"] == method]
    elif len(methods) > 1:
        raise ValueError(f"results hold fits by several methods ({', '.join(methods)}); "
                         f"choose one with method=")
    if not sel:
        raise ValueError("no fits with threshold at F_n in "
                         f"{{{', '.join(f'{f:g}' for f in wanted)}}}"
                         + (f" by the {method} method" if method else "") + " to plot")

    def _delta(r) -> float:
        return float(r["fit"]["params"]["delta_abs"])

    cells = {(r["task"], r["F_n"], r["K_theta"]): r for r in summarise(sel)}
    # mu, sigma (and their flag) of the finite fits; N50 and n of every realization
    finite_stats = {(r["task"], r["F_n"], r["K_theta"]): r
                    for r in summarise([r for r in sel if math.isfinite(_delta(r))])}
    rows = sorted({(t, f) for (t, f, _) in cells})
    cols = sorted({k for (_, _, k) in cells})

    finite = np.array([_delta(r) for r in sel], dtype=float)
    if upper == "auto":
        upper = _auto_upper(finite[np.isfinite(finite)],
                            max(float(r["true_params"]["delta_abs"]) for r in sel))
    any_over = bool(np.any(finite[np.isfinite(finite)] >= upper))
    d_sym = symbol("delta_abs")
    truths = {float(st["true_delta_abs"]) for st in cells.values()}
    # the quantity and its value with its unit, as the other figures name a true value
    true_name = (f"true {d_sym} ({truths.pop():g} IPUT)" if len(truths) == 1
                 else f"true {d_sym} (each panel's)")
    handles = [Patch(color="C2", alpha=0.25, lw=0, label=rf"true {d_sym} $\pm$50 %"),
               Line2D([], [], color="k", ls="--", lw=0.9, label=true_name)]
    if any_over:
        handles.append(Patch(facecolor="C1", alpha=0.85, hatch="////", lw=0,
                             label=f"≥ {upper:g} IPUT (in the last bin)"))
    own = (f"Estimated threshold over realizations ({sel[0]['method']} method; Figs. 14/15 "
           f"of Pool et al. 2012); ≠ and red: differs from the paper")
    title_text = _title_text(title, own)
    if title_text != own and stats is not None \
            and any(st["paper_mu"] is not None for st in cells.values()):
        # the title's key, where the title no longer gives it: in the legend
        handles.append(Line2D([], [], ls="none", marker=r"$\neq$", color="C3", ms=7,
                              label="differs from the paper (also red)"))
    labels = [h.get_label() for h in handles]

    if ax is None:
        size = _figsize(figsize, ax, (2.3 * len(cols) + 0.9, 1.75 * len(rows) + 1.1))
        if figsize is None:
            # a narrow figure: room for the wrapped title's and the legend's extra lines
            extra = 0.2 * ((len(_wrap(title_text, size[0] - 0.3, 10.0).splitlines()) - 1
                            if title_text else -1)
                           + math.ceil(len(labels) / _legend_columns(labels, size[0], 3)) - 1)
            size = _figsize(None, ax, (size[0], size[1] + extra))
        fig, axes = _new_figure(len(rows), len(cols), size, sharex=True, squeeze=False)
        axes = np.asarray(axes, dtype=object)
    else:
        _figsize(figsize, ax, (0.0, 0.0))
        flat = np.atleast_1d(np.asarray(ax, dtype=object)).ravel()
        if flat.size != len(rows) * len(cols):
            raise ValueError(f"ax must hold {len(rows) * len(cols)} axes ({len(rows)} rows of "
                             f"task and F_n x {len(cols)} columns of K_theta), got {flat.size}")
        axes = flat.reshape(len(rows), len(cols))
        fig = axes[0, 0].figure

    edges = np.linspace(0.0, upper, bins + 1)
    texts = []  # (axes, statistics, colour, bar heights): placed once the figure is laid out
    filled = []  # the panels with fits
    for i, (task, fn) in enumerate(rows):
        for j, k in enumerate(cols):
            a = axes[i, j]
            if i == 0:
                a.set_title(f"$K_\\theta$ = {k:g}", fontsize="medium")
            if j == 0:
                a.set_ylabel(f"{task}, {symbol('F_n')} = {fn:g}\ncount")
            if i == len(rows) - 1:
                a.set_xlabel(_param_label("delta_abs"))
            st = cells.get((task, fn, k))
            if st is None:
                a.text(0.5, 0.5, "no fits", ha="center", va="center", transform=a.transAxes)
                a.set_yticks([])
                continue
            d = np.array([_delta(r) for r in sel
                          if r["task"] == task and abs(float(r["remnant_fraction"]) - fn) < 1e-9
                          and abs(float(r["motion_gain"]) - k) < 1e-9])
            fin = d[np.isfinite(d)]
            failed = d.size - fin.size
            n_over = int(np.count_nonzero(fin >= upper))
            true = st["true_delta_abs"]
            a.axvspan(0.5 * true, 1.5 * true, color="C2", alpha=0.25, lw=0)
            heights, _, _ = a.hist(fin[fin < upper], bins=edges, color="C0", alpha=0.85)
            heights = np.array(heights, dtype=float)
            if n_over:
                a.bar(edges[-2], n_over, width=edges[-1] - edges[-2], bottom=heights[-1],
                      align="edge", color="C1", alpha=0.85, hatch="////", lw=0)
                heights[-1] += n_over
            a.axvline(true, color="k", ls="--", lw=0.9)
            fs = finite_stats.get((task, fn, k))
            paper = st["paper_mu"] is not None
            # short lines: four panels side by side on a page leave about 1.5 in for them
            # a value that differs from the paper's: "≠" in front, not the colour alone (grey
            # print, colour-blind readers)
            mark = {True: "≠", False: ""}
            lines = ["no finite fit"] if fs is None else [
                mark[bool(fs["flag_mu"])] + f"$\\mu$={fs['mu']:.4f}"
                + ("" if math.isnan(fs["sigma"]) else f", $\\sigma$={fs['sigma']:.4f}")]
            if paper:
                lines.append(f"paper {st['paper_mu']:.4f}, {st['paper_sigma']:.4f}")
            # (of 100 realizations, as the paper counts: "/n" only for another number)
            lines.append(mark[bool(st["flag_N50"])] + f"$N_{{50\\%}}$={st['N50']}"
                         + ("" if st["n"] == 100 else f"/{st['n']}")
                         + (f" (paper {st['paper_N50']})" if paper else ""))
            if failed:
                lines.append(f"{failed} failed" + (f" ($\\mu$, $\\sigma$ of {fs['n']})"
                                                   if fs is not None and fs["n"] > 1 else ""))
            if n_over:
                lines.append(f"≥{upper:g}: {n_over}")
            flag = st["flag_N50"] or bool(fs is not None and fs["flag_mu"])
            filled.append(a)
            if stats is not None:
                texts.append((a, "\n".join(lines), "C3" if flag else "k", heights))
            a.yaxis.get_major_locator().set_params(integer=True)
            a.set_xlim(0.0, upper)
            a.set_ylim(0.0, max(1.0, float(heights.max())) * 1.05)
            a.grid(True, lw=0.3, alpha=0.5)

    if ax is None:
        _legend_below(fig, handles, labels, ncols=3)
        if title_text:
            fig.suptitle(_wrap(title_text, fig.get_figwidth() - 0.3, 10.0), fontsize=10)
    else:
        # on a user's axes: the first panel with fits, where it covers least
        first = filled[0] if filled else axes.flat[0]
        first.legend(handles=handles, loc="best", fontsize=SMALLEST_FONT)
        if title_text:
            fig.suptitle(title_text, fontsize=10)
    _keep_note(fig, own)
    if stats is not None:
        _place_statistics(fig, edges, texts, stats)
    return fig


def _place_statistics(fig, edges: np.ndarray, texts, where: str) -> None:
    """The histograms' statistics (:func:`plot_threshold_histograms`' ``stats``): in each
    panel's top right corner, the y axis raised until they clear the bars ("inside"), or over
    the panel ("above"); "auto": inside unless that covers a bar or runs over the y tick
    labels or out of the panel in any panel, then above in every panel (unless the figure has
    no room for them there either: inside, as before)."""
    import contextlib
    import warnings

    if not texts:
        return
    if where in ("inside", "auto"):
        boxes = [(a, a.text(0.97, 0.96, text, ha="right", va="top", fontsize=SMALLEST_FONT,
                            transform=a.transAxes, color=color,
                            bbox={"facecolor": "white", "alpha": 0.75, "lw": 0, "pad": 1.0}),
                  heights) for a, text, color, heights in texts]
        ylims = [a.get_ylim() for a, _, _ in boxes]
        _clear_bars(fig, edges, boxes)
        if where == "inside" or not any(_covers(a, txt) for a, txt, _ in boxes):
            return
        for (a, txt, _), lim in zip(boxes, ylims):  # too small a corner: above the panels
            txt.set_visible(False)
            a.set_ylim(*lim)
    above = [(a, a.annotate(text, xy=(0.0, 1.0), xycoords="axes fraction", xytext=(0.0, 3.0),
                            textcoords="offset points", ha="left", va="bottom",
                            fontsize=SMALLEST_FONT, color=color, annotation_clip=False))
             for a, text, color, _ in texts]
    headed = [a for a in {id(a): a for a, _ in above}.values() if a.get_title()]
    # (auto: a layout that collapses is caught here, and the statistics go back inside)
    watch = warnings.catch_warnings(record=True) if where == "auto" else contextlib.nullcontext([])
    with watch as caught:
        if where == "auto":
            warnings.simplefilter("always")
        # the headings (K_theta, on the top row) go up above the statistics
        fig.draw_without_rendering()
        tall = max(t.get_window_extent().height for _, t in above) * 72.0 / fig.dpi
        for a in headed:
            a.set_title(a.get_title(), fontsize="medium",
                        pad=tall + 3.0 + _pyplot().rcParams["axes.titlepad"])
        fig.draw_without_rendering()
    if where == "above":
        return
    if any("collapsed" in str(w.message) for w in caught):
        # no room above either (a title of several lines over short panels): inside after all
        for a, txt in above:
            txt.remove()
        for a in headed:
            a.set_title(a.get_title(), fontsize="medium")
        for a, txt, _ in boxes:
            txt.set_visible(True)
        _clear_bars(fig, edges, boxes)
    else:
        for a, txt, _ in boxes:
            txt.remove()


def _covers(ax, txt) -> bool:
    """Whether a statistics text inside ``ax`` covers one of its bars, runs over its y tick
    labels (left of the axes) or out of it at the bottom (a panel shorter than the text)."""
    from matplotlib.patches import Rectangle

    tb, ab = txt.get_window_extent(), ax.get_window_extent()
    if tb.x0 < ab.x0 - 0.5 or tb.y0 < ab.y0 - 0.5:
        return True
    for p in ax.patches:
        if isinstance(p, Rectangle) and p.get_height() > 0 and p.get_width() > 0 \
                and p.get_facecolor()[3] > 0.5:
            pb = p.get_window_extent()
            if pb.x0 < tb.x1 - 1 and tb.x0 < pb.x1 - 1 and pb.y0 < tb.y1 - 1 and tb.y0 < pb.y1 - 1:
                return True
    return False


def _auto_upper(estimates: np.ndarray, true: float) -> float:
    """A round right end (1, 2, 2.5 or 5 x 10^k) above 98 % of ``estimates`` (times 1.05) and
    above 1.6 ``true`` (the +50 % margin and a little room), for ``upper="auto"``."""
    need = 1.6 * true
    if estimates.size:
        need = max(need, 1.05 * float(np.quantile(estimates, 0.98)))
    if not (math.isfinite(need) and need > 0):
        return 0.1
    scale = 10.0 ** math.floor(math.log10(need))
    for m in (1.0, 2.0, 2.5, 5.0, 10.0):
        if m * scale >= need * (1 - 1e-12):
            return float(f"{m * scale:.12g}")
    return 10.0 * scale


#: What every campaign result needs for :func:`plot_threshold_histograms`.
_CAMPAIGN_KEYS = ("task", "remnant_fraction", "motion_gain", "threshold", "method",
                  "true_params", "fit")
_CAMPAIGN_TAKES = ("campaign result dicts, as bayespilot.campaign.load_results(out_dir) reads "
                   "them (or bayespilot.campaign.run_job returns them)")


def _campaign_results(results: Any) -> list[Mapping[str, Any]]:
    """``results`` as a list, refused with what it takes unless it is campaign result dicts:
    a TypeError for a single result or what is not a dict (a FitResult), a ValueError for a
    dict that is not a campaign result (a fit's ``to_dict()``)."""
    if isinstance(results, (str, bytes, os.PathLike, Mapping)) or not hasattr(results,
                                                                             "__iter__"):
        raise TypeError(f"results must be a list of {_CAMPAIGN_TAKES}; got "
                        f"{type(results).__name__}"
                        + (f" {str(results)!r} (read the folder with load_results)"
                           if isinstance(results, (str, os.PathLike)) else ""))
    out = list(results)
    for i, r in enumerate(out):
        if not isinstance(r, Mapping):
            raise TypeError(f"results must be {_CAMPAIGN_TAKES}; results[{i}] is a "
                            f"{type(r).__name__}")
        missing = [k for k in _CAMPAIGN_KEYS if k not in r]
        if missing or not isinstance(r["fit"], Mapping) \
                or not isinstance(r["fit"].get("params"), Mapping):
            what = (f"lacks {', '.join(repr(k) for k in missing)}" if missing
                    else "has no 'fit' with 'params'")
            raise ValueError(f"results must be {_CAMPAIGN_TAKES}; results[{i}] is a dict that "
                             f"{what} (a fit's to_dict() is not a campaign result)")
    return out


def _clear_bars(fig, edges: np.ndarray, boxes) -> None:
    """Raise each panel's y limit until its statistics text is above the bars under it."""
    if not boxes:
        return
    # (again after a change: new y tick labels can move the axes in the layout)
    for _ in range(3):
        fig.draw_without_rendering()  # lays the figure out: the text's place on the page
        changed = False
        for a, txt, heights in boxes:
            tb, ab = txt.get_window_extent(), a.get_window_extent()
            if ab.height <= 0:
                continue
            bottom = (tb.y0 - ab.y0) / ab.height  # the text's bottom, fraction of the height
            # (a few pixels' margin: a bar just beside the text counts as under it)
            x0, x1 = a.transData.inverted().transform([[tb.x0 - 4.0, 0.0],
                                                       [tb.x1 + 4.0, 0.0]])[:, 0]
            under = heights[(edges[1:] > x0) & (edges[:-1] < x1)]
            top = float(under.max()) if under.size else 0.0
            if top <= 0:
                continue
            room = max(bottom - 0.04, 0.3)  # a tiny panel: at least the lower 30 % for bars
            lo, hi = a.get_ylim()
            if top > lo + room * (hi - lo) + 1e-9 * (hi - lo):
                a.set_ylim(lo, lo + (top - lo) / room)
                changed = True
        if not changed:
            return


# --- posteriors (bayespilot.sample) ------------------------------------------------------------
def _posterior_or_raise(posterior):
    from .sample import Posterior

    if not isinstance(posterior, Posterior):
        raise TypeError(f"posterior must be a bayespilot.sample.Posterior, got {type(posterior).__name__}")
    return posterior


def _names(names: Any) -> tuple[str, ...]:
    """``names`` of a posterior plot as a tuple: a str is one name (``"delta_abs"``, not its
    letters); anything else must be a sequence of str."""
    if isinstance(names, str):
        return (names,)
    try:
        out = tuple(names)
    except TypeError:
        raise TypeError(f"names must be a parameter name or a sequence of them, got "
                        f"{type(names).__name__}") from None
    bad = [n for n in out if not isinstance(n, str)]
    if bad:
        raise TypeError(f"names must be parameter names (str), got {bad[0]!r}")
    return out


#: The likelihoods of :func:`bayespilot.sample.sample` as a figure names them.
_LIKELIHOOD_NAMES = {"eq4": "Eq. (4) likelihood"}


def _run_note(posterior, n_draws: int) -> str:
    lik = posterior.settings.get("likelihood", "?")
    return (f"{n_draws} draws ({_LIKELIHOOD_NAMES.get(lik, f'{lik} likelihood')}, "
            f"{'converged' if posterior.converged else 'not converged'})")


def plot_marginal(posterior: Posterior, name: str = "delta_abs", truth: float | None = None,
                  ax: Any = None, *, model: Any = None,
                  figsize: tuple[float, float] | None = None,
                  title: bool | str = True) -> Figure:
    """Histogram of one parameter's posterior draws with its 90 % HDI, median and (if given) truth.

    The 90 % HDI is a black bar above the histogram (not a shaded span, so that a span
    added to the axes, such as a fit's standard error, keeps its own colour), the median
    an orange dash-dotted line and the truth a dashed black line.  The title (draws,
    likelihood, convergence) is wrapped to the width of the axes.

    Parameters
    ----------
    posterior : bayespilot.sample.Posterior
    name : str
        A sampled parameter (default the threshold).
    truth : float, optional
        The true value (simulations), drawn as a dashed line.
    ax : matplotlib Axes, optional
        Default: a new figure, with the legend under the axes; on given axes
        the legend is under the axes' x label, clear of the bars.
    model : bayespilot.model.PilotModel, optional
        The sampled model, for the unit of a parameter outside the paper's.
        Without it, a posterior of a catalogue extension of the paper's model
        (``bayespilot diagnose`` writes them) has its extension's units, any
        other Table 1's.
    figsize : (float, float), optional
        Size of the new figure, inches (default 5.5 x 3.8); not with ``ax``.
    title : bool or str, default True
        True: the axes' title (the parameter, draws, likelihood, whether the
        chain converged); False (or ""): no title, the axes taking its room;
        a str: that text as the title.  The title's own text is kept,
        whatever ``title``, in the figure's attribute ``_bayespilot_note``
        (:data:`NOTE_ATTR`), for a caption; without the title, a posterior
        that has not converged gives a
        :class:`~bayespilot.sample.ConvergenceWarning` (the figure no
        longer says so).

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If ``posterior`` is not a Posterior, or ``title`` is neither a bool
        nor a str.
    ValueError
        If ``name`` was not sampled, ``truth`` is not a finite number, or
        ``figsize`` is given with ``ax`` or is not two positive numbers.
    """
    from matplotlib.ticker import MaxNLocator

    from ._labels import symbol, unit_text

    posterior = _posterior_or_raise(posterior)
    x = posterior.draws(name)
    model = _posterior_model(posterior, model)
    _title_text(title, None)  # (checked before a figure is made)
    if truth is not None:
        try:
            truth = float(truth)
        except (TypeError, ValueError):
            raise ValueError(f"truth must be a number, got {truth!r}") from None
        if not math.isfinite(truth):
            raise ValueError(f"truth must be finite, got {truth!r}")
    lo, hi = posterior.credible_interval(name, 0.9)
    new = ax is None
    if new:
        fig, ax = _new_figure(1, 1, _figsize(figsize, None, (5.5, 3.8)))
    else:
        _figsize(figsize, ax, (0.0, 0.0))
        fig = ax.figure
    heights, edges, _ = ax.hist(x, bins=50, density=True, color="C0", alpha=0.7, lw=0)
    top = float(np.max(heights)) if len(heights) and np.max(heights) > 0 else 1.0
    # the HDI as a bar above the bars (the axes' top raised to make room)
    ax.set_ylim(0.0, 1.16 * top)
    ax.yaxis.set_major_locator(MaxNLocator(5))
    # the numbers with their unit, the truth named as every figure names it (T1)
    unit = unit_text(_param_unit(name, model))
    unit = f" {unit}" if unit else ""
    ax.plot([lo, hi], [1.08 * top] * 2, color="k", lw=3, solid_capstyle="butt",
            label=f"90 % HDI [{lo:.4g}, {hi:.4g}]{unit}")
    ax.plot([lo, hi], [1.08 * top] * 2, "|", color="k", ms=8, mew=1.2)
    med = float(np.median(x))
    ax.axvline(med, color="C1", lw=1.5, ls="-.", label=f"median {med:.4g}{unit}")
    if truth is not None:
        ax.axvline(truth, color="k", lw=1.2, ls="--",
                   label=f"true {symbol(name)} ({truth:.4g}{unit})")
    ax.set_xlabel(_param_label(name, model))
    density = "posterior density" + _per_unit(_param_unit(name, model))
    ax.set_ylabel(density)
    handles, labels = ax.get_legend_handles_labels()
    own = f"{symbol(name)}: {_run_note(posterior, x.size)}"
    _keep_note(fig, own)
    _warn_untitled(posterior, title, "plot_marginal")
    text = _title_text(title, own)
    if new:
        _legend_below(fig, handles, labels, ncols=3)
        if text:
            ax.set_title(_wrap(text, fig.get_figwidth() - 0.3, _points("medium")),
                         fontsize="medium")
    else:
        width = ax.get_position().width * fig.get_figwidth()
        if text:
            ax.set_title(_wrap(text, width, _points("medium")), fontsize="medium")
        legend = _legend_under_xlabel(ax, handles, labels, width)
        if fig.get_layout_engine() is None:
            # no layout to make room under the axes: if the legend is off the figure, it goes
            # in the upper corner, the axes' top raised until the bars and the HDI are below it
            fig.draw_without_rendering()
            if legend.get_window_extent().y0 < fig.bbox.y0:
                legend.remove()
                legend = ax.legend(handles, labels, loc="upper right", fontsize="small")
                tall = np.asarray(heights, float).copy()
                tall[(edges[1:] > lo) & (edges[:-1] < hi)] = 1.12 * top  # (the HDI bar)
                _clear_bars(fig, edges, [(ax, legend, tall)])
    if " (" in density:
        # a short figure (a column's 3.5 x 2.6 in without a title): the unit on a second line
        # rather than the label running off the figure
        fig.draw_without_rendering()
        box = ax.yaxis.label.get_window_extent()
        if box.y1 > fig.bbox.y1 + 0.5 or box.y0 < fig.bbox.y0 - 0.5:
            ax.set_ylabel(density.replace(" (", "\n(", 1))
    return fig


def _points(size: str | float) -> float:
    """A font size (a number or a name such as "medium") in points."""
    from matplotlib.font_manager import FontProperties

    return FontProperties(size=size).get_size_in_points()


def _legend_under_xlabel(ax, handles, labels, width: float):
    """The legend of a user's axes under their x label (clear of the data; constrained layout
    makes room), placed a fixed distance below the axes so that a new layout keeps it there."""
    from matplotlib.transforms import ScaledTranslation

    fig = ax.figure
    fig.draw_without_rendering()  # the tick labels' and the label's place
    below = ax.xaxis.get_tightbbox()
    drop = 0.05 if below is None else max(0.0, ax.get_window_extent().y0 - below.y0) / fig.dpi
    trans = ax.transAxes + ScaledTranslation(0.0, -(drop + 0.03), fig.dpi_scale_trans)
    return ax.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0),
                     bbox_transform=trans, borderaxespad=0.0,
                     ncols=_legend_columns(labels, width, 2), fontsize="small", frameon=False)


def plot_pair(posterior: Posterior, names: Sequence[str] = ("K_m", "tau_m", "delta_abs"),
              truth: Mapping[str, float] | None = None, ax: Any = None, *, model: Any = None,
              figsize: tuple[float, float] | None = None, title: bool | str = True) -> Figure:
    """Pairwise scatter of posterior draws (lower triangle) with marginal histograms (diagonal).

    A new figure has a title (draws, likelihood, convergence).  Where ``truth``
    gives values, a legend (in the empty upper-right panel; under the axes
    for one parameter) says that the dashed lines and crosses mark them.

    Parameters
    ----------
    posterior : bayespilot.sample.Posterior
    names : str or sequence of str
        Sampled parameters to show (at least one; a str is one name).
    truth : mapping of str to float, optional
        True values, drawn as dashed lines / crosses where given.
    ax : 2-D array of matplotlib Axes, optional
        len(names) x len(names) axes.  Default: a new figure.
    model : bayespilot.model.PilotModel, optional
        The sampled model, for the units of parameters outside the paper's
        (default: as :func:`plot_marginal` finds it).
    figsize : (float, float), optional
        Size of the new figure, inches (default: 2.3 in per panel, at most
        7.5 in wide); not with ``ax``.
    title : bool or str, default True
        True: a new figure's title, "Posterior: " with the draws, likelihood
        and convergence (none on given axes); False (or ""): no title, the
        panels taking its room; a str: that text as the figure's title (on
        given axes too).  The title's own text is kept, whatever ``title``,
        in the figure's attribute ``_bayespilot_note`` (:data:`NOTE_ATTR`);
        without the title, a posterior that has not converged gives a
        :class:`~bayespilot.sample.ConvergenceWarning`.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If ``posterior`` is not a Posterior, ``names`` is neither a str nor
        a sequence of str, or ``title`` is neither a bool nor a str.
    ValueError
        If a name was not sampled, ``names`` is empty, ``ax`` has the wrong
        shape, or ``figsize`` is given with ``ax`` or is not two positive
        numbers.
    """
    from matplotlib.lines import Line2D
    from matplotlib.ticker import MaxNLocator

    posterior = _posterior_or_raise(posterior)
    model = _posterior_model(posterior, model)
    names = _names(names)
    if not names:
        raise ValueError("names must hold at least one parameter")
    _title_text(title, None)  # (checked before a figure is made)
    draws = [posterior.draws(n) for n in names]
    truth = dict(truth or {})
    k = len(names)
    new = ax is None
    if new:
        side = min(2.3, (PAGE_WIDTH - 0.7) / k)  # per panel
        fig, axes = _new_figure(k, k, _figsize(figsize, None, (side * k + 0.7, side * k + 0.9)),
                                squeeze=False)
    else:
        _figsize(figsize, ax, (0.0, 0.0))
        axes = np.asarray(ax, dtype=object)
        if axes.size != k * k:
            raise ValueError(f"ax must hold {k} x {k} axes, got {axes.size}")
        axes = axes.reshape(k, k)
        fig = axes[0, 0].figure
    panel = min(fig.get_figwidth(), fig.get_figheight()) / k
    small = panel < 1.5  # many panels: fewer, smaller ticks
    labels = [_param_label(n, model) for n in names]
    # one range per parameter, shared by its column (x) and its row (y): tick labels only
    # on the outer panels, so the panels keep their room
    lims = []
    for n, x in zip(names, draws):
        lo, hi = float(np.min(x)), float(np.max(x))
        if n in truth:
            lo, hi = min(lo, float(truth[n])), max(hi, float(truth[n]))
        pad = 0.05 * (hi - lo) if hi > lo else 0.05 * max(abs(lo), 1.0)
        lims.append((lo - pad, hi + pad))
    marked_line = marked_cross = False
    for i in range(k):
        for j in range(k):
            a = axes[i, j]
            if j > i:
                a.set_axis_off()
                continue
            if i == j:
                a.hist(draws[i], bins=40, color="C0", alpha=0.7, lw=0)
                a.set_yticks([])
                if names[i] in truth:
                    a.axvline(truth[names[i]], color="k", ls="--", lw=1)
                    marked_line = True
            else:
                a.plot(draws[j], draws[i], ".", ms=1.5, color="C0", alpha=0.3, rasterized=True)
                if names[i] in truth and names[j] in truth:
                    a.plot(truth[names[j]], truth[names[i]], "kx", ms=7 if not small else 5,
                           mew=1.5)
                    marked_cross = True
            a.set_xlim(*lims[j])
            if i != j:
                a.set_ylim(*lims[i])
            # few ticks on every panel: a panel's width holds 3-4 labels of 5-6 digits
            a.xaxis.set_major_locator(MaxNLocator(3 if small else 4))
            if i != j:
                a.yaxis.set_major_locator(MaxNLocator(3 if small else 4))
            if small:
                a.tick_params(labelsize=SMALLEST_FONT)
            if i == k - 1:
                a.set_xlabel(labels[j], fontsize=SMALLEST_FONT + 1 if small else None)
                if small:
                    a.tick_params(axis="x", labelrotation=45)
            else:
                a.tick_params(labelbottom=False)
            if j == 0 and i > 0:
                a.set_ylabel(labels[i], fontsize=SMALLEST_FONT + 1 if small else None)
            elif i != j:
                a.tick_params(labelleft=False)
    if not small:
        _unclash_ticks(fig, axes[k - 1, :])
    handles = []
    if marked_line:
        handles.append(Line2D([], [], color="k", ls="--", lw=1, label="true value (histograms)"))
    if marked_cross:
        handles.append(Line2D([], [], color="k", marker="x", ls="none", ms=7, mew=1.5,
                              label="true values (scatter)"))
    if handles:
        if k > 1:
            # in the empty upper triangle, from its right corner leftwards; not laid out (the
            # layout would widen the last column to hold it)
            axes[0, k - 1].legend(handles=handles, loc="upper right", fontsize="small",
                                  frameon=False, borderaxespad=0.0).set_in_layout(False)
        elif new:
            _legend_below(fig, handles, [h.get_label() for h in handles], ncols=2)
        else:
            axes[0, 0].legend(handles=handles, loc="best", fontsize="small")
    own = f"Posterior: {_run_note(posterior, draws[0].size)}"
    _keep_note(fig, own)
    _warn_untitled(posterior, title, "plot_pair")
    text = _title_text(title, own)
    # (given axes: a title only when the caller names one; numpy's True is True)
    if text and (new or isinstance(title, str)):
        fig.suptitle(_wrap(text, fig.get_figwidth() - 0.3, 10.0), fontsize=10)
    return fig


def _unclash_ticks(fig, row) -> None:
    """Rotate the x tick labels of a row of axes by 45 degrees where two of them overlap or
    nearly touch (less than half a character apart: "0.19750.2000" reads as one number)."""
    fig.draw_without_rendering()
    for a in row:
        labels = [t for t in a.get_xticklabels() if t.get_visible() and t.get_text()]
        if len(labels) < 2:
            continue
        gap = 0.3 * labels[0].get_fontsize() * fig.dpi / 72.0  # pixels
        boxes = sorted((t.get_window_extent() for t in labels), key=lambda b: b.x0)
        if any(b1.x0 < b0.x1 + gap for b0, b1 in zip(boxes, boxes[1:])):
            a.tick_params(axis="x", labelrotation=45)


def plot_chains(posterior: Posterior, names: Sequence[str] | None = None,
                ax: Sequence[Any] | None = None, *, model: Any = None,
                figsize: tuple[float, float] | None = None, title: bool | str = True) -> Figure:
    """Retained draws of every walker against the step number, one panel per parameter, and lp.

    The x axis is the step of the full chain (burn-in ``discard`` and the
    thinning ``thin`` of the Posterior undone), so panels line up with tau,
    each parameter's integrated autocorrelation time, written above its panel.
    The last panel is the log posterior up to a constant (the prior's and the
    likelihood's normalisation left out).

    The y labels are aligned; where they would run into each other (short
    panels), the log posterior's is ``$\\ln p$``, and if they still would
    (a figure 3.5 in wide and 6 in tall with the paper's eight parameters)
    every parameter's is its symbol only (the units then belong in the
    caption).  The title is on the left above the
    first panel, or, where it would run into that panel's autocorrelation
    time (a narrow figure), above the figure.

    Parameters
    ----------
    posterior : bayespilot.sample.Posterior
    names : str or sequence of str, optional
        Parameters to show (default: all sampled; a str is one name).
    ax : sequence of matplotlib Axes, optional
        len(names) + 1 axes (the last for the log posterior).  Default: a new figure.
    model : bayespilot.model.PilotModel, optional
        The sampled model, for the units of parameters outside the paper's
        (default: as :func:`plot_marginal` finds it).
    figsize : (float, float), optional
        Size of the new figure, inches (default 7 in wide, about 1 in per
        panel, at most 9.5 in tall); not with ``ax``.
    title : bool or str, default True
        True: the title (walkers, steps, whether the chain converged); False
        (or ""): no title, the panels taking its room; a str: that text as
        the title.  The title's own text is kept, whatever ``title``, in the
        figure's attribute ``_bayespilot_note`` (:data:`NOTE_ATTR`); without
        the title, a posterior that has not converged gives a
        :class:`~bayespilot.sample.ConvergenceWarning`.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If ``posterior`` is not a Posterior, ``names`` is neither a str nor
        a sequence of str, or ``title`` is neither a bool nor a str.
    ValueError
        If a name was not sampled, ``ax`` has the wrong number of axes, or
        ``figsize`` is given with ``ax`` or is not two positive numbers.
    """
    posterior = _posterior_or_raise(posterior)
    model = _posterior_model(posterior, model)
    names = posterior.parameter_names if names is None else _names(names)
    for n in names:
        posterior.draws(n)  # validates the name
    _title_text(title, None)  # (checked before a figure is made)
    post = posterior.idata.posterior
    discard = int(posterior.settings.get("discard", 0))
    thin = int(posterior.settings.get("thin", 1))
    n_panels = len(names) + 1
    if ax is None:
        size = _figsize(figsize, ax, (7.0, 1.05 * n_panels + 0.8))
        fig, axes = _new_figure(n_panels, 1, size, sharex=True)
        axes = list(np.atleast_1d(axes))
    else:
        _figsize(figsize, ax, (0.0, 0.0))
        axes = list(np.atleast_1d(np.asarray(ax, dtype=object)))
        if len(axes) != n_panels:
            raise ValueError(f"ax must hold {n_panels} axes (one per parameter and one for lp), "
                             f"got {len(axes)}")
        fig = axes[0].figure
    from ._labels import symbol

    # (each panel's label in full, and short: the symbol alone, for a panel too short for it)
    series = [(n, (_param_label(n, model), symbol(n)), np.asarray(post[n].values, float))
              for n in names]
    series.append(("lp", ("log posterior\n(+ const.)", r"$\ln p$"),
                   np.asarray(posterior.idata.sample_stats["lp"].values, float)))
    notes = {}
    for a, (name, ylabels, v) in zip(axes, series):
        steps = discard + thin * np.arange(v.shape[1])
        a.plot(steps, v.T, lw=0.4, alpha=0.5, color="C0")
        a.set_ylabel(ylabels[0])
        tau = posterior.tau.get(name) if name != "lp" else None
        if tau is not None and math.isfinite(tau):
            # above the top spine, right-aligned (the panel's title, if any, is on the left)
            notes[a] = a.annotate(f"autocorrelation time {tau:.0f} steps", xy=(1.0, 1.0),
                                  xycoords="axes fraction", xytext=(0.0, 2.0),
                                  textcoords="offset points", ha="right", va="bottom",
                                  fontsize=SMALLEST_FONT)
        a.grid(True, lw=0.3, alpha=0.6)
    axes[-1].set_xlabel("step")
    own = (f"{len(series[0][2])} walkers, {posterior.settings.get('n_steps', '?')} steps, "
           f"{'converged' if posterior.converged else 'not converged'}")
    _keep_note(fig, own)
    _warn_untitled(posterior, title, "plot_chains")
    text = _title_text(title, own)
    if text:
        head = axes[0].set_title(text, fontsize="medium", loc="left")
        note = notes.get(axes[0])
        if note is not None:
            fig.draw_without_rendering()
            if head.get_window_extent().x1 > note.get_window_extent().x0 - 4.0:
                # beside the autocorrelation time there is no room: above the figure (a new
                # one, laid out to make room), or wrapped to the room left (a user's axes)
                ab = axes[0].get_window_extent()
                room = (note.get_window_extent().x0 - ab.x0) / fig.dpi - 0.1
                if ax is None or room < 1.0:
                    head.set_text("")
                    fig.suptitle(_wrap(text, fig.get_figwidth() - 0.3, _points("medium")),
                                 fontsize="medium")
                else:
                    head.set_text(_wrap(text, room, _points("medium")))
    # labels in one column; where two run into each other (short panels: rotated, a label's
    # length is upright), every label is the short one (units in the caption, not some here)
    # (first the log posterior's, the longest, then every parameter's)
    fig.align_ylabels(axes)
    if _labels_clash(fig, axes):
        axes[-1].set_ylabel(series[-1][1][1])
        if _labels_clash(fig, axes):
            for a, (_, ylabels, _) in zip(axes, series):
                a.set_ylabel(ylabels[1])
    return fig


def _labels_clash(fig, axes) -> bool:
    """Whether, the figure laid out, two of the y labels of ``axes`` (a column of panels)
    overlap or one runs off the figure."""
    fig.draw_without_rendering()
    boxes = [a.yaxis.label.get_window_extent() for a in axes if a.yaxis.label.get_text()]
    page = fig.bbox
    if any(b.y0 < page.y0 - 0.5 or b.y1 > page.y1 + 0.5 for b in boxes):
        return True
    return any(b0.overlaps(b1) for i, b0 in enumerate(boxes) for b1 in boxes[i + 1:])


__all__ += ["plot_marginal", "plot_pair", "plot_chains"]

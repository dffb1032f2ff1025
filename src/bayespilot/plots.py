"""Figures of recordings and results.

Every function here takes results (a :class:`~bayespilot.recording.Recording`,
a :class:`~bayespilot.simulate.Simulation`, arrays), draws on the axes it is
given or on a new figure, and returns the figure.  Nothing here calls
``plt.show()``; matplotlib is imported only when a figure is drawn, so
``import bayespilot`` stays cheap.
"""

from __future__ import annotations

import math
import os
import sys
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from .recording import Recording
from .simulate import Simulation

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

    from .sample import Posterior

__all__ = ["plot_traces", "plot_threshold_histograms"]


def _pyplot():
    """matplotlib.pyplot, on the Agg backend when there is no display to draw on."""
    import matplotlib

    headless = (sys.platform.startswith("linux")
                and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"))
    if headless and "matplotlib.pyplot" not in sys.modules:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_traces(recording: Recording | Simulation, *, canal: Sequence[float] | np.ndarray | None = None,
                delta_abs: float | None = None, ax: Sequence[Any] | None = None) -> Figure:
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
        needs ``canal``.
    ax : sequence of matplotlib Axes, optional
        One axes per panel (3 without ``canal``, 4 with it).  Default: a new
        figure.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If ``recording`` is neither a Recording nor a Simulation.
    ValueError
        If ``canal`` is not a finite 1-D array with one value per sample,
        ``delta_abs`` is negative, not finite or given without ``canal``, or
        ``ax`` has the wrong number of axes.

    Examples
    --------
    >>> from bayespilot.simulate import simulate
    >>> sim = simulate(task="FD", motion_gain=1.0, seed=1, duration=5.0)
    >>> fig = plot_traces(sim.recording, canal=sim.channels["vestibular"]["pre"], delta_abs=0.0075)
    >>> len(fig.axes)
    4
    """
    if isinstance(recording, Simulation):
        sim = recording
        recording = sim.recording
        if canal is None and "vestibular" in sim.channels:
            canal = sim.channels["vestibular"]["pre"]
            if delta_abs is None:
                delta_abs = sim.params.get("delta_abs")
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording or Simulation, got {type(recording).__name__}")
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

    panels = [(recording.e, "e (rad)", "tracking error"),
              (recording.u, "u (rad)", "control output"),
              (recording.theta_ddot_m, r"$\ddot\theta_m$ (rad/s$^2$)", "motion acceleration")]
    if canal is not None:
        panels.append((canal, "i (IPUT)", "canal output"))

    if ax is None:
        plt = _pyplot()
        fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(9.0, 2.0 * len(panels) + 0.8),
                                 layout="constrained")
        axes = list(np.atleast_1d(axes))
    else:
        axes = list(np.atleast_1d(np.asarray(ax, dtype=object)))
        if len(axes) != len(panels):
            raise ValueError(f"ax must hold {len(panels)} axes (one per panel: "
                             f"{', '.join(p[2] for p in panels)}), got {len(axes)}")
        fig = axes[0].figure

    t = recording.t
    for a, (y, label, _) in zip(axes, panels):
        a.plot(t, y, lw=0.7, color="C0")
        a.set_ylabel(label)
        a.grid(True, lw=0.3, alpha=0.6)
    if canal is not None and delta_abs is not None:
        a = axes[3]
        a.axhspan(-delta_abs, delta_abs, color="C3", alpha=0.2, lw=0,
                  label=rf"$\pm\delta_{{abs}}$ = $\pm${delta_abs:g}")
        for level in (-delta_abs, delta_abs):
            a.axhline(level, color="C3", lw=0.6, ls="--")
        above = float(np.mean(np.abs(canal) > delta_abs))
        a.legend(loc="upper right", fontsize="small",
                 title=f"|i| > threshold {100 * above:.0f}% of the time",
                 title_fontsize="small")
    axes[-1].set_xlabel("t (s)")
    axes[-1].set_xlim(t[0], t[-1])
    src = f"{recording.source}: " if recording.source else ""
    axes[0].set_title(f"{src}task {recording.task}, $K_\\theta$ = {recording.motion_gain:g}, "
                      f"{recording.duration:g} s")
    return fig


def plot_threshold_histograms(results: Sequence[Any], *, fractions: Sequence[float] = (0.0, 0.2, 0.3),
                              method: str | None = None, bins: int = 40,
                              upper: float = 0.1, ax: Any = None) -> Figure:
    """Histograms of the estimated threshold over realizations, after Figs. 14 and 15.

    One panel per (task, F_n, K_theta) cell present in ``results`` (rows:
    task and F_n; columns: K_theta), for the fits with threshold.  Each panel
    shows the histogram of the final delta_abs on [0, ``upper``], the true
    value (dashed line) and the +-50 % margins around it (shaded), with our
    mu, sigma and N50 and, where Figs. 14/15 have the cell, the paper's.

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
    upper : float
        Right end of the delta_abs axis, IPUT (Table 1 bound: 0.1).
    ax : array of matplotlib Axes, optional
        One axes per panel (rows x columns as above, or flat in that order).
        Default: a new figure.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ValueError
        If no fit with threshold at the requested ``fractions`` is in
        ``results``, several methods are present and ``method`` is not given,
        or ``ax`` has the wrong number of axes.

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
    from .campaign import summarise

    if isinstance(bins, bool) or not isinstance(bins, (int, np.integer)) or bins < 1:
        raise ValueError(f"bins must be a positive integer, got {bins!r}")
    if not (isinstance(upper, (int, float)) and math.isfinite(upper) and upper > 0):
        raise ValueError(f"upper must be a positive number, got {upper!r}")
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
    stats = {(r["task"], r["F_n"], r["K_theta"]): r for r in summarise(sel)}
    rows = sorted({(t, f) for (t, f, _) in stats})
    cols = sorted({k for (_, _, k) in stats})

    if ax is None:
        plt = _pyplot()
        fig, axes = plt.subplots(len(rows), len(cols), sharex=True, squeeze=False,
                                 figsize=(2.9 * len(cols) + 0.6, 2.1 * len(rows) + 0.8),
                                 layout="constrained")
        axes = np.asarray(axes, dtype=object)
    else:
        flat = np.atleast_1d(np.asarray(ax, dtype=object)).ravel()
        if flat.size != len(rows) * len(cols):
            raise ValueError(f"ax must hold {len(rows) * len(cols)} axes ({len(rows)} rows of "
                             f"task and F_n x {len(cols)} columns of K_theta), got {flat.size}")
        axes = flat.reshape(len(rows), len(cols))
        fig = axes[0, 0].figure

    edges = np.linspace(0.0, upper, bins + 1)
    for i, (task, fn) in enumerate(rows):
        for j, k in enumerate(cols):
            a = axes[i, j]
            st = stats.get((task, fn, k))
            if st is None:
                a.text(0.5, 0.5, "no fits", ha="center", va="center", transform=a.transAxes)
                a.set_yticks([])
                continue
            d = np.array([float(r["fit"]["params"]["delta_abs"]) for r in sel
                          if r["task"] == task and abs(float(r["remnant_fraction"]) - fn) < 1e-9
                          and abs(float(r["motion_gain"]) - k) < 1e-9])
            true = st["true_delta_abs"]
            a.axvspan(0.5 * true, 1.5 * true, color="C2", alpha=0.25, lw=0,
                      label=r"true $\pm$50 %")
            a.hist(np.clip(d, 0.0, upper), bins=edges, color="C0", alpha=0.85)
            a.axvline(true, color="k", ls="--", lw=0.9, label="true")
            sig = "" if math.isnan(st["sigma"]) else f", $\\sigma$={st['sigma']:.4f}"
            text = (f"$\\mu$={st['mu']:.4f}{sig}\nN50={st['N50']}/{st['n']}")
            if st["paper_mu"] is not None:
                text += (f"\npaper: {st['paper_mu']:.4f}, {st['paper_sigma']:.4f}, "
                         f"{st['paper_N50']}%")
            a.text(0.97, 0.95, text, ha="right", va="top", fontsize="x-small",
                   transform=a.transAxes, color="C3" if st["flag"] else "k",
                   bbox={"facecolor": "white", "alpha": 0.75, "lw": 0, "pad": 1.5})
            a.yaxis.get_major_locator().set_params(integer=True)
            a.set_xlim(0.0, upper)
            a.grid(True, lw=0.3, alpha=0.5)
            if i == 0:
                a.set_title(f"$K_\\theta$ = {k:g}", fontsize="medium")
            if j == 0:
                a.set_ylabel(f"{task}, $F_n$ = {fn:g}\ncount")
            if i == len(rows) - 1:
                a.set_xlabel(r"$\delta_{abs}$ (IPUT)")
    # the legend on the first panel that has fits (a panel may say "no fits")
    for a in axes.flat:
        if a.get_legend_handles_labels()[0]:
            a.legend(loc="center right", fontsize="x-small")
            break
    which = sel[0]["method"]
    fig.suptitle(f"Estimated threshold over realizations ({which} method; Figs. 14/15 of "
                 f"Pool et al. 2012); red text: differs from the paper")
    return fig


# --- posteriors (bayespilot.sample) ------------------------------------------------------------
def _posterior_or_raise(posterior):
    from .sample import Posterior

    if not isinstance(posterior, Posterior):
        raise TypeError(f"posterior must be a bayespilot.sample.Posterior, got {type(posterior).__name__}")
    return posterior


def plot_marginal(posterior: Posterior, name: str = "delta_abs", truth: float | None = None,
                  ax: Any = None) -> Figure:
    """Histogram of one parameter's posterior draws with its 90 % HDI, median and (if given) truth.

    Parameters
    ----------
    posterior : bayespilot.sample.Posterior
    name : str
        A sampled parameter (default the threshold).
    truth : float, optional
        The true value (simulations), drawn as a dashed line.
    ax : matplotlib Axes, optional
        Default: a new figure.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If ``posterior`` is not a Posterior.
    ValueError
        If ``name`` was not sampled, or ``truth`` is not a finite number.
    """
    posterior = _posterior_or_raise(posterior)
    x = posterior.draws(name)
    if truth is not None:
        try:
            truth = float(truth)
        except (TypeError, ValueError):
            raise ValueError(f"truth must be a number, got {truth!r}") from None
        if not math.isfinite(truth):
            raise ValueError(f"truth must be finite, got {truth!r}")
    lo, hi = posterior.credible_interval(name, 0.9)
    if ax is None:
        plt = _pyplot()
        fig, ax = plt.subplots(figsize=(5.5, 3.6), layout="constrained")
    else:
        fig = ax.figure
    ax.hist(x, bins=50, density=True, color="C0", alpha=0.7, lw=0)
    ax.axvspan(lo, hi, color="C0", alpha=0.15, lw=0, label=f"90% HDI [{lo:.4g}, {hi:.4g}]")
    med = float(np.median(x))
    ax.axvline(med, color="C0", lw=1.2, label=f"median {med:.4g}")
    if truth is not None:
        ax.axvline(truth, color="k", lw=1.2, ls="--", label=f"truth {truth:.4g}")
    ax.set_xlabel(name)
    ax.set_ylabel("posterior density")
    ax.legend(loc="best", fontsize="small")
    ax.set_title(f"{name}: {x.size} draws ({posterior.settings.get('likelihood', '?')} likelihood, "
                 f"{'converged' if posterior.converged else 'not converged'})", fontsize="medium")
    return fig


def plot_pair(posterior: Posterior, names: Sequence[str] = ("K_m", "tau_m", "delta_abs"),
              truth: Mapping[str, float] | None = None, ax: Any = None) -> Figure:
    """Pairwise scatter of posterior draws (lower triangle) with marginal histograms (diagonal).

    Parameters
    ----------
    posterior : bayespilot.sample.Posterior
    names : sequence of str
        Sampled parameters to show (at least one).
    truth : mapping of str to float, optional
        True values, drawn as dashed lines / crosses where given.
    ax : 2-D array of matplotlib Axes, optional
        len(names) x len(names) axes.  Default: a new figure.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If ``posterior`` is not a Posterior.
    ValueError
        If a name was not sampled, ``names`` is empty, or ``ax`` has the wrong shape.
    """
    posterior = _posterior_or_raise(posterior)
    names = tuple(names)
    if not names:
        raise ValueError("names must hold at least one parameter")
    draws = [posterior.draws(n) for n in names]
    truth = dict(truth or {})
    k = len(names)
    if ax is None:
        plt = _pyplot()
        fig, axes = plt.subplots(k, k, figsize=(2.4 * k + 0.6, 2.4 * k + 0.4), squeeze=False,
                                 layout="constrained")
    else:
        axes = np.asarray(ax, dtype=object)
        if axes.size != k * k:
            raise ValueError(f"ax must hold {k} x {k} axes, got {axes.size}")
        axes = axes.reshape(k, k)
        fig = axes[0, 0].figure
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
            else:
                a.plot(draws[j], draws[i], ".", ms=1.5, color="C0", alpha=0.3, rasterized=True)
                if names[i] in truth and names[j] in truth:
                    a.plot(truth[names[j]], truth[names[i]], "kx", ms=7, mew=1.5)
            if i == k - 1:
                a.set_xlabel(names[j])
            if j == 0 and i > 0:
                a.set_ylabel(names[i])
    return fig


def plot_chains(posterior: Posterior, names: Sequence[str] | None = None,
                ax: Sequence[Any] | None = None) -> Figure:
    """Retained draws of every walker against the step number, one panel per parameter, and lp.

    The x axis is the step of the full chain (burn-in ``discard`` and the
    thinning ``thin`` of the Posterior undone), so panels line up with tau.

    Parameters
    ----------
    posterior : bayespilot.sample.Posterior
    names : sequence of str, optional
        Parameters to show (default: all sampled).
    ax : sequence of matplotlib Axes, optional
        len(names) + 1 axes (the last for the log posterior).  Default: a new figure.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    TypeError
        If ``posterior`` is not a Posterior.
    ValueError
        If a name was not sampled, or ``ax`` has the wrong number of axes.
    """
    posterior = _posterior_or_raise(posterior)
    names = posterior.parameter_names if names is None else tuple(names)
    for n in names:
        posterior.draws(n)  # validates the name
    post = posterior.idata.posterior
    discard = int(posterior.settings.get("discard", 0))
    thin = int(posterior.settings.get("thin", 1))
    n_panels = len(names) + 1
    if ax is None:
        plt = _pyplot()
        fig, axes = plt.subplots(n_panels, 1, sharex=True, figsize=(8.0, 1.3 * n_panels + 0.8),
                                 layout="constrained")
        axes = list(np.atleast_1d(axes))
    else:
        axes = list(np.atleast_1d(np.asarray(ax, dtype=object)))
        if len(axes) != n_panels:
            raise ValueError(f"ax must hold {n_panels} axes (one per parameter and one for lp), "
                             f"got {len(axes)}")
        fig = axes[0].figure
    series = [(n, np.asarray(post[n].values, float)) for n in names]
    series.append(("lp", np.asarray(posterior.idata.sample_stats["lp"].values, float)))
    for a, (label, v) in zip(axes, series):
        steps = discard + thin * np.arange(v.shape[1])
        a.plot(steps, v.T, lw=0.4, alpha=0.5, color="C0")
        a.set_ylabel(label)
        tau = posterior.tau.get(label)
        if tau is not None and math.isfinite(tau):
            a.text(1.0, 1.0, f"tau = {tau:.0f}", transform=a.transAxes, ha="right", va="top",
                   fontsize="x-small")
        a.grid(True, lw=0.3, alpha=0.6)
    axes[-1].set_xlabel("step")
    axes[0].set_title(f"{len(series[0][1])} walkers, {posterior.settings.get('n_steps', '?')} steps, "
                      f"{'converged' if posterior.converged else 'NOT converged'}", fontsize="medium")
    return fig


__all__ += ["plot_marginal", "plot_pair", "plot_chains"]

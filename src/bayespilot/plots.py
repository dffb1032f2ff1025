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
from typing import Any, Sequence

import numpy as np

from .recording import Recording
from .simulate import Simulation

__all__ = ["plot_traces"]


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
                delta_abs: float | None = None, ax: Sequence[Any] | None = None):
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

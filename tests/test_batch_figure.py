"""fit-batch's summary figure (:func:`bayespilot.batch._plot_summary`) stays legible for many
conditions (scale audit, finding 4: at 60 conditions and more the figure stayed a page wide,
its condition names overlapped into a black band and its legend covered runs).

Everything is measured on the drawn figure: the boxes of the tick labels as the renderer
draws them, the legend's box against each run's marker (its centre and radius) and each
posterior bar, all in display pixels.  The runs are made up here (no fits run): the places
they must be drawn at are worked out by hand from their keys' order.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bayespilot.batch import _plot_summary

TASKS, GAINS = ("FD", "FT"), (0.0, 0.5, 1.0)


def _batch(n: int, runs: int = 3, subject: str = "s", decisions: bool = False):
    """``(rows, conditions)`` as ``fit_batch`` writes them for ``n`` conditions (a subject's
    six: two tasks, three K_theta) of ``runs`` runs each: delta_abs spread over 0 .. 0.09
    (some exactly 0), delta_bic of both signs, the first run of each with a posterior HDI."""
    rng = np.random.default_rng(n)
    conditions, rows = [], []
    for i in range(n):
        who, task, gain = f"{subject}{i // 6 + 1:02d}", TASKS[(i // 3) % 2], GAINS[i % 3]
        conditions.append({"subject": who, "task": task, "motion_gain": gain,
                           "label": f"{who}, {task}, K_theta = {gain:g}"})
        for r in range(runs):
            d = 0.0 if (i + r) % 7 == 0 else float(rng.uniform(0.0, 0.09))
            rows.append({"key": f"{who}_{task}_K{gain:g}_r{r}", "subject": who, "task": task,
                         "motion_gain": gain, "delta_abs": d,
                         "delta_bic": float(rng.normal(2.0, 4.0)), "error": "",
                         "decision": (("threshold", "none", "inconclusive")[(i + r) % 3]
                                      if decisions else ""),
                         "delta_abs_posterior_hdi_low": max(d - 0.01, 0.0) if r == 0 else "",
                         "delta_abs_posterior_hdi_high": d + 0.012 if r == 0 else ""})
    return rows, conditions


def _shown(c) -> str:
    """A condition's name as the figure writes it."""
    return c["label"].replace("K_theta", r"$K_\theta$")


def _drawn(fig):
    fig.canvas.draw()
    return fig.canvas.get_renderer()


def _tick_labels(ax):
    return [t for t in (*ax.get_xticklabels(), *ax.get_yticklabels())
            if t.get_visible() and t.get_text()]


def _overlapping_labels(fig, ax) -> list[tuple[str, str]]:
    renderer = _drawn(fig)
    labels = _tick_labels(ax)
    boxes = [t.get_window_extent(renderer) for t in labels]
    return [(labels[i].get_text(), labels[j].get_text()) for i in range(len(boxes))
            for j in range(i + 1, len(boxes)) if boxes[i].overlaps(boxes[j])]


def _covered_by_legend(fig, ax) -> list[str]:
    """The runs (markers, bars) the legend's box covers, as drawn."""
    from matplotlib.collections import PathCollection

    renderer = _drawn(fig)
    (legend,) = [lg for lg in (ax.get_legend(), *fig.legends) if lg is not None]
    box = legend.get_window_extent(renderer)
    covered = []
    for c in ax.collections:
        if not isinstance(c, PathCollection):
            continue
        centres = c.get_offset_transform().transform(c.get_offsets())
        radius = math.sqrt(float(np.max(c.get_sizes()))) / 2 * fig.dpi / 72  # (pt**2 -> px)
        for px, py in centres:
            if (box.x0 - radius <= px <= box.x1 + radius
                    and box.y0 - radius <= py <= box.y1 + radius):
                covered.append(f"{c.get_label()} at ({px:.0f}, {py:.0f}) px")
    for bars in ax.containers:
        for lines in bars.lines[2]:
            for (x0, y0), (x1, y1) in lines.get_segments():
                t = np.linspace(0.0, 1.0, 50)[:, None]
                along = ax.transData.transform(np.hstack([x0 + t * (x1 - x0),
                                                          y0 + t * (y1 - y0)]))
                if any(box.contains(px, py) for px, py in along):
                    covered.append(f"the bar at ({x0:g}, {y0:g})")
    return covered


@pytest.mark.parametrize("n", [3, 60, 240])
def test_every_condition_is_named_clear_of_the_others_and_the_legend_clear_of_the_runs(n):
    """3 conditions (columns, as before), 60 (10 subjects: 180 recordings) and 240 (720
    recordings): every condition named, no two names' boxes overlapping, the legend outside
    the axes and over no run's marker or bar.  Before, the figure stayed 7.5 x 4 in: at 60
    conditions 409 pairs of names overlapped and the legend covered 6 runs."""
    rows, conditions = _batch(n)
    fig = _plot_summary(rows, conditions)
    ax = fig.axes[0]
    named = [t.get_text() for t in _tick_labels(ax)]
    assert [s for s in named if s in {_shown(c) for c in conditions}] == [
        _shown(c) for c in conditions]  # each once, in the conditions' order
    assert _overlapping_labels(fig, ax) == []
    assert _covered_by_legend(fig, ax) == []
    legend = ax.get_legend().get_window_extent()
    assert not legend.overlaps(ax.get_window_extent())  # (outside the data, wherever it is)
    w, h = fig.get_size_inches()
    if n == 3:  # the small figure keeps its size (a column of about an inch per condition)
        assert (w, h) == (4.8, 4.0)
    else:  # a page wide, growing with the conditions: at least 0.14 in of axes per row
        assert w == 7.5 and h <= 60.0
        assert ax.get_window_extent().height / fig.dpi / n >= 0.14


def test_beyond_60_inches_every_kth_condition_is_named():
    """960 conditions (2880 recordings): the figure stops at 60 in (matplotlib draws at
    most 2**16 pixels a side) and names every 4th condition (a row of the axes is 0.062 in,
    a name needs 0.19), a tick on every row; still no two names overlapping."""
    rows, conditions = _batch(960)
    fig = _plot_summary(rows, conditions)
    ax = fig.axes[0]
    assert tuple(fig.get_size_inches()) == (7.5, 60.0)
    assert [t.get_text() for t in ax.get_yticklabels()] == [_shown(c) for c in conditions[::4]]
    assert list(ax.get_yticks()) == list(range(0, 960, 4))
    assert sorted([*ax.get_yticks(), *ax.get_yticks(minor=True)]) == list(range(960))
    assert _overlapping_labels(fig, ax) == []
    assert _covered_by_legend(fig, ax) == []


def test_a_few_conditions_keep_their_columns_with_the_legend_under_their_names():
    """Six conditions (a subject): the figure of before, 7.5 x 4 in, a column each, the names
    at 30 degrees; the legend, which was inside the axes (over a run here), now under the
    names."""
    rows, conditions = _batch(6)
    fig = _plot_summary(rows, conditions)
    ax = fig.axes[0]
    assert tuple(fig.get_size_inches()) == (7.5, 4.0)
    names = ax.get_xticklabels()
    assert [t.get_text() for t in names] == [_shown(c) for c in conditions]
    assert {t.get_rotation() for t in names} == {30.0}
    assert _overlapping_labels(fig, ax) == []
    assert _covered_by_legend(fig, ax) == []
    legend = ax.get_legend().get_window_extent()
    assert legend.y1 <= min(t.get_window_extent().y0 for t in names)


def test_names_too_long_for_columns_get_rows():
    """Three conditions whose names (long subject names) do not fit side by side, level or
    at 30 degrees: a row each (before, the level names overlapped)."""
    rows, conditions = _batch(3, subject="participant-0001-visit-")
    fig = _plot_summary(rows, conditions)
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_yticklabels()] == [_shown(c) for c in conditions]
    assert [t.get_text() for t in ax.get_xticklabels() if t.get_text()][0] == "0.00"
    assert tuple(fig.get_size_inches()) == (7.5, 4.0)
    assert _overlapping_labels(fig, ax) == []
    assert _covered_by_legend(fig, ax) == []


def test_the_rows_put_each_run_where_the_columns_did_turned_across():
    """In rows, a run is at (delta_abs, its condition's row), its condition's runs 0.15 of a
    row apart in key order (as in the columns, 0.15 of a column), the first condition at
    the top; marked by its decision; its HDI a level bar from its low to its high end; the
    title as asked for."""
    from matplotlib.collections import PathCollection

    rows, conditions = _batch(13, runs=2, decisions=True)
    fig = _plot_summary(rows, conditions)
    ax = fig.axes[0]
    expected: dict[str, list[list[float]]] = {}
    bars = []
    for i, c in enumerate(conditions):
        mine = [r for r in rows if (r["subject"], r["task"], r["motion_gain"])
                == (c["subject"], c["task"], c["motion_gain"])]
        for j, r in enumerate(mine):  # two runs: -0.075 and +0.075 of a row
            y = i + (j - 0.5) * 0.15
            expected.setdefault(r["decision"], []).append([r["delta_abs"], y])
            if r["delta_abs_posterior_hdi_low"] != "":
                bars.append([[r["delta_abs_posterior_hdi_low"], y],
                             [r["delta_abs_posterior_hdi_high"], y]])
    got = {c.get_label(): c.get_offsets().tolist() for c in ax.collections
           if isinstance(c, PathCollection)}
    assert got.keys() == expected.keys() == {"threshold", "none", "inconclusive"}
    for kind in expected:
        assert np.allclose(sorted(got[kind]), sorted(expected[kind]), rtol=1e-12), kind
    (hdi,) = ax.containers
    assert hdi.get_label() == "posterior 90 % HDI"
    (segments,) = [c.get_segments() for c in hdi.lines[2]]
    assert np.allclose(np.array(segments), bars, rtol=1e-12)
    lo, hi = ax.get_ylim()
    assert (lo, hi) == (12.5, -0.5)  # (the first condition on top)
    assert ax.get_xlim()[0] == 0.0 and "IPUT" in ax.get_xlabel()
    assert ax.get_title() == "The threshold of 26 runs in 13 conditions"
    for title, said in ((False, ""), ("Fig. 3", "Fig. 3")):
        assert _plot_summary(rows, conditions, title=title).axes[0].get_title() == said


def test_a_title_that_is_not_one_is_refused_before_a_figure_is_made():
    import matplotlib.pyplot as plt

    rows, conditions = _batch(60)
    before = plt.get_fignums()
    with pytest.raises(TypeError, match="title must be True"):
        _plot_summary(rows, conditions, title=None)
    assert plt.get_fignums() == before

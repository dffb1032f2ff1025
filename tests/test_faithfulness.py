"""Faithfulness to Pool et al. (2012): Tables 4 and 5 and Fig. 13, against the paper's numbers.

The full comparison (every cell, 100 realizations) is analyses/faithfulness.py;
these tests check representative cells with few realizations.
"""

import numpy as np
import pytest

from bayespilot import presets
from bayespilot.likelihood import Likelihood
from bayespilot.model import paper_model
from bayespilot.simulate import simulate

GRID = np.linspace(0.0, 0.1, 201)  # the Fig. 13 range, step 0.0005


@pytest.mark.parametrize("task", ["FD", "FT"])
def test_table4_remnant_gain_at_unit_motion_gain(task):
    """K_n for F_n = 0.2, K_theta = 1 against Table 4, with unit-variance noise at 100 Hz.

    With the forcing scale fixed from Table 5 (0.2), our K_n runs 10-20% below
    Table 4 (docs/faithfulness.md); a unit-PSD convention would be 10x off and
    the printed forcing amplitudes ~5x off, so the band still discriminates.
    """
    gains = [simulate(task=task, motion_gain=1.0, remnant_fraction=0.2, seed=s).remnant_gain
             for s in range(2)]
    paper = presets.TABLE4_K_N[(task, 0.2)][3]
    assert 0.75 * paper < np.mean(gains) < 1.1 * paper


@pytest.mark.parametrize("task, k", [("FD", 1.0), ("FT", 1.0), ("FT", 0.5), ("FD", 0.75)])
def test_table5_fraction_above_threshold(task, k):
    """P(|i| > 0.0075) at F_n = 0.25 within 0.03 of Table 5 (4 realizations)."""
    kn = presets.TABLE4_K_N[(task, 0.25)][presets.MOTION_GAINS.index(k)]
    p = [np.mean(np.abs(simulate(task=task, motion_gain=k, remnant_gain=kn, seed=s)
                        .channels["vestibular"]["pre"]) > 0.0075) for s in range(4)]
    assert np.mean(p) == pytest.approx(presets.TABLE5[(task, k)][0], abs=0.03)


def _curve(k, initial="periodic", remnant_fraction=None, seed=0):
    model = paper_model()
    sim = simulate(model, task="FD", motion_gain=k, remnant_fraction=remnant_fraction, seed=seed)
    lik = Likelihood(model, sim.recording, initial=initial)
    x = np.tile(model.free_vector(sim.params), (GRID.size, 1))
    x[:, -1] = GRID
    return lik.batch(x), lik


@pytest.mark.parametrize("k", [0.25, 1.0])
def test_fig13_minimum_at_true_threshold_without_remnant(k):
    curve, _ = _curve(k)
    assert abs(GRID[np.argmin(curve)] - 0.0075) <= GRID[1] - GRID[0] + 1e-12


def test_fig13_plateau_above_max_canal_output_at_low_motion_gain():
    """K_theta = 0.25: above max|i| the threshold blocks everything and -ln L is flat."""
    curve, lik = _curve(0.25)
    max_i = np.abs(lik.X[1]).max()
    above = GRID > max_i
    assert max_i < 0.1 and above.sum() > 10
    assert np.ptp(curve[above]) == 0.0
    assert curve[above][0] - curve.min() > 100.0   # the vestibular channel matters

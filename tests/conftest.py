"""Shared fixtures: short simulated recordings (session-scoped) and seeded generators."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

# tests/naive.py is imported as a plain module by the tests (and the benchmarks).
sys.path.insert(0, str(Path(__file__).parent))

from bayespilot.model import paper_model  # noqa: E402
from bayespilot.recording import Recording  # noqa: E402
from bayespilot.simulate import simulate  # noqa: E402

#: Length of the simulated recordings used by the kernel tests, s.
DURATION = 20.0


def make_rng(seed: int = 0) -> np.random.Generator:
    """The one way tests make random numbers: a seeded numpy Generator."""
    return np.random.default_rng(seed)


def without_theta(rec: Recording) -> Recording:
    """The same recording without its optional ``theta`` column.

    In ``initial="periodic"`` mode the canal then starts from the pitch rate
    estimated from theta_ddot_m (zero mean of its integral over the record)
    and everything else treats the record as one period of a periodic signal,
    which is what ``tests/naive.py`` implements.
    """
    signals = {k: v for k, v in rec.signals.items() if k != "theta"}
    return Recording(signals, rec.sample_rate_hz, rec.motion_gain, rec.task, rec.metadata,
                     source=rec.source)


@pytest.fixture(scope="session")
def fd_sim():
    """FD task, K_theta = 1, F_n = 0.2, 20 s, Table 3 parameters."""
    return simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=11, duration=DURATION)


@pytest.fixture(scope="session")
def ft_sim():
    """FT task, K_theta = 0.75, F_n = 0.2, 20 s, Table 3 parameters."""
    return simulate(task="FT", motion_gain=0.75, remnant_fraction=0.2, seed=12, duration=DURATION)


@pytest.fixture(scope="session")
def fd_rec(fd_sim):
    """fd_sim's recording without the theta column (see :func:`without_theta`)."""
    return without_theta(fd_sim.recording)


@pytest.fixture(scope="session")
def ft_rec(ft_sim):
    return without_theta(ft_sim.recording)


@pytest.fixture(scope="session")
def model():
    return paper_model()


@pytest.fixture(autouse=True)
def _close_figures():
    """Close the figures a test left open: pyplot keeps every one (over 20 it warns, and a
    worker's memory grows with each test file of figures).  The Figure objects a test or a
    fixture holds stay usable."""
    yield
    plt = sys.modules.get("matplotlib.pyplot")
    if plt is not None:
        plt.close("all")

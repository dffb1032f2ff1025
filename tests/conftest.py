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

#: The test files that take longest, longest first (measured with ``pytest --durations``
#: on 2 cores, 2026-11-29: test_diagnose_batch about a quarter of the suite's test time,
#: test_diagnose_pooled an eighth, then tens of seconds each).  They are collected first and
#: xdist, told to keep that order (``--no-loadscope-reorder`` in pyproject.toml), hands each
#: worker the next file in it: the long files start first and the short ones fill the end
#: (longest processing time first).  xdist's own order, by number of tests, could leave a
#: file of few slow tests to start last while the other worker idled.  A file not listed
#: keeps its place (alphabetical) after these; the list need not be exact to help.
SLOW_FILES = ("test_diagnose_batch.py", "test_diagnose_pooled.py", "test_diagnose.py",
              "test_compare.py", "test_report_figures.py", "test_fit.py",
              "test_extension_compare_diagnose.py", "test_cli.py", "test_campaign.py",
              "test_plots_figures.py", "test_batch.py", "test_cli_fit_batch.py",
              "test_simulate.py", "test_docs.py", "test_diagnose_custom.py",
              "test_faithfulness.py", "test_cli_figures.py", "test_cli_with.py",
              "test_likelihood.py", "test_cli_diagnose.py", "test_cli_lab.py",
              "test_bad_input.py", "test_api_docs.py", "test_provenance.py", "test_example.py")


def pytest_collection_modifyitems(config, items):
    """The slow files first, in :data:`SLOW_FILES`' order, each file's tests in their own
    order (a stable sort by file)."""
    rank = {name: i for i, name in enumerate(SLOW_FILES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


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

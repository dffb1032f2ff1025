"""Fill numba's on-disk cache for the test suite, in two processes at once.

``python tests/_warm_numba.py a`` (or ``b``): each part compiles a different half of the
kernels the tests use most (found with numba's compile events on an empty cache), so that
the two halves compile side by side on two cores.  ``conftest.pytest_configure`` runs both
before pytest-xdist starts its workers: on a fresh install (CI) every worker otherwise
compiled the same kernels at the same time, about 140 s of compiling each, before its
first test.  A kernel left out here is compiled where it is first used, as before; a part
that fails costs nothing but its time (the tests compile what they need).

Written for the test suite's speed, not part of the package: the package's own warm-up
(``bayespilot.campaign._warm_numba_cache``) runs one process, as a dask client has.
"""

from __future__ import annotations

import sys
import warnings

import numpy as np


def _synthetic(n: int, fs: float = 100.0, seed: int = 0):
    """A recording of sums of sines (no simulation: part ``b`` leaves the simulator to
    part ``a``), ``n`` samples at ``fs``."""
    from bayespilot.recording import Recording

    t = np.arange(n) / fs
    rng = np.random.default_rng(seed)
    w = np.array([0.3, 0.9, 2.1, 5.3, 11.0])
    e = 0.01 * sum(np.sin(wi * t + rng.uniform(0, 6)) for wi in w)
    tdm = 0.02 * sum(np.sin(wi * t + rng.uniform(0, 6)) for wi in w)
    u = 0.5 * e + 0.1 * tdm + 0.001 * rng.standard_normal(n)
    return Recording(dict(t=t, e=e, theta_ddot_m=tdm, u=u), fs, 1.0, "FD")


def part_a() -> None:
    """The simulator, the segmented (SIMD) Eq. 4 kernels, the time response and the
    Gauss-Newton Jacobian: a simulation and the fast and paper fits of it."""
    from bayespilot.campaign import _warm_numba_cache

    _warm_numba_cache({"fast", "paper"})


def part_b() -> None:
    """The fused Eq. 4 kernels (a record the segmented kernel does not take) and the
    coloured-noise kernels (whitened and profiled AR), with their Jacobian."""
    from bayespilot.likelihood import Likelihood
    from bayespilot.model import paper_model
    from bayespilot.sample import sample

    rec = _synthetic(1601)  # (not a multiple of 8 samples: the fused kernels)
    model = paper_model()
    lik = Likelihood(model, rec)
    x = model.free_vector(model.defaults)
    lik.neg_log_lik(x)
    lik.batch(np.vstack([x, x]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sample(rec, seed=0, max_steps=20, min_steps=20, progress=False, likelihood="coloured")


if __name__ == "__main__":
    {"a": part_a, "b": part_b}[sys.argv[1]]()

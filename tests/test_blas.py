"""The fits run their dense algebra on one BLAS thread (``bayespilot._blas``) and give the
caller's thread setting back afterwards."""

from __future__ import annotations

import pytest
from scipy import optimize
from threadpoolctl import threadpool_info, threadpool_limits

from bayespilot.fit.fast import fit_fast
from bayespilot.noise import fit_ar


def _blas_threads() -> int:
    return max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")


def test_fit_fast_runs_least_squares_on_one_blas_thread(fd_sim, monkeypatch):
    seen = []
    real = optimize.least_squares

    def spy(*args, **kwargs):
        seen.append(_blas_threads())
        return real(*args, **kwargs)

    monkeypatch.setattr(optimize, "least_squares", spy)
    with threadpool_limits(limits=2, user_api="blas"):  # what a 2-core machine starts with
        before = _blas_threads()
        fit_fast(fd_sim.recording, seed=0, n_starts=2, profile_step=0.01)
        after = _blas_threads()
    assert seen and set(seen) == {1}
    assert after == before  # the caller's setting is restored


def test_fit_ar_keeps_its_docstring_and_result(fd_sim):
    """The decorator is transparent: same name, docs and numbers as the undecorated function."""
    eps = fd_sim.recording.u - fd_sim.recording.u.mean()
    assert fit_ar.__name__ == "fit_ar" and "BIC" in fit_ar.__doc__
    a = fit_ar(eps, order=4)
    b = fit_ar.__wrapped__(eps, order=4)
    assert a == pytest.approx(b, rel=0, abs=0)

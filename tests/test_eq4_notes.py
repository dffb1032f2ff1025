"""A posterior or a comparison under Eq. 4 (the default: the paper's white-residual likelihood)
says below its numbers that they are overconfident on closed-loop recordings, and points to
the coloured likelihood; one under the coloured likelihood does not.

The measurements behind the notes: docs/posteriors.md ("A held-out check": Eq. 4's 90 %
intervals held the truth in 0-8 of 20 held-out runs per parameter) and docs/comparison.md
("Which likelihood": Eq. 4 decided 'threshold' on 5 of 20 recordings without one)."""

from __future__ import annotations

import dataclasses

import pytest

from bayespilot.compare import EQ4_COMPARISON_NOTE, compare
from bayespilot.sample import EQ4_POSTERIOR_NOTE, sample
from bayespilot.simulate import simulate


@pytest.fixture(scope="module")
def rec():
    return simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=1,
                    duration=10.0).recording


def test_an_eq4_posterior_says_its_intervals_are_too_narrow(rec):
    post = sample(rec, max_steps=40, min_steps=40, check_every=20, seed=0, progress=False)
    assert post.settings["likelihood"] == "eq4"
    lines = str(post).splitlines()
    assert lines[-1] == EQ4_POSTERIOR_NOTE  # below the table, once
    assert sum(EQ4_POSTERIOR_NOTE in ln for ln in lines) == 1
    assert "several times too narrow" in lines[-1] and "--likelihood coloured" in lines[-1]
    coloured = dataclasses.replace(post, settings=dict(post.settings, likelihood="coloured"))
    assert EQ4_POSTERIOR_NOTE not in str(coloured)
    assert str(coloured).splitlines()[1:] == lines[1:-1]  # (the first names the likelihood)


def test_an_eq4_comparison_says_its_bayes_factor_is_inflated(rec):
    c = compare(rec, nlive=30, dlogz=2.0, seed=0, savage_dickey_samples=False)
    assert c.settings["likelihood"] == "eq4"
    lines = c.summary().splitlines()
    assert lines[-2] == f"  {EQ4_COMPARISON_NOTE}"  # (the last line is the time)
    assert "decide 'threshold' on recordings without one" in lines[-2]
    coloured = dataclasses.replace(c, settings=dict(c.settings, likelihood="coloured"))
    assert EQ4_COMPARISON_NOTE not in coloured.summary()
    assert coloured.summary().splitlines()[1:] == lines[1:-2] + lines[-1:]


def test_a_pool_of_eq4_comparisons_says_its_sum_is_inflated():
    """pool() sums the recordings' ln BF: under Eq. 4 the sum of inflated ones decided
    'threshold' on the held-out recordings without a threshold (+15.6 over 20), so its
    summary says so too; the likelihood is kept, and read back from a file."""
    from bayespilot.compare import PooledComparison, pool

    def made(lik, v):
        d = {"log_bayes_factor": v, "log_bayes_factor_err": 0.5}
        return d if lik is None else dict(d, settings={"likelihood": lik})

    eq4 = pool([made("eq4", v) for v in (5.0, 7.0, 6.0)])
    assert eq4.likelihood == "eq4" and eq4.decision == "threshold"
    assert eq4.summary().splitlines()[1] == f"  {EQ4_COMPARISON_NOTE}"
    assert PooledComparison.from_dict(eq4.to_dict()).likelihood == "eq4"
    coloured = pool([made("coloured", v) for v in (5.0, 7.0, 6.0)])
    assert coloured.likelihood == "coloured" and "\n" not in coloured.summary()
    mixed = pool([made("coloured", 5.0), made("eq4", 7.0)])
    assert mixed.likelihood == "mixed" and EQ4_COMPARISON_NOTE in mixed.summary()
    bare = pool([made(None, 5.0), made(None, 7.0)])  # (hand-made, or files of before)
    assert bare.likelihood == "" and "\n" not in bare.summary()
    old = {k: v for k, v in eq4.to_dict().items() if k != "likelihood"}
    assert PooledComparison.from_dict(old).likelihood == ""

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

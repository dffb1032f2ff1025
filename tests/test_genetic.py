"""Step I genetic algorithm: encoding, a problem with a known minimum, reproducibility, Step I.

References are independent of the implementation: chromosomes are built from
``format(k, "020b")`` strings and decoded with the closed form
``lower + (upper - lower) * k / (2**bits - 1)``; the optimiser is checked on a
convex quadratic with a known minimiser; the Step I threshold is recomputed
from the runs in plain Python.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from bayespilot.fit.genetic import (GAResult, decode, encode, genetic_algorithm, resolution,
                                    step_one)
from bayespilot.likelihood import Likelihood
from bayespilot.model import paper_model
from bayespilot.simulate import simulate

BITS = 20
TOP = 2**BITS - 1
LOWER, UPPER = paper_model().bounds  # Table 1
# The known minimiser, well inside the bounds (0.15 ... 0.85 of each range).
X_STAR = LOWER + (UPPER - LOWER) * np.linspace(0.15, 0.85, LOWER.size)


def quadratic(x: np.ndarray) -> np.ndarray:
    return np.sum(((x - X_STAR) / (UPPER - LOWER)) ** 2, axis=1)


class Counting:
    """Wraps an objective; records the shape and the minimum of every call."""

    def __init__(self, objective):
        self.objective = objective
        self.shapes: list[tuple[int, ...]] = []
        self.minima: list[float] = []

    def __call__(self, x):
        self.shapes.append(x.shape)
        f = self.objective(x)
        self.minima.append(float(np.min(f)))
        return f


def _chromosome(ints) -> np.ndarray:
    """Bits of a chromosome from one integer per parameter, via Python's own formatting."""
    return np.array([int(c) for k in ints for c in format(int(k), f"0{BITS}b")], dtype=bool)


def _arrays(r: GAResult):
    return (r.x, np.array([r.fun]), r.history_best_x, r.history_best_fun, r.history_mean_fun)


@pytest.fixture(scope="module")
def quadratic_run():
    obj = Counting(quadratic)
    return genetic_algorithm(obj, LOWER, UPPER, population=160, generations=100, seed=7), obj


# --- encoding ----------------------------------------------------------------------------
def test_decode_matches_closed_form_and_resolution():
    ints = [0, 1, 2**19, TOP - 1, TOP, 123456, 654321, 1]
    got = decode(_chromosome(ints), LOWER, UPPER, bits=BITS)
    want = LOWER + (UPPER - LOWER) * np.array(ints, float) / TOP
    np.testing.assert_allclose(got, want, rtol=1e-15, atol=0)
    step = (UPPER - LOWER) / (2**20 - 1)
    np.testing.assert_allclose(resolution(LOWER, UPPER, BITS), step, rtol=1e-15)
    one = decode(_chromosome([1] * LOWER.size), LOWER, UPPER, bits=BITS)
    np.testing.assert_allclose(one - LOWER, step, rtol=1e-12)
    # The paper: 1e-5 for K_v, T_vl and K_m and 1e-7 for delta_abs.
    assert 9e-6 < step[0] < 1e-5 and 9e-8 < step[-1] < 1e-7


def test_all_zero_and_all_one_bits_give_the_bounds_exactly():
    lo, hi = np.array([0.1, -3.0, 5.0]), np.array([0.3, 7.7, 30.0])
    genes = np.zeros((2, 3 * BITS), dtype=bool)
    genes[1] = True
    x = decode(genes, lo, hi, bits=BITS)
    assert np.array_equal(x[0], lo) and np.array_equal(x[1], hi)


def test_encode_is_the_inverse_of_decode_on_the_grid():
    rng = np.random.default_rng(3)
    ints = rng.integers(0, TOP + 1, size=LOWER.size)
    genes = _chromosome(ints)
    assert np.array_equal(encode(decode(genes, LOWER, UPPER), LOWER, UPPER), genes)


# --- a problem with a known answer ----------------------------------------------------------
def test_finds_the_minimum_of_a_quadratic(quadratic_run):
    res, _ = quadratic_run
    # Plain binary coding has Hamming cliffs at 1/2, 1/4, ... of the range: a run
    # can stall ~5 % of the range from x* (seen over 100 seeds), hence 6 %.
    assert np.all(np.abs(res.x - X_STAR) / (UPPER - LOWER) < 0.06)
    assert res.fun == float(quadratic(res.x[None])[0])
    assert res.fun < 0.01


def test_history_shapes_and_best_so_far_never_increases(quadratic_run):
    res, obj = quadratic_run
    assert res.history_best_x.shape == (101, LOWER.size)
    assert res.history_best_fun.shape == res.history_mean_fun.shape == (101,)
    assert np.all(np.diff(res.history_best_fun) <= 0)
    assert np.array_equal(res.history_best_x[-1], res.x) and res.history_best_fun[-1] == res.fun
    # Elitism: the best of each generation itself never gets worse.
    assert np.all(np.diff(obj.minima) <= 0)
    np.testing.assert_array_equal(res.history_best_fun, obj.minima)
    assert np.all(res.history_mean_fun >= res.history_best_fun)
    assert res.history_mean_fun[-1] < res.history_mean_fun[0]


def test_objective_called_once_per_generation_on_the_whole_population(quadratic_run):
    res, obj = quadratic_run
    assert len(obj.shapes) == 100 + 1
    assert set(obj.shapes) == {(160, LOWER.size)}
    assert res.n_evaluations == 101 * 160


def test_same_seed_same_result_different_seed_different(quadratic_run):
    res, _ = quadratic_run
    again = genetic_algorithm(quadratic, LOWER, UPPER, population=160, generations=100, seed=7)
    for a, b in zip(_arrays(res), _arrays(again)):
        assert np.array_equal(a, b)
    # The recorded seed repeats the run too.
    rerun = genetic_algorithm(quadratic, LOWER, UPPER, population=160, generations=100,
                              seed=res.seed)
    assert np.array_equal(rerun.history_best_x, res.history_best_x)
    other = genetic_algorithm(quadratic, LOWER, UPPER, population=160, generations=100, seed=8)
    assert not np.array_equal(other.history_best_x, res.history_best_x)
    assert not np.array_equal(other.history_mean_fun, res.history_mean_fun)


def test_non_finite_values_rank_worst():
    def obj(x):
        f = quadratic(x)
        f[x[:, 0] > 5.0] = np.inf  # an "unstable" half of the K_v range
        f[x[:, 1] > 8.0] = np.nan
        return f

    res = genetic_algorithm(obj, LOWER, UPPER, population=40, generations=40, seed=2)
    assert np.isfinite(res.fun) and res.x[0] <= 5.0 and res.x[1] <= 8.0
    assert np.all(np.isfinite(res.history_mean_fun))


def test_initial_vectors_are_placed_and_elitism_zero_runs():
    res = genetic_algorithm(quadratic, LOWER, UPPER, population=10, generations=0, seed=0,
                            initial=X_STAR)
    assert res.fun <= quadratic(X_STAR[None])[0] + 1e-10
    assert np.all(np.abs(res.x - X_STAR) <= resolution(LOWER, UPPER))
    count = Counting(quadratic)
    res0 = genetic_algorithm(count, LOWER, UPPER, population=10, generations=5, elitism=0,
                             seed=0)
    assert count.shapes == [(10, LOWER.size)] * 6
    # no elite kept: the best of a generation can be lost, and is in 2 of the 5 (generations
    # 2 and 3: 0.3204 -> 0.3865 -> 0.4577); one elite (elitism >= 1) never loses it
    worse = np.diff(count.minima) > 0
    assert worse.tolist() == [False, True, True, False, False]
    assert count.minima[1:4] == pytest.approx([0.32041379, 0.38650, 0.45773], abs=1e-5)
    # the history is the best found so far, not the generation's best
    np.testing.assert_array_equal(res0.history_best_fun, np.minimum.accumulate(count.minima))


def test_to_dict_is_json():
    res = genetic_algorithm(quadratic, LOWER, UPPER, population=8, generations=3, seed=5)
    d = json.loads(json.dumps(res.to_dict()))
    assert d["x"] == res.x.tolist() and len(d["history_best_fun"]) == 4
    assert d["seed"] == {"entropy": 5, "spawn_key": []}
    assert d["settings"]["population"] == 8


# --- Step I on a simulated recording ------------------------------------------------------
@pytest.fixture(scope="module")
def short_likelihood():
    sim = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.1, seed=21, duration=20.0)
    return Likelihood(paper_model(), sim.recording)


@pytest.fixture(scope="module")
def step_one_result(short_likelihood):
    return step_one(short_likelihood, repetitions=3, n_best=2, generations=30, seed=1)


def test_step_one_improves_on_the_centre_and_averages_the_best_thresholds(short_likelihood,
                                                                          step_one_result):
    res = step_one_result
    lo, hi = paper_model().bounds
    centre = short_likelihood.neg_log_lik((lo + hi) / 2)
    funs = [r.fun for r in res.runs]
    assert len(res.runs) == 3 and min(funs) < centre
    # Independently: sort the runs by -ln L and average delta_abs of the best two.
    j = list(paper_model().parameter_names).index("delta_abs")
    best_two = sorted(range(3), key=lambda i: funs[i])[:2]
    assert res.delta_abs == pytest.approx(np.mean([res.runs[i].x[j] for i in best_two]),
                                          rel=1e-15)
    assert list(res.order) == sorted(range(3), key=lambda i: funs[i])
    assert res.best.fun == min(funs)
    for r in res.runs:  # each run's best is the likelihood at that vector
        assert r.fun == pytest.approx(short_likelihood.neg_log_lik(r.x), rel=1e-12)
    json.dumps(res.to_dict())


def test_step_one_seeds_are_spawned_from_the_root(short_likelihood, step_one_result):
    lo, hi = paper_model().bounds
    child = np.random.SeedSequence(1).spawn(3)[2]
    alone = genetic_algorithm(short_likelihood.batch, lo, hi, generations=30, seed=child)
    assert np.array_equal(alone.history_best_x, step_one_result.runs[2].history_best_x)


def test_step_one_without_threshold_gives_none(short_likelihood):
    lik = Likelihood(paper_model(threshold=False), short_likelihood.recording)
    res = step_one(lik, repetitions=2, n_best=1, population=8, generations=2, seed=0)
    assert res.delta_abs is None and res.runs[0].x.shape == (7,)


# --- bad input -----------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, match", [
    (dict(population=161), "population"),
    (dict(population=0), "population"),
    (dict(p_crossover=-0.1), "p_crossover"),
    (dict(p_mutation=1.5), "p_mutation"),
    (dict(p_mutation=float("nan")), "p_mutation"),
    (dict(bits=1), "bits"),
    (dict(bits=53), "bits"),
    (dict(elitism=10), "elitism"),
    (dict(lower=[0.0, 1.0], upper=[1.0, 1.0]), "lower"),
    (dict(lower=[0.0, 2.0], upper=[1.0, 1.0]), "lower"),
    (dict(lower=[0.0, -np.inf], upper=[1.0, 1.0]), "finite"),
    (dict(initial=[[2.0, 0.5]]), "initial"),
])
def test_bad_input_raises_value_error_naming_the_argument(kwargs, match):
    args = dict(lower=[0.0, 0.0], upper=[1.0, 1.0], population=10, generations=1)
    args.update(kwargs)
    lo, hi = args.pop("lower"), args.pop("upper")
    with pytest.raises(ValueError, match=match):
        genetic_algorithm(lambda x: np.sum(x, axis=1), lo, hi, **args)


def test_bad_objective():
    with pytest.raises(TypeError, match="objective"):
        genetic_algorithm("not a function", [0.0], [1.0])
    with pytest.raises(ValueError, match="objective"):
        genetic_algorithm(lambda x: np.zeros(3), [0.0], [1.0], population=4, generations=1)


def test_step_one_bad_input(short_likelihood):
    with pytest.raises(ValueError, match="n_best"):
        step_one(short_likelihood, repetitions=2, n_best=3)
    with pytest.raises(ValueError, match="repetitions"):
        step_one(short_likelihood, repetitions=0)


def test_paper_settings_are_the_papers_and_every_fitters_default():
    """Section III.A's GA (population 160, 100 generations, crossover 0.7, mutation 0.01,
    20 bits, 20 repetitions, the best 5): the constant, and the defaults of the three
    functions that restate them in their signatures (so that help() shows them), agree."""
    import inspect

    from bayespilot.fit.genetic import PAPER_SETTINGS, genetic_algorithm, step_one
    from bayespilot.fit.three_step import fit_paper

    paper = {"population": 160, "generations": 100, "p_crossover": 0.7, "p_mutation": 0.01,
             "bits": 20, "repetitions": 20, "n_best": 5}
    assert dict(PAPER_SETTINGS) == paper
    for fn in (genetic_algorithm, step_one, fit_paper):
        params = inspect.signature(fn).parameters
        given = {k: params[k].default for k in paper if k in params}
        assert given == {k: paper[k] for k in given}, fn.__name__
    assert set(inspect.signature(fit_paper).parameters) >= set(paper)

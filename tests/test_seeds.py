"""seed=None draws a seed from fresh entropy, and the result records it: given back as
``seed`` it repeats the run bit for bit (simulate, fit_fast, fit_paper, sample, diagnose).
Before, None was recorded as None and such a run could not be repeated."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.stats import qmc

from bayespilot._seeds import resolve_seed
from bayespilot.fit.fast import fit_fast
from bayespilot.fit.genetic import genetic_algorithm
from bayespilot.fit.three_step import fit_paper
from bayespilot.likelihood import Likelihood
from bayespilot.model import paper_model
from bayespilot.simulate import simulate


@pytest.fixture(scope="module")
def rec():
    return simulate(task="FD", motion_gain=1.0, remnant_fraction=0.1, seed=1,
                    duration=20.0).recording


def test_resolve_seed():
    assert resolve_seed(7) == 7 and resolve_seed(np.uint32(9)) == 9
    drawn = {resolve_seed(None) for _ in range(5)}
    assert len(drawn) == 5 and all(0 <= s < 2**31 for s in drawn)
    for bad in (True, 1.0, -1, "3", np.random.default_rng(0)):
        with pytest.raises(ValueError, match="seed must be an integer >= 0 or None"):
            resolve_seed(bad)


def test_simulate_records_the_seed_it_drew():
    a = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.1, seed=None, duration=5.0)
    assert isinstance(a.seed, int) and a.recording.source == f"simulation(seed={a.seed})"
    b = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.1, seed=a.seed, duration=5.0)
    assert np.array_equal(a.recording.u, b.recording.u)
    with pytest.raises(ValueError, match="seed"):
        simulate(task="FD", motion_gain=1.0, seed=np.random.default_rng(0), duration=5.0)


def test_fits_record_the_seed_they_drew(rec):
    a = fit_fast(rec, seed=None, n_starts=2, profile_step=0.02)
    b = fit_fast(rec, seed=a.seed, n_starts=2, profile_step=0.02)
    assert isinstance(a.seed, int) and a.params == b.params and a.neg_log_lik == b.neg_log_lik
    # the starts are the Latin hypercube of the recorded seed: -ln L (no threshold, the fit's
    # discard) at each, drawn here with scipy; another seed draws other starts
    lik0 = Likelihood(paper_model(threshold=False), rec, discard=a.settings["discard"])
    lo, hi = lik0.model.bounds

    def start_nll(seed):
        x = qmc.scale(qmc.LatinHypercube(d=lo.size, seed=seed).random(2), lo, hi)
        return [lik0.neg_log_lik(row) for row in x]

    assert [r["start_neg_log_lik"] for r in a.steps["starts"]] == pytest.approx(
        start_nll(a.seed), rel=1e-12)
    other = fit_fast(rec, seed=a.seed + 1, n_starts=2, profile_step=0.02)
    assert [r["start_neg_log_lik"] for r in other.steps["starts"]] == pytest.approx(
        start_nll(a.seed + 1), rel=1e-12)
    assert not np.allclose(start_nll(a.seed), start_nll(a.seed + 1), rtol=1e-3)
    json.dumps(a.to_dict())  # a Generator seed made it unserialisable; now refused:
    with pytest.raises(ValueError, match="seed"):
        fit_fast(rec, seed=np.random.default_rng(0), n_starts=1)
    kw = dict(repetitions=2, n_best=1, population=10, generations=3)
    p = fit_paper(rec, seed=None, **kw)
    q = fit_paper(rec, seed=p.seed, **kw)
    assert isinstance(p.seed, int) and p.params == q.params and p.steps == q.steps
    # GA run i is seeded with child i of SeedSequence(seed): rerun here with plain
    # genetic_algorithm on the same likelihood, it ends at the same point
    lik = Likelihood(paper_model(), rec, discard=p.settings["discard"])
    ga = {k: p.settings[k] for k in ("population", "generations", "p_crossover", "p_mutation",
                                     "bits")}
    runs = p.steps["step1"]["runs"]
    for i, ss in enumerate(np.random.SeedSequence(p.seed).spawn(2)):
        g = genetic_algorithm(lik.batch, *paper_model().bounds, seed=ss, **ga)
        assert runs[i]["seed"] == {"entropy": p.seed, "spawn_key": [i]}
        assert runs[i]["x"] == g.x.tolist() and runs[i]["fun"] == g.fun


def test_sample_records_the_seed_it_drew(rec):
    from bayespilot.sample import ConvergenceWarning, sample

    kw = dict(n_walkers=24, max_steps=20, min_steps=10, check_every=10, progress=False)
    with pytest.warns(ConvergenceWarning):  # 20 steps: too short, said
        a = sample(rec, seed=None, **kw)
    with pytest.warns(ConvergenceWarning):
        b = sample(rec, seed=a.seed, **kw)
    assert isinstance(a.seed, int) and a.settings["entropy"] == str(a.seed)
    assert a.settings["init_point"] == b.settings["init_point"]
    for name in a.parameter_names:
        assert np.array_equal(a.idata.posterior[name].values, b.idata.posterior[name].values)
    # the chain starts at fit_fast's estimate with the recorded seed, bit for bit
    init = fit_fast(rec, seed=a.seed, discard=a.settings["discard_seconds"])
    assert a.settings["init"] == "fit_fast"
    assert a.settings["init_point"] == {k: init.params[k] for k in a.parameter_names}
    # and another seed another chain: another initial ball and other moves, not just the
    # ~1e-14 rounding of another fit_fast start (the optimum is the same)
    with pytest.warns(ConvergenceWarning):
        c = sample(rec, seed=a.seed + 1, **kw)
    # (the walkers' last draws: the kept draws can differ in number, with tau)
    ka, kc = a.idata.posterior["K_v"].values[..., -1], c.idata.posterior["K_v"].values[..., -1]
    assert ka.shape == kc.shape == (24,)
    assert np.median(np.abs(ka - kc)) > 1e-6 * np.median(np.abs(ka))


def test_diagnose_records_the_seed_it_drew(rec):
    from bayespilot.diagnose import diagnose

    kw = dict(n_bootstrap=2, candidates=["time-varying-gains"], progress=False)
    a = diagnose(rec, seed=None, **kw)
    b = diagnose(rec, seed=a.settings["seed"], **kw)
    assert isinstance(a.settings["seed"], int)
    da, db = a.to_dict(), b.to_dict()
    for d in (da, db):
        d["settings"].pop("timings", None)
        d.pop("elapsed_seconds", None)
    assert json.dumps(da, sort_keys=True) == json.dumps(db, sort_keys=True)


def test_nested_evidence_and_compare_record_the_seed_they_drew(rec):
    from bayespilot.compare import compare, nested_evidence

    def ll(x):
        return -0.5 * float(x @ x)

    a = nested_evidence(ll, [-5, -5], [5, 5], nlive=30, seed=None)
    b = nested_evidence(ll, [-5, -5], [5, 5], nlive=30, seed=a.settings["seed"])
    assert isinstance(a.settings["seed"], int) and a.log_z == b.log_z
    c = compare(rec, nlive=20, seed=None, savage_dickey_samples=False)
    d = compare(rec, nlive=20, seed=c.seed, savage_dickey_samples=False)
    assert isinstance(c.seed, int) and c.log_bayes_factor == d.log_bayes_factor

"""Time to 1000 effective samples of delta_abs, and one evidence, per likelihood (issue 4).

Run:  python benchmarks/bench_sample.py [--likelihoods eq4,coloured,profiled] [--nlive 200]
                                        [--oversample M]

``profiled`` is the coloured likelihood with the AR model re-fitted at every
parameter vector (``sample(..., ar="profiled")``); it has no evidence.

Simulates task FD, K_theta = 1, K_n = 0.104 (F_n ~ 0.2, Table 4), 81.92 s,
with the paper's model (``--oversample M``: its vestibular channel at M
times the rate in the likelihood).  For each likelihood it times, with numba limited to
one thread:

- the initial maximum-likelihood fit that ``sample`` starts from (for
  ``coloured`` a prediction-error fit that also gives the AR noise model);
- the emcee run itself (``sample(init=fit)``, run to its convergence rule);
- the time per 1000 effective samples of delta_abs: emcee wall time x 1000 /
  ess_bulk(delta_abs) (arviz, on the kept, thinned draws), and the same from
  emcee's autocorrelation time (n_walkers x kept steps / tau of delta_abs);
- one dynesty evidence of the model with threshold (``evidence``, nlive live
  points, the same noise model).

Kernels are compiled / loaded from the cache by a short warm-up first.
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import warnings

import numba

from bayespilot.compare import evidence
from bayespilot.fit.fast import fit_fast
from bayespilot.model import paper_model
from bayespilot.noise import ARNoise
from bayespilot.sample import COLOURED_DISCARD, ConvergenceWarning, sample
from bayespilot.simulate import simulate


def _noise(fit) -> ARNoise | None:
    d = fit.settings.get("noise")
    return None if d is None else ARNoise.from_dict(d)


#: sample() options of each benchmarked likelihood.
OPTIONS = {"eq4": {"likelihood": "eq4"}, "coloured": {"likelihood": "coloured", "ar": "fixed"},
           "profiled": {"likelihood": "coloured", "ar": "profiled"}}


def _warm_up(lik: str, model) -> None:
    rec = simulate(task="FD", motion_gain=1.0, remnant_gain=0.104, seed=4, duration=10.0).recording
    fit = fit_fast(rec, model, seed=0, noise="ar" if lik != "eq4" else None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sample(rec, model, **OPTIONS[lik], init=fit, max_steps=40, min_steps=20,
               check_every=20, progress=False, seed=0)
        if lik != "profiled":
            evidence(rec, model, likelihood=lik, noise=_noise(fit), nlive=20, dlogz=50.0,
                     seed=0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--likelihoods", default="eq4,coloured,profiled")
    ap.add_argument("--nlive", type=int, default=200)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--oversample", type=int, default=1,
                    help="the likelihood's vestibular channel at M times the rate (default 1)")
    args = ap.parse_args(argv)
    numba.set_num_threads(1)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs; "
          f"numba threads {numba.get_num_threads()}; load {os.getloadavg()}")
    rec = simulate(task="FD", motion_gain=1.0, remnant_gain=0.104, seed=args.seed).recording
    model = paper_model(oversample=args.oversample)
    print(f"model: {model.name}")
    rows = []
    for lik in args.likelihoods.split(","):
        _warm_up(lik, model)
        t0 = time.perf_counter()
        discard = COLOURED_DISCARD if lik != "eq4" else 0.0
        fit = fit_fast(rec, model, seed=0, noise="ar" if lik != "eq4" else None,
                       discard=discard)
        t_fit = time.perf_counter() - t0
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            post = sample(rec, model, **OPTIONS[lik], init=fit, seed=0, progress=False)
        t_sample = time.perf_counter() - t0
        s = post.summary()["delta_abs"]
        n_draws = post.idata.posterior["delta_abs"].size
        st = post.settings  # kept steps x walkers over tau: emcee's own effective sample size
        ess_tau = (st["n_steps"] - st["discard"]) * st["n_walkers"] / post.tau["delta_abs"]
        noise = _noise(fit)
        nan = float("nan")
        t_ev, log_z, log_z_err, n_calls = nan, nan, nan, 0
        if lik != "profiled":
            t0 = time.perf_counter()
            ev = evidence(rec, model, likelihood=lik, noise=noise, discard=discard,
                          nlive=args.nlive, seed=0)
            t_ev = time.perf_counter() - t0
            log_z, log_z_err, n_calls = ev.log_z, ev.log_z_err, ev.n_calls
        rows.append((lik, t_fit, t_sample, post.converged, n_draws, s["ess_bulk"], ess_tau,
                     1000.0 * t_sample / s["ess_bulk"], 1000.0 * t_sample / ess_tau, t_ev,
                     log_z, log_z_err, n_calls))
        if lik != "eq4":
            print(f"{lik}: AR order {noise.order}")
    print(f"{'likelihood':10s} {'fit s':>6s} {'emcee s':>8s} {'conv':>5s} {'draws':>7s} "
          f"{'ESS bulk':>9s} {'ESS tau':>8s} {'s/1000 ESS (bulk)':>18s} {'(tau)':>7s} "
          f"{'evidence s':>10s} {'ln Z':>10s} {'+-':>5s} {'calls':>7s}")
    for r in rows:
        print(f"{r[0]:10s} {r[1]:6.1f} {r[2]:8.1f} {str(r[3]):>5s} {r[4]:7d} {r[5]:9.0f} "
              f"{r[6]:8.0f} {r[7]:18.1f} {r[8]:7.1f} {r[9]:10.1f} {r[10]:10.1f} {r[11]:5.2f} "
              f"{r[12]:7d}")
    print(f"load at the end: {os.getloadavg()}")


if __name__ == "__main__":
    main()

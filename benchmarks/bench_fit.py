"""Time one faithful three-step fit and one fast fit on a full-length simulated recording.

Run:  python benchmarks/bench_fit.py [--repeats 2]

Prints wall times (both numba threads in use) and the estimates; the figures
go to docs/performance.md with this command.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numba
import numpy as np

from bayespilot.fit.fast import fit_fast
from bayespilot.fit.three_step import fit_paper
from bayespilot.likelihood import Likelihood
from bayespilot.model import paper_model
from bayespilot.simulate import simulate


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args(argv)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs; "
          f"numba threads {numba.get_num_threads()}; load {os.getloadavg()}")
    sim = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=3)
    rec = sim.recording
    # warm-up: compile / load every kernel once
    fit_paper(rec, seed=0, repetitions=1, n_best=1, population=20, generations=2)
    fit_fast(rec, seed=0, n_starts=1, profile_step=0.05)
    truth = Likelihood(paper_model(), rec).neg_log_lik(sim.params)
    rows = []
    for name, fn in (("paper three-step (20 x GA 160x100, GN, scan)", lambda: fit_paper(rec, seed=1)),
                     ("fast (8 starts, profile step 0.0025)", lambda: fit_fast(rec, seed=1))):
        ts = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            fit = fn()
            ts.append(time.perf_counter() - t0)
        rows.append((name, float(np.median(ts)), min(ts), fit))
    print(f"\n-ln L at the true parameters: {truth:.2f}")
    print(f"{'fit':<48} {'median s':>9} {'min s':>7} {'-ln L':>11} {'delta_abs':>9}")
    for name, med, mn, fit in rows:
        print(f"{name:<48} {med:9.2f} {mn:7.2f} {fit.neg_log_lik:11.2f} {fit.params['delta_abs']:9.4f}")
    print(f"load at the end: {os.getloadavg()}")


if __name__ == "__main__":
    main()

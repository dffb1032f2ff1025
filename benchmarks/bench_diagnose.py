"""Time one ``diagnose`` at N = 8192 on one core (issue 5, target <= 2 min).

Run:  python benchmarks/bench_diagnose.py [--repeats 1] [--bootstrap 39] [--runs R]
                                          [--omega-c RAD_S] [--oversample M]
                                          [--washout OMEGA_W] [--calibrate B]
                                          [--bayes-factor] [--shared-posterior]

Simulates task FD, K_theta = 1, K_n = 0.104 (F_n ~ 0.2, Table 4) with the
paper's model, loads the kernels once (a short diagnose), then times the full
diagnosis with numba limited to one thread; prints the wall time per stage.
``--runs R`` (R >= 2) times ``diagnose_pooled`` on R such runs (seeds 3, 4, ...);
``--omega-c inf --oversample 8`` the whole-band decision likelihood with the
motion channel at 8x.  ``--washout 0.5`` simulates a washout of 0.5 rad/s, so
that a candidate is chosen and its test calibrated (``--calibrate`` replicates,
default 39): the slowest path.  ``--bayes-factor`` then also times
``bayes_factor`` (nested sampling, its defaults) on the diagnosed run;
``--runs R --washout W --shared-posterior`` times ``shared_posterior`` of the
pooled diagnosis's chosen extension (its default grid).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import warnings

import numba
import numpy as np

from bayespilot import presets
from bayespilot.diagnose import (EvidenceWarning, bayes_factor, diagnose, diagnose_pooled,
                                 get_extension, shared_posterior)
from bayespilot.model import paper_model
from bayespilot.simulate import simulate


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--bootstrap", type=int, default=39)
    ap.add_argument("--runs", type=int, default=1, help="R >= 2: time diagnose_pooled on R runs")
    ap.add_argument("--omega-c", type=float, default=None, help="decision band, rad/s (inf: whole)")
    ap.add_argument("--oversample", type=int, default=1, help="motion channel at M x the rate")
    ap.add_argument("--washout", type=float, default=None, metavar="OMEGA_W",
                    help="simulate a washout of this break frequency (rad/s)")
    ap.add_argument("--calibrate", type=int, default=39, metavar="B",
                    help="replicates of the chosen candidate's calibration (default 39)")
    ap.add_argument("--bayes-factor", action="store_true",
                    help="also time bayes_factor on the diagnosed run (one recording only)")
    ap.add_argument("--shared-posterior", action="store_true",
                    help="with --runs R: also time shared_posterior of the chosen extension")
    args = ap.parse_args(argv)
    if args.shared_posterior and args.runs < 2:
        ap.error("--shared-posterior needs --runs R >= 2")
    if args.bayes_factor and args.runs > 1:
        ap.error("--bayes-factor takes one run")
    numba.set_num_threads(1)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs; "
          f"numba threads {numba.get_num_threads()}; load {os.getloadavg()}")
    model, params = None, None
    if args.washout is not None:
        model = get_extension("motion-washout").build(paper_model())
        params = dict(presets.paper_parameters("FD"), omega_w=args.washout)
    recs = [simulate(model, params, task="FD", motion_gain=1.0, remnant_gain=0.104,
                     seed=3 + j).recording for j in range(max(args.runs, 1))]
    rec = recs[0]
    warm = simulate(task="FD", motion_gain=1.0, remnant_gain=0.104, seed=4, duration=20.0).recording
    kw = {"omega_c": args.omega_c, "oversample": args.oversample,
          "n_calibrate": args.calibrate}
    with warnings.catch_warnings():  # (a 20-s warm-up run: not whole periods, said)
        warnings.simplefilter("ignore", EvidenceWarning)
        diagnose(warm, n_bootstrap=1, **dict(kw, n_calibrate=0))  # compile / load every kernel
    ts = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        if args.runs > 1:
            res = diagnose_pooled(recs, seed=0, n_bootstrap=args.bootstrap, **kw)
        else:
            res = diagnose(rec, seed=0, n_bootstrap=args.bootstrap, **kw)
        ts.append(time.perf_counter() - t0)
    runs = f"{args.runs} runs pooled, " if args.runs > 1 else ""
    if args.omega_c is not None or args.oversample != 1:
        runs += f"omega_c {args.omega_c}, oversample {args.oversample}, "
    if args.washout is not None:
        runs += f"washout {args.washout:g} rad/s, calibration B = {args.calibrate}, "
    print(f"N = {rec.n_samples}, {runs}bootstrap B = {args.bootstrap}: decision {res.physics}")
    if args.runs > 1:
        print(f"wall time: median {np.median(ts):.1f} s, min {min(ts):.1f} s over {len(ts)} run(s)"
              f"; the refit after the test (last run) {res.settings.get('refit_seconds', 0):.1f} s")
        if args.shared_posterior:
            if res.chosen is None:
                print("shared_posterior: nothing chosen (simulate an effect: --washout)")
            else:
                t0 = time.perf_counter()
                post = shared_posterior(res, recs)
                print(f"shared_posterior: {time.perf_counter() - t0:.1f} s for "
                      f"{post.settings['points']} grid points x {args.runs} runs")
                print("\n".join(post.summary_lines()))
        print(f"load at the end: {os.getloadavg()}")
        return
    print(f"wall time: median {np.median(ts):.1f} s, min {min(ts):.1f} s over {len(ts)} run(s)")
    print("stages (last run): " + ", ".join(f"{k} {v:.1f} s"
                                            for k, v in res.settings["timings"].items()))
    if args.bayes_factor:
        t0 = time.perf_counter()
        bf = bayes_factor(res, rec, seed=0)
        print(f"bayes_factor: {time.perf_counter() - t0:.1f} s; {bf.summary_line()}")
        print("  likelihood calls: base "
              f"{bf.base.n_calls}, extended {bf.extended.n_calls}; runs kept: base "
              f"{sum(r['used'] for r in bf.settings['runs_base'])}/"
              f"{len(bf.settings['runs_base'])}, extended "
              f"{sum(r['used'] for r in bf.settings['runs_extended'])}/"
              f"{len(bf.settings['runs_extended'])}")
    print(f"load at the end: {os.getloadavg()}")


if __name__ == "__main__":
    main()

"""What the model's unknown start-up state costs the estimates, and what discarding a lead-in buys.

Run:  python analyses/lead_in.py [--realizations 20] [--discard 2.0]

With remnant, the pilot's output before t = 0 is not the periodic steady state
the likelihood assumes, so H_nm and the delays start in the wrong state and the
first 1-2 s of the residual carry a start-up error (``docs/faithfulness.md``,
part E).  For each task at K_theta = 1 and F_n = 0.2 the script simulates
``--realizations`` runs with the Table 3 pilot (delta_abs = 0.0075), refines
all eight parameters by Gauss-Newton from the truth (delta_abs held at the
truth: the question is the bias of the rest, not the optimiser) once on the
whole record (the paper's Eq. 4) and once with the first ``--discard``
seconds left out of Eq. 4, and prints the mean and standard deviation of the
relative error of every parameter for both.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from bayespilot.campaign import job_seed
from bayespilot.fit.gauss_newton import refine
from bayespilot.likelihood import Likelihood
from bayespilot.model import paper_model
from bayespilot.simulate import simulate

HERE = Path(__file__).resolve().parent


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--realizations", type=int, default=20)
    ap.add_argument("--discard", type=float, default=2.0)
    ap.add_argument("--out", type=Path, default=HERE / "results" / "lead_in.json")
    args = ap.parse_args(argv)
    model = paper_model()
    names = [n for n in model.parameter_names if n != "delta_abs"]
    table = {}
    for task in ("FD", "FT"):
        errs = {0.0: [], args.discard: []}
        for r in range(args.realizations):
            sim = simulate(task=task, motion_gain=1.0, remnant_fraction=0.2,
                           seed=job_seed("remnant", task, 1.0, 0.2, 1000 + r))
            truth = dict(sim.params)
            for d in errs:
                lik = Likelihood(model, sim.recording, discard=d)
                fit = refine(lik, truth, hold=("delta_abs",))
                errs[d].append([fit.params[n] / truth[n] - 1.0 for n in names])
        print(f"\n{task}, K_theta = 1, F_n = 0.2, {args.realizations} realizations: relative error "
              f"of the Gauss-Newton estimate from the truth, mean (sd)")
        print(f"{'':<10}" + "".join(f"{n:>16}" for n in names))
        for d, e in errs.items():
            e = np.array(e)
            label = "whole" if d == 0 else f"skip {d:g} s"
            print(f"{label:<10}" + "".join(f"{m:>+8.3f} ({s:.3f})" for m, s in
                                          zip(e.mean(0), e.std(0, ddof=1))))
            table[f"{task}_discard{d:g}"] = {"mean": dict(zip(names, e.mean(0).tolist())),
                                             "sd": dict(zip(names, e.std(0, ddof=1).tolist())),
                                             "n": len(e)}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(table, indent=1))
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The fast estimator beside the paper's three-step fit, on the same simulated data sets.

Run:  python analyses/fast_vs_faithful.py [--run N] [--workers 1]

The paper-method fits are those of the replication campaign
(``analyses/results/replication``, written by ``replicate_paper.py``).  The
fast fits (:func:`bayespilot.fit.fast.fit_fast`) of the very same recordings
(the recordings follow from the job's cell and realization alone, see
:mod:`bayespilot.campaign`) go to ``analyses/results/replication_fast``;
``--run N`` fits up to N recordings that have a paper fit but no fast fit
yet, through the same resumable dask campaign.

Printed, per method, over the recordings that both methods fitted with and
without threshold:

- accuracy: median absolute error of delta_abs, the fraction within +-50 % of
  the truth (the paper's N50 % as a fraction), and the median relative error
  of every other parameter;
- the -ln L reached: median of fast minus paper (negative: the fast one found
  a better optimum) and how often each was lower;
- time per fit;
- violations: the model with threshold contains the one without
  (delta_abs = 0), so at the optimum -ln L with threshold is never higher.
  How often does each estimator end with the threshold fit worse than the
  no-threshold fit (by more than 0.01)?
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from bayespilot import presets
from bayespilot.campaign import Job, load_results, paper_study, run_campaign

HERE = Path(__file__).resolve().parent
TOL = 0.01  # -ln L units: below this two optima are the same


def _by_recording(results: list[dict]) -> dict[tuple, dict[bool, dict]]:
    out: dict[tuple, dict[bool, dict]] = defaultdict(dict)
    for r in results:
        out[r["task"], r["motion_gain"], r["remnant_fraction"], r["realization"]][r["threshold"]] = r
    return out


def _jobs(method: str) -> list[Job]:
    return paper_study(100, tasks=("FD", "FT"), motion_gains=presets.MOTION_GAINS,
                       remnant_fractions=presets.REMNANT_FRACTIONS, threshold=(True, False),
                       method=method, remnant="table4")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", type=int, default=0,
                    help="fast-fit up to N recordings that have paper fits but no fast fits")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--paper-dir", type=Path, default=HERE / "results" / "replication")
    ap.add_argument("--fast-dir", type=Path, default=HERE / "results" / "replication_fast")
    args = ap.parse_args(argv)

    paper_jobs, fast_jobs = _jobs("paper"), _jobs("fast")
    paper = _by_recording(load_results(args.paper_dir, paper_jobs)) if args.paper_dir.is_dir() else {}
    have_fast = (_by_recording(load_results(args.fast_dir, fast_jobs))
                 if args.fast_dir.is_dir() else {})
    if args.run:
        want = []
        for rec, pair in paper.items():
            if len(pair) == 2 and len(have_fast.get(rec, {})) < 2:
                want += [j for j in fast_jobs if (j.task, j.motion_gain, j.remnant_fraction,
                                                  j.realization) == rec]
        want = want[:2 * args.run]
        if want:
            print(f"fast-fitting {len(want)} jobs")
            run_campaign(want, args.fast_dir, workers=args.workers, progress=False)
        have_fast = _by_recording(load_results(args.fast_dir, fast_jobs))

    common = [rec for rec in paper if len(paper[rec]) == 2 and len(have_fast.get(rec, {})) == 2]
    if not common:
        print("no recording has both paper and fast fits with and without threshold yet")
        return 0
    print(f"{len(common)} recordings fitted by both methods, with and without threshold "
          f"(cells: {len({r[:3] for r in common})})\n")
    names = [n for n in presets.PARAMETER_NAMES if n != "delta_abs"]
    stats = {}
    for label, res in (("paper", paper), ("fast", have_fast)):
        d_err, n50, rel, times, viol = [], [], defaultdict(list), [], []
        for rec in common:
            thr, nothr = res[rec][True], res[rec][False]
            truth = thr["true_params"]
            d = thr["fit"]["params"]["delta_abs"]
            d_err.append(abs(d - truth["delta_abs"]))
            n50.append(abs(d - truth["delta_abs"]) <= 0.5 * truth["delta_abs"])
            for n in names:
                rel[n].append(abs(thr["fit"]["params"][n] / truth[n] - 1.0))
            times += [thr["fit"]["elapsed_seconds"], nothr["fit"]["elapsed_seconds"]]
            viol.append(thr["fit"]["neg_log_lik"] > nothr["fit"]["neg_log_lik"] + TOL)
        stats[label] = dict(d_err=np.median(d_err), n50=np.mean(n50),
                            rel={n: np.median(v) for n, v in rel.items()},
                            time=np.median(times), viol=int(np.sum(viol)))
    dn = np.array([have_fast[r][True]["fit"]["neg_log_lik"] - paper[r][True]["fit"]["neg_log_lik"]
                   for r in common])
    n = len(common)
    print(f"{'':<34} {'paper (3-step)':>15} {'fast':>10}")
    print(f"{'median |delta_abs error|, IPUT':<34} {stats['paper']['d_err']:>15.4f} "
          f"{stats['fast']['d_err']:>10.4f}")
    print(f"{'fraction within +-50 % (N50/100)':<34} {stats['paper']['n50']:>15.2f} "
          f"{stats['fast']['n50']:>10.2f}")
    for p in names:
        print(f"{'median rel. error ' + p:<34} {stats['paper']['rel'][p]:>15.3f} "
              f"{stats['fast']['rel'][p]:>10.3f}")
    print(f"{'median time per fit, s':<34} {stats['paper']['time']:>15.1f} "
          f"{stats['fast']['time']:>10.1f}")
    print(f"{'threshold fit worse than none':<34} {stats['paper']['viol']:>10} of {n:<3} "
          f"{stats['fast']['viol']:>5} of {n}")
    print(f"\n-ln L with threshold, fast minus paper: median {np.median(dn):+.2f}; fast lower "
          f"(by > {TOL}) in {np.sum(dn < -TOL)}, paper lower in {np.sum(dn > TOL)}, "
          f"equal in {np.sum(np.abs(dn) <= TOL)} of {n}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Replicate the simulation study of Pool et al. (2012), Section III.B.2 (Figs. 14 and 15).

Run:  python analyses/replicate_paper.py [--realizations 100] [--chunk N] [--method paper]
                                         [--report-only]
                                         [--remnant table4|fraction] [--fits both|threshold|none]
                                         [--remnant-fractions 0,0.1,0.2,0.25,0.3]
                                         [--motion-gains 0.25,0.5,0.75,1]
                                         [--iterate]
                                         [--workers N | --scheduler tcp://host:8786]
                                         [--out analyses/results/replication]

The remnant gain of each cell is the paper's Table 4 value by default, the
same for every realization, as the paper did; ``--remnant fraction``
calibrates K_n on each realization to reach F_n exactly instead (in the
Table 3 loop of FD at K_theta = 0.25 some realizations cannot reach 0.3).

The study is 2 tasks x 4 K_theta x 5 F_n x 100 realizations, each fitted with
and without threshold: 8000 fits.  Every fit is written to
``OUT/<key>.json`` as it finishes (:func:`bayespilot.campaign.run_campaign`),
so the study runs in resumable pieces: ``--chunk N`` runs only the next N
unfinished fits and stops; run the script again to go on (an interrupted run
loses only the fits in flight).  The jobs are ordered realization first, so
after any chunk every cell has about the same number of realizations.

``--iterate`` repeats Steps II and III until nothing changes (our option, not
the paper's single pass) and writes to ``analyses/results/replication_iterate``
unless ``--out`` is given: the same recordings and GA seeds, so the two
directories compare fit for fit.

After each run the script prints our mu, sigma and N50 of delta_abs per cell
beside the paper's (over the fits finished so far), with the binomial check
of :func:`bayespilot.campaign.summarise`, and writes ``OUT/summary.csv``,
``OUT/summary.md`` and ``OUT/delta_abs_histograms.png``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from bayespilot import presets
from bayespilot.campaign import (CampaignError, Job, load_results, paper_study, run_campaign,
                                 summarise, summary_markdown, write_summary_csv)

HERE = Path(__file__).resolve().parent


def _unfinished(jobs: list[Job], out: Path) -> list[Job]:
    done = {r["key"] for r in load_results(out, jobs)} if out.is_dir() else set()
    return [j for j in jobs if j.key not in done]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--realizations", type=int, default=100,
                    help="remnant realizations per cell (default 100, as in the paper)")
    ap.add_argument("--chunk", type=int, default=None,
                    help="run at most this many unfinished fits, then stop (default: all)")
    ap.add_argument("--method", choices=("paper", "fast"), default="paper")
    ap.add_argument("--workers", type=int, default=None,
                    help="local worker processes (default one per core)")
    ap.add_argument("--scheduler", default=None, help="address of a running dask scheduler")
    ap.add_argument("--out", type=Path, default=None,
                    help="result directory (default analyses/results/replication, or "
                         "replication_iterate with --iterate)")
    ap.add_argument("--remnant", choices=("table4", "fraction"), default="table4",
                    help="K_n from the paper's Table 4 (default, as the paper did) or "
                         "calibrated to F_n per realization")
    ap.add_argument("--remnant-fractions", default="0,0.1,0.2,0.25,0.3",
                    help="comma-separated F_n of the grid (default all five; Figs. 14/15 "
                         "need 0,0.2,0.3)")
    ap.add_argument("--motion-gains", default=",".join(f"{k:g}" for k in presets.MOTION_GAINS),
                    help="comma-separated K_theta of the grid (default all four)")
    ap.add_argument("--fits", choices=("both", "threshold", "none"), default="both",
                    help="fit with and without threshold (default), or one of the two")
    ap.add_argument("--iterate", action="store_true",
                    help="repeat Steps II and III until nothing changes (paper method only)")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--report-only", action="store_true",
                    help="fit nothing: rebuild the summary from the result files")
    args = ap.parse_args(argv)
    if args.iterate and args.method != "paper":
        ap.error("--iterate is an option of the paper method")
    if args.out is None:
        args.out = HERE / "results" / ("replication_iterate" if args.iterate else "replication")
    if args.realizations < 1 or (args.chunk is not None and args.chunk < 1):
        ap.error("--realizations and --chunk must be >= 1")

    fractions = tuple(float(x) for x in args.remnant_fractions.split(","))
    thresholds = {"both": (True, False), "threshold": (True,), "none": (False,)}[args.fits]
    gains = tuple(float(x) for x in args.motion_gains.split(","))
    jobs = paper_study(args.realizations, tasks=("FD", "FT"), motion_gains=gains,
                       remnant_fractions=fractions, threshold=thresholds, method=args.method,
                       remnant=args.remnant, **({"iterate": True} if args.iterate else {}))
    todo = _unfinished(jobs, args.out)
    run = [] if args.report_only else todo if args.chunk is None else todo[:args.chunk]
    print(f"{len(jobs)} fits in the study ({args.method} method), {len(jobs) - len(todo)} "
          f"already in {args.out}; running {len(run)} now")
    t0 = time.perf_counter()
    if run:
        try:
            summary = run_campaign(run, args.out, scheduler=args.scheduler, workers=args.workers,
                                   progress=not args.no_progress)
        except CampaignError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        print(f"{summary}")
        for key, msg in list(summary.errors.items())[:10]:
            print(f"  failed: {key}: {msg}")
    results = load_results(args.out, jobs)
    left = len(jobs) - len(results)
    print(f"{len(results)} of {len(jobs)} fits done ({time.perf_counter() - t0:.0f} s this run)"
          + (f"; {left} to go: run the script again to continue" if left else ""))
    if not results:
        return 0
    rows = summarise(results)
    table = summary_markdown(rows)
    print()
    print(table)
    flagged = [r for r in rows if r["flag"]]
    n_paper = sum(r["paper_mu"] is not None for r in rows)
    print(f"\n{len(flagged)} of {n_paper} cells with a paper value flagged "
          f"(N50 beyond 2 binomial sd, or mu beyond 2 standard errors)")
    write_summary_csv(rows, args.out / "summary.csv")
    (args.out / "summary.md").write_text(
        "# Simulation study (Section III.B.2): ours beside Figs. 14/15\n\n"
        f"{len(results)} of {len(jobs)} fits ({args.method} method"
        f"{', Steps II-III iterated' if args.iterate else ''}), written by "
        f"analyses/replicate_paper.py.\n\n" + table + "\n", encoding="utf-8")
    if any(r["threshold"] for r in results):
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from bayespilot._figstyle import save_figure
        from bayespilot.plots import plot_threshold_histograms

        fig = plot_threshold_histograms(results, fractions=(0.0, 0.2, 0.3), method=args.method)
        save_figure(fig, args.out / "delta_abs_histograms.png")
        plt.close(fig)
        print(f"wrote {args.out / 'summary.csv'}, summary.md and delta_abs_histograms.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())

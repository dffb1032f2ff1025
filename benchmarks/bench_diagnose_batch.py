"""Time ``diagnose_batch`` on S subjects x R runs of N = 8192 on a local dask cluster.

Run:  python benchmarks/bench_diagnose_batch.py [--subjects 2] [--runs 4] [--workers 2]
                                                [--pool] [--reports] [--bootstrap 39]

Simulates task FD, F_n = 0.2, the paper's model (K_theta 1 for the first
subject, 0.75 for the second, ...), writes each run as a recording with its
subject in a temporary folder, and times the whole batch as a user runs it:
the cluster's start, the warm-up of numba's cache and every diagnosis.  Prints
the wall time, the time per recording, and the decisions.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

from bayespilot.diagnose.batch import batch_summary_rows, diagnose_batch, plan_batch
from bayespilot.io import read_recording, write_recording
from bayespilot.recording import Recording
from bayespilot.simulate import simulate


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--subjects", type=int, default=2)
    ap.add_argument("--runs", type=int, default=4, help="runs per subject")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--bootstrap", type=int, default=39)
    ap.add_argument("--pool", action="store_true", help="pool each subject's runs")
    ap.add_argument("--reports", action="store_true", help="write each report too")
    args = ap.parse_args(argv)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs; "
          f"{args.workers} workers; load {os.getloadavg()}")
    with tempfile.TemporaryDirectory() as tmp:
        paths = []
        for s in range(args.subjects):
            k = (1.0, 0.75, 0.5, 0.25)[s % 4]
            for j in range(args.runs):
                rec = simulate(task="FD", motion_gain=k, remnant_fraction=0.2,
                               seed=100 * s + j).recording
                stem = Path(tmp) / "recordings" / f"s{s + 1}-run{j + 1}"
                write_recording(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain,
                                          rec.task, {"subject": f"s{s + 1}", "run": j + 1}),
                                stem)
                paths.append(str(stem))
        out = Path(tmp) / "out"
        t0 = time.perf_counter()
        summary = diagnose_batch(paths, out, pool=args.pool, n_bootstrap=args.bootstrap,
                                 reports=args.reports, workers=args.workers)
        wall = time.perf_counter() - t0
        print(summary)
        print(f"wall {wall:.1f} s for {len(paths)} recordings "
              f"({wall / len(paths):.1f} s per recording on {args.workers} workers)")
        tasks = plan_batch(paths, [read_recording(p) for p in paths], pool=args.pool)
        for row in batch_summary_rows(tasks, out):
            print(f"  {row['key']}: {row['physics']} (smallest p {row['smallest_p_value']:.3g}, "
                  f"{row['smallest_p_candidate']})")


if __name__ == "__main__":
    main()

"""Single pass against iterated Steps II-III on the same replication data sets.

Reads the per-fit JSON files that ``analyses/replicate_paper.py`` writes to
``analyses/results/replication`` (the paper's single pass) and
``analyses/results/replication_iterate`` (``--iterate``), pairs the fits of
the same data set and GA seed, and prints per cell: mu and N50 of delta_abs
for both, the median gain in -ln L, and how often iterating ends lower,
equal or higher. At F_n = 0 it also counts the fits with threshold that end
worse than the nested fit without threshold (``*_nothr_*`` files in the
iterate folder; with delta_abs fixed at 0 there is nothing to iterate, so
they serve both).

Usage::

    python analyses/compare_iterate.py [--single DIR] [--iterated DIR]

Nothing is fitted here; the numbers in docs/replication.md ("Steps II and III
iterated") are this script's output.
"""
from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
TRUE_DELTA = 0.0075
EQUAL_TOL = 1e-3  # units of -ln L within which two fits count as equal


def _load(folder: Path, kind: str) -> dict[str, dict]:
    fits = {}
    for path in sorted(folder.glob(f"*_{kind}_paper_*.json")):
        d = json.loads(path.read_text())
        fits[d["key"].replace(f"_{kind}_", "_")] = d
    return fits


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--single", type=Path, default=HERE / "results" / "replication")
    ap.add_argument("--iterated", type=Path,
                    default=HERE / "results" / "replication_iterate")
    args = ap.parse_args(argv)

    single = _load(args.single, "thr")
    iterated = _load(args.iterated, "thr")
    none = _load(args.iterated, "nothr")
    keys = sorted(set(single) & set(iterated))
    if not keys:
        ap.error(f"no fit is in both {args.single} and {args.iterated}")

    cells: dict[tuple, list[str]] = defaultdict(list)
    for k in keys:
        d = iterated[k]
        cells[(d["task"], d["remnant_fraction"], d["motion_gain"])].append(k)

    def within(x):
        return abs(x - TRUE_DELTA) <= 0.5 * TRUE_DELTA

    lower = equal = higher = 0
    print(f"{len(keys)} fits in both folders\n")
    print("task  F_n   K  |  n | single mu  N50 | iterated mu  N50 | "
          "median gain in -ln L | nested worse (single / iterated)")
    for cell in sorted(cells):
        ks = cells[cell]
        ds = np.array([single[k]["fit"]["params"]["delta_abs"] for k in ks])
        di = np.array([iterated[k]["fit"]["params"]["delta_abs"] for k in ks])
        gain = np.array([single[k]["fit"]["neg_log_lik"]
                         - iterated[k]["fit"]["neg_log_lik"] for k in ks])
        lower += int(np.sum(gain > EQUAL_TOL))
        equal += int(np.sum(np.abs(gain) <= EQUAL_TOL))
        higher += int(np.sum(gain < -EQUAL_TOL))
        nested = ""
        with_none = [k for k in ks if k in none]
        if with_none:
            ref = {k: none[k]["fit"]["neg_log_lik"] for k in with_none}
            ws = sum(single[k]["fit"]["neg_log_lik"] > ref[k] for k in with_none)
            wi = sum(iterated[k]["fit"]["neg_log_lik"] > ref[k] for k in with_none)
            nested = f"{ws} / {wi} of {len(with_none)}"
        task, fn, kt = cell
        print(f"{task}  {fn:<4g} {kt:<4g} | {len(ks):2d} | "
              f"{ds.mean():.4f} {sum(map(within, ds)):3d}     | "
              f"{di.mean():.4f} {sum(map(within, di)):5d}    | "
              f"{np.median(gain):20.1f} | {nested}")
    print(f"\niterating ends lower on {lower}, equal on {equal}, higher on "
          f"{higher} of {len(keys)} (equal: within {EQUAL_TOL:g})")
    at_zero = [k for k in keys if iterated[k]["remnant_fraction"] == 0]
    di0 = [iterated[k]["fit"]["params"]["delta_abs"] for k in at_zero]
    near = sum(0.0075 <= d <= 0.0077 for d in di0)
    print(f"F_n = 0: iterated delta_abs in [0.0075, 0.0077] in {near} of {len(at_zero)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Time what fit-batch's command does before any fit: reading the recordings for their keys
and checking that no output file is an input or another output.

Run:  python benchmarks/bench_batch_preflight.py [--n 90 180 360 720]

Writes one 10-s recording (task FD, K_theta 1, F_n 0.2) under n names in a temporary
folder and times, as ``bayespilot fit-batch FOLDER --out OUT`` runs them,
``cli._batch_keys`` (every recording read) and ``cli._batch_files`` with
``cli._refuse_overwriting`` (the outputs against the inputs).  The check compared every
pair of files until 2026-11-29 (123 s at n = 720, paid on every resume); it now looks each
file up once.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import tempfile
import time
import warnings
from pathlib import Path

from bayespilot import cli
from bayespilot.io import write_recording
from bayespilot.simulate import simulate


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, nargs="+", default=[90, 180, 360, 720])
    args = ap.parse_args(argv)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs; "
          f"load {os.getloadavg()}")
    warnings.simplefilter("ignore")  # (10-s records: each questionable, said once a batch)
    rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=1,
                   duration=10.0).recording
    with tempfile.TemporaryDirectory() as tmp:
        one = Path(tmp) / "one"
        write_recording(rec, one)
        for n in args.n:
            folder = Path(tmp) / f"recs{n}"
            folder.mkdir()
            for i in range(n):
                for ext in (".csv", ".json"):
                    shutil.copyfile(one.with_suffix(ext), folder / f"s{i:04d}{ext}")
            paths = cli._recordings_in([str(folder)])
            out = Path(tmp) / f"out{n}"
            t0 = time.perf_counter()
            keys = cli._batch_keys(paths, pool=False) or []
            t1 = time.perf_counter()
            outputs = [("--out", f) for f in [*cli._batch_files(
                paths, out, pool=False, reports=False, keys=keys, formats=("png",)),
                out / "conditions.csv"]]
            inputs = [f for p in paths for f in cli._recording_files(p)]
            cli._refuse_overwriting(outputs, inputs)
            t2 = time.perf_counter()
            print(f"n = {n}: reading for the keys {t1 - t0:.2f} s; the overwrite check "
                  f"{t2 - t1:.3f} s ({len(outputs)} outputs, {len(inputs)} inputs)", flush=True)


if __name__ == "__main__":
    main()

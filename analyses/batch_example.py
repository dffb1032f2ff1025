"""A lab's batch: three subjects x four runs, one subject's simulator with a washout, diagnosed blind.

Run:  python analyses/batch_example.py [--workers 2]

Simulates task FD, K_theta = 1, F_n = 0.25 (Table 4's K_n), four runs each of
three subjects with the paper's Table 3 pilot: s1 and s3 on the correct model,
s2 with a motion-cueing washout at 0.3 rad/s that the recordings do not log
(the size at which one run is named in 7 of 8 cases in the proof study,
docs/diagnose-evidence.md).  Writes the twelve recordings (subject in each JSON, no
generator truth), then runs ``bayespilot.diagnose.batch.diagnose_batch`` on
them blind twice: each run alone, and each subject's runs pooled.  Prints
both summary tables beside the truth and writes
``docs/figures/diagnose_batch.png`` (each run alone) and
``docs/figures/diagnose_batch_pooled.png``; the batch outputs go to
``analyses/results/diagnose_batch/`` (git keeps the two ``summary.csv``; the
recordings and per-diagnosis files are rebuilt, and reused on a rerun).
"""

from __future__ import annotations

import argparse
import csv
import shutil
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "analyses" / "results" / "diagnose_batch"
FIG = ROOT / "docs" / "figures"
SUBJECTS = {"s1": None, "s2": 0.3, "s3": None}  # subject -> washout omega_w (None: none)
RUNS = 4


def write_recordings(folder: Path) -> list[str]:
    from bayespilot import presets
    from bayespilot.diagnose import get_extension
    from bayespilot.io import write_recording
    from bayespilot.model import paper_model
    from bayespilot.recording import Recording
    from bayespilot.simulate import simulate

    kn = presets.TABLE4_K_N[("FD", 0.25)][presets.MOTION_GAINS.index(1.0)]
    paths = []
    for i, (subject, omega_w) in enumerate(SUBJECTS.items()):
        model, params = paper_model(), presets.paper_parameters("FD")
        if omega_w is not None:
            model = get_extension("motion-washout").build(model)
            params["omega_w"] = omega_w
        for j in range(RUNS):
            stem = folder / f"{subject}-run{j + 1}"
            paths.append(str(stem))
            if stem.with_suffix(".json").is_file():
                continue
            rec = simulate(model, params, task="FD", motion_gain=1.0, remnant_gain=kn,
                           seed=7000 + 10 * i + j).recording
            write_recording(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain,
                                      rec.task, {"subject": subject, "run": j + 1}), stem)
    return paths


def show(out: Path, title: str) -> None:
    print(f"\n{title}")
    print(f"{'key':<14} {'truth':<15} {'decision':<16} {'p':>9}  {'params'}")
    for r in csv.DictReader((out / "summary.csv").open()):
        subject = r["subject"]
        truth = "motion-washout" if SUBJECTS[subject] is not None else "none"
        p = f"{float(r['p_value']):.2g}" if r["p_value"] else "-"
        print(f"{r['key']:<14} {truth:<15} {r['physics']:<16} {p:>9}  {r['params']}")


def main(argv=None) -> int:
    from bayespilot.diagnose.batch import diagnose_batch

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    paths = write_recordings(OUT / "recordings")
    for pool, name, fig in ((False, "alone", "diagnose_batch.png"),
                            (True, "pooled", "diagnose_batch_pooled.png")):
        t0 = time.perf_counter()
        summary = diagnose_batch(paths, OUT / name, pool=pool, workers=args.workers, seed=0)
        print(f"{summary} (wall {time.perf_counter() - t0:.0f} s)")
        show(OUT / name, "each run alone" if not pool else "each subject's runs pooled")
        shutil.copyfile(OUT / name / "summary.png", FIG / fig)
        print(f"wrote {FIG / fig}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

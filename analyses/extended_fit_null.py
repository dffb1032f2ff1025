"""An extended model fitted by the plain fitters on correct-model data: white Eq. 4 against AR.

A catalogue entry's model (``get_extension(name).build(paper_model())``) can
be handed to ``fit_fast``, ``sample`` and ``compare`` like any model. This
script shows which likelihood to compare it with the base model under. It
simulates control recordings of the paper's model (no extension in the
truth; the remnant coloured as the paper's), fits the base model and each
GLS entry of the catalogue with ``fit_fast``, once with Eq. 4's white
residual and once with ``noise="ar"`` (a prediction-error fit under an AR
noise model), and prints the -ln L improvement of the extension over the
base model. With no extension in the data the improvement should be about
what chance gives (a mean of df / 2 for df new parameters, less for an
entry whose base model sits at a bound), which is what ``diagnose``'s GLS
decision likelihood keeps; Eq. 4's white residual lets the extension's new
low-frequency freedom fit the coloured remnant instead.

Usage::

    python analyses/extended_fit_null.py [--runs N] [--out FILE.jsonl]

Default: 6 runs per task (FD and FT), K_theta 1, F_n 0.15, 81.92 s; about
10 minutes on one core. The numbers in docs/diagnose.md ("The extended model
in the other tools") are this script's output, stored in
``analyses/results/extended_fit_null.jsonl``.
"""
from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np

from bayespilot._seeds import spawn_seeds
from bayespilot.diagnose import get_extension
from bayespilot.fit.fast import fit_fast
from bayespilot.model import paper_model
from bayespilot.presets import paper_parameters
from bayespilot.simulate import simulate

HERE = Path(__file__).resolve().parent
#: The GLS entries (control-saturation is fitted by the censored likelihood, diagnose only).
ENTRIES = ("motion-system-dynamics", "motion-washout", "otolith-channel", "threshold-shape",
           "time-varying-gains")
SEED = 20261129


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=6, help="control runs per task (default 6)")
    ap.add_argument("--out", default=str(HERE / "results" / "extended_fit_null.jsonl"))
    args = ap.parse_args()
    seeds = spawn_seeds(SEED, 2 * args.runs)
    rows = []
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("w") as fh:
        for k, seed in enumerate(seeds):
            task = ("FD", "FT")[k // args.runs]
            rec = simulate(paper_model(), paper_parameters(task), task=task,
                           remnant_fraction=0.15, seed=seed, duration=81.92).recording
            row = {"task": task, "seed": seed, "improvement": {}}
            for noise in ("white", "ar"):
                kw = {"noise": "ar"} if noise == "ar" else {}
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    base = fit_fast(rec, paper_model(), seed=0, **kw).neg_log_lik
                    for name in ENTRIES:
                        model = get_extension(name).build(paper_model())
                        ext = fit_fast(rec, model, seed=0, **kw).neg_log_lik
                        row["improvement"].setdefault(name, {})[noise] = base - ext
            rows.append(row)
            fh.write(json.dumps(row) + "\n")
            fh.flush()
            print(f"run {k + 1}/{len(seeds)} ({task}, seed {seed}): "
                  + ", ".join(f"{n}: {v['white']:.2f} / {v['ar']:.2f}"
                              for n, v in row["improvement"].items()), flush=True)
    print("\n-ln L improvement of the extension over the base model on "
          f"{len(rows)} correct-model runs (white Eq. 4 | AR prediction error)")
    print(f"{'entry':24s} {'df':>3s} {'white median':>13s} {'white max':>10s} "
          f"{'AR median':>10s} {'AR max':>8s}")
    for name in ENTRIES:
        w = np.array([r["improvement"][name]["white"] for r in rows])
        a = np.array([r["improvement"][name]["ar"] for r in rows])
        print(f"{name:24s} {get_extension(name).df:3d} {np.median(w):13.2f} {w.max():10.2f} "
              f"{np.median(a):10.2f} {a.max():8.2f}")


if __name__ == "__main__":
    main()

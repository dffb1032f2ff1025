"""A held-out check of the posteriors' intervals and of compare's decision, by likelihood.

Run:  python analyses/heldout_check.py --posteriors eq4 --n 20
      python analyses/heldout_check.py --posteriors profiled --n 20
      python analyses/heldout_check.py --comparisons eq4 --delta 0 --n 20
      python analyses/heldout_check.py --comparisons coloured --delta 0 --n 10
      python analyses/heldout_check.py --comparisons eq4 --delta 0.0075 --n 10
      python analyses/heldout_check.py --report-only

``analyses/calibration.py`` chose the coloured likelihood on its own 200 recordings (seeds
from 4,000,000); this script checks the choice, and the defaults, on recordings it never saw:
FD, K_theta = 1, F_n = 0.2, 81.92 s, Table 3 truth (``--kt``, ``--fn``, ``--task`` for other
cells).  Everything else is the package's default.

* ``--posteriors LIK``: ``bayespilot.sample(rec, seed=r)`` with ``likelihood="eq4"`` (LIK
  ``eq4``) or ``"coloured"`` (LIK ``profiled``: the AR model profiled, ``sample``'s default
  ``ar``); recording seed 7,000,000 + 1000 case + r, case = 100 K_theta x 10 + 10 F_n
  (1002 for K_theta 1, F_n 0.2: seeds 8,002,000 + r).  The report counts how often the 90 %
  and 50 % HDIs (``Posterior.credible_interval``) and the central 90 % interval hold the
  truth, the spread of the posterior medians over the runs against the mean posterior sd (1
  is honest; above 1 the intervals are too narrow), and the same for the maximum-likelihood
  fit the chain starts from (``settings["init_point"]``: the prediction-error fit under the
  coloured likelihood, the Eq. 4 fit under Eq. 4).
* ``--comparisons LIK``: ``bayespilot.compare.compare(rec, seed=r)`` with ``likelihood=LIK``
  on recordings with delta_abs = ``--delta`` (seed 8,000,000 (+ 500 with a threshold) +
  1000 case + r: 9,002,000 + r without a threshold, 9,002,500 + r with), without the Savage-Dickey check (it does not enter the decision); the
  report counts the decisions.

One JSON per run in ``analyses/results/heldout_check/raw/`` (resumable: a run on disk is not
redone); one process, ``NUMBA_NUM_THREADS=1`` for the figures in docs/posteriors.md ("A
held-out check") and docs/comparison.md ("Which likelihood"): median 9 s per Eq. 4
posterior, 26 s profiled, 31 s per Eq. 4 comparison and 57 s coloured.
"""

from __future__ import annotations

import argparse
import json
import math
import time
import warnings
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
from scipy import stats

RAW = Path(__file__).resolve().parent / "results" / "heldout_check" / "raw"
NAMES = ("K_v", "T_vl", "tau_v", "K_m", "tau_m", "omega_nm", "zeta_nm", "delta_abs")


def _case(task: str, kt: float, fn: float) -> int:
    """The cell's number in the seeds: 100 K_theta x 10 + 10 F_n (+ 5000 for FT); one per cell
    for K_theta a multiple of 0.01 and F_n of 0.1 below 1, which is checked (F_n 0.15 and 0.2
    would share one)."""
    if abs(kt * 100 - round(kt * 100)) > 1e-9 or abs(fn * 10 - round(fn * 10)) > 1e-9 \
            or not 0 <= fn < 1:
        raise SystemExit(f"--kt {kt} --fn {fn}: the seeds take K_theta in steps of 0.01 and "
                         "F_n in steps of 0.1 below 1")
    return int(round(kt * 100)) * 10 + int(round(fn * 10)) + (0 if task == "FD" else 5000)


def run_posteriors(lik: str, task: str, kt: float, fn: float, start: int, n: int) -> None:
    """Sample the posterior of runs start..start+n-1 (those not on disk)."""
    import bayespilot
    from bayespilot.presets import paper_parameters
    from bayespilot.simulate import simulate

    tag = f"{lik}_{task}_kt{kt}_fn{fn}"
    for r in range(start, start + n):
        path = RAW / f"{tag}_r{r:03d}.json"
        if path.exists():
            continue
        seed = 7_000_000 + 1000 * _case(task, kt, fn) + r
        truth = dict(paper_parameters(task))
        rec = simulate(params=truth, task=task, motion_gain=kt, remnant_fraction=fn,
                       seed=seed).recording
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            post = bayespilot.sample(rec, seed=r, progress=False,
                                     likelihood="eq4" if lik == "eq4" else "coloured")
        res = {"tag": tag, "r": r, "seed": seed, "truth": truth, "lik": lik,
               "elapsed": time.perf_counter() - t0, "converged": bool(post.converged),
               "n_steps": post.settings.get("n_steps"), "summary": post.summary(),
               "init_point": post.settings.get("init_point"), "params": {}}
        for name in post.parameter_names:
            x = np.asarray(post.idata.posterior[name].values, dtype=float).ravel()
            res["params"][name] = {
                "sd": float(x.std(ddof=1)),
                "quantiles": np.quantile(x, [0.05, 0.25, 0.5, 0.75, 0.95]).tolist(),
                "hdi50": list(post.credible_interval(name, 0.5)),
                "hdi90": list(post.credible_interval(name, 0.9))}
        RAW.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(res, indent=1, default=float))
        print(f"{tag} r{r:03d}: {res['elapsed']:.0f} s, converged {res['converged']}",
              flush=True)


def run_comparisons(lik: str, delta: float, task: str, kt: float, fn: float, start: int,
                    n: int) -> None:
    """Compare runs start..start+n-1 with and without threshold (those not on disk)."""
    from bayespilot.compare import compare
    from bayespilot.presets import paper_parameters
    from bayespilot.simulate import simulate

    tag = f"cmp_{lik}_{task}_kt{kt}_fn{fn}_d{delta}"
    for r in range(start, start + n):
        path = RAW / f"{tag}_r{r:03d}.json"
        if path.exists():
            continue
        seed = 8_000_000 + (0 if delta == 0 else 500) + 1000 * _case(task, kt, fn) + r
        truth = dict(paper_parameters(task), delta_abs=delta)
        rec = simulate(params=truth, task=task, motion_gain=kt, remnant_fraction=fn,
                       seed=seed).recording
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            c = compare(rec, seed=r, savage_dickey_samples=False, likelihood=lik)
        res = {"tag": tag, "r": r, "seed": seed, "truth": truth,
               "elapsed": time.perf_counter() - t0, "decision": c.decision,
               "log_bayes_factor": c.log_bayes_factor,
               "log_bayes_factor_err": c.log_bayes_factor_err}
        RAW.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(res, indent=1, default=float))
        print(f"{tag} r{r:03d}: ln BF {c.log_bayes_factor:+.1f} -> {c.decision}", flush=True)


def report() -> None:
    """The coverage and decision tables from what is on disk."""
    groups = defaultdict(list)
    for f in sorted(RAW.glob("*.json")):
        d = json.loads(f.read_text())
        groups[d["tag"]].append(d)
    for tag, rows in groups.items():
        n = len(rows)
        if tag.startswith("cmp_"):
            counts = Counter(r["decision"] for r in rows)
            bf = [r["log_bayes_factor"] for r in rows]
            print(f"\n{tag}: {n} recordings: " + ", ".join(f"{k} {v}" for k, v in
                                                         sorted(counts.items()))
                  + f"; ln BF {min(bf):+.1f} to {max(bf):+.1f}")
            continue
        lo, hi = (int(stats.binom.ppf(q, n, 0.9)) for q in (0.025, 0.975))
        print(f"\n{tag}: {n} runs, converged {sum(r['converged'] for r in rows)}; 90 % HDIs "
              f"should hold the truth in {0.9 * n:.1f} (95 % range {lo}-{hi})")
        print(f"  {'param':9s} {'HDI90':>6s} {'HDI50':>6s} {'cen90':>6s} {'sd(med)/psd':>12s} "
              f"{'sd(fit)/psd':>12s}")
        for p in NAMES:
            t = np.array([r["truth"][p] for r in rows])
            h90 = np.array([r["params"][p]["hdi90"] for r in rows])
            h50 = np.array([r["params"][p]["hdi50"] for r in rows])
            q = np.array([r["params"][p]["quantiles"] for r in rows])
            psd = np.array([r["params"][p]["sd"] for r in rows])
            k90 = int(np.sum((h90[:, 0] <= t) & (t <= h90[:, 1])))
            k50 = int(np.sum((h50[:, 0] <= t) & (t <= h50[:, 1])))
            c90 = int(np.sum((q[:, 0] <= t) & (t <= q[:, 4])))
            ratio = q[:, 2].std(ddof=1) / psd.mean() if n > 1 else math.nan
            fit = np.array([(r.get("init_point") or {}).get(p, math.nan) for r in rows])
            fit_ratio = np.std(fit, ddof=1) / psd.mean() if n > 1 else math.nan
            print(f"  {p:9s} {k90:3d}/{n:<2d} {k50:3d}/{n:<2d} {c90:3d}/{n:<2d} {ratio:12.2f} "
                  f"{fit_ratio:12.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--posteriors", choices=("eq4", "profiled"))
    ap.add_argument("--comparisons", choices=("eq4", "coloured"))
    ap.add_argument("--delta", type=float, default=0.0, help="delta_abs of --comparisons' runs")
    ap.add_argument("--task", default="FD", choices=("FD", "FT"))
    ap.add_argument("--kt", type=float, default=1.0)
    ap.add_argument("--fn", type=float, default=0.2)
    ap.add_argument("--start", type=int, default=0)
    ap.add_argument("--n", type=int, default=20)
    ap.add_argument("--report-only", action="store_true")
    a = ap.parse_args()
    if not a.report_only:
        if a.posteriors:
            run_posteriors(a.posteriors, a.task, a.kt, a.fn, a.start, a.n)
        if a.comparisons:
            run_comparisons(a.comparisons, a.delta, a.task, a.kt, a.fn, a.start, a.n)
    report()


if __name__ == "__main__":
    main()

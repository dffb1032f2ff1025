"""The paper's Fig. 11 (with against without threshold) redone as a Bayesian model comparison.

Run:  python analyses/fig11_comparison.py [--realizations 2] [--chunk N] [--null]
                                          [--likelihood coloured|eq4] [--report-only]

Fig. 11 of Pool et al. (2012) compares the mean final -ln L of the model with
and without threshold over the 40 experimental data sets of each condition
(task x K_theta) with a two-sample t-test (t(78)), and finds no significant
difference anywhere.  The experimental data are not available, so this script
simulates recordings of each condition (Table 3 truth, delta_abs = 0.0075
IPUT, F_n = 0.2, T0 = 81.92 s) and runs :func:`bayespilot.compare.compare` on
each: the log Bayes factor from nested sampling, the decision per recording,
the pooled sum of ln BF per condition with its decision, and the paired
t-test of the per-recording ln BF; beside it, the paper's style of test on
our maximum-likelihood -ln L (two-sample t-test with against without) and the
paper's numbers.  ``--null`` adds recordings simulated with delta_abs = 0 (no
threshold) for the same conditions.  The likelihood is the prediction-error
(``coloured``) one by default: under Eq. 4, 8192 correlated samples count as
independent and every Bayes factor is overconfident.

Resumable: one JSON per comparison in ``analyses/results/fig11/`` (the
likelihood in its name, e.g. ``FD_k1_d0.0075_r000_coloured.json``; the
first four, without a suffix, used Eq. 4).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from bayespilot._files import dumps, number

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "analyses" / "results" / "fig11"
TASKS = ("FD", "FT")
GAINS = (0.25, 0.5, 0.75, 1.0)
F_N = 0.2


def seed_of(task, k, delta, r) -> int:
    return 6_000_000 + 100_000 * TASKS.index(task) + 10_000 * GAINS.index(k) + \
        (5_000 if delta == 0 else 0) + r


def _path(task, k, delta, r, lik) -> Path:
    return OUT / f"{task}_k{k:g}_d{delta:g}_r{r:03d}{'' if lik == 'eq4' else '_' + lik}.json"


def run_one(task, k, delta, r, nlive, savage_dickey, lik) -> None:
    from bayespilot.compare import compare
    from bayespilot.presets import paper_parameters
    from bayespilot.simulate import simulate

    p = paper_parameters(task)
    p["delta_abs"] = delta
    sim = simulate(params=p, task=task, motion_gain=k, remnant_fraction=F_N,
                   seed=seed_of(task, k, delta, r))
    t0 = time.perf_counter()
    c = compare(sim.recording, likelihood=lik, seed=r, nlive=nlive,
                savage_dickey_samples=savage_dickey)
    d = c.to_dict()
    d.update({"task": task, "K_theta": k, "true_delta_abs": delta, "realization": r,
              "F_n": F_N, "sim_seed": seed_of(task, k, delta, r), "likelihood": lik})
    path = _path(task, k, delta, r, lik)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(dumps(d))  # standard JSON: a non-finite number as null
    print(f"  {task} K={k:g} delta={delta:g} r{r}: ln BF = {c.log_bayes_factor:+.2f} +- "
          f"{c.log_bayes_factor_err:.2f} -> {c.decision} ({time.perf_counter() - t0:.0f} s)",
          flush=True)


def _read(path: Path) -> dict:
    """One comparison file, with NaN again where :func:`bayespilot._files.dumps` wrote null
    for a non-finite number, in the numbers the report computes with."""
    d = json.loads(path.read_text())
    for k in ("log_bayes_factor", "log_bayes_factor_err"):
        if k in d:
            d[k] = number(d[k])
    ic = d.get("information_criteria") or {}
    for k in ("neg_log_lik_threshold", "neg_log_lik_none"):
        if k in ic:
            ic[k] = number(ic[k])
    return d


def report(rows) -> dict:
    from scipy import stats

    from bayespilot.compare import pool
    from bayespilot.presets import FIG11

    out = {}
    for delta in sorted({r["true_delta_abs"] for r in rows}, reverse=True):
        print(f"\nSimulated with delta_abs = {delta:g} IPUT, F_n = {F_N}:")
        print(f"{'cell':<9} | {'paper: -lnL with / without, t, p':>36} | n | "
              f"{'ours: mean -lnL with / without':>31} | {'t, p':>11} | "
              f"{'sum ln BF':>15} | {'pooled':>12} | {'per recording (thr/none/inc)':>28} | "
              f"paired t p | P(plateau) per recording")
        for k in GAINS:
            for task in TASKS:
                sel = [r for r in rows if r["task"] == task and r["K_theta"] == k
                       and r["true_delta_abs"] == delta]
                if not sel:
                    continue
                pw, pn, pt, pp = FIG11[(task, k)]
                ic1 = [r["information_criteria"]["neg_log_lik_threshold"] for r in sel]
                ic0 = [r["information_criteria"]["neg_log_lik_none"] for r in sel]
                if len(sel) >= 2:
                    tt = stats.ttest_ind(ic1, ic0)
                    t_txt = f"{abs(tt.statistic):.2f}, {tt.pvalue:.2f}"
                else:
                    t_txt = "-"
                pl = pool(sel, label=f"{task} {k:g}")
                dec = pl.decisions
                paired = "-" if math.isnan(pl.t_pvalue) else f"{pl.t_pvalue:.3g}"
                plateau = [r.get("plateau_probability") for r in sel]
                pl_txt = "/".join("-" if v is None else f"{v:.2f}" for v in plateau)
                print(f"{task} {k:<6g} | {pw:>9.1f} / {pn:>9.1f}, {pt:.3f}, {pp:.2f} | "
                      f"{len(sel)} | {np.mean(ic1):>14.1f} / {np.mean(ic0):>14.1f} | {t_txt:>11} | "
                      f"{pl.log_bayes_factor:+7.1f} +- {pl.log_bayes_factor_err:4.1f} | "
                      f"{pl.decision:>12} | {dec['threshold']:>10}/{dec['none']}/{dec['inconclusive']:<15}"
                      f" | {paired:>10} | {pl_txt}"
                      + (f"\n{'':<9}   pooled: {pl.decision_note}" if pl.decision_note else ""))
                out[f"{task}_k{k:g}_d{delta:g}"] = dict(pl.to_dict(), mean_nll_threshold=float(
                    np.mean(ic1)), mean_nll_none=float(np.mean(ic0)),
                    log_bayes_factors=[r["log_bayes_factor"] for r in sel],
                    decisions_per_recording=[r["decision"] for r in sel],
                    plateau_probabilities=plateau,
                    paper=[pw, pn, pt, pp])
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realizations", type=int, default=2)
    ap.add_argument("--chunk", type=int, default=None)
    ap.add_argument("--nlive", type=int, default=150)
    ap.add_argument("--likelihood", choices=("coloured", "eq4"), default="coloured")
    ap.add_argument("--null", action="store_true", help="also delta_abs = 0 recordings")
    ap.add_argument("--gains", default="0.25,0.5,0.75,1")
    ap.add_argument("--savage-dickey", action="store_true", help="also sample for Savage-Dickey")
    ap.add_argument("--report-only", action="store_true")
    args = ap.parse_args(argv)
    gains = tuple(float(g) for g in args.gains.split(","))
    deltas = (0.0075, 0.0) if args.null else (0.0075,)
    done = 0
    if not args.report_only:
        for r in range(args.realizations):
            for delta in deltas:
                for k in gains:
                    for task in TASKS:
                        if _path(task, k, delta, r, args.likelihood).exists():
                            continue
                        if args.chunk is not None and done >= args.chunk:
                            break
                        run_one(task, k, delta, r, args.nlive, args.savage_dickey,
                                args.likelihood)
                        done += 1
    rows = [d for d in (_read(p) for p in sorted(OUT.glob("*_r[0-9]*.json")))
            if d.get("likelihood", "eq4") == args.likelihood]
    if not rows:
        print("no results yet")
        return 0
    summary = report(rows)
    out = OUT / f"summary_{args.likelihood}.json"
    out.write_text(dumps(summary, version=False))  # (its keys are all cells)
    print(f"\nwrote {out.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

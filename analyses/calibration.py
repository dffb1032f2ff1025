"""Calibration of the posterior credible intervals (issue 4, item 3).

Run:  python analyses/calibration.py [--chunk N] [--per-task 100] [--report-only]

Simulates recordings at F_n = 0.2, K_theta = 1 for both tasks (FD, FT; Table 3
truth, the paper's T0 = 81.92 s) and samples the posterior of each under the
two likelihoods of :func:`bayespilot.sample.sample`:

``eq4``
    white output error (the paper's Eq. 4), started from the fast
    output-error fit;
``coloured``
    the default coloured likelihood: an AR model of the output error (order
    by BIC) estimated from a prediction-error fit (``fit_fast(noise="ar")``)
    and held fixed, the first 2 s left out, started from that fit.

``profiled``
    the coloured likelihood with the AR model (the same order) re-estimated
    at every parameter vector (``sample(..., ar="profiled")``), from the
    same prediction-error fit: it tests whether the too-narrow gains of the
    fixed AR model come from holding the noise model fixed in closed loop.

``profiled8``
    the profiled coloured likelihood with the vestibular channel at 8 times
    the recording's rate (``paper_model(oversample=8)``), from the same
    prediction-error fit: it tests whether delta_abs's over-wide intervals
    come from the 100-Hz model's error at the dead zone's corners
    (``analyses/threshold_information.py --kinks``).

A fifth set, ``ar2`` (the first version of the coloured likelihood: an AR(2)
model sampled with the pilot parameters, the whole record), was run on the
first 14 recordings only; it is reported beside the others because it shows
why the AR order matters, and is not run further (``--likelihoods`` can).

For every
parameter it records whether the central (equal-tailed) 50 % and 90 % credible
intervals contain the truth, and prints the fraction that do with a 95 %
binomial (Wilson) interval, beside the nominal level and the band within
which a calibrated method's fraction falls 95 % of the time.

Resumable: one JSON per (recording, likelihood) in
``analyses/results/calibration/`` (e.g. ``FD_r007_coloured.json``) and one per
recording for the shared fit; ``--chunk N`` does the next N recordings that
are unfinished (recordings alternate between tasks, so any prefix is
balanced), then prints the table from everything on disk and writes
``docs/figures/calibration_coverage.png`` and ``.../calibration/summary.json``.
A higher ``--max-steps`` than a chain on disk stopped at redoes that chain if
it had not converged, so the cap of the whole study can be raised afterwards.
"""

from __future__ import annotations

import argparse
import json
import math
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "analyses" / "results" / "calibration"
FIGURE = ROOT / "docs" / "figures" / "calibration_coverage.png"
TASKS = ("FD", "FT")
LIKELIHOODS = ("eq4", "coloured", "profiled", "profiled8", "ar2")
#: sample() options of each likelihood studied.
OPTIONS = {"eq4": {"likelihood": "eq4"},
           "coloured": {"likelihood": "coloured", "ar": "fixed"},
           "profiled": {"likelihood": "coloured", "ar": "profiled"},
           "profiled8": {"likelihood": "coloured", "ar": "profiled"},
           "ar2": {"likelihood": "coloured", "ar": "sampled", "ar_order": 2, "discard": 0.0}}
#: The vestibular channel's oversampling factor of each likelihood studied (default 1).
OVERSAMPLE = {"profiled8": 8}
#: Panel titles of the figure ("Eq. (4) likelihood" as the package's figures name it).
LABELS = {"eq4": "Eq. (4) likelihood", "coloured": "coloured, AR fixed",
          "profiled": "coloured, AR profiled",
          "profiled8": "AR profiled, motion 8x", "ar2": "coloured, AR(2) sampled"}
F_N, K_THETA = 0.2, 1.0
LEVELS = (0.5, 0.9)
NAMES = ("K_v", "T_vl", "tau_v", "K_m", "tau_m", "omega_nm", "zeta_nm", "delta_abs")


def seed_of(task: str, r: int) -> int:
    """Seed of realization r of a task (disjoint from the replication campaign's seeds)."""
    return 4_000_000 + 100_000 * TASKS.index(task) + r


def jobs(per_task: int):
    for r in range(per_task):
        for task in TASKS:
            yield task, r


def _path(task: str, r: int, what: str) -> Path:
    return OUT / f"{task}_r{r:03d}_{what}.json"


def _write(path: Path, obj) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(obj, indent=1, allow_nan=True))
    tmp.replace(path)


def _finished(task: str, r: int, lik: str, max_steps: int) -> bool:
    """Whether a posterior is on disk that this run would not redo.

    A chain that stopped at a lower cap than ``max_steps`` without converging
    is redone: sampling is seeded, so the rerun repeats its steps and goes on,
    and the study is then the one run with the higher cap throughout.
    """
    path = _path(task, r, lik)
    if not path.exists():
        return False
    d = json.loads(path.read_text())
    return bool(d["converged"]) or d["n_steps"] >= max_steps


def run_one(task: str, r: int, likelihoods, max_steps: int) -> None:
    from bayespilot.fit.fast import fit_fast
    from bayespilot.fit.result import FitResult
    from bayespilot.model import paper_model
    from bayespilot.presets import paper_parameters
    from bayespilot.sample import ConvergenceWarning, sample
    from bayespilot.simulate import simulate

    truth = paper_parameters(task)
    sim = simulate(task=task, motion_gain=K_THETA, remnant_fraction=F_N, seed=seed_of(task, r))
    rec = sim.recording
    def fit_of(what, **kw):
        path = _path(task, r, what)
        if path.exists():
            return FitResult.from_dict(json.loads(path.read_text()))
        fit = fit_fast(rec, seed=r, n_starts=4, **kw)
        _write(path, fit.to_dict(full=False))
        return fit

    for lik in likelihoods:
        path = _path(task, r, lik)
        if _finished(task, r, lik, max_steps):
            continue
        # the output-error fit for Eq. 4 (and AR(2)); a prediction-error fit for the AR model
        fit = (fit_of("fitpem", noise="ar", discard=2.0)
               if lik in ("coloured", "profiled", "profiled8") else fit_of("fit"))
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            post = sample(rec, paper_model(oversample=OVERSAMPLE.get(lik, 1)), **OPTIONS[lik],
                          init=fit, seed=r, max_steps=max_steps, progress=False)
        q = {}
        for n in NAMES:
            x = post.draws(n)
            q[n] = {str(p): float(v) for p, v in
                    zip((0.05, 0.25, 0.5, 0.75, 0.95), np.quantile(x, (0.05, 0.25, 0.5, 0.75, 0.95)))}
            q[n]["hdi_50"] = list(post.credible_interval(n, 0.5))
            q[n]["hdi_90"] = list(post.credible_interval(n, 0.9))
        _write(path, {"task": task, "realization": r, "seed": seed_of(task, r), "likelihood": lik,
                      "truth": truth, "quantiles": q, "converged": post.converged,
                      "tau": post.tau, "n_steps": post.settings["n_steps"],
                      "n_draws": int(post.draws("K_v").size),
                      "acceptance": post.settings["acceptance_fraction"],
                      "seconds": time.perf_counter() - t0, "fit_seconds": fit.elapsed,
                      "remnant_fraction": sim.remnant_fraction,
                      "settings": {k: post.settings.get(k) for k in
                                   ("likelihood", "ar", "ar_order", "discard_seconds",
                                    "model")}})
        print(f"  {task} r{r:03d} {lik:>8}: {post.settings['n_steps']} steps, "
              f"{'converged' if post.converged else 'NOT converged'}, "
              f"{time.perf_counter() - t0:.0f} s", flush=True)


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion k/n."""
    if n == 0:
        return (math.nan, math.nan)
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return (c - h, c + h)


def load():
    rows = []
    for p in sorted(OUT.glob("*_r*_*.json")):
        if p.name.endswith(("_fit.json", "_fitpem.json")):
            continue
        rows.append(json.loads(p.read_text()))
    return rows


def coverage(rows, lik: str, task: str | None = None, kind: str = "central"):
    """{name: {level: (k, n)}} for rows of one likelihood (and task)."""
    sel = [r for r in rows if r["likelihood"] == lik and (task is None or r["task"] == task)]
    out = {}
    for name in NAMES:
        out[name] = {}
        for level in LEVELS:
            k = 0
            for r in sel:
                q = r["quantiles"][name]
                if kind == "central":
                    lo, hi = q[str(round(0.5 - level / 2, 2))], q[str(round(0.5 + level / 2, 2))]
                else:
                    lo, hi = q[f"hdi_{int(level * 100)}"]
                k += lo <= r["truth"][name] <= hi
            out[name][level] = (k, len(sel))
    return out


def report(rows) -> dict:
    summary = {}
    for lik in LIKELIHOODS:
        n_all = sum(1 for r in rows if r["likelihood"] == lik)
        if not n_all:
            continue
        conv = sum(1 for r in rows if r["likelihood"] == lik and r["converged"])
        secs = [r["seconds"] for r in rows if r["likelihood"] == lik]
        print(f"\n{lik} likelihood: {n_all} recordings ({sum(1 for r in rows if r['likelihood'] == lik and r['task'] == 'FD')} FD, "
              f"{sum(1 for r in rows if r['likelihood'] == lik and r['task'] == 'FT')} FT), "
              f"{conv} converged, median {np.median(secs):.0f} s per posterior")
        band = {lv: 1.96 * math.sqrt(lv * (1 - lv) / n_all) for lv in LEVELS}
        print(f"{'parameter':<10} | {'50% coverage [95% CI]':>24} | {'90% coverage [95% CI]':>24} |"
              f" FD 50/90 | FT 50/90")
        cov = coverage(rows, lik)
        per = {t: coverage(rows, lik, t) for t in TASKS}
        summary[lik] = {"n": n_all, "converged": conv, "nominal_band": band, "parameters": {}}
        for name in NAMES:
            cells = []
            entry = {}
            for lv in LEVELS:
                k, n = cov[name][lv]
                lo, hi = wilson(k, n)
                flag = "" if abs(k / n - lv) <= band[lv] else "*"
                cells.append(f"{k / n:5.2f}{flag:1} [{lo:4.2f}, {hi:4.2f}] ({k:>3}/{n})")
                entry[str(lv)] = {"k": k, "n": n, "fraction": k / n, "wilson_95": [lo, hi],
                                  "within_band": not flag}
            pt = " | ".join("{:.2f}/{:.2f}".format(*(per[t][name][lv][0] / max(per[t][name][lv][1], 1)
                                                     for lv in LEVELS)) for t in TASKS)
            print(f"{name:<10} | {cells[0]:>24} | {cells[1]:>24} | {pt}")
            summary[lik]["parameters"][name] = entry
        print(f"(* outside the band nominal +- 1.96 sqrt(p(1-p)/n): 50%: +-{band[0.5]:.3f}, "
              f"90%: +-{band[0.9]:.3f})")
    return summary


def figure(rows, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from bayespilot._figstyle import save_figure
    from bayespilot._labels import symbol

    liks = [lk for lk in LIKELIHOODS if any(r["likelihood"] == lk for r in rows)]
    # two panels a row (a page's width, 7 in); the legend in the free cell, else below
    ncols = min(len(liks), 2)
    nrows = math.ceil(len(liks) / ncols)
    free = nrows * ncols > len(liks)
    fig, axes = plt.subplots(nrows, ncols, figsize=(7.0, 2.5 * nrows + 0.6 + (0 if free else 0.4)),
                             sharey=True, squeeze=False, layout="constrained")
    x = np.arange(len(NAMES))
    colours = dict(zip(LEVELS, ("C0", "C1")))
    markers = dict(zip(LEVELS, ("o", "s")))  # told apart without colour too (greyscale)
    for a, lik in zip(axes.flat, liks):
        cov = coverage(rows, lik)
        n = cov[NAMES[0]][LEVELS[0]][1]
        for j, lv in enumerate(LEVELS):
            col = colours[lv]
            band = 1.96 * math.sqrt(lv * (1 - lv) / n)
            a.axhspan(lv - band, lv + band, color=col, alpha=0.15, lw=0)
            a.axhline(lv, color=col, lw=0.8, ls="--")
            f = np.array([cov[nm][lv][0] / n for nm in NAMES])
            ci = np.array([wilson(cov[nm][lv][0], n) for nm in NAMES])
            a.errorbar(x + (j - 0.5) * 0.2, f, yerr=[f - ci[:, 0], ci[:, 1] - f],
                       fmt=markers[lv], color=col, ms=3.5, capsize=2)
        a.set_xticks(x, [symbol(nm) for nm in NAMES])
        a.set_ylim(-0.04, 1.04)  # a share of 0 shows its whole marker
        a.set_title(f"{LABELS[lik]}: {n} recordings", fontsize="medium")
        a.grid(True, axis="y", lw=0.3, alpha=0.6)
    for a in axes[:, 0]:
        a.set_ylabel("share of intervals\nholding the truth")
    handles = []
    for lv in LEVELS:
        c = colours[lv]
        handles += [Line2D([], [], ls="none", marker=markers[lv], ms=3.5, color=c,
                           label=f"{int(lv * 100)} % intervals: share, 95 % Wilson interval"),
                    Line2D([], [], color=c, lw=0.8, ls="--",
                           label=f"nominal {int(lv * 100)} %"),
                    Patch(color=c, alpha=0.15, lw=0,
                          label=f"95 % range of a calibrated method's {int(lv * 100)} %")]
    if free:  # the empty cell of the grid holds the legend, off every panel's points
        for a in list(axes.flat)[len(liks):]:
            a.set_axis_off()
        axes.flat[-1].legend(handles=handles, loc="center", fontsize="small", frameon=False)
    else:
        fig.legend(handles=handles, loc="outside lower center", ncol=2, fontsize="small",
                   frameon=False)
    fig.suptitle(f"Coverage of central credible intervals\n({symbol('F_n')} = {F_N}, "
                 f"{symbol('K_theta')} = {K_THETA:g}, FD and FT)", fontsize="medium")
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-task", type=int, default=100, help="recordings per task (default 100)")
    ap.add_argument("--chunk", type=int, default=None,
                    help="do at most this many unfinished recordings, then report")
    ap.add_argument("--likelihoods", default="eq4,coloured",
                    help="comma-separated, of eq4, coloured, profiled, profiled8, ar2 "
                         "(default eq4,coloured)")
    ap.add_argument("--max-steps", type=int, default=6000,
                    help="cap on the steps of each chain (default 6000); raising it redoes "
                         "the chains that stopped at a lower cap without converging")
    ap.add_argument("--tasks", default=",".join(TASKS),
                    help="comma-separated tasks to run (default FD,FT; two processes can "
                         "take one task each)")
    ap.add_argument("--from", dest="first", type=int, default=0, metavar="R",
                    help="start at realization R (a second process can take the end of a "
                         "task's list; the first skips what it finds done)")
    ap.add_argument("--report-only", action="store_true")
    args = ap.parse_args(argv)
    tasks = tuple(args.tasks.split(","))
    if not set(tasks) <= set(TASKS):
        ap.error(f"--tasks: each of {TASKS}, got {args.tasks!r}")
    liks = tuple(args.likelihoods.split(","))
    done = 0
    if not args.report_only:
        for task, r in jobs(args.per_task):
            if task not in tasks or r < args.first:
                continue
            if all(_finished(task, r, lk, args.max_steps) for lk in liks):
                continue
            if args.chunk is not None and done >= args.chunk:
                break
            run_one(task, r, liks, args.max_steps)
            done += 1
    rows = load()
    if not rows:
        print("no results yet")
        return 0
    summary = report(rows)
    _write(OUT / "summary.json", summary)
    figure(rows, FIGURE)
    print(f"\nwrote {FIGURE.relative_to(ROOT)} and {(OUT / 'summary.json').relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

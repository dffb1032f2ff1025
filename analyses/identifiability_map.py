"""Identifiability of the threshold per condition, from posteriors (issue 4, item 5).

Run:  python analyses/identifiability_map.py [--chunk N] [--realizations 3]
                                             [--likelihood coloured|profiled|eq4]
                                             [--tasks FD,FT] [--max-steps 6000]
                                             [--report-only]

For every cell of the simulation study of Section III.B.2 (task FD/FT x
K_theta 0.25/0.5/0.75/1 x F_n 0/0.1/0.2/0.25/0.3; Table 3 truth,
delta_abs = 0.0075 IPUT, T0 = 81.92 s) and several remnant realizations, it
fits the recording and samples the posterior from the fit (by default with
the prediction-error ``coloured`` likelihood, whose intervals the
calibration study checks; ``--likelihood profiled`` for the same likelihood
with the AR model re-fitted at every parameter vector, ``ar="profiled"``;
``--likelihood eq4`` for the paper's Eq. 4),
then records for delta_abs: the posterior median, the central 90 % interval,
P50 = the posterior probability of |delta_abs - 0.0075| <= 0.5 x 0.0075 (the
paper's +-50 % criterion), and a 50-bin histogram of the draws on [0, 0.1]
(flat or bimodal where the likelihood plateau above max|i| leaves the
threshold unidentified).  The paper's N50% (Figs. 14/15, 100 three-step
estimates) is shown beside the mean P50 where the paper has the cell
(F_n = 0, 0.2, 0.3).

Resumable: one JSON per (cell, realization) in
``analyses/results/identifiability/``; ``--chunk N`` does the next N
unfinished ones, realization 0 of every cell first.  Writes
``docs/figures/identifiability_map.png`` and ``.../summary.json``.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "analyses" / "results" / "identifiability"
FIGURE = ROOT / "docs" / "figures" / "identifiability_map.png"
TASKS = ("FD", "FT")
GAINS = (0.25, 0.5, 0.75, 1.0)
FRACTIONS = (0.0, 0.1, 0.2, 0.25, 0.3)
TRUE = 0.0075
EDGES = np.linspace(0.0, 0.1, 51)


def seed_of(task: str, k: float, fn: float, r: int) -> int:
    return (5_000_000 + 100_000 * TASKS.index(task) + 10_000 * GAINS.index(k)
            + 1_000 * FRACTIONS.index(fn) + r)


def _path(task, k, fn, r, lik) -> Path:
    return OUT / f"{task}_k{k:g}_fn{fn:g}_r{r:03d}_{lik}.json"


def _write(path: Path, obj) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(obj, indent=1, allow_nan=True))
    tmp.replace(path)


def run_one(task, k, fn, r, lik, max_steps) -> dict:
    from bayespilot.fit.fast import fit_fast
    from bayespilot.model import paper_model
    from bayespilot.sample import ConvergenceWarning, sample
    from bayespilot.simulate import simulate

    t0 = time.perf_counter()
    sim = simulate(task=task, motion_gain=k, remnant_fraction=fn, seed=seed_of(task, k, fn, r))
    rec = sim.recording
    # the prediction-error fit for the coloured likelihood (its AR model comes with it)
    coloured = lik in ("coloured", "profiled", "profiled8")
    fit = fit_fast(rec, seed=r, n_starts=4, **({"noise": "ar", "discard": 2.0} if coloured else {}))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        post = sample(rec, paper_model(oversample=8 if lik == "profiled8" else 1),
                      likelihood="coloured" if coloured else lik,
                      ar="profiled" if lik.startswith("profiled") else "fixed",
                      init=fit, seed=r, max_steps=max_steps, progress=False)
    d = post.draws("delta_abs")
    i = sim.channels["vestibular"]["pre"]
    res = {"task": task, "K_theta": k, "F_n": fn, "realization": r, "likelihood": lik,
           "seed": seed_of(task, k, fn, r), "true_delta_abs": TRUE,
           "median": float(np.median(d)), "q05": float(np.quantile(d, 0.05)),
           "q95": float(np.quantile(d, 0.95)), "mean": float(d.mean()),
           "p50": float(np.mean(np.abs(d - TRUE) <= 0.5 * TRUE)),
           "histogram": np.histogram(d, EDGES)[0].tolist(), "fit_delta_abs": fit.params["delta_abs"],
           "max_abs_i": float(np.abs(i).max()), "converged": post.converged,
           "tau_max": float(max(post.tau.values())), "n_steps": post.settings["n_steps"],
           "seconds": time.perf_counter() - t0}
    _write(_path(task, k, fn, r, lik), res)
    print(f"  {task} K={k:g} F_n={fn:g} r{r}: median {res['median']:.4f} "
          f"[{res['q05']:.4f}, {res['q95']:.4f}] P50 {res['p50']:.2f} "
          f"({'conv' if post.converged else 'not conv'}, {res['seconds']:.0f} s)", flush=True)
    return res


def load(lik: str):
    return [json.loads(p.read_text()) for p in sorted(OUT.glob(f"*_r*_{lik}.json"))]


def report(rows) -> dict:
    from bayespilot.presets import FIG14_15

    print(f"\n{'cell':<18} {'n':>2} | {'median(s)':>22} | {'90% intervals':>36} | {'P50':>11} | "
          f"{'mean P50':>8} | paper N50% | conv")
    summary = {}
    for task in TASKS:
        for fn in FRACTIONS:
            for k in GAINS:
                sel = [r for r in rows if r["task"] == task and r["K_theta"] == k and r["F_n"] == fn]
                if not sel:
                    continue
                paper = FIG14_15.get((task, fn, k))
                p50 = float(np.mean([r["p50"] for r in sel]))
                med = " ".join(f"{r['median']:.4f}" for r in sel)
                ivs = " ".join(f"[{r['q05']:.4f},{r['q95']:.4f}]" for r in sel)
                ps = " ".join(f"{r['p50']:.2f}" for r in sel)
                conv = sum(r["converged"] for r in sel)
                print(f"{task} K={k:<4g} F_n={fn:<4g} {len(sel):>2} | {med:>22} | {ivs:>36} | "
                      f"{ps:>11} | {p50:8.2f} | {'' if paper is None else paper[2]:>10} | "
                      f"{conv}/{len(sel)}")
                summary[f"{task}_k{k:g}_fn{fn:g}"] = {
                    "n": len(sel), "mean_p50": p50, "medians": [r["median"] for r in sel],
                    "q05": [r["q05"] for r in sel], "q95": [r["q95"] for r in sel],
                    "p50": [r["p50"] for r in sel], "paper_N50": None if paper is None else paper[2],
                    "converged": conv}
    return summary


#: The likelihoods as the figure's title names them ("Eq. (4) likelihood" as the package's
#: figures do).
LIKELIHOOD_NAMES = {"eq4": "Eq. (4) likelihood", "coloured": "coloured likelihood",
                    "profiled": "coloured likelihood, AR profiled",
                    "profiled8": "coloured likelihood, AR profiled, motion 8x"}


def figure(rows, path: Path, lik: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from bayespilot._figstyle import save_figure
    from bayespilot._labels import label, symbol
    from bayespilot.presets import FIG14_15

    d_abs, k_theta, f_n = symbol("delta_abs"), symbol("K_theta"), symbol("F_n")
    fig, axes = plt.subplots(3, 2, figsize=(7.0, 9.0), sharex=True, sharey="row",
                             layout="constrained", gridspec_kw={"height_ratios": [1.3, 1.3, 1]})
    width = 0.8 / len(FRACTIONS)
    missing = False
    colors = plt.cm.viridis(np.linspace(0, 0.9, len(FRACTIONS)))
    for col, task in enumerate(TASKS):
        a, h, b = axes[0, col], axes[1, col], axes[2, col]
        for jf, fn in enumerate(FRACTIONS):
            for ik, k in enumerate(GAINS):
                sel = [r for r in rows if r["task"] == task and r["K_theta"] == k and r["F_n"] == fn]
                x0 = ik + (jf - (len(FRACTIONS) - 1) / 2) * width
                for m, r in enumerate(sel):
                    x = x0 + (m - (len(sel) - 1) / 2) * width / max(len(sel), 1) * 0.8
                    a.plot([x, x], [r["q05"], r["q95"]], color=colors[jf], lw=1.1)
                    a.plot(x, r["median"], "o", color=colors[jf], ms=2.5)
                # the pooled histogram of the draws, as a column of shades
                if sel:
                    hist = np.sum([r["histogram"] for r in sel], axis=0).astype(float)
                    hist /= hist.max() if hist.max() > 0 else 1
                    h.imshow(hist[:, None], extent=(x0 - width / 2, x0 + width / 2, 0, 0.1),
                             origin="lower", aspect="auto", cmap="Blues", vmin=0, vmax=1)
                    b.bar(x0, np.mean([r["p50"] for r in sel]), width=width * 0.9,
                          color=colors[jf])
                else:  # a cell not run, apart from a probability of 0
                    b.plot(x0, 0.03, "x", color="0.5", ms=4)
                    missing = True
                paper = FIG14_15.get((task, fn, k))
                if paper is not None:
                    b.plot(x0, paper[2] / 100, "s", mfc="none", mec="k", ms=5)
        for ax in (a, h):
            # the package's convention (plot_threshold_histograms): the true value a dashed
            # black line, its +-50 % a green band
            ax.axhspan(0.5 * TRUE, 1.5 * TRUE, color="C2", alpha=0.25, lw=0)
            ax.axhline(TRUE, color="k", lw=0.9, ls="--")
            ax.set_ylim(0, 0.1)
            ax.set_xlim(-0.5, len(GAINS) - 0.5)
        a.set_title(f"task {task}: posterior median, 90 % interval", fontsize="medium")
        h.set_title(f"task {task}: draws pooled over realizations", fontsize="medium")
        b.set_title(f"task {task}: P({d_abs} within true $\\pm$50 %)", fontsize="medium")
        b.set_ylim(0, 1.05)
        b.set_xticks(range(len(GAINS)), [f"{k_theta} = {k:g}" for k in GAINS],
                     fontsize="small")
        b.grid(True, axis="y", lw=0.3, alpha=0.6)
    axes[0, 0].set_ylabel(label("delta_abs", "IPUT"))
    axes[1, 0].set_ylabel(label("delta_abs", "IPUT") + "\n(darker: more draws)")
    axes[2, 0].set_ylabel("posterior probability")
    # one legend below the panels, off the bars and intervals
    handles = [Patch(color=c, label=f"{f_n} = {fn:g}") for c, fn in zip(colors, FRACTIONS)]
    handles += [Patch(color="C2", alpha=0.25, lw=0, label=r"true $\pm$50 %"),
                Line2D([], [], color="k", ls="--", lw=0.9,
                       label=f"true {d_abs} = {TRUE:g} IPUT"),
                Line2D([], [], ls="none", marker="s", mfc="none", mec="k", ms=5,
                       label="paper $N_{50\\%}$ / 100 (Figs. 14/15)")]
    if missing:
        handles.append(Line2D([], [], ls="none", marker="x", color="0.5", ms=4,
                              label="cell not run"))
    fig.legend(handles=handles, loc="outside lower center",
               ncol=4 if len(handles) % 4 == 0 else 3, fontsize="small", frameon=False)
    n = len(rows)
    fig.suptitle(f"Identifiability of the threshold from posteriors\n({LIKELIHOOD_NAMES[lik]}, "
                 f"{n} recordings; colour: remnant fraction {f_n})", fontsize="medium")
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realizations", type=int, default=3)
    ap.add_argument("--chunk", type=int, default=None)
    ap.add_argument("--likelihood", default="coloured",
                    choices=("eq4", "coloured", "profiled", "profiled8"),
                    help="coloured: AR noise model fixed at the fit; profiled: re-fitted at "
                         "every parameter vector (sample(..., ar='profiled')); profiled8: that "
                         "with the motion channel at 8 times the rate (paper_model(oversample=8))")
    ap.add_argument("--tasks", default=",".join(TASKS),
                    help="comma-separated tasks to run (default both; one process per task "
                         "uses both cores)")
    ap.add_argument("--max-steps", type=int, default=6000)
    ap.add_argument("--report-only", action="store_true")
    args = ap.parse_args(argv)
    tasks = tuple(t.strip() for t in args.tasks.split(",") if t.strip())
    if not tasks or any(t not in TASKS for t in tasks):
        ap.error(f"--tasks must name tasks among {', '.join(TASKS)}, got {args.tasks!r}")
    done = 0
    if not args.report_only:
        for r in range(args.realizations):
            for k in (1.0, 0.25, 0.75, 0.5):  # most informative contrasts first
                for task in tasks:
                    for fn in FRACTIONS:
                        if _path(task, k, fn, r, args.likelihood).exists():
                            continue
                        if args.chunk is not None and done >= args.chunk:
                            break
                        run_one(task, k, fn, r, args.likelihood, args.max_steps)
                        done += 1
    rows = load(args.likelihood)
    if not rows:
        print("no results yet")
        return 0
    summary = report(rows)
    _write(OUT / f"summary_{args.likelihood}.json", summary)
    figure_path = FIGURE if args.likelihood == "coloured" else \
        FIGURE.with_name(f"identifiability_map_{args.likelihood}.png")
    figure(rows, figure_path, args.likelihood)
    print(f"\nwrote {figure_path.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Fig. 11 of Pool et al. (2012) on simulated data: final -ln L with and without threshold.

Run:  python analyses/fig11_neg_log_lik.py [--method paper|fast] [--remnant-fraction 0.2]

Reads the campaign's fits (``analyses/results/replication`` for the paper's
method, ``analyses/results/replication_fast`` for the fast one; run
``replicate_paper.py`` / ``fast_vs_faithful.py --run N`` first).  Every
recording there is fitted with and without threshold, so for each cell
(task x K_theta) at the chosen F_n the script prints

- the mean final -ln L with and without threshold beside the paper's Fig. 11
  (the paper's are measured data of 40 runs per model and cell, so only the
  pattern compares, not the level);
- the paper's test: an unpaired two-sample t-test of the two sets of -ln L
  (scipy.stats.ttest_ind, t with n1 + n2 - 2 degrees of freedom, the paper's
  t(78));
- the paired comparison the design allows (same recording, two models):
  the mean difference, a paired t-test (scipy.stats.ttest_rel) and the
  Wilcoxon signed-rank test, and how often the threshold fit is worse than the
  no-threshold fit (impossible at the optimum: the threshold model contains
  the other one).

The unpaired test cannot see a difference of a few units of -ln L against a
spread of hundreds between realizations; the paired one can.  The figure
``docs/figures/fig11_neg_log_lik_<method>.png`` (``..._paper.png`` by default)
shows the per-recording differences.
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy import stats

from bayespilot import presets
from bayespilot.campaign import load_results

HERE = Path(__file__).resolve().parent
FIGURES = HERE.parent / "docs" / "figures"
TOL = 0.01
#: -ln L as the package's fit figures write it (bayespilot.fit.figures).
NLL = r"$-\ln L$"


def pairs(results: list[dict], remnant_fraction: float) -> dict[tuple[str, float], np.ndarray]:
    """(task, K_theta) -> array (n, 2) of final -ln L [with, without] per recording."""
    by = defaultdict(dict)
    for r in results:
        if abs(r["remnant_fraction"] - remnant_fraction) > 1e-9:
            continue
        by[r["task"], r["motion_gain"], r["realization"]][bool(r["threshold"])] = \
            r["fit"]["neg_log_lik"]
    out = defaultdict(list)
    for (task, kt, _), d in sorted(by.items()):
        if len(d) == 2:
            out[task, kt].append((d[True], d[False]))
    return {k: np.array(v) for k, v in out.items()}


def plot_differences(cells: dict[tuple[str, float], np.ndarray], remnant_fraction: float,
                     method: str) -> Path:
    """Draw the per-recording differences -ln L with threshold minus without (``cells`` as
    :func:`pairs` returns them) per task and K_theta, in the paper's notation
    (:mod:`bayespilot._labels`), 7 in wide; write ``fig11_neg_log_lik_<method>.png`` with
    :func:`bayespilot._figstyle.save_figure` and return its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FixedLocator, FuncFormatter

    from bayespilot._figstyle import save_figure
    from bayespilot._labels import symbol

    fig, axes = plt.subplots(1, 2, figsize=(7.0, 3.0), sharey=True, layout="constrained")
    ticks = [-1000, -100, -10, -1, 0, 1, 10, 100, 1000]
    for ax, task in zip(axes, ("FD", "FT")):
        for j, kt in enumerate(presets.MOTION_GAINS):
            if (task, kt) in cells:
                d = cells[task, kt][:, 0] - cells[task, kt][:, 1]
                x = j + np.random.default_rng(j).uniform(-0.15, 0.15, d.size)
                ax.plot(x, d, "o", ms=3, alpha=0.7)
        ax.axhline(0, color="k", lw=0.8)
        ax.set_xticks(range(len(presets.MOTION_GAINS)), [f"{k:g}" for k in presets.MOTION_GAINS])
        ax.set_xlabel(symbol("K_theta"))
        ax.set_title(task, fontsize="medium")
        # logarithmic beyond +-1, linear within (the suptitle says so); ticks as plain numbers
        ax.set_yscale("symlog", linthresh=1.0)
        ax.yaxis.set_major_locator(FixedLocator(ticks))
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}".replace("-", "\u2212")))
    axes[0].set_ylabel(r"$-\ln L_\mathrm{thr} - (-\ln L_\mathrm{none})$")
    fig.suptitle(f"Per recording: {NLL} with threshold (thr) minus without (none), "
                 f"{symbol('F_n')} = {remnant_fraction:g}, {method} method\n"
                 "(above 0: the threshold fit ended worse; axis logarithmic beyond "
                 "\u00b11, linear within)", fontsize="medium")
    FIGURES.mkdir(parents=True, exist_ok=True)
    out = FIGURES / f"fig11_neg_log_lik_{method}.png"
    save_figure(fig, out)
    plt.close(fig)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--method", choices=("paper", "fast"), default="paper")
    ap.add_argument("--remnant-fraction", type=float, default=0.2)
    ap.add_argument("--results", type=Path, default=None)
    args = ap.parse_args(argv)
    folder = args.results or HERE / "results" / (
        "replication" if args.method == "paper" else "replication_fast")
    if not folder.is_dir():
        print(f"{folder}: no results yet (run analyses/replicate_paper.py first)")
        return 1
    cells = pairs(load_results(folder), args.remnant_fraction)
    if not cells:
        print(f"no recording at F_n = {args.remnant_fraction} has both fits yet")
        return 0
    print(f"Final -ln L with and without threshold, {args.method} method, F_n = "
          f"{args.remnant_fraction} (simulated; the paper's values are measured data)\n")
    print(f"{'cell':<9} {'n':>3} {'with':>10} {'without':>10} {'paper w':>9} {'paper w/o':>9} "
          f"{'t':>6} {'p':>5} {'paper t, p':>11} {'mean diff':>9} {'paired p':>9} "
          f"{'Wilcoxon p':>10} {'worse':>6}")
    order = [(t, k) for k in presets.MOTION_GAINS for t in ("FD", "FT")]
    for cell in order:
        if cell not in cells:
            continue
        a = cells[cell]
        n = len(a)
        diff = a[:, 0] - a[:, 1]
        t, p = stats.ttest_ind(a[:, 0], a[:, 1]) if n > 1 else (np.nan, np.nan)
        _, pp = stats.ttest_rel(a[:, 0], a[:, 1]) if n > 1 else (np.nan, np.nan)
        pw = stats.wilcoxon(diff).pvalue if n > 5 and np.any(diff != 0) else np.nan
        worse = int(np.sum(diff > TOL))
        pw_, pwo, pt, pp_ = presets.FIG11[cell]
        print(f"{cell[0]} {cell[1]:<6} {n:>3} {a[:, 0].mean():>10.1f} {a[:, 1].mean():>10.1f} "
              f"{pw_:>9.0f} {pwo:>9.0f} {abs(t):>6.3f} {p:>5.2f} {f'{pt}, {pp_}':>11} "
              f"{diff.mean():>9.2f} {pp:>9.2g} {pw:>10.2g} {worse:>3}/{n}")
    print("\n'worse': recordings on which the threshold fit ended with a higher -ln L than the "
          f"fit without threshold (by > {TOL}); at the optimum this cannot happen.")

    out = plot_differences(cells, args.remnant_fraction, args.method)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

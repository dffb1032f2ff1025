"""Faithfulness to Pool et al. (2012): our numbers beside the paper's.

Run:  python analyses/faithfulness.py [--quick] [--out analyses/results] [--figures docs/figures]
      python analyses/faithfulness.py --figure-only   # Fig. 13 redrawn from the stored part D

Parts (each prints a table beside the paper's and writes its numbers to
``analyses/results/faithfulness.json``):

A. forcing scale: which amplitude scale of Table 2 the simulation study ran at,
   from the paper's own evidence (Table 5 fractions, Table 4 gains, std and
   peaks of i);
B. Table 4: the remnant gain K_n our calibration gives for each F_n, task and
   K_theta, under the white-noise convention that reproduces the paper;
C. Table 5: P(|i| > 0.0075) over 100 realizations at F_n = 0.25, mean, spread
   and error of the mean;
D. Fig. 13: -ln L versus delta_abs with the other parameters at their true
   values, for both treatments of the initial conditions;
E. the model response at the true parameters against the simulator's u - n;
F. the sign of the motion channel.

``--quick`` uses fewer realizations (for a smoke run); the committed results
and docs/faithfulness.md come from the full run.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

from bayespilot import presets
from bayespilot._files import VERSION_KEY, dumps
from bayespilot.likelihood import Likelihood
from bayespilot.model import paper_model
from bayespilot.simulate import simulate

CELLS = [(task, k) for task in ("FD", "FT") for k in presets.MOTION_GAINS]
SCALES = (0.15, 0.2, 0.25, 0.3)
THRESH = 0.0075


def _nan_for_null(x):
    """The stored results with NaN again where :func:`bayespilot._files.dumps` wrote null
    (NaN is not JSON; this script stores no None of its own)."""
    if isinstance(x, dict):
        return {k: _nan_for_null(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_nan_for_null(v) for v in x]
    return math.nan if x is None else x


def _scale_point(args):
    task, kth, scale, seed = args
    sim = simulate(task=task, motion_gain=kth, remnant_fraction=0.25, seed=seed, forcing_scale=scale)
    i = sim.channels["vestibular"]["pre"]
    return (task, kth, scale, seed, float(np.mean(np.abs(i) > THRESH)), float(i.std()),
            float(np.abs(i).max()), sim.remnant_gain)


def part_a(pool, seeds):
    """Find the forcing scale: interpolate, per cell, the scale that matches Table 5 and Table 4."""
    jobs = [(t, k, s, sd) for (t, k) in CELLS for s in SCALES for sd in seeds]
    rows = list(pool.map(_scale_point, jobs))
    res = {}
    print("\nA. Forcing-function scale (F_n = 0.25): per cell, the Table 2 amplitude factor that")
    print("   reproduces the paper's P(|i|>0.0075) (Table 5) and K_n (Table 4)")
    print(f"{'cell':>9} | " + " ".join(f"P@{s:<5g}" for s in SCALES) + " | paper P | scale(P) |"
          + " ".join(f"Kn@{s:<5g}" for s in SCALES) + " | paper Kn | scale(Kn)")
    est_p, est_k = [], []
    for (t, k) in CELLS:
        P = np.array([np.mean([r[4] for r in rows if r[:3] == (t, k, s)]) for s in SCALES])
        K = np.array([np.mean([r[7] for r in rows if r[:3] == (t, k, s)]) for s in SCALES])
        S = np.array([np.mean([r[5] for r in rows if r[:3] == (t, k, s)]) for s in SCALES])
        M = np.array([np.mean([r[6] for r in rows if r[:3] == (t, k, s)]) for s in SCALES])
        p_ref = presets.TABLE5[(t, k)][0]
        k_ref = presets.TABLE4_K_N[(t, 0.25)][presets.MOTION_GAINS.index(k)]
        # both P and K_n increase monotonically with the scale: invert by interpolation
        s_p = float(np.interp(p_ref, P, SCALES, left=np.nan, right=np.nan))
        s_k = float(np.interp(k_ref, K, SCALES, left=np.nan, right=np.nan))
        est_p.append(s_p)
        est_k.append(s_k)
        res[f"{t} {k:g}"] = {"P": P.tolist(), "K_n": K.tolist(), "std_i": S.tolist(),
                             "max_i": M.tolist(), "scale_from_P": s_p, "scale_from_K_n": s_k}
        print(f"{t} {k:>4g} | " + " ".join(f"{x:7.3f}" for x in P) + f" | {p_ref:7.2f} | {s_p:8.3f} |"
              + " ".join(f"{x:8.3f}" for x in K) + f" | {k_ref:8.3f} | {s_k:8.3f}")
    res["scales"] = list(SCALES)
    res["median_scale_from_P"] = float(np.nanmedian(est_p))
    res["median_scale_from_K_n"] = float(np.nanmedian(est_k))
    print(f"   median scale from Table 5: {res['median_scale_from_P']:.3f}; "
          f"from Table 4: {res['median_scale_from_K_n']:.3f}; preset "
          f"FORCING_SCALE['paper_simulation'] = {presets.FORCING_SCALE['paper_simulation']}")
    return res


def _kn_point(args):
    task, kth, fn, seed = args
    try:
        kn = simulate(task=task, motion_gain=kth, remnant_fraction=fn, seed=seed).remnant_gain
    except ValueError:  # this closed loop cannot reach F_n (it saturates below it)
        kn = float("nan")
    return (task, kth, fn, seed, kn)


def part_b(pool, seeds):
    jobs = [(t, k, fn, sd) for (t, k) in CELLS for fn in (0.1, 0.2, 0.25, 0.3) for sd in seeds]
    rows = list(pool.map(_kn_point, jobs))
    res = {}
    print("\nB. Table 4: remnant gain K_n (ours: mean over realizations, each calibrated; white noise")
    print("   of unit variance per sample at 100 Hz, i.e. two-sided PSD 0.01 rad^2 s)")
    print(f"{'F_n':>5} | " + " | ".join(f"{t} {k:<4g} ours/paper" for (t, k) in CELLS))
    for fn in (0.1, 0.2, 0.25, 0.3):
        cells = []
        for (t, k) in CELLS:
            vals = np.array([r[4] for r in rows if r[:3] == (t, k, fn)])
            ours = float(np.nanmean(vals)) if np.isfinite(vals).any() else float("nan")
            unreached = int(np.sum(~np.isfinite(vals)))
            ref = presets.TABLE4_K_N[(t, fn)][presets.MOTION_GAINS.index(k)]
            res[f"{t} {k:g} {fn:g}"] = {"ours": ours, "paper": ref, "unreachable": unreached,
                                        "n": int(vals.size)}
            mark = f"*{unreached}" if unreached else ""
            cells.append(f"{ours:6.3f}/{ref:5.3f}{mark}")
        print(f"{fn:5.2f} | " + " | ".join(f"{c:>18}" for c in cells))
    ratios = [v["ours"] / v["paper"] for v in res.values() if np.isfinite(v["ours"])]
    res["ratio_median"] = float(np.median(ratios))
    print("   *k: k of the realizations cannot reach this F_n at all (the loop saturates below it)")
    print(f"   median ours/paper = {res['ratio_median']:.3f} (a convention of unit PSD instead "
          f"would give 1/10 of ours: ratio {res['ratio_median'] / 10:.3f})")
    return res


def _p_point(args):
    task, kth, kn, seed = args
    sim = simulate(task=task, motion_gain=kth, remnant_gain=kn, seed=seed)
    i = sim.channels["vestibular"]["pre"]
    return task, kth, seed, float(np.mean(np.abs(i) > THRESH)), sim.remnant_fraction


def part_c(pool, kn_table, n_real):
    jobs = [(t, k, kn_table[f"{t} {k:g} 0.25"]["ours"], 1000 + s)
            for (t, k) in CELLS for s in range(n_real)]
    rows = list(pool.map(_p_point, jobs))
    res = {}
    print(f"\nC. Table 5: P(|i| > 0.0075) at F_n = 0.25 over {n_real} realizations (our K_n from B)")
    print(f"{'cell':>9} | {'ours mean':>9} {'spread':>8} {'err mean':>9} | {'paper':>6} {'+-':>7} | diff")
    for (t, k) in CELLS:
        P = np.array([r[3] for r in rows if r[:2] == (t, k)])
        F = np.array([r[4] for r in rows if r[:2] == (t, k)])
        ref, pm = presets.TABLE5[(t, k)]
        res[f"{t} {k:g}"] = {"mean": float(P.mean()), "std": float(P.std(ddof=1)),
                             "sem": float(P.std(ddof=1) / np.sqrt(P.size)), "paper": ref,
                             "paper_pm": pm, "mean_F_n": float(F.mean())}
        r = res[f"{t} {k:g}"]
        flag = "  > 0.02" if abs(r["mean"] - ref) > 0.02 else ""
        print(f"{t} {k:>4g} | {r['mean']:9.3f} {r['std']:8.4f} {r['sem']:9.5f} | {ref:6.2f} {pm:7.4f}"
              f" | {r['mean'] - ref:+.3f}{flag}")
    return res


def _fig13_point(args):
    kth, fn, seed, initial = args
    model = paper_model()
    kn = 0.0
    sim = simulate(model, task="FD", motion_gain=kth, remnant_fraction=fn or None, seed=seed)
    lik = Likelihood(model, sim.recording, initial=initial)
    grid = np.linspace(0.0, 0.1, 201)
    x = np.tile(model.free_vector(sim.params), (grid.size, 1))
    x[:, model.parameter_names.index("delta_abs")] = grid
    nll = lik.batch(x)
    i = sim.channels["vestibular"]["pre"]
    return kth, fn, seed, initial, nll.tolist(), float(np.abs(i).max()), kn


def part_d(pool, n_real, figdir):
    grid = np.linspace(0.0, 0.1, 201)
    jobs = [(k, fn, s, ini) for k in (0.25, 1.0) for fn in (0.0, 0.1, 0.25) for s in range(n_real)
            for ini in ("periodic", "rest")]
    rows = list(pool.map(_fig13_point, jobs))
    res = {"grid_step": float(grid[1] - grid[0])}
    print("\nD. Fig. 13: argmin of -ln L over delta_abs (true 0.0075; grid step 0.0005), FD")
    print(f"{'K_theta':>7} {'F_n':>5} | {'periodic: argmin mean (range)':>32} | {'rest: argmin mean (range)':>30}"
          " | plateau above max|i| (periodic)")
    for k in (0.25, 1.0):
        for fn in (0.0, 0.1, 0.25):
            line = f"{k:7g} {fn:5g} |"
            entry = {}
            for ini in ("periodic", "rest"):
                sel = [r for r in rows if r[0] == k and r[1] == fn and r[3] == ini]
                mins = np.array([grid[int(np.argmin(r[4]))] for r in sel])
                entry[ini] = {"argmin": mins.tolist(), "curves": [r[4] for r in sel]}
                line += f" {mins.mean():.4f} ({mins.min():.4f}-{mins.max():.4f})".rjust(33) + " |"
            sel = [r for r in rows if r[0] == k and r[1] == fn and r[3] == "periodic"]
            maxi = float(np.mean([r[5] for r in sel]))
            c = np.array(sel[0][4])
            above = grid > maxi
            flat = float(np.ptp(c[above])) if above.any() else float("nan")
            entry["max_abs_i"] = maxi
            entry["ptp_above_max_i"] = flat
            entry["rise_to_plateau"] = float(c[-1] - c.min())
            line += f" max|i|={maxi:.3f}, spread above it={flat:.2f} (rise {c[-1] - c.min():.1f})"
            res[f"{k:g} {fn:g}"] = entry
            print(line)
    _plot_fig13(res, grid, figdir)
    return res


#: The figure's name (docs/faithfulness.md embeds it).
FIG13 = "fig13_likelihood_vs_delta_abs.png"
#: -ln L as the package's fit figures write it (bayespilot.fit.figures).
NLL = r"$-\ln L$"


def _plot_fig13(res, grid, figdir):
    """Fig. 13 from part D's curves (``res`` = the stored ``D_fig13``): -ln L over delta_abs
    per realization, its minimum, the truth; 7 x 4.5 in (a page's width, text printed at its
    size), the paper's notation (:mod:`bayespilot._labels`), saved by
    :func:`bayespilot._figstyle.save_figure`."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from bayespilot._figstyle import save_figure
    from bayespilot._labels import label, symbol

    grid = np.asarray(grid)
    fig, axes = plt.subplots(2, 3, figsize=(7.0, 4.5), sharex=True, layout="constrained")
    n = 0
    for r, k in enumerate((0.25, 1.0)):
        for c, fn in enumerate((0.0, 0.1, 0.25)):
            ax = axes[r, c]
            curves = res[f"{k:g} {fn:g}"]["periodic"]["curves"]
            n = max(n, len(curves))
            for curve in curves:
                curve = np.array(curve)
                ax.plot(grid, curve, lw=0.8, color="0.3")
                j = int(np.argmin(curve))
                ax.plot(grid[j], curve[j], "o", mfc="white", mec="k", ms=4)
            ax.axvline(THRESH, ls="--", color="k", lw=0.8)
            ax.set_title(f"{symbol('K_theta')} = {k:g}, {symbol('F_n')} = {fn:g}",
                         fontsize="medium")
            ax.tick_params(labelsize="small")
            ax.yaxis.get_offset_text().set_fontsize("small")
            if r == 1:
                ax.set_xlabel(label("delta_abs", "IPUT"))
            if c == 0:
                ax.set_ylabel(NLL)
    handles = [Line2D([], [], color="0.3", lw=0.8,
                      label=f"{NLL}, one realization ({n} per panel)"),
               Line2D([], [], ls="none", marker="o", mfc="white", mec="k", ms=4,
                      label="its minimum"),
               Line2D([], [], color="k", ls="--", lw=0.8,
                      label=f"true {symbol('delta_abs')} = {THRESH:g} IPUT")]
    fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize="small",
               frameon=False)
    fig.suptitle(f"Fig. 13 (FD): {NLL} versus {symbol('delta_abs')}, the other parameters "
                 "at their true values", fontsize="medium")
    save_figure(fig, Path(figdir) / FIG13)
    plt.close(fig)


def _err_point(args):
    task, kth, fn, seed, oversample = args
    model = paper_model()
    sim = simulate(model, task=task, motion_gain=kth, remnant_fraction=fn or None, seed=seed,
                   oversample=oversample)
    rec = sim.recording
    out = {}
    for ini in ("periodic", "rest"):
        uh = Likelihood(model, rec, initial=ini).response(sim.params)
        err = uh - (rec.u - sim.remnant)
        out[ini] = (float(np.sqrt(np.mean(err**2)) / np.std(rec.u - sim.remnant)),
                    float(np.sqrt(np.mean(err[500:] ** 2)) / np.std(rec.u - sim.remnant)))
    return task, kth, fn, oversample, out


def part_e(pool):
    jobs = [(t, k, fn, 7, ov) for (t, k) in CELLS for fn in (0.0, 0.2) for ov in (10,)]
    jobs += [("FD", 1.0, 0.0, 7, ov) for ov in (5, 20, 40)]
    rows = list(pool.map(_err_point, jobs))
    res = {}
    print("\nE. Model response at the true parameters vs the simulator's u - n:")
    print("   rms(u_hat - (u - n)) / std(u - n); 'after 5 s' leaves out the first 500 samples")
    print(f"{'cell':>9} {'F_n':>4} {'oversample':>10} | {'periodic':>9} {'after 5 s':>9} | {'rest':>9} {'after 5 s':>9}")
    for t, k, fn, ov, out in rows:
        res[f"{t} {k:g} {fn:g} {ov}"] = out
        print(f"{t} {k:>4g} {fn:4g} {ov:10d} | {out['periodic'][0]:9.2e} {out['periodic'][1]:9.2e} | "
              f"{out['rest'][0]:9.2e} {out['rest'][1]:9.2e}")
    return res


def part_f():
    """The motion channel's sign: with + the closed loop diverges for the Table 3 parameters."""
    model = paper_model()
    plus = replace(model, channels=(model.channels[0], replace(model.channels[1], sign=1.0)))
    res = {}
    print("\nF. Sign of the motion channel (Table 3 parameters, F_n = 0):")
    for name, m in (("minus (ours)", model), ("plus", plus)):
        for t in ("FD", "FT"):
            try:
                sim = simulate(m, task=t, motion_gain=1.0, seed=0)
                out = f"stable, std(u) = {sim.recording.u.std():.4f} rad"
                res[f"{name} {t}"] = True
            except RuntimeError:
                out = "diverges"
                res[f"{name} {t}"] = False
            print(f"   {name:>13} {t}: {out}")
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="few realizations (smoke run)")
    ap.add_argument("--out", default="analyses/results", help="directory for faithfulness.json")
    ap.add_argument("--figures", default="docs/figures", help="directory for figures")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--figure-only", action="store_true",
                    help="only redraw Fig. 13 from the stored part D (faithfulness.json is "
                         "read, not written; nothing is simulated)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    figdir = Path(args.figures)
    if args.figure_only:
        path = out / "faithfulness.json"
        if not path.exists() or "D_fig13" not in json.loads(path.read_text()):
            print(f"{path}: no part D (Fig. 13) stored; run the script without --figure-only")
            return 1
        stored = _nan_for_null(json.loads(path.read_text()))["D_fig13"]
        figdir.mkdir(parents=True, exist_ok=True)
        _plot_fig13(stored, np.linspace(0.0, 0.1, 201), figdir)  # part D's grid
        print(f"wrote {figdir / FIG13} from {path}")
        return 0
    out.mkdir(parents=True, exist_ok=True)
    figdir.mkdir(parents=True, exist_ok=True)
    seeds_a = range(2) if args.quick else range(3)
    seeds_b = range(2) if args.quick else range(6)
    n_c = 10 if args.quick else 100
    n_d = 3 if args.quick else 10
    t0 = time.time()
    path = out / "faithfulness.json"
    # Resumable: each part is saved as it finishes and skipped on the next run
    # (delete the file, or the part's key, to recompute).
    results = _nan_for_null(json.loads(path.read_text())) if path.exists() else {}
    results.pop(VERSION_KEY, None)  # each write names the release that wrote it
    if results.get("quick") not in (None, args.quick):
        results = {}
    results["quick"] = args.quick

    def part(key, fn):
        if key not in results:
            results[key] = fn()
            path.write_text(dumps(results))
        else:
            print(f"\n({key}: loaded from {path})")

    with ProcessPoolExecutor(args.workers) as pool:
        part("A_forcing_scale", lambda: part_a(pool, seeds_a))
        part("B_table4", lambda: part_b(pool, seeds_b))
        part("C_table5", lambda: part_c(pool, results["B_table4"], n_c))
        part("D_fig13", lambda: part_d(pool, n_d, figdir))
        part("E_model_vs_simulator", lambda: part_e(pool))
    part("F_sign", part_f)
    results["seconds"] = time.time() - t0
    path.write_text(dumps(results))
    print(f"\nwrote {out / 'faithfulness.json'} and {figdir / FIG13} "
          f"in {results['seconds']:.0f} s")


if __name__ == "__main__":
    raise SystemExit(main())

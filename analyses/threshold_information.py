"""Where the information on the threshold comes from, and why its intervals over-cover (issue 4).

Run:  python analyses/threshold_information.py [--recordings 5] [--spectra 20] [--scatter 40]
      python analyses/threshold_information.py --exact 200 [--open-loop 1000] --exact-only
                                               [--oversample 8]
      python analyses/threshold_information.py --kinks 6 [--oversample 10]
      python analyses/threshold_information.py --figure-only    # check 3 and its figure

The calibration study (``analyses/calibration.py``) finds the 50 % and 90 %
intervals of delta_abs too wide at K_theta = 1, F_n = 0.2.  This script
prints the three measurements that ``docs/posteriors.md`` reports about it,
from the calibration's own recordings (same seeds) and result files:

1. Shape and width of the posteriors (from the calibration files, AR fixed
   and profiled): the ratio of the upper to the lower half of the 90 %
   interval (1 = symmetric), the posterior sd estimated from the
   interquartile range, and the sd of the posterior medians across the
   recordings, i.e. how much the estimate actually varies.
2. The Gauss-Newton standard error of delta_abs at the prediction-error fit
   of the first ``--recordings`` FD recordings, for the AR order that BIC
   chose and for orders 20, 30 and 40: whether a richer noise model changes
   the likelihood's curvature.
3. The frequency-domain Fisher information of one FD recording: the Welch
   spectrum of d u_hat / d theta over the Welch spectrum of the residual at
   the true parameters, summed per frequency band, for delta_abs and K_m,
   with the residual's spectrum; the figure is
   ``docs/figures/threshold_information.png``.
4. Two checks on the residual at the true parameters, over the first
   ``--spectra`` FD recordings: whether its high-frequency part (where the
   threshold's information lies) is a deterministic discretisation error
   common to all recordings (mean correlation of band-passed residuals over
   the pairs of recordings, which a common component makes positive) rather
   than remnant, and whether the AR model of one
   recording's residual over- or underestimates the residual's spectrum per
   band (AR spectrum over the Welch spectrum averaged over the recordings).
   An AR spectrum too high where the information lies would make the
   posterior wider than the estimate varies; too low, narrower.
5. Is -ln L quadratic in delta_abs?  On ``--scatter`` FD recordings, with
   the other seven parameters held at the truth: the scatter of the 1-D
   maximum-likelihood estimates across recordings, beside the Gauss-Newton
   standard error (the width a quadratic -ln L with that slope information
   has, and about the posterior's) and the standard error implied by the
   finite-difference curvature of -ln L at steps from 2.5e-5 to 1.6e-3
   (equal at every step if -ln L is quadratic).  Then the same scatter
   against the Gauss-Newton standard error for the joint fit of all eight
   parameters (the calibration's prediction-error fits).
6. With ``--exact N``: is the over-coverage intrinsic to the dead zone's
   likelihood?  Exact 1-D posteriors of delta_abs (flat prior, -ln L on a
   grid of 5001 points over [0, 0.02], the seven other parameters at the
   truth, the AR model held fixed) and their coverage, in four settings:
   (a) open loop with an exactly specified model: e and theta_ddot_m of one
   closed-loop recording, u = u_hat(truth) + AR noise drawn from the AR
   model of that recording's residual at the truth, and the likelihood
   given that same AR model (``--open-loop`` realizations);
   (b) ``N`` fresh closed-loop recordings (seeds ``EXACT_SEED + r``) as
   simulated, AR model fitted to each one's residual at the truth;
   (c) the same recordings with u replaced by u_hat(truth) + the remnant that
   drove that loop: the closed loop (its inputs carry that remnant) without
   the model error, i.e. the gap between the simulator (continuous, RK4 at
   1 kHz) and the fitted model (Tustin at 100 Hz);
   (d) u = u_hat(truth) + an independent remnant realization: no feedback
   and no model error.
   For each: sd of the 1-D MLEs, mean Gauss-Newton SE, mean posterior sd,
   coverage of the central 50 %/90 % credible and likelihood-ratio
   intervals, and the exponent of -ln L's rise (as in 5).  Then the
   mechanism, on the first 40 recordings: the model error's cross term in
   -ln L, -eps_m' (u_hat(delta) - u_hat(truth)) / s2 (whitened), beside the
   rise that (c) has, at delta = truth +- 0.001.
7. With ``--kinks N``: where in the model that error is made.  The model
   error and its bowl kappa for the package's motion path, for one that
   interpolates the delay before the dead zone, for one run at 10 times
   the rate, and for two with a first-order hold (see :func:`kink_variants`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from calibration import OUT as CAL  # the calibration study's result files and seeds
from calibration import seed_of as calibration_seed

ROOT = Path(__file__).resolve().parents[1]
FIGURE = ROOT / "docs" / "figures" / "threshold_information.png"
TRUE = 0.0075
BANDS = ((0, 1), (1, 3), (3, 6), (6, 10), (10, 20), (20, 35), (35, 50))


def posterior_shape() -> None:
    print("1. delta_abs posteriors of the calibration study (K_theta = 1, F_n = 0.2)")
    print(f"{'likelihood':<10} {'task':<4} {'n':>3} {'median':>8} {'upper/lower':>11} "
          f"{'post. sd':>9} {'sd of medians':>13} {'ratio':>6} {'cover 50/90':>11}")
    for lik in ("coloured", "profiled"):
        for task in ("FD", "FT"):
            rows = [json.loads(p.read_text()) for p in sorted(CAL.glob(f"{task}_r*_{lik}.json"))]
            if not rows:
                continue
            q = np.array([[r["quantiles"]["delta_abs"][k] for k in ("0.05", "0.25", "0.5", "0.75",
                                                                      "0.95")] for r in rows])
            skew = np.median((q[:, 4] - q[:, 2]) / (q[:, 2] - q[:, 0]))
            post_sd = np.mean((q[:, 3] - q[:, 1]) / 2 / 0.6745)
            spread = np.std(q[:, 2], ddof=1)
            c50 = np.mean((q[:, 1] <= TRUE) & (TRUE <= q[:, 3]))
            c90 = np.mean((q[:, 0] <= TRUE) & (TRUE <= q[:, 4]))
            name = "AR fixed" if lik == "coloured" else "AR prof."
            print(f"{name:<10} {task:<4} {len(rows):>3} {np.median(q[:, 2]):8.5f} {skew:11.2f} "
                  f"{post_sd:9.5f} {spread:13.5f} {post_sd / spread:6.2f} {c50:5.2f}/{c90:.2f}")


def curvature(n_rec: int) -> None:
    from bayespilot.likelihood import Likelihood
    from bayespilot.model import paper_model
    from bayespilot.noise import ARNoise
    from bayespilot.simulate import simulate

    model = paper_model()
    names = model.parameter_names
    print(f"\n2. Gauss-Newton standard error of delta_abs at the prediction-error fit, by AR order "
          f"(FD, recordings 0-{n_rec - 1})")
    for r in range(n_rec):
        path = CAL / f"FD_r{r:03d}_fitpem.json"
        if not path.exists():
            print(f"  no {path.name}: run analyses/calibration.py first")
            return
        fit = json.loads(path.read_text())
        rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2,
                       seed=calibration_seed("FD", r)).recording
        p = fit["params"]
        base = Likelihood(model, rec, discard=2.0)
        eps = base.residual(p)[base.used]
        cells = []
        for order in (fit["settings"]["noise"]["order"], 20, 30, 40):
            lik = Likelihood(model, rec, discard=2.0, noise=ARNoise.from_residual(eps, order=order))
            w = lik.fit_residual(p)
            J = lik.fit_jacobian(p)
            cov = np.mean(w**2) * np.linalg.inv(J.T @ J)
            i = names.index("delta_abs")
            cells.append(f"p={order}: {np.sqrt(cov[i, i]):.5f}")
        print(f"  r{r}: " + "  ".join(cells))


def information_spectrum() -> None:
    from scipy import signal

    from bayespilot.likelihood import Likelihood
    from bayespilot.model import paper_model
    from bayespilot.simulate import simulate

    sim = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=calibration_seed("FD", 0))
    sim0 = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.0, seed=calibration_seed("FD", 0))
    model = paper_model()
    lik = Likelihood(model, sim.recording, discard=2.0)
    lik0 = Likelihood(model, sim0.recording, discard=2.0)
    fs = sim.recording.sample_rate_hz
    eps = lik.residual(sim.params)[lik.used]
    eps0 = lik0.residual(sim0.params)[lik0.used]
    _, J = lik.jacobian(sim.params, ["delta_abs", "K_m"])
    f, P = signal.welch(eps, fs=fs, nperseg=1024)
    _, P0 = signal.welch(eps0, fs=fs, nperseg=1024)
    info = {}
    for j, name in enumerate(("delta_abs", "K_m")):
        _, Pj = signal.welch(J[lik.used, j], fs=fs, nperseg=1024)
        info[name] = Pj / P
    low = P[f < 1].mean()
    print("\n3. Frequency-domain Fisher information, FD recording 0 (Welch, 1024-sample segments)")
    head = ("band (Hz)", "residual PSD / PSD < 1 Hz", "no remnant / with",
            "share of delta_abs info", "share of K_m info")
    print(f"{head[0]:<10} {head[1]:>30} {head[2]:>24} {head[3]:>24} {head[4]:>18}")
    for a, b in BANDS:
        s = (f >= a) & (f < b)
        print(f"{a:>3}-{b:<6} {P[s].mean() / low:30.1e} {P0[s].mean() / P[s].mean():24.1e} "
              f"{info['delta_abs'][s].sum() / info['delta_abs'].sum():24.3f} "
              f"{info['K_m'][s].sum() / info['K_m'].sum():18.3f}")

    plot_information(f, P, P0, info)


def plot_information(f, P, P0, info) -> None:
    """The figure of check 3 (``docs/figures/threshold_information.png``): the residual's
    Welch spectrum ``P`` with remnant and ``P0`` without, and the cumulative share of the
    Fisher information ``info[name]`` of delta_abs and K_m, over the frequencies ``f`` (Hz).
    The paper's notation (:mod:`bayespilot._labels`); the second series of each panel
    dashed, so the two read apart in greyscale; saved by
    :func:`bayespilot._figstyle.save_figure`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bayespilot._figstyle import save_figure
    from bayespilot._labels import symbol

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7.0, 6.0), sharex=True, layout="constrained")
    a1.semilogy(f[1:], P[1:], color="C0", ls="-",
                label=f"residual at the truth ({symbol('F_n')} = 0.2)")
    a1.semilogy(f[1:], P0[1:], color="C1", ls="--",
                label="residual without remnant (discretisation)")
    a1.set_ylabel("PSD of the residual of $u$ (rad$^2$/Hz)")
    a1.legend(fontsize="small")
    a1.set_title(f"FD, {symbol('K_theta')} = 1: residual spectrum and where the "
                 "information lies", fontsize="medium")
    for name, ls in (("delta_abs", "-"), ("K_m", "--")):
        cum = np.cumsum(info[name][1:]) / info[name][1:].sum()
        a2.plot(f[1:], cum, ls=ls, label=symbol(name))
    a2.set_xlabel("frequency (Hz)")
    a2.set_ylabel("cumulative share of\nFisher information")
    a2.grid(True, lw=0.3, alpha=0.6)
    a2.legend(fontsize="small")
    FIGURE.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, FIGURE)
    plt.close(fig)
    print(f"\nwrote {FIGURE.relative_to(ROOT)}")


def residual_checks(n_rec: int) -> None:
    from scipy import signal

    from bayespilot.likelihood import Likelihood
    from bayespilot.model import paper_model
    from bayespilot.noise import fit_ar
    from bayespilot.simulate import simulate

    model = paper_model()
    fs = 100.0
    eps = []
    for r in range(n_rec):
        sim = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2,
                       seed=calibration_seed("FD", r))
        lik = Likelihood(model, sim.recording, discard=2.0)
        eps.append(lik.residual(sim.params)[lik.used])
    f, _ = signal.welch(eps[0], fs=fs, nperseg=1024)
    p_mean = np.mean([signal.welch(e, fs=fs, nperseg=1024)[1] for e in eps], axis=0)
    print(f"\n4. The residual at the truth, FD recordings 0-{n_rec - 1}")
    print(f"{'band (Hz)':<10} {'corr between recordings (sd)':>30} "
          + " ".join(f"{'AR(' + str(p) + ')/Welch':>12}" for p in ("BIC", 20, 40)))
    ratios = []
    for order in (None, 20, 40):
        a = fit_ar(eps[0], order=order)
        w = signal.lfilter(np.r_[1.0, -a], [1.0], eps[0])[a.size:]
        _, h = signal.freqz([1.0], np.r_[1.0, -a], worN=f, fs=fs)
        ratios.append(2.0 * w.var() / fs * np.abs(h) ** 2 / p_mean)  # one-sided PSD
    for a, b in BANDS:
        lo, hi = max(a, 0.2), min(b, 49.0)
        sos = signal.butter(4, [lo, hi], btype="band", fs=fs, output="sos")
        x = np.array([signal.sosfiltfilt(sos, e) for e in eps])
        c = np.corrcoef(x)
        pairs = c[np.triu_indices(len(eps), 1)]  # a common component makes these positive
        s = (f >= a) & (f < b)
        print(f"{a:>3}-{b:<6} {pairs.mean():+22.3f} +- {pairs.std(ddof=1):5.3f} "
              + " ".join(f"{np.mean(rr[s]):12.2f}" for rr in ratios))


STEPS = (2.5e-5, 5e-5, 1e-4, 2e-4, 4e-4, 8e-4, 1.6e-3)


def conditional_scatter(n_rec: int) -> None:
    from scipy import optimize

    from bayespilot.likelihood import Likelihood
    from bayespilot.model import paper_model
    from bayespilot.noise import ARNoise
    from bayespilot.simulate import simulate

    model = paper_model()
    names = model.parameter_names
    k = names.index("delta_abs")
    est, gn, curv, joint, jse = [], [], [], [], []
    for r in range(n_rec):
        sim = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2,
                       seed=calibration_seed("FD", r))
        p = dict(sim.params)
        lik0 = Likelihood(model, sim.recording, discard=2.0)
        noise = ARNoise.from_residual(lik0.residual(p)[lik0.used])
        lik = Likelihood(model, sim.recording, discard=2.0, noise=noise)

        def f(d):
            return lik.neg_log_lik({**p, "delta_abs": float(d)})
        grid = np.linspace(0.003, 0.012, 19)  # bracket first: -ln L has kinks in delta_abs
        i = int(np.argmin([f(d) for d in grid]))
        d = optimize.minimize_scalar(f, bounds=(grid[max(i - 1, 0)], grid[min(i + 1, 18)]),
                                     method="bounded", options={"xatol": 1e-8}).x
        at = {**p, "delta_abs": d}
        J = lik.fit_jacobian(at)[:, k]
        gn.append(np.sqrt(np.mean(lik.fit_residual(at) ** 2) / (J @ J)))
        c = np.array([(f(d + h) - 2.0 * f(d) + f(d - h)) / h**2 for h in STEPS])
        curv.append(np.where(c > 0, 1.0 / np.sqrt(np.abs(c)), np.nan))
        est.append(d)
        # the joint fit of all eight: the calibration's prediction-error fit of this recording
        path = CAL / f"FD_r{r:03d}_fitpem.json"
        if path.exists():
            fit = json.loads(path.read_text())
            lik = Likelihood(model, sim.recording, discard=2.0,
                             noise=ARNoise(fit["settings"]["noise"]["a"]))
            w = lik.fit_residual(fit["params"])
            Jf = lik.fit_jacobian(fit["params"])
            joint.append(fit["params"]["delta_abs"])
            jse.append(np.sqrt(np.mean(w**2) * np.linalg.inv(Jf.T @ Jf)[k, k]))
    est, sd = np.array(est), np.std(est, ddof=1)
    curv = np.nanmean(np.array(curv), axis=0)
    print(f"\n5. Scatter of the estimate of delta_abs against its standard errors "
          f"(FD recordings 0-{n_rec - 1})")
    print(f"  alone (the others at the truth): mean {est.mean():.5f} (truth {TRUE}), sd across "
          f"recordings {sd:.5f}; Gauss-Newton SE {np.mean(gn):.5f} (SE/sd {np.mean(gn) / sd:.2f})")
    print("  SE from the curvature of -ln L by finite-difference step (mean over recordings):")
    print("   " + "  ".join(f"{h:.1e}: {c:.5f}" for h, c in zip(STEPS, curv)))
    slope = np.polyfit(np.log(STEPS), np.log(curv), 1)[0]
    print(f"  -ln L rises like |step|^{2.0 - 2.0 * slope:.2f} near its minimum "
          f"(2 would be quadratic)")
    if len(joint) > 2:
        joint = np.array(joint)
        print(f"  jointly (the calibration's prediction-error fits, {len(joint)} recordings): "
              f"mean {joint.mean():.5f}, sd {joint.std(ddof=1):.5f}, mean Gauss-Newton SE "
              f"{np.mean(jse):.5f}, SE/sd {np.mean(jse) / joint.std(ddof=1):.2f}")


EXACT_SEED = 7_000_000  # closed-loop recordings of check 6 (not the calibration's seeds)
GRID = np.linspace(0.0, 0.02, 5001)  # delta_abs; the flat prior is [0, 0.1], no mass beyond 0.02


def _grid_posterior(lik, free0, k: int) -> dict:
    """-ln L over GRID (the others at free0): MLE, exact flat-prior posterior, GN SE."""
    F = np.tile(free0, (GRID.size, 1))
    F[:, k] = GRID
    nll = lik.batch(F)
    i = int(np.argmin(nll))
    post = np.exp(-(nll - nll[i]))
    cdf = np.cumsum(post)
    cdf /= cdf[-1]
    q = np.interp([0.05, 0.25, 0.75, 0.95], cdf, GRID)
    mean = np.sum(post * GRID) / post.sum()
    at = free0.copy()
    at[k] = GRID[i]
    J = lik.fit_jacobian(at, ["delta_abs"])[:, 0]
    # finite-difference curvature of -ln L at the MLE, as in check 5
    S = np.tile(at, (2 * len(STEPS) + 1, 1))
    S[1:, k] += np.r_[STEPS, -np.array(STEPS)]
    v = lik.batch(S)
    c = (v[1:len(STEPS) + 1] + v[len(STEPS) + 1:] - 2.0 * v[0]) / np.array(STEPS) ** 2
    return {"mle": GRID[i], "q": q, "sd": np.sqrt(np.sum(post * (GRID - mean) ** 2) / post.sum()),
            "se": np.sqrt(np.mean(lik.fit_residual(at) ** 2) / (J @ J)),
            "lr": 2.0 * (np.interp(TRUE, GRID, nll) - nll[i]),
            "curv": np.where(c > 0, 1.0 / np.sqrt(np.abs(c)), np.nan)}


def _coverage_row(name: str, rows: list[dict]) -> None:
    n = len(rows)
    mle = np.array([r["mle"] for r in rows])
    q = np.array([r["q"] for r in rows])
    lr = np.array([r["lr"] for r in rows])
    c50 = np.mean((q[:, 1] <= TRUE) & (TRUE <= q[:, 2]))
    c90 = np.mean((q[:, 0] <= TRUE) & (TRUE <= q[:, 3]))
    curv = np.nanmean([r["curv"] for r in rows], axis=0)
    expo = 2.0 - 2.0 * np.polyfit(np.log(STEPS), np.log(curv), 1)[0]
    sd = mle.std(ddof=1)
    print(f"  {name:<28} {n:>5} {mle.mean():8.5f} {sd:8.5f} {np.mean([r['se'] for r in rows]):8.5f} "
          f"{np.mean([r['sd'] for r in rows]):9.5f} {c50:6.3f} {c90:6.3f} "
          f"{np.mean(lr <= 0.4549):6.3f} {np.mean(lr <= 2.7055):6.3f} "
          f"+-{1.96 * np.sqrt(0.25 / n):.3f}/{1.96 * np.sqrt(0.09 / n):.3f} {expo:6.2f}")


def exact_posteriors(n_closed: int, n_open: int, oversample: int = 1) -> None:
    from scipy import signal

    from bayespilot.likelihood import Likelihood
    from bayespilot.model import paper_model
    from bayespilot.noise import ARNoise
    from bayespilot.simulate import remnant, simulate

    model = paper_model(oversample=oversample)  # the simulator ignores oversample
    k = model.parameter_names.index("delta_abs")
    print(f"\n6. Exact 1-D posteriors of delta_abs on a grid (FD, the others at the truth, "
          f"flat prior; truth {TRUE}; likelihood {model.name})")
    print(f"  {'setting':<28} {'n':>5} {'mean MLE':>8} {'sd(MLE)':>8} {'mean SE':>8} "
          f"{'post. sd':>9} {'cr.50':>6} {'cr.90':>6} {'LR50':>6} {'LR90':>6} {'band':>12} "
          f"{'expo.':>6}")
    rows: dict[str, list] = {"(a) open loop, exact model": []}
    sim = simulate(model, task="FD", motion_gain=1.0, remnant_fraction=0.2,
                   seed=calibration_seed("FD", 0))
    free0 = model.free_vector(sim.params)
    lik = Likelihood(model, sim.recording, discard=2.0)
    u0 = lik.response(free0)
    noise = ARNoise.from_residual((sim.recording.u - u0)[lik.used])
    s_w = noise.whiten((sim.recording.u - u0)[lik.used]).std()
    burn = 20_000
    for r in range(n_open):
        w = np.random.default_rng(EXACT_SEED + 500_000 + r).standard_normal(burn + u0.size)
        x = signal.lfilter([1.0], np.r_[1.0, -noise.a], s_w * w)[burn:]
        lik = Likelihood(model, sim.recording.with_signals(u=u0 + x), discard=2.0, noise=noise)
        rows["(a) open loop, exact model"].append(_grid_posterior(lik, free0, k))
    if n_open:
        _coverage_row("(a) open loop, exact model", rows["(a) open loop, exact model"])

    names = ("(b) closed loop, as simulated", "(c) closed loop, no model err",
             "(d) independent remnant")
    rows = {name: [] for name in names}
    mech = []
    for r in range(n_closed):
        sim = simulate(model, task="FD", motion_gain=1.0, remnant_fraction=0.2,
                       seed=EXACT_SEED + r)
        rec, st = sim.recording, sim.settings
        free0 = model.free_vector(sim.params)
        lik0 = Likelihood(model, rec, discard=2.0)
        u0 = lik0.response(free0)
        h = 1.0 / (rec.sample_rate_hz * st["oversample"])
        other = remnant(u0.size * st["oversample"], h, sim.remnant_gain, st["T_n"],
                        np.random.default_rng(EXACT_SEED + 1_000_000 + r),
                        st["noise_psd"])[::st["oversample"]]
        for name, u in zip(names, (rec.u, u0 + sim.remnant, u0 + other)):
            rr = rec.with_signals(u=u)
            eps = u[lik0.used] - u0[lik0.used]
            lik = Likelihood(model, rr, discard=2.0, noise=ARNoise.from_residual(eps))
            rows[name].append(_grid_posterior(lik, free0, k))
        if r < 40:  # the model error's cross term in -ln L at truth +- 0.001
            noise = ARNoise.from_residual((rec.u - u0)[lik0.used])
            nw = noise.whiten(sim.remnant[lik0.used])
            em = noise.whiten((rec.u - u0 - sim.remnant)[lik0.used])
            s2 = np.mean(nw**2)
            rise, cross = [], []
            for d in (-0.001, 0.001):
                f = free0.copy()
                f[k] = TRUE + d
                g = noise.whiten((lik0.response(f) - u0)[lik0.used])
                rise.append(g @ g / (2.0 * s2))
                cross.append(-(em @ g) / s2)
            mech.append((np.mean(rise), np.mean(cross), (cross[1] - cross[0]) / 2.0,
                         em @ em / s2))
    for name in names:
        _coverage_row(name, rows[name])
    if mech:
        m = np.array(mech)
        kappa = m[:, 1].mean() / m[:, 0].mean()
        print(f"  model error eps_m = u - u_hat(truth) - remnant, whitened, first {len(m)} "
              f"recordings: energy {m[:, 3].mean():.1f} s2 (mean); at truth +- 0.001 it adds "
              f"{m[:, 1].mean():.2f} (even part, sd {m[:, 1].std(ddof=1):.2f}) to -ln L's rise "
              f"of {m[:, 0].mean():.2f} without it, kappa = {kappa:.2f}; odd part "
              f"{m[:, 2].mean():+.2f}")
        z90, z50 = 1.6449 * np.sqrt(1 + kappa), 0.6745 * np.sqrt(1 + kappa)
        from scipy.stats import norm
        print(f"  a deterministic bowl (1 + kappa) I / 2 d^2 over a score of variance I: "
              f"sd(MLE) / posterior sd = 1/sqrt(1 + kappa) = {1 / np.sqrt(1 + kappa):.2f}, "
              f"coverage {2 * norm.cdf(z50) - 1:.3f} / {2 * norm.cdf(z90) - 1:.3f} at 50 / 90 %")


def _area_corrected_dz(i: np.ndarray, d: float) -> np.ndarray:
    """Dead-zone samples of a periodic canal output, each corrected by half the area error of
    its two intervals (check 7, variant G): the exact mean of dz(i(t)) over an interval with
    i linear between samples, less the trapezoid of its end samples."""
    def antiderivative(x):  # integral_0^x dz(s) ds
        a = np.maximum(np.abs(x) - d, 0.0)
        return 0.5 * a * a

    dz = np.sign(i) * np.maximum(np.abs(i) - d, 0.0)
    i1 = np.roll(i, -1)
    di = i1 - i
    mean = dz.copy()
    moving = np.abs(di) > 1e-12
    mean[moving] = (antiderivative(i1[moving]) - antiderivative(i[moving])) / di[moving]
    flat = ~moving
    mean[flat] = np.sign(i[flat]) * np.maximum(np.abs(i[flat]) - d, 0.0)
    eps = mean - 0.5 * (dz + np.roll(dz, -1))
    return dz + 0.5 * (eps + np.roll(eps, 1))


def kink_variants(n_rec: int, oversample: int = 10) -> None:
    """Which part of the 100-Hz model makes the error at the dead zone's kinks (check 7).

    On the first ``n_rec`` recordings of check 6 (FD, K_theta = 1, F_n = 0.2),
    the model error at the truth, eps_m = (u - remnant) - u_hat(truth), and the
    bowl it adds to -ln L around delta_abs (kappa: the second difference of
    the whitened -ln L at truth +- 0.001 with eps_m in the data, over the same
    without it, minus 1), for three versions of the motion path, written from
    the equations with the plain NumPy twins of ``tests/naive.py``:

    A. the package's model: dead zone on the 100-Hz canal output, then the
       delay by linear interpolation, Tustin at 100 Hz;
    B. the delay interpolated first, then the dead zone (in continuous time
       the two commute; sampled, B keeps the interpolation off the kink);
    C. the motion path at ``oversample`` times the rate: the canal output
       interpolated linearly, the dead zone and the delay there, Tustin of
       -K_m H_nm at the fine rate, every ``oversample``-th sample kept.
    F. A with a first-order hold instead of Tustin for -K_m H_nm (exact for
       inputs linear between samples: no frequency warping);
    G. F with each sample corrected by half of its two intervals' area error
       (the exact mean of the dead zone of the linearly interpolated canal
       output over an interval, less the trapezoid of its end samples).
    P. the package's likelihood with the vestibular channel oversampled
       (``paper_model(oversample=M)``, ``kernels/_oversample.py``): C as the
       package computes it, at the recording's rate.

    Energies are in innovation variances s2 of the AR model of the residual.
    """
    import sys

    from scipy import signal

    from bayespilot import presets
    from bayespilot.likelihood import Likelihood
    from bayespilot.model import paper_model
    from bayespilot.noise import ARNoise
    from bayespilot.simulate import simulate

    sys.path.insert(0, str(ROOT / "tests"))
    import naive  # the plain NumPy/SciPy twin of the likelihood's model

    model = paper_model()
    p0 = presets.paper_parameters("FD")
    M = int(oversample)

    def motion(p, i, dt, variant):
        if variant in "AFG":
            d = naive.delay(naive.dead_zone(i, p["delta_abs"]), p["tau_m"], dt, "periodic")
        elif variant == "B":
            d = naive.dead_zone(naive.delay(i, p["tau_m"], dt, "periodic"), p["delta_abs"])
        else:
            n = i.size
            tf = np.arange(n * M) * dt / M
            i_f = np.interp(tf, np.arange(n) * dt, i, period=n * dt)
            d_f = np.interp(tf - p["tau_m"], tf, naive.dead_zone(i_f, p["delta_abs"]),
                            period=n * dt)
            w, z = p["omega_nm"], p["zeta_nm"]
            b, a = signal.bilinear([-p["K_m"] * w * w], [1.0, 2 * z * w, w * w], fs=M / dt)
            return naive.steady_filter(b, a, d_f)[::M]
        w, z = p["omega_nm"], p["zeta_nm"]
        num, den = [-p["K_m"] * w * w], [1.0, 2 * z * w, w * w]
        if variant in "FG":
            if variant == "G":
                d = naive.delay(_area_corrected_dz(i, p["delta_abs"]), p["tau_m"], dt,
                                "periodic")
            bd, a, _ = signal.cont2discrete((num, den), dt, method="foh")
            b, a = np.ravel(bd), np.ravel(a)
        else:
            b, a = signal.bilinear(num, den, fs=1.0 / dt)
        idx = np.arange(-500 - 2, i.size)  # the likelihood's 5-s warm-up, periodic
        fir = signal.lfilter(b, [1.0], np.take(d, idx, mode="wrap"))[2:]
        return signal.lfilter([1.0], a, fir)[500:]

    print(f"\n7. The model error at the kinks, six versions of the motion path "
          f"({n_rec} recordings of check 6)")
    rows = {v: [] for v in "ABCFGP"}
    fine_model = paper_model(oversample=M)
    for r in range(n_rec):
        sim = simulate(model, task="FD", motion_gain=1.0, remnant_fraction=0.2,
                       seed=EXACT_SEED + r)
        rec = sim.recording
        lik = Likelihood(model, rec)
        i = lik.X[1]
        visual = lik.response(dict(p0, K_m=0.0))  # the visual channel alone
        clean = rec.u - sim.remnant
        ar = ARNoise.from_residual((rec.u - lik.response(p0))[200:])

        def w(x):
            return ar.whiten(x[200:])

        s2 = float(np.mean(w(rec.u - lik.response(p0)) ** 2))
        fine = Likelihood(fine_model, rec)
        for v in "ABCFGP":
            def resp(d, v=v):
                if v == "P":
                    return fine.response(dict(p0, delta_abs=d))
                return visual + motion(dict(p0, delta_abs=d), i, rec.dt, v)

            y0 = resp(TRUE)
            if v == "A":  # the twin is the package's model
                assert np.allclose(y0, lik.response(p0), rtol=0, atol=1e-9 * np.abs(y0).max())

            def f(d, data):
                return float(np.sum(w(data - resp(d)) ** 2) / s2)

            h = 0.001
            bowl = f(TRUE + h, clean) + f(TRUE - h, clean) - 2 * f(TRUE, clean)
            ref = f(TRUE + h, y0) + f(TRUE - h, y0) - 2 * f(TRUE, y0)
            rows[v].append((f(TRUE, clean), bowl / ref - 1.0))
    names = {"A": "A, the package (dead zone, then delay)", "B": "B, delay, then dead zone",
             "C": f"C, motion path at {M}x the rate", "F": "F, A with a first-order hold",
             "G": "G, F with area-corrected samples",
             "P": f"P, the package, oversample={M}"}
    for v in "ABCFGP":
        a = np.array(rows[v])
        print(f"   {names[v]:<40} model-error energy {a[:, 0].mean():6.2f} s2 "
              f"(range {a[:, 0].min():.2f}-{a[:, 0].max():.2f}), kappa {a[:, 1].mean():+.3f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recordings", type=int, default=5,
                    help="FD calibration recordings for the AR-order check (default 5)")
    ap.add_argument("--spectra", type=int, default=20,
                    help="FD calibration recordings for the residual checks (default 20)")
    ap.add_argument("--scatter", type=int, default=40,
                    help="FD calibration recordings for check 5 (default 40, 0 skips it)")
    ap.add_argument("--exact", type=int, default=0,
                    help="fresh closed-loop FD recordings for check 6 (default 0 skips it)")
    ap.add_argument("--open-loop", type=int, default=1000,
                    help="open-loop noise realizations for check 6 (default 1000)")
    ap.add_argument("--exact-only", action="store_true", help="run check 6 only")
    ap.add_argument("--oversample", type=int, default=None, metavar="M",
                    help="--kinks: the fine rate of variants C and P, samples per interval "
                         "(default 10); --exact: the likelihood's vestibular channel at M "
                         "times the rate (default 1, the paper's computation)")
    ap.add_argument("--kinks", type=int, default=0, metavar="N",
                    help="run only check 7 on the first N recordings of check 6: the model "
                         "error at the kinks for three versions of the motion path")
    ap.add_argument("--figure-only", action="store_true",
                    help="run only check 3 (two simulations of FD recording 0, seconds): its "
                         "table and docs/figures/threshold_information.png")
    args = ap.parse_args(argv)
    if args.figure_only:
        information_spectrum()
        return 0
    if args.kinks:
        kink_variants(args.kinks, args.oversample or 10)
        return 0
    if args.exact_only:
        exact_posteriors(args.exact, args.open_loop, args.oversample or 1)
        return 0
    posterior_shape()
    curvature(args.recordings)
    information_spectrum()
    residual_checks(args.spectra)
    if args.scatter:
        conditional_scatter(args.scatter)
    if args.exact:
        exact_posteriors(args.exact, args.open_loop, args.oversample or 1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

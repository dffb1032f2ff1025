"""The likelihood with its vestibular channel oversampled: cost per evaluation against M.

Run:  python benchmarks/bench_oversample.py [--factors 1,2,4,8] [--repeats 200]

Times, on task FD, K_theta = 1, F_n = 0.2, 81.92 s (N = 8192):

- ``Likelihood.neg_log_lik`` on one thread (M = 1 is the paper's
  computation, by the segmented SIMD kernel where the CPU has one; M > 1 is
  the general path with ``kernels/_oversample.py``);
- ``Likelihood.batch`` of 160 vectors on all numba threads, per evaluation;
- the coloured likelihood with the AR model profiled (what ``sample`` runs
  by default), 160-batch per evaluation;
- the plain NumPy/SciPy twin of the oversampled response (the canal output
  interpolated, dead zone, ``np.interp`` delay and ``lfilter`` at M times the
  rate), for scale.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numba
import numpy as np
from scipy import signal

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import naive  # noqa: E402
from bayespilot import presets  # noqa: E402
from bayespilot.likelihood import Likelihood  # noqa: E402
from bayespilot.model import paper_model  # noqa: E402
from bayespilot.noise import ARNoise  # noqa: E402
from bayespilot.simulate import simulate  # noqa: E402


def median_us(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e6 * statistics.median(times)


def twin(p, lik, M):
    """u_hat with the vestibular channel at M times the rate, in NumPy/SciPy."""
    i, dt = lik.X[1], lik.dt
    n = i.size
    tf = np.arange(n * M) * dt / M
    i_f = np.interp(tf, np.arange(n) * dt, i, period=n * dt)
    d_f = np.interp(tf - p["tau_m"], tf, naive.dead_zone(i_f, p["delta_abs"]), period=n * dt)
    w, z = p["omega_nm"], p["zeta_nm"]
    b, a = signal.bilinear([-p["K_m"] * w * w], [1.0, 2 * z * w, w * w], fs=M / dt)
    return naive.steady_filter(b, a, d_f)[::M]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--factors", default="1,2,4,8")
    ap.add_argument("--repeats", type=int, default=200)
    args = ap.parse_args(argv)
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"numba threads {numba.get_num_threads()}; load {os.getloadavg()}")
    sim = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=3)
    rec, p = sim.recording, presets.paper_parameters("FD")
    rng = np.random.default_rng(0)
    print(f"{'M':>3} {'kernel':>10} {'single us':>10} {'batch us/eval':>14} "
          f"{'profiled AR us/eval':>20} {'NumPy twin us':>14}")
    for M in (int(x) for x in args.factors.split(",")):
        model = paper_model(oversample=M)
        lik = Likelihood(model, rec)
        free = model.free_vector(p) * (1 + 0.02 * rng.standard_normal((160, model.n_free)))
        free[:, -1] = np.abs(free[:, -1])
        numba.set_num_threads(1)
        t1 = median_us(lambda: lik.neg_log_lik(p), args.repeats)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        tb = median_us(lambda: lik.batch(free), max(5, args.repeats // 20)) / 160
        noise = ARNoise.from_residual(lik.residual(p)[200:])
        from bayespilot.kernels import _coloured as C

        out = np.empty(160)
        fl = np.zeros(160, dtype=np.bool_)

        def profiled():
            C.neg_log_lik_profiled_batch(free, lik._free_idx, lik._base, noise.order, lik.X,
                                         lik.u, *lik._args(), lik.dt, lik.periodic, lik.warm,
                                         lik.s2_floor, numba.get_num_threads(), out, fl, 200)

        tp = median_us(profiled, max(5, args.repeats // 20)) / 160
        tt = median_us(lambda: twin(p, lik, M), max(3, args.repeats // 50)) if M > 1 else float("nan")
        print(f"{M:>3} {'segmented' if lik.segmented else 'general':>10} {t1:10.1f} {tb:14.2f} "
              f"{tp:20.2f} {tt:14.0f}")
    print(f"load at the end: {os.getloadavg()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

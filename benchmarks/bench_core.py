"""Core-kernel benchmarks: the Eq. 4 likelihood and the closed-loop simulator.

Run on demand (not part of the test suite)::

    /tmp/venv/bin/python benchmarks/bench_core.py            # full run
    /tmp/venv/bin/python benchmarks/bench_core.py --quick    # fewer repeats, no NumPy RK4

Prints one table comparing the numba kernels with plain NumPy/SciPy
implementations of the same computation (checked to agree before timing):

1. one likelihood evaluation at N = 8192 on one thread;
2. a batch of 160 parameter vectors on all numba threads (and on one) vs 160
   SciPy evaluations;
3. one closed-loop simulation (81.92 s, F_n = 0.2) vs a fixed-step NumPy RK4 loop.

(1) and (2) time both likelihood kernels: the segmented SIMD kernel
(``kernels/_segmented.py``, what ``Likelihood`` uses on a CPU with AVX-512 or
AVX2) and the fused scalar kernel (``kernels/_response.py``, what it uses
elsewhere or with ``BAYESPILOT_KERNEL=scalar``).  The ratio columns compare
with the tuned SciPy likelihood and with ``InterpLikelihood``, the reference
as the issue words it.

Timings are medians over repeats after warm-up calls (``time.perf_counter``).
"""

from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import NamedTuple

import numba
import numpy as np
from scipy import signal

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # tests/naive.py: the slow reference

import naive  # noqa: E402
from bayespilot import presets  # noqa: E402
from bayespilot.kernels import _response as R  # noqa: E402
from bayespilot.kernels import _segmented as SEG  # noqa: E402
from bayespilot.likelihood import Likelihood  # noqa: E402
from bayespilot.model import paper_model  # noqa: E402
from bayespilot.simulate import TrackingTask, simulate  # noqa: E402

TARGET_SINGLE_US = 30.0
TARGET_BATCH_MS = 2.0
TARGET_RATIO = 100.0


class Timing(NamedTuple):
    """Seconds per call: the median over repeats and the fastest repeat."""

    median: float
    best: float


def median_time(fn, repeats: int, warmup: int = 3, inner: int = 1) -> Timing:
    """Seconds per call of ``fn`` over ``repeats`` timings of ``inner`` calls each."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(inner):
            fn()
        times.append((time.perf_counter() - t0) / inner)
    return Timing(statistics.median(times), min(times))


# --- a tuned NumPy/SciPy likelihood ------------------------------------------------------
def _tustin2(b1, b0, a1, a0, fs):
    """Tustin of (b1 s + b0) / (s^2 + a1 s + a0): (B, A) with A[0] = 1, by formula."""
    c = 2.0 * fs
    c2 = c * c
    d0 = c2 + a1 * c + a0
    B = np.array([b1 * c + b0, 2.0 * b0, b0 - b1 * c]) / d0
    A = np.array([1.0, 2.0 * (a0 - c2) / d0, (c2 - a1 * c + a0) / d0])
    return B, A


class ScipyLikelihood:
    """-ln L (periodic mode) with NumPy array ops and ``scipy.signal.lfilter``.

    The channel inputs (e and the canal output i) are taken from a
    :class:`~bayespilot.likelihood.Likelihood` so both compute the same thing.
    Per evaluation: dead zone, delays by index arithmetic with wrap-around and
    linear interpolation, Tustin coefficients by formula, two FIR ``lfilter``
    calls and one all-pole ``lfilter`` for H_nm (warm-started).
    """

    def __init__(self, lik: Likelihood) -> None:
        self.e = lik.X[0].copy()
        self.i = lik.X[1].copy()
        self.u = lik.u.copy()
        self.n = lik.n
        self.fs = 1.0 / lik.dt
        self.warm = lik.warm
        self.base = np.arange(-self.warm - 2, self.n)
        self.floor = lik.s2_floor

    def _delayed(self, x, tau):
        dd = tau * self.fs
        m = math.floor(dd)
        f = dd - m
        idx = self.base - m
        return (1.0 - f) * x.take(idx, mode="wrap") + f * x.take(idx - 1, mode="wrap")

    def __call__(self, th) -> float:
        K_v, T_vl, tau_v, K_m, tau_m, w, z, d = th
        o = np.sign(self.i) * np.maximum(np.abs(self.i) - d, 0.0)
        w2 = w * w
        b_v, a = _tustin2(K_v * T_vl * w2, K_v * w2, 2.0 * z * w, w2, self.fs)
        b_m, _ = _tustin2(0.0, -K_m * w2, 2.0 * z * w, w2, self.fs)
        v = (signal.lfilter(b_v, [1.0], self._delayed(self.e, tau_v))
             + signal.lfilter(b_m, [1.0], self._delayed(o, tau_m)))[2:]
        y = signal.lfilter([1.0], a, v)[self.warm:]
        if not np.isfinite(y[-1]):
            return np.inf
        s2 = max(float(np.mean((self.u - y) ** 2)), self.floor)
        return 0.5 * self.n * math.log(s2) + 0.5 * self.n


class InterpLikelihood(ScipyLikelihood):
    """The reference as issue 2 words it: ``lfilter`` with the delays by ``numpy.interp``.

    The periodic extension of the channel inputs is indexed once here (enough
    samples either side for the warm-up and the largest delay), so each delay
    is one ``np.interp`` over the sample times; everything else as
    :class:`ScipyLikelihood`.
    """

    def __init__(self, lik: Likelihood, max_delay: float = 1.5) -> None:
        super().__init__(lik)
        ext = self.warm + 2 + int(math.ceil(max_delay * self.fs)) + 2
        k = np.arange(-ext, self.n + ext)
        self.t_ext = k / self.fs
        self.wrap = k % self.n
        self.t_out = self.base / self.fs

    def _delayed(self, x, tau):
        return np.interp(self.t_out - tau, self.t_ext, x[self.wrap])


# --- a plain NumPy/Python closed loop (fixed-step RK4) ----------------------------------
def numpy_closed_loop(params, task: TrackingTask, oversample: int = 10):
    """The paper's loop (Fig. 2) with the paper's pilot model, RK4 in plain Python floats.

    Same conventions as ``bayespilot.simulate``: step h = dt / oversample, a
    run-in of ``task.run_in``, forcing tabulated at half steps, delays read a
    history of the channel signals with linear interpolation, rest before t = 0,
    no remnant.  Returns u at the recording's samples.
    """
    K_v, T_vl, tau_v, K_m, tau_m, w, z, dz = (params[k] for k in presets.PARAMETER_NAMES)
    K_c = task.controlled_element[0][0]
    k_du = task.control_gain
    k_th = task.motion_gain
    fs = task.sample_rate_hz
    h = 1.0 / (fs * oversample)
    n_rec = task.n_samples
    k_start = int(round(task.run_in / h))
    n_steps = k_start + n_rec * oversample
    t_half = np.arange(2 * n_steps + 2) * (h / 2)
    ft = task.target(t_half).tolist()
    fd = task.disturbance(t_half).tolist()
    a_c = presets.K_SCC * presets.T_SCC1 / presets.T_SCC2   # canal feedthrough
    b_c = presets.K_SCC * (1.0 - presets.T_SCC1 / presets.T_SCC2)
    T2 = presets.T_SCC2
    w2 = w * w
    zw2 = 2.0 * z * w
    hist_v = [0.0] * (n_steps + 2)
    hist_m = [0.0] * (n_steps + 2)

    def delayed(hist, t, tau, k_now, q_now):
        p = (t - tau) / h
        if p < 0.0:
            return 0.0
        if p >= k_now:
            return q_now
        kk = int(p)
        fr = p - kk
        return hist[kk] + fr * (hist[kk + 1] - hist[kk])

    def derivs(x, j, t, k_now):
        th, thd, xc, zv1, zv2, zm1, zm2 = x
        u = w2 * (zv1 + T_vl * zv2) + w2 * zm1
        delta = k_du * u + fd[j]
        thdd = K_c * delta
        e = ft[j] - th
        thddm = k_th * thdd
        i = a_c * thddm + b_c * xc
        o = math.copysign(max(abs(i) - dz, 0.0), i)
        qv = delayed(hist_v, t, tau_v, k_now, e)
        qm = delayed(hist_m, t, tau_m, k_now, o)
        dx = (thd, thdd, (thddm - xc) / T2,
              zv2, -w2 * zv1 - zw2 * zv2 + K_v * qv,
              zm2, -w2 * zm1 - zw2 * zm2 - K_m * qm)
        return dx, u, e, o

    x = [0.0] * 7
    _, _, e0, o0 = derivs(x, 0, 0.0, 0)
    hist_v[0], hist_m[0] = e0, o0
    u_rec = np.empty(n_rec)
    r = 0
    for k in range(n_steps):
        t = k * h
        k1, u, _, _ = derivs(x, 2 * k, t, k)
        if k >= k_start and (k - k_start) % oversample == 0 and r < n_rec:
            u_rec[r] = u
            r += 1
        xs = [a + 0.5 * h * b for a, b in zip(x, k1)]
        k2, _, _, _ = derivs(xs, 2 * k + 1, t + 0.5 * h, k)
        xs = [a + 0.5 * h * b for a, b in zip(x, k2)]
        k3, _, _, _ = derivs(xs, 2 * k + 1, t + 0.5 * h, k)
        xs = [a + h * b for a, b in zip(x, k3)]
        k4, _, _, _ = derivs(xs, 2 * k + 2, t + h, k)
        x = [a + h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
             for a, b1, b2, b3, b4 in zip(x, k1, k2, k3, k4)]
        _, _, e1, o1 = derivs(x, 2 * k + 2, t + h, k + 1)
        hist_v[k + 1], hist_m[k + 1] = e1, o1
    return u_rec


# --- the benchmark --------------------------------------------------------------------------
def machine() -> str:
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
        name = next((ln.split(":", 1)[1].strip() for ln in out.splitlines()
                     if ln.startswith("Model name")), platform.processor())
    except (OSError, subprocess.CalledProcessError):
        name = platform.processor()
    return f"{name}, {os.cpu_count()} logical CPUs"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats; skip the NumPy RK4 loop")
    args = ap.parse_args(argv)
    rep = 0.2 if args.quick else 1.0

    max_threads = numba.config.NUMBA_NUM_THREADS
    print(f"bayespilot core benchmark, {datetime.date.today().isoformat()}")
    print(f"machine: {machine()}; python {platform.python_version()}, numpy {np.__version__}, "
          f"numba {numba.__version__}")
    print(f"numba threads available: {max_threads}; load average: "
          f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}")

    model = paper_model()
    sim = simulate(model, task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=1)
    rec = sim.recording
    lik = Likelihood(model, rec)  # periodic, warm-up 5 s
    enabled = SEG.ENABLED
    try:
        SEG.ENABLED = False
        lik_fused = Likelihood(model, rec)  # the same likelihood on the fused scalar kernel
    finally:
        SEG.ENABLED = enabled
    print(f"likelihood kernel: {'segmented SIMD' if lik.segmented else 'fused scalar'} "
          f"({SEG.REASON})")
    n = rec.n_samples
    theta = model.full_vector(sim.params)
    free = model.free_vector(sim.params)
    sp = ScipyLikelihood(lik)
    si = InterpLikelihood(lik)

    # agreement before timing
    v_nb = lik.neg_log_lik(free)
    v_sp = sp(theta)
    assert abs(v_nb - v_sp) <= 1e-9 * abs(v_nb), (v_nb, v_sp)
    assert abs(v_nb - si(theta)) <= 1e-9 * abs(v_nb), (v_nb, si(theta))
    assert abs(v_nb - lik_fused.neg_log_lik(free)) <= 1e-11 * abs(v_nb)
    rows = []

    def row(label, seconds, per_eval=None, note=""):
        rows.append((label, seconds, per_eval, note))

    # (1) one evaluation, one thread
    numba.set_num_threads(1)
    y = np.empty(n)
    q = np.empty(n)
    v = np.empty(n)
    p = model.plan
    kargs = (theta, lik.X, lik.u, p.ch_int, p.ch_float, p.st_int, p.st_const, p.out_int, lik.dt,
             lik.periodic, lik.warm, lik.s2_floor, y, q, v,
             np.empty((lik.X.shape[0], n + 2 * lik.pad)), lik.pad)
    reps = int(400 * rep) + 5
    t_raw = median_time(lambda: R.neg_log_lik_one(*kargs), reps, inner=20)
    t_api_fused = median_time(lambda: lik_fused.neg_log_lik(free), reps, inner=20)
    if lik.segmented:
        sargs = (theta, *lik._seg_args)
        t_seg = median_time(lambda: SEG.neg_log_lik_segmented_one(*sargs), reps, inner=20)
    t_api = median_time(lambda: lik.neg_log_lik(free), reps, inner=20)
    t_sp = median_time(lambda: sp(theta), int(100 * rep) + 5, inner=5)
    t_si = median_time(lambda: si(theta), int(100 * rep) + 5, inner=5)
    e, tdm, u, dt, warm = rec.e, rec.theta_ddot_m, rec.u, rec.dt, lik.warm
    params = sim.params
    t_naive = median_time(lambda: naive.naive_neg_log_lik(params, u, e, tdm, dt, "periodic", warm),
                          int(30 * rep) + 3, warmup=1)
    print(f"\nN = {n}; -ln L numba {v_nb:.6f}, SciPy {v_sp:.6f}")

    # (2) batch of 160 on all threads (and on one) vs 160 SciPy evaluations
    lo, hi = model.bounds
    pop = np.random.default_rng(0).uniform(lo, hi, size=(160, model.n_free))
    full_pop = np.array([model.full_vector(r) for r in pop])
    out = np.empty(160)
    numba.set_num_threads(max_threads)
    ref = np.array([sp(th) for th in full_pop])
    got = lik.batch(pop, out=out)
    assert np.allclose(got, ref, rtol=1e-9, atol=0), np.max(np.abs(got - ref))
    old = lik_fused.batch(pop)
    seg_vs_fused = float(np.max(np.abs(got - old) / np.abs(old)))
    assert seg_vs_fused <= 1e-11, seg_vs_fused
    batch = {}
    for th in (max_threads, 1):
        numba.set_num_threads(th)
        for name, lk in (("new", lik), ("fused", lik_fused)):
            batch[name, th] = median_time(lambda: lk.batch(pop, out=out),
                                          int((60 if th > 1 else 30) * rep) + 5)
    numba.set_num_threads(max_threads)
    t_batch = batch["new", max_threads]
    t_sp_batch = median_time(lambda: [sp(th) for th in full_pop], int(5 * rep) + 2, warmup=1)

    # (3) closed loop, 81.92 s at 1 kHz after a 40.96 s run-in
    t_sim_one = median_time(lambda: simulate(model, task="FD", remnant_gain=sim.remnant_gain,
                                             seed=1), int(10 * rep) + 2, warmup=1)
    t_sim_cal = median_time(lambda: simulate(model, task="FD", remnant_fraction=0.2, seed=1),
                            int(5 * rep) + 1, warmup=1)
    task = TrackingTask.paper("FD", 1.0)
    if not args.quick:
        t0 = time.perf_counter()
        u_np = numpy_closed_loop(sim.params, task)
        t_np_loop = time.perf_counter() - t0
        t_np_loop = Timing(t_np_loop, t_np_loop)
        u_nb = simulate(model, task="FD", remnant_gain=0.0).recording.u
        loop_diff = float(np.max(np.abs(u_np - u_nb)) / np.std(u_nb))
    else:
        t_np_loop = Timing(float("nan"), float("nan"))
        loop_diff = float("nan")

    us = 1e6
    print(f"\n{'computation':<60} {'median':>11} {'min':>11} {'per eval':>11} {'vs SciPy':>9} "
          f"{'vs interp':>9}")
    print("-" * 116)
    sp_per = t_sp.median                 # SciPy seconds per evaluation (single)
    sp_batch_per = t_sp_batch.median / 160
    si_per = t_si.median                 # InterpLikelihood seconds per evaluation

    def line(label, t: Timing, count=None, base_per=None, unit="us", si_per=None):
        scale = us if unit == "us" else 1e3
        per = t.median / count if count else None
        s_p = f"{per * us:8.2f} us" if per is not None else ""
        s_r = f"{base_per / per:8.1f}x" if (base_per is not None and per) else ""
        s_i = f"{si_per / per:8.1f}x" if (si_per is not None and per) else ""
        nd = 3 if t.median * scale < 10 else 1
        print(f"{label:<60} {t.median * scale:8.{nd}f} {unit} {t.best * scale:8.{nd}f} {unit} "
              f"{s_p:>11} {s_r:>9} {s_i:>9}")

    kern = "segmented SIMD" if lik.segmented else "fused scalar"
    print(f"(1) one -ln L evaluation, N = {n}, periodic, one thread")
    if lik.segmented:
        line("  numba segmented kernel (one row)", t_seg, 1, sp_per, si_per=si_per)
    line("  numba fused kernel neg_log_lik_one (preallocated buffers)", t_raw, 1, sp_per,
         si_per=si_per)
    line(f"  numba Likelihood.neg_log_lik ({kern})", t_api, 1, sp_per, si_per=si_per)
    line("  numba Likelihood.neg_log_lik (fused scalar)", t_api_fused, 1, sp_per, si_per=si_per)
    line("  NumPy/SciPy tuned (Tustin by formula, lfilter, take)", t_sp, 1, sp_per, si_per=si_per)
    line("  NumPy/SciPy as worded (lfilter, np.interp)", t_si, 1, sp_per, si_per=si_per)
    line("  tests/naive.py (bilinear, lfilter, np.interp)", t_naive, 1, sp_per, si_per=si_per)
    print("(2) batch of 160 parameter vectors within Table 1 bounds "
          f"(segmented vs fused: max rel. difference {seg_vs_fused:.1e})")
    for th in (max_threads, 1):
        w = "thread" if th == 1 else "threads"
        line(f"  numba Likelihood.batch, {kern}, {th} {w}", batch["new", th], 160, sp_batch_per,
             "ms", si_per)
        line(f"  numba Likelihood.batch, fused scalar, {th} {w}", batch["fused", th], 160,
             sp_batch_per, "ms", si_per)
    line("  160 x NumPy/SciPy tuned", t_sp_batch, 160, sp_batch_per, "ms", si_per)
    print("(3) closed-loop simulation, 81.92 s (+40.96 s run-in), RK4 at 1 kHz")
    line("  numba simulate(), one loop (remnant_gain given)", t_sim_one, unit="ms")
    line("  numba simulate(), F_n = 0.2 (K_n calibrated: several loops)", t_sim_cal, unit="ms")
    if not args.quick:
        line("  plain Python/NumPy RK4 loop, one loop", t_np_loop, unit="ms")
        print(f"  (NumPy loop vs numba at K_n = 0: max |du| / std(u) = {loop_diff:.1e}; "
              f"one-loop speed-up {t_np_loop.median / t_sim_one.median:.0f}x)")

    print("\ntargets:")
    t_one = t_seg if lik.segmented else t_raw
    r_single = sp_per / t_one.median
    r_batch = sp_batch_per / (t_batch.median / 160)
    ri_single = si_per / t_one.median
    ri_batch = si_per / (t_batch.median / 160)
    ri_batch_min = t_si.best / (t_batch.best / 160)
    ok1 = t_one.median * us <= TARGET_SINGLE_US and t_api.median * us <= TARGET_SINGLE_US
    ok2 = t_batch.median * 1e3 <= TARGET_BATCH_MS
    ok3 = ri_batch >= TARGET_RATIO
    print(f"  one evaluation <= {TARGET_SINGLE_US:.0f} us on one core: "
          f"{t_one.median * us:.1f} us kernel ({kern}), {t_api.median * us:.1f} us API"
          f"  -> {'met' if ok1 else 'NOT met'}")
    print(f"  160-batch <= {TARGET_BATCH_MS:.0f} ms on {max_threads} cores: "
          f"{t_batch.median * 1e3:.2f} ms ({kern})  -> {'met' if ok2 else 'NOT met'}")
    print(f"  batch per evaluation >= {TARGET_RATIO:.0f}x faster than the SciPy reference "
          f"(lfilter + np.interp): {ri_batch:.1f}x on medians ({ri_batch_min:.1f}x on minima)"
          f"  -> {'met' if ok3 else 'NOT met'}; single {ri_single:.1f}x; "
          f"vs tuned SciPy single {r_single:.1f}x, batch {r_batch:.1f}x; "
          f"vs tests/naive.py single {t_naive.median / t_one.median:.0f}x, "
          f"batch {t_naive.median * 160 / t_batch.median:.0f}x")
    print(f"load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

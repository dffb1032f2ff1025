"""The segmented SIMD kernel (``kernels/_segmented.py``) against the fused scalar kernel.

The fused kernel (``_response.neg_log_lik_one``) is the reference: the segmented
kernel regroups its arithmetic (eight record segments per vector, each from a
zero state, corrected afterwards), so it must agree to round-off (1e-11
relative), return +inf for the same rows, and recompute exactly (to the bit)
the rows it leaves to the fused kernel.  The tests force the segmented kernel
on (``_segmented.ENABLED``), so they exercise it on any CPU; on a CPU without
AVX-512 LLVM lowers the same vector code to narrower registers.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest

import naive
from conftest import make_rng
from bayespilot import presets
from bayespilot.diagnose.catalogue import CATALOGUE
from bayespilot.kernels import _response as R
from bayespilot.kernels import _segmented as SEG
from bayespilot.kernels import _simd
from bayespilot.likelihood import Likelihood, PerfectFitWarning
from bayespilot.model import PilotModel, paper_model
from bayespilot.recording import Recording

RTOL = 1e-11
FD = dict(presets.TABLE3["FD"])


@pytest.fixture
def segmented(monkeypatch):
    """Likelihoods made inside the test use the segmented kernel where eligible."""
    monkeypatch.setattr(SEG, "ENABLED", True)


def _fused(lik: Likelihood, rows: np.ndarray) -> np.ndarray:
    """The reference: the fused scalar kernel, one row at a time (as before the change)."""
    n = lik.n
    y, q, v = np.empty(n), np.empty(n), np.empty(n)
    Qp = np.empty((lik.X.shape[0], n + 2 * lik.pad))
    out = np.empty(len(rows))
    for i, row in enumerate(rows):
        theta = lik._base.copy()
        theta[lik._free_idx] = row
        out[i] = R.neg_log_lik_one(theta, lik.X, lik.u, *lik._args(), lik.dt, lik.periodic,
                                   lik.warm, lik.s2_floor, y, q, v, Qp, lik.pad, lik.skip)[0]
    out[~np.isfinite(out)] = np.inf
    return out


def _assert_close(got: np.ndarray, ref: np.ndarray, rtol: float = RTOL) -> None:
    assert np.array_equal(np.isposinf(got), np.isposinf(ref)), (got, ref)
    fin = np.isfinite(ref)
    assert np.all(np.isfinite(got[fin]))
    if fin.any():
        rel = np.abs(got[fin] - ref[fin]) / np.abs(ref[fin])
        assert rel.max() <= rtol, f"max relative difference {rel.max():.2e}"


def _with_u(rec: Recording, u: np.ndarray) -> Recording:
    signals = dict(rec.signals)
    signals["u"] = u
    return Recording(signals, rec.sample_rate_hz, rec.motion_gain, rec.task, rec.metadata)


def _uniform(model, m, seed):
    lo, hi = model.bounds
    return make_rng(seed).uniform(lo, hi, size=(m, model.n_free))


# --- what uses it ---------------------------------------------------------------------------
def test_eligibility(segmented, fd_sim, fd_rec, model):
    rec = fd_sim.recording
    assert Likelihood(model, rec).segmented
    assert Likelihood(model, fd_rec).segmented
    assert Likelihood(paper_model(threshold=False), rec).segmented
    assert not Likelihood(model, rec, initial="rest").segmented
    assert not Likelihood(model, rec, discard=2.0).segmented
    from bayespilot.noise import ARNoise
    assert not Likelihood(model, rec, noise=ARNoise([0.5])).segmented
    for ext in CATALOGUE:
        assert not Likelihood(ext.build(model), rec).segmented, ext.name
    # a record that is not 8 equal segments
    odd = Recording({k: v[:-3] for k, v in rec.signals.items()}, rec.sample_rate_hz,
                    rec.motion_gain, rec.task, rec.metadata)
    assert not Likelihood(model, odd).segmented


def test_switched_off_uses_the_fused_kernel_bit_for_bit(monkeypatch, fd_sim, model):
    monkeypatch.setattr(SEG, "ENABLED", False)
    lik = Likelihood(model, fd_sim.recording)
    assert not lik.segmented
    pop = _uniform(model, 40, 3)
    ref = _fused(lik, pop)
    assert np.array_equal(lik.batch(pop), ref)
    assert lik.neg_log_lik(pop[5]) == ref[5]


@pytest.mark.parametrize("which", range(len(CATALOGUE)))
def test_ineligible_models_unchanged_bit_for_bit(segmented, fd_sim, model, which):
    ext = CATALOGUE[which]
    m = ext.build(model)
    lik = Likelihood(m, fd_sim.recording)
    pop = _uniform(m, 12, 50 + which)
    ref = _fused(lik, pop)
    assert np.array_equal(lik.batch(pop), ref)
    assert lik.neg_log_lik(pop[0]) == ref[0]


@pytest.mark.parametrize("kw", [dict(discard=2.0), dict(initial="rest")])
def test_ineligible_settings_unchanged_bit_for_bit(segmented, fd_sim, model, kw):
    lik = Likelihood(model, fd_sim.recording, **kw)
    pop = _uniform(model, 20, 4)
    ref = _fused(lik, pop)
    assert np.array_equal(lik.batch(pop), ref)
    assert lik.neg_log_lik(pop[1]) == ref[1]


# --- values ---------------------------------------------------------------------------------
def test_uniform_population_matches_fused_kernel(segmented, fd_sim, model):
    lik = Likelihood(model, fd_sim.recording)
    assert lik.segmented
    pop = _uniform(model, 300, 5)
    _assert_close(lik.batch(pop), _fused(lik, pop))


@pytest.mark.parametrize("task", ["FD", "FT"])
def test_population_near_the_truth_matches_fused_kernel(segmented, fd_sim, ft_sim, model, task):
    sim = fd_sim if task == "FD" else ft_sim
    lik = Likelihood(model, sim.recording)
    x0 = model.free_vector(sim.params)
    pop = x0 * make_rng(6).uniform(0.95, 1.05, size=(200, model.n_free))
    _assert_close(lik.batch(pop), _fused(lik, pop))


def test_remnant_free_recording(segmented, model):
    """Without remnant (F_n = 0, as in a fifth of the paper's simulation study) fits near
    the truth are nearly perfect: the first pass's corrections cancel and the second
    pass (from the true start states) or the fused kernel takes over."""
    from bayespilot.simulate import simulate

    # 40.96 s: on this record most of these rows take the second pass (20 s: none)
    sim = simulate(model, task="FD", motion_gain=1.0, remnant_gain=0.0, seed=17, duration=40.96)
    lik = Likelihood(model, sim.recording)
    x0 = model.free_vector(sim.params)
    rng = make_rng(18)
    pop = np.vstack([x0, x0 * rng.uniform(0.995, 1.005, size=(40, model.n_free)),
                     x0 * rng.uniform(0.95, 1.05, size=(40, model.n_free))])
    _assert_close(lik.batch(pop), _fused(lik, pop))


def _special_rows(model, lik):
    names = model.parameter_names
    beyond = (lik.pad + 2) * lik.dt  # a delay beyond the fused path's padding
    inside = (lik.pad - 5) * lik.dt  # the longest delay the layout covers
    changes = [
        dict(zeta_nm=0.0), dict(zeta_nm=-0.3), dict(zeta_nm=-1e-6), dict(omega_nm=np.nan),
        dict(K_m=np.nan), dict(K_v=np.inf),
        dict(tau_v=beyond), dict(tau_m=beyond), dict(tau_v=-beyond),
        dict(tau_v=inside), dict(tau_m=inside), dict(tau_v=-inside + 1e-9),
        dict(tau_v=-0.3), dict(tau_m=-0.05), dict(tau_v=1.0), dict(tau_m=0.0),
        dict(delta_abs=10.0), dict(delta_abs=0.0), dict(delta_abs=-0.01),
        dict(delta_abs=np.nan), dict(delta_abs=np.inf),
        dict(K_v=0.0), dict(K_m=0.0), dict(K_v=0.0, K_m=0.0), dict(T_vl=0.0),
        dict(zeta_nm=1e-4), dict(zeta_nm=1e-4, omega_nm=30.0), dict(zeta_nm=5.0),
        dict(zeta_nm=1e3), dict(omega_nm=0.5), dict(omega_nm=200.0),
    ]
    rows = []
    for ch in changes:
        x = model.free_vector(FD)
        for k, val in ch.items():
            x[names.index(k)] = val
        rows.append(x)
    return np.array(rows), changes


def test_special_rows(segmented, fd_sim, model):
    lik = Likelihood(model, fd_sim.recording)
    rows, changes = _special_rows(model, lik)
    ref = _fused(lik, rows)
    got = lik.batch(rows)
    _assert_close(got, ref)
    assert np.isposinf(got[:6]).all()
    # rows the layout does not cover go to the fused kernel: the same bits
    exact = [i for i, ch in enumerate(changes)
             if any(k.startswith("tau") and abs(v) > lik.pad * lik.dt for k, v in ch.items())
             or ch.get("delta_abs", 0.0) < 0 or np.isnan(ch.get("delta_abs", 0.0))]
    assert len(exact) == 5
    assert np.array_equal(got[exact], ref[exact])


@pytest.mark.parametrize("warmup", [0.0, 0.01, 2.5, 2.51, 17.49, 20.0, 45.0])
def test_warmup_lengths(segmented, fd_sim, model, warmup):
    """Every position of the warm-up's start in a segment (the first step, the last, none)."""
    lik = Likelihood(model, fd_sim.recording, warmup=warmup)
    pop = np.vstack([model.free_vector(fd_sim.params), _uniform(model, 40, 8)])
    _assert_close(lik.batch(pop), _fused(lik, pop))


def test_threshold_free_and_reordered_models(segmented, fd_sim, model):
    """The model without threshold (dead zone fixed at 0) and the paper's model with its
    channels in the other order (the dead-zone channel first)."""
    rec = fd_sim.recording
    m7 = paper_model(threshold=False)
    lik7 = Likelihood(m7, rec)
    pop7 = _uniform(m7, 60, 9)
    _assert_close(lik7.batch(pop7), _fused(lik7, pop7))
    swapped = PilotModel(model.channels[::-1], model.parameters, name="swapped")
    liks = Likelihood(swapped, rec)
    assert liks.segmented
    pop = _uniform(model, 60, 10)
    got = liks.batch(pop)
    _assert_close(got, _fused(liks, pop))
    _assert_close(got, _fused(Likelihood(model, rec), pop))


def test_matches_naive(segmented, fd_sim, model):
    """Against the plain NumPy/SciPy twin (tests/naive.py), to its usual tolerance."""
    rec = fd_sim.recording
    lik = Likelihood(model, rec)
    rows = np.vstack([model.free_vector(fd_sim.params), _uniform(model, 8, 11)])
    got = lik.batch(rows)
    for x, g in zip(rows, got):
        params = model.as_dict(x)
        ref = naive.naive_neg_log_lik(params, rec.u, rec.e, rec.theta_ddot_m, rec.dt,
                                      "periodic", lik.warm, canal_output=lik.X[1])
        assert g == pytest.approx(ref, rel=1e-9, abs=0)


def test_perfect_fit(segmented, fd_sim, model):
    """u = the model's own response: the lane corrections cancel, the fused kernel decides."""
    rec = fd_sim.recording
    u_model = Likelihood(model, rec).response(FD)
    lik = Likelihood(model, _with_u(rec, u_model))
    x0 = model.free_vector(FD)
    rows = np.array([x0 * (1.0 + d) for d in (0.0, 1e-12, 1e-9, 1e-6, 1e-4, 1e-2, 1e-1)])
    got = lik.batch(rows)
    ref = _fused(lik, rows)
    assert np.all(np.isfinite(got))
    _assert_close(got, ref)
    assert np.array_equal(got[:3], ref[:3])  # recomputed by the fused kernel
    with pytest.warns(PerfectFitWarning):
        assert lik.neg_log_lik(x0) == got[0]


# --- determinism ----------------------------------------------------------------------------
def test_independent_of_threads_order_and_batch_size(segmented, fd_sim, model):
    lik = Likelihood(model, fd_sim.recording)
    rows, _ = _special_rows(model, lik)
    pop = np.vstack([_uniform(model, 50, 12), rows])
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = lik.batch(pop)
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        many = lik.batch(pop)
    finally:
        numba.set_num_threads(threads)
    assert np.array_equal(one, many)
    perm = make_rng(13).permutation(len(pop))
    assert np.array_equal(lik.batch(pop[perm]), one[perm])
    for size in (1, 5, 16, 17, 33):
        assert np.array_equal(lik.batch(pop[-size:]), one[-size:])
    fin = np.all(np.isfinite(pop), axis=1)
    assert np.array_equal([lik.neg_log_lik(x) for x in pop[fin]], one[fin])


# --- pieces ---------------------------------------------------------------------------------
def test_layout(fd_sim, model):
    lik = Likelihood(model, fd_sim.recording)
    lay = SEG.build_layout(lik.X, lik.u, 0, 1, lik.pad)
    n, S, H, L = lik.n, lay.S, lay.H, SEG.L
    assert S * L == n and H == lik.pad + SEG.HALO_EXTRA
    e, i = lik.X[0], lik.X[1]
    P = lay.P.reshape(S + 2 * H, L)
    Q = lay.Q.reshape(S + 2 * H, L)
    for r in (0, 1, H - 1, H, H + S - 1, S + 2 * H - 1):
        for lane in (0, 3, L - 1):
            k = lane * S + r - H
            assert P[r, lane] == e[k % n] + 2.0 * e[(k - 1) % n] + e[(k - 2) % n]
            assert Q[r, lane] == e[k % n] - e[(k - 2) % n]
            assert lay.I.reshape(S + 2 * H, L)[r, lane] == i[k % n]
    assert np.array_equal(lay.U.reshape(S, L).T.ravel(), lik.u)
    for a in (lay.P, lay.Q, lay.I, lay.U):
        assert a.ctypes.data % 64 == 0
    assert SEG.build_layout(lik.X[:, :-1], lik.u[:-1], 0, 1, lik.pad) is None


@numba.njit
def _clamp_both(x, d, out):
    for k in range(0, x.shape[0], _simd.W):
        vd = _simd.vbload(d, k)
        xv = _simd.vload(x, k)
        _simd.vstore(out, k, _simd.vsub(xv, _simd.vclamp_abs(xv, vd)))
        _simd.vstore(out, x.shape[0] + k, _simd.vsub(xv, _simd.vclamp_abs_minmax(xv, vd)))


def test_dead_zone_forms_agree():
    """VRANGEPD (where the target has AVX-512DQ) and compare-and-select give the dead zone
    of the fused kernel, sign(x) max(|x| - d, 0)."""
    rng = make_rng(14)
    x = np.concatenate([rng.normal(0, 0.05, 4000), [0.0, -0.0, 0.02, -0.02, 1e-300, -np.inf,
                                                    np.inf, 0.5, -0.5, 1e300, -1e300, 3.0]])
    x = x[: x.size // 8 * 8].copy()
    for d in (0.0, 0.02, 0.5, np.inf):
        dd = np.full(x.size, d)
        out = np.empty(2 * x.size)
        _clamp_both(x, dd, out)
        with np.errstate(invalid="ignore"):
            a = np.abs(x) - d
        ref = np.where(x >= 0, 1.0, -1.0) * np.where(a > 0, a, 0.0)
        fin = np.isfinite(x)
        assert np.array_equal(out[:x.size][fin], ref[fin])
        assert np.array_equal(out[x.size:][fin], ref[fin])


# --- the switch and the cache, in fresh processes -------------------------------------------
_SCRIPT = """
import numpy as np
from bayespilot.likelihood import Likelihood
from bayespilot.kernels import _segmented as SEG
from bayespilot.model import paper_model
from bayespilot.recording import Recording
d = np.load({data!r})
rec = Recording(dict(t=d["t"], e=d["e"], theta_ddot_m=d["tdm"], u=d["u"]), 100.0, 1.0, "FD")
lik = Likelihood(paper_model(), rec)
v = lik.batch(d["pop"])
lik.neg_log_lik(d["pop"][0])
fns = (SEG.neg_log_lik_segmented_batch, SEG.neg_log_lik_segmented_one)
hits = sum(sum(f.stats.cache_hits.values()) for f in fns)
misses = sum(sum(f.stats.cache_misses.values()) for f in fns)
print(SEG.ENABLED, lik.segmented, hits, misses, *[repr(float(x)) for x in v])
"""


def _run(tmp_path, rec, pop, env_extra):
    data = tmp_path / "data.npz"
    np.savez(data, t=rec.t, e=rec.e, tdm=rec.theta_ddot_m, u=rec.u, pop=pop)
    env = {k: v for k, v in os.environ.items() if k != "BAYESPILOT_KERNEL"}
    env.update(env_extra)
    env["PYTHONPATH"] = str(Path(SEG.__file__).parents[2]) + os.pathsep + env.get("PYTHONPATH", "")
    res = subprocess.run([sys.executable, "-c", _SCRIPT.format(data=str(data))], env=env,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    words = res.stdout.split()
    return words[0] == "True", words[1] == "True", int(words[2]), int(words[3]), \
        np.array([float(w) for w in words[4:]])


@pytest.mark.parametrize("choice", ["scalar", "segmented"])
def test_environment_switch_and_cache(tmp_path, fd_rec, model, choice):
    """``BAYESPILOT_KERNEL`` picks the kernel at import; with ``segmented`` a fresh process
    loads the compiled kernel from numba's cache (this process compiled it first)."""
    rec = fd_rec
    pop = _uniform(model, 20, 15)
    lik = Likelihood(model, rec)
    ref = _fused(lik, pop)
    if choice == "segmented":
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(SEG, "ENABLED", True)
            seg = Likelihood(model, rec)
            here = seg.batch(pop)  # compiles and caches, if not yet
            seg.neg_log_lik(pop[0])
    enabled, used, hits, misses, got = _run(tmp_path, rec, pop, {"BAYESPILOT_KERNEL": choice})
    if choice == "scalar":
        assert not enabled and not used
        assert np.array_equal(got, ref)
    else:
        assert enabled and used
        assert np.array_equal(got, here)
        assert hits >= 2 and misses == 0


def _features_without(prefixes: tuple[str, ...]) -> str:
    import llvmlite.binding as llvm

    feats = llvm.get_host_cpu_features()
    for k in list(feats):
        if k.startswith(prefixes):
            feats[k] = False
    return feats.flatten()


_X86 = __import__("platform").machine().lower() in ("x86_64", "amd64")


@pytest.mark.slow
@pytest.mark.skipif(not (_X86 and {"avx2", "fma"} <= _simd.target_features()),
                    reason="needs an x86-64 host with AVX2 and FMA")
def test_without_avx512(tmp_path, fd_rec, model):
    """Compiled for an AVX2 CPU (no AVX-512: the vectors split over two registers, the dead
    zone by compare-and-select), the segmented kernel is still chosen and gives the AVX-512
    build's values to the bit (each lane does the same IEEE operations); compiled for the
    x86-64 baseline (no AVX2, no FMA) the fused scalar kernel is chosen.  The first run
    compiles the kernels for the AVX2 target (about 40 s), later runs load them from cache."""
    rec = fd_rec
    pop = np.vstack([_uniform(model, 30, 16), model.free_vector(FD)])
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(SEG, "ENABLED", True)
        here = Likelihood(model, rec).batch(pop)
    avx2 = {"NUMBA_CPU_NAME": "haswell",
            "NUMBA_CPU_FEATURES": _features_without(("avx512", "amx", "avx10", "evex512"))}
    enabled, used, _, _, got = _run(tmp_path, rec, pop, avx2)
    assert enabled and used
    assert np.array_equal(got, here)
    _assert_close(got, _fused(Likelihood(model, rec), pop))
    base = dict(os.environ, NUMBA_CPU_NAME="x86-64",
                NUMBA_CPU_FEATURES="+64bit,+cx8,+fxsr,+mmx,+sse,+sse2")
    base.pop("BAYESPILOT_KERNEL", None)
    res = subprocess.run([sys.executable, "-c", "from bayespilot.kernels import _segmented as S; "
                          "print(S.AVAILABLE, S.ENABLED)"], env=base, capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["False", "False"]

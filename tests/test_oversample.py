"""Channels run at M times the recording's rate (``Channel.oversample``, ``kernels/_oversample.py``).

References: a slow NumPy/SciPy twin written from the definition (the canal
output interpolated linearly to M points per interval, the dead zone and the
delay there by ``np.interp``, -K_m H_nm by ``scipy.signal.bilinear`` at
dt / M and ``lfilter``, every M-th sample kept); central differences for the
Jacobians; the 1x kernels; and the twin at M = 64 as the continuous-time limit.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

import naive
from bayespilot import presets
from bayespilot.likelihood import Likelihood
from bayespilot.model import (MAX_OVERSAMPLE, Channel, LinearDrift, Parameter, SoftDeadZone,
                              Washout, paper_model)

FD = dict(presets.TABLE3["FD"])


def twin_motion(p, i, dt, M, initial, warm):
    """The vestibular channel's share of u_hat at M times the rate, from the definition.

    Periodic: the fine record wraps, and the fine H_nm recursion starts from
    zero state where the package's starts (M warm-up samples before
    ``warm`` recording samples before the end), reading the wrapped input.
    Rest: everything is zero before t = -dt, the canal output ramps from 0 at
    t = -dt to i[0] at t = 0, and the recursion starts from zero at t = 0.
    """
    n = i.size
    nf = n * M
    tf = np.arange(nf) * dt / M
    w, z = p["omega_nm"], p["zeta_nm"]
    b, a = signal.bilinear([-p["K_m"] * w * w], [1.0, 2 * z * w, w * w], fs=M / dt)
    if initial == "periodic":
        i_f = np.interp(tf, np.arange(n) * dt, i, period=n * dt)
        d_f = np.interp(tf - p["tau_m"], tf, naive.dead_zone(i_f, p["delta_abs"]), period=n * dt)
        start = (warm + 1) * M - 1  # fine samples of warm-up
        idx = np.arange(-start - 2, nf)
        fir = signal.lfilter(b, [1.0], np.take(d_f, idx, mode="wrap"))[2:]
        return signal.lfilter([1.0], a, fir)[start:][::M]
    t_ext = np.arange(-M, nf) * dt / M
    i_ext = np.interp(t_ext, np.r_[-dt, np.arange(n) * dt], np.r_[0.0, i])
    d_f = np.interp(tf - p["tau_m"], t_ext, naive.dead_zone(i_ext, p["delta_abs"]), left=0.0)
    return signal.lfilter(b, a, d_f)[::M]


@pytest.mark.parametrize("M", [2, 8])
@pytest.mark.parametrize("initial", ["periodic", "rest"])
@pytest.mark.parametrize("case", ["table3", "large_threshold", "short_delay"])
def test_response_matches_twin(fd_rec, M, initial, case):
    p = {"table3": FD, "large_threshold": dict(FD, delta_abs=0.03, tau_m=0.4567),
         "short_delay": dict(FD, tau_m=0.0234, delta_abs=0.004)}[case]
    # warmed up over the whole record: the kernel's scalar recursion and the twin's fine one
    # start from rest in different states, and 20 s leave e^-58 of that
    lik = Likelihood(paper_model(oversample=M), fd_rec, initial=initial, warmup=fd_rec.duration)
    coarse = Likelihood(paper_model(), fd_rec, initial=initial, warmup=fd_rec.duration)
    visual = coarse.response(dict(p, K_m=0.0))  # the 1x visual channel, unchanged
    ref = visual + twin_motion(p, lik.X[1], fd_rec.dt, M, initial, lik.warm)
    got = lik.response(p)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    # and it is not the 1x model: the dead zone's corners are resolved
    assert np.abs(got - coarse.response(p)).max() > 1e-4 * np.abs(ref).max()


def test_converges_to_the_continuous_limit(fd_rec):
    """The motion channel at M = 8 is 20x closer than at 1x to the twin at M = 64."""
    p = FD
    lik = Likelihood(paper_model(), fd_rec)
    limit = twin_motion(p, lik.X[1], fd_rec.dt, 64, "periodic", lik.warm)
    err = {}
    for M in (1, 2, 4, 8):
        motion = (Likelihood(paper_model(oversample=M), fd_rec).response(p)
                  - lik.response(dict(p, K_m=0.0)))
        err[M] = np.sqrt(np.mean((motion - limit) ** 2))
    assert err[1] > err[2] > err[4] > err[8]
    assert err[8] < err[1] / 20, err


def test_one_is_the_paper_computation(fd_rec):
    """oversample=1 is the model as before: same plan, same kernel, same values to the bit."""
    a = Likelihood(paper_model(), fd_rec)
    b = Likelihood(paper_model(oversample=1), fd_rec)
    assert b.segmented == a.segmented
    rows = np.array([list(FD.values()), list(dict(FD, delta_abs=0.02).values())])
    assert np.array_equal(a.batch(rows), b.batch(rows))
    assert paper_model().with_oversampling(1).name == paper_model().name


def test_batch_equals_single_to_the_bit(fd_rec):
    m = paper_model(oversample=4)
    lik = Likelihood(m, fd_rec)
    assert not lik.segmented
    rng = np.random.default_rng(3)
    rows = m.free_vector(FD) * (1 + 0.1 * rng.standard_normal((9, m.n_free)))
    rows[:, -1] = np.abs(rows[:, -1])
    single = np.array([lik.neg_log_lik(r) for r in rows])
    assert np.array_equal(lik.batch(rows), single)
    assert np.all(np.isfinite(single))


def _central_differences(lik, p, names, rel=1e-5):
    cols = []
    for name in names:
        h = rel * max(abs(p[name]), 1e-2)
        cols.append((lik.response(dict(p, **{name: p[name] + h}))
                     - lik.response(dict(p, **{name: p[name] - h}))) / (2 * h))
    return np.column_stack(cols)


@pytest.mark.parametrize("initial", ["periodic", "rest"])
@pytest.mark.parametrize("variant", ["paper", "washout", "soft", "drift"])
def test_jacobian_matches_central_differences(fd_rec, initial, variant):
    m = paper_model()
    p = dict(FD, tau_v=0.2834, tau_m=0.1977)
    if variant == "washout":
        m = m.add_stage("vestibular", Washout(), [Parameter("omega_w", 0.01, 10, 0.3)])
        p["omega_w"] = 0.3
    elif variant == "soft":
        m = m.with_nonlinearity("vestibular", SoftDeadZone(),
                                [Parameter("w_soft", 1e-4, 0.05, 0.002)])
        p["w_soft"] = 0.002
    elif variant == "drift":
        m = m.with_modulation("vestibular", LinearDrift(), [Parameter("drift", -1, 1, 0.0)])
        p["drift"] = 0.3
    m = m.with_oversampling(4, ["vestibular"])
    lik = Likelihood(m, fd_rec, initial=initial)
    y, J = lik.jacobian(p)
    np.testing.assert_allclose(y, lik.response(p), rtol=0, atol=1e-12 * np.abs(y).max())
    fd = _central_differences(lik, p, m.parameter_names)
    for j, name in enumerate(m.parameter_names):
        scale = np.abs(fd[:, j]).max()
        assert np.abs(J[:, j] - fd[:, j]).max() < 2e-5 * scale, name


def test_oversampled_fit_jacobian_through_noise_model(fd_sim):
    """The coloured likelihood and its whitened Jacobian run on the oversampled response."""
    from bayespilot.noise import ARNoise

    m = paper_model(oversample=4)
    base = Likelihood(m, fd_sim.recording)
    noise = ARNoise.from_residual(base.residual(fd_sim.params), order=4)
    lik = Likelihood(m, fd_sim.recording, noise=noise)
    r = lik.fit_residual(fd_sim.params)
    np.testing.assert_allclose(r, noise.whiten(base.residual(fd_sim.params)), rtol=1e-12)
    J = lik.fit_jacobian(fd_sim.params, ["K_m", "delta_abs"])
    np.testing.assert_allclose(J, -noise.whiten(base.jacobian(fd_sim.params, ["K_m", "delta_abs"])[1]),
                               rtol=1e-12, atol=1e-15)


def test_bad_oversampling_is_refused():
    for bad in (0, MAX_OVERSAMPLE + 1, 2.5, True, "8"):
        with pytest.raises(ValueError, match="oversample must be an integer"):
            Channel("c", "e", delay="tau_v", oversample=bad)
    with pytest.raises(ValueError, match="oversample must be an integer"):
        paper_model(oversample=0)
    with pytest.raises(KeyError, match="no channel 'motion'"):
        paper_model().with_oversampling(4, ["motion"])
    linear = paper_model().with_nonlinearity("vestibular", None)
    with pytest.raises(ValueError, match="no channel has a nonlinearity"):
        linear.with_oversampling(4)


def test_summary_and_default_channels():
    m = paper_model().with_oversampling(8)
    assert [c.oversample for c in m.channels] == [1, 8]  # only the dead-zone channel
    assert "[8x the rate]" in m.summary()
    assert paper_model(threshold=False, oversample=8).channels[1].oversample == 8


def test_cli_oversample(tmp_path, capsys):
    """``--oversample M`` prints the oversampled model's -ln L; a bad M is a usage error."""
    import json

    from bayespilot.cli import main
    from bayespilot.io import read_recording

    assert main(["simulate", "--task", "FD", "--motion-gain", "1", "--remnant-fraction", "0.2",
                 "--seed", "4", "--duration", "10", "-o", str(tmp_path / "run"), "-q"]) == 0
    pfile = tmp_path / "p.json"
    pfile.write_text(json.dumps(FD))
    capsys.readouterr()
    assert main(["loglik", str(tmp_path / "run"), "--params", str(pfile), "--oversample", "8",
                 "-q"]) == 0
    out = capsys.readouterr().out
    rec = read_recording(tmp_path / "run")
    # (10 s is not whole forcing periods: loglik leaves the first 2 s out, as the fitters do)
    assert float(out.split("=")[1]) == Likelihood(paper_model(oversample=8), rec,
                                                  discard=2.0).neg_log_lik(FD)
    for bad, msg in (("0", "must be >= 1"), ("65", "must be <= 64"), ("2.5", "whole number")):
        assert main(["loglik", str(tmp_path / "run"), "--params", str(pfile),
                     "--oversample", bad]) == 2
        assert msg in capsys.readouterr().err


def test_diagnose_refuses_bad_oversample(fd_rec):
    from bayespilot.diagnose import diagnose

    with pytest.raises(ValueError, match="oversample must be an integer"):
        diagnose(fd_rec, oversample=0)

"""The decision likelihood's low-pass and the report's residual spectrum at sample rates other
than the paper's 100 Hz: the same response in Hz (rad/s) at every rate, and at 100 Hz exactly
what they were with the fixed 61 taps and 1024-sample Welch segments."""

from __future__ import annotations

import math
import types

import numpy as np
import pytest
from scipy import signal

from bayespilot import presets
from bayespilot.diagnose import DiagnosisResult
from bayespilot.diagnose import decide as D
from bayespilot.diagnose import report as R
from bayespilot.likelihood import Likelihood
from bayespilot.model import paper_model
from bayespilot.noise import MAX_AR_ORDER, fit_ar
from bayespilot.simulate import simulate

F_C = D.OMEGA_C / (2 * np.pi)  # the low-pass's cut-off, Hz


def _gain_db(taps: np.ndarray, f_hz, fs: float) -> np.ndarray:
    _, H = signal.freqz(taps, worN=np.atleast_1d(np.asarray(f_hz, float)), fs=fs)
    return 20 * np.log10(np.abs(H))


@pytest.mark.parametrize("fs", [50.0, 100.0, 200.0, 250.0, 1000.0])
def test_decision_low_pass_stops_twice_the_cut_off_at_every_rate(fs):
    fir, decim = D._lowpass(D.OMEGA_C, fs)
    # 0.6 s of taps from 100 Hz up; below, the 61 taps (a narrower transition than at 100 Hz)
    assert fir.size % 2 == 1 and fir.size == max(61, 2 * round(0.3 * fs) + 1)
    # what noise_model builds is this filter
    eps = np.random.default_rng(0).standard_normal(int(30 * fs))
    nm = D.noise_model(eps, 1.0 / fs, order=0)
    np.testing.assert_array_equal(nm.fir, fir)
    assert nm.decimation == decim and nm.to_dict()["fir_taps"] == fir.size
    # -63 dB at 100 Hz; the fixed 61 taps gave -27 dB at 200 Hz and -1.6 dB at 1 kHz
    assert _gain_db(fir, 2 * F_C, fs)[0] < -50.0
    # and everything that the decimation folds into the kept band is stopped
    nyq = fs / decim / 2
    f = np.linspace(nyq, fs / 2, 20001)
    assert _gain_db(fir, f, fs).max() < -50.0
    if fs < 100.0:
        np.testing.assert_array_equal(fir, signal.firwin(61, F_C, fs=fs))  # unchanged
    else:
        # the response in Hz is the 100-Hz filter's (to 0.002 in gain, from 0 to 2 omega_c)
        f = np.linspace(0.0, 2 * F_C, 400)
        ref = signal.freqz(D._lowpass(D.OMEGA_C, 100.0)[0], worN=f, fs=100.0)[1]
        np.testing.assert_allclose(np.abs(signal.freqz(fir, worN=f, fs=fs)[1]), np.abs(ref),
                                   atol=2e-3)


@pytest.mark.parametrize("fs, old_db", [(200.0, -27.0), (1000.0, -1.6)])
def test_low_pass_stops_where_the_old_61_tap_filter_failed(fs, old_db):
    """The regression: the fixed 61 taps at 200 Hz and 1 kHz barely low-pass at 2 omega_c
    (-27 dB, -1.6 dB); the filter noise_model builds now stops it by more than 50 dB."""
    old = signal.firwin(61, F_C, fs=fs)
    assert _gain_db(old, 2 * F_C, fs)[0] == pytest.approx(old_db, abs=0.5)
    nm = D.noise_model(np.random.default_rng(0).standard_normal(int(30 * fs)), 1.0 / fs, order=0)
    assert nm.fir.size > old.size
    assert _gain_db(nm.fir, 2 * F_C, fs)[0] < -50.0


def test_low_pass_at_100_hz_is_the_61_tap_filter_exactly():
    fir, decim = D._lowpass(D.OMEGA_C, 100.0)
    np.testing.assert_array_equal(fir, signal.firwin(61, F_C, fs=100.0))
    assert decim == 5
    fir, decim = D._lowpass(math.inf, 100.0)
    np.testing.assert_array_equal(fir, np.ones(1))
    assert decim == 1


def test_decision_likelihood_at_100_hz_is_unchanged_bit_for_bit():
    """On a 100-Hz recording the noise model, the reduced residual and the GLS -ln L equal a
    direct reimplementation of the former fixed 61-tap path, exactly."""
    rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=1,
                   duration=20.0).recording
    assert rec.sample_rate_hz == 100.0
    model = paper_model()
    truth = presets.paper_parameters("FD")
    lik = Likelihood(model, rec)
    eps = lik.residual(truth)
    skip = 300
    noise = D.noise_model(eps, rec.dt, skip=skip)

    # the former path, written out
    fs = 1.0 / rec.dt
    fir = signal.firwin(61, F_C, fs=fs)
    decim = max(1, int(math.floor(fs / (2.0 * 2.5 * F_C))))

    def reduce_old(x):
        return signal.lfilter(fir, [1.0], x, axis=0)[skip::decim]

    red = reduce_old(eps)
    ar = fit_ar(red, max_order=min(MAX_AR_ORDER, red.size // 5))
    np.testing.assert_array_equal(noise.fir, fir)
    assert noise.decimation == decim == 5
    np.testing.assert_array_equal(noise.reduce(eps), red)
    np.testing.assert_array_equal(noise.ar, ar)

    def nll_old(params):
        red = reduce_old(rec.u - lik.response(params))
        w = signal.lfilter(np.concatenate([[1.0], -ar]), [1.0], red, axis=0)[ar.size:]
        m = w.size
        return 0.5 * m * math.log(max(float(np.mean(w * w)), 1e-300)) + 0.5 * m

    wl = D.Whitened(model, rec, noise)
    for p in (truth, dict(truth, K_m=0.5, tau_m=0.21)):
        assert wl.neg_log_lik(p) == nll_old(p)


def test_white_residual_at_1khz_is_not_aliased_by_the_decimation():
    """A white residual at 1 kHz, low-passed and decimated by 50 (to 20 Hz): its spectrum above
    2 omega_c stays more than 40 dB below the pass band; with 61 taps it came through at the
    pass band's level (the whole 0-50 Hz folded in)."""
    fs = 1000.0
    rng = np.random.default_rng(3)
    eps = rng.standard_normal(int(120 * fs))
    skip = int(5 * fs)
    nm = D.noise_model(eps, 1.0 / fs, skip=skip, order=0)
    assert nm.decimation == 50 and nm.fir.size == 601
    fs_red = fs / nm.decimation

    def stop_over_pass_db(red):
        f, P = signal.welch(red, fs=fs_red, nperseg=256)
        w = 2 * np.pi * f
        stop = P[w >= 2 * D.OMEGA_C].mean()
        pas = P[(w > 0) & (w <= 0.5 * D.OMEGA_C)].mean()
        return 10 * math.log10(stop / pas)

    new = stop_over_pass_db(nm.reduce(eps))
    old = stop_over_pass_db(signal.lfilter(signal.firwin(61, F_C, fs=fs), [1.0],
                                           eps)[skip::nm.decimation])
    assert new < -40.0
    assert old > -10.0
    # the same as at 100 Hz
    eps100 = rng.standard_normal(int(120 * 100))
    nm100 = D.noise_model(eps100, 0.01, skip=500, order=0)
    assert abs(stop_over_pass_db(nm100.reduce(eps100)) - new) < 6.0


def _fake_result(fs: float, duration: float = 60.0, with_dt: bool = True) -> DiagnosisResult:
    x = np.random.default_rng(1).standard_normal(int(duration * fs))
    settings = {"skip_seconds": 5.0}
    if with_dt:
        settings["dt"] = 1.0 / fs
    return DiagnosisResult(False, "none", [], {}, {}, None, settings, 0.0,
                           arrays={"residual": x})


def _spectrum_line(result, **kw):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import warnings

    with warnings.catch_warnings():
        # the fake result has no conditioned panels, so no legend there
        warnings.filterwarnings("ignore", message="No artists with labels")
        fig = R.plot_residuals(result, **kw)
    try:
        line = fig.axes[0].get_lines()[0]
        return np.asarray(line.get_xdata()), np.asarray(line.get_ydata())
    finally:
        plt.close(fig)


def test_residual_spectrum_starts_at_the_same_frequency_at_100_hz_and_1_khz():
    w100, P100 = _spectrum_line(_fake_result(100.0))
    w1k, _ = _spectrum_line(_fake_result(1000.0))
    lowest = 2 * np.pi / 10.24
    assert w100[0] == pytest.approx(lowest, rel=1e-9)
    assert w1k[0] == pytest.approx(lowest, rel=1e-9)  # was 2 pi / 1.024 = 6.1 rad/s
    # at 100 Hz exactly the former 1024-sample Welch estimate, as a density per rad/s (its
    # per-Hz density over 2 pi), up to twice the decision's cut-off (the band it uses)
    from bayespilot.diagnose.decide import OMEGA_C

    x = _fake_result(100.0).arrays["residual"][500:]
    f, P = signal.welch(x, fs=100.0, nperseg=1024)
    keep = 2 * np.pi * f[1:] <= 2 * OMEGA_C
    np.testing.assert_array_equal(w100, 2 * np.pi * f[1:][keep])
    np.testing.assert_allclose(P100, P[1:][keep] / (2 * np.pi), rtol=1e-12)
    assert w1k[-1] == pytest.approx(w100[-1], rel=1e-9)


def test_residual_spectrum_segment_is_capped_at_the_record():
    """A record shorter than 10.24 s after the skip: one segment of the whole of it (no
    warning)."""
    import warnings

    res = _fake_result(1000.0, duration=12.0)  # 7 s after the skip
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        w, _ = _spectrum_line(res)
    assert not [c for c in caught if "nperseg" in str(c.message)]
    assert w[0] == pytest.approx(2 * np.pi / 7.0, rel=1e-9)


def test_residual_spectrum_sample_interval_comes_from_the_recording():
    res = _fake_result(1000.0, with_dt=False)
    with pytest.raises(ValueError, match="sample interval"):
        _spectrum_line(res)
    w, P = _spectrum_line(res, recording=types.SimpleNamespace(dt=1e-3))
    assert w[0] == pytest.approx(2 * np.pi / 10.24, rel=1e-9)
    # the density at the recording's rate (1 kHz: a 10240-sample Welch segment), not 0.01's
    f, P1k = signal.welch(res.arrays["residual"][5000:], fs=1000.0, nperseg=10240)
    np.testing.assert_allclose(P, P1k[1:w.size + 1] / (2 * np.pi), rtol=1e-12)

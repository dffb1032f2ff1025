"""The AR output-error model (bayespilot.noise) against scipy.signal and known processes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from conftest import make_rng
from bayespilot.noise import ARNoise, fit_ar


def _ar_process(a, n, seed):
    """x_k = sum_j a_j x_{k-j} + w_k, w ~ N(0, 1), by scipy.signal.lfilter (burn-in dropped)."""
    w = make_rng(seed).standard_normal(n + 2000)
    return signal.lfilter([1.0], np.r_[1.0, -np.asarray(a)], w)[2000:], w[2000:]


def test_fit_ar_recovers_known_coefficients_and_order():
    a = [1.5, -0.9, 0.3]
    x, _ = _ar_process(a, 40000, 1)
    est = fit_ar(x)  # order by BIC
    assert est.size == 3
    # least-squares AR estimates have standard error ~ 1/sqrt(n) = 0.005 here
    np.testing.assert_allclose(est, a, atol=0.03)
    np.testing.assert_allclose(fit_ar(x, order=3), est, atol=1e-3)  # same fit, 27 fewer rows


def test_whitening_recovers_the_innovations():
    a = [1.2, -0.5]
    x, w = _ar_process(a, 5000, 2)
    got = ARNoise(a).whiten(x)
    np.testing.assert_allclose(got, w[2:], rtol=0, atol=1e-10)
    # on columns, as for a Jacobian
    X = np.column_stack([x, 2 * x])
    np.testing.assert_allclose(ARNoise(a).whiten(X)[:, 1], 2 * got, rtol=1e-12)


def test_from_residual_round_trip_and_errors():
    x, _ = _ar_process([0.8], 4000, 3)
    noise = ARNoise.from_residual(x, order=1)
    assert noise.order == 1 and abs(noise.a[0] - 0.8) < 0.05
    back = ARNoise.from_dict(noise.to_dict())
    np.testing.assert_array_equal(back.a, noise.a)
    with pytest.raises(ValueError, match="not an AR noise model"):
        ARNoise.from_dict({"kind": "white"})
    with pytest.raises(ValueError, match="finite 1-D"):
        fit_ar(np.array([1.0, np.inf, 2.0]))
    with pytest.raises(ValueError, match="an AR.20. model needs at least 84 samples, got 40$"):
        fit_ar(x[:40], order=20)
    # (an empty series and the default orders said "AR order must be in [0, -1]")
    with pytest.raises(ValueError, match="x is empty"):
        fit_ar(np.zeros(0))
    with pytest.raises(ValueError, match=r"AR.30. model needs at least 124 samples, got 10 "
                                         r"\(give a smaller max_order\)"):
        fit_ar(x[:10])
    with pytest.raises(ValueError, match="AR order must be >= 0, got -1"):
        fit_ar(x, order=-1)
    with pytest.raises(ValueError, match="more than 3 samples"):
        ARNoise([0.1, 0.1, 0.1]).whiten(np.ones(3))
    # orders are integers, at least one is tried; coefficients are a 1-D sequence; a stored
    # order agrees with its coefficients
    with pytest.raises(ValueError, match="max_order must be >= 1"):
        fit_ar(x, max_order=0)
    for bad in (2.7, "3", True):
        with pytest.raises(ValueError, match="order must be an integer"):
            fit_ar(x, order=bad)
    assert fit_ar(x, order=np.int64(1)).shape == (1,)
    with pytest.raises(ValueError, match="1-D"):
        ARNoise([[0.5, 0.1], [0.2, 0.3]])
    with pytest.raises(ValueError, match="order 2 with 1 coefficients"):
        ARNoise.from_dict({"kind": "ar", "order": 2, "a": [0.5]})


def test_fit_fast_refuses_a_record_too_short_for_the_ar_model(monkeypatch, tmp_path, capsys):
    """Audit: 'fit --method fast --noise ar' on a 1.6-s record ended in "unexpected ValueError:
    an AR(30) model needs at least 124 samples ... please report it".  It is a RecordingError
    (bad input: exit 2, one line) raised before any fitting, naming the shortest record."""
    import bayespilot.fit.fast as F
    from bayespilot.cli import main
    from bayespilot.recording import RecordingError
    from bayespilot.simulate import simulate

    def no_fit(*a, **k):
        raise AssertionError("fitting started")

    rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=3,
                   duration=1.6).recording
    with monkeypatch.context() as m:
        m.setattr(F, "refine", no_fit)
        # 160 samples, the first 0.4 s (a quarter) left out: 120 < 4 (30 + 1) = 124; 165
        # samples keep 165 - 41 = 124
        with pytest.raises(RecordingError, match=r"^simulation\(seed=3\): 1\.6 s, 120 samples "
                           r"after the first 0\.4 s; an AR noise model of order up to 30 \(chosen by "
                           r"BIC\) needs at least 124 there, a record of at least 1\.65 s$"):
            F.fit_fast(rec, noise="ar", seed=0)
        # (half the record, the most a discard may be)
        with pytest.raises(RecordingError, match=r"80 samples after the first 0\.8 s; an AR\(30\) "
                           r"noise model needs at least 124 there, a record of at least 2\.04 s "
                           r"with the first 0\.8 s left out$"):
            F.fit_fast(rec, noise="ar", noise_order=30, discard=0.8, seed=0)
        # an order the record holds (4 (20 + 1) = 84 <= 120) passes the check and is fitted
        with pytest.raises(AssertionError, match="fitting started"):
            F.fit_fast(rec, noise="ar", noise_order=20, seed=0)
    assert main(["simulate", "--task", "FD", "--seed", "3", "--duration", "1.6", "-o",
                 str(tmp_path / "short"), "-q"]) == 0
    capsys.readouterr()
    code = main(["fit", str(tmp_path / "short"), "--method", "fast", "--noise", "ar", "-q"])
    err = capsys.readouterr().err
    assert code == 2
    errors = [line for line in err.splitlines() if "error" in line]
    assert errors == [f"bayespilot: error: {tmp_path / 'short'}: 1.6 s, 120 samples after the "
                      "first 0.4 s; an AR noise model of order up to 30 (chosen by BIC) needs at "
                      "least 124 there, a record of at least 1.65 s"]

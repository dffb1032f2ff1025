"""Tests of bayespilot.diagnose.calibrate: the bootstrap calibration of a candidate's test, its
p-value against scipy.stats, a replicate's statistic retraced by hand, and the decision that
gives way when the chosen candidate fails its calibrated test."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats

from bayespilot import presets
from bayespilot.diagnose import SKIP_SECONDS, _calibrated_decision, _prepare, diagnose
from bayespilot.diagnose import decide as D
from bayespilot.diagnose import get_extension
from bayespilot.diagnose import locate as L
from bayespilot.diagnose.calibrate import Calibration, calibrate_candidate, reference_mean
from bayespilot.fit.fast import fit_fast
from bayespilot.model import paper_model
from bayespilot.simulate import simulate


class _Silent:
    def set_postfix_str(self, *a, **k):
        pass

    def update(self, *a, **k):
        pass


def test_reference_means_are_the_asymptotic_nulls():
    # 0.5 chi2(0) + 0.5 chi2(1) halved: 0.25; chi2(2) halved: 1
    for name in ("motion-washout", "motion-system-dynamics", "threshold-shape"):
        assert reference_mean(get_extension(name)) == 0.25
    for name in ("time-varying-gains", "otolith-channel"):
        assert reference_mean(get_extension(name)) == 1.0
    with pytest.raises(ValueError, match="GLS"):
        calibrate_candidate(get_extension("control-saturation"), [], [], 1.0)


@pytest.fixture(scope="module")
def control_run():
    rec = simulate(task="FD", motion_gain=1.0, remnant_gain=0.063, seed=31,
                   duration=30.0).recording
    run = _prepare(rec, seed=0, n_bootstrap=0, base_fit=None, skip_seconds=SKIP_SECONDS,
                   omega_c=None, n_starts=2, profile_noise=False, bar=_Silent())
    return rec, run


def test_calibration_of_a_washout_on_a_control(control_run):
    rec, run = control_run
    ext = get_extension("motion-washout")
    for runs, recs in (([run], [rec, rec]), ([run, run], [rec]), ([], [])):
        with pytest.raises(ValueError, match="one recording per run"):
            calibrate_candidate(ext, runs, recs, 1.0, n_replicates=1)
    d = 1.3  # an observed improvement to calibrate (the test's input, not this run's)
    cal = calibrate_candidate(ext, [run], [rec], d, n_replicates=4, seed=5, n_starts=2)
    assert isinstance(cal, Calibration) and cal.replicates == 4
    assert cal.null_mean == pytest.approx(cal.statistics.mean())
    assert cal.scale == pytest.approx(cal.statistics.mean() / 0.25)
    # the chi-bar-squared p-value at 2 d / max(1, c), from scipy.stats directly
    c = max(1.0, cal.scale)
    assert cal.p_nominal == pytest.approx(0.5 * stats.chi2.sf(2 * d, 1))
    assert cal.p_value == pytest.approx(0.5 * stats.chi2.sf(2 * d / c, 1))
    assert cal.p_empirical == pytest.approx((1 + np.sum(cal.statistics >= d)) / 5)
    assert json.loads(json.dumps(cal.to_dict()))["replicates"] == 4


def _replicate0(run, rec, seed=9):
    """Replicate 0 of a calibration seeded ``seed``: the base model at the run's GLS fit
    simulated with the run's remnant level and colour."""
    K_n, T_n = L.remnant_like(run.lik0.residual(run.base.params)[run.skip:], rec.dt)
    seed0 = int(np.random.SeedSequence(seed).generate_state(1)[0])
    rep = simulate(run.base_model, run.base.params, task=L.task_of(rec, run.forcing),
                   remnant_gain=K_n, T_n=T_n, seed=seed0, oversample=10).recording
    return rep, seed0


def _statistic_by_hand(run, rep, seed0, ext, passes=1):
    """The candidate's d(-ln L) on a replicate, step by step: the Eq. 4 fit, ``passes`` times
    the noise model and the GLS base fit, the extension's fit, the base refitted from it."""
    from bayespilot.likelihood import Likelihood

    fit = fit_fast(rep, run.base_model, seed=seed0, n_starts=2, profile_step=0.005, discard=0.0)
    at = {k: v for k, v in fit.params.items() if k in run.base_model.parameter_names}
    for _ in range(passes):
        noise = D.noise_model(Likelihood(run.base_model, rep).residual(at), rep.dt,
                              skip=run.skip)
        _, base = D.fit_base_gls(run.base_model, rep, at, noise)
        at = base.params
    res, _ = D.fit_candidate(ext, run.base_model, rep, base, noise)
    null = D.null_refit(ext, run.base_model, rep, res, noise)
    ref = min(base.neg_log_lik, null.neg_log_lik)
    return max(0.0, ref - res.fit.neg_log_lik)


def test_a_replicates_statistic_retraced_by_hand(control_run):
    """Replicate 0: the base model at the run's GLS fit simulated with the run's remnant level
    and colour, then the Eq. 4 fit, the noise model from its residual, the GLS base fit, the
    extension's fit and the base model refitted from it, step by step."""
    rec, run = control_run
    ext = get_extension("time-varying-gains")
    cal = calibrate_candidate(ext, [run], [rec], 0.0, n_replicates=1, seed=9, n_starts=2)
    rep, seed0 = _replicate0(run, rec)
    # the replicate has the recording's forcing and a remnant of the residual's level
    np.testing.assert_allclose(rep.signals["f_t"], rec.signals["f_t"], atol=1e-9)
    from bayespilot.likelihood import Likelihood

    eps = Likelihood(run.base_model, rep).residual(run.base.params)
    assert np.std(eps[run.skip:]) == pytest.approx(
        np.std(run.lik0.residual(run.base.params)[run.skip:]), rel=0.3)
    assert cal.statistics[0] == pytest.approx(_statistic_by_hand(run, rep, seed0, ext), abs=1e-8)
    # seeded: the same seed, the same replicates; another seed, others
    again = calibrate_candidate(ext, [run], [rec], 0.0, n_replicates=2, seed=9, n_starts=2)
    assert again.statistics[0] == cal.statistics[0]
    other = calibrate_candidate(ext, [run], [rec], 0.0, n_replicates=2, seed=10, n_starts=2)
    assert not np.any(np.isin(other.statistics, again.statistics))


def test_a_second_noise_pass_and_its_calibration_retraced_by_hand(control_run):
    """noise_passes=2: the AR model again from the GLS base fit's residual, the GLS fit again;
    a calibration replicate of that run makes the same two passes."""
    rec, run = control_run
    run2 = _prepare(rec, seed=0, n_bootstrap=0, base_fit=run.base_fit,
                    skip_seconds=SKIP_SECONDS, omega_c=None, n_starts=2, profile_noise=False,
                    bar=_Silent(), noise_passes=2)
    assert run2.noise_passes == 2
    noise = D.noise_model(run.lik0.residual(run.base.params), rec.dt, skip=run.skip)
    _, base = D.fit_base_gls(run.base_model, rec, run.base.params, noise)
    np.testing.assert_array_equal(run2.noise.ar, noise.ar)
    assert run2.base.neg_log_lik == base.neg_log_lik
    # the second pass is not the first: another AR model, another -ln L
    assert run2.noise.ar.shape != run.noise.ar.shape or \
        np.max(np.abs(run2.noise.ar - run.noise.ar)) > 1e-6
    assert run2.base.neg_log_lik != run.base.neg_log_lik
    # replicate 0 of its calibration, by hand with two passes
    ext = get_extension("time-varying-gains")
    cal = calibrate_candidate(ext, [run2], [rec], 0.0, n_replicates=1, seed=9, n_starts=2)
    rep, seed0 = _replicate0(run2, rec)
    assert cal.statistics[0] == pytest.approx(
        _statistic_by_hand(run2, rep, seed0, ext, passes=2), abs=1e-8)


def test_diagnose_passes_noise_passes_on(control_run):
    rec, run = control_run
    res = diagnose(rec, n_bootstrap=0, base_fit=run.base_fit, n_starts=2,
                   candidates=["motion-washout"], noise_passes=2)
    assert res.settings["noise_passes"] == 2
    noise = D.noise_model(run.lik0.residual(run.base.params), rec.dt, skip=run.skip)
    _, base = D.fit_base_gls(run.base_model, rec, run.base.params, noise)
    assert res.settings["noise_model"]["ar_order"] == noise.ar.size
    # the GLS base fit under the second pass's noise model (no candidate's fit found a better
    # base fit here, so it is the reported one), not the first pass's
    assert res.settings["rebased"] == []
    assert res.base["gls_neg_log_lik"] == pytest.approx(base.neg_log_lik, abs=1e-8)
    assert abs(run.base.neg_log_lik - base.neg_log_lik) > 0.1


@pytest.mark.parametrize("bad", [0, 6, True, 1.5])
def test_bad_noise_passes_are_refused(control_run, bad):
    rec, _ = control_run
    with pytest.raises(ValueError, match="noise_passes"):
        diagnose(rec, n_bootstrap=0, noise_passes=bad)


def _result(name, p, bf):
    ext = get_extension(name)
    r = D.CandidateResult(name, True, "", 5.0, 10.0, ext.df, p, 2 * bf, bf)
    return r


def test_a_choice_that_fails_calibration_gives_way():
    wash = _result("motion-washout", 1e-5, 10.0)
    drift = _result("time-varying-gains", 1e-4, 5.0)
    plat = _result("motion-system-dynamics", 0.5, -3.0)
    asked = []

    def cal(res, p):
        return Calibration(res.physics, 39, 1.0, 0.25, 4.0, res.p_value, p, 0.025,
                           np.zeros(39))

    def calibrate(res):
        asked.append(res.physics)
        return cal(res, {"motion-washout": 0.01, "time-varying-gains": 2e-4}[res.physics])

    ranking, chosen, tested, level = _calibrated_decision([wash, drift, plat], 0.01, calibrate)
    assert level == pytest.approx(0.01 / 3)
    assert asked == ["motion-washout", "time-varying-gains"]
    assert chosen is drift and ranking[0] is drift
    assert not wash.justified and wash.p_value == 0.01 and wash.calibration.scale == 4.0
    assert drift.justified and drift.p_value == 2e-4
    assert plat.calibration is None
    # every choice failing: none; no calibration possible: the asymptotic test stands
    for r in (wash, drift):
        r.p_value, r.calibration = 1e-5, None
    _, chosen, _, _ = _calibrated_decision([wash, drift, plat], 0.01, lambda r: cal(r, 0.5))
    assert chosen is None and not wash.justified and not drift.justified
    wash.p_value = drift.p_value = 1e-5
    _, chosen, _, _ = _calibrated_decision([wash, drift, plat], 0.01, lambda r: None)
    assert chosen is wash and wash.p_value == 1e-5


def test_diagnose_calibrates_a_strong_washout(tmp_path):
    model = get_extension("motion-washout").build(paper_model())
    p = dict(presets.paper_parameters("FD"), omega_w=0.8)
    rec = simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063, seed=22,
                   duration=40.96).recording
    res = diagnose(rec, seed=0, n_bootstrap=0, n_starts=2, n_calibrate=3,
                   candidates=["motion-washout", "time-varying-gains"])
    assert res.physics == "motion-washout"
    cal = res.chosen.calibration
    assert cal.replicates == 3
    assert res.chosen.p_value == cal.p_value < res.settings["level_per_candidate"]
    # the asymptotic (chi-bar-squared) p-value of the observed improvement, and the
    # calibrated one at the statistic over max(1, scale), from scipy.stats directly
    d = res.chosen.delta_neg_log_lik
    assert cal.p_nominal == pytest.approx(0.5 * stats.chi2.sf(2 * d, 1), rel=1e-9)
    assert cal.p_value == pytest.approx(
        0.5 * stats.chi2.sf(2 * d / max(1.0, cal.scale), 1), rel=1e-9)
    # the replicates are of the base model: well below the washout's improvement (10.9)
    assert cal.statistics.max() < 0.5 * res.chosen.delta_neg_log_lik
    d = json.loads(res.to_json())
    assert d["ranking"][0]["calibration"]["replicates"] == 3
    assert d["settings"]["n_calibrate"] == 3
    assert "calibrated by 3 replicates" in res.summary()
    page = res.report(tmp_path)["html"].read_text()
    assert "<p>motion-washout: test calibrated by 3 replicates" in page
    for bad in (-1, True, 2.5):
        with pytest.raises(ValueError, match="n_calibrate"):
            diagnose(rec, n_calibrate=bad)
    with pytest.raises(ValueError, match="profile_noise"):
        diagnose(rec, n_calibrate=3, profile_noise=True)
    assert math.isfinite(res.settings["timings"]["calibrate"])

"""Tests of bayespilot.diagnose.profile: the profile-likelihood intervals of the chosen
extension's new parameters against constrained refits made by a plain loop, the Wald interval
where the profile is quadratic, a bound, and a fit that is not the maximum."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats

from bayespilot import presets
from bayespilot.diagnose import decide as D
from bayespilot.diagnose import diagnose, get_extension
from bayespilot.diagnose.profile import BETTER_TOL, profile_interval, profile_intervals
from bayespilot.model import paper_model
from bayespilot.simulate import simulate

Q90 = stats.chi2.ppf(0.9, 1)


def _case(entry, truth, seed, duration):
    model = get_extension(entry).build(paper_model())
    p = dict(presets.paper_parameters("FD"), **truth)
    rec = simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063, seed=seed,
                   duration=duration).recording
    res = diagnose(rec, seed=0, n_bootstrap=0, n_starts=2, candidates=[entry])
    c = res.ranking[0]
    if c.refit is None:  # not chosen: reported the same way, as analyses/ checks it
        D.report_final_fit(c, res.base_model, rec, res.arrays["noise"])
    return rec, res, c


@pytest.fixture(scope="module")
def washout():
    return _case("motion-washout", {"omega_w": 0.8}, 22, 40.96)


def _held_deviance(c, rec, name, value, scan):
    """2 d(-ln L) x scale at ``name`` = ``value``: every other refined parameter refitted by
    the plain route (GLS refine, then a delta_abs scan), from the reported fit."""
    wl = D.Whitened(c.model, rec, c.noise)
    held = tuple(n for n in c.fit.refined if n != name)
    f = D._gls_refine(wl, dict(c.fit.params, **{name: value}), held)
    if scan:
        f = D.scan_threshold(wl, f, held)
    return 2 * (f.neg_log_lik - c.fit.neg_log_lik) * c.interval[name].scale


def test_profile_interval_ends_where_the_deviance_reaches_the_chi2_quantile(washout):
    rec, res, c = washout
    assert res.physics == "motion-washout"
    iv = c.interval["omega_w"]
    est, se = c.params["omega_w"], c.stderr["omega_w"]
    assert iv.lower < est < iv.upper and not (iv.lower_open or iv.upper_open)
    # the scale makes a quadratic profile give the reported Wald interval
    own = c.refit["own_stderr"]["omega_w"]
    assert iv.scale == pytest.approx(min(1.0, (own / se) ** 2))
    assert iv.lower == pytest.approx(est - 1.645 * se, abs=0.25 * se)
    assert iv.upper == pytest.approx(est + 1.645 * se, abs=0.25 * se)
    # at each end, a constrained refit made here reaches the chi2_1 90 % quantile
    for end in (iv.lower, iv.upper):
        assert _held_deviance(c, rec, "omega_w", end, scan=True) == pytest.approx(Q90, abs=0.4)
    # every point of the profile inside the level lies in the interval (the hull)
    inside = iv.values[iv.deviance <= Q90]
    assert np.all((inside >= iv.lower) & (inside <= iv.upper))
    # reported: JSON, summary
    d = json.loads(res.to_json())["chosen"]["interval"]["omega_w"]
    assert d["lower"] == pytest.approx(iv.lower) and d["level"] == 0.9
    assert "90 % profile-likelihood interval" in res.summary()


def test_profile_interval_closed_at_a_bound():
    """A soft threshold fitted at its corner width's upper bound (0.05 IPUT): the interval
    runs to the bound and is closed there; below, it ends where the deviance reaches the
    quantile."""
    rec, res, c = _case("threshold-shape", {"w_soft": 0.045}, 40_003, 81.92)
    iv = c.interval["w_soft"]
    upper = c.model.parameter("w_soft").upper
    assert c.params["w_soft"] == pytest.approx(upper, rel=1e-6)
    assert iv.upper == upper and not iv.upper_open
    assert 0.0 < iv.lower < upper and not iv.lower_open
    assert _held_deviance(c, rec, "w_soft", iv.lower, scan=False) == pytest.approx(Q90, abs=0.5)


def test_profile_finds_a_better_fit_than_the_one_it_is_given(washout):
    """Given a fit that is not the maximum (omega_w held 4 s.e. above it, the rest refitted),
    the profile reaches the maximum and the fit is made again from there."""
    rec, res, c = washout
    wl = D.Whitened(c.model, rec, c.noise)
    names = c.fit.refined
    se = c.stderr["omega_w"]
    off = D._gls_refine(wl, dict(c.fit.params, omega_w=c.params["omega_w"] + 4 * se),
                        tuple(n for n in names if n != "omega_w"))
    off = D.FitSummary(off.params, off.neg_log_lik, names, np.diag(np.full(len(names), 1e-4)))
    fit, ivs = profile_intervals(wl, off, ["omega_w"], names, scan=True,
                                 test_stderr=c.stderr)
    assert fit.neg_log_lik < off.neg_log_lik - BETTER_TOL
    assert fit.params["omega_w"] == pytest.approx(c.params["omega_w"], abs=0.2 * se)
    assert ivs["omega_w"].lower < fit.params["omega_w"] < ivs["omega_w"].upper


@pytest.mark.parametrize("kw, match", [({"level": 1.5}, "level"), ({"step": 0.0}, "step"),
                                       ({"step": math.nan}, "step"), ({"scale": 2.0}, "scale"),
                                       ({"name": "omega_ms"}, "refined parameters")])
def test_profile_interval_rejects_bad_settings(washout, kw, match):
    rec, res, c = washout
    wl = D.Whitened(c.model, rec, c.noise)
    args = dict(name="omega_w", scan=True, step=0.01, scale=1.0, level=0.9)
    args.update(kw)
    with pytest.raises(ValueError, match=match):
        profile_interval(wl, c.fit, names=c.fit.refined, **args)
    with pytest.raises(TypeError, match="Whitened"):
        profile_interval(None, c.fit, "omega_w", c.fit.refined, scan=True, step=0.01)


def test_profile_without_the_tests_standard_error_is_unscaled(washout):
    """Without a standard error from the test the deviance is not scaled: the interval ends
    where the unscaled deviance reaches the quantile, about as wide as the fit's own Wald
    interval (the profile is not quite quadratic)."""
    rec, res, c = washout
    wl = D.Whitened(c.model, rec, c.noise)
    fit, ivs = profile_intervals(wl, c.fit, ["omega_w"], c.fit.refined, scan=True,
                                 test_stderr={})
    iv, own = ivs["omega_w"], c.refit["own_stderr"]["omega_w"]
    assert iv.scale == 1.0 and fit is c.fit
    assert iv.upper - iv.lower == pytest.approx(2 * 1.645 * own, rel=0.2)
    scaled = c.interval["omega_w"]
    for end in (iv.lower, iv.upper):
        d = _held_deviance(c, rec, "omega_w", end, scan=True) / scaled.scale
        assert d == pytest.approx(Q90, abs=0.4)
    with pytest.raises(ValueError, match="max_restarts"):
        profile_intervals(wl, c.fit, ["omega_w"], c.fit.refined, scan=True, test_stderr={},
                          max_restarts=-1)


def test_intervals_reach_the_report_and_the_batch_summary(washout, tmp_path):
    from bayespilot.diagnose.batch import DiagnoseTask, batch_summary_rows

    rec, res, c = washout
    paths = res.report(tmp_path / "rep")
    assert paths["profile"].stat().st_size > 0
    assert "Profile likelihood of the new parameters" in paths["html"].read_text()
    task = DiagnoseTask("run", ("run",), None, "FD", 1.0)
    (row,) = batch_summary_rows([task], tmp_path, {"run": res.to_dict()})
    iv = c.interval["omega_w"]
    assert json.loads(row["interval"]) == {"omega_w": [iv.lower, iv.upper]}
    # without the profile: no interval anywhere, and no figure
    again = diagnose(rec, seed=0, n_bootstrap=0, n_starts=2, candidates=["motion-washout"],
                     intervals=False)
    assert again.chosen.interval == {} and again.to_dict()["chosen"]["interval"] == {}
    assert "profile" not in again.report(tmp_path / "rep2")
    from bayespilot.diagnose.report import plot_profile
    with pytest.raises(ValueError, match="no profile intervals"):
        plot_profile(again)
    # here the profile found no better fit: the same reported estimate either way
    assert again.chosen.params["omega_w"] == pytest.approx(c.params["omega_w"], rel=1e-9)

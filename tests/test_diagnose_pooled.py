"""Tests of bayespilot.diagnose.diagnose_pooled: the pooled fit against a slow profile over the
shared parameter (each run fitted on its own at fixed values), and decisions on simulated runs."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats

from bayespilot import presets
from bayespilot.diagnose import PooledDiagnosisResult, diagnose_pooled, get_extension
from bayespilot.diagnose import decide as D
from bayespilot.model import paper_model
from bayespilot.simulate import simulate


def _runs(omega_w, seeds):
    if omega_w is None:
        model, p = paper_model(), presets.paper_parameters("FD")
    else:
        model = get_extension("motion-washout").build(paper_model())
        p = dict(presets.paper_parameters("FD"), omega_w=omega_w)
    return [simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063, seed=s,
                     duration=40.96).recording for s in seeds]


@pytest.fixture(scope="module")
def washout_runs():
    return _runs(0.4, (41, 42))


@pytest.fixture(scope="module")
def washout_result(washout_runs):
    return diagnose_pooled(washout_runs, seed=0, n_bootstrap=0, n_starts=2, n_calibrate=3,
                           candidates=["motion-washout", "time-varying-gains"])


@pytest.fixture(scope="module")
def washout_posterior(washout_runs, washout_result):
    """shared_posterior of the washout diagnosis on 11 grid points (computed once: two tests
    read it), kept on the result as its posterior."""
    from bayespilot.diagnose import shared_posterior

    post = shared_posterior(washout_result, washout_runs, n_grid=11)
    assert washout_result.posterior is post
    return post


def test_pooled_reports_the_fit_with_each_runs_own_noise_model(washout_runs, washout_result):
    """The reported pooled fit (pooled_final_fit): each run's delta_abs at the minimum of a
    plain grid scan of its own GLS likelihood (the run's own noise model, the other
    parameters at the reported fit), and the pooled -ln L recomputed from the runs' own
    likelihoods; the test's fit stays beside it and in arrays["fits"]."""
    res = washout_result
    c = res.chosen
    assert c.physics == "motion-washout" and c.refit is not None and len(c.noise) == 2
    assert c.refit["test_params"]["omega_w"] == res.arrays["fits"]["motion-washout"][0]["omega_w"]
    assert c.params["omega_w"] == pytest.approx(0.4, abs=2.5 * c.stderr["omega_w"])
    total = 0.0
    for rec, run, nz in zip(washout_runs, res.runs, c.noise):
        q = run["params"]
        assert q["omega_w"] == c.params["omega_w"]
        wl = D.Whitened(c.model, rec, nz)
        total += wl.neg_log_lik(q)
        grid = np.arange(0.0, c.model.parameter("delta_abs").upper + 2.5e-4, 5e-4)
        best = min(grid, key=lambda d: wl.neg_log_lik(dict(q, delta_abs=float(d))))
        assert abs(q["delta_abs"] - best) <= 5e-4 + 1e-12
    assert total == pytest.approx(c.refit["neg_log_lik"], abs=1e-6)
    assert res.to_dict()["chosen"]["refit"]["delta_abs"][1] == [r["params"]["delta_abs"]
                                                               for r in res.runs]
    assert "each run's delta_abs" in res.summary()
    from bayespilot.diagnose.pooled import pooled_final_fit
    fits = res.arrays["fits"]["motion-washout"]
    with pytest.raises(ValueError, match="one parameter set and one noise model per recording"):
        pooled_final_fit(get_extension("motion-washout"), res.arrays["base_model"],
                         washout_runs, fits[:1], res.arrays["noise"])
    with pytest.raises(ValueError, match="rounds"):
        pooled_final_fit(get_extension("motion-washout"), res.arrays["base_model"],
                         washout_runs, fits, res.arrays["noise"], rounds=0)
    with pytest.raises(ValueError, match="fitted by GLS"):
        D.final_fit(get_extension("control-saturation"), res.arrays["base_model"],
                    washout_runs[0], None, res.arrays["noise"][0])
    # the pooled fit takes a catalogue Extension as final_fit does, not anything that says "gls"
    import types
    for ext in (get_extension("control-saturation"), types.SimpleNamespace(likelihood="gls")):
        with pytest.raises(ValueError, match="fitted by GLS"):
            pooled_final_fit(ext, res.arrays["base_model"], washout_runs, fits,
                             res.arrays["noise"])
    with pytest.raises(TypeError, match="NoiseModel"):
        D.own_noise(c.model, washout_runs[0], fits[0], "ar2")


def test_pooled_rejects_bad_input(washout_runs):
    with pytest.raises(ValueError, match="at least two"):
        diagnose_pooled(washout_runs[:1])
    with pytest.raises(TypeError, match="Recording"):
        diagnose_pooled([washout_runs[0], washout_runs[1].u])
    with pytest.raises(ValueError, match="unknown extension"):
        diagnose_pooled(washout_runs, candidates=["gravity"])
    with pytest.raises(ValueError, match="names an entry twice"):
        diagnose_pooled(washout_runs, candidates=["motion-washout"] * 2)
    # the same run twice, even under another name, would count its evidence twice
    from bayespilot.recording import Recording

    r0 = washout_runs[0]
    alias = Recording(dict(r0.signals), r0.sample_rate_hz, r0.motion_gain, r0.task,
                      dict(r0.metadata), "elsewhere.csv")
    with pytest.raises(ValueError, match="runs 1 and 3 .* are the same recording"):
        diagnose_pooled([r0, washout_runs[1], alias])
    with pytest.raises(ValueError, match="noise_passes"):
        diagnose_pooled(washout_runs, noise_passes=0)


def test_pooled_passes_noise_passes_to_every_run(washout_runs, monkeypatch):
    from bayespilot.diagnose import pooled as P

    seen = []

    class Stop(Exception):
        pass

    def fake(rec, **kw):
        seen.append(kw["noise_passes"])
        if len(seen) == len(washout_runs):
            raise Stop
        return None

    monkeypatch.setattr(P, "_prepare", fake)
    with pytest.raises(Stop):
        diagnose_pooled(washout_runs, noise_passes=2)
    assert seen == [2, 2]


def test_pooled_warns_when_the_runs_say_they_differ(washout_runs, monkeypatch):
    """Runs whose metadata give other subjects or K_theta are pooled with a PoolingWarning."""
    import warnings

    from bayespilot.diagnose import pooled as P
    from bayespilot.recording import Recording

    class Stop(Exception):
        pass

    def stop(rec, **kw):
        raise Stop

    monkeypatch.setattr(P, "_prepare", stop)

    def relabel(rec, subject, k=None):
        return Recording(rec.signals, rec.sample_rate_hz,
                         rec.motion_gain if k is None else k, rec.task, {"subject": subject})

    a, b = washout_runs
    with pytest.warns(P.PoolingWarning, match=r"subject s1, s2; K_theta 0.75, 1\)"):
        with pytest.raises(Stop):
            diagnose_pooled([relabel(a, "s1"), relabel(b, "s2", 0.75)])
    with warnings.catch_warnings():
        warnings.simplefilter("error", P.PoolingWarning)
        with pytest.raises(Stop):  # one subject (or none said): no warning
            diagnose_pooled([relabel(a, "s1"), relabel(b, "s1")])
        with pytest.raises(Stop):
            diagnose_pooled(washout_runs)


def test_pooled_names_a_shared_washout(washout_result):
    res = washout_result
    assert isinstance(res, PooledDiagnosisResult)
    assert res.physics == "motion-washout" and res.mismatch
    assert res.chosen.params["omega_w"] == pytest.approx(0.4, rel=0.35)
    assert 0 < res.chosen.stderr["omega_w"] < 0.2
    # every run gains at the shared value (a real omission, not one run's artefact)
    shares = [r["delta_neg_log_lik"]["motion-washout"] for r in res.runs]
    assert len(shares) == 2 and min(shares) > 0
    assert sum(shares) == pytest.approx(res.chosen.delta_neg_log_lik, abs=1e-6)
    # its test calibrated by replicates of both runs' base models, refitted together
    cal = res.chosen.calibration
    assert cal.replicates == 3 and res.chosen.p_value == cal.p_value
    d = res.chosen.delta_neg_log_lik  # chi-bar-squared, nominal and at 2 d / max(1, scale)
    assert cal.p_nominal == pytest.approx(0.5 * stats.chi2.sf(2 * d, 1), rel=1e-9)
    assert cal.p_value == pytest.approx(
        0.5 * stats.chi2.sf(2 * d / max(1.0, cal.scale), 1), rel=1e-9)
    assert cal.statistics.max() < 0.5 * res.chosen.delta_neg_log_lik
    assert "calibrated by 3 replicates" in res.summary()
    d = json.loads(res.to_json())
    assert d["pooled"] is True and d["n_runs"] == 2 and d["physics"] == "motion-washout"
    assert {"physics", "delta_neg_log_lik", "p_value", "params"} <= set(d["ranking"][0])
    assert d["units"]["omega_w"] == "rad/s" and d["units"]["tau_m"] == "s"
    assert "rad/s" in next(line for line in res.summary().splitlines()
                           if line.strip().startswith("omega_w"))


def test_pooled_fit_matches_a_profile_over_the_shared_parameter(washout_runs, washout_result):
    """Slow reference: at fixed omega_w, fit each run on its own (its noise model as pooled
    uses it) and add their -ln L; the pooled optimum is the minimum of that profile."""
    res = washout_result
    ext = get_extension("motion-washout")
    model = ext.build(paper_model())
    base_total = sum(run["base"]["gls_neg_log_lik"] for run in res.runs)
    # rebuild each run's noise model exactly as diagnose_pooled did (same code path)
    from bayespilot.diagnose import SKIP_SECONDS, _base_gls

    whitened = []
    for rec, run in zip(washout_runs, res.runs):
        start = {k: v for k, v in run["base"]["params"].items()
                 if k in paper_model().parameter_names}
        _, noise, base = _base_gls(rec, paper_model(), start,
                                   skip=int(round(SKIP_SECONDS * rec.sample_rate_hz)))
        # the reported base is the best fit found (a refit from a candidate's fit can only
        # improve it; here by a hair)
        assert run["base"]["gls_neg_log_lik"] <= base.neg_log_lik + 1e-9
        assert base.neg_log_lik == pytest.approx(run["base"]["gls_neg_log_lik"], abs=0.01)
        # the samples its Eq. 4 -ln L is over, as a single diagnosis's base says them
        assert (run["base"]["discard_seconds"], run["base"]["n"]) == (0.0, rec.n_samples)
        whitened.append((D.Whitened(model, rec, noise), base))
    names = tuple(n for n in model.parameter_names if n not in ("omega_w", "delta_abs"))
    grid = np.array([0.25, 0.3, 0.35, 0.4, 0.45, 0.5, 0.6])
    profile = []
    for w in grid:
        tot = 0.0
        for wl, base in whitened:
            tot += D._gls_refine(wl, dict(base.params, omega_w=float(w)), names).neg_log_lik
        profile.append(tot)
    profile = np.array(profile)
    pooled = base_total - res.chosen.delta_neg_log_lik
    # the pooled fit is no worse than any point of the profile (small optimiser slack) ...
    assert pooled <= profile.min() + 0.05
    # ... and its shared omega_w sits where the profile is within 0.5 of its minimum
    near = grid[profile <= profile.min() + 0.5]
    assert near.min() - 0.05 <= res.chosen.params["omega_w"] <= near.max() + 0.05


def test_pooled_controls_say_none_and_report(tmp_path, monkeypatch):
    res = diagnose_pooled(_runs(None, (43, 44)), seed=0, n_bootstrap=0, n_starts=2,
                          candidates=["motion-washout", "otolith-channel", "control-saturation"])
    assert res.physics == "none" and not res.mismatch
    assert "2 runs pooled" in res.summary()
    # every GLS test is against the runs' final base fits (after any refit from a candidate)
    ref = sum(r["base"]["gls_neg_log_lik"] for r in res.runs)
    for c in res.ranking:
        if c.physics in ("motion-washout", "otolith-channel"):
            assert c.delta_neg_log_lik == pytest.approx(max(0.0, ref - c.fit.neg_log_lik),
                                                        abs=1e-9)
    paths = res.report(tmp_path / "rep", formats=("svg",))
    for key in ("candidates", "runs", "json", "html"):
        assert paths[key].stat().st_size > 0
    assert "data:image/png;base64," in paths["html"].read_text()
    # the vector copies beside the PNGs, listed, and nothing else
    assert paths["runs_svg"] == tmp_path / "rep" / "runs.svg" and "<text" in paths[
        "runs_svg"].read_text(encoding="utf-8")
    assert set((tmp_path / "rep").iterdir()) == set(paths.values())
    with pytest.raises(ValueError, match="formats"):
        res.report(tmp_path / "rep", formats=("jpeg",))
    # a full disk at the second figure of another report in the folder: the earlier page and
    # diagnosis.json are removed, not left to disagree with the new figure, and it is said
    from test_disk_full import _fail_at

    _fail_at(monkeypatch, 2)
    with pytest.raises(OSError, match=r"No space left on device; the report in .* is "
                                      r"incomplete, without report.html"):
        res.report(tmp_path / "rep")  # (its first figure replaced: the folder changed)
    left = {p.name for p in (tmp_path / "rep").iterdir()}
    assert "report.html" not in left and "diagnosis.json" not in left and "candidates.png" in left


def test_pooled_whole_band_starts_from_the_low_band_fit(monkeypatch):
    """On the whole band the pooled fit of each extension also starts from its pooled fit on the
    low-passed band (pooled._pooled_guide): a 6-rad/s platform shared by two runs is named there,
    and without that start the fit stops in a local optimum of the delays and misses it."""
    import math

    from bayespilot.diagnose import pooled as P

    model = get_extension("motion-system-dynamics").build(paper_model())
    p = dict(presets.paper_parameters("FD"), omega_ms=6.0)
    recs = [simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063, seed=s,
                     duration=40.96).recording for s in (25, 26)]
    kw = dict(seed=0, n_bootstrap=0, n_starts=2, omega_c=math.inf, oversample=8,
              candidates=["motion-system-dynamics"], n_calibrate=0)
    res = diagnose_pooled(recs, **kw)
    assert res.physics == "motion-system-dynamics"
    assert res.chosen.params["omega_ms"] == pytest.approx(6.0, rel=0.25)
    assert res.chosen.p_value < 1e-6
    monkeypatch.setattr(P, "_pooled_guide", lambda *a: None)
    alone = diagnose_pooled(recs, **kw)
    assert alone.ranking[0].delta_neg_log_lik < res.chosen.delta_neg_log_lik - 10


def _fd_hessian(f, x, rel=1e-3):
    """Central-difference Hessian of a scalar function (plain NumPy)."""
    x = np.asarray(x, float)
    h = rel * np.maximum(np.abs(x), 0.05)
    n = x.size
    H = np.empty((n, n))
    f0 = f(x)
    for i in range(n):
        for j in range(i, n):
            if i == j:
                e = np.zeros(n)
                e[i] = h[i]
                H[i, i] = (f(x + e) - 2 * f0 + f(x - e)) / h[i] ** 2
            else:
                ei, ej = np.zeros(n), np.zeros(n)
                ei[i], ej[j] = h[i], h[j]
                H[i, j] = H[j, i] = (f(x + ei + ej) - f(x + ei - ej) - f(x - ei + ej)
                                     + f(x - ei - ej)) / (4 * h[i] * h[j])
    return H


def test_shared_posterior_is_the_laplace_marginal_of_the_pooled_likelihood(
        washout_runs, washout_result, washout_posterior, tmp_path):
    """Reference: at three grid values of omega_w, each run's pilot parameters refitted on its
    own and integrated out with a central-difference Hessian of its GLS -ln L (not the
    Gauss-Newton one the module uses); the log density's differences must agree."""
    from bayespilot.diagnose import shared_posterior

    res = washout_result
    post = washout_posterior  # (the result's posterior: the fixture's first user)
    assert res.posterior is post and post.names == ("omega_w",)
    from bayespilot.diagnose.report import plot_shared_posterior

    fig = plot_shared_posterior(post)  # a density over omega_w (rad/s) is in s/rad
    assert fig.axes[0].get_ylabel() == "posterior density (s/rad)"
    g, logp = post.grid[0], post.log_density
    model = res.chosen.model
    names = tuple(n for n in model.parameter_names if n not in ("omega_w", "delta_abs"))
    wls = [D.Whitened(model, rec, nz) for rec, nz in zip(washout_runs, res.arrays["noise"])]

    # each run's delta_abs held at the reported fit's (refitted after the test with the run's
    # own noise model), the rest of the likelihood the test's
    held = [q["delta_abs"] for q in res.arrays["final_fits"]]
    assert post.settings["delta_abs"]["runs"] == held
    assert held != [q["delta_abs"] for q in res.arrays["fits"]["motion-washout"]]

    def reference(w):
        total = 0.0
        for wl, q, d in zip(wls, res.arrays["fits"]["motion-washout"], held):
            fit = D._gls_refine(wl, dict(q, omega_w=float(w), delta_abs=d), names)
            x0 = np.array([fit.params[n] for n in names])

            def f(x, fit=fit, wl=wl):
                return wl.neg_log_lik(dict(fit.params, **dict(zip(names, x))))

            sign, ld = np.linalg.slogdet(_fd_hessian(f, x0))
            assert sign > 0
            total += -fit.neg_log_lik - 0.5 * ld
        return total

    k0 = int(np.argmax(logp))
    pts = [k for k in (k0 - 3, k0, k0 + 3) if 0 <= k < g.size]
    assert len(pts) >= 2
    ref = {k: reference(g[k]) for k in pts}
    for k in pts:  # (measured: within 0.003 of each other, 5-7 units from the mode)
        assert logp[k] - logp[k0] == pytest.approx(ref[k] - ref[k0], abs=0.02)
    # the Bayes factor: the reference's three values fitted by a parabola in omega_w, integrated
    # in closed form (a Gaussian) over the prior box, against each run's base model refitted on
    # its own and integrated out with the central-difference Hessian
    assert len(pts) == 3
    c2, c1, c0 = np.polyfit(g[pts], [ref[k] for k in pts], 2)
    assert c2 < 0
    log_int = c0 - c1 ** 2 / (4 * c2) + 0.5 * math.log(math.pi / -c2)
    base_model = res.arrays["base_model"]
    base_ref = 0.0
    for rec, nz, run in zip(washout_runs, res.arrays["noise"], res.runs):
        wl = D.Whitened(base_model, rec, nz)
        fit = D._gls_refine(wl, dict(run["base"]["gls_params"]), names)
        x0 = np.array([fit.params[n] for n in names])
        sign, ld = np.linalg.slogdet(_fd_hessian(
            lambda x, fit=fit, wl=wl: wl.neg_log_lik(dict(fit.params, **dict(zip(names, x)))),
            x0))
        base_ref += -fit.neg_log_lik - 0.5 * ld
    width = model.parameter("omega_w").upper - model.parameter("omega_w").lower
    lbf_ref = log_int - math.log(width) - base_ref
    assert post.log_bayes_factor == pytest.approx(lbf_ref, abs=0.15)  # (measured: 15.42, 15.54)
    # the best ln L on the grid is the pooled fit's under the grid's likelihood, a grid step's
    # quadratic drop at most, against the base model refitted here; with the reported fit's
    # delta_abs the extended model fits the test's noise models better than in the test
    bf = post.settings["bayes_factor"]
    gain_ml = -post.settings["pooled_fit_neg_log_lik"] - bf["base_log_lik"]
    assert 0 <= gain_ml - bf["gain"] < 0.3
    assert bf["gain"] > res.chosen.delta_neg_log_lik  # (measured: 19.78 against 19.06)
    assert not bf["volume_driven"]
    # the Schwarz approximation is a few units off, both decisive
    assert post.log_bayes_factor > 5 and res.chosen.log_bayes_factor > 5
    # a near-Gaussian posterior: its spread is the pooled fit's standard error, its centre the fit
    m = post.marginals["omega_w"]
    assert m["sd"] == pytest.approx(res.chosen.stderr["omega_w"], rel=0.3)
    assert m["interval"][0] < res.chosen.params["omega_w"] < m["interval"][1]
    assert m["interval"][0] < 0.4 < m["interval"][1] and post.edge_mass < 0.01
    # JSON, summary and report carry it
    d = json.loads(res.to_json())
    assert d["posterior"]["marginals"]["omega_w"]["median"] == pytest.approx(m["median"])
    assert d["posterior"]["log_bayes_factor"] == pytest.approx(post.log_bayes_factor)
    assert "posterior of the shared parameters" in res.summary()
    assert "ln BF (motion-washout : none)" in res.summary()
    paths = res.report(tmp_path / "rep")
    assert paths["posterior"].stat().st_size > 0
    # refusals: another number of recordings, the runs in another order
    with pytest.raises(ValueError, match="2 runs"):
        shared_posterior(res, washout_runs[:1])
    with pytest.raises(ValueError, match="not the recordings"):
        shared_posterior(res, washout_runs[::-1])
    with pytest.raises(TypeError, match="got one Recording"):
        shared_posterior(res, washout_runs[0])
    with pytest.raises(ValueError, match="width"):
        shared_posterior(res, washout_runs, width=True)
    # a grid too narrow (+-2 standard errors, where the density has fallen by about 2) is
    # moved out by its span on both sides: +-6, the default grid again (moved out once more
    # on its lower side, where the skewed density has not fallen enough), the same density
    narrow = shared_posterior(res, washout_runs, n_grid=11, width=2.0)
    assert post.settings["widened"] == ["omega_w lower to 0.02"]
    assert narrow.settings["widened"][:2] == ["omega_w lower to 0.134701",
                                             "omega_w upper to 0.595183"]
    assert narrow.settings["widened"][2:] == post.settings["widened"]
    np.testing.assert_allclose(narrow.grid[0], g, rtol=1e-9)
    np.testing.assert_allclose(narrow.log_density, logp, atol=1e-6)
    assert narrow.log_bayes_factor == pytest.approx(post.log_bayes_factor, abs=1e-6)
    # a candidate not chosen: the drifts improve -ln L by about 1 for two parameters, so the
    # runs speak against them (measured: -2.9 on this 5 x 5 grid; Schwarz -6.1)
    drift = next(c for c in res.ranking if c.physics == "time-varying-gains")
    assert 0 < drift.delta_neg_log_lik < 3
    other = shared_posterior(res, washout_runs, physics="time-varying-gains", n_grid=5)
    assert other.names == ("drift_v", "drift_m") and res.posterior is other
    assert -8 < other.log_bayes_factor < -1 and drift.log_bayes_factor < -1
    for bad in ("otolith-channel", "control-saturation"):
        with pytest.raises(ValueError, match="no pooled GLS fit"):
            shared_posterior(res, washout_runs, physics=bad)


def test_shared_posterior_of_two_shared_parameters():
    """Two shared drifts on a 5 x 5 grid: near-Gaussian, so each marginal's sd is the pooled
    fit's standard error and its central 90 % interval the fit +- 1.645 of them; a grid too
    coarse is refused."""
    from bayespilot.diagnose import shared_posterior

    model = get_extension("time-varying-gains").build(paper_model())
    p = dict(presets.paper_parameters("FD"), drift_v=0.6, drift_m=0.3)
    recs = [simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063, seed=s,
                     duration=40.96).recording for s in (5, 6)]
    res = diagnose_pooled(recs, seed=0, n_bootstrap=0, n_starts=2,
                          candidates=["time-varying-gains"])
    assert res.physics == "time-varying-gains"
    post = shared_posterior(res, recs, n_grid=5)
    assert post.log_density.shape == (5, 5) and post.settings["failed_points"] == 0
    for n in ("drift_v", "drift_m"):
        # the grid is of the test's likelihood with each run's delta_abs at the reported fit's:
        # centred on the pooled fit under it, near the test's (the drifts barely move delta_abs)
        v, se = post.ml[n], post.stderr[n]
        # (measured: drift_m 0.3289 +- 0.0932 against the test's 0.3225 +- 0.0928)
        assert v == pytest.approx(res.chosen.refit["test_params"][n],
                                  abs=0.2 * res.chosen.stderr[n])
        assert se == pytest.approx(res.chosen.stderr[n], rel=0.1)
        m = post.marginals[n]
        assert m["sd"] == pytest.approx(se, rel=0.2)
        assert m["interval"][0] == pytest.approx(v - 1.645 * se, abs=0.3 * se)
        assert m["interval"][1] == pytest.approx(v + 1.645 * se, abs=0.3 * se)
        assert m["interval"][0] < p[n] < m["interval"][1]
    with pytest.raises(ValueError, match="n_grid"):
        shared_posterior(res, recs, n_grid=3)


def test_pooled_refine_reports_the_covariance_of_the_point_it_returns(washout_runs,
                                                                     washout_result,
                                                                     monkeypatch):
    """When the optimiser's solution is worse than the start, the start is returned, and so is
    the covariance at the start (not the rejected solution's)."""
    from types import SimpleNamespace

    from bayespilot.diagnose import pooled as P

    c = washout_result.chosen
    wls = [D.Whitened(c.model, rec, nz) for rec, nz in zip(washout_runs, c.noise)]
    qs = [r["params"] for r in washout_result.runs]
    names = tuple(n for n in c.model.parameter_names if n not in ("omega_w", "delta_abs"))
    bases = [D.FitSummary(q, math.nan, (), np.zeros((0, 0))) for q in qs]
    ps, f, cov = P._pooled_refine(wls, bases, names, ("omega_w",), {"omega_w": qs[0]["omega_w"]})
    assert cov[0, 0] > 0

    real = P.optimize.least_squares

    def worse(fun, x0, **kw):  # a "solution" far off, with a Jacobian that says nothing
        sol = real(fun, x0, **kw)
        bad = np.clip(x0 * 1.3, kw["bounds"][0], kw["bounds"][1])
        return SimpleNamespace(x=bad, jac=np.zeros_like(sol.jac))

    monkeypatch.setattr(P.optimize, "least_squares", worse)
    ps2, f2, cov2 = P._pooled_refine(wls, bases, names, ("omega_w",),
                                     {"omega_w": qs[0]["omega_w"]})
    assert f2 == pytest.approx(sum(wl.neg_log_lik(q) for wl, q in zip(wls, qs)), abs=1e-6)
    assert cov2[0, 0] > 0 and cov2[0, 0] == pytest.approx(cov[0, 0], rel=0.05)


def test_a_failed_grid_point_does_not_wreck_the_shared_posterior(washout_runs, washout_result,
                                                                 washout_posterior, monkeypatch):
    """A grid point whose pooled fit fails gets its density from its neighbours: the marginal
    stays where it was (left at zero density, the spline through it put the median outside
    the interval it had), and the summary says how many points failed."""
    import bayespilot.diagnose.posterior as P
    from bayespilot.diagnose import shared_posterior

    post0 = washout_posterior
    m0 = post0.marginals["omega_w"]
    g = post0.grid[0]
    target = g[int(np.argmin(np.abs(g - m0["mode"]))) + 1]  # beside the mode
    real = P._laplace_term

    def failing(wls, ps, names):
        if abs(ps[0].get("omega_w", -9.0) - target) < 1e-12:
            return -math.inf  # e.g. a singular Gauss-Newton Hessian there
        return real(wls, ps, names)

    monkeypatch.setattr(P, "_laplace_term", failing)
    post = shared_posterior(washout_result, washout_runs, n_grid=11)
    m = post.marginals["omega_w"]
    assert post.settings["failed_points"] == 1 and np.allclose(post.grid[0], g)
    assert abs(m["median"] - m0["median"]) < 0.3 * m0["sd"]
    assert m["sd"] == pytest.approx(m0["sd"], rel=0.2)
    assert post.log_bayes_factor == pytest.approx(post0.log_bayes_factor, abs=0.5)
    assert any("1 of 11 grid points failed" in line for line in post.summary_lines())


def test_a_pooled_diagnosis_read_back_from_its_json_is_the_same(washout_runs, washout_result,
                                                                tmp_path):
    """from_json gives back the runs, the Fisher-combined evidence, the calibrated ranking and
    the shared posterior: the same to_dict, summary and report; the posterior step, which
    needs the noise models a file does not keep, is refused by name."""
    from bayespilot.diagnose import DiagnosisResult, shared_posterior

    res = washout_result
    if res.posterior is None:
        shared_posterior(res, washout_runs, n_grid=7)
    res.to_json(tmp_path / "d.json")
    back = PooledDiagnosisResult.from_json(tmp_path / "d.json")
    assert json.loads(back.to_json()) == json.loads(res.to_json())
    assert back.summary() == res.summary()
    assert back.chosen.calibration.replicates == res.chosen.calibration.replicates
    np.testing.assert_allclose(back.posterior.log_density, res.posterior.log_density,
                               rtol=1e-12)
    paths = back.report(tmp_path / "rep")
    assert {"candidates", "runs", "posterior", "html", "json"} <= set(paths)
    assert json.loads(paths["json"].read_text()) == json.loads(res.to_json())
    with pytest.raises(ValueError, match="does not carry its runs' noise models"):
        shared_posterior(back, washout_runs)
    with pytest.raises(ValueError, match="a pooled diagnosis: read it with PooledDiagnosisResult"):
        DiagnosisResult.from_json(tmp_path / "d.json")
    (tmp_path / "s.json").write_text(json.dumps(dict(res.to_dict(), pooled=False)))
    with pytest.raises(ValueError, match="a single-run diagnosis: read it with DiagnosisResult"):
        PooledDiagnosisResult.from_json(tmp_path / "s.json")


def test_a_pooled_result_missing_a_runs_part_names_it():
    """A damaged pooled result file: a run without its base fit is named (it was a KeyError)."""
    d = {"pooled": True, "physics": "none", "mismatch": False, "ranking": [], "where": {},
         "runs": [{"base": {"params": {}}, "where": {}}, {"where": {}}]}
    with pytest.raises(ValueError, match="run 2 has no base"):
        PooledDiagnosisResult.from_dict(d)


def test_each_runs_base_fit_on_a_bound_and_dropped_replicates_are_kept(washout_runs,
                                                                        monkeypatch, tmp_path):
    """A run's base fit on a bound (its BaseFitWarning) and its bootstrap's dropped replicates
    were said but not kept: the pooled runs had no ``base_at_bounds`` and no bootstrap counts,
    and the JSON and summary no "base fit ON A BOUND" line.  Now each run keeps them, through
    to_dict/from_dict, and the summary says them under the run.  (Hand-made Eq. 4 fits, run
    0's on omega_nm's upper bound; the first bootstrap replicate diverging.)"""
    import sys
    import warnings

    from bayespilot.diagnose import BaseFitWarning, EvidenceWarning
    from bayespilot.fit import fast
    from bayespilot.fit.result import FitResult

    first = washout_runs[0]

    def fit_fast(rec, model, **kwargs):
        p = dict(presets.paper_parameters("FD"), **({"omega_nm": 30.0} if rec is first else {}))
        return FitResult(p, -1.0e4, 80.0, "fast", 0, True, bounds=dict(presets.TABLE1_BOUNDS))

    sim = sys.modules["bayespilot.simulate"]
    real, calls = sim.simulate, []

    def first_diverges(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            raise RuntimeError("the closed loop diverged")
        return real(*args, **kwargs)

    monkeypatch.setattr(fast, "fit_fast", fit_fast)
    monkeypatch.setattr(sim, "simulate", first_diverges)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = diagnose_pooled(washout_runs, seed=0, n_bootstrap=2, n_starts=1, n_calibrate=0,
                              refit=False, candidates=["time-varying-gains"])
    bound = [str(w.message) for w in caught if w.category is BaseFitWarning]
    assert len(bound) == 1 and "omega_nm = 30 on its upper bound (30, Eq. 4 fit)" in bound[0]
    dropped = [w for w in caught if "bootstrap replicates survived" in str(w.message)]
    assert len(dropped) == 1 and dropped[0].category is EvidenceWarning
    r0, r1 = res.runs
    edge = r0["base_at_bounds"]
    assert edge[0] == {"parameter": "omega_nm", "value": 30.0, "side": "upper", "bound": 30.0,
                       "fit": "Eq. 4"}
    assert bound[0][len(first.source) + 2:] in r0["evidence_notes"]
    assert "base_at_bounds" not in r1  # (its base fit: the paper's values)
    assert (r0["bootstrap"]["replicates"], r0["bootstrap"]["dropped"],
            r0["bootstrap"]["diverged"]) == (1, 1, 1)
    assert r1["bootstrap"]["replicates"] == 2 and r1["bootstrap"]["dropped"] == 0
    res.to_json(tmp_path / "d.json")
    back = PooledDiagnosisResult.from_json(tmp_path / "d.json")
    assert back.runs[0]["base_at_bounds"] == edge and back.runs[0]["bootstrap"]["dropped"] == 1
    assert json.loads(back.to_json()) == json.loads(res.to_json())
    text = res.summary()
    assert back.summary() == text
    runs = text.split("\nruns:\n")[1].splitlines()
    assert runs[1].startswith("    base fit ON A BOUND: omega_nm = 30 (upper bound, Eq. 4)")
    assert runs[2] == ("    bootstrap: only 1 of 2 replicates survived (1 closed loop(s) "
                       "diverged): check the signs and units of u, e and control_gain")
    assert text.count("ON A BOUND") == 1 and "bootstrap: only" not in "\n".join(runs[3:])


def test_pooled_bic_penalty_counts_every_runs_whitened_samples(washout_runs, washout_result):
    """The pooled test's BIC penalty is df ln m with m the whitened samples of all runs
    (each with its own noise model), not of one run; its Schwarz ln BF is delta_bic / 2."""
    res = washout_result
    ranked = [c for c in res.ranking if c.testable and c.fit is not None]
    assert ranked
    for c in ranked:
        m = sum(D.Whitened(c.model, rec, nz).m
                for rec, nz in zip(washout_runs, res.arrays["noise"]))
        one = D.Whitened(c.model, washout_runs[0], res.arrays["noise"][0]).m
        assert m > 1.5 * one
        assert c.statistic - c.delta_bic == pytest.approx(c.df * math.log(m), rel=1e-12)
        assert c.log_bayes_factor == pytest.approx(c.delta_bic / 2, rel=1e-12)

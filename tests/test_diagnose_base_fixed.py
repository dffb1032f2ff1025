"""diagnose holds the parameters a given base_fit held fixed, in every fit it makes.

Before, the base model was the paper's with base_fit's bounds only: a parameter the user had
held (``fit_fast(rec, paper_model().fix(tau_v=0.3))``) was estimated again by the GLS base
fit, by every extension's fit and by the replicates, so that the diagnosis tested another base
model than the one the user fitted.
"""

from __future__ import annotations

import dataclasses

import pytest

from bayespilot import presets
from bayespilot.diagnose import DiagnosisResult, NAMES, diagnose, get_extension
from bayespilot.diagnose import decide as D
from bayespilot.diagnose.catalogue import Extension, unregister_extension
from bayespilot.fit import fast as fast_module
from bayespilot.fit.fast import fit_fast
from bayespilot.fit.result import FitResult
from bayespilot.likelihood import Likelihood
from bayespilot.model import LinearDrift, Parameter, paper_model
from bayespilot.simulate import simulate

TAU_V = 0.3  # held; the free fit of this recording puts tau_v at 0.226 (the truth 0.279)

#: the washout recording is 40.96 s, not whole periods of the forcing (said by every fit)
pytestmark = pytest.mark.filterwarnings("ignore::bayespilot.likelihood.NotWholePeriodsWarning")


@pytest.fixture(scope="module")
def washout_rec():
    model = get_extension("motion-washout").build(paper_model())
    p = dict(presets.paper_parameters("FD"), omega_w=0.8)
    return simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063, seed=3,
                    duration=40.96).recording


def _hand_fit(rec, params, held):
    """A FitResult of the paper's model at ``params`` with the names ``held`` not estimated
    (its recorded bounds the free parameters' Table 1 boxes, as fit_fast records them)."""
    lik = Likelihood(paper_model(), rec, discard=0.0)
    bounds = {k: b for k, b in presets.TABLE1_BOUNDS.items() if k not in held}
    return FitResult(dict(params), lik.neg_log_lik(params), lik.vaf(params), "fast", 0,
                     params["delta_abs"] != 0.0, bounds=bounds)


def test_a_parameter_base_fit_held_stays_held_in_every_fit(washout_rec, monkeypatch, tmp_path):
    """tau_v held at 0.3 by the user's fit: the GLS base fit, the washout's fit and test, its
    refit and profile interval, the bootstrap's and the calibration's replicates all hold it
    there (before: the GLS base fit moved it to 0.2580, the washout's reported fit to
    0.2637, with omega_w 0.7917 against 0.8084 now)."""
    fit = fit_fast(washout_rec, paper_model().fix(tau_v=TAU_V), seed=0, n_starts=2,
                   discard=0.0)
    assert fit.fixed == ("tau_v",) and fit.params["tau_v"] == TAU_V
    held_in = []  # tau_v's fixed value in every model a GLS likelihood is made of
    orig = D.Whitened.__init__

    def spy(self, model, *a, **k):
        held_in.append(model.fixed.get("tau_v"))
        orig(self, model, *a, **k)

    monkeypatch.setattr(D.Whitened, "__init__", spy)
    replicate_fits = []  # tau_v's fixed value in the calibration replicates' Eq. 4 fits
    orig_fast = fast_module.fit_fast

    def spy_fast(rec, model=None, *a, **k):
        replicate_fits.append(model.fixed.get("tau_v"))
        return orig_fast(rec, model, *a, **k)

    monkeypatch.setattr(fast_module, "fit_fast", spy_fast)
    res = diagnose(washout_rec, base_fit=fit, seed=0, n_bootstrap=2, n_starts=2,
                   n_calibrate=2, candidates=["motion-washout"])
    assert res.base["gls_params"]["tau_v"] == TAU_V and "tau_v" not in res.base["gls_stderr"]
    assert res.physics == "motion-washout"
    c = res.chosen
    assert c.all_params["tau_v"] == TAU_V and "tau_v" not in c.stderr
    assert c.params["omega_w"] == pytest.approx(0.8084, abs=5e-4)  # (truth 0.8)
    assert res.settings["base_fixed"] == {"tau_v": TAU_V}
    assert res.base_model.fixed == {"tau_v": TAU_V}
    assert c.model.fixed == {"tau_v": TAU_V, "zeta_w": 0.7}
    assert c.refit is not None and c.interval["omega_w"].lower < 0.8 < c.interval["omega_w"].upper
    assert c.calibration is not None and c.calibration.replicates == 2
    assert replicate_fits == [TAU_V, TAU_V]  # the two calibration replicates
    # the base GLS fit, the bootstrap's 2 refits, the washout's fit, its refit and profile,
    # the calibration's replicates: every one held it
    assert len(held_in) >= 10 and set(held_in) == {TAU_V}
    line = "base model's parameters held fixed as base_fit held them (in every fit here): " \
           "tau_v = 0.3 s"
    assert line in res.summary()
    res.to_json(tmp_path / "d.json")
    back = DiagnosisResult.from_json(tmp_path / "d.json")
    assert back.settings["base_fixed"] == {"tau_v": TAU_V} and line in back.summary()


def test_a_threshold_held_at_a_nonzero_value_is_held_by_the_threshold_shape_test(washout_rec):
    """delta_abs held at 0.006 (not 0: a fit with a threshold): the base fit no longer scans
    it, and threshold-shape, which refines it with its reference, holds it too (before: the
    scan moved it to 0.00372, the threshold-shape fit to 7e-7, p 0.12 against 0.049 now)."""
    p = presets.paper_parameters("FD")
    fit = _hand_fit(washout_rec, dict(p, delta_abs=0.006), held=("delta_abs",))
    assert fit.fixed == ("delta_abs",) and fit.threshold
    res = diagnose(washout_rec, base_fit=fit, seed=0, n_bootstrap=0,
                   candidates=["threshold-shape"], intervals=False)
    assert res.base["gls_params"]["delta_abs"] == 0.006
    (shape,) = res.ranking
    assert shape.testable and shape.all_params["delta_abs"] == 0.006
    assert shape.p_value == pytest.approx(0.0493, abs=5e-4)
    assert res.settings["base_fixed"] == {"delta_abs": 0.006}
    assert shape.model.fixed == {"delta_abs": 0.006} and "delta_abs" not in shape.stderr


def test_a_fit_without_threshold_is_refused_before_any_work(washout_rec, monkeypatch):
    """A base_fit made with threshold=False (delta_abs held at 0) was diagnosed with its
    threshold scanned back (to 0.002 here): now a ValueError that says to give a fit with it."""
    p = dict(presets.paper_parameters("FD"), delta_abs=0.0)
    fit = _hand_fit(washout_rec, p, held=("delta_abs",))
    assert not fit.threshold and fit.fixed == ("delta_abs",)
    monkeypatch.setattr(D, "fit_base_gls", lambda *a, **k: pytest.fail("fitted"))
    with pytest.raises(ValueError, match=r"without threshold \(delta_abs held at 0\).*"
                                         r"give a base_fit made with the threshold"):
        diagnose(washout_rec, base_fit=fit, seed=0, n_bootstrap=0,
                 candidates=["time-varying-gains"])


def test_every_catalogue_entry_keeps_the_held_parameters_and_silent_ones_stay_free(
        washout_rec):
    """The base model holds base_fit's fixed parameters at its values; every built-in
    entry's build keeps them (the extension point keeps a model's fixed parameters); a
    parameter only marked as not identified (a silent channel's) stays free, as before."""
    from bayespilot.diagnose import _base_model, _check_held

    p = presets.paper_parameters("FD")
    fit = _hand_fit(washout_rec, dict(p, delta_abs=0.007, zeta_nm=0.2),
                    held=("delta_abs", "zeta_nm"))
    model, wider = _base_model(fit, 1)
    assert model.fixed == {"delta_abs": 0.007, "zeta_nm": 0.2} and wider == {}
    for name in NAMES:
        built = get_extension(name).build(model)
        assert {k: built.fixed[k] for k in ("delta_abs", "zeta_nm")} == model.fixed, name
    _check_held(NAMES, model, model.fixed)  # none refused
    quiet = dataclasses.replace(_hand_fit(washout_rec, p, held=()),
                                settings={"unidentified": ["K_m", "tau_m"]})
    assert _base_model(quiet, 1)[0].fixed == {}


def test_an_entry_whose_build_frees_a_held_parameter_is_refused(washout_rec, monkeypatch):
    """An entry of one's own that frees tau_v would estimate what base_fit held (and count a
    degree of freedom it does not say): refused before any fit, naming it."""
    ext = Extension("drift-and-free-delay", "a visual gain drift", "gain drift",
                    ("time.gain_drift_visual",),
                    lambda m: m.with_modulation("visual", LinearDrift("drift_x"), [
                        Parameter("drift_x", -1.5, 1.5, 0.0)]).free("tau_v"),
                    ("drift_x",))
    fit = _hand_fit(washout_rec, presets.paper_parameters("FD"), held=("tau_v",))
    monkeypatch.setattr(D, "fit_base_gls", lambda *a, **k: pytest.fail("fitted"))
    try:
        with pytest.raises(ValueError, match=r"extension 'drift-and-free-delay': its build of "
                                             r"the base model leaves tau_v \(free, base_fit's "
                                             r"0.279\)"):
            diagnose(washout_rec, base_fit=fit, seed=0, n_bootstrap=0, candidates=[ext])
    finally:
        unregister_extension("drift-and-free-delay")

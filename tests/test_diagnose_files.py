"""The diagnosis family's result files and reprs (API audit 2026-11-29, ``audit_api.md``).

What each test holds the code to:

- a pooled diagnosis's ``where`` keeps NaN p-values through its file (#3);
- one diagnosis file writes an infinity one way: the single-run ``chosen`` as the
  ``ranking`` does (``"inf"``/``"-inf"``, NaN as null), and reads old files' nulls (#1);
- ``NoiseModel ==`` is identity and does not raise (#7);
- a shared posterior's file keeps its log density, not only the density (#11);
- :class:`ExtensionBayesFactor` and :class:`SharedPosterior` have ``to_json``/``from_json``
  like the diagnoses', and refuse a file of another kind naming it (C2);
- a candidate's, a noise model's and a shared posterior's repr is short (C7).

All objects are built by hand (no fitting): each test takes well under a second.
"""

from __future__ import annotations

import copy
import json
import math
import pickle

import numpy as np
import pytest

from bayespilot._files import dumps, write_text_atomic
from bayespilot.diagnose import (DiagnosisResult, PooledDiagnosisResult, SharedPosterior,
                                 get_extension)
from bayespilot.diagnose.decide import CandidateResult, FitSummary, noise_model
from bayespilot.diagnose.nested import EvidenceSummary, ExtensionBayesFactor
from bayespilot.model import paper_model

from conftest import make_rng

INF = math.inf


def _strict(text: str) -> dict:
    """``text`` parsed by a JSON parser that refuses NaN and Infinity tokens."""
    def reject(token):
        raise ValueError(f"not standard JSON: {token}")

    return json.loads(text, parse_constant=reject)


def _same(a, b) -> bool:
    """Equal, NaN equal to NaN, type-aware for floats and str (``"inf"`` is not inf)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    return type(a) is type(b) and a == b


def _noise():
    """A real decision noise model (61 FIR taps, an AR filter) of a white residual."""
    return noise_model(0.01 * make_rng(0).standard_normal(3000), 0.01, skip=100)


# --- #3: the pooled where ---------------------------------------------------------------------

def _pooled_result() -> PooledDiagnosisResult:
    cand = CandidateResult("motion-washout", True, "GLS likelihood-ratio test", 0.4, 0.8, 1,
                           0.2, -5.0, -2.5, {"omega_w": 0.3})
    where = {"frequency.motion_high": {"p_value": math.nan, "values": [1.5, math.nan]},
             "time.drift": {"p_value": 0.01, "values": [2.0, 3.0]}}
    return PooledDiagnosisResult(False, "none", [cand], [], where, None, {"alpha": 0.01}, 2.0)


def test_pooled_where_keeps_nan_p_values_after_reload(tmp_path):
    res = _pooled_result()
    path = tmp_path / "pooled.json"
    res.to_json(path)
    back = PooledDiagnosisResult.from_json(path)
    assert _same(back.where, res.where)
    p = back.where["frequency.motion_high"]["p_value"]
    assert isinstance(p, float) and math.isnan(p)
    # what a script did before saving works after reading back
    assert [v["p_value"] < 0.05 for v in back.where.values()] == \
        [v["p_value"] < 0.05 for v in res.where.values()] == [False, True]
    assert back.to_dict() == res.to_dict()


# --- #1: one convention for infinities inside one diagnosis file -------------------------------

def _single_result() -> DiagnosisResult:
    """Exact flat tops: an infinite statistic, with a NaN and infinities among the numbers."""
    chosen = CandidateResult(
        "control-saturation", True, "flat tops", INF, 12.0, 0, 0.0, INF, INF,
        params={"u_max": 0.3, "u_min": -0.3, "sigma": math.nan},
        stderr={"u_max": INF, "K_v": 0.05}, all_params={"K_v": 1.2, "u_max": 0.3, "x": -INF},
        signature_score=2.0, justified=True)
    other = CandidateResult("otolith-channel", False, "no theta column")
    base = {"params": {"K_v": 1.2}, "neg_log_lik": -100.0, "vaf": 80.0,
            "gls_params": {"K_v": 1.2}, "gls_neg_log_lik": -90.0, "gls_stderr": {"K_v": 0.05}}
    arrays = {"before_vaf": 80.0, "after_vaf": 85.0, "before_eq4_neg_log_lik": -100.0,
              "after_eq4_neg_log_lik": -INF}
    return DiagnosisResult(True, "control-saturation", [chosen, other], {}, base, chosen,
                           {"alpha": 0.01, "n_tested": 1, "skip_seconds": 5.0}, 3.0, "run.csv",
                           arrays)


def test_json_number_writes_infinities_as_strings_and_nan_as_null():
    from bayespilot.diagnose.decide import json_number

    assert [json_number(x) for x in (1.5, INF, -INF, math.nan, np.float64(-INF), 2)] == \
        [1.5, "inf", "-inf", None, "-inf", 2.0]


def test_single_run_chosen_writes_infinities_as_the_ranking_does(tmp_path):
    res = _single_result()
    d = _strict(res.to_json())
    chosen, ranked = d["chosen"], d["ranking"][0]
    for key in ("delta_neg_log_lik", "params", "stderr", "all_params"):
        assert chosen[key] == ranked[key], key
    assert chosen["delta_neg_log_lik"] == "inf"
    assert chosen["params"] == {"u_max": 0.3, "u_min": -0.3, "sigma": None}
    assert chosen["stderr"] == {"u_max": "inf", "K_v": 0.05}
    assert chosen["all_params"] == {"K_v": 1.2, "u_max": 0.3, "x": "-inf"}
    assert chosen["neg_log_lik_after"] == "-inf"
    assert (chosen["neg_log_lik_before"], chosen["vaf_before"], chosen["vaf_after"]) == \
        (-100.0, 80.0, 85.0)
    # the fields written are those of before
    assert set(chosen) == {"physics", "params", "stderr", "all_params", "delta_neg_log_lik",
                           "neg_log_lik_before", "neg_log_lik_after", "vaf_before", "vaf_after",
                           "refit", "interval", "posterior"}
    # read back: the infinities are infinities again, and the file is written the same
    path = tmp_path / "diagnosis.json"
    res.to_json(path)
    back = DiagnosisResult.from_json(path)
    assert back.chosen.delta_neg_log_lik == INF and back.chosen.stderr["u_max"] == INF
    assert back.chosen.all_params["x"] == -INF and math.isnan(back.chosen.params["sigma"])
    assert back.arrays["after_eq4_neg_log_lik"] == -INF
    assert back.to_dict() == res.to_dict()
    assert back.summary() == res.summary()


def test_single_run_chosen_reads_old_nulls_and_new_strings():
    """Files written before wrote null for the chosen's infinities; both forms load (the
    chosen built from ``d["chosen"]`` when the ranking lacks it)."""
    d = _strict(_single_result().to_json())
    old = copy.deepcopy(d)
    old["chosen"].update(delta_neg_log_lik=None, neg_log_lik_after=None,
                         stderr={"u_max": None, "K_v": 0.05})
    for doc, want in ((old, math.nan), (d, INF)):
        doc = copy.deepcopy(doc)
        doc["ranking"] = doc["ranking"][1:]  # the chosen from d["chosen"] itself
        back = DiagnosisResult.from_dict(doc)
        assert _same(back.chosen.delta_neg_log_lik, want)
        assert _same(back.chosen.stderr, {"u_max": want, "K_v": 0.05})
        assert back.chosen.params["u_max"] == 0.3
    assert "after_eq4_neg_log_lik" not in DiagnosisResult.from_dict(old).arrays  # as before
    assert DiagnosisResult.from_dict(d).arrays["after_eq4_neg_log_lik"] == -INF


# --- #7: NoiseModel == ----------------------------------------------------------------------

def test_noise_model_equality_is_identity_and_does_not_raise():
    nm = _noise()
    copied = pickle.loads(pickle.dumps(nm))
    assert nm == nm
    assert (nm == copied) is False and (nm != copied) is True
    assert np.array_equal(nm.fir, copied.fir) and np.array_equal(nm.ar, copied.ar)
    assert len({nm, copied}) == 2  # hashable (by identity)


# --- #11 and C2: the shared posterior's file --------------------------------------------------

def _shared_posterior() -> SharedPosterior:
    grid = np.linspace(0.1, 0.7, 7)
    log_density = np.array([-800.0, -30.0, -3.0, -1.0, -2.0, -20.0, -INF])
    marg = {"median": 0.4, "mean": 0.41, "sd": 0.05, "interval": [0.3, 0.5], "mode": 0.4,
            "density": np.exp(log_density).tolist()}
    return SharedPosterior("motion-washout", ("omega_w",), [grid], log_density,
                           {"omega_w": marg}, {"omega_w": 0.4}, {"omega_w": 0.05}, 0.0,
                           {"method": "Laplace", "points": 7}, 1.5, 2.5)


def _check_same_posterior(back: SharedPosterior, sp: SharedPosterior) -> None:
    assert back.physics == sp.physics and back.names == sp.names
    assert _same(back.grid, sp.grid)
    np.testing.assert_array_equal(back.log_density, sp.log_density)
    assert _same(back.marginals, sp.marginals)
    assert (back.ml, back.stderr, back.edge_mass, back.settings, back.elapsed,
            back.log_bayes_factor) == (sp.ml, sp.stderr, sp.edge_mass, sp.settings, sp.elapsed,
                                       sp.log_bayes_factor)


def test_shared_posterior_keeps_a_log_density_below_exp_underflow():
    sp = _shared_posterior()
    d = _strict(dumps(sp.to_dict()))
    assert d["log_density"] == [-800.0, -30.0, -3.0, -1.0, -2.0, -20.0, "-inf"]
    assert d["density"][0] == 0.0  # still written, for readers of before
    back = SharedPosterior.from_dict(d)
    assert back.log_density[0] == -800.0  # exp(-800) underflows: log(density) gave -inf
    _check_same_posterior(back, sp)
    # an old file, density only: the log of the density, as before
    old = {k: v for k, v in d.items() if k != "log_density"}
    with np.errstate(divide="ignore"):
        np.testing.assert_array_equal(SharedPosterior.from_dict(old).log_density,
                                      np.log(np.exp(sp.log_density)))


def test_shared_posterior_to_json_and_from_json(tmp_path):
    sp = _shared_posterior()
    text = sp.to_json()
    assert isinstance(text, str) and _strict(text)["physics"] == "motion-washout"
    path = tmp_path / "shared.json"
    assert sp.to_json(path) == text == path.read_text(encoding="utf-8")
    _check_same_posterior(SharedPosterior.from_json(path), sp)
    # the file 'bayespilot diagnose --posterior X.json' writes for several runs
    cli = tmp_path / "cli_posterior.json"
    write_text_atomic(cli, dumps(sp.to_dict()))
    _check_same_posterior(SharedPosterior.from_json(cli), sp)
    # ... and one written before log_density was (density only)
    old = tmp_path / "old_posterior.json"
    write_text_atomic(old, dumps({k: v for k, v in sp.to_dict().items() if k != "log_density"}))
    assert SharedPosterior.from_json(old).log_density[3] == -1.0


def test_shared_posterior_from_json_needs_what_from_dict_needs(tmp_path):
    """from_json asks for the density as from_dict does: ``log_density``, or ``density``
    without it.  A file with log_density alone was refused by from_json ("no density") though
    from_dict loads it (review 2026-11-29, finding 8); one with neither is refused, named."""
    sp = _shared_posterior()
    d = {k: v for k, v in sp.to_dict().items() if k != "density"}
    _check_same_posterior(SharedPosterior.from_dict(_strict(dumps(d))), sp)
    path = tmp_path / "log_only.json"
    write_text_atomic(path, dumps(d))
    _check_same_posterior(SharedPosterior.from_json(path), sp)
    neither = tmp_path / "neither.json"
    write_text_atomic(neither, dumps({k: v for k, v in d.items() if k != "log_density"}))
    with pytest.raises(ValueError, match="neither.json.*not a SharedPosterior.*log_density"):
        SharedPosterior.from_json(neither)
    # a null log_density is as missing (from_dict then takes the density)
    write_text_atomic(neither, dumps(dict(d, log_density=None)))
    with pytest.raises(ValueError, match="neither.json.*not a SharedPosterior"):
        SharedPosterior.from_json(neither)


# --- C2: the Bayes factor's file --------------------------------------------------------------

def _bayes_factor() -> ExtensionBayesFactor:
    return ExtensionBayesFactor("motion-washout", 3.2, 0.5, "strong", "motion-washout", 4.1,
                                EvidenceSummary(-120.5, 0.2, -100.0),
                                EvidenceSummary(-123.7, 0.2, -104.0),
                                {"omega_w": [0.01, 2.0]}, {"nlive": 30, "runs": 1}, 12.0)


def test_extension_bayes_factor_to_json_and_from_json(tmp_path):
    bf = _bayes_factor()
    text = bf.to_json()
    assert isinstance(text, str) and _strict(text)["log_bayes_factor"] == 3.2
    path = tmp_path / "bf.json"
    assert bf.to_json(path) == text == path.read_text(encoding="utf-8")
    back = ExtensionBayesFactor.from_json(path)
    assert back.to_dict() == bf.to_dict()
    assert back.extended == bf.extended and back.base == bf.base
    assert back.summary_line() == bf.summary_line()


def test_from_json_refuses_a_file_of_another_kind_naming_it(tmp_path):
    bf_file, sp_file, diag_file = (tmp_path / n for n in ("bf.json", "sp.json", "diag.json"))
    _bayes_factor().to_json(bf_file)
    _shared_posterior().to_json(sp_file)
    _pooled_result().to_json(diag_file)
    for cls, path in ((SharedPosterior, bf_file), (SharedPosterior, diag_file),
                      (ExtensionBayesFactor, sp_file), (ExtensionBayesFactor, diag_file)):
        with pytest.raises(ValueError, match=f"{path.name}.*not an? {cls.__name__}"):
            cls.from_json(path)
    with pytest.raises(ValueError, match="bf.json"):
        PooledDiagnosisResult.from_json(bf_file)


# --- C7: reprs ---------------------------------------------------------------------------------

def test_reprs_are_short_and_say_what_matters():
    model = get_extension("motion-washout").build(paper_model())
    names = model.parameter_names
    fit = FitSummary({n: 0.1 for n in names}, -1000.0, tuple(names),
                     np.eye(len(names)) * 1e-4, 12)
    cand = CandidateResult("motion-washout", True, "GLS likelihood-ratio test, chi-bar-squared",
                           12.3, 24.6, 1, 1.2e-6, 18.2, 9.1, {"omega_w": 0.30349},
                           {n: 0.01 for n in names}, {n: 0.1 for n in names},
                           signature_score=3.0, justified=True, fit=fit, model=model,
                           noise=_noise())
    text = repr(cand)
    assert len(text) < 600, text
    assert "\n" not in text
    for part in ("'motion-washout'", "justified=True", "p_value=1.2e-06", "omega_w"):
        assert part in text, part
    untestable = repr(CandidateResult("otolith-channel", False, "no theta column"))
    assert "testable=False" in untestable and "no theta column" in untestable

    nm = _noise()
    text = repr(nm)
    assert len(text) < 200 and "array" not in text, text
    assert f"fir_taps={nm.fir.size}" in text and f"ar_order={nm.ar.size}" in text

    text = repr(_shared_posterior())
    assert len(text) < 600 and "array" not in text and "density" not in text, text
    assert "'motion-washout'" in text and "log_bayes_factor=2.5" in text


# --- units: every parameter's, in the files, the summaries and the batch's table ---------------

def test_units_are_kept_through_the_file_and_shown_beside_the_fitted_values(tmp_path):
    from bayespilot.diagnose import _parameter_units
    from bayespilot.diagnose.batch import DiagnoseTask, batch_summary_rows

    base = paper_model()
    washout = get_extension("motion-washout").build(base)
    units = _parameter_units(base, None, washout)
    # the paper's Table 1 units, then the entry's own (the base model's names come first)
    assert units["tau_m"] == "s" and units["K_m"] == "rad/IPUT" and units["delta_abs"] == "IPUT"
    assert units["omega_w"] == "rad/s" and list(units)[:8] == list(base.all_names)
    # control-saturation's reported numbers: the limits and the censored fit's sigma in u's
    # unit, the count of censored samples a number
    sat = _parameter_units(base, get_extension("control-saturation").build(base))
    assert {k: sat[k] for k in ("u_max", "u_min", "sigma", "n_censored")} == {
        "u_max": "rad", "u_min": "rad", "sigma": "rad", "n_censored": "-"}
    assert "u_min" not in units  # (only with the entry)
    chosen = CandidateResult("motion-washout", True, "GLS", 8.0, 16.0, 1, 1e-5, 10.0, 5.0,
                             {"omega_w": 0.31}, {"omega_w": 0.02}, justified=True)
    res = DiagnosisResult(True, "motion-washout", [chosen], {},
                          {"params": {}, "neg_log_lik": -1.0, "vaf": 80.0},
                          chosen, {"alpha": 0.01, "n_tested": 1, "skip_seconds": 5.0}, 1.0,
                          "run.csv", units=units)
    assert "  omega_w            0.31 +- 0.02 rad/s" in res.summary().splitlines()
    res.to_json(tmp_path / "d.json")
    back = DiagnosisResult.from_json(tmp_path / "d.json")
    assert back.units == units and back.summary() == res.summary()
    assert _strict((tmp_path / "d.json").read_text())["units"]["omega_w"] == "rad/s"
    # the batch's table: the chosen parameters' units, as JSON; none from an older file
    task = DiagnoseTask("run", ("run.csv",), None, "FD", 1.0)
    row, = batch_summary_rows([task], tmp_path, {"run": res.to_dict()})
    assert json.loads(row["units"]) == {"omega_w": "rad/s"}
    old = {k: v for k, v in res.to_dict().items() if k != "units"}
    row, = batch_summary_rows([task], tmp_path, {"run": old})
    assert row["units"] == "" and json.loads(row["params"]) == {"omega_w": 0.31}
    assert DiagnosisResult.from_dict(old).units == {}
    # the report's candidate table (also the pooled one's)
    from bayespilot.diagnose.report import _candidate_table
    assert "0.31 &plusmn; 0.02 rad/s" in _candidate_table([chosen], units)
    assert "0.31 &plusmn; 0.02</td>" in _candidate_table([chosen])


# --- a candidate's boundary null is kept in its file (audit_structure.md 7.8) ------------------

def _custom_entry(name: str, boundary_null: bool):
    """An entry of one's own, never registered (as a result file of another session's)."""
    from bayespilot.diagnose.catalogue import Extension

    def build(model):
        return model

    return Extension(name, "a custom entry", "nothing", (), build, ("T_vis",),
                     boundary_null=boundary_null)


def test_lr_verdict_records_the_boundary_null_in_the_result_and_its_file():
    """One helper makes a GLS candidate's test (single-run and pooled): its statistic,
    p-value, delta BIC and ``how``; the result keeps whether the null is on a boundary, its
    JSON too, and reads it back."""
    from bayespilot.diagnose import decide as D

    washout, gains = get_extension("motion-washout"), get_extension("time-varying-gains")
    v = D.lr_verdict(washout, 2.5, 1000)
    assert (v.statistic, v.df, v.boundary_null) == (5.0, 1, True)
    assert v.p_value == D.lr_p_value(5.0, washout)
    assert v.delta_bic == 5.0 - math.log(1000)
    assert v.how == "GLS likelihood-ratio test, 0.5 chi2(0) + 0.5 chi2(1) (boundary null)"
    w = D.lr_verdict(gains, 2.5, 1000, test="pooled GLS likelihood-ratio test over 3 runs")
    assert not w.boundary_null and w.delta_bic == 5.0 - gains.df * math.log(1000)
    assert w.how == f"pooled GLS likelihood-ratio test over 3 runs, chi2({gains.df})"
    # a test made again against another reference keeps its own penalty
    assert D.lr_verdict(washout, 1.0, penalty=5.0 - v.delta_bic).delta_bic == 2.0 - math.log(1000)
    with pytest.raises(ValueError, match="m or penalty"):
        D.lr_verdict(washout, 1.0)
    # the critical value is where the p-value reaches the level
    for ext in (washout, gains):
        crit = D.critical_value(ext.df, ext.boundary_null, 0.01)
        assert D.lr_p_value(crit, ext) == pytest.approx(0.01, rel=1e-9)

    res = v.result("motion-washout", {"omega_w": 0.3}, {"omega_w": 0.05}, {"omega_w": 0.3})
    assert res.boundary_null and res.reason == v.how
    assert (res.delta_neg_log_lik, res.statistic, res.p_value, res.delta_bic,
            res.log_bayes_factor) == (2.5, 5.0, v.p_value, v.delta_bic, v.delta_bic / 2)
    d = _strict(dumps(res.to_dict()))
    assert d["boundary_null"] is True
    back = CandidateResult.from_dict(d)
    assert back.boundary_null is True and back.to_dict() == res.to_dict()
    # read from the field, not from how the test is worded: an entry of one's own, its
    # reason reworded
    d["physics"], d["reason"] = "my-lag", "LR test, reference mixture at the edge"
    assert CandidateResult.from_dict(d).boundary_null is True
    d["boundary_null"], d["reason"] = False, v.how
    assert CandidateResult.from_dict(d).boundary_null is False
    # positional construction as before: the field comes after the others, default None
    # (not recorded: the report asks the catalogue)
    assert CandidateResult("motion-washout", True, "GLS", 0.4, 0.8, 1, 0.2, -5.0, -2.5,
                           {"omega_w": 0.3}).boundary_null is None


def test_a_file_written_before_boundary_null_reads_it_from_the_reason():
    """A result file of before the field: its one-parameter test named a boundary null in
    ``reason`` (as the decision wrote it); read so, and written with the field after."""
    from bayespilot.diagnose import decide as D

    v = D.lr_verdict(_custom_entry("my-lag", True), 2.5, 1000)
    old = v.result("my-lag", {"T_vis": 0.1}, {}, {}).to_dict()
    del old["boundary_null"]
    back = CandidateResult.from_dict(old)
    assert back.boundary_null is True and back.to_dict()["boundary_null"] is True
    plain = D.lr_verdict(_custom_entry("my-lag", False), 2.5, 1000).result("my-lag", {}, {}, {})
    old = plain.to_dict()
    del old["boundary_null"]
    assert CandidateResult.from_dict(old).boundary_null is False
    # only a one-parameter test had the chi-bar-squared reference
    assert CandidateResult.from_dict({"physics": "x", "testable": True, "df": 2,
                                      "reason": "(boundary null)"}).boundary_null is False
    # read from the reference the test names, not from the words: an entry of one's own
    # whose reason says it is not a boundary null
    assert CandidateResult.from_dict({"physics": "x", "testable": True, "df": 1,
                                      "reason": "LR test, chi2(1) (not a boundary null)"}
                                     ).boundary_null is False


def test_eq4_neg_log_lik_is_floored_as_the_likelihoods():
    """The report's before/after -ln L (Eq. 4, variance profiled out) by the kernels' one
    helper: a perfect fit gives its floored finite value, no warning; otherwise the value is
    N/2 ln(mean r^2) + N/2 as before (audit_structure.md 7.10)."""
    import warnings

    from bayespilot.diagnose import _eq4_neg_log_lik
    from bayespilot.kernels._response import neg_log_lik_from_sse

    floor = 1e-24 * 0.3 + 1e-300
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = _eq4_neg_log_lik(np.zeros(1000), floor)
    assert math.isfinite(got) and got == neg_log_lik_from_sse(0.0, 1000, floor)[0]
    r = make_rng(1).standard_normal(777)
    n = r.size
    assert _eq4_neg_log_lik(r, floor) == float(0.5 * n * math.log(np.mean(r * r)) + 0.5 * n)

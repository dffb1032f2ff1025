"""Result files read back what was saved: NaN where a number was NaN (not None), a field of
a later release ignored, a missing one named, numpy arrays written, a posterior's own fields
(the audit of saving and reloading, 2026-11-29: findings 2, 4, 8, 9 and C6)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from bayespilot import _files
from bayespilot.compare import Comparison, Evidence, SavageDickey, information_criteria


def same(a, b) -> bool:
    """Equal, NaN equal to NaN, type-aware (None is not NaN, a list not a tuple), recursively."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if type(a) is not type(b):
        return False
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return a == b


def assert_same_fields(a, b, skip=()):
    for f in dataclasses.fields(a):
        if f.name in skip:
            continue
        x, y = getattr(a, f.name), getattr(b, f.name)
        if dataclasses.is_dataclass(x):
            assert_same_fields(x, y, skip)
        else:
            assert same(x, y), (f.name, x, y)


def _evidence(**changes):
    ev = Evidence(-12.5, 0.2, 3.1, -2.0, {"K_v": 1.1, "delta_abs": 0.004},
                  {"K_v": 1.05, "delta_abs": 0.003}, ("K_v", "delta_abs"), 1200, 300, 1.5,
                  {"nlive": 40, "seed": 7})
    return dataclasses.replace(ev, **changes)


def _comparison(**changes):
    """A comparison as compare makes one (with a plateau onset, so a probability), NaN in
    every numeric field nested where the audit found None after reloading."""
    ic = information_criteria(-100.0, -95.0, 9, 8, 1000)
    ic.update(neg_log_lik_none=math.nan, log_bayes_factor_bic=math.nan, aic_none=math.nan,
              ml_threshold={"K_v": 1.1, "delta_abs": math.nan}, ml_none={"K_v": math.inf})
    sd = SavageDickey(math.nan, True, "200 of 4000 draws within 2 bandwidths of 0", None, 10.0,
                      math.nan, 0.002, 4000, 200)
    c = Comparison(2.5, 0.3, "threshold", _evidence(best={"K_v": math.nan, "delta_abs": 0.004}),
                   _evidence(mean={"K_v": -math.inf}), sd, ic,
                   {"likelihood": "eq4", "decision_note": "", "plateau_onset": 0.05}, 11, 3.0,
                   "run.csv", math.nan)
    return dataclasses.replace(c, **changes)


# --- finding 2: nested NaN is NaN again, and the summary works after reloading ---------------
def test_comparison_with_nested_nan_round_trips_and_summarises(tmp_path):
    c = _comparison()
    text = c.summary()  # before saving: "nan" in the lines
    back = Comparison.from_json(c.to_json(tmp_path / "c.json"))
    # every field, NaN-aware (an infinity is written as null, so it comes back NaN: the sign
    # is the one thing a standard JSON null cannot keep)
    expected = _comparison(evidence_none=_evidence(mean={"K_v": math.nan}))
    expected.information_criteria["ml_none"] = {"K_v": math.nan}
    assert_same_fields(expected, back)
    assert math.isnan(back.information_criteria["neg_log_lik_none"])
    assert math.isnan(back.plateau_probability)
    assert back.information_criteria["k_none"] == 8 and back.information_criteria["n"] == 1000
    assert back.summary() == text


def test_comparison_summary_after_reloading_a_nan_neg_log_lik(tmp_path):
    """The audit's crash: summary() raised TypeError (None.__format__) after the round trip."""
    c = _comparison(evidence_threshold=_evidence(), evidence_none=_evidence())
    c.information_criteria.update(neg_log_lik_none=math.nan, neg_log_lik_threshold=math.nan)
    back = Comparison.from_json(c.to_json(tmp_path / "c.json"))
    assert "-ln L (ML) threshold = nan, none = nan" in back.summary()
    assert back.summary() == c.summary()


def test_comparison_without_a_plateau_probability_keeps_none(tmp_path):
    """None (no plateau onset, or a file of before the field) is not made NaN."""
    c = _comparison(plateau_probability=None, settings={"likelihood": "eq4"})
    back = Comparison.from_json(c.to_json(tmp_path / "c.json"))
    assert back.plateau_probability is None
    d = json.loads(c.to_json())
    del d["plateau_probability"]
    assert Comparison.from_dict(d).plateau_probability is None


def test_evidence_best_and_mean_nan_round_trip():
    ev = _evidence(best={"K_v": math.nan}, mean={"K_v": 2.0, "delta_abs": math.nan},
                   log_z=math.nan)
    back = Evidence.from_dict(json.loads(_files.dumps(ev.to_dict())))
    assert_same_fields(ev, back, skip=("settings",))
    assert back.settings == {"nlive": 40, "seed": 7}


@pytest.mark.parametrize("sd", [
    SavageDickey(-2.1, True, "ok", None, 10.0, 81.0, 0.001, 4000, 900),
    SavageDickey(math.nan, True, "ok", None, 10.0, math.nan, math.nan, 4000, 900),
    SavageDickey(None, False, "too few draws near 0", 3.5, 10.0, 0.5, 0.002, 4000, 3),
    SavageDickey(None, False, "too few draws near 0", None, 10.0, math.nan, 0.002, 4000, 3),
])
def test_savage_dickey_from_dict_round_trips(sd):
    back = SavageDickey.from_dict(json.loads(_files.dumps(sd.to_dict())))
    assert_same_fields(sd, back)


# --- finding 8: a later release's field is ignored, a missing one named ---------------------
def test_evidence_and_savage_dickey_ignore_a_field_of_a_later_release():
    ev = _evidence()
    assert Evidence.from_dict({**ev.to_dict(), "new_field": 1}) == ev
    sd = SavageDickey(-2.1, True, "ok", None, 10.0, 81.0, 0.001, 4000, 900)
    assert SavageDickey.from_dict({**sd.to_dict(), "new_field": [1, 2]}) == sd


def test_evidence_and_savage_dickey_name_a_missing_field():
    d = _evidence().to_dict()
    del d["log_z_err"]
    with pytest.raises(_files.WrongKind, match="no log_z_err"):
        Evidence.from_dict(d)
    sd = SavageDickey(-2.1, True, "ok", None, 10.0, 81.0, 0.001, 4000, 900).to_dict()
    del sd["bandwidth"]
    with pytest.raises(_files.WrongKind, match="no bandwidth"):
        SavageDickey.from_dict(sd)


def test_comparison_file_with_later_fields_loads_and_one_missing_a_field_is_named(tmp_path):
    c = _comparison()
    d = json.loads(c.to_json())
    d["evidence_threshold"]["new_field"] = 1
    d["savage_dickey"]["new_field"] = "x"
    path = tmp_path / "later.json"
    path.write_text(json.dumps(d))
    back = Comparison.from_json(path)
    assert_same_fields(Comparison.from_json(c.to_json(tmp_path / "c.json")), back)
    del d["savage_dickey"]["n_near"]
    del d["evidence_none"]["n_iter"]
    path.write_text(json.dumps(d))
    with pytest.raises(ValueError, match=r"later\.json: .*no n_near") as info:
        Comparison.from_json(path)
    assert not isinstance(info.value, TypeError)
    d["savage_dickey"] = None
    path.write_text(json.dumps(d))
    with pytest.raises(ValueError, match=r"later\.json: evidence_none: .*no n_iter"):
        Comparison.from_json(path)


# --- finding 9: numpy arrays are written, non-finite entries as null -------------------------
def test_json_ready_writes_numpy_arrays():
    x = {"a": np.array([1.0, np.nan, np.inf]), "b": np.arange(4).reshape(2, 2),
         "c": [np.array([True, False])], "d": np.float32(0.5)}
    assert _files.json_ready(x) == {"a": [1.0, None, None], "b": [[0, 1], [2, 3]],
                                    "c": [[True, False]], "d": 0.5}
    text = _files.dumps({"settings": {"x": np.array([[1.0, -np.inf]])}})
    assert json.loads(text)["settings"]["x"] == [[1.0, None]]


# --- finding 4 and C6: a posterior's netCDF holds its fields as they are now, and units ------
class _Chain:
    """The two methods _to_idata reads from an emcee sampler: ``shape`` (steps, walkers,
    parameters) of normal draws about ``centre`` (also tests/test_disk_full.py's)."""

    def __init__(self, shape=(40, 6, 2), seed=1, scale=0.01, centre=0.5):
        self.x = np.random.default_rng(seed).standard_normal(shape) * scale + centre

    def get_chain(self):
        return self.x

    def get_log_prob(self):
        return -0.5 * (self.x ** 2).sum(axis=2)


def _posterior(units=None):
    from bayespilot.sample import Posterior, _to_idata

    tau = {"K_v": 3.0, "delta_abs": 4.0}
    meta = {"parameter_names": ["K_v", "delta_abs"], "tau": tau, "converged": False, "seed": 1,
            "settings": {"likelihood": "eq4", "n_steps": 40, "keep": "yes",
                         "true_parameters": {"delta_abs": 0.01}}}
    args = (_Chain(), ["K_v", "delta_abs"], np.array([3.0, 4.0]), meta)
    idata, meta = _to_idata(*args) if units is None else _to_idata(*args, units)
    return Posterior(idata, ("K_v", "delta_abs"), dict(tau), False, meta["settings"], 1)


def test_posterior_netcdf_writes_its_current_fields(tmp_path):
    from bayespilot.sample import _META_ATTR, Posterior

    post = _posterior()
    frozen = post.idata.posterior.attrs[_META_ATTR]
    post.settings["note"] = "kept?"
    post.tau["K_v"] = 999.0
    del post.settings["keep"]
    changed = dataclasses.replace(post, converged=True, seed=23,
                                  settings=dict(post.settings, true_parameters={"K_v": 1.5}))
    back = Posterior.from_netcdf(changed.to_netcdf(tmp_path / "p.nc"))
    assert_same_fields(changed, back, skip=("idata",))
    assert back.settings["note"] == "kept?" and back.tau["K_v"] == 999.0
    # the attributes for other netCDF readers follow too; a setting removed leaves none behind
    attrs = back.idata.posterior.attrs
    assert attrs["note"] == "kept?" and "keep" not in attrs and attrs["converged"] == 1
    assert attrs["true_K_v"] == 1.5 and "true_delta_abs" not in attrs
    assert back.idata.sample_stats.attrs["note"] == "kept?"
    # the object written is left as it was
    assert changed.idata.posterior.attrs[_META_ATTR] == frozen
    np.testing.assert_array_equal(back.draws("K_v"), post.draws("K_v"))


def test_posterior_netcdf_of_before_the_fix_still_loads(tmp_path):
    """A file as the old to_netcdf wrote it (the idata as sampling left it, no units)."""
    from bayespilot.sample import Posterior

    post = _posterior()
    path = tmp_path / "old.nc"
    post.idata.to_netcdf(str(path))
    back = Posterior.from_netcdf(path)
    assert_same_fields(post, back, skip=("idata",))
    assert "units" not in back.idata.posterior["K_v"].attrs
    again = Posterior.from_netcdf(back.to_netcdf(tmp_path / "again.nc"))
    assert_same_fields(post, again, skip=("idata",))


def test_posterior_variables_carry_units_through_the_file(tmp_path):
    from bayespilot.sample import Posterior

    post = _posterior(units={"K_v": "-", "delta_abs": "IPUT"})
    back = Posterior.from_netcdf(post.to_netcdf(tmp_path / "p.nc"))
    assert {n: back.idata.posterior[n].attrs.get("units") for n in back.parameter_names} \
        == {"K_v": "-", "delta_abs": "IPUT"}

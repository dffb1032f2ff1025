"""diagnose on recordings from other labs: what the bootstrap and the frequency evidence need.

Each case is a valid recording that the paper's never are: a plant the simulator cannot run
(relative degree 1), a task "other" that leaves its plant (or its control gain) out, no
forcing functions, a rounded base frequency, a target-only or disturbance-only run.  The
diagnosis goes on without what it cannot make, and says so once with an EvidenceWarning.
Short records (30 s), two bootstrap replicates and one candidate, so that each test takes
seconds.
"""

from __future__ import annotations

import copy
import math
import warnings

import numpy as np
import pytest

from bayespilot.diagnose import EvidenceWarning, diagnose
from bayespilot.diagnose.locate import SNAP_TOLERANCE, describing_function, forcing_of
from bayespilot.forcing import Multisine
from bayespilot.io import read_recording, write_recording
from bayespilot.presets import paper_parameters
from bayespilot.recording import Recording
from bayespilot.simulate import TrackingTask, simulate

#: Length of the lab records, s (whole periods of their forcing).
T = 30.0
QUICK = dict(seed=0, n_bootstrap=2, candidates=["time-varying-gains"], intervals=False)
#: The frequency-domain evidence, written out (a missing one is NaN, not left out).
FREQUENCY = {"frequency.visual", "frequency.motion_low", "frequency.motion_high",
             "frequency.power_target", "frequency.power_disturbance"}


def lab_task(target_on: bool = True, disturbance_on: bool = True) -> TrackingTask:
    """A lab's task "other": its own multisines over T s, the paper's plant, stated."""
    w0 = 2 * np.pi / T
    nt = np.array([2, 5, 9, 15, 26, 43, 71, 117])
    nd = np.array([3, 7, 11, 19, 31, 53, 83, 131])
    rng = np.random.default_rng(1)
    at = 0.02 / np.sqrt(1 + (w0 * nt / 1.5) ** 2) * target_on
    ad = 0.01 * (1 + w0 * nd / 3) * disturbance_on
    ft = Multisine(w0, nt, at, rng.uniform(0, 2 * np.pi, nt.size))
    fd = Multisine(w0, nd, ad, rng.uniform(0, 2 * np.pi, nd.size))
    return TrackingTask(ft, fd, motion_gain=1.0, duration=T, task="other")


@pytest.fixture(scope="module")
def lab_rec():
    """A lab run (forcing and plant in its metadata), as simulated."""
    return simulate(params=paper_parameters("FD"), task=lab_task(), remnant_gain=0.06,
                    seed=3).recording


def _as_lab_file(rec: Recording, tmp_path, metadata=None, drop=()) -> Recording:
    """``rec`` written with other metadata (and without some columns) and read back."""
    signals = {k: v for k, v in rec.signals.items() if k not in drop}
    out = Recording(signals, rec.sample_rate_hz, rec.motion_gain, rec.task,
                    rec.metadata if metadata is None else metadata)
    write_recording(out, tmp_path / "lab")
    return read_recording(tmp_path / "lab")


def _diagnose(rec, **kw):
    """diagnose with every warning caught: (result, EvidenceWarning texts, other warnings)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = diagnose(rec, **{**QUICK, **kw})
    said = [str(w.message) for w in caught if issubclass(w.category, EvidenceWarning)]
    others = [f"{w.category.__name__}: {w.message}" for w in caught
              if not issubclass(w.category, EvidenceWarning)]
    return res, said, others


def _no_p_values(res) -> bool:
    assert FREQUENCY <= set(res.where), sorted(res.where)  # (not true of an empty where)
    return all(not math.isfinite(e.p_value) for e in res.where.values())


def _frequency_keys(res) -> list[str]:
    """The frequency keys of ``res.where``, which must be exactly :data:`FREQUENCY`."""
    keys = [k for k in res.where if k.startswith("frequency.")]
    assert set(keys) == FREQUENCY, keys
    return keys


def test_a_lab_run_with_forcing_and_plant_is_diagnosed_without_a_warning(lab_rec):
    res, said, others = _diagnose(lab_rec)
    assert said == [] and others == []
    assert res.settings["bootstrap"]["replicates"] == 2
    assert "skipped" not in res.settings["bootstrap"]
    assert len(_frequency_keys(res)) == 5 and len(res.where) > 5
    assert all(math.isfinite(res.where[k].value) for k in res.where)
    assert math.isfinite(res.where["frequency.visual"].p_value)


def test_a_plant_of_relative_degree_one_skips_the_bootstrap_and_says_why(lab_rec, tmp_path):
    # K/s: valid in the recording format and for the fit, but not for the simulator
    meta = {k: v for k, v in lab_rec.metadata.items() if k != "controlled_element_gain"}
    meta["controlled_element"] = {"num": [1.5], "den": [1.0, 0.0]}
    rec = _as_lab_file(lab_rec, tmp_path, meta)
    res, said, others = _diagnose(rec, n_calibrate=2)
    assert others == []
    boot = [s for s in said if "the bootstrap of the located evidence is skipped" in s]
    assert len(boot) == 1, said
    assert rec.source in boot[0]
    assert "relative degree 1" in boot[0] and "simulates the plant" in boot[0]
    assert "no p-values" in boot[0]
    assert any("calibration" in s and "relative degree 1" in s for s in said)
    skipped = res.settings["bootstrap"]["skipped"]
    assert "relative degree 1" in skipped and ">= 2" in skipped
    assert res.settings["bootstrap"]["replicates"] == 0
    assert "relative degree 1" in res.settings["calibration_skipped"]
    assert _no_p_values(res)
    assert math.isfinite(res.where["frequency.visual"].value)  # the statistics are still made
    assert "the bootstrap was skipped" in res.summary()
    assert res.to_dict()["settings"]["bootstrap"]["skipped"] == skipped


def test_a_task_other_that_leaves_its_plant_out_is_told_which_plant_is_simulated(lab_rec,
                                                                                  tmp_path):
    """No controlled_element, no control_gain: the recording format reads the paper's 4/s^2,
    and the bootstrap simulates it; a lab whose plant differs is told (it was silent)."""
    meta = {k: v for k, v in lab_rec.metadata.items()
            if k not in ("controlled_element_gain", "controlled_element", "control_gain")}
    rec = _as_lab_file(lab_rec, tmp_path, meta)
    res, said, others = _diagnose(rec)
    assert others == []
    assert len(said) == 1, said
    assert "which the recording format reads as the paper's plant, 4/s^2" in said[0]
    assert "if yours differs, give it in the sidecar" in said[0]
    assert "skipped" not in res.settings["bootstrap"]
    assert res.settings["bootstrap"]["replicates"] == 2
    # the paper's tasks imply the paper's plant: the bootstrap runs
    paper = Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, "FD", meta)
    res, said, _ = _diagnose(paper)
    assert said == [] and res.settings["bootstrap"]["replicates"] == 2


def test_a_task_other_that_gives_its_plant_but_no_control_gain_is_told_which_gain_is_simulated(
        lab_rec, tmp_path):
    """The plant given, control_gain left out: the recording format reads the paper's 0.69, and
    the bootstrap simulated the loop with it without a word (only a missing plant was told)."""
    meta = {k: v for k, v in lab_rec.metadata.items() if k != "control_gain"}
    assert "controlled_element_gain" in meta
    rec = _as_lab_file(lab_rec, tmp_path, meta)
    assert rec.control_gain == 0.69
    res, said, others = _diagnose(rec)
    assert others == []
    assert len(said) == 1, said
    assert rec.source in said[0]
    assert "gives its plant but no control_gain" in said[0] and "0.69" in said[0]
    assert "if yours differs, give it in the sidecar" in said[0]
    assert res.settings["bootstrap"]["replicates"] == 2
    # nothing to say without a bootstrap, or for the paper's tasks (their gain is the paper's)
    assert _diagnose(rec, n_bootstrap=0)[1] == []
    paper = Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, "FD", meta)
    assert _diagnose(paper)[1] == []


def test_no_forcing_functions_skip_the_bootstrap_and_say_what_to_give(lab_rec, tmp_path):
    meta = {k: v for k, v in lab_rec.metadata.items() if k != "forcing"}
    rec = _as_lab_file(lab_rec, tmp_path, meta, drop=("f_t", "f_d"))
    res, said, others = _diagnose(rec)
    assert others == []
    assert len(said) == 1, said
    assert "no forcing functions are known" in said[0] and "no p-values" in said[0]
    assert "f_t and f_d columns" in said[0] and "base_frequency" in said[0]
    assert "no forcing functions" in res.settings["bootstrap"]["skipped"]
    assert _no_p_values(res)
    assert all(math.isnan(res.where[k].value) for k in _frequency_keys(res))
    # without a bootstrap asked for, only the frequency evidence is missing
    res, said, _ = _diagnose(rec, n_bootstrap=0)
    assert len(said) == 1 and "frequency evidence is missing" in said[0]
    assert "bootstrap" not in said[0] and "skipped" not in res.settings["bootstrap"]


def _with_base_frequency(rec: Recording, w0: float, drop=()) -> Recording:
    meta = copy.deepcopy(dict(rec.metadata))
    meta["forcing"]["base_frequency"] = w0
    signals = {k: v for k, v in rec.signals.items() if k not in drop}
    return Recording(signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta)


def test_a_rounded_base_frequency_is_snapped_to_the_record_bins(lab_rec):
    exact = lab_rec.metadata["forcing"]["base_frequency"]
    rounded = _with_base_frequency(lab_rec, round(exact, 4))  # 0.2094: lines <= 0.025 cycle off
    fo = forcing_of(rounded)
    assert fo.periodic and fo.target.base_frequency == pytest.approx(exact, rel=1e-12)
    assert np.array_equal(fo.k_target, forcing_of(lab_rec).k_target)
    assert len(fo.notes) == 1 and "taken as" in fo.notes[0] and "0.2094" in fo.notes[0]
    res0, said0, _ = _diagnose(lab_rec, n_bootstrap=0)
    res, said, others = _diagnose(rounded, n_bootstrap=0)
    assert said0 == [] and others == []
    assert len(said) == 1 and "DFT bins" in said[0]
    for k in _frequency_keys(res):
        assert math.isfinite(res.where[k].value)
        assert res.where[k].value == pytest.approx(res0.where[k].value, rel=1e-6)
    # without the f_t and f_d columns too (the signals made from the snapped multisines)
    res, _, _ = _diagnose(_with_base_frequency(lab_rec, round(exact, 4), drop=("f_t", "f_d")),
                          n_bootstrap=0)
    assert res.where["frequency.visual"].value == pytest.approx(
        res0.where["frequency.visual"].value, rel=1e-3)


def test_the_paper_printed_base_frequency_is_snapped():
    # the paper prints 0.0767 rad/s for 2 pi / 81.92 s: 0.003 cycle off at the highest line
    rec = simulate(task="FD", remnant_gain=0.06, seed=1).recording
    exact = rec.metadata["forcing"]["base_frequency"]
    assert forcing_of(rec).periodic and forcing_of(rec).notes == ()
    fo = forcing_of(_with_base_frequency(rec, 0.0767))
    assert fo.periodic and fo.target.base_frequency == pytest.approx(exact, rel=1e-12)
    assert np.array_equal(fo.k_disturbance, forcing_of(rec).k_disturbance)


def test_a_base_frequency_beyond_the_tolerance_says_why_the_frequency_evidence_is_missing(
        lab_rec):
    rec = _with_base_frequency(lab_rec, 0.209)  # the highest line 0.27 cycle off
    fo = forcing_of(rec)
    assert not fo.periodic and fo.target.base_frequency == 0.209
    res, said, others = _diagnose(rec, n_bootstrap=0)
    # (and the sidecar's multisine, 0.27 cycle off at its highest line by the end, is said
    # to contradict the f_t/f_d columns, which hold the exact forcing)
    assert others == [] and len(said) == 2, said
    assert "frequency evidence" in said[0] and "is missing" in said[0]
    assert "disturbance line n = 131" in said[0] and "0.27 cycle" in said[0]
    assert "does not match the recording's columns" in said[1]
    assert 0.27 > SNAP_TOLERANCE
    assert all(math.isnan(res.where[k].value) for k in _frequency_keys(res))


@pytest.mark.parametrize("on, zero, only", [((True, False), "f_d", "target only"),
                                            ((False, True), "f_t", "disturbance only")])
def test_one_forcing_function_zero_skips_the_two_input_estimate_cleanly(on, zero, only,
                                                                        tmp_path):
    rec = simulate(params=paper_parameters("FD"), task=lab_task(*on), remnant_gain=0.06,
                   seed=4).recording
    fo = forcing_of(rec)
    assert fo.periodic and not fo.two_input and fo.zero == (zero,)
    with pytest.raises(ValueError, match=f"{zero} is zero throughout"):
        describing_function(rec.u, rec.e, rec.theta_ddot_m, fo)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = diagnose(rec, **QUICK)
        res.report(tmp_path / "report")
    said = [str(w.message) for w in caught if issubclass(w.category, EvidenceWarning)]
    others = [f"{w.category.__name__}: {w.message}" for w in caught
              if not issubclass(w.category, EvidenceWarning)]
    assert others == []  # no divide-by-zero, invalid-value or All-NaN-slice warnings
    assert len(said) == 1, said
    assert zero in said[0] and only in said[0] and "frequency.visual" in said[0]
    for k in ("frequency.visual", "frequency.motion_low", "frequency.motion_high"):
        assert math.isnan(res.where[k].value)
    # the residual's power at the lines of the forcing function that is there; none at the
    # zero one's (it forces no line: its placeholder's bin is not a forced frequency)
    there, gone = (("target", "disturbance") if zero == "f_d" else ("disturbance", "target"))
    k = f"frequency.power_{there}"
    assert math.isfinite(res.where[k].value) and math.isfinite(res.where[k].p_value)
    assert math.isnan(res.where[f"frequency.power_{gone}"].value)
    assert f"frequency.power_{gone} (no forced lines)" in said[0]
    assert res.settings["bootstrap"]["replicates"] == 2
    assert (tmp_path / "report" / "report.html").exists()


def test_the_progress_bar_counts_every_replicate_and_ends_full(lab_rec, monkeypatch):
    """The bar ticks once per bootstrap replicate (the bootstrap was one stage, frozen for
    tens of seconds) and is full when it closes (the refit after it came later)."""
    import tqdm.auto

    bars = []

    class Bar:
        def __init__(self, total=None, **kw):
            self.total, self.n, self.closed_at = total, 0, None
            bars.append(self)

        def update(self, k=1):
            self.n += k
            assert self.n <= self.total, (self.n, self.total)  # never past the end

        def set_postfix_str(self, *a, **k):
            pass

        def refresh(self):
            pass

        def close(self):
            self.closed_at = (self.n, self.total)

    monkeypatch.setattr(tqdm.auto, "tqdm", Bar)
    res, said, others = _diagnose(lab_rec, n_bootstrap=3, progress=True)
    (bar,) = bars
    assert res.settings["bootstrap"]["replicates"] == 3
    assert bar.closed_at == (bar.total, bar.total) and bar.total == 2 + 1 + 3
    # a chosen extension: its refit is one more stage, inside the bar
    from bayespilot.diagnose import get_extension
    from bayespilot.model import paper_model

    model = get_extension("motion-washout").build(paper_model())
    washed = simulate(model, dict(paper_parameters("FD"), omega_w=0.8), task="FD",
                      motion_gain=1.0, remnant_gain=0.063, seed=22, duration=40.96).recording
    res, said, others = _diagnose(washed, candidates=["motion-washout"], progress=True)
    bar = bars[-1]
    assert res.physics == "motion-washout"
    assert bar.closed_at == (bar.total, bar.total) and bar.total == 2 + 1 + 2 + 1


# --- a quantised u on a grid not through 0; a bootstrap whose replicates all fail; a base
# --- fit on a bound of its box (the nuisance audit)
def _with_u(rec: Recording, u) -> Recording:
    signals = dict(rec.signals)
    signals["u"] = np.asarray(u, float)
    return Recording(signals, rec.sample_rate_hz, rec.motion_gain, rec.task, rec.metadata)


def test_a_quantised_u_is_recognised_whatever_its_grid_offset(lab_rec):
    """An 8-bit u, centred (u - mean(u), as the offset warning advises) or on a trimmed grid,
    is as quantised as on a grid through 0: its peaks' repeats are no flat tops."""
    from bayespilot.diagnose.decide import flat_tops
    from bayespilot.diagnose.locate import _grid, _quantum

    q = 1.0 / 2**8
    uq = np.round(lab_rec.u / q) * q
    tops = flat_tops(uq)["n_samples"]
    assert tops > 0  # the peaks repeat on this grid (the false control-saturation's cause)
    for u in (uq, uq - uq.mean(), uq + 0.37 * q, uq - 10.3 * q):
        step, offset = _grid(u)
        assert step == pytest.approx(q, rel=1e-9) and abs(offset) <= q / 2
        assert np.allclose((u - offset) / step, np.rint((u - offset) / step), atol=1e-6)
        assert flat_tops(u)["n_samples"] == tops  # (the count and the limits shift with u)
        assert flat_tops(u)["hi"] - flat_tops(u)["lo"] == pytest.approx(uq.max() - uq.min())
    assert _quantum(lab_rec.u) == 0.0  # full precision
    clipped = np.clip(lab_rec.u, -0.2, 0.2)  # a real limit, unquantised: flat tops decide
    assert _quantum(clipped) == 0.0 and flat_tops(clipped)["n_samples"] > 0
    # the diagnosis: not a finding without a bootstrap (it named control-saturation, p = 0)
    res, said, others = _diagnose(_with_u(lab_rec, uq - uq.mean()), n_bootstrap=0,
                                  candidates=["control-saturation"])
    (sat,) = res.ranking
    assert res.physics == "none" and sat.p_value == 1.0, sat.reason
    assert "u is quantised" in sat.reason and "not a finding" in sat.reason


def test_a_quantised_u_with_a_few_samples_off_its_grid_is_still_quantised(lab_rec):
    """One sample off the grid (ten zeros padded onto a centred 8-bit u, an interpolated
    glitch) made the whole u "full precision", and its peaks' repeats named control-saturation
    at p = 0; now u is quantised when 99 % of its samples are on the grid.  A lab writing 4
    decimals (a grid whose levels are seldom seen twice) is recognised; a continuous u,
    clipped or padded, is not."""
    from bayespilot.diagnose.locate import _grid

    q = 1.0 / 2**8
    uq = np.round(lab_rec.u / q) * q
    centred = uq - uq.mean()
    padded = centred.copy()
    padded[:10] = 0.0
    glitch = centred.copy()
    glitch[1000] = 0.37 * centred[999] + 0.63 * centred[1001] + 0.1 * q
    w4 = np.round(lab_rec.u, 4)  # (as the CSV reads back)
    assert not np.array_equal(w4, np.round(w4 / 1e-4) * 1e-4)  # (not exact multiples of 1e-4)
    for u, step_is, off in ((padded, q, slice(0, 10)), (glitch, q, slice(1000, 1001)),
                            (w4, 1e-4, slice(0, 0)), (w4 - w4.mean(), 1e-4, slice(0, 0))):
        step, offset = _grid(u)
        assert step == pytest.approx(step_is, rel=1e-6) and abs(offset) <= step / 2
        k = (u - offset) / step
        on = np.abs(k - np.rint(k)) < 1e-3
        assert not on[off].any() and np.count_nonzero(~on) == off.stop - off.start
    zeros = lab_rec.u.copy()
    zeros[:10] = 0.0
    for u in (lab_rec.u, np.clip(lab_rec.u, -0.2, 0.2), zeros, np.float32(lab_rec.u)):
        assert _grid(u) == (0.0, 0.0)  # full precision
    # the diagnosis: the padded u's peaks are no finding without a bootstrap (were p = 0)
    res, said, others = _diagnose(_with_u(lab_rec, padded), n_bootstrap=0,
                                  candidates=["control-saturation"])
    (sat,) = res.ranking
    assert res.physics == "none" and sat.p_value == 1.0, sat.reason
    assert "u is quantised" in sat.reason and "not a finding" in sat.reason


def test_bootstrap_replicates_that_all_fail_are_said(lab_rec, monkeypatch):
    """Every replicate's closed loop failing (a sign-flipped u's base fit) left every located
    p-value "n/a" without a word; now an EvidenceWarning, the settings and the summary say it."""
    import sys

    from bayespilot.diagnose import _dropped_note

    def diverges(*args, **kwargs):
        raise RuntimeError("the closed loop diverged")

    monkeypatch.setattr(sys.modules["bayespilot.simulate"], "simulate", diverges)
    res, said, others = _diagnose(lab_rec, n_bootstrap=3)
    assert others == []
    assert len(said) == 1, said
    assert "only 0 of 3 bootstrap replicates survived (3 closed loop(s) diverged)" in said[0]
    assert "destabilises the recorded plant" in said[0] and "control_gain" in said[0]
    assert said[0] == f"{lab_rec.source}: {res.settings['evidence_notes'][0]}"
    boot = res.settings["bootstrap"]
    assert boot["replicates"] == 0 and boot["dropped"] == 3 and boot["diverged"] == 3
    assert all(not math.isfinite(e.p_value) for e in res.where.values())
    line = "only 0 of 3 replicates survived"
    assert line in res.summary()
    assert line in type(res).from_dict(res.to_dict()).summary()
    # some survived: the p-values are coarser, and said so; all survived: nothing
    part = _dropped_note({"replicates": 2, "dropped": 1, "diverged": 0}, 3)
    assert "only 2 of 3" in part and "1 refit(s) failed" in part and "rest on 2" in part
    assert _dropped_note({"replicates": 3, "dropped": 0, "diverged": 0}, 3) is None


def test_a_base_fit_on_a_bound_is_said_and_recorded(lab_rec, tmp_path):
    """A base fit with a pilot parameter on a bound of its box (a sign-flipped recording's:
    omega_nm on 30, tau_m on 0) named physics without a word about it; now a BaseFitWarning,
    in the settings, the JSON and the summary; delta_abs = 0 ("no threshold"), a fixed or an
    unidentified parameter is no such case.  The decision is made as ever."""
    import dataclasses

    from bayespilot.diagnose import BaseFitWarning, _base_at_bounds
    from bayespilot.fit.result import FitResult
    from bayespilot.model import paper_model
    from bayespilot.presets import TABLE1_BOUNDS

    params = dict(paper_parameters("FD"), omega_nm=30.0)
    fit = FitResult(params, -1.0e4, 80.0, "fast", 0, True, bounds=dict(TABLE1_BOUNDS))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = diagnose(lab_rec, seed=0, n_bootstrap=0, candidates=["time-varying-gains"],
                       base_fit=fit, intervals=False)
    said = [str(w.message) for w in caught if issubclass(w.category, BaseFitWarning)]
    assert len(said) == 1, [str(w.message) for w in caught]
    assert "omega_nm = 30 on its upper bound (30, Eq. 4 fit)" in said[0]
    assert "sign or unit convention" in said[0] and "rather than for missing physics" in said[0]
    edge = res.settings["base_at_bounds"]
    assert edge[0] == {"parameter": "omega_nm", "value": 30.0, "side": "upper", "bound": 30.0,
                       "fit": "Eq. 4"}
    assert said[0] == f"{lab_rec.source}: {res.settings['evidence_notes'][0]}"
    res.to_json(tmp_path / "d.json")
    back = type(res).from_json(tmp_path / "d.json")
    assert back.settings["base_at_bounds"] == edge
    for r in (res, back):
        assert "base fit ON A BOUND: omega_nm = 30 (upper bound, Eq. 4)" in r.summary()
    # not said: delta_abs = 0, a parameter fixed or not identified
    m = paper_model()
    quiet = [dataclasses.replace(fit, params=dict(paper_parameters("FD"), delta_abs=0.0)),
             dataclasses.replace(fit, bounds={k: b for k, b in TABLE1_BOUNDS.items()
                                             if k != "omega_nm"}),
             dataclasses.replace(fit, settings={"unidentified": ["omega_nm"]})]
    for f in quiet:
        assert _base_at_bounds(f, None, m) == []
    assert _base_at_bounds(dataclasses.replace(fit, params=dict(params, delta_abs=0.1)),
                           None, m)[1]["parameter"] == "delta_abs"  # its upper bound is one

"""Interactive use (a notebook, a REPL): warnings that name the user's line, results that do not
change under the user's hands, short reprs, progress bars closed however a call ends, ``==`` that
does not raise, and a top-level namespace that tab-completes."""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pytest
import tqdm as tqdm_pkg

import bayespilot
from bayespilot.compare import Comparison, Evidence, PooledComparison, pool
from bayespilot.diagnose import DiagnosisResult, diagnose, diagnose_pooled, get_extension
from bayespilot.diagnose import decide as D
from bayespilot.diagnose.pooled import PooledDiagnosisResult
from bayespilot.sample import ConvergenceWarning, Posterior, sample
from bayespilot.simulate import simulate

#: A chain far too short to converge: a ConvergenceWarning, in about a second.
TINY = dict(n_walkers=16, max_steps=40, min_steps=0, check_every=20, progress=False)


@pytest.fixture(scope="module")
def sim():
    return simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=2, duration=8.0)


@pytest.fixture(scope="module")
def tiny_posterior(sim):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        post = sample(sim.recording, init=sim.params, seed=0, **TINY)
    return post, caught


def _live_bars() -> int:
    return len(getattr(tqdm_pkg.tqdm, "_instances", ()))


def _evidence(log_z, max_log_lik, names=("K_v", "delta_abs")):
    return Evidence(log_z, 0.3, 5.0, max_log_lik, {n: 0.1 for n in names},
                    {n: 0.1 for n in names}, tuple(names), 1000, 100, 1.0,
                    {"nlive": 50, "seed": 1}, np.zeros((500, len(names))), np.full(500, 1 / 500))


def _comparison(source="runs/subject_01/FD_k1_run1.csv"):
    return Comparison(3.2, 0.4, "threshold", _evidence(-100.0, -90.0),
                      _evidence(-103.2, -93.0, ("K_v",)), None,
                      {"delta_aic": 4.0, "delta_bic": 2.0, "neg_log_lik_threshold": 90.0,
                       "neg_log_lik_none": 93.0, "ml_threshold": {"K_v": 1.0, "delta_abs": 0.01},
                       "ml_none": {"K_v": 1.0}},
                      {"likelihood": "eq4", "n_samples": 8192, "runs": 1,
                       "noise": {"ar": [0.5, 0.1]}, "decision_note": ""},
                      seed=0, elapsed=12.0, source=source, plateau_probability=0.01)


def _candidate(physics="motion-washout", justified=True):
    fit = D.FitSummary({"K_v": 1.0, "omega_w": 0.4}, 100.0, ("omega_w",), np.eye(1))
    return D.CandidateResult(physics, True, delta_neg_log_lik=12.0, statistic=24.0, df=1,
                             p_value=1e-5, delta_bic=20.0, log_bayes_factor=10.0,
                             params={"omega_w": 0.4}, stderr={"omega_w": 0.05},
                             all_params={"K_v": 1.0, "omega_w": 0.4}, justified=justified,
                             fit=fit)


def _diagnosis():
    chosen = _candidate()
    ranking = [chosen, _candidate("time-varying-gains", justified=False)]
    return DiagnosisResult(True, "motion-washout", ranking, {}, {"neg_log_lik": 100.0,
                                                                 "vaf": 90.0},
                           chosen, {"alpha": 0.05, "n_tested": 2, "skip_seconds": 5.0}, 3.0,
                           source="runs/subject_01/FD_k1_run1.csv",
                           arrays={"residual": np.zeros(8192), "u": np.ones(8192)})


# --- 1. warnings name the caller's line ------------------------------------------------------------
def test_sample_convergence_warning_names_the_callers_line(tiny_posterior):
    _, caught = tiny_posterior
    conv = [w for w in caught if issubclass(w.category, ConvergenceWarning)]
    assert conv, "a 40-step chain converged?"
    assert conv[0].filename == __file__  # not bayespilot/_blas.py
    assert conv[0].message.n_steps == 40 and conv[0].message.tau is not None  # still carried


def test_warn_at_caller_takes_a_warning_instance():
    from bayespilot._caller import warn_at_caller

    with pytest.warns(ConvergenceWarning, match="short") as caught:
        warn_at_caller(ConvergenceWarning("too short", np.ones(2), 7))
    assert caught[0].filename == __file__ and caught[0].message.n_steps == 7
    with pytest.warns(RuntimeWarning, match="plain") as caught:
        warn_at_caller("plain", RuntimeWarning)
    assert caught[0].filename == __file__


@pytest.mark.filterwarnings("ignore:.*not a whole number of periods:RuntimeWarning")
def test_compare_mode_check_warning_names_the_callers_line(sim, monkeypatch):
    """Every threshold run misses the main mode: the warning is at the call of compare()."""
    from bayespilot import compare as C

    truth = dict(sim.params)

    def fake_evidence(recording, model, **kw):
        names = tuple(model.parameter_names)
        best = {n: truth[n] for n in names}
        lost = "delta_abs" in names  # the model with threshold: its best ln L far too low
        return Evidence(-100.0, 0.3, 5.0, -1e4 if lost else -50.0, best, best, names, 10, 10,
                        0.0, {"nlive": 40, "seed": kw.get("seed")})

    monkeypatch.setattr(C, "evidence", fake_evidence)
    with pytest.warns(RuntimeWarning, match="missed the main mode") as caught:
        bayespilot.compare(sim.recording, nlive=40, runs=1, seed=0, savage_dickey_samples=False)
    mine = [w for w in caught if "missed the main mode" in str(w.message)]
    assert mine[0].filename == __file__


class _Stop(Exception):
    pass


def _relabelled(rec, subject=None, shift=0.0):
    """``rec`` with another subject in its metadata and ``shift`` added to u."""
    from bayespilot.recording import Recording

    signals = dict(rec.signals, u=rec.signals["u"] + shift)
    return Recording(signals, rec.sample_rate_hz, rec.motion_gain, rec.task,
                     {} if subject is None else {"subject": subject})


def test_pooling_warning_names_the_callers_line(sim, monkeypatch):
    from bayespilot.diagnose import pooled as P

    def stop(rec, **kw):
        raise _Stop

    monkeypatch.setattr(P, "_prepare", stop)
    a = _relabelled(sim.recording, "s1")
    b = _relabelled(sim.recording, "s2", shift=1e-3)  # not a repeat of a
    with pytest.warns(P.PoolingWarning) as caught, pytest.raises(_Stop):
        diagnose_pooled([a, b], skip_seconds=2.0)
    assert caught[0].filename == __file__


def test_campaign_cache_warning_names_the_callers_line(monkeypatch, tmp_path):
    """A failed warm-up of numba's cache warns at the caller's line, whatever calls run_keyed."""
    from bayespilot import campaign as C

    class Client:
        def submit(self, fn, *args, pure=False):
            return object()

    def warm():
        raise RuntimeError("no cache")

    monkeypatch.setattr(C, "_connect", lambda stack, *a: Client())
    monkeypatch.setattr("tqdm.auto.tqdm", _raise_stop)  # stop before waiting on the futures
    with pytest.warns(RuntimeWarning, match="warming numba's cache failed") as caught, \
            pytest.raises(_Stop):
        C.run_keyed([("k", len, ((),), {})], tmp_path, total=1, skipped=0, scheduler=None,
                    workers=1, progress=False, connect_timeout=1, warm=warm)
    assert caught[0].filename == __file__


def _raise_stop(*args, **kwargs):
    raise _Stop


# --- 2. draws are the user's to change ---------------------------------------------------------------
def test_draws_is_a_copy(tiny_posterior, tmp_path):
    post, _ = tiny_posterior
    for p in (post, Posterior.from_netcdf(post.to_netcdf(tmp_path / "p.nc"))):
        before = p.draws("delta_abs").copy()
        d = p.draws("delta_abs")
        d *= 1000
        np.testing.assert_array_equal(p.draws("delta_abs"), before)
        assert p.truth is not p.settings.get("true_parameters")


# --- 3. short reprs -----------------------------------------------------------------------------------
def _one_short_line(text: str, *words: str) -> None:
    assert "\n" not in text and len(text) < 200, text
    for w in words:
        assert w in text, (w, text)


def test_posterior_repr_is_one_short_line(tiny_posterior, tmp_path):
    post, _ = tiny_posterior
    _one_short_line(repr(post), "Posterior", "8 parameters", "NOT converged", "16 walkers")
    back = Posterior.from_netcdf(post.to_netcdf(tmp_path / "p.nc"))
    assert repr(back) == repr(post)
    bare = Posterior(None, ("a",), {}, True)  # no InferenceData: still a repr
    _one_short_line(repr(bare), "1 parameters", "converged")


def test_comparison_repr_is_one_short_line(tmp_path):
    c = _comparison()
    _one_short_line(repr(c), "<Comparison", "+3.20", "0.40", "threshold", "N = 8192", "run1.csv")
    back = Comparison.from_json(c.to_json(tmp_path / "c.json"))
    assert repr(back) == repr(c)
    nothing = Comparison.from_dict({"log_bayes_factor": None, "log_bayes_factor_err": None,
                                    "decision": "inconclusive",
                                    "evidence_threshold": c.evidence_threshold.to_dict(),
                                    "evidence_none": c.evidence_none.to_dict(),
                                    "information_criteria": {}})
    _one_short_line(repr(nothing), "nan", "inconclusive")


def test_pooled_comparison_repr_and_str(tmp_path):
    c = _comparison()
    p = pool([c, c.to_dict()], label="FD, K_theta = 1")
    _one_short_line(repr(p), "<PooledComparison", "FD, K_theta = 1", "2 recordings", "+6.40")
    assert str(p) == p.summary()
    back = PooledComparison.from_json(p.to_json(tmp_path / "p.json"))
    assert repr(back) == repr(p) and str(back) == str(p)


def test_diagnosis_reprs_are_one_short_line(tmp_path):
    d = _diagnosis()
    _one_short_line(repr(d), "<DiagnosisResult", "motion-washout", "2 candidates", "run1.csv")
    d.to_json(tmp_path / "d.json")
    back = DiagnosisResult.from_json(tmp_path / "d.json")
    _one_short_line(repr(back), "<DiagnosisResult", "motion-washout", "2 candidates")
    none = DiagnosisResult(False, "none", [], {}, {}, None, {}, 0.0)
    _one_short_line(repr(none), "no extension justified", "0 candidates")
    pooled = PooledDiagnosisResult(True, "motion-washout", d.ranking, [{}, {}], {}, d.chosen,
                                   {}, 1.0, arrays={"x": np.zeros(10000)})
    _one_short_line(repr(pooled), "<PooledDiagnosisResult", "motion-washout", "2 runs",
                    "2 candidates")


# --- 4. progress bars closed however a call ends -------------------------------------------------------
def _interrupt(*args, **kwargs):
    raise KeyboardInterrupt


def test_diagnose_closes_its_bar_when_interrupted(sim, monkeypatch):
    from bayespilot import diagnose as Dg

    monkeypatch.setattr(Dg, "_prepare", _interrupt)
    before = _live_bars()
    with pytest.raises(KeyboardInterrupt) as info:
        diagnose(sim.recording, skip_seconds=2.0, progress=True)
    assert _live_bars() == before, info  # (info keeps the frames, as a REPL's last traceback)


def test_diagnose_pooled_closes_its_bar_when_interrupted(sim, monkeypatch):
    from bayespilot.diagnose import pooled as P

    monkeypatch.setattr(P, "_prepare", _interrupt)
    other = _relabelled(sim.recording, shift=1e-3)
    before = _live_bars()
    with pytest.raises(KeyboardInterrupt) as info:
        diagnose_pooled([sim.recording, other], skip_seconds=2.0, progress=True)
    assert _live_bars() == before, info  # (info keeps the frames, as a REPL's last traceback)


def test_shared_posterior_closes_its_bar_when_interrupted(sim, monkeypatch):
    from bayespilot.diagnose import pooled as P
    from bayespilot.diagnose import posterior as SP
    from bayespilot.model import paper_model

    model = get_extension("motion-washout").build(paper_model())
    chosen = _candidate()
    chosen.model, chosen.fit = model, None
    fits = [dict(sim.params, omega_w=0.4)]

    class Whitened:
        def __init__(self, *a):
            pass

        def neg_log_lik(self, q):
            return 0.0

    monkeypatch.setattr(SP, "_check_pooled", lambda *a: (chosen, fits, [sim.recording]))
    monkeypatch.setattr(D, "Whitened", Whitened)
    monkeypatch.setattr(P, "_pooled_refine", _interrupt)
    result = PooledDiagnosisResult(True, "motion-washout", [chosen], [{}], {}, chosen, {}, 0.0,
                                   arrays={"noise": [None]})
    before = _live_bars()
    with pytest.raises(KeyboardInterrupt) as info:
        SP.shared_posterior(result, [sim.recording], progress=True)
    assert _live_bars() == before, info  # (info keeps the frames, as a REPL's last traceback)


# --- 5. tqdm.auto: a widget in a notebook ---------------------------------------------------------------
def test_genetic_step_one_uses_tqdm_auto(monkeypatch):
    from bayespilot.fit import genetic as G

    made = []

    class Bar:
        def __init__(self, *a, **kw):
            made.append(kw)

        def update(self, n):
            pass

        def set_postfix(self, **kw):
            pass

        def close(self):
            pass

    class Lik:
        class model:
            parameter_names = ("a", "b")
            bounds = (np.zeros(2), np.ones(2))

        @staticmethod
        def batch(x):
            return np.sum((np.atleast_2d(x) - 0.3) ** 2, axis=1)

    monkeypatch.setattr("tqdm.auto.tqdm", Bar)
    G.step_one(Lik(), repetitions=2, n_best=1, seed=0, progress=True, population=8,
               generations=2)
    assert made and made[0]["total"] == 2


def test_campaign_bar_uses_tqdm_auto(monkeypatch, tmp_path):
    from bayespilot import campaign as C

    class Client:
        def submit(self, fn, *args, pure=False):
            return object()

    monkeypatch.setattr(C, "_connect", lambda stack, *a: Client())
    monkeypatch.setattr("tqdm.auto.tqdm", _raise_stop)
    with pytest.raises(_Stop):
        C.run_keyed([("k", len, ((),), {})], tmp_path, total=1, skipped=0, scheduler=None,
                    workers=1, progress=True, connect_timeout=1)


# --- 6. to_dict is a copy -----------------------------------------------------------------------------
def test_comparison_to_dict_is_a_copy():
    c = _comparison()
    d = c.to_dict()
    d["settings"]["likelihood"] = "changed"
    d["settings"]["noise"]["ar"].append(9.0)
    d["information_criteria"]["delta_aic"] = -1.0
    d["information_criteria"]["ml_threshold"]["K_v"] = -1.0
    d["evidence_threshold"]["settings"]["nlive"] = -1
    assert c.settings["likelihood"] == "eq4" and c.settings["noise"]["ar"] == [0.5, 0.1]
    assert c.information_criteria["delta_aic"] == 4.0
    assert c.information_criteria["ml_threshold"]["K_v"] == 1.0
    assert c.evidence_threshold.settings["nlive"] == 50
    assert c.to_dict() == _comparison().to_dict()


# --- 7. == does not raise -------------------------------------------------------------------------------
def test_results_with_arrays_compare_by_identity():
    d = _diagnosis()
    for obj in (d, d.chosen, d.chosen.fit,
                PooledDiagnosisResult(True, "x", [], [], {}, None, {}, 0.0,
                                      arrays={"x": np.zeros(3)})):
        twin = copy.deepcopy(obj)
        assert obj == obj and not (obj == twin) and obj != twin
        assert obj in [twin, obj]
    assert d.ranking.index(d.chosen) == 0


def test_calibrations_profiles_and_bayes_factors_compare_by_identity():
    """Value equality of a Calibration or ProfileInterval compared their arrays and raised
    "The truth value of an array ... is ambiguous"; an ExtensionBayesFactor holds two
    posteriors."""
    from bayespilot.diagnose.calibrate import Calibration
    from bayespilot.diagnose.nested import ExtensionBayesFactor
    from bayespilot.diagnose.profile import ProfileInterval

    cal = Calibration("motion-washout", 2, 1.0, 0.5, 2.0, 0.1, 0.2, 0.3, np.array([1.0, 2.0]))
    prof = ProfileInterval("K_v", 0.95, 1.0, 2.0, values=np.zeros(3), deviance=np.zeros(3))
    bf = ExtensionBayesFactor("motion-washout", 1.0, 0.1, "positive", "extended", None,
                              np.zeros(2), np.zeros(2))
    for obj, twin in ((cal, Calibration.from_dict(cal.to_dict())), (prof, copy.deepcopy(prof)),
                      (bf, copy.deepcopy(bf))):
        assert obj == obj and not (obj == twin) and obj != twin
        assert obj in [twin, obj]


# --- 8. the top-level namespace ---------------------------------------------------------------------
def test_top_level_namespace_is_clean_and_completes():
    names = dir(bayespilot)
    assert "sample" in names and "compare" in names and "__version__" in names
    assert "PackageNotFoundError" not in names and "version" not in names
    assert set(bayespilot.__all__) == {"sample", "compare"}
    for n in bayespilot.__all__:
        assert callable(getattr(bayespilot, n))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        bayespilot.nope  # noqa: B018
    assert isinstance(bayespilot.__version__, str)


def test_a_fit_and_a_likelihood_have_one_line_reprs_and_the_fits_dict_is_a_copy():
    """A fit_paper result's dataclass repr held every GA history (464,000 characters when
    typed in a notebook); to_dict() handed out its settings and steps by reference."""
    from bayespilot.fit.fast import fit_fast
    from bayespilot.likelihood import Likelihood
    from bayespilot.model import paper_model
    from bayespilot.simulate import simulate

    rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.15, seed=2).recording
    fit = fit_fast(rec, seed=0, n_starts=1, profile_step=0.05)
    r = repr(fit)
    assert r.startswith("<FitResult fast: 8 parameters (with threshold), -ln L = ")
    assert "\n" not in r and len(r) < 200 and f"{fit.vaf:.1f} %" in r
    d = fit.to_dict()
    d["settings"]["n_starts"] = 123
    d["steps"]["added"] = 1
    assert fit.settings["n_starts"] == 1 and "added" not in fit.steps
    # ... and its own dicts refuse in-place changes (fit.params["K_v"] = 999 was saved by
    # to_json and then reported beyond its bound by from_json)
    with pytest.raises(TypeError, match=r"a FitResult's params, settings, steps, bounds and "
                                        r"units cannot be changed in place: copy them "
                                        r"\(dict\(fit.params\), fit.to_dict\(\)\)"):
        fit.params["K_v"] = 999.0
    with pytest.raises(TypeError, match="cannot be changed in place"):
        fit.steps["profile_grid"].append(0.2)
    assert fit.to_dict()["params"]["K_v"] == fit.params["K_v"] != 999.0
    lik = Likelihood(paper_model(), rec)
    assert repr(lik) == ("<Likelihood: Pool et al. (2012), 8 free parameters, N = 8192 at 100 Hz, "
                         f"initial='periodic', discard 0 s, white noise, {rec.source}>")


def test_plots_keep_a_backend_chosen_by_mplbackend_on_a_headless_machine():
    """Jupyter's kernel chooses its inline backend through MPLBACKEND: on a server without a
    display the plots replaced it with Agg, and the notebook showed no figures."""
    import os
    import subprocess
    import sys

    code = ("import matplotlib; from bayespilot.plots import _pyplot; _pyplot(); "
            "print(matplotlib.get_backend())")
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "MPLBACKEND")}
    chosen = subprocess.run([sys.executable, "-c", code], env=dict(env, MPLBACKEND="svg"),
                            capture_output=True, text=True, check=True).stdout.strip()
    default = subprocess.run([sys.executable, "-c", code], env=env,
                             capture_output=True, text=True, check=True).stdout.strip()
    assert chosen == "svg"
    if sys.platform.startswith("linux"):
        assert default.lower() == "agg"  # no display, nothing chosen: Agg, as before


def test_a_recordings_signals_and_metadata_refuse_changes_and_stay_read_only_when_copied():
    """rec.signals["u"] = ... replaced u without any check, rec.metadata[...] = ... changed
    the plant the bootstrap simulates, and a pickled or deep-copied recording (a dask
    worker's) came back with writable arrays."""
    import json
    import pickle

    from bayespilot.simulate import simulate

    rec = simulate(task="FD", motion_gain=1.0, seed=1, duration=5.0).recording
    with pytest.raises(TypeError, match="cannot be changed in place"):
        rec.signals["u"] = np.zeros(rec.n_samples)
    with pytest.raises(TypeError, match="cannot be changed in place"):
        rec.metadata["controlled_element_gain"] = 99.0
    with pytest.raises(TypeError):
        rec.metadata.update(control_gain=1.0)
    assert rec.metadata["controlled_element_gain"] == 4.0
    for back in (pickle.loads(pickle.dumps(rec)), copy.deepcopy(rec)):
        assert not back.u.flags.writeable and np.array_equal(back.u, rec.u)
        assert back.metadata == rec.metadata and back.source == rec.source
        with pytest.raises(TypeError):
            back.signals["e"] = back.e
    # at every depth (the forcing, the plant), and apart from the caller's own dicts
    with pytest.raises(TypeError, match="cannot be changed in place"):
        rec.metadata["forcing"]["base_frequency"] = 1.0
    with pytest.raises(TypeError, match="cannot be changed in place"):
        rec.metadata["forcing"]["target"]["n"].append(3)
    from bayespilot.recording import Recording

    plant = {"num": [4.0], "den": [1.0, 0.0, 0.0]}
    own = Recording(dict(rec.signals), rec.sample_rate_hz, rec.motion_gain, "other",
                    {"controlled_element": plant})
    plant["num"][0] = 99.0
    assert own.controlled_element[0].tolist() == [4.0]
    # still a dict wherever one is read
    assert json.loads(json.dumps(rec.metadata)) == json.loads(json.dumps(dict(rec.metadata)))
    assert set(dict(rec.signals, u=rec.u)) == set(rec.signals)

"""The pilot model as data (names, bounds, Table 1) and its extension point.

The extension check adds a first-order washout s / (s + omega_w) after the
canal model and verifies the likelihood kernel against ``tests/naive.py``
with the same extra Tustin filter, its limit omega_w -> 0, the parameter
bookkeeping, and the closed-loop simulator with the extended model.
"""

from __future__ import annotations

import numpy as np
import pytest

import naive
from bayespilot import presets
from bayespilot.likelihood import Likelihood
from bayespilot.model import (Channel, DeadZone, FixedFilter, LinearDrift, MotionSystem, Parameter,
                              Saturation, SecondOrderWashout, SoftDeadZone, Washout, paper_model)
from bayespilot.simulate import simulate

FD = dict(presets.TABLE3["FD"])
OMEGA_W = Parameter("omega_w", 0.01, 10.0, 0.5, "rad/s")


def washout_model():
    return paper_model().add_stage("vestibular", Washout("omega_w"), [OMEGA_W])


def washout_tf(params):
    """The extra stage for naive.py: s / (s + omega_w)."""
    return [1.0, 0.0], [1.0, params["omega_w"]]


def _base(params):
    return {k: v for k, v in params.items() if k != "omega_w"}


# --- the paper's model ------------------------------------------------------------------
def test_paper_model_names_order_and_table1_bounds():
    m = paper_model()
    assert m.parameter_names == ("K_v", "T_vl", "tau_v", "K_m", "tau_m", "omega_nm", "zeta_nm",
                                 "delta_abs")
    assert m.parameter_names == presets.PARAMETER_NAMES
    assert m.n_free == 8
    lo, hi = m.bounds
    assert np.array_equal(lo, [presets.TABLE1_BOUNDS[n][0] for n in m.parameter_names])
    assert np.array_equal(hi, [presets.TABLE1_BOUNDS[n][1] for n in m.parameter_names])
    # spot-check Table 1 itself
    assert presets.TABLE1_BOUNDS["omega_nm"] == (5.0, 30.0)
    assert presets.TABLE1_BOUNDS["delta_abs"] == (0.0, 0.1)
    assert m.defaults == FD
    assert [c.name for c in m.channels] == ["visual", "vestibular"]
    assert m.channels[1].sign == -1.0 and m.channels[0].sign == 1.0


def test_threshold_free_model():
    m7 = paper_model(threshold=False)
    assert m7.n_free == 7
    assert m7.parameter_names == presets.PARAMETER_NAMES[:7]
    assert m7.fixed == {"delta_abs": 0.0}
    assert not m7.has_threshold and paper_model().has_threshold
    lo, hi = m7.bounds
    assert lo.shape == hi.shape == (7,)
    full = m7.full_vector(m7.free_vector(FD))
    assert full[-1] == 0.0 and np.array_equal(full[:7], [FD[n] for n in m7.parameter_names])
    # fixing and freeing round-trips
    assert paper_model().fix(delta_abs=0.0).n_free == 7
    assert m7.free("delta_abs").n_free == 8


def test_vector_dict_round_trip():
    m = paper_model()
    vec = m.free_vector(dict(FD, tau_v=0.3))
    assert m.as_dict(vec)["tau_v"] == 0.3
    assert np.array_equal(m.full_vector(m.as_dict(vec)), vec)


# --- extension: a washout after the canals ----------------------------------------------
def test_washout_parameter_bookkeeping():
    m = washout_model()
    assert m.parameter_names == presets.PARAMETER_NAMES + ("omega_w",)
    assert m.n_free == 9
    lo, hi = m.bounds
    assert (lo[-1], hi[-1]) == (0.01, 10.0)
    assert np.array_equal(lo[:8], paper_model().bounds[0])
    assert m.defaults["omega_w"] == 0.5
    assert "omega_w" in m.channels[1].parameter_names
    assert len(m.channels[1].stages) == 2
    # the base model is unchanged (models are values)
    assert paper_model().n_free == 8
    assert m.fix(omega_w=0.3).n_free == 8


def test_washout_response_matches_naive_rest(fd_sim):
    rec = fd_sim.recording
    m = washout_model()
    lik = Likelihood(m, rec, initial="rest")
    for params in (dict(FD, omega_w=0.5), dict(FD, omega_w=3.7, tau_m=0.1234, delta_abs=0.001)):
        ref = naive.naive_response(params, rec.e, rec.theta_ddot_m, rec.dt, "rest", 0,
                                   extra_vestibular=[washout_tf])
        assert np.max(np.abs(lik.response(params) - ref)) < 1e-10 * np.std(ref)
        nll = naive.naive_neg_log_lik(params, rec.u, rec.e, rec.theta_ddot_m, rec.dt, "rest", 0,
                                      extra_vestibular=[washout_tf])
        assert lik.neg_log_lik(params) == pytest.approx(nll, rel=1e-9, abs=0)


def test_washout_response_matches_naive_periodic(fd_sim, fd_rec):
    """Periodic steady state of a first-order parametric stage (a regression test: Tustin
    of a first-order stage must stay first order, with no cancelled pole at z = -1), slow
    ones included (omega_w = 0.02 rad/s: a 50-s time constant, which a warm-up over the
    record's last seconds would leave as a start-up transient)."""
    m = washout_model()
    for params in (dict(FD, omega_w=0.5), dict(FD, omega_w=7.3, tau_m=0.0042),
                   dict(FD, omega_w=0.02)):
        # without theta the whole chain is the documented periodic one ...
        lik = Likelihood(m, fd_rec, initial="periodic")
        ref = naive.naive_response(params, fd_rec.e, fd_rec.theta_ddot_m, fd_rec.dt, "periodic",
                                   lik.warm, extra_vestibular=[washout_tf])
        assert np.max(np.abs(lik.response(params) - ref)) < 1e-10 * np.std(ref)
        # ... with theta, the stages after the likelihood's own canal output i
        rec = fd_sim.recording
        lik = Likelihood(m, rec, initial="periodic")
        ref = naive.naive_response(params, rec.e, rec.theta_ddot_m, rec.dt, "periodic",
                                   lik.warm, extra_vestibular=[washout_tf],
                                   canal_output=lik.X[1])
        assert np.max(np.abs(lik.response(params) - ref)) < 1e-10 * np.std(ref)


@pytest.mark.parametrize("stage, new, tf", [
    (MotionSystem(), {"omega_ms": 6.0, "zeta_ms": 0.7},
     lambda p: ([p["omega_ms"] ** 2], [1.0, 2 * p["zeta_ms"] * p["omega_ms"], p["omega_ms"] ** 2])),
    (SecondOrderWashout(), {"omega_w": 0.5, "zeta_w": 0.7},
     lambda p: ([1.0, 0.0, 0.0], [1.0, 2 * p["zeta_w"] * p["omega_w"], p["omega_w"] ** 2])),
], ids=["motion-system", "second-order-washout"])
def test_second_order_stage_matches_naive_periodic(fd_rec, stage, new, tf):
    """The periodic steady state of a second-order parametric stage (the motion-system and
    second-order washout entries) against naive.py's steady filter: reading the input's
    history x[-1] for x[-2] moved u_hat by 4e-4 of its sd and passed every other test (the
    first-order washout has no x[-2])."""
    m = paper_model().add_stage("vestibular", stage,
                                [Parameter(n, 0.01, 50.0, v) for n, v in new.items()])
    params = dict(FD, **new)
    lik = Likelihood(m, fd_rec, initial="periodic")
    ref = naive.naive_response(params, fd_rec.e, fd_rec.theta_ddot_m, fd_rec.dt, "periodic",
                               lik.warm, extra_vestibular=[tf])
    assert np.max(np.abs(lik.response(params) - ref)) < 1e-10 * np.std(ref)


def test_washout_tends_to_base_model(fd_sim):
    rec = fd_sim.recording
    lik_w = Likelihood(washout_model(), rec, initial="rest")
    lik_0 = Likelihood(paper_model(), rec, initial="rest")
    base = lik_0.response(FD)
    diffs = []
    for om in (1e-3, 1e-6, 1e-9):
        diffs.append(np.max(np.abs(lik_w.response(dict(FD, omega_w=om)) - base)) / np.std(base))
    assert diffs[-1] < 1e-7
    assert diffs[0] > diffs[1] > diffs[2]


def test_simulator_runs_with_washout_and_likelihood_explains_it():
    m = washout_model()
    truth = dict(FD, omega_w=0.5)
    sim = simulate(m, params=truth, duration=10.0, remnant_fraction=0.0)
    assert sim.params == truth
    assert sim.remnant_gain == 0.0
    rec = sim.recording
    assert rec.n_samples == 1000
    lik = Likelihood(m, rec, initial="rest")
    assert lik.vaf(truth) > 99.0
    # ... and the washout matters: the base model at the same values explains less
    assert Likelihood(paper_model(), rec, initial="rest").vaf(_base(truth)) < lik.vaf(truth) - 1.0


# --- errors ---------------------------------------------------------------------------
def test_unknown_channel():
    with pytest.raises(KeyError, match="otolith.*visual, vestibular"):
        paper_model().add_stage("otolith", Washout("omega_w"), [OMEGA_W])


@pytest.mark.parametrize("build", [
    lambda m: m.add_stage("vestibuler", Washout("omega_w"), [OMEGA_W]),
    lambda m: m.with_nonlinearity("otolith", None),
    lambda m: m.with_modulation("otolith", None),
    lambda m: m.with_oversampling(8, ["otolith"]),
    lambda m: m.with_oversampling(8, "otolith"),
])
def test_unknown_channel_is_a_value_error_naming_the_channels(build):
    """A ValueError (still a KeyError, as before) whose message is not wrapped in quotes."""
    with pytest.raises(ValueError) as err:
        build(paper_model())
    msg = str(err.value)
    assert msg.startswith("no channel '") and msg.endswith("channels: visual, vestibular"), msg
    assert isinstance(err.value, KeyError)


def test_with_oversampling_takes_one_channel_name_as_a_string():
    m = paper_model().with_oversampling(8, "visual")
    assert [c.oversample for c in m.channels] == [8, 1]
    assert m.name == paper_model().with_oversampling(8, ["visual"]).name
    assert m.name.endswith("8x visual")


@pytest.mark.parametrize("build, message", [
    # the kind codes overlap between families: a Washout (stage 2) would run as a soft dead zone
    (lambda m: m.with_nonlinearity("vestibular", Washout("omega_w"), [OMEGA_W]),
     "nonlinearity must be a Nonlinearity.*got Washout"),
    (lambda m: m.with_modulation("visual", DeadZone("d3"), [Parameter("d3", 0.0, 1.0, 0.5)]),
     "modulation must be a Modulation.*got DeadZone"),
    (lambda m: m.add_stage("vestibular", DeadZone("d2"), [Parameter("d2", 0.0, 1.0, 0.5)]),
     "stage must be a Stage.*got DeadZone"),
    (lambda m: m.with_output(LinearDrift("g"), [Parameter("g", -1.0, 1.0, 0.0)]),
     "output block must be a Nonlinearity.*got LinearDrift"),
    (lambda m: m.add_channel(Channel("c", "e", delay="tau_v", stages=(Saturation("u_max"),)),
                             [Parameter("u_max", 0.1, 1.0, 0.5)]),
     "channel 'c': a stage must be a Stage"),
    (lambda m: m.add_channel(Channel("c", "e", delay="tau_v", nonlinearity=Washout("omega_w")),
                             [OMEGA_W]),
     "channel 'c': the nonlinearity must be a Nonlinearity"),
])
def test_block_of_the_wrong_family_is_refused(build, message):
    with pytest.raises(TypeError, match=message):
        build(paper_model())


def test_blocks_of_the_right_family_and_none_are_accepted():
    m = paper_model()
    m = m.with_nonlinearity("vestibular", SoftDeadZone("delta_abs", "w_soft"),
                            [Parameter("w_soft", 1e-5, 0.05, 0.002)])
    m = m.with_modulation("visual", LinearDrift("g_v"), [Parameter("g_v", -1.0, 1.0, 0.0)])
    m = m.with_output(Saturation("u_max"), [Parameter("u_max", 1e-6, 10.0, 1.0)])
    m = m.add_stage("vestibular", Washout("omega_w"), [OMEGA_W])
    assert m.n_free == 12
    m = m.with_nonlinearity("vestibular", None).with_modulation("visual", None).with_output(None)
    assert m.channels[1].nonlinearity is None and m.channels[0].modulation is None
    assert m.output is None


def test_improper_fixed_filter_with_leading_zeros_is_refused():
    """(s + 2) / (0 s + 1) is improper: the simulator dropped its s term, the likelihood put a
    pole at z = -1.  Leading zeros are removed before the order check."""
    with pytest.raises(ValueError, match="proper transfer function"):
        FixedFilter((1.0, 2.0), (0.0, 1.0))
    with pytest.raises(ValueError, match="proper transfer function"):
        FixedFilter((1.0, 0.0, 0.0), (0.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="denominator must not be zero"):
        FixedFilter((1.0,), (0.0, 0.0))
    with pytest.raises(ValueError, match="proper transfer function"):
        FixedFilter((1.0,), (0.0, 1.0, 1.0, 1.0, 1.0))
    # leading zeros are harmless once stripped (the kernels' coefficients are unchanged)
    f = FixedFilter((0.0, 0.0, 3.0), (0.0, 2.0, 1.0))
    assert (f.num, f.den) == ((3.0,), (2.0, 1.0))
    np.testing.assert_array_equal(f.constants(), FixedFilter((3.0,), (2.0, 1.0)).constants())
    assert FixedFilter((0.0,), (0.0, 1.0)).num == (0.0,)  # a zero numerator keeps one coefficient
    assert FixedFilter((0.0, 1.0, 2.0), (0.0, 0.0, 1.0, 1.0)).den == (1.0, 1.0)


def test_complex_values_are_refused_not_truncated():
    m = paper_model()
    v = m.free_vector(FD)
    with pytest.raises(ValueError, match="real"):
        m.full_vector(v + 1j)
    with pytest.raises(ValueError, match="real"):
        m.full_vector(list(v[:-1]) + [np.complex128(0.01 + 1j)])
    with pytest.raises(ValueError, match="K_v must be a real number"):
        m.full_vector({"K_v": np.complex128(1 + 2j)})
    with pytest.raises(ValueError, match="delta_abs must be a real number"):
        m.fix(delta_abs=np.complex128(0.01 + 1j))
    with pytest.raises(ValueError, match="real number"):
        FixedFilter((np.complex128(1 + 1j),), (1.0, 1.0))
    # real numpy scalars still work
    assert m.full_vector({"K_v": np.float32(1.5)})[0] == 1.5
    assert m.fix(delta_abs=np.float64(0.01)).fixed == {"delta_abs": 0.01}


def test_a_parameter_declared_again_must_be_declared_alike():
    """A new declaration of an existing name was silently dropped, even with other bounds."""
    with pytest.raises(ValueError, match="K_v is already declared with bounds \\[0, 10\\]"):
        paper_model().add_stage("vestibular", Washout("K_v"), [Parameter("K_v", 0.0, 100.0, 50.0)])
    with pytest.raises(ValueError, match="omega_w is already declared"):
        washout_model().add_stage("visual", Washout("omega_w"), [Parameter("omega_w", 0.01, 10.0, 0.7)])
    with pytest.raises(ValueError, match="unit"):
        washout_model().add_stage("visual", Washout("omega_w"), [Parameter("omega_w", 0.01, 10.0, 0.5, "Hz")])
    # declared alike (e.g. the otolith entry's two channels share K_ot): one parameter
    m = washout_model().add_stage("visual", Washout("omega_w"), [OMEGA_W])
    assert m.parameter_names.count("omega_w") == 1 and m.n_free == 9
    shared = [Parameter("K_x", -5.0, 5.0, 0.0, "-")]
    m = (paper_model().add_channel(Channel("x1", "e", delay="tau_v", gain=("K_x",)), shared)
         .add_channel(Channel("x2", "theta", delay="tau_v", gain=("K_x",)), shared))
    assert m.parameter("K_x") == shared[0] and m.n_free == 9


def test_undeclared_parameter():
    with pytest.raises(ValueError, match="not declared: omega_w"):
        paper_model().add_stage("vestibular", Washout("omega_w"))
    with pytest.raises(ValueError, match="not declared: delta_2"):
        paper_model().with_nonlinearity("visual", DeadZone("delta_2"))


def test_fix_unknown_parameter():
    with pytest.raises(ValueError, match="unknown parameter 'K_x'.*K_v"):
        paper_model().fix(K_x=1.0)
    with pytest.raises(KeyError, match="unknown parameter 'omega_w'"):
        paper_model().parameter("omega_w")
    # a fixed value outside the bounds, or freeing a name the model lacks, passed silently
    with pytest.raises(ValueError, match=r"fix: K_v = -1 is outside its bounds \[0, 10\]"):
        paper_model().fix(K_v=-1.0)
    with pytest.raises(ValueError, match="free: unknown parameter.s. 'bogus'; this model has K_v"):
        paper_model().free("bogus")
    m = paper_model().fix(delta_abs=0.0)
    assert "delta_abs" not in m.parameter_names
    assert "delta_abs" in m.free("delta_abs").parameter_names
    assert m.free("K_v").parameter_names == m.parameter_names  # free already: unchanged
    assert paper_model().fix(delta_abs=0.1).fixed == {"delta_abs": 0.1}  # the bound itself


def test_a_threshold_bounded_away_from_zero_still_has_its_threshold_free_fits():
    """The package's nested model is delta_abs = 0 whatever the threshold's bounds: fixing it
    is not the user's fix (which refuses a value outside them), or fit_fast refused its own
    threshold-free start on a model with delta_abs in [0.001, 0.1]."""
    from dataclasses import replace

    from bayespilot.fit.fast import fit_fast
    from bayespilot.simulate import simulate

    m = paper_model()
    m = replace(m, parameters=tuple(replace(p, lower=0.001) if p.name == "delta_abs" else p
                                    for p in m.parameters))
    with pytest.raises(ValueError, match="outside its bounds"):
        m.fix(delta_abs=0.0)
    rec = simulate(task="FD", remnant_fraction=0.1, seed=0, duration=10.0).recording
    for threshold in (True, False):
        fit = fit_fast(rec, m, seed=0, n_starts=1, threshold=threshold, profile_step=0.02)
        assert np.isfinite(fit.neg_log_lik)
        assert (fit.params["delta_abs"] >= 0.001) if threshold else fit.params["delta_abs"] == 0


def test_bad_parameter_and_channel_definitions():
    with pytest.raises(ValueError, match="outside"):
        Parameter("omega_w", 0.01, 10.0, 20.0)
    with pytest.raises(ValueError, match="lower < upper"):
        Parameter("omega_w", 1.0, 0.5, 0.7)
    # a complex, text or bool bound is a clear ValueError (a complex one was a TypeError)
    for bad in ({"lower": 0.01 + 1j}, {"upper": "10"}, {"default": True}):
        kw = {"lower": 0.01, "upper": 10.0, "default": 0.7, **bad}
        (field,) = bad
        with pytest.raises(ValueError, match=f"omega_w: {field} must be a real number"):
            Parameter("omega_w", **kw)
    with pytest.raises(ValueError, match="identifier"):
        Parameter(3, 0.0, 1.0, 0.5)
    assert Parameter("g", -1, 1, 0).lower == -1.0 and isinstance(Parameter("g", -1, 1, 0).lower,
                                                                 float)
    with pytest.raises(ValueError, match="unknown source 'pitch'"):
        Channel("c", "pitch", delay="tau_v")
    with pytest.raises(ValueError, match="duplicate channel"):
        paper_model().add_channel(Channel("visual", "e", delay="tau_v"))


@pytest.mark.parametrize("omega_w", [0.05, 2.0])
def test_stage_jacobian_in_periodic_steady_state(fd_rec, omega_w):
    """d u_hat / d omega_w (and a pilot parameter) from the tangent kernel, whose stage starts
    from the periodic steady state of the pair (y, dy), against central differences."""
    m = washout_model()
    lik = Likelihood(m, fd_rec, initial="periodic")
    p = dict(FD, omega_w=omega_w)
    names = ("omega_w", "K_m")
    _, J = lik.jacobian(p, names)
    for k, name in enumerate(names):
        h = 1e-6 * max(1.0, abs(p[name]))
        d = (lik.response(dict(p, **{name: p[name] + h}))
             - lik.response(dict(p, **{name: p[name] - h}))) / (2 * h)
        np.testing.assert_allclose(J[:, k], d, rtol=1e-5, atol=1e-6 * np.abs(d).max())


def test_a_block_kind_the_kernels_do_not_compute_is_refused():
    """The kernels pass an unknown kind code through as no block: a user's Hysteresis (code 7)
    gave the same -ln L at every threshold, the threshold-free model's, without a word."""
    from dataclasses import dataclass

    from bayespilot.model import Modulation, Nonlinearity, Stage

    @dataclass(frozen=True)
    class Hysteresis(Nonlinearity):
        kind = 7
        parameters: tuple = ("delta_abs",)

    @dataclass(frozen=True)
    class LeadLag(Stage):
        kind = 42
        parameters: tuple = ()

    @dataclass(frozen=True)
    class Wobble(Modulation):
        kind = True  # a bool is no code, though True == 1 == MOD_LINEAR
        parameters: tuple = ("drift",)

    m = paper_model()
    with pytest.raises(ValueError, match=r"Hysteresis.kind = 7 is not a Nonlinearity code.*"
                                         r"NL_DEADZONE = 1.*NL_SATURATION = 3"):
        m.with_nonlinearity("vestibular", Hysteresis())
    with pytest.raises(ValueError, match="LeadLag.kind = 42 is not a Stage code"):
        m.add_stage("visual", LeadLag())
    with pytest.raises(ValueError, match="LeadLag.kind = 42"):
        Channel("c", "e", delay="tau_v", stages=(LeadLag(),))
    with pytest.raises(ValueError, match="Wobble.kind = True is not a Modulation code"):
        m.with_modulation("visual", Wobble(), [Parameter("drift", -1.0, 1.0, 0.0)])
    with pytest.raises(ValueError, match="Hysteresis.kind = 7"):
        m.with_output(Hysteresis())


def test_a_parameter_no_block_reads_is_refused_and_a_replaced_blocks_are_dropped():
    """A free parameter no block reads has a zero Jacobian column (fit_fast "estimated" a
    delta_abs of 0.09 for a model whose dead zone had been replaced): it is refused, and
    replacing a block drops the parameters only that block used."""
    from bayespilot.model import PilotModel

    m = paper_model()
    idle = PilotModel(m.channels, m.parameters + (Parameter("zzz", 0.0, 1.0, 0.5),))
    rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.15, seed=1, duration=5.0)
    with pytest.raises(ValueError, match="used by no block: zzz"):
        Likelihood(idle, rec.recording)  # refused where it is put to use
    # a fixed one is harmless and allowed
    Likelihood(idle.fix(zzz=0.5), rec.recording)
    capped = m.with_nonlinearity("vestibular", Saturation("i_max"),
                                 [Parameter("i_max", 1e-3, 1.0, 0.1)])
    assert capped.all_names == m.all_names[:-1] + ("i_max",) and not capped.has_threshold
    assert paper_model(threshold=False).with_nonlinearity("vestibular", None).fixed == {}
    soft = m.with_nonlinearity("vestibular", SoftDeadZone("delta_abs", "w_soft"),
                               [Parameter("w_soft", 1e-5, 0.05, 0.002)])
    assert soft.all_names == m.all_names + ("w_soft",)  # delta_abs is still read: kept
    drift = m.with_modulation("visual", LinearDrift("g_v"), [Parameter("g_v", -1.0, 1.0, 0.0)])
    assert drift.with_modulation("visual", None).all_names == m.all_names
    sat = m.with_output(Saturation("u_max"), [Parameter("u_max", 1e-6, 10.0, 1.0)]).fix(u_max=2.0)
    assert sat.with_output(None).all_names == m.all_names and sat.with_output(None).fixed == {}


def test_source_codes_are_the_closed_loop_kernels():
    """A channel's source is a name in the model and a code in the simulator's kernel; the
    kernel takes every code it does not know as theta, so the two tables must be one."""
    from bayespilot.kernels import _closed_loop as K
    from bayespilot.model import SOURCE_CODES, SOURCES

    assert set(SOURCE_CODES) == set(SOURCES)
    assert SOURCE_CODES == {"e": K.SRC_E, "theta_ddot_m": K.SRC_THETA_DDOT_M,
                            "theta_m": K.SRC_THETA_M, "theta": K.SRC_THETA}
    assert sorted(SOURCE_CODES.values()) == list(range(len(SOURCES)))


def test_soft_dead_zone_values_against_numpy():
    """The soft dead zone's values, w [softplus((|x| - d)/w) - softplus(-d/w)] sign(x), by
    numpy's logaddexp (a bug made in both the value and its tangent passed every test, which
    compared the two with each other)."""
    from bayespilot.kernels._blocks import NL_SOFT_DEADZONE, nonlinearity

    d, w = 0.0075, 0.002
    x = np.linspace(-0.05, 0.05, 2001)
    got = np.array([nonlinearity(NL_SOFT_DEADZONE, v, d, w) for v in x])
    want = np.sign(x) * w * (np.logaddexp(0.0, (np.abs(x) - d) / w) - np.logaddexp(0.0, -d / w))
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-18)
    assert nonlinearity(NL_SOFT_DEADZONE, 0.0, d, w) == 0.0
    # far beyond the corner it is the crisp dead zone, |x| - d, less w softplus(-d/w)
    assert nonlinearity(NL_SOFT_DEADZONE, 0.05, d, w) == pytest.approx(
        0.05 - d - w * np.logaddexp(0.0, -d / w), rel=1e-9)

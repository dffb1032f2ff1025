"""An extender's model: the model without threshold, the blocks' parameter counts, and fits
where no parameter vector is stable (an audit of extending the model, 2026-11-29)."""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass

import numpy as np
import pytest

from bayespilot.fit.fast import fit_fast
from bayespilot.fit.three_step import _model_for, fit_paper
from bayespilot.kernels import _blocks as B
from bayespilot.likelihood import Likelihood
from bayespilot.model import (Channel, DeadZone, FirstOrderLag, FixedFilter, LinearDrift,
                              MotionSystem, Nonlinearity, Parameter, Saturation,
                              SecondOrderWashout, SoftDeadZone, Stage, Washout, paper_model)
from bayespilot.presets import paper_parameters
from bayespilot.simulate import simulate


@pytest.fixture(scope="module")
def rec():
    """FD, K_theta 1, F_n 0.1, 20.48 s of the paper's model (delta_abs 0.0075)."""
    return simulate(task="FD", motion_gain=1.0, remnant_fraction=0.1, seed=3,
                    duration=20.48).recording


def _soft():
    return paper_model().with_nonlinearity("vestibular", SoftDeadZone("delta_abs", "w_soft"), [
        Parameter("w_soft", 1e-5, 0.05, 0.002, "IPUT", "corner width")])


# --- the model without threshold ------------------------------------------------------------
def test_without_threshold_of_a_soft_dead_zone_is_the_linear_model(rec):
    """A soft dead zone at delta_abs = 0 is no identity (it halves small inputs, and w_soft
    stayed free): the fit "without threshold" recovered most of what a threshold explains (an
    audit: -ln L 308 of 407 units below the linear model's on an 81.92-s run).  Without
    threshold is now the model with the block removed: its fit is the fit of the linear
    model, built independently (no nonlinearity), on the same record, to the bit."""
    soft = _soft()
    linear = paper_model().with_nonlinearity("vestibular", None)
    assert linear.parameter_names == ("K_v", "T_vl", "tau_v", "K_m", "tau_m", "omega_nm",
                                      "zeta_nm")
    # the old null model is not the linear one: the soft block at delta 0 changes -ln L
    p = dict(paper_parameters("FD"), w_soft=0.01)
    old = Likelihood(soft._fixed(delta_abs=0.0), rec, discard=2.0).neg_log_lik(p)
    p_lin = {k: p[k] for k in linear.parameter_names}
    lin = Likelihood(linear, rec, discard=2.0).neg_log_lik(p_lin)
    assert abs(old - lin) > 10.0

    none = _model_for(soft, threshold=False)
    assert none.parameter_names == linear.parameter_names  # w_soft and delta_abs gone
    assert none.channels[1].nonlinearity is None and not none.has_threshold
    assert Likelihood(none, rec, discard=2.0).neg_log_lik(p_lin) == lin

    f_none = fit_fast(rec, soft, threshold=False, seed=0, n_starts=2)
    f_lin = fit_fast(rec, linear, seed=0, n_starts=2)
    assert f_none.params == f_lin.params
    assert f_none.neg_log_lik == f_lin.neg_log_lik
    assert f_none.threshold is False and "w_soft" not in f_none.params


def test_paper_model_without_threshold_is_delta_abs_fixed_at_zero(rec):
    """The crisp dead zone keeps the paper's construction exactly: delta_abs fixed at 0, the
    same parameters and name, and a fit equal to the bit to that of ``_fixed(delta_abs=0)``."""
    m = paper_model()
    none = m.without_threshold()
    assert none.fixed == {"delta_abs": 0.0} and none.name == m.name
    assert none.parameters == m.parameters and none.channels == m.channels
    assert not none.has_threshold and m.has_threshold
    off = paper_model(threshold=False)
    assert off.without_threshold() is off and _model_for(off, threshold=False) is off
    a = fit_fast(rec, m, threshold=False, seed=1, n_starts=2)
    b = fit_fast(rec, m._fixed(delta_abs=0.0), seed=1, n_starts=2)
    assert a.params == b.params and a.neg_log_lik == b.neg_log_lik and not a.threshold


def test_without_threshold_holds_any_dead_zone_at_zero():
    """A dead zone's threshold of another name is held at 0 too (before, threshold=False left
    it free and the fit read "with threshold"), as is one fixed at a nonzero value; a dead zone
    on the output as well."""
    renamed = paper_model().with_nonlinearity(
        "vestibular", DeadZone("delta_pitch"), [Parameter("delta_pitch", 0.0, 0.1, 0.0075)])
    none = _model_for(renamed, threshold=False)
    assert none.fixed == {"delta_pitch": 0.0} and not none.has_threshold
    held = paper_model().fix(delta_abs=0.01)
    assert held.has_threshold and held.without_threshold().fixed == {"delta_abs": 0.0}
    on_u = paper_model(threshold=False).with_output(
        SoftDeadZone("u_dead", "u_w"), [Parameter("u_dead", 0.0, 0.1, 0.001),
                                        Parameter("u_w", 1e-5, 0.01, 0.001)])
    out = on_u.without_threshold()
    assert out.output is None and out.all_names == paper_model().all_names
    assert out.fixed == {"delta_abs": 0.0}


def test_without_threshold_keeps_a_clipped_copy_that_declares_its_limit(rec):
    """A dead zone composed of channels, the linear motion channel minus a copy clipped at a
    limit that its block declares as a threshold: the model without threshold holds that limit
    at 0 (the copy silent, the difference the linear channel), it does not remove the block
    (the copy unclipped would cancel the motion channel).  Reference: the linear model's -ln
    L at the same parameters."""
    import dataclasses

    from bayespilot.likelihood import Likelihood

    class Limit(Saturation):  # (a Saturation whose limit is the threshold)
        @property
        def thresholds(self):
            return tuple(self.parameters)

    lin = paper_model(threshold=False).without_threshold()
    motion = next(c for c in lin.channels if c.name == "vestibular")
    clipped = dataclasses.replace(motion, name="clipped", sign=-motion.sign,
                                  nonlinearity=Limit("i_lim"))
    composed = dataclasses.replace(
        lin, channels=(*lin.channels, clipped),
        parameters=(*lin.parameters, Parameter("i_lim", 0.0, 0.1, 0.0075, "IPUT")))
    none = composed.without_threshold()
    assert none.fixed.get("i_lim") == 0.0 and len(none.channels) == 3
    p = {k: v for k, v in paper_parameters("FD").items() if k != "delta_abs"}
    want = Likelihood(lin, rec, discard=2.0).neg_log_lik(p)
    assert Likelihood(none, rec, discard=2.0).neg_log_lik(p) == pytest.approx(want, rel=1e-9)


def test_has_threshold_agrees_with_the_fits_label(rec):
    """A free parameter named delta_abs is the threshold the fitters scan, whatever block reads
    it (a Saturation in a dead zone composed of channels): has_threshold said False while the
    fit read "with threshold".  Now they agree, with and without threshold."""
    sat = paper_model().with_nonlinearity("vestibular", Saturation("delta_abs"))
    assert "delta_abs" in sat.parameter_names
    assert sat.has_threshold
    none = sat.without_threshold()
    assert none.fixed == {"delta_abs": 0.0} and not none.has_threshold
    for threshold in (True, False):
        fit = fit_fast(rec, sat, threshold=threshold, seed=0, n_starts=1, profile_step=0.05,
                       scan_step=0.05)
        assert fit.threshold is _model_for(sat, threshold).has_threshold is threshold


# --- blocks whose parameters the kernels do not read as declared ---------------------------
def _reads(f) -> tuple[bool, ...]:
    """Which of p0, p1 change ``f(x, p0, p1)`` at a few points: an independent reading of how
    many parameters a kernel function reads."""
    points = list(itertools.product((-0.3, 0.02, 0.7), (0.05, 0.2), (0.6, 0.3)))
    return (any(f(x, p0, p1) != f(x, 1.7 * p0, p1) for x, p0, p1 in points),
            any(f(x, p0, p1) != f(x, p0, 1.7 * p1) for x, p0, p1 in points))


def test_arity_tables_match_the_kernels_and_the_builtin_blocks():
    """ARITY_* say how many of (p0, p1) the kernels read; checked against the kernels
    themselves, and every built-in block names that many."""
    const = np.array([1.0, 0.5, 0.0, 1.0, 2.0, 0.0])
    for kind, n in B.ARITY_STAGE.items():
        reads = _reads(lambda x, p0, p1, kind=kind: B.stage_tf(kind, p0, p1, const))
        assert reads == tuple(i < n for i in range(2)), kind
    for kind, n in B.ARITY_NL.items():
        reads = _reads(lambda x, p0, p1, kind=kind: B.nonlinearity(kind, x, p0, p1))
        assert reads == tuple(i < n for i in range(2)), kind
    assert B.modulation(B.MOD_LINEAR, 0.9, 0.4) != B.modulation(B.MOD_LINEAR, 0.9, 0.5)
    assert B.ARITY_MOD == {B.MOD_LINEAR: 1}
    blocks = [FixedFilter((1.0,), (1.0, 1.0)), Washout(), SecondOrderWashout(), MotionSystem(),
              FirstOrderLag(), DeadZone(), SoftDeadZone(), Saturation(), LinearDrift()]
    table = {**{("S", k): v for k, v in B.ARITY_STAGE.items()},
             **{("N", k): v for k, v in B.ARITY_NL.items()},
             **{("M", k): v for k, v in B.ARITY_MOD.items()}}
    for b in blocks:
        fam = "S" if isinstance(b, Stage) else "N" if isinstance(b, Nonlinearity) else "M"
        assert len(b.parameters) == table.pop((fam, b.kind)), type(b).__name__
    assert not table  # every code has a built-in block


@dataclass(frozen=True)
class AsymDeadZone(Nonlinearity):
    """The audit's asymmetric dead zone: the dead zone's code, a second threshold."""

    pos: str = "delta_abs"
    neg: str = "delta_neg"
    kind = B.NL_DEADZONE

    @property
    def parameters(self):
        return (self.pos, self.neg)


@dataclass(frozen=True)
class Platform(Stage):
    """MotionSystem's code with the damping left out."""

    kind = B.STAGE_LOWPASS2

    @property
    def parameters(self):
        return ("w_b",)


@dataclass(frozen=True)
class NoParamDZ(Nonlinearity):
    kind = B.NL_DEADZONE
    parameters = ()


@dataclass(frozen=True)
class StrParams(Stage):
    kind = B.STAGE_HIGHPASS1

    @property
    def parameters(self):
        return "omega_q"


@dataclass(frozen=True)
class CalledDZ(Nonlinearity):
    """One parameter, as the dead zone, but maths of its own in a __call__ the kernels never
    call."""

    kind = B.NL_DEADZONE
    parameters = ("delta_abs",)

    def __call__(self, x, d):
        return np.where(x > d, x - d, 0.0)


@dataclass(frozen=True)
class Coefficients(Stage):
    kind = B.STAGE_FIXED
    parameters = ()


def test_a_reused_code_with_another_parameter_count_is_refused():
    """The asymmetric dead zone ran as the symmetric one and fit_fast "estimated" delta_neg;
    a third parameter on a two-parameter stage was never read; a missing second one was read
    as 0 (an undamped stage: -ln L = +inf everywhere); a dead zone with no parameters raised a
    bare IndexError at the likelihood.  All are refused where they are added."""
    neg = Parameter("delta_neg", 0.0, 0.1, 0.0075)
    with pytest.raises(ValueError, match=r"AsymDeadZone names 2 parameters \(delta_abs, "
                                         r"delta_neg\).*never read delta_neg.*built-in "
                                         r"DeadZone's maths"):
        paper_model().with_nonlinearity("vestibular", AsymDeadZone(), [neg])
    with pytest.raises(ValueError, match=r"Platform names 1 parameter \(w_b\).*the built-in "
                                         r"MotionSystem.*missing one as 0"):
        paper_model().add_stage("vestibular", Platform(), [Parameter("w_b", 1, 50, 20)])
    with pytest.raises(ValueError, match="NoParamDZ names 0 parameters"):
        paper_model().with_nonlinearity("vestibular", NoParamDZ())
    with pytest.raises(ValueError, match="NoParamDZ names 0 parameters"):
        paper_model(threshold=False).with_output(NoParamDZ())
    with pytest.raises(ValueError, match="NoParamDZ names 0 parameters"):
        Channel("c", "e", delay="tau_v", nonlinearity=NoParamDZ())
    with pytest.raises(ValueError, match="CalledDZ defines __call__, which the kernels never "
                                         "call.*built-in DeadZone's maths"):
        paper_model().with_nonlinearity("vestibular", CalledDZ())
    with pytest.raises(ValueError, match="only a FixedFilter carries"):
        paper_model().add_stage("vestibular", Coefficients())


def test_parameters_given_as_a_str_are_refused():
    """``parameters = "omega_q"`` was read letter by letter: "parameters used but not
    declared: _, a, e, g, m, o, q"."""
    with pytest.raises(TypeError, match=r"StrParams.parameters must be a tuple of parameter "
                                        r"names, got the str 'omega_q' \(write \('omega_q',\)\)"):
        paper_model().add_stage("vestibular", StrParams(),
                                [Parameter("omega_q", 0.01, 5, 0.5)])


def test_the_wrong_slot_error_lists_only_the_package_blocks():
    """The TypeError listed the family's subclasses, users' refused ones among them."""
    for bad in (AsymDeadZone(), NoParamDZ(), CalledDZ()):  # (the family gains subclasses)
        assert isinstance(bad, Nonlinearity)
    with pytest.raises(TypeError) as err:
        paper_model().with_nonlinearity("vestibular", Washout("om"),
                                        [Parameter("om", 0.01, 5, 0.5)])
    assert "must be a Nonlinearity (DeadZone, SoftDeadZone, Saturation) or None" in str(err.value)
    with pytest.raises(TypeError) as err:
        paper_model().add_stage("vestibular", DeadZone())
    assert ("must be a Stage (FixedFilter, Washout, SecondOrderWashout, MotionSystem, "
            "FirstOrderLag), got DeadZone") in str(err.value)


# --- no stable parameter vector -------------------------------------------------------------
def test_fits_refuse_a_model_unstable_everywhere(rec):
    """A lag declared with a negative time constant (bounds [-1, -0.01]) is unstable at every
    parameter vector: fit_fast and fit_paper returned a FitResult of random parameters at
    -ln L = +inf without a word, and sample blamed the init only."""
    from bayespilot.sample import sample

    m = paper_model().add_stage("vestibular", FirstOrderLag("T_x"),
                                [Parameter("T_x", -1.0, -0.01, -0.1, "s")])
    with pytest.raises(ValueError, match=r"no start gave a finite likelihood: every parameter "
                                         r"vector tried \(2 Latin-hypercube starts.*unstable.*"
                                         r"check the blocks' bounds \(T_x in \[-1, -0.01\]"):
        fit_fast(rec, m, seed=0, n_starts=2)
    with pytest.raises(ValueError, match=r"no start gave a finite likelihood.*Step I.*T_x"):
        fit_paper(rec, m, seed=0, repetitions=1, n_best=1, population=20, generations=5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(RuntimeError, match="give a better init; the init itself has a "
                                               "non-finite likelihood.*check the blocks' bounds"):
            sample(rec, m, init=dict(m.defaults), n_walkers=20, max_steps=100, min_steps=50,
                   check_every=50, seed=0, progress=False)


# --- changing a channel's fields -------------------------------------------------------------
def test_with_channel_adds_a_lead_as_building_the_channel_by_hand(rec):
    """with_channel("vestibular", lead=...) is the model built with dataclasses.replace (what
    an extender had to do): the same -ln L at the same parameters; removing the lead again
    drops its parameter and gives the paper model's -ln L; a misspelt field is refused."""
    import dataclasses

    T_ml = Parameter("T_ml", 0.0, 1.0, 0.1, "s")
    base = paper_model()
    lead = base.with_channel("vestibular", lead="T_ml", parameters=[T_ml])
    chans = tuple(dataclasses.replace(c, lead="T_ml") if c.name == "vestibular" else c
                  for c in base.channels)
    by_hand = dataclasses.replace(base, channels=chans, parameters=(*base.parameters, T_ml))
    p = dict(paper_parameters("FD"), T_ml=0.15)
    want = Likelihood(by_hand, rec, discard=2.0).neg_log_lik(p)
    assert Likelihood(lead, rec, discard=2.0).neg_log_lik(p) == want
    assert want != Likelihood(base, rec, discard=2.0).neg_log_lik(paper_parameters("FD"))
    back = lead.with_channel("vestibular", lead=None)
    assert back.parameter_names == base.parameter_names
    assert Likelihood(back, rec, discard=2.0).neg_log_lik(paper_parameters("FD")) == \
        Likelihood(base, rec, discard=2.0).neg_log_lik(paper_parameters("FD"))
    with pytest.raises(TypeError, match="unknown field.s. leed; a channel's fields are delay"):
        base.with_channel("vestibular", leed="T_ml")
    with pytest.raises(ValueError, match="not declared: T_x"):
        base.with_channel("vestibular", lead="T_x")

"""The multimodal pilot model (Fig. 4 of Pool et al. 2012) as composable parts.

A :class:`PilotModel` is a set of parallel :class:`Channel` objects that all
feed one neuromuscular block H_nm, plus an optional output nonlinearity.  A
channel takes a source signal (``"e"``, ``"theta_ddot_m"``, ...), passes it
through linear stages (fixed, like the canal model, or with parameters, like a
washout), a static nonlinearity (the dead-zone threshold), a time delay and an
equalisation gain with optional lead:

    u = H_nm(s) sum_c  sign_c K_c (1 + T_c s) e^{-tau_c s} g_c(t) NL_c( H_c(s) x_c )  + n

The paper's model (:func:`paper_model`) is two channels: visual
``K_v (1 + T_vl s) e^{-tau_v s} e`` and vestibular
``-K_m e^{-tau_m s} DZ(H_scc(s) theta_ddot_m)``.

Extension point
---------------
Models are values: :meth:`PilotModel.add_stage`, :meth:`PilotModel.add_channel`,
:meth:`PilotModel.with_nonlinearity`, :meth:`PilotModel.with_modulation` and
:meth:`PilotModel.with_output` return new models with the extra parameters
registered.  :meth:`PilotModel.plan` compiles any such model into the plain
arrays that the numba simulator and likelihood interpret, so an extension
needs no change to the simulator, the likelihood or the fitters.  A new kind
of linear block or nonlinearity is a new code in ``kernels/_blocks.py`` (with
its derivative there or in ``kernels/_sensitivity.py``, and its number of
parameters in the ``ARITY_*`` tables; docs/model.md lists the places) plus a
small class here, a subclass of :class:`Stage`, :class:`Nonlinearity` or
:class:`Modulation` (the kind codes of the three families overlap, so each
slot of a channel takes only its own family; a code the kernels do not compute
is refused, and so is a block naming another number of parameters than its
code reads: a subclass reusing a code is computed as the built-in block).

The model without threshold (:meth:`PilotModel.without_threshold`) is the model
with a dead zone's half-width held at 0 (the identity), or with any other
threshold nonlinearity (a soft dead zone) removed.

Sign convention
---------------
The motion channel enters with a minus sign (``sign=-1``), so K_m > 0 as in
Table 3: a nose-up acceleration makes the pilot push the stick nose-down,
which is the stabilising (rate-damping) feedback the paper describes.  With a
plus sign the closed loop of Fig. 2 is unstable for the Table 3 parameters
(tested in ``tests/test_simulate.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from . import presets
from ._html import SummaryHTML
from .forcing import _is_complex
from .kernels import _blocks as B
from .kernels import _response as R

__all__ = [
    "MAX_OVERSAMPLE", "Parameter", "Stage", "Nonlinearity", "Modulation", "FixedFilter", "Washout",
    "SecondOrderWashout", "MotionSystem", "FirstOrderLag", "DeadZone", "SoftDeadZone", "Saturation",
    "LinearDrift", "Channel",
    "PilotModel", "Plan", "paper_model", "SOURCES", "semicircular_canal", "UnknownChannelError",
]

#: Source signals a channel may take, and what they are.
SOURCES = {
    "e": "tracking error shown on the display, rad",
    "theta_ddot_m": "commanded (presented) pitch acceleration, rad/s^2",
    "theta_m": "presented pitch attitude K_theta * theta, rad (needs the theta column)",
    "theta": "controlled element pitch attitude, rad",
}
SOURCE_CODES = {"e": 0, "theta_ddot_m": 1, "theta_m": 2, "theta": 3}
MAX_STAGES = 4
#: Largest oversampling factor of a channel (:attr:`Channel.oversample`).
MAX_OVERSAMPLE = 64


class UnknownChannelError(ValueError, KeyError):
    """A channel name the model does not have (a ValueError; also a KeyError, as before)."""

    def __str__(self) -> str:  # KeyError would show the message in quotes
        return str(self.args[0]) if self.args else ""


def _parameter_value(name: str, value) -> float:
    """A parameter's value as a finite float, or a ValueError naming the parameter (complex
    numbers refused: float() would drop their imaginary part)."""
    if np.iscomplexobj(value):
        raise ValueError(f"parameter {name} must be a real number, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"parameter {name} must be a number, got {value!r}") from None
    if not math.isfinite(x):
        raise ValueError(f"parameter {name} must be finite, got {value!r}")
    return x


def _real(value, what: str) -> float:
    """``float(value)``, refusing complex numbers (which float() would truncate)."""
    if np.iscomplexobj(value):
        raise ValueError(f"{what} must be a real number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class Parameter:
    """A named model parameter with bounds (the prior support) and a default.

    Attributes
    ----------
    name : str
        The parameter's name, a Python identifier (e.g. ``"K_v"``).
    lower, upper : float
        Bounds, lower < upper, both finite, in the parameter's unit: the
        fitters' search box and the support of the uniform prior.
    default : float
        Start value and value when not estimated, in [lower, upper].
    unit : str, default "-"
        The unit, e.g. ``"s"``, ``"rad/s"`` (``"-"``: dimensionless).
    description : str, default ""
        A short description for reports.

    Raises
    ------
    ValueError
        If ``name`` is not an identifier, a bound or the default is not a
        real number (a bool, text or complex), the bounds are not finite
        with lower < upper, or the default lies outside them.

    Examples
    --------
    >>> Parameter("K_v", 0.0, 10.0, 1.0).lower
    0.0
    """

    name: str
    lower: float
    upper: float
    default: float
    unit: str = "-"
    description: str = ""

    def __post_init__(self) -> None:
        if not (isinstance(self.name, str) and self.name.isidentifier()):
            raise ValueError(f"parameter name must be an identifier, got {self.name!r}")
        for field_name in ("lower", "upper", "default"):
            value = getattr(self, field_name)
            if isinstance(value, (bool, np.bool_, str, bytes)) or np.iscomplexobj(value):
                raise ValueError(f"{self.name}: {field_name} must be a real number, "
                                 f"got {value!r}")
            try:
                object.__setattr__(self, field_name, float(value))
            except (TypeError, ValueError):
                raise ValueError(f"{self.name}: {field_name} must be a real number, "
                                 f"got {value!r}") from None
        if not (math.isfinite(self.lower) and math.isfinite(self.upper) and self.lower < self.upper):
            raise ValueError(f"{self.name}: need finite lower < upper, got [{self.lower}, {self.upper}]")
        if not (self.lower <= self.default <= self.upper):
            raise ValueError(f"{self.name}: default {self.default} outside [{self.lower}, {self.upper}]")


# --- block families ---------------------------------------------------------------
class Stage:
    """Base class of the linear blocks of a channel (:attr:`Channel.stages`).

    A subclass is a frozen dataclass with a class attribute ``kind`` (a
    ``STAGE_*`` code of ``kernels/_blocks.py``) and a ``parameters`` tuple of
    as many parameter names as the kernels read for that code
    (``ARITY_STAGE`` there: 0 to 2).  A subclass that reuses a built-in
    block's code is computed as that block, whatever else it defines.

    Attributes
    ----------
    kind : int
        The block's ``STAGE_*`` code (a class attribute).
    parameters : tuple of str
        Names of the block's parameters, in the kernel's order (p0, p1).
    """

    __slots__ = ()


class Nonlinearity:
    """Base class of the static nonlinearities (a channel's, or the model output's).

    ``kind`` is an ``NL_*`` code of ``kernels/_blocks.py``; ``parameters``
    names as many parameters as the kernels read for that code (``ARITY_NL``
    there: 1 or 2).  A subclass that reuses a built-in block's code (a new code
    is refused) is computed as that block: the kernels never call a Python
    method of it, so a block of other maths (an asymmetric dead zone) is a new
    code in the kernels (docs/model.md, "Extending the model"); one that names
    another number of parameters than its code reads, or defines ``__call__``,
    is refused.

    Attributes
    ----------
    kind : int
        The block's ``NL_*`` code (a class attribute).
    parameters : tuple of str
        Names of the block's parameters, in the kernel's order (p0, p1).
    thresholds : tuple of str
        The names among ``parameters`` that are thresholds (half-widths of
        an input range the block passes nothing through): empty here; a dead
        zone's ``delta``.  A model with one free is :attr:`PilotModel.has_threshold`
        and its fits read "with threshold".
    """

    __slots__ = ()

    @property
    def thresholds(self) -> tuple[str, ...]:
        """The names among ``parameters`` that are thresholds (none by default)."""
        return ()


class Modulation:
    """Base class of the gain modulations of a channel (:attr:`Channel.modulation`).

    ``kind`` is a ``MOD_*`` code of ``kernels/_blocks.py``; ``parameters``
    names one parameter (``ARITY_MOD`` there).

    Attributes
    ----------
    kind : int
        The block's ``MOD_*`` code (a class attribute).
    parameters : tuple of str
        Name of the block's parameter (p0).
    """

    __slots__ = ()


def _used_names(channels: Iterable["Channel"], output: Any, omega_nm: str,
                zeta_nm: str) -> set[str]:
    """The parameter names some block of a model reads."""
    used = {omega_nm, zeta_nm}
    for c in channels:
        used.update(c.parameter_names)
    if output is not None:
        used.update(output.parameters)
    return used


#: The kernel code prefix of each block family.
_KIND_PREFIX = {Stage: "STAGE_", Nonlinearity: "NL_", Modulation: "MOD_"}
#: How many parameters the kernels read for each code of a family (``kernels/_blocks.py``).
_ARITY = {Stage: B.ARITY_STAGE, Nonlinearity: B.ARITY_NL, Modulation: B.ARITY_MOD}


def _kernel_codes(prefix: str) -> dict[int, str]:
    """The kind codes ``kernels/_blocks.py`` computes for one family (``STAGE_`` ...), code ->
    name, without the family's NONE."""
    return {v: k for k, v in vars(B).items()
            if k.startswith(prefix) and k != prefix + "NONE" and isinstance(v, int)}


def _builtin_blocks(family: type) -> dict[int, type]:
    """The package's own block classes of ``family`` (this module's direct subclasses whose
    ``kind`` is a code the kernels compute), kind code -> class.  A user's subclass, even one
    refused, is no member to offer."""
    codes = _kernel_codes(_KIND_PREFIX[family])
    return {c.kind: c for c in family.__subclasses__()
            if c.__module__ == __name__ and getattr(c, "kind", None) in codes}


def _builtin_parameters(cls: type) -> str:
    """The parameters of the built-in block ``cls`` as its defaults name them ("(delta)")."""
    try:
        names = cls().parameters
    except TypeError:  # (FixedFilter: no defaults, and no parameters)
        names = ()
    return "(" + ", ".join(names) + ")" if names else "(none)"


def _check_block(block, family: type, where: str, optional: bool = True) -> None:
    """Raise TypeError unless ``block`` belongs to ``family`` (or is None, if optional) and its
    ``parameters`` is a tuple of names, and ValueError if its ``kind`` is no code of that family
    that the kernels compute, or it names other than as many parameters as the kernels read
    for that code (a subclass that reuses a built-in block's code is computed as that block)."""
    if optional and block is None:
        return
    builtin = _builtin_blocks(family)
    if not isinstance(block, family):
        members = ", ".join(c.__name__ for c in builtin.values())
        alt = " or None" if optional else ""
        raise TypeError(f"{where} must be a {family.__name__} ({members}){alt}, "
                        f"got {type(block).__name__}")
    # The kernels switch on the code and pass an unknown one through unchanged: a subclass with
    # a code of its own would run as no block at all, without a word.
    codes = _kernel_codes(_KIND_PREFIX[family])
    kind = getattr(block, "kind", None)
    if isinstance(kind, (bool, np.bool_)) or kind not in codes:
        known = ", ".join(f"{v} = {k}" for k, v in codes.items())
        raise ValueError(
            f"{where}: {type(block).__name__}.kind = {kind!r} is not a {family.__name__} code "
            f"the kernels compute ({known}); a new kind of block needs kernel code "
            "(docs/model.md, 'Extending the model')")
    name = type(block).__name__
    names = getattr(block, "parameters", None)
    if isinstance(names, str):  # a str is a sequence of one-letter "names"
        raise TypeError(f"{where}: {name}.parameters must be a tuple of parameter names, got "
                        f"the str {names!r} (write ({names!r},))")
    if not isinstance(names, (tuple, list)) or not all(isinstance(n, str) for n in names):
        raise TypeError(f"{where}: {name}.parameters must be a tuple of parameter names (str), "
                        f"got {names!r}")
    same = builtin.get(kind)
    what = same.__name__ if same is not None else codes[kind]
    need = _ARITY[family].get(kind)
    if need is not None and len(names) != need:
        said = ", ".join(names) if names else "none"
        if len(names) > need:
            lost = ", ".join(names[need:])
            effect = (f"the kernels would never read {lost}: they compute the built-in "
                      f"{what}'s maths, on its {need} parameter{'' if need == 1 else 's'} "
                      f"{_builtin_parameters(same) if same is not None else ''}, whatever "
                      f"{name} means")
        else:
            effect = (f"the kernels read {need} for kind = {kind}, as the built-in {what}"
                      f"{' ' + _builtin_parameters(same) if same is not None else ''}, and "
                      f"would take the missing one{'' if need - len(names) == 1 else 's'} as 0")
        raise ValueError(
            f"{where}: {name} names {len(names)} parameter{'' if len(names) == 1 else 's'} "
            f"({said}) for kind = {kind} ({codes[kind]}); {effect}.  Reusing a built-in "
            "block's code gives that block's maths: a block of other maths needs a kind code of "
            "its own and kernel code (docs/model.md, 'Extending the model')")
    if same is not None and type(block) is not same and callable(block):
        raise ValueError(
            f"{where}: {name} defines __call__, which the kernels never call: kind = {kind} "
            f"({codes[kind]}) makes them compute the built-in {what}'s maths, whatever {name} "
            "says; a block of other maths needs a kind code of its own and kernel code "
            "(docs/model.md, 'Extending the model')")
    if kind == B.STAGE_FIXED and family is Stage and not isinstance(block, FixedFilter):
        raise ValueError(f"{where}: {name}.kind = {kind} (STAGE_FIXED) is the FixedFilter's "
                         "code, whose coefficients only a FixedFilter carries: use FixedFilter "
                         "(or a subclass of it)")


# --- linear stages ---------------------------------------------------------------
@dataclass(frozen=True)
class FixedFilter(Stage):
    """A fixed (parameter-free) proper transfer function of order <= 2.

    Parameters
    ----------
    num, den : sequence of float
        Coefficients in powers of s, highest first (as in ``scipy.signal``).
        Leading zeros are removed (at least one coefficient is kept).

    Raises
    ------
    ValueError
        If a coefficient is complex, ``den`` is all zero, or after removing
        leading zeros the denominator has order > 2 or the numerator a
        higher order than the denominator (an improper filter).
    """

    num: tuple[float, ...]
    den: tuple[float, ...]
    kind = B.STAGE_FIXED
    parameters: tuple[str, ...] = field(default=(), init=False)

    def __post_init__(self) -> None:
        num = _strip_leading_zeros(tuple(_real(x, "FixedFilter coefficient") for x in self.num))
        den = _strip_leading_zeros(tuple(_real(x, "FixedFilter coefficient") for x in self.den))
        if not any(den):
            raise ValueError(f"FixedFilter: the denominator must not be zero, got {self.den!r}")
        if not num or len(den) > 3 or len(num) > len(den):
            raise ValueError("FixedFilter needs a proper transfer function of order <= 2 "
                             f"(leading zeros removed: num={list(num)}, den={list(den)})")
        object.__setattr__(self, "num", num)
        object.__setattr__(self, "den", den)

    def constants(self) -> np.ndarray:
        """The filter as the kernels' six constants.

        Returns
        -------
        ndarray, shape (6,)
            (b0, b1, b2, a0, a1, a2): numerator then denominator coefficients
            in ascending powers of s, zero-padded to order 2.
        """
        b = np.zeros(3)
        a = np.zeros(3)
        b[: len(self.num)] = self.num[::-1]
        a[: len(self.den)] = self.den[::-1]
        return np.concatenate([b, a])


def _strip_leading_zeros(coef: tuple[float, ...]) -> tuple[float, ...]:
    """``coef`` without its leading zeros, keeping at least one coefficient."""
    k = 0
    while k < len(coef) - 1 and coef[k] == 0.0:
        k += 1
    return coef[k:]


@dataclass(frozen=True)
class Washout(Stage):
    """First-order washout (high-pass) s / (s + omega), omega a parameter (rad/s).

    Attributes
    ----------
    omega : str, default "omega_w"
        Name of the break-frequency parameter, rad/s.
    """

    omega: str = "omega_w"
    kind = B.STAGE_HIGHPASS1

    @property
    def parameters(self) -> tuple[str, ...]:
        """The parameter names, ``(omega,)``."""
        return (self.omega,)


@dataclass(frozen=True)
class SecondOrderWashout(Stage):
    """Second-order washout s^2 / (s^2 + 2 zeta omega s + omega^2).

    Attributes
    ----------
    omega : str, default "omega_w"
        Name of the break-frequency parameter, rad/s.
    zeta : str, default "zeta_w"
        Name of the damping-ratio parameter (dimensionless).
    """

    omega: str = "omega_w"
    zeta: str = "zeta_w"
    kind = B.STAGE_HIGHPASS2

    @property
    def parameters(self) -> tuple[str, ...]:
        """The parameter names, ``(omega, zeta)``."""
        return (self.omega, self.zeta)


@dataclass(frozen=True)
class MotionSystem(Stage):
    """Second-order motion-platform dynamics omega^2 / (s^2 + 2 zeta omega s + omega^2).

    Attributes
    ----------
    omega : str, default "omega_ms"
        Name of the bandwidth (natural-frequency) parameter, rad/s.
    zeta : str, default "zeta_ms"
        Name of the damping-ratio parameter (dimensionless).
    """

    omega: str = "omega_ms"
    zeta: str = "zeta_ms"
    kind = B.STAGE_LOWPASS2

    @property
    def parameters(self) -> tuple[str, ...]:
        """The parameter names, ``(omega, zeta)``."""
        return (self.omega, self.zeta)


@dataclass(frozen=True)
class FirstOrderLag(Stage):
    """First-order lag 1 / (T s + 1), T a parameter (s).

    Attributes
    ----------
    T : str, default "T_lag"
        Name of the time-constant parameter, s.
    """

    T: str = "T_lag"
    kind = B.STAGE_LOWPASS1

    @property
    def parameters(self) -> tuple[str, ...]:
        """The parameter names, ``(T,)``."""
        return (self.T,)


# --- nonlinearities --------------------------------------------------------------
@dataclass(frozen=True)
class DeadZone(Nonlinearity):
    """Dead zone of half-width ``delta``: sign(x) max(|x| - delta, 0) (Fig. 3).

    Attributes
    ----------
    delta : str, default "delta_abs"
        Name of the half-width (threshold) parameter, in the units of the
        block's input (IPUT, the canal output, for the paper's ``delta_abs``).
    """

    delta: str = "delta_abs"
    kind = B.NL_DEADZONE

    @property
    def parameters(self) -> tuple[str, ...]:
        """The parameter names, ``(delta,)``."""
        return (self.delta,)

    @property
    def thresholds(self) -> tuple[str, ...]:
        """``(delta,)``: the dead zone's half-width is a threshold."""
        return (self.delta,)


@dataclass(frozen=True)
class SoftDeadZone(Nonlinearity):
    """A dead zone with rounded corners of width ``width`` (tends to DeadZone as width -> 0).

    The output is w (softplus((|x| - delta) / w) - softplus(-delta / w)) sign(x),
    w = ``width``: 0 at 0, odd, smooth everywhere.

    Attributes
    ----------
    delta : str, default "delta_abs"
        Name of the half-width (threshold) parameter, in the units of the
        block's input.
    width : str, default "w_soft"
        Name of the corner-width parameter, in the units of the block's input
        (floored at 1e-12).
    """

    delta: str = "delta_abs"
    width: str = "w_soft"
    kind = B.NL_SOFT_DEADZONE

    @property
    def parameters(self) -> tuple[str, ...]:
        """The parameter names, ``(delta, width)``."""
        return (self.delta, self.width)

    @property
    def thresholds(self) -> tuple[str, ...]:
        """``(delta,)``: the half-width is a threshold, the corner width is not."""
        return (self.delta,)


@dataclass(frozen=True)
class Saturation(Nonlinearity):
    """Clipping at +- ``limit``.

    Attributes
    ----------
    limit : str, default "u_max"
        Name of the clipping-level parameter, in the units of the block's
        input (rad for a saturation on the model output u).
    """

    limit: str = "u_max"
    kind = B.NL_SATURATION

    @property
    def parameters(self) -> tuple[str, ...]:
        """The parameter names, ``(limit,)``."""
        return (self.limit,)


# --- gain modulation -------------------------------------------------------------
@dataclass(frozen=True)
class LinearDrift(Modulation):
    """Channel gain times 1 + rate (t/T - 1/2): a gain that drifts linearly over the run.

    t is the time from the start of the record and T its duration, so the gain
    is the channel's own at mid-run.  Before the record (the simulator's
    run-in, a likelihood's lead-in from rest) the gain keeps its value at the
    start, 1 - rate / 2.

    Attributes
    ----------
    rate : str, default "drift"
        Name of the drift parameter: the relative change of the gain over the
        whole run (dimensionless).
    """

    rate: str = "drift"
    kind = B.MOD_LINEAR

    @property
    def parameters(self) -> tuple[str, ...]:
        """The parameter names, ``(rate,)``."""
        return (self.rate,)


@dataclass(frozen=True)
class Channel:
    """One parallel path of the pilot model, from a source signal to the H_nm input.

    Parameters
    ----------
    name : str
        Channel name, e.g. ``"visual"``.
    source : str
        One of :data:`SOURCES`.
    delay : str
        Name of the time-delay parameter (s).
    gain : tuple of str
        Names of parameters whose product is the channel gain (empty: 1).
    stages : tuple of Stage
        Linear blocks applied to the source, in order (FixedFilter, Washout, ...).
    nonlinearity : Nonlinearity or None
        DeadZone, SoftDeadZone, Saturation (a :class:`Nonlinearity`) or None.
    lead : str or None
        Name of the lead time constant T in (1 + T s), or None.
    sign : {+1, -1}
        How the channel enters the sum.
    gain_const : float
        A constant factor on the gain.
    modulation : Modulation or None
        LinearDrift (a :class:`Modulation`) or None.
    oversample : int, default 1
        Run the channel's path after its parametric stages (nonlinearity,
        delay, its share of H_nm) at this many times the recording's rate in
        the likelihood, from the stage output interpolated linearly.  1 is
        the paper's computation; 8 removes most of a sampled dead zone's
        error at its corners (``docs/posteriors.md``) at about that many
        times the channel's cost.  The simulator ignores it (it always runs
        finer than it records).

    Raises
    ------
    ValueError
        On an unknown source, a sign other than +-1, more than two gain
        parameters or :data:`MAX_STAGES` stages, or a bad ``oversample``; a
        block whose ``kind`` is no code the kernels compute, or that names
        another number of parameters than the kernels read for its code
        (a subclass reusing a built-in block's code gets that block's maths),
        or defines a ``__call__`` they never call.
    TypeError
        If a stage is not a :class:`Stage`, the nonlinearity not a
        :class:`Nonlinearity` or the modulation not a :class:`Modulation`
        (the kernels would read the kind code of another family), or a
        block's ``parameters`` is not a tuple of names (a str).
    """

    name: str
    source: str
    delay: str
    gain: tuple[str, ...] = ()
    stages: tuple = ()
    nonlinearity: Nonlinearity | None = None
    lead: str | None = None
    sign: float = 1.0
    gain_const: float = 1.0
    modulation: Modulation | None = None
    oversample: int = 1

    def __post_init__(self) -> None:
        if self.source not in SOURCES:
            raise ValueError(f"channel {self.name!r}: unknown source {self.source!r}; "
                             f"choose from {', '.join(SOURCES)}")
        if self.sign not in (1.0, -1.0, 1, -1):
            raise ValueError(f"channel {self.name!r}: sign must be +1 or -1")
        if len(self.gain) > 2:
            raise ValueError(f"channel {self.name!r}: at most two gain parameters")
        if len(self.stages) > MAX_STAGES:
            raise ValueError(f"channel {self.name!r}: at most {MAX_STAGES} stages")
        for st in self.stages:
            _check_block(st, Stage, f"channel {self.name!r}: a stage", optional=False)
        _check_block(self.nonlinearity, Nonlinearity, f"channel {self.name!r}: the nonlinearity")
        _check_block(self.modulation, Modulation, f"channel {self.name!r}: the modulation")
        if isinstance(self.oversample, bool) or not isinstance(self.oversample, (int, np.integer)) \
                or not 1 <= self.oversample <= MAX_OVERSAMPLE:
            raise ValueError(f"channel {self.name!r}: oversample must be an integer in "
                             f"[1, {MAX_OVERSAMPLE}], got {self.oversample!r}")
        object.__setattr__(self, "oversample", int(self.oversample))
        object.__setattr__(self, "gain", tuple(self.gain))
        object.__setattr__(self, "stages", tuple(self.stages))

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the parameters the channel uses: delay, gains, lead, then its blocks'."""
        names = [self.delay, *self.gain]
        if self.lead:
            names.append(self.lead)
        for st in self.stages:
            names.extend(st.parameters)
        for blk in (self.nonlinearity, self.modulation):
            if blk is not None:
                names.extend(blk.parameters)
        return tuple(names)


@dataclass(frozen=True, eq=False)
class Plan:
    """A model compiled to the arrays the numba kernels interpret (see kernels/_response.py).

    Made by :attr:`PilotModel.plan`; parameters are referred to by their
    index in the full vector (-1: none).

    Attributes
    ----------
    names : tuple of str
        Every parameter name, in full-vector order.
    ch_int : ndarray of int64, shape (n_channels, CH_NFIELDS)
        Per channel: nonlinearity kind and parameter indices, delay, gain and
        lead indices, modulation kind and parameter index, number of stages,
        source code and oversampling factor (the ``CH_*`` columns).
    ch_float : ndarray, shape (n_channels, CHF_NFIELDS)
        Per channel: the constant gain factor and the sign.
    st_int : ndarray of int64, shape (n_channels, MAX_STAGES, 3)
        Per stage: kind code and the indices of its two parameters.
    st_const : ndarray, shape (n_channels, MAX_STAGES, 6)
        Per fixed stage: :meth:`FixedFilter.constants` (zero otherwise).
    out_int : ndarray of int64, shape (OUT_NFIELDS,)
        Indices of omega_nm and zeta_nm, then the output nonlinearity's kind
        and parameter indices.
    sources : tuple of str
        Each channel's source signal (a key of :data:`SOURCES`).
    """

    names: tuple[str, ...]
    ch_int: np.ndarray
    ch_float: np.ndarray
    st_int: np.ndarray
    st_const: np.ndarray
    out_int: np.ndarray
    sources: tuple[str, ...]


def semicircular_canal() -> FixedFilter:
    """Reduced canal model, Eq. 1: K_scc (1 + T1 s) / (1 + T2 s), IPUT per rad/s^2.

    Returns
    -------
    FixedFilter
        The canal's transfer function with the constants of ``presets``
        (K_SCC, T_SCC1, T_SCC2).
    """
    return FixedFilter((presets.K_SCC * presets.T_SCC1, presets.K_SCC), (presets.T_SCC2, 1.0))


def _paper_parameters() -> tuple[Parameter, ...]:
    units = presets.PARAMETER_UNITS
    desc = {
        "K_v": "visual gain", "T_vl": "visual lead time constant", "tau_v": "visual delay",
        "K_m": "motion gain", "tau_m": "motion delay", "omega_nm": "neuromuscular frequency",
        "zeta_nm": "neuromuscular damping", "delta_abs": "absolute threshold on canal output",
    }
    fd = presets.TABLE3["FD"]
    return tuple(Parameter(n, *presets.TABLE1_BOUNDS[n], fd[n], units[n], desc[n])
                 for n in presets.PARAMETER_NAMES)


@dataclass(frozen=True, eq=False)
class PilotModel(SummaryHTML):
    """A multimodal pilot model: channels, neuromuscular block, parameters.

    Use :func:`paper_model` for the model of Pool et al. (2012) and the
    ``add_*``/``with_*`` methods to extend it.

    Parameters
    ----------
    channels : sequence of Channel
    parameters : sequence of Parameter
        Every parameter the channels refer to (order = full-vector order).
    omega_nm, zeta_nm : str
        Names of the neuromuscular frequency and damping parameters.
    output : Nonlinearity or None
        A nonlinearity on the model output (e.g. control saturation).
    fixed : mapping of str to float
        Parameters held at a value (not estimated), e.g. ``{"delta_abs": 0}``.
    name : str
        A label for reports.

    Raises
    ------
    ValueError
        On duplicate parameter or channel names, a parameter used but not
        declared, or a fixed value of an unknown parameter, or one that is
        complex or not finite.
    TypeError
        If ``output`` is not a :class:`Nonlinearity` (or None); the output
        block is checked as a channel's blocks are (:class:`Channel`).
    """

    channels: tuple[Channel, ...]
    parameters: tuple[Parameter, ...]
    omega_nm: str = "omega_nm"
    zeta_nm: str = "zeta_nm"
    output: Nonlinearity | None = None
    fixed: Mapping[str, float] = field(default_factory=dict)
    name: str = "pilot model"

    def __post_init__(self) -> None:
        object.__setattr__(self, "channels", tuple(self.channels))
        object.__setattr__(self, "parameters", tuple(self.parameters))
        object.__setattr__(self, "fixed", dict(self.fixed))
        _check_block(self.output, Nonlinearity, "the output block")
        known = [p.name for p in self.parameters]
        if len(set(known)) != len(known):
            raise ValueError("duplicate parameter names")
        if len({c.name for c in self.channels}) != len(self.channels):
            raise ValueError("duplicate channel names")
        used = _used_names(self.channels, self.output, self.omega_nm, self.zeta_nm)
        missing = sorted(used - set(known))
        if missing:
            raise ValueError(f"parameters used but not declared: {', '.join(missing)}")
        for k, v in self.fixed.items():
            if k not in known:
                raise ValueError(f"cannot fix unknown parameter {k!r}; known: {', '.join(known)}")
            if not math.isfinite(_real(v, f"fixed value of {k}")):
                raise ValueError(f"fixed value of {k} must be finite")

    # -- parameter bookkeeping -----------------------------------------------
    @property
    def all_names(self) -> tuple[str, ...]:
        """Every parameter name, in full-vector order."""
        return tuple(p.name for p in self.parameters)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the free (estimated) parameters, in vector order."""
        return tuple(p.name for p in self.parameters if p.name not in self.fixed)

    @property
    def n_free(self) -> int:
        """Number of free (estimated) parameters."""
        return len(self.parameter_names)

    def parameter(self, name: str) -> Parameter:
        """The declared :class:`Parameter` called ``name`` (free or fixed).

        Parameters
        ----------
        name : str
            The parameter's name, e.g. ``"delta_abs"``.

        Returns
        -------
        Parameter

        Raises
        ------
        KeyError
            No parameter of that name (a lookup by name, as a dict's).
        """
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(f"unknown parameter {name!r}; known: {', '.join(self.all_names)}")

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) arrays of the free parameters."""
        ps = [self.parameter(n) for n in self.parameter_names]
        return np.array([p.lower for p in ps]), np.array([p.upper for p in ps])

    @property
    def defaults(self) -> dict[str, float]:
        """Every parameter's default value by name (fixed ones too), in its unit."""
        return {p.name: p.default for p in self.parameters}

    @cached_property
    def free_index(self) -> np.ndarray:
        """Positions of the free parameters in the full vector."""
        full = self.all_names
        return np.array([full.index(n) for n in self.parameter_names], dtype=np.int64)

    def full_vector(self, values: Mapping[str, float] | Sequence[float] | np.ndarray | None = None) -> np.ndarray:
        """Full parameter vector from free values (by name or in order), defaults and fixed values.

        Parameters
        ----------
        values : mapping of str to float, sequence of float, ndarray or None, optional
            Values by name (free parameters not given take their defaults;
            values given for fixed parameters are ignored), or the
            free-parameter vector in :attr:`parameter_names` order, or None
            (the defaults).

        Returns
        -------
        ndarray, shape (len(all_names),)
            Every parameter's value in :attr:`all_names` order, fixed ones at
            their fixed values.

        Raises
        ------
        ValueError
            On unknown or misspelled names, a wrong length, or complex or
            non-finite values.
        """
        full = np.array([p.default for p in self.parameters], dtype=float)
        names = self.all_names
        for k, v in self.fixed.items():
            full[names.index(k)] = float(v)
        if values is None:
            return full
        if isinstance(values, Mapping):
            unknown = [k for k in values if k not in names]
            if unknown:
                raise ValueError(f"unknown parameter(s) {', '.join(map(repr, unknown))}; "
                                 f"this model has {', '.join(names)}")
            for k, v in values.items():
                if k in self.fixed:
                    continue
                full[names.index(k)] = _parameter_value(k, v)
            return full
        if _is_complex(values):
            raise ValueError("parameter values must be real numbers, got complex values")
        arr = np.asarray(values, dtype=float)
        if arr.shape != (self.n_free,):
            raise ValueError(f"expected {self.n_free} free parameter values "
                             f"({', '.join(self.parameter_names)}), got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError("parameter values must be finite")
        full[self.free_index] = arr
        return full

    def free_vector(self, values: Mapping[str, float] | None = None) -> np.ndarray:
        """Free-parameter vector from values by name (defaults for the rest).

        Parameters
        ----------
        values : mapping of str to float or None, optional
            Values by name; free parameters not given take their defaults,
            values of fixed parameters are ignored.  None: the defaults.

        Returns
        -------
        ndarray, shape (n_free,)
            The free parameters' values in :attr:`parameter_names` order.

        Raises
        ------
        ValueError
            As :meth:`full_vector`.
        """
        return self.full_vector(values)[self.free_index]

    def as_dict(self, vector: np.ndarray | Sequence[float], *, full: bool = False) -> dict[str, float]:
        """Name -> value from a free (default) or full vector.

        Parameters
        ----------
        vector : ndarray or sequence of float
            Values in :attr:`parameter_names` order, or in :attr:`all_names`
            order with ``full=True``.
        full : bool, default False
            ``vector`` is the full vector (every parameter, fixed ones too).

        Returns
        -------
        dict of str to float

        Raises
        ------
        ValueError
            If ``vector`` is not of the length the names have.
        """
        vec = np.asarray(vector, dtype=float)
        names = self.all_names if full else self.parameter_names
        if vec.shape != (len(names),):
            raise ValueError(f"expected {len(names)} values, got shape {vec.shape}")
        return {n: float(x) for n, x in zip(names, vec)}

    # -- building new models ----------------------------------------------------
    def _with_params(self, new: Iterable[Parameter]) -> tuple[Parameter, ...]:
        """The parameters plus ``new``; a name declared again must be declared alike."""
        params = list(self.parameters)
        have = {p.name: p for p in params}
        for p in new:
            old = have.get(p.name)
            if old is None:
                params.append(p)
                have[p.name] = p
            elif ((old.lower, old.upper, old.default, old.unit)
                  != (p.lower, p.upper, p.default, p.unit)):
                raise ValueError(
                    f"parameter {p.name} is already declared with bounds "
                    f"[{old.lower:g}, {old.upper:g}], "
                    f"default {old.default:g}, unit {old.unit!r}; the new declaration has "
                    f"[{p.lower:g}, {p.upper:g}], default {p.default:g}, unit {p.unit!r} "
                    "(use another name, or declare it alike to share it)")
        return tuple(params)

    def _rebuilt(self, **fields: Any) -> "PilotModel":
        """``replace(self, **fields)`` without the parameters that no block uses any more (a
        replaced block's; dropped from ``fixed`` too), so that a builder never leaves a
        parameter behind for the fitters to estimate in vain."""
        get = lambda k: fields.get(k, getattr(self, k))  # noqa: E731
        used = _used_names(get("channels"), get("output"), get("omega_nm"), get("zeta_nm"))
        before = _used_names(self.channels, self.output, self.omega_nm, self.zeta_nm)
        # only parameters this change stopped using: one the model declared unused (fixed) stays
        dropped = before - used
        fields["parameters"] = tuple(p for p in get("parameters") if p.name not in dropped)
        fields["fixed"] = {k: v for k, v in get("fixed").items() if k not in dropped}
        return replace(self, **fields)

    def _channel(self, name: str) -> int:
        for i, c in enumerate(self.channels):
            if c.name == name:
                return i
        raise UnknownChannelError(f"no channel {name!r} in this model; channels: "
                                  f"{', '.join(c.name for c in self.channels)}")

    def _with_block(self, name: str, block: Any, params: Iterable[Parameter],
                    **change: Callable[[Channel], Any]) -> "PilotModel":
        """The model with channel ``name``'s fields replaced by ``change`` (field -> function
        of the channel), ``params`` declared, and ``block`` named in the model's name."""
        chans = list(self.channels)
        i = self._channel(name)
        chans[i] = replace(chans[i], **{k: f(chans[i]) for k, f in change.items()})
        return self._rebuilt(channels=tuple(chans), parameters=self._with_params(params),
                             name=f"{self.name} + {type(block).__name__} on {name}")

    def fix(self, **values: float) -> "PilotModel":
        """A model with some parameters held fixed, e.g. ``fix(delta_abs=0.0)``.

        Parameters
        ----------
        **values : float
            Parameter name -> the value to hold it at, in its unit (added to
            the already fixed ones; a name fixed before takes the new value).

        Returns
        -------
        PilotModel
            A new model; this one is unchanged.

        Raises
        ------
        ValueError
            On an unknown parameter, or a value that is complex, not finite or
            outside the parameter's bounds.
        """
        known = {p.name: p for p in self.parameters}
        for k, v in values.items():
            p, x = known.get(k), _real(v, f"fixed value of {k}")
            if p is not None and math.isfinite(x) and not p.lower <= x <= p.upper:
                raise ValueError(f"fix: {k} = {x:g} is outside its bounds "
                                 f"[{p.lower:g}, {p.upper:g}]")
        return self._fixed(**values)

    def _fixed(self, **values: float) -> "PilotModel":
        """:meth:`fix` without the bounds check, for the package's nested models: the model
        without threshold is ``delta_abs = 0`` whatever the bounds a user gave the threshold
        (a lower bound above 0 made every fit refuse its own threshold-free start), and a
        control limit is the level read from the flat tops."""
        fixed = dict(self.fixed)
        fixed.update({k: _real(v, f"fixed value of {k}") for k, v in values.items()})
        return replace(self, fixed=fixed)

    def free(self, *names: str) -> "PilotModel":
        """A model in which the named fixed parameters are estimated again (a free one named
        stays free).

        Parameters
        ----------
        *names : str
            Names of the parameters to free.

        Returns
        -------
        PilotModel
            A new model; this one is unchanged.

        Raises
        ------
        ValueError
            On a name the model does not have.
        """
        unknown = [n for n in names if n not in self.all_names]
        if unknown:
            raise ValueError(f"free: unknown parameter(s) {', '.join(map(repr, unknown))}; "
                             f"this model has {', '.join(self.all_names)}")
        return replace(self, fixed={k: v for k, v in self.fixed.items() if k not in names})

    def add_stage(self, channel: str, stage: Stage, parameters: Iterable[Parameter] = ()) -> "PilotModel":
        """Append a linear stage (e.g. :class:`Washout`) to a channel, before its nonlinearity.

        Parameters
        ----------
        channel : str
            Name of the channel, e.g. ``"vestibular"``.
        stage : Stage
            The block to append after the channel's other stages.
        parameters : iterable of Parameter, default ()
            Declarations of the block's new parameters (bounds, default,
            unit).  A name the model already declares may be given again
            only with the same bounds, default and unit (it is then shared).

        Returns
        -------
        PilotModel
            A new model; this one is unchanged.

        Raises
        ------
        ValueError
            On an unknown channel, an undeclared parameter, a parameter
            declared again with other bounds, default or unit, or a block the
            kernels do not compute as declared (its code, its number of
            parameters: :class:`Channel`).
        TypeError
            If ``stage`` is not a :class:`Stage`, or its ``parameters`` not a
            tuple of names.
        """
        _check_block(stage, Stage, "add_stage: the stage", optional=False)
        return self._with_block(channel, stage, parameters, stages=lambda c: c.stages + (stage,))

    def with_nonlinearity(self, channel: str, nonlinearity: Nonlinearity | None,
                          parameters: Iterable[Parameter] = ()) -> "PilotModel":
        """Replace a channel's nonlinearity (e.g. a :class:`SoftDeadZone` threshold; None: none).

        Parameters
        ----------
        channel : str
            Name of the channel, e.g. ``"vestibular"``.
        nonlinearity : Nonlinearity or None
            The new nonlinearity; None removes it.
        parameters : iterable of Parameter, default ()
            Declarations of the block's new parameters (bounds, default,
            unit).  A name the model already declares may be given again
            only with the same bounds, default and unit (it is then shared).

        Returns
        -------
        PilotModel
            A new model; this one is unchanged.  The old nonlinearity's
            parameters that no other block uses are dropped (a threshold
            replaced by a saturation leaves no ``delta_abs`` to estimate).

        Raises
        ------
        ValueError
            On an unknown channel, an undeclared parameter, a parameter
            declared again with other bounds, default or unit, or a block the
            kernels do not compute as declared (its code, its number of
            parameters: :class:`Channel`).
        TypeError
            If ``nonlinearity`` is neither a :class:`Nonlinearity` nor None, or its
            ``parameters`` not a tuple of names.
        """
        _check_block(nonlinearity, Nonlinearity, "with_nonlinearity: the nonlinearity")
        return self._with_block(channel, nonlinearity, parameters,
                                nonlinearity=lambda c: nonlinearity)

    def with_modulation(self, channel: str, modulation: Modulation | None,
                        parameters: Iterable[Parameter] = ()) -> "PilotModel":
        """Modulate a channel's gain over the run (e.g. :class:`LinearDrift`; None: constant).

        Parameters
        ----------
        channel : str
            Name of the channel, e.g. ``"visual"``.
        modulation : Modulation or None
            The new gain modulation; None makes the gain constant.
        parameters : iterable of Parameter, default ()
            Declarations of the block's new parameters (bounds, default,
            unit).  A name the model already declares may be given again
            only with the same bounds, default and unit (it is then shared).

        Returns
        -------
        PilotModel
            A new model; this one is unchanged.  Parameters that only the
            replaced block used are dropped.

        Raises
        ------
        ValueError
            On an unknown channel, an undeclared parameter, a parameter
            declared again with other bounds, default or unit, or a block the
            kernels do not compute as declared (its code, its number of
            parameters: :class:`Channel`).
        TypeError
            If ``modulation`` is neither a :class:`Modulation` nor None, or its
            ``parameters`` not a tuple of names.
        """
        _check_block(modulation, Modulation, "with_modulation: the modulation")
        return self._with_block(channel, modulation, parameters, modulation=lambda c: modulation)

    def with_channel(self, channel: str, parameters: Iterable[Parameter] = (),
                     **fields: Any) -> "PilotModel":
        """Change fields of a channel: a lead, its delay, gain, sign, source, stages, ...

        For what the block builders (:meth:`add_stage`, :meth:`with_nonlinearity`,
        :meth:`with_modulation`) do not cover: e.g. a lead (1 + T_ml s) on the motion
        channel, ``with_channel("vestibular", lead="T_ml", parameters=[Parameter("T_ml", 0.0,
        1.0, 0.1, "s")])``.  The channel is rebuilt with the new fields (and checked as
        :class:`Channel` checks any); a parameter only the old fields read is dropped.

        Parameters
        ----------
        channel : str
            Name of the channel, e.g. ``"vestibular"``.
        parameters : iterable of Parameter, default ()
            Declarations of the new parameters the fields name (bounds, default, unit).  A
            name the model already declares may be given again only with the same bounds,
            default and unit (it is then shared: ``delay="tau_v"`` gives the channel the
            visual channel's delay).
        **fields
            :class:`Channel` fields and their new values (not ``name``).

        Returns
        -------
        PilotModel
            A new model; this one is unchanged.

        Raises
        ------
        TypeError
            A field :class:`Channel` does not have (or ``name``), none given, or a value
            :class:`Channel` refuses by type (a stage that is not a :class:`Stage`, ...).
        ValueError
            On an unknown channel, an undeclared parameter, a parameter declared again
            with other bounds, default or unit, or a value :class:`Channel` refuses.

        Examples
        --------
        >>> lead = paper_model().with_channel(
        ...     "vestibular", lead="T_ml", parameters=[Parameter("T_ml", 0.0, 1.0, 0.1, "s")])
        >>> lead.parameter_names[-1], lead.channels[1].lead
        ('T_ml', 'T_ml')
        """
        from dataclasses import fields as dataclass_fields

        known = {f.name for f in dataclass_fields(Channel)} - {"name"}
        unknown = sorted(set(fields) - known)
        if unknown or not fields:
            said = f"unknown field(s) {', '.join(unknown)}" if unknown else "no field given"
            raise TypeError(f"with_channel: {said}; a channel's fields are "
                            f"{', '.join(sorted(known))}")
        chans = list(self.channels)
        i = self._channel(channel)
        chans[i] = replace(chans[i], **fields)
        return self._rebuilt(channels=tuple(chans), parameters=self._with_params(parameters),
                             name=f"{self.name} + {channel} with "
                                  f"{', '.join(f'{k}={v!r}' for k, v in fields.items())}")

    def add_channel(self, channel: Channel, parameters: Iterable[Parameter] = ()) -> "PilotModel":
        """Add a parallel channel (e.g. an otolith channel).

        Parameters
        ----------
        channel : Channel
            The new channel; its name must differ from the model's channels'.
        parameters : iterable of Parameter, default ()
            Declarations of the channel's new parameters (bounds, default,
            unit).  A name the model already declares may be given again
            only with the same bounds, default and unit (it is then shared).

        Returns
        -------
        PilotModel
            A new model; this one is unchanged.

        Raises
        ------
        ValueError
            On a duplicate channel name, an undeclared parameter, or a
            parameter declared again with other bounds, default or unit.
        """
        return replace(self, channels=self.channels + (channel,),
                       parameters=self._with_params(parameters),
                       name=f"{self.name} + {channel.name} channel")

    def with_oversampling(self, factor: int, channels: str | Sequence[str] | None = None) -> "PilotModel":
        """A model whose likelihood runs some channels at ``factor`` times the recording's rate.

        Parameters
        ----------
        factor : int
            Oversampling factor M, 1 to :data:`MAX_OVERSAMPLE` (1: the paper's computation).
        channels : str or sequence of str, optional
            The channel, or channels, to oversample; default: every channel
            with a nonlinearity (the dead-zone threshold), where a sampled
            signal errs most (a linear channel gains little).

        Returns
        -------
        PilotModel
            The same parameters and structure; see :attr:`Channel.oversample`.

        Raises
        ------
        ValueError
            On an unknown channel, a bad ``factor``, or (``channels`` not
            given) a model without a nonlinearity.

        Examples
        --------
        >>> paper_model().with_oversampling(8).channels[1].oversample
        8
        """
        if channels is None:
            channels = [c.name for c in self.channels if c.nonlinearity is not None]
            if not channels:
                raise ValueError("no channel has a nonlinearity; name the channels to oversample")
        elif isinstance(channels, str):
            channels = [channels]
        else:
            channels = list(channels)
        chans = list(self.channels)
        for name in channels:
            i = self._channel(name)
            chans[i] = replace(chans[i], oversample=factor)
        model = replace(self, channels=tuple(chans))
        return model if factor == 1 else replace(model, name=f"{self.name}, {factor}x {', '.join(channels)}")

    def with_output(self, output: Nonlinearity | None, parameters: Iterable[Parameter] = ()) -> "PilotModel":
        """Put a nonlinearity (e.g. :class:`Saturation`) on the model output (None: none).

        Parameters
        ----------
        output : Nonlinearity or None
            The block applied to the model output u (after H_nm); None
            removes it.
        parameters : iterable of Parameter, default ()
            Declarations of the block's new parameters (bounds, default,
            unit).  A name the model already declares may be given again
            only with the same bounds, default and unit (it is then shared).

        Returns
        -------
        PilotModel
            A new model; this one is unchanged.  Parameters that only the
            replaced block used are dropped.

        Raises
        ------
        ValueError
            On an undeclared parameter, a parameter declared again with
            other bounds, default or unit, or a block the kernels do not
            compute as declared (its code, its number of parameters:
            :class:`Channel`).
        TypeError
            If ``output`` is neither a :class:`Nonlinearity` nor None, or its
            ``parameters`` not a tuple of names.
        """
        _check_block(output, Nonlinearity, "with_output: the output block")
        return self._rebuilt(output=output, parameters=self._with_params(parameters),
                             name=f"{self.name} + output {type(output).__name__}")

    @property
    def has_threshold(self) -> bool:
        """True if a channel's or the output's nonlinearity has a threshold
        (:attr:`Nonlinearity.thresholds`) that is estimated or fixed at a nonzero value, or a
        parameter named ``delta_abs`` is estimated (the name the fitters scan and profile as
        the threshold, whatever block reads it: a fit of such a model reads "with threshold",
        :attr:`~bayespilot.fit.result.FitResult.threshold`)."""
        if "delta_abs" in self.parameter_names:
            return True
        return any(self.fixed.get(name, None) != 0.0 for name in self._threshold_names)

    @property
    def _threshold_names(self) -> tuple[str, ...]:
        """The names the channels' and the output's nonlinearities declare as thresholds
        (:attr:`Nonlinearity.thresholds`), each once, in the model's order."""
        return tuple(dict.fromkeys(name for nl in [c.nonlinearity for c in self.channels]
                                   + [self.output] if nl is not None
                                   for name in nl.thresholds))

    def without_threshold(self) -> "PilotModel":
        """The model without threshold: the null model that the fitters' ``threshold=False``
        and the comparison with and without threshold take.

        A soft dead zone (:class:`SoftDeadZone`, or any block of its kind code) is not the
        identity at a half-width of 0 (it still halves small inputs): it is removed, with the
        parameters only it read (its ``w_soft``).  Every other nonlinearity that has
        thresholds (:attr:`Nonlinearity.thresholds`) has them held at 0: a dead zone
        (:class:`DeadZone`) is the identity there, so for the paper's model that is
        ``delta_abs`` fixed at 0, the model of ``paper_model(threshold=False)`` (the same
        parameters, in the same order); a block of one's own that declares a threshold (e.g.
        a :class:`Saturation` subclass in a dead zone composed of channels, the linear
        channel minus a clipped copy: clipped at 0 the copy is silent and the difference
        linear) keeps its place, as removing it would change what the other channels
        compute.  A parameter named ``delta_abs`` still estimated after that (read by a block
        that declares no threshold) is held at 0 too, as the fitters take that name for the
        threshold.

        Returns
        -------
        PilotModel
            The model without threshold (:attr:`has_threshold` False); this model itself if
            it has none already.  A model that lost a block is renamed to say so.

        Examples
        --------
        >>> paper_model().without_threshold().fixed
        {'delta_abs': 0.0}
        >>> soft = paper_model().with_nonlinearity(
        ...     "vestibular", SoftDeadZone("delta_abs", "w_soft"),
        ...     [Parameter("w_soft", 1e-5, 0.05, 0.002, "IPUT")])
        >>> soft.without_threshold().parameter_names
        ('K_v', 'T_vl', 'tau_v', 'K_m', 'tau_m', 'omega_nm', 'zeta_nm')
        """
        zero: dict[str, float] = {}
        removed: list[str] = []

        def keep(nl, where: str):
            """The block in place of ``nl`` (None: removed), its thresholds held at 0."""
            if nl is None or not tuple(nl.thresholds):
                return nl
            if nl.kind != B.NL_SOFT_DEADZONE:  # (a dead zone: the identity at 0)
                zero.update((name, 0.0) for name in nl.thresholds)
                return nl
            removed.append(f"{type(nl).__name__} {where}")
            return None

        chans = tuple(replace(c, nonlinearity=n) if n is not c.nonlinearity else c
                      for c in self.channels
                      for n in [keep(c.nonlinearity, f"on {c.name}")])
        output = keep(self.output, "on the output")
        model = self
        if removed:
            model = self._rebuilt(channels=chans, output=output,
                                  name=f"{self.name}, no threshold ({', '.join(removed)} "
                                       "removed)")
        if "delta_abs" in model.parameter_names:
            zero.setdefault("delta_abs", 0.0)
        zero = {k: v for k, v in zero.items() if model.fixed.get(k, None) != v}
        return model._fixed(**zero) if zero else model

    # -- compile --------------------------------------------------------------
    @cached_property
    def plan(self) -> Plan:
        """The model as kernel tables (cached).

        Raises
        ------
        ValueError
            If a free parameter is read by no block.
        """
        # A free parameter that no block reads has a zero Jacobian column: a fitter would
        # "estimate" it anywhere in its bounds and report it (a delta_abs without a dead zone).
        # Checked here, where the model is put to use, not when it is built: a builder may
        # declare a parameter one step before the block that reads it (add_channel twice).
        used = _used_names(self.channels, self.output, self.omega_nm, self.zeta_nm)
        idle = [n for n in self.parameter_names if n not in used]
        if idle:
            raise ValueError(f"parameters declared but used by no block: {', '.join(idle)} "
                             "(a parameter no block reads cannot be estimated: leave it out, "
                             "or fix it)")
        names = self.all_names
        idx = {n: i for i, n in enumerate(names)}

        def ix(name):
            return -1 if name is None else idx[name]

        nc = len(self.channels)
        ch_int = np.full((nc, R.CH_NFIELDS), -1, dtype=np.int64)
        ch_float = np.zeros((nc, R.CHF_NFIELDS))
        st_int = np.full((nc, MAX_STAGES, 3), -1, dtype=np.int64)
        st_int[:, :, 0] = B.STAGE_NONE
        st_const = np.zeros((nc, MAX_STAGES, 6))
        for c, ch in enumerate(self.channels):
            nl = ch.nonlinearity
            ch_int[c, R.CH_NL_KIND] = B.NL_NONE if nl is None else nl.kind
            if nl is not None:
                ps = nl.parameters
                ch_int[c, R.CH_NL_P0] = ix(ps[0])
                ch_int[c, R.CH_NL_P1] = ix(ps[1]) if len(ps) > 1 else -1
            ch_int[c, R.CH_DELAY] = ix(ch.delay)
            ch_int[c, R.CH_GAIN0] = ix(ch.gain[0]) if len(ch.gain) > 0 else -1
            ch_int[c, R.CH_GAIN1] = ix(ch.gain[1]) if len(ch.gain) > 1 else -1
            ch_int[c, R.CH_LEAD] = ix(ch.lead)
            mod = ch.modulation
            ch_int[c, R.CH_MOD_KIND] = B.MOD_NONE if mod is None else mod.kind
            ch_int[c, R.CH_MOD_P0] = -1 if mod is None else ix(mod.parameters[0])
            ch_int[c, R.CH_NSTAGES] = len(ch.stages)
            ch_int[c, R.CH_SOURCE] = SOURCE_CODES[ch.source]
            ch_int[c, R.CH_OVERSAMPLE] = ch.oversample
            ch_float[c, R.CHF_GAIN_CONST] = ch.gain_const
            ch_float[c, R.CHF_SIGN] = float(ch.sign)
            for s, st in enumerate(ch.stages):
                st_int[c, s, 0] = st.kind
                ps = st.parameters
                st_int[c, s, 1] = ix(ps[0]) if len(ps) > 0 else -1
                st_int[c, s, 2] = ix(ps[1]) if len(ps) > 1 else -1
                if isinstance(st, FixedFilter):
                    st_const[c, s] = st.constants()
        out_int = np.full(R.OUT_NFIELDS, -1, dtype=np.int64)
        out_int[R.OUT_OMEGA] = ix(self.omega_nm)
        out_int[R.OUT_ZETA] = ix(self.zeta_nm)
        out_int[R.OUT_NL_KIND] = B.NL_NONE if self.output is None else self.output.kind
        if self.output is not None:
            ps = self.output.parameters
            out_int[R.OUT_NL_P0] = ix(ps[0])
            out_int[R.OUT_NL_P1] = ix(ps[1]) if len(ps) > 1 else -1
        return Plan(names, ch_int, ch_float, st_int, st_const, out_int,
                    tuple(c.source for c in self.channels))

    def summary(self) -> str:
        """A readable description of the structure and parameters."""
        lines = [f"{self.name}: {len(self.channels)} channel(s) -> H_nm({self.omega_nm}, {self.zeta_nm})"]
        for c in self.channels:
            parts = [c.source]
            parts += [type(s).__name__ for s in c.stages]
            if c.nonlinearity is not None:
                parts.append(type(c.nonlinearity).__name__)
            g = "*".join(c.gain) or "1"
            lead = f"(1 + {c.lead} s)" if c.lead else ""
            parts.append(f"{'-' if c.sign < 0 else '+'}{g}{lead} e^(-{c.delay} s)")
            if c.oversample > 1:
                parts.append(f"[{c.oversample}x the rate]")
            lines.append(f"  {c.name}: " + " -> ".join(parts))
        lines.append("  parameters: " + ", ".join(
            f"{p.name}" + (f"={self.fixed[p.name]:g} (fixed)" if p.name in self.fixed else "")
            for p in self.parameters))
        return "\n".join(lines)


def paper_model(threshold: bool = True, oversample: int = 1) -> PilotModel:
    """The multimodal pilot model of Pool et al. (2012), Fig. 4 and Eq. 2-3.

    Parameters
    ----------
    threshold : bool, default True
        With ``False``, ``delta_abs`` is fixed at 0: the model without threshold
        (the same model, one parameter fewer).
    oversample : int, default 1
        Run the vestibular channel (dead zone, delay, H_nm) at this many
        times the recording's rate in the likelihood
        (:meth:`PilotModel.with_oversampling`).  1 (the default) is the
        paper's computation at the recording's rate; 8 makes the
        threshold's credible intervals calibrated (``docs/posteriors.md``).
        Applied with and without threshold alike, so the two compare on
        one discretisation.

    Returns
    -------
    PilotModel
        Visual channel K_v (T_vl s + 1) e^(-tau_v s) on e; vestibular channel
        -K_m e^(-tau_m s) on the canal output of theta_ddot_m through the dead
        zone delta_abs; both through H_nm (omega_nm, zeta_nm); the paper's
        bounds (Table 1) and Table 3's FD values as start values.

    Examples
    --------
    >>> paper_model().parameter_names
    ('K_v', 'T_vl', 'tau_v', 'K_m', 'tau_m', 'omega_nm', 'zeta_nm', 'delta_abs')
    >>> paper_model(threshold=False).n_free
    7
    """
    visual = Channel("visual", "e", delay="tau_v", gain=("K_v",), lead="T_vl")
    vestibular = Channel("vestibular", "theta_ddot_m", delay="tau_m", gain=("K_m",),
                         stages=(semicircular_canal(),), nonlinearity=DeadZone("delta_abs"),
                         sign=-1.0)
    model = PilotModel((visual, vestibular), _paper_parameters(), name="Pool et al. (2012)")
    if not threshold:
        model = replace(model.fix(delta_abs=0.0), name="Pool et al. (2012), no threshold")
    if oversample != 1:
        model = model.with_oversampling(oversample, ("vestibular",))
    return model

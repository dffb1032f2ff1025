"""The catalogue of physics the paper's pilot model leaves out, each a model extension.

Every entry is an :class:`Extension`: a name, a function that turns a base
:class:`~bayespilot.model.PilotModel` into the extended model through the
model's extension point (``add_stage``, ``add_channel``,
``with_nonlinearity``, ``with_modulation``, ``with_output``), the new
parameters with their bounds, a short physics description, and the signature
it should leave in the located evidence (keys of
:data:`bayespilot.diagnose.locate.EVIDENCE`, which
:func:`~bayespilot.diagnose.locate.statistics` measures).

The six entries and their conventions
-------------------------------------
``motion-system-dynamics``
    The platform's bandwidth and lag between the commanded motion (which the
    recording logs as ``theta_ddot_m``) and the motion the pilot feels: a
    second-order low-pass omega_ms^2 / (s^2 + 2 zeta_ms omega_ms s + omega_ms^2)
    on the vestibular channel (before the threshold).
``motion-washout``
    High-pass filtering of the presented motion by the motion-cueing
    algorithm: a second-order washout s^2 / (s^2 + 2 zeta_w omega_w s + omega_w^2)
    on the vestibular channel with zeta_w fixed at 0.7 (the usual tuning) and
    omega_w estimated.
``otolith-channel``
    A parallel response to the specific force at the pilot's head.  With x
    forward, z down and nose-up pitch positive, a head at height h ABOVE the
    pitch rotation point (h > 0 above, h < 0 below; bounds +-3 m) feels

        f_x = g theta_m - h theta_ddot_m,   g = 9.81 m/s^2,

    theta_m = K_theta theta from the recording's ``theta`` column.  The
    otolith dynamics are fixed, the Young & Meiry (1968) model with unit static
    gain, H_oto(s) = (1 + 13.2 s) / ((1 + 5.33 s)(1 + 0.66 s)).  Since the
    channel is linear it is built as two parallel channels (one on theta_m,
    one on theta_ddot_m) that share the gain K_ot (rad per m/s^2) and the
    vestibular delay tau_m, and enter with the vestibular channel's minus
    sign: u gets -K_ot H_nm e^{-tau_m s} H_oto f_x.
``threshold-shape``
    A threshold that is not a crisp dead zone: the softplus-rounded dead zone
    of :class:`~bayespilot.model.SoftDeadZone` with corner width w_soft (IPUT);
    w_soft -> 0 is the paper's dead zone.
``time-varying-gains``
    Pilot gains that drift during the run: K_v and K_m each multiplied by
    1 + drift (t/T - 1/2) (:class:`~bayespilot.model.LinearDrift`).
``control-saturation``
    The control clipped at the device's travel limits.  u shows flat tops
    (runs of samples at the same extreme value); those samples are censored
    (the pilot's command was at least that large), and the extension is
    fitted by the censored (Tobit) likelihood of
    :mod:`bayespilot.kernels._censored`.  The limits are read from the flat
    tops, not estimated.

Entries of your own
-------------------
:func:`register_extension` adds an entry to the catalogue for this process,
after checking it; :func:`get_extension` finds it after the built-in ones,
``diagnose(candidates=None)`` tests it after them (:func:`candidate_names`),
and :func:`registered_extensions` and :func:`unregister_extension` list and
remove such entries.  :data:`CATALOGUE` and :data:`NAMES` stay the built-in
entries.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Mapping

from ..model import (Channel, FixedFilter, LinearDrift, MotionSystem, Parameter, PilotModel,
                     Saturation, SecondOrderWashout, SoftDeadZone)

if TYPE_CHECKING:
    import numpy as np

    from ..recording import Recording

__all__ = ["Extension", "CATALOGUE", "NAMES", "G", "OTOLITH_NUM", "OTOLITH_DEN",
           "otolith_filter", "get_extension", "specific_force", "LIKELIHOODS",
           "register_extension", "unregister_extension", "registered_extensions",
           "candidate_names"]

#: Gravity used in the specific force, m/s^2.
G = 9.81
#: Young & Meiry (1968) otolith model, unit static gain: (1 + 13.2 s) / ((1 + 5.33 s)(1 + 0.66 s)).
OTOLITH_NUM = (13.2, 1.0)
OTOLITH_DEN = (5.33 * 0.66, 5.33 + 0.66, 1.0)


def otolith_filter() -> FixedFilter:
    """The fixed otolith dynamics H_oto(s) (Young & Meiry 1968, unit static gain).

    Returns
    -------
    FixedFilter
        H_oto(s) = (1 + 13.2 s) / ((1 + 5.33 s)(1 + 0.66 s)) (:data:`OTOLITH_NUM`,
        :data:`OTOLITH_DEN`), a stage of the ``otolith-channel`` entry's two channels.
    """
    return FixedFilter(OTOLITH_NUM, OTOLITH_DEN)


def specific_force(recording: Recording, h_head: float) -> np.ndarray:
    """Specific force along x at the pilot's head, f_x = g theta_m - h theta_ddot_m (m/s^2).

    theta_m = K_theta theta from the recording's ``theta`` column; ``h_head``
    is the head's height above the pitch rotation point (positive above), m.

    Parameters
    ----------
    recording : Recording
        Must have the ``theta`` column (pitch attitude, rad); K_theta
        (``motion_gain``) and theta_ddot_m (rad/s^2) are read from it too.
    h_head : float
        Height of the pilot's head above the pitch rotation point, m
        (positive above, negative below).

    Returns
    -------
    ndarray
        f_x at each sample of the recording, m/s^2 (g = :data:`G`).

    Raises
    ------
    ValueError
        If the recording has no ``theta`` column.
    """
    if "theta" not in recording:
        raise ValueError("the specific force needs the recording's 'theta' column")
    return G * recording.motion_gain * recording["theta"] - float(h_head) * recording.theta_ddot_m


@dataclass(frozen=True)
class Extension:
    """One entry of the catalogue.

    An entry of one's own is added with :func:`register_extension`, which
    checks it.

    Attributes
    ----------
    name : str
        Catalogue name, e.g. ``"motion-washout"``.
    physics : str
        What it models, in a sentence or two.
    signature : str
        What it should leave in the located evidence, in words.
    signature_keys : tuple of str
        Keys of the located evidence that this physics should light up.
    build : callable
        ``build(model) -> PilotModel``: the extended model.
    new_parameters : tuple of str
        Free parameters the extension adds.
    starts : tuple of dict
        Starting values of the new parameters for the fit (multi-start).
    likelihood : {"gls", "censored"}
        Which likelihood fits and tests it (see :mod:`bayespilot.diagnose.decide`).
    needs : tuple of str
        Recording columns it needs beyond those every recording has (e.g.
        ``("theta",)``): every one its model's channels read (a channel on
        ``theta_m`` or ``theta`` reads ``theta``; :func:`register_extension`
        checks).  :func:`~bayespilot.diagnose.diagnose` skips the entry on a
        recording without them.
    refine_threshold : bool
        Whether delta_abs is re-estimated with it (the threshold shape entry).
    boundary_null : bool
        Whether the base model is the extension at the edge of its parameter
        range (a washout at omega_w -> 0, a platform at omega_ms -> infinity,
        a dead zone of corner width 0) rather than inside it.  With one new
        parameter the likelihood-ratio statistic is then a 50:50 mixture of
        chi2(0) and chi2(1) under the null (Self & Liang 1987), which halves
        the chi2(1) p-value.
    """

    name: str
    physics: str
    signature: str
    signature_keys: tuple[str, ...]
    build: Callable[[PilotModel], PilotModel]
    new_parameters: tuple[str, ...]
    starts: tuple[Mapping[str, float], ...] = field(default_factory=tuple)
    likelihood: str = "gls"
    needs: tuple[str, ...] = ()
    refine_threshold: bool = False
    boundary_null: bool = False

    @property
    def df(self) -> int:
        """Degrees of freedom the extension adds (its free new parameters)."""
        return len(self.new_parameters)


def _motion_system(model: PilotModel) -> PilotModel:
    # The damping is fixed at 0.7 (as the washout's): what one run identifies is the
    # platform's lag, and a free damping would be unidentified where the base model is
    # (omega_ms -> infinity), which leaves the test without a known null distribution.
    m = model.add_stage("vestibular", MotionSystem("omega_ms", "zeta_ms"), [
        Parameter("omega_ms", 2.0, 100.0, 30.0, "rad/s", "motion-platform bandwidth"),
        Parameter("zeta_ms", 0.4, 2.0, 0.7, "-", "motion-platform damping (fixed)")])
    return m.fix(zeta_ms=0.7)


def _washout(model: PilotModel) -> PilotModel:
    m = model.add_stage("vestibular", SecondOrderWashout("omega_w", "zeta_w"), [
        Parameter("omega_w", 0.02, 5.0, 0.5, "rad/s", "washout break frequency"),
        Parameter("zeta_w", 0.2, 2.0, 0.7, "-", "washout damping (fixed)")])
    return m.fix(zeta_w=0.7)


def _otolith(model: PilotModel) -> PilotModel:
    params = [Parameter("K_ot", -5.0, 5.0, 0.0, "rad/(m/s^2)", "otolith channel gain"),
              Parameter("h_head", -3.0, 3.0, 0.0, "m",
                        "head height above the pitch rotation point (positive above)")]
    tilt = Channel("otolith_tilt", "theta_m", delay="tau_m", gain=("K_ot",),
                   stages=(otolith_filter(),), sign=-1.0, gain_const=G)
    # -K_ot * (-h theta_ddot_m) = +K_ot h theta_ddot_m
    trans = Channel("otolith_trans", "theta_ddot_m", delay="tau_m", gain=("K_ot", "h_head"),
                    stages=(otolith_filter(),), sign=1.0)
    return model.add_channel(tilt, params).add_channel(trans, params)


def _threshold_shape(model: PilotModel) -> PilotModel:
    return model.with_nonlinearity("vestibular", SoftDeadZone("delta_abs", "w_soft"), [
        Parameter("w_soft", 1e-5, 0.05, 0.002, "IPUT", "corner width of the soft dead zone")])


def _time_varying(model: PilotModel) -> PilotModel:
    m = model.with_modulation("visual", LinearDrift("drift_v"), [
        Parameter("drift_v", -1.5, 1.5, 0.0, "-", "relative change of K_v over the run")])
    return m.with_modulation("vestibular", LinearDrift("drift_m"), [
        Parameter("drift_m", -1.5, 1.5, 0.0, "-", "relative change of K_m over the run")])


def _saturation(model: PilotModel) -> PilotModel:
    return model.with_output(Saturation("u_max"), [
        Parameter("u_max", 1e-6, 10.0, 1.0, "rad", "control travel limit (from the flat tops)")])


CATALOGUE: tuple[Extension, ...] = (
    Extension(
        "motion-system-dynamics",
        "The motion platform's bandwidth and lag: the pilot feels a low-passed, delayed "
        "version of the commanded motion that the recording logs.",
        "The motion channel's describing function loses magnitude and phase at the higher "
        "forcing frequencies; residual power at the disturbance frequencies.",
        ("frequency.motion_high", "frequency.power_disturbance"),
        _motion_system, ("omega_ms",),
        ({"omega_ms": 40.0}, {"omega_ms": 15.0}, {"omega_ms": 7.0}),
        boundary_null=True),
    Extension(
        "motion-washout",
        "High-pass filtering of the presented motion by the motion-cueing washout: "
        "low-frequency motion is not presented.",
        "The motion channel's describing function loses magnitude and gains phase lead at "
        "the lowest forcing frequencies.",
        ("frequency.motion_low", "frequency.power_disturbance"),
        _washout, ("omega_w",),
        ({"omega_w": 0.2}, {"omega_w": 0.8}, {"omega_w": 2.0}),
        boundary_null=True),
    Extension(
        "otolith-channel",
        "A parallel response to the specific force at the pilot's head, "
        "f_x = g theta_m - h theta_ddot_m, through the otolith dynamics.",
        "The motion channel's describing function departs from the canal model at low "
        "frequencies (tilt, g theta_m) and possibly high (h theta_ddot_m).",
        ("frequency.motion_low", "frequency.motion_high", "frequency.power_disturbance"),
        _otolith, ("K_ot", "h_head"),
        ({"K_ot": 0.02, "h_head": 1.0}, {"K_ot": -0.02, "h_head": 1.0},
         {"K_ot": 0.02, "h_head": -1.0}, {"K_ot": -0.02, "h_head": -1.0}),
        needs=("theta",)),
    Extension(
        "threshold-shape",
        "A threshold that is not a crisp dead zone: motion just above the threshold is "
        "partly perceived (a soft, rounded dead zone).",
        "The residual depends on the canal output i near +-delta_abs.",
        ("amplitude.canal",),
        _threshold_shape, ("w_soft",),
        ({"w_soft": 0.001}, {"w_soft": 0.004}, {"w_soft": 0.012}),
        refine_threshold=True, boundary_null=True),
    Extension(
        "time-varying-gains",
        "Pilot gains that drift during the run (fatigue, learning): K_v and K_m change "
        "linearly from start to end.",
        "Local fits over segments of the run show trending gains; the residual is "
        "non-stationary.",
        ("time.gain_drift_visual", "time.gain_drift_motion", "time.variance_drift",
         "time.nonstationarity"),
        _time_varying, ("drift_v", "drift_m"),
        ({"drift_v": 0.0, "drift_m": 0.0},)),
    Extension(
        "control-saturation",
        "The control device's travel limit clips the pilot's command.",
        "Flat tops in u (runs of samples at the same extreme value); residual conditioned on "
        "|u| departs at the largest |u|.",
        ("amplitude.flat_tops", "amplitude.control"),
        _saturation, (),
        likelihood="censored"),
)

#: The catalogue names, in order.
NAMES: tuple[str, ...] = tuple(e.name for e in CATALOGUE)


#: The likelihoods an entry is fitted and tested by: ``"gls"``, the decision likelihood
#: (:mod:`bayespilot.diagnose.decide`), and ``"censored"``, the flat-top test and censored
#: (Tobit) fit wired to the built-in ``control-saturation`` entry (its limits are read from
#: the flat tops, not fitted), so that an entry of your own is always ``"gls"``.
LIKELIHOODS: tuple[str, ...] = ("gls", "censored")

#: The entries :func:`register_extension` added, by name, in the order they were first
#: registered (this process only; :func:`~bayespilot.diagnose.batch.diagnose_batch` sends
#: them to its workers).
_REGISTERED: dict[str, Extension] = {}


#: The recording column a channel's source reads beyond those every recording has
#: (:data:`bayespilot.recording.REQUIRED_SIGNALS`): an entry whose model has such a channel
#: must name the column in ``needs``.
_SOURCE_COLUMNS = {"theta_m": "theta", "theta": "theta"}


def _columns_read(model: PilotModel) -> dict[str, list[str]]:
    """The optional recording columns ``model``'s channels read: column -> the channels
    ("name (source)") that read it."""
    out: dict[str, list[str]] = {}
    for ch in model.channels:
        col = _SOURCE_COLUMNS.get(ch.source)
        if col is not None:
            out.setdefault(col, []).append(f"{ch.name} ({ch.source})")
    return out


def _unlisted_needs(ext: Extension, model: PilotModel) -> str | None:
    """Why ``ext``'s ``needs`` leaves out a column ``model`` (its build of the base model)
    reads, or None: without it :func:`~bayespilot.diagnose.diagnose` would not skip the entry
    on a recording lacking the column but fail at its fit, after the base fit and the
    bootstrap."""
    read = _columns_read(model)
    left = [c for c in read if c not in tuple(ext.needs)]
    if not left:
        return None
    which = "; ".join(f"the {c!r} column, read by the channel(s) {', '.join(read[c])}"
                      for c in left)
    fixed = tuple(ext.needs) + tuple(left)
    return (f"extension {ext.name!r}: its model reads {which}, and needs={tuple(ext.needs)!r} "
            f"leaves it out; give needs={fixed!r}, so that diagnose skips the entry on a "
            f"recording without {'it' if len(left) == 1 else 'them'} rather than failing at "
            f"its fit after the base fit and the bootstrap")


def _names_tuple(value: Any, what: str, name: str) -> tuple[str, ...]:
    """``value`` (a tuple or list of distinct str) as a tuple, or a ValueError naming ``what``."""
    if isinstance(value, str):
        raise ValueError(f"extension {name!r}: {what} must be a tuple of str, got the string "
                         f"{value!r} (write ({value!r},))")
    if not isinstance(value, (tuple, list)) or not all(isinstance(v, str) for v in value):
        raise ValueError(f"extension {name!r}: {what} must be a tuple of str, got {value!r}")
    if len(set(value)) != len(value):
        raise ValueError(f"extension {name!r}: {what} names one twice: {list(value)}")
    return tuple(value)


def _validated(ext: Extension) -> Extension:
    """``ext`` checked as an entry of one's own (:func:`register_extension`), its sequences
    as tuples; a ValueError saying what is wrong otherwise."""
    import numbers

    from ..model import paper_model
    from .locate import EVIDENCE

    if not isinstance(ext, Extension):
        raise TypeError(f"an entry of the catalogue is an Extension, got {type(ext).__name__}")
    name = ext.name
    if not isinstance(name, str) or not name.strip() or name != name.strip():
        raise ValueError(f"an extension's name must be a non-empty str without surrounding "
                         f"spaces, got {name!r}")
    if name in NAMES:
        raise ValueError(f"{name!r} is the name of a built-in catalogue entry, which cannot be "
                         f"replaced; give yours another name")
    if name.lower() == "none":
        raise ValueError("'none' is the decision's word for no extension; give the entry "
                         "another name")
    for what in ("physics", "signature"):
        if not isinstance(getattr(ext, what), str):
            raise ValueError(f"extension {name!r}: {what} must be a str (a sentence or two), "
                             f"got {getattr(ext, what)!r}")
    keys = _names_tuple(ext.signature_keys, "signature_keys", name)
    unknown = [k for k in keys if k not in EVIDENCE]
    if unknown:
        raise ValueError(f"extension {name!r}: signature_keys {unknown} are not keys of the "
                         f"located evidence; these are: {', '.join(EVIDENCE)}")
    new = _names_tuple(ext.new_parameters, "new_parameters", name)
    needs = _names_tuple(ext.needs, "needs", name)
    if ext.likelihood not in LIKELIHOODS:
        raise ValueError(f"extension {name!r}: likelihood must be one of "
                         f"{', '.join(map(repr, LIKELIHOODS))}, got {ext.likelihood!r}")
    if ext.likelihood != "gls":
        raise ValueError(f"extension {name!r}: likelihood 'censored' is the flat-top test of "
                         f"the built-in control-saturation entry, wired to that entry; an "
                         f"entry of your own is fitted and tested by 'gls'")
    for what in ("refine_threshold", "boundary_null"):
        if not isinstance(getattr(ext, what), bool):
            raise ValueError(f"extension {name!r}: {what} must be True or False, got "
                             f"{getattr(ext, what)!r}")
    if not new:
        raise ValueError(f"extension {name!r}: new_parameters is empty; an entry adds at least "
                         f"one free parameter (its test has as many degrees of freedom)")
    if not callable(ext.build):
        raise ValueError(f"extension {name!r}: build must be a function of the base model "
                         f"returning the extended PilotModel, got {ext.build!r}")
    base = paper_model()
    try:
        model = ext.build(base)
    except Exception as exc:  # noqa: BLE001 - said with the entry's name
        raise ValueError(f"extension {name!r}: build(paper_model()) raised "
                         f"{type(exc).__name__}: {exc}") from exc
    if not isinstance(model, PilotModel):
        raise ValueError(f"extension {name!r}: build(paper_model()) returned a "
                         f"{type(model).__name__}, not a PilotModel")
    lost = [n for n in base.parameter_names if n not in model.parameter_names]
    if lost:
        raise ValueError(f"extension {name!r}: build(paper_model()) leaves the base model's "
                         f"{', '.join(lost)} fixed or out; an extension must keep the base "
                         f"model's free parameters free (its test counts only those it adds)")
    unlisted = _unlisted_needs(dataclasses.replace(ext, needs=needs), model)
    if unlisted is not None:
        raise ValueError(unlisted)
    added = [n for n in model.parameter_names if n not in base.parameter_names]
    if set(added) != set(new):
        raise ValueError(f"extension {name!r}: build(paper_model()) adds the free parameters "
                         f"{added}, and new_parameters names {list(new)}; they must be the same "
                         f"(the test has len(new_parameters) degrees of freedom; fix a parameter "
                         f"that is not estimated with model.fix(...))")
    starts = ext.starts
    if isinstance(starts, Mapping):
        starts = (starts,)
    if not isinstance(starts, (tuple, list)) or not all(isinstance(s, Mapping) for s in starts):
        raise ValueError(f"extension {name!r}: starts must be a tuple of dicts (new parameter -> "
                         f"starting value), got {ext.starts!r}")
    for s in starts:
        other = [k for k in s if k not in new]
        if other:
            raise ValueError(f"extension {name!r}: a start gives {other}, which are not among "
                             f"its new_parameters {list(new)} (the other parameters start at "
                             f"the base fit)")
        for k, v in s.items():
            p = model.parameter(k)
            if (isinstance(v, bool) or not isinstance(v, numbers.Real)
                    or not p.lower <= float(v) <= p.upper):
                raise ValueError(f"extension {name!r}: the start {k} = {v!r} is not a number "
                                 f"within {k}'s bounds [{p.lower:g}, {p.upper:g}]")
    return dataclasses.replace(ext, signature_keys=keys, new_parameters=new, needs=needs,
                               starts=tuple({k: float(v) for k, v in s.items()} for s in starts))


def register_extension(ext: Extension) -> Extension:
    """Add an entry of your own to the catalogue, for this process.

    :func:`get_extension` finds it after the built-in entries, so that
    :func:`~bayespilot.diagnose.diagnose` and
    :func:`~bayespilot.diagnose.diagnose_pooled` can test it (by name or as
    the Extension itself in ``candidates``; ``candidates=None`` tests it
    too, after the built-in entries: :func:`candidate_names`), and what
    they return can be reported, sampled and weighed.
    :func:`~bayespilot.diagnose.batch.diagnose_batch` sends the registered
    entries it tests to its workers.  Registering an entry of the same name
    again replaces it.

    The entry is checked before it is added: a name that is not a built-in
    entry's (nor ``"none"``); ``build`` a function that, applied to
    :func:`~bayespilot.model.paper_model`, returns a PilotModel which keeps
    the base model's free parameters free and adds exactly the free
    parameters ``new_parameters`` names (at least one: the test's degrees of
    freedom), and whose channels read only the recording columns every
    recording has or that ``needs`` names (a channel on ``theta_m`` or
    ``theta`` needs ``needs=("theta",)``); ``likelihood`` ``"gls"`` (``"censored"`` is wired to the
    built-in ``control-saturation``); ``signature_keys`` keys of the located
    evidence (:data:`bayespilot.diagnose.locate.EVIDENCE`); ``starts`` giving
    values within the bounds of new parameters only.  What is not checked:
    that the extended model reduces to the base model at some value of its
    new parameters (a nested model), which the likelihood-ratio test
    assumes; state where in ``boundary_null``.

    Parameters
    ----------
    ext : Extension
        The entry.  ``signature_keys``, ``new_parameters`` and ``needs`` may
        be lists; they are stored as tuples.

    Returns
    -------
    Extension
        The entry as registered (its sequences as tuples, ``starts`` as a
        tuple of dicts).

    Raises
    ------
    TypeError
        ``ext`` is not an Extension.
    ValueError
        The entry fails a check above; the message says which.

    Examples
    --------
    >>> from bayespilot.model import FirstOrderLag, Parameter
    >>> lag = Extension(
    ...     "visual-lag", "A first-order lag on the visual channel.",
    ...     "The visual describing function loses phase at high frequency.",
    ...     ("frequency.visual",),
    ...     lambda m: m.add_stage("visual", FirstOrderLag("T_vis"),
    ...                           [Parameter("T_vis", 1e-3, 0.5, 0.05, "s", "visual lag")]),
    ...     ("T_vis",), ({"T_vis": 0.05},), boundary_null=True)
    >>> register_extension(lag).name in candidate_names()
    True
    >>> unregister_extension("visual-lag").name
    'visual-lag'
    """
    ext = _validated(ext)
    _REGISTERED[ext.name] = ext
    return ext


def unregister_extension(name: str) -> Extension:
    """Remove an entry :func:`register_extension` added.

    Results made with it keep their numbers; a method of theirs that needs
    the entry again (a report's figures, a posterior, a Bayes factor) then
    raises until it is registered again.

    Parameters
    ----------
    name : str
        The entry's name.

    Returns
    -------
    Extension
        The entry removed.

    Raises
    ------
    ValueError
        ``name`` is a built-in entry's (they cannot be removed) or no entry
        of that name is registered.
    """
    if name in NAMES:
        raise ValueError(f"{name!r} is a built-in catalogue entry, which cannot be removed")
    try:
        return _REGISTERED.pop(name)
    except (KeyError, TypeError):
        raise ValueError(f"no registered extension {name!r}; registered: "
                         f"{', '.join(_REGISTERED) or 'none'}") from None


def registered_extensions() -> tuple[Extension, ...]:
    """The entries :func:`register_extension` added in this process, in the order first added.

    Returns
    -------
    tuple of Extension
        Empty when there are none.
    """
    return tuple(_REGISTERED.values())


def candidate_names() -> tuple[str, ...]:
    """The names :func:`~bayespilot.diagnose.diagnose` tests when ``candidates=None``.

    Returns
    -------
    tuple of str
        The built-in :data:`NAMES`, then the registered entries' names in
        the order they were first registered: exactly :data:`NAMES` when
        none is registered.
    """
    return NAMES + tuple(_REGISTERED)


def get_extension(name: str) -> Extension:
    """The catalogue entry called ``name``: a built-in one, else a registered one.

    Parameters
    ----------
    name : str
        A catalogue name: one of :data:`NAMES` (exactly, e.g.
        ``"motion-washout"``) or of an entry :func:`register_extension` added.

    Returns
    -------
    Extension
        The entry of :data:`CATALOGUE`, or the registered one.

    Raises
    ------
    ValueError
        If there is no such entry.
    """
    for e in CATALOGUE:
        if e.name == name:
            return e
    try:
        return _REGISTERED[name]
    except (KeyError, TypeError):  # (TypeError: an unhashable name)
        pass
    raise ValueError(f"unknown extension {name!r}; the catalogue has "
                     f"{', '.join(candidate_names())} (an entry of your own: "
                     f"register_extension)")


def _candidate_name(candidate: str | Extension) -> str:
    """The name of one of ``diagnose``'s ``candidates``: a catalogue name as it is, an
    Extension registered first (a built-in entry itself: its name).

    Parameters
    ----------
    candidate : str or Extension
        A catalogue name or an entry.

    Returns
    -------
    str
        The entry's name, which :func:`get_extension` finds.

    Raises
    ------
    ValueError
        An unknown name, or an Extension :func:`register_extension` refuses
        (a built-in entry's name on another entry among them).
    """
    if isinstance(candidate, Extension):
        if candidate.name in NAMES and get_extension(candidate.name) == candidate:
            return candidate.name
        return register_extension(candidate).name
    return get_extension(candidate).name

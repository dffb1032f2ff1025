"""The result of a maximum-likelihood fit: parameters by name, fit quality, how it was found."""

from __future__ import annotations

import copy
import math
import re
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Mapping

from .. import presets
from .._files import WrongKind, dumps, read_result, require_keys, write_text_atomic
from .._html import SummaryHTML
from ..recording import _frozen, _ReadOnlyDict, _ReadOnlyList, _thawed

__all__ = ["FitResult", "EstimateOnBoundWarning", "NotAtMaximumWarning", "ON_BOUND_RTOL",
           "CHECK_GAP"]

#: An estimate counts as on a bound (:attr:`FitResult.at_bounds`) within this fraction of the
#: width of its search box (1e-5 of K_v's [0, 10]); the bounded fits stop a hair inside.
ON_BOUND_RTOL = 1e-6

#: The paper's model (with and without threshold, oversampled or not): a fit saved before the
#: bounds were recorded had Table 1's.
_PAPER_MODEL = re.compile(r"Pool et al\. \(2012\)(, no threshold)?(, \d+x vestibular)?")


class EstimateOnBoundWarning(RuntimeWarning):
    """A fitted parameter ended on a bound of its search box (:attr:`FitResult.at_bounds`): the
    bound, not the data, stopped it, and the other estimates moved to make up for it."""


class NotAtMaximumWarning(RuntimeWarning):
    """A paper-method fit stopped short of a maximum of ln L that Gauss-Newton with delta_abs
    free reaches from its result (``steps["check"]``, :func:`~bayespilot.fit.three_step.fit_paper`):
    the paper's single pass of Steps II and III leaves delta_abs where the other parameters
    were refined for Step I's value."""


#: A paper-method fit further than this below the maximum its check reaches (in -ln L) is said
#: to stop short (:class:`NotAtMaximumWarning`): 1.92 is chi-square(1) at 95 % over 2, how far
#: the edge of a 95 % profile-likelihood interval lies below its maximum.
CHECK_GAP = 1.92


class _FitDict(_ReadOnlyDict):
    """A dict of a :class:`FitResult` (its ``params``, ``settings``, ...) that refuses to be
    changed in place, as a recording's metadata (:class:`~bayespilot.recording._ReadOnlyDict`),
    with a fit's message.  A copy (``dict(...)``, ``copy.deepcopy``) is a plain dict."""

    _REFUSAL = ("a FitResult's params, settings, steps, bounds and units cannot be changed in "
                "place: copy them (dict(fit.params), fit.to_dict()) and edit the copy, or make "
                "a new result (dataclasses.replace(fit, params=...))")


class _FitList(_ReadOnlyList):
    """A list inside a :class:`FitResult` (a GA history, a scan's grid), read-only as
    :class:`_FitDict`."""

    _REFUSAL = _FitDict._REFUSAL


#: The fields of a FitResult held read-only (:meth:`FitResult.__post_init__`).
_READ_ONLY = ("params", "settings", "steps", "bounds", "units")


def _bound_side(value: float, lo: float, hi: float) -> str | None:
    """``"lower"`` or ``"upper"`` when ``value`` is within :data:`ON_BOUND_RTOL` of the box
    ``[lo, hi]``'s width of that bound, or beyond it; else None."""
    tol = ON_BOUND_RTOL * (hi - lo)
    if value <= lo + tol:
        return "lower"
    if value >= hi - tol:
        return "upper"
    return None


@dataclass(frozen=True, eq=False)
class FitResult(SummaryHTML):
    """A fitted pilot model.

    ``params``, ``settings``, ``steps``, ``bounds`` and ``units`` are read-only copies of
    what the result was made with (at every depth): ``fit.params["K_v"] = 1`` is a
    TypeError, since a changed estimate would no longer be the fit its -ln L, VAF and file
    describe.  Edit a copy (``dict(fit.params)``, :meth:`to_dict`), or make a new result
    (``dataclasses.replace(fit, params=...)``).

    Attributes
    ----------
    params : dict
        Every parameter of the model by name (fixed ones included, e.g.
        ``delta_abs = 0`` without threshold).
    neg_log_lik : float
        Final -ln L (Eq. 4, output-error variance profiled out).  With a noise
        model (:func:`~bayespilot.fit.fast.fit_fast` with ``noise="ar"`` or an
        :class:`~bayespilot.noise.ARNoise`; ``settings["noise"]``) it is Eq. 4
        of the residual whitened by that model, not comparable with the -ln L
        of a fit without one.
    vaf : float
        Variance accounted for, percent.
    method : {"paper", "fast"}
    seed : int or None
        The seed used (drawn from fresh entropy when ``seed=None`` was
        given); None in results saved before it was recorded.
    threshold : bool
        Whether the model has a threshold (delta_abs, or another
        nonlinearity's), estimated or held fixed at a nonzero value
        (:attr:`~bayespilot.model.PilotModel.has_threshold`); False when it is
        fixed at 0.
    settings : dict
        Every setting of the procedure.
    steps : dict
        Step I (the GA repetitions and their histories), Step II (each
        refinement) and Step III (the scan), or the fast method's stages.
    elapsed : float
        Wall time, s.
    source : str or None
        The recording it was fitted to.
    bounds : dict
        The search box: (lower, upper) of every free parameter by name, in
        its unit (Table 1 for the paper's); empty in a result saved before it
        was recorded (then Table 1 for the paper's model, see :attr:`at_bounds`).
    units : dict
        Every parameter's unit by name, as its model declares it; empty in a
        result saved before it was recorded (then the paper's units).
    """

    params: dict[str, float]
    neg_log_lik: float
    vaf: float
    method: str
    seed: int | None
    threshold: bool
    settings: dict[str, Any] = field(default_factory=dict)
    steps: dict[str, Any] = field(default_factory=dict)
    elapsed: float = math.nan
    source: str | None = None
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # read-only copies: an estimate edited in place was saved by to_json, and from_json
        # then reported it beyond its bound
        for name in _READ_ONLY:
            object.__setattr__(self, name, _frozen(getattr(self, name), _FitDict, _FitList))

    def __reduce__(self):
        # Built again through __init__ when unpickled or deep-copied, so that the copy is
        # read-only too (a deep copy of the dicts alone would be plain, editable ones).
        return (type(self), tuple(_thawed(getattr(self, f.name)) for f in fields(self)))

    @classmethod
    def _declared(cls, model) -> dict[str, Any]:
        """``bounds`` and ``units`` of a fit of ``model`` (keywords of the constructor)."""
        free = set(model.parameter_names)
        return {"bounds": {p.name: (float(p.lower), float(p.upper)) for p in model.parameters
                           if p.name in free},
                "units": {p.name: p.unit for p in model.parameters}}

    def _box(self) -> dict[str, tuple[float, float]]:
        """The free parameters' bounds: as recorded, or for a result saved before they were,
        Table 1's when it is a fit of the paper's model (nothing known otherwise)."""
        if self.bounds:
            return self.bounds
        if _PAPER_MODEL.fullmatch(str(self.settings.get("model", ""))):
            fixed = () if self.threshold else ("delta_abs",)
            return {k: tuple(presets.TABLE1_BOUNDS[k]) for k in self.params
                    if k in presets.TABLE1_BOUNDS and k not in fixed}
        return {}

    @property
    def fixed(self) -> tuple[str, ...]:
        """The parameters held fixed, not estimated (``delta_abs`` without threshold, and any
        a model fixed), in the order of :attr:`params`."""
        box = self._box()
        if box:
            return tuple(k for k in self.params if k not in box)
        return ("delta_abs",) if (not self.threshold and "delta_abs" in self.params) else ()

    @property
    def at_bounds(self) -> dict[str, str]:
        """The free parameters whose estimate is on a bound of the search box, by name:
        ``"lower"`` or ``"upper"``.

        On means within :data:`ON_BOUND_RTOL` of the box's width, or beyond (the paper's
        Step II is unconstrained).  Such an estimate is where the bound stopped the fit, not
        an optimum of the likelihood, except ``delta_abs = 0``, the answer "no threshold".
        An estimate on the upper bound of a gain, or of a delay, often means that the bounds
        do not suit the recording's units (e.g. u in degrees: K_v ends on 10).  Empty if the
        bounds are not known (a result of another model saved before they were recorded).
        """
        out = {}
        for k, (lo, hi) in self._box().items():
            side = _bound_side(self.params.get(k, math.nan), lo, hi)
            if side is not None:
                out[k] = side
        return out

    def _edge_text(self, name: str, side: str) -> tuple[str, float]:
        """("on" or "beyond", the bound) of a parameter in :attr:`at_bounds`."""
        lo, hi = self._box()[name]
        bound = lo if side == "lower" else hi
        v = self.params[name]
        beyond = ((v < lo if side == "lower" else v > hi)
                  and abs(v - bound) > ON_BOUND_RTOL * (hi - lo))
        return ("beyond" if beyond else "on"), bound

    def _unit(self, name: str) -> str:
        if name in self.units:
            return self.units[name]
        return presets.PARAMETER_UNITS.get(name, "")

    def to_dict(self, *, full: bool = True) -> dict[str, Any]:
        """JSON-ready dict: ``params``, ``neg_log_lik``, ``vaf``, ``method``, ``seed``, ... .

        Parameters
        ----------
        full : bool, default True
            Include ``steps``, the per-step details (the GA histories, each
            refinement, the scan); False leaves them out (a short summary).

        Returns
        -------
        dict
            ``params``, ``neg_log_lik``, ``vaf``, ``method``, ``seed``,
            ``threshold``, ``elapsed_seconds`` (s), ``source``, ``settings``,
            ``bounds`` (name -> [lower, upper] of the free parameters), ``units``
            and, with ``full``, ``steps``.
        """
        # copies: a caller editing the dict (or the JSON it becomes) leaves the fit alone
        d = {"params": dict(self.params), "neg_log_lik": self.neg_log_lik, "vaf": self.vaf,
             "method": self.method, "seed": self.seed, "threshold": self.threshold,
             "elapsed_seconds": self.elapsed, "source": self.source,
             "settings": copy.deepcopy(self.settings),
             "bounds": {k: list(b) for k, b in self.bounds.items()}, "units": dict(self.units)}
        if full:
            d["steps"] = copy.deepcopy(self.steps)
        return d

    def __repr__(self) -> str:
        # one line: the dataclass's repr held every GA history (464,000 characters in a notebook)
        n = len(self.params) - len(self.fixed)
        where = f", {self.source}" if self.source else ""
        return (f"<FitResult {self.method}: {n} parameters "
                f"({'with' if self.threshold else 'without'} threshold), "
                f"-ln L = {self.neg_log_lik:.6g}, VAF {self.vaf:.1f} %{where}>")

    def to_json(self, path: str | Path, *, full: bool = True) -> Path:
        """Write :meth:`to_dict` to ``path`` (parent folders created).

        Non-finite numbers are written as null (read back as NaN by
        :meth:`from_json`); an existing file is replaced only once the new one
        is written.

        Parameters
        ----------
        path : str or Path
            The JSON file to write.
        full : bool, default True
            Include the per-step details (see :meth:`to_dict`).

        Returns
        -------
        Path
            ``path``.
        """
        return write_text_atomic(path, dumps(self.to_dict(full=full)))

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "FitResult":
        """The fit a :meth:`to_dict` holds (a null number is NaN).

        Parameters
        ----------
        d : dict
            A :meth:`to_dict` (as read from JSON); ``steps`` may be absent
            (``full=False``), as may the fields after ``method``.

        Returns
        -------
        FitResult

        Raises
        ------
        ValueError
            ``d`` lacks what a fit's dict has (``params``, ``neg_log_lik``,
            ``vaf``, ``method``): another kind of file; or a number in it
            (an estimate, a bound, -ln L, ...) is not one (the message names
            its key).
        """
        require_keys(d, ("params", "neg_log_lik", "vaf", "method"), "a fit result")

        def num(v, key):  # (a non-finite number was written as null, _files.dumps)
            try:
                return math.nan if v is None else float(v)
            except (TypeError, ValueError):
                raise WrongKind(f"not a fit result: {key} is {v!r}, not a number "
                                "(or null)") from None

        def mapping(key):
            v = d.get(key)
            if v is None and key != "params":
                return {}
            if not isinstance(v, Mapping):
                what = "null" if v is None else f"a {type(v).__name__}"
                raise WrongKind(f"not a fit result: {key} is {what}, not an object of "
                                "name: value")
            return v

        def pair(k, b):
            if not isinstance(b, (list, tuple)) or len(b) != 2:
                raise WrongKind(f"not a fit result: bounds[{k!r}] is {b!r}, not [lower, upper]")
            return num(b[0], f"bounds[{k!r}][0]"), num(b[1], f"bounds[{k!r}][1]")

        params = {k: num(v, f"params[{k!r}]") for k, v in mapping("params").items()}
        return cls(params, num(d["neg_log_lik"], "neg_log_lik"), num(d["vaf"], "vaf"),
                   d["method"], d.get("seed"), bool(d.get("threshold", True)),
                   d.get("settings", {}), d.get("steps", {}),
                   num(d.get("elapsed_seconds"), "elapsed_seconds"), d.get("source"),
                   {k: pair(k, b) for k, b in mapping("bounds").items()},
                   {k: str(u) for k, u in mapping("units").items()})

    @classmethod
    def from_json(cls, path: str | Path) -> "FitResult":
        """The fit a :meth:`to_json` file holds.

        Parameters
        ----------
        path : str or Path
            The JSON file.

        Returns
        -------
        FitResult

        Raises
        ------
        FileNotFoundError
            No file at ``path``.
        ValueError
            The file is not JSON, or not a fit's (the message names it).
        """
        return read_result(path, cls.from_dict, "a FitResult")

    def summary(self) -> str:
        """A readable table of the estimates and the fit.

        Each parameter with the unit its model declares (the paper's for a result saved
        before units were recorded); ``(fixed)`` beside those not estimated, ``(not
        identified)`` beside those ``settings["unidentified"]`` lists (a channel silent
        throughout the record, e.g. the motion channel's on a run without motion: where the
        fit stopped, not estimates; the fitters record them), and ``*`` beside an
        estimate on a bound of the search box (:attr:`at_bounds`; not for those not
        identified), named under the table.  The -ln L of a fit with a noise model
        (``settings["noise"]``) is labelled ``-ln L (AR-whitened residual)``: it is not
        comparable with Eq. 4's of a fit without one.
        """
        unknown = [k for k in self.settings.get("unidentified") or () if k in self.params]
        fixed = set(self.fixed)
        edge = {k: side for k, side in self.at_bounds.items() if k not in unknown}
        lines = [f"bayespilot fit ({self.method} method, "
                 f"{'with' if self.threshold else 'without'} threshold, seed {self.seed})"]
        if self.source:
            lines.append(f"recording: {self.source}")
        model = self.settings.get("model")
        if isinstance(model, str) and " + " in model:  # (an extended model: say which)
            lines.append(f"model: {model}")
        lines.append(f"{'parameter':<10} {'estimate':>12}   unit")
        for k, v in self.params.items():
            mark = "*" if k in edge else " "
            note = "  (fixed)" if k in fixed else "  (not identified)" if k in unknown else ""
            lines.append(f"{k:<10} {v:>12.6g}{mark}  {self._unit(k)}{note}".rstrip())
        # (a fit with a noise model: Eq. 4 of the whitened residual, not comparable with Eq. 4's)
        label = "-ln L (AR-whitened residual)" if self.settings.get("noise") else "-ln L"
        lines.append(f"{label} = {self.neg_log_lik:.3f}   VAF = {self.vaf:.2f} %   "
                     f"time = {self.elapsed:.1f} s")
        discard = self.settings.get("discard") or 0.0
        if discard:  # (the -ln L is of the samples after it: say so)
            why = self.settings.get("discard_reason")
            lines.append(f"the first {discard:g} s left out of -ln L and VAF"
                         + (f" ({why.split(': ', 1)[-1]})" if why else ""))
        if unknown:
            lines.append(f"not identified: {', '.join(unknown)}: their channel's input is zero "
                         f"throughout the record (e.g. a run without motion), so the record says "
                         f"nothing about them; their values are where the fit stopped, not "
                         f"estimates")
        check = self.steps.get("check") if isinstance(self.steps, dict) else None
        if check and check.get("gap", 0.0) > CHECK_GAP:
            lines.append(f"not at a maximum: Gauss-Newton with delta_abs free from this fit "
                         f"reaches -ln L = {check['neg_log_lik']:.3f} (delta_abs "
                         f"{check['params']['delta_abs']:.6g}); the paper's single pass stopped "
                         f"{check['gap']:.1f} short (Steps II and III iterated, or the fast method, "
                         f"reach it: iterate=True, bayespilot fit --iterate)")
        if edge:
            said = []
            for k, side in edge.items():
                where, bound = self._edge_text(k, side)
                said.append(f"{k} ({'' if where == 'on' else 'beyond '}{side} {bound:g}"
                            + (": no threshold" if k == "delta_abs" and side == "lower" else "")
                            + ")")
            lines.append(f"* on a bound of the search box: {', '.join(said)}")
            if set(edge) - {"delta_abs"}:
                lines.append("  such an estimate is the bound's, not the data's: the bounds "
                             "(Table 1 for the paper's parameters)\n  may not suit the "
                             "recording's units (SI, angles in radians) or the model")
        return "\n".join(lines)

    __str__ = summary

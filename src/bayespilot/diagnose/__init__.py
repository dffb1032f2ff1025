"""Diagnose model mismatch: locate it, name the missing physics, model it, show the fit improve.

:func:`diagnose` runs the whole procedure on one recording and returns a
:class:`DiagnosisResult`:

1. **Fit** the paper's model (the fast estimator, Eq. 4), then re-fit it by
   the decision likelihood: generalised least squares on the residual
   low-passed, decimated and whitened by an AR model of the fitted residual
   (:class:`~bayespilot.diagnose.decide.Whitened`).
2. **Locate** where the data and the model differ (frequency, time,
   amplitude statistics of the residual), each calibrated by a parametric
   bootstrap of the fitted model with its own remnant, every replicate
   refitted (:mod:`bayespilot.diagnose.locate`).
3. **Name**: fit every entry of the catalogue
   (:mod:`bayespilot.diagnose.catalogue`) and test it against the base model
   (likelihood-ratio test on the decision likelihood; flat tops and the
   censored likelihood for control saturation).  The answer is ``"none"``
   when no test passes the family-wise level ``alpha`` (Bonferroni over the
   candidates tested).  Among the candidates that pass, the one with the
   largest ``log_bayes_factor`` (the Schwarz approximation of ln BF, delta
   BIC / 2) is chosen, unless others come within 2 of its delta BIC: then,
   of these, the one whose signature the located evidence shows most
   strongly (``signature_score``; the larger delta BIC breaks a tie).  Exact
   flat tops (p = 0, an infinite delta BIC) decide.  The ranking is by
   ``log_bayes_factor``, the candidates that pass before the others and
   those not testable last, with the chosen one first.
   Optionally (``n_calibrate``) the chosen candidate's test is first
   calibrated by a parametric bootstrap of the base model
   (:mod:`bayespilot.diagnose.calibrate`); a candidate that fails its
   calibrated test gives way to the next.
4. **Model**: the chosen extension's parameters with standard errors, from
   a fit made after the test with the extended model's own noise model and
   delta_abs (:func:`~bayespilot.diagnose.decide.final_fit`), and their
   profile-likelihood intervals (:mod:`bayespilot.diagnose.profile`);
   :func:`~bayespilot.diagnose.posterior.sample_chosen` then samples the
   extended model's posterior (optional, tens of seconds;
   :func:`~bayespilot.diagnose.posterior.shared_posterior` the shared
   parameters' of a pooled diagnosis), and
   :func:`~bayespilot.diagnose.nested.bayes_factor` weighs an extension
   against the base model by nested sampling (optional, minutes).
5. **Show**: :meth:`DiagnosisResult.report` writes PNG figures, a
   self-contained HTML report and a JSON summary.

It reads the recording only (signals, K_theta, the task description and its
forcing functions); never the ``simulation`` key of a simulated run's sidecar.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from .._files import (dumps, json_ready, number, numbers, read_result, require_keys,
                      write_text_atomic)
from .catalogue import (CATALOGUE, NAMES, Extension, _candidate_name, candidate_names,
                        get_extension, register_extension, registered_extensions,
                        unregister_extension)
from .locate import BaseFitWarning, EvidenceWarning
from .._blas import one_blas_thread
from .._caller import warn_at_caller
from .._html import SummaryHTML
from .._seeds import resolve_seed

if TYPE_CHECKING:
    from ..fit.result import FitResult
    from ..recording import Recording

__all__ = ["diagnose", "DiagnosisResult", "CATALOGUE", "NAMES", "Extension", "get_extension",
           "register_extension", "unregister_extension", "registered_extensions",
           "candidate_names", "EvidenceWarning", "BaseFitWarning"]

#: Default family-wise false-alarm level of the decision.
ALPHA = 0.01
#: Default replicates of the parametric bootstrap that calibrates the chosen candidate's test
#: (0: off; see :mod:`bayespilot.diagnose.calibrate` for why it is not on by default).
N_CALIBRATE = 0
#: Most passes of the noise model's estimation (``noise_passes``).
MAX_NOISE_PASSES = 5
#: Seconds at the start of the record left out of the decision likelihood and the evidence.
SKIP_SECONDS = 5.0
#: A better base fit found from an extension's fit (``decide.null_refit``) by more than this
#: (in -ln L) makes every extension be fitted again from it; a smaller gain only moves the
#: reference of the tests.
REBASE_TOL = 0.5
#: At most this many such refits.
MAX_REBASE = 2



class _JSONSummary:
    """``to_json`` and ``from_json`` for a result that has ``to_dict`` and ``from_dict``: the
    diagnoses (:class:`_DiagnosisJSON`), the Bayes factor
    (:class:`~bayespilot.diagnose.nested.ExtensionBayesFactor`) and the shared posterior
    (:class:`~bayespilot.diagnose.posterior.SharedPosterior`).  A class sets
    :attr:`_file_keys`, the keys a file of its kind has, or overrides :meth:`_from_file`."""

    #: Keys every file of this kind has (its ``from_dict``'s required ones): ``from_json``
    #: refuses a file without them as another kind of result, naming the file.
    _file_keys: tuple[str, ...] = ()

    def to_json(self, path: str | Path | None = None) -> str:
        """The JSON summary as text; also written to ``path`` when given.

        Parameters
        ----------
        path : str or Path, optional
            Also write the text to this file (atomically: a reader never sees half of
            it; parent folders are created).

        Returns
        -------
        str
            The JSON text (standard JSON: no NaN or Infinity tokens), whether or not
            ``path`` is given.
        """
        text = dumps(self.to_dict())
        if path is not None:
            write_text_atomic(path, text)
        return text

    @classmethod
    def from_json(cls, path: str | Path):
        """The result a :meth:`to_json` file holds.

        For a diagnosis: ``diagnosis.json`` of a report, the JSON of
        ``bayespilot diagnose --json``, a batch's per-recording file; it keeps
        the decision, the ranking, the located evidence, the fits' numbers and
        the posterior's summary, not the signals, fitted models and noise
        models a diagnosis carries in memory (see its ``from_dict``).  For a
        shared posterior also the file ``bayespilot diagnose --posterior
        X.json`` writes for several runs.

        Parameters
        ----------
        path : str or Path
            The result file.

        Returns
        -------
        DiagnosisResult, PooledDiagnosisResult, ExtensionBayesFactor or SharedPosterior
            Of the class it is called on; a file of another kind is refused.

        Raises
        ------
        FileNotFoundError
            No file at ``path``.
        ValueError
            The file is not JSON, or holds another kind of result (the message
            names the file).
        """
        return read_result(path, lambda d: cls._from_file(d, str(path)), cls._kind())

    @classmethod
    def _kind(cls) -> str:
        """The kind of result, for messages: "a DiagnosisResult", "an ExtensionBayesFactor"."""
        return f"{'an' if cls.__name__[0] in 'AEIOU' else 'a'} {cls.__name__}"

    @classmethod
    def _from_file(cls, d: Mapping[str, Any], source_file: str):
        """The result of the dict ``d`` read from ``source_file``; WrongKind (named with the file
        by :func:`~bayespilot._files.read_result`) without :attr:`_file_keys`."""
        require_keys(d, cls._file_keys, cls._kind())
        return cls.from_dict(d)


class _DiagnosisJSON(_JSONSummary, SummaryHTML):
    """:class:`_JSONSummary` of a diagnosis: it also reads a diagnose-batch file (its
    settings, then the diagnosis), and its ``from_dict`` names the file in its messages."""

    @classmethod
    def _from_file(cls, d: Mapping[str, Any], source_file: str):
        if isinstance(d.get("diagnosis"), Mapping) and "physics" not in d:
            d = d["diagnosis"]  # a diagnose-batch file: its settings, then the diagnosis
        return cls.from_dict(d, source_file=source_file)


def _parameter_units(*models: Any) -> dict[str, str]:
    """Each parameter's unit as the models declare it (``"-"``: dimensionless), by name; the
    first model to declare a name gives its unit (a name shared by the models has one unit:
    :meth:`~bayespilot.model.PilotModel.extend` refuses another).  None is skipped.

    A diagnosis keeps this for the base model and every candidate's extended model, so that
    a result file says what unit each of its numbers has (``units`` in its JSON)."""
    units: dict[str, str] = {}
    for m in models:
        for p in getattr(m, "parameters", ()) if m is not None else ():
            units.setdefault(p.name, p.unit)
    if "u_max" in units:  # control-saturation also reports the flat tops' other limit, the
        # censored fit's remnant sd (both in u's unit, as u_max) and the censored samples
        units.setdefault("u_min", units["u_max"])
        units.setdefault("sigma", units["u_max"])
        units.setdefault("n_censored", "-")
    return units


def _unit_suffix(units: Mapping[str, str], name: str) -> str:
    """" rad/s" after a number in the summary; "" for a dimensionless or unknown unit."""
    u = units.get(name)
    return "" if not u or u == "-" else f" {u}"


def _short_repr(result: Any, what: str, source: Any = None) -> str:
    """``<Class: decision, what, source>`` on one line, for a diagnosis in a notebook; it
    does not raise on a result read back from its JSON (or half built)."""
    try:
        if getattr(result, "mismatch", False):
            p = getattr(getattr(result, "chosen", None), "p_value", None)
            decision = (f"{result.physics} justified"
                        + ("" if p is None else f" (p = {float(p):.2g})"))
        else:
            decision = "no extension justified"
    except Exception:  # noqa: BLE001 - a repr must not raise
        decision = "?"
    text = "" if not source else str(source)
    text = text if len(text) <= 60 else "..." + text[-57:]
    return f"<{type(result).__name__}: {decision}, {what}{', ' + text if text else ''}>"


def _base_from(d: Mapping[str, Any]) -> dict[str, Any]:
    """A base fit's dict (``base``) as a result file holds it, its nulls NaN."""
    return {k: numbers(v) if isinstance(v, Mapping) else number(v) for k, v in d.items()}


def _base_samples(base_fit: Any, recording: Recording) -> dict[str, float | int]:
    """``discard_seconds`` and ``n``: the samples the base fit's -ln L (Eq. 4) is over.
    diagnose's own base fit takes the whole record (discard 0), where ``bayespilot fit`` may
    leave out a start-up (a base_fit given)."""
    discard = float(base_fit.settings.get("discard") or 0.0)
    return {"discard_seconds": discard,
            "n": recording.n_samples - int(round(discard * recording.sample_rate_hz))}


def _base_over(base: Mapping[str, Any]) -> str:
    """" (whole record, N = 8192)" or " (after the first 2 s, N = 7992)": the samples the base
    fit's -ln L (Eq. 4) is over (``base["discard_seconds"]``, ``base["n"]``), which ``bayespilot
    fit`` may count otherwise (it leaves out a start-up on a record not of whole periods); ""
    for a file written before they were recorded."""
    d, n = base.get("discard_seconds"), base.get("n")
    if d is None or n is None or not (math.isfinite(float(d)) and math.isfinite(float(n))):
        return ""
    where = "whole record" if float(d) == 0.0 else f"after the first {float(d):g} s"
    return f" ({where}, N = {int(n)})"


def _ranking_and_chosen(d: Mapping[str, Any], pooled: bool, source_file: str | None):
    """A result file's dict of a diagnosis of the kind asked for (:func:`_kind_check`): its
    ranking (CandidateResults) and its chosen candidate, the ranking's entry of that name
    (built from ``d["chosen"]`` if the ranking lacks it), or None."""
    from .decide import CandidateResult

    _kind_check(d, pooled, source_file)
    ranking = [CandidateResult.from_dict(c) for c in d["ranking"]]
    c = d.get("chosen")
    if c is None:
        return ranking, None
    chosen = next((r for r in ranking if r.physics == c["physics"]), None)
    return ranking, chosen or CandidateResult.from_dict(dict(
        {"testable": True, "justified": True}, **c))


def _kind_check(d: Mapping[str, Any], pooled: bool, source_file: str | None) -> None:
    """Refuse a dict that is not a diagnosis's of the kind asked for, naming what it is."""
    where = f"{source_file} holds" if source_file else "this dict is"
    if not {"physics", "ranking", "where"} <= set(d):
        raise ValueError(f"{where} not a diagnosis result (no physics, ranking and where)")
    if bool(d.get("pooled")) != pooled:
        raise ValueError(f"{where} a {'pooled' if d.get('pooled') else 'single-run'} "
                         f"diagnosis: read it with "
                         f"{'PooledDiagnosisResult' if d.get('pooled') else 'DiagnosisResult'}"
                         f".from_json")
    # (read unconditionally by from_dict: a KeyError without this)
    missing = [k for k in ("mismatch",) + (() if pooled else ("base",)) if k not in d]
    if missing:
        raise ValueError(f"{where} not a complete {'pooled' if pooled else 'single-run'} "
                         f"diagnosis result: no {', '.join(missing)}")


def _bic(c) -> str:
    """A candidate's delta BIC for the summary's table: "inf" for exact flat tops (the
    censored test's strongest finding), "-" where none was computed (-inf or NaN: an entry
    fitted without a likelihood, such as control-saturation without flat tops)."""
    if math.isfinite(c.delta_bic):
        return f"{c.delta_bic:.1f}"
    return "inf" if c.delta_bic > 0 else "-"


def _fitted_lines(chosen, units: Mapping[str, str] | None = None) -> list[str]:
    """The chosen extension's reported parameters +- standard errors with their units, and
    how they were made when refitted after the test (beside the test's estimate)."""
    ref = chosen.refit
    lines = []
    for k, v in chosen.params.items():
        was = f"   (test's fit {ref['test_params'][k]:.5g}; s.e. the test's)" if ref else ""
        lines.append(f"  {k:<10} {v:12.5g} +- {chosen.stderr.get(k, math.nan):.2g}"
                     f"{_unit_suffix(units or {}, k)}{was}")
        if k in chosen.interval:
            iv = chosen.interval[k]
            lines.append(f"  {'':<10} {100 * iv.level:.0f} % profile-likelihood interval {iv}")
    if ref:
        d0, d1 = ref["delta_abs"]
        if isinstance(d0, list):
            d0, d1 = (", ".join(f"{d:.4g}" for d in x) for x in (d0, d1))
            lines.append(f"  {ref['how']}; each run's delta_abs {d0} -> {d1}")
        else:
            lines.append(f"  {ref['how']}" + (f"; delta_abs {d0:.4g} -> {d1:.4g}"
                                              if d0 is not None and d1 is not None else ""))
    return lines


def _at_bounds_lines(edge) -> list[str]:
    """The summary's lines for ``settings["base_at_bounds"]`` (none without it)."""
    if not edge:
        return []
    said = ", ".join(f"{d['parameter']} = {d['value']:.4g} ({d['side']} bound, {d['fit']})"
                     for d in edge)
    return [f"base fit ON A BOUND: {said}; a named extension may be making up for a "
            f"recording problem (sign or unit convention, offset), not physics"]


def _base_bounds_lines(wider) -> list[str]:
    """The summary's line for ``settings["base_bounds"]`` (the base model's bounds that are
    the given base fit's, not Table 1's), or none."""
    if not wider:
        return []
    return ["base model's bounds from base_fit (Table 1's otherwise): "
            + ", ".join(f"{k} in [{lo:g}, {hi:g}]" for k, (lo, hi) in wider.items())]


def _calibration_lines(ranking) -> list[str]:
    """The summary's account of the tests calibrated by the parametric bootstrap."""
    lines = []
    for c in ranking:
        cal = c.calibration
        if cal is None:
            continue
        lines.append(f"{c.physics}: test calibrated by {cal.replicates} replicates of the base "
                     f"model: null mean d(-lnL) {cal.null_mean:.2f} (reference "
                     f"{cal.reference_mean:.2f}, scale {cal.scale:.2f}), p {cal.p_nominal:.2g} "
                     f"-> {cal.p_value:.2g}" + ("" if c.justified else " (not justified)"))
    return [""] + lines if lines else []


@dataclass(eq=False)  # by identity: == on its arrays would be ambiguous
class DiagnosisResult(_DiagnosisJSON):
    """What :func:`diagnose` found.

    Attributes
    ----------
    mismatch : bool
        True if an extension of the catalogue is justified at level ``alpha``.
    physics : str
        The chosen catalogue name, or ``"none"``.
    ranking : list of CandidateResult
        Every candidate, best first.
    where : dict of str to Evidence
        The located evidence with bootstrap p-values.
    base : dict
        The base model's fit: ``params``, ``neg_log_lik`` (Eq. 4), ``vaf``,
        ``gls_neg_log_lik``, ``gls_params`` (every parameter, those held
        fixed at their values) and ``gls_stderr`` (the GLS
        estimates' standard errors; decision likelihood), and
        ``discard_seconds`` and ``n``, the samples ``neg_log_lik`` and
        ``vaf`` are over (diagnose's own base fit: the whole record,
        ``discard_seconds`` 0, where ``bayespilot fit`` may leave out a
        start-up; absent in files written before they were recorded).
    chosen : CandidateResult or None
        The chosen extension's fit (parameters, standard errors).
    settings : dict
        alpha, seed, bootstrap size, band, skip, remnant of the replicates
        (``bootstrap``; with ``skipped``, why, when the bootstrap asked for
        could not be made; ``dropped`` replicates that failed), the base
        fit's parameters on a bound (``base_at_bounds``, when any), the base
        model's bounds taken from ``base_fit`` (``base_bounds``: name ->
        [lower, upper], those that are not Table 1's; when any), the base
        model's parameters held fixed as ``base_fit`` held them
        (``base_fixed``: name -> value; when any).
    elapsed : float
        Wall time, s.
    source : str or None
        The recording diagnosed.
    arrays : dict
        What the report's figures are drawn from, kept in memory: the base
        fit's residual and output, describing functions, amplitude spectra,
        the chosen fit's output, residual, VAF (%) and -ln L (Eq. 4) before
        and after, the forcing frequencies, the decision's noise model.
        After :meth:`from_dict` only the numbers a result file keeps, and
        ``"from_json"`` (the file, or True).
    posterior : Posterior or None
        The chosen extended model's posterior, once
        :func:`~bayespilot.diagnose.posterior.sample_chosen` has sampled it.
    bayes_factor : ExtensionBayesFactor or None
        ln BF of an extension against the base model by nested sampling, once
        :func:`~bayespilot.diagnose.nested.bayes_factor` has computed it.
    base_model : PilotModel or None
        The base model the candidates extend.
    units : dict of str to str
        Each parameter's unit (``"-"``: dimensionless), by name: the base
        model's and every candidate's new parameters; ``units`` in the JSON.  Empty for a file
        written before units were recorded.
    """

    mismatch: bool
    physics: str
    ranking: list
    where: dict
    base: dict
    chosen: Any
    settings: dict
    elapsed: float
    source: str | None = None
    arrays: dict = field(default_factory=dict, repr=False)
    posterior: Any = field(default=None, repr=False)
    bayes_factor: Any = field(default=None, repr=False)
    base_model: Any = field(default=None, repr=False)
    units: dict = field(default_factory=dict, repr=False)

    def __repr__(self) -> str:
        """One line (the dataclass's would print every candidate's arrays)."""
        return _short_repr(self, f"{len(self.ranking or ())} candidates", self.source)

    def _posterior_dict(self) -> dict[str, Any] | None:
        if self.chosen is None:
            return None
        if self.posterior is None:  # a result read from a file keeps the posterior's summary
            return self.arrays.get("posterior_summary")
        from .posterior import posterior_dict

        return posterior_dict(self.posterior, tuple(self.chosen.params))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: ``mismatch``, ``physics``, ``ranking``, ``where``, ``base``, ... ."""
        from .decide import json_number

        def num(x):  # absent stays None
            return None if x is None else json_number(x)

        chosen = None
        if self.chosen is not None:
            # the numbers as the ranking writes them (its to_dict): an infinity as "inf" or
            # "-inf" in both, not "inf" in the ranking and null here for the same candidate
            cd = self.chosen.to_dict()
            chosen = {"physics": self.chosen.physics, "params": cd["params"],
                      "stderr": cd["stderr"], "all_params": cd["all_params"],
                      "delta_neg_log_lik": cd["delta_neg_log_lik"],
                      "neg_log_lik_before": num(self.arrays.get("before_eq4_neg_log_lik")),
                      "neg_log_lik_after": num(self.arrays.get("after_eq4_neg_log_lik")),
                      "vaf_before": num(self.arrays.get("before_vaf")),
                      "vaf_after": num(self.arrays.get("after_vaf")),
                      "refit": cd["refit"], "interval": cd["interval"],
                      "posterior": self._posterior_dict()}
        return json_ready({
            "mismatch": self.mismatch, "physics": self.physics,
            "ranking": [c.to_dict() for c in self.ranking],
            "where": {k: e.to_dict() for k, e in self.where.items()},
            "base": self.base, "chosen": chosen, "settings": self.settings,
            "bayes_factor": None if self.bayes_factor is None else self.bayes_factor.to_dict(),
            "elapsed_seconds": self.elapsed, "source": self.source,
            "units": dict(self.units)})

    def summary(self) -> str:
        """A readable account: the decision, the ranking, the located evidence."""
        lines = [f"bayespilot diagnose{' ' + self.source if self.source else ''}",
                 f"decision: {self.physics}" + (" (mismatch)" if self.mismatch else
                                                " (no extension justified)"),
                 f"base model: -ln L (Eq. 4) = {self.base['neg_log_lik']:.2f}"
                 f"{_base_over(self.base)}, VAF = {self.base['vaf']:.2f} %",
                 *_base_bounds_lines(self.settings.get("base_bounds")),
                 *_base_fixed_lines(self.settings.get("base_fixed"), self.units),
                 *_at_bounds_lines(self.settings.get("base_at_bounds")),
                 f"level: alpha = {self.settings['alpha']:g} over "
                 f"{self.settings['n_tested']} candidates",
                 *([f"base model refitted from an extension's fit: -ln L (GLS) better by "
                    f"{sum(r['gain'] for r in self.settings['rebased']):.2f}; every test is "
                    f"against that fit and the plots' base residual is its; the located "
                    f"evidence's p-values are the first base fit's"]
                  if self.settings.get("rebased") else []),
                 "", f"{'candidate':<24} {'d(-lnL)':>9} {'p':>9} {'dBIC':>9} {'sig':>5}  params"]
        for c in self.ranking:
            if not c.testable:
                lines.append(f"{c.physics:<24} {'-':>9} {'-':>9} {'-':>9} {'-':>5}  ({c.reason})")
                continue
            ps = ", ".join(f"{k}={v:.4g}" for k, v in c.params.items())
            p = f"{c.p_value:.2g}"
            lines.append(f"{c.physics:<24} {c.delta_neg_log_lik:9.2f} {p:>9} {_bic(c):>9} "
                         f"{c.signature_score:5.2f}  {ps}{'  *' if c.justified else ''}")
        lines += _calibration_lines(self.ranking)
        if self.chosen is not None:
            lines += ["", f"fitted {self.chosen.physics}:",
                      *_fitted_lines(self.chosen, self.units)]
            after = self.arrays.get("after_vaf")
            if after is not None:
                lines.append(f"  VAF {self.arrays['before_vaf']:.2f} % -> {after:.2f} %, "
                             f"-ln L (Eq. 4) {self.arrays['before_eq4_neg_log_lik']:.1f} -> "
                             f"{self.arrays['after_eq4_neg_log_lik']:.1f} (after the first "
                             f"{self.settings['skip_seconds']:g} s)")
            post = self._posterior_dict()
            if post is not None:
                lines.append(f"  posterior ({post['likelihood']} likelihood, "
                             f"{'converged' if post['converged'] else 'NOT converged'}): "
                             "median, 90 % HDI")
                for k in post["new_parameters"]:
                    d = post["params"][k]
                    lines.append(f"  {k:<10} {d['median']:12.5g}  [{d['hdi_90'][0]:.4g}, "
                                 f"{d['hdi_90'][1]:.4g}]")
        if self.bayes_factor is not None:
            lines += ["", self.bayes_factor.summary_line()]
        boot = self.settings.get("bootstrap", {})
        skipped = boot.get("skipped")
        dropped = int(boot.get("dropped") or 0)
        lines += ["", f"located evidence (no p-values: the bootstrap was skipped, {skipped}):"
                  if skipped else
                  f"located evidence (bootstrap p-values; only {boot.get('replicates', 0)} of "
                  f"{boot.get('replicates', 0) + dropped} replicates survived, the others' "
                  f"closed loop diverged or refit failed: check the signs and units of u, e "
                  f"and control_gain):" if dropped else
                  "located evidence (bootstrap p-values):"]
        for k, e in self.where.items():
            if not math.isfinite(e.value):
                continue
            p = "n/a" if not math.isfinite(e.p_value) else f"{e.p_value:.3f}"
            lines.append(f"  {k:<28} {e.value:12.4g}  p = {p}")
        bf = self.bayes_factor
        more = (f" (and {bf.elapsed:.1f} s for the Bayes factor's nested sampling)"
                if bf is not None and bf.elapsed > 0 else "")  # (its runs come after)
        lines.append(f"time: {self.elapsed:.1f} s{more}")
        return "\n".join(lines)

    __str__ = summary

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, source_file: str | None = None
                  ) -> "DiagnosisResult":
        """The diagnosis a :meth:`to_dict` holds, as far as a result file keeps it.

        Its ``summary()``, ``to_dict()`` and numbers are the original's.
        Not kept, so not here: the signals the report's figures are drawn
        from, the candidates' fitted models and noise models (``fit``,
        ``model``, ``noise`` are None), the posterior's draws (its summary
        is kept and shown) and the base model; :meth:`report`,
        :func:`~bayespilot.diagnose.posterior.sample_chosen` and
        :func:`~bayespilot.diagnose.nested.bayes_factor` need the diagnosis
        made again.  An infinity is ``"inf"``/``"-inf"`` in ``ranking`` and
        ``chosen`` alike; files written before 2026-11-29 have null for one in
        ``chosen``, read as missing.

        Parameters
        ----------
        d : mapping
            A single-run diagnosis's :meth:`to_dict` (or its JSON, parsed).
        source_file : str, optional
            Where ``d`` was read from, for messages.

        Returns
        -------
        DiagnosisResult

        Raises
        ------
        ValueError
            ``d`` is not a diagnosis's, or is a pooled one's
            (:meth:`PooledDiagnosisResult.from_dict`), or lacks ``mismatch`` or
            ``base`` (the message names it).
        """
        from .locate import Evidence
        from .nested import ExtensionBayesFactor

        ranking, chosen = _ranking_and_chosen(d, False, source_file)
        c = d.get("chosen")
        arrays: dict[str, Any] = {"from_json": source_file or True}
        if c is not None:
            for key, name in (("before_vaf", "vaf_before"), ("after_vaf", "vaf_after"),
                              ("before_eq4_neg_log_lik", "neg_log_lik_before"),
                              ("after_eq4_neg_log_lik", "neg_log_lik_after")):
                # a number, or "inf"/"-inf"; null (absent, or an infinity as files
                # written before 2026-11-29 wrote it) leaves it out, as before
                if c.get(name) is not None:
                    arrays[key] = number(c[name])
            if c.get("posterior") is not None:
                arrays["posterior_summary"] = c["posterior"]
        bf = d.get("bayes_factor")
        return cls(bool(d["mismatch"]), d["physics"], ranking,
                   {k: Evidence.from_dict(e) for k, e in d["where"].items()},
                   _base_from(d["base"]), chosen, dict(d.get("settings") or {}),
                   number(d.get("elapsed_seconds", 0.0)), d.get("source"), arrays,
                   bayes_factor=None if bf is None else ExtensionBayesFactor.from_dict(bf),
                   units=dict(d.get("units") or {}))

    def report(self, directory: str | Path, *, formats: Sequence[str] = ("png",),
               title: bool = True) -> dict[str, Path]:
        """Write PNG figures, ``report.html`` (figures embedded) and ``diagnosis.json``.

        Parameters
        ----------
        directory : str or Path
            Created, with its parents, if missing; files of the same names in
            it are replaced.
        formats : sequence of str, optional
            Also write each figure in these formats beside its PNG (``"pdf"``,
            ``"svg"``: for a paper; fonts embedded as TrueType, SVG text kept
            as text); another name is refused (ValueError).
        title : bool, optional
            True (default): each figure with its own title; False: the figures
            without titles, for a paper whose captions say it (a panel's note,
            such as a posterior's draws and convergence, moves into its legend;
            :func:`~bayespilot.diagnose.report.write_report`).

        Returns
        -------
        dict of str to Path
            The files written, by name (see
            :func:`~bayespilot.diagnose.report.write_report`).

        Raises
        ------
        ValueError
            The result was read from a file (:meth:`from_json`), which keeps
            the numbers but not the signals the figures are drawn from; or
            ``formats`` names one that is not ``"png"``, ``"pdf"`` or ``"svg"``.
        TypeError
            ``title`` is not True or False.
        """
        from .report import write_report

        if self.arrays.get("from_json"):
            where = self.arrays["from_json"]
            raise ValueError(f"this diagnosis was read from "
                             f"{'a dict' if where is True else where}: a result file keeps its "
                             f"numbers, not the signals the report's figures are drawn from; "
                             f"diagnose the recording again to write its report")

        return write_report(self, directory, formats=formats, title=title)


def _check(recording, alpha, n_bootstrap, skip_seconds, candidates, oversample=1,
           n_calibrate=0, noise_passes=1, omega_c=None):
    from ..model import MAX_OVERSAMPLE
    from ..recording import Recording

    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    if not (isinstance(alpha, (int, float)) and 0 < alpha < 1):
        raise ValueError(f"alpha must be in (0, 1), got {alpha!r}")
    if not isinstance(n_bootstrap, (int, np.integer)) or n_bootstrap < 0:
        raise ValueError(f"n_bootstrap must be an integer >= 0, got {n_bootstrap!r}")
    if isinstance(n_calibrate, bool) or not isinstance(n_calibrate, (int, np.integer)) \
            or n_calibrate < 0:
        raise ValueError(f"n_calibrate must be an integer >= 0, got {n_calibrate!r}")
    if isinstance(noise_passes, bool) or not isinstance(noise_passes, (int, np.integer)) \
            or not 1 <= noise_passes <= MAX_NOISE_PASSES:
        raise ValueError(f"noise_passes must be an integer in [1, {MAX_NOISE_PASSES}], "
                         f"got {noise_passes!r}")
    if not (isinstance(skip_seconds, (int, float)) and 0 <= skip_seconds):
        raise ValueError(f"skip_seconds must be a number >= 0 s, got {skip_seconds!r}")
    if not skip_seconds < recording.duration / 2:
        raise ValueError(f"the recording{' ' + recording.source if recording.source else ''} is "
                         f"{recording.duration:g} s long: too short to leave out the first "
                         f"{skip_seconds:g} s (skip_seconds) and keep more than as much; it "
                         f"needs more than {2 * skip_seconds:g} s")
    if isinstance(oversample, bool) or not isinstance(oversample, (int, np.integer)) \
            or not 1 <= oversample <= MAX_OVERSAMPLE:
        raise ValueError(f"oversample must be an integer in [1, {MAX_OVERSAMPLE}], "
                         f"got {oversample!r}")
    if omega_c is not None:
        # (the noise model refuses these too, but only after the base fit)
        if isinstance(omega_c, bool) or not isinstance(omega_c, (int, float, np.integer,
                                                                 np.floating)) \
                or not omega_c > 0:
            raise ValueError(f"omega_c must be a positive number of rad/s (math.inf: the "
                             f"whole band), got {omega_c!r}")
        limit = 2 * math.pi * 0.45 * recording.sample_rate_hz
        if math.isfinite(omega_c) and not omega_c < limit:
            raise ValueError(f"{_where(recording)}omega_c = {omega_c:g} rad/s is too close "
                             f"to the Nyquist frequency of a recording sampled at "
                             f"{recording.sample_rate_hz:g} Hz: the low-pass needs it below 0.45 "
                             f"of the sampling frequency, {limit:.4g} rad/s (math.inf keeps "
                             f"the whole band)")
    if isinstance(candidates, str):
        raise ValueError(f"candidates must be a list of catalogue names, got the string "
                         f"{candidates!r} (write [{candidates!r}])")
    if isinstance(candidates, Extension):
        raise ValueError(f"candidates must be a list of catalogue names or entries, got the "
                         f"Extension {candidates.name!r} alone (write [entry])")
    # None: the built-in catalogue, then the registered entries (exactly NAMES when none is);
    # an Extension among them is registered (catalogue.register_extension checks it)
    names = (candidate_names() if candidates is None
             else tuple(_candidate_name(c) for c in candidates))
    if len(set(names)) != len(names):
        # each name is one test of the Bonferroni split: a repeat would lower the level
        raise ValueError(f"candidates names an entry twice: {list(names)}")
    if not names:
        raise ValueError("candidates is empty: name at least one catalogue entry (None: all)")
    _check_needs(names)
    return names


def _check_needs(names) -> None:
    """Refuse (ValueError naming the entry and its ``needs``), before any fit, a candidate
    whose model reads a recording column its ``needs`` leaves out (an entry put in the
    registry without :func:`register_extension`'s check): it would fail at its own fit, after
    the base fit, the bootstrap and the candidates before it, where ``needs`` lets the
    diagnosis skip it on a recording without the column."""
    from ..model import paper_model
    from .catalogue import _unlisted_needs

    base = None
    for name in names:
        ext = get_extension(name)
        if ext.likelihood != "gls":
            continue
        base = paper_model() if base is None else base
        why = _unlisted_needs(ext, ext.build(base))
        if why is not None:
            raise ValueError(why)


def _base_gls(recording, base_model, start: Mapping[str, float], *, skip: int,
              omega_c: float | None = None, noise_passes: int = 1):
    """The noise model of the base fit's residual and the GLS fit of the base model under it.

    The first stage of :func:`diagnose` after its base fit, for studies that
    refit extensions as it does.  Returns the Eq. 4 likelihood of the base
    model, the noise model and the GLS fit (a ``decide.FitSummary``).  The
    first pass estimates the noise model from the residual at ``start`` (the
    Eq. 4 fit); each further pass re-estimates it from the residual of the
    GLS fit under the previous one and refits.
    """
    from ..likelihood import Likelihood
    from . import decide as D

    omega_c = D.OMEGA_C if omega_c is None else float(omega_c)
    lik0 = Likelihood(base_model, recording)
    at = start
    for _ in range(noise_passes):
        noise = D.noise_model(lik0.residual(at), recording.dt, skip=skip, omega_c=omega_c)
        _, base = D.fit_base_gls(base_model, recording, at, noise)
        at = base.params
    return lik0, noise, base


def _where(recording) -> str:
    """The recording's source as a message prefix ("" without one)."""
    return f"{recording.source}: " if recording.source else ""


def _warn(recording, text: str, category: type[Warning] = EvidenceWarning) -> None:
    """One :class:`EvidenceWarning` (or ``category``) about ``recording``, attributed to the
    first caller outside bayespilot (``diagnose``, ``diagnose_pooled`` or a batch, however
    nested)."""
    warn_at_caller(_where(recording) + text, category)


def _dropped_why(dropped: int, diverged: int) -> str:
    """Why ``dropped`` bootstrap replicates were left out, ``diverged`` of them by their closed
    loop, the others by their refit."""
    return ", ".join(text for n, text in ((diverged, f"{diverged} closed loop(s) diverged"),
                                          (dropped - diverged,
                                           f"{dropped - diverged} refit(s) failed")) if n)


def _dropped_note(boot_info: Mapping[str, Any], n_bootstrap: int) -> str | None:
    """The EvidenceWarning's text when fewer bootstrap replicates survived than were asked
    for (``locate.bootstrap`` drops those whose closed loop diverges or whose refit fails),
    or None."""
    kept = int(boot_info.get("replicates", 0))
    if n_bootstrap <= 0 or kept >= n_bootstrap or "skipped" in boot_info:
        return None
    why = _dropped_why(n_bootstrap - kept, int(boot_info.get("diverged", 0)))
    then = ("so every located statistic's p-value is missing (n/a)" if kept == 0 else
            f"so the located p-values rest on {kept} (the smallest is {1 / (kept + 1):.2g})")
    return (f"only {kept} of {n_bootstrap} bootstrap replicates survived ({why}), {then}: "
            f"the fitted pilot most likely destabilises the recorded plant in the closed loop "
            f"the bootstrap simulates, which is what a recording problem makes of the base "
            f"fit; check the signs and units of u, e and control_gain (and the controlled "
            f"element) against the recording format")


def _base_at_bounds(base_fit, base, base_model) -> list[dict[str, Any]]:
    """The pilot parameters of the base fit on (or beyond) a bound of their search box: of
    the Eq. 4 fit (``FitResult.at_bounds``), then of the GLS base fit ``base`` (a
    ``decide.FitSummary``, bounded by ``base_model``'s), each parameter once.

    Not ``delta_abs`` on its lower bound (0, the answer "no threshold"), nor a parameter held
    fixed or not identified (the Eq. 4 fit's ``settings["unidentified"]``, a silent
    channel's).  Each entry: ``parameter``, ``value``, ``side`` ("lower" or "upper"),
    ``bound``, ``fit`` ("Eq. 4" or "GLS").
    """
    from ..fit.result import _bound_side

    quiet = set(base_fit.settings.get("unidentified") or ())
    fixed = set(base_fit.fixed)
    out: list[dict[str, Any]] = []

    def add(name, value, side, bound, fit):
        if name in quiet or name in fixed or (name == "delta_abs" and side == "lower") \
                or any(d["parameter"] == name for d in out):
            return
        out.append({"parameter": name, "value": float(value), "side": side,
                    "bound": float(bound), "fit": fit})

    for k, side in base_fit.at_bounds.items():
        add(k, base_fit.params[k], side, base_fit._edge_text(k, side)[1], "Eq. 4")
    if base is not None:
        for k in base.refined:
            par = base_model.parameter(k)
            lo, hi, v = float(par.lower), float(par.upper), float(base.params[k])
            side = _bound_side(v, lo, hi)
            if side is not None:
                add(k, v, side, lo if side == "lower" else hi, "GLS")
    return out


def _base_at_bounds_note(edge: Sequence[Mapping[str, Any]]) -> str:
    """The BaseFitWarning's text for :func:`_base_at_bounds`' list (not empty)."""
    said = ", ".join(f"{d['parameter']} = {d['value']:.4g} on its {d['side']} bound "
                     f"({d['bound']:g}, {d['fit']} fit)" for d in edge)
    return (f"the base fit has {said}: the bound, not the data, stopped it, because of the "
            f"recording (a sign or unit convention of u, e or theta, an offset), of a loop "
            f"gain unlike the paper's (the base model's bounds are Table 1's, K_v and K_m up "
            f"to 10, unless base_fit was made with others: a small plant or stick gain can "
            f"need more), or of physics the base model lacks (a strong otolith channel can "
            f"put tau_m on 1 s); an extension named from this base fit may be making up for "
            f"the recording or the bounds rather than for missing physics: check the "
            f"recording (signs, units, offsets) and, for a gain on its bound, rescale u "
            f"(diagnose rec.with_signals(u=rec.u / c), c = 10 say, and multiply the fitted "
            f"K_v and K_m by c; docs/fitting.md, 'A loop gain unlike the paper's') or give "
            f"a base_fit made with wider bounds, before reading the decision")


def _base_fixed(base_fit, model, where: str = "") -> dict[str, float]:
    """The parameters ``base_fit`` held fixed (:attr:`~bayespilot.fit.result.FitResult.fixed`)
    that ``model`` (the paper's) has, name -> ``base_fit``'s value: the base model holds them
    there too, so that no fit of the diagnosis (the GLS base fit, every extension's, the
    profile intervals, the bootstrap's and the calibration's replicates) estimates what the
    user held.  A parameter only marked as not identified (``settings["unidentified"]``, a
    silent channel's) is free in ``base_fit`` and stays free, as without a base_fit.

    A ValueError for a fit without threshold (``delta_abs`` held at 0): the catalogue extends
    the paper's model with its threshold (``threshold-shape`` reshapes it, every extension's
    reported fit rescans it), which a base model without one would turn into another question
    (whether there is a threshold at all: :mod:`bayespilot.compare`'s)."""
    held = [k for k in base_fit.fixed if k in model.all_names and k in base_fit.params]
    if "delta_abs" in held and float(base_fit.params["delta_abs"]) == 0.0:
        raise ValueError(
            f"{where}base_fit was made without threshold (delta_abs held at 0): diagnose tests "
            f"extensions of the paper's model with its threshold (threshold-shape reshapes it, "
            f"the reported fits rescan it), and would otherwise estimate the delta_abs this fit "
            f"held; give a base_fit made with the threshold "
            f"(fit_fast or fit_paper with threshold=True, the default), or none (diagnose "
            f"then makes its own); whether there is a threshold at all is bayespilot.compare's "
            f"question")
    return {k: float(base_fit.params[k]) for k in held}


def _check_held(names: Sequence[str], base_model, held: Mapping[str, float]) -> None:
    """A ValueError, before any fit, if a candidate's ``build`` of ``base_model`` frees or
    changes a parameter the base model holds for ``base_fit`` (``held``): its test would
    estimate what the user held and count a degree of freedom it does not say.  The built-in
    entries keep a model's fixed parameters (``add_stage``, ``with_nonlinearity``, ... keep
    them); an entry that no longer has the parameter at all (it replaced the block that read
    it) holds nothing and is accepted."""
    if not held:
        return
    for name in names:
        model = get_extension(name).build(base_model)
        bad = [f"{k} ({'free' if k not in model.fixed else f'held at {model.fixed[k]:g}'}, "
               f"base_fit's {v:g})" for k, v in held.items()
               if k in model.all_names and model.fixed.get(k) != v]
        if bad:
            raise ValueError(
                f"extension {name!r}: its build of the base model leaves {', '.join(bad)}, "
                f"which base_fit held fixed and the diagnosis holds in the base model; an "
                f"extension must keep the base model's fixed parameters (build it with the "
                f"model's add_stage, add_channel, with_nonlinearity, with_modulation or "
                f"with_output, which keep them), or leave this candidate out")


def _base_fixed_lines(held, units: Mapping[str, str] | None = None) -> list[str]:
    """The summary's line for ``settings["base_fixed"]`` (the parameters the base model holds
    at base_fit's values, as base_fit held them), or none."""
    if not held:
        return []
    return ["base model's parameters held fixed as base_fit held them (in every fit here): "
            + ", ".join(f"{k} = {float(v):g}{_unit_suffix(units or {}, k)}"
                        for k, v in held.items())]


def _base_model(base_fit, oversample: int, where: str = ""):
    """The base model the candidates extend: the paper's (Table 1 bounds), with the bounds
    ``base_fit`` was made with where they differ (a lab whose loop gain needs K_v > 10) and
    the parameters it held fixed held at its values (:func:`_base_fixed`; the returned model's
    ``fixed``), and those differences of bounds (name -> [lower, upper]; empty: Table 1's).

    A ValueError, before any fit, if an estimate of ``base_fit`` lies outside the bounds of
    that base model (its bounds not recorded, or a fit of another model): the catalogue's
    tests would start from a point the base model cannot hold; or if ``base_fit`` was made
    without threshold (:func:`_base_fixed`)."""
    import dataclasses

    from ..model import paper_model

    model = paper_model(oversample=oversample)
    if base_fit is None:
        return model, {}
    box = base_fit._box()
    params, wider = [], {}
    for p in model.parameters:
        lo, hi = (float(v) for v in box.get(p.name, (p.lower, p.upper)))
        if (lo, hi) != (p.lower, p.upper):
            p = dataclasses.replace(p, lower=lo, upper=hi, default=min(max(p.default, lo), hi))
            wider[p.name] = [lo, hi]
        params.append(p)
    if wider:
        model = dataclasses.replace(model, parameters=tuple(params))
    held = _base_fixed(base_fit, model, where)
    if held:  # (without the bounds check: the fit's own model may have had other bounds)
        model = model._fixed(**held)
    out = []
    for p in model.parameters:
        v = base_fit.params.get(p.name)
        if p.name in model.parameter_names and v is not None and not (
                p.lower - 1e-9 * (p.upper - p.lower) <= float(v)
                <= p.upper + 1e-9 * (p.upper - p.lower)) and p.name not in box:
            out.append(f"{p.name} = {float(v):.4g} outside [{p.lower:g}, {p.upper:g}]")
    if out:
        raise ValueError(
            f"{where}base_fit has {', '.join(out)}, the bounds of diagnose's base model (the "
            f"paper's, Table 1), and records no bounds of its own for "
            f"{'it' if len(out) == 1 else 'them'}: the catalogue's tests extend the paper's "
            f"model within its bounds, where this fit cannot be held.  Rescale u so that the "
            f"estimates fall inside Table 1 (diagnose rec.with_signals(u=rec.u / c) and "
            f"multiply the fitted K_v and K_m by c; docs/fitting.md, 'A loop gain unlike the "
            f"paper's'), or give a base_fit made by fit_fast or fit_paper with widened "
            f"bounds (it records them; diagnose then uses them)")
    return model, wider


#: What a recording without forcing functions misses (a warning's text; what to give:
#: ``locate.GIVE_FORCING``).
_NO_FORCING = ("no forcing functions are known (no forcing in the sidecar, no f_t and f_d "
               "columns): the frequency evidence is missing")


def _bootstrap_obstacle(recording, forcing) -> tuple[str, str] | None:
    """Why the parametric bootstrap (and the calibration) cannot simulate this recording's
    task, or None: ``(reason, message)``, the reason for the settings and the warning's text
    (without the source).

    No forcing functions known, or a controlled element the simulator cannot run (relative
    degree below 2, seen by building the task as :func:`~.locate.task_of` does).
    """
    from . import locate as L

    skipped = "the bootstrap of the located evidence is skipped, so the evidence has no p-values"
    if forcing is None:
        return ("no forcing functions known: no forcing in the sidecar, no f_t and f_d columns",
                f"{_NO_FORCING}, and {skipped} (it simulates the task with them); "
                f"{L.GIVE_FORCING}")
    try:
        L.task_of(recording, forcing)
    except ValueError as exc:
        num, den = (np.trim_zeros(np.atleast_1d(x), "f") for x in recording.controlled_element)
        plant = (f"num [{', '.join(f'{x:g}' for x in num)}], "
                 f"den [{', '.join(f'{x:g}' for x in den)}]")
        degree = den.size - max(num.size, 1)
        if degree >= 2:  # refused for another reason: say it as the simulator does
            return (f"the task cannot be simulated: {exc}",
                    f"{skipped}: it simulates the task, which cannot be simulated ({exc})")
        return (f"controlled element of relative degree {degree}: the bootstrap simulates the "
                f"plant, which needs relative degree >= 2",
                f"{skipped}: it simulates the plant, and the controlled element ({plant}) has "
                f"relative degree {degree}, where the simulator needs 2 or more")
    return None


def _default_plant(recording) -> bool:
    """A task ``"other"`` whose sidecar leaves the plant out: the recording format then means
    the paper's K_c/s^2 with K_c = 4 (and K_delta_u = 0.69), which the bootstrap simulates."""
    return recording.task == "other" and not ({"controlled_element", "controlled_element_gain"}
                                              & set(recording.metadata))


@dataclass
class _Run:
    """One recording's first stages: base fit, GLS fit, noise model, located evidence."""

    base_model: Any
    base_fit: Any
    base: Any
    noise: Any
    lik0: Any
    forcing: Any
    statistics: dict
    where: dict
    boot_info: dict
    skip: int
    timings: dict
    noise_passes: int = 1
    #: Why the task cannot be simulated (``_bootstrap_obstacle``), or None.
    obstacle: tuple[str, str] | None = None
    #: The EvidenceWarnings said about this recording (kept in the result's settings).
    notes: tuple[str, ...] = ()
    #: The base fit's parameters on a bound (:func:`_base_at_bounds`; a BaseFitWarning).
    base_at_bounds: tuple = ()


def _prepare(recording, *, seed, n_bootstrap, base_fit, skip_seconds, omega_c, n_starts,
             profile_noise, bar, oversample: int = 1, noise_passes: int = 1) -> _Run:
    """Base fit (Eq. 4), the noise model and GLS base fit, and the calibrated evidence.

    Before the fit, one :class:`EvidenceWarning` per gap in the evidence this recording
    will have (the forcing's notes; a bootstrap asked for that cannot be made).
    """
    from ..fit.fast import fit_fast
    from . import decide as D
    from . import locate as L

    # what the recording allows, said before the (long) computation
    forcing = L.forcing_of(recording)
    notes = list(forcing.notes) if forcing is not None else []
    obstacle = _bootstrap_obstacle(recording, forcing)
    if obstacle is not None and n_bootstrap > 0:
        notes.append(obstacle[1])
    elif forcing is None:  # the frequency evidence is missing with or without a bootstrap
        notes.append(f"{_NO_FORCING}; {L.GIVE_FORCING}")
    if obstacle is None and n_bootstrap > 0 and _default_plant(recording):
        notes.append("the recording (task 'other') gives no controlled_element or "
                     "controlled_element_gain, which the recording format reads as the "
                     "paper's plant, 4/s^2 (and control_gain 0.69 unless given): the "
                     "bootstrap simulates that plant; if yours differs, give it in the "
                     "sidecar, or the evidence's p-values are of the wrong plant")
    elif obstacle is None and n_bootstrap > 0 and recording.task == "other" \
            and "control_gain" not in recording.metadata:
        notes.append("the recording (task 'other') gives its plant but no control_gain, which "
                     "the recording format reads as the paper's K_delta_u, 0.69: the bootstrap "
                     "simulates the loop with that gain; if yours differs, give it in the "
                     "sidecar, or the evidence's p-values are of the wrong loop")
    for note in notes:
        _warn(recording, note)
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    bar.set_postfix_str("base fit")
    base_model, _ = _base_model(base_fit, oversample, _where(recording))
    if base_fit is None:
        # discard=0: the diagnosis leaves out its own start (skip_seconds) of every statistic
        base_fit = fit_fast(recording, base_model, seed=seed, n_starts=n_starts,
                            profile_step=0.005, discard=0.0)
    start = {k: v for k, v in base_fit.params.items() if k in base_model.parameter_names}
    timings["base_fit"] = time.perf_counter() - t0
    skip = int(round(skip_seconds * recording.sample_rate_hz))
    lik0, noise, base = _base_gls(recording, base_model, start, skip=skip, omega_c=omega_c,
                                  noise_passes=noise_passes)
    if profile_noise:
        base, noise = D.refit_with_noise(base_model, recording, base, noise,
                                         tuple(n for n in base_model.parameter_names
                                               if n != "delta_abs"))
    timings["base_gls"] = time.perf_counter() - t0 - timings["base_fit"]
    edge = _base_at_bounds(base_fit, base, base_model)
    if edge:  # (the decision is made as ever; the warning says how far to trust it)
        note = _base_at_bounds_note(edge)
        notes.append(note)
        _warn(recording, note, BaseFitWarning)
    bar.update(1)
    bar.set_postfix_str(f"located evidence ({n_bootstrap} bootstrap replicates)")
    t1 = time.perf_counter()
    st = L.statistics(recording, base_model, base.params, forcing, skip=skip, with_arrays=True)
    null = None
    boot_info: dict[str, Any] = {"replicates": 0}
    if n_bootstrap > 0 and obstacle is not None:
        boot_info["skipped"] = obstacle[0]
    elif n_bootstrap > 0:
        def refit(rep, start=base.params):
            # the GLS base fit again, from the generating parameters under the recording's
            # noise model (the Eq. 4 fit's multi-start search would cost ~1.5 s a replicate)
            return D.fit_base_gls(base_model, rep, start, noise)[1].params

        bar.total = (bar.total or 0) + n_bootstrap  # a tick a replicate (0.3 s each)
        bar.refresh()
        null, boot_info = L.bootstrap(recording, base_model, base.params, forcing,
                                      st["arrays"]["residual"], n_replicates=n_bootstrap,
                                      seed=seed, skip=skip, refit=refit, progress=bar.update)
        note = _dropped_note(boot_info, n_bootstrap)
        if note is not None:
            notes.append(note)
            _warn(recording, note)
    where = L.calibrate(st["values"], null)
    timings["locate"] = time.perf_counter() - t1
    bar.update(1)
    return _Run(base_model, base_fit, base, noise, lik0, forcing, st, where, boot_info, skip,
                timings, noise_passes, obstacle, tuple(notes), tuple(edge))


def _fit_candidates(names, recording, base_model, base, noise, where, boot_info, profile_noise,
                    bar, guide=None):
    """Fit and test every candidate from the GLS base fit ``base``.

    ``guide``: name -> parameters of the candidate's fit on the low-passed band
    (``decide.guide_fits``), one more start for its fit.
    Returns the candidate results and the delta_abs-refined reference (or None).
    """
    from . import decide as D

    results = []
    refined = None
    for name in names:
        ext = get_extension(name)
        bar.set_postfix_str(name)
        if ext.likelihood == "censored":
            res = _saturation(recording, base_model, base, where, boot_info)
        else:
            ref = base
            if ext.refine_threshold:
                # the entry refines delta_abs, which the base fit only scanned on a grid:
                # its reference gets the same freedom (else that alone is its "improvement")
                if refined is None:
                    refined = D.refine_threshold(base_model, recording, base, noise)
                ref = refined
            extra = [guide[name]] if guide and name in guide else []
            res, _ = D.fit_candidate(ext, base_model, recording, ref, noise,
                                     profile_noise=profile_noise, extra_starts=extra)
        sig = [where[k].p_value for k in ext.signature_keys
               if k in where and math.isfinite(where[k].p_value)]
        res.signature_score = float(max([-math.log10(p) for p in sig], default=0.0))
        results.append(res)
        bar.update(1)
    return results, refined


def _best_null(names, results, base_model, recording, noise):
    """The best base-model fit reached from any candidate's fit (:func:`decide.null_refit`)."""
    from . import decide as D

    best = None
    for name, res in zip(names, results):
        got = D.null_refit(get_extension(name), base_model, recording, res, noise)
        if got is not None and (best is None or got.neg_log_lik < best.neg_log_lik):
            best = got
    return best


def _calibrator(runs, recordings, n_calibrate, seed, bar, n_starts=4):
    """The calibration function of :func:`_calibrated_decision` for these runs; None, with an
    :class:`EvidenceWarning`, when a run's task cannot be simulated (:func:`_bootstrap_obstacle`:
    the asymptotic test stands)."""
    from .calibrate import calibrate_candidate

    for run, rec in zip(runs, recordings):
        if run.obstacle is not None:
            _warn(rec, f"the calibration of the chosen candidate's test (n_calibrate) is "
                       f"skipped, so the asymptotic test stands: {run.obstacle[0]}")
            return None

    # the replicates' own seeds: a child of the seed, apart from the located evidence's
    child = None if seed is None else np.random.SeedSequence(seed).spawn(1)[0]

    def calibrate(res):
        bar.total = (bar.total or 0) + n_calibrate
        bar.set_postfix_str(f"calibrating {res.physics} ({n_calibrate} replicates)")
        bar.refresh()
        return calibrate_candidate(get_extension(res.physics), runs, recordings,
                                   res.delta_neg_log_lik, n_replicates=n_calibrate,
                                   seed=child, n_starts=n_starts, progress=bar.update)
    return calibrate


def _decide(results, alpha):
    """Bonferroni over the testable candidates; choose among the justified; rank all.

    Returns ``(ranking, chosen, tested, level)``.
    """
    tested = [r for r in results if r.testable]
    level = alpha / max(len(tested), 1)
    for r in tested:
        r.justified = bool(r.p_value < level)
    justified = [r for r in tested if r.justified]
    chosen = None
    if justified:
        # flat tops (probability zero under continuous noise) decide saturation;
        # otherwise the largest BIC improvement, near-ties (< 2) broken by signature
        chosen = max(justified, key=lambda r: (r.log_bayes_factor, r.signature_score))
        close = [r for r in justified if math.isfinite(chosen.delta_bic)
                 and chosen.delta_bic - r.delta_bic < 2.0]
        if len(close) > 1:
            chosen = max(close, key=lambda r: (r.signature_score, r.delta_bic))

    def rank_key(r):
        return (r.testable, r.justified, r.log_bayes_factor if r.testable else -math.inf)

    ranking = sorted(results, key=rank_key, reverse=True)
    if chosen is not None:
        ranking.remove(chosen)
        ranking.insert(0, chosen)
    return ranking, chosen, tested, level


def _calibrated_decision(results, alpha, calibrate):
    """:func:`_decide`, then the chosen candidate's test calibrated by ``calibrate`` (a
    function of a CandidateResult returning a ``calibrate.Calibration`` or None); a choice
    that fails its calibrated test gives way to the next justified candidate, calibrated in
    turn.  Flat tops (``control-saturation``) are not recalibrated: they decide.
    """
    ranking, chosen, tested, level = _decide(results, alpha)
    done = set()
    while (calibrate is not None and chosen is not None and chosen.physics not in done
           and get_extension(chosen.physics).likelihood == "gls"):
        done.add(chosen.physics)
        cal = calibrate(chosen)
        chosen.calibration = cal
        if cal is None:
            break
        chosen.p_value = cal.p_value
        ranking, chosen, tested, level = _decide(results, alpha)
    return ranking, chosen, tested, level


@one_blas_thread
def diagnose(recording: Recording, *, seed: int | None = 0, alpha: float = ALPHA,
             n_bootstrap: int = 39, candidates: Sequence[str | Extension] | None = None,
             base_fit: FitResult | None = None,
             skip_seconds: float = SKIP_SECONDS, omega_c: float | None = None,
             n_starts: int = 4, profile_noise: bool = False, oversample: int = 1,
             n_calibrate: int = N_CALIBRATE, noise_passes: int = 1, refit: bool = True,
             intervals: bool = True, progress: bool = False) -> DiagnosisResult:
    """Locate a model mismatch, name the missing physics, fit it (see module docs).

    Parameters
    ----------
    recording : Recording
    seed : int or None
        Seeds the base fit's starts and the bootstrap; the same seed gives the
        same result.  None draws one from fresh entropy, recorded in
        ``settings["seed"]``.
    alpha : float
        Family-wise false-alarm level of the decision, split over the
        candidates tested (Bonferroni).
    n_bootstrap : int
        Replicates of the parametric bootstrap behind the located evidence,
        each simulated and refitted (about 0.5 s a replicate at N = 8192;
        0: no calibration; the decision does not depend on it except through
        the signature scores and the quantised-flat-top case).
    candidates : sequence of str or Extension, optional
        Catalogue names to test, or entries: an Extension of one's own is
        registered (:func:`~bayespilot.diagnose.catalogue.register_extension`,
        which checks it), a built-in one stands for its name.  Default: the
        built-in catalogue, then the entries registered in this process
        (:func:`~bayespilot.diagnose.catalogue.candidate_names`; with none
        registered, :data:`NAMES`).
    base_fit : FitResult, optional
        A fit of the paper's model to this recording, to skip the base fit.
        The base model (which every candidate extends; their own parameters
        keep their bounds) takes the bounds it was made with where they are
        not Table 1's: a lab whose loop gain needs K_v > 10 fits with
        widened bounds (docs/fitting.md, "A loop gain unlike the paper's")
        and gives that fit here (``settings["base_bounds"]``).  Without
        it, the base model has Table 1's bounds; rescaling u
        (``recording.with_signals(u=recording.u / c)``) is the other way
        round them.  The parameters it held fixed
        (:attr:`~bayespilot.fit.result.FitResult.fixed`, e.g. a fit of
        ``paper_model().fix(tau_v=0.3)``) the base model holds at its
        values, so that no fit of the diagnosis estimates them: the GLS
        base fit, every extension's fit and test, the reported refit and
        its profile intervals, the bootstrap's and the calibration's
        replicates (``settings["base_fixed"]``, and a line of the
        summary); an extension whose ``build`` would free one is refused.
        Parameters it only marks as not identified
        (``settings["unidentified"]``, a silent channel's) stay free, as
        without it.  A fit without threshold (``delta_abs`` held at 0) is
        refused: the catalogue extends the model with its threshold.
    skip_seconds : float
        Start of the record left out of the decision likelihood and evidence
        (the likelihood's start-up transient).
    omega_c : float, optional
        Cut-off of the decision likelihood's low-pass, rad/s (default 25).
        ``math.inf`` keeps the whole band: with ``oversample=1`` the model's
        100-Hz discretisation error becomes visible there and raises false
        alarms; with ``oversample=8`` it does not (0 false alarms on the
        proof study's 48 controls, 56 % of its concealed cases named against
        51 % by default, at twice the time; ``docs/diagnose-evidence.md``).  Above
        25 rad/s every extension is also started from its fit on the
        25-rad/s band (``decide.guide_fits``).
    n_starts : int
        Starting points of the base fit.
    profile_noise : bool
        Re-estimate the noise model's AR coefficients with each fit (the base
        and every extension) instead of holding those of the base model's
        residual, which whitens part of what the base model misses.  About
        30 % more time; off by default because the proof study rerun with it
        named no more (52 of 95 concealed cases against 54 of 96, no false
        alarm either way; ``docs/diagnose-evidence.md``).
    oversample : int
        The base model's (and so every extension's) vestibular channel at
        this many times the recording's rate in the likelihood
        (``paper_model(oversample=...)``); 1, the default, is the paper's
        computation.  With 8 the model's discretisation error no longer
        shows in the whole band (``docs/diagnose-evidence.md``).
    n_calibrate : int
        Replicates B of the parametric bootstrap that calibrates the chosen
        candidate's test before it is accepted (:mod:`.calibrate`: the base
        model simulated with its own remnant, the candidate refitted on each
        replicate; its p-value is then the reference's at the statistic
        divided by the replicates' scale when that is above 1).  A choice
        that fails gives way to the next justified candidate.  0 keeps the
        asymptotic test alone (the default: see
        :mod:`bayespilot.diagnose.calibrate` for what it was measured to do).
        Costs about 2 s per replicate (each retraces the diagnosis' Eq. 4
        and GLS fits), only when a candidate is justified.
    noise_passes : int
        How often the noise model is estimated before the tests: 1 (the
        default) from the residual of the Eq. 4 base fit; each further pass
        (at most 5) from the residual of the GLS base fit under the previous
        one, then the GLS base fit again.  In the closed loop the Eq. 4 fit
        absorbs part of the remnant's lowest frequencies, so its residual's
        AR model under-weights them; a second pass corrects that (on 400
        correct-model runs the washout's null mean went from 0.272 to 0.248,
        the platform's from 0.164 to 0.207, reference 0.25;
        ``docs/diagnose-evidence.md``).  A calibration (``n_calibrate``) retraces the
        same passes.
    refit : bool
        Report the chosen extension's estimates from a fit made after the
        test with its own noise model and delta_abs
        (:func:`~bayespilot.diagnose.decide.final_fit`) rather than the
        test's fit, which holds both at the base model's values (on 160
        runs: a 6-rad/s platform's bandwidth spread 0.58 against 0.39 rad/s,
        delta_abs biased).  The standard errors stay the test's, which cover
        those estimates (86-95 % for 90 % stated on four entries) where the
        refit's own are up to 1.4 times too small: the closed loop and the
        dead zone give the estimates a heavy tail (``docs/diagnose-evidence.md``,
        *The reported fit*).  The test's statistics are the same either way;
        its estimates stay in ``chosen.refit``.  About 5 s with the profile
        intervals for a washout at N = 8192 (eight starts in delta_abs each
        round), only when an extension is chosen.
    intervals : bool
        With ``refit``: 90 % profile-likelihood intervals of the chosen
        extension's new parameters (``chosen.interval``,
        :mod:`bayespilot.diagnose.profile`), the deviance scaled so that a
        quadratic profile gives the reported Wald interval.  Where the
        profile is not quadratic they differ: on 160 runs with a soft
        threshold (w_soft = 0.045, near its bound 0.05) the profile found a
        better fit than the refit's in 19 (counted before the refit's starts
        in delta_abs), which is then reported, and its
        interval held the truth in 140 (88 %), the Wald interval in 110
        (69 %; ``docs/diagnose-evidence.md``, *The profile-likelihood
        interval*).  0.1-8 s (the otolith's two parameters the longest).
    progress : bool
        Show a tqdm bar over the stages (base fit, located evidence, each
        candidate, the calibration's replicates).

    Returns
    -------
    DiagnosisResult

    Raises
    ------
    TypeError
        If ``recording`` is not a Recording, or ``base_fit`` (given) is not a
        :class:`~bayespilot.fit.result.FitResult`.
    ValueError
        If ``alpha`` is not in (0, 1); ``n_bootstrap`` or ``n_calibrate`` is
        not an integer >= 0; ``noise_passes`` or ``oversample`` is not an
        integer in its range; ``skip_seconds`` is not in [0, half the
        recording); ``omega_c`` (given) is not a positive number, or is
        finite and not below 0.45 of the sampling frequency (in rad/s);
        ``candidates`` is a string or one Extension, empty,
        repeats a name, names one that is not in the catalogue or gives an
        Extension that :func:`~bayespilot.diagnose.catalogue.register_extension`
        refuses, or names an entry whose model reads a recording column its
        ``needs`` leaves out (checked before the base fit); ``base_fit`` has
        an estimate outside the paper's bounds (Table 1) and records no
        bounds of its own for it (the message says to rescale u), or was
        made without threshold (``delta_abs`` held at 0), or a candidate's
        ``build`` frees a parameter it held fixed; or
        ``n_calibrate`` is asked for with ``profile_noise=True``.

    Warns
    -----
    EvidenceWarning
        Before the base fit, once for each gap in the located evidence: no
        forcing functions known (no frequency evidence, no bootstrap); forcing
        lines that are not whole cycles of the record (no frequency
        evidence); a forcing function zero throughout (no visual or motion
        describing-function evidence); a base frequency snapped to the
        record's DFT bins; and, with ``n_bootstrap > 0``, a task the bootstrap
        cannot simulate, so that the evidence has no p-values (a controlled
        element of relative degree below 2; ``settings["bootstrap"]["skipped"]``
        then says why); and, with ``n_bootstrap > 0``, a task ``"other"``
        that leaves its plant out, which the recording format reads as the
        paper's 4/s^2 and the bootstrap simulates.  The messages are kept in
        ``settings["evidence_notes"]``.  With ``n_calibrate > 0`` the
        calibration is skipped for the same reasons, said once more when it
        would start (``settings["calibration_skipped"]``).  After the
        bootstrap, once when fewer replicates survived than were asked for
        (their closed loop diverged or their refit failed:
        ``settings["bootstrap"]["dropped"]``, ``["diverged"]``; none
        surviving leaves every p-value missing), which a base fit made from a
        recording problem (u of the other sign) gives.
    BaseFitWarning
        After the base fit, once when a pilot parameter of it (the Eq. 4 fit,
        :attr:`~bayespilot.fit.result.FitResult.at_bounds`, or the GLS fit)
        is on a bound of its search box, other than ``delta_abs = 0`` and a
        parameter fixed or not identified: the named extension may be making
        up for a recording problem, or for bounds that do not suit the loop
        (a gain on its bound: the message names the rescale of u), rather
        than physics.  The decision is made
        as ever; ``settings["base_at_bounds"]`` records the parameters (and
        the summary shows them).  A subclass of EvidenceWarning.

    Examples
    --------
    >>> from bayespilot.simulate import simulate
    >>> rec = simulate(task="FD", motion_gain=1.0, remnant_gain=0.06, seed=1,
    ...                duration=30.0).recording
    >>> res = diagnose(rec, seed=0, n_bootstrap=0, candidates=["time-varying-gains"])
    >>> res.physics in ("none", "time-varying-gains")
    True
    """
    from ..likelihood import vaf
    from . import decide as D
    from . import locate as L

    names = _check(recording, alpha, n_bootstrap, skip_seconds, candidates, oversample,
                   n_calibrate, noise_passes, omega_c)
    if base_fit is not None:
        from ..fit.result import FitResult

        if not isinstance(base_fit, FitResult):
            raise TypeError(f"base_fit must be a FitResult (of fit_fast or fit_paper), got "
                            f"{type(base_fit).__name__}")
    # a base fit outside the base model's bounds, or without threshold: refused before any
    # work; so is a candidate whose build frees a parameter base_fit held
    model0, wider = _base_model(base_fit, oversample, _where(recording))
    held = dict(model0.fixed)  # (base_fit's held parameters, :func:`_base_fixed`)
    _check_held(names, model0, held)
    seed = resolve_seed(seed)  # None: a fresh one, recorded in the settings
    if profile_noise and n_calibrate:
        raise ValueError("n_calibrate does not combine with profile_noise=True (the replicates "
                         "retrace the decision with the noise model held)")
    t0 = time.perf_counter()
    from tqdm.auto import tqdm

    bar = tqdm(total=2 + len(names), desc="diagnose", unit="stage", disable=not progress)
    try:  # the bar closed however the call ends (an interrupt, an error)
        run = _prepare(recording, seed=seed, n_bootstrap=n_bootstrap, base_fit=base_fit,
                       skip_seconds=skip_seconds, omega_c=omega_c, n_starts=n_starts,
                       profile_noise=profile_noise, bar=bar, oversample=oversample,
                       noise_passes=noise_passes)
        base_model, base_fit, base, noise = run.base_model, run.base_fit, run.base, run.noise
        lik0, forcing, st, where, boot_info, skip = (run.lik0, run.forcing, run.statistics,
                                                      run.where, run.boot_info, run.skip)
        timings = run.timings

        # -- name
        t2 = time.perf_counter()
        rebased = []
        guide = None
        if noise.omega_c > D.OMEGA_C:
            # a wider band than the default: start each extension from its low-band fit too
            bar.set_postfix_str(f"low-band fits (omega_c = {D.OMEGA_C:g} rad/s)")
            guide = D.guide_fits(names, base_model, recording,
                                 {k: v for k, v in base_fit.params.items()
                                  if k in base_model.parameter_names}, skip, get_extension)
        kept: dict[str, Any] = {}  # each candidate's best fit over the rounds
        for _ in range(MAX_REBASE + 1):
            results, refined = _fit_candidates(names, recording, base_model, base, noise, where,
                                               boot_info, profile_noise, bar, guide)
            for r in results:
                old = kept.get(r.physics)
                if (old is None or r.fit is None or old.fit is None
                        or r.fit.neg_log_lik <= old.fit.neg_log_lik):
                    kept[r.physics] = r
            if profile_noise:
                break  # each fit has its own noise model: the -ln L are not comparable
            better = _best_null(names, [kept[n] for n in names], base_model, recording, noise)
            if better is None or not better.neg_log_lik < base.neg_log_lik:
                break
            gain = base.neg_log_lik - better.neg_log_lik
            base = better
            if gain <= REBASE_TOL or len(rebased) == MAX_REBASE:
                rebased.append({"gain": gain, "refitted": False})
                break
            # a better basin of the base model: every extension again from there
            rebased.append({"gain": gain, "refitted": True})
            bar.total += len(names)  # every extension once more
            bar.refresh()
        results = [kept[n] for n in names]
        if rebased:
            # every test against the best base fit found (threshold-shape: or its refinement)
            for r in results:
                ext = get_extension(r.physics)
                ref = base.neg_log_lik
                if ext.refine_threshold and refined is not None:
                    ref = min(ref, refined.neg_log_lik)
                D.retest(r, ext, ref)
        timings["name"] = time.perf_counter() - t2
        t3 = time.perf_counter()
        calibrate = None
        if n_calibrate > 0:
            calibrate = _calibrator([dataclasses.replace(run, base=base)], [recording],
                                    n_calibrate, seed, bar, n_starts)
        uncalibrated = run.obstacle if n_calibrate > 0 else None
        ranking, chosen, tested, level = _calibrated_decision(results, alpha, calibrate)
        timings["calibrate"] = time.perf_counter() - t3
        t4 = time.perf_counter()
        if (refit and chosen is not None and chosen.fit is not None
                and get_extension(chosen.physics).likelihood == "gls"):
            bar.total += 1  # the refit and profile intervals: seconds, the bar still open
            bar.set_postfix_str(f"refit of {chosen.physics}")
            D.report_final_fit(chosen, base_model, recording, noise, intervals=intervals)
            bar.update(1)
    finally:
        bar.close()
    timings["refit"] = time.perf_counter() - t4

    # -- model and show: residual after the chosen extension
    arrays = dict(st.get("arrays", {}))
    if rebased and st.get("arrays"):
        # the plots' base residual and describing functions at the base fit the tests are
        # against (the located p-values stay those of the first base fit, where their
        # bootstrap was made: settings["rebased"] says so)
        arrays.update(L.statistics(recording, base_model, base.params, forcing, skip=skip,
                                   with_arrays=True).get("arrays", {}))
    sl = slice(skip, None)
    y_before = L.steady_response(base_model, recording, base.params)
    arrays["before_vaf"] = vaf(recording.u[sl], y_before[sl])
    if chosen is not None and chosen.fit is not None:
        if chosen.physics == "control-saturation":
            y = lik0.response(chosen.fit.params)
            y = np.clip(y, chosen.params["u_min"], chosen.params["u_max"])
        else:
            # periodic steady state: a slow stage (washout) has no start-up transient
            y = L.steady_response(chosen.model, recording, chosen.fit.params)
        arrays["after_u_hat"] = y
        arrays["after_residual"] = recording.u - y
        arrays["after_vaf"] = vaf(recording.u[sl], y[sl])
        arrays["after_eq4_neg_log_lik"] = _eq4_neg_log_lik((recording.u - y)[sl], lik0.s2_floor)
        arrays["before_eq4_neg_log_lik"] = _eq4_neg_log_lik((recording.u - y_before)[sl],
                                                            lik0.s2_floor)
        if forcing is not None and forcing.two_input:
            arrays["df_after"] = L.describing_function(y, recording.e, recording.theta_ddot_m,
                                                       forcing)
    arrays["forcing_frequencies"] = (forcing.target.frequencies, forcing.disturbance.frequencies) \
        if forcing is not None else None
    arrays["level"] = level
    arrays["noise"] = noise  # the decision's noise model (decide.NoiseModel)
    base_d = {"params": dict(base_fit.params), "neg_log_lik": float(base_fit.neg_log_lik),
              "vaf": float(base_fit.vaf),
              # every parameter, those held fixed (settings["base_fixed"]) at their values
              "gls_params": base_model.as_dict(base_model.full_vector(base.params), full=True),
              "gls_neg_log_lik": float(base.neg_log_lik),
              "gls_stderr": base.stderr, **_base_samples(base_fit, recording)}
    settings = {"alpha": alpha, "level_per_candidate": level, "n_tested": len(tested),
                "seed": seed, "n_bootstrap": n_bootstrap, "bootstrap": boot_info,
                "n_calibrate": n_calibrate, "noise_passes": noise_passes, "refit": refit,
                "intervals": intervals, "skip_seconds": skip_seconds, "dt": recording.dt,
                "noise_model": noise.to_dict(),
                "candidates": list(names), "timings": timings, "rebased": rebased,
                "decision_likelihood": "GLS: residual low-passed, decimated and whitened by an "
                                       "AR model of the base residual"}
    if uncalibrated is not None:
        settings["calibration_skipped"] = uncalibrated[0]
    if run.notes:
        settings["evidence_notes"] = list(run.notes)  # (the EvidenceWarnings, for the record)
    if run.base_at_bounds:
        settings["base_at_bounds"] = [dict(d) for d in run.base_at_bounds]  # (BaseFitWarning)
    if wider:
        settings["base_bounds"] = wider  # the base model's bounds that are base_fit's
    if held:
        settings["base_fixed"] = dict(held)  # held in every fit at base_fit's values
    return DiagnosisResult(chosen is not None, chosen.physics if chosen else "none", ranking,
                           where, base_d, chosen, settings, time.perf_counter() - t0,
                           recording.source, arrays, base_model=base_model,
                           units=_parameter_units(base_model, *(c.model for c in ranking)))


def _eq4_neg_log_lik(r: np.ndarray, s2_floor: float) -> float:
    """Eq. 4's -ln L of the output error ``r`` (independent samples, variance profiled out):
    N/2 ln(mean r^2) + N/2, the variance floored at ``s2_floor`` (a :class:`Likelihood`'s) as
    everywhere else (:func:`bayespilot.kernels._response.neg_log_lik_from_sse`): a perfect
    fit gives a finite value."""
    from ..kernels._response import neg_log_lik_from_sse

    r = np.asarray(r, dtype=float)
    return float(neg_log_lik_from_sse(float(np.sum(r * r)), r.size, float(s2_floor))[0])


def _saturation(recording, base_model, base, where, boot_info):
    """Test and fit ``control-saturation``: flat tops and the censored likelihood."""
    from . import decide as D
    from . import locate as L

    ext = get_extension("control-saturation")
    tops = D.flat_tops(recording.u)
    if tops["n_samples"] == 0:
        return D.CandidateResult(ext.name, True, "no flat tops in u (no samples at a limit)",
                                 df=0, p_value=1.0)
    # the bootstrap records the quantum; without a bootstrap (or without forcing functions to
    # simulate) it is read here, or a quantised u's repeated peaks would count as impossible
    q = boot_info["quantum"] if "quantum" in boot_info else L._quantum(recording.u)
    if not q:
        # exact repeats of the extreme value: probability 0 under continuous noise
        p = 0.0
        how = (f"{tops['n_samples']} samples in {tops['n_runs']} flat top(s); exact repeats "
               f"have probability 0 under a continuous-noise model; censored likelihood fit")
    else:
        e = where.get("amplitude.flat_tops")
        if e is not None and math.isfinite(e.p_value):
            p = e.p_value
            how = (f"{tops['n_samples']} samples in flat tops; u is quantised ({q:.3g}), p from "
                   f"the quantised bootstrap; censored likelihood fit")
        else:
            p = 1.0
            how = (f"{tops['n_samples']} samples in flat tops, but u is quantised ({q:.3g}) and "
                   f"no bootstrap tested how often its peaks repeat by chance: not a finding "
                   f"(diagnose with n_bootstrap > 0); censored likelihood fit")
    fit, f_start, sigma = D.fit_censored(base_model, recording, base.params, tops)
    d = max(0.0, f_start - fit.neg_log_lik)
    model = ext.build(base_model)._fixed(u_max=max(abs(tops["hi"]), abs(tops["lo"])))
    params = {"u_max": tops["hi"], "u_min": tops["lo"], "n_censored": float(tops["n_samples"]),
              "sigma": sigma}
    all_params = dict(fit.params)
    all_params.update(u_max=tops["hi"], u_min=tops["lo"])
    res = D.CandidateResult(ext.name, True, how, d, float(tops["n_samples"]), 0, float(p),
                            math.inf if p == 0.0 else 2.0 * d,
                            math.inf if p == 0.0 else d, params, fit.stderr, all_params)
    res.fit = fit
    res.model = model
    return res


from .pooled import PooledDiagnosisResult, diagnose_pooled  # noqa: E402  (uses the helpers above)
from .posterior import SharedPosterior, sample_chosen, shared_posterior  # noqa: E402
from .nested import bayes_factor  # noqa: E402

__all__ += ["diagnose_pooled", "PooledDiagnosisResult", "sample_chosen", "shared_posterior",
            "SharedPosterior", "bayes_factor"]

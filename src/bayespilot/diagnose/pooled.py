"""Diagnose several runs of one condition together: shared physics, per-run pilot.

One run of 81.92 s often cannot tell a small omission from remnant (the
single-run proof study misses most of the smallest effects, see
``docs/diagnose-evidence.md``).  A lab records several runs per subject and
condition, and the physics the base model leaves out - the platform's
bandwidth, the washout, an otolith response, the threshold's shape, a drift
over the run, the stick's limit - is a property of the set-up and the
subject, the same in every run, while the pilot's gains and delays may
differ from run to run.  :func:`diagnose_pooled` tests exactly that model:

1. each run gets the base stages of :func:`~bayespilot.diagnose.diagnose`
   (Eq. 4 fit, its own noise model and GLS fit, located evidence);
2. every GLS extension is fitted to all runs at once, with the pilot
   parameters per run and the extension's new parameters shared; the pooled
   -ln L is the sum of the runs' GLS -ln L (each with its own noise level),
   so the likelihood-ratio statistic 2 (sum base - pooled) has the
   extension's df, not R times it;
   (for ``threshold-shape``, which refines each run's delta_abs, the
   reference is the base model with delta_abs refined too);
3. ``control-saturation`` (flat tops) pools the runs' flat-top tests: any run
   with exact repeats of its extreme value decides it;
4. the same Bonferroni decision as for one run.

The signature scores combine each located statistic's bootstrap p-values
over the runs (Fisher's method).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np
from scipy import linalg, optimize, stats

from .._blas import one_blas_thread
from .._caller import warn_at_caller
from .._files import json_ready, number, numbers, write_text_atomic
from .._seeds import resolve_seed
from . import (ALPHA, MAX_REBASE, N_CALIBRATE, REBASE_TOL, SKIP_SECONDS, _calibrated_decision,
               _at_bounds_lines, _base_from, _base_samples, _bic, _calibration_lines,
               _calibrator, _check, _dropped_why, _fitted_lines, _DiagnosisJSON, _ranking_and_chosen, _short_repr,
               _parameter_units, _prepare, _saturation)
from .catalogue import Extension, get_extension

if TYPE_CHECKING:
    from ..recording import Recording

__all__ = ["diagnose_pooled", "PooledDiagnosisResult", "PoolingWarning", "pooling_disagreements",
           "pooled_final_fit"]

#: How the chosen extension's reported pooled fit is made (``diagnose_pooled(refit=True)``).
POOLED_FINAL_FIT = ("refitted after the test: each run's AR noise model re-estimated from its "
                    "extended model's residual, each run's delta_abs rescanned, three times")


class PoolingWarning(UserWarning):
    """Runs given to :func:`diagnose_pooled` that say they are not of one subject and condition."""


def pooling_disagreements(recordings: Sequence[Recording],
                          names: Sequence[str] | None = None) -> str | None:
    """What the runs' own metadata disagree on (subject, task, K_theta, the task's loop), or None.

    Pooling shares the extension's parameters over the runs, which assumes the
    physics left out is the same in every run.  Runs of several subjects or
    conditions may still be pooled on purpose (a platform's bandwidth is the
    same for every subject), so :func:`diagnose_pooled` warns
    (:class:`PoolingWarning`) and does not refuse.  Besides the subject, the
    task name and K_theta, the runs are compared on what the diagnosis reads
    of their task, as it reads it: the sample rate, the controlled element
    (``Recording.controlled_element``: the paper's 4/s^2 when none is given;
    compared with its denominator's leading coefficient 1), ``control_gain``
    (``Recording.control_gain``: 0.69 when not given) and the forcing
    functions (:func:`~bayespilot.diagnose.locate.forcing_of`: the sidecar's,
    else the ``f_t``/``f_d`` columns'; compared by the frequencies, in rad/s,
    and amplitudes of their lines of nonzero amplitude, within 1e-4 and 1e-3 of
    the largest amplitude: not by their phases, so another realisation of
    one forcing's phases is the same forcing; a run without any, or whose
    columns are not whole periods of separate lines, is not counted).

    Parameters
    ----------
    recordings : sequence of Recording
        The runs to pool.
    names : sequence of str, optional
        One name per run (e.g. its path): each value is then followed by the
        runs that give it, in parentheses.

    Returns
    -------
    str or None
        For each of subject (the metadata's ``subject``; a run without one is
        not counted), task, K_theta, sample_rate_hz, controlled_element,
        control_gain and forcing on which the runs give more than one value,
        ``"<what> <values>"`` with the values sorted and joined by ``", "``,
        these joined by ``"; "``; None when the runs agree.  A plant is
        written as its transfer function (``8/(s^2 + 2 s)``), a forcing by
        its lines per forcing function (``target 8 lines 0.209-7.85 rad/s rms
        0.0406 + disturbance ...``).

    Raises
    ------
    ValueError
        ``names`` is not one per run.

    Examples
    --------
    >>> from bayespilot.recording import Recording
    >>> import numpy as np
    >>> sig = {k: np.zeros(4) for k in ("e", "u", "theta_ddot_m")}
    >>> sig["t"] = np.arange(4) / 100.0
    >>> runs = [Recording(sig, 100.0, 1.0, "FD", {"subject": s}) for s in ("s1", "s2")]
    >>> pooling_disagreements(runs)
    'subject s1, s2'
    >>> runs = [Recording(sig, 100.0, 1.0, "other", {"subject": "s1", "control_gain": g})
    ...         for g in (0.69, 1.0)]
    >>> pooling_disagreements(runs, names=["a", "b"])
    'control_gain 0.69 (a), 1 (b)'
    """
    recs = list(recordings)
    if names is not None and len(names) != len(recs):
        raise ValueError(f"{len(names)} names for {len(recs)} recordings")
    said = []
    for what, values in (("subject", [r.metadata.get("subject") for r in recs]),
                         ("task", [r.task for r in recs]),
                         ("K_theta", [f"{r.motion_gain:g}" for r in recs]),
                         ("sample_rate_hz", [f"{r.sample_rate_hz:g}" for r in recs]),
                         ("controlled_element", [_plant_text(r) for r in recs]),
                         ("control_gain", [f"{r.control_gain:g}" for r in recs]),
                         ("forcing", _forcing_texts(recs))):
        given = sorted({str(v) for v in values if v is not None}, key=_in_order)
        if len(given) > 1:
            if names is not None:  # each value with the runs that give it
                given = [f"{v} ({', '.join(str(n) for n, w in zip(names, values) if str(w) == v)})"
                         for v in given]
            said.append(f"{what} {', '.join(given)}")
    return "; ".join(said) or None


def _in_order(value: str) -> tuple:
    """Sort key of a value :func:`pooling_disagreements` says: numbers by size (50 before
    250), before other text, alphabetically."""
    try:
        return (0, float(value), value)
    except ValueError:
        return (1, 0.0, value)


def _polynomial_text(c: np.ndarray) -> str:
    """A polynomial in s, coefficients highest power first: ``s^2 + 2 s``, ``8``."""
    deg = c.size - 1
    terms = []
    for i, a in enumerate(c):
        if a == 0:
            continue
        p = deg - i
        s = "" if p == 0 else ("s" if p == 1 else f"s^{p}")
        mag = abs(float(a))
        coef = f"{mag:.6g}" if (mag != 1 or not s) else ""
        term = f"{coef} {s}".strip()
        terms.append(("-" if a < 0 else "+", term))
    if not terms:
        return "0"
    text = ("-" if terms[0][0] == "-" else "") + terms[0][1]
    return text + "".join(f" {sign} {term}" for sign, term in terms[1:])


def _plant_text(recording: Recording) -> str:
    """The controlled element the diagnosis reads (``Recording.controlled_element``, the
    paper's 4/s^2 without one), as a transfer function with its denominator's leading
    coefficient 1 (so 4/(2 s^2) and 2/s^2 read alike)."""
    num, den = (np.trim_zeros(np.asarray(c, float), "f") for c in recording.controlled_element)
    if den.size == 0:  # (the reader refuses a zero denominator; said as it is)
        return f"{_polynomial_text(num)}/0"
    num, den = num / den[0], den / den[0]
    n, d = _polynomial_text(num), _polynomial_text(den)
    if num.size > 1:
        n = f"({n})"
    return n if d == "1" else f"{n}/({d})" if " " in d else f"{n}/{d}"


def _forcing_lines(recording: Recording) -> tuple | None:
    """The forcing the diagnosis reads (:func:`~bayespilot.diagnose.locate.forcing_of`): per
    forcing function the frequencies (rad/s) and amplitudes of its lines of nonzero
    amplitude, sorted by frequency; None without a forcing, or when it is read from f_t/f_d
    columns that are not whole periods of separate lines (their DFT smears each forcing over
    hundreds of lines, which depend on where the record was cut, not on the forcing)."""
    from .locate import forcing_of

    f = forcing_of(recording)
    if f is None or not (isinstance(recording.metadata.get("forcing"), Mapping) or f.periodic):
        return None
    out = []
    for m in (f.target, f.disturbance):
        live = np.asarray(m.amplitude) != 0
        w, a = np.asarray(m.frequencies)[live], np.abs(np.asarray(m.amplitude)[live])
        o = np.argsort(w)
        out.append((w[o], a[o]))
    return tuple(out)


def _same_forcing(x: tuple, y: tuple) -> bool:
    """Two :func:`_forcing_lines` alike: the same number of lines per forcing function, at
    the same frequencies within 1e-4 (relative) and amplitudes within 1e-3 of the largest."""
    top = max([float(np.max(a)) for w, a in (*x, *y) if a.size] or [0.0])
    return all(wx.size == wy.size and np.allclose(wx, wy, rtol=1e-4, atol=0.0)
               and np.allclose(ax, ay, rtol=0.0, atol=1e-3 * top)
               for (wx, ax), (wy, ay) in zip(x, y))


def _forcing_texts(recordings: Sequence[Recording]) -> list[str | None]:
    """Each run's forcing as :func:`pooling_disagreements` says it, the same text for runs of
    the same forcing (:func:`_same_forcing`) and different texts for different ones; None for
    a run without a forcing."""
    lines = [_forcing_lines(r) for r in recordings]
    kinds: list[tuple] = []  # one representative per forcing seen
    texts: list[str] = []
    out: list[str | None] = []
    for x in lines:
        if x is None:
            out.append(None)
            continue
        for k, y in enumerate(kinds):
            if _same_forcing(x, y):
                out.append(texts[k])
                break
        else:
            parts = []
            for name, (w, a) in zip(("target", "disturbance"), x):
                parts.append(f"{name} {w.size} lines {w.min():.3g}-{w.max():.3g} rad/s rms "
                             f"{math.sqrt(float(np.sum(a ** 2)) / 2):.3g}" if w.size
                             else f"no {name}")
            text = " + ".join(parts)
            if text in texts:  # (alike in this summary, yet not the same forcing)
                text += f" [{sum(t.startswith(text) for t in texts) + 1}]"
            kinds.append(x)
            texts.append(text)
            out.append(text)
    return out


@dataclass(eq=False)  # by identity: == on its arrays would be ambiguous
class PooledDiagnosisResult(_DiagnosisJSON):
    """What :func:`diagnose_pooled` found.

    Attributes
    ----------
    mismatch : bool
        True if an extension is justified at level ``alpha``.
    physics : str
        The chosen catalogue name, or ``"none"``.
    ranking : list of CandidateResult
        Every candidate, best first; ``params`` and ``stderr`` are the shared
        new parameters, ``delta_neg_log_lik`` is summed over the runs.
    runs : list of dict
        Per run: ``source``, ``base`` (Eq. 4 and GLS fits), ``where`` (located
        evidence), ``delta_neg_log_lik`` (each candidate's improvement in
        that run at the pooled fit), ``params`` (the run's pilot parameters
        under the chosen extension, if any), ``bootstrap`` (its located
        evidence's bootstrap, as a single run's ``settings["bootstrap"]``:
        ``replicates``, ``dropped``, ``diverged``, or ``skipped``), and when
        there are any, ``evidence_notes`` (the run's EvidenceWarnings) and
        ``base_at_bounds`` (its base fit's parameters on a bound, a
        BaseFitWarning; as a single run's ``settings["base_at_bounds"]``).
    where : dict
        Located statistics with Fisher-combined p-values over the runs: per
        key, ``p_value`` (NaN when a run has none) and ``values`` (each run's
        value), floats also after :meth:`from_dict`.
    chosen : CandidateResult or None
    settings : dict
    elapsed : float
        Wall time, s.
    arrays : dict
        Not in the JSON: ``noise`` (each run's noise model), ``base_model``,
        ``fits`` (each GLS candidate's pooled fit, the parameters per run),
        which :func:`~bayespilot.diagnose.shared_posterior` starts from, and
        ``final_fits`` (the chosen extension's refit after the test,
        :func:`pooled_final_fit`, the parameters per run; None without a
        refit), whose delta_abs it also reads.
    posterior : SharedPosterior or None
        Set by :func:`~bayespilot.diagnose.shared_posterior`.
    units : dict of str to str
        Each parameter's unit (``"-"``: dimensionless), by name, as
        :attr:`DiagnosisResult.units`; ``units`` in the JSON.
    """

    mismatch: bool
    physics: str
    ranking: list
    runs: list
    where: dict
    chosen: Any
    settings: dict
    elapsed: float
    arrays: dict = field(default_factory=dict, repr=False)
    posterior: Any = field(default=None, repr=False)
    units: dict = field(default_factory=dict, repr=False)

    def __repr__(self) -> str:
        """One line (the dataclass's would print every run's and candidate's numbers)."""
        return _short_repr(self, f"{len(self.runs or ())} runs pooled, "
                                 f"{len(self.ranking or ())} candidates")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: ``mismatch``, ``physics``, ``ranking``, ``where``, ``runs``, ... ."""
        runs = [dict(r, where={k: e.to_dict() for k, e in r["where"].items()})
                for r in self.runs]
        chosen = None if self.chosen is None else self.chosen.to_dict()
        return json_ready({"mismatch": self.mismatch, "physics": self.physics, "pooled": True,
                      "n_runs": len(self.runs),
                      "ranking": [c.to_dict() for c in self.ranking],
                      "where": self.where, "runs": runs, "chosen": chosen,
                      "posterior": None if self.posterior is None else self.posterior.to_dict(),
                      "settings": self.settings, "elapsed_seconds": self.elapsed,
                      "units": dict(self.units)})

    def summary(self) -> str:
        """A readable account: the decision, the ranking, each run's share."""
        R = len(self.runs)
        lines = [f"bayespilot diagnose, {R} runs pooled (shared extension, pilot per run)",
                 f"decision: {self.physics}" + (" (mismatch)" if self.mismatch else
                                                " (no extension justified)"),
                 f"level: alpha = {self.settings['alpha']:g} over "
                 f"{self.settings['n_tested']} candidates",
                 *([f"runs' base models refitted from the extensions' fits: pooled -ln L "
                    f"better by {sum(r['gain'] for r in self.settings['rebased']):.2f}; every "
                    f"test is against those fits"] if self.settings.get("rebased") else []),
                 "",
                 f"{'candidate':<24} {'d(-lnL)':>9} {'p':>9} {'dBIC':>9}  per run"
                 f"{'':<{max(0, 7 * R - 7)}}  shared params"]
        for c in self.ranking:
            if not c.testable:
                lines.append(f"{c.physics:<24} {'-':>9} {'-':>9} {'-':>9}  ({c.reason})")
                continue
            per = " ".join(f"{r['delta_neg_log_lik'].get(c.physics, math.nan):6.1f}"
                           for r in self.runs)
            ps = ", ".join(f"{k}={v:.4g}" for k, v in c.params.items())
            lines.append(f"{c.physics:<24} {c.delta_neg_log_lik:9.2f} {c.p_value:9.2g} "
                         f"{_bic(c):>9}  {per}  {ps}{'  *' if c.justified else ''}")
        lines += _calibration_lines(self.ranking)
        if self.chosen is not None and self.chosen.params:
            lines += ["", f"fitted {self.chosen.physics} (shared by the {R} runs):",
                      *_fitted_lines(self.chosen, self.units)]
            if self.posterior is not None:
                lines += self.posterior.summary_lines()
        lines += ["", "runs:"]
        for r in self.runs:
            lines.append(f"  {str(r['source']):<40} base VAF {r['base']['vaf']:6.2f} %, "
                         f"-ln L (Eq. 4) {r['base']['neg_log_lik']:.1f}")
            lines += [f"    {line}" for line in _at_bounds_lines(r.get("base_at_bounds"))]
            boot = r.get("bootstrap") or {}
            dropped = int(boot.get("dropped") or 0)
            if dropped and "skipped" not in boot:
                kept = int(boot.get("replicates") or 0)
                why = _dropped_why(dropped, int(boot.get("diverged") or 0))
                lines.append(f"    bootstrap: only {kept} of {kept + dropped} replicates "
                             f"survived ({why}): check the signs and units of u, e and "
                             f"control_gain")
        lines.append(f"time: {self.elapsed:.1f} s")
        return "\n".join(lines)

    __str__ = summary

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, source_file: str | None = None
                  ) -> "PooledDiagnosisResult":
        """The pooled diagnosis a :meth:`to_dict` holds, as far as a result file keeps it.

        Its ``summary()``, ``to_dict()``, numbers and :meth:`report` are the
        original's.  Not kept, so not here: the runs' noise models, the base
        model and the candidates' pooled fits (``arrays`` is empty; ``fit``,
        ``model`` and ``noise`` of each candidate are None), which
        :func:`~bayespilot.diagnose.shared_posterior` needs; a posterior
        computed before is kept (:class:`SharedPosterior`).

        Parameters
        ----------
        d : mapping
            A pooled diagnosis's :meth:`to_dict` (or its JSON, parsed).
        source_file : str, optional
            Where ``d`` was read from, for messages.

        Returns
        -------
        PooledDiagnosisResult

        Raises
        ------
        ValueError
            ``d`` is not a diagnosis's, or is a single run's
            (:meth:`DiagnosisResult.from_dict`), or lacks ``mismatch`` or a
            run's ``base`` or ``where`` (the message names it).
        """
        from .locate import Evidence
        from .posterior import SharedPosterior

        ranking, chosen = _ranking_and_chosen(d, True, source_file)
        runs = []
        for i, r in enumerate(d.get("runs", ()), start=1):
            lost = [k for k in ("base", "where") if k not in r]
            if lost:  # (a KeyError below without this)
                raise ValueError(f"{source_file + ' holds' if source_file else 'this dict is'} "
                                 f"not a complete pooled diagnosis result: run {i} has no "
                                 f"{' and '.join(lost)}")
            run = dict(r, base=_base_from(r["base"]),
                       where={k: Evidence.from_dict(e) for k, e in r["where"].items()},
                       delta_neg_log_lik=numbers(r.get("delta_neg_log_lik")))
            if r.get("params") is not None:
                run["params"] = numbers(r["params"])
            runs.append(run)
        # the combined statistics as diagnose_pooled made them: NaN, not None, for a p-value
        # or value the file has as null (an unbootstrapped run), so that comparisons such
        # as where[k]["p_value"] < 0.05 work on a result read back
        where = {k: dict(v, p_value=number(v.get("p_value")),
                         values=[number(x) for x in v.get("values", ())])
                 for k, v in d["where"].items()}
        post = d.get("posterior")
        return cls(bool(d["mismatch"]), d["physics"], ranking, runs, where, chosen,
                   dict(d.get("settings") or {}), number(d.get("elapsed_seconds", 0.0)),
                   posterior=None if post is None else SharedPosterior.from_dict(post),
                   units=dict(d.get("units") or {}))

    def report(self, directory: str | Path, *, formats: Sequence[str] = ("png",),
               title: bool = True) -> dict[str, Path]:
        """Write ``candidates.png``, ``runs.png``, ``diagnosis.json`` and ``report.html``
        (and ``posterior.png`` once :func:`~bayespilot.diagnose.shared_posterior` has run).

        Parameters
        ----------
        directory : str or Path
            Created, with its parents, if missing; files of the same names in
            it are replaced.  A figure file an earlier report wrote there and
            this one does not is removed; any other file is left, also one of a
            figure's name (see ``manifest``).
        formats : sequence of str, optional
            Also write each figure in these formats beside its PNG (``"pdf"``,
            ``"svg"``), as :meth:`DiagnosisResult.report` does.
        title : bool, optional
            True (default): each figure with its own title; False: the figures
            without titles (``title=False`` of :func:`plot_runs` and of the
            report's plot functions), for a paper whose captions say it; the
            page's headings and captions stay.

        Returns
        -------
        dict of str to Path
            The files by name: ``candidates``, ``runs``, ``posterior`` (when
            set), each figure's other formats as ``<name>_pdf`` and
            ``<name>_svg``, ``json``, ``html`` and ``manifest``
            (:data:`~bayespilot.diagnose.report.MANIFEST`, the hidden list of
            the figure files written, as :meth:`DiagnosisResult.report`
            writes it).

        Raises
        ------
        OSError
            ``directory`` cannot be created or a file in it written.
        ValueError
            ``formats`` names one that is not ``"png"``, ``"pdf"`` or ``"svg"``.
        TypeError
            ``title`` is not True or False.
        """
        from .report import (_checked_formats, _whole_report, plot_candidates,
                             plot_shared_posterior)

        formats = _checked_formats(formats)
        if not isinstance(title, (bool, np.bool_)):  # (before anything is written)
            raise TypeError(f"title must be True or False, got {title!r}")
        t = bool(title)
        out = Path(directory)
        out.mkdir(parents=True, exist_ok=True)
        figures = {"candidates": lambda: plot_candidates(self, title=t),
                   "runs": lambda: plot_runs(self, title=t),
                   "posterior": None if self.posterior is None
                   else (lambda: plot_shared_posterior(self.posterior, title=t))}
        # (a failure part-way leaves no page or diagnosis.json of an earlier report beside
        # the new figures: _whole_report, as the single-run report)
        with _whole_report(out) as written:
            return self._write_report_files(out, figures, formats, written)

    def _write_report_files(self, out: Path, figures: Mapping[str, Any],
                            formats: Sequence[str], written: set[str]) -> dict[str, Path]:
        """The files of :meth:`report`, each name added to ``written`` once written."""
        import html

        from .report import (_STYLE, _candidate_table, _img, _listed, _notes_html,
                             _write_figures, _yes_no)

        paths = _write_figures(_listed(figures), out, formats)  # (names in report.FIGURES)
        paths["json"] = out / "diagnosis.json"
        self.to_json(paths["json"])
        written.add(paths["json"].name)

        title = f"bayespilot pooled diagnosis: {html.escape(self.physics)}"
        page = (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
                f"<title>{title}</title><style>{_STYLE}</style></head><body><h1>{title}</h1>"
                f"<p>{len(self.runs)} runs; extension parameters shared, pilot parameters per "
                f"run. Mismatch: <b>{_yes_no(self.mismatch)}</b>. Decision at family-wise "
                f"level alpha = {self.settings['alpha']:g} "
                f"({self.settings['level_per_candidate']:.2g} per candidate).</p>"
                + _notes_html([(str(r.get("source") or f"run {j + 1}"), n)
                               for j, r in enumerate(self.runs)
                               for n in r.get("evidence_notes", ())]) +
                f"<h2>Candidates (pooled)</h2>{_candidate_table(self.ranking, self.units)}"
                + _img(paths["candidates"],
                       "Improvement of the pooled decision likelihood (summed over the runs) by "
                       "each candidate with its parameters shared; the black mark is what its "
                       "test needs, the p-values are at the right.") +
                "<h2>Each run's share</h2>"
                + _img(paths["runs"],
                       "Each run's improvement at the pooled fit: a real omission improves "
                       "every run, one run's artefact only that run.") +
                (("<h2>Posterior of the shared parameters</h2>"
                  + _img(paths["posterior"],
                         "Marginal posterior of each shared parameter (grid, Laplace over the "
                         "runs' own parameters) with the pooled fit, its standard error and "
                         "the central 90 % interval."))
                 if "posterior" in paths else "") +
                f"<pre>{html.escape(self.summary())}</pre></body></html>\n")
        paths["html"] = out / "report.html"
        write_text_atomic(paths["html"], page)
        written.add(paths["html"].name)
        return paths


def plot_runs(result: PooledDiagnosisResult, ax: Any = None, *, title: bool | str = True,
              figsize: tuple[float, float] | None = None):
    """Each run's improvement of -ln L per candidate at the pooled fit (grouped bars).

    A real omission improves every run a little; one run's artefact improves one run.

    Parameters
    ----------
    result : PooledDiagnosisResult
        A pooled diagnosis (:func:`diagnose_pooled`).
    ax : matplotlib Axes, optional
        Default: a new figure (constrained layout, a page, 7.5 in, wide at
        most); given axes' figure is left as it is.
    title : bool or str, optional
        True (default): "Each run's share (decision: <extension>)"; False:
        none, the axes taking its room (for a paper, whose caption says
        it); a str: that text.  The convention of every plot function
        (:mod:`bayespilot.plots`).
    figsize : (float, float), optional
        Width and height (in) of a new figure, as given (default 7.5 x 4);
        not with ``ax``.  Narrower than 5 in (a column), the runs' legend
        goes under the axes instead of beside them.

    Returns
    -------
    matplotlib.figure.Figure
        The runs named by their source's file stem (``run j`` without one),
        in a legend titled "run", each run's bars hatched differently as
        well as coloured (told apart in greyscale).

    Raises
    ------
    TypeError
        ``title`` is not True, False or a str.
    ValueError
        ``figsize`` given with ``ax``, or not two positive numbers.
    """
    from ..plots import _title_text
    from .report import PAGE_WIDTH, _figure_and_axes, _label_axes, _legend_under

    text = _title_text(title, f"Each run's share (decision: {result.physics})")
    # each run's name: its source's file stem (recs/s1_run2.csv -> s1_run2), "run j" without
    # one; a name two runs share gets its run number
    names = []
    for j, r in enumerate(result.runs):
        src = r.get("source")
        names.append((Path(str(src)).stem or str(src)) if src else f"run {j + 1}")
    names = [f"{n} (run {j + 1})" if names.count(n) > 1 else n for j, n in enumerate(names)]
    fig, ax = _figure_and_axes(ax, figsize=(PAGE_WIDTH, 4), given=figsize)
    rows = [c for c in result.ranking if c.testable]
    R = len(result.runs)
    width = 0.8 / max(R, 1)
    top = 0.0
    for j, (r, name) in enumerate(zip(result.runs, names)):
        d = [r["delta_neg_log_lik"].get(c.physics, math.nan) for c in rows]
        top = max(top, float(np.nanmax(np.abs(d), initial=0.0)))
        ax.barh(np.arange(len(rows)) + (j - (R - 1) / 2) * width, d, height=width, label=name,
                hatch=RUN_HATCHES[j % len(RUN_HATCHES)], edgecolor="w", linewidth=0)
    ax.axvline(0.0, color="k", lw=0.8)
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels([c.physics for c in rows], fontsize="small")
    ax.set_ylim(len(rows) - 0.5, -0.5)
    if top > 50:  # a censored fit's large gain beside the GLS candidates' few units
        ax.set_xscale("symlog", linthresh=1.0)
    ax.grid(True, axis="x", alpha=0.3)
    ax.set_axisbelow(True)
    ax.set_xlabel(r"$\Delta(-\ln L)$ of each run at the pooled fit: "
                  r"$-\ln L_\mathrm{base} - (-\ln L_\mathrm{pooled\ extension})$")
    if fig.get_figwidth() < 5.0:
        # a column's width: the title and x label wrapped to the axes' room, the runs' legend
        # under them (beside them, the names left the bars no room)
        _label_axes(ax, text, ax.get_xlabel())
        _legend_under(ax, title="run")
    else:
        if text:
            ax.set_title(text, fontsize="medium")
        ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0), title="run",
                  title_fontsize="small")
    return fig


#: The hatching of each run's bars in :func:`plot_runs` (cycled), beside the colour cycle's.
RUN_HATCHES = ("", "///", "...", "xxx", "\\\\\\", "+++", "oo", "---")


def _refuse_repeats(recs: Sequence[Recording]) -> None:
    """Refuse a run given twice: pooling it would count its evidence twice (a path and the same
    file's .csv, or a copy, are the same run; what is compared is the signals)."""
    from ..recording import _signals_digest

    seen: dict[str, int] = {}
    for j, rec in enumerate(recs):
        key = _signals_digest(rec)
        if key in seen:
            i = seen[key]
            raise ValueError(f"runs {i + 1} and {j + 1} ({recs[i].source or 'run ' + str(i + 1)}, "
                             f"{rec.source or 'run ' + str(j + 1)}) are the same recording: "
                             "pooling it twice would count its evidence twice")
        seen[key] = j


def _pooled_refine(wls, bases, names, shared, start_shared, *, max_nfev: int = 60):
    """Least squares on the stacked whitened residuals: ``names`` per run, ``shared`` common.

    Each run's residual is scaled by its GLS noise level at the start, which
    makes the stacked sum of squares the pooled likelihood to first order; a
    second pass re-scales at the first pass's solution.  (scipy's least
    squares cannot minimise a sum of logs directly; two passes of this
    iteratively re-weighted form reach it to well under 0.1 in -ln L.)
    Returns ``(params per run, pooled -ln L, covariance of the shared parameters)``.
    """
    model = wls[0].model
    R, p, k = len(wls), len(names), len(shared)
    lo1 = np.array([model.parameter(n).lower for n in names])
    hi1 = np.array([model.parameter(n).upper for n in names])
    los = np.array([model.parameter(n).lower for n in shared])
    his = np.array([model.parameter(n).upper for n in shared])
    lo = np.concatenate([np.tile(lo1, R), los])
    hi = np.concatenate([np.tile(hi1, R), his])
    full = [dict(model.as_dict(model.free_vector(dict(b.params, **start_shared))))
            for b in bases]

    def params_of(x):
        out = []
        for r in range(R):
            q = dict(full[r])
            q.update(zip(names, (float(v) for v in x[r * p:(r + 1) * p])))
            q.update(zip(shared, (float(v) for v in x[R * p:])))
            out.append(q)
        return out

    def run_resid(r, q):
        y = wls[r].lik.response(q)
        if not np.all(np.isfinite(y)):
            return None
        return wls[r].whiten(wls[r].u - y)

    def total(ps):
        return float(sum(wl.neg_log_lik(q) for wl, q in zip(wls, ps)))

    x = np.concatenate([np.concatenate([[full[r][n] for n in names] for r in range(R)]),
                        [full[0][n] for n in shared]])
    span = hi - lo
    x = np.clip(x, lo + 1e-9 * span, hi - 1e-9 * span)
    x_start = x.copy()
    f_start = total(params_of(x_start))
    J = None
    def scales(ps):
        """Each run's 1 / (GLS noise level) at ``ps`` (1 where its response is not finite)."""
        out = []
        for r in range(R):
            w = run_resid(r, ps[r])
            out.append(1.0 / math.sqrt(max(float(np.mean(w * w)), 1e-300)) if w is not None
                       else 1.0)
        return out

    for _pass in range(2):
        scale = scales(params_of(x))
        big = [1e3 * float(np.std(wl.u)) * s + 1e-300 for wl, s in zip(wls, scale)]

        def resid(x, scale=scale, big=big):
            qs = params_of(x)
            parts = []
            for r in range(R):
                w = run_resid(r, qs[r])
                parts.append(np.full(wls[r].m, big[r]) if w is None else w * scale[r])
            return np.concatenate(parts)

        def jac(x, scale=scale):
            qs = params_of(x)
            blocks = np.zeros((sum(wl.m for wl in wls), R * p + k))
            row = 0
            for r in range(R):
                _, Jr = wls[r].lik.jacobian(qs[r], tuple(names) + tuple(shared))
                m = wls[r].m
                if np.all(np.isfinite(Jr)):
                    Jw = -wls[r].whiten(Jr) * scale[r]
                    blocks[row:row + m, r * p:(r + 1) * p] = Jw[:, :p]
                    blocks[row:row + m, R * p:] = Jw[:, p:]
                row += m
            return blocks

        sol = optimize.least_squares(resid, x, jac=jac, bounds=(lo, hi), method="trf",
                                     x_scale="jac", max_nfev=max_nfev, xtol=1e-8, ftol=1e-9)
        x = sol.x
        J = sol.jac
    ps = params_of(x)
    f = total(ps)
    if not math.isfinite(f) or f > f_start:
        ps, f = params_of(x_start), f_start
        # the covariance of the point reported (each run scaled by its noise level there),
        # not of the solution thrown away
        J = jac(x_start, scale=scales(ps))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cov = linalg.pinvh(J.T @ J) if J is not None else np.full((R * p + k,) * 2, np.nan)
    return ps, f, cov[R * p:, R * p:]


def pooled_final_fit(ext: Any, base_model: Any, recordings: Sequence, params: Sequence[dict],
                     noises: Sequence, *, rounds: int = 3) -> tuple[list, float, np.ndarray, list]:
    """The pooled counterpart of :func:`bayespilot.diagnose.decide.final_fit`: the chosen
    extension refitted to all runs with each run's own noise model and delta_abs.

    ``rounds`` times: each run's AR noise model is estimated again from the
    extended model's residual there (same low-pass and decimation), the pooled
    model (pilot parameters per run, the extension's shared) is refitted under
    them, and each run's delta_abs is scanned again with the shared parameters
    held (:func:`~bayespilot.diagnose.decide.scan_threshold`), the pooled fit
    repeated until no scan moves it.

    Parameters
    ----------
    ext, base_model
        As for :func:`~bayespilot.diagnose.decide.final_fit`.
    recordings : sequence of Recording
        The pooled runs.
    params : sequence of dict
        The extended model's parameters per run at the test's fit.
    noises : sequence of NoiseModel
        The runs' decision noise models (their low-pass, decimation and skip
        are kept).
    rounds : int
        How often the noise models are estimated again.

    Returns
    -------
    params : list of dict
        The extended model's parameters per run (the shared ones equal).
    neg_log_lik : float
        The pooled -ln L under the new noise models.
    cov : ndarray
        Covariance of the shared parameters under them (too sharp on repeated
        closed-loop runs: ``diagnose_pooled`` reports the test's).
    noises : list of NoiseModel
        The runs' last noise models.
    """
    from . import decide as D

    if not (isinstance(rounds, (int, np.integer)) and rounds >= 1):
        raise ValueError(f"rounds must be an integer >= 1, got {rounds!r}")
    if not len(recordings) == len(params) == len(noises) >= 2:
        raise ValueError(f"need one parameter set and one noise model per recording, two "
                         f"recordings or more; got {len(recordings)} recordings, "
                         f"{len(params)} parameter sets, {len(noises)} noise models")
    if not isinstance(ext, Extension) or ext.likelihood != "gls":
        raise ValueError(f"ext must be a catalogue Extension fitted by GLS, got {ext!r}")
    model = ext.build(base_model)
    shared = tuple(ext.new_parameters)
    names = tuple(n for n in model.parameter_names if n not in shared
                  and (ext.refine_threshold or n != "delta_abs"))
    ps, noises = [dict(q) for q in params], list(noises)
    f, cov = math.nan, np.full((len(shared),) * 2, np.nan)
    for _ in range(rounds):
        noises = [D.own_noise(model, rec, q, nz) for rec, q, nz in zip(recordings, ps, noises)]
        wls = [D.Whitened(model, rec, nz) for rec, nz in zip(recordings, noises)]
        for scans in range(5):
            starts = [D.FitSummary(q, math.nan, (), np.zeros((0, 0))) for q in ps]
            ps, f, cov = _pooled_refine(wls, starts, names, shared,
                                        {n: ps[0][n] for n in shared})
            if ext.refine_threshold or scans == 4:
                break
            moved = False
            for r, wl in enumerate(wls):
                got = D.scan_threshold(wl, D.FitSummary(ps[r], wl.neg_log_lik(ps[r]), names,
                                                        np.zeros((0, 0))), names)
                if got.params["delta_abs"] != ps[r]["delta_abs"]:
                    ps[r], moved = dict(got.params), True
            if not moved:
                break
    return ps, f, cov, noises


def _refined_base(runs, recordings):
    """The base model refitted to every run with delta_abs refined too (no shared parameters).

    The threshold-shape entry refines each run's delta_abs continuously, where
    the base fit only scanned it on a grid (5e-4 IPUT): over several runs that
    freedom alone improved the controls' pooled -ln L by about 1 (4.6 in one
    control of the proof study, where a run's scan had picked another local
    minimum), so its test was anti-conservative (a third of 48 pooled controls
    had p < 0.05).  Its reference is therefore the base model with the same
    freedom.  Returns ``(pooled -ln L, base parameters per run)``.
    """
    from . import decide as D

    model = runs[0].base_model
    wls = [D.Whitened(model, rec, run.noise) for rec, run in zip(recordings, runs)]
    ps, f, _ = _pooled_refine(wls, [r.base for r in runs], model.parameter_names, (), {})
    return f, ps


def _pooled_candidate(ext, runs, recordings, refined_base=None, guide=None):
    """Fit one GLS extension to all runs (shared new parameters) and test it.

    ``refined_base``: ``(pooled -ln L, parameters per run)`` of the base model
    with delta_abs refined (:func:`_refined_base`), the reference for an
    entry that refines delta_abs.  ``guide``: the extended model's parameters
    per run from its pooled fit on the low-passed band (:func:`_pooled_guide`),
    one more start.
    """
    from . import decide as D

    missing = sorted({c for rec in recordings for c in ext.needs if c not in rec})
    if missing:
        return D.CandidateResult(ext.name, False, f"needs the recording column(s) "
                                 f"{', '.join(missing)} in every run", df=ext.df), None
    model = ext.build(runs[0].base_model)
    wls = [D.Whitened(model, rec, run.noise) for rec, run in zip(recordings, runs)]
    names = tuple(n for n in model.parameter_names if n not in ext.new_parameters
                  and (ext.refine_threshold or n != "delta_abs"))
    base_total = float(sum(r.base.neg_log_lik for r in runs))
    starts = [r.base for r in runs]
    if ext.refine_threshold and refined_base is not None and refined_base[0] < base_total:
        base_total = refined_base[0]
        starts = [D.FitSummary(dict(q), math.nan, (), np.zeros((0, 0))) for q in refined_base[1]]
    best = None
    for st in ext.starts or ({},):
        try:
            got = _pooled_refine(wls, starts, names, ext.new_parameters, st)
        except (ValueError, np.linalg.LinAlgError):
            continue
        if best is None or got[1] < best[1]:
            best = got
    if guide is not None:
        try:
            got = _pooled_refine(wls, [D.FitSummary(dict(q), math.nan, (), np.zeros((0, 0)))
                                       for q in guide], names, ext.new_parameters,
                                 {n: guide[0][n] for n in ext.new_parameters})
        except (ValueError, np.linalg.LinAlgError):
            got = None
        if got is not None and (best is None or got[1] < best[1]):
            best = got
    if best is None:
        return D.CandidateResult(ext.name, False, "the pooled fit failed from every start",
                                 df=ext.df), None
    ps, f, cov = best
    se = np.sqrt(np.clip(np.diag(cov), 0, None))
    verdict = D.lr_verdict(ext, max(0.0, base_total - f), sum(wl.m for wl in wls),
                           test=f"pooled GLS likelihood-ratio test over {len(runs)} runs")
    res = verdict.result(ext.name, {n: ps[0][n] for n in ext.new_parameters},
                         {n: float(s) for n, s in zip(ext.new_parameters, se)}, {})
    res.model = model
    res.fit = D.FitSummary({}, f, (), np.zeros((0, 0)))  # the pooled -ln L, for a later retest
    if starts[0] is runs[0].base:
        ref = [r.base.neg_log_lik for r in runs]
    else:
        ref = [D.Whitened(runs[0].base_model, rec, r.noise).neg_log_lik(b.params)
               for rec, r, b in zip(recordings, runs, starts)]
    own = [float(wl.neg_log_lik(q)) for wl, q in zip(wls, ps)]
    per_run = [float(f0 - g) for f0, g in zip(ref, own)]
    return res, (ps, per_run, own)


def _pooled_saturation(recordings, runs):
    """Pool the runs' flat-top tests: exact repeats in any run decide; else Fisher's method."""
    from . import decide as D

    ext = get_extension("control-saturation")
    each = [_saturation(rec, run.base_model, run.base, run.where, run.boot_info)
            for rec, run in zip(recordings, runs)]
    per_run = [float(c.delta_neg_log_lik) for c in each]
    if not any(c.params for c in each):
        return D.CandidateResult(ext.name, True, "no flat tops in u in any run", df=0,
                                 p_value=1.0), per_run
    ps = [c.p_value for c in each]
    p = 0.0 if min(ps) == 0.0 else float(stats.combine_pvalues(ps, method="fisher")[1])
    d = float(sum(per_run))
    withtops = [c for c in each if c.params]
    params = {"u_max": max(c.params["u_max"] for c in withtops),
              "u_min": min(c.params["u_min"] for c in withtops),
              "n_censored": float(sum(c.params["n_censored"] for c in withtops))}
    how = (f"flat tops in {len(withtops)} of {len(each)} runs; "
           + ("exact repeats have probability 0 under a continuous-noise model" if p == 0.0
              else "Fisher's combination of the runs' flat-top p-values"))
    res = D.CandidateResult(ext.name, True, how, d, params["n_censored"], 0, p,
                            math.inf if p == 0.0 else 2.0 * d, math.inf if p == 0.0 else d,
                            params, {}, {})
    res.model = withtops[0].model  # (the extended model, for its parameters' units)
    return res, per_run


def _pooled_guide(names, runs, recs):
    """Each extension's pooled fit on the band low-passed at ``decide.OMEGA_C``: starts for a
    wider band (the pooled counterpart of :func:`bayespilot.diagnose.decide.guide_fits`).

    Every run gets its own noise model and GLS base fit on the low band, then
    each GLS extension is fitted to all runs there.  Returns name -> the
    extended model's parameters per run.
    """
    import dataclasses

    from . import decide as D

    low = []
    for rec, run in zip(recs, runs):
        start = {k: v for k, v in run.base_fit.params.items()
                 if k in run.base_model.parameter_names}
        noise, base = D.low_band_base(run.base_model, rec, start, run.skip)
        low.append(dataclasses.replace(run, noise=noise, base=base))
    out: dict[str, list[dict[str, float]]] = {}
    refined = None
    for name in names:
        ext = get_extension(name)
        if ext.likelihood != "gls":
            continue
        if ext.refine_threshold and refined is None:
            refined = _refined_base(low, recs)
        _, extra = _pooled_candidate(ext, low, recs, refined)
        if extra is not None:
            out[name] = [dict(q) for q in extra[0]]
    return out


def _pooled_candidates(names, runs, recs, where, bar, guide=None):
    """Fit and test every candidate on all runs from the runs' GLS base fits.

    Returns ``(results, shares, fits, own, refined)``: the candidate results,
    each candidate's per-run improvement, its per-run parameters and -ln L,
    and the delta_abs-refined reference (or None).
    """
    results, shares, fits, own = [], {}, {}, {}
    refined = None
    for name in names:
        ext = get_extension(name)
        bar.set_postfix_str(name)
        if ext.likelihood == "censored":
            res, shares[name] = _pooled_saturation(recs, runs)
        else:
            if ext.refine_threshold and refined is None:
                refined = _refined_base(runs, recs)
            res, extra = _pooled_candidate(ext, runs, recs, refined,
                                           guide.get(name) if guide else None)
            if extra is not None:
                fits[name], shares[name], own[name] = extra
        sig = [where[k]["p_value"] for k in ext.signature_keys
               if k in where and math.isfinite(where[k]["p_value"])]
        res.signature_score = float(max([-math.log10(max(p, 1e-300)) for p in sig],
                                        default=0.0))
        results.append(res)
        bar.update(1)
    return results, shares, fits, own, refined


def _pooled_null(names, fits, runs, recs):
    """Per run, the best base-model fit: its GLS base fit or one reached from a candidate's fit.

    The pooled counterpart of :func:`bayespilot.diagnose.decide.null_refit`:
    each run's base model is refitted from each candidate's parameters for
    that run (the candidate's new parameters dropped); under the base model
    the runs are independent, so each run keeps its own best.
    """
    from . import decide as D

    model = runs[0].base_model
    best = [r.base for r in runs]
    for name in names:
        ext = get_extension(name)
        if name not in fits or ext.likelihood != "gls":
            continue
        for j, (rec, run, q) in enumerate(zip(recs, runs, fits[name])):
            got = D.null_refit_from(ext, model, rec, q, run.noise)
            if got is not None and got.neg_log_lik < best[j].neg_log_lik:
                best[j] = got
    return best


@one_blas_thread
def diagnose_pooled(recordings: Sequence, *, seed: int | None = 0, alpha: float = ALPHA,
                    n_bootstrap: int = 39,
                    candidates: Sequence[str | Extension] | None = None,
                    skip_seconds: float = SKIP_SECONDS, omega_c: float | None = None,
                    n_starts: int = 4, oversample: int = 1, n_calibrate: int = N_CALIBRATE,
                    noise_passes: int = 1, refit: bool = True,
                    progress: bool = False) -> PooledDiagnosisResult:
    """Diagnose several runs of one condition together (see the module docs).

    Parameters
    ----------
    recordings : sequence of Recording
        Two or more runs of the same task and condition (one subject).  Each
        keeps its own pilot parameters; the extension's parameters are shared.
    seed : int or None
        Seeds each run's base fit and bootstrap (run j uses ``seed + j``, so
        the runs' order is part of the seed: the same runs in another order
        draw other bootstrap replicates; and two calls whose seeds differ by
        less than the number of runs share streams: run j + 1 of ``seed``
        draws what run j of ``seed + 1`` draws, so repeat a pooled
        diagnosis with a seed at least the number of runs away).  None draws one from fresh
        entropy, recorded in ``settings["seed"]``.
    alpha, n_bootstrap, candidates, skip_seconds, omega_c, n_starts, oversample
        As for :func:`~bayespilot.diagnose.diagnose` (``candidates``: catalogue
        names or entries, an entry of one's own registered; default the
        built-in catalogue, then the registered entries).  With ``omega_c`` above
        25 rad/s every extension is also started from its pooled fit on the
        25-rad/s band (:func:`_pooled_guide`).
    n_calibrate : int
        As for :func:`~bayespilot.diagnose.diagnose`: each replicate simulates
        every run's base model and refits the candidate to all of them, so it
        costs about R times a single run's.
    noise_passes : int
        As for :func:`~bayespilot.diagnose.diagnose`, for every run.
    refit : bool
        Report the chosen extension's estimates from a pooled fit made after
        the test with each run's own noise model and delta_abs
        (:func:`pooled_final_fit`), with the test's standard errors, as
        :func:`~bayespilot.diagnose.diagnose` does for one run; the test's fit
        stays in ``chosen.refit`` and in ``arrays["fits"]``, and
        :func:`~bayespilot.diagnose.shared_posterior` (under the decision
        likelihood) starts from it.
    progress : bool
        As for :func:`~bayespilot.diagnose.diagnose`.

    Returns
    -------
    PooledDiagnosisResult

    Raises
    ------
    TypeError
        One of ``recordings`` is not a Recording.
    ValueError
        Fewer than two recordings, one recording given twice (the same
        signals, under whatever path), or a bad setting (named; as for
        :func:`~bayespilot.diagnose.diagnose`, ``omega_c`` among them).

    Warns
    -----
    PoolingWarning
        The recordings give different subjects, tasks or K_theta, or differ in
        the task the diagnosis reads (sample rate, controlled element,
        control_gain, forcing functions; :func:`pooling_disagreements`).
    EvidenceWarning
        Per run, as for :func:`~bayespilot.diagnose.diagnose` (kept in that
        run's ``runs[j]["evidence_notes"]``); with ``n_calibrate > 0`` and a
        run whose task cannot be simulated, the calibration is skipped.
    BaseFitWarning
        Per run whose base fit has a pilot parameter on a bound, as for
        :func:`~bayespilot.diagnose.diagnose` (the parameters in that run's
        ``runs[j]["base_at_bounds"]``, the summary's line under the run).
    """
    from tqdm.auto import tqdm

    from . import decide as D

    recs = list(recordings)
    if len(recs) < 2:
        raise ValueError(f"pooling needs at least two recordings, got {len(recs)}")
    names = None
    for rec in recs:
        names = _check(rec, alpha, n_bootstrap, skip_seconds, candidates, oversample,
                       n_calibrate, noise_passes, omega_c)
    _refuse_repeats(recs)
    seed = resolve_seed(seed)  # None: a fresh one, recorded in the settings
    mixed = pooling_disagreements(recs)
    if mixed:
        warn_at_caller(f"the runs are not of one subject and condition ({mixed}); pooling "
                       "assumes the physics left out is the same in every run", PoolingWarning)
    t0 = time.perf_counter()
    bar = tqdm(total=2 * len(recs) + len(names), desc="diagnose (pooled)", unit="stage",
               disable=not progress)
    try:
        runs = [_prepare(rec, seed=seed + j, n_bootstrap=n_bootstrap,
                         base_fit=None, skip_seconds=skip_seconds, omega_c=omega_c,
                         n_starts=n_starts, profile_noise=False, bar=bar, oversample=oversample,
                         noise_passes=noise_passes)
                for j, rec in enumerate(recs)]
        keys = sorted(set.intersection(*(set(r.where) for r in runs)))
        where = {}
        for k in keys:
            ps = [r.where[k].p_value for r in runs]
            ok = [min(max(q, 1e-300), 1.0) for q in ps if math.isfinite(q)]
            where[k] = {"p_value": float(stats.combine_pvalues(ok, method="fisher")[1])
                        if len(ok) == len(ps) and ok else math.nan,
                        "values": [r.where[k].value for r in runs]}
        guide = None
        if runs[0].noise.omega_c > D.OMEGA_C:
            # a wider band than the default: start each extension from its low-band fit too
            bar.set_postfix_str(f"low-band fits (omega_c = {D.OMEGA_C:g} rad/s)")
            guide = _pooled_guide(names, runs, recs)
        rebased = []
        kept: dict[str, Any] = {}  # each candidate's best pooled fit over the rounds
        fits, shares, own = {}, {}, {}
        for _ in range(MAX_REBASE + 1):
            results, sh, fi, ow, refined = _pooled_candidates(names, runs, recs, where, bar, guide)
            for r in results:
                old = kept.get(r.physics)
                if (old is None or r.fit is None or old.fit is None
                        or r.fit.neg_log_lik <= old.fit.neg_log_lik):
                    kept[r.physics] = r
                    for store, new in ((fits, fi), (shares, sh), (own, ow)):
                        if r.physics in new:
                            store[r.physics] = new[r.physics]
            better = _pooled_null(names, fits, runs, recs)
            gain = float(sum(r.base.neg_log_lik - b.neg_log_lik for r, b in zip(runs, better)))
            if not gain > 0:
                break
            for run, b in zip(runs, better):
                run.base = b
            if gain <= REBASE_TOL or len(rebased) == MAX_REBASE:
                rebased.append({"gain": gain, "refitted": False})
                break
            # a better basin of the base model in some run: every extension again from there
            rebased.append({"gain": gain, "refitted": True})
            bar.total += len(names)  # every extension once more
            bar.refresh()
        results = [kept[n] for n in names]
        if rebased:
            # every test against the runs' best base fits found (threshold-shape: or the refined)
            ref = float(sum(r.base.neg_log_lik for r in runs))
            for r in results:
                ext = get_extension(r.physics)
                if ext.refine_threshold and refined is not None and refined[0] < ref:
                    D.retest(r, ext, refined[0])  # per-run shares stay against the refined base
                    continue
                D.retest(r, ext, ref)
                if r.physics in own:
                    shares[r.physics] = [float(run.base.neg_log_lik - g)
                                         for run, g in zip(runs, own[r.physics])]
        calibrate = (_calibrator(runs, recs, n_calibrate, seed, bar, n_starts) if n_calibrate > 0
                     else None)
        ranking, chosen, tested, level = _calibrated_decision(results, alpha, calibrate)
        final = None
        t_refit = time.perf_counter()
        if refit and chosen is not None and chosen.physics in fits:
            bar.total += 1  # the pooled refit: seconds, the bar still open
            bar.set_postfix_str(f"refit of {chosen.physics}")
            ext = get_extension(chosen.physics)
            ps, f, cov, own = pooled_final_fit(ext, runs[0].base_model, recs, fits[chosen.physics],
                                               [run.noise for run in runs])
            final = ps
            se = np.sqrt(np.clip(np.diag(cov), 0, None))
            # the estimates are reported, the standard errors stay the test's (as for one run)
            chosen.record_refit(ps[0], dict(zip(ext.new_parameters, se)), own, POOLED_FINAL_FIT,
                                [[q.get("delta_abs") for q in fits[chosen.physics]],
                                 [q.get("delta_abs") for q in ps]], neg_log_lik=float(f))
            bar.update(1)
    finally:
        bar.close()
    t_refit = time.perf_counter() - t_refit
    run_d = []
    for j, (rec, run) in enumerate(zip(recs, runs)):
        chosen_params = None
        if final is not None:
            chosen_params = final[j]
        elif chosen is not None and chosen.physics in fits:
            chosen_params = fits[chosen.physics][j]
        run_d.append({"source": rec.source,
                      "base": {"params": dict(run.base_fit.params),
                               "neg_log_lik": float(run.base_fit.neg_log_lik),
                               "vaf": float(run.base_fit.vaf),
                               "gls_params": dict(run.base.params),
                               "gls_neg_log_lik": float(run.base.neg_log_lik),
                               **_base_samples(run.base_fit, rec)},
                      "where": run.where,
                      "delta_neg_log_lik": {n: s[j] for n, s in shares.items()},
                      "params": chosen_params,
                      "bootstrap": dict(run.boot_info),
                      **({"evidence_notes": list(run.notes)} if run.notes else {}),
                      # (the BaseFitWarning's parameters, as a single run's settings keep them)
                      **({"base_at_bounds": [dict(d) for d in run.base_at_bounds]}
                         if run.base_at_bounds else {})})
    settings = {"alpha": alpha, "level_per_candidate": level, "n_tested": len(tested),
                "seed": seed, "n_bootstrap": n_bootstrap, "n_calibrate": n_calibrate,
                "noise_passes": noise_passes, "refit": refit, "refit_seconds": t_refit,
                "skip_seconds": skip_seconds,
                "candidates": list(names), "n_runs": len(recs), "rebased": rebased,
                "decision_likelihood": "sum over runs of the GLS likelihood (each run's own AR "
                                       "noise model and level); extension parameters shared"}
    return PooledDiagnosisResult(chosen is not None, chosen.physics if chosen else "none",
                                 ranking, run_d, where, chosen, settings,
                                 time.perf_counter() - t0,
                                 {"noise": [run.noise for run in runs],
                                  "base_model": runs[0].base_model,
                                  "fits": {n: [dict(q) for q in ps] for n, ps in fits.items()},
                                  "final_fits": final},
                                 units=_parameter_units(runs[0].base_model,
                                                       *(c.model for c in ranking)))

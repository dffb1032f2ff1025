"""Fit and compare many recorded runs on dask.distributed: one result file per recording.

A lab has hundreds of recordings (subjects x conditions x runs) and wants, for each run,
the pilot model's parameters with and without the threshold and the evidence for the
threshold, and that evidence pooled per condition.  :func:`fit_batch` fits each recording
with and without the threshold (:func:`~bayespilot.fit.three_step.fit_paper` or
:func:`~bayespilot.fit.fast.fit_fast`, the paper's model:
:func:`~bayespilot.model.paper_model`, as ``bayespilot fit REC`` without ``--with``),
takes the information criteria of the two (:func:`~bayespilot.compare.information_criteria`),
with ``compare=True`` the Bayes factor by nested sampling
(:func:`~bayespilot.compare.compare`) and, with ``posterior=True``, the posterior of the
parameters by emcee (:func:`~bayespilot.sample.sample`, started as ``bayespilot sample``
starts it), as independent tasks on a dask cluster: a local one by default, an existing
one by address.  It is the sibling of
:func:`bayespilot.diagnose.batch.diagnose_batch` and shares its pieces: the cluster loop
(:func:`bayespilot.campaign.run_keyed`: atomic result files, an ``<key>.error.json`` for
a task that raised while the others go on, which the next call retries, a progress bar,
a lost cluster stopping the batch with what finished saved), the keys
(:func:`~bayespilot.diagnose.batch.plan_batch`: the file stem, ``<folder>_<stem>`` when
two stems clash), the seeds (:func:`~bayespilot.diagnose.batch.task_seed` of the batch's
``seed`` and the recording's signals: both fits and the comparison of a recording run
with it, whatever the order of the paths or the other recordings of the batch; so does
its posterior's chain) and the
resume rule: a result that exists and was made from the same recording (its signals'
digest and what the fit reads of its sidecar, K_theta among it) with the same settings
is not redone; one made from another recording or with other settings is a
:class:`~bayespilot.diagnose.batch.ResultConflictError` that names the key and says what
differs, before anything runs.

Every recording is read and checked (long enough to fit) in this process before the
cluster starts: the unreadable ones are all named in one error and nothing runs.  The
workers receive the recordings, not their paths (a remote cluster needs no shared
folder); the warnings of a task's fits are kept in its result (``warnings``), and this
process says each kind once at the end, naming the recordings.

Outputs in ``out_dir``:

- ``<key>.json``: ``key``, ``recording`` (the path as given), ``recording_digests`` and
  ``recording_metadata`` (as :func:`~bayespilot.diagnose.batch.diagnose_batch` records
  them: one each), ``subject``, ``task``, ``motion_gain``, ``settings`` (``method``,
  ``noise``, ``iterate``, ``oversample``, ``compare``, ``nlive``, ``fit_options``,
  ``compare_options``, with ``posterior=True`` also ``posterior`` (true) and
  ``sample_options`` (every option the chain ran with but the model and seed: ``sample(
  recording, paper_model(oversample=...), seed=settings["seed"], **sample_options)``
  repeats it), ``seed``: the task's own, and ``batch_seed``), ``fit_threshold``
  and ``fit_none`` (``FitResult.to_dict(full=False)``), ``information_criteria`` (of
  the two fits' -ln L, k counted as :func:`~bayespilot.compare.compare` counts it: the
  free parameters, those of an AR noise model among them, and 1 for the output-error
  variance), ``comparison`` (``Comparison.to_dict()``, or null), ``posterior`` (with
  ``posterior=True``: ``summary``, per parameter by name what ``bayespilot sample --json``
  writes, :meth:`~bayespilot.sample.Posterior.summary`: mean, median, hdi_90, r_hat,
  ess_bulk, ess_tail, tau; ``converged``; ``steps``; ``file``, the netCDF file's name; null
  without it, or when the sampling failed: then ``posterior_error`` says why, and the fits
  are kept), ``warnings``
  (``category`` and ``message``, each once), ``elapsed_seconds``, ``host``, ``versions``
  and ``bayespilot_version`` (the worker's).
- ``<key>.nc`` (with ``posterior=True``): the posterior, ArviZ InferenceData as netCDF
  (:meth:`~bayespilot.sample.Posterior.to_netcdf`; read it with
  :meth:`~bayespilot.sample.Posterior.from_netcdf`, ``arviz.from_netcdf`` or ``bayespilot
  plot``), written by this process before its ``<key>.json``.
- ``summary.csv`` (:data:`SUMMARY_FIELDS`), one row per recording whose result (or error)
  file in ``out_dir`` was made with the batch's settings, sorted by key: this call's and
  those an earlier call on other recordings left there.
- ``conditions.csv`` (:data:`CONDITION_FIELDS`), one row per condition (subject, task,
  K_theta) of those rows: the threshold's spread over the runs, the summed improvement
  of -ln L and BIC by the threshold, and with ``compare`` the runs' Bayes factors pooled
  (:func:`~bayespilot.compare.pool`).  With ``posterior=True`` it has nothing more: the
  runs' posteriors are not pooled (a condition's delta_abs shared by its runs, or drawn
  from a population, is a model of its own: a hierarchical one), and a median of the
  runs' posterior medians would say no more than ``delta_abs_median`` of their
  estimates, with no uncertainty; each run's interval is in ``summary.csv``
  (``delta_abs_posterior_median``, ``delta_abs_posterior_hdi_low`` and
  ``delta_abs_posterior_hdi_high``: named apart from ``conditions.csv``'s columns, so that
  the two tables can be joined).
- ``summary.png`` (``summary.<format>`` for each of ``formats``): each run's delta_abs per
  condition, marked by the run's decision, with its posterior's 90 % HDI as an error bar
  when it was sampled.
"""

from __future__ import annotations

import math
import platform
import tempfile
import time
import warnings
from collections import defaultdict
from contextlib import suppress
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np

from . import presets
from ._figstyle import figure_options

if TYPE_CHECKING:
    from distributed import Client
    from distributed.deploy import Cluster

    from .campaign import CampaignSummary
    from .model import PilotModel
    from .recording import Recording

__all__ = ["fit_batch", "SUMMARY_FIELDS", "CONDITION_FIELDS"]

#: Columns of ``summary.csv``: the recording, the parameters of its fit with threshold by
#: name, -ln L with and without, the VAF with threshold, delta_bic (none - threshold:
#: positive favours the threshold), with ``compare`` the ln Bayes factor, its error and the
#: decision, with ``posterior`` delta_abs's posterior median and 90 % HDI
#: (``delta_abs_posterior_*``: not ``conditions.csv``'s ``delta_abs_median``, the median of
#: the runs' estimates), whether the chain converged and, for a sampling that failed, its
#: error; the seed the task ran with and, for a task that failed, its error.  Every column is
#: always written: one not computed (no ``compare``, no ``posterior``, a failed task) is
#: empty, as are None, NaN and infinite values.
SUMMARY_FIELDS = ("key", "subject", "task", "motion_gain", *presets.PARAMETER_NAMES,
                  "neg_log_lik", "neg_log_lik_none", "vaf", "delta_bic", "log_bayes_factor",
                  "log_bayes_factor_err", "decision", "delta_abs_posterior_median",
                  "delta_abs_posterior_hdi_low", "delta_abs_posterior_hdi_high", "converged", "posterior_error", "seed", "error")

#: Columns of ``conditions.csv``: the condition (subject, '' when the recordings give none;
#: task; K_theta) and its ``label``, the runs with a result, delta_abs's median, min and max
#: over them, the sums over them of -ln L none - threshold and of delta_bic, and with
#: ``compare`` the pooled ln Bayes factor, its error and decision
#: (:func:`~bayespilot.compare.pool`).
CONDITION_FIELDS = ("subject", "task", "motion_gain", "label", "n_runs", "delta_abs_median",
                    "delta_abs_min", "delta_abs_max", "sum_delta_neg_log_lik", "sum_delta_bic",
                    "log_bayes_factor", "log_bayes_factor_err", "decision")

#: Warnings not recorded (libraries' notices to developers), as run_job leaves them out.
_QUIET = (DeprecationWarning, PendingDeprecationWarning, FutureWarning)


def _information_criteria(fit_threshold: Any, fit_none: Any, model: PilotModel,
                          recording: Recording) -> dict[str, Any]:
    """:func:`~bayespilot.compare.information_criteria` of the two fits, k counted as
    :func:`~bayespilot.compare.compare` counts it (the model's free parameters, an AR
    noise model's coefficients, + 1 for the output-error variance; without threshold those
    of the model the fit without threshold fitted, ``model.without_threshold()``), n the
    samples the fit with threshold's likelihood uses (after its discard, less the AR
    order)."""
    from .compare import information_criteria
    from .likelihood import Likelihood
    from .noise import ARNoise

    def noise(fit: Any) -> ARNoise | None:
        given = fit.settings.get("noise")
        return None if not given else ARNoise.from_dict(given)

    def k(m: PilotModel, fit: Any) -> int:
        return m.n_free + (0 if noise(fit) is None else noise(fit).order) + 1

    lik = Likelihood(model, recording, initial=fit_threshold.settings["initial"],
                     discard=fit_threshold.settings["discard"], noise=noise(fit_threshold))
    return information_criteria(fit_threshold.neg_log_lik, fit_none.neg_log_lik,
                                k(model, fit_threshold),
                                k(model.without_threshold(), fit_none), lik.n_terms)


def _run_fit_task(recording: Recording, settings: Mapping[str, Any]
                  ) -> tuple[dict[str, Any], Any]:
    """One recording's task, on a worker: both fits, their information criteria, (with
    ``settings["compare"]``) the comparison and (with ``settings.get("posterior")``) the
    posterior, all seeded by ``settings["seed"]``; the warnings kept (each once), not
    issued.  Returns the result file's computed part and the
    :class:`~bayespilot.sample.Posterior` (None without one: not asked for, or its sampling
    failed, which the result's ``posterior_error`` says; the fits are kept), which this
    process writes as ``<key>.nc`` (it pickles as its InferenceData: tens of kB to a few
    MB)."""
    from . import __version__
    from ._files import VERSION_KEY
    from .campaign import _fit_function, _versions, _warnings_once
    from .model import paper_model
    from .noise import ARNoise

    t0 = time.perf_counter()
    model = paper_model(threshold=True, oversample=settings["oversample"])
    kw = dict(settings["fit_options"])
    if settings["method"] == "paper":
        kw["iterate"] = settings["iterate"]
    elif settings["noise"] == "ar":
        kw["noise"] = "ar"
    fit = _fit_function(settings["method"])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for quiet in _QUIET:
            warnings.simplefilter("ignore", quiet)
        with_threshold = fit(recording, model, threshold=True, seed=settings["seed"], **kw)
        if kw.get("noise") == "ar" and kw.get("noise_order") is None:
            # the AR order the fit with threshold chose, for both: with an order each, the
            # two -ln L were sums over different samples with different noise models, and
            # their information criteria compared nothing
            kw["noise_order"] = ARNoise.from_dict(with_threshold.settings["noise"]).order
        without = fit(recording, model, threshold=False, seed=settings["seed"], **kw)
        ic = _information_criteria(with_threshold, without, model, recording)
        comparison = None
        if settings["compare"]:
            from .compare import compare

            comparison = compare(recording, model, seed=settings["seed"],
                                 nlive=settings["nlive"], progress=False,
                                 **settings["compare_options"]).to_dict()
        post, sampled, failed = None, None, {}
        if settings.get("posterior"):
            from .sample import sample

            try:  # (as `bayespilot sample REC --seed S` starts it: from its own fast fit)
                post = sample(recording, model, seed=settings["seed"], progress=False,
                              **settings["sample_options"])
                sampled = {"summary": post.summary(), "converged": bool(post.converged),
                           "steps": int(post.settings["n_steps"])}
            except Exception as exc:  # noqa: BLE001 - the fits are kept, the error recorded
                post, failed = None, {"posterior_error": f"{type(exc).__name__}: {exc}"}
    said = _warnings_once(caught)
    return {"fit_threshold": with_threshold.to_dict(full=False),
            "fit_none": without.to_dict(full=False), "information_criteria": ic,
            "comparison": comparison,
            **({"posterior": sampled, **failed} if settings.get("posterior") else {}),
            "warnings": said, "elapsed_seconds": time.perf_counter() - t0,
            "host": platform.node(), "versions": _versions(), VERSION_KEY: __version__}, post


#: sample()'s arguments the batch sets itself (the recording, its model and seed, no progress
#: bar on a worker) or leaves at their default, so that the chain starts as ``bayespilot
#: sample`` starts it (from sample's own fit: ``init``, ``noise``) and writes no file on a
#: worker (``backend``): not taken from ``sample_options``.
_SET_BY_BATCH = ("recording", "model", "seed", "progress", "init", "noise", "backend")


def _sample_options(given: Mapping[str, Any], model: PilotModel) -> dict[str, Any]:
    """``sample_options`` checked (ValueError) and completed as the chain runs with them and
    the result records them: ``likelihood`` and ``max_steps`` at sample()'s defaults (those
    of ``bayespilot sample``) unless given, ``min_steps`` at min(its default, max_steps) as
    ``bayespilot sample --max-steps`` sets it, the others as given."""
    import inspect

    from .campaign import _json_roundtrip
    from .sample import _check_int, likelihood_options, sample

    if not isinstance(given, Mapping):
        raise ValueError(f"sample_options must be a mapping of keywords of sample(), got "
                         f"{type(given).__name__}")
    params = inspect.signature(sample).parameters
    bad = sorted(map(str, (k for k in given if k not in params or k in _SET_BY_BATCH)))
    if bad:
        raise ValueError(f"sample_options: {', '.join(map(repr, bad))} is not an option of "
                         f"sample() the batch passes on (it gives each recording its model and "
                         f"seed and starts the chain as bayespilot sample does); it takes "
                         f"{', '.join(sorted(set(params) - set(_SET_BY_BATCH)))}")
    opts = {"likelihood": params["likelihood"].default,
            "max_steps": params["max_steps"].default, **given}
    likelihood_options(model, opts["likelihood"], opts.get("ar", params["ar"].default),
                       opts.get("ar_order"))
    max_steps = _check_int("max_steps", opts["max_steps"], 1)
    opts.setdefault("min_steps", min(params["min_steps"].default, max_steps))
    if _check_int("min_steps", opts["min_steps"], 0) > max_steps:
        raise ValueError(f"sample_options: min_steps ({opts['min_steps']}) must not exceed "
                         f"max_steps ({max_steps})")
    try:
        return _json_roundtrip(opts)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"sample_options must be JSON-serialisable, as the result files "
                         f"record them ({exc})") from None


def _options(method: str, noise: str, iterate: bool, oversample: int, compare: bool,
             nlive: int | None, fit_options: Mapping[str, Any] | None,
             compare_options: Mapping[str, Any] | None, posterior: bool = False,
             sample_options: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The batch's settings, checked (ValueError), as its result files record them (without
    the seeds); ``posterior`` and ``sample_options`` only with ``posterior=True`` (absent
    when False: results made before the option still resume, as diagnose_batch's)."""
    from .campaign import Job, _json_roundtrip
    from .compare import _check_int
    from .model import paper_model

    if method not in ("paper", "fast"):
        raise ValueError(f"method must be 'paper' or 'fast', got {method!r}")
    if noise not in ("white", "ar"):
        raise ValueError(f"noise must be 'white' or 'ar', got {noise!r}")
    if noise == "ar" and method != "fast":
        raise ValueError("noise='ar' (a prediction-error fit) goes with method='fast'")
    for name, value in (("iterate", iterate), ("compare", compare), ("posterior", posterior)):
        if not isinstance(value, bool):
            raise ValueError(f"{name} must be True or False, got {value!r}")
    if iterate and method != "paper":
        raise ValueError("iterate=True repeats Steps II and III of method='paper'")
    model = paper_model(threshold=True, oversample=oversample)  # (a bad oversample: raised)
    if nlive is not None and not compare:
        raise ValueError(f"nlive sets the live points of the comparison; give it with "
                         f"compare=True (got nlive={nlive!r})")
    if compare:
        import inspect

        from .compare import compare as compare_function

        params = inspect.signature(compare_function).parameters
        # (compare's own rule: the model with threshold needs the most live points)
        nlive = _check_int("nlive", params["nlive"].default if nlive is None else nlive,
                           2 * model.n_free + 2)
        refused = {"recording", "model", "seed", "nlive", "progress"}
        bad = sorted(k for k in compare_options or {} if k not in params or k in refused)
        if bad:
            raise ValueError(f"compare_options: {', '.join(map(repr, bad))} is not an option of "
                             f"compare() the batch passes on (give nlive and seed as "
                             f"fit_batch's own)")
    elif compare_options:
        raise ValueError("compare_options are options of the comparison; give them with "
                         "compare=True")
    fit_options = dict(fit_options or {})
    own = sorted(set(fit_options) & {"iterate", "noise"})
    if own:
        raise ValueError(f"fit_options: give {', '.join(own)} as fit_batch's own keyword")
    # (the campaign's check of a fit's options: names, True/False, JSON)
    fit_options = Job(task="FD", motion_gain=1.0, remnant_fraction=0.0, realization=0,
                      threshold=True, method=method, fit_kwargs=fit_options).fit_kwargs
    try:
        compare_options = _json_roundtrip(dict(compare_options or {}))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"compare_options must be JSON-serialisable ({exc})") from None
    if compare and noise == "ar":
        # the fits whiten the output error by an AR model: the comparison too (compare's
        # AR output-error likelihood, one AR model for both), or the row's delta_bic and
        # its Bayes factor weighed the threshold under two noise models
        compare_options.setdefault("likelihood", "coloured")
    if sample_options and not posterior:
        raise ValueError("sample_options are options of the posterior's chain; give them with "
                         "posterior=True")
    sampled = ({"posterior": True, "sample_options": _sample_options(sample_options or {}, model)}
               if posterior else {})
    return {"method": method, "noise": noise, "iterate": iterate, "oversample": int(oversample),
            "compare": compare, "nlive": nlive if compare else None,
            "fit_options": fit_options, "compare_options": compare_options, **sampled}


def _fittable_problem(recording: Recording, options: Mapping[str, Any]) -> str | None:
    """Why the batch's fits cannot use ``recording`` (too short, u constant, a discard it
    cannot take), as the fits would say it on a worker, or None."""
    from .fit.fast import _check_ar_fittable
    from .fit.three_step import _check_fittable
    from .likelihood import _checked_discard, _coloured_default, _startup_default
    from .model import paper_model

    fit = options["fit_options"]
    ar = options["noise"] == "ar"
    discard = fit.get("discard")
    if discard is None:
        discard = (_coloured_default(recording.duration) if ar
                   else _startup_default(recording, fit.get("initial", "periodic")))
    try:
        with warnings.catch_warnings():  # (the fits say them, recorded in the results)
            warnings.simplefilter("ignore")
            discard = _checked_discard(recording, discard)
            _check_fittable(recording, paper_model(oversample=options["oversample"]), discard)
            if ar:
                _check_ar_fittable(recording, discard, fit.get("noise_order"),
                                   fit.get("discard") is None)
    except ValueError as exc:
        return str(exc)
    return None


def _done(out: Path, key: str) -> dict[str, Any] | None:
    """The result file ``out/<key>.json`` if it is one of a batch's (parses, records ``key``
    and a fit), else None (missing, cut short, another kind of file: to run)."""
    from .campaign import _read_json

    stored = _read_json(out / f"{key}.json")
    ok = isinstance(stored, dict) and stored.get("key") == key and "fit_threshold" in stored
    return stored if ok else None


def _say_warned(out: Path, keys: Sequence[str]) -> None:
    """Each kind of warning that the tasks of ``keys`` whose results are in ``out`` (those
    this call ran and saved) recorded, once: a RuntimeWarning naming how many recordings
    and which, with one message, as :func:`~bayespilot.campaign.run_campaign` says those of
    its fits; and the posteriors that could not be sampled (``posterior_error``) likewise."""
    from ._caller import warn_at_caller
    from .campaign import _listed, _say_each_kind

    warned: dict[str, list[tuple[str, str]]] = defaultdict(list)
    unsampled: list[tuple[str, str]] = []
    for key in keys:
        stored = _done(out, key) or {}
        for w in stored.get("warnings") or ():
            warned[w["category"]].append((key, w["message"]))
        if stored.get("posterior_error"):
            unsampled.append((key, str(stored["posterior_error"])))
    if unsampled:
        named = sorted(k for k, _ in unsampled)
        warn_at_caller(f"the posterior could not be sampled for {len(named)} recording(s) "
                       f"({_listed(named, 3)}), e.g. {named[0]}: {dict(unsampled)[named[0]]}; "
                       f"their fits are kept, and each result file says why under "
                       f"'posterior_error' (the next call with these settings runs them again)",
                       RuntimeWarning)
    _say_each_kind(warned, "recording(s)")


def _view(stored: Any) -> Any:
    """What must agree for a result file to count as done (the form of
    :func:`bayespilot.diagnose.batch._differs`' views): the recording's signals' digest,
    what the fit reads of its sidecar, the settings; None for a file that records none."""
    if not isinstance(stored, Mapping):
        return None
    digests, meta = stored.get("recording_digests"), stored.get("recording_metadata")
    settings = stored.get("settings")
    if not (isinstance(digests, list) and isinstance(meta, list) and len(meta) == len(digests)
            and isinstance(settings, dict)):
        return None
    return {"recordings": sorted(map(str, digests)), "settings": settings,
            "metadata": dict(zip(map(str, digests), meta))}


def _batch_settings(stored: Any) -> Any:
    """A result (or error) file's settings without the task's own ``seed``: what the tasks
    of one batch share (``batch_seed`` among it); None if it records none."""
    settings = stored.get("settings") if isinstance(stored, Mapping) else None
    if not isinstance(settings, dict):
        return None
    return {k: v for k, v in settings.items() if k != "seed"}


def _digest(stored: Mapping[str, Any]) -> str | None:
    """The recording's signals' digest a result or error file records, or None."""
    digests = stored.get("recording_digests")
    return str(digests[0]) if isinstance(digests, list) and len(digests) == 1 else None


def _results(out: Path, settings: Mapping[str, Any],
             current: Mapping[str, str] | None = None) -> dict[str, dict[str, Any]]:
    """Every result file in ``out`` (or, for a task that failed, its error file) made with
    the batch's ``settings`` (:func:`_batch_settings`), by key; one per recording: of two
    files of the same signals (a recording renamed or moved since, so under another key),
    the key of this call's (``current``: key -> digest) is kept, else the first by key.
    Warns (:class:`~bayespilot.diagnose.batch.SummaryScopeWarning`) of the files left out:
    made with other settings, or another key's copy of a recording."""
    from ._caller import warn_at_caller
    from .campaign import _listed, _read_json
    from .diagnose.batch import SummaryScopeWarning

    current = dict(current or {})
    found: dict[str, dict[str, Any]] = {}
    other: list[str] = []
    for f in sorted(out.glob("*.json")):
        failed = f.name.endswith(".error.json")
        key = f.name[:-len(".error.json")] if failed else f.stem
        stored = _read_json(f)
        if not (isinstance(stored, dict) and stored.get("key") == key
                and (failed or "fit_threshold" in stored)):
            continue
        if _batch_settings(stored) != settings:
            other.append(key)
            continue
        if failed:  # (a result wins over an old error file, whichever is read first)
            found.setdefault(key, stored)
        else:
            found[key] = stored
    owner = {d: k for k, d in current.items()}  # digest -> the key kept: this call's,
    for key in sorted(found):  # else the first by key
        d = _digest(found[key])
        if d is not None:
            owner.setdefault(d, key)
    copies = sorted(k for k in found if _digest(found[k]) is not None
                    and owner.get(_digest(found[k]), k) != k)
    for key in copies:
        del found[key]
    if other:
        warn_at_caller(f"{len(other)} result file(s) in {out} made with other settings are "
                       f"left out of summary.csv and conditions.csv ({_listed(sorted(other), 3)}); "
                       f"use one folder per setting", SummaryScopeWarning)
    if copies:
        warn_at_caller(f"{len(copies)} result file(s) in {out} hold a recording that another "
                       f"key holds too (renamed or moved since): left out of the tables, which "
                       f"count each run once ({_listed(copies, 3)}); delete them",
                       SummaryScopeWarning)
    return found


def _summary_row(stored: Mapping[str, Any]) -> dict[str, Any]:
    """A row of ``summary.csv`` (:data:`SUMMARY_FIELDS`) from a result or error file."""
    row = {"key": stored["key"], "subject": stored.get("subject") or "",
           "task": stored.get("task"), "motion_gain": stored.get("motion_gain"),
           "seed": stored["settings"].get("seed")}
    if "fit_threshold" not in stored:
        return {**row, "error": f"{stored.get('error')}: {stored.get('message')}"}
    fit, none = stored["fit_threshold"], stored["fit_none"]
    comparison = stored.get("comparison") or {}
    post = stored.get("posterior") or {}
    delta = (post.get("summary") or {}).get("delta_abs") or {}
    low, high = delta.get("hdi_90") or (None, None)
    return {**row, **{n: fit["params"].get(n) for n in presets.PARAMETER_NAMES},
            "neg_log_lik": fit["neg_log_lik"], "neg_log_lik_none": none["neg_log_lik"],
            "vaf": fit["vaf"], "delta_bic": stored["information_criteria"]["delta_bic"],
            "log_bayes_factor": comparison.get("log_bayes_factor"),
            "log_bayes_factor_err": comparison.get("log_bayes_factor_err"),
            "decision": comparison.get("decision"),
            "delta_abs_posterior_median": delta.get("median"),
            "delta_abs_posterior_hdi_low": low, "delta_abs_posterior_hdi_high": high,
            "converged": post.get("converged"),
            "posterior_error": stored.get("posterior_error")}


def _label(subject: str, task: str, motion_gain: float) -> str:
    """A condition's name, as :func:`~bayespilot.compare.pool` labels it: "s1, FD, K_theta = 1"
    ("FD, K_theta = 1" without a subject)."""
    return ", ".join([*([subject] if subject else []), str(task),
                      f"K_theta = {float(motion_gain):g}"])


def _condition_rows(results: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The rows of ``conditions.csv`` (:data:`CONDITION_FIELDS`) of the results (no error
    files), one per (subject, task, K_theta), sorted."""
    from .compare import pool

    groups: dict[tuple, list[Mapping[str, Any]]] = defaultdict(list)
    for r in results:
        groups[(r.get("subject") or "", str(r.get("task")), float(r["motion_gain"]))].append(r)
    rows = []
    for (subject, task, gain), runs in sorted(groups.items()):
        delta = [r["fit_threshold"]["params"]["delta_abs"] for r in runs]
        row = {"subject": subject, "task": task, "motion_gain": gain,
               "label": _label(subject, task, gain), "n_runs": len(runs),
               "delta_abs_median": float(np.median(delta)), "delta_abs_min": min(delta),
               "delta_abs_max": max(delta),
               "sum_delta_neg_log_lik": math.fsum(r["fit_none"]["neg_log_lik"]
                                                  - r["fit_threshold"]["neg_log_lik"]
                                                  for r in runs),
               "sum_delta_bic": math.fsum(r["information_criteria"]["delta_bic"] for r in runs)}
        compared = [r["comparison"] for r in runs if r.get("comparison")]
        if compared:
            try:
                p = pool(compared, label=row["label"])
                row.update(log_bayes_factor=p.log_bayes_factor,
                           log_bayes_factor_err=p.log_bayes_factor_err, decision=p.decision)
            except ValueError as exc:  # (the same run under two keys, left by earlier calls)
                row["decision"] = f"not pooled: {exc}"
        rows.append(row)
    return rows


#: fit-batch's summary figure draws at most this many conditions one column each, as it
#: always did, and only while their names fit side by side (measured: each name's box clear
#: of the next, level up to 3 conditions, at 30 degrees beyond; about 7 short names,
#: "s01, FD, K_theta = 0.5", fill a page's width) ...
_SUMMARY_COLUMNS = 12
#: ... else one row each, their names level, the figure a page wide and this tall (in) per
#: row of its axes: a name (0.13 in of small text) and a gap, as diagnose-batch's summary
#: (:data:`bayespilot.diagnose.batch.SUMMARY_ROW_HEIGHT`) ...
_SUMMARY_ROW = 0.19
#: ... and this tall (in) around the rows (title, the delta_abs scale above and below them,
#: its label: 0.91 in as drawn) ...
_SUMMARY_ROWS_MARGIN = 1.0
#: ... up to this height (in; as diagnose-batch's: matplotlib draws at most 2**16 pixels a
#: side, 60 in is 36000 at 600 dpi): beyond about 310 conditions every k-th is named.
_SUMMARY_MAX_HEIGHT = 60.0


def _summary_rows_size(n: int) -> tuple[float, float]:
    """The size (in) of the summary figure of ``n`` conditions drawn one row each: a page
    wide, :data:`_SUMMARY_ROW` per row and :data:`_SUMMARY_ROWS_MARGIN` around them, at
    least 4 in (the columns' height) and at most :data:`_SUMMARY_MAX_HEIGHT`."""
    from .plots import PAGE_WIDTH

    return PAGE_WIDTH, min(max(4.0, _SUMMARY_ROWS_MARGIN + _SUMMARY_ROW * n), _SUMMARY_MAX_HEIGHT)


def _tick_labels_overlap(labels: Sequence[Any]) -> bool:
    """Whether the boxes of any two of the tick ``labels`` (of a laid out figure) overlap."""
    boxes = [t.get_window_extent() for t in labels if t.get_visible() and t.get_text()]
    return any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1:])


def _plot_summary(rows: Sequence[Mapping[str, Any]], conditions: Sequence[Mapping[str, Any]],
                  title: bool | str = True) -> Any:
    """Each run's delta_abs (rows of ``summary.csv`` with a result), one column per condition,
    marked by the run's decision (with a comparison) or by the sign of its delta_bic, with
    its posterior's 90 % HDI as an error bar where it has one; the runs of a condition side
    by side in its column, in the order of their keys (their bars would overlap); ``title``
    as every plot function takes it (:func:`bayespilot.plots.plot_trace`).

    Columns while the conditions' names fit side by side (:data:`_SUMMARY_COLUMNS`: a figure
    at most a page wide, 4 in tall); else one row per condition, top to bottom, delta_abs
    across (its scale above and below the rows), the figure a page wide and as tall as
    the rows need (:func:`_summary_rows_size`; every k-th condition named beyond
    :data:`_SUMMARY_MAX_HEIGHT`). The legend is outside the data: under the columns'
    names, right of the rows."""
    import re

    from .diagnose.report import _legend_under, _pyplot, _subplots
    from .plots import _legend_columns, _param_label, _title_text

    where = {(c["subject"], c["task"], c["motion_gain"]): i for i, c in enumerate(conditions)}
    done = [r for r in rows if not r.get("error")]
    column: dict[int, list[int]] = defaultdict(list)  # condition -> its runs (indices in done)
    for n, r in enumerate(done):
        column[where[(r["subject"], str(r["task"]), float(r["motion_gain"]))]].append(n)
    x = {}
    for i, runs in column.items():
        step = min(0.15, 0.6 / max(len(runs) - 1, 1))
        x.update({n: i + (j - (len(runs) - 1) / 2) * step for j, n in enumerate(runs)})
    compared = any(r.get("decision") for r in done)
    kinds = ({"threshold": ("o", "C0", "threshold"), "none": ("x", "C3", "none"),
              "inconclusive": ("s", "0.5", "inconclusive")} if compared else
             {True: ("o", "C0", r"$\Delta$BIC > 0 (threshold)"),
              False: ("x", "C3", r"$\Delta$BIC $\leq$ 0 (none)")})
    bars = [(x[n], float(r["delta_abs_posterior_hdi_low"]),
             float(r["delta_abs_posterior_hdi_high"]))
            for n, r in enumerate(done)
            if r.get("delta_abs_posterior_hdi_low") not in (None, "")
            and r.get("delta_abs_posterior_hdi_high") not in (None, "")]
    names = [c["label"].replace("K_theta", r"$K_\theta$") for c in conditions]
    n_cond = len(conditions)
    text = _title_text(title, f"The threshold of {len(done)} run{'s' if len(done) != 1 else ''}"
                              f" in {n_cond} condition{'s' if n_cond != 1 else ''}")

    def draw(across: bool) -> Any:  # one column per condition (across), else one row
        if across:
            fig, ax = _subplots(figsize=(max(4.8, 1.6 + 1.0 * n_cond), 4.0))
        else:
            fig, ax = _subplots(figsize=_summary_rows_size(n_cond), tall=True)
        for kind, (marker, colour, label) in kinds.items():
            xs, ys = [], []
            for n, r in enumerate(done):
                mine = r.get("decision") if compared else float(r["delta_bic"]) > 0
                if mine == kind:
                    xs.append(x[n])
                    ys.append(r["delta_abs"])
            if xs:  # (whole at delta_abs = 0, on the axis: not cut in half)
                ax.scatter(*((xs, ys) if across else (ys, xs)), marker=marker, c=colour,
                           label=label, zorder=3, clip_on=False,
                           **({} if across else {"s": 16}))
        if bars:  # (centred on the interval: it need not hold the estimate)
            bx, lo, hi = (np.array(v, dtype=float) for v in zip(*bars))
            style = dict(fmt="none", ecolor="0.35", elinewidth=1.0, zorder=2,
                         label="posterior 90 % HDI")
            if across:
                ax.errorbar(bx, (lo + hi) / 2, yerr=(hi - lo) / 2, capsize=2.5, **style)
            else:
                ax.errorbar((lo + hi) / 2, bx, xerr=(hi - lo) / 2, capsize=1.5, **style)
        if across:
            ax.set_xticks(range(n_cond))
            ax.set_xticklabels(names, rotation=30 if n_cond > 3 else 0,
                               ha="right" if n_cond > 3 else "center", fontsize="small")
            ax.set_xlim(-0.6, n_cond - 0.4)
            ax.set_ylim(bottom=0.0)  # (0: no threshold)
            ax.set_ylabel(_param_label("delta_abs"))
            ax.grid(axis="y", alpha=0.3)
            # as many columns as fit (its entries' width as drawn, not as mathtext spells it)
            shown = [re.sub(r"\$?\\[A-Za-z]+\$?", "x", h.get_label()).replace("$", "")
                     for h in ax.get_legend_handles_labels()[0]]
            _legend_under(ax, title="per run",
                          ncols=_legend_columns(shown, fig.get_figwidth(), len(shown)))
        else:
            # every k-th named where a row of the axes is shorter than a name and its gap
            row = (fig.get_figheight() - _SUMMARY_ROWS_MARGIN) / max(n_cond, 1)
            k = max(1, math.ceil(_SUMMARY_ROW / row - 1e-9))
            ax.set_yticks(range(0, n_cond, k))
            ax.set_yticklabels(names[::k], fontsize="small")
            if k > 1:  # (a tick on every row: the unnamed ones counted from a named one)
                ax.set_yticks(range(n_cond), minor=True)
            ax.set_ylim(n_cond - 0.5, -0.5)  # (the first condition at the top)
            ax.set_xlim(left=0.0)  # (0: no threshold)
            ax.set_xlabel(_param_label("delta_abs"))
            ax.xaxis.set_label_position("top")
            ax.tick_params(axis="x", top=True, labeltop=True)
            ax.grid(axis="both", alpha=0.3)
            ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
                      fontsize="small", title="per run", title_fontsize="small")
        if text:
            ax.set_title(text, fontsize="medium")
        return fig, ax

    if n_cond <= _SUMMARY_COLUMNS:
        fig, ax = draw(True)
        fig.draw_without_rendering()  # (the names' place)
        if not _tick_labels_overlap(ax.get_xticklabels()):
            return fig
        _pyplot().close(fig)
    return draw(False)[0]


def _write_summaries(out: Path, settings: Mapping[str, Any],
                     current: Mapping[str, str] | None = None,
                     figure: Mapping[str, Any] | None = None) -> None:
    """``summary.csv``, ``conditions.csv`` and (when a task finished) ``summary.<format>`` of
    the results in ``out`` made with ``settings`` (:func:`_batch_settings`; ``current``: this
    call's keys and digests, :func:`_results`; ``figure``: title, formats and dpi,
    :func:`bayespilot._figstyle.figure_options`, default a titled PNG at
    :data:`~bayespilot.diagnose.report.FIGURE_DPI`); a summary figure of another format, or
    of no result now, is removed (it showed other results).  The earlier figure is removed
    before the tables are written, the new one drawn after them: a write that fails (a full
    disk) never leaves a figure of other results beside new tables."""
    from ._files import write_csv_atomic
    from .diagnose.report import _remove_summary_figures, _write_summary_figure

    found = _results(out, settings, current)
    rows = [_summary_row(found[k]) for k in sorted(found)]
    conditions = _condition_rows([found[k] for k in sorted(found) if "fit_threshold" in found[k]])
    _remove_summary_figures(out)
    write_csv_atomic(out / "summary.csv", SUMMARY_FIELDS, rows)
    write_csv_atomic(out / "conditions.csv", CONDITION_FIELDS, conditions)
    figure = {"title": True, "formats": ("png",), "dpi": None, **(figure or {})}
    _write_summary_figure((lambda: _plot_summary(rows, conditions, title=figure["title"]))
                          if conditions else None, out, figure["formats"], figure["dpi"])


def fit_batch(paths: Sequence[str | Path], out_dir: str | Path, *, method: str = "paper",
              noise: str = "white", iterate: bool = False, oversample: int = 1,
              compare: bool = False, nlive: int | None = None, seed: int = 0,
              fit_options: Mapping[str, Any] | None = None,
              compare_options: Mapping[str, Any] | None = None, posterior: bool = False,
              sample_options: Mapping[str, Any] | None = None,
              scheduler: "str | Client | Cluster | None" = None, workers: int | None = None,
              progress: bool | str = True, connect_timeout: float = 10.0,
              warm_cache: bool = True, title: bool = True, formats: Sequence[str] = ("png",),
              dpi: int | None = None) -> "CampaignSummary":
    """Fit (compare, sample) many recordings, with and without threshold, on dask.distributed.

    Parameters
    ----------
    paths : sequence of str or Path
        Recordings (stems, .csv, .json or .mat paths), as ``bayespilot fit`` takes them;
        one named twice (its ``.csv`` and its ``.json``) is fitted once.
    out_dir : str or Path
        Created if missing; ``<key>.json`` per recording, ``summary.csv``,
        ``conditions.csv`` and ``summary.png`` (module docs).
    method : {"paper", "fast"}
        :func:`~bayespilot.fit.three_step.fit_paper` (minutes a fit) or
        :func:`~bayespilot.fit.fast.fit_fast` (seconds).
    noise : {"white", "ar"}
        The output-error model: white (Eq. 4, the paper's) or, with ``method="fast"``
        only, an AR model estimated with the fit (a prediction-error fit); its
        coefficients count in k of the information criteria.  The fit with threshold
        picks the AR order by BIC and the fit without uses the same order (unless
        ``fit_options`` gives ``noise_order``), so both -ln L are sums over the same
        samples.
    iterate : bool
        With ``method="paper"`` only: repeat Steps II and III until they agree.
    oversample : int
        Run the vestibular channel at this many times the recording's rate
        (:func:`~bayespilot.model.paper_model`), in the fits and the comparison.
    compare : bool
        Also compare the models with and without threshold on each recording by nested
        sampling (:func:`~bayespilot.compare.compare`: minutes a recording) and pool the
        Bayes factors per condition in ``conditions.csv``.
    nlive : int, optional
        The comparison's live points (default: :func:`~bayespilot.compare.compare`'s);
        only with ``compare``.
    seed : int
        The batch's seed (>= 0).  Each recording's fits and comparison run with its own,
        :func:`~bayespilot.diagnose.batch.task_seed` of ``seed`` and its signals' digest
        (recorded in ``settings["seed"]`` and in ``summary.csv``: ``fit_fast(recording,
        seed=...)`` repeats the fit), beside ``settings["batch_seed"]``.
    fit_options : mapping, optional
        Other keywords of the fit function, the same for every fit (e.g.
        ``{"n_starts": 4}`` for the fast method, ``{"population": 80}`` for the
        paper's); ``iterate`` and ``noise`` are this function's own.  Recorded in the
        settings.
    compare_options : mapping, optional
        Other keywords of :func:`~bayespilot.compare.compare` (e.g.
        ``{"savage_dickey_samples": False}``, which leaves out the emcee run of its
        Savage-Dickey check, about half its time); only with ``compare``.  Recorded in
        the settings.
    posterior : bool
        Also sample each recording's posterior of the model with threshold
        (:func:`~bayespilot.sample.sample`, emcee until converged: 5 to 10 s for an
        81.92-s run with the eq4 likelihood on one core, two to three times that with
        "coloured"), after its fits, with the recording's seed and the model of the
        fits, started as ``bayespilot sample`` starts it (from sample's own fast fit,
        not from the batch's fits), so that ``bayespilot sample REC --seed S
        --oversample M [--likelihood L] [--max-steps N]`` with the seed the result
        records gives the same chain.  Its summary is in the result
        (``posterior``) and in ``summary.csv`` (delta_abs's median and 90 % HDI:
        ``delta_abs_posterior_median``, ``delta_abs_posterior_hdi_low`` and
        ``delta_abs_posterior_hdi_high``; ``converged``), the draws in ``<key>.nc``.  A sampling that fails is recorded
        (``posterior_error``, said once at the end) and the fits are kept; the next call
        runs that recording again (as it does one whose ``<key>.nc`` is gone).  Recorded in
        the settings (only when True: results made before the option still resume).
    sample_options : mapping, optional
        Other keywords of :func:`~bayespilot.sample.sample`, only with ``posterior``:
        ``likelihood`` ("eq4" or "coloured", default "eq4" as ``bayespilot sample``'s),
        ``ar``, ``ar_order``, ``max_steps`` (default 20000), ``min_steps`` (default
        min(1000, max_steps), as ``bayespilot sample --max-steps`` sets it),
        ``n_walkers``, ``check_every``, ``discard``, ``tau_factor``, ``tau_rtol``, ...;
        not ``init``, ``noise``, ``backend``, ``seed``, ``progress`` (the batch's own).
        Recorded in the settings with those defaults filled in.
    scheduler, workers, progress, connect_timeout, warm_cache
        As for :func:`~bayespilot.campaign.run_campaign` (the lines count recordings).
    title : bool
        True (default): the summary figure with its title (how many runs in how many
        conditions); False: without, for a paper whose caption says it.
    formats : sequence of str
        The formats of the summary figure, ``summary.<format>`` each (default PNG; "pdf"
        and "svg" are vector); one of another format left by an earlier call is removed.
    dpi : int, optional
        The resolution of ``summary.png`` (default
        :data:`~bayespilot.diagnose.report.FIGURE_DPI`).

    Returns
    -------
    CampaignSummary
        ``total`` recordings, ``completed`` by this call, ``skipped`` (done before),
        ``failed`` with one line per key in ``errors`` (each in ``<key>.error.json``).

    Raises
    ------
    bayespilot.recording.RecordingError
        A recording cannot be read (every such file is named); nothing is run.  A
        ValueError.
    ValueError
        A bad setting (``noise="ar"`` without ``method="fast"``, ``iterate`` without
        ``method="paper"``, ``nlive`` or ``compare_options`` without ``compare``,
        ``sample_options`` without ``posterior``, an unknown fit or sample option, a bad
        likelihood or ``max_steps``, ``workers`` not a positive integer or given with
        ``scheduler``, ``connect_timeout`` not a positive number, another ``progress``,
        ``formats`` empty or naming one not in ("png", "pdf", "svg"), a ``dpi`` that is not
        a whole number >= 1), recordings the fits cannot use (too short, u constant:
        every one named), keys that clash, the same recording (its signals) under two
        names; nothing is run.
    ResultConflictError
        ``out_dir`` holds a result of one of the batch's keys made from another recording
        (by its signals, or by what the fit reads of its sidecar: K_theta, the sample
        rate, the task, the plant, the forcing) or with other settings: the message names
        the file and says what differs; nothing is run.  Also an ``out_dir`` that holds
        results of another command (``<key>.json`` of
        :func:`~bayespilot.diagnose.batch.diagnose_batch`, with ``diagnosis``, or a
        ``summary.csv`` this function did not write), which the batch would replace: the
        message names them.  A CampaignError and a ValueError
        (:class:`bayespilot.diagnose.batch.ResultConflictError`).
    CampaignError
        The cluster cannot be reached or started or is lost during the run (what
        finished is saved), ``out_dir`` cannot be written in (a result or posterior
        file among them; the summary tables and figure: every result is saved, and the
        same call again writes them), a worker lacks bayespilot or has another version of
        it, or (``posterior``) arviz cannot be imported here.
    TypeError
        A ``scheduler`` that is not an address (str), a ``distributed.Client`` or a
        ``distributed.deploy.Cluster``; a ``title`` that is not True or False.

    Warns
    -----
    RuntimeWarning
        Once per kind of warning the tasks issued on the workers (a
        QuestionableRecordingWarning, an EstimateOnBoundWarning, a ConvergenceWarning of
        a chain, ...), naming how many recordings and which; each result file lists its
        own under ``warnings``.  Once for the posteriors that could not be sampled.
    QuestionableRecordingWarning
        Once per reason reading the recordings gives (a short record, a low sample
        rate, ...), naming how many recordings and which; a reason of one recording as
        reading it says it.

    Examples
    --------
    >>> summary = fit_batch(["out/s1-run1", "out/s1-run2"], "fits", method="fast",
    ...                     workers=2)  # doctest: +SKIP
    """
    from . import campaign as C
    from .diagnose.batch import (ResultConflictError, _differs, _read_recordings,
                                 _recording_metadata, _refuse_another_commands_folder,
                                 _the_recording, plan_batch, task_seed)
    from .recording import _signals_digest

    t0 = time.perf_counter()
    C._check_cluster_options(scheduler, workers, progress, connect_timeout)
    figure = figure_options(title, formats, dpi)
    options = _options(method, noise, iterate, oversample, compare, nlive, fit_options,
                       compare_options, posterior, sample_options)
    if options.get("posterior"):  # (this process writes the posteriors: said now)
        from .sample import _arviz

        try:
            _arviz()
        except Exception as exc:  # noqa: BLE001 - whatever arviz's import raises
            raise C.CampaignError(f"posterior=True writes each posterior with arviz, which "
                                  f"cannot be imported ({type(exc).__name__}: {exc})") from None
    task_seed(seed, [])  # (a bad seed: the ValueError, before any file is read)
    # (a folder of diagnose-batch's, or a summary.csv of another's: refused before the
    # recordings are read)
    _refuse_another_commands_folder(Path(out_dir), "fit-batch")
    first: dict[str, str] = {}  # a recording named twice (its .csv and its .json) is one
    for p in map(str, paths):
        first.setdefault(_the_recording(p), p)
    paths = list(first.values())
    if not paths:
        raise ValueError("no recordings given")
    # (every one read, the unreadable all named; a reason to question many said once,
    # naming them, not once per recording on every call)
    recs = _read_recordings(paths)
    unfit = [said for said in (_fittable_problem(r, options) for r in recs.values()) if said]
    if unfit:
        raise ValueError(f"{len(unfit)} of {len(paths)} recordings cannot be fitted; nothing "
                         "was run:\n  " + "\n  ".join(unfit))
    tasks = plan_batch(paths, [recs[p] for p in paths])
    digests = {p: _signals_digest(r) for p, r in recs.items()}
    by_digest: dict[str, str] = {}
    twice = []
    for p, d in digests.items():
        if d in by_digest:
            twice.append(f"{by_digest[d]} and {p}")
        by_digest.setdefault(d, p)
    if twice:
        raise ValueError(f"the same recording under two names: {'; '.join(twice)} hold the same "
                         f"signals (conditions.csv would count the run twice); give each run "
                         f"once")
    out = Path(out_dir)
    try:  # (a folder that cannot be written in: said now, not after the first result)
        out.mkdir(parents=True, exist_ok=True)
        # one byte written, not an empty file: a full disk still makes an empty one
        with tempfile.TemporaryFile(dir=out) as probe:
            probe.write(b"\0")
            probe.flush()
    except OSError as exc:
        raise C.CampaignError(f"{out}: cannot write in the output folder "
                              f"({exc.strerror or exc})") from None

    def header(t: Any) -> dict[str, Any]:  # what a result (and an error file) records first
        p = t.paths[0]
        return C._json_roundtrip({
            "recording": p, "recording_digests": [digests[p]],
            "recording_metadata": [_recording_metadata(recs[p])], "subject": t.subject,
            "task": t.task, "motion_gain": t.motion_gain,
            "settings": {**options, "seed": task_seed(seed, [digests[p]]), "batch_seed": seed}})

    headers = {t.key: header(t) for t in tasks}
    done = {t.key: (t, _done(out, t.key)) for t in tasks}
    done = {key: (t, old) for key, (t, old) in done.items() if old is not None}
    for key, (t, old) in done.items():  # (all checked before anything runs)
        was, now = _view(old), _view(headers[key])
        if was != now:  # (_differs' words are the diagnosis's: what the fit reads here)
            said = _differs(was, now, {digests[t.paths[0]]: t.paths[0]}).replace(
                "which the diagnosis reads", "which the fit reads")
            raise ResultConflictError(f"{out / (key + '.json')} holds a fit of {key} from "
                                      f"{said}; use another output folder or delete it")
    for key, (t, old) in done.items():
        if old.get("subject") != headers[key]["subject"]:
            # (a subject corrected in the sidecar since: no refit, the fits do not read it,
            # but the tables group by it; kept, a resume left the run in its old condition)
            C._write_json_atomic(out / f"{key}.json", {**old, "subject": headers[key]["subject"]})
    if options.get("posterior"):  # (a result whose posterior failed, or whose posterior
        done = {key: (t, old) for key, (t, old) in done.items()  # file is gone: run again)
                if old.get("posterior") and (out / f"{key}.nc").is_file()}
    pending = [t for t in tasks if t.key not in done]

    def to_json(key: str, value: Any) -> dict[str, Any]:
        result, post = value  # (post: the Posterior, or None; _run_fit_task)
        nc = out / f"{key}.nc"
        if post is not None:  # (before <key>.json: a result names a file that exists)
            try:
                post.to_netcdf(nc)
            except OSError as exc:
                raise C.CampaignError(f"{nc}: cannot write the posterior "
                                      f"({exc.strerror or exc})") from None
            result = {**result, "posterior": {**result["posterior"], "file": nc.name}}
        elif options.get("posterior"):  # (failed: an earlier file is not this result's)
            with suppress(FileNotFoundError):
                nc.unlink()
        return C._jsonable({"key": key, **headers[key], **result})

    try:
        completed, errors = C.run_keyed(
            [(t.key, _run_fit_task, (recs[t.paths[0]], headers[t.key]["settings"]),
              headers[t.key]) for t in pending], out,
            total=len(tasks), skipped=len(done), scheduler=scheduler, workers=workers,
            progress=progress, connect_timeout=connect_timeout,
            warm=(lambda: C._warm_numba_cache({method})) if warm_cache else None,
            desc="recordings", unit="recording",
            to_json=to_json, scatter=True)
    except BaseException:  # (the run stopped: what finished is saved, and its warnings
        with suppress(Warning):  # said, but a warning made an error must not hide why)
            _say_warned(out, [t.key for t in pending])
        raise
    _say_warned(out, [t.key for t in pending])
    try:
        _write_summaries(out, _batch_settings(next(iter(headers.values()))),
                         {t.key: digests[t.paths[0]] for t in tasks}, figure)
    except OSError as exc:  # (a full disk: each recording's result is saved)
        reason = " ".join(str(exc.strerror or exc).split())
        raise C.CampaignError(f"{out}: cannot write the summary tables and figure ({reason}); "
                              f"each recording's result is saved there: run the same "
                              f"command again to write them") from None
    return C.CampaignSummary(len(tasks), completed, len(done), len(errors), errors, out,
                             time.perf_counter() - t0, "recordings")

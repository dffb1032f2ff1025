"""Diagnose many recordings on dask.distributed: one result file per recording or per condition.

A lab has hundreds of recordings (subjects x conditions x runs).
:func:`diagnose_batch` diagnoses each one alone (:func:`~bayespilot.diagnose.diagnose`)
or, with ``pool=True``, the runs of each subject and condition together
(:func:`~bayespilot.diagnose.diagnose_pooled`), as independent tasks on a
dask cluster: a local one by default, an existing one by address.  It shares
the cluster loop of :func:`bayespilot.campaign.run_campaign` (atomic result
files, an ``<key>.error.json`` for a task that raised while the others go on,
a progress bar) and its resume semantics: a result file that exists, parses
and was made from the same recordings and settings is not redone; one made
from others is an error that says what differs, not a silent mix.  "The same"
recordings by their content (the digests of their signals, which each result
records: a batch run again from another working folder, or with its
recordings moved, resumes; results made before digests were recorded: as the
files resolve) and by what the diagnosis reads of their sidecars, which each
result records too (``recording_metadata``: the sample rate, ``motion_gain``
(K_theta), ``task``, and ``control_gain``, ``controlled_element_gain``,
``controlled_element`` and ``forcing`` where given; not ``subject``, ``run``
or ``notes``): a sidecar corrected since its diagnosis (another K_theta) is a
changed recording, refused, saying which value differs, not taken as done.
A result made before that was recorded is compared on the task and K_theta of
its ``condition``, and resumes by its signals alone if it records no
condition.  "The same" settings with the defaults filled in (an option
left out is its default).  A recording named twice (a glob giving both its
``.csv`` and its ``.json``) is diagnosed once.  A lost cluster (the scheduler
gone mid-run) stops the batch with what finished saved, to resume.  ``reports`` is
not a setting: a diagnosis done before keeps what it has, and one without a
report is named by a :class:`MissingReportWarning`.

Seeds: each diagnosis runs with its own seed, drawn from the batch's ``seed``
and its recordings' content (:func:`task_seed`: ``stream_seed(seed, k)`` with
``k`` taken from the SHA-256 of the recordings' signal digests; not of their
sidecars: a run diagnosed again after its ``motion_gain`` was corrected keeps
its seed), so that two
recordings' bootstraps (and base-fit starts, and posterior chains) draw
independent streams, and a diagnosis's seed does not depend on the order of
the paths, on which other recordings are in the batch, or on resuming.  A
pooled condition's runs are seeded ``s + j`` from its seed ``s``
(:func:`~bayespilot.diagnose.diagnose_pooled`), run j the j-th in the order of
the runs' signals' digests (:func:`plan_batch`): the same recordings under
other names or in other folders give the same diagnosis.  A pooled result
made before (its runs in the order of their files) resumes as it is.  Each
result records the seed its diagnosis ran with (``settings["seed"]``: ``diagnose(recording,
seed=...)`` with the other settings repeats it) and the batch's
(``settings["batch_seed"]``, what a resume compares).  A result of one of the
batch's keys written before seeds were drawn per diagnosis (its settings
record no ``batch_seed``: every diagnosis ran with the batch's seed itself)
is refused by a :class:`ResultConflictError` that names it, not mixed with
or overwritten by those of the new scheme.

Every recording is read, and every setting checked, in this process before
the cluster starts, so a bad file among hundreds is reported (all of them at
once) before any work is done.  The workers receive the recordings
themselves, not their paths, so a remote cluster needs no shared folder.  The
results (and, with ``reports=True``, each diagnosis's HTML report) are
written here.

Outputs in ``out_dir``: ``<key>.json`` (``key``, ``recordings``, ``settings``
(the options, the diagnosis's own ``seed`` and the ``batch_seed``),
``recording_digests``, ``recording_metadata`` (one per recording, as
``recordings``), ``condition``, ``diagnosis``: the same dict as ``bayespilot diagnose
--json`` writes, ``warnings`` (those the diagnosis issued on the worker but its
evidence notes, which ``diagnosis`` keeps: ``category`` and ``message``, each once, as
fit-batch's results list theirs; said once per kind at the end, naming the diagnoses),
``elapsed_seconds``, ``host``, ``versions`` and ``bayespilot_version``: those of
the worker that made the diagnosis, not of the process that writes the file),
``<key>/`` (the report, with
``reports=True``), ``summary.png`` (every candidate's p-value in every
diagnosis, :func:`~bayespilot.diagnose.report.plot_batch`, each diagnosis
named; ``summary.<format>`` of each of ``formats``) and
``summary.csv`` (one row per key: the decision, the
chosen extension's p-value, -ln L improvement and parameters, with
``posterior=True`` its posterior's medians and 90 % intervals, the candidate
with the smallest p-value and that p-value (the nearest miss when the answer
is ``none``), or the error; and the diagnosis's seed).  ``summary.csv`` and
``summary.png`` cover every
diagnosis in ``out_dir`` made with the batch's settings, sorted by key: this
call's, and those an earlier call on other recordings left there (a batch run
again on a subset, or on new recordings, into the same folder keeps the
others' rows).  Result files made with other settings (under other keys) are
left out, and a :class:`SummaryScopeWarning` names them.

Keys: a recording alone is keyed by its file stem (by ``<folder>_<stem>`` when
two recordings share a stem); a pooled condition by
``<subject>_<task>_k<K_theta>``.  Pooling groups recordings by the
recording's ``subject``, ``task`` and ``motion_gain`` (each must give
``subject``); a group of one is diagnosed alone.  A group whose runs differ in
the rest of the task the diagnosis reads (the sample rate, the controlled
element, ``control_gain`` or the forcing functions, as
:func:`~bayespilot.diagnose.pooled.pooling_disagreements` compares them: a lab's
task ``"other"`` under one label) is refused before any work is done, naming
its runs and what differs: the batch pools what it groups without being
asked, and pooling shares the extension's parameters over runs of one task.
"""

from __future__ import annotations

import json
import math
import platform
import re
import time
import warnings
from collections import Counter, defaultdict
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from .._figstyle import figure_options
from .._files import json_ready, replacing, write_csv_atomic
from ..campaign import CampaignError
from ..recording import _signals_digest
from .locate import BaseFitWarning, EvidenceWarning

if TYPE_CHECKING:
    from distributed import Client
    from distributed.deploy import Cluster

    from ..campaign import CampaignSummary
    from ..recording import Recording
    from . import DiagnosisResult
    from .catalogue import Extension
    from .pooled import PooledDiagnosisResult

__all__ = ["DiagnoseTask", "plan_batch", "task_seed", "run_diagnose_task", "diagnose_batch",
           "batch_summary_rows", "SUMMARY_FIELDS", "MissingReportWarning",
           "SummaryScopeWarning", "ResultConflictError"]


class MissingReportWarning(UserWarning):
    """``reports=True``, and diagnoses finished before (not redone) have no report in
    ``out_dir/<key>/``: a report needs the diagnosis's traces, which the result file does not
    keep.  The message names them and says how to get them."""


class SummaryScopeWarning(UserWarning):
    """``out_dir`` holds diagnoses made with other settings (under other keys): ``summary.csv``
    covers those made with the batch's settings and leaves them out.  The message names
    them."""


class ResultConflictError(CampaignError, ValueError):
    """``out_dir`` holds a result of one of the batch's keys made from other recordings or
    settings: bad input (the message says what differs), not a failure of the run.  A
    :class:`~bayespilot.campaign.CampaignError` (as it was) and a ValueError."""


#: Columns of ``summary.csv``.
SUMMARY_FIELDS = ("key", "n_runs", "subject", "task", "motion_gain", "physics", "mismatch",
                  "p_value", "delta_neg_log_lik", "params", "interval", "posterior",
                  "smallest_p_candidate", "smallest_p_value", "error", "seed", "units")

@dataclass(frozen=True)
class DiagnoseTask:
    """One diagnosis of a batch: a recording alone, or the runs of one condition pooled.

    Attributes
    ----------
    key : str
        Name of the result file (module docs, "Keys").
    paths : tuple of str
        The recordings, as given.
    subject : str or None
    task : str or None
        None only for a diagnosis an earlier batch left in the folder whose result file
        does not record it (made before its condition was recorded).
    motion_gain : float or None
        As ``task``.
    """

    key: str
    paths: tuple[str, ...]
    subject: str | None
    task: str | None
    motion_gain: float | None

    @property
    def pooled(self) -> bool:
        """True if the task diagnoses several runs together (:func:`diagnose_pooled`)."""
        return len(self.paths) > 1


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "-", text).strip("-") or "x"


def _subject(rec) -> str | None:
    s = rec.metadata.get("subject")
    return None if s is None else str(s)


def _clashes(keys: Sequence[str]) -> list[str]:
    """The keys that occur more than once, sorted."""
    return sorted(k for k, n in Counter(keys).items() if n > 1)


def plan_batch(paths: Sequence[str], recordings: Sequence, *, pool: bool = False,
               digests: Mapping[str, str] | None = None) -> list[DiagnoseTask]:
    """The batch's diagnoses: one per recording, or (``pool``) one per subject and condition.

    Parameters
    ----------
    paths : sequence of str
        Where each recording was read from (its key comes from the file stem).
    recordings : sequence of Recording
        The recordings read from ``paths``, in the same order.
    pool : bool
        Group the runs of one subject, task and motion gain into one pooled
        diagnosis, its runs in the order of their signals' digests
        (:func:`~bayespilot.recording._signals_digest`; run j is seeded
        ``s + j`` from the task's seed ``s``, and the pooled fit sums the
        runs in that order: by their content, the result depends neither on
        the order the paths were given nor on the files' names or folders).
    digests : mapping of str to str, optional
        Each path's signals' digest, if already computed (default: computed
        from ``recordings`` when ``pool``).

    Returns
    -------
    list of DiagnoseTask

    Raises
    ------
    ValueError
        ``pool`` and a recording without ``subject``; two recordings whose keys
        cannot be told apart; ``pool`` and a group whose runs differ in the
        sample rate, the controlled element, ``control_gain`` or the forcing
        functions (:func:`~bayespilot.diagnose.pooled.pooling_disagreements`; every
        such group named, with its runs and what differs); ``digests`` without one
        of the paths.
    """
    if len(paths) != len(recordings):
        raise ValueError(f"{len(paths)} paths for {len(recordings)} recordings")
    missing = [str(p) for p in paths if digests is not None and str(p) not in digests]
    if missing:
        raise ValueError(f"digests has no digest of {', '.join(missing[:3])}"
                         f"{' ...' if len(missing) > 3 else ''} ({len(missing)} of "
                         f"{len(paths)} paths): give one per path, or none")
    if not pool:
        stems = [Path(p).stem if Path(p).suffix in (".csv", ".json", ".mat") else Path(p).name
                 for p in paths]
        count = Counter(stems)
        keys = [_slug(f"{Path(p).parent.name}_{s}" if count[s] > 1 else s)
                for p, s in zip(paths, stems)]
        dupes = _clashes(keys)
        if dupes:
            raise ValueError(f"recordings that give the same result name: {', '.join(dupes)} "
                             f"(the same file twice, or the same folder and stem)")
        return [DiagnoseTask(k, (str(p),), _subject(r), r.task, float(r.motion_gain))
                for k, p, r in zip(keys, paths, recordings)]
    missing = [str(p) for p, r in zip(paths, recordings) if _subject(r) is None]
    if missing:
        raise ValueError("pooling groups runs by subject, and these recordings give no "
                         f"'subject' in their JSON: {', '.join(missing[:5])}"
                         f"{' ...' if len(missing) > 5 else ''}")
    groups: dict[tuple, list[str]] = defaultdict(list)
    for p, r in zip(paths, recordings):
        groups[(_subject(r), r.task, float(r.motion_gain))].append(str(p))
    dupes = sorted({f"{s}/{t}/{k:g}: {q}" for (s, t, k), ps in groups.items()
                    for q in ps if ps.count(q) > 1})
    if dupes:
        raise ValueError(f"the same recording twice in one condition: {', '.join(dupes)}")
    mixed = _mixed_groups(groups, dict(zip(map(str, paths), recordings)))
    if mixed:
        raise ValueError(
            f"pooling groups runs by subject, task and K_theta, and in {len(mixed)} group(s) "
            f"the runs differ in the task the diagnosis reads: {'; and '.join(mixed)}. "
            f"Pooling shares the extension's parameters over runs of one task; diagnose "
            f"each task's runs in a batch of their own (its own out folder), or without "
            f"pooling")
    if digests is None:
        digests = {str(p): _signals_digest(r) for p, r in zip(paths, recordings)}

    def by_content(p: str) -> tuple[str, str]:  # (the file: only between equal signals)
        return digests[p], _the_recording(p)

    tasks = [DiagnoseTask(_slug(f"{s}_{t}_k{k:g}"), tuple(sorted(ps, key=by_content)),
                          s, t, k)
             for (s, t, k), ps in sorted(groups.items())]
    clash = _clashes([t.key for t in tasks])
    if clash:
        raise ValueError(f"subjects whose names give the same result name: {', '.join(clash)} "
                         "(only letters, digits, '.', '_' and '-' are kept)")
    return tasks


def _mixed_groups(groups: Mapping[tuple, Sequence[str]], by_path: Mapping[str, Any]
                  ) -> list[str]:
    """For each group of :func:`plan_batch` (``(subject, task, K_theta) -> paths``) whose runs
    differ in the rest of the task the diagnosis reads (sample rate, controlled element,
    control_gain, forcing: :func:`~bayespilot.diagnose.pooled.pooling_disagreements`), one text:
    the group and what differs, each value with its runs; sorted by group."""
    from .pooled import pooling_disagreements

    said = []
    for (s, t, k), ps in sorted(groups.items()):
        if len(ps) > 1:
            what = pooling_disagreements([by_path[p] for p in ps], names=ps)
            if what:
                said.append(f"{s}/{t}/K_theta {k:g} ({len(ps)} runs): {what}")
    return said


def task_seed(seed: int, digests: Sequence[str]) -> int:
    """The seed of one diagnosis of a batch: drawn from the batch's ``seed`` and its recordings.

    ``stream_seed(seed, k)`` (:func:`bayespilot._seeds.stream_seed`, not
    ``seed + k``: batches of seeds 3 and 4 share no stream), with ``k`` the first 60
    bits of the SHA-256 of the recordings' signal digests, sorted and joined by
    newlines.  A function of the recordings' content alone: not of their paths
    or order, nor of the other diagnoses of the batch, so a batch run again, on
    a subset, or resumed gives each diagnosis the seed it had.

    Parameters
    ----------
    seed : int
        The batch's seed (>= 0).
    digests : sequence of str
        The task's recordings' :func:`~bayespilot.recording._signals_digest`
        (one for a recording alone, one per run for a pooled condition).

    Returns
    -------
    int
        A 31-bit seed, what the diagnosis runs with (``diagnose(recording,
        seed=...)`` repeats it).

    Raises
    ------
    ValueError
        ``seed`` is not an integer >= 0.

    Examples
    --------
    >>> task_seed(0, ["ab", "cd"]) == task_seed(0, ["cd", "ab"]) != task_seed(1, ["ab", "cd"])
    True
    """
    import hashlib

    from .._seeds import stream_seed

    import numbers

    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    if isinstance(digests, str):  # (one recording's digest, not its characters)
        digests = [digests]
    text = "\n".join(sorted(str(d) for d in digests))
    k = int(hashlib.sha256(text.encode()).hexdigest()[:15], 16)
    return stream_seed(int(seed), k)


def run_diagnose_task(task: DiagnoseTask, recordings: Sequence[Recording],
                      options: Mapping[str, Any], extensions: Sequence[Extension] = ()
                      ) -> tuple[DiagnosisResult | PooledDiagnosisResult, float]:
    """Diagnose one task (on a worker); returns the result object and the seconds it took.

    ``options`` are :func:`~bayespilot.diagnose.diagnose`'s keywords and
    ``posterior`` (bool): when an extension fitted by the GLS likelihood is
    chosen, also its posterior (:func:`~bayespilot.diagnose.sample_chosen` for
    one run, :func:`~bayespilot.diagnose.shared_posterior` pooled); a failure
    there is recorded in the result's ``settings["posterior_error"]``, the
    diagnosis kept.

    Parameters
    ----------
    task : DiagnoseTask
        The diagnosis to make: one recording alone, or (``task.pooled``, more
        than one path) the runs of one condition by
        :func:`~bayespilot.diagnose.diagnose_pooled`.
    recordings : sequence of Recording
        The task's recordings, in the order of ``task.paths`` (for a task of
        one recording only the first is read).
    options : mapping of str to object
        Keywords of :func:`~bayespilot.diagnose.diagnose` (of
        :func:`~bayespilot.diagnose.diagnose_pooled` for a pooled task), the
        same for both, and ``posterior`` (bool, default False) as above; not
        modified.  ``options["seed"]`` is used as given: :func:`diagnose_batch`
        gives each task its own (:func:`task_seed`), not the batch's.  With
        ``posterior`` a single run's chain is seeded by ``options["seed"]``
        (default 0) too and its warnings are silenced;
        :func:`~bayespilot.diagnose.shared_posterior` takes its defaults.
    extensions : sequence of Extension
        Catalogue entries of one's own that ``options["candidates"]`` names,
        registered here first
        (:func:`~bayespilot.diagnose.catalogue.register_extension`): a
        worker is another process, which has only the built-in catalogue
        and what it is sent.

    Returns
    -------
    result : DiagnosisResult or PooledDiagnosisResult
        The diagnosis (pooled for a pooled task), with ``result.posterior``
        set when a posterior was asked for and made.
    elapsed : float
        Wall time of the diagnosis and its posterior, s.

    Raises
    ------
    ValueError
        A bad option value, an entry ``register_extension`` refuses or a
        recording the diagnosis refuses, as the diagnosis raises it.  A
        ValueError or RuntimeError of the posterior is not raised but
        recorded (above).
    TypeError
        An option that is not a keyword of the diagnosis, or a recording that
        is not a Recording.
    """
    from . import (diagnose, diagnose_pooled, get_extension, register_extension, sample_chosen,
                   shared_posterior)

    for ext in extensions:  # (again on a worker that has them: the same name replaces)
        register_extension(ext)
    opts = dict(options)
    want = bool(opts.pop("posterior", False))
    t0 = time.perf_counter()
    with warnings.catch_warnings():  # kept in the result (_notes), said by the batch once
        warnings.simplefilter("ignore", EvidenceWarning)
        if task.pooled:
            res = diagnose_pooled(list(recordings), **opts)
        else:
            res = diagnose(recordings[0], **opts)
    if want and res.chosen is not None and get_extension(res.physics).likelihood == "gls":
        try:
            if task.pooled:
                shared_posterior(res, list(recordings))
            else:
                with warnings.catch_warnings():  # a short chain says so in its own settings
                    warnings.simplefilter("ignore")
                    sample_chosen(res, recordings[0], seed=opts.get("seed", 0))
        except (ValueError, RuntimeError) as exc:
            res.settings["posterior_error"] = f"{type(exc).__name__}: {exc}"
    return res, time.perf_counter() - t0


def _run_on_worker(task: DiagnoseTask, recordings: Sequence[Recording],
                   options: Mapping[str, Any], extensions: Sequence[Extension] = ()
                   ) -> tuple[Any, float, dict[str, Any]]:
    """:func:`run_diagnose_task` as the batch's task, with where and by which code it ran:
    ``(result, elapsed, made)``, ``made`` the worker's ``host``, ``versions``
    (:func:`bayespilot.campaign._versions`) and its bayespilot release under
    :data:`~bayespilot._files.VERSION_KEY`.  Taken here, on the worker: the result file
    (written by the client) named the client's machine and versions, whichever worker had
    made its numbers (run_job records them so for replicate).  And ``warnings``: those the
    diagnosis issued (``category`` and ``message``, each once,
    :func:`bayespilot.campaign._warnings_once`), recorded, not issued (a worker printed each
    raw, with dask's line, a SilentChannelWarning once per candidate of a run without
    motion), but for its EvidenceWarnings, which the diagnosis keeps itself (:func:`_notes`),
    and libraries' notices to developers (as fit_batch's tasks leave them out)."""
    from .. import __version__
    from .._files import VERSION_KEY
    from ..campaign import _versions, _warnings_once

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for quiet in (DeprecationWarning, PendingDeprecationWarning, FutureWarning,
                      EvidenceWarning):
            warnings.simplefilter("ignore", quiet)
        res, elapsed = run_diagnose_task(task, recordings, options, extensions)
    return res, elapsed, {"host": platform.node(), "versions": _versions(),
                          VERSION_KEY: __version__, "warnings": _warnings_once(caught)}


def _notes(res: Any) -> list[tuple[str, type[EvidenceWarning]]]:
    """The EvidenceWarnings a diagnosis kept (``settings["evidence_notes"]``; a pooled one's
    per run), each text once, with its category: :class:`BaseFitWarning` for the note of a
    base fit on a bound (the text :func:`~bayespilot.diagnose._base_at_bounds_note` makes of
    the parameters kept beside it, ``settings["base_at_bounds"]`` or the run's
    ``base_at_bounds``), :class:`EvidenceWarning` for the others."""
    from . import _base_at_bounds_note

    notes: dict[str, type[EvidenceWarning]] = {}
    for part in (res.settings, *(getattr(res, "runs", None) or ())):
        edge = part.get("base_at_bounds")
        bound = _base_at_bounds_note(edge) if edge else None
        for note in part.get("evidence_notes", ()):
            notes.setdefault(note, BaseFitWarning if note == bound else EvidenceWarning)
    return list(notes.items())


def _warm() -> None:
    """One short diagnosis here, so that the workers load numba's cache (campaign module docs)."""
    from ..simulate import simulate
    from . import NAMES, diagnose

    with warnings.catch_warnings():  # (about this 20-s run of ours, not the user's)
        warnings.simplefilter("ignore", EvidenceWarning)
        diagnose(simulate(task="FD", motion_gain=1.0, remnant_fraction=0.2, seed=0,
                          duration=20.0).recording, seed=0, n_bootstrap=1,
                 candidates=NAMES)  # (the built-in entries, whatever is registered)


def _task_options(task: DiagnoseTask, options: Mapping[str, Any],
                  digests: Mapping[str, str]) -> dict[str, Any]:
    """The keywords ``task``'s diagnosis runs with: the batch's ``options`` with ``seed`` (the
    batch's) replaced by the task's own (:func:`task_seed`)."""
    return {**options, "seed": task_seed(options["seed"], [digests[p] for p in task.paths])}


#: The sidecar keys a diagnosis reads besides ``sample_rate_hz``, ``motion_gain`` and ``task``
#: (the task description: the loop the bootstrap simulates, and the forcing functions; module
#: docs of :mod:`bayespilot.diagnose`); ``subject``, ``run``, ``notes`` and unknown keys are not.
_READ_KEYS = ("control_gain", "controlled_element_gain", "controlled_element", "forcing")


def _recording_metadata(recording: Recording) -> dict[str, Any]:
    """What a diagnosis reads of a recording besides its signals (a result file's
    ``recording_metadata``, one per recording; what a resume compares with the signals'
    digests): ``sample_rate_hz``, ``motion_gain`` (K_theta), ``task``, and each of
    :data:`_READ_KEYS` the sidecar gives, as given (one left out is not filled in with its
    default: the diagnosis says when it takes one).  Not in the seed (:func:`task_seed`)."""
    d: dict[str, Any] = {"sample_rate_hz": float(recording.sample_rate_hz),
                         "motion_gain": float(recording.motion_gain), "task": recording.task}
    d.update({k: json_ready(recording.metadata[k]) for k in _READ_KEYS
              if k in recording.metadata})
    if "control_gain" in d:  # the value read, not how it was written (69e-2 is 0.69)
        d["control_gain"] = float(d["control_gain"])
    if isinstance(d.get("forcing"), dict):
        # the fields the diagnosis reads, as numbers: the lines' multiples ``n`` as integers,
        # as the format has them (6.0 is line 6; results written before this recorded 6.0,
        # which compares equal to 6 on resume), the rest as floats; a key of the lab's own
        # inside the forcing object is not read, as the format says of unknown keys
        f = d["forcing"]
        d["forcing"] = {"base_frequency": float(f["base_frequency"]),
                        **{part: {"n": [int(x) for x in f[part]["n"]],
                                  **{k: [float(x) for x in f[part][k]]
                                     for k in ("amplitude", "phase")}}
                           for part in ("target", "disturbance")}}
    return d


def _settings(task: DiagnoseTask, options: Mapping[str, Any],
              digests: Mapping[str, str],
              metadata: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, Any]:
    """What a result file records of how it was made: the recordings as given, their
    content's digests (``digests``: path -> :func:`~bayespilot.recording._signals_digest`;
    what a resume compares), what the diagnosis read of their sidecars (``metadata``: path ->
    :func:`_recording_metadata`; compared too, when the result records it) and the settings:
    the batch's ``options`` with ``seed`` the task's own (:func:`_task_options`) and
    ``batch_seed`` the batch's."""
    d: dict[str, Any] = {"recordings": list(task.paths)}
    d["recording_digests"] = [digests[p] for p in task.paths]
    if metadata is not None:
        d["recording_metadata"] = [metadata[p] for p in task.paths]
    d["settings"] = {**_task_options(task, options, digests), "batch_seed": options["seed"]}
    # (the summary's columns of a diagnosis an earlier batch left; on resume compared only
    # for a result that records no recording_metadata, which says more: _resume_view)
    d["condition"] = {"subject": task.subject, "task": task.task,
                      "motion_gain": task.motion_gain}
    return json.loads(json.dumps(d))


def _the_recording(path: Any) -> str:
    """The file a recording path names, as :func:`~bayespilot.io.read_recording` resolves it
    (a stem, its ``.csv`` and its ``.json`` are one recording): the absolute path of its CSV
    (or ``.mat``) file; the path as given if it no longer resolves."""
    from ..io import _resolve

    try:
        first = _resolve(Path(str(path)))[2]
        return str(Path(first).resolve())
    except Exception:  # noqa: BLE001 - a recording gone since (RecordingError), a bad path
        return str(path)


#: A number in a warning's text (what differs from one recording to the next in one reason:
#: "the record is 10 s long", "max |theta_ddot_m| = 0.12 rad/s^2").
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _read_recordings(paths: Sequence[str]) -> dict[str, Recording]:
    """Each of ``paths`` read (:func:`~bayespilot.io.read_recording`), by path, for a batch.

    The QuestionableRecordingWarnings of reading are said once per reason, not once per
    recording (:func:`_say_questionable`: a lab's hundreds of short runs gave hundreds of
    lines, on every call); other warnings pass on as they were.  The recordings that cannot be
    read are all named in one RecordingError, after those warnings; nothing is run."""
    from ..io import read_recording
    from ..recording import QuestionableRecordingWarning, RecordingError

    recs: dict[str, Recording] = {}
    bad: list[str] = []
    questioned: list[tuple[str, str, str]] = []  # (path, reason without the path, as said)
    others = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", QuestionableRecordingWarning)
        for p in paths:
            try:
                recs[p] = read_recording(p)
            except RecordingError as exc:
                bad.append(str(exc))
            source = recs[p].source if p in recs else None
            for w in caught:
                if not issubclass(w.category, QuestionableRecordingWarning):
                    others.append(w)
                    continue
                text = str(w.message)
                for prefix in (f"{source}: " if source else None, f"{p}: "):
                    if prefix and text.startswith(prefix):
                        text = text[len(prefix):]
                        break
                questioned.append((p, text, str(w.message)))
            del caught[:]
    for w in others:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    if bad:
        with suppress(Warning):  # (a warning made an error must not hide why)
            _say_questionable(questioned, len(paths))
        raise RecordingError(f"{len(bad)} of {len(paths)} recordings cannot be read; nothing "
                             "was run:\n  " + "\n  ".join(bad))
    _say_questionable(questioned, len(paths))
    return recs


def _say_questionable(questioned: Sequence[tuple[str, str, str]], total: int) -> None:
    """One :class:`~bayespilot.recording.QuestionableRecordingWarning` per reason of
    ``questioned`` (``(path, reason, message)``: the reason without the path, and the warning's
    text as reading the recording said it), naming how many of
    the ``total`` recordings and which (the first three, then "... (N in all)").  Reasons that
    differ in their numbers alone (a record of 10 s and one of 12 s) are one: said with one
    recording's text.  A reason of one recording is said as reading it says it."""
    from .._caller import warn_at_caller
    from ..campaign import _listed
    from ..recording import QuestionableRecordingWarning

    kinds: dict[str, list[tuple[str, str, str]]] = {}
    for p, reason, message in questioned:
        kinds.setdefault(_NUMBER.sub("#", reason), []).append((p, reason, message))
    for seen in kinds.values():
        names = sorted({p for p, _, _ in seen})
        first = min(reason for p, reason, _ in seen if p == names[0])
        if len(names) == 1:  # (each as read: one recording's own)
            texts = list(dict.fromkeys(message for _, _, message in seen))
        elif len({reason for _, reason, _ in seen}) == 1:
            texts = [f"{len(names)} of {total} recordings ({_listed(names, 3)}): {first}"]
        else:
            texts = [f"{len(names)} of {total} recordings ({_listed(names, 3)}), e.g. "
                     f"{names[0]}: {first}"]
        for text in texts:
            warn_at_caller(text, QuestionableRecordingWarning)


def _resume_view(stored: Mapping[str, Any], defaults: Mapping[str, Any], *,
                 by_content: bool = False, metadata: bool = False,
                 condition: bool = False) -> Any:
    """What must agree for a result file to count as done: its recordings and its settings
    with ``defaults`` filled in (``candidates=None`` as the whole built-in catalogue: a batch
    run with entries of one's own registered records its candidates by name).  The recordings
    by their content's digests (``by_content``, results that record them: the same runs
    from another working folder, or moved), else as the files they resolve to
    (:func:`_the_recording`); sorted either way (a pooled task's runs are in the files'
    order, which results made before that was so may not have).  With ``metadata`` (results
    that record ``recording_metadata``) also what the diagnosis read of each recording's
    sidecar (:func:`_recording_metadata`: K_theta, the sample rate, the task, the plant, the
    forcing), by its signals' digest; with ``condition`` (a result made before that was
    recorded, which records its ``condition``) the condition's task and K_theta, the
    sidecar values it does record."""
    recs = stored.get("recordings")
    if by_content:
        recs = stored.get("recording_digests")
    merged = _settings_view(stored, defaults)
    if not isinstance(recs, list) or merged is None:
        return None
    view = {"recordings": sorted(recs if by_content else (_the_recording(p) for p in recs)),
            "settings": merged}
    if metadata:
        meta, digests = stored.get("recording_metadata"), stored.get("recording_digests")
        if not (isinstance(meta, list) and isinstance(digests, list)
                and len(meta) == len(digests) and all(isinstance(m, dict) for m in meta)):
            return None
        view["metadata"] = dict(zip(map(str, digests), meta))
    if condition:
        cond = stored.get("condition")
        cond = cond if isinstance(cond, dict) else {}
        view["condition"] = {k: cond.get(k) for k in ("task", "motion_gain")}
    return view


def _compares_condition(stored: Mapping[str, Any]) -> bool:
    """True for a result that records no ``recording_metadata`` (made before it was) but
    records its condition's task and K_theta: those are compared on resume (a sidecar's
    ``motion_gain`` corrected since); other sidecar values it cannot be compared on."""
    cond = stored.get("condition")
    return ("recording_metadata" not in stored and isinstance(cond, dict)
            and cond.get("task") is not None and cond.get("motion_gain") is not None)


def _settings_view(stored: Mapping[str, Any], defaults: Mapping[str, Any]) -> Any:
    """A result (or error) file's settings with ``defaults`` filled in and
    ``candidates=None`` as the built-in catalogue (:func:`_resume_view`); None if it records
    none."""
    settings = stored.get("settings")
    if not isinstance(settings, dict):
        return None
    from .catalogue import NAMES

    merged = {**defaults, **settings}
    if merged.get("candidates") is None:  # None: the built-in catalogue, in its order
        merged["candidates"] = list(NAMES)
    return merged


def _batch_view(stored: Mapping[str, Any], defaults: Mapping[str, Any]) -> Any:
    """:func:`_settings_view` without the diagnosis's own ``seed`` (each diagnosis of a batch
    has its own, :func:`task_seed`): what the diagnoses of one batch share, ``batch_seed``
    among it; None if it records no settings."""
    view = _settings_view(stored, defaults)
    if view is not None:
        view.pop("seed", None)
    return view


def _seeded_by_batch(stored: Any) -> bool:
    """True for a result file written before seeds were drawn per diagnosis: its settings
    record no ``batch_seed`` (its ``seed`` is the batch's, which every diagnosis ran with)."""
    return (isinstance(stored, dict) and isinstance(stored.get("settings"), dict)
            and "batch_seed" not in stored["settings"])


def _earlier_tasks(tasks: Sequence[DiagnoseTask], out: Path, settings: Any,
                   defaults: Mapping[str, Any]) -> tuple[list[DiagnoseTask], list[str]]:
    """The diagnoses in ``out`` that are not ``tasks``': as tasks, those whose result file (or,
    for one that failed, error file) records ``settings`` (a :func:`_batch_view`: each its
    own seed, the same ``batch_seed``), sorted by key; and the keys of those made with other
    settings (a result of the earlier seeding, without ``batch_seed``, is among these: its
    settings differ from ``settings`` by that key).  Other JSON files are not results of a
    batch and are passed over."""
    from .. import campaign as C

    mine = {t.key for t in tasks}
    keys = sorted({f.name[:-len(".error.json")] if f.name.endswith(".error.json") else f.stem
                   for f in out.glob("*.json")} - mine)
    same, other = [], []
    for key in keys:
        stored = C._read_json(out / f"{key}.json")
        if not (isinstance(stored, dict) and stored.get("key") == key
                and "diagnosis" in stored):
            stored = C._read_json(out / f"{key}.error.json")
            if not (isinstance(stored, dict) and stored.get("key") == key
                    and isinstance(stored.get("recordings"), list)):
                continue
        view = _batch_view(stored, defaults)
        if view is None:
            continue
        if view != settings:
            other.append(key)
            continue
        cond = stored.get("condition") if isinstance(stored.get("condition"), dict) else {}
        same.append(DiagnoseTask(key, tuple(str(p) for p in stored.get("recordings") or ()),
                                 cond.get("subject"), cond.get("task"), cond.get("motion_gain")))
    return same, other


def _value_change(key: str, old: Mapping[str, Any], new: Mapping[str, Any]) -> str:
    """One sidecar value of two :func:`_recording_metadata`, for the refusal's message: a
    number or a name as it is, a plant or a forcing by its name alone."""
    def said(d: Mapping[str, Any]) -> str:
        if key not in d:
            return "not given"
        return repr(d[key]) if isinstance(d[key], (str, int, float, type(None))) else "given"

    if said(old) == said(new) == "given":
        return f"{key} changed"
    return f"{key} {said(old)} there, {said(new)} here"


def _differs(old: Any, new: Any, names: Mapping[str, str] | None = None) -> str:
    """What of two :func:`_resume_view` differs, for the refusal's message; ``names``: a
    recording's signals' digest -> its path here (to say which run of a pooled task)."""
    if not (isinstance(old, dict) and isinstance(new, dict)):
        return "it is not a result of this batch"
    if old["recordings"] != new["recordings"]:
        return "other recordings"
    said, changes = [], []  # (changes: per run, the sidecar values it reads that differ)
    if old.get("metadata") != new.get("metadata"):
        # (the runs by their names here: their digests' order differs from machine to
        # machine, with the simulated signals' last bits)
        for digest in sorted(new.get("metadata") or {},
                             key=lambda d: ((names or {}).get(d, d), d)):
            was, now = (old.get("metadata") or {}).get(digest, {}), new["metadata"][digest]
            keys = sorted(k for k in set(was) | set(now) if was.get(k) != now.get(k))
            where = f"{(names or {}).get(digest, digest)}: " if len(new["metadata"]) > 1 else ""
            changes += [where + ", ".join(_value_change(k, was, now) for k in keys)] if keys else []
    if old.get("condition") != new.get("condition"):  # (a result that records no metadata)
        changes.append(", ".join(_value_change(k, old["condition"], new["condition"])
                                 for k in ("task", "motion_gain")
                                 if old["condition"].get(k) != new["condition"].get(k)))
    if changes:
        said.append("the same signals with other sidecar values, which the diagnosis reads ("
                    + "; ".join(changes) + ")")
    keys = sorted(k for k in set(old["settings"]) | set(new["settings"])
                  if old["settings"].get(k) != new["settings"].get(k))
    if "batch_seed" in keys:  # (the diagnosis's seed follows from it)
        keys = [k for k in keys if k != "seed"]
    if keys or not said:
        def value(settings: Mapping[str, Any], k: str) -> str:  # (a setting one file lacks:
            return repr(settings[k]) if k in settings else "not set"  # not "None")

        said.append("other settings: " + ", ".join(f"{k} {value(old['settings'], k)} there, "
                                                   f"{value(new['settings'], k)} here"
                                                   for k in keys))
    return " and ".join(said)


#: The batch commands that write ``<key>.json`` and ``summary.csv`` into an output folder:
#: for each, what its result files have (a key the other's lack), what its error files have
#: (the context :func:`~bayespilot.campaign.run_keyed` writes with the error), the columns its
#: ``summary.csv`` has always had, and its Python function.
_BATCH_KINDS = {
    "fit-batch": {"result": "fit_threshold", "error": "recording",
                  "columns": {"key", "neg_log_lik_none", "delta_bic"},
                  "function": "bayespilot.batch.fit_batch", "what": "a fit"},
    "diagnose-batch": {"result": "diagnosis", "error": "recordings",
                       "columns": {"key", "physics", "mismatch"},
                       "function": "bayespilot.diagnose.batch.diagnose_batch",
                       "what": "a diagnosis"},
    "replicate": {"result": "job", "error": None,
                  "columns": {"task", "F_n", "K_theta", "N50", "paper_N50"},
                  "function": "bayespilot.campaign.run_campaign", "what": "a simulated fit"},
}


def _file_of(stored: Any, key: str, failed: bool) -> str | None:
    """Which command of :data:`_BATCH_KINDS` wrote the parsed file ``stored`` of ``key`` (an
    error file when ``failed``), or None (not a result of theirs)."""
    if not (isinstance(stored, dict) and stored.get("key") == key):
        return None
    for command, kind in _BATCH_KINDS.items():
        mark = kind["error" if failed else "result"]
        others = [k["result"] for c, k in _BATCH_KINDS.items() if c != command]
        if mark is not None and mark in stored and not any(k in stored for k in others):
            return command
    return None


def _summary_of(path: Path) -> str | None:
    """Which command of :data:`_BATCH_KINDS` wrote the CSV at ``path`` (by its header), "" for
    a CSV none of them wrote, None where there is none (or it is empty)."""
    import csv

    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            header = next(csv.reader(fh), None)
    except (OSError, UnicodeDecodeError, csv.Error):
        return "" if path.exists() else None
    if not header:
        return None
    return next((command for command, kind in _BATCH_KINDS.items()
                 if kind["columns"] <= set(header)), "")


def _refuse_another_commands_folder(out: Path, command: str, *, summary: bool = True) -> None:
    """Refuse (:class:`ResultConflictError`) an output folder that holds the results of
    another command, before anything runs.

    ``bayespilot fit-batch`` and ``bayespilot diagnose-batch`` (and ``replicate``) each write
    ``<key>.json`` and ``summary.csv`` (and ``summary.png``) in their folder: one run into the
    other's folder took the other's ``<key>.json`` for "not done" and replaced it, and its
    summary, without a word.  A folder is refused that holds a ``<key>.json`` (or
    ``<key>.error.json``) the other command wrote (by the keys only each writes:
    ``fit_threshold`` against ``diagnosis``), or a ``summary.csv`` that ``command`` did not
    write (by its header: the other's, or a file of one's own); the message names the files,
    says which command wrote them and to use another output folder.  ``summary=False``
    checks the result files only (for :func:`~bayespilot.campaign.run_campaign`, which
    writes no summary.csv: its caller may keep its own there)."""
    from .. import campaign as C

    if not out.is_dir():
        return
    theirs: dict[str, list[str]] = defaultdict(list)
    for f in sorted(out.glob("*.json")):
        failed = f.name.endswith(".error.json")
        key = f.name[:-len(".error.json")] if failed else f.stem
        stored = C._read_json(f)
        by = _file_of(stored, key, failed)
        if by is not None and by != command:
            theirs[by].append(f.name)
    summary = _summary_of(out / "summary.csv") if summary else None
    if not theirs and summary in (None, command):
        return
    said = []
    for by, names in sorted(theirs.items()):
        kind = _BATCH_KINDS[by]
        said.append(f"{len(names)} result file(s) of 'bayespilot {by}' ({kind['function']}: "
                    f"{kind['what']} each, with \"{kind['result']}\" where {command}'s have "
                    f"\"{_BATCH_KINDS[command]['result']}\"): {', '.join(names[:3])}"
                    f"{' ...' if len(names) > 3 else ''}")
    if summary not in (None, command):
        said.append(f"summary.csv of 'bayespilot {summary}'" if summary else
                    "a summary.csv that no bayespilot batch wrote (its columns are not "
                    f"{command}'s)")
    harm = [*(["mix its <key>.json results with theirs (neither command could resume "
               "the folder)"] if theirs else []),
            *(["replace that summary.csv with its own"] if summary not in (None, command)
              else [])]
    raise ResultConflictError(
        f"{out} holds {' and '.join(said)}: {command} would {' and '.join(harm)}; use another "
        f"output folder (--out) for {command}; nothing was run")


def diagnose_batch(paths: Sequence[str | Path], out_dir: str | Path, *, pool: bool = False,
                   seed: int = 0, alpha: float | None = None, n_bootstrap: int | None = None,
                   n_calibrate: int | None = None, noise_passes: int = 1,
                   candidates: Sequence[str | Extension] | None = None,
                   posterior: bool = False,
                   reports: bool = False, title: bool = True,
                   formats: Sequence[str] = ("png",), dpi: int | None = None,
                   scheduler: "str | Client | Cluster | None" = None,
                   workers: int | None = None,
                   progress: bool | str = True, connect_timeout: float = 10.0,
                   warm_cache: bool = True) -> "CampaignSummary":
    """Diagnose many recordings as independent tasks on dask.distributed.

    Parameters
    ----------
    paths : sequence of str or Path
        Recordings (stems, .csv, .json or .mat paths), as ``bayespilot diagnose`` takes them.
    out_dir : str or Path
        Created if missing; ``<key>.json`` per diagnosis and ``summary.csv`` (module docs).
    pool : bool
        Diagnose the runs of each subject and condition together (module docs).
    seed : int
        The batch's seed (>= 0).  Each diagnosis runs with its own seed,
        :func:`task_seed` of ``seed`` and its recordings' content, so that the
        diagnoses' bootstraps (base-fit starts, posterior chains) are
        independent draws, and a diagnosis's seed does not depend on the
        paths' order, the other recordings of the batch or a resume.  Each
        result records it (``settings["seed"]``, and ``seed`` in
        ``summary.csv``: ``diagnose(recording, seed=...)`` with the other
        settings repeats that diagnosis) beside ``settings["batch_seed"]``.
    alpha, n_bootstrap, n_calibrate, noise_passes, candidates
        As for :func:`~bayespilot.diagnose.diagnose` (None: its default), the
        same for every diagnosis.  ``candidates`` may give
        catalogue entries of one's own, registered here; every registered entry the
        diagnoses test (with ``candidates=None``: every registered entry)
        is sent to the workers with each task and registered there, and
        the result files record the candidates by name (with entries
        registered, ``candidates=None`` is recorded as the names it
        stands for).  An entry's ``build`` travels pickled by cloudpickle:
        one defined in the script or notebook is sent whole, one imported
        from a module of one's own must be importable on the workers.
    posterior : bool
        Where an extension fitted by the GLS likelihood is chosen, also its
        posterior: the extended model sampled by emcee for one run
        (:func:`~bayespilot.diagnose.sample_chosen`, tens of seconds to
        minutes), the shared parameters on a grid for a pooled condition
        (:func:`~bayespilot.diagnose.shared_posterior`, seconds).  In each
        result's ``diagnosis`` and in ``summary.csv`` (``posterior``: per new
        parameter the median and the 90 % interval).
    reports : bool
        Also write each diagnosis's report (PNG figures and HTML) to
        ``out_dir/<key>/``, for the diagnoses this call makes.  Not a setting
        of the result files: a diagnosis finished before is not redone, and
        if it has no report (it was made without ``reports``) a
        :class:`MissingReportWarning` names it (a report needs the traces,
        which the result file does not keep; delete its ``<key>.json`` and
        call again to redo it with its report).
    title : bool
        True (default): the figures with their titles; False: ``summary.png``
        and the reports' figures without (``title=False`` of
        :func:`~bayespilot.diagnose.report.plot_batch` and of the reports,
        for a paper whose captions say it).  Like ``reports`` and the two
        below, not a setting of the result files.
    formats : sequence of str
        The formats of the summary's figure, ``summary.<format>`` each
        (``"png"``, ``"pdf"``, ``"svg"``; default PNG only); each report
        writes its PNGs (its page embeds them) and, beside them, the others.
    dpi : int, optional
        The resolution of ``summary.png`` (default
        :data:`~bayespilot.diagnose.report.FIGURE_DPI`); a report's PNGs stay
        at that default.
    scheduler, workers, progress, connect_timeout, warm_cache
        As for :func:`~bayespilot.campaign.run_campaign` (the lines say
        diagnoses).

    Returns
    -------
    CampaignSummary
        ``total`` diagnoses, ``completed`` by this call, ``skipped`` (done
        before), ``failed`` with one line per key in ``errors``.

    Raises
    ------
    bayespilot.recording.RecordingError
        A recording cannot be read (every such file is named); nothing is run.
    ValueError
        A bad setting, recordings the settings do not suit (too short: every
        one named, one line each), keys that clash, ``pool`` without
        subjects, the same recording (the same signals) under two names in
        one pooled condition, an entry of one's
        own that ``register_extension`` refuses or that cannot be pickled,
        ``formats`` empty or naming one not in ``("png", "pdf", "svg")``, a
        ``dpi`` that is not a whole number >= 1, ``workers`` not a positive
        integer or given with ``scheduler``, ``connect_timeout`` not a positive
        number; nothing is run.
    ResultConflictError
        ``out_dir`` holds a result of the same key made from other recordings
        or settings (the message says which); nothing is run.  The recordings
        are compared by their content and by what the diagnosis reads of their
        sidecars (K_theta, the sample rate, the task, the plant, the forcing:
        a ``motion_gain`` corrected since is refused, named; module docs), the settings with the
        diagnosis's defaults filled in (``alpha=None`` and ``alpha=0.01`` are
        one), the seeds by ``batch_seed``.  Also results of the batch's keys
        written before seeds were drawn per diagnosis (they record no
        ``batch_seed``; module docs, "Seeds"), all named at once.  Also an
        ``out_dir`` that holds results of another command (``<key>.json`` of
        :func:`bayespilot.batch.fit_batch`, with ``fit_threshold``, or its
        ``summary.csv``: a ``summary.csv`` this function did not write), which
        the batch would replace: the message names them.  A CampaignError and a
        ValueError.
    CampaignError
        The cluster cannot be reached or started or is lost during the run
        (what finished is saved), ``out_dir`` cannot be written in (checked
        before computing) or a result or the summary cannot be written (every
        diagnosis is saved; the same call again writes the summary); a worker of the
        scheduler, Client or Cluster given lacks bayespilot or has another
        version of it (the workers are named; nothing is run), or a Client
        given is closed.
    TypeError
        A ``scheduler`` that is not an address (str), a
        ``distributed.Client`` or a ``distributed.deploy.Cluster``; a
        ``title`` that is not True or False (nothing is run).

    Warns
    -----
    MissingReportWarning
        ``reports`` and finished diagnoses without a report (above).
    SummaryScopeWarning
        ``out_dir`` holds diagnoses made with other settings, left out of
        ``summary.csv`` (which covers every diagnosis there made with these
        settings: this call's and earlier calls', module docs).
    EvidenceWarning
        Once per gap in the diagnoses' evidence (no forcing, a record not
        whole periods, ...), naming how many diagnoses and which have it;
        each result keeps its own in its settings.
    BaseFitWarning
        The same, for a base fit with a pilot parameter on a bound (a
        subclass of EvidenceWarning, issued as what it was in the diagnosis).
    RuntimeWarning
        Once per kind of the other warnings the diagnoses issued on the
        workers (a SilentChannelWarning of a run without motion, ...), naming
        how many diagnoses and which, with one's message; each result file
        lists its own under ``warnings``.
    QuestionableRecordingWarning
        Once per reason reading the recordings gives (a short record, a low
        sample rate, ...), naming how many recordings and which; a reason of
        one recording as reading it says it.

    Examples
    --------
    >>> summary = diagnose_batch(["out/s1-run1", "out/s1-run2"], "diagnoses",
    ...                          workers=2)  # doctest: +SKIP
    """
    import inspect

    from .. import campaign as C
    from . import SKIP_SECONDS, _check, diagnose
    from .catalogue import Extension, _candidate_name, candidate_names, registered_extensions

    t0 = time.perf_counter()
    if not isinstance(posterior, bool):
        raise ValueError(f"posterior must be True or False, got {posterior!r}")
    figure = figure_options(title, formats, dpi)  # (checked before anything is run)
    # (a bad workers or connect_timeout was found only after every recording was read)
    C._check_cluster_options(scheduler, workers, progress, connect_timeout)
    paths = [str(p) for p in paths]
    if not paths:
        raise ValueError("no recordings given")
    # (a folder of fit-batch's: refused before the recordings are read)
    _refuse_another_commands_folder(Path(out_dir), "diagnose-batch")
    # a recording named twice (run.csv and run.json from one glob, or the same path) is one
    first: dict[str, str] = {}
    for p in paths:
        first.setdefault(_the_recording(p), p)
    paths = list(first.values())
    # (all read before any is refused; a reason to question many is said once, naming them)
    by_path = _read_recordings(paths)
    recs = [by_path[p] for p in paths]
    options = {"seed": seed, "noise_passes": noise_passes}
    for name, value in (("alpha", alpha), ("n_bootstrap", n_bootstrap),
                        ("n_calibrate", n_calibrate)):
        if value is not None:
            options[name] = value
    if isinstance(candidates, Extension):
        raise ValueError(f"candidates must be a list of catalogue names or entries, got the "
                         f"Extension {candidates.name!r} alone (write [entry])")
    if candidates is not None:  # (an entry of one's own registered here, then by its name)
        options["candidates"] = [_candidate_name(c) if isinstance(c, Extension) else c
                                 for c in candidates]
    elif registered_extensions():
        # None stands for the built-in catalogue and the registered entries: recorded by name,
        # so that a result made without them is not taken for one made with them
        options["candidates"] = list(candidate_names())
    # the entries of one's own the diagnoses test, sent to the workers with each task
    shipped = tuple(e for e in registered_extensions() if e.name in options.get("candidates", ()))
    _picklable(shipped)
    if posterior:  # (absent when False: results made before the option still resume)
        options["posterior"] = True
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    default = {k: v.default for k, v in inspect.signature(diagnose).parameters.items()}

    def check(rec: Recording, skip: float) -> None:
        _check(rec, options.get("alpha", default["alpha"]),
               options.get("n_bootstrap", default["n_bootstrap"]), skip,
               options.get("candidates"), 1,
               options.get("n_calibrate", default["n_calibrate"]), noise_passes)

    check(recs[0], 0.0)  # the settings (a bad one: its own error, not one per recording)
    unfit = []  # then what each recording must have for them (long enough), all named
    for rec, p in zip(recs, paths):
        try:
            check(rec, SKIP_SECONDS)
        except ValueError as exc:  # (the message names the recording, or is given its path)
            said = str(exc)
            unfit.append(said if (rec.source and rec.source in said) or p in said
                         else f"{p}: {said}")
    if unfit:
        raise ValueError(f"{len(unfit)} of {len(paths)} recordings cannot be diagnosed with "
                         f"these settings; nothing was run:\n  " + "\n  ".join(unfit))
    digests = {p: _signals_digest(r) for p, r in by_path.items()}
    tasks = plan_batch(paths, recs, pool=pool, digests=digests)
    metadata = {p: _recording_metadata(r) for p, r in by_path.items()}
    twice = []  # one run under two names (a copy) in a pooled condition: refused now, not
    for t in tasks:  # by the diagnosis on a worker
        seen: dict[str, str] = {}
        for p in t.paths:
            if digests[p] in seen:
                twice.append(f"{seen[digests[p]]} and {p}")
            seen.setdefault(digests[p], p)
    if twice:
        raise ValueError(f"the same recording under two names in one pooled condition: "
                         f"{'; '.join(twice)} hold the same signals (pooling them would count "
                         f"one run's evidence twice); give each run once")
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
        # a folder that exists but cannot be written in: said now, not after the first result
        # (one byte written, not an empty file: a full disk still makes an empty one)
        with replacing(out / ".bayespilot-write-check") as probe:
            probe.write_bytes(b"\0")
        (out / ".bayespilot-write-check").unlink()
    except OSError as exc:
        raise C.CampaignError(f"{out}: cannot write in the output folder "
                              f"({exc.strerror or exc})") from None
    # what an option left out means, so that a result made with it given (the CLI gives
    # every one) and one made without it (alpha=None) resume each other
    implied = json.loads(json.dumps(
        {**{k: default[k] for k in ("seed", "noise_passes", "alpha", "n_bootstrap",
                                    "n_calibrate", "candidates")}, "posterior": False}))
    found = {t.key: C._read_json(out / f"{t.key}.json") for t in tasks}
    found = {k: old for k, old in found.items()
             if isinstance(old, dict) and old.get("key") == k and "diagnosis" in old}
    by_batch = [k for k, old in found.items() if _seeded_by_batch(old)]
    if by_batch:  # (every diagnosis ran with the batch's seed: not this batch's diagnoses)
        n = len(by_batch)
        one = n == 1
        raise ResultConflictError(
            f"{out} holds {n} diagnos{'is' if one else 'es'} of this batch's keys "
            f"({', '.join(by_batch[:5])}{' ...' if n > 5 else ''}) made by an earlier "
            f"bayespilot, which ran every diagnosis of a batch with the batch's seed itself "
            f"(the seed {found[by_batch[0]]['settings'].get('seed')!r} recorded, no "
            f"batch_seed); each diagnosis now runs with its own seed drawn from the batch's "
            f"seed and its recordings, so {'it' if one else 'they'} would not be repeated by "
            f"this batch: use another output folder, or delete "
            f"{'its' if one else 'their'} <key>.json to redo {'it' if one else 'them'}")
    pending, skipped, unreported, as_drawn = [], 0, [], []
    for t in tasks:
        old = found.get(t.key)
        if old is None:
            pending.append(t)
            continue
        by_content = isinstance(old.get("recording_digests"), list)
        # what the diagnosis read of the sidecars (K_theta, the plant, the forcing) as the
        # result records it: all of it, or (made before that was recorded) its condition's
        # task and K_theta; a result that records neither resumes by its signals alone
        compare = {"metadata": "recording_metadata" in old,
                   "condition": _compares_condition(old)}
        was = _resume_view(old, implied, by_content=by_content, **compare)
        now = _resume_view(_settings(t, options, digests, metadata), implied,
                           by_content=by_content, **compare)
        if was != now:
            names = {digests[p]: p for p in t.paths}
            raise ResultConflictError(f"{out / (t.key + '.json')} holds a diagnosis of {t.key} "
                                      f"from {_differs(was, now, names)}; use another output "
                                      f"folder or delete it")
        skipped += 1
        if reports and not (out / t.key / "report.html").is_file():
            unreported.append(t.key)
        elif reports and any(figure[k] != _FIGURE_DEFAULTS[k] for k in ("title", "formats")):
            # (dpi is the summary figure's: a report is drawn at its own, so the command's
            # default --dpi, which is not None, said every report was drawn otherwise)
            as_drawn.append(t.key)
    if as_drawn:  # (--format, --no-title reach the reports this call draws only)
        n = len(as_drawn)
        warnings.warn(f"{n} report(s) of diagnoses finished before are left as they were "
                      f"drawn, not in the figure options asked for now ({', '.join(as_drawn[:5])}"
                      f"{' ...' if n > 5 else ''}): a report needs the diagnosis's traces, "
                      f"which <key>.json does not keep; delete a <key>.json and run again to "
                      f"redraw its report", MissingReportWarning, stacklevel=2)
    if unreported:
        n = len(unreported)
        one = n == 1
        warnings.warn(f"{n} diagnos{'is' if one else 'es'} finished before, without a "
                      f"report, {'is' if one else 'are'} not redone and get{'s' if one else ''} "
                      f"no report in {out}/<key>/ ({', '.join(unreported[:5])}"
                      f"{' ...' if n > 5 else ''}): "
                      f"a report needs the diagnosis's traces, which <key>.json does not "
                      f"keep; delete {'its' if n == 1 else 'their'} <key>.json and run "
                      f"again to redo {'it' if n == 1 else 'them'} with "
                      f"{'its report' if n == 1 else 'reports'}",
                      MissingReportWarning, stacklevel=2)

    by_key = {t.key: t for t in pending}

    def to_json(key: str, value) -> dict[str, Any]:
        res, elapsed, made = value  # (made: the worker's host and versions, _run_on_worker)
        made = dict(made)
        recorded = made.pop("warnings", [])  # (on the worker; said here once per kind)
        for w in recorded:
            warned[w["category"]].append((key, w["message"]))
        t = by_key[key]
        if reports:
            try:
                res.report(out / key, formats=figure["formats"], title=figure["title"])
            except OSError as exc:
                raise C.CampaignError(f"{out / key}: cannot write the report "
                                      f"({exc.strerror or exc})") from None
        for said in _notes(res):  # (silenced on the worker, said here once per text)
            noted.setdefault(said, []).append(key)
        return C._jsonable({"key": key, **_settings(t, options, digests, metadata),
                            "diagnosis": res.to_dict(), "warnings": recorded,
                            "elapsed_seconds": elapsed,
                            # (the worker's release, which dumps keeps, not the client's)
                            **made})

    noted: dict[tuple[str, type[EvidenceWarning]], list[str]] = {}
    warned: dict[str, list[tuple[str, str]]] = defaultdict(list)

    def say_warned() -> None:  # (by note and key, not in the order the diagnoses finished)
        for (note, category), keys in sorted(noted.items(), key=lambda item: item[0][0]):
            keys = sorted(keys)
            n = len(keys)
            warnings.warn(f"{n} diagnos{'is' if n == 1 else 'es'} ({', '.join(keys[:3])}"
                          f"{' ...' if n > 3 else ''}): {note}", category, stacklevel=3)
        C._say_each_kind(warned, "diagnosis(es)")

    try:
        completed, errors = C.run_keyed(
            [(t.key, _run_on_worker, (t, [by_path[p] for p in t.paths],
                                         _task_options(t, options, digests), shipped),
              _settings(t, options, digests, metadata)) for t in pending], out,
            total=len(tasks), skipped=skipped, scheduler=scheduler, workers=workers,
            progress=progress, connect_timeout=connect_timeout,
            warm=_warm if warm_cache else None, desc="diagnoses", unit="diagnosis",
            to_json=to_json, scatter=True)
    except BaseException:  # (the run stopped: what finished is saved, and its warnings said,
        with suppress(Warning):  # but a warning made an error must not hide why)
            say_warned()
        raise
    say_warned()
    settings = _batch_view({"settings": json.loads(json.dumps({**options,
                                                                "batch_seed": seed}))}, implied)
    earlier, other = _earlier_tasks(tasks, out, settings, implied)
    if other:
        n = len(other)
        warnings.warn(f"{out} holds {n} diagnos{'is' if n == 1 else 'es'} made with other "
                      f"settings ({', '.join(other[:5])}{' ...' if n > 5 else ''}), left out "
                      f"of summary.csv: it covers the diagnoses made with this batch's "
                      f"settings", SummaryScopeWarning, stacklevel=2)
    try:
        write_summary(sorted([*tasks, *earlier], key=lambda t: t.key), out, **figure)
    except OSError as exc:  # (a full disk: each diagnosis is saved)
        reason = " ".join(str(exc.strerror or exc).split())
        raise CampaignError(f"{out}: cannot write the summary table and figure ({reason}); "
                            f"each diagnosis is saved there: run the same command again to "
                            f"write them") from None
    return C.CampaignSummary(len(tasks), completed, skipped, len(errors), errors, out,
                             time.perf_counter() - t0, "diagnoses")


def _picklable(extensions: Sequence[Extension]) -> None:
    """Refuse, before the cluster starts, an entry that cannot be sent to the workers (dask
    pickles a task's arguments by cloudpickle)."""
    if not extensions:
        return
    import cloudpickle

    for ext in extensions:
        try:
            cloudpickle.dumps(ext)
        except Exception as exc:  # noqa: BLE001 - what pickle raises varies (TypeError, ...)
            raise ValueError(f"the extension {ext.name!r} cannot be sent to the workers: "
                             f"pickling it failed ({type(exc).__name__}: {exc}); give it a "
                             f"build function defined in the script or an importable "
                             f"module") from None


def _diagnoses(tasks: Sequence[DiagnoseTask], out: Path) -> dict[str, dict | None]:
    """Each task's diagnosis dict from its result file in ``out`` (None: no result)."""
    from .. import campaign as C

    found = {}
    for t in tasks:
        res = C._read_json(out / f"{t.key}.json")
        found[t.key] = res["diagnosis"] if isinstance(res, dict) and "diagnosis" in res else None
    return found


def _posterior_cell(d: Mapping[str, Any], chosen: Mapping[str, Any]) -> str:
    """JSON {new parameter: [median, 90 % lower, upper]} of a diagnosis dict's posterior (a
    single run's draws: the HDI; pooled: the central interval), or ''."""
    post = d.get("posterior")
    if not post:
        return ""
    if "marginals" in post:  # pooled: SharedPosterior.to_dict()
        cells = {n: [m["median"], *m["interval"]] for n, m in post["marginals"].items()}
    else:  # one run: posterior_dict
        cells = {}
        for n in chosen.get("params") or {}:
            p = post.get("params", {}).get(n)
            if p is not None:
                lo, hi = p.get("hdi_90", [math.nan, math.nan])
                cells[n] = [p.get("median"), lo, hi]
    return _cell(cells)


def _cell(obj: Any) -> str:
    """A summary CSV cell holding JSON: standard JSON (a missing number as null, not NaN)."""
    return json.dumps(json_ready(obj), allow_nan=False)


def batch_summary_rows(tasks: Sequence[DiagnoseTask], out_dir: str | Path,
                       diagnoses: Mapping[str, dict | None] | None = None
                       ) -> list[dict[str, Any]]:
    """One row per task from its result (or error) file in ``out_dir``: ``SUMMARY_FIELDS``.

    ``diagnoses``: the result files' diagnoses by key, if already read.

    Parameters
    ----------
    tasks : sequence of DiagnoseTask
        The batch's diagnoses (:func:`plan_batch`), one row each, in this order.
    out_dir : str or Path
        The folder of the result files ``<key>.json`` and the error files
        ``<key>.error.json``.
    diagnoses : mapping of str to dict or None, optional
        Each key's ``diagnosis`` dict (as ``DiagnosisResult.to_dict()`` or the
        pooled one makes it; None: no result), as :func:`write_summary` has
        read them; default: read from the result files in ``out_dir``.  A key
        without a diagnosis is looked up in its error file.

    Returns
    -------
    list of dict
        One dict per task with the keys of :data:`SUMMARY_FIELDS`: ``key``,
        ``n_runs``, ``subject`` ('' if none), ``task``, ``motion_gain``
        (K_theta); from a diagnosis its ``physics`` and ``mismatch``, the
        chosen candidate's ``p_value``, ``delta_neg_log_lik``, ``params``
        and ``interval`` (JSON text: name -> value, name -> [lower, upper])
        and ``posterior`` (JSON text: name -> [median, 90 % lower, upper], or
        ''), and among the candidates whose p-value is a number the smallest
        (``smallest_p_candidate``, ``smallest_p_value``: the nearest miss when
        the answer is ``none``); without one, ``error`` (the error file's
        ``"<error>: <message>"``, or ``"no result"``); and ``seed``, the
        seed the diagnosis ran with (:func:`task_seed`; ``diagnose(recording,
        seed=...)`` repeats it); ``units`` (JSON text: name -> unit of each
        parameter in ``params``, whose names ``interval`` and ``posterior`` share; ``"-"``
        dimensionless; '' for a file written before units were recorded).  Fields
        that do not apply are ''.
    """
    from .. import campaign as C

    out = Path(out_dir)
    if diagnoses is None:
        diagnoses = _diagnoses(tasks, out)
    rows = []
    for t in tasks:
        row = {"key": t.key, "n_runs": len(t.paths), "subject": t.subject or "",
               "task": t.task, "motion_gain": t.motion_gain, "physics": "", "mismatch": "",
               "p_value": "", "delta_neg_log_lik": "", "params": "", "interval": "",
               "posterior": "",
               "smallest_p_candidate": "", "smallest_p_value": "", "error": "", "seed": "",
               "units": ""}
        d = diagnoses.get(t.key)
        if d is not None:
            row.update(physics=d["physics"], mismatch=d["mismatch"])
            row["seed"] = (d.get("settings") or {}).get("seed", "")
            chosen = next((c for c in d["ranking"] if c["physics"] == d["physics"]), None)
            if chosen is not None:
                row.update(p_value=chosen.get("p_value"),
                           delta_neg_log_lik=chosen.get("delta_neg_log_lik"),
                           params=_cell(chosen.get("params") or {}),
                           interval=_cell({n: [iv["lower"], iv["upper"]] for n, iv in
                                           (chosen.get("interval") or {}).items()}),
                           posterior=_posterior_cell(d, chosen))
                units = d.get("units") or {}
                if units:
                    row["units"] = _cell({n: units[n] for n in chosen.get("params") or {}
                                          if n in units})
            tested = [c for c in d["ranking"] if isinstance(c.get("p_value"), (int, float))]
            if tested:  # the nearest miss when the answer is none
                best = min(tested, key=lambda c: c["p_value"])
                row.update(smallest_p_candidate=best["physics"], smallest_p_value=best["p_value"])
        else:
            err = C._read_json(out / f"{t.key}.error.json")
            row["error"] = (f"{err.get('error')}: {err.get('message')}"
                            if isinstance(err, dict) else "no result")
            if isinstance(err, dict) and isinstance(err.get("settings"), dict):
                row["seed"] = err["settings"].get("seed", "")
        rows.append(row)
    return rows


#: :func:`write_summary`'s figure options when not given (diagnose_batch's defaults).
_FIGURE_DEFAULTS = {"title": True, "formats": ("png",), "dpi": None}

#: The summary figure's height per diagnosis (in) beyond a page's diagnoses, so that
#: :func:`~bayespilot.diagnose.report.plot_batch` names every row (it names every k-th where
#: a row of its axes, before the layout, is narrower than 0.14 in: 0.19 in of figure gives
#: 0.146 in of axes at matplotlib's default subplot margins, 0.77 of the height) ...
SUMMARY_ROW_HEIGHT = 0.19
#: ... up to this height (in; matplotlib draws at most 2**16 pixels a side: 60 in is 36000 at
#: 600 dpi); a batch of more diagnoses than fit (about 315) has every k-th named.
SUMMARY_MAX_HEIGHT = 60.0


def _summary_figsize(n: int) -> tuple[float, float] | None:
    """The size of the summary figure of ``n`` diagnoses: None (plot_batch's own, a page at
    most) while a page names every row, else a page wide and :data:`SUMMARY_ROW_HEIGHT` per
    diagnosis, up to :data:`SUMMARY_MAX_HEIGHT`."""
    from ..plots import PAGE_HEIGHT, PAGE_WIDTH

    tall = SUMMARY_ROW_HEIGHT * n
    if tall <= PAGE_HEIGHT:
        return None
    return PAGE_WIDTH, min(tall, SUMMARY_MAX_HEIGHT)


def write_summary(tasks: Sequence[DiagnoseTask], out_dir: str | Path, *, title: bool = True,
                  formats: Sequence[str] = ("png",), dpi: int | None = None) -> Path:
    """Write ``out_dir/summary.csv`` (:func:`batch_summary_rows`) and, when any diagnosis
    finished, ``out_dir/summary.<format>`` for each of ``formats`` (default PNG,
    :func:`~bayespilot.diagnose.report.plot_batch` with ``title``, at ``dpi``, default
    :data:`~bayespilot.diagnose.report.FIGURE_DPI`; beyond a page's diagnoses the figure
    grows so that every one is named, :func:`_summary_figsize`); returns the CSV's path.

    The earlier figure is removed before the table is written, the new one drawn after it:
    a write that fails (a full disk: an OSError) never leaves a figure of other diagnoses
    beside a new table."""
    from .report import _remove_summary_figures, _write_summary_figure, plot_batch

    out = Path(out_dir)
    found = _diagnoses(tasks, out)
    _remove_summary_figures(out)
    path = write_csv_atomic(out / "summary.csv", SUMMARY_FIELDS,
                            batch_summary_rows(tasks, out, found))
    done = [(key, d) for key, d in found.items() if d is not None]
    formats = figure_options(title, formats, dpi)["formats"]
    _write_summary_figure((lambda: plot_batch(done, title=title,
                                              figsize=_summary_figsize(len(done))))
                          if done else None, out, formats, dpi)
    return path

"""The Monte Carlo study of Section III.B.2 as a campaign of independent fits on dask.distributed.

A campaign is a list of :class:`Job` (one simulated remnant realization, one
fit); :func:`paper_study` builds the paper's grid (task x K_theta x F_n x
realization, with and without threshold).  :func:`run_campaign` sends the jobs
to a dask cluster and writes every finished fit to ``out_dir/<key>.json`` as
it arrives; :func:`load_results` reads them back and :func:`summarise` gives
the Figs. 14/15 numbers (mu, sigma, N50%) beside the paper's.

Seeds
-----
Every number of a job follows from its fields.  The remnant seed is derived
from (task, K_theta, F_n, realization) only, so the fits with and without
threshold, and by either method, see the same recording (a paired
comparison, as in Fig. 11).  The fit seed (GA / Latin-hypercube starts) comes
from the same four fields through a separate stream of the same
``numpy.random.SeedSequence``, so it is independent of the remnant.  Both are
``SeedSequence([SEED_ROOT, stream, task code, round(1e4 K_theta),
round(1e4 F_n), realization]).generate_state(1, uint64)[0] >> 1`` with stream
0 for the remnant and 1 for the fit (see :func:`job_seed`).

Resume semantics
----------------
A result file is written atomically (a temporary file in the same folder,
then ``os.replace``) as soon as its fit finishes, so a file that exists is
complete.  Running the same jobs again skips every job whose file exists and
parses (its fit is not redone); a file that does not parse is redone.  A job
that raised leaves ``<key>.error.json`` (type, message, traceback) and the
campaign goes on; the next run retries it and removes the error file once it
succeeds.  A result file written for other settings of the same key (other
fit options) is an error, not a silent mix.

Numba and the workers
---------------------
The kernels are compiled with ``cache=True`` (:mod:`bayespilot._jit`), so a
process loads compiled code from the on-disk cache instead of compiling.
Before submitting, :func:`run_campaign` runs one tiny simulation and fit of
each method in the client process: this fills the cache once, and the
workers, which import the kernels only when their first job arrives, load it
instead of each compiling every kernel (tens of seconds each) at the same
time.  Workers of a remote cluster profit
only if they share the package folder (or ``NUMBA_CACHE_DIR``) with the client.
A local cluster gives each worker ``cpu_count // workers`` numba threads, so
the parallel GA kernel does not oversubscribe the cores.
"""

from __future__ import annotations

import inspect
import json
import logging
import math
import os
import platform
import sys
import time
import traceback
import warnings
from contextlib import ExitStack, contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable, Mapping, Sequence

import numpy as np

from . import presets
from ._caller import warn_at_caller
from ._html import SummaryHTML
from ._interrupt import caused_by_interrupt

if TYPE_CHECKING:  # (only named in annotations: distributed is imported when a campaign runs)
    from distributed import Client
    from distributed.deploy import Cluster

__all__ = ["Job", "CampaignError", "CampaignSummary", "paper_study", "run_job", "run_campaign",
           "load_results", "summarise", "summary_markdown", "write_summary_csv", "job_seed",
           "SEED_ROOT", "TRUE_DELTA_ABS", "WorkerVersionError"]

#: Root entropy of every seed of a campaign (arbitrary, fixed: the paper's year and issue).
SEED_ROOT = 2012_035_003
#: The true threshold of the simulation study (Table 3, both tasks), IPUT.
TRUE_DELTA_ABS = presets.TABLE3["FD"]["delta_abs"]
_TASK_CODE = {"FD": 1, "FT": 2}
_STREAMS = {"remnant": 0, "fit": 1}
_METHODS = ("paper", "fast")


class CampaignError(RuntimeError):
    """A campaign cannot run: the scheduler is unreachable, results cannot be written, ... ."""


def job_seed(stream: str, task: str, motion_gain: float, remnant_fraction: float,
             realization: int) -> int:
    """The seed of ``stream`` ("remnant" or "fit") for one cell and realization (module docs).

    Parameters
    ----------
    stream : {"remnant", "fit"}
        Which of the job's two independent streams: the simulated remnant
        noise (stream 0) or the fit's GA / Latin-hypercube starts (stream 1).
    task : {"FD", "FT"}
        The task of the cell.
    motion_gain : float
        K_theta of the cell; it enters as ``round(1e4 K_theta)``, so gains
        equal to four decimals (e.g. ``1`` and ``1.0``) give the same seed.
    remnant_fraction : float
        F_n of the cell, entered as ``round(1e4 F_n)`` in the same way.
    realization : int
        Realization number.

    Returns
    -------
    int
        A seed in [0, 2**63): the first uint64 of the ``SeedSequence``,
        shifted right by one bit.

    Raises
    ------
    ValueError
        If ``stream`` is not "remnant" or "fit", or ``task`` not "FD" or "FT".

    Examples
    --------
    >>> job_seed("remnant", "FD", 1.0, 0.2, 7) == job_seed("remnant", "FD", 1, 0.2, 7)
    True
    >>> job_seed("remnant", "FD", 1.0, 0.2, 7) != job_seed("fit", "FD", 1.0, 0.2, 7)
    True
    """
    if stream not in _STREAMS:
        raise ValueError(f"stream must be 'remnant' or 'fit', got {stream!r}")
    if task not in _TASK_CODE:
        raise ValueError(f"task must be one of {', '.join(_TASK_CODE)}, got {task!r}")
    entropy = [SEED_ROOT, _STREAMS[stream], _TASK_CODE[task], int(round(1e4 * motion_gain)),
               int(round(1e4 * remnant_fraction)), int(realization)]
    return int(np.random.SeedSequence(entropy).generate_state(1, np.uint64)[0] >> np.uint64(1))


def _fit_function(method: str):
    if method == "paper":
        from .fit.three_step import fit_paper
        return fit_paper
    from .fit.fast import fit_fast
    return fit_fast


def _fit_option_names(method: str) -> tuple[str, ...]:
    sig = inspect.signature(_fit_function(method))
    return tuple(n for n, p in sig.parameters.items()
                 if p.kind == p.KEYWORD_ONLY and n not in ("threshold", "seed", "progress"))


def _bool_option_names(method: str) -> tuple[str, ...]:
    """The fit options whose default is a bool (e.g. ``iterate``): they take True or False only."""
    sig = inspect.signature(_fit_function(method))
    return tuple(n for n in _fit_option_names(method)
                 if isinstance(sig.parameters[n].default, bool))


def _json_roundtrip(obj: Any) -> Any:
    return json.loads(json.dumps(obj))


@dataclass(frozen=True)
class Job:
    """One fit of the campaign: a simulated realization and how to fit it.

    Parameters
    ----------
    task : {"FD", "FT"}
    motion_gain : float
        K_theta.
    remnant_fraction : float
        F_n in [0, 1); 0 simulates without remnant.
    realization : int
        Realization number >= 0 (sets the seeds, see the module docs).
    threshold : bool
        Fit the model with (True) or without (False) threshold.
    method : {"paper", "fast"}
        :func:`~bayespilot.fit.three_step.fit_paper` or
        :func:`~bayespilot.fit.fast.fit_fast`.
    fit_kwargs : dict
        Further keyword arguments of the fit function (e.g. ``repetitions``),
        JSON-serialisable.  An option whose default is a bool (``iterate``
        of the paper method) must be True or False: a string such as
        ``"False"`` is refused, not taken for its truth value.
    duration : float or None
        Measurement time of the simulated run, s (None: the paper's 81.92 s).
    remnant : {"fraction", "table4"}
        How the remnant gain K_n is set: ``"fraction"`` calibrates K_n on each
        realization so that it reaches F_n exactly; ``"table4"`` uses the gain
        the paper lists for the cell in its Table 4, the same for every
        realization, as the paper did ("The values of K_n used to achieve
        these remnant fractions ... are listed in Table 4"); the fraction each
        realization then reaches is recorded.  ``"table4"`` needs a cell of
        Table 4 (F_n 0.1, 0.2, 0.25, 0.3; K_theta 0.25, 0.5, 0.75, 1) or F_n = 0.

    Attributes
    ----------
    key : str
        Stable name of the job and of its result file, e.g.
        ``FD_k1_fn0.2_r007_thr_paper`` (``_kn4`` appended for Table 4 gains,
        ``_T20`` for a 20-s run).
    remnant_seed, fit_seed : int
        The seeds of the simulated remnant and of the fit (:func:`job_seed`).

    Raises
    ------
    ValueError
        If a field is out of its range or of the wrong kind (a task other
        than "FD"/"FT", K_theta < 0, F_n outside [0, 1), a negative or
        non-integer realization, ``threshold`` not a bool, an unknown method,
        an option the method does not take or that is not JSON-serialisable,
        a duration that is not a positive number), or ``remnant="table4"``
        for a cell Table 4 does not list.

    Examples
    --------
    >>> Job("FD", 1.0, 0.2, 7).key
    'FD_k1_fn0.2_r007_thr_paper'
    >>> Job("FT", 0.25, 0.0, 12, threshold=False, method="fast", duration=20).key
    'FT_k0.25_fn0_r012_nothr_fast_T20'
    >>> Job("FD", 0.25, 0.3, 0, remnant="table4").key
    'FD_k0.25_fn0.3_r000_thr_paper_kn4'
    """

    task: str
    motion_gain: float
    remnant_fraction: float
    realization: int
    threshold: bool = True
    method: str = "paper"
    fit_kwargs: dict[str, Any] = field(default_factory=dict, hash=False)
    duration: float | None = None
    remnant: str = "fraction"

    def __post_init__(self) -> None:
        if self.task not in _TASK_CODE:
            raise ValueError(f"task must be 'FD' or 'FT', got {self.task!r}")
        for name in ("motion_gain", "remnant_fraction"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                    or not math.isfinite(v):
                raise ValueError(f"{name} must be a finite number, got {v!r}")
            object.__setattr__(self, name, float(v))
        if self.motion_gain < 0:
            raise ValueError(f"motion_gain must be >= 0, got {self.motion_gain}")
        if not 0.0 <= self.remnant_fraction < 1.0:
            raise ValueError(f"remnant_fraction must be in [0, 1), got {self.remnant_fraction}")
        if isinstance(self.realization, bool) or not isinstance(self.realization, (int, np.integer)) \
                or self.realization < 0:
            raise ValueError(f"realization must be an integer >= 0, got {self.realization!r}")
        object.__setattr__(self, "realization", int(self.realization))
        if not isinstance(self.threshold, (bool, np.bool_)):
            raise ValueError(f"threshold must be True or False, got {self.threshold!r}")
        object.__setattr__(self, "threshold", bool(self.threshold))
        if self.method not in _METHODS:
            raise ValueError(f"method must be 'paper' or 'fast', got {self.method!r}")
        if not isinstance(self.fit_kwargs, Mapping):
            raise ValueError(f"fit_kwargs must be a dict, got {type(self.fit_kwargs).__name__}")
        allowed = _fit_option_names(self.method)
        unknown = [k for k in self.fit_kwargs if k not in allowed]
        if unknown:
            raise ValueError(f"unknown option(s) {', '.join(map(repr, unknown))} for the "
                             f"{self.method} method; valid are {', '.join(allowed)}")
        for name in _bool_option_names(self.method):
            v = self.fit_kwargs.get(name, False)
            if not isinstance(v, bool):
                raise ValueError(f"option {name} must be True or False, got {v!r}")
        try:
            kw = _json_roundtrip(dict(self.fit_kwargs))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"fit_kwargs must be JSON-serialisable ({exc})") from None
        object.__setattr__(self, "fit_kwargs", kw)
        if self.duration is not None:
            d = self.duration
            if isinstance(d, bool) or not isinstance(d, (int, float, np.floating, np.integer)) \
                    or not (math.isfinite(d) and d > 0):
                raise ValueError(f"duration must be a positive number of seconds or None, got {d!r}")
            object.__setattr__(self, "duration", float(d))
        if self.remnant not in ("fraction", "table4"):
            raise ValueError(f"remnant must be 'fraction' or 'table4', got {self.remnant!r}")
        if self.remnant == "table4" and self.remnant_fraction > 0:
            self.remnant_gain  # a cell that Table 4 does not list raises here

    @property
    def remnant_gain(self) -> float | None:
        """K_n of Table 4 for this cell (``remnant="table4"``), 0 for F_n = 0, else None."""
        if self.remnant != "table4":
            return None
        if self.remnant_fraction == 0:
            return 0.0
        row = presets.TABLE4_K_N.get((self.task, self.remnant_fraction))
        gains = tuple(presets.MOTION_GAINS)
        if row is None or self.motion_gain not in gains:
            raise ValueError(f"Table 4 lists no remnant gain for {self.task}, F_n = "
                             f"{self.remnant_fraction:g}, K_theta = {self.motion_gain:g} "
                             f"(it has F_n 0.1, 0.2, 0.25, 0.3 and K_theta "
                             f"{', '.join(f'{g:g}' for g in gains)}); use remnant='fraction'")
        return float(row[gains.index(self.motion_gain)])

    @property
    def key(self) -> str:
        """Stable name of the job and of its result file, e.g. ``FD_k1_fn0.2_r007_thr_paper``."""
        k = (f"{self.task}_k{self.motion_gain:g}_fn{self.remnant_fraction:g}_r{self.realization:03d}"
             f"_{'thr' if self.threshold else 'nothr'}_{self.method}")
        if self.remnant == "table4":
            k += "_kn4"
        return k if self.duration is None else f"{k}_T{self.duration:g}"

    @property
    def remnant_seed(self) -> int:
        """Seed of the simulated remnant, the same for every job of the cell and realization
        (with and without threshold, either method: :func:`job_seed` ``("remnant", ...)``)."""
        return job_seed("remnant", self.task, self.motion_gain, self.remnant_fraction,
                        self.realization)

    @property
    def fit_seed(self) -> int:
        """Seed of the fit's GA or Latin-hypercube starts (:func:`job_seed` ``("fit", ...)``),
        independent of :attr:`remnant_seed`."""
        return job_seed("fit", self.task, self.motion_gain, self.remnant_fraction, self.realization)

    def to_dict(self) -> dict[str, Any]:
        """The fields as a JSON-ready dict (what a result file stores under ``"job"``)."""
        return {"task": self.task, "motion_gain": self.motion_gain,
                "remnant_fraction": self.remnant_fraction, "realization": self.realization,
                "threshold": self.threshold, "method": self.method,
                "fit_kwargs": dict(self.fit_kwargs), "duration": self.duration,
                "remnant": self.remnant}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Job":
        """The job a :meth:`to_dict` holds.

        Parameters
        ----------
        d : mapping
            ``task``, ``motion_gain``, ``remnant_fraction`` and ``realization``;
            the other fields optional (their defaults when absent).

        Returns
        -------
        Job

        Raises
        ------
        KeyError
            If a required field is missing.
        ValueError
            If a field is invalid (see :class:`Job`).
        """
        return cls(d["task"], d["motion_gain"], d["remnant_fraction"], d["realization"],
                   d.get("threshold", True), d.get("method", "paper"), d.get("fit_kwargs", {}),
                   d.get("duration"), d.get("remnant", "fraction"))


def paper_study(realizations: int = 100, tasks: Sequence[str] = ("FD", "FT"),
                motion_gains: Sequence[float] = presets.MOTION_GAINS,
                remnant_fractions: Sequence[float] = (0.0, 0.1, 0.2, 0.25, 0.3),
                threshold: bool | Sequence[bool] = (True, False), method: str = "paper", *,
                duration: float | None = None, remnant: str = "fraction",
                first_realization: int = 0, **fit_kwargs: Any) -> list[Job]:
    """The jobs of the simulation study of Section III.B.2 (Figs. 14 and 15).

    Parameters
    ----------
    realizations : int
        Remnant realizations per cell (the paper: 100).
    tasks, motion_gains, remnant_fractions
        The grid.
    threshold : bool or sequence of bool
        Fit with threshold, without, or both (default).
    method : {"paper", "fast"}
    duration : float, optional
        Shorter simulated runs (s), for smoke tests.
    remnant : {"fraction", "table4"}
        K_n calibrated to F_n per realization, or the paper's Table 4 gains
        (see :class:`Job`).
    first_realization : int
        The realizations are numbered from this one (default 0): each number
        seeds its remnant and fit (:func:`job_seed`), so a study from 100 is
        an independent repeat of the one from 0 (the seeds' root is fixed,
        :data:`SEED_ROOT`), and the two can share an output folder.
    **fit_kwargs
        Options of the fit function, e.g. ``repetitions=2`` (see :class:`Job`).

    Returns
    -------
    list of Job
        Realization outermost, so that any leading part of the list covers
        every cell with a few realizations (useful for a campaign run in chunks).

    Examples
    --------
    >>> jobs = paper_study(2, tasks=("FD",), motion_gains=(1.0,), remnant_fractions=(0.2,))
    >>> [j.key for j in jobs]  # doctest: +NORMALIZE_WHITESPACE
    ['FD_k1_fn0.2_r000_thr_paper', 'FD_k1_fn0.2_r000_nothr_paper',
     'FD_k1_fn0.2_r001_thr_paper', 'FD_k1_fn0.2_r001_nothr_paper']
    >>> [j.realization for j in paper_study(2, tasks=("FD",), motion_gains=(1.0,),
    ...                                     remnant_fractions=(0.2,), threshold=True,
    ...                                     first_realization=100)]
    [100, 101]
    """
    if isinstance(realizations, bool) or not isinstance(realizations, (int, np.integer)) \
            or realizations < 1:
        raise ValueError(f"realizations must be a positive integer, got {realizations!r}")
    if isinstance(first_realization, bool) \
            or not isinstance(first_realization, (int, np.integer)) or first_realization < 0:
        raise ValueError(f"first_realization must be an integer >= 0, got "
                         f"{first_realization!r}")
    thresholds = (threshold,) if isinstance(threshold, (bool, np.bool_)) else tuple(threshold)
    for name, seq in (("tasks", tasks), ("motion_gains", motion_gains),
                      ("remnant_fractions", remnant_fractions), ("threshold", thresholds)):
        if isinstance(seq, str) or len(seq) == 0:
            raise ValueError(f"{name} must be a non-empty sequence, got {seq!r}")
    return [Job(task, k, fn, r, thr, method, dict(fit_kwargs), duration, remnant)
            for r in range(int(first_realization), int(first_realization) + int(realizations))
            for task in tasks for k in motion_gains
            for fn in remnant_fractions for thr in thresholds]


def _jsonable(obj: Any) -> Any:
    """Numpy scalars and arrays, tuples and mappings to plain JSON types."""
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    return obj


def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": platform.python_version()}
    for name in ("bayespilot", "numpy", "scipy", "numba", "distributed"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out


def _warnings_once(caught: Iterable[Any]) -> list[dict[str, str]]:
    """The warnings a task recorded (``warnings.catch_warnings(record=True)``) as its result
    file keeps them: ``category`` (the class's name) and ``message``, each once, in order."""
    said: list[dict[str, str]] = []
    for w in caught:
        entry = {"category": w.category.__name__, "message": str(w.message)}
        if entry not in said:
            said.append(entry)
    return said


def _say_each_kind(warned: Mapping[str, Sequence[tuple[str, str]]], what: str) -> None:
    """Say each kind of warning the tasks recorded once (``warned``: category -> (key,
    message) pairs): a RuntimeWarning naming how many tasks (``what``, e.g. "fit(s)") and
    which, with the message most of them share (ties: the first in order) and, where their
    messages differ, how many different ones there are."""
    for category, seen in sorted(warned.items()):
        keys = sorted({k for k, _ in seen})
        said_by: dict[str, set[str]] = {}
        for k, m in seen:
            said_by.setdefault(m, set()).add(k)
        # (a diagnosis without motion warns once per candidate: the example is the message
        # the most tasks share, not one candidate's picked by the alphabet)
        example = min(said_by, key=lambda m: (-len(said_by[m]), m))
        by = min(said_by[example])
        others = (f" ({len(said_by)} different messages in all)" if len(said_by) > 1 else "")
        warn_at_caller(f"{category} in {len(keys)} {what} ({_listed(keys, 3)}), e.g. "
                       f"{by}: {example}{others}; each result file lists its warnings under "
                       f"'warnings'", RuntimeWarning)


def run_job(job: Job) -> dict[str, Any]:
    """Simulate one realization and fit it; return a JSON-ready dict.

    Keys: ``key``; the job fields (``task``, ``motion_gain``,
    ``remnant_fraction``, ``realization``, ``threshold``, ``method``,
    ``fit_kwargs``, ``duration``) and the same under ``"job"``;
    ``remnant_seed``, ``fit_seed`` and the same as exact decimal text,
    ``remnant_seed_text``, ``fit_seed_text`` (the seeds reach 2**63; a reader
    that takes JSON numbers as doubles, such as jq or JavaScript, rounds the
    integers above 2**53), and so ``fit["seed_text"]`` beside ``fit["seed"]``;
    ``true_params``; ``K_n`` and ``F_n`` (the remnant gain and the fraction **reached**;
    ``remnant_fraction`` is the one asked for, the ``F_n`` of :func:`summarise`), and
    ``F_n_reached``, the same reached fraction under an unambiguous name; ``fit``
    (``FitResult.to_dict(full=False)``);
    ``step1_delta_abs`` and ``check`` (paper method with threshold only: the fit's own
    check, ``gap``, ``neg_log_lik`` and ``delta_abs``, see
    :class:`~bayespilot.fit.result.NotAtMaximumWarning`, which is not issued here);
    ``elapsed_seconds``
    (simulation and fit); ``host``; ``versions``; ``warnings``, those the
    simulation and the fit issued (``category``, ``message``; each once;
    :class:`~bayespilot.fit.result.NotAtMaximumWarning` left out), which
    are recorded instead of issued.

    Parameters
    ----------
    job : Job
        The realization to simulate (task, K_theta, F_n or the Table 4 gain,
        duration, :attr:`Job.remnant_seed`) and how to fit it (threshold,
        method, ``fit_kwargs``, :attr:`Job.fit_seed`).

    Returns
    -------
    dict
        The keys above, with plain JSON types only (numpy scalars and arrays
        converted); the job fields include ``remnant`` too, as in
        :meth:`Job.to_dict`.  ``F_n`` (and ``F_n_reached``) is 0 when the job has no
        remnant.

    Raises
    ------
    TypeError
        If ``job`` is not a :class:`Job`.

    Notes
    -----
    Errors of :func:`~bayespilot.simulate.simulate` and of the fit function
    pass through unchanged, e.g. a ValueError when the remnant fraction
    cannot be reached or a RuntimeError when the simulated closed loop
    diverges; :func:`run_campaign` records them in ``<key>.error.json``.
    """
    from .simulate import simulate

    if not isinstance(job, Job):
        raise TypeError(f"job must be a Job, got {type(job).__name__}")
    t0 = time.perf_counter()
    if job.remnant == "table4":
        noise = {"remnant_gain": job.remnant_gain}
    else:
        noise = {"remnant_fraction": job.remnant_fraction or None}
    from .fit.result import NotAtMaximumWarning

    # the warnings go into the result (a worker's stderr is a log nobody reads on a cluster,
    # and on a local one thousands of them buried the progress); run_campaign says them once
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        # (libraries' notices to developers are not the fit's; a study of the procedure: its
        # shortfall is recorded, under "check")
        for quiet in (DeprecationWarning, PendingDeprecationWarning, FutureWarning,
                      NotAtMaximumWarning):
            warnings.simplefilter("ignore", quiet)
        sim = simulate(task=job.task, motion_gain=job.motion_gain, seed=job.remnant_seed,
                       duration=job.duration, **noise)
        fit = _fit_function(job.method)(sim.recording, threshold=job.threshold,
                                        seed=job.fit_seed, **job.fit_kwargs)
    said = _warnings_once(caught)
    out: dict[str, Any] = {"key": job.key, **job.to_dict(), "job": job.to_dict(),
                           "remnant_seed": job.remnant_seed, "fit_seed": job.fit_seed,
                           # exact copies: readers of JSON numbers as doubles round seeds > 2**53
                           "remnant_seed_text": str(job.remnant_seed),
                           "fit_seed_text": str(job.fit_seed),
                           "true_params": dict(sim.params), "K_n": sim.remnant_gain,
                           "F_n": sim.remnant_fraction, "F_n_reached": sim.remnant_fraction,
                           "fit": fit.to_dict(full=False), "warnings": said}
    if isinstance(out["fit"].get("seed"), (int, np.integer)) \
            and not isinstance(out["fit"]["seed"], bool):
        out["fit"]["seed_text"] = str(out["fit"]["seed"])  # (the same seed, nested: as exact)
    step1 = fit.steps.get("step1_delta_abs")
    if step1 is not None:
        out["step1_delta_abs"] = step1
    check = fit.steps.get("check")
    if check is not None:  # how far short of a maximum the paper's single pass stopped
        out["check"] = {"gap": check["gap"], "neg_log_lik": check["neg_log_lik"],
                        "delta_abs": check["params"].get("delta_abs")}
    from . import __version__
    from ._files import VERSION_KEY

    # the worker's release, which made the numbers (the file's writer, the client, keeps it
    # and does not stamp its own)
    out.update({"elapsed_seconds": time.perf_counter() - t0, "host": platform.node(),
                "versions": _versions(), VERSION_KEY: __version__})
    return _jsonable(out)


@dataclass(frozen=True)
class CampaignSummary(SummaryHTML):
    """What :func:`run_campaign` did.

    Attributes
    ----------
    total : int
        Jobs asked for.
    completed : int
        Fits run and written by this call.
    skipped : int
        Jobs whose result file already existed and parsed (not redone).
    failed : int
        Jobs that raised (see ``errors`` and ``out_dir/<key>.error.json``).
    errors : dict
        key -> one-line message of each failure.
    out_dir : Path
        The folder of the result files.
    elapsed : float
        Wall time of the call, s.
    what : str
        What was run, for the printed summary ("fits", "diagnoses").
    """

    _html_text = "__str__"  # (a notebook shows its printed account)

    total: int
    completed: int
    skipped: int
    failed: int
    errors: dict[str, str]
    out_dir: Path
    elapsed: float
    what: str = "fits"

    @property
    def ok(self) -> bool:
        """True if no job failed."""
        return self.failed == 0

    def __str__(self) -> str:
        one = {"fits": "fit", "recordings": "recording", "diagnoses": "diagnosis"}
        what = one.get(self.what, self.what) if self.total == 1 else self.what
        return (f"{self.total} {what}: {self.completed} run, {self.skipped} already done, "
                f"{self.failed} failed ({self.elapsed:.1f} s) -> {self.out_dir}")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (a copy): the fields, with ``out_dir`` as text and ``elapsed`` as
        ``elapsed_seconds``, as in the package's other result files; ``json.dumps`` writes
        it, and :meth:`from_dict` reads it back."""
        return {"total": int(self.total), "completed": int(self.completed),
                "skipped": int(self.skipped), "failed": int(self.failed),
                "errors": {str(k): str(v) for k, v in self.errors.items()},
                "out_dir": str(self.out_dir), "elapsed_seconds": float(self.elapsed),
                "what": self.what}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "CampaignSummary":
        """The summary back from :meth:`to_dict` (parsed JSON); unknown keys (a later
        release's, ``bayespilot_version``) are ignored.

        Parameters
        ----------
        d : mapping
            A dict of :meth:`to_dict`, e.g. ``json.loads`` of a file it was written to.

        Returns
        -------
        CampaignSummary

        Raises
        ------
        ValueError
            If ``d`` lacks one of the keys :meth:`to_dict` writes (another kind of dict).
        """
        from ._files import require_keys

        require_keys(d, ("total", "completed", "skipped", "failed", "errors", "out_dir",
                         "elapsed_seconds"), "a campaign summary")
        return cls(int(d["total"]), int(d["completed"]), int(d["skipped"]), int(d["failed"]),
                   dict(d["errors"] or {}), Path(d["out_dir"]), float(d["elapsed_seconds"]),
                   d.get("what", "fits"))


def _result_path(out_dir: Path, job: Job) -> Path:
    return out_dir / f"{job.key}.json"


def _read_json(path: Path) -> Any:
    """The parsed file, or None if it is missing or does not parse."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return None


def _write_json_atomic(path: Path, obj: Any) -> None:
    from ._files import dumps, write_text_atomic

    try:
        write_text_atomic(path, dumps(obj))
    except OSError as exc:
        raise CampaignError(f"{path}: cannot write the result ({exc.strerror or exc})") from None


def _warm_numba_cache(methods: Iterable[str]) -> None:
    """One tiny simulation and fit per method and threshold setting, in this process.

    Fills numba's on-disk cache (``cache=True``) so that workers load the
    compiled kernels instead of each compiling them at the same time.
    """
    from .fit.fast import fit_fast
    from .fit.three_step import fit_paper
    from .simulate import simulate

    from .fit.result import NotAtMaximumWarning

    rec = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.1, seed=0, duration=2.0).recording
    for thr in (True, False):
        if "paper" in methods:
            with warnings.catch_warnings():  # (a 4 x 1 GA stops short: only compiling here)
                warnings.simplefilter("ignore", NotAtMaximumWarning)
                fit_paper(rec, threshold=thr, seed=0, repetitions=1, n_best=1, population=4,
                          generations=1, discard=0.0)  # the jobs' kernels: no discard
        if "fast" in methods:
            fit_fast(rec, threshold=thr, seed=0, n_starts=1, profile_step=0.05, discard=0.0)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def _check_scheduler(scheduler: Any) -> None:
    """A TypeError unless ``scheduler`` is None, an address, a Client or a Cluster."""
    if scheduler is None or isinstance(scheduler, str):
        return
    try:
        from distributed import Client
        from distributed.deploy import Cluster
    except ImportError:  # (then it cannot be one of theirs)
        pass
    else:
        if isinstance(scheduler, (Client, Cluster)):
            return
    raise TypeError(f"scheduler must be a dask scheduler's address (a str, e.g. "
                    f"'tcp://host:8786'), a distributed.Client, a distributed.deploy.Cluster "
                    f"(e.g. dask_jobqueue.SLURMCluster) or None (a local cluster), got "
                    f"{type(scheduler).__name__}")


def _scheduler_name(scheduler: Any) -> str:
    """How the messages name a scheduler: its address, also for a Client or a Cluster."""
    if isinstance(scheduler, str):
        return repr(scheduler)
    address = None
    try:
        address = getattr(scheduler, "scheduler_address", None)  # a Cluster
        if address is None:  # a Client
            address = getattr(getattr(scheduler, "scheduler", None), "address", None)
    except Exception:  # noqa: BLE001 - (a cluster that is gone: named by its type)
        pass
    kind = type(scheduler).__name__
    return (f"{address!r} (of the {kind} given)" if isinstance(address, str)
            else f"an unknown address (of the {kind} given)")


def _worker_numba_threads(workers: int, cpu_count: int | None = None,
                          environ: Mapping[str, str] | None = None) -> int:
    """The numba threads of each worker of a local cluster of ``workers`` processes.

    The cores shared among the workers, ``cpu_count // workers`` (at least 1; ``cpu_count``
    default :func:`os.cpu_count`), unless the user's ``NUMBA_NUM_THREADS`` (in ``environ``,
    default :data:`os.environ`) is a whole number >= 1 below it: that one, as the user asked
    (a higher one is not taken: the workers would oversubscribe the cores; a value that is
    not a whole number >= 1 is not the user's thread count, and the share is used)."""
    cpus = os.cpu_count() if cpu_count is None else cpu_count
    share = max(1, int(cpus or 1) // max(1, int(workers)))
    asked = (os.environ if environ is None else environ).get("NUMBA_NUM_THREADS", "")
    try:
        user = int(asked.strip())
    except ValueError:
        return share
    return min(share, user) if user >= 1 else share


def _connect(stack: ExitStack, scheduler: "str | Client | Cluster | None", workers: int | None,
             connect_timeout: float):
    """A distributed.Client: to ``scheduler``, or to a LocalCluster closed with ``stack``.

    A Client given is used as it is (not closed: it is the caller's); a Cluster given gets
    a Client of its own, closed with ``stack`` (the cluster is left running).  The workers of
    a cluster given must have this bayespilot (:func:`_check_workers`)."""
    from distributed import Client, LocalCluster

    if scheduler is None:
        n = int(workers or os.cpu_count() or 1)
        numba_threads = _worker_numba_threads(n)
        # Two attempts: a worker process that fails to come up (an AssertionError from the
        # nanny, as in dask/distributed#1286) failed one clean-clone test run here on
        # 2026-11-25 and did not recur on rerunning; a second failure is reported.
        for attempt in range(2):
            try:
                # (dashboard_address=None does not turn the dashboard off, dask/distributed
                # #8136: a random port instead of a warning that 8787 is taken)
                cluster = stack.enter_context(LocalCluster(
                    n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                    env={"NUMBA_NUM_THREADS": str(numba_threads)}))
                break
            except Exception as exc:
                if attempt == 1:
                    raise CampaignError(f"cannot start a local dask cluster with {n} workers "
                                        f"({_first_line(exc)})") from None
        return stack.enter_context(Client(cluster))
    where = _scheduler_name(scheduler)
    if isinstance(scheduler, Client):
        if getattr(scheduler, "asynchronous", False):
            raise TypeError("an asynchronous distributed.Client (asynchronous=True) cannot "
                            "run a campaign, which waits for its results; give its "
                            "scheduler's address (client.scheduler.address) instead")
        if scheduler.status != "running":
            raise CampaignError(f"the dask Client given is not connected to its scheduler "
                                f"(status {scheduler.status!r})")
        client = scheduler  # the caller's: used as it is, and not closed here
    else:
        client = _client_within(Client, scheduler, connect_timeout, name=where)
        stack.enter_context(client)
    try:
        client.wait_for_workers(1, timeout=connect_timeout)
    except (OSError, TimeoutError) as exc:
        raise CampaignError(f"the dask scheduler at {where} has no workers "
                            f"(waited {connect_timeout:g} s: {_first_line(exc)})") from None
    _check_workers(client, where)
    return client


def _listed(items: Sequence[str], most: int = 5) -> str:
    return ", ".join(items[:most]) + (f", ... ({len(items)} in all)" if len(items) > most else "")


def _check_workers(client: Any, where: str) -> None:
    """A CampaignError unless every worker of ``client`` has bayespilot at this process's version.

    Asked with ``client.run(importlib.metadata.version, "bayespilot")`` (a function every
    Python has, so that a worker without bayespilot answers with an error instead of failing
    to unpickle ours; a worker sent a task it cannot unpickle exits, and the campaign waited
    for ever with no worker, or lost that worker's capacity without a word)."""
    from importlib.metadata import PackageNotFoundError, version

    want = _installed_version()
    if want is None:  # (not installed here, run from a source folder: no version)
        return
    try:
        answers = client.run(version, "bayespilot", on_error="return")
    except Exception as exc:  # noqa: BLE001 - the scheduler went away, ...
        raise CampaignError(f"cannot ask the workers of the dask scheduler at {where} for "
                            f"their bayespilot version ({_first_line(exc)})") from None
    try:
        names = {a: w.get("name") for a, w in client.scheduler_info()["workers"].items()}
    except Exception:  # noqa: BLE001 - (the workers are then named by address only)
        names = {}

    def label(address: str) -> str:
        name = names.get(address)
        return address if name is None or str(name) == address else f"{name} ({address})"

    lacking, other, silent = [], [], []
    for address, answer in sorted(answers.items()):
        if isinstance(answer, PackageNotFoundError):
            lacking.append(address)
        elif isinstance(answer, BaseException):  # (gone since it registered, unreachable)
            silent.append(f"{label(address)}: {_first_line(answer)}")
        elif answer != want:
            other.append(f"{label(address)}: {answer}")
    if lacking:
        # no metadata is not no package: a worker importing bayespilot from a source folder
        # (PYTHONPATH) has it without a version to compare; said, not refused
        import importlib.util

        try:
            found = client.run(importlib.util.find_spec, "bayespilot", workers=lacking,
                               on_error="return")
        except Exception:  # noqa: BLE001 - then they count as lacking it
            found = {}
        unknown = [a for a in lacking if found.get(a) is not None
                   and not isinstance(found.get(a), BaseException)]
        lacking = [label(a) for a in lacking if a not in unknown]
        if unknown:
            warn_at_caller(f"{len(unknown)} dask worker(s) of the scheduler at {where} import "
                           f"bayespilot without an installed version (a source folder on "
                           f"PYTHONPATH?): it cannot be checked against this process's "
                           f"{want} ({_listed([label(a) for a in unknown])})", RuntimeWarning)
    if silent:  # (not refused: dask sends them no task if they are gone)
        warn_at_caller(f"{len(silent)} dask worker(s) of the scheduler at {where} did not say "
                       f"their bayespilot version ({_listed(silent)})", RuntimeWarning)
    if lacking or other:
        said = []
        if lacking:
            said.append(f"{len(lacking)} without it ({_listed(lacking)})")
        if other:
            said.append(f"{len(other)} with another version ({_listed(other)})")
        raise CampaignError(f"the dask workers of the scheduler at {where} must have "
                            f"bayespilot {want}, as this process has: {len(answers)} "
                            f"worker(s), {' and '.join(said)}; install bayespilot=={want} in "
                            f"the workers' environment (or stop those workers); nothing was "
                            f"run")


def _client_within(Client: Any, scheduler: "str | Cluster", connect_timeout: float, *,
                   name: str | None = None):
    """``Client(scheduler)``, or a CampaignError when it fails or does not answer in time.

    ``scheduler``: an address or a Cluster; ``name``: how the messages call it (default:
    its repr).

    Made in a thread that is given up after ``connect_timeout`` and a grace of
    :data:`CONNECT_GRACE` s: a port that answers but is not a dask scheduler (its
    dashboard's, 8787, given by mistake) kept ``Client`` waiting past its own timeout, and a
    peer answering something else made it fail with a MemoryError of exabytes."""
    import threading

    box: dict[str, Any] = {}

    def connect() -> None:
        try:
            box["client"] = Client(scheduler, timeout=f"{connect_timeout}s")
        except BaseException as exc:  # noqa: BLE001 - any failure is "cannot reach"
            box["error"] = exc

    worker = threading.Thread(target=connect, name="bayespilot-connect", daemon=True)
    worker.start()
    worker.join(connect_timeout + CONNECT_GRACE)
    where = repr(scheduler) if name is None else name
    if worker.is_alive():
        raise CampaignError(f"cannot reach the dask scheduler at {where}: no dask answer "
                            f"within {connect_timeout + CONNECT_GRACE:g} s (is it the "
                            f"scheduler's address, tcp://HOST:8786, not its dashboard's?)")
    if "error" in box:
        exc = box["error"]
        # (a peer that answers but speaks another protocol, e.g. HTTP, gets its reply read as
        # a dask frame length: a MemoryError of exabytes says nothing to the user)
        said = ("something answered there, but not in dask's protocol (is it the scheduler's "
                "address, tcp://HOST:8786, and not another service's?)"
                if isinstance(exc, MemoryError) else _first_line(exc))
        raise CampaignError(f"cannot reach the dask scheduler at {where} within "
                            f"{connect_timeout:g} s ({said})")
    return box["client"]


#: ``progress="lines"`` (a batch job's log, where a bar redrawn with carriage returns is noise):
#: a line when another 5 % of the tasks has finished, and one at least every minute (the run
#: is alive); the clock is looked at every second between tasks.
LINES_STEP = 0.05
LINES_EVERY = 60.0
_LINES_TICK = 1.0


def _check_cluster_options(scheduler: Any, workers: Any, progress: Any,
                           connect_timeout: Any) -> None:
    """The cluster options of run_campaign, diagnose_batch and fit_batch, checked before
    anything is read or run: ``scheduler`` (TypeError, :func:`_check_scheduler`),
    ``progress``; ``workers`` None or a positive integer and only without ``scheduler``, and
    ``connect_timeout`` a positive number of seconds (ValueError)."""
    import numbers

    _check_scheduler(scheduler)
    _check_progress(progress)
    if workers is not None:
        if scheduler is not None:
            raise ValueError(f"workers sets the size of the local cluster; do not give it "
                             f"with scheduler (got {workers!r} with a scheduler)")
        if isinstance(workers, bool) or not isinstance(workers, numbers.Integral) or workers < 1:
            raise ValueError(f"workers must be a positive integer, got {workers!r}")
    if isinstance(connect_timeout, bool) or not (isinstance(connect_timeout, numbers.Real)
                                                 and connect_timeout > 0):
        raise ValueError(f"connect_timeout must be a positive number of seconds, "
                         f"got {connect_timeout!r}")


def _check_progress(progress: Any) -> None:
    """A ValueError unless ``progress`` is True, False (or 1, 0), ``"bar"`` or ``"lines"``."""
    if not (isinstance(progress, (bool, np.bool_)) or progress in ("bar", "lines")
            or (isinstance(progress, (int, np.integer)) and progress in (0, 1))):
        raise ValueError(f"progress must be True or 'bar' (a bar), 'lines' (plain lines) or "
                         f"False (1 and 0 for True and False), got {progress!r}")


def _clock(seconds: float) -> str:
    """Seconds as H:MM:SS (tqdm's way)."""
    s = int(round(seconds))
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}"


class _ProgressLines:
    """The plain progress lines of :func:`run_keyed` (``progress="lines"``), counted where the
    tasks finish.  :meth:`line` is the line due at ``now`` with ``done`` tasks finished
    (``before`` of them before this run) and ``failed`` failed, if one is; :meth:`update` and
    :meth:`beat` write it.  Thread-safe: :func:`_beating` calls :meth:`beat` from a thread."""

    def __init__(self, total: int, before: int, what: str, now: float,
                 stream: Any = None) -> None:
        import threading

        self.total, self.before, self.what = total, before, what
        self.stream = sys.stderr if stream is None else stream
        self.start = self.last = now
        self.done, self.failed = before, 0
        self.said = before  # (finished at the last line)
        self._lock = threading.Lock()

    def line(self, now: float) -> str | None:
        done, failed = self.done, self.failed
        step = max(1, math.ceil(LINES_STEP * self.total))
        if (done + failed) // step <= self.said // step and now - self.last < LINES_EVERY:
            return None
        self.said, self.last = done + failed, now
        elapsed = now - self.start
        new = done + failed - self.before
        left = self.total - done - failed
        eta = f", about {_clock(elapsed / new * left)} left" if new > 0 and left > 0 else ""
        before = f", {self.before} before this run" if self.before else ""
        return (f"bayespilot: {done}/{self.total} {self.what} done, {failed} failed{before} "
                f"({_clock(elapsed)} elapsed{eta})")

    def update(self, done: int, failed: int, now: float | None = None) -> None:
        """Counts after a task finished; the line, if one is due."""
        with self._lock:
            self.done, self.failed = done, failed
        self.beat(now)

    def beat(self, now: float | None = None) -> None:
        """The line due now, if any: after :meth:`update`, or the minute's (no task finished
        for a minute)."""
        with self._lock:
            self._write(self.line(time.monotonic() if now is None else now))

    def _write(self, text: str | None) -> None:
        if text is None:
            return
        try:
            self.stream.write(text + "\n")  # (one write: not split by a warning's line)
            self.stream.flush()
        except (OSError, ValueError):  # (stderr gone: the run goes on)
            pass


@contextmanager
def _beating(lines: _ProgressLines | None):
    """:meth:`_ProgressLines.beat` every second from a thread while the block runs."""
    import threading

    if lines is None:
        yield
        return
    stop = threading.Event()

    def beat() -> None:
        while not stop.wait(_LINES_TICK):
            lines.beat()

    thread = threading.Thread(target=beat, name="bayespilot-progress", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()


def _installed_version() -> str | None:
    """bayespilot's installed version, None when run from a source folder (no metadata)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("bayespilot")
    except PackageNotFoundError:
        return None


class WorkerVersionError(RuntimeError):
    """A task ran on a dask worker whose bayespilot is another version than the client's."""


def _on_this_version(want: str, fn: Any, *args: Any) -> Any:
    """``fn(*args)`` on a worker, if its bayespilot is ``want`` (the client's version).

    :func:`_check_workers` asks the workers a cluster has when the run starts; a worker that
    joins later (an adaptive dask-jobqueue cluster) is checked by each task it is given: a
    task on another version fails with a WorkerVersionError (its error file says so) instead
    of writing a result of other code.  A worker importing bayespilot from a source folder
    (no installed version) runs it, as :func:`_check_workers` lets it."""
    have = _installed_version()
    if have is not None and have != want:
        import socket

        raise WorkerVersionError(f"the dask worker on {socket.gethostname()} has bayespilot "
                                 f"{have}, the client {want}; install bayespilot=={want} in "
                                 f"the workers' environment and run again to resume")
    return fn(*args)


def _cancel(client: Any, futures: Mapping[Any, Any]) -> None:
    """Cancel the futures not yet collected (none when the loop ran to its end)."""
    if not futures or getattr(client, "status", None) != "running":
        return
    try:
        client.cancel(list(futures))
    except Exception:  # noqa: BLE001 - (a scheduler gone: nothing left to cancel)
        pass


#: Seconds beyond ``connect_timeout`` that :func:`_client_within` waits for a connection.
CONNECT_GRACE = 5.0


def run_keyed(tasks: Sequence[tuple[str, Any, tuple, Mapping[str, Any]]], out: Path, *,
              total: int, skipped: int, scheduler: "str | Client | Cluster | None",
              workers: int | None,
              progress: bool | str, connect_timeout: float, warm: Any = None,
              desc: str = "fits",
              unit: str = "fit", to_json: Any = None,
              scatter: bool = False) -> tuple[int, dict[str, str]]:
    """Run keyed tasks on dask.distributed, writing ``out/<key>.json`` as each one finishes.

    The cluster loop that :func:`run_campaign` and
    :func:`bayespilot.diagnose.batch.diagnose_batch` share.  ``tasks``: one
    ``(key, function, args, context)`` each; ``function(*args)`` returns a
    JSON-ready dict, written atomically to ``out/<key>.json``; a task that raises
    leaves ``out/<key>.error.json`` (``context``, the error, its traceback) and
    the others go on; a success removes an old error file.  ``to_json(key,
    value)``, if given, turns a task's return value into that dict in this
    process (where it may also write files of its own).  ``warm``: called
    once in this process after connecting (numba's cache, module docs); a failure
    there is a warning, but an interrupt (Ctrl-C, which numba re-raises as a
    SystemError caused by the KeyboardInterrupt) is a KeyboardInterrupt, raised
    before anything is submitted.  ``progress``: as for :func:`run_campaign`;
    ``total`` and ``skipped`` set its count (tasks already done before the call),
    ``desc`` names the tasks (``unit`` one of them on the bar).  ``scatter``: send each task's arguments to
    the cluster first (one future per argument), so that large data (recordings)
    is not embedded in the task graph.  Returns ``(completed, {key: one-line
    error})``.  ``scheduler``, ``workers``, ``connect_timeout``: as for
    :func:`run_campaign` (a ``scheduler`` of another type is a TypeError, also with
    no task to run).  While the results come in, and until the client is closed, the
    ``distributed.client`` logger is silenced (a lost scheduler is this function's
    one-line CampaignError), unless its level is DEBUG or lower; its level is
    restored at the end.
    """
    _check_scheduler(scheduler)
    _check_progress(progress)
    completed, errors = 0, {}
    if not tasks:
        return completed, errors
    from distributed import as_completed
    from tqdm.auto import tqdm  # a widget in a notebook, text on a terminal

    with ExitStack() as stack:
        # (restored last, after the client is closed: its closing logs the lost scheduler too)
        client_log = logging.getLogger("distributed.client")
        stack.callback(client_log.setLevel, client_log.level)
        # connect first, so that an unreachable scheduler is reported at once
        client = _connect(stack, scheduler, workers, connect_timeout)
        if warm is not None:
            try:
                warm()
            except Exception as exc:  # not fatal: the workers then compile for themselves
                if caused_by_interrupt(exc):  # Ctrl-C in a numba kernel: stop, submit nothing
                    raise KeyboardInterrupt from exc
                warn_at_caller(f"warming numba's cache failed ({_first_line(exc)}); each "
                               f"worker compiles the kernels itself", RuntimeWarning)
        futures = {}
        # what is left of them when the loop ends early (Ctrl-C, an error writing a result)
        # is cancelled: a caller's Client, kept open, ran them on otherwise
        stack.callback(_cancel, client, futures)
        want = _installed_version()
        for key, fn, args, ctx in tasks:
            if scatter:  # each argument whole, as one future ([a]: not its items one by one)
                args = tuple(client.scatter([a], hash=False)[0] for a in args)
            if want is not None:  # (a worker that joined after _check_workers: checked here)
                args, fn = (want, fn, *args), _on_this_version
            futures[client.submit(fn, *args, pure=False)] = (key, ctx)
        bar = stack.enter_context(tqdm(total=total, initial=skipped, desc=desc, unit=unit,
                                       disable=progress not in (True, "bar"),
                                       file=sys.stderr, smoothing=0.1, dynamic_ncols=True))
        lines = (_ProgressLines(total, skipped, desc, time.monotonic())
                 if progress == "lines" else None)
        stack.enter_context(_beating(lines))
        lost = []
        if client_log.getEffectiveLevel() > logging.DEBUG:  # (unless asked for debugging)
            # a lost scheduler is reported below in one line; the client's reconnection
            # logged a 25-line traceback of its own before it
            client_log.setLevel(logging.CRITICAL)
        for fut in as_completed(futures):
            key, ctx = futures.pop(fut)
            if fut.status not in ("finished", "error"):  # cancelled, lost: not the task's fault
                lost.append(key)
                bar.update(1)
                continue
            if fut.status == "finished":
                value = fut.result()
                _write_json_atomic(out / f"{key}.json",
                                   value if to_json is None else to_json(key, value))
                completed += 1
                try:
                    (out / f"{key}.error.json").unlink()
                except FileNotFoundError:
                    pass
            else:
                exc = fut.exception()
                tb = fut.traceback()
                errors[key] = _first_line(exc)
                _write_json_atomic(out / f"{key}.error.json", {
                    "key": key, **ctx, "error": type(exc).__name__, "message": str(exc),
                    "traceback": "".join(traceback.format_tb(tb)) if tb is not None else None,
                    "time": time.strftime("%Y-%m-%dT%H:%M:%S%z")})
                bar.write(f"failed: {key}: {errors[key]}", file=sys.stderr)
            fut.release()
            bar.update(1)
            bar.set_postfix(failed=len(errors), refresh=False)
            if lines is not None:
                lines.update(skipped + completed, len(errors))
    if lost:
        raise CampaignError(f"lost the dask cluster: {len(lost)} of {len(tasks)} tasks did not "
                            f"finish ({completed} finished and were saved"
                            f"{f', {len(errors)} failed' if errors else ''}); run the same "
                            f"command again to resume")
    return completed, errors


def run_campaign(jobs: Iterable[Job], out_dir: str | Path, *,
                 scheduler: "str | Client | Cluster | None" = None,
                 workers: int | None = None, progress: bool | str = True,
                 connect_timeout: float = 10.0, warm_cache: bool = True) -> CampaignSummary:
    """Run the jobs on dask.distributed, writing ``out_dir/<key>.json`` as each fit finishes.

    Parameters
    ----------
    jobs : iterable of Job
        Keys must be unique.
    out_dir : str or Path
        Created if missing.  Jobs whose result file exists and parses are
        skipped (module docs, "Resume semantics").
    scheduler : str, distributed.Client or distributed.deploy.Cluster, optional
        A running dask cluster: the address of its scheduler
        (``"tcp://host:8786"``), a connected ``distributed.Client`` (used as
        it is and left open) or a ``Cluster`` object (``dask_jobqueue.SLURMCluster``,
        ``LocalCluster``, ...: connected to with a Client of its own, closed at
        the end; the cluster is left running).  Its workers must have
        bayespilot at the version of this process: they are asked after
        connecting, and a CampaignError names those that lack it or have
        another before anything is submitted; a worker that joins later
        is checked by each task it runs (a task on another version fails
        with a WorkerVersionError in its error file).  Tasks left when
        the call is interrupted or fails are cancelled, also on a Client
        given.  Default:
        a ``LocalCluster`` of ``workers`` single-threaded processes, started
        and closed here.  On a cluster of your own, start one single-threaded
        worker process per core, or set ``NUMBA_NUM_THREADS`` in the workers'
        environment so that the numba threads of the workers on one machine
        add up to its cores.
    workers : int, optional
        Workers of the local cluster (default ``os.cpu_count()``); not with
        ``scheduler``.
    progress : bool, 'bar' or 'lines'
        True or ``'bar'``: a tqdm bar on stderr, fits done / total, with the
        time left.  ``'lines'``: plain lines on stderr instead, for a batch
        job's log, where a bar redrawn in place is noise: one when another
        5 % of the fits has finished and one at least every minute, each
        ``bayespilot: <done>/<total> fits done, <n> failed (<elapsed> elapsed,
        about <left> left)``.  False: neither.
    connect_timeout : float
        Seconds to wait for the scheduler and for its first worker.
    warm_cache : bool
        Fill numba's cache in this process first (module docs).

    Returns
    -------
    CampaignSummary

    Raises
    ------
    CampaignError
        The scheduler cannot be reached (within ``connect_timeout``) or has no
        workers, a worker lacks bayespilot or has another version of it (the
        workers are named; nothing is run), a Client given is closed, a
        local cluster cannot start, a result cannot be written, or ``out_dir``
        holds a result of the same key for other settings, or results of
        :func:`~bayespilot.batch.fit_batch` or
        :func:`~bayespilot.diagnose.batch.diagnose_batch` (a
        :class:`~bayespilot.diagnose.batch.ResultConflictError`, nothing run).
    ValueError
        Duplicate keys, ``workers`` < 1 or given with ``scheduler``, another
        ``progress``.
    TypeError
        A ``scheduler`` that is not an address, a Client or a Cluster, or
        an asynchronous Client.

    Warns
    -----
    RuntimeWarning
        Once per kind of warning the fits of this call issued on the workers
        (a QuestionableRecordingWarning, an EstimateOnBoundWarning, ...),
        naming how many fits and which; each result file lists its own under
        ``warnings`` (:func:`run_job`).  Also when numba's cache cannot be
        warmed, and for workers of a given cluster that did not say their
        version.

    Examples
    --------
    >>> jobs = paper_study(1, tasks=("FD",), motion_gains=(1.0,), remnant_fractions=(0.2,),
    ...                    method="fast", duration=5.0, n_starts=1)
    >>> summary = run_campaign(jobs, "campaign-out", workers=1, progress=False)  # doctest: +SKIP
    """
    t0 = time.perf_counter()
    jobs = list(jobs)
    for j in jobs:
        if not isinstance(j, Job):
            raise TypeError(f"jobs must be Job objects, got {type(j).__name__}")
    seen: set[str] = set()
    dupes = sorted({j.key for j in jobs if j.key in seen or seen.add(j.key)})
    if dupes:
        raise ValueError(f"duplicate job keys: {', '.join(dupes[:5])}"
                         f"{' ...' if len(dupes) > 5 else ''}")
    _check_cluster_options(scheduler, workers, progress, connect_timeout)
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CampaignError(f"{out}: cannot create the output folder "
                            f"({exc.strerror or exc})") from None
    from .diagnose.batch import _refuse_another_commands_folder

    # (fit-batch's or diagnose-batch's results there were taken for "not done" and replaced)
    _refuse_another_commands_folder(out, "replicate", summary=False)

    pending: list[Job] = []
    skipped = 0
    for j in jobs:
        old = _read_json(_result_path(out, j))
        if not (isinstance(old, dict) and old.get("key") == j.key and "fit" in old):
            pending.append(j)
            continue
        if old.get("job") != _json_roundtrip(j.to_dict()):
            raise CampaignError(f"{_result_path(out, j)} holds a fit of {j.key} with other "
                                f"settings ({old.get('job')}); use another output folder "
                                f"or delete it")
        skipped += 1

    warned: dict[str, list[tuple[str, str]]] = {}

    def to_json(key: str, value: dict[str, Any]) -> dict[str, Any]:
        for w in value.get("warnings") or ():
            warned.setdefault(w["category"], []).append((key, w["message"]))
        return value

    def say_warned() -> None:
        _say_each_kind(warned, "fit(s)")

    try:
        completed, errors = run_keyed(
            [(j.key, run_job, (j,), {"job": j.to_dict()}) for j in pending], out,
            total=len(jobs), skipped=skipped, scheduler=scheduler, workers=workers,
            progress=progress, connect_timeout=connect_timeout,
            warm=(lambda: _warm_numba_cache({j.method for j in pending})) if warm_cache else None,
            desc="fits", unit="fit", to_json=to_json)
    except BaseException:  # (the run stopped: what finished is saved, and its warnings said,
        with suppress(Warning):  # but a warning made an error (-W error) must not hide why)
            say_warned()
        raise
    say_warned()
    return CampaignSummary(len(jobs), completed, skipped, len(errors), errors, out,
                           time.perf_counter() - t0)


def load_results(out_dir: str | Path, jobs: Iterable[Job] | None = None) -> list[dict[str, Any]]:
    """The result dicts in ``out_dir`` (those of ``jobs`` only, if given), sorted by key.

    Error files (``*.error.json``) and files that are not a finished fit are
    left out; a file that does not parse is left out with a warning.

    Parameters
    ----------
    out_dir : str or Path
        The output folder of a campaign (``out_dir`` of :func:`run_campaign`).
    jobs : iterable of Job, optional
        Read only the result files of these jobs (``<key>.json``); jobs
        without a file are skipped.  The files are found by key: the settings
        stored in them are not compared with the jobs'.  Default: every
        ``*.json`` file in ``out_dir``.

    Returns
    -------
    list of dict
        The parsed result files (as :func:`run_job` returns them), those
        holding a ``"key"`` and a ``"fit"``, sorted by ``"key"``.

    Raises
    ------
    FileNotFoundError
        If ``out_dir`` is not an existing folder.

    Warns
    -----
    RuntimeWarning
        For each file that is not valid JSON (it is left out).
    """
    out = Path(out_dir)
    if not out.is_dir():
        raise FileNotFoundError(f"{out}: no such folder")
    if jobs is not None:
        paths = [_result_path(out, j) for j in jobs]
        paths = [p for p in paths if p.exists()]
    else:
        paths = sorted(p for p in out.glob("*.json") if not p.name.endswith(".error.json"))
    results = []
    for p in paths:
        d = _read_json(p)
        if d is None:
            warnings.warn(f"{p}: left out, not valid JSON (an interrupted write is redone "
                          f"by the next run)", RuntimeWarning, stacklevel=2)
        elif isinstance(d, dict) and "key" in d and "fit" in d:
            results.append(d)
    return sorted(results, key=lambda d: d["key"])


def _paper_cell(task: str, fn: float, k: float):
    for (t, f, kk), v in presets.FIG14_15.items():
        if t == task and abs(f - fn) < 1e-9 and abs(kk - k) < 1e-9:
            return v
    return None


def summarise(results: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Figs. 14/15 statistics per (task, F_n, K_theta, threshold, method), beside the paper's.

    Each result needs ``task``, ``remnant_fraction``, ``motion_gain``,
    ``threshold``, ``method``, ``true_params["delta_abs"]``,
    ``fit["params"]["delta_abs"]`` and ``fit["neg_log_lik"]`` (what
    :func:`run_job` returns).

    Parameters
    ----------
    results : iterable of mapping
        Result dicts, e.g. from :func:`load_results`; only the fields above
        are read.  Results are grouped into cells by (task, F_n, K_theta,
        threshold, method) with F_n and K_theta as given by the job (not the
        fraction a realization reached).

    Returns
    -------
    list of dict, one per cell, sorted, with
        ``task, F_n, K_theta, threshold, method``; ``n``; ``mu`` and ``sigma``
        (ddof=1; NaN for n < 2) of the final delta_abs; ``N50`` (count within
        +-50 % of the true delta_abs, bounds included) and ``N50_pct``;
        ``mean_neg_log_lik``; ``paper_mu, paper_sigma, paper_N50`` (None where
        Figs. 14/15 have no such cell; the paper's are fits with threshold);
        ``flag_N50``: ``|N50 - n p| > 2 sqrt(n p (1-p))`` with
        p = paper_N50 / 100 (for n = 100 this is ``|N50 - paper_N50| > ...``;
        for p = 0 or 1 any difference flags); ``flag_mu``:
        ``|mu - paper_mu| > 2 sqrt(sigma^2/n + paper_sigma^2/100)`` (False for
        n < 2); ``flag`` = either.  ``true_delta_abs``: the cell's true
        delta_abs, IPUT.  Rows are ordered by method, then fits with
        threshold before those without, then task, F_n and K_theta; an empty
        ``results`` gives an empty list.

    Raises
    ------
    ValueError
        If the results of one cell have different true delta_abs.
    KeyError
        If a result lacks one of the fields above.
    """
    groups: dict[tuple, list[Mapping[str, Any]]] = {}
    for r in results:
        key = (r["task"], float(r["remnant_fraction"]), float(r["motion_gain"]),
               bool(r["threshold"]), r["method"])
        groups.setdefault(key, []).append(r)
    rows = []
    order = sorted(groups, key=lambda k: (k[4], not k[3], k[0], k[1], k[2]))
    for key in order:
        task, fn, k, thr, method = key
        rs = groups[key]
        d = np.array([float(r["fit"]["params"]["delta_abs"]) for r in rs])
        truths = {float(r["true_params"]["delta_abs"]) for r in rs}
        if len(truths) != 1:
            raise ValueError(f"cell {key} mixes true delta_abs values {sorted(truths)}")
        true = truths.pop()
        n = d.size
        mu = float(d.mean())
        sigma = float(d.std(ddof=1)) if n > 1 else math.nan
        n50 = int(np.count_nonzero(np.abs(d - true) <= 0.5 * true))
        nll = float(np.mean([float(r["fit"]["neg_log_lik"]) for r in rs]))
        row = {"task": task, "F_n": fn, "K_theta": k, "threshold": thr, "method": method, "n": n,
               "mu": mu, "sigma": sigma, "N50": n50, "N50_pct": 100.0 * n50 / n,
               "mean_neg_log_lik": nll, "true_delta_abs": true, "paper_mu": None,
               "paper_sigma": None, "paper_N50": None, "flag_N50": False, "flag_mu": False,
               "flag": False}
        paper = _paper_cell(task, fn, k) if thr else None
        if paper is not None:
            pmu, psig, pn50 = paper
            p = pn50 / 100.0
            flag_n50 = abs(n50 - n * p) > 2.0 * math.sqrt(n * p * (1.0 - p))
            flag_mu = n > 1 and abs(mu - pmu) > 2.0 * math.sqrt(sigma**2 / n + psig**2 / 100.0)
            row.update({"paper_mu": pmu, "paper_sigma": psig, "paper_N50": pn50,
                        "flag_N50": bool(flag_n50), "flag_mu": bool(flag_mu),
                        "flag": bool(flag_n50 or flag_mu)})
        rows.append(row)
    return rows


SUMMARY_COLUMNS = ("task", "F_n", "K_theta", "threshold", "method", "n", "mu", "sigma", "N50",
                   "N50_pct", "paper_mu", "paper_sigma", "paper_N50", "flag_N50", "flag_mu",
                   "flag", "mean_neg_log_lik", "true_delta_abs")


def write_summary_csv(rows: Sequence[Mapping[str, Any]], path: str | Path) -> Path:
    """Write :func:`summarise` rows as CSV (empty fields where the paper has no cell).

    Parameters
    ----------
    rows : sequence of mapping
        Rows of :func:`summarise`.  The columns are :data:`SUMMARY_COLUMNS`, in
        that order; other keys are ignored, and a missing key, None, NaN or an
        infinity gives an empty field.
    path : str or Path
        The CSV file to write (UTF-8, with a header line); an existing file
        is replaced atomically (a failed write keeps it), its folder is
        created if missing.

    Returns
    -------
    Path
        ``path``, as a Path.

    Raises
    ------
    OSError
        If the file cannot be written.
    """
    from ._files import write_csv_atomic

    return write_csv_atomic(path, SUMMARY_COLUMNS, rows)


def summary_markdown(rows: Sequence[Mapping[str, Any]]) -> str:
    """:func:`summarise` rows as a Markdown table, ours beside the paper's (Figs. 14/15).

    Parameters
    ----------
    rows : sequence of mapping
        Rows of :func:`summarise` (every key it gives but ``true_delta_abs``
        and ``flag`` is read).

    Returns
    -------
    str
        A header, a separator line and one line per row, joined by newlines
        (no trailing newline).  Empty cells where a value is None or NaN;
        N50 as a count when n = 100, else as a count and its percentage;
        the last column names the flagged statistics (``N50``, ``mu``) in bold.

    Raises
    ------
    KeyError
        If a row lacks one of the keys read.
    """
    def f(x, spec):
        return "" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)

    head = ("| task | F_n | K_theta | thr | method | n | mu | sigma | N50 | paper mu | "
            "paper sigma | paper N50% | mean -ln L | flag |")
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        flags = ",".join(n for n, on in (("N50", r["flag_N50"]), ("mu", r["flag_mu"])) if on)
        n50 = (f"{r['N50']}" if r["n"] == 100 else f"{r['N50']} ({r['N50_pct']:.0f}%)")
        lines.append(
            f"| {r['task']} | {r['F_n']:g} | {r['K_theta']:g} | {'yes' if r['threshold'] else 'no'} "
            f"| {r['method']} | {r['n']} | {f(r['mu'], '.4f')} | {f(r['sigma'], '.4f')} | {n50} "
            f"| {f(r['paper_mu'], '.4f')} | {f(r['paper_sigma'], '.4f')} | {f(r['paper_N50'], 'd')} "
            f"| {f(r['mean_neg_log_lik'], '.1f')} | {('**' + flags + '**') if flags else ''} |")
    return "\n".join(lines)

"""The ``bayespilot`` command: simulate runs, evaluate -ln L, run the demo.

``main(argv)`` parses the command line, runs one subcommand and returns the
exit code (0 success, 1 runtime failure, 2 bad input or usage).  Every
refusal is one line on stderr, ``bayespilot: error: <message>``, without a
traceback.  The numerical modules are imported inside the subcommands, so
``bayespilot --help`` answers at once.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import re
import sys
import traceback
import warnings
from pathlib import Path
from typing import Mapping, Sequence

from . import __version__
# the figures' resolution, the formats 'bayespilot plot --format' writes and how a vector
# figure keeps its text: one definition for the commands and the reports (a light module)
from ._figstyle import PLOT_DPI, PLOT_FORMATS, save_figure
# (Ctrl-C inside a numba kernel reaches the command as a SystemError caused by it)
from ._interrupt import caused_by_interrupt as _interrupted

__all__ = ["main", "EXIT_OK", "EXIT_FAILURE", "EXIT_USAGE"]

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2

PROG = "bayespilot"


class UsageError(Exception):
    """Bad input from the user (arguments, files): one line on stderr, exit code 2."""


class CommandFailed(Exception):
    """Valid input, but the computation or writing the output failed: exit code 1."""


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors become :class:`UsageError` (one line, exit 2)."""

    def error(self, message: str):  # type: ignore[override]
        raise UsageError(f"{message} (see '{self.prog} --help')")


# --- argument types -----------------------------------------------------------------
def _finite(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(x):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return x


def _nonnegative(text: str) -> float:
    x = _finite(text)
    if x < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return x


def _positive(text: str) -> float:
    x = _finite(text)
    if x <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return x


def _fraction(text: str) -> float:
    x = _finite(text)
    if not 0.0 <= x < 1.0:
        raise argparse.ArgumentTypeError(f"must be in [0, 1), got {text}")
    return x


def _whole_number(minimum: int):
    """An argparse type: a whole number >= ``minimum``."""
    def parse(text: str) -> int:
        try:
            x = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected a whole number >= {minimum}, got {text!r}") from None
        if x < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {text}")
        return x
    return parse


_seed = _whole_number(0)


def _output_path(text: str) -> str:
    """An argparse type: an output file or folder.  An empty path is refused (an unset
    ``$OUT`` in a script: it was skipped, or meant the current folder), and a leading ``~``
    is expanded: the shell leaves ``--json=~/fit.json`` as it is, which made a folder
    named ``~``."""
    if not text:
        raise argparse.ArgumentTypeError("an empty path; give a file or folder name")
    return os.path.expanduser(text)


#: A dask scheduler's address as ``Client`` takes it: ``[SCHEME://]HOST:PORT``, HOST a name,
#: an IPv4 address or an IPv6 one in brackets.  Checked here, without importing distributed
#: (which takes half a second): a trailing slash or a missing port failed in distributed as
#: "invalid literal for int()", and not at all on a folder whose jobs were all done.
_SCHEDULER_ADDRESS = re.compile(r"(?:(?P<scheme>[A-Za-z][A-Za-z0-9+.-]*)://)?"
                                r"(?P<host>\[[0-9A-Fa-f:.]+(?:%[\w.-]+)?\]|[\w.-]+)"
                                r":(?P<port>[0-9]{1,5})")
#: The schemes of distributed's own transports a scheduler listens on (inproc:// is within
#: one process only); another is taken if a package registers it (entry points of the group
#: ``distributed.comm.backends``).
_DASK_SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")


def _scheduler_address(text: str) -> str:
    """An argparse type: --scheduler, a dask scheduler's address (``_SCHEDULER_ADDRESS``).
    An empty one is refused (an unset ``$SCHEDULER`` in a job script: the header called it
    a local cluster, then the run failed to reach it)."""
    if not text:
        raise argparse.ArgumentTypeError(
            "an empty address; give the scheduler's, e.g. tcp://HOST:8786, or leave "
            "--scheduler out for a local cluster")
    m = _SCHEDULER_ADDRESS.fullmatch(text)
    if m is None or not 0 < int(m["port"]) < 65536:
        raise argparse.ArgumentTypeError(
            f"not a dask scheduler address (tcp://HOST:PORT, e.g. tcp://10.0.0.5:8786): "
            f"{text!r}")
    scheme = m["scheme"] or "tcp"  # (as distributed reads it: TCP:// is not tcp://)
    if scheme not in _DASK_SCHEMES:
        from importlib.metadata import entry_points

        known = {e.name for e in entry_points(group="distributed.comm.backends")}
        if scheme not in known:
            raise argparse.ArgumentTypeError(
                f"not a dask scheduler address: unknown scheme {m['scheme']!r} in {text!r} "
                f"(dask's are {', '.join(_DASK_SCHEMES)}; tcp://HOST:PORT, e.g. "
                f"tcp://10.0.0.5:8786)")
    return text


def _cluster_choice(args: argparse.Namespace) -> None:
    """Check and settle replicate's and diagnose-batch's cluster options: --scheduler or
    --workers, not both; --scheduler-file read into ``args.scheduler`` (the address the
    scheduler wrote there, as ``dask scheduler --scheduler-file``, dask-mpi and
    dask-jobqueue write it), waiting up to --connect-timeout for the file to appear (a
    job script starts the scheduler and the command together)."""
    import json
    import time

    path = getattr(args, "scheduler_file", None)
    if (args.scheduler is not None or path is not None) and args.workers is not None:
        raise UsageError(f"give {'--scheduler' if path is None else '--scheduler-file'} (an "
                         f"existing cluster) or --workers (a local one), not both")
    if path is None:
        return
    deadline = time.monotonic() + args.connect_timeout
    while True:
        try:
            with open(path, encoding="utf-8") as fh:
                text = fh.read()
            info = json.loads(text)
            if not isinstance(info, dict):  # (JSON, but not an object: not a scheduler file)
                raise KeyError("address")
            address = info["address"]
            break
        except FileNotFoundError:
            if time.monotonic() >= deadline:
                raise CommandFailed(f"{path}: no scheduler file after {args.connect_timeout:g} "
                                    f"s (is the dask scheduler started with --scheduler-file "
                                    f"{path}?)") from None
        except (OSError, ValueError, KeyError) as exc:
            # (a file being written does not parse yet: read again; one that parses but has
            # no address is not a scheduler file, said at once)
            if isinstance(exc, KeyError) or time.monotonic() >= deadline:
                raise UsageError(f"argument --scheduler-file: {path}: not a dask scheduler "
                                 f"file ({exc.__class__.__name__}: {exc}); it holds the "
                                 f"scheduler's address as JSON, {{\"address\": "
                                 f"\"tcp://HOST:PORT\", ...}}") from None
        time.sleep(0.5)
    try:
        args.scheduler = _scheduler_address(address if isinstance(address, str) else "")
    except argparse.ArgumentTypeError as exc:
        raise UsageError(f"argument --scheduler-file: {path}: {exc}") from None


def _oversample(text: str) -> int:
    """An argparse type: an oversampling factor, 1 to model.MAX_OVERSAMPLE."""
    from .model import MAX_OVERSAMPLE

    x = _whole_number(1)(text)
    if x > MAX_OVERSAMPLE:
        raise argparse.ArgumentTypeError(f"must be <= {MAX_OVERSAMPLE}, got {text}")
    return x


def _oversample_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--oversample", type=_oversample, default=1, metavar="M",
                   help="run the motion channel (dead zone, delay, H_nm) at M times the "
                        "recording's rate in the likelihood: 1 is the paper's computation "
                        "(default); 8 removes the 100-Hz model's error at the dead zone's "
                        "corners, which makes delta_abs's intervals calibrated "
                        "(docs/posteriors.md)")


# --- helpers --------------------------------------------------------------------------


def _save_figure(fig, path: Path, dpi: int = PLOT_DPI,
                 formats: Sequence[str] = ()) -> list[Path]:
    """Write a figure (format from ``path``'s suffix; with ``formats``, once in each of them,
    ``path`` with its suffix replaced: ``--format`` given twice) and close it; the files
    written.  A failed write is a runtime failure (exit 1).  ``dpi`` sets a PNG's
    resolution; in a PDF or SVG only the rasterized point clouds (the pair plot's) use it.
    A PDF's fonts are embedded as TrueType and an SVG's text stays text
    (``_figstyle.VECTOR_TEXT``)."""
    paths = [Path(path).with_suffix(f".{fmt}") for fmt in formats] or [Path(path)]
    try:
        for one in paths:
            try:
                save_figure(fig, one, dpi)
            except OSError as exc:
                raise CommandFailed(f"{one}: cannot write the plot "
                                    f"({_os_reason(exc)})") from None
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)
    return paths


@contextlib.contextmanager
def _untitled_notes():
    """Within: the ConvergenceWarnings of figures drawn without their titles (a posterior
    figure's title says "not converged", :func:`bayespilot.plots._warn_untitled`) kept in
    the list yielded, not shown: the command says it once, in its own words."""
    from .sample import ConvergenceWarning

    kept: list = []
    with _warnings_of(ConvergenceWarning, kept.append):
        yield kept


def _formats(args: argparse.Namespace) -> tuple[str, ...]:
    """The formats ``--format`` asks for (:func:`_figure_arguments`), each once, in the
    order given; png when none is given."""
    return tuple(dict.fromkeys(args.format or ("png",)))


def _figure_arguments(p: argparse.ArgumentParser, *, format_help: str = "",
                      dpi_help: str = "") -> None:
    """--format (repeatable) and --dpi of a command that writes figures: 'plot', 'replicate',
    'diagnose-batch' and 'demo' (:func:`_formats`, :func:`_save_figure`); ``format_help``,
    ``dpi_help``: the command's own words after the options' help."""
    p.add_argument("--format", action="append", choices=PLOT_FORMATS, default=None,
                   help="file format of the figures: png (default), or pdf and svg, which "
                        "are vector (fonts embedded as TrueType, SVG text kept as text), for "
                        "a paper; give it twice for two formats (--format pdf --format png)"
                        + format_help)
    p.add_argument("--dpi", type=_whole_number(20), default=PLOT_DPI, metavar="N",
                   help=f"resolution of a PNG, dots per inch (default {PLOT_DPI}, for the "
                        f"screen; 300 or more for print){dpi_help}")


def _no_title_argument(p: argparse.ArgumentParser, what: str,
                       note: str = "; a chain that has not converged, which a title said, "
                                   "is said on stderr instead") -> None:
    """--no-title of a command that writes figures (``what``: which; ``note``: where what
    the titles said goes)."""
    p.add_argument("--no-title", action="store_true",
                   help=f"draw {what} without their titles, for a paper whose captions say "
                        f"what they said{note}")


def _title(args: argparse.Namespace) -> bool:
    """The ``title=`` of the plot functions: False with --no-title."""
    return not args.no_title


def _cluster_where(args: argparse.Namespace) -> str:
    """Where replicate's, diagnose-batch's and fit-batch's tasks run, in words."""
    return args.scheduler or f"{args.workers or 'all'} local worker(s)"


def _progress(args: argparse.Namespace) -> bool:
    """Whether to draw progress bars: not with --quiet, and only on a terminal (a bar
    redrawn with carriage returns is noise in a log file or a pipe)."""
    return not args.quiet and sys.stderr.isatty()


def _cluster_progress(args: argparse.Namespace) -> bool | str:
    """The progress of replicate and diagnose-batch: the bar on a terminal, plain lines when
    stderr is not one (a batch job's log showed the header, then nothing for hours; see
    :func:`bayespilot.campaign.run_campaign`), nothing with --quiet."""
    if args.quiet:
        return False
    return True if _progress(args) else "lines"


def _say(args: argparse.Namespace, text: str) -> None:
    """An informational line on stdout, unless --quiet."""
    if not args.quiet:
        print(text)


def _detail(args: argparse.Namespace, text: str) -> None:
    """A detail on stderr, with --verbose only."""
    if args.verbose:
        print(text, file=sys.stderr)


#: What a fit's result file has besides ``params`` (FitResult.from_dict requires them): a
#: JSON object with them is read as 'bayespilot fit --json' wrote it, its ``params`` taken.
_FIT_KEYS = ("params", "neg_log_lik", "vaf", "method")


def _read_params(path: str, model, *, require: Sequence[str] = (),
                 detail=None, with_hint: bool = False) -> dict[str, float]:
    """Pilot parameters by name from a JSON file, checked against ``model``'s names and bounds.

    Parameters
    ----------
    path : str
        A JSON object of parameter values by name, or a fit's result
        (``bayespilot fit --json``, :meth:`FitResult.to_json
        <bayespilot.fit.result.FitResult.to_json>`: an object with ``params``,
        ``neg_log_lik``, ``vaf`` and ``method``), whose ``params`` are taken.
    model : PilotModel
        The names and bounds the values are checked against.
    require : sequence of str
        Names that must be given.
    detail : callable, optional
        Called with one line saying where the values came from (a fit's file).
    with_hint : bool
        The command takes ``--with``: an unknown name that a catalogue entry adds is
        said with the ``--with`` that gives it.

    Returns
    -------
    dict of str to float

    Raises
    ------
    UsageError
        The file cannot be read, is not JSON, or holds an unknown name, a value
        that is not a finite number or is outside its bounds, or lacks a
        ``require``-d name.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise UsageError(f"{p}: parameter file not found") from None
    except IsADirectoryError:
        raise UsageError(f"{p}: is a directory, not a parameter file") from None
    except UnicodeDecodeError as exc:
        raise UsageError(f"{p}: is not UTF-8 text ({exc.reason})") from None
    except OSError as exc:
        raise UsageError(f"{p}: cannot be read ({_os_reason(exc)})") from None

    def reject(name: str):
        raise ValueError(f"{name} is not a finite number")

    try:
        obj = json.loads(text, parse_constant=reject)
    except json.JSONDecodeError as exc:
        raise UsageError(f"{p}: is not valid JSON ({exc.msg} at line {exc.lineno} "
                         f"column {exc.colno})") from None
    except (ValueError, RecursionError) as exc:
        raise UsageError(f"{p}: is not valid JSON ({exc})") from None
    names = model.all_names
    if not isinstance(obj, dict):
        raise UsageError(f"{p}: must hold a JSON object of parameter values by name "
                         f"({', '.join(names)}), e.g. {{\"K_v\": 1.057}}, or a fit's "
                         f"result ('bayespilot fit --json')")
    what = "parameter"
    if isinstance(obj.get("params"), dict) and all(k in obj for k in _FIT_KEYS):
        # a fit's result (FitResult.to_json): its estimates, checked below as any file's
        if detail is not None:
            thr = "with" if obj.get("threshold", True) else "without"
            detail(f"{p}: a fit's result ({obj.get('method')} method, {thr} threshold"
                   + (f", of {obj['source']}" if obj.get("source") else "")
                   + "): its params are taken")
        obj, what = obj["params"], "fit's parameter"
    kind = _result_kind(obj) if what == "parameter" else None
    if kind is not None:  # (its keys are not parameter names: said as the file it is)
        raise UsageError(f"{p}: is {kind}, not a parameter file: give a JSON object of "
                         f"parameter values by name ({', '.join(names)}), e.g. "
                         f"{{\"K_v\": 1.057}}, or a fit's result ('bayespilot fit --json')")
    unknown = [k for k in obj if k not in names]
    if unknown:
        hint = ""
        if "params" in unknown:  # a result file of another kind, or a fit's cut short
            hint = (f" (a fit's result, as 'bayespilot fit --json' writes it, is read by its "
                    f"params when it has {', '.join(_FIT_KEYS)})")
        elif with_hint:  # e.g. the fit of an extended model, read without its --with
            entries = _entries_adding(unknown, model)
            if entries:
                hint = (" (" + " and ".join(f"{', '.join(new)}: give --with {name}"
                                            for name, new in entries) + ")")
        raise UsageError(f"{p}: unknown {what} name(s) {', '.join(map(repr, unknown))}; "
                         f"valid names are {', '.join(names)}{hint}")
    values: dict[str, float] = {}
    for name, v in obj.items():
        ok = isinstance(v, (int, float)) and not isinstance(v, bool)
        try:
            x = float(v) if ok else math.nan
        except OverflowError:
            x = math.nan
        if not math.isfinite(x):
            raise UsageError(f"{p}: {name} must be a finite number, got {json.dumps(v)}")
        par = model.parameter(name)
        if not par.lower <= x <= par.upper:
            unit = "" if par.unit == "-" else f" {par.unit}"
            raise UsageError(f"{p}: {name} = {x:g} is outside its range [{par.lower:g}, "
                             f"{par.upper:g}]{unit} (Table 1 of Pool et al. 2012)")
        values[name] = x
    missing = [n for n in require if n not in values]
    if missing:
        raise UsageError(f"{p}: missing parameter(s) {', '.join(missing)} "
                         f"(this command needs {', '.join(require)})")
    return values


def _result_kind(obj: Mapping[str, object]) -> str | None:
    """What a JSON object read as a parameter file is when it is another of bayespilot's files
    (a diagnosis, a batch's result, a comparison, a posterior's summary, a recording's
    sidecar), said for the refusal; None for anything else (a parameter file, or a file
    whose unknown names are said one by one)."""
    fmt = obj.get("format")
    if isinstance(fmt, str) and fmt.startswith("bayespilot-recording/"):
        return "a recording's JSON sidecar"
    if "fit_threshold" in obj and "fit_none" in obj:
        return ("a result of 'bayespilot fit-batch' (its fits are under \"fit_threshold\" "
                "and \"fit_none\"; 'bayespilot fit REC --json' writes one fit's file)")
    if "diagnosis" in obj and "recordings" in obj:
        return "a result of 'bayespilot diagnose-batch' (a diagnosis)"
    if "ranking" in obj and "physics" in obj:
        return "a diagnosis ('bayespilot diagnose --json')"
    if "log_bayes_factor" in obj and "decision" in obj:
        return "a comparison ('bayespilot compare --json')"
    if "job" in obj and "fit" in obj:
        return "a result of 'bayespilot replicate' (a simulated run's fit)"
    table = obj.get("summary") if "converged" in obj else obj  # (its table, before with it)
    if (isinstance(table, Mapping) and table
            and all(isinstance(v, dict) and "median" in v and "r_hat" in v
                    for v in table.values())):
        return "a posterior's summary ('bayespilot sample --json': statistics per parameter)"
    return None


def _entries_adding(names: Sequence[str], model) -> list[tuple[str, list[str]]]:
    """(catalogue name, the ``names`` it adds) for each built-in entry that adds some of
    ``names`` to ``model`` (none where the catalogue cannot be had)."""
    try:
        from .diagnose.catalogue import CATALOGUE
    except Exception:  # noqa: BLE001 - a hint only
        return []
    found = []
    for ext in CATALOGUE:
        try:
            added = set(ext.build(model).all_names) - set(model.all_names)
        except Exception:  # noqa: BLE001 - an entry that cannot extend this model
            continue
        hit = [n for n in names if n in added]
        if hit:
            found.append((ext.name, hit))
    return found


def _read(path: str):
    """A Recording from disk; any problem with it is bad input.

    A questionable recording (short, slowly sampled) is read, with one
    ``bayespilot: warning: ...`` line on stderr per reason.
    """
    from .io import read_recording
    from .recording import RecordingError

    try:
        with _questionable_said():
            return read_recording(path)
    except RecordingError as exc:
        raise UsageError(str(exc)) from None


@contextlib.contextmanager
def _questionable_said():
    """Within: each QuestionableRecordingWarning becomes one ``bayespilot: warning: ...`` line
    on stderr (when the block ends, also by an exception); other warnings pass on."""
    from .recording import QuestionableRecordingWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", QuestionableRecordingWarning)
        try:
            yield
        finally:
            others = []
            for w in caught:
                if issubclass(w.category, QuestionableRecordingWarning):
                    print(f"{PROG}: warning: {w.message}", file=sys.stderr)
                else:
                    others.append(w)
    for w in others:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def _warning_line(message) -> None:
    """``bayespilot: warning: <message>`` on stderr, in the command's words
    (:func:`_in_cli_words`: diagnose-batch's grouped worker warnings said "fix them
    (model.fix)"), above any progress bar on the screen (printed directly, it ran into the
    bar's line)."""
    from tqdm.auto import tqdm

    tqdm.write(f"{PROG}: warning: {_in_cli_words(message)}", file=sys.stderr)


#: The library's advice in a warning that a command-line user cannot follow, and what the
#: command says instead (SilentChannelWarning: the command line has no option to fix a
#: parameter or to drop a channel).
_LIBRARY_ADVICE = {
    ": fix them (model.fix) or use a model without the channel":
        ": the record says nothing about them, and the values given for them are not "
        "estimates",
    # (compare's Savage-Dickey posterior: the command line sets no sample_options)
    "to run longer, raise sample_options['max_steps'], or give a converged posterior "
    "(posterior=, or bayespilot compare --posterior POST.nc from bayespilot sample)":
        "give a converged posterior (--posterior POST.nc, from bayespilot sample)",
}


def _in_cli_words(message) -> str:
    """A warning's text with the library's advice (:data:`_LIBRARY_ADVICE`) replaced by the
    command's."""
    text = str(message)
    for library, cli in _LIBRARY_ADVICE.items():
        text = text.replace(library, cli)
    return text


def _warning_lines_once():
    """A handle for :func:`_warnings_of`: each message a :func:`_warning_line` (in the
    command's words, :func:`_in_cli_words`), once."""
    said: set[str] = set()

    def say(message) -> None:
        text = _in_cli_words(message)
        if text not in said:
            said.add(text)
            _warning_line(text)

    return say


@contextlib.contextmanager
def _warnings_of(category, handle):
    """Within: each warning of ``category`` (a class or a tuple of them) goes to
    ``handle(message)`` as it is raised, instead of Python's display; other warnings are shown
    as before."""
    categories = category if isinstance(category, tuple) else (category,)
    with warnings.catch_warnings():
        for one in categories:
            warnings.simplefilter("always", one)
        shown = warnings.showwarning

        def show(message, cat, filename, lineno, file=None, line=None):
            if issubclass(cat, categories):
                handle(message)
            else:
                shown(message, cat, filename, lineno, file, line)

        warnings.showwarning = show
        yield


def _subject_name(text: str) -> str:
    """--subject: a non-empty name without surrounding blanks or a slash (diagnose-batch
    names its files after it)."""
    if not text.strip() or text != text.strip() or "/" in text or "\\" in text:
        raise argparse.ArgumentTypeError(f"a subject must be a non-empty name without leading "
                                         f"or trailing blanks or a slash, got {text!r}")
    return text


def _simulate_and_write(out: str | Path, params: Mapping[str, float], *, task: str, motion_gain: float,
                        seed: int, remnant_fraction: float | None = None,
                        remnant_gain: float | None = None, duration: float | None = None,
                        sample_rate_hz: float | None = None, subject: str | None = None,
                        model=None):
    """Simulate one run with the paper's model (or ``model``, e.g. one extended by
    ``--with``) and write it; returns (simulation, csv, json).

    The paper's task ``task`` (FD or FT) at ``motion_gain``, recorded at
    ``sample_rate_hz`` (None: the paper's 100 Hz); a rate whose Nyquist
    frequency is not above every forcing line is a usage error.  The JSON
    sidecar gets a ``simulation`` key with the true parameters, the remnant
    gain and fraction, T_n and the seed, so the truth travels with the file;
    ``subject`` (optional) goes into it as the format's ``subject`` key.
    """
    from .model import paper_model
    from .recording import RecordingError
    from .simulate import TrackingTask, simulate

    try:
        tracking = TrackingTask.paper(task, motion_gain, **(
            {} if sample_rate_hz is None else {"sample_rate_hz": float(sample_rate_hz)}))
    except ValueError as exc:  # a rate too low for the forcing (its Nyquist frequency)
        if sample_rate_hz is None:
            raise UsageError(str(exc)) from None
        # (the library's advice in the option's words: the CLI cannot leave a line out)
        said = str(exc).replace("raise sample_rate_hz above", "give --sample-rate above")
        raise UsageError(f"argument --sample-rate: {said.replace(' or leave the line out', '')}"
                         ) from None
    try:
        sim = simulate(model if model is not None else paper_model(), params, task=tracking,
                       remnant_fraction=remnant_fraction, remnant_gain=remnant_gain, seed=seed,
                       duration=duration)
    except RuntimeError as exc:
        raise CommandFailed(str(exc)) from None
    except ValueError as exc:  # e.g. a remnant fraction this loop cannot reach
        raise UsageError(str(exc)) from None
    if subject is not None:  # (what diagnose-batch --pool groups the runs by)
        from dataclasses import replace

        sim = replace(sim, recording=replace(sim.recording,
                                             metadata=dict(sim.recording.metadata,
                                                           subject=subject)))
    try:
        csv_path, json_path = sim.write(out)
    except RecordingError as exc:  # e.g. an output path ending in .mat
        raise UsageError(str(exc)) from None
    except OSError as exc:
        where = exc.filename or out
        if str(where).endswith(".tmp"):  # write_recording's temporary file: name the output
            where = out
        raise CommandFailed(f"{where}: cannot write the recording ({_os_reason(exc)})") from None
    return sim, csv_path, json_path


def _likelihood(model, recording, params: Mapping[str, float], initial: str = "periodic",
                discard: float | None = None):
    """(-ln L, VAF %) of ``model`` on ``recording``, after the first ``discard`` s (None: as
    the fitters choose, the start-up of a record not known to be whole periods).

    A non-finite -ln L is a usage error (exit 2) when the record is shorter
    than a channel's delay needs (:func:`bayespilot.fit.three_step._too_short_for_delays`,
    the fitters' rule), else a failure (exit 1): the model is unstable at ``params``.
    """
    from .fit.three_step import _too_short_for_delays
    from .likelihood import Likelihood, PerfectFitWarning, _startup_default

    if discard is None:  # as the fitters: a record not known to be whole periods: start-up out
        discard = _startup_default(recording, initial)
    lik = Likelihood(model, recording, initial=initial, discard=discard)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", PerfectFitWarning)
        value = lik.neg_log_lik(params)
    for w in caught:
        print(f"{PROG}: warning: {w.message}", file=sys.stderr)
    if not math.isfinite(value):
        short = _too_short_for_delays(model, recording, params)
        if short is not None:
            raise UsageError(short)
        raise CommandFailed(f"the pilot model is unstable at these parameters on "
                            f"{recording.source or 'this recording'} (-ln L = {value})")
    return value, lik.vaf(params)


# --- subcommands ------------------------------------------------------------------------
def _cmd_simulate(args: argparse.Namespace) -> int:
    from . import presets

    rate = args.sample_rate
    if args.duration is not None and args.duration * rate < 2:
        raise UsageError(f"argument --duration: {args.duration:g} s is shorter than 2 samples "
                         f"at {rate:g} Hz")
    _refuse_overwriting([("-o/--output", f) for f in _stem_files(args.output)],
                        [("the --params file", args.params),
                         *_code_files(args.extended_by, "--with")],
                        recordings=False)  # (its own rule: a simulated one is replaced)
    if not args.force:
        _refuse_replacing_a_recording(args.output)
    model = _paper_model_with(args, fitted=False)
    params = presets.paper_parameters(args.task)
    if args.params is not None:
        params.update(_read_params(args.params, model, detail=lambda text: _detail(args, text),
                                   with_hint=True))
    # the truth of an extension's new parameters is the user's to say (a default of the
    # entry's, e.g. K_ot = 0, would simulate a run without the effect)
    unsaid = [n for n in model.parameter_names if n not in params]
    if unsaid:
        said = ", ".join(f"{n} in [{model.parameter(n).lower:g}, {model.parameter(n).upper:g}]"
                         + ("" if model.parameter(n).unit == "-"
                            else f" {model.parameter(n).unit}") for n in unsaid)
        raise UsageError(f"argument --with: give the true value of {said} in --params "
                         f"(e.g. {{\"{unsaid[0]}\": {model.parameter(unsaid[0]).default:g}}})")
    _detail(args, "parameters: " + ", ".join(f"{k}={v:g}" for k, v in params.items()))
    sim, csv_path, json_path = _simulate_and_write(
        args.output, params, task=args.task, motion_gain=args.motion_gain, seed=args.seed,
        remnant_fraction=None if args.remnant_gain is not None else args.remnant_fraction,
        remnant_gain=args.remnant_gain, duration=args.duration, sample_rate_hz=rate,
        subject=args.subject, model=model)
    rec = sim.recording
    _say(args, f"wrote {csv_path} and {json_path}: task {rec.task}, K_theta = {rec.motion_gain:g}, "
               f"{rec.duration:g} s at {rec.sample_rate_hz:g} Hz, seed {args.seed}, "
               f"K_n = {sim.remnant_gain:.4g}, "
               f"F_n = {sim.remnant_fraction:.3f}")
    return EXIT_OK


def _cmd_loglik(args: argparse.Namespace) -> int:
    # (the model is built once, before the recording is read: the parameter file is checked
    # against it first; built again for the entries' columns, a --with FILE.py ran twice)
    model, entries = _paper_model_and_entries(
        args, threshold=not args.no_threshold,
        without_threshold="--no-threshold" if args.no_threshold else None)
    params = _read_params(args.params, model, require=model.parameter_names,
                          detail=lambda text: _detail(args, text), with_hint=True)
    held = sorted(set(model._threshold_names) & set(params))
    if args.no_threshold and held:  # (every threshold the model declares is held at 0)
        said = (f"--no-threshold: {', '.join(held)} from the parameter file "
                f"{'are' if len(held) > 1 else 'is'} ignored (held at 0, as fit --no-threshold "
                f"holds every threshold)")
        # (a threshold other than the one the option names: a warning line; stdout's first
        # line stays the value)
        if held == ["delta_abs"]:
            _detail(args, said)
        else:
            _warning_line(said)
    rec = _read(args.recording)
    _check_columns(entries, rec)
    _detail(args, f"{rec!r}\n{model.summary()}\ninitial conditions: {args.initial}")
    from .likelihood import _startup_default, _startup_reason

    skipped = _startup_default(rec, args.initial)  # (once: said below if not 0)
    value, vaf = _likelihood(model, rec, params, args.initial, skipped)
    print(f"-ln L = {value!r}")
    _say(args, f"VAF = {vaf:.2f} %")
    if skipped:
        _say(args, f"(the first {skipped:g} s left out: {_startup_reason(rec).split(': ', 1)[-1]})")
    return EXIT_OK


def _fit_method_rules(args: argparse.Namespace) -> None:
    """Refuse (exit 2) --noise ar and --iterate with the method they do not go with, as fit
    and fit-batch take them (:func:`_fit_method_arguments`)."""
    if args.noise == "ar" and args.method != "fast":
        raise UsageError("argument --noise: 'ar' (a prediction-error fit) goes with --method fast")
    if args.iterate and args.method != "paper":
        raise UsageError("argument --iterate: it repeats Steps II and III of --method paper")


def _cmd_fit(args: argparse.Namespace) -> int:
    from .fit.fast import fit_fast
    from .fit.three_step import fit_paper

    _fit_method_rules(args)
    from .recording import RecordingError

    _refuse_overwriting([("--json", args.json)],
                        [*_recording_files(args.recording),
                         *_code_files(args.extended_by, "--with")])
    rec = _read(args.recording)
    if args.json:  # checked before the fit: its seconds are not lost to a bad path
        _check_writable(args.json, "fit")
    threshold = not args.no_threshold
    model = _paper_model_with(args, rec,
                              without_threshold=None if threshold else "--no-threshold")
    try:
        if args.method == "paper":
            _say(args, f"fitting {rec.source} with the paper's three-step procedure "
                       f"(20 GA runs of 160 x 100, Gauss-Newton, threshold scan) ...")
            from .fit.result import NotAtMaximumWarning

            with warnings.catch_warnings():  # (said by the summary, with --iterate's hint)
                warnings.simplefilter("ignore", NotAtMaximumWarning)
                fit = fit_paper(rec, model, threshold=threshold, seed=args.seed,
                                iterate=args.iterate, progress=_progress(args))
        else:
            _say(args, f"fitting {rec.source} with the fast estimator"
                       + (" (prediction error: AR noise model)" if args.noise == "ar" else "")
                       + " ...")
            fit = fit_fast(rec, model, threshold=threshold, seed=args.seed,
                           **({"noise": "ar"} if args.noise == "ar" else {}))
    except RecordingError as exc:  # a record a fit cannot use (too short, u constant)
        raise UsageError(str(exc)) from None
    if not math.isfinite(fit.neg_log_lik):
        raise CommandFailed("the fit did not reach a finite -ln L")
    print(fit.summary())
    if args.json:
        try:
            fit.to_json(args.json)
        except OSError as exc:
            raise CommandFailed(f"{args.json}: cannot write the fit ({_os_reason(exc)})") from None
        _say(args, f"wrote {args.json}")
    return EXIT_OK


#: The options of the full demo (dest -> flag); --quick runs a fixed check and refuses them.
_DEMO_ONLY = {"task": "--task", "motion_gains": "--motion-gains", "duration": "--duration",
              "max_steps": "--max-steps", "nlive": "--nlive", "likelihood": "--likelihood"}


def _cmd_demo(args: argparse.Namespace) -> int:
    # the full demo's options default to None here, so that one given with --quick is seen
    given = {k: getattr(args, k) for k in _DEMO_ONLY if getattr(args, k) is not None}
    if args.quick and given:
        raise UsageError("argument --quick: the quick check is fixed (one 81.92-s run of task FD, "
                         "K_theta = 1, F_n = 0.2) and takes only --out, --seed, --format, "
                         f"--dpi and --no-title; drop {', '.join(_DEMO_ONLY[k] for k in given)} "
                         "or --quick")
    formats = _formats(args)
    if not args.quick:
        from .example import LabRecordingThere, run_example

        figure = {"formats": formats, "dpi": args.dpi, "title": not args.no_title}
        try:  # (warnings one line each, as they come: the demo runs for minutes)
            with _warnings_of(RuntimeWarning, _warning_lines_once()):
                report = run_example(args.out, seed=args.seed, **given, **figure,
                                     progress=_progress(args), say=lambda text: _say(args, text))
        except OSError as exc:
            raise CommandFailed(f"{args.out}: cannot write the example "
                                f"({_os_reason(exc)})") from None
        except LabRecordingThere as exc:  # (a lab's recording where a run's would go)
            raise UsageError(f"argument --out: {exc}") from None
        print(f"report: {report}")
        return EXIT_OK
    from . import presets
    from .model import paper_model
    from .plots import plot_traces

    task, motion_gain, fraction = "FD", 1.0, 0.2
    truth = presets.paper_parameters(task)
    out = Path(args.out)
    # (a recording there of the demo's own is replaced, as a rerun does; a lab's is refused)
    _refuse_replacing_a_recording(out / "recording", "--out", force=False)
    _say(args, f"Simulating task {task} at K_theta = {motion_gain:g}, remnant fraction "
               f"F_n = {fraction:g}, Table 3 parameters of Pool et al. (2012), seed {args.seed} ...")
    sim, csv_path, json_path = _simulate_and_write(out / "recording", truth, task=task,
                                                   motion_gain=motion_gain, seed=args.seed,
                                                   remnant_fraction=fraction)
    _say(args, f"wrote {csv_path} and {json_path} ({sim.recording.duration:g} s, "
               f"K_n = {sim.remnant_gain:.4g}, F_n = {sim.remnant_fraction:.3f})")
    rec = _read(csv_path)  # evaluate what was written, as a user would
    with_thr, vaf = _likelihood(paper_model(), rec, truth)
    without_thr, vaf0 = _likelihood(paper_model(threshold=False), rec, truth)
    print(f"-ln L at Table 3 parameters, with threshold (delta_abs = {truth['delta_abs']:g}): "
          f"{with_thr:.2f}")
    print(f"-ln L at Table 3 parameters, without threshold (delta_abs = 0):      {without_thr:.2f}")
    print(f"VAF with threshold: {vaf:.2f} %   (without: {vaf0:.2f} %)")
    written = _save_figure(plot_traces(rec, canal=sim.channels["vestibular"]["pre"],
                                       delta_abs=truth["delta_abs"], title=_title(args)),
                           out / "traces", args.dpi, formats)
    _say(args, f"wrote {' and '.join(str(p) for p in written)} (e, u, theta_ddot_m and the "
               f"canal output i with the band +-delta_abs)")
    return EXIT_OK


def _csv_of(item_type, what: str):
    """An argparse type: a comma-separated list of ``item_type`` values, no repeats."""
    def parse(text: str) -> tuple:
        parts = [t.strip() for t in text.split(",")]
        if not text.strip() or any(not t for t in parts):
            raise argparse.ArgumentTypeError(f"expected a comma-separated list of {what}, "
                                             f"got {text!r}")
        values = tuple(item_type(t) for t in parts)
        if len(set(values)) != len(values):
            raise argparse.ArgumentTypeError(f"repeated value in {text!r}")
        return values
    return parse


def _task_name(text: str) -> str:
    if text not in ("FD", "FT"):
        raise argparse.ArgumentTypeError(f"task must be FD or FT, got {text!r}")
    return text


_count = _whole_number(1)


#: paper_study's own keywords, and the option of 'replicate' that sets each: not fit options.
_STUDY_SETTINGS = {"realizations": "--realizations",
                   "first_realization": "--first-realization", "tasks": "--tasks",
                   "motion_gains": "--motion-gains", "remnant_fractions": "--remnant-fractions",
                   "threshold": "--fits", "method": "--method", "duration": "--duration",
                   "remnant": "--remnant"}


def _fit_option(text: str) -> tuple[str, object]:
    """An argparse type: ``NAME=VALUE``, the value a JSON value (true/false in any case are
    booleans; anything that is not JSON is a string).  A name that a 'replicate' option
    sets (threshold, duration, remnant, ...) is refused, naming that option."""
    name, sep, value = text.partition("=")
    name = name.strip()
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    if name in _STUDY_SETTINGS:
        raise argparse.ArgumentTypeError(
            f"{name!r} is not a fit option: give {_STUDY_SETTINGS[name]} instead")
    if value.strip().lower() in ("true", "false"):  # Python's True/False as well as JSON's
        return name, value.strip().lower() == "true"
    try:
        parsed = json.loads(value)
    except ValueError:
        parsed = value
    return name, parsed


_FITS = {"both": (True, False), "threshold": (True,), "none": (False,)}
_FITS_SAID = {"both": "with and without threshold", "threshold": "with threshold",
              "none": "without threshold"}


def _hist_upper(text: str) -> float | str:
    """--hist-upper: a positive number (IPUT) or 'auto'."""
    if text.strip().lower() == "auto":
        return "auto"
    return _positive(text)


def _cmd_replicate(args: argparse.Namespace) -> int:
    from ._files import write_text_atomic
    from .campaign import (CampaignError, load_results, paper_study, run_campaign, summarise,
                           summary_markdown, write_summary_csv)

    _cluster_choice(args)
    try:
        jobs = paper_study(args.realizations, tasks=args.tasks, motion_gains=args.motion_gains,
                           remnant_fractions=args.remnant_fractions,
                           threshold=_FITS[args.fits], method=args.method,
                           duration=args.duration, remnant=args.remnant,
                           first_realization=args.first_realization,
                           **dict(args.fit_option))
    except ValueError as exc:  # an option the fit function does not take, a cell Table 4 lacks
        arg = "--remnant" if "Table 4" in str(exc) else "--fit-option"
        raise UsageError(f"argument {arg}: {exc}") from None
    out = Path(args.out)
    _refuse_overwriting([("--out", out / "summary.csv"), ("--out", out / "summary.md")], [])
    from .diagnose.batch import ResultConflictError, _refuse_another_commands_folder

    try:  # (another batch's results or a summary of one's own: the batches' own rule)
        _refuse_another_commands_folder(out, "replicate")
    except ResultConflictError as exc:
        raise UsageError(f"argument --out: {exc}") from None
    _say(args, f"{len(jobs)} fits ({args.method} method, {args.realizations} realization(s) x "
               f"{len(args.tasks)} task(s) x {len(args.motion_gains)} K_theta x "
               f"{len(args.remnant_fractions)} F_n, {_FITS_SAID[args.fits]}) on "
               f"{_cluster_where(args)} -> {out}")
    try:
        # (its warnings, the fits' said once per kind and the cluster's, as the command's lines)
        with _warnings_of(RuntimeWarning, _warning_line):
            summary = run_campaign(jobs, out, scheduler=args.scheduler, workers=args.workers,
                                   progress=_cluster_progress(args),
                                   connect_timeout=args.connect_timeout)
    except CampaignError as exc:
        raise CommandFailed(str(exc)) from None
    _say(args, str(summary))
    results = load_results(out, jobs)
    if not results:
        raise CommandFailed(f"no fit finished; the errors are in {out}/<key>.error.json")
    rows = summarise(results)
    table = summary_markdown(rows)
    csv_path, md_path, png = out / "summary.csv", out / "summary.md", out / "delta_abs_histograms.png"
    header = (f"# Simulation study of Pool et al. (2012), Section III.B.2: ours beside Figs. 14/15\n\n"
              f"{len(results)} of {len(jobs)} fits finished ({args.method} method"
              f"{'' if args.duration is None else f', {args.duration:g}-s runs'}"
              f"{', options ' + str(dict(args.fit_option)) if args.fit_option else ''}).\n"
              f"mu, sigma: mean and standard deviation (ddof 1) of the final delta_abs; N50: "
              f"estimates within +-50 % of the true 0.0075 IPUT. The paper's columns are the "
              f"fits with threshold over 100 realizations. flag: N50 differs from the paper's "
              f"by more than 2 binomial standard deviations, or mu by more than 2 standard "
              f"errors.\n\n")
    fractions = [f for f in args.remnant_fractions if f in (0.0, 0.2, 0.3)] \
        or list(args.remnant_fractions)
    try:
        # (the figure of an earlier call removed first: it would stand beside tables of
        # other results if the new one cannot be drawn)
        for fmt in ("png", "pdf", "svg"):
            png.with_suffix(f".{fmt}").unlink(missing_ok=True)
        write_summary_csv(rows, csv_path)
        write_text_atomic(md_path, header + table + "\n")
    except OSError as exc:
        raise CommandFailed(f"cannot write the summary in {out} ({_os_reason(exc)})") from None
    print(table)
    if any(r["threshold"] for r in results):
        from .plots import plot_threshold_histograms

        figures = _save_figure(plot_threshold_histograms(results, fractions=fractions,
                                                         method=args.method,
                                                         upper=args.hist_upper,
                                                         title=_title(args)),
                               png, args.dpi, _formats(args))
        _say(args, f"wrote {csv_path}, {md_path} and {' and '.join(map(str, figures))}")
    else:
        _say(args, f"wrote {csv_path} and {md_path} (no fit with threshold finished: no figure)")
    if summary.failed:
        raise CommandFailed(f"{summary.failed} of {summary.total} fits failed (messages in "
                            f"{out}/<key>.error.json); run the same command again to retry them")
    return EXIT_OK


# --- posteriors and model comparison (bayespilot.sample, bayespilot.compare) ----------------------
def _said_to_user(w: warnings.WarningMessage) -> bool:
    """Whether a warning a command recorded is printed: the computation's (RuntimeWarning and
    its subclasses) and the recording's (QuestionableRecordingWarning: a stick offset)."""
    from .recording import QuestionableRecordingWarning

    return issubclass(w.category, (RuntimeWarning, QuestionableRecordingWarning))


def _print_warnings(caught) -> None:
    """Warnings caught during a computation, one line each on stderr."""
    seen = set()
    for w in caught:
        text = _in_cli_words(w.message)
        if text not in seen:
            seen.add(text)
            print(f"{PROG}: warning: {text}", file=sys.stderr)


def _read_posterior(path: str):
    """A Posterior from a netCDF file written by 'bayespilot sample'; problems are bad input."""
    from .sample import Posterior

    p = Path(path)
    if not p.exists():
        raise UsageError(f"{p}: posterior file not found")
    if p.is_dir():
        raise UsageError(f"{p}: is a directory, not a posterior (.nc) file")
    _import_arviz()  # (outside the try below: its failure is not the file's)
    try:
        return Posterior.from_netcdf(p)
    except ValueError as exc:  # (the library names its method: said in the command's words)
        said = str(exc)
        for library in ("written by Posterior.to_netcdf", "written by bayespilot.sample"):
            said = said.replace(library, f"written by '{PROG} sample' (or Posterior.to_netcdf)")
        raise UsageError(said) from None
    except Exception as exc:  # netCDF4/h5netcdf/xarray raise many types for a file that is not netCDF
        raise UsageError(f"{p}: is not a netCDF posterior written by '{PROG} sample' (or "
                         f"Posterior.to_netcdf): reading it raised {type(exc).__name__}") from None


def _import_arviz():
    """arviz (``sample._arviz``), or a failure (exit 1) that names why it cannot be imported.

    arviz writes below HOME when imported (``~/.cache/arviz``): with an unwritable HOME its
    import raises OSError, which the handlers of a posterior's reading or the sampler's
    backend took for a problem with the user's file.
    """
    from .sample import _arviz

    try:
        return _arviz()
    except Exception as exc:  # noqa: BLE001 - whatever arviz's import raises
        hint = "; is HOME writable? arviz writes to ~/.cache" if isinstance(exc, OSError) else ""
        raise CommandFailed(f"cannot import arviz ({type(exc).__name__}: {exc}){hint}") from None


def _write_json(path: str, obj, *, version: bool = True) -> None:
    """``obj`` as JSON at ``path``, atomically (a failed write keeps the old file); with the
    bayespilot version unless ``version`` is False (see ``_files.dumps``)."""
    from ._files import dumps, write_text_atomic

    try:
        write_text_atomic(path, dumps(obj, version=version))
    except OSError as exc:
        raise CommandFailed(f"{path}: cannot write ({_os_reason(exc)})") from None


def _os_reason(exc: OSError) -> str:
    """Why a file could not be written, in words: a path through a file says which one
    (the error said 'File exists' or 'Not a directory')."""
    if isinstance(exc, (FileExistsError, NotADirectoryError)):
        return (f"{exc.filename} is a file, not a folder" if exc.filename and
                isinstance(exc, FileExistsError) else "a part of the path is a file, not a folder")
    # (one line: HDF5's texts break lines, and an error is one line)
    return " ".join(str(exc.strerror or exc).split())


#: Bytes :func:`_check_writable` writes beside an output before the computation: one block of
#: a file system, which a full disk refuses (an empty file it accepted, and the computation
#: ran to fail at the end).  A disk with less free than the output needs still passes.
_PROBE_BYTES = 4096


def _check_writable(path: str | Path, what: str) -> None:
    """Refuse, before a long computation, an output file that could not be written (its
    result would be lost): the folder is created and :data:`_PROBE_BYTES` written beside it
    and removed (also when the write fails)."""
    from ._files import temporary_sibling

    p = Path(path)
    # (Path drops a trailing slash: 'dir/' not yet there wrote a file named 'dir')
    if p.is_dir() or str(path).endswith(("/", os.sep)):
        raise UsageError(f"{path}: is a folder; give a file name for the {what}")
    probe = None
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        probe = temporary_sibling(p)
        probe.write_bytes(b"\0" * _PROBE_BYTES)
    except OSError as exc:
        raise CommandFailed(f"{p}: cannot write the {what} ({_os_reason(exc)})") from None
    finally:
        if probe is not None:
            with contextlib.suppress(OSError):
                probe.unlink()


def _recording_files(spec: str) -> list[tuple[str, Path]]:
    """(what, path) of each file a recording argument is read from.

    The files are ``io._resolve``'s, the resolution ``io.read_recording`` itself uses (a
    copy of it here had lower-cased ``up.CSV`` to ``up.csv``: the file read went
    unguarded, and another file was refused): a ``.mat`` file; a ``.csv`` or ``.json``, as
    given, with its partner; for a stem, all of ``STEM.csv``, ``STEM.json`` and
    ``STEM.mat``: the ones it reads and the ones it would read instead (a ``STEM.json``
    written beside a lone ``STEM.mat`` hides the recording).  None for a spec that names
    no recording: the read refuses it before anything is written.
    """
    from . import io as recording_io
    from .recording import RecordingError

    p = Path(spec)
    where = f"the recording REC {spec}"
    try:
        kind, stem, first, second = recording_io._resolve(p, spec)
    except (RecordingError, OSError):  # (said by the read, in its words)
        return []
    if stem != p:  # a file named: it (and a CSV's or JSON's partner) is what is read
        if kind == "mat":
            return [(where, first)]
        return [(f"the CSV of {where}", first), (f"the JSON sidecar of {where}", second)]
    added = recording_io._with_suffix_added
    return [(f"the CSV of {where}", added(p, ".csv")),
            (f"the JSON sidecar of {where}", added(p, ".json")),
            (f"the .mat file of {where}", added(p, ".mat"))]


def _code_files(specs: Sequence[str], option: str) -> list[tuple[str, Path]]:
    """(what, path) of the Python files among --with/--extension's ``FILE.py:NAME``."""
    out = []
    for spec in specs:
        where, sep, _ = spec.rpartition(":")
        if sep and where.endswith(".py"):
            out.append((f"the {option} file", Path(where)))
    return out


def _file_key(path: Path) -> tuple[tuple[int, int] | None, str]:
    """What :func:`_same_file` compares of ``path``: its ``(st_dev, st_ino)`` when it exists
    and can be stat'ed (None when not), and its resolved path."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):  # (missing, or cannot be stat'ed: by its resolved path)
        inode = None
    else:
        inode = (st.st_dev, st.st_ino)
    return inode, os.path.realpath(path)


def _same_file(a: Path, b: Path) -> bool:
    """Whether ``a`` and ``b`` are one file: :func:`os.path.samefile` where both exist (a
    hard link, a symlink, another case on a case-insensitive disk), else the resolved
    paths."""
    (inode_a, real_a), (inode_b, real_b) = _file_key(a), _file_key(b)
    if inode_a is not None and inode_b is not None:
        return inode_a == inode_b
    return real_a == real_b


class _FileIndex:
    """Files, each with a value, and the first of them that is one file with a given path, by
    :func:`_same_file`'s rule (by inode where both exist, else by resolved path), found in
    constant time.  :func:`_refuse_overwriting` compared each output with every input and
    every earlier output: 4 million comparisons, 2 minutes, before a fit-batch of 720
    recordings started (and before each of its resumes)."""

    def __init__(self) -> None:
        self._inodes: dict[tuple[int, int], int] = {}  # the existing files
        self._paths: dict[str, int] = {}  # every file, by its resolved path
        self._missing: dict[str, int] = {}  # those without an inode, by resolved path
        self._values: list = []

    def add(self, key: tuple[tuple[int, int] | None, str], value) -> None:
        """Add a file (its :func:`_file_key`) with its value."""
        inode, real = key
        i = len(self._values)
        self._values.append(value)
        self._paths.setdefault(real, i)
        if inode is None:
            self._missing.setdefault(real, i)
        else:
            self._inodes.setdefault(inode, i)

    def first(self, key: tuple[tuple[int, int] | None, str]):
        """The value of the first file added that is the file of ``key``, or None."""
        inode, real = key
        if inode is None:  # (compared with every file by resolved path)
            hits = [self._paths.get(real)]
        else:  # (by inode with the existing ones, by resolved path with the others)
            hits = [self._inodes.get(inode), self._missing.get(real)]
        first = min((i for i in hits if i is not None), default=None)
        return None if first is None else self._values[first]


def _refuse_overwriting(outputs: Sequence[tuple[str, str | Path | None]],
                        inputs: Sequence[tuple[str, str | Path | None]], *,
                        recordings: bool = True) -> None:
    """Refuse (exit 2), before anything is computed, an output that is a file the command
    reads, another output of it, or a file of a recording.

    The outputs are replaced atomically and the command says it succeeded, so a typo
    (``--json out/run.json`` for ``out/run-fit.json``) destroyed the recording's sidecar,
    the ``--params`` file or the posterior read, without a word; so did one that named
    another recording's file (``--json recs/s2-run1.csv``, ``--json recs/s1-run2.json``):
    a lab's measurement, which cannot be made again (:func:`_recording_part`).  A previous
    result of the command (a fit's JSON written again) is replaced, as the option says.

    Parameters
    ----------
    outputs : sequence of (option, path)
        Each file the command will write, with the option that names it; a None path is
        not given.
    inputs : sequence of (what, path)
        Each file the command reads, said as ``what`` (e.g. "the --params file"); None is
        not given.  An input that is also an output (``sample --backend``) is left out of
        ``inputs``: writing it is what the option asks for.
    recordings : bool
        Also refuse an output that is an existing recording's file (True); ``simulate``,
        which writes recordings, has its own rule (:func:`_refuse_replacing_a_recording`).

    Raises
    ------
    UsageError
        An output is one of the inputs, two outputs are one file, or (``recordings``) an
        output is a file of an existing recording.
    """
    read = _FileIndex()  # (each file stat'ed once: the check is linear in the files)
    for what, path in inputs:
        if path is not None:
            read.add(_file_key(Path(path)), (what, Path(path)))
    seen = _FileIndex()
    for option, path in outputs:
        if path is None:
            continue
        out = Path(path)
        key = _file_key(out)
        found = read.first(key)
        if found is not None:
            what, src = found
            said = what if out == src else f"{src}, {what}"
            raise UsageError(f"argument {option}: {out} is {said}, which this command "
                             f"reads: writing it would destroy that input; give another "
                             f"file name")
        found = seen.first(key)
        if found is not None:
            raise UsageError(f"argument {option}: {out} is also the file of {found}; give "
                             f"each output its own file name")
        seen.add(key, option)
        part = _recording_part(out) if recordings else None
        if part is not None:
            where = ("use another --out folder" if option == "--out" else
                     "give another file name")
            raise UsageError(f"argument {option}: {out} is {part}: a measurement, which "
                             f"writing there would destroy; {where}")


def _is_recording_sidecar(path: Path) -> bool:
    """Whether ``path`` is a recording's JSON sidecar: a JSON object whose ``"format"`` is the
    recording format's (``bayespilot-recording/1``, docs/recording-format.md; a later
    version's too)."""
    try:
        data = path.read_bytes()
    except OSError:  # (missing, a folder, unreadable: not one said here)
        return False
    if b"bayespilot-recording/" not in data:  # (a result file: not parsed)
        return False
    try:
        obj = json.loads(data.decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError, RecursionError):
        return False
    fmt = obj.get("format") if isinstance(obj, dict) else None
    return isinstance(fmt, str) and fmt.startswith("bayespilot-recording/")


def _recording_part(path: Path) -> str | None:
    """What of a recording the existing file ``path`` is, said for a refusal, or None.

    A JSON sidecar (its ``"format"`` is the recording format's), a ``.csv`` beside such a
    sidecar (``STEM.csv`` with ``STEM.json``: the pair :func:`bayespilot.io.read_recording`
    reads), or a ``.mat`` file (bayespilot reads .mat recordings and writes none).  A file
    of a command's own (a fit's JSON written before) is not one: it is replaced."""
    from .io import _pair_paths

    if not path.is_file():
        return None
    suffix = path.suffix.lower()
    if suffix == ".mat":
        return "a .mat file, a recording as bayespilot reads one (it writes no .mat file)"
    if suffix == ".csv":
        sidecar = _pair_paths(path)[1]
        if _is_recording_sidecar(sidecar):
            return (f"the CSV of the recording {path.with_suffix('')} (its sidecar {sidecar} "
                    f"is a recording's)")
        return None
    if suffix == ".json" and _is_recording_sidecar(path):
        return "the JSON sidecar of a recording (its \"format\" is the recording format's)"
    return None


def _refuse_replacing_a_recording(out: str | Path, option: str = "-o/--output",
                                  force: bool = True) -> None:
    """Refuse (exit 2) to replace a recording that ``bayespilot simulate`` did not write.

    A simulated recording's sidecar says so (its ``"simulation"`` key): simulating onto it
    again is the common case (a changed seed) and replaces it, as ``-o`` says.  A lab's
    recording at that stem (a sidecar without it, or a CSV without a sidecar) is a
    measurement that cannot be made again; ``--force`` replaces it all the same (``force``:
    the command has it, said in the message; ``option`` names the option that put the
    recording there, ``demo --quick``'s ``--out``).

    Raises
    ------
    UsageError
        A file of the stem exists and is not a simulated recording's.
    """
    from .io import _pair_on_disk

    files, sidecar, simulated = _pair_on_disk(out)
    if not files or simulated:
        return
    there = " and ".join(str(p) for p in files)
    why = ("no \"simulation\" in its sidecar" if sidecar is not None else
           "a file without a simulated recording's sidecar")
    raise UsageError(f"argument {option}: {there} "
                     f"{'are' if ' and ' in there else 'is'} not a recording 'bayespilot "
                     f"simulate' wrote ({why}: a lab's measurement, or another file): "
                     f"simulating onto it would replace it; "
                     + ("give another name, or --force to replace it" if force else
                        "give another folder"))


def _stem_files(out: str) -> list[Path]:
    """The CSV and JSON that ``write_recording(..., out)`` writes (a stem, or its .csv or
    .json): io's own rule."""
    from .io import _pair_paths

    return list(_pair_paths(Path(out)))


def _report_files(folder: str | Path) -> list[Path]:
    """The files a diagnosis's report writes (or, as a stale figure, removes) in ``folder``:
    its figures in every format (the report module's list of them, ``FIGURES``: a figure
    added there is guarded here too), ``diagnosis.json``, ``report.html`` and the
    manifest."""
    from .diagnose.report import FIGURES, FORMATS, MANIFEST

    return [Path(folder) / name for name in (
        "diagnosis.json", "report.html", MANIFEST,
        *(f"{figure}.{fmt}" for figure in FIGURES for fmt in FORMATS))]


def _cmd_sample(args: argparse.Namespace) -> int:
    from .sample import sample

    out = Path(args.output)
    if out.suffix != ".nc":
        raise UsageError(f"argument -o/--output: {out} must end in .nc (a netCDF file)")
    if args.likelihood == "coloured" and args.ar == "profiled" and args.ar_order == 0:
        # (sample() refuses it too, in its keywords' words: said here in the options')
        raise UsageError("argument --ar-order: 0 with --ar profiled: a profiled AR model needs "
                         "an order >= 1; leave --ar-order out for the order chosen by BIC, or "
                         "give --likelihood eq4 for white output error")
    # (--backend is read and written: it is an output here, never the recording's)
    _refuse_overwriting([("-o/--output", args.output), ("--json", args.json),
                         ("--backend", args.backend)],
                        [*_recording_files(args.recording),
                         *_code_files(args.extended_by, "--with")])
    rec = _read(args.recording)
    model = _paper_model_with(args, rec)
    _import_arviz()  # (before the sampler: its failure is not the backend's, nor lost hours)
    _check_writable(args.output, "posterior")  # hours of sampling are not lost to an unwritable file
    if args.json:
        _check_writable(args.json, "summary")
    if args.backend:  # (its folder made, as the posterior's: refused after the fit, it was)
        _check_writable(args.backend, "sampler's backend file")
    _say(args, f"sampling the posterior of {rec.source} ({args.likelihood} likelihood, at most "
               f"{args.max_steps} steps; starts with a maximum-likelihood fit) ...")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            post = sample(rec, model,
                          likelihood=args.likelihood, ar=args.ar, ar_order=args.ar_order,
                          seed=args.seed,
                          max_steps=args.max_steps, min_steps=min(1000, args.max_steps),
                          progress=_progress(args), backend=args.backend)
        except RuntimeError as exc:
            raise CommandFailed(str(exc)) from None
        except ValueError as exc:  # e.g. a backend file of another run
            raise UsageError(str(exc)) from None
        except OSError as exc:  # the HDF5 backend cannot be created or opened
            if args.backend is None:  # (not the backend's: unexpected, said as such)
                raise
            raise CommandFailed(f"{args.backend}: cannot open the sampler's backend file "
                                f"({_os_reason(exc)})") from None
    _print_warnings(w for w in caught if _said_to_user(w))
    # (before the file: a write that fails still leaves the summary; a stdout that fails
    # does not stop the command before the file, see _GuardedStdout)
    print(post)
    try:
        post.to_netcdf(out)
    except OSError as exc:
        raise CommandFailed(f"{out}: cannot write the posterior ({_os_reason(exc)})") from None
    _say(args, f"wrote {out}")
    if args.json:
        # fit-batch's "posterior" object (summary, converged, steps, file) and what the
        # chain was run on (a bare table said neither whether it converged nor of what)
        st = post.settings
        _write_json(args.json, {
            "summary": post.summary(), "converged": bool(post.converged),
            "steps": int(st["n_steps"]), "file": str(out), "seed": post.seed,
            **{k: st.get(k) for k in ("likelihood", "max_steps", "min_steps", "model",
                                      "recording", "recording_sha256")}})
        _say(args, f"wrote {args.json}")
    return EXIT_OK


def _cmd_compare(args: argparse.Namespace) -> int:
    from .compare import compare

    _refuse_overwriting([("--json", args.json)],
                        [*_recording_files(args.recording),
                         ("the --posterior file", args.posterior),
                         *_code_files(args.extended_by, "--with")])
    posterior = _read_posterior(args.posterior) if args.posterior else None
    rec = _read(args.recording)
    # (compare's model without threshold is this one's without_threshold(): a soft dead
    # zone of --with threshold-shape removed, the linear model)
    model = _paper_model_with(args, rec)
    if args.json:
        _check_writable(args.json, "comparison")
    _say(args, f"comparing the model with and without threshold on {rec.source} "
               f"({args.likelihood} likelihood, dynesty with {args.nlive} live points) ...")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            result = compare(rec, model,
                             likelihood=args.likelihood, ar=args.ar, ar_order=args.ar_order,
                             seed=args.seed, nlive=args.nlive,
                             posterior=posterior,
                             savage_dickey_samples=not args.no_savage_dickey,
                             progress=_progress(args))
        except RuntimeError as exc:
            raise CommandFailed(str(exc)) from None
        except ValueError as exc:  # e.g. a --posterior of another recording: bad input
            raise UsageError(str(exc)) from None
    _print_warnings(w for w in caught if _said_to_user(w))
    print(result.summary())
    if args.json:
        d = result.to_dict()
        if args.posterior and isinstance(d["settings"].get("posterior"), dict):
            d["settings"]["posterior"]["file"] = str(args.posterior)  # (the file it read)
        _write_json(args.json, d)
        _say(args, f"wrote {args.json}")
    return EXIT_OK


def _cmd_plot(args: argparse.Namespace) -> int:
    from . import presets
    from .plots import _posterior_model, plot_chains, plot_marginal, plot_pair

    formats = _formats(args)
    figures = [Path(args.output) / f"{name}.{fmt}" for name in ("pair", "trace")
               for fmt in formats]
    if Path(args.posterior).name.startswith("marginal_"):  # (marginal_<parameter>.<format>)
        figures.append(Path(args.output) / Path(args.posterior).name)
    _refuse_overwriting([("-o/--output", f) for f in figures],
                        [("the posterior POST.nc", args.posterior)])
    post = _read_posterior(args.posterior)
    # a posterior of a catalogue extension (written by 'diagnose'): its model gives the units
    model = _posterior_model(post)
    out = Path(args.output)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CommandFailed(f"{out}: cannot create the folder ({_os_reason(exc)})") from None
    truth = post.truth
    names = post.parameter_names
    main = "delta_abs" if "delta_abs" in names else names[0]
    written = []
    # delta_abs (or the first parameter), then each parameter an extension adds
    added = [n for n in names if n not in presets.PARAMETER_NAMES and not n.startswith("pacf_")]
    title = _title(args)
    # (without titles each figure's ConvergenceWarning: said once, below, in the command's words)
    with _untitled_notes() as notes:
        for name in dict.fromkeys([main, *added]):
            written += _save_figure(plot_marginal(post, name, truth=truth.get(name),
                                                  model=model, title=title),
                                    out / f"marginal_{name}", args.dpi, formats)
        pair = [n for n in ("K_m", "tau_m", "delta_abs") if n in names]
        if pair:
            written += _save_figure(plot_pair(post, pair, truth=truth, model=model,
                                              title=title), out / "pair", args.dpi, formats)
        written += _save_figure(plot_chains(post, model=model, title=title), out / "trace",
                                args.dpi, formats)
    if notes:
        steps = post.settings.get("n_steps")
        print(f"{PROG}: warning: {args.posterior}: the chain has not converged"
              f"{f' ({steps} steps)' if steps else ''}; the figures' titles, which say so, are "
              f"left out (--no-title): say it in their captions", file=sys.stderr)
    note = (f" (true {main} = {truth[main]:g} marked)" if main in truth else "")
    _say(args, "wrote " + ", ".join(str(p) for p in written) + note)
    return EXIT_OK



def _weigh(args: argparse.Namespace, res, rec) -> None:
    """--bayes-factor: ln BF of the chosen (or top-ranked) extension, stored on ``res``."""
    from .diagnose import bayes_factor

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            name = res.physics if res.physics != "none" else "the top-ranked candidate"
            _say(args, f"weighing {name} against the base model by nested sampling (three "
                       "runs per model, minutes) ...")
            bf = bayes_factor(res, rec, seed=args.seed, progress=_progress(args))
    except ValueError as exc:  # e.g. control-saturation: nothing to weigh
        print(f"{PROG}: warning: no Bayes factor: {exc}", file=sys.stderr)
        return
    _say(args, bf.summary_line())


def _cmd_diagnose(args: argparse.Namespace) -> int:
    from .diagnose import (candidate_names, diagnose, diagnose_pooled, get_extension,
                           sample_chosen, shared_posterior)
    from .diagnose.pooled import PoolingWarning, pooling_disagreements

    if args.bayes_factor and len(args.recording) > 1:
        raise UsageError("argument --bayes-factor: takes one recording (the evidence of a "
                         "pooled model is not built)")
    if args.report_format and not args.report:
        raise UsageError("argument --report-format: needs --report DIR (the folder the "
                         "figures are written to)")
    if args.no_title and not args.report:
        raise UsageError("argument --no-title: needs --report DIR (the figures it leaves the "
                         "titles out of)")
    if args.posterior is not None:
        want = ".nc" if len(args.recording) == 1 else ".json"
        if Path(args.posterior).suffix != want:
            raise UsageError(f"argument --posterior: {args.posterior} must end in {want} "
                             + ("(a netCDF file of the draws)" if want == ".nc" else
                                "(several runs: the shared parameters' posterior on a grid, "
                                "as JSON)"))
    report = _report_files(args.report) if args.report else []
    if args.json:  # (the report's diagnosis.json is the --json's content: the same file is fine)
        report = [f for f in report if not (f.name == "diagnosis.json"
                                            and _same_file(f, Path(args.json)))]
    _refuse_overwriting([("--json", args.json), ("--posterior", args.posterior),
                         *(("--report", f) for f in report)],
                        [*(f for r in args.recording for f in _recording_files(r)),
                         *_code_files(args.extension, "--extension")])
    _load_extensions(args.extension)
    recs = [_read(r) for r in args.recording]
    for path, what in ((args.posterior, "posterior"), (args.json, "diagnosis")):
        if path:  # checked before the diagnosis: its minutes are not lost to a bad path
            _check_writable(path, what)
    if args.report:  # (a block written in the folder: a full disk is refused now, too)
        _check_writable(Path(args.report) / "report.html", "report")
    try:
        if len(recs) == 1:
            rec = recs[0]
            _say(args, f"diagnosing {rec.source}: base fit, located evidence ({args.bootstrap} "
                       f"bootstrap replicates), {len(candidate_names())} catalogue extensions ...")
            res = diagnose(rec, seed=args.seed, n_bootstrap=args.bootstrap, alpha=args.alpha,
                           n_calibrate=args.calibrate, noise_passes=args.noise_passes,
                           progress=_progress(args))
        else:
            _say(args, f"diagnosing {len(recs)} runs pooled (extension parameters shared, "
                       f"pilot parameters per run): base fits, located evidence "
                       f"({args.bootstrap} bootstrap replicates each), {len(candidate_names())} catalogue "
                       f"extensions ...")
            mixed = pooling_disagreements(recs)
            if mixed:  # said now, before the long computation
                print(f"{PROG}: warning: the runs are not of one subject and condition "
                      f"({mixed}); pooling assumes the physics left out is the same in every "
                      "run", file=sys.stderr)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", PoolingWarning)
                res = diagnose_pooled(recs, seed=args.seed, n_bootstrap=args.bootstrap,
                                      alpha=args.alpha, n_calibrate=args.calibrate,
                                      noise_passes=args.noise_passes, progress=_progress(args))
    except ValueError as exc:  # e.g. a recording too short for the analysis
        raise UsageError(str(exc)) from None
    # (a posterior that cannot be written fails the command at the end: the diagnosis is
    # still printed and its --json and --report written; it was lost with the posterior)
    unwritten: str | None = None
    if args.posterior is not None:
        if res.chosen is None or get_extension(res.physics).likelihood != "gls":
            # asked for a file and none is written: a warning, even with --quiet
            print(f"{PROG}: warning: decision {res.physics}: no extended model to sample; "
                  f"{args.posterior} not written", file=sys.stderr)
        elif len(recs) > 1:
            _say(args, f"the posterior of {res.physics}'s shared parameters and its Bayes "
                       "factor (a grid; each run's pilot parameters refitted and integrated "
                       "out) ...")
            from ._files import dumps, write_text_atomic

            try:
                shared_posterior(res, recs, progress=_progress(args))
            except ValueError as exc:
                raise CommandFailed(str(exc)) from None
            try:
                write_text_atomic(args.posterior, dumps(res.posterior.to_dict()))
                _say(args, f"wrote {args.posterior}")
            except OSError as exc:
                unwritten = f"{args.posterior}: cannot write the posterior ({_os_reason(exc)})"
        else:
            _say(args, f"sampling the posterior of the model with {res.physics} (coloured "
                       "likelihood, started at its fit) ...")
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                try:
                    post = sample_chosen(res, recs[0], seed=args.seed, progress=_progress(args))
                except RuntimeError as exc:
                    raise CommandFailed(str(exc)) from None
            _print_warnings(w for w in caught if _said_to_user(w))
            try:
                post.to_netcdf(args.posterior)
                _say(args, f"wrote {args.posterior}")
            except OSError as exc:
                unwritten = f"{args.posterior}: cannot write the posterior ({_os_reason(exc)})"
    if args.bayes_factor:
        _weigh(args, res, recs[0])
    print(res.summary())
    also = "" if unwritten is None else f"; and {unwritten}"  # (said with a later failure)
    if args.json:
        try:
            res.to_json(args.json)
        except OSError as exc:
            raise CommandFailed(f"{args.json}: cannot write the diagnosis ({_os_reason(exc)})"
                                f"{also}") from None
        _say(args, f"wrote {args.json}")
    if args.report:
        try:
            paths = res.report(args.report, formats=args.report_format, title=_title(args))
        except OSError as exc:
            # (a report that fails part-way removes its diagnosis.json, which --json may be:
            # written again, as the command said it was)
            if args.json and not Path(args.json).exists():
                with contextlib.suppress(OSError):
                    res.to_json(args.json)
            raise CommandFailed(f"{args.report}: cannot write the report "
                                f"({_os_reason(exc)}){also}") from None
        _say(args, f"wrote {paths['html']} (with {', '.join(p.name for k, p in paths.items() if k not in ('html', 'manifest'))})")
    if unwritten:
        raise CommandFailed(f"{unwritten}; the diagnosis above was printed"
                            f"{' and its other files written' if args.json or args.report else ''}")
    return EXIT_OK


def _recordings_in(args_paths: Sequence[str]) -> list[str]:
    """The recordings named: each path as given, a folder as every recording in it (sorted):
    each CSV with its JSON sidecar (by stem) and each .mat file."""
    out: list[str] = []
    for a in args_paths:
        d = Path(a)
        if not d.is_dir():
            out.append(a)
            continue
        found = sorted({str(c.with_suffix("")) for c in d.glob("*.csv")
                        if c.with_suffix(".json").is_file()} | {str(m) for m in d.glob("*.mat")})
        orphans = sorted(c.name for c in d.glob("*.csv") if not c.with_suffix(".json").is_file())
        if orphans:  # (a CSV without its sidecar is not a recording: said, not skipped)
            raise UsageError(f"{a}: {', '.join(orphans[:5])}{' ...' if len(orphans) > 5 else ''}"
                             f" without {'its' if len(orphans) == 1 else 'their'} JSON sidecar"
                             f" (a recording is NAME.csv with NAME.json); add "
                             f"{'it' if len(orphans) == 1 else 'them'}, or move the CSV "
                             f"file{'' if len(orphans) == 1 else 's'} out of the folder")
        if not found:
            raise UsageError(f"{a}: a folder without recordings (no NAME.csv with its "
                             "NAME.json, no .mat file)")
        out += found
    return out


def _batch_keys(paths: Sequence[str], *, pool: bool) -> list[str] | None:
    """The keys of ``diagnose_batch(paths, ..., pool=pool)`` (and, with ``pool`` False, of
    ``fit_batch(paths, ...)``): ``plan_batch`` on the recordings, a recording named twice
    counted once, as the batches do.  The recordings are
    read for it (milliseconds each; a pooled key is their subject and condition).  None
    when one cannot be read or the keys clash: the batch refuses that before it writes
    anything."""
    from .diagnose.batch import _the_recording, plan_batch
    from .io import read_recording
    from .recording import RecordingError

    first: dict[str, str] = {}
    for p in paths:
        first.setdefault(_the_recording(p), p)
    unique = list(first.values())
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # (the batch's own read says them, once)
            recordings = [read_recording(p) for p in unique]
        return [task.key for task in plan_batch(unique, recordings, pool=pool)]
    except (RecordingError, ValueError, OSError):
        return None


def _batch_files(paths: Sequence[str], out: str | Path, *, pool: bool,
                 reports: bool, keys: Sequence[str] | None = None,
                 formats: Sequence[str] = ("png",)) -> list[Path]:
    """The files ``diagnose_batch(paths, out, pool=pool, reports=reports)`` may write (those of
    ``fit_batch(paths, out)`` with ``pool`` and ``reports`` False, but for its
    ``conditions.csv``).

    ``summary.csv`` and ``summary.<format>`` of each of ``formats`` (``summary.png``), and
    for each diagnosis ``<key>.json`` (or
    ``<key>.error.json``) and, with ``reports``, its report in ``<key>/``.  The keys are
    the batch's own (``plan_batch`` on the recordings, a recording named twice counted
    once, as the batch does): guessed from the recordings' names, ``a/run out/run --out
    out`` was refused for ``out/run.json``, which the batch (keys ``a_run``, ``out_run``)
    never writes.  The recordings are read for it (milliseconds each; a pooled key is
    their subject and condition).  When one cannot be read or the keys clash, only the
    summary's files: the batch refuses that before it writes anything.

    Parameters
    ----------
    paths : sequence of str
        The recordings, as the batch is given them.
    out : str or Path
        The batch's ``--out`` folder.
    pool, reports : bool
        As ``diagnose_batch`` takes them.
    keys : sequence of str, optional
        The batch's keys, if :func:`_batch_keys` has given them already (None: taken here).
    formats : sequence of str, optional
        The formats of the summary's figure (diagnose-batch's --format).

    Returns
    -------
    list of Path
    """
    out = Path(out)
    files = [out / "summary.csv", *(out / f"summary.{fmt}" for fmt in formats)]
    if keys is None:
        keys = _batch_keys(paths, pool=pool) or ()
    for key in keys:
        files += [out / f"{key}.json", out / f"{key}.error.json"]
        if reports:
            files += _report_files(out / key)
    return files


@contextlib.contextmanager
def _batch_errors():
    """Within: diagnose-batch's and fit-batch's refusals and failures as the command's. A
    result in DIR of another recording or other settings (ResultConflictError) and bad input
    (a ValueError: an unreadable recording, one the settings do not suit) are exit 2; the
    cluster's failures (CampaignError) exit 1."""
    from .campaign import CampaignError
    from .diagnose.batch import ResultConflictError

    try:
        yield
    except ResultConflictError as exc:  # (a CampaignError and a ValueError: bad input)
        raise UsageError(str(exc)) from None
    except CampaignError as exc:
        raise CommandFailed(str(exc)) from None
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _earlier_rows(table: str, summary) -> int:
    """How many rows of a batch's summary.csv (its text) an earlier run made: the table
    covers every result in DIR made with the batch's settings."""
    import csv

    return len(list(csv.DictReader(table.splitlines(keepends=True)))) - summary.total


def _cmd_diagnose_batch(args: argparse.Namespace) -> int:
    from .diagnose.batch import (MissingReportWarning, SummaryScopeWarning, _the_recording,
                                 diagnose_batch)
    from .diagnose.locate import EvidenceWarning

    _cluster_choice(args)
    _load_extensions(args.extension)
    paths = _recordings_in(args.recording)
    read = [f for p in paths for f in _recording_files(p)]
    keys = _batch_keys(paths, pool=args.pool) or []  # (none: the batch refuses the input)
    formats = _formats(args)
    _refuse_overwriting([("--out", f) for f in _batch_files(paths, args.out, pool=args.pool,
                                                            reports=args.reports, keys=keys,
                                                            formats=formats)],
                        [*read, *_code_files(args.extension, "--extension")])
    # (said before the recordings are read: a refusal of one of them may follow, and nothing
    # has run then)
    _say(args, f"{len({_the_recording(p) for p in paths})} recording(s) to diagnose"
               f"{', the runs of each subject and condition pooled' if args.pool else ''} "
               f"on {_cluster_where(args)} -> {args.out}; each is read and checked before "
               f"anything runs")
    unreported = []  # MissingReportWarning: finished before, without a report

    def said(message) -> None:  # --reports, and finished diagnoses it cannot give one
        unreported.append(message)
        print(f"{PROG}: warning: {message}", file=sys.stderr)

    # (the evidence's gaps: one line per kind of gap, after the diagnoses, from their
    # results; the workers keep them quiet)
    with _batch_errors(), _questionable_said(), _warnings_of(MissingReportWarning, said), \
            _warnings_of((EvidenceWarning, SummaryScopeWarning, RuntimeWarning), _warning_line):
        summary = diagnose_batch(paths, args.out, pool=args.pool, seed=args.seed,
                                 alpha=args.alpha, n_bootstrap=args.bootstrap,
                                 n_calibrate=args.calibrate,
                                 noise_passes=args.noise_passes, reports=args.reports,
                                 posterior=args.posterior, formats=formats, dpi=args.dpi,
                                 title=_title(args),
                                 scheduler=args.scheduler, workers=args.workers,
                                 progress=_cluster_progress(args),
                                 connect_timeout=args.connect_timeout)
    _say(args, str(summary))
    with open(Path(args.out) / "summary.csv", encoding="utf-8") as fh:
        table = fh.read()
    print(table, end="")
    # (the summary covers every diagnosis in DIR made with these settings: say so when an
    # earlier run's are in it)
    earlier = _earlier_rows(table, summary)
    if not args.reports:
        reports = ""
    elif unreported:
        reports = (", with its report in <key>/ except for the diagnoses finished before "
                   "without one (see the warning)")
    else:
        reports = " with its report in <key>/"
    scope = (f" (with {earlier} diagnos{'is' if earlier == 1 else 'es'} an earlier run made "
             f"in {args.out} with these settings)" if earlier > 0 else "")
    # (the figure is written when any diagnosis finished)
    figures = [f for f in (Path(args.out) / f"summary.{fmt}" for fmt in formats) if f.is_file()]
    _say(args, f"wrote {Path(args.out) / 'summary.csv'}{scope}"
               f"{''.join(f', {f}' for f in figures)} and one <key>.json per "
               f"diagnosis{reports}")
    if summary.failed:
        raise CommandFailed(f"{summary.failed} of {summary.total} diagnoses failed (messages in "
                            f"{args.out}/<key>.error.json); run the same command again to "
                            "retry them")
    return EXIT_OK

def _cmd_fit_batch(args: argparse.Namespace) -> int:
    from .batch import fit_batch
    from .diagnose.batch import SummaryScopeWarning, _the_recording

    _fit_method_rules(args)
    if args.nlive is not None and not args.compare:
        raise UsageError("argument --nlive: it sets the nested sampling of --compare; give "
                         "--compare too, or leave --nlive out")
    for flag, value in (("--likelihood", args.likelihood), ("--max-steps", args.max_steps)):
        if value is not None and not args.posterior:
            raise UsageError(f"argument {flag}: it sets the chain of --posterior; give "
                             f"--posterior too, or leave {flag} out")
    # (only those given: the batch fills in sample()'s defaults, bayespilot sample's, so that
    # a Python call's results resume the command's)
    sample_options = ({k: v for k, v in (("likelihood", args.likelihood),
                                         ("max_steps", args.max_steps)) if v is not None}
                      if args.posterior else None)
    _cluster_choice(args)
    paths = _recordings_in(args.recording)
    out = Path(args.out)
    keys = _batch_keys(paths, pool=False) or []  # (none: the batch refuses the input)
    _refuse_overwriting([("--out", f) for f in [*_batch_files(paths, out, pool=False,
                                                              reports=False, keys=keys,
                                                              formats=_formats(args)),
                                                out / "conditions.csv"]],
                        [f for p in paths for f in _recording_files(p)])
    how = (f"the paper's three-step procedure{', iterated' if args.iterate else ''}"
           if args.method == "paper" else
           f"the fast estimator{', prediction error' if args.noise == 'ar' else ''}")
    if args.posterior:
        _import_arviz()  # (the posteriors are written here: said before anything runs)
    extra = [*(["compared by nested sampling"] if args.compare else []),
             *([f"with the posterior sampled by emcee ({args.likelihood or 'eq4'} likelihood, "
                f"at most {args.max_steps or 20000} steps)"] if args.posterior else [])]
    _say(args, f"{len({_the_recording(p) for p in paths})} recording(s) to fit with and without "
               f"threshold ({how}){''.join(', ' + e for e in extra)}{',' if extra else ''} "
               f"on {_cluster_where(args)} -> {out}; each is read and checked before anything "
               f"runs")
    # (the fits' warnings, said once per kind at the end from their results, and the
    # cluster's: the command's lines; the recordings' as diagnose-batch says them)
    with _batch_errors(), _questionable_said(), \
            _warnings_of((RuntimeWarning, SummaryScopeWarning), _warning_line):
        summary = fit_batch(paths, out, method=args.method, noise=args.noise,
                            iterate=args.iterate, oversample=args.oversample,
                            compare=args.compare, nlive=args.nlive, seed=args.seed,
                            posterior=args.posterior, sample_options=sample_options,
                            scheduler=args.scheduler, workers=args.workers,
                            progress=_cluster_progress(args),
                            connect_timeout=args.connect_timeout, title=_title(args),
                            formats=_formats(args), dpi=args.dpi)
    _say(args, str(summary))
    try:
        table = (out / "conditions.csv").read_text(encoding="utf-8")
        runs = (out / "summary.csv").read_text(encoding="utf-8")
    except OSError as exc:
        raise CommandFailed(f"{out}: cannot read the summary the batch wrote "
                            f"({_os_reason(exc)})") from None
    print(table, end="")
    # (the tables cover every recording's fits in DIR made with these settings: say so when
    # an earlier run's are in them)
    earlier = _earlier_rows(runs, summary)
    scope = (f" (with {earlier} recording{'' if earlier == 1 else 's'} an earlier run fitted "
             f"in {out} with these settings)" if earlier > 0 else "")
    figures = [out / f"summary.{fmt}" for fmt in _formats(args)]  # (when any fit finished)
    posteriors = " and <key>.nc (its posterior)" if args.posterior else ""
    _say(args, f"wrote {out / 'conditions.csv'} (one row per subject, task and K_theta), "
               f"{out / 'summary.csv'} (one row per recording){scope}"
               f"{''.join(f', {f}' for f in figures if f.is_file())} and one "
               f"<key>.json{posteriors} per recording")
    if summary.failed:
        raise CommandFailed(f"{summary.failed} of {summary.total} recordings' fits failed "
                            f"(messages in {out}/<key>.error.json); run the same command "
                            f"again to retry them")
    unsampled = _unsampled(runs, keys) if args.posterior else 0
    if unsampled:
        raise CommandFailed(f"{unsampled} of {summary.total} recordings' posteriors could not "
                            f"be sampled (why: 'posterior_error' in {out}/<key>.json; their "
                            f"fits are kept); run the same command again to sample them again")
    return EXIT_OK


def _unsampled(summary_csv: str, keys: Sequence[str]) -> int:
    """How many rows of fit-batch's ``summary.csv`` (its text) of ``keys`` (this call's
    recordings) record a ``posterior_error``."""
    import csv

    mine = set(keys)
    return sum(1 for row in csv.DictReader(summary_csv.splitlines(keepends=True))
               if row.get("key") in mine and row.get("posterior_error"))


# --- the parser ------------------------------------------------------------------------
def _recording_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", metavar="REC",
                   help="the recording: its stem (out/run), its .csv or .json path, or a .mat file")


def _seed_argument(p: argparse.ArgumentParser, help: str) -> None:
    """``--seed S`` (an integer >= 0, default 0), as every stochastic command has it."""
    p.add_argument("--seed", type=_seed, default=0, metavar="S", help=help)


def _load_extensions(specs: Sequence[str], option: str = "--extension") -> list:
    """The catalogue entries named by --extension, each registered for this process.

    ``FILE.py:NAME`` runs the file as a module that is not put in ``sys.modules``, so that
    cloudpickle sends its build functions to a batch's workers by value (they cannot import
    a file they were never given); ``package.module:NAME`` imports the module, which the
    workers must then be able to import too.  NAME is an Extension or a list or tuple of
    them.  Any problem is bad input, said with the option (``option``) and its value.
    """
    import importlib
    import importlib.util

    from .diagnose import Extension, register_extension

    out: list = []
    for spec in specs:
        where, sep, name = spec.rpartition(":")
        bad = f"argument {option}: {spec}"
        if not sep or not where or not name.isidentifier():
            raise UsageError(f"{bad}: give FILE.py:NAME or package.module:NAME (NAME: the "
                             "Extension, or a list of them, defined there)")
        if where.endswith(".py") and not Path(where).is_file():
            raise UsageError(f"{bad}: no file {where}")
        try:
            if where.endswith(".py"):
                found = importlib.util.spec_from_file_location(
                    f"_bayespilot_extension_{len(out)}_{Path(where).stem}", where)
                module = importlib.util.module_from_spec(found)
                found.loader.exec_module(module)
            else:
                module = importlib.import_module(where)
        except Exception as exc:  # noqa: BLE001 - the user's code can raise anything
            raise UsageError(f"{bad}: {where} failed to load ({type(exc).__name__}: {exc})") \
                from None
        if not hasattr(module, name):
            raise UsageError(f"{bad}: {where} defines no {name!r}")
        obj = getattr(module, name)
        entries = [obj] if isinstance(obj, Extension) else obj
        if not isinstance(entries, (list, tuple)) or not entries or not all(
                isinstance(e, Extension) for e in entries):
            raise UsageError(f"{bad}: {name} is {type(obj).__name__}, not an Extension "
                             "(bayespilot.diagnose.Extension) or a list of them")
        for e in entries:
            try:
                register_extension(e)
            except (TypeError, ValueError) as exc:
                raise UsageError(f"{bad}: {exc}") from None
        out += entries
    return out


def _with_argument(p: argparse.ArgumentParser, simulated: bool = False) -> None:
    """--with: the paper's model extended by catalogue entries (simulate, fit, loglik, sample,
    compare; ``simulated``: simulate's, which takes control-saturation too)."""
    entries = ("motion-system-dynamics, motion-washout, otolith-channel, threshold-shape, "
               "time-varying-gains" + (", control-saturation" if simulated else ""))
    p.add_argument("--with", dest="extended_by", action="append", default=[], metavar="PHYSICS",
                   help=f"extend the paper's model by this catalogue entry of 'bayespilot "
                        f"diagnose' ({entries}), or by one of your own given as FILE.py:NAME or "
                        f"package.module:NAME; repeatable (applied in order)")


def _paper_model_with(args: argparse.Namespace, recording=None, *, threshold: bool = True,
                      fitted: bool = True, without_threshold: str | None = None):
    """The model of :func:`_paper_model_and_entries` (which see), without its entries."""
    return _paper_model_and_entries(args, recording, threshold=threshold, fitted=fitted,
                                    without_threshold=without_threshold)[0]


def _check_columns(entries: Sequence, recording) -> None:
    """Refuse, as bad input, a ``--with`` entry that ``recording`` lacks a column for."""
    for ext in entries:
        missing = [c for c in ext.needs if c not in recording]
        if missing:
            raise UsageError(f"argument --with: {ext.name} needs the recording column(s) "
                             f"{', '.join(missing)}, which {recording.source} lacks")


def _paper_model_and_entries(args: argparse.Namespace, recording=None, *,
                             threshold: bool = True, fitted: bool = True,
                             without_threshold: str | None = None) -> tuple:
    """The paper's model (``--oversample``), extended by each ``--with`` entry in turn (and,
    ``threshold`` False, then without threshold:
    :meth:`~bayespilot.model.PilotModel.without_threshold`, the model ``fit --no-threshold``
    fits), and the entries (for :func:`_check_columns` once the recording is read: a
    ``FILE.py:NAME`` is run once, by this call).

    Refused as bad input: an entry the recording lacks a column for; (``fitted``: a command
    that fits or evaluates the likelihood) one that only ``diagnose`` fits (its likelihood
    is not Eq. 4's); and, when the command takes only the model without threshold
    (``without_threshold``: how it says so, e.g. ``"--no-threshold"``), one that adds a
    threshold block that is not a dead zone (``threshold-shape``'s soft dead zone, whatever
    threshold it reads): the model without threshold removes that block
    (:meth:`~bayespilot.model.PilotModel.without_threshold`), which leaves the paper's model
    without threshold, the entry with nothing to do.  (``compare`` weighs the model with
    the entry against that one: not refused.)
    """
    from .compare import _null_differences
    from .model import paper_model

    model = paper_model(oversample=getattr(args, "oversample", 1))
    used: list = []
    for spec in args.extended_by:
        if ":" in spec:
            entries = _load_extensions([spec], "--with")
        else:
            from .diagnose import get_extension

            try:
                entries = [get_extension(spec)]
            except ValueError as exc:  # (an entry of one's own, in the command's words)
                raise UsageError("argument --with: " + str(exc).replace(
                    "register_extension", "FILE.py:NAME")) from None
        for ext in entries:
            if fitted and ext.likelihood != "gls":
                raise UsageError(f"argument --with: {ext.name} is fitted by the "
                                 f"{ext.likelihood} likelihood, which only 'bayespilot "
                                 f"diagnose' has")
            if recording is not None:
                _check_columns([ext], recording)
            try:
                model = ext.build(model)
            except (TypeError, ValueError, KeyError) as exc:
                raise UsageError(f"argument --with: {ext.name} cannot extend "
                                 f"{model.name!r} ({exc})") from None
            # (the model without threshold removes a threshold block that is not a dead
            # zone, without_threshold's own rule: with --no-threshold the entry's block
            # would do nothing)
            removed = (_null_differences(model, model.without_threshold())[0]
                       if without_threshold else [])
            if removed:
                raise UsageError(f"argument --with: {ext.name} with {without_threshold}: the "
                                 f"model without threshold removes its {removed[0]} (it is not "
                                 f"the identity at a threshold of 0), which leaves the model "
                                 f"without it; drop --with {ext.name}, or use it with a free "
                                 f"threshold (without --no-threshold)")
            used.append(ext)
    return (model if threshold else model.without_threshold()), used


def _diagnose_arguments(p: argparse.ArgumentParser, seed_help: str | None = None) -> None:
    """--seed, --bootstrap, --alpha, --calibrate and --noise-passes, as diagnose and
    diagnose-batch take them (``seed_help``: diagnose-batch's own --seed help)."""
    _seed_argument(p, seed_help or "seed of the base fit's starts and the bootstrap (default 0; "
                                   "run j of a pooled diagnosis uses S + j)")
    p.add_argument("--bootstrap", type=_whole_number(0), default=39, metavar="B",
                   help="bootstrap replicates for the located evidence (default 39; 0: none)")
    p.add_argument("--alpha", type=_fraction, default=0.01, metavar="A",
                   help="family-wise false-alarm level of the decision (default 0.01)")
    p.add_argument("--calibrate", type=_whole_number(0), default=0, metavar="B",
                   help="calibrate the chosen candidate's test by B replicates of a parametric "
                        "bootstrap of the base model before accepting it (default 0: the "
                        "asymptotic test alone; 39 is a sensible B, about 2 s each per run)")
    p.add_argument("--noise-passes", type=_whole_number(1), default=1, metavar="P",
                   help="estimate the decision's AR noise model P times (default 1: from the "
                        "Eq. 4 fit's residual; 2: again from the GLS base fit's, which "
                        "removes the washout test's small excess on correct-model runs; "
                        "at most 5)")
    p.add_argument("--extension", action="append", default=[], metavar="FILE.py:NAME",
                   help="a catalogue entry of your own (repeatable): NAME, a "
                        "bayespilot.diagnose.Extension or a list of them, in the Python file "
                        "FILE.py or in a module on PYTHONPATH (package.module:NAME); "
                        "registered and tested after the built-in entries")


def _fit_method_arguments(p: argparse.ArgumentParser) -> None:
    """--method, --noise and --iterate, as fit and fit-batch take them (the rules between them:
    :func:`_fit_method_rules`)."""
    p.add_argument("--method", choices=("paper", "fast"), default="paper",
                   help="'paper': the three-step procedure of Pool et al. (GA, Gauss-Newton, "
                        "scan; default); 'fast': multi-start least squares with a profile over "
                        "delta_abs")
    p.add_argument("--noise", choices=("white", "ar"), default="white",
                   help="'white': Eq. 4 as the paper has it (default); 'ar': a prediction-error "
                        "fit, the residual whitened by an AR model and the first 2 s left out "
                        "(a quarter of a record under 8 s; with --method fast; see "
                        "docs/fitting.md)")
    p.add_argument("--iterate", action="store_true",
                   help="repeat Steps II and III until delta_abs and -ln L stop changing "
                        "(with --method paper; the paper runs them once, which stops short on "
                        "remnant-free or low-remnant records, see docs/fitting.md)")


def _batch_seed_help(each: str, command: str) -> str:
    """--seed's help in diagnose-batch and fit-batch: ``each`` says how the tasks' seeds are
    drawn (``diagnose.batch.task_seed``), ``command`` repeats one task."""
    return (f"the batch's seed (default 0): {each}, recorded as settings.seed in <key>.json "
            f"and the seed column of summary.csv ('bayespilot {command} REC --seed' with it "
            f"and the same options repeats one); S is recorded as settings.batch_seed")


def _cluster_arguments(p: argparse.ArgumentParser) -> None:
    """--scheduler, --workers and --connect-timeout, as replicate and diagnose-batch take them."""
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", type=_scheduler_address, metavar="ADDRESS",
                       help="address of a running dask scheduler, [tcp://]HOST:PORT, e.g. "
                            "tcp://host:8786 (default: a local cluster)")
    where.add_argument("--scheduler-file", type=_output_path, metavar="FILE",
                       help="the JSON file a dask scheduler wrote its address to (dask "
                            "scheduler --scheduler-file FILE, dask-mpi, dask-jobqueue); "
                            "waited for up to --connect-timeout")
    p.add_argument("--workers", type=_count, metavar="N",
                   help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--connect-timeout", type=_positive, default=10.0, metavar="S",
                   help="seconds to wait for --scheduler and its first worker before giving up "
                        "with exit code 1 (default 10)")


def _likelihood_arguments(p: argparse.ArgumentParser, profiled: bool = False) -> None:
    """--likelihood, --ar, --ar-order and --oversample, as sample() and compare() take them (``profiled``:
    the command offers --ar profiled, which sample() has and the evidence has not)."""
    p.add_argument("--likelihood", choices=("eq4", "coloured"), default="eq4",
                   help="'eq4': white output error (the paper's Eq. 4, default; on "
                        "closed-loop recordings its intervals are several times too narrow "
                        "and its Bayes factors inflated); 'coloured': AR output error (a "
                        "prediction-error likelihood: the calibrated one, docs/posteriors.md "
                        "and docs/comparison.md)")
    if profiled:
        p.add_argument("--ar", choices=("profiled", "fixed", "sampled"), default="profiled",
                       help="'coloured' only: the AR model re-estimated at every parameter "
                            "vector (profiled, default: the calibrated one), estimated once "
                            "from a prediction-error fit and held (fixed), or sampled with "
                            "the pilot parameters")
    else:
        p.add_argument("--ar", choices=("fixed", "sampled"), default="fixed",
                       help="'coloured' only: the AR model estimated once from a "
                            "prediction-error fit and held (default), or sampled with the "
                            "pilot parameters")
    p.add_argument("--ar-order", type=_whole_number(0), default=None, metavar="P",
                   help="'coloured' only: order of the AR model (default: by BIC for --ar "
                        "fixed" + (" and profiled" if profiled else "") + ", 2 for --ar sampled)")
    _oversample_argument(p)


TOP_EPILOG = """\
Estimates pilot-model parameters and motion-perception thresholds from
manual-tracking recordings, after Pool et al. (2012), J. Guidance, Control,
and Dynamics 35(3), 749-763.

Examples:
  bayespilot demo
  bayespilot simulate --task FT --motion-gain 1 --remnant-fraction 0.2 --seed 3 -o out/run
  bayespilot loglik out/run --params params.json
  bayespilot fit out/run --json out/run-fit.json
  bayespilot fit out/run --iterate --json out/run-fit.json
  bayespilot sample out/run -o out/run-post.nc --json out/run-post.json
  bayespilot plot out/run-post.nc -o out/run-plots
  bayespilot compare out/run --json out/run-compare.json

A recording is two files with one stem, STEM.csv (signals) and STEM.json
(what the run was); see docs/recording-format.md.

Exit codes:
  0  success
  1  runtime failure (the simulated loop diverged, the model is unstable at
     the given parameters, an output file could not be written, the dask
     scheduler could not be reached)
  2  bad input or usage (a missing, unreadable or invalid recording or
     parameter file, a recording too short for the command, an unknown
     parameter name, an out-of-range value)
Errors are one line on stderr: 'bayespilot: error: <message>'.
"""

SIMULATE_EPILOG = """\
Simulates one run of the closed-loop tracking task (Fig. 2 of the paper) with
the multimodal pilot model (Fig. 4) and writes it as OUT.csv + OUT.json in the
recording format. The JSON sidecar also records the true parameters, K_n,
F_n, T_n, the seed and the simulation's settings (run-in, oversampling,
forcing scale) under the key "simulation". The same seed gives the same
files, bit for bit. A simulated recording at OUT is replaced; any other
recording there (a lab's) is refused unless --force.

--sample-rate sets the recording's rate (default 100 Hz, the paper's); the
loop is integrated at 1 kHz or finer whatever the rate, and the remnant gain
K_n means the same remnant at any rate.

Parameter file (--params): a JSON object with some of
K_v, T_vl, tau_v, K_m, tau_m, omega_nm, zeta_nm, delta_abs;
the others keep their Table 3 values for the task. Values must lie within the
bounds of Table 1. For example:
  {"K_m": 0.3, "delta_abs": 0.02}
A fit's JSON ('bayespilot fit --json') is taken too: its "params", all eight.

--with PHYSICS simulates the paper's model extended by a catalogue entry of
'bayespilot diagnose' (a concealed case to diagnose); --params must then give
the entry's new parameters, e.g. --with motion-washout and {"omega_w": 0.3}.

Examples:
  bayespilot simulate --task FT --motion-gain 1 --remnant-fraction 0.2 --seed 3 -o out/run
  bayespilot simulate --task FD --motion-gain 0.5 --params params.json --duration 40 -o out/short
  bayespilot simulate --task FD --remnant-fraction 0.2 --sample-rate 50 -o out/run50
  bayespilot simulate --task FD --params out/run-fit.json --seed 4 -o out/refit
  bayespilot simulate --task FT --remnant-fraction 0.15 --with motion-washout --params washout.json -o out/washout
"""

LOGLIK_EPILOG = """\
Prints -ln L of Eq. 4 (output error variance profiled out; lower is better),
with the pilot model driven by the recording's measured e and theta_ddot_m,
then the variance accounted for (VAF) on a second line unless --quiet.

Parameter file (--params): a JSON object with all of
K_v, T_vl, tau_v, K_m, tau_m, omega_nm, zeta_nm, delta_abs
(with --no-threshold, delta_abs may be left out; it is fixed at 0). E.g.
  {"K_v": 1.057, "T_vl": 0.409, "tau_v": 0.279, "K_m": 0.532, "tau_m": 0.203,
   "omega_nm": 12.0, "zeta_nm": 0.22, "delta_abs": 0.0075}
A fit's JSON ('bayespilot fit --json') is taken too: its "params" (with
--no-threshold its delta_abs is ignored; -v says so).

Examples:
  bayespilot loglik out/run --params params.json
  bayespilot loglik out/run.csv --params params.json --no-threshold --initial rest
  bayespilot loglik out/run --params out/run-fit.json
"""

FIT_EPILOG = """\
Estimates K_v, T_vl, tau_v, K_m, tau_m, omega_nm, zeta_nm and delta_abs by
maximum likelihood (Eq. 4) and prints a table with -ln L and the VAF. The
JSON (--json) has "params" (the 8 names), "neg_log_lik", "vaf", "method",
"seed", the settings, and the details of every step (GA repetitions with their
histories, Gauss-Newton refinements, the threshold scan).

In closed-loop tracking the remnant also drives e, which biases Eq. 4's
output-error fit; --method fast --noise ar makes a prediction-error fit
instead (the residual whitened by an AR model; its -ln L is on the whitened
residual and the AR model is in the JSON's settings).

Examples:
  bayespilot fit out/run --json out/run-fit.json
  bayespilot fit out/run --iterate --json out/run-fit.json
  bayespilot fit out/run --method fast --no-threshold --seed 2
  bayespilot fit out/run --method fast --noise ar --json out/run-pem.json
"""

DEMO_EPILOG = """\
Runs the main job on a built-in example, the worked example of the docs: simulates
a small study (one 81.92 s run of task FD per motion gain K_theta, 0.5 and 1
by default, remnant fraction 0.15, the Table 3 pilot of Pool et al. 2012),
writes the runs as recordings and reads them back, fits each by maximum
likelihood with and without threshold, samples the posterior with emcee,
compares the models with and without threshold by nested sampling, and writes
DIR/report.md with a table and figures (and the fits, posteriors and
comparisons beside it). All three use the coloured (prediction-error)
likelihood unless --likelihood eq4. A few minutes on a laptop; the first run
also compiles the numerical kernels.

--quick instead simulates one run (FD, K_theta = 1, F_n = 0.2) to
DIR/recording.csv + .json, prints -ln L at the paper's parameters with and
without threshold and the VAF, and plots the traces to DIR/traces.png, in
seconds. This check is fixed: it takes --out, --seed and the figures' options
only, and --task, --motion-gains, --duration, --max-steps, --nlive or
--likelihood with it is a usage error.

The figures are PNGs unless --format pdf or svg (vector, for a paper; --format
twice: both; report.md then shows the PNGs if written, else the SVGs, else links
the PDFs); --no-title draws them without their titles (the run, its draws and
likelihood, "not converged": the last is said on stderr).

Examples:
  bayespilot demo
  bayespilot demo --out /tmp/demo --seed 7 --motion-gains 0.25,0.5,0.75,1
  bayespilot demo --quick
  bayespilot demo --quick --format pdf --no-title
"""


REPLICATE_EPILOG = """\
Replicates the simulation study of Section III.B.2 (Figs. 14 and 15): for each
task, K_theta, remnant fraction F_n and realization, simulates a run with the
Table 3 parameters (remnant gain K_n from the paper's Table 4 by default, as
the paper did; --remnant fraction calibrates K_n to F_n on each realization
instead) and fits it with and without threshold (--fits). The fits run in
parallel on dask.distributed: a local cluster (--workers, default one per
core) or an existing one (--scheduler tcp://host:8786). Seeds follow from the
task, K_theta, F_n and realization number, so a rerun gives the same fits.

Each fit is written to DIR/<key>.json (e.g. FD_k1_fn0.2_r007_thr_paper_kn4.json)
as soon as it finishes. Running the same command again skips the fits already
in DIR, so an interrupted campaign resumes where it stopped; a fit that failed
is in DIR/<key>.error.json and is retried. At the end the command writes
DIR/summary.csv and DIR/summary.md (mu, sigma and N50 of delta_abs per cell
beside the paper's, with a binomial check) and DIR/delta_abs_histograms.png
(--format pdf or svg: .pdf or .svg, vector, for a paper; --format twice: both;
--no-title: without the figure's title, its key "differs from the paper" then
in the legend). The full study is 8000 fits (4000 with threshold, 4000 without).

Examples:
  bayespilot replicate --realizations 100 --out replication
  bayespilot replicate --realizations 5 --method fast --tasks FD --motion-gains 0.25,1 \\
      --remnant-fractions 0,0.2 --out quick --workers 2
  bayespilot replicate --realizations 100 --out replication --scheduler tcp://10.0.0.5:8786
  bayespilot replicate --realizations 8 --fits threshold --out iterated --fit-option iterate=true
  bayespilot replicate --realizations 100 --out replication --format pdf --no-title
"""

SAMPLE_EPILOG = """\
Samples the posterior of K_v, T_vl, tau_v, K_m, tau_m, omega_nm, zeta_nm and
delta_abs with emcee (priors uniform on the Table 1 bounds), starting from a
fast maximum-likelihood fit, until the chain is 50 autocorrelation times long
(or --max-steps), and writes it as ArviZ InferenceData to POST.nc (netCDF:
the draws, the sample statistics lp and acceptance, and the settings as
attributes; for a simulated recording also the true values). Prints mean,
median, 90% HDI, R-hat, ESS and the autocorrelation time of each parameter.
'eq4' treats the output error as white (the paper's Eq. 4). 'coloured'
models it as an AR process of an order chosen by BIC, with the first 2 s
(a quarter of a record under 8 s) left out: by default (--ar profiled) re-fitted by least squares at every
parameter vector, which widens the gains' intervals by what the noise model
shares with them in closed loop; with --ar fixed estimated once from a
prediction-error fit and held while the pilot parameters are sampled; with
--ar sampled its partial autocorrelations pacf_1..pacf_P are sampled too. In
closed-loop tracking the output error is the coloured remnant: see
docs/posteriors.md for how the likelihoods' intervals are calibrated.

The summary JSON (--json) has under "summary" one object per parameter name
with mean, median, hdi_90 ([low, high]), r_hat, ess_bulk, ess_tail and tau,
and whether the chain converged, its steps, the netCDF file, the seed, the
likelihood, max_steps, min_steps, the model and the recording.
A run that stops at --max-steps before converging warns and still writes.

Examples:
  bayespilot sample out/run -o out/run-post.nc --json out/run-post.json
  bayespilot sample out/run -o out/run-col.nc --likelihood coloured --max-steps 5000
  bayespilot sample out/run -o out/run-ar2.nc --likelihood coloured --ar sampled --ar-order 2
  bayespilot sample out/run -o out/run-prof.nc --likelihood coloured --ar profiled
"""

COMPARE_EPILOG = """\
Compares the pilot model with threshold (delta_abs uniform on [0, 0.1]) and
without (delta_abs = 0) on one recording: the log Bayes factor ln BF =
ln Z(threshold) - ln Z(none) from nested sampling (dynesty) with its standard
error, a Savage-Dickey cross-check from an emcee posterior (sampled here, or
given with --posterior; valid only where the posterior has draws near
delta_abs = 0), and AIC/BIC from the maximum-likelihood fits. The decision is
'threshold' if ln BF - 2 err > ln 10, 'none' if ln BF + 2 err < -ln 10, and
'inconclusive' otherwise (Jeffreys' "strong" evidence; see docs/comparison.md).

The JSON (--json) has log_bayes_factor, log_bayes_factor_err, decision,
jeffreys_category, savage_dickey_log_bayes_factor, savage_dickey_valid,
delta_aic, delta_bic (none - threshold: > 0 favours the threshold), both
evidences and the settings.

Examples:
  bayespilot compare out/run --json out/run-compare.json
  bayespilot compare out/run --posterior out/run-post.nc --seed 1
"""

PLOT_EPILOG = """\
Plots a posterior written by 'bayespilot sample' into DIR:
marginal_delta_abs.png (histogram with the 90 % HDI, the median and, for a
simulated recording, the true value), pair.png (K_m, tau_m, delta_abs) and
trace.png (every walker and the log posterior against the step). A posterior
of a model with a catalogue extension (written by 'bayespilot diagnose') also
gets marginal_NAME.png for each parameter the extension adds, and its axes
carry the extension's units. With --format pdf or svg the same names end in
.pdf or .svg (vector figures for a paper, fonts embedded as TrueType, SVG
text kept as text: --dpi then only sets the resolution of the pair plot's
point clouds); --format given twice writes both. --no-title leaves out the
figures' titles (the draws, the likelihood, "not converged"), for a paper
whose captions say it; a chain that has not converged is then said on stderr.

Examples:
  bayespilot plot out/run-post.nc -o out/run-plots
  bayespilot plot out/run-post.nc -o out/run-plots --format pdf --no-title
  bayespilot plot out/run-post.nc -o out/run-plots --format svg --format png --dpi 300
"""

DIAGNOSE_BATCH_EPILOG = """\
Runs 'bayespilot diagnose' on many recordings as independent tasks on a dask
cluster: a local one (--workers, default one per core) or an existing one
(--scheduler tcp://host:8786; the workers receive the recordings, no shared
folder needed). Every recording is read and checked first: a bad file is
reported with all others and nothing runs. Each diagnosis is written to
DIR/<key>.json as it finishes (key: the recording's stem, or
<subject>_<task>_k<K_theta> with --pool); one that fails leaves
DIR/<key>.error.json and the others go on; running the same command again
skips the finished ones and retries the failed (the same recordings: a stem,
its .csv or its .json, with the same sidecar values; the same settings,
defaults filled in); a <key>.json
made from other recordings or settings is refused (exit 2), and so is a DIR
that holds fit-batch's results (or a summary.csv diagnose-batch did not
write): use another --out. With --pool, one
recording under two names (a copy) in a condition is refused before anything
runs. --reports writes the reports of the diagnoses a run makes: one
finished before without a report is not redone and gets none (a warning
names it; delete its <key>.json to redo it with its report).
DIR/summary.csv has one row per diagnosis in DIR made with these settings,
sorted by key: this run's, and those an earlier run on other recordings left
in DIR (a warning names any made with other settings, left out): the
decision (physics, mismatch), the chosen extension's p_value,
delta_neg_log_lik and params, the candidate with the smallest p-value, or
the error; DIR/summary.png draws every candidate's p-value in every
diagnosis, one named row each (past about 50 diagnoses the figure grows
beyond a page, up to 60 in). For a paper: --format pdf or svg writes
DIR/summary.pdf or .svg instead (twice: both) and each report's figures in
that format beside their PNGs, which the report's page embeds; --no-title
draws the summary and the reports' figures without their titles.
--extension FILE.py:NAME adds a lab's own catalogue entries, sent
to the workers whole (one from package.module:NAME must be importable on
them). About 21 s per recording of 81.92 s on one core (with --bootstrap
39), see docs/performance.md.

Examples:
  bayespilot diagnose-batch recordings/ --out diagnoses
  bayespilot diagnose-batch recordings/ --out pooled --pool --reports
  bayespilot diagnose-batch recordings/ --out paper --reports --format pdf --no-title
  bayespilot diagnose-batch recordings/ --out pooled-post --pool --posterior
  bayespilot diagnose-batch recordings/ --out diagnoses --scheduler tcp://10.0.0.5:8786
"""

FIT_BATCH_EPILOG = """\
Fits the pilot model with threshold and without (delta_abs fixed at 0) to
many recordings, as independent tasks on a dask cluster: a local one
(--workers, default one per core) or an existing one (--scheduler
tcp://host:8786; the workers receive the recordings, no shared folder
needed). Every recording is read and checked first: a bad file is reported
with all others and nothing runs. Both fits of a recording use one seed,
drawn from --seed and the recording's content. Each recording's result is
written to DIR/<key>.json as it finishes (key: the recording's stem, or
<parent>_<stem> where two stems clash): both fits, their information
criteria and, with --compare, the comparison; one that fails leaves
DIR/<key>.error.json and the others go on (exit 1 at the end); running the
same command again skips the finished ones and retries the failed; a
<key>.json made from another recording or with other settings is refused
(exit 2), and so is a DIR that holds diagnose-batch's results (or a
summary.csv fit-batch did not write): use another --out. --noise ar goes
with --method fast and --iterate with --method paper, as in 'bayespilot fit'.

DIR/summary.csv has one row per recording fitted in DIR with these
settings, sorted by key: its key, subject, task and K_theta, the parameters
with threshold, -ln L of both fits, the VAF, delta_bic (BIC without
threshold minus BIC with: > 0 favours the threshold), with --compare ln BF,
its error and decision, the seed and any error. Every column is always
there: one not computed (no --compare, no --posterior) is empty, as is a
value that is missing, NaN or infinite. DIR/conditions.csv, printed
at the end, has one row per subject, task and K_theta: the number of runs,
delta_abs's median, min and max over them, the summed differences of -ln L
and BIC, and with --compare the pooled ln BF, its error and decision.
DIR/summary.png draws every run's delta_abs per condition. One fit of an
81.92-s run takes about 2 s (--method fast) or 1.3 s (--method paper; 4 s on
a CPU without AVX2 or AVX-512), two per recording; --compare adds minutes per recording.

--posterior also samples each recording's posterior after its fits, as
'bayespilot sample REC --seed S' samples it (the same --likelihood and
--max-steps, with their defaults, and --oversample), S the seed its result
records, so that command repeats the chain: 5 to 10 s for an 81.92-s run
(eq4), two to three times that with --likelihood coloured. DIR/<key>.nc holds the draws
(netCDF, for 'bayespilot plot' or arviz), <key>.json the summary that
'bayespilot sample --json' writes under 'posterior', and summary.csv
delta_abs's posterior median and 90 % HDI (delta_abs_posterior_median,
delta_abs_posterior_hdi_low, delta_abs_posterior_hdi_high; conditions.csv's
delta_abs_median is the median of the runs' estimates) and whether the
chain converged;
summary.png draws the interval as an error bar. A sampling that fails is
said and recorded (posterior_error), the fits are kept and the command exits
with 1; run it again to sample those recordings again. --format pdf (or svg)
and --no-title draw the summary figure for a paper.

Examples:
  bayespilot fit-batch recordings/ --out fits
  bayespilot fit-batch recordings/ --out fits-pem --method fast --noise ar
  bayespilot fit-batch recordings/ --out compared --method fast --compare --nlive 200
  bayespilot fit-batch recordings/ --out posteriors --method fast --posterior
  bayespilot fit-batch recordings/ --out fits --scheduler tcp://10.0.0.5:8786
"""

DIAGNOSE_EPILOG = """\
Locates where a recording and the fitted pilot model differ, names the physics
the model leaves out, fits it, and shows the fit improve. Steps: the fast
fit of the paper's model; located evidence (frequency, time, amplitude) with
p-values from a parametric bootstrap (--bootstrap replicates of the fitted
model with its own remnant); every catalogue extension (motion-system-dynamics,
motion-washout, otolith-channel, threshold-shape, time-varying-gains,
control-saturation) fitted and tested by a likelihood-ratio test on a
pre-whitened (GLS) likelihood, or by its flat tops and the censored likelihood
for control-saturation. The answer is 'none' when no extension passes the
family-wise level --alpha. With --calibrate B the chosen candidate's test is
first calibrated by a parametric bootstrap of the base model (B replicates,
each the closed loop simulated with the run's own remnant and the diagnosis
retraced for that candidate); a candidate whose calibrated p-value fails gives
way to the next. Reads only the recording. Under a minute at N = 8192; a
calibration adds about 2 s per replicate and run (see docs/diagnose.md and
docs/performance.md).

The JSON (--json) has mismatch, physics (a catalogue name or 'none'), ranking
(physics, delta_neg_log_lik, p_value, delta_bic, params, stderr per
candidate), where (each located statistic with its bootstrap p-value), base,
chosen and the settings. --report DIR writes residuals.png, candidates.png,
frequency_response.png (on whole forcing periods), evidence.png (with
bootstrap p-values), diagnosis.json and report.html (self-contained, figures
embedded). --posterior POST.nc also samples the posterior of the chosen
extended model (emcee, started at its fit; tens of seconds), writes it as
netCDF (readable by 'bayespilot plot') and adds its medians and 90 %
intervals to the summary and JSON and posterior.png to the report.
--bayes-factor also weighs the chosen extension (on 'none': the
top-ranked candidate) against the base model by nested sampling: ln BF with
priors uniform on the bounds, three runs per model, several minutes at
N = 8192; beside the decision, which stays the likelihood-ratio test's.
For a paper, --report-format pdf (or svg) also writes each figure as a vector
file beside its PNG, and --no-title draws the report's figures without their
titles (a panel's note, such as a posterior's draws and "not converged", then
in its legend).

Several recordings (runs of one condition) are diagnosed together: each run
keeps its own pilot parameters, the extension's parameters are shared, and
the test adds the runs' likelihoods, so a small omission that one run cannot
tell from remnant can be found in four. The JSON then also has runs (each
run's base fit, evidence and share of each candidate's improvement); the
report writes candidates.png, runs.png, diagnosis.json and report.html.

A lab's own catalogue entries (an Extension, see docs/diagnose.md, "Your own
catalogue entry") are tested after the built-in ones with --extension
FILE.py:NAME, repeatable; diagnose-batch sends them to its workers.

Examples:
  bayespilot diagnose out/run --json out/run-diagnosis.json
  bayespilot diagnose out/run --report out/run-diagnosis --seed 1
  bayespilot diagnose out/run --extension mylab_entries.py:VISUAL_LAG
  bayespilot diagnose out/run --report out/run-diagnosis --posterior out/run-ext.nc
  bayespilot diagnose out/run1 out/run2 out/run3 out/run4 --report out/pooled
  bayespilot diagnose out/run --report out/paper --report-format pdf --no-title
"""

def _common(parser: argparse.ArgumentParser, *, sub: bool) -> None:
    """-q/-v, on the top-level parser and (so they work after the command) on each subcommand."""
    parser.add_argument("-q", "--quiet", action="store_true",
                        default=argparse.SUPPRESS if sub else False,
                        help="print only the results (no progress bars or lines, summaries or "
                             "VAF line)")
    parser.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS if sub else 0,
                        help="print details (parameters, model, recording) to stderr, and the "
                             "traceback of an unexpected error")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``bayespilot`` command."""
    fmt = argparse.RawDescriptionHelpFormatter
    parser = _Parser(prog=PROG, formatter_class=fmt, epilog=TOP_EPILOG,
                     description="bayespilot: pilot-model parameters and motion-perception "
                                 "thresholds from manual-tracking recordings.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    _common(parser, sub=False)
    subs = parser.add_subparsers(dest="command", metavar="COMMAND", required=True,
                                 parser_class=_Parser)

    p = subs.add_parser("simulate", formatter_class=fmt, epilog=SIMULATE_EPILOG,
                        help="simulate a tracking run and write it as a recording",
                        description="Simulate one tracking run with the paper's pilot model.")
    p.add_argument("-o", "--output", type=_output_path, required=True, metavar="OUT",
                   help="output stem (or .csv path): writes OUT.csv and OUT.json, creating "
                        "missing directories")
    p.add_argument("--task", choices=("FD", "FT"), default="FD",
                   help="FD: mainly disturbance rejection; FT: mainly target following "
                        "(sets the forcing scaling and the Table 3 parameters; default FD)")
    p.add_argument("--motion-gain", type=_nonnegative, default=1.0, metavar="K",
                   help="motion cueing gain K_theta >= 0 (0: no motion; default 1)")
    rem = p.add_mutually_exclusive_group()
    rem.add_argument("--remnant-fraction", type=_fraction, default=0.0, metavar="F",
                     help="remnant fraction F_n = var(n)/var(u) in [0, 1), Eq. 7; K_n is "
                          "calibrated to reach it on this run (default 0: no remnant)")
    rem.add_argument("--remnant-gain", type=_nonnegative, default=None, metavar="K",
                     help="remnant gain K_n >= 0 of Eq. 6, instead of --remnant-fraction")
    _seed_argument(p, "seed of the remnant noise, an integer >= 0 (default 0)")
    p.add_argument("--duration", type=_positive, default=None, metavar="S",
                   help="measurement time in seconds (default 81.92, the paper's T0)")
    p.add_argument("--sample-rate", type=_positive, default=100.0, metavar="HZ",
                   help="sample rate of the recording in Hz (default 100, the paper's; e.g. 50 "
                        "or 120 as other labs record); above twice the forcing's highest "
                        "line, 2.6 Hz")
    p.add_argument("--params", metavar="FILE.json",
                   help="JSON object overriding some Table 3 parameters by name, or a fit's "
                        "JSON ('bayespilot fit --json': its params) (see below)")
    p.add_argument("--subject", type=_subject_name, default=None, metavar="S",
                   help="the sidecar's subject (what 'diagnose-batch --pool' groups runs by; "
                        "default: none)")
    p.add_argument("--force", action="store_true",
                   help="replace a recording at OUT that 'bayespilot simulate' did not write "
                        "(refused without it; a simulated one is always replaced)")
    _with_argument(p, simulated=True)
    _common(p, sub=True)
    p.set_defaults(handler=_cmd_simulate)

    p = subs.add_parser("loglik", formatter_class=fmt, epilog=LOGLIK_EPILOG,
                        help="print -ln L (Eq. 4) of a recording at given parameters",
                        description="Evaluate the negative log-likelihood of Eq. 4.")
    _recording_argument(p)
    p.add_argument("--params", required=True, metavar="FILE.json",
                   help="JSON object with the pilot parameters by name, or a fit's JSON "
                        "('bayespilot fit --json': its params) (see below)")
    p.add_argument("--no-threshold", action="store_true",
                   help="use the model without threshold (delta_abs fixed at 0)")
    p.add_argument("--initial", choices=("periodic", "rest"), default="periodic",
                   help="model start-up: 'periodic' treats the record as periodic (filters in "
                        "steady state), 'rest' starts from zero state (default periodic)")
    _oversample_argument(p)
    _with_argument(p)
    _common(p, sub=True)
    p.set_defaults(handler=_cmd_loglik)

    p = subs.add_parser("fit", formatter_class=fmt, epilog=FIT_EPILOG,
                        help="maximum-likelihood fit of the pilot model to a recording",
                        description="Fit the multimodal pilot model (with or without threshold).")
    _recording_argument(p)
    p.add_argument("--no-threshold", action="store_true",
                   help="fit the model without threshold (delta_abs fixed at 0)")
    _fit_method_arguments(p)
    _seed_argument(p, "seed of the genetic algorithm / starting points (default 0)")
    p.add_argument("--json", type=_output_path, metavar="OUT",
                   help="write the result (params, neg_log_lik, vaf, method, seed and every "
                        "step) to this JSON file")
    _oversample_argument(p)
    _with_argument(p)
    _common(p, sub=True)
    p.set_defaults(handler=_cmd_fit)

    p = subs.add_parser("demo", formatter_class=fmt, epilog=DEMO_EPILOG,
                        help="simulate, evaluate and plot a built-in example",
                        description="The main job of bayespilot on a built-in example.")
    p.add_argument("--out", default="bayespilot-demo", type=_output_path, metavar="DIR",
                   help="output directory (default bayespilot-demo/)")
    _seed_argument(p, "seed of the remnant noise, fits and samplers, an integer >= 0 "
                   "(default 0)")
    p.add_argument("--quick", action="store_true",
                   help="instead, the fixed seconds-long check: one simulated run (FD, "
                        "K_theta = 1, F_n = 0.2), -ln L at the paper's parameters and a plot; "
                        "takes only --out, --seed, --format, --dpi and --no-title (--task, "
                        "--motion-gains, --duration, --max-steps, --nlive and --likelihood are "
                        "refused with it)")
    # defaults None: the full demo's (run_example's) apply, and one given with --quick is seen
    p.add_argument("--task", type=_task_name, default=None, help="FD or FT (default FD)")
    p.add_argument("--motion-gains", type=_csv_of(_positive, "numbers > 0"), default=None,
                   metavar="K,K", help="K_theta of the runs, one run each (default 0.5,1)")
    p.add_argument("--duration", type=_positive, default=None, metavar="S",
                   help="measurement time of each run, s (default 81.92)")
    p.add_argument("--max-steps", type=_count, default=None, metavar="N",
                   help="cap on the emcee chain length per run (default 6000)")
    p.add_argument("--nlive", type=_count, default=None, metavar="N",
                   help="live points of the nested sampler (default 150)")
    p.add_argument("--likelihood", choices=("coloured", "eq4"), default=None,
                   help="'coloured': the prediction-error likelihood (default); 'eq4': the "
                        "paper's Eq. 4, for the fits, posteriors and comparisons")
    _figure_arguments(p, dpi_help="; pdf and svg use it only for the pair plot's rasterized "
                                  "point clouds")
    _no_title_argument(p, "the figures")
    _common(p, sub=True)
    p.set_defaults(handler=_cmd_demo)

    p = subs.add_parser("replicate", formatter_class=fmt, epilog=REPLICATE_EPILOG,
                        help="replicate the simulation study (Figs. 14/15) on a dask cluster",
                        description="Run the Monte Carlo study of Section III.B.2 as a "
                                    "resumable campaign of fits.")
    p.add_argument("--realizations", type=_count, default=100, metavar="N",
                   help="remnant realizations per cell (default 100, as in the paper)")
    p.add_argument("--first-realization", type=_whole_number(0), default=0, metavar="K",
                   help="number the realizations from K (default 0): each number seeds its "
                        "remnant and fit, so '--first-realization 100' is an independent "
                        "repeat of the study (same folder or another)")
    p.add_argument("--out", type=_output_path, required=True, metavar="DIR",
                   help="folder for one JSON per fit and the summary (created if missing; "
                        "fits already in it are not redone)")
    _cluster_arguments(p)
    p.add_argument("--method", choices=("paper", "fast"), default="paper",
                   help="'paper': the three-step procedure (default); 'fast': multi-start "
                        "least squares with a profile over delta_abs")
    p.add_argument("--tasks", type=_csv_of(_task_name, "tasks (FD, FT)"), default=("FD", "FT"),
                   metavar="LIST", help="comma-separated tasks (default FD,FT)")
    p.add_argument("--motion-gains", type=_csv_of(_nonnegative, "numbers >= 0"),
                   default=(0.25, 0.5, 0.75, 1.0), metavar="LIST",
                   help="comma-separated K_theta values (default 0.25,0.5,0.75,1)")
    p.add_argument("--remnant-fractions", type=_csv_of(_fraction, "numbers in [0, 1)"),
                   default=(0.0, 0.1, 0.2, 0.25, 0.3), metavar="LIST",
                   help="comma-separated F_n values (default 0,0.1,0.2,0.25,0.3)")
    p.add_argument("--remnant", choices=("table4", "fraction"), default="table4",
                   help="'table4': the remnant gain K_n of the paper's Table 4 for the cell, "
                        "the same for every realization (default, as the paper did); "
                        "'fraction': K_n calibrated so that each realization reaches F_n")
    p.add_argument("--fits", choices=tuple(_FITS), default="both",
                   help="fit each run with and without threshold ('both', default), "
                        "or only one of the two")
    p.add_argument("--duration", type=_positive, default=None, metavar="S",
                   help="measurement time of each simulated run in seconds (default 81.92; "
                        "shorter for a quick check)")
    p.add_argument("--fit-option", type=_fit_option, action="append", default=[],
                   metavar="NAME=VALUE",
                   help="an option of the fit (repeatable), e.g. repetitions=5, "
                        "iterate=true or population=80 for the paper method, n_starts=4 for "
                        "the fast one; VALUE is a JSON value (true/false, True/False: a "
                        "boolean; iterate takes only these); what the options above set "
                        "(threshold: --fits, duration, remnant, ...) is refused here")
    p.add_argument("--hist-upper", type=_hist_upper, default=0.1, metavar="X|auto",
                   help="right end of the histograms' delta_abs axis in IPUT (default 0.1, "
                        "the Table 1 bound and the axis of the paper's Figs. 14/15); 'auto': "
                        "just above nearly all estimates, to show the shape of tight "
                        "distributions (fits beyond the end are counted in the last bin)")
    _figure_arguments(p)
    _no_title_argument(p, "the histograms", note=" (its key, 'differs from the paper', "
                                                 "then in the legend)")
    _common(p, sub=True)
    p.set_defaults(handler=_cmd_replicate)

    p = subs.add_parser("sample", formatter_class=fmt, epilog=SAMPLE_EPILOG,
                        help="sample the posterior of the pilot parameters (emcee)",
                        description="Posterior of the pilot-model parameters with emcee.")
    _recording_argument(p)
    p.add_argument("-o", "--output", type=_output_path, required=True, metavar="POST.nc",
                   help="the posterior as a netCDF file (ArviZ InferenceData)")
    _likelihood_arguments(p, profiled=True)
    _with_argument(p)
    p.add_argument("--json", type=_output_path, metavar="SUMMARY",
                   help="write the per-parameter summary to this JSON file")
    _seed_argument(p, "seed of the initial fit and the sampler (default 0)")
    p.add_argument("--max-steps", type=_count, default=20000, metavar="N",
                   help="stop after N steps even if not converged (default 20000)")
    p.add_argument("--backend", type=_output_path, metavar="FILE.h5",
                   help="emcee HDF5 file: a run interrupted or stopped at --max-steps resumes "
                        "from it")
    _common(p, sub=True)
    p.set_defaults(handler=_cmd_sample)

    p = subs.add_parser("compare", formatter_class=fmt, epilog=COMPARE_EPILOG,
                        help="Bayes factor of the model with threshold against the one without",
                        description="Model comparison: with against without threshold.")
    _recording_argument(p)
    p.add_argument("--json", metavar="OUT", type=_output_path,
                   help="write the result to this JSON file")
    _seed_argument(p, "seed of the nested sampler and the sampler (default 0)")
    _likelihood_arguments(p)
    _with_argument(p)
    p.add_argument("--nlive", type=_whole_number(20), default=200, metavar="N",
                   help="live points of each nested-sampling run (default 200)")
    p.add_argument("--posterior", metavar="POST.nc",
                   help="posterior from 'bayespilot sample' for the Savage-Dickey check "
                        "(default: sample one)")
    p.add_argument("--no-savage-dickey", action="store_true",
                   help="skip the Savage-Dickey check (no emcee run)")
    _common(p, sub=True)
    p.set_defaults(handler=_cmd_compare)

    p = subs.add_parser("plot", formatter_class=fmt, epilog=PLOT_EPILOG,
                        help="plot a posterior: marginal of delta_abs, pair plot, traces",
                        description="Plots of a posterior written by 'bayespilot sample'.")
    p.add_argument("posterior", metavar="POST.nc", help="netCDF file from 'bayespilot sample'")
    p.add_argument("-o", "--output", type=_output_path, required=True, metavar="DIR",
                   help="folder for the figures (created if missing)")
    _figure_arguments(p, dpi_help="; pdf and svg use it only for the pair plot's rasterized "
                                  "point clouds")
    _no_title_argument(p, "the figures")
    _common(p, sub=True)
    p.set_defaults(handler=_cmd_plot)

    p = subs.add_parser("diagnose", formatter_class=fmt, epilog=DIAGNOSE_EPILOG,
                        help="locate a model mismatch, name the missing physics, fit it",
                        description="Diagnose model mismatch on one recording, or on several "
                                    "runs of one condition together.")
    p.add_argument("recording", metavar="REC", nargs="+",
                   help="the recording: its stem (out/run), its .csv or .json path, or a .mat "
                        "file; several runs of one condition are diagnosed together (pooled)")
    p.add_argument("--json", metavar="OUT", type=_output_path,
                   help="write the diagnosis to this JSON file")
    p.add_argument("--report", type=_output_path, metavar="DIR",
                   help="write PNG figures, report.html and diagnosis.json to this folder")
    p.add_argument("--report-format", action="append", choices=("pdf", "svg"), default=[],
                   metavar="{pdf,svg}",
                   help="with --report, also write each figure in this vector format beside "
                        "its PNG, for a paper (fonts as TrueType; may be given twice)")
    p.add_argument("--no-title", action="store_true",
                   help="with --report, draw its figures without their titles, for a paper "
                        "whose captions say what they said (a panel's note, such as a "
                        "posterior's 'not converged', moves into its legend; the page's "
                        "headings and captions stay)")
    _diagnose_arguments(p)
    p.add_argument("--posterior", type=_output_path, metavar="POST.nc",
                   help="one recording: also sample the posterior of the chosen extended model "
                        "(emcee, coloured likelihood) and write it to this netCDF file; "
                        "several (POST.json): the posterior of the extension's shared "
                        "parameters on a grid, as JSON; the summary, JSON and report then "
                        "include it")
    p.add_argument("--bayes-factor", action="store_true",
                   help="one recording: also weigh the chosen extension (on 'none': the "
                        "top-ranked candidate) against the base model by nested sampling "
                        "(ln BF, minutes); the summary, JSON and report then include it")
    _common(p, sub=True)
    p.set_defaults(handler=_cmd_diagnose)

    p = subs.add_parser("diagnose-batch", formatter_class=fmt, epilog=DIAGNOSE_BATCH_EPILOG,
                        help="diagnose many recordings on a dask cluster",
                        description="Diagnose every recording alone, or the runs of each "
                                    "subject and condition pooled, as a resumable batch.")
    p.add_argument("recording", metavar="REC", nargs="+",
                   help="recordings (stems, .csv, .json or .mat paths) or folders of them")
    p.add_argument("--out", type=_output_path, required=True, metavar="DIR",
                   help="folder for one <key>.json per diagnosis and summary.csv (created if "
                        "missing; diagnoses already in it are not redone)")
    p.add_argument("--pool", action="store_true",
                   help="diagnose the runs of each subject, task and motion gain together "
                        "(each recording must give 'subject' in its JSON)")
    p.add_argument("--reports", action="store_true",
                   help="also write each diagnosis's report (PNG figures, report.html) to "
                        "DIR/<key>/")
    p.add_argument("--posterior", action="store_true",
                   help="where an extension is chosen, also its posterior (one run: emcee, "
                        "minutes; pooled: the shared parameters on a grid, seconds), in each "
                        "<key>.json and summary.csv")
    _figure_arguments(p, format_help="; with --reports also each report's figures in it, "
                                     "beside the PNGs its page embeds",
                      dpi_help=" (the summary's figure; a report's PNGs, which its page "
                               "embeds, stay at the default)")
    _no_title_argument(p, "the summary's figure and the reports' figures",
                       note=" (the summary's key, its dot, box and grey, then belongs in "
                            "the caption)")
    _diagnose_arguments(p, seed_help=_batch_seed_help(
        "each diagnosis runs with its own seed drawn from S and its recordings' content (not "
        "from their paths, order or the other recordings; run j of a pooled one, in the order "
        "of the runs' content, uses its seed + j)", "diagnose"))
    _cluster_arguments(p)
    _common(p, sub=True)
    p.set_defaults(handler=_cmd_diagnose_batch)

    p = subs.add_parser("fit-batch", formatter_class=fmt, epilog=FIT_BATCH_EPILOG,
                        help="fit many recordings with and without threshold on a dask cluster",
                        description="Fit every recording with and without threshold, weigh "
                                    "the threshold per recording and per subject and "
                                    "condition, as a resumable batch.")
    p.add_argument("recording", metavar="REC", nargs="+",
                   help="recordings (stems, .csv, .json or .mat paths) or folders of them")
    p.add_argument("--out", type=_output_path, required=True, metavar="DIR",
                   help="folder for one <key>.json per recording, summary.csv, conditions.csv "
                        "and summary.png (created if missing; recordings fitted in it "
                        "already are not redone)")
    _fit_method_arguments(p)
    _oversample_argument(p)
    p.add_argument("--compare", action="store_true",
                   help="also the log Bayes factor of the threshold for each recording "
                        "(nested sampling, as 'bayespilot compare' weighs one: minutes each) "
                        "and pooled per subject and condition")
    p.add_argument("--nlive", type=_whole_number(20), default=None, metavar="N",
                   help="with --compare: live points of each nested-sampling run (default "
                        "200, compare's)")
    p.add_argument("--posterior", action="store_true",
                   help="also sample each recording's posterior (emcee, as 'bayespilot sample' "
                        "samples one, with the recording's seed: seconds to a minute each), "
                        "written as DIR/<key>.nc, its summary in <key>.json and delta_abs's "
                        "median and 90%% HDI in summary.csv")
    p.add_argument("--likelihood", choices=("eq4", "coloured"), default=None,
                   help="with --posterior: 'eq4': white output error (the paper's Eq. 4, "
                        "default; its intervals several times too narrow on closed-loop "
                        "recordings); 'coloured': AR output error (a prediction-error "
                        "likelihood, its AR model profiled: the calibrated one), as "
                        "'bayespilot sample' takes it")
    p.add_argument("--max-steps", type=_count, default=None, metavar="N",
                   help="with --posterior: stop each chain after N steps even if not "
                        "converged (default 20000, as 'bayespilot sample')")
    _figure_arguments(p, dpi_help=" (the summary's figure)")
    _no_title_argument(p, "the summary's figure", note=" (how many runs in how many "
                       "conditions)")
    _seed_argument(p, _batch_seed_help(
        "each recording's fits run with its own seed drawn from S and its content (not from "
        "its path, order or the other recordings)", "fit"))
    _cluster_arguments(p)
    _common(p, sub=True)
    p.set_defaults(handler=_cmd_fit_batch)
    return parser


class _GuardedStdout:
    """``sys.stdout`` while a command runs: a write or flush that fails (the reader of a
    pipe went away, ``| head``; a full disk, ``> /dev/full``) is kept in :attr:`error` and
    the rest of the output is dropped, instead of raising out of a ``print``.

    A command prints its summary before it writes its files, so that a file that cannot be
    written still leaves the result on the screen (``_cmd_sample``); a stdout that fails
    must then not cost the files either: the print carries on, the files are written, and
    :func:`main` says what became of stdout and sets the exit code.  Everything else is the
    wrapped stream's.
    """

    def __init__(self, stream) -> None:
        self.stream = stream
        self.error: OSError | None = None

    def write(self, text: str) -> int:
        if self.error is None:
            try:
                return self.stream.write(text)
            except OSError as exc:
                self.error = exc
        return len(text)

    def flush(self) -> None:
        if self.error is None:
            try:
                self.stream.flush()
            except OSError as exc:
                self.error = exc

    def __getattr__(self, name: str):
        return getattr(self.stream, name)


def _stdout_to_devnull(stream) -> None:
    """Point ``stream``'s file descriptor at the null device, so that the interpreter's
    flush at exit of what it still holds does not fail again (the Python docs' advice for
    SIGPIPE); a stream without one (a test's capture) is left alone."""
    try:
        fd = stream.fileno()
    except (AttributeError, OSError, ValueError):
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, fd)
    finally:
        if null != fd:
            os.close(null)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``bayespilot`` command with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    Parameters
    ----------
    argv : sequence of str, optional
        The command-line arguments after the program name, e.g.
        ``["simulate", "-o", "run1"]``; None reads ``sys.argv[1:]``.

    Returns
    -------
    int
        The exit code: what the subcommand returns on success
        (:data:`EXIT_OK`, 0); :data:`EXIT_USAGE` (2) for bad input or usage,
        including ``-q`` given with ``-v``; :data:`EXIT_FAILURE` (1) when the
        computation or writing the output fails, or for an unexpected error
        (one line on stderr; the traceback too with ``-v``), and when standard
        output cannot be written (a full disk: ``cannot write to standard
        output``); 130 on KeyboardInterrupt, also one that reaches the command
        as another exception (numba's SystemError); 0 after ``--help`` and
        ``--version``.

    Notes
    -----
    Nothing is raised to the caller: every refusal or failure is one line
    ``bayespilot: error: <message>`` on stderr and an exit code, and
    argparse's SystemExit is turned into its exit code.  A standard output
    that goes away (``| head``) or fails stops only the printing: the
    command still writes its files, and the exit code is theirs (0 after a
    closed pipe).  A standard output with the strict error handler (an
    ASCII or latin-1 one) replaces what it cannot encode by backslash
    escapes while the command runs, as standard error does, and gets its
    handler back at the end; any other handler is kept (the C locale's
    ``surrogateescape`` writes a path's undecodable bytes back as given).
    With standard error closed (``2>&-``) its messages are dropped, not
    mixed into the results.
    """
    stdout, stderr = sys.stdout, sys.stderr
    if stderr is None:  # (2>&-: print(file=None) wrote the messages into stdout's results)
        sys.stderr = open(os.devnull, "w", encoding="utf-8")
    guard = None
    errors = None  # stdout's own error handler, put back at the end, when it was changed
    if stdout is not None:
        # (a non-ASCII path on an ASCII or latin-1 stdout: '\xfc' printed, not a crash after
        # the computation; stderr has this handler already.  Only a strict one is replaced:
        # the C locale's surrogateescape writes a path's undecodable bytes back as they
        # came, which a terminal shows as the name, where a backslash escape would not)
        if getattr(stdout, "errors", None) == "strict":
            with contextlib.suppress(AttributeError, ValueError, OSError):
                stdout.reconfigure(errors="backslashreplace")
                errors = "strict"
        guard = sys.stdout = _GuardedStdout(stdout)
    try:
        code = _main(argv)
        if guard is None:
            return code
        guard.flush()  # (here, not at the interpreter's exit: "Exception ignored", exit 120)
        if guard.error is None:
            return code
        _stdout_to_devnull(stdout)
        if isinstance(guard.error, BrokenPipeError):  # the reader went away: not an error
            return code
        print(f"{PROG}: error: cannot write to standard output "
              f"({_os_reason(guard.error)})", file=sys.stderr)
        return code or EXIT_FAILURE
    finally:
        if guard is not None:
            sys.stdout = stdout
        if errors is not None:  # (a caller in this process keeps its stdout as it was)
            with contextlib.suppress(AttributeError, ValueError, OSError):
                stdout.reconfigure(errors=errors)
        if stderr is None:
            sys.stderr.close()
            sys.stderr = None


def _main(argv: Sequence[str] | None) -> int:
    """:func:`main` once its standard streams are set up: the command run, its refusals
    and failures turned into one line on stderr and an exit code."""
    parser = build_parser()
    verbose = 0
    try:
        args = parser.parse_args(argv)
        verbose = args.verbose
        if args.quiet and args.verbose:
            raise UsageError("give -q/--quiet or -v/--verbose, not both")
        # (imported once a command runs: --help and --version stay quick)
        from .diagnose.locate import EvidenceWarning
        from .fit.result import EstimateOnBoundWarning
        from .likelihood import NotWholePeriodsWarning, SilentChannelWarning
        from .recording import QuestionableRecordingWarning

        # the package's warnings about a run, one line each (Python's display is two lines
        # naming the bayespilot script); a command that records its own prints them itself
        with _warnings_of((SilentChannelWarning, EvidenceWarning, NotWholePeriodsWarning,
                           EstimateOnBoundWarning, QuestionableRecordingWarning),
                          _warning_lines_once()):
            return args.handler(args)
    except SystemExit as exc:  # --help, --version
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else EXIT_USAGE)
    except UsageError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except CommandFailed as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (bayespilot fit ... | head): not an error
        # (main's _GuardedStdout keeps the prints from raising it; this is for a write that
        # bypassed it)
        # (stdout is closed: point it at devnull so that the interpreter's flush at exit does
        # not raise again, as the Python docs advise for SIGPIPE)
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_OK
    except Exception as exc:  # a bug: say so in one line; the traceback with -v
        if _interrupted(exc):  # Ctrl-C in a numba kernel: a SystemError caused by it
            print(f"{PROG}: interrupted", file=sys.stderr)
            return 130
        if verbose:
            traceback.print_exc()
        print(f"{PROG}: error: unexpected {type(exc).__name__}: {' '.join(str(exc).split())} "
              f"(run with -v for the traceback, and please report it)", file=sys.stderr)
        return EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())

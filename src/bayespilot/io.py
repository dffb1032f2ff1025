"""Read and write recordings on disk (recording format, version 1).

A recording is two files with the same stem: ``NAME.csv`` holds the signals
and ``NAME.json`` says what the run was (see ``docs/recording-format.md``).
MATLAB ``.mat`` files whose variables follow the same names can be read too.

Every refusal raises :class:`~bayespilot.recording.RecordingError` with one
message that starts with the file it is about, then the problem, e.g.
``"out/run.csv: missing required column(s): u"``.  Readers never guess a
missing value and never change the files they read.  :func:`write_recording`
replaces a pair atomically: a failure leaves the previous pair untouched.
"""

from __future__ import annotations

import csv
import io as _stdio
import json
import math
import os
import re
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from bayespilot._files import temporary_sibling, utf8_text
from bayespilot.recording import (OPTIONAL_KEYS, OPTIONAL_SIGNALS, REQUIRED_SIGNALS, TASKS,
                                  Recording, RecordingError)
from bayespilot.recording import (_describe, _is_number, _metadata_problems, _near_miss,
                                  _warn_if_questionable)

__all__ = ["FORMAT", "read_recording", "read_mat", "write_recording"]

#: The ``format`` string of the recording format this module reads and writes.
FORMAT = "bayespilot-recording/1"
#: Keys every ``NAME.json`` must have.
REQUIRED_KEYS = ("format", "sample_rate_hz", "motion_gain", "task")
#: The struct variable of a ``.mat`` file that may hold the metadata keys.
MAT_METADATA_STRUCT = "metadata"
#: What a recording is, for messages about a path that names something else.
_WHAT_A_RECORDING_IS = "a recording is NAME.csv with NAME.json, or a .mat file"

PathLike = str | os.PathLike[str]

# A decimal number as written in a CSV cell (surrounding blanks are allowed).
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
# CSV text made only of these characters can only spell numbers (or garbage
# that numpy.loadtxt refuses too): it takes the fast path of one C parse.
_FAST_BODY = re.compile(r"[0-9eE+\-.,\r\n \t]*")
_NAN = re.compile(r"[+-]?nan", re.IGNORECASE)
_INF = re.compile(r"[+-]?inf(?:inity)?", re.IGNORECASE)
# A number with a decimal comma (German Excel: "0,5", "1.234,5"); the cell is quoted, since
# ',' also separates the fields.
_DECIMAL_COMMA = re.compile(r"[+-]?(?:\d+(?:\.\d{3})*)?,\d+(?:[eE][+-]?\d+)?", re.ASCII)
# Excel's separator hint, a first line "sep=," (or "sep=;", "sep=<tab>").
_SEP_LINE = re.compile(r"\s*sep=\S?\s*", re.IGNORECASE)


# ---------------------------------------------------------------------------
# small helpers
# ---------------------------------------------------------------------------
def _fail(where: Any, msg: str) -> RecordingError:
    return RecordingError(f"{where}: {msg}")


def _as_path(path: Any, argname: str = "path", *, folder_ok: bool = False) -> Path:
    """``path`` as a Path; ``""`` is refused, and so is ``"."`` unless ``folder_ok`` (a
    reader, which then says that it is a folder)."""
    if isinstance(path, (str, os.PathLike)):
        p = Path(path)
        if os.fspath(path) == "" or (str(p) == "." and not folder_ok):
            raise RecordingError(f"{argname} must name a file, got {path!r}")
        return p
    raise TypeError(f"{argname} must be a str or os.PathLike, got {type(path).__name__}")


def _shown(path: PathLike, p: Path) -> str:
    """``path`` as the user wrote it (a folder's trailing ``/`` kept), for messages."""
    shown = os.fspath(path)
    return shown if isinstance(shown, str) else str(p)


def _with_suffix_added(stem: Path, suffix: str) -> Path:
    """``stem`` + ``suffix``, keeping any dots already in the stem's name."""
    return stem.parent / (stem.name + suffix)


def _pair_paths(path: Path) -> tuple[Path, Path]:
    """The CSV and JSON :func:`write_recording` writes for ``path``: a stem, or the ``.csv``
    or ``.json`` path of the pair (any case)."""
    stem = path.with_suffix("") if path.suffix.lower() in (".csv", ".json") else path
    return _with_suffix_added(stem, ".csv"), _with_suffix_added(stem, ".json")


def _pair_on_disk(path: str | os.PathLike) -> tuple[list[Path], Any, bool]:
    """The recording pair :func:`write_recording` would write at ``path`` as it lies on disk:
    its files that exist, its sidecar parsed (None where there is none, or it is no JSON),
    and whether ``bayespilot simulate`` wrote it (the sidecar's ``"simulation"`` block).  The
    one rule by which the command line and the demo replace a simulated run but refuse a
    lab's measurement."""
    csv_path, json_path = _pair_paths(Path(path))
    there = [p for p in (csv_path, json_path) if p.exists()]
    try:
        sidecar = json.loads(json_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        sidecar = None
    simulated = isinstance(sidecar, dict) and isinstance(sidecar.get("simulation"), dict)
    return there, sidecar, simulated


def _read_bytes(path: Path) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except FileNotFoundError:
        raise _fail(path, "file not found") from None
    except IsADirectoryError:
        raise _fail(path, "is a directory, not a file") from None
    except OSError as exc:
        raise _fail(path, f"cannot be read ({exc.strerror or exc})") from None


# ---------------------------------------------------------------------------
# metadata (the JSON sidecar, or the scalar variables of a .mat file)
# ---------------------------------------------------------------------------
def _check_metadata(where: Any, obj: Mapping[str, Any], *, what: str = "key") -> tuple[float, float, str, dict]:
    """Check the keys of a recording's metadata; return (rate, K_theta, task, rest).

    ``obj`` holds every key, required ones included.  ``what`` is the word for
    a key in messages ("key" for JSON, "variable" for .mat files).
    """
    missing = [k for k in REQUIRED_KEYS if k not in obj]
    if missing:
        others = [k for k in obj if k not in _METADATA_KEYS]
        hints = [f"{k!r} for {near}" for k in others
                 if (near := _near_miss(k, missing)) is not None]
        hint = f" (misspelled? the file has {', '.join(hints)})" if hints else ""
        raise _fail(where, f"missing required {what}(s): {', '.join(missing)}{hint}")
    fmt = obj["format"]
    if fmt != FORMAT or not isinstance(fmt, str):
        raise _fail(where, f"unknown format {fmt!r} (expected {FORMAT!r})")
    problems = []  # every bad key, in one message
    rate = obj["sample_rate_hz"]
    rate_ok = _is_number(rate) and math.isfinite(rate) and rate > 0
    if not rate_ok:
        problems.append(f"sample_rate_hz must be a positive finite number, got {rate!r}")
    kth = obj["motion_gain"]
    if not _is_number(kth) or not math.isfinite(kth) or kth < 0:
        problems.append(f"motion_gain must be a finite number >= 0, got {kth!r}")
    task = obj["task"]
    if not isinstance(task, str) or task not in TASKS:
        problems.append(f"task must be one of {', '.join(repr(t) for t in TASKS)}, got {task!r}")
    # the optional keys: the same checks as for a Recording built in Python (the forcing's
    # lines against the Nyquist frequency when the rate is a valid one)
    problems += _metadata_problems(obj, float(rate) if rate_ok else None)
    if problems:
        raise _fail(where, "; ".join(problems))

    rest = {k: v for k, v in obj.items() if k not in REQUIRED_KEYS}
    return float(rate), float(kth), task, rest


def _multiples(t: np.ndarray, unit: np.ndarray | float) -> bool:
    """Whether every t is a whole multiple of ``unit`` (to a few float64 rounding units)."""
    slack = 4.0 * np.spacing(np.maximum(np.abs(t), 1.0))
    return bool(np.all(np.abs(t - np.round(t / unit) * unit) <= slack))


def _rounding_hint(t: np.ndarray, rate: float) -> str:
    """Why ``t``, refused as not uniform, may be so: rounded when it was written ('' if not).

    An exporting tool that keeps a few decimals (an Excel "0.000" format: 1 ms, too coarse
    at 120 Hz) or a few significant digits (MATLAB's csvwrite: 5) makes the steps alternate
    between two values a rounding unit apart, which the reader rightly refuses.  The hint is
    given only when every t is a multiple of that unit and lies within half a unit of the
    exact time k / sample_rate_hz, the unit finer than a step: a dropped, repeated or
    jittered sample is not explained by it.  Decimals are tried first, then significant
    digits (whose unit grows with t)."""
    dt = 1.0 / rate
    exact = np.arange(t.size) / rate
    slack = 4.0 * np.spacing(np.maximum(np.abs(t), 1.0))
    for d in range(10):
        unit = 10.0 ** -d
        if unit >= dt or not _multiples(t, unit):
            continue
        if np.all(np.abs(t - exact) <= unit / 2 + slack):
            return (f"; t looks rounded to {unit:g} s (written with {d} decimal"
                    f"{'' if d == 1 else 's'}): write t with more digits")
        break  # the coarsest unit t is made of does not explain it: significant digits?
    nonzero = np.abs(t) > 0
    scale = np.zeros_like(t)
    scale[nonzero] = np.floor(np.log10(np.abs(t[nonzero])))
    for digits in range(1, 16):
        unit = np.where(nonzero, 10.0 ** (scale - digits + 1), 1.0)
        if not _multiples(t, unit):
            continue
        coarsest = float(np.max(unit[nonzero], initial=0.0))  # (a t of 0 is exact)
        if coarsest < dt and np.all(np.abs(t - exact) <= np.where(nonzero, unit, 0.0) / 2 + slack):
            return (f"; t looks rounded to {digits} significant digits ({coarsest:g} s at its "
                    f"end; MATLAB's csvwrite keeps 5): write t with more digits")
        return ""
    return ""


def _build(signals: dict[str, np.ndarray], rate: float, kth: float, task: str,
           metadata: dict, where: Any, stem: Path) -> Recording:
    """Make the Recording; any problem it finds is reported against ``where``."""
    source = str(stem)
    try:
        rec = Recording(signals, rate, kth, task, metadata, source=source)
    except RecordingError as exc:
        msg = str(exc)
        prefix = f"{source}: "
        if msg.startswith(prefix):
            msg = msg[len(prefix):]
        if msg.startswith("t is not uniformly spaced") and "t" in signals:
            msg += _rounding_hint(np.asarray(signals["t"], dtype=np.float64), rate)
        raise _fail(where, msg) from None
    # valid but unlike the paper's data (short, slow): warn, at the reader's caller
    _warn_if_questionable(rec)
    return rec


# ---------------------------------------------------------------------------
# CSV + JSON
# ---------------------------------------------------------------------------
def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not allowed; values must be finite numbers")


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"duplicate key {key!r}")
        out[key] = value
    return out


def _read_json(path: Path) -> dict[str, Any]:
    raw = _read_bytes(path)
    if not raw.strip():
        raise _fail(path, "file is empty (expected a JSON object)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise _fail(path, f"is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    try:
        obj = json.loads(text, parse_constant=_reject_constant, object_pairs_hook=_no_duplicates)
    except json.JSONDecodeError as exc:
        raise _fail(path, f"is not valid JSON ({exc.msg} at line {exc.lineno} column {exc.colno})") from None
    except ValueError as exc:
        raise _fail(path, f"is not valid JSON ({exc})") from None
    if not isinstance(obj, dict):
        raise _fail(path, f"must hold a JSON object at the top level, got {_describe(obj)}")
    return obj


def _parse_column(path: Path, name: str, values: list[str], lines: list[int]) -> np.ndarray:
    """Convert one column's cells to float64, refusing anything but finite decimals."""
    out = np.empty(len(values), dtype=np.float64)
    for i, cell in enumerate(values):
        s = cell.strip()
        where = f"in column {name!r} at line {lines[i]}"
        if not s:
            raise _fail(path, f"empty value {where}")
        if _NAN.fullmatch(s):
            raise _fail(path, f"NaN {where} (values must be finite)")
        if _INF.fullmatch(s):
            raise _fail(path, f"infinite value {cell!r} {where} (values must be finite)")
        if not _NUMBER.fullmatch(s):
            hint = ""
            if _DECIMAL_COMMA.fullmatch(s):
                hint = (f" (a decimal comma? the format writes numbers with '.' as the decimal "
                        f"point, {s.replace('.', '').replace(',', '.')!r}, and ',' between fields)")
            raise _fail(path, f"non-numeric value {cell!r} {where}{hint}")
        v = float(s)
        if not math.isfinite(v):
            raise _fail(path, f"infinite value {cell!r} {where} (overflows a float; values must be finite)")
        out[i] = v
    return out


def _header_hint(header: list[str], missing: list[str]) -> str:
    """Why a header may lack required columns: another separator, a comment line, a
    misspelled name ('' if none of these)."""
    line = ",".join(header)
    shown = line if len(line) <= 60 else line[:57] + "..."
    if line.lstrip().startswith("#"):
        return (f" (the first line reads {shown!r}: the format has no comment lines; its first "
                f"line is the header row of column names)")
    for sep, name in ((";", "';'"), ("\t", "tabs")):
        if sep in line:
            return (f" (the header reads {shown!r}: the format is comma-separated, not "
                    f"separated by {name}, with '.' as the decimal point)")
    names = [h.strip() for h in header]
    known = set(REQUIRED_SIGNALS + OPTIONAL_SIGNALS)
    hints = [f"{h!r} for {near}" for h in names
             if h not in known and (near := _near_miss(h, missing)) is not None]
    return f" (misspelled? the header has {', '.join(hints)})" if hints else ""


def _check_header(path: Path, header: list[str]) -> list[str]:
    line = ",".join(header)
    if _SEP_LINE.fullmatch(line):  # (else: "empty column name in the header (column 2)")
        raise _fail(path, f"the first line reads {line!r}, Excel's separator hint: the format "
                          f"has no such line; its first line is the header row of column names "
                          f"(delete that line)")
    for j, h in enumerate(header):
        if "\ufeff" in h:  # the file's first BOM is gone when decoded: this is another one
            raise _fail(path, f"a byte-order mark (U+FEFF) in the header, column {j + 1} "
                              f"({h.strip()!r}): the file has a second one after the first "
                              f"(saved again with a BOM added, or files joined?); remove it")
    names = [h.strip() for h in header]
    for j, h in enumerate(names):
        if not h:
            raise _fail(path, f"empty column name in the header (column {j + 1})")
    seen: set[str] = set()
    for h in names:
        if h in seen:
            raise _fail(path, f"duplicate column name {h!r} in the header")
        seen.add(h)
    missing = [c for c in REQUIRED_SIGNALS if c not in seen]
    if missing:
        raise _fail(path, f"missing required column(s): {', '.join(missing)}"
                          + _header_hint(header, missing))
    return names


def _read_csv_fast(path: Path, text: str) -> dict[str, np.ndarray] | None:
    """Parse a plain all-numeric CSV in C; None if anything is unusual.

    Only text whose body consists of digits, signs, points, exponents,
    commas, blanks and line ends is tried, and the result is used only if
    it has one row per line and one column per header name; anything else
    goes to the careful reader, which finds and names the problem.
    """
    header_line, newline, body = text.partition("\n")
    if not newline or '"' in header_line or not header_line.strip():
        return None
    names = _check_header(path, next(csv.reader([header_line.rstrip("\r")])))
    body = body.rstrip("\r\n")
    if not body or not _FAST_BODY.fullmatch(body):
        return None
    try:
        arr = np.loadtxt(_stdio.StringIO(body), delimiter=",", dtype=np.float64, ndmin=2,
                         comments=None, encoding=None)
    except ValueError:
        return None
    if arr.shape != (body.count("\n") + 1, len(names)) or not np.isfinite(arr).all():
        return None
    return {name: np.ascontiguousarray(arr[:, j]) for j, name in enumerate(names)}


def _is_blank(row: list[str]) -> bool:
    """A CSV row that is an empty line or one holding only blanks (spaces, tabs)."""
    return not row or (len(row) == 1 and not row[0].strip())


def _read_csv(path: Path) -> dict[str, np.ndarray]:
    raw = _read_bytes(path)
    if not raw:
        raise _fail(path, "file is empty (expected a header row and data rows)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise _fail(path, f"is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    fast = _read_csv_fast(path, text)
    if fast is not None:
        return fast
    reader = csv.reader(_stdio.StringIO(text, newline=""), strict=True)
    try:
        header = next(reader, None)
        while header is not None and _is_blank(header):  # blank lines before the header
            header = next(reader, None)
        if header is None:
            raise _fail(path, "file is empty (expected a header row and data rows)")
        names = _check_header(path, header)
        ncol = len(names)
        rows: list[list[str]] = []
        lines: list[int] = []
        blank_at: int | None = None
        for row in reader:
            if _is_blank(row):  # blank lines at the end are allowed, as editors leave them
                if blank_at is None:
                    blank_at = reader.line_num
                continue
            if blank_at is not None:
                stray = text.find("\r\r\n")
                if stray >= 0:  # csv reads "\r\r\n" as a line end and a blank line
                    line_no = text.count("\n", 0, stray) + 1
                    raise _fail(path, f"line {line_no} ends in "
                                      f"\\r\\r\\n: stray carriage returns (line ends converted "
                                      f"twice, e.g. Python's csv.writer on Windows without "
                                      f"newline=''); end lines in \\n or \\r\\n")
                raise _fail(path, f"line {blank_at} is blank (expected {ncol} fields)")
            if len(row) != ncol:
                fields = f"{len(row)} field" + ("" if len(row) == 1 else "s")
                why = ("a comment line? the format has none" if row[0].lstrip().startswith("#")
                       else "one per header column; columns must have equal length")
                raise _fail(path, f"line {reader.line_num} has {fields}, expected {ncol} ({why})")
            rows.append(row)
            lines.append(reader.line_num)
    except csv.Error as exc:
        raise _fail(path, f"is not valid CSV at line {reader.line_num} ({exc})") from None
    if not rows:
        raise _fail(path, "header only, no data rows")
    columns = list(zip(*rows))
    return {name: _parse_column(path, name, list(col), lines) for name, col in zip(names, columns)}


def _resolve(path: Path, shown: str | None = None) -> tuple[str, Path, Path, Path]:
    """Return (kind, stem, first, second) for a path given to read_recording.

    kind is "mat" (first is the .mat file) or "pair" (first is the CSV,
    second the JSON).  ``shown`` is the path as given, for messages
    (default ``str(path)``; also used by :mod:`bayespilot.diagnose.batch`).
    """
    if shown is None:
        shown = str(path)
    if path.is_dir() and (str(path) in (".", "..") or shown.endswith(("/", os.sep))
                          or os.path.basename(shown) in (".", "..")):
        raise _fail(shown, f"a folder, not a recording ({_WHAT_A_RECORDING_IS})")
    suffix = path.suffix.lower()
    if suffix == ".mat":
        return "mat", path.with_suffix(""), path, path
    if suffix == ".csv":
        return "pair", path.with_suffix(""), path, path.with_suffix(".json")
    if suffix == ".json":
        return "pair", path.with_suffix(""), path.with_suffix(".csv"), path
    csv_path = _with_suffix_added(path, ".csv")
    json_path = _with_suffix_added(path, ".json")
    mat_path = _with_suffix_added(path, ".mat")
    if not csv_path.exists() and not json_path.exists():
        if mat_path.exists():
            return "mat", path, mat_path, mat_path
        if path.is_dir():
            raise _fail(shown, f"a folder, not a recording ({_WHAT_A_RECORDING_IS})")
        if path.exists():  # post.nc, fig.png, data.h5: a file, but not one of a recording
            raise _fail(shown, f"not a recording ({_WHAT_A_RECORDING_IS})")
        if shown.endswith(("/", os.sep)):  # a folder was meant (its slash: not a stem)
            raise _fail(shown, "no such folder")
        raise _fail(path, f"file not found (looked for {csv_path} and {json_path})")
    return "pair", path, csv_path, json_path


def read_recording(path: PathLike) -> Recording:
    """Read a recording from disk.

    Parameters
    ----------
    path : str or os.PathLike
        The stem (``out/run``), the CSV (``out/run.csv``) or the JSON sidecar
        (``out/run.json``) of a recording in the CSV + JSON format; or a
        MATLAB ``.mat`` file (read with :func:`read_mat`).  A stem with
        neither ``STEM.csv`` nor ``STEM.json`` but a ``STEM.mat`` reads that.

    Returns
    -------
    Recording
        Signals by column name (unknown columns kept), ``sample_rate_hz``,
        ``motion_gain``, ``task``, and every other JSON key in ``metadata``
        (unknown keys kept).  ``source`` is the stem.

    Raises
    ------
    RecordingError
        With one message naming the file and the problem, if ``path`` is a
        folder or a file that is not a recording (``post.nc``); a file is
        missing, unreadable or empty; the CSV has a missing, duplicate or
        empty column name (with a hint when the header is separated by ``;``
        or tabs, is a ``#`` comment, or misspells a required name; named: a
        first line ``sep=,``, Excel's separator hint, and a second byte-order
        mark), a row with too few or too many fields, a blank line before
        more data (named: lines ending in ``\\r\\r\\n``), no data rows, or an
        empty, non-numeric (with a hint for a decimal comma), NaN or infinite
        value; ``t`` does not start at 0, is not uniform or disagrees with
        ``sample_rate_hz`` (with a hint when ``t`` looks like milliseconds or
        sample counts, or rounded to a few decimals or significant digits);
        the JSON is not valid
        JSON, not an object, lacks a required key, has an unknown ``format``
        or a key of the wrong type or value (``controlled_element`` without
        numeric ``num``/``den``, with a zero or improper plant, or together
        with ``controlled_element_gain``; ``forcing`` without
        ``base_frequency`` or with ``target``/``disturbance`` arrays ``n``,
        ``amplitude``, ``phase`` of unequal length; ...).  Every bad key of
        the JSON is named in the one message.
    TypeError
        If ``path`` is not a str or path.

    Warns
    -----
    QuestionableRecordingWarning
        If the record is shorter than 30 s or sampled below 50 Hz, has
        ``motion_gain`` 0 but a moving ``theta_ddot_m``, a ``control_gain``
        that is not positive, or a key that looks like a misspelled optional
        key (see :func:`~bayespilot.recording.questionable`); the recording
        is still returned.

    Notes
    -----
    CSV cells are decimal numbers (surrounding blanks allowed); header names
    are stripped of surrounding blanks; empty lines, or lines of blanks only,
    at the end are ignored.  ``NaN``/``Infinity`` are refused in both files,
    as are duplicate JSON keys.  A ``run`` of ``1.0`` is read as ``1`` (JSON
    does not tell them apart; :func:`read_mat` does the same).  The files are
    only opened for reading.

    Examples
    --------
    >>> import tempfile, numpy as np
    >>> from bayespilot.recording import Recording
    >>> t = np.arange(5) / 100.0
    >>> rec = Recording({"t": t, "e": 0 * t, "u": 0 * t, "theta_ddot_m": 0 * t},
    ...                 sample_rate_hz=100.0, motion_gain=1.0, task="FD")
    >>> with tempfile.TemporaryDirectory() as d:
    ...     csv_path, json_path = write_recording(rec, d + "/run")
    ...     back = read_recording(d + "/run")
    >>> back.n_samples, back.sample_rate_hz, back.task
    (5, 100.0, 'FD')
    """
    p = _as_path(path, folder_ok=True)
    kind, stem, first, second = _resolve(p, _shown(path, p))
    if kind == "mat":
        return read_mat(first)
    csv_path, json_path = first, second
    csv_exists, json_exists = csv_path.exists(), json_path.exists()
    if p.suffix.lower() == ".json":
        if not json_exists:
            raise _fail(json_path, "file not found")
        if not csv_exists:
            raise _fail(json_path, f"no signals file {csv_path} found")
    else:
        if not csv_exists:
            if p.suffix.lower() == ".csv":
                raise _fail(csv_path, "file not found")
            raise _fail(json_path, f"no signals file {csv_path} found")
        if not json_exists:
            raise _fail(csv_path, f"no sidecar {json_path} found")
    meta = _read_json(json_path)
    _integral_run(meta)
    rate, kth, task, rest = _check_metadata(json_path, meta)
    signals = _read_csv(csv_path)
    return _build(signals, rate, kth, task, rest, csv_path, stem)


# ---------------------------------------------------------------------------
# MATLAB
# ---------------------------------------------------------------------------
_SIGNAL_NAMES = REQUIRED_SIGNALS + OPTIONAL_SIGNALS
_METADATA_KEYS = REQUIRED_KEYS + OPTIONAL_KEYS


def _from_matlab(where: Path, name: str, value: Any) -> Any:
    """Convert a loadmat(simplify_cells=True) value to plain JSON-like Python."""
    if isinstance(value, Mapping):
        return {str(k): _from_matlab(where, f"{name}.{k}", v) for k, v in value.items()}
    if isinstance(value, (str, bool)) or value is None:
        return value
    if isinstance(value, (int, float)):
        return value
    if isinstance(value, complex) or (isinstance(value, np.ndarray) and value.dtype.kind == "c") \
            or isinstance(value, np.complexfloating):
        raise _fail(where, f"variable {name!r} is complex; only real values can be read")
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [_from_matlab(where, f"{name}[{i}]", v) for i, v in enumerate(value)]
    if isinstance(value, np.ndarray):
        if value.dtype.kind == "U":
            if value.size == 0:
                return ""
            return value.item() if value.ndim == 0 else [str(s) for s in value.ravel()]
        if value.dtype.kind == "O":
            if value.ndim == 0:
                return _from_matlab(where, name, value.item())
            return [_from_matlab(where, f"{name}[{i}]", v) for i, v in enumerate(value.tolist())]
        if value.dtype.kind in "biuf":
            return value.tolist()
    raise _fail(where, f"variable {name!r} has a type that cannot be read ({type(value).__name__})")


def _as_list(x: Any) -> Any:
    """A scalar squeezed out of a 1-element MATLAB vector, back as a list."""
    return [x] if _is_number(x) else x


def _integral_run(meta: dict[str, Any]) -> None:
    """``run`` 1.0 as the integer 1: JSON has one kind of number, so 1.0 is the number 1
    (tools that write every number as a float, MATLAB and pandas' to_json, write it so);
    1.5 and true stay refused."""
    run = meta.get("run")
    if isinstance(run, float) and run.is_integer():
        meta["run"] = int(run)


def _mat_normalise(meta: dict[str, Any]) -> None:
    """Undo MATLAB conventions for the keys whose types the format fixes."""
    _integral_run(meta)
    ce = meta.get("controlled_element")
    if isinstance(ce, dict):
        for part in ("num", "den"):
            if part in ce:
                ce[part] = _as_list(ce[part])
    forcing = meta.get("forcing")
    if isinstance(forcing, dict):
        for name in ("target", "disturbance"):
            part = forcing.get(name)
            if isinstance(part, dict):
                for arr in ("n", "amplitude", "phase"):
                    if arr in part:
                        part[arr] = _as_list(part[arr])
                if isinstance(part.get("n"), list):
                    part["n"] = [int(v) if isinstance(v, float) and v.is_integer() else v
                                 for v in part["n"]]


def read_mat(path: PathLike) -> Recording:
    """Read a recording from a MATLAB ``.mat`` file (versions 4 to 7.2).

    The file must hold:

    - the signals as real numeric vectors (row or column) named like the CSV
      columns: ``t``, ``e``, ``u``, ``theta_ddot_m`` (required), ``theta``,
      ``f_t``, ``f_d`` (optional), all with one value per sample of ``t``;
    - the metadata as scalar variables named like the JSON keys:
      ``sample_rate_hz`` (required, the sample rate is never guessed from
      ``t``), ``motion_gain`` (required), ``task`` (required, a char array
      ``'FD'``, ``'FT'`` or ``'other'``) and optionally
      ``controlled_element_gain``, ``control_gain``, ``subject``, ``run``,
      ``notes``, ``controlled_element`` (struct with ``num``, ``den``) and
      ``forcing`` (struct with ``base_frequency``, ``target`` and
      ``disturbance``, each a struct with ``n``, ``amplitude``, ``phase``).
      The metadata keys may instead (or as well) be fields of one struct
      variable named ``metadata``; a key given in both places is refused.
      ``format`` is optional, but when present must be
      ``'bayespilot-recording/1'``.

    Any other numeric vector with one value per sample of ``t`` is kept as a
    signal; any other variable (scalar, string, struct, cell, matrix) is kept
    in ``metadata``, converted to plain Python (lists, dicts, numbers, str).

    Parameters
    ----------
    path : str or os.PathLike
        The ``.mat`` file.

    Returns
    -------
    Recording
        As :func:`read_recording` returns; ``source`` is the path without
        ``.mat``.

    Raises
    ------
    RecordingError
        With one message naming the file and the problem: file missing or
        not a readable .mat file (including MATLAB v7.3/HDF5 files), a
        required variable missing, a signal that is not a real vector of
        the length of ``t`` or is not finite, ``t`` not uniform or
        disagreeing with ``sample_rate_hz``, or a metadata key of the wrong
        type (the same checks as for a JSON sidecar).
    TypeError
        If ``path`` is not a str or path.

    Warns
    -----
    QuestionableRecordingWarning
        For the reasons :func:`read_recording` gives (a short or slowly
        sampled record, ...; see :func:`~bayespilot.recording.questionable`).

    Examples
    --------
    >>> import tempfile, numpy as np, scipy.io
    >>> t = np.arange(5) / 50.0
    >>> with tempfile.TemporaryDirectory() as d:
    ...     scipy.io.savemat(d + "/run.mat", {"t": t, "e": 0 * t, "u": 0 * t,
    ...                      "theta_ddot_m": 0 * t, "sample_rate_hz": 50.0,
    ...                      "motion_gain": 0.5, "task": "FT", "subject": "S3"})
    ...     rec = read_mat(d + "/run.mat")
    >>> rec.sample_rate_hz, rec.motion_gain, rec.metadata["subject"]
    (50.0, 0.5, 'S3')
    """
    p = _as_path(path, folder_ok=True)
    if not p.exists():
        raise _fail(p, "file not found")
    if p.is_dir():
        raise _fail(_shown(path, p), "is a directory, not a file")
    import scipy.io  # noqa: PLC0415 - keep `import bayespilot.io` cheap

    try:
        with open(p, "rb") as fh:
            raw = scipy.io.loadmat(fh, simplify_cells=True)
    except NotImplementedError:
        raise _fail(p, "MATLAB v7.3 (HDF5) files are not supported; "
                       "save with save(..., '-v7') instead") from None
    except OSError as exc:
        raise _fail(p, f"cannot be read ({exc.strerror or exc})") from None
    except Exception as exc:  # scipy raises ValueError, TypeError, ... on garbage
        raise _fail(p, f"is not a readable MATLAB .mat file ({type(exc).__name__}: {exc})") from None
    variables = {k: v for k, v in raw.items() if not k.startswith("__")}

    if "t" not in variables:
        raise _fail(p, "missing required variable(s): " + ", ".join(
            c for c in REQUIRED_SIGNALS if c not in variables))
    t = variables["t"]
    if not isinstance(t, np.ndarray) or t.ndim != 1 or t.dtype.kind not in "biuf":
        shape = getattr(t, "shape", ())
        raise _fail(p, f"variable 't' must be a real numeric vector, got shape {shape}")
    n = t.size

    meta: dict[str, Any] = {}
    struct = variables.pop(MAT_METADATA_STRUCT, None)
    if struct is not None:
        if not isinstance(struct, Mapping):
            raise _fail(p, f"variable {MAT_METADATA_STRUCT!r} must be a struct of metadata keys, "
                           f"got {type(struct).__name__}")
        for k, v in struct.items():
            meta[str(k)] = _from_matlab(p, f"{MAT_METADATA_STRUCT}.{k}", v)

    signals: dict[str, np.ndarray] = {}
    for name, value in variables.items():
        is_vector = (isinstance(value, np.ndarray) and value.ndim == 1
                     and value.dtype.kind in "biufc")
        if name in _SIGNAL_NAMES:
            if not is_vector or value.size != n:
                shape = getattr(value, "shape", ())
                raise _fail(p, f"variable {name!r} must be a numeric vector with one value per "
                               f"sample of t ({n}), got shape {shape}")
            if value.dtype.kind == "c":
                raise _fail(p, f"variable {name!r} is complex; only real values can be read")
            signals[name] = value.astype(np.float64)
        elif name in _METADATA_KEYS or not (is_vector and value.size == n):
            if name in meta:
                raise _fail(p, f"metadata key {name!r} is given both as a variable and in the "
                               f"{MAT_METADATA_STRUCT!r} struct")
            meta[name] = _from_matlab(p, name, value)
        else:
            if value.dtype.kind == "c":
                raise _fail(p, f"variable {name!r} is complex; only real values can be read")
            signals[name] = value.astype(np.float64)

    missing = [c for c in REQUIRED_SIGNALS if c not in signals]
    if missing:
        raise _fail(p, f"missing required variable(s): {', '.join(missing)}")
    if "sample_rate_hz" not in meta:
        raise _fail(p, "no sample_rate_hz variable (the sample rate is never guessed from t)")
    meta.setdefault("format", FORMAT)
    _mat_normalise(meta)
    rate, kth, task, rest = _check_metadata(p, meta, what="variable")
    return _build(signals, rate, kth, task, rest, p, p.with_suffix(""))


# ---------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------
def _to_json(where: Any, name: str, value: Any) -> Any:
    """Plain JSON types for metadata values (numpy arrays and scalars allowed); strings are
    passed through :func:`bayespilot._files.utf8_text`, as a result file's are (so that a
    recording's sidecar and a result of it spell a C-locale argument the same way)."""
    if isinstance(value, Mapping):
        out = {}
        for k, v in value.items():
            if not isinstance(k, str):
                raise _fail(where, f"metadata key {name}.{k!r} is not a string")
            out[utf8_text(k)] = _to_json(where, f"{name}.{k}", v)
        return out
    if isinstance(value, str):
        return utf8_text(value)
    if isinstance(value, (list, tuple)):
        return [_to_json(where, f"{name}[{i}]", v) for i, v in enumerate(value)]
    if isinstance(value, np.ndarray):
        return _to_json(where, name, value.tolist())
    if isinstance(value, np.generic):
        return _to_json(where, name, value.item())
    if isinstance(value, float) and not math.isfinite(value):
        raise _fail(where, f"metadata {name} is {value!r}, which JSON cannot hold")
    if value is None or isinstance(value, (str, bool, int, float)):
        return value
    raise _fail(where, f"metadata {name} of type {type(value).__name__} cannot be written as JSON")


def _open_temp(directory: Path, name: str) -> tuple[Path, int]:
    """Create a new, empty temporary file next to its target (mode honours umask); its name
    by :func:`bayespilot._files.temporary_sibling`, as every temporary file's."""
    while True:
        tmp = temporary_sibling(directory / name)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
        except FileExistsError:  # pragma: no cover - the pid and 32 random bits
            continue
        return tmp, fd


def _write_temp(directory: Path, name: str, data: bytes, temps: list[Path]) -> Path:
    tmp, fd = _open_temp(directory, name)
    temps.append(tmp)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    return tmp


def _remove_quietly(path: Path) -> None:
    try:
        os.remove(path)
    except FileNotFoundError:
        pass


def write_recording(recording: Recording, path: PathLike) -> tuple[Path, Path]:
    """Write a recording as ``STEM.csv`` and ``STEM.json``.

    Parameters
    ----------
    recording : Recording
        The recording to write.
    path : str or os.PathLike
        The stem (``out/run``), or the ``.csv`` or ``.json`` path of the pair.
        Missing parent directories are created.

    Returns
    -------
    csv_path, json_path : Path
        The files written.

    Raises
    ------
    RecordingError
        If the recording cannot be written so that :func:`read_recording`
        reads it back: a column name that is empty, has surrounding blanks or
        a line break; metadata that is not JSON (a non-finite number, an
        object of another type), reuses a required key, or that the reader
        would refuse; or ``path`` ends in ``.mat`` or in a path separator (a
        folder, not a stem).
    TypeError
        If ``recording`` is not a Recording or ``path`` not a str or path.
    OSError
        If the files cannot be written; the previous pair, if any, is then
        left as it was and no temporary file is left behind.

    Notes
    -----
    Columns come in the order ``t, e, u, theta_ddot_m``, then the others in
    the recording's order.  Text (column names, metadata) is written as UTF-8;
    lone surrogates in it, as Python gives command-line arguments under the C
    locale (``--subject Müller`` with ``LC_ALL=C PYTHONUTF8=0``), are first
    decoded as the UTF-8 bytes they escape, and any other one, or bytes that
    are not UTF-8, become U+FFFD: as in the result files
    (:func:`bayespilot._files.utf8_text`).  Numbers are written with ``repr`` (the shortest
    text that reads back as the same float), so a round trip is exact.
    Both files are first written in full to temporary files in the target
    directory, then moved into place with :func:`os.replace`, the JSON last;
    if the second move fails the previous CSV is put back.

    Examples
    --------
    >>> import tempfile, numpy as np
    >>> from bayespilot.recording import Recording
    >>> t = np.arange(4) / 10.0
    >>> rec = Recording({"t": t, "e": t, "u": -t, "theta_ddot_m": 0 * t, "stick_force": t},
    ...                 sample_rate_hz=10.0, motion_gain=0.0, task="other",
    ...                 metadata={"subject": "S1", "run": 2})
    >>> with tempfile.TemporaryDirectory() as d:
    ...     csv_path, json_path = write_recording(rec, d + "/lab/run2.csv")
    ...     print(csv_path.read_text().splitlines()[:2])
    ...     back = read_recording(json_path)
    ['t,e,u,theta_ddot_m,stick_force', '0.0,0.0,-0.0,0.0,0.0']
    >>> bool(np.array_equal(back.u, rec.u)), back.metadata
    (True, {'subject': 'S1', 'run': 2})
    """
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    p = _as_path(path)
    shown = _shown(path, p)
    if shown.endswith(("/", os.sep)):  # ("out/" wrote out.csv and out.json beside the folder)
        raise _fail(shown, f"a folder; give the recording's stem in it ({shown}NAME, written "
                           f"as NAME.csv and NAME.json)")
    if p.suffix.lower() == ".mat":
        raise _fail(p, "write_recording writes the CSV + JSON pair; give a stem, .csv or .json path")
    csv_path, json_path = _pair_paths(p)

    # -- build both files in memory, and check them as the reader would ----
    names = list(REQUIRED_SIGNALS) + [c for c in recording.signals if c not in REQUIRED_SIGNALS]
    for name in names:
        if not name or name != name.strip() or "\n" in name or "\r" in name:
            raise _fail(csv_path, f"column name {name!r} cannot be written (empty, surrounding "
                                  f"blanks or a line break)")
    head = _stdio.StringIO()
    csv.writer(head, lineterminator="\n").writerow([utf8_text(c) for c in names])
    columns = [recording.signals[c].tolist() for c in names]
    body = "\n".join(",".join(map(repr, row)) for row in zip(*columns))
    csv_bytes = (head.getvalue() + body + "\n").encode("utf-8")

    meta = _to_json(json_path, "metadata", dict(recording.metadata))
    clash = [k for k in REQUIRED_KEYS if k in meta]
    if clash:
        raise _fail(json_path, f"metadata reuses required key(s) {', '.join(clash)}")
    doc = {"format": FORMAT, "sample_rate_hz": recording.sample_rate_hz,
           "motion_gain": recording.motion_gain, "task": recording.task, **meta}
    _check_metadata(json_path, doc)
    json_bytes = (json.dumps(doc, indent=2, allow_nan=False, ensure_ascii=False) + "\n").encode("utf-8")

    # -- write temporaries, then move them into place, JSON last -----------
    directory = csv_path.parent
    directory.mkdir(parents=True, exist_ok=True)
    temps: list[Path] = []
    backup: Path | None = None
    csv_replaced = False
    try:
        tmp_csv = _write_temp(directory, csv_path.name, csv_bytes, temps)
        tmp_json = _write_temp(directory, json_path.name, json_bytes, temps)
        if csv_path.exists():  # keep the previous CSV until the JSON is in place
            backup = temporary_sibling(csv_path, ".bak.tmp")
            temps.append(backup)
            try:
                os.link(csv_path, backup)
            except OSError:  # no hard links on this file system
                shutil.copy2(csv_path, backup)
        os.replace(tmp_csv, csv_path)
        csv_replaced = True
        os.replace(tmp_json, json_path)
    except BaseException:
        if csv_replaced:  # put the previous CSV back (or remove the new lone one)
            try:
                if backup is not None:
                    os.replace(backup, csv_path)
                else:
                    _remove_quietly(csv_path)
            except OSError:  # pragma: no cover - nothing more can be done
                pass
        for tmp in temps:
            try:
                _remove_quietly(tmp)
            except OSError:  # pragma: no cover
                pass
        raise
    if backup is not None:
        _remove_quietly(backup)
    return csv_path, json_path

"""Writing result files so that an interrupted write never leaves half a file."""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import math
import os
import uuid
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping, Sequence

import numpy as np


#: The longest file name (one path component) most file systems take, in bytes (ext4,
#: XFS, btrfs, APFS, tmpfs; NTFS counts 255 UTF-16 units, which the bytes never exceed): the
#: limit of :func:`temporary_sibling` where the folder's own cannot be asked (no
#: ``os.pathconf``, as on Windows) or is larger.
NAME_MAX = 255


def _name_max(folder: Path) -> int:
    """The longest file name ``folder`` takes, in bytes: its ``PC_NAME_MAX``, at most
    :data:`NAME_MAX`; :data:`NAME_MAX` where that cannot be asked."""
    try:
        return min(NAME_MAX, os.pathconf(folder, "PC_NAME_MAX"))
    except (AttributeError, OSError, ValueError):  # no pathconf (Windows), or no answer
        return NAME_MAX


def temporary_sibling(path: str | os.PathLike, tail: str = ".tmp") -> Path:
    """A hidden file name beside ``path``, unique to this process and call (two writers of
    one path never share it).

    Parameters
    ----------
    path : str or os.PathLike
        The file the temporary one stands in for (or backs up).
    tail : str, default ".tmp"
        The end of the name (``".bak.tmp"`` for a backup of ``path``).

    Returns
    -------
    Path
        ``.<name>.<pid>-<8 hex><tail>`` in ``path``'s folder.

    Notes
    -----
    The one rule for temporary and backup names (:func:`replacing`,
    :func:`bayespilot.io.write_recording`).  ``<name>`` is cut short (whole characters)
    so that the whole name fits the folder's limit (``PC_NAME_MAX``, at most
    :data:`NAME_MAX`; :data:`NAME_MAX` where it cannot be asked): a legal long name of up
    to 255 bytes stays writable (the ~22 bytes added made it "File name too long").  The
    pid and the random part, not the name, keep it unique; it stays in ``path``'s folder,
    so the rename is atomic.
    """
    path = Path(path)
    end = f".{os.getpid()}-{uuid.uuid4().hex[:8]}{tail}"
    budget = _name_max(path.parent) - len(os.fsencode(f".{end}"))
    stem = path.name
    # by characters, not bytes: a cut inside a UTF-8 sequence would give a name that is
    # not valid text (and os.fsencode of a str counts its bytes as the OS will see them)
    while stem and len(os.fsencode(stem)) > budget:
        stem = stem[:-1]
    return path.with_name(f".{stem}{end}")


@contextlib.contextmanager
def replacing(path: str | os.PathLike) -> Iterator[Path]:
    """Within: write the file at the yielded temporary path; on leaving, it replaces ``path``.

    A reader sees the old file or the new one, never a truncated one (the
    rename is atomic on one file system).  When the block raises (a full disk,
    ``path`` a folder, an interrupt) the old file is kept, the temporary one
    removed, and the exception goes on.  Parent folders are created.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temporary_sibling(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def utf8_text(s: str) -> str:
    """``s`` as text that UTF-8 can hold: a lone surrogate made valid.

    Under a C/POSIX locale with UTF-8 mode off (``LC_ALL=C PYTHONUTF8=0``), Python decodes
    the command line and file names as ASCII with ``surrogateescape``, so "Müller" arrives
    as ``"M\\udcc3\\udcbcller"``: written as it is, such text crashes a strict UTF-8
    write (``surrogates not allowed``) or goes into a JSON file as lone surrogates (mojibake
    for its readers, refused by strict parsers).  Those escaped bytes are turned back into
    the bytes they stood for and decoded as UTF-8, which restores the original text
    ("Müller"); bytes that are not UTF-8, and any other lone surrogate, become U+FFFD.
    Text without surrogates is returned as it is.
    """
    try:
        s.encode("utf-8")
        return s
    except UnicodeEncodeError:
        pass
    # a surrogate outside U+DC80-U+DCFF stands for no byte (surrogateescape refuses it): one
    # U+FFFD each, the escaped bytes beside it still restored
    s = "".join("\ufffd" if "\ud800" <= c <= "\udfff" and not "\udc80" <= c <= "\udcff"
                else c for c in s)
    return s.encode("utf-8", "surrogateescape").decode("utf-8", "replace")


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8, :func:`utf8_text`) to ``path`` atomically (:func:`replacing`);
    returns ``path``."""
    text = utf8_text(text)
    with replacing(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_csv_atomic(path: str | os.PathLike, fieldnames: Sequence[str],
                     rows: Iterable[Mapping[str, Any]]) -> Path:
    """``rows`` as CSV (UTF-8, a header line) at ``path``, atomically
    (:func:`write_text_atomic`); keys not in ``fieldnames`` are ignored, and a missing key,
    None, NaN or an infinity gives an empty field."""
    def cell(v: Any) -> Any:
        return "" if v is None or (isinstance(v, float) and not math.isfinite(v)) else v

    buf = io.StringIO(newline="")
    # "\n" rows: write_text makes them the platform's line ends (csv's "\r\n" became
    # "\r\r\n" on Windows)
    w = csv.DictWriter(buf, fieldnames=list(fieldnames), extrasaction="ignore",
                       lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({c: cell(r.get(c)) for c in fieldnames})
    return write_text_atomic(path, buf.getvalue())


def json_ready(x: Any) -> Any:
    """Nested dicts, lists, tuples and numpy arrays (as nested lists) with numpy scalars as
    Python numbers and non-finite floats as None: what standard JSON can hold (NaN and
    Infinity are not JSON; many parsers outside Python refuse them), and strings (values
    and keys) as valid text (:func:`utf8_text`: a path given under ``LC_ALL=C PYTHONUTF8=0``
    holds lone surrogates)."""
    if isinstance(x, str):
        return utf8_text(x)
    if isinstance(x, dict):
        return {json_ready(k) if isinstance(k, str) else k: json_ready(v)
                for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_ready(v) for v in x]
    if isinstance(x, np.ndarray):
        # tolist gives Python scalars (nested lists), whose non-finite floats the float
        # branch below then makes None; json.dumps refuses the array itself
        return json_ready(x.tolist())
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x


#: The key of a result file that names the bayespilot release that wrote it.
VERSION_KEY = "bayespilot_version"


def dumps(obj: Any, *, version: bool = True) -> str:
    """The standard JSON text of a result's ``to_dict()``: NaN, +inf and -inf as null
    (:func:`json_ready`; standard JSON has no token for them).

    The package's convention: a null in a result file is NaN, or a non-finite number (+inf
    or -inf, its sign not kept) written where a finite one was expected; a reader's
    ``from_dict`` makes it NaN (:func:`number`, :func:`nan_for_null`).  A field whose None
    is a value of its own (e.g. the ln BF of a Savage-Dickey estimate that is not valid)
    reads a null as None.  The exception: the diagnosis files keep +inf and -inf, apart
    from a missing value, as the strings ``"inf"`` and ``"-inf"``, through
    :func:`bayespilot.diagnose.decide.json_number` (before this function sees them): the
    ranking (``CandidateResult.to_dict``), the single-run ``chosen``
    (``DiagnosisResult.to_dict``) and a shared posterior's ``log_density``
    (``SharedPosterior.to_dict``).  :func:`number` reads them back as infinities, in
    whichever file it meets them.

    A dict is written with :data:`VERSION_KEY`, the release that wrote it (readers ignore
    it), so that a result file says which code made its numbers; ``version=False`` leaves
    it out (a dict whose keys are all of one kind, such as a posterior's summary by
    parameter).
    """
    if version and isinstance(obj, Mapping) and VERSION_KEY not in obj:
        from . import __version__

        obj = {**obj, VERSION_KEY: __version__}
    return json.dumps(json_ready(obj), indent=1, allow_nan=False)


def number(v: Any) -> float:
    """A number as a result file holds it, as a float.

    Null is NaN: a null stands for NaN, or for a non-finite number written where a finite
    one was expected (:func:`dumps` writes both as null and keeps no sign), so NaN is all a
    reader can restore.  The strings ``"inf"`` and ``"-inf"`` are +inf and -inf, wherever
    they are read: the diagnosis files write an infinity so (apart from a missing value),
    through :func:`bayespilot.diagnose.decide.json_number`, in the ranking
    (``CandidateResult.to_dict``, e.g. an infinite delta BIC), the single-run ``chosen``
    (``DiagnosisResult.to_dict``) and a shared posterior's ``log_density``
    (``SharedPosterior.to_dict``).
    """
    return math.nan if v is None else float(v)


def numbers(d: Mapping[str, Any] | None) -> dict[str, float]:
    """A result file's dict of numbers (name -> :func:`number`); {} for null."""
    return {k: number(v) for k, v in (d or {}).items()}


def read_json(path: str | os.PathLike, what: str) -> dict[str, Any]:
    """The JSON object in the file ``path``, or a ValueError that names the file and says it
    is not ``what`` (a result file of another kind, or not JSON)."""
    path = Path(path)
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path} is not a JSON file ({exc})") from None
    if not isinstance(d, dict):
        raise ValueError(f"{path} holds a JSON {type(d).__name__}, not {what}")
    return d


class WrongKind(ValueError):
    """A ``from_dict`` refusing a dict of another kind of result; :func:`read_result` names
    the file in front of the message."""


def require_keys(d: Mapping[str, Any], keys: Iterable[str], what: str) -> None:
    """Refuse (:class:`WrongKind`) a result file's dict that lacks any of ``keys``: another
    kind of file than ``what`` (e.g. "a fit result"), naming what is missing and what it has."""
    missing = [k for k in keys if k not in d]
    if missing:
        raise WrongKind(f"not {what}: no {', '.join(missing)} (this one has "
                        f"{', '.join(list(d)[:6]) or 'nothing'})")


def read_result(path: str | os.PathLike, from_dict: Any, what: str) -> Any:
    """``from_dict`` of the JSON object in the file ``path`` (``what``: the kind of result, for
    messages); a dict of another kind is a ValueError that names the file."""
    d = read_json(path, what)
    try:
        return from_dict(d)
    except WrongKind as exc:
        raise ValueError(f"{path}: {exc}") from None


def dataclass_fields(cls: type, d: Mapping[str, Any], what: str) -> dict[str, Any]:
    """The entries of a result file's dict ``d`` that are fields of the dataclass ``cls``.

    A key ``cls`` does not have (a field a later release added) is left out, so that an
    older reader still loads a newer file; a field without a default that ``d`` lacks is
    refused (:class:`WrongKind`, naming it and ``what``), not a TypeError from ``cls``.
    """
    fields = dataclasses.fields(cls)
    require_keys(d, [f.name for f in fields if f.default is dataclasses.MISSING
                     and f.default_factory is dataclasses.MISSING], what)
    names = {f.name for f in fields}
    return {k: v for k, v in d.items() if k in names}


def nan_for_null(cls: type, d: Mapping[str, Any]) -> dict[str, Any]:
    """``d`` with NaN for a null in each field of the dataclass ``cls`` annotated ``float``
    (as :func:`dumps` wrote a non-finite number; a field that may be None is annotated
    otherwise and keeps its None); without :data:`VERSION_KEY`, which is not a field."""
    floats = {f.name for f in dataclasses.fields(cls) if f.type in (float, "float")}
    return {k: (math.nan if v is None and k in floats else v) for k, v in d.items()
            if k != VERSION_KEY}

"""Writing result files so that an interrupted write never leaves half a file."""

from __future__ import annotations

import csv
import io
import json
import math
import os
import uuid
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence


def temporary_sibling(path: str | os.PathLike) -> Path:
    """A hidden file name beside ``path``, unique to this process and call (two writers of
    one path never share it)."""
    path = Path(path)
    return path.with_name(f".{path.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp")


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary sibling and a rename.

    Parent folders are created.  A reader sees the old file or the new one,
    never a truncated one (the rename is atomic on one file system); when the
    write fails (a full disk, ``path`` a folder) the old file is kept and the
    temporary one removed, and the OSError is raised.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temporary_sibling(path)
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_csv_atomic(path: str | os.PathLike, fieldnames: Sequence[str],
                     rows: Iterable[Mapping[str, Any]]) -> Path:
    """``rows`` as CSV (UTF-8, a header line) at ``path``, atomically
    (:func:`write_text_atomic`); keys not in ``fieldnames`` are ignored, and a missing key,
    None, NaN or an infinity gives an empty field."""
    def cell(v: Any) -> Any:
        return "" if v is None or (isinstance(v, float) and not math.isfinite(v)) else v

    buf = io.StringIO(newline="")
    w = csv.DictWriter(buf, fieldnames=list(fieldnames), extrasaction="ignore")
    w.writeheader()
    for r in rows:
        w.writerow({c: cell(r.get(c)) for c in fieldnames})
    return write_text_atomic(path, buf.getvalue())


def dumps(obj: Any) -> str:
    """The JSON text of a result's ``to_dict()`` (NaN allowed, as Python's json writes it)."""
    return json.dumps(obj, indent=1, allow_nan=True)

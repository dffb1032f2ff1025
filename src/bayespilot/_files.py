"""Writing result files so that an interrupted write never leaves half a file."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import uuid
from pathlib import Path
from typing import Any, Iterable, Iterator, Mapping, Sequence


def temporary_sibling(path: str | os.PathLike) -> Path:
    """A hidden file name beside ``path``, unique to this process and call (two writers of
    one path never share it)."""
    path = Path(path)
    return path.with_name(f".{path.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp")


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


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`replacing`); returns ``path``."""
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


def dumps(obj: Any) -> str:
    """The JSON text of a result's ``to_dict()`` (NaN allowed, as Python's json writes it)."""
    return json.dumps(obj, indent=1, allow_nan=True)

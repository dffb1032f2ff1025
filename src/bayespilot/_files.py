"""Writing result files so that an interrupted write never leaves half a file."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary sibling and a rename.

    Parent folders are created.  A reader sees the old file or the new one,
    never a truncated one (the rename is atomic on one file system).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)
    return path


def dumps(obj: Any) -> str:
    """The JSON text of a result's ``to_dict()`` (NaN allowed, as Python's json writes it)."""
    return json.dumps(obj, indent=1, allow_nan=True)

"""Atomic writes (bayespilot._files): a failed write keeps the old file and leaves no temporary
file behind; two writers never share a temporary name."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from bayespilot._files import temporary_sibling, write_text_atomic


def _half_then_full(self, text, *a, **k):  # half the text written, then the disk is full
    with open(self, "w", encoding="utf-8") as fh:
        fh.write(text[: len(text) // 2])
    raise OSError(28, "No space left on device")


def _failing_rename(src, dst):
    raise OSError(18, "Invalid cross-device link")


@pytest.mark.parametrize("where, name, broken", [(Path, "write_text", _half_then_full),
                                                 (os, "replace", _failing_rename)])
def test_a_failed_write_keeps_the_old_file_and_no_temporary(tmp_path, monkeypatch, where, name,
                                                            broken):
    """A full disk half-way through, or a rename that fails: the old file is kept and no
    temporary file is left (a fixed r.json.tmp was left behind)."""
    target = tmp_path / "r.json"
    write_text_atomic(target, '{"old": 1}')
    monkeypatch.setattr(where, name, broken)
    with pytest.raises(OSError):
        write_text_atomic(target, '{"new": 2}')
    monkeypatch.undo()
    assert target.read_text() == '{"old": 1}'
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]


def test_a_folder_in_the_way_is_an_error_and_leaves_nothing(tmp_path):
    (tmp_path / "out.json").mkdir()
    with pytest.raises(OSError):
        write_text_atomic(tmp_path / "out.json", "{}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]


def test_temporary_names_are_unique_hidden_siblings(tmp_path):
    a, b = temporary_sibling(tmp_path / "x.nc"), temporary_sibling(tmp_path / "x.nc")
    assert a != b and a.parent == tmp_path and a.name.startswith(".x.nc.")
    assert str(os.getpid()) in a.name and a.suffix == ".tmp"


def test_csv_rows_with_empty_fields_for_missing_values(tmp_path):
    """None, NaN and infinities are empty fields (the campaign summary wrote 'nan' where its
    docstring promised an empty field); other keys are ignored; written atomically."""
    import csv
    import math

    from bayespilot._files import write_csv_atomic

    path = write_csv_atomic(tmp_path / "s.csv", ["a", "b", "c"],
                            [{"a": 1.5, "b": math.nan, "c": None, "x": 9},
                             {"a": math.inf, "b": "t"}])
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    assert rows == [["a", "b", "c"], ["1.5", "", ""], ["", "t", ""]]
    assert b"\r" not in path.read_bytes() or os.linesep == "\r\n"  # one line end per row
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.csv"]

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


def test_results_are_standard_json_and_read_back_with_their_nans(tmp_path):
    """Non-finite numbers are written as null (NaN and Infinity are not JSON: a strict
    parser refused a comparison's Savage-Dickey densities and a short chain's r_hat), and a
    result's float fields read back as NaN; a field that may be None keeps its None."""
    import json
    import math

    import numpy as np

    from bayespilot._files import dumps
    from bayespilot.compare import SavageDickey
    from bayespilot.fit.result import FitResult

    def strict(text):
        return json.loads(text, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))

    fit = FitResult({"K_v": 1.5, "delta_abs": 0.0}, -10.0, 90.0, "fast", 3, True,
                    {"x": np.float64(np.inf)}, {"scan": [1.0, math.nan]})
    text = dumps(fit.to_dict())
    d = strict(text)
    assert d["elapsed_seconds"] is None and d["settings"]["x"] is None
    back = FitResult.from_dict(d)
    assert math.isnan(back.elapsed) and back.params == fit.params
    sd = SavageDickey(None, False, "no draws near 0", None, 2.0, math.nan, math.nan, 100, 0)
    again = strict(dumps(sd.to_dict()))
    from bayespilot._files import nan_for_null
    got = SavageDickey(**nan_for_null(SavageDickey, again))
    assert got.log_bayes_factor is None and got.lower_bound is None
    assert math.isnan(got.posterior_density) and math.isnan(got.bandwidth)
    assert got.prior_density == 2.0


def test_result_readers_name_a_file_of_another_kind(tmp_path):
    """A recording's sidecar, a CSV or a missing file given to a result reader: a ValueError
    (FileNotFoundError) that names the file, not a KeyError, a JSONDecodeError or h5py's
    "file signature not found"."""
    import json

    from bayespilot.compare import Comparison, PooledComparison
    from bayespilot.fit.result import FitResult
    from bayespilot.sample import Posterior

    side = tmp_path / "run.json"
    side.write_text(json.dumps({"format": "bayespilot-recording/1", "sample_rate_hz": 100.0}))
    csv = tmp_path / "run.csv"
    csv.write_text("t,u\n0,1\n")
    with pytest.raises(ValueError, match=r"run.json: not a fit result: no params, neg_log_lik, "
                                         r"vaf, method .*this one has format, sample_rate_hz"):
        FitResult.from_json(side)
    with pytest.raises(ValueError, match="run.json: not a comparison: no log_bayes_factor"):
        Comparison.from_json(side)
    with pytest.raises(ValueError, match="run.json: not a pooled comparison: no n, "
                                         "log_bayes_factor"):
        PooledComparison.from_json(side)
    for read in (FitResult.from_json, Comparison.from_json):
        with pytest.raises(ValueError, match="run.csv is not a JSON file"):
            read(csv)
    with pytest.raises(ValueError, match="run.json: not a netCDF file written by "
                                         "Posterior.to_netcdf"):
        Posterior.from_netcdf(side)
    with pytest.raises(FileNotFoundError, match="missing.nc"):
        Posterior.from_netcdf(tmp_path / "missing.nc")


def test_a_result_file_names_the_release_that_wrote_it():
    """Every result dict written is stamped with the bayespilot version (a reader of a file
    from last year can tell which code made its numbers); readers ignore the key; a dict
    keyed by one kind (a posterior's summary by parameter) can be written without it."""
    import json

    import bayespilot
    from bayespilot._files import VERSION_KEY, dumps, nan_for_null
    from bayespilot.compare import SavageDickey
    from bayespilot.fit.result import FitResult

    fit = FitResult({"K_v": 1.5}, -10.0, 90.0, "fast", 3, False)
    d = json.loads(dumps(fit.to_dict()))
    assert VERSION_KEY == "bayespilot_version" and d[VERSION_KEY] == bayespilot.__version__
    assert FitResult.from_dict(d).to_dict() == fit.to_dict()
    assert VERSION_KEY not in json.loads(dumps(fit.to_dict(), version=False))
    assert json.loads(dumps({VERSION_KEY: "0.0.1"})) == {VERSION_KEY: "0.0.1"}  # (kept)
    assert json.loads(dumps([1, 2])) == [1, 2]  # (only a dict has keys to stamp)
    sd = SavageDickey(None, False, "no draws near 0", None, 2.0, 1.0, 0.1, 100, 0)
    assert SavageDickey(**nan_for_null(SavageDickey, json.loads(dumps(sd.to_dict())))) == sd

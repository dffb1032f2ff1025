"""A full disk (ENOSPC) while bayespilot writes (audit of a full disk, findings 1-3): a clean
OSError or CampaignError of one line, no temporary file left, an earlier good file kept as it
was, no folder of mixed results.

The full disk is simulated (CI is not root, no tmpfs): the byte write of a temporary file, a
figure's save or a table's write raises ``OSError(ENOSPC)`` after writing part of its bytes.
"""

from __future__ import annotations

import csv
import dataclasses
import errno
import json
import os
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.figure  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from bayespilot import campaign as C  # noqa: E402
from bayespilot.campaign import CampaignError  # noqa: E402
from bayespilot.io import write_recording  # noqa: E402
from bayespilot.recording import Recording  # noqa: E402
from bayespilot.simulate import simulate  # noqa: E402

FULL = os.strerror(errno.ENOSPC)  # "No space left on device"


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _full_disk(path, data: bytes = b"") -> None:
    """Write the first bytes of ``data`` (at most 4 KiB) to ``path``, then fail as a full disk."""
    with open(path, "wb") as fh:
        fh.write(data[:4096] or b"\x89PNG")
    raise OSError(errno.ENOSPC, FULL, str(path))


def _left(folder: Path) -> list[str]:
    """The hidden (temporary) files in ``folder``."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def _fail_text_write(monkeypatch, prefix: str) -> None:
    """Path.write_text of a file whose name starts with ``prefix`` fails as a full disk."""
    real = Path.write_text

    def write_text(self, data, *args, **kwargs):
        if self.name.startswith(prefix):
            _full_disk(self, data.encode())
        return real(self, data, *args, **kwargs)

    monkeypatch.setattr(Path, "write_text", write_text)


# --- F1: the netCDF posterior ---------------------------------------------------------------------
from test_result_files import _Chain  # noqa: E402  (a fake emcee sampler)


def _posterior():
    from bayespilot.sample import Posterior, _to_idata

    names = ["K_v", "tau_v", "delta_abs"]
    tau = {"K_v": 3.0, "tau_v": float("nan"), "delta_abs": 5.0}
    meta = {"parameter_names": names, "tau": tau, "converged": False, "seed": 11,
            "settings": {"likelihood": "coloured", "n_steps": 60, "ar": "profiled",
                         "tau_history": [[20, 2.5], [40, float("nan")]],
                         "true_parameters": {"K_v": 0.4}}}
    idata, meta = _to_idata(_Chain((60, 8, 3), seed=7, scale=0.05, centre=0.4), names, np.array([3.0, 4.0, 5.0]), meta,
                            {"K_v": "-", "tau_v": "s", "delta_abs": "IPUT"})
    return Posterior(idata, tuple(names), tau, False, meta["settings"], 11)


def _old_way(post, path):
    """The file as ``Posterior.to_netcdf`` wrote it before (arviz writing HDF5 to the path
    itself): the independent reference of the file's contents."""
    from bayespilot.sample import _arviz, _set_meta_attrs

    meta = {"parameter_names": list(post.parameter_names), "tau": dict(post.tau),
            "converged": bool(post.converged), "settings": dict(post.settings), "seed": post.seed}
    idata = _arviz().InferenceData(**{g: getattr(post.idata, g).copy(deep=False)
                                      for g in post.idata.groups()})
    _set_meta_attrs(idata, meta)
    idata.to_netcdf(str(path))


def _contents(path):
    """Every group and variable of an HDF5 file: attributes (values and types), dtype, shape,
    chunks, filters, fill value and data; dimension references by their shape."""
    import h5py

    def attrs(obj):
        return {k: (np.asarray(v).shape if k in ("DIMENSION_LIST", "REFERENCE_LIST")
                    else (repr(v), type(v).__name__)) for k, v in obj.attrs.items()}

    out = {}
    with h5py.File(path, "r") as f:
        out["/"] = (attrs(f), list(f))

        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                out[name] = (attrs(obj), str(obj.dtype), obj.shape, obj.chunks, obj.compression,
                             obj.compression_opts, obj.shuffle, repr(obj.fillvalue),
                             np.asarray(obj[()]).tobytes())
            else:
                out[name] = (attrs(obj), list(obj))

        f.visititems(visit)
    return out


def test_posterior_netcdf_is_built_in_memory_and_reads_back_as_before(tmp_path, monkeypatch):
    """HDF5 never writes the file itself (on a full disk it failed part-way: h5py
    RuntimeErrors, a segmentation fault); the file holds exactly what the old way wrote, and
    the same bytes run to run."""
    import arviz as az
    import h5py

    from bayespilot.sample import _META_ATTR, Posterior

    post = _posterior()
    _old_way(post, tmp_path / "old.nc")
    real = h5py.File.__init__

    def no_hdf5_file_writes(self, name, mode="r", *args, **kwargs):
        if isinstance(name, (str, bytes, os.PathLike)) and mode != "r":
            raise AssertionError(f"HDF5 writes the file {name} itself")
        real(self, name, mode, *args, **kwargs)

    with monkeypatch.context() as m:
        m.setattr(h5py.File, "__init__", no_hdf5_file_writes)
        assert post.to_netcdf(tmp_path / "new.nc") == tmp_path / "new.nc"
        post.to_netcdf(tmp_path / "again.nc")
    assert (tmp_path / "new.nc").read_bytes() == (tmp_path / "again.nc").read_bytes()
    assert _contents(tmp_path / "new.nc") == _contents(tmp_path / "old.nc")
    old, new = Posterior.from_netcdf(tmp_path / "old.nc"), Posterior.from_netcdf(tmp_path / "new.nc")
    for f in ("parameter_names", "converged", "seed"):
        assert getattr(new, f) == getattr(old, f) == getattr(post, f)
    assert json.dumps(new.settings) == json.dumps(old.settings)  # (NaN in tau_history kept)
    assert new.settings["tau_history"][1][0] == 40 and np.isnan(new.settings["tau_history"][1][1])
    assert new.tau["K_v"] == 3.0 and np.isnan(new.tau["tau_v"])
    for g in ("posterior", "sample_stats"):
        a, b = getattr(old.idata, g), getattr(new.idata, g)
        assert a.attrs == b.attrs and a.attrs[_META_ATTR]
        for v in a.data_vars:
            np.testing.assert_array_equal(b[v].values, a[v].values)
            assert b[v].attrs == a[v].attrs
    np.testing.assert_array_equal(new.draws("K_v"), post.draws("K_v"))
    assert new.idata.posterior["delta_abs"].attrs["units"] == "IPUT"
    read = az.from_netcdf(str(tmp_path / "new.nc"))
    assert read.groups() == ["posterior", "sample_stats"]
    np.testing.assert_array_equal(read.sample_stats["lp"].values,
                                  post.idata.sample_stats["lp"].values)


def test_posterior_netcdf_on_a_full_disk_is_one_clean_oserror(tmp_path, monkeypatch):
    """The bytes' write fails part-way (ENOSPC): an OSError of one line, the earlier file
    kept byte for byte, no temporary file left."""
    post = _posterior()
    path = tmp_path / "post.nc"
    post.to_netcdf(path)
    good = path.read_bytes()
    changed = dataclasses.replace(post, seed=12)

    with monkeypatch.context() as m:
        m.setattr(Path, "write_bytes", lambda self, data: _full_disk(self, data))
        with pytest.raises(OSError) as caught:
            changed.to_netcdf(path)
    assert caught.value.errno == errno.ENOSPC and caught.value.strerror == FULL
    assert "\n" not in str(caught.value)
    assert path.read_bytes() == good
    assert sorted(p.name for p in tmp_path.iterdir()) == ["post.nc"]
    # a new file that cannot be written leaves nothing
    with monkeypatch.context() as m:
        m.setattr(Path, "write_bytes", lambda self, data: _full_disk(self, data))
        with pytest.raises(OSError, match=FULL):
            changed.to_netcdf(tmp_path / "other.nc")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["post.nc"]


# --- F2: a batch's summary tables and figure ------------------------------------------------------
FAST = {"n_starts": 1, "profile_step": 0.02}
QUIET = {"method": "fast", "fit_options": FAST, "progress": False, "warm_cache": False}


def _write(folder, name, *, seed):
    rec = simulate(task="FD", motion_gain=1.0, remnant_gain=0.07, seed=seed,
                   duration=20.0).recording
    os.makedirs(folder, exist_ok=True)
    write_recording(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task,
                              {"subject": "s1"}), folder / name)
    return str(folder / name)


@pytest.fixture(scope="module")
def recs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("recs")
    return [_write(folder, "a", seed=1), _write(folder, "b", seed=2)]


def _run_here(monkeypatch):
    """The batch's tasks run in this process (run_keyed replaced, no cluster)."""
    def run_keyed(tasks, out, *, to_json, **kwargs):
        for key, fn, args, _ in tasks:
            C._write_json_atomic(out / f"{key}.json", to_json(key, fn(*args)))
        return len(tasks), {}

    monkeypatch.setattr(C, "run_keyed", run_keyed)


def _keys(table):
    with open(table, newline="", encoding="utf-8") as fh:
        return [r["key"] for r in csv.DictReader(fh)]


def test_fit_batch_summary_on_a_full_disk(recs, tmp_path, monkeypatch):
    """The figure's save fails (ENOSPC) after the new tables: a CampaignError of one line that
    names the folder, says the results are saved and to run again; no figure of the earlier
    results beside the new tables; run again, the figure is written, nothing refitted."""
    from bayespilot.batch import fit_batch

    _run_here(monkeypatch)
    out = tmp_path / "out"
    fit_batch(recs[:1], out, **QUIET)
    assert (out / "summary.png").is_file() and _keys(out / "summary.csv") == ["a"]
    with monkeypatch.context() as m:
        m.setattr(matplotlib.figure.Figure, "savefig",
                  lambda self, fname, *a, **k: _full_disk(fname))
        with pytest.raises(CampaignError) as caught:
            fit_batch(recs, out, **QUIET)
    said = str(caught.value)
    assert "\n" not in said
    assert said == (f"{out}: cannot write the summary tables and figure ({FULL}); each "
                    f"recording's result is saved there: run the same command again to write "
                    f"them")
    assert (out / "b.json").is_file() and _keys(out / "summary.csv") == ["a", "b"]
    assert not (out / "summary.png").exists()  # (it showed a alone)
    assert _left(out) == []
    again = fit_batch(recs, out, **QUIET)
    assert (again.completed, again.skipped) == (0, 2)
    assert (out / "summary.png").read_bytes().startswith(b"\x89PNG\r\n")


def test_diagnose_batch_summary_on_a_full_disk(recs, diagnosis, tmp_path, monkeypatch):
    """The table's write fails (ENOSPC): a CampaignError of one line, the earlier table kept,
    the earlier figure (of other diagnoses) removed, not left beside the new results."""
    import bayespilot.diagnose.batch as B
    from bayespilot.diagnose.batch import diagnose_batch

    def run_keyed(tasks, out, **kwargs):  # (no diagnosis run: another one's stored for each)
        for key, _, _, context in tasks:
            C._write_json_atomic(out / f"{key}.json",
                                 {"key": key, **context, "diagnosis": diagnosis.to_dict()})
        return len(tasks), {}

    monkeypatch.setattr(C, "run_keyed", run_keyed)
    out = tmp_path / "out"
    out.mkdir()
    earlier = ",".join(B.SUMMARY_FIELDS) + "\n"  # (an earlier batch's table, no row)
    (out / "summary.csv").write_text(earlier, encoding="utf-8")
    (out / "summary.png").write_bytes(b"\x89PNG of other diagnoses")
    _fail_text_write(monkeypatch, ".summary.csv.")  # (the table's temporary file)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(CampaignError) as caught:
            diagnose_batch(recs, out, progress=False, warm_cache=False, n_bootstrap=0,
                           candidates=["motion-washout"])
    said = str(caught.value)
    assert "\n" not in said
    assert said == (f"{out}: cannot write the summary table and figure ({FULL}); each "
                    f"diagnosis is saved there: run the same command again to write them")
    assert (out / "summary.csv").read_text(encoding="utf-8") == earlier
    assert not (out / "summary.png").exists()
    assert sorted(p.name for p in out.glob("*.json")) == ["a.json", "b.json"]


# --- F3: a diagnosis report -----------------------------------------------------------------------
@pytest.fixture(scope="module")
def diagnosis():
    """A 25-s FT run diagnosed without a bootstrap on one candidate (a few seconds)."""
    from bayespilot.diagnose import diagnose

    rec = simulate(task="FT", motion_gain=1.0, remnant_gain=0.06, seed=31,
                   duration=25.0).recording
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return diagnose(rec, seed=0, n_bootstrap=0, n_starts=2, candidates=["motion-washout"])


def _fail_at(monkeypatch, n):
    """Figure saves from the ``n``-th on (1: the first) fail as a full disk."""
    real = matplotlib.figure.Figure.savefig
    calls = []

    def savefig(self, fname, *args, **kwargs):
        calls.append(fname)
        if len(calls) >= n:
            _full_disk(fname)
        return real(self, fname, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)


def test_a_report_that_fails_part_way_leaves_no_page_of_another_recording(diagnosis, tmp_path,
                                                                         monkeypatch):
    """Recording A's report, then B's fails at its second figure (a full disk): the folder
    holds B's first figure, so A's report.html and diagnosis.json are removed (not left to
    disagree with it) and the OSError says, in one line, that the report is incomplete."""
    out = tmp_path / "rep"
    diagnosis.report(out)
    assert f"Recording: {diagnosis.source}." in (out / "report.html").read_text(encoding="utf-8")
    other = dataclasses.replace(diagnosis, source="recs/other-run")
    with monkeypatch.context() as m:
        _fail_at(m, 2)
        with pytest.raises(OSError) as caught:
            other.report(out)
    assert caught.value.errno == errno.ENOSPC
    assert str(caught.value.strerror) == (f"{FULL}; the report in {out} is incomplete, without "
                                          f"report.html: run again once it can be written")
    assert "\n" not in str(caught.value)
    names = sorted(p.name for p in out.iterdir())
    assert "report.html" not in names and "diagnosis.json" not in names
    assert "residuals.png" in names and _left(out) == [".bayespilot-report.json"]
    # run again: a whole report of B
    other.report(out)
    assert "Recording: recs/other-run" in (out / "report.html").read_text(encoding="utf-8")
    assert json.loads((out / "diagnosis.json").read_text())["source"] == "recs/other-run"


def test_a_report_whose_page_fails_keeps_its_own_json_only(diagnosis, tmp_path, monkeypatch):
    """The page's write fails (every figure and diagnosis.json of B written): A's report.html
    is removed, B's diagnosis.json kept (it agrees with the figures)."""
    out = tmp_path / "rep"
    diagnosis.report(out)
    other = dataclasses.replace(diagnosis, source="recs/other-run")
    _fail_text_write(monkeypatch, ".report.html.")  # (the page's temporary file)
    with pytest.raises(OSError, match="incomplete, without report.html"):
        other.report(out)
    assert not (out / "report.html").exists() and _left(out) == [".bayespilot-report.json"]
    assert json.loads((out / "diagnosis.json").read_text())["source"] == "recs/other-run"


def test_a_report_that_fails_before_any_file_changed_keeps_the_earlier_one(diagnosis, tmp_path,
                                                                          monkeypatch):
    """A full disk at the first figure: the earlier report stays whole, byte for byte, and
    the error is the disk's, as it was."""
    out = tmp_path / "rep"
    diagnosis.report(out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    other = dataclasses.replace(diagnosis, source="recs/other-run")
    with monkeypatch.context() as m:
        _fail_at(m, 1)
        with pytest.raises(OSError) as caught:
            other.report(out)
    assert caught.value.strerror == FULL
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


# --- F5: the batches' check of the output folder --------------------------------------------------
def test_the_batches_refuse_a_full_disk_before_running(recs, tmp_path, monkeypatch):
    """On a full disk an empty file is still made (no data block), so the folder check must
    write a byte: refused before any task runs, in one line, and nothing is left."""
    import tempfile

    from bayespilot.batch import fit_batch
    from bayespilot.diagnose.batch import diagnose_batch

    def nothing_runs(*args, **kwargs):
        raise AssertionError("a task ran")

    class FullDiskFile:  # a file made (empty), whose bytes do not fit
        def __init__(self, fh):
            self.fh = fh

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

        def write(self, data):
            if data:
                raise OSError(errno.ENOSPC, FULL)
            return 0

        def flush(self):
            pass

        def close(self):
            self.fh.close()

    real_temporary = tempfile.TemporaryFile
    real_write_bytes, real_write_text = Path.write_bytes, Path.write_text

    def write_bytes(self, data):
        if data and ".bayespilot-write-check." in self.name:
            real_write_bytes(self, b"")
            raise OSError(errno.ENOSPC, FULL, str(self))
        return real_write_bytes(self, data)

    def write_text(self, data, *args, **kwargs):
        if data and ".bayespilot-write-check." in self.name:
            real_write_text(self, "")
            raise OSError(errno.ENOSPC, FULL, str(self))
        return real_write_text(self, data, *args, **kwargs)

    monkeypatch.setattr(C, "run_keyed", nothing_runs)
    monkeypatch.setattr(tempfile, "TemporaryFile",
                        lambda *a, **k: FullDiskFile(real_temporary(*a, **k)))
    monkeypatch.setattr(Path, "write_bytes", write_bytes)
    monkeypatch.setattr(Path, "write_text", write_text)
    for run, out in ((lambda out: fit_batch(recs, out, **QUIET), tmp_path / "fb"),
                     (lambda out: diagnose_batch(recs, out, progress=False, warm_cache=False,
                                                 n_bootstrap=0), tmp_path / "db")):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with pytest.raises(CampaignError) as caught:
                run(out)
        assert str(caught.value) == f"{out}: cannot write in the output folder ({FULL})"
        assert list(out.iterdir()) == []  # (the probe's file removed)

"""The files a diagnosis report writes, and how (audit of unusual environments, findings 3, 4, 6
and 13): a report removes only the figure files an earlier report wrote, never a file of the
user's that has a figure's name; every figure is replaced atomically; a legal long file name
stays writable; text with lone surrogates (argv under ``LC_ALL=C PYTHONUTF8=0``) is written as
the UTF-8 text it stood for."""

from __future__ import annotations

import base64
import dataclasses
import json
import os
import warnings

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from bayespilot._figstyle import save_figure  # noqa: E402
from bayespilot._files import (dumps, json_ready, temporary_sibling,  # noqa: E402
                               write_text_atomic)
from bayespilot.diagnose import diagnose  # noqa: E402
from bayespilot.diagnose import report as R  # noqa: E402
from bayespilot.simulate import simulate  # noqa: E402

#: "Müller" as Python's argv holds it under LC_ALL=C with UTF-8 mode off (surrogateescape).
ESCAPED = "M\udcc3\udcbcller"


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


@pytest.fixture(scope="module")
def short():
    """A 25-s FT run diagnosed without a bootstrap on one candidate (a few seconds): no
    evidence figure (no p-values), no describing function, nothing chosen (no posterior)."""
    rec = simulate(task="FT", motion_gain=1.0, remnant_gain=0.06, seed=31,
                   duration=25.0).recording
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return diagnose(rec, seed=0, n_bootstrap=0, n_starts=2, candidates=["motion-washout"])


def _draw():
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    return fig


# -- 3. only our own files are removed ----------------------------------------------------------


def test_a_report_leaves_the_users_files_of_figure_names(short, tmp_path):
    """A folder such as paper/ holding the user's posterior.pdf, evidence.png and
    residuals.svg: a report that draws no posterior nor evidence figure and no SVG leaves all
    three as they were (it deleted them); a figure file the previous report wrote and this
    one does not write is removed."""
    user = {"posterior.pdf": b"my posterior", "evidence.png": b"my evidence",
            "residuals.svg": b"<svg>mine</svg>"}
    for name, data in user.items():
        (tmp_path / name).write_bytes(data)
    first = short.report(tmp_path, formats=("pdf",))
    assert "evidence" not in first and "posterior" not in first
    for name, data in user.items():
        assert (tmp_path / name).read_bytes() == data, name
    assert first["residuals_pdf"].is_file() and first["candidates_pdf"].is_file()
    listed = json.loads(first["manifest"].read_text(encoding="utf-8"))["files"]
    assert set(listed) == {p.name for k, p in first.items()
                           if k not in ("json", "html", "manifest")}
    # again without PDFs: the previous report's PDFs go, the user's posterior.pdf stays
    again = short.report(tmp_path)
    assert not (tmp_path / "residuals.pdf").exists()
    assert not (tmp_path / "candidates.pdf").exists()
    for name, data in user.items():
        assert (tmp_path / name).read_bytes() == data, name
    assert set(tmp_path.iterdir()) == set(again.values()) | {tmp_path / n for n in user}


def test_a_stale_figure_is_removed_unless_changed_since(tmp_path):
    """A figure of an earlier report that this one does not draw is removed; one the user
    replaced since (the bytes differ from those the manifest records) is kept."""
    R._write_figures({"a": _draw, "b": _draw, "c": _draw}, tmp_path, ("png", "pdf"))
    (tmp_path / "c.pdf").write_bytes(b"the user's own c.pdf")
    paths = R._write_figures({"a": _draw, "b": None, "c": None}, tmp_path, ("png",))
    assert not (tmp_path / "b.png").exists() and not (tmp_path / "b.pdf").exists()
    assert not (tmp_path / "a.pdf").exists() and not (tmp_path / "c.png").exists()
    assert (tmp_path / "c.pdf").read_bytes() == b"the user's own c.pdf"
    assert sorted(p.name for p in tmp_path.iterdir()) == [R.MANIFEST, "a.png", "c.pdf"]
    assert paths["manifest"] == tmp_path / R.MANIFEST
    # an edited manifest cannot name a file outside the figures
    outside = tmp_path.parent / f"{tmp_path.name}-outside.png"
    outside.write_bytes(b"x")
    (tmp_path / "report.html").write_text("<title>bayespilot diagnosis</title>")
    (tmp_path / R.MANIFEST).write_text(json.dumps({"files": {
        f"../{outside.name}": R._digest(outside),
        "report.html": R._digest(tmp_path / "report.html")}}))
    R._write_figures({"a": _draw}, tmp_path, ("png",))
    assert outside.exists() and (tmp_path / "report.html").exists()


def test_a_folder_of_an_older_release_loses_only_embedded_pngs(tmp_path):
    """No manifest (a report of a release before it): only a PNG whose bytes the old
    report.html embeds is provably a figure of ours; any other file is left."""
    R._write_figures({"b": _draw}, tmp_path, ("png",))
    (tmp_path / R.MANIFEST).unlink()
    b64 = base64.b64encode((tmp_path / "b.png").read_bytes()).decode("ascii")
    (tmp_path / "report.html").write_text(
        f'<title>bayespilot diagnosis: x</title><img alt="b" src="data:image/png;base64,{b64}">')
    (tmp_path / "c.png").write_bytes(b"not in the page")
    (tmp_path / "b.pdf").write_bytes(b"%PDF- no page embeds it")
    R._write_figures({"a": _draw, "b": None, "c": None}, tmp_path, ("png",))
    assert not (tmp_path / "b.png").exists()
    assert (tmp_path / "c.png").read_bytes() == b"not in the page"
    assert (tmp_path / "b.pdf").exists()


# -- 4. atomic figures, page last -----------------------------------------------------------------


def test_save_figure_replaces_atomically(tmp_path, monkeypatch):
    """save_figure writes a temporary sibling (its format given, not taken from ".tmp") and
    renames it: a savefig that fails half-way (a full disk, an interrupt) leaves the old
    file whole and no temporary file."""
    target = tmp_path / "fig.png"
    target.write_bytes(b"the old figure")
    fig = _draw()
    real = type(fig).savefig
    seen = {}

    def half_then_interrupt(self, fname, *a, **k):
        seen.update(fname=fname, format=k.get("format"))
        with open(fname, "wb") as fh:
            fh.write(b"\x89PNG\r\n")  # a header only, as the audit found
        raise KeyboardInterrupt

    monkeypatch.setattr(type(fig), "savefig", half_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        save_figure(fig, target)
    assert target.read_bytes() == b"the old figure"
    assert [p.name for p in tmp_path.iterdir()] == ["fig.png"]
    assert os.fspath(seen["fname"]) != os.fspath(target) and seen["format"] == "png"
    monkeypatch.setattr(type(fig), "savefig", real)
    for name, head in (("fig.png", b"\x89PNG"), ("fig.pdf", b"%PDF-"), ("FIG.SVG", b"<?xml")):
        save_figure(fig, tmp_path / name)
        assert (tmp_path / name).read_bytes().startswith(head), name
    assert sorted(p.name for p in tmp_path.iterdir()) == ["FIG.SVG", "fig.pdf", "fig.png"]


def test_a_failed_figure_keeps_the_earlier_report(short, tmp_path, monkeypatch):
    """A report that fails while writing a figure leaves the earlier report's figure, page
    and result file as they were: the figures go first, each atomically, the page last."""
    short.report(tmp_path)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    import matplotlib.figure

    def fail(self, fname, *a, **k):
        with open(fname, "wb") as fh:
            fh.write(b"\x89PNG")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", fail)
    with pytest.raises(OSError):
        short.report(tmp_path)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


# -- 13. long names -------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["z" * 250 + ".json", "ü" * 125 + ".json", "y" * 255])
def test_a_legal_long_name_stays_writable(tmp_path, name):
    """A name of up to 255 bytes is legal; its temporary sibling (hidden, unique, in the same
    folder) must be too: it was ~22 bytes longer, "File name too long"."""
    assert len(os.fsencode(name)) <= 255
    a, b = temporary_sibling(tmp_path / name), temporary_sibling(tmp_path / name)
    assert a != b and a.parent == tmp_path and a.name.startswith(".") and a.suffix == ".tmp"
    assert len(os.fsencode(a.name)) <= 255
    write_text_atomic(tmp_path / name, "{}")
    assert (tmp_path / name).read_text() == "{}"
    assert [p.name for p in tmp_path.iterdir()] == [name]


def test_a_short_name_keeps_its_temporary_name(tmp_path):
    a = temporary_sibling(tmp_path / "x.nc")
    assert a.name.startswith(".x.nc.") and str(os.getpid()) in a.name


def test_temporary_names_follow_the_folders_name_max(tmp_path, monkeypatch):
    """The folder's PC_NAME_MAX is the limit where it is smaller than 255 (it was 255
    regardless); where pathconf cannot answer, 255.  A tail (a backup's ".bak.tmp") counts."""
    name = "\u00fc" * 100 + ".json"
    monkeypatch.setattr(os, "pathconf", lambda folder, key: 64)
    for tail in (".tmp", ".bak.tmp"):
        a = temporary_sibling(tmp_path / name, tail)
        assert len(os.fsencode(a.name)) <= 64 and a.name.endswith(tail) and a.name.isprintable()
    assert temporary_sibling(tmp_path / "x.nc").name.startswith(".x.nc.")

    def no_answer(folder, key):
        raise OSError("no answer")

    monkeypatch.setattr(os, "pathconf", no_answer)
    a = temporary_sibling(tmp_path / name)
    assert 64 < len(os.fsencode(a.name)) <= 255
    monkeypatch.delattr(os, "pathconf")  # as on Windows
    assert 64 < len(os.fsencode(temporary_sibling(tmp_path / name).name)) <= 255


# -- 6. lone surrogates -------------------------------------------------------------------------


def test_surrogate_escaped_text_is_written_as_utf8(tmp_path):
    """Text with argv's surrogate escapes is written as the UTF-8 it stood for (it raised
    "surrogates not allowed"), in a text file and in a result JSON (which held
    "\\udcc3\\udcbc"), keys included; other lone surrogates become U+FFFD."""
    path = write_text_atomic(tmp_path / "r.html", f"<p>{ESCAPED}</p>")
    assert path.read_text(encoding="utf-8") == "<p>Müller</p>"
    d = json.loads(dumps({"source": f"{ESCAPED}/Lauf 1", "runs": [ESCAPED], ESCAPED: 1}))
    assert d["source"] == "Müller/Lauf 1" and d["runs"] == ["Müller"] and d["Müller"] == 1
    assert json_ready("plain ü") == "plain ü"
    assert json_ready("a\ud800b") == "a\ufffdb"
    assert "\\udc" not in dumps({"source": ESCAPED})


def test_report_of_a_surrogate_escaped_source(short, tmp_path):
    """A diagnosis of a recording named on a C-locale command line: its report is written
    (report.html raised half-way), the page and diagnosis.json say "Müller"."""
    res = dataclasses.replace(short, source=f"/data/{ESCAPED}/run")
    paths = res.report(tmp_path)
    assert "/data/Müller/run" in paths["html"].read_text(encoding="utf-8")
    assert json.loads(paths["json"].read_text(encoding="utf-8"))["source"] == "/data/Müller/run"

"""Recordings and kernels in unusual environments: a read-only install, the C locale, long
file names, and files as other tools write them (audit of unusual environments, findings
6, 8, 13 and 14, suggestions 3 to 5)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from bayespilot._files import dumps, temporary_sibling, utf8_text
from bayespilot.io import FORMAT, read_recording, write_recording
from bayespilot.recording import Recording, RecordingError


def _rec(n: int = 50, rate: float = 100.0, **metadata) -> Recording:
    rng = np.random.default_rng(0)
    t = np.arange(n) / rate
    signals = {"t": t, "e": rng.normal(size=n), "u": rng.normal(size=n),
               "theta_ddot_m": rng.normal(size=n)}
    return Recording(signals, rate, 0.5, "FT", metadata)


# ---------------------------------------------------------------------------
# 8: no writable folder for numba's cache (a read-only install, an unwritable HOME)
# ---------------------------------------------------------------------------
# Every cache folder numba tries is refused as on a read-only file system (beside the
# sources, the user's cache folder), except those under ALLOWED (none if it is empty): numba
# then raised "cannot cache function ...: no locator available" at the kernels' import.
NO_CACHE_FOLDER = textwrap.dedent("""
    import os, warnings
    import numba.core.caching as caching

    allowed = os.environ["ALLOWED"]
    ensure = caching._CacheLocator.ensure_cache_path

    def read_only(self):
        path = os.path.abspath(self.get_cache_path())
        if not allowed or not path.startswith(allowed):
            raise PermissionError(30, "Read-only file system", path)
        ensure(self)

    caching._CacheLocator.ensure_cache_path = read_only
    warnings.simplefilter("always")
    with warnings.catch_warnings(record=True) as caught:
        from bayespilot import _jit
        from bayespilot.kernels import _blocks   # the package's kernels (import only)
        from kern import twice                   # one small kernel, compiled here
        print("result", twice(21.0))
    said = [str(w.message) for w in caught if "numba finds no writable folder" in str(w.message)]
    print("warnings", len(said))
    print("fallback", _jit._cache_fallback)
    print("NUMBA_CACHE_DIR", os.environ.get("NUMBA_CACHE_DIR", ""))
    print("said", said[0] if said else "")
""")
KERNEL = "from bayespilot._jit import njit\n\n@njit\ndef twice(x):\n    return 2.0 * x\n"


def _without_cache_folder(tmp_path: Path, allowed: str) -> dict[str, str]:
    (tmp_path / "kern.py").write_text(KERNEL)
    env = dict(os.environ, NUMBA_NUM_THREADS="1", ALLOWED=allowed,
               TMPDIR=str(tmp_path / "tmp"),
               PYTHONPATH=os.pathsep.join([str(tmp_path), *filter(None, [os.environ.get("PYTHONPATH")])]))
    env.pop("NUMBA_CACHE_DIR", None)
    (tmp_path / "tmp").mkdir(exist_ok=True)
    out = subprocess.run([sys.executable, "-c", NO_CACHE_FOLDER], env=env, cwd=tmp_path,
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    return dict(line.split(" ", 1) for line in out.stdout.splitlines())


def test_numba_cache_falls_back_to_a_private_temporary_folder(tmp_path):
    tmp = str(tmp_path / "tmp")  # as TMPDIR gives it
    got = _without_cache_folder(tmp_path, allowed=tmp)
    assert got["result"] == "42.0"
    assert got["warnings"] == "1", got
    assert got["fallback"] == "temporary"
    folder = Path(got["NUMBA_CACHE_DIR"])
    assert folder.parent == Path(tmp) and folder.name.startswith("bayespilot-numba-cache")
    assert f"caching them in {folder}" in got["said"] and "NUMBA_CACHE_DIR" in got["said"]
    assert list(folder.rglob("kern.twice-*.nbi")), "the kernel was not cached there"
    if hasattr(os, "getuid"):  # pickles are loaded from it: this user's alone
        assert folder.stat().st_mode & 0o077 == 0
    # the next process finds it again (one folder per user, not one per process)
    assert _without_cache_folder(tmp_path, allowed=tmp)["NUMBA_CACHE_DIR"] == str(folder)


def test_numba_compiles_without_cache_when_no_folder_is_writable(tmp_path):
    got = _without_cache_folder(tmp_path, allowed="")
    assert got["result"] == "42.0"
    assert got["warnings"] == "1", got
    assert got["fallback"] == "off"
    assert got["NUMBA_CACHE_DIR"] == ""  # the useless setting was taken back
    assert "compiling them anew" in got["said"]


def test_numba_cache_unchanged_where_numba_finds_a_folder():
    # the normal machine: numba's own choice, no setting made, no warning
    code = ("import os, warnings; warnings.simplefilter('error', RuntimeWarning);"
            "from bayespilot import _jit; from bayespilot.kernels import _blocks;"
            "print(_jit._cache_fallback, os.environ.get('NUMBA_CACHE_DIR'))")
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    env.pop("NUMBA_CACHE_DIR", None)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True, timeout=600)
    assert out.stdout.split() == ["None", "None"]


# ---------------------------------------------------------------------------
# 13: long file names
# ---------------------------------------------------------------------------
@pytest.mark.parametrize("stem", ["y" * 250, "\u00fc" * 125])  # 250 bytes: NAME.json is 255
def test_write_recording_with_the_longest_legal_names(tmp_path, stem):
    rec = _rec()
    csv_path, json_path = write_recording(rec, tmp_path / stem)
    assert len(os.fsencode(json_path.name)) == 255
    write_recording(rec, tmp_path / stem)  # again: the previous CSV's backup is long too
    assert np.array_equal(read_recording(tmp_path / stem).u, rec.u)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([csv_path.name, json_path.name])


def test_temporary_names_stay_within_255_bytes_and_unique(tmp_path):
    # (the one helper, _files.temporary_sibling, that write_recording uses too)
    for name in ["run.csv", "x" * 255, "\u00fc" * 127 + ".", "\u20ac" * 85]:
        names = {temporary_sibling(tmp_path / name).name for _ in range(20)}
        assert len(names) == 20
        for tmp in names:
            assert len(os.fsencode(tmp)) <= 255 and tmp.startswith(".") and tmp.endswith(".tmp")
            assert tmp.isprintable()  # never half a UTF-8 character
    assert re.fullmatch(rf"\.run\.csv\.{os.getpid()}-[0-9a-f]{{8}}\.tmp",
                        temporary_sibling(tmp_path / "run.csv").name)
    backup = temporary_sibling(tmp_path / ("x" * 255), ".bak.tmp").name
    assert len(os.fsencode(backup)) <= 255 and backup.endswith(".bak.tmp")


def test_write_recording_names_its_temporaries_by_the_shared_rule(tmp_path, monkeypatch):
    """write_recording's temporary and backup names are _files.temporary_sibling's: within
    the folder's PC_NAME_MAX (here said to be 100 bytes), the pid in them.  io had a second
    helper of its own (review 2026-11-29, finding 6)."""
    created = []
    real_open, real_link = os.open, os.link

    def spy_open(path, *args, **kwargs):
        created.append(Path(path).name)
        return real_open(path, *args, **kwargs)

    def spy_link(src, dst, *args, **kwargs):
        created.append(Path(dst).name)
        return real_link(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "pathconf", lambda folder, name: 100)
    monkeypatch.setattr(os, "open", spy_open)
    monkeypatch.setattr(os, "link", spy_link)
    stem = tmp_path / ("r" * 120)  # its files' names are legal here (255), longer than 100
    write_recording(_rec(), stem)
    write_recording(_rec(), stem)  # again: with a backup of the previous CSV
    temps = [n for n in created if n.endswith(".tmp")]
    assert len(temps) == 5 and sum(n.endswith(".bak.tmp") for n in temps) == 1
    for n in temps:
        assert len(os.fsencode(n)) <= 100 and f".{os.getpid()}-" in n
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r" * 120 + ".csv", "r" * 120 + ".json"]


# ---------------------------------------------------------------------------
# 6: text from the C locale (LC_ALL=C PYTHONUTF8=0): lone surrogates
# ---------------------------------------------------------------------------
def test_write_recording_decodes_surrogate_escaped_text(tmp_path):
    escaped = "M\u00fcller".encode().decode("ascii", "surrogateescape")  # as argv gives it
    assert escaped == "M\udcc3\udcbcller"
    rec = _rec(subject=escaped, notes="bad: \ud800", lab={"Gr\udcc3\udcbc\u00dfe": escaped})
    signals = dict(rec.signals, **{"kraft_" + escaped: rec.u})
    rec = Recording(signals, rec.sample_rate_hz, rec.motion_gain, rec.task, rec.metadata)
    csv_path, json_path = write_recording(rec, tmp_path / "run")
    doc = json.loads(json_path.read_bytes().decode("utf-8"))
    assert doc["subject"] == "M\u00fcller"
    assert doc["notes"] == "bad: \ufffd"  # a surrogate that escapes no byte: as json_ready
    assert doc["lab"] == {"Gr\u00fc\u00dfe": "M\u00fcller"}
    back = read_recording(tmp_path / "run")
    assert back.metadata["subject"] == "M\u00fcller"
    assert "kraft_M\u00fcller" in back.signals


def test_a_sidecar_and_a_result_file_spell_the_same_subject_the_same_way(tmp_path):
    """One normaliser of lone surrogates (_files.utf8_text): the recording's JSON and a result
    file agree, also for text with escaped bytes and a surrogate that escapes none (the
    sidecar wrote "M??ller ?", the result "Müller \ufffd"; review 2026-11-29, finding 5)."""
    subject = "M\udcc3\udcbcller \ud800"
    _, json_path = write_recording(_rec(subject=subject), tmp_path / "run")
    sidecar = json.loads(json_path.read_bytes().decode("utf-8"))["subject"]
    result = json.loads(dumps({"subject": subject}))["subject"]
    assert sidecar == result == utf8_text(subject) == "M\u00fcller \ufffd"


# ---------------------------------------------------------------------------
# 14: clearer refusals of CSV files as other tools write them
# ---------------------------------------------------------------------------
def _written(tmp_path: Path, rec: Recording | None = None) -> tuple[Path, str]:
    """A valid pair, and its CSV text."""
    write_recording(rec if rec is not None else _rec(), tmp_path / "run")
    return tmp_path / "run", (tmp_path / "run.csv").read_text()


@pytest.mark.parametrize("tail", ["   \n", "\t\n", " \r\n\n", "  "])
def test_trailing_line_of_blanks_accepted_like_an_empty_one(tmp_path, tail):
    stem, text = _written(tmp_path)
    (tmp_path / "run.csv").write_text(text + tail, newline="")
    assert np.array_equal(read_recording(stem).u, _rec().u)


def test_line_of_blanks_in_the_middle_is_named_blank(tmp_path):
    stem, text = _written(tmp_path)
    lines = text.splitlines(keepends=True)
    (tmp_path / "run.csv").write_text("".join(lines[:5] + [" \t \n"] + lines[5:]), newline="")
    with pytest.raises(RecordingError, match=r"run\.csv: line 6 is blank \(expected 4 fields\)"):
        read_recording(stem)


def test_lines_ending_in_cr_cr_lf_named(tmp_path):
    stem, text = _written(tmp_path)
    (tmp_path / "run.csv").write_bytes(text.replace("\n", "\r\r\n").encode())
    with pytest.raises(RecordingError, match=r"run\.csv: line 1 ends in \\r\\r\\n: stray "
                                             r"carriage returns"):
        read_recording(stem)
    # from line 7 on only (a file appended to): the line is named
    lines = text.splitlines(keepends=True)
    mixed = "".join(lines[:6]) + "".join(lines[6:]).replace("\n", "\r\r\n")
    (tmp_path / "run.csv").write_bytes(mixed.encode())
    with pytest.raises(RecordingError, match=r"line 7 ends in \\r\\r\\n: stray carriage"):
        read_recording(stem)


@pytest.mark.parametrize("first", ["sep=,", "sep=;", "SEP=,", "sep=\t"])
def test_excel_separator_line_gets_a_hint(tmp_path, first):
    stem, text = _written(tmp_path)
    (tmp_path / "run.csv").write_text(first + "\n" + text)
    with pytest.raises(RecordingError, match=r"run\.csv: the first line reads .*Excel's separator "
                                             r"hint: the format has no such line"):
        read_recording(stem)


def test_second_byte_order_mark_named(tmp_path):
    stem, text = _written(tmp_path)
    (tmp_path / "run.csv").write_bytes(b"\xef\xbb\xbf\xef\xbb\xbf" + text.encode())
    with pytest.raises(RecordingError, match=r"run\.csv: a byte-order mark \(U\+FEFF\) in the "
                                             r"header, column 1 .*second one"):
        read_recording(stem)
    (tmp_path / "run.csv").write_bytes(b"\xef\xbb\xbf" + text.encode())  # one BOM: fine
    read_recording(stem)


# ---------------------------------------------------------------------------
# suggestions 3 to 5
# ---------------------------------------------------------------------------
def _with_t(tmp_path: Path, rate: float, n: int, fmt) -> Path:
    """A pair whose t column is written as ``fmt(t)`` (the exporting tool's rounding)."""
    stem, text = _written(tmp_path, _rec(n=n, rate=rate))
    lines = text.splitlines()
    t = np.arange(n) / rate
    body = [fmt(tk) + line[line.index(","):] for tk, line in zip(t, lines[1:])]
    (tmp_path / "run.csv").write_text("\n".join([lines[0], *body]) + "\n")
    return stem


@pytest.mark.parametrize("rate, n, fmt, hint", [
    (120.0, 500, lambda x: f"{x:.3f}", r"t looks rounded to 0\.001 s \(written with 3 decimals\)"),
    (120.0, 1300, lambda x: f"{x:.5g}", r"t looks rounded to 5 significant digits \(0\.001 s"),
    (300.0, 500, lambda x: f"{x:.4f}", r"t looks rounded to 0\.0001 s"),
])
def test_rounded_t_gets_a_hint(tmp_path, rate, n, fmt, hint):
    stem = _with_t(tmp_path, rate, n, fmt)
    with pytest.raises(RecordingError, match=r"run\.csv: t is not uniformly spaced \(step .*\); "
                                             + hint + r".*: write t with more digits$"):
        read_recording(stem)


@pytest.mark.parametrize("edit", ["drop", "jitter"])
def test_no_rounding_hint_for_a_dropped_or_jittered_sample(tmp_path, edit):
    # a real defect, not the rounding: the one of t written with 3 decimals (which alone
    # would get the hint), the other jittered by 1 % of a step at full precision
    rate, n = 120.0, 500
    if edit == "drop":
        cells = [f"{tk:.3f}" for tk in np.delete(np.arange(n + 1) / rate, 200)]
    else:
        cells = [repr(float(tk)) for tk in np.arange(n) / rate + (np.arange(n) == 300) * 0.01 / rate]
    (tmp_path / "run.csv").write_text("t,e,u,theta_ddot_m\n" + "".join(f"{c},0,0,0\n" for c in cells))
    (tmp_path / "run.json").write_text(json.dumps(
        {"format": FORMAT, "sample_rate_hz": rate, "motion_gain": 0, "task": "other"}))
    with pytest.raises(RecordingError, match="t is not uniformly spaced") as info:
        read_recording(tmp_path / "run")
    assert "rounded" not in str(info.value)


def test_decimal_comma_in_quoted_cells_gets_a_hint(tmp_path):
    stem, text = _written(tmp_path)
    lines = text.splitlines()
    lines[3] = lines[3].split(",", 1)[0] + ',"0,5","1.234,5",' + lines[3].split(",", 3)[3]
    (tmp_path / "run.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(RecordingError, match=r"run\.csv: non-numeric value '0,5' in column 'e' at "
                                             r"line 4 \(a decimal comma\? .*'0\.5'"):
        read_recording(stem)


def test_integral_float_run_in_the_sidecar_read_as_an_integer(tmp_path):
    stem, _ = _written(tmp_path)
    doc = json.loads((tmp_path / "run.json").read_text())
    (tmp_path / "run.json").write_text(json.dumps({**doc, "run": 3.0}))
    run = read_recording(stem).metadata["run"]
    assert run == 3 and type(run) is int
    for bad in (3.5, True, "3"):  # still refused
        (tmp_path / "run.json").write_text(json.dumps({**doc, "run": bad}))
        with pytest.raises(RecordingError, match=r"run must be an integer"):
            read_recording(stem)

"""The command line's checks before a batch, at a lab's scale (findings 1, 3 and 6 of the scale
audit).

fit-batch and diagnose-batch check every file they may write against every file they read
(``cli._refuse_overwriting``) before every run, resumes included: the check compared each
output with each input and each earlier output, about 4 million comparisons and 2 minutes
for 720 recordings.  It now looks each file up once; the tests hold it to the pairwise rule
it replaced (``_pairwise`` below, the code it replaced) on files that are one under another
spelling, through a symlink or a hard link, and on missing files, and count its filesystem
calls for n and 2n recordings.  The keys the check needs are worked out by reading the
recordings (``cli._batch_keys``); the batch reads them again and says their warnings, so the
first read says none.
"""

from __future__ import annotations

import itertools
import os
import warnings
from pathlib import Path

import pytest

from bayespilot import cli
from bayespilot.cli import main


# --- the pairwise rule, as cli._refuse_overwriting applied it before --------------------------
def _pairwise_same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return os.path.realpath(a) == os.path.realpath(b)


def _pairwise(outputs, inputs) -> str | None:
    """The refusal of the quadratic check (its loops, verbatim), or None."""
    read = [(what, Path(path)) for what, path in inputs if path is not None]
    seen = []
    for option, path in outputs:
        if path is None:
            continue
        out = Path(path)
        for what, src in read:
            if _pairwise_same_file(out, src):
                said = what if out == src else f"{src}, {what}"
                return (f"argument {option}: {out} is {said}, which this command reads: "
                        f"writing it would destroy that input; give another file name")
        for other, earlier in seen:
            if _pairwise_same_file(out, earlier):
                return (f"argument {option}: {out} is also the file of {other}; give each "
                        f"output its own file name")
        seen.append((option, out))
    return None


def _refusal(outputs, inputs) -> str | None:
    try:
        cli._refuse_overwriting(outputs, inputs, recordings=False)
    except cli.UsageError as exc:
        return str(exc)
    return None


@pytest.fixture
def files(tmp_path):
    """A folder with one file under several names, and missing files under several names:
    ``a.json``; ``b.csv`` and its hard link ``hard.csv``; ``link.json`` -> ``a.json``;
    ``ln`` -> ``sub/`` (a folder); ``dangling.json`` -> the missing ``gone.json``."""
    d = tmp_path
    (d / "sub").mkdir()
    (d / "a.json").write_text("{}")
    (d / "b.csv").write_text("t\n0\n")
    os.link(d / "b.csv", d / "hard.csv")
    (d / "link.json").symlink_to(d / "a.json")
    (d / "ln").symlink_to(d / "sub", target_is_directory=True)
    (d / "dangling.json").symlink_to(d / "gone.json")
    return d


#: Spellings of files of ``files``, existing and missing.
SPELLINGS = ["a.json", "sub/../a.json", "link.json", "ln/../a.json", "b.csv", "hard.csv",
             "x.json", "sub/../x.json", "sub/y.json", "ln/y.json", "gone.json", "dangling.json",
             "ln", "sub"]


def test_the_refusals_are_the_pairwise_ones(files):
    """Every refusal (its message, naming the first input or output that is the same file)
    is the quadratic check's, for two outputs and two inputs among all the spellings."""
    paths = [files / s for s in SPELLINGS]
    for a, b in itertools.product(paths, repeat=2):  # (also diagnose's --report and --json)
        assert cli._same_file(a, b) == _pairwise_same_file(a, b), (a, b)
    refused = 0
    for out1, out2 in itertools.product(paths, repeat=2):
        outputs = [("--json", out1), ("--posterior", None), ("-o/--output", out2)]
        for in1, in2 in itertools.combinations_with_replacement([None, *paths], 2):
            inputs = [("the --params file", in1), ("the CSV of the recording REC r", in2)]
            expected = _pairwise(outputs, inputs)
            assert _refusal(outputs, inputs) == expected, (outputs, inputs)
            refused += expected is not None
    assert refused > 10000  # (most of the cases are refusals: the comparison has teeth)


def test_each_kind_of_same_file_is_refused(files):
    """The cases by name, with the messages written out."""
    a, sub_a = files / "a.json", files / "sub" / ".." / "a.json"
    params = [("the --params file", a)]
    reads = "which this command reads: writing it would destroy that input; give another file name"
    # another spelling, a symlink, a hard link, a symlinked folder
    assert _refusal([("--json", sub_a)], params) == (
        f"argument --json: {sub_a} is {a}, the --params file, {reads}")
    assert _refusal([("--json", files / "link.json")], params) == (
        f"argument --json: {files / 'link.json'} is {a}, the --params file, {reads}")
    assert _refusal([("--json", files / "hard.csv")], [("the CSV", files / "b.csv")]) == (
        f"argument --json: {files / 'hard.csv'} is {files / 'b.csv'}, the CSV, {reads}")
    assert _refusal([("--json", a)], params) == f"argument --json: {a} is the --params file, {reads}"
    # the first input that is the file is named
    assert _refusal([("--json", a)], [("first", files / "link.json"), ("second", a)]) == (
        f"argument --json: {a} is {files / 'link.json'}, first, {reads}")
    # missing files: by their resolved paths (a symlinked folder, a dangling symlink)
    assert _refusal([("--json", files / "ln" / "y.json")],
                    [("the --params file", files / "sub" / "y.json")]) is not None
    assert _refusal([("--json", files / "gone.json")],
                    [("the --params file", files / "dangling.json")]) is not None
    # two outputs, missing or not, that are one file; the first one's option is named
    own = "give each output its own file name"
    assert _refusal([("--json", files / "x.json"), ("--posterior", files / "y.json"),
                     ("-o/--output", files / "sub" / ".." / "x.json")], []) == (
        f"argument -o/--output: {files / 'sub' / '..' / 'x.json'} is also the file of --json; "
        f"{own}")
    assert _refusal([("--json", files / "b.csv"), ("--posterior", files / "hard.csv")], []) == (
        f"argument --posterior: {files / 'hard.csv'} is also the file of --json; {own}")
    # other files: taken
    assert _refusal([("--json", files / "x.json"), ("--posterior", files / "sub" / "x.json")],
                    [("the --params file", a), ("the CSV", files / "b.csv"), ("none", None)]) \
        is None


def _recordings_worth(root: Path, n: int):
    """fit-batch's outputs and inputs for ``n`` recordings, as _cmd_fit_batch gives them: each
    recording ``recs/rI`` (its .csv, .json and the .mat it would read instead) and its
    ``out/rI.json`` and ``out/rI.error.json``, every other .json written by an earlier run."""
    recs, out = root / "recs", root / "out"
    recs.mkdir(parents=True)
    out.mkdir()
    for i in range(n):
        (recs / f"r{i}.csv").write_text("t\n0\n")
        (recs / f"r{i}.json").write_text("{}")
        if i % 2:
            (out / f"r{i}.json").write_text('{"result": true}')
    inputs = [f for i in range(n) for f in cli._recording_files(str(recs / f"r{i}"))]
    outputs = [("--out", f) for f in [out / "summary.csv", out / "summary.png",
                                      *(out / f"r{i}{ext}" for i in range(n)
                                        for ext in (".json", ".error.json")),
                                      out / "conditions.csv"]]
    assert len(inputs) == 3 * n and len(outputs) == 2 * n + 3
    return outputs, inputs


def _filesystem_calls(monkeypatch, outputs, inputs) -> int:
    """The os.stat and os.lstat calls (Path.exists, samefile, realpath, ...) of the check."""
    calls = 0

    def counted(real):
        def call(*args, **kwargs):
            nonlocal calls
            calls += 1
            return real(*args, **kwargs)
        return call

    with monkeypatch.context() as m:
        for name in ("stat", "lstat"):
            m.setattr(os, name, counted(getattr(os, name)))
        cli._refuse_overwriting(outputs, inputs)
    return calls


def test_the_check_is_linear_in_the_files(tmp_path, monkeypatch):
    """Twice the recordings, about twice the filesystem calls (the pairwise check made four
    times as many: 4 million comparisons for 720 recordings)."""
    n = 20
    small = _filesystem_calls(monkeypatch, *_recordings_worth(tmp_path / "n", n))
    large = _filesystem_calls(monkeypatch, *_recordings_worth(tmp_path / "2n", 2 * n))
    assert small >= 5 * n  # (each of the 5 n files is looked at)
    assert large / small <= 2.2, (small, large)


# --- the recordings' warnings, said by the batch and not by the check before it --------------
@pytest.fixture(scope="module")
def short_recs(tmp_path_factory):
    """Two 10-s recordings: each read warns that it is far shorter than the paper's runs."""
    d = tmp_path_factory.mktemp("short")
    for stem, seed in (("s1-run1", 1), ("s1-run2", 2)):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            assert main(["simulate", "--subject", "s1", "--duration", "10", "--seed", str(seed),
                         "-o", str(d / stem), "-q"]) == 0
    return d


@pytest.mark.parametrize("command", ["fit-batch", "diagnose-batch"])
def test_the_check_says_no_recording_warning(short_recs, tmp_path, monkeypatch, capsys,
                                             command):
    """The check reads every recording for the batch's keys; the batch reads them again and
    says their QuestionableRecordingWarnings: the check's read says none (it said each short
    recording once more, one line each, on every run)."""
    import bayespilot.batch
    import bayespilot.diagnose.batch
    from bayespilot.io import read_recording
    from bayespilot.recording import QuestionableRecordingWarning

    with warnings.catch_warnings(record=True) as caught:  # (the recordings are questionable)
        warnings.simplefilter("always")
        read_recording(short_recs / "s1-run1")
    assert [w for w in caught if issubclass(w.category, QuestionableRecordingWarning)]
    assert cli._batch_keys(cli._recordings_in([str(short_recs)]), pool=False) == ["s1-run1",
                                                                                  "s1-run2"]

    def batch(paths, out, **kwargs):
        raise ValueError("the batch is not run here")

    monkeypatch.setattr(bayespilot.batch, "fit_batch", batch)
    monkeypatch.setattr(bayespilot.diagnose.batch, "diagnose_batch", batch)
    capsys.readouterr()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main([command, str(short_recs), "--out", str(tmp_path / "out"), "--workers",
                     "1", "-q"])
    err = capsys.readouterr().err
    assert code == 2 and err == "bayespilot: error: the batch is not run here\n", err
    assert [str(w.message) for w in caught
            if issubclass(w.category, QuestionableRecordingWarning)] == []

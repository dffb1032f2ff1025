"""The documentation: the site builds strictly and every example in it runs.

* ``mkdocs build --strict`` (warnings, including griffe's docstring warnings
  and broken links, fail the build) into a temporary folder;
* every fenced ```python block of ``docs/*.md`` and ``README.md`` is executed,
  the blocks of one page in order in one namespace, in a temporary working
  directory (so files the examples write land there).  A block opts out only
  with an explicit ```{.python .skip} fence (superfences' class form: a bare
  word after the language would make it no fence at all);
* every ``bayespilot ...`` command in the pages' ``console``/``bash`` blocks
  and in the CLI's own help epilogs is parsed by the CLI's parser (not run),
  so the documented commands and options exist.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = sorted(DOCS.glob("*.md")) + [ROOT / "README.md"]

# A fenced block: ``` + info string on the opening line, body, closing ``` at the
# same indentation (none: our pages fence at column 0).
_FENCE = re.compile(r"^```([^\n`]*)\n(.*?)^```[ \t]*$", re.S | re.M)


def fenced_blocks(text: str) -> list[tuple[str, str, int]]:
    """(info string, body, line number of the opening fence) of every fenced block."""
    return [(m.group(1).strip(), m.group(2), text.count("\n", 0, m.start()) + 1)
            for m in _FENCE.finditer(text)]


def python_blocks(text: str) -> tuple[list[tuple[str, int]], int]:
    """The ``python`` blocks to run, as (body, line), and how many opted out with ``skip``."""
    run, skipped = [], 0
    for info, body, line in fenced_blocks(text):
        words = info.split()
        if info.startswith("{"):  # ```{.python .skip}: the classes, the first the language
            words = [w.strip("{}").lstrip(".") for w in words]
        if not words or words[0] != "python":
            continue
        if "skip" in words[1:]:
            skipped += 1
        else:
            run.append((body, line))
    return run, skipped


def test_fence_parser_finds_python_blocks_and_skips_marked_ones():
    text = ("intro\n```python\nx = 1\n```\n\n```console\n$ bayespilot demo\n```\n"
            "```{.python .skip}\nraise SystemExit\n```\n```python\ny = x + 1\n```\n")
    run, skipped = python_blocks(text)
    assert [body for body, _ in run] == ["x = 1\n", "y = x + 1\n"]
    assert [line for _, line in run] == [2, 12]
    assert skipped == 1
    assert [info for info, _, _ in fenced_blocks(text)] == ["python", "console",
                                                            "{.python .skip}", "python"]


# --- the site --------------------------------------------------------------------------------
def _nav_files(nav) -> list[str]:
    files = []
    for item in nav:
        value = next(iter(item.values())) if isinstance(item, dict) else item
        files += _nav_files(value) if isinstance(value, list) else [value]
    return files


def test_every_page_is_in_the_nav():
    import yaml  # installed with mkdocs (the test extra)

    # mkdocs.yml holds no custom tags, so a plain safe_load reads it.
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))
    in_nav = set(_nav_files(config["nav"]))
    on_disk = {p.name for p in PAGES if p.parent == DOCS}
    assert on_disk - in_nav == set(), "pages missing from the nav of mkdocs.yml"
    assert in_nav - on_disk == set(), "nav entries without a page"


def test_site_builds_strictly(tmp_path):
    # mkdocs, mkdocs-material and mkdocstrings[python] are in the test extra: no skip
    site = tmp_path / "site"
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")  # Material's banner is not a build problem
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file",
         str(ROOT / "mkdocs.yml"), "--site-dir", str(site)],
        capture_output=True, text=True, cwd=ROOT, env=env, stdin=subprocess.DEVNULL, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    api = (site / "api" / "index.html").read_text(encoding="utf-8")
    # the reference is rendered from the docstrings, not left as ':::' lines
    for name in ("io.read_recording", "model.paper_model", "fit.three_step.fit_paper",
                 "campaign.run_campaign", "recording.QuestionableRecordingWarning",
                 "sample.sample", "plots.plot_traces"):
        assert f'id="bayespilot.{name}"' in api, name
    assert ":::" not in api
    # the equations reach MathJax
    assert "arithmatex" in (site / "model" / "index.html").read_text(encoding="utf-8")
    # every fence became a code block: one the Markdown did not take as a fence leaves its
    # ``` as text and swallows the page after it into a code block, headings and all
    for html in site.rglob("index.html"):
        assert "<p>```" not in html.read_text(encoding="utf-8"), html.parent.name


# --- the examples ----------------------------------------------------------------------------
def _pages_with_examples() -> list[Path]:
    return [p for p in PAGES if python_blocks(p.read_text(encoding="utf-8"))[0]]


def test_the_pages_have_examples_to_run():
    names = {p.name for p in _pages_with_examples()}
    assert {"README.md", "install.md", "converting.md", "fitting.md", "model.md"} <= names


@pytest.mark.parametrize("page", _pages_with_examples(), ids=lambda p: p.name)
def test_page_examples_run(page, tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")  # examples may plot; never open a window
    monkeypatch.chdir(tmp_path)
    blocks, _ = python_blocks(page.read_text(encoding="utf-8"))
    namespace: dict = {"__name__": f"docs_example_{page.stem.replace('-', '_')}"}
    for body, line in blocks:
        # compile with the page's line numbers, so a traceback points into the page
        code = compile("\n" * line + body, str(page), "exec")
        try:
            exec(code, namespace)  # noqa: S102 - our own documentation
        finally:
            import matplotlib.pyplot as plt

            plt.close("all")


# --- the documented commands -------------------------------------------------------------------
def _commands(text: str) -> list[str]:
    """``bayespilot ...`` command lines of a text (continuations joined, comments and $ dropped)."""
    text = text.replace("\\\n", " ")
    out = []
    for raw in text.splitlines():
        line = raw.strip()
        line = line[1:].strip() if line.startswith("$") else line
        if line.startswith("bayespilot "):
            out.append(line)
    return out


def _documented_commands() -> list[tuple[str, str]]:
    found = []
    for page in PAGES:
        for info, body, line in fenced_blocks(page.read_text(encoding="utf-8")):
            if info.split()[:1] in (["console"], ["bash"], ["shell"], ["sh"]):
                found += [(f"{page.name}:{line}", c) for c in _commands(body)]
    from bayespilot import cli

    for name in dir(cli):
        if name.endswith("_EPILOG"):
            found += [(f"cli.{name}", c) for c in _commands(getattr(cli, name))]
    return found


def test_documented_commands_are_found():
    where = {w.split(":")[0] for w, _ in _documented_commands()}
    assert {"cli.md", "install.md", "campaigns.md", "cli.TOP_EPILOG"} <= where


@pytest.mark.parametrize("where,command", _documented_commands())
def test_documented_command_parses(where, command):
    from bayespilot.cli import build_parser

    argv = shlex.split(command, comments=True)[1:]
    if "--help" in argv or "-h" in argv or "--version" in argv:
        return  # these exit from the parser by design (checked in test_cli/test_bad_input)
    try:
        args = build_parser().parse_args(argv)
    except Exception as exc:  # noqa: BLE001 - the message is the point
        pytest.fail(f"{where}: {command!r} does not parse: {exc}")
    assert callable(args.handler)


# --- citation ------------------------------------------------------------------------------------
def test_citation_file_cites_the_paper_and_this_version():
    import yaml

    import bayespilot

    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    paper = cff["preferred-citation"]
    assert paper["type"] == "article" and paper["year"] == 2012
    assert (paper["volume"], paper["issue"], paper["start"], paper["end"]) == (35, 3, 749, 763)
    assert [a["family-names"] for a in paper["authors"]] == [
        "Pool", "Valente Pais", "de Vroome", "van Paassen", "Mulder"]
    assert paper in cff["references"]
    # the same doi wherever the docs cite the paper
    for page in (ROOT / "README.md", DOCS / "index.md", DOCS / "model.md"):
        assert f"10.2514/{paper['doi'].split('/')[1]}" in page.read_text(encoding="utf-8"), page
    assert cff["type"] == "software" and cff["license"] == "BSD-3-Clause"
    if not bayespilot.__version__.startswith("0.0.0+"):  # an installed package
        assert str(cff["version"]) == bayespilot.__version__

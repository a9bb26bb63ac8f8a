"""The README and docs/ say what their commands print, and the docs site builds without a broken
link (tools/docs_check.py; the convention is in docs/writing-docs.md)."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))
import docs_check as dc  # noqa: E402

README = ROOT / "README.md"
BLOCKS = [b for f in dc.doc_files() for b in dc.parse_blocks(f)]
CHEAP = [b for b in BLOCKS if b.kind == "cheap"]


def test_the_site_builds_strict_with_every_page(tmp_path):
    """`mkdocs build --strict`: a broken link, a missing anchor or page fails; no nav is
    declared, so every .md of docs/ must come out as a page."""
    site = tmp_path / "site"
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    r = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-q",
                        "-f", str(ROOT / "mkdocs.yml"), "-d", str(site)],
                       capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    pages = sorted((ROOT / "docs").rglob("*.md"))
    assert len(pages) >= 10
    for page in pages:
        rel = page.relative_to(ROOT / "docs").with_suffix("")
        html = site / ("index.html" if rel.name == "index" else rel / "index.html")
        assert html.is_file(), f"no page for docs/{page.relative_to(ROOT / 'docs')}"
    # The diagram pictures linked from docs/ with ../diagrams/ are in the site.
    assert (site / "_repo" / "diagrams" / "closed_loop.svg").is_file()
    # Nothing is fetched when the site is read: no remote fonts or stylesheets.
    index = (site / "index.html").read_text()
    assert "fonts.googleapis" not in index and "fonts.gstatic" not in index


_RUNS: dict = {}


def _run(block):
    if block.name not in _RUNS:
        _RUNS[block.name] = dc.run_block(block)
    return _RUNS[block.name]


@pytest.mark.parametrize("block", CHEAP, ids=[b.name for b in CHEAP])
def test_documented_command_prints_what_the_docs_say(block):
    problems = dc.check_run(block, _run(block))
    assert not problems, "\n".join(problems)


def _bump(number: str) -> str:
    """The number with its last digit changed."""
    i = max(k for k, ch in enumerate(number) if ch.isdigit())
    return number[:i] + str((int(number[i]) + 1) % 10) + number[i + 1:]


def test_editing_any_number_of_the_readme_fails_the_check():
    """Every number the README shows — in a command's printed output or in its text — is
    edited in turn (one digit), and the check must then fail."""
    text = README.read_text(encoding="utf-8")
    assert not dc.check_readme_text(README, text)
    edited = 0
    for block in dc.parse_blocks(README, text):
        if block.kind != "cheap":
            continue
        run = _run(block)
        assert not dc.check_run(block, run)
        for k, command in enumerate(block.commands):
            for i, line in enumerate(command.expected):
                for m in dc.NUMBER.finditer(line):
                    new_line = line[:m.start()] + _bump(m.group()) + line[m.end():]
                    commands = [dc.Command(c.text, list(c.expected)) for c in block.commands]
                    commands[k].expected[i] = new_line
                    assert dc.check_run(block, run, commands), \
                        f"{block.name}: editing {m.group()!r} in {line!r} goes unnoticed"
                    edited += 1
    assert edited >= 20
    # The README's text: each number edited is no longer one its commands print.
    prose = dc.prose_numbers(text)
    assert prose, "the README's text has no number to edit"
    stripped = dc.CODE.sub(lambda m: "\0" * len(m.group()), dc.GENERATED.sub(
        lambda m: "\0" * len(m.group()), text))
    for m in dc.NUMBER.finditer(stripped):
        new = text[:m.start()] + _bump(m.group()) + text[m.end():]
        assert dc.check_readme_text(README, new), f"editing {m.group()!r} goes unnoticed"


def test_generated_sections_are_what_the_results_give():
    sections = [(f, name) for f in dc.doc_files()
                for name, _ in dc.generated_sections(f.read_text(encoding="utf-8"))]
    assert sections, "no generated section: the speed table is generated from its JSON"
    for f in dc.doc_files():
        assert not dc.check_generated(f), "run `make docs-regenerate`"


def test_editing_a_generated_figure_fails():
    f = ROOT / "docs" / "speed.md"
    text = f.read_text(encoding="utf-8")
    m = next(dc.GENERATED.finditer(text))
    body = m.group(3)
    n = next(dc.NUMBER.finditer(body))
    edited = text[:m.start(3)] + body[:n.start()] + _bump(n.group()) + body[n.end():] \
        + text[m.end(3):]
    assert dc.check_generated(f, edited)


def test_the_comparison_rules():
    assert dc.compare(["a 1.25 b"], ["a  1.25 b   "]) is None
    assert dc.compare(["a 1.25 b"], ["a 1.26 b"]) is not None
    assert dc.compare(["a 1.25 b"], ["a 1.25 b", "more"]) is not None        # nothing unshown
    assert dc.compare(["…", "x 1", "…"], ["p", "x 1", "q"]) is None
    assert dc.compare(["x 1", "y 2"], ["x 1", "z", "y 2"]) is not None         # no silent gap
    assert dc.compare(["t [machine-dependent] s, f …"], ["t 3.14 s, f 7"]) is None
    assert dc.compare(["t [machine-dependent] s"], ["u 3.14 s"]) is not None
    (blk,) = dc.parse_blocks(Path("x.md"), "<!-- check: full exit=2 -->\n```console\n"
                             "$ a \\\n  b\nout\n$ c\n```\n")
    assert blk.kind == "full" and blk.options["exit"] == "2"
    assert [c.text for c in blk.commands] == ["a  b", "c"] and blk.commands[0].expected == ["out"]


def test_blocks_not_run_in_ci_are_few_and_known():
    """Long blocks run under `make docs-check-full`; a pending block waits for a command the
    code does not have yet (listed in the report of `python tools/docs_check.py --list`)."""
    pending = [b.name for b in BLOCKS if b.kind == "pending"]
    assert all(re.match(r"README.md:\d+$", n) for n in pending), pending
    assert len(CHEAP) >= 6

"""Checks that README.md and docs/ say what the commands print (`make docs-check`).

The convention (docs/writing-docs.md):

- A ```console block is a command with its printed output: lines starting with ``$ `` are
  commands (a trailing ``\\`` continues one on the next line), the lines after one, up to the next
  ``$ ``, are what it prints on standard output. The checker runs every command of the block in
  one bash shell, in a scratch directory that sees the repository's files (so ``out/...`` is
  written there, never into the checkout), and compares.
- The comparison is line by line, whitespace runs counted as one space, every number as written:
  an edited digit fails. A line that is just ``…`` stands for any number of lines (abridged
  output); ``…`` inside a line stands for any text. ``[machine-dependent]`` stands for any text
  too and marks a figure that depends on the machine (a wall time, a speed ratio): such a figure
  is never typed by hand; tables of them are generated from a benchmark's JSON (below).
- An HTML comment on the line before the fence sets options: ``<!-- check: full -->`` (a long
  command: run by ``make docs-check-full`` only, not in CI), ``<!-- check: pending -->`` (a
  command the code does not support yet: listed, not run), ``exit=N`` (the exit status of the
  block's last command; default 0, and every other command must exit 0), ``stderr`` (the
  printed lines are the last command's standard error), ``timeout=S`` (default 600).
- ``<!-- begin generated: NAME -->`` … ``<!-- end generated: NAME -->`` holds text rendered by
  ``GENERATORS[NAME]`` from a committed file (a benchmark's JSON); ``--regenerate`` rewrites it,
  the check fails when it differs.
- In README.md every number outside code and generated sections must appear in the output of one
  of its checked blocks (or in its ``<!-- check: prose-numbers ... -->`` list of fixed facts),
  so a number edited in the README's text fails too.
- Relative links of README.md must name existing files (the docs site's own build, `mkdocs build
  --strict`, checks the links of docs/).

    python tools/docs_check.py [--full] [--list] [--regenerate] [--only TEXT] [FILE ...]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ELLIPSIS = "…"
MACHINE = "[machine-dependent]"
OPTION = re.compile(r"^\s*<!--\s*check:\s*(.*?)\s*-->\s*$")
FENCE = re.compile(r"^(\s*)```console\s*$")
NUMBER = re.compile(r"(?<![\w.])[-+−]?\d+(?:[.,]\d+)*(?![\w])")


def doc_files(root: Path = ROOT) -> list[Path]:
    """README.md and every Markdown page of docs/."""
    return [root / "README.md"] + sorted((root / "docs").rglob("*.md"))


@dataclass
class Command:
    text: str                     # the command as a shell line (continuations joined)
    expected: list[str] = field(default_factory=list)


@dataclass
class Block:
    path: Path
    line: int                     # 1-based line of the opening fence
    options: dict
    commands: list[Command]

    @property
    def name(self) -> str:
        try:
            rel = self.path.relative_to(ROOT)
        except ValueError:
            rel = self.path
        return f"{rel}:{self.line}"

    @property
    def kind(self) -> str:
        if "pending" in self.options:
            return "pending"
        return "full" if "full" in self.options else "cheap"


def parse_options(text: str) -> dict:
    options = {}
    for word in text.split():
        key, _, value = word.partition("=")
        options[key] = value or True
    return options


def parse_blocks(path: Path, text: str | None = None) -> list[Block]:
    """Every ```console block of a Markdown file, with its options."""
    lines = (path.read_text(encoding="utf-8") if text is None else text).split("\n")
    blocks, i, outer = [], 0, False
    while i < len(lines):
        if lines[i].lstrip().startswith("````"):       # an example of Markdown, not a block
            outer = not outer
        m = FENCE.match(lines[i])
        if not m or outer:
            i += 1
            continue
        indent = len(m.group(1))
        j = i - 1
        while j >= 0 and not lines[j].strip():
            j -= 1
        option = OPTION.match(lines[j]) if j >= 0 else None
        options = parse_options(option.group(1)) if option else {}
        start, i = i, i + 1
        commands: list[Command] = []
        while i < len(lines) and lines[i].strip() != "```":
            line = lines[i][indent:] if lines[i][:indent].strip() == "" else lines[i]
            if line.startswith("$ "):
                text_ = line[2:]
                while text_.endswith("\\") and i + 1 < len(lines):
                    i += 1
                    text_ = text_[:-1] + " " + lines[i].strip()
                commands.append(Command(text_))
            elif commands:
                commands[-1].expected.append(line)
            i += 1
        if not commands:
            raise ValueError(f"{path}:{start + 1}: a console block without a `$ ` command")
        blocks.append(Block(path, start + 1, options, commands))
        i += 1
    return blocks


# ---------------------------------------------------------------------------------------------
# Running and comparing.

def _shell_command(text: str) -> str:
    """The documented command with the virtual environment's programs replaced by the running
    interpreter (the suite may run from another environment than ./.venv)."""
    py = f'"{sys.executable}"'
    text = re.sub(r"(?<![\w/])\.venv/bin/handeye-drake\b", f"{py} -m handeye_drake.apps.cli", text)
    return re.sub(r"(?<![\w/])\.venv/bin/python\b", py, text)


@dataclass
class Run:
    stdout: list[str]
    stderr: list[str]
    status: list[int]


_RUNS: dict = {}


def run_block(block: Block, root: Path = ROOT) -> Run:
    """Runs a block's commands in one bash shell in a scratch directory whose entries link to
    the repository's (commands write their `out/` there). Blocks with the same commands (the
    README's tour and a page's) run once."""
    key = (tuple(" ".join(c.text.split()) for c in block.commands), str(root))
    if key not in _RUNS:
        _RUNS[key] = _run_block(block, root)
    return _RUNS[key]


def _run_block(block: Block, root: Path) -> Run:
    with tempfile.TemporaryDirectory(prefix="docs-check-") as tmp:
        work = Path(tmp) / "repo"
        work.mkdir()
        for entry in root.iterdir():
            if entry.name not in {".git", ".venv", "out", "site"}:
                (work / entry.name).symlink_to(entry)
        script = ["set -u"]
        for k, c in enumerate(block.commands):
            script.append(f"{{ {_shell_command(c.text)}\n}} >'{tmp}/o{k}' 2>'{tmp}/e{k}' "
                          f"</dev/null; echo $? >'{tmp}/s{k}'")
            if k + 1 < len(block.commands):
                script.append(f"[ \"$(cat '{tmp}/s{k}')\" = 0 ] || exit 0")
        env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""),
                   OPENBLAS_NUM_THREADS="1", COLUMNS="100")
        subprocess.run(["bash", "-c", "\n".join(script)], cwd=work, env=env,
                       timeout=float(block.options.get("timeout", 600)), check=False)
        out, err, status = [], [], []
        for k in range(len(block.commands)):
            s = Path(tmp) / f"s{k}"
            if not s.exists():
                break
            status.append(int(s.read_text().strip() or -1))
            out.append((Path(tmp) / f"o{k}").read_text(errors="replace"))
            err.append((Path(tmp) / f"e{k}").read_text(errors="replace"))
        return Run(out, err, status)


def _normalize(line: str) -> str:
    return " ".join(line.split())


def _pattern(expected: str) -> re.Pattern:
    parts = re.split(r"(…|\[machine-dependent\])", _normalize(expected))
    return re.compile("".join(".*?" if p in (ELLIPSIS, MACHINE) else re.escape(p)
                              for p in parts))


def compare(expected: list[str], actual: list[str]) -> str | None:
    """None when `actual` is what `expected` says, else a message naming the first difference."""
    exp = [e for e in expected]
    while exp and not exp[-1].strip():
        exp.pop()
    act = [a for a in actual]
    while act and not act[-1].strip():
        act.pop()
    pats = [None if _normalize(e) == ELLIPSIS else _pattern(e) for e in exp]
    best = [0, 0]                 # the furthest expected line reached, and the actual line there
    memo: dict = {}

    def match(i: int, j: int) -> bool:
        if (i, j) in memo:
            return memo[i, j]
        if i > best[0] or (i == best[0] and j > best[1]):
            best[:] = [i, j]
        if i == len(pats):
            ok = j == len(act)
        elif pats[i] is None:
            ok = any(match(i + 1, k) for k in range(j, len(act) + 1))
        else:
            ok = j < len(act) and bool(pats[i].fullmatch(_normalize(act[j]))) and match(i + 1, j + 1)
        memo[i, j] = ok
        return ok

    sys.setrecursionlimit(max(10000, 4 * (len(exp) + len(act))))
    if match(0, 0):
        return None
    i, j = best
    if i == len(pats):
        return f"unexpected output after the last line shown:\n    {act[j]!r}"
    got = repr(act[j]) if j < len(act) else "(end of output)"
    return f"expected:\n    {exp[i]!r}\n  printed:\n    {got}"


def check_run(block: Block, run: Run, commands: list[Command] | None = None) -> list[str]:
    """Differences between what a block says (or `commands`: the same block, edited) and a run."""
    commands = block.commands if commands is None else commands
    problems = []
    want_exit = int(block.options.get("exit", 0))
    for k, c in enumerate(commands):
        if k >= len(run.status):
            problems.append(f"`{c.text}` did not run (an earlier command failed)")
            break
        last = k == len(commands) - 1
        status = run.status[k]
        expected_status = want_exit if last else 0
        if status != expected_status:
            tail = (run.stderr[k] or run.stdout[k]).strip().splitlines()[-5:]
            problems.append(f"`{c.text}` exited with {status}, expected {expected_status}:\n    "
                            + "\n    ".join(tail))
            continue
        stream = run.stderr[k] if (last and "stderr" in block.options) else run.stdout[k]
        diff = compare(c.expected, stream.split("\n"))
        if diff:
            problems.append(f"`{c.text}` printed something else:\n  {diff}")
    return problems


# ---------------------------------------------------------------------------------------------
# Generated sections: text rendered from committed benchmark results.

def _time(value: float, unit: str) -> str:
    seconds = value * {"s": 1.0, "ms": 1e-3, "µs": 1e-6}[unit]
    if seconds >= 1:
        return f"{seconds:.2f} s"
    if seconds >= 1e-3:
        return f"{1e3 * seconds:.3g} ms"
    return f"{1e6 * seconds:.3g} µs"


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def render_speed_table(report: dict) -> str:
    """Markdown of `handeye-drake benchmark speed --json`: each timing beside its reference
    timed in the same run, and the ratio, with the machine's load."""
    out = [f"Measured by `{report['command']}` ({report['wall_time_s']:.0f} s; BLAS "
           f"{report['blas'].split(',')[0]}; load average {report['load_average_before']} "
           f"before, {report['load_average_after']} after).", "",
           "| section | what | time | reference, timed in the same run | ratio | target |",
           "|---|---|---|---|---|---|"]
    for r in report["rows"]:
        section = r["section"]
        if "ratio" in r and "what" in r:
            unit = r.get("unit", "µs")
            target = f"≤ {r['target']:g}×" if r.get("target") else ""
            if r.get("target"):
                target += " met" if r["ratio"] <= r["target"] else " **not met**"
            cpu = f" (CPU time {r['cpu_ratio']:.2f}×)" if "cpu_ratio" in r else ""
            out.append(f"| {section} | {_cell(r['what'])} | {_time(r['value_us'], unit)} | "
                       f"{_cell(r['reference'])}: {_time(r['reference_us'], unit)} | "
                       f"{r['ratio']:.2f}×{cpu} | {target} |")
        elif section == "corners" and "images" in r:
            out.append(f"| corners | corner-level fit (k1k2), {r['images']} images × "
                       f"{r['corners'] // r['images']} corners ({r['ms_per_image']:.3g} ms per "
                       f"image) | {_time(r['seconds'], 's')} | `cv2.calibrateCamera` on the same "
                       f"corners: {_time(r['reference_seconds'], 's')} | {r['ratio']:.2f}× | |")
        elif section == "calibrate" and "pairs" in r:
            if r.get("exit_code", 0) != 0:
                ours = f"exit code {r['exit_code']}"
            else:
                ours = _time(r["seconds"], "s")
            ref = (f"OpenCV `calibrateHandEye` (Park): {_time(r['opencv_seconds'], 's')}"
                   if "opencv_seconds" in r else "OpenCV: " + _cell(r.get("opencv", "")))
            ratio = (f"{r['seconds'] / r['opencv_seconds']:.2f}×"
                     if "opencv_seconds" in r and r.get("exit_code", 0) == 0 else "")
            out.append(f"| calibrate | the whole `calibrate` command, {r['pairs']} pairs "
                       f"({r['us_per_pair']:.0f} µs per pair) | {ours} | {ref} | {ratio} | |")
        elif "growth_exponent" in r:
            out.append(f"| calibrate | growth of its wall time with the pairs N | "
                       f"N^{r['growth_exponent']:.2f} | | | |")
        elif "cost_per_image_growth" in r:
            out.append(f"| corners | cost per image at 10× the images | "
                       f"{r['cost_per_image_growth']:.2f}× | | | |")
    return "\n".join(out) + "\n"


def speed_table(root: Path = ROOT) -> str:
    """The table of docs/speed.md, from benchmarks/results/speed.json."""
    return render_speed_table(json.loads((root / "benchmarks/results/speed.json").read_text()))


def _median(m: dict, key: str, digits: int = 3) -> str:
    return f"{m[key]['median']:.{digits}g}"


def render_accuracy_table(report: dict) -> str:
    """Markdown of `handeye-drake benchmark accuracy --json`: medians of the final errors per
    setting for ours, the best OpenCV method, the paper's filter and the ML reference."""
    out = ["| setting | ours | best OpenCV | paper's filter | ML reference |", "|---|---|---|---|---|"]
    for name, setting in report["settings"].items():
        methods = setting["methods"]
        ours_name = "manifold_ml_start" if "manifold_ml_start" in methods else "target"
        ours = methods[ours_name]
        cv = {k: v for k, v in methods.items() if k.startswith("opencv_") and v["runs"]}
        best_r = min(cv, key=lambda k: cv[k]["rotation_deg"]["median"])
        best_t = min(cv, key=lambda k: cv[k]["translation_pct"]["median"])
        cv_text = (f"{_median(cv[best_r], 'rotation_deg')}° ({best_r[7:]}) / "
                   f"{_median(cv[best_t], 'translation_pct')} % ({best_t[7:]})")
        paper = methods["paper_kf"]
        failed = setting["runs"] - paper["runs"]
        paper_text = (f"{_median(paper, 'rotation_deg')}° / {_median(paper, 'translation_pct')} %"
                      + (f" ({failed} failed)" if failed else ""))
        ml = methods[setting["reference"]]
        out.append(f"| `{name}`: {_cell(setting['description'])}; {setting['runs']} runs, error of "
                   f"{setting['error_of']} | **{_median(ours, 'rotation_deg')}° / "
                   f"{_median(ours, 'translation_pct')} %** (`{ours_name}`) | {cv_text} | "
                   f"{paper_text} | {_median(ml, 'rotation_deg')}° / "
                   f"{_median(ml, 'translation_pct')} % (`{setting['reference']}`) |")
    met = sum(t["met"] for t in report["targets"])
    out += ["", f"Targets checked by the benchmark: {met} of {len(report['targets'])} met. "
            f"From `{report['command']}` (seed {report['seed']}; the errors do not depend on the "
            f"machine)."]
    return "\n".join(out) + "\n"


def accuracy_table(root: Path = ROOT) -> str:
    """The table of docs/benchmarks.md, from benchmarks/results/accuracy.json."""
    return render_accuracy_table(
        json.loads((root / "benchmarks/results/accuracy.json").read_text(encoding="utf-8")))


GENERATORS = {"speed-table": speed_table, "accuracy-table": accuracy_table}
GENERATED = re.compile(r"^(<!-- begin generated: ([\w-]+) -->\n)(.*?)^(<!-- end generated: \2 -->)",
                       re.S | re.M)


def generated_sections(text: str):
    for m in GENERATED.finditer(text):
        yield m.group(2), m.group(3)


def check_generated(path: Path, text: str | None = None, root: Path = ROOT) -> list[str]:
    text = path.read_text(encoding="utf-8") if text is None else text
    problems = []
    for name, body in generated_sections(text):
        if name not in GENERATORS:
            problems.append(f"{path.name}: unknown generated section {name!r}")
        elif body != GENERATORS[name](root):
            problems.append(f"{path.name}: generated section {name!r} differs from what "
                            f"`python tools/docs_check.py --regenerate` writes")
    return problems


def regenerate(path: Path, root: Path = ROOT) -> bool:
    text = path.read_text(encoding="utf-8")
    new = GENERATED.sub(lambda m: m.group(1) + GENERATORS[m.group(2)](root) + m.group(4), text)
    if new != text:
        path.write_text(new, encoding="utf-8")
    return new != text


# ---------------------------------------------------------------------------------------------
# The README's own text: numbers and links.

CODE = re.compile(r"```.*?```|`[^`\n]*`|<!--.*?-->|\]\([^)]*\)|<[^>]*>", re.S)


def prose_numbers(text: str) -> list[str]:
    """Numbers of a Markdown text outside code, comments, link targets and generated sections."""
    text = GENERATED.sub("", text)
    return NUMBER.findall(CODE.sub(" ", text))


def check_readme_text(path: Path, text: str | None = None) -> list[str]:
    """Each number of the README's prose appears in a checked block's output or its declared
    fixed facts; each relative link names an existing file."""
    text = path.read_text(encoding="utf-8") if text is None else text
    known = set()
    for block in parse_blocks(path, text):
        if block.kind != "pending":
            for c in block.commands:
                known.update(NUMBER.findall("\n".join(c.expected)))
    for m in re.finditer(r"<!--\s*check:\s*prose-numbers\s+(.*?)-->", text, re.S):
        known.update(m.group(1).split())
    problems = [f"{path.name}: the number {n} in the text is neither printed by one of its "
                f"checked commands nor declared in `<!-- check: prose-numbers ... -->`"
                for n in prose_numbers(text) if n not in known]
    for target in re.findall(r"\]\(([^)\s]+)\)|src=\"([^\"]+)\"", text):
        target = (target[0] or target[1]).split("#")[0]
        if target and not re.match(r"[a-z]+:", target) and not (path.parent / target).exists():
            problems.append(f"{path.name}: link to a missing file: {target}")
    return problems


# ---------------------------------------------------------------------------------------------

def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("files", nargs="*", type=Path, help="Markdown files (default README + docs/)")
    p.add_argument("--full", action="store_true", help="also run the long blocks (`full`)")
    p.add_argument("--only-full", action="store_true", help="run only the long blocks")
    p.add_argument("--list", action="store_true", help="list the blocks and what runs them")
    p.add_argument("--only", metavar="TEXT", help="only blocks whose name or command has TEXT")
    p.add_argument("--regenerate", action="store_true", help="rewrite the generated sections")
    args = p.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    files = [f.resolve() for f in args.files] or doc_files()
    if args.regenerate:
        for f in files:
            if regenerate(f):
                print(f"regenerated {f.relative_to(ROOT)}")
        return 0
    blocks = [b for f in files for b in parse_blocks(f)]
    if args.only:
        blocks = [b for b in blocks
                  if args.only in b.name or any(args.only in c.text for c in b.commands)]
    if args.list:
        for b in blocks:
            print(f"{b.kind:8s} {b.name:32s} $ {b.commands[0].text[:90]}")
        return 0
    problems = []
    for f in files:
        problems += check_generated(f)
        if f.name == "README.md" and f.parent == ROOT:
            problems += check_readme_text(f)
    wanted = {"cheap", "full"} if args.full else ({"full"} if args.only_full else {"cheap"})
    for b in blocks:
        if b.kind not in wanted:
            print(f"skip  {b.name} ({b.kind})")
            continue
        print(f"run   {b.name}: $ {b.commands[0].text[:80]}", flush=True)
        found = check_run(b, run_block(b))
        problems += [f"{b.name}: {x}" for x in found]
    for x in problems:
        print("FAIL  " + x)
    print(f"docs check: {len(problems)} problem(s)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())

"""The Python examples of the docs run and say what they claim; every `handeye-drake` command of
the README and docs/ names real options (the commands shown with their output are run by
tests/test_docs.py)."""

import os
import re
import shlex
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
PYTHON_API = ROOT / "docs" / "python-api.md"
DOCS = [README] + sorted((ROOT / "docs").rglob("*.md"))


def _python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", PYTHON_API.read_text(), re.S)


def _run(code: str) -> dict:
    namespace: dict = {}
    cwd = os.getcwd()
    os.chdir(ROOT)  # the examples use paths relative to the repository root
    try:
        exec(compile(code, "docs/python-api.md", "exec"), namespace)
    finally:
        os.chdir(cwd)
    return namespace


def test_the_python_api_page_has_the_four_examples():
    blocks = _python_blocks()
    assert len(blocks) == 4
    assert "HandEyeTargetFilter" in blocks[0] and "calibrate(" in blocks[1]
    assert "DiagramBuilder" in blocks[2] and "run_scenario" in blocks[3]


def test_the_estimation_core_example_is_accurate():
    namespace = _run(_python_blocks()[0])
    he, X_true = namespace["he"], namespace["X_EC_true"]
    assert he.rotation_error_deg(X_true, namespace["X_EC"]) < 0.2
    assert he.rotation_error_deg(X_true, namespace["kf"].X_EC) < 0.5
    f = namespace["f"]
    assert he.rotation_error_deg(X_true, f.X_EC) < 0.1
    assert np.linalg.norm(X_true[:3, 3] - f.X_EC[:3, 3]) < 2e-3
    assert np.all(f.X_EC_rotation_std_deg > 0) and np.all(f.X_EC_rotation_std_deg < 0.1)
    assert f.diagnostics() == []


def test_the_calibrate_example_is_ok_and_right():
    import json
    namespace = _run(_python_blocks()[1])
    result = namespace["result"]
    truth = np.array(json.loads((ROOT / "handeye_drake/data/example_truth.json").read_text())
                     ["X_EC"])
    assert result.verdict.status == "OK"
    assert np.linalg.norm(result.X_EC[:3, 3] - truth[:3, 3]) < 4 * np.linalg.norm(
        result.translation_std)
    images = namespace["from_images"]
    assert images.verdict.status == "OK" and images.corners is not None
    assert set(namespace["files"]) >= {"handeye.urdf"}


def test_the_drake_calibrator_example_ends_within_its_sigma():
    namespace = _run(_python_blocks()[2])
    p, std, X_EC = namespace["X_EC_estimate"][9:], namespace["X_EC_std"], namespace["X_EC"]
    assert np.all(np.abs(p - X_EC[:3, 3]) < 4 * std[3:])
    assert np.all(std[3:] < 0.01)


def test_the_scenario_example_runs():
    namespace = _run(_python_blocks()[3])
    result = namespace["result"]
    assert result.rotation_error_deg[-1] < result.initial_rotation_error_deg
    assert namespace["loop"].calibrator.get_name() == "calibrator"


def _pending_commands() -> set[str]:
    """Commands of blocks marked `<!-- check: pending -->`: the code does not have them yet."""
    sys.path.insert(0, str(ROOT / "tools"))
    import docs_check
    return {" ".join(c.text.split()) for f in DOCS for b in docs_check.parse_blocks(f)
            if b.kind == "pending" for c in b.commands}


def _commands() -> list[list[str]]:
    text = "\n".join(f.read_text() for f in DOCS)
    text = re.sub(r"\\\n\s*", " ", text)
    pending = _pending_commands()
    out = []
    for line in text.splitlines():
        if " ".join(line.strip()[2:].split()) in pending:
            continue
        line = line.strip().lstrip("$ ")
        if line.startswith(".venv/bin/handeye-drake "):
            line = re.sub(r"\[[^\]]*\]", "", line.split("#")[0]).split(" > ")[0]
            out.append(shlex.split(line)[1:])
    return out


def test_every_handeye_drake_command_in_the_docs_parses():
    """Each command's options exist (a renamed option would leave the docs wrong)."""
    from handeye_drake.apps.cli import make_parser
    commands = _commands()
    assert len(commands) >= 15
    parser = make_parser()
    for argv in commands:
        argv = [a.replace("$D", "handeye_drake/data/example_images") for a in argv]
        try:
            parser.parse_args(argv)
        except SystemExit as e:
            pytest.fail(f"documented command does not parse ({e.code}): handeye-drake "
                        + " ".join(argv))

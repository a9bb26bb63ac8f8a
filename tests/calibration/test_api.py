"""The calibration library (``handeye_drake.calibration``): one entry point with the command
line's defaults, the same result through the Python API and the CLI, importable without the
applications, no import cycle anywhere in the package."""

import ast
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import handeye_drake
from handeye_drake.apps.cli import main
from handeye_drake.calibration import CalibrationOptions, calibrate, read_inputs, solve
from handeye_drake.calibration.report import _strict_json

PACKAGE = Path(handeye_drake.__file__).resolve().parent
DATA = PACKAGE / "data"
IMAGES = DATA / "example_images"
ROBOT, CAMERA = DATA / "example_robot.tum", DATA / "example_camera.tum"


def _json(value):
    return json.loads(json.dumps(_strict_json(value)))


def test_python_api_and_cli_give_bit_identical_results(tmp_path, capsys):
    result = calibrate(str(ROBOT), str(CAMERA))
    assert main(["calibrate", "--robot", str(ROBOT), "--camera", str(CAMERA), "--out",
                 str(tmp_path / "cli")]) == 0
    doc = json.loads((tmp_path / "cli" / "calibration.json").read_text())
    assert doc == _json(result.to_json())
    # The command line's robot accuracy is the library's default: the σ include it.
    assert doc["robot_accuracy"] == {"rotation_deg": 0.03, "translation_m": 0.0003}


def test_images_through_the_api_and_the_cli(tmp_path, capsys):
    spec = "charuco:7x5:0.04:0.03:DICT_5X5_100"
    result = calibrate(str(IMAGES / "robot_poses.tum"), images=str(IMAGES), target=spec,
                       intrinsics=str(IMAGES / "intrinsics.yaml"))
    assert main(["calibrate", "--images", str(IMAGES), "--robot", str(IMAGES / "robot_poses.tum"),
                 "--target", spec, "--intrinsics", str(IMAGES / "intrinsics.yaml"), "--out",
                 str(tmp_path / "cli")]) == 0
    doc = json.loads((tmp_path / "cli" / "calibration.json").read_text())
    api = _json(result.to_json())
    for key in ("X_EC", "X_BT", "verdict", "intrinsics", "task_space_sigma"):
        assert doc[key] == api[key], key
    assert doc["corner_level"]["per_image"] == api["corner_level"]["per_image"]


def test_options_have_units_and_are_checked():
    o = CalibrationOptions()
    assert o.robot_accuracy == (0.03, 0.0003) and o.mode == "eye_in_hand"
    assert CalibrationOptions(robot_accuracy_deg=0, robot_accuracy_mm=0).robot_accuracy is None
    assert CalibrationOptions(mode="eye-to-hand").mode == "eye_to_hand"
    for bad, match in (({"mode": "hand"}, "mode"), ({"refine_intrinsics": "all"},
                                                     "refine_intrinsics"),
                       ({"robot_accuracy_mm": -1}, "robot_accuracy_mm"),
                       ({"max_noise_deg": "1"}, "max_noise_deg")):
        with pytest.raises(ValueError, match=match):
            CalibrationOptions(**bad)
    with pytest.raises(ValueError, match="options"):
        calibrate(str(ROBOT), str(CAMERA), options={"mode": "eye_in_hand"})
    with pytest.raises(ValueError, match="give one of"):
        read_inputs(str(ROBOT))
    with pytest.raises(ValueError, match="target"):
        read_inputs(str(ROBOT), images=str(IMAGES))


def test_export_is_refused_on_fail_and_round_trips_on_ok(tmp_path):
    streams = read_inputs(str(ROBOT), str(CAMERA))
    ok = solve(streams)
    texts = ok.export("urdf,json")
    assert "handeye.urdf" in texts and "tool0" in texts["handeye.urdf"]
    X = np.array(json.loads(texts["handeye.json"])["X_EC"]["matrix"]) \
        if "X_EC" in json.loads(texts["handeye.json"]) else None
    if X is not None:
        np.testing.assert_allclose(X, ok.X_EC, atol=1e-12)
    bad = calibrate(str(IMAGES / "robot_poses.tum"), images=str(IMAGES),
                    target="charuco:7x5:0.044:0.033:DICT_5X5_100",
                    intrinsics=str(IMAGES / "intrinsics.yaml"))
    assert bad.verdict.status == "FAIL"
    with pytest.raises(ValueError, match="verdict is FAIL"):
        bad.export("urdf")


def test_the_calibration_stages_import_without_apps_or_drake():
    code = ("import sys, handeye_drake.calibration as c, handeye_drake.calibration.align, "
            "handeye_drake.calibration.corners, handeye_drake.calibration.checks; "
            "bad = [m for m in sys.modules if m.startswith(('handeye_drake.apps', 'pydrake'))]; "
            "print(bad); sys.exit(1 if bad else 0)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr


def _import_graph() -> dict:
    """Module → the package modules it imports, every import statement counted (at the top, in
    functions, under conditions: a lazy import is still an edge)."""
    modules = {}
    for p in PACKAGE.rglob("*.py"):
        parts = list(p.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        modules[".".join(parts)] = p
    graph = {}
    for name, path in modules.items():
        is_package = path.name == "__init__.py"
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = name.split(".") if is_package else name.split(".")[:-1]
                    base = base[:len(base) - (node.level - 1)]
                    prefix = ".".join(base + ([node.module] if node.module else []))
                else:
                    prefix = node.module or ""
                # ``from P import m`` imports module P.m when there is one (P itself only runs
                # as its parent package), else the name m of module P.
                targets = [f"{prefix}.{a.name}" if f"{prefix}.{a.name}" in modules else prefix
                           for a in node.names]
            for t in targets:
                while t and t not in modules and "." in t:
                    t = t.rsplit(".", 1)[0]
                if t in modules and t != name:
                    deps.add(t)
        graph[name] = deps
    return graph


def _cycles(graph) -> list:
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles_anywhere():
    graph = _import_graph()
    # The detector finds a cycle when there is one.
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == [["a", "b", "c"]]
    assert _cycles(graph) == []
    # Floors: nothing below the applications imports them; the estimation core and the camera
    # model (estimation, vision) import no floor above them.
    for name, deps in graph.items():
        if not name.startswith("handeye_drake.apps"):
            assert not any(d.startswith("handeye_drake.apps") for d in deps), (name, deps)
        if name.startswith(("handeye_drake.estimation", "handeye_drake.vision")):
            assert all(d.startswith(("handeye_drake.estimation", "handeye_drake.vision"))
                       for d in deps), (name, deps)
        if name.startswith("handeye_drake.recorded"):
            assert not any(d.startswith("handeye_drake.calibration") for d in deps), (name, deps)

"""Exports round-tripped through their consumers, and ROS bags read back and calibrated.

    python benchmarks/cell_io.py

1. Every export of ``recorded.exports`` for the test transforms (the example's X_EC, identity,
   pitch ±90° and within 1e-7°/1e-9° of it, 180° rotations about five axes, three random
   poses), read back by its consumer: Drake's URDF parser (``CalcRelativeTransform``), the xacro
   macro expanded and parsed by Drake, ``ProcessModelDirectives``, ``yaml_load_typed`` into
   ``CameraConfig`` (X_PB · X_BC), the launch file's ``Node`` arguments (``ast``), the one-line
   command (``shlex``), the JSON and TUM readers. Prints the largest |entry| difference to X.
2. The simulated recording of ``tests/test_bags.py`` (12 s; tf chain of 7 transforms, 4 of them
   dynamic at 50 Hz in two /tf messages per stamp; camera
   X_CT at 10 Hz with 0.1° / 0.5 mm noise, 20 ms camera latency; 7 image topics) written as ROS 1
   .bag, ROS 2
   sqlite3 and ROS 2 MCAP; prints size, read time, the recovered streams' error to the truth and
   ``calibrate_streams``'s X_EC error on them.
"""
import ast
import shlex
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from tests.recorded.test_bags import (CAMERA_LATENCY, EPOCH_NS, FORMATS, robot_truth, simulate,  # noqa: E402
                       write_recording)
from tests.recorded.test_exports import CASES, _flags_to_transform, _plant_with, _robot_urdf  # noqa: E402

from pydrake.common.yaml import yaml_load_typed  # noqa: E402
from pydrake.multibody.parsing import (LoadModelDirectivesFromString, Parser,  # noqa: E402
                                       ProcessModelDirectives)
from pydrake.multibody.plant import MultibodyPlant  # noqa: E402
from pydrake.systems.sensors import CameraConfig  # noqa: E402

from handeye_drake.estimation.se3 import rotation_angle  # noqa: E402
from handeye_drake.recorded import bags, exports  # noqa: E402
from handeye_drake.calibration import calibrate_streams  # noqa: E402
from handeye_drake.recorded.example import TRUE_X_EC  # noqa: E402
from handeye_drake.recorded.formats import read_poses  # noqa: E402


def _relative(plant, context, child="camera_optical_frame"):
    return plant.CalcRelativeTransform(context, plant.GetFrameByName("tool0"),
                                       plant.GetFrameByName(child)).GetAsMatrix4()


def consumers(d: Path) -> dict:
    """{format: the transform as its consumer reads it back from the files in d}."""
    out = {}
    root = ET.parse(d / "handeye.urdf").getroot()
    plant, context = _plant_with(_robot_urdf("".join(ET.tostring(e, encoding="unicode")
                                                     for e in root)))
    out["urdf (Drake Parser)"] = _relative(plant, context)
    ns = "{http://www.ros.org/wiki/xacro}"
    root = ET.parse(d / "handeye.xacro").getroot()
    values = {e.get("name"): e.get("value") for e in root.findall(f"{ns}property")}
    values.update(parent="tool0", child="camera_optical_frame")
    body = "".join(ET.tostring(e, encoding="unicode") for e in root.find(f"{ns}macro"))
    for key, value in sorted(values.items(), key=lambda kv: -len(kv[0])):
        body = body.replace("${" + key + "}", value)
    out["xacro macro (Drake Parser)"] = _relative(*_plant_with(_robot_urdf(body)))
    plant = MultibodyPlant(0.0)
    parser = Parser(plant)
    parser.AddModelsFromString(_robot_urdf(), "urdf")
    ProcessModelDirectives(LoadModelDirectivesFromString(
        (d / "handeye_directives.yaml").read_text()), plant, parser)
    plant.Finalize()
    out["drake directive (ProcessModelDirectives)"] = _relative(plant,
                                                                plant.CreateDefaultContext())
    config = yaml_load_typed(schema=CameraConfig, filename=str(d / "handeye_camera_config.yaml"))
    out["CameraConfig (yaml_load_typed, X_PB·X_BC)"] = (
        config.X_PB.GetDeterministicValue() @ config.X_BC.GetDeterministicValue()).GetAsMatrix4()
    tree = ast.parse((d / "handeye.launch.py").read_text())
    (node,) = [n for n in ast.walk(tree) if isinstance(n, ast.Call)
               and getattr(n.func, "id", None) == "Node"]
    args = [ast.literal_eval(k.value) for k in node.keywords if k.arg == "arguments"][0]
    out["ROS 2 launch (ast)"] = _flags_to_transform(args)[0]
    command = [s for s in (d / "handeye_static_tf.sh").read_text().splitlines()
               if s and not s.startswith("#")][0]
    out["static_transform_publisher command (shlex)"] = _flags_to_transform(
        shlex.split(command)[4:])[0]
    out["json (read_transform_json)"] = exports.read_transform_json(d / "handeye.json")[0]
    out["tum (formats.read_poses)"] = read_poses(d / "handeye.tum", "robot", "tum").poses[0]
    return out


def main():
    worst = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, X in CASES.items():
            d = Path(tmp) / name
            exports.export_calibration(X, d, formats="all", parent_frame="tool0")
            for fmt, Y in consumers(d).items():
                err = float(np.abs(Y - X).max())
                if err >= worst.get(fmt, (-1.0, ""))[0]:
                    worst[fmt] = (err, name)
    print(f"1. export round trips over {len(CASES)} transforms: largest |entry| difference to X")
    for fmt, (err, name) in worst.items():
        print(f"   {fmt:45s} {err:.1e}  (worst case: {name})")

    sim = simulate()
    truth_robot = np.array([robot_truth((ns - EPOCH_NS) * 1e-9)[0] for ns in sim["robot_ns"]])
    truth_camera = np.array([X for _, X in sim["camera"]])
    print("\n2. simulated recording as ROS bags (12 s; robot tf 50 Hz along 7 transforms, camera "
          "10 Hz, 7 image topics × 25 images 6×8)")
    print(f"   {'format':8s} {'size kB':>8s} {'read s':>7s} {'robot err':>10s} "
          f"{'camera err':>10s} {'offset s':>9s} {'X_EC rot °':>10s} {'trans mm':>9s} "
          f"{'σ rot °':>8s} {'σ trans mm':>10s}")
    with tempfile.TemporaryDirectory() as tmp:
        for fmt in FORMATS:
            path = write_recording(Path(tmp) / ("cell.bag" if fmt == "ros1" else f"cell_{fmt}"),
                                   fmt, sim, leading_slash=fmt == "ros1")
            size = sum(p.stat().st_size for p in ([path] if path.is_file() else
                                                  path.iterdir()))
            t0 = time.perf_counter()
            data = bags.read_bag(path, ("base_link", "tool0"), camera_topic="/camera/target_pose")
            read_s = time.perf_counter() - t0
            r = calibrate_streams(data.robot, data.camera)
            rot = np.degrees(rotation_angle(r.X_EC[:3, :3] @ TRUE_X_EC[:3, :3].T))
            trans = 1000 * np.linalg.norm(r.X_EC[:3, 3] - TRUE_X_EC[:3, 3])
            print(f"   {fmt:8s} {size / 1024:8.0f} {read_s:7.2f} "
                  f"{np.abs(data.robot.poses - truth_robot).max():10.1e} "
                  f"{np.abs(data.camera.poses - truth_camera).max():10.1e} "
                  f"{r.aligned.time_offset:9.4f} {rot:10.4f} {trans:9.3f} "
                  f"{np.linalg.norm(r.rotation_std_deg):8.4f} "
                  f"{1000 * np.linalg.norm(r.translation_std):10.3f}")
    print(f"   (true camera latency {CAMERA_LATENCY} s; σ = norm of the reported 1σ vector)")


if __name__ == "__main__":
    main()

"""Exports round-trip through their real consumers: Drake's URDF parser, model directives,
CameraConfig + ApplyCameraConfig, the launch file's Python syntax, XML, and the package's own
TUM/JSON readers. Tolerance 1e-9 on every matrix entry."""

import ast
import json
import math
import shlex
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from pydrake.common.yaml import yaml_load_typed
from pydrake.lcm import DrakeLcm
from pydrake.multibody.parsing import (LoadModelDirectivesFromString, Parser,
                                       ProcessModelDirectives)
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.sensors import ApplyCameraConfig, CameraConfig, RgbdSensor
from scipy.spatial.transform import Rotation

from handeye_drake.recorded import exports as ex
from handeye_drake.recorded.example import TRUE_X_EC
from handeye_drake.recorded.formats import read_poses
from handeye_drake.estimation.se3 import make_transform, rotation_exp
from handeye_drake.vision.camera_model import CameraIntrinsics

TOL = 1e-9


def _rpy_deg(r, p, y):
    return Rotation.from_euler("xyz", np.radians([r, p, y])).as_matrix()


def _cases():
    t = [0.0123456789012, -0.0456789, 0.0789]
    cases = {
        "example": TRUE_X_EC,
        "identity": np.eye(4),
        "pitch+90": make_transform(_rpy_deg(30.0, 90.0, -40.0), t),
        "pitch-90": make_transform(_rpy_deg(-120.0, -90.0, 75.0), t),
        "pitch+90-1e-7deg": make_transform(_rpy_deg(10.0, 90.0 - 1e-7, 20.0), t),
        "pitch-90+1e-9deg": make_transform(_rpy_deg(170.0, -90.0 + 1e-9, -170.0), t),
    }
    for name, axis in (("x", [1, 0, 0]), ("y", [0, 1, 0]), ("z", [0, 0, 1]),
                       ("xy", [1, 1, 0]), ("xyz", [1, -2, 3])):
        a = np.array(axis, float)
        cases[f"180-{name}"] = make_transform(rotation_exp(math.pi * a / np.linalg.norm(a)), t)
    rng = np.random.default_rng(7)
    for k in range(3):
        cases[f"random{k}"] = make_transform(rotation_exp(rng.normal(size=3)),
                                             rng.normal(size=3) * 0.3)
    return cases


CASES = _cases()


def _assert_close(A, B, tol=TOL):
    err = np.abs(np.asarray(A) - np.asarray(B)).max()
    assert err <= tol, f"max |difference| {err:.3g} > {tol}"


def _robot_urdf(inner: str = "") -> str:
    """A base link, a revolute joint to a flange link ``tool0`` (q = 0 puts tool0 0.5 m up) and
    whatever ``inner`` adds."""
    inertial = ('<inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" '
                'ixz="0" iyz="0"/></inertial>')
    return (f'<robot name="robot"><link name="base_link">{inertial}</link>'
            f'<link name="tool0">{inertial}</link>'
            '<joint name="j1" type="revolute"><parent link="base_link"/><child link="tool0"/>'
            '<origin xyz="0.1 0.2 0.5" rpy="0.3 0.2 0.1"/><axis xyz="0 0 1"/>'
            '<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
            f'{inner}</robot>')


def _plant_with(urdf: str):
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModelsFromString(urdf, "urdf")
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link"))
    plant.Finalize()
    return plant, plant.CreateDefaultContext()


@pytest.mark.parametrize("name", sorted(CASES))
def test_rpy_and_quaternion_rebuild_the_rotation(name):
    R = CASES[name][:3, :3]
    rpy = ex.rpy_from_rotation(R)
    _assert_close(ex.rotation_from_rpy(rpy), R, 1e-14)
    _assert_close(Rotation.from_euler("xyz", rpy).as_matrix(), R, 1e-14)
    assert -math.pi / 2 <= rpy[1] <= math.pi / 2
    q = ex.quaternion_xyzw(R)
    assert q[3] >= 0
    _assert_close(Rotation.from_quat(q).as_matrix(), R, 1e-14)


@pytest.mark.parametrize("name", sorted(CASES))
def test_urdf_joint_through_drake_parser(name, tmp_path):
    X = CASES[name]
    (path,) = ex.export_calibration(X, tmp_path, formats=["urdf"])
    root = ET.parse(path).getroot()
    inner = "".join(ET.tostring(e, encoding="unicode") for e in root)
    plant, context = _plant_with(_robot_urdf(inner))
    X_EC = plant.CalcRelativeTransform(context, plant.GetFrameByName("tool0"),
                                       plant.GetFrameByName("camera_optical_frame"))
    _assert_close(X_EC.GetAsMatrix4(), X)
    joint = root.find("joint")
    assert joint.get("type") == "fixed"
    assert joint.find("parent").get("link") == "tool0"
    assert joint.find("child").get("link") == "camera_optical_frame"


def test_urdf_eye_to_hand_parent_is_the_base(tmp_path):
    X_BC = CASES["pitch-90"]
    text = ex.urdf_joint(X_BC, mode="eye_to_hand", child_frame="cell_camera_optical_frame")
    assert "X_BC" in text
    plant, context = _plant_with(_robot_urdf(text.split("-->\n")[-1]))
    X = plant.CalcRelativeTransform(context, plant.GetFrameByName("base_link"),
                                    plant.GetFrameByName("cell_camera_optical_frame"))
    _assert_close(X.GetAsMatrix4(), X_BC)


@pytest.mark.parametrize("name", ["example", "pitch+90", "180-xy"])
def test_xacro_properties_and_macro(name, tmp_path):
    X = CASES[name]
    (path,) = ex.export_calibration(X, tmp_path, formats="xacro",
                                    X_std=[0.001, 0.002, 0.003, 1e-4, 2e-4, 3e-4])
    root = ET.parse(path).getroot()
    ns = "{http://www.ros.org/wiki/xacro}"
    props = {e.get("name"): e.get("value") for e in root.findall(f"{ns}property")}
    num = {k: float(v) for k, v in props.items() if k not in ("handeye_parent", "handeye_child")}
    R = ex.rotation_from_rpy([num["handeye_roll"], num["handeye_pitch"], num["handeye_yaw"]])
    p = [num["handeye_x"], num["handeye_y"], num["handeye_z"]]
    _assert_close(make_transform(R, p), X)
    q = [num[f"handeye_q{c}"] for c in "xyzw"]
    _assert_close(make_transform(Rotation.from_quat(q).as_matrix(), p), X)
    assert (props["handeye_parent"], props["handeye_child"]) == ("tool0", "camera_optical_frame")
    # Expand the macro as xacro would (substitute ${...}; defaults for parent/child) and load
    # the result into Drake.
    macro = root.find(f"{ns}macro")
    assert macro.get("name") == "handeye_camera_joint"
    values = {**props, "parent": "tool0", "child": "camera_optical_frame"}
    body = "".join(ET.tostring(e, encoding="unicode") for e in macro)
    for key, value in sorted(values.items(), key=lambda kv: -len(kv[0])):
        body = body.replace("${" + key + "}", value)
    assert "${" not in body
    plant, context = _plant_with(_robot_urdf(body))
    X_EC = plant.CalcRelativeTransform(context, plant.GetFrameByName("tool0"),
                                       plant.GetFrameByName("camera_optical_frame"))
    _assert_close(X_EC.GetAsMatrix4(), X)
    assert "1-sigma: rotation [0.0573, 0.1146, 0.1719] deg" in path.read_text()


def _flags_to_transform(args):
    flags = dict(zip(args[::2], args[1::2]))
    p = [float(flags[f"--{c}"]) for c in "xyz"]
    q = [float(flags[f"--q{c}"]) for c in "xyzw"]
    assert abs(np.linalg.norm(q) - 1) < 1e-15
    return make_transform(Rotation.from_quat(q).as_matrix(), p), flags


@pytest.mark.parametrize("name", sorted(CASES))
def test_ros2_launch_file_and_command(name, tmp_path):
    X = CASES[name]
    launch, script = ex.export_calibration(X, tmp_path, formats=["ros2"], parent_frame="flange")
    assert (launch.name, script.name) == ("handeye.launch.py", "handeye_static_tf.sh")
    tree = ast.parse(launch.read_text())
    imports = {(n.module, a.name) for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
               for a in n.names}
    assert ("launch_ros.actions", "Node") in imports
    assert ("launch", "LaunchDescription") in imports
    functions = [n for n in tree.body if isinstance(n, ast.FunctionDef)]
    assert [f.name for f in functions] == ["generate_launch_description"]
    (node,) = [n for n in ast.walk(tree) if isinstance(n, ast.Call)
               and getattr(n.func, "id", None) == "Node"]
    kw = {k.arg: ast.literal_eval(k.value) for k in node.keywords}
    assert (kw["package"], kw["executable"]) == ("tf2_ros", "static_transform_publisher")
    X_read, flags = _flags_to_transform(kw["arguments"])
    _assert_close(X_read, X)
    assert (flags["--frame-id"], flags["--child-frame-id"]) == ("flange", "camera_optical_frame")

    lines = [s for s in script.read_text().splitlines() if s and not s.startswith("#")]
    (command,) = lines
    words = shlex.split(command)
    assert words[:4] == ["ros2", "run", "tf2_ros", "static_transform_publisher"]
    assert words[4:] == kw["arguments"]
    assert command == ex.static_transform_publisher_command(X, "flange")


@pytest.mark.parametrize("name", sorted(CASES))
def test_drake_model_directive(name, tmp_path):
    X = CASES[name]
    (path,) = ex.export_calibration(X, tmp_path, formats=["drake"],
                                    parent_frame="robot::tool0")
    plant = MultibodyPlant(0.0)
    parser = Parser(plant)
    parser.AddModelsFromString(_robot_urdf(), "urdf")
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link"))
    ProcessModelDirectives(LoadModelDirectivesFromString(path.read_text()), plant, parser)
    plant.Finalize()
    context = plant.CreateDefaultContext()
    camera = plant.GetFrameByName("camera_optical_frame")
    assert plant.GetModelInstanceName(camera.model_instance()) == "robot"
    X_EC = plant.CalcRelativeTransform(context, plant.GetFrameByName("tool0"), camera)
    _assert_close(X_EC.GetAsMatrix4(), X)


def test_unscoped_directive_parent_resolves_in_drake(tmp_path):
    plant = MultibodyPlant(0.0)
    parser = Parser(plant)
    parser.AddModelsFromString(_robot_urdf(), "urdf")
    ProcessModelDirectives(LoadModelDirectivesFromString(
        ex.drake_model_directive(TRUE_X_EC)), plant, parser)
    plant.Finalize()
    X = plant.CalcRelativeTransform(plant.CreateDefaultContext(),
                                    plant.GetFrameByName("tool0"),
                                    plant.GetFrameByName("camera_optical_frame"))
    _assert_close(X.GetAsMatrix4(), TRUE_X_EC)


@pytest.mark.parametrize("name", sorted(CASES))
def test_drake_camera_config_yaml(name, tmp_path):
    X = CASES[name]
    (path,) = ex.export_calibration(X, tmp_path, formats=["camera_config"],
                                    parent_frame="robot::tool0")
    config = yaml_load_typed(schema=CameraConfig, filename=str(path))
    assert config.X_PB.base_frame == "robot::tool0"
    X_PB = config.X_PB.GetDeterministicValue().GetAsMatrix4()
    X_BC = config.X_BC.GetDeterministicValue().GetAsMatrix4()
    _assert_close(X_PB, X)
    _assert_close(X_BC, np.eye(4), 0.0)
    _assert_close(X_PB @ X_BC, X)


def test_camera_config_applied_places_the_colour_camera(tmp_path):
    """ApplyCameraConfig builds the real RgbdSensor: its colour camera frame in the flange frame
    is X; the intrinsics come through unchanged."""
    X = CASES["pitch-90"]
    K = CameraIntrinsics(alpha_u=612.5, alpha_v=611.25, u0=319.75, v0=241.125, width=640,
                         height=480)
    (path,) = ex.export_calibration(X, tmp_path, formats=["camera_config"],
                                    parent_frame="robot::tool0", intrinsics=K)
    config = yaml_load_typed(schema=CameraConfig, filename=str(path))
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, 0.0)
    Parser(plant).AddModelsFromString(_robot_urdf(), "urdf")
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link"))
    plant.Finalize()
    ApplyCameraConfig(config=config, builder=builder, lcm=DrakeLcm("memq://"))
    diagram = builder.Build()
    (sensor,) = [s for s in diagram.GetSystems() if isinstance(s, RgbdSensor)]
    context = diagram.CreateDefaultContext()
    X_WB = sensor.body_pose_in_world_output_port().Eval(sensor.GetMyContextFromRoot(context))
    X_WE = plant.GetFrameByName("tool0").CalcPoseInWorld(plant.GetMyContextFromRoot(context))
    color = sensor.default_color_render_camera().core()
    X_EC = X_WE.inverse() @ X_WB @ color.sensor_pose_in_camera_body()
    _assert_close(X_EC.GetAsMatrix4(), X)
    info = color.intrinsics()
    assert (info.width(), info.height()) == (640, 480)
    assert (info.focal_x(), info.focal_y(), info.center_x(), info.center_y()) == \
        (612.5, 611.25, 319.75, 241.125)


@pytest.mark.parametrize("name", sorted(CASES))
def test_json_and_tum_read_back_with_the_package_readers(name, tmp_path):
    X = CASES[name]
    cov = np.diag([1e-6, 4e-6, 9e-6, 1e-8, 4e-8, 9e-8])
    json_path, tum_path = ex.export_calibration(X, tmp_path, formats=["json", "tum"],
                                                X_std=cov)
    X_json, doc = ex.read_transform_json(json_path)
    _assert_close(X_json, X, 1e-15)  # the matrix itself (pose_stream re-projects it on SO(3))
    w, x, y, z = doc["X_EC"]["quaternion_wxyz"]
    _assert_close(make_transform(Rotation.from_quat([x, y, z, w]).as_matrix(),
                                 doc["X_EC"]["translation"]), X)
    _assert_close(make_transform(ex.rotation_from_rpy(np.radians(doc["X_EC"]["rpy_deg"])),
                                 doc["X_EC"]["translation"]), X)
    assert doc["std"]["covariance"] == cov.tolist()
    np.testing.assert_allclose(doc["std"]["rotation_deg"], np.degrees([1e-3, 2e-3, 3e-3]))
    stream = read_poses(tum_path, "robot", "tum")
    assert len(stream) == 1 and stream.timestamps.tolist() == [0.0]
    _assert_close(stream.poses[0], X)


def test_eye_to_hand_defaults_and_names(tmp_path):
    paths = ex.export_calibration(CASES["180-z"], tmp_path, formats="all", mode="eye_to_hand")
    assert [p.name for p in paths] == [n for f in ex.FORMATS for n in ex.FILE_NAMES[f]]
    _, doc = ex.read_transform_json(tmp_path / "handeye.json")
    assert (doc["mode"], doc["parent_frame"]) == ("eye_to_hand", "base_link")
    assert "X_BC" in doc and "X_EC" not in doc
    for p in paths:
        text = p.read_text()
        assert "X_BC, pose of the camera C in the robot base frame B" in text or p.suffix == \
            ".json"
        assert "optical" in text


def test_every_file_states_its_rotation_convention(tmp_path):
    texts = ex.export_texts(TRUE_X_EC)
    for name in ("handeye.urdf", "handeye.xacro", "handeye_directives.yaml",
                 "handeye_camera_config.yaml"):
        assert "extrinsic X-Y-Z" in texts[name], name
    for name in ("handeye.launch.py", "handeye_static_tf.sh", "handeye.tum"):
        assert "qx, qy, qz, qw" in texts[name] or "x y z w" in texts[name], name
    assert "scalar first (w, x, y, z)" in texts["handeye.json"]


def test_never_overwrites_without_permission(tmp_path):
    ex.export_calibration(TRUE_X_EC, tmp_path, formats=["tum"])
    before = (tmp_path / "handeye.tum").read_text()
    with pytest.raises(ValueError, match=r"handeye\.tum exists; not overwriting"):
        ex.export_calibration(CASES["180-x"], tmp_path, formats=["json", "tum"])
    assert (tmp_path / "handeye.tum").read_text() == before
    assert not (tmp_path / "handeye.json").exists()  # nothing written when one file exists
    ex.export_calibration(CASES["180-x"], tmp_path, formats=["json", "tum"], overwrite=True)
    _assert_close(read_poses(tmp_path / "handeye.tum", "robot", "tum").poses[0], CASES["180-x"])


@pytest.mark.parametrize("kwargs, message", [
    ({"X": np.diag([1.0, 1.0, 1.001, 1.0])}, r"X \(rotation block\): not a rotation"),
    ({"X": np.full((4, 4), np.nan)}, r"X: .*(NaN|finite)"),
    ({"formats": ["urdf", "sdf"]}, r"formats: unknown 'sdf'"),
    ({"formats": []}, r"formats: empty list"),
    ({"formats": "all,sdf"}, r"formats: unknown 'sdf'"),
    ({"mode": "hand_in_eye"}, r"mode: expected one of eye_in_hand, eye_to_hand"),
    ({"parent_frame": "tool 0"}, r"parent_frame: expected a frame/link name"),
    ({"child_frame": 'cam"era'}, r"child_frame: expected a frame/link name"),
    ({"child_frame": "tool0"}, r"child_frame: must differ from parent_frame"),
    ({"X_std": [1, 2, 3]},
     r"X_std: expected 6 standard deviations \[rad, rad, rad, m, m, m\] or a 6×6 covariance, "
     r"got shape \(3,\)"),
    ({"X_std": [-1, 0, 0, 0, 0, 0]}, r"X_std: standard deviations must be ≥ 0"),
])
def test_bad_arguments_are_value_errors(kwargs, message, tmp_path):
    args = {"X": TRUE_X_EC, "out_dir": tmp_path / "out", **kwargs}
    with pytest.raises(ValueError, match=message):
        ex.export_calibration(**args)
    assert not (tmp_path / "out").exists()


def test_skewed_intrinsics_are_refused():
    K = CameraIntrinsics(alpha_u=600.0, alpha_v=600.0, theta=math.pi / 2 - 0.01)
    with pytest.raises(ValueError, match="intrinsics: Drake's CameraConfig has no skew"):
        ex.drake_camera_config(TRUE_X_EC, intrinsics=K)


def test_json_is_strict_json():
    doc = json.loads(ex.transform_json(TRUE_X_EC))
    assert doc["X_EC"]["rpy_deg"][2] == pytest.approx(90.0, abs=1e-12)

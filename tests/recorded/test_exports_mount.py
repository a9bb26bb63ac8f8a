"""Exports attached to a camera's mount link (``mount_offset`` = X_MC, the optical frame in the
mount link): the offset read from a camera URDF / plain xacro, the exported joint alone loaded
with the camera's own description in Drake, every other format attached to the mount, the σ
propagated, and bad descriptions refused with one line naming the argument."""

import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from pydrake.common.yaml import yaml_load_typed
from pydrake.multibody.parsing import LoadModelDirectivesFromString, Parser, \
    ProcessModelDirectives
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.sensors import CameraConfig
from scipy.spatial.transform import Rotation

from handeye_drake.apps.cli import main
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp, rotation_log
from handeye_drake.recorded import exports as ex
from handeye_drake.recorded.camera_description import CameraDescription, read_camera_offset
from handeye_drake.recorded.formats import read_poses
from tests.recorded.test_exports import CASES, _assert_close, _robot_urdf

HERE = Path(__file__).parent / "camera_descriptions"
URDF, XACRO = HERE / "d435_like.urdf", HERE / "d435_like.urdf.xacro"
OPTICAL = "camera_color_optical_frame"
DATA = Path(__file__).parents[2] / "handeye_drake" / "data"


def _origin(xyz, rpy):
    """A joint origin, composed independently of the package (scipy's extrinsic xyz = URDF)."""
    return make_transform(Rotation.from_euler("xyz", rpy).as_matrix(), xyz)


H = math.pi / 2
LINK = _origin([0.0106, 0.0175, 0.0125], [0, 0, 0])              # bottom screw → camera_link
COLOR = _origin([-0.00012, 0.015, 0.00031], [0.0021, -0.0013, 0.0007])
OPTICAL_ROT = _origin([0, 0, 0], [-H, 0, -H])


def _camera_elements(path=URDF) -> str:
    root = ET.parse(path).getroot()
    return "".join(ET.tostring(e, encoding="unicode") for e in root)


@pytest.mark.parametrize("path", [URDF, XACRO], ids=["urdf", "xacro"])
def test_offset_is_the_fixed_joints_composed(path):
    _assert_close(read_camera_offset(path, "camera_link", OPTICAL), COLOR @ OPTICAL_ROT, 1e-15)
    _assert_close(read_camera_offset(path, "camera_bottom_screw_frame", OPTICAL),
                  LINK @ COLOR @ OPTICAL_ROT, 1e-15)
    # Up to the common ancestor and down again; and the other way round.
    X = read_camera_offset(path, "camera_depth_optical_frame", OPTICAL)
    _assert_close(X, inverse(OPTICAL_ROT) @ COLOR @ OPTICAL_ROT, 1e-15)
    _assert_close(read_camera_offset(path, OPTICAL, "camera_link"),
                  inverse(COLOR @ OPTICAL_ROT), 1e-15)
    assert CameraDescription(path).chain("camera_link", OPTICAL) == [
        "camera_color_joint", "camera_color_optical_joint"]


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
@pytest.mark.parametrize("name", ["example", "pitch+90", "180-xy", "random1"])
def test_urdf_is_the_joint_alone_and_round_trips(name, mode):
    X, X_MC = CASES[name], read_camera_offset(URDF, "camera_link", OPTICAL)
    text = ex.urdf_document(X, child_frame="camera_link", mode=mode, mount_offset=X_MC,
                            optical_frame=OPTICAL)
    root = ET.fromstring(text)
    assert [e.tag for e in root] == ["joint"]          # no <link>: the camera's URDF has it
    joint = root.find("joint")
    parent = "tool0" if mode == "eye_in_hand" else "base_link"
    assert (joint.get("type"), joint.find("parent").get("link"),
            joint.find("child").get("link")) == ("fixed", parent, "camera_link")
    origin = joint.find("origin")
    X_PM = make_transform(ex.rotation_from_rpy([float(v) for v in origin.get("rpy").split()]),
                          [float(v) for v in origin.get("xyz").split()])
    _assert_close(X_PM @ X_MC, X)
    _assert_close(X_PM, X @ inverse(X_MC))


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
@pytest.mark.parametrize("name", ["example", "pitch-90", "180-x", "random0"])
def test_drake_loads_the_joint_with_the_camera_description(name, mode):
    """The exported joint and the camera's own URDF in one MultibodyPlant: it parses (no link
    declared twice) and the optical frame sits at X in the flange (or base) frame."""
    X = CASES[name]
    mount = "camera_bottom_screw_frame"                # the camera description's root link
    joint = ex.urdf_joint(X, child_frame=mount, mode=mode,
                          mount_offset=read_camera_offset(URDF, mount, OPTICAL),
                          optical_frame=OPTICAL)
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModelsFromString(_robot_urdf(joint + _camera_elements()), "urdf")
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link"))
    plant.Finalize()
    context = plant.CreateDefaultContext()
    parent = plant.GetFrameByName("tool0" if mode == "eye_in_hand" else "base_link")
    X_read = plant.CalcRelativeTransform(context, parent, plant.GetFrameByName(OPTICAL))
    _assert_close(X_read.GetAsMatrix4(), X)


def test_the_xacro_macro_adds_the_joint_alone():
    X, X_MC = CASES["random2"], read_camera_offset(XACRO, "camera_link", OPTICAL)
    text = ex.xacro_properties(X, child_frame="camera_link", mount_offset=X_MC,
                               optical_frame=OPTICAL)
    root = ET.fromstring(text)
    ns = "{http://www.ros.org/wiki/xacro}"
    props = {e.get("name"): e.get("value") for e in root.findall(f"{ns}property")}
    macro = root.find(f"{ns}macro")
    assert [e.tag for e in macro] == ["joint"]
    assert macro.find("joint").get("name") == "handeye_${child}_joint"
    assert (props["handeye_child"], props["handeye_optical_frame"]) == ("camera_link", OPTICAL)
    p = {k: float(props[f"handeye_{k}"]) for k in ("x", "y", "z", "roll", "pitch", "yaw")}
    X_EM = make_transform(ex.rotation_from_rpy([p["roll"], p["pitch"], p["yaw"]]),
                          [p["x"], p["y"], p["z"]])
    _assert_close(X_EM @ X_MC, X)


def test_every_format_attaches_the_mount(tmp_path):
    X, X_MC = CASES["pitch+90"], read_camera_offset(URDF, "camera_link", OPTICAL)
    X_EM = X @ inverse(X_MC)
    paths = ex.export_calibration(X, tmp_path, "all", parent_frame="robot::tool0",
                                  child_frame="camera_link", mount_offset=X_MC,
                                  optical_frame=OPTICAL, X_std=[1e-3] * 3 + [1e-4] * 3)
    files = {p.name: p for p in paths}
    for p in paths:
        assert "camera_link" in p.read_text() and OPTICAL in p.read_text()
    # ROS 2: parent → mount (the driver publishes mount → optical).
    words = files["handeye_static_tf.sh"].read_text().splitlines()[-1].split()[4:]
    flags = dict(zip(words[::2], words[1::2]))
    q = [float(flags[f"--q{c}"]) for c in "xyzw"]
    X_tf = make_transform(Rotation.from_quat(q).as_matrix(), [float(flags[f"--{c}"])
                                                              for c in "xyz"])
    _assert_close(X_tf @ X_MC, X)
    assert (flags["--frame-id"], flags["--child-frame-id"]) == ("robot::tool0", "camera_link")
    # Drake directives: the mount frame on the flange and the optical frame on the mount.
    plant = MultibodyPlant(0.0)
    parser = Parser(plant)
    parser.AddModelsFromString(_robot_urdf(), "urdf")
    ProcessModelDirectives(LoadModelDirectivesFromString(
        files["handeye_directives.yaml"].read_text()), plant, parser)
    plant.Finalize()
    context, tool0 = plant.CreateDefaultContext(), plant.GetFrameByName("tool0")
    for frame, expected in (("camera_link", X_EM), (OPTICAL, X)):
        _assert_close(plant.CalcRelativeTransform(context, tool0, plant.GetFrameByName(frame))
                      .GetAsMatrix4(), expected)
    # CameraConfig: the body is the mount, the colour camera is at X_MC on it.
    config = yaml_load_typed(schema=CameraConfig,
                             filename=str(files["handeye_camera_config.yaml"]))
    X_PB = config.X_PB.GetDeterministicValue().GetAsMatrix4()
    X_BC = config.X_BC.GetDeterministicValue().GetAsMatrix4()
    _assert_close(X_BC, X_MC)
    _assert_close(X_PB @ X_BC, X)
    # JSON: the calibrated optical pose, and the mount's.
    X_json, doc = ex.read_transform_json(files["handeye.json"])
    _assert_close(X_json, X)
    assert (doc["child_frame"], doc["optical_frame"]) == ("camera_link", OPTICAL)
    _assert_close(np.array(doc["mount"]["X_EM"]["matrix"]) @ np.array(doc["mount"]["X_MC"]
                                                                       ["matrix"]), X)
    # TUM: the mount's pose.
    _assert_close(read_poses(files["handeye.tum"], "robot", "tum").poses[0] @ X_MC, X)


def test_sigma_is_propagated_through_the_offset():
    """The covariance of X_EM is J P Jᵀ with the exact first-order map of the error state:
    checked against finite perturbations of X_EC."""
    X, X_MC = CASES["random1"], read_camera_offset(URDF, "camera_bottom_screw_frame", OPTICAL)
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 6))
    P = A @ A.T * 1e-6
    X_EM, P_M = ex.mount_pose(X, X_MC, P)
    J = np.zeros((6, 6))
    h = 1e-7
    for k in range(6):
        d = np.zeros(6)
        d[k] = h
        Xk = make_transform(rotation_exp(d[:3]) @ X[:3, :3], X[:3, 3] + d[3:])
        Mk = Xk @ inverse(X_MC)
        J[:3, k] = rotation_log(Mk[:3, :3] @ X_EM[:3, :3].T) / h
        J[3:, k] = (Mk[:3, 3] - X_EM[:3, 3]) / h
    np.testing.assert_allclose(P_M, J @ P @ J.T, rtol=1e-5, atol=1e-14)
    # The translation σ grows with the lever arm of the offset; the rotation σ is unchanged.
    np.testing.assert_allclose(np.diag(P_M)[:3], np.diag(P)[:3], rtol=1e-12)
    assert not np.allclose(np.diag(P_M)[3:], np.diag(P)[3:], rtol=1e-3)
    doc = json.loads(ex.transform_json(X, child_frame="camera_bottom_screw_frame",
                                       X_std=P, mount_offset=X_MC, optical_frame=OPTICAL))
    np.testing.assert_allclose(doc["mount"]["std"]["covariance"], P_M, rtol=1e-12)
    assert doc["std"]["covariance"] == P.tolist()


def _write(tmp_path, body, xacro=False) -> Path:
    ns = ' xmlns:xacro="http://www.ros.org/wiki/xacro"' if xacro else ""
    path = tmp_path / ("cam.urdf.xacro" if xacro else "cam.urdf")
    path.write_text(f'<?xml version="1.0"?>\n<robot name="c"{ns}>{body}</robot>\n')
    return path


J = '<joint name="{0}" type="fixed"><parent link="{1}"/><child link="{2}"/>{3}</joint>'


@pytest.mark.parametrize("body, xacro, message", [
    ('<link name="a"/><link name="b"/>', False, r"optical_frame: no chain of joints between "
     r"'a' and 'b' .*separate trees"),
    (J.format("j", "a", "b", '<origin xyz="0 0"/>'), False, r"joint 'j' origin xyz: expected "
     "3 finite numbers"),
    (J.format("j", "a", "b", '<origin rpy="0 ${q} 0"/>'), True, r"no property 'q'"),
    ('<xacro:macro name="m" params="p"/>' + J.format("j", "a", "b", ""), True,
     r"<xacro:macro> is not supported .*xacro FILE > camera.urdf"),
    ('<xacro:include filename="x.xacro"/>', True, r"<xacro:include> is not supported"),
    (J.format("j", "a", "b", '<origin xyz="$(arg x) 0 0"/>'), True, r"\$\(\.\.\.\) substitution"),
    (J.format("j", "a", "b", '<origin xyz="${__import__(1)} 0 0"/>'), True,
     r"cannot evaluate .*only numbers, properties"),
    (J.format("j", "a", "b", "") + J.format("k", "a", "b", ""), False,
     "link 'b' is the child of two joints"),
    # Bounded time and memory, and the argument named, for arithmetic a file should not hold.
    (J.format("j", "a", "b", '<origin xyz="${9**9**9} 0 0"/>'), True,
     r"cannot evaluate .*result too large|cannot evaluate .*Numerical result out of range"),
    (J.format("j", "a", "b", '<origin xyz="${\'a\' * 1000000000} 0 0"/>'), True,
     r"cannot evaluate .*not a number"),
    (J.format("j", "a", "b", '<origin xyz="${sqrt(-1)} 0 0"/>'), True,
     r"cannot evaluate .*math domain error"),
    (J.format("j", "a", "b", '<origin xyz="${(-8)**(1/3)} 0 0"/>'), True,
     r"cannot evaluate .*not a real number"),
])
def test_bad_descriptions_are_one_line_value_errors(body, xacro, message, tmp_path):
    with pytest.raises(ValueError, match=message) as e:
        read_camera_offset(_write(tmp_path, body, xacro), "a", "b")
    assert "\n" not in str(e.value)


def test_not_xml_and_not_a_robot(tmp_path):
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot><link name='a'></robot>")
    with pytest.raises(ValueError, match="camera_urdf: .* is not well-formed XML"):
        read_camera_offset(bad, "a", "b")
    bad.write_text("<sdf/>")
    with pytest.raises(ValueError, match=r"not a URDF/xacro file \(root element <sdf>"):
        read_camera_offset(bad, "a", "b")


def test_export_arguments_of_a_mount_are_checked():
    X_MC = read_camera_offset(URDF, "camera_link", OPTICAL)
    with pytest.raises(ValueError, match="child_frame: with mount_offset, child_frame names "
                                         "the camera's mount link"):
        ex.export_texts(CASES["example"], mount_offset=X_MC)   # child = optical = default
    with pytest.raises(ValueError, match="optical_frame: names the optical frame of a "
                                         "mount_offset"):
        ex.export_texts(CASES["example"], optical_frame=OPTICAL)
    with pytest.raises(ValueError, match=r"mount_offset \(rotation block\): not a rotation"):
        ex.export_texts(CASES["example"], child_frame="camera_link",
                        mount_offset=np.diag([1.0, 1.0, 1.1, 1.0]))


# --------------------------------------------------------------------------------- command
def _calibrate(tmp_path, *extra):
    return main(["calibrate", "--robot", str(DATA / "example_robot.tum"), "--camera",
                 str(DATA / "example_camera.tum"), "--out", str(tmp_path / "out"), *extra])


def test_calibrate_exports_to_the_mount_from_a_camera_urdf(tmp_path, capsys):
    code = _calibrate(tmp_path, "--export", "urdf,json", "--child-frame", "camera_link",
                      "--camera-urdf", str(XACRO), "--optical-frame", OPTICAL)
    out = capsys.readouterr().out
    assert code == 0, out
    assert "exports attach the mount link camera_link" in out
    assert "camera_link already has a parent joint" in out      # the realsense-like layout
    X_EC, doc = ex.read_transform_json(tmp_path / "out" / "handeye.json")
    root = ET.parse(tmp_path / "out" / "handeye.urdf").getroot()
    assert [e.tag for e in root] == ["joint"]
    origin = root.find("joint/origin")
    X_EM = make_transform(ex.rotation_from_rpy([float(v) for v in origin.get("rpy").split()]),
                          [float(v) for v in origin.get("xyz").split()])
    _assert_close(X_EM @ read_camera_offset(URDF, "camera_link", OPTICAL), X_EC)
    calibrated = json.loads((tmp_path / "out" / "calibration.json").read_text())
    _assert_close(np.array(calibrated["X_EC"]["matrix"]), X_EC)


def test_calibrate_exports_to_the_mount_from_an_offset(tmp_path):
    code = _calibrate(tmp_path, "--export", "json", "--child-frame", "camera_link",
                      "--mount-offset", "0,0.015,0,-0.5,0.5,-0.5,0.5")
    assert code == 0
    X_EC, doc = ex.read_transform_json(tmp_path / "out" / "handeye.json")
    assert doc["optical_frame"] == "camera_optical_frame"
    X_MC = np.array(doc["mount"]["X_MC"]["matrix"])
    _assert_close(X_MC, _origin([0, 0.015, 0], [-H, 0, -H]), 1e-15)
    _assert_close(np.array(doc["mount"]["X_EM"]["matrix"]) @ X_MC, X_EC)


@pytest.mark.parametrize("args, message", [
    (["--camera-urdf", URDF, "--child-frame", "camera_lnk", "--optical-frame", OPTICAL],
     "--child-frame: no link 'camera_lnk' in"),
    (["--camera-urdf", URDF, "--child-frame", "camera_link", "--optical-frame", "optical"],
     "--optical-frame: no link 'optical' in"),
    (["--camera-urdf", URDF, "--child-frame", "camera_link", "--optical-frame",
      "camera_pan_optical_frame"], "--camera-urdf: joint 'camera_pan_joint' (revolute"),
    (["--camera-urdf", "missing.urdf", "--child-frame", "camera_link", "--optical-frame",
      OPTICAL], "--camera-urdf: cannot read missing.urdf"),
    (["--camera-urdf", DATA / "example_robot.tum", "--child-frame", "camera_link",
      "--optical-frame", OPTICAL], "--camera-urdf: ", ),
    (["--camera-urdf", URDF, "--child-frame", "camera_link"], "--optical-frame: with "
     "--camera-urdf, name the optical frame"),
    (["--mount-offset", "0,0,0,-0.5,0.5,-0.5,0.5"], "--child-frame: with --mount-offset, "
     "name the camera's mount link"),
    (["--mount-offset", "0,0,0,1,1,0,0", "--child-frame", "camera_link"],
     "--mount-offset: the quaternion"),
    (["--mount-offset", "0,0,0", "--child-frame", "camera_link"],
     "--mount-offset: expected 7 comma-separated numbers"),
    (["--optical-frame", OPTICAL], "--optical-frame: names the optical frame of a mount link"),
])
def test_calibrate_refuses_bad_mount_arguments(args, message, tmp_path, capsys):
    export = [] if "--optical-frame" in args and len(args) == 2 else ["--export", "urdf"]
    code = _calibrate(tmp_path, *export, *map(str, args))
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err, err
    assert "Traceback" not in err and not (tmp_path / "out").exists()


def test_calibrate_mount_needs_export(tmp_path, capsys):
    code = _calibrate(tmp_path, "--mount-offset", "0,0,0,0,0,0,1", "--child-frame", "cam")
    err = capsys.readouterr().err
    assert code == 2 and "--mount-offset: attaches the exports to a mount link; give --export" \
        in err

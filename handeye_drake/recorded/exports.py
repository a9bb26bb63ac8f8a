"""Exports of a hand-eye result into the files a robot cell consumes (URDF, xacro, ROS 2, Drake).

The transform exported is ``X_EC`` (``mode="eye_in_hand"``: the camera C in the end-effector /
flange frame E; parent = the flange link, e.g. ``tool0``) or ``X_BC`` (``mode="eye_to_hand"``:
the camera in the robot base B; parent = the base link, e.g. ``base_link``). Lengths in metres.

Camera frame. Like OpenCV, this package's camera frame C has +x right (image columns), +y down
(image rows), +z forward (the optical axis). ROS calls that frame the *optical* frame
(``<camera>_optical_frame``, REP 103/105), distinct from the ROS body frame ``<camera>_link``
(x forward, y left, z up); hence the default child frame ``camera_optical_frame``. If your robot
description attaches the camera by its ``camera_link``, keep that link and attach it to the
optical frame exported here with the fixed rotation rpy = (−π/2, 0, −π/2) optical→link, or
export the pose of the link yourself (``X_EC @ X_C_link``). Drake's camera frame (``CameraInfo``,
``RgbdSensor``) is the same as OpenCV's.

Rotation conventions written in every file:

- RPY = roll, pitch, yaw about the *fixed* parent axes X, then Y, then Z (extrinsic X-Y-Z),
  i.e. R = Rz(yaw) · Ry(pitch) · Rx(roll). That is URDF's ``rpy``, Drake's ``RollPitchYaw``
  and ``!Rpy``, and ``estimation.se3.rpy``. Radians in URDF/xacro, degrees in Drake ``!Rpy``.
- Quaternions: Hamilton, unit, scalar-last (x, y, z, w) for ROS (tf2, ``static_transform_
  publisher``) and TUM; scalar-first (w, x, y, z) in the JSON, like the rest of the package.
  The sign is chosen with w ≥ 0.

Numbers are written with ``repr`` of the double (shortest text that reads back to the same
double), so every export round-trips to ~1e-15; RPY angles are computed so that they rebuild the
rotation to machine precision even at gimbal lock (pitch = ±90°), where roll and yaw are not
unique. Files are never overwritten unless ``overwrite=True``.

Uncertainty (optional ``X_std``): 6 standard deviations [δθx, δθy, δθz (rad), δtx, δty, δtz
(m)] or a 6×6 covariance of that error state, in the package's convention: R = exp([δθ]×) R̂
(δθ about the parent frame's axes) and t = t̂ + δt. It is written as comments (and in the JSON).

Nothing here imports Drake or ROS: the functions return text.
"""

from __future__ import annotations

import json
import math
import re
import shlex
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..estimation.validation import as_matrix, as_transform, check_covariance

FORMATS = ("urdf", "xacro", "ros2", "drake", "camera_config", "json", "tum")
MODES = ("eye_in_hand", "eye_to_hand")
DEFAULT_CHILD_FRAME = "camera_optical_frame"
DEFAULT_PARENT_FRAMES = {"eye_in_hand": "tool0", "eye_to_hand": "base_link"}

#: Largest accepted max(‖RᵀR − I‖_F, |det R − 1|) of the exported rotation. Exported files round
#: trip to 1e-9, so the input must be a rotation to that precision (orthonormalize it first).
ROTATION_TOLERANCE = 1e-9

#: File names written by ``export_calibration`` for each format.
FILE_NAMES = {
    "urdf": ("handeye.urdf",),
    "xacro": ("handeye.xacro",),
    "ros2": ("handeye.launch.py", "handeye_static_tf.sh"),
    "drake": ("handeye_directives.yaml",),
    "camera_config": ("handeye_camera_config.yaml",),
    "json": ("handeye.json",),
    "tum": ("handeye.tum",),
}

_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_./:-]*$")
_RPY_LINE = ("RPY = roll, pitch, yaw about the fixed parent axes X, then Y, then Z (extrinsic "
             "X-Y-Z: R = Rz(yaw) Ry(pitch) Rx(roll); URDF rpy = Drake RollPitchYaw)")
_OPTICAL_LINE = ("camera frame: OpenCV/ROS optical convention, x right, y down, z forward "
                 "(ROS *_optical_frame)")


# ------------------------------------------------------------------------------------ numbers
def _num(v) -> str:
    """Shortest text that reads back to the same double (never '-0.0' noise for exact zeros)."""
    v = float(v)
    return "0.0" if v == 0.0 else repr(v)


def rpy_from_rotation(R) -> np.ndarray:
    """Roll, pitch, yaw (rad; extrinsic X-Y-Z, URDF/Drake convention) that rebuild R to machine
    precision, also at gimbal lock (|pitch| = 90°, where only roll ∓ yaw is defined; yaw is then
    set from the first column and roll absorbs the rest). Pitch in [−π/2, π/2]."""
    R = np.asarray(R, dtype=float)
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    yaw = math.atan2(R[1, 0], R[0, 0]) if math.hypot(R[0, 0], R[1, 0]) > 1e-300 else 0.0
    # Roll from what remains (≈ Rx(roll)), so that the triple reproduces R even when yaw is
    # ill-determined near gimbal lock.
    M = _ry(pitch).T @ _rz(yaw).T @ R
    roll = math.atan2(M[2, 1], M[1, 1])
    return np.array([roll, pitch, yaw])


def rotation_from_rpy(rpy) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll) (the inverse of ``rpy_from_rotation``)."""
    r, p, y = (float(v) for v in rpy)
    return _rz(y) @ _ry(p) @ _rx(r)


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def quaternion_xyzw(R) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of R, with w ≥ 0 (ROS / TUM order)."""
    q = Rotation.from_matrix(np.asarray(R, dtype=float)).as_quat()
    q = q / np.linalg.norm(q)
    return -q if q[3] < 0 else q


# --------------------------------------------------------------------------------- arguments
def _check_X(X) -> np.ndarray:
    try:
        M = as_transform(X, "X", rigid=True, tol=ROTATION_TOLERANCE)
    except ValueError as e:
        if "rotation block" not in str(e):
            raise
        raise ValueError(f"{e}; exports round-trip to 1e-9, so X's rotation must be orthonormal "
                         "to that precision: project it first (estimation.orthonormalize)") \
            from None
    if np.abs(M[3] - [0.0, 0.0, 0.0, 1.0]).max() != 0.0:
        M = M.copy()
        M[3] = [0.0, 0.0, 0.0, 1.0]
    return M


def _check_mode(mode) -> str:
    if mode not in MODES:
        raise ValueError(f"mode: expected one of {', '.join(MODES)}, got {mode!r}")
    return mode


def _check_name(value, name: str) -> str:
    if not isinstance(value, str) or not _NAME.match(value):
        raise ValueError(f"{name}: expected a frame/link name of letters, digits and _ . / : - "
                         f"(no spaces or quotes), got {value!r}")
    return value


def _frames(mode, parent_frame, child_frame) -> tuple[str, str, str]:
    mode = _check_mode(mode)
    parent = DEFAULT_PARENT_FRAMES[mode] if parent_frame is None else parent_frame
    _check_name(parent, "parent_frame")
    _check_name(child_frame, "child_frame")
    if parent == child_frame:
        raise ValueError(f"child_frame: must differ from parent_frame, both are {parent!r}")
    return mode, parent, child_frame


def _std(X_std) -> tuple[np.ndarray, np.ndarray | None] | None:
    """(6 standard deviations, covariance or None) from a 6-vector or a 6×6 covariance."""
    if X_std is None:
        return None
    try:
        shape = np.shape(X_std) if not isinstance(X_std, (str, bytes)) else None
    except ValueError:  # ragged nesting
        shape = None
    if shape == (6, 6):
        P = check_covariance(X_std, "X_std", 6)
        return np.sqrt(np.diag(P)), P
    if shape != (6,):
        raise ValueError("X_std: expected 6 standard deviations [rad, rad, rad, m, m, m] or a "
                         f"6×6 covariance, got {f'shape {shape}' if shape else repr(X_std)[:60]}")
    s = as_matrix(X_std, "X_std", (6,))
    if np.any(s < 0):
        raise ValueError(f"X_std: standard deviations must be ≥ 0, got {s.tolist()}")
    return s, None


def _description(mode: str) -> tuple[str, str]:
    if mode == "eye_in_hand":
        return "X_EC", "pose of the camera C in the end-effector (flange) frame E"
    return "X_BC", "pose of the camera C in the robot base frame B"


def _header(X_name: str, what: str, parent: str, child: str, extra: list[str],
            std) -> list[str]:
    lines = [f"handeye_drake calibration: {X_name}, {what}",
             f"parent frame: {parent}; child frame: {child}; lengths in metres",
             _OPTICAL_LINE] + extra
    if std is not None:
        s = std[0]
        lines.append("1-sigma: rotation [" + ", ".join(f"{math.degrees(v):.4g}" for v in s[:3])
                     + "] deg about the parent axes (R = exp([dtheta]x) R_hat), translation ["
                     + ", ".join(f"{1000 * v:.4g}" for v in s[3:]) + "] mm")
    return lines


def _parts(X):
    xyz = X[:3, 3]
    return xyz, rpy_from_rotation(X[:3, :3]), quaternion_xyzw(X[:3, :3])


def _xml_comment(lines: list[str], indent: str = "") -> str:
    return "\n".join(f"{indent}<!-- {line.replace('--', '- -')} -->" for line in lines)


# ---------------------------------------------------------------------------------- formats
def urdf_joint(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME, mode="eye_in_hand",
               joint_name=None, X_std=None) -> str:
    """A URDF fragment: the child ``<link>`` and a ``<joint type="fixed">`` from ``parent_frame``
    to it with ``<origin xyz rpy>`` = X (metres, radians, RPY as in the module docstring).
    Paste it inside your robot's ``<robot>`` element."""
    X = _check_X(X)
    mode, parent, child = _frames(mode, parent_frame, child_frame)
    joint_name = f"{child}_joint" if joint_name is None else _check_name(joint_name,
                                                                         "joint_name")
    xyz, rpy, _ = _parts(X)
    X_name, what = _description(mode)
    head = _header(X_name, what, parent, child, [_RPY_LINE + "; radians"], _std(X_std))
    return "\n".join([
        _xml_comment(head),
        f'<link name="{child}"/>',
        f'<joint name="{joint_name}" type="fixed">',
        f'  <parent link="{parent}"/>',
        f'  <child link="{child}"/>',
        f'  <origin xyz="{" ".join(_num(v) for v in xyz)}" '
        f'rpy="{" ".join(_num(v) for v in rpy)}"/>',
        "</joint>",
    ]) + "\n"


def urdf_document(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME, mode="eye_in_hand",
                  joint_name=None, X_std=None, robot_name="handeye_calibration") -> str:
    """``urdf_joint`` wrapped in a ``<robot>`` element (a well-formed XML file; the parent link is
    not in it: copy the link and joint into your robot description)."""
    _check_name(robot_name, "robot_name")
    body = urdf_joint(X, parent_frame, child_frame, mode, joint_name, X_std)
    indented = "\n".join("  " + line for line in body.rstrip("\n").splitlines())
    return (f'<?xml version="1.0"?>\n<robot name="{robot_name}">\n'
            f"  <!-- Copy the link and joint below into your robot description. -->\n"
            f"{indented}\n</robot>\n")


def xacro_properties(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME, mode="eye_in_hand",
                     X_std=None, prefix="handeye_") -> str:
    """A xacro file: properties ``{prefix}x, y, z, roll, pitch, yaw`` (metres, radians),
    ``{prefix}qx … qw``, ``{prefix}parent``, ``{prefix}child``, and a macro
    ``{prefix}camera_joint`` (params ``parent``, ``child`` defaulting to them) that adds the
    fixed joint and child link. Include it with ``<xacro:include filename="handeye.xacro"/>``
    and call ``<xacro:handeye_camera_joint/>``."""
    X = _check_X(X)
    mode, parent, child = _frames(mode, parent_frame, child_frame)
    if not isinstance(prefix, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", prefix):
        raise ValueError(f"prefix: expected an identifier, got {prefix!r}")
    xyz, rpy, q = _parts(X)
    X_name, what = _description(mode)
    head = _header(X_name, what, parent, child,
                   [_RPY_LINE + "; radians", "quaternion order (qx, qy, qz, qw)"], _std(X_std))
    props = [("x", xyz[0]), ("y", xyz[1]), ("z", xyz[2]), ("roll", rpy[0]), ("pitch", rpy[1]),
             ("yaw", rpy[2]), ("qx", q[0]), ("qy", q[1]), ("qz", q[2]), ("qw", q[3])]
    p = prefix
    lines = ['<?xml version="1.0"?>', '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">',
             _xml_comment(head, "  ")]
    lines += [f'  <xacro:property name="{p}{k}" value="{_num(v)}"/>' for k, v in props]
    lines += [f'  <xacro:property name="{p}parent" value="{parent}"/>',
              f'  <xacro:property name="{p}child" value="{child}"/>',
              f'  <xacro:macro name="{p}camera_joint" params="parent:=${{{p}parent}} '
              f'child:=${{{p}child}}">',
              '    <link name="${child}"/>',
              '    <joint name="${child}_joint" type="fixed">',
              '      <parent link="${parent}"/>',
              '      <child link="${child}"/>',
              f'      <origin xyz="${{{p}x}} ${{{p}y}} ${{{p}z}}" '
              f'rpy="${{{p}roll}} ${{{p}pitch}} ${{{p}yaw}}"/>',
              "    </joint>",
              "  </xacro:macro>",
              "</robot>"]
    return "\n".join(lines) + "\n"


def static_transform_publisher_arguments(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME,
                                         mode="eye_in_hand") -> list[str]:
    """The arguments of ROS 2 ``tf2_ros static_transform_publisher`` (new-style flags, Humble
    and later): ``--x --y --z --qx --qy --qz --qw --frame-id PARENT --child-frame-id CHILD``."""
    X = _check_X(X)
    mode, parent, child = _frames(mode, parent_frame, child_frame)
    xyz, _, q = _parts(X)
    args = []
    for flag, v in zip(("--x", "--y", "--z", "--qx", "--qy", "--qz", "--qw"),
                       list(xyz) + list(q)):
        args += [flag, _num(v)]
    return args + ["--frame-id", parent, "--child-frame-id", child]


def static_transform_publisher_command(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME,
                                       mode="eye_in_hand") -> str:
    """The one-line shell command publishing X on /tf_static:
    ``ros2 run tf2_ros static_transform_publisher --x … --child-frame-id CHILD``."""
    args = static_transform_publisher_arguments(X, parent_frame, child_frame, mode)
    return shlex.join(["ros2", "run", "tf2_ros", "static_transform_publisher"] + args)


def ros2_launch(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME, mode="eye_in_hand",
                X_std=None, node_name="handeye_static_tf") -> str:
    """A ROS 2 Python launch file: one ``launch_ros.actions.Node`` running ``tf2_ros
    static_transform_publisher`` with ``static_transform_publisher_arguments``."""
    args = static_transform_publisher_arguments(X, parent_frame, child_frame, mode)
    _check_name(node_name, "node_name")
    mode, parent, child = _frames(mode, parent_frame, child_frame)
    X_name, what = _description(mode)
    head = _header(X_name, what, parent, child,
                   ["translation --x --y --z in metres; rotation as a unit quaternion in ROS "
                    "order (qx, qy, qz, qw)",
                    "publishes the transform of child_frame in frame_id on /tf_static"],
                   _std(X_std))
    pairs = [f"                {args[i]!r}, {args[i + 1]!r}," for i in range(0, len(args), 2)]
    return "\n".join(
        [f"# {line}" for line in head] +
        ["", "from launch import LaunchDescription", "from launch_ros.actions import Node", "",
         "", "def generate_launch_description():",
         "    return LaunchDescription([",
         "        Node(",
         "            package='tf2_ros',",
         "            executable='static_transform_publisher',",
         f"            name={node_name!r},",
         "            arguments=["] + pairs +
        ["            ],",
         "        ),",
         "    ])"]) + "\n"


def _static_tf_script(X, parent, child, mode, X_std) -> str:
    X_name, what = _description(mode)
    head = _header(X_name, what, parent, child,
                   ["rotation as a unit quaternion in ROS order (qx, qy, qz, qw)"], _std(X_std))
    return ("#!/bin/sh\n" + "".join(f"# {line}\n" for line in head) +
            static_transform_publisher_command(X, parent, child, mode) + "\n")


def drake_model_directive(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME,
                          mode="eye_in_hand", X_std=None) -> str:
    """A Drake model-directives YAML with one ``add_frame``: the camera frame ``child_frame``
    posed by ``X_PF`` = X on ``parent_frame`` (use Drake's scoped name, e.g. ``ur5e::tool0``,
    when several models have that frame). Load it with
    ``LoadModelDirectives``/``ProcessModelDirectives`` after the directive adding the robot."""
    X = _check_X(X)
    mode, parent, child = _frames(mode, parent_frame, child_frame)
    xyz, rpy, _ = _parts(X)
    X_name, what = _description(mode)
    head = _header(X_name, what, parent, child,
                   [_RPY_LINE + "; !Rpy deg: [roll, pitch, yaw] in degrees"], _std(X_std))
    deg = [math.degrees(v) for v in rpy]
    return "\n".join(
        [f"# {line}" for line in head] +
        ["directives:",
         "- add_frame:",
         f"    name: {child}",
         "    X_PF:",
         f"      base_frame: {parent}",
         f"      translation: [{', '.join(_num(v) for v in xyz)}]",
         f"      rotation: !Rpy {{ deg: [{', '.join(_num(v) for v in deg)}] }}"]) + "\n"


def drake_camera_config(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME,
                        mode="eye_in_hand", X_std=None, intrinsics=None,
                        name="handeye_camera") -> str:
    """A Drake ``CameraConfig`` YAML (load with ``yaml_load_typed(schema=CameraConfig, …)`` or
    paste under a scenario's ``cameras:``) placing the simulated camera where it was calibrated.

    What is set: ``X_PB`` = X with ``base_frame: parent_frame`` (the sensor body B in the parent
    frame), and ``X_BC`` = ``X_BD`` = identity, so the colour (and depth) camera frame — Drake's
    camera frame, x right, y down, z forward like OpenCV's — coincides with the body: the
    colour camera's pose in the parent is X_PB · X_BC = X. ``intrinsics`` (an object with
    ``alpha_u, alpha_v, u0, v0, width, height`` and no skew, e.g. ``vision.CameraIntrinsics`` or
    ``bags.CameraInfo``) sets ``width, height, focal: !FocalLength {x: fx, y: fy}, center_x,
    center_y`` (Drake's pixel (0, 0) is the centre of the first pixel, as in OpenCV); without it
    Drake's defaults remain. Lens distortion has no Drake counterpart and is not written.
    """
    X = _check_X(X)
    mode, parent, child = _frames(mode, parent_frame, child_frame)
    _check_name(name, "name")
    xyz, rpy, _ = _parts(X)
    X_name, what = _description(mode)
    head = _header(X_name, what, parent, child,
                   [_RPY_LINE + "; !Rpy deg: [roll, pitch, yaw] in degrees",
                    "X_PB: camera body B in base_frame; X_BC = X_BD = identity, so the colour "
                    f"camera frame (Drake: x right, y down, z forward) is {child}"],
                   _std(X_std))
    deg = [math.degrees(v) for v in rpy]
    lines = [f"# {line}" for line in head] + [f"name: {name}"]
    if intrinsics is not None:
        lines += _intrinsics_lines(intrinsics)
    lines += ["X_PB:",
              f"  base_frame: {parent}",
              f"  translation: [{', '.join(_num(v) for v in xyz)}]",
              f"  rotation: !Rpy {{ deg: [{', '.join(_num(v) for v in deg)}] }}",
              "X_BC:",
              "  translation: [0.0, 0.0, 0.0]",
              "  rotation: !Rpy { deg: [0.0, 0.0, 0.0] }",
              "X_BD:",
              "  translation: [0.0, 0.0, 0.0]",
              "  rotation: !Rpy { deg: [0.0, 0.0, 0.0] }"]
    return "\n".join(lines) + "\n"


def _intrinsics_lines(intrinsics) -> list[str]:
    try:
        fx, fy, cx, cy = (float(getattr(intrinsics, k)) for k in ("alpha_u", "alpha_v", "u0",
                                                                  "v0"))
        w, h = int(intrinsics.width), int(intrinsics.height)
    except (AttributeError, TypeError, ValueError):
        raise ValueError("intrinsics: expected an object with alpha_u, alpha_v, u0, v0, width, "
                         f"height (e.g. CameraIntrinsics), got {type(intrinsics).__name__}") \
            from None
    theta = getattr(intrinsics, "theta", math.pi / 2)
    if abs(float(theta) - math.pi / 2) > 1e-12:
        raise ValueError(f"intrinsics: Drake's CameraConfig has no skew; theta must be π/2, got "
                         f"{theta!r}")
    if not (all(math.isfinite(v) for v in (fx, fy, cx, cy)) and fx > 0 and fy > 0 and w > 0
            and h > 0 and 0 < cx < w and 0 < cy < h):
        raise ValueError(f"intrinsics: need fx, fy > 0 and 0 < cx < width, 0 < cy < height, got "
                         f"fx={fx}, fy={fy}, cx={cx}, cy={cy}, width={w}, height={h}")
    return [f"width: {w}", f"height: {h}",
            f"focal: !FocalLength {{ x: {_num(fx)}, y: {_num(fy)} }}",
            f"center_x: {_num(cx)}", f"center_y: {_num(cy)}"]


def transform_json(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME, mode="eye_in_hand",
                   X_std=None) -> str:
    """JSON with the transform under its name (``X_EC`` or ``X_BC``), laid out like the X_EC
    block of ``calibrate``'s ``calibration.json``: ``matrix`` (row-major 4×4),
    ``translation``, ``quaternion_wxyz``, ``rpy_deg``; plus frames, mode, conventions and, with
    X_std, ``std`` (``rotation_deg``, ``translation``, and ``covariance`` when given)."""
    X = _check_X(X)
    mode, parent, child = _frames(mode, parent_frame, child_frame)
    xyz, rpy, q = _parts(X)
    X_name, what = _description(mode)
    doc = {
        "description": f"{X_name}: {what}",
        "mode": mode,
        "parent_frame": parent,
        "child_frame": child,
        "conventions": {
            "units": "metres; radians unless _deg",
            "rpy": "roll, pitch, yaw about the fixed parent axes X, Y, Z (extrinsic X-Y-Z, "
                   "URDF rpy = Drake RollPitchYaw)",
            "quaternion": "Hamilton, scalar first (w, x, y, z), w >= 0",
            "camera_frame": "x right, y down, z forward (OpenCV; ROS *_optical_frame)",
        },
        X_name: {
            "matrix": X.tolist(),
            "translation": xyz.tolist(),
            "quaternion_wxyz": [q[3], q[0], q[1], q[2]],
            "rpy_deg": [math.degrees(v) for v in rpy],
        },
    }
    std = _std(X_std)
    if std is not None:
        doc["std"] = {"rotation_deg": np.degrees(std[0][:3]).tolist(),
                      "translation": std[0][3:].tolist(),
                      "error_state": "R = exp([dtheta]x) R_hat (dtheta about the parent axes, "
                                     "rad), t = t_hat + dt"}
        if std[1] is not None:
            doc["std"]["covariance"] = std[1].tolist()
    return json.dumps(doc, indent=2, allow_nan=False) + "\n"


def read_transform_json(path) -> tuple[np.ndarray, dict]:
    """Reads a ``transform_json`` file back: (the 4×4 matrix, the whole document). The matrix is
    validated as a rigid transform (ValueError naming the file otherwise)."""
    from .formats import pose_stream
    try:
        doc = json.loads(Path(path).read_text())
        name = "X_EC" if doc.get("mode") == "eye_in_hand" else "X_BC"
        matrix = doc[name]["matrix"]
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as e:
        raise ValueError(f"{path}: not a handeye_drake transform JSON ({e})") from None
    return pose_stream([matrix], source=str(path)).poses[0], doc


def tum_text(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME, mode="eye_in_hand",
             X_std=None, timestamp: float = 0.0) -> str:
    """One TUM line ``timestamp tx ty tz qx qy qz qw`` (quaternion scalar last) after ``#``
    comments; ``formats.read_poses(path, "robot", "tum")`` reads it back."""
    X = _check_X(X)
    mode, parent, child = _frames(mode, parent_frame, child_frame)
    t = float(timestamp)
    if not math.isfinite(t):
        raise ValueError(f"timestamp: must be finite, got {timestamp!r}")
    xyz, _, q = _parts(X)
    X_name, what = _description(mode)
    head = _header(X_name, what, parent, child,
                   ["timestamp tx ty tz qx qy qz qw (quaternion scalar last, x y z w)"],
                   _std(X_std))
    return "".join(f"# {line}\n" for line in head) + \
        " ".join(_num(v) for v in [t, *xyz, *q]) + "\n"


# ------------------------------------------------------------------------------- entry point
def export_texts(X, formats=FORMATS, mode="eye_in_hand", parent_frame=None,
                 child_frame=DEFAULT_CHILD_FRAME, X_std=None, intrinsics=None) -> dict:
    """{file name: text} of every file ``export_calibration`` would write (nothing written)."""
    formats = parse_formats(formats)
    mode, parent, child = _frames(mode, parent_frame, child_frame)
    X = _check_X(X)
    _std(X_std)
    out = {}
    for fmt in formats:
        if fmt == "urdf":
            out["handeye.urdf"] = urdf_document(X, parent, child, mode, X_std=X_std)
        elif fmt == "xacro":
            out["handeye.xacro"] = xacro_properties(X, parent, child, mode, X_std)
        elif fmt == "ros2":
            out["handeye.launch.py"] = ros2_launch(X, parent, child, mode, X_std)
            out["handeye_static_tf.sh"] = _static_tf_script(X, parent, child, mode, X_std)
        elif fmt == "drake":
            out["handeye_directives.yaml"] = drake_model_directive(X, parent, child, mode, X_std)
        elif fmt == "camera_config":
            out["handeye_camera_config.yaml"] = drake_camera_config(X, parent, child, mode,
                                                                    X_std, intrinsics)
        elif fmt == "json":
            out["handeye.json"] = transform_json(X, parent, child, mode, X_std)
        else:
            out["handeye.tum"] = tum_text(X, parent, child, mode, X_std)
    return out


def parse_formats(formats) -> tuple[str, ...]:
    """Validated tuple of formats from a sequence or a comma-separated string ("all" = every
    format), in ``FORMATS`` order, without duplicates."""
    if isinstance(formats, str):
        formats = [f.strip() for f in formats.split(",") if f.strip()]
    try:
        items = list(formats)
    except TypeError:
        raise ValueError(f"formats: expected names from {', '.join(FORMATS)} or 'all', got "
                         f"{formats!r}") from None
    unknown = [f for f in items if f not in FORMATS and f != "all"]
    if "all" in items and not unknown:
        return FORMATS
    if unknown or not items:
        what = f"unknown {', '.join(map(repr, unknown))}" if unknown else "empty list"
        raise ValueError(f"formats: {what}; expected names from {', '.join(FORMATS)} or 'all'")
    return tuple(f for f in FORMATS if f in items)


def export_calibration(X, out_dir, formats=FORMATS, mode="eye_in_hand", parent_frame=None,
                       child_frame=DEFAULT_CHILD_FRAME, X_std=None, overwrite=False,
                       intrinsics=None) -> list[Path]:
    """Writes the calibrated transform into ``out_dir`` (created) in each of ``formats``.

    Args:
        X: 4×4 ``X_EC`` (eye-in-hand: camera C in end-effector E) or ``X_BC`` (eye-to-hand:
            camera in base B), metres; its rotation must be orthonormal to 1e-9.
        out_dir: output directory.
        formats: names from ``FORMATS`` (or "all", or a comma-separated string):
            urdf → handeye.urdf; xacro → handeye.xacro; ros2 → handeye.launch.py and
            handeye_static_tf.sh; drake → handeye_directives.yaml; camera_config →
            handeye_camera_config.yaml; json → handeye.json; tum → handeye.tum.
        mode: "eye_in_hand" or "eye_to_hand" (names the transform and the default parent).
        parent_frame: the link/frame X is expressed in (default ``tool0`` for eye-in-hand,
            ``base_link`` for eye-to-hand).
        child_frame: the camera frame's name (default ``camera_optical_frame``: X places the
            OpenCV/ROS optical frame, x right, y down, z forward).
        X_std: None, 6 standard deviations [rad ×3, m ×3] or a 6×6 covariance (written as
            comments and in the JSON).
        overwrite: replace existing files; otherwise an existing file is a ValueError naming it
            (checked for every file before anything is written).
        intrinsics: optional camera intrinsics for the CameraConfig (see
            ``drake_camera_config``).

    Returns:
        The paths written, in ``FORMATS`` order.
    """
    texts = export_texts(X, formats, mode, parent_frame, child_frame, X_std, intrinsics)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"out_dir: {out} exists and is not a directory")
    paths = [out / name for name in texts]
    if not overwrite:
        existing = [str(p) for p in paths if p.exists()]
        if existing:
            also = f" (also {', '.join(existing[1:])})" if len(existing) > 1 else ""
            raise ValueError(f"{existing[0]} exists{also}; not overwriting (pass overwrite=True, "
                             "command line --overwrite)")
    try:
        out.mkdir(parents=True, exist_ok=True)
        for p, text in zip(paths, texts.values()):
            p.write_text(text)
            if p.suffix == ".sh":
                p.chmod(0o755)
    except OSError as e:
        raise ValueError(f"out_dir: cannot write {out} ({e.strerror or e})") from None
    return paths

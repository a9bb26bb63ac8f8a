"""Exports of a hand-eye result into the files a robot cell consumes (URDF, xacro, ROS 2, Drake).

The transform exported is ``X_EC`` (``mode="eye_in_hand"``: the camera C in the end-effector /
flange frame E; parent = the flange link, e.g. ``tool0``) or ``X_BC`` (``mode="eye_to_hand"``:
the camera in the robot base B; parent = the base link, e.g. ``base_link``). Lengths in metres.

Camera frame. Like OpenCV, this package's camera frame C has +x right (image columns), +y down
(image rows), +z forward (the optical axis). ROS calls that frame the *optical* frame
(``<camera>_optical_frame``, REP 103/105), distinct from the ROS body frame ``<camera>_link``
(x forward, y left, z up); hence the default child frame ``camera_optical_frame``. Drake's
camera frame (``CameraInfo``, ``RgbdSensor``) is the same as OpenCV's.

Mount link. A camera driver's own description (e.g. ``realsense2_description``) declares
``camera_link`` → … → ``camera_color_optical_frame``; exporting the optical link too would
declare it twice. Every function takes ``mount_offset`` = X_MC, the optical frame's fixed pose in
the camera's mount link M (read from the camera's URDF/xacro by
``camera_description.read_camera_offset``, or known: ROS ``camera_link`` → optical is
rpy (−π/2, 0, −π/2)); ``child_frame`` then names M and the files place M at
X_EM = X_EC · X_MC⁻¹ (X_BM for eye-to-hand), the URDF/xacro as the joint alone, and the σ is
propagated through the fixed offset.

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
from dataclasses import dataclass
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
def _check_X(X, name: str = "X") -> np.ndarray:
    try:
        M = as_transform(X, name, rigid=True, tol=ROTATION_TOLERANCE)
    except ValueError as e:
        if "rotation block" not in str(e):
            raise
        raise ValueError(f"{e}; exports round-trip to 1e-9, so {name}'s rotation must be "
                         "orthonormal "
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
        lines.append(_sigma_line(std[0]))
    return lines


def _sigma_line(s) -> str:
    return ("1-sigma: rotation [" + ", ".join(f"{math.degrees(v):.4g}" for v in s[:3])
            + "] deg about the parent axes (R = exp([dtheta]x) R_hat), translation ["
            + ", ".join(f"{1000 * v:.4g}" for v in s[3:]) + "] mm")


def _parts(X):
    xyz = X[:3, 3]
    return xyz, rpy_from_rotation(X[:3, :3]), quaternion_xyzw(X[:3, :3])


def _xml_comment(lines: list[str], indent: str = "") -> str:
    return "\n".join(f"{indent}<!-- {line.replace('--', '- -')} -->" for line in lines)


@dataclass(frozen=True)
class _Resolved:
    """What a file states: the transform written (``X``: X_EC/X_BC, or with a mount offset the
    mount link's pose X_EM/X_BM), its σ, the frames, and the mount's offset when there is one."""
    X: np.ndarray
    std: tuple | None
    mode: str
    parent: str
    child: str
    name: str
    what: str
    X_hand: np.ndarray                 # the calibrated optical frame's pose (X_EC / X_BC)
    optical: str | None = None         # mount exports: the optical frame's name
    X_MC: np.ndarray | None = None     # mount exports: the optical frame in the mount link

    @property
    def mount(self) -> bool:
        return self.X_MC is not None

    def head(self, extra: list[str]) -> list[str]:
        hand, _ = _description(self.mode)
        if not self.mount:
            return _header(self.name, self.what, self.parent, self.child, extra, self.std)
        xyz, rpy, _ = _parts(self.X_MC)
        hxyz, hrpy, _ = _parts(self.X_hand)
        lines = [f"handeye_drake calibration: {self.name} = {hand} * inverse(X_MC), "
                 f"{self.what}",
                 f"parent frame: {self.parent}; child frame: {self.child} (the mount link M, "
                 "declared by the camera's own description); lengths in metres",
                 f"X_MC (fixed, given): the optical frame {self.optical} in {self.child}: xyz "
                 f"[{_short(xyz)}] m, rpy [{_short(rpy)}] rad",
                 f"{hand} (calibrated) = {self.name} * X_MC: the optical frame {self.optical}, "
                 f"xyz [{_short(hxyz)}] m, rpy [{_short(hrpy)}] rad",
                 _OPTICAL_LINE + f": {self.optical}"] + extra
        if self.std is not None:
            lines.append(_sigma_line(self.std[0]) + f" (of {self.name}, through the fixed X_MC)")
        return lines


def _short(v) -> str:
    return ", ".join(f"{float(x):.6g}" for x in v)


def _mount_std(std, X_hand, X_MC):
    """σ of X_HM = X_HC · X_MC⁻¹ from that of X_HC (error state R = exp([δθ]×) R̂ about the
    parent axes, t = t̂ + δt): δθ is unchanged and δt_M = δt − [a]× δθ with a = R̂_HC t_CM, the
    mount's offset from the camera in parent axes. Returns (6 σ, 6×6 covariance)."""
    if std is None:
        return None
    s, P = std
    P = np.diag(s**2) if P is None else P
    t_CM = -X_MC[:3, :3].T @ X_MC[:3, 3]
    a = X_hand[:3, :3] @ t_CM
    J = np.eye(6)
    J[3:, :3] = -np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    Q = J @ P @ J.T
    Q = 0.5 * (Q + Q.T)
    return np.sqrt(np.maximum(np.diag(Q), 0.0)), Q


def mount_pose(X, mount_offset, X_std=None):
    """(X_HM, its σ as a 6×6 covariance or None): the pose of the camera's mount link M in the
    parent H (flange E or base B) given the calibrated optical frame's pose X = X_HC and the
    optical frame's fixed pose in the mount, ``mount_offset`` = X_MC: X_HM = X_HC · X_MC⁻¹."""
    X = _check_X(X)
    X_MC = _check_X(mount_offset, "mount_offset")
    X_CM = np.linalg.inv(X_MC)
    X_CM[3] = [0.0, 0.0, 0.0, 1.0]
    std = _mount_std(_std(X_std), X, X_MC)
    return X @ X_CM, None if std is None else std[1]


def _resolve(X, mode, parent_frame, child_frame, X_std, mount_offset=None,
             optical_frame=None) -> _Resolved:
    X = _check_X(X)
    mode, parent, child = _frames(mode, parent_frame, child_frame)
    std = _std(X_std)
    name, what = _description(mode)
    if mount_offset is None:
        if optical_frame is not None:
            raise ValueError("optical_frame: names the optical frame of a mount_offset; give "
                             "mount_offset (X_MC) too, or leave it out")
        return _Resolved(X, std, mode, parent, child, name, what, X)
    optical = DEFAULT_CHILD_FRAME if optical_frame is None else optical_frame
    _check_name(optical, "optical_frame")
    if optical in (child, parent):
        raise ValueError(f"child_frame: with mount_offset, child_frame names the camera's mount "
                         f"link (e.g. camera_link) and optical_frame the optical frame; both "
                         f"are {optical!r}" if optical == child else
                         f"optical_frame: must differ from parent_frame, both are {optical!r}")
    X_MC = _check_X(mount_offset, "mount_offset")
    X_HM, _ = mount_pose(X, X_MC)
    m = "X_EM" if mode == "eye_in_hand" else "X_BM"
    where = "end-effector (flange) frame E" if mode == "eye_in_hand" else "robot base frame B"
    return _Resolved(X_HM, _mount_std(std, X, X_MC), mode, parent, child, m,
                     f"pose of the camera's mount link M = {child} in the {where}", X,
                     optical, X_MC)


# ---------------------------------------------------------------------------------- formats
_MOUNT_ARGS = """
    With ``mount_offset`` (4×4 X_MC: the optical frame's fixed pose in the camera's mount link,
    metres), ``child_frame`` names that mount link (e.g. ``camera_link``) and the file places it:
    X_EM = X · X_MC⁻¹ (σ propagated); ``optical_frame`` (default ``camera_optical_frame``) names
    the optical frame in the comments."""


def urdf_joint(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME, mode="eye_in_hand",
               joint_name=None, X_std=None, *, mount_offset=None, optical_frame=None) -> str:
    """A URDF fragment: the child ``<link>`` and a ``<joint type="fixed">`` from ``parent_frame``
    to it with ``<origin xyz rpy>`` = X (metres, radians, RPY as in the module docstring).
    Paste it inside your robot's ``<robot>`` element.

    With ``mount_offset`` the fragment is the joint alone (default name
    ``handeye_<mount>_joint``): its child, the mount link, and the chain down to the optical
    frame come from the camera's own description (e.g. realsense2_description), which would
    clash with a second declaration of any of its links.""" + _MOUNT_ARGS
    r = _resolve(X, mode, parent_frame, child_frame, X_std, mount_offset, optical_frame)
    default_joint = f"handeye_{r.child}_joint" if r.mount else f"{r.child}_joint"
    joint_name = default_joint if joint_name is None else _check_name(joint_name, "joint_name")
    xyz, rpy, _ = _parts(r.X)
    head = r.head([_RPY_LINE + "; radians"])
    return "\n".join([_xml_comment(head)] + ([] if r.mount else [f'<link name="{r.child}"/>']) + [
        f'<joint name="{joint_name}" type="fixed">',
        f'  <parent link="{r.parent}"/>',
        f'  <child link="{r.child}"/>',
        f'  <origin xyz="{" ".join(_num(v) for v in xyz)}" '
        f'rpy="{" ".join(_num(v) for v in rpy)}"/>',
        "</joint>",
    ]) + "\n"


def urdf_document(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME, mode="eye_in_hand",
                  joint_name=None, X_std=None, robot_name="handeye_calibration", *,
                  mount_offset=None, optical_frame=None) -> str:
    """``urdf_joint`` wrapped in a ``<robot>`` element (a well-formed XML file; the parent link is
    not in it: copy the link and joint into your robot description)."""
    _check_name(robot_name, "robot_name")
    body = urdf_joint(X, parent_frame, child_frame, mode, joint_name, X_std,
                      mount_offset=mount_offset, optical_frame=optical_frame)
    indented = "\n".join("  " + line for line in body.rstrip("\n").splitlines())
    what = ("the joint below into your robot description, beside the camera's own description "
            f"(which declares {child_frame})" if mount_offset is not None else
            "the link and joint below into your robot description")
    return (f'<?xml version="1.0"?>\n<robot name="{robot_name}">\n'
            f"  <!-- Copy {what}. -->\n"
            f"{indented}\n</robot>\n")


def xacro_properties(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME, mode="eye_in_hand",
                     X_std=None, prefix="handeye_", *, mount_offset=None,
                     optical_frame=None) -> str:
    """A xacro file: properties ``{prefix}x, y, z, roll, pitch, yaw`` (metres, radians),
    ``{prefix}qx … qw``, ``{prefix}parent``, ``{prefix}child``, and a macro
    ``{prefix}camera_joint`` (params ``parent``, ``child`` defaulting to them) that adds the
    fixed joint and child link. Include it with ``<xacro:include filename="handeye.xacro"/>``
    and call ``<xacro:handeye_camera_joint/>``. With ``mount_offset`` the macro adds the joint
    alone (``handeye_${child}_joint``; the camera's description declares the mount link) and
    the properties are those of X_EM.""" + _MOUNT_ARGS
    r = _resolve(X, mode, parent_frame, child_frame, X_std, mount_offset, optical_frame)
    if not isinstance(prefix, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", prefix):
        raise ValueError(f"prefix: expected an identifier, got {prefix!r}")
    xyz, rpy, q = _parts(r.X)
    head = r.head([_RPY_LINE + "; radians", "quaternion order (qx, qy, qz, qw)"])
    props = [("x", xyz[0]), ("y", xyz[1]), ("z", xyz[2]), ("roll", rpy[0]), ("pitch", rpy[1]),
             ("yaw", rpy[2]), ("qx", q[0]), ("qy", q[1]), ("qz", q[2]), ("qw", q[3])]
    p = prefix
    lines = ['<?xml version="1.0"?>', '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">',
             _xml_comment(head, "  ")]
    lines += [f'  <xacro:property name="{p}{k}" value="{_num(v)}"/>' for k, v in props]
    lines += [f'  <xacro:property name="{p}parent" value="{r.parent}"/>',
              f'  <xacro:property name="{p}child" value="{r.child}"/>']
    if r.mount:
        lines += [f'  <xacro:property name="{p}optical_frame" value="{r.optical}"/>']
    lines += [f'  <xacro:macro name="{p}camera_joint" params="parent:=${{{p}parent}} '
              f'child:=${{{p}child}}">']
    if not r.mount:
        lines += ['    <link name="${child}"/>']
    lines += [f'    <joint name="{"handeye_" if r.mount else ""}${{child}}_joint" type="fixed">',
              '      <parent link="${parent}"/>',
              '      <child link="${child}"/>',
              f'      <origin xyz="${{{p}x}} ${{{p}y}} ${{{p}z}}" '
              f'rpy="${{{p}roll}} ${{{p}pitch}} ${{{p}yaw}}"/>',
              "    </joint>",
              "  </xacro:macro>",
              "</robot>"]
    return "\n".join(lines) + "\n"


def static_transform_publisher_arguments(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME,
                                         mode="eye_in_hand", *, mount_offset=None,
                                         optical_frame=None) -> list[str]:
    """The arguments of ROS 2 ``tf2_ros static_transform_publisher`` (new-style flags, Humble
    and later): ``--x --y --z --qx --qy --qz --qw --frame-id PARENT --child-frame-id CHILD``
    (with ``mount_offset``: the mount link's pose; the camera driver publishes the rest)."""
    r = _resolve(X, mode, parent_frame, child_frame, None, mount_offset, optical_frame)
    xyz, _, q = _parts(r.X)
    args = []
    for flag, v in zip(("--x", "--y", "--z", "--qx", "--qy", "--qz", "--qw"),
                       list(xyz) + list(q)):
        args += [flag, _num(v)]
    return args + ["--frame-id", r.parent, "--child-frame-id", r.child]


def static_transform_publisher_command(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME,
                                       mode="eye_in_hand", *, mount_offset=None,
                                       optical_frame=None) -> str:
    """The one-line shell command publishing X on /tf_static:
    ``ros2 run tf2_ros static_transform_publisher --x … --child-frame-id CHILD``."""
    args = static_transform_publisher_arguments(X, parent_frame, child_frame, mode,
                                                mount_offset=mount_offset,
                                                optical_frame=optical_frame)
    return shlex.join(["ros2", "run", "tf2_ros", "static_transform_publisher"] + args)


def _tf_lines(r: _Resolved) -> list[str]:
    line = "publishes the transform of child_frame in frame_id on /tf_static"
    if r.mount:
        line += (f" (the camera driver's robot_state_publisher publishes {r.child} -> "
                 f"{r.optical} from its own description)")
    return [line]


def ros2_launch(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME, mode="eye_in_hand",
                X_std=None, node_name="handeye_static_tf", *, mount_offset=None,
                optical_frame=None) -> str:
    """A ROS 2 Python launch file: one ``launch_ros.actions.Node`` running ``tf2_ros
    static_transform_publisher`` with ``static_transform_publisher_arguments``."""
    args = static_transform_publisher_arguments(X, parent_frame, child_frame, mode,
                                                mount_offset=mount_offset,
                                                optical_frame=optical_frame)
    _check_name(node_name, "node_name")
    r = _resolve(X, mode, parent_frame, child_frame, X_std, mount_offset, optical_frame)
    head = r.head(["translation --x --y --z in metres; rotation as a unit quaternion in ROS "
                   "order (qx, qy, qz, qw)"] + _tf_lines(r))
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


def _static_tf_script(X, parent, child, mode, X_std, mount_offset=None,
                      optical_frame=None) -> str:
    r = _resolve(X, mode, parent, child, X_std, mount_offset, optical_frame)
    head = r.head(["rotation as a unit quaternion in ROS order (qx, qy, qz, qw)"] + _tf_lines(r))
    return ("#!/bin/sh\n" + "".join(f"# {line}\n" for line in head) +
            static_transform_publisher_command(X, parent, child, mode, mount_offset=mount_offset,
                                               optical_frame=optical_frame) + "\n")


def _rotation_yaml(X) -> str:
    return f"!Rpy {{ deg: [{', '.join(_num(math.degrees(v)) for v in _parts(X)[1])}] }}"


def drake_model_directive(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME,
                          mode="eye_in_hand", X_std=None, *, mount_offset=None,
                          optical_frame=None) -> str:
    """A Drake model-directives YAML with one ``add_frame``: the camera frame ``child_frame``
    posed by ``X_PF`` = X on ``parent_frame`` (use Drake's scoped name, e.g. ``ur5e::tool0``,
    when several models have that frame). Load it with
    ``LoadModelDirectives``/``ProcessModelDirectives`` after the directive adding the robot.
    With ``mount_offset``: the mount link's frame on ``parent_frame`` (X_PF = X_EM), then the
    optical frame on the mount (X_PF = X_MC), so Drake holds both.""" + _MOUNT_ARGS
    r = _resolve(X, mode, parent_frame, child_frame, X_std, mount_offset, optical_frame)
    head = r.head([_RPY_LINE + "; !Rpy deg: [roll, pitch, yaw] in degrees"])
    lines = [f"# {line}" for line in head] + [
        "directives:",
        "- add_frame:",
        f"    name: {r.child}",
        "    X_PF:",
        f"      base_frame: {r.parent}",
        f"      translation: [{', '.join(_num(v) for v in r.X[:3, 3])}]",
        f"      rotation: {_rotation_yaml(r.X)}"]
    if r.mount:
        lines += [f"# the optical frame on the mount link (X_MC, fixed; leave it out if a model "
                  f"you add already has {r.optical} on {r.child})",
                  "- add_frame:",
                  f"    name: {r.optical}",
                  "    X_PF:",
                  f"      base_frame: {r.child}",
                  f"      translation: [{', '.join(_num(v) for v in r.X_MC[:3, 3])}]",
                  f"      rotation: {_rotation_yaml(r.X_MC)}"]
    return "\n".join(lines) + "\n"


def drake_camera_config(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME,
                        mode="eye_in_hand", X_std=None, intrinsics=None,
                        name="handeye_camera", *, mount_offset=None,
                        optical_frame=None) -> str:
    """A Drake ``CameraConfig`` YAML (load with ``yaml_load_typed(schema=CameraConfig, …)`` or
    paste under a scenario's ``cameras:``) placing the simulated camera where it was calibrated.

    What is set: ``X_PB`` = X with ``base_frame: parent_frame`` (the sensor body B in the parent
    frame), and ``X_BC`` = ``X_BD`` = identity, so the colour (and depth) camera frame — Drake's
    camera frame, x right, y down, z forward like OpenCV's — coincides with the body: the
    colour camera's pose in the parent is X_PB · X_BC = X. With ``mount_offset`` the body is
    the mount link: ``X_PB`` = X_EM and ``X_BC`` = ``X_BD`` = X_MC (the colour camera is again
    at X). ``intrinsics`` (an object with
    ``alpha_u, alpha_v, u0, v0, width, height`` and no skew, e.g. ``vision.CameraIntrinsics`` or
    ``bags.CameraInfo``) sets ``width, height, focal: !FocalLength {x: fx, y: fy}, center_x,
    center_y`` (Drake's pixel (0, 0) is the centre of the first pixel, as in OpenCV); without it
    Drake's defaults remain. Lens distortion has no Drake counterpart and is not written.
    """
    r = _resolve(X, mode, parent_frame, child_frame, X_std, mount_offset, optical_frame)
    _check_name(name, "name")
    body = (f"X_PB: the mount link {r.child} (the sensor body B) in base_frame; X_BC = X_BD = "
            f"X_MC, so the colour camera frame (Drake: x right, y down, z forward) is "
            f"{r.optical}" if r.mount else
            "X_PB: camera body B in base_frame; X_BC = X_BD = identity, so the colour "
            f"camera frame (Drake: x right, y down, z forward) is {r.child}")
    head = r.head([_RPY_LINE + "; !Rpy deg: [roll, pitch, yaw] in degrees", body])
    X_BC = r.X_MC if r.mount else np.eye(4)
    lines = [f"# {line}" for line in head] + [f"name: {name}"]
    if intrinsics is not None:
        lines += _intrinsics_lines(intrinsics)
    lines += ["X_PB:",
              f"  base_frame: {r.parent}",
              f"  translation: [{', '.join(_num(v) for v in r.X[:3, 3])}]",
              f"  rotation: {_rotation_yaml(r.X)}"]
    for key in ("X_BC", "X_BD"):
        lines += [f"{key}:",
                  f"  translation: [{', '.join(_num(v) for v in X_BC[:3, 3])}]",
                  f"  rotation: {_rotation_yaml(X_BC)}"]
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


def _pose_block(X) -> dict:
    xyz, rpy, q = _parts(X)
    return {"matrix": X.tolist(), "translation": xyz.tolist(),
            "quaternion_wxyz": [q[3], q[0], q[1], q[2]],
            "rpy_deg": [math.degrees(v) for v in rpy]}


def _std_block(std) -> dict:
    out = {"rotation_deg": np.degrees(std[0][:3]).tolist(), "translation": std[0][3:].tolist(),
           "error_state": "R = exp([dtheta]x) R_hat (dtheta about the parent axes, rad), "
                          "t = t_hat + dt"}
    if std[1] is not None:
        out["covariance"] = std[1].tolist()
    return out


def transform_json(X, parent_frame=None, child_frame=DEFAULT_CHILD_FRAME, mode="eye_in_hand",
                   X_std=None, *, mount_offset=None, optical_frame=None) -> str:
    """JSON with the transform under its name (``X_EC`` or ``X_BC``), laid out like the X_EC
    block of ``calibrate``'s ``calibration.json``: ``matrix`` (row-major 4×4),
    ``translation``, ``quaternion_wxyz``, ``rpy_deg``; plus frames, mode, conventions and, with
    X_std, ``std`` (``rotation_deg``, ``translation``, and ``covariance`` when given).

    With ``mount_offset``: ``child_frame`` is the mount link, ``optical_frame`` the optical
    frame (still the pose under ``X_EC``/``X_BC``), and ``mount`` holds ``X_MC`` (the offset),
    ``X_EM``/``X_BM`` (the mount link's pose, what the other files write) and its ``std``."""
    r = _resolve(X, mode, parent_frame, child_frame, X_std, mount_offset, optical_frame)
    hand, what = _description(r.mode)
    doc = {
        "description": f"{hand}: {what}",
        "mode": r.mode,
        "parent_frame": r.parent,
        "child_frame": r.child,
        "conventions": {
            "units": "metres; radians unless _deg",
            "rpy": "roll, pitch, yaw about the fixed parent axes X, Y, Z (extrinsic X-Y-Z, "
                   "URDF rpy = Drake RollPitchYaw)",
            "quaternion": "Hamilton, scalar first (w, x, y, z), w >= 0",
            "camera_frame": "x right, y down, z forward (OpenCV; ROS *_optical_frame)",
        },
        hand: _pose_block(r.X_hand),
    }
    std = _std(X_std)
    if std is not None:
        doc["std"] = _std_block(std)
    if r.mount:
        doc["optical_frame"] = r.optical
        doc["mount"] = {
            "description": f"{r.name} = {hand} * inverse(X_MC): {r.what}; X_MC: the optical "
                           f"frame {r.optical} in the mount link {r.child} (fixed, given)",
            "frame": r.child, "optical_frame": r.optical,
            "X_MC": _pose_block(r.X_MC), r.name: _pose_block(r.X)}
        if r.std is not None:
            doc["mount"]["std"] = _std_block(r.std)
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
             X_std=None, timestamp: float = 0.0, *, mount_offset=None,
             optical_frame=None) -> str:
    """One TUM line ``timestamp tx ty tz qx qy qz qw`` (quaternion scalar last) after ``#``
    comments; ``formats.read_poses(path, "robot", "tum")`` reads it back. With
    ``mount_offset`` the line is the mount link's pose X_EM."""
    r = _resolve(X, mode, parent_frame, child_frame, X_std, mount_offset, optical_frame)
    t = float(timestamp)
    if not math.isfinite(t):
        raise ValueError(f"timestamp: must be finite, got {timestamp!r}")
    xyz, _, q = _parts(r.X)
    head = r.head(["timestamp tx ty tz qx qy qz qw (quaternion scalar last, x y z w)"])
    return "".join(f"# {line}\n" for line in head) + \
        " ".join(_num(v) for v in [t, *xyz, *q]) + "\n"


# ------------------------------------------------------------------------------- entry point
def export_texts(X, formats=FORMATS, mode="eye_in_hand", parent_frame=None,
                 child_frame=DEFAULT_CHILD_FRAME, X_std=None, intrinsics=None, *,
                 mount_offset=None, optical_frame=None) -> dict:
    """{file name: text} of every file ``export_calibration`` would write (nothing written)."""
    formats = parse_formats(formats)
    r = _resolve(X, mode, parent_frame, child_frame, X_std, mount_offset, optical_frame)
    X, parent, child, mode = r.X_hand, r.parent, r.child, r.mode
    m = {"mount_offset": mount_offset, "optical_frame": optical_frame}
    out = {}
    for fmt in formats:
        if fmt == "urdf":
            out["handeye.urdf"] = urdf_document(X, parent, child, mode, X_std=X_std, **m)
        elif fmt == "xacro":
            out["handeye.xacro"] = xacro_properties(X, parent, child, mode, X_std, **m)
        elif fmt == "ros2":
            out["handeye.launch.py"] = ros2_launch(X, parent, child, mode, X_std, **m)
            out["handeye_static_tf.sh"] = _static_tf_script(X, parent, child, mode, X_std, **m)
        elif fmt == "drake":
            out["handeye_directives.yaml"] = drake_model_directive(X, parent, child, mode,
                                                                   X_std, **m)
        elif fmt == "camera_config":
            out["handeye_camera_config.yaml"] = drake_camera_config(X, parent, child, mode,
                                                                    X_std, intrinsics, **m)
        elif fmt == "json":
            out["handeye.json"] = transform_json(X, parent, child, mode, X_std, **m)
        else:
            out["handeye.tum"] = tum_text(X, parent, child, mode, X_std, **m)
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
                       intrinsics=None, *, mount_offset=None,
                       optical_frame=None) -> list[Path]:
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
        mount_offset: None, or the optical frame's fixed pose X_MC in the camera's mount link
            (4×4, metres; e.g. ``camera_description.read_camera_offset`` of the camera's
            URDF). ``child_frame`` then names the mount link (e.g. ``camera_link``): every
            file places it at X_EM = X · X_MC⁻¹ (σ propagated), the URDF/xacro hold only the
            joint (the camera's own description declares the link), the CameraConfig's
            X_BC = X_MC, the JSON keeps X alongside.
        optical_frame: the optical frame's name with ``mount_offset`` (default
            ``camera_optical_frame``).

    Returns:
        The paths written, in ``FORMATS`` order.
    """
    texts = export_texts(X, formats, mode, parent_frame, child_frame, X_std, intrinsics,
                         mount_offset=mount_offset, optical_frame=optical_frame)
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

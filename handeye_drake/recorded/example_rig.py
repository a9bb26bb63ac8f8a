"""Generator of a rendered multi-camera rig for ``handeye-drake calibrate --camera NAME:DIR``.

The cell of ``example_images`` (a UR5e, base at the world origin so B = W, a ChArUco board face
up on the table at X_BT) with several cameras rendered by Drake (RenderEngineVtk) at the same
robot poses (``example_images.sample_robot_poses``: the first hand camera sees the whole board
from 0.38–0.55 m):

- ``wrist``: on the flange at ``example_images.TRUE_X_EC`` (eye-in-hand: X_EC);
- ``wrist2``: on the flange 6 cm beside it, toed in 7° (a stereo pair; it sees most of the board);
- ``cell``: fixed in the cell at ``TRUE_X_BC_CELL``, 0.9 m from the board, looking at it
  obliquely (a cell camera watching the same board: X_BC; the arm may hide part of the board).

Several boards (``boards``, e.g. ``two_boards()``: a second ChArUco board of another dictionary
0.5 m beside the first, watched by the cell camera ``side`` of ``TWO_BOARD_RIG``; with
``board_images`` the hand cameras turn to it for a few more robot poses).

Files written to ``out_dir``: ``robot_poses.tum`` (X_BE, one line per image index, shared by every
camera), and per camera ``NAME/img_000.png`` … (grey PNG; the same index is the same instant) and
``NAME/intrinsics.yaml``; ``truth.json`` (X_BT, per camera its mount, X_EC or X_BC, intrinsics).

Unkind options: ``distortion`` per camera (the rendered pinhole image re-mapped through OpenCV's
model), ``moved`` {name: (index, X_delta)}: from image ``index`` on, the camera's mount is
X · X_delta (a camera knocked during the recording), ``blank`` names a camera whose images do
not show the board (covered lens).

A recording as real multi-camera cells make them (``generate_stamped_rig``): the arm moving
without stopping through the poses, a robot pose stream at ``robot_rate`` Hz with real time
stamps, each camera free-running at its own period with frames dropped and its own clock offset,
its images named by their stamps (``<seconds>.<fraction>``, ``frame_<nanoseconds>``,
``<seconds>_<nanoseconds>``, or ``img_k`` with a ``timestamps.txt``: ``recorded.image_stamps``).
``generate_example_rig``'s output (index-paired) is unchanged.

Drake and OpenCV are imported inside the functions (``handeye_drake.recorded`` stays Drake-free).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..estimation.se3 import inverse, make_transform, rotation_from_rpy
from .example_images import (BACKGROUND, INTRINSICS, SUPERSAMPLE, TARGET_SPEC, TRUE_X_EC,
                             _HOME_Q, _target_pose, _tum_line, sample_robot_poses)

#: Second hand camera: 6 cm along x_C of the first, toed in 7° about y_C towards the board.
TRUE_X_EC2 = TRUE_X_EC @ make_transform(rotation_from_rpy([0.0, math.radians(-7.0), 0.0]),
                                        [0.06, 0.0, 0.0])


def _look_at(p_B, aim_B, up_B=(0.0, 0.0, 1.0)) -> np.ndarray:
    """X_BC of a camera at p_B whose optical axis z_C points at aim_B, image y_C down-ish."""
    z = np.asarray(aim_B, float) - np.asarray(p_B, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, -np.asarray(up_B, float))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return make_transform(np.column_stack([x, y, z]), p_B)


#: The cell camera: 0.9 m from the board centre, on the far side from the robot, 40° above the
#: table, looking at the board.
TRUE_X_BC_CELL = _look_at([-1.05, -0.62, 0.62], [-0.50, -0.15, 0.0]) @ make_transform(
    rotation_from_rpy([0.0, 0.0, math.radians(4.0)]), [0.0, 0.0, 0.0])

#: A second board on the table (``TWO_BOARDS``): a 5×4-square ChArUco of another dictionary
#: (DICT_4X4_50: none of its markers reads as the first board's), 0.5 m beside the first, out of
#: the cell camera's view, turned −25° about z_B.
SIDE_TARGET_SPEC = "charuco:5x4:0.035:0.026:DICT_4X4_50"
_SIDE_R_BT = rotation_from_rpy([0.0, 0.0, math.radians(-25.0)]) @ rotation_from_rpy(
    [math.pi, 0.0, 0.0])
X_BT_SIDE = make_transform(_SIDE_R_BT, np.array([-0.10, -0.52, 0.0]) - _SIDE_R_BT @ np.array(
    [0.0875, 0.07, 0.0]))
#: A cell camera watching the side board only, 0.8 m from it, 45° above the table.
TRUE_X_BC_SIDE = _look_at([-0.12, -1.10, 0.58], [-0.10, -0.52, 0.0])



def two_boards() -> dict:
    """Two boards on the table, {name: (spec, "cell", X_BT)}: ``table`` (the example's board,
    the robot poses aim at it) and ``side`` (``SIDE_TARGET_SPEC`` at ``X_BT_SIDE``)."""
    from ..vision.targets import parse_target
    return {"table": (TARGET_SPEC, "cell", _target_pose(parse_target(TARGET_SPEC))),
            "side": (SIDE_TARGET_SPEC, "cell", X_BT_SIDE)}


#: A two-board rig: the default rig's cameras and ``side`` watching the side board.
TWO_BOARD_RIG = {"wrist": ("hand", TRUE_X_EC), "wrist2": ("hand", TRUE_X_EC2),
                 "cell": ("cell", TRUE_X_BC_CELL), "side": ("cell", TRUE_X_BC_SIDE)}

#: The default rig: name → (mount "hand" | "cell", X_EC or X_BC).
DEFAULT_RIG = {"wrist": ("hand", TRUE_X_EC), "wrist2": ("hand", TRUE_X_EC2),
               "cell": ("cell", TRUE_X_BC_CELL)}

#: A board on the flange (``board_mount="hand"``): 15 × 12 cm on a bracket 9 cm beside the flange
#: along x_E, upright (its normal along x_E, printed face out), spanning y_E and z_E.
HAND_TARGET_SPEC = "charuco:5x4:0.03:0.022:DICT_5X5_100"
TRUE_X_ET = make_transform(np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]),
                           [0.09, -0.075, 0.10])
#: Two cell cameras at the height of the flange, 0.8 m from the board, 40° apart, looking at it.
TRUE_X_BC_A = _look_at([-0.90, 0.52, 0.50], [-0.47, -0.15, 0.45])
TRUE_X_BC_B = _look_at([-0.37, 0.64, 0.50], [-0.47, -0.15, 0.45])
#: The rig of a board on the flange: two cell cameras (eye-to-hand).
HAND_BOARD_RIG = {"cell_a": ("cell", TRUE_X_BC_A), "cell_b": ("cell", TRUE_X_BC_B)}


def _distort(image, K, dist):
    """The pinhole image as seen through OpenCV's distortion model ``dist`` (same K)."""
    import cv2
    h, w = image.shape[:2]
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pts = np.stack([u.ravel(), v.ravel()], 1).reshape(-1, 1, 2)
    xy = cv2.undistortPoints(pts, K, np.asarray(dist, float)).reshape(-1, 2)
    src = xy @ K[:2, :2].T + K[:2, 2]
    return cv2.remap(image, src[:, 0].reshape(h, w).astype(np.float32),
                     src[:, 1].reshape(h, w).astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)


def _render(cameras: dict, qs, intrinsics, boards, pixels_per_metre, supersample=SUPERSAMPLE):
    """{name: [grey image per q]} of cameras {name: (mount, X)} (one diagram, all cameras);
    ``boards`` [(name, target, mount, X)]: each board at X_BT in the cell or X_ET on the
    flange. ``qs``: the joint positions of every camera's images, or {name: its own}."""
    import cv2
    from pydrake.systems.framework import DiagramBuilder

    from ..systems.arm import add_arm
    from ..systems.rendered_camera import add_target_geometry, mount_rendered_camera
    builder = DiagramBuilder()
    arm = add_arm(builder, q0=_HOME_Q)
    for board_name, target, mount, X in boards:
        if mount == "cell":
            add_target_geometry(arm.scene_graph, target, X, pixels_per_metre=pixels_per_metre,
                                name=f"target_{board_name}")
            continue
        plant = arm.plant
        body = arm.ee_frame.body() if hasattr(arm.ee_frame, "body") else \
            plant.GetFrameByName(arm.ee_frame).body()
        frame = arm.ee_frame if hasattr(arm.ee_frame, "body") else \
            plant.GetFrameByName(arm.ee_frame)
        X_body_E = frame.GetFixedPoseInBodyFrame().GetAsMatrix4()
        add_target_geometry(arm.scene_graph, target, X_body_E @ np.asarray(X),
                            pixels_per_metre=pixels_per_metre,
                            frame_id=plant.GetBodyFrameIdOrThrow(body.index()),
                            source_id=plant.get_source_id(), name=f"target_{board_name}")
    handles = {}
    for name, (mount, X) in cameras.items():
        frame = arm.ee_frame if mount == "hand" else arm.plant.world_frame()
        handles[name] = mount_rendered_camera(
            builder, arm.scene_graph, arm.plant, frame, X, intrinsics, supersample=supersample,
            clipping_near=0.05, clipping_far=3.0, background=BACKGROUND, name=f"rig_{name}")
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = arm.plant.GetMyMutableContextFromRoot(context)
    out = {name: [] for name in cameras}
    if isinstance(qs, dict):
        for name, cam in handles.items():
            for q in qs[name]:
                arm.plant.SetPositions(plant_context, arm.model_instance, q)
                out[name].append(cv2.cvtColor(cam.EvalColorImage(context), cv2.COLOR_RGBA2GRAY))
        return out
    for q in qs:
        arm.plant.SetPositions(plant_context, arm.model_instance, q)
        for name, cam in handles.items():
            out[name].append(cv2.cvtColor(cam.EvalColorImage(context), cv2.COLOR_RGBA2GRAY))
    return out


def generate_example_rig(out_dir, seed: int = 0, num_images: int = 10, cameras: dict | None = None,
                         distortion: dict | None = None, moved: dict | None = None,
                         blank=(), pixels_per_metre: float = 2500.0,
                         robot_error=(0.0, 0.0), supersample: int = SUPERSAMPLE,
                         board_mount: str = "cell", boards: dict | None = None,
                         board_images: dict | None = None,
                         moved_board: tuple | None = None) -> dict:
    """Renders the rig (module docstring) into ``out_dir`` and returns the truth (also written as
    ``truth.json``). ``cameras``: {name: (mount, X_EC or X_BC)} (default ``DEFAULT_RIG``).
    ``robot_error`` (deg, m): per-axis RMS of the error of the recorded flange poses, a smooth
    function of the joint angles (an uncalibrated arm's pose error repeats with its
    configuration), δ = A sin q + B cos q about and along E; the images are rendered at the true
    poses. ``supersample``: anti-aliasing factor of the renderer (k × k samples per pixel).
    ``board_mount`` "hand": the board ``HAND_TARGET_SPEC`` rides on the flange at ``TRUE_X_ET``
    (default cameras ``HAND_BOARD_RIG``), not on the table. ``boards`` {name: (spec, mount
    "cell" | "hand", X_BT | X_ET)}: several boards instead (e.g. ``two_boards()``; the first is
    the one the robot poses aim at); ``board_images`` {name: n}: n more robot poses (after the
    ``num_images``) aimed at that cell board the way the first ones aim at the first board;
    ``moved_board`` (name, index, X_delta): from image ``index`` on, that board is at
    X · X_delta (a board pushed during the recording; not with ``moved``)."""
    import cv2
    from ..vision.camera_model import CameraIntrinsics
    from ..vision.intrinsics import write_intrinsics_yaml
    from ..vision.targets import format_target, parse_target

    if board_mount not in ("cell", "hand"):
        raise ValueError(f"board_mount: expected 'cell' or 'hand', got {board_mount!r}")
    hand_board = board_mount == "hand"
    if boards is None:
        spec = HAND_TARGET_SPEC if hand_board else TARGET_SPEC
        boards = {"board": (spec, board_mount, TRUE_X_ET if hand_board else
                            _target_pose(parse_target(TARGET_SPEC)))}
    elif not boards or any(m not in ("cell", "hand") for _, m, _ in boards.values()):
        raise ValueError(f"boards: expected {{name: (spec, 'cell' | 'hand', X)}}, got {boards!r}")
    board_images = dict(board_images or {})
    for name, n in board_images.items():
        if name not in boards or boards[name][1] != "cell":
            raise ValueError(f"board_images: {name!r} is not a cell board of the rig")
    cameras = dict((HAND_BOARD_RIG if hand_board else DEFAULT_RIG) if cameras is None
                   else cameras)
    for name, (mount, _) in cameras.items():
        if mount not in ("hand", "cell"):
            raise ValueError(f"cameras[{name!r}]: mount must be 'hand' or 'cell', got {mount!r}")
    distortion, moved = dict(distortion or {}), dict(moved or {})
    first_board = next(iter(boards.values()))
    on_table = first_board[1] == "cell"
    qs, X_BEs = sample_robot_poses(seed, num_images, first_board[0] if on_table else None,
                                   first_board[2] if on_table else None)
    qs = list(qs)
    for i, (name, n) in enumerate(board_images.items()):
        q2, X2 = sample_robot_poses(seed + 1000 * (i + 1), int(n), boards[name][0],
                                    boards[name][2])
        qs += list(q2)
        X_BEs += list(X2)
    qs = np.array(qs)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    board_list = [(n, parse_target(spec), m, np.asarray(X, float))
                  for n, (spec, m, X) in boards.items()]
    fx, fy, cx, cy, width, height = INTRINSICS
    pinhole = CameraIntrinsics(alpha_u=fx, alpha_v=fy, u0=cx, v0=cy, width=width, height=height,
                               distortion=(0.0,) * 5)
    images = _render(cameras, qs, pinhole, board_list, pixels_per_metre, supersample)
    if moved_board is not None:
        bname, k0, delta = moved_board
        if moved or bname not in boards:
            raise ValueError(f"moved_board: {bname!r} is not a board of the rig, or given with "
                             "moved")
        after = _render(cameras, qs[int(k0):], pinhole,
                        [(n, t, m, X @ np.asarray(delta, float) if n == bname else X)
                         for n, t, m, X in board_list], pixels_per_metre, supersample)
        for n in cameras:
            images[n][int(k0):] = after[n]
    if moved:
        first = min(int(k) for k, _ in moved.values())
        after = _render({n: (cameras[n][0], cameras[n][1] @ np.asarray(d, float))
                         for n, (_, d) in moved.items()}, qs[first:], pinhole, board_list,
                        pixels_per_metre, supersample)
        for n, (k, _) in moved.items():
            images[n][k:] = after[n][k - first:]
    truth_cams = {}
    for name, (mount, X) in cameras.items():
        folder = out / name
        folder.mkdir(exist_ok=True)
        dist = tuple(float(d) for d in distortion.get(name, (0.0,) * 5))
        for k, img in enumerate(images[name]):
            if name in blank:
                img = np.full_like(img, 80)
            elif any(dist):
                img = _distort(img, pinhole.K, dist)
            cv2.imwrite(str(folder / f"img_{k:03d}.png"), img, [cv2.IMWRITE_PNG_COMPRESSION, 9])
        write_intrinsics_yaml(CameraIntrinsics(alpha_u=fx, alpha_v=fy, u0=cx, v0=cy,
                                               width=width, height=height, distortion=dist),
                              folder / "intrinsics.yaml")
        truth_cams[name] = {"mount": mount, "mode": "eye_in_hand" if mount == "hand"
                            else "eye_to_hand",
                            ("X_EC" if mount == "hand" else "X_BC"): np.asarray(X).tolist(),
                            "distortion": list(dist),
                            "moved": None if name not in moved else
                            {"from_index": int(moved[name][0]),
                             "X_delta": np.asarray(moved[name][1]).tolist()},
                            "blank": name in blank}
    lines = ["# handeye_drake example rig: X_BE (flange in robot base), metres; line k goes "
             "with img_k.png of every camera", "# index tx ty tz qx qy qz qw"]
    recorded = [X.copy() for X in X_BEs]
    if any(robot_error):
        from ..estimation.se3 import rotation_exp
        err_rng = np.random.default_rng(seed + 7919)
        A, B = err_rng.normal(size=(2, 6, 6)) / math.sqrt(6.0)
        scale = np.repeat([math.radians(robot_error[0]), robot_error[1]], 3)
        for k, q in enumerate(qs):
            d = scale * (A @ np.sin(q) + B @ np.cos(q))
            recorded[k] = X_BEs[k] @ make_transform(rotation_exp(d[:3]), d[3:])
    lines += [_tum_line(float(k), X) for k, X in enumerate(recorded)]
    (out / "robot_poses.tum").write_text("\n".join(lines) + "\n")
    _, target, mount0, X0 = board_list[0]
    truth = {"description": "multi-camera rig rendered by handeye_drake/recorded/example_rig.py",
             "seed": int(seed), "target": format_target(target), "board_mount": mount0,
             ("X_BT" if mount0 == "cell" else "X_ET"): X0.tolist(),
             "boards": {n: {"target": format_target(t), "mount": m,
                            ("X_BT" if m == "cell" else "X_ET"): X.tolist(),
                            "moved": None if moved_board is None or moved_board[0] != n else
                            {"from_index": int(moved_board[1]),
                             "X_delta": np.asarray(moved_board[2]).tolist()}}
                        for n, t, m, X in board_list},
             "intrinsics": {"fx": fx, "fy": fy, "cx": cx, "cy": cy, "width": width,
                            "height": height},
             "cameras": truth_cams, "X_BE": [X.tolist() for X in X_BEs],
             "robot_error": list(map(float, robot_error)),
             "X_BE_recorded": [X.tolist() for X in recorded]}
    (out / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return truth


#: File-name styles of ``generate_stamped_rig`` (``recorded.image_stamps``' conventions).
STAMP_STYLES = ("seconds", "file", "nanoseconds", "sec_nsec")


def _stamp_name(style: str, stamp: float, k: int) -> str:
    ns = int(round(stamp * 1e9))
    sec, nsec = divmod(ns, 1_000_000_000)
    if style == "seconds":
        return f"{sec}.{nsec // 1000:06d}.png"            # TUM RGB-D: microseconds
    if style == "nanoseconds":
        return f"frame_{ns}.png"
    if style == "sec_nsec":
        return f"{sec}_{nsec:09d}.png"
    return f"img_{k:03d}.png"


def _smooth_joint_path(q_knots, t_knots):
    """q(t): from knot to knot in joint space with a smoothstep profile (3s² − 2s³): the arm
    slows through each pose, never stops, its speed continuous (no corner for the interpolation
    of the robot's samples to cut)."""
    q_knots = np.asarray(q_knots, float)

    def q_at(t):
        k = int(np.clip(np.searchsorted(t_knots, t, side="right") - 1, 0, len(t_knots) - 2))
        s = float(np.clip((t - t_knots[k]) / (t_knots[k + 1] - t_knots[k]), 0.0, 1.0))
        s = s * s * (3.0 - 2.0 * s)
        return q_knots[k] + s * (q_knots[k + 1] - q_knots[k])
    return q_at


def generate_stamped_rig(out_dir, seed: int = 0, num_poses: int = 8, cameras: dict | None = None,
                         periods: dict | None = None, offsets: dict | None = None,
                         drop: float = 0.15, styles: dict | None = None,
                         robot_rate: float = 100.0, segment: float = 1.5,
                         start: float = 1764800000.0, robot_error=(0.0, 0.0),
                         supersample: int = SUPERSAMPLE, pixels_per_metre: float = 2500.0) -> dict:
    """A rig recorded the way real cells record (module docstring) into ``out_dir``; returns the
    truth (also ``truth.json``).

    The arm passes through ``num_poses`` poses of ``sample_robot_poses`` one every ``segment`` s
    from ``start`` (epoch seconds), along a smooth joint path (``_smooth_joint_path``).
    ``robot_poses.tum``: the flange pose X_BE at ``robot_rate`` Hz stamped on the robot's clock
    (the truth's time), with ``robot_error`` as ``generate_example_rig`` (a function of the joint
    angles). Camera NAME (``cameras`` as ``generate_example_rig``'s, default ``DEFAULT_RIG``)
    takes an image every ``periods[NAME]`` s (default 0.35 s, 0.5 s, 0.6 s, … by camera)
    from a phase of its own, drops each with probability ``drop``, and stamps it on its clock:
    true time + ``offsets[NAME]`` (default +0.03 s, −0.02 s, +0.045 s, … — the ``time_offset``
    convention, camera stamp − robot time). ``styles[NAME]`` in ``STAMP_STYLES`` names the files
    (default: one each, in order); "file" writes ``img_k.png`` and a ``timestamps.txt``."""
    import cv2
    from ..estimation.se3 import rotation_exp
    from ..systems.arm import make_control_plant
    from ..vision.camera_model import CameraIntrinsics
    from ..vision.intrinsics import write_intrinsics_yaml
    from ..vision.targets import format_target, parse_target

    cameras = dict(cameras or DEFAULT_RIG)
    names = list(cameras)
    periods = {n: (periods or {}).get(n, (0.35, 0.5, 0.6, 0.7, 0.8)[i % 5])
               for i, n in enumerate(names)}
    offsets = {n: (offsets or {}).get(n, (0.03, -0.02, 0.045, -0.035, 0.01)[i % 5])
               for i, n in enumerate(names)}
    styles = {n: (styles or {}).get(n, STAMP_STYLES[i % len(STAMP_STYLES)])
              for i, n in enumerate(names)}
    for n in names:
        if styles[n] not in STAMP_STYLES:
            raise ValueError(f"styles[{n!r}]: expected one of {STAMP_STYLES}, got {styles[n]!r}")
        if not periods[n] > 0:
            raise ValueError(f"periods[{n!r}]: expected seconds > 0, got {periods[n]!r}")
    if not (0.0 <= drop < 1.0 and robot_rate > 0 and segment > 0):
        raise ValueError("drop in [0, 1), robot_rate and segment > 0 expected")
    q_knots, _ = sample_robot_poses(seed, num_poses)
    t_knots = start + segment * np.arange(num_poses)
    q_at = _smooth_joint_path(q_knots, t_knots)
    plant = make_control_plant()
    context = plant.CreateDefaultContext()
    frame_E = plant.GetFrameByName("tool0")

    def fk(q):
        plant.SetPositions(context, q)
        return plant.CalcRelativeTransform(context, plant.world_frame(), frame_E).GetAsMatrix4()

    err_rng = np.random.default_rng(seed + 7919)
    A, B = err_rng.normal(size=(2, 6, 6)) / math.sqrt(6.0)
    scale = np.repeat([math.radians(robot_error[0]), robot_error[1]], 3)

    def recorded(q):
        X = fk(q)
        if any(robot_error):
            d = scale * (A @ np.sin(q) + B @ np.cos(q))
            X = X @ make_transform(rotation_exp(d[:3]), d[3:])
        return X

    n_robot = int(math.floor((t_knots[-1] - t_knots[0]) * robot_rate + 1e-9)) + 1
    t_robot = t_knots[0] + np.arange(n_robot) / robot_rate
    lines = ["# handeye_drake stamped example rig: X_BE (flange in robot base), metres, at "
             f"{robot_rate:g} Hz on the robot's clock", "# timestamp tx ty tz qx qy qz qw"]
    lines += [_tum_line(float(t), recorded(q_at(t))) for t in t_robot]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "robot_poses.tum").write_text("\n".join(lines) + "\n")
    rng = np.random.default_rng(seed + 104729)
    times = {}
    for n in names:
        phase = rng.uniform(0.0, periods[n])
        t = np.arange(t_knots[0] + phase, t_knots[-1], periods[n])
        times[n] = t[rng.uniform(size=len(t)) >= drop]
    X_BT = _target_pose(parse_target(TARGET_SPEC))
    target = parse_target(TARGET_SPEC)
    fx, fy, cx, cy, width, height = INTRINSICS
    pinhole = CameraIntrinsics(alpha_u=fx, alpha_v=fy, u0=cx, v0=cy, width=width, height=height,
                               distortion=(0.0,) * 5)
    images = _render(cameras, {n: [q_at(t) for t in times[n]] for n in names}, pinhole,
                     [("board", target, "cell", X_BT)], pixels_per_metre, supersample)
    truth_cams = {}
    for n, (mount, X) in cameras.items():
        folder = out / n
        folder.mkdir(exist_ok=True)
        stamps = times[n] + offsets[n]
        files = [_stamp_name(styles[n], float(s), k) for k, s in enumerate(stamps)]
        for f, img in zip(files, images[n]):
            cv2.imwrite(str(folder / f), img, [cv2.IMWRITE_PNG_COMPRESSION, 9])
        if styles[n] == "file":
            (folder / "timestamps.txt").write_text(
                "# image, stamp on the camera's clock (s)\n"
                + "".join(f"{f} {s:.9f}\n" for f, s in zip(files, stamps)))
        write_intrinsics_yaml(pinhole, folder / "intrinsics.yaml")
        truth_cams[n] = {"mount": mount, "mode": "eye_in_hand" if mount == "hand"
                         else "eye_to_hand", ("X_EC" if mount == "hand" else "X_BC"):
                         np.asarray(X).tolist(), "period_s": float(periods[n]),
                         "time_offset_s": float(offsets[n]), "style": styles[n],
                         "files": files, "true_times": times[n].tolist(),
                         "X_BE": [fk(q_at(t)).tolist() for t in times[n]]}
    truth = {"description": "stamped multi-camera rig rendered by "
             "handeye_drake/recorded/example_rig.py (generate_stamped_rig)",
             "seed": int(seed), "target": format_target(target), "board_mount": "cell",
             "X_BT": X_BT.tolist(), "robot_rate_hz": float(robot_rate),
             "robot_samples": int(n_robot), "knot_times": t_knots.tolist(),
             "robot_error": list(map(float, robot_error)), "drop": float(drop),
             "cameras": truth_cams}
    (out / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return truth


def write_rig_bag(rig_dir, path, storage: str = "mcap", names=None, period: float = 1.2,
                  latency: float = 0.035, tf_rate: float = 50.0) -> dict:
    """A ROS bag of a rendered rig (``generate_example_rig``'s ``rig_dir``): the flange passes
    through pose k at t_k = 1 + ``period``·k s (moving between the poses at constant speed, as
    ``example_bag``), ``/tf`` ``base_link`` → ``tool0`` at ``tf_rate`` Hz (the recorded, possibly
    erroneous poses), and per camera NAME its images on ``/NAME/image_raw`` (mono8) with a
    ``CameraInfo`` on ``/NAME/camera_info``, stamped ``latency`` s after t_k. Returns {name:
    topic}."""
    import cv2
    from ..vision.intrinsics import load_intrinsics
    from .example_bag import BagWriter, _ns, _robot_pose
    rig_dir = Path(rig_dir)
    truth = json.loads((rig_dir / "truth.json").read_text())
    names = list(truth["cameras"]) if names is None else list(names)
    X_BE = np.array(truth["X_BE_recorded"])
    knots = 1.0 + period * np.arange(len(X_BE))
    b = BagWriter(path, storage)
    tf = "tf2_msgs/msg/TFMessage"
    for i in range(int(round((knots[-1] + 1.0) * tf_rate)) + 1):
        t = i / tf_rate
        ns = _ns(t)
        b.add("/tf", tf, ns + 2_000_000, b.tf([b.transform(ns, "base_link", "tool0",
                                                           _robot_pose(t, knots, X_BE))]))
    topics = {}
    for name in names:
        topic = f"/{name}/image_raw"
        topics[name] = topic
        intr = load_intrinsics(rig_dir / name / "intrinsics.yaml")
        for k, t in enumerate(knots):
            grey = cv2.imread(str(rig_dir / name / f"img_{k:03d}.png"), cv2.IMREAD_GRAYSCALE)
            stamp = _ns(t + latency)
            b.add(topic, "sensor_msgs/msg/Image", stamp + 15_000_000,
                  b.image(stamp, f"{name}_optical_frame", grey, "mono8"))
            b.add(f"/{name}/camera_info", "sensor_msgs/msg/CameraInfo", stamp + 15_000_000,
                  b.camera_info(stamp, f"{name}_optical_frame", intr.K, intr.distortion,
                                intr.width, intr.height))
    b.write()
    return topics


def relative_truth(truth: dict, a: str, b: str) -> np.ndarray | None:
    """True X_{C_a C_b} of two cameras on the same mount (None across mounts)."""
    ca, cb = truth["cameras"][a], truth["cameras"][b]
    if ca["mount"] != cb["mount"]:
        return None
    key = "X_EC" if ca["mount"] == "hand" else "X_BC"
    return inverse(np.asarray(ca[key])) @ np.asarray(cb[key])


if __name__ == "__main__":
    import argparse
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--num-images", type=int, default=10)
    parser.add_argument("--two-boards", action="store_true",
                        help="two boards on the table (table, side), TWO_BOARD_RIG's cameras, "
                             "4 more robot poses aimed at the side board")
    parser.add_argument("--stamped", action="store_true",
                        help="the arm moving through the poses (--num-images of them), a robot "
                             "stream at 100 Hz, cameras free-running at their own rates with "
                             "dropped frames and clock offsets, files named by their stamps")
    a = parser.parse_args()
    if a.stamped:
        t = generate_stamped_rig(a.out_dir, a.seed, a.num_images)
        print(f"wrote {t['robot_samples']} robot poses and " + ", ".join(
            f"{len(c['files'])} {n} images ({c['style']}, clock {c['time_offset_s']:+.3f} s)"
            for n, c in t["cameras"].items()) + f" to {a.out_dir}")
    else:
        t = generate_example_rig(a.out_dir, a.seed, a.num_images, **(
            {"cameras": TWO_BOARD_RIG, "boards": two_boards(), "board_images": {"side": 4}}
            if a.two_boards else {}))
        print(f"wrote {len(t['X_BE'])} images per camera ({', '.join(t['cameras'])}) to "
              f"{a.out_dir}")

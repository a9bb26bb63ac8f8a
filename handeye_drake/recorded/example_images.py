"""Generator of a small rendered image set for ``handeye-drake calibrate --images``.

A UR5e (the bundled model, base at the world origin, so B = W) carries a camera on its flange at
``TRUE_X_EC`` (6.4 cm off the flange axis, turned 92° about it and tilted a few degrees); a ChArUco
board lies face up on the table. For each of ``num_images`` robot poses the camera looks at the
board from 0.38–0.55 m, tilted 12–32° from the board's normal about a random horizontal axis and
rolled up to ±30° about its optical axis, so consecutive poses differ by 15–40° about varied
axes. Each pose is reached by inverse kinematics on the UR5e (so every pose is reachable) and the
image is rendered by Drake (RenderEngineVtk, EGL) from the camera mounted on ``tool0``, with the
arm's own geometry in the scene, a dark background and 3 × 3 supersampling (anti-aliasing).

Files written to ``out_dir``:

- ``img_000.png`` …: 640×480 8-bit grey PNG;
- ``robot_poses.tum``: X_BE (flange in base, from forward kinematics at the solved joints),
  ``index tx ty tz qx qy qz qw`` (metres), one line per image in file-name order;
- ``intrinsics.yaml``: OpenCV FileStorage YAML (``camera_matrix``, ``distortion_coefficients``
  (zero: the renderer is a pinhole), ``image_width``, ``image_height``);
- ``truth.json``: X_EC, X_BT, the target spec, the intrinsics, and per image the joint positions,
  X_BE and the true X_CT.

The same seed gives the same bytes on the same machine (the rendered pixels may differ across GPU
drivers). Run ``python -m handeye_drake.recorded.example_images OUT_DIR [--seed N]``.

Drake and OpenCV are imported inside ``generate_example_images`` so that importing
``handeye_drake.recorded`` stays Drake-free.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from ..estimation.se3 import inverse, make_transform, quat_wxyz, rotation_angle, \
    rotation_exp, rotation_from_rpy, rpy

#: The true camera-on-hand transform: camera 6.4 cm ahead of the flange, 6.4 cm aside, turned 92°
#: about the flange axis and tilted by −3° and 4°.
TRUE_X_EC = make_transform(rotation_from_rpy(np.radians([-3.0, 4.0, 92.0])),
                           [0.038, -0.052, 0.064])

#: A 7×5-square ChArUco board (0.28 m × 0.20 m), 24 inner corners.
TARGET_SPEC = "charuco:7x5:0.04:0.03:DICT_5X5_100"

#: Pinhole intrinsics (px): fx, fy, cx, cy, width, height.
INTRINSICS = (612.0, 611.5, 318.6, 243.2, 640, 480)

#: Board face up on the table (z_T = −z_B, so the camera above sees the printed face), its
#: centre at p_B = (−0.50, −0.15, 0) m, turned 10° about z_B.
_BOARD_CENTRE_B = np.array([-0.50, -0.15, 0.0])
_R_BT = rotation_from_rpy([0.0, 0.0, math.radians(10.0)]) @ rotation_from_rpy([math.pi, 0.0, 0.0])

#: Anti-aliasing: each pixel averages 3 × 3 rendered samples (corner RMS ≈ 0.04 px, like a
#: good real camera, instead of up to 0.3 px with one sample per pixel).
SUPERSAMPLE = 3

#: A dark grey-blue background (a table or floor), so the board's white border stands out.
BACKGROUND = (0.30, 0.32, 0.36)

#: Pixels of margin every target corner keeps from the image border.
IMAGE_MARGIN_PX = 25.0

_HOME_Q = np.array([0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0])


def _target_pose(target) -> np.ndarray:
    from ..vision.targets import pattern_extent
    x0, y0, x1, y1 = pattern_extent(target)
    centre_T = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0])
    return make_transform(_R_BT, _BOARD_CENTRE_B - _R_BT @ centre_T)


def _sample_camera_pose(rng, X_BT: np.ndarray, centre_T: np.ndarray) -> np.ndarray:
    """X_BC looking at the board centre (± 3 cm) from 0.38–0.55 m, tilted 12–32° from the board
    normal about a random horizontal axis, rolled ±30° about the optical axis."""
    distance = rng.uniform(0.38, 0.55)
    tilt = math.radians(rng.uniform(12.0, 32.0))
    azimuth = rng.uniform(0.0, 2.0 * math.pi)
    roll = math.radians(rng.uniform(-30.0, 30.0))
    aim_B = X_BT[:3, :3] @ centre_T + X_BT[:3, 3] + np.append(rng.uniform(-0.03, 0.03, 2), 0.0)
    # Straight down with image x along the board's x, then tilted and rolled.
    R_down = X_BT[:3, :3]  # camera z = board z (into the board), x = board x
    axis = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
    R_BC = rotation_exp(tilt * axis) @ R_down @ rotation_exp([0.0, 0.0, roll])
    p_BC = aim_B - distance * R_BC[:, 2]
    return make_transform(R_BC, p_BC)


def _tum_line(t: float, X: np.ndarray) -> str:
    w, x, y, z = quat_wxyz(X[:3, :3])
    p = X[:3, 3]
    return (f"{t:.6f} {p[0]:.9f} {p[1]:.9f} {p[2]:.9f} {x:.9f} {y:.9f} {z:.9f} {w:.9f}")


def _solve_ik(plant, context, frame_E, X_BE: np.ndarray, q_guess: np.ndarray):
    """Joint positions reaching X_BE (within 1e-5 m / rad; the caller records the forward
    kinematics of the result, not X_BE), or None."""
    from pydrake.math import RotationMatrix
    from pydrake.multibody.inverse_kinematics import InverseKinematics
    from pydrake.solvers import Solve
    ik = InverseKinematics(plant, context)
    # (Zero-width bounds make SNOPT report infeasibility.)
    tol = 1e-7
    ik.AddPositionConstraint(frame_E, np.zeros(3), plant.world_frame(), X_BE[:3, 3] - tol,
                             X_BE[:3, 3] + tol)
    ik.AddOrientationConstraint(plant.world_frame(), RotationMatrix(X_BE[:3, :3]), frame_E,
                                RotationMatrix(), tol)
    prog = ik.get_mutable_prog()
    prog.AddQuadraticErrorCost(np.eye(len(q_guess)), q_guess, ik.q())
    result = Solve(prog, q_guess)
    if not result.is_success():
        return None
    q = result.GetSolution(ik.q())
    plant.SetPositions(context, q)
    X = plant.CalcRelativeTransform(context, plant.world_frame(), frame_E).GetAsMatrix4()
    if np.linalg.norm(X[:3, 3] - X_BE[:3, 3]) > 1e-5 or rotation_angle(
            X[:3, :3].T @ X_BE[:3, :3]) > 1e-5:
        return None
    return q


def example_intrinsics():
    """The ``CameraIntrinsics`` of the image set (zero distortion written out, as OpenCV's
    calibration sample does)."""
    from ..vision.camera_model import CameraIntrinsics
    fx, fy, cx, cy, width, height = INTRINSICS
    return CameraIntrinsics(alpha_u=fx, alpha_v=fy, u0=cx, v0=cy, width=width, height=height,
                            distortion=(0.0,) * 5)


def sample_robot_poses(seed: int = 0, num_images: int = 14, target_spec: str | None = None,
                       X_BT=None) -> tuple[np.ndarray, list]:
    """The joint positions (num_images × 6, rad) and flange poses X_BE (forward kinematics, 4×4)
    of the image set: random camera poses (module docstring) kept if the UR5e reaches them, every
    board corner projects ≥ ``IMAGE_MARGIN_PX`` inside the image and the camera turned 15–40°
    from the previous pose. Deterministic; the first k poses do not depend on num_images ≥ k.
    ``target_spec``, ``X_BT``: aim at another board on the table (default the example's)."""
    from ..systems.arm import make_control_plant
    from ..vision.targets import object_points, parse_target, pattern_extent

    if isinstance(num_images, bool) or not isinstance(num_images, (int, np.integer)) \
            or num_images < 1:
        raise ValueError(f"num_images: expected an integer ≥ 1, got {num_images!r}")
    rng = np.random.default_rng(seed)
    target = parse_target(TARGET_SPEC if target_spec is None else target_spec)
    X_BT = _target_pose(target) if X_BT is None else np.asarray(X_BT, float)
    x0, y0, x1, y1 = pattern_extent(target)
    centre_T = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0])
    # The board's outer corners must be in view too, not only the inner corners.
    p_TQ = np.vstack([object_points(target)[1],
                      [[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]]])
    K = example_intrinsics().K
    width, height = INTRINSICS[4:]
    plant = make_control_plant()
    context = plant.CreateDefaultContext()
    frame_E = plant.GetFrameByName("tool0")

    qs, X_BEs, X_BC_prev, q_prev = [], [], None, _HOME_Q
    for _ in range(200 * num_images):
        if len(qs) == num_images:
            break
        X_BC = _sample_camera_pose(rng, X_BT, centre_T)
        if X_BC_prev is not None:
            angle = math.degrees(rotation_angle(X_BC_prev[:3, :3].T @ X_BC[:3, :3]))
            if not 15.0 <= angle <= 40.0:
                continue
        q = _solve_ik(plant, context, frame_E, X_BC @ inverse(TRUE_X_EC), q_prev)
        if q is None:
            continue
        plant.SetPositions(context, q)
        X_BE = plant.CalcRelativeTransform(context, plant.world_frame(), frame_E).GetAsMatrix4()
        X_CT = inverse(X_BE @ TRUE_X_EC) @ X_BT
        p_CQ = p_TQ @ X_CT[:3, :3].T + X_CT[:3, 3]
        uv = (p_CQ @ K.T)[:, :2] / p_CQ[:, 2:]
        m = IMAGE_MARGIN_PX
        if np.any(p_CQ[:, 2] <= 0.1) or np.any(uv < m) or np.any(
                uv[:, 0] > width - 1 - m) or np.any(uv[:, 1] > height - 1 - m):
            continue
        qs.append(q)
        X_BEs.append(X_BE)
        X_BC_prev, q_prev = X_BE @ TRUE_X_EC, q
    else:  # pragma: no cover - the sampling ranges make this practically unreachable
        raise RuntimeError(f"found only {len(qs)} of {num_images} reachable camera poses")
    return np.array(qs), X_BEs


def generate_example_images(out_dir, seed: int = 0, num_images: int = 14,
                            pixels_per_metre: float = 3000.0) -> dict:
    """Renders the image set described in the module docstring into ``out_dir`` (created) and
    returns the truth dictionary (also written as ``truth.json``). Deterministic for a seed; the
    first k images do not depend on ``num_images`` ≥ k."""
    import cv2
    from pydrake.systems.framework import DiagramBuilder

    from ..systems.arm import add_arm
    from ..systems.rendered_camera import add_target_geometry, mount_rendered_camera
    from ..vision.intrinsics import write_intrinsics_yaml
    from ..vision.targets import format_target, parse_target

    qs, X_BEs = sample_robot_poses(seed, num_images)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    target = parse_target(TARGET_SPEC)
    intrinsics = example_intrinsics()
    fx, fy, cx, cy, width, height = INTRINSICS
    X_BT = _target_pose(target)

    builder = DiagramBuilder()
    arm = add_arm(builder, q0=_HOME_Q)
    add_target_geometry(arm.scene_graph, target, X_BT, pixels_per_metre=pixels_per_metre)
    camera = mount_rendered_camera(builder, arm.scene_graph, arm.plant, arm.ee_frame, TRUE_X_EC,
                                   intrinsics, supersample=SUPERSAMPLE, clipping_near=0.05,
                                   clipping_far=3.0, background=BACKGROUND)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = arm.plant.GetMyMutableContextFromRoot(context)

    robot_lines = ["# handeye_drake example images: X_BE (flange in robot base), metres; line k "
                   "goes with img_k.png", "# index tx ty tz qx qy qz qw"]
    images = []
    for k, (q, X_BE) in enumerate(zip(qs, X_BEs)):
        arm.plant.SetPositions(plant_context, arm.model_instance, q)
        grey = cv2.cvtColor(camera.EvalColorImage(context), cv2.COLOR_RGBA2GRAY)
        name = f"img_{k:03d}.png"
        cv2.imwrite(str(out / name), grey, [cv2.IMWRITE_PNG_COMPRESSION, 9])
        robot_lines.append(_tum_line(float(k), X_BE))
        images.append({"file": name, "q": q.tolist(), "X_BE": X_BE.tolist(),
                       "X_CT": (inverse(X_BE @ TRUE_X_EC) @ X_BT).tolist()})

    (out / "robot_poses.tum").write_text("\n".join(robot_lines) + "\n")
    write_intrinsics_yaml(intrinsics, out / "intrinsics.yaml")
    truth = {
        "description": "images rendered by handeye_drake/recorded/example_images.py for "
                       "`handeye-drake calibrate --images` (eye-in-hand, UR5e, B = W)",
        "seed": int(seed),
        "target": format_target(target),
        "intrinsics": {"fx": fx, "fy": fy, "cx": cx, "cy": cy, "width": width,
                       "height": height, "distortion": [0.0] * 5},
        "X_EC": TRUE_X_EC.tolist(),
        "X_EC_translation": TRUE_X_EC[:3, 3].tolist(),
        "X_EC_quaternion_wxyz": quat_wxyz(TRUE_X_EC[:3, :3]).tolist(),
        "X_EC_rpy_deg": np.degrees(rpy(TRUE_X_EC[:3, :3])).tolist(),
        "X_BT": X_BT.tolist(),
        "pixels_per_metre": float(pixels_per_metre),
        "supersample": SUPERSAMPLE,
        "images": images,
    }
    (out / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return truth


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--num-images", type=int, default=14)
    a = parser.parse_args()
    truth = generate_example_images(a.out_dir, a.seed, a.num_images)
    print(f"wrote {len(truth['images'])} images to {a.out_dir}")

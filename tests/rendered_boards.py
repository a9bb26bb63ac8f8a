"""Eye-in-hand image sets of any board rendered by Drake (RenderEngineVtk, the UR5e of
``recorded.example_images`` reaching each camera pose by IK), made unkind afterwards: strong
barrel distortion (the pinhole render re-mapped through OpenCV's model), Gaussian blur, sensor
noise, any roll of the camera about its axis (so OpenCV labels a symmetric board from either
end) and, optionally, views with the board half out of the image.

``render_set(folder, spec, ...)`` writes ``img_NNN.png``, ``robot_poses.tum`` and
``intrinsics.yaml`` (with the distortion) and returns the truth."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp
from handeye_drake.recorded.example_images import (_HOME_Q, TRUE_X_EC, _R_BT, _solve_ik,
                                                   _tum_line)
from handeye_drake.vision.camera_model import CameraIntrinsics
from handeye_drake.vision.intrinsics import write_intrinsics_yaml
from handeye_drake.vision.targets import object_points, parse_target, pattern_extent

WIDTH, HEIGHT = 640, 480
PINHOLE = CameraIntrinsics(alpha_u=560.0, alpha_v=561.0, u0=322.4, v0=237.9, width=WIDTH,
                           height=HEIGHT)
DISTORTION = (-0.26, 0.08, 0.0, 0.0, 0.0)
BOARD_CENTRE_B = np.array([-0.50, -0.15, 0.0])


def board_pose(target) -> np.ndarray:
    x0, y0, x1, y1 = pattern_extent(target)
    centre = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0])
    return make_transform(_R_BT, BOARD_CENTRE_B - _R_BT @ centre)


def _distort_maps(K: np.ndarray, dist) -> tuple[np.ndarray, np.ndarray]:
    """For each pixel of the distorted image, where to read the pinhole image."""
    u, v = np.meshgrid(np.arange(WIDTH, dtype=np.float64), np.arange(HEIGHT, dtype=np.float64))
    pts = np.stack([u.ravel(), v.ravel()], 1).reshape(-1, 1, 2)
    xy = cv2.undistortPoints(pts, K, np.asarray(dist, float)).reshape(-1, 2)
    src = xy @ K[:2, :2].T + K[:2, 2]
    return (src[:, 0].reshape(HEIGHT, WIDTH).astype(np.float32),
            src[:, 1].reshape(HEIGHT, WIDTH).astype(np.float32))


def _camera_pose(rng, X_BT, centre_T, distance, roll_deg, aim_offset=(0.0, 0.0)):
    tilt = math.radians(rng.uniform(12.0, 30.0))
    azimuth = rng.uniform(0.0, 2.0 * math.pi)
    axis = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
    R_BC = rotation_exp(tilt * axis) @ X_BT[:3, :3] @ rotation_exp(
        [0.0, 0.0, math.radians(roll_deg)])
    aim = X_BT[:3, :3] @ (centre_T + [aim_offset[0], aim_offset[1], 0.0]) + X_BT[:3, 3]
    return make_transform(R_BC, aim - distance * R_BC[:, 2])


def render_set(folder, spec: str, n: int = 8, seed: int = 0, half_out: int = 0,
               blur_px: float = 0.7, noise: float = 2.0, distance=(0.36, 0.5),
               pixels_per_metre: float = 4000.0) -> dict:
    """Renders ``n`` views (rolls spread over the full turn) plus ``half_out`` views with the
    board half out of the image; returns the truth (X_EC, X_BT, X_BE, which images are the
    half-out ones, the spec, the intrinsics path)."""
    from pydrake.systems.framework import DiagramBuilder

    from handeye_drake.systems.arm import add_arm, make_control_plant
    from handeye_drake.systems.rendered_camera import add_target_geometry, mount_rendered_camera

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    target = parse_target(spec)
    X_BT = board_pose(target)
    x0, y0, x1, y1 = pattern_extent(target)
    centre_T = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0])
    p_TQ = np.vstack([object_points(target)[1],
                      [[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]]])
    intrinsics = CameraIntrinsics(alpha_u=PINHOLE.alpha_u, alpha_v=PINHOLE.alpha_v,
                                  u0=PINHOLE.u0, v0=PINHOLE.v0, width=WIDTH, height=HEIGHT,
                                  distortion=DISTORTION)
    K, dist = intrinsics.K, intrinsics.distortion_coefficients
    rng = np.random.default_rng(seed)
    plant = make_control_plant()
    context = plant.CreateDefaultContext()
    frame_E = plant.GetFrameByName("tool0")
    # (The UR5e wrist reaches -140° to +180° of roll from this home pose.)
    rolls = list(np.linspace(-135.0, 175.0, n) + rng.uniform(-5, 5, n))
    qs, X_BEs, half = [], [], []
    q_prev = _HOME_Q
    for k in range(n + half_out):
        for _ in range(300):
            out_view = k >= n
            roll = rolls[k] if not out_view else rng.uniform(-135.0, 175.0)
            phi = rng.uniform(0.0, 2.0 * math.pi)
            offset = (0.0, 0.0) if not out_view else tuple(
                rng.uniform(0.12, 0.3) * np.array([math.cos(phi), math.sin(phi)]))
            X_BC = _camera_pose(rng, X_BT, centre_T, rng.uniform(*distance), roll, offset)
            X_CT = inverse(X_BC) @ X_BT
            p = p_TQ @ X_CT[:3, :3].T + X_CT[:3, 3]
            uv, _ = cv2.projectPoints(p_TQ, cv2.Rodrigues(X_CT[:3, :3])[0], X_CT[:3, 3], K, dist)
            uv = uv.reshape(-1, 2)
            inside = (uv[:, 0] > 12) & (uv[:, 0] < WIDTH - 13) & (uv[:, 1] > 12) & \
                (uv[:, 1] < HEIGHT - 13)
            points_in = inside[:-4].mean()  # the board's points, not its outline
            if np.any(p[:, 2] < 0.15) or (not out_view and not inside.all()) or (
                    out_view and not 0.3 < points_in < 0.7):
                continue
            q = _solve_ik(plant, context, frame_E, X_BC @ inverse(TRUE_X_EC), q_prev)
            if q is None:
                continue
            plant.SetPositions(context, q)
            qs.append(q)
            X_BEs.append(plant.CalcRelativeTransform(context, plant.world_frame(),
                                                     frame_E).GetAsMatrix4())
            half.append(out_view)
            q_prev = q
            break
        else:  # pragma: no cover
            raise RuntimeError(f"no reachable view {k} of {spec}")

    builder = DiagramBuilder()
    arm = add_arm(builder, q0=_HOME_Q)
    add_target_geometry(arm.scene_graph, target, X_BT, pixels_per_metre=pixels_per_metre)
    camera = mount_rendered_camera(builder, arm.scene_graph, arm.plant, arm.ee_frame, TRUE_X_EC,
                                   PINHOLE, supersample=1, clipping_near=0.05,
                                   clipping_far=3.0, background=(0.30, 0.32, 0.36))
    diagram = builder.Build()
    root = diagram.CreateDefaultContext()
    plant_context = arm.plant.GetMyMutableContextFromRoot(root)
    maps = _distort_maps(K, dist)
    lines = ["# rendered board set: X_BE, index tx ty tz qx qy qz qw"]
    for k, (q, X_BE) in enumerate(zip(qs, X_BEs)):
        arm.plant.SetPositions(plant_context, arm.model_instance, q)
        grey = cv2.cvtColor(camera.EvalColorImage(root), cv2.COLOR_RGBA2GRAY)
        img = cv2.remap(grey, maps[0], maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        if blur_px > 0:
            img = cv2.GaussianBlur(img, (0, 0), blur_px)
        img = np.clip(img + rng.normal(0.0, noise, img.shape), 0, 255).astype(np.uint8)
        cv2.imwrite(str(folder / f"img_{k:03d}.png"), img)
        lines.append(_tum_line(float(k), X_BE))
    (folder / "robot_poses.tum").write_text("\n".join(lines) + "\n")
    write_intrinsics_yaml(intrinsics, folder / "intrinsics.yaml")
    return {"spec": spec, "X_EC": TRUE_X_EC, "X_BT": X_BT, "X_BE": np.array(X_BEs),
            "half_out": [f"img_{k:03d}.png" for k, h in enumerate(half) if h],
            "intrinsics": folder / "intrinsics.yaml", "robot": folder / "robot_poses.tum"}

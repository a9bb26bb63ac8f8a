"""Accuracy of ``detect_target`` on frames rendered by Drake, against the true X_CT.

    python benchmarks/rendered_detection_accuracy.py [--poses N] [--seed S]

Renders a chessboard (9x6 inner corners of 30 mm) and a ChArUco board (7x5 squares of 40 mm)
from N random camera poses (seeded): distance 0.4–0.6 m, optical axis within ~30° of the board
normal, any roll, aim point ±2 cm around the board centre; 640×480, fx = 605, fy = 598 px, with
one sample per pixel and with 3 × 3 supersampling. Prints, per target and sampling, the median
and maximum rotation error (°), translation error (mm), reprojection RMS (px), and the median
NEES of the error under the detector's covariance (6 if the covariance is right). Frames where
the board is not fully detected are counted, not scored.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pydrake.geometry import SceneGraph  # noqa: E402
from pydrake.systems.framework import DiagramBuilder  # noqa: E402

from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp, \
    rotation_log  # noqa: E402
from handeye_drake.systems.rendered_camera import add_rendered_camera, \
    add_target_geometry  # noqa: E402
from handeye_drake.vision.camera_model import CameraIntrinsics  # noqa: E402
from handeye_drake.vision.detection import detect_target  # noqa: E402
from handeye_drake.vision.targets import parse_target, pattern_extent  # noqa: E402

INTRINSICS = CameraIntrinsics(alpha_u=605.0, alpha_v=598.0, u0=331.3, v0=228.7, width=640,
                              height=480)
X_WT = make_transform(rotation_exp([0.1, -0.2, 0.3]), [0.3, -0.1, 0.05])
TARGETS = (("chessboard", "chessboard:9x6:0.03"),
           ("charuco", "charuco:7x5:0.04:0.03:DICT_5X5_100"))


def random_poses(target, n: int, seed: int) -> list[np.ndarray]:
    """X_TC of n cameras looking at the board centre (see the module docstring)."""
    rng = np.random.default_rng(seed)
    x0, y0, x1, y1 = pattern_extent(target)
    centre = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0])
    poses = []
    for _ in range(n):
        R = rotation_exp(np.append(rng.uniform(-0.5, 0.5, 2), 0.0)) @ rotation_exp(
            [0.0, 0.0, rng.uniform(-math.pi, math.pi)])
        aim = centre + np.append(rng.uniform(-0.02, 0.02, 2), 0.0)
        poses.append(make_transform(R, aim - rng.uniform(0.4, 0.6) * R[:, 2]))
    return poses


def evaluate(target, poses, supersample: int) -> dict:
    builder = DiagramBuilder()
    scene_graph = builder.AddSystem(SceneGraph())
    add_target_geometry(scene_graph, target, X_WT)
    cameras = [add_rendered_camera(builder, scene_graph, scene_graph.world_frame_id(),
                                   X_WT @ X_TC, INTRINSICS, supersample=supersample,
                                   name=f"c{k}") for k, X_TC in enumerate(poses)]
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    rot, trans, rms, nees, missed = [], [], [], [], 0
    for camera, X_TC in zip(cameras, poses):
        detection = detect_target(camera.EvalColorImage(context), target, INTRINSICS)
        if not detection.found:
            missed += 1
            continue
        X_CT = inverse(X_TC)
        dtheta = rotation_log(X_CT[:3, :3] @ detection.X_CT[:3, :3].T)
        dt = X_CT[:3, 3] - detection.X_CT[:3, 3]
        error = np.concatenate([dtheta, dt])
        rot.append(math.degrees(np.linalg.norm(dtheta)))
        trans.append(1000 * np.linalg.norm(dt))
        rms.append(detection.reprojection_rms_px)
        nees.append(float(error @ np.linalg.solve(detection.covariance, error)))
    return {"rot": np.array(rot), "trans": np.array(trans), "rms": np.array(rms),
            "nees": np.array(nees), "missed": missed}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=20)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args()
    print(f"{args.poses} random poses per row (seed {args.seed}); median / max")
    print(f"{'target':<11} {'samples':>7} {'rotation (deg)':>16} {'translation (mm)':>17} "
          f"{'RMS (px)':>13} {'NEES med':>9} {'missed':>6}")
    for name, spec in TARGETS:
        target = parse_target(spec)
        poses = random_poses(target, args.poses, args.seed)
        for k in (1, 3):
            r = evaluate(target, poses, k)
            print(f"{name:<11} {f'{k}x{k}':>7} "
                  f"{np.median(r['rot']):>7.3f} / {r['rot'].max():<6.3f} "
                  f"{np.median(r['trans']):>7.3f} / {r['trans'].max():<7.3f} "
                  f"{np.median(r['rms']):>5.3f} / {r['rms'].max():<5.3f} "
                  f"{np.median(r['nees']):>9.1f} {r['missed']:>6}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Corner-level vs pose-level vs OpenCV's five methods on image sets rendered by Drake with known
truth, and the leave-one-out pixel error of each answer on the shipped image example.

Each set: ``recorded.example_images`` with another seed (a UR5e reaching random camera poses
around a ChArUco board by inverse kinematics, rendered by ``RgbdSensor``/RenderEngineVtk), in
three variants: as rendered (a pinhole), with lens distortion applied to the pixels
(k1 −0.12, k2 0.05, by ``cv2.remap``), and with the distortion applied and the intrinsics given
2 % wrong in focal length. The same detections feed every method: ``calibrate``'s answer
(``corners.calibrate_images``, ``--refine-intrinsics auto``), the pose-level fit it starts from
(``calibrate_streams``: maximum likelihood on the PnP poses, 20 % held out) and
``cv2.calibrateHandEye``'s five methods on the PnP poses. Printed per variant: median errors
against the truth, mean NEES of the reported covariance (χ²(6): 6, with its 99 % band), and what
``auto`` chose.

    .venv/bin/python benchmarks/corner_level_rendered.py [--seeds 8] [--images 14]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import math
import tempfile
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
from scipy.stats import chi2

from handeye_drake.calibration.corners import calibrate_images
from handeye_drake.calibration.inputs import image_streams
from handeye_drake.calibration.pipeline import calibrate_streams, ml_fit, robot_error_covariance
from handeye_drake.estimation import reprojection as rp
from handeye_drake.estimation.se3 import inverse, rotation_log
from handeye_drake.estimation.solvers import calibrate_hand_eye
from handeye_drake.recorded.example_images import generate_example_images

OPENCV = ("tsai", "park", "horaud", "andreff", "daniilidis")
DISTORTION = (-0.12, 0.05, 0.0, 0.0, 0.0)
SETTINGS = dict(robot_accuracy=None, seed=0)


def distort_images(folder: Path, K: np.ndarray, dist) -> None:
    """Re-maps every rendered (pinhole) image so that it shows lens distortion ``dist``."""
    files = sorted(folder.glob("img_*.png"))
    h, w = cv2.imread(str(files[0]), cv2.IMREAD_GRAYSCALE).shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    pts = np.stack([u.ravel(), v.ravel()], 1).reshape(-1, 1, 2)
    # For each distorted pixel, where the pinhole image has it.
    xy = cv2.undistortPoints(pts, K, np.asarray(dist, float)).reshape(-1, 2)
    src = xy @ K[:2, :2].T + K[:2, 2]
    map_x = src[:, 0].reshape(h, w).astype(np.float32)
    map_y = src[:, 1].reshape(h, w).astype(np.float32)
    for f in files:
        img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        cv2.imwrite(str(f), cv2.remap(img, map_x, map_y, cv2.INTER_LINEAR,
                                      borderMode=cv2.BORDER_CONSTANT, borderValue=80))


def intrinsics_spec(truth, focal_factor=1.0, distortion=(0.0,) * 5) -> str:
    i = truth["intrinsics"]
    return ",".join(f"{v:.9g}" for v in (i["fx"] * focal_factor, i["fy"] * focal_factor,
                                         i["cx"], i["cy"], *distortion))


def errors(X, X_true):
    return (math.degrees(np.linalg.norm(rotation_log(X[:3, :3] @ X_true[:3, :3].T))),
            1000 * np.linalg.norm(X[:3, 3] - X_true[:3, 3]))


def nees(X, X_true, cov):
    d = np.concatenate([rotation_log(X[:3, :3] @ X_true[:3, :3].T), X[:3, 3] - X_true[:3, 3]])
    return float(d @ np.linalg.solve(cov, d))


def run_set(folder: Path, truth: dict, spec: str, rows: dict, chosen: Counter) -> None:
    X_EC = np.array(truth["X_EC"])
    with contextlib.redirect_stdout(io.StringIO()):
        streams = image_streams(folder, folder / "robot_poses.tum", truth["target"], spec)
    X_BE, X_CT = streams.robot.poses, streams.camera.poses
    for m in OPENCV:
        rows.setdefault(f"OpenCV {m}", []).append(
            (*errors(calibrate_hand_eye(list(X_BE), list(X_CT), m), X_EC), math.nan))
    pose = calibrate_streams(streams.robot, streams.camera, **SETTINGS)
    rows.setdefault("pose-level ML (calibrate before)", []).append(
        (*errors(pose.X_hand, X_EC), nees(pose.X_hand, X_EC, pose.covariance)))
    result = calibrate_images(streams, SETTINGS, "auto")
    rows.setdefault("corner-level ML (calibrate now)", []).append(
        (*errors(result.X_hand, X_EC), nees(result.X_hand, X_EC, result.covariance)))
    # The command line's default σ also holds the robot's accuracy (0.03° / 0.3 mm): the
    # rendered arm has none, so this NEES shows how conservative the default is.
    with_robot = result.covariance + robot_error_covariance(result.X_hand, (0.03, 3e-4))
    rows.setdefault("  same, σ with --robot-accuracy", []).append(
        (*errors(result.X_hand, X_EC), nees(result.X_hand, X_EC, with_robot)))
    chosen[result.corners.model] += 1


def shipped_leave_one_out() -> None:
    """Leave-one-out prediction (px) of each shipped image's corners by the pose-level fit and by
    the corner-level fit of the other images (the same detections)."""
    from handeye_drake.recorded.example_images import TARGET_SPEC
    folder = Path(__file__).resolve().parents[1] / "handeye_drake" / "data" / "example_images"
    with contextlib.redirect_stdout(io.StringIO()):
        streams = image_streams(folder, folder / "robot_poses.tum", TARGET_SPEC,
                                folder / "intrinsics.yaml")
    X_BE, X_CT = np.asarray(streams.robot.poses), np.asarray(streams.camera.poses)
    dets = streams.detections
    v = rp.intrinsics_vector(streams.intrinsics.K, streams.intrinsics.distortion)
    sq, n = 0.0, 0
    for k in range(len(X_BE)):
        rest = np.setdiff1d(np.arange(len(X_BE)), [k])
        start = calibrate_hand_eye(list(X_BE[rest]), list(X_CT[rest]), "park")
        f = ml_fit(X_BE[rest], X_CT[rest], start, 1e-3, 1e-4)
        X_CT_k = inverse(f.X_H) @ inverse(X_BE[k]) @ f.X_F
        p = dets[k].object_points @ X_CT_k[:3, :3].T + X_CT_k[:3, 3]
        uv = rp.project(p, v, False)[0]
        sq += float(np.sum((uv - dets[k].image_points) ** 2))
        n += len(uv)
    result = calibrate_images(streams, SETTINGS, "auto")
    print(f"\nshipped example (14 images), leave-one-out prediction of each image's corners: "
          f"pose-level ML {math.sqrt(sq / n):.3f} px, corner-level "
          f"({result.corners.model}) {result.corners.cv['rms_px']:.3f} px")


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=8)
    p.add_argument("--images", type=int, default=14)
    a = p.parse_args()
    variants = [("rendered (pinhole), intrinsics exact", False, 1.0),
                ("lens distortion applied, intrinsics exact", True, 1.0),
                ("lens distortion applied, focal 2 % wrong", True, 1.02)]
    results = {v[0]: ({}, Counter()) for v in variants}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(1, a.seeds + 1):
            folder = Path(tmp) / f"set{seed}"
            truth = generate_example_images(folder, seed=seed, num_images=a.images)
            K = np.array([[truth["intrinsics"]["fx"], 0, truth["intrinsics"]["cx"]],
                          [0, truth["intrinsics"]["fy"], truth["intrinsics"]["cy"]], [0, 0, 1]])
            title, _, _ = variants[0]
            run_set(folder, truth, intrinsics_spec(truth), *results[title])
            distort_images(folder, K, DISTORTION)
            for title, _, factor in variants[1:]:
                run_set(folder, truth, intrinsics_spec(truth, factor, DISTORTION),
                        *results[title])
    band = chi2.ppf([0.005, 0.995], 6 * a.seeds) / a.seeds
    for title, (rows, chosen) in results.items():
        print(f"\n{title}: {a.seeds} sets of {a.images} images (NEES: mean, 99 % band of the mean "
              f"{band[0]:.2f}–{band[1]:.2f}); auto chose {dict(chosen)}")
        print(f"  {'method':<34} {'rotation (deg)':>15} {'translation (mm)':>17} {'NEES':>8}")
        for name, r in rows.items():
            x = np.array(r)
            ne = f"{np.mean(x[:, 2]):8.2f}" if np.isfinite(x[:, 2]).all() else "       -"
            print(f"  {name:<34} {np.median(x[:, 0]):15.4f} {np.median(x[:, 1]):17.3f} {ne}")
    shipped_leave_one_out()


if __name__ == "__main__":
    main()

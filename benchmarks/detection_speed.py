"""Target detection: accuracy and time per 640×480 frame, per target type.

    OPENBLAS_NUM_THREADS=1 python benchmarks/detection_speed.py [--frames 30] [--seed 0]

Each frame images a printed target (``render_target``, exact scale) through a 640×480 pinhole
camera with fx = 600 px at 0.5 m (random tilt ~N(0, 17°) per axis, any roll), area-sampled from
3× resolution, blurred (σ 0.5 px) and noisy (σ 2 grey levels). For each type it prints the worst
and RMS pose errors against the true X_CT, the median time of ``detect_target`` and, as the
reference measured in the same run on the same frames, the median time of OpenCV's detection
call alone (``findChessboardCorners``, ``CharucoDetector.detectBoard``,
``ArucoDetector.detectMarkers``), and the time on frames without the target, plain or cluttered
(for the chessboard, with ``thorough=False`` in brackets: no ``findChessboardCornersSB``
fallback).
"""
import argparse
import math
import time

import cv2
import numpy as np

from handeye_drake.estimation.se3 import make_transform, rotation_exp, rotation_log
from handeye_drake.vision.camera_model import CameraIntrinsics
from handeye_drake.vision.detection import detect_target
from handeye_drake.vision.targets import (
    CharucoTarget,
    ChessboardTarget,
    charuco_board,
    get_dictionary,
    parse_target,
    pattern_extent,
    render_target,
    target_dictionary_name,
)

CAMERA = CameraIntrinsics(alpha_u=600.0, alpha_v=602.0, u0=318.5, v0=241.0, width=640,
                          height=480)
SPECS = ["chessboard:9x6:0.0236", "charuco:5x7:0.036195:0.018256:DICT_6X6_250",
         "apriltag:36h11:0.1:10", "aprilgrid:36h11:4x3:0.04:0.3"]


def frame(target, X_CT, texture, A, rng, s=3):
    S = np.array([[s, 0.0, 0.5 * (s - 1)], [0.0, s, 0.5 * (s - 1)], [0.0, 0.0, 1.0]])
    H = S @ CAMERA.K @ X_CT[:3, [0, 1, 3]] @ np.linalg.inv(A)
    hi = cv2.warpPerspective(texture, H, (640 * s, 480 * s), flags=cv2.INTER_LINEAR,
                             borderValue=90.0)
    img = cv2.GaussianBlur(cv2.resize(hi, (640, 480), interpolation=cv2.INTER_AREA), (0, 0), 0.5)
    return np.clip(np.round(img + rng.normal(0.0, 2.0, img.shape)), 0, 255).astype(np.uint8)


def opencv_only(target):
    if isinstance(target, ChessboardTarget):
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | \
            cv2.CALIB_CB_FAST_CHECK
        return lambda g: cv2.findChessboardCorners(g, (target.cols, target.rows), flags=flags)
    if isinstance(target, CharucoTarget):
        detector = cv2.aruco.CharucoDetector(charuco_board(target))
        return detector.detectBoard
    detector = cv2.aruco.ArucoDetector(get_dictionary(target_dictionary_name(target)))
    return detector.detectMarkers


def median_ms(fn, images, repeats=3):
    times = []
    for image in images:
        best = math.inf
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn(image)
            best = min(best, time.perf_counter() - t0)
        times.append(best)
    return 1000.0 * float(np.median(times))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=30)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(f"cv2 {cv2.__version__}, {args.frames} frames per target, 640×480, fx 600 px, 0.5 m")
    print("| target | found | rot err worst / RMS (deg) | trans err worst / RMS (mm) | "
          "reproj. RMS (px) | detect_target (ms) | OpenCV detection alone (ms) | ratio | "
          "target absent, plain (ms) | target absent, clutter (ms) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for spec in SPECS:
        target = parse_target(spec)
        rng = np.random.default_rng(args.seed)
        x0, y0, x1, y1 = pattern_extent(target)
        margin = 0.12 * min(x1 - x0, y1 - y0) + 0.005
        texture, A = render_target(target, 8000.0, margin)
        texture = (25.0 + 210.0 * texture.astype(np.float32) / 255.0).astype(np.float32)
        centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
        images, poses = [], []
        for _ in range(args.frames):
            R = rotation_exp([0, 0, rng.uniform(-np.pi, np.pi)]) @ rotation_exp(
                rng.normal(0.0, 0.3, 3))
            X_CT = make_transform(R, np.array([0.0, 0.0, 0.5]) + rng.normal(0, 0.01, 3)
                                  - R @ centre)
            images.append(frame(target, X_CT, texture, A, rng))
            poses.append(X_CT)
        rot, trans, rms = [], [], []
        for image, X_CT in zip(images, poses):
            det = detect_target(image, target, CAMERA)
            if det.found:
                rot.append(math.degrees(np.linalg.norm(rotation_log(
                    X_CT[:3, :3] @ det.X_CT[:3, :3].T))))
                trans.append(1000.0 * np.linalg.norm(X_CT[:3, 3] - det.X_CT[:3, 3]))
                rms.append(det.reprojection_rms_px)
        ours = median_ms(lambda g: detect_target(g, target, CAMERA), images)
        ref = median_ms(opencv_only(target), images)
        # Frames without the target: a plain background (sensor noise only), and clutter
        # (smoothed high-contrast noise: blobs with edges and corners everywhere).
        plain = [np.clip(rng.normal(90.0, 2.0, (480, 640)), 0, 255).astype(np.uint8)
                 for _ in range(5)]
        clutter = [np.clip(cv2.GaussianBlur(rng.normal(128.0, 300.0, (480, 640)), (0, 0), 2.0),
                           0, 255).astype(np.uint8) for _ in range(5)]
        absent = []
        for frames in (plain, clutter):
            text = f"{median_ms(lambda g: detect_target(g, target, CAMERA), frames, 1):.1f}"
            if isinstance(target, ChessboardTarget):
                fast = median_ms(lambda g: detect_target(g, target, CAMERA, thorough=False),
                                 frames, 1)
                text += f" ({fast:.1f})"
            absent.append(text)
        rot, trans = np.array(rot), np.array(trans)
        print(f"| `{spec}` | {len(rot)}/{args.frames} | {rot.max():.3f} / "
              f"{np.sqrt(np.mean(rot ** 2)):.3f} | {trans.max():.3f} / "
              f"{np.sqrt(np.mean(trans ** 2)):.3f} | {np.mean(rms):.3f} | {ours:.1f} | {ref:.1f} "
              f"| {ours / ref:.2f} | {absent[0]} | {absent[1]} |")

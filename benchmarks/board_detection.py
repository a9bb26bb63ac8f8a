"""Board detection in unkind views: which OpenCV chessboard detector finds the board, how
accurate its corners are, and what correcting a circle's perspective shift is worth on boards
rendered by Drake.

    python benchmarks/board_detection.py [--views N] [--seed S]

Part 1 — chessboard 9x11 inner corners (25 mm) in N views of 1280×720 px, fx 900 px, k1 −0.18,
k2 0.03 (the real set of issue 33), synthesized without a renderer (the printed pattern through
the plane's homography at 2× and averaged down, then re-mapped through the distortion): board
0.45–1.3 m away, off-centre, tilted up to ~57°, any roll, Gaussian blur σ 0–3 px, light falling
off across the image to 35–100 % at 50–100 % exposure, noise σ 2 grey levels; every corner in
the image.
Counts the boards found by ``findChessboardCorners`` (classic, adaptive threshold, fast check),
the chain ``detect_target`` used before (classic, then SB),
``findChessboardCornersSB`` (with ``CALIB_CB_NORMALIZE_IMAGE``, and with the default flags)
and ``detect_target`` (SB normalized, SB default, then classic with its fast check), the
corner errors against the true projections (max over a board, median over boards) of SB alone,
SB + ``CALIB_CB_ACCURACY``, SB + ``cornerSubPix`` (what ``detect_target`` reports) and classic
+ ``cornerSubPix``, and each detector's time as a ratio to the classic one measured in the same
run.

Part 2 — circle grids rendered by Drake (RenderEngineVtk, 640×480, fx 600 px, 2×2
supersampling) from N random poses (0.35–0.55 m, tilt up to ~35°, any roll): the largest
predicted shift between a circle's image centroid and its centre's image, and the error of the
detected points and of X_CT against the truth with the correction (``detect_target``'s
default) and without it (``correct_circle_centres=False``).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import cv2  # noqa: E402

from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp, \
    rotation_log  # noqa: E402
from handeye_drake.vision.camera_model import CameraIntrinsics  # noqa: E402
from handeye_drake.vision.detection import (_circle_centre_shift, _subpix_window,  # noqa: E402
                                            detect_target)
from handeye_drake.vision.targets import (object_points, parse_target, pattern_extent,  # noqa
                                          render_target)

CHESS = "chessboard:9x11:0.025"
REAL = CameraIntrinsics(alpha_u=900.0, alpha_v=900.0, u0=646.0, v0=355.0, width=1280, height=720,
                        distortion=(-0.18, 0.03, 0.0, 0.0, 0.0))
RENDER = CameraIntrinsics(alpha_u=600.0, alpha_v=601.0, u0=321.3, v0=238.7, width=640, height=480)
CIRCLES = ("acircles:4x11:0.02:white", "circles:7x6:0.03:0.02")


def _synth(spec, K: CameraIntrinsics, X_CT, blur, rng, texture):
    image, A = texture
    W, H = K.width, K.height
    Hm = K.K @ np.column_stack([X_CT[:3, 0], X_CT[:3, 1], X_CT[:3, 3]]) @ np.linalg.inv(A)
    S = np.diag([2.0, 2.0, 1.0])
    S[:2, 2] = 0.5
    big = cv2.warpPerspective(image, S @ Hm, (2 * W, 2 * H), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=100)
    img = cv2.resize(big, (W, H), interpolation=cv2.INTER_AREA)
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    xy = cv2.undistortPoints(np.stack([u.ravel(), v.ravel()], 1).reshape(-1, 1, 2), K.K,
                             K.distortion_coefficients).reshape(-1, 2)
    src = xy @ K.K[:2, :2].T + K.K[:2, 2]
    img = cv2.remap(img, src[:, 0].reshape(H, W).astype(np.float32),
                    src[:, 1].reshape(H, W).astype(np.float32), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=100)
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    # Uneven light: a linear fall-off across the image to 35–100 % and a dimmer exposure.
    g = rng.uniform(0.35, 1.0)
    d = rng.normal(size=2)
    d /= np.linalg.norm(d)
    ramp = ((u - W / 2) * d[0] + (v - H / 2) * d[1]) / math.hypot(W, H) + 0.5
    light = rng.uniform(0.5, 1.0) * (g + (1.0 - g) * ramp)
    return np.clip(img * light + rng.normal(0, 2.0, img.shape), 0, 255).astype(np.uint8)


def _pose(spec, rng, distance, tilt_sigma):
    x0, y0, x1, y1 = pattern_extent(parse_target(spec))
    centre = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0])
    R = rotation_exp([0, 0, rng.uniform(-math.pi, math.pi)]) @ rotation_exp(
        np.append(np.clip(rng.normal(0, tilt_sigma, 2), -1.0, 1.0), 0.0))
    # Off-centre too: near the image border, where the distortion is strongest.
    return make_transform(R, np.array([*(rng.normal(0, 0.12, 2) * distance), distance])
                          - R @ centre)


def _error(found, corners, truth):
    if not found or corners is None or len(corners) != len(truth):
        return None
    c = np.asarray(corners, float).reshape(-1, 2)
    # Compare in whichever order (the board is symmetric: its labels may run from either end).
    return min(np.abs(c - truth).max(), np.abs(c[::-1] - truth).max())


def chessboards(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    texture = render_target(CHESS, 6000.0, margin=0.02)
    _, p = object_points(CHESS)
    size = (9, 11)
    names = ("classic", "classic, then SB (before)", "SB", "SB default flags", "SB+ACCURACY",
             "SB+cornerSubPix",
             "classic+cornerSubPix", "detect_target")
    found = dict.fromkeys(names, 0)
    errors = {k: [] for k in names}
    times = {k: 0.0 for k in ("classic", "SB", "SB+ACCURACY", "detect_target")}
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 40, 1e-3)

    def subpix(img, c):
        c = np.array(c, np.float32).reshape(-1, 1, 2)   # a copy: cornerSubPix works in place
        w = _subpix_window(c.reshape(-1, 2), size[0])
        return cv2.cornerSubPix(img, c, (w, w), (-1, -1), crit)

    made, missed = 0, []
    while made < n:
        X = _pose(CHESS, rng, rng.uniform(0.45, 1.3), 0.5)
        truth = cv2.projectPoints(p, cv2.Rodrigues(X[:3, :3])[0], X[:3, 3], REAL.K,
                                  REAL.distortion_coefficients)[0].reshape(-1, 2)
        m = 8
        if np.any(truth < m) or np.any(truth[:, 0] > REAL.width - m) or \
                np.any(truth[:, 1] > REAL.height - m):
            continue                   # every corner in view: a board a detector should find
        made += 1
        img = _synth(CHESS, REAL, X, rng.uniform(0.0, 3.0), rng, texture)
        t = time.perf_counter()
        ok_c, c_c = cv2.findChessboardCorners(img, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH
                                              | cv2.CALIB_CB_NORMALIZE_IMAGE
                                              | cv2.CALIB_CB_FAST_CHECK)
        times["classic"] += time.perf_counter() - t
        t = time.perf_counter()
        ok_s, c_s = cv2.findChessboardCornersSB(img, size, flags=cv2.CALIB_CB_NORMALIZE_IMAGE)
        times["SB"] += time.perf_counter() - t
        t = time.perf_counter()
        ok_a, c_a = cv2.findChessboardCornersSB(img, size, flags=cv2.CALIB_CB_NORMALIZE_IMAGE
                                                | cv2.CALIB_CB_ACCURACY)
        ok_0, c_0 = cv2.findChessboardCornersSB(img, size)
        times["SB+ACCURACY"] += time.perf_counter() - t
        t = time.perf_counter()
        det = detect_target(img, CHESS, REAL)
        times["detect_target"] += time.perf_counter() - t
        if not det.found:
            missed.append(det.reason)
        # What detect_target did before: classic, else SB; then cornerSubPix.
        ok_f, c_f = (ok_c, c_c) if ok_c else (ok_s, c_s)
        c_f = subpix(img, c_f) if ok_f else None
        results = {"classic": (ok_c, c_c), "SB": (ok_s, c_s), "SB default flags": (ok_0, c_0),
                   "classic, then SB (before)": (ok_f, c_f), "SB+ACCURACY": (ok_a, c_a),
                   "SB+cornerSubPix": (ok_s, subpix(img, c_s) if ok_s else None),
                   "classic+cornerSubPix": (ok_c, subpix(img, c_c) if ok_c else None),
                   "detect_target": (det.found, det.image_points if det.found else None)}
        for k, (ok, c) in results.items():
            e = _error(ok, c, truth)
            if e is not None:
                found[k] += 1
                errors[k].append(e)
    print(f"chessboard 9x11 in {n} views of 1280×720 px, k1 −0.18, blur σ 0–3 px, uneven "
          f"light (seed {seed})")
    print(f"  {'detector':<28} {'found':>7} {'corner error, max per board (px)':>36}")
    for k in names:
        e = np.array(errors[k])
        stats = f"median {np.median(e):.3f}, 90 % {np.percentile(e, 90):.3f}" if len(e) else "-"
        print(f"  {k:<28} {found[k]:>3}/{n:<3} {stats:>36}")
    for reason in missed:
        print(f"  detect_target missed: {reason}")
    ref = times["classic"]
    print("  time per view relative to the classic detector (same run): " + ", ".join(
        f"{k} {times[k] / ref:.1f}×" for k in ("SB", "SB+ACCURACY", "detect_target"))
        + f" (classic {1000 * ref / n:.1f} ms)")


def circle_grids(n: int, seed: int) -> None:
    from pydrake.geometry import SceneGraph
    from pydrake.systems.framework import DiagramBuilder

    from handeye_drake.systems.rendered_camera import add_rendered_camera, add_target_geometry
    X_WT = make_transform(rotation_exp([0.1, -0.2, 0.3]), [0.3, -0.1, 0.05])
    print(f"circle grids rendered by Drake (RenderEngineVtk), {n} views each, 640×480 px, "
          f"fx 600 px (seed {seed}); median / max")
    print(f"  {'board':<26} {'shift (px)':>11} {'points (px)':>20} {'rotation (deg)':>22} "
          f"{'translation (mm)':>22}")
    for spec in CIRCLES:
        target = parse_target(spec)
        rng = np.random.default_rng(seed)
        x0, y0, x1, y1 = pattern_extent(target)
        centre = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0])
        poses = []
        while len(poses) < n:
            R = rotation_exp(np.append(rng.uniform(-0.6, 0.6, 2), 0.0)) @ rotation_exp(
                [0.0, 0.0, rng.uniform(-math.pi, math.pi)])
            X_TC = make_transform(R, centre + np.append(rng.uniform(-0.02, 0.02, 2), 0.0)
                                  - rng.uniform(0.35, 0.55) * R[:, 2])
            poses.append(X_TC)
        builder = DiagramBuilder()
        scene_graph = builder.AddSystem(SceneGraph())
        add_target_geometry(scene_graph, target, X_WT)
        cameras = [add_rendered_camera(builder, scene_graph, scene_graph.world_frame_id(),
                                       X_WT @ X_TC, RENDER, supersample=2, name=f"c{k}")
                   for k, X_TC in enumerate(poses)]
        diagram = builder.Build()
        context = diagram.CreateDefaultContext()
        _, p = object_points(target)
        rows = {True: [], False: []}
        shifts = []
        for camera, X_TC in zip(cameras, poses):
            image = camera.EvalColorImage(context)
            X_CT = inverse(X_TC)
            shifts.append(np.abs(_circle_centre_shift(X_CT, target, RENDER)).max())
            truth = cv2.projectPoints(p, cv2.Rodrigues(X_CT[:3, :3])[0], X_CT[:3, 3], RENDER.K,
                                      None)[0].reshape(-1, 2)
            for corrected in (True, False):
                det = detect_target(image, target, RENDER, correct_circle_centres=corrected)
                if not det.found:
                    if corrected:
                        print(f"  {spec} missed: {det.reason}")
                    continue
                # A symmetric grid may be labelled from the other end: compare its points in
                # the detector's labels, its pose after undoing the turn the points show.
                pts = np.empty_like(det.image_points)
                pts[det.ids] = det.image_points
                X = det.X_CT
                if np.abs(pts - truth).max() > 5.0:
                    pts = pts[::-1]
                    from handeye_drake.vision.targets import target_symmetries
                    G = target_symmetries(target)[0][0]
                    X = X @ inverse(G)
                rows[corrected].append((np.abs(pts - truth).max(),
                                        math.degrees(np.linalg.norm(rotation_log(
                                            X[:3, :3] @ X_CT[:3, :3].T))),
                                        1000 * np.linalg.norm(X[:3, 3] - X_CT[:3, 3])))
        for corrected in (True, False):
            r = np.array(rows[corrected])
            label = f"{spec} {'corrected' if corrected else 'raw'}"
            shift = f"{np.median(shifts):.3f} / {max(shifts):.3f}" if corrected else ""
            print(f"  {label:<36} {shift:>11} "
                  + "  ".join(f"{np.median(r[:, k]):>8.4f} / {r[:, k].max():<8.4f}"
                              for k in range(3)) + f"  ({len(r)} found)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=16)
    parser.add_argument("--seed", type=int, default=5)
    args = parser.parse_args()
    chessboards(args.views, args.seed)
    circle_grids(args.views, args.seed)
    return 0


if __name__ == "__main__":
    sys.exit(main())

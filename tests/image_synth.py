"""Image sets of a planar target with known truth, made without a renderer (for fast tests of the
image path in both modes): the printed pattern (``vision.targets.render_target``) is mapped into
each image by the homography of its pose, at twice the resolution and averaged down (anti-
aliasing), then re-mapped to show lens distortion when asked.

Eye-in-hand: the board lies in the cell (X_BT), the camera rides on the flange (X_EC).
Eye-to-hand: the camera is fixed in the cell (X_BC), the board rides on the flange (X_ET).
Files: ``img_NNN.png``, ``robot_poses.tum`` (X_BE, one line per image), and the returned truth.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from handeye_drake.estimation.se3 import inverse, make_transform, quat_wxyz, rotation_exp
from handeye_drake.vision.targets import parse_target, pattern_extent, render_target

WIDTH, HEIGHT = 640, 480
K = np.array([[600.0, 0.0, 322.0], [0.0, 601.0, 238.0], [0.0, 0.0, 1.0]])
SPEC = "charuco:7x5:0.04:0.03:DICT_5X5_100"
X_EC = make_transform(rotation_exp([0.04, -0.05, 1.57]), [0.035, -0.05, 0.07])
X_BT = make_transform(rotation_exp([math.pi, 0.0, 0.3]), [0.55, -0.12, 0.0])
X_BC_FIXED = make_transform(rotation_exp([2.2, 0.3, 0.1]), [0.9, 0.4, 0.8])
X_ET = make_transform(rotation_exp([0.1, 0.05, -0.2]), [0.02, -0.03, 0.09])


def _undistort_map(dist):
    u, v = np.meshgrid(np.arange(WIDTH, dtype=np.float64), np.arange(HEIGHT, dtype=np.float64))
    pts = np.stack([u.ravel(), v.ravel()], 1).reshape(-1, 1, 2)
    xy = cv2.undistortPoints(pts, K, np.asarray(dist, float)).reshape(-1, 2)
    src = xy @ K[:2, :2].T + K[:2, 2]
    return (src[:, 0].reshape(HEIGHT, WIDTH).astype(np.float32),
            src[:, 1].reshape(HEIGHT, WIDTH).astype(np.float32))


def _image(X_CT, texture, A, maps):
    H = K @ np.column_stack([X_CT[:3, 0], X_CT[:3, 1], X_CT[:3, 3]]) @ np.linalg.inv(A)
    S = np.diag([2.0, 2.0, 1.0])
    S[:2, 2] = 0.5                      # pixel centres of the 2× image
    big = cv2.warpPerspective(texture, S @ H, (2 * WIDTH, 2 * HEIGHT), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=90)
    img = cv2.resize(big, (WIDTH, HEIGHT), interpolation=cv2.INTER_AREA)
    if maps is not None:
        img = cv2.remap(img, maps[0], maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                        borderValue=90)
    return img


def synthesize(folder, mode: str = "eye_in_hand", n: int = 12, seed: int = 0,
               distortion=(0.0,) * 5, spec: str = SPEC) -> dict:
    """Writes the image set into ``folder`` and returns the truth: X_hand (X_EC or X_BC),
    X_fixed (X_BT or X_ET), K, distortion, X_BE (n, 4, 4)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    target = parse_target(spec)
    texture, A = render_target(target, 4000.0, margin=0.02)
    x0, y0, x1, y1 = pattern_extent(target)
    centre_T = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0])
    corners_T = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], float)
    maps = _undistort_map(distortion) if np.any(distortion) else None
    lines = ["# synthetic image set: X_BE, index tx ty tz qx qy qz qw"]
    X_BEs = []
    while len(X_BEs) < n:
        # The target's centre 0.35–0.5 m in front of the camera, tilted up to ~30°.
        R_CT = rotation_exp(rng.normal(size=3) * [0.35, 0.35, 0.6])
        p_centre = np.array([rng.uniform(-0.06, 0.06), rng.uniform(-0.05, 0.05),
                             rng.uniform(0.35, 0.5)])
        X_CT = make_transform(R_CT, p_centre - R_CT @ centre_T)
        p = corners_T @ X_CT[:3, :3].T + X_CT[:3, 3]
        if np.any(p[:, 2] < 0.2) or (R_CT @ [0, 0, 1])[2] < 0.5:
            continue                              # the printed face must look at the camera
        uv = (p @ K.T)[:, :2] / p[:, 2:]
        if np.any(uv < 15) or np.any(uv[:, 0] > WIDTH - 16) or np.any(uv[:, 1] > HEIGHT - 16):
            continue
        if mode == "eye_in_hand":
            X_BE = X_BT @ inverse(X_CT) @ inverse(X_EC)
        else:
            X_BE = X_BC_FIXED @ X_CT @ inverse(X_ET)
        k = len(X_BEs)
        cv2.imwrite(str(folder / f"img_{k:03d}.png"), _image(X_CT, texture, A, maps))
        q = quat_wxyz(X_BE[:3, :3])
        lines.append(f"{k} " + " ".join(f"{v:.12f}" for v in X_BE[:3, 3]) + " "
                     + " ".join(f"{v:.12f}" for v in (q[1], q[2], q[3], q[0])))
        X_BEs.append(X_BE)
    (folder / "robot_poses.tum").write_text("\n".join(lines) + "\n")
    hand = X_EC if mode == "eye_in_hand" else X_BC_FIXED
    fixed = X_BT if mode == "eye_in_hand" else X_ET
    return {"X_hand": hand, "X_fixed": fixed, "K": K, "distortion": tuple(distortion),
            "X_BE": np.array(X_BEs), "spec": spec,
            "intrinsics": ",".join(f"{v:.10g}" for v in (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))}

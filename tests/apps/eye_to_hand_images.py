"""A small eye-to-hand image set with known truth: a camera fixed in the cell at X_BC looks at a
chessboard held by the flange at X_ET; each image is the board warped by the pinhole homography
(2 × 2 supersampled, so corners fall at their sub-pixel positions), no lens distortion; the robot poses carry a small error (``write_set``).

``write_set(out_dir)`` writes ``img_NN.png``, ``robot_poses.tum`` (X_BE, metres) and returns the
truth (X_BC, X_ET, the target spec and the intrinsics string for ``--intrinsics``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from handeye_drake.estimation.se3 import inverse, make_transform, quat_wxyz, rotation_exp

TARGET = "chessboard:9x6:0.03"
SIZE = (640, 480)
K = np.array([[600.0, 0.0, 321.5], [0.0, 600.0, 238.0], [0.0, 0.0, 1.0]])
#: Camera 1.1 m from the base, looking back at the robot; board 4 cm off the flange.
X_BC = make_transform(rotation_exp([2.2, 0.2, -0.3]), [1.1, 0.25, 0.55])
X_ET = make_transform(rotation_exp([0.05, -0.08, 0.6]), [-0.12, -0.09, 0.04])


def _render(X_CT: np.ndarray, texture: np.ndarray, A: np.ndarray) -> np.ndarray:
    import cv2
    S = np.array([[2.0, 0.0, 0.5], [0.0, 2.0, 0.5], [0.0, 0.0, 1.0]])  # 1× → 2× pixel centres
    H = S @ K @ np.column_stack([X_CT[:3, 0], X_CT[:3, 1], X_CT[:3, 3]]) @ np.linalg.inv(A)
    big = cv2.warpPerspective(texture, H, (2 * SIZE[0], 2 * SIZE[1]), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=60)
    return cv2.resize(big, SIZE, interpolation=cv2.INTER_AREA)


def write_set(out_dir, n: int = 12, seed: int = 0) -> dict:
    import cv2

    from handeye_drake.vision.targets import render_target
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    texture, A = render_target(TARGET, 2400.0, margin=0.02)
    centre = np.array([0.12, 0.075, 0.0])  # the board's middle in T
    lines = ["# timestamp tx ty tz qx qy qz qw (X_BE, flange in base, metres)"]
    for k in range(n):
        axis = rng.normal(size=3)
        axis[2] = 0.0
        tilt = math.radians(rng.uniform(15, 35)) * axis / np.linalg.norm(axis)
        R = rotation_exp(tilt) @ rotation_exp([0.0, 0.0, math.radians(rng.uniform(-30, 30))])
        p = np.array([rng.uniform(-0.06, 0.06), rng.uniform(-0.05, 0.05), rng.uniform(0.55, 0.75)])
        X_CT = make_transform(R, p - R @ centre)
        X_BE = X_BC @ X_CT @ inverse(X_ET)
        cv2.imwrite(str(out / f"img_{k:02d}.png"), _render(X_CT, texture, A))
        # The robot reports its pose with a repeatability-like error (0.02°, 0.1 mm per axis).
        X_BE = X_BE @ make_transform(rotation_exp(np.radians(0.02) * rng.normal(size=3)),
                                     1e-4 * rng.normal(size=3))
        w, x, y, z = quat_wxyz(X_BE[:3, :3])
        t = X_BE[:3, 3]
        lines.append(f"{k} {t[0]:.6f} {t[1]:.6f} {t[2]:.6f} {x:.9f} {y:.9f} {z:.9f} {w:.9f}")
    (out / "robot_poses.tum").write_text("\n".join(lines) + "\n")
    return {"X_BC": X_BC, "X_ET": X_ET, "target": TARGET,
            "intrinsics": f"{K[0, 0]:g},{K[1, 1]:g},{K[0, 2]:g},{K[1, 2]:g}"}


if __name__ == "__main__":
    import sys
    print(write_set(sys.argv[1]))

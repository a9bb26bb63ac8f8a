"""``benchmark speed``'s ``corners`` section: the corner-level fit (``estimation.reprojection``)
against OpenCV's own bundle adjustment of the same corners, in the same run.

Reference: ``cv2.calibrateCamera`` on the same detections with the intrinsics given as a guess
(fx, fy, cx, cy, k1, k2 refined; p1, p2, k3 fixed) — per-image poses and shared intrinsics by
Levenberg–Marquardt in C++, the same size of problem (6 parameters per image plus the shared
ones) as the corner-level fit with ``k1k2``, whose per-image unknowns are the pose errors. Printed:
seconds of each, their ratio, and our cost per image at each size (flat = linear in the number of
images).
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..estimation import reprojection as rp
from ..estimation.se3 import inverse, make_transform, rotation_exp

#: Image counts timed (48 corners each).
CORNER_SIZES = (100, 1000)


def _corner_set(n: int, seed: int = 0):
    """n images of an 8×6 board (30 mm) from random flange poses, projected by OpenCV with
    k1 −0.1, k2 0.05, 0.1 px noise and a 0.03° / 0.15 mm robot error per image."""
    import cv2
    rng = np.random.default_rng(seed)
    X_EC = make_transform(rotation_exp([0.05, -0.03, 1.6]), [0.04, -0.05, 0.06])
    X_BT = make_transform(rotation_exp([math.pi, 0, 0.2]), [0.6, 0.0, 0.0])
    gx, gy = np.meshgrid(np.arange(8) * 0.03, np.arange(6) * 0.03)
    board = np.stack([gx.ravel(), gy.ravel(), 0 * gx.ravel()], 1)
    v = np.array([612.0, 611.0, 321.0, 239.0, -0.1, 0.05, 0, 0, 0])
    K, dist = rp.intrinsics_matrix(v)
    X_BE, img = [], []
    while len(X_BE) < n:
        c = X_BT[:3, 3] + [0.1, 0.08, 0.45] + rng.normal(size=3) * [0.1, 0.1, 0.05]
        X_BC = make_transform(rotation_exp([math.pi, 0, 0]) @ rotation_exp(
            rng.normal(size=3) * 0.3), c)
        X = X_BC @ inverse(X_EC)
        err = make_transform(rotation_exp(rng.normal(size=3) * math.radians(0.03)),
                             rng.normal(size=3) * 0.15e-3)
        X_CT = inverse(X @ err @ X_EC) @ X_BT
        if np.min(board @ X_CT[:3, :3].T[:, 2] + X_CT[2, 3]) < 0.15:
            continue
        uv = cv2.projectPoints(board, cv2.Rodrigues(X_CT[:3, :3])[0], X_CT[:3, 3], K,
                               dist)[0].reshape(-1, 2) + rng.normal(size=(len(board), 2)) * 0.1
        if np.any(uv < 0) or np.any(uv[:, 0] > 639) or np.any(uv[:, 1] > 479):
            continue
        X_BE.append(X)
        img.append(uv)
    return np.array(X_BE), board, img, v, X_EC, X_BT


def corners_section(sizes=CORNER_SIZES, log=print) -> list[dict]:
    import cv2
    rows = []
    for n in sizes:
        X_BE, board, img, v, X_EC, X_BT = _corner_set(n, seed=n)
        data = rp.CornerData.from_lists(X_BE, [board] * n, img)
        start_H = X_EC @ make_transform(rotation_exp([0.002, -0.001, 0.002]),
                                        [0.001, 0.001, -0.001])
        v0 = v.copy()
        v0[:2] *= 1.005
        t = time.perf_counter()
        fit = rp.fit_corners(data, start_H, X_BT, v0, "k1k2")
        ours = time.perf_counter() - t
        K0, d0 = rp.intrinsics_matrix(v0)
        flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_TANGENT_DIST
                 | cv2.CALIB_FIX_K3)
        t = time.perf_counter()
        cv2.calibrateCamera([board.astype(np.float32)] * n, [u.astype(np.float32) for u in img],
                            (640, 480), K0.copy(), d0.copy(), flags=flags)
        reference = time.perf_counter() - t
        row = {"section": "corners", "images": n, "corners": 48 * n, "seconds": ours,
               "ms_per_image": 1000 * ours / n, "reference_seconds": reference,
               "ratio": ours / reference, "iterations": fit.iterations}
        rows.append(row)
        log(f"  corner-level fit (k1k2), {n:5d} images × 48 corners: {ours:7.2f} s "
            f"({row['ms_per_image']:.2f} ms per image) = {row['ratio']:.2f}× "
            f"cv2.calibrateCamera on the same corners ({reference:.2f} s)")
    if len(rows) >= 2:
        per = [r["ms_per_image"] for r in rows]
        rows.append({"section": "corners", "cost_per_image_growth": per[-1] / per[0]})
        log(f"  cost per image at {rows[-2]['images']} vs {rows[0]['images']} images: "
            f"{per[-1] / per[0]:.2f}× (1 = linear in the number of images)")
    return rows


__all__ = ["CORNER_SIZES", "corners_section"]

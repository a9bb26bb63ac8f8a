"""Unkind synthetic views of a planar target without a renderer (fast detector tests): the printed
pattern (``render_target``) mapped by the homography of a pose at 2× resolution, averaged down,
re-mapped through strong lens distortion, blurred and noised as asked. Pixel convention: OpenCV's
(pixel centres at integers)."""

from __future__ import annotations

import cv2
import numpy as np

from handeye_drake.estimation.se3 import make_transform, rotation_exp
from handeye_drake.vision.camera_model import CameraIntrinsics
from handeye_drake.vision.targets import parse_target, pattern_extent, render_target


def intrinsics(width=1280, height=720, f=900.0, k1=-0.18, k2=0.03) -> CameraIntrinsics:
    dist = (k1, k2, 0.0, 0.0, 0.0) if k1 or k2 else ()
    return CameraIntrinsics(alpha_u=f, alpha_v=f * 1.002, u0=(width - 1) / 2 + 7.3,
                            v0=(height - 1) / 2 - 4.1, width=width, height=height,
                            distortion=dist)


def board_pose(spec, distance=0.6, tilt=(0.35, -0.25), roll=0.3, offset=(0.0, 0.0)):
    """X_CT with the board's centre ``distance`` m in front, at ``offset`` (m, in C's x, y)."""
    x0, y0, x1, y1 = pattern_extent(parse_target(spec))
    centre = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0])
    R = rotation_exp([tilt[0], tilt[1], roll])
    return make_transform(R, np.array([offset[0], offset[1], distance]) - R @ centre)


_TEXTURES = {}


def view(spec, K: CameraIntrinsics, X_CT, blur_px: float = 0.0, noise: float = 0.0,
         background: int = 110, seed: int = 0, ppm: float = 8000.0) -> np.ndarray:
    """uint8 grey image of the target at X_CT seen by K (distortion included)."""
    key = (spec, ppm)
    if key not in _TEXTURES:
        _TEXTURES[key] = render_target(parse_target(spec), ppm, margin=0.015)
    texture, A = _TEXTURES[key]
    W, H = K.width, K.height
    Kp = np.array(K.K, float)
    Hm = Kp @ np.column_stack([X_CT[:3, 0], X_CT[:3, 1], X_CT[:3, 3]]) @ np.linalg.inv(A)
    S = np.diag([2.0, 2.0, 1.0])
    S[:2, 2] = 0.5
    big = cv2.warpPerspective(texture, S @ Hm, (2 * W, 2 * H), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=background)
    img = cv2.resize(big, (W, H), interpolation=cv2.INTER_AREA)
    if K.distortion:
        u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
        pts = np.stack([u.ravel(), v.ravel()], 1).reshape(-1, 1, 2)
        xy = cv2.undistortPoints(pts, Kp, K.distortion_coefficients).reshape(-1, 2)
        src = xy @ Kp[:2, :2].T + Kp[:2, 2]
        img = cv2.remap(img, src[:, 0].reshape(H, W).astype(np.float32),
                        src[:, 1].reshape(H, W).astype(np.float32), cv2.INTER_LINEAR,
                        borderMode=cv2.BORDER_CONSTANT, borderValue=background)
    if blur_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_px)
    if noise > 0:
        rng = np.random.default_rng(seed)
        img = np.clip(img + rng.normal(0, noise, img.shape), 0, 255).astype(np.uint8)
    return img

"""Synthetic camera images of calibration targets for the vision tests (no mocks: the printed
pattern of ``render_target`` is imaged through a pinhole + OpenCV distortion model).

The image is rendered at ``supersample``× the resolution with an exact per-pixel ray → plane
mapping (undistortion of each pixel, then the inverse homography of the plane), box-filtered
down to the camera resolution (pixel area integration), blurred (optics) and given Gaussian
grey-level noise (sensor)."""

from __future__ import annotations

import cv2
import numpy as np

from handeye_drake.estimation.se3 import make_transform, rotation_exp
from handeye_drake.vision.camera_model import CameraIntrinsics
from handeye_drake.vision.targets import pattern_extent, render_target

#: The test camera: 640×480, fx ≈ 600 px.
CAMERA = CameraIntrinsics(alpha_u=600.0, alpha_v=602.0, u0=318.5, v0=241.0, width=640,
                          height=480)


def look_at_pose(target, distance, tilt=(0.0, 0.0, 0.0), offset=(0.0, 0.0), roll=0.0):
    """X_CT of a camera ``distance`` m in front of the target's printed face, looking at the
    pattern centre (shifted by ``offset`` m in T), then the target rotated by ``tilt`` (rotation
    vector, rad, about its centre, in C) and ``roll`` about the optical axis."""
    x0, y0, x1, y1 = pattern_extent(target)
    centre = np.array([(x0 + x1) / 2 + offset[0], (y0 + y1) / 2 + offset[1], 0.0])
    # Fronto-parallel: T's z (into the board) along C's z, x along C's x.
    R = rotation_exp([0.0, 0.0, roll]) @ rotation_exp(tilt)
    p = np.array([0.0, 0.0, distance]) - R @ centre
    return make_transform(R, p)


def synthetic_image(target, X_CT, intrinsics=CAMERA, rng=None, noise_sigma=2.0, blur_sigma=0.5,
                    supersample=3, margin=None, background=90, paper=235, ink=25):
    """uint8 grey (H, W) image of ``target`` printed on white paper (``margin`` m of white around
    the pattern, default one pattern module) seen at ``X_CT`` by ``intrinsics`` (its distortion
    included)."""
    s = int(supersample)
    W, H = intrinsics.width, intrinsics.height
    K = intrinsics.K
    if margin is None:
        x0, y0, x1, y1 = pattern_extent(target)
        margin = 0.12 * min(x1 - x0, y1 - y0) + 0.005
    # Texture resolution: about one texel per high-resolution pixel at the nearest corner.
    x0, y0, x1, y1 = pattern_extent(target)
    corners = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], float)
    z = (corners @ X_CT[:3, :3].T + X_CT[:3, 3])[:, 2]
    ppm = min(1.5 * s * K[0, 0] / max(z.min(), 1e-3), 30000.0)
    texture, A = render_target(target, ppm, margin)
    texture = (ink + (paper - ink) * (texture.astype(np.float32) / 255.0)).astype(np.float32)

    # Centres of the high-resolution pixels in low-resolution pixel coordinates.
    U, V = np.meshgrid((np.arange(W * s) + 0.5) / s - 0.5, (np.arange(H * s) + 0.5) / s - 0.5)
    uv = np.stack([U.ravel(), V.ravel()], axis=1).astype(np.float64)
    dist = np.asarray(intrinsics.distortion, float) if getattr(intrinsics, "distortion", ()) \
        else None
    if dist is None:
        xy = (uv - K[:2, 2]) @ np.linalg.inv(K[:2, :2]).T
    else:
        xy = cv2.undistortPointsIter(uv.reshape(-1, 1, 2), K, dist, None, None,
                                     (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
                                     ).reshape(-1, 2)
    Hn = X_CT[:3, [0, 1, 3]]  # [r1 r2 t]: plane (x_T, y_T, 1) → normalized ray
    q = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1) @ np.linalg.inv(Hn).T
    in_front = q[:, 2] > 1e-9
    q[~in_front, 2] = 1.0
    tex = (q / q[:, 2:3]) @ A.T
    map_x = np.where(in_front, tex[:, 0], -1e6).reshape(H * s, W * s).astype(np.float32)
    map_y = np.where(in_front, tex[:, 1], -1e6).reshape(H * s, W * s).astype(np.float32)
    hi = cv2.remap(texture, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                   borderValue=float(background))
    img = cv2.resize(hi, (W, H), interpolation=cv2.INTER_AREA)
    if blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_sigma)
    if noise_sigma > 0:
        rng = np.random.default_rng(0) if rng is None else rng
        img = img + rng.normal(0.0, noise_sigma, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def project(X_CT, p_TQ, intrinsics=CAMERA):
    """Pixels (N, 2) of target points through the camera (with its distortion)."""
    rvec, _ = cv2.Rodrigues(X_CT[:3, :3])
    dist = np.asarray(intrinsics.distortion, float) if getattr(intrinsics, "distortion", ()) \
        else None
    uv, _ = cv2.projectPoints(np.asarray(p_TQ, float).reshape(-1, 1, 3), rvec, X_CT[:3, 3],
                              intrinsics.K, dist)
    return uv.reshape(-1, 2)

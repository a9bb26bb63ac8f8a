"""Synthetic camera images of calibration targets for the vision tests (no mocks: the printed
pattern of ``render_target`` is imaged through a pinhole + OpenCV distortion model).

The image is rendered at ``supersample``× the resolution with an exact per-pixel mapping (the
plane's homography, or with distortion each pixel's undistorted ray met with the plane),
box-filtered down to the camera resolution (pixel area integration), blurred (optics) and given Gaussian
grey-level noise (sensor)."""

from __future__ import annotations

import functools

import cv2
import numpy as np

from handeye_drake.estimation.se3 import make_transform, rotation_exp
from handeye_drake.vision.camera_model import CameraIntrinsics
from handeye_drake.vision.targets import format_target, pattern_extent, render_target

#: The test camera: 640×480, fx ≈ 600 px.
CAMERA = CameraIntrinsics(alpha_u=600.0, alpha_v=602.0, u0=318.5, v0=241.0, width=640,
                          height=480)


@functools.lru_cache(maxsize=16)
def _texture(spec, ppm, margin):
    return render_target(spec, ppm, margin)


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
    sheet = np.array([[x0 - margin, y0 - margin, 0], [x1 + margin, y0 - margin, 0],
                      [x1 + margin, y1 + margin, 0], [x0 - margin, y1 + margin, 0]], float)
    assert np.all((sheet @ X_CT[:3, :3].T + X_CT[:3, 3])[:, 2] > 0.01), "paper behind the camera"
    ppm = min(1.5 * s * K[0, 0] / max(z.min(), 1e-3), 30000.0)
    texture, A = _texture(format_target(target), float(np.ceil(ppm / 500.0) * 500.0), margin)
    texture = (ink + (paper - ink) * (texture.astype(np.float32) / 255.0)).astype(np.float32)

    if intrinsics.distortion_coefficients is None:
        # High-resolution pixel U = s (u + ½) − ½ of low-resolution pixel u (centres at integers).
        S = np.array([[s, 0.0, 0.5 * (s - 1)], [0.0, s, 0.5 * (s - 1)], [0.0, 0.0, 1.0]])
        H_img_tex = S @ K @ X_CT[:3, [0, 1, 3]] @ np.linalg.inv(A)
        hi = cv2.warpPerspective(texture, H_img_tex, (W * s, H * s), flags=cv2.INTER_LINEAR,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=float(background))
    else:
        hi = _remap_distorted(texture, A, X_CT, intrinsics, s, background)
    img = cv2.resize(hi, (W, H), interpolation=cv2.INTER_AREA)
    if blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_sigma)
    if noise_sigma > 0:
        rng = np.random.default_rng(0) if rng is None else rng
        img = img + rng.normal(0.0, noise_sigma, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def _remap_distorted(texture, A, X_CT, intrinsics, s, background):
    """The high-resolution image through the lens distortion: each pixel centre is undistorted
    to its ray, which meets the plane at a texture point."""
    W, H, K = intrinsics.width, intrinsics.height, intrinsics.K
    # The undistorted ray is a smooth function of the pixel: solve it on a grid 4 high-resolution
    # pixels apart (plus a border) and interpolate bicubically.
    step = 4
    gw, gh = W * s // step + 3, H * s // step + 3
    U, V = np.meshgrid((np.arange(gw) - 1) * step, (np.arange(gh) - 1) * step)
    uv = np.stack([U.ravel(), V.ravel()], axis=1).astype(np.float64)
    uv = ((uv + 0.5) / s - 0.5).reshape(-1, 1, 2)
    xy = cv2.undistortPointsIter(uv, K, intrinsics.distortion_coefficients, None, None,
                                 (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12))
    grid_x = xy[:, 0, 0].reshape(gh, gw).astype(np.float32)
    grid_y = xy[:, 0, 1].reshape(gh, gw).astype(np.float32)
    # High-resolution pixel (i, j) sits at grid coordinate (i / step + 1, j / step + 1).
    jj, ii = np.meshgrid(np.arange(W * s, dtype=np.float32) / step + 1,
                         np.arange(H * s, dtype=np.float32) / step + 1)
    x = cv2.remap(grid_x, jj, ii, cv2.INTER_CUBIC).astype(np.float64)
    y = cv2.remap(grid_y, jj, ii, cv2.INTER_CUBIC).astype(np.float64)
    # Elementwise arithmetic rather than (N, 3) @ (3, 3) products, which go through BLAS and
    # crawl when its threads compete for the cores.
    G = np.linalg.inv(X_CT[:3, [0, 1, 3]])  # normalized ray → plane (x_T, y_T, 1): [r1 r2 t]⁻¹
    qx = G[0, 0] * x + G[0, 1] * y + G[0, 2]
    qy = G[1, 0] * x + G[1, 1] * y + G[1, 2]
    qw = G[2, 0] * x + G[2, 1] * y + G[2, 2]
    in_front = qw > 1e-9  # the pixel's ray meets the plane in front of the camera
    qw = np.where(in_front, qw, 1.0)
    map_x = np.where(in_front, A[0, 0] * qx / qw + A[0, 2], -1e6).astype(np.float32)
    map_y = np.where(in_front, A[1, 1] * qy / qw + A[1, 2], -1e6).astype(np.float32)
    return cv2.remap(texture, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=float(background))


def project(X_CT, p_TQ, intrinsics=CAMERA):
    """Pixels (N, 2) of target points through the camera (with its distortion)."""
    rvec, _ = cv2.Rodrigues(X_CT[:3, :3])
    dist = intrinsics.distortion_coefficients
    uv, _ = cv2.projectPoints(np.asarray(p_TQ, float).reshape(-1, 1, 3), rvec, X_CT[:3, 3],
                              intrinsics.K, dist)
    return uv.reshape(-1, 2)

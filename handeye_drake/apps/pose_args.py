"""Poses, points and intrinsics on the command line (``plan``, ``session``): ``x,y,z,qx,qy,qz,qw``
(metres, quaternion scalar last), ``x,y,z`` and ``fx,fy,cx,cy,W,H`` (pixels)."""

from __future__ import annotations

import numpy as np

from ..estimation.se3 import make_transform, rotation_from_quat_wxyz
from ..vision.camera_model import CameraIntrinsics


def _numbers(text: str, name: str, counts: tuple) -> np.ndarray:
    try:
        v = np.array([float(s) for s in text.replace(" ", ",").split(",") if s], dtype=float)
    except ValueError:
        raise ValueError(f"{name}: expected {' or '.join(map(str, counts))} comma-separated "
                         f"numbers, got {text!r}") from None
    if len(v) not in counts:
        raise ValueError(f"{name}: expected {' or '.join(map(str, counts))} comma-separated "
                         f"numbers, got {len(v)} in {text!r}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name}: values must be finite, got {text!r}")
    return v


def parse_pose(text: str, name: str) -> np.ndarray:
    """``x,y,z,qx,qy,qz,qw`` (metres; quaternion scalar last, norm within 1e-3 of 1) → 4×4."""
    v = _numbers(text, name, (7,))
    q = v[3:]
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > 1e-3:
        raise ValueError(f"{name}: the quaternion (qx, qy, qz, qw) = {q.tolist()} has norm "
                         f"{norm:.6g}, expected 1 (order x,y,z,qx,qy,qz,qw)")
    q = q / norm
    return make_transform(rotation_from_quat_wxyz([q[3], q[0], q[1], q[2]]), v[:3])


def parse_point(text: str, name: str) -> np.ndarray:
    """``x,y,z`` (or a full pose, whose translation is used) → (3,)."""
    v = _numbers(text, name, (3, 7))
    return v[:3] if len(v) == 3 else parse_pose(text, name)[:3, 3]


def parse_intrinsics(text: str) -> CameraIntrinsics:
    """``--intrinsics``: any form ``calibrate --intrinsics`` takes (an OpenCV or ROS camera_info
    YAML, which carry the image size), or ``fx,fy,cx,cy,W,H`` (the image size, W×H pixels,
    last)."""
    from pathlib import Path

    from ..vision.intrinsics import load_intrinsics
    if Path(text).is_file() or "," not in text:
        try:
            return load_intrinsics(text)
        except ValueError as e:
            raise ValueError(f"--intrinsics: {e}") from None
    v = _numbers(text, "--intrinsics", (6,))
    fx, fy, cx, cy, w, h = v
    if w != int(w) or h != int(h):
        raise ValueError(f"--intrinsics: width and height must be integers, got {w:g}, {h:g}")
    try:
        return CameraIntrinsics(alpha_u=fx, alpha_v=fy, u0=cx, v0=cy, width=int(w),
                                height=int(h))
    except ValueError as e:
        raise ValueError(f"--intrinsics {text}: {e}") from None

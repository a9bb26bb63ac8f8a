"""Corner sets with known truth, made without images (fast): a planar grid seen by a camera of
known intrinsics (OpenCV's model, distortion included) from robot poses whose errors repeat with
the pose, each image's corners projected, noised and detected by PnP with the intrinsics the
user *gives* (which may be wrong) — the ``Streams`` ``calibrate`` gets from image inputs.

Eye-in-hand: X_EC on the flange, the grid in the cell (X_BT). Eye-to-hand: X_BC fixed, the grid
on the flange (X_ET)."""

from __future__ import annotations

import math

import cv2
import numpy as np

from handeye_drake.calibration.inputs import Streams
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp
from handeye_drake.recorded.formats import pose_stream
from handeye_drake.vision.camera_model import CameraIntrinsics
from handeye_drake.vision.detection import TargetDetection, _pose

WIDTH, HEIGHT = 640, 480
#: fx fy cx cy k1 k2 p1 p2 k3 of the true camera (a wide lens with visible barrel distortion).
TRUTH = np.array([600.0, 601.0, 322.0, 238.0, -0.22, 0.09, 0.0008, -0.0006, 0.0])
X_EC = make_transform(rotation_exp([0.04, -0.05, 1.57]), [0.035, -0.05, 0.07])
X_BT = make_transform(rotation_exp([math.pi, 0.0, 0.3]), [0.55, -0.12, 0.0])
X_BC = make_transform(rotation_exp([2.2, 0.3, 0.1]), [0.9, 0.4, 0.8])
X_ET = make_transform(rotation_exp([0.1, 0.05, -0.2]), [0.02, -0.03, 0.09])
GRID = np.array([[0.03 * i, 0.03 * j, 0.0] for j in range(6) for i in range(8)])


def _project(P_C, v):
    K = np.array([[v[0], 0, v[2]], [0, v[1], v[3]], [0, 0, 1.0]])
    uv, _ = cv2.projectPoints(P_C.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K,
                              np.asarray(v[4:9], float))
    return uv.reshape(-1, 2)


def intrinsics_of(v) -> CameraIntrinsics:
    K = np.array([[v[0], 0, v[2]], [0, v[1], v[3]], [0, 0, 1.0]])
    return CameraIntrinsics.from_matrix(K, WIDTH, HEIGHT, tuple(float(x) for x in v[4:9]))


def corner_streams(given, mode: str = "eye_in_hand", n: int = 12, seed: int = 0,
                   pixel_sigma: float = 0.15, robot_error=(0.02, 0.2), truth=TRUTH,
                   shift_pairs: int = 0, robot_scale: float = 1.0):
    """(Streams as ``image_streams`` makes them, truth dict).

    ``given``: the intrinsics vector [fx fy cx cy k1 k2 p1 p2 k3] the user gives (detection and
    the fit use it). ``robot_error``: (deg, mm) per-axis σ of a pose error that repeats with the
    pose (a function of the pose's index). ``shift_pairs``: the images paired with the robot
    poses shifted by this many. ``robot_scale``: factor on the robot file's translations."""
    rng = np.random.default_rng(seed)
    X_BE, dets = [], []
    centre = GRID.mean(axis=0)
    while len(X_BE) < n + abs(shift_pairs):
        R_CT = rotation_exp(rng.normal(size=3) * [0.35, 0.35, 0.6])
        p = np.array([rng.uniform(-0.07, 0.07), rng.uniform(-0.05, 0.05), rng.uniform(0.3, 0.5)])
        X_CT = make_transform(R_CT, p - R_CT @ centre)
        P_C = GRID @ X_CT[:3, :3].T + X_CT[:3, 3]
        if (R_CT @ [0, 0, 1])[2] < 0.5:
            continue
        uv = _project(P_C, truth)
        if np.any(uv < 10) or np.any(uv[:, 0] > WIDTH - 11) or np.any(uv[:, 1] > HEIGHT - 11):
            continue
        if mode == "eye_in_hand":
            X = X_BT @ inverse(X_CT) @ inverse(X_EC)          # X_BE
        else:
            X = X_BC @ X_CT @ inverse(X_ET)                   # X_BE
        X_BE.append(X)
        dets.append(uv + pixel_sigma * rng.normal(size=uv.shape))
    X_BE = np.array(X_BE)
    # The robot's reported pose: its error repeats with the pose (a smooth function of it).
    reported = []
    for X in X_BE:
        a = np.sin(X[:3, 3] * 17.0 + np.arange(3))
        err = make_transform(rotation_exp(np.radians(robot_error[0]) * a),
                             1e-3 * robot_error[1] * np.cos(X[:3, 3] * 13.0 + np.arange(3)))
        reported.append(X @ err)
    reported = np.array(reported)
    if shift_pairs:
        reported = reported[shift_pairs:] if shift_pairs > 0 else reported[:shift_pairs]
        dets = dets[:len(reported)] if shift_pairs > 0 else dets[-shift_pairs:]
    reported = reported[:n]
    dets = dets[:n]
    reported[:, :3, 3] *= robot_scale
    given = np.asarray(given, float)
    K = np.array([[given[0], 0, given[2]], [0, given[1], given[3]], [0, 0, 1.0]])
    detections, poses = [], []
    for uv in dets:
        ok, rvec, tvec = cv2.solvePnP(GRID.astype(np.float64), uv.astype(np.float64), K,
                                      given[4:9], flags=cv2.SOLVEPNP_ITERATIVE)
        X = _pose(rvec, tvec)
        proj = _project(GRID @ X[:3, :3].T + X[:3, 3], given)
        rms = float(np.sqrt(np.mean(np.sum((proj - uv) ** 2, axis=1))))
        detections.append(TargetDetection(True, "", np.arange(len(GRID)), uv, GRID.copy(), X,
                                           rms, None, pixel_sigma))
        poses.append(X)
    robot = pose_stream(reported, None, "robot_poses.tum")
    camera = pose_stream(np.array(poses), None, f"images ({n})")
    inputs = {"images": {"count": n, "detected": n, "target": "grid 8x6 0.03",
                         "intrinsics": "given", "intrinsics_note": ""},
              "robot": {"path": None, "format": "tum", "translation_scale": 1.0}}
    # Which stream is the camera's is known (as for image files: roles_known).
    streams = Streams(robot, camera, inputs, (), [], intrinsics_of(given), None, detections,
                      "given", roles_known=True)
    hand = X_EC if mode == "eye_in_hand" else X_BC
    return streams, {"X_hand": hand, "intrinsics": truth}

"""Corner sets of cells as unkind as real ones, without a renderer (for the leave-one-out
benchmark and the σ-honesty tests): a UR5e whose kinematics are off (perturbed DH: link lengths,
offsets and joint zeros), so that its pose errors repeat with the joint angles, or a robot with
independent per-image pose errors; strong lens distortion; few images; little rotation.

The UR5e table is Universal Robots' published DH table (the one ``models/ur5e.urdf`` is built
from). A "measured" X_BE is the nominal kinematics at the joint angles; the true flange pose the
perturbed kinematics at the same angles. Corners are projected with ``cv2.projectPoints`` (the
OpenCV model the fit uses) plus Gaussian pixel noise, and each image's X_CT is solvePnP's.

Eye-in-hand: the board lies in the cell (X_BT), the camera rides on the flange (X_EC).
Eye-to-hand: the camera is fixed in the cell (X_BC), the board rides on the flange (X_ET).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import least_squares

from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp

#: UR5e standard DH: a (m), d (m), α (rad) per joint.
UR5E_A = np.array([0.0, -0.425, -0.3922, 0.0, 0.0, 0.0])
UR5E_D = np.array([0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996])
UR5E_ALPHA = np.array([math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0])


@dataclass
class DH:
    """A DH table (a, d, α per joint) with joint zero offsets θ₀ (rad)."""
    a: np.ndarray = field(default_factory=lambda: UR5E_A.copy())
    d: np.ndarray = field(default_factory=lambda: UR5E_D.copy())
    alpha: np.ndarray = field(default_factory=lambda: UR5E_ALPHA.copy())
    theta0: np.ndarray = field(default_factory=lambda: np.zeros(6))

    def fk(self, q) -> np.ndarray:
        """X_BE (4×4) at joint angles q (6,)."""
        X = np.eye(4)
        for a, d, al, th in zip(self.a, self.d, self.alpha, np.asarray(q) + self.theta0):
            ct, st, ca, sa = math.cos(th), math.sin(th), math.cos(al), math.sin(al)
            X = X @ np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                              [0.0, sa, ca, d], [0.0, 0.0, 0.0, 1.0]])
        return X

    def perturbed(self, rng, length_m=2e-3, angle_deg=0.15) -> "DH":
        """The same table with each a, d off by N(0, length_m) and each α, θ₀ by
        N(0, angle_deg): a real arm's kinematic error (a few mm at the flange)."""
        s = math.radians(angle_deg)
        return DH(self.a + rng.normal(size=6) * length_m, self.d + rng.normal(size=6) * length_m,
                  self.alpha + rng.normal(size=6) * s, self.theta0 + rng.normal(size=6) * s)


NOMINAL = DH()


def _pose_error(X, Y) -> np.ndarray:
    R = X[:3, :3].T @ Y[:3, :3]
    return np.concatenate([cv2.Rodrigues(R)[0].ravel(), X[:3, 3] - Y[:3, 3]])


def inverse_kinematics(X_BE, q0, dh: DH = NOMINAL) -> np.ndarray | None:
    """Joint angles whose ``dh`` flange pose is X_BE (least squares from q0), or None."""
    sol = least_squares(lambda q: _pose_error(dh.fk(q), X_BE), q0, xtol=1e-12, ftol=1e-12)
    return sol.x if np.linalg.norm(_pose_error(dh.fk(sol.x), X_BE)) < 1e-7 else None


#: A joint configuration of the UR5e reaching over the cell with the flange pointing down.
Q_HOME = np.array([0.0, -1.9, 1.9, -1.57, -1.57, 0.0])


@dataclass
class CornerSet:
    """Measured robot poses X_BE (K, 4, 4), per-image corners (object (n, 3) m in T, image
    (n, 2) px), each image's PnP X_CT, the intrinsics vector the corners were made with, the
    truth (X_hand, X_fixed) and the true flange poses."""
    mode: str
    X_BE: np.ndarray
    object_points: list
    image_points: list
    X_CT: np.ndarray
    intrinsics: np.ndarray
    X_hand: np.ndarray
    X_fixed: np.ndarray
    X_BE_true: np.ndarray
    width: int = 640
    height: int = 480


def board(cols=9, rows=7, square=0.025) -> np.ndarray:
    gx, gy = np.meshgrid(np.arange(cols) * square, np.arange(rows) * square)
    return np.stack([gx.ravel(), gy.ravel(), 0 * gx.ravel()], 1)


#: Truth shared by the sets.
X_EC = make_transform(rotation_exp([0.03, -0.04, 1.55]), [0.045, -0.06, 0.07])
X_BT = make_transform(rotation_exp([math.pi, 0.0, 0.25]), [0.45, -0.10, 0.0])
X_BC = make_transform(rotation_exp([math.pi, 0.0, 0.0]) @ rotation_exp([0.15, -0.1, 0.4]),
                      [0.45, 0.05, 0.95])
X_ET = make_transform(rotation_exp([0.05, 0.03, -0.15]), [0.02, -0.03, 0.09])


def corner_set(rng, mode="eye_in_hand", n=16, robot="dh", distortion=(-0.3, 0.12, 0, 0, 0),
               tilt=0.35, pixel_noise=0.15, dh_error=(2e-3, 0.15), pose_error=(0.2, 1.5e-3),
               grid=(9, 7), square=0.025, width=640, height=480, f=600.0,
               X_fixed=None, X_hand=None, distance=(0.3, 0.5), lens_extra=(0.0, 0.0),
               partial=0.0, true_dh: DH | None = None) -> CornerSet:
    """A set of ``n`` images.

    Args:
        robot: "dh" (a perturbed UR5e: ``dh_error`` (m, deg) per DH parameter) or "independent"
            (each image's flange pose off by N(0, ``pose_error`` (deg, m)) per axis).
        distortion: k1 k2 p1 p2 k3 of the lens; tilt: spread (rad) of the board's orientation
            in the camera (little rotation: small); distance: range (m) of the board's centre
            in front of the camera.
        lens_extra: (k3, s1) of the true lens beyond the model given (a lens the 5-coefficient
            model only approximates: k3 added, and a thin-prism term s1).
        partial: fraction of the images that see only part of the board (a random half-plane
            of its corners cut off).
        true_dh: the arm's true kinematics (default: drawn from ``rng`` by ``dh_error``): the
            same arm over several sessions.
    """
    v = np.array([f, f * 1.001, width / 2 + 3.0, height / 2 - 2.0, *distortion], float)
    K = np.array([[v[0], 0, v[2]], [0, v[1], v[3]], [0, 0, 1.0]])
    dist = v[4:]
    P = board(*grid, square)
    centre = P.mean(axis=0)
    if robot == "dh" and true_dh is None:
        true_dh = NOMINAL.perturbed(rng, *dh_error)
    X_hand = X_hand if X_hand is not None else (X_EC if mode == "eye_in_hand" else X_BC)
    X_fixed = X_fixed if X_fixed is not None else (X_BT if mode == "eye_in_hand" else X_ET)
    out = {k: [] for k in ("X_BE", "obj", "img", "X_CT", "true")}
    q_prev = Q_HOME.copy()
    tries = 0
    while len(out["X_BE"]) < n:
        tries += 1
        if tries > 200 * n:
            raise RuntimeError("corner_set: could not place the images")
        # The board's centre 0.3–0.5 m in front of the camera, turned by up to ~tilt.
        R_CT = rotation_exp(rng.normal(size=3) * [tilt, tilt, 2 * tilt])
        p = np.array([rng.uniform(-0.04, 0.04), rng.uniform(-0.03, 0.03), rng.uniform(*distance)])
        X_CT_des = make_transform(R_CT, p - R_CT @ centre)
        if mode == "eye_in_hand":
            X_BE = X_fixed @ inverse(X_CT_des) @ inverse(X_hand)
        else:
            X_BE = X_hand @ X_CT_des @ inverse(X_fixed)
        for start in (q_prev, Q_HOME, *(Q_HOME + [0, 0, 0, 0, 0, a] for a in (1.6, -1.6, 3.1))):
            q = inverse_kinematics(X_BE, start)
            if q is not None:
                break
        if q is None:
            continue
        if robot == "dh":
            X_true = true_dh.fk(q)
        else:
            s = np.array([math.radians(pose_error[0])] * 3 + [pose_error[1]] * 3)
            e = rng.normal(size=6) * s
            X_true = X_BE @ make_transform(rotation_exp(e[:3]), e[3:])
        X_CT = inverse(X_true @ X_hand) @ X_fixed if mode == "eye_in_hand" else \
            inverse(X_hand) @ X_true @ X_fixed
        pc = P @ X_CT[:3, :3].T + X_CT[:3, 3]
        if np.any(pc[:, 2] < 0.15) or (X_CT[:3, :3] @ [0, 0, 1])[2] < 0.3:
            continue
        true_dist = np.r_[dist[:4], dist[4] + lens_extra[0], 0, 0, 0, lens_extra[1], 0, 0, 0]
        uv = cv2.projectPoints(P, cv2.Rodrigues(X_CT[:3, :3])[0], X_CT[:3, 3], K,
                               true_dist)[0].reshape(-1, 2)
        if np.any(uv < 10) or np.any(uv[:, 0] > width - 10) or np.any(uv[:, 1] > height - 10):
            continue
        uv = uv + rng.normal(size=uv.shape) * pixel_noise
        Pk = P
        if rng.uniform() < partial:
            # Half out of view: the corners on one side of a random line through the board kept.
            nrm = rotation_exp([0, 0, rng.uniform(0, 2 * math.pi)])[:2, 0]
            keep = (P[:, :2] - centre[:2]) @ nrm > rng.uniform(-0.3, 0.1) * np.ptp(P[:, 0])
            if keep.sum() < 12:
                continue
            Pk, uv = P[keep], uv[keep]
        ok, rvec, tvec = cv2.solvePnP(Pk, uv, K, dist)
        X_pnp = make_transform(cv2.Rodrigues(rvec)[0], tvec.ravel())
        q_prev = q
        out["X_BE"].append(X_BE)
        out["obj"].append(Pk.copy())
        out["img"].append(uv)
        out["X_CT"].append(X_pnp)
        out["true"].append(X_true)
    return CornerSet(mode, np.array(out["X_BE"]), out["obj"], out["img"], np.array(out["X_CT"]),
                     v, X_hand, X_fixed, np.array(out["true"]), width, height)


def streams_of(cs: CornerSet, images=None, intrinsics=None):
    """``calibration.inputs.Streams`` of the set (or of the images listed), as the image reader
    makes them: robot poses, PnP camera poses, one detection per image, the given intrinsics
    (default: the true ones)."""
    from handeye_drake.calibration.inputs import Streams
    from handeye_drake.recorded.formats import pose_stream
    from handeye_drake.vision.camera_model import CameraIntrinsics
    from handeye_drake.vision.detection import TargetDetection
    idx = np.arange(len(cs.X_BE)) if images is None else np.asarray(images, int)
    v = cs.intrinsics if intrinsics is None else np.asarray(intrinsics, float)
    K = np.array([[v[0], 0, v[2]], [0, v[1], v[3]], [0, 0, 1.0]])
    cam = CameraIntrinsics.from_matrix(K, cs.width, cs.height, tuple(v[4:]))
    dets = []
    for k in idx:
        P, uv = cs.object_points[k], cs.image_points[k]
        ok, rvec, tvec = cv2.solvePnP(P, uv, K, v[4:])
        X = make_transform(cv2.Rodrigues(rvec)[0], tvec.ravel())
        proj = cv2.projectPoints(P, rvec, tvec, K, v[4:])[0].reshape(-1, 2)
        rms = float(np.sqrt(np.mean(np.sum((proj - uv) ** 2, axis=1))))
        dets.append(TargetDetection(True, "", np.arange(len(P)), uv.copy(), P.copy(), X, rms,
                                    None, rms / math.sqrt(2)))
    robot = pose_stream(cs.X_BE[idx], None, "robot")
    camera = pose_stream(np.array([d.X_CT for d in dets]), None, "camera")
    return Streams(robot, camera, {"synthetic": {"images": len(idx)}}, (), [], cam, None, dets,
                   "given", roles_known=True)

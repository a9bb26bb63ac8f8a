"""Is a hand-eye result consistent with its data? Pose residuals, the fixed pose every sample
implies, noise estimates, and the usual mistakes tried as alternatives (pure numpy).

Both set-ups reduce to one model, AX = ZB on synchronized poses:

- eye-in-hand (camera on the flange, target fixed in the cell): X_CT = X_CE · X_EB · X_BT, the
  unknowns are X_EC (camera on the hand) and X_BT (target in the robot base);
- eye-to-hand (camera fixed in the cell, target on the flange): X_CT = X_CB · X_BE · X_ET, the
  unknowns are X_BC (camera in the base) and X_ET (target on the flange). It is the eye-in-hand
  model with the robot pose inverted ("robot side" X_EB instead of X_BE): the same code solves
  both, returning X_BC where eye-in-hand returns X_EC.

So below, ``X_R`` is the robot-side pose of each sample (X_BE, or X_EB for eye-to-hand), ``X_H``
the hand-eye unknown (X_EC, or X_BC) and ``X_F`` the fixed pose (X_BT, or X_ET):
X_CT = X_H⁻¹ · X_R⁻¹ · X_F.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from .se3 import inverse

MODES = ("eye_in_hand", "eye_to_hand")

#: Median of the χ distribution with 3 degrees of freedom: the median norm of a 3-vector of
#: independent N(0, σ²) components is this × σ.
CHI3_MEDIAN = 1.5382


def check_mode(mode) -> str:
    if mode not in MODES:
        raise ValueError(f"mode: expected one of {MODES}, got {mode!r}")
    return mode


def robot_side(X_BE: np.ndarray, mode: str) -> np.ndarray:
    """The robot-side poses X_R of the common model: X_BE (eye-in-hand) or X_EB (eye-to-hand)."""
    X_BE = np.asarray(X_BE, dtype=float)
    if check_mode(mode) == "eye_in_hand":
        return X_BE
    return inverse_stack(X_BE)


def inverse_stack(X: np.ndarray) -> np.ndarray:
    """Inverses of a (N, 4, 4) stack of rigid transforms."""
    R = np.transpose(X[:, :3, :3], (0, 2, 1))
    out = np.zeros_like(X)
    out[:, :3, :3] = R
    out[:, :3, 3] = -np.einsum("nij,nj->ni", R, X[:, :3, 3])
    out[:, 3, 3] = 1.0
    return out


def implied_fixed_poses(X_R: np.ndarray, X_CT: np.ndarray, X_H: np.ndarray) -> np.ndarray:
    """The fixed pose each sample implies, X_F[k] = X_R[k] · X_H · X_CT[k] (the target in the base
    for eye-in-hand, in the flange for eye-to-hand). With the right X_H they all coincide up to
    the measurement noise: their spread is the consistency check users know from ViSP."""
    return X_R @ np.asarray(X_H, dtype=float)[None] @ X_CT


def mean_pose(X: np.ndarray) -> np.ndarray:
    """Chordal mean of a stack of poses: the rotation nearest the mean rotation matrix, the mean
    translation."""
    M = X[:, :3, :3].mean(axis=0)
    U, _, Vt = np.linalg.svd(M)
    R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0]) @ Vt
    out = np.eye(4)
    out[:3, :3] = R
    out[:3, 3] = X[:, :3, 3].mean(axis=0)
    return out


def pose_residuals(X_R, X_CT, X_H, X_F) -> tuple[np.ndarray, np.ndarray]:
    """Per sample: the angle (deg) and the distance (m) between the measured X_CT and the one
    the model predicts, X_H⁻¹ X_R⁻¹ X_F."""
    X_R = np.asarray(X_R, dtype=float)
    X_CT = np.asarray(X_CT, dtype=float)
    predicted = inverse(np.asarray(X_H, dtype=float))[None] @ inverse_stack(X_R) @ \
        np.asarray(X_F, dtype=float)[None]
    R_err = np.transpose(predicted[:, :3, :3], (0, 2, 1)) @ X_CT[:, :3, :3]
    angle = np.degrees(np.linalg.norm(Rotation.from_matrix(R_err).as_rotvec(), axis=1))
    return angle, np.linalg.norm(X_CT[:, :3, 3] - predicted[:, :3, 3], axis=1)


def noise_from_residuals(angle_deg: np.ndarray, distance: np.ndarray) -> tuple[float, float]:
    """Per-axis noise (rad, m) that explains pose residuals, robustly: the median residual norm of
    an isotropic 3-D Gaussian is ``CHI3_MEDIAN`` σ. (The fit absorbs a little of the noise; with
    tens of samples or more that bias is a few percent.)"""
    return (float(np.radians(np.median(angle_deg)) / CHI3_MEDIAN),
            float(np.median(distance) / CHI3_MEDIAN))


@dataclass(frozen=True)
class Spread:
    """How much the per-sample fixed poses disagree: RMS angle (deg) and RMS distance (m) to their
    mean, and the largest of each."""
    rotation_rms_deg: float
    translation_rms: float
    rotation_max_deg: float
    translation_max: float


def fixed_pose_spread(X_F_samples: np.ndarray) -> Spread:
    mean = mean_pose(X_F_samples)
    R_err = np.transpose(mean[:3, :3])[None] @ X_F_samples[:, :3, :3]
    angle = np.degrees(np.linalg.norm(Rotation.from_matrix(R_err).as_rotvec(), axis=1))
    d = np.linalg.norm(X_F_samples[:, :3, 3] - mean[:3, 3], axis=1)
    return Spread(float(np.sqrt(np.mean(angle**2))), float(np.sqrt(np.mean(d**2))),
                  float(angle.max()), float(d.max()))


def rotation_from_swapped_quaternions(R: np.ndarray) -> np.ndarray:
    """The rotations a file's quaternions give when read in the other order: the file holds
    (w, x, y, z) but was read as (x, y, z, w) — the rotations ``R`` (N, 3, 3) were built from the
    numbers in the wrong order; this rebuilds them from the same numbers in the right one."""
    q_read = Rotation.from_matrix(R).as_quat()  # the file's 4 numbers, up to a common sign
    return Rotation.from_quat(np.roll(q_read, -1, axis=1)).as_matrix()


def with_rotations(X: np.ndarray, R: np.ndarray) -> np.ndarray:
    out = np.array(X, dtype=float, copy=True)
    out[:, :3, :3] = R
    return out


def with_scaled_translations(X: np.ndarray, scale: float) -> np.ndarray:
    out = np.array(X, dtype=float, copy=True)
    out[:, :3, 3] *= scale
    return out

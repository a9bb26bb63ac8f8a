"""Synthetic hand-eye data: the paper's simulated motions and pose datasets, in one place.

The paper's setting (docs/method.md §8), in its "length units": the true X = X_CE has
roll-pitch-yaw angles uniform in [0, 2π) and translation coordinates N(0, 100²); robot motions
B = X_{E(k−1)E(k)} have roll-pitch-yaw ~ N(0, (2π/100)²) and translation ~ N(0, 1); the camera
measures the motion A = X B X⁻¹ with additive noise on the coefficients of R_A and on t_A.
Rotations from roll-pitch-yaw use Drake's RollPitchYaw convention (extrinsic X-Y-Z).

Pose datasets (metres): robot poses X_BE and measured target poses X_CT of a fixed target X_BT,
for the pose-based estimators and the batch calibration.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from .se3 import inverse, make_transform, rotation_exp, rotation_from_rpy

#: Std of each roll-pitch-yaw angle of a random robot motion (rad).
MOTION_RPY_SIGMA = 2.0 * np.pi / 100.0
#: Std of each translation coordinate of a random robot motion (length units).
MOTION_TRANSLATION_SIGMA = 1.0
#: Std of each translation coordinate of the random hand-eye X (length units).
X_TRANSLATION_SIGMA = 100.0
#: Angle of the paper's two predefined self-calibration rotations (about E's x, then y axis).
SELF_CALIBRATION_ANGLE = np.radians(30.0)


def transforms(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(..., 4, 4) homogeneous transforms from (..., 3, 3) rotations and (..., 3) translations."""
    X = np.zeros(R.shape[:-2] + (4, 4))
    X[..., :3, :3] = R
    X[..., :3, 3] = t
    X[..., 3, 3] = 1.0
    return X


def random_hand_eye(rng: np.random.Generator) -> np.ndarray:
    """X = X_CE: roll-pitch-yaw uniform in [0, 2π), translation coordinates N(0, 100²)."""
    R = rotation_from_rpy(rng.uniform(0.0, 2.0 * np.pi, 3))
    return make_transform(R, rng.normal(0.0, X_TRANSLATION_SIGMA, 3))


def random_robot_motions(rng: np.random.Generator, K: int) -> np.ndarray:
    """K robot motions B (K, 4, 4): rpy ~ N(0, (2π/100)²), translation ~ N(0, 1) (all K
    rotations are drawn first, then all K translations)."""
    R = Rotation.from_euler("xyz", rng.normal(0.0, MOTION_RPY_SIGMA, (K, 3))).as_matrix()
    return transforms(R.reshape(K, 3, 3), rng.normal(0.0, MOTION_TRANSLATION_SIGMA, (K, 3)))


def self_calibration_motions(angle: float = SELF_CALIBRATION_ANGLE) -> np.ndarray:
    """The two predefined robot motions (2, 4, 4): ``angle`` about E's x axis, then y axis."""
    R = Rotation.from_rotvec([[angle, 0.0, 0.0], [0.0, angle, 0.0]]).as_matrix()
    return transforms(R, np.zeros((2, 3)))


def camera_motions(X_CE: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Exact camera motions A = X B X⁻¹ (so that A X = X B) for a stack B (..., 4, 4)."""
    return X_CE @ B @ np.linalg.inv(X_CE)


def add_coefficient_noise(A: np.ndarray, unit_rotation: np.ndarray, unit_translation: np.ndarray,
                          rotation_sigma: float, translation_sigma: float) -> np.ndarray:
    """The paper's measurement: R_A + σ_r Δ (every coefficient, not re-orthonormalized) and
    t_A + σ_t v, from unit-variance draws Δ (..., 3, 3) and v (..., 3)."""
    A = A.copy()
    A[..., :3, :3] += rotation_sigma * unit_rotation
    A[..., :3, 3] += translation_sigma * unit_translation
    return A


def paper_motions(rng: np.random.Generator, rotation_sigma: float, translation_sigma: float,
                  num_motions: int):
    """One run of the paper's setting: (X_CE, A_list (raw measured motions, rotation blocks not
    orthonormal), B_list)."""
    X_CE = random_hand_eye(rng)
    B = random_robot_motions(rng, num_motions)
    noise = rng.normal(size=(num_motions, 12))
    A = add_coefficient_noise(camera_motions(X_CE, B), noise[:, :9].reshape(-1, 3, 3),
                              noise[:, 9:], rotation_sigma, translation_sigma)
    return X_CE, list(A), list(B)


def chain_poses(A_list, B_list):
    """Pose sequences reproducing the motions: X_BE_k = X_BE_{k−1} B_k, X_CT_k = A_k⁻¹ X_CT_{k−1}
    (X_BE_0 = X_CT_0 = I; A rigid), so that X_CT_{k−1} X_CT_k⁻¹ = A_k and X_BE_{k−1}⁻¹ X_BE_k =
    B_k."""
    X_BE, X_CT = [np.eye(4)], [np.eye(4)]
    for A, B in zip(A_list, B_list):
        X_BE.append(X_BE[-1] @ B)
        X_CT.append(inverse(A) @ X_CT[-1])
    return X_BE, X_CT


def inject_wrong_poses(X_CT_list, fraction: float, rng: np.random.Generator):
    """Replaces round(fraction·K) poses (never the first) by wrong ones: a uniformly random
    rotation at the position of another, randomly chosen sample. Returns (poses, indices)."""
    K = len(X_CT_list)
    n = int(round(fraction * K))
    idx = np.sort(rng.choice(np.arange(1, K), size=n, replace=False))
    out = [X.copy() for X in X_CT_list]
    for i in idx:
        j = int(rng.integers(K))
        out[i] = make_transform(Rotation.random(random_state=rng).as_matrix(), X_CT_list[j][:3, 3])
    return out, idx


def orbit_poses(rng: np.random.Generator, num_poses: int, rotation_std: float,
                rotation_sigma: float, translation_sigma: float, distance: float = 0.5):
    """(X_EC, X_BE list, measured X_CT list): a camera with a random hand-eye transform
    (±5 cm) orbiting a target at ``distance`` m, each view rotated by a rotation vector
    ~ N(0, rotation_std² I) rad, the measured pose perturbed with so3 noise (rotation_sigma rad,
    translation_sigma m)."""
    X_EC = make_transform(Rotation.random(random_state=rng).as_matrix(),
                          rng.normal(0.0, 0.05, 3))
    X_BT = make_transform(Rotation.random(random_state=rng).as_matrix(),
                          np.array([0.6, 0.0, 0.0]) + rng.normal(0.0, 0.05, 3))
    X_TC0 = make_transform(rotation_from_rpy([np.pi, 0.0, 0.0]), [0.0, 0.0, distance])
    X_CE = inverse(X_EC)
    X_BE, X_CT = [], []
    for _ in range(num_poses):
        X_TC = make_transform(rotation_exp(rng.normal(0.0, rotation_std, 3)),
                              rng.normal(0.0, 0.02, 3)) @ X_TC0
        X_BE.append(X_BT @ X_TC @ X_CE)
        Y = inverse(X_TC)
        Y[:3, :3] = rotation_exp(rotation_sigma * rng.normal(size=3)) @ Y[:3, :3]
        Y[:3, 3] += translation_sigma * rng.normal(size=3)
        X_CT.append(Y)
    return X_EC, X_BE, X_CT


def random_pose(rng: np.random.Generator, rotation_scale: float = np.pi,
                translation_scale: float = 1.0) -> np.ndarray:
    """A pose with rotation vector ~ N(0, (rotation_scale/2)² I) and translation
    ~ N(0, translation_scale² I)."""
    return make_transform(rotation_exp(rng.normal(size=3) * rotation_scale / 2),
                          rng.normal(size=3) * translation_scale)


def pose_dataset(rng: np.random.Generator, X_EC, n: int, rotation_scale: float = 0.5,
                 translation_scale: float = 0.3):
    """Robot poses X_BE and exact target-in-camera poses X_CT = (X_BE X_EC)⁻¹ X_BT of a fixed
    random target X_BT, for n random robot poses. Returns (X_BE list, X_CT list)."""
    X_BT = make_transform(rotation_exp(rng.normal(size=3)), [0.8, 0.1, 0.2])
    X_BE = [random_pose(rng, rotation_scale, translation_scale) for _ in range(n)]
    X_CT = [inverse(X @ X_EC) @ X_BT for X in X_BE]
    return X_BE, X_CT

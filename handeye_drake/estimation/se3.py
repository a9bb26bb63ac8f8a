"""Small rigid-body helpers on 4×4 numpy arrays (no Drake needed).

Conventions: a pose ``X_AB`` is the 4×4 homogeneous transform of frame B measured in frame A,
so ``p_AQ = X_AB @ p_BQ`` and ``X_AC = X_AB @ X_BC``. Quaternions are [w, x, y, z]. Rotation
vectors are axis·angle with angle in [0, π]. Twists are ordered like Drake's SpatialVelocity:
[ω; v] (angular first).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def skew(w) -> np.ndarray:
    """[w]_× such that skew(w) @ u = w × u."""
    w = np.asarray(w, dtype=float)
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def make_transform(R, p) -> np.ndarray:
    X = np.eye(4)
    X[:3, :3] = R
    X[:3, 3] = p
    return X


def inverse(X) -> np.ndarray:
    """Inverse of a rigid transform (uses Rᵀ, so only for rigid X)."""
    X = np.asarray(X, dtype=float)
    R, p = X[:3, :3], X[:3, 3]
    return make_transform(R.T, -R.T @ p)


def rotation_exp(rotvec) -> np.ndarray:
    return Rotation.from_rotvec(np.asarray(rotvec, dtype=float)).as_matrix()


def rotation_log(R) -> np.ndarray:
    """Rotation vector of a rotation matrix (angle in [0, π])."""
    return Rotation.from_matrix(np.asarray(R, dtype=float)).as_rotvec()


def rotation_angle(R) -> float:
    """Angle of a rotation in radians, robust near 0 and π."""
    return float(np.linalg.norm(rotation_log(R)))


def quat_wxyz(R) -> np.ndarray:
    """Unit quaternion [w, x, y, z] of a rotation matrix, with w ≥ 0."""
    x, y, z, w = Rotation.from_matrix(np.asarray(R, dtype=float)).as_quat()
    q = np.array([w, x, y, z])
    return -q if q[0] < 0 else q


def rotation_from_quat_wxyz(q) -> np.ndarray:
    w, x, y, z = np.asarray(q, dtype=float)
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def rpy(R) -> np.ndarray:
    """Roll-pitch-yaw (extrinsic X-Y-Z, Drake's RollPitchYaw convention) in radians."""
    return Rotation.from_matrix(np.asarray(R, dtype=float)).as_euler("xyz")


def rotation_from_rpy(rpy_angles) -> np.ndarray:
    return Rotation.from_euler("xyz", np.asarray(rpy_angles, dtype=float)).as_matrix()


def twist_transform(X_AB) -> np.ndarray:
    """6×6 matrix mapping a twist of a body expressed at B's origin in frame B, [ω_B; v_B],
    to the same rigid motion expressed at A's origin in frame A, [ω_A; v_A] (X_AB rigid).

    ω_A = R ω_B,  v_A = R v_B + p × (R ω_B),  with R, p = X_AB's rotation and translation.
    """
    X_AB = np.asarray(X_AB, dtype=float)
    R, p = X_AB[:3, :3], X_AB[:3, 3]
    T = np.zeros((6, 6))
    T[:3, :3] = R
    T[3:, 3:] = R
    T[3:, :3] = skew(p) @ R
    return T


def pose_to_vector(X) -> np.ndarray:
    """12-vector [vec_row(R); p] used on Drake ports that carry (possibly non-rigid,
    measured) poses."""
    X = np.asarray(X, dtype=float)
    return np.concatenate([X[:3, :3].reshape(9), X[:3, 3]])


def vector_to_pose(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return make_transform(v[:9].reshape(3, 3), v[9:12])


def retract_pose(X, delta) -> np.ndarray:
    """X ⊕ δ with δ = [δθ; δt]: R ← exp([δθ]×) R, t ← t + δt (the filters' error state)."""
    return make_transform(rotation_exp(delta[:3]) @ X[:3, :3], X[:3, 3] + delta[3:6])


def inverse_tangent_jacobian(X_CE) -> np.ndarray:
    """6×6 J with δ_EC ≈ J δ_CE for X_EC = inv(X_CE), both perturbations of the form
    R = exp(δθ) R̂, t = t̂ + δt: δθ_EC = −Rᵀ δθ, δt_EC = −Rᵀ [t]× δθ − Rᵀ δt."""
    R, t = X_CE[:3, :3], X_CE[:3, 3]
    J = np.zeros((6, 6))
    J[:3, :3] = -R.T
    J[3:, :3] = -R.T @ skew(t)
    J[3:, 3:] = -R.T
    return J

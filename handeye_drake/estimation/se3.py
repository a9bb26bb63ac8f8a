"""Small rigid-body helpers on 4×4 numpy arrays (no Drake needed).

Conventions: a pose ``X_AB`` is the 4×4 homogeneous transform of frame B measured in frame A,
so ``p_AQ = X_AB @ p_BQ`` and ``X_AC = X_AB @ X_BC``. Quaternions are [w, x, y, z]. Rotation
vectors are axis·angle with angle in [0, π]. Twists are ordered like Drake's SpatialVelocity:
[ω; v] (angular first).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation


def skew(w) -> np.ndarray:
    """[w]_× such that skew(w) @ u = w × u."""
    w = np.asarray(w, dtype=float)
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


_BOTTOM_ROW = np.array([0.0, 0.0, 0.0, 1.0])


def make_transform(R, p) -> np.ndarray:
    X = np.empty((4, 4))  # (every entry is written: cheaper than np.eye, called per sample)
    X[:3, :3] = R
    X[:3, 3] = p
    X[3] = _BOTTOM_ROW
    return X


def inverse(X) -> np.ndarray:
    """Inverse of a rigid transform (uses Rᵀ, so only for rigid X)."""
    X = np.asarray(X, dtype=float)
    R, p = X[:3, :3], X[:3, 3]
    return make_transform(R.T, -R.T @ p)


def _quat_xyzw_from_rotvec(wx: float, wy: float, wz: float) -> tuple:
    angle = math.sqrt(wx * wx + wy * wy + wz * wz)
    if angle <= 1e-3:  # Taylor series of sin(θ/2)/θ: no cancellation as θ → 0
        angle2 = angle * angle
        scale = 0.5 - angle2 / 48 + angle2 * angle2 / 3840
    else:
        scale = math.sin(angle / 2) / angle
    return scale * wx, scale * wy, scale * wz, math.cos(angle / 2)


def _matrix_from_quat_xyzw(x: float, y: float, z: float, w: float) -> list:
    x2, y2, z2, w2 = x * x, y * y, z * z, w * w
    xy, zw, xz, yw, yz, xw = x * y, z * w, x * z, y * w, y * z, x * w
    return [[x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw)],
            [2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw)],
            [2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2]]


def _quat_xyzw_from_rotation(m: list) -> tuple:
    """Unit quaternion of an orthonormal 3×3 (nested list) by Shepperd's method: the largest of
    the four candidate components is computed from the diagonal, so no branch divides by a small
    number, at θ → π included."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = m
    trace = m00 + m11 + m22
    decision = (m00, m11, m22, trace)
    choice, vmax = 0, decision[0]
    for k in (1, 2, 3):  # the first maximum wins, as in scipy
        if decision[k] > vmax:
            choice, vmax = k, decision[k]
    if choice == 0:
        q = [1 - trace + 2 * m00, m10 + m01, m20 + m02, m21 - m12]
    elif choice == 1:
        q = [m01 + m10, 1 - trace + 2 * m11, m21 + m12, m02 - m20]
    elif choice == 2:
        q = [m02 + m20, m12 + m21, 1 - trace + 2 * m22, m10 - m01]
    else:
        q = [m21 - m12, m02 - m20, m10 - m01, 1 + trace]
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm


def _rotvec_from_quat_xyzw(x: float, y: float, z: float, w: float) -> list:
    if w < 0 or (w == 0 and (x < 0 or (x == 0 and (y < 0 or (y == 0 and z < 0))))):
        x, y, z, w = -x, -y, -z, -w  # w ≥ 0: the angle lies in [0, π]
    angle = 2 * math.atan2(math.sqrt(x * x + y * y + z * z), w)
    if angle <= 1e-3:  # Taylor series of θ/sin(θ/2)
        angle2 = angle * angle
        scale = 2 + angle2 / 12 + 7 * angle2 * angle2 / 2880
    else:
        scale = angle / math.sin(angle / 2)
    return [scale * x, scale * y, scale * z]


def _is_orthonormal(m: list) -> bool:
    """RRᵀ = I within the tolerance scipy's ``Rotation.from_matrix`` uses (atol 1e-12, rtol
    1e-5 on the diagonal) — above it scipy projects onto SO(3) first."""
    for i in range(3):
        ri = m[i]
        for j in range(i, 3):
            rj = m[j]
            g = ri[0] * rj[0] + ri[1] * rj[1] + ri[2] * rj[2]
            if i == j:
                if not abs(g - 1.0) <= 1e-12 + 1e-5:
                    return False
            elif not abs(g) <= 1e-12:
                return False
    return True


def rotation_exp(rotvec) -> np.ndarray:
    """exp([ω]×): the rotation matrix of a rotation vector ω (axis · angle, rad).

    Computed through the unit quaternion (sin(θ/2)/θ · ω, cos(θ/2)), with a Taylor series for
    θ ≤ 1e-3 — the same arithmetic as scipy's ``Rotation.from_rotvec(ω).as_matrix()``, without
    its per-call overhead."""
    w = np.asarray(rotvec, dtype=float)
    if w.shape != (3,):
        return Rotation.from_rotvec(w).as_matrix()  # stacks, and scipy's shape errors
    wx, wy, wz = w.tolist()
    if not math.isfinite(wx * wx + wy * wy + wz * wz):
        return Rotation.from_rotvec(w).as_matrix()  # NaN / inf / overflow: scipy's result
    return np.array(_matrix_from_quat_xyzw(*_quat_xyzw_from_rotvec(wx, wy, wz)))


def rotation_log(R) -> np.ndarray:
    """Rotation vector of a rotation matrix (angle in [0, π]), accurate at θ → 0 and θ → π.

    Through the quaternion (Shepperd's method), like scipy's
    ``Rotation.from_matrix(R).as_rotvec()`` — same arithmetic and results, including its
    projection of a non-orthonormal R onto SO(3) and its ValueError for det R ≤ 0."""
    M = np.asarray(R, dtype=float)
    if M.shape != (3, 3):
        return Rotation.from_matrix(M).as_rotvec()
    m = M.tolist()
    (a, b, c), (d, e, f), (g, h, i) = m
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if not (det > 0 and _is_orthonormal(m)):
        return Rotation.from_matrix(M).as_rotvec()  # projection / error path: scipy's own
    return np.array(_rotvec_from_quat_xyzw(*_quat_xyzw_from_rotation(m)))


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

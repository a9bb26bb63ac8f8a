"""Compiled kernels of the per-sample work (numba, nopython, cached on disk).

The closed loop runs the target filter's update, the servo's twist and the camera's projection
at every camera sample; written with numpy they cost more in per-call overhead (a microsecond or
more per array operation on 3×3 … 12×12 arrays) than in arithmetic. These are the same
formulas (the numpy modules state them and keep the checked, general entry points), compiled.
Results equal the numpy path's to rounding (tests compare them), not bit for bit: compiled
products sum in another order.

Every kernel is compiled once per machine (``cache=True``: the machine code is kept beside the
source in ``__pycache__``, or in numba's cache directory when that is read-only).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_CACHE = dict(cache=True, nogil=True)


# --------------------------------------------------------------------------- SO(3) and SE(3)

@njit(**_CACHE)
def rotation_exp(w):
    """exp([w]×) through the unit quaternion (se3.rotation_exp's formula)."""
    wx, wy, wz = w[0], w[1], w[2]
    angle = math.sqrt(wx * wx + wy * wy + wz * wz)
    if angle <= 1e-3:
        a2 = angle * angle
        scale = 0.5 - a2 / 48 + a2 * a2 / 3840
    else:
        scale = math.sin(angle / 2) / angle
    x, y, z, qw = scale * wx, scale * wy, scale * wz, math.cos(angle / 2)
    x2, y2, z2, w2 = x * x, y * y, z * z, qw * qw
    xy, zw, xz, yw, yz, xw = x * y, z * qw, x * z, y * qw, y * z, x * qw
    R = np.empty((3, 3))
    R[0, 0], R[0, 1], R[0, 2] = x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw)
    R[1, 0], R[1, 1], R[1, 2] = 2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw)
    R[2, 0], R[2, 1], R[2, 2] = 2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2
    return R


@njit(**_CACHE)
def is_orthonormal(R):
    """RRᵀ = I within scipy's tolerance and det R > 0 (se3._is_orthonormal and its det test)."""
    for i in range(3):
        for j in range(i, 3):
            g = R[i, 0] * R[j, 0] + R[i, 1] * R[j, 1] + R[i, 2] * R[j, 2]
            if i == j:
                if not abs(g - 1.0) <= 1e-12 + 1e-5:
                    return False
            elif not abs(g) <= 1e-12:
                return False
    return np.linalg.det(R) > 0


@njit(**_CACHE)
def rotation_log(R):
    """Rotation vector of an orthonormal R (angle in [0, π]) by Shepperd's quaternion, as
    se3.rotation_log; callers check ``is_orthonormal`` first."""
    m00, m01, m02 = R[0, 0], R[0, 1], R[0, 2]
    m10, m11, m12 = R[1, 0], R[1, 1], R[1, 2]
    m20, m21, m22 = R[2, 0], R[2, 1], R[2, 2]
    trace = m00 + m11 + m22
    choice, vmax = 0, m00
    if m11 > vmax:
        choice, vmax = 1, m11
    if m22 > vmax:
        choice, vmax = 2, m22
    if trace > vmax:
        choice = 3
    if choice == 0:
        q0, q1, q2, q3 = 1 - trace + 2 * m00, m10 + m01, m20 + m02, m21 - m12
    elif choice == 1:
        q0, q1, q2, q3 = m01 + m10, 1 - trace + 2 * m11, m21 + m12, m02 - m20
    elif choice == 2:
        q0, q1, q2, q3 = m02 + m20, m12 + m21, 1 - trace + 2 * m22, m10 - m01
    else:
        q0, q1, q2, q3 = m21 - m12, m02 - m20, m10 - m01, 1 + trace
    norm = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
    x, y, z, w = q0 / norm, q1 / norm, q2 / norm, q3 / norm
    if w < 0 or (w == 0 and (x < 0 or (x == 0 and (y < 0 or (y == 0 and z < 0))))):
        x, y, z, w = -x, -y, -z, -w
    angle = 2 * math.atan2(math.sqrt(x * x + y * y + z * z), w)
    if angle <= 1e-3:
        a2 = angle * angle
        scale = 2 + a2 / 12 + 7 * a2 * a2 / 2880
    else:
        scale = angle / math.sin(angle / 2)
    out = np.empty(3)
    out[0], out[1], out[2] = scale * x, scale * y, scale * z
    return out


@njit(**_CACHE)
def _svd_rotation(M):
    U, _, Vt = np.linalg.svd(M)
    s = np.sign(np.linalg.det(U @ Vt))
    if s == 0.0:
        s = 1.0
    D = np.eye(3)
    D[2, 2] = s
    return U @ D @ Vt


@njit(**_CACHE)
def project_to_rotation(M):
    """The nearest rotation U diag(1, 1, sign det(UVᵀ)) Vᵀ (orthonormalize's "svd"). For
    det M > 0 that is M's orthogonal polar factor, reached here by Newton's iteration
    X ← (X + X⁻ᵀ) / 2 (quadratic: three or four steps from a measured rotation, a fraction of
    an SVD's cost; the two agree to rounding); the SVD otherwise, or if it does not settle."""
    X = M.copy()
    for _ in range(30):
        a, b, c = X[0, 0], X[0, 1], X[0, 2]
        d, e, f = X[1, 0], X[1, 1], X[1, 2]
        g, h, i = X[2, 0], X[2, 1], X[2, 2]
        c00, c01, c02 = e * i - f * h, f * g - d * i, d * h - e * g  # cofactors
        det = a * c00 + b * c01 + c * c02
        if not det > 1e-12:
            return _svd_rotation(M)
        c10, c11, c12 = c * h - b * i, a * i - c * g, b * g - a * h
        c20, c21, c22 = b * f - c * e, c * d - a * f, a * e - b * d
        # X⁻ᵀ = cofactor matrix / det
        C = np.empty((3, 3))
        C[0, 0], C[0, 1], C[0, 2] = c00, c01, c02
        C[1, 0], C[1, 1], C[1, 2] = c10, c11, c12
        C[2, 0], C[2, 1], C[2, 2] = c20, c21, c22
        Y = np.empty((3, 3))
        for r in range(3):
            for k in range(3):
                Y[r, k] = 0.5 * (X[r, k] + C[r, k] / det)
        step = 0.0
        for r in range(3):
            for k in range(3):
                step = max(step, abs(Y[r, k] - X[r, k]))
        X = Y
        if step <= 1e-15:
            return X
    return _svd_rotation(M)


@njit(**_CACHE)
def inverse_pose(X):
    out = np.empty((4, 4))
    for i in range(3):
        for j in range(3):
            out[i, j] = X[j, i]
        out[i, 3] = -(X[0, i] * X[0, 3] + X[1, i] * X[1, 3] + X[2, i] * X[2, 3])
    out[3, 0], out[3, 1], out[3, 2], out[3, 3] = 0.0, 0.0, 0.0, 1.0
    return out


@njit(**_CACHE)
def _skew(v):
    S = np.zeros((3, 3))
    S[0, 1], S[0, 2] = -v[2], v[1]
    S[1, 0], S[1, 2] = v[2], -v[0]
    S[2, 0], S[2, 1] = -v[1], v[0]
    return S


@njit(**_CACHE)
def _retract(X, delta):
    out = np.empty((4, 4))
    out[:3, :3] = rotation_exp(delta[:3]) @ X[:3, :3].copy()
    out[:3, 3] = X[:3, 3] + delta[3:6]
    out[3, 0], out[3, 1], out[3, 2], out[3, 3] = 0.0, 0.0, 0.0, 1.0
    return out


# ------------------------------------------------------------------------ the target filter

@njit(**_CACHE)
def spd_inverse(S):
    """(S⁻¹, True) of a symmetric positive definite S by Cholesky; (S, False) when a pivot is
    not positive (the caller falls back to the pseudo-inverse)."""
    n = S.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        d = S[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 0.0:
            return S, False
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, n):
            s = S[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    # L⁻¹ (lower triangular), then S⁻¹ = L⁻ᵀ L⁻¹.
    Li = np.zeros((n, n))
    for j in range(n):
        Li[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, n):
            s = 0.0
            for k in range(j, i):
                s -= L[i, k] * Li[k, j]
            Li[i, j] = s / L[i, i]
    return Li.T @ Li, True


@njit(**_CACHE)
def pose_residual(X_CE, X_BT, X_EB, R_CTm, t_CTm):
    """(z, H, ok) of manifold.pose_residual; ok False when R_CTm R_CTᵀ is not a rotation to
    scipy's tolerance (the numpy path then handles it)."""
    R_CE, t_CE = X_CE[:3, :3].copy(), X_CE[:3, 3].copy()  # (contiguous: BLAS-free products)
    R_EB, t_EB = X_EB[:3, :3].copy(), X_EB[:3, 3].copy()
    u = R_EB @ X_BT[:3, 3].copy() + t_EB
    R_CB = R_CE @ R_EB
    R_CT = R_CB @ X_BT[:3, :3].copy()
    t_CT = R_CE @ u + t_CE
    z = np.empty(6)
    H = np.zeros((6, 12))
    E = R_CTm @ R_CT.T
    if not is_orthonormal(E):
        return z, H, False
    z[:3] = rotation_log(E)
    z[3:] = t_CTm - t_CT
    for i in range(3):
        H[i, i] = 1.0
        H[3 + i, 3 + i] = 1.0
    H[:3, 6:9] = R_CB
    H[3:, :3] = -_skew(R_CE @ u)
    H[3:, 9:12] = R_CB
    return z, H, True


@njit(**_CACHE)
def pose_update(X_CE, X_BT, P, X_EB, R_CTm, t_CTm, Rn, bound, iterations):
    """One iterated error-state EKF update of (X_CE, X_BT) by a synchronized sample — the
    arithmetic of manifold.error_state_update with pose_residual and retract_pose_pair.

    Returns (X_CE, X_BT, P, code, nis): code 0 fused, 1 rejected (NIS not finite or above
    ``bound``), 2 not handled here (a non-positive-definite innovation covariance or a
    non-rotation residual: the caller runs the numpy path)."""
    z, H, ok = pose_residual(X_CE, X_BT, X_EB, R_CTm, t_CTm)
    if not ok:
        return X_CE, X_BT, P, 2, math.nan
    S_inv, ok = spd_inverse(H @ P @ H.T + Rn)
    if not ok:
        return X_CE, X_BT, P, 2, math.nan
    nis = z @ (S_inv @ z)
    if not math.isfinite(nis) or nis > bound:
        return X_CE, X_BT, P, 1, nis
    est_CE, est_BT = X_CE, X_BT
    delta = np.zeros(12)
    for i in range(iterations):
        K = P @ H.T @ S_inv
        delta_new = K @ (z + H @ delta)
        d = delta_new - delta
        step = math.sqrt(d @ d)
        delta = delta_new
        est_CE, est_BT = _retract(X_CE, delta[:6]), _retract(X_BT, delta[6:])
        if i + 1 == iterations or step < 1e-9:
            break
        z, H, ok = pose_residual(est_CE, est_BT, X_EB, R_CTm, t_CTm)
        if not ok:
            return X_CE, X_BT, P, 2, math.nan
        S_inv, ok = spd_inverse(H @ P @ H.T + Rn)
        if not ok:
            return X_CE, X_BT, P, 2, math.nan
    K = P @ H.T @ S_inv
    I_KH = np.eye(12) - K @ H
    P_new = I_KH @ P @ I_KH.T + K @ Rn @ K.T
    return est_CE, est_BT, 0.5 * (P_new + P_new.T), 0, nis


@njit(**_CACHE)
def estimate_outputs(X_CE, P):
    """(x_CE, x_EC, X_EC std [deg ×3, m ×3], X_EC covariance (36)) of a hand-eye estimate X_CE
    with the covariance P of its error (the leading 6×6 block): the calibrator's outputs, as
    ``pose_to_vector``, ``inverse`` and ``EstimatorBase.X_EC_covariance`` compute them."""
    X_EC = inverse_pose(X_CE)
    x_CE, x_EC = np.empty(12), np.empty(12)
    for i in range(3):
        for j in range(3):
            x_CE[3 * i + j], x_EC[3 * i + j] = X_CE[i, j], X_EC[i, j]
        x_CE[9 + i], x_EC[9 + i] = X_CE[i, 3], X_EC[i, 3]
    # J = [[−Rᵀ, 0], [−Rᵀ [t]×, −Rᵀ]] (se3.inverse_tangent_jacobian)
    Rt = np.ascontiguousarray(X_CE[:3, :3].T)
    J = np.zeros((6, 6))
    J[:3, :3] = -Rt
    J[3:, :3] = -(Rt @ _skew(X_CE[:3, 3].copy()))
    J[3:, 3:] = -Rt
    C = J @ np.ascontiguousarray(P[:6, :6]) @ J.T
    std = np.empty(6)
    for i in range(6):
        v = max(C[i, i], 0.0)
        std[i] = math.degrees(math.sqrt(v)) if i < 3 else math.sqrt(v)
    return x_CE, x_EC, std, C.reshape(36)


# ------------------------------------------------------------------------ the visual servo

@njit(**_CACHE)
def twist_motion(x, s, orthonormalize):
    """(R, p) of X0 · exp(V s) for the servo's pose state x = [vec_row(R0); p0; t0; V]
    (servo._twist_motion's scalar arithmetic, operation for operation)."""
    ax, ay, az = s * x[13], s * x[14], s * x[15]
    bx, by, bz = s * x[16], s * x[17], s * x[18]
    th2 = ax * ax + ay * ay + az * az
    if th2 < 1e-8:
        A, B, C = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0, 1.0 / 6.0 - th2 / 120.0
    else:
        th = math.sqrt(th2)
        A, B = math.sin(th) / th, (1.0 - math.cos(th)) / th2
        C = (1.0 - A) / th2
    d = 1.0 - B * th2
    E = np.empty((3, 3))
    E[0, 0], E[0, 1], E[0, 2] = d + B * ax * ax, B * ax * ay - A * az, B * ax * az + A * ay
    E[1, 0], E[1, 1], E[1, 2] = B * ay * ax + A * az, d + B * ay * ay, B * ay * az - A * ax
    E[2, 0], E[2, 1], E[2, 2] = B * az * ax - A * ay, B * az * ay + A * ax, d + B * az * az
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    ex, ey, ez = ay * cz - az * cy, az * cx - ax * cz, ax * cy - ay * cx
    j = (bx + B * cx + C * ex, by + B * cy + C * ey, bz + B * cz + C * ez)
    R = np.empty((3, 3))
    p = np.empty(3)
    for r in range(3):
        r0, r1, r2 = x[3 * r], x[3 * r + 1], x[3 * r + 2]
        for k in range(3):
            R[r, k] = r0 * E[0, k] + r1 * E[1, k] + r2 * E[2, k]
        p[r] = x[9 + r] + r0 * j[0] + r1 * j[1] + r2 * j[2]
    if orthonormalize:
        G = np.empty((3, 3))
        for i in range(3):
            for k in range(3):
                G[i, k] = R[0, i] * R[0, k] + R[1, i] * R[1, k] + R[2, i] * R[2, k]
        out = np.empty((3, 3))
        for i in range(3):
            for k in range(3):
                acc = 0.0
                for m in range(3):
                    acc += R[i, m] * ((1.5 if m == k else 0.0) - 0.5 * G[m, k])
                out[i, k] = acc
        R = out
    return R, p


@njit(**_CACHE)
def servo_errors(features, visible, x_CT, p_TQ, desired, min_depth):
    """(Z, usable, number usable, RMS feature error over them or −1 when none) of the servo's
    sample: the depths Z_i = (X_CT p_TQi)_z, usable = visible and Z > min_depth."""
    n = p_TQ.shape[0]
    Z = np.empty(n)
    usable = np.empty(n, np.bool_)
    total, count = 0.0, 0
    for i in range(n):
        Z[i] = (p_TQ[i, 0] * x_CT[6] + p_TQ[i, 1] * x_CT[7] + p_TQ[i, 2] * x_CT[8]) + x_CT[11]
        usable[i] = visible[i] > 0.5 and Z[i] > min_depth
        if usable[i]:
            du, dv = features[2 * i] - desired[2 * i], features[2 * i + 1] - desired[2 * i + 1]
            total += du * du + dv * dv
            count += 1
    return Z, usable, count, (math.sqrt(total / count) if count else -1.0)


@njit(**_CACHE)
def servo_sample(features, visible, x_CT, p_TQ, desired, min_depth):
    """``servo_errors`` and whether its three inputs are all finite (the servo's input check),
    in one call: (Z, usable, number usable, RMS error or −1, finite)."""
    finite = True
    for a in (features, visible, x_CT):
        for i in range(a.shape[0]):
            finite = finite and math.isfinite(a[i])
    Z, usable, count, error = servo_errors(features, visible, x_CT, p_TQ, desired, min_depth)
    return Z, usable, count, error, finite


@njit(**_CACHE)
def servo_twist(features, Z, usable, x_CE, K2, principal_point, desired, gain, max_w, max_v):
    """V_E = −gain · pinv(L_E) (s − s*) over the usable points, saturated (whole twist scaled)
    to ‖ω‖ ≤ max_w, ‖v‖ ≤ max_v — servo.VisualServoController._ServoTwist's formulas."""
    m = 0
    for i in range(usable.shape[0]):
        m += usable[i]
    # twist_transform(X_CE) = [[R, 0], [[p]× R, R]]
    R = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            R[i, j] = x_CE[3 * i + j]
    T = np.zeros((6, 6))
    T[:3, :3] = R
    T[3:, 3:] = R
    T[3:, :3] = _skew(x_CE[9:12].copy()) @ R
    Kinv = np.linalg.inv(K2)
    Ln = np.zeros((2 * m, 6))
    error = np.empty(2 * m)
    row = 0
    for i in range(usable.shape[0]):
        if not usable[i]:
            continue
        du, dv = features[2 * i] - principal_point[0], features[2 * i + 1] - principal_point[1]
        x = Kinv[0, 0] * du + Kinv[0, 1] * dv
        y = Kinv[1, 0] * du + Kinv[1, 1] * dv
        z = Z[i]
        # K2 times the point's 2×6 block of the normalized interaction matrix.
        M = np.zeros((2, 6))
        M[0, 0], M[0, 1], M[0, 2] = x * y, -(1.0 + x * x), y
        M[0, 3], M[0, 5] = -1.0 / z, x / z
        M[1, 0], M[1, 1], M[1, 2] = 1.0 + y * y, -x * y, -x
        M[1, 4], M[1, 5] = -1.0 / z, y / z
        for r in range(2):
            for c in range(6):
                Ln[row + r, c] = K2[r, 0] * M[0, c] + K2[r, 1] * M[1, c]
        error[row] = features[2 * i] - desired[2 * i]
        error[row + 1] = features[2 * i + 1] - desired[2 * i + 1]
        row += 2
    L = Ln @ T
    V = -gain * (np.linalg.pinv(L, 1e-10) @ error)
    w = math.sqrt(V[0] * V[0] + V[1] * V[1] + V[2] * V[2])
    v = math.sqrt(V[3] * V[3] + V[4] * V[4] + V[5] * V[5])
    scale = 1.0
    if w > max_w:
        scale = min(scale, max_w / w)
    if v > max_v:
        scale = min(scale, max_v / v)
    return scale * V


# ------------------------------------------------------------------------ the point camera

@njit(**_CACHE)
def hand_poses(X_WBodyE, X_BodyE, X_WBodyB, X_BodyB):
    """(x_WE, X_WE, X_BE) from the plant's body poses (systems.arm.EndEffectorPoseInput)."""
    X_WE = X_WBodyE @ X_BodyE
    X_BE = inverse_pose(X_WBodyB @ X_BodyB) @ X_WE
    x = np.empty(12)
    for i in range(3):
        for j in range(3):
            x[3 * i + j] = X_WE[i, j]
        x[9 + i] = X_WE[i, 3]
    return x, X_WE, X_BE


@njit(**_CACHE)
def camera_sample(X_WE, X_EC, X_WT, p_TQ, K2, principal_point, width, height, min_depth,
                  pixel_sigma, pixel_noise, rotation_sigma, translation_sigma, paper_model,
                  pose_noise):
    """(uv (2N), visible (N, 0/1), x_CT measured, x_WC) of systems.camera.HandEyeCamera's sample:
    the projection of the target's points (noiseless where not in front, 0 behind), pixel noise
    on the points in the image, and the pose noise of camera_model.apply_pose_noise ("paper":
    R + σ N (9 coefficients), else exp(σ n) R) plus σ_t n on the translation. A zero σ skips its
    noise (the noise arrays are then not read)."""
    X_WC = X_WE @ X_EC
    X_CT = inverse_pose(X_WC) @ X_WT
    n = p_TQ.shape[0]
    uv = np.zeros(2 * n)
    visible = np.zeros(n)
    for i in range(n):
        pc = np.empty(3)
        for r in range(3):
            pc[r] = (p_TQ[i, 0] * X_CT[r, 0] + p_TQ[i, 1] * X_CT[r, 1]
                     + p_TQ[i, 2] * X_CT[r, 2]) + X_CT[r, 3]
        if not pc[2] > min_depth:
            continue
        x, y = pc[0] / pc[2], pc[1] / pc[2]
        u = (x * K2[0, 0] + y * K2[0, 1]) + principal_point[0]
        v = (x * K2[1, 0] + y * K2[1, 1]) + principal_point[1]
        inside = u >= 0 and u < width and v >= 0 and v < height
        if inside:
            visible[i] = 1.0
            if pixel_sigma > 0:
                u += pixel_sigma * pixel_noise[2 * i]
                v += pixel_sigma * pixel_noise[2 * i + 1]
        uv[2 * i], uv[2 * i + 1] = u, v
    x_CT, x_WC = np.empty(12), np.empty(12)
    if rotation_sigma > 0 or translation_sigma > 0:
        if paper_model:
            Rm = np.empty((3, 3))
            for i in range(3):
                for j in range(3):
                    Rm[i, j] = X_CT[i, j] + rotation_sigma * pose_noise[3 * i + j]
        else:
            w = np.empty(3)
            for i in range(3):
                w[i] = rotation_sigma * pose_noise[i]
            Rm = rotation_exp(w) @ np.ascontiguousarray(X_CT[:3, :3])
        for i in range(3):
            for j in range(3):
                x_CT[3 * i + j] = Rm[i, j]
            x_CT[9 + i] = X_CT[i, 3] + translation_sigma * pose_noise[9 + i]
    else:
        for i in range(3):
            for j in range(3):
                x_CT[3 * i + j] = X_CT[i, j]
            x_CT[9 + i] = X_CT[i, 3]
    for i in range(3):
        for j in range(3):
            x_WC[3 * i + j] = X_WC[i, j]
        x_WC[9 + i] = X_WC[i, 3]
    return uv, visible, x_CT, x_WC


@njit(**_CACHE)
def rotation_fast_test(x, tolerance):
    """The rotation R = x[:9] (row-major, a pose vector's) is clearly a rotation to
    ``tolerance``: ‖RᵀR − I‖_F² ≤ (0.999 tol)² and |det R − 1| ≤ 0.999 tol. False decides
    nothing: the exact test (``validation.rotation_defect``) then does."""
    a, b, c, d, e, f, g, h, i = x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7], x[8]
    g00, g11, g22 = a * a + d * d + g * g - 1.0, b * b + e * e + h * h - 1.0, \
        c * c + f * f + i * i - 1.0
    g01, g02, g12 = a * b + d * e + g * h, a * c + d * f + g * i, b * c + e * f + h * i
    frob2 = g00 * g00 + g11 * g11 + g22 * g22 + 2.0 * (g01 * g01 + g02 * g02 + g12 * g12)
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    bound = 0.999 * tolerance
    return frob2 <= bound * bound and abs(det - 1.0) <= bound


@njit(**_CACHE)
def camera_step(X_WBodyE, X_BodyE, X_WBodyB, X_BodyB, X_EC, X_WT, p_TQ, K2, principal_point,
                width, height, min_depth, pixel_sigma, pixel_noise, rotation_sigma,
                translation_sigma, paper_model, pose_noise, rotation_tolerance):
    """systems.camera.HandEyeCamera's sample from the plant's body poses in one call: the
    arithmetic of ``hand_poses`` then ``camera_sample`` (the same functions, so the same
    numbers), as one array [uv (2N); visible (N); x_CT; x_WC; x_BE; checks (3)] with
    checks = [x_WE finite, x_WE's rotation passes the camera's fast test (frob² and det within
    0.999 × rotation_tolerance; 0 leaves the exact test to the caller), the noise read is
    finite]."""
    x, X_WE, X_BE = hand_poses(X_WBodyE, X_BodyE, X_WBodyB, X_BodyB)
    uv, visible, x_CT, x_WC = camera_sample(
        X_WE, X_EC, X_WT, p_TQ, K2, principal_point, width, height, min_depth, pixel_sigma,
        pixel_noise, rotation_sigma, translation_sigma, paper_model, pose_noise)
    n = p_TQ.shape[0]
    out = np.empty(3 * n + 39)
    out[:2 * n] = uv
    out[2 * n:3 * n] = visible
    k = 3 * n
    out[k:k + 12] = x_CT
    out[k + 12:k + 24] = x_WC
    for i in range(3):
        for j in range(3):
            out[k + 24 + 3 * i + j] = X_BE[i, j]
        out[k + 33 + i] = X_BE[i, 3]
    finite = True
    for i in range(12):
        finite = finite and math.isfinite(x[i])
    noise_finite = True
    for i in range(pixel_noise.shape[0]):
        noise_finite = noise_finite and math.isfinite(pixel_noise[i])
    for i in range(pose_noise.shape[0]):
        noise_finite = noise_finite and math.isfinite(pose_noise[i])
    out[k + 36] = 1.0 if finite else 0.0
    out[k + 37] = 1.0 if rotation_fast_test(x, rotation_tolerance) else 0.0
    out[k + 38] = 1.0 if noise_finite else 0.0
    return out


@njit(**_CACHE)
def all_finite(a, b):
    """Every entry of the 1-D arrays a and b is finite."""
    for x in (a, b):
        for i in range(x.shape[0]):
            if not math.isfinite(x[i]):
                return False
    return True


@njit(**_CACHE)
def sample_poses(x_BE, x_CT):
    """(X_BE, X_CT, all finite) of a synchronized sample's two pose vectors [vec_row(R); p]
    (se3.vector_to_pose of each)."""
    X_BE, X_CT = np.empty((4, 4)), np.empty((4, 4))
    finite = True
    for X, x in ((X_BE, x_BE), (X_CT, x_CT)):
        for i in range(3):
            for j in range(3):
                X[i, j] = x[3 * i + j]
            X[i, 3] = x[9 + i]
            X[3, i] = 0.0
        X[3, 3] = 1.0
        for k in range(12):
            finite = finite and math.isfinite(x[k])
    return X_BE, X_CT, finite


@njit(**_CACHE)
def rotation_between(R0, R1):
    """(φ, ok) with R1 = R0 exp([φ]×) (estimator.rotation_vector_between); ok False when R0ᵀR1
    is not a rotation to scipy's tolerance (the caller takes the general path)."""
    M = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            M[i, j] = R0[0, i] * R1[0, j] + R0[1, i] * R1[1, j] + R0[2, i] * R1[2, j]
    if not is_orthonormal(M):
        return np.zeros(3), False
    return rotation_log(M), True


# ------------------------------------------------------------- the calibrator's per-sample step

#: Offsets in ``HandEyeTargetFilter.to_vector()`` (checked against its ``_LAYOUT`` by
#: ``manifold.HandEyeTargetFilter.vector_update``).
TARGET_FILTER_LAYOUT = dict(X_CE=0, X_BT=12, P=24, target_known=168, R_BE_ref=169,
                            counters=178, size=195)


@njit(**_CACHE)
def _vector_pose(v, start):
    X = np.empty((4, 4))
    for i in range(3):
        for j in range(3):
            X[i, j] = v[start + 3 * i + j]
        X[i, 3] = v[start + 9 + i]
        X[3, i] = 0.0
    X[3, 3] = 1.0
    return X


@njit(**_CACHE)
def _put_pose(v, start, X):
    for i in range(3):
        for j in range(3):
            v[start + 3 * i + j] = X[i, j]
        v[start + 9 + i] = X[i, 3]


@njit(**_CACHE)
def target_filter_step(v, x_BE, x_CT, G1, Rn, bound, iterations, max_consecutive, mode):
    """One sample of ``HandEyeTargetFilter._update`` (and of its ``_gated_update`` and
    counters) on its state vector ``v`` (``to_vector``'s layout), with the calibrator's outputs
    of the result (``estimate_outputs`` and the status [mode, updates, rejected, NIS or −1]).

    ``max_consecutive``: the config's ``max_consecutive_rejections`` (−1 for None). Returns
    (code, v_new, x_CE, x_EC, std, cov, status): code 0 fused, 1 rejected, 2 not handled here —
    the first sample (it places the target), no reference rotation yet, a rejection that would
    start the covariance-inflation recovery, the rare cases ``pose_update`` leaves, a
    non-rotation excitation step, or a result with an entry beyond ±1e300 (the numpy path then
    decides, and raises if it is not finite). Same kernels in the same order as the numpy path:
    equal to it bit for bit."""
    nothing = np.zeros(0)
    if v[168] == 0.0 or math.isnan(v[169]):
        return 2, v, nothing, nothing, nothing, nothing, nothing
    X_BE, X_CT, finite = sample_poses(x_BE, x_CT)
    if not finite:
        return 2, v, nothing, nothing, nothing, nothing, nothing
    R_CTm = project_to_rotation(np.ascontiguousarray(X_CT[:3, :3]))
    X_EB = inverse_pose(X_BE)
    P = v[24:168].copy().reshape(12, 12) + G1
    X_CE_new, X_BT_new, P_new, code, nis = pose_update(
        _vector_pose(v, 0), _vector_pose(v, 12), P, X_EB, R_CTm,
        np.ascontiguousarray(X_CT[:3, 3]), Rn, bound, iterations)
    out = v.copy()
    c = 178
    if code == 2:
        return 2, v, nothing, nothing, nothing, nothing, nothing
    if code == 1:
        if (max_consecutive >= 0 and math.isfinite(nis)
                and out[c + 3] + 1 >= max_consecutive):
            return 2, v, nothing, nothing, nothing, nothing, nothing
        out[24:168] = P.reshape(144)
        out[c + 1] += 1.0  # rejected
        out[c + 3] += 1.0  # consecutive
        out[c + 5] = nis
    else:
        for M in (X_CE_new, X_BT_new, P_new):
            for e in M.ravel():
                if not abs(e) <= 1e300:
                    return 2, v, nothing, nothing, nothing, nothing, nothing
        R_BE_ref = v[169:178].copy().reshape(3, 3)
        phi, ok = rotation_between(R_BE_ref, np.ascontiguousarray(X_BE[:3, :3]))
        if not ok:
            return 2, v, nothing, nothing, nothing, nothing, nothing
        _put_pose(out, 0, X_CE_new)
        _put_pose(out, 12, X_BT_new)
        out[24:168] = P_new.reshape(144)
        out[c] += 1.0      # updates
        out[c + 3] = 0.0   # consecutive
        out[c + 5] = nis
        if math.isfinite(nis):
            out[c + 6] += nis
            out[c + 7] += 1.0
        for i in range(3):
            for j in range(3):
                out[c + 8 + 3 * i + j] += phi[i] * phi[j]
    X_CE = _vector_pose(out, 0)
    x_CE, x_EC, std, cov = estimate_outputs(X_CE, out[24:168].copy().reshape(12, 12))
    status = np.empty(4)
    status[0], status[1], status[2] = mode, out[c], out[c + 1]
    status[3] = out[c + 5] if math.isfinite(out[c + 5]) else -1.0
    return code, out, x_CE, x_EC, std, cov, status

"""Classical (batch) hand-eye solvers of AX = XB, cross-checked against OpenCV.

Frames (docs/method.md §2): the robot reports ``X_BE`` (end-effector E in robot base B, OpenCV's
"gripper→base"), the camera measures ``X_CT`` (target T in camera C, OpenCV's "target→camera").
A camera motion A = X_{CiCj} and the matching end-effector motion B = X_{EiEj} between two samples
i, j satisfy

    A X_CE = X_CE B,        equivalently   B X_EC = X_EC A,

with the paper's X = ``X_CE`` (E in C) and OpenCV's "cam2gripper" ``X_EC`` = inv(X_CE).

Methods (``METHODS``). Except for "andreff", each follows OpenCV's ``calibrateHandEye``
(modules/calib3d/src/calibration_handeye.cpp) step by step, solving B Y = Y A for Y = X_EC exactly
as OpenCV does (its "gripper" motion is our B, its "camera" motion our A; the translation least
squares is posed for Y's translation, so results match OpenCV to rounding, not only to first
order in the noise), then returning X_CE = inv(Y):

- "tsai": Tsai–Lenz 1989. Modified Rodrigues vectors P = 2 sin(θ/2)·n of both motions give
  skew(P_B + P_A) P' = P_A − P_B (least squares), R_Y from P' = tan(θ_Y/2)·n_Y; then the
  translation by least squares of (R_B − I) t_Y = R_Y t_A − t_B. Singular when θ_Y → 180°.
- "park": Park–Martin 1994. Log maps α = log R_B, β = log R_A, M = Σ β αᵀ and
  R_Y = (MᵀM)^{-1/2} Mᵀ, computed as the polar factor U Vᵀ of Mᵀ (SVD, det fixed to +1): equal
  when M is full rank with det M > 0, and still unique with exactly two motions (rank-2 M).
  Translation as in "tsai".
- "horaud": Horaud–Dornaika 1995, quaternion form q_B * q = q * q_A: q is the eigenvector of the
  smallest eigenvalue of Σ (Q(q_B) − W(q_A))ᵀ (Q(q_B) − W(q_A)). Translation as in "tsai".
- "andreff": the paper's linear model (docs/method.md §3, ``linear_model.linear_system``) stacked over all
  motions, for X = X_CE. As in Andreff et al. 2001 the rotation comes from the homogeneous part:
  the right singular vector of the smallest singular value of the stacked 9K×9 block
  [I9 − R_A ⊗ R_B], reshaped row-major, scaled by sign(det)/|det|^{1/3} (so det = +1) and
  projected on SO(3) (SVD); the translation is then re-solved by least squares from
  (I3 − R_A) t_X = t_A − R_X t_B. OpenCV instead solves the full 12K×12 inhomogeneous system at
  once (rotation and translation jointly, translation not re-solved) and normalizes the rotation
  afterwards, so results agree exactly only on noise-free data.
- "daniilidis": Daniilidis 1999 dual quaternions: SVD of the 6K×8 matrix built from the dual
  quaternions of each motion pair, solution in the span of the two right singular vectors of the
  smallest singular values, fixed by the unit-norm and orthogonality constraints (a quadratic).

Quaternion signs: every motion's rotation quaternion is taken with w ≥ 0. A and B have the same
rotation angle, so their quaternions then have consistent signs (needed by "tsai", "horaud" and
"daniilidis"); OpenCV 4.14 does the same (older releases, before opencv/opencv PR #24897, left
the sign to a conversion branch for motions of 120° or more).

Known difference with OpenCV 4.14 (found by reproducing its output, see
tests/test_opencv_crosscheck.py): its "tsai" silently discards every motion pair whose gripper or
camera rotation has sin(θ/2) outside [0.15, 0.85], i.e. θ outside ≈ [17.3°, 116.4°] (PR #24897).
Ours keeps every motion — the paper's self-calibration uses exactly two motions, possibly small —
so the two "tsai" agree exactly only when no pair falls outside that band.

Data requirements (checked, ``ValueError`` otherwise): at least two motions, every motion with a
rotation angle ≥ ``min_angle`` on both sides (a pure translation has no rotation axis), rotation
axes not all parallel (the rotation about a common axis is unobservable), and the rotation angles
of A_k and B_k not grossly different for every k (they are equal for corresponding motions).
That last check catches mismatched data (lists out of sync, absolute poses given as motions, a
wrong Euler-angle convention) but not an inverted pose list (X_EB given for X_BE, X_TC for X_CT):
inverting the poses turns each motion into a conjugate of its inverse, with the same angle.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from .linear_model import linear_system_matrices, relative_motions
from .orthonormalize import orthonormalize_unchecked
from .se3 import inverse, make_transform, skew
from .validation import as_transform_list, check_positive, check_same_length

METHODS = ("tsai", "park", "horaud", "andreff", "daniilidis")

#: How ``calibrate_hand_eye`` forms motions from K samples: every pair i < j (as OpenCV does,
#: K(K−1)/2 motions) or consecutive samples only (K−1 motions, ``relative_motions``).
PAIRS = ("all", "consecutive")

#: Default smallest accepted rotation angle of a motion (rad). Only catches (near-)pure
#: translations; small but genuine rotations pass and simply weigh little in every method.
MIN_ROTATION_ANGLE = 1e-3

#: Rotation axes all within this angle (rad) of their common direction count as parallel.
MIN_AXIS_ANGLE = np.radians(1.0)

#: |θ_A − θ_B| above max(absolute, relative·max(θ_A, θ_B)) counts as a gross disagreement.
ANGLE_MISMATCH_ABS = np.radians(5.0)
ANGLE_MISMATCH_REL = 0.2


# ---------------------------------------------------------------------------------------------
# Quaternion helpers ([w, x, y, z], Hamilton product), vectorized over motions.

def _quats(R: np.ndarray) -> np.ndarray:
    """(K, 4) unit quaternions [w, x, y, z] of a (K, 3, 3) stack of rotations, with w ≥ 0."""
    xyzw = Rotation.from_matrix(R).as_quat()
    q = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    return np.where(q[:, :1] < 0, -q, q)


def _qmult(s: np.ndarray, t: np.ndarray) -> np.ndarray:
    s0, s1, s2, s3 = s
    t0, t1, t2, t3 = t
    return np.array([
        s0 * t0 - s1 * t1 - s2 * t2 - s3 * t3,
        s0 * t1 + s1 * t0 + s2 * t3 - s3 * t2,
        s0 * t2 - s1 * t3 + s2 * t0 + s3 * t1,
        s0 * t3 + s1 * t2 - s2 * t1 + s3 * t0,
    ])


def _quat_to_rotation(q: np.ndarray) -> np.ndarray:
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _dual_quaternion(X: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Vector parts of the dual quaternion (q, q') of X, q' = ½ (0, t) * q: (a, a')."""
    q_prime = 0.5 * _qmult(np.concatenate([[0.0], X[:3, 3]]), q)
    return q[1:], q_prime[1:]


# ---------------------------------------------------------------------------------------------
# The solvers. Inputs are validated (K, 4, 4) stacks of rigid motions A (camera), B (robot).
# Each returns X_CE.

def _translation_Y(A: np.ndarray, B: np.ndarray, R_Y: np.ndarray) -> np.ndarray:
    """Least squares t_Y of (I − R_B) t_Y = t_B − R_Y t_A (OpenCV's Tsai/Park/Horaud step)."""
    C = (np.eye(3)[None] - B[:, :3, :3]).reshape(-1, 3)
    d = (B[:, :3, 3] - A[:, :3, 3] @ R_Y.T).reshape(-1)
    return np.linalg.lstsq(C, d, rcond=None)[0]


#: Near this hand-eye angle Tsai–Lenz's tan(θ/2) parametrization degrades (see ``_tsai``).
TSAI_GUARD_ANGLE = np.radians(170.0)


def _tsai(A, B, guard: bool = True):
    P_A = 2.0 * _quats(A[:, :3, :3])[:, 1:]
    P_B = 2.0 * _quats(B[:, :3, :3])[:, 1:]
    M = np.concatenate([skew(pb + pa) for pb, pa in zip(P_B, P_A)])
    P = np.linalg.lstsq(M, (P_A - P_B).reshape(-1), rcond=None)[0]  # tan(θ_Y/2)·n_Y
    # Near θ_Y = 180° (a camera mounted upside down) tan(θ/2) blows up and the least squares
    # settles on a wrong rotation. Check the rotation equation B Y = Y A it should satisfy:
    # against the motions' size, and against Park's rotation (no such singularity) on the same
    # motions — a Tsai rotation fitting clearly worse than Park's is its singularity showing.
    R_Y = _quat_to_rotation(np.concatenate([[1.0], P]))

    def residual(R):
        return float(np.median([np.linalg.norm(B[k, :3, :3] @ R - R @ A[k, :3, :3])
                                for k in range(len(A))]))
    reference = np.median([np.linalg.norm(B[k, :3, :3] - np.eye(3)) for k in range(len(A))])
    alpha = Rotation.from_matrix(B[:, :3, :3]).as_rotvec()
    beta = Rotation.from_matrix(A[:, :3, :3]).as_rotvec()
    R_park = orthonormalize_unchecked((beta.T @ alpha).T, "svd")
    r_park, r_tsai = residual(R_park), residual(R_Y)
    near = 2.0 * np.arctan(np.linalg.norm(P)) > TSAI_GUARD_ANGLE and np.degrees(
        np.linalg.norm(Rotation.from_matrix(R_Y @ R_park.T).as_rotvec())) > 0.05
    if guard and (near or r_tsai > 0.5 * max(reference, 1e-12)
                  or r_tsai > 2.0 * r_park + 1e-9 * reference):
        raise ValueError(
            "tsai: the hand-eye rotation is near 180° (e.g. a camera mounted upside down), "
            "where Tsai–Lenz's tan(θ/2) parametrization is singular and its result unreliable "
            f"(rotation residual {r_tsai:.3g}, Park's {r_park:.3g}, motions {reference:.3g}); use "
            "park, horaud or daniilidis")
    return inverse(make_transform(R_Y, _translation_Y(A, B, R_Y)))


def _park(A, B):
    alpha = Rotation.from_matrix(B[:, :3, :3]).as_rotvec()
    beta = Rotation.from_matrix(A[:, :3, :3]).as_rotvec()
    M = beta.T @ alpha  # Σ β αᵀ
    R_Y = orthonormalize_unchecked(M.T, "svd")
    return inverse(make_transform(R_Y, _translation_Y(A, B, R_Y)))


def _horaud(A, B):
    N = np.zeros((4, 4))
    for (r0, rx, ry, rz), (c0, cx, cy, cz) in zip(_quats(B[:, :3, :3]), _quats(A[:, :3, :3])):
        Q = np.array([[r0, -rx, -ry, -rz], [rx, r0, -rz, ry], [ry, rz, r0, -rx],
                      [rz, -ry, rx, r0]])  # Q(r) q = r * q
        W = np.array([[c0, -cx, -cy, -cz], [cx, c0, cz, -cy], [cy, -cz, c0, cx],
                      [cz, cy, -cx, c0]])  # W(r) q = q * r
        N += (Q - W).T @ (Q - W)
    _, V = np.linalg.eigh(N)
    R_Y = _quat_to_rotation(V[:, 0])
    return inverse(make_transform(R_Y, _translation_Y(A, B, R_Y)))


def _andreff(A, B):
    systems = [linear_system_matrices(a, b) for a, b in zip(A, B)]
    # Rotation: null space of the stacked homogeneous block (I9 − R_A ⊗ R_B) vec_row(R_X) = 0.
    H = np.concatenate([C[:9, :9] for C, _ in systems])
    v = np.linalg.svd(H, full_matrices=False)[2][-1]
    M = v.reshape(3, 3)
    det = np.linalg.det(M)
    if abs(det) < 1e-12:
        raise ValueError("andreff: the null vector of the rotation block is rank-deficient "
                         f"(det = {det:.3g}); the motions do not determine the rotation")
    R_X = orthonormalize_unchecked(np.sign(det) / np.cbrt(abs(det)) * M, "svd")
    # Translation given R_X: rows (I3 − R_A) t_X = t_A − (I3 ⊗ t_Bᵀ) vec_row(R_X).
    r = R_X.reshape(9)
    C_t = np.concatenate([C[9:, 9:] for C, _ in systems])
    d = np.concatenate([y[9:] - C[9:, :9] @ r for C, y in systems])
    return make_transform(R_X, np.linalg.lstsq(C_t, d, rcond=None)[0])


def _daniilidis(A, B):
    q_A, q_B = _quats(A[:, :3, :3]), _quats(B[:, :3, :3])
    T = np.zeros((6 * len(A), 8))
    for k in range(len(A)):
        a, a_p = _dual_quaternion(B[k], q_B[k])  # OpenCV's gripper motion
        b, b_p = _dual_quaternion(A[k], q_A[k])  # OpenCV's camera motion
        T[6 * k:6 * k + 3, 0] = a - b
        T[6 * k:6 * k + 3, 1:4] = skew(a + b)
        T[6 * k + 3:6 * k + 6, 0] = a_p - b_p
        T[6 * k + 3:6 * k + 6, 1:4] = skew(a_p + b_p)
        T[6 * k + 3:6 * k + 6, 4] = a - b
        T[6 * k + 3:6 * k + 6, 5:8] = skew(a + b)
    V = np.linalg.svd(T, full_matrices=False)[2]
    (u1, v1), (u2, v2) = (V[6, :4], V[6, 4:]), (V[7, :4], V[7, 4:])
    # λ1 (u1, v1) + λ2 (u2, v2) with qᵀq' = 0: a λ1² + b λ1λ2 + c λ2² = 0 (Daniilidis eq. 34).
    qa, qb, qc = u1 @ v1, u1 @ v2 + u2 @ v1, u2 @ v2
    sq = np.sqrt(max(qb * qb - 4 * qa * qc, 0.0))  # < 0 only through rounding/noise
    if max(abs(qa), abs(qc)) < 1e-300:
        candidates = [(1.0, 0.0), (0.0, 1.0)]
    elif abs(qa) >= abs(qc):  # solve for s = λ1/λ2 (OpenCV's form)
        candidates = [((-qb + sq) / (2 * qa), 1.0), ((-qb - sq) / (2 * qa), 1.0)]
    else:  # solve for λ2/λ1: better conditioned when qa ≈ 0
        candidates = [(1.0, (-qb + sq) / (2 * qc)), (1.0, (-qb - sq) / (2 * qc))]
    # The other root spans (0, q), whose real-quaternion part vanishes: keep the larger |q|.
    l1, l2 = max(candidates, key=lambda c: np.linalg.norm((c[0] * u1 + c[1] * u2)
                                                           / np.hypot(*c)))
    scale = 1.0 / np.linalg.norm(l1 * u1 + l2 * u2)
    q = scale * (l1 * u1 + l2 * u2)
    q_prime = scale * (l1 * v1 + l2 * v2)
    R_Y = _quat_to_rotation(q)
    t_Y = 2.0 * _qmult(q_prime, q * np.array([1.0, -1.0, -1.0, -1.0]))[1:]
    return inverse(make_transform(R_Y, t_Y))


_SOLVERS = {"tsai": _tsai, "park": _park, "horaud": _horaud, "andreff": _andreff,
            "daniilidis": _daniilidis}


# ---------------------------------------------------------------------------------------------
# Checks.

def _check_method(method) -> str:
    if method not in METHODS:
        raise ValueError(f"method: unknown hand-eye method {method!r}; valid methods are "
                         f"{', '.join(repr(m) for m in METHODS)}")
    return method


def _project_rotations(Xs: list[np.ndarray], name: str) -> list[np.ndarray]:
    out = []
    for i, X in enumerate(Xs):
        s = np.linalg.svd(X[:3, :3], compute_uv=False)
        if s[0] == 0 or s[2] / s[0] < 1e-12:
            raise ValueError(f"{name}[{i}]: rotation block is rank-deficient (singular values "
                             f"{s.tolist()}), it cannot be projected onto a rotation")
        Y = X.copy()
        Y[:3, :3] = orthonormalize_unchecked(X[:3, :3], "svd")
        out.append(Y)
    return out


def _axis_spread(rotvecs: np.ndarray, angles: np.ndarray) -> float:
    """Largest angle (rad, in [0, π/2]) between a rotation axis and the axes' common line.

    The common line is the principal direction of Σ n nᵀ (axis signs do not matter). O(K), unlike
    the largest pairwise angle, which it bounds: pairwise ≤ 2 · spread. Computed with atan2, which
    stays accurate for nearly parallel axes (arccos of a dot product does not).
    """
    n = rotvecs / angles[:, None]
    u = np.linalg.eigh(n.T @ n)[1][:, -1]
    return float(np.max(np.arctan2(np.linalg.norm(np.cross(n, u), axis=1), np.abs(n @ u))))


def _check_motions(A: np.ndarray, B: np.ndarray, label: Callable[[int], str],
                   min_angle: float) -> None:
    K = len(A)
    if K < 2:
        raise ValueError(f"need at least 2 motions with non-parallel rotation axes, got {K}")
    rv_A = Rotation.from_matrix(A[:, :3, :3]).as_rotvec()
    rv_B = Rotation.from_matrix(B[:, :3, :3]).as_rotvec()
    th_A, th_B = np.linalg.norm(rv_A, axis=1), np.linalg.norm(rv_B, axis=1)
    for k in range(K):
        if min(th_A[k], th_B[k]) < min_angle:
            raise ValueError(
                f"{label(k)}: rotation angle is {np.degrees(th_A[k]):.3g}° (camera, A) / "
                f"{np.degrees(th_B[k]):.3g}° (robot, B), below min_angle = "
                f"{np.degrees(min_angle):.3g}°: a (near-)pure translation has no rotation axis "
                "and cannot be used by these methods; drop it or add a rotation")
    diff = np.abs(th_A - th_B)
    gross = diff > np.maximum(ANGLE_MISMATCH_ABS, ANGLE_MISMATCH_REL * np.maximum(th_A, th_B))
    if np.all(gross):
        raise ValueError(
            f"rotation angles of the camera motions A_k and robot motions B_k must be equal "
            f"(AX = XB makes them conjugate), but all {K} motions disagree grossly (median "
            f"|θ_A − θ_B| = {np.degrees(np.median(diff)):.3g}°; {label(0)}: θ_A = "
            f"{np.degrees(th_A[0]):.3g}°, θ_B = {np.degrees(th_B[0]):.3g}°). The two lists do "
            "not describe the same motions: probably a wrong frame convention or data "
            "mix-up — e.g. absolute poses passed where relative motions are expected, robot "
            "and camera samples out of sync, or rotations built with the wrong Euler-angle / "
            "quaternion convention. Expected robot poses X_BE (end-effector in base, OpenCV's "
            "gripper→base) and camera poses X_CT (target in camera, OpenCV's target→camera)")
    ax_A, ax_B = _axis_spread(rv_A, th_A), _axis_spread(rv_B, th_B)
    if min(ax_A, ax_B) < MIN_AXIS_ANGLE:
        raise ValueError(
            f"all rotation axes of the {K} motions are (near-)parallel: every axis lies within "
            f"{np.degrees(ax_B):.3f}° (robot, B) / {np.degrees(ax_A):.3f}° (camera, A) of their "
            f"common direction, below {np.degrees(MIN_AXIS_ANGLE):.3g}°; the hand-eye rotation "
            "about that axis (and the translation along it) is then undetermined — add a "
            "motion rotating about a different axis")


def _solve(A: list, B: list, method: str, label: Callable[[int], str],
           min_angle: float, guard: bool = True) -> np.ndarray:
    A, B = np.array(A, dtype=float), np.array(B, dtype=float)
    _check_motions(A, B, label, min_angle)
    # Numerically degenerate input (e.g. subnormal translations) may overflow inside a solver;
    # that is detected on the result and reported, not warned about.
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        X_CE = _tsai(A, B, guard) if method == "tsai" else _SOLVERS[method](A, B)
    if not np.all(np.isfinite(X_CE)):
        raise ValueError(f"{method}: numerically degenerate motions, the solution is not finite")
    return X_CE


# ---------------------------------------------------------------------------------------------
# Public API.

def solve_ax_xb(A_list, B_list, method: str = "daniilidis", orthonormalize_inputs: bool = False,
                min_angle: float = MIN_ROTATION_ANGLE, singularity_guard: bool = True
                ) -> np.ndarray:
    """Solves A_k X = X B_k for the hand-eye X = X_CE (pose of E in C) with a classical method.

    Args:
        A_list: K ≥ 2 camera motions A_k = X_{C(i)C(j)} (4×4 arrays or RigidTransform), e.g. the
            first output of ``linear_model.relative_motions``.
        B_list: the K matching end-effector motions B_k = X_{E(i)E(j)}.
        method: one of ``METHODS`` (see the module docstring).
        orthonormalize_inputs: by default every motion must be rigid (rotation block orthonormal
            within ``validation.ROTATION_TOLERANCE`` = 1e-5). Camera motions measured under the
            paper's noise model (additive noise on the matrix coefficients) are not: project
            them first (``orthonormalize``), or pass True to have every rotation block projected
            on SO(3) with the SVD.
        min_angle: smallest accepted rotation angle (rad) of any A_k or B_k.
        singularity_guard: "tsai" refuses a hand-eye rotation near 180° (its tan(θ/2)
            parametrization is singular there: above 170° its rotation must agree with Park's
            within 0.05°, and its rotation equation must fit as well as Park's); False reproduces
            the published algorithm, wrong results included (the paper reproduction uses it).

    Returns:
        X_CE as a 4×4 numpy array (rigid).

    Raises:
        ValueError: unknown method; malformed, non-finite or (without orthonormalize_inputs)
            non-rigid motions; lists of different lengths; fewer than 2 motions; a motion
            rotating less than ``min_angle``; all rotation axes (near-)parallel; rotation angles
            of A_k and B_k grossly different for every k; "tsai" near its 180° singularity.
    """
    method = _check_method(method)
    min_angle = check_positive(min_angle, "min_angle")
    A = as_transform_list(A_list, "A_list", rigid=not orthonormalize_inputs)
    B = as_transform_list(B_list, "B_list", rigid=not orthonormalize_inputs)
    check_same_length(A, "A_list", B, "B_list")
    if orthonormalize_inputs:
        A, B = _project_rotations(A, "A_list"), _project_rotations(B, "B_list")
    return _solve(A, B, method, lambda k: f"motion {k} (A_list[{k}], B_list[{k}])", min_angle,
                  bool(singularity_guard))


def calibrate_hand_eye(X_BE_list, X_CT_list, method: str = "daniilidis", pairs: str = "all",
                       orthonormalize_inputs: bool = False,
                       min_angle: float = MIN_ROTATION_ANGLE) -> np.ndarray:
    """Hand-eye calibration with ``cv2.calibrateHandEye``'s conventions: returns X_EC.

    Drop-in for OpenCV: its (R_gripper2base, t_gripper2base) are X_BE, (R_target2cam,
    t_target2cam) are X_CT, and its output (R_cam2gripper, t_cam2gripper) is X_EC (camera C in
    end-effector E) = inv(X_CE). The target must stay fixed in the robot base.

    Args:
        X_BE_list: K end-effector poses in the robot base (4×4 arrays or RigidTransform).
        X_CT_list: K target poses in the camera, sampled at the same instants.
        method: one of ``METHODS``.
        pairs: "all" (default, what OpenCV does — checked in calibration_handeye.cpp): one motion
            per sample pair i < j, A = X_{CjCi} = X_CT[j] X_CT[i]⁻¹, B = X_{EjEi} =
            X_BE[j]⁻¹ X_BE[i], in OpenCV's order, so identical formulations give OpenCV's result
            to rounding. "consecutive": the K−1 motions of ``linear_model.relative_motions``
            (samples k−1 → k), the paper's convention; fewer, independent motions.
        orthonormalize_inputs: project the rotation blocks of X_CT on SO(3) (SVD) instead of
            requiring them rigid (see ``solve_ax_xb``).
        min_angle: smallest accepted rotation angle (rad) of any motion; with pairs="all" two
            samples with (nearly) the same orientation therefore raise.

    Returns:
        X_EC as a 4×4 numpy array.

    Raises:
        ValueError: as ``solve_ax_xb`` (errors name the samples of the offending motion), plus
            unknown ``pairs`` and fewer than 3 samples (2 motions are needed).
    """
    method = _check_method(method)
    if pairs not in PAIRS:
        raise ValueError(f"pairs: expected one of {PAIRS}, got {pairs!r}")
    min_angle = check_positive(min_angle, "min_angle")
    X_BE = as_transform_list(X_BE_list, "X_BE_list", rigid=True)
    X_CT = as_transform_list(X_CT_list, "X_CT_list", rigid=not orthonormalize_inputs)
    check_same_length(X_BE, "X_BE_list", X_CT, "X_CT_list")
    if len(X_BE) < 3:
        raise ValueError(f"X_BE_list, X_CT_list: need at least 3 samples (2 motions with "
                         f"non-parallel rotation axes), got {len(X_BE)}")
    if orthonormalize_inputs:
        X_CT = _project_rotations(X_CT, "X_CT_list")
    if pairs == "consecutive":
        A, B = relative_motions(X_BE, X_CT)
        index = [(k - 1, k) for k in range(1, len(X_BE))]
    else:
        index = [(i, j) for i in range(len(X_BE)) for j in range(i + 1, len(X_BE))]
        A = [X_CT[j] @ inverse(X_CT[i]) for i, j in index]
        B = [inverse(X_BE[j]) @ X_BE[i] for i, j in index]
    X_CE = _solve(A, B, method, lambda k: f"motion between samples {index[k][0]} and "
                  f"{index[k][1]} of X_BE_list/X_CT_list", min_angle)
    return inverse(X_CE)

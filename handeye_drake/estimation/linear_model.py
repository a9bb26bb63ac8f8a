"""Relative motions and the paper's linear model of AX = XB (docs/method.md §2–§3).

Frames: the robot reports ``X_BE`` (end-effector E in robot base B, OpenCV's "gripper→base"), the
camera measures ``X_CT`` (target T in camera C, OpenCV's "target→camera"). Between samples k−1 and
k the camera moves by A_k = X_{C(k−1)C(k)} and the end-effector by B_k = X_{E(k−1)E(k)}; then
A_k X = X B_k holds for the paper's X = ``X_CE`` (pose of E in C).
"""

from __future__ import annotations

import numpy as np

from .validation import as_transform, as_transform_list, check_same_length

_I3, _I9 = np.eye(3), np.eye(9)
_I3.flags.writeable = _I9.flags.writeable = False


def relative_motions(X_BE_list, X_CT_list, rigid_camera: bool = True):
    """Camera and robot motions between consecutive samples.

    Args:
        X_BE_list: K ≥ 2 poses of the end-effector in the robot base (4×4 or RigidTransform).
        X_CT_list: K poses of the target in the camera, sampled at the same instants.
        rigid_camera: with False, camera poses may have non-orthonormal rotation blocks (the
            paper's additive coefficient noise); they are then inverted as general matrices.

    Returns:
        (A_list, B_list): K−1 camera motions A_k = X_{C(k−1)C(k)} = X_CT[k−1] X_CT[k]⁻¹ and robot
        motions B_k = X_{E(k−1)E(k)} = X_BE[k−1]⁻¹ X_BE[k], as 4×4 arrays, with A_k X_CE = X_CE B_k.
    """
    X_BE = as_transform_list(X_BE_list, "X_BE_list", rigid=True, min_length=2)
    X_CT = as_transform_list(X_CT_list, "X_CT_list", rigid=rigid_camera, min_length=2)
    check_same_length(X_BE, "X_BE_list", X_CT, "X_CT_list")
    if not rigid_camera:
        for i, X in enumerate(X_CT):
            if abs(np.linalg.det(X[:3, :3])) < 1e-9:
                raise ValueError(f"X_CT_list[{i}]: rotation block is singular, cannot be inverted")
    with np.errstate(over="ignore", invalid="ignore"):
        A_list, B_list = relative_motions_unchecked(np.array(X_BE), np.array(X_CT))
    for name, motions in (("X_CT_list", A_list), ("X_BE_list", B_list)):
        for k, M in enumerate(motions):
            if not np.all(np.isfinite(M)):
                raise ValueError(f"{name}[{k}], {name}[{k + 1}]: the motion between them "
                                 "overflows (translations too large?)")
    return list(A_list), list(B_list)


def relative_motions_unchecked(X_BE: np.ndarray, X_CT: np.ndarray):
    """``relative_motions`` on validated (K, 4, 4) stacks, vectorized: (A (K−1, 4, 4),
    B (K−1, 4, 4)). Camera poses are inverted as general matrices, so measured rotation blocks
    need not be orthonormal."""
    A = X_CT[:-1] @ np.linalg.inv(X_CT[1:])
    R, p = X_BE[:-1, :3, :3], X_BE[:-1, :3, 3]
    B = np.einsum("kji,kjl->kil", R, X_BE[1:, :3, :])  # R_{k-1}ᵀ [R_k | p_k]
    B[:, :, 3] -= np.einsum("kji,kj->ki", R, p)
    B = np.concatenate([B, np.broadcast_to([0.0, 0.0, 0.0, 1.0], (len(B), 1, 4))], axis=1)
    return A, B


def linear_system_matrices(A: np.ndarray, B: np.ndarray):
    """``linear_system`` without input checks, for inner loops on already-validated arrays."""
    R_A, t_A = A[:3, :3], A[:3, 3]
    R_B, t_B = B[:3, :3], B[:3, 3]
    C = np.zeros((12, 12))
    # I9 − R_A ⊗ R_B (the Kronecker product's entries, without np.kron's overhead)
    C[:9, :9] = _I9 - (R_A[:, None, :, None] * R_B[None, :, None, :]).reshape(9, 9)
    C[9, 0:3] = t_B  # I3 ⊗ t_Bᵀ
    C[10, 3:6] = t_B
    C[11, 6:9] = t_B
    C[9:, 9:] = _I3 - R_A
    y = np.zeros(12)
    y[9:] = t_A
    return C, y


def linear_system(A, B):
    """The paper's linear measurement model C x = y of one motion pair (docs/method.md §3).

    x = [i; j; k; t_X] stacks the rows of R_X (row-major vec) and t_X, for X = X_CE.

        C = | I9 − R_A ⊗ R_B      0       |,   y = | 0_9 |
            | I3 ⊗ t_Bᵀ        I3 − R_A   |        | t_A |

    Args:
        A: camera motion X_{C(k−1)C(k)} (4×4; its rotation block may be non-orthonormal, as under
            the paper's noise model).
        B: robot motion X_{E(k−1)E(k)} (4×4 rigid).

    Returns:
        (C, y): a 12×12 matrix and a 12-vector.
    """
    A = as_transform(A, "A", rigid=False)
    B = as_transform(B, "B", rigid=True)
    return linear_system_matrices(A, B)


def state_from_transform(X_CE) -> np.ndarray:
    """The 12-vector x = [vec_row(R_X); t_X] of X = X_CE."""
    X = np.asarray(X_CE, dtype=float)
    return np.concatenate([X[:3, :3].reshape(9), X[:3, 3]])

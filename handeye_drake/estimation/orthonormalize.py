"""Projection of an estimated 3×3 block onto SO(3) (docs/method.md §6).

The filter state keeps the 9 rotation coefficients unconstrained; they are projected outside the
filter loop. Three projections are offered:

- ``"svd"``: the orthogonal Procrustes solution U diag(1, 1, det(UVᵀ)) Vᵀ, the nearest rotation in
  Frobenius norm.
- ``"qr"``: Gram–Schmidt in its stable (Householder QR) form: keeps the direction of the first
  column exactly, so it is not the nearest rotation.
- ``"horn"``: Horn's quaternion minimization: the unit quaternion maximizing tr(Rᵀ M) is the
  eigenvector of the largest eigenvalue of a symmetric 4×4 matrix. It reaches the same optimum as
  SVD in exact arithmetic, through a symmetric eigenproblem that needs no sign repair.
"""

from __future__ import annotations

import numpy as np

from .validation import as_matrix

METHODS = ("svd", "qr", "horn")


def _svd(M):
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return U @ D @ Vt


def _qr(M):
    Q, R = np.linalg.qr(M)
    # Make diag(R) positive so Q's columns point like M's, then repair a reflection on the last.
    Q = Q * np.sign(np.where(np.diag(R) == 0, 1.0, np.diag(R)))
    if np.linalg.det(Q) < 0:
        Q[:, 2] = -Q[:, 2]
    return Q


def horn_matrix(M) -> np.ndarray:
    """Symmetric 4×4 N with qᵀ N q = tr(R(q)ᵀ M) for unit quaternions q = [w, x, y, z]."""
    S = np.asarray(M, dtype=float).T  # tr(Rᵀ M) = tr(R S) with S = Mᵀ, Horn's form.
    Sxx, Sxy, Sxz = S[0]
    Syx, Syy, Syz = S[1]
    Szx, Szy, Szz = S[2]
    return np.array([
        [Sxx + Syy + Szz, Syz - Szy, Szx - Sxz, Sxy - Syx],
        [Syz - Szy, Sxx - Syy - Szz, Sxy + Syx, Szx + Sxz],
        [Szx - Sxz, Sxy + Syx, -Sxx + Syy - Szz, Syz + Szy],
        [Sxy - Syx, Szx + Sxz, Syz + Szy, -Sxx - Syy + Szz],
    ])


def _horn(M):
    w, V = np.linalg.eigh(horn_matrix(M))
    q0, q1, q2, q3 = V[:, np.argmax(w)]
    return np.array([
        [q0**2 + q1**2 - q2**2 - q3**2, 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)],
        [2 * (q2 * q1 + q0 * q3), q0**2 - q1**2 + q2**2 - q3**2, 2 * (q2 * q3 - q0 * q1)],
        [2 * (q3 * q1 - q0 * q2), 2 * (q3 * q2 + q0 * q1), q0**2 - q1**2 - q2**2 + q3**2],
    ])


def orthonormalize_unchecked(M: np.ndarray, method: str = "svd") -> np.ndarray:
    """``orthonormalize`` without input checks (inner loops on validated, full-rank input)."""
    if method == "svd":
        return _svd(M)
    if method == "qr":
        return _qr(M)
    return _horn(M)


def orthonormalize(M, method: str = "svd") -> np.ndarray:
    """Nearest proper rotation (det = +1) to a full-rank 3×3 matrix with det > 0.

    Args:
        M: a 3×3 array (e.g. the rows i, j, k of R_X from the filter state, stacked).
        method: "svd", "qr" or "horn" (see the module docstring).

    Raises:
        ValueError: unknown method, wrong shape, non-finite or rank-deficient M, or a reflection
            (det M < 0): the "nearest rotation" of a reflection flips an axis arbitrarily (for
            diag(1, 1, −1) it is the identity), which would turn a mirrored frame into a
            confident wrong answer.
    """
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    M = as_matrix(M, "M", (3, 3))
    scale = float(np.abs(M).max())
    if scale == 0.0:
        raise ValueError("M: the zero matrix has no nearest rotation")
    M = M / scale  # the projection is scale-invariant; this keeps every product finite
    s = np.linalg.svd(M, compute_uv=False)
    if s[2] / s[0] < 1e-12:
        raise ValueError(f"M: rank-deficient 3×3 matrix (relative singular values "
                         f"{(s / s[0]).tolist()}), no unique nearest rotation")
    det = float(np.linalg.det(M))
    if det < 0:
        raise ValueError("M: a reflection (det < 0), not a (noisy) rotation: a mirrored axis "
                         "(right- vs left-handed frame, or a flipped sign) in the data?")
    return orthonormalize_unchecked(M, method)

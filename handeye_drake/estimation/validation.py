"""Input checking shared by every public entry point.

Every check raises ``ValueError`` naming the argument and what is wrong, so bad data never turns
into a NaN or a silently wrong estimate downstream. Nothing here imports Drake: a
``pydrake.math.RigidTransform`` is recognised by duck typing (``GetAsMatrix4``).
"""

from __future__ import annotations

import numpy as np

from .defaults import MAX_MAGNITUDE, MAX_POSE_MAGNITUDE, ROTATION_TOLERANCE  # noqa: F401


def as_matrix(value, name: str, shape: tuple[int, ...]) -> np.ndarray:
    """Returns ``value`` as a finite float array of ``shape`` or raises ValueError."""
    try:
        M = np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError) as e:
        raise ValueError(f"{name}: expected a numeric array of shape {shape}, got "
                         f"{type(value).__name__} ({e})") from None
    if M.shape != tuple(shape):
        raise ValueError(f"{name}: expected shape {tuple(shape)}, got {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return M


def rotation_defect(R: np.ndarray) -> float:
    """max(‖RᵀR − I‖_F, |det R − 1|): zero for an exact rotation."""
    return float(max(np.linalg.norm(R.T @ R - np.eye(3)), abs(np.linalg.det(R) - 1.0)))


def check_rotation(R, name: str, tol: float = ROTATION_TOLERANCE) -> np.ndarray:
    """Returns R as a 3×3 array after checking it is a proper rotation (within ``tol``)."""
    R = as_matrix(R, name, (3, 3))
    defect = rotation_defect(R)
    if defect > tol:
        raise ValueError(
            f"{name}: not a rotation matrix (max(‖RᵀR − I‖, |det R − 1|) = {defect:.3g} > "
            f"tolerance {tol:g}); det = {np.linalg.det(R):.6g}")
    return R


def as_transform(X, name: str, rigid: bool = True, tol: float = ROTATION_TOLERANCE) -> np.ndarray:
    """Returns a pose as a 4×4 homogeneous numpy array.

    Accepts a 4×4 array-like or a ``pydrake.math.RigidTransform``. The last row must be
    [0, 0, 0, 1]. With ``rigid=True`` the 3×3 block must be a proper rotation within ``tol``;
    with ``rigid=False`` any finite 3×3 block is accepted (the paper's camera-noise model adds
    noise to the rotation coefficients, so a measured camera motion need not be orthonormal).
    """
    if hasattr(X, "GetAsMatrix4"):
        X = X.GetAsMatrix4()
    M = as_matrix(X, name, (4, 4))
    big = float(np.abs(M).max())
    if big > MAX_POSE_MAGNITUDE:
        raise ValueError(f"{name}: entries up to {big:.3g} are implausibly large for a pose "
                         f"(limit {MAX_POSE_MAGNITUDE:g}; wrong units?)")
    if not rigid and np.abs(M[:3, :3]).max() > 10.0:
        raise ValueError(f"{name}: rotation block has entries up to "
                         f"{np.abs(M[:3, :3]).max():.3g}, not a (noisy) rotation")
    if np.abs(M[3] - [0.0, 0.0, 0.0, 1.0]).max() > 1e-9:
        raise ValueError(f"{name}: last row of a homogeneous transform must be [0, 0, 0, 1], "
                         f"got {M[3].tolist()}")
    if rigid:
        check_rotation(M[:3, :3], f"{name} (rotation block)", tol)
    return M


def as_transform_list(Xs, name: str, rigid: bool = True, min_length: int = 0) -> list[np.ndarray]:
    """Validates a sequence of poses (see ``as_transform``); element errors name the index."""
    if isinstance(Xs, np.ndarray) and Xs.ndim != 3:
        raise ValueError(f"{name}: expected a sequence of 4×4 transforms, got an array of shape "
                         f"{Xs.shape}")
    if isinstance(Xs, (str, bytes)) or hasattr(Xs, "GetAsMatrix4"):
        raise ValueError(f"{name}: expected a sequence of 4×4 transforms, got "
                         f"{type(Xs).__name__}")
    try:
        items = list(Xs)
    except TypeError:
        raise ValueError(f"{name}: expected a sequence of 4×4 transforms, got "
                         f"{type(Xs).__name__}") from None
    if len(items) < min_length:
        raise ValueError(f"{name}: needs at least {min_length} poses, got {len(items)}")
    return [as_transform(X, f"{name}[{i}]", rigid=rigid) for i, X in enumerate(items)]


def check_same_length(a: list, a_name: str, b: list, b_name: str) -> None:
    if len(a) != len(b):
        raise ValueError(f"{a_name} and {b_name} must have the same length, got {len(a)} and "
                         f"{len(b)}")


def check_positive(value, name: str, allow_zero: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        bound = "≥ 0" if allow_zero else "> 0"
        raise ValueError(f"{name}: must be finite and {bound}, got {value!r}")
    if v > MAX_MAGNITUDE:
        # Squares (variances) of larger values overflow to inf.
        raise ValueError(f"{name}: {value!r} is too large (must be ≤ {MAX_MAGNITUDE:g})")
    return v


def check_covariance(P, name: str, n: int) -> np.ndarray:
    """An n×n symmetric positive semi-definite matrix (scalars and length-n diagonals allowed)."""
    P = np.array(P, dtype=float) if not np.isscalar(P) else np.array(P, dtype=float)
    if P.ndim == 0:
        P = float(check_positive(P, name, allow_zero=True)) * np.eye(n)
    elif P.ndim == 1:
        P = as_matrix(P, name, (n,))
        if np.any(P < 0):
            raise ValueError(f"{name}: diagonal variances must be ≥ 0, got min {P.min():g}")
        P = np.diag(P)
    P = as_matrix(P, name, (n, n))
    if not np.allclose(P, P.T, rtol=1e-9, atol=1e-12 * max(1.0, np.abs(P).max())):
        raise ValueError(f"{name}: covariance must be symmetric")
    min_eig = np.linalg.eigvalsh(0.5 * (P + P.T)).min()
    if min_eig < -1e-9 * max(1.0, np.abs(P).max()):
        raise ValueError(f"{name}: covariance must be positive semi-definite, smallest "
                         f"eigenvalue {min_eig:.3g}")
    return 0.5 * (P + P.T)


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
    """Returns a pose as a 4×4 homogeneous numpy array (a new array: later changes of the
    caller's ``X`` do not reach it).

    Accepts a 4×4 array-like or a ``pydrake.math.RigidTransform``. The last row must be
    [0, 0, 0, 1]. With ``rigid=True`` the 3×3 block must be a proper rotation within ``tol``;
    with ``rigid=False`` any finite 3×3 block is accepted (the paper's camera-noise model adds
    noise to the rotation coefficients, so a measured camera motion need not be orthonormal).
    """
    if hasattr(X, "GetAsMatrix4"):
        X = X.GetAsMatrix4()
    # Fast path for what nearly every caller passes (a float 4×4 array): one copy, then the
    # checks on Python floats; anything unusual takes the detailed path, which says what is wrong.
    if type(X) is np.ndarray and X.shape == (4, 4):
        try:
            M = np.array(X, dtype=float)
        except (TypeError, ValueError, OverflowError):
            M = None
        if M is not None and _plausible_transform(M.tolist(), rigid, tol):
            return M
    return _as_transform_checked(X, name, rigid, tol)


def _plausible_transform(m: list, rigid: bool, tol: float) -> bool:
    """True when the 4×4 nested list passes every check of ``as_transform`` (no message)."""
    r0, r1, r2, r3 = m
    if r3 != [0.0, 0.0, 0.0, 1.0] and not (
            abs(r3[0]) <= 1e-9 and abs(r3[1]) <= 1e-9 and abs(r3[2]) <= 1e-9
            and abs(r3[3] - 1.0) <= 1e-9):
        return False
    for row in (r0, r1, r2):
        for v in row:  # also false for NaN
            if not abs(v) <= MAX_POSE_MAGNITUDE:
                return False
    a, b, c = r0[0], r0[1], r0[2]
    d, e, f = r1[0], r1[1], r1[2]
    g, h, i = r2[0], r2[1], r2[2]
    if not rigid:
        return max(abs(a), abs(b), abs(c), abs(d), abs(e), abs(f), abs(g), abs(h),
                   abs(i)) <= 10.0
    # max(‖RᵀR − I‖_F, |det R − 1|) ≤ tol, as rotation_defect.
    g00 = a * a + d * d + g * g - 1.0
    g11 = b * b + e * e + h * h - 1.0
    g22 = c * c + f * f + i * i - 1.0
    g01 = a * b + d * e + g * h
    g02 = a * c + d * f + g * i
    g12 = b * c + e * f + h * i
    frob2 = g00 * g00 + g11 * g11 + g22 * g22 + 2.0 * (g01 * g01 + g02 * g02 + g12 * g12)
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    # A margin keeps a matrix at the tolerance's edge on the detailed path (same verdict as
    # rotation_defect's own arithmetic).
    return frob2 <= (0.999 * tol) ** 2 and abs(det - 1.0) <= 0.999 * tol


def _as_transform_checked(X, name: str, rigid: bool, tol: float) -> np.ndarray:
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


def check_noisy_rotation(M, name: str) -> None:
    """Refuses the 3×3 rotation block of a validated transform ``M`` (4×4 or 3×3) when it is no
    noisy rotation at all: det ≤ 1e-6 (singular, or a reflection)."""
    (a, b, c), (d, e, f), (g, h, i) = (row[:3] for row in M[:3].tolist())
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    if not det > 1e-6:
        raise ValueError(f"{name}: rotation block is not a (noisy) rotation (det = {det:.3g}; a "
                         "reflection or a singular matrix — a flipped axis in the data?)")


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


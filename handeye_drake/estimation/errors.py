"""Error measures of docs/method.md §8. Both arguments must use the same convention (both X_CE or both
X_EC): the relative translation error differs between the two."""

from __future__ import annotations

import numpy as np

from .se3 import quat_wxyz, rotation_angle
from .validation import as_transform


def rotation_error_quat(X_true, X_est) -> float:
    """‖q − q̂‖ between unit quaternions, sign-safe (min over q̂ and −q̂); in [0, √2]."""
    q = quat_wxyz(as_transform(X_true, "X_true")[:3, :3])
    q_hat = quat_wxyz(as_transform(X_est, "X_est")[:3, :3])
    return float(min(np.linalg.norm(q - q_hat), np.linalg.norm(q + q_hat)))


def rotation_error_deg(X_true, X_est) -> float:
    """Angle of R_trueᵀ R_est in degrees."""
    R = as_transform(X_true, "X_true")[:3, :3]
    R_hat = as_transform(X_est, "X_est")[:3, :3]
    return float(np.degrees(rotation_angle(R.T @ R_hat)))


def translation_error_rel(X_true, X_est) -> float:
    """‖t − t̂‖ / ‖t‖ (dimensionless). Raises ValueError when ‖t‖ = 0 (undefined)."""
    t = as_transform(X_true, "X_true")[:3, 3]
    t_hat = as_transform(X_est, "X_est")[:3, 3]
    norm = np.linalg.norm(t)
    if norm < 1e-12:
        raise ValueError("X_true: translation is zero, the relative translation error is "
                         "undefined; compare absolute translations instead")
    return float(np.linalg.norm(t - t_hat) / norm)

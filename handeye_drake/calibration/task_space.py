"""Uncertainty where a user acts: the σ (m) of points located through the calibrated transform."""

from __future__ import annotations

import numpy as np

from ..estimation.reprojection import point_sigma

#: Distance (m) in front of the camera of the point whose σ is reported.
POINT_DISTANCE = 0.5


def task_sigmas(mode: str, X_H, covariance, X_R=None) -> dict:
    """σ (m, RMS radius) of points a user acts on, from the hand-eye covariance: a point
    ``POINT_DISTANCE`` in front of the camera, and the tool-centre point (the flange origin; for
    eye-to-hand at the mean flange position of the robot-side poses ``X_R``) as located through
    the result."""
    X_H = np.asarray(X_H, float)
    p_front = X_H[:3, :3] @ np.array([0.0, 0.0, POINT_DISTANCE])
    if mode == "eye_in_hand":
        p_tcp = np.zeros(3)
    else:
        p_tcp = np.zeros(3) if X_R is None else np.mean(
            np.linalg.inv(np.asarray(X_R, float))[:, :3, 3], axis=0)
    return {"point_in_front_m": point_sigma(covariance, p_front),
            "point_in_front_distance_m": POINT_DISTANCE,
            # The tool point as the camera locates it: at p_C = R̂ᵀ (p_tcp − t̂) in C, so the
            # rotated point to pass is p_tcp − t̂ (its sign sets the rotation–translation term).
            "tool_centre_point_m": point_sigma(covariance, p_tcp - X_H[:3, 3]),
            "definition": "RMS radius (√trace of the 3×3 covariance) of the point's position "
                          "error through the calibrated transform"}


__all__ = ["POINT_DISTANCE", "task_sigmas"]

"""Names, plausibility bounds and small helpers shared by the calibration stages (kept apart so that the fit and
the checks need not import each other)."""

from __future__ import annotations

import numpy as np

#: Largest plausible hand-eye translation (m) per mode: a camera on the flange is close to it;
#: a camera in the cell is within a few metres of the robot base.
DEFAULT_MAX_HAND_EYE_DISTANCE = {"eye_in_hand": 0.5, "eye_to_hand": 5.0}


def hand_name(mode: str) -> str:
    """The hand-eye unknown of the mode: X_EC (eye-in-hand) or X_BC (eye-to-hand)."""
    return "X_EC" if mode == "eye_in_hand" else "X_BC"


def fixed_name(mode: str) -> str:
    """The pose fixed in the other robot frame: X_BT (eye-in-hand) or X_ET (eye-to-hand)."""
    return "X_BT" if mode == "eye_in_hand" else "X_ET"


def tangent_std(covariance) -> tuple[np.ndarray, np.ndarray]:
    """(rotation std (deg), translation std (m)) per axis of a 6×6 error covariance."""
    d = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    return np.degrees(d[:3]), d[3:]


__all__ = ["DEFAULT_MAX_HAND_EYE_DISTANCE", "fixed_name", "hand_name", "tangent_std"]

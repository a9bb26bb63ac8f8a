"""Vision: pinhole camera model, point-feature interaction matrices and the IBVS law (numpy only,
no Drake import). The Drake systems using them are ``handeye_drake.systems.camera`` and
``handeye_drake.systems.servo``."""

from .camera_model import (
    MIN_DEPTH,
    POSE_NOISE_MODELS,
    CameraIntrinsics,
    apply_pose_noise,
    SelfCalibrationMotion,
    default_self_calibration_motions,
    end_effector_interaction_matrix,
    ibvs_twist,
    normalized_from_pixels,
    pixel_interaction_matrix,
    point_interaction_matrix,
    project_points,
    saturate_twist,
    target_visibility,
)

__all__ = [
    "MIN_DEPTH",
    "POSE_NOISE_MODELS",
    "CameraIntrinsics",
    "apply_pose_noise",
    "SelfCalibrationMotion",
    "default_self_calibration_motions",
    "end_effector_interaction_matrix",
    "ibvs_twist",
    "normalized_from_pixels",
    "pixel_interaction_matrix",
    "point_interaction_matrix",
    "project_points",
    "saturate_twist",
    "target_visibility",
]

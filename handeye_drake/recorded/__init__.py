"""Reading recorded robot and camera data, aligning it in time and forming motion pairs (the
library under ``handeye_drake.apps.calibrate``).

- ``formats``: readers of TUM, CSV-matrix and OpenCV-YAML pose files into validated
  ``PoseStream``s (robot: X_BE, end-effector in base; camera: X_CT, target in camera);
- ``align``: SLERP/linear interpolation of the robot pose at the camera instants and estimation of
  the constant clock offset between the streams;
- ``selection``: motion pairs (consecutive + wide), screw-angle and residual outlier rejection,
  classical solution with held-out validation, bootstrap covariance;
- ``example``: the generator of the shipped example recording (``handeye_drake/data``).

Nothing here imports Drake.
"""

from .align import (
                    AlignedSamples,
                    PoseInterpolator,
                    TimeOffsetEstimate,
                    UnobservableTimeOffset,
                    align_streams,
                    estimate_time_offset,
                    interpolate_poses,
)
from .formats import (
                    FORMATS,
                    PoseStream,
                    parse_csv_matrix,
                    parse_opencv_yaml,
                    parse_poses,
                    parse_tum,
                    pose_stream,
                    read_poses,
)
from .selection import (
                    InconsistentMotions,
                    MotionPairs,
                    RobustFit,
                    form_pairs,
                    pair_residuals,
                    robust_hand_eye,
)

__all__ = [
    "FORMATS",
    "AlignedSamples",
    "InconsistentMotions",
    "MotionPairs",
    "PoseInterpolator",
    "PoseStream",
    "RobustFit",
    "TimeOffsetEstimate",
    "UnobservableTimeOffset",
    "align_streams",
    "estimate_time_offset",
    "form_pairs",
    "interpolate_poses",
    "pair_residuals",
    "parse_csv_matrix",
    "parse_opencv_yaml",
    "parse_poses",
    "parse_tum",
    "pose_stream",
    "read_poses",
    "robust_hand_eye",
]

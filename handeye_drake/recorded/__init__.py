"""Reading recorded robot and camera data, aligning it in time, forming motion pairs, and writing
the result where a robot cell uses it (the library under ``handeye_drake.apps.calibrate``).

- ``formats``: readers of TUM, CSV-matrix and OpenCV-YAML pose files into validated
  ``PoseStream``s (robot: X_BE, end-effector in base; camera: X_CT, target in camera);
- ``bags``: robot (tf), camera (pose topic or tf) streams, images and CameraInfo from ROS 1/2
  bags without ROS (``read_bag``; ``iter_images`` streams an image topic one image at a time);
- ``align``: SLERP/linear interpolation of the robot pose at the camera instants and estimation of
  the constant clock offset between the streams;
- ``selection``: motion pairs (consecutive + wide), screw-angle and residual outlier rejection,
  classical solution with held-out validation, bootstrap covariance;
- ``exports``: the result as URDF/xacro, a ROS 2 launch file and command, Drake model directives
  and CameraConfig, JSON and TUM (``export_calibration``);
- ``example``: the generator of the shipped example recording (``handeye_drake/data``);
  ``example_bag``: the shipped example images as a ROS 1/2 bag (tf, images, CameraInfo).

Nothing here imports Drake.
"""

from .align import (AlignedSamples, PoseInterpolator, TimeOffsetEstimate, UnobservableTimeOffset,
                    align_streams, estimate_time_offset, interpolate_poses)
from .bags import BagData, BagImage, CameraInfo, iter_images, read_bag
from .exports import export_calibration
from .formats import (FORMATS, PoseStream, parse_csv_matrix, parse_opencv_yaml, parse_poses,
                      parse_tum, pose_stream, read_poses)
from .selection import (InconsistentMotions, MotionPairs, RobustFit, form_pairs, pair_residuals,
                        robust_hand_eye)

__all__ = [
    "FORMATS",
    "AlignedSamples",
    "BagData",
    "BagImage",
    "CameraInfo",
    "InconsistentMotions",
    "MotionPairs",
    "PoseInterpolator",
    "PoseStream",
    "RobustFit",
    "TimeOffsetEstimate",
    "UnobservableTimeOffset",
    "align_streams",
    "estimate_time_offset",
    "export_calibration",
    "form_pairs",
    "interpolate_poses",
    "iter_images",
    "pair_residuals",
    "parse_csv_matrix",
    "parse_opencv_yaml",
    "parse_poses",
    "parse_tum",
    "pose_stream",
    "read_bag",
    "read_poses",
    "robust_hand_eye",
]

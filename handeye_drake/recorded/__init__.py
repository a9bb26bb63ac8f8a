"""Reading recorded robot and camera data and writing the result where a robot cell uses it: the
file and bag I/O of the calibration library (``handeye_drake.calibration``), no estimation.

- ``formats``: readers of TUM, CSV-matrix and OpenCV-YAML pose files into validated
  ``PoseStream``s (robot: X_BE, end-effector in base; camera: X_CT, target in camera);
- ``bags``: robot (tf), camera (pose topic or tf) streams, images and CameraInfo from ROS 1/2
  bags without ROS (``read_bag``; ``iter_images`` streams an image topic one image at a time);
- ``exports``: the result as URDF/xacro, a ROS 2 launch file and command, Drake model directives
  and CameraConfig, JSON and TUM (``export_calibration``);
- ``example``: the generator of the shipped example recording (``handeye_drake/data``);
  ``example_bag``: the shipped example images as a ROS 1/2 bag (tf, images, CameraInfo).

Nothing here imports Drake.
"""

from .bags import BagData, BagImage, CameraInfo, iter_images, read_bag
from .exports import export_calibration
from .formats import (FORMATS, PoseStream, parse_csv_matrix, parse_opencv_yaml, parse_poses,
                      parse_tum, pose_stream, read_poses)

__all__ = [
    "FORMATS",
    "BagData",
    "BagImage",
    "CameraInfo",
    "PoseStream",
    "export_calibration",
    "iter_images",
    "parse_csv_matrix",
    "parse_opencv_yaml",
    "parse_poses",
    "parse_tum",
    "pose_stream",
    "read_bag",
    "read_poses",
]

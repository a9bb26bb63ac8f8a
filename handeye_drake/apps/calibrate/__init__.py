"""``handeye-drake calibrate``: hand-eye calibration of a real robot from recorded data.

- ``inputs``: pose files, ROS bags (pose topics, tf, or images of a target), or image files of a
  target paired with robot poses, as streams;
- ``pipeline``: ``calibrate_streams`` — alignment, classical start, maximum likelihood on the raw
  poses, hold-out;
- ``checks``: the verdict (OK / WARN / FAIL) and the usual mistakes tried as alternatives;
- ``report``: the printed table and ``calibration.json``; ``online``: the replay through the
  paper's filter; ``command``: the command line.
"""

from .command import add_parser, run_calibrate_command
from .inputs import Streams, bag_image_streams, bag_streams, file_streams, image_streams
from .pipeline import CalibrationResult, calibrate_streams
from .report import table, to_dict, write_json


def calibrate_files(robot_path, camera_path, fmt=None, camera_in_target: bool = False,
                    translation_scale: float = 1.0, **kwargs) -> CalibrationResult:
    """``calibrate_streams`` on two pose files (``file_streams`` reads them; extra keyword
    arguments go to ``calibrate_streams``)."""
    s = file_streams(robot_path, camera_path, fmt, camera_in_target, translation_scale,
                     translation_scale)
    result = calibrate_streams(s.robot, s.camera, quaternion_streams=s.quaternion_streams,
                               **kwargs)
    result.inputs = s.inputs
    return result


__all__ = ["CalibrationResult", "Streams", "add_parser", "bag_image_streams", "bag_streams",
           "calibrate_files", "calibrate_streams", "file_streams", "image_streams",
           "run_calibrate_command", "table", "to_dict", "write_json"]

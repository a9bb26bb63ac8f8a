"""The calibration of a real robot cell, as a library: ``calibrate(robot, camera | images | bag,
options) -> CalibrationResult`` (``api``), and each stage in the order the data flows:

- ``inputs``: pose files, ROS bags (pose topics, tf, or images of a target), image files of a
  target, read into ``Streams`` (robot X_BE, camera X_CT; the detections of image inputs);
- ``align``: the robot pose interpolated at each camera instant; the clock offset estimated;
- ``pipeline``: ``calibrate_streams`` — motion-pair selection and a classical start
  (``estimation.selection``), maximum likelihood on the raw poses, hold-out, split-half, the
  robot's accuracy, observability;
- ``corners``: for image inputs, the corner-level maximum likelihood over every image with the
  intrinsics refined as chosen, and the pixel-level checks;
- ``checks``: the verdict (OK / WARN / FAIL) with the usual mistakes tried as alternatives;
  ``changepoint``: a move of the target or of the camera during the recording;
- ``session``: ``CalibrationSession``, a live calibration — samples one by one, the next pose,
  stop when σ reaches a target with verdict OK;
- ``online``: the replay through the on-line filters; ``task_space``: σ where a user acts;
- ``report``: the text summary and ``calibration.json``; ``compare``: two calibrations of one
  mount (consistent, or the mount moved).

Nothing here imports ``handeye_drake.apps`` or Drake; ``handeye-drake calibrate`` is this
library with a command line.
"""

from .api import (DEFAULT_ROBOT_ACCURACY, CalibrationOptions, calibrate, calibrate_files,
                  read_inputs, solve)
from .checks import Reason, Verdict
from .compare import Comparison, compare
from .corners import CornerStage, calibrate_images, refine_with_corners
from .inputs import Streams, bag_image_streams, bag_streams, file_streams, image_streams
from .pipeline import CalibrationResult, calibrate_streams
from .report import table, to_dict, write_json
from .session import CalibrationSession, CandidatePoses, SessionStep

__all__ = ["CalibrationOptions", "CalibrationResult", "CalibrationSession", "CandidatePoses",
           "Comparison", "CornerStage", "DEFAULT_ROBOT_ACCURACY",
           "Reason", "Streams", "Verdict", "bag_image_streams", "bag_streams", "calibrate",
           "calibrate_files", "calibrate_images", "calibrate_streams", "compare", "file_streams",
           "image_streams", "read_inputs", "refine_with_corners", "SessionStep", "solve", "table",
           "to_dict", "write_json"]

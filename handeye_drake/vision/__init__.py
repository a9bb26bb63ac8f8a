"""Vision: pinhole camera model, point-feature interaction matrices and the IBVS law (numpy only,
no Drake import). The Drake systems using them are ``handeye_drake.systems.camera`` and
``handeye_drake.systems.servo``.

Calibration targets (spec strings, object points, printable boards) are in
``handeye_drake.vision.targets``, intrinsics files in ``handeye_drake.vision.intrinsics`` and the
OpenCV target detector in ``handeye_drake.vision.detection`` (numpy/OpenCV, no Drake)."""

from .camera_model import *  # noqa: F401,F403
from .camera_model import __all__  # noqa: F401

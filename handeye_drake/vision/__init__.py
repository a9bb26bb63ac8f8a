"""Vision: pinhole camera model, point-feature interaction matrices and the IBVS law (numpy only,
no Drake import). The Drake systems using them are ``handeye_drake.systems.camera`` and
``handeye_drake.systems.servo``."""

from .camera_model import *  # noqa: F401,F403
from .camera_model import __all__  # noqa: F401

"""Drake LeafSystems of the closed loop, one per module (see each class's docstring for ports).

    arm.py           add_arm, make_control_plant, DifferentialIkDriver, EndEffectorPoseSensor
    camera.py        HandEyeCamera
    servo.py         VisualServoController
    calibrator.py    HandEyeCalibrator
    motion_source.py PaperMotionSource
"""

from .arm import (
                  UR5E_HOME_Q,
                  UR5E_URDF,
                  DifferentialIkDriver,
                  EndEffectorPoseSensor,
                  add_arm,
                  make_control_plant,
)
from .calibrator import HandEyeCalibrator
from .camera import HandEyeCamera
from .motion_source import PaperMotionSource
from .servo import SelfCalibrationMotion, VisualServoController

__all__ = ["DifferentialIkDriver", "EndEffectorPoseSensor", "HandEyeCalibrator",
           "HandEyeCamera", "PaperMotionSource", "SelfCalibrationMotion", "UR5E_HOME_Q",
           "UR5E_URDF", "VisualServoController", "add_arm", "make_control_plant"]

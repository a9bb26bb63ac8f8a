"""Drake LeafSystems of the closed loop, one per module (see each class's docstring for ports).

    arm.py           add_arm, make_control_plant, DifferentialIkDriver, EndEffectorPoseSensor
    camera.py        HandEyeCamera
    servo.py         VisualServoController
    calibrator.py    HandEyeCalibrator
    motion_source.py PaperMotionSource
    rendered_camera.py  add_target_geometry, add_rendered_camera, mount_rendered_camera,
                        camera_config, RenderedCamera (functions: RgbdSensor + textured target)
    image_downsampler.py ImageAreaDownsampler (supersampling of rendered images)
    target_detector.py TargetDetector
"""

from .arm import (UR5E_HOME_Q, UR5E_URDF, DifferentialIkDriver, EndEffectorPoseSensor, add_arm,
                  make_control_plant)
from .calibrator import HandEyeCalibrator
from .camera import HandEyeCamera
from .image_downsampler import ImageAreaDownsampler
from .motion_source import PaperMotionSource
from .rendered_camera import (RenderedCamera, add_rendered_camera, add_target_geometry,
                              camera_config, mount_rendered_camera)
from .servo import SelfCalibrationMotion, VisualServoController
from .target_detector import TargetDetector

__all__ = ["DifferentialIkDriver", "EndEffectorPoseSensor", "HandEyeCalibrator",
           "HandEyeCamera", "ImageAreaDownsampler", "PaperMotionSource", "RenderedCamera",
           "SelfCalibrationMotion", "TargetDetector", "UR5E_HOME_Q", "UR5E_URDF",
           "VisualServoController", "add_arm", "add_rendered_camera", "add_target_geometry",
           "camera_config", "make_control_plant", "mount_rendered_camera"]

"""Drake LeafSystems of the closed loop, one per module (see each class's docstring for ports).

    arm.py           add_arm, make_control_plant, add_pose_tracking_driver (Drake's C++
                     differential-IK integrator tracking a commanded pose), DifferentialIkDriver
                     (a commanded twist), EndEffectorPoseSensor, frame_in_body
    camera.py        HandEyeCamera
    servo.py         VisualServoController
    calibrator.py    HandEyeCalibrator, add_hand_eye_calibrator (into any diagram)
    motion_source.py PaperMotionSource
    rendered_camera.py  add_target_geometry, add_rendered_camera, mount_rendered_camera,
                        camera_config, RenderedCamera (functions: RgbdSensor + textured target)
    perception_scene.py add_perception_scene_graph, PerceptionScenePoses (a render-only copy
                     of the plant's scene, posed when a camera renders, not every plant step)
    image_downsampler.py ImageAreaDownsampler (supersampling of rendered images)
    target_detector.py TargetDetector
    camera_pose.py   HandCameraPose (true X_WC of a rendered camera, for logs and Meshcat, and
                     the robot pose X_BE of the same instant)
    trigger_sampler.py CameraTriggerSampler (robot pose held from a rendered camera's trigger)
    frame_recorder.py FrameRecorder (a few rendered frames kept for pictures)
"""

from .arm import (UR5E_HOME_Q, UR5E_URDF, DifferentialIkDriver, EndEffectorPoseSensor,
                  PoseTrackingDriver, add_arm, add_pose_tracking_driver, frame_in_body,
                  make_control_plant)
from .calibrator import HandEyeCalibrator, add_hand_eye_calibrator
from .camera import HandEyeCamera
from .camera_pose import HandCameraPose
from .frame_recorder import FrameRecorder
from .image_downsampler import ImageAreaDownsampler
from .motion_source import PaperMotionSource
from .perception_scene import PerceptionScene, PerceptionScenePoses, add_perception_scene_graph
from .rendered_camera import (RenderedCamera, add_rendered_camera, add_target_geometry,
                              camera_config, mount_rendered_camera)
from .servo import SelfCalibrationMotion, VisualServoController
from .target_detector import TargetDetector
from .trigger_sampler import CameraTriggerSampler

__all__ = ["CameraTriggerSampler", "DifferentialIkDriver", "EndEffectorPoseSensor",
           "FrameRecorder", "HandCameraPose", "PerceptionScene", "PerceptionScenePoses",
           "add_perception_scene_graph", "PoseTrackingDriver", "add_pose_tracking_driver",
           "frame_in_body", "HandEyeCalibrator", "HandEyeCamera", "ImageAreaDownsampler", "PaperMotionSource", "RenderedCamera",
           "SelfCalibrationMotion", "TargetDetector", "UR5E_HOME_Q", "UR5E_URDF",
           "VisualServoController", "add_arm", "add_hand_eye_calibrator", "add_rendered_camera", "add_target_geometry",
           "camera_config", "make_control_plant", "mount_rendered_camera"]

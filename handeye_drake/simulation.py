"""The closed loop (docs/method.md §7–§8) as one Drake Diagram, and a runner for it.

    ┌──────────┐ desired_state ┌───────┐ body_poses              ┌────────┐
    │ diff_ik  │──────────────▶│ plant │────────────────────────▶│ camera │◀─ noise
    └──────────┘               └───────┘                         └────────┘
         ▲ X_BE_desired                        X_BE (at the trigger) │    │ features, visible,
    ┌────┴──────┐◀───────────────────────────────────────────────────┼────┘ X_CT_measured
    │ servo     │   phase ┌────────────┐◀──────────────────────────────┘
    │ (IBVS)    │────────▶│ calibrator │
    └───────────┘◀────────└────────────┘
          X_CE_estimate (the feedback of the design)

The point-feature camera reads the end-effector pose from the plant's body poses and holds the
robot pose X_BE of its trigger instant for the calibrator (one Python system samples both).

The arm's driver (``scenario.arm.driver``): with ``!PoseCommand`` (default) ``diff_ik`` is Drake's
C++ ``DifferentialInverseKinematicsIntegrator`` tracking the servo's ``X_BE_desired``, followed by
a ``StateInterpolatorWithDiscreteDerivative`` (``desired_state``); with ``!TwistCommand`` it is
the Python ``DifferentialIkDriver`` taking the servo's ``V_WE_E_command``.

With a rendered camera (``camera.model: !RenderedImages``) the camera box is the board in
SceneGraph, an ``RgbdSensor`` on the flange and a ``TargetDetector`` on its images (features,
visible, X_CT_measured, and ``found`` → the calibrator's ``X_CT_valid``, its covariance →
``X_CT_covariance`` when asked); the true X_WC and the robot pose X_BE are sampled from the plant's body poses by
``HandCameraPose``, in the same update phase as the image.

``build_diagram(scenario)`` returns the Diagram and handles to its parts; ``run_scenario``
simulates it and returns a ``ScenarioResult``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from pydrake.common import RandomDistribution, RandomGenerator
from pydrake.systems.analysis import ApplySimulatorConfig, Simulator
from pydrake.systems.framework import Diagram, DiagramBuilder, EventStatus
from pydrake.systems.primitives import (
    ConstantVectorSource,
    LogVectorOutput,
    Multiplexer,
    RandomSource,
)

from .estimation.errors import rotation_error_deg, translation_error_rel
from .estimation.se3 import inverse, make_transform, pose_to_vector, rotation_log, vector_to_pose
from .scenario import (
    RENDERED_PIXEL_SIGMA,
    RenderedImages,
    TwistCommand,
    Scenario,
    So3PoseNoise,
    transform_matrix,
)
from .systems.arm import (
    DifferentialIkDriver,
    EndEffectorPoseSensor,
    PoseTrackingDriver,
    add_arm,
    add_pose_tracking_driver,
    make_control_plant,
)
from .systems.calibrator import (
    STATUS_COLLECTING,
    STATUS_FILTERING,
    STATUS_INIT_FAILED,
    HandEyeCalibrator,
    add_hand_eye_calibrator,
)
from .systems.camera import HandEyeCamera
from .systems.camera_pose import HandCameraPose
from .systems.frame_recorder import FrameRecorder
from .systems.servo import SelfCalibrationMotion, VisualServoController
from .systems.target_detector import TargetDetector
from .vision.camera_model import CameraIntrinsics, project_points, target_visibility

#: Final RMS feature error (px) above which a run's servo counts as not converged.
SERVO_CONVERGED_PX = 5.0
#: Steps of the arm's driver (and of its set-point interpolator) per camera period.
DRIVER_STEPS_PER_PERIOD = 3


def intrinsics_of(scenario: Scenario) -> CameraIntrinsics:
    """The pinhole intrinsics of ``scenario.camera`` (Drake's CameraConfig + the axes angle)."""
    s = scenario.camera.sensor
    u0, v0 = s.principal_point()
    return CameraIntrinsics(alpha_u=s.focal_x(), alpha_v=s.focal_y(),
                            theta=np.radians(scenario.camera.axes_angle_deg), u0=u0, v0=v0,
                            width=s.width, height=s.height)


def target_points_T(scenario: Scenario) -> np.ndarray:
    """p_TQ (N×3, m): the target points the servo uses as features — ``target.points``, or the
    feature points of the rendered board (``camera.model.feature_ids``)."""
    if isinstance(scenario.camera.model, RenderedImages):
        return scenario.camera.model.feature_points_T()
    return np.asarray(scenario.target.points, dtype=float)


def camera_pose_on_hand(scenario: Scenario, plant) -> np.ndarray:
    """The true X_EC = X_EP · X_PB · X_BC of ``scenario.camera.sensor`` (P its ``X_PB``
    base frame, which must be fixed to the end-effector's body)."""
    s = scenario.camera.sensor
    X_PB = transform_matrix(s.X_PB, "camera.sensor.X_PB")
    X_BC = transform_matrix(s.X_BC, "camera.sensor.X_BC")
    parent = s.X_PB.base_frame or scenario.arm.ee_frame
    if not plant.HasFrameNamed(parent):
        raise ValueError(f"camera.sensor.X_PB.base_frame: no frame named {parent!r} on the arm")
    frame_P = plant.GetFrameByName(parent)
    frame_E = plant.GetFrameByName(scenario.arm.ee_frame)
    if frame_P.body().index() not in {b.index() for b in plant.GetBodiesWeldedTo(frame_E.body())}:
        raise ValueError(f"camera.sensor.X_PB.base_frame: {parent!r} is not fixed to the "
                         f"end-effector {scenario.arm.ee_frame!r} (the camera must ride on the "
                         "hand)")
    context = plant.CreateDefaultContext()
    X_EP = plant.CalcRelativeTransform(context, frame_E, frame_P).GetAsMatrix4()
    return X_EP @ X_PB @ X_BC


def desired_features(scenario: Scenario) -> np.ndarray:
    """s* (2N px): the target points projected from the desired camera pose X_TC_desired."""
    X_CT = inverse(transform_matrix(scenario.servo.X_TC_desired, "servo.X_TC_desired"))
    p_TQ = target_points_T(scenario)
    p_CQ = (X_CT[:3, :3] @ p_TQ.T).T + X_CT[:3, 3]
    uv, in_front, in_image = project_points(p_CQ, intrinsics_of(scenario))
    if not np.all(in_front & in_image):
        raise ValueError("servo.X_TC_desired: some target points are behind the camera or "
                         f"outside the image at the desired pose (visible: "
                         f"{(in_front & in_image).astype(int).tolist()})")
    return uv.reshape(-1)


def add_noise_sources(builder, system, port_names, period: float) -> None:
    """Feeds each named (Gaussian random) input port of ``system`` from its own
    ``RandomSource`` "<port>_source", sampled every ``period`` so that each sample of the system
    sees fresh noise; ``diagram.SetRandomContext`` then seeds them all."""
    for name in port_names:
        port = system.GetInputPort(name)
        noise = builder.AddNamedSystem(f"{name}_source", RandomSource(
            RandomDistribution.kGaussian, port.size(), period))
        builder.Connect(noise.get_output_port(), port)


def self_calibration_motions(scenario: Scenario) -> list[SelfCalibrationMotion]:
    """The configured motions, mapped from the camera frame to E through the *guess* of X_EC
    (the true one is unknown to the controller)."""
    X_EC = scenario.X_EC_guess_matrix()
    motions = []
    for m in scenario.servo.self_calibration:
        axis_C = np.asarray(m.axis_C, dtype=float)
        axis_E = X_EC[:3, :3] @ (axis_C / np.linalg.norm(axis_C))
        pivot_E = X_EC[:3, :3] @ np.array([0.0, 0.0, m.pivot_distance]) + X_EC[:3, 3]
        motions.append(SelfCalibrationMotion(axis_E=axis_E, angle=np.radians(m.angle_deg),
                                             pivot_E=pivot_E, duration=m.duration))
    return motions


@dataclass
class ClosedLoop:
    """The built diagram and handles to its subsystems."""
    diagram: Diagram
    plant: object
    scene_graph: object
    model_instance: object
    driver: PoseTrackingDriver | DifferentialIkDriver
    ee_sensor: EndEffectorPoseSensor | None  # only when something reads it (rendered, Meshcat)
    camera: HandEyeCamera
    servo: VisualServoController
    calibrator: HandEyeCalibrator
    X_EC_true: np.ndarray
    loggers: dict = field(default_factory=dict)
    #: ``CellCameraParts`` of ``scenario.cell_cameras``.
    cell_cameras: list = field(default_factory=list)


@dataclass
class _Arm:
    handles: object
    control_plant: object
    driver: PoseTrackingDriver | DifferentialIkDriver
    q0: np.ndarray
    X_BE0: np.ndarray  # the start pose of E in B (m)
    ee_sensor: EndEffectorPoseSensor | None = None

    def pose_sensor(self, builder: DiagramBuilder) -> EndEffectorPoseSensor:
        """The end-effector pose sensor ("ee_sensor"), added on first use: every Python system
        in a diagram costs time at each simulator step, used or not."""
        if self.ee_sensor is None:
            h = self.handles
            self.ee_sensor = builder.AddNamedSystem("ee_sensor", EndEffectorPoseSensor(
                h.plant, h.base_frame, h.ee_frame))
            builder.Connect(h.plant.get_body_poses_output_port(),
                            self.ee_sensor.get_body_poses_input_port())
        return self.ee_sensor


def add_arm_with_driver(scenario: Scenario, builder: DiagramBuilder) -> _Arm:
    """The arm's MultibodyPlant (``scenario.plant_config``), its driver (``scenario.arm.driver``:
    Drake's differential-IK integrator tracking a commanded pose, or our differential-IK driver
    taking a twist; three steps per camera period); the end-effector pose sensor is added when
    needed (``_Arm.pose_sensor``)."""
    a = scenario.arm
    X_WB = transform_matrix(a.X_WB, "arm.X_WB")
    q0 = np.radians(a.q0_deg)
    urdf = a.urdf or None
    control_plant = make_control_plant(urdf=urdf, base_frame=a.base_frame, X_WB=X_WB)
    if len(q0) != control_plant.num_positions():
        raise ValueError(f"arm.q0_deg: expected {control_plant.num_positions()} joint angles, "
                         f"got {len(q0)}")
    handles = add_arm(builder, plant_config=scenario.plant_config, urdf=urdf,
                      base_frame=a.base_frame, ee_frame=a.ee_frame, X_WB=X_WB, q0=q0)
    time_step = scenario.period / DRIVER_STEPS_PER_PERIOD
    if isinstance(a.driver, TwistCommand):
        driver = builder.AddNamedSystem("diff_ik", DifferentialIkDriver(
            control_plant, a.ee_frame, time_step, q0, velocity_scale=a.driver.velocity_scale))
        builder.Connect(driver.get_desired_state_output_port(),
                        handles.plant.get_desired_state_input_port(handles.model_instance))
    else:
        driver = add_pose_tracking_driver(builder, handles, control_plant, time_step,
                                          velocity_scale=a.driver.velocity_scale)
    context = control_plant.CreateDefaultContext()
    control_plant.SetPositions(context, q0)
    X_BE0 = control_plant.CalcRelativeTransform(
        context, control_plant.GetFrameByName(a.base_frame),
        control_plant.GetFrameByName(a.ee_frame)).GetAsMatrix4()
    return _Arm(handles, control_plant, driver, q0, X_BE0)


def add_camera(scenario: Scenario, builder: DiagramBuilder, arm: _Arm, X_EC_true):
    """The camera selected by ``scenario.camera.model``: a ``HandEyeCamera`` (point features)
    or the ``RenderedCameraParts`` of a rendered camera and its detector. Either has the output
    ports the servo and the calibrator read (``get_features_output_port``,
    ``get_visible_output_port``, ``get_X_CT_output_port``) and ``get_X_WC_output_port``."""
    if isinstance(scenario.camera.model, RenderedImages):
        return add_rendered_camera_and_detector(scenario, builder, arm, X_EC_true)
    return add_point_camera(scenario, builder, arm, X_EC_true)


def add_point_camera(scenario: Scenario, builder: DiagramBuilder, arm: _Arm,
                     X_EC_true) -> HandEyeCamera:
    """The point-feature camera (a pose oracle) reading the arm's body poses, and its noise
    sources."""
    model = scenario.camera.model
    noise = model.pose_noise
    if isinstance(noise, So3PoseNoise):
        noise_model, rotation_sigma = "so3", noise.rotation_sigma
    else:
        noise_model, rotation_sigma = "paper", noise.rotation_coefficient_sigma
    camera = builder.AddNamedSystem("camera", HandEyeCamera(
        intrinsics=intrinsics_of(scenario), X_EC=X_EC_true,
        p_TQ=np.asarray(scenario.target.points, dtype=float),
        X_WT=transform_matrix(scenario.target.X_WT, "target.X_WT"), period=scenario.period,
        pixel_sigma=model.pixel_sigma, pose_noise_model=noise_model,
        rotation_sigma=rotation_sigma, translation_sigma=noise.translation_sigma,
        plant=arm.handles.plant, base_frame_name=scenario.arm.base_frame,
        ee_frame_name=scenario.arm.ee_frame))
    builder.Connect(arm.handles.plant.get_body_poses_output_port(),
                    camera.get_body_poses_input_port())
    add_noise_sources(builder, camera, ("pixel_noise", "pose_noise"), scenario.period)
    return camera


#: Options of the in-loop detector: the slow chessboard search (75+ ms on a frame without a
#: board) is off, so a frame where the board is lost costs no more than one where it is found;
#: the pixel noise of its covariance is floored at the noise the calibrator assumes for rendered
#: frames (``scenario.RENDERED_PIXEL_SIGMA``, which says why).
LOOP_DETECT_OPTIONS = {"thorough": False, "min_pixel_sigma": RENDERED_PIXEL_SIGMA}


@dataclass
class RenderedCameraParts:
    """A rendered camera in the loop: the ``RgbdSensor`` on the flange (``rendered``), the
    ``TargetDetector`` measuring its images, the true camera pose for logs (``pose``) and the
    ``FrameRecorder`` of the frames to save. Its ``get_*_output_port`` methods are those of
    ``HandEyeCamera`` that the servo, the calibrator and the loggers read."""
    rendered: object
    detector: TargetDetector
    pose: HandCameraPose
    recorder: FrameRecorder | None
    detect_options: dict
    #: The perception-only scene the camera renders from (``add_perception_scene_graph``);
    #: cameras in the cell render from it too.
    scene: object = None

    def get_features_output_port(self):
        return self.detector.get_features_output_port()

    def get_visible_output_port(self):
        return self.detector.get_visible_output_port()

    def get_X_CT_output_port(self):
        return self.detector.get_X_CT_measured_output_port()

    def get_X_WC_output_port(self):
        return self.pose.get_X_WC_output_port()


def add_rendered_camera_and_detector(scenario: Scenario, builder: DiagramBuilder, arm: _Arm,
                                     X_EC_true) -> RenderedCameraParts:
    """The board of ``camera.model.target`` at ``target.X_WT`` in the scene graph (perception
    and illustration roles), an ``RgbdSensor`` on the end-effector at the true X_EC with
    ``camera.sensor``'s intrinsics, clipping and background — rendering from a perception-only
    copy of the scene (``add_perception_scene_graph``) — the ``TargetDetector`` on its colour
    image, and the camera pose X_WC from the kinematics."""
    from .systems.perception_scene import add_perception_scene_graph
    from .systems.rendered_camera import add_target_geometry, mount_rendered_camera
    model, sensor = scenario.camera.model, scenario.camera.sensor
    target = model.parsed_target()
    intrinsics = intrinsics_of(scenario)
    plant = arm.handles.plant
    add_target_geometry(arm.handles.scene_graph, target,
                        transform_matrix(scenario.target.X_WT, "target.X_WT"))
    # The camera renders from a copy of the scene posed only when it renders: a renderer in the
    # plant's SceneGraph would be updated at each of the plant's steps (≈ 17 a frame).
    hand = plant.GetFrameByName(scenario.arm.ee_frame).body()
    scene = add_perception_scene_graph(builder, plant, arm.handles.scene_graph, bodies=[hand])
    bg = sensor.background
    near, far = sensor.clipping_near, sensor.clipping_far
    # The depth range (unused: colour only) kept inside the clipping range.
    z_near, z_far = max(sensor.z_near, near), min(sensor.z_far, far)
    if not z_near < z_far:
        z_near, z_far = near, far
    rendered = mount_rendered_camera(
        builder, scene, plant, scenario.arm.ee_frame, X_EC_true,
        intrinsics, supersample=model.supersample, name=sensor.name or "camera",
        clipping_near=near, clipping_far=far, z_near=z_near, z_far=z_far,
        background=(bg.r(), bg.g(), bg.b()), fps=sensor.fps)
    detector = builder.AddNamedSystem("target_detector", TargetDetector(
        target, intrinsics, scenario.period, feature_ids=model.feature_ids_or_default(),
        **LOOP_DETECT_OPTIONS))
    builder.Connect(rendered.color_image_output_port(), detector.get_color_image_input_port())
    pose = builder.AddNamedSystem("camera_pose", HandCameraPose(
        X_EC_true, scenario.period, plant=arm.handles.plant,
        base_frame_name=scenario.arm.base_frame, ee_frame_name=scenario.arm.ee_frame))
    builder.Connect(arm.handles.plant.get_body_poses_output_port(),
                    pose.get_body_poses_input_port())
    recorder = None
    if model.frames_to_save:
        recorder = builder.AddNamedSystem("frame_recorder", FrameRecorder(
            model.frames_to_save, scenario.period))
        builder.Connect(rendered.color_image_output_port(),
                        recorder.get_color_image_input_port())
    return RenderedCameraParts(rendered=rendered, detector=detector, pose=pose,
                               recorder=recorder, detect_options=dict(LOOP_DETECT_OPTIONS),
                               scene=scene)


@dataclass
class CellCameraParts:
    """A camera fixed in the cell in the loop: its rendered sensor, detector and on-line
    calibrator (``CellCameraCalibrator``), and its true X_BC."""
    name: str
    rendered: object
    detector: TargetDetector
    calibrator: object
    X_BC_true: np.ndarray


def add_cell_cameras(scenario: Scenario, builder: DiagramBuilder, arm: _Arm,
                     camera: RenderedCameraParts, calibrator, sampled_X_BE) -> list:
    """Each of ``scenario.cell_cameras``: an ``RgbdSensor`` fixed in the world at its X_WC
    (rendering from the hand camera's perception scene, with the hand camera's intrinsics), a
    ``TargetDetector`` on its images and a ``CellCameraCalibrator`` fed by the hand camera's
    measurement, the robot pose sampled at the trigger and the hand calibrator's X_EC estimate
    and covariance — one calibrator system per camera (the cell camera's X_BC is determined only
    through the board's pose, which the hand camera's calibration gives)."""
    from .systems.cell_camera_calibrator import CellCameraCalibrator
    from .systems.rendered_camera import add_rendered_camera
    model, sensor = scenario.camera.model, scenario.camera.sensor
    intrinsics = intrinsics_of(scenario)
    X_WB = transform_matrix(scenario.arm.X_WB, "arm.X_WB")
    parts = []
    bg = sensor.background
    for cell in scenario.cell_cameras:
        X_WC = transform_matrix(cell.X_WC, f"cell_cameras[{cell.name}].X_WC")
        sg = camera.scene.scene_graph
        rendered = add_rendered_camera(
            builder, sg, sg.world_frame_id(), X_WC, intrinsics, supersample=model.supersample,
            name=cell.name, clipping_near=sensor.clipping_near,
            clipping_far=max(sensor.clipping_far, 3.0), background=(bg.r(), bg.g(), bg.b()),
            fps=sensor.fps)
        detector = builder.AddNamedSystem(f"{cell.name}_detector", TargetDetector(
            model.parsed_target(), intrinsics, scenario.period,
            feature_ids=model.feature_ids_or_default(), **LOOP_DETECT_OPTIONS))
        builder.Connect(rendered.color_image_output_port(), detector.get_color_image_input_port())
        X_BC_true = inverse(X_WB) @ X_WC
        cal = builder.AddNamedSystem(f"{cell.name}_calibrator", CellCameraCalibrator(
            scenario.period, offset=scenario.period / DRIVER_STEPS_PER_PERIOD))
        for name, port in (("X_BE", sampled_X_BE), ("X_CT_hand", camera.get_X_CT_output_port()),
                           ("hand_valid", camera.detector.get_found_output_port()),
                           ("X_EC", calibrator.get_X_EC_output_port()),
                           ("X_EC_covariance", calibrator.get_X_EC_covariance_output_port()),
                           ("X_CT_cell", detector.get_X_CT_measured_output_port()),
                           ("cell_valid", detector.get_found_output_port()),
                           ("X_CT_cell_covariance", detector.get_covariance_output_port())):
            builder.Connect(port, cal.get_input_port_by_name(name))
        parts.append(CellCameraParts(cell.name, rendered, detector, cal, X_BC_true))
    return parts


def connect_detector_to_calibrator(scenario: Scenario, builder: DiagramBuilder,
                                   camera: RenderedCameraParts, calibrator) -> None:
    """The detector's ``found`` flag gates the calibrator (a frame without the board is
    skipped); its covariance goes to the calibrator when ``camera.model.use_detector_covariance``
    (the estimator then uses it instead of fixed sigmas)."""
    builder.Connect(camera.detector.get_found_output_port(),
                    calibrator.get_X_CT_valid_input_port())
    if scenario.camera.model.use_detector_covariance:
        builder.Connect(camera.detector.get_covariance_output_port(),
                        calibrator.get_X_CT_covariance_input_port())


def detector_ports(camera: RenderedCameraParts) -> dict:
    """The detector's ``found``, ``reprojection_rms``, ``num_points`` and ``covariance`` output
    ports, by the names ``run_scenario`` logs them under."""
    return {"detector_found": camera.detector.get_found_output_port(),
            "reprojection_rms": camera.detector.get_reprojection_rms_output_port(),
            "detector_num_points": camera.detector.get_num_points_output_port(),
            "detector_covariance": camera.detector.get_covariance_output_port()}


class LogSlice:
    """One logged port of ``add_logger``'s single ``VectorLogSink``: ``FindLog(context)`` gives
    its ``sample_times()``, ``data()`` (its rows of the log) and ``num_samples()``, like a
    ``VectorLogSink`` of its own."""

    def __init__(self, logger, start: int, stop: int):
        self.logger, self.start, self.stop = logger, start, stop

    def FindLog(self, context):
        return _SlicedLog(self.logger.FindLog(context), self.start, self.stop)


@dataclass
class _SlicedLog:
    log: object
    start: int
    stop: int

    def sample_times(self):
        return self.log.sample_times()

    def data(self):
        return self.log.data()[self.start:self.stop]

    def num_samples(self) -> int:
        return self.log.num_samples()


def add_logger(builder: DiagramBuilder, ports: dict, period: float) -> dict:
    """Logs every vector output port of ``ports`` ({name: port}) every ``period`` with one C++
    ``Multiplexer`` and one ``VectorLogSink`` ("log"), rather than a logger per port (each system
    costs time at every simulator step). Returns {name: LogSlice}."""
    mux = builder.AddNamedSystem("log_multiplexer", Multiplexer(
        [port.size() for port in ports.values()]))
    slices, start = {}, 0
    for i, (name, port) in enumerate(ports.items()):
        builder.Connect(port, mux.get_input_port(i))
        slices[name] = (start, start + port.size())
        start += port.size()
    logger = LogVectorOutput(mux.get_output_port(), builder, period)
    logger.set_name("log")
    return {name: LogSlice(logger, a, b) for name, (a, b) in slices.items()}


@dataclass
class SavedFrame:
    """A rendered frame kept by ``camera.model.frames_to_save``: its index there, the requested
    time and the sample time (s), the RGBA image and the detection on it (what the detector in
    the loop computed: the same function, options and image)."""
    index: int
    requested_time: float
    time: float
    image: np.ndarray
    detection: object

    def drawn(self, intrinsics: CameraIntrinsics) -> np.ndarray:
        """BGR uint8 image with the detection drawn (``vision.detection.draw_detection``)."""
        from .vision.detection import draw_detection
        return draw_detection(self.image, self.detection, intrinsics)


def _saved_frames(scenario: Scenario, camera: RenderedCameraParts, context) -> list:
    if camera.recorder is None:
        return []
    from .vision.detection import detect_target
    detector = camera.detector
    frames = []
    for index, t, image in camera.recorder.frames(camera.recorder.GetMyContextFromRoot(context)):
        detection = detect_target(image, detector.target, detector.intrinsics,
                                  **camera.detect_options)
        frames.append(SavedFrame(index, scenario.camera.model.frames_to_save[index], t, image,
                                 detection))
    return frames


def _detector_diagnostics(loop, logs: dict, times) -> list[str]:
    """Why a rendered run should not be trusted: the board lost at the end of the run."""
    if not isinstance(loop.camera, RenderedCameraParts):
        return []
    found = logs["detector_found"].data()[0] > 0.5
    if found[-1]:
        return []
    seen = np.flatnonzero(found)
    last = f"last seen at t = {times[seen[-1]]:.3f} s" if seen.size else "never seen"
    return [f"the detector does not find the board at the end of the run ({last}; "
            f"found in {int(found.sum())} of {found.size} frames): the servo holds still "
            "(zero command) and the calibrator skips those frames"]


def _detector_results(scenario: Scenario, loop, logs: dict, context) -> dict:
    """The ``ScenarioResult`` fields of a rendered camera's detector (empty otherwise)."""
    if not isinstance(loop.camera, RenderedCameraParts):
        return {}
    return {"detector_found": logs["detector_found"].data()[0].copy(),
            "reprojection_rms_px": logs["reprojection_rms"].data()[0].copy(),
            "detector_num_points": logs["detector_num_points"].data()[0].copy(),
            "detector_covariance": logs["detector_covariance"].data().T.reshape(-1, 6, 6),
            "frames": _saved_frames(scenario, loop.camera, context)}


def add_servo(scenario: Scenario, builder: DiagramBuilder, arm: _Arm,
              camera) -> VisualServoController:
    """The IBVS controller (with its self-calibration prelude), fed by the camera's features
    and commanding the arm's driver: a pose (integrated from the arm's start pose) or a
    twist."""
    servo = builder.AddNamedSystem("servo", VisualServoController(
        intrinsics=intrinsics_of(scenario), p_TQ=target_points_T(scenario),
        desired_features=desired_features(scenario), gain=scenario.servo.gain,
        period=scenario.period, self_calibration_motions=self_calibration_motions(scenario),
        max_angular_speed=scenario.servo.max_angular_speed,
        max_linear_speed=scenario.servo.max_linear_speed, X_BE_initial=arm.X_BE0))
    builder.Connect(camera.get_features_output_port(), servo.get_features_input_port())
    builder.Connect(camera.get_visible_output_port(), servo.get_visible_input_port())
    builder.Connect(camera.get_X_CT_output_port(), servo.get_X_CT_input_port())
    if isinstance(arm.driver, PoseTrackingDriver):
        builder.Connect(servo.get_X_BE_desired_output_port(),
                        arm.driver.X_BE_desired_input_port())
    else:
        builder.Connect(servo.get_command_output_port(),
                        arm.driver.get_V_WE_E_command_input_port())
    return servo


def robot_pose_at_trigger(camera):
    """The output port of X_BE held from each camera trigger: the point-feature camera's own
    ``X_BE`` (sampled with its image), or the rendered camera's ``HandCameraPose`` (which
    samples in the unrestricted phase, where the detector renders its image)."""
    if isinstance(camera, RenderedCameraParts):
        return camera.pose.get_X_BE_output_port()
    return camera.get_X_BE_output_port()


def add_calibrator(scenario: Scenario, builder: DiagramBuilder, arm: _Arm, camera,
                   servo) -> tuple[HandEyeCalibrator, object]:
    """The calibrator, fed by the robot pose sampled on the camera's clock (so that (X_BE, X_CT)
    pairs are synchronous), the camera's measurement and the servo's phase. Returns it and the
    output port of the sampled robot pose."""
    period = scenario.period
    sampled_X_BE = robot_pose_at_trigger(camera)
    self_calibration_time = sum(m.duration for m in scenario.servo.self_calibration)
    # The scenario only supplies values: the wiring is ``add_hand_eye_calibrator``'s, the same
    # one a diagram without a scenario uses.
    calibrator = add_hand_eye_calibrator(
        builder, estimator=scenario.estimator_config(), period=period,
        X_CE_initial_guess=scenario.X_CE_guess_matrix(), X_BE=sampled_X_BE,
        X_CT=camera.get_X_CT_output_port(), phase=servo.get_phase_output_port(),
        num_self_calibration_motions=len(scenario.servo.self_calibration),
        init_method=scenario.calibrator.init_method,
        max_self_calibration_samples=int(np.ceil(self_calibration_time / period)) + 4,
        # Any time strictly between two triggers reads the same held sample; the driver's first
        # step after the trigger adds no simulator step of its own (half a period would add one
        # per period).
        offset=period / DRIVER_STEPS_PER_PERIOD,
        name="calibrator")
    return calibrator, sampled_X_BE


def build_diagram(scenario: Scenario, feedback: bool = True, X_CE_fixed=None,
                  meshcat=None, with_loggers: bool = True) -> ClosedLoop:
    """Builds the closed loop.

    Args:
        scenario: a ``Scenario`` (validated here).
        feedback: True wires the calibrator's ``X_CE_estimate`` into the servo's interaction
            matrix; False feeds the servo the constant ``X_CE_fixed`` (default: the scenario's
            guess) — the calibrator still runs, but open loop.
        meshcat: an optional ``pydrake.geometry.Meshcat`` to visualize the arm in.
        with_loggers: add the log ``run_scenario`` reads (off for a clean picture): one
            ``VectorLogSink`` of all logged ports (``add_logger``).

    Exported ports: outputs ``X_EC_estimate``, ``features``, ``feature_error``,
    ``V_WE_E_command``, ``X_WC``.
    """
    scenario.validate()
    builder = DiagramBuilder()
    arm = add_arm_with_driver(scenario, builder)
    X_EC_true = camera_pose_on_hand(scenario, arm.control_plant)
    _check_start_visibility(scenario, arm, X_EC_true)
    camera = add_camera(scenario, builder, arm, X_EC_true)
    servo = add_servo(scenario, builder, arm, camera)
    calibrator, sampled_X_BE = add_calibrator(scenario, builder, arm, camera, servo)
    if isinstance(camera, RenderedCameraParts):
        connect_detector_to_calibrator(scenario, builder, camera, calibrator)
    cells = add_cell_cameras(scenario, builder, arm, camera, calibrator, sampled_X_BE) \
        if scenario.cell_cameras else []
    for cell in cells:
        builder.ExportOutput(cell.calibrator.get_output_port_by_name("X_BC_estimate"),
                             f"{cell.name}_X_BC_estimate")
    if feedback:
        builder.Connect(calibrator.get_X_CE_output_port(), servo.get_X_CE_input_port())
    else:
        X_CE_fixed = scenario.X_CE_guess_matrix() if X_CE_fixed is None else X_CE_fixed
        fixed = builder.AddNamedSystem("fixed_hand_eye", ConstantVectorSource(
            pose_to_vector(np.asarray(X_CE_fixed, dtype=float))))
        builder.Connect(fixed.get_output_port(), servo.get_X_CE_input_port())

    builder.ExportOutput(calibrator.get_X_EC_output_port(), "X_EC_estimate")
    builder.ExportOutput(camera.get_features_output_port(), "features")
    builder.ExportOutput(servo.get_feature_error_output_port(), "feature_error")
    builder.ExportOutput(servo.get_command_output_port(), "V_WE_E_command")
    builder.ExportOutput(camera.get_X_WC_output_port(), "X_WC")

    loggers = {}
    if with_loggers:
        ports = {
            "X_EC_estimate": calibrator.get_X_EC_output_port(),
            "X_EC_two_motion": calibrator.get_two_motion_output_port(),
            "X_EC_std": calibrator.get_X_EC_std_output_port(),
            "calibrator_status": calibrator.get_status_output_port(),
            "feature_error": servo.get_feature_error_output_port(),
            "phase": servo.get_phase_output_port(),
            "servo_status": servo.get_status_output_port(),
            "features": camera.get_features_output_port(),
            "visible": camera.get_visible_output_port(),
            "X_WC": camera.get_X_WC_output_port(),
            "V_WE_E_command": servo.get_command_output_port(),
            "X_BE_sampled": sampled_X_BE,
            "X_CT_measured": camera.get_X_CT_output_port(),
            **({"ik_status": arm.driver.get_status_output_port()}
               if isinstance(arm.driver, DifferentialIkDriver) else {}),
        }
        if isinstance(camera, RenderedCameraParts):
            ports.update(detector_ports(camera))
        for cell in cells:
            for name in ("X_BC_estimate", "X_BC_std", "frames"):
                ports[f"{cell.name}:{name}"] = cell.calibrator.get_output_port_by_name(name)
            ports[f"{cell.name}:found"] = cell.detector.get_found_output_port()
            ports[f"{cell.name}:X_CT_measured"] = cell.detector.get_X_CT_measured_output_port()
        loggers = add_logger(builder, ports, scenario.period)

    if meshcat is not None:
        from .systems.visualization import add_meshcat_visualization
        add_meshcat_visualization(
            builder, arm.handles.scene_graph, meshcat,
            transform_matrix(scenario.target.X_WT, "target.X_WT"),
            target_points_T(scenario), scenario.period,
            camera.get_X_WC_output_port(), arm.pose_sensor(builder).get_X_WE_output_port(),
            calibrator.get_X_EC_output_port())

    diagram = builder.Build()
    diagram.set_name("handeye_closed_loop")
    return ClosedLoop(diagram=diagram, plant=arm.handles.plant,
                      scene_graph=arm.handles.scene_graph,
                      model_instance=arm.handles.model_instance, driver=arm.driver,
                      ee_sensor=arm.ee_sensor, camera=camera, servo=servo, calibrator=calibrator,
                      X_EC_true=X_EC_true, loggers=loggers, cell_cameras=cells)


def _check_start_visibility(scenario: Scenario, arm: _Arm, X_EC) -> None:
    """Fails before simulating when the target is not fully in view at the start pose."""
    plant = arm.control_plant
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, arm.q0)
    X_WE = plant.CalcRelativeTransform(context, plant.world_frame(),
                                       plant.GetFrameByName(scenario.arm.ee_frame)).GetAsMatrix4()
    _, in_front, in_image = target_visibility(
        intrinsics_of(scenario), X_WE, X_EC, target_points_T(scenario),
        transform_matrix(scenario.target.X_WT, "target.X_WT"))
    visible = in_front & in_image
    if not np.all(visible):
        raise ValueError("arm.q0_deg / target.X_WT: at the start pose the target points "
                         f"{np.flatnonzero(~visible).tolist()} are behind the "
                         "camera or outside the image")


@dataclass
class ScenarioResult:
    """What a run produced. Poses are 4×4; ``times`` are the calibrator's log times."""
    scenario: Scenario
    times: np.ndarray
    X_EC_true: np.ndarray
    X_EC_estimates: np.ndarray        # (K, 4, 4), one per camera sample
    X_EC_initial: np.ndarray          # the two-motion solution
    rotation_error_deg: np.ndarray    # (K,) of X_EC_estimates vs X_EC_true
    translation_error_rel: np.ndarray
    initial_rotation_error_deg: float
    initial_translation_error_rel: float
    feature_error_px: np.ndarray      # (K,) RMS over visible points
    features: np.ndarray              # (K, 2N)
    desired_features: np.ndarray      # (2N,)
    phase: np.ndarray
    calibrator_status: np.ndarray     # (K, 4): [mode, accepted, rejected, last NIS]
    X_EC_std: np.ndarray              # (K, 6): rotation (deg) and translation std of X_EC
    servo_status: np.ndarray
    #: (K,) the ``!TwistCommand`` driver's DifferentialInverseKinematicsStatus per camera sample
    #: (0 solution found); None with ``!PoseCommand`` (Drake's integrator logs a warning instead).
    ik_status: np.ndarray | None
    X_WC: np.ndarray                  # (K, 4, 4) true camera poses
    X_BE_samples: np.ndarray          # (K, 4, 4) robot poses sampled at the camera trigger
    X_CT_samples: np.ndarray          # (K, 4, 4) the matching measured target poses
    servo_start_time: float
    sim_time: float
    wall_time: float
    #: The calibrator's mode at the end (``systems.calibrator.STATUS_*``) and why its estimate
    #: should not be trusted (empty when nothing is wrong).
    calibrator_mode: float = 0.0
    diagnostics: list = field(default_factory=list)
    #: The run was stopped (Ctrl-C) before ``scenario.duration``.
    interrupted: bool = False
    #: CPU time (s) of this process over the same span as ``wall_time`` (all its threads):
    #: what the run cost, less sensitive than wall time to other processes on the machine.
    cpu_time: float = float("nan")
    #: (K, 6) the servo's command [ω (rad/s); v (m/s)] in E.
    V_WE_E_command: np.ndarray | None = None
    #: Rendered camera only (None otherwise), per camera sample: the detector's found flag (1/0),
    #: the reprojection RMS (px) and the number of board points of its last found frame / this
    #: frame, and the frames kept by ``camera.model.frames_to_save`` (``SavedFrame``).
    detector_found: np.ndarray | None = None
    reprojection_rms_px: np.ndarray | None = None
    detector_num_points: np.ndarray | None = None
    #: (K, 6, 6) the detector's covariance of X_CT_samples ([δθ (rad); δt (m)], of the last
    #: found frame).
    detector_covariance: np.ndarray | None = None
    frames: list = field(default_factory=list)
    #: (6, 6) the calibrator's covariance of the final X_EC's error [δθ (rad); δt (m)]
    #: (R = exp([δθ]×) R̂, about / along E's axes), at the end of the run.
    X_EC_covariance: np.ndarray | None = None
    #: Per camera in the cell (``scenario.cell_cameras``): {"X_BC_true", "X_BC_estimates"
    #: (K, 4, 4), "X_BC_std" (K, 6: deg, m), "X_BC_covariance" (6, 6, at the end), "frames",
    #: "found" (K,), "X_CT_samples" (K, 4, 4: its detector's X_CT of the last found frame, at
    #: the hand camera's samples), "rotation_error_deg" (K,), "translation_error_m" (K,),
    #: "nees" (the final X_BC's error whitened by "X_BC_covariance": χ²(6) when its σ is
    #: honest; None before a frame with both cameras)}.
    cell_cameras: dict = field(default_factory=dict)

    @property
    def real_time_factor(self) -> float:
        return self.sim_time / self.wall_time

    @property
    def filter_updates(self) -> int:
        return int(self.calibrator_status[-1, 1])

    def summary(self) -> dict:
        solved = self.calibrator_mode == STATUS_FILTERING
        return {
            "two_motion_rotation_error_deg": self.initial_rotation_error_deg if solved else None,
            "two_motion_translation_error_rel": (self.initial_translation_error_rel if solved
                                                 else None),
            "final_rotation_error_deg": float(self.rotation_error_deg[-1]),
            "final_translation_error_rel": float(self.translation_error_rel[-1]),
            "final_feature_error_px": float(self.feature_error_px[-1]),
            "estimator": type(self.scenario.calibrator.estimator).__name__,
            "two_motion_solution_found": solved,
            "filter_updates": self.filter_updates,
            "rejected_measurements": int(self.calibrator_status[-1, 2]),
            "final_X_EC_rotation_std_deg": [float(v) for v in self.X_EC_std[-1, :3]],
            "final_X_EC_translation_std": [float(v) for v in self.X_EC_std[-1, 3:]],
            # The estimates themselves (X_EC: camera C in the end-effector E, metres).
            "final_X_EC": np.asarray(self.X_EC_estimates[-1], float).tolist(),
            "final_X_EC_covariance": None if self.X_EC_covariance is None else
            np.asarray(self.X_EC_covariance, float).tolist(),
            "covariance_convention": "6x6 of [dtheta (rad); dt (m)], R = exp([dtheta]x) R_hat "
                                     "about E's axes, t = t_hat + dt",
            "two_motion_X_EC": np.asarray(self.X_EC_initial, float).tolist() if solved else None,
            "true_X_EC": np.asarray(self.X_EC_true, float).tolist(),
            "simulated_time_s": self.sim_time,
            "wall_time_s": self.wall_time,
            "real_time_factor": self.real_time_factor,
            "diagnostics": list(self.diagnostics),
            "interrupted": self.interrupted,
            **self._detector_summary(),
            **({"cell_cameras": {n: {
                "final_X_BC": np.asarray(c["X_BC_estimates"][-1], float).tolist(),
                "true_X_BC": np.asarray(c["X_BC_true"], float).tolist(),
                "final_rotation_error_deg": float(c["rotation_error_deg"][-1]),
                "final_translation_error_m": float(c["translation_error_m"][-1]),
                "final_X_BC_rotation_std_deg": [float(v) for v in c["X_BC_std"][-1, :3]],
                "final_X_BC_translation_std": [float(v) for v in c["X_BC_std"][-1, 3:]],
                "final_X_BC_covariance": np.asarray(c["X_BC_covariance"], float).tolist(),
                "final_nees": c["nees"],
                # As the hand camera's detector_frames (log 0, the initialization, left out).
                "detector_frames": int(c["found"][1:].size),
                "detector_found_frames": int(np.sum(c["found"][1:] > 0.5)),
                "frames_used": int(c["frames"][-1])} for n, c in self.cell_cameras.items()}}
               if self.cell_cameras else {}),
        }

    def _detector_summary(self) -> dict:
        """Rendered camera only: how often the detector found the board, and its reprojection
        RMS (px) over the frames where it did (log 0, the initialization, left out: log 1
        repeats the frame at t = 0)."""
        if self.detector_found is None:
            return {}
        found = self.detector_found[1:] > 0.5
        rms = self.reprojection_rms_px[1:][found]
        return {"detector_frames": int(found.size), "detector_found_frames": int(found.sum()),
                "reprojection_rms_px_median": float(np.median(rms)) if rms.size else None,
                "reprojection_rms_px_max": float(rms.max()) if rms.size else None}


def run_scenario(scenario: Scenario, feedback: bool = True, X_CE_fixed=None,
                 meshcat=None, progress=None) -> ScenarioResult:
    """Builds and simulates ``scenario`` (noise seeded by ``scenario.seed``).

    ``progress``: optional callable receiving the simulated time (s) as the run advances. A
    ``KeyboardInterrupt`` (Ctrl-C) stops the run: the result then holds what was simulated so far
    and ``interrupted`` is True.
    """
    loop = build_diagram(scenario, feedback=feedback, X_CE_fixed=X_CE_fixed, meshcat=meshcat)
    simulator = Simulator(loop.diagram)
    ApplySimulatorConfig(scenario.simulator_config, simulator)
    context = simulator.get_mutable_context()
    loop.diagram.SetRandomContext(context, RandomGenerator(int(scenario.seed)))
    if progress is not None:
        def monitor(root_context):
            progress(root_context.get_time())
            return EventStatus.Succeeded()
        simulator.set_monitor(monitor)
    if meshcat is not None:
        meshcat.StartRecording()
    start, cpu_start = time.perf_counter(), time.process_time()
    interrupted = False
    try:
        simulator.Initialize()
        simulator.AdvanceTo(scenario.duration)
    except KeyboardInterrupt:
        interrupted = True
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()
    result = _collect_result(scenario, loop, context, wall)
    result.interrupted = interrupted
    result.cpu_time = cpu
    return result


def _collect_result(scenario: Scenario, loop: ClosedLoop, context, wall: float) -> ScenarioResult:
    logs = {name: logger.FindLog(context) for name, logger in loop.loggers.items()}
    est_log = logs["X_EC_estimate"]
    times = est_log.sample_times()
    X_EC_est = np.array([vector_to_pose(v) for v in est_log.data().T])
    X_EC_true = loop.X_EC_true
    X_EC_initial = vector_to_pose(logs["X_EC_two_motion"].data()[:, -1])
    phase = logs["phase"].data()[0]
    M = len(scenario.servo.self_calibration)
    servo_start = float(times[np.argmax(phase >= M)]) if np.any(phase >= M) else float("nan")
    data = {name: log.data().T for name, log in logs.items()}
    if not all(np.all(np.isfinite(v)) for v in data.values()):
        bad = [name for name, v in data.items() if not np.all(np.isfinite(v))]
        raise RuntimeError(f"non-finite values logged on {bad}")
    calibrator_context = loop.calibrator.GetMyContextFromRoot(context)
    mode = float(loop.calibrator.get_status_output_port().Eval(calibrator_context)[0])
    covariance = np.asarray(loop.calibrator.get_X_EC_covariance_output_port().Eval(
        calibrator_context), float).reshape(6, 6)
    diagnostics = loop.calibrator.estimator(calibrator_context).diagnostics()
    if mode == STATUS_INIT_FAILED:
        diagnostics.insert(0, "the two-motion solution failed (the self-calibration motions do "
                              "not determine X: too small, or about parallel axes); the "
                              "estimator started from the guess X_EC_guess")
    elif mode == STATUS_COLLECTING:
        diagnostics.insert(0, "the self-calibration motions did not finish: no estimate yet")
    final_error = float(data["feature_error"][-1, 0])
    if final_error > SERVO_CONVERGED_PX:
        diagnostics.append(f"the servo did not converge: final feature error {final_error:.3g} px "
                           f"(> {SERVO_CONVERGED_PX:g} px)")
    return ScenarioResult(
        scenario=scenario, times=times, X_EC_true=X_EC_true, X_EC_estimates=X_EC_est,
        X_EC_initial=X_EC_initial,
        rotation_error_deg=np.array([rotation_error_deg(X_EC_true, X) for X in X_EC_est]),
        translation_error_rel=np.array([translation_error_rel(X_EC_true, X) for X in X_EC_est]),
        initial_rotation_error_deg=rotation_error_deg(X_EC_true, X_EC_initial),
        initial_translation_error_rel=translation_error_rel(X_EC_true, X_EC_initial),
        feature_error_px=data["feature_error"][:, 0], features=data["features"],
        desired_features=desired_features(scenario), phase=phase,
        calibrator_status=data["calibrator_status"], X_EC_std=data["X_EC_std"],
        servo_status=data["servo_status"][:, 0],
        ik_status=data["ik_status"][:, 0] if "ik_status" in data else None,
        X_WC=np.array([vector_to_pose(v) for v in data["X_WC"]]),
        X_BE_samples=np.array([vector_to_pose(v) for v in data["X_BE_sampled"]]),
        X_CT_samples=np.array([vector_to_pose(v) for v in data["X_CT_measured"]]),
        servo_start_time=servo_start, sim_time=float(context.get_time()), wall_time=wall,
        calibrator_mode=mode, diagnostics=diagnostics + _detector_diagnostics(loop, logs, times),
        V_WE_E_command=data["V_WE_E_command"], X_EC_covariance=covariance,
        cell_cameras=_cell_results(loop, data, context),
        **_detector_results(scenario, loop, logs, context))


def _cell_results(loop: ClosedLoop, data: dict, context) -> dict:
    out = {}
    for cell in loop.cell_cameras:
        X = np.array([vector_to_pose(v) for v in data[f"{cell.name}:X_BC_estimate"]])
        cal_context = cell.calibrator.GetMyContextFromRoot(context)
        cov = np.asarray(cell.calibrator.get_output_port_by_name("X_BC_covariance").Eval(
            cal_context), float).reshape(6, 6)
        out[cell.name] = {
            "X_BC_true": cell.X_BC_true, "X_BC_estimates": X,
            "X_BC_std": data[f"{cell.name}:X_BC_std"], "X_BC_covariance": cov,
            "frames": data[f"{cell.name}:frames"][:, 0], "found": data[f"{cell.name}:found"][:, 0],
            "X_CT_samples": np.array([vector_to_pose(v)
                                      for v in data[f"{cell.name}:X_CT_measured"]]),
            "rotation_error_deg": np.array([rotation_error_deg(cell.X_BC_true, x) for x in X]),
            "translation_error_m": np.linalg.norm(X[:, :3, 3] - cell.X_BC_true[:3, 3], axis=1),
            "nees": _nees(cell.X_BC_true, X[-1], cov)}
    return out


def _nees(X_true, X_est, covariance) -> float | None:
    """The error [δθ; δt] of X_est (R_true = exp([δθ]×) R_est, t_true = t_est + δt: the
    calibrators' covariance convention) whitened by ``covariance``: χ²(6) when the covariance
    is honest; None when it is singular (no frame with both cameras yet)."""
    R = X_true[:3, :3] @ X_est[:3, :3].T
    e = np.concatenate([rotation_log(R), X_true[:3, 3] - X_est[:3, 3]])
    try:
        return float(e @ np.linalg.solve(covariance, e))
    except np.linalg.LinAlgError:
        return None


@dataclass
class CalibratorBench:
    """The calibrator alone, fed by ``PaperMotionSource``."""
    diagram: Diagram
    source: object
    calibrator: HandEyeCalibrator
    X_CE_true: np.ndarray
    loggers: dict = field(default_factory=dict)


def build_calibrator_bench(X_EC_true, estimator, period: float = 0.1,
                           rotation_sigma: float = 2 * np.pi / 100,
                           translation_sigma: float = 1.0, pose_noise_model: str = "paper",
                           camera_rotation_sigma: float = 0.01,
                           camera_translation_sigma: float = 0.1,
                           self_calibration_angle: float = np.radians(30.0),
                           init_method: str = "daniilidis",
                           max_self_calibration_samples: int = 0) -> CalibratorBench:
    """A diagram of the calibrator fed by the paper's random small motions (no arm, no servo,
    docs/method.md §8): two self-calibration rotations of ``self_calibration_angle`` about E's x
    then y axes, then random motions; the camera motion is measured with the given noise.
    ``estimator``: the calibrator's estimator settings (``estimation.configs``). Loggers:
    the calibrator's inputs (``X_BE``, ``X_CT_measured``, ``phase``) and outputs."""
    from .estimation.synthetic import self_calibration_motions as two_rotations
    from .systems.motion_source import PaperMotionSource

    X_EC_true = np.asarray(X_EC_true, dtype=float)
    scale = max(1.0, float(np.linalg.norm(X_EC_true[:3, 3])))
    X_BE0 = np.eye(4)
    X_BT = X_BE0 @ X_EC_true @ make_transform(np.eye(3), [0.0, 0.0, 5.0 * scale])
    builder = DiagramBuilder()
    source = builder.AddNamedSystem("motion_source", PaperMotionSource(
        X_EC_true, X_BT, X_BE0, list(two_rotations(self_calibration_angle)), period,
        rotation_sigma, translation_sigma, pose_noise_model, camera_rotation_sigma,
        camera_translation_sigma))
    add_noise_sources(builder, source, ("motion_noise", "pose_noise"), period)
    calibrator = builder.AddNamedSystem("calibrator", HandEyeCalibrator(
        period=period, X_CE_initial_guess=np.eye(4), estimator=estimator,
        init_method=init_method, max_self_calibration_samples=max_self_calibration_samples))
    builder.Connect(source.get_X_BE_output_port(), calibrator.get_X_BE_input_port())
    builder.Connect(source.get_X_CT_output_port(), calibrator.get_X_CT_input_port())
    builder.Connect(source.get_phase_output_port(), calibrator.get_phase_input_port())
    loggers = {}
    for name, port in {"X_EC_estimate": calibrator.get_X_EC_output_port(),
                       "X_EC_two_motion": calibrator.get_two_motion_output_port(),
                       "status": calibrator.get_status_output_port(),
                       "X_BE": source.get_X_BE_output_port(),
                       "X_CT_measured": source.get_X_CT_output_port(),
                       "phase": source.get_phase_output_port()}.items():
        loggers[name] = LogVectorOutput(port, builder, period)
        loggers[name].set_name(f"log_{name}")
    builder.ExportOutput(calibrator.get_X_EC_output_port(), "X_EC_estimate")
    diagram = builder.Build()
    diagram.set_name("handeye_calibrator_bench")
    return CalibratorBench(diagram=diagram, source=source, calibrator=calibrator,
                           X_CE_true=inverse(X_EC_true), loggers=loggers)

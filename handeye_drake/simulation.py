"""The closed loop of PAPER §7–§8 as one Drake Diagram, and a runner for it.

    ┌──────────┐ desired_state ┌───────┐ body_poses ┌────────────┐ X_WE ┌────────┐
    │ diff_ik  │──────────────▶│ plant │───────────▶│ ee_sensor  │─────▶│ camera │◀─ noise
    └──────────┘               └───────┘            └────────────┘      └────────┘
         ▲ V_WE_E_command                                │ X_BE            │ features, visible,
    ┌────┴──────┐◀────────────────────────────────────────┼─────────────────┘ X_CT_measured
    │ servo     │   phase ┌────────────┐ X_BE  ┌──────────▼──────────┐
    │ (IBVS)    │────────▶│ calibrator │◀──────│ robot_pose_sampler  │ (ZeroOrderHold, camera clock)
    └───────────┘◀────────└────────────┘       └─────────────────────┘
          X_CE_estimate (the feedback of the design)

``build_diagram(scenario)`` returns the Diagram and handles to its parts; ``run_scenario``
simulates it and returns a ``ScenarioResult``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from pydrake.common import RandomDistribution, RandomGenerator
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import (ConstantVectorSource, LogVectorOutput, RandomSource,
                                        ZeroOrderHold)

from .estimation.errors import rotation_error_deg, translation_error_rel
from .estimation.se3 import inverse, pose_to_vector, vector_to_pose
from .scenario import Scenario, transform_matrix
from .systems.arm import DifferentialIkDriver, EndEffectorPoseSensor, add_arm, make_control_plant
from .systems.calibrator import HandEyeCalibrator
from .systems.camera import HandEyeCamera
from .systems.servo import SelfCalibrationMotion, VisualServoController
from .vision.camera_model import CameraIntrinsics, project_points, target_visibility

def intrinsics_of(scenario: Scenario) -> CameraIntrinsics:
    c = scenario.camera
    return CameraIntrinsics(alpha_u=c.alpha_u, alpha_v=c.alpha_v, theta=np.radians(c.theta_deg),
                            u0=c.u0, v0=c.v0, width=c.width, height=c.height)


def desired_features(scenario: Scenario) -> np.ndarray:
    """s* (2N px): the target points projected from the desired camera pose X_TC_desired."""
    X_CT = inverse(transform_matrix(scenario.servo.X_TC_desired, "servo.X_TC_desired"))
    p_TQ = np.asarray(scenario.target.points, dtype=float)
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
    driver: DifferentialIkDriver
    ee_sensor: EndEffectorPoseSensor
    camera: HandEyeCamera
    servo: VisualServoController
    calibrator: HandEyeCalibrator | None
    loggers: dict = field(default_factory=dict)


def build_diagram(scenario: Scenario, feedback: bool = True, X_CE_fixed=None,
                  meshcat=None, with_loggers: bool = True) -> ClosedLoop:
    """Builds the closed loop.

    Args:
        scenario: a validated ``Scenario``.
        feedback: True wires the calibrator's ``X_CE_estimate`` into the servo's interaction
            matrix; False feeds the servo the constant ``X_CE_fixed`` (default: the scenario's
            guess) — the calibrator still runs, but open loop.
        meshcat: an optional ``pydrake.geometry.Meshcat`` to visualize the arm in.
        with_loggers: add the VectorLogSinks ``run_scenario`` reads (off for a clean picture).

    Exported ports: outputs ``X_EC_estimate``, ``features``, ``feature_error``,
    ``V_WE_E_command``, ``X_WC``.
    """
    scenario.validate()
    period = scenario.period
    intrinsics = intrinsics_of(scenario)
    p_TQ = np.asarray(scenario.target.points, dtype=float)
    X_EC_true = scenario.X_EC_true_matrix()
    X_WT = transform_matrix(scenario.target.X_WT, "target.X_WT")
    X_WB = transform_matrix(scenario.arm.X_WB, "arm.X_WB")
    q0 = np.radians(scenario.arm.q0_deg)
    urdf = scenario.arm.urdf or None
    s_star = desired_features(scenario)

    builder = DiagramBuilder()
    arm = add_arm(builder, time_step=scenario.arm.time_step, urdf=urdf,
                  base_frame=scenario.arm.base_frame, ee_frame=scenario.arm.ee_frame, X_WB=X_WB,
                  q0=q0)
    plant = arm.plant
    plant.set_name("plant")
    control_plant = make_control_plant(urdf=urdf, base_frame=scenario.arm.base_frame, X_WB=X_WB)
    if len(q0) != control_plant.num_positions():
        raise ValueError(f"arm.q0_deg: expected {control_plant.num_positions()} joint angles, "
                         f"got {len(q0)}")
    _check_start_visibility(scenario, control_plant, q0, intrinsics, X_EC_true, X_WT, p_TQ)

    driver = builder.AddNamedSystem("diff_ik", DifferentialIkDriver(
        control_plant, scenario.arm.ee_frame, period / 3.0, q0))
    builder.Connect(driver.get_desired_state_output_port(),
                    plant.get_desired_state_input_port(arm.model_instance))
    ee_sensor = builder.AddNamedSystem("ee_sensor", EndEffectorPoseSensor(
        plant, scenario.arm.base_frame, scenario.arm.ee_frame))
    builder.Connect(plant.get_body_poses_output_port(), ee_sensor.get_body_poses_input_port())

    c = scenario.camera
    camera = builder.AddNamedSystem("camera", HandEyeCamera(
        intrinsics=intrinsics, X_EC=X_EC_true, p_TQ=p_TQ, X_WT=X_WT, period=period,
        pixel_sigma=c.pixel_sigma, pose_noise_model=c.pose_noise_model,
        rotation_sigma=c.rotation_sigma, translation_sigma=c.translation_sigma))
    builder.Connect(ee_sensor.GetOutputPort("X_WE"), camera.GetInputPort("X_WE"))
    add_noise_sources(builder, camera, ("pixel_noise", "pose_noise"), period)

    servo = builder.AddNamedSystem("servo", VisualServoController(
        intrinsics=intrinsics, p_TQ=p_TQ, desired_features=s_star, gain=scenario.servo.gain,
        period=period, self_calibration_motions=self_calibration_motions(scenario),
        max_angular_speed=scenario.servo.max_angular_speed,
        max_linear_speed=scenario.servo.max_linear_speed))
    for name in ("features", "visible", "X_CT_measured"):
        builder.Connect(camera.GetOutputPort(name), servo.GetInputPort(name))
    builder.Connect(servo.GetOutputPort("V_WE_E_command"), driver.GetInputPort("V_WE_E_command"))

    # The robot pose is sampled with the camera's clock so that (X_BE, X_CT) pairs are synchronous.
    sampler = builder.AddNamedSystem("robot_pose_sampler", ZeroOrderHold(period, 12))
    builder.Connect(ee_sensor.GetOutputPort("X_BE"), sampler.get_input_port())

    k = scenario.calibrator
    self_calibration_time = sum(m.duration for m in scenario.servo.self_calibration)
    calibrator = builder.AddNamedSystem("calibrator", HandEyeCalibrator(
        period=period, X_CE_initial_guess=scenario.X_CE_guess_matrix(),
        num_self_calibration_motions=len(scenario.servo.self_calibration),
        init_method=k.init_method, estimator=k.estimator,
        P0=np.asarray(k.default_P0(), dtype=float), process_cov=k.process_noise,
        rotation_sigma=k.rotation_sigma, translation_sigma=k.translation_sigma,
        noise_model=k.noise_model, orthonormalization=k.orthonormalization,
        min_rotation_deg=k.min_rotation_deg,
        gate_probability=k.gate_probability or None,
        max_self_calibration_samples=int(np.ceil(self_calibration_time / period)) + 4))
    builder.Connect(sampler.get_output_port(), calibrator.get_X_BE_input_port())
    builder.Connect(camera.GetOutputPort("X_CT_measured"), calibrator.get_X_CT_input_port())
    builder.Connect(servo.GetOutputPort("phase"), calibrator.get_phase_input_port())
    if feedback:
        builder.Connect(calibrator.get_X_CE_output_port(), servo.GetInputPort("X_CE_estimate"))
    else:
        X_CE_fixed = scenario.X_CE_guess_matrix() if X_CE_fixed is None else X_CE_fixed
        fixed = builder.AddNamedSystem("fixed_hand_eye", ConstantVectorSource(
            pose_to_vector(np.asarray(X_CE_fixed, dtype=float))))
        builder.Connect(fixed.get_output_port(), servo.GetInputPort("X_CE_estimate"))

    builder.ExportOutput(calibrator.get_X_EC_output_port(), "X_EC_estimate")
    builder.ExportOutput(camera.GetOutputPort("features"), "features")
    builder.ExportOutput(servo.GetOutputPort("feature_error"), "feature_error")
    builder.ExportOutput(servo.GetOutputPort("V_WE_E_command"), "V_WE_E_command")
    builder.ExportOutput(camera.GetOutputPort("X_WC"), "X_WC")

    loggers = {}
    log_period = period
    for name, port in {} if not with_loggers else {
        "X_EC_estimate": calibrator.get_X_EC_output_port(),
        "X_EC_two_motion": calibrator.get_two_motion_output_port(),
        "X_EC_std": calibrator.get_X_EC_std_output_port(),
        "calibrator_status": calibrator.get_status_output_port(),
        "covariance": calibrator.get_covariance_output_port(),
        "feature_error": servo.GetOutputPort("feature_error"),
        "phase": servo.GetOutputPort("phase"),
        "servo_status": servo.GetOutputPort("status"),
        "features": camera.GetOutputPort("features"),
        "visible": camera.GetOutputPort("visible"),
        "X_WC": camera.GetOutputPort("X_WC"),
        "V_WE_E_command": servo.GetOutputPort("V_WE_E_command"),
        "ik_status": driver.GetOutputPort("status"),
        "X_BE_sampled": sampler.get_output_port(),
        "X_CT_measured": camera.GetOutputPort("X_CT_measured"),
    }.items():
        logger = LogVectorOutput(port, builder, log_period)
        logger.set_name(f"log_{name}")
        loggers[name] = logger

    if meshcat is not None:
        from .systems.visualization import add_meshcat_visualization
        add_meshcat_visualization(builder, arm.scene_graph, meshcat, X_WT, p_TQ, period,
                                  camera.GetOutputPort("X_WC"), ee_sensor.GetOutputPort("X_WE"),
                                  calibrator.get_X_EC_output_port())

    diagram = builder.Build()
    diagram.set_name("handeye_closed_loop")
    return ClosedLoop(diagram=diagram, plant=plant, scene_graph=arm.scene_graph,
                      model_instance=arm.model_instance, driver=driver, ee_sensor=ee_sensor,
                      camera=camera, servo=servo, calibrator=calibrator, loggers=loggers)


def _check_start_visibility(scenario, control_plant, q0, intrinsics, X_EC, X_WT, p_TQ):
    """Fails before simulating when the target is not fully in view at the start pose."""
    context = control_plant.CreateDefaultContext()
    control_plant.SetPositions(context, q0)
    X_WE = control_plant.CalcRelativeTransform(
        context, control_plant.world_frame(),
        control_plant.GetFrameByName(scenario.arm.ee_frame)).GetAsMatrix4()
    _, in_front, in_image = target_visibility(intrinsics, X_WE, X_EC, p_TQ, X_WT)
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
    ik_status: np.ndarray
    X_WC: np.ndarray                  # (K, 4, 4) true camera poses
    X_BE_samples: np.ndarray          # (K, 4, 4) robot poses sampled at the camera trigger
    X_CT_samples: np.ndarray          # (K, 4, 4) the matching measured target poses
    servo_start_time: float
    sim_time: float
    wall_time: float

    @property
    def real_time_factor(self) -> float:
        return self.sim_time / self.wall_time

    @property
    def filter_updates(self) -> int:
        return int(self.calibrator_status[-1, 1])

    def summary(self) -> dict:
        return {
            "two_motion_rotation_error_deg": self.initial_rotation_error_deg,
            "two_motion_translation_error_rel": self.initial_translation_error_rel,
            "final_rotation_error_deg": float(self.rotation_error_deg[-1]),
            "final_translation_error_rel": float(self.translation_error_rel[-1]),
            "final_feature_error_px": float(self.feature_error_px[-1]),
            "estimator": self.scenario.calibrator.estimator,
            "filter_updates": self.filter_updates,
            "rejected_measurements": int(self.calibrator_status[-1, 2]),
            "final_X_EC_rotation_std_deg": [float(v) for v in self.X_EC_std[-1, :3]],
            "final_X_EC_translation_std": [float(v) for v in self.X_EC_std[-1, 3:]],
            "simulated_time_s": self.sim_time,
            "wall_time_s": self.wall_time,
            "real_time_factor": self.real_time_factor,
        }


def run_scenario(scenario: Scenario, feedback: bool = True, X_CE_fixed=None,
                 meshcat=None) -> ScenarioResult:
    """Builds and simulates ``scenario`` (noise seeded by ``scenario.seed``)."""
    loop = build_diagram(scenario, feedback=feedback, X_CE_fixed=X_CE_fixed, meshcat=meshcat)
    simulator = Simulator(loop.diagram)
    context = simulator.get_mutable_context()
    loop.diagram.SetRandomContext(context, RandomGenerator(int(scenario.seed)))
    if meshcat is not None:
        meshcat.StartRecording()
    start = time.perf_counter()
    simulator.Initialize()
    simulator.AdvanceTo(scenario.duration)
    wall = time.perf_counter() - start
    if meshcat is not None:
        meshcat.StopRecording()
        meshcat.PublishRecording()

    logs = {name: logger.FindLog(context) for name, logger in loop.loggers.items()}
    est_log = logs["X_EC_estimate"]
    times = est_log.sample_times()
    X_EC_est = np.array([vector_to_pose(v) for v in est_log.data().T])
    X_EC_true = scenario.X_EC_true_matrix()
    X_EC_initial = vector_to_pose(logs["X_EC_two_motion"].data()[:, -1])
    phase = logs["phase"].data()[0]
    M = len(scenario.servo.self_calibration)
    servo_start = float(times[np.argmax(phase >= M)]) if np.any(phase >= M) else float("nan")
    data = {name: log.data().T for name, log in logs.items()}
    if not all(np.all(np.isfinite(v)) for v in data.values()):
        bad = [name for name, v in data.items() if not np.all(np.isfinite(v))]
        raise RuntimeError(f"non-finite values logged on {bad}")
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
        ik_status=data["ik_status"][:, 0],
        X_WC=np.array([vector_to_pose(v) for v in data["X_WC"]]),
        X_BE_samples=np.array([vector_to_pose(v) for v in data["X_BE_sampled"]]),
        X_CT_samples=np.array([vector_to_pose(v) for v in data["X_CT_measured"]]),
        servo_start_time=servo_start, sim_time=float(context.get_time()), wall_time=wall)


@dataclass
class CalibratorBench:
    """The calibrator alone, fed by ``PaperMotionSource``."""
    diagram: Diagram
    source: object
    calibrator: HandEyeCalibrator
    X_CE_true: np.ndarray
    loggers: dict = field(default_factory=dict)


def build_calibrator_bench(X_EC_true, period: float = 0.1, rotation_sigma: float = 2 * np.pi / 100,
                           translation_sigma: float = 1.0, pose_noise_model: str = "paper",
                           camera_rotation_sigma: float = 0.01,
                           camera_translation_sigma: float = 0.1,
                           self_calibration_angle: float = np.radians(30.0),
                           estimator: str = "paper", init_method: str = "daniilidis",
                           P0=None) -> CalibratorBench:
    """A diagram of the calibrator fed by PAPER §8's random small motions (no arm, no servo):
    two self-calibration rotations of ``self_calibration_angle`` about E's x then y axes, then
    random motions. The filter is tuned to the camera noise it is given."""
    from .estimation.se3 import make_transform, rotation_exp
    from .systems.motion_source import PaperMotionSource

    X_EC_true = np.asarray(X_EC_true, dtype=float)
    scale = max(1.0, float(np.linalg.norm(X_EC_true[:3, 3])))
    X_BE0 = np.eye(4)
    X_BT = X_BE0 @ X_EC_true @ make_transform(np.eye(3), [0.0, 0.0, 5.0 * scale])
    motions = [make_transform(rotation_exp([self_calibration_angle, 0.0, 0.0]), [0.0, 0.0, 0.0]),
               make_transform(rotation_exp([0.0, self_calibration_angle, 0.0]), [0.0, 0.0, 0.0])]
    builder = DiagramBuilder()
    source = builder.AddNamedSystem("motion_source", PaperMotionSource(
        X_EC_true, X_BT, X_BE0, motions, period, rotation_sigma, translation_sigma,
        pose_noise_model, camera_rotation_sigma, camera_translation_sigma))
    add_noise_sources(builder, source, ("motion_noise", "pose_noise"), period)
    calibrator = builder.AddNamedSystem("calibrator", HandEyeCalibrator(
        period=period, X_CE_initial_guess=np.eye(4), init_method=init_method,
        estimator=estimator, P0=P0, rotation_sigma=camera_rotation_sigma,
        translation_sigma=camera_translation_sigma, noise_model=pose_noise_model))
    builder.Connect(source.GetOutputPort("X_BE"), calibrator.get_X_BE_input_port())
    builder.Connect(source.GetOutputPort("X_CT_measured"), calibrator.get_X_CT_input_port())
    builder.Connect(source.GetOutputPort("phase"), calibrator.get_phase_input_port())
    loggers = {}
    for name, port in {"X_EC_estimate": calibrator.get_X_EC_output_port(),
                       "X_EC_two_motion": calibrator.get_two_motion_output_port(),
                       "status": calibrator.get_status_output_port()}.items():
        loggers[name] = LogVectorOutput(port, builder, period)
        loggers[name].set_name(f"log_{name}")
    builder.ExportOutput(calibrator.get_X_EC_output_port(), "X_EC_estimate")
    diagram = builder.Build()
    diagram.set_name("handeye_calibrator_bench")
    return CalibratorBench(diagram=diagram, source=source, calibrator=calibrator,
                           X_CE_true=inverse(X_EC_true), loggers=loggers)

"""Scenario of a closed-loop run, Drake style: dataclasses with defaults (Drake's own config
structs where they exist: ``SimulatorConfig``, ``MultibodyPlantConfig``, ``CameraConfig``),
loaded from YAML with ``pydrake.common.yaml.yaml_load_typed``; variants are typed unions selected
by a YAML tag (``calibrator.estimator: !ManifoldFilter {...}``, ``camera.model: ...``).

Units: metres, seconds, radians unless a field says ``_deg``; pixels for image quantities. Poses
use Drake's ``pydrake.common.schema.Transform`` (YAML: ``translation: [x, y, z]`` and
``rotation: !Rpy { deg: [r, p, y] }``).

The default scenario: a UR5e above a table, a camera on its flange (``camera.sensor.X_PB``, the
true X_EC, unknown to the controller) looking down at a 5-point target; two 20° self-calibration
rotations about the camera's x and y axes through a point 0.45 m in front of it, then image-based
visual servoing to a pose 0.35 m above the target.

``load_scenario(path)`` checks the file against the schema first, so a mistake is reported with
the file and the field path (``my.yaml: camera.model.pixel_sigm: unknown field; did you mean
'pixel_sigma'?``), then validates the values (``Scenario.validate``).
"""

import dataclasses
import difflib
import math
import typing
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.common.schema import Rotation, Transform
from pydrake.common.yaml import yaml_dump_typed, yaml_load_data, yaml_load_typed
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.systems.analysis import SimulatorConfig
from pydrake.systems.sensors import CameraConfig

from .estimation import defaults
from .estimation.configs import EstimatorConfig, ManifoldFilter, TargetFilter
from .estimation.se3 import inverse
from .estimation.validation import check_positive, check_rotation

#: Largest accepted seed (Drake's RandomGenerator is a 32-bit Mersenne twister).
MAX_SEED = 2**32 - 1
#: Largest accepted duration (s) and smallest time step: bounds that keep a run finite.
MAX_DURATION = 3600.0
MIN_TIME_STEP = 1e-5
#: Largest accepted camera rate (frames per second): real hand-eye cameras run at 5–120; past
#: this the run's frames (kept for the calibrator) grow without bound.
MAX_FPS = 1000.0


def _transform(xyz, rpy_deg, base_frame=None) -> Transform:
    return Transform(base_frame=base_frame, translation=list(xyz),
                     rotation=Rotation.Rpy(deg=list(rpy_deg)))


def transform_matrix(t: Transform, name: str) -> np.ndarray:
    """4×4 matrix of a schema Transform, checked to be a rigid transform."""
    # (GetDeterministicValue aborts the process on a random pose: ask first.)
    if not t.IsDeterministic():
        raise ValueError(f"{name}: expected a deterministic pose, got a random one (!Uniform, "
                         "!Gaussian); give a fixed translation and rotation")
    try:
        X = t.GetDeterministicValue().GetAsMatrix4()
    except Exception as e:  # a malformed rotation
        raise ValueError(f"{name}: expected a deterministic pose ({' '.join(str(e).split())})") \
            from None
    if not np.all(np.isfinite(X)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    check_rotation(X[:3, :3], f"{name}.rotation")
    return X


@dataclass
class PoseCommand:
    """The servo commands a pose (default): it integrates its twist over each control period into
    a desired end-effector pose X_BE_desired, which Drake's C++
    ``DifferentialInverseKinematicsIntegrator`` tracks three times per camera period under the
    arm's joint position limits and ``velocity_scale`` × its joint velocity limits — a
    servo-to-pose robot interface."""
    velocity_scale: float = 1.0


@dataclass
class TwistCommand:
    """The servo commands a twist, turned into joint set points by ``systems.arm``'s Python
    ``DifferentialIkDriver`` (same rate and limits as ``PoseCommand``; slower: one Python QP
    call per step). Kept to compare with the loop of earlier versions."""
    velocity_scale: float = 1.0


ArmDriver = typing.Union[PoseCommand, TwistCommand]


@dataclass
class ArmConfig:
    """The robot. ``urdf`` empty = the shipped UR5e; ``q0_deg``: start joint angles (deg);
    ``driver``: what the servo commands (``!PoseCommand``, default, or ``!TwistCommand``)."""
    urdf: str = ""
    base_frame: str = "base_link"
    ee_frame: str = "tool0"
    q0_deg: list[float] = field(default_factory=lambda: [0.0, -90.0, 90.0, -90.0, -90.0, 0.0])
    X_WB: Transform = field(default_factory=lambda: _transform([0, 0, 0], [0, 0, 0]))
    driver: ArmDriver = field(default_factory=PoseCommand)


@dataclass
class So3PoseNoise:
    """Noise of the measured target pose X_CT: R ← exp([n]×) R with n ~ N(0, σ² I3) (rad per
    axis, in C), p ← p + N(0, σ_t² I3) (m)."""
    rotation_sigma: float = defaults.CAMERA_ROTATION_SIGMA
    translation_sigma: float = defaults.CAMERA_TRANSLATION_SIGMA


@dataclass
class CoefficientPoseNoise:
    """The paper's noise of the measured target pose: N(0, σ²) added to each of the 9
    coefficients of R (dimensionless; the result is not re-orthonormalized), p ← p +
    N(0, σ_t² I3) (m)."""
    rotation_coefficient_sigma: float = defaults.CAMERA_ROTATION_SIGMA
    translation_sigma: float = defaults.CAMERA_TRANSLATION_SIGMA


@dataclass
class PointFeatures:
    """The camera as a pose oracle (fast): noisy projections of ``target.points`` and a noisy
    measurement of the target pose X_CT."""
    pixel_sigma: float = defaults.PIXEL_SIGMA
    pose_noise: typing.Union[So3PoseNoise, CoefficientPoseNoise] = field(
        default_factory=So3PoseNoise)


#: The default board of a rendered camera: 5 × 4 squares of 3 cm (15 × 12 cm), 4 × 3 inner
#: corners; small enough to stay in a 640 × 480, fx = 800 view at 0.35 m (0.28 m wide).
DEFAULT_RENDERED_TARGET = "charuco:5x4:0.03:0.022:DICT_5X5_100"

#: Per-coordinate corner noise (px) the calibrator assumes for a rendered camera: the pose
#: sigmas of the estimator come from the PnP covariance at the desired view with this noise
#: (``Scenario.rendered_pose_sigmas``), and the in-loop detector floors its covariance's pixel
#: noise at it (``simulation.LOOP_DETECT_OPTIONS``). The corners of rendered frames scatter by
#: only ≈ 0.03 px, but their errors depend on the pose (aliasing, texture sampling), so they
#: repeat from frame to frame while the camera slows down and rests. Over 5 variants of
#: ``scenarios/rendered.yaml`` (``benchmarks/rendered_loop.py --consistency``), the mean NEES of
#: the final X_EC (6 degrees of freedom: 6 is consistent) was 11.1 at 0.05 px (overconfident,
#: up to 31.8) and 1.5 at 0.1 px (at most 4.0); with the detector's covariance floored at
#: 0.1 px, 4.3 (at most 9.4).
RENDERED_PIXEL_SIGMA = 0.1


@dataclass
class RenderedImages:
    """The camera renders images of a calibration board (Drake ``RgbdSensor``, RenderEngineVtk,
    headless through EGL) and a detector (``systems.target_detector``, OpenCV) measures them: the
    servo's features and the calibrator's X_CT come from the images. Slower than
    ``PointFeatures`` (render + detect every frame).

    The image size, focal lengths, principal point (OpenCV's convention: pixel centres at
    integers; Drake's half-pixel offset is added when rendering), frame rate, clipping planes and
    background are ``camera.sensor``'s; a rendered camera has no skew (``camera.axes_angle_deg``
    = 90) and no distortion. The board lies at ``target.X_WT`` (T: x along the printed columns,
    y along the rows, z INTO the board; a board face up on a table has X_WT rpy [180, 0, yaw] and
    is seen from the −z_T side); ``target.points`` is not used.

    The calibrator skips the frames where the board is not found, and its estimator's noise is
    derived from ``RENDERED_PIXEL_SIGMA`` (unless set in ``calibrator.estimator``), or is each
    frame's detector covariance with ``use_detector_covariance``."""
    #: The board, a ``vision.targets`` spec (``chessboard:…``, ``charuco:…``, ``apriltag:…``,
    #: ``aprilgrid:…``), rendered as a textured board and detected.
    target: str = DEFAULT_RENDERED_TARGET
    #: Ids (``vision.targets.object_points``) of the board points used as IBVS features, at
    #: least 3 not on one line; empty = the four outermost corners (``default_feature_ids``).
    feature_ids: list[int] = field(default_factory=list)
    #: Anti-aliasing: render k times larger and average k × k blocks (1…8; ≈ k² the render
    #: time). RenderEngineVtk takes one sample per pixel, so board edges along the pixel grid
    #: alias; 1 is enough when the desired view is rolled about the optical axis.
    supersample: int = 1
    #: Feed the detector's covariance of each X_CT (PnP Jacobian, residual pixel noise) to the
    #: calibrator (TargetFilter only: sets its ``use_measurement_covariance``).
    use_detector_covariance: bool = False
    #: Times (s) at which ``handeye-drake simulate`` saves the rendered frame, with the detection
    #: drawn, as ``frames/frame_NNN.png`` (the first camera frame at or after each time).
    frames_to_save: list[float] = field(default_factory=lambda: [0.0, 1.0, 4.0, 8.0])

    def parsed_target(self):
        """The ``vision.targets`` target (ValueError naming ``camera.model.target``)."""
        from .vision.targets import parse_target
        try:
            return parse_target(self.target)
        except ValueError as e:
            raise ValueError(f"camera.model.target: {e}") from None

    def feature_ids_or_default(self) -> list[int]:
        return list(self.feature_ids) if self.feature_ids else default_feature_ids(
            self.parsed_target())

    def feature_points_T(self) -> np.ndarray:
        """N×3 p_TQ (m) of the feature points, in ``feature_ids`` order."""
        from .vision.targets import object_points
        ids, p_TQ = object_points(self.parsed_target())
        row = {int(i): k for k, i in enumerate(ids)}
        return p_TQ[[row[i] for i in self.feature_ids_or_default()]]


def default_feature_ids(target) -> list[int]:
    """The ids of the four outermost points of a target, in image order for a frontal view
    (top-left, top-right, bottom-right, bottom-left of the printed pattern): the extremes of
    x + y and x − y over ``object_points(target)``."""
    from .vision.targets import object_points
    ids, p = object_points(target)
    s, d = p[:, 0] + p[:, 1], p[:, 0] - p[:, 1]
    return [int(ids[np.argmin(s)]), int(ids[np.argmax(d)]), int(ids[np.argmax(s)]),
            int(ids[np.argmin(d)])]


CameraModel = typing.Union[PointFeatures, RenderedImages]


def _default_sensor() -> CameraConfig:
    # X_PB: the true camera pose on the flange (X_EC), unknown to the controller.
    return CameraConfig(width=640, height=480, focal=CameraConfig.FocalLength(x=800.0, y=800.0),
                        center_x=320.0, center_y=240.0, fps=30.0, name="hand_camera",
                        X_PB=_transform([0.04, -0.03, 0.06], [4, -3, 92]))


@dataclass
class CameraSettings:
    """The camera: Drake's ``CameraConfig`` for the sensor (image size, focal lengths, principal
    point, rate ``fps``, and its pose ``X_PB`` on a frame of the arm — the true hand-eye
    transform: X_EC = X_EP · X_PB · X_BC, P = ``X_PB.base_frame``, a frame fixed to the
    end-effector's body, or the end-effector frame itself when empty), the paper's angle between
    the image axes, and the camera model."""
    sensor: CameraConfig = field(default_factory=_default_sensor)
    #: Angle θ between the image axes (deg); 90 = no skew. Only the point-feature model can skew.
    axes_angle_deg: float = 90.0
    model: CameraModel = field(default_factory=PointFeatures)


@dataclass
class TargetConfig:
    """Target frame T in the world and its points p_TQ (m), the IBVS features."""
    X_WT: Transform = field(default_factory=lambda: _transform([-0.47, -0.10, 0.0], [0, 0, 20]))
    points: list[list[float]] = field(default_factory=lambda: [
        [-0.05, -0.05, 0.0], [0.05, -0.05, 0.0], [0.05, 0.05, 0.0], [-0.05, 0.05, 0.0],
        [0.0, 0.0, 0.03]])


@dataclass
class SelfCalibrationMotionConfig:
    """A rotation by ``angle_deg`` about ``axis_C`` (a direction in the camera frame, mapped to E
    through the initial hand-eye guess) through a point ``pivot_distance`` (m) in front of the
    camera, executed at constant speed in ``duration`` s."""
    axis_C: list[float] = field(default_factory=lambda: [1.0, 0.0, 0.0])
    angle_deg: float = 20.0
    pivot_distance: float = 0.45
    duration: float = 2.0


@dataclass
class ServoConfig:
    """Image-based visual servo: gain λ (1/s), saturations (rad/s, m/s), and the desired camera
    pose relative to the target (``X_TC_desired``) from which the desired features s* are
    projected."""
    gain: float = 0.8
    max_angular_speed: float = 0.5
    max_linear_speed: float = 0.15
    X_TC_desired: Transform = field(default_factory=lambda: _transform([0, 0, 0.35],
                                                                       [180, 0, 0]))
    self_calibration: list[SelfCalibrationMotionConfig] = field(default_factory=lambda: [
        SelfCalibrationMotionConfig(axis_C=[1.0, 0.0, 0.0]),
        SelfCalibrationMotionConfig(axis_C=[0.0, 1.0, 0.0])])


@dataclass
class CalibratorConfig:
    """On-line calibrator: the classical solver of the self-calibration motions and the
    estimator (a tagged union: ``!TargetFilter`` (default), ``!ManifoldFilter``,
    ``!PaperFilter``; see ``handeye_drake.estimation.configs``). Estimator noise sigmas left
    unset are derived from the camera model (``estimator_config``)."""
    init_method: str = "daniilidis"
    estimator: EstimatorConfig = field(default_factory=TargetFilter)


@dataclass
class CellCamera:
    """A camera fixed in the cell (X_WC, OpenCV axes: z along the optical axis) with the hand
    camera's intrinsics, rendered, watching the same board; its X_BC is calibrated on line from
    the hand camera's estimate (``systems.cell_camera_calibrator``). Needs the rendered camera
    model."""
    name: str = "cell_camera"
    X_WC: Transform = field(default_factory=lambda: _transform([-0.95, -0.45, 0.55],
                                                                [-130, 0, -60]))


@dataclass
class Scenario:
    #: Seeds every noise source (0 … 2³² − 1); the same seed gives bit-identical runs.
    seed: int = 0
    #: Simulated time (s).
    duration: float = 12.0
    simulator_config: SimulatorConfig = field(default_factory=SimulatorConfig)
    #: Drake's plant settings; the default is ``systems.arm.DEFAULT_PLANT_CONFIG`` (2 ms, live
    #: output ports: see there why).
    plant_config: MultibodyPlantConfig = field(
        default_factory=lambda: MultibodyPlantConfig(time_step=0.002,
                                                     use_sampled_output_ports=False))
    arm: ArmConfig = field(default_factory=ArmConfig)
    camera: CameraSettings = field(default_factory=CameraSettings)
    target: TargetConfig = field(default_factory=TargetConfig)
    servo: ServoConfig = field(default_factory=ServoConfig)
    calibrator: CalibratorConfig = field(default_factory=CalibratorConfig)
    #: Cameras fixed in the cell, rendered, calibrated on line through the board's pose that the
    #: hand camera's calibration gives (``CellCamera``; rendered camera model only).
    cell_cameras: list[CellCamera] = field(default_factory=list)
    #: The user's rough guess of X_EC: used for the self-calibration pivots and before the
    #: two-motion solution exists.
    X_EC_guess: Transform = field(default_factory=lambda: _transform([0.0, 0.0, 0.05],
                                                                      [0, 0, 90]))

    def validate(self) -> "Scenario":
        """Raises ValueError (naming the field) on anything that would make the simulation
        meaningless or endless."""
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or \
                not 0 <= self.seed <= MAX_SEED:
            raise ValueError(f"seed: expected an integer in [0, {MAX_SEED}], got {self.seed!r}")
        check_positive(self.duration, "duration")
        if self.duration > MAX_DURATION:
            raise ValueError(f"duration: {self.duration:g} s is longer than the {MAX_DURATION:g} "
                             "s a run may last (split it, or raise scenario.MAX_DURATION)")
        check_positive(self.plant_config.time_step, "plant_config.time_step")
        if self.plant_config.time_step < MIN_TIME_STEP:
            raise ValueError(f"plant_config.time_step: {self.plant_config.time_step:g} s is below "
                             f"{MIN_TIME_STEP:g} s (the run would never end)")
        v = self.arm.driver.velocity_scale
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0.0 < v <= 1.0):
            raise ValueError(f"arm.driver.velocity_scale: must be in (0, 1], got {v!r}")
        if self.cell_cameras and not isinstance(self.camera.model, RenderedImages):
            raise ValueError("cell_cameras: cameras in the cell render the board; set "
                             "camera.model to !RenderedImages")
        names = [c.name for c in self.cell_cameras]
        if len(set(names)) != len(names) or any(not n for n in names):
            raise ValueError(f"cell_cameras: names must be distinct and non-empty, got {names}")
        s = self.camera.sensor
        check_positive(s.fps, "camera.sensor.fps")
        if s.fps > MAX_FPS:
            raise ValueError(f"camera.sensor.fps: {s.fps:g} frames per second is beyond the "
                             f"{MAX_FPS:g} a simulated camera may run at (cameras run at 5–120)")
        if s.width < 1 or s.height < 1:
            raise ValueError(f"camera.sensor: image size must be positive, got {s.width}×"
                             f"{s.height}")
        check_positive(s.focal_x(), "camera.sensor.focal")
        check_positive(s.focal_y(), "camera.sensor.focal")
        if not 0.0 < self.camera.axes_angle_deg < 180.0:
            raise ValueError("camera.axes_angle_deg: must be in (0, 180), got "
                             f"{self.camera.axes_angle_deg}")
        if self.period > 0.5 * self.duration:
            raise ValueError(f"camera.sensor.fps: one frame every {self.period:g} s leaves "
                             f"fewer than 2 frames in duration = {self.duration:g} s")
        if isinstance(self.camera.model, RenderedImages):
            self._validate_rendered()
        else:
            m = self.camera.model
            check_positive(m.pixel_sigma, "camera.model.pixel_sigma", allow_zero=True)
            for name, value in dataclasses.asdict(m.pose_noise).items():
                check_positive(value, f"camera.model.pose_noise.{name}", allow_zero=True)
        check_positive(self.servo.gain, "servo.gain")
        check_positive(self.servo.max_angular_speed, "servo.max_angular_speed")
        check_positive(self.servo.max_linear_speed, "servo.max_linear_speed")
        if len(self.servo.self_calibration) < 2:
            raise ValueError("servo.self_calibration: needs at least 2 motions (with non-parallel "
                             f"axes), got {len(self.servo.self_calibration)}")
        for i, m in enumerate(self.servo.self_calibration):
            check_positive(m.duration, f"servo.self_calibration[{i}].duration")
            check_positive(m.pivot_distance, f"servo.self_calibration[{i}].pivot_distance",
                           allow_zero=True)
            if len(m.axis_C) != 3 or not np.all(np.isfinite(m.axis_C)) or \
                    np.linalg.norm(m.axis_C) < 1e-9:
                raise ValueError(f"servo.self_calibration[{i}].axis_C: needs a non-zero finite "
                                 f"3-vector, got {m.axis_C}")
        from .estimation.solvers import METHODS
        if self.calibrator.init_method not in METHODS:
            raise ValueError(f"calibrator.init_method: expected one of {METHODS}, got "
                             f"{self.calibrator.init_method!r}")
        self.estimator_config()
        transform_matrix(self.camera.sensor.X_PB, "camera.sensor.X_PB")
        transform_matrix(self.camera.sensor.X_BC, "camera.sensor.X_BC")
        transform_matrix(self.X_EC_guess, "X_EC_guess")
        transform_matrix(self.target.X_WT, "target.X_WT")
        transform_matrix(self.servo.X_TC_desired, "servo.X_TC_desired")
        transform_matrix(self.arm.X_WB, "arm.X_WB")
        if isinstance(self.camera.model, RenderedImages):
            return self  # target.points is not used: the features are the board's
        try:
            pts = np.asarray(self.target.points, dtype=float)
        except ValueError:
            raise ValueError("target.points: needs a list of [x, y, z] points (every point with "
                             "3 coordinates)") from None
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 3 or not np.all(np.isfinite(pts)):
            raise ValueError("target.points: needs at least 3 finite [x, y, z] points, got "
                             f"shape {pts.shape}")
        spread = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
        if spread[1] < 1e-6 * max(spread[0], 1e-12):
            raise ValueError("target.points: the points are collinear (or all equal); a 6-DOF "
                             "visual servo needs at least 3 points not on one line")
        return self

    def _validate_rendered(self) -> None:
        m, s = self.camera.model, self.camera.sensor
        target = m.parsed_target()
        if self.camera.axes_angle_deg != 90.0:
            raise ValueError("camera.axes_angle_deg: a rendered camera has no skew (must be 90), "
                             f"got {self.camera.axes_angle_deg}")
        from .vision.targets import object_points
        ids, p_TQ = object_points(target)
        feature_ids = m.feature_ids_or_default()
        unknown = [i for i in feature_ids if i not in set(ids.tolist())]
        if unknown:
            raise ValueError(f"camera.model.feature_ids: {unknown} are not points of "
                             f"{m.target} (ids {ids.min()}…{ids.max()}, see "
                             "vision.targets.object_points)")
        if len(set(feature_ids)) != len(feature_ids) or len(feature_ids) < 3:
            raise ValueError("camera.model.feature_ids: needs at least 3 distinct ids, got "
                             f"{feature_ids}")
        pts = m.feature_points_T()
        spread = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
        if spread[1] < 1e-6 * spread[0]:
            raise ValueError(f"camera.model.feature_ids: the points {feature_ids} are on one "
                             "line; a 6-DOF visual servo needs 3 points not on one line")
        k = m.supersample
        if isinstance(k, bool) or not isinstance(k, int) or not 1 <= k <= 8:
            raise ValueError(f"camera.model.supersample: expected an integer in [1, 8], got {k!r}")
        if m.use_detector_covariance and not isinstance(self.calibrator.estimator, TargetFilter):
            raise ValueError("camera.model.use_detector_covariance: only the !TargetFilter "
                             "estimator uses a measurement covariance, the calibrator's is "
                             f"!{type(self.calibrator.estimator).__name__}")
        if len(m.frames_to_save) > 100:
            raise ValueError(f"camera.model.frames_to_save: at most 100 frames, got "
                             f"{len(m.frames_to_save)}")
        for i, t in enumerate(m.frames_to_save):
            check_positive(t, f"camera.model.frames_to_save[{i}]", allow_zero=True)
        near = check_positive(s.clipping_near, "camera.sensor.clipping_near")
        far = check_positive(s.clipping_far, "camera.sensor.clipping_far")
        if not near < far:
            raise ValueError(f"camera.sensor.clipping_near: must be < clipping_far, got {near} "
                             f"≥ {far}")
        d = transform_matrix(self.servo.X_TC_desired, "servo.X_TC_desired")[2, 3]
        if not near < abs(d) < far:
            raise ValueError(f"servo.X_TC_desired: the board at {abs(d):g} m is outside the "
                             f"camera's clipping range [{near:g}, {far:g}] m "
                             "(camera.sensor.clipping_near, clipping_far)")

    def rendered_pose_sigmas(self) -> tuple[float, float]:
        """(rotation (rad), translation (m)) sigmas of the target pose a rendered camera measures
        at the desired view: the largest standard deviations of the PnP covariance
        σ² (JᵀJ)⁻¹ of all the board's points seen from ``servo.X_TC_desired``, with σ the
        detector's corner noise on rendered frames (``RENDERED_PIXEL_SIGMA``)."""
        return _rendered_pose_sigmas(self)

    @property
    def period(self) -> float:
        """The camera period (s)."""
        return 1.0 / self.camera.sensor.fps

    def X_EC_guess_matrix(self) -> np.ndarray:
        return transform_matrix(self.X_EC_guess, "X_EC_guess")

    def X_CE_guess_matrix(self) -> np.ndarray:
        return inverse(self.X_EC_guess_matrix())

    def estimator_config(self):
        """The calibrator's estimator settings with every unset noise sigma derived from the
        camera model, validated (``camera.model.pose_noise``: the pose noise for
        ``TargetFilter``; for the motion filters, the noise of a motion differenced from two
        such poses with the target at the desired distance)."""
        est = self.calibrator.estimator
        model = self.camera.model
        if isinstance(model, RenderedImages):
            (so3, st), coefficient = self.rendered_pose_sigmas(), None
            if model.use_detector_covariance and isinstance(est, TargetFilter):
                est = dataclasses.replace(est, use_measurement_covariance=True)
        elif isinstance(model.pose_noise, So3PoseNoise):
            so3, coefficient = model.pose_noise.rotation_sigma, None
            st = model.pose_noise.translation_sigma
        else:
            coefficient = model.pose_noise.rotation_coefficient_sigma
            so3 = coefficient / math.sqrt(2.0)  # the rotation-vector part of coefficient noise
            st = model.pose_noise.translation_sigma
        d = float(np.linalg.norm(transform_matrix(self.servo.X_TC_desired,
                                                  "servo.X_TC_desired")[:3, 3]))
        # A = X_CT0 X_CT1⁻¹: two poses' noise, the rotation noise moving t_A by ~ ‖t_CT‖.
        motion_st = math.sqrt(2.0 * st**2 + 4.0 / 3.0 * so3**2 * d**2)
        if isinstance(est, TargetFilter):
            derived = {"rotation_sigma": so3, "translation_sigma": st}
        elif isinstance(est, ManifoldFilter):
            derived = {"rotation_sigma": math.sqrt(2.0) * so3, "translation_sigma": motion_st}
        else:
            derived = {"rotation_coefficient_sigma": math.sqrt(2.0) * (
                coefficient if coefficient is not None else so3 * math.sqrt(4.0 / 3.0)),
                "translation_sigma": motion_st}
        changes = {k: max(v, 1e-9) for k, v in derived.items() if getattr(est, k) is None}
        return dataclasses.replace(est, **changes).validated("calibrator.estimator")


def _rendered_pose_sigmas(scenario: Scenario) -> tuple[float, float]:
    from .vision.camera_model import CameraIntrinsics
    from .vision.detection import project_with_jacobian
    from .vision.targets import object_points
    m, s = scenario.camera.model, scenario.camera.sensor
    u0, v0 = s.principal_point()
    intrinsics = CameraIntrinsics(alpha_u=s.focal_x(), alpha_v=s.focal_y(), u0=u0, v0=v0,
                                  width=s.width, height=s.height)
    X_CT = inverse(transform_matrix(scenario.servo.X_TC_desired, "servo.X_TC_desired"))
    _, p_TQ = object_points(m.parsed_target())
    _, J = project_with_jacobian(X_CT, p_TQ, intrinsics)
    cov = RENDERED_PIXEL_SIGMA**2 * np.linalg.inv(J.T @ J)
    std = np.sqrt(np.diag(cov))
    return float(std[:3].max()), float(std[3:].max())


# ----------------------------------------------------------------------------- YAML checking
def _is_schema(t) -> bool:
    return dataclasses.is_dataclass(t) or hasattr(t, "__fields__")


def _fields(t) -> dict:
    if dataclasses.is_dataclass(t):
        hints = typing.get_type_hints(t)
        return {f.name: hints[f.name] for f in dataclasses.fields(t)}
    return {f.name: f.type for f in t.__fields__}


def _describe(value) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _check(data, schema, path: str) -> None:
    """Raises ValueError "PATH: problem" for the first mismatch between plain YAML data and a
    schema type (unknown fields with a suggestion, wrong scalar types, unknown tags)."""
    where = path or "(top level)"
    origin = typing.get_origin(schema)
    if origin is typing.Union:
        members = [m for m in typing.get_args(schema) if m is not type(None)]
        if data is None and len(members) < len(typing.get_args(schema)):
            return
        tag = data.get("_tag") if isinstance(data, dict) else None
        if tag is None:
            if len(members) == 1 or not all(_is_schema(m) for m in members):
                if len(members) == 1:
                    _check(data, members[0], path)
                return  # a scalar-or-struct union (Drake's own): left to yaml_load_typed
            _check(data, members[0], path)
            return
        names = {f"!{getattr(m, '__name__', '')}": m for m in members}
        if tag not in names:
            raise ValueError(f"{where}: unknown type tag {tag}; expected one of "
                             f"{', '.join(sorted(names))}")
        _check(data, names[tag], path)
        return
    if origin in (list, typing.List):
        if not isinstance(data, list):
            raise ValueError(f"{where}: expected a list, got {_describe(data)}")
        (item,) = typing.get_args(schema) or (typing.Any,)
        for i, v in enumerate(data):
            _check(v, item, f"{path}[{i}]")
        return
    if schema is float:
        if isinstance(data, bool) or not isinstance(data, (int, float, str)):
            raise ValueError(f"{where}: expected a number, got {_describe(data)}")
        if isinstance(data, str):
            try:
                float(data)
            except ValueError:
                raise ValueError(f"{where}: expected a number, got {_describe(data)}") from None
        return
    if schema is int:
        if isinstance(data, bool) or not isinstance(data, int):
            raise ValueError(f"{where}: expected an integer, got {_describe(data)}")
        return
    if schema is bool:
        if not isinstance(data, bool):
            raise ValueError(f"{where}: expected true or false, got {_describe(data)}")
        return
    if schema is str:
        if not isinstance(data, str):
            raise ValueError(f"{where}: expected a string, got {_describe(data)}")
        return
    if _is_schema(schema):
        if data is None:
            return
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected a mapping of fields, got {_describe(data)}")
        fields = _fields(schema)
        for key, value in data.items():
            if key == "_tag":
                continue
            child = f"{path}.{key}" if path else str(key)
            if key not in fields:
                close = difflib.get_close_matches(str(key), list(fields), n=1)
                hint = f"; did you mean {close[0]!r}?" if close else (
                    f"; known fields: {', '.join(fields)}")
                raise ValueError(f"{child}: unknown field{hint}")
            if schema.__module__.startswith("pydrake.common.schema"):
                continue  # Drake's pose/distribution types: yaml_load_typed checks them
            _check(value, fields[key], child)


def load_scenario(path=None, text: str | None = None) -> Scenario:
    """The default scenario, or one read from a YAML file / string (unset fields keep their
    defaults). Raises ValueError — one line naming the file and the field — on malformed YAML,
    unknown fields, wrong types, or invalid values."""
    if path is None and text is None:
        return Scenario().validate()
    source = "scenario"
    if text is None:
        p = Path(path)
        source = str(p)
        if not p.is_file():
            raise ValueError(f"scenario: no such file {source!r}")
        raw = p.read_bytes()[:10_000_001]
        if len(raw) > 10_000_000:
            raise ValueError(f"{source}: larger than 10 MB, not a scenario file")
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as e:
            line = raw[:e.start].count(b"\n") + 1
            raise ValueError(f"{source}:{line}: not UTF-8 text (byte {e.start})") from None
    if not text.strip():
        raise ValueError(f"{source}: the file is empty")
    try:
        data = yaml_load_data(text)
    except Exception as e:  # the YAML parser's errors (syntax, !!python tags, ...)
        raise ValueError(f"{source}: not a valid scenario YAML file: "
                         f"{' '.join(str(e).split())}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{source}: expected a mapping of scenario fields at the top level, "
                         f"got {_describe(data)}")
    try:
        _check(data, Scenario, "")
    except ValueError as e:
        raise ValueError(f"{source}: {e}") from None
    try:
        scenario = yaml_load_typed(schema=Scenario, data=text, defaults=Scenario())
    except Exception as e:  # noqa: BLE001 - Drake's loader raises RuntimeError/TypeError/...
        raise ValueError(f"{source}: {' '.join(str(e).split())}") from None
    try:
        return scenario.validate()
    except ValueError as e:
        raise ValueError(f"{source}: {e}") from None


def dump_scenario(scenario: Scenario) -> str:
    return yaml_dump_typed(scenario)


def replace(scenario: Scenario, **changes) -> Scenario:
    return dataclasses.replace(scenario, **changes)

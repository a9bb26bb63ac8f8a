"""Scenario description of a closed-loop run, Drake style: dataclasses with defaults, loadable from
YAML with ``pydrake.common.yaml.yaml_load_typed``.

Units: metres, seconds, radians unless a field says ``_deg``; pixels for image quantities. Poses
use Drake's ``pydrake.common.schema.Transform`` (YAML: ``translation: [x, y, z]`` and
``rotation: !Rpy { deg: [r, p, y] }``).

The default scenario: a UR5e above a table, a camera on its flange (``X_EC_true``) looking down
at a 5-point target; two 20° self-calibration rotations about the camera's x and y axes through a
point 0.45 m in front of it, then image-based visual servoing to a pose 0.35 m above the target.
"""


import dataclasses
from dataclasses import dataclass, field
from pathlib import Path


import numpy as np
from pydrake.common.schema import Rotation, Transform
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed

from .estimation.se3 import inverse
from .estimation.validation import check_positive, check_rotation


def _transform(xyz, rpy_deg) -> Transform:
    return Transform(translation=list(xyz), rotation=Rotation.Rpy(deg=list(rpy_deg)))


def transform_matrix(t: Transform, name: str) -> np.ndarray:
    """4×4 matrix of a schema Transform, checked to be a rigid transform."""
    try:
        X = t.GetDeterministicValue().GetAsMatrix4()
    except Exception as e:  # a stochastic (Uniform, Gaussian) pose, or a malformed rotation
        raise ValueError(f"{name}: expected a deterministic pose ({e})") from None
    if not np.all(np.isfinite(X)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    check_rotation(X[:3, :3], f"{name}.rotation")
    return X


@dataclass
class ArmConfig:
    """The robot. ``urdf`` empty = the shipped UR5e; ``q0`` start joint angles (deg)."""
    urdf: str = ""
    base_frame: str = "base_link"
    ee_frame: str = "tool0"
    q0_deg: list[float] = field(default_factory=lambda: [0.0, -90.0, 90.0, -90.0, -90.0, 0.0])
    time_step: float = 0.002
    X_WB: Transform = field(default_factory=lambda: _transform([0, 0, 0], [0, 0, 0]))


@dataclass
class CameraConfig:
    """Pinhole intrinsics (α_u, α_v, angle θ between image axes, principal point, image size),
    rate, and sensor noise. ``pose_noise_model``: "paper" (additive on rotation coefficients,
    ``rotation_sigma`` dimensionless) or "so3" (rotation vector, ``rotation_sigma`` rad)."""
    alpha_u: float = 800.0
    alpha_v: float = 800.0
    theta_deg: float = 90.0
    u0: float = 320.0
    v0: float = 240.0
    width: int = 640
    height: int = 480
    rate_hz: float = 30.0
    pixel_sigma: float = 0.5
    pose_noise_model: str = "so3"
    rotation_sigma: float = 0.002
    translation_sigma: float = 0.0005


@dataclass
class TargetConfig:
    """Target frame T in world and its points p_TQ (m)."""
    X_WT: Transform = field(default_factory=lambda: _transform([-0.47, -0.10, 0.0], [0, 0, 20]))
    points: list[list[float]] = field(default_factory=lambda: [
        [-0.05, -0.05, 0.0], [0.05, -0.05, 0.0], [0.05, 0.05, 0.0], [-0.05, 0.05, 0.0],
        [0.0, 0.0, 0.03]])


@dataclass
class SelfCalibrationMotionConfig:
    """A rotation by ``angle_deg`` about ``axis_C`` (a direction in the camera frame, mapped to E
    through the initial hand-eye guess) through a point ``pivot_distance`` in front of the camera,
    executed at constant speed in ``duration`` s."""
    axis_C: list[float] = field(default_factory=lambda: [1.0, 0.0, 0.0])
    angle_deg: float = 20.0
    pivot_distance: float = 0.45
    duration: float = 2.0


@dataclass
class ServoConfig:
    """Image-based visual servo: gain λ (1/s), saturations, and the desired camera pose relative
    to the target (``X_TC_desired``) from which the desired features s* are projected."""
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
    """On-line calibrator. ``estimator``: "paper" (PAPER §4–§5, diagonal G2), "paper_full"
    (estimate-dependent G2), "manifold" (error-state EKF on SE(3) on motion pairs) or "target"
    (error-state EKF on the raw poses, AX = ZB, the default). The sigmas describe what the
    estimator measures: the camera motion A for the paper/manifold estimators (paper:
    coefficient std; so3: rad), the target pose X_CT for "target". ``P0_diagonal``: 12 entries
    (9 rotation coefficients, 3 translations in m²) for the paper estimators, 6 ([δθ rad²;
    δt m²]) for ours; empty = the estimator's default."""
    estimator: str = "target"
    init_method: str = "daniilidis"
    noise_model: str = "so3"
    rotation_sigma: float = 0.002
    translation_sigma: float = 0.0005
    P0_diagonal: list[float] = field(default_factory=list)
    process_noise: float = 0.0
    orthonormalization: str = "svd"
    #: Motion estimators form a pair once the robot has turned this much since the last used
    #: sample (0: every sample, as the paper).
    min_rotation_deg: float = 0.0
    #: NIS gate probability of our estimators (0 disables the gate).
    gate_probability: float = 0.999

    def default_P0(self) -> list:
        if self.P0_diagonal:
            return list(self.P0_diagonal)
        if self.estimator in ("paper", "paper_full"):
            return [1e-4] * 9 + [1e-4] * 3
        return [(np.radians(1.0))**2] * 3 + [0.01**2] * 3


@dataclass
class Scenario:
    seed: int = 0
    duration: float = 12.0
    arm: ArmConfig = field(default_factory=ArmConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    target: TargetConfig = field(default_factory=TargetConfig)
    servo: ServoConfig = field(default_factory=ServoConfig)
    calibrator: CalibratorConfig = field(default_factory=CalibratorConfig)
    #: The real camera pose on the flange (E → C), unknown to the controller.
    X_EC_true: Transform = field(default_factory=lambda: _transform([0.04, -0.03, 0.06],
                                                                     [4, -3, 92]))
    #: The user's rough guess of it: used for the self-calibration pivots and before the
    #: two-motion solution exists.
    X_EC_guess: Transform = field(default_factory=lambda: _transform([0.0, 0.0, 0.05],
                                                                      [0, 0, 90]))

    def validate(self) -> "Scenario":
        """Raises ValueError on anything that would make the simulation meaningless."""
        check_positive(self.duration, "duration")
        check_positive(self.camera.rate_hz, "camera.rate_hz")
        check_positive(self.arm.time_step, "arm.time_step")
        check_positive(self.servo.gain, "servo.gain")
        check_positive(self.servo.max_angular_speed, "servo.max_angular_speed")
        check_positive(self.servo.max_linear_speed, "servo.max_linear_speed")
        for name in ("pixel_sigma", "rotation_sigma", "translation_sigma"):
            check_positive(getattr(self.camera, name), f"camera.{name}", allow_zero=True)
        for name in ("rotation_sigma", "translation_sigma", "process_noise", "min_rotation_deg"):
            check_positive(getattr(self.calibrator, name), f"calibrator.{name}", allow_zero=True)
        from .systems.calibrator import ESTIMATORS
        if self.calibrator.estimator not in ESTIMATORS:
            raise ValueError(f"calibrator.estimator: expected one of {ESTIMATORS}, got "
                             f"{self.calibrator.estimator!r}")
        n = 12 if self.calibrator.estimator in ("paper", "paper_full") else 6
        P0 = self.calibrator.default_P0()
        if len(P0) != n or not all(np.isfinite(v) and v > 0 for v in P0):
            raise ValueError(f"calibrator.P0_diagonal: needs {n} positive finite variances for "
                             f"estimator {self.calibrator.estimator!r}, got {P0}")
        if not 0.0 <= self.calibrator.gate_probability < 1.0:
            raise ValueError("calibrator.gate_probability: must be in [0, 1), got "
                             f"{self.calibrator.gate_probability}")
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
        for name in ("X_EC_true", "X_EC_guess"):
            transform_matrix(getattr(self, name), name)
        transform_matrix(self.target.X_WT, "target.X_WT")
        transform_matrix(self.servo.X_TC_desired, "servo.X_TC_desired")
        transform_matrix(self.arm.X_WB, "arm.X_WB")
        pts = np.asarray(self.target.points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 3 or not np.all(np.isfinite(pts)):
            raise ValueError("target.points: needs at least 3 finite [x, y, z] points, got "
                             f"shape {pts.shape}")
        return self

    @property
    def period(self) -> float:
        return 1.0 / self.camera.rate_hz

    def X_EC_true_matrix(self) -> np.ndarray:
        return transform_matrix(self.X_EC_true, "X_EC_true")

    def X_EC_guess_matrix(self) -> np.ndarray:
        return transform_matrix(self.X_EC_guess, "X_EC_guess")

    def X_CE_guess_matrix(self) -> np.ndarray:
        return inverse(self.X_EC_guess_matrix())


def load_scenario(path=None, text: str | None = None) -> Scenario:
    """The default scenario, or one read from a YAML file / string (unset fields keep their
    defaults). Raises ValueError on unknown fields, wrong types, or invalid values."""
    if path is None and text is None:
        return Scenario().validate()
    if text is None:
        p = Path(path)
        if not p.is_file():
            raise ValueError(f"scenario: no such file {str(p)!r}")
        text = p.read_text()
    if not text.strip():
        raise ValueError("scenario: the file is empty")
    try:
        scenario = yaml_load_typed(schema=Scenario, data=text, defaults=Scenario())
    except RuntimeError as e:
        raise ValueError(f"scenario: {e}") from None
    return scenario.validate()


def dump_scenario(scenario: Scenario) -> str:
    return yaml_dump_typed(scenario)


def replace(scenario: Scenario, **changes) -> Scenario:
    return dataclasses.replace(scenario, **changes)

"""Settings of the on-line estimators: one dataclass per estimator.

A scenario selects an estimator by type (a tagged union in YAML, the way Drake selects
variants)::

    calibrator:
      estimator: !TargetFilter
        rotation_sigma: 0.002

Every field has one meaning and one unit, written in its name or its comment. A noise sigma left
at ``None`` means "what the camera produces": ``handeye_drake.scenario`` fills it from the
camera's noise model before the estimator is built; building an estimator directly needs it set.

Variances are given as diagonals (lists), in the unit of their error state squared.
"""

import math
import typing
from dataclasses import dataclass, field, replace

from . import defaults

ORTHONORMALIZATIONS = ("svd", "qr", "horn")


def _number(value, name: str, lo: typing.Optional[float] = 0.0, lo_open: bool = False,
            hi: typing.Optional[float] = None, hi_open: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(v):
        raise ValueError(f"{name}: expected a finite number, got {value!r}")
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise ValueError(f"{name}: must be {'>' if lo_open else '≥'} {lo:g}, got {value!r}")
    if hi is not None and (v > hi or (hi_open and v == hi)):
        raise ValueError(f"{name}: must be {'<' if hi_open else '≤'} {hi:g}, got {value!r}")
    if abs(v) > defaults.MAX_MAGNITUDE:
        raise ValueError(f"{name}: {value!r} is too large (must be ≤ {defaults.MAX_MAGNITUDE:g})")
    return v


def _integer(value, name: str, lo: int, hi: int) -> int:
    ok = (not isinstance(value, bool) and isinstance(value, (int, float))
          and (isinstance(value, int) or math.isfinite(value)) and lo <= value <= hi
          and int(value) == value)
    if not ok:
        raise ValueError(f"{name}: expected an integer in [{lo}, {hi}], got {value!r}")
    return int(value)


def _sigma(value, name: str, allow_zero: bool) -> float:
    if value is None:
        raise ValueError(f"{name}: not set (None means 'from the camera model', which only a "
                         "scenario can fill in); give a value")
    return _number(value, name, 0.0, lo_open=not allow_zero, hi=defaults.MAX_SIGMA)


def _variances(values, name: str, n: int, allow_empty: bool) -> list[float]:
    try:
        values = list(values)
    except TypeError:
        raise ValueError(f"{name}: needs a list of {n} variances, got {values!r}") from None
    if allow_empty and len(values) == 0:
        return []
    if len(values) != n:
        raise ValueError(f"{name}: needs {n} variances, got {values!r}")
    return [_number(v, f"{name}[{i}]", 0.0, hi=defaults.MAX_SIGMA**2)
            for i, v in enumerate(values)]


def _probability(value, name: str) -> float | None:
    if value is None:
        return None
    return _number(value, name, 0.0, lo_open=True, hi=1.0, hi_open=True)


def _choice(value, name: str, choices) -> str:
    if value not in choices:
        raise ValueError(f"{name}: expected one of {tuple(choices)}, got {value!r}")
    return value


@dataclass
class PaperFilter:
    """The paper's linear Kalman filter on motion pairs (``kalman.HandEyeKalmanFilter``).

    State x = [vec_row(R_X); t_X] (12) of X = X_CE; each motion pair (A, B) is the linear
    measurement y = C x + n of ``linear_model.linear_system``.
    """
    #: G2, the covariance of n: "diagonal" = the paper's approximation diag(σ_r² I9, σ_t² I3);
    #: "exact" = the estimate-dependent G2 evaluated at the current estimate and B.
    noise_covariance: str = "diagonal"
    #: Std of the additive noise on each of the 9 coefficients of the measured camera motion's
    #: rotation R_A (dimensionless).
    rotation_coefficient_sigma: typing.Optional[float] = None
    #: Std of each coordinate of the measured camera motion's translation t_A (m).
    translation_sigma: typing.Optional[float] = None
    #: P0 diagonal: 9 variances of the rotation coefficients, then 3 of t_X (m²).
    initial_variances: list[float] = field(default_factory=lambda: [1e-4] * 12)
    #: G1 diagonal (12, same units as P0), added at every update; empty = 0 (X constant).
    process_variances: list[float] = field(default_factory=list)
    #: A motion pair is formed once the robot has turned this much since the last used sample
    #: (0: every sample, as the paper). A pair that is mostly noise biases the linear model.
    min_rotation_deg: float = 0.0
    #: Projection of the 9 estimated coefficients onto SO(3): "svd", "qr" or "horn".
    orthonormalization: str = "svd"
    #: NIS gate probability (None: no gate, as the paper). The gross-error bound
    #: ``defaults.GROSS_ERROR_SIGMAS`` applies in any case.
    gate_probability: typing.Optional[float] = None
    #: Replay the samples recorded during the self-calibration motions after the two-motion
    #: start (the paper does not).
    replay_self_calibration: bool = False

    def validated(self, prefix: str = "PaperFilter") -> "PaperFilter":
        """A checked copy; raises ValueError naming ``prefix.field``."""
        return replace(
            self,
            noise_covariance=_choice(self.noise_covariance, f"{prefix}.noise_covariance",
                                     ("diagonal", "exact")),
            rotation_coefficient_sigma=_sigma(self.rotation_coefficient_sigma,
                                              f"{prefix}.rotation_coefficient_sigma", True),
            translation_sigma=_sigma(self.translation_sigma, f"{prefix}.translation_sigma", True),
            initial_variances=_variances(self.initial_variances, f"{prefix}.initial_variances",
                                         12, False),
            process_variances=_variances(self.process_variances, f"{prefix}.process_variances",
                                         12, True),
            min_rotation_deg=_number(self.min_rotation_deg, f"{prefix}.min_rotation_deg", 0.0,
                                     hi=180.0),
            orthonormalization=_choice(self.orthonormalization, f"{prefix}.orthonormalization",
                                       ORTHONORMALIZATIONS),
            gate_probability=_probability(self.gate_probability, f"{prefix}.gate_probability"),
            replay_self_calibration=bool(self.replay_self_calibration))


@dataclass
class ManifoldFilter:
    """Error-state EKF on SE(3) fed with motion pairs (``manifold.ManifoldHandEyeFilter``)."""
    #: Rotation-vector noise of the measured camera motion R_A (rad per axis).
    rotation_sigma: typing.Optional[float] = None
    #: Noise of each coordinate of the measured camera motion's translation t_A (m).
    translation_sigma: typing.Optional[float] = None
    #: P0 diagonal of the X_CE error [δθ (rad²); δt (m²)] after the two-motion start.
    initial_variances: list[float] = field(
        default_factory=lambda: [math.radians(1.0) ** 2] * 3 + [0.01**2] * 3)
    #: Process noise diagonal (6, same units), added before every update; empty = 0.
    process_variances: list[float] = field(default_factory=list)
    #: NIS gate probability (None: no gate).
    gate_probability: typing.Optional[float] = defaults.GATE_PROBABILITY
    #: Gauss–Newton iterations of the update (1 = plain EKF).
    iterations: int = defaults.ITERATIONS
    #: Gate rejections in a row that trigger the covariance inflation (None: never).
    max_consecutive_rejections: typing.Optional[int] = defaults.MAX_CONSECUTIVE_REJECTIONS
    #: As ``PaperFilter.min_rotation_deg``.
    min_rotation_deg: float = 0.0
    #: How the filter starts after the self-calibration motions: "two_motion" (the classical
    #: two-motion solution with ``initial_variances``) or "ml" (the outlier-screened
    #: maximum-likelihood estimate and covariance of the buffered self-calibration motions).
    start: str = "two_motion"
    #: Replay the samples recorded during the self-calibration motions after the start.
    replay_self_calibration: bool = True

    def validated(self, prefix: str = "ManifoldFilter") -> "ManifoldFilter":
        return replace(
            self,
            rotation_sigma=_sigma(self.rotation_sigma, f"{prefix}.rotation_sigma", False),
            translation_sigma=_sigma(self.translation_sigma, f"{prefix}.translation_sigma",
                                     False),
            initial_variances=_variances(self.initial_variances, f"{prefix}.initial_variances",
                                         6, False),
            process_variances=_variances(self.process_variances, f"{prefix}.process_variances",
                                         6, True),
            gate_probability=_probability(self.gate_probability, f"{prefix}.gate_probability"),
            iterations=_integer(self.iterations, f"{prefix}.iterations", 1, 100),
            max_consecutive_rejections=None if self.max_consecutive_rejections is None else
            _integer(self.max_consecutive_rejections, f"{prefix}.max_consecutive_rejections", 1,
                     10**6),
            min_rotation_deg=_number(self.min_rotation_deg, f"{prefix}.min_rotation_deg", 0.0,
                                     hi=180.0),
            start=_choice(self.start, f"{prefix}.start", ("two_motion", "ml")),
            replay_self_calibration=bool(self.replay_self_calibration))


@dataclass
class TargetFilter:
    """Error-state EKF for AX = ZB on the raw synchronized poses, estimating the fixed target
    pose X_BT alongside X_CE (``manifold.HandEyeTargetFilter``)."""
    #: Rotation-vector noise of the measured target pose R_CT (rad per axis).
    rotation_sigma: typing.Optional[float] = None
    #: Noise of each coordinate of the measured target position t_CT (m).
    translation_sigma: typing.Optional[float] = None
    #: P0 diagonal of the X_CE error [δθ (rad²); δt (m²)] after the two-motion start.
    initial_variances: list[float] = field(
        default_factory=lambda: [math.radians(1.0) ** 2] * 3 + [0.01**2] * 3)
    #: Prior variances of the target pose error [δθ (rad²); δt (m²)]: nearly unknown.
    target_prior_variances: list[float] = field(default_factory=lambda: [1.0] * 6)
    #: Process noise diagonal of X_CE (6), added before every update; empty = 0.
    process_variances: list[float] = field(default_factory=list)
    gate_probability: typing.Optional[float] = defaults.GATE_PROBABILITY
    iterations: int = defaults.ITERATIONS
    max_consecutive_rejections: typing.Optional[int] = defaults.MAX_CONSECUTIVE_REJECTIONS
    #: Use the covariance each measurement comes with (e.g. a target detector's, from its PnP
    #: Jacobian) instead of the fixed sigmas, when the measurement has one.
    use_measurement_covariance: bool = False
    replay_self_calibration: bool = True

    def validated(self, prefix: str = "TargetFilter") -> "TargetFilter":
        return replace(
            self,
            rotation_sigma=_sigma(self.rotation_sigma, f"{prefix}.rotation_sigma", False),
            translation_sigma=_sigma(self.translation_sigma, f"{prefix}.translation_sigma",
                                     False),
            initial_variances=_variances(self.initial_variances, f"{prefix}.initial_variances",
                                         6, False),
            target_prior_variances=_variances(self.target_prior_variances,
                                              f"{prefix}.target_prior_variances", 6, False),
            process_variances=_variances(self.process_variances, f"{prefix}.process_variances",
                                         6, True),
            gate_probability=_probability(self.gate_probability, f"{prefix}.gate_probability"),
            iterations=_integer(self.iterations, f"{prefix}.iterations", 1, 100),
            max_consecutive_rejections=None if self.max_consecutive_rejections is None else
            _integer(self.max_consecutive_rejections, f"{prefix}.max_consecutive_rejections", 1,
                     10**6),
            use_measurement_covariance=bool(self.use_measurement_covariance),
            replay_self_calibration=bool(self.replay_self_calibration))


#: The estimator settings a scenario can select (the first is the default).
EstimatorConfig = typing.Union[TargetFilter, ManifoldFilter, PaperFilter]
ESTIMATOR_CONFIGS = (TargetFilter, ManifoldFilter, PaperFilter)

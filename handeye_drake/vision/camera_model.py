"""Pinhole camera model, point-feature interaction matrices and the IBVS law (numpy only).

Conventions (see the project README and docs/method.md §7):

* Camera frame C: origin at the optical centre, +z along the optical axis (points in front of the
  camera have z > 0), +x towards increasing u (image columns), +y towards increasing v (rows).
* Normalized coordinates of a point Q: (x, y) = (X/Z, Y/Z) with p_CQ = (X, Y, Z).
* Pixels: [u, v, 1]ᵀ = K [x, y, 1]ᵀ with Faugeras' intrinsic matrix

      K = | α_u   −α_u cot θ    u0 |
          | 0      α_v / sin θ  v0 |
          | 0      0            1  |

  (θ is the angle between the image axes; θ = π/2 means no skew). A pixel (u, v) is inside the
  image when 0 ≤ u < width and 0 ≤ v < height.
* Twists are ordered like Drake's SpatialVelocity, [ω; v] (angular first). ``V_C`` is the
  camera's spatial velocity in the world expressed in C (at C's origin); ``V_E`` likewise for the
  end-effector frame E.
* The paper's hand-eye X is ``X_CE`` (E measured in C); the camera-on-the-hand pose is
  ``X_EC`` = inv(X_CE).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..estimation.se3 import inverse, rotation_exp, twist_transform
from ..estimation.validation import as_matrix, as_transform, check_positive

#: Points with depth Z ≤ MIN_DEPTH (in the length unit of the poses) are not projected: they are
#: behind the camera or so close to its centre that x = X/Z would blow up.
MIN_DEPTH = 1e-6

#: |θ − π/2| must stay below π/2 − SKEW_MARGIN: near θ = 0 or π the term α_v / sin θ explodes and
#: K becomes numerically singular.
SKEW_MARGIN = 1e-3


@dataclasses.dataclass(frozen=True)
class CameraIntrinsics:
    """Intrinsic parameters of a pinhole camera (Faugeras convention, see the module docstring).

    Attributes:
        alpha_u, alpha_v: scale factors, pixels per unit of normalized coordinate (> 0).
        theta: angle between the image axes in radians, in (0, π); π/2 means no skew.
        u0, v0: principal point in pixels.
        width, height: image size in pixels (integers ≥ 1).
        distortion: OpenCV's distortion coefficients (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2,
            s3, s4[, τx, τy]]]]): 0, 4, 5, 8, 12 or 14 numbers; () means none. Only the OpenCV
            based functions (``vision.detection``, ``vision.intrinsics``) apply it; the pinhole
            functions of this module (projection, interaction matrices, IBVS) use K alone.
    """

    alpha_u: float
    alpha_v: float
    theta: float = math.pi / 2
    u0: float = 320.0
    v0: float = 240.0
    width: int = 640
    height: int = 480
    distortion: tuple = ()

    def __post_init__(self):
        self.validate()

    @classmethod
    def from_fov(cls, width: int, height: int, fov_y: float) -> "CameraIntrinsics":
        """A skew-free camera with square pixels, principal point at the image centre and vertical
        field of view ``fov_y`` (radians, in (0, π))."""
        fov_y = check_positive(fov_y, "fov_y")
        if fov_y >= math.pi:
            raise ValueError(f"fov_y: must be < π, got {fov_y!r}")
        height_f = check_positive(height, "height")
        f = 0.5 * height_f / math.tan(0.5 * fov_y)
        return cls(alpha_u=f, alpha_v=f, theta=math.pi / 2, u0=0.5 * float(width),
                   v0=0.5 * height_f, width=width, height=height)

    @classmethod
    def from_matrix(cls, K, width: int, height: int, distortion=()) -> "CameraIntrinsics":
        """From a 3×3 intrinsic matrix (OpenCV's camera matrix, skew allowed, K[2] = [0, 0, 1]),
        the image size and OpenCV distortion coefficients."""
        K = as_matrix(K, "K", (3, 3))
        if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
            raise ValueError(f"K: expected an upper-triangular intrinsic matrix with last row "
                             f"[0, 0, 1], got {K.tolist()}")
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError(f"K: focal lengths K[0,0] and K[1,1] must be > 0, got "
                             f"{K[0, 0]!r}, {K[1, 1]!r}")
        theta = math.atan2(K[0, 0], -K[0, 1])  # K[0,1] = −α_u cot θ
        return cls(alpha_u=K[0, 0], alpha_v=K[1, 1] * math.sin(theta), theta=theta, u0=K[0, 2],
                   v0=K[1, 2], width=width, height=height, distortion=distortion)

    @property
    def distortion_coefficients(self) -> np.ndarray | None:
        """The distortion as an array for OpenCV's ``distCoeffs``, None when there is none."""
        return np.array(self.distortion, dtype=float) if self.distortion else None

    def validate(self) -> None:
        """Raises ValueError naming the offending field. Also normalizes the field types (floats,
        and ints for the image size) so equal cameras compare equal."""
        values = {}
        for name in ("alpha_u", "alpha_v", "theta", "u0", "v0", "width", "height"):
            raw = getattr(self, name)
            try:
                value = float(raw)
            except (TypeError, ValueError):
                raise ValueError(f"CameraIntrinsics.{name}: expected a number, got {raw!r}") \
                    from None
            if not math.isfinite(value):
                raise ValueError(f"CameraIntrinsics.{name}: must be finite, got {raw!r}")
            values[name] = value
        for name in ("alpha_u", "alpha_v"):
            if values[name] <= 0:
                raise ValueError(f"CameraIntrinsics.{name}: scale factor must be > 0, got "
                                 f"{values[name]!r}")
        theta = values["theta"]
        if abs(theta - math.pi / 2) >= math.pi / 2 - SKEW_MARGIN:
            raise ValueError(
                f"CameraIntrinsics.theta: angle between image axes must lie in "
                f"({SKEW_MARGIN:g}, π − {SKEW_MARGIN:g}) rad (π/2 = no skew), got {theta!r}; "
                f"near 0 or π the intrinsic matrix K is singular")
        for name in ("width", "height"):
            if values[name] < 1 or values[name] != round(values[name]):
                raise ValueError(f"CameraIntrinsics.{name}: image size must be an integer ≥ 1 "
                                 f"pixel, got {getattr(self, name)!r}")
            values[name] = int(round(values[name]))
        values["distortion"] = _validate_distortion(self.distortion)
        for name, value in values.items():
            object.__setattr__(self, name, value)

    @property
    def K(self) -> np.ndarray:
        """3×3 intrinsic matrix (see the module docstring)."""
        # Exactly 0 without skew (1/tan(π/2) is 6e-17 in floating point).
        skew = 0.0 if self.theta == math.pi / 2 else -self.alpha_u / math.tan(self.theta)
        return np.array([
            [self.alpha_u, skew, self.u0],
            [0.0, self.alpha_v / math.sin(self.theta), self.v0],
            [0.0, 0.0, 1.0],
        ])

    @property
    def K_inv(self) -> np.ndarray:
        return np.linalg.inv(self.K)


#: Lengths of OpenCV's distortion vectors (plumb bob with or without k3, rational, thin prism,
#: tilted sensor).
DISTORTION_LENGTHS = (0, 4, 5, 8, 12, 14)


def _validate_distortion(raw) -> tuple:
    if isinstance(raw, (str, bytes)):
        raise ValueError(f"CameraIntrinsics.distortion: expected a sequence of numbers, got "
                         f"{raw!r}")
    try:
        d = np.asarray(raw if raw is not None else (), dtype=float).ravel()
    except (TypeError, ValueError):
        raise ValueError(f"CameraIntrinsics.distortion: expected a sequence of numbers, got "
                         f"{raw!r}") from None
    if d.size not in DISTORTION_LENGTHS:
        lengths = ", ".join(map(str, DISTORTION_LENGTHS))
        raise ValueError(f"CameraIntrinsics.distortion: OpenCV takes {lengths} "
                         f"coefficients (k1, k2, p1, p2[, k3[, k4, k5, k6…]]), got {d.size}")
    if not np.all(np.isfinite(d)):
        raise ValueError(f"CameraIntrinsics.distortion: must be finite, got {d.tolist()}")
    return tuple(float(v) for v in d)


def _check_intrinsics(intrinsics, name: str = "intrinsics") -> CameraIntrinsics:
    if not isinstance(intrinsics, CameraIntrinsics):
        raise ValueError(f"{name}: expected a CameraIntrinsics, got {type(intrinsics).__name__}")
    return intrinsics


def as_points(value, name: str, dim: int) -> np.ndarray:
    """An N×dim finite float array (a single point of length ``dim`` is promoted to 1×dim)."""
    try:
        M = np.array(value, dtype=float)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name}: expected a numeric N×{dim} array ({e})") from None
    if M.ndim == 1 and M.shape[0] == dim:
        M = M.reshape(1, dim)
    if M.ndim != 2 or M.shape[1] != dim:
        raise ValueError(f"{name}: expected shape (N, {dim}), got {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    return M


def _as_depths(Z, name: str, n: int) -> np.ndarray:
    Z = as_matrix(np.atleast_1d(Z), name, (n,))
    if np.any(Z <= 0):
        raise ValueError(f"{name}: depths must be > 0 (point in front of the camera), got min "
                         f"{Z.min():g}")
    return Z


def project_points(p_CQ, intrinsics: CameraIntrinsics, min_depth: float = MIN_DEPTH):
    """Projects points given in the camera frame onto the image.

    Args:
        p_CQ: N×3 points (a single 3-vector is accepted as 1×3).
        intrinsics: the camera.
        min_depth: points with Z ≤ min_depth are not projected.

    Returns:
        (uv, in_front, in_image): N×2 pixel coordinates (0 for points not in front), N booleans
        Z > min_depth, and N booleans "in front and 0 ≤ u < width and 0 ≤ v < height".
    """
    intrinsics = _check_intrinsics(intrinsics)
    p_CQ = as_points(p_CQ, "p_CQ", 3)
    min_depth = check_positive(min_depth, "min_depth")
    Z = p_CQ[:, 2]
    in_front = Z > min_depth
    uv = np.zeros((p_CQ.shape[0], 2))
    if np.any(in_front):
        xy = p_CQ[in_front, :2] / Z[in_front, None]
        uv[in_front] = xy @ intrinsics.K[:2, :2].T + [intrinsics.u0, intrinsics.v0]
    in_image = (in_front & (uv[:, 0] >= 0) & (uv[:, 0] < intrinsics.width)
                & (uv[:, 1] >= 0) & (uv[:, 1] < intrinsics.height))
    return uv, in_front, in_image


def normalized_from_pixels(uv, intrinsics: CameraIntrinsics) -> np.ndarray:
    """N×2 normalized coordinates (x, y) of N×2 pixels (inverse of the projection's K)."""
    intrinsics = _check_intrinsics(intrinsics)
    uv = as_points(uv, "uv", 2)
    A = intrinsics.K[:2, :2]
    return np.linalg.solve(A, (uv - [intrinsics.u0, intrinsics.v0]).T).T


def point_interaction_matrix(x, y, Z) -> np.ndarray:
    """2×6 interaction matrix L of a world-fixed point seen at normalized coordinates (x, y) and
    depth Z: ṡ = L · V_C with s = (x, y) and V_C = [ω; v] the camera's spatial velocity expressed
    in C. This is the Espiau–Chaumette–Rives matrix with its columns reordered from [v; ω]."""
    try:
        x, y, Z = float(x), float(y), float(Z)
    except (TypeError, ValueError):
        raise ValueError(f"point_interaction_matrix: x, y, Z must be numbers, got "
                         f"{x!r}, {y!r}, {Z!r}") from None
    if not all(math.isfinite(a) for a in (x, y, Z)):
        raise ValueError(f"point_interaction_matrix: x, y, Z must be finite, got {x}, {y}, {Z}")
    if Z <= 0:
        raise ValueError(f"Z: depth must be > 0 (point in front of the camera), got {Z!r}")
    return np.array([
        #  ω_x        ω_y           ω_z   v_x      v_y      v_z
        [x * y, -(1.0 + x * x), y, -1.0 / Z, 0.0, x / Z],
        [1.0 + y * y, -x * y, -x, 0.0, -1.0 / Z, y / Z],
    ])


def pixel_interaction_matrix(uv, Z, intrinsics: CameraIntrinsics) -> np.ndarray:
    """2N×6 matrix mapping the camera twist V_C = [ω; v] (in C) to the pixel velocities
    [u̇0, v̇0, u̇1, v̇1, …] of N world-fixed points seen at pixels ``uv`` (N×2) with depths ``Z``
    (N, > 0)."""
    intrinsics = _check_intrinsics(intrinsics)
    uv = as_points(uv, "uv", 2)
    Z = _as_depths(Z, "Z", uv.shape[0])
    xy = normalized_from_pixels(uv, intrinsics)
    A = intrinsics.K[:2, :2]
    L = np.empty((2 * uv.shape[0], 6))
    for i, ((x, y), z) in enumerate(zip(xy, Z)):
        L[2 * i:2 * i + 2] = A @ point_interaction_matrix(x, y, z)
    return L


def end_effector_interaction_matrix(uv, Z, intrinsics: CameraIntrinsics, X_CE) -> np.ndarray:
    """2N×6 matrix mapping the end-effector twist V_E = [ω; v] (expressed in E) to pixel
    velocities: the paper's Lᵀ (§7), = pixel_interaction_matrix · twist_transform(X_CE).

    ``X_CE`` (4×4 or RigidTransform) is the hand-eye transform, i.e. where the current estimate
    enters the control law. Its rotation block is used as given (it should be a rotation: feed the
    orthonormalized estimate), only finiteness and the homogeneous last row are checked."""
    X_CE = as_transform(X_CE, "X_CE", rigid=False)
    return pixel_interaction_matrix(uv, Z, intrinsics) @ twist_transform(X_CE)


def target_visibility(intrinsics: CameraIntrinsics, X_WE, X_EC, p_TQ, X_WT,
                      min_depth: float = MIN_DEPTH):
    """Projects the target points for an end-effector pose (pure geometry, no noise).

    Returns (uv, in_front, in_image) as ``project_points`` does, for p_CQ = inv(X_WE X_EC) X_WT
    p_TQ. A scenario can use it to fail early when the target is not in view at the start pose.
    """
    X_WE = as_transform(X_WE, "X_WE")
    X_EC = as_transform(X_EC, "X_EC")
    X_WT = as_transform(X_WT, "X_WT")
    p_TQ = as_points(p_TQ, "p_TQ", 3)
    X_CT = inverse(X_WE @ X_EC) @ X_WT
    p_CQ = p_TQ @ X_CT[:3, :3].T + X_CT[:3, 3]
    return project_points(p_CQ, intrinsics, min_depth)


POSE_NOISE_MODELS = ("paper", "so3")


def apply_pose_noise(X_CT, noise, model: str, rotation_sigma: float,
                     translation_sigma: float) -> np.ndarray:
    """Noisy measurement of the target pose X_CT from 12 standard-normal samples ``noise``.

    * ``"paper"`` (docs/method.md §5): R += rotation_sigma · reshape(noise[:9], 3×3) (row-major),
      additive on each coefficient and deliberately NOT re-orthonormalized.
    * ``"so3"``: R ← exp(rotation_sigma · noise[:3]) · R, a rotation-vector perturbation (radians,
      expressed in C), so R stays a rotation.

    In both models p += translation_sigma · noise[9:12]. Returns a 4×4 array.
    """
    X_CT = as_transform(X_CT, "X_CT", rigid=False)
    noise = as_matrix(noise, "noise", (12,))
    rotation_sigma = check_positive(rotation_sigma, "rotation_sigma", allow_zero=True)
    translation_sigma = check_positive(translation_sigma, "translation_sigma", allow_zero=True)
    X = X_CT.copy()
    if model == "paper":
        X[:3, :3] = X_CT[:3, :3] + rotation_sigma * noise[:9].reshape(3, 3)
    elif model == "so3":
        X[:3, :3] = rotation_exp(rotation_sigma * noise[:3]) @ X_CT[:3, :3]
    else:
        raise ValueError(f"model: unknown pose noise model {model!r}, expected one of "
                         f"{POSE_NOISE_MODELS}")
    X[:3, 3] = X_CT[:3, 3] + translation_sigma * noise[9:12]
    return X


def saturate_twist(V, max_angular_speed: float = math.inf,
                   max_linear_speed: float = math.inf) -> np.ndarray:
    """Scales the whole twist [ω; v] by one factor ≤ 1 so that ‖ω‖ ≤ max_angular_speed and
    ‖v‖ ≤ max_linear_speed (the direction of the screw is kept)."""
    V = as_matrix(V, "V", (6,))
    scale = 1.0
    w, v = np.linalg.norm(V[:3]), np.linalg.norm(V[3:])
    if w > max_angular_speed:
        scale = min(scale, max_angular_speed / w)
    if v > max_linear_speed:
        scale = min(scale, max_linear_speed / v)
    return scale * V


def ibvs_twist(uv, uv_desired, Z, intrinsics: CameraIntrinsics, X_CE, gain: float,
               visible=None, rcond: float = 1e-10) -> np.ndarray:
    """Image-based visual servo law of the paper (§7): V_E = −λ · pinv(L_E) (s − s*).

    Args:
        uv, uv_desired: N×2 current and desired pixels (or flat 2N vectors u0, v0, u1, …).
        Z: N current depths (only those of the used points must be > 0).
        intrinsics: the camera (may be rough).
        X_CE: hand-eye estimate (E in C), the paper's X.
        gain: λ in 1/s (> 0).
        visible: optional N booleans; only these points enter the law.
        rcond: relative cutoff of the pseudo-inverse's singular values.

    Returns:
        The end-effector twist [ω; v] expressed in E (6,), unsaturated.
    """
    uv = as_points(np.reshape(uv, (-1, 2)) if np.ndim(uv) == 1 else uv, "uv", 2)
    n = uv.shape[0]
    uv_desired = as_points(np.reshape(uv_desired, (-1, 2)) if np.ndim(uv_desired) == 1
                            else uv_desired, "uv_desired", 2)
    if uv_desired.shape != uv.shape:
        raise ValueError(f"uv_desired: expected {n} points like uv, got {uv_desired.shape[0]}")
    Z = as_matrix(Z, "Z", (n,))
    gain = check_positive(gain, "gain")
    mask = np.ones(n, bool) if visible is None else as_matrix(visible, "visible", (n,)) != 0
    if not np.any(mask):
        raise ValueError("visible: no point is visible, the servo law is undefined")
    L = end_effector_interaction_matrix(uv[mask], Z[mask], intrinsics, X_CE)
    error = (uv[mask] - uv_desired[mask]).reshape(-1)
    return -gain * (np.linalg.pinv(L, rcond=rcond) @ error)


@dataclasses.dataclass(frozen=True)
class SelfCalibrationMotion:
    """A predefined rotation of the end-effector by ``angle`` (rad) about the axis through
    ``pivot_E`` (a point fixed in E, length units) with direction ``axis_E`` (normalized on
    construction), executed at constant speed in ``duration`` seconds.

    The commanded twist, expressed in E, is ω = (angle/duration)·axis_E and v = −ω × pivot_E (so the
    pivot does not move)."""

    axis_E: tuple
    angle: float
    pivot_E: tuple = (0.0, 0.0, 0.0)
    duration: float = 1.0

    def __post_init__(self):
        axis = as_matrix(self.axis_E, "SelfCalibrationMotion.axis_E", (3,))
        norm = np.linalg.norm(axis)
        if norm < 1e-9:
            raise ValueError(f"SelfCalibrationMotion.axis_E: rotation axis must be non-zero, got "
                             f"{axis.tolist()}")
        pivot = as_matrix(self.pivot_E, "SelfCalibrationMotion.pivot_E", (3,))
        try:
            angle = float(self.angle)
        except (TypeError, ValueError):
            raise ValueError(f"SelfCalibrationMotion.angle: expected a number, got "
                             f"{self.angle!r}") from None
        if not math.isfinite(angle):
            raise ValueError(f"SelfCalibrationMotion.angle: must be finite, got {self.angle!r}")
        duration = check_positive(self.duration, "SelfCalibrationMotion.duration")
        object.__setattr__(self, "axis_E", tuple((axis / norm).tolist()))
        object.__setattr__(self, "pivot_E", tuple(pivot.tolist()))
        object.__setattr__(self, "angle", angle)
        object.__setattr__(self, "duration", duration)

    def twist_E(self) -> np.ndarray:
        """Constant commanded twist [ω; v] expressed in E."""
        w = (self.angle / self.duration) * np.asarray(self.axis_E)
        return np.concatenate([w, -np.cross(w, np.asarray(self.pivot_E))])


def default_self_calibration_motions(pivot_E, angle: float = math.radians(15.0),
                                     duration: float = 1.0,
                                     axes_E=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))):
    """The paper's two self-calibration motions: rotations about two non-parallel axes (needed for
    a unique two-motion solution), here about E's x and y axes through ``pivot_E``. Choosing the
    target centre (expressed in E at the start pose) as the pivot keeps the target in view."""
    return [SelfCalibrationMotion(axis_E=tuple(a), angle=angle, pivot_E=tuple(pivot_E),
                                  duration=duration) for a in axes_E]


__all__ = [
    "DISTORTION_LENGTHS",
    "MIN_DEPTH",
    "POSE_NOISE_MODELS",
    "CameraIntrinsics",
    "apply_pose_noise",
    "SelfCalibrationMotion",
    "default_self_calibration_motions",
    "end_effector_interaction_matrix",
    "ibvs_twist",
    "normalized_from_pixels",
    "pixel_interaction_matrix",
    "point_interaction_matrix",
    "project_points",
    "saturate_twist",
    "target_visibility",
]

"""Observability of the hand-eye transform from a set of robot poses, and partial calibration.

Which parts of the hand-eye pose a recording determines, and how well, follows from the Fisher
information of the maximum-likelihood pose form (``ml.refine_ml_poses``, AX = ZB)

    X_CT_k = X_CH · Y_k · X_FT ⊕ noise,

with the robot pose Y_k, the camera's holder H (the robot frame the camera is rigidly attached
to) and the target's fixture F (the robot frame the target is fixed in):

==============  ============  =======================  ============  ============
mode            Y_k           X_CH (hand-eye unknown)  X_FT          named in
==============  ============  =======================  ============  ============
"eye_in_hand"   X_EB = X_BE⁻¹  X_CE (X_HC = X_EC)       X_BT          E
"eye_to_hand"   X_BE          X_CB (X_HC = X_BC)       X_ET          B
==============  ============  =======================  ============  ============

The information matrix (12×12, error state [δθ_CH; δt_CH; δθ_FT; δt_FT], left perturbations
R = exp(δθ) R̂, t = t̂ + δt) depends on the robot poses, the rotation of X_CH and the translations
only; it does not depend on the measurements. ``analyze_observability`` marginalizes the target
pose out (Schur complement: what the data says about the hand-eye pose whatever the target pose
is), expresses it for X_HC about and along the axes of H, and names the directions that the
data does not determine (zero information) or determines much worse than the others.

The classic degeneracies, in plain words (eye-in-hand):

- every robot rotation about parallel axes (a SCARA / 4-DOF robot, or a 6-DOF arm that only
  turns its last joint): the camera's translation along that axis is unobservable — moving the
  camera along the axis and the target by the same amount explains the data as well;
- rotation axes only a few degrees apart: the same direction is weakly determined, its standard
  deviation growing like 1 / (axis spread);
- no rotation at all: the camera position on the hand is unobservable.

``refine_ml_poses_fixed`` solves the pose-form ML problem with components of X_HC held at known
values (``parse_fixed("tz=0.052,yaw_deg=90")``): the translation of X_HC along H's axes (tx, ty,
tz, metres) and its roll-pitch-yaw angles (Drake's RollPitchYaw, extrinsic X-Y-Z, as URDF
``<origin rpy>``). Yaw is the rotation about H's z axis, exactly (a left perturbation of yaw is
exp(δ e_z) R), so a weak "rotation about H z" is fixed by ``yaw``. The covariance of the result
is the inverse of the constrained information: zero variance on the fixed components, honest
variances for the others *given* the fixed values.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from .se3 import inverse_tangent_jacobian
from .ml import (_check_noise, _measured_rotations, _pose_residual_summary,
                 _pose_terms, left_jacobian, pose_jacobians, pose_whitening)
from .se3 import inverse, make_transform, rotation_exp, rotation_from_rpy, rotation_log, rpy
from .solvers import calibrate_hand_eye
from .validation import as_transform, as_transform_list, check_positive, check_same_length

MODES = ("eye_in_hand", "eye_to_hand")

#: The frame in which each mode names directions and fixed components (the camera's holder).
HOLDER_FRAME = {"eye_in_hand": "E", "eye_to_hand": "B"}

#: Components of X_HC that ``fixed=`` may hold: translation in H (metres), roll-pitch-yaw (rad).
COMPONENTS = ("tx", "ty", "tz", "roll", "pitch", "yaw")

#: A direction whose (normalized) information is below this fraction of the largest is
#: unobservable: the data carries no information about it (numerically zero).
UNOBSERVABLE_RELATIVE_INFORMATION = 1e-9

#: Default ratio of standard deviations above which a direction counts as weak.
WEAK_RATIO = 10.0

#: Robot motions rotating less than this have no meaningful axis in the motion check (rad).
_MIN_AXIS_ROTATION = math.radians(0.5)

#: Rotation axes whose spread (``MotionCheck.axis_spread_deg``) is below this are parallel (rad).
PARALLEL_AXES = math.radians(1.0)

#: ... and below this nearly parallel, the cause named for weak directions (rad).
NEARLY_PARALLEL_AXES = math.radians(10.0)

#: Rotations below this (largest motion) are "small", the cause named for weak directions (rad).
SMALL_ROTATION = math.radians(5.0)

#: Largest number of samples whose pairwise motions the motion check uses (evenly subsampled).
_MAX_CHECK_SAMPLES = 60

#: Translations of a fixed component beyond this (metres) are refused as implausible.
_MAX_FIXED_TRANSLATION = 10.0


class UnobservableError(ValueError):
    """The data does not determine some free component of the hand-eye pose; ``report`` (an
    ``ObservabilityReport``) names the directions."""

    def __init__(self, message: str, report: "ObservabilityReport"):
        super().__init__(message)
        self.report = report


def check_mode(mode) -> str:
    if mode not in MODES:
        raise ValueError(f"mode: expected one of {MODES}, got {mode!r}")
    return mode


def robot_side_poses(X_BE_list, mode: str = "eye_in_hand", name: str = "X_BE_list") -> np.ndarray:
    """(K, 4, 4) robot poses as they enter the model: Y_k = X_EB (eye-in-hand) or X_BE
    (eye-to-hand)."""
    check_mode(mode)
    X_BE = as_transform_list(X_BE_list, name, rigid=True)
    if mode == "eye_in_hand":
        return np.array([inverse(X) for X in X_BE]).reshape(-1, 4, 4)
    return np.array(X_BE).reshape(-1, 4, 4)


def sample_jacobians(X_BE_list, X_CH, X_FT, rotation_sigma: float, translation_sigma: float,
                     mode: str = "eye_in_hand", noise_model: str = "so3") -> np.ndarray:
    """(K, m, 12) whitened Jacobian of each sample's residual (``ml.pose_jacobians``) with
    respect to [δθ_CH; δt_CH; δθ_FT; δt_FT]; see the module docstring for H, F and the modes."""
    Y = robot_side_poses(X_BE_list, mode)
    X_CH = as_transform(X_CH, "X_CH")
    X_FT = as_transform(X_FT, "X_FT")
    return pose_jacobians(Y, X_CH, X_FT, rotation_sigma, translation_sigma, noise_model)


def information_matrix(X_BE_list, X_CH, X_FT, rotation_sigma: float, translation_sigma: float,
                       mode: str = "eye_in_hand", noise_model: str = "so3") -> np.ndarray:
    """Fisher information (12×12) of the pose-form ML fit for the robot poses ``X_BE_list``.

    Args:
        X_BE_list: K end-effector poses in the robot base (rigid; K may be 0).
        X_CH: the hand-eye estimate, X_CE (eye-in-hand) or X_CB (eye-to-hand), 4×4 rigid.
        X_FT: the target pose estimate, X_BT (eye-in-hand) or X_ET (eye-to-hand), 4×4 rigid
            (only its translation matters).
        rotation_sigma: std of the camera pose's rotation-vector noise (rad, "so3") or of its
            rotation coefficients ("paper").
        translation_sigma: std of each coordinate of the camera pose's translation noise (m).
        mode: "eye_in_hand" or "eye_to_hand".
        noise_model: "so3" or "paper" (``ml.NOISE_MODELS``).

    Returns:
        Σ_k H_kᵀ H_k over [δθ_CH (rad); δt_CH (m); δθ_FT; δt_FT], left perturbations
        (R = exp(δθ) R̂, t = t̂ + δt). Its inverse, when it exists, is the Cramér–Rao bound of
        ``ml.refine_ml_poses``'s ``full_covariance``.

    Raises:
        ValueError: naming the argument (malformed poses, bad sigmas, unknown mode/noise model).
    """
    check_mode(mode)
    _check_noise(noise_model, rotation_sigma, translation_sigma)
    X_BE = as_transform_list(X_BE_list, "X_BE_list", rigid=True)
    if not X_BE:
        return np.zeros((12, 12))
    H = sample_jacobians(X_BE, X_CH, X_FT, rotation_sigma, translation_sigma, mode, noise_model)
    info = np.einsum("kmi,kmj->ij", H, H)
    return 0.5 * (info + info.T)


def _check_information(info, n: int = 12) -> np.ndarray:
    try:
        M = np.array(info, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"info: expected a {n}×{n} numeric matrix, got "
                         f"{type(info).__name__}") from None
    if M.shape != (n, n):
        raise ValueError(f"info: expected shape ({n}, {n}), got {M.shape}")
    if not np.all(np.isfinite(M)):
        raise ValueError("info: contains NaN or infinite values")
    scale = max(1.0, float(np.abs(M).max()))
    if not np.allclose(M, M.T, rtol=1e-9, atol=1e-12 * scale):
        raise ValueError("info: an information matrix must be symmetric")
    M = 0.5 * (M + M.T)
    if np.linalg.eigvalsh(M)[0] < -1e-9 * scale:
        raise ValueError("info: an information matrix must be positive semi-definite")
    return M


def marginal_information(info) -> np.ndarray:
    """Information (6×6) on the hand-eye error state [δθ_CH; δt_CH] with the target pose
    marginalized out: the Schur complement I_hh − I_ht I_tt⁻¹ I_th (I_tt pseudo-inverted when
    singular, i.e. without samples)."""
    return _schur(_check_information(info), 6)


def holder_information(S_CH, X_CH) -> np.ndarray:
    """The 6×6 information ``S_CH`` on X_CH's error state re-expressed for X_HC = X_CH⁻¹ (the
    camera in its holder): [δθ_HC (rad, about H's axes); δt_HC (m, along H's axes)]."""
    J_inv = inverse_tangent_jacobian(inverse(X_CH))  # δ_CH = J_inv δ_HC
    S = J_inv.T @ S_CH @ J_inv
    return 0.5 * (S + S.T)


# ------------------------------------------------------------------------------ motion check
@dataclass
class MotionCheck:
    """How the robot rotates between the samples, the usual cause of weak directions.

    Attributes:
        num_samples: samples used (at most 60, evenly subsampled).
        num_motions: motions between sample pairs rotating at least 0.5°.
        max_angle_deg, median_angle_deg: their rotation angles.
        common_axis: (3,) unit principal direction of their rotation vectors, in H.
        axis_spread_deg: RMS angle of their rotation axes from that common line, each motion
            weighted by its rotation angle: atan(√(s₂² + s₃²) / s₁) with s the singular values
            below (0 when all rotations are about parallel axes, 54.7° for an even spread).
        axis_singular_values: singular values of the stacked rotation vectors (rad) of the
            motions, largest first.
        axis_condition_number: their ratio largest / smallest (inf when the axes span less than
            3 dimensions): how unevenly the motions rotate about H's three axes.
    """
    num_samples: int
    num_motions: int
    max_angle_deg: float
    median_angle_deg: float
    common_axis: np.ndarray | None
    axis_spread_deg: float
    axis_singular_values: np.ndarray
    axis_condition_number: float

    @property
    def parallel_axes(self) -> bool:
        return self.num_motions > 0 and self.axis_spread_deg <= math.degrees(PARALLEL_AXES)

    @property
    def nearly_parallel_axes(self) -> bool:
        return self.num_motions > 0 and self.axis_spread_deg <= math.degrees(NEARLY_PARALLEL_AXES)

    @property
    def small_rotations(self) -> bool:
        return self.max_angle_deg < math.degrees(SMALL_ROTATION)


def check_robot_motions(X_BE_list, mode: str = "eye_in_hand") -> MotionCheck:
    """Rotation angles and axis spread of the motions between every pair of samples (in H: E for
    eye-in-hand, B for eye-to-hand)."""
    Y = robot_side_poses(X_BE_list, mode)
    if len(Y) < 2:
        raise ValueError(f"X_BE_list: the motion check needs at least 2 poses, got {len(Y)}")
    if len(Y) > _MAX_CHECK_SAMPLES:
        Y = Y[np.round(np.linspace(0, len(Y) - 1, _MAX_CHECK_SAMPLES)).astype(int)]
    i, j = np.triu_indices(len(Y), 1)
    # Motion between samples i and j of the holder frame: Y_i Y_j⁻¹ (rotation axis in H).
    R = Y[i, :3, :3] @ np.transpose(Y[j, :3, :3], (0, 2, 1))
    rv = np.array([rotation_log(r) for r in R]).reshape(-1, 3)
    th = np.linalg.norm(rv, axis=1)
    largest = float(np.degrees(th.max()))
    rv, th = rv[th >= _MIN_AXIS_ROTATION], th[th >= _MIN_AXIS_ROTATION]
    if len(th) == 0:
        return MotionCheck(len(Y), 0, largest, 0.0, None, 0.0, np.zeros(3), math.inf)
    # The common line and the spread come from the stacked rotation vectors, so that each motion
    # weighs by its angle: a small motion has a poorly defined axis and carries little
    # information about the hand-eye rotation anyway.
    _, s, Vt = np.linalg.svd(rv, full_matrices=False)
    s = np.concatenate([s, np.zeros(3 - len(s))])
    u = Vt[0]
    spread = math.atan2(math.hypot(s[1], s[2]), s[0])
    cond = float(s[0] / s[2]) if s[2] > 1e-12 * s[0] else math.inf
    return MotionCheck(len(Y), len(th), float(np.degrees(th.max())),
                       float(np.degrees(np.median(th))), u, float(np.degrees(spread)), s, cond)


# ------------------------------------------------------------------------------ the report
def axis_name(v, frame: str) -> str:
    """'E z' when the line of ``v`` is within 10° of an axis of the frame, else the unit vector."""
    v = np.asarray(v, dtype=float)
    v = v / np.linalg.norm(v)
    k = int(np.argmax(np.abs(v)))
    if abs(v[k]) >= math.cos(math.radians(10.0)):
        return f"{frame} {'xyz'[k]}"
    v = v if v[k] > 0 else -v
    return f"{frame} [{v[0]:+.2f}, {v[1]:+.2f}, {v[2]:+.2f}]"


@dataclass(eq=False)
class Direction:
    """One principal direction of the hand-eye information (an eigenvector).

    Attributes:
        vector: (6,) unit eigenvector in normalized coordinates [δθ_HC (rad); δt_HC / L].
        information: its eigenvalue in those coordinates.
        kind: "rotation", "translation" or "mixed" (both parts above 5 % of the vector).
        rotation_axis, translation_axis: unit directions (in H) of its rotation and translation
            parts (None when that part is negligible).
        rotation_std_deg, translation_std: standard deviations of the rotation (deg) and
            translation (m) an error along this direction has (inf when unobservable).
        status: "unobservable", "weak" or "ok".
        name: in plain words, e.g. "translation along E z".
    """
    vector: np.ndarray
    information: float
    kind: str
    rotation_axis: np.ndarray | None
    translation_axis: np.ndarray | None
    rotation_std_deg: float
    translation_std: float
    status: str
    name: str

    @property
    def std_text(self) -> str:
        if self.status == "unobservable":
            return "unobservable"
        parts = []
        if self.rotation_axis is not None:
            parts.append(f"{self.rotation_std_deg:.3g}°")
        if self.translation_axis is not None:
            parts.append(f"{1000 * self.translation_std:.3g} mm")
        return " / ".join(parts)


@dataclass
class ObservabilityReport:
    """What a set of robot poses determines about the hand-eye pose (``analyze_observability``).

    Attributes:
        mode: "eye_in_hand" or "eye_to_hand".
        frame: H, the frame directions are named in ("E" or "B").
        information: 6×6 marginal information on X_HC's error state [δθ (rad); δt (m)], about
            and along H's axes (target pose marginalized).
        length_scale: L (m), the length that makes rotations and translations comparable: a
            rotation error δ (rad) and a translation error L·δ count the same.
        directions: the six principal directions, least determined first.
        condition_number: largest / smallest normalized information (inf if singular).
        rotation_std_deg: (3,) marginal std of the rotation about H's x, y, z axes (deg); inf
            where the rotation about that axis is not determined.
        translation_std: (3,) marginal std of the translation along H's axes (m), inf likewise.
        motion: ``MotionCheck`` of the robot poses, None when they were not given.
        messages: plain-words findings (empty when everything is well determined).
    """
    mode: str
    frame: str
    information: np.ndarray
    length_scale: float
    directions: list
    condition_number: float
    rotation_std_deg: np.ndarray
    translation_std: np.ndarray
    motion: MotionCheck | None = None
    messages: list = field(default_factory=list)

    @property
    def unobservable(self) -> list:
        return [d for d in self.directions if d.status == "unobservable"]

    @property
    def weak(self) -> list:
        return [d for d in self.directions if d.status == "weak"]

    @property
    def observable(self) -> bool:
        """Every direction of the hand-eye pose is determined (possibly weakly)."""
        return not self.unobservable

    @property
    def ok(self) -> bool:
        """No unobservable and no weak direction."""
        return not self.unobservable and not self.weak

    def unobservable_translation_basis(self) -> np.ndarray:
        """(3, k) orthonormal basis (in H) of the unobservable pure translations."""
        t = [d.translation_axis for d in self.unobservable if d.kind == "translation"]
        if not t:
            return np.zeros((3, 0))
        U, s, _ = np.linalg.svd(np.array(t).T, full_matrices=False)
        return U[:, s > 1e-6]

    def suggested_fixes(self) -> list:
        """Components whose fixing (``fixed=``) removes the unobservable directions, when axes
        of H do: for k unobservable translations, the k translation components that best
        span them (kept if they do so well); yaw for a rotation about H z."""
        out = []
        N = self.unobservable_translation_basis()
        k = N.shape[1]
        if k:
            axes = sorted(np.argsort(-np.linalg.norm(N, axis=1))[:k])
            if abs(np.linalg.det(N[axes])) >= 0.5:
                out += ["t" + "xyz"[i] for i in axes]
        for d in self.unobservable:
            if d.kind == "rotation" and abs(d.rotation_axis[2]) >= math.cos(math.radians(10)):
                out.append("yaw_deg")
        return out

    def lines(self) -> list:
        """The report as printable lines."""
        out = [f"observability ({self.mode}, directions in {self.frame}; condition number "
               f"{self.condition_number:.3g} with L = {self.length_scale:.3g} m):"]
        rot = ", ".join("∞" if not math.isfinite(s) else f"{s:.3g}" for s in self.rotation_std_deg)
        tra = ", ".join("∞" if not math.isfinite(s) else f"{1000 * s:.3g}"
                        for s in self.translation_std)
        out.append(f"  σ rotation about {self.frame} x, y, z: [{rot}] deg; translation along "
                   f"{self.frame} x, y, z: [{tra}] mm")
        if self.motion is not None:
            m = self.motion
            common = axis_name(m.common_axis, self.frame) if m.common_axis is not None else "—"
            out.append(f"  robot motions: {m.num_motions} between {m.num_samples} samples rotate "
                       f"≥ 0.5° (largest {m.max_angle_deg:.1f}°, median "
                       f"{m.median_angle_deg:.1f}°); axis spread {m.axis_spread_deg:.2f}° about "
                       f"{common}, axis condition number {m.axis_condition_number:.3g}")
        out += [f"  {msg}" for msg in self.messages] or ["  every direction is well determined"]
        return out

    def summary(self) -> str:
        return "\n".join(self.lines())

    def to_dict(self) -> dict:
        """JSON-friendly summary (inf written as null)."""
        def num(x):
            return float(x) if math.isfinite(x) else None
        d = {"mode": self.mode, "frame": self.frame,
             "observable": self.observable, "weak": bool(self.weak), "ok": self.ok,
             "length_scale_m": self.length_scale,
             "condition_number": num(self.condition_number),
             "rotation_std_deg": [num(x) for x in self.rotation_std_deg],
             "translation_std_m": [num(x) for x in self.translation_std],
             "directions": [{"name": x.name, "status": x.status,
                             "rotation_std_deg": num(x.rotation_std_deg),
                             "translation_std_m": num(x.translation_std)}
                            for x in self.directions],
             "suggested_fixes": self.suggested_fixes(),
             "messages": list(self.messages)}
        if self.motion is not None:
            m = self.motion
            d["motion"] = {"num_motions": m.num_motions, "max_angle_deg": m.max_angle_deg,
                           "median_angle_deg": m.median_angle_deg,
                           "axis_spread_deg": m.axis_spread_deg,
                           "axis_condition_number": num(m.axis_condition_number)}
        return d


def _direction(v, lam, lam_max, L, frame, weak_ratio, limits) -> Direction:
    vr, vt = v[:3], v[3:]
    nr, nt = float(np.linalg.norm(vr)), float(np.linalg.norm(vt))
    r_axis = vr / nr if nr >= 0.05 else None
    t_axis = vt / nt if nt >= 0.05 else None
    kind = "mixed" if (r_axis is not None and t_axis is not None) else \
        ("rotation" if r_axis is not None else "translation")
    unobservable = lam <= UNOBSERVABLE_RELATIVE_INFORMATION * lam_max
    s = math.inf if unobservable else 1.0 / math.sqrt(lam)
    rot_std, trans_std = math.degrees(nr * s), nt * s * L
    weak = lam < lam_max / weak_ratio**2
    if limits[0] is not None and r_axis is not None and rot_std > limits[0]:
        weak = True
    if limits[1] is not None and t_axis is not None and trans_std > limits[1]:
        weak = True
    status = "unobservable" if unobservable else ("weak" if weak else "ok")
    parts = []
    if r_axis is not None:
        parts.append(f"rotation about {axis_name(r_axis, frame)}")
    if t_axis is not None:
        parts.append(f"translation along {axis_name(t_axis, frame)}")
    return Direction(v.copy(), float(lam), kind, r_axis, t_axis, rot_std, trans_std, status,
                     " coupled with ".join(parts))


def _cause(d: Direction, motion: MotionCheck | None, frame: str) -> str:
    if motion is None:
        return ""
    if motion.num_motions == 0:
        return "the robot does not rotate between the samples"
    ax = axis_name(motion.common_axis, frame)
    along_axis = d.translation_axis is not None and \
        abs(float(d.translation_axis @ motion.common_axis)) >= math.cos(math.radians(10.0))
    if motion.parallel_axes:
        what = "every rotation is about parallel axes"
        if along_axis and d.kind == "translation":
            what += " — typical of 4-DOF/SCARA robots"
        return f"{what} (axis spread {motion.axis_spread_deg:.2f}° about {ax})"
    if motion.nearly_parallel_axes:
        return (f"the rotation axes are nearly parallel (axis spread {motion.axis_spread_deg:.1f}° "
                f"about {ax}; axis condition number {motion.axis_condition_number:.3g}) — rotate "
                "about axes further apart")
    if motion.small_rotations:
        return (f"the rotations are small (largest {motion.max_angle_deg:.1f}°) — rotate the "
                "tool more between poses")
    if motion.axis_condition_number > 10.0:
        return (f"the motions rotate unevenly about {frame}'s axes (axis condition number "
                f"{motion.axis_condition_number:.3g})")
    return ""


def _others(d: Direction, cov_n: np.ndarray, L: float) -> str:
    """' vs ≤ X for the others': the largest std of the same kind (rotation or translation)
    across the axes perpendicular to the weak direction (observable part of the covariance)."""
    if d.kind == "mixed":
        return ""
    rotation = d.kind == "rotation"
    axis = d.rotation_axis if rotation else d.translation_axis
    C = cov_n[:3, :3] if rotation else cov_n[3:, 3:] * L**2
    P = np.eye(3) - np.outer(axis, axis)
    s = math.sqrt(max(float(np.linalg.eigvalsh(P @ C @ P)[-1]), 0.0))
    return (f" vs ≤ {math.degrees(s):.3g}° about the perpendicular axes" if rotation else
            f" vs ≤ {1000 * s:.3g} mm along the perpendicular axes")


def analyze_observability(info, X_CH, mode: str = "eye_in_hand", X_BE_list=None,
                          length_scale: float | None = None, weak_ratio: float = WEAK_RATIO,
                          max_rotation_std_deg: float | None = None,
                          max_translation_std: float | None = None,
                          X_FT=None) -> ObservabilityReport:
    """Names the directions of the hand-eye pose that the data leaves unobservable or weak.

    The target pose is marginalized out (``marginal_information``) and the information is
    expressed for X_HC = X_CH⁻¹ (the camera in its holder H: X_EC or X_BC) about and along H's
    axes. Rotation (rad) and translation (m) are made comparable with a length L: in the
    normalized coordinates [δθ; δt / L] every eigenvalue λ is the information of a principal
    direction, whose error has std 1/√λ. A direction is

    - "unobservable" when λ ≤ 1e-9 λ_max (the data carries no information about it);
    - "weak" when its std exceeds ``weak_ratio`` × that of the best-determined direction
      (λ < λ_max / weak_ratio²), or an absolute limit when given.

    With the robot poses, ``check_robot_motions`` names the cause (parallel or nearly parallel
    rotation axes, small rotations).

    Args:
        info: the 12×12 ``information_matrix`` (or any information on [δ_CH; δ_FT]).
        X_CH: the hand-eye estimate it was evaluated at (X_CE eye-in-hand, X_CB eye-to-hand).
        mode: "eye_in_hand" or "eye_to_hand".
        X_BE_list: the robot poses, for the motion check (optional).
        length_scale: L (m, > 0). Default: the median camera–target distance when
            ``X_BE_list`` and ``X_FT`` are given, else 1 m.
        weak_ratio: > 1.
        max_rotation_std_deg, max_translation_std: optional absolute limits (deg, m) above which
            a direction is weak too.
        X_FT: the target pose estimate (X_BT / X_ET), for the default length scale.

    Returns:
        ``ObservabilityReport``.

    Raises:
        ValueError: naming the argument.
    """
    mode = check_mode(mode)
    frame = HOLDER_FRAME[mode]
    X_CH = as_transform(X_CH, "X_CH")
    weak_ratio = check_positive(weak_ratio, "weak_ratio")
    if weak_ratio <= 1.0:
        raise ValueError(f"weak_ratio: must be > 1, got {weak_ratio!r}")
    limits = (None if max_rotation_std_deg is None
              else check_positive(max_rotation_std_deg, "max_rotation_std_deg"),
              None if max_translation_std is None
              else check_positive(max_translation_std, "max_translation_std"))
    Y = None if X_BE_list is None else robot_side_poses(X_BE_list, mode)
    if length_scale is None:
        L = 1.0
        if Y is not None and len(Y) and X_FT is not None:
            X_FT = as_transform(X_FT, "X_FT")
            p = (X_CH[:3, :3] @ (Y[:, :3, :3] @ X_FT[:3, 3] + Y[:, :3, 3]).T).T + X_CH[:3, 3]
            L = max(float(np.median(np.linalg.norm(p, axis=1))), 1e-3)
    else:
        L = check_positive(length_scale, "length_scale")
    S = holder_information(marginal_information(info), X_CH)
    D = np.diag([1.0, 1.0, 1.0, L, L, L])
    w, V = np.linalg.eigh(D @ S @ D)
    lam_max = float(w[-1])
    if lam_max <= 0:
        lam_max = 1.0  # no information at all: every direction unobservable
    dirs = [_direction(V[:, k], max(float(w[k]), 0.0), lam_max, L, frame, weak_ratio, limits)
            for k in range(6)]
    cond = lam_max / w[0] if w[0] > UNOBSERVABLE_RELATIVE_INFORMATION * lam_max else math.inf

    # Marginal stds per axis: inf when the axis has a component in the unobservable subspace.
    null = np.array([d.vector for d in dirs if d.status == "unobservable"]).reshape(-1, 6)
    good = [k for k in range(6) if dirs[k].status != "unobservable"]
    cov_n = (V[:, good] / w[good]) @ V[:, good].T
    std = np.sqrt(np.maximum(np.diag(cov_n), 0.0)) * np.array([1, 1, 1, L, L, L])
    if len(null):
        std[np.linalg.norm(null, axis=0) > 1e-6] = math.inf
    motion = None if Y is None or len(Y) < 2 else check_robot_motions(X_BE_list, mode)

    messages = []
    unobs_t = [d for d in dirs if d.status == "unobservable" and d.kind == "translation"]
    if len(unobs_t) >= 2:
        # A whole plane or space of translations: one message instead of arbitrary basis
        # vectors.
        if len(unobs_t) == 3:
            what = f"the camera position in {frame} (translation along every axis)"
        else:
            n = np.cross(unobs_t[0].translation_axis, unobs_t[1].translation_axis)
            what = f"translation perpendicular to {axis_name(n, frame)}"
        cause = _cause(unobs_t[0], motion, frame)
        messages.append(f"{what} is unobservable: "
                        + (cause if cause else "the motions do not determine it"))
    for d in dirs:
        if d.status == "ok" or (len(unobs_t) >= 2 and d in unobs_t):
            continue
        cause = _cause(d, motion, frame)
        if d.status == "unobservable":
            name = d.name
            if (motion is not None and motion.parallel_axes and d.kind == "translation"
                    and abs(float(d.translation_axis @ motion.common_axis)) >= 0.98):
                name = ("translation along the rotation axis "
                        f"({axis_name(d.translation_axis, frame)})")
            msg = f"{name} is unobservable" + (f": {cause}" if cause else
                                              ": the motions do not determine it")
        else:
            ref = _others(d, cov_n, L)
            msg = f"{d.name} is weakly determined (σ {d.std_text}{ref})" + \
                (f": {cause}" if cause else "")
        messages.append(msg)
    report = ObservabilityReport(mode, frame, S, L, dirs, cond, np.degrees(std[:3]), std[3:],
                                 motion, messages)
    hint = report.suggested_fixes()
    if hint:
        messages.append("fix " + " and ".join(hint) + " to a known value (e.g. --fix "
                        + ",".join(f"{h}=VALUE" for h in hint) + ") for a partial calibration")
    return report


def observability_report(X_BE_list, X_CH, X_FT, rotation_sigma: float,
                         translation_sigma: float, mode: str = "eye_in_hand",
                         noise_model: str = "so3", **kwargs) -> ObservabilityReport:
    """``information_matrix`` then ``analyze_observability`` with the motion check and the
    camera–target distance as length scale (keyword arguments are passed on)."""
    info = information_matrix(X_BE_list, X_CH, X_FT, rotation_sigma, translation_sigma, mode,
                              noise_model)
    return analyze_observability(info, X_CH, mode, X_BE_list=X_BE_list, X_FT=X_FT, **kwargs)


def reduced_coordinates(X_CH, fixed=()) -> tuple[np.ndarray, list, np.ndarray]:
    """Coordinates of the pose form with components of X_HC held (``fixed`` names).

    Returns (T, names, G): T (12 × (n + 6)) maps [free hand-eye parameters; δ_FT] to
    [δ_CH; δ_FT] at X_CH, G (6 × n) maps the free parameters to X_HC's error state
    [δθ_HC; δt_HC]; the free parameters (``names``) are X_HC's translation components
    along H (m) and either its rotation error δθ_HC (rad, about H's axes; when no angle is held)
    or its free roll-pitch-yaw angles (rad). Conditioning the information on the fixed values
    is then Tᵀ I T.
    """
    X_HC = inverse(as_transform(X_CH, "X_CH"))
    fixed = set(fixed)
    bad = fixed - set(COMPONENTS)
    if bad:
        raise ValueError(f"fixed: unknown component(s) {sorted(bad)}; valid: "
                         f"{', '.join(COMPONENTS)}")
    G, names = [], []
    if fixed & {"roll", "pitch", "yaw"}:
        E = _rpy_rate_matrix(rpy(X_HC[:3, :3]))
        for i, c in enumerate(COMPONENTS[3:]):
            if c not in fixed:
                G.append(np.concatenate([E[:, i], np.zeros(3)]))
                names.append(c)
    else:
        for i, c in enumerate(("rx", "ry", "rz")):
            G.append(np.eye(6)[i])
            names.append(c)
    for i, c in enumerate(COMPONENTS[:3]):
        if c not in fixed:
            G.append(np.eye(6)[3 + i])
            names.append(c)
    G = np.array(G).reshape(-1, 6).T  # δ_HC = G p
    n = G.shape[1]
    T = np.zeros((12, n + 6))
    T[:6, :n] = inverse_tangent_jacobian(X_HC) @ G  # δ_CH = J(X_HC) δ_HC
    T[6:, n:] = np.eye(6)
    return T, names, G


def hand_eye_std(info, X_CH, fixed=()) -> tuple[np.ndarray, np.ndarray]:
    """Marginal standard deviations of X_HC (the camera in its holder) from an information
    matrix on [δ_CH; δ_FT], given the ``fixed`` components (zero std): rotation about H's axes
    (deg, (3,)) and translation along them (m, (3,)); inf where the information does not
    determine them."""
    M = _check_information(info)
    T, _, G = reduced_coordinates(X_CH, fixed)
    n = T.shape[1] - 6
    S = _schur(T.T @ M @ T, n)
    w, V = np.linalg.eigh(S) if n else (np.zeros(0), np.zeros((0, 0)))
    lam_max = float(w[-1]) if n and w[-1] > 0 else 1.0
    good = w > UNOBSERVABLE_RELATIVE_INFORMATION * lam_max
    cov_p = (V[:, good] / w[good]) @ V[:, good].T if n else np.zeros((0, 0))
    cov = G @ cov_p @ G.T
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    if n and not good.all():
        null = G @ V[:, ~good]
        std[np.linalg.norm(null, axis=1) > 1e-6 * max(1.0, np.abs(G).max())] = math.inf
    return np.degrees(std[:3]), std[3:]


def _schur(M: np.ndarray, n: int) -> np.ndarray:
    """Information on the first n coordinates with the rest marginalized (pseudo-inverse)."""
    A, B, C = M[:n, :n], M[:n, n:], M[n:, n:]
    w, V = np.linalg.eigh(C)
    keep = w > 1e-12 * max(w[-1], 1e-300)
    S = A - B @ ((V[:, keep] / w[keep]) @ V[:, keep].T) @ B.T
    return 0.5 * (S + S.T)


# ------------------------------------------------------------------------------ --fix parsing
_UNITS = {"": 1.0, "_deg": math.pi / 180.0, "_mm": 1e-3}


def parse_fixed(text) -> dict:
    """Parses ``"tz=0.052,yaw_deg=90"`` into ``{"tz": 0.052, "yaw": 1.5707963…}``.

    Names: tx, ty, tz (metres; tx_mm… in millimetres) — the translation of X_HC (the camera in
    E for eye-in-hand, in B for eye-to-hand) along H's axes; roll, pitch, yaw (radians;
    roll_deg… in degrees) — its Drake RollPitchYaw (extrinsic X-Y-Z, URDF ``rpy``) angles.
    Separators: commas (spaces allowed around them).

    Raises:
        ValueError: "--fix: …" naming the offending item (unknown name, missing '=', not a
            number, non-finite, given twice, a translation beyond 10 m, an angle beyond π).
    """
    if isinstance(text, dict):
        return check_fixed(text)
    if not isinstance(text, str):
        raise ValueError(f"--fix: expected a string like 'tz=0.052,yaw_deg=90', got "
                         f"{type(text).__name__}")
    items = [s.strip() for s in text.split(",")]
    if not text.strip() or any(not s for s in items):
        raise ValueError(f"--fix: empty item in {text!r}; expected NAME=VALUE items separated by "
                         "commas, e.g. 'tz=0.052,yaw_deg=90'")
    out: dict = {}
    valid = ", ".join(c + u for c in COMPONENTS for u in
                      (("", "_mm") if c.startswith("t") else ("", "_deg")))
    for item in items:
        if "=" not in item:
            raise ValueError(f"--fix: {item!r} has no '=': expected NAME=VALUE, e.g. tz=0.052")
        name, value = (s.strip() for s in item.split("=", 1))
        m = re.fullmatch(r"(tx|ty|tz|roll|pitch|yaw)(_deg|_mm)?", name)
        if m is None or (m.group(2) == "_deg" and name[0] == "t") or \
                (m.group(2) == "_mm" and name[0] != "t"):
            raise ValueError(f"--fix: unknown component {name!r}; valid names: {valid}")
        comp = m.group(1)
        try:
            v = float(value)
        except ValueError:
            raise ValueError(f"--fix: {name}={value!r}: the value is not a number") from None
        if not math.isfinite(v):
            raise ValueError(f"--fix: {name}={value}: the value must be finite")
        if comp in out:
            raise ValueError(f"--fix: {comp} is given twice (in {text!r})")
        out[comp] = v * _UNITS[m.group(2) or ""]
    return check_fixed(out, "--fix")


def check_fixed(fixed, name: str = "fixed") -> dict:
    """Validates a ``{component: value}`` dict (metres, radians); returns a clean copy."""
    if fixed is None:
        return {}
    if not isinstance(fixed, dict):
        raise ValueError(f"{name}: expected a dict like {{'tz': 0.052}}, got "
                         f"{type(fixed).__name__}")
    out = {}
    for k, v in fixed.items():
        if k not in COMPONENTS:
            raise ValueError(f"{name}: unknown component {k!r}; valid: {', '.join(COMPONENTS)} "
                             "(metres, radians)")
        try:
            v = float(v)
        except (TypeError, ValueError):
            raise ValueError(f"{name}: {k}={v!r} is not a number") from None
        if not math.isfinite(v):
            raise ValueError(f"{name}: {k}={v!r} must be finite")
        if k.startswith("t") and abs(v) > _MAX_FIXED_TRANSLATION:
            raise ValueError(f"{name}: {k}={v:g} m is implausible (more than "
                             f"{_MAX_FIXED_TRANSLATION:g} m); translations are in metres"
                             + (f" — use {k}_mm= for millimetres" if name == "--fix" else ""))
        if not k.startswith("t") and abs(v) > math.pi + 1e-9:
            raise ValueError(f"{name}: {k}={v:g} rad is beyond ±π; angles are in radians"
                             + (f" — use {k}_deg= for degrees" if name == "--fix" else ""))
        out[k] = v
    if "pitch" in out and abs(math.cos(out["pitch"])) < 1e-3 and ("roll" in out or "yaw" in out):
        raise ValueError(f"{name}: roll and yaw are not separately defined at pitch = ±90° "
                         "(gimbal lock); fix the rotation with a pitch away from ±90°")
    return out


# ------------------------------------------------------------------------------ partial ML fit
def _rpy_rate_matrix(angles) -> np.ndarray:
    """E with δθ = E d(roll, pitch, yaw) for R = Rz(yaw) Ry(pitch) Rx(roll) (left
    perturbation, axes of the parent frame)."""
    r, p, y = angles
    cy, sy, cp, sp = math.cos(y), math.sin(y), math.cos(p), math.sin(p)
    return np.array([[cy * cp, -sy, 0.0], [sy * cp, cy, 0.0], [-sp, 0.0, 1.0]])


@dataclass
class PartialMLResult:
    """Result of ``refine_ml_poses_fixed``.

    Attributes:
        mode, frame: as ``ObservabilityReport``.
        X_CH: the hand-eye estimate (X_CE eye-in-hand, X_CB eye-to-hand), 4×4.
        X_HC: its inverse, the camera in its holder (X_EC / X_BC).
        X_FT: the target pose estimate (X_BT / X_ET).
        fixed: the components held (metres, radians).
        parameters: {tx, ty, tz (m), roll, pitch, yaw (rad)} of X_HC.
        parameter_std: their standard deviations (0 for fixed ones; inf for roll/yaw at gimbal
            lock).
        X_HC_covariance: 6×6 covariance of X_HC's error state [δθ (rad, about H's axes);
            δt (m)], singular along the fixed components.
        covariance: 6×6 covariance of X_CH's error state (``MLResult.covariance``'s convention).
        full_covariance: 12×12 of [δθ_CH; δt_CH; δθ_FT; δt_FT].
        X_HC_rotation_std_deg, X_HC_translation_std: marginal stds about / along H's axes.
        cost: Σ r² of the whitened residuals (χ² with ``dof`` degrees of freedom under the
            noise model).
        dof: number of residuals − number of estimated parameters.
        residuals: (K, 2) per sample [rotation (deg), translation (m)].
        num_iterations: Jacobian evaluations.
    """
    mode: str
    frame: str
    X_CH: np.ndarray
    X_HC: np.ndarray
    X_FT: np.ndarray
    fixed: dict
    parameters: dict
    parameter_std: dict
    X_HC_covariance: np.ndarray
    covariance: np.ndarray
    full_covariance: np.ndarray
    X_HC_rotation_std_deg: np.ndarray
    X_HC_translation_std: np.ndarray
    cost: float
    dof: int
    residuals: np.ndarray
    num_iterations: int


class _FixedChart:
    """Free parameters x ↔ (X_HC, X_FT) around a centre, with components of X_HC held.

    Translation: t_HC[i] = centre[i] + x (free) or the fixed value. Rotation: a left chart
    exp(δθ) R_c when no angle is fixed, else roll-pitch-yaw with the fixed angles held.
    X_FT: left chart. x = [free translations, rotation parameters, δ_FT (6)].
    """

    def __init__(self, X_HC, X_FT, fixed):
        self.fixed = fixed
        self.t_free = [i for i, c in enumerate(COMPONENTS[:3]) if c not in fixed]
        self.r_free = [i for i, c in enumerate(COMPONENTS[3:]) if c not in fixed]
        self.use_rpy = len(self.r_free) < 3
        t = X_HC[:3, 3].copy()
        for i, c in enumerate(COMPONENTS[:3]):
            if c in fixed:
                t[i] = fixed[c]
        self.t_c = t
        if self.use_rpy:
            a = rpy(X_HC[:3, :3])
            for i, c in enumerate(COMPONENTS[3:]):
                if c in fixed:
                    a[i] = fixed[c]
            self.rpy_c = a
        else:
            self.R_c = X_HC[:3, :3].copy()
        self.X_FT_c = X_FT.copy()
        self.n = len(self.t_free) + (len(self.r_free) if self.use_rpy else 3) + 6

    def split(self, x):
        nt = len(self.t_free)
        nr = self.n - 6 - nt
        return x[:nt], x[nt:nt + nr], x[nt + nr:]

    def poses(self, x):
        xt, xr, xf = self.split(x)
        t = self.t_c.copy()
        t[self.t_free] += xt
        if self.use_rpy:
            a = self.rpy_c.copy()
            a[self.r_free] += xr
            R = rotation_from_rpy(a)
        else:
            R = rotation_exp(xr) @ self.R_c
        X_FT = make_transform(rotation_exp(xf[:3]) @ self.X_FT_c[:3, :3],
                              self.X_FT_c[:3, 3] + xf[3:])
        return make_transform(R, t), X_FT

    def angles(self, x):
        if not self.use_rpy:
            return rpy(self.poses(x)[0][:3, :3])
        a = self.rpy_c.copy()
        a[self.r_free] += self.split(x)[1]
        return a

    def tangent_map(self, x):
        """T (12 × n): [δ_CH; δ_FT] = T dx at x."""
        xt, xr, xf = self.split(x)
        X_HC, _ = self.poses(x)
        G = np.zeros((6, self.n - 6))  # δ_HC = G d(x_t, x_r)
        nt = len(xt)
        for col, i in enumerate(self.t_free):
            G[3 + i, col] = 1.0
        if self.use_rpy:
            E = _rpy_rate_matrix(self.angles(x))
            G[:3, nt:] = E[:, self.r_free]
        else:
            G[:3, nt:] = left_jacobian(xr)
        T = np.zeros((12, self.n))
        T[:6, :self.n - 6] = inverse_tangent_jacobian(X_HC) @ G  # δ_CH = J(X_HC) δ_HC
        T[6:9, self.n - 6:self.n - 3] = left_jacobian(xf[:3])
        T[9:, self.n - 3:] = np.eye(3)
        return T

    def recentred(self, x):
        X_HC, X_FT = self.poses(x)
        if self.use_rpy:
            a = self.angles(x)
            chart = _FixedChart.__new__(_FixedChart)
            chart.__dict__.update(self.__dict__)
            chart.t_c = X_HC[:3, 3].copy()
            chart.rpy_c = a
            chart.X_FT_c = X_FT
            return chart
        return _FixedChart(X_HC, X_FT, self.fixed)


def _common_axis(rv: np.ndarray) -> np.ndarray:
    n = rv / np.linalg.norm(rv, axis=1)[:, None]
    return np.linalg.eigh(n.T @ n)[1][:, -1]


def _rotation_between(a, b) -> np.ndarray:
    """The smallest rotation taking unit vector a to unit vector b."""
    c = np.cross(a, b)
    s, d = np.linalg.norm(c), float(a @ b)
    if s < 1e-12:
        if d > 0:
            return np.eye(3)
        p = np.eye(3)[int(np.argmin(np.abs(a)))]
        c = np.cross(a, p)
        return rotation_exp(math.pi * c / np.linalg.norm(c))
    return rotation_exp(c / s * math.atan2(s, d))


def _initial_guesses(Y, X_CT, fixed) -> list:
    """Starting X_HC: the Daniilidis solution when the classical solver accepts the data, and a
    fan of 12 rotations about the common rotation axis (which AX = XB maps from H to C) when the
    axes are (nearly) parallel — the rotation about that axis is then only resolved by the
    translations, too weakly for a classical solver."""
    guesses = []
    try:
        # Y plays X_EB's part in both modes: the solver takes its inverse and returns X_HC.
        guesses.append(calibrate_hand_eye([inverse(y) for y in Y], list(X_CT), "daniilidis",
                                          pairs="consecutive"))
    except ValueError:
        pass
    idx = np.round(np.linspace(0, len(Y) - 1, min(len(Y), _MAX_CHECK_SAMPLES))).astype(int)
    i, j = np.triu_indices(len(idx), 1)
    i, j = idx[i], idx[j]
    rv_H = np.array([rotation_log(Y[a, :3, :3] @ Y[b, :3, :3].T) for a, b in zip(i, j)])
    rv_C = np.array([rotation_log(X_CT[a][:3, :3] @ X_CT[b][:3, :3].T) for a, b in zip(i, j)])
    ok = np.linalg.norm(rv_H, axis=1) >= _MIN_AXIS_ROTATION
    if ok.sum() == 0:
        return guesses or [np.eye(4)]
    rv_H, rv_C = rv_H[ok], rv_C[ok]
    a_H = _common_axis(rv_H)
    n = rv_H / np.linalg.norm(rv_H, axis=1)[:, None]
    spread = float(np.max(np.arctan2(np.linalg.norm(np.cross(n, a_H), axis=1), np.abs(n @ a_H))))
    if guesses and spread > NEARLY_PARALLEL_AXES:
        return guesses
    a_C = (np.sign(rv_H @ a_H)[:, None] * rv_C).sum(axis=0)
    a_C /= np.linalg.norm(a_C)
    R0 = _rotation_between(a_H, a_C)  # R_CH a_H = a_C
    t = np.array([fixed.get(c, 0.0) for c in COMPONENTS[:3]])
    for phi in np.linspace(0, 2 * math.pi, 12, endpoint=False):
        R_CH = rotation_exp(phi * a_C) @ R0
        guesses.append(make_transform(R_CH.T, t))
    return guesses


def _fit_fixed(chart: _FixedChart, data, noise_model, sr, st, max_rounds=8, t_prior=None,
               W=None):
    """LM in the chart, re-centred until the step vanishes. ``t_prior`` = (t0, σ): extra
    residuals (t_HC − t0)/σ on the free translation components, which pin directions the data
    leaves undetermined (otherwise LM may wander along them) and barely move the others."""
    njev = 0
    for _ in range(max_rounds):
        def prior(x, c):
            if t_prior is None:
                return np.zeros(0), np.zeros((0, c.n))
            free = c.t_free
            r = (c.t_c[free] + x[:len(free)] - t_prior[0][free]) / t_prior[1]
            return r, np.eye(len(free), c.n) / t_prior[1]

        def fun(x, c=chart):
            X_HC, X_FT = c.poses(x)
            return np.concatenate([_pose_terms((inverse(X_HC), X_FT), data, noise_model, sr,
                                               st, W)[0], prior(x, c)[0]])

        def jac(x, c=chart):
            X_HC, X_FT = c.poses(x)
            return np.vstack([_pose_terms((inverse(X_HC), X_FT), data, noise_model, sr, st,
                                          W)[1] @ c.tangent_map(x), prior(x, c)[1]])

        sol = least_squares(fun, np.zeros(chart.n), jac=jac, method="lm", xtol=1e-14,
                            ftol=1e-14, gtol=1e-14, max_nfev=100 * chart.n)
        njev += int(sol.njev or 0)
        if not np.all(np.isfinite(sol.x)):
            raise ValueError("X_CH_init: the least-squares refinement diverged")
        chart = chart.recentred(sol.x)
        if np.linalg.norm(sol.x) < 1e-12:
            break
        if chart.use_rpy and abs(math.cos(chart.rpy_c[1])) < 1e-6:
            raise ValueError("fixed: the fit reached pitch = ±90° (gimbal lock), where roll and "
                             "yaw are not separately defined; fix a different angle")
    x0 = np.zeros(chart.n)
    X_HC, X_FT = chart.poses(x0)
    r, H = _pose_terms((inverse(X_HC), X_FT), data, noise_model, sr, st, W)
    return chart, r, H, njev


def _partial_fit(X_BE_list, X_CT_list, X_CH_init, sr, st, noise_model, X_FT_init, fixed, mode,
                 translation_prior_std=None, covariances=None):
    """The best local ML fit (over the starting points) with ``fixed`` held; the information
    may be singular (unobservable directions then keep their starting values)."""
    Y = robot_side_poses(X_BE_list, mode)
    X_CT = as_transform_list(X_CT_list, "X_CT_list", rigid=(noise_model == "so3"))
    check_same_length(list(Y), "X_BE_list", X_CT, "X_CT_list")
    if len(Y) < 3:
        raise ValueError(f"X_BE_list, X_CT_list: need at least 3 samples, got {len(Y)}")
    W = None if covariances is None else pose_whitening(covariances, len(Y))
    R_CTm, R_CTp = _measured_rotations(X_CT, "X_CT_list", noise_model)
    data = (R_CTm, R_CTp, np.array([x[:3, 3] for x in X_CT]), Y[:, :3, :3], Y[:, :3, 3])
    X_CT_p = [make_transform(R, x[:3, 3]) for R, x in zip(R_CTp, X_CT)]
    if X_CH_init is None:
        starts = [inverse(X) for X in _initial_guesses(Y, X_CT_p, fixed)]
    else:
        starts = [as_transform(X_CH_init, "X_CH_init")]

    best = None
    for X_CH0 in starts:
        X_FT0 = (inverse(Y[0]) @ inverse(X_CH0) @ X_CT_p[0] if X_FT_init is None
                 else as_transform(X_FT_init, "X_FT_init"))
        try:
            t_prior = None if translation_prior_std is None else \
                (inverse(X_CH0)[:3, 3], translation_prior_std)
            chart, r, H, njev = _fit_fixed(_FixedChart(inverse(X_CH0), X_FT0, fixed), data,
                                           noise_model, sr, st, t_prior=t_prior, W=W)
        except ValueError:
            if len(starts) == 1:
                raise
            continue
        if best is None or r @ r < best[1] @ best[1]:
            best = (chart, r, H, njev)
    if best is None:
        raise ValueError("X_CH_init: no starting point led to a finite fit")
    return (*best, data)


def pose_residuals(X_BE_list, X_CT_list, X_CH, X_FT, mode: str = "eye_in_hand") -> np.ndarray:
    """(K, 2) per sample: [angle between measured and predicted R_CT (deg), ‖measured −
    predicted t_CT‖ (m)] for the prediction X_CH · Y_k · X_FT (``robot_side_poses``)."""
    Y = robot_side_poses(X_BE_list, mode)
    X_CT = as_transform_list(X_CT_list, "X_CT_list", rigid=False)
    check_same_length(list(Y), "X_BE_list", X_CT, "X_CT_list")
    if not X_CT:
        return np.zeros((0, 2))
    _, R_CTp = _measured_rotations(X_CT, "X_CT_list", "so3")
    data = (R_CTp, R_CTp, np.array([x[:3, 3] for x in X_CT]), Y[:, :3, :3], Y[:, :3, 3])
    return _pose_residual_summary((as_transform(X_CH, "X_CH"), as_transform(X_FT, "X_FT")), data)


def recording_observability(X_BE_list, X_CT_list, rotation_sigma: float,
                            translation_sigma: float, mode: str = "eye_in_hand",
                            noise_model: str = "so3", X_CH_init=None,
                            **kwargs) -> tuple[ObservabilityReport, np.ndarray, np.ndarray]:
    """Observability report of a recording, even when it does not determine the hand-eye pose.

    The report is evaluated at the local ML fit of the samples (started from ``X_CH_init``, or
    as ``refine_ml_poses_fixed`` starts without one). Where the data does not determine a
    direction the fit keeps its starting value there (zero for the translation along a SCARA's
    axis), which moves the linearization point by up to the camera offset: the named
    directions are exact (they depend on the robot motions only), the σ of the others are then
    approximate. (A 1 m prior on the camera offset pins the undetermined directions; its pull
    on the determined ones is ~(σ_t / 1 m)², negligible.) Keyword arguments go to
    ``analyze_observability``.

    Returns:
        (report, X_CH, X_FT): the ``ObservabilityReport`` and the linearization point
        (X_CE, X_BT eye-in-hand; X_CB, X_ET eye-to-hand).
    """
    mode = check_mode(mode)
    sr, st = _check_noise(noise_model, rotation_sigma, translation_sigma)
    # A 1 m prior on the camera offset keeps unobservable translations at their start.
    chart, *_ = _partial_fit(X_BE_list, X_CT_list, X_CH_init, sr, st, noise_model, None, {},
                             mode, translation_prior_std=1.0)
    X_HC, X_FT = chart.poses(np.zeros(chart.n))
    X_CH = inverse(X_HC)
    return (observability_report(X_BE_list, X_CH, X_FT, sr, st, mode, noise_model, **kwargs),
            X_CH, X_FT)


def refine_ml_poses_fixed(X_BE_list, X_CT_list, X_CH_init, rotation_sigma, translation_sigma,
                          noise_model: str = "so3", X_FT_init=None, fixed=None,
                          mode: str = "eye_in_hand", covariances=None) -> PartialMLResult:
    """Maximum-likelihood hand-eye and target poses (``ml.refine_ml_poses``'s model) with
    components of the camera-in-holder pose X_HC held at known values: a partial calibration.

    When the robot cannot rotate about every axis, part of the hand-eye pose is unobservable
    (``analyze_observability`` names it, e.g. the translation along the rotation axis of a
    SCARA). Holding those components at values known otherwise (a drawing, a measurement)
    makes the rest estimable; the covariance is the inverse of the information of the free
    parameters, i.e. exact given the fixed values (zero variance on them).

    Args:
        X_BE_list: K ≥ 3 end-effector poses in the robot base.
        X_CT_list: the K measured target poses in the camera.
        X_CH_init: starting hand-eye estimate (X_CE eye-in-hand, X_CB eye-to-hand), or None to
            start from the Daniilidis solution and, when the rotation axes are (nearly)
            parallel, a fan of starts about the common axis (the best fit is kept).
        rotation_sigma, translation_sigma, noise_model: as ``ml.refine_ml_poses`` (scalars, or
            per-axis σ about / along the camera's axes).
        X_FT_init: starting target pose (X_BT / X_ET); default from the first sample.
        fixed: {component: value} (``COMPONENTS``, metres and radians) or a string for
            ``parse_fixed``; empty means the ordinary ML fit in this parametrization.
        mode: "eye_in_hand" or "eye_to_hand".
        covariances: optional (K, 6, 6) per-sample camera pose covariances, as
            ``ml.refine_ml_poses`` (they replace the sigmas).

    Returns:
        ``PartialMLResult``.

    Raises:
        ValueError: as ``ml.refine_ml_poses``; a bad ``fixed``.
        UnobservableError (a ValueError): free components that the data still does not
            determine (the message names them; ``.report`` is the ``ObservabilityReport``).
    """
    mode = check_mode(mode)
    if covariances is None:
        sr, st = _check_noise(noise_model, rotation_sigma, translation_sigma)
    else:
        if noise_model != "so3":
            raise ValueError("covariances: per-sample covariances need noise_model 'so3'")
        sr = st = 1.0
    fixed = parse_fixed(fixed) if isinstance(fixed, str) else check_fixed(fixed)
    chart, r, H, njev, data = _partial_fit(X_BE_list, X_CT_list, X_CH_init, sr, st, noise_model,
                                           X_FT_init, fixed, mode, covariances=covariances)
    x0 = np.zeros(chart.n)
    X_HC, X_FT = chart.poses(x0)
    X_CH = inverse(X_HC)
    T = chart.tangent_map(x0)
    Jx = H @ T
    info_x = Jx.T @ Jx
    w = np.linalg.eigvalsh(info_x)
    if not np.isfinite(w).all() or w[0] <= 1e-13 * w[-1]:
        report = analyze_observability(H.T @ H, X_CH, mode, X_BE_list=X_BE_list, X_FT=X_FT)
        still = [d.name for d in report.unobservable] or ["(numerically) some direction"]
        free = [c for c in COMPONENTS if c not in fixed]
        raise UnobservableError(
            f"fixed: with {', '.join(sorted(fixed)) or 'nothing'} fixed, the free components "
            f"({', '.join(free)}) are still not determined by the data: {'; '.join(still)} is "
            "unobservable" + (f" (fix {' and '.join(report.suggested_fixes())})"
                              if report.suggested_fixes() else ""), report)
    cov_x = np.linalg.inv(info_x)
    cov_x = 0.5 * (cov_x + cov_x.T)
    full = T @ cov_x @ T.T
    full = 0.5 * (full + full.T)
    J = inverse_tangent_jacobian(X_CH)  # δ_HC = J δ_CH
    cov_HC = J @ full[:6, :6] @ J.T
    cov_HC = 0.5 * (cov_HC + cov_HC.T)
    for i, c in enumerate(COMPONENTS[:3]):  # exact zeros (not 1e-20) on fixed translations
        if c in fixed:
            cov_HC[3 + i, :] = cov_HC[:, 3 + i] = 0.0
    d = np.sqrt(np.maximum(np.diag(cov_HC), 0.0))
    angles = rpy(X_HC[:3, :3])
    params = {c: float(v) for c, v in zip(COMPONENTS, [*X_HC[:3, 3], *angles])}
    E = _rpy_rate_matrix(angles)
    if abs(math.cos(angles[1])) > 1e-9:
        cov_rpy = np.linalg.solve(E, np.linalg.solve(E, cov_HC[:3, :3]).T)
        rpy_std = np.sqrt(np.maximum(np.diag(cov_rpy), 0.0))
    else:
        rpy_std = np.array([math.inf, float(d[1]), math.inf])
    std = {c: float(v) for c, v in zip(COMPONENTS, [*d[3:], *rpy_std])}
    for c in fixed:
        std[c] = 0.0
    return PartialMLResult(mode=mode, frame=HOLDER_FRAME[mode], X_CH=X_CH, X_HC=X_HC, X_FT=X_FT,
                           fixed=dict(fixed), parameters=params, parameter_std=std,
                           X_HC_covariance=cov_HC, covariance=full[:6, :6].copy(),
                           full_covariance=full, X_HC_rotation_std_deg=np.degrees(d[:3]),
                           X_HC_translation_std=d[3:], cost=float(r @ r),
                           dof=int(len(r) - chart.n), residuals=_pose_residual_summary(
                               (X_CH, X_FT), data), num_iterations=njev)

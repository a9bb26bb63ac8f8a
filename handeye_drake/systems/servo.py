"""Visual-servo controller with a self-calibration prelude (docs/method.md §1 and §7).

The control law itself is ``handeye_drake.vision.camera_model.ibvs_twist``; this module sequences
the phases and wraps it as a sampled Drake system.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import LeafSystem

from ..estimation.se3 import pose_to_vector, skew
from ..estimation.validation import as_matrix, as_transform, check_positive, rotation_defect
from ..vision.camera_model import (
    MIN_DEPTH,
    CameraIntrinsics,
    SelfCalibrationMotion,
    as_points,
    default_self_calibration_motions,
)

__all__ = [
    "STATUS_INVALID_ESTIMATE",
    "STATUS_OK",
    "STATUS_TOO_FEW_VISIBLE",
    "SelfCalibrationMotion",
    "VisualServoController",
    "default_self_calibration_motions",
]

STATUS_OK = 0
#: Fewer than ``min_visible`` usable points (visible and in front): in the servo phase the command
#: is zero. Also reported during self-calibration, whose command does not depend on the image.
STATUS_TOO_FEW_VISIBLE = 1
#: Servo phase only: the X_CE_estimate input's rotation block is far from a rotation (e.g. a
#: calibrator that is not initialized yet outputs zeros); the command is zero.
STATUS_INVALID_ESTIMATE = 2

#: max(‖RᵀR − I‖_F, |det R − 1|) above which the hand-eye estimate is refused (STATUS 2). Loose on
#: purpose: a slightly non-orthonormal estimate still gives a usable interaction matrix.
ESTIMATE_ROTATION_TOLERANCE = 0.25


class VisualServoController(LeafSystem):
    """Sampled image-based visual servo on N point features, preceded by predefined
    self-calibration motions.

    Phases (by time, starting at t = 0): phase k < M executes ``self_calibration_motions[k]``
    (constant twist ``motion.twist_E()`` during ``motion.duration``, one after the other); from
    t = Σ durations on, phase M is the servo law of docs/method.md §7,

        V_E = −λ · pinv(L_E) (s − s*),   L_E = end_effector_interaction_matrix(s, Z, K, X_CE)

    over the usable points (visible, depth > 0), with depths Z_i = (X_CT p_TQi)_z from the measured
    target pose and X_CE the current hand-eye estimate from the calibrator. The servo twist is
    saturated (whole twist scaled, direction kept) to ‖ω‖ ≤ max_angular_speed and
    ‖v‖ ≤ max_linear_speed; the self-calibration twists must already satisfy these limits.
    Every self-calibration duration must be a whole number of periods, so each motion is executed
    exactly (angle reached at the phase boundary).

    The command computed at a sample t_k is held on (t_k, t_{k+1}] (Drake discrete-update
    semantics). With the camera at the same rate the controller uses the previous sample's image,
    and a sampled arm at the same rate applies the command one sample later: e_{k+1} =
    e_k − λ·period·e_{k−2}, stable for λ·period < 0.618 (keep it ≲ 0.2 for a smooth decay). At
    t = 0 no image exists yet, so the initialization sample reports STATUS_TOO_FEW_VISIBLE.

    The commanded pose: the servo also integrates its held twist into a desired end-effector
    pose, X_BE_desired(t) = X_k · exp(V_k (t − t_k)) on (t_k, t_{k+1}] (the SE(3) exponential
    of the body twist, E's motion under a constant twist expressed in E), with X_k the desired
    pose reached at the end of the previous period — starting at ``X_BE_initial`` (the robot's
    start pose; B is the base frame of whatever tracks it). A servo-to-pose robot interface
    (e.g. Drake's ``DifferentialInverseKinematicsIntegrator`` with frame A = B) tracks it; the
    twist output serves a velocity interface. The desired pose does not wait for the arm: a
    motion the arm cannot follow (joint limits) is still commanded.

    Input ports:
        features (2N): current pixels [u0, v0, u1, v1, …] (px).
        visible (N): 1.0 for visible points (> 0.5 counts as visible).
        X_CT_measured (12): measured target pose in C, [vec_row(R); p]; gives the depths.
        X_CE_estimate (12): hand-eye estimate (E in C, the paper's X), [vec_row(R); p]; only read
            in the servo phase.

    Output ports (all read the discrete state):
        V_WE_E_command (6): commanded end-effector twist [ω (rad/s); v (length/s)] expressed in E.
        phase (1): phase index as a float (0..M−1 self-calibration, M servo).
        feature_error (1): RMS over usable points of ‖s_i − s*_i‖ (px); held when no point is
            usable.
        status (1): STATUS_OK (0), STATUS_TOO_FEW_VISIBLE (1) or STATUS_INVALID_ESTIMATE (2).
        X_BE_desired (abstract RigidTransform): the commanded pose of E in B (m), a function of
            time and the state (computed when read: once per step of the pose tracker).

    Discrete state: one group per vector output, and [X_k ([vec_row(R); p]); t_k; V_k] of the
    commanded pose.
    """

    def __init__(self, intrinsics: CameraIntrinsics, p_TQ, desired_features, gain: float,
                 period: float, self_calibration_motions=(), max_angular_speed: float = 1.0,
                 max_linear_speed: float = 0.5, min_visible: int = 3, X_BE_initial=None):
        LeafSystem.__init__(self)
        X_BE0 = np.eye(4) if X_BE_initial is None else as_transform(X_BE_initial,
                                                                     "X_BE_initial")
        if not isinstance(intrinsics, CameraIntrinsics):
            raise ValueError(f"intrinsics: expected a CameraIntrinsics, got "
                             f"{type(intrinsics).__name__}")
        self._intrinsics = intrinsics
        self._p_TQ = as_points(p_TQ, "p_TQ", 3)
        n = self._p_TQ.shape[0]
        if n < 3:
            raise ValueError(f"p_TQ: a 6-DOF servo needs at least 3 points, got {n}")
        self._desired = as_matrix(np.reshape(desired_features, -1)
                                  if np.size(desired_features) == 2 * n else desired_features,
                                  "desired_features", (2 * n,))
        self._gain = check_positive(gain, "gain")
        self._desired_uv = self._desired.reshape(n, 2)
        self._K2 = intrinsics.K[:2, :2]
        self._principal_point = np.array([intrinsics.u0, intrinsics.v0])
        self._period = check_positive(period, "period")
        self._max_w = self._check_speed_limit(max_angular_speed, "max_angular_speed")
        self._max_v = self._check_speed_limit(max_linear_speed, "max_linear_speed")
        try:
            valid = (not isinstance(min_visible, bool) and float(min_visible).is_integer()
                     and 3 <= int(min_visible) <= n)
        except (TypeError, ValueError, OverflowError):
            valid = False
        if not valid:
            raise ValueError(f"min_visible: must be an integer in [3, {n}] (3 points are needed "
                             f"for a 6-DOF servo, there are {n}), got {min_visible!r}")
        self._min_visible = int(min_visible)

        self._motions = list(self_calibration_motions)
        self._motion_twists = []
        self._phase_end_steps = []  # cumulative number of periods at the end of each motion
        steps = 0
        for k, motion in enumerate(self._motions):
            name = f"self_calibration_motions[{k}]"
            if not isinstance(motion, SelfCalibrationMotion):
                raise ValueError(f"{name}: expected a SelfCalibrationMotion, got "
                                 f"{type(motion).__name__}")
            ratio = motion.duration / self._period
            if abs(ratio - round(ratio)) > 1e-6 * max(1.0, ratio) or round(ratio) < 1:
                raise ValueError(f"{name}.duration: must be a positive whole number of periods "
                                 f"({self._period:g} s), got {motion.duration:g} s")
            V = motion.twist_E()
            if np.linalg.norm(V[:3]) > self._max_w * (1 + 1e-9) \
                    or np.linalg.norm(V[3:]) > self._max_v * (1 + 1e-9):
                raise ValueError(
                    f"{name}: twist ‖ω‖ = {np.linalg.norm(V[:3]):.4g}, ‖v‖ = "
                    f"{np.linalg.norm(V[3:]):.4g} exceeds max_angular_speed = {self._max_w:g} / "
                    f"max_linear_speed = {self._max_v:g}; increase its duration")
            steps += int(round(ratio))
            self._motion_twists.append(V)
            self._phase_end_steps.append(steps)

        self._features_port = self.DeclareVectorInputPort("features", 2 * n)
        self._visible_port = self.DeclareVectorInputPort("visible", n)
        self._X_CT_port = self.DeclareVectorInputPort("X_CT_measured", 12)
        self._X_CE_port = self.DeclareVectorInputPort("X_CE_estimate", 12)

        self._command_index = self.DeclareDiscreteState(6)
        self._phase_index = self.DeclareDiscreteState(1)
        self._error_index = self.DeclareDiscreteState(1)
        self._status_index = self.DeclareDiscreteState(1)
        # [X_k ([vec_row(R); p]); t_k; V_k]: what the commanded pose is computed from, in one
        # group (the pose is read three times a period).
        self._pose_index = self.DeclareDiscreteState(np.concatenate([pose_to_vector(X_BE0),
                                                                     np.zeros(7)]))
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._UpdateCommand)
        self.DeclareInitializationDiscreteUpdateEvent(self._UpdateCommand)

        self._command_port = self.DeclareStateOutputPort("V_WE_E_command", self._command_index)
        self._phase_port = self.DeclareStateOutputPort("phase", self._phase_index)
        self._error_port = self.DeclareStateOutputPort("feature_error", self._error_index)
        self._status_port = self.DeclareStateOutputPort("status", self._status_index)
        self._X_BE_desired_port = self.DeclareAbstractOutputPort(
            "X_BE_desired", lambda: AbstractValue.Make(RigidTransform()), self._CalcDesiredPose,
            prerequisites_of_calc={self.time_ticket(),
                                   self.discrete_state_ticket(self._pose_index)})

    # Ports, as members so users can wire them by handle.
    def get_features_input_port(self):
        return self._features_port

    def get_visible_input_port(self):
        return self._visible_port

    def get_X_CT_input_port(self):
        return self._X_CT_port

    def get_X_CE_input_port(self):
        return self._X_CE_port

    def get_command_output_port(self):
        return self._command_port

    def get_phase_output_port(self):
        return self._phase_port

    def get_feature_error_output_port(self):
        return self._error_port

    def get_status_output_port(self):
        return self._status_port

    def get_X_BE_desired_output_port(self):
        return self._X_BE_desired_port

    def SetDesiredPose(self, context, X_BE) -> None:
        """Restarts the commanded pose at X_BE (4×4 or RigidTransform, E in B) at the context's
        time, e.g. the robot's pose when the run starts."""
        V = context.get_discrete_state(self._command_index).get_value()
        context.SetDiscreteState(self._pose_index, np.concatenate([
            pose_to_vector(as_transform(X_BE, "X_BE")), [context.get_time()], V]))

    @staticmethod
    def _check_speed_limit(value, name):
        if value == math.inf:
            return math.inf
        return check_positive(value, name)

    @property
    def num_phases(self) -> int:
        """M + 1: the self-calibration motions and the servo phase."""
        return len(self._motions) + 1

    @property
    def servo_start_time(self) -> float:
        """Time (s) at which the servo phase starts (end of the self-calibration motions)."""
        return (self._phase_end_steps[-1] if self._phase_end_steps else 0) * self._period

    @property
    def period(self) -> float:
        return self._period

    def phase_at(self, t: float) -> int:
        """Phase index of the sample taken at time t (s)."""
        step = math.floor(t / self._period + 1e-6)  # robust to t = k·period ± rounding
        for k, end in enumerate(self._phase_end_steps):
            if step < end:
                return k
        return len(self._motions)

    def _UpdateCommand(self, context, discrete_state):
        n = self._p_TQ.shape[0]
        features = self._EvalFinite(self._features_port, context)
        visible = self._EvalFinite(self._visible_port, context) > 0.5
        x_CT = self._EvalFinite(self._X_CT_port, context)
        Z = (self._p_TQ @ x_CT[:9].reshape(3, 3).T + x_CT[9:12])[:, 2]
        usable = visible & (Z > MIN_DEPTH)
        n_usable = int(usable.sum())

        error = (features - self._desired).reshape(n, 2)[usable]
        if n_usable > 0:
            feature_error = float(np.sqrt(np.mean(np.sum(error ** 2, axis=1))))
        else:  # nothing to measure: keep the last value, status says why
            feature_error = float(context.get_discrete_state(self._error_index).get_value()[0])
        status = STATUS_OK if n_usable >= self._min_visible else STATUS_TOO_FEW_VISIBLE

        phase = self.phase_at(context.get_time())
        command = np.zeros(6)
        if phase < len(self._motions):
            command = self._motion_twists[phase]
        elif status == STATUS_OK:
            x_CE = self._EvalFinite(self._X_CE_port, context)
            if not _is_estimate_rotation(x_CE):
                status = STATUS_INVALID_ESTIMATE
            else:
                command = self._ServoTwist(features.reshape(n, 2), Z, x_CE, usable)

        discrete_state.get_mutable_vector(self._command_index).SetFromVector(command)
        discrete_state.get_mutable_vector(self._phase_index).SetFromVector([float(phase)])
        discrete_state.get_mutable_vector(self._error_index).SetFromVector([feature_error])
        discrete_state.get_mutable_vector(self._status_index).SetFromVector([float(status)])
        # The desired pose reached at the end of the elapsed command period becomes X_k.
        t = context.get_time()
        R, p = self._DesiredPose(context, t, orthonormalize=True)
        discrete_state.set_value(self._pose_index, np.concatenate([R.reshape(9), p, [t],
                                                                   command]))

    def _DesiredPose(self, context, t, orthonormalize: bool = False):
        """(R (3×3), p) of X_k · exp(V_k (t − t_k)): E's pose under the constant body twist
        V_k."""
        x = context.get_discrete_state(self._pose_index).get_value()
        values = x.tolist()  # Python floats: same products as numpy's, less overhead
        s = t - values[12]
        V = values[13:]
        if s == 0.0 or not any(V):
            return x[:9].reshape(3, 3), x[9:12]
        R, p = _twist_motion(values, [s * v for v in V], orthonormalize)
        return np.array(R), np.array(p)

    def _CalcDesiredPose(self, context, output) -> None:
        R, p = self._DesiredPose(context, context.get_time())
        output.set_value(RigidTransform(RotationMatrix(R), p))

    def _ServoTwist(self, uv, Z, x_CE, usable) -> np.ndarray:
        """``saturate_twist(ibvs_twist(uv, s*, Z, K, X_CE, gain, visible=usable), ...)`` (X_CE as
        the pose vector x_CE) without
        the per-call checks of its arguments (checked once, in the constructor, or just above):
        the same arithmetic, step by step (tests check they are equal)."""
        uv_m = uv[usable]
        xy = np.linalg.solve(self._K2, (uv_m - self._principal_point).T).T
        x, y, z = xy[:, 0], xy[:, 1], Z[usable]
        # Each point's 2×6 block of the normalized interaction matrix, stacked (N, 2, 6).
        M = np.zeros((len(uv_m), 2, 6))
        M[:, 0, 0], M[:, 0, 1], M[:, 0, 2] = x * y, -(1.0 + x * x), y
        M[:, 0, 3], M[:, 0, 5] = -1.0 / z, x / z
        M[:, 1, 0], M[:, 1, 1], M[:, 1, 2] = 1.0 + y * y, -x * y, -x
        M[:, 1, 4], M[:, 1, 5] = -1.0 / z, y / z
        # twist_transform(X_CE) from the pose vector: [[R, 0], [[p]× R, R]].
        R, p = x_CE[:9].reshape(3, 3), x_CE[9:12]
        T = np.zeros((6, 6))
        T[:3, :3] = R
        T[3:, 3:] = R
        T[3:, :3] = skew(p) @ R
        L = (self._K2 @ M).reshape(-1, 6) @ T
        error = (uv_m - self._desired_uv[usable]).reshape(-1)
        V = -self._gain * (np.linalg.pinv(L, rcond=1e-10) @ error)
        scale = 1.0
        w, v = np.linalg.norm(V[:3]), np.linalg.norm(V[3:])
        if w > self._max_w:
            scale = min(scale, self._max_w / w)
        if v > self._max_v:
            scale = min(scale, self._max_v / v)
        return scale * V

    def _EvalFinite(self, port, context):
        value = port.Eval(context)  # (a new array)
        if not np.isfinite(value).all():
            raise ValueError(f"{port.get_name()} input of {self.get_name()!r}: contains NaN or "
                             f"infinite values at t = {context.get_time()}")
        return value


def _is_estimate_rotation(x) -> bool:
    """``rotation_defect(R) ≤ ESTIMATE_ROTATION_TOLERANCE`` for R = the first 9 entries of a
    pose vector (row-major), on Python floats; the exact test decides near the bound."""
    a, b, c, d, e, f, g, h, i = x[:9].tolist()
    g00, g11, g22 = a * a + d * d + g * g - 1.0, b * b + e * e + h * h - 1.0, \
        c * c + f * f + i * i - 1.0
    g01, g02, g12 = a * b + d * e + g * h, a * c + d * f + g * i, b * c + e * f + h * i
    frob2 = g00 * g00 + g11 * g11 + g22 * g22 + 2.0 * (g01 * g01 + g02 * g02 + g12 * g12)
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    tol = 0.999 * ESTIMATE_ROTATION_TOLERANCE
    if frob2 <= tol * tol and abs(det - 1.0) <= tol:
        return True
    return rotation_defect(np.reshape(x[:9], (3, 3))) <= ESTIMATE_ROTATION_TOLERANCE


def _twist_motion(x, sV, orthonormalize: bool):
    """([R row-major], [p]) of X0 · exp([a; b]): the pose X0 = x ([vec_row(R0); p0], a list)
    moved by the body twist [ω; v] held for s seconds, sV = [a; b] = [ω s (rad); v s (m)]
    expressed in the moving frame — the SE(3) exponential, R = R0 exp([a]×) and
    p = p0 + R0 J(a) b, J the left Jacobian of SO(3). On Python floats (3×3 numpy calls cost
    more than the arithmetic). ``orthonormalize``: one Newton step R ← R (3I − RᵀR) / 2, so a
    pose integrated over many periods stays a rotation to rounding."""
    ax, ay, az, bx, by, bz = sV
    th2 = ax * ax + ay * ay + az * az
    if th2 < 1e-8:  # Taylor series: the terms dropped are below 1e-17
        A, B, C = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0, 1.0 / 6.0 - th2 / 120.0
    else:
        th = math.sqrt(th2)
        A, B = math.sin(th) / th, (1.0 - math.cos(th)) / th2
        C = (1.0 - A) / th2
    # exp([a]×) = I + A [a]× + B [a]×², with [a]×² = a aᵀ − θ² I.
    d = 1.0 - B * th2
    E = ((d + B * ax * ax, B * ax * ay - A * az, B * ax * az + A * ay),
         (B * ay * ax + A * az, d + B * ay * ay, B * ay * az - A * ax),
         (B * az * ax - A * ay, B * az * ay + A * ax, d + B * az * az))
    # J b = b + B a × b + C a × (a × b)
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    ex, ey, ez = ay * cz - az * cy, az * cx - ax * cz, ax * cy - ay * cx
    j = (bx + B * cx + C * ex, by + B * cy + C * ey, bz + B * cz + C * ez)
    # R = R0 E and p = p0 + R0 J b, written out (the same products and sums, in the same order,
    # as row-by-column loops: a third of the cost; this runs three times a camera period).
    (e00, e01, e02), (e10, e11, e12), (e20, e21, e22) = E
    j0, j1, j2 = j
    r00, r01, r02, r10, r11, r12, r20, r21, r22, p0, p1, p2 = x[:12]
    R = [[r00 * e00 + r01 * e10 + r02 * e20, r00 * e01 + r01 * e11 + r02 * e21,
          r00 * e02 + r01 * e12 + r02 * e22],
         [r10 * e00 + r11 * e10 + r12 * e20, r10 * e01 + r11 * e11 + r12 * e21,
          r10 * e02 + r11 * e12 + r12 * e22],
         [r20 * e00 + r21 * e10 + r22 * e20, r20 * e01 + r21 * e11 + r22 * e21,
          r20 * e02 + r21 * e12 + r22 * e22]]
    p = [p0 + r00 * j0 + r01 * j1 + r02 * j2, p1 + r10 * j0 + r11 * j1 + r12 * j2,
         p2 + r20 * j0 + r21 * j1 + r22 * j2]
    if orthonormalize:
        G = [[sum(R[m][i] * R[m][k] for m in range(3)) for k in range(3)] for i in range(3)]
        R = [[sum(r[m] * ((1.5 if m == k else 0.0) - 0.5 * G[m][k]) for m in range(3))
              for k in range(3)] for r in R]
    return R, p

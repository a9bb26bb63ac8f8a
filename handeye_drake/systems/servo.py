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

from ..estimation import kernels
from ..estimation.se3 import pose_to_vector
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

_ZERO_TWIST = np.zeros(6)


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
        # (contiguous float arrays: what the compiled kernels take)
        self._K2 = np.ascontiguousarray(intrinsics.K[:2, :2], dtype=float)
        self._principal_point = np.array([intrinsics.u0, intrinsics.v0], dtype=float)
        self._p_TQ = np.ascontiguousarray(self._p_TQ, dtype=float)
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
        features = self._features_port.Eval(context)  # (new arrays)
        visible = self._visible_port.Eval(context)
        x_CT = self._X_CT_port.Eval(context)
        Z, usable, n_usable, feature_error, finite = kernels.servo_sample(
            features, visible, x_CT, self._p_TQ, self._desired, MIN_DEPTH)
        if not finite:  # the input to blame, by name
            for port in (self._features_port, self._visible_port, self._X_CT_port):
                self._EvalFinite(port, context)
        if n_usable == 0:  # nothing to measure: keep the last value, status says why
            feature_error = float(context.get_discrete_state(self._error_index).get_value()[0])
        status = STATUS_OK if n_usable >= self._min_visible else STATUS_TOO_FEW_VISIBLE

        t = context.get_time()
        phase = self.phase_at(t)
        command = _ZERO_TWIST
        if phase < len(self._motions):
            command = self._motion_twists[phase]
        elif status == STATUS_OK:
            x_CE = self._EvalFinite(self._X_CE_port, context)
            if not _is_estimate_rotation(x_CE):
                status = STATUS_INVALID_ESTIMATE
            else:
                command = self._ServoTwist(features, Z, x_CE, usable)

        # (set_value: one call into Drake per group, half the cost of get_mutable_vector().
        # SetFromVector)
        discrete_state.set_value(self._command_index, command)
        discrete_state.set_value(self._phase_index, np.array([float(phase)]))
        discrete_state.set_value(self._error_index, np.array([float(feature_error)]))
        discrete_state.set_value(self._status_index, np.array([float(status)]))
        # The desired pose reached at the end of the elapsed command period becomes X_k.
        R, p = self._DesiredPose(context, t, orthonormalize=True)
        state = np.empty(19)
        state[:9], state[9:12], state[12], state[13:] = R.reshape(9), p, t, command
        discrete_state.set_value(self._pose_index, state)

    def _DesiredPose(self, context, t, orthonormalize: bool = False):
        """(R (3×3), p) of X_k · exp(V_k (t − t_k)): E's pose under the constant body twist
        V_k (``kernels.twist_motion``)."""
        x = context.get_discrete_state(self._pose_index).get_value()
        s = t - x[12]
        if s == 0.0 or not x[13:].any():
            return x[:9].reshape(3, 3), x[9:12]
        return kernels.twist_motion(x, s, orthonormalize)

    def _CalcDesiredPose(self, context, output) -> None:
        # _DesiredPose without its zero-twist test: the kernel's exp of a zero twist is the
        # identity exactly, so it returns X_k's R and p unchanged (three calls a period).
        x = context.get_discrete_state(self._pose_index).get_value()
        s = context.get_time() - x[12]
        R, p = (x[:9].reshape(3, 3), x[9:12]) if s == 0.0 else kernels.twist_motion(x, s, False)
        # In place (half the cost of a new RigidTransform); RotationMatrix(R) does not check R
        # in Drake's release builds either.
        output.get_mutable_value().set(RotationMatrix.MakeUnchecked(R), p)

    def _ServoTwist(self, features, Z, x_CE, usable) -> np.ndarray:
        """``saturate_twist(ibvs_twist(uv, s*, Z, K, X_CE, gain, visible=usable), ...)`` (pixels
        ``features`` (2N), X_CE as the pose vector x_CE) without the per-call checks of its
        arguments (checked once, in the constructor, or just above): the same formulas, compiled
        (``kernels.servo_twist``; tests check they agree to rounding)."""
        return kernels.servo_twist(features, Z, usable, x_CE, self._K2, self._principal_point,
                                   self._desired, self._gain, self._max_w, self._max_v)

    def _EvalFinite(self, port, context):
        value = port.Eval(context)  # (a new array)
        if not np.isfinite(value).all():
            raise ValueError(f"{port.get_name()} input of {self.get_name()!r}: contains NaN or "
                             f"infinite values at t = {context.get_time()}")
        return value


def _is_estimate_rotation(x) -> bool:
    """``rotation_defect(R) ≤ ESTIMATE_ROTATION_TOLERANCE`` for R = the first 9 entries of a pose
    vector (row-major): the compiled fast test, the exact one where it cannot decide."""
    if kernels.rotation_fast_test(x, ESTIMATE_ROTATION_TOLERANCE):
        return True
    return rotation_defect(np.reshape(x[:9], (3, 3))) <= ESTIMATE_ROTATION_TOLERANCE

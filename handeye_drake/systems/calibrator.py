"""The on-line hand-eye calibrator as a discrete Drake system (PAPER §1, §4–§7).

Life cycle, driven by the servo controller's ``phase`` output:

1. While phase < M (the M self-calibration motions run), it records the synchronized robot and
   camera poses at every phase boundary ("key frames").
2. When phase reaches M (servoing starts) it solves the M motion pairs between key frames with a
   classical solver (Daniilidis by default, as the paper) → the initial state x₀.
3. Then, at every sample, it forms the small motion pair (A, B) between consecutive samples and
   runs one step of ``kalman_step`` — the same arithmetic as ``HandEyeKalmanFilter``.

The estimate outputs are wired back to the controller's interaction matrix: that is the feedback
of the design.

Timing: both pose inputs must be sampled at the same instants (the camera trigger). In the
closed-loop diagram the robot pose goes through a ``ZeroOrderHold`` clocked with the camera, and
this system updates half a period after the trigger (``offset``), when both hold that trigger's
sample.
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from ..estimation.kalman import (NOISE_MODELS, kalman_step, measurement_covariance,
                                 transform_from_state)
from ..estimation.linear_model import linear_system_matrices, state_from_transform
from ..estimation.orthonormalize import METHODS as ORTHONORMALIZATION_METHODS
from ..estimation.se3 import inverse, pose_to_vector, rotation_angle, vector_to_pose
from ..estimation.solvers import METHODS as SOLVER_METHODS
from ..estimation.solvers import solve_ax_xb
from ..estimation.validation import as_transform, check_covariance, check_positive

#: Values of the ``status`` output's first entry.
STATUS_COLLECTING = 0.0   # self-calibration motions in progress, output = initial guess
STATUS_FILTERING = 1.0    # two-motion solution found, Kalman filter running
STATUS_INIT_FAILED = 2.0  # the classical solver rejected the motions; filtering from the guess


class HandEyeCalibrator(LeafSystem):
    """Discrete on-line hand-eye calibrator.

    Input ports:
        X_BE (12): robot pose, end-effector E in robot base B, [vec_row(R); p], sampled at the
            camera trigger.
        X_CT_measured (12): measured target pose in the camera (may be non-orthonormal under the
            paper's noise model), same instants.
        phase (1): the controller's phase; values < num_self_calibration_motions mean motion k is
            running, larger values mean servoing.

    Output ports:
        X_CE_estimate (12): the paper's X (E in C), rotation projected on SO(3).
        X_EC_estimate (12): the camera on the hand, inv(X_CE_estimate).
        X_EC_two_motion (12): the classical two-motion solution (the initial guess until known).
        covariance (144): the filter's 12×12 covariance of x = [vec_row(R_X); t_X], row-major.
        status (2): [STATUS_*, number of Kalman updates].

    Discrete state groups: x (12), P (144), previous sample (X_BE, X_CT: 24), key frames
    ((M+1)·24), bookkeeping [mode, key frames recorded, has previous sample, updates], and the
    two-motion X_CE (12).
    """

    def __init__(self, period: float, X_CE_initial_guess, num_self_calibration_motions: int = 2,
                 init_method: str = "daniilidis", P0=None, process_cov=None,
                 rotation_sigma: float = 0.01, translation_sigma: float = 0.001,
                 noise_model: str = "paper", orthonormalization: str = "svd",
                 min_rotation_deg: float = 0.0, offset: float | None = None):
        super().__init__()
        self._period = check_positive(period, "period")
        self._offset = 0.5 * self._period if offset is None else check_positive(
            offset, "offset", allow_zero=True)
        X0 = as_transform(X_CE_initial_guess, "X_CE_initial_guess")
        M = int(num_self_calibration_motions)
        if M != num_self_calibration_motions or M < 2:
            raise ValueError("num_self_calibration_motions: needs an integer ≥ 2 (two motions "
                             f"with non-parallel axes), got {num_self_calibration_motions!r}")
        if init_method not in SOLVER_METHODS:
            raise ValueError(f"init_method: expected one of {SOLVER_METHODS}, got {init_method!r}")
        if noise_model not in NOISE_MODELS:
            raise ValueError(f"noise_model: expected one of {NOISE_MODELS}, got {noise_model!r}")
        if orthonormalization not in ORTHONORMALIZATION_METHODS:
            raise ValueError(f"orthonormalization: expected one of "
                             f"{ORTHONORMALIZATION_METHODS}, got {orthonormalization!r}")
        self._M = M
        self._init_method = init_method
        self._noise_model = noise_model
        self._orthonormalization = orthonormalization
        self._rotation_sigma = check_positive(rotation_sigma, "rotation_sigma", allow_zero=True)
        self._translation_sigma = check_positive(translation_sigma, "translation_sigma",
                                                 allow_zero=True)
        self._P0 = check_covariance(np.eye(12) if P0 is None else P0, "P0", 12)
        self._G1 = check_covariance(0.0 if process_cov is None else process_cov, "process_cov", 12)
        self._x_guess = state_from_transform(X0)
        self._min_rotation = np.radians(check_positive(min_rotation_deg, "min_rotation_deg",
                                                       allow_zero=True))

        self._X_BE_port = self.DeclareVectorInputPort("X_BE", 12)
        self._X_CT_port = self.DeclareVectorInputPort("X_CT_measured", 12)
        self._phase_port = self.DeclareVectorInputPort("phase", 1)

        self._x_index = self.DeclareDiscreteState(self._x_guess)
        self._P_index = self.DeclareDiscreteState(self._P0.reshape(144))
        self._prev_index = self.DeclareDiscreteState(24)
        self._keys_index = self.DeclareDiscreteState((M + 1) * 24)
        # [mode, key frames recorded, has previous sample, number of Kalman updates]
        self._info_index = self.DeclareDiscreteState(4)
        self._two_motion_index = self.DeclareDiscreteState(self._x_guess)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, self._offset, self._DoUpdate)

        x_ticket = {self.discrete_state_ticket(self._x_index)}
        self._X_CE_port = self.DeclareVectorOutputPort(
            "X_CE_estimate", 12, self._CalcXCE, prerequisites_of_calc=x_ticket)
        self._X_EC_port = self.DeclareVectorOutputPort(
            "X_EC_estimate", 12, self._CalcXEC, prerequisites_of_calc=x_ticket)
        self._two_motion_port = self.DeclareVectorOutputPort(
            "X_EC_two_motion", 12, self._CalcTwoMotion,
            prerequisites_of_calc={self.discrete_state_ticket(self._two_motion_index)})
        self._covariance_port = self.DeclareVectorOutputPort(
            "covariance", 144, self._CalcCovariance,
            prerequisites_of_calc={self.discrete_state_ticket(self._P_index)})
        self._status_port = self.DeclareVectorOutputPort(
            "status", 2, self._CalcStatus,
            prerequisites_of_calc={self.discrete_state_ticket(self._info_index)})

    # Ports, as members so users can wire them by handle.
    def get_X_BE_input_port(self):
        return self._X_BE_port

    def get_X_CT_input_port(self):
        return self._X_CT_port

    def get_phase_input_port(self):
        return self._phase_port

    def get_X_CE_output_port(self):
        return self._X_CE_port

    def get_X_EC_output_port(self):
        return self._X_EC_port

    def get_two_motion_output_port(self):
        return self._two_motion_port

    def get_covariance_output_port(self):
        return self._covariance_port

    def get_status_output_port(self):
        return self._status_port

    @property
    def period(self) -> float:
        return self._period

    def measurement_covariance(self, X_CE, B) -> np.ndarray:
        return measurement_covariance(self._noise_model, self._rotation_sigma,
                                      self._translation_sigma, X_CE[:3, :3], X_CE[:3, 3],
                                      B[:3, :3])

    def _estimate(self, context) -> np.ndarray:
        x = context.get_discrete_state(self._x_index).get_value()
        return transform_from_state(x, self._orthonormalization)

    def _DoUpdate(self, context, discrete_state):
        X_BE_vec = self._X_BE_port.Eval(context)
        X_CT_vec = self._X_CT_port.Eval(context)
        phase = float(self._phase_port.Eval(context)[0])
        if not (np.all(np.isfinite(X_BE_vec)) and np.all(np.isfinite(X_CT_vec))):
            raise ValueError(f"HandEyeCalibrator at t={context.get_time():.4f}: non-finite pose "
                             "on the X_BE or X_CT_measured input")
        info = context.get_discrete_state(self._info_index).get_value().copy()
        mode, num_keys, has_prev, num_updates = info
        sample = np.concatenate([X_BE_vec, X_CT_vec])

        if mode == STATUS_COLLECTING:
            keys = context.get_discrete_state(self._keys_index).get_value().copy()
            # Key frame 0 is the first sample; key frame k+1 the first sample of phase ≥ k+1.
            if int(num_keys) == 0 or phase >= num_keys:
                keys[int(num_keys) * 24:(int(num_keys) + 1) * 24] = sample
                num_keys += 1
                discrete_state.get_mutable_vector(self._keys_index).SetFromVector(keys)
            if num_keys == self._M + 1:
                mode = self._Initialize(keys, discrete_state)
        elif has_prev:
            prev = context.get_discrete_state(self._prev_index).get_value()
            B = inverse(vector_to_pose(prev[:12])) @ vector_to_pose(X_BE_vec)
            if rotation_angle(B[:3, :3]) < self._min_rotation:
                # Too little motion since the last used sample: keep that sample as the start of
                # the next pair (the pair would carry mostly noise, which biases the linear model).
                discrete_state.get_mutable_vector(self._info_index).SetFromVector(
                    [mode, num_keys, has_prev, num_updates])
                return
            # The measured camera pose may be non-orthonormal (paper noise): general inverse.
            A = vector_to_pose(prev[12:]) @ np.linalg.inv(vector_to_pose(X_CT_vec))
            x = context.get_discrete_state(self._x_index).get_value()
            P = context.get_discrete_state(self._P_index).get_value().reshape(12, 12)
            C, y = linear_system_matrices(A, B)
            G2 = self.measurement_covariance(transform_from_state(x, self._orthonormalization), B)
            x_new, P_new = kalman_step(x, P, C, y, self._G1, G2)
            if np.all(np.isfinite(x_new)) and np.all(np.isfinite(P_new)):
                discrete_state.get_mutable_vector(self._x_index).SetFromVector(x_new)
                discrete_state.get_mutable_vector(self._P_index).SetFromVector(P_new.reshape(144))
                num_updates += 1
        if mode != STATUS_COLLECTING:
            discrete_state.get_mutable_vector(self._prev_index).SetFromVector(sample)
            has_prev = 1.0
        discrete_state.get_mutable_vector(self._info_index).SetFromVector(
            [mode, num_keys, has_prev, num_updates])

    def _Initialize(self, keys, discrete_state) -> float:
        """Two-motion classical solution from the key frames; returns the new mode."""
        X_BE = [vector_to_pose(keys[k * 24:k * 24 + 12]) for k in range(self._M + 1)]
        X_CT = [vector_to_pose(keys[k * 24 + 12:k * 24 + 24]) for k in range(self._M + 1)]
        A_list = [X_CT[k - 1] @ np.linalg.inv(X_CT[k]) for k in range(1, self._M + 1)]
        B_list = [inverse(X_BE[k - 1]) @ X_BE[k] for k in range(1, self._M + 1)]
        try:
            X_CE0 = solve_ax_xb(A_list, B_list, self._init_method, orthonormalize_inputs=True)
        except ValueError:
            # Degenerate self-calibration motions: keep the guess, keep filtering, and say so.
            return STATUS_INIT_FAILED
        x0 = state_from_transform(X_CE0)
        discrete_state.get_mutable_vector(self._x_index).SetFromVector(x0)
        discrete_state.get_mutable_vector(self._P_index).SetFromVector(self._P0.reshape(144))
        discrete_state.get_mutable_vector(self._two_motion_index).SetFromVector(x0)
        return STATUS_FILTERING

    def _CalcXCE(self, context, output: BasicVector):
        output.SetFromVector(pose_to_vector(self._estimate(context)))

    def _CalcXEC(self, context, output: BasicVector):
        output.SetFromVector(pose_to_vector(inverse(self._estimate(context))))

    def _CalcTwoMotion(self, context, output: BasicVector):
        x = context.get_discrete_state(self._two_motion_index).get_value()
        output.SetFromVector(pose_to_vector(inverse(transform_from_state(x,
                                                                         self._orthonormalization))))

    def _CalcCovariance(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._P_index).get_value())

    def _CalcStatus(self, context, output: BasicVector):
        info = context.get_discrete_state(self._info_index).get_value()
        output.SetFromVector([info[0], info[3]])

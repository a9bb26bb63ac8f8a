"""The on-line hand-eye calibrator as a discrete Drake system (PAPER §1, §4–§7, and beyond).

Life cycle, driven by the servo controller's ``phase`` output:

1. While phase < M (the M self-calibration motions run), it records the synchronized robot and
   camera poses at every phase boundary ("key frames") — and, for our estimators, every sample.
2. When phase reaches M (servoing starts) it solves the M motion pairs between key frames with a
   classical solver (Daniilidis by default, as the paper) → the initial estimate.
3. Then, at every sample, it refines the estimate with the selected estimator:

   - ``"paper"``: PAPER §4's linear Kalman filter on the motion (A, B) since the previous used
     sample, with PAPER §5's diagonal G2 — the arithmetic of ``HandEyeKalmanFilter``.
   - ``"paper_full"``: the same with the estimate-dependent G2.
   - ``"manifold"``: ``ManifoldHandEyeFilter``'s error-state EKF on SE(3) on the same motions;
     the buffered self-calibration samples are replayed first.
   - ``"target"``: ``HandEyeTargetFilter``: AX = ZB on the raw synchronized poses, estimating
     the fixed target pose alongside X; replays the buffered self-calibration samples first.
     Each measurement enters once with white noise, which is why it is the default.

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
from scipy.stats import chi2

from ..estimation.kalman import kalman_step, measurement_covariance, transform_from_state
from ..estimation.linear_model import linear_system_matrices, state_from_transform
from ..estimation.manifold import (gated_error_state_update, inverse_tangent_jacobian,
                                   measurement_noise_covariance, motion_residual, pose_residual,
                                   retract_pose, retract_pose_pair)
from ..estimation.orthonormalize import METHODS as ORTHONORMALIZATION_METHODS
from ..estimation.orthonormalize import orthonormalize_unchecked
from ..estimation.se3 import inverse, make_transform, pose_to_vector, rotation_angle, \
    vector_to_pose
from ..estimation.solvers import METHODS as SOLVER_METHODS
from ..estimation.solvers import solve_ax_xb
from ..estimation.validation import as_transform, check_covariance, check_positive

ESTIMATORS = ("paper", "paper_full", "manifold", "target")

#: Values of the ``status`` output's first entry.
STATUS_COLLECTING = 0.0   # self-calibration motions in progress, output = initial guess
STATUS_FILTERING = 1.0    # two-motion solution found, on-line estimator running
STATUS_INIT_FAILED = 2.0  # the classical solver rejected the motions; filtering from the guess


def _axial_map() -> np.ndarray:
    """3×9 L with δθ ≈ L vec_row(δR) at R = I (axial vector of the skew part)."""
    L = np.zeros((3, 9))
    for k in range(9):
        E = np.zeros(9)
        E[k] = 1.0
        M = E.reshape(3, 3)
        L[:, k] = 0.5 * np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])
    return L


_AXIAL = _axial_map()


def tangent_covariance_of_paper_state(x, P12) -> np.ndarray:
    """6×6 covariance of [δθ; δt] of X_CE implied by the paper filter's 12×12 covariance
    (first-order: δθ = axial(δR R̂ᵀ))."""
    R_hat = orthonormalize_unchecked(np.asarray(x[:9]).reshape(3, 3), "svd")
    # vec_row(δR R̂ᵀ) = (I3 ⊗ R̂) vec_row(δR)
    J = np.zeros((6, 12))
    J[:3, :9] = _AXIAL @ np.kron(np.eye(3), R_hat)
    J[3:, 9:] = np.eye(3)
    return J @ P12 @ J.T


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
        X_CE_estimate (12): the paper's X (E in C), an exact rigid transform.
        X_EC_estimate (12): the camera on the hand, inv(X_CE_estimate).
        X_EC_two_motion (12): the classical two-motion solution (the initial guess until known).
        X_EC_std (6): standard deviations of X_EC: rotation about E's axes (deg), translation
            (length units, in E), from the estimator's covariance.
        covariance (144): the estimator's covariance, row-major 12×12 (paper: of
            [vec_row(R_X); t_X]; manifold: the top-left 6×6 block, of [δθ; δt] of X_CE; target:
            of [δθ_CE; δt_CE; δθ_BT; δt_BT]).
        status (4): [STATUS_*, accepted updates, rejected measurements (NIS gate), last NIS].
    """

    def __init__(self, period: float, X_CE_initial_guess, num_self_calibration_motions: int = 2,
                 init_method: str = "daniilidis", estimator: str = "target", P0=None,
                 process_cov=None, rotation_sigma: float = 0.002,
                 translation_sigma: float = 0.0005, noise_model: str = "so3",
                 orthonormalization: str = "svd", min_rotation_deg: float = 0.0,
                 gate_probability: float | None = 0.999, max_self_calibration_samples: int = 0,
                 max_consecutive_rejections: int | None = 5, offset: float | None = None):
        """
        Args:
            period: sample period (s), the camera's.
            X_CE_initial_guess: used until the two-motion solution exists (4×4 rigid).
            num_self_calibration_motions: M ≥ 2.
            init_method: classical solver of the M motions (see ``solve_ax_xb``).
            estimator: one of ``ESTIMATORS``.
            P0: initial covariance after the two-motion solution: 12×12 (or 12-diagonal) for the
                paper estimators, 6×6 (or 6-diagonal) of [δθ (rad); δt] for ours.
            process_cov: process noise, same size as P0's (target: of X_CE's 6 errors).
            rotation_sigma, translation_sigma, noise_model: the measurement noise. For "paper" /
                "paper_full" they describe the camera *motion* A's coefficients (PAPER §5, and
                noise_model is ignored); for "manifold" the motion A; for "target" the measured
                pose X_CT; noise_model "so3" (rad) or "paper" (coefficients).
            min_rotation_deg: motion estimators form a pair only once the robot turned this much
                since the last used sample (0: every sample, as the paper).
            gate_probability: NIS gate of our estimators (None disables).
            max_consecutive_rejections: after this many gate rejections in a row the covariance
                is inflated so the estimate cannot freeze (see ``gated_error_state_update``);
                None disables the recovery.
            max_self_calibration_samples: buffer size for the replay of self-calibration samples
                (our estimators); 0 disables the replay.
            offset: update offset after the camera trigger (default: half a period).
        """
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
        if estimator not in ESTIMATORS:
            raise ValueError(f"estimator: expected one of {ESTIMATORS}, got {estimator!r}")
        if noise_model not in ("so3", "paper"):
            raise ValueError(f"noise_model: expected 'so3' or 'paper', got {noise_model!r}")
        if orthonormalization not in ORTHONORMALIZATION_METHODS:
            raise ValueError(f"orthonormalization: expected one of "
                             f"{ORTHONORMALIZATION_METHODS}, got {orthonormalization!r}")
        self._M = M
        self._init_method = init_method
        self._estimator = estimator
        self._paper = estimator in ("paper", "paper_full")
        self._orthonormalization = orthonormalization
        self._rotation_sigma = check_positive(rotation_sigma, "rotation_sigma",
                                              allow_zero=self._paper)
        self._translation_sigma = check_positive(translation_sigma, "translation_sigma",
                                                 allow_zero=self._paper)
        self._noise_model = noise_model
        self._min_rotation = np.radians(check_positive(min_rotation_deg, "min_rotation_deg",
                                                       allow_zero=True))
        n = 12 if self._paper else 6
        self._P0 = check_covariance(np.eye(n) if P0 is None else P0, "P0", n)
        self._G1 = check_covariance(0.0 if process_cov is None else process_cov, "process_cov", n)
        if not self._paper:
            self._Rn = measurement_noise_covariance(noise_model, self._rotation_sigma,
                                                    self._translation_sigma)
        if gate_probability is None:
            self._gate = np.inf
        else:
            if not 0.0 < float(gate_probability) < 1.0:
                raise ValueError(f"gate_probability: must be in (0, 1) or None, got "
                                 f"{gate_probability!r}")
            self._gate = float(chi2.ppf(float(gate_probability), 6))
        if max_consecutive_rejections is not None and (
                int(max_consecutive_rejections) != max_consecutive_rejections
                or max_consecutive_rejections < 1):
            raise ValueError("max_consecutive_rejections: needs an integer ≥ 1 or None, got "
                             f"{max_consecutive_rejections!r}")
        self._max_consecutive_rejections = max_consecutive_rejections
        cap = int(max_self_calibration_samples)
        if cap != max_self_calibration_samples or cap < 0:
            raise ValueError("max_self_calibration_samples: needs an integer ≥ 0, got "
                             f"{max_self_calibration_samples!r}")
        self._buffer_capacity = 0 if self._paper else cap
        self._x_guess = state_from_transform(X0)

        self._X_BE_port = self.DeclareVectorInputPort("X_BE", 12)
        self._X_CT_port = self.DeclareVectorInputPort("X_CT_measured", 12)
        self._phase_port = self.DeclareVectorInputPort("phase", 1)

        # Estimate: paper = raw x (12); ours = pose vector of X_CE (12); target adds X_BT (12).
        self._est_index = self.DeclareDiscreteState(np.concatenate([self._x_guess,
                                                                    pose_to_vector(np.eye(4))]))
        P_init = np.zeros((12, 12))
        P_init[:n, :n] = self._P0
        self._P_index = self.DeclareDiscreteState(P_init.reshape(144))
        self._prev_index = self.DeclareDiscreteState(24)
        self._keys_index = self.DeclareDiscreteState((M + 1) * 24)
        # [mode, key frames, has previous sample, accepted, rejected, last NIS, buffered samples,
        #  consecutive rejections]
        self._info_index = self.DeclareDiscreteState(8)
        self._two_motion_index = self.DeclareDiscreteState(self._x_guess)
        self._buffer_index = self.DeclareDiscreteState(max(1, self._buffer_capacity * 24))
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, self._offset, self._DoUpdate)

        est_ticket = {self.discrete_state_ticket(self._est_index)}
        self._X_CE_port = self.DeclareVectorOutputPort(
            "X_CE_estimate", 12, self._CalcXCE, prerequisites_of_calc=est_ticket)
        self._X_EC_port = self.DeclareVectorOutputPort(
            "X_EC_estimate", 12, self._CalcXEC, prerequisites_of_calc=est_ticket)
        self._two_motion_port = self.DeclareVectorOutputPort(
            "X_EC_two_motion", 12, self._CalcTwoMotion,
            prerequisites_of_calc={self.discrete_state_ticket(self._two_motion_index)})
        self._std_port = self.DeclareVectorOutputPort(
            "X_EC_std", 6, self._CalcStd,
            prerequisites_of_calc={self.discrete_state_ticket(self._est_index),
                                   self.discrete_state_ticket(self._P_index)})
        self._covariance_port = self.DeclareVectorOutputPort(
            "covariance", 144, self._CalcCovariance,
            prerequisites_of_calc={self.discrete_state_ticket(self._P_index)})
        self._status_port = self.DeclareVectorOutputPort(
            "status", 4, self._CalcStatus,
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

    def get_X_EC_std_output_port(self):
        return self._std_port

    def get_covariance_output_port(self):
        return self._covariance_port

    def get_status_output_port(self):
        return self._status_port

    @property
    def period(self) -> float:
        return self._period

    @property
    def estimator(self) -> str:
        return self._estimator

    # ------------------------------------------------------------------ estimate bookkeeping
    def _X_CE_of(self, est) -> np.ndarray:
        if self._paper:
            return transform_from_state(est[:12], self._orthonormalization)
        return vector_to_pose(est[:12])

    def _P6_of(self, est, P12) -> np.ndarray:
        """Covariance of [δθ; δt] of X_CE."""
        if self._paper:
            return tangent_covariance_of_paper_state(est[:12], P12)
        return P12[:6, :6]

    def _step(self, est, P12, info, sample_prev, sample) -> tuple:
        """One refinement step on the sample pair / the sample; returns (est, P12, info)."""
        X_BE, X_CT = vector_to_pose(sample[:12]), vector_to_pose(sample[12:])
        accepted = True
        if self._estimator == "target":
            X_CE, X_BT = vector_to_pose(est[:12]), vector_to_pose(est[12:])
            meas = (inverse(X_BE), orthonormalize_unchecked(X_CT[:3, :3], "svd"), X_CT[:3, 3])
            P = P12.copy()
            P[:6, :6] += self._G1
            (X_CE, X_BT), P, accepted, nis, _ = gated_error_state_update(
                (X_CE, X_BT), P, meas, pose_residual, retract_pose_pair, self._Rn, self._gate,
                3, int(info[7]), self._max_consecutive_rejections)
            est = np.concatenate([pose_to_vector(X_CE), pose_to_vector(X_BT)])
            P12 = P
        else:
            X_BE0, X_CT0 = vector_to_pose(sample_prev[:12]), vector_to_pose(sample_prev[12:])
            B = inverse(X_BE0) @ X_BE
            # The measured camera pose may be non-orthonormal (paper noise): general inverse.
            A = X_CT0 @ np.linalg.inv(X_CT)
            if self._paper:
                x = est[:12]
                C, y = linear_system_matrices(A, B)
                G2 = measurement_covariance(
                    "paper" if self._estimator == "paper" else "full", self._rotation_sigma,
                    self._translation_sigma, *self._rt(x), B[:3, :3])
                x, P = kalman_step(x, P12, C, y, self._G1, G2)
                est = np.concatenate([x, est[12:]])
                P12 = P
                nis = float("nan")
            else:
                X_CE = vector_to_pose(est[:12])
                meas = (orthonormalize_unchecked(A[:3, :3], "svd"), A[:3, 3], B[:3, :3], B[:3, 3])
                X_CE, P, accepted, nis, _ = gated_error_state_update(
                    X_CE, P12[:6, :6] + self._G1, meas, motion_residual, retract_pose, self._Rn,
                    self._gate, 3, int(info[7]), self._max_consecutive_rejections)
                est = np.concatenate([pose_to_vector(X_CE), est[12:]])
                P12 = P12.copy()
                P12[:6, :6] = P
        if not (np.all(np.isfinite(est)) and np.all(np.isfinite(P12))):
            return None
        info = info.copy()
        info[3 if accepted else 4] += 1
        info[7] = 0.0 if accepted else info[7] + 1
        info[5] = nis if np.isfinite(nis) else -1.0
        return est, P12, info

    def _rt(self, x):
        X = transform_from_state(x, self._orthonormalization)
        return X[:3, :3], X[:3, 3]

    # --------------------------------------------------------------------------- the update
    def _DoUpdate(self, context, discrete_state):
        X_BE_vec = self._X_BE_port.Eval(context)
        X_CT_vec = self._X_CT_port.Eval(context)
        phase = float(self._phase_port.Eval(context)[0])
        if not (np.all(np.isfinite(X_BE_vec)) and np.all(np.isfinite(X_CT_vec))):
            raise ValueError(f"HandEyeCalibrator at t={context.get_time():.4f}: non-finite pose "
                             "on the X_BE or X_CT_measured input")
        info = context.get_discrete_state(self._info_index).get_value().copy()
        est = context.get_discrete_state(self._est_index).get_value().copy()
        P12 = context.get_discrete_state(self._P_index).get_value().reshape(12, 12).copy()
        sample = np.concatenate([X_BE_vec, X_CT_vec])

        if info[0] == STATUS_COLLECTING:
            keys = context.get_discrete_state(self._keys_index).get_value().copy()
            num_keys = int(info[1])
            # Key frame 0 is the first sample; key frame k+1 the first sample of phase ≥ k+1.
            if num_keys == 0 or phase >= num_keys:
                keys[num_keys * 24:(num_keys + 1) * 24] = sample
                info[1] = num_keys = num_keys + 1
                discrete_state.get_mutable_vector(self._keys_index).SetFromVector(keys)
            buffer = None
            if self._buffer_capacity:
                buffer = context.get_discrete_state(self._buffer_index).get_value().copy()
                n_buf = int(info[6])
                if n_buf < self._buffer_capacity:
                    buffer[n_buf * 24:(n_buf + 1) * 24] = sample
                    info[6] = n_buf + 1
                discrete_state.get_mutable_vector(self._buffer_index).SetFromVector(buffer)
            if num_keys == self._M + 1:
                est, P12, info, x_two_motion = self._Initialize(keys, buffer, est, info)
                discrete_state.get_mutable_vector(self._two_motion_index).SetFromVector(
                    x_two_motion)
                info[2] = 1.0
                discrete_state.get_mutable_vector(self._prev_index).SetFromVector(sample)
        elif info[2]:
            prev = context.get_discrete_state(self._prev_index).get_value()
            B = inverse(vector_to_pose(prev[:12])) @ vector_to_pose(X_BE_vec)
            if self._estimator == "target" or rotation_angle(B[:3, :3]) >= self._min_rotation:
                result = self._step(est, P12, info, prev, sample)
                if result is not None:
                    est, P12, info = result
                discrete_state.get_mutable_vector(self._prev_index).SetFromVector(sample)
            # else: too little motion since the last used sample: keep that sample as the start
            # of the next pair (a pair that is mostly noise biases the paper's linear model).
        discrete_state.get_mutable_vector(self._est_index).SetFromVector(est)
        discrete_state.get_mutable_vector(self._P_index).SetFromVector(P12.reshape(144))
        discrete_state.get_mutable_vector(self._info_index).SetFromVector(info)

    def _Initialize(self, keys, buffer, est, info):
        """Two-motion classical solution from the key frames, then (ours) the replay of the
        buffered self-calibration samples. Returns (est, P12, info, two-motion state x)."""
        X_BE = [vector_to_pose(keys[k * 24:k * 24 + 12]) for k in range(self._M + 1)]
        X_CT = [vector_to_pose(keys[k * 24 + 12:k * 24 + 24]) for k in range(self._M + 1)]
        A_list = [X_CT[k - 1] @ np.linalg.inv(X_CT[k]) for k in range(1, self._M + 1)]
        B_list = [inverse(X_BE[k - 1]) @ X_BE[k] for k in range(1, self._M + 1)]
        try:
            X_CE0 = solve_ax_xb(A_list, B_list, self._init_method, orthonormalize_inputs=True)
            info[0] = STATUS_FILTERING
        except ValueError:
            # Degenerate self-calibration motions: keep the guess, keep filtering, and say so.
            X_CE0 = self._X_CE_of(est)
            info[0] = STATUS_INIT_FAILED
        x_two_motion = state_from_transform(X_CE0)
        n = len(self._P0)
        P12 = np.zeros((12, 12))
        P12[:n, :n] = self._P0
        if self._paper:
            est = np.concatenate([state_from_transform(X_CE0), est[12:]])
            return est, P12, info, x_two_motion
        est = np.concatenate([pose_to_vector(X_CE0), pose_to_vector(np.eye(4))])
        if self._estimator == "target":
            # The target pose implied by the first sample; nearly unknown a priori.
            X_BT0 = X_BE[0] @ inverse(X_CE0) @ make_transform(
                orthonormalize_unchecked(X_CT[0][:3, :3], "svd"), X_CT[0][:3, 3])
            est[12:] = pose_to_vector(X_BT0)
            P12[6:, 6:] = np.eye(6)
        samples = ([buffer[k * 24:(k + 1) * 24] for k in range(int(info[6]))]
                   if buffer is not None else [])
        prev = None
        for s in samples:
            if prev is not None or self._estimator == "target":
                result = self._step(est, P12, info, prev, s)
                if result is not None:
                    est, P12, info = result
            prev = s
        return est, P12, info, x_two_motion

    # ------------------------------------------------------------------------------ outputs
    def _CalcXCE(self, context, output: BasicVector):
        est = context.get_discrete_state(self._est_index).get_value()
        output.SetFromVector(pose_to_vector(self._X_CE_of(est)))

    def _CalcXEC(self, context, output: BasicVector):
        est = context.get_discrete_state(self._est_index).get_value()
        output.SetFromVector(pose_to_vector(inverse(self._X_CE_of(est))))

    def _CalcTwoMotion(self, context, output: BasicVector):
        x = context.get_discrete_state(self._two_motion_index).get_value()
        output.SetFromVector(pose_to_vector(inverse(transform_from_state(x, "svd"))))

    def _CalcStd(self, context, output: BasicVector):
        est = context.get_discrete_state(self._est_index).get_value()
        P12 = context.get_discrete_state(self._P_index).get_value().reshape(12, 12)
        X_CE = self._X_CE_of(est)
        J = inverse_tangent_jacobian(X_CE)
        d = np.sqrt(np.maximum(np.diag(J @ self._P6_of(est, P12) @ J.T), 0.0))
        output.SetFromVector(np.concatenate([np.degrees(d[:3]), d[3:]]))

    def _CalcCovariance(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._P_index).get_value())

    def _CalcStatus(self, context, output: BasicVector):
        info = context.get_discrete_state(self._info_index).get_value()
        output.SetFromVector([info[0], info[3], info[4], info[5]])

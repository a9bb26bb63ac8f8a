"""A source of synchronized robot and camera poses without an arm: docs/method.md §8's simulated motions.

It first executes the given self-calibration motions (one per sample, with ``phase`` 0, 1, …),
then random small robot motions (roll-pitch-yaw ~ N(0, rotation_sigma²), translation ~
N(0, translation_sigma²)). As in the paper's simulations, the noise is on the measured camera
*motion* A (the camera works as visual odometry): A_meas = noise(X_CE B X_CE⁻¹), and the output
pose is chained so that X_CT_meas[k−1] X_CT_meas[k]⁻¹ = A_meas exactly. It feeds
``HandEyeCalibrator`` directly, to study the calibrator alone.
"""

from __future__ import annotations

import numpy as np
from pydrake.common import RandomDistribution
from pydrake.systems.framework import BasicVector, LeafSystem

from ..estimation.se3 import inverse, make_transform, pose_to_vector, rotation_from_rpy
from ..estimation.validation import as_transform, check_positive
from ..vision.camera_model import POSE_NOISE_MODELS, apply_pose_noise


class PaperMotionSource(LeafSystem):
    """Random robot motions and noisy target-in-camera measurements, one per ``period``.

    Args:
        X_EC: true camera pose on the hand (4×4).
        X_BT: target pose in the robot base (4×4).
        X_BE0: initial end-effector pose in the base (4×4).
        self_calibration_motions: robot motions B (4×4, in E) executed first, one per sample.
        rotation_sigma: std of the roll-pitch-yaw angles of each random motion (rad).
        translation_sigma: std of each translation coordinate of each random motion.
        pose_noise_model, camera_rotation_sigma, camera_translation_sigma: the noise of the
            measured camera motion A, as ``apply_pose_noise`` ("paper": additive on the
            coefficients of R_A).

    Input ports: ``motion_noise`` (6, Gaussian random), ``pose_noise`` (12, Gaussian random).
    Output ports: ``X_BE`` (12), ``X_CT_measured`` (12), ``phase`` (1: k during
    self-calibration motion k's end sample, M afterwards).
    """

    def __init__(self, X_EC, X_BT, X_BE0, self_calibration_motions, period: float,
                 rotation_sigma: float = 2 * np.pi / 100, translation_sigma: float = 1.0,
                 pose_noise_model: str = "paper", camera_rotation_sigma: float = 0.01,
                 camera_translation_sigma: float = 0.1):
        super().__init__()
        self._X_EC = as_transform(X_EC, "X_EC")
        self._X_BT = as_transform(X_BT, "X_BT")
        X_BE0 = as_transform(X_BE0, "X_BE0")
        self._motions = [as_transform(B, f"self_calibration_motions[{i}]")
                         for i, B in enumerate(self_calibration_motions)]
        if pose_noise_model not in POSE_NOISE_MODELS:
            raise ValueError(f"pose_noise_model: expected one of {POSE_NOISE_MODELS}, got "
                             f"{pose_noise_model!r}")
        self._period = check_positive(period, "period")
        self._rotation_sigma = check_positive(rotation_sigma, "rotation_sigma", allow_zero=True)
        self._translation_sigma = check_positive(translation_sigma, "translation_sigma",
                                                 allow_zero=True)
        self._noise = (pose_noise_model,
                       check_positive(camera_rotation_sigma, "camera_rotation_sigma", True),
                       check_positive(camera_translation_sigma, "camera_translation_sigma", True))

        self._motion_noise_port = self.DeclareVectorInputPort(
            "motion_noise", 6, random_type=RandomDistribution.kGaussian)
        self._pose_noise_port = self.DeclareVectorInputPort(
            "pose_noise", 12, random_type=RandomDistribution.kGaussian)
        # [X_BE (12), X_CT_measured (12), phase, sample count]
        X_CT0 = inverse(X_BE0 @ self._X_EC) @ self._X_BT
        self._state_index = self.DeclareDiscreteState(
            np.concatenate([pose_to_vector(X_BE0), pose_to_vector(X_CT0), [0.0, 0.0]]))
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, self._period, self._UpdateSample)
        ticket = {self.discrete_state_ticket(self._state_index)}
        self._X_BE_port = self.DeclareVectorOutputPort("X_BE", 12, self._CalcX_BE,
                                                       prerequisites_of_calc=ticket)
        self._X_CT_port = self.DeclareVectorOutputPort("X_CT_measured", 12, self._CalcX_CT,
                                     prerequisites_of_calc=ticket)
        self._phase_port = self.DeclareVectorOutputPort("phase", 1, self._CalcPhase,
                                                        prerequisites_of_calc=ticket)


    # Ports, as members so users can wire them by handle.
    def get_motion_noise_input_port(self):
        return self._motion_noise_port

    def get_pose_noise_input_port(self):
        return self._pose_noise_port

    def get_X_BE_output_port(self):
        return self._X_BE_port

    def get_X_CT_output_port(self):
        return self._X_CT_port

    def get_phase_output_port(self):
        return self._phase_port

    def _UpdateSample(self, context, discrete_state):
        s = context.get_discrete_state(self._state_index).get_value()
        k = int(s[25])
        X_BE = make_transform(s[:9].reshape(3, 3), s[9:12])
        if k < len(self._motions):
            B = self._motions[k]
        else:
            n = self._motion_noise_port.Eval(context)
            B = make_transform(rotation_from_rpy(self._rotation_sigma * n[:3]),
                               self._translation_sigma * n[3:])
        X_BE = X_BE @ B
        X_CE = inverse(self._X_EC)
        A = apply_pose_noise(X_CE @ B @ self._X_EC, self._pose_noise_port.Eval(context),
                             *self._noise)
        X_CT_prev = make_transform(s[12:21].reshape(3, 3), s[21:24])
        X_CT_measured = np.linalg.inv(A) @ X_CT_prev
        phase = min(k + 1, len(self._motions))
        discrete_state.get_mutable_vector(self._state_index).SetFromVector(np.concatenate(
            [pose_to_vector(X_BE), pose_to_vector(X_CT_measured), [phase, k + 1]]))

    def _CalcX_BE(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._state_index).get_value()[:12])

    def _CalcX_CT(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._state_index).get_value()[12:24])

    def _CalcPhase(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._state_index).get_value()[24:25])

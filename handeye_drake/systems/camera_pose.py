"""The true pose of a camera on the hand, sampled when a rendered camera takes its image, for
logs and Meshcat (Drake's ``RgbdSensor`` renders on demand and keeps no sampled pose)."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem

from ..estimation.se3 import pose_to_vector, vector_to_pose
from ..estimation.validation import ROTATION_TOLERANCE, as_transform, check_positive, \
    rotation_defect
from .arm import EndEffectorPoseInput


class HandCameraPose(LeafSystem):
    """X_WC = X_WE · X_EC, sampled every ``period`` seconds (and at initialization) and held, like
    ``HandEyeCamera``'s ``X_WC`` output: the camera pose at the instant its image is taken.

    It samples in an unrestricted update, like ``TargetDetector`` and ``CameraTriggerSampler``,
    so it sees the plant in the state the image was rendered from (see
    ``systems.trigger_sampler``).

    With ``plant`` (the arm's MultibodyPlant) it reads the end-effector pose from the plant's
    body poses and also holds the robot pose X_BE of the same instant (E in the base B): one
    sampler for what the calibrator and the logs need of the trigger instant, instead of a pose
    sensor and a ``CameraTriggerSampler``.

    Input port:
        X_WE (12): end-effector pose in the world, [vec_row(R); p (m)]; without ``plant``.
        body_poses (abstract, list of RigidTransform X_W·Body by BodyIndex): with ``plant``,
            instead of X_WE; connect ``plant.get_body_poses_output_port()``.
    Output ports:
        X_WC (12): true camera pose in the world, [vec_row(R); p (m)], of the last sample.
        X_BE (12): the end-effector pose in B at the last sample (with ``plant``; without one
            B = W: the X_WE sample).
    """

    def __init__(self, X_EC, period: float, offset: float = 0.0, plant=None,
                 base_frame_name: str = "base_link", ee_frame_name: str = "tool0"):
        LeafSystem.__init__(self)
        self._X_EC = as_transform(X_EC, "X_EC")
        self._period = check_positive(period, "period")
        offset = check_positive(offset, "offset", allow_zero=True)
        self._ee_input = EndEffectorPoseInput(self, plant, base_frame_name, ee_frame_name)
        self._X_WE_port, self._frames = self._ee_input.port, self._ee_input.frames
        self._X_WC_index = self.DeclareDiscreteState(pose_to_vector(np.eye(4)))
        self._X_BE_index = self.DeclareDiscreteState(pose_to_vector(np.eye(4)))
        self.DeclarePeriodicUnrestrictedUpdateEvent(self._period, offset, self._Sample)
        self.DeclareInitializationUnrestrictedUpdateEvent(self._Sample)
        self._X_WC_port = self.DeclareStateOutputPort("X_WC", self._X_WC_index)
        self._X_BE_port = self.DeclareStateOutputPort("X_BE", self._X_BE_index)

    def get_X_WE_input_port(self):
        return self._ee_input.X_WE_port()

    def get_body_poses_input_port(self):
        return self._ee_input.body_poses_port()

    def get_X_BE_output_port(self):
        return self._X_BE_port

    def get_X_WC_output_port(self):
        return self._X_WC_port

    @property
    def X_EC(self) -> np.ndarray:
        return self._X_EC.copy()

    def _Sample(self, context, state):
        x, _, X_BE = self._ee_input.Eval(context)
        x = np.asarray(x, dtype=float)
        if not np.all(np.isfinite(x)) or rotation_defect(x[:9].reshape(3, 3)) > \
                ROTATION_TOLERANCE:
            raise ValueError(f"X_WE input of {self.get_name()!r}: not a finite rigid pose at "
                             f"t = {context.get_time()}: {x.tolist()}")
        discrete = state.get_mutable_discrete_state()
        discrete.get_mutable_vector(self._X_WC_index).SetFromVector(
            pose_to_vector(vector_to_pose(x) @ self._X_EC))
        discrete.get_mutable_vector(self._X_BE_index).SetFromVector(
            x if X_BE is None else pose_to_vector(X_BE))

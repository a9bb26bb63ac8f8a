"""The true pose of a camera on the hand, sampled when a rendered camera takes its image, for
logs and Meshcat (Drake's ``RgbdSensor`` renders on demand and keeps no sampled pose)."""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import LeafSystem

from ..estimation.se3 import pose_to_vector, vector_to_pose
from ..estimation.validation import ROTATION_TOLERANCE, as_transform, check_positive, \
    rotation_defect


class HandCameraPose(LeafSystem):
    """X_WC = X_WE · X_EC, sampled every ``period`` seconds (and at initialization) and held, like
    ``HandEyeCamera``'s ``X_WC`` output: the camera pose at the instant its image is taken.

    It samples in an unrestricted update, like ``TargetDetector`` and ``CameraTriggerSampler``,
    so it sees the plant in the state the image was rendered from (see
    ``systems.trigger_sampler``).

    Input port:
        X_WE (12): end-effector pose in the world, [vec_row(R); p (m)].
    Output port:
        X_WC (12): true camera pose in the world, [vec_row(R); p (m)], of the last sample.
    """

    def __init__(self, X_EC, period: float, offset: float = 0.0):
        LeafSystem.__init__(self)
        self._X_EC = as_transform(X_EC, "X_EC")
        self._period = check_positive(period, "period")
        offset = check_positive(offset, "offset", allow_zero=True)
        self._X_WE_port = self.DeclareVectorInputPort("X_WE", 12)
        self._X_WC_index = self.DeclareDiscreteState(pose_to_vector(np.eye(4)))
        self.DeclarePeriodicUnrestrictedUpdateEvent(self._period, offset, self._Sample)
        self.DeclareInitializationUnrestrictedUpdateEvent(self._Sample)
        self._X_WC_port = self.DeclareStateOutputPort("X_WC", self._X_WC_index)

    def get_X_WE_input_port(self):
        return self._X_WE_port

    def get_X_WC_output_port(self):
        return self._X_WC_port

    @property
    def X_EC(self) -> np.ndarray:
        return self._X_EC.copy()

    def _Sample(self, context, state):
        x = np.array(self._X_WE_port.Eval(context), dtype=float)
        if not np.all(np.isfinite(x)) or rotation_defect(x[:9].reshape(3, 3)) > \
                ROTATION_TOLERANCE:
            raise ValueError(f"X_WE input of {self.get_name()!r}: not a finite rigid pose at "
                             f"t = {context.get_time()}: {x.tolist()}")
        state.get_mutable_discrete_state().get_mutable_vector(self._X_WC_index).SetFromVector(
            pose_to_vector(vector_to_pose(x) @ self._X_EC))

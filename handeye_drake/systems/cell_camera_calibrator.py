"""On-line calibration of a cell camera (fixed in the cell, X_BC) that watches the same fixed board
as a hand camera: one calibrator system per camera.

Why a system of its own, not one filter for the rig: a fixed camera watching a fixed board sees
one view — the robot's motion tells nothing about X_BC by itself. X_BC enters only through the
board's pose, which the hand camera's calibration gives: at each frame where both cameras see the
board,

    X_BC,k = X_BE,k · X_EC · X_CT,hand,k · X_CT,cell,k⁻¹

so the hand camera's filter (``HandEyeCalibrator``, refined from the servo's motion) is the rig's
only estimator of motion, and this system composes its current X_EC with the frames it keeps
(a ring buffer of the last ``capacity`` frames): as the hand camera's estimate is refined, the
cell camera's follows — it is recomputed from every kept frame at each update, not filtered.

Estimate: the chordal mean of the X_BC,k rotations and the mean of their translations.
Covariance [δθ (rad); δt (m)] about/along B (R = exp(δθ) R̂): the hand camera's X_EC covariance
through the composition (numerical Jacobian), plus the cell detector's covariance of its view
through X_CT,cell⁻¹ (not divided by the number of frames: a fixed view repeats its error), plus the
scatter of the X_BC,k over the frames divided by their number (the hand camera's view noise).

Ports (12-vectors are ``pose_to_vector`` [vec_row(R); p]):
- inputs ``X_BE`` (12, sampled at the camera trigger), ``X_CT_hand`` (12), ``hand_valid`` (1),
  ``X_EC`` (12, the hand calibrator's estimate), ``X_EC_covariance`` (36), ``X_CT_cell`` (12),
  ``cell_valid`` (1), ``X_CT_cell_covariance`` (36, the cell detector's, in its [δθ; δt] of X_CT);
- outputs ``X_BC_estimate`` (12), ``X_BC_std`` (6: rotation deg, translation m), ``X_BC_covariance``
  (36), ``frames`` (1: frames kept).
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import EventStatus, LeafSystem

from ..estimation.se3 import inverse, pose_to_vector, retract_pose, rotation_log, vector_to_pose
from ..estimation.validation import as_transform, check_positive

#: A pair of 12-vectors per kept frame: X_BE and X_CT,hand · X_CT,cell⁻¹.
_FRAME = 24


def _mean_pose(Xs: np.ndarray) -> np.ndarray:
    """Chordal mean rotation (SVD projection of the summed rotations) and mean translation."""
    U, _, Vt = np.linalg.svd(Xs[:, :3, :3].sum(axis=0))
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, Xs[:, :3, 3].mean(axis=0)
    return X


def _tangent(X1, X2):
    return np.concatenate([rotation_log(X1[:3, :3] @ X2[:3, :3].T), X1[:3, 3] - X2[:3, 3]])


class CellCameraCalibrator(LeafSystem):
    """X_BC of a cell camera from the hand camera's X_EC estimate (module docstring).

    Args:
        period: the cameras' sample period (s); offset: the update offset after the trigger.
        X_BC_initial_guess: output before the first frame with both cameras (4×4).
        capacity: frames kept (the most recent).
    """

    def __init__(self, period: float, X_BC_initial_guess=None, capacity: int = 300,
                 offset: float | None = None):
        super().__init__()
        self._period = check_positive(period, "period")
        offset = 0.5 * self._period if offset is None else check_positive(offset, "offset",
                                                                          allow_zero=True)
        if isinstance(capacity, bool) or not isinstance(capacity, (int, np.integer)) \
                or capacity < 1:
            raise ValueError(f"capacity: expected an integer ≥ 1, got {capacity!r}")
        self._capacity = int(capacity)
        X0 = np.eye(4) if X_BC_initial_guess is None else as_transform(
            X_BC_initial_guess, "X_BC_initial_guess", rigid=True)
        self._in = {name: self.DeclareVectorInputPort(name, n) for name, n in (
            ("X_BE", 12), ("X_CT_hand", 12), ("hand_valid", 1), ("X_EC", 12),
            ("X_EC_covariance", 36), ("X_CT_cell", 12), ("cell_valid", 1),
            ("X_CT_cell_covariance", 36))}
        self._buffer = self.DeclareDiscreteState(self._capacity * _FRAME)
        self._count = self.DeclareDiscreteState(1)           # frames seen (ring position)
        self._X = self.DeclareDiscreteState(pose_to_vector(X0))
        # Before the first frame with both cameras: 180° and 10 m, i.e. unknown (logs stay finite).
        self._std = self.DeclareDiscreteState([180.0] * 3 + [10.0] * 3)
        self._cov = self.DeclareDiscreteState(np.zeros(36))
        self._kept = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, offset, self._Update)
        self._out = {name: self.DeclareStateOutputPort(name, index) for name, index in (
            ("X_BC_estimate", self._X), ("X_BC_std", self._std),
            ("X_BC_covariance", self._cov), ("frames", self._kept))}

    def get_input_port_by_name(self, name: str):
        return self._in[name]

    def get_output_port_by_name(self, name: str):
        return self._out[name]

    def _Update(self, context, discrete):
        ev = {n: p.Eval(context) for n, p in self._in.items()}
        if ev["hand_valid"][0] < 0.5 or ev["cell_valid"][0] < 0.5:
            return EventStatus.DidNothing()
        X_CT_cell = vector_to_pose(ev["X_CT_cell"])
        B = vector_to_pose(ev["X_CT_hand"]) @ inverse(X_CT_cell)
        count = int(discrete.get_vector(self._count).value()[0])
        buf = discrete.get_mutable_vector(self._buffer).get_mutable_value()
        slot = count % self._capacity
        buf[slot * _FRAME:(slot + 1) * _FRAME] = np.concatenate([ev["X_BE"], pose_to_vector(B)])
        count += 1
        discrete.get_mutable_vector(self._count).SetFromVector([count])
        n = min(count, self._capacity)
        frames = buf[:n * _FRAME].reshape(n, 2, 12)
        A = np.array([vector_to_pose(v) for v in frames[:, 0]])
        Bs = np.array([vector_to_pose(v) for v in frames[:, 1]])
        X_EC = vector_to_pose(ev["X_EC"])

        def estimate(X_EC_, last_B=None):
            Bk = Bs if last_B is None else np.concatenate([Bs[:-1], last_B[None]])
            return _mean_pose(A @ X_EC_[None] @ Bk)

        X = estimate(X_EC)
        per = np.array([_tangent(Xk, X) for Xk in A @ X_EC[None] @ Bs])
        scatter = (per.T @ per) / max(n - 1, 1) / n if n > 1 else np.zeros((6, 6))
        h = 1e-6
        J_ec = np.zeros((6, 6))
        J_cell = np.zeros((6, 6))
        for i in range(6):
            d = np.zeros(6)
            d[i] = h
            J_ec[:, i] = (_tangent(estimate(retract_pose(X_EC, d)), X)
                          - _tangent(estimate(retract_pose(X_EC, -d)), X)) / (2 * h)
            # The cell view's error moves every frame alike (one fixed view): perturb them all.
            Bp = vector_to_pose(ev["X_CT_hand"]) @ inverse(retract_pose(X_CT_cell, d))
            Bm = vector_to_pose(ev["X_CT_hand"]) @ inverse(retract_pose(X_CT_cell, -d))
            J_cell[:, i] = (_tangent(_mean_pose(A @ X_EC[None] @ (Bs @ inverse(B) @ Bp)), X)
                            - _tangent(_mean_pose(A @ X_EC[None] @ (Bs @ inverse(B) @ Bm)), X)
                            ) / (2 * h)
        C = (J_ec @ np.asarray(ev["X_EC_covariance"]).reshape(6, 6) @ J_ec.T
             + J_cell @ np.asarray(ev["X_CT_cell_covariance"]).reshape(6, 6) @ J_cell.T
             + scatter)
        C = 0.5 * (C + C.T)
        sd = np.sqrt(np.maximum(np.diag(C), 0.0))
        discrete.get_mutable_vector(self._X).SetFromVector(pose_to_vector(X))
        discrete.get_mutable_vector(self._cov).SetFromVector(C.reshape(36))
        discrete.get_mutable_vector(self._std).SetFromVector(
            np.concatenate([np.degrees(sd[:3]), sd[3:]]))
        discrete.get_mutable_vector(self._kept).SetFromVector([n])
        return EventStatus.Succeeded()


__all__ = ["CellCameraCalibrator"]

"""The interface every on-line hand-eye estimator implements, and what they share.

An on-line estimator is built from its settings (a dataclass of ``configs``) and an initial
``X_CE``; it is fed synchronized samples one at a time; it exposes its estimate with its
uncertainty; and its whole state round-trips exactly through a flat vector, which is how the Drake
calibrator (``systems.calibrator``) keeps it as discrete state — so the system's step *is* the
class's step.

    est = HandEyeTargetFilter(TargetFilter(rotation_sigma=0.002, translation_sigma=5e-4), X_CE0)
    for X_BE, X_CT in samples:          # robot pose (E in B), measured target pose (T in C)
        est.update(X_BE, X_CT)          # False: not fused (gated out, too little motion, ...)
    est.X_EC, est.X_EC_rotation_std_deg, est.X_EC_translation_std, est.diagnostics()
    v = est.to_vector(); same = type(est).from_vector(est.config, v)

Estimators built on motion pairs (A, B) form them from consecutive samples themselves; they also
take motions directly through ``update_motion(A, B)`` (A = X_{C(k−1)C(k)}, B = X_{E(k−1)E(k)}).

Frames: X_CE is the paper's X (end-effector E in camera C); X_EC = inv(X_CE) is the camera on the
hand. Covariances of a pose are of the error state [δθ; δt] with R = exp([δθ]×) R̂ (rad, about
the axes of the frame the pose is expressed in) and t = t̂ + δt (m).
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from . import defaults
from .se3 import inverse, inverse_tangent_jacobian, rotation_angle, rotation_log


class OnlineEstimator(Protocol):
    """What ``HandEyeCalibrator`` and the applications need from an on-line estimator."""

    config: object

    def update(self, X_BE, X_CT, X_CT_covariance=None) -> bool:
        """Fuses one synchronized sample (robot pose X_BE, measured target pose X_CT, optionally
        the 6×6 covariance of X_CT's error); True when it changed the estimate."""

    @property
    def X_CE(self) -> np.ndarray: ...

    @property
    def X_EC(self) -> np.ndarray: ...

    @property
    def covariance(self) -> np.ndarray:
        """Covariance of the estimator's own error state (layout in its class docstring)."""

    @property
    def X_CE_covariance(self) -> np.ndarray:
        """6×6 covariance of X_CE's error [δθ (rad, about C's axes); δt (m, in C)]."""

    @property
    def num_updates(self) -> int: ...

    @property
    def num_rejected(self) -> int: ...

    def diagnostics(self) -> list[str]: ...

    def to_vector(self) -> np.ndarray: ...

    @classmethod
    def from_vector(cls, config, vector): ...

    @classmethod
    def vector_size(cls, config) -> int: ...


class VectorLayout:
    """Named slices of a flat state vector (to keep ``to_vector`` / ``from_vector`` readable)."""

    def __init__(self, **sizes: int):
        self.slices = {}
        start = 0
        for name, n in sizes.items():
            self.slices[name] = slice(start, start + n)
            start += n
        self.size = start

    def pack(self, **parts) -> np.ndarray:
        v = np.empty(self.size)
        for name, s in self.slices.items():
            v[s] = np.ravel(parts[name])
        return v

    def unpack(self, v) -> dict:
        v = np.asarray(v, dtype=float)
        if v.shape != (self.size,):
            raise ValueError(f"vector: expected {self.size} values, got shape {v.shape}")
        return {name: v[s] for name, s in self.slices.items()}


class Excitation:
    """How much the robot has rotated, and about which axes: S = Σ φ φᵀ over the rotation vectors
    φ (rad, in E) the estimator learned from. Robot poses are exact, so this tells which
    directions of X the data can determine, independently of the (noisy) estimate.

    A rotation φ = θ n constrains the hand-eye rotation about the axes perpendicular to n only,
    so the information about the rotation of X in a direction v is ≈ vᵀ (tr(S) I − S) v / σ²
    (σ: the rotation noise of a measurement). Its weakest direction is S's dominant axis: with
    rotations about parallel axes only, the rotation about that axis and the translation along
    it are not determined (4-DOF / SCARA-like motions).
    """

    def __init__(self, S=None):
        self.S = np.zeros((3, 3)) if S is None else np.array(S, dtype=float).reshape(3, 3)

    def add(self, phi) -> None:
        self.S += np.outer(phi, phi)

    def weakest(self, rotation_sigma: float) -> tuple[np.ndarray, float]:
        """(unit axis in E, predicted std of the rotation of X about it in degrees)."""
        w, V = np.linalg.eigh(self.S)
        info = (w[0] + w[1]) / max(rotation_sigma, 1e-300) ** 2
        std = math.degrees(1.0 / math.sqrt(info)) if info > 0 else math.inf
        return V[:, 2], std

    def message(self, rotation_sigma: float, what: str = "X") -> str | None:
        axis, std = self.weakest(rotation_sigma)
        if std <= defaults.UNOBSERVABLE_STD_DEG:
            return None
        if not np.any(self.S):
            return (f"{what} is not observable: the robot has not rotated (no fused sample "
                    "rotates it)")
        a = np.round(axis / np.linalg.norm(axis), 2).tolist()
        return (f"{what} is not observable from these motions: the rotation about the "
                f"end-effector axis {a} (and the translation along it) is determined only to "
                f"±{min(std, 999.0):.3g}° — every rotation is about (nearly) parallel axes or too "
                "small; rotate about another axis")


class EstimatorBase:
    """Shared bookkeeping: counters, standard deviations of X_EC, diagnostics.

    Subclasses keep ``self._X_CE_hat()`` and ``self.X_CE_covariance`` and the counters
    ``_num_updates`` (fused), ``_num_rejected`` (refused by the gate or as gross errors),
    ``_num_skipped`` (not usable: first sample, too little rotation), ``_consecutive`` (rejections
    in a row), ``_num_inflations``, ``_last_nis``, and ``_excitation``.
    """

    config: object
    #: Rotation noise (rad per axis) used by the excitation check; set by subclasses.
    _excitation_sigma: float = 1e-3

    def _copy(self):
        """An independent copy, cheaply: updates assign new arrays to the estimator's attributes
        and never change an array in place — except the excitation sum, copied here."""
        other = object.__new__(type(self))  # (copy.copy's result, without its protocol)
        other.__dict__.update(self.__dict__)
        other._excitation = Excitation(self._excitation.S)
        return other

    def _init_counters(self) -> None:
        self._num_updates = 0
        self._num_rejected = 0
        self._num_skipped = 0
        self._consecutive = 0
        self._num_inflations = 0
        self._last_nis = math.nan
        self._nis_sum = 0.0
        self._nis_count = 0
        self._excitation = Excitation()

    _COUNTERS = VectorLayout(num_updates=1, num_rejected=1, num_skipped=1, consecutive=1,
                             num_inflations=1, last_nis=1, nis_sum=1, nis_count=1, excitation=9)
    #: Dimension of one measurement (the χ² degrees of freedom of its NIS); set by subclasses.
    _MEASUREMENT_DOF = 6

    @classmethod
    def vector_size(cls, config=None) -> int:
        """Length of ``to_vector`` (the subclass's ``_LAYOUT``; the same for every config)."""
        return cls._LAYOUT.size

    def _record_nis(self, nis: float) -> None:
        """Adds the NIS of a fused measurement to the consistency test of ``diagnostics``."""
        if math.isfinite(nis):
            self._nis_sum += float(nis)
            self._nis_count += 1

    def _counters_vector(self) -> np.ndarray:
        # ``_COUNTERS``'s order, written out (it runs at every sample of the calibrator).
        return np.array([self._num_updates, self._num_rejected, self._num_skipped,
                         self._consecutive, self._num_inflations, self._last_nis, self._nis_sum,
                         self._nis_count, *self._excitation.S.ravel().tolist()], dtype=float)

    def _set_counters(self, v) -> None:
        c = self._COUNTERS.unpack(v)
        self._num_updates = int(c["num_updates"][0])
        self._num_rejected = int(c["num_rejected"][0])
        self._num_skipped = int(c["num_skipped"][0])
        self._consecutive = int(c["consecutive"][0])
        self._num_inflations = int(c["num_inflations"][0])
        self._last_nis = float(c["last_nis"][0])
        self._nis_sum = float(c["nis_sum"][0])
        self._nis_count = int(c["nis_count"][0])
        self._excitation = Excitation(c["excitation"])

    def _motion_since_previous(self, X_BE, X_CT):
        """For the motion-pair filters: (A, B) from the previous usable sample to this one, or
        None for the first sample and for motions rotating less than ``self._min_rotation``
        (counted as skipped). A uses a general inverse: measured poses may be non-orthonormal
        (coefficient noise, or poses chained from noisy motions). The caller stores
        ``self._prev`` once it has used the motion."""
        if self._prev is None:
            self._prev = (X_BE, X_CT)
            self._num_skipped += 1
            return None
        X_BE0, X_CT0 = self._prev
        B = inverse(X_BE0) @ X_BE
        if self._min_rotation and rotation_angle(B[:3, :3]) < self._min_rotation:
            self._num_skipped += 1
            return None
        return X_CT0 @ np.linalg.inv(X_CT), B

    # ------------------------------------------------------------------------ the estimate
    @property
    def X_CE(self) -> np.ndarray:
        """Estimate of X_CE, the paper's X (E in C), an exact rigid transform."""
        return self._X_CE_hat().copy()

    @property
    def X_EC(self) -> np.ndarray:
        """Estimate of X_EC = inv(X_CE), the camera on the hand."""
        return inverse(self._X_CE_hat())

    @property
    def X_EC_covariance(self) -> np.ndarray:
        """6×6 covariance of X_EC's error [δθ (rad, about E's axes); δt (m, in E)]."""
        J = inverse_tangent_jacobian(self._X_CE_hat())
        return J @ self.X_CE_covariance @ J.T

    @property
    def rotation_std_deg(self) -> np.ndarray:
        """Standard deviations of X_CE's rotation error about C's axes (deg)."""
        return np.degrees(np.sqrt(np.maximum(np.diag(self.X_CE_covariance)[:3], 0.0)))

    @property
    def translation_std(self) -> np.ndarray:
        """Standard deviations of t_CE's coordinates (m, in C)."""
        return np.sqrt(np.maximum(np.diag(self.X_CE_covariance)[3:], 0.0))

    @property
    def X_EC_rotation_std_deg(self) -> np.ndarray:
        """Standard deviations of X_EC's rotation error about E's axes (deg)."""
        return np.degrees(np.sqrt(np.maximum(np.diag(self.X_EC_covariance)[:3], 0.0)))

    @property
    def X_EC_translation_std(self) -> np.ndarray:
        """Standard deviations of t_EC's coordinates (m, in E)."""
        return np.sqrt(np.maximum(np.diag(self.X_EC_covariance)[3:], 0.0))

    # --------------------------------------------------------------------------- counters
    @property
    def num_updates(self) -> int:
        """Measurements fused so far."""
        return self._num_updates

    @property
    def num_rejected(self) -> int:
        """Measurements refused by the NIS gate or as gross errors."""
        return self._num_rejected

    @property
    def num_skipped(self) -> int:
        """Samples not usable (the first of a motion pair, too little rotation)."""
        return self._num_skipped

    @property
    def num_inflations(self) -> int:
        """Gate lock-outs recovered from by inflating the covariance."""
        return self._num_inflations

    @property
    def last_nis(self) -> float:
        """Normalized innovation squared of the last measurement (nan before any)."""
        return self._last_nis

    @property
    def last_rejected(self) -> bool:
        return self._consecutive > 0

    @property
    def excitation(self) -> Excitation:
        return Excitation(self._excitation.S)

    def diagnostics(self) -> list[str]:
        """Why the estimate should not be trusted (empty when nothing is wrong): the data does not
        determine every direction of X, or the filter refuses (nearly) every measurement."""
        out = []
        message = self._excitation.message(self._excitation_sigma)
        if message:
            out.append(message)
        seen = self._num_updates + self._num_rejected
        if self._num_rejected and self._num_rejected >= max(3, 0.5 * seen):
            out.append(f"the filter rejected {self._num_rejected} of {seen} measurements: the "
                       "data does not fit its noise model (wrong sigmas, wrong frames, or a wrong "
                       "start)")
        message = self.consistency_message()
        if message:
            out.append(message)
        return out

    @property
    def mean_nis(self) -> float:
        """Mean normalized innovation squared of the fused measurements (nan before any); its
        expectation is the measurement dimension when the noise model is right."""
        return self._nis_sum / self._nis_count if self._nis_count else math.nan

    def consistency_message(self) -> str:
        """Non-empty when the fused measurements do not fit the noise model: their mean NIS is
        above both its 99.9 % bound and ``defaults.NIS_TOLERANCE`` × its expectation, over at
        least ``defaults.NIS_MIN_UPDATES`` updates. The covariance — the σ reported — is then too
        small."""
        n, m = self._nis_count, self._MEASUREMENT_DOF
        if n < defaults.NIS_MIN_UPDATES:
            return ""
        from scipy.stats import chi2
        bound = max(float(chi2.ppf(0.999, m * n)) / n, defaults.NIS_TOLERANCE * m)
        mean = self.mean_nis
        if mean <= bound:
            return ""
        return (f"the measurements do not fit the noise model: their mean NIS is {mean:.3g} for "
                f"{m}-dimensional measurements over {n} updates (expected ≈ {m}, bound "
                f"{bound:.3g}), so the σ reported are too small — check the noise settings "
                "(their size, pose noise vs motion noise), the frames and the synchronization")


def rotation_vector_between(R0, R1) -> np.ndarray:
    """φ with R1 = R0 exp([φ]×): the rotation from R0 to R1 in R0's frame (rad)."""
    return rotation_log(np.asarray(R0).T @ np.asarray(R1))

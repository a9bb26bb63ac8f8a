"""On-line hand-eye estimators that respect SO(3): error-state (multiplicative) Kalman filters.

The estimate is kept as an exact rigid transform; the filter state is a small perturbation
δ = [δθ; δt] with R = exp(δθ) R̂, t = t̂ + δt, and the covariance lives in that tangent space.

- ``ManifoldHandEyeFilter``: the paper's measurement, one motion pair (A, B) at a time, with
  rotation-vector noise on the measured R_A, iterated where the update is large, behind an
  innovation (NIS) gate.
- ``HandEyeTargetFilter``: AX = ZB on raw synchronized poses: X_CE and the fixed target pose in
  the robot base X_BT, estimated jointly from each (X_BE, X_CT) sample. Each measurement enters
  once with white noise; differencing poses into motions instead makes consecutive motions share
  noise and throws away the fact that the target does not move.

Both implement ``estimator.OnlineEstimator`` (settings: ``configs.ManifoldFilter``,
``configs.TargetFilter``). Frames: X_CE is the paper's X (E in C); X_EC = inv(X_CE); X_BE
end-effector in robot base; X_CT target in camera; X_BT target in robot base.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import scipy.linalg
from scipy.linalg.lapack import dpotrf as _potrf
from scipy.linalg.lapack import dpotrs as _potrs
from scipy.stats import chi2

from . import defaults, kernels
from .configs import ManifoldFilter, TargetFilter
from .estimator import EstimatorBase, VectorLayout, rotation_vector_between
from .orthonormalize import orthonormalize_unchecked
from .se3 import (
    inverse,
    make_transform,
    pose_to_vector,
    retract_pose,
    rotation_log,
    skew,
    vector_to_pose,
)
from .validation import as_transform, check_covariance, check_noisy_rotation


_I3 = np.eye(3)
_I3.flags.writeable = False
_EYES = {}
_NO_R_BE_REF = np.full(9, np.nan)  # (to_vector of a filter whose target is not placed yet)


def _eye(n: int) -> np.ndarray:
    """A shared read-only n×n identity (hot paths allocate none)."""
    I = _EYES.get(n)
    if I is None:
        I = _EYES[n] = np.eye(n)
        I.flags.writeable = False
    return I


def _robust_inverse(S):
    """S⁻¹ of a symmetric positive definite S through its Cholesky factor; the pseudo-inverse
    when S is not positive definite. (LAPACK's potrf/potrs called directly: the same arithmetic
    as ``scipy.linalg.cho_factor``/``cho_solve``, without their per-call checks.)"""
    c, info = _potrf(S, lower=0, overwrite_a=0, clean=0)
    if info == 0:
        x, info = _potrs(c, _eye(len(S)), lower=0, overwrite_b=0)
        if info == 0:
            return x
    if info < 0:  # an illegal argument: not expected for a finite square S
        raise ValueError(f"innovation covariance: LAPACK rejected argument {-info}")
    return np.linalg.pinv(S, rcond=1e-12, hermitian=True)


@functools.lru_cache(maxsize=64)
def gate_threshold(probability: float | None, dof: int) -> float:
    """NIS threshold of a gate probability (∞ for None)."""
    return math.inf if probability is None else float(chi2.ppf(probability, dof))


def error_state_update(estimate, P, measurement, residual, retract, Rn, gate=np.inf,
                       iterations: int = 3):
    """One iterated error-state EKF update, as a pure function.

    Args:
        estimate: the prior estimate (any object ``residual``/``retract`` understand).
        P: prior covariance of the error state (n×n), process noise already added.
        measurement: passed to ``residual(estimate, measurement) -> (z, H)`` with z = y ⊖ h(x̂)
            and H = ∂h/∂δ (so z(x̂ ⊕ δ) ≈ z − H δ).
        retract: ``retract(estimate, δ)`` → the estimate moved by δ.
        Rn: measurement noise covariance (m×m).
        gate: NIS threshold; above it (or above the gross-error bound
            m · ``defaults.GROSS_ERROR_SIGMAS``²) the measurement is rejected.
        iterations: Gauss–Newton iterations (1 = plain EKF); δ is always measured from the prior.

    Returns:
        (estimate, P, accepted, nis): unchanged estimate and P when rejected.
    """
    z, H = residual(estimate, measurement)
    S_inv = _robust_inverse(H @ P @ H.T + Rn)
    nis = float(z @ S_inv @ z)
    if not math.isfinite(nis) or nis > min(gate, len(z) * defaults.GROSS_ERROR_SIGMAS**2):
        return estimate, P, False, nis
    est, delta = estimate, np.zeros(len(P))
    for i in range(iterations):
        K = P @ H.T @ S_inv
        delta_new = K @ (z + H @ delta)
        d = delta_new - delta
        step = math.sqrt(float(d @ d))
        delta = delta_new
        est = retract(estimate, delta)
        if i + 1 == iterations or step < 1e-9:
            break
        z, H = residual(est, measurement)
        S_inv = _robust_inverse(H @ P @ H.T + Rn)
    K = P @ H.T @ S_inv
    I_KH = _eye(len(P)) - K @ H
    P_new = I_KH @ P @ I_KH.T + K @ Rn @ K.T
    return est, 0.5 * (P_new + P_new.T), True, nis


def covariance_inflation(z, H, P, Rn, target_nis: float, max_scale: float = 1e12):
    """Smallest s ≥ 1 with zᵀ (s H P Hᵀ + Rn)⁻¹ z ≤ target_nis, or None if no s ≤ max_scale
    achieves it (the innovation is not explained by any error of the state: a true outlier).

    Used to recover from a gate lock-out: an innovation that only a larger state error explains
    means the covariance is too small (inconsistent), not that the measurement is wrong.
    """
    HPH = H @ P @ H.T

    def nis(scale):
        return float(z @ _robust_inverse(scale * HPH + Rn) @ z)

    if nis(1.0) <= target_nis:
        return 1.0
    if not nis(max_scale) <= target_nis:
        return None
    lo, hi = 0.0, float(np.log(max_scale))  # bisection on log s: NIS decreases with s
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if nis(np.exp(mid)) <= target_nis:
            hi = mid
        else:
            lo = mid
    return float(np.exp(hi))


def pose_pair_update(estimate, P, measurement, residual, retract, Rn, gate=np.inf,
                     iterations: int = 3):
    """``error_state_update`` with ``residual = pose_residual`` and ``retract =
    retract_pose_pair`` (the target filter's), compiled (``kernels.pose_update``): the same
    arithmetic, equal to rounding. The rare cases the kernel leaves (an innovation covariance
    that is not positive definite, a residual rotation off SO(3)) take the numpy path."""
    X_CE, X_BT = estimate
    X_EB, R_CTm, t_CTm = measurement
    bound = min(gate, 6 * defaults.GROSS_ERROR_SIGMAS**2)
    X_CE_new, X_BT_new, P_new, code, nis = kernels.pose_update(
        np.ascontiguousarray(X_CE), np.ascontiguousarray(X_BT), np.ascontiguousarray(P),
        np.ascontiguousarray(X_EB), np.ascontiguousarray(R_CTm), np.ascontiguousarray(t_CTm),
        np.ascontiguousarray(Rn, dtype=float), float(bound), int(iterations))
    if code == 2:
        return error_state_update(estimate, P, measurement, residual, retract, Rn, gate,
                                  iterations)
    if code == 1:
        return estimate, P, False, float(nis)
    return (X_CE_new, X_BT_new), P_new, True, float(nis)


def gated_error_state_update(estimate, P, measurement, residual, retract, Rn, gate,
                             iterations: int, consecutive_rejections: int,
                             max_consecutive_rejections: int | None,
                             update=error_state_update):
    """``error_state_update`` with the NIS gate's lock-out recovery, as a pure function.

    When this measurement would be the ``max_consecutive_rejections``-th rejection in a row, so
    many rejections are far more likely a covariance that is too small (bad start, inconsistent
    P0) than outliers; without recovery the estimate would freeze and every later measurement be
    discarded. P is then inflated just enough for this innovation to look typical (χ² median);
    a measurement that no state error explains, or a gross error, stays rejected.

    ``update``: ``error_state_update`` or a function with its signature and results
    (``pose_pair_update``).

    Returns (estimate, P, accepted, nis, inflated).
    """
    est, P_new, accepted, nis = update(estimate, P, measurement, residual, retract, Rn, gate,
                                       iterations)
    if (accepted or max_consecutive_rejections is None or not np.isfinite(nis)
            or consecutive_rejections + 1 < max_consecutive_rejections):
        return est, P_new, accepted, nis, False
    z, H = residual(estimate, measurement)
    if nis > len(z) * defaults.GROSS_ERROR_SIGMAS**2:
        return est, P_new, False, nis, False
    s = covariance_inflation(z, H, P, Rn, float(chi2.ppf(0.5, len(z))))
    if s is None:
        return est, P_new, False, nis, False
    est, P_new, accepted, _ = update(estimate, s * P, measurement, residual, retract, Rn,
                                     np.inf, iterations)
    return est, P_new, accepted, nis, accepted


def motion_residual(X_CE, measurement):
    """(z, H) of one motion pair for ``error_state_update``; measurement = (R_A (projected on
    SO(3)), t_A, R_B, t_B); error state [δθ; δt] of X_CE."""
    R_Am, t_Am, R_B, t_B = measurement
    R, t = X_CE[:3, :3], X_CE[:3, 3]
    R_A = R @ R_B @ R.T
    t_A = R @ t_B + t - R_A @ t
    z = np.empty(6)
    z[:3] = rotation_log(R_Am @ R_A.T)
    z[3:] = t_Am - t_A
    I_RA = _I3 - R_A
    H = np.empty((6, 6))
    H[:3, :3] = I_RA
    H[:3, 3:] = 0.0
    H[3:, :3] = -skew(R @ t_B) + skew(R_A @ t) @ I_RA
    H[3:, 3:] = I_RA
    return z, H


def pose_residual(estimate, measurement):
    """(z, H) of one synchronized sample for AX = ZB; estimate = (X_CE, X_BT), measurement =
    (X_EB, R_CT (projected on SO(3)), t_CT); error state [δθ_CE; δt_CE; δθ_BT; δt_BT]."""
    X_CE, X_BT = estimate
    X_EB, R_CTm, t_CTm = measurement
    R_CE, t_CE = X_CE[:3, :3], X_CE[:3, 3]
    R_EB, t_EB = X_EB[:3, :3], X_EB[:3, 3]
    u = R_EB @ X_BT[:3, 3] + t_EB  # target origin in E
    R_CT = R_CE @ R_EB @ X_BT[:3, :3]
    t_CT = R_CE @ u + t_CE
    z = np.empty(6)
    z[:3] = rotation_log(R_CTm @ R_CT.T)
    z[3:] = t_CTm - t_CT
    R_CB = R_CE @ R_EB
    H = np.zeros((6, 12))
    H[:3, :3] = _I3
    H[:3, 6:9] = R_CB
    H[3:, :3] = -skew(R_CE @ u)
    H[3:, 3:6] = _I3
    H[3:, 9:12] = R_CB
    return z, H


def retract_pose_pair(estimate, delta):
    X_CE, X_BT = estimate
    return retract_pose(X_CE, delta[:6]), retract_pose(X_BT, delta[6:12])


def _noise_covariance(rotation_sigma: float, translation_sigma: float) -> np.ndarray:
    return np.diag([rotation_sigma**2] * 3 + [translation_sigma**2] * 3)


def _measured_rotation(R, name: str) -> np.ndarray:
    """The nearest rotation of a measured (possibly non-orthonormal) rotation block; refuses
    blocks that are no noisy rotation at all (singular, or a reflection)."""
    check_noisy_rotation(R, name)
    return orthonormalize_unchecked(R, "svd")


def _check_sample(X_BE, X_CT) -> tuple[np.ndarray, np.ndarray]:
    X_BE = as_transform(X_BE, "X_BE", rigid=True)
    X_CT = as_transform(X_CT, "X_CT", rigid=False)
    check_noisy_rotation(X_CT, "X_CT")  # (its projection onto SO(3) is the update's)
    return X_BE, X_CT


class _ErrorStateFilter(EstimatorBase):
    """The gated, iterated update shared by both filters."""

    _update_function = staticmethod(error_state_update)

    def _gated_update(self, meas, Rn, process) -> bool:
        est, P, accepted, nis, inflated = gated_error_state_update(
            self._estimate, self._P + process, meas, self._residual, self._retract, Rn,
            self._gate, self.config.iterations, self._consecutive,
            self.config.max_consecutive_rejections, self._update_function)
        self._last_nis = nis
        if not accepted:
            self._P = P
            self._num_rejected += 1
            self._consecutive += 1
            return False
        # (a sum is NaN or infinite when any entry is, or when it overflows: far beyond any
        # pose or covariance an update can meaningfully reach)
        total = float(P.sum())
        for v in (est if isinstance(est, tuple) else (est,)):
            total += float(v.sum())
        if not math.isfinite(total):
            raise ValueError("the update produced a non-finite estimate; state left unchanged")
        self._estimate, self._P = est, P
        self._num_updates += 1
        self._consecutive = 0
        self._num_inflations += int(inflated)
        self._record_nis(nis)
        return True

    @property
    def covariance(self) -> np.ndarray:
        """Covariance of the error state (see the class docstring for its layout)."""
        return self._P.copy()

    @property
    def X_CE_covariance(self) -> np.ndarray:
        return self._P[:6, :6].copy()


class ManifoldHandEyeFilter(_ErrorStateFilter):
    """Error-state EKF on SE(3) for AX = XB, one motion pair at a time.

    Measurement model: R_A = exp(n_r) R_X R_B R_Xᵀ, t_A = R_X t_B + t_X − R_A t_X + n_t with
    n_r ~ N(0, σ_r² I3) (rad), n_t ~ N(0, σ_t² I3) (m); error state [δθ; δt] of X_CE (6), so
    ``covariance`` is 6×6. Measured R_A may be non-orthonormal (the paper's coefficient noise);
    it is projected onto SO(3) (for coefficient noise of std σ, use rotation_sigma = σ/√2).

    ``update(X_BE, X_CT)`` forms the motion from the previous usable sample;
    ``update_motion(A, B)`` takes A = X_{C(k−1)C(k)}, B = X_{E(k−1)E(k)} directly. Both return
    False when the NIS gate rejected the pair (the estimate is then unchanged).

    Args:
        config: ``configs.ManifoldFilter`` (sigmas set).
        X_CE_init: initial estimate (4×4 rigid or RigidTransform).
        X_CE_covariance: optional 6×6 initial covariance replacing ``config.initial_variances``
            (e.g. the covariance of an ML start-up, see ``from_motions``).
    """

    _LAYOUT = VectorLayout(X_CE=12, P=36, prev=24, has_prev=1,
                           counters=EstimatorBase._COUNTERS.size)

    def __init__(self, config: ManifoldFilter, X_CE_init, X_CE_covariance=None):
        self.config = config.validated()
        self._estimate = as_transform(X_CE_init, "X_CE_init")
        self._P = (np.diag(self.config.initial_variances) if X_CE_covariance is None else
                   check_covariance(X_CE_covariance, "X_CE_covariance", 6))
        self._setup()
        self._prev = None
        self._init_counters()

    def _setup(self) -> None:
        c = self.config
        self._Rn = _noise_covariance(c.rotation_sigma, c.translation_sigma)
        self._G1 = np.diag(c.process_variances) if c.process_variances else np.zeros((6, 6))
        self._gate = gate_threshold(c.gate_probability, 6)
        self._min_rotation = math.radians(c.min_rotation_deg)
        self._excitation_sigma = c.rotation_sigma

    _residual = staticmethod(motion_residual)
    _retract = staticmethod(retract_pose)

    @classmethod
    def from_motions(cls, config: ManifoldFilter, A_list, B_list, method: str = "park",
                     coefficient_noise: bool = False):
        """A filter started consistently from a short buffer of motion pairs (e.g. the first
        10): ``ml.robust_initial_estimate`` (outlier-screened classical solution refined to the
        ML estimate) gives both the initial X_CE and its covariance; feed the filter the motions
        that follow. The start-up result (with its ``inliers`` mask) is kept as ``start_up``.
        ``coefficient_noise``: the measured R_A carry the paper's coefficient noise (of std
        √2 · config.rotation_sigma); the start-up then uses that likelihood exactly."""
        from .ml import robust_initial_estimate
        c = config.validated()
        if coefficient_noise:
            start = robust_initial_estimate(A_list, B_list, math.sqrt(2.0) * c.rotation_sigma,
                                            c.translation_sigma, "paper", method)
        else:
            start = robust_initial_estimate(A_list, B_list, c.rotation_sigma,
                                            c.translation_sigma, "so3", method)
        f = cls(c, start.X_CE, X_CE_covariance=start.covariance)
        f.start_up = start
        return f

    # ------------------------------------------------------------------------------- updates
    def update_motion(self, A, B) -> bool:
        """Fuses one motion pair; False if the NIS gate rejected it. Raises ValueError on bad
        input, leaving the state as it was."""
        A = as_transform(A, "A", rigid=False)
        B = as_transform(B, "B", rigid=True)
        return self._update_motion(_measured_rotation(A[:3, :3], "A"), A[:3, 3], B)

    def _update_motion(self, R_A, t_A, B) -> bool:
        fused = self._gated_update((R_A, t_A, B[:3, :3], B[:3, 3]), self._Rn, self._G1)
        if fused:
            self._excitation.add(rotation_log(B[:3, :3]))
        return fused

    def update(self, X_BE, X_CT, X_CT_covariance=None) -> bool:
        """Forms the motion pair since the previous usable sample and fuses it (the first
        sample, and samples within ``min_rotation_deg`` of the previous one, are skipped)."""
        return self._update(*_check_sample(X_BE, X_CT))

    def _update(self, X_BE, X_CT) -> bool:
        motion = self._motion_since_previous(X_BE, X_CT)
        if motion is None:
            return False
        A, B = motion
        fused = self._update_motion(orthonormalize_unchecked(A[:3, :3], "svd"), A[:3, 3], B)
        self._prev = (X_BE, X_CT)
        return fused

    def _X_CE_hat(self) -> np.ndarray:
        return self._estimate

    @property
    def state(self) -> np.ndarray:
        """[vec_row(R_X); t_X] of X_CE, the layout of ``HandEyeKalmanFilter.state``."""
        return pose_to_vector(self._estimate)

    # ------------------------------------------------------------------------------ vector
    def to_vector(self) -> np.ndarray:
        prev = (np.zeros(24) if self._prev is None else
                np.concatenate([pose_to_vector(self._prev[0]), pose_to_vector(self._prev[1])]))
        return self._LAYOUT.pack(X_CE=pose_to_vector(self._estimate), P=self._P, prev=prev,
                                 has_prev=float(self._prev is not None),
                                 counters=self._counters_vector())

    @classmethod
    def from_vector(cls, config: ManifoldFilter, vector):
        """The filter whose ``to_vector()`` is ``vector``; ``config`` must be validated (it is
        not re-checked: this is the Drake system's per-step path)."""
        v = cls._LAYOUT.unpack(vector)
        f = cls.__new__(cls)
        f.config = config
        f._setup()
        f._estimate = vector_to_pose(v["X_CE"])
        f._P = v["P"].reshape(6, 6).copy()
        f._prev = ((vector_to_pose(v["prev"][:12]), vector_to_pose(v["prev"][12:]))
                   if v["has_prev"][0] else None)
        f._set_counters(v["counters"])
        return f


class HandEyeTargetFilter(_ErrorStateFilter):
    """Error-state EKF for AX = ZB on synchronized poses: X_CE and the fixed target X_BT.

    ``update(X_BE, X_CT)`` fuses one synchronized sample: the robot pose (E in base, exact) and
    the measured target pose in the camera, modelled as X_CT = X_CE · X_BE⁻¹ · X_BT ⊕ noise
    (rotation-vector noise on R_CT, additive translation noise; or the sample's own 6×6
    covariance with ``config.use_measurement_covariance``). The error state is
    [δθ_CE; δt_CE; δθ_BT; δt_BT] (12), so ``covariance`` is 12×12; ``X_CE_covariance`` is its
    6×6 hand-eye block.

    The target pose needs no prior: without ``X_BT_init`` the first sample places it (the pose
    implied by that sample and the initial hand-eye estimate, with
    ``config.target_prior_variances``) and is not fused otherwise. A refused update (bad input,
    gate) leaves the whole state untouched.

    Args:
        config: ``configs.TargetFilter`` (sigmas set).
        X_CE_init: initial estimate (4×4 rigid or RigidTransform).
        X_BT_init: optional initial target pose in the robot base.
        X_CE_covariance: optional 6×6 initial covariance of X_CE (replaces
            ``config.initial_variances``).
    """

    _LAYOUT = VectorLayout(X_CE=12, X_BT=12, P=144, target_known=1, R_BE_ref=9,
                           counters=EstimatorBase._COUNTERS.size)

    def __init__(self, config: TargetFilter, X_CE_init, X_BT_init=None, X_CE_covariance=None):
        self.config = config.validated()
        X_CE = as_transform(X_CE_init, "X_CE_init")
        P_hand_eye = (np.diag(self.config.initial_variances) if X_CE_covariance is None else
                      check_covariance(X_CE_covariance, "X_CE_covariance", 6))
        self._P = scipy.linalg.block_diag(P_hand_eye, np.diag(self.config.target_prior_variances))
        self._target_known = X_BT_init is not None
        X_BT = np.eye(4) if X_BT_init is None else as_transform(X_BT_init, "X_BT_init")
        self._estimate = (X_CE, X_BT)
        self._R_BE_ref = None
        self._setup()
        self._init_counters()

    def _setup(self) -> None:
        c = self.config
        self._Rn = _noise_covariance(c.rotation_sigma, c.translation_sigma)
        self._G1 = np.zeros((12, 12))
        if c.process_variances:
            self._G1[:6, :6] = np.diag(c.process_variances)
        self._gate = gate_threshold(c.gate_probability, 6)
        self._excitation_sigma = c.rotation_sigma

    _residual = staticmethod(pose_residual)
    _retract = staticmethod(retract_pose_pair)
    _update_function = staticmethod(pose_pair_update)

    def update(self, X_BE, X_CT, X_CT_covariance=None) -> bool:
        """Fuses one synchronized sample; False if the NIS gate rejected it (the state is then
        unchanged). ``X_CT_covariance``: the sample's 6×6 covariance of [δθ; δt] of X_CT, used
        when ``config.use_measurement_covariance``. Raises ValueError on bad input."""
        X_BE, X_CT = _check_sample(X_BE, X_CT)
        if X_CT_covariance is not None:
            X_CT_covariance = check_covariance(X_CT_covariance, "X_CT_covariance", 6)
        return self._update(X_BE, X_CT, X_CT_covariance)

    def _update(self, X_BE, X_CT, X_CT_covariance=None) -> bool:
        R_CTm = kernels.project_to_rotation(np.ascontiguousarray(X_CT[:3, :3]))
        if not self._target_known:
            # The first sample only places the target (X_BT implied by it and the current
            # hand-eye estimate), keeping its prior covariance: fusing it would make a first
            # sample that happens to be an outlier the reference every later sample is gated
            # against.
            X_CE = self._estimate[0]
            self._estimate = (X_CE, X_BE @ inverse(X_CE) @ make_transform(R_CTm, X_CT[:3, 3]))
            self._target_known = True
            self._R_BE_ref = X_BE[:3, :3].copy()
            self._num_skipped += 1
            return False
        Rn = (X_CT_covariance if self.config.use_measurement_covariance
              and X_CT_covariance is not None else self._Rn)
        X_EB = kernels.inverse_pose(np.ascontiguousarray(X_BE))
        fused = self._gated_update((X_EB, R_CTm, X_CT[:3, 3]), Rn, self._G1)
        if fused:
            if self._R_BE_ref is None:  # X_BT_init given: no placing sample
                self._R_BE_ref = X_BE[:3, :3].copy()
            R_BE = np.ascontiguousarray(X_BE[:3, :3])
            phi, ok = kernels.rotation_between(self._R_BE_ref, R_BE)
            self._excitation.add(phi if ok else rotation_vector_between(self._R_BE_ref,
                                                                        X_BE[:3, :3]))
        return fused

    @classmethod
    def vector_step(cls, config: TargetFilter):
        """``step(v, x_BE, x_CT, mode) -> (code, v_new, x_CE, x_EC, std, cov, status)``: ``_update``
        of one sample (pose vectors [vec_row(R); p], no sample covariance) applied to a state
        vector ``v`` (``to_vector()``), compiled (``kernels.target_filter_step``, equal bit for
        bit), with the calibrator's outputs of the result. Code 2: a case it leaves to
        ``from_vector(v)._update`` (then ``v_new`` is ``v``). ``config`` must be validated."""
        layout = {name: s.start for name, s in cls._LAYOUT.slices.items()}
        layout["size"] = cls._LAYOUT.size
        if layout != kernels.TARGET_FILTER_LAYOUT:
            raise AssertionError(f"kernels.TARGET_FILTER_LAYOUT {kernels.TARGET_FILTER_LAYOUT} "
                                 f"differs from HandEyeTargetFilter._LAYOUT {layout}")
        f = cls.__new__(cls)
        f.config = config
        f._setup()
        G1, Rn = np.ascontiguousarray(f._G1), np.ascontiguousarray(f._Rn)
        bound = float(min(f._gate, 6 * defaults.GROSS_ERROR_SIGMAS**2))
        iterations = int(config.iterations)
        limit = (-1 if config.max_consecutive_rejections is None
                 else int(config.max_consecutive_rejections))
        kernel = kernels.target_filter_step

        def step(v, x_BE, x_CT, mode):
            return kernel(v, x_BE, x_CT, G1, Rn, bound, iterations, limit, float(mode))
        return step

    def _X_CE_hat(self) -> np.ndarray:
        return self._estimate[0]

    @property
    def X_BT(self) -> np.ndarray:
        """Estimate of the target pose in the robot base."""
        return self._estimate[1].copy()

    @property
    def state(self) -> np.ndarray:
        """[vec_row(R_X); t_X] of X_CE."""
        return pose_to_vector(self._estimate[0])

    def diagnostics(self) -> list[str]:
        out = super().diagnostics()
        if self._num_updates == 0 and self._num_rejected:
            out.append(f"no sample accepted: all {self._num_rejected} were rejected (the first "
                       "samples disagree with the start estimate beyond their noise)")
        return out

    # ------------------------------------------------------------------------------ vector
    def to_vector(self) -> np.ndarray:
        # ``_LAYOUT``'s order, written out (the calibrator stores it at every sample).
        X_CE, X_BT = self._estimate
        return np.concatenate((
            X_CE[:3, :3].ravel(), X_CE[:3, 3], X_BT[:3, :3].ravel(), X_BT[:3, 3],
            self._P.ravel(), (float(self._target_known),),
            _NO_R_BE_REF if self._R_BE_ref is None else self._R_BE_ref.ravel(),
            self._counters_vector()))

    @classmethod
    def from_vector(cls, config: TargetFilter, vector):
        """The filter whose ``to_vector()`` is ``vector``; ``config`` must be validated."""
        v = cls._LAYOUT.unpack(vector)
        f = cls.__new__(cls)
        f.config = config
        f._setup()
        f._estimate = (vector_to_pose(v["X_CE"]), vector_to_pose(v["X_BT"]))
        f._P = v["P"].reshape(12, 12).copy()
        f._target_known = bool(v["target_known"][0])
        f._R_BE_ref = None if np.isnan(v["R_BE_ref"][0]) else v["R_BE_ref"].reshape(3, 3).copy()
        f._set_counters(v["counters"])
        return f

"""On-line hand-eye estimators that respect SO(3) (beyond PAPER §9's open points).

Both are error-state (multiplicative) extended Kalman filters: the estimate is kept as an exact
rigid transform, the filter state is a small perturbation δ = [δθ; δt] with
R = exp(δθ) R̂, t = t̂ + δt, and the covariance lives in that 6-D tangent space.

- ``ManifoldHandEyeFilter``: the paper's measurement, one motion pair (A, B) at a time, with the
  sensor's noise on SO(3) ("so3": rotation-vector noise on R_A) or the paper's coefficient noise
  ("paper", mapped to its rotation-vector equivalent), iterated where the update is large, with an
  innovation (NIS) gate against outliers.
- ``HandEyeTargetFilter``: the same idea on raw synchronized poses, AX = ZB: it estimates X_CE
  and the fixed target pose in the robot base X_BT jointly from each (X_BE, X_CT) sample. Each
  measurement then enters once, with white noise; differencing poses into motions (A, B) instead
  makes consecutive motions share noise and throws away the fact that the target does not move.

Frames: X_CE is the paper's X (E in C); X_EC = inv(X_CE); X_BE end-effector in robot base; X_CT
target in camera; X_BT target in robot base.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from scipy.stats import chi2

from .orthonormalize import orthonormalize_unchecked
from .se3 import inverse, make_transform, rotation_exp, rotation_log, skew
from .validation import as_transform, check_covariance, check_positive

NOISE_MODELS = ("so3", "paper")


def _project(R):
    """Nearest rotation of a measured (possibly non-orthonormal) rotation block."""
    return orthonormalize_unchecked(np.asarray(R, dtype=float), "svd")


def rotation_noise_variance(noise_model: str, rotation_sigma: float) -> float:
    """Variance of each rotation-vector component of the measured rotation's error.

    "so3": the sensor perturbs the rotation vector: σ². "paper": i.i.d. N(0, σ²) on the 9
    coefficients of R; after projection onto SO(3) only the skew part of Δ Rᵀ survives, whose
    axial vector has variance σ²/2 per component.
    """
    if noise_model == "so3":
        return rotation_sigma**2
    if noise_model == "paper":
        return 0.5 * rotation_sigma**2
    raise ValueError(f"noise_model: expected one of {NOISE_MODELS}, got {noise_model!r}")


def _robust_inverse(S):
    try:
        return scipy.linalg.cho_solve(scipy.linalg.cho_factor(S, check_finite=False),
                                      np.eye(len(S)), check_finite=False)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(S, rcond=1e-12, hermitian=True)


def _std_deg_and_length(P6):
    d = np.sqrt(np.maximum(np.diag(P6), 0.0))
    return np.degrees(d[:3]), d[3:6]


def inverse_tangent_jacobian(X_CE) -> np.ndarray:
    """6×6 J with δ_EC ≈ J δ_CE for X_EC = inv(X_CE), both perturbations of the form
    R = exp(δθ) R̂, t = t̂ + δt: δθ_EC = −Rᵀ δθ, δt_EC = −Rᵀ [t]× δθ − Rᵀ δt."""
    R, t = X_CE[:3, :3], X_CE[:3, 3]
    J = np.zeros((6, 6))
    J[:3, :3] = -R.T
    J[3:, :3] = -R.T @ skew(t)
    J[3:, 3:] = -R.T
    return J


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
        gate: NIS threshold; above it the measurement is rejected.
        iterations: Gauss–Newton iterations (1 = plain EKF); δ is always measured from the prior.

    Returns:
        (estimate, P, accepted, nis): unchanged estimate and P when rejected.
    """
    z, H = residual(estimate, measurement)
    S_inv = _robust_inverse(H @ P @ H.T + Rn)
    nis = float(z @ S_inv @ z)
    if not np.isfinite(nis) or nis > gate:
        return estimate, P, False, nis
    est, delta = estimate, np.zeros(len(P))
    for i in range(iterations):
        K = P @ H.T @ S_inv
        delta_new = K @ (z + H @ delta)
        step = float(np.linalg.norm(delta_new - delta))
        delta = delta_new
        est = retract(estimate, delta)
        if i + 1 == iterations or step < 1e-9:
            break
        z, H = residual(est, measurement)
        S_inv = _robust_inverse(H @ P @ H.T + Rn)
    K = P @ H.T @ S_inv
    I_KH = np.eye(len(P)) - K @ H
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


def gated_error_state_update(estimate, P, measurement, residual, retract, Rn, gate,
                             iterations: int, consecutive_rejections: int,
                             max_consecutive_rejections: int | None):
    """``error_state_update`` with the NIS gate's lock-out recovery, as a pure function.

    When this measurement would be the ``max_consecutive_rejections``-th rejection in a row, so
    many rejections are far more likely a covariance that is too small (bad start, inconsistent
    P0) than outliers; without recovery the estimate would freeze and every later measurement be
    discarded. P is then inflated just enough for this innovation to look typical (χ² median);
    a measurement that no state error explains stays rejected.

    Returns (estimate, P, accepted, nis, inflated).
    """
    est, P_new, accepted, nis = error_state_update(estimate, P, measurement, residual, retract,
                                                   Rn, gate, iterations)
    if (accepted or max_consecutive_rejections is None or not np.isfinite(nis)
            or consecutive_rejections + 1 < max_consecutive_rejections):
        return est, P_new, accepted, nis, False
    z, H = residual(estimate, measurement)
    s = covariance_inflation(z, H, P, Rn, float(chi2.ppf(0.5, len(z))))
    if s is None:
        return est, P_new, False, nis, False
    est, P_new, accepted, _ = error_state_update(estimate, s * P, measurement, residual,
                                                 retract, Rn, np.inf, iterations)
    return est, P_new, accepted, nis, accepted


def motion_residual(X_CE, measurement):
    """(z, H) of one motion pair for ``error_state_update``; measurement = (R_A (projected on
    SO(3)), t_A, R_B, t_B); error state [δθ; δt] of X_CE."""
    R_Am, t_Am, R_B, t_B = measurement
    R, t = X_CE[:3, :3], X_CE[:3, 3]
    R_A = R @ R_B @ R.T
    t_A = R @ t_B + t - R_A @ t
    z = np.concatenate([rotation_log(R_Am @ R_A.T), t_Am - t_A])
    I = np.eye(3)
    H = np.zeros((6, 6))
    H[:3, :3] = I - R_A
    H[3:, :3] = -skew(R @ t_B) + skew(R_A @ t) @ (I - R_A)
    H[3:, 3:] = I - R_A
    return z, H


def retract_pose(X, delta):
    """X ⊕ δ: R ← exp(δθ) R, t ← t + δt."""
    return make_transform(rotation_exp(delta[:3]) @ X[:3, :3], X[:3, 3] + delta[3:6])


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
    z = np.concatenate([rotation_log(R_CTm @ R_CT.T), t_CTm - t_CT])
    H = np.zeros((6, 12))
    H[:3, :3] = np.eye(3)
    H[:3, 6:9] = R_CE @ R_EB
    H[3:, :3] = -skew(R_CE @ u)
    H[3:, 3:6] = np.eye(3)
    H[3:, 9:12] = R_CE @ R_EB
    return z, H


def retract_pose_pair(estimate, delta):
    X_CE, X_BT = estimate
    return retract_pose(X_CE, delta[:6]), retract_pose(X_BT, delta[6:12])


def measurement_noise_covariance(noise_model: str, rotation_sigma: float,
                                 translation_sigma: float) -> np.ndarray:
    """6×6 covariance of [rotation-vector error; translation error] of a measured pose/motion."""
    return np.diag([rotation_noise_variance(noise_model, rotation_sigma)] * 3
                   + [translation_sigma**2] * 3)


class _ErrorStateFilter:
    """Shared machinery: gate, iterated update, covariance bookkeeping."""

    _dim = 6

    def __init__(self, P0, process_cov, rotation_sigma, translation_sigma, noise_model,
                 gate_probability, iterations, max_consecutive_rejections=5,
                 orthonormalization="svd"):
        if orthonormalization not in ("svd", "qr", "horn"):
            raise ValueError("orthonormalization: expected one of ('svd', 'qr', 'horn'), got "
                             f"{orthonormalization!r}")
        self._orthonormalization = orthonormalization
        if noise_model not in NOISE_MODELS:
            raise ValueError(f"noise_model: expected one of {NOISE_MODELS}, got {noise_model!r}")
        self._noise_model = noise_model
        self._rotation_sigma = check_positive(rotation_sigma, "rotation_sigma")
        self._translation_sigma = check_positive(translation_sigma, "translation_sigma")
        self._Rn = measurement_noise_covariance(noise_model, self._rotation_sigma,
                                                self._translation_sigma)
        n = self._dim
        self._P = check_covariance(np.eye(n) if P0 is None else P0, "P0", n)
        self._G1 = check_covariance(0.0 if process_cov is None else process_cov, "process_cov", n)
        if gate_probability is None:
            self._gate = np.inf
        else:
            p = float(gate_probability)
            if not 0.0 < p < 1.0:
                raise ValueError(f"gate_probability: must be in (0, 1) or None, got "
                                 f"{gate_probability!r}")
            self._gate = float(chi2.ppf(p, 6))
        it = int(iterations)
        if it != iterations or it < 1:
            raise ValueError(f"iterations: needs an integer ≥ 1, got {iterations!r}")
        self._iterations = it
        if max_consecutive_rejections is None:
            self._max_consecutive = None
        else:
            k = int(max_consecutive_rejections)
            if k != max_consecutive_rejections or k < 1:
                raise ValueError("max_consecutive_rejections: needs an integer ≥ 1 or None, got "
                                 f"{max_consecutive_rejections!r}")
            self._max_consecutive = k
        self._num_updates = 0
        self._num_rejected = 0
        self._consecutive_rejections = 0
        self._num_inflations = 0
        self._last_nis = float("nan")
        self._last_rejected = False

    # Subclasses provide: _residual(estimate, meas) -> (z (6), H (6×n)), _retract(estimate, δ).
    def _update(self, meas) -> bool:
        est, P, accepted, nis, inflated = gated_error_state_update(
            self._estimate, self._P + self._G1, meas, self._residual, self._retract, self._Rn,
            self._gate, self._iterations, self._consecutive_rejections, self._max_consecutive)
        self._last_nis = nis
        self._last_rejected = not accepted
        if not accepted:
            self._P = P
            self._num_rejected += 1
            self._consecutive_rejections += 1
            return False
        if not (all(np.all(np.isfinite(v)) for v in self._finite_parts(est))
                and np.all(np.isfinite(P))):
            raise ValueError("the update produced a non-finite estimate; state left unchanged")
        self._estimate, self._P = est, P
        self._num_updates += 1
        self._consecutive_rejections = 0
        self._num_inflations += int(inflated)
        return True

    @property
    def covariance(self) -> np.ndarray:
        """Covariance of the error state (see the class docstring for its layout)."""
        return self._P.copy()

    @property
    def num_updates(self) -> int:
        return self._num_updates

    @property
    def num_rejected(self) -> int:
        """Measurements rejected by the NIS gate so far."""
        return self._num_rejected

    @property
    def last_nis(self) -> float:
        """Normalized innovation squared of the last measurement (χ² with 6 dof if consistent)."""
        return self._last_nis

    @property
    def last_rejected(self) -> bool:
        return self._last_rejected

    @property
    def num_inflations(self) -> int:
        """Gate lock-outs recovered from by inflating the covariance (see
        ``max_consecutive_rejections``)."""
        return self._num_inflations


    # The hand-eye part, common to both filters: its error state is the first 6 of the state.
    def _hand_eye(self) -> np.ndarray:
        raise NotImplementedError

    @property
    def X_CE(self) -> np.ndarray:
        """Estimate of X_CE, the paper's X (an exact rigid transform)."""
        return self._hand_eye().copy()

    @property
    def X_EC(self) -> np.ndarray:
        """Estimate of X_EC = inv(X_CE), the camera on the hand."""
        return inverse(self._hand_eye())

    @property
    def state(self) -> np.ndarray:
        """[vec_row(R_X); t_X] of X_CE, the layout of ``HandEyeKalmanFilter.state``."""
        X = self._hand_eye()
        return np.concatenate([X[:3, :3].reshape(9), X[:3, 3]])

    @property
    def X_CE_covariance(self) -> np.ndarray:
        """6×6 covariance of X_CE's error [δθ (rad, about C's axes); δt]."""
        return self._P[:6, :6].copy()

    @property
    def rotation_std_deg(self) -> np.ndarray:
        """Standard deviations of the rotation error of X_CE about C's axes (deg)."""
        return _std_deg_and_length(self._P[:6, :6])[0]

    @property
    def translation_std(self) -> np.ndarray:
        """Standard deviations of t_CE's coordinates (length units, in C)."""
        return _std_deg_and_length(self._P[:6, :6])[1]

    @property
    def X_EC_covariance(self) -> np.ndarray:
        """6×6 covariance of X_EC's error [δθ (rad, about E's axes); δt]."""
        J = inverse_tangent_jacobian(self._hand_eye())
        return J @ self._P[:6, :6] @ J.T

    @property
    def X_EC_rotation_std_deg(self) -> np.ndarray:
        """Standard deviations of the rotation error of X_EC about E's axes (deg)."""
        return _std_deg_and_length(self.X_EC_covariance)[0]

    @property
    def X_EC_translation_std(self) -> np.ndarray:
        """Standard deviations of t_EC's coordinates (length units, in E)."""
        return _std_deg_and_length(self.X_EC_covariance)[1]


class ManifoldHandEyeFilter(_ErrorStateFilter):
    """Error-state EKF on SE(3) for AX = XB, one motion pair at a time.

    Same interface as ``HandEyeKalmanFilter``: ``update(A, B)`` with A = X_{C(k−1)C(k)} (camera
    motion, may be non-orthonormal under the paper's noise; it is projected onto SO(3)), B =
    X_{E(k−1)E(k)} (robot motion, rigid); properties ``X_CE``, ``X_EC``, ``covariance``, ``state``.

    Measurement model: R_A = exp(n_r) R_X R_B R_Xᵀ, t_A = R_X t_B + t_X − R_A t_X + n_t, with
    n_r ~ N(0, σ_r'² I3) (σ_r' from ``rotation_noise_variance``) and n_t ~ N(0, σ_t² I3).

    Args:
        X_CE_init: initial estimate (4×4 rigid or RigidTransform).
        P0: 6×6 covariance of the initial error [δθ (rad); δt (length)] (6-diagonal or scalar
            accepted); default I6.
        process_cov: 6×6 process noise added before each update; default 0 (X constant).
        rotation_sigma: rotation noise of the measured A: rad (rotation vector) for "so3", the
            coefficient std for "paper".
        translation_sigma: std of each coordinate of the measured t_A.
        noise_model: "so3" or "paper".
        orthonormalization: accepted for interface parity with ``HandEyeKalmanFilter``; the
            estimate is always an exact rotation, so it is only used to project measured R_A.
        gate_probability: NIS gate: a pair whose normalized innovation exceeds the χ²(6)
            quantile of this probability is rejected (counted in ``num_rejected``); None disables.
        iterations: maximum Gauss–Newton iterations of the iterated EKF (1 = plain EKF).
        max_consecutive_rejections: after this many gate rejections in a row the filter takes
            its covariance, not the measurements, to be wrong (a gate lock-out, e.g. after a bad
            start): it inflates P until the current innovation is typical and accepts it
            (counted in ``num_inflations``); a measurement that no state error explains stays
            rejected. None disables (a lock-out then freezes the estimate for good).
    """

    def __init__(self, X_CE_init, P0=None, process_cov=None, rotation_sigma: float = 0.1,
                 translation_sigma: float = 0.1, noise_model: str = "so3",
                 orthonormalization: str = "svd", gate_probability: float | None = 0.999,
                 iterations: int = 3, max_consecutive_rejections: int | None = 5):
        self._estimate = as_transform(X_CE_init, "X_CE_init")
        super().__init__(P0, process_cov, rotation_sigma, translation_sigma, noise_model,
                         gate_probability, iterations, max_consecutive_rejections,
                         orthonormalization)

    _residual = staticmethod(motion_residual)
    _retract = staticmethod(retract_pose)

    @classmethod
    def from_motions(cls, A_list, B_list, rotation_sigma: float, translation_sigma: float,
                     noise_model: str = "so3", method: str = "park", **kwargs):
        """A filter started consistently from a short buffer of motion pairs (e.g. the first
        10): ``ml.robust_initial_estimate`` (outlier-screened classical solution refined to the
        ML estimate) gives both ``X_CE_init`` and ``P0``; feed the filter the motions that
        follow. This is the estimator ``handeye-drake benchmark accuracy`` measures as
        ``manifold_ml_start``. The start-up result (with its ``inliers`` mask) is kept as
        ``start_up``. Other keyword arguments go to the constructor."""
        from .ml import robust_initial_estimate
        start = robust_initial_estimate(A_list, B_list, rotation_sigma, translation_sigma,
                                        noise_model, method)
        f = cls(start.X_CE, P0=start.covariance, rotation_sigma=rotation_sigma,
                translation_sigma=translation_sigma, noise_model=noise_model, **kwargs)
        f.start_up = start
        return f

    @staticmethod
    def _finite_parts(X):
        return (X,)

    def update(self, A, B) -> bool:
        """Fuses one motion pair; returns False if the NIS gate rejected it (the estimate is then
        unchanged). Raises ValueError on bad input, leaving the state as it was."""
        A = as_transform(A, "A", rigid=False)
        B = as_transform(B, "B", rigid=True)
        if np.linalg.svd(A[:3, :3], compute_uv=False)[-1] < 1e-6:
            raise ValueError("A: rotation block is singular, not a (noisy) rotation")
        R_Am = orthonormalize_unchecked(A[:3, :3], self._orthonormalization)
        return self._update((R_Am, A[:3, 3], B[:3, :3], B[:3, 3]))

    def _hand_eye(self) -> np.ndarray:
        return self._estimate


class HandEyeTargetFilter(_ErrorStateFilter):
    """Error-state EKF for AX = ZB on synchronized poses: X_CE and the fixed target X_BT.

    ``update(X_BE, X_CT)`` fuses one synchronized sample: the robot pose (E in base, exact) and
    the measured target pose in the camera, modelled as
    X_CT = X_CE · X_BE⁻¹ · X_BT ⊕ noise (rotation-vector noise on R_CT for "so3", coefficient
    noise for "paper"; additive translation noise). The error state is
    [δθ_CE; δt_CE; δθ_BT; δt_BT] (12), so ``covariance`` is 12×12; ``X_CE_covariance`` is its
    6×6 hand-eye block.

    The target pose needs no prior: ``X_BT_init`` defaults to the one implied by the first
    sample and the initial hand-eye estimate, with ``target_prior_cov`` (default: 1 rad² and
    1 length² per axis, i.e. nearly unknown).

    The NIS gate and its lock-out recovery (``max_consecutive_rejections``) work as in
    ``ManifoldHandEyeFilter``.
    """

    _dim = 12

    def __init__(self, X_CE_init, P0=None, process_cov=None, rotation_sigma: float = 0.01,
                 translation_sigma: float = 0.001, noise_model: str = "so3",
                 orthonormalization: str = "svd", gate_probability: float | None = 0.999,
                 iterations: int = 3, X_BT_init=None, target_prior_cov=None,
                 max_consecutive_rejections: int | None = 5):
        X_CE = as_transform(X_CE_init, "X_CE_init")
        P_hand_eye = check_covariance(np.eye(6) if P0 is None else P0, "P0", 6)
        P_target = check_covariance(1.0 if target_prior_cov is None else target_prior_cov,
                                    "target_prior_cov", 6)
        G1 = check_covariance(0.0 if process_cov is None else process_cov, "process_cov", 6)
        super().__init__(scipy.linalg.block_diag(P_hand_eye, P_target), None, rotation_sigma,
                         translation_sigma, noise_model, gate_probability, iterations,
                         max_consecutive_rejections, orthonormalization)
        self._G1 = scipy.linalg.block_diag(G1, np.zeros((6, 6)))
        self._target_known = X_BT_init is not None
        X_BT = np.eye(4) if X_BT_init is None else as_transform(X_BT_init, "X_BT_init")
        self._estimate = (X_CE, X_BT)

    _residual = staticmethod(pose_residual)
    _retract = staticmethod(retract_pose_pair)

    @staticmethod
    def _finite_parts(est):
        return est

    def update(self, X_BE, X_CT) -> bool:
        """Fuses one synchronized sample; returns False if the NIS gate rejected it."""
        X_BE = as_transform(X_BE, "X_BE", rigid=True)
        X_CT = as_transform(X_CT, "X_CT", rigid=False)
        if np.linalg.svd(X_CT[:3, :3], compute_uv=False)[-1] < 1e-6:
            raise ValueError("X_CT: rotation block is singular, not a (noisy) rotation")
        R_CTm = orthonormalize_unchecked(X_CT[:3, :3], self._orthonormalization)
        if not self._target_known:
            # The target pose implied by this sample and the current hand-eye estimate.
            X_CE = self._estimate[0]
            self._estimate = (X_CE, X_BE @ inverse(X_CE) @ make_transform(R_CTm, X_CT[:3, 3]))
            self._target_known = True
        return self._update((inverse(X_BE), R_CTm, X_CT[:3, 3]))

    def _hand_eye(self) -> np.ndarray:
        return self._estimate[0]

    @property
    def X_BT(self) -> np.ndarray:
        """Estimate of the target pose in the robot base."""
        return self._estimate[1].copy()

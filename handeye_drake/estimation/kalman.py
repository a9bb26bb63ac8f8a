"""The paper's on-line hand-eye Kalman filter (PAPER §4–§6).

State x = [vec_row(R_X); t_X] ∈ R¹² for X = ``X_CE`` (end-effector in camera), modelled constant
up to process noise G1; each motion pair (A, B) gives the linear measurement y = C x + n of
``linear_system``. The rotation coefficients stay unconstrained inside the filter (keeping it a
linear, optimal filter); ``X_CE`` projects them onto SO(3) outside the loop.

The step itself is a pure function (``kalman_step``) so the Drake calibrator can keep x and P as
discrete state and call exactly the same arithmetic.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from .linear_model import linear_system_matrices, state_from_transform
from .orthonormalize import METHODS as ORTHONORMALIZATION_METHODS
from .orthonormalize import orthonormalize_unchecked
from .se3 import inverse, make_transform
from .validation import as_transform, check_covariance, check_positive

NOISE_MODELS = ("paper", "full")


def measurement_covariance(noise_model: str, rotation_sigma: float, translation_sigma: float,
                           R_X=None, t_X=None, R_B=None) -> np.ndarray:
    """Covariance G2 of the measurement noise n in y = C x + n (PAPER §5).

    The camera motion is measured as R_A = R̃_A + Δ (i.i.d. N(0, rotation_sigma²) coefficients)
    and t_A = t̃_A + v_a (N(0, translation_sigma² I3)). Then n = [vec_row(Δ R_X R_Bᵀ); Δ t_X + v_a].

    - "paper": the paper's approximation R_X ≈ I, t_X ≈ 0, R_B ≈ I: G2 = diag(σ_r² I9, σ_t² I3).
    - "full": the exact G2 at the given R_X, t_X, R_B (the filter passes its current estimate).
      With Q = R_X R_Bᵀ, V = blockdiag(Qᵀ, Qᵀ, Qᵀ), W = blockdiag(t_Xᵀ, t_Xᵀ, t_Xᵀ), Σ1 = σ_r² I9:
      G2 = [[V Σ1 Vᵀ, V Σ1 Wᵀ], [W Σ1 Vᵀ, σ_t² I3 + W Σ1 Wᵀ]].
      The translation block grows with ‖t_X‖², which the paper's approximation ignores.
    """
    sr2, st2 = rotation_sigma**2, translation_sigma**2
    G2 = np.zeros((12, 12))
    if noise_model == "paper":
        G2[:9, :9] = sr2 * np.eye(9)
        G2[9:, 9:] = st2 * np.eye(3)
        return G2
    if noise_model != "full":
        raise ValueError(f"noise_model: expected one of {NOISE_MODELS}, got {noise_model!r}")
    Q = R_X @ R_B.T
    V = np.kron(np.eye(3), Q.T)
    W = np.kron(np.eye(3), np.asarray(t_X, dtype=float)[None, :])
    G2[:9, :9] = sr2 * V @ V.T
    G2[:9, 9:] = sr2 * V @ W.T
    G2[9:, :9] = G2[:9, 9:].T
    G2[9:, 9:] = st2 * np.eye(3) + sr2 * W @ W.T
    return G2


def kalman_step(x, P, C, y, G1, G2):
    """One step of PAPER §4's recursion, returning (x_new, P_new).

    K = P Cᵀ S⁻¹ with S = C P Cᵀ + G2; x ← x + K (y − C x);
    P ← (I − K C) P (I − K C)ᵀ + K G2 Kᵀ + G1 (Joseph form: algebraically equal to the paper's
    P − K S Kᵀ + G1 for this gain, but it stays symmetric positive semi-definite in floating point).
    A singular S (zero measurement noise with an uninformative motion) is handled with a
    pseudo-inverse, which is the minimum-variance gain on the observable subspace.
    """
    S = C @ P @ C.T + G2
    S = 0.5 * (S + S.T)
    PCt = P @ C.T
    try:
        factor = scipy.linalg.cho_factor(S, check_finite=False)
        K = scipy.linalg.cho_solve(factor, PCt.T, check_finite=False).T
    except np.linalg.LinAlgError:
        K = PCt @ np.linalg.pinv(S, rcond=1e-12, hermitian=True)
    x_new = x + K @ (y - C @ x)
    I_KC = np.eye(len(x)) - K @ C
    P_new = I_KC @ P @ I_KC.T + K @ G2 @ K.T + G1
    return x_new, 0.5 * (P_new + P_new.T)


def transform_from_state(x, method: str = "svd") -> np.ndarray:
    """X_CE from the raw 12-vector state: the rotation rows projected onto SO(3)."""
    x = np.asarray(x, dtype=float)
    return make_transform(orthonormalize_unchecked(x[:9].reshape(3, 3), method), x[9:12])


class HandEyeKalmanFilter:
    """On-line estimator of the hand-eye transform from small motion pairs (PAPER §4–§6).

    Frames: ``update(A, B)`` takes the camera motion A = X_{C(k−1)C(k)} and the robot motion
    B = X_{E(k−1)E(k)} (see ``relative_motions``); the estimate is X = ``X_CE`` (pose of the
    end-effector E in the camera C, the paper's X); ``X_EC`` is its inverse (camera on the hand).

    Args:
        X_CE_init: initial estimate (4×4 rigid or RigidTransform), e.g. the two-motion solution.
        P0: initial covariance (12×12, a 12-diagonal or a scalar); the paper's default I12.
        process_cov: G1 (12×12, 12-diagonal or scalar); default 0 (X constant).
        rotation_sigma: std of the additive noise on each coefficient of the measured R_A.
        translation_sigma: std of the noise on each coordinate of the measured t_A (length units).
        noise_model: "paper" (G2 = diag(σ_r² I9, σ_t² I3), PAPER §5's approximation) or "full"
            (the estimate-dependent G2 evaluated at the current estimate and R_B).
        orthonormalization: "svd", "qr" or "horn", the projection used by ``X_CE``.
    """

    def __init__(self, X_CE_init, P0=None, process_cov=None, rotation_sigma: float = 0.1,
                 translation_sigma: float = 0.1, noise_model: str = "paper",
                 orthonormalization: str = "svd"):
        X0 = as_transform(X_CE_init, "X_CE_init", rigid=True)
        if noise_model not in NOISE_MODELS:
            raise ValueError(f"noise_model: expected one of {NOISE_MODELS}, got {noise_model!r}")
        if orthonormalization not in ORTHONORMALIZATION_METHODS:
            raise ValueError(f"orthonormalization: expected one of {ORTHONORMALIZATION_METHODS}, "
                             f"got {orthonormalization!r}")
        self._rotation_sigma = check_positive(rotation_sigma, "rotation_sigma", allow_zero=True)
        self._translation_sigma = check_positive(translation_sigma, "translation_sigma",
                                                 allow_zero=True)
        self._noise_model = noise_model
        self._orthonormalization = orthonormalization
        self._x = state_from_transform(X0)
        self._P = check_covariance(np.eye(12) if P0 is None else P0, "P0", 12)
        self._G1 = check_covariance(0.0 if process_cov is None else process_cov, "process_cov", 12)
        self._num_updates = 0

    def measurement_covariance(self, B) -> np.ndarray:
        """G2 this filter uses for a robot motion B at the current estimate."""
        B = as_transform(B, "B", rigid=True)
        X = self.X_CE
        return measurement_covariance(self._noise_model, self._rotation_sigma,
                                      self._translation_sigma, X[:3, :3], X[:3, 3], B[:3, :3])

    def update(self, A, B) -> None:
        """Fuses one motion pair: A = X_{C(k−1)C(k)} (camera, may be non-orthonormal), B =
        X_{E(k−1)E(k)} (robot, rigid). Raises ValueError on bad input, leaving the state as it was."""
        A = as_transform(A, "A", rigid=False)
        B = as_transform(B, "B", rigid=True)
        C, y = linear_system_matrices(A, B)
        G2 = self.measurement_covariance(B)
        x, P = kalman_step(self._x, self._P, C, y, self._G1, G2)
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
            raise ValueError("A, B: the update produced a non-finite state (motion magnitudes "
                             f"|t_A| = {np.linalg.norm(A[:3, 3]):.3g}, |t_B| = "
                             f"{np.linalg.norm(B[:3, 3]):.3g}); state left unchanged")
        self._x, self._P = x, P
        self._num_updates += 1

    @property
    def state(self) -> np.ndarray:
        """The raw (unconstrained) 12-vector [vec_row(R_X); t_X]."""
        return self._x.copy()

    @property
    def covariance(self) -> np.ndarray:
        """12×12 covariance of ``state``."""
        return self._P.copy()

    @property
    def X_CE(self) -> np.ndarray:
        """Estimate of X_CE (the paper's X), rotation projected onto SO(3)."""
        return transform_from_state(self._x, self._orthonormalization)

    @property
    def X_EC(self) -> np.ndarray:
        """Estimate of X_EC = inv(X_CE): the camera pose on the hand."""
        return inverse(self.X_CE)

    @property
    def num_updates(self) -> int:
        return self._num_updates

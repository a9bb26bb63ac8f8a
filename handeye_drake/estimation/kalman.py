"""The paper's on-line hand-eye Kalman filter (method description: docs/method.md §4–§6).

State x = [vec_row(R_X); t_X] ∈ R¹² for X = ``X_CE`` (end-effector in camera), modelled constant
up to process noise G1; each motion pair (A, B) gives the linear measurement y = C x + n of
``linear_system``. The rotation coefficients stay unconstrained inside the filter (keeping it a
linear, optimal filter); ``X_CE`` projects them onto SO(3) outside the loop.

The step itself is a pure function (``kalman_step``); ``HandEyeKalmanFilter`` implements
``estimator.OnlineEstimator`` around it (settings: ``configs.PaperFilter``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg.lapack import dpotrf as _potrf
from scipy.linalg.lapack import dpotrs as _potrs

from . import defaults
from .configs import PaperFilter
from .estimator import EstimatorBase, VectorLayout
from .linear_model import linear_system_matrices, state_from_transform
from .manifold import _eye, gate_threshold
from .orthonormalize import orthonormalize_unchecked
from .se3 import make_transform, pose_to_vector, rotation_log, vector_to_pose
from .validation import as_transform, check_covariance, check_noisy_rotation, check_positive

#: Values of ``PaperFilter.noise_covariance``.
NOISE_COVARIANCES = ("diagonal", "exact")

_AXIAL = np.zeros((3, 9))  # δθ ≈ L vec_row(δR) at R = I: the axial vector of the skew part
for _k, (_i, _j, _s) in enumerate(((2, 1, 1), (1, 2, -1), (0, 2, 1), (2, 0, -1), (1, 0, 1),
                                   (0, 1, -1))):
    _AXIAL[_k // 2, 3 * _i + _j] = 0.5 * _s


#: The raw rotation block may deviate from a rotation by this many of its entries' σ (plus
#: ``SHRINK_FLOOR``) before ``diagnostics`` reports the filter as biased.
SHRINK_SIGMAS = 4.0
SHRINK_FLOOR = 1e-3


def measurement_covariance(noise_covariance: str, rotation_sigma: float,
                           translation_sigma: float, R_X=None, t_X=None, R_B=None) -> np.ndarray:
    """Covariance G2 of the measurement noise n in y = C x + n (docs/method.md §5).

    The camera motion is measured as R_A = R̃_A + Δ (i.i.d. N(0, rotation_sigma²) coefficients)
    and t_A = t̃_A + v_a (N(0, translation_sigma² I3), m). Then n = [vec_row(Δ R_X R_Bᵀ);
    Δ t_X + v_a].

    - "diagonal": the paper's approximation R_X ≈ I, t_X ≈ 0, R_B ≈ I: G2 = diag(σ_r² I9,
      σ_t² I3).
    - "exact": the exact G2 at the given R_X, t_X, R_B (the filter passes its current estimate).
      With Q = R_X R_Bᵀ, V = blockdiag(Qᵀ, Qᵀ, Qᵀ), W = blockdiag(t_Xᵀ, t_Xᵀ, t_Xᵀ), Σ1 = σ_r² I9:
      G2 = [[V Σ1 Vᵀ, V Σ1 Wᵀ], [W Σ1 Vᵀ, σ_t² I3 + W Σ1 Wᵀ]].
      The translation block grows with ‖t_X‖², which the paper's approximation ignores.
    """
    sr = check_positive(rotation_sigma, "rotation_sigma", allow_zero=True)
    st = check_positive(translation_sigma, "translation_sigma", allow_zero=True)
    if noise_covariance not in NOISE_COVARIANCES:
        raise ValueError(f"noise_covariance: expected one of {NOISE_COVARIANCES}, got "
                         f"{noise_covariance!r}")
    if noise_covariance == "diagonal":
        return np.diag([sr**2] * 9 + [st**2] * 3)
    try:
        R_X, t_X, R_B = (np.asarray(v, dtype=float) for v in (R_X, t_X, R_B))
    except (TypeError, ValueError) as e:
        raise ValueError(f"R_X, t_X, R_B: the exact covariance needs numeric R_X (3×3), t_X (3) "
                         f"and R_B (3×3) ({e})") from None
    if R_X.shape != (3, 3) or t_X.shape != (3,) or R_B.shape != (3, 3):
        raise ValueError(f"R_X, t_X, R_B: the exact covariance needs R_X (3×3), t_X (3) and "
                         f"R_B (3×3), got shapes {R_X.shape}, {t_X.shape}, {R_B.shape}")
    return _exact_covariance(sr, st, R_X, t_X, R_B)


def _exact_covariance(sr, st, R_X, t_X, R_B) -> np.ndarray:
    sr2 = sr * sr
    Q = R_X @ R_B.T
    V = np.kron(np.eye(3), Q.T)
    W = np.kron(np.eye(3), t_X[None, :])
    G2 = np.empty((12, 12))
    G2[:9, :9] = sr2 * V @ V.T
    G2[:9, 9:] = sr2 * V @ W.T
    G2[9:, :9] = G2[:9, 9:].T
    G2[9:, 9:] = st * st * np.eye(3) + sr2 * W @ W.T
    return G2


def kalman_step(x, P, C, y, G1, G2):
    """One step of the paper's recursion (docs/method.md §4), returning (x_new, P_new, nis).

    K = P Cᵀ S⁻¹ with S = C P Cᵀ + G2; x ← x + K (y − C x);
    P ← (I − K C) P (I − K C)ᵀ + K G2 Kᵀ + G1 (Joseph form: algebraically equal to the paper's
    P − K S Kᵀ + G1 for this gain, but it stays symmetric positive semi-definite in floating point).
    A singular S (zero measurement noise with an uninformative motion) is handled with a
    pseudo-inverse, which is the minimum-variance gain on the observable subspace.
    ``nis`` = rᵀ S⁻¹ r of the innovation r = y − C x (χ²(12) when the filter is consistent).
    """
    S = C @ P @ C.T + G2
    S = 0.5 * (S + S.T)
    PCt = P @ C.T
    r = y - C @ x
    # LAPACK's Cholesky called directly: scipy.linalg.cho_factor / cho_solve's arithmetic
    # without their per-call checks.
    c, info = _potrf(S, lower=0, overwrite_a=0, clean=0)
    if info == 0:
        Kt, info = _potrs(c, PCt.T, lower=0, overwrite_b=0)
        s, info_r = _potrs(c, r, lower=0, overwrite_b=0)
        info = info or info_r
    if info == 0:
        K = Kt.T
        nis = float(r @ s)
    else:
        S_pinv = np.linalg.pinv(S, rcond=1e-12, hermitian=True)
        K = PCt @ S_pinv
        nis = float(r @ S_pinv @ r)
    x_new = x + K @ r
    I_KC = _eye(len(x)) - K @ C
    P_new = I_KC @ P @ I_KC.T + K @ G2 @ K.T + G1
    return x_new, 0.5 * (P_new + P_new.T), nis


def transform_from_state(x, method: str = "svd") -> np.ndarray:
    """X_CE from the raw 12-vector state: the rotation rows projected onto SO(3)."""
    x = np.asarray(x, dtype=float)
    return make_transform(orthonormalize_unchecked(x[:9].reshape(3, 3), method), x[9:12])


def tangent_covariance_of_state(x, P12) -> np.ndarray:
    """6×6 covariance of [δθ; δt] of X_CE implied by the paper filter's 12×12 covariance of
    [vec_row(R_X); t_X] (first order: δθ = axial(δR R̂ᵀ))."""
    R_hat = orthonormalize_unchecked(np.asarray(x[:9]).reshape(3, 3), "svd")
    J = np.zeros((6, 12))
    J[:3, :9] = _AXIAL @ np.kron(np.eye(3), R_hat)  # vec_row(δR R̂ᵀ) = (I3 ⊗ R̂) vec_row(δR)
    J[3:, 9:] = np.eye(3)
    return J @ P12 @ J.T


class HandEyeKalmanFilter(EstimatorBase):
    """On-line estimator of the hand-eye transform from small motion pairs (docs/method.md
    §4–§6), settings ``configs.PaperFilter``.

    ``update_motion(A, B)`` takes the camera motion A = X_{C(k−1)C(k)} (its rotation block may be
    non-orthonormal under the paper's coefficient noise) and the robot motion B = X_{E(k−1)E(k)}
    (rigid; see ``relative_motions``); ``update(X_BE, X_CT)`` forms that pair from consecutive
    samples itself. The estimate is X = ``X_CE`` (the paper's X); ``X_EC`` is its inverse.
    ``covariance`` is the 12×12 covariance of ``state`` = [vec_row(R_X); t_X];
    ``X_CE_covariance`` its first-order 6×6 image on [δθ; δt].

    ``covariance``: optional 12×12 initial covariance replacing ``config.initial_variances``.

    Measurements are refused (``update*`` returns False, state unchanged except the process
    noise) when their innovation exceeds the gate (``config.gate_probability``, off by default as
    in the paper) or the gross-error bound ``defaults.GROSS_ERROR_SIGMAS``.
    """

    _MEASUREMENT_DOF = 12
    _LAYOUT = VectorLayout(x=12, P=144, prev=24, has_prev=1, counters=EstimatorBase._COUNTERS.size)

    def __init__(self, config: PaperFilter, X_CE_init, covariance=None):
        self.config = config.validated()
        self._x = state_from_transform(as_transform(X_CE_init, "X_CE_init", rigid=True))
        self._P = (np.diag(self.config.initial_variances) if covariance is None else
                   check_covariance(covariance, "covariance", 12))
        self._setup()
        self._prev = None
        self._init_counters()

    def _setup(self) -> None:
        c = self.config
        self._G1 = np.diag(c.process_variances) if c.process_variances else np.zeros((12, 12))
        self._G2_diagonal = np.diag([c.rotation_coefficient_sigma**2] * 9
                                    + [c.translation_sigma**2] * 3)
        self._G2_diagonal.flags.writeable = False
        self._gate = min(gate_threshold(c.gate_probability, 12),
                         12 * defaults.GROSS_ERROR_SIGMAS**2)
        self._min_rotation = math.radians(c.min_rotation_deg)
        self._excitation_sigma = max(c.rotation_coefficient_sigma, 1e-12)

    def measurement_covariance(self, B) -> np.ndarray:
        """G2 this filter uses for a robot motion B at the current estimate."""
        B = as_transform(B, "B", rigid=True)
        return self._G2(B[:3, :3]).copy()

    def _G2(self, R_B) -> np.ndarray:
        c = self.config
        if c.noise_covariance == "diagonal":
            return self._G2_diagonal
        X = self._X_CE_hat()
        return _exact_covariance(c.rotation_coefficient_sigma, c.translation_sigma, X[:3, :3],
                                 X[:3, 3], R_B)

    # ------------------------------------------------------------------------------- updates
    def update_motion(self, A, B) -> bool:
        """Fuses one motion pair; False when it is refused (see the class docstring). Raises
        ValueError on bad input, leaving the state as it was."""
        A = as_transform(A, "A", rigid=False)
        B = as_transform(B, "B", rigid=True)
        check_noisy_rotation(A, "A")
        return self._update_motion(A, B)

    def _update_motion(self, A, B) -> bool:
        C, y = linear_system_matrices(A, B)
        x, P, nis = kalman_step(self._x, self._P, C, y, self._G1, self._G2(B[:3, :3]))
        self._last_nis = nis
        if not nis <= self._gate:
            self._P = self._P + self._G1
            self._num_rejected += 1
            self._consecutive += 1
            return False
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
            raise ValueError("A, B: the update produced a non-finite state (motion magnitudes "
                             f"|t_A| = {np.linalg.norm(A[:3, 3]):.3g}, |t_B| = "
                             f"{np.linalg.norm(B[:3, 3]):.3g}); state left unchanged")
        self._x, self._P = x, P
        self._num_updates += 1
        self._consecutive = 0
        self._record_nis(nis)
        self._excitation.add(rotation_log(B[:3, :3]))
        return True

    def update(self, X_BE, X_CT, X_CT_covariance=None) -> bool:
        """Forms the motion pair since the previous usable sample and fuses it (the first
        sample, and samples within ``min_rotation_deg`` of the previous one, are skipped)."""
        X_BE = as_transform(X_BE, "X_BE", rigid=True)
        X_CT = as_transform(X_CT, "X_CT", rigid=False)
        check_noisy_rotation(X_CT, "X_CT")
        return self._update(X_BE, X_CT)

    def _update(self, X_BE, X_CT) -> bool:
        motion = self._motion_since_previous(X_BE, X_CT)
        if motion is None:
            return False
        fused = self._update_motion(*motion)
        self._prev = (X_BE, X_CT)
        return fused

    # ------------------------------------------------------------------------------ estimate
    def _X_CE_hat(self) -> np.ndarray:
        return transform_from_state(self._x, self.config.orthonormalization)

    @property
    def state(self) -> np.ndarray:
        """The raw (unconstrained) 12-vector [vec_row(R_X); t_X]."""
        return self._x.copy()

    @property
    def covariance(self) -> np.ndarray:
        """12×12 covariance of ``state``."""
        return self._P.copy()

    @property
    def X_CE_covariance(self) -> np.ndarray:
        return tangent_covariance_of_state(self._x, self._P)

    def rotation_block_singular_values(self) -> np.ndarray:
        """Singular values of the raw 3×3 rotation block (all 1 for a rotation)."""
        return np.linalg.svd(self._x[:9].reshape(3, 3), compute_uv=False)

    def diagnostics(self) -> list[str]:
        """``EstimatorBase.diagnostics``, and the bias of the linear model: the measured motions
        carry noise inside the measurement matrix (errors in variables), which pulls the raw
        rotation block towards zero — most with many small motions and a broad initial
        covariance. Its translation is then biased by about (1 − s) times the target distance
        while the covariance stays small, so a block that has shrunk beyond its own σ is
        reported here."""
        out = super().diagnostics()
        s = self.rotation_block_singular_values()
        deviation = float(np.max(np.abs(1.0 - s)))
        allowed = SHRINK_SIGMAS * math.sqrt(float(np.max(np.diag(self._P)[:9]))) + SHRINK_FLOOR
        if deviation > allowed:
            out.append(f"the filter's rotation block is {deviation:.3g} away from a rotation "
                       f"(singular values {', '.join(f'{v:.4g}' for v in s)}; its σ allows "
                       f"{allowed:.2g}): the linear filter is biased by the noise of the motions "
                       "(errors in variables) and its σ are too small — use fewer, larger "
                       "motions or a smaller initial covariance, or the ManifoldFilter")
        return out

    # -------------------------------------------------------------------------------- vector
    def to_vector(self) -> np.ndarray:
        prev = (np.zeros(24) if self._prev is None else
                np.concatenate([pose_to_vector(self._prev[0]), pose_to_vector(self._prev[1])]))
        return self._LAYOUT.pack(x=self._x, P=self._P, prev=prev,
                                 has_prev=float(self._prev is not None),
                                 counters=self._counters_vector())

    @classmethod
    def from_vector(cls, config: PaperFilter, vector):
        """The filter whose ``to_vector()`` is ``vector``; ``config`` must be validated."""
        v = cls._LAYOUT.unpack(vector)
        f = cls.__new__(cls)
        f.config = config
        f._setup()
        f._x = v["x"].copy()
        f._P = v["P"].reshape(12, 12).copy()
        f._prev = ((vector_to_pose(v["prev"][:12]), vector_to_pose(v["prev"][12:]))
                   if v["has_prev"][0] else None)
        f._set_counters(v["counters"])
        return f

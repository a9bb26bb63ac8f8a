"""Maximum-likelihood batch reference for the hand-eye transform (beyond docs/method.md §9).

Given every measurement at once, the best any estimator can do under a known sensor noise model
is the maximum-likelihood (ML) estimate: the minimizer of the sum of squared residuals *whitened
by the noise the data was generated with*. It is the reference the on-line filters and the
classical closed-form methods are measured against:

- it is the ML estimate under the model the data is generated with — asymptotically unbiased and
  efficient, so no unbiased estimator has a smaller covariance to first order in the noise;
- its covariance (JᵀJ)⁻¹, J the Jacobian of the whitened residuals, evaluated at the truth on
  noise-free measurements, is the Fisher information's inverse, i.e. the Cramér–Rao bound
  (``cramer_rao_bound``); at the estimate it is the usual Gauss–Newton covariance.

Two forms:

- ``refine_ml``: motion pairs (A_k, B_k) with A_k X = X B_k (docs/method.md §2), unknown X = X_CE. The
  noise is on the measured camera motion A (the paper's simulations):

  * ``"so3"``: R_A = exp(n_r) R̃_A with n_r ~ N(0, σ_r² I3) (rad), t_A = t̃_A + n_t. Residual
    [log(R_A R̂_Aᵀ)/σ_r; (t_A − t̂_A)/σ_t]. (Exact ML up to the Jacobian of the exponential map
    in the density of R_A, a factor 1 + O(σ_r²).)
  * ``"paper"``: R_A = R̃_A + Δ, Δ's 9 coefficients i.i.d. N(0, σ_r²), t_A = t̃_A + n_t
    (docs/method.md §5). Residual [vec_row(R_A − R̂_A)/σ_r; (t_A − t̂_A)/σ_t] on the raw, non-orthonormal
    measured R_A — the exact Gaussian ML residual of that model.

  with the prediction R̂_A = R_X R_B R_Xᵀ, t̂_A = R_X t_B + t_X − R̂_A t_X (exact given X and B).
  Motions are treated as independent: true when the noise is on the motions (the paper's model);
  when motions are differenced from noisy poses, consecutive motions share noise and the pose
  form below is the exact one.

- ``refine_ml_poses``: synchronized raw poses (X_BE_k, X_CT_k), AX = ZB:
  X_CT = X_CE · X_BE⁻¹ · X_BT, unknowns X_CE and the fixed target pose X_BT (12 parameters).
  The noise is on each measured pose (``apply_pose_noise``'s models): each measurement enters
  once with white noise. This is the ML reference for the closed-loop data. Under "so3" the
  noise may be anisotropic: per-axis standard deviations about / along the camera frame C's
  axes (a diagonal 6×6 covariance Σ_C; a camera's PnP pose is typically several times worse in
  depth than laterally), or one full 6×6 covariance per sample (a detector's); the residual of
  sample k is then whitened by the Cholesky factor of its covariance, L_k⁻¹ r_k.

Parametrization (the convention of ``manifold``): X = (exp(δθ) R̂, t̂ + δt), error state
[δθ (rad); δt (length)], so ``covariance`` is directly comparable with
``ManifoldHandEyeFilter.covariance``. The nonlinear least squares is solved with
``scipy.optimize.least_squares`` (Levenberg–Marquardt, analytic Jacobians) in that chart around
the initial estimate, then re-centred and polished until the step vanishes.

Frames: X_CE is the paper's X (end-effector E in camera C); X_EC = inv(X_CE) (camera on the
hand); X_BE end-effector in robot base; X_CT target in camera; X_BT target in robot base.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from .se3 import inverse, inverse_tangent_jacobian, make_transform, rotation_exp
from .solvers import METHODS, MIN_ROTATION_ANGLE, solve_ax_xb
from .validation import (as_matrix, as_transform, as_transform_list, check_positive,
                         check_same_length)

NOISE_MODELS = ("so3", "paper")


def rotation_noise_variance(noise_model: str, rotation_sigma: float) -> float:
    """Variance of each rotation-vector component of a measured rotation's error.

    "so3": the sensor perturbs the rotation vector: σ². "paper": i.i.d. N(0, σ²) on the 9
    coefficients of R; after projection onto SO(3) only the skew part of Δ Rᵀ survives, whose
    axial vector has variance σ²/2 per component.
    """
    if noise_model == "so3":
        return rotation_sigma**2
    if noise_model == "paper":
        return 0.5 * rotation_sigma**2
    raise ValueError(f"noise_model: expected one of {NOISE_MODELS}, got {noise_model!r}")

#: Smallest eigenvalue of JᵀJ, relative to the largest, for X to count as determined.
_MIN_RELATIVE_INFORMATION = 1e-13


@dataclass
class MLResult:
    """Result of ``refine_ml`` / ``refine_ml_poses``.

    Attributes:
        X_CE: ML estimate of the paper's X (E in C), 4×4 rigid.
        X_EC: inv(X_CE), the camera pose on the hand.
        covariance: 6×6 covariance (JᵀJ)⁻¹ of the X_CE error state [δθ (rad); δt] with
            R = exp(δθ) R̂, t = t̂ + δt (``manifold``'s convention); for the pose form, the X_CE
            block of ``full_covariance`` (X_BT marginalized).
        X_EC_covariance: the same uncertainty for X_EC, through
            ``se3.inverse_tangent_jacobian``.
        X_EC_rotation_std_deg: standard deviations of X_EC's rotation error about E's axes (deg).
        X_EC_translation_std: standard deviations of t_EC's coordinates (length units, in E).
        cost: Σ r² of the whitened residuals at the estimate (χ² with m − n degrees of freedom
            under the noise model: a check of the assumed sigmas).
        num_iterations: Jacobian evaluations of the least-squares solver (all polish rounds).
        residuals: (K, 2) per motion (per sample for the pose form): [angle between the measured
            (projected) and predicted rotation (deg), ‖measured − predicted translation‖].
        X_BT: pose form only, the ML estimate of the target pose in the robot base.
        full_covariance: pose form only, the 12×12 covariance of
            [δθ_CE; δt_CE; δθ_BT; δt_BT]; motion form: equal to ``covariance``.
        inliers: ``robust_initial_estimate`` only, a boolean mask over the input motions of
            those kept in the final fit.
    """
    X_CE: np.ndarray
    X_EC: np.ndarray
    covariance: np.ndarray
    X_EC_covariance: np.ndarray
    X_EC_rotation_std_deg: np.ndarray
    X_EC_translation_std: np.ndarray
    cost: float
    num_iterations: int
    residuals: np.ndarray
    X_BT: np.ndarray | None = None
    full_covariance: np.ndarray | None = None
    inliers: np.ndarray | None = None


# ---------------------------------------------------------------------------------------------
# SO(3) Jacobians, vectorized over a stack of rotation vectors (K, 3).

def _skew_stack(w: np.ndarray) -> np.ndarray:
    S = np.zeros(w.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -w[..., 2], w[..., 1]
    S[..., 1, 0], S[..., 1, 2] = w[..., 2], -w[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -w[..., 1], w[..., 0]
    return S


def left_jacobian(phi) -> np.ndarray:
    """J_l(φ) with exp(φ + h) ≈ exp(J_l(φ) h) exp(φ):
    I + (1 − cos θ)/θ² [φ]× + (θ − sin θ)/θ³ [φ]×²."""
    phi = np.asarray(phi, dtype=float)
    th = float(np.linalg.norm(phi))
    S = _skew_stack(phi)
    if th < 1e-6:
        return np.eye(3) + 0.5 * S + S @ S / 6.0
    return (np.eye(3) + (1.0 - np.cos(th)) / th**2 * S
            + (th - np.sin(th)) / th**3 * S @ S)


def _right_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    """J_r⁻¹(φ) (K, 3, 3) with log(exp(φ) exp(h)) ≈ φ + J_r⁻¹(φ) h:
    I + ½ [φ]× + (1/θ² − (1 + cos θ)/(2 θ sin θ)) [φ]×²."""
    th = np.linalg.norm(phi, axis=-1)
    S = _skew_stack(phi)
    small = th < 1e-4
    th_safe = np.where(small, 1.0, th)
    c = np.where(small, 1.0 / 12.0 + th**2 / 720.0,
                 1.0 / th_safe**2 - (1.0 + np.cos(th_safe)) / (2.0 * th_safe * np.sin(th_safe)))
    return np.eye(3) + 0.5 * S + c[..., None, None] * (S @ S)


def _rotvecs(R: np.ndarray) -> np.ndarray:
    return Rotation.from_matrix(R).as_rotvec()


def _project_stack(M: np.ndarray) -> np.ndarray:
    """Nearest rotations (SVD) of a (K, 3, 3) stack."""
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    U = U.copy()
    U[:, :, 2] *= d[:, None]
    return U @ Vt


def _E_times(R: np.ndarray) -> np.ndarray:
    """(K, 9, 3): column i = vec_row(skew(e_i) R_k), i.e. ∂ vec_row(exp(ε) R)/∂ε at ε = 0."""
    D = np.zeros((len(R), 9, 3))
    for i in range(3):
        e = np.zeros(3)
        e[i] = 1.0
        D[:, :, i] = (_skew_stack(e)[None] @ R).reshape(len(R), 9)
    return D


# ---------------------------------------------------------------------------------------------
# Whitened residuals and their Jacobians (w.r.t. a left perturbation at the evaluation point).

def _motion_terms(X_CE, data, noise_model, sr, st):
    """(r (K·m), H (K·m × 6)) of the motion form at X_CE, H = ∂r/∂[δθ; δt] (left perturbation
    of X_CE at X_CE). data = (R_Am, R_Am_projected, t_Am, R_B, t_B) stacks."""
    R_Am, R_Ap, t_Am, R_B, t_B = data
    K = len(R_B)
    R, t = X_CE[:3, :3], X_CE[:3, 3]
    R_A = R[None] @ R_B @ R.T[None]
    t_A = t_B @ R.T + t[None] - R_A @ t
    I = np.eye(3)[None]
    I_RA = I - R_A
    # ∂(left perturbation ε of R̂_A)/∂δθ = I − R̂_A;  ∂t̂_A/∂[δθ; δt].
    dt_dth = -_skew_stack(t_B @ R.T) + _skew_stack(R_A @ t) @ I_RA
    r_t = (t_Am - t_A) / st
    H_t = -np.concatenate([dt_dth, I_RA], axis=2) / st
    if noise_model == "so3":
        phi = _rotvecs(R_Ap @ np.transpose(R_A, (0, 2, 1)))
        r_r = phi / sr
        H_r = np.concatenate([-_right_jacobian_inverse(phi) @ I_RA, np.zeros((K, 3, 3))],
                             axis=2) / sr
    else:
        r_r = (R_Am - R_A).reshape(K, 9) / sr
        H_r = np.concatenate([-_E_times(R_A) @ I_RA, np.zeros((K, 9, 3))], axis=2) / sr
    r = np.concatenate([r_r, r_t], axis=1).reshape(-1)
    H = np.concatenate([H_r, H_t], axis=1).reshape(-1, 6)
    return r, H


def _motion_residual_summary(X_CE, data):
    R_Am, R_Ap, t_Am, R_B, t_B = data
    R, t = X_CE[:3, :3], X_CE[:3, 3]
    R_A = R[None] @ R_B @ R.T[None]
    t_A = t_B @ R.T + t[None] - R_A @ t
    ang = np.degrees(np.linalg.norm(_rotvecs(R_Ap @ np.transpose(R_A, (0, 2, 1))), axis=1))
    return np.stack([ang, np.linalg.norm(t_Am - t_A, axis=1)], axis=1)


def _pose_prediction(X_CE, X_BT, R_EB, t_EB):
    R_CE, t_CE = X_CE[:3, :3], X_CE[:3, 3]
    u = t_EB + R_EB @ X_BT[:3, 3]  # target origin in E
    R_CT = R_CE[None] @ R_EB @ X_BT[:3, :3][None]
    t_CT = u @ R_CE.T + t_CE[None]
    return R_CT, t_CT, u


def _axis_scale(s):
    """A per-axis σ (3,) as a column (3, 1) for dividing Jacobian rows; a scalar unchanged."""
    s = np.asarray(s, dtype=float)
    return s[:, None] if s.ndim else float(s)


def _pose_terms(est, data, noise_model, sr, st, W=None):
    """(r, H) of the pose form at est = (X_CE, X_BT); H w.r.t. [δθ_CE; δt_CE; δθ_BT; δt_BT].
    sr, st: scalars or per-axis (3,) σ about / along C's axes; ``W`` (K, 6, 6): per-sample
    whitening matrices (then sr, st are ignored; "so3" only)."""
    X_CE, X_BT = est
    R_CTm, R_CTp, t_CTm, R_EB, t_EB = data
    K = len(R_EB)
    if W is not None:
        sr = st = 1.0
    R_CT, t_CT, u = _pose_prediction(X_CE, X_BT, R_EB, t_EB)
    R_CE_EB = X_CE[:3, :3][None] @ R_EB
    # Left perturbation of R̂_CT: ε = δθ_CE + R_CE R_EB δθ_BT.
    deps = np.concatenate([np.broadcast_to(np.eye(3), (K, 3, 3)), np.zeros((K, 3, 3)), R_CE_EB,
                           np.zeros((K, 3, 3))], axis=2)
    dt = np.concatenate([-_skew_stack(u @ X_CE[:3, :3].T),
                         np.broadcast_to(np.eye(3), (K, 3, 3)), np.zeros((K, 3, 3)), R_CE_EB],
                        axis=2)
    r_t = (t_CTm - t_CT) / st
    H_t = -dt / _axis_scale(st)
    if noise_model == "so3":
        phi = _rotvecs(R_CTp @ np.transpose(R_CT, (0, 2, 1)))
        r_r = phi / sr
        H_r = -_right_jacobian_inverse(phi) @ deps / _axis_scale(sr)
    else:
        r_r = (R_CTm - R_CT).reshape(K, 9) / sr
        H_r = -_E_times(R_CT) @ deps / sr
    r = np.concatenate([r_r, r_t], axis=1)
    H = np.concatenate([H_r, H_t], axis=1)
    if W is not None:
        r = np.einsum("kij,kj->ki", W, r)
        H = W @ H
    return r.reshape(-1), H.reshape(-1, 12)


def _pose_residual_summary(est, data):
    X_CE, X_BT = est
    R_CTm, R_CTp, t_CTm, R_EB, t_EB = data
    R_CT, t_CT, _ = _pose_prediction(X_CE, X_BT, R_EB, t_EB)
    ang = np.degrees(np.linalg.norm(_rotvecs(R_CTp @ np.transpose(R_CT, (0, 2, 1))), axis=1))
    return np.stack([ang, np.linalg.norm(t_CTm - t_CT, axis=1)], axis=1)


# ---------------------------------------------------------------------------------------------
# The solver: LM in the chart around a centre, re-centred until the step vanishes.

def _retract(X, delta):
    return make_transform(rotation_exp(delta[:3]) @ X[:3, :3], X[:3, 3] + delta[3:6])


def _retract_all(center, delta):
    return tuple(_retract(X, delta[6 * i:6 * i + 6]) for i, X in enumerate(center))


def _chart_jacobian(delta, n_poses):
    """∂(left perturbation)/∂δ of the chart X = exp(δθ) R_c: blockdiag(J_l(δθ), I) per pose."""
    J = np.eye(6 * n_poses)
    for i in range(n_poses):
        J[6 * i:6 * i + 3, 6 * i:6 * i + 3] = left_jacobian(delta[6 * i:6 * i + 3])
    return J


def _solve(center: tuple, terms, max_rounds: int = 6):
    """Minimizes Σ r² over the poses in ``center`` (a tuple of 4×4). Returns (poses, J, r, njev)."""
    n = 6 * len(center)
    njev = 0
    for _ in range(max_rounds):
        def fun(d, c=center):
            return terms(_retract_all(c, d))[0]

        def jac(d, c=center):
            return terms(_retract_all(c, d))[1] @ _chart_jacobian(d, len(c))

        sol = least_squares(fun, np.zeros(n), jac=jac, method="lm", xtol=1e-14, ftol=1e-14,
                            gtol=1e-14, max_nfev=200 * n)
        njev += int(sol.njev or 0)
        if not np.all(np.isfinite(sol.x)):
            raise ValueError("X_CE_init: the least-squares refinement diverged (non-finite step)")
        center = _retract_all(center, sol.x)
        scale = max(1.0, max(float(np.linalg.norm(X[:3, 3])) for X in center))
        if np.linalg.norm(sol.x[:3]) < 1e-12 and np.linalg.norm(sol.x[3:]) < 1e-12 * scale:
            break
    r, H = terms(center)
    return center, H, r, njev


def _covariance(H: np.ndarray, what: str) -> np.ndarray:
    info = H.T @ H
    w = np.linalg.eigvalsh(info)
    if not np.isfinite(w).all() or w[0] <= _MIN_RELATIVE_INFORMATION * w[-1]:
        raise ValueError(
            f"{what}: the measurements do not determine the hand-eye transform (the Fisher "
            f"information JᵀJ is singular: eigenvalues {np.array2string(w, precision=3)}); "
            "typically all rotation axes are parallel or the motions are pure translations")
    cov = np.linalg.inv(info)
    return 0.5 * (cov + cov.T)


def _result(X_CE, cov6, r, njev, residuals, X_BT=None, full_cov=None) -> MLResult:
    J = inverse_tangent_jacobian(X_CE)
    cov_EC = J @ cov6 @ J.T
    d = np.sqrt(np.maximum(np.diag(cov_EC), 0.0))
    return MLResult(X_CE=X_CE, X_EC=inverse(X_CE), covariance=cov6, X_EC_covariance=cov_EC,
                    X_EC_rotation_std_deg=np.degrees(d[:3]), X_EC_translation_std=d[3:],
                    cost=float(r @ r), num_iterations=njev, residuals=residuals, X_BT=X_BT,
                    full_covariance=cov6 if full_cov is None else full_cov)


# ---------------------------------------------------------------------------------------------
# Input checks.

def _check_sigma(value, name: str, per_axis: bool):
    """A positive finite scalar, or (``per_axis``) three of them (one per axis of C)."""
    if per_axis and np.ndim(value) == 1:
        v = as_matrix(value, name, (3,))
        if not np.all(v > 0):
            raise ValueError(f"{name}: per-axis standard deviations must be > 0, got "
                             f"{np.array2string(v, precision=3)}")
        return v
    if np.ndim(value) > 0:
        raise ValueError(f"{name}: expected a positive number" + (
            " or 3 per-axis values" if per_axis else " (one σ: this form is isotropic)")
            + f", got shape {np.shape(value)}")
    return check_positive(value, name)


def _check_noise(noise_model, rotation_sigma, translation_sigma, per_axis: bool = True):
    """(σ_r, σ_t): scalars, or (per_axis) (3,) arrays about / along the camera's axes (a
    scalar means isotropic). "paper" has one coefficient σ for the rotation."""
    if noise_model not in NOISE_MODELS:
        raise ValueError(f"noise_model: expected one of {NOISE_MODELS}, got {noise_model!r}")
    sr = _check_sigma(rotation_sigma, "rotation_sigma", per_axis and noise_model == "so3")
    return sr, _check_sigma(translation_sigma, "translation_sigma", per_axis)


def pose_whitening(covariances, count: int, name: str = "covariances") -> np.ndarray:
    """Whitening matrices W_k = L_k⁻¹ (K, 6, 6), Σ_k = L_k L_kᵀ (Cholesky), of per-sample 6×6
    covariances of the camera pose error [δθ (rad, about C's axes); δt (m)]: W_k r_k is white.

    Raises:
        ValueError: ``name`` not (count, 6, 6), not finite, not symmetric or not positive
            definite (naming the first bad sample).
    """
    C = as_matrix(covariances, name, (count, 6, 6))
    asym = np.abs(C - np.transpose(C, (0, 2, 1))).max(axis=(1, 2))
    scale = np.abs(C).max(axis=(1, 2))
    bad = np.flatnonzero(asym > 1e-9 * np.maximum(scale, 1e-300))
    if len(bad):
        raise ValueError(f"{name}[{bad[0]}]: not symmetric")
    C = 0.5 * (C + np.transpose(C, (0, 2, 1)))
    W = np.empty_like(C)
    for k, Ck in enumerate(C):
        try:
            L = np.linalg.cholesky(Ck)
        except np.linalg.LinAlgError:
            raise ValueError(f"{name}[{k}]: not positive definite") from None
        W[k] = np.linalg.solve(L, np.eye(6))
    if not np.all(np.isfinite(W)):
        raise ValueError(f"{name}: a covariance is too ill-conditioned to whiten")
    return W


def _measured_rotations(X: list[np.ndarray], name: str, noise_model: str):
    """(raw, projected) rotation stacks of measured poses/motions."""
    M = np.array([x[:3, :3] for x in X])
    s = np.linalg.svd(M, compute_uv=False)
    bad = np.flatnonzero(s[:, 2] < 1e-6 * np.maximum(s[:, 0], 1e-300))
    if len(bad):
        raise ValueError(f"{name}[{bad[0]}]: rotation block is (near-)singular, not a noisy "
                         "rotation")
    P = _project_stack(M)
    return (M if noise_model == "paper" else P), P


def _motion_data(A_list, B_list, noise_model):
    # "paper": the raw measured rotation block (not orthonormal) is the measurement itself.
    A = as_transform_list(A_list, "A_list", rigid=(noise_model == "so3"))
    B = as_transform_list(B_list, "B_list", rigid=True)
    check_same_length(A, "A_list", B, "B_list")
    if len(A) < 2:
        raise ValueError(f"A_list, B_list: need at least 2 motions (with non-parallel rotation "
                         f"axes), got {len(A)}")
    R_Am, R_Ap = _measured_rotations(A, "A_list", noise_model)
    return (R_Am, R_Ap, np.array([a[:3, 3] for a in A]), np.array([b[:3, :3] for b in B]),
            np.array([b[:3, 3] for b in B]))


# ---------------------------------------------------------------------------------------------
# Public API.

def refine_ml(A_list, B_list, X_CE_init, rotation_sigma: float, translation_sigma: float,
              noise_model: str = "so3") -> MLResult:
    """Maximum-likelihood X_CE from motion pairs A_k X_CE = X_CE B_k (see the module docstring).

    It is the right reference for the estimators of this package: it is the ML estimate under
    the model the data is generated with (``noise_model`` and the sigmas must be the sensor's),
    and its covariance (JᵀJ)⁻¹ is the Cramér–Rao bound when evaluated at the truth
    (``cramer_rao_bound``): to first order no unbiased estimator can do better on the same data.

    Args:
        A_list: K ≥ 2 measured camera motions A_k = X_{C(k−1)C(k)} (4×4; under "paper" the
            rotation block is the raw, non-orthonormal measurement; under "so3" it must be a
            rotation).
        B_list: the K robot motions B_k = X_{E(k−1)E(k)} (rigid, exact).
        X_CE_init: starting point of the local refinement (e.g. a classical solution); the
            refinement converges to the local minimum of the negative log-likelihood near it.
        rotation_sigma: "so3": std of each rotation-vector component of the noise on R_A (rad);
            "paper": std of each of the 9 coefficients of R_A.
        translation_sigma: std of each coordinate of the noise on t_A (length units).
        noise_model: "so3" or "paper".

    Returns:
        ``MLResult``.

    Raises:
        ValueError: malformed / non-finite inputs (naming the argument), lists of different
            lengths, fewer than 2 motions, non-positive sigmas, unknown noise model, or motions
            that do not determine X (singular Fisher information).
    """
    sr, st = _check_noise(noise_model, rotation_sigma, translation_sigma, per_axis=False)
    data = _motion_data(A_list, B_list, noise_model)
    X0 = as_transform(X_CE_init, "X_CE_init")
    return _refine_motions(data, X0, noise_model, sr, st)


def _refine_motions(data, X0, noise_model, sr, st) -> MLResult:
    def terms(est):
        return _motion_terms(est[0], data, noise_model, sr, st)

    (X_CE,), H, r, njev = _solve((X0,), terms)
    cov = _covariance(H, "A_list, B_list")
    return _result(X_CE, cov, r, njev, _motion_residual_summary(X_CE, data))


def robust_initial_estimate(A_list, B_list, rotation_sigma: float, translation_sigma: float,
                            noise_model: str = "so3", method: str = "park",
                            gate_probability: float = 0.999, max_rounds: int = 5) -> MLResult:
    """A consistent starting point (estimate *and* covariance) for an on-line filter, from a
    short buffer of motion pairs that may contain wrong measurements.

    Seeding ``ManifoldHandEyeFilter`` with ``X_CE_init=result.X_CE, P0=result.covariance`` and
    feeding it the motions that follow makes its estimate match the batch ML of all motions
    (checked by ``handeye-drake benchmark accuracy``), where a two-motion classical start with a
    guessed P0 can leave it inconsistent: linearized far from the truth, it becomes
    overconfident and its NIS gate then rejects good measurements.

    Steps: (1) drop motions whose rotation angles disagree: AX = XB makes θ_A = θ_B, and a
    rotation-vector noise n moves the angle by at most ‖n‖, so |θ_A − θ_B| is compared with the
    χ²(3) quantile of ``gate_probability`` times the per-axis noise std (this test does not need
    X); (2) a classical closed-form solution (``solve_ax_xb(method)``) of the kept motions
    rotating at least ``solvers.MIN_ROTATION_ANGLE``; (3) ``refine_ml`` of the kept motions;
    (4) drop motions whose squared whitened residual exceeds the χ²(m) quantile (m = 6 for
    "so3", 12 for "paper"), re-admit those now below it, and refine again until the set stops
    changing (at most ``max_rounds`` rounds).

    Args:
        A_list, B_list, rotation_sigma, translation_sigma, noise_model: as ``refine_ml``.
        method: the classical solver of step 2 (``solvers.METHODS``).
        gate_probability: probability of keeping a consistent motion in each test, in (0, 1).
        max_rounds: integer ≥ 1.

    Returns:
        ``MLResult`` of the kept motions, with ``inliers`` (boolean mask over the input).

    Raises:
        ValueError: as ``refine_ml``; unknown method; bad gate_probability or max_rounds; fewer
            than 2 consistent motions; or the classical solver's errors on the kept motions
            (e.g. all rotation axes parallel).
    """
    sr, st = _check_noise(noise_model, rotation_sigma, translation_sigma, per_axis=False)
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    try:
        p = float(gate_probability)
    except (TypeError, ValueError):
        p = float("nan")
    if not 0.0 < p < 1.0:
        raise ValueError(f"gate_probability: must be in (0, 1), got {gate_probability!r}")
    if int(max_rounds) != max_rounds or max_rounds < 1:
        raise ValueError(f"max_rounds: needs an integer ≥ 1, got {max_rounds!r}")
    data = _motion_data(A_list, B_list, noise_model)
    R_Am, R_Ap, t_Am, R_B, t_B = data
    th_A = np.linalg.norm(_rotvecs(R_Ap), axis=1)
    th_B = np.linalg.norm(_rotvecs(R_B), axis=1)
    sigma_axis = np.sqrt(rotation_noise_variance(noise_model, sr))
    angle_ok = np.abs(th_A - th_B) <= np.sqrt(chi2.ppf(p, 3)) * sigma_axis
    if angle_ok.sum() < 2:
        raise ValueError(f"A_list, B_list: only {int(angle_ok.sum())} of {len(R_B)} motions have "
                         "camera and robot rotation angles that agree within the noise; need "
                         "at least 2 (wrong rotation_sigma, or wrong frame conventions?)")
    solvable = angle_ok & (np.minimum(th_A, th_B) >= MIN_ROTATION_ANGLE)
    idx = np.flatnonzero(solvable)
    X0 = solve_ax_xb([make_transform(R_Ap[i], t_Am[i]) for i in idx],
                     [make_transform(R_B[i], t_B[i]) for i in idx], method)
    m = 6 if noise_model == "so3" else 12
    threshold = chi2.ppf(p, m)
    keep = angle_ok
    result = _refine_motions(tuple(d[keep] for d in data), X0, noise_model, sr, st)
    for _ in range(int(max_rounds) - 1):
        r, _ = _motion_terms(result.X_CE, data, noise_model, sr, st)
        new_keep = angle_ok & (np.sum(r.reshape(len(R_B), m) ** 2, axis=1) <= threshold)
        if new_keep.sum() < 2 or np.array_equal(new_keep, keep):
            break
        keep = new_keep
        result = _refine_motions(tuple(d[keep] for d in data), result.X_CE, noise_model, sr, st)
    result.inliers = keep.copy()
    return result


def cramer_rao_bound(A_list, B_list, X_CE, rotation_sigma: float, translation_sigma: float,
                     noise_model: str = "so3") -> np.ndarray:
    """Cramér–Rao bound (6×6) on the X_CE error state [δθ (rad); δt] (R = exp(δθ) R̂,
    t = t̂ + δt) for the motions B_k at the true X_CE: the inverse Fisher information
    (Σ_k H_kᵀ Σ⁻¹ H_k)⁻¹ of the measurement model of ``refine_ml``.

    The Fisher information is evaluated at the noise-free measurements A_k = X_CE B_k X_CE⁻¹
    (its definition takes the expectation over the noise), so it depends on the motions B_k and
    X_CE only; ``A_list`` is validated and paired with ``B_list`` but its values are not used.

    Raises:
        ValueError: as ``refine_ml``.
    """
    sr, st = _check_noise(noise_model, rotation_sigma, translation_sigma, per_axis=False)
    data = _motion_data(A_list, B_list, noise_model)
    X = as_transform(X_CE, "X_CE")
    R_B, t_B = data[3], data[4]
    R, t = X[:3, :3], X[:3, 3]
    R_A = R[None] @ R_B @ R.T[None]
    t_A = t_B @ R.T + t[None] - R_A @ t
    exact = (R_A, R_A, t_A, R_B, t_B)
    _, H = _motion_terms(X, exact, noise_model, sr, st)
    return _covariance(H, "A_list, B_list")


def refine_ml_poses(X_BE_list, X_CT_list, X_CE_init, rotation_sigma, translation_sigma,
                    noise_model: str = "so3", X_BT_init=None, covariances=None) -> MLResult:
    """Maximum-likelihood X_CE and target pose X_BT from synchronized poses (AX = ZB).

    Model: X_CT_k = X_CE · X_BE_k⁻¹ · X_BT ⊕ noise, with ``apply_pose_noise``'s models on the
    measured target pose: "so3" (R_CT = exp(n_r) R̃_CT, n_r ~ N(0, diag(σ_r²)) rad about C's
    axes) or "paper" (additive N(0, σ_r²) on the 9 coefficients, raw measurement kept), and
    t_CT = t̃_CT + n_t, n_t ~ N(0, diag(σ_t²)) along C's axes. Robot poses are exact. This is
    the reference for closed-loop data: every camera measurement enters once with white noise
    (differencing poses into motions would correlate them).

    Args:
        X_BE_list: K ≥ 3 end-effector poses in the robot base (rigid).
        X_CT_list: the K measured target poses in the camera, same instants.
        X_CE_init: initial hand-eye estimate (4×4 rigid).
        rotation_sigma, translation_sigma: the camera pose noise (see above): a scalar
            (isotropic) or, "so3" for the rotation, 3 per-axis values (rad about C's x, y, z;
            m along them). Ignored when ``covariances`` is given (may then be None).
        noise_model: "so3" or "paper".
        X_BT_init: initial target pose; default the one implied by the first sample,
            X_BE_0 · X_CE_init⁻¹ · X_CT_0 (rotation projected on SO(3)).
        covariances: optional (K, 6, 6) covariance of each measurement's error
            [δθ (rad, about C's axes); δt (m)] ("so3" only), e.g. a detector's
            (``vision.detection``'s ``covariance``); the residuals are whitened by its Cholesky
            factor instead of the sigmas.

    Returns:
        ``MLResult`` with ``X_BT`` and the 12×12 ``full_covariance`` of
        [δθ_CE; δt_CE; δθ_BT; δt_BT]; ``covariance`` is its X_CE block.

    Raises:
        ValueError: malformed / non-finite inputs (naming the argument), lists of different
            lengths, fewer than 3 samples, non-positive sigmas, unknown noise model, bad
            covariances (shape, symmetry, positive definiteness), or poses that do not
            determine X_CE (singular Fisher information).
    """
    if covariances is None:
        sr, st = _check_noise(noise_model, rotation_sigma, translation_sigma)
    else:
        if noise_model != "so3":
            raise ValueError("covariances: per-sample covariances need noise_model 'so3'")
        sr = st = 1.0
    X_BE = as_transform_list(X_BE_list, "X_BE_list", rigid=True)
    X_CT = as_transform_list(X_CT_list, "X_CT_list", rigid=(noise_model == "so3"))
    check_same_length(X_BE, "X_BE_list", X_CT, "X_CT_list")
    if len(X_BE) < 3:
        raise ValueError(f"X_BE_list, X_CT_list: need at least 3 samples (2 motions with "
                         f"non-parallel rotation axes), got {len(X_BE)}")
    W = None if covariances is None else pose_whitening(covariances, len(X_BE))
    R_CTm, R_CTp = _measured_rotations(X_CT, "X_CT_list", noise_model)
    X_EB = [inverse(X) for X in X_BE]
    data = (R_CTm, R_CTp, np.array([x[:3, 3] for x in X_CT]), np.array([x[:3, :3] for x in X_EB]),
            np.array([x[:3, 3] for x in X_EB]))
    X0 = as_transform(X_CE_init, "X_CE_init")
    if X_BT_init is None:
        X_BT0 = X_BE[0] @ inverse(X0) @ make_transform(R_CTp[0], X_CT[0][:3, 3])
    else:
        X_BT0 = as_transform(X_BT_init, "X_BT_init")

    def terms(est):
        return _pose_terms(est, data, noise_model, sr, st, W)

    (X_CE, X_BT), H, r, njev = _solve((X0, X_BT0), terms)
    cov = _covariance(H, "X_BE_list, X_CT_list")
    return _result(X_CE, cov[:6, :6].copy(), r, njev, _pose_residual_summary((X_CE, X_BT), data),
                   X_BT=X_BT, full_cov=cov)


def pose_residual_vectors(X_EB, X_CT, X_CE, X_BT) -> np.ndarray:
    """(K, 6) per sample: [log(R_CT R̂_CTᵀ) (rad, about C's axes); t_CT − t̂_CT (m, in C)], the
    error of each measured target pose X_CT_k against the prediction X_CE · X_EB_k · X_BT in
    the left-perturbation convention of the noise model (so that the noise covariance
    estimated from them is the one ``refine_ml_poses`` takes). Inputs are (K, 4, 4) stacks
    (X_CT rigid) and 4×4 poses; no validation (internal helper of the calibration pipeline)."""
    X_EB = np.asarray(X_EB, dtype=float).reshape(-1, 4, 4)
    X_CT = np.asarray(X_CT, dtype=float).reshape(-1, 4, 4)
    R_CT, t_CT, _ = _pose_prediction(np.asarray(X_CE, float), np.asarray(X_BT, float),
                                     X_EB[:, :3, :3], X_EB[:, :3, 3])
    phi = _rotvecs(X_CT[:, :3, :3] @ np.transpose(R_CT, (0, 2, 1)))
    return np.concatenate([phi, X_CT[:, :3, 3] - t_CT], axis=1)


def pose_jacobians(X_EB, X_CE, X_BT, rotation_sigma, translation_sigma,
                   noise_model: str = "so3") -> np.ndarray:
    """Per-sample whitened Jacobians of the pose form at noise-free measurements.

    For each robot pose, the Jacobian of the whitened residual of ``refine_ml_poses`` with
    respect to [δθ_CE; δt_CE; δθ_BT; δt_BT] (left perturbations, ``manifold``'s convention),
    evaluated where the measurement equals its prediction X_CE · X_EB_k · X_BT. Σ_k H_kᵀ H_k is
    then the Fisher information of the samples (what ``estimation.observability`` analyses and
    ``estimation.planning`` maximises); it depends on the robot poses, the rotation of X_CE and
    the translations of X_CE and X_BT only.

    Eye-to-hand (camera fixed in the base, target on the flange) is the same model with
    X_EB → X_BE, X_CE → X_CB and X_BT → X_ET.

    Args:
        X_EB: (K, 4, 4) robot poses inverted (base in end-effector), rigid.
        X_CE, X_BT: the linearization point (4×4 rigid).
        rotation_sigma, translation_sigma, noise_model: as ``refine_ml_poses`` (scalars or
            per-axis).

    Returns:
        (K, m, 12) array, m = 6 ("so3") or 12 ("paper").
    """
    sr, st = _check_noise(noise_model, rotation_sigma, translation_sigma)
    X_EB = np.asarray(X_EB, dtype=float).reshape(-1, 4, 4)
    R_EB, t_EB = X_EB[:, :3, :3], X_EB[:, :3, 3]
    R_CT, t_CT, _ = _pose_prediction(X_CE, X_BT, R_EB, t_EB)
    _, H = _pose_terms((X_CE, X_BT), (R_CT, R_CT, t_CT, R_EB, t_EB), noise_model, sr, st)
    return H.reshape(len(X_EB), -1, 12)

"""Corner-level maximum likelihood: hand-eye calibration fitted to the detected target corners.

The pose-level fit (``ml.refine_ml_poses``) reduces every image to one PnP pose and fits those
poses. This module fits what the camera measured: every detected corner of every image, through
the kinematic chain and OpenCV's camera model, with the intrinsics optionally refined jointly.

Model (``mode`` of ``estimation.consistency``, robot-side poses X_R):

    X_CT,k = X_H⁻¹ · X_R,k⁻¹ · X_F           eye-in-hand: X_H = X_EC, X_R = X_BE, X_F = X_BT
                                             eye-to-hand: X_H = X_BC, X_R = X_EB, X_F = X_ET
    u_kj  = π(K, d; Exp(e_k) ⊕ X_CT,k · (s · P_j)) + n_kj,   n_kj ~ N(0, σ_px² I₂)
    e_k   ~ N(0, Σ_e),  Σ_e = diag(σ_e²) (6)

- π is ``cv2.projectPoints``'s model: x = X/Z, y = Y/Z, r² = x² + y²,
  x' = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2 x²), y' likewise, u = fx x' + cx,
  v = fy y' + cy (pixel centres as OpenCV's).
- e_k = [δθ; δt] is a per-image pose error of X_CT,k in the camera frame C (R = exp(δθ) R̂,
  t = t̂ + δt: the pose-level fit's convention): the robot's pose error at that image (its
  repeatability and the part of its absolute error that varies over the workspace), a
  target that flexes, a camera that shakes. Each image's corners share it, so without it
  the corners of one image would count as independent evidence and the σ would be far too
  small. It is marginalized analytically (Schur complement) — the cost stays linear in the
  number of images.
- σ_px and Σ_e are estimated from the data (expectation–maximization on the fit's residuals
  and the posterior of each e_k), floored at ``PIXEL_SIGMA_FLOOR`` and ``POSE_SIGMA_FLOOR``.
- The unknowns: X_H, X_F (error state [δθ; δt], R = exp(δθ) R̂, t = t̂ + δt, as the pose-level
  fit), optionally intrinsics (``INTRINSICS_MODELS``) shared by all images, optionally the
  target's scale s (a wrong declared target size).
- Robust: one Huber-weighted round, then corners beyond ``CORNER_OUTLIER_CHI2`` and images whose
  pose error is beyond ``IMAGE_OUTLIER_CHI2`` are rejected and the fit repeated on the rest.

Covariance: the inverse of the information of the global parameters after marginalizing the
e_k, so the σ of X_H include the intrinsics' uncertainty when they are refined.

Cross-validation (``cross_validate``): each image (or fold of images) is predicted by the fit of
the others (e_k = 0: what a new image would show), RMS px over its corners. It is a check and
the basis of the model choice (``select_intrinsics_model``), never a reason to leave data out of
the answer.

No Drake import: numpy and scipy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

from .ml import _skew_stack
from .se3 import inverse, rotation_exp, skew

#: Intrinsics models, simplest first: which of [fx, fy, cx, cy, k1, k2, p1, p2, k3] are free.
#: "focal" scales fx and fy together (their ratio kept).
INTRINSICS_MODELS = ("none", "focal", "pinhole", "k1k2", "full")
INTRINSICS_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
_FREE = {"none": (), "pinhole": (0, 1, 2, 3), "k1k2": (0, 1, 2, 3, 4, 5),
         "full": tuple(range(9))}
#: Floors of the estimated noise: σ_px (px) and the per-image pose error (rad, m).
PIXEL_SIGMA_FLOOR = 0.01
POSE_SIGMA_FLOOR = (1e-6, 1e-7)
#: Huber threshold of the first round (in σ_px) and the rejection bounds of the later rounds:
#: a corner whose whitened residual² is beyond the χ²(2) quantile of 1 − 1e-6, an image whose
#: whitened pose error² is beyond the χ²(6) quantile of the same probability.
HUBER_K = 3.0
CORNER_OUTLIER_CHI2 = float(chi2.ppf(1 - 1e-6, 2))
IMAGE_OUTLIER_CHI2 = float(chi2.ppf(1 - 1e-6, 6))
#: σ = MAD_SCALE · median |x| for zero-mean Gaussian x.
MAD_SCALE = 1.482602218505602
#: Over-relaxation of the per-image pose error's EM steps (in log σ; 1 = plain EM).
EM_RELAXATION = 1.8
#: σ_e pooled over the three axes of its rotation and of its translation (two levels, not six).
#: Per axis, the levels are estimated from K images less what the 12+ global parameters absorb,
#: and the pixels barely tell a rotation about x from a translation along y: on sets whose robot
#: errors repeat with the joint angles (or are few), some axes come out far too small, the fit
#: trusts those images' poses along them, and left-out images are predicted worse than by a plain
#: corner bundle (``benchmarks/loo_vs_bundle.py``). A robot's error is about as large about
#: every axis of the camera's frame: two pooled levels are estimated three times as well.
POOLED_POSE_ERROR = True
#: Smallest depth (m) a corner may have in front of the camera.
MIN_DEPTH = 1e-3


@dataclass
class CornerData:
    """The detections of K images: ``image`` (N,) index of the image of each corner (sorted),
    ``object_points`` (N, 3) in T (m), ``image_points`` (N, 2) px; ``X_R`` (K, 4, 4) the
    robot-side pose of each image (see the module docstring)."""
    X_R: np.ndarray
    image: np.ndarray
    object_points: np.ndarray
    image_points: np.ndarray

    @classmethod
    def from_lists(cls, X_R, object_points, image_points) -> "CornerData":
        """From per-image lists (K poses, K arrays of (n_k, 3) and (n_k, 2))."""
        X_R = np.asarray(X_R, dtype=float).reshape(-1, 4, 4)
        if not (len(X_R) == len(object_points) == len(image_points)):
            raise ValueError(f"corners: {len(X_R)} poses, {len(object_points)} object point sets "
                             f"and {len(image_points)} image point sets; one of each per image")
        P, U, idx = [], [], []
        for k, (p, u) in enumerate(zip(object_points, image_points)):
            p = np.asarray(p, dtype=float).reshape(-1, 3)
            u = np.asarray(u, dtype=float).reshape(-1, 2)
            if len(p) != len(u):
                raise ValueError(f"corners: image {k} has {len(p)} object points and {len(u)} "
                                 "image points")
            P.append(p)
            U.append(u)
            idx.append(np.full(len(p), k))
        data = cls(X_R, np.concatenate(idx).astype(int), np.concatenate(P), np.concatenate(U))
        if not (np.all(np.isfinite(data.X_R)) and np.all(np.isfinite(data.object_points))
                and np.all(np.isfinite(data.image_points))):
            raise ValueError("corners: poses and points must be finite")
        return data

    @property
    def num_images(self) -> int:
        return len(self.X_R)

    def subset(self, images) -> "CornerData":
        """The data of the given images (renumbered 0..len−1 in the given order, sorted)."""
        images = np.sort(np.asarray(images, dtype=int))
        remap = np.full(self.num_images, -1)
        remap[images] = np.arange(len(images))
        keep = remap[self.image] >= 0
        return CornerData(self.X_R[images], remap[self.image[keep]], self.object_points[keep],
                          self.image_points[keep])


def intrinsics_vector(K, distortion=()) -> np.ndarray:
    """[fx, fy, cx, cy, k1, k2, p1, p2, k3] from a 3×3 K (no skew) and OpenCV's distortion
    (0, 4 or 5 coefficients)."""
    K = np.asarray(K, dtype=float)
    if abs(K[0, 1]) > 1e-9 * K[0, 0]:
        raise ValueError("intrinsics: the corner-level fit takes a camera without skew "
                         f"(K[0,1] = {K[0, 1]!r})")
    d = np.zeros(5)
    dist = np.ravel(np.asarray(distortion if distortion is not None else (), dtype=float))
    if dist.size not in (0, 4, 5) and np.any(dist[5:] != 0):
        raise ValueError("intrinsics: the corner-level fit takes OpenCV's k1, k2, p1, p2, k3 "
                         f"model; the rational or thin-prism terms given ({dist.size} "
                         "coefficients) are not supported")
    d[:min(dist.size, 5)] = dist[:5]
    return np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *d])


def intrinsics_matrix(v) -> tuple[np.ndarray, np.ndarray]:
    """(K 3×3, distortion (5,)) of an intrinsics vector."""
    v = np.asarray(v, dtype=float)
    return np.array([[v[0], 0.0, v[2]], [0.0, v[1], v[3]], [0.0, 0.0, 1.0]]), v[4:9].copy()


def _selection(model: str, v0: np.ndarray) -> np.ndarray:
    """9 × m: the change of the intrinsics vector per free parameter of the model. ``model``:
    one of ``INTRINSICS_MODELS``, or one of them with parameters released on top, joined by
    "+" (``"focal+cy"``, ``"k1k2+p1+p2"``: the held-fixed intrinsics tested one by one)."""
    base, *extra = str(model).split("+")
    if base not in INTRINSICS_MODELS or any(e not in INTRINSICS_NAMES for e in extra):
        raise ValueError(f"refine_intrinsics: expected one of {', '.join(INTRINSICS_MODELS)}, "
                         f"got {model!r}")
    if base == "focal":
        S = np.zeros((9, 1))
        S[0, 0], S[1, 0] = 1.0, v0[1] / v0[0]
    else:
        free = _FREE[base]
        S = np.zeros((9, len(free)))
        S[list(free), range(len(free))] = 1.0
    for name in extra:
        col = np.zeros((9, 1))
        col[INTRINSICS_NAMES.index(name), 0] = 1.0
        if np.linalg.matrix_rank(np.hstack([S, col])) > S.shape[1]:
            S = np.hstack([S, col])
    return S


def project(p_C: np.ndarray, v: np.ndarray, jacobians: bool = True):
    """OpenCV's projection of points p_C (N, 3) in the camera frame with intrinsics vector v.

    Returns (uv (N, 2), J_p (N, 2, 3) ∂uv/∂p_C, J_i (N, 2, 9) ∂uv/∂v); the Jacobians are None
    when ``jacobians`` is False."""
    fx, fy, cx, cy, k1, k2, p1, p2, k3 = v
    X, Y, Z = p_C[:, 0], p_C[:, 1], p_C[:, 2]
    iz = 1.0 / Z
    x, y = X * iz, Y * iz
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xy = x * y
    xd = x * radial + 2 * p1 * xy + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * xy
    uv = np.stack([fx * xd + cx, fy * yd + cy], axis=1)
    if not jacobians:
        return uv, None, None
    D = k1 + r2 * (2 * k2 + 3 * k3 * r2)            # d radial / d r²
    dxd_dx = radial + 2 * x * x * D + 2 * p1 * y + 6 * p2 * x
    dxd_dy = 2 * xy * D + 2 * p1 * x + 2 * p2 * y
    dyd_dy = radial + 2 * y * y * D + 6 * p1 * y + 2 * p2 * x
    n = len(p_C)
    # ∂(x, y)/∂p_C, then chain through the distortion and K.
    A = np.zeros((n, 2, 2))
    A[:, 0, 0], A[:, 0, 1] = fx * dxd_dx, fx * dxd_dy
    A[:, 1, 0], A[:, 1, 1] = fy * dxd_dy, fy * dyd_dy
    B = np.zeros((n, 2, 3))
    B[:, 0, 0], B[:, 0, 2] = iz, -x * iz
    B[:, 1, 1], B[:, 1, 2] = iz, -y * iz
    J_p = A @ B
    J_i = np.zeros((n, 2, 9))
    J_i[:, 0, 0], J_i[:, 1, 1] = xd, yd
    J_i[:, 0, 2], J_i[:, 1, 3] = 1.0, 1.0
    r4 = r2 * r2
    for col, m in ((4, r2), (5, r4), (8, r4 * r2)):
        J_i[:, 0, col], J_i[:, 1, col] = fx * x * m, fy * y * m
    J_i[:, 0, 6], J_i[:, 1, 6] = fx * 2 * xy, fy * (r2 + 2 * y * y)
    J_i[:, 0, 7], J_i[:, 1, 7] = fx * (r2 + 2 * x * x), fy * 2 * xy
    return uv, J_p, J_i


@dataclass
class _State:
    X_H: np.ndarray
    X_F: np.ndarray
    v: np.ndarray                   # intrinsics vector (9,)
    scale: float
    e: np.ndarray                   # (K, 6) per-image pose errors


def _chain(data: CornerData, st: _State, frame: str):
    """Camera-frame points of every corner and the pieces of their Jacobians (see
    ``_linearize``)."""
    Ri = np.linalg.inv(data.X_R)[data.image]
    sP = st.scale * data.object_points
    E = rotation_exp(st.e[:, :3]).reshape(-1, 3, 3)[data.image] if np.any(st.e[:, :3]) \
        else None
    d = st.e[data.image, 3:]
    if frame == "target":        # the error moves the target: P' = E s P + δt, in T
        P_T = (sP if E is None else np.einsum("nij,nj->ni", E, sP)) + d
    else:
        P_T = sP
    w_T = P_T @ st.X_F[:3, :3].T                                  # R_F P'
    q = np.einsum("nij,nj->ni", Ri[:, :3, :3], w_T + st.X_F[:3, 3]) + Ri[:, :3, 3]
    R_H, t_H = st.X_H[:3, :3], st.X_H[:3, 3]
    p0 = (q - t_H) @ R_H                                          # R_Hᵀ (q − t_H)
    if frame == "target":
        p_C = p0
    else:                        # the error moves the camera: p_C = E p0 + δt, in C
        p_C = (p0 if E is None else np.einsum("nij,nj->ni", E, p0)) + d
    return p_C, p0, q, Ri, w_T, E, sP


#: Frames of the per-image pose error: "camera" (a left perturbation of X_CT about C's origin:
#: the robot's error as it moves a camera on the flange) or "target" (a right perturbation
#: about T's origin: the robot's error as it moves a target on the flange).
POSE_ERROR_FRAMES = ("camera", "target")


def _linearize(data: CornerData, st: _State, S_i: np.ndarray, free_scale: bool,
               jacobians: bool = True, frame: str = "camera"):
    """Residuals (N, 2) px, predicted − measured, and Jacobians: J_g (N, 2, G) of the globals
    [δθ_H, δt_H, δθ_F, δt_F, intrinsics (m), scale?], J_e (N, 2, 6) of the image's pose
    error."""
    p_C, p0, q, Ri, w_T, E, sP = _chain(data, st, frame)
    if np.any(p_C[:, 2] <= MIN_DEPTH):
        raise ValueError("corner-level fit: target points behind the camera at the estimate "
                         "(the start is far from the data, or the chain is read the wrong way)")
    uv, J_p, J_i = project(p_C, st.v, jacobians)
    res = uv - data.image_points
    if not jacobians:
        return res, None, None
    n = len(p_C)
    R_HT = st.X_H[:3, :3].T
    A = R_HT[None] @ Ri[:, :3, :3]                                # ∂p0/∂p_F
    G = 12 + S_i.shape[1] + int(free_scale)
    dp = np.zeros((n, 3, G))
    # R = exp(δθ) R̂, t = t̂ + δt for X_H and X_F: R_F P' → R_F P' − [R_F P']× δθ_F, and
    # R_Hᵀ a → R_Hᵀ a + R_Hᵀ [a]× δθ_H.
    dp[:, :, 0:3] = R_HT[None] @ _skew_stack(q - st.X_H[:3, 3])
    dp[:, :, 3:6] = -R_HT
    dp[:, :, 6:9] = -A @ _skew_stack(w_T)
    dp[:, :, 9:12] = A
    AR = A @ st.X_F[:3, :3]                                       # ∂p0/∂P' (in T)
    if free_scale:
        P = data.object_points if E is None or frame != "target" else \
            np.einsum("nij,nj->ni", E, data.object_points)
        dp[:, :, -1] = np.einsum("nij,nj->ni", AR, P)
    J_e = np.zeros((n, 2, 6))
    if frame == "target":
        EsP = sP if E is None else np.einsum("nij,nj->ni", E, sP)
        J_e[:, :, :3] = J_p @ (AR @ -_skew_stack(EsP))
        J_e[:, :, 3:] = J_p @ AR
    else:
        if E is not None:
            dp = E @ dp
        Ep0 = p0 if E is None else np.einsum("nij,nj->ni", E, p0)
        J_e[:, :, :3] = J_p @ -_skew_stack(Ep0)
        J_e[:, :, 3:] = J_p
    J_g = J_p @ dp
    J_g[:, :, 12:12 + S_i.shape[1]] = J_i @ S_i
    return res, J_g, J_e


def _retract(st: _State, dg: np.ndarray, de: np.ndarray, S_i: np.ndarray, free_scale: bool,
             v0: np.ndarray) -> _State:
    X_H = st.X_H.copy()
    X_H[:3, :3] = rotation_exp(dg[:3]) @ X_H[:3, :3]
    X_H[:3, 3] += dg[3:6]
    X_F = st.X_F.copy()
    X_F[:3, :3] = rotation_exp(dg[6:9]) @ X_F[:3, :3]
    X_F[:3, 3] += dg[9:12]
    m = S_i.shape[1]
    v = st.v + S_i @ dg[12:12 + m]
    scale = st.scale * math.exp(dg[-1] / max(st.scale, 1e-12)) if free_scale else st.scale
    e = st.e + de
    return _State(X_H, X_F, v, scale, e)


@dataclass
class CornerFit:
    """The result of ``fit_corners``.

    Attributes:
        X_H: hand-eye pose (X_EC eye-in-hand, X_BC eye-to-hand); X_F: the fixed pose (X_BT or
            X_ET).
        covariance: 6×6 of X_H's error [δθ (rad); δt (m)] (R = exp(δθ) R̂), marginal over every
            other unknown (the intrinsics' uncertainty included when they are refined).
        fixed_covariance: 6×6 of X_F's error.
        intrinsics: the intrinsics vector [fx, fy, cx, cy, k1, k2, p1, p2, k3] used (refined or
            as given); intrinsics_covariance: 9×9 (zero where not refined).
        model: the intrinsics model; scale, scale_std: the target's scale (1 and 0 unless
            ``free_scale``).
        pixel_sigma: σ_px (px per coordinate); pose_sigma: (6,) σ_e of the per-image pose error
            [rad about C's x y z; m along them].
        residuals: (N, 2) measured − predicted px of every corner (the e_k included);
        corner_used: (N,) bool, image_used: (K,) bool (False: rejected as outliers).
        image_rms_px: (K,) RMS px per image (corner norms, inliers); image_pose_chi2: (K,)
            whitened ‖e_k‖².
        rms_px: RMS px over the inlier corners. dof: 2 N_in − parameters.
        covariance_full: G × G of every global parameter.
    """
    X_H: np.ndarray
    X_F: np.ndarray
    covariance: np.ndarray
    fixed_covariance: np.ndarray
    intrinsics: np.ndarray
    intrinsics_covariance: np.ndarray
    model: str
    scale: float
    scale_std: float
    pixel_sigma: float
    pose_sigma: np.ndarray
    residuals: np.ndarray
    corner_used: np.ndarray
    image_used: np.ndarray
    image_rms_px: np.ndarray
    image_pose_chi2: np.ndarray
    image_errors: np.ndarray
    rms_px: float
    dof: int
    iterations: int
    pose_error_frame: str = "camera"
    covariance_full: np.ndarray = field(repr=False, default=None)

    def X_CT(self, X_R) -> np.ndarray:
        """Predicted X_CT of robot-side poses X_R (K, 4, 4) (e = 0)."""
        X_R = np.asarray(X_R, dtype=float).reshape(-1, 4, 4)
        return inverse(self.X_H)[None] @ np.linalg.inv(X_R) @ self.X_F[None]


def _image_systems(data, J_g, J_e, res, e, w, inv_prior, starts):
    """Each image's whitened system [J_e J_g | b; Λ^½ 0 | Λ^½ e_k], padded to one row count:
    (K, rows, 6 + G) and (K, rows)."""
    K = data.num_images
    n, _, G = J_g.shape
    counts = np.bincount(data.image, minlength=K)
    rows = max(2 * int(counts.max()), G + 1) + 6
    A = np.zeros((K, rows, 6 + G))
    b = np.zeros((K, rows))
    pos = np.arange(n) - starts[data.image]
    sw = np.sqrt(w)
    for a in range(2):
        A[data.image, 2 * pos + a, :6] = sw[:, None] * J_e[:, a]
        A[data.image, 2 * pos + a, 6:] = sw[:, None] * J_g[:, a]
        b[data.image, 2 * pos + a] = sw * res[:, a]
    A[:, rows - 6:, :6] = np.diag(np.sqrt(inv_prior))
    b[:, rows - 6:] = e * np.sqrt(inv_prior)
    return A, b


def _solve_gn(data, st, S_i, free_scale, v0, sigma_px, pose_sigma, weights, frame,
              max_iter=30, tol=1e-10, final=True):
    """Levenberg–Marquardt on the whitened corner residuals plus the e_k prior, with the e_k
    eliminated per image in square-root form: a QR of each image's system, whose trailing block
    is the square root of the globals' information with e_k eliminated (forming
    H_gg − Σ H_ge H_ee⁻¹ H_eg instead cancels catastrophically where a per-image error nearly
    mimics a global parameter, e.g. a focal length and each image's depth).

    Returns (state, iterations, square root of the globals' information, cost, posterior
    covariances of the e_k (K, 6, 6), residuals, J_e)."""
    K = data.num_images
    inv_prior = 1.0 / pose_sigma ** 2
    starts = np.searchsorted(data.image, np.arange(K))
    w = weights / sigma_px ** 2
    lam = 1e-6

    def cost_of(s):
        r = _linearize(data, s, S_i, free_scale, False, frame)[0]
        return float(np.sum(w[:, None] * r ** 2) + np.sum(s.e ** 2 * inv_prior))

    cost = cost_of(st)
    it = 0
    small = 0
    for it in range(1, max_iter + 1):
        r, J_g, J_e = _linearize(data, st, S_i, free_scale, True, frame)
        A, b = _image_systems(data, J_g, J_e, r, st.e, w, inv_prior, starts)
        G = J_g.shape[2]
        # R of [A b] holds R of A and Qᵀb in its last column (no Q formed).
        R_aug = np.linalg.qr(np.concatenate([A, b[..., None]], axis=2), mode="r")
        R, c = R_aug[:, :6 + G, :6 + G], R_aug[:, :6 + G, 6 + G]
        R_ee, R_eg, R_gg = R[:, :6, :6], R[:, :6, 6:], R[:, 6:, 6:]
        root = R_gg.reshape(-1, G)
        rhs = -c[:, 6:].reshape(-1)
        scale = np.maximum(np.linalg.norm(root, axis=0), 1e-300)
        while True:
            M = np.vstack([root / scale, math.sqrt(lam) * np.eye(G)])
            y = np.concatenate([rhs, np.zeros(G)])
            dg = np.linalg.lstsq(M, y, rcond=None)[0] / scale
            de = np.linalg.solve(R_ee, (-c[:, :6] - np.einsum("kij,j->ki", R_eg, dg))[..., None]
                                 )[..., 0]
            try:
                new = _retract(st, dg, de, S_i, free_scale, v0)
                new_cost = cost_of(new)
            except ValueError:
                new_cost = math.inf
            if np.isfinite(new_cost) and new_cost <= cost:
                lam = max(lam / 10.0, 1e-12)
                break
            lam *= 10.0
            if lam > 1e6:
                new, new_cost = st, cost
                break
        decrease = cost - new_cost
        st, cost = new, new_cost
        small = small + 1 if decrease <= tol * max(cost, 1.0) else 0
        if small >= 2 or lam > 1e6:
            break
    if not final:
        # The last linearization (one step before the solution): enough for the noise
        # levels' EM step; the covariance is computed at the solution (``final``).
        R_ee_inv = np.linalg.inv(R_ee)
        return st, it, root, cost, R_ee_inv @ np.swapaxes(R_ee_inv, 1, 2), r, J_e
    root, P_e, r, J_e = _at_solution(data, st, S_i, free_scale, w, inv_prior, frame)
    return st, it, root, cost, P_e, r, J_e


def _at_solution(data, st, S_i, free_scale, w, inv_prior, frame):
    """(square root of the globals' information, posterior covariances of the e_k, residuals,
    J_e) at ``st``."""
    starts = np.searchsorted(data.image, np.arange(data.num_images))
    r, J_g, J_e = _linearize(data, st, S_i, free_scale, True, frame)
    A, _ = _image_systems(data, J_g, J_e, r, st.e, w, inv_prior, starts)
    R = np.linalg.qr(A, mode="r")
    G = J_g.shape[2]
    root = R[:, 6:, 6:].reshape(-1, G)
    # Posterior covariance of each e_k given the globals: (R_eeᵀ R_ee)⁻¹.
    R_ee_inv = np.linalg.inv(R[:, :6, :6])
    return root, R_ee_inv @ np.swapaxes(R_ee_inv, 1, 2), r, J_e


def _covariance(root: np.ndarray) -> np.ndarray:
    """(RᵀR)⁻¹ of a square root R of an information matrix whose parameters have very different
    units (rad, m, px, distortion): columns equilibrated, then an SVD; ValueError when a
    direction is not determined."""
    d = np.linalg.norm(root, axis=0)
    if not np.all(np.isfinite(root)) or np.any(d <= 0):
        raise ValueError("corner-level fit: the data do not determine every parameter")
    _, sv, Vt = np.linalg.svd(root / d, full_matrices=False)
    if sv[-1] <= 1e-7 * sv[0]:
        raise ValueError("corner-level fit: the data do not determine every parameter "
                         f"(information condition number {(sv[0] / max(sv[-1], 1e-300)) ** 2:.3g})")
    C = (Vt.T / sv ** 2) @ Vt / np.outer(d, d)
    return 0.5 * (C + C.T)


def fit_corners(data: CornerData, X_H0, X_F0, intrinsics0, model: str = "none",
                free_scale: bool = False, pixel_sigma0: float = 0.5, pose_sigma0=None,
                estimate_noise: bool = True, robust: bool = True, scale0: float = 1.0,
                max_rounds: int = 3, max_em: int = 12,
                pose_error_frame: str = "camera",
                pose_error_pooled: bool | None = None) -> CornerFit:
    """Corner-level maximum likelihood (see the module docstring).

    Args:
        data: ``CornerData`` (robot-side poses and the detected corners of each image).
        X_H0, X_F0: start (e.g. the pose-level fit).
        intrinsics0: (K 3×3, distortion) or an intrinsics vector (9,): the start, and the
            values held where the model does not refine.
        model: one of ``INTRINSICS_MODELS``.
        free_scale: also estimate the target's scale s (the declared sizes times s).
        pixel_sigma0, pose_sigma0: start of σ_px (px) and σ_e (6,) (rad, m); with
            ``estimate_noise`` False they are held.
        robust: a Huber round, then corner and image outlier rejection.
        pose_error_pooled: σ_e estimated as one rotation and one translation level (the three
            axes pooled), else one level per axis; None: ``POOLED_POSE_ERROR``.
        pose_error_frame: where the per-image pose error acts (``POSE_ERROR_FRAMES``):
            "camera" for eye-in-hand, "target" for eye-to-hand (the part the robot carries).

    Raises:
        ValueError: bad arguments, too few images, or data that do not determine the unknowns.
    """
    if pose_error_frame not in POSE_ERROR_FRAMES:
        raise ValueError(f"pose_error_frame: expected one of {POSE_ERROR_FRAMES}, got "
                         f"{pose_error_frame!r}")
    frame = pose_error_frame
    if pose_error_pooled is None:
        pose_error_pooled = POOLED_POSE_ERROR
    v0 = np.asarray(intrinsics0, dtype=float) if np.ndim(intrinsics0) == 1 else \
        intrinsics_vector(*intrinsics0)
    if v0.shape != (9,) or not np.all(np.isfinite(v0)) or v0[0] <= 0 or v0[1] <= 0:
        raise ValueError(f"intrinsics0: expected 9 finite values with fx, fy > 0, got {v0!r}")
    S_i = _selection(model, v0)
    if data.num_images < 3:
        raise ValueError(f"corners: {data.num_images} images; ≥ 3 needed")
    sigma = max(float(pixel_sigma0), PIXEL_SIGMA_FLOOR)
    floor = np.repeat(POSE_SIGMA_FLOOR, 3)
    ps = np.maximum(np.asarray(pose_sigma0 if pose_sigma0 is not None else
                               [1e-3] * 3 + [1e-3] * 3, dtype=float), floor)
    st = _State(np.asarray(X_H0, float).copy(), np.asarray(X_F0, float).copy(), v0.copy(),
                float(scale0), np.zeros((data.num_images, 6)))
    K = data.num_images
    corner_ok = np.ones(len(data.image), bool)
    image_ok = np.ones(K, bool)
    total_it = 0
    rounds = max_rounds if robust else 1
    for rnd in range(rounds):
        huber = robust and rnd == 0
        for em in range(max_em if estimate_noise else 1):
            weights = (corner_ok & image_ok[data.image]).astype(float)
            if huber:
                r = _linearize(data, st, S_i, free_scale, False, frame)[0]
                norm = np.linalg.norm(r, axis=1) / sigma
                weights = weights * np.minimum(1.0, HUBER_K / np.maximum(norm, 1e-12))
            # After the first solve of a round, each EM step moves the noise levels a little:
            # a few warm-started iterations follow them.
            st, it, H_s, cost, P_e, r, J_e = _solve_gn(data, st, S_i, free_scale, v0,
                                                       sigma, ps, weights, frame,
                                                       max_iter=30 if em == 0 else 3,
                                                       final=False)
            total_it += it
            if not estimate_noise:
                break
            # EM: σ_px² from the inlier residuals and the posterior spread of the e_k; σ_e²
            # from ê_k² and the posterior variances.
            use = weights > 0
            lever = np.einsum("nai,nij,naj->n", J_e, P_e[data.image], J_e) / sigma ** 2
            new_sigma = math.sqrt(max(
                (np.sum(weights[use][:, None] * r[use] ** 2) + sigma ** 2 * np.sum(
                    (weights * lever)[use])) / max(2.0 * np.sum(weights[use] > 0), 1.0),
                PIXEL_SIGMA_FLOOR ** 2))
            ok = image_ok
            # The globals take part of the images' spread (G parameters among 6 K
            # residuals of the e_k): a REML-like correction of the mean.
            n_ok = int(ok.sum())
            reml = n_ok / max(n_ok - H_s.shape[1] / 6.0, 1.0)
            second = reml * np.mean(st.e[ok] ** 2 + np.diagonal(P_e[ok], axis1=1, axis2=2),
                                    axis=0)
            if pose_error_pooled:
                second = np.repeat([second[:3].mean(), second[3:].mean()], 3)
            new_ps = np.sqrt(np.maximum(second, floor ** 2))
            change = max(abs(new_sigma / sigma - 1), float(np.max(np.abs(new_ps / ps - 1))))
            # EM creeps towards the per-image pose error's level (the pixel noise converges
            # in a step or two); over-relaxed in log σ (a fixed point of the same map) it
            # gets there in a few steps.
            sigma = new_sigma
            ps = np.maximum(ps * (new_ps / ps) ** EM_RELAXATION, floor)
            if change < 0.02:
                break
        if not robust or rnd == rounds - 1:
            break
        r = _linearize(data, st, S_i, free_scale, False, frame)[0]
        new_corner = np.sum(r ** 2, axis=1) / sigma ** 2 <= CORNER_OUTLIER_CHI2
        # The images' pose errors judged against a robust level (median absolute value per
        # axis, widened for few images): one gross error inflates the EM level enough to pass
        # its own test (a robot pose 10 mm off among 0.03 mm ones).
        robust_level = MAD_SCALE * np.median(np.abs(st.e[image_ok]), axis=0) \
            * math.sqrt(1.0 + 3.0 / max(int(image_ok.sum()), 1))
        level = np.minimum(ps, np.maximum(robust_level, floor))
        e_chi = np.sum(st.e ** 2 / level ** 2, axis=1)
        new_image = e_chi <= IMAGE_OUTLIER_CHI2
        counts = np.bincount(data.image[new_corner], minlength=K)
        new_image &= counts >= 4
        if new_image.sum() < 3:
            new_image = image_ok
        if np.array_equal(new_corner, corner_ok) and np.array_equal(new_image, image_ok) \
                and not huber:
            break
        corner_ok, image_ok = new_corner, new_image
    weights = (corner_ok & image_ok[data.image]).astype(float)
    # The information at the solution, with the final noise levels.
    H_s = _at_solution(data, st, S_i, free_scale, weights / sigma ** 2, 1.0 / ps ** 2, frame)[0]
    cov_g = _covariance(H_s)
    m = S_i.shape[1]
    cov_i = S_i @ cov_g[12:12 + m, 12:12 + m] @ S_i.T
    r = -_linearize(data, st, S_i, free_scale, False, frame)[0]   # measured − predicted
    used = weights > 0
    norms2 = np.sum(r ** 2, axis=1)
    img_rms = np.sqrt(np.bincount(data.image, norms2 * used, K)
                      / np.maximum(np.bincount(data.image, used.astype(float), K), 1))
    n_in = int(used.sum())
    G = cov_g.shape[0]
    scale_std = math.sqrt(cov_g[-1, -1]) if free_scale else 0.0
    return CornerFit(
        X_H=st.X_H, X_F=st.X_F, covariance=cov_g[:6, :6].copy(),
        fixed_covariance=cov_g[6:12, 6:12].copy(), intrinsics=st.v.copy(),
        intrinsics_covariance=cov_i, model=model, scale=st.scale, scale_std=scale_std,
        pixel_sigma=sigma, pose_sigma=ps, residuals=r, corner_used=corner_ok,
        image_used=image_ok, image_rms_px=img_rms,
        image_pose_chi2=np.sum(st.e ** 2 / ps ** 2, axis=1), image_errors=st.e.copy(),
        rms_px=float(math.sqrt(np.mean(norms2[used]))) if n_in else math.nan,
        dof=2 * n_in - G - 6 * int(image_ok.sum()), iterations=total_it, pose_error_frame=frame,
        covariance_full=cov_g)


def predict(fit: CornerFit, X_R, object_points) -> np.ndarray:
    """Pixels (n, 2) where the corners ``object_points`` (n, 3) of a new image taken at the
    robot-side pose X_R appear by the fit (no per-image error: what a new image shows)."""
    X_CT = fit.X_CT(X_R)[0]
    P = fit.scale * np.asarray(object_points, dtype=float)
    p_C = P @ X_CT[:3, :3].T + X_CT[:3, 3]
    return project(p_C, fit.intrinsics, jacobians=False)[0]


def cross_validate(data: CornerData, fit: CornerFit, folds: int | None = None,
                   free_scale: bool = False, seed: int = 0, every_corner: bool = False) -> dict:
    """Prediction error of images left out of the fit: every image (``folds`` None and at most
    ``LOO_MAX_IMAGES`` images: leave-one-out) or ``folds`` groups, each fitted without them from
    ``fit`` (its noise levels held) and predicted with no per-image error.

    Returns {"rms_px": RMS px over the predicted corners, "image_rms_px": (K,) per image,
    "method": "leave-one-out" | "k-fold (k)"}. Only the images and corners ``fit`` used are
    predicted (``every_corner``: every corner of every image, each fitted without its own image
    and without those ``fit`` rejected: what a user's own left-out test measures)."""
    use = np.flatnonzero(fit.image_used)
    if every_corner:
        return _cross_validate_every_corner(data, fit, free_scale)
    K = len(use)
    if folds is None:
        folds = K if K <= LOO_MAX_IMAGES else 10
    folds = max(2, min(int(folds), K))
    rng = np.random.default_rng(seed)
    order = use if folds == K else rng.permutation(use)
    groups = np.array_split(order, folds)
    v = fit.intrinsics
    per_image = np.full(data.num_images, np.nan)
    sq_sum, count = 0.0, 0
    chi2_sum, dof_sum = 0.0, 0
    for g in groups:
        rest = np.setdiff1d(use, g)
        sub = data.subset(rest)
        keep_c = fit.corner_used[np.isin(data.image, rest)]
        sub = CornerData(sub.X_R, sub.image[keep_c], sub.object_points[keep_c],
                         sub.image_points[keep_c])
        try:
            f = fit_corners(sub, fit.X_H, fit.X_F, v, fit.model, free_scale, fit.pixel_sigma,
                            fit.pose_sigma, estimate_noise=False, robust=False,
                            scale0=fit.scale, pose_error_frame=fit.pose_error_frame)
        except ValueError:
            continue
        for k in g:
            sel = (data.image == k) & fit.corner_used
            if not sel.any():
                continue
            one = CornerData(data.X_R[k:k + 1], np.zeros(int(sel.sum()), int),
                             data.object_points[sel], data.image_points[sel])
            q, dof = _predictive_chi2(f, one, free_scale)
            chi2_sum += q
            dof_sum += dof
            uv = predict(f, data.X_R[k], data.object_points[sel])
            d2 = np.sum((data.image_points[sel] - uv) ** 2, axis=1)
            per_image[k] = math.sqrt(float(np.mean(d2)))
            sq_sum += float(np.sum(d2))
            count += len(d2)
    method = "leave-one-out" if folds == K else f"{folds}-fold"
    return {"rms_px": math.sqrt(sq_sum / count) if count else math.nan,
            "image_rms_px": per_image, "method": method, "folds": folds,
            "chi2_per_dof": chi2_sum / dof_sum if dof_sum else math.nan, "dof": dof_sum}


def _cross_validate_every_corner(data: CornerData, fit: CornerFit, free_scale: bool) -> dict:
    """``cross_validate(every_corner=True)``: leave-one-out over every image."""
    use = np.flatnonzero(fit.image_used)
    per_image = np.full(data.num_images, np.nan)
    sq_sum, count = 0.0, 0
    for k in range(data.num_images):
        rest = use[use != k]
        sub = data.subset(rest)
        keep_c = fit.corner_used[np.isin(data.image, rest)]
        sub = CornerData(sub.X_R, sub.image[keep_c], sub.object_points[keep_c],
                         sub.image_points[keep_c])
        try:
            f = fit_corners(sub, fit.X_H, fit.X_F, fit.intrinsics, fit.model, free_scale,
                            fit.pixel_sigma, fit.pose_sigma, estimate_noise=False, robust=False,
                            scale0=fit.scale, pose_error_frame=fit.pose_error_frame)
        except ValueError:
            continue
        sel = data.image == k
        uv = predict(f, data.X_R[k], data.object_points[sel])
        d2 = np.sum((data.image_points[sel] - uv) ** 2, axis=1)
        per_image[k] = math.sqrt(float(np.mean(d2)))
        sq_sum += float(np.sum(d2))
        count += len(d2)
    return {"rms_px": math.sqrt(sq_sum / count) if count else math.nan,
            "image_rms_px": per_image, "method": "leave-one-out",
            "folds": data.num_images}


def _predictive_chi2(fit: CornerFit, one: CornerData, free_scale: bool) -> tuple[float, int]:
    """Whitened squared prediction error of one new image (its corners ``one``) by ``fit``,
    and its degrees of freedom: the error's covariance is the pixel noise, the image's own
    pose error (its prior Σ_e) and the fit's own uncertainty, each through its Jacobian."""
    S_i = _selection(fit.model, fit.intrinsics)
    st = _State(fit.X_H, fit.X_F, fit.intrinsics, fit.scale, np.zeros((1, 6)))
    res, J_g, J_e = _linearize(one, st, S_i, free_scale, True, fit.pose_error_frame)
    n = len(res)
    Jg = J_g.reshape(2 * n, -1)
    Je = J_e.reshape(2 * n, 6)
    C = fit.pixel_sigma ** 2 * np.eye(2 * n) + (Je * fit.pose_sigma ** 2) @ Je.T \
        + Jg @ fit.covariance_full @ Jg.T
    r = res.reshape(-1)
    return float(r @ np.linalg.solve(C, r)), 2 * n


#: Largest number of images cross-validated leave-one-out (more: 10-fold).
LOO_MAX_IMAGES = 40
#: ``select_intrinsics_model`` keeps a simpler model whose cross-validated error is within this
#: factor of the best one's: more parameters must predict left-out images more than 4 % better.
#: (Measured on rendered images: refining k1, k2 that were given exactly gains 3–4 % in pixels by
#: absorbing interpolation artifacts, and doubles the hand-eye error.)
SIMPLER_WITHIN = 1.04


def select_intrinsics_model(data: CornerData, X_H0, X_F0, intrinsics0, models=INTRINSICS_MODELS,
                            pixel_sigma0: float = 0.5, pose_sigma0=None, seed: int = 0,
                            folds: int | None = None, pose_error_frame: str = "camera",
                            zero_fixed_distortion: bool = False):
    """Fits every intrinsics model and keeps the one whose images are best predicted when left
    out (``cross_validate``), or a simpler one within ``SIMPLER_WITHIN`` of it.

    ``zero_fixed_distortion``: each model holds the distortion terms it does not refine at 0
    (not at ``intrinsics0``'s: for intrinsics estimated from the same images, whose poorly
    determined terms would otherwise bias the models that hold them).

    Returns (chosen model, {model: {"fit": CornerFit | None, "cv": dict | None, "error": str}})."""
    out = {}
    v_start = np.asarray(intrinsics0, dtype=float) if np.ndim(intrinsics0) == 1 else \
        intrinsics_vector(*intrinsics0)
    for m in models:
        v_m = v_start.copy()
        if zero_fixed_distortion:
            free = set(_FREE.get(m, ()))
            for i in range(4, 9):
                if i not in free:
                    v_m[i] = 0.0
        try:
            f = fit_corners(data, X_H0, X_F0, v_m, m, pixel_sigma0=pixel_sigma0,
                            pose_sigma0=pose_sigma0, pose_error_frame=pose_error_frame)
            cv = cross_validate(data, f, folds, seed=seed)
            out[m] = {"fit": f, "cv": cv, "error": ""}
        except ValueError as e:
            out[m] = {"fit": None, "cv": None, "error": str(e)}
    scored = [(o["cv"]["rms_px"], m) for m, o in out.items()
              if o["cv"] is not None and np.isfinite(o["cv"]["rms_px"])]
    if not scored:
        errors = "; ".join(f"{m}: {o['error']}" for m, o in out.items())
        raise ValueError(f"corner-level fit failed for every intrinsics model ({errors})")
    best = min(scored)[0]
    chosen = next(m for m in models if m in out and out[m]["cv"] is not None
                  and out[m]["cv"]["rms_px"] <= SIMPLER_WITHIN * best)
    return chosen, out


def point_sigma(covariance, p_H) -> float:
    """RMS radius (m) of the uncertainty of a point p_H fixed in the hand-eye holder frame's
    child (e.g. a point in front of the camera, given in C, for X_EC): √trace of its 3×3
    covariance in the parent frame, from X's 6×6 error covariance [δθ; δt] (R = exp(δθ) R̂)
    and the rotated point R̂ p_H (pass it rotated)."""
    J = np.hstack([-skew(np.asarray(p_H, float)), np.eye(3)])
    C = J @ np.asarray(covariance, float) @ J.T
    return float(math.sqrt(max(np.trace(C), 0.0)))



def scale_midpoint(X: np.ndarray, covariance: np.ndarray, scale: float):
    """The two readings of a pose X fitted with a target scale s ≠ 1 and the answer that covers
    both. "The print is s× its declared size": X as fitted; "the robot's translations are s×
    their true lengths": the same rotation, the translation divided by s (the whole cell scaled
    by 1/s shows the same pixels). The answer: the midpoint of the translations, with covariance
    the propagated one plus ¼ (t_A − t_B)(t_A − t_B)ᵀ (a 50/50 mixture: each reading 1σ from the
    answer along their difference).

    ``covariance``: 7×7 of [δθ; δt; δs] (R = exp(δθ) R̂). Returns (X_robot, X_answer, C_answer
    6×6)."""
    s = float(scale)
    t = X[:3, 3]
    X_robot, X_mid = X.copy(), X.copy()
    X_robot[:3, 3] = t / s
    X_mid[:3, 3] = 0.5 * (t + t / s)
    # δm = ½(1 + 1/s) δt − t / (2 s²) δs; rotation unchanged.
    J = np.zeros((6, 7))
    J[:3, :3] = np.eye(3)
    J[3:, 3:6] = 0.5 * (1.0 + 1.0 / s) * np.eye(3)
    J[3:, 6] = -t / (2.0 * s * s)
    d = np.concatenate([np.zeros(3), 0.5 * (t - t / s)])
    C = J @ np.asarray(covariance, float) @ J.T + np.outer(d, d)
    return X_robot, X_mid, 0.5 * (C + C.T)

__all__ = ["CornerData", "CornerFit", "INTRINSICS_MODELS", "INTRINSICS_NAMES",
           "cross_validate", "fit_corners", "intrinsics_matrix", "intrinsics_vector",
           "point_sigma", "predict", "scale_midpoint", "project", "select_intrinsics_model"]

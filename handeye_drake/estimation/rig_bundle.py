"""Corner-level maximum likelihood of a camera rig: N cameras, each on the hand (eye-in-hand:
X_EC) or fixed in the cell (X_BC), and one or more boards, each in the cell (X_BT) or on the hand
(X_ET), fitted jointly to every detected corner. Each board's pose is one unknown for every camera
that sees it: the cameras' poses relative to each other come out with their covariance.

The model of each (camera c, board b) block is ``reprojection``'s, with the robot-side pose X_R
between the two mounts (``robot_side``):

    X_CT,k = X_c⁻¹ · X_R,k⁻¹ · X_b          hand camera, cell board: X_R = X_BE
                                            cell camera, hand board: X_R = X_EB
                                            same mount:             X_R = I (a fixed view)
    u_kj = π(K_c, d_c; Exp(e_k) ⊕ X_CT,k · P_j) + n_kj,   n ~ N(0, σ_px,cb² I₂),
    e_k ~ N(0, diag σ_e,cb²)

The per-image pose errors e_k are marginalized per image (square-root form, as
``reprojection._solve_gn``); the pixel noise and pose-error levels are estimated per block by EM;
one Huber round, then corner and image outliers rejected per block. Each image's pose error is
its own (cameras seeing the board at the same instant share the robot's error in truth: treating
them as independent overstates the board's information by at most √N_cameras where the robot's
error dominates the pixels' — the verdict's consistency tests use the fitted levels).

Unknowns (global vector, error state [δθ; δt] with R = exp(δθ) R̂, t = t̂ + δt): per camera X_c
(6) and its intrinsics (``reprojection.INTRINSICS_MODELS``: m_c), per board X_b (6).

No Drake import: numpy and scipy.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from .reprojection import (CORNER_OUTLIER_CHI2, EM_RELAXATION, HUBER_K, IMAGE_OUTLIER_CHI2,
                           MAD_SCALE, PIXEL_SIGMA_FLOOR, POSE_SIGMA_FLOOR, CornerData, _State,
                           _covariance, _image_systems, _linearize, _selection)
from .se3 import inverse, rotation_exp, rotation_log

MOUNTS = ("hand", "cell")
#: Pixel noise floor (px) of a fixed view: one view cannot tell a corner detector's bias (a few
#: hundredths of a pixel on sharp images, more on real ones) from the pose; 0.1 px is the bias
#: level of a good corner detector (measured on the rendered boards: 0.05–0.07 px RMS of the
#: detected corners against the true projections).
FIXED_VIEW_PIXEL_FLOOR = 0.1


def robot_side(camera_mount: str, board_mount: str, X_BE) -> np.ndarray:
    """X_R (K, 4, 4) of the block model from the flange poses X_BE (K, 4, 4)."""
    X_BE = np.asarray(X_BE, dtype=float).reshape(-1, 4, 4)
    for name, m in (("camera_mount", camera_mount), ("board_mount", board_mount)):
        if m not in MOUNTS:
            raise ValueError(f"{name}: expected one of {MOUNTS}, got {m!r}")
    if camera_mount == board_mount:
        return np.repeat(np.eye(4)[None], len(X_BE), axis=0)
    return X_BE.copy() if camera_mount == "hand" else np.linalg.inv(X_BE)


def pose_error_frame(camera_mount: str, board_mount: str) -> str:
    """Where a block's per-image error acts: on the part the robot carries (the camera on the
    hand: "camera"; the board on the hand seen from the cell: "target"); a fixed view: "camera"
    (a shaking camera)."""
    return "target" if (camera_mount, board_mount) == ("cell", "hand") else "camera"


@dataclass
class RigBlock:
    """The corners camera ``camera`` detected of board ``board``: ``data`` (``CornerData`` with
    X_R from ``robot_side``), ``instants`` (K,) the index of each image's instant (shared by the
    cameras of one recording), ``frame`` the pose-error frame."""
    camera: int
    board: int
    data: CornerData
    instants: np.ndarray
    frame: str = "camera"
    #: True when camera and board share a mount: every image repeats one view, so its images'
    #: corner errors are not independent — they count as one image (weight 1/K), with the
    #: pixel noise floored at ``FIXED_VIEW_PIXEL_FLOOR``.
    fixed_view: bool = False
    #: Factor ≥ 1 on the block's corner variance (``fit_rig``'s ``variance_factors``).
    variance_factor: float = 1.0


@dataclass
class BlockResult:
    """Per block: noise levels, inliers, residuals (measured − predicted px)."""
    pixel_sigma: float
    pose_sigma: np.ndarray
    corner_used: np.ndarray
    image_used: np.ndarray
    image_rms_px: np.ndarray
    image_pose_chi2: np.ndarray
    image_errors: np.ndarray
    rms_px: float
    residuals: np.ndarray = field(repr=False, default=None)


@dataclass
class RigFit:
    """The result of ``fit_rig``: X_cameras[c] (X_EC or X_BC by the camera's mount), X_boards[b]
    (X_BT or X_ET), intrinsics[c] (9,), models[c]; ``covariance_full`` of the global vector;
    ``columns`` {("camera", c) | ("board", b) | ("intrinsics", c): slice}; ``blocks`` the
    ``BlockResult`` of each block."""
    X_cameras: list
    X_boards: list
    intrinsics: list
    models: list
    covariance_full: np.ndarray
    columns: dict
    blocks: list
    iterations: int = 0
    #: Per board its scale (true sizes / declared: 1 unless ``fit_rig(free_scale=True)``).
    scales: list = None
    #: The shared robot error's level (6: rad, m about and along E; None without shared
    #: instants) and its value per shared instant.
    robot_sigma: np.ndarray = None
    robot_errors: np.ndarray = None
    #: The covariance with the robot's repeating error marginalized at every instant
    #: (``fit_rig(robot_level=…)``), the camera-to-camera transforms'; None without.
    covariance_systematic: np.ndarray = None

    def scale_std(self, b: int) -> float:
        s = self.columns.get(("scale", b))
        return 0.0 if s is None else math.sqrt(max(float(self.covariance_full[s, s][0, 0]),
                                                    0.0))

    def camera_covariance(self, c: int) -> np.ndarray:
        s = self.columns[("camera", c)]
        return self.covariance_full[s, s].copy()

    def board_covariance(self, b: int) -> np.ndarray:
        s = self.columns[("board", b)]
        return self.covariance_full[s, s].copy()

    def intrinsics_covariance(self, c: int) -> np.ndarray:
        S = _selection(self.models[c], self.intrinsics[c])
        s = self.columns[("intrinsics", c)]
        return S @ self.covariance_full[s, s] @ S.T

    def relative(self, a: int, b: int, board: int | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
        """X_{C_a C_b} = X_a⁻¹ X_b (meaningful for two cameras on one mount) and its 6×6
        covariance [δθ; δt] (R = exp(δθ) R̂), from the joint covariance of X_a and X_b; with
        ``board`` and its scale free, 7×7 of [δθ; δt; δs_board] (``with_scale``)."""
        Xa, Xb = self.X_cameras[a], self.X_cameras[b]
        X = inverse(Xa) @ Xb
        J = np.zeros((6, 12))
        h = 1e-7
        for i in range(12):
            d = np.zeros(6)
            d[i % 6] = h
            Pp = (_perturb(Xa, d), Xb) if i < 6 else (Xa, _perturb(Xb, d))
            Pm = (_perturb(Xa, -d), Xb) if i < 6 else (Xa, _perturb(Xb, -d))
            J[:, i] = (tangent(inverse(Pp[0]) @ Pp[1], X) - tangent(inverse(Pm[0]) @ Pm[1], X)
                       ) / (2 * h)
        sa, sb = self.columns[("camera", a)], self.columns[("camera", b)]
        idx = np.r_[np.arange(sa.start, sa.stop), np.arange(sb.start, sb.stop)]
        if board is not None and ("scale", board) in self.columns:
            idx = np.r_[idx, self.columns[("scale", board)].start]
            J7 = np.zeros((7, 13))
            J7[:6, :12], J7[6, 12] = J, 1.0
            J = J7
        full = self.covariance_full if self.covariance_systematic is None \
            else self.covariance_systematic
        C = J @ full[np.ix_(idx, idx)] @ J.T
        return X, 0.5 * (C + C.T)

    def with_scale(self, kind: str, i: int, board: int = 0) -> np.ndarray:
        """Covariance of [δθ; δt] of camera or board ``i`` (``kind`` "camera" | "board") and the
        scale of ``board`` (7×7; 6×6 when the scale was held)."""
        s = self.columns[(kind, i)]
        idx = np.arange(s.start, s.stop)
        if ("scale", board) in self.columns:
            idx = np.r_[idx, self.columns[("scale", board)].start]
        return self.covariance_full[np.ix_(idx, idx)].copy()


def _perturb(X, d):
    Y = X.copy()
    Y[:3, :3] = rotation_exp(d[:3]) @ X[:3, :3]
    Y[:3, 3] = X[:3, 3] + d[3:]
    return Y


def tangent(X1, X2) -> np.ndarray:
    """[log(R1 R2ᵀ); t1 − t2]: the error state of X1 about X2."""
    return np.concatenate([rotation_log(X1[:3, :3] @ X2[:3, :3].T), X1[:3, 3] - X2[:3, 3]])


def _columns(num_cameras, num_boards, S, free_scale=False):
    cols, n = {}, 0
    for c in range(num_cameras):
        cols[("camera", c)] = slice(n, n + 6)
        n += 6
    for b in range(num_boards):
        cols[("board", b)] = slice(n, n + 6)
        n += 6
    for c in range(num_cameras):
        m = S[c].shape[1]
        cols[("intrinsics", c)] = slice(n, n + m)
        n += m
    if free_scale:
        for b in range(num_boards):
            cols[("scale", b)] = slice(n, n + 1)
            n += 1
    return cols, n


def _block_columns(blk, cols):
    c, b = blk.camera, blk.board
    out = np.r_[np.arange(cols[("camera", c)].start, cols[("camera", c)].stop),
                np.arange(cols[("board", b)].start, cols[("board", b)].stop),
                np.arange(cols[("intrinsics", c)].start, cols[("intrinsics", c)].stop)]
    if ("scale", b) in cols:   # ``_linearize``'s scale column comes last
        out = np.r_[out, cols[("scale", b)].start]
    return out


class _RigState:
    def __init__(self, X_cameras, X_boards, v, e, scales=None, d=None):
        self.X_c = [np.asarray(X, float).copy() for X in X_cameras]
        self.X_b = [np.asarray(X, float).copy() for X in X_boards]
        self.v = [np.asarray(x, float).copy() for x in v]
        self.e = [np.asarray(x, float).copy() for x in e]
        self.s = [1.0] * len(self.X_b) if scales is None else [float(x) for x in scales]
        #: (groups with a shared robot error, 6): the flange's pose error at those instants.
        self.d = np.zeros((0, 6)) if d is None else np.asarray(d, float).copy()

    def block(self, i, blk) -> _State:
        return _State(self.X_c[blk.camera], self.X_b[blk.board], self.v[blk.camera],
                      self.s[blk.board], self.e[i])

    def retract(self, dg, de, dd, cols, S) -> "_RigState":
        new = _RigState(self.X_c, self.X_b, self.v, [e + d for e, d in zip(self.e, de)],
                        self.s, self.d + dd)
        for b in range(len(new.s)):
            if ("scale", b) in cols:
                new.s[b] = new.s[b] + float(dg[cols[("scale", b)]][0])
                if not new.s[b] > 0.0:
                    raise ValueError("board scale left (0, ∞)")
        for c in range(len(new.X_c)):
            new.X_c[c] = _perturb(new.X_c[c], dg[cols[("camera", c)]])
            new.v[c] = new.v[c] + S[c] @ dg[cols[("intrinsics", c)]]
        for b in range(len(new.X_b)):
            new.X_b[b] = _perturb(new.X_b[b], dg[cols[("board", b)]])
        return new


def _flange_side(blk) -> int:
    """How the flange's pose error δ (X_BE,true = X_BE · T(δ), about and along E) enters a
    block's X_R: +1 X_R = X_BE (a camera on the hand), −1 X_R = X_EB (a board on the hand seen
    from the cell), 0 none (a fixed view)."""
    if blk.fixed_view:
        return 0
    return -1 if blk.frame == "target" else 1


class _Groups:
    """The images of every block grouped by instant. Where two or more images that the robot
    moves (not fixed views) share an instant, they share the robot's pose error there: one δ
    (6, in E) for them all, besides each image's own error e (a camera's shake, a detector's
    bias shared by an image's corners) — treating the robot's error as each camera's own would
    let it into the camera-to-camera transforms, where it cancels in truth."""

    def __init__(self, blocks, shared: bool, min_moved: int = 2):
        members = {}
        for i, blk in enumerate(blocks):
            for k, g in enumerate(np.asarray(blk.instants, int)):
                members.setdefault(int(g), []).append((i, k))
        self.members = [members[g] for g in sorted(members)]
        self.delta = [-1] * len(self.members)
        self.index = [np.full(b.data.num_images, -1) for b in blocks]
        n = 0
        for gi, mem in enumerate(self.members):
            moved = [(i, k) for i, k in mem if _flange_side(blocks[i]) != 0]
            if shared and len(moved) >= min_moved:
                self.delta[gi] = n
                for i, k in moved:
                    self.index[i][k] = n
                n += 1
        self.num_delta = n


def _T(d) -> np.ndarray:
    d = np.atleast_2d(d)
    T = np.repeat(np.eye(4)[None], len(d), axis=0)
    T[:, :3, :3] = Rotation.from_rotvec(d[:, :3]).as_matrix()
    T[:, :3, 3] = d[:, 3:]
    return T


def _effective(blk, idx, d, extra=None) -> CornerData:
    """The block's data with the shared flange errors d applied to X_R (images idx ≥ 0)."""
    side = _flange_side(blk)
    sel = idx >= 0
    if side == 0 or not sel.any():
        return blk.data
    D = d[idx[sel]] if extra is None else d[idx[sel]] + extra
    T = _T(D)
    X = blk.data.X_R.copy()
    X[sel] = X[sel] @ T if side > 0 else np.linalg.inv(T) @ X[sel]
    return CornerData(X, blk.data.image, blk.data.object_points, blk.data.image_points)


def _residuals(blocks, st, S, groups, i, blk):
    data = _effective(blk, groups.index[i], st.d)
    return _linearize(data, st.block(i, blk), S[blk.camera], False, False, blk.frame)[0]


def _cost(blocks, st, S, w, inv_prior, groups, inv_prior_d):
    total = float(np.sum(st.d ** 2 * inv_prior_d))
    for i, blk in enumerate(blocks):
        r = _residuals(blocks, st, S, groups, i, blk)
        total += float(np.sum(w[i][:, None] * r ** 2) + np.sum(st.e[i] ** 2 * inv_prior[i]))
    return total


def _delta_jacobian(blk, st, S, groups, i, h=1e-6) -> np.ndarray:
    """(N, 2, 6) ∂ predicted pixels / ∂ δ (central differences; zeros where no δ)."""
    idx = groups.index[i]
    n = len(blk.data.image)
    J = np.zeros((n, 2, 6))
    if _flange_side(blk) == 0 or not np.any(idx >= 0):
        return J
    stb = st.block(i, blk)
    for a in range(6):
        e = np.zeros(6)
        e[a] = h
        rp = _linearize(_effective(blk, idx, st.d, e), stb, S[blk.camera], False, False,
                        blk.frame)[0]
        rm = _linearize(_effective(blk, idx, st.d, -e), stb, S[blk.camera], False, False,
                        blk.frame)[0]
        J[:, :, a] = (rp - rm) / (2 * h)
    J[idx[blk.data.image] < 0] = 0.0
    return J


def _systems(blocks, st, S, w, inv_prior, cols, G, groups, inv_prior_d):
    """Per instant the QR of its images' whitened system (every block's image at that instant,
    their own pose errors e and, where shared, the robot's δ eliminated); returns (global root
    rows, rhs, per group (R_nn, R_ng, c_n, layout), residuals, J_e, J_δ per block)."""
    res, jes, jgs, jds, starts, bcs = [], [], [], [], [], []
    for i, blk in enumerate(blocks):
        d = blk.data
        data = _effective(blk, groups.index[i], st.d)
        r, J_g, J_e = _linearize(data, st.block(i, blk), S[blk.camera],
                                 ("scale", blk.board) in cols, True, blk.frame)
        res.append(r)
        jes.append(J_e)
        jgs.append(J_g)
        jds.append(_delta_jacobian(blk, st, S, groups, i))
        starts.append(np.searchsorted(d.image, np.arange(d.num_images + 1)))
        bcs.append(_block_columns(blk, cols))
    roots, rhs, parts = [], [], []
    for gi, mem in enumerate(groups.members):
        nd = 6 if groups.delta[gi] >= 0 else 0
        nn = nd + 6 * len(mem)
        n_rows = sum(2 * (starts[i][k + 1] - starts[i][k]) for i, k in mem) + nn
        A = np.zeros((max(n_rows, nn + G + 1), nn + G))
        b = np.zeros(A.shape[0])
        row = 0
        for m, (i, k) in enumerate(mem):
            sl = slice(starts[i][k], starts[i][k + 1])
            sw = np.sqrt(w[i][sl])
            n = sl.stop - sl.start
            for a in range(2):
                rr = slice(row + a, row + 2 * n, 2)
                A[rr, nd + 6 * m:nd + 6 * m + 6] = sw[:, None] * jes[i][sl, a]
                if nd and groups.index[i][k] >= 0:
                    A[rr, :6] = sw[:, None] * jds[i][sl, a]
                A[rr, nn + bcs[i]] = sw[:, None] * jgs[i][sl, a]
                b[rr] = sw * res[i][sl, a]
            row += 2 * n
            q = np.sqrt(inv_prior[i])
            A[row:row + 6, nd + 6 * m:nd + 6 * m + 6] = np.diag(q)
            b[row:row + 6] = st.e[i][k] * q
            row += 6
        if nd:
            q = np.sqrt(inv_prior_d)
            A[row:row + 6, :6] = np.diag(q)
            b[row:row + 6] = st.d[groups.delta[gi]] * q
        R_aug = np.linalg.qr(np.column_stack([A, b]), mode="r")
        R, c = R_aug[:nn + G, :nn + G], R_aug[:nn + G, nn + G]
        roots.append(R[nn:, nn:])
        rhs.append(-c[nn:])
        parts.append((R[:nn, :nn], R[:nn, nn:], c[:nn], nd, mem))
    return np.vstack(roots), np.concatenate(rhs), parts, res, jes, jds


def _info(blocks, weights, sigma):
    """Per block the corner weights of the solve: inlier weights / σ², a fixed view's divided by
    its number of images, with σ floored (``RigBlock.fixed_view``)."""
    out = []
    for blk, wt, s in zip(blocks, weights, sigma):
        if blk.fixed_view:
            k = max(len(np.unique(blk.data.image[wt > 0])), 1)
            out.append(wt / (k * blk.variance_factor * max(s, FIXED_VIEW_PIXEL_FLOOR) ** 2))
        else:
            out.append(wt / (blk.variance_factor * s ** 2))
    return out


def _nuisance_step(parts, dg, blocks, groups):
    de = [np.zeros((b.data.num_images, 6)) for b in blocks]
    dd = np.zeros((groups.num_delta, 6))
    for gi, (R_nn, R_ng, c_n, nd, mem) in enumerate(parts):
        x = np.linalg.solve(R_nn, -c_n - R_ng @ dg)
        if nd:
            dd[groups.delta[gi]] = x[:6]
        for m, (i, k) in enumerate(mem):
            de[i][k] = x[nd + 6 * m:nd + 6 * m + 6]
    return de, dd


def _solve(blocks, st, S, cols, G, sigma, ps, weights, groups, pd, max_iter=30, tol=1e-10):
    w = _info(blocks, weights, sigma)
    inv_prior = [1.0 / p ** 2 for p in ps]
    inv_prior_d = 1.0 / pd ** 2
    cost = _cost(blocks, st, S, w, inv_prior, groups, inv_prior_d)
    lam, small, it = 1e-6, 0, 0
    for it in range(1, max_iter + 1):
        root, rhs, parts, *_ = _systems(blocks, st, S, w, inv_prior, cols, G, groups,
                                        inv_prior_d)
        scale = np.maximum(np.linalg.norm(root, axis=0), 1e-300)
        while True:
            M = np.vstack([root / scale, math.sqrt(lam) * np.eye(G)])
            dg = np.linalg.lstsq(M, np.concatenate([rhs, np.zeros(G)]), rcond=None)[0] / scale
            de, dd = _nuisance_step(parts, dg, blocks, groups)
            try:
                new = st.retract(dg, de, dd, cols, S)
                new_cost = _cost(blocks, new, S, w, inv_prior, groups, inv_prior_d)
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
    return st, it, w, inv_prior, inv_prior_d


def fit_rig(blocks, X_cameras0, X_boards0, intrinsics0, models=None, pixel_sigma0=None,
            pose_sigma0=None, estimate_noise: bool = True, robust: bool = True,
            max_rounds: int = 3, max_em: int = 10, variance_factors=None,
            covariance: bool = True, free_scale: bool = False, scales0=None,
            shared_robot_error: bool = True, robot_sigma0=None, robot_level=None) -> RigFit:
    """The joint corner-level fit (module docstring).

    Args:
        blocks: ``RigBlock`` list (each ≥ 3 images).
        X_cameras0, X_boards0: starts (4×4 each; X_EC / X_BC, X_BT / X_ET by the mounts).
        intrinsics0: per camera an intrinsics vector (9,) — the start and the values held.
        models: per camera one of ``reprojection.INTRINSICS_MODELS`` (default "none").
        pixel_sigma0, pose_sigma0: per block starts of σ_px (px) and σ_e (6,) (rad, m).
        variance_factors: per block a factor ≥ 1 on its corners' variance (e.g. the camera's
            own cross-validation factor: its left-out images predicted worse than its noise
            model says).
        covariance: False skips the covariance (``covariance_full`` None: a refit whose
            answer alone is wanted, e.g. the jackknife's).
        free_scale: each board's scale s (true sizes / declared) is an unknown too (a print a
            fraction of a percent off; the same pixels as the robot's translations s× long).
        scales0: per board the scale's start (and value held without ``free_scale``).
        shared_robot_error: images that the robot moves and that share an instant share one
            flange pose error δ (``_Groups``), its level (6, about and along E) estimated by EM
            from ``robot_sigma0``; False: each image's error is its own only.
        robot_level: (deg, m) per axis of the robot's error that repeats over the recording
            (a kinematic error: it follows the joint angles, so it does not average out as the
            per-instant model assumes — ``calibration.corners.systematic_robot_level``). The
            covariance is then that of a flange error of at least this level at every instant
            the robot moves an image, marginalized (``RigFit.covariance_systematic``, used by
            ``relative``): the camera-to-camera transforms' σ hold it — a robot error reaches
            them through the instants only one camera sees. Each camera's own answer takes the
            constant part instead (``pipeline.robot_error_covariance``, by the caller); the
            estimate is not changed.

    Raises:
        ValueError: bad arguments, or data that do not determine every unknown (a camera whose
            board no other camera places, a board seen only from its own mount).
    """
    nc, nb = len(X_cameras0), len(X_boards0)
    if not blocks:
        raise ValueError("blocks: no camera saw a board")
    models = list(models) if models is not None else ["none"] * nc
    v0 = [np.asarray(v, float) for v in intrinsics0]
    if len(models) != nc or len(v0) != nc:
        raise ValueError(f"fit_rig: {nc} cameras, {len(v0)} intrinsics and {len(models)} models")
    for blk in blocks:
        if not (0 <= blk.camera < nc and 0 <= blk.board < nb):
            raise ValueError(f"fit_rig: block of camera {blk.camera} board {blk.board} out of "
                             "range")
        if blk.data.num_images < 3:
            raise ValueError(f"fit_rig: camera {blk.camera} has {blk.data.num_images} images "
                             "of board {blk.board}; ≥ 3 needed")
    S = [_selection(m, v) for m, v in zip(models, v0)]
    cols, G = _columns(nc, nb, S, free_scale)
    nbk = len(blocks)
    factors = [max(float(f), 1.0) for f in (variance_factors or [1.0] * nbk)]
    blocks = [dataclasses.replace(b, variance_factor=f) for b, f in zip(blocks, factors)]
    sigma = [max(float(s), PIXEL_SIGMA_FLOOR) for s in (pixel_sigma0 or [0.3] * nbk)]
    floor = np.repeat(POSE_SIGMA_FLOOR, 3)
    ps = [np.maximum(np.asarray(p if p is not None else [1e-3] * 6, float), floor)
          for p in (pose_sigma0 or [None] * nbk)]
    groups = _Groups(blocks, shared_robot_error)
    pd = np.maximum(np.asarray(robot_sigma0 if robot_sigma0 is not None else [1e-3] * 6,
                               float), floor)
    st = _RigState(X_cameras0, X_boards0, v0, [np.zeros((b.data.num_images, 6)) for b in blocks],
                   scales0, np.zeros((groups.num_delta, 6)))
    corner_ok = [np.ones(len(b.data.image), bool) for b in blocks]
    image_ok = [np.ones(b.data.num_images, bool) for b in blocks]
    total = 0
    rounds = max_rounds if robust else 1
    for rnd in range(rounds):
        huber = robust and rnd == 0
        for em in range(max_em if estimate_noise else 1):
            weights = []
            for i, blk in enumerate(blocks):
                wt = (corner_ok[i] & image_ok[i][blk.data.image]).astype(float)
                if huber:
                    r = _residuals(blocks, st, S, groups, i, blk)
                    norm = np.linalg.norm(r, axis=1) / sigma[i]
                    wt = wt * np.minimum(1.0, HUBER_K / np.maximum(norm, 1e-12))
                weights.append(wt)
            st, it, w, inv_prior, inv_prior_d = _solve(blocks, st, S, cols, G, sigma, ps,
                                                       weights, groups, pd,
                                                       max_iter=30 if em == 0 else 4)
            total += it
            if not estimate_noise:
                break
            _, _, parts, res, jes, jds = _systems(blocks, st, S, w, inv_prior, cols, G,
                                                  groups, inv_prior_d)
            # Posterior covariances of each image's own error (P_e), of the shared δ (P_d) and
            # the pixel variance they explain per corner (lever, in σ² units).
            P_e = [np.zeros((b.data.num_images, 6, 6)) for b in blocks]
            lever = [np.zeros(len(b.data.image)) for b in blocks]
            P_d = np.zeros((groups.num_delta, 6, 6))
            for gi, (R_nn, _, _, nd, mem) in enumerate(parts):
                Ri = np.linalg.inv(R_nn)
                P = Ri @ Ri.T
                if nd:
                    P_d[groups.delta[gi]] = P[:6, :6]
                for m, (i, k) in enumerate(mem):
                    e_sl = slice(nd + 6 * m, nd + 6 * m + 6)
                    P_e[i][k] = P[e_sl, e_sl]
                    c_sl = slice(*np.searchsorted(blocks[i].data.image, [k, k + 1]))
                    if nd and groups.index[i][k] >= 0:
                        idx = np.r_[0:6, e_sl.start:e_sl.stop]
                        J = np.concatenate([jds[i][c_sl], jes[i][c_sl]], axis=2)
                        Pm = P[np.ix_(idx, idx)]
                    else:
                        J, Pm = jes[i][c_sl], P[e_sl, e_sl]
                    lever[i][c_sl] = np.einsum("nai,ij,naj->n", J, Pm, J) / sigma[i] ** 2
            change = 0.0
            for i, blk in enumerate(blocks):
                wt, r = weights[i], res[i]
                use = wt > 0
                new_sigma = math.sqrt(max(
                    (np.sum(wt[use][:, None] * r[use] ** 2) + sigma[i] ** 2 * np.sum(
                        (wt * lever[i])[use])) / max(2.0 * np.sum(use), 1.0),
                    PIXEL_SIGMA_FLOOR ** 2))
                ok = image_ok[i]
                n_ok = int(ok.sum())
                Gb = 12 + S[blk.camera].shape[1] + int(free_scale)
                reml = n_ok / max(n_ok - Gb / 6.0, 1.0)
                new_ps = np.sqrt(np.maximum(reml * np.mean(st.e[i][ok] ** 2 + np.diagonal(
                    P_e[i][ok], axis1=1, axis2=2), axis=0), floor ** 2))
                change = max(change, abs(new_sigma / sigma[i] - 1),
                             float(np.max(np.abs(new_ps / ps[i] - 1))))
                sigma[i] = new_sigma
                ps[i] = np.maximum(ps[i] * (new_ps / ps[i]) ** EM_RELAXATION, floor)
            if groups.num_delta:
                new_pd = np.sqrt(np.maximum(np.mean(st.d ** 2 + np.diagonal(
                    P_d, axis1=1, axis2=2), axis=0), floor ** 2))
                change = max(change, float(np.max(np.abs(new_pd / pd - 1))))
                pd = np.maximum(pd * (new_pd / pd) ** EM_RELAXATION, floor)
            if change < 0.02:
                break
        if not robust or rnd == rounds - 1:
            break
        same = not huber
        for i, blk in enumerate(blocks):
            d = blk.data
            r = _residuals(blocks, st, S, groups, i, blk)
            new_corner = np.sum(r ** 2, axis=1) / sigma[i] ** 2 <= CORNER_OUTLIER_CHI2
            robust_level = MAD_SCALE * np.median(np.abs(st.e[i][image_ok[i]]), axis=0) \
                * math.sqrt(1.0 + 3.0 / max(int(image_ok[i].sum()), 1))
            level = np.minimum(ps[i], np.maximum(robust_level, floor))
            new_image = np.sum(st.e[i] ** 2 / level ** 2, axis=1) <= IMAGE_OUTLIER_CHI2
            new_image &= np.bincount(d.image[new_corner], minlength=d.num_images) >= 4
            if new_image.sum() < 3:
                new_image = image_ok[i]
            same = same and np.array_equal(new_corner, corner_ok[i]) and np.array_equal(
                new_image, image_ok[i])
            corner_ok[i], image_ok[i] = new_corner, new_image
        if same:
            break
    weights = [(corner_ok[i] & image_ok[i][b.data.image]).astype(float)
               for i, b in enumerate(blocks)]
    w = _info(blocks, weights, sigma)
    inv_prior = [1.0 / p ** 2 for p in ps]
    cov = cov_sys = None
    if covariance:
        cov = _covariance(_systems(blocks, st, S, w, inv_prior, cols, G, groups,
                                   1.0 / pd ** 2)[0])
    if covariance and robot_level is not None:
        every = _Groups(blocks, True, min_moved=1)
        d = np.zeros((every.num_delta, 6))
        for gi, n in enumerate(every.delta):
            if n >= 0 and groups.delta[gi] >= 0:
                d[n] = st.d[groups.delta[gi]]
        level = np.maximum(pd, np.repeat([math.radians(float(robot_level[0])),
                                          float(robot_level[1])], 3))
        st_every = _RigState(st.X_c, st.X_b, st.v, st.e, st.s, d)
        cov_sys = _covariance(_systems(blocks, st_every, S, w, inv_prior, cols, G, every,
                                       1.0 / level ** 2)[0])
    results = []
    for i, blk in enumerate(blocks):
        d = blk.data
        r = -_residuals(blocks, st, S, groups, i, blk)
        used = weights[i] > 0
        n2 = np.sum(r ** 2, axis=1)
        K = d.num_images
        img_rms = np.sqrt(np.bincount(d.image, n2 * used, K)
                          / np.maximum(np.bincount(d.image, used.astype(float), K), 1))
        results.append(BlockResult(
            sigma[i], ps[i], corner_ok[i], image_ok[i], img_rms,
            np.sum(st.e[i] ** 2 / ps[i] ** 2, axis=1), st.e[i].copy(),
            float(math.sqrt(np.mean(n2[used]))) if used.any() else math.nan, r))
    return RigFit(st.X_c, st.X_b, st.v, models, cov, cols, results, total, list(st.s),
                  pd if groups.num_delta else None, st.d.copy(), cov_sys)




def jackknife_factors(blocks, fit: RigFit, pairs=()) -> dict:
    """A-posteriori variance factors (≥ 1) from a delete-one-instant jackknife: each instant's
    images (every camera's) left out in turn, the rig refitted from ``fit`` with its noise
    levels held; the spread of the answers (jackknife covariance C_J) against the fit's own
    covariance C gives trace(C⁻¹ C_J) / 6 per camera and per pair (a, b) of ``pairs`` (their
    X_a⁻¹ X_b) and per board — what the corners' noise model misses (a detector's bias shared
    by an image's corners, …) widens the σ, never narrows them. Returns {("camera", c) |
    ("board", b) | ("pair", a, b): factor}, {} when fewer than 5 instants can be left out."""
    instants = np.unique(np.concatenate([b.instants for b in blocks]))
    answers = []
    for g in instants:
        sub = []
        for b in blocks:
            keep = np.flatnonzero(b.instants != g)
            if len(keep) < 3:
                break
            sub.append(dataclasses.replace(b, data=b.data.subset(keep), instants=b.instants[keep]))
        else:
            try:
                f = fit_rig(sub, fit.X_cameras, fit.X_boards, fit.intrinsics, fit.models,
                            [r.pixel_sigma for r in fit.blocks],
                            [r.pose_sigma for r in fit.blocks], estimate_noise=False,
                            robust=False, variance_factors=[b.variance_factor for b in blocks],
                            covariance=False, free_scale=any(k[0] == "scale" for k in fit.columns),
                            scales0=fit.scales, shared_robot_error=fit.robot_sigma is not None,
                            robot_sigma0=fit.robot_sigma)
            except ValueError:
                continue
            answers.append(f)
    G = len(answers)
    if G < 5:
        return {}
    out = {}

    def factor(values, C):
        d = np.array(values)
        d = d - d.mean(axis=0)
        C_J = (G - 1) / G * d.T @ d
        try:
            return max(1.0, float(np.trace(np.linalg.solve(C, C_J))) / 6.0)
        except np.linalg.LinAlgError:
            return 1.0

    for c in range(len(fit.X_cameras)):
        out[("camera", c)] = factor([tangent(f.X_cameras[c], fit.X_cameras[c]) for f in answers],
                                    fit.camera_covariance(c))
    for b in range(len(fit.X_boards)):
        out[("board", b)] = factor([tangent(f.X_boards[b], fit.X_boards[b]) for f in answers],
                                   fit.board_covariance(b))
    for a, b in pairs:
        X, C = fit.relative(a, b)
        out[("pair", a, b)] = factor([tangent(inverse(f.X_cameras[a]) @ f.X_cameras[b], X)
                                      for f in answers], C)
    return out


__all__ = ["BlockResult", "MOUNTS", "RigBlock", "RigFit", "fit_rig", "jackknife_factors",
           "pose_error_frame", "robot_side", "tangent"]

"""Which robot poses to record next: greedy D-optimal design on the hand-eye information.

Criterion. Each recorded pose k adds H_kᵀ H_k to the Fisher information of the pose-form
maximum-likelihood fit (``observability.information_matrix``; H_k is the whitened Jacobian of
its residual). With the target pose marginalized out, the hand-eye part of the information is
the Schur complement S (6×6, its inverse the Cramér–Rao bound of the hand-eye pose). The
planner picks, one at a time, the candidate pose that maximizes log det S after adding it
(D-optimal design), up to n poses:

- log det S is −2 × the log volume of the hand-eye confidence ellipsoid, i.e. (for Gaussian
  errors) the information the new measurements carry about the hand-eye pose, whatever the
  target pose;
- it does not depend on units or parametrization: rescaling radians vs metres, or expressing
  the error for X_CE instead of X_EC, adds a constant to log det S, so the choice is the same.
  The trace (A-optimality) or the largest eigenvalue (E-optimality) would mix radians with
  metres and change with the unit;
- it rewards most the directions that are least determined (adding information a along a
  direction with information λ gains log(1 + a/λ)), so it fills weak directions first;
- greedy is cheap: by the matrix determinant lemma, the gain of a candidate is
  log det(I + H P Hᵀ) − log det(I + H_F Q H_Fᵀ) with P the inverse joint information and Q the
  inverse target block (6×6 determinants), for all candidates at once.

Before any sample the joint information is singular; a weak prior (1 rad and 1 m standard
deviation on every component by default) keeps log det finite so the first picks are ranked
too. The information depends on the current estimates only through the rotation of the hand-eye
pose and the positions of camera and target, so a rough estimate (a drawing, a tape measure) is
enough to plan the first poses.

Frames and modes as in ``observability``: eye-in-hand X_CH = X_CE, X_FT = X_BT; eye-to-hand
X_CH = X_CB, X_FT = X_ET. Candidate and sample poses are always X_BE (end-effector in base).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..vision.camera_model import CameraIntrinsics, as_points, project_points
from .ml import _check_noise
from .observability import (COMPONENTS, check_mode, hand_eye_std, information_matrix,
                            reduced_coordinates, sample_jacobians)
from .se3 import inverse, make_transform, rotation_exp, rotation_log
from .validation import as_transform, as_transform_list, check_positive


#: Exchange passes over the chosen set at most (each pass tries every position once).
_MAX_EXCHANGE_PASSES = 20


@dataclass
class Plan:
    """Result of ``plan_next_poses``.

    Attributes:
        indices: the chosen candidates, in the order to record them.
        log_det_gain: increase of log det of the hand-eye information brought by each pick.
        rotation_std_deg: (n + 1, 3) predicted std of the hand-eye rotation about H's axes
            (deg) before any pick (row 0; inf where undetermined) and after each pick.
        translation_std: (n + 1, 3) the same for the translation along H's axes (m).
    """
    indices: list
    log_det_gain: list
    rotation_std_deg: np.ndarray
    translation_std: np.ndarray


def _visible_mask(candidates, visibility) -> np.ndarray:
    if visibility is None:
        return np.ones(len(candidates), bool)
    if callable(visibility):
        return np.array([bool(visibility(X)) for X in candidates], dtype=bool)
    try:
        mask = np.array(visibility, dtype=bool).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError("visibility: expected None, a callable X_BE -> bool or one boolean per "
                         "candidate") from None
    if len(mask) != len(candidates):
        raise ValueError(f"visibility: expected {len(candidates)} booleans (one per candidate), "
                         f"got {len(mask)}")
    return mask


def _fixed_names(fixed) -> tuple:
    if fixed is None:
        return ()
    if isinstance(fixed, str):
        fixed = [fixed]
    names = tuple(fixed)
    bad = [c for c in names if c not in COMPONENTS]
    if bad:
        raise ValueError(f"fixed: unknown component(s) {bad}; valid: {', '.join(COMPONENTS)}")
    return names


def plan_next_poses(candidates_X_BE, X_CH_estimate, X_FT_estimate, samples_X_BE=(),
                    rotation_sigma: float = 0.002, translation_sigma: float = 0.001,
                    n: int = 5, mode: str = "eye_in_hand", visibility=None,
                    noise_model: str = "so3", fixed=(), prior_rotation_std: float = 1.0,
                    prior_translation_std: float = 1.0, exchange: bool = True) -> Plan:
    """Greedy D-optimal choice of the next ``n`` poses among candidates (module docstring).

    Args:
        candidates_X_BE: candidate end-effector poses in the base (4×4 rigid), e.g. from
            ``sample_candidate_poses`` or a list of reachable poses.
        X_CH_estimate: current hand-eye estimate (X_CE eye-in-hand, X_CB eye-to-hand).
        X_FT_estimate: current target pose estimate (X_BT / X_ET); only its position matters.
        samples_X_BE: poses already recorded (may be empty).
        rotation_sigma, translation_sigma, noise_model: the camera pose noise (``ml``).
        n: number of poses to choose (1 ≤ n ≤ number of usable candidates).
        mode: "eye_in_hand" or "eye_to_hand".
        visibility: None, one boolean per candidate, or a callable X_BE → bool; candidates
            marked False are never chosen.
        fixed: names of hand-eye components held at known values (``observability.COMPONENTS``,
            e.g. ("tz",) for a SCARA): the criterion is then the information of the others.
        prior_rotation_std, prior_translation_std: the weak prior (rad, m) that ranks the first
            picks when the samples do not determine the poses yet.
        exchange: after the greedy picks, swap chosen poses for better candidates while the
            criterion grows (Fedorov exchange); the set is then listed in greedy order.

    Returns:
        ``Plan``.

    Raises:
        ValueError: naming the argument.
    """
    mode = check_mode(mode)
    _check_noise(noise_model, rotation_sigma, translation_sigma)
    cands = as_transform_list(candidates_X_BE, "candidates_X_BE", rigid=True)
    if not cands:
        raise ValueError("candidates_X_BE: no candidate poses")
    samples = as_transform_list(samples_X_BE, "samples_X_BE", rigid=True)
    X_CH = as_transform(X_CH_estimate, "X_CH_estimate")
    X_FT = as_transform(X_FT_estimate, "X_FT_estimate")
    fixed = _fixed_names(fixed)
    pr = check_positive(prior_rotation_std, "prior_rotation_std")
    pt = check_positive(prior_translation_std, "prior_translation_std")
    allowed = _visible_mask(cands, visibility)
    if isinstance(n, bool) or int(n) != n or n < 1:
        raise ValueError(f"n: expected an integer ≥ 1, got {n!r}")
    n = int(n)
    if n > allowed.sum():
        raise ValueError(f"n: asked for {n} poses but only {int(allowed.sum())} of "
                         f"{len(cands)} candidates are usable")

    T, names, _ = reduced_coordinates(X_CH, fixed)
    m = T.shape[1]
    k = m - 6
    prior = np.diag([pr ** -2 if c in ("rx", "ry", "rz", "roll", "pitch", "yaw") else pt ** -2
                     for c in names] + [pr ** -2] * 3 + [pt ** -2] * 3)
    I_data = information_matrix(samples, X_CH, X_FT, rotation_sigma, translation_sigma, mode,
                                noise_model)
    Lam = T.T @ I_data @ T + prior
    H_full = sample_jacobians(cands, X_CH, X_FT, rotation_sigma, translation_sigma, mode,
                              noise_model)  # (Nc, r, 12)
    G = H_full @ T  # the same in the reduced coordinates
    G_F = G[:, :, k:]
    eye = np.eye(G.shape[1])

    def gains(Lam):
        """log det gain of the hand-eye marginal for every candidate added to Lam."""
        P = np.linalg.inv(Lam)
        Q = np.linalg.inv(Lam[k:, k:])
        A = eye + G @ P @ np.transpose(G, (0, 2, 1))
        B = eye + G_F @ Q @ np.transpose(G_F, (0, 2, 1))
        return np.linalg.slogdet(A)[1] - np.linalg.slogdet(B)[1]

    def greedy(Lam, pool, count):
        picks = []
        pool = pool.copy()
        for _ in range(count):
            g = gains(Lam)
            g[~pool] = -np.inf
            best = int(np.argmax(g))
            picks.append((best, float(g[best])))
            pool[best] = False
            Lam = Lam + G[best].T @ G[best]
        return picks, Lam

    picks, Lam_end = greedy(Lam, allowed, n)
    chosen = [i for i, _ in picks]
    if exchange:
        # Fedorov exchange: swap a chosen pose for a better candidate while log det grows (each
        # swap strictly increases it, so this terminates; greedy alone is typically 1 unit of
        # log det short of it for 5 poses).
        for _ in range(_MAX_EXCHANGE_PASSES):
            swapped = False
            for pos in range(n):
                i = chosen[pos]
                Lam_minus = Lam_end - G[i].T @ G[i]
                g = gains(Lam_minus)
                pool = allowed.copy()
                pool[chosen] = False
                pool[i] = True
                g[~pool] = -np.inf
                best = int(np.argmax(g))
                if g[best] > g[i] + 1e-9:
                    chosen[pos] = best
                    Lam_end = Lam + np.einsum("cri,crj->ij", G[chosen], G[chosen])
                    swapped = True
            if not swapped:
                break
        # Record the chosen set in greedy order, so that stopping early loses the least.
        only = np.zeros(len(cands), bool)
        only[chosen] = True
        picks, _ = greedy(Lam, only, n)

    # Predicted stds from the data alone (no prior): inf where undetermined.
    I_full = I_data.copy()
    rot, trans = [], []
    r0, t0 = hand_eye_std(I_full, X_CH, fixed)
    rot.append(r0)
    trans.append(t0)
    for i, _ in picks:
        I_full = I_full + H_full[i].T @ H_full[i]
        r, t = hand_eye_std(I_full, X_CH, fixed)
        rot.append(r)
        trans.append(t)
    return Plan([i for i, _ in picks], [g for _, g in picks], np.array(rot), np.array(trans))


def suggest_next_poses(candidates_X_BE, X_CH_estimate, X_FT_estimate, samples_X_BE=(),
                       rotation_sigma: float = 0.002, translation_sigma: float = 0.001,
                       n: int = 5, mode: str = "eye_in_hand", visibility=None,
                       **kwargs) -> list:
    """Indices into ``candidates_X_BE`` of the next ``n`` poses to record, best first
    (``plan_next_poses``, which also predicts the standard deviations after each)."""
    return plan_next_poses(candidates_X_BE, X_CH_estimate, X_FT_estimate, samples_X_BE,
                           rotation_sigma, translation_sigma, n, mode, visibility,
                           **kwargs).indices


# ------------------------------------------------------------------------------ candidates
def _random_rotation_vectors(rng, n, max_angle):
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    # Uniform in the ball of rotation vectors of radius max_angle (angle density ∝ θ²).
    angle = max_angle * rng.uniform(size=n) ** (1.0 / 3.0)
    return axis * angle[:, None]


def _random_offsets(rng, n, radius):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    return d * (radius * rng.uniform(size=n) ** (1.0 / 3.0))[:, None]


def _rotation_between(a, b):
    """The smallest rotation taking unit vector a to unit vector b (None if opposite)."""
    c = np.cross(a, b)
    s, cos = np.linalg.norm(c), float(a @ b)
    if s < 1e-12:
        return np.eye(3) if cos > 0 else None
    return rotation_exp(c / s * math.atan2(s, cos))


def _aim(X_BE, X_EC, p_BT, d_C):
    """The pose turned about the camera centre so that the target point is seen in the camera
    direction d_C (unit, in C) — where it was seen from the centre pose."""
    X_BC = X_BE @ X_EC
    d = p_BT - X_BC[:3, 3]
    norm = np.linalg.norm(d)
    if norm < 1e-9:
        return None
    R = _rotation_between(X_BC[:3, :3] @ d_C, d / norm)
    if R is None:
        return None
    return make_transform(R @ X_BC[:3, :3], X_BC[:3, 3]) @ inverse(X_EC)


def sample_candidate_poses(X_BE_center, p_FT, n: int, max_angle_deg: float, max_distance: float,
                           rng, X_HC=None, intrinsics: CameraIntrinsics | None = None,
                           p_FQ=None, margin_px: float = 0.0, mode: str = "eye_in_hand",
                           max_attempts: int | None = None) -> np.ndarray:
    """Random end-effector poses around a pose, within stated limits, with the target in view.

    Pure geometry: whether the robot can reach a pose (joint limits, collisions) is the
    caller's to check (e.g. with inverse kinematics).

    Each candidate X_BE differs from ``X_BE_center`` by a rotation of at most ``max_angle_deg``
    and a flange displacement of at most ``max_distance``. Eye-in-hand with ``X_HC`` (= X_EC):
    after a random rotation and displacement the camera is turned about its own centre so that
    it sees the target point ``p_FT`` (= p_BT) in the same direction as from the centre pose
    (the target stays where it was in the image), so the candidates differ in viewpoint and
    roll — what the hand-eye information needs.
    With ``intrinsics``, a candidate is kept only when every target point ``p_FQ`` (default
    ``p_FT`` alone) projects in front of the camera, inside the image by ``margin_px``.

    Args:
        X_BE_center: the pose to sample around (4×4 rigid).
        p_FT: the target's position: in B (eye-in-hand, p_BT) or on the flange in E
            (eye-to-hand, p_ET); a 3-vector or a 4×4 pose (its translation is used).
        n: number of candidates (≥ 1).
        max_angle_deg: largest rotation from the centre pose (deg, in (0, 180]).
        max_distance: largest flange displacement (m, > 0).
        rng: a ``numpy.random.Generator``.
        X_HC: the camera in its holder (X_EC eye-in-hand, X_BC eye-to-hand); needed for aiming
            and for the visibility check.
        intrinsics: ``vision.camera_model.CameraIntrinsics`` for the visibility check.
        p_FQ: (N, 3) target points in F (B eye-in-hand, E eye-to-hand) that must be in view.
        margin_px: margin inside the image border (pixels, ≥ 0).
        mode: "eye_in_hand" or "eye_to_hand" (no aiming: the camera is fixed).
        max_attempts: random draws before giving up (default 200 n).

    Returns:
        (n, 4, 4) candidate poses X_BE.

    Raises:
        ValueError: naming the argument; or when fewer than n candidates satisfy the limits
            within ``max_attempts`` draws (the message says which test rejected them).
    """
    mode = check_mode(mode)
    X_c = as_transform(X_BE_center, "X_BE_center")
    p = np.asarray(p_FT, dtype=float)
    if p.shape == (4, 4):
        p = as_transform(p, "p_FT")[:3, 3]
    else:
        p = as_points(p, "p_FT", 3)[0] if p.size == 3 else as_points(p, "p_FT", 3)
        if p.ndim != 1:
            raise ValueError(f"p_FT: expected a 3-vector or a 4×4 pose, got shape {p.shape}")
    if isinstance(n, bool) or int(n) != n or n < 1:
        raise ValueError(f"n: expected an integer ≥ 1, got {n!r}")
    n = int(n)
    max_angle = math.radians(check_positive(max_angle_deg, "max_angle_deg"))
    if max_angle > math.pi:
        raise ValueError(f"max_angle_deg: must be ≤ 180, got {max_angle_deg!r}")
    max_distance = check_positive(max_distance, "max_distance")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
    X_HC = None if X_HC is None else as_transform(X_HC, "X_HC")
    if intrinsics is not None:
        if not isinstance(intrinsics, CameraIntrinsics):
            raise ValueError(f"intrinsics: expected a CameraIntrinsics, got "
                             f"{type(intrinsics).__name__}")
        if X_HC is None:
            raise ValueError("X_HC: needed with intrinsics (where the camera is)")
    points = p.reshape(1, 3) if p_FQ is None else as_points(p_FQ, "p_FQ", 3)
    margin = check_positive(margin_px, "margin_px", allow_zero=True)
    attempts = 200 * n if max_attempts is None else int(max_attempts)
    if attempts < n:
        raise ValueError(f"max_attempts: must be ≥ n = {n}, got {max_attempts!r}")

    if mode == "eye_in_hand" and X_HC is not None:
        X_BC0 = X_c @ X_HC
        d_C = X_BC0[:3, :3].T @ (p - X_BC0[:3, 3])
        if np.linalg.norm(d_C) < 1e-9:
            raise ValueError("p_FT: the target point is at the camera centre of the centre pose")
        d_C /= np.linalg.norm(d_C)
    out = []
    rejected = {"aim": 0, "angle": 0, "distance": 0, "view": 0}
    batch = 64
    drawn = 0
    while len(out) < n and drawn < attempts:
        m = min(batch, attempts - drawn)
        drawn += m
        rv = _random_rotation_vectors(rng, m, max_angle)
        dp = _random_offsets(rng, m, max_distance)
        for w, d in zip(rv, dp):
            X = make_transform(rotation_exp(w) @ X_c[:3, :3], X_c[:3, 3] + d)
            if mode == "eye_in_hand" and X_HC is not None:
                X = _aim(X, X_HC, p, d_C)
                if X is None:
                    rejected["aim"] += 1
                    continue
            if np.linalg.norm(rotation_log(X[:3, :3] @ X_c[:3, :3].T)) > max_angle + 1e-12:
                rejected["angle"] += 1
                continue
            if np.linalg.norm(X[:3, 3] - X_c[:3, 3]) > max_distance + 1e-12:
                rejected["distance"] += 1
                continue
            if intrinsics is not None:
                X_CF = inverse(X @ X_HC) if mode == "eye_in_hand" else inverse(X_HC) @ X
                p_CQ = points @ X_CF[:3, :3].T + X_CF[:3, 3]
                uv, front, _ = project_points(p_CQ, intrinsics)
                inside = front & (uv[:, 0] >= margin) & (uv[:, 1] >= margin) & \
                    (uv[:, 0] <= intrinsics.width - margin) & \
                    (uv[:, 1] <= intrinsics.height - margin)
                if not inside.all():
                    rejected["view"] += 1
                    continue
            out.append(X)
            if len(out) == n:
                break
    if len(out) < n:
        why = ", ".join(f"{v} by the {k} test" for k, v in rejected.items() if v)
        raise ValueError(f"sample_candidate_poses: only {len(out)} of {n} candidates found in "
                         f"{drawn} draws (rejected: {why or 'none'}); widen max_angle_deg / "
                         "max_distance, check that the target is in view at the centre pose, "
                         "or raise max_attempts")
    return np.array(out)

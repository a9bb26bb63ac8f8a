"""Helpers shared by the tests (data generators, error measures, filter constructors).

Data generators live in the library (``handeye_drake.estimation.synthetic``); these are thin
conveniences on top of it.
"""

import numpy as np

from handeye_drake.estimation.se3 import rotation_from_rpy
from handeye_drake.recorded.example import camera_pose
from handeye_drake.recorded.formats import pose_stream as _pose_stream

from handeye_drake.estimation.configs import ManifoldFilter, PaperFilter, TargetFilter
from handeye_drake.estimation.kalman import HandEyeKalmanFilter
from handeye_drake.estimation.manifold import HandEyeTargetFilter, ManifoldHandEyeFilter
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp, rotation_log
from handeye_drake.estimation.synthetic import pose_dataset, random_pose  # noqa: F401

simulate_poses = pose_dataset


def random_small_pose(rng, rotation_scale, translation_scale):
    """Rotation vector ~ N(0, rotation_scale²), translation ~ N(0, translation_scale²)."""
    return make_transform(rotation_exp(rng.normal(size=3) * rotation_scale),
                          rng.normal(size=3) * translation_scale)


def tangent_error(X_true, X_est):
    """δ with X_true = X_est ⊕ δ in the filters' convention: [log(R R̂ᵀ); t − t̂]."""
    return np.concatenate([rotation_log(X_true[:3, :3] @ X_est[:3, :3].T),
                           X_true[:3, 3] - X_est[:3, 3]])


def _split_P0(P0, n):
    """(initial_variances, full covariance or None) of a P0 given as scalar, diagonal or matrix."""
    if P0 is None:
        return None, None
    P0 = np.asarray(P0, dtype=float)
    if P0.ndim == 0:
        return [float(P0)] * n, None
    if P0.ndim == 1:
        return list(P0), None
    return None, P0


def manifold_filter(X_CE_init, P0=None, rotation_sigma=0.01, translation_sigma=0.01, **settings):
    """``ManifoldHandEyeFilter`` with rotation-vector noise ``rotation_sigma`` (rad)."""
    diag, full = _split_P0(P0, 6)
    if diag is not None:
        settings["initial_variances"] = diag
    config = ManifoldFilter(rotation_sigma=rotation_sigma, translation_sigma=translation_sigma,
                            **settings)
    return ManifoldHandEyeFilter(config, X_CE_init, X_CE_covariance=full)


def target_filter(X_CE_init, P0=None, rotation_sigma=0.01, translation_sigma=0.001,
                  X_BT_init=None, target_prior_cov=None, **settings):
    """``HandEyeTargetFilter`` with rotation-vector noise ``rotation_sigma`` (rad)."""
    diag, full = _split_P0(P0, 6)
    if diag is not None:
        settings["initial_variances"] = diag
    if target_prior_cov is not None:
        settings["target_prior_variances"] = list(np.diag(np.atleast_2d(target_prior_cov))
                                                  if np.ndim(target_prior_cov) == 2 else
                                                  np.broadcast_to(target_prior_cov, 6))
    config = TargetFilter(rotation_sigma=rotation_sigma, translation_sigma=translation_sigma,
                          **settings)
    return HandEyeTargetFilter(config, X_CE_init, X_BT_init=X_BT_init, X_CE_covariance=full)


def paper_filter(X_CE_init, P0=None, rotation_sigma=0.1, translation_sigma=0.1,
                 noise_covariance="diagonal", **settings):
    """``HandEyeKalmanFilter`` with coefficient noise ``rotation_sigma``."""
    diag, full = _split_P0(P0 if P0 is not None else 1.0, 12)
    if diag is not None:
        settings["initial_variances"] = diag
    return HandEyeKalmanFilter(PaperFilter(rotation_coefficient_sigma=rotation_sigma,
                                           translation_sigma=translation_sigma,
                                           noise_covariance=noise_covariance, **settings),
                               X_CE_init, covariance=full)


def motion_pairs(rng, X_CE, n, rotation_sigma_deg=3.6, translation_sigma=1.0):
    """Paper §8 robot motions and the exact camera motions A = X B X⁻¹."""
    pairs = []
    for _ in range(n):
        B = make_transform(rotation_exp(np.radians(rotation_sigma_deg) * rng.normal(size=3)),
                           translation_sigma * rng.normal(size=3))
        pairs.append((X_CE @ B @ inverse(X_CE), B))
    return pairs


def noisy(A, rng, rotation_sigma, translation_sigma):
    A = A.copy()
    A[:3, :3] += rotation_sigma * rng.normal(size=(3, 3))
    A[:3, 3] += translation_sigma * rng.normal(size=3)
    return A


# --------------------------------------------------------------------- recorded streams
def synthetic_streams(offset, seed=0, duration=12.0, noise_deg=0.1, noise_t=0.0005):
    """Robot at 50 Hz, camera at 15 Hz stamped ``offset`` s late, the example's motion."""
    rng = np.random.default_rng(seed)
    X_EC = make_transform(rotation_from_rpy(np.radians([10, -5, 30])), [0.02, 0.05, 0.1])
    X_BT = make_transform(np.eye(3), [0.55, 0.05, 0.0])
    t_r = np.arange(int(duration * 50) + 1) / 50.0
    t_c = 0.3 + np.arange(int((duration - 0.6) * 15)) / 15.0
    X_BE = [camera_pose(t) @ inverse(X_EC) for t in t_r]
    X_CT = [make_transform(rotation_exp(np.radians(noise_deg) * rng.normal(size=3)),
                           noise_t * rng.normal(size=3)) @ inverse(camera_pose(t)) @ X_BT
            for t in t_c]
    return (_pose_stream(X_BE, t_r, "robot"), _pose_stream(X_CT, t_c + offset, "camera"), X_EC)


def aligned_synthetic(n=120, seed=1, outliers=()):
    rng = np.random.default_rng(seed)
    X_EC = make_transform(rotation_from_rpy(np.radians([10, -5, 30])), [0.02, 0.05, 0.1])
    X_BT = make_transform(np.eye(3), [0.55, 0.05, 0.0])
    t = np.arange(n) / 6.0
    X_BE = np.array([camera_pose(s) @ inverse(X_EC) for s in t])
    X_CT = np.array([make_transform(rotation_exp(np.radians(0.1) * rng.normal(size=3)),
                                    0.0005 * rng.normal(size=3)) @ inverse(camera_pose(s)) @ X_BT
                     for s in t])
    for k in outliers:
        X_CT[k] = make_transform(rotation_exp(np.radians(8) * np.array([0.6, 0.0, 0.8])),
                                 [0.03, -0.02, 0.0]) @ X_CT[k]
    return X_BE, X_CT, X_EC



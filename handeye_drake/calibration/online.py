"""The recording replayed through the on-line filters (``calibrate --online``): how the paper's
linear Kalman filter and the manifold filter, started from the same two-motion classical
solution, converge towards the batch result — with their own σ and diagnostics, so a filter
that ends far from the batch result with a small σ is seen as such."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..estimation.configs import ManifoldFilter, PaperFilter
from ..estimation.kalman import HandEyeKalmanFilter
from ..estimation.manifold import ManifoldHandEyeFilter
from ..estimation.se3 import inverse, rotation_angle, rotation_log
from ..estimation.solvers import solve_ax_xb


@dataclass
class OnlineReplay:
    """The replay's outcome.

    Attributes:
        estimator: "paper" (``HandEyeKalmanFilter``) or "manifold" (``ManifoldHandEyeFilter``).
        X_H_init: the two-motion classical solution the filter starts from (X_EC or X_BC).
        init_pairs: sample indices of the two motions used for it.
        X_H: the filter's final estimate.
        times: (U,) camera time (s), or sample index, of each update.
        rotation_diff_deg, translation_diff: (U,) difference to the batch result after each
            update (deg; m).
        rotation_sigma, translation_sigma: the noise given to the filter (coefficient σ; m).
        skipped: motions the filter refused.
        step_deg: keyframe step of the replayed motions (0: every consecutive motion).
        rotation_std_deg, translation_std: the filter's final 1σ of X_H per axis (deg; m).
        diagnostics: the filter's reasons not to trust its estimate (empty: none).
    """
    estimator: str
    X_H_init: np.ndarray
    init_pairs: list
    X_H: np.ndarray
    times: np.ndarray
    rotation_diff_deg: np.ndarray
    translation_diff: np.ndarray
    rotation_sigma: float
    translation_sigma: float
    skipped: int
    step_deg: float
    rotation_std_deg: np.ndarray
    translation_std: np.ndarray
    diagnostics: list

    @property
    def label(self) -> str:
        return ESTIMATORS[self.estimator]

    def final_nees(self, X_H_batch) -> float:
        """Squared difference to the batch result in units of the filter's own σ (per-axis,
        summed over the 6 axes; ≈ 6 when the σ are right and the batch result is exact)."""
        if not len(self.times):
            return math.nan
        dR = rotation_log_between(X_H_batch, self.X_H)
        dt = self.X_H[:3, 3] - X_H_batch[:3, 3]
        z = np.concatenate([np.degrees(dR) / self.rotation_std_deg, dt / self.translation_std])
        return float(z @ z)


#: The filters replayed, by name.
ESTIMATORS = {"paper": "HandEyeKalmanFilter (paper, exact G2)",
              "manifold": "ManifoldHandEyeFilter"}
#: Prior of both filters around the two-motion start: 1° per rotation axis, 50 mm per
#: translation axis (two-motion starts on recordings are often tens of mm off).
PRIOR_STD = (math.radians(1.0), 0.05)


def rotation_log_between(X1, X2) -> np.ndarray:
    return rotation_log(X1[:3, :3].T @ X2[:3, :3])


def rotation_diff_deg(X1, X2) -> float:
    return math.degrees(rotation_angle(X1[:3, :3].T @ X2[:3, :3]))


def translation_diff(X1, X2) -> float:
    return float(np.linalg.norm(X1[:3, 3] - X2[:3, 3]))


def keyframe_motions(X_R, X_CT, usable, step_deg: float, start: int = 0):
    """Motions between keyframes in time order: from the current keyframe to the first later
    usable sample whose robot rotation from it reaches ``step_deg`` (every consecutive motion
    when 0). Yields (i, j, A, B)."""
    step = math.radians(step_deg)
    key = start
    while key < len(X_R) and not usable[key]:
        key += 1
    for k in range(key + 1, len(X_R)):
        if not usable[k]:
            continue
        B = inverse(X_R[key]) @ X_R[k]
        if rotation_angle(B[:3, :3]) < step:
            continue
        yield key, k, X_CT[key] @ inverse(X_CT[k]), B
        key = k


def replay(result, step_deg: float = 10.0, min_rotation_deg: float = 5.0,
           estimator: str = "paper") -> OnlineReplay:
    """Replays the inlying samples through an on-line filter, as the paper runs it: started
    from the classical solution of the first two keyframe motions that determine X, with the
    noise of the batch fit and the prior ``PRIOR_STD``.

    Args:
        result: a ``CalibrationResult``.
        step_deg: feed the motion between keyframes rotating ≥ step_deg apart (0: every one).
        min_rotation_deg: smallest rotation of the two start motions.
        estimator: "paper" (``HandEyeKalmanFilter``, exact G2) or "manifold"
            (``ManifoldHandEyeFilter``).
    """
    if not (isinstance(step_deg, (int, float)) and 0 <= step_deg <= 90):
        raise ValueError(f"online_step_deg: must be a number in [0, 90], got {step_deg!r}")
    if estimator not in ESTIMATORS:
        raise ValueError(f"estimator: expected one of {sorted(ESTIMATORS)}, got {estimator!r}")
    X_R, X_CT = np.asarray(result.aligned.X_BE), np.asarray(result.aligned.X_CT)
    usable = result.sample_used != "outlier"
    batch = result.fit.X_H
    first = second = None
    errors = []
    for i, j, A, B in keyframe_motions(X_R, X_CT, usable, max(step_deg, min_rotation_deg)):
        if first is None:
            first = (i, j, A, B)
            continue
        try:
            X_CE_init = solve_ax_xb([first[2], A], [first[3], B], "daniilidis")
        except ValueError as e:
            errors.append(str(e))
            continue
        second = (i, j, A, B)
        break
    if second is None:
        raise ValueError("on-line replay: the recording has no two motions rotating ≥ "
                         f"{max(step_deg, min_rotation_deg):g}° about non-parallel axes to "
                         "initialize the filter" + (f" ({errors[-1]})" if errors else ""))
    # The noise of a motion between two poses with the batch fit's pose noise: the paper's
    # coefficient noise (a rotation vector of σ has entries of σ·√(2/3)), and the translation
    # with the lever arm of the camera rotation noise at the target distance d.
    d = float(np.median(np.linalg.norm(X_CT[:, :3, 3], axis=1)))
    sr, st_pose = result.fit.rotation_sigma, result.fit.translation_sigma
    r_prior, t_prior = PRIOR_STD
    if estimator == "paper":
        coefficient = math.sqrt(2.0 * 4.0 / 3.0) * sr
        st = math.sqrt(2.0 * st_pose**2 + 4.0 / 3.0 * sr**2 * d**2)
        f = HandEyeKalmanFilter(
            PaperFilter(noise_covariance="exact", rotation_coefficient_sigma=coefficient,
                        translation_sigma=st,
                        initial_variances=[r_prior**2] * 9 + [t_prior**2] * 3), X_CE_init)
    else:
        st = math.sqrt(2.0 * st_pose**2 + 2.0 * sr**2 * d**2)
        f = ManifoldHandEyeFilter(
            ManifoldFilter(rotation_sigma=math.sqrt(2.0) * sr, translation_sigma=st,
                           initial_variances=[r_prior**2] * 3 + [t_prior**2] * 3,
                           gate_probability=None), X_CE_init)
    times, rot, trans = [], [], []
    skipped = 0
    camera_times = result.aligned.camera_times
    for i, j, A, B in keyframe_motions(X_R, X_CT, usable, step_deg, start=second[1]):
        try:
            fused = f.update_motion(A, B)
        except ValueError:
            fused = False
        if not fused:
            skipped += 1
            continue
        times.append(camera_times[j] if camera_times is not None else float(j))
        rot.append(rotation_diff_deg(f.X_EC, batch))
        trans.append(translation_diff(f.X_EC, batch))
    return OnlineReplay(estimator, inverse(X_CE_init), [list(first[:2]), list(second[:2])],
                        f.X_EC, np.array(times), np.array(rot), np.array(trans), sr, st,
                        skipped, float(step_deg), np.asarray(f.X_EC_rotation_std_deg),
                        np.asarray(f.X_EC_translation_std), list(f.diagnostics()))



"""Motion pairs from aligned samples: formation, outlier rejection, fit and hold-out validation.

Pairs. From M aligned samples (X_BE[k], X_CT[k]), a pair (i, j), i < j, gives the camera motion
A = X_{CiCj} = X_CT[i] X_CT[j]⁻¹ and the robot motion B = X_{EiEj} = X_BE[i]⁻¹ X_BE[j], with
A X_CE = X_CE B. Two kinds of pairs are formed:

- consecutive pairs (k, k+1): the small motions of the recording (what the on-line filter eats);
  with more than ``MAX_CONSECUTIVE_PAIRS`` + 1 samples, only ``MAX_CONSECUTIVE_PAIRS`` of them,
  starting at evenly spaced samples (a long high-rate recording's consecutive motions are tiny,
  below ``min_rotation_deg``, and tens of thousands of them already pin down the noise level of
  the screw-angle test; all of them would cost memory and time linear in the recording);
- wide pairs: a matching of the samples (each sample in at most one wide pair, so wide pairs have
  independent noise) chosen greedily by decreasing robot rotation angle, capped at
  ``max_pair_angle_deg`` (90° by default: larger motions bring no more information and approach
  the 180° singularities of the quaternion-based methods). When there are more than
  ``MAX_WIDE_SAMPLES`` samples, only a uniform subset of them enters the matching.

Classical methods use only the pairs rotating at least ``min_rotation_deg`` on both sides: the
rotation axis of a small motion is dominated by noise. The others are reported as unusable.

Outliers. (1) Screw-angle test: the rotation angles of A and B are equal (they are conjugate), so
a pair with |θ_A − θ_B| > max(5 σ̂, 0.01°) is rejected, σ̂ = 1.4826 · MAD of θ_A − θ_B over all
pairs. (2) Consensus refit (RANSAC-like, deterministic): solve on the usable pairs passing (1),
compute every pair's residual of AX = XB (rotation angle of (A X)(X B)⁻¹ in degrees and
‖t(A X) − t(X B)‖ in length units), reject pairs above 3 × the median residual of the current
inliers, re-solve, until the inlier set no longer changes. A camera sample all of whose pairs are
rejected is reported as an outlying camera pose (samples in no pair, beyond the caps above, are
not examined).

Data that no X can explain are refused rather than trimmed down: rotation angles of A and B that
disagree in the median (> max(1°, 20 %) of the motion: streams out of sync or not the same
recording), more than half of the pairs failing (1), or (2) keeping less than half of the usable
pairs (``InconsistentMotions``; the error then says whether inverting the camera or the robot
poses would fit, the usual convention mix-ups).

Hold-out. A seeded random ``holdout_fraction`` of the usable inlier pairs is set aside; X is
solved on the rest and its residuals on the held-out pairs are reported. A held-out wide pair
shares no sample with another wide pair, but may with a consecutive pair (those are fitted only
when they rotate ≥ ``min_rotation_deg``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from .se3 import inverse
from .solvers import METHODS, solve_ax_xb
from .validation import MAX_MAGNITUDE
from .consistency import inverse_stack


def invert_poses(X) -> np.ndarray:
    """Inverses of a stack of rigid transforms (N, 4, 4) (uses Rᵀ: rigid input only); huge
    translations give inf, refused later."""
    with np.errstate(over="ignore", invalid="ignore"):
        return inverse_stack(np.asarray(X, dtype=float).reshape(-1, 4, 4))

MAX_WIDE_SAMPLES = 1500
#: Largest number of consecutive pairs formed (see the module docstring).
MAX_CONSECUTIVE_PAIRS = 20000
#: Below this many pairs the noise level of the screw-angle test (a MAD over the pairs) is too
#: uncertain to tell noise from outliers; failing it then says so.
MIN_PAIRS_FOR_OUTLIER_TEST = 10
#: Floors of the outlier thresholds, so noise-free data does not reject rounding errors.
ANGLE_TEST_FLOOR_DEG = 0.01
RESIDUAL_FLOOR_DEG = 1e-4
RESIDUAL_FLOOR_LENGTH = 1e-7


@dataclass(frozen=True)
class MotionPairs:
    """Motion pairs between aligned samples (see the module docstring).

    Attributes:
        index: (P, 2) sample indices (i, j), i < j.
        consecutive: (P,) True for (k, k+1) pairs, False for wide pairs.
        A: (P, 4, 4) camera motions X_{CiCj}; B: (P, 4, 4) robot motions X_{EiEj}.
        angle_A, angle_B: (P,) rotation angles (rad).
    """

    index: np.ndarray
    consecutive: np.ndarray
    A: np.ndarray
    B: np.ndarray
    angle_A: np.ndarray
    angle_B: np.ndarray

    def __len__(self) -> int:
        return len(self.index)


def _check_samples(X_BE, X_CT):
    X_BE = np.asarray(X_BE, dtype=float)
    X_CT = np.asarray(X_CT, dtype=float)
    if X_BE.ndim != 3 or X_BE.shape[1:] != (4, 4) or X_CT.shape != X_BE.shape:
        raise ValueError(f"X_BE, X_CT: expected two (M, 4, 4) arrays of the same length, got "
                         f"{X_BE.shape} and {X_CT.shape}")
    if not (np.all(np.isfinite(X_BE)) and np.all(np.isfinite(X_CT))):
        raise ValueError("X_BE, X_CT: contain NaN or infinite values")
    if max(_abs_max(X_BE), _abs_max(X_CT)) > MAX_MAGNITUDE:
        raise ValueError(f"X_BE, X_CT: entries beyond {MAX_MAGNITUDE:g}, products of poses would "
                         "overflow")
    return X_BE, X_CT


def _abs_max(X: np.ndarray) -> float:
    """max |X| without a temporary copy of X (recordings can hold 10⁶ poses)."""
    return max(float(X.max(initial=0.0)), -float(X.min(initial=0.0)))


def _motion_angles(M: np.ndarray) -> np.ndarray:
    return np.linalg.norm(Rotation.from_matrix(M[:, :3, :3]).as_rotvec(), axis=1)


def form_pairs(X_BE, X_CT, max_pair_angle_deg: float = 90.0,
               min_rotation_deg: float = 5.0) -> MotionPairs:
    """Consecutive pairs plus a greedy max-rotation matching of wide pairs (module docstring).

    Args:
        X_BE: (M, 4, 4) robot poses; X_CT: (M, 4, 4) camera poses at the same instants.
        max_pair_angle_deg: largest robot rotation of a wide pair.
        min_rotation_deg: wide pairs rotating less (robot side) are not formed.
    """
    X_BE, X_CT = _check_samples(X_BE, X_CT)
    M = len(X_BE)
    if M < 2:
        raise ValueError(f"need at least 2 aligned samples to form a motion, got {M}")
    starts = np.arange(M - 1)
    if M - 1 > MAX_CONSECUTIVE_PAIRS:
        starts = np.unique(np.linspace(0, M - 2, MAX_CONSECUTIVE_PAIRS).round().astype(int))
    cand = np.arange(M)
    if M > MAX_WIDE_SAMPLES:
        cand = np.unique(np.linspace(0, M - 1, MAX_WIDE_SAMPLES).round().astype(int))
    q = Rotation.from_matrix(X_BE[cand, :3, :3]).as_quat()
    angle = 2.0 * np.arccos(np.clip(np.abs(q @ q.T), 0.0, 1.0))
    iu, ju = np.triu_indices(len(cand), k=2)  # j ≥ i + 2 in candidate order
    a = angle[iu, ju]
    ok = (a <= math.radians(max_pair_angle_deg)) & (a >= math.radians(min_rotation_deg))
    iu, ju, a = iu[ok], ju[ok], a[ok]
    order = np.lexsort((ju, iu, -a))  # largest angle first; ties by index: deterministic
    used = [False] * len(cand)
    free = len(cand)
    wide = []
    for i, j in zip(iu[order].tolist(), ju[order].tolist()):  # Python ints: a fast loop
        if not (used[i] or used[j]):
            used[i] = used[j] = True
            wide.append((int(cand[i]), int(cand[j])))
            free -= 2
            if free < 2:
                break
    index = np.concatenate([np.c_[starts, starts + 1], np.array(wide, dtype=int).reshape(-1, 2)])
    consecutive = np.arange(len(index)) < len(starts)
    i, j = index[:, 0], index[:, 1]
    A = X_CT[i] @ invert_poses(X_CT[j])
    B = invert_poses(X_BE[i]) @ X_BE[j]
    return MotionPairs(index, consecutive, A, B, _motion_angles(A), _motion_angles(B))


def pair_residuals(A, B, X_CE) -> tuple[np.ndarray, np.ndarray]:
    """Residuals of A X = X B for stacks A, B (P, 4, 4): rotation angle of (A X)(X B)⁻¹ in degrees
    and ‖t(A X) − t(X B)‖ in length units."""
    A, B, X = np.asarray(A, float), np.asarray(B, float), np.asarray(X_CE, float)
    AX, XB = A @ X, X @ B
    R = AX[:, :3, :3] @ np.transpose(XB[:, :3, :3], (0, 2, 1))
    c = (np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0
    rot = np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))
    # arccos is imprecise near 0: use the rotation vector there.
    small = rot < 1.0
    if small.any():
        rot[small] = np.degrees(np.linalg.norm(Rotation.from_matrix(R[small]).as_rotvec(),
                                               axis=1))
    return rot, np.linalg.norm(AX[:, :3, 3] - XB[:, :3, 3], axis=1)


def _mad_scale(x: np.ndarray) -> float:
    return 1.4826 * float(np.median(np.abs(x - np.median(x)))) if len(x) else 0.0


def _solve(pairs: MotionPairs, mask: np.ndarray, method: str, what: str) -> np.ndarray:
    """solve_ax_xb on the masked pairs, with the failure explained in terms of the recording."""
    idx = np.flatnonzero(mask)
    if len(idx) < 2:
        raise ValueError(f"{what}: only {len(idx)} usable motion pair(s), at least 2 with "
                         "non-parallel rotation axes are needed")
    try:
        return solve_ax_xb(list(pairs.A[idx]), list(pairs.B[idx]), method)
    except ValueError as e:
        raise ValueError(f"{what}: {e}") from None
    except np.linalg.LinAlgError as e:  # the core should not raise this; keep it one line
        raise ValueError(f"{what}: linear algebra failure in {method} ({e})") from None


@dataclass(frozen=True)
class RobustFit:
    """Outcome of ``robust_hand_eye`` (all masks are over ``pairs``).

    Attributes:
        pairs: the formed motion pairs.
        usable: both rotations ≥ min_rotation_deg (classical methods can use the pair).
        screw_ok: passed the screw-angle test.
        inlier: passed both outlier tests.
        fit, held_out: usable inliers used to solve / set aside for validation.
        X_CE: the solution on ``fit`` (4×4).
        X_CE_all: the solution on all usable inliers (used for the residual test).
        angle_tolerance_deg: threshold of the screw-angle test.
        residual_tolerance: (deg, length) thresholds of the residual test.
        iterations: consensus refits performed.
        outlier_samples: sample indices all of whose pairs were rejected.
        holdout_note: why no pair was held out (empty when some were).
    """

    pairs: MotionPairs
    usable: np.ndarray
    screw_ok: np.ndarray
    inlier: np.ndarray
    fit: np.ndarray
    held_out: np.ndarray
    X_CE: np.ndarray
    X_CE_all: np.ndarray
    angle_tolerance_deg: float
    residual_tolerance: tuple
    iterations: int
    outlier_samples: np.ndarray
    holdout_note: str


class InconsistentMotions(ValueError):
    """No hand-eye transform fits the motions (wrong conventions, units or synchronization)."""


#: Convention mix-ups tried when the motions are inconsistent, to say which one fits.
_ALTERNATIVES = (
    ("camera", "the camera poses fit when inverted: the camera file holds X_TC (camera in "
               "target) — toggle --camera-pose-is-camera-in-target"),
    ("robot", "the robot poses fit when inverted: the robot file holds X_EB (base in "
              "end-effector, OpenCV's base2gripper) instead of X_BE — invert them"),
    ("both", "the robot and camera poses fit when both inverted: the robot file holds X_EB "
             "and the camera file X_TC"),
)


def robust_hand_eye(X_BE, X_CT, method: str = "daniilidis", min_rotation_deg: float = 5.0,
                    max_pair_angle_deg: float = 90.0, holdout_fraction: float = 0.2,
                    seed: int = 0, max_iterations: int = 20,
                    diagnose_conventions: bool = True) -> RobustFit:
    """Forms pairs, rejects outliers, solves with a classical ``method`` and holds out pairs.

    Args:
        X_BE, X_CT: (M, 4, 4) aligned robot and camera poses.
        method: a classical method of ``solvers.METHODS``.
        min_rotation_deg: smallest rotation (deg) of a pair usable by the classical method.
        max_pair_angle_deg: largest rotation of a wide pair.
        holdout_fraction: share of the usable inlier pairs set aside for validation, in [0, 0.5].
        seed: seeds the hold-out split.
        max_iterations: bound on the consensus refits.
        diagnose_conventions: when no hand-eye transform fits the motions, try the usual
            convention mix-ups (inverted camera and/or robot poses) and say which one fits.

    Note: inverting both streams (X_EB and X_TC) gives motions that are just as consistent (the
    same AX = XB problem for the target pose in the base), so that mix-up cannot be detected.

    Raises:
        ValueError: with the reason for degenerate data: too few samples or usable motions
            (pure translations), parallel rotation axes, camera and robot rotations that do not
            match (conventions, synchronization), or too many outliers;
            ``InconsistentMotions`` when no X fits the usable motions.
    """
    try:
        return _robust_hand_eye(X_BE, X_CT, method, min_rotation_deg, max_pair_angle_deg,
                                holdout_fraction, seed, max_iterations)
    except InconsistentMotions as e:
        if not diagnose_conventions:
            raise
        X_BE, X_CT = _check_samples(X_BE, X_CT)
        inv_BE = invert_poses(X_BE)
        inv_CT = invert_poses(X_CT)
        fitting = []
        for which, hint in _ALTERNATIVES:
            alt_BE = inv_BE if which in ("robot", "both") else X_BE
            alt_CT = inv_CT if which in ("camera", "both") else X_CT
            try:
                _robust_hand_eye(alt_BE, alt_CT, method, min_rotation_deg, max_pair_angle_deg,
                                 0.0, seed, max_iterations)
            except ValueError:
                continue
            fitting.append(hint)
        # Inverting both streams turns AX = XB into the same problem for the target pose, so a
        # single-stream mix-up also "fits" with the other stream inverted: list every candidate.
        hint = " — or ".join(fitting) if fitting else e.args[1]
        raise InconsistentMotions(f"{e.args[0]}; {hint}") from None


def _robust_hand_eye(X_BE, X_CT, method: str = "daniilidis", min_rotation_deg: float = 5.0,
                     max_pair_angle_deg: float = 90.0, holdout_fraction: float = 0.2,
                     seed: int = 0, max_iterations: int = 20) -> RobustFit:
    """The pipeline of ``robust_hand_eye`` (without the convention diagnosis)."""
    if method not in METHODS:
        raise ValueError(f"method: unknown hand-eye method {method!r}; valid methods are "
                         f"{', '.join(METHODS)}")
    for name, v, lo, hi in (("min_rotation_deg", min_rotation_deg, 0.0, 90.0),
                            ("max_pair_angle_deg", max_pair_angle_deg, 1.0, 179.0),
                            ("holdout_fraction", holdout_fraction, 0.0, 0.5)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and lo <= v <= hi):
            raise ValueError(f"{name}: must be a number in [{lo:g}, {hi:g}], got {v!r}")
    X_BE, X_CT = _check_samples(X_BE, X_CT)
    if len(X_BE) < 3:
        raise ValueError(f"too few samples: {len(X_BE)} aligned robot/camera samples, at least "
                         "3 (2 motions with non-parallel rotation axes) are needed")
    pairs = form_pairs(X_BE, X_CT, max_pair_angle_deg, min_rotation_deg)
    min_rot = math.radians(min_rotation_deg)
    usable = (pairs.angle_A >= min_rot) & (pairs.angle_B >= min_rot)
    max_B = float(np.degrees(pairs.angle_B.max()))
    if max_B < min_rotation_deg:
        raise ValueError(
            f"degenerate motion: the robot never rotates by {min_rotation_deg:g}° between two "
            f"samples (largest rotation {max_B:.3g}°) — a (near-)pure translation carries no "
            "rotation axis and the hand-eye rotation is unobservable; record motions rotating "
            "10–30° about different axes (or lower --min-rotation)")

    # (1) Screw-angle test on every pair.
    e = np.degrees(pairs.angle_A - pairs.angle_B)
    angle_tol = max(5.0 * _mad_scale(e), ANGLE_TEST_FLOOR_DEG)
    screw_ok = np.abs(e) <= angle_tol
    big = usable | (pairs.angle_B >= min_rot)
    med_e = float(np.median(np.abs(e[big]))) if big.any() else 0.0
    med_theta = float(np.degrees(np.median(pairs.angle_B[big]))) if big.any() else 0.0
    if big.any() and med_e > max(1.0, 0.2 * med_theta):
        raise ValueError(
            f"camera and robot motions do not match: the rotation angles of A (camera) and B "
            f"(robot) must be equal, but differ by {med_e:.3g}° in median for motions of "
            f"{med_theta:.3g}° — are the streams synchronized (--time-offset auto), in the "
            "right format/quaternion order (tum: qx qy qz qw), and from the same recording?")
    if screw_ok.sum() < 0.5 * len(pairs) and len(pairs) < MIN_PAIRS_FOR_OUTLIER_TEST:
        raise ValueError(
            f"too few samples to tell noise from outliers: {len(X_BE)} aligned samples give "
            f"{len(pairs)} motion pairs, and {int((~screw_ok).sum())} fail the screw-angle test "
            f"|θ_A − θ_B| ≤ {angle_tol:.3g}°, whose noise level is estimated from these same "
            f"pairs (θ_A − θ_B = {', '.join(f'{v:.3g}' for v in e)}°); record more samples "
            f"(≥ {MIN_PAIRS_FOR_OUTLIER_TEST} motion pairs) or check the poses")
    if screw_ok.sum() < 0.5 * len(pairs):
        raise ValueError(
            f"too many outliers: {int((~screw_ok).sum())} of {len(pairs)} motion pairs fail the "
            f"screw-angle test |θ_A − θ_B| ≤ {angle_tol:.3g}°")
    if not (usable & screw_ok).any() or (usable & screw_ok).sum() < 2:
        raise ValueError(
            f"too few motions: only {int((usable & screw_ok).sum())} motion pair(s) rotate by at "
            f"least {min_rotation_deg:g}° on both sides and pass the screw-angle test "
            f"({int(usable.sum())} before it; largest robot rotation {max_B:.3g}°); at least 2 "
            "with non-parallel rotation axes are needed — record larger rotations about "
            "different axes")

    # (2) Consensus refit on the residuals of AX = XB.
    inlier = screw_ok.copy()
    tol = (math.inf, math.inf)
    iterations = 0
    first_median = None
    for iterations in range(1, max_iterations + 1):
        X_all = _solve(pairs, inlier & usable, method, "hand-eye solution")
        rot, trans = pair_residuals(pairs.A, pairs.B, X_all)
        if first_median is None:
            first_median = float(np.median(rot[inlier])), float(np.median(trans[inlier]))
        tol = (max(3.0 * float(np.median(rot[inlier])), RESIDUAL_FLOOR_DEG),
               max(3.0 * float(np.median(trans[inlier])), RESIDUAL_FLOOR_LENGTH))
        new = screw_ok & (rot <= tol[0]) & (trans <= tol[1])
        kept, before = int((new & usable).sum()), int((screw_ok & usable).sum())
        if kept < max(2, 0.5 * before):
            # Consistent data lose a few pairs here; losing most means no X fits the motions.
            raise InconsistentMotions(
                f"inconsistent motions: no hand-eye transform fits them — the residual test "
                f"keeps only {kept} of {before} usable motion pairs (median residual of AX = XB "
                f"{first_median[0]:.3g}°, {first_median[1]:.3g} length units)",
                consistency_hint(pairs, screw_ok & usable))
        if np.array_equal(new, inlier):
            break
        inlier = new
    X_all = _solve(pairs, inlier & usable, method, "hand-eye solution")

    # Samples whose every pair was rejected: outlying camera poses.
    counts = np.zeros(len(X_BE), dtype=int)
    bad = np.zeros(len(X_BE), dtype=int)
    np.add.at(counts, pairs.index.reshape(-1), 1)
    np.add.at(bad, pairs.index[~inlier].reshape(-1), 1)
    outlier_samples = np.flatnonzero((counts > 0) & (bad == counts))

    # Hold-out split of the usable inliers.
    candidates = np.flatnonzero(inlier & usable)
    n_hold = int(round(holdout_fraction * len(candidates)))
    note = ""
    if n_hold == 0:
        note = "hold-out disabled" if holdout_fraction == 0 else \
            f"{len(candidates)} usable pairs are too few to hold {holdout_fraction:.0%} out"
    elif len(candidates) - n_hold < 3:
        note = f"only {len(candidates)} usable pairs: none held out (≥ 3 must remain to fit)"
        n_hold = 0
    rng = np.random.default_rng(seed)
    held = np.zeros(len(pairs), dtype=bool)
    held[np.sort(rng.permutation(candidates)[:n_hold])] = True
    fit = inlier & usable & ~held
    X_CE = _solve(pairs, fit, method, "hand-eye solution on the fitted pairs") if n_hold else X_all
    return RobustFit(pairs, usable, screw_ok, inlier, fit, held, X_CE, X_all, angle_tol, tol,
                     iterations, outlier_samples, note)


def consistency_hint(pairs: MotionPairs, mask: np.ndarray) -> str:
    """What usually makes camera and robot motions inconsistent, judged from the screw
    translations d = n·t along the rotation axes n, which A and B share (d_A = d_B)."""
    idx = np.flatnonzero(mask & (pairs.angle_A > 1e-6) & (pairs.angle_B > 1e-6))
    default = ("check the conventions: robot poses must be X_BE (end-effector in base), camera "
               "poses X_CT (target in camera; --camera-pose-is-camera-in-target for X_TC), and "
               "the streams synchronized")
    if len(idx) < 3:
        return default
    rv_A = Rotation.from_matrix(pairs.A[idx, :3, :3]).as_rotvec()
    rv_B = Rotation.from_matrix(pairs.B[idx, :3, :3]).as_rotvec()
    d_A = np.einsum("ki,ki->k", rv_A / pairs.angle_A[idx, None], pairs.A[idx, :3, 3])
    d_B = np.einsum("ki,ki->k", rv_B / pairs.angle_B[idx, None], pairs.B[idx, :3, 3])
    if np.median(np.abs(d_B)) > 0:
        ratio = float(np.median(np.abs(d_A)) / np.median(np.abs(d_B)))
        if not 1 / 3 < ratio < 3:
            return (f"the camera translations along the screw axes are {ratio:.3g}× the "
                    "robot's: do the two files use the same length unit?")
    return default


def residual_summary(rot_deg: np.ndarray, trans: np.ndarray) -> dict:
    """Median, RMS and max of rotation (deg) and translation (length) residuals."""
    if len(rot_deg) == 0:
        return {"count": 0}
    return {"count": int(len(rot_deg)),
            "rotation_deg": {"median": float(np.median(rot_deg)),
                             "rms": float(np.sqrt(np.mean(rot_deg ** 2))),
                             "max": float(np.max(rot_deg))},
            "translation": {"median": float(np.median(trans)),
                            "rms": float(np.sqrt(np.mean(trans ** 2))),
                            "max": float(np.max(trans))}}


def bootstrap_covariance(pairs: MotionPairs, fit: np.ndarray, X_CE: np.ndarray, method: str,
                         resamples: int = 50, seed: int = 0) -> tuple[np.ndarray, int]:
    """Bootstrap over the fitted pairs: 6×6 covariance of the error state [δθ (rad); δt] of X_EC,
    with R_EC,b = exp([δθ]×) R_EC (δθ about the end-effector axes) and t_EC,b = t_EC + δt for
    each resample's solution.

    Pairs are resampled with replacement (``resamples`` times, seeded); resamples the method
    cannot solve (e.g. all axes parallel) are skipped. Returns (covariance, resamples used).

    Raises:
        ValueError: fewer than 10 resamples could be solved.
    """
    idx = np.flatnonzero(fit)
    rng = np.random.default_rng(seed)
    X_EC = inverse(X_CE)
    deltas = []
    for _ in range(int(resamples)):
        pick = np.sort(rng.integers(0, len(idx), len(idx)))
        try:
            Xb = inverse(solve_ax_xb(list(pairs.A[idx[pick]]), list(pairs.B[idx[pick]]),
                                     method))
        except (ValueError, np.linalg.LinAlgError):
            continue
        dtheta = Rotation.from_matrix(Xb[:3, :3] @ X_EC[:3, :3].T).as_rotvec()
        deltas.append(np.concatenate([dtheta, Xb[:3, 3] - X_EC[:3, 3]]))
    if len(deltas) < 10:
        raise ValueError(f"standard deviations: only {len(deltas)} of {resamples} bootstrap "
                         f"resamples of the {len(idx)} fitted pairs could be solved; the motions "
                         "are too few or too degenerate for an uncertainty estimate")
    D = np.array(deltas)
    return D.T @ D / len(D), len(D)  # second moment about the estimate (includes any bias)

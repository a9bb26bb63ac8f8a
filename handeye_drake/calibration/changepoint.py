"""Something that should be fixed moved during the recording: the target was bumped, or the camera
shifted on its mount. The samples before and after the move each fit AX = ZB, together they do
not — a failure that no re-reading of the files explains, so it is looked for separately."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..estimation.se3 import rotation_angle
from ..estimation.solvers import calibrate_hand_eye
from ..estimation.consistency import implied_fixed_poses, mean_pose, pose_residuals

#: Fewest samples on each side of a move for each part to be fitted.
MIN_PART = 8
#: Samples per part used by the quick fits (spread over the part, ≥ 1° of rotation apart).
QUICK = 25
#: The parts must fit this much better than the whole in rotation or in translation (median
#: residuals), and not worse than ``NOT_WORSE`` times in the other (a small move shows in one).
BETTER_BY = 0.5
NOT_WORSE = 1.15
#: The fixed pose (or the hand-eye pose) of the two parts must differ by this many times the
#: uncertainty of a part's estimate (median residual / √(samples in the smaller part)).
MOVE_SIGMAS = 5.0


@dataclass
class Move:
    """A change point: the samples ``[0, index)`` and ``[index, M)`` each fit alone."""
    index: int
    what: str               # "target" or "camera"
    rotation_deg: float     # how far it moved
    translation: float      # m
    part_residuals: tuple   # (deg, m) medians of the two parts fitted separately
    whole_residuals: tuple  # (deg, m) medians of one fit of all samples

    def message(self, lines, hand: str) -> str:
        where = (f"between the camera samples of lines {lines[self.index - 1]} and "
                 f"{lines[self.index]}" if lines is not None else
                 f"between samples {self.index - 1} and {self.index}")
        thing = ("the target moved (it was bumped, or is not fixed)" if self.what == "target"
                 else f"the camera moved on its mount ({hand} changed)")
        return (f"{thing} {where}: each part fits alone (median residuals "
                f"{self.part_residuals[0]:.3g}° / {1000 * self.part_residuals[1]:.3g} mm, against "
                f"{self.whole_residuals[0]:.3g}° / {1000 * self.whole_residuals[1]:.3g} mm "
                f"together) and the two parts put it {self.rotation_deg:.3g}° / "
                f"{1000 * self.translation:.3g} mm apart — calibrate from one part (or re-record "
                "with everything fixed)")


def _diverse(X_R, usable) -> np.ndarray:
    """≤ QUICK usable sample indices spread over the part whose robot orientations are pairwise
    ≥ 1° apart (the classical solvers use every pair, and refuse near-pure translations)."""
    kept = []
    for k in np.unique(np.linspace(0, len(X_R) - 1, 4 * QUICK).round().astype(int)):
        if not usable[k]:
            continue
        R = X_R[k, :3, :3]
        if all(rotation_angle(X_R[j, :3, :3].T @ R) >= math.radians(1.0) for j in kept):
            kept.append(int(k))
            if len(kept) == QUICK:
                break
    return np.array(kept)


def _quick(X_R, X_CT):
    """(X_H, X_F, rotation residuals, translation residuals) of a Park fit on ≤ QUICK samples,
    refitted once without the samples beyond 3 median residuals (gross outliers); residuals over
    all given samples."""
    usable = np.ones(len(X_R), dtype=bool)
    for _ in range(2):
        idx = _diverse(X_R, usable)
        if len(idx) < 3:
            raise ValueError("too few distinct orientations")
        X_H = calibrate_hand_eye(list(X_R[idx]), list(X_CT[idx]), "park", min_angle=0.01)
        X_F = mean_pose(implied_fixed_poses(X_R[idx], X_CT[idx], X_H))
        deg, dist = pose_residuals(X_R, X_CT, X_H, X_F)
        usable = (deg <= 3 * np.median(deg)) & (dist <= 3 * np.median(dist))
    return X_H, X_F, deg, dist


def _normalized(X_R, X_CT, fit, parts) -> np.ndarray:
    """Each sample's residuals under one part's model, in units of the parts' median residuals."""
    deg, dist = pose_residuals(X_R, X_CT, fit[0], fit[1])
    return deg / max(parts[0], 1e-9) + dist / max(parts[1], 1e-12)


def find_move(X_R, X_CT) -> Move | None:
    """The most likely single move, or None when one fit of all samples is as good as two.

    X_R: (M, 4, 4) robot-side poses (X_BE eye-in-hand, X_EB eye-to-hand); X_CT: (M, 4, 4).
    """
    X_R, X_CT = np.asarray(X_R, dtype=float), np.asarray(X_CT, dtype=float)
    M = len(X_R)
    if M < 2 * MIN_PART:
        return None
    try:
        _, _, deg, dist = _quick(X_R, X_CT)
    except ValueError:
        return None
    whole = (float(np.median(deg)), float(np.median(dist)))

    def split(k):
        try:
            a, b = _quick(X_R[:k], X_CT[:k]), _quick(X_R[k:], X_CT[k:])
        except ValueError:
            return None
        d = np.concatenate([a[2], b[2]])
        m = np.concatenate([a[3], b[3]])
        score = float(np.median(d)) / max(whole[0], 1e-9) + float(np.median(m)) / max(whole[1],
                                                                                     1e-12)
        return score, (float(np.median(d)), float(np.median(m))), a, b

    grid = np.unique(np.linspace(MIN_PART, M - MIN_PART, 16).round().astype(int))
    tried = {k: split(int(k)) for k in grid}
    tried = {k: v for k, v in tried.items() if v is not None}
    if not tried:
        return None
    best = min(tried, key=lambda k: tried[k][0])
    step = int(grid[1] - grid[0]) if len(grid) > 1 else 1
    for k in range(max(MIN_PART, best - step), min(M - MIN_PART, best + step) + 1):
        if k not in tried:
            r = split(k)
            if r is not None:
                tried[k] = r
    best = min(tried, key=lambda k: tried[k][0])
    _, parts, a, b = tried[best]
    # The change point itself: where the samples stop fitting the first part's model better
    # than the second's (each sample's residuals, normalized, under both models).
    ra = _normalized(X_R, X_CT, a, parts)
    rb = _normalized(X_R, X_CT, b, parts)
    prefer_a = (ra < rb).astype(float)
    # k maximizing (#samples before k preferring a) + (#samples from k preferring b)
    gain = np.concatenate([[0.0], np.cumsum(prefer_a - (1.0 - prefer_a))])
    ks = np.arange(MIN_PART, M - MIN_PART + 1)
    k_star = int(ks[np.argmax(gain[ks])])
    if k_star != best:
        r = split(k_star)
        if r is not None:
            best = k_star
            _, parts, a, b = r
    ratios = (parts[0] / max(whole[0], 1e-9), parts[1] / max(whole[1], 1e-12))
    if not (min(ratios) <= BETTER_BY and max(ratios) <= NOT_WORSE):
        return None
    # Which fixed thing moved: the target pose X_F, or the hand-eye pose X_H.
    moves = {}
    for what, (Xa, Xb) in (("target", (a[1], b[1])), ("camera", (a[0], b[0]))):
        moves[what] = (math.degrees(rotation_angle(Xa[:3, :3].T @ Xb[:3, :3])),
                       float(np.linalg.norm(Xa[:3, 3] - Xb[:3, 3])))
    what = max(moves, key=lambda w: moves[w][0] / max(parts[0], 1e-9)
               + moves[w][1] / max(parts[1], 1e-12))
    r_deg, t = moves[what]
    scale = MOVE_SIGMAS / math.sqrt(min(best, M - best))
    if r_deg < scale * parts[0] and t < scale * parts[1]:
        return None
    return Move(int(best), what, r_deg, t, parts, whole)


__all__ = ["Move", "find_move"]

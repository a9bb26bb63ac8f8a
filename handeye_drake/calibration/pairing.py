"""Two wrong causes of image inputs read as others (issue 37): images paired with the robot
poses shifted by some (an image missing or extra at the start — read as a clock offset), and
intrinsics of another image resolution (read as ambiguous poses or unsynchronized streams).

Each is recognised by the reading that explains the data best:

- pairing: the rotation angle of every relative motion is the same seen by the camera and by
  the robot (whatever the hand-eye transform and the mode); with the samples paired in order,
  each pairing shift k is scored by the median |θ_camera − θ_robot| over motions of 1–3 steps,
  and a shift that makes them agree where the order given does not is named;
- resolution: a principal point far from the image centre, off by the same factor on both
  axes, is where an image of that many times the size has its centre.

Frames: robot poses X_BE, camera poses X_CT (only rotation angles of relative motions are used).
"""

from __future__ import annotations

import math

import numpy as np

from .checks import Reason

#: Shifts tried (samples).
MAX_SHIFT = 3
#: A shift is named when its angle mismatch is below this fraction of the order given's and
#: below ``SHIFT_MAX_DEG``.
SHIFT_BETTER = 0.25
SHIFT_MAX_DEG = 2.0
#: Principal points this far (as a factor of the centre's coordinates) and this alike on both
#: axes read as another resolution.
RESOLUTION_FACTOR = 1.2
RESOLUTION_AGREE = 0.08


def _angles(R0, R1) -> np.ndarray:
    c = (np.einsum("kij,kij->k", R0, R1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def shift_scores(X_BE, X_CT, max_shift: int = MAX_SHIFT) -> dict:
    """{k: median |θ_camera − θ_robot| (deg)} for camera sample i paired with robot pose i + k
    (k in ±max_shift, at least 5 pairs each)."""
    RB = np.asarray(X_BE, float)[:, :3, :3]
    RC = np.asarray(X_CT, float)[:, :3, :3]
    out = {}
    for k in range(-max_shift, max_shift + 1):
        i0, i1 = max(0, -k), min(len(RC), len(RB) - k)
        if i1 - i0 < 5:
            continue
        c, b = RC[i0:i1], RB[i0 + k:i1 + k]
        diffs = [np.abs(_angles(c[:-L], c[L:]) - _angles(b[:-L], b[L:]))
                 for L in (1, 2, 3) if L < len(c)]
        out[k] = float(np.median(np.concatenate(diffs)))
    return out


def pairing_shift(X_BE, X_CT) -> tuple[int, dict] | None:
    """(k, scores) when pairing camera sample i with robot pose i + k (k ≠ 0) makes the motions
    agree and the order given does not; else None."""
    scores = shift_scores(X_BE, X_CT)
    if 0 not in scores:
        return None
    k = min(scores, key=scores.get)
    if k != 0 and scores[k] <= SHIFT_BETTER * scores[0] and scores[k] <= SHIFT_MAX_DEG:
        return k, scores
    return None


def shift_message(k: int, scores: dict, images: bool) -> str:
    n = abs(k)
    one = "one" if n == 1 else str(n)
    sample = ("image" if images else "camera sample") + ("s" if n > 1 else "")
    pose = "robot pose" + ("s" if n > 1 else "")
    if k > 0:
        where = (f"camera sample i fits robot pose i + {n}: {one} {pose} more at the start "
                 f"(or {one} {sample} missing there)")
        fix = f"drop the first {pose}" if n == 1 else f"drop the first {n} {pose}"
    else:
        where = (f"camera sample i fits robot pose i − {n}: {one} {sample} more at the start "
                 f"(or {one} {pose} missing there)")
        fix = f"drop the first {sample}" if n == 1 else f"drop the first {n} {sample}"
    return (f"the {'images' if images else 'camera samples'} are paired with the robot poses "
            f"shifted by {one}: {where} — paired that way the motions' rotation angles agree "
            f"to {scores[k]:.3g}° in median instead of {scores[0]:.3g}° (they pair in order, "
            f"one each, not by time) — {fix}, or add the missing one, so that they pair in "
            "order")


def by_index(streams) -> bool:
    """The samples pair by order (image files, or pose files without timestamps)."""
    return not (streams.robot.has_timestamps and streams.camera.has_timestamps)


def resolution_hint(intrinsics, width: int | None = None, height: int | None = None) -> str:
    """A sentence when the intrinsics' principal point is where another resolution's image has
    its centre (the same factor on both axes, beyond ``RESOLUTION_FACTOR``); else ""."""
    if intrinsics is None:
        return ""
    w = width or intrinsics.width
    h = height or intrinsics.height
    sx = (intrinsics.u0 + 0.5) / (w / 2.0)
    sy = (intrinsics.v0 + 0.5) / (h / 2.0)
    if sx <= 0 or sy <= 0 or abs(sx / sy - 1.0) > RESOLUTION_AGREE:
        return ""
    s = math.sqrt(sx * sy)
    if abs(math.log(s)) < math.log(RESOLUTION_FACTOR):
        return ""
    # Resolutions differ by simple ratios (2, 3/2, 4/3, ...): the nearest within 3 %.
    from fractions import Fraction
    nice = Fraction(s).limit_denominator(4)
    if nice > 0 and abs(float(nice) / s - 1.0) < 0.03:
        s = float(nice)
    return (f"intrinsics of another image resolution: their principal point "
            f"({intrinsics.u0:.1f}, {intrinsics.v0:.1f}) is the centre of a "
            f"{round(w * s)}×{round(h * s)} image, not of these {w}×{h} ones — scale fx, fy, "
            f"cx, cy by {1 / s:.4g} (or calibrate the camera at this resolution)")


def check_pairing(result, streams) -> None:
    """A FAIL reason in ``result.verdict`` when a shifted pairing explains a failed verdict of
    samples paired by order (its consequences dropped)."""
    if result.verdict.status != "FAIL" or not by_index(streams):
        return
    found = pairing_shift(streams.robot.poses, streams.camera.poses)
    if found is None:
        return
    images = bool(streams.detections or streams.images)
    reason = Reason("FAIL", "pairing_shift", shift_message(*found, images))
    keep = [r for r in result.verdict.reasons if r.code not in CONSEQUENCES]
    result.verdict = type(result.verdict)("FAIL", [reason] + keep)


def check_resolution(result, streams) -> None:
    """Intrinsics of another resolution, when the principal point says so: named in the
    verdict's intrinsics reason (or as one, a WARN at least: the answer rests on pixels measured
    with them)."""
    if not (streams.detections or streams.images) or streams.intrinsics_source != "given":
        return
    hint = resolution_hint(streams.intrinsics)
    if not hint:
        return
    reasons = list(result.verdict.reasons)
    for i, r in enumerate(reasons):
        if r.code == "intrinsics":
            reasons[i] = Reason(r.level, r.code, f"{hint}; {r.message}")
            break
    else:
        level = "FAIL" if result.verdict.status == "FAIL" else "WARN"
        reasons = [Reason(level, "intrinsics", hint)] + [
            r for r in reasons if r.code not in CONSEQUENCES]
    status = "FAIL" if any(r.level == "FAIL" for r in reasons) else "WARN"
    result.verdict = type(result.verdict)(status, reasons)


#: What a shifted pairing causes.
CONSEQUENCES = ("residuals", "sigma", "held_out", "outliers", "time_offset", "pixel_residuals",
                "image_outliers", "intrinsics", "target_size", "camera_scale", "weak",
                "implausible_result", "swapped_streams", "robot_millimetres",
                "camera_millimetres", "other_mode", "clock_offset", "robot_quaternion_order",
                "camera_quaternion_order", "both_quaternion_order", "robot_inverted")


def explain_failure(error: ValueError, streams) -> ValueError:
    """A calibration that found no answer: its message replaced by the cause that explains it,
    when one does (a shifted pairing, intrinsics of another resolution); else ``error``."""
    if by_index(streams):
        found = pairing_shift(streams.robot.poses, streams.camera.poses)
        if found is not None:
            images = bool(streams.detections or streams.images)
            return ValueError(f"no hand-eye transform fits the samples as paired; likely "
                              f"cause: {shift_message(*found, images)} (as paired: {error})")
    if (streams.detections or streams.images) and streams.intrinsics_source == "given":
        hint = resolution_hint(streams.intrinsics)
        if hint:
            return ValueError(f"no hand-eye transform fits the camera poses; likely cause: "
                              f"{hint} (as given: {error})")
    return error


__all__ = ["check_pairing", "check_resolution", "explain_failure", "pairing_shift",
           "resolution_hint", "shift_scores"]

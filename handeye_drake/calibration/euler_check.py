"""Robot poses read as Euler angles (``--format csv-euler:ORDER:UNIT``): is the convention the
right one? Every order fits *some* rotation, so a wrong ORDER (or extrinsic for intrinsic, or the
unit) is not seen when the file is read; it is seen in the data: the robot motions then disagree
with the camera's. The other conventions are tried as alternatives of the verdict (the same quick
fit and the same "explains the data far better" rule as ``checks``); one that explains the data
FAILs the verdict and is named with the ``--format`` that reads it.

Frames as ``pipeline``: the robot stream holds X_BE (flange E in base B), the camera X_CT.
"""

from __future__ import annotations

import dataclasses
import itertools

from ..recorded.formats import EULER_FORMAT, read_poses
from . import checks
from .align import estimate_time_offset
from .naming import DEFAULT_MAX_HAND_EYE_DISTANCE

#: Every Tait-Bryan and proper Euler order, extrinsic (lowercase) and intrinsic (uppercase).
ORDERS = tuple("".join(p) for p in itertools.product("xyz", repeat=3)
               if p[0] != p[1] and p[1] != p[2])
ORDERS = ORDERS + tuple(o.upper() for o in ORDERS)


def _other_formats(fmt: str) -> list[str]:
    """The conventions a file read as ``fmt`` may have been written in, likeliest first: the
    same letters the other way (extrinsic ↔ intrinsic), the letters reversed, the other unit,
    then every other order."""
    _, order, unit = fmt.split(":")
    other_unit = "rad" if unit == "deg" else "deg"
    flipped = order.swapcase()
    first = [flipped, order[::-1], flipped[::-1]]
    out = [f"{EULER_FORMAT}:{o}:{unit}" for o in first + [o for o in ORDERS if o not in first]
           if o != order]
    return out + [f"{EULER_FORMAT}:{order}:{other_unit}"]


def _robot_as(streams, path, fmt: str, scale: float):
    """``streams.robot`` with the rotations of the robot file read as ``fmt`` (the same samples,
    matched by their line), or None when the file does not read that way."""
    try:
        other = read_poses(path, "robot", fmt, False, scale, None)
    except ValueError:
        return None
    row = {int(line): k for k, line in enumerate(other.lines)}
    try:
        idx = [row[int(line)] for line in streams.robot.lines]
    except KeyError:
        return None
    return dataclasses.replace(streams.robot, poses=other.poses[idx])


def _alternatives(streams, path, fmt, scale) -> list:
    """The other conventions as ``checks.Alternative``; each estimates its own clock offset when
    both streams are stamped (a wrong order also misleads the offset found from the angles)."""
    own_offset = streams.robot.has_timestamps and streams.camera.has_timestamps
    alts = []
    for alt in _other_formats(fmt):
        robot = _robot_as(streams, path, alt, scale)
        if robot is None:
            continue
        alts.append(checks.Alternative(
            "robot_euler_convention",
            f"the robot file's Euler angles are {alt.split(':', 1)[1]}, not "
            f"{fmt.split(':', 1)[1]} (lowercase: about the fixed axes, uppercase: about the "
            "turning axes)", f"--robot-format {alt}",
            lambda r, c, robot=robot: (robot, c, "auto_offset" if own_offset else None)))
    return alts


def _best(streams, path, fmt, scale, reading, max_noise, max_distance):
    """(the data as read, the alternatives tried, the best one that explains the data or None)."""
    tried = checks.try_alternatives(streams.robot, streams.camera, reading,
                                    _alternatives(streams, path, fmt, scale))
    better = checks.explaining(tried, *max_noise, max_distance)
    return tried[0], tried[1:], (better[0] if better else None)


def _euler(fmt) -> bool:
    return (fmt or "").startswith(EULER_FORMAT + ":")


def check_robot_euler(result, streams, path, fmt, scale: float) -> None:
    """Adds the Euler conventions tried to ``result.hypotheses`` and, when one explains the data
    far better than ``fmt`` (``checks.explaining``), a FAIL reason naming it to
    ``result.verdict`` (the residuals it causes are its consequence, not another reason).
    Nothing for other formats."""
    if not _euler(fmt) or path is None:
        return
    base, tried, best = _best(streams, path, fmt, scale, checks.reading_of(result),
                              result.settings["max_noise"],
                              result.settings["max_hand_eye_distance_m"])
    # The closest few are shown with the other alternatives (36 would bury them).
    shown = sorted(tried, key=lambda h: (h.rotation_deg, h.translation_m))[:3]
    result.hypotheses = list(result.hypotheses) + shown
    if best is None:
        return
    reasons = [r for r in result.verdict.reasons if r.code != "residuals"] + [checks.Reason(
        "FAIL", "robot_euler_convention",
        f"{best.description}: read that way the data fit with median residuals "
        f"{best.rotation_deg:.3g}° / {1000 * best.translation_m:.3g} mm instead of "
        f"{base.rotation_deg:.3g}° / {1000 * base.translation_m:.3g} mm — {best.fix}")]
    result.verdict = checks.Verdict("FAIL", reasons)


def explain_failure(error: ValueError, streams, path, fmt, scale: float,
                    settings: dict) -> ValueError:
    """A calibration that found no answer, its message replaced by the Euler convention that
    explains the robot file when there is one; else ``error`` unchanged."""
    if not _euler(fmt) or path is None:
        return error
    mode = settings.get("mode", "eye_in_hand")
    offset = settings.get("time_offset")
    if not isinstance(offset, (int, float)):
        offset = 0.0
        if streams.robot.has_timestamps and streams.camera.has_timestamps:
            side = streams.robot if mode == "eye_in_hand" else streams.robot.inverted()
            try:
                offset = estimate_time_offset(side, streams.camera,
                                              settings.get("time_offset_range", 0.5)).offset
            except ValueError:
                pass
    reading = checks.Reading(mode, float(offset), "given", settings.get("time_offset_range", 0.5),
                             ())
    distance = settings.get("max_hand_eye_distance") or DEFAULT_MAX_HAND_EYE_DISTANCE[mode]
    _, _, best = _best(streams, path, fmt, scale, reading, settings.get("max_noise", (1, 0.01)),
                       distance)
    if best is None:
        return error
    return ValueError(f"no hand-eye transform fits the data as read; likely cause: "
                      f"{best.description} — read that way the data fit with median residuals "
                      f"{best.rotation_deg:.3g}° / {1000 * best.translation_m:.3g} mm: {best.fix} "
                      f"(as read: {error})")


__all__ = ["check_robot_euler", "explain_failure"]

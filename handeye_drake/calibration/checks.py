"""The verdict of a calibration: is the result consistent with its data, and if not, why?

A result is reported as a success only when its residuals, in rotation and in translation, are
consistent with plausible measurement noise and with its own σ. Each check below adds a reason
(FAIL or WARN) that names what is wrong and what to do:

- residuals beyond plausible camera noise (``max_noise``): the data do not fit — then the usual
  mistakes are tried as alternatives, and the one that explains the data is named;
- held-out samples fitting worse than the fitted ones (F-test of their mean whitened residual²
  against the fit samples'): the fit does not generalize. Both are whitened by the same noise
  model, so a misestimated noise level (e.g. anisotropic noise summarized by one σ) cancels: the
  test fires when the held-out samples are worse, not when the σ are off;
- two independent halves of the data disagree beyond their σ (split-half NEES): the σ are too
  small — unmodelled effects (clock offset, robot kinematic errors, a target that moved);
- an implausible result (a camera farther from the flange than ``max_hand_eye_distance``);
- directions the motions do not determine (observability), too few samples, an offset on the
  search bound, too many outliers.

Alternatives (``default_alternatives``), each re-fitted quickly on a subset of the samples and
compared by their median pose residuals: quaternions written scalar-first (w x y z) in either
file, robot and camera streams swapped, the other mode (equivalently: robot poses X_EB given for
X_BE, or camera poses X_TC for X_CT), a file in millimetres, the camera's translations at
another scale (a target of another size) or only their depths (a focal length off: the one of
the two that leaves the smaller translation residuals is named), and a clock offset other than
the one forced. Two readings are not decided by those medians: swapped streams fit AX = ZB exactly
as well (the target's pose takes the hand-eye transform's place), so the stream that carries
the noise says which is the camera's (``swap_evidence``; without timestamps a tie is a WARN),
whatever the hand-eye distance; and the camera translations' scale is the maximum-likelihood
profile's (``pipeline.camera_scale_test``: > 5σ from 1 FAILs). Held ``--fix`` values are
tested against the fit that frees them (``pipeline.fixed_component_test``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import f as f_distribution

from ..estimation.solvers import calibrate_hand_eye
from .align import align_streams, estimate_time_offset
from ..estimation.consistency import (implied_fixed_poses, mean_pose, pose_residuals,
                                     rotation_from_swapped_quaternions, with_rotations,
                                     with_scaled_translations)
from ..recorded.formats import PoseStream
from .naming import DEFAULT_MAX_HAND_EYE_DISTANCE, hand_name

#: Samples used by the quick fit of each alternative (evenly spaced over the recording).
QUICK_SAMPLES = 40
#: An alternative explains the data when its median residuals are at most this fraction of the
#: data as read in rotation or in translation, and not worse (by more than ``NOT_WORSE``) in the
#: other. (Some mistakes leave one of the two unchanged: swapping the quaternion order of both
#: files conjugates every rotation alike, millimetres only scale translations.)
BETTER_BY = 0.5
NOT_WORSE = 1.15
#: A smaller improvement (at most this fraction) is still reported, as a WARN.
SOMEWHAT_BETTER = 0.8
#: More outlying samples than this fraction: WARN; than the second: FAIL.
OUTLIER_FRACTIONS = (0.1, 0.3)
#: The camera translations' scale (``pipeline.camera_scale_test``) this many σ from 1: FAIL;
#: beyond ``SCALE_WARN_SIGMA``: WARN.
SCALE_FAIL_SIGMA = 5.0
#: ... and off by more than this fraction (0.2 %: 1 mm at 0.5 m).
SCALE_MIN_ERROR = 0.002
#: The quick fits' scale search resolves the camera translation scale to about 1 %.
QUICK_SCALE_RESOLUTION = 0.01
SCALE_WARN_SIGMA = 3.0
#: Fewest samples for a calibration worth trusting (WARN below).
MIN_SAMPLES = 8


@dataclass
class Reason:
    level: str      # "FAIL" or "WARN"
    code: str
    message: str

    def to_dict(self) -> dict:
        return {"level": self.level, "code": self.code, "message": self.message}


@dataclass
class Verdict:
    status: str
    reasons: list = field(default_factory=list)

    def line(self) -> str:
        """``verdict: OK``, or ``verdict: FAIL (2 reasons)`` — the reasons follow it."""
        n = len(self.reasons)
        return f"verdict: {self.status}" + (f" ({n} reason{'s' * (n > 1)})" if n else "")

    def to_dict(self) -> dict:
        return {"status": self.status, "reasons": [r.to_dict() for r in self.reasons]}


@dataclass
class Alternative:
    """A way the data could have been read wrongly: ``apply(robot, camera)`` returns the streams
    as they would be if the mistake were undone (and the mode to fit them in)."""
    code: str
    description: str
    fix: str
    apply: object


@dataclass
class Hypothesis:
    """An alternative, fitted: its median residuals (deg, m) and hand-eye translation norm."""
    code: str
    description: str
    fix: str
    rotation_deg: float
    translation_m: float
    hand_eye_distance: float
    error: str = ""
    mode: str = ""  # the mode it was fitted in ("" = the mode of the data as read)
    evidence: dict | None = None  # swapped_streams: ``swap_evidence``

    def to_dict(self) -> dict:
        d = {k: getattr(self, k) for k in ("code", "description", "fix", "rotation_deg",
                                           "translation_m", "hand_eye_distance", "error")}
        if self.evidence is not None:
            d["evidence"] = self.evidence
        return d


def _quick_fit(robot: PoseStream, camera: PoseStream, mode: str, offset: float):
    """Median pose residuals (deg, m) and |t| of a classical fit on a subset of the samples."""
    robot_side = robot if mode == "eye_in_hand" else robot.inverted()
    aligned = align_streams(robot_side, camera, offset)
    X_R, X_CT = np.asarray(aligned.X_BE), np.asarray(aligned.X_CT)
    idx = np.unique(np.linspace(0, len(X_R) - 1, min(QUICK_SAMPLES, len(X_R))).round().astype(int))
    X_R, X_CT = X_R[idx], X_CT[idx]
    X_H = calibrate_hand_eye(list(X_R), list(X_CT), "park", min_angle=0.01)
    X_F = mean_pose(implied_fixed_poses(X_R, X_CT, X_H))
    deg, dist = pose_residuals(X_R, X_CT, X_H, X_F)
    return float(np.median(deg)), float(np.median(dist)), float(np.linalg.norm(X_H[:3, 3]))


def _stream(poses: np.ndarray, like: PoseStream) -> PoseStream:
    return dataclasses.replace(like, poses=poses)


@dataclass
class Reading:
    """How the streams were read and fitted: what the alternatives are compared with."""
    mode: str
    time_offset: float
    time_offset_mode: str
    time_offset_range: float
    quaternion_streams: tuple
    warnings: list = field(default_factory=list)
    camera_from_images: bool = False  # detections in images: the files cannot be swapped


def reading_of(result) -> Reading:
    return Reading(result.mode, result.aligned.time_offset, result.time_offset_mode,
                   result.settings["time_offset_range_s"], result.settings["quaternion_streams"],
                   result.warnings, bool(result.settings.get("camera_from_images")))


def default_alternatives(robot: PoseStream, camera: PoseStream, reading: Reading
                         ) -> list[Alternative]:
    """The usual mistakes (see the module docstring) that apply to these streams."""
    other = "eye_to_hand" if reading.mode == "eye_in_hand" else "eye_in_hand"
    alts = []
    quaternions = reading.quaternion_streams
    for which in ("robot", "camera"):
        if which not in quaternions:
            continue
        alts.append(Alternative(
            f"{which}_quaternion_order",
            f"the {which} file's quaternions are scalar-first (w x y z), not TUM's x y z w",
            f"--{which}-quaternion-order wxyz",
            lambda r, c, w=which: (
                _stream(with_rotations(r.poses, rotation_from_swapped_quaternions(
                    r.poses[:, :3, :3])), r) if w == "robot" else r,
                _stream(with_rotations(c.poses, rotation_from_swapped_quaternions(
                    c.poses[:, :3, :3])), c) if w == "camera" else c, None)))
    if len(quaternions) == 2:
        alts.append(Alternative(
            "both_quaternion_order", "both files' quaternions are scalar-first (w x y z)",
            "--robot-quaternion-order wxyz --camera-quaternion-order wxyz",
            lambda r, c: (_stream(with_rotations(r.poses, rotation_from_swapped_quaternions(
                r.poses[:, :3, :3])), r), _stream(with_rotations(
                    c.poses, rotation_from_swapped_quaternions(c.poses[:, :3, :3])), c), None)))
    if not reading.camera_from_images:
        alts.append(Alternative(
            "swapped_streams", "the robot and camera files are swapped",
            "swap --robot and --camera",
            lambda r, c: (c, r, "auto_offset" if r.has_timestamps and c.has_timestamps
                          else None)))
    alts.append(Alternative(
        "other_mode",
        f"the data fit {other.replace('_', '-')}: the camera is "
        + ("fixed in the cell (target on the flange)" if other == "eye_to_hand" else
           "on the flange") + ", or the robot poses are inverted (X_EB given for X_BE), or the "
        "camera poses are (X_TC given for X_CT)",
        f"--mode {other.replace('_', '-')} if that is the set-up, else invert the camera stream "
        "(add or drop --camera-pose-is-camera-in-target)", lambda r, c: (r, c, other)))
    if reading.mode == "eye_to_hand":
        # Eye-in-hand data with inverted robot poses fit the other mode with a plausible
        # distance; eye-to-hand ones fit eye-in-hand with the camera's distance from the base as
        # "hand-eye" distance, which that mode's limit rejects: the inversion is tried as such.
        alts.append(Alternative(
            "robot_inverted", "the robot poses are inverted (X_EB, the base in the end-effector "
            "frame, given for X_BE)", "invert the robot poses: the file must hold X_BE "
            "(end-effector in base)", lambda r, c: (r.inverted(), c, None)))
    for which in ("robot", "camera"):
        alts.append(Alternative(
            f"{which}_millimetres", f"the {which} file's translations are in millimetres",
            f"--{which}-translation-scale 0.001",
            lambda r, c, w=which: (
                _stream(with_scaled_translations(r.poses, 1e-3), r) if w == "robot" else r,
                _stream(with_scaled_translations(c.poses, 1e-3), c) if w == "camera" else c,
                None)))
    alts.append(_camera_scale_alternative(reading))
    alts.append(_camera_focal_alternative(reading))
    if (reading.time_offset_mode == "given" or "same timestamps" in reading.time_offset_mode) \
            and robot.has_timestamps and camera.has_timestamps:
        alts.append(Alternative(
            "clock_offset", "the clock offset given does not fit the data",
            "--time-offset auto", lambda r, c: (r, c, "auto_offset")))
    return alts


#: Range of the camera translation scale searched by the scale alternative.
SCALE_RANGE = (0.5, 2.0)


def _camera_scale_alternative(reading: Reading) -> Alternative:
    """The camera's translations off by a factor: a wrong target size (the square or marker size
    given to the detector or to --target) or a target printed at another scale — rotations fit,
    translations do not. ``apply`` searches the factor (golden section on log s, the median
    translation residual of the quick fit) and words the alternative with it."""
    alt = Alternative("camera_scale", "", "", None)

    def apply(r, c):
        # bracket 0.69 · 0.618¹⁴ ≈ 1e-3 in log s
        factor = _best_factor(reading, r, c, with_scaled_translations, SCALE_RANGE, 14)
        if abs(factor - 1.0) <= QUICK_SCALE_RESOLUTION:
            # The best scale is the one given, to what the quick fit on a subset resolves
            # (the profile of ``pipeline.camera_scale_test`` measures small scales): not a
            # reading to offer (a 1.003× "wrong size" was a false WARN).
            raise ValueError(f"the best camera translation scale is {factor:.4g}: as given")
        alt.description = (f"the camera's translations are {1 / factor:.4g}× their true size: a "
                           "wrong target size (the square or marker size given to the detector "
                           "or to --target) or a target printed at another scale")
        alt.fix = (f"multiply the target's sizes by {factor:.4g} (or "
                   f"--camera-translation-scale {factor:.4g} for pose files)")
        return r, _stream(with_scaled_translations(c.poses, factor), c), None

    alt.apply = apply
    return alt


def _best_factor(reading: Reading, r, c, transform, bounds, iterations: int) -> float:
    """The factor in ``bounds`` for which ``transform(camera poses, factor)`` fits the robot's
    best (the quick fit's median translation residual; golden section on log factor)."""
    def cost(log_s):
        scaled = _stream(transform(c.poses, math.exp(log_s)), c)
        return _quick_fit(r, scaled, reading.mode, reading.time_offset)[1]
    return _golden_log(cost, *bounds, iterations=iterations)


def _golden_log(cost, lo: float, hi: float, iterations: int = 14) -> float:
    """The factor in [lo, hi] minimizing ``cost(log factor)`` (golden section on log)."""
    a, b = math.log(lo), math.log(hi)
    g = (math.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = b - g * (b - a), a + g * (b - a)
    f1, f2 = cost(x1), cost(x2)
    for _ in range(iterations):
        if f1 < f2:
            b, x2, f2 = x2, x1, f1
            x1 = b - g * (b - a)
            f1 = cost(x1)
        else:
            a, x1, f1 = x1, x2, f2
            x2 = a + g * (b - a)
            f2 = cost(x2)
    return math.exp(0.5 * (a + b))


def _with_scaled_depths(X_CT: np.ndarray, factor: float) -> np.ndarray:
    out = np.array(X_CT, dtype=float, copy=True)
    out[:, 2, 3] *= factor
    return out


#: Range of the focal factor searched by the focal alternative.
FOCAL_RANGE = (0.8, 1.25)


def _camera_focal_alternative(reading: Reading) -> Alternative:
    """The focal length of the intrinsics that measured the camera poses off by a factor k: a
    target's pose from its image then has its depth (z of X_CT, along the optical axis) k× the
    true one and its lateral offsets unchanged (u − cx = fx X / Z), where a target of another
    size scales all three alike — and only a focal error moves the rotations (a tilted target's
    foreshortening). ``apply`` searches k and words the alternative with it."""
    alt = Alternative("camera_focal", "", "", None)

    def apply(r, c):
        # 10 steps bracket log k to 0.45 · 0.618¹⁰ ≈ 0.004: enough for the 1 % it must resolve.
        factor = _best_factor(reading, r, c, _with_scaled_depths, FOCAL_RANGE, 10)
        if abs(factor - 1.0) <= QUICK_SCALE_RESOLUTION:
            raise ValueError(f"the best camera depth scale is {factor:.4g}: as given")
        alt.description = (f"the camera's depths are {1 / factor:.4g}× the true ones and their "
                           "lateral offsets are not: the focal length of the camera intrinsics "
                           f"is about {1 / factor:.3g}× the true one (not a target of another "
                           "size, which would scale all three alike)")
        alt.fix = (f"calibrate the camera (or let the images refine it: --refine-intrinsics "
                   f"auto); the focal length given is about {1 / factor:.3g}× what the poses say")
        return r, _stream(_with_scaled_depths(c.poses, factor), c), None

    alt.apply = apply
    return alt


#: Interior samples used by ``stream_roughness`` (evenly spaced).
ROUGHNESS_SAMPLES = 400
#: Roughness below this (deg) is motion curvature or rounding, not measurement noise.
ROUGHNESS_FLOOR_DEG = 0.003
#: One stream this many times rougher than the other: it is the camera's.
ROUGHNESS_RATIO = 3.0


def _median_period(stream: PoseStream) -> float | None:
    t = stream.timestamps
    if t is None or len(t) < 2:
        return None
    d = np.diff(np.asarray(t, float))
    d = d[d > 0]
    return float(np.median(d)) if len(d) else None


def stream_roughness(stream: PoseStream, spacing: float | None = None) -> float | None:
    """How far each sample's rotation is from the interpolation of the samples ``spacing``
    seconds before and after it (deg, median over up to ``ROUGHNESS_SAMPLES`` samples; default
    spacing: the stream's own period): the residuals of a stream about a smooth motion. A
    robot's reported poses are smooth (their roughness is the curvature of the motion over the
    spacing, the same for both streams at the same spacing); a camera's carry its measurement
    noise on top. None without timestamps or with fewer than 5 samples."""
    t = stream.timestamps
    period = _median_period(stream)
    if t is None or len(t) < 5 or period is None:
        return None
    t = np.asarray(t, float)
    m = max(1, int(round((spacing or period) / period)))
    k = np.arange(m, len(t) - m)
    if len(k) < 3:
        return None
    k = k[t[k + m] > t[k - m]]
    if len(k) < 3:
        return None
    k = k[np.unique(np.linspace(0, len(k) - 1, min(ROUGHNESS_SAMPLES, len(k))).round()
                    .astype(int))]
    from scipy.spatial.transform import Rotation
    R = np.asarray(stream.poses, float)[:, :3, :3]
    w = (t[k] - t[k - m]) / (t[k + m] - t[k - m])
    a = Rotation.from_matrix(R[k - m])
    step = (a.inv() * Rotation.from_matrix(R[k + m])).as_rotvec()
    interp = a * Rotation.from_rotvec(step * w[:, None])
    err = (interp.inv() * Rotation.from_matrix(R[k])).magnitude()
    return float(np.degrees(np.median(err)))


def swap_evidence(robot: PoseStream, camera: PoseStream) -> dict:
    """Which stream carries the camera's noise, from their roughness (``stream_roughness``, both
    at the sparser stream's period so that the motion's curvature counts alike):
    ``reading`` "as_read" (the camera stream is the rough one), "swapped" (the robot stream
    is), or None (no timestamps, or no clear difference) — the residuals of the AX = ZB fits
    cannot tell: swapping both streams fits exactly as well, the target's pose taking the
    hand-eye transform's place."""
    periods = [p for p in (_median_period(robot), _median_period(camera)) if p]
    spacing = max(periods) if len(periods) == 2 else None
    rough_r = stream_roughness(robot, spacing) if spacing else None
    rough_c = stream_roughness(camera, spacing) if spacing else None
    reading = None
    if rough_r is not None and rough_c is not None:
        r, c = max(rough_r, ROUGHNESS_FLOOR_DEG), max(rough_c, ROUGHNESS_FLOOR_DEG)
        if c >= ROUGHNESS_RATIO * r:
            reading = "as_read"
        elif r >= ROUGHNESS_RATIO * c:
            reading = "swapped"
    return {"reading": reading, "robot_roughness_deg": rough_r,
            "camera_roughness_deg": rough_c}


def try_alternatives(robot, camera, reading: Reading, alternatives) -> list[Hypothesis]:
    """Fits the data as read and each alternative quickly, on the same subset size."""
    offset = reading.time_offset
    error = ""
    try:
        base = _quick_fit(robot, camera, reading.mode, offset)
    except ValueError as e:
        base = (math.inf, math.inf, math.inf)
        error = " ".join(str(e).split())[:200]
    out = [Hypothesis("as_read", "the data as read", "", *base, error=error)]
    for alt in alternatives:
        try:
            r, c, mode = alt.apply(robot, camera)
            off = offset
            if mode == "auto_offset":  # the alternative's own clock offset
                mode = reading.mode
                side = r if mode == "eye_in_hand" else r.inverted()
                off = estimate_time_offset(side, c, reading.time_offset_range).offset
            out.append(Hypothesis(alt.code, alt.description, alt.fix,
                                  *_quick_fit(r, c, mode or reading.mode, off),
                                  mode="" if mode in (None, reading.mode) else mode,
                                  evidence=swap_evidence(robot, camera)
                                  if alt.code == "swapped_streams" else None))
        except ValueError as e:
            out.append(Hypothesis(alt.code, alt.description, alt.fix, math.inf, math.inf,
                                  math.inf, error=" ".join(str(e).split())[:200]))
    return out


def explaining(hypotheses, max_deg: float, max_m: float, max_distance: float = math.inf,
               better_by: float = BETTER_BY) -> list[Hypothesis]:
    """The alternatives that explain the data better than the data as read, best first: far
    smaller residuals (see ``BETTER_BY``), or — when both fit — a plausible hand-eye distance
    where the data as read give an implausible one (swapped streams fit AX = ZB as well, with the
    target's pose in the base as "hand-eye" transform). An alternative whose hand-eye distance is
    itself implausible explains nothing."""
    base = hypotheses[0]
    b_deg, b_m = max(base.rotation_deg, 1e-3), max(base.translation_m, 1e-5)
    found = [h for h in hypotheses[1:]
             if _explains(h, base, max_deg, max_m, max_distance, better_by)]
    return sorted(found, key=lambda h: h.rotation_deg / b_deg + h.translation_m / b_m)


def _explains(h: Hypothesis, base: Hypothesis, max_deg: float, max_m: float,
              max_distance: float, better_by: float = BETTER_BY) -> bool:
    # Residual medians are per-axis noise × CHI3_MEDIAN (1.54) when the data fit.
    # An alternative in the other mode is held to that mode's plausible distance.
    own_distance = DEFAULT_MAX_HAND_EYE_DISTANCE[h.mode] if h.mode else max_distance
    plausible = (h.rotation_deg <= max_deg * 1.54 and h.translation_m <= max_m * 1.54
                 and h.hand_eye_distance <= own_distance)
    fits = (h.rotation_deg <= max_deg * 1.54 and h.translation_m <= max_m * 1.54
            and np.isfinite(h.rotation_deg))
    if h.code == "swapped_streams" and h.evidence is not None:
        # Both readings fit AX = ZB alike (their residual medians are of different points and
        # frames, not comparable); the stream that carries the noise says which is the camera.
        which = h.evidence.get("reading")
        if which == "swapped":
            return fits
        if which == "as_read" or not fits:
            return False
        # No timestamps to tell: the residuals decide only when far better (a mere
        # difference in medians is no evidence; ``swap_ambiguity`` reports the tie).
        b_deg, b_m = max(base.rotation_deg, 1e-3), max(base.translation_m, 1e-5)
        return (h.rotation_deg / b_deg <= better_by and h.translation_m / b_m <= better_by
                and better_by <= BETTER_BY)
    if not plausible or not np.isfinite(h.rotation_deg):
        return False
    b_deg, b_m = max(base.rotation_deg, 1e-3), max(base.translation_m, 1e-5)
    r_deg, r_m = h.rotation_deg / b_deg, h.translation_m / b_m
    if min(r_deg, r_m) <= better_by and max(r_deg, r_m) <= NOT_WORSE:
        return True
    return (base.hand_eye_distance > max_distance and h.hand_eye_distance <= own_distance
            and r_deg <= 2.0 and r_m <= 2.0)


#: Fewest held-out samples for the held-out test.
MIN_HELD_OUT = 3


def held_out_test(result) -> dict | None:
    """Do the held-out samples fit as well as the fitted ones? The ratio of their mean whitened
    residual² per degree of freedom, held-out (6 per sample, inflated by the estimate's own
    error: 1 + p / (6 n_fit), p = 12 parameters) over fit (6 n_fit − p dof); under the model it
    is F(6 n_held, 6 n_fit − p) distributed, whatever the noise level assumed. None when fewer
    than ``MIN_HELD_OUT`` samples are held out."""
    used = result.sample_used
    w = getattr(result, "whitened_sq", None)
    held, fit = used == "held_out", used == "fit"
    n_h, n_f = int(held.sum()), int(fit.sum())
    if w is None or n_h < MIN_HELD_OUT or n_f < 3:
        return None
    dof_f = max(int(result.fit.dof), 1)
    p = 6 * n_f - dof_f
    ratio = float(np.mean(w[held]) / 6.0 / (1.0 + p / (6.0 * n_f))
                  / (np.sum(w[fit]) / dof_f))
    lines = np.asarray(result.aligned.camera_lines)
    worst = np.flatnonzero(held)[int(np.argmax(w[held]))]
    return {"ratio": ratio, "bound": float(f_distribution.ppf(0.999, 6 * n_h, dof_f)),
            "held_out": n_h, "fit": n_f, "dof": (6 * n_h, dof_f),
            "worst_line": int(lines[worst]), "worst_whitened_sq": float(w[worst])}


def verdict(result) -> Verdict:
    """The checks of the module docstring on a ``CalibrationResult``."""
    reasons = []
    fit = result.fit
    name = hand_name(result.mode)
    max_deg, max_m = result.settings["max_noise"]
    # The worst axis: max_noise bounds every axis's noise.
    sr_deg, st = math.degrees(float(np.max(fit.rotation_sigmas))), \
        float(np.max(fit.translation_sigmas))
    base = result.hypotheses[0] if result.hypotheses else None
    better = explaining(result.hypotheses, max_deg, max_m,
                        result.settings["max_hand_eye_distance_m"]) if base is not None else []
    noisy = sr_deg > max_deg or st > max_m
    far = float(np.linalg.norm(fit.X_H[:3, 3])) > result.settings["max_hand_eye_distance_m"]
    hints = [] if better or base is None else explaining(
        result.hypotheses, max_deg, max_m, result.settings["max_hand_eye_distance_m"],
        SOMEWHAT_BETTER)
    by_code = {h.code: h for h in result.hypotheses}
    sc, fo = by_code.get("camera_scale"), by_code.get("camera_focal")
    if sc is not None and fo is not None:
        # A target scale and a focal error both change the camera's translations: the reading
        # that leaves the smaller translation residuals is the cause (the other explains part).
        drop = "camera_focal" if sc.translation_m <= fo.translation_m else "camera_scale"
        better = [h for h in better if h.code != drop]
        hints = [h for h in hints if h.code != drop]
    scale = getattr(result, "scale_test", None)
    if scale is not None:
        # The maximum-likelihood profile of the scale decides, not the quick fits' medians.
        better = [h for h in better if h.code != "camera_scale"]
        hints = [h for h in hints if h.code != "camera_scale"]
        level = "FAIL" if scale["sigmas"] > SCALE_FAIL_SIGMA else (
            "WARN" if scale["sigmas"] > SCALE_WARN_SIGMA else "")
        if abs(scale["factor"] - 1.0) <= SCALE_MIN_ERROR:
            # Significant but immaterial (a long recording resolves 0.04 %): a print's and a
            # robot's own scale are not better than this.
            level = ""
        if level and not better:
            f = scale["factor"]
            reasons.append(Reason(
                level, "camera_scale",
                f"the camera's translations are {1 / f:.4g}× their true size: a wrong target "
                "size (the square or marker size given to the detector or to --target) or a "
                f"target printed at another scale — with a free scale on them the data fit "
                f"best at {f:.4g} ± {scale['std']:.2g}, {scale['sigmas']:.3g}σ from 1 (or the "
                f"robot's translations are {f:.4g}× theirs: the data cannot tell the two "
                f"apart) — multiply the target's sizes by {f:.4g} (or "
                f"--camera-translation-scale {f:.4g} for pose files)"))
    for level, found in (("FAIL", better), ("WARN", hints)):
        if found:
            best = found[0]
            reasons.append(Reason(
                level, best.code,
                f"{best.description}: read that way the data fit with median residuals "
                f"{best.rotation_deg:.3g}° / {1000 * best.translation_m:.3g} mm instead of "
                f"{base.rotation_deg:.3g}° / {1000 * base.translation_m:.3g} mm — {best.fix}"))
    if noisy:
        reasons.append(Reason(
            "FAIL", "residuals",
            f"the residuals are beyond what a camera pose measurement has: noise "
            f"{sr_deg:.3g}° / {1000 * st:.3g} mm per axis (plausible: ≤ {max_deg:g}° / "
            f"{1000 * max_m:g} mm, --max-noise)"
            + ("" if better else "; no usual mistake (quaternion order, swapped or "
               "inverted streams, units, clock offset) explains them: check that the streams "
               "belong to the same recording and that the target did not move")))
    swapped = next((h for h in result.hypotheses if h.code == "swapped_streams"), None)
    swap_reading = (swapped.evidence or {}).get("reading") if swapped is not None else None
    if far and not noisy:
        hint = ""
        if swapped is not None and swap_reading != "as_read" and \
                swapped.hand_eye_distance < 0.5 * np.linalg.norm(fit.X_H[:3, 3]) and \
                swapped.rotation_deg < 4 * max(base.rotation_deg, 1e-3):
            hint = (f"; with robot and camera files swapped the data fit as well and put the "
                    f"camera {swapped.hand_eye_distance:.3g} m away — swapped files?")
        reasons.append(Reason(
            "FAIL", "implausible_result",
            f"{name} puts the camera {np.linalg.norm(fit.X_H[:3, 3]):.3g} m from the "
            f"{'flange' if result.mode == 'eye_in_hand' else 'robot base'} (more than "
            f"--max-hand-eye-distance {result.settings['max_hand_eye_distance_m']:g} m)" + hint))
    if swapped is not None and swapped.evidence is not None and swap_reading is None \
            and not better and not far and not noisy and not any(
                r.code == "swapped_streams" for r in reasons):
        # No timestamps to say which stream is the camera's, and both readings fit: the
        # result is one of two, not an answer.
        own = DEFAULT_MAX_HAND_EYE_DISTANCE[swapped.mode] if swapped.mode else \
            result.settings["max_hand_eye_distance_m"]
        b_deg, b_m = max(base.rotation_deg, 1e-3), max(base.translation_m, 1e-5)
        if (np.isfinite(swapped.rotation_deg) and swapped.hand_eye_distance <= own
                and swapped.rotation_deg <= 2 * b_deg and swapped.translation_m <= 2 * b_m):
            reasons.append(Reason(
                "WARN", "swap_ambiguous",
                f"the data fit as well with the robot and camera files swapped (median "
                f"residuals {swapped.rotation_deg:.3g}° / {1000 * swapped.translation_m:.3g} mm "
                f"instead of {base.rotation_deg:.3g}° / {1000 * base.translation_m:.3g} mm; the "
                f"camera would be {swapped.hand_eye_distance:.3g} m from the "
                f"{'flange' if result.mode == 'eye_in_hand' else 'robot base'}): AX = ZB fits "
                "both readings alike, and without timestamps nothing says which stream is the "
                "camera's — check that --robot holds the robot's poses and --camera the "
                "camera's"))
    n_fit = int(np.sum(result.sample_used == "fit"))
    if n_fit < MIN_SAMPLES:
        reasons.append(Reason("WARN", "too_few_samples",
                              f"only {n_fit} samples fit (≥ {MIN_SAMPLES} recommended)"))
    held_out = held_out_test(result)
    if held_out is not None and not noisy and held_out["ratio"] > held_out["bound"]:
        reasons.append(Reason(
            "WARN", "held_out",
            f"the held-out samples fit worse than the fitted ones: mean whitened residual² "
            f"{held_out['ratio']:.3g}× the fit's (F-test, 99.9 % bound {held_out['bound']:.3g} "
            f"for {held_out['held_out']} held-out and {held_out['fit']} fit samples; worst "
            f"held-out sample line {held_out['worst_line']}): the result may not generalize — "
            "a target or camera that moved during part of the recording, or unmodelled robot "
            "errors"))
    if result.split is not None and not result.split.consistent and not noisy:
        s = result.split
        reasons.append(Reason(
            "FAIL", "sigma",
            f"the σ are too small: two independent halves of the samples give {name} estimates "
            f"{s.rotation_diff_deg:.3g}° / {1000 * s.translation_diff:.3g} mm apart, NEES "
            f"{s.nees:.3g} > {s.threshold:.3g} — unmodelled effects (clock offset, robot "
            "kinematic errors, a target that moved) dominate the noise"))
    for t in getattr(result, "fixed_tests", None) or []:
        if t.level:
            reasons.append(Reason(t.level, "fixed_value", t.message))
    obs = result.observability
    if obs is not None:  # with held components: the analysis given their values
        if not obs.observable:
            reasons.append(Reason("FAIL", "unobservable", "; ".join(obs.messages)))
        elif obs.weak:
            reasons.append(Reason("WARN", "weak", "; ".join(obs.messages)))
    n = len(result.sample_used)
    outliers = int(np.sum(result.sample_used == "outlier"))
    if n and outliers > OUTLIER_FRACTIONS[1] * n:
        reasons.append(Reason("FAIL", "outliers", f"{outliers} of {n} samples are outliers"))
    elif n and outliers > OUTLIER_FRACTIONS[0] * n:
        reasons.append(Reason("WARN", "outliers", f"{outliers} of {n} samples are outliers"))
    est = result.time_offset
    if est is not None and abs(est.offset) > 0.9 * est.search_range:
        reasons.append(Reason("WARN", "time_offset",
                              f"the clock offset {est.offset:+.4f} s is near the search bound "
                              f"±{est.search_range:g} s (--time-offset-range)"))
    for w in result.warnings:
        if w.startswith("time offset not estimated"):
            reasons.append(Reason("WARN", "time_offset", w))
        elif w.startswith("the camera poses' systematic uncertainty"):
            reasons.append(Reason("WARN", "self_calibrated_intrinsics",
                                  w + "; calibrate the camera separately (--intrinsics) for a "
                                  "more accurate result"))
    status = "FAIL" if any(r.level == "FAIL" for r in reasons) else (
        "WARN" if reasons else "OK")
    return Verdict(status, reasons)


__all__ = ["Alternative", "Hypothesis", "Reading", "Reason", "Verdict", "default_alternatives",
           "explaining", "held_out_test", "reading_of", "try_alternatives", "verdict"]

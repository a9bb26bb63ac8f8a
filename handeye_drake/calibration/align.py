"""Time alignment of a robot stream (X_BE) and a camera stream (X_CT) recorded at different rates.

Convention for the constant time offset between the two clocks: ``time_offset`` = (camera time
stamp) − (robot-clock time of the same instant); a camera that stamps its images 20 ms late has
``time_offset = +0.02``. The robot pose matching a camera sample stamped t is therefore
X_BE(t − time_offset), interpolated between the two robot samples around it: linear in
translation, SLERP (constant-speed geodesic) in rotation.

The offset can be estimated (``estimate_time_offset``): for the true offset the rotation angle of
each camera motion A between two camera samples equals that of the matching robot motion B
(A = X B X⁻¹ are conjugate, whatever the hand-eye X), so the offset minimizes a robust measure of
|θ_A| − |θ_B| over the recording: a grid search over the bounded range, then a bounded scalar
refinement around the best grid point.

Scale: the interpolator computes the relative rotation of a robot sampling interval only when a
query falls in it, so building one for 10⁶ robot samples costs a validation pass, and queries cost
what they touch. The offset search compares motions starting at no more than
``MAX_OFFSET_ANCHORS`` camera samples, evenly spaced over the recording (see
``estimate_time_offset``).
"""

from __future__ import annotations

import math
import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from ..estimation.interpolation import PoseInterpolator
from ..recorded.formats import LineNumbers, PoseStream, _progress, slow_clock_hint

#: Largest number of camera samples the motions of the time-offset search start from. Beyond,
#: evenly spaced ones are used: the cost minimum's width is set by the sampling period and the
#: noise, not by the number of motions, and each of the (up to 2001) cost evaluations would
#: otherwise be linear in the recording.
MAX_OFFSET_ANCHORS = 2000


@dataclass(frozen=True)
class AlignedSamples:
    """Camera samples with the robot pose at the same instant.

    Attributes:
        X_BE: (M, 4, 4) robot poses (interpolated at the camera instants).
        X_CT: (M, 4, 4) camera poses (as read).
        camera_times: (M,) camera time stamps, or None for index-paired streams.
        camera_index: (M,) index of each kept sample in the camera stream.
        camera_lines: line of each kept sample in the camera file (``LineNumbers``).
        camera_source: the camera file name.
        time_offset: the offset used (s; see the module docstring).
        dropped_outside: camera lines dropped because they fall outside the robot's time span.
        dropped_gap: camera lines dropped because the robot stream has a gap there.
    """

    X_BE: np.ndarray
    X_CT: np.ndarray
    camera_times: np.ndarray | None
    camera_index: np.ndarray
    camera_lines: tuple
    camera_source: str
    time_offset: float
    dropped_outside: tuple
    dropped_gap: tuple

    def __len__(self) -> int:
        return len(self.X_BE)

    def where(self, k: int) -> str:
        return f"{self.camera_source}:{self.camera_lines[k]}"


def _median_period(times: np.ndarray) -> float:
    return float(np.median(np.diff(times))) if len(times) > 1 else math.inf


def _units_hint(robot: PoseStream, camera: PoseStream) -> str:
    """Why the clocks of two streams may not match: a time unit other than seconds in one of
    them (a slow clock, or spans far apart in length), for messages; "" when nothing shows."""
    hints = []
    r = float(robot.timestamps[-1] - robot.timestamps[0]) if len(robot) > 1 else 0.0
    c = float(camera.timestamps[-1] - camera.timestamps[0]) if len(camera) > 1 else 0.0
    alike = r > 0 and c > 0 and 1 / 30 < c / r < 30
    for s, other in ((robot, camera), (camera, robot)):
        h = slow_clock_hint(s.timestamps)
        # A sparse stream (one image every 1.2 s) beside a fast one over the same span is in
        # the same unit, seconds: in milliseconds it would span 1000× the other's time.
        if h and not (alike and slow_clock_hint(other.timestamps) is None):
            hints.append(f"{s.source}: {h}")
    if not hints and len(robot) > 1 and len(camera) > 1:
        if r > 0 and c > 0 and not alike:
            big, small = (camera, robot) if c > r else (robot, camera)
            hints.append(f"{big.source} spans {max(c, r) / min(c, r):.3g}× the time of "
                         f"{small.source}: do both files use the same time unit (seconds; "
                         "time_scale, command line --time-scale, rescales one)?")
    return "; ".join(hints)


def _too_few(stream: PoseStream, need: int, what: str) -> ValueError:
    return ValueError(f"{stream.source}: too few samples: only {len(stream)}, at least {need} "
                      f"are needed ({what})")


#: Camera instants outside the robot's time span by at most this fraction of the median robot
#: period are taken at the span's end (not dropped).
EDGE_TOLERANCE = 0.01


def align_streams(robot: PoseStream, camera: PoseStream, time_offset: float = 0.0,
                  max_gap: float | None = None, min_samples: int = 3) -> AlignedSamples:
    """Pairs each camera sample with the robot pose at the same instant.

    With timestamps on both streams the robot pose is interpolated at t_camera − time_offset;
    camera samples outside the robot's time span (by more than ``EDGE_TOLERANCE`` of a robot
    period), or inside a robot sampling interval longer
    than ``max_gap`` (default 5 × the median robot period), are dropped and listed. Streams
    without timestamps are paired by index and must have the same length (time_offset 0).

    Raises:
        ValueError: one stream timestamped and not the other, mismatched lengths, non-finite
            offset, fewer than ``min_samples`` aligned samples (streams that do not overlap in
            time: different clocks?).
    """
    try:
        time_offset = float(time_offset)
    except (TypeError, ValueError):
        raise ValueError(f"time_offset: expected a number of seconds, got {time_offset!r}") \
            from None
    if not math.isfinite(time_offset):
        raise ValueError(f"time_offset: must be finite, got {time_offset!r}")
    if robot.has_timestamps != camera.has_timestamps:
        with_t, without = (robot, camera) if robot.has_timestamps else (camera, robot)
        raise ValueError(f"{without.source}: has no timestamps but {with_t.source} has; both "
                         "streams need timestamps to be aligned (or neither, to pair them by "
                         "index)")
    if not robot.has_timestamps:
        if len(robot) != len(camera):
            raise ValueError(f"{robot.source} has {len(robot)} poses and {camera.source} has "
                             f"{len(camera)}: mismatched lengths (without timestamps the "
                             "streams are paired sample by sample)")
        if time_offset != 0.0:
            raise ValueError("time_offset: the streams have no timestamps, a time offset "
                             "cannot be applied")
        if len(camera) < min_samples:
            raise _too_few(camera, min_samples, f"{min_samples - 1} motions")
        return AlignedSamples(_read_only(robot.poses), _read_only(camera.poses), None,
                              np.arange(len(camera)), LineNumbers(camera.lines), camera.source,
                              0.0, LineNumbers(), LineNumbers())
    # Too short to align at all: say so, rather than blame the clocks below.
    if len(camera) < min_samples:
        raise _too_few(camera, min_samples, f"{min_samples - 1} motions")
    if len(robot) < 2:
        raise _too_few(robot, 2, "to interpolate the robot pose between samples")
    interp = PoseInterpolator(robot.timestamps, robot.poses)
    if max_gap is None:
        max_gap = 5.0 * _median_period(robot.timestamps)
    q = camera.timestamps - time_offset
    t0, t1 = interp.span
    # An instant a hair outside the span (an offset of a fraction of a millisecond on streams
    # stamped alike) is the end pose, not a lost sample.
    edge = EDGE_TOLERANCE * _median_period(robot.timestamps)
    q = np.where((q < t0) & (q >= t0 - edge), t0, np.where((q > t1) & (q <= t1 + edge), t1, q))
    inside = (q >= t0) & (q <= t1)
    in_gap = np.zeros_like(inside)
    in_gap[inside] = interp.segment_length(q[inside]) > max_gap
    keep = inside & ~in_gap
    lines = LineNumbers(camera.lines)
    dropped_outside = lines[~inside]
    dropped_gap = lines[in_gap]
    if keep.sum() < min_samples:
        hint = _units_hint(robot, camera)
        raise ValueError(
            f"{camera.source}: only {int(keep.sum())} of {len(camera)} camera samples fall inside "
            f"the robot's time span [{t0!r}, {t1!r}] s of {robot.source} (camera stamps "
            f"[{float(camera.timestamps[0])!r}, {float(camera.timestamps[-1])!r}] s, time offset "
            f"{time_offset!r} s){' outside its gaps' if in_gap.any() else ''}; at least "
            f"{min_samples} are needed — "
            + (hint if hint else "do the streams use the same clock and time unit?"))
    idx = np.flatnonzero(keep)
    # Samples are dropped at the ends (outside the span) or in gaps: a contiguous run of kept
    # samples is a view, not a copy of up to 10⁶ poses.
    contiguous = len(idx) and idx[-1] - idx[0] + 1 == len(idx)
    X_CT = _read_only(camera.poses[idx[0]:idx[-1] + 1]) if contiguous else camera.poses[idx]
    return AlignedSamples(interp(q[idx]), X_CT, camera.timestamps[idx], idx, lines[idx],
                          camera.source, time_offset, dropped_outside, dropped_gap)


def _read_only(a: np.ndarray) -> np.ndarray:
    """A read-only view (no copy of a large stream; callers must not write into it anyway)."""
    v = a.view()
    v.flags.writeable = False
    return v


class UnobservableTimeOffset(ValueError):
    """The recording does not determine the time offset (too short, too little rotation, or a
    rotation speed too uniform); the offset then matters little, and 0 is a fair default."""


@dataclass(frozen=True)
class TimeOffsetEstimate:
    """Result of ``estimate_time_offset``.

    Attributes:
        offset: the estimated time offset (s), camera stamp − robot time.
        search_range: the half-width R (s) of the searched interval [−R, R].
        grid: offsets of the coarse grid (s); ``cost``: the robust cost on it (rad).
        num_motions: number of camera motions compared.
        residual_rms_deg: RMS of θ_A − θ_B (deg) over the inlying motions at the offset.
    """

    offset: float
    search_range: float
    grid: np.ndarray
    cost: np.ndarray
    num_motions: int
    residual_rms_deg: float


#: Levels of the wide search (each narrows the range about its best offset): a bound, never a
#: recursion without end.
MAX_WIDE_LEVELS = 6


def _angles(R0: np.ndarray, R1: np.ndarray) -> np.ndarray:
    """Rotation angles of R0ᵀ R1 (rad), from the trace (clipped): fast, vectorized."""
    c = (np.einsum("kij,kij->k", R0, R1) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def _wide_search(robot: PoseStream, camera: PoseStream, interp, R: float, lags, step,
                 units: str, depth: int = 0) -> TimeOffsetEstimate:
    """``estimate_time_offset`` when ±R leaves fewer than half of the camera samples inside the
    robot's span for every offset: each grid offset is scored on the camera samples its own
    robot instants cover (at least half of those covered at offset 0, so offset 0 always
    counts), the trimmed mean of |θ_A − θ_B| over motions of the smallest lag; the usual search
    then refines ±4 grid steps about the best one."""
    t0, t1 = interp.span
    tc = camera.timestamps
    need = max(8, int(np.count_nonzero((tc >= t0) & (tc <= t1))) // 2)
    asked = step
    if step is None:
        periods = [_median_period(robot.timestamps), _median_period(tc)]
        step = min(p for p in periods if math.isfinite(p)) / 4.0
    step = max(float(step), 2.0 * R / 2000.0)
    grid = np.linspace(-R, R, 2 * int(math.ceil(R / step)) + 1)
    R_CT = camera.poses[:, :3, :3]
    cost = np.full(len(grid), np.inf)
    for g, d in enumerate(grid):
        k = np.flatnonzero((tc - d >= t0) & (tc - d <= t1))
        if len(k) < need:
            continue
        if len(k) > MAX_OFFSET_ANCHORS:
            k = k[np.unique(np.linspace(0, len(k) - 1, MAX_OFFSET_ANCHORS).round().astype(int))]
        R_BE = interp.rotations(tc[k] - d)
        r = np.concatenate([np.abs(_angles(R_CT[k[:-L]], R_CT[k[L:]])
                                   - _angles(R_BE[:-L], R_BE[L:]))
                            for L in sorted({int(v) for v in lags}) if 0 < L < len(k)])
        m = max(1, int(0.8 * len(r)))
        cost[g] = float(np.partition(r, m - 1)[:m].mean())
    best = float(grid[int(np.argmin(cost))])
    if abs(best) >= R - step:
        raise ValueError(
            f"time offset estimation: the best offset lies on the search bound ({best:+.4g} s "
            f"of ±{R:g} s): the offset is larger than the range, or the streams do not match — "
            "widen --time-offset-range or check the timestamps" + units)
    shifted = dataclasses.replace(camera, timestamps=tc - best)
    # The widest range about the best offset that keeps half of the samples for every offset
    # (the ordinary search's condition), at least 4 grid steps.
    margin = np.minimum(tc - best - t0, t1 - (tc - best))
    keeps = float(np.sort(margin)[::-1][need - 1])
    # The refinement uses the step asked for (the grid's may be coarser, at most 2001 points):
    # each level narrows the range by the grid's ratio, so this ends in a few levels (a loop
    # on the same coarse step never would).
    near = estimate_time_offset(robot, shifted, min(R, max(keeps, 4 * (grid[1] - grid[0]))),
                                lags, asked, _depth=depth + 1)
    return TimeOffsetEstimate(best + near.offset, R, near.grid + best, near.cost,
                              near.num_motions, near.residual_rms_deg)


def estimate_time_offset(robot: PoseStream, camera: PoseStream, search_range: float = 0.5,
                         lags=(1, 2, 4, 8), step: float | None = None, *,
                         _depth: int = 0) -> TimeOffsetEstimate:
    """Estimates the constant offset (camera stamp − robot time) in [−search_range, search_range].

    For each lag L in ``lags`` the rotation angle θ_A of the camera motion between camera samples
    k and k+L is compared with the angle θ_B of the robot motion between the interpolated robot
    poses at the same instants. The cost is the mean of the 80 % smallest |θ_A − θ_B| on a grid
    of step ``step`` (default: a quarter of the smaller median sampling period, at most 2001
    points); around the best grid point a bounded scalar minimization of a Cauchy loss (scale
    from the residuals there, so outlying camera poses weigh little) refines the offset. Only
    camera samples whose robot instant stays inside the robot's time span for every candidate
    offset are used, so all candidates compare the same motions. With more than
    ``MAX_OFFSET_ANCHORS`` such samples, the motions start at ``MAX_OFFSET_ANCHORS`` of them,
    evenly spaced (each still compared with the sample L later).

    Raises:
        UnobservableTimeOffset (a ValueError): too few samples overlapping for every candidate
            offset, a camera that barely rotates, a flat cost (rotation speed too uniform).
        ValueError: missing timestamps, a bad range, a cost minimum on the search bound (offset
            larger than the range, or streams that do not match).

    When the cost is flat or its minimum lies on the bound and a stream's sampling period is
    1 s or more, the message says the timestamps may be in milliseconds, microseconds or
    nanoseconds (``formats.slow_clock_hint``).
    """
    if not (robot.has_timestamps and camera.has_timestamps):
        raise ValueError("time offset estimation needs timestamps in both streams "
                         f"({robot.source}, {camera.source})")
    try:
        R = float(search_range)
    except (TypeError, ValueError):
        raise ValueError(f"search_range: expected seconds, got {search_range!r}") from None
    if not (math.isfinite(R) and R > 0):
        raise ValueError(f"search_range: must be finite and > 0, got {search_range!r}")
    if len(camera) < 4:
        raise UnobservableTimeOffset(f"time offset estimation: {camera.source} has only "
                                     f"{len(camera)} samples, at least 4 are needed")
    if len(robot) < 2:
        raise UnobservableTimeOffset(f"time offset estimation: {robot.source} has only "
                                     f"{len(robot)} sample, at least 2 are needed")
    units = _units_hint(robot, camera)
    units = f" ({units})" if units else ""
    interp = PoseInterpolator(robot.timestamps, robot.poses)
    t0, t1 = interp.span
    tc = camera.timestamps
    ok = np.flatnonzero((tc - R >= t0) & (tc + R <= t1))
    inside = int(np.count_nonzero((tc >= t0) & (tc <= t1)))
    if len(ok) < max(4, inside // 2) and inside >= 8:
        if _depth >= MAX_WIDE_LEVELS:
            # Still too wide after the bounded narrowings: a range far beyond the recording, or
            # an overlap too short (a bag still being recorded) — not estimable (yet).
            raise UnobservableTimeOffset(
                f"time offset estimation: ±{R:g} s is too wide for the recording's length "
                f"({t1 - t0:.4g} s of robot poses; {len(ok)} of {inside} camera samples of "
                f"{camera.source} stay inside it for every candidate offset) even after "
                f"{_depth} narrowings — reduce --time-offset-range{units} or record longer")
        # A range wide for the recording's length: every candidate offset on its own overlap
        # first, then the usual search in a narrow range about the best one.
        return _wide_search(robot, camera, interp, R, lags, step, units, _depth)
    if len(ok) < 4:
        raise UnobservableTimeOffset(
            f"time offset estimation: only {len(ok)} camera samples of {camera.source} stay "
            f"inside the robot's time span [{t0!r}, {t1!r}] s for every offset in ±{R:g} s; "
            "need at least 4 — reduce the search range or check that both streams use the "
            f"same clock{units}")
    lags = sorted({int(L) for L in lags if 0 < int(L) < len(ok)})
    if not lags:
        raise ValueError(f"lags: expected sample counts in [1, {len(ok) - 1}]")
    anchors = np.arange(len(ok))
    if len(ok) > MAX_OFFSET_ANCHORS:
        anchors = np.unique(np.linspace(0, len(ok) - 1, MAX_OFFSET_ANCHORS).round().astype(int))
    firsts, seconds = [], []
    for L in lags:
        a = anchors[anchors + L < len(ok)]
        firsts.append(a)
        seconds.append(a + L)
    k0, k1 = np.concatenate(firsts), np.concatenate(seconds)
    # Interpolate only at the samples the motions use: positions in `used`.
    used, inverse_index = np.unique(np.concatenate([k0, k1]), return_inverse=True)
    j0, j1 = inverse_index[:len(k0)], inverse_index[len(k0):]
    R_CT = camera.poses[ok[used], :3, :3]
    tq = tc[ok[used]]
    # The camera motion A = R_CT[k0] R_CT[k1]ᵀ has the angle of R_CT[k0]ᵀ R_CT[k1] (conjugate).
    theta_A = _angles(R_CT[j0], R_CT[j1])
    if np.median(theta_A) < np.radians(0.05):
        raise UnobservableTimeOffset(
            f"time offset estimation: the camera barely rotates (median motion "
            f"{np.degrees(np.median(theta_A)):.3g}° between compared samples); the offset is "
            "unobservable, pass --time-offset SECONDS instead")

    def residuals(delta: float) -> np.ndarray:
        R_BE = interp.rotations(tq - delta)
        return theta_A - _angles(R_BE[j0], R_BE[j1])

    def trimmed(delta: float) -> float:
        r = np.abs(residuals(delta))
        m = max(1, int(0.8 * len(r)))
        return float(np.partition(r, m - 1)[:m].mean())

    if step is None:
        periods = [_median_period(robot.timestamps), _median_period(tc)]
        step = min(p for p in periods if math.isfinite(p)) / 4.0
    step = max(float(step), 2.0 * R / 2000.0)
    n = int(math.ceil(R / step))
    grid = np.linspace(-R, R, 2 * n + 1)
    bar = _progress(len(grid), "time offset search", None, unit="offsets")
    cost = np.empty(len(grid))
    try:
        for g, d in enumerate(grid):
            cost[g] = trimmed(d)
            bar.update(1)
    finally:
        bar.close()
    best = int(np.argmin(cost))
    if best in (0, len(grid) - 1):
        raise ValueError(
            f"time offset estimation: the best offset lies on the search bound "
            f"({grid[best]:+.4g} s of ±{R:g} s): the offset is larger than the range, or the "
            "streams do not match — widen --time-offset-range or check the timestamps"
            + units)
    spread = float(np.median(cost) - cost[best])
    # Flat: no clear minimum, relative to the noise floor and to the motion sizes (rounding).
    if not spread > max(0.05 * cost[best], 1e-6 * float(np.median(theta_A))):
        raise UnobservableTimeOffset(
            f"time offset estimation: the cost is flat over ±{R:g} s (best {cost[best]:.3g} "
            f"rad, median {np.median(cost):.3g} rad): the rotation speed is too uniform to "
            "observe a time offset; pass --time-offset SECONDS instead" + units)
    r = residuals(grid[best])
    scale = max(1.4826 * float(np.median(np.abs(r - np.median(r)))), 1e-6)

    def cauchy(delta: float) -> float:
        return float(np.log1p((residuals(delta) / scale) ** 2).sum())

    lo, hi = grid[max(best - 2, 0)], grid[min(best + 2, len(grid) - 1)]
    res = minimize_scalar(cauchy, bounds=(lo, hi), method="bounded",
                          options={"xatol": 1e-6})
    offset = float(res.x) if cauchy(float(res.x)) <= cauchy(grid[best]) else float(grid[best])
    r = residuals(offset)
    inl = np.abs(r) <= 5 * scale
    rms = float(np.degrees(np.sqrt(np.mean(r[inl] ** 2)))) if inl.any() else math.nan
    return TimeOffsetEstimate(offset, R, grid, cost, len(theta_A), rms)

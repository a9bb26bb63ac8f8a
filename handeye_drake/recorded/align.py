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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.spatial.transform import Rotation

from .formats import PoseStream


def _floats(value, name: str) -> np.ndarray:
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError) as e:
        raise ValueError(f"{name}: expected numbers ({e})") from None


class PoseInterpolator:
    """X(t) from timestamped rigid poses: linear translation, SLERP rotation per segment.

    Args:
        times: (N,) strictly increasing finite seconds, N ≥ 1.
        poses: (N, 4, 4) rigid transforms (not re-validated: pass a ``PoseStream``'s arrays).
    """

    def __init__(self, times, poses):
        self.times = _floats(times, "times")
        self.poses = _floats(poses, "poses")
        if self.times.ndim != 1 or len(self.times) == 0 or self.poses.shape != (
                len(self.times), 4, 4):
            raise ValueError(f"times, poses: expected (N,) and (N, 4, 4) with N ≥ 1, got "
                             f"{self.times.shape} and {self.poses.shape}")
        if not (np.all(np.isfinite(self.times)) and np.all(np.isfinite(self.poses))):
            raise ValueError("times, poses: contain NaN or infinite values")
        if np.any(np.diff(self.times) <= 0):
            raise ValueError("times: must be strictly increasing")
        self._R = self.poses[:, :3, :3]
        self._p = self.poses[:, :3, 3]
        if len(self.times) > 1:
            rel = Rotation.from_matrix(np.transpose(self._R[:-1], (0, 2, 1)) @ self._R[1:])
            self._segment_rotvec = rel.as_rotvec()  # R_{i+1} = R_i exp([ω_i]×)
        else:
            self._segment_rotvec = np.zeros((0, 3))

    @property
    def span(self) -> tuple[float, float]:
        return float(self.times[0]), float(self.times[-1])

    def segment_length(self, query_times) -> np.ndarray:
        """Length (s) of the robot sampling interval around each query time (0 when the query
        is a sample time itself)."""
        q = np.asarray(query_times, dtype=float)
        i, s = self._locate(q)
        if len(self.times) == 1:
            return np.zeros_like(q)
        length = self.times[i + 1] - self.times[i]
        return np.where((s == 0) | (s == 1), 0.0, length)

    def _locate(self, q):
        if len(self.times) == 1:
            return np.zeros(q.shape, dtype=int), np.zeros(q.shape)
        i = np.clip(np.searchsorted(self.times, q, side="right") - 1, 0, len(self.times) - 2)
        s = (q - self.times[i]) / (self.times[i + 1] - self.times[i])
        return i, np.clip(s, 0.0, 1.0)

    def rotations(self, query_times) -> np.ndarray:
        """(M, 3, 3) interpolated rotations (queries must lie inside ``span``)."""
        q = self._check(query_times)
        i, s = self._locate(q)
        if len(self.times) == 1:
            return self._R[i]
        return self._R[i] @ Rotation.from_rotvec(s[:, None] * self._segment_rotvec[i]).as_matrix()

    def __call__(self, query_times) -> np.ndarray:
        """(M, 4, 4) interpolated poses (queries must lie inside ``span``)."""
        q = self._check(query_times)
        i, s = self._locate(q)
        X = np.zeros((len(q), 4, 4))
        X[:, 3, 3] = 1.0
        X[:, :3, :3] = self.rotations(q)
        if len(self.times) == 1:
            X[:, :3, 3] = self._p[i]
        else:
            X[:, :3, 3] = self._p[i] + s[:, None] * (self._p[i + 1] - self._p[i])
        return X

    def _check(self, query_times) -> np.ndarray:
        q = np.atleast_1d(_floats(query_times, "query_times"))
        if q.ndim != 1:
            raise ValueError(f"query_times: expected a 1-D array, got shape {q.shape}")
        if not np.all(np.isfinite(q)):
            raise ValueError("query_times: contain NaN or infinite values")
        t0, t1 = self.span
        outside = (q < t0) | (q > t1)
        if np.any(outside):
            k = int(np.argmax(outside))
            raise ValueError(f"query_times[{k}] = {float(q[k])!r} is outside the interpolated "
                             f"time span [{t0!r}, {t1!r}]")
        return q


def interpolate_poses(times, poses, query_times) -> np.ndarray:
    """Poses at ``query_times`` (inside [times[0], times[-1]]) by linear translation and SLERP
    rotation between the surrounding samples; (M, 4, 4)."""
    return PoseInterpolator(times, poses)(query_times)


@dataclass(frozen=True)
class AlignedSamples:
    """Camera samples with the robot pose at the same instant.

    Attributes:
        X_BE: (M, 4, 4) robot poses (interpolated at the camera instants).
        X_CT: (M, 4, 4) camera poses (as read).
        camera_times: (M,) camera time stamps, or None for index-paired streams.
        camera_index: (M,) index of each kept sample in the camera stream.
        camera_lines: line of each kept sample in the camera file (for messages).
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


def align_streams(robot: PoseStream, camera: PoseStream, time_offset: float = 0.0,
                  max_gap: float | None = None, min_samples: int = 3) -> AlignedSamples:
    """Pairs each camera sample with the robot pose at the same instant.

    With timestamps on both streams the robot pose is interpolated at t_camera − time_offset;
    camera samples outside the robot's time span, or inside a robot sampling interval longer
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
            raise ValueError(f"{camera.source}: only {len(camera)} samples, at least "
                             f"{min_samples} are needed (2 motions)")
        return AlignedSamples(robot.poses.copy(), camera.poses.copy(), None,
                              np.arange(len(camera)), camera.lines, camera.source, 0.0, (), ())
    interp = PoseInterpolator(robot.timestamps, robot.poses)
    if max_gap is None:
        max_gap = 5.0 * _median_period(robot.timestamps)
    q = camera.timestamps - time_offset
    t0, t1 = interp.span
    inside = (q >= t0) & (q <= t1)
    in_gap = np.zeros_like(inside)
    in_gap[inside] = interp.segment_length(q[inside]) > max_gap
    keep = inside & ~in_gap
    dropped_outside = tuple(camera.lines[k] for k in np.flatnonzero(~inside))
    dropped_gap = tuple(camera.lines[k] for k in np.flatnonzero(in_gap))
    if keep.sum() < min_samples:
        raise ValueError(
            f"{camera.source}: only {int(keep.sum())} of {len(camera)} camera samples fall inside "
            f"the robot's time span [{t0!r}, {t1!r}] s of {robot.source} (camera stamps "
            f"[{float(camera.timestamps[0])!r}, {float(camera.timestamps[-1])!r}] s, time offset "
            f"{time_offset!r} s){' outside its gaps' if in_gap.any() else ''}; at least "
            f"{min_samples} are needed — do the streams use the same clock and time unit?")
    idx = np.flatnonzero(keep)
    return AlignedSamples(interp(q[keep]), camera.poses[keep].copy(), camera.timestamps[keep],
                          idx, tuple(camera.lines[k] for k in idx), camera.source, time_offset,
                          dropped_outside, dropped_gap)


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


def _angles(R0: np.ndarray, R1: np.ndarray) -> np.ndarray:
    """Rotation angles of R0ᵀ R1 (rad), from the trace (clipped): fast, vectorized."""
    c = (np.einsum("kij,kij->k", R0, R1) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def estimate_time_offset(robot: PoseStream, camera: PoseStream, search_range: float = 0.5,
                         lags=(1, 2, 4, 8), step: float | None = None) -> TimeOffsetEstimate:
    """Estimates the constant offset (camera stamp − robot time) in [−search_range, search_range].

    For each lag L in ``lags`` the rotation angle θ_A of the camera motion between camera samples
    k and k+L is compared with the angle θ_B of the robot motion between the interpolated robot
    poses at the same instants. The cost is the mean of the 80 % smallest |θ_A − θ_B| on a grid
    of step ``step`` (default: a quarter of the smaller median sampling period, at most 2001
    points); around the best grid point a bounded scalar minimization of a Cauchy loss (scale
    from the residuals there, so outlying camera poses weigh little) refines the offset. Only
    camera samples whose robot instant stays inside the robot's time span for every candidate
    offset are used, so all candidates compare the same motions.

    Raises:
        UnobservableTimeOffset (a ValueError): too few samples overlapping for every candidate
            offset, a camera that barely rotates, a flat cost (rotation speed too uniform).
        ValueError: missing timestamps, a bad range, a cost minimum on the search bound (offset
            larger than the range, or streams that do not match).
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
    interp = PoseInterpolator(robot.timestamps, robot.poses)
    t0, t1 = interp.span
    tc = camera.timestamps
    ok = np.flatnonzero((tc - R >= t0) & (tc + R <= t1))
    if len(ok) < 4:
        raise UnobservableTimeOffset(
            f"time offset estimation: only {len(ok)} camera samples of {camera.source} stay "
            f"inside the robot's time span [{t0!r}, {t1!r}] s for every offset in ±{R:g} s; "
            "need at least 4 — reduce the search range or check that both streams use the "
            "same clock")
    R_CT = camera.poses[ok, :3, :3]
    tq = tc[ok]
    firsts, seconds = [], []
    for L in lags:
        if L < len(ok):
            firsts.append(np.arange(len(ok) - L))
            seconds.append(np.arange(L, len(ok)))
    k0, k1 = np.concatenate(firsts), np.concatenate(seconds)
    # The camera motion A = R_CT[k0] R_CT[k1]ᵀ has the angle of R_CT[k0]ᵀ R_CT[k1] (conjugate).
    theta_A = _angles(R_CT[k0], R_CT[k1])
    if np.median(theta_A) < np.radians(0.05):
        raise UnobservableTimeOffset(
            f"time offset estimation: the camera barely rotates (median motion "
            f"{np.degrees(np.median(theta_A)):.3g}° between compared samples); the offset is "
            "unobservable, pass --time-offset SECONDS instead")

    def residuals(delta: float) -> np.ndarray:
        R_BE = interp.rotations(tq - delta)
        return theta_A - _angles(R_BE[k0], R_BE[k1])

    def trimmed(delta: float) -> float:
        r = np.sort(np.abs(residuals(delta)))
        return float(r[:max(1, int(0.8 * len(r)))].mean())

    if step is None:
        periods = [_median_period(robot.timestamps), _median_period(tc)]
        step = min(p for p in periods if math.isfinite(p)) / 4.0
    step = max(float(step), 2.0 * R / 2000.0)
    n = int(math.ceil(R / step))
    grid = np.linspace(-R, R, 2 * n + 1)
    cost = np.array([trimmed(d) for d in grid])
    best = int(np.argmin(cost))
    if best in (0, len(grid) - 1):
        raise ValueError(
            f"time offset estimation: the best offset lies on the search bound "
            f"({grid[best]:+.4g} s of ±{R:g} s): the offset is larger than the range, or the "
            "streams do not match — widen --time-offset-range or check the timestamps")
    spread = float(np.median(cost) - cost[best])
    # Flat: no clear minimum, relative to the noise floor and to the motion sizes (rounding).
    if not spread > max(0.05 * cost[best], 1e-6 * float(np.median(theta_A))):
        raise UnobservableTimeOffset(
            f"time offset estimation: the cost is flat over ±{R:g} s (best {cost[best]:.3g} "
            f"rad, median {np.median(cost):.3g} rad): the rotation speed is too uniform to "
            "observe a time offset; pass --time-offset SECONDS instead")
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

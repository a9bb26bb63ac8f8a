"""Interpolation of a stack of timed rigid poses: linear in translation, SLERP (constant-speed
geodesic) in rotation.

Scale: the interpolator computes the relative rotation of a sampling interval only when a query
falls in it, so building one for 10⁶ samples costs a validation pass, and queries cost what they
touch.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

_BLOCK = 1 << 16  # queries interpolated at a time: bounded temporaries


def _log_rotations(M: np.ndarray) -> np.ndarray:
    """Rotation vectors of a stack of rotation matrices: from the skew part and the trace
    (θ = atan2(sin θ, cos θ), accurate at small angles); scipy's from_matrix near π, where the
    skew part vanishes."""
    s = 0.5 * np.stack([M[:, 2, 1] - M[:, 1, 2], M[:, 0, 2] - M[:, 2, 0],
                        M[:, 1, 0] - M[:, 0, 1]], axis=1)
    sin = np.sqrt(np.einsum("ni,ni->n", s, s))
    cos = 0.5 * (np.trace(M, axis1=1, axis2=2) - 1.0)
    theta = np.arctan2(sin, cos)
    factor = np.ones_like(theta)
    nz = sin > 0
    factor[nz] = theta[nz] / sin[nz]
    out = factor[:, None] * s
    far = cos < -0.5  # beyond 120°
    if far.any():
        out[far] = Rotation.from_matrix(M[far]).as_rotvec()
    return out


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
        if not np.all(self.times[1:] > self.times[:-1]):
            raise ValueError("times: must be strictly increasing")
        self._R = self.poses[:, :3, :3]
        self._p = self.poses[:, :3, 3]
        # ω_i with R_{i+1} = R_i exp([ω_i]×), computed for the intervals queries fall in.
        n = max(len(self.times) - 1, 0)
        self._segment_rotvec_cache = np.empty((n, 3))
        self._segment_known = np.zeros(n, dtype=bool)

    def _segment_rotvec(self, i: np.ndarray) -> np.ndarray:
        """ω of the sampling intervals i (computed once each)."""
        missing = i[~self._segment_known[i]]
        if len(missing):
            if len(missing) > len(self._segment_known) // 16:
                need = np.zeros(len(self._segment_known), dtype=bool)
                need[missing] = True
                missing = np.flatnonzero(need)
            else:
                missing = np.unique(missing)
            for b in range(0, len(missing), _BLOCK):
                m = missing[b:b + _BLOCK]
                self._segment_rotvec_cache[m] = _log_rotations(
                    np.einsum("nki,nkj->nij", self._R[m], self._R[m + 1]))
            self._segment_known[missing] = True
        return self._segment_rotvec_cache[i]

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
        with np.errstate(over="ignore"):
            length = self.times[i + 1] - self.times[i]
        return np.where((s == 0) | (s == 1), 0.0, length)

    def _locate(self, q):
        if len(self.times) == 1:
            return np.zeros(q.shape, dtype=int), np.zeros(q.shape)
        i = np.clip(np.searchsorted(self.times, q, side="right") - 1, 0, len(self.times) - 2)
        with np.errstate(over="ignore", invalid="ignore"):  # huge spans: clipped below
            s = (q - self.times[i]) / (self.times[i + 1] - self.times[i])
        return i, np.clip(np.nan_to_num(s, nan=0.0), 0.0, 1.0)

    def _rotations(self, i: np.ndarray, s: np.ndarray, out: np.ndarray) -> None:
        """out[k] = R_i exp(s ω_i) for located queries, block by block (bounded temporaries)."""
        if len(self.times) == 1:
            out[:] = self._R[i]
            return
        for b in range(0, len(i), _BLOCK):
            ib, sb = i[b:b + _BLOCK], s[b:b + _BLOCK]
            out[b:b + _BLOCK] = self._R[ib] @ Rotation.from_rotvec(
                sb[:, None] * self._segment_rotvec(ib)).as_matrix()

    def rotations(self, query_times) -> np.ndarray:
        """(M, 3, 3) interpolated rotations (queries must lie inside ``span``)."""
        q = self._check(query_times)
        i, s = self._locate(q)
        out = np.empty((len(q), 3, 3))
        self._rotations(i, s, out)
        return out

    def __call__(self, query_times) -> np.ndarray:
        """(M, 4, 4) interpolated poses (queries must lie inside ``span``)."""
        q = self._check(query_times)
        i, s = self._locate(q)
        X = np.zeros((len(q), 4, 4))
        X[:, 3, 3] = 1.0
        self._rotations(i, s, X[:, :3, :3])
        if len(self.times) == 1:
            X[:, :3, 3] = self._p[i]
        else:
            for b in range(0, len(q), _BLOCK):
                ib, sb = i[b:b + _BLOCK], s[b:b + _BLOCK]
                X[b:b + _BLOCK, :3, 3] = self._p[ib] + sb[:, None] * (self._p[ib + 1]
                                                                       - self._p[ib])
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

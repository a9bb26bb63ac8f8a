"""Shared pieces of the paper's experiments (docs/method.md §8): the batched paper filter,
error measures over stacks, and the result/task types of a sweep. numpy/scipy only.

Reproducibility: every simulated run r of an experiment draws from its own generator
``numpy.random.default_rng(SeedSequence(seed, spawn_key=(code, r)))`` (``run_rng``), so results
do not depend on how runs are chunked into tasks or spread over workers. Within an experiment the
noise levels share each run's draws (common random numbers: the same X, robot motions and
unit-variance noise, scaled by the level), which makes level-to-level comparisons less noisy
than independent draws would.

Units: the paper's "length units" (robot translations have std 1, hand-eye translations std 100).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from scipy.spatial.transform import Rotation

#: Std of an angle drawn uniformly in [0, 2π): the "spread" of X's roll-pitch-yaw angles.
X_RPY_STD = 2.0 * np.pi / np.sqrt(12.0)


def run_rng(seed: int, code: int, run: int) -> np.random.Generator:
    """The generator of run ``run`` of the experiment numbered ``code``."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(int(code),
                                                                                int(run))))


# ---------------------------------------------------------------------------------------------
# Rotations and errors over stacks.

def quat_wxyz(R: np.ndarray) -> np.ndarray:
    """(n, 4) unit quaternions [w, x, y, z] of (n, 3, 3) rotations."""
    xyzw = Rotation.from_matrix(R).as_quat()
    return np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)


def horn_quaternions(M: np.ndarray) -> np.ndarray:
    """Horn's minimization for a stack (n, 3, 3): the unit quaternions [w, x, y, z] of the
    rotations maximizing tr(Rᵀ M) (eigenvector of the largest eigenvalue of the symmetric 4×4
    ``orthonormalize.horn_matrix``), vectorized."""
    S = np.swapaxes(M, -1, -2)
    Sxx, Sxy, Sxz = S[:, 0, 0], S[:, 0, 1], S[:, 0, 2]
    Syx, Syy, Syz = S[:, 1, 0], S[:, 1, 1], S[:, 1, 2]
    Szx, Szy, Szz = S[:, 2, 0], S[:, 2, 1], S[:, 2, 2]
    N = np.stack([
        np.stack([Sxx + Syy + Szz, Syz - Szy, Szx - Sxz, Sxy - Syx], axis=-1),
        np.stack([Syz - Szy, Sxx - Syy - Szz, Sxy + Syx, Szx + Sxz], axis=-1),
        np.stack([Szx - Sxz, Sxy + Syx, -Sxx + Syy - Szz, Syz + Szy], axis=-1),
        np.stack([Sxy - Syx, Szx + Sxz, Syz + Szy, -Sxx - Syy + Szz], axis=-1),
    ], axis=-2)
    return np.linalg.eigh(N)[1][..., :, -1]


def quaternion_distance(q: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """‖q − q̂‖, sign-safe (min over ±q̂), along the last axis."""
    return np.minimum(np.linalg.norm(q - q_true, axis=-1), np.linalg.norm(q + q_true, axis=-1))


def state_errors(states: np.ndarray, X_true: np.ndarray):
    """Errors of filter states against the truth, docs/method.md §8's measures.

    Args:
        states: (R, K+1, 12) raw states [vec_row(R_X); t_X] of R runs.
        X_true: (R, 4, 4) the true X_CE of each run.

    Returns:
        (rotation, translation), each (R, K+1): ‖q − q̂‖ of the Horn projection of the rotation
        rows, and ‖t − t̂‖ / ‖t‖.
    """
    n_runs, n_steps = states.shape[:2]
    q = horn_quaternions(states[..., :9].reshape(-1, 3, 3)).reshape(n_runs, n_steps, 4)
    q_true = quat_wxyz(X_true[:, :3, :3])[:, None, :]
    t_true = X_true[:, None, :3, 3]
    translation = (np.linalg.norm(states[..., 9:] - t_true, axis=-1)
                   / np.linalg.norm(t_true, axis=-1))
    return quaternion_distance(q, q_true), translation


def curve_stats(errors: np.ndarray, axis: int = 0) -> dict:
    """min, max, mean and RMS of errors over runs (``axis``)."""
    return {"min": errors.min(axis=axis), "max": errors.max(axis=axis),
            "mean": errors.mean(axis=axis), "rms": np.sqrt(np.mean(errors**2, axis=axis))}


# ---------------------------------------------------------------------------------------------
# The paper's Kalman filter, batched over runs.

def linear_systems(A: np.ndarray, B: np.ndarray):
    """docs/method.md §3's C (n, 12, 12) and y (n, 12) for stacks of motions A, B (n, 4, 4): the batched
    ``linear_model.linear_system_matrices``."""
    n = len(A)
    R_A, t_A, R_B, t_B = A[:, :3, :3], A[:, :3, 3], B[:, :3, :3], B[:, :3, 3]
    C = np.zeros((n, 12, 12))
    # kron(R_A, R_B)[3i+k, 3j+l] = R_A[i, j] R_B[k, l]
    C[:, :9, :9] = np.eye(9) - np.einsum("nij,nkl->nikjl", R_A, R_B).reshape(n, 9, 9)
    for i in range(3):
        C[:, 9 + i, 3 * i:3 * i + 3] = t_B
    C[:, 9:, 9:] = np.eye(3) - R_A
    y = np.zeros((n, 12))
    y[:, 9:] = t_A
    return C, y


def batched_paper_filter(x0: np.ndarray, A: np.ndarray, B: np.ndarray, G2: np.ndarray,
                         P0: np.ndarray | None = None, G1: np.ndarray | None = None) -> np.ndarray:
    """docs/method.md §4's Kalman filter run on R independent runs at once.

    The same arithmetic as ``kalman.kalman_step`` (gain K = P Cᵀ S⁻¹, Joseph-form covariance), with
    a fixed G2 (the paper's tuning, docs/method.md §5) so S stays positive definite.

    Args:
        x0: (R, 12) initial states.
        A, B: (R, K, 4, 4) camera (possibly non-orthonormal) and robot motions.
        G2: (12, 12) measurement covariance; P0: initial covariance (default I12, the paper's);
        G1: process covariance (default 0).

    Returns:
        (R, K+1, 12): the state before any motion, then after each of the K motions.
    """
    n_runs, K = A.shape[:2]
    I12 = np.eye(12)
    x = np.array(x0, dtype=float)
    P = np.tile(I12 if P0 is None else P0, (n_runs, 1, 1))
    states = np.empty((n_runs, K + 1, 12))
    states[:, 0] = x
    for k in range(K):
        C, y = linear_systems(A[:, k], B[:, k])
        CP = C @ P
        S = CP @ np.swapaxes(C, 1, 2) + G2
        Kt = np.linalg.solve(S, CP)  # Kᵀ = S⁻¹ C P (P, S symmetric)
        Kg = np.swapaxes(Kt, 1, 2)
        x = x + np.einsum("nij,nj->ni", Kg, y - np.einsum("nij,nj->ni", C, x))
        IKC = I12 - Kg @ C
        P = IKC @ P @ np.swapaxes(IKC, 1, 2) + Kg @ G2 @ Kt
        if G1 is not None:
            P = P + G1
        P = 0.5 * (P + np.swapaxes(P, 1, 2))
        states[:, k + 1] = x
    return states


# ---------------------------------------------------------------------------------------------
# Sweeps: tasks and results.

@dataclass(frozen=True)
class Task:
    """One unit of work sent to an executor: ``fn(*args)``; ``key`` orders the results."""
    key: tuple
    fn: Callable
    args: tuple


@dataclass
class SweepResult:
    """What one experiment produced.

    Attributes:
        experiment: the experiment's name (see ``experiments.EXPERIMENTS``).
        figures: the paper figures it reproduces.
        runs, seed: as requested.
        levels: the swept values (noise σ, perturbation fraction, ...), ``level_name`` names them.
        data: named numpy arrays (shapes documented by each experiment).
        meta: settings and counters (JSON-friendly), e.g. solver failures.
        cpu_time: summed wall time of the tasks inside the workers (s).
    """
    experiment: str
    figures: tuple
    runs: int
    seed: int
    levels: list
    level_name: str
    data: dict = field(default_factory=dict)
    meta: dict = field(default_factory=dict)
    cpu_time: float = 0.0


def pyplot():
    """matplotlib.pyplot on the headless Agg backend."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def chunks(n: int, size: int) -> list[tuple[int, int]]:
    """[start, stop) ranges covering range(n) in pieces of at most ``size``."""
    return [(s, min(n, s + size)) for s in range(0, n, size)]


def fmt(v: Any) -> str:
    """Deterministic text of a CSV cell."""
    if isinstance(v, (float, np.floating)):
        return "nan" if not np.isfinite(v) else f"{float(v):.10g}"
    return str(v)


def write_csv(path, header: list[str], rows) -> None:
    with open(path, "w") as f:
        f.write(",".join(header) + "\n")
        for row in rows:
            f.write(",".join(fmt(v) for v in row) + "\n")

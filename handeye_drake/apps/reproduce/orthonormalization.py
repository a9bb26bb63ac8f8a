"""Figure 2: error of the projection onto SO(3) of a noisy rotation matrix — SVD, QR and Horn's
quaternion minimization (docs/method.md §6).

Each run draws a rotation R (roll-pitch-yaw uniform in [0, 2π), like the paper's X) and unit
Gaussian noise N (3×3); at noise level σ the "measured" matrix is M = R + σ N (the paper's
additive coefficient noise), projected with the project's ``orthonormalize`` methods. The error is
docs/method.md §8's ‖q − q̂‖ between the true and recovered unit quaternions.

Expected: SVD (with the determinant fix) and Horn reach the same optimum — the nearest rotation in
Frobenius norm — so they agree to rounding; QR keeps the first column's direction exactly and is
less accurate.

Data: ``errors`` (L, runs, 3) for the methods in ``METHODS``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ...estimation.orthonormalize import orthonormalize_unchecked
from .common import (
    SweepResult,
    Task,
    chunks,
    curve_stats,
    pyplot,
    quat_wxyz,
    quaternion_distance,
    run_rng,
    write_csv,
)

NAME = "orthonormalization"
FIGURES = ("fig2",)
CODE = 2
DEFAULT_RUNS = 1000
LEVELS = (0.001, 0.01, 0.05, 0.1, 0.5, 1.0)
METHODS = ("svd", "qr", "horn")
LABELS = {"svd": "SVD (with det fix; coincides with Horn)", "qr": "QR",
          "horn": "minimization (Horn)"}
STYLES = {"svd": "--", "qr": "-.", "horn": "-"}


def _task(seed: int, sigma: float, start: int, stop: int) -> tuple[np.ndarray, float]:
    t0 = time.perf_counter()
    errors = np.empty((stop - start, len(METHODS)))
    for i, run in enumerate(range(start, stop)):
        rng = run_rng(seed, CODE, run)
        R = Rotation.from_euler("xyz", rng.uniform(0.0, 2.0 * np.pi, 3)).as_matrix()
        M = R + sigma * rng.normal(size=(3, 3))
        projected = np.array([orthonormalize_unchecked(M, m) for m in METHODS])
        errors[i] = quaternion_distance(quat_wxyz(projected), quat_wxyz(R[None])[0])
    return errors, time.perf_counter() - t0


def tasks(runs: int, seed: int, options: dict) -> list[Task]:
    return [Task(key=(li, a), fn=_task, args=(seed, float(s), a, b))
            for li, s in enumerate(LEVELS) for a, b in chunks(runs, 500)]


def assemble(results: dict, runs: int, seed: int, options: dict) -> SweepResult:
    errors = np.empty((len(LEVELS), runs, len(METHODS)))
    cpu = 0.0
    for (li, a), (e, dt) in results.items():
        errors[li, a:a + len(e)] = e
        cpu += dt
    return SweepResult(experiment=NAME, figures=FIGURES, runs=runs, seed=seed,
                       levels=list(LEVELS), level_name="sigma", data={"errors": errors},
                       meta={"methods": list(METHODS)}, cpu_time=cpu)


def stats(result: SweepResult) -> dict:
    """{method: {stat: (L,)}} over runs."""
    e = result.data["errors"]
    return {m: curve_stats(e[:, :, j], axis=1) for j, m in enumerate(METHODS)}


def write(result: SweepResult, figure: str, out: Path,
          plot: bool = True) -> list[Path]:
    s = stats(result)
    e = result.data["errors"]
    csv = out / f"{figure}.csv"
    write_csv(csv, ["method", "sigma", "runs", "min", "max", "mean", "rms"],
              [(m, sig, result.runs, s[m]["min"][li], s[m]["max"][li], s[m]["mean"][li],
                s[m]["rms"][li]) for m in METHODS for li, sig in enumerate(result.levels)])
    if not plot:
        return [csv]
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    sig = np.asarray(result.levels)
    for m in METHODS:
        axes[0].loglog(sig, s[m]["mean"], STYLES[m], color="k", marker="o", ms=3,
                       label=LABELS[m])
    axes[0].set_xlabel("noise σ on each coefficient of R")
    axes[0].set_ylabel("mean ‖q − q̂‖")
    axes[0].set_title(f"Fig. 2: rotation recovered from R + σN ({result.runs} per level)")
    axes[0].legend()
    axes[0].grid(True, which="both", alpha=0.3)
    for j, m in enumerate(METHODS[1:], start=1):
        diff = np.max(np.abs(e[:, :, j] - e[:, :, 0]), axis=1)
        axes[1].semilogy(sig, np.maximum(diff, 1e-17), STYLES[m], color="k", marker="o", ms=3,
                         label=f"{LABELS[m]} − SVD")
    axes[1].set_xscale("log")
    axes[1].set_xlabel("noise σ")
    axes[1].set_ylabel("max over runs of |error − SVD's error|")
    axes[1].set_title("Horn = SVD to rounding; QR differs")
    axes[1].legend()
    axes[1].grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    png = out / f"{figure}.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return [png, csv]


def summary(result: SweepResult, figure: str) -> str:
    s = stats(result)
    e = result.data["errors"]
    lines = [f"### Fig. 2 — orthonormalization error ‖q − q̂‖ of R + σN ({result.runs} matrices "
             "per level)", "",
             "| σ | SVD mean | SVD RMS | QR mean | QR RMS | Horn mean | Horn RMS | "
             "max abs(Horn − SVD) |", "|---|---|---|---|---|---|---|---|"]
    for li, sig in enumerate(result.levels):
        d = np.max(np.abs(e[li, :, 2] - e[li, :, 0]))
        cells = [f"{s[m][k][li]:.4g}" for m in METHODS for k in ("mean", "rms")]
        lines.append(f"| {sig:g} | " + " | ".join(cells) + f" | {d:.1e} |")
    return "\n".join(lines) + "\n"

"""Figure 9: the two-motion initial estimate — Tsai–Lenz vs Daniilidis (docs/method.md §1, §8).

Each run draws X = X_CE as in Figs 3–8 (rpy uniform in [0, 2π), translation std 100), executes
the two predefined self-calibration motions (30° about E's x then y axis) and measures the camera
motions with docs/method.md §5's noise: σ on every coefficient of R_A (σ ∈ LEVELS) and 0.1 on t_A (as in
Figs 3–4, so each level's Daniilidis solution is the start of the filter there). Both methods
(``solve_ax_xb`` with ``orthonormalize_inputs=True``) solve the same noisy pair.

A third solver is ours, not the paper's: Daniilidis on translations divided by their mean norm
(``daniilidis_scaled``), the result scaled back. Daniilidis' SVD mixes rotation rows (unitless) and
dual rows (length units) in one least-squares problem, so with ‖t_X‖ ≈ 170 the translation noise
leaks into the rotation; rescaling removes that unit dependence.

Runs where the solvers reject the motions (ValueError: e.g. the rotation angles of A and B
disagree grossly at σ ≥ 0.5) count as failures; statistics are over the other runs.

Data: ``errors`` (L, runs, 3 solvers, 2) — [‖q − q̂‖, ‖t − t̂‖/‖t‖], NaN for failures.
"""

from __future__ import annotations

import time
from pathlib import Path

import warnings

import numpy as np

from ...estimation.solvers import solve_ax_xb
from ...estimation.synthetic import (
    add_coefficient_noise,
    camera_motions,
    random_hand_eye,
    self_calibration_motions,
)
from .common import (
    SweepResult,
    Task,
    chunks,
    pyplot,
    quat_wxyz,
    quaternion_distance,
    run_rng,
    write_csv,
)

NAME = "two_motion"
FIGURES = ("fig9",)
CODE = 9
DEFAULT_RUNS = 500
LEVELS = (0.0, 0.001, 0.005, 0.01, 0.05, 0.1, 0.5, 1.0)
TRANSLATION_SIGMA = 0.1
SOLVERS = ("tsai", "daniilidis", "daniilidis_scaled")
LABELS = {"tsai": "Tsai–Lenz [11]", "daniilidis": "Daniilidis [2]",
          "daniilidis_scaled": "Daniilidis, translations normalized (ours)"}
STYLES = {"tsai": "--", "daniilidis": "-", "daniilidis_scaled": ":"}
RUN_CHUNK = 250


def solve(A: list, B: list, solver: str) -> np.ndarray:
    """X_CE from the motion pairs with one of ``SOLVERS`` (raises ValueError like solve_ax_xb)."""
    if solver != "daniilidis_scaled":
        return solve_ax_xb(A, B, solver, orthonormalize_inputs=True)
    norms = [np.linalg.norm(M[:3, 3]) for M in list(A) + list(B)]
    norms = [v for v in norms if v > 0]
    scale = float(np.mean(norms)) if norms else 1.0
    A, B = [np.array(M, dtype=float) for M in A], [np.array(M, dtype=float) for M in B]
    for M in A + B:
        M[:3, 3] /= scale  # A X = X B holds for (t_A, t_B, t_X) / scale
    X = solve_ax_xb(A, B, "daniilidis", orthonormalize_inputs=True)
    X[:3, 3] *= scale
    return X


def _task(seed: int, sigma: float, start: int, stop: int) -> tuple[np.ndarray, float]:
    t0 = time.perf_counter()
    B = self_calibration_motions()
    n = stop - start
    X = np.empty((n, 4, 4))
    X_hat = np.full((n, len(SOLVERS), 4, 4), np.nan)
    for i, run in enumerate(range(start, stop)):
        rng = run_rng(seed, CODE, run)
        X[i] = random_hand_eye(rng)
        A = add_coefficient_noise(camera_motions(X[i], B), rng.normal(size=(2, 3, 3)),
                                  rng.normal(size=(2, 3)), sigma, TRANSLATION_SIGMA)
        for j, solver in enumerate(SOLVERS):
            try:
                X_hat[i, j] = solve(list(A), list(B), solver)
            except ValueError:
                pass
    # docs/method.md §8's errors (as errors.rotation_error_quat / translation_error_rel), vectorized.
    errors = np.full((n, len(SOLVERS), 2), np.nan)
    ok = np.isfinite(X_hat[:, :, 0, 0])
    q_true = np.repeat(quat_wxyz(X[:, :3, :3])[:, None], len(SOLVERS), axis=1)
    errors[ok, 0] = quaternion_distance(quat_wxyz(X_hat[ok][:, :3, :3]), q_true[ok])
    t_true = np.repeat(X[:, None, :3, 3], len(SOLVERS), axis=1)[ok]
    errors[ok, 1] = (np.linalg.norm(X_hat[ok][:, :3, 3] - t_true, axis=1)
                     / np.linalg.norm(t_true, axis=1))
    return errors, time.perf_counter() - t0


def tasks(runs: int, seed: int, options: dict) -> list[Task]:
    return [Task(key=(li, a), fn=_task, args=(seed, float(s), a, b))
            for li, s in enumerate(LEVELS) for a, b in chunks(runs, RUN_CHUNK)]


def assemble(results: dict, runs: int, seed: int, options: dict) -> SweepResult:
    errors = np.empty((len(LEVELS), runs, len(SOLVERS), 2))
    cpu = 0.0
    for (li, a), (e, dt) in results.items():
        errors[li, a:a + len(e)] = e
        cpu += dt
    return SweepResult(experiment=NAME, figures=FIGURES, runs=runs, seed=seed,
                       levels=list(LEVELS), level_name="sigma_rotation",
                       data={"errors": errors},
                       meta={"solvers": list(SOLVERS), "translation_sigma": TRANSLATION_SIGMA,
                             "motions": "30° about E's x, then y"}, cpu_time=cpu)


def stats(result: SweepResult) -> dict:
    """{(solver, part): {stat: (L,)}} over the successful runs; part 0 rotation, 1 translation;
    plus ``failures`` (L,) per solver."""
    e = result.data["errors"]
    out = {}
    for j, solver in enumerate(SOLVERS):
        ok = np.isfinite(e[:, :, j, 0])
        out[solver, "failures"] = (~ok).sum(axis=1)
        for p in (0, 1):
            v = e[:, :, j, p]
            with np.errstate(invalid="ignore"), warnings.catch_warnings():
                # A level where every run failed has no statistics: NaN, said by "failures".
                warnings.simplefilter("ignore", RuntimeWarning)
                out[solver, p] = {"min": np.nanmin(v, axis=1), "max": np.nanmax(v, axis=1),
                                  "mean": np.nanmean(v, axis=1),
                                  "rms": np.sqrt(np.nanmean(v**2, axis=1))}
    return out


def write(result: SweepResult, figure: str, out: Path,
          plot: bool = True) -> list[Path]:
    s = stats(result)
    csv = out / f"{figure}.csv"
    rows = []
    for solver in SOLVERS:
        for li, sig in enumerate(result.levels):
            n_fail = int(s[solver, "failures"][li])
            for p, part in enumerate(("rotation", "translation")):
                st = s[solver, p]
                rows.append((solver, part, sig, result.runs - n_fail, n_fail, st["min"][li],
                             st["max"][li], st["mean"][li], st["rms"][li]))
    write_csv(csv, ["solver", "error", "sigma_rotation", "runs_ok", "runs_failed", "min", "max",
                    "mean", "rms"], rows)

    if not plot:
        return [csv]
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    sig = np.asarray(result.levels)
    for p, (ax, title) in enumerate(zip(axes, ("rotation error ‖q − q̂‖ (mean)",
                                               "relative translation error (mean)"))):
        for solver in SOLVERS:
            ax.plot(sig, s[solver, p]["mean"], STYLES[solver], color="k", marker="o", ms=3,
                    label=LABELS[solver])
        ax.set_xscale("symlog", linthresh=1e-3)
        ax.set_yscale("log")
        ax.set_xlabel("noise σ on each coefficient of R_A (t_A noise 0.1)")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"Fig. 9: two-motion initial estimate, {result.runs} runs per level")
    fig.tight_layout()
    png = out / f"{figure}.png"
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return [png, csv]


def summary(result: SweepResult, figure: str) -> str:
    s = stats(result)
    lines = [f"### Fig. 9 — two-motion estimate, Tsai–Lenz vs Daniilidis ({result.runs} runs "
             "per level; rotation ‖q − q̂‖, translation relative; mean / RMS over successful "
             "runs)", "",
             "Two predefined motions (30° about E's x, then y), camera motions measured with σ on "
             f"every coefficient of R_A and {TRANSLATION_SIGMA:g} on t_A; X as in Figs 3–8 "
             "(‖t_X‖ ≈ 170). \"Dan. normalized\": Daniilidis on translations divided by their "
             "mean norm (ours). Failed runs: both solvers reject the motions (ValueError).", "",
             "| σ on R_A | failed runs | Tsai rot. | Daniilidis rot. | Dan. normalized rot. | "
             "Tsai transl. | Daniilidis transl. | Dan. normalized transl. |",
             "|---|---|---|---|---|---|---|---|"]
    for li, sig in enumerate(result.levels):
        cells = [f"{s[solver, p]['mean'][li]:.4g} / {s[solver, p]['rms'][li]:.4g}"
                 for p in (0, 1) for solver in SOLVERS]
        fails = int(max(s[solver, "failures"][li] for solver in SOLVERS))
        lines.append(f"| {sig:g} | {fails} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"

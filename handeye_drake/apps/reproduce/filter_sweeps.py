"""Figures 3–8: the paper's Kalman filter on the paper's random small robot motions (docs/method.md §8).

Each run draws a hand-eye X = X_CE (roll-pitch-yaw uniform in [0, 2π), translation std 100),
K robot motions B (rpy ~ N(0, (2π/100)²), translation ~ N(0, 1)), the exact camera motions
A = X B X⁻¹ and measures them with docs/method.md §5's additive noise (σ_r on every coefficient of R_A,
σ_t on t_A). The filter (docs/method.md §4) starts from an initial estimate with P0 = I12, G1 = 0 and is
tuned for σ = 0.1: G2 = 0.01 I12. Errors are recorded before any motion (index 0, the initial
estimate) and after each motion; per level the curves are min, max, mean and RMS over the runs.

- ``rotation_noise`` (Figs 3, 4): σ_r ∈ LEVELS, σ_t = 0.1 (what the filter expects).
- ``translation_noise`` (Figs 5, 6): σ_t ∈ LEVELS. The paper does not state the rotation noise
  of this sweep; we set σ_r = 0 ("noise in the rotation part and in the translation part studied
  separately"). With σ_r = 0.1 the term Δ_A t_X (‖t_X‖ ≈ 170) swamps every σ_t ≤ 1 and the six
  curves coincide.
- For Figs 3–6 the paper does not say where the filter starts: we use the two-motion Daniilidis
  solution of the two predefined self-calibration motions (30° about E's x then y axis), measured
  with the same noise (its rotation blocks projected on SO(3) first). When Daniilidis rejects the
  noisy motions (only at σ_r ≥ 0.5) the filter starts from X = identity; ``init_failures`` counts
  these runs.
- ``initial_estimate`` (Figs 7, 8): the start is the truth with white noise on its roll-pitch-yaw
  angles and translation, of std p × (the spread used to draw X: 2π/√12 rad — the std of a
  uniform angle on [0, 2π) — and 100), p ∈ INIT_LEVELS. Measurement noise σ_r = 0, σ_t = 0.1
  (the paper does not state it).

Data: ``rotation`` and ``translation`` (L, runs, K+1) errors, ``init_failures`` (L,).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ...estimation.solvers import solve_ax_xb
from ...estimation.synthetic import (
    X_TRANSLATION_SIGMA,
    add_coefficient_noise,
    camera_motions,
    random_hand_eye,
    random_robot_motions,
    self_calibration_motions,
    transforms,
)
from .common import (
    X_RPY_STD,
    SweepResult,
    Task,
    batched_paper_filter,
    chunks,
    curve_stats,
    pyplot,
    run_rng,
    state_errors,
    write_csv,
)

LEVELS = (0.0, 0.01, 0.05, 0.1, 0.5, 1.0)
INIT_LEVELS = (0.0, 0.05, 0.10, 0.50, 0.75, 1.00)
DEFAULT_RUNS = 50
DEFAULT_MOTIONS = 100
#: The filter is tuned for σ = 0.1 on every measured coefficient: G2 = 0.01 I12.
FILTER_SIGMA = 0.1
#: The noise held fixed while another is swept.
NOMINAL_TRANSLATION_SIGMA = 0.1
FIG56_ROTATION_SIGMA = 0.0
FIG78_NOISE = (0.0, 0.1)
RUN_CHUNK = 50

#: name → (code, figures (rotation, translation), levels, level_name, description)
SWEEPS = {
    "rotation_noise": (3, ("fig3", "fig4"), LEVELS, "sigma_rotation",
                       "rotation noise σ on R_A coefficients (translation noise 0.1)"),
    "translation_noise": (5, ("fig5", "fig6"), LEVELS, "sigma_translation",
                          "translation noise σ on t_A (no rotation noise)"),
    "initial_estimate": (7, ("fig7", "fig8"), INIT_LEVELS, "perturbation",
                         "initial estimate = truth + noise at p × the spread of X "
                         "(noise σ_r = 0, σ_t = 0.1)"),
}


def _noise_of(kind: str, level: float) -> tuple[float, float]:
    if kind == "rotation_noise":
        return level, NOMINAL_TRANSLATION_SIGMA
    if kind == "translation_noise":
        return FIG56_ROTATION_SIGMA, level
    return FIG78_NOISE


def _task(kind: str, seed: int, level: float, start: int, stop: int, K: int) -> dict:
    t0 = time.perf_counter()
    code = SWEEPS[kind][0]
    sr, st = _noise_of(kind, level)
    n = stop - start
    X = np.empty((n, 4, 4))
    A = np.empty((n, K, 4, 4))
    B = np.empty((n, K, 4, 4))
    X0 = np.empty((n, 4, 4))
    B_cal = self_calibration_motions()
    failures = 0
    for i, run in enumerate(range(start, stop)):
        rng = run_rng(seed, code, run)
        # Fixed draw order, identical for every level (common random numbers).
        X[i] = random_hand_eye(rng)
        B[i] = random_robot_motions(rng, K)
        unit_D, unit_v = rng.normal(size=(K, 3, 3)), rng.normal(size=(K, 3))
        cal_D, cal_v = rng.normal(size=(2, 3, 3)), rng.normal(size=(2, 3))
        rpy_noise, t_noise = rng.normal(size=3), rng.normal(size=3)
        A[i] = add_coefficient_noise(camera_motions(X[i], B[i]), unit_D, unit_v, sr, st)
        if kind == "initial_estimate":
            rpy = Rotation.from_matrix(X[i, :3, :3]).as_euler("xyz") + level * X_RPY_STD * rpy_noise
            X0[i] = transforms(Rotation.from_euler("xyz", rpy).as_matrix(),
                               X[i, :3, 3] + level * X_TRANSLATION_SIGMA * t_noise)
        else:
            A_cal = add_coefficient_noise(camera_motions(X[i], B_cal), cal_D, cal_v, sr, st)
            try:
                X0[i] = solve_ax_xb(list(A_cal), list(B_cal), "daniilidis",
                                    orthonormalize_inputs=True)
            except ValueError:
                X0[i] = np.eye(4)
                failures += 1
    x0 = np.concatenate([X0[:, :3, :3].reshape(n, 9), X0[:, :3, 3]], axis=1)
    G2 = FILTER_SIGMA**2 * np.eye(12)
    states = batched_paper_filter(x0, A, B, G2)
    rotation, translation = state_errors(states, X)
    return {"rotation": rotation, "translation": translation, "init_failures": failures,
            "cpu_time": time.perf_counter() - t0}


def tasks(kind: str, runs: int, seed: int, options: dict) -> list[Task]:
    K = int(options.get("motions", DEFAULT_MOTIONS))
    levels = SWEEPS[kind][2]
    return [Task(key=(li, a), fn=_task, args=(kind, seed, float(lv), a, b, K))
            for li, lv in enumerate(levels) for a, b in chunks(runs, RUN_CHUNK)]


def assemble(kind: str, results: dict, runs: int, seed: int, options: dict) -> SweepResult:
    code, figures, levels, level_name, description = SWEEPS[kind]
    K = int(options.get("motions", DEFAULT_MOTIONS))
    rot = np.empty((len(levels), runs, K + 1))
    tra = np.empty_like(rot)
    failures = np.zeros(len(levels), dtype=int)
    cpu = 0.0
    for (li, a), r in results.items():
        rot[li, a:a + len(r["rotation"])] = r["rotation"]
        tra[li, a:a + len(r["translation"])] = r["translation"]
        failures[li] += r["init_failures"]
        cpu += r["cpu_time"]
    noise = [_noise_of(kind, lv) for lv in levels]
    return SweepResult(
        experiment=kind, figures=figures, runs=runs, seed=seed, levels=list(levels),
        level_name=level_name, data={"rotation": rot, "translation": tra,
                                     "init_failures": failures},
        meta={"description": description, "motions": K, "filter_G2": FILTER_SIGMA**2,
              "P0": "I12", "noise_rotation_translation": noise,
              "initial_estimate": ("perturbed truth" if kind == "initial_estimate" else
                                   "two-motion Daniilidis (30° about E's x, then y)")},
        cpu_time=cpu)


def _metric(figure: str, result: SweepResult) -> str:
    return "rotation" if figure == result.figures[0] else "translation"


def _level_text(result: SweepResult, level: float) -> str:
    if result.level_name == "perturbation":
        return f"{100 * level:g} %"
    return f"σ = {level:g}"


TITLES = {
    "rotation": "rotation error ‖q − q̂‖",
    "translation": "relative translation error ‖t − t̂‖ / ‖t‖",
}


def write(result: SweepResult, figure: str, out: Path,
          plot: bool = True) -> list[Path]:
    metric = _metric(figure, result)
    errors = result.data[metric]
    K = errors.shape[2] - 1
    csv = out / f"{figure}.csv"
    rows = []
    for li, lv in enumerate(result.levels):
        s = curve_stats(errors[li])
        rows += [(lv, k, s["min"][k], s["max"][k], s["mean"][k], s["rms"][k])
                 for k in range(K + 1)]
    write_csv(csv, [result.level_name, "motion", "min", "max", "mean", "rms"], rows)

    if not plot:
        return [csv]
    plt = pyplot()
    fig, axes = plt.subplots(2, 3, figsize=(13, 7), sharex=True)
    k = np.arange(K + 1)
    for ax, (li, lv) in zip(axes.flat, enumerate(result.levels)):
        s = curve_stats(errors[li])
        ax.plot(k, s["max"], "-", color="k", lw=1, label="min / max")
        ax.plot(k, s["min"], "-", color="k", lw=1)
        ax.plot(k, s["mean"], "--", color="C0", lw=1.5, label="mean")
        ax.plot(k, s["rms"], "-.", color="C3", lw=1.5, label="RMS")
        ax.set_title(_level_text(result, lv))
        ax.set_ylim(bottom=0)
        ax.grid(True, alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("motion index")
    for ax in axes[:, 0]:
        ax.set_ylabel(TITLES[metric].split(" ‖")[0])
    axes[0, 0].legend(fontsize=8)
    number = figure.removeprefix("fig")
    fig.suptitle(f"Fig. {number}: {TITLES[metric]} vs motion — {result.meta['description']}; "
                 f"{result.runs} runs per level")
    fig.tight_layout()
    png = out / f"{figure}.png"
    fig.savefig(png, dpi=100)
    plt.close(fig)
    return [png, csv]


def summary(result: SweepResult, figure: str) -> str:
    metric = _metric(figure, result)
    errors = result.data[metric]
    K = errors.shape[2] - 1
    number = figure.removeprefix("fig")
    head = result.level_name.replace("sigma_", "σ ")
    lines = [f"### Fig. {number} — {TITLES[metric]}, {result.meta['description']} "
             f"({result.runs} runs, {K} motions)", "",
             f"Paper's filter: P0 = I12, G1 = 0, G2 = {FILTER_SIGMA**2:g} I12 (tuned for σ = "
             f"{FILTER_SIGMA:g}); start: {result.meta['initial_estimate']}"
             + ("" if result.experiment == "initial_estimate" else
                " (identity when Daniilidis rejects the noisy motions)") + ".", "",
             f"| {head} | initial mean | final mean | final RMS | final max | "
             "init. solver failures |", "|---|---|---|---|---|---|"]
    for li, lv in enumerate(result.levels):
        e = errors[li]
        level = f"{100 * lv:g} %" if result.level_name == "perturbation" else f"{lv:g}"
        fails = ("—" if result.experiment == "initial_estimate"
                 else str(int(result.data["init_failures"][li])))
        lines.append(f"| {level} | {e[:, 0].mean():.4g} | {e[:, -1].mean():.4g} | "
                     f"{np.sqrt(np.mean(e[:, -1]**2)):.4g} | {e[:, -1].max():.4g} | {fails} |")
    return "\n".join(lines) + "\n"

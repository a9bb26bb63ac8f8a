"""Hand-eye calibration of a real robot from recorded pose streams: the ``calibrate`` command.

    handeye-drake calibrate --robot FILE --camera FILE [--format tum|csv-matrix|opencv-yaml]
        [--method daniilidis|tsai|park|horaud|andreff] [--online] [--out DIR]
        [--camera-pose-is-camera-in-target] [--time-offset auto|SECONDS] ...

Pipeline (``calibrate_streams``): read the robot stream (X_BE) and the camera stream (X_CT, see
``formats``); estimate the clock offset if asked and interpolate the robot pose at every camera
instant (``align``); form motion pairs, reject outliers, solve AX = XB with a classical method on
80 % of the usable pairs and report the residuals of the 20 % held out (``selection``); estimate
the standard deviations of X_EC; optionally replay the small consecutive motions through the
paper's ``HandEyeKalmanFilter`` and plot its convergence. Results: a printed table and
``OUT/calibration.json`` (bit-identical for the same inputs and seed).

Standard deviations (``std_method``): "ml" (default) takes the covariance of
``estimation.ml.refine_ml`` run on the fitted pairs from the classical solution, with the "so3"
noise levels estimated from that solution's residuals (the ML-refined X_EC is reported too, as
``X_EC_ml``); "bootstrap" resamples the fitted pairs with replacement (50 seeded resamples) and
re-solves with the classical method. Both describe the error state [δθ; δt] of X_EC with
R_EC = exp([δθ]×) R̂_EC (δθ about the end-effector axes, radians) and t_EC = t̂_EC + δt (length
units, end-effector axes).
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..estimation.configs import PaperFilter
from ..estimation.kalman import HandEyeKalmanFilter
from ..estimation.se3 import inverse, quat_wxyz, rpy
from ..estimation.solvers import METHODS, solve_ax_xb
from ..recorded.align import (
    AlignedSamples,
    TimeOffsetEstimate,
    UnobservableTimeOffset,
    align_streams,
    estimate_time_offset,
)
from ..recorded.formats import FORMATS, MAX_TRANSLATION, PoseStream, read_poses
from ..recorded.selection import (
    RobustFit,
    bootstrap_covariance,
    consistency_hint,
    pair_residuals,
    residual_summary,
    robust_hand_eye,
)
from .outputs import OutputDir, prepare_output_dir

DEFAULT_METHOD = "daniilidis"
BOOTSTRAP_RESAMPLES = 50


@dataclass
class OnlineReplay:
    """The recording's consecutive motions replayed through ``HandEyeKalmanFilter``.

    Attributes:
        X_EC_init: the two-motion classical solution the filter starts from.
        init_pairs: sample indices of the two motions used for it.
        X_EC: the filter's final estimate.
        times: (U,) time (camera clock, s; or motion index) of each update.
        rotation_diff_deg, translation_diff: (U,) difference of the filter's X_EC after each
            update to the batch X_EC (deg; length units).
        rotation_sigma, translation_sigma: the noise levels given to the filter.
        skipped: updates the filter refused (non-finite state).
        step_deg: keyframe step of the replayed motions (0: every consecutive motion).
    """

    X_EC_init: np.ndarray
    init_pairs: list
    X_EC: np.ndarray
    times: np.ndarray
    rotation_diff_deg: np.ndarray
    translation_diff: np.ndarray
    rotation_sigma: float
    translation_sigma: float
    skipped: int
    step_deg: float


@dataclass
class CalibrationResult:
    """Everything ``calibrate_streams`` found; ``to_dict`` is the JSON document."""

    robot: PoseStream
    camera: PoseStream
    method: str
    time_offset_mode: str
    time_offset: TimeOffsetEstimate | None
    aligned: AlignedSamples
    fit: RobustFit
    X_EC: np.ndarray
    covariance: np.ndarray
    std_method: str
    std_detail: dict
    fit_residuals: dict
    held_out_residuals: dict
    noise: dict
    seed: int
    settings: dict
    online: OnlineReplay | None = None
    X_EC_ml: np.ndarray | None = None
    warnings: list = field(default_factory=list)
    inputs: dict = field(default_factory=dict)

    @property
    def X_CE(self) -> np.ndarray:
        return inverse(self.X_EC)

    @property
    def rotation_std_deg(self) -> np.ndarray:
        return np.degrees(np.sqrt(np.diag(self.covariance)[:3]))

    @property
    def translation_std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance)[3:])

    @property
    def rpy_std_deg(self) -> np.ndarray:
        """Roll-pitch-yaw standard deviations, first-order propagation of the covariance."""
        R = self.X_EC[:3, :3]
        J = np.zeros((3, 3))
        h = 1e-6
        for k in range(3):
            d = np.zeros(3)
            d[k] = h
            plus = rpy(Rotation.from_rotvec(d).as_matrix() @ R)
            minus = rpy(Rotation.from_rotvec(-d).as_matrix() @ R)
            J[:, k] = (np.angle(np.exp(1j * (plus - minus)))) / (2 * h)
        return np.degrees(np.sqrt(np.maximum(np.diag(J @ self.covariance[:3, :3] @ J.T), 0.0)))

    def to_dict(self) -> dict:
        f, p, a = self.fit, self.fit.pairs, self.aligned
        X = self.X_EC
        out = {
            "inputs": self.inputs,
            "method": self.method,
            "settings": self.settings,
            "seed": self.seed,
            "time_offset": {
                "mode": self.time_offset_mode,
                "value_s": a.time_offset,
                "convention": "camera stamp - robot time of the same instant",
                **({} if self.time_offset is None else {
                    "search_range_s": self.time_offset.search_range,
                    "motions_compared": self.time_offset.num_motions,
                    "angle_residual_rms_deg": self.time_offset.residual_rms_deg}),
            },
            "alignment": {
                "camera_samples": len(self.camera),
                "robot_samples": len(self.robot),
                "aligned": len(a),
                "dropped_outside_robot_span": len(a.dropped_outside),
                "dropped_outside_robot_span_lines": list(a.dropped_outside),
                "dropped_in_robot_gaps": len(a.dropped_gap),
                "dropped_in_robot_gaps_lines": list(a.dropped_gap),
            },
            "pairs": {
                "formed": len(p),
                "consecutive": int(p.consecutive.sum()),
                "wide": int((~p.consecutive).sum()),
                "min_rotation_deg": self.settings["min_rotation_deg"],
                "usable": int(f.usable.sum()),
                "below_min_rotation": int((~f.usable).sum()),
                "screw_angle_rejected": int((~f.screw_ok).sum()),
                "screw_angle_tolerance_deg": f.angle_tolerance_deg,
                "residual_rejected": int((f.screw_ok & ~f.inlier).sum()),
                "residual_tolerance_deg": f.residual_tolerance[0],
                "residual_tolerance_length": f.residual_tolerance[1],
                "consensus_iterations": f.iterations,
                "usable_inliers": int((f.inlier & f.usable).sum()),
                "fit": int(f.fit.sum()),
                "held_out": int(f.held_out.sum()),
                "held_out_note": f.holdout_note,
            },
            "outlier_camera_samples": {
                "count": int(len(f.outlier_samples)),
                "lines": [int(a.camera_lines[k]) for k in f.outlier_samples],
            },
            "X_EC": {
                "matrix": X.tolist(),
                "translation": X[:3, 3].tolist(),
                "quaternion_wxyz": quat_wxyz(X[:3, :3]).tolist(),
                "rpy_deg": np.degrees(rpy(X[:3, :3])).tolist(),
            },
            "X_CE": {"matrix": self.X_CE.tolist()},
            "X_EC_ml": None if self.X_EC_ml is None else {
                "matrix": self.X_EC_ml.tolist(),
                "note": "maximum-likelihood refinement (estimation.ml.refine_ml) of X_EC on the "
                        "fitted pairs; X_EC above is the classical solution"},
            "std_method": self.std_method,
            "std": {
                "rotation_deg": self.rotation_std_deg.tolist(),
                "error_state": "R_EC = exp([dtheta]x) R_EC_hat (dtheta about the end-effector "
                               "axes, rad), t_EC = t_EC_hat + dt",
                "translation": self.translation_std.tolist(),
                "rpy_deg": self.rpy_std_deg.tolist(),
                "covariance": self.covariance.tolist(),
                **self.std_detail,
            },
            "fit_residuals": self.fit_residuals,
            "held_out_residuals": self.held_out_residuals,
            "motion_noise": self.noise,
            "online": None,
            "warnings": list(self.warnings),
        }
        if self.online is not None:
            o = self.online
            out["online"] = {
                "filter": "HandEyeKalmanFilter (PaperFilter, noise_covariance='exact')",
                "updates": int(len(o.times)),
                "keyframe_step_deg": o.step_deg,
                "skipped_updates": o.skipped,
                "init_pairs": [list(map(int, ij)) for ij in o.init_pairs],
                "X_EC_init": o.X_EC_init.tolist(),
                "X_EC": o.X_EC.tolist(),
                "rotation_sigma": o.rotation_sigma,
                "translation_sigma": o.translation_sigma,
                "initial_diff_to_batch": {"rotation_deg": _rot_diff(o.X_EC_init, self.X_EC),
                                          "translation": _trans_diff(o.X_EC_init, self.X_EC)},
                "final_diff_to_batch": {
                    "rotation_deg": float(o.rotation_diff_deg[-1]) if len(o.times) else None,
                    "translation": float(o.translation_diff[-1]) if len(o.times) else None},
            }
        return out

    def table(self) -> str:
        """The human-readable summary printed by the command."""
        f, p, a = self.fit, self.fit.pairs, self.aligned
        X = self.X_EC
        lines = [f"robot:  {self.robot.source} ({len(self.robot)} poses)",
                 f"camera: {self.camera.source} ({len(self.camera)} poses)"]
        if self.time_offset is not None:
            lines.append(f"time offset: {a.time_offset:+.5f} s estimated (camera stamp − robot "
                         f"time; searched ±{self.time_offset.search_range:g} s over "
                         f"{self.time_offset.num_motions} motions)")
        elif self.camera.has_timestamps:
            lines.append(f"time offset: {a.time_offset:+.5f} s ({self.time_offset_mode})")
        else:
            lines.append("time offset: none (no timestamps, samples paired by index)")
        dropped = ""
        if a.dropped_outside:
            dropped += (f"; dropped {len(a.dropped_outside)} outside the robot's time span "
                        f"(lines {_short_list(a.dropped_outside)})")
        if a.dropped_gap:
            dropped += (f"; dropped {len(a.dropped_gap)} in robot gaps "
                        f"(lines {_short_list(a.dropped_gap)})")
        lines.append(f"aligned: {len(a)} of {len(self.camera)} camera samples{dropped}")
        lines.append(f"motion pairs: {len(p)} ({int(p.consecutive.sum())} consecutive + "
                     f"{int((~p.consecutive).sum())} wide); {int(f.usable.sum())} rotate ≥ "
                     f"{self.settings['min_rotation_deg']:g}° (usable by {self.method}), "
                     f"{int((~f.usable).sum())} below")
        out_lines = [a.camera_lines[k] for k in f.outlier_samples]
        lines.append(f"outliers: {int((~f.screw_ok).sum())} pairs fail the screw-angle test "
                     f"(|θA − θB| > {f.angle_tolerance_deg:.3g}°), "
                     f"{int((f.screw_ok & ~f.inlier).sum())} the residual test (> "
                     f"{f.residual_tolerance[0]:.3g}° or {f.residual_tolerance[1]:.3g}); "
                     f"outlying camera poses: {len(out_lines)}"
                     + (f" (lines {_short_list(out_lines)})" if out_lines else ""))
        lines.append(f"solved on {int(f.fit.sum())} pairs, {int(f.held_out.sum())} held out"
                     + (f" ({f.holdout_note})" if f.holdout_note else ""))
        lines.append("")
        std_t, std_r = self.translation_std, self.rpy_std_deg
        how = ("maximum-likelihood covariance" if self.std_method == "ml" else
               f"bootstrap, {self.std_detail.get('resamples')} resamples")
        lines.append(f"X_EC (camera in end-effector frame), {self.method}; ± 1σ ({how})")
        for row in X:
            lines.append("  [" + " ".join(f"{v:+.6f}" for v in row) + "]")
        lines.append("  translation      " + _vec(X[:3, 3], "{:+.5f}") + "  ± "
                     + _vec(std_t, "{:.5f}"))
        lines.append("  quaternion wxyz  " + _vec(quat_wxyz(X[:3, :3]), "{:+.6f}"))
        lines.append("  roll-pitch-yaw   " + _vec(np.degrees(rpy(X[:3, :3])), "{:+.4f}")
                     + " deg  ± " + _vec(std_r, "{:.4f}") + " deg")
        lines.append("  rotation σ about end-effector axes " + _vec(self.rotation_std_deg,
                                                                    "{:.4f}") + " deg")
        lines.append("")
        lines.append("residuals of AX = XB     rotation (deg)             translation")
        lines.append("                         median    rms      max     median     rms"
                     "        max")
        for name, r in (("fitted", self.fit_residuals), ("held out", self.held_out_residuals)):
            if r.get("count", 0):
                lines.append(f"  {name:<9}({r['count']:>4} pairs) "
                             f"{r['rotation_deg']['median']:.4f}  {r['rotation_deg']['rms']:.4f}"
                             f"  {r['rotation_deg']['max']:.4f}   "
                             f"{r['translation']['median']:.3e}  {r['translation']['rms']:.3e}"
                             f"  {r['translation']['max']:.3e}")
            else:
                lines.append(f"  {name:<9}(none)")
        if self.online is not None:
            o = self.online
            lines.append("")
            motions = (f"motions between keyframes ≥ {o.step_deg:g}° apart" if o.step_deg
                       else "consecutive motions")
            lines.append(f"on-line replay: {len(o.times)} {motions} through "
                         f"HandEyeKalmanFilter from the two-motion {self.method} solution "
                         f"(σ_R = {o.rotation_sigma:.3g}, σ_t = {o.translation_sigma:.3g})")
            lines.append(f"  difference to the batch X_EC: initial "
                         f"{_rot_diff(o.X_EC_init, X):.4f}° / {_trans_diff(o.X_EC_init, X):.3e}"
                         f", final {o.rotation_diff_deg[-1]:.4f}° / "
                         f"{o.translation_diff[-1]:.3e}" if len(o.times) else
                         "  (no motion to replay)")
        for w in self.warnings:
            lines.append(f"WARNING: {w}")
        return "\n".join(lines)


def _vec(v, fmt: str) -> str:
    return "[" + " ".join(fmt.format(x) for x in v) + "]"


def _short_list(values, n: int = 8) -> str:
    values = list(values)
    s = ", ".join(str(v) for v in values[:n])
    return s + (f", … ({len(values) - n} more)" if len(values) > n else "")


def _rot_diff(X1, X2) -> float:
    return float(np.degrees(np.linalg.norm(
        Rotation.from_matrix(X1[:3, :3].T @ X2[:3, :3]).as_rotvec())))


def _trans_diff(X1, X2) -> float:
    return float(np.linalg.norm(X1[:3, 3] - X2[:3, 3]))


def _motion_noise(fit: RobustFit, X_CE: np.ndarray) -> dict:
    """Noise levels of the paper's model from the inlier pairs' residuals: per-coefficient σ of
    R_A − R_X R_B R_Xᵀ and per-coordinate σ of t_A − (R_X t_B + t_X − R_A t_X)."""
    p = fit.pairs
    idx = np.flatnonzero(fit.inlier)
    R_X, t_X = X_CE[:3, :3], X_CE[:3, 3]
    R_A, t_A = p.A[idx, :3, :3], p.A[idx, :3, 3]
    R_B, t_B = p.B[idx, :3, :3], p.B[idx, :3, 3]
    E_R = R_A - R_X @ R_B @ R_X.T
    E_t = t_A - (t_B @ R_X.T + t_X - R_A @ t_X)
    return {"pairs": int(len(idx)),
            "rotation_coefficient_sigma": max(float(np.sqrt(np.mean(E_R ** 2))), 1e-9),
            "translation_sigma": max(float(np.sqrt(np.mean(E_t ** 2))), 1e-12)}


STD_METHODS = ("ml", "bootstrap")


def _so3_noise(A: np.ndarray, B: np.ndarray, X_CE: np.ndarray) -> tuple[float, float]:
    """Per-axis σ of the "so3" motion-noise model (R_A = exp(n_r) R̃_A, t_A = t̃_A + n_t) from
    the residuals of A against its prediction by X_CE and B: log(R_A R̂_Aᵀ) and t_A − t̂_A."""
    R_X, t_X = X_CE[:3, :3], X_CE[:3, 3]
    R_A_hat = R_X @ B[:, :3, :3] @ R_X.T
    n_r = Rotation.from_matrix(A[:, :3, :3] @ np.transpose(R_A_hat, (0, 2, 1))).as_rotvec()
    n_t = A[:, :3, 3] - (B[:, :3, 3] @ R_X.T + t_X - R_A_hat @ t_X)
    return max(float(np.sqrt(np.mean(n_r ** 2))), 1e-9), max(float(np.sqrt(np.mean(n_t ** 2))),
                                                             1e-12)


def _uncertainty(fit: RobustFit, method: str, std_method: str, resamples: int, seed: int):
    """(6×6 covariance of X_EC's error state, details, ML-refined X_EC or None).

    "ml": ``estimation.ml.refine_ml`` on the fitted pairs from the classical solution, with the
    "so3" noise levels estimated from that solution's residuals; its X_EC covariance.
    "bootstrap": ``selection.bootstrap_covariance``. Both: [δθ; δt] with R_EC = exp(δθ) R̂_EC
    (δθ about the end-effector axes, rad) and t_EC = t̂_EC + δt (length units, in E).
    """
    p, idx = fit.pairs, np.flatnonzero(fit.fit)
    if std_method == "bootstrap":
        cov, used = bootstrap_covariance(p, fit.fit, fit.X_CE, method, resamples, seed)
        return cov, {"resamples": int(resamples), "resamples_solved": int(used),
                     "bootstrap_seed": int(seed)}, None
    from ..estimation.ml import refine_ml
    sigma_r, sigma_t = _so3_noise(p.A[idx], p.B[idx], fit.X_CE)
    try:
        res = refine_ml(list(p.A[idx]), list(p.B[idx]), fit.X_CE, sigma_r, sigma_t,
                        noise_model="so3")
    except (ValueError, np.linalg.LinAlgError) as e:
        raise ValueError(f"standard deviations (maximum-likelihood refinement): {e}; try "
                         "--std bootstrap") from None
    cov = np.asarray(res.X_EC_covariance, dtype=float)
    dof = 6 * len(idx) - 6
    return 0.5 * (cov + cov.T), {
        "noise_model": "so3",
        "rotation_sigma_rad": sigma_r,
        "translation_sigma": sigma_t,
        "ml_cost_per_dof": float(res.cost) / dof if dof > 0 else None,
        "ml_minus_classical": {"rotation_deg": _rot_diff(res.X_EC, inverse(fit.X_CE)),
                               "translation": _trans_diff(res.X_EC, inverse(fit.X_CE))},
    }, np.asarray(res.X_EC, dtype=float)


def keyframe_motions(aligned: AlignedSamples, fit: RobustFit, step_deg: float, start: int = 0):
    """Motions between keyframes of the recording, in time order: from the current keyframe to
    the first later sample whose robot rotation from it reaches ``step_deg`` (every consecutive
    motion when 0), which becomes the next keyframe. Outlying camera samples (``fit``) are
    skipped, and a motion failing the screw-angle test is skipped too (after 3 such failures in
    a row the keyframe moves on). Yields (i, j, A, B)."""
    bad = set(int(k) for k in fit.outlier_samples)
    X_BE, X_CT = aligned.X_BE, aligned.X_CT
    step = math.radians(step_deg)
    key = start
    while key < len(X_BE) and key in bad:
        key += 1
    failures = 0
    for k in range(key + 1, len(X_BE)):
        if k in bad:
            continue
        B = inverse(X_BE[key]) @ X_BE[k]
        theta_B = float(np.linalg.norm(Rotation.from_matrix(B[:3, :3]).as_rotvec()))
        if theta_B < step:
            continue
        A = X_CT[key] @ inverse(X_CT[k])
        theta_A = float(np.linalg.norm(Rotation.from_matrix(A[:3, :3]).as_rotvec()))
        if abs(math.degrees(theta_A - theta_B)) > fit.angle_tolerance_deg:
            failures += 1
            if failures >= 3:
                key, failures = k, 0
            continue
        yield key, k, A, B
        key, failures = k, 0


def replay_online(aligned: AlignedSamples, fit: RobustFit, X_EC_batch: np.ndarray, method: str,
                  rotation_sigma: float, translation_sigma: float, step_deg: float = 10.0,
                  min_rotation_deg: float = 5.0) -> OnlineReplay:
    """Replays the recording through ``HandEyeKalmanFilter``, as the paper runs it on-line.

    Initialization: the classical ``method`` solution of the two first usable motions of the
    recording (keyframe motions rotating ≥ max(step_deg, min_rotation_deg), the second one's
    axis not parallel to the first). Then every later keyframe motion (``keyframe_motions`` with
    ``step_deg``; 0 replays every consecutive motion) updates the filter, in time order. The
    filter's noise levels are those estimated from the batch solution's residuals.
    """
    first = second = None
    init_step = max(step_deg, min_rotation_deg)
    errors = []
    for i, j, A, B in keyframe_motions(aligned, fit, init_step):
        if first is None:
            first = (i, j, A, B)
            continue
        try:
            X_CE_init = solve_ax_xb([first[2], A], [first[3], B], method)
        except ValueError as e:
            errors.append(str(e))
            continue
        second = (i, j, A, B)
        break
    if second is None:
        raise ValueError("on-line replay: the recording has no two motions rotating ≥ "
                         f"{init_step:g}° about non-parallel axes to initialize the filter"
                         + (f" ({errors[-1]})" if errors else ""))
    kf = HandEyeKalmanFilter(PaperFilter(noise_covariance="exact",
                                         rotation_coefficient_sigma=rotation_sigma,
                                         translation_sigma=translation_sigma,
                                         initial_variances=[1.0] * 12), X_CE_init)
    times, rot, trans = [], [], []
    skipped = 0
    for i, j, A, B in keyframe_motions(aligned, fit, step_deg, start=second[1]):
        try:
            fused = kf.update_motion(A, B)
        except ValueError:
            skipped += 1
            continue
        if not fused:
            skipped += 1
            continue
        X = kf.X_EC
        times.append(aligned.camera_times[j] if aligned.camera_times is not None else float(j))
        rot.append(_rot_diff(X, X_EC_batch))
        trans.append(_trans_diff(X, X_EC_batch))
    return OnlineReplay(inverse(X_CE_init), [list(first[:2]), list(second[:2])], kf.X_EC,
                        np.array(times), np.array(rot), np.array(trans), float(rotation_sigma),
                        float(translation_sigma), skipped, float(step_deg))


def plot_online(result: CalibrationResult, path) -> Path:
    """PNG of the on-line filter's convergence towards the batch estimate."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    o = result.online
    fig, axes = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    init = (_rot_diff(o.X_EC_init, result.X_EC), _trans_diff(o.X_EC_init, result.X_EC))
    xlabel = "camera time (s)" if result.aligned.camera_times is not None else "sample index"
    for ax, y, y0, label in ((axes[0], o.rotation_diff_deg, init[0], "rotation (deg)"),
                             (axes[1], o.translation_diff, init[1], "translation (m)")):
        ax.semilogy(o.times, np.maximum(y, 1e-9), label="HandEyeKalmanFilter")
        ax.axhline(max(y0, 1e-9), color="C3", ls="--", lw=1,
                   label=f"two-motion {result.method} start")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    axes[1].set_xlabel(xlabel)
    axes[0].set_title("On-line replay: difference of the filter's X_EC to the batch X_EC")
    fig.tight_layout()
    fig.savefig(path, dpi=100, metadata={"Software": None})
    plt.close(fig)
    return Path(path)


def _diagnose(fit: RobustFit, held: dict, fitted: dict) -> list[str]:
    """Warnings for a poor fit, with what usually causes it."""
    ref = held if held.get("count") else fitted
    if not ref.get("count") or ref["rotation_deg"]["median"] <= 1.0:
        return []
    return [f"large residuals: median rotation residual {ref['rotation_deg']['median']:.3g}° "
            f"on {ref['count']} pairs; " + consistency_hint(fit.pairs, fit.inlier & fit.usable)]


def calibrate_streams(robot: PoseStream, camera: PoseStream, method: str = DEFAULT_METHOD,
                      time_offset=None, time_offset_range: float = 0.5,
                      min_rotation_deg: float = 5.0, max_pair_angle_deg: float = 90.0,
                      holdout_fraction: float = 0.2, bootstrap_resamples: int = BOOTSTRAP_RESAMPLES,
                      seed: int = 0, online: bool = False, std_method: str = "ml",
                      online_step_deg: float = 10.0) -> CalibrationResult:
    """Calibrates X_EC from a robot stream (X_BE) and a camera stream (X_CT).

    Args:
        robot, camera: streams from ``formats.read_poses`` (or ``formats.pose_stream``).
        method: classical method of ``solvers.METHODS`` for the batch solution.
        time_offset: seconds (camera stamp − robot time); "auto" to estimate it in
            [−time_offset_range, time_offset_range]; None (default): "auto" when both streams
            have timestamps, except that an unobservable offset (``UnobservableTimeOffset``:
            too short, too little or too uniform rotation) then falls back to 0 with a warning;
            0 for index-paired streams.
        min_rotation_deg, max_pair_angle_deg, holdout_fraction: see ``selection``.
        std_method: "ml" (covariance of ``estimation.ml.refine_ml``, noise levels from the
            classical solution's residuals) or "bootstrap" (over the fitted pairs).
        bootstrap_resamples: resamples of the bootstrap standard deviations.
        seed: seeds the hold-out split and the bootstrap.
        online: also replay the recording through ``HandEyeKalmanFilter`` (``replay_online``).
        online_step_deg: keyframe step of the replayed motions (0: every consecutive motion).

    Raises:
        ValueError: bad arguments, streams that cannot be aligned, degenerate or inconsistent
            motions (the message says why).
    """
    if method not in METHODS:
        raise ValueError(f"method: unknown hand-eye method {method!r}; valid methods are "
                         f"{', '.join(METHODS)}")
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed: expected a non-negative integer, got {seed!r}")
    if not isinstance(bootstrap_resamples, (int, np.integer)) or not 10 <= bootstrap_resamples \
            <= 10_000:
        raise ValueError(f"bootstrap_resamples: expected an integer in [10, 10000], got "
                         f"{bootstrap_resamples!r}")
    if std_method not in STD_METHODS:
        raise ValueError(f"std_method: expected one of {STD_METHODS}, got {std_method!r}")
    if not (isinstance(online_step_deg, (int, float)) and 0 <= online_step_deg <= 90):
        raise ValueError(f"online_step_deg: must be a number in [0, 90], got "
                         f"{online_step_deg!r}")
    if not (isinstance(time_offset_range, (int, float)) and math.isfinite(time_offset_range)
            and time_offset_range > 0):
        raise ValueError(f"time_offset_range: must be finite and > 0, got "
                         f"{time_offset_range!r}")
    estimate, warnings = None, []
    if time_offset is None:
        offset, mode = 0.0, "default: none (no timestamps)"
        if robot.has_timestamps and camera.has_timestamps:
            try:
                estimate = estimate_time_offset(robot, camera, time_offset_range)
                offset, mode = estimate.offset, "auto (default)"
            except UnobservableTimeOffset as e:
                mode = "default: 0 (offset unobservable)"
                warnings.append(f"time offset not estimated, 0 used: {e}")
    elif isinstance(time_offset, str):
        if time_offset != "auto":
            raise ValueError(f"time_offset: expected 'auto' or seconds, got {time_offset!r}")
        estimate = estimate_time_offset(robot, camera, time_offset_range)
        offset, mode = estimate.offset, "auto"
    else:
        offset, mode = time_offset, "given"
    aligned = align_streams(robot, camera, offset)
    fit = robust_hand_eye(aligned.X_BE, aligned.X_CT, method, min_rotation_deg,
                          max_pair_angle_deg, holdout_fraction, seed)
    X_EC = inverse(fit.X_CE)
    p = fit.pairs
    fitted = residual_summary(*pair_residuals(p.A[fit.fit], p.B[fit.fit], fit.X_CE))
    held = residual_summary(*pair_residuals(p.A[fit.held_out], p.B[fit.held_out], fit.X_CE))
    noise = _motion_noise(fit, fit.X_CE)
    cov, detail, X_EC_ml = _uncertainty(fit, method, std_method, int(bootstrap_resamples),
                                        int(seed))
    if not np.all(np.isfinite(cov)):
        raise ValueError("standard deviations: non-finite covariance (degenerate motions)")
    result = CalibrationResult(
        robot, camera, method, mode, estimate, aligned, fit, X_EC, cov, std_method, detail,
        fitted, held, noise, int(seed),
        {"min_rotation_deg": float(min_rotation_deg),
         "max_pair_angle_deg": float(max_pair_angle_deg),
         "holdout_fraction": float(holdout_fraction),
         "time_offset_range_s": float(time_offset_range)}, X_EC_ml=X_EC_ml)
    result.warnings.extend(warnings + _diagnose(fit, held, fitted))
    if online:
        result.online = replay_online(aligned, fit, X_EC, method,
                                      noise["rotation_coefficient_sigma"],
                                      noise["translation_sigma"], float(online_step_deg),
                                      float(min_rotation_deg))
    return result


def calibrate_files(robot_path, camera_path, fmt: str | None = None,
                    camera_in_target: bool = False, translation_scale: float = 1.0,
                    max_translation: float | None = MAX_TRANSLATION, **kwargs) -> CalibrationResult:
    """``calibrate_streams`` on two files (``formats.read_poses`` reads them; ``fmt`` None infers
    each file's format from its extension). Extra keyword arguments go to ``calibrate_streams``.
    """
    robot = read_poses(robot_path, "robot", fmt, False, translation_scale, max_translation)
    camera = read_poses(camera_path, "camera", fmt, camera_in_target, translation_scale,
                        max_translation)
    result = calibrate_streams(robot, camera, **kwargs)
    # The digests of the bytes the readers read: no second read (FIFOs, pipes).
    result.inputs = {"robot": {"path": str(robot_path), "sha256": robot.sha256,
                               "samples": len(robot)},
                     "camera": {"path": str(camera_path), "sha256": camera.sha256,
                                "samples": len(camera)},
                     "format": fmt or "from extension",
                     "camera_pose_is_camera_in_target": bool(camera_in_target),
                     "translation_scale": float(translation_scale)}
    return result


def write_outputs(result: CalibrationResult, out_dir, force: bool = False) -> list[Path]:
    """Writes ``calibration.json`` (and ``online_convergence.png`` when replayed) in out_dir
    (a directory or an ``outputs.OutputDir`` already claimed; see ``apps.outputs``)."""
    out = out_dir if isinstance(out_dir, OutputDir) else prepare_output_dir(out_dir, "calibrate",
                                                                             force)
    try:
        path = out.path("calibration.json")
        path.write_text(json.dumps(result.to_dict(), indent=2, allow_nan=False) + "\n")
        written = [path]
        if result.online is not None and len(result.online.times):
            written.append(plot_online(result, out.path("online_convergence.png")))
    except OSError as e:
        raise ValueError(f"--out {out.root}: cannot write the results ({e.strerror or e})") \
            from None
    out.finish(written)
    return written


# ----------------------------------------------------------------------------------- command
def _time_offset_arg(text: str):
    if text == "auto":
        return "auto"
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected 'auto' or seconds, got {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
    return v


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Adds the ``calibrate`` subcommand to an argparse ``subparsers`` object."""
    p = subparsers.add_parser(
        "calibrate", help="hand-eye calibration from recorded robot and camera poses",
        description="Estimate X_EC (camera in end-effector) from a robot pose stream (X_BE, "
                    "end-effector in base) and a camera pose stream (X_CT, target in camera).")
    p.add_argument("--robot", required=True, metavar="FILE", help="robot poses X_BE")
    p.add_argument("--camera", required=True, metavar="FILE",
                   help="camera poses X_CT (target in camera)")
    p.add_argument("--format", choices=FORMATS, default=None,
                   help="file format (default: from the extension: .tum/.txt, .csv, .yaml/.yml)")
    p.add_argument("--method", choices=METHODS, default=DEFAULT_METHOD,
                   help=f"classical AX = XB method (default {DEFAULT_METHOD})")
    p.add_argument("--online", action="store_true",
                   help="replay the motions through HandEyeKalmanFilter and plot its convergence")
    p.add_argument("--online-step", type=float, default=10.0, metavar="DEG",
                   help="--online feeds the filter the motion between keyframes rotating ≥ DEG "
                        "apart (default 10); 0 feeds every consecutive (small) motion")
    p.add_argument("--out", default="out/calibrate", metavar="DIR",
                   help="output directory (default out/calibrate); an existing one must be "
                        "empty or hold this command's earlier output")
    p.add_argument("--force", action="store_true",
                   help="write into a non-empty --out that is not this command's output "
                        "(never overwriting files the tool did not write)")
    p.add_argument("--camera-pose-is-camera-in-target", action="store_true",
                   help="the camera file holds X_TC (camera in target) instead of X_CT")
    p.add_argument("--time-offset", type=_time_offset_arg, default=None,
                   metavar="auto|SECONDS",
                   help="camera stamp − robot time of the same instant, or 'auto' to estimate "
                        "it (default: auto when both files have timestamps, falling back to 0 "
                        "with a warning when the recording does not determine it)")
    p.add_argument("--time-offset-range", type=float, default=0.5, metavar="SECONDS",
                   help="search range ± of --time-offset auto (default 0.5)")
    p.add_argument("--min-rotation", type=float, default=5.0, metavar="DEG",
                   help="smallest rotation of a motion used by the classical method (default 5)")
    p.add_argument("--max-pair-angle", type=float, default=90.0, metavar="DEG",
                   help="largest rotation of a wide motion pair (default 90)")
    p.add_argument("--holdout", type=float, default=0.2, metavar="FRACTION",
                   help="share of motion pairs held out for validation (default 0.2)")
    p.add_argument("--std", choices=STD_METHODS, default="ml",
                   help="standard deviations from the maximum-likelihood covariance (default) or "
                        "a bootstrap over the motion pairs")
    p.add_argument("--bootstrap", type=int, default=BOOTSTRAP_RESAMPLES, metavar="N",
                   help=f"bootstrap resamples for the standard deviations (default "
                        f"{BOOTSTRAP_RESAMPLES})")
    p.add_argument("--seed", type=int, default=0, help="seed of the hold-out split and bootstrap")
    p.add_argument("--translation-scale", type=float, default=1.0, metavar="FACTOR",
                   help="multiply every translation (0.001 for files in millimetres)")
    p.add_argument("--max-translation", type=float, default=MAX_TRANSLATION, metavar="METRES",
                   help=f"reject translations longer than this (default {MAX_TRANSLATION:g}; "
                        "units check)")
    p.set_defaults(func=run_calibrate_command)
    return p


def run_calibrate_command(args) -> int:
    """Runs ``calibrate`` from parsed arguments; raises ValueError on bad input."""
    out = prepare_output_dir(args.out, "calibrate", args.force)
    result = calibrate_files(
        args.robot, args.camera, args.format, args.camera_pose_is_camera_in_target,
        args.translation_scale, args.max_translation, method=args.method,
        time_offset=args.time_offset, time_offset_range=args.time_offset_range,
        min_rotation_deg=args.min_rotation, max_pair_angle_deg=args.max_pair_angle,
        holdout_fraction=args.holdout, std_method=args.std,
        bootstrap_resamples=args.bootstrap, seed=args.seed,
        online=args.online, online_step_deg=args.online_step)
    written = write_outputs(result, out)
    print(result.table())
    print("wrote: " + ", ".join(str(p) for p in written))
    return 0


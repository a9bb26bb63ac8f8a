"""PNG plots of a closed-loop run (matplotlib, headless Agg backend)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..systems.servo import STATUS_TOO_FEW_VISIBLE  # noqa: E402


def _servo_start_line(ax, result):
    if np.isfinite(result.servo_start_time):
        ax.axvline(result.servo_start_time, color="0.6", ls=":", lw=1, label="servo starts")


def plot_feature_error(result, path) -> Path:
    """RMS feature error over time; samples without a usable image (the first sample, targets
    out of view) are left out rather than drawn as a dive to zero."""
    fig, ax = plt.subplots(figsize=(7, 3.5))
    seen = result.servo_status != STATUS_TOO_FEW_VISIBLE
    ax.semilogy(result.times[seen], result.feature_error_px[seen])
    _servo_start_line(ax, result)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("RMS feature error (px)")
    ax.set_title("Visual servo: ‖s − s*‖ (RMS over visible points)")
    ax.grid(True, which="both", alpha=0.3)
    if ax.get_legend_handles_labels()[0]:  # a run too short to reach the servo has no line
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_image_trajectories(result, path) -> Path:
    c = result.scenario.camera.sensor
    fig, ax = plt.subplots(figsize=(6.4, 4.8 * 6.4 / 6.4))
    uv = result.features.reshape(len(result.times), -1, 2)
    s_star = result.desired_features.reshape(-1, 2)
    for i in range(uv.shape[1]):
        line, = ax.plot(uv[:, i, 0], uv[:, i, 1], lw=1)
        ax.plot(uv[0, i, 0], uv[0, i, 1], "o", color=line.get_color(), mfc="none")
        ax.plot(s_star[i, 0], s_star[i, 1], "x", color=line.get_color(), ms=9)
    ax.set_xlim(0, c.width)
    ax.set_ylim(c.height, 0)
    ax.set_aspect("equal")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    ax.set_title("Image trajectories (o start, x desired)")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_handeye_errors(result, path) -> Path:
    """Like the paper's Fig. 10: errors over time, the two-motion error as a horizontal line,
    the estimate's own ±1σ as a band around its error (σ: the RMS radius √trace of the
    filter's rotation (deg) / translation covariance, the latter in % of the true ‖t_EC‖) and
    the self-calibration motions (before servoing starts) shaded."""
    fig, axes = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    mask = result.times >= result.servo_start_time
    std = np.asarray(result.X_EC_std, float)
    t_norm = max(float(np.linalg.norm(np.asarray(result.X_EC_true)[:3, 3])), 1e-12)
    sigmas = (np.linalg.norm(std[:, :3], axis=1), 100 * np.linalg.norm(std[:, 3:], axis=1) / t_norm)
    for ax, series, initial, sigma, label in (
            (axes[0], result.rotation_error_deg, result.initial_rotation_error_deg, sigmas[0],
             "rotation error (deg)"),
            (axes[1], 100 * result.translation_error_rel,
             100 * result.initial_translation_error_rel, sigmas[1],
             "translation error (% of ‖t‖)")):
        if np.isfinite(result.servo_start_time):
            ax.axvspan(result.times[0], result.servo_start_time, color="0.85", lw=0,
                       label="self-calibration motions")
        t, e, s = result.times[mask], series[mask], sigma[mask]
        ax.fill_between(t, np.maximum(e - s, 0.0), e + s, color="C0", alpha=0.2, lw=0,
                        label="±1σ (the filter's own)")
        ax.plot(t, e, label="on-line Kalman estimate")
        ax.axhline(initial, color="C3", ls="--", label="two-motion (Daniilidis) estimate")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        ax.set_ylim(bottom=0)
        if len(e):  # the band's first, widest samples would flatten the rest
            top = max(float(np.nanpercentile(e + s, 98)), float(initial)) * 1.15
            if np.isfinite(top) and top > 0:
                ax.set_ylim(0, top)
    axes[0].legend(fontsize=8)
    axes[1].set_xlabel("time (s)")
    axes[0].set_title("Hand-eye error of X_EC during servoing")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def write_run_plots(result, out_dir) -> list[Path]:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return [plot_feature_error(result, out / "feature_error.png"),
            plot_image_trajectories(result, out / "image_trajectories.png"),
            plot_handeye_errors(result, out / "handeye_error.png")]

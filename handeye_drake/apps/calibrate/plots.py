"""Pictures of ``calibrate``'s results (matplotlib, headless)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...calibration.online import rotation_diff_deg, translation_diff


def plot_online(result, path) -> Path:
    """PNG of the on-line filters' convergence towards the batch estimate."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    replays = result.online
    fig, axes = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    o0 = replays[0]
    init = (rotation_diff_deg(o0.X_H_init, result.X_hand),
            translation_diff(o0.X_H_init, result.X_hand))
    xlabel = "camera time (s)" if result.aligned.camera_times is not None else "sample index"
    from matplotlib.ticker import FuncFormatter
    # Translations in mm, log axes labelled with plain numbers (0.01, 1, 100), not 10^x.
    plain = FuncFormatter(lambda v, _: f"{v:g}")
    for k, (ax, y0, label) in enumerate(((axes[0], init[0], "rotation (deg)"),
                                         (axes[1], 1000 * init[1], "translation (mm)"))):
        for o in replays:
            y = o.rotation_diff_deg if k == 0 else 1000 * np.asarray(o.translation_diff)
            ax.semilogy(o.times, np.maximum(y, 1e-6), label=o.label)
        ax.axhline(max(y0, 1e-6), color="C3", ls="--", lw=1, label="two-motion start")
        ax.yaxis.set_major_formatter(plain)
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    axes[1].set_xlabel(xlabel)
    axes[0].set_title("On-line replay: difference of each filter's estimate to the batch result")
    fig.tight_layout()
    fig.savefig(path, dpi=100, metadata={"Software": None})
    plt.close(fig)
    return Path(path)


__all__ = ["plot_online"]

"""Closed-loop comparison of the calibrator's estimators on the default scenario.

    python benchmarks/closed_loop_estimators.py [--seeds 0 1 2] [--driver pose|twist]
                                                [--estimators target manifold paper]
                                                [--consistency]

For each estimator (the default `target`, and the scenario files in scenarios/) and seed, runs
the full Drake diagram and prints the two-motion and final hand-eye errors of X_EC, the final
feature error and the real-time factor. ``--driver twist`` runs the loop with
``arm.driver: !TwistCommand`` (the Python differential-IK driver on the servo's twist) instead
of the default pose command. ``--consistency`` adds, per run, the final X_EC error in units of
the reported σ (Σ z² over the 6 axes: 6 is consistent), the reported rotation σ (deg, norm over
the 3 axes) and the mean NIS of the filter's updates.
"""
import argparse
from pathlib import Path

import numpy as np

from handeye_drake.estimation.se3 import rotation_log
from handeye_drake.scenario import PoseCommand, TwistCommand, load_scenario
from handeye_drake.simulation import run_scenario

ROOT = Path(__file__).resolve().parent.parent
CASES = {"target": ("target (default)", None),
         "manifold": ("manifold", ROOT / "scenarios" / "manifold_filter.yaml"),
         "paper": ("paper", ROOT / "scenarios" / "paper_filter.yaml")}


def consistency(result) -> tuple[float, float, float]:
    """(Σ z², rotation σ (deg, norm), mean NIS) of a run's final X_EC estimate: z = error / σ
    per axis, the error [δθ (about E's axes); δt (in E)] with R_true = exp(δθ) R̂."""
    X, X_hat = result.X_EC_true, result.X_EC_estimates[-1]
    e = np.concatenate([np.degrees(rotation_log(X[:3, :3] @ X_hat[:3, :3].T)),
                        X[:3, 3] - X_hat[:3, 3]])
    std = result.X_EC_std[-1]
    nis = result.calibrator_status[:, 3]
    updating = np.flatnonzero(np.diff(result.calibrator_status[:, 1]) > 0) + 1
    return (float(np.sum((e / std) ** 2)), float(np.linalg.norm(std[:3])),
            float(np.mean(nis[updating])))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--driver", choices=("pose", "twist"), default="pose")
    parser.add_argument("--estimators", nargs="+", choices=list(CASES), default=list(CASES))
    parser.add_argument("--consistency", action="store_true")
    args = parser.parse_args()
    extra = " Σz² | rot σ (deg) | mean NIS |" if args.consistency else ""
    print("| estimator | seed | two-motion rot (deg) / trans (%) | final rot (deg) / trans (%) "
          f"| final feature error (px) | real-time factor |{extra}")
    print("|---|---|---|---|---|---|" + ("---|---|---|" if args.consistency else ""))
    for key in args.estimators:
        name, path = CASES[key]
        for seed in args.seeds:
            scenario = load_scenario(path)
            scenario.seed = seed
            scenario.arm.driver = TwistCommand() if args.driver == "twist" else PoseCommand()
            result = run_scenario(scenario)
            q = result.summary()
            row = (f"| {name} | {seed} | {q['two_motion_rotation_error_deg']:.3f} / "
                   f"{100 * q['two_motion_translation_error_rel']:.2f} | "
                   f"{q['final_rotation_error_deg']:.3f} / "
                   f"{100 * q['final_translation_error_rel']:.2f} | "
                   f"{q['final_feature_error_px']:.2f} | {q['real_time_factor']:.1f} |")
            if args.consistency:
                z2, sigma, nis = consistency(result)
                row += f" {z2:.1f} | {sigma:.3f} | {nis:.2f} |"
            print(row, flush=True)

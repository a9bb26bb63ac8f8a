"""Closed-loop comparison of the calibrator's estimators on the default scenario.

    python benchmarks/closed_loop_estimators.py [--seeds 0 1 2]

For each estimator (the default `target`, and the scenario files in scenarios/) and seed, runs
the full Drake diagram and prints the two-motion and final hand-eye errors of X_EC, the final
feature error and the real-time factor.
"""
import argparse
from pathlib import Path

from handeye_drake.scenario import load_scenario
from handeye_drake.simulation import run_scenario

ROOT = Path(__file__).resolve().parent.parent
CASES = [("target (default)", None),
         ("manifold", ROOT / "scenarios" / "manifold_filter.yaml"),
         ("paper", ROOT / "scenarios" / "paper_filter.yaml")]

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    args = parser.parse_args()
    print("| estimator | seed | two-motion rot (deg) / trans (%) | final rot (deg) / trans (%) "
          "| final feature error (px) | real-time factor |")
    print("|---|---|---|---|---|---|")
    for name, path in CASES:
        for seed in args.seeds:
            scenario = load_scenario(path)
            scenario.seed = seed
            q = run_scenario(scenario).summary()
            print(f"| {name} | {seed} | {q['two_motion_rotation_error_deg']:.3f} / "
                  f"{100 * q['two_motion_translation_error_rel']:.2f} | "
                  f"{q['final_rotation_error_deg']:.3f} / "
                  f"{100 * q['final_translation_error_rel']:.2f} | "
                  f"{q['final_feature_error_px']:.2f} | {q['real_time_factor']:.1f} |")

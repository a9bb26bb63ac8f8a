"""Is ``handeye-drake calibrate`` ever confidently wrong? NEES of its result against the truth
on simulated recordings with anisotropic camera noise (``calibrate_vs_opencv.simulate_recording``:
PnP-like noise 0.15°/0.15°/0.05° and 0.3/0.3/1.0 mm about/along the camera's x/y/z, a
configuration-dependent robot error, 3 gross outliers, a clock offset).

    OPENBLAS_NUM_THREADS=1 python benchmarks/calibrate_nees.py [--seeds 30] [--first 0]
        [--robot-accuracy]

Per seed: the error of X_EC against the truth in units of the reported covariance,
NEES = δᵀ Σ⁻¹ δ (χ²(6) when the σ are honest; 99.9 % bound 22.46), the verdict and its causes.
Prints the distribution: mean (6 expected), quantiles, seeds beyond the bound.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.stats import chi2

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from calibrate_vs_opencv import simulate_recording  # noqa: E402
from handeye_drake.calibration import calibrate_streams  # noqa: E402
from handeye_drake.estimation.se3 import rotation_log  # noqa: E402


def nees_of(result, X_EC_true) -> float:
    d = np.concatenate([rotation_log(X_EC_true[:3, :3] @ result.X_EC[:3, :3].T),
                        X_EC_true[:3, 3] - result.X_EC[:3, 3]])
    return float(d @ np.linalg.solve(result.covariance, d))


#: The simulated robot error: RMS 0.03° / 0.3 mm (norm), i.e. per axis / √3.
SIMULATED_ROBOT_ACCURACY = (0.03 / np.sqrt(3.0), 0.0003 / np.sqrt(3.0))


def run(seeds, robot_accuracy=None, log=print) -> list[dict]:
    rows = []
    for seed in seeds:
        robot, camera, X_EC, _ = simulate_recording(seed)
        r = calibrate_streams(robot, camera, **(
            {} if robot_accuracy is None else {"robot_accuracy": robot_accuracy}))
        e = nees_of(r, X_EC)
        rows.append({"seed": seed, "nees": e, "verdict": r.verdict.status,
                     "causes": [c.code for c in r.verdict.reasons],
                     "err_rot_deg": float(np.degrees(np.linalg.norm(
                         rotation_log(X_EC[:3, :3] @ r.X_EC[:3, :3].T)))),
                     "err_trans_mm": 1000 * float(np.linalg.norm(X_EC[:3, 3] - r.X_EC[:3, 3])),
                     "std_rot_deg": float(np.linalg.norm(r.rotation_std_deg)),
                     "std_trans_mm": 1000 * float(np.linalg.norm(r.translation_std))})
        x = rows[-1]
        log(f"  seed {seed:2d}: NEES {e:7.2f}; error {x['err_rot_deg']:.4f}° / "
            f"{x['err_trans_mm']:.3f} mm, σ (norm) {x['std_rot_deg']:.4f}° / "
            f"{x['std_trans_mm']:.3f} mm; verdict {x['verdict']} {x['causes']}", flush=True)
    return rows


def summary(rows) -> str:
    e = np.array([r["nees"] for r in rows])
    bound = chi2.ppf(0.999, 6)
    verdicts = [r["verdict"] for r in rows]
    held = sum("held_out" in r["causes"] for r in rows)
    return (f"NEES over {len(e)} seeds: mean {e.mean():.2f} (6 expected; 95 % band of the mean "
            f"{chi2.ppf(0.025, 6 * len(e)) / len(e):.2f}–{chi2.ppf(0.975, 6 * len(e)) / len(e):.2f}),"
            f" median {np.median(e):.2f} (χ²(6) median {chi2.median(6):.2f}), max {e.max():.2f}; "
            f"beyond the 99.9 % bound {bound:.2f}: {int(np.sum(e > bound))}; "
            f"error vs truth median {np.median([r['err_rot_deg'] for r in rows]):.4f}° / "
            f"{np.median([r['err_trans_mm'] for r in rows]):.3f} mm; verdicts: "
            + ", ".join(f"{v} × {verdicts.count(v)}" for v in sorted(set(verdicts)))
            + f"; held_out WARN: {held}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=30)
    parser.add_argument("--first", type=int, default=0)
    parser.add_argument("--robot-accuracy", action="store_true",
                        help="also run with robot_accuracy = the simulated robot error")
    args = parser.parse_args()
    start = time.perf_counter()
    rows = run(range(args.first, args.first + args.seeds))
    print(summary(rows))
    if args.robot_accuracy:
        print(f"with robot_accuracy={SIMULATED_ROBOT_ACCURACY} (the simulated robot error):")
        print(summary(run(range(args.first, args.first + args.seeds),
                          SIMULATED_ROBOT_ACCURACY)))
    print(f"({time.perf_counter() - start:.0f} s)")

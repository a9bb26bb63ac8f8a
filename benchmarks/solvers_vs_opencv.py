"""Our five classical solvers against OpenCV's ``cv2.calibrateHandEye`` on one noisy data set.

    python benchmarks/solvers_vs_opencv.py [--seed 0] [--poses 15] [--rotation-noise-deg 0.5]
                                           [--translation-noise 0.001]

Eye-in-hand poses tilted 20–55° about random axes, a target fixed in the base, noise on the
measured X_CT (rotation vector and translation). Prints each method's error of X_EC for ours
(all pose pairs, as OpenCV, and consecutive pairs) and OpenCV's, and their difference.
"""
import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from tests.estimation.test_solvers_vs_opencv import (CV_METHODS, errors, make_dataset,  # noqa: E402
                                                     opencv_X_EC)

from handeye_drake import calibrate_hand_eye  # noqa: E402

if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--poses", type=int, default=15)
    parser.add_argument("--rotation-noise-deg", type=float, default=0.5)
    parser.add_argument("--translation-noise", type=float, default=1e-3)
    args = parser.parse_args()
    X_EC, X_BE, X_CT = make_dataset(args.seed, args.poses, args.rotation_noise_deg,
                                    args.translation_noise)
    print(f"{args.poses} poses, seed {args.seed}, noise {args.rotation_noise_deg}° / "
          f"{1000 * args.translation_noise:g} mm on X_CT; errors of X_EC")
    print("| method | ours rot (°) | ours trans (mm) | OpenCV rot (°) | OpenCV trans (mm) | "
          "‖ours − OpenCV‖ rot (°) / trans (mm) | ours, consecutive pairs rot (°) / trans (mm) |")
    print("|---|---|---|---|---|---|---|")
    for method in CV_METHODS:
        ours = calibrate_hand_eye(X_BE, X_CT, method)
        cons = calibrate_hand_eye(X_BE, X_CT, method, pairs="consecutive")
        cv = opencv_X_EC(X_BE, X_CT, method)
        (r_o, t_o), (r_c, t_c), (r_cv, t_cv), (r_d, t_d) = (
            errors(X_EC, ours), errors(X_EC, cons), errors(X_EC, cv), errors(cv, ours))
        print(f"| {method} | {np.degrees(r_o):.4f} | {1000 * t_o:.3f} | {np.degrees(r_cv):.4f} | "
              f"{1000 * t_cv:.3f} | {np.degrees(r_d):.1e} / {1000 * t_d:.1e} | "
              f"{np.degrees(r_c):.4f} / {1000 * t_c:.3f} |")

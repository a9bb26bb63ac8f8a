"""How far a calibration is from the truth, for the shipped examples (whose truth is known).

    .venv/bin/python examples/error_against_truth.py out/calibrate/calibration.json \
        handeye_drake/data/example_truth.json

Prints the rotation angle (degrees) and the translation distance (millimetres) between the X_EC
of `calibrate`'s calibration.json and the X_EC of a truth file (example_truth.json, or
example_images/truth.json: a 4×4 matrix), and the result's σ (norms of the per-axis 1σ).
"""

from __future__ import annotations

import json
import sys

import numpy as np

from handeye_drake.estimation.errors import rotation_error_deg


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print("usage: error_against_truth.py CALIBRATION_JSON TRUTH_JSON", file=sys.stderr)
        return 2
    result = json.loads(open(argv[0]).read())["X_EC"]
    X = np.array(result["matrix"])
    X_true = np.array(json.loads(open(argv[1]).read())["X_EC"])
    angle = rotation_error_deg(X_true, X)
    distance_mm = 1e3 * np.linalg.norm(X[:3, 3] - X_true[:3, 3])
    sigma_deg = np.linalg.norm(result["std"]["rotation_deg"])
    sigma_mm = 1e3 * np.linalg.norm(result["std"]["translation_m"])
    print(f"X_EC from the truth: {angle:.4f}° / {distance_mm:.3f} mm "
          f"(its σ: {sigma_deg:.4f}° / {sigma_mm:.3f} mm)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

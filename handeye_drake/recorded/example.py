"""Generator of the example recording shipped in ``handeye_drake/data/``.

A camera on the hand circles a fixed target for 20 s with smooth, non-periodic rotations (roll,
pitch and yaw oscillations of 25°, 20° and 30° at incommensurate frequencies, so motions between
samples rotate 10–30° about varied axes), keeping the target near its optical axis at ~0.5 m.

- robot stream ``example_robot.tum``: X_BE at 50 Hz from t = 0 to 20 s, exact (6 decimals);
- camera stream ``example_camera.tum``: X_CT at 15 Hz from t = −0.1 to 20.1 s (so a few camera
  samples fall outside the robot's span), stamped ``TIME_OFFSET`` = 0.02 s late (the camera's
  latency: stamp = instant + 0.02 s), with noise on the pose (rotation: a random rotation vector
  with σ = 0.1° per axis; translation: σ = 0.5 mm per axis), and two gross outliers (poses
  perturbed by 10–20° and 3–8 cm);
- ``example_truth.json``: the true X_EC (camera in end-effector), the offset, the outlier lines.

Regenerate with ``python -m handeye_drake.recorded.example OUT_DIR [--seed N]`` (the shipped
files use seed 0).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ..estimation.se3 import (
    inverse,
    make_transform,
    quat_wxyz,
    rotation_exp,
    rotation_from_rpy,
    rpy,
)

ROBOT_RATE = 50.0
CAMERA_RATE = 15.0
DURATION = 20.0
TIME_OFFSET = 0.02
ROTATION_NOISE_DEG = 0.1
TRANSLATION_NOISE = 0.0005
NUM_OUTLIERS = 2

#: The true camera-on-hand transform X_EC: camera 7 cm ahead of the flange, 4.5 cm aside,
#: turned 90° about the flange axis and slightly tilted.
TRUE_X_EC = make_transform(rotation_from_rpy(np.radians([1.5, -2.0, 90.0])),
                           [0.045, -0.012, 0.068])

#: The target, fixed in the robot base.
X_BT = make_transform(np.eye(3), [0.55, 0.05, 0.0])


def camera_pose(t: float) -> np.ndarray:
    """X_BC(t): the camera looks down at the target from ~0.5 m, rotating smoothly."""
    angles = np.radians([25.0 * np.sin(2 * np.pi * 0.11 * t + 0.3),
                         20.0 * np.sin(2 * np.pi * 0.17 * t + 1.1),
                         30.0 * np.sin(2 * np.pi * 0.07 * t + 2.0)])
    R_BC = rotation_from_rpy([np.pi, 0.0, 0.0]) @ rotation_from_rpy(angles)
    distance = 0.5 + 0.05 * np.sin(2 * np.pi * 0.13 * t)
    offset = np.array([0.03 * np.sin(2 * np.pi * 0.19 * t), 0.03 * np.cos(2 * np.pi * 0.23 * t),
                       0.0])
    p_BC = X_BT[:3, 3] + offset - distance * R_BC[:, 2]  # optical axis (z) through the target
    return make_transform(R_BC, p_BC)


def _tum_line(t: float, X: np.ndarray) -> str:
    w, x, y, z = quat_wxyz(X[:3, :3])
    p = X[:3, 3]
    return (f"{t:.6f} {p[0]:.6f} {p[1]:.6f} {p[2]:.6f} {x:.8f} {y:.8f} {z:.8f} {w:.8f}")


def generate_example(out_dir, seed: int = 0) -> dict:
    """Writes ``example_robot.tum``, ``example_camera.tum`` and ``example_truth.json`` in
    ``out_dir`` (created) and returns the truth dictionary. Deterministic for a given seed."""
    rng = np.random.default_rng(seed)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    X_CE = inverse(TRUE_X_EC)

    robot_times = np.arange(int(round(DURATION * ROBOT_RATE)) + 1) / ROBOT_RATE
    robot = ["# handeye_drake example robot stream: X_BE (end-effector in base), metres",
             "# timestamp tx ty tz qx qy qz qw"]
    for t in robot_times:
        robot.append(_tum_line(t, camera_pose(t) @ X_CE))

    instants = -0.1 + np.arange(int(round((DURATION + 0.2) * CAMERA_RATE)) + 1) / CAMERA_RATE
    n = len(instants)
    outliers = np.sort(rng.choice(np.arange(n // 5, 4 * n // 5), NUM_OUTLIERS, replace=False))
    header = ["# handeye_drake example camera stream: X_CT (target in camera), metres",
              f"# stamped {TIME_OFFSET} s late; noise {ROTATION_NOISE_DEG} deg / "
              f"{1000 * TRANSLATION_NOISE} mm; {NUM_OUTLIERS} gross outliers",
              "# timestamp tx ty tz qx qy qz qw"]
    camera, outlier_lines = list(header), []
    for k, tau in enumerate(instants):
        X_CT = inverse(camera_pose(tau)) @ X_BT
        noise = make_transform(rotation_exp(np.radians(ROTATION_NOISE_DEG) * rng.normal(size=3)),
                               TRANSLATION_NOISE * rng.normal(size=3))
        X_CT = noise @ X_CT
        if k in outliers:
            axis = rng.normal(size=3)
            axis /= np.linalg.norm(axis)
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction)
            gross = make_transform(rotation_exp(np.radians(rng.uniform(10, 20)) * axis),
                                   rng.uniform(0.03, 0.08) * direction)
            X_CT = gross @ X_CT
            outlier_lines.append(len(camera) + 1)
        camera.append(_tum_line(tau + TIME_OFFSET, X_CT))

    (out / "example_robot.tum").write_text("\n".join(robot) + "\n")
    (out / "example_camera.tum").write_text("\n".join(camera) + "\n")
    truth = {
        "description": "simulated recording for `handeye-drake calibrate` (see "
                       "handeye_drake/recorded/example.py)",
        "seed": seed,
        "X_EC": TRUE_X_EC.tolist(),
        "X_EC_translation": TRUE_X_EC[:3, 3].tolist(),
        "X_EC_quaternion_wxyz": quat_wxyz(TRUE_X_EC[:3, :3]).tolist(),
        "X_EC_rpy_deg": np.degrees(rpy(TRUE_X_EC[:3, :3])).tolist(),
        "time_offset_s": TIME_OFFSET,
        "robot_rate_hz": ROBOT_RATE,
        "camera_rate_hz": CAMERA_RATE,
        "rotation_noise_deg": ROTATION_NOISE_DEG,
        "translation_noise": TRANSLATION_NOISE,
        "outlier_camera_lines": outlier_lines,
    }
    (out / "example_truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return truth


def data_dir() -> Path:
    """The package's data directory holding the shipped example."""
    return Path(__file__).resolve().parent.parent / "data"


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out_dir", nargs="?", default=str(data_dir()))
    parser.add_argument("--seed", type=int, default=0)
    a = parser.parse_args()
    print(json.dumps(generate_example(a.out_dir, a.seed), indent=2))

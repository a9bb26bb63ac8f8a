"""Large recordings for ``handeye-drake calibrate``: generate them, and time the command on them.

    python benchmarks/calibrate_scale.py generate OUT_DIR --robot-lines N [--camera-lines M]
        [--camera-rate HZ] [--seed S]
    python benchmarks/calibrate_scale.py run OUT_DIR [--python PY] [-- extra calibrate args]

``generate`` writes ``robot.tum`` (X_BE at 50 Hz, N lines, exact to 6 decimals) and
``camera.tum`` (X_CT, M lines at ``--camera-rate`` from t = −0.1 s, stamped 0.02 s late, 0.1° /
0.5 mm noise, one gross outlier per 150 samples) of the motion of the shipped example
(``handeye_drake/recorded/example.py``: its ``camera_pose`` and ``TRUE_X_EC``, evaluated here
with numpy on whole time arrays so that 10⁶ lines take seconds), and ``truth.json``.

``run`` runs ``handeye-drake calibrate`` on them under ``/usr/bin/time -v`` and prints the wall
time, the peak resident memory and the error of the X_EC found against the truth.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from handeye_drake.recorded.example import (ROTATION_NOISE_DEG, TIME_OFFSET, TRANSLATION_NOISE,
                                            TRUE_X_EC, X_BT, camera_pose)

ROBOT_RATE = 50.0


def camera_poses(t: np.ndarray) -> np.ndarray:
    """``example.camera_pose`` on an array of times: (N, 4, 4) X_BC."""
    t = np.asarray(t, dtype=float)
    angles = np.radians(np.c_[25.0 * np.sin(2 * np.pi * 0.11 * t + 0.3),
                              20.0 * np.sin(2 * np.pi * 0.17 * t + 1.1),
                              30.0 * np.sin(2 * np.pi * 0.07 * t + 2.0)])
    R_BC = (Rotation.from_euler("xyz", [np.pi, 0.0, 0.0])
            * Rotation.from_euler("xyz", angles)).as_matrix()
    distance = 0.5 + 0.05 * np.sin(2 * np.pi * 0.13 * t)
    offset = np.c_[0.03 * np.sin(2 * np.pi * 0.19 * t), 0.03 * np.cos(2 * np.pi * 0.23 * t),
                   np.zeros_like(t)]
    X = np.zeros((len(t), 4, 4))
    X[:, :3, :3] = R_BC
    X[:, :3, 3] = X_BT[:3, 3] + offset - distance[:, None] * R_BC[:, :, 2]
    X[:, 3, 3] = 1.0
    return X


def _inverse(X: np.ndarray) -> np.ndarray:
    out = np.zeros_like(X)
    Rt = np.transpose(X[:, :3, :3], (0, 2, 1))
    out[:, :3, :3] = Rt
    out[:, :3, 3] = -np.einsum("nij,nj->ni", Rt, X[:, :3, 3])
    out[:, 3, 3] = 1.0
    return out


def _write_tum(path: Path, header: list[str], t: np.ndarray, X: np.ndarray) -> None:
    q = Rotation.from_matrix(X[:, :3, :3]).as_quat()  # x y z w
    q[q[:, 3] < 0] *= -1.0  # w ≥ 0, as example.py writes them
    p = X[:, :3, 3]
    with open(path, "w") as f:
        f.write("".join(h + "\n" for h in header))
        block = 100_000
        for s in range(0, len(t), block):
            e = min(s + block, len(t))
            f.write("".join(
                f"{t[k]:.6f} {p[k, 0]:.6f} {p[k, 1]:.6f} {p[k, 2]:.6f} {q[k, 0]:.8f} "
                f"{q[k, 1]:.8f} {q[k, 2]:.8f} {q[k, 3]:.8f}\n" for k in range(s, e)))


def generate(out_dir, robot_lines: int, camera_lines: int = 304, camera_rate: float = 15.0,
             seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    X_CE = np.linalg.inv(TRUE_X_EC)
    t_r = np.arange(robot_lines) / ROBOT_RATE
    _write_tum(out / "robot.tum", ["# X_BE (end-effector in base), metres",
                                   "# timestamp tx ty tz qx qy qz qw"],
               t_r, camera_poses(t_r) @ X_CE)
    tau = -0.1 + np.arange(camera_lines) / camera_rate
    X_CT = _inverse(camera_poses(tau)) @ X_BT
    noise = np.zeros_like(X_CT)
    noise[:, :3, :3] = Rotation.from_rotvec(
        np.radians(ROTATION_NOISE_DEG) * rng.normal(size=(camera_lines, 3))).as_matrix()
    noise[:, :3, 3] = TRANSLATION_NOISE * rng.normal(size=(camera_lines, 3))
    noise[:, 3, 3] = 1.0
    X_CT = noise @ X_CT
    n_out = max(2, camera_lines // 150)
    outliers = np.sort(rng.choice(np.arange(camera_lines // 5, 4 * camera_lines // 5), n_out,
                                  replace=False))
    axis = rng.normal(size=(n_out, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    direction = rng.normal(size=(n_out, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    gross = np.zeros((n_out, 4, 4))
    gross[:, :3, :3] = Rotation.from_rotvec(
        np.radians(rng.uniform(10, 20, n_out))[:, None] * axis).as_matrix()
    gross[:, :3, 3] = rng.uniform(0.03, 0.08, n_out)[:, None] * direction
    gross[:, 3, 3] = 1.0
    X_CT[outliers] = gross @ X_CT[outliers]
    header = ["# X_CT (target in camera), metres", "# timestamp tx ty tz qx qy qz qw"]
    _write_tum(out / "camera.tum", header, tau + TIME_OFFSET, X_CT)
    truth = {"X_EC": TRUE_X_EC.tolist(), "time_offset_s": TIME_OFFSET,
             "robot_lines": robot_lines, "camera_lines": camera_lines,
             "camera_rate_hz": camera_rate, "seed": seed,
             "outlier_camera_lines": (outliers + len(header) + 1).tolist()}
    (out / "truth.json").write_text(json.dumps(truth, indent=1) + "\n")
    return truth


def _rotation_error_deg(X1, X2) -> float:
    return float(np.degrees(np.linalg.norm(
        Rotation.from_matrix(np.asarray(X1)[:3, :3].T @ np.asarray(X2)[:3, :3]).as_rotvec())))


def run(out_dir, python: str = sys.executable, extra=()) -> dict:
    """``handeye-drake calibrate`` on OUT_DIR/{robot,camera}.tum under /usr/bin/time -v."""
    d = Path(out_dir)
    shutil.rmtree(d / "out", ignore_errors=True)  # the command writes only into a new directory
    cmd = ["/usr/bin/time", "-v", python, "-m", "handeye_drake.apps.cli", "calibrate", "--robot",
           str(d / "robot.tum"), "--camera", str(d / "camera.tum"), "--out", str(d / "out"),
           *extra]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", p.stderr)
    res = {"returncode": p.returncode, "wall_s": round(wall, 2),
           "peak_rss_mb": round(int(rss.group(1)) / 1024) if rss else None}
    if p.returncode == 0:
        truth = json.loads((d / "truth.json").read_text())
        cal = json.loads((d / "out" / "calibration.json").read_text())
        X, X_true = np.array(cal["X_EC"]["matrix"]), np.array(truth["X_EC"])
        res.update(rotation_error_deg=round(_rotation_error_deg(X_true, X), 4),
                   translation_error_mm=round(1000 * float(np.linalg.norm(X[:3, 3]
                                                                          - X_true[:3, 3])), 3),
                   time_offset_s=cal["time_offset"]["value_s"],
                   std_rotation_deg=cal["std"]["rotation_deg"])
    else:
        res["stderr_tail"] = [ln for ln in p.stderr.splitlines() if "error" in ln.lower()][-3:]
    return res


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    g = sub.add_parser("generate")
    g.add_argument("out_dir")
    g.add_argument("--robot-lines", type=int, required=True)
    g.add_argument("--camera-lines", type=int, default=304)
    g.add_argument("--camera-rate", type=float, default=15.0)
    g.add_argument("--seed", type=int, default=0)
    r = sub.add_parser("run")
    r.add_argument("out_dir")
    r.add_argument("--python", default=sys.executable)
    r.add_argument("extra", nargs="*")
    a = parser.parse_args()
    if a.command == "generate":
        assert np.allclose(camera_poses(np.array([0.0, 7.3]))[1], camera_pose(7.3), atol=1e-12)
        print(json.dumps(generate(a.out_dir, a.robot_lines, a.camera_lines, a.camera_rate,
                                  a.seed)))
    else:
        print(json.dumps(run(a.out_dir, a.python, a.extra)))

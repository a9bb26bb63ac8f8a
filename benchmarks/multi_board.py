"""Multi-camera rig with two boards: one joint fit of both boards against the rig of one board.

    OPENBLAS_NUM_THREADS=1 python benchmarks/multi_board.py [--seeds 0 1 2] [--images 10]

For each seed a rig is rendered (``recorded.example_rig`` with ``two_boards()`` and
``TWO_BOARD_RIG``: a UR5e, the ChArUco board ``table`` (DICT_5X5_100) and 0.5 m beside it the
board ``side`` (DICT_4X4_50); two hand cameras ``wrist``/``wrist2`` 6 cm apart that see ``table``
in the first ``--images`` robot poses and ``side`` in 4 more; a cell camera ``cell`` watching
``table``, a cell camera ``side`` watching ``side``); the recorded robot poses carry an error that
repeats with the joint angles (``--robot-error`` deg,mm per axis). On the same images:

- one board: ``calibrate_rig`` with ``table`` only (the reference: what the command line did
  before several boards) — the camera ``side`` sees at most a corner of that board, far away;
- two boards: ``calibrate_rig`` with both boards, each board's pose one unknown for all cameras.

Printed per seed and answer: the error to the truth (rotation deg, translation mm), its σ (norms
of the per-axis values) and NEES (error whitened by its covariance: χ²(6), mean 6 when σ is
honest); then the means over the seeds and the ratio one board / two boards of the errors.
"""
import argparse
import math
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from handeye_drake.calibration.api import CalibrationOptions
from handeye_drake.calibration.rig import RigBoard, RigCamera, calibrate_rig
from handeye_drake.estimation.rig_bundle import tangent
from handeye_drake.recorded.example_rig import TWO_BOARD_RIG, generate_example_rig, two_boards


def _err(X, X_true, C):
    e = tangent(X, np.asarray(X_true))
    s = np.sqrt(np.maximum(np.diag(C), 0.0))
    return (math.degrees(np.linalg.norm(e[:3])), 1000 * np.linalg.norm(e[3:]),
            math.degrees(np.linalg.norm(s[:3])), 1000 * np.linalg.norm(s[3:]),
            float(e @ np.linalg.solve(C, e)))


def _answers(r, truth):
    out = {}
    for n, c in r.cameras.items():
        if c.X is not None and c.verdict.status != "FAIL":
            out[f"{c.key} {n}"] = _err(c.X, truth["cameras"][n][c.key], c.covariance)
    for n, b in r.boards.items():
        if b.X is not None:
            out[f"{b.key} {n}"] = _err(b.X, truth["boards"][n][b.key], b.covariance)
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--images", type=int, default=10)
    p.add_argument("--robot-error", default="0.02,0.2", help="deg,mm per axis")
    p.add_argument("--robot-accuracy", default="0.03,0.3",
                   help="deg,mm: the robot's accuracy the calibration is told (the command "
                        "line's --robot-accuracy, default its default; 0,0 leaves it out)")
    a = p.parse_args()
    deg, mm = (float(v) for v in a.robot_error.split(","))
    acc = [float(v) for v in a.robot_accuracy.split(",")]
    options = CalibrationOptions(refine_intrinsics="none", robot_accuracy_deg=acc[0],
                                 robot_accuracy_mm=acc[1])
    rows = {"one board": {}, "two boards": {}}
    for seed in a.seeds:
        tmp = Path(tempfile.mkdtemp(prefix="multi_board_"))
        try:
            truth = generate_example_rig(tmp, seed=seed, num_images=a.images,
                                         cameras=TWO_BOARD_RIG, boards=two_boards(),
                                         board_images={"side": 4},
                                         robot_error=(deg, mm / 1000.0))
            cams = [RigCamera(n, tmp / n, m, str(tmp / n / "intrinsics.yaml"))
                    for n, (m, _) in TWO_BOARD_RIG.items()]
            boards = [RigBoard(n, b["target"], b["mount"]) for n, b in truth["boards"].items()]
            for label, bs in (("one board", boards[:1]), ("two boards", boards)):
                t0 = time.perf_counter()
                r = calibrate_rig(cams, tmp / "robot_poses.tum", bs, options=options)
                dt = time.perf_counter() - t0
                print(f"seed {seed}, {label}: rig {r.verdict.status} ({dt:.1f} s)"
                      + "".join(f"; camera {n} FAIL: {c.verdict.reasons[0].message[:80]}"
                                for n, c in r.cameras.items() if c.verdict.status == "FAIL"))
                for k, (er, et, sr, st, nees) in _answers(r, truth).items():
                    rows[label].setdefault(k, []).append((er, et, nees))
                    print(f"  {k:10s} {er:.4f}° / {et:.3f} mm (σ {sr:.4f}° / {st:.3f} mm), "
                          f"NEES {nees:.1f}")
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    print(f"\nmean over seeds {a.seeds} (robot error {deg}° / {mm} mm per axis"
          + f"; robot accuracy told {acc[0]}° / {acc[1]} mm):")
    print("| answer | one board | two boards | ratio one / two (rotation, translation) |")
    print("|---|---|---|---|")
    for k in rows["two boards"]:
        two = np.mean(rows["two boards"][k], axis=0)
        one = np.mean(rows["one board"][k], axis=0) if k in rows["one board"] and len(
            rows["one board"][k]) == len(a.seeds) else None
        cell = "— (not calibrated)" if one is None else \
            f"{one[0]:.4f}° / {one[1]:.3f} mm (NEES {one[2]:.1f})"
        ratio = "—" if one is None else f"{one[0] / two[0]:.2f}, {one[1] / two[1]:.2f}"
        print(f"| {k} | {cell} | {two[0]:.4f}° / {two[1]:.3f} mm (NEES {two[2]:.1f}) | "
              f"{ratio} |")


if __name__ == "__main__":
    main()

"""Multi-camera rig: the joint fit against separate single-camera calibrations on the same images.

    OPENBLAS_NUM_THREADS=1 python benchmarks/multi_camera.py [--seeds 0 1 2] [--images 12]

For each seed a rig is rendered (``recorded.example_rig``: UR5e, a ChArUco board in the cell, two
hand cameras ``wrist`` and ``wrist2`` 6 cm apart — ``wrist2`` with strong barrel distortion, its
images re-mapped through OpenCV's model — and a ``cell`` camera watching the board from 0.9 m);
the recorded robot poses carry an error that repeats with the joint angles (``--robot-error``
deg,mm per axis). Each seed is calibrated twice: with ``wrist2`` seeing the board in every
image, and in its first 5 only (``--wrist2-images``: a camera that often looks away; blank
frames keep the pairing by index). On the same images:

- separate: each camera calibrated alone by the single-camera pipeline
  (``corners.calibrate_images``, what ``calibrate --images`` does); the cell camera sees one fixed
  view of a fixed board and cannot be calibrated alone;
- joint: ``calibration.rig.calibrate_rig`` (the board's pose one unknown for every camera).

``--rig flange``: two cameras fixed in the cell (``cell_a``, ``cell_b``, 40° apart at 0.8 m)
watch a 15 × 12 cm board on a bracket on the flange (eye-to-hand: each can be calibrated alone;
the arm hides the board in some images).

Printed per seed and camera: the error to the truth (rotation deg, translation mm) of X_EC / X_BC
and of the camera-to-camera transform X_wrist_wrist2 (separate: X_EC,1⁻¹ X_EC,2 of the two
separate answers), with each answer's σ (norms of the per-axis values) and its NEES (error
whitened by its covariance: χ²(6), mean 6 when σ is honest); then the mean over the seeds and the
ratio separate / joint of the errors.
"""
import argparse
import math
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from handeye_drake.calibration.api import CalibrationOptions
from handeye_drake.calibration.rig import RigCamera, calibrate_rig
from handeye_drake.estimation.rig_bundle import tangent
from handeye_drake.recorded.example_rig import generate_example_rig, relative_truth

DISTORTION = {"wrist2": (-0.28, 0.09, 0.0005, -0.0003, 0.0)}


def _err(X, X_true, C):
    e = tangent(X, X_true)
    s = np.sqrt(np.maximum(np.diag(C), 0.0))
    return (math.degrees(np.linalg.norm(e[:3])), 1000 * np.linalg.norm(e[3:]),
            math.degrees(np.linalg.norm(s[:3])), 1000 * np.linalg.norm(s[3:]),
            float(e @ np.linalg.solve(C, e)))


def _relative_separate(a, b):
    """X_{C_a C_b} of two separate answers and its covariance (independent answers: the
    first-order propagation of both covariances)."""
    from handeye_drake.estimation.rig_bundle import RigFit
    cols = {("camera", 0): slice(0, 6), ("camera", 1): slice(6, 12)}
    C = np.zeros((12, 12))
    C[:6, :6], C[6:, 6:] = a.covariance, b.covariance
    f = RigFit([a.X_hand, b.X_hand], [], [], [], C, cols, [])
    return f.relative(0, 1)


#: The pair of cameras on one mount whose transform is compared, per rig.
PAIRS = {"table": ("wrist", "wrist2"), "flange": ("cell_a", "cell_b")}


def render(tmp, seed, images, robot_error, rig="table"):
    t0 = time.perf_counter()
    if rig == "table":
        truth = generate_example_rig(tmp, seed=seed, num_images=images, distortion=DISTORTION,
                                     robot_error=robot_error)
    else:
        truth = generate_example_rig(tmp, seed=seed, num_images=images, robot_error=robot_error,
                                     board_mount="hand")
    return truth, time.perf_counter() - t0


def run(tmp, truth, refine, wrist2_images, rig="table"):
    """Separate and joint answers; on the table rig with wrist2 seeing the board in its first
    ``wrist2_images`` images only (it looks away after them: blank frames keep the pairing by
    index)."""
    import cv2
    images = len(truth["X_BE"])
    dirs = {n: Path(tmp) / n for n in truth["cameras"]}
    if rig == "table":
        folder = Path(tmp) / f"wrist2_{wrist2_images}"
        shutil.copytree(Path(tmp) / "wrist2", folder, dirs_exist_ok=True)
        for k in range(wrist2_images, images):
            path = str(folder / f"img_{k:03d}.png")
            cv2.imwrite(path, np.full_like(cv2.imread(path, 0), 80))
        dirs["wrist2"] = folder
    cams = [RigCamera(n, dirs[n], c["mount"], str(dirs[n] / "intrinsics.yaml"))
            for n, c in truth["cameras"].items()]
    t0 = time.perf_counter()
    rig_result = calibrate_rig(cams, f"{tmp}/robot_poses.tum", truth["target"],
                               board_mount=truth.get("board_mount", "cell"),
                               options=CalibrationOptions(refine_intrinsics=refine))
    pair = PAIRS[rig]
    rig = rig_result
    t_fit = time.perf_counter() - t0
    rows = {}
    for name, c in rig.cameras.items():
        X_true = np.asarray(truth["cameras"][name][c.key])
        sep = None if c.alone is None else _err(c.alone.X_hand, X_true, c.alone.covariance)
        joint = None if c.X is None else _err(c.X, X_true, c.covariance)
        rows[f"{c.key} {name}"] = (sep, joint)
    a, b = rig.cameras[pair[0]], rig.cameras[pair[1]]
    rel_true = relative_truth(truth, *pair)
    sep = None
    if a.alone is not None and b.alone is not None:
        sep = _err(*_relative_separate(a.alone, b.alone)[:1], rel_true,
                   _relative_separate(a.alone, b.alone)[1])
    X, C = rig.relative.get(pair, (None, None))
    rows[f"X_{pair[0]}_{pair[1]}"] = (sep, None if X is None else _err(X, rel_true, C))
    return rig, rows, t_fit


def fmt(v):
    if v is None:
        return "—"
    return f"{v[0]:.4f}° / {v[1]:.3f} mm (σ {v[2]:.4f}° / {v[3]:.3f} mm, NEES {v[4]:.1f})"


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--images", type=int, default=12)
    p.add_argument("--robot-error", type=float, nargs=2, default=(0.02, 0.2),
                   metavar=("DEG", "MM"))
    p.add_argument("--refine-intrinsics", default="auto")
    p.add_argument("--wrist2-images", type=int, nargs="+", default=[12, 5],
                   help="runs with wrist2 seeing the board in its first N images only")
    p.add_argument("--rig", choices=("table", "flange"), default="table",
                   help="table: wrist + wrist2 + cell camera, the board on the table; flange: "
                        "two cell cameras watching a board on the flange")
    a = p.parse_args()
    if a.rig == "flange":
        a.wrist2_images = [a.images]
    robot_error = (a.robot_error[0], a.robot_error[1] / 1000.0)
    what = ("wrist + wrist2 (distorted) on the hand, cell camera fixed; board in the cell"
            if a.rig == "table" else "cell_a and cell_b fixed in the cell; board on the flange")
    print(f"rig: {what}; {a.images} images per camera; robot pose error {a.robot_error[0]}° / "
          f"{a.robot_error[1]} mm per axis (repeats with the joint angles); "
          f"--refine-intrinsics {a.refine_intrinsics}")
    variants = [min(n, a.images) for n in a.wrist2_images]
    sums = {n: {} for n in variants}
    for seed in a.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            truth, t_render = render(tmp, seed, a.images, robot_error, a.rig)
            for n2 in variants:
                rig, rows, t_fit = run(tmp, truth, a.refine_intrinsics, n2, a.rig)
                seen = f"wrist2 sees the board in {n2} of {a.images} images" \
                    if a.rig == "table" else f"{a.images} images"
                print(f"\nseed {seed}, {seen}: rig "
                      f"verdict {rig.verdict.status}; render {t_render:.1f} s, separate + joint "
                      f"calibration {t_fit:.1f} s")
                print(f"| {'answer':<16} | {'separate (single-camera)':<58} | "
                      f"{'joint (rig)':<58} |")
                for k, (sep, joint) in rows.items():
                    print(f"| {k:<16} | {fmt(sep):<58} | {fmt(joint):<58} |")
                    acc = sums[n2].setdefault(k, [[], []])
                    if sep is not None:
                        acc[0].append(sep)
                    if joint is not None:
                        acc[1].append(joint)
    for n2 in variants:
        seen = f"wrist2 sees the board in {n2} of {a.images} images" if a.rig == "table" \
            else "board on the flange"
        print(f"\n{seen} — mean over seeds "
              f"{' '.join(map(str, a.seeds))} (error to the truth; ratio separate / joint):")
        print("| answer | separate | joint | ratio (rotation, translation) |")
        print("|---|---|---|---|")
        for k, (sep, joint) in sums[n2].items():
            ms = np.mean(sep, axis=0) if sep else None
            mj = np.mean(joint, axis=0) if joint else None
            ratio = "—" if ms is None or mj is None else \
                f"{ms[0] / mj[0]:.2f}, {ms[1] / mj[1]:.2f}"
            s = "— (cannot calibrate alone)" if ms is None else \
                f"{ms[0]:.4f}° / {ms[1]:.3f} mm (NEES {ms[4]:.1f})"
            j = "—" if mj is None else f"{mj[0]:.4f}° / {mj[1]:.3f} mm (NEES {mj[4]:.1f})"
            print(f"| {k} | {s} | {j} | {ratio} |")


if __name__ == "__main__":
    main()

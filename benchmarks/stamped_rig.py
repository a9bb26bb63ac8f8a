"""Image folders paired in time: each camera's clock offset estimated against ignoring it.

    OPENBLAS_NUM_THREADS=1 python benchmarks/stamped_rig.py [--seeds 0 1 2] [--poses 8]

For each seed a rig is rendered as real cells record (``recorded.example_rig.generate_stamped_rig``:
the UR5e moving through ``--poses`` poses without stopping, its flange pose at 100 Hz on an epoch
clock with an error that repeats with the joint angles, ``--robot-error`` deg,mm per axis; hand
cameras ``wrist`` every 0.35 s and ``wrist2`` every 0.5 s, 15 % of the frames dropped, their
clocks +30 ms and −20 ms off the robot's; files ``frame_<ns>.png`` and a ``timestamps.txt``).
The rig is calibrated twice on the same images, paired in time (``calibration.rig``):

- estimated: each camera's clock offset estimated on its own (the default);
- ignored: the offset taken as 0 (``--time-offset 0``: the images paired with the robot pose at
  their stamp, as if the clocks agreed).

Printed per seed and camera: the estimated offset against the truth, the error to the truth
(rotation deg, translation mm) of X_EC (the rig's answer, or the camera's own when the rig left it
out) and of X_wrist_wrist2, its NEES (χ²(6): mean 6 when σ is honest) and the verdict with its
FAIL reasons; then the mean over the seeds and the ratio ignored / estimated of the errors.
"""
import argparse
import math
import shutil
import tempfile
from pathlib import Path

import numpy as np

from handeye_drake.calibration.api import CalibrationOptions
from handeye_drake.calibration.rig import RigCamera, calibrate_rig
from handeye_drake.estimation.rig_bundle import tangent
from handeye_drake.recorded.example_rig import DEFAULT_RIG, generate_stamped_rig, relative_truth

CAMERAS = {"wrist": DEFAULT_RIG["wrist"], "wrist2": DEFAULT_RIG["wrist2"]}


def _err(X, X_true, C):
    e = tangent(X, X_true)
    return (math.degrees(np.linalg.norm(e[:3])), 1000 * np.linalg.norm(e[3:]),
            float(e @ np.linalg.solve(C, e)))


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--poses", type=int, default=8)
    p.add_argument("--robot-error", default="0.02,0.2", metavar="DEG,MM")
    a = p.parse_args()
    deg, mm = (float(v) for v in a.robot_error.split(","))
    rows = {"estimated": [], "ignored": []}
    for seed in a.seeds:
        out = Path(tempfile.mkdtemp(prefix=f"stamped_rig_{seed}_"))
        try:
            truth = generate_stamped_rig(
                out, seed=seed, num_poses=a.poses, cameras=CAMERAS,
                periods={"wrist": 0.35, "wrist2": 0.5}, offsets={"wrist": 0.03, "wrist2": -0.02},
                styles={"wrist": "nanoseconds", "wrist2": "file"}, drop=0.15,
                robot_error=(deg, mm / 1000.0), supersample=2)
            cams = [RigCamera(n, out / n, "hand", str(out / n / "intrinsics.yaml"))
                    for n in CAMERAS]
            for how, offset in (("estimated", None), ("ignored", 0.0)):
                r = calibrate_rig(cams, out / "robot_poses.tum", truth["target"],
                                  options=CalibrationOptions(refine_intrinsics="none",
                                                             time_offset_s=offset))
                row = {}
                for n, c in r.cameras.items():
                    # A camera left out of the rig's answer: its own (single-camera) answer.
                    X, C, which = (c.X, c.covariance, "rig") if c.X is not None else (
                        (c.alone.X_hand, c.alone.covariance, "alone") if c.alone is not None
                        else (None, None, ""))
                    codes = ",".join(r.code for r in c.verdict.reasons if r.level == "FAIL")
                    if X is None:
                        row[n] = None
                        print(f"seed {seed} {how:9s} {n:6s}: no answer (FAIL {codes})")
                        continue
                    e = _err(X, np.asarray(truth["cameras"][n]["X_EC"]), C)
                    off = c.alone.aligned.time_offset
                    row[n] = e
                    print(f"seed {seed} {how:9s} {n:6s}: offset {1000 * off:+7.2f} ms (true "
                          f"{1000 * truth['cameras'][n]['time_offset_s']:+.0f}), "
                          f"{len(c.alone.aligned)} images; X_EC ({which}) {e[0]:.4f}° / "
                          f"{e[1]:.3f} mm, NEES {e[2]:.1f}; {c.verdict.status}"
                          + (f" {codes}" if codes else ""))
                for (x, y), (X, C) in r.relative.items():
                    e = _err(X, relative_truth(truth, x, y), C)
                    row["relative"] = e
                    print(f"seed {seed} {how:9s} X_{x}_{y}: {e[0]:.4f}° / {e[1]:.3f} mm, NEES "
                          f"{e[2]:.1f}; rig {r.verdict.status}")
                rows[how].append(row)
        finally:
            shutil.rmtree(out, ignore_errors=True)
    print(f"\nmean over seeds {' '.join(map(str, a.seeds))}:")
    for key in ("wrist", "wrist2", "relative"):
        means = {}
        for how in rows:
            v = [r[key] for r in rows[how] if r.get(key) is not None]
            means[how] = np.mean(v, axis=0) if v else None
        est, ign = means["estimated"], means["ignored"]
        text = [f"{how} {m[0]:.4f}° / {m[1]:.3f} mm (NEES {m[2]:.1f})" if m is not None else
                f"{how} none" for how, m in means.items()]
        ratio = (f"; ratio ignored / estimated {ign[0] / est[0]:.2f}, {ign[1] / est[1]:.2f}"
                 if est is not None and ign is not None else "")
        print(f"  {key:8s}: " + ", ".join(text) + ratio)


if __name__ == "__main__":
    main()

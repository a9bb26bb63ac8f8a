"""Issue 37, family 2: every restricted intrinsics model × every kind of wrong held-fixed value,
on synthetic corner sets (``tests/corner_synth.py``: OpenCV's camera model with barrel
distortion, robot pose errors that repeat with the pose, 0.15 px corner noise), each case with
``SEEDS`` seeds. Prints one row per case: the verdict, the cause named (the held-intrinsics
test's parameters), the answer's error against the truth and in its own σ (√NEES, 6 dof), and
counts the defects: an OK answer outside its σ (√NEES > 4.7, χ²(6)'s 0.999 quantile), a
wrong parameter named, a right recording refused.

    PYTHONPATH=. python benchmarks/held_intrinsics.py [--seeds N] [--models none,focal]

The shipped rendered images (``handeye_drake/data/example_images``, exact intrinsics) are in
``tests/apps/test_calibrate_corners.py``; this is the wider, faster matrix.
"""

from __future__ import annotations

import argparse
import sys
import time
import zlib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

KINDS = ("right", "focal", "cx", "cy", "k1flip", "k1=0", "p1", "p2", "k3")
OUTSIDE = 4.7


def wrong(kind, rng):
    from tests.corner_synth import TRUTH
    names = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
    v = TRUTH.copy()
    sign = rng.choice([-1.0, 1.0])
    if kind == "right":
        return v, ()
    if kind == "focal":
        v[:2] *= 1 + sign * rng.uniform(0.025, 0.04)
        return v, ("fx", "fy")
    if kind in ("cx", "cy"):
        v[names.index(kind)] += sign * rng.uniform(20, 35)
        return v, (kind,)
    if kind == "k1flip":
        v[4:6] = -v[4:6]
        return v, ("k1", "k2")
    if kind == "k1=0":
        v[4:6] = 0.0
        return v, ("k1", "k2")
    if kind == "k3":
        v[8] += sign * rng.uniform(0.05, 0.15)
        return v, ("k3",)
    v[names.index(kind)] += sign * rng.uniform(0.003, 0.006)
    return v, (kind,)


def main() -> int:
    from handeye_drake import rotation_error_deg
    from handeye_drake.calibration import CalibrationOptions, solve
    from handeye_drake.calibration.held_intrinsics import held_parameters
    from handeye_drake.estimation.se3 import rotation_log
    from tests.corner_synth import corner_streams

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--models", default="none,focal,pinhole,k1k2")
    ap.add_argument("--mode", default="eye_in_hand")
    a = ap.parse_args()
    print(f"{'model':8} {'wrong':7} {'seed':>4}  {'verdict':7} {'cause named':24} "
          f"{'error':>16} {'√NEES':>6}  {'s':>4}")
    defects = {"ok_outside_sigma": 0, "wrong_cause": 0, "right_refused": 0}
    cases = 0
    for model in a.models.split(","):
        for kind in KINDS:
            for seed in range(a.seeds):
                rng = np.random.default_rng(zlib.crc32(f"{model}-{kind}-{seed}".encode()))
                given, bad = wrong(kind, rng)
                held = held_parameters(model, given)
                if bad and not set(bad) & set(held):
                    continue            # the model refines it: not a held-fixed case
                streams, truth = corner_streams(given, a.mode, n=12, seed=seed)
                t0 = time.perf_counter()
                r = solve(streams, CalibrationOptions(mode=a.mode, refine_intrinsics=model))
                dt = time.perf_counter() - t0
                X, T = r.X_hand, truth["X_hand"]
                d = np.concatenate([rotation_log(T[:3, :3] @ X[:3, :3].T), T[:3, 3] - X[:3, 3]])
                sig = float(np.sqrt(d @ np.linalg.solve(r.covariance, d)))
                test = r.corners.held or {}
                named = [n["name"] for n in test.get("named", [])]
                codes = [x.code for x in r.verdict.reasons]
                cause = ",".join(named) if named else ("/".join(codes) or "-")
                status = r.verdict.status
                cases += 1
                if status == "OK" and sig > OUTSIDE:
                    defects["ok_outside_sigma"] += 1
                # The cause: the intrinsics, and the held parameter named when the held-value
                # test named one (a refined one is named by the refined-intrinsics reason).
                first = r.verdict.reasons[0].code if r.verdict.reasons else ""
                if bad and status != "OK" and (first != "intrinsics"
                                               or (named and named[0] not in bad)):
                    defects["wrong_cause"] += 1
                if not bad and status != "OK":
                    defects["right_refused"] += 1
                print(f"{model:8} {kind:7} {seed:4d}  {status:7} {cause[:24]:24} "
                      f"{rotation_error_deg(T, X):6.3f}° {1000 * np.linalg.norm(d[3:]):6.2f} mm "
                      f"{sig:6.1f}  {dt:4.1f}", flush=True)
    print(f"{cases} cases; defects: {defects}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

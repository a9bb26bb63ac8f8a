"""Leave-one-out pixel error of ``calibrate``'s default answer against a plain corner bundle, on
synthetic corner sets as unkind as real cells (``tests/robot_cells.py``): a UR5e with perturbed
kinematics (pose errors that repeat with the joint angles) or independent per-image robot pose
errors, eye-in-hand and eye-to-hand, strong lens distortion, few images, little rotation.

Each of ``--leave-out`` images (evenly spread over the set) is left out in turn and predicted
from the others: by the default answer (``calibration.api.solve``, default options, the given
intrinsics, ``--refine-intrinsics auto``) and by a plain corner bundle — hand-eye and fixed pose
fitted to every corner, robot poses taken as exact, every image weighted equally — once with the
given intrinsics held and once with fx fy cx cy k1 k2 refined. Printed per set: RMS px of the
left-out corners, and the ratio of the default answer to the better of the two bundles
(≤ 1.05: as good as the plain bundle). Also each answer's error against the truth and its NEES
(χ²(6): 6).

    .venv/bin/python benchmarks/loo_vs_bundle.py [--leave-out 0] [--seed 1] [--per-axis]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from handeye_drake.calibration.api import CalibrationOptions, solve  # noqa: E402
from handeye_drake.estimation import reprojection as rp  # noqa: E402
from handeye_drake.estimation.se3 import inverse, rotation_log  # noqa: E402
from tests.robot_cells import corner_set, streams_of  # noqa: E402

#: (title, corner_set keyword arguments)
SETS = [
    ("eye-in-hand, perturbed-DH UR5e (≈ 2 mm), strong distortion, 10 images",
     dict(mode="eye_in_hand", n=10, robot="dh")),
    ("eye-to-hand, 1920×1200, board 0.5–0.8 m, lens beyond its 5 coefficients, DH ≈ 0.3 mm",
     dict(mode="eye_to_hand", n=10, robot="dh", width=1920, height=1200, f=1400.0,
          distance=(0.5, 0.8), pixel_noise=0.1, dh_error=(0.3e-3, 0.02),
          lens_extra=(0.02, 0.001))),
    ("eye-in-hand, perturbed-DH UR5e (≈ 5 mm), half the images see part of the board",
     dict(mode="eye_in_hand", n=10, robot="dh", partial=0.5, dh_error=(4e-3, 0.3))),
    ("eye-to-hand, independent errors 0.2°/1.5 mm, 10 images",
     dict(mode="eye_to_hand", n=10, robot="independent")),
    ("eye-in-hand, perturbed-DH UR5e, 7 images",
     dict(mode="eye_in_hand", n=7, robot="dh")),
    ("eye-in-hand, perturbed-DH UR5e, little rotation, 10 images",
     dict(mode="eye_in_hand", n=10, robot="dh", tilt=0.12, distortion=(-0.05, 0.0, 0, 0, 0))),
]


def robot_side(mode, X_BE):
    return X_BE if mode == "eye_in_hand" else np.linalg.inv(X_BE)


def bundle(cs, rest, X_H0, X_F0, model):
    """Plain corner bundle on images ``rest``: robot exact (the per-image pose error held at the
    fit's floor), equal weights, no outlier rejection."""
    data = rp.CornerData.from_lists(robot_side(cs.mode, cs.X_BE[rest]),
                                    [cs.object_points[k] for k in rest],
                                    [cs.image_points[k] for k in rest])
    return rp.fit_corners(data, X_H0, X_F0, cs.intrinsics, model, pixel_sigma0=0.2,
                          pose_sigma0=np.r_[[rp.POSE_SIGMA_FLOOR[0]] * 3,
                                            [rp.POSE_SIGMA_FLOOR[1]] * 3],
                          estimate_noise=False, robust=False,
                          pose_error_frame="camera" if cs.mode == "eye_in_hand" else "target")


def predicted_sq(fit, cs, k):
    uv = rp.predict(fit, robot_side(cs.mode, cs.X_BE[k]), cs.object_points[k])
    return np.sum((uv - cs.image_points[k]) ** 2, axis=1)


def errors(X, X_true, cov):
    d = np.concatenate([rotation_log(X[:3, :3] @ X_true[:3, :3].T), X[:3, 3] - X_true[:3, 3]])
    return (math.degrees(np.linalg.norm(d[:3])), 1000 * np.linalg.norm(d[3:]),
            float(d @ np.linalg.solve(cov, d)))


def run(title, kw, seed, leave_out):
    rng = np.random.default_rng(seed)
    cs = corner_set(rng, **kw)
    K = len(cs.X_BE)
    options = CalibrationOptions(mode=kw["mode"])
    full = solve(streams_of(cs), options)
    out = sorted(set(np.linspace(0, K - 1, min(leave_out or K, K)).round().astype(int)))
    sq = {"ours": [], "bundle (given)": [], "bundle (k1k2)": []}
    for k in out:
        rest = np.setdiff1d(np.arange(K), [k])
        r = solve(streams_of(cs, rest), options)
        sq["ours"].append(predicted_sq(r.corners.fit, cs, k))
        for name, model in (("bundle (given)", "none"), ("bundle (k1k2)", "k1k2")):
            b = bundle(cs, rest, r.corners.fit.X_H, r.corners.fit.X_F, model)
            sq[name].append(predicted_sq(b, cs, k))
    rms = {n: math.sqrt(float(np.mean(np.concatenate(v)))) for n, v in sq.items()}
    ref = min(rms["bundle (given)"], rms["bundle (k1k2)"])
    e = errors(full.X_hand, cs.X_hand, full.covariance)
    b = bundle(cs, np.arange(K), full.X_hand, full.corners.fit.X_F, "k1k2")
    eb = errors(b.X_H, cs.X_hand, b.covariance)
    print(f"{title}\n  LOO px: ours {rms['ours']:.3f}  bundle given {rms['bundle (given)']:.3f}  "
          f"bundle k1k2 {rms['bundle (k1k2)']:.3f}  ratio {rms['ours'] / ref:.3f}   "
          f"[ours: {full.verdict.status}, {full.corners.model}, error {e[0]:.3f}° / {e[1]:.2f} mm, "
          f"NEES {e[2]:.1f}; bundle k1k2 error {eb[0]:.3f}° / {eb[1]:.2f} mm]", flush=True)
    return rms["ours"] / ref


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--leave-out", type=int, default=0, help="images left out per set, evenly spread (default 0: every one; a few "
                        "are a noisy sample)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--sets", default="", help="comma-separated set numbers (default: all)")
    p.add_argument("--per-axis", action="store_true",
                   help="the per-image pose error's level estimated per axis (the model before "
                        "POOLED_POSE_ERROR), for comparison")
    a = p.parse_args()
    rp.POOLED_POSE_ERROR = not a.per_axis
    chosen = [int(s) for s in a.sets.split(",") if s] or range(len(SETS))
    t = time.perf_counter()
    ratios = [run(*SETS[i], a.seed, a.leave_out) for i in chosen]
    print(f"ratio ours / best plain bundle: max {max(ratios):.3f} (≤ 1.05 wanted) over "
          f"{len(ratios)} sets; {time.perf_counter() - t:.0f} s")


if __name__ == "__main__":
    main()

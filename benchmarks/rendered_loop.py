"""The rendered camera in the closed loop: detector accuracy, cost, and the loop against the
point-feature camera; with ``--consistency``, the calibrator's consistency on rendered images.

    OPENBLAS_NUM_THREADS=1 python benchmarks/rendered_loop.py [--scenario FILE] [--seed N]
    OPENBLAS_NUM_THREADS=1 python benchmarks/rendered_loop.py --consistency [--pixel-sigmas ...]

Default mode: runs ``scenarios/rendered.yaml`` and its point-feature twin (the same scenario with
``camera.model`` = ``PointFeatures()``, its default noise, and ``target.points`` = the board's
feature points, so the servo has the same features and the same desired image) on the same seed,
and prints:

- the detector's accuracy on every rendered frame of the run against the true X_CT (from the
  robot pose sampled when the image was taken): RMS and maximum rotation (deg) and translation
  (mm) errors, the median reprojection RMS (px), and the mean NEES of the errors under the
  detector's own covariance (6 = consistent, below = conservative);
- the median time of ``detect_target`` on 30 of the run's frames (same options as in the loop)
  and the camera's cost per frame in the loop, (wall time rendered − wall time points) / frames;
- for both loops: two-motion and final hand-eye errors of X_EC, final feature error, real-time
  factor.

``--consistency``: on a few variants of the scenario (desired roll about the optical axis, true
X_EC, board yaw), runs the loop with the estimator's noise from the assumed corner noise
(``--pixel-sigmas``, px; the default ``RENDERED_PIXEL_SIGMA`` among them) and with the detector's
covariance, and prints per run and on average: the per-frame NEES of the measurement errors under
the assumed noise, the final hand-eye error, and the final NEES of X_EC under the calibrator's
covariance (error normalized by its standard deviations, 6 degrees of freedom: 6 on average is
consistent, much more is overconfident).
"""

from __future__ import annotations

import argparse
import copy
import statistics
import time
from pathlib import Path

import numpy as np
from pydrake.common.schema import Rotation

from handeye_drake.estimation.se3 import inverse, rotation_from_rpy, rotation_log
from handeye_drake.scenario import (
    RENDERED_PIXEL_SIGMA,
    PointFeatures,
    load_scenario,
    transform_matrix,
)
from handeye_drake.simulation import LOOP_DETECT_OPTIONS, intrinsics_of, run_scenario
from handeye_drake.vision.detection import detect_target
from handeye_drake.vision.targets import pattern_extent

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_SCENARIO = ROOT / "scenarios" / "rendered.yaml"


def _tangent(X_true, X_est):
    return np.concatenate([rotation_log(X_true[:3, :3] @ X_est[:3, :3].T),
                           X_true[:3, 3] - X_est[:3, 3]])


def measurement_errors(result):
    """(K, 6) errors [δθ (rad); δt (m)] of the found X_CT samples against the truth, and the
    indices of those samples (the first log sample, before any trigger, left out)."""
    s = result.scenario
    X_WT = transform_matrix(s.target.X_WT, "target.X_WT")
    X_WB = transform_matrix(s.arm.X_WB, "arm.X_WB")
    rows, errors = [], []
    for k in range(1, len(result.times)):
        if result.detector_found[k] < 0.5:
            continue
        X_CT_true = inverse(X_WB @ result.X_BE_samples[k] @ result.X_EC_true) @ X_WT
        errors.append(_tangent(X_CT_true, result.X_CT_samples[k]))
        rows.append(k)
    return np.array(errors), np.array(rows)


def final_nees(result) -> float:
    """Final X_EC error (rotation deg about E's axes, translation m) normalized by the
    calibrator's standard deviations, squared and summed (diagonal NEES, 6 dof)."""
    z = _tangent(result.X_EC_true, result.X_EC_estimates[-1])
    z[:3] = np.degrees(z[:3])
    z /= result.X_EC_std[-1]
    return float(z @ z)


def points_twin(scenario):
    twin = copy.deepcopy(scenario)
    twin.target.points = scenario.camera.model.feature_points_T().tolist()
    twin.camera.model = PointFeatures()
    return twin.validate()


def row(name, r) -> str:
    q = r.summary()
    return (f"| {name} | {q['two_motion_rotation_error_deg']:.3f} / "
            f"{100 * q['two_motion_translation_error_rel']:.2f} | "
            f"{q['final_rotation_error_deg']:.4f} / {100 * q['final_translation_error_rel']:.3f} | "
            f"{q['final_feature_error_px']:.3f} | {q['filter_updates']} | "
            f"{q['real_time_factor']:.2f} ({q['wall_time_s']:.1f} s) |")


def compare(path, seed: int) -> None:
    scenario = load_scenario(path)
    scenario.seed = seed
    # Keep 30 frames spread over the run to time the detector on.
    scenario.camera.model.frames_to_save = list(np.linspace(0.0, scenario.duration - 0.1, 30))
    rendered = run_scenario(scenario)
    points = run_scenario(points_twin(scenario))

    E, rows = measurement_errors(rendered)
    rot = np.degrees(np.linalg.norm(E[:, :3], axis=1))
    trans = 1e3 * np.linalg.norm(E[:, 3:], axis=1)
    nees = [e @ np.linalg.solve(rendered.detector_covariance[k], e) for e, k in zip(E, rows)]
    found = rendered.detector_found > 0.5
    print(f"scenario {path} (seed {seed}), {len(rendered.times) - 1} frames, board found in "
          f"{int(found[1:].sum())}")
    print(f"detector vs truth over {len(E)} frames: rotation RMS {np.sqrt(np.mean(rot**2)):.4f}°"
          f" (max {rot.max():.4f}°), translation RMS {np.sqrt(np.mean(trans**2)):.4f} mm (max "
          f"{trans.max():.4f} mm) at {np.min(rendered.X_CT_samples[rows, 2, 3]):.3f}–"
          f"{np.max(rendered.X_CT_samples[rows, 2, 3]):.3f} m; reprojection RMS median "
          f"{np.median(rendered.reprojection_rms_px[found]):.4f} px; mean NEES under the "
          f"detector's covariance {np.mean(nees):.2f} (6 = consistent)")
    times = []
    for frame in rendered.frames:
        for _ in range(3):
            start = time.perf_counter()
            detect_target(frame.image, scenario.camera.model.parsed_target(),
                          intrinsics_of(scenario), **LOOP_DETECT_OPTIONS)
            times.append(time.perf_counter() - start)
    camera_cost = (rendered.wall_time - points.wall_time) / len(rendered.times)
    print(f"detect_target: median {1e3 * statistics.median(times):.1f} ms per frame "
          f"({len(rendered.frames)} frames × 3); camera cost in the loop (render + detect + recorder): "
          f"{1e3 * camera_cost:.1f} ms per frame")
    print()
    print("| camera | two-motion rot (deg) / trans (%) | final rot (deg) / trans (%) | final "
          "feature error (px) | updates | real-time factor (wall) |")
    print("|---|---|---|---|---|---|")
    print(row("rendered", rendered))
    print(row("points (twin)", points))


def variants(path):
    """A few variants of the scenario: desired roll, true X_EC, board yaw (about its centre)."""
    base = load_scenario(path)
    base.camera.model.frames_to_save = []
    x0, y0, x1, y1 = pattern_extent(base.camera.model.parsed_target())
    centre_T = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0])
    X_WT = transform_matrix(base.target.X_WT, "target.X_WT")
    centre_W = X_WT[:3, :3] @ centre_T + X_WT[:3, 3]
    out = []
    for roll, xec_rpy, yaw in ((25, [4, -3, 92], 20), (-20, [4, -3, 92], 20),
                               (35, [-3, 5, 88], 20), (15, [2, 2, 95], 10),
                               (30, [-5, -4, 90], 30)):
        s = copy.deepcopy(base)
        s.servo.X_TC_desired.rotation = Rotation.Rpy(deg=[0, 0, roll])
        s.camera.sensor.X_PB.rotation = Rotation.Rpy(deg=xec_rpy)
        s.target.X_WT.rotation = Rotation.Rpy(deg=[180, 0, yaw])
        s.target.X_WT.translation = centre_W - rotation_from_rpy(
            np.radians([180, 0, yaw])) @ centre_T
        out.append((f"roll {roll}°, X_EC rpy {xec_rpy}, yaw {yaw}°", s.validate()))
    return out


def consistency(path, pixel_sigmas) -> None:
    print("| run | noise | per-frame NEES (mean) | final rot (deg) / trans (%) | final NEES |")
    print("|---|---|---|---|---|")
    summary = {}
    for name, s in variants(path):
        settings = [(f"σ = {p:g} px", p) for p in pixel_sigmas] + [("detector covariance",
                                                                      None)]
        for label, p in settings:
            t = copy.deepcopy(s)
            if p is None:
                t.camera.model.use_detector_covariance = True
                rotation_sigma, translation_sigma = t.rendered_pose_sigmas()
            else:
                rotation_sigma, translation_sigma = (
                    v * p / RENDERED_PIXEL_SIGMA for v in t.rendered_pose_sigmas())
                t.calibrator.estimator.rotation_sigma = rotation_sigma
                t.calibrator.estimator.translation_sigma = translation_sigma
            r = run_scenario(t)
            E, rows = measurement_errors(r)
            if p is None:
                nees = [e @ np.linalg.solve(r.detector_covariance[k], e) for e, k in zip(E, rows)]
            else:
                R = np.diag([rotation_sigma**2] * 3 + [translation_sigma**2] * 3)
                nees = [e @ np.linalg.solve(R, e) for e in E]
            q = r.summary()
            fn = final_nees(r)
            summary.setdefault(label, []).append((np.mean(nees), q["final_rotation_error_deg"],
                                                  100 * q["final_translation_error_rel"], fn))
            print(f"| {name} | {label} | {np.mean(nees):.2f} | "
                  f"{q['final_rotation_error_deg']:.4f} / "
                  f"{100 * q['final_translation_error_rel']:.3f} | {fn:.2f} |", flush=True)
    print()
    print("| noise | per-frame NEES (mean) | final rot (deg) / trans (%) (mean) | final NEES "
          "(mean, 6 = consistent) |")
    print("|---|---|---|---|")
    for label, values in summary.items():
        v = np.mean(values, axis=0)
        print(f"| {label} | {v[0]:.2f} | {v[1]:.4f} / {v[2]:.3f} | {v[3]:.2f} |")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default=str(DEFAULT_SCENARIO))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--consistency", action="store_true")
    parser.add_argument("--pixel-sigmas", type=float, nargs="+",
                        default=[0.05, RENDERED_PIXEL_SIGMA])
    args = parser.parse_args()
    if args.consistency:
        consistency(args.scenario, args.pixel_sigmas)
    else:
        compare(args.scenario, args.seed)

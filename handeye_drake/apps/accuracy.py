"""``handeye-drake benchmark accuracy``: every estimator on the same data, against the ML limit.

    handeye-drake benchmark accuracy [--json FILE] [--runs N] [--closed-loop-runs N] [--seed S]
                                     [--workers W] [--noise-levels σ ...] [--settings ...]

Settings (each run draws its data once; every method sees exactly that data):

1. ``paper-σ`` — docs/method.md §8's small motions: robot motions B with roll-pitch-yaw ~ N(0, (2π/100)²)
   and translation ~ N(0, 1) per coordinate; true X = X_CE with roll-pitch-yaw uniform in
   [0, 2π) and translation coordinates ~ N(0, 100²); 100 motions; the camera measures the motion
   A with the paper's noise: N(0, σ²) on each coefficient of R_A (σ ∈ ``--noise-levels``) and
   N(0, 0.1²) on t_A. Errors of X_CE (the paper's X).
2. ``paper-σ+outliers`` — the same runs (identical inlier data) with 5 % of the camera poses
   replaced by wrong poses (uniformly random rotation, the position of another sample): each
   wrong pose corrupts the two motions that use it.
3. ``closed-loop`` — the Drake diagram (``run_scenario(load_scenario())``, seeds S, S+1, …):
   robot poses X_BE and camera-measured target poses X_CT (so3 noise, 0.002 rad / 0.5 mm)
   sampled at the camera rate during the two self-calibration rotations and the servo motion.
   Errors of X_EC (the camera on the hand, what the diagram reports).
4. ``large-motions`` — 20 synthetic poses of a camera viewing a target from 0.5 m with rotations
   of about 30° (rotation vector ~ N(0, 0.3² I) rad around a nominal view), same camera noise.
   Errors of X_EC.

Methods (the ``--json`` names):

- ``paper_kf``: docs/method.md §4–§5's linear Kalman filter (``HandEyeKalmanFilter``, diagonal G2 tuned to
  the true noise), initialized with Daniilidis on the first two motions, P0 = I12 as the paper.
- ``manifold``: ``ManifoldHandEyeFilter`` with the same two-motion initialization (noise model
  "paper" in settings 1–2, P0 = diag(1 rad², 100²), the prior spread of X; NIS gate 0.999).
- ``manifold_ml_start`` (ours, settings 1–2): ``ManifoldHandEyeFilter`` seeded by
  ``ml.robust_initial_estimate`` on the first 10 motions (X and its covariance as P0; motions
  whose rotation angles disagree or whose residuals fail a χ² test are dropped), then fed the
  following motions one at a time through its NIS gate. On-line after a 10-motion start-up
  batch. Why not the two-motion start: with σ ≥ 0.05 two motions of ~6° are mostly noise, the
  start is tens of degrees off, and an EKF linearized there becomes inconsistent.
- ``target`` (ours, settings 3–4): ``HandEyeTargetFilter`` (AX = ZB on the raw poses) replayed
  offline on the samples, initialized as the diagram's calibrator (Daniilidis on the key frames,
  the scenario's P0). ``diagram_default`` is the estimate the diagram itself produced (the same
  filter, in the loop). ``manifold`` and ``paper_kf`` there run on consecutive-sample motions
  with the motion noise implied by the pose noise (``motion_noise_from_pose_noise``); at 30 Hz
  these motions are a fraction of a degree, mostly noise, so they learn little.
- ``opencv_<method>``: ``cv2.calibrateHandEye`` with each of its five methods on the pose
  sequences (settings 1–2: X_BE_k = X_BE_{k−1} B_k, X_CT_k = A_k⁻¹ X_CT_{k−1}, which reproduces
  the motions A_k, rotation blocks projected on SO(3)). OpenCV forms a motion from every pair of
  poses. Skipped with a message when cv2 or calibrateHandEye is absent.
- ``park_consecutive``, ``daniilidis_consecutive``: this package's classical solvers on the
  consecutive motions only (context for OpenCV's all-pairs formulation).
- ``ml``: the maximum-likelihood reference (``ml.refine_ml`` / ``ml.refine_ml_poses`` under the
  model the data was generated with; the lowest-cost of local refinements started from a
  classical solution and from the truth — the truth only helps find the global minimum, so this
  is a reference, not a deployable method). With outliers: ``ml_inliers``, the ML of the
  uncorrupted motions only (an oracle).

Runs are seeded (``numpy.random.SeedSequence`` of the seed, the setting and the run index), so
the output does not depend on ``--workers``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from ..estimation.configs import ManifoldFilter, PaperFilter, TargetFilter
from ..estimation.defaults import (
    CAMERA_ROTATION_SIGMA,
    CAMERA_TRANSLATION_SIGMA,
    ROTATION_TOLERANCE,
)
from ..estimation.errors import rotation_error_deg, translation_error_rel
from ..estimation.kalman import HandEyeKalmanFilter
from ..estimation.manifold import HandEyeTargetFilter, ManifoldHandEyeFilter
from ..estimation.ml import refine_ml, refine_ml_poses
from ..estimation.orthonormalize import orthonormalize_unchecked
from ..estimation.se3 import inverse, make_transform
from ..estimation.solvers import solve_ax_xb
from ..estimation.startup import two_motion_estimate
from ..estimation.synthetic import chain_poses, inject_wrong_poses, orbit_poses, paper_motions
from ..estimation.validation import rotation_defect
from .executors import add_executor_arguments, make_executor
from .outputs import check_output_file

PAPER_NOISE_LEVELS = (0.01, 0.05, 0.1)
PAPER_TRANSLATION_SIGMA = 0.1
PAPER_NUM_MOTIONS = 100
OUTLIER_FRACTION = 0.05
START_UP_MOTIONS = 10
LARGE_NUM_POSES = 20
LARGE_ROTATION_STD = 0.3  # rad per axis of the viewing rotation: ~30° rotations
OPENCV_METHODS = ("tsai", "park", "horaud", "andreff", "daniilidis")
SETTINGS = ("paper", "outliers", "closed_loop", "large")

#: The methods the targets are checked on.
OURS_MOTIONS = "manifold_ml_start"
OURS_POSES = "target"


# ---------------------------------------------------------------------------------------------
# OpenCV.

def opencv_unavailable_reason() -> str | None:
    """None when ``cv2.calibrateHandEye`` can be used, else why not."""
    try:
        import cv2
    except ImportError as e:
        return f"OpenCV (cv2) is not installed ({e}); pip install 'opencv-python-headless<5'"
    if not hasattr(cv2, "calibrateHandEye"):
        return f"cv2 {cv2.__version__} has no calibrateHandEye (OpenCV 4.x needed)"
    return None


def opencv_calibrate(X_BE_list, X_CT_list) -> dict:
    """X_EC from ``cv2.calibrateHandEye`` for each of its five methods (all pose pairs).

    Its gripper→base poses are X_BE, target→camera poses X_CT, and its cam2gripper output is
    X_EC. A method that raises (cv2.error) maps to None.
    """
    import cv2
    R_g = [np.ascontiguousarray(X[:3, :3]) for X in X_BE_list]
    t_g = [np.ascontiguousarray(X[:3, 3]) for X in X_BE_list]
    R_t = [np.ascontiguousarray(X[:3, :3]) for X in X_CT_list]
    t_t = [np.ascontiguousarray(X[:3, 3]) for X in X_CT_list]
    out = {}
    for name in OPENCV_METHODS:
        flag = getattr(cv2, f"CALIB_HAND_EYE_{name.upper()}")
        try:
            R, t = cv2.calibrateHandEye(R_g, t_g, R_t, t_t, method=flag)
            X_EC = make_transform(np.asarray(R, dtype=float), np.asarray(t, dtype=float).ravel())
            out[f"opencv_{name}"] = X_EC if np.all(np.isfinite(X_EC)) else None
        except cv2.error:
            out[f"opencv_{name}"] = None
    return out


# ---------------------------------------------------------------------------------------------
# Data.

def motion_noise_from_pose_noise(X_CT_list, rotation_sigma: float, translation_sigma: float):
    """Per-axis noise (σ_r rad, σ_t) of a motion A = X_CT_{k−1} X_CT_k⁻¹ differenced from two poses
    with so3 noise (σ_r, σ_t): R_A's rotation-vector error n_{k−1} − R_A n_k (variance 2σ_r²);
    t_A's error e_{k−1} − R_A e_k − [n_{k−1}]× R_A t_k + R_A [n_k]× t_k (variance ≈ 2σ_t² +
    (4/3) σ_r² ‖t_CT‖², using the median distance). Consecutive motions share a pose, so their
    noises are correlated; the motion filters ignore that."""
    d = float(np.median([np.linalg.norm(X[:3, 3]) for X in X_CT_list]))
    return (np.sqrt(2.0) * rotation_sigma,
            float(np.sqrt(2.0 * translation_sigma**2 + 4.0 / 3.0 * rotation_sigma**2 * d**2)))


# ---------------------------------------------------------------------------------------------
# Estimators run on a data set.

def _run_filter(f, pairs):
    for a, b in pairs:
        f.update_motion(a, b)
    return f


def _run_poses(f, X_BE, X_CT):
    for X_be, X_ct in zip(X_BE, X_CT):
        f.update(X_be, X_ct)
    return f


def _ml_reference(fit, starts):
    """Lowest-cost ML refinement over several starts (failures skipped)."""
    best = None
    for X0 in starts:
        if X0 is None:
            continue
        try:
            r = fit(X0)
        except ValueError:
            continue
        if best is None or r.cost < best.cost - 1e-9 * max(1.0, best.cost):
            best = r
    return best


def _safe(fn):
    try:
        return fn()
    except ValueError:
        return None


def _errors(X_true, estimates: dict) -> dict:
    """{method: [rotation error (deg), relative translation error]} (None: the method failed:
    it raised, or returned a non-finite or non-rigid result, e.g. a reflection)."""
    out = {}
    for name, X in estimates.items():
        if (X is None or not np.all(np.isfinite(X))
                or rotation_defect(np.asarray(X)[:3, :3]) > ROTATION_TOLERANCE):
            out[name] = None
        else:
            out[name] = [rotation_error_deg(X_true, X), translation_error_rel(X_true, X)]
    return out


def _paper_task(task) -> dict:
    """One run of settings 1 and 2 (same inlier data)."""
    entropy, sigma, num_motions, with_outliers, use_cv = task
    rng = np.random.default_rng(np.random.SeedSequence(entropy))
    st = PAPER_TRANSLATION_SIGMA
    X_CE, A, B = paper_motions(rng, sigma, st, num_motions)
    A_rigid = [make_transform(orthonormalize_unchecked(a[:3, :3], "svd"), a[:3, 3]) for a in A]
    out_rng = np.random.default_rng(np.random.SeedSequence(list(entropy) + [7]))
    # The paper's coefficient noise σ: its rotation-vector part has σ/√2 per axis.
    manifold_config = ManifoldFilter(rotation_sigma=sigma / np.sqrt(2.0), translation_sigma=st,
                                     initial_variances=[1.0] * 3 + [100.0**2] * 3)

    def estimators(A_used, B_used, poses, clean_mask):
        est, info = {}, {}
        # The paper's start: Daniilidis on the first two motions (projected on SO(3)).
        X0 = _safe(lambda: solve_ax_xb(A_used[:2], B_used[:2], "daniilidis",
                                       orthonormalize_inputs=True))
        if X0 is not None:
            est["paper_kf"] = _safe(lambda: _run_filter(HandEyeKalmanFilter(
                PaperFilter(rotation_coefficient_sigma=sigma, translation_sigma=st,
                            initial_variances=[1.0] * 12), X0),
                zip(A_used[2:], B_used[2:])).X_CE)
            mf = _safe(lambda: _run_filter(ManifoldHandEyeFilter(
                manifold_config, X0), zip(A_used[2:], B_used[2:])))
            est["manifold"] = None if mf is None else mf.X_CE
        n = START_UP_MOTIONS
        ours = _safe(lambda: _run_filter(ManifoldHandEyeFilter.from_motions(
            manifold_config, A_used[:n], B_used[:n], coefficient_noise=True),
            zip(A_used[n:], B_used[n:])))
        est[OURS_MOTIONS] = None if ours is None else ours.X_CE
        if ours is not None:
            start = ours.start_up
            bad = ~clean_mask
            info["start_up_dropped_corrupted"] = int(np.sum(bad[:n] & ~start.inliers))
            info["start_up_dropped_clean"] = int(np.sum(~bad[:n] & ~start.inliers))
            info["corrupted_motions_after_start"] = int(np.sum(bad[n:]))
            info["rejected"] = ours.num_rejected
        if use_cv:
            est.update({k: None if v is None else inverse(v)
                        for k, v in opencv_calibrate(*poses).items()})
        return est, info

    # Setting 1: clean.
    poses = chain_poses(A_rigid, B)
    clean = np.ones(len(A), dtype=bool)
    est, info = estimators(A, B, poses, clean)
    est["park_consecutive"] = _safe(lambda: solve_ax_xb(A_rigid, B, "park"))
    est["daniilidis_consecutive"] = _safe(lambda: solve_ax_xb(A_rigid, B, "daniilidis"))

    def fit(X):
        return refine_ml(A, B, X, sigma, st, "paper")
    ref = _ml_reference(fit, [est["park_consecutive"], X_CE])
    est["ml"] = None if ref is None else ref.X_CE
    result = {"clean": _errors(X_CE, est), "clean_info": info}
    if not with_outliers:
        return result

    # Setting 2: 5 % wrong camera poses; motions that touch one are recomputed from the poses.
    X_BE, X_CT = poses
    X_CT_bad, idx = inject_wrong_poses(X_CT, OUTLIER_FRACTION, out_rng)
    bad = np.zeros(len(A), dtype=bool)
    for i in idx:
        bad[max(i - 1, 0)] = True  # motion i−1 goes from pose i−1 to pose i
        if i < len(A):
            bad[i] = True
    A_bad = [X_CT_bad[k] @ inverse(X_CT_bad[k + 1]) if bad[k] else A[k] for k in range(len(A))]
    est, info = estimators(A_bad, B, (X_BE, X_CT_bad), ~bad)
    good = np.flatnonzero(~bad)

    def fit_inliers(X):
        return refine_ml([A[k] for k in good], [B[k] for k in good], X, sigma, st, "paper")
    ref = _ml_reference(fit_inliers, [_safe(lambda: solve_ax_xb(
        [A_rigid[k] for k in good], [B[k] for k in good], "park")), X_CE])
    est["ml_inliers"] = None if ref is None else ref.X_CE
    info["corrupted_motions"] = int(bad.sum())
    result["outliers"] = _errors(X_CE, est)
    result["outliers_info"] = info
    return result


def _pose_filters(X_BE, X_CT, X_CE0, P0, rotation_sigma, translation_sigma, gate):
    """Our filters and the paper's replayed offline on synchronized poses (closed loop / large)."""
    est = {}
    P0 = list(np.diag(P0))
    target = _safe(lambda: _run_poses(HandEyeTargetFilter(TargetFilter(
        rotation_sigma=rotation_sigma, translation_sigma=translation_sigma,
        initial_variances=P0, gate_probability=gate), X_CE0), X_BE, X_CT))
    est[OURS_POSES] = None if target is None else target.X_EC
    sr_A, st_A = motion_noise_from_pose_noise(X_CT, rotation_sigma, translation_sigma)
    mf = _safe(lambda: _run_poses(ManifoldHandEyeFilter(ManifoldFilter(
        rotation_sigma=sr_A, translation_sigma=st_A, initial_variances=P0,
        gate_probability=gate), X_CE0), X_BE, X_CT))
    est["manifold"] = None if mf is None else mf.X_EC
    # The paper's filter models coefficient noise: σ_c²/2 = σ_r² per rotation-vector axis.
    kf = _safe(lambda: _run_poses(HandEyeKalmanFilter(PaperFilter(
        rotation_coefficient_sigma=np.sqrt(2.0) * sr_A, translation_sigma=st_A), X_CE0),
        X_BE, X_CT))
    est["paper_kf"] = None if kf is None else kf.X_EC
    return est


def _closed_loop_task(task) -> dict:
    seed, use_cv = task
    from ..scenario import load_scenario
    from ..simulation import run_scenario

    scenario = load_scenario()
    scenario.seed = int(seed)
    result = run_scenario(scenario)
    valid = [k for k in range(len(result.X_BE_samples))
             if rotation_defect(result.X_BE_samples[k][:3, :3]) < ROTATION_TOLERANCE]
    X_BE = [result.X_BE_samples[k] for k in valid]
    X_CT = [result.X_CT_samples[k] for k in valid]
    phase = result.phase[valid]
    keys = [0] + [int(np.argmax(phase >= m)) for m in range(1, 3)]
    X_CE0 = two_motion_estimate([X_BE[i] for i in keys], [X_CT[i] for i in keys],
                                scenario.calibrator.init_method)
    noise = scenario.camera.model.pose_noise
    config = scenario.estimator_config()
    est = {"diagram_default": result.X_EC_estimates[-1]}
    est.update(_pose_filters(X_BE, X_CT, X_CE0, np.diag(config.initial_variances),
                             noise.rotation_sigma, noise.translation_sigma,
                             config.gate_probability))
    if use_cv:
        est.update(opencv_calibrate(X_BE, X_CT))
    X_CE_true = inverse(result.X_EC_true)

    def fit(X):
        return refine_ml_poses(X_BE, X_CT, X, noise.rotation_sigma, noise.translation_sigma,
                               "so3")
    start = None if est[OURS_POSES] is None else inverse(est[OURS_POSES])
    ref = _ml_reference(fit, [start, X_CE0, X_CE_true])
    est["ml"] = None if ref is None else ref.X_EC
    return {"closed_loop": _errors(result.X_EC_true, est),
            "closed_loop_info": {"samples": len(valid), "sim_wall_time_s": result.wall_time}}


def _large_task(task) -> dict:
    entropy, use_cv = task
    rng = np.random.default_rng(np.random.SeedSequence(entropy))
    sr, st = CAMERA_ROTATION_SIGMA, CAMERA_TRANSLATION_SIGMA
    X_EC, X_BE, X_CT = orbit_poses(rng, LARGE_NUM_POSES, LARGE_ROTATION_STD, sr, st)
    X_CE_true = inverse(X_EC)
    X_CE0 = _safe(lambda: solve_ax_xb([X_CT[0] @ inverse(X_CT[1]), X_CT[1] @ inverse(X_CT[2])],
                                      [inverse(X_BE[0]) @ X_BE[1], inverse(X_BE[1]) @ X_BE[2]],
                                      "daniilidis"))
    est = {}
    if X_CE0 is not None:
        P0 = np.diag([np.radians(1.0)**2] * 3 + [0.01**2] * 3)
        est.update(_pose_filters(X_BE, X_CT, X_CE0, P0, sr, st, 0.999))
    if use_cv:
        est.update(opencv_calibrate(X_BE, X_CT))

    def fit(X):
        return refine_ml_poses(X_BE, X_CT, X, sr, st, "so3")
    start = None if est.get(OURS_POSES) is None else inverse(est[OURS_POSES])
    ref = _ml_reference(fit, [start, X_CE0, X_CE_true])
    est["ml"] = None if ref is None else ref.X_EC
    return {"large": _errors(X_EC, est)}


# ---------------------------------------------------------------------------------------------
# Statistics, table, targets.

def summarize(errors: list, reference: str) -> dict:
    """Per-method median / RMS of rotation (deg) and translation (%) errors over runs, and the
    ratio of the medians to the reference method's."""
    methods = []
    for run in errors:
        for name in run:
            if name not in methods:
                methods.append(name)
    stats = {}
    for name in methods:
        vals = np.array([run[name] for run in errors if run.get(name) is not None], dtype=float)
        failures = sum(1 for run in errors if run.get(name) is None)
        if len(vals) == 0:
            stats[name] = {"runs": 0, "failures": failures}
            continue
        rot, tr = vals[:, 0], 100.0 * vals[:, 1]
        stats[name] = {"runs": int(len(vals)), "failures": failures,
                       "rotation_deg": {"median": float(np.median(rot)),
                                        "rms": float(np.sqrt(np.mean(rot**2)))},
                       "translation_pct": {"median": float(np.median(tr)),
                                           "rms": float(np.sqrt(np.mean(tr**2)))}}
    ref = stats.get(reference, {})
    for s in stats.values():
        if "rotation_deg" in s and "rotation_deg" in ref:
            s["ratio_to_ml"] = {
                "rotation": s["rotation_deg"]["median"] / max(ref["rotation_deg"]["median"],
                                                              1e-300),
                "translation": s["translation_pct"]["median"]
                / max(ref["translation_pct"]["median"], 1e-300)}
    return stats


def format_table(title: str, stats: dict) -> str:
    lines = [title,
             f"  {'method':24s} {'runs':>5s}  {'rot med°':>9s} {'rot RMS°':>9s}  "
             f"{'tr med %':>9s} {'tr RMS %':>9s}  {'÷ML rot':>8s} {'÷ML tr':>7s}"]
    for name, s in stats.items():
        if "rotation_deg" not in s:
            lines.append(f"  {name:24s} {0:5d}  (failed in all {s['failures']} runs)")
            continue
        ratio = s.get("ratio_to_ml", {})
        fails = f"  ({s['failures']} failed)" if s["failures"] else ""
        lines.append(
            f"  {name:24s} {s['runs']:5d}  {s['rotation_deg']['median']:9.4f} "
            f"{s['rotation_deg']['rms']:9.4f}  {s['translation_pct']['median']:9.4f} "
            f"{s['translation_pct']['rms']:9.4f}  {ratio.get('rotation', np.nan):8.2f} "
            f"{ratio.get('translation', np.nan):7.2f}{fails}")
    return "\n".join(lines)


def check_targets(settings: dict) -> list:
    """The issue's targets, evaluated on the small-motion settings (see the module docstring)."""
    checks = []
    for key, setting in settings.items():
        if not key.startswith("paper-") or key.endswith("+outliers"):
            continue
        stats = setting["methods"]
        ours = stats.get(OURS_MOTIONS, {})
        if "rotation_deg" not in ours:
            continue
        cv = {k: v for k, v in stats.items() if k.startswith("opencv_") and "rotation_deg" in v}
        for q, unit in (("rotation_deg", "°"), ("translation_pct", "%")):
            o = ours[q]["median"]
            if cv:
                best = min(cv, key=lambda k: cv[k][q]["median"])
                b = cv[best][q]["median"]
                checks.append({"setting": key, "target": f"{q}: ours ≤ best OpenCV",
                               "ours": o, "other": b, "other_method": best, "met": o <= b})
            ml = stats.get("ml", {})
            if q in ml:
                m = ml[q]["median"]
                checks.append({"setting": key, "target": f"{q}: ours ≤ 1.25 × ML",
                               "ours": o, "other": m, "ratio": o / m, "met": o <= 1.25 * m})
            out = settings.get(key + "+outliers", {}).get("methods", {}).get(OURS_MOTIONS, {})
            if q in out:
                w = out[q]["median"]
                checks.append({"setting": key + "+outliers",
                               "target": f"{q}: growth with 5 % wrong poses < 20 %",
                               "ours": w, "other": o, "ratio": w / o, "met": w < 1.2 * o})
    return checks


def _format_check(c) -> str:
    mark = "MET" if c["met"] else "NOT MET"
    if "ratio" in c:
        detail = f"{c['ours']:.4g} vs {c['other']:.4g} (ratio {c['ratio']:.3f})"
    else:
        detail = f"{c['ours']:.4g} vs {c['other']:.4g} ({c['other_method']})"
    return f"  [{mark:7s}] {c['setting']:22s} {c['target']:42s} {detail}"


# ---------------------------------------------------------------------------------------------
# Driver.

def run_accuracy_benchmark(runs: int = 20, closed_loop_runs: int = 4, seed: int = 0,
                           workers: int = 2, noise_levels=PAPER_NOISE_LEVELS,
                           settings=SETTINGS, num_motions: int = PAPER_NUM_MOTIONS,
                           log=print, executor=None, executor_name: str = "") -> dict:
    """Runs the benchmark and returns the JSON-able report (see the module docstring)."""
    for name, v in (("runs", runs), ("closed_loop_runs", closed_loop_runs),
                    ("workers", workers)):
        if int(v) != v or v < (1 if name == "workers" else 0):
            raise ValueError(f"{name}: needs a non-negative integer (workers ≥ 1), got {v!r}")
    if int(num_motions) != num_motions or num_motions < START_UP_MOTIONS + 2:
        raise ValueError(f"num_motions: needs an integer ≥ {START_UP_MOTIONS + 2}, got "
                         f"{num_motions!r}")
    unknown = [s for s in settings if s not in SETTINGS]
    if unknown:
        raise ValueError(f"settings: unknown {unknown}, expected a subset of {SETTINGS}")
    levels = [float(s) for s in noise_levels]
    if not all(np.isfinite(s) and s > 0 for s in levels):
        raise ValueError(f"noise_levels: need positive finite sigmas, got {noise_levels!r}")
    reason = opencv_unavailable_reason()
    use_cv = reason is None
    if not use_cv:
        log(f"OpenCV methods skipped: {reason}")

    tasks = []  # (kind, key, function, argument)
    if "closed_loop" in settings:
        tasks += [("closed_loop", None, _closed_loop_task, (seed + i, use_cv))
                  for i in range(closed_loop_runs)]
    if "paper" in settings or "outliers" in settings:
        for li, sigma in enumerate(levels):
            tasks += [("paper", sigma, _paper_task,
                       ((seed, 1, li, r), sigma, num_motions, "outliers" in settings, use_cv))
                      for r in range(runs)]
    if "large" in settings:
        tasks += [("large", None, _large_task, ((seed, 4, r), use_cv)) for r in range(runs)]

    start = time.perf_counter()
    if executor is not None:  # any concurrent.futures.Executor (e.g. Dask's)
        futures = [executor.submit(fn, arg) for _, _, fn, arg in tasks]
        outputs = [f.result() for f in futures]
    elif workers > 1 and len(tasks) > 1:
        with ProcessPoolExecutor(max_workers=int(workers)) as pool:
            futures = [pool.submit(fn, arg) for _, _, fn, arg in tasks]
            outputs = [f.result() for f in futures]
    else:
        outputs = [fn(arg) for _, _, fn, arg in tasks]
    wall = time.perf_counter() - start

    collected: dict[str, dict] = {}

    def add(key, description, frame, errors, info=None):
        entry = collected.setdefault(key, {"description": description, "error_of": frame,
                                           "errors": [], "info": []})
        entry["errors"].append(errors)
        if info is not None:
            entry["info"].append(info)

    for (kind, sigma, _, _), out in zip(tasks, outputs):
        if kind == "paper":
            if "paper" in settings:
                add(f"paper-{sigma:g}", f"docs/method.md §8 small motions, {num_motions} motions, paper "
                    f"noise σ_R = {sigma:g} (coefficients), σ_t = {PAPER_TRANSLATION_SIGMA:g}",
                    "X_CE", out["clean"], out["clean_info"])
            if "outliers" in out:
                add(f"paper-{sigma:g}+outliers", f"the same runs with "
                    f"{100 * OUTLIER_FRACTION:g} % of the camera poses replaced by wrong poses",
                    "X_CE", out["outliers"], out["outliers_info"])
        elif kind == "closed_loop":
            add("closed-loop", "Drake closed loop (default scenario; self-calibration + IBVS), "
                "camera so3 noise 0.002 rad / 0.5 mm", "X_EC", out["closed_loop"],
                out["closed_loop_info"])
        else:
            add("large-motions", f"{LARGE_NUM_POSES} poses, ~30° rotations, camera so3 noise "
                "0.002 rad / 0.5 mm", "X_EC", out["large"])

    report = {"seed": seed, "runs": runs, "closed_loop_runs": closed_loop_runs,
              "workers": workers, "executor": executor_name or (
                  f"{workers} local worker processes" if workers > 1 else "serial"),
              "noise_levels": levels, "opencv": reason or "used",
              "settings": {}}
    for key, entry in collected.items():
        reference = "ml_inliers" if key.endswith("+outliers") else "ml"
        stats = summarize(entry["errors"], reference)
        setting = {"description": entry["description"], "error_of": entry["error_of"],
                   "reference": reference, "runs": len(entry["errors"]), "methods": stats}
        if entry["info"]:
            keys = sorted({k for i in entry["info"] for k in i})
            setting["info_mean"] = {k: float(np.mean([i[k] for i in entry["info"] if k in i]))
                                    for k in keys}
        report["settings"][key] = setting
    report["targets"] = check_targets(report["settings"])
    report["wall_time_s"] = wall
    return report


def format_report(report: dict) -> str:
    parts = []
    for key, s in report["settings"].items():
        title = (f"[{key}] {s['description']}; errors of {s['error_of']} over {s['runs']} runs; "
                 f"÷ML = median / {s['reference']}'s median")
        parts.append(format_table(title, s["methods"]))
        if "info_mean" in s:
            parts.append("  mean per run: " + ", ".join(f"{k} {v:.2f}"
                                                       for k, v in s["info_mean"].items()))
    if report["targets"]:
        parts.append(f"Targets (ours = {OURS_MOTIONS}, medians):")
        parts += [_format_check(c) for c in report["targets"]]
    parts.append(f"wall time {report['wall_time_s']:.1f} s "
                 f"({report.get('executor', str(report['workers']) + ' workers')})")
    return "\n".join(parts)


def _accuracy(args) -> int:
    json_path = check_output_file(args.json, "--json", args.force) if args.json else None
    # Dask when asked (--scheduler / --dask-local); else the benchmark's own process pool.
    with make_executor(1, args.scheduler, args.dask_local) as (executor, where):
        report = run_accuracy_benchmark(
            runs=args.runs, closed_loop_runs=args.closed_loop_runs, seed=args.seed,
            workers=args.workers, noise_levels=args.noise_levels, settings=args.settings,
            num_motions=args.motions, executor=executor,
            executor_name=where if executor is not None else "")
    report["command"] = " ".join(["handeye-drake"] + sys.argv[1:])
    print(format_report(report))
    if json_path is not None:
        json_path.write_text(json.dumps(report, indent=2) + "\n")
        print(f"wrote {json_path}")
    return 0


def add_parser(benchmark_subparsers) -> argparse.ArgumentParser:
    """Adds ``accuracy`` to the ``benchmark`` command's sub-parsers (the CLI's)."""
    acc = benchmark_subparsers.add_parser(
        "accuracy", help="every estimator (paper's filter, ours, OpenCV's five, ML reference) "
        "on the same data: small motions (docs/method.md §8), with outliers, the closed loop, large "
        "motions", description="Runs the paper's filter, our filters, OpenCV's five methods and "
        "the maximum-likelihood reference on the same seeded data and prints median / RMS "
        "errors and their ratio to the ML reference, then checks the accuracy targets.")
    acc.add_argument("--json", metavar="FILE", help="also write the results to this JSON file "
                     "(checked before the run; an existing file needs --force)")
    acc.add_argument("--force", action="store_true", help="overwrite an existing --json file")
    acc.add_argument("--runs", type=int, default=20, metavar="N",
                     help="random runs per noise level and for the large-motion setting "
                     "(default 20)")
    acc.add_argument("--closed-loop-runs", type=int, default=4, metavar="N",
                     help="closed-loop simulations (seeds S, S+1, …; default 4)")
    acc.add_argument("--seed", type=int, default=0, metavar="S", help="base seed (default 0)")
    add_executor_arguments(acc)
    acc.add_argument("--noise-levels", type=float, nargs="+", default=list(PAPER_NOISE_LEVELS),
                     help="rotation-coefficient σ of the small-motion settings "
                     "(default 0.01 0.05 0.1)")
    acc.add_argument("--motions", type=int, default=PAPER_NUM_MOTIONS,
                     help="motions per small-motion run (default 100)")
    acc.add_argument("--settings", nargs="+", choices=SETTINGS, default=list(SETTINGS),
                     help="which settings to run (default all)")
    acc.set_defaults(func=_accuracy)
    return acc

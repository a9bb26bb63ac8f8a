"""``handeye-drake benchmark speed``: every cost as a ratio against a reference measured beside it.

    handeye-drake benchmark speed [--repeats N] [--sections ...] [--calibrate-sizes N ...]
                                  [--rendered-duration S]
                                  [--json FILE]

Each figure is a ratio of two timings taken in the same run, interleaved (A, B, B, A, ...), as
the median of ``--repeats`` timings, with BLAS pinned to one thread, so a loaded or slower machine
moves both sides alike; the machine's load average is printed beside the table. The loop
sections also print the ratio of the CPU times of the same runs (this process's CPU time over the
same spans), which other processes sharing the cores distort less than wall time.

Sections (``--sections``):

- ``estimators``: each on-line estimator's ``update(X_BE, X_CT)`` (validated, public) and
  ``_update`` (unchecked: what the Drake calibrator runs) against a straight-line numpy
  implementation of the same update written here (``reference_*``: no validation, no abstraction),
  on the same samples; the reference's estimate, covariance and counters must equal the library's
  to 1e-9 (checked at every run, so the reference is the same computation). Target ≤ 1.5×.
- ``calibrator``: the ``HandEyeCalibrator`` system's cost per sample inside a Drake diagram
  (recorded samples from C++ ``TrajectorySource``s, stepped by a ``Simulator``, its estimate
  logged) against the bare estimator's ``_update`` on the same samples (the final estimates must
  be equal).
- ``loop``: the default closed loop (``run_scenario(load_scenario())``: arm, camera, servo
  commanding a pose, calibrator, Drake's C++ ``DifferentialInverseKinematicsIntegrator``
  tracking the pose, the log) against the same arm plant driven by the same integrator (same
  time step, same joint limits) toward a fixed pose under an end-effector speed limit — a
  constant twist — and nothing else. Target ≤ 1.3×; both real-time factors are printed. The
  same loop with ``arm.driver: !TwistCommand`` (our Python differential-IK driver on the servo's
  twist) is timed beside them, and the reference with as many idle Python ``LeafSystem``s as the
  loop has (no ports, no events: the simulator's cost of a Python system at each of its steps),
  the reference tracking the poses the loop itself commanded (recorded in one run, replayed: the
  loop's own motion, so a harder motion is not what the ratio measures), the loop without its
  log, and the loop's Python callbacks per camera sample (camera, servo, calibrator; each timed
  in one more run) against the time the 1.3× target leaves for all the loop's own work —
  for comparison (no targets).
- ``rendered``: the rendered-camera loop (``run_scenario`` of ``scenarios/rendered.yaml``
  shortened to ``--rendered-duration`` s) against rendering the same frames with the same
  ``RgbdSensor`` at the same arm poses and running ``detect_target`` on them, alone (the
  detections must equal the loop's). Target ≤ 1.3×; per-frame render, detect and rest.
- ``corners``: the corner-level fit of image inputs (``estimation.reprojection``, intrinsics
  k1k2) on 100 and 1000 images × 48 corners against ``cv2.calibrateCamera`` (OpenCV's bundle
  adjustment of per-image poses and shared intrinsics, C++) on the same corners; and its cost
  per image at both sizes (``apps.speed_corners``).
- ``calibrate``: ``handeye-drake calibrate`` (the whole command, in this process) on recordings
  of 10², 10³, 10⁴, 10⁵ camera samples made with ``recorded.example``'s pose model: time per
  pair and the growth exponent of the wall time (log-log fit), beside OpenCV's
  ``calibrateHandEye`` on the same synchronized pairs (skipped where its all-pairs formulation
  would not fit in memory).
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import io
import json
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .outputs import check_output_file

#: Sections in the order they run.
SECTIONS = ("estimators", "calibrator", "loop", "rendered", "calibrate", "corners")
#: Targets of the issue: largest accepted ratio per section.
TARGETS = {"estimators": 1.5, "loop": 1.3, "rendered": 1.3}
CALIBRATE_SIZES = (100, 1000, 10_000, 100_000)
#: Largest all-pairs problem handed to OpenCV (N(N−1)/2 motions; its Tsai stacks 3 rows each).
OPENCV_MAX_PAIRS = 1_000_000


def pin_blas_threads() -> str:
    """One BLAS thread in this process (and its children): timings then measure our code, not
    how many idle cores the machine has."""
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    os.environ["OMP_NUM_THREADS"] = "1"
    from threadpoolctl import threadpool_info, threadpool_limits
    threadpool_limits(1)
    pools = threadpool_info()
    return ", ".join(f"{p['internal_api']} {p['num_threads']} thread(s)" for p in pools) or "none"


def load_average() -> str:
    try:
        return " ".join(f"{v:.2f}" for v in os.getloadavg()) + f" on {os.cpu_count()} CPUs"
    except OSError:
        return "unavailable"


def interleaved(runners: dict, repeats: int) -> dict:
    """Runs each ``runner() -> (seconds, result)`` ``repeats`` times, alternating the order
    (A B, B A, ...) so that drifts of the machine's load hit every side alike; garbage collection
    off while timing. Returns {name: (median seconds, all timings, last result)}."""
    names = list(runners)
    times = {n: [] for n in names}
    results = {}
    for r in range(repeats):
        for n in (names if r % 2 == 0 else names[::-1]):
            gc.collect()
            gc.disable()
            try:
                seconds, results[n] = runners[n]()
            finally:
                gc.enable()
            times[n].append(seconds)
    return {n: (statistics.median(times[n]), times[n], results[n]) for n in names}


# ---------------------------------------------------------------------------------------------
# Data: the pose model of ``recorded.example`` (a camera circling a target), sampled at 30 Hz.

def sample_poses(n: int, rate: float = 30.0, seed: int = 0, rotation_sigma: float = 0.002,
                 translation_sigma: float = 0.0005):
    """(X_BE (n, 4, 4), X_CT (n, 4, 4) with SO(3) noise, X_CE true, X_BT) at ``rate`` Hz."""
    from ..estimation.se3 import inverse, make_transform, rotation_exp
    from ..recorded.example import TRUE_X_EC, X_BT, camera_pose
    rng = np.random.default_rng(seed)
    X_CE = inverse(TRUE_X_EC)
    X_BE, X_CT = [], []
    for k in range(n):
        X_BC = camera_pose(k / rate)
        X_BE.append(X_BC @ X_CE)
        X = inverse(X_BC) @ X_BT
        X_CT.append(make_transform(rotation_exp(rotation_sigma * rng.normal(size=3)) @ X[:3, :3],
                                   X[:3, 3] + translation_sigma * rng.normal(size=3)))
    return np.array(X_BE), np.array(X_CT), X_CE, X_BT


# ---------------------------------------------------------------------------------------------
# Straight-line references: the estimators' updates in plain numpy, no validation, no helpers
# shared with the library (so the comparison measures the library's overhead, and the equality
# check that the two compute the same thing).

def _ref_exp(w):
    x, y, z = w.tolist()
    th2 = x * x + y * y + z * z
    th = math.sqrt(th2)
    if th < 1e-4:
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        a, b = math.sin(th) / th, (1.0 - math.cos(th)) / th2
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + a * K + b * (K @ K)


def _ref_log(R):
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R.tolist()
    c = max(-1.0, min(1.0, 0.5 * (r00 + r11 + r22 - 1.0)))
    th = math.acos(c)
    v = np.array([r21 - r12, r02 - r20, r10 - r01])
    if th < 1e-4:
        return (0.5 + th * th / 12.0) * v
    return (0.5 * th / math.sin(th)) * v  # residuals and motions here are far from π


def _ref_project(M):
    U, _, Vt = np.linalg.svd(M)
    if np.linalg.det(U @ Vt) < 0:
        U[:, 2] = -U[:, 2]
    return U @ Vt


def _ref_skew(v):
    x, y, z = v.tolist()
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def reference_target_filter(X_BE, X_CT, X_CE0, P0, Rn, gate, iterations):
    """AX = ZB error-state EKF (``HandEyeTargetFilter``'s update) written out; returns
    (X_CE, X_BT, P, excitation S, accepted count)."""
    R_CE, t_CE = X_CE0[:3, :3].copy(), X_CE0[:3, 3].copy()
    P = P0.copy()
    I3, I12 = np.eye(3), np.eye(12)
    S_exc = np.zeros((3, 3))
    R_BT = t_BT = R_ref = None
    accepted = 0
    for k in range(len(X_BE)):
        R_BE, t_BE = X_BE[k, :3, :3], X_BE[k, :3, 3]
        R_m, t_m = _ref_project(X_CT[k, :3, :3]), X_CT[k, :3, 3]
        if R_BT is None:  # the first sample places the target
            R_BT = R_BE @ R_CE.T @ R_m
            t_BT = R_BE @ (R_CE.T @ t_m - R_CE.T @ t_CE) + t_BE
            R_ref = R_BE.copy()
            continue
        R_EB = R_BE.T
        t_EB = -R_EB @ t_BE
        R_CE_k, t_CE_k, R_BT_k, t_BT_k = R_CE, t_CE, R_BT, t_BT
        delta = np.zeros(12)
        for it in range(iterations):
            u = R_EB @ t_BT_k + t_EB
            R_CB = R_CE_k @ R_EB
            z = np.concatenate([_ref_log(R_m @ (R_CB @ R_BT_k).T), t_m - (R_CE_k @ u + t_CE_k)])
            H = np.zeros((6, 12))
            H[:3, :3] = I3
            H[:3, 6:9] = R_CB
            H[3:, :3] = -_ref_skew(R_CE_k @ u)
            H[3:, 3:6] = I3
            H[3:, 9:12] = R_CB
            PHt = P @ H.T
            S_inv = np.linalg.inv(H @ PHt + Rn)
            if it == 0:
                nis = z @ S_inv @ z
                if not nis <= gate:
                    raise AssertionError("reference: a gated sample (choose data without)")
            K = PHt @ S_inv
            delta_new = K @ (z + H @ delta)
            step = np.linalg.norm(delta_new - delta)
            delta = delta_new
            R_CE_k, t_CE_k = _ref_exp(delta[:3]) @ R_CE, t_CE + delta[3:6]
            R_BT_k, t_BT_k = _ref_exp(delta[6:9]) @ R_BT, t_BT + delta[9:12]
            if step < 1e-9:
                break
        I_KH = I12 - K @ H
        P = I_KH @ P @ I_KH.T + K @ Rn @ K.T
        P = 0.5 * (P + P.T)
        R_CE, t_CE, R_BT, t_BT = R_CE_k, t_CE_k, R_BT_k, t_BT_k
        phi = _ref_log(R_ref.T @ R_BE)
        S_exc += np.outer(phi, phi)
        accepted += 1
    X_CE = np.eye(4)
    X_CE[:3, :3], X_CE[:3, 3] = R_CE, t_CE
    X_BT = np.eye(4)
    X_BT[:3, :3], X_BT[:3, 3] = R_BT, t_BT
    return X_CE, X_BT, P, S_exc, accepted


def reference_manifold_filter(X_BE, X_CT, X_CE0, P0, Rn, gate, iterations):
    """AX = XB error-state EKF on consecutive motions (``ManifoldHandEyeFilter``'s update);
    returns (X_CE, P, excitation S, accepted count)."""
    R, t = X_CE0[:3, :3].copy(), X_CE0[:3, 3].copy()
    P = P0.copy()
    I3, I6 = np.eye(3), np.eye(6)
    S_exc = np.zeros((3, 3))
    accepted = 0
    for k in range(1, len(X_BE)):
        A = X_CT[k - 1] @ np.linalg.inv(X_CT[k])
        R_Am, t_Am = _ref_project(A[:3, :3]), A[:3, 3]
        R0, p0 = X_BE[k - 1, :3, :3], X_BE[k - 1, :3, 3]
        R_B = R0.T @ X_BE[k, :3, :3]
        t_B = R0.T @ (X_BE[k, :3, 3] - p0)
        R_k, t_k = R, t
        delta = np.zeros(6)
        for it in range(iterations):
            R_A = R_k @ R_B @ R_k.T
            z = np.concatenate([_ref_log(R_Am @ R_A.T), t_Am - (R_k @ t_B + t_k - R_A @ t_k)])
            I_RA = I3 - R_A
            H = np.zeros((6, 6))
            H[:3, :3] = I_RA
            H[3:, :3] = -_ref_skew(R_k @ t_B) + _ref_skew(R_A @ t_k) @ I_RA
            H[3:, 3:] = I_RA
            PHt = P @ H.T
            S_inv = np.linalg.inv(H @ PHt + Rn)
            if it == 0:
                if not z @ S_inv @ z <= gate:
                    raise AssertionError("reference: a gated sample (choose data without)")
            K = PHt @ S_inv
            delta_new = K @ (z + H @ delta)
            step = np.linalg.norm(delta_new - delta)
            delta = delta_new
            R_k, t_k = _ref_exp(delta[:3]) @ R, t + delta[3:]
            if step < 1e-9:
                break
        I_KH = I6 - K @ H
        P = I_KH @ P @ I_KH.T + K @ Rn @ K.T
        P = 0.5 * (P + P.T)
        R, t = R_k, t_k
        phi = _ref_log(R_B)
        S_exc += np.outer(phi, phi)
        accepted += 1
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, t
    return X, P, S_exc, accepted


def reference_paper_filter(X_BE, X_CT, x0, P0, G2, gate):
    """The paper's linear Kalman filter on consecutive motions (``HandEyeKalmanFilter``'s
    update, diagonal G2, no process noise); returns (x, P, excitation S, accepted count)."""
    x, P = x0.copy(), P0.copy()
    I3, I9, I12 = np.eye(3), np.eye(9), np.eye(12)
    S_exc = np.zeros((3, 3))
    accepted = 0
    C = np.zeros((12, 12))
    y = np.zeros(12)
    for k in range(1, len(X_BE)):
        A = X_CT[k - 1] @ np.linalg.inv(X_CT[k])
        R0, p0 = X_BE[k - 1, :3, :3], X_BE[k - 1, :3, 3]
        R_B = R0.T @ X_BE[k, :3, :3]
        t_B = R0.T @ (X_BE[k, :3, 3] - p0)
        C[:9, :9] = I9 - np.kron(A[:3, :3], R_B)
        C[9:, :9] = np.kron(I3, t_B[None, :])
        C[9:, 9:] = I3 - A[:3, :3]
        y[9:] = A[:3, 3]
        PCt = P @ C.T
        S_inv = np.linalg.inv(C @ PCt + G2)
        r = y - C @ x
        if not r @ S_inv @ r <= gate:
            raise AssertionError("reference: a gated sample (choose data without)")
        K = PCt @ S_inv
        x = x + K @ r
        I_KC = I12 - K @ C
        P = I_KC @ P @ I_KC.T + K @ G2 @ K.T
        P = 0.5 * (P + P.T)
        phi = _ref_log(R_B)
        S_exc += np.outer(phi, phi)
        accepted += 1
    return x, P, S_exc, accepted


def _close(name: str, ours, ref, tol: float = 1e-9) -> None:
    ours, ref = np.asarray(ours, dtype=float), np.asarray(ref, dtype=float)
    scale = max(1.0, float(np.abs(ref).max())) if name.startswith("X") else \
        max(float(np.abs(ref).max()), 1e-300)
    err = float(np.abs(ours - ref).max()) / scale
    if not err <= tol:
        raise AssertionError(f"reference and library disagree on {name}: relative difference "
                             f"{err:.3g} > {tol:g}")


def estimator_section(repeats: int, num_samples: int = 300, log=print) -> list[dict]:
    """Library update (public and unchecked) vs the straight-line reference, per estimator."""
    from ..estimation.configs import ManifoldFilter, PaperFilter, TargetFilter
    from ..estimation.kalman import HandEyeKalmanFilter
    from ..estimation.manifold import HandEyeTargetFilter, ManifoldHandEyeFilter, gate_threshold
    from ..estimation.se3 import make_transform, rotation_exp

    X_BE, X_CT, X_CE, _ = sample_poses(num_samples)
    X_BE_list, X_CT_list = list(X_BE), list(X_CT)
    X0 = make_transform(rotation_exp([0.01, -0.008, 0.006]) @ X_CE[:3, :3],
                        X_CE[:3, 3] + [0.003, -0.002, 0.002])
    target = TargetFilter(rotation_sigma=0.002, translation_sigma=0.0005)
    # Motions between 30 Hz samples share the samples' noise: sigmas of two poses' noise.
    manifold = ManifoldFilter(rotation_sigma=0.004, translation_sigma=0.0015)
    paper = PaperFilter(rotation_coefficient_sigma=0.004, translation_sigma=0.0015)
    rows = []

    def library(cls, config, method):
        def run():
            est = cls(config, X0)
            fn = getattr(est, method)
            start = time.perf_counter()
            for a, b in zip(X_BE_list, X_CT_list):
                fn(a, b)
            return time.perf_counter() - start, est
        return run

    def timed(fn, *args):
        def run():
            start = time.perf_counter()
            out = fn(*args)
            return time.perf_counter() - start, out
        return run

    t = target.validated()
    P0_target = np.diag(t.initial_variances + t.target_prior_variances)
    Rn_t = np.diag([t.rotation_sigma**2] * 3 + [t.translation_sigma**2] * 3)
    m = manifold.validated()
    Rn_m = np.diag([m.rotation_sigma**2] * 3 + [m.translation_sigma**2] * 3)
    p = paper.validated()
    G2 = np.diag([p.rotation_coefficient_sigma**2] * 9 + [p.translation_sigma**2] * 3)
    x0 = np.concatenate([X0[:3, :3].reshape(9), X0[:3, 3]])
    cases = [
        ("HandEyeTargetFilter (TargetFilter)", HandEyeTargetFilter, target,
         timed(reference_target_filter, X_BE, X_CT, X0, P0_target, Rn_t,
               gate_threshold(t.gate_probability, 6), t.iterations), num_samples - 1),
        ("ManifoldHandEyeFilter (ManifoldFilter)", ManifoldHandEyeFilter, manifold,
         timed(reference_manifold_filter, X_BE, X_CT, X0, np.diag(m.initial_variances), Rn_m,
               gate_threshold(m.gate_probability, 6), m.iterations), num_samples - 1),
        ("HandEyeKalmanFilter (PaperFilter)", HandEyeKalmanFilter, paper,
         timed(reference_paper_filter, X_BE, X_CT, x0, np.diag(p.initial_variances), G2,
               12 * 1000.0**2), num_samples - 1),
    ]
    for name, cls, config, reference, updates in cases:
        timings = interleaved({"update": library(cls, config, "update"),
                               "_update": library(cls, config, "_update"),
                               "reference": reference}, repeats)
        ref_out = timings["reference"][2]
        for path in ("update", "_update"):
            est = timings[path][2]
            if est.num_updates != updates or est.num_rejected:
                raise AssertionError(f"{name}: {est.num_updates} updates, {est.num_rejected} "
                                     f"rejected (expected {updates}, 0)")
            if cls is HandEyeTargetFilter:
                _close("X_CE", est.X_CE, ref_out[0])
                _close("X_BT", est.X_BT, ref_out[1])
            elif cls is ManifoldHandEyeFilter:
                _close("X_CE", est.X_CE, ref_out[0])
            else:
                _close("x", est.state, ref_out[0])
            _close("P", est.covariance, ref_out[-3])
            _close("excitation", est.excitation.S, ref_out[-2])
            if ref_out[-1] != updates:
                raise AssertionError(f"{name}: reference accepted {ref_out[-1]} of {updates}")
        ref_us = 1e6 * timings["reference"][0] / num_samples
        for path, label in (("update", "update(X_BE, X_CT), validated"),
                            ("_update", "_update (unchecked, the Drake system's)")):
            us = 1e6 * timings[path][0] / num_samples
            rows.append({"section": "estimators", "what": f"{name} {label}",
                         "value_us": us, "reference": "straight-line numpy reference",
                         "reference_us": ref_us, "ratio": us / ref_us,
                         "target": TARGETS["estimators"]})
        log(_format_row(rows[-2]))
        log(_format_row(rows[-1]))
    return rows


def _format_row(row: dict) -> str:
    target = row.get("target")
    mark = "" if target is None else ("  [MET]" if row["ratio"] <= target else "  [NOT MET]")
    bound = "" if target is None else f" (target ≤ {target:g}×)"
    unit = row.get("unit", "µs")
    digits = 3 if unit in ("s", "ms") else 1
    return (f"  {row['what']}: {row['value_us']:.{digits}f} {unit} vs {row['reference']} "
            f"{row['reference_us']:.{digits}f} {unit} → {row['ratio']:.2f}×{bound}{mark}")


# ---------------------------------------------------------------------------------------------
# The calibrator system in a diagram vs the bare estimator.

def calibrator_section(repeats: int, num_samples: int = 300, log=print) -> list[dict]:
    """Per-sample cost of ``HandEyeCalibrator`` stepped by a Simulator (inputs from C++
    ``TrajectorySource``s replaying recorded samples, the X_EC estimate logged) against the bare
    estimator's ``_update`` on the same samples; both must end with the same estimate."""
    from pydrake.systems.analysis import Simulator
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, TrajectorySource
    from pydrake.trajectories import PiecewisePolynomial

    from ..estimation.configs import TargetFilter
    from ..estimation.manifold import HandEyeTargetFilter
    from ..estimation.se3 import make_transform, pose_to_vector, rotation_exp
    from ..systems.calibrator import HandEyeCalibrator

    period = 1.0 / 30.0
    X_BE, X_CT, X_CE, _ = sample_poses(num_samples)
    X0 = make_transform(rotation_exp([0.01, -0.008, 0.006]) @ X_CE[:3, :3],
                        X_CE[:3, 3] + [0.003, -0.002, 0.002])
    config = TargetFilter(rotation_sigma=0.002, translation_sigma=0.0005).validated()
    times = period * np.arange(num_samples + 1)
    vectors = [np.array([pose_to_vector(X) for X in Xs] + [pose_to_vector(Xs[-1])]).T
               for Xs in (X_BE, X_CT)]

    builder = DiagramBuilder()
    calibrator = builder.AddNamedSystem("calibrator", HandEyeCalibrator(
        period=period, X_CE_initial_guess=X0, estimator=config))
    for port, data in zip((calibrator.get_X_BE_input_port(), calibrator.get_X_CT_input_port()),
                          vectors):
        source = builder.AddSystem(TrajectorySource(PiecewisePolynomial.ZeroOrderHold(times,
                                                                                       data)))
        builder.Connect(source.get_output_port(), port)
    phase = builder.AddSystem(ConstantVectorSource([2.0]))
    builder.Connect(phase.get_output_port(), calibrator.get_phase_input_port())
    logger = LogVectorOutput(calibrator.get_X_EC_output_port(), builder, period)
    diagram = builder.Build()
    end = (num_samples - 1) * period + 0.75 * period  # the last update is at (n − ½) periods

    def system():
        simulator = Simulator(diagram)
        context = simulator.get_mutable_context()
        calibrator.SetEstimator(calibrator.GetMyMutableContextFromRoot(context),
                                HandEyeTargetFilter(config, X0))
        start = time.perf_counter()
        simulator.Initialize()
        simulator.AdvanceTo(end)
        seconds = time.perf_counter() - start
        est = calibrator.estimator(calibrator.GetMyContextFromRoot(context))
        return seconds, (est, logger.FindLog(context).num_samples())

    X_BE_list, X_CT_list = list(X_BE), list(X_CT)

    def bare():
        est = HandEyeTargetFilter(config, X0)
        start = time.perf_counter()
        for a, b in zip(X_BE_list, X_CT_list):
            est._update(a, b)
        return time.perf_counter() - start, est

    timings = interleaved({"system": system, "bare": bare}, repeats)
    est, logged = timings["system"][2]
    if not np.array_equal(est.X_CE, timings["bare"][2].X_CE):
        raise AssertionError("the calibrator system and the bare estimator disagree")
    us = 1e6 * timings["system"][0] / num_samples
    ref = 1e6 * timings["bare"][0] / num_samples
    row = {"section": "calibrator", "what": f"HandEyeCalibrator (TargetFilter) per sample in a "
           f"Simulator ({num_samples} samples, estimate logged: {logged} samples)",
           "value_us": us, "reference": "bare HandEyeTargetFilter._update", "reference_us": ref,
           "ratio": us / ref, "target": None}
    log(_format_row(row))
    return [row]


# ---------------------------------------------------------------------------------------------
# The closed loop vs the arm driven by Drake's C++ differential IK.

def arm_reference_diagram(scenario, twist_duration: float | None = None,
                          idle_python_systems: int = 0, commanded_poses=None, extend=None):
    """The scenario's arm plant (same ``plant_config``, same start) driven by Drake's C++
    ``DifferentialInverseKinematicsIntegrator`` at our driver's time step and joint limits,
    toward a fixed pose reached at a constant end-effector twist (its speed limits) — and nothing
    else, but ``idle_python_systems`` Python ``LeafSystem``s without ports or events (what
    Python systems cost the simulator by being there). ``commanded_poses`` ((times, poses) of
    ``record_commanded_poses``): instead, the loop's own driver (``add_pose_tracking_driver``:
    the same integrator with frame A = B and the scenario's velocity scale) tracks those poses,
    replayed by ``PoseReplay`` — the loop's own motion; ``extend(builder, handles, control)``,
    if given, is called with it before the diagram is built (what a variant adds, e.g. a camera).
    Returns (diagram, integrator, plant, q0)."""
    from pydrake.common.value import AbstractValue
    from pydrake.math import RigidTransform
    from pydrake.multibody.inverse_kinematics import (
        DifferentialInverseKinematicsIntegrator,
        DifferentialInverseKinematicsParameters,
    )
    from pydrake.systems.framework import DiagramBuilder
    from pydrake.systems.primitives import (
        ConstantValueSource,
        StateInterpolatorWithDiscreteDerivative,
    )

    from ..estimation.se3 import make_transform, rotation_exp
    from ..scenario import transform_matrix
    from ..simulation import DRIVER_STEPS_PER_PERIOD
    from ..systems.arm import add_arm, make_control_plant

    a = scenario.arm
    X_WB = transform_matrix(a.X_WB, "arm.X_WB")
    q0 = np.radians(a.q0_deg)
    builder = DiagramBuilder()
    handles = add_arm(builder, plant_config=scenario.plant_config, urdf=a.urdf or None,
                      base_frame=a.base_frame, ee_frame=a.ee_frame, X_WB=X_WB, q0=q0)
    control = make_control_plant(urdf=a.urdf or None, base_frame=a.base_frame, X_WB=X_WB)
    n = control.num_positions()
    dt = scenario.period / DRIVER_STEPS_PER_PERIOD  # the loop's driver step
    if commanded_poses is not None:
        # The loop's own driver (frame A = B, its velocity scale, no end-effector speed limit)
        # fed the loop's own commands.
        from ..systems.arm import add_pose_tracking_driver
        driver = add_pose_tracking_driver(builder, handles, control, dt,
                                          velocity_scale=a.driver.velocity_scale)
        replay = builder.AddNamedSystem("pose_replay", PoseReplay(*commanded_poses))
        builder.Connect(replay.get_output_port(), driver.X_BE_desired_input_port())
        if extend is not None:
            extend(builder, handles, control)
        return builder.Build(), driver.integrator, handles.plant, q0
    params = DifferentialInverseKinematicsParameters(n, n)
    params.set_joint_position_limits((control.GetPositionLowerLimits(),
                                      control.GetPositionUpperLimits()))
    params.set_joint_velocity_limits((control.GetVelocityLowerLimits(),
                                      control.GetVelocityUpperLimits()))
    # A twist of 0.05 rad/s about E's x axis and 1 cm/s along its y, z axes, held by the speed
    # limits until the pose it leads to (after the whole run) is reached.
    duration = scenario.duration if twist_duration is None else twist_duration
    w, v = 0.05, 0.01
    params.set_end_effector_angular_speed_limit(w)
    params.set_end_effector_translational_velocity_limits([-v] * 3, [v] * 3)
    frame_E = control.GetFrameByName(a.ee_frame)
    ik = builder.AddNamedSystem("diff_ik_integrator", DifferentialInverseKinematicsIntegrator(
        control, frame_E, dt, params))
    context = control.CreateDefaultContext()
    control.SetPositions(context, q0)
    X_WE0 = control.CalcRelativeTransform(context, control.world_frame(), frame_E).GetAsMatrix4()
    X_WE_goal = X_WE0 @ make_transform(rotation_exp([w * duration, 0.0, 0.0]),
                                       [0.0, v * duration, v * duration])
    goal = builder.AddSystem(ConstantValueSource(AbstractValue.Make(RigidTransform(X_WE_goal))))
    builder.Connect(goal.get_output_port(), ik.GetInputPort("X_AE_desired"))
    to_state = builder.AddSystem(StateInterpolatorWithDiscreteDerivative(
        n, dt, suppress_initial_transient=True))
    builder.Connect(ik.get_output_port(), to_state.get_input_port())
    builder.Connect(to_state.get_output_port(),
                    handles.plant.get_desired_state_input_port(handles.model_instance))
    from pydrake.systems.framework import LeafSystem
    for k in range(idle_python_systems):
        builder.AddNamedSystem(f"idle_python_{k}", LeafSystem())
    return builder.Build(), ik, handles.plant, q0



def simulate_reference(scenario, diagram, integrator, q0):
    """Simulates an ``arm_reference_diagram`` for ``scenario.duration`` from joint positions
    q0 (its integrator started there); returns (wall s, this process's CPU s) of Initialize +
    AdvanceTo."""
    from pydrake.systems.analysis import ApplySimulatorConfig, Simulator

    simulator = Simulator(diagram)
    ApplySimulatorConfig(scenario.simulator_config, simulator)
    context = simulator.get_mutable_context()
    integrator.SetPositions(integrator.GetMyMutableContextFromRoot(context), q0)
    start, cpu = time.perf_counter(), time.process_time()
    simulator.Initialize()
    simulator.AdvanceTo(scenario.duration)
    return time.perf_counter() - start, time.process_time() - cpu

class _Timed:
    """Wraps methods of classes, adding each call's duration (s) to ``seconds[class name]``
    (restored on exit): what a system's callbacks cost inside a run."""

    def __init__(self, methods: dict):
        self.methods, self.seconds, self._saved = methods, {}, []

    def __enter__(self):
        for cls, names in self.methods.items():
            self.seconds[cls.__name__] = 0.0
            for name in names:
                original = getattr(cls, name)
                self._saved.append((cls, name, original))
                setattr(cls, name, self._wrap(original, cls.__name__))
        return self

    def _wrap(self, original, key):
        seconds, clock = self.seconds, time.perf_counter

        def timed(*args):
            start = clock()
            try:
                return original(*args)
            finally:
                seconds[key] += clock() - start
        return timed

    def __exit__(self, *exc):
        for cls, name, original in reversed(self._saved):
            setattr(cls, name, original)


def _loop_callbacks():
    """{class: its Drake callbacks} of the default loop's Python systems."""
    from ..systems.calibrator import HandEyeCalibrator
    from ..systems.camera import HandEyeCamera
    from ..systems.servo import VisualServoController
    return {HandEyeCamera: ["_UpdateImage"],
            VisualServoController: ["_UpdateCommand", "_CalcDesiredPose"],
            HandEyeCalibrator: ["_UpdateEstimate"]}


def record_commanded_poses(scenario):
    """(times (s), RigidTransforms) of X_BE_desired as Drake's integrator read it in one run of
    the loop (its time step: three per camera period)."""
    from pydrake.math import RigidTransform

    from ..simulation import run_scenario
    from ..systems.servo import VisualServoController

    recorded = {}
    original = VisualServoController._CalcDesiredPose

    def recording(self, context, output):
        original(self, context, output)
        recorded[context.get_time()] = RigidTransform(output.get_value())

    VisualServoController._CalcDesiredPose = recording
    try:
        run_scenario(scenario)
    finally:
        VisualServoController._CalcDesiredPose = original
    times = sorted(recorded)
    return times, [recorded[t] for t in times]


def _pose_replay_class():
    from pydrake.common.value import AbstractValue
    from pydrake.math import RigidTransform
    from pydrake.systems.framework import LeafSystem

    class PoseReplay(LeafSystem):
        """Output ``X_AE_desired`` (abstract RigidTransform): the recorded pose of the latest
        recorded time ≤ t (a list lookup: the cheapest a Python source can be)."""

        def __init__(self, times, poses):
            super().__init__()
            self._times, self._poses = list(times), list(poses)
            self.DeclareAbstractOutputPort(
                "X_AE_desired", lambda: AbstractValue.Make(RigidTransform()), self._CalcPose,
                prerequisites_of_calc={self.time_ticket()})

        def _CalcPose(self, context, output):
            import bisect
            i = bisect.bisect_right(self._times, context.get_time()) - 1
            output.set_value(self._poses[max(i, 0)])

    return PoseReplay


def PoseReplay(times, poses):
    """A ``LeafSystem`` replaying recorded poses (see ``_pose_replay_class``)."""
    return _pose_replay_class()(times, poses)


def loop_section(repeats: int, log=print) -> list[dict]:
    """The default closed loop (``run_scenario``'s simulation time) against the arm alone driven
    by Drake's C++ differential IK (``arm_reference_diagram``), simulating the same duration;
    beside them (no targets) the loop with the twist driver, the loop without its log, the
    reference with as many idle Python systems as the loop has (what they cost), the reference
    tracking the loop's own commanded poses (what the loop's motion costs the arm), and the
    loop's Python callbacks per camera sample against what the target leaves them."""
    from pydrake.systems.analysis import ApplySimulatorConfig, Simulator

    from ..scenario import TwistCommand, load_scenario
    from ..simulation import build_diagram, run_scenario

    scenario = load_scenario()
    twist = load_scenario()
    twist.arm.driver = TwistCommand()
    diagram, ik, plant, q0 = arm_reference_diagram(scenario)
    # The loop's own Python systems (camera, servo, calibrator): what being in the diagram costs
    # each (with a sampled-port plant, a pybind11 witness query at every step; with live ports,
    # the default, about nothing); the reference with as many idle ones shows it.
    python_systems = [sys_ for sys_ in build_diagram(scenario, with_loggers=False).diagram
                      .GetSystems() if type(sys_).__module__.startswith("handeye_drake")]
    idle = arm_reference_diagram(scenario, idle_python_systems=len(python_systems))
    # The same arm and integrator tracking the poses the loop itself commanded (recorded in one
    # untimed run): the loop's motion without its camera, servo and calibrator.
    replay = arm_reference_diagram(scenario, commanded_poses=record_commanded_poses(scenario))

    def simulate(diagram, ik):
        return simulate_reference(scenario, diagram, ik, q0)

    def reference():
        seconds, cpu = simulate(diagram, ik)
        cpu_times["reference"].append(cpu)
        return seconds, None

    def idle_reference():
        seconds, cpu = simulate(idle[0], idle[1])
        cpu_times["idle"].append(cpu)
        return seconds, None

    def unlogged_loop():
        # What run_scenario simulates, without its log (one VectorLogSink of the logged ports).
        from pydrake.common import RandomGenerator
        built = build_diagram(scenario, with_loggers=False)
        simulator = Simulator(built.diagram)
        ApplySimulatorConfig(scenario.simulator_config, simulator)
        built.diagram.SetRandomContext(simulator.get_mutable_context(),
                                       RandomGenerator(int(scenario.seed)))
        start, cpu = time.perf_counter(), time.process_time()
        simulator.Initialize()
        simulator.AdvanceTo(scenario.duration)
        cpu_times["unlogged"].append(time.process_time() - cpu)
        return time.perf_counter() - start, None

    def replay_reference():
        seconds, cpu = simulate(replay[0], replay[1])
        cpu_times["replay"].append(cpu)
        return seconds, None

    cpu_times = {"reference": [], "loop": [], "twist": [], "idle": [], "replay": [],
                 "unlogged": []}

    def loop():
        result = run_scenario(scenario)  # wall_time: Initialize + AdvanceTo, as above
        cpu_times["loop"].append(result.cpu_time)
        return result.wall_time, result

    def twist_loop():
        result = run_scenario(twist)
        cpu_times["twist"].append(result.cpu_time)
        return result.wall_time, result

    timings = interleaved({"loop": loop, "reference": reference, "twist": twist_loop,
                           "idle": idle_reference, "replay": replay_reference,
                           "unlogged": unlogged_loop}, repeats)
    ref = timings["reference"][0]
    reference_text = (f"arm + C++ DifferentialInverseKinematicsIntegrator (real-time factor "
                      f"{scenario.duration / ref:.2f})")
    rows = []
    for key, what, target in (
            ("loop", "closed loop (default scenario: pose command", TARGETS["loop"]),
            ("twist", "closed loop with arm.driver: !TwistCommand (Python IK driver", None)):
        ours = timings[key][0]
        summary = timings[key][2].summary()
        cpu_ratio = statistics.median(cpu_times[key]) / statistics.median(cpu_times["reference"])
        rows.append({"section": "loop", "what": f"{what}, {scenario.duration:g} s simulated; "
                     f"real-time factor {scenario.duration / ours:.2f})", "value_us": ours,
                     "unit": "s", "reference": reference_text, "reference_us": ref,
                     "ratio": ours / ref, "target": target, "cpu_ratio": cpu_ratio,
                     "final_rotation_error_deg": summary["final_rotation_error_deg"]})
        log(_format_row(rows[-1]) + f"; CPU time ratio {cpu_ratio:.2f}×")
    beside = (
        ("idle", f"the reference with {len(python_systems)} idle Python LeafSystems (as many as "
         f"the loop has: {', '.join(sorted(sys_.get_name() for sys_ in python_systems))})"),
        ("unlogged", "the closed loop without its log (build_diagram(with_loggers=False))"),
        ("replay", "the loop's own driver tracking the poses the loop commanded (recorded, "
         "replayed by a Python list lookup): the loop's motion"))
    for key, what in beside:
        ours = timings[key][0]
        cpu_ratio = statistics.median(cpu_times[key]) / statistics.median(cpu_times["reference"])
        rows.append({"section": "loop", "what": what, "value_us": ours, "unit": "s",
                     "reference": "the reference", "reference_us": ref, "ratio": ours / ref,
                     "target": None, "cpu_ratio": cpu_ratio})
        log(_format_row(rows[-1]) + f"; CPU time ratio {cpu_ratio:.2f}×")
    # What the loop's own systems cost beyond the arm making the same motion: the loop's motion
    # is faster than the reference's (self-calibration rotations), which costs the plant's
    # solver more iterations by itself (the replay row's ratio).
    loop_s, replay_s = timings["loop"][0], timings["replay"][0]
    cpu_ratio = statistics.median(cpu_times["loop"]) / statistics.median(cpu_times["replay"])
    rows.append({"section": "loop", "what": "the closed loop against the arm making the same "
                 "motion (the row above)", "value_us": loop_s, "unit": "s",
                 "reference": "the arm on the loop's motion", "reference_us": replay_s,
                 "ratio": loop_s / replay_s, "target": None, "cpu_ratio": cpu_ratio})
    log(_format_row(rows[-1]) + f"; CPU time ratio {cpu_ratio:.2f}×")
    rows.append(_callback_budget_row(scenario, ref, log))
    return rows


def _callback_budget_row(scenario, reference_seconds: float, log) -> dict:
    """The loop's Python callbacks per camera sample (one more run, each callback timed) against
    what the loop target leaves them: (target − 1) × the reference, over the camera samples."""
    from ..simulation import run_scenario

    with _Timed(_loop_callbacks()) as timed:
        result = run_scenario(scenario)
    samples = len(result.times)
    budget = (TARGETS["loop"] - 1.0) * reference_seconds / samples
    spent = sum(timed.seconds.values()) / samples
    parts = ", ".join(f"{name} {seconds / samples * 1e3:.3f}"
                      for name, seconds in sorted(timed.seconds.items(), key=lambda kv: -kv[1]))
    row = {"section": "loop", "what": f"Python callbacks per camera sample ({samples} samples; "
           f"{parts} ms), against what the {TARGETS['loop']:g}× target leaves for all the "
           "loop's own work", "value_us": spent * 1e3, "unit": "ms",
           "reference": "the budget", "reference_us": budget * 1e3, "ratio": spent / budget,
           "target": None, "callbacks_ms": {k: v / samples * 1e3
                                            for k, v in timed.seconds.items()}}
    log(_format_row(row))
    return row


# ---------------------------------------------------------------------------------------------
# The rendered loop (a hook: filled in once camera.model has a rendered variant).

def rendered_model_type():
    """The rendered camera model's settings type, if the scenario schema has one."""
    import typing

    from ..scenario import CameraModel
    for t in typing.get_args(CameraModel) or (CameraModel,):
        if "render" in t.__name__.lower():
            return t
    return None


#: The rendered scenario the section times (the repository's ``scenarios/rendered.yaml``).
RENDERED_SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "rendered.yaml"
#: Simulated time (s) of the rendered loop timed: its two self-calibration motions and the
#: start of the servo, 121 frames at 30 Hz.
RENDERED_DURATION = 4.0


def rendered_scenario(path=None, duration: float = RENDERED_DURATION):
    """``scenarios/rendered.yaml`` (or ``path``) shortened to ``duration`` s, with no frames
    saved (``frames_to_save`` copies images for the output, it is not part of the loop)."""
    from ..scenario import load_scenario
    s = load_scenario(RENDERED_SCENARIO if path is None else path)
    s.duration = float(duration)
    s.camera.model.frames_to_save = []
    return s.validate()


def arm_positions_reaching(plant, base_frame: str, ee_frame: str, X_BE, q0,
                           tolerance: float = 1e-12, max_iterations: int = 30) -> np.ndarray:
    """(K, n) joint positions whose forward kinematics give each X_BE[k] (end-effector in
    base), by Newton steps on the pose error from the previous frame's solution (``q0`` for the
    first): consecutive frames of a run are close, so each solution stays on the branch the
    arm was on. Raises AssertionError when a pose is not reached to ``tolerance`` (m, rad)."""
    from pydrake.multibody.tree import JacobianWrtVariable

    from ..estimation.se3 import rotation_log
    context = plant.CreateDefaultContext()
    frame_B, frame_E = plant.GetFrameByName(base_frame), plant.GetFrameByName(ee_frame)
    q = np.array(q0, dtype=float)
    out = []
    for k, X in enumerate(X_BE):
        for _ in range(max_iterations):
            plant.SetPositions(context, q)
            X_now = plant.CalcRelativeTransform(context, frame_B, frame_E).GetAsMatrix4()
            error = np.concatenate([rotation_log(X[:3, :3] @ X_now[:3, :3].T),
                                    X[:3, 3] - X_now[:3, 3]])
            if np.abs(error).max() <= tolerance:
                break
            J = plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kQDot, frame_E,
                                                  np.zeros(3), frame_B, frame_B)
            q = q + np.linalg.lstsq(J, error, rcond=None)[0]
        else:
            raise AssertionError(f"frame {k}: the arm's pose was not reached (error "
                                 f"{np.abs(error).max():.3g})")
        out.append(q.copy())
    return np.array(out)


def rendered_reference(scenario):
    """The loop's arm and rendered camera alone: the same systems (``add_arm_with_driver``,
    ``add_rendered_camera_and_detector``: plant, scene graph, board, ``RgbdSensor``) built into a
    diagram that is never simulated. Returns ``run(Q) -> (seconds, (render s, detect s,
    detections))``: for each row of Q the arm's positions are set, the colour image port is
    evaluated (one render) and ``detect_target`` runs on it with the loop's options, exactly as
    ``TargetDetector`` does (grey conversion included)."""
    from pydrake.systems.framework import DiagramBuilder

    from ..simulation import (add_arm_with_driver, add_rendered_camera_and_detector,
                              camera_pose_on_hand)
    from ..vision.detection import as_grey_image, detect_target

    builder = DiagramBuilder()
    arm = add_arm_with_driver(scenario, builder)
    parts = add_rendered_camera_and_detector(scenario, builder, arm,
                                             camera_pose_on_hand(scenario, arm.control_plant))
    diagram = builder.Build()
    plant, port = arm.handles.plant, parts.rendered.color_image_output_port()
    camera_system = port.get_system()
    target, intrinsics = parts.detector.target, parts.detector.intrinsics
    options = parts.detect_options

    def run(Q, cpu_times=None):
        context = diagram.CreateDefaultContext()  # (as the Simulator's, made before timing)
        plant_context = plant.GetMyMutableContextFromRoot(context)
        camera_context = camera_system.GetMyContextFromRoot(context)
        render = detect = 0.0
        detections = []
        start, cpu = time.perf_counter(), time.process_time()
        for q in Q:
            plant.SetPositions(plant_context, q)
            t0 = time.perf_counter()
            image = port.Eval(camera_context)
            t1 = time.perf_counter()
            detections.append(detect_target(as_grey_image(image.data), target, intrinsics,
                                             **options))
            t2 = time.perf_counter()
            render += t1 - t0
            detect += t2 - t1
        if cpu_times is not None:  # (the CPU time of the same span)
            cpu_times.append(time.process_time() - cpu)
        return time.perf_counter() - start, (render, detect, detections)

    return run


def check_same_detections(detections, found, X_CT, tolerance: float = 1e-9) -> float:
    """The reference's detections against the loop's log (found flags per frame; X_CT, the
    last found pose, on found frames): AssertionError unless they agree. Returns the largest
    difference of the X_CT entries (rotation entries and metres)."""
    found = np.asarray(found) > 0.5
    ours = np.array([bool(d.found) for d in detections])
    if ours.shape != found.shape or np.any(ours != found):
        where = (np.flatnonzero(ours != found).tolist() if ours.shape == found.shape
                 else f"{ours.size} frames vs {found.size}")
        raise AssertionError(f"reference and loop disagree on where the target was found: "
                             f"{where}")
    diff = max((float(np.abs(d.X_CT - X).max()) for d, X, f in zip(detections, X_CT, found) if f),
               default=0.0)
    if not diff <= tolerance:
        raise AssertionError(f"reference and loop disagree on X_CT: {diff:.3g} > {tolerance:g}")
    return diff


def rendered_section(repeats: int, log=print, duration: float = RENDERED_DURATION,
                     scenario_path=None) -> list[dict]:
    """The rendered loop (``run_scenario`` of ``scenarios/rendered.yaml`` shortened to
    ``duration``: arm, rendered camera, detector, servo, calibrator, loggers) against rendering
    and detecting the same frames alone (``rendered_reference``: same ``RgbdSensor`` set-up, the
    arm set to the joint positions that reach the robot poses the loop logged at each frame, the
    same number of frames). The reference's detections must equal the loop's
    (``check_same_detections``), so both sides render and detect the same images. Target
    ≤ 1.3×; per-frame costs: render, detect (reference), rest = (loop − reference) / frames."""
    from ..scenario import transform_matrix
    from ..simulation import run_scenario
    from ..systems.arm import make_control_plant

    model = rendered_model_type()
    if model is None:
        log("  rendered loop: not available yet (camera.model has no rendered variant)")
        return [{"section": "rendered", "what": "rendered loop", "status": "not available yet"}]
    path = RENDERED_SCENARIO if scenario_path is None else Path(scenario_path)
    if not path.is_file():
        log(f"  rendered loop: not measured ({path} not found: run from a source checkout)")
        return [{"section": "rendered", "what": "rendered loop", "status": "no scenario file"}]
    scenario = rendered_scenario(path, duration)
    # An untimed run gives the robot pose of every frame (the loop is deterministic: each timed
    # run renders the same frames, checked below).
    first = run_scenario(scenario)
    a = scenario.arm
    control = make_control_plant(urdf=a.urdf or None, base_frame=a.base_frame,
                                 X_WB=transform_matrix(a.X_WB, "arm.X_WB"))
    Q = arm_positions_reaching(control, a.base_frame, a.ee_frame, first.X_BE_samples,
                               np.radians(a.q0_deg))
    reference_run = rendered_reference(scenario)
    costs = []  # (render s, detect s) of every reference run
    cpu_times = {"loop": [], "reference": []}

    def loop():
        result = run_scenario(scenario)  # wall_time: Initialize + AdvanceTo
        cpu_times["loop"].append(result.cpu_time)
        return result.wall_time, result

    def reference():
        seconds, out = reference_run(Q, cpu_times["reference"])
        costs.append(out[:2])
        return seconds, out

    timings = interleaved({"loop": loop, "reference": reference}, repeats)
    result = timings["loop"][2]
    frames = len(Q)
    if len(result.times) != frames or not np.array_equal(result.X_BE_samples,
                                                         first.X_BE_samples):
        raise AssertionError("the rendered loop is not repeatable: its frames changed")
    diff = check_same_detections(timings["reference"][2][2], result.detector_found,
                                 result.X_CT_samples)
    ours, ref = timings["loop"][0], timings["reference"][0]
    # Render and detect per frame: medians over the repeats of the reference's sums.
    render_ms = 1e3 * statistics.median(c[0] for c in costs) / frames
    detect_ms = 1e3 * statistics.median(c[1] for c in costs) / frames
    row = {"section": "rendered",
           "what": f"rendered loop ({path.name}, {scenario.duration:g} s simulated, {frames} "
           f"frames; real-time factor {scenario.duration / ours:.2f})", "value_us": ours,
           "unit": "s", "reference": f"the same {frames} frames rendered (same RgbdSensor, "
           "same arm poses) and detected alone", "reference_us": ref, "ratio": ours / ref,
           "target": TARGETS["rendered"], "frames": frames,
           "per_frame_ms": {"loop": 1e3 * ours / frames, "render": render_ms,
                            "detect": detect_ms, "rest": 1e3 * (ours - ref) / frames},
           "cpu_ratio": statistics.median(cpu_times["loop"])
           / statistics.median(cpu_times["reference"]),
           "found_frames": int(np.sum(result.detector_found > 0.5)),
           "max_X_CT_difference": diff}
    log(_format_row(row) + f"; CPU time ratio {row['cpu_ratio']:.2f}×")
    pf = row["per_frame_ms"]
    log(f"  per frame: loop {pf['loop']:.1f} ms = render {pf['render']:.1f} ms + detect "
        f"{pf['detect']:.1f} ms + rest {pf['rest']:.1f} ms (arm simulation, servo, calibrator, "
        f"samplers, loggers); board found in {row['found_frames']} of {frames} frames, "
        f"detections equal to the loop's (max |ΔX_CT| {diff:.1e})")
    return [row]


# ---------------------------------------------------------------------------------------------
# calibrate on growing recordings, beside OpenCV.

def write_recording(directory, num_camera: int, seed: int = 0):
    """TUM files of ``recorded.example``'s pose model (robot at 50 Hz, camera at 15 Hz stamped
    0.02 s late, 0.1° / 0.5 mm noise) with ``num_camera`` camera samples. Returns (robot path,
    camera path, synchronized X_BE (N, 4, 4), X_CT (N, 4, 4)) — the pairs OpenCV gets."""
    from scipy.spatial.transform import Rotation

    from ..estimation.se3 import inverse
    from ..recorded import example as ex

    def poses(t):
        """``example.camera_pose`` vectorized: X_BC (len(t), 4, 4)."""
        angles = np.radians(np.stack([25.0 * np.sin(2 * np.pi * 0.11 * t + 0.3),
                                      20.0 * np.sin(2 * np.pi * 0.17 * t + 1.1),
                                      30.0 * np.sin(2 * np.pi * 0.07 * t + 2.0)], axis=1))
        R = Rotation.from_euler("xyz", [np.pi, 0.0, 0.0]).as_matrix() @ \
            Rotation.from_euler("xyz", angles).as_matrix()
        distance = 0.5 + 0.05 * np.sin(2 * np.pi * 0.13 * t)
        offset = np.stack([0.03 * np.sin(2 * np.pi * 0.19 * t),
                           0.03 * np.cos(2 * np.pi * 0.23 * t), 0 * t], axis=1)
        X = np.zeros((len(t), 4, 4))
        X[:, :3, :3] = R
        X[:, :3, 3] = ex.X_BT[:3, 3] + offset - distance[:, None] * R[:, :, 2]
        X[:, 3, 3] = 1.0
        return X

    def tum(path, header, t, X):
        q = Rotation.from_matrix(X[:, :3, :3]).as_quat()  # x y z w
        q *= np.where(q[:, 3:] < 0, -1.0, 1.0)
        rows = np.column_stack([t, X[:, :3, 3], q])
        with open(path, "w") as f:
            f.write(header + "\n# timestamp tx ty tz qx qy qz qw\n")
            np.savetxt(f, rows, fmt=["%.6f"] + ["%.6f"] * 3 + ["%.8f"] * 4)

    rng = np.random.default_rng(seed)
    X_CE = inverse(ex.TRUE_X_EC)
    duration = (num_camera - 1) / ex.CAMERA_RATE
    t_robot = np.arange(int(np.ceil(duration * ex.ROBOT_RATE)) + 2) / ex.ROBOT_RATE - 0.04
    t_camera = np.arange(num_camera) / ex.CAMERA_RATE
    X_BE = poses(t_robot) @ X_CE
    X_BC = poses(t_camera)
    X_CT = np.linalg.inv(X_BC) @ ex.X_BT
    noise = Rotation.from_rotvec(np.radians(ex.ROTATION_NOISE_DEG)
                                 * rng.normal(size=(num_camera, 3))).as_matrix()
    X_CT[:, :3, :3] = noise @ X_CT[:, :3, :3]
    X_CT[:, :3, 3] += ex.TRANSLATION_NOISE * rng.normal(size=(num_camera, 3))
    robot, camera = Path(directory) / "robot.tum", Path(directory) / "camera.tum"
    tum(robot, "# X_BE (end-effector in base), metres", t_robot, X_BE)
    tum(camera, "# X_CT (target in camera), metres", t_camera + ex.TIME_OFFSET, X_CT)
    return robot, camera, poses(t_camera) @ X_CE, X_CT


def _opencv_calibrate(X_BE, X_CT):
    import cv2
    R, t = cv2.calibrateHandEye([X[:3, :3] for X in X_BE], [X[:3, 3] for X in X_BE],
                                [X[:3, :3] for X in X_CT], [X[:3, 3] for X in X_CT],
                                method=cv2.CALIB_HAND_EYE_PARK)
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, np.ravel(t)
    return X


def calibrate_section(sizes=CALIBRATE_SIZES, log=print) -> list[dict]:
    """``handeye-drake calibrate`` (in this process, output to a temporary directory) on
    recordings of each size; OpenCV's Park on the same synchronized pairs where its all-pairs
    formulation stays below ``OPENCV_MAX_PAIRS`` motions."""
    from ..estimation.errors import rotation_error_deg
    from ..recorded.example import TRUE_X_EC
    from .calibrate import add_parser

    # The calibrate command's own parser (not ``cli.main``: the CLI imports this module).
    parser = argparse.ArgumentParser(prog="handeye-drake")
    add_parser(parser.add_subparsers(dest="command"))

    def cli_main(argv):
        args = parser.parse_args(argv)
        return args.func(args)

    try:
        import cv2  # noqa: F401
        cv_reason = None
    except ImportError as e:
        cv_reason = f"OpenCV not importable ({e})"
    rows = []
    with tempfile.TemporaryDirectory(prefix="handeye-speed-") as tmp:
        for n in sizes:
            d = Path(tmp) / str(n)
            d.mkdir()
            robot, camera, X_BE, X_CT = write_recording(d, n)
            out = io.StringIO()
            start = time.perf_counter()
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
                code = cli_main(["calibrate", "--robot", str(robot), "--camera", str(camera),
                                 "--out", str(d / "out")])
            seconds = time.perf_counter() - start
            row = {"section": "calibrate", "pairs": n, "seconds": seconds,
                   "us_per_pair": 1e6 * seconds / n, "exit_code": code}
            result = d / "out" / "calibration.json"
            if code == 0 and result.is_file():
                data = json.loads(result.read_text())
                X = data.get("X_EC")
                X = X.get("matrix") if isinstance(X, dict) else X  # (the format may evolve)
                try:
                    row["rotation_error_deg"] = rotation_error_deg(TRUE_X_EC, np.array(X))
                except (TypeError, ValueError):
                    pass
            motions = n * (n - 1) // 2
            if cv_reason is not None:
                row["opencv"] = cv_reason
            elif motions > OPENCV_MAX_PAIRS:
                row["opencv"] = (f"skipped: calibrateHandEye uses all {motions:.3g} pairs of "
                                 "poses (its matrices would not fit in memory)")
            else:
                start = time.perf_counter()
                X_cv = _opencv_calibrate(X_BE, X_CT)
                row["opencv_seconds"] = time.perf_counter() - start
                row["opencv_rotation_error_deg"] = rotation_error_deg(TRUE_X_EC, X_cv)
            rows.append(row)
            log(_format_calibrate(row))
    ok = [r for r in rows if r["exit_code"] == 0]
    if len(ok) >= 2:
        slope = float(np.polyfit(np.log([r["pairs"] for r in ok]),
                                 np.log([r["seconds"] for r in ok]), 1)[0])
        rows.append({"section": "calibrate", "growth_exponent": slope})
        log(f"  calibrate: wall time grows as N^{slope:.2f} (log-log fit over "
            f"{', '.join(str(r['pairs']) for r in ok)} pairs)")
    return rows


def _format_calibrate(row: dict) -> str:
    text = (f"  calibrate, {row['pairs']:>6d} pairs: {row['seconds']:8.2f} s "
            f"({row['us_per_pair']:.0f} µs/pair)")
    if row["exit_code"] != 0:
        text += f", exit code {row['exit_code']}"
    elif "rotation_error_deg" in row:
        text += f", rotation error {row['rotation_error_deg']:.4f}°"
    if "opencv_seconds" in row:
        text += (f"; OpenCV Park {row['opencv_seconds']:.3f} s "
                 f"({1e6 * row['opencv_seconds'] / row['pairs']:.0f} µs/pair, error "
                 f"{row['opencv_rotation_error_deg']:.4f}°)")
    elif "opencv" in row:
        text += f"; OpenCV {row['opencv']}"
    return text


# ---------------------------------------------------------------------------------------------
# Driver and command line.

def run_speed_benchmark(sections=SECTIONS, repeats: int = 7, loop_repeats: int = 3,
                        calibrate_sizes=CALIBRATE_SIZES, log=print,
                        rendered_duration: float = RENDERED_DURATION) -> dict:
    """Runs the requested sections and returns the JSON-able report."""
    unknown = [s for s in sections if s not in SECTIONS]
    if unknown:
        raise ValueError(f"sections: unknown {unknown}, expected a subset of {SECTIONS}")
    for name, v in (("repeats", repeats), ("loop_repeats", loop_repeats)):
        if isinstance(v, bool) or int(v) != v or v < 1:
            raise ValueError(f"{name}: expected a positive integer, got {v!r}")
    blas = pin_blas_threads()
    report = {"blas": blas, "load_average_before": load_average(), "rows": []}
    log(f"BLAS: {blas}; load average {report['load_average_before']} (1, 5, 15 min)")
    start = time.perf_counter()
    for section in sections:
        log(f"[{section}]")
        if section == "estimators":
            report["rows"] += estimator_section(repeats, log=log)
        elif section == "calibrator":
            report["rows"] += calibrator_section(repeats, log=log)
        elif section == "loop":
            report["rows"] += loop_section(loop_repeats, log=log)
        elif section == "rendered":
            report["rows"] += rendered_section(loop_repeats, log=log,
                                               duration=rendered_duration)
        elif section == "corners":
            from .speed_corners import corners_section
            report["rows"] += corners_section(log=log)
        else:
            report["rows"] += calibrate_section(calibrate_sizes, log=log)
    report["load_average_after"] = load_average()
    report["wall_time_s"] = time.perf_counter() - start
    log(f"load average after: {report['load_average_after']}; {report['wall_time_s']:.0f} s")
    return report


def _speed(args) -> int:
    json_path = check_output_file(args.json, "--json", args.force) if args.json else None
    report = run_speed_benchmark(args.sections, args.repeats, args.loop_repeats,
                                 args.calibrate_sizes, rendered_duration=args.rendered_duration)
    report["command"] = " ".join(["handeye-drake"] + sys.argv[1:])
    if json_path is not None:
        json_path.write_text(json.dumps(report, indent=2) + "\n")
        print(f"wrote {json_path}")
    return 0


def add_parser(benchmark_subparsers) -> argparse.ArgumentParser:
    """Adds ``speed`` to the ``benchmark`` command's sub-parsers (the CLI's)."""
    p = benchmark_subparsers.add_parser(
        "speed", help="cost of the estimators, the calibrator system, the closed loop and "
        "calibrate, each as a ratio against a reference measured in the same run",
        description="Times each piece against a reference measured beside it (interleaved, "
        "medians, one BLAS thread) and prints the ratios with the machine's load average.")
    p.add_argument("--sections", nargs="+", choices=SECTIONS, default=list(SECTIONS),
                   help="what to measure (default all)")
    p.add_argument("--repeats", type=int, default=7, metavar="N",
                   help="timings per side for the estimator and calibrator sections (default 7)")
    p.add_argument("--loop-repeats", type=int, default=3, metavar="N",
                   help="timings per side for the closed loop (default 3)")
    p.add_argument("--calibrate-sizes", type=int, nargs="+", default=list(CALIBRATE_SIZES),
                   metavar="N", help="camera samples of the calibrate recordings "
                   "(default 100 1000 10000 100000)")
    p.add_argument("--rendered-duration", type=float, default=RENDERED_DURATION, metavar="S",
                   help="simulated seconds of the rendered loop (default "
                   f"{RENDERED_DURATION:g})")
    p.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    p.add_argument("--force", action="store_true", help="overwrite an existing --json file")
    p.set_defaults(func=_speed)
    return p

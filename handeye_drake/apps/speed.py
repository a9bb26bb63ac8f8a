"""``handeye-drake benchmark speed``: every cost as a ratio against a reference measured beside it.

    handeye-drake benchmark speed [--repeats N] [--sections ...] [--calibrate-sizes N ...]
                                  [--json FILE]

Each figure is a ratio of two timings taken in the same run, interleaved (A, B, B, A, ...), as
the median of ``--repeats`` timings, with BLAS pinned to one thread, so a loaded or slower machine
moves both sides alike; the machine's load average is printed beside the table.

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
- ``loop``: the default closed loop (``run_scenario(load_scenario())``: arm, camera, servo,
  calibrator, our differential-IK driver, loggers) against the same arm plant driven by Drake's
  C++ ``DifferentialInverseKinematicsIntegrator`` (same time step, same joint limits) toward a
  fixed pose under an end-effector speed limit — a constant twist — and nothing else. Target
  ≤ 1.3×; both real-time factors are printed.
- ``rendered``: the rendered-camera loop against rendering and detecting the same frames alone
  (target ≤ 1.3×); "not available yet" until ``camera.model`` has a rendered variant.
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
SECTIONS = ("estimators", "calibrator", "loop", "rendered", "calibrate")
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
    return (f"  {row['what']}: {row['value_us']:.1f} {unit} vs {row['reference']} "
            f"{row['reference_us']:.1f} {unit} → {row['ratio']:.2f}×{bound}{mark}")

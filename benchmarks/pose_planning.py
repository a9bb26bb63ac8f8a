"""Which poses to record: the D-optimal planner against random poses and the half-sphere rule.

    python benchmarks/pose_planning.py [--seeds 50] [--candidates 300] [--max-angle 30]
                                       [--max-distance 0.15] [--json FILE]

Simulated eye-in-hand cell: a camera 8 cm off the flange (X_EC of the shipped example), a target
0.45 m below the camera's start pose, camera pose noise 0.002 rad / 1 mm (``so3``). Per seed:

- candidates: ``sample_candidate_poses`` around the start pose (rotation ≤ --max-angle, flange
  displacement ≤ --max-distance, camera aimed at the target, the 0.2 m target inside a 640×480
  image with 50° vertical field of view);
- planner: ``plan_next_poses`` linearized at a rough guess (the true X_EC off by 2° and 1 cm,
  the target by 2 cm), no samples yet; the first N of its order;
- random: the first N of a random permutation of the same candidates;
- half-sphere: the rule of thumb — N camera positions spread (golden spiral) on a spherical
  cap around the target at the start distance, looking at the target, rolled about the optical
  axis; the cap's angle and the roll range are the largest (≤ --max-angle) that keep every pose
  within the candidates' limits, so all three methods work in the same workspace.

Each set of N poses gets noisy camera poses and the ML fit (``refine_ml_poses``, started from the
rough guess). Reported: medians over seeds of the final error of X_EC (rotation deg, translation
mm) and of the predicted σ (√trace of the rotation / translation blocks of the Cramér–Rao bound
at the truth, the expected norm of the error), and the number of poses (4–40) random and
half-sphere need to reach the planner's median error and σ with 5, 8 and 12 poses.
"""
import argparse
import json
import math
import time

import numpy as np

from handeye_drake.estimation.ml import refine_ml_poses
from handeye_drake.estimation.observability import information_matrix
from handeye_drake.estimation.planning import plan_next_poses, sample_candidate_poses
from handeye_drake.estimation.se3 import (inverse, inverse_tangent_jacobian, make_transform,
                                          retract_pose, rotation_exp, rotation_from_rpy,
                                          rotation_log)
from handeye_drake.vision.camera_model import CameraIntrinsics, apply_pose_noise

X_EC = make_transform(rotation_from_rpy(np.radians([1.5, -2.0, 90.0])), [0.045, -0.012, 0.068])
X_CE = inverse(X_EC)
P_BT = np.array([0.55, 0.05, 0.0])
X_BT = make_transform(rotation_exp([math.pi, 0.0, 0.3]), P_BT)
DISTANCE = 0.45
X_BC_START = make_transform(rotation_exp([math.pi, 0.0, 0.0]), P_BT + [0.0, 0.0, DISTANCE])
X_BE_START = X_BC_START @ X_CE
CAMERA = CameraIntrinsics.from_fov(640, 480, math.radians(50.0))
HALF = 0.1
CORNERS = P_BT + np.array([[HALF, HALF, 0], [-HALF, HALF, 0], [HALF, -HALF, 0], [-HALF, -HALF, 0]])
SIGMA_R, SIGMA_T = 0.002, 0.001
N_REPORT = (5, 8, 12)
N_GRID = tuple(range(4, 41))  # random and half-sphere; the planner only at N_REPORT
METHODS = ("planner", "random", "half-sphere")


def look_at(p_camera, p_target, roll):
    """X_BE of a camera at p_camera looking at p_target, rolled by ``roll`` about its axis from
    the start pose's image orientation."""
    z = p_target - p_camera
    z /= np.linalg.norm(z)
    x = X_BC_START[:3, 0] - (X_BC_START[:3, 0] @ z) * z  # image x as at the start pose
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(z, x), z]) @ rotation_exp([0.0, 0.0, roll])
    return make_transform(R, p_camera) @ X_CE


def half_sphere(n, max_angle, phase):
    """The rule of thumb: n viewpoints on a golden spiral over a spherical cap (polar angle
    ≤ max_angle) around the target at the start distance, looking at it, rolls spread over
    ±max_angle."""
    golden = math.pi * (3.0 - math.sqrt(5.0))
    poses = []
    for i in range(n):
        polar = max_angle * math.sqrt((i + 0.5) / n)
        az = phase + i * golden
        d = np.array([math.sin(polar) * math.cos(az), math.sin(polar) * math.sin(az),
                      math.cos(polar)])
        roll = max_angle * (2.0 * ((i * 0.6180339887) % 1.0) - 1.0)
        poses.append(look_at(P_BT + DISTANCE * d, P_BT, roll))
    return poses


def within_limits(poses, max_angle, max_distance):
    return all(np.linalg.norm(rotation_log(X[:3, :3] @ X_BE_START[:3, :3].T)) <= max_angle
               and np.linalg.norm(X[:3, 3] - X_BE_START[:3, 3]) <= max_distance for X in poses)


def scaled_half_sphere(n, max_angle, max_distance, phase):
    """``half_sphere`` with its cap and roll range shrunk (bisection) until every pose respects
    the same limits as the candidates; returns (poses, the angle used)."""
    lo, hi = 0.0, max_angle
    if within_limits(half_sphere(n, hi, phase), max_angle, max_distance):
        return half_sphere(n, hi, phase), hi
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if within_limits(half_sphere(n, mid, phase), max_angle,
                                            max_distance) else (lo, mid)
    return half_sphere(n, lo, phase), lo


def predicted_sigma(X_BE):
    """(rotation deg, translation mm): √trace of the X_EC blocks of the Cramér–Rao bound."""
    info = information_matrix(X_BE, X_CE, X_BT, SIGMA_R, SIGMA_T)
    w = np.linalg.eigvalsh(info)
    if w[0] <= 1e-12 * w[-1]:
        return math.inf, math.inf
    cov = np.linalg.inv(info)[:6, :6]
    J = inverse_tangent_jacobian(X_CE)
    c = J @ cov @ J.T
    return math.degrees(math.sqrt(np.trace(c[:3, :3]))), 1000 * math.sqrt(np.trace(c[3:, 3:]))


def fit_error(X_BE, rng, X_CE_guess):
    X_CT = [apply_pose_noise(X_CE @ inverse(x) @ X_BT, rng.normal(size=12), "so3", SIGMA_R,
                             SIGMA_T) for x in X_BE]
    try:
        r = refine_ml_poses(X_BE, X_CT, X_CE_guess, SIGMA_R, SIGMA_T)
    except ValueError:
        return math.inf, math.inf
    rot = math.degrees(np.linalg.norm(rotation_log(r.X_EC[:3, :3] @ X_EC[:3, :3].T)))
    return rot, 1000 * float(np.linalg.norm(r.X_EC[:3, 3] - X_EC[:3, 3]))


def run_seed(seed, n_candidates, max_angle_deg, max_distance, exchange=True):
    rng = np.random.default_rng(seed)
    cands = sample_candidate_poses(X_BE_START, P_BT, n_candidates, max_angle_deg, max_distance,
                                   rng, X_HC=X_EC, intrinsics=CAMERA, p_FQ=CORNERS,
                                   margin_px=10.0)
    guess_CE = inverse(retract_pose(X_EC, np.concatenate([
        math.radians(2.0) * _unit(rng), 0.01 * _unit(rng)])))
    guess_BT = make_transform(X_BT[:3, :3], P_BT + 0.02 * _unit(rng))
    perm = rng.permutation(len(cands))
    phase = rng.uniform(0, 2 * math.pi)
    out = {m: {} for m in METHODS}
    plan_time, cap = 0.0, {}
    for n in N_GRID:
        hs, cap[n] = scaled_half_sphere(n, math.radians(max_angle_deg), max_distance, phase)
        sets = {"random": cands[perm[:n]], "half-sphere": hs}
        if n in N_REPORT:
            t0 = time.perf_counter()
            sets["planner"] = cands[plan_next_poses(cands, guess_CE, guess_BT, (), SIGMA_R,
                                                    SIGMA_T, n=n, exchange=exchange).indices]
            plan_time += time.perf_counter() - t0
        for m, poses in sets.items():
            out[m][n] = (*fit_error(list(poses), rng, guess_CE), *predicted_sigma(list(poses)))
    return out, plan_time, cap


def _unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def needed(med, method, target_rot, target_trans, k=0):
    """Smallest N of the grid at which both medians (errors: k = 0, predicted σ: k = 2) reach
    the targets."""
    for n in N_GRID:
        if med[method][n][k] <= target_rot and med[method][n][k + 1] <= target_trans:
            return str(n)
    return f"> {max(N_GRID)}"


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--candidates", type=int, default=300)
    parser.add_argument("--max-angle", type=float, default=30.0, help="deg")
    parser.add_argument("--max-distance", type=float, default=0.15, help="m")
    parser.add_argument("--no-exchange", action="store_true",
                        help="greedy picks only (no Fedorov exchange)")
    parser.add_argument("--json", help="write the medians to this file")
    args = parser.parse_args()
    t0 = time.perf_counter()
    runs, plan_times, caps = [], [], []
    for seed in range(args.seeds):
        r, pt, cap = run_seed(seed, args.candidates, args.max_angle, args.max_distance,
                              not args.no_exchange)
        runs.append(r)
        plan_times.append(pt)
        caps.append(cap)
    med = {m: {n: np.median([[r[m][n][k] for k in range(4)] for r in runs], axis=0)
               for n in runs[0][m]} for m in METHODS}
    print(f"{args.seeds} seeds, {args.candidates} candidates (≤ {args.max_angle:g}°, "
          f"≤ {args.max_distance:g} m), noise {SIGMA_R} rad / {1000 * SIGMA_T:g} mm; medians of "
          f"the X_EC error and of the predicted σ (√trace of the Cramér–Rao bound)")
    print("| poses | method | rotation error (°) | translation error (mm) | predicted σ rot (°) | "
          "predicted σ trans (mm) | error ratio planner / this (rot, trans) |")
    print("|---|---|---|---|---|---|---|")
    for n in N_REPORT:
        for m in METHODS:
            e = med[m][n]
            p = med["planner"][n]
            ratio = "" if m == "planner" else f"{p[0] / e[0]:.2f}, {p[1] / e[1]:.2f}"
            print(f"| {n} | {m} | {e[0]:.4f} | {e[1]:.3f} | {e[2]:.4f} | {e[3]:.3f} | {ratio} |")
    print()
    print("poses needed to reach the planner's median error (rotation and translation), and "
          "its median predicted σ:")
    for n in N_REPORT:
        e = med["planner"][n]
        print(f"  planner with {n:2d} poses: error {e[0]:.4f}° / {e[1]:.3f} mm: random "
              f"{needed(med, 'random', e[0], e[1])}, half-sphere "
              f"{needed(med, 'half-sphere', e[0], e[1])}; σ {e[2]:.4f}° / {e[3]:.3f} mm: "
              f"random {needed(med, 'random', e[2], e[3], 2)}, half-sphere "
              f"{needed(med, 'half-sphere', e[2], e[3], 2)}")
    print("half-sphere cap and roll range that keep its poses within the limits (median over "
          "seeds): " + ", ".join(f"{n} poses {np.degrees(np.median([c[n] for c in caps])):.1f}°"
                                 for n in N_REPORT))
    print(f"planning time per seed ({len(N_REPORT)} plans of {', '.join(map(str, N_REPORT))} "
          f"poses among {args.candidates}{'' if args.no_exchange else ', with exchange'}): "
          f"median {1000 * np.median(plan_times):.0f} ms; total run "
          f"{time.perf_counter() - t0:.1f} s")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({m: {str(n): [float(x) for x in v] for n, v in med[m].items()}
                       for m in METHODS}, f, indent=1)

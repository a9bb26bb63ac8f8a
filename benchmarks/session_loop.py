"""Calibrate until good enough, in the Drake loop: the simulated UR5e with a rendered camera and
the board detector executes the session's suggested poses until it says stop, against random
feasible poses and a half-sphere pattern.

    python benchmarks/session_loop.py [--seeds 20] [--camera rendered|oracle] [--supersample 2]
                                      [--target-sigma 0.1,0.5] [--max-poses 40]
                                      [--candidates 60] [--replan-after N]
                                      [--methods session,random,half-sphere]
                                      [--json FILE] [--picture FILE]

The cell: the shipped UR5e (with its collision capsules) on a table (floor plane at z = 0), a
0.2 × 0.15 m ChArUco board (8 × 6 squares of 25 mm, 35 inner corners; ``--target``) lying face
up at p_BT = (−0.45, −0.15, 0) m, a 640×480 camera (f = 800 px) on the flange with the
simulation's true mount X_EC (4 cm, −3 cm, 6 cm; rpy 4°, −3°, 92°); the planner and the session
only know a rough mount, as from a drawing (3.5 cm, −2.5 cm, 5.5 cm; rpy 2°, −2°, 91°: 9 mm and
2.4° off), and keep 2 cm clearance and the board 60 px inside the image to absorb it. Per seed:

- feasible pool: ``planning.FeasiblePlanner`` (rough mount) with --candidates verified views
  (IK with joint limits, 2 cm clearance to the table and between links, the board's corners in
  the image by 60 px, 0.3–0.7 m away, tilt ≤ 40°);
- session: ``CalibrationSession`` with ``planning.as_session_planner`` — after each sample the
  D-optimal best unvisited pose, reached by a straight joint move (or via the start pose when
  that move is not collision-free);
  with ``--replan-after N``, the IK of the unvisited views is solved again once after N samples
  with the session's estimate of the mount (``as_session_planner(replan_after=N)``);
- random: the same pool in a random order;
- half-sphere: the hand-written pattern — the camera on a half-sphere around the board's centre
  (straight above at four rolls, then 8 azimuths at 20° and 8 at 35° tilt, 0.6/0.65 m (nearer,
  the corners leave the 60 px margin), rolls alternating), each pose solved by IK to within
  1 cm / 3°; repeated when it runs out.

Every executed move is checked on the TRUE cell (true camera mount) every 0.01 rad of joint
motion; a collision is any signed distance < 0. Every suggested pose is checked on the true cell
(within joint limits, no collision): "feasible". Execution is kinematic on the Drake
``MultibodyPlant`` (the arm reaches each commanded joint configuration; the flange pose is its
forward kinematics).

The camera (``--camera rendered``, default): one Drake ``Diagram``
(``systems.rendered_cell.RenderedHandCell``) holds the UR5e's ``MultibodyPlant``, the textured
board in SceneGraph, an ``RgbdSensor`` (RenderEngineVtk, EGL) on the flange at the true X_EC and
the project's ``TargetDetector``; at each pose where a sample is taken (only there) it renders
one frame and the detector measures X_CT (ChArUco corners, IPPE/solvePnP, as in
``vision.detection``); a frame where the board is not found gives no sample ("lost"). The
session gets that X_CT and the robot's reported pose with 0.02° and 0.1 mm noise per axis (the
session's --robot-accuracy). ``--supersample 2`` (default) renders 2× and averages 2 × 2 blocks:
RenderEngineVtk does not anti-alias, and with one sample per pixel the board's edges along the
pixel grid (the half-sphere's straight-down views at rolls 0/90/180/270°) cost up to 1.3° of
pose error on a frontal view (measured; a real lens blurs them) — the session then flags those
samples as outliers (verdict WARN) and, rightly, does not stop. ``--camera oracle``: no
rendering; the true X_CT with 0.05° and 0.3 mm noise per axis.

Reported per method: poses to stop (median and quartiles over the seeds that stopped; how many
stopped within --max-poses), the true error at stop (rotation deg, translation mm; median and
worst), the share of seeds with the true error within 3σ of the reported one (both parts),
collisions in the executed moves, infeasible suggested poses, lost views; the frames rendered,
the run time and the load average.
"""
import argparse
import json
import math
import os
import time

import numpy as np

from handeye_drake.calibration import CalibrationOptions
from handeye_drake.calibration.session import CalibrationSession
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_angle, rotation_exp
from handeye_drake.planning import FeasiblePlanner, ViewSpec, as_session_planner
from handeye_drake.planning.feasible import UR5E_HOME_Q, _look_rotation
from handeye_drake.apps.session_simulate import SimulatedCell

# The cell of ``handeye-drake session --simulate`` (``apps.session_simulate``).
CELL = SimulatedCell()
K = CELL.intrinsics
BOARD = CELL.board_points
X_BT = CELL.X_BT
X_EC_TRUE = CELL.X_EC
X_EC_GUESS = CELL.X_EC_guess
CAMERA_NOISE = (0.05, 0.3)     # deg, mm per axis
ROBOT_NOISE = (0.02, 0.1)
#: The rendered board: a ChArUco of 8 × 6 squares of 25 mm (0.2 × 0.15 m, 35 inner corners).
TARGET_SPEC = CELL.target_spec


def noisy(X, deg, mm, rng):
    return make_transform(rotation_exp(rng.normal(0, math.radians(deg), 3)) @ X[:3, :3],
                          X[:3, 3] + rng.normal(0, mm / 1000, 3))


def half_sphere(planner, view):
    """The pattern's poses X_BE (rough mount), before IK."""
    c = X_BT[:3, :3] @ view.center + X_BT[:3, 3]
    out = []
    rings = [(0.0, [0, 90, 180, 270], 0.6)] + [
        (20.0, list(range(0, 360, 45)), 0.6), (35.0, list(range(0, 360, 45)), 0.65)]
    for tilt, angles, d in rings:
        for k, a in enumerate(angles):
            t, az = math.radians(tilt), math.radians(a)
            dir_T = np.array([math.sin(t) * math.cos(az), math.sin(t) * math.sin(az),
                              math.cos(t)])
            z = X_BT[:3, :3] @ dir_T
            roll = math.radians(a if tilt == 0 else (45 if k % 2 else -45))
            X_BC = make_transform(_look_rotation(z, roll), c - d * z)
            out.append(X_BC @ inverse(X_EC_GUESS))
    return out


def pattern_configs(planner, view):
    qs = []
    for X in half_sphere(planner, view):
        q, ok = planner.solve_ik(X, planner.q_nominal, position_tolerance_m=0.01,
                                 angle_tolerance_deg=3.0)
        if ok and planner.check(q).ok:
            qs.append(q)
    return qs


def run(method, seed, world, planner, pool, pattern, args, cell=None):
    """One calibration until stop; returns its record."""
    rng = np.random.default_rng(1000 + seed)
    options = CalibrationOptions(robot_accuracy_deg=ROBOT_NOISE[0],
                                 robot_accuracy_mm=ROBOT_NOISE[1], seed=seed)
    next_pose = as_session_planner(planner, pool, replan_after=args.replan_after) \
        if method == "session" else None
    # The rough mount tells the robot's poses from the camera's (``roles_evidence``), as
    # ``session --hand-eye`` does.
    session = CalibrationSession(args.sigma[0], args.sigma[1], options, next_pose=next_pose,
                                 camera_sigma_deg=0.1, camera_sigma_mm=1.0,
                                 hand_eye_guess=X_EC_GUESS)
    if method == "random":
        order = iter([pool.q[i] for i in rng.permutation(len(pool))])
    elif method == "half-sphere":
        order = iter([pattern[k % len(pattern)] for k in range(args.max_poses)])
    q_prev = UR5E_HOME_Q
    pose = next_pose([], None, None) if next_pose else None
    collisions = infeasible = lost = poses = 0
    min_clear = math.inf
    step = None
    while poses < args.max_poses:
        if method == "session":
            if pose is None:
                break
            path = [np.asarray(p) for p in pose["path"]]
            q = np.asarray(pose["q"])
        else:
            q = next(order, None)
            if q is None:
                break
            path = [q]
            if planner.check_segment(q_prev, q)[0] < planner.min_distance_m:
                # The session's rule: via the start pose, or skip the pose.
                path = [planner.q_nominal, q]
                if min(planner.check_segment(q_prev, planner.q_nominal)[0],
                       planner.check_segment(planner.q_nominal, q)[0]) < planner.min_distance_m:
                    continue
        poses += 1
        # Execute on the true cell, checked densely.
        a = q_prev
        for b in path:
            d = world.check_segment(a, b, 0.01)[0]
            min_clear = min(min_clear, d)
            collisions += d < 0
            a = b
        f = world.check(q)
        infeasible += not (f.within_limits and f.min_distance_m >= 0)
        q_prev = q
        if cell is None:                       # the pose oracle
            X_BE = world.X_BE(q)
            seen = f.in_image                  # the true camera sees the whole board
        else:                                  # render one frame at q and detect the board
            shot = cell.observe(q)
            X_BE, seen, X_CT = shot.X_BE, shot.found, shot.X_CT
        if not seen:
            lost += 1          # no board in the image: no sample
            step = session.last
            pose = next_pose(list(session.X_BE), None if step is None else step.X_hand,
                             None if step is None else step.X_fixed) if next_pose else None
            continue
        X_BE_reported = noisy(X_BE, *ROBOT_NOISE, rng)
        if cell is None:
            X_CT = noisy(inverse(X_BE @ X_EC_TRUE) @ X_BT, *CAMERA_NOISE, rng)
        step = session.add(X_BE_reported, X_CT)
        if step.stop:
            break
        pose = step.next_pose
    rec = {"method": method, "seed": seed, "poses": poses, "stopped": bool(step and step.stop),
           "replanned": getattr(next_pose, "replanned", 0),
           "collisions": int(collisions), "infeasible": int(infeasible), "lost": lost,
           "min_clearance_m": float(min_clear)}
    if step is not None and step.rotation_sigma_deg is not None:
        X = step.X_hand
        rot = math.degrees(rotation_angle(X[:3, :3].T @ X_EC_TRUE[:3, :3]))
        tra = 1000 * float(np.linalg.norm(X[:3, 3] - X_EC_TRUE[:3, 3]))
        rec.update(rotation_error_deg=rot, translation_error_mm=tra,
                   sigma_deg=step.rotation_sigma_deg, sigma_mm=step.translation_sigma_mm,
                   within_3sigma=bool(rot <= 3 * step.rotation_sigma_deg
                                      and tra <= 3 * step.translation_sigma_mm),
                   verdict=step.verdict)
    return rec


def summary(records, method, max_poses):
    rs = [r for r in records if r["method"] == method]
    st = [r for r in rs if r["stopped"]]
    n = np.array([r["poses"] for r in st]) if st else np.array([np.nan])
    e_r = np.array([r["rotation_error_deg"] for r in st]) if st else np.array([np.nan])
    e_t = np.array([r["translation_error_mm"] for r in st]) if st else np.array([np.nan])
    within = sum(r.get("within_3sigma", False) for r in st)
    return {"method": method, "seeds": len(rs), "stopped": len(st),
            "poses_median": float(np.median(n)), "poses_q1": float(np.percentile(n, 25)),
            "poses_q3": float(np.percentile(n, 75)),
            "rot_err_median_deg": float(np.median(e_r)), "rot_err_max_deg": float(np.max(e_r)),
            "tra_err_median_mm": float(np.median(e_t)), "tra_err_max_mm": float(np.max(e_t)),
            "within_3sigma": within, "collisions": sum(r["collisions"] for r in rs),
            "infeasible": sum(r["infeasible"] for r in rs),
            "lost": sum(r["lost"] for r in rs),
            "executed": sum(r["poses"] for r in rs), "max_poses": max_poses}


TABLE_HEADER = (
    "| method | stopped | poses to stop, median [IQR] | true error at stop, median (max) | "
    "true error ≤ 3σ | collisions | infeasible poses | lost views |\n"
    "|---|---|---|---|---|---|---|---|")


def table_row(r) -> str:
    return (f"| {r['method']} | {r['stopped']}/{r['seeds']} | {r['poses_median']:.0f} "
            f"[{r['poses_q1']:.0f}–{r['poses_q3']:.0f}] | {r['rot_err_median_deg']:.3f}° "
            f"({r['rot_err_max_deg']:.3f}°), {r['tra_err_median_mm']:.2f} mm "
            f"({r['tra_err_max_mm']:.2f} mm) | {r['within_3sigma']}/{r['stopped']} | "
            f"{r['collisions']} in {r['executed']} moves | {r['infeasible']} | "
            f"{r['lost']} of {r['executed']} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--target-sigma", default="0.1,0.5", metavar="DEG,MM")
    ap.add_argument("--max-poses", type=int, default=40)
    ap.add_argument("--candidates", type=int, default=60)
    ap.add_argument("--camera", choices=("rendered", "oracle"), default="rendered",
                    help="rendered: Drake renders the board, the detector measures X_CT "
                         "(default); oracle: the true X_CT with Gaussian noise")
    ap.add_argument("--target", default=TARGET_SPEC, metavar="SPEC",
                    help=f"--camera rendered: the board (default {TARGET_SPEC}, 0.2 × 0.15 m)")
    ap.add_argument("--supersample", type=int, default=2,
                    help="--camera rendered: anti-aliasing factor of the sensor (default 2)")
    ap.add_argument("--replan-after", type=int, default=None, metavar="N",
                    help="session: after N samples re-solve the IK of the unvisited candidates "
                         "with the current estimate of the mount (default: never)")
    ap.add_argument("--methods", default="session,random,half-sphere",
                    help="comma-separated subset of session,random,half-sphere")
    ap.add_argument("--json", default=None)
    ap.add_argument("--picture", default=None, metavar="PNG",
                    help="also draw the first seed's session tour")
    args = ap.parse_args()
    args.sigma = tuple(float(x) for x in args.target_sigma.split(","))
    methods = [m for m in args.methods.split(",") if m]
    if not methods or any(m not in ("session", "random", "half-sphere") for m in methods):
        raise SystemExit(f"--methods: expected a subset of session,random,half-sphere, got "
                         f"{args.methods!r}")
    # The planner keeps the board 60 px inside the image: the rough mount is ~5° off.
    view = ViewSpec(distance_range_m=(0.3, 0.7), max_tilt_deg=40, intrinsics=K,
                    target_points=BOARD, margin_px=60)
    # The true cell judges what happened: collisions (< 0 mm), and the whole board in the true
    # camera's image (else the sample is lost).
    world = FeasiblePlanner("eye_in_hand", X_EC_TRUE, X_BT, view=ViewSpec(
        distance_range_m=(0.05, 2.0), max_tilt_deg=89, cone_half_angle_deg=89, intrinsics=K,
        target_points=BOARD, margin_px=0), min_distance_m=0.0)
    cell = None
    if args.camera == "rendered":
        from handeye_drake.systems.rendered_cell import RenderedHandCell
        cell = RenderedHandCell(args.target, K, X_EC_TRUE, X_BT, supersample=args.supersample)
    t0 = time.time()
    records = []
    for seed in range(args.seeds):
        planner = FeasiblePlanner("eye_in_hand", X_EC_GUESS, X_BT, view=view,
                                  min_distance_m=0.02, seed=seed)
        pool = planner.sample_candidates(args.candidates)
        if seed == 0:
            pattern = pattern_configs(planner, view)
            if not pattern:
                raise SystemExit("half-sphere pattern: no pose reachable")
        for method in methods:
            records.append(run(method, seed, world, planner, pool, pattern, args, cell))
        if seed == 0:
            print(f"half-sphere pattern: {len(pattern)} of {len(half_sphere(planner, view))} "
                  "poses reachable and collision-free")
            if args.picture:
                from handeye_drake.planning.preview import write_picture
                plan = planner.rank(pool, 10)
                tour = planner.plan_tour(UR5E_HOME_Q, pool.q[plan.indices])
                write_picture(planner, tour, args.picture)
        print(f"seed {seed}: " + ", ".join(
            f"{r['method']} {r['poses']}{'' if r['stopped'] else '+'}"
            for r in records[-len(methods):]) + f"  ({time.time() - t0:.0f} s)", flush=True)
    rows = [summary(records, m, args.max_poses) for m in methods]
    if cell is None:
        camera = (f"camera pose oracle {CAMERA_NOISE[0]}° / {CAMERA_NOISE[1]} mm per axis")
    else:
        camera = (f"rendered camera ({args.target}, 640×480, supersample {args.supersample}) "
                  f"and detector, {cell.frames} frames rendered and detected in "
                  f"{cell.seconds:.0f} s ({1000 * cell.seconds / max(cell.frames, 1):.0f} ms "
                  "each)")
    print(f"\nσ target {args.sigma[0]:g}° / {args.sigma[1]:g} mm, {args.seeds} seeds, "
          f"at most {args.max_poses} poses; {camera}; robot {ROBOT_NOISE[0]}° / "
          f"{ROBOT_NOISE[1]} mm per axis\n")
    print(TABLE_HEADER)
    for r in rows:
        print(table_row(r))
    took = time.time() - t0
    load = os.getloadavg()
    if args.replan_after:
        n = [r["replanned"] for r in records if r["method"] == "session"]
        print(f"\nsession: IK re-solved with the estimated mount after {args.replan_after} "
              f"samples, {sum(n)} candidates in {len(n)} runs")
    print(f"\n{took:.0f} s; load average {load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"summary": rows, "records": records, "seconds": took,
                       "frames": None if cell is None else cell.frames,
                       "args": {k: v for k, v in vars(args).items()}}, fh, indent=1)


if __name__ == "__main__":
    main()

"""``handeye-drake plan --feasible``: reachable, collision-free calibration poses for a robot in its
cell, from Drake's inverse kinematics (``planning.FeasiblePlanner``), ranked D-optimally, ordered
into a short tour with a collision-checked trajectory.

Writes into ``--out``: ``joints.csv`` and ``joints.json`` (the poses in the tour's order: joint
angles in rad and X_BE), ``next_poses.tum`` (X_BE, as the other candidate sources),
``trajectory.csv`` (t in s, joint angles in rad, sampled at 50 Hz), ``plan.json`` (settings,
predicted σ after each pose, the collision check), ``tour.html`` (a Meshcat animation that opens
offline in a browser) and ``tour.png`` (a picture of the poses).

Frames: B the robot base, E the flange, C the camera, T the target (z into the board).
``--hand-eye`` is the rough X_EC (X_BC eye-to-hand), ``--target`` the target pose X_BT (X_ET
eye-to-hand), x,y,z[,qx,qy,qz,qw]: a position alone means a board lying face up in the cell
(eye-in-hand) or facing out along the flange's z (eye-to-hand).
"""

from __future__ import annotations

import csv
import json
import math

import numpy as np

from ..estimation.se3 import inverse, make_transform, quat_wxyz, rotation_exp


def parse_target_pose(text: str, mode: str) -> np.ndarray:
    from .pose_args import _numbers, parse_pose
    v = _numbers(text, "--target", (3, 7))
    if len(v) == 7:
        return parse_pose(text, "--target")
    # Face up (z_T down, into the table) / facing out of the flange (z_T = −z_E).
    return make_transform(rotation_exp(np.array([math.pi, 0.0, 0.0])), v)


def _range(text: str, name: str) -> tuple:
    from .pose_args import _numbers
    lo, hi = _numbers(text, name, (2,))
    if not (0 < lo <= hi):
        raise ValueError(f"{name}: expected MIN,MAX with 0 < MIN ≤ MAX (m), got {text!r}")
    return float(lo), float(hi)


def _pose_row(X):
    q = quat_wxyz(X[:3, :3])
    return [*X[:3, 3].tolist(), float(q[1]), float(q[2]), float(q[3]), float(q[0])]


def run_feasible_plan(args, out, mode) -> int:
    """The ``--feasible`` branch of ``plan.run_plan`` (arguments already parsed)."""
    from ..planning import FeasiblePlanner, InfeasibleError, ViewSpec, load_cell
    from ..planning.cell import Cell
    from ..planning.preview import write_preview
    from .pose_args import parse_intrinsics, parse_pose

    if args.hand_eye is None or args.target is None:
        raise ValueError("--hand-eye and --target: --feasible needs the rough camera pose "
                         "(X_EC, X_BC eye-to-hand) and the target pose (X_BT, X_ET eye-to-hand)")
    if args.candidates or args.around or args.camera:
        raise ValueError("--feasible: generates its own candidates; drop --candidates, --around "
                         "and --camera")
    X_HC = parse_pose(args.hand_eye, "--hand-eye")
    X_FT = parse_target_pose(args.target, mode)
    intrinsics = parse_intrinsics(args.intrinsics) if args.intrinsics else None
    points = None
    if args.board:
        from .pose_args import _numbers
        w, h = _numbers(args.board, "--board", (2,))
        if w <= 0 or h <= 0:
            raise ValueError(f"--board: expected WIDTH,HEIGHT > 0 (m), got {args.board!r}")
        points = np.array([[x, y, 0.0] for x in (0, w) for y in (0, h)])
    if not (0 < args.max_tilt < 90):
        raise ValueError(f"--max-tilt: expected a value in (0, 90) degrees, got {args.max_tilt}")
    view = ViewSpec(distance_range_m=_range(args.distance_range, "--distance-range"),
                    max_tilt_deg=args.max_tilt, intrinsics=intrinsics, target_points=points)
    cell = load_cell(args.cell) if args.cell else Cell()
    meshcat = None
    if not args.no_preview:
        from pydrake.geometry import Meshcat
        meshcat = Meshcat()
    planner = FeasiblePlanner(mode, X_HC, X_FT, urdf=args.urdf, base_frame=args.base_frame,
                              ee_frame=args.ee_frame, cell=cell, view=view,
                              min_distance_m=args.min_distance, meshcat=meshcat, seed=args.seed)
    q_start = planner.q_nominal
    d0, pair0 = planner.min_distance(q_start)
    if d0 < planner.min_distance_m:
        raise InfeasibleError(f"start configuration: {pair0[0]} is {1000 * d0:.0f} mm from "
                              f"{pair0[1]} (minimum {1000 * planner.min_distance_m:g} mm)")
    cands = planner.sample_candidates(args.num_candidates)
    sr = math.radians(args.rotation_sigma_deg or 0.1)
    st = args.translation_sigma or 0.001
    plan = planner.rank(cands, args.n, (), X_HC, X_FT, sr, st)
    chosen = [cands.q[i] for i in plan.indices]
    tour = planner.plan_tour(q_start, chosen)
    if not tour.order:
        raise InfeasibleError("tour: no chosen pose can be reached from the start without "
                              "collision")
    check_d, check_t, check_pair = planner.check_trajectory(tour.trajectory)
    print(f"feasible planning ({mode}): {len(cands)} verified candidates from {cands.attempts} "
          f"IK problems" + (f" (rejected: " + "; ".join(
              f"{v}× {k}" for k, v in cands.rejected.most_common(3)) + ")"
                             if cands.rejected else ""))
    rows, steps = [], []
    for rank, k in enumerate(tour.order, start=1):
        i = plan.indices[k]
        q, X = cands.q[i], cands.X_BE[i]
        f = planner.check(q)
        greedy_rank = k + 1
        r, t = plan.rotation_std_deg[greedy_rank], plan.translation_std[greedy_rank]
        rows.append([rank, *q.tolist(), *_pose_row(X)])
        steps.append({"rank": rank, "information_rank": greedy_rank, "q_rad": q.tolist(),
                      "X_BE_xyz_quat_xyzw": _pose_row(X), "time_s": tour.pose_times[rank - 1],
                      "min_distance_m": f.min_distance_m, "target_distance_m":
                          f.target_distance_m, "tilt_deg": f.tilt_deg,
                      "off_axis_deg": f.off_axis_deg})
        print(f"  {rank:2d}. q [{' '.join(f'{x:+.3f}' for x in q)}] rad  xyz "
              f"[{' '.join(f'{x:+.3f}' for x in X[:3, 3])}]  view {f.target_distance_m:.2f} m, "
              f"tilt {f.tilt_deg:.0f}°, clearance {1000 * f.min_distance_m:.0f} mm")
    all_r, all_t = plan.rotation_std_deg[-1], plan.translation_std[-1]
    print(f"  predicted σ after all {len(plan.indices)}: rotation "
          f"[{' '.join(f'{x:.3g}' for x in all_r)}] deg, translation "
          f"[{' '.join(f'{1000 * x:.3g}' for x in all_t)}] mm")
    print(f"  trajectory {tour.duration_s:.1f} s, {tour.detours} detour(s), "
          f"{len(tour.dropped)} pose(s) dropped; smallest clearance "
          f"{1000 * check_d:.1f} mm ({check_pair[0]} – {check_pair[1]}, checked every "
          f"{tour.check_step_rad:g} rad)")
    names = [planner.plant.get_joint(j).name() for j in planner.plant.GetJointIndices()
             if planner.plant.get_joint(j).num_positions() == 1]
    files = []
    p = out.path("joints.csv")
    with p.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["rank", *[f"{n}_rad" for n in names], "x", "y", "z", "qx", "qy", "qz", "qw"])
        w.writerows(rows)
    files.append(p)
    p = out.path("joints.json")
    p.write_text(json.dumps({"frames": "q in rad; X_BE flange in base (m, quaternion xyzw)",
                             "joint_names": names, "poses": steps}, indent=2) + "\n")
    files.append(p)
    p = out.path("next_poses.tum")
    lines = ["# feasible poses X_BE in tour order; written by handeye-drake plan --feasible",
             "# rank tx ty tz qx qy qz qw"]
    lines += [" ".join([str(r[0])] + [f"{x:.9f}" for x in r[-7:]]) for r in rows]
    p.write_text("\n".join(lines) + "\n")
    files.append(p)
    p = out.path("trajectory.csv")
    traj = tour.trajectory
    with p.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t_s", *[f"{n}_rad" for n in names]])
        for t in np.arange(0.0, traj.end_time() + 1e-9, 0.02):
            w.writerow([f"{t:.3f}", *[f"{x:.6f}" for x in traj.value(t).ravel()]])
    files.append(p)
    p = out.path("plan.json")
    p.write_text(json.dumps({
        "mode": mode, "urdf": planner.urdf, "base_frame": args.base_frame,
        "ee_frame": args.ee_frame, "num_candidates": len(cands),
        "ik_attempts": cands.attempts, "rejected": dict(cands.rejected),
        "rotation_sigma_rad": sr, "translation_sigma_m": st,
        "distance_range_m": list(view.distance_range_m), "max_tilt_deg": view.max_tilt_deg,
        "min_distance_m": planner.min_distance_m,
        "predicted_std": {"rotation_deg": plan.rotation_std_deg[1:].tolist(),
                          "translation_m": plan.translation_std[1:].tolist()},
        "trajectory": {"duration_s": tour.duration_s, "detours": tour.detours,
                       "dropped": len(tour.dropped), "check_step_rad": tour.check_step_rad,
                       "min_clearance_m": check_d, "min_clearance_time_s": check_t,
                       "min_clearance_pair": list(check_pair)},
        "poses": steps}, indent=2) + "\n")
    files.append(p)
    files += write_preview(planner, tour, out.path("tour.html"), out.path("tour.png"),
                           meshcat=meshcat)
    out.finish(files)
    print("wrote: " + ", ".join(str(f) for f in files))
    return 0


def add_arguments(p) -> None:
    g = p.add_argument_group("feasible poses with Drake (--feasible)")
    g.add_argument("--feasible", action="store_true",
                   help="generate candidates by inverse kinematics for the robot in its cell "
                        "(joint limits, collisions, the target in view) and write the joint "
                        "configurations, a checked trajectory and a preview")
    g.add_argument("--urdf", default=None, metavar="FILE",
                   help="robot model with collision geometry (default: the shipped UR5e)")
    g.add_argument("--base-frame", default="base_link", help="base frame B (default base_link)")
    g.add_argument("--ee-frame", default="tool0", help="flange frame E (default tool0)")
    g.add_argument("--cell", metavar="YAML", help="floor_z and boxes (m, in B); default: a "
                   "floor at z = 0")
    g.add_argument("--distance-range", default="0.3,0.7", metavar="MIN,MAX",
                   help="camera–target distance (m, default 0.3,0.7)")
    g.add_argument("--max-tilt", type=float, default=40.0, metavar="DEG",
                   help="largest angle between the optical axis and the board normal (default "
                        "40)")
    g.add_argument("--board", metavar="WIDTH,HEIGHT",
                   help="the board's size (m) from the target origin along x and y: its corners "
                        "must be in the image (with --intrinsics)")
    g.add_argument("--min-distance", type=float, default=0.01, metavar="METRES",
                   help="smallest clearance between the robot, camera, target and cell (default "
                        "0.01)")
    g.add_argument("--no-preview", action="store_true",
                   help="skip the Meshcat HTML and PNG preview")

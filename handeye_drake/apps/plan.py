"""``handeye-drake plan``: the next robot poses to record for a hand-eye calibration.

    handeye-drake plan [--robot FILE [--camera FILE]] (--candidates FILE | --around POSE)
                       [--hand-eye POSE] [--target POINT] [--n 5] [--out DIR] …

Ranks candidate end-effector poses by the information they add to the hand-eye estimate
(``estimation.planning.plan_next_poses``: greedy D-optimal design with exchange on the hand-eye
part of the Fisher information) and writes the best N as a TUM file with the predicted
standard deviations after each.

Estimates to linearize at: from the recording when ``--camera`` is given (maximum-likelihood
fit of the recorded samples; camera noise estimated from its residuals unless given), else
from ``--hand-eye`` (a rough X_EC, e.g. from a drawing) and ``--target`` (the target's position
in the base). Poses on the command line are ``x,y,z,qx,qy,qz,qw`` (metres, TUM/ROS quaternion
order, scalar last). Eye-to-hand (``--mode eye_to_hand``): ``--hand-eye`` is X_BC (the camera
in the base) and ``--target`` the target's position on the flange (in E).

With ``--feasible`` the candidates come from Drake's inverse kinematics for the robot in its cell
instead (``apps.plan_feasible``: joint limits, collisions, the target in view), and the command
also writes the joint configurations, a collision-checked trajectory and a Meshcat preview.

The command is ``add_parser(subparsers)`` / ``run_plan(args)`` of the project CLI.
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from .argtypes import int_up_to, positive_deg_mm, positive_float
from .outputs import prepare_output_dir
from .pose_args import _numbers, parse_intrinsics, parse_point, parse_pose  # noqa: F401
from ..estimation.observability import (HOLDER_FRAME, UnobservableError,
                                        observability_report, parse_fixed, pose_residuals,
                                        recording_observability, refine_ml_poses_fixed)
from ..estimation.planning import plan_next_poses, sample_candidate_poses
from ..estimation.se3 import inverse, make_transform, quat_wxyz
from ..calibration.align import align_streams
from ..recorded.formats import FORMATS, read_poses

#: Default camera pose noise when it cannot be estimated (no --camera): 0.1° and 1 mm.
DEFAULT_ROTATION_SIGMA_DEG = 0.1
DEFAULT_TRANSLATION_SIGMA = 0.001


def _tum_line(stamp: float, X: np.ndarray) -> str:
    w, x, y, z = quat_wxyz(X[:3, :3])
    t = X[:3, 3]
    return f"{stamp:g} {t[0]:.6f} {t[1]:.6f} {t[2]:.6f} {x:.9f} {y:.9f} {z:.9f} {w:.9f}"


def _fmt_std(v, scale: float, digits: str) -> str:
    return "[" + " ".join("∞" if not math.isfinite(x) else format(scale * x, digits)
                          for x in v) + "]"


def _estimate_from_recording(args, fixed, mode):
    """(X_CH, X_FT, X_BE samples, sigmas, note) from --robot/--camera."""
    robot = read_poses(args.robot, "robot", args.format,
                       translation_scale=args.translation_scale)
    camera = read_poses(args.camera, "camera", args.format,
                        camera_in_target=args.camera_pose_is_camera_in_target,
                        translation_scale=args.translation_scale)
    offset = _check_recording(robot, camera, args, fixed, mode)
    aligned = align_streams(robot, camera, offset)
    X_BE, X_CT = list(aligned.X_BE), list(aligned.X_CT)
    sr = math.radians(args.rotation_sigma_deg or DEFAULT_ROTATION_SIGMA_DEG)
    st = args.translation_sigma or DEFAULT_TRANSLATION_SIGMA
    guess = None if args.hand_eye is None else inverse(parse_pose(args.hand_eye, "--hand-eye"))

    def fit(sr, st):
        try:
            r = refine_ml_poses_fixed(X_BE, X_CT, guess, sr, st, fixed=fixed, mode=mode)
            return r.X_CH, r.X_FT, r.residuals
        except UnobservableError:
            # The recording leaves part of the hand-eye pose undetermined (e.g. a SCARA's
            # height): plan from the fit of the rest — choosing poses that fix it is the point.
            _, X_CH, X_FT = recording_observability(X_BE, X_CT, sr, st, mode, X_CH_init=guess)
            return X_CH, X_FT, pose_residuals(X_BE, X_CT, X_CH, X_FT, mode)

    X_CH, X_FT, res = fit(sr, st)
    note = "given"
    dropped = 0
    if args.rotation_sigma_deg is None or args.translation_sigma is None:
        # Camera noise from the residuals, robustly: the norm of a 3-D isotropic Gaussian error
        # has median 1.5382 σ; samples beyond the 99.9 % quantile of that norm (χ with 3
        # degrees of freedom) are dropped as outliers and the noise re-estimated from the rest.
        chi3_median, chi3_999 = 1.5382, 4.0331
        rot, tra = np.radians(res[:, 0]), res[:, 1]
        sr_hat = max(float(np.median(rot)) / chi3_median, 1e-6)
        st_hat = max(float(np.median(tra)) / chi3_median, 1e-7)
        keep = (rot <= chi3_999 * sr_hat) & (tra <= chi3_999 * st_hat)
        if keep.sum() >= 3:
            dropped = int((~keep).sum())
            X_BE = [x for x, k in zip(X_BE, keep) if k]
            X_CT = [x for x, k in zip(X_CT, keep) if k]
            dof = max(3 * len(X_BE) - 6, 1)
            sr_hat = math.sqrt(float(np.sum(rot[keep] ** 2)) / dof)
            st_hat = math.sqrt(float(np.sum(tra[keep] ** 2)) / dof)
        sr = sr if args.rotation_sigma_deg is not None else max(sr_hat, 1e-6)
        st = st if args.translation_sigma is not None else max(st_hat, 1e-7)
        X_CH, X_FT, _ = fit(sr, st)
        note = "estimated from the fit's residuals" + (
            f", {dropped} outlying samples dropped" if dropped else "")
    return X_CH, X_FT, X_BE, sr, st, (f"fit of {len(X_BE)} recorded samples", note)


#: Reasons of calibrate's verdict that do not stop a plan: a recording too short or too poor to
#: determine every direction is what planning is for.
PLAN_TOLERATES = ("unobservable", "weak", "too_few_samples", "held_out", "sigma", "time_offset")
#: Without --intrinsics, the target counts as in view within this angle of the optical axis
#: (wider than any usual lens's half field of view: only what no camera sees is refused).
VIEW_CONE_DEG = 60.0


def _check_recording(robot, camera, args, fixed, mode) -> float:
    """calibrate's checks on the recording a plan starts from: a FAIL that says the data are
    read wrong (swapped or inverted files, units, quaternion order, a target that moved, an
    implausible mount) refuses the plan, naming the cause, as calibrate would; what only says
    the recording is too short (unobservable or weak directions, few samples) does not.
    Returns the clock offset (s) to pair the samples with: --time-offset, or calibrate's
    estimate (auto, the default when both files have timestamps)."""
    from ..calibration.pipeline import calibrate_streams
    given = args.time_offset if isinstance(args.time_offset, (int, float)) else 0.0
    try:
        result = calibrate_streams(robot, camera, mode=mode, time_offset=args.time_offset,
                                   holdout_fraction=0.0, fixed=fixed or None,
                                   robot_accuracy=None)
    except ValueError as e:
        text = str(e)
        if any(w in text for w in ("unobservable", "does not determine", "parallel",
                                   "at least", "too few")):
            return given    # too short or too poor to check: the plan is how it gets better
        raise ValueError(f"--robot, --camera: the recording does not calibrate ({text}); a "
                         "plan from it would start from a wrong estimate") from None
    bad = [r for r in result.verdict.reasons if r.level == "FAIL"
           and r.code not in PLAN_TOLERATES]
    if bad:
        raise ValueError(f"--robot, --camera: calibrate's checks fail on the recording "
                         f"({bad[0].code}: {bad[0].message}); a plan from it would start from a "
                         "wrong estimate — fix the cause first")
    return float(result.time_offset.offset) if result.time_offset is not None else given


def _in_view(X_BE, X_HC, p_F, mode, intrinsics) -> tuple[bool, np.ndarray]:
    """(the target point is in view, its position in C) at the robot pose X_BE: in front of
    the camera and inside the image (with intrinsics) or within ``VIEW_CONE_DEG`` of the
    optical axis."""
    X_CF = inverse(np.asarray(X_BE) @ X_HC) if mode == "eye_in_hand" else \
        inverse(X_HC) @ np.asarray(X_BE)
    p_C = X_CF[:3, :3] @ p_F + X_CF[:3, 3]
    if p_C[2] <= 1e-3:
        return False, p_C
    if intrinsics is not None:
        from ..vision.camera_model import project_points
        return bool(project_points(p_C, intrinsics)[2][0]), p_C
    return math.degrees(math.atan2(math.hypot(p_C[0], p_C[1]), p_C[2])) <= VIEW_CONE_DEG, p_C


def _where(p_C) -> str:
    if p_C[2] <= 1e-3:
        return f"behind the camera (z = {p_C[2]:+.3f} m in C)"
    return (f"{math.degrees(math.atan2(math.hypot(p_C[0], p_C[1]), p_C[2])):.0f}° off the "
            "optical axis")


def run_plan(args) -> int:
    """Runs ``plan`` from parsed arguments; raises ValueError on bad input."""
    # The noise as the estimation below reads it: σ_rot in degrees, σ_trans in metres.
    args.rotation_sigma_deg, args.translation_sigma = (None, None) if args.noise is None else \
        (args.noise[0], args.noise[1] / 1000.0)
    mode = args.mode.replace("-", "_")
    H = HOLDER_FRAME[mode]
    fixed = parse_fixed(args.fix) if args.fix else {}
    # What the robot's accuracy leaves of any σ target (the session refuses one below it).
    from .session import floor_line
    acc = _numbers(args.robot_accuracy, "--robot-accuracy", (2,))
    if not np.all(acc >= 0):
        raise ValueError(f"--robot-accuracy: expected DEG,MM ≥ 0, got {args.robot_accuracy!r}")
    target = None
    if args.target_sigma is not None:
        target = _numbers(args.target_sigma, "--target-sigma", (2,))
        if not np.all(target > 0):
            raise ValueError(f"--target-sigma: expected DEG,MM > 0, got {args.target_sigma!r}")
    X_guess = parse_pose(args.hand_eye, "--hand-eye") if args.hand_eye else None
    floor = floor_line(target, acc, X_guess)
    out = prepare_output_dir(args.out, "plan", args.force)
    print(floor)
    if args.n < 1:
        raise ValueError(f"--n: must be ≥ 1, got {args.n}")
    if args.num_candidates is not None and args.num_candidates < 1:
        raise ValueError(f"--num-candidates: must be ≥ 1, got {args.num_candidates}")
    if args.feasible:
        from .plan_feasible import run_feasible_plan
        if args.num_candidates is None:
            args.num_candidates = 60
        return run_feasible_plan(args, out, mode)
    if args.num_candidates is None:
        args.num_candidates = 500
    if args.camera and not args.robot:
        raise ValueError("--camera: needs --robot (the robot poses of the same samples)")
    if args.candidates and args.around:
        raise ValueError("--candidates and --around: give one source of candidate poses")
    if not args.candidates and not args.around:
        raise ValueError("give candidate poses: --candidates FILE, or --around POSE to sample "
                         "them")
    for name in ("rotation_sigma_deg", "translation_sigma"):
        v = getattr(args, name)
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ValueError(f"--{name.replace('_', '-')}: must be finite and > 0, got {v}")

    if args.camera:
        if args.target is not None:
            raise ValueError("--target: the target pose comes from the recording (--camera); "
                             "drop --target")
        X_CH, X_FT, samples, sr, st, (source, noise_note) = _estimate_from_recording(
            args, fixed, mode)
    else:
        if args.hand_eye is None or args.target is None:
            raise ValueError("--hand-eye and --target: without --camera, planning needs a rough "
                             "hand-eye pose and the target's position")
        X_CH = inverse(parse_pose(args.hand_eye, "--hand-eye"))
        X_FT = make_transform(np.eye(3), parse_point(args.target, "--target"))
        samples = [] if not args.robot else list(read_poses(
            args.robot, "robot", args.format, translation_scale=args.translation_scale).poses)
        sr = math.radians(args.rotation_sigma_deg or DEFAULT_ROTATION_SIGMA_DEG)
        st = args.translation_sigma or DEFAULT_TRANSLATION_SIGMA
        source, noise_note = "--hand-eye / --target", "given" if (
            args.rotation_sigma_deg and args.translation_sigma) else "default"

    intrinsics = parse_intrinsics(args.intrinsics) if args.intrinsics else None
    X_HC0, p_F = inverse(X_CH), X_FT[:3, 3]
    lens = "in the image" if intrinsics is not None else \
        f"within {VIEW_CONE_DEG:g}° of the optical axis"
    if samples and not args.camera:
        # The recorded poses saw the target: guesses that put it out of view there are wrong.
        views = [_in_view(X, X_HC0, p_F, mode, intrinsics) for X in samples]
        blind = [k for k, (ok, _) in enumerate(views) if not ok]
        if len(blind) > len(samples) // 2:
            raise ValueError(
                f"--hand-eye, --target: with them the target is not {lens} at {len(blind)} of "
                f"the {len(samples)} recorded poses of --robot (first: pose {blind[0] + 1}, "
                f"{_where(views[blind[0]][1])}) — the recorded poses saw it; check --hand-eye "
                f"({'X_EC' if mode == 'eye_in_hand' else 'X_BC'}), --target and --mode")
    if args.candidates:
        candidates = read_poses(args.candidates, "robot", args.format,
                                translation_scale=args.translation_scale).poses
        visibility = None
        if intrinsics is not None:
            from ..vision.camera_model import project_points
            p = X_FT[:3, 3]
            X_HC = inverse(X_CH)

            def visibility(X):
                X_CF = inverse(X @ X_HC) if mode == "eye_in_hand" else X_CH @ X
                _, _, inside = project_points(X_CF[:3, :3] @ p + X_CF[:3, 3], intrinsics)
                return bool(inside[0])
    else:
        center = parse_pose(args.around, "--around")
        ok, p_C = _in_view(center, X_HC0, p_F, mode, intrinsics)
        if not ok:
            raise ValueError(
                f"--around: the camera does not see the target at this pose: the target is "
                f"{_where(p_C)} (must be {lens}) — candidates sampled around it would be blind; "
                f"check --around, --hand-eye "
                f"({'X_EC' if mode == 'eye_in_hand' else 'X_BC'}) and --target")
        rng = np.random.default_rng(args.seed)
        candidates = sample_candidate_poses(
            center, X_FT[:3, 3], args.num_candidates, args.max_angle, args.max_distance, rng,
            X_HC=inverse(X_CH), intrinsics=intrinsics, mode=mode)
        visibility = None

    if visibility is None:
        # Never a blind pose: without intrinsics, the target in front within the cone.
        def visibility(X):
            return _in_view(X, X_HC0, p_F, mode, intrinsics)[0]
    seen = [bool(visibility(X)) for X in candidates]
    if not any(seen):
        first = _in_view(candidates[0], X_HC0, p_F, mode, intrinsics)[1]
        raise ValueError(
            f"--candidates: the camera sees the target at none of the {len(candidates)} "
            f"candidate poses (the first: target {_where(first)}; it must be {lens}) — check "
            f"--hand-eye ({'X_EC' if mode == 'eye_in_hand' else 'X_BC'}), --target and the "
            "candidates' frame")
    if sum(seen) < args.n:
        raise ValueError(f"--n: only {sum(seen)} of the {len(candidates)} candidates see the "
                         f"target ({lens}); asked for {args.n}")
    blind_note = "" if all(seen) else (f"; {len(seen) - sum(seen)} of {len(candidates)} "
                                       f"candidates left out: the target is not {lens} there")
    plan = plan_next_poses(candidates, X_CH, X_FT, samples, sr, st, n=args.n, mode=mode,
                           visibility=visibility, fixed=tuple(fixed))
    X_HC = inverse(X_CH)
    hc = f"X_{H}C"
    print(f"planning {args.n} poses ({mode}) among {len(candidates)} candidates; estimates from "
          f"{source}; camera noise {math.degrees(sr):.3g}° / {1000 * st:.3g} mm ({noise_note})"
          + blind_note)
    print(f"  {hc} translation [{' '.join(f'{x:+.4f}' for x in X_HC[:3, 3])}] m"
          + (f"; fixed: {', '.join(f'{k}={v:g}' for k, v in fixed.items())}" if fixed else ""))
    report = None
    if len(samples) >= 2:
        report = observability_report(samples, X_CH, X_FT, sr, st, mode)
        resolved = {f.removesuffix("_deg") for f in report.suggested_fixes()} <= set(fixed)
        for line in report.lines():
            if resolved and report.suggested_fixes() and line.lstrip().startswith("fix "):
                line = f"    resolved by --fix {','.join(fixed)}: the other components are " \
                    "calibrated"
            print("  " + line)
    print(f"  now:     σ rotation about {H} x,y,z {_fmt_std(plan.rotation_std_deg[0], 1, '.3g')} "
          f"deg, translation {_fmt_std(plan.translation_std[0], 1000, '.3g')} mm "
          f"({len(samples)} samples)")
    lines = ["# next poses to record (X_BE, end-effector in base), best first; written by "
             "handeye-drake plan", "# rank tx ty tz qx qy qz qw"]
    steps = []
    for k, i in enumerate(plan.indices, start=1):
        X = np.asarray(candidates[i])
        r, t = plan.rotation_std_deg[k], plan.translation_std[k]
        print(f"  {k:2d}. candidate {i:4d}  xyz [{' '.join(f'{x:+.4f}' for x in X[:3, 3])}]  "
              f"σ rot {_fmt_std(r, 1, '.3g')} deg, trans {_fmt_std(t, 1000, '.3g')} mm")
        lines.append(_tum_line(k, X))
        q = quat_wxyz(X[:3, :3])
        steps.append({"rank": k, "candidate": int(i), "X_BE_xyz": X[:3, 3].tolist(),
                      "X_BE_quat_xyzw": [float(q[1]), float(q[2]), float(q[3]), float(q[0])],
                      "rotation_std_deg": [x if math.isfinite(x) else None for x in r.tolist()],
                      "translation_std_m": [x if math.isfinite(x) else None
                                            for x in t.tolist()],
                      "log_det_gain": plan.log_det_gain[k - 1]})
    tum = out.path("next_poses.tum")
    tum.write_text("\n".join(lines) + "\n")
    js = out.path("plan.json")
    js.write_text(json.dumps({
        "mode": mode, "num_candidates": len(candidates), "num_samples": len(samples),
        "rotation_sigma_rad": sr, "translation_sigma_m": st, "fixed": fixed,
        f"{hc}_estimate": X_HC.tolist(), "target_position": X_FT[:3, 3].tolist(),
        "std_now": {"rotation_deg": [x if math.isfinite(x) else None
                                     for x in plan.rotation_std_deg[0].tolist()],
                    "translation_m": [x if math.isfinite(x) else None
                                      for x in plan.translation_std[0].tolist()]},
        "observability": None if report is None else report.to_dict(),
        "next_poses": steps}, indent=2) + "\n")
    out.finish([tum, js])
    print(f"wrote: {tum}, {js}")
    return 0


def _angle_up_to_180(text: str) -> float:
    """``--max-angle``: a rotation bound (deg) in (0, 180]."""
    v = positive_float(text)
    if v > 180:
        raise argparse.ArgumentTypeError(f"expected an angle in (0, 180] degrees, got {text!r}")
    return v


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Adds the ``plan`` subcommand to an argparse ``subparsers`` object."""
    p = subparsers.add_parser(
        "plan", help="suggest the next robot poses to record (D-optimal design)",
        description="Rank candidate robot poses by the information they add to the hand-eye "
                    "estimate and write the best N (X_BE, TUM) with the predicted standard "
                    "deviations after each. Poses are given as x,y,z,qx,qy,qz,qw (metres, "
                    "quaternion scalar last).")
    p.add_argument("--robot", metavar="FILE", help="robot poses X_BE recorded so far")
    p.add_argument("--camera", metavar="FILE",
                   help="camera poses X_CT (target in camera) of the same samples: the "
                        "estimates then come from their maximum-likelihood fit")
    p.add_argument("--format", choices=FORMATS, default=None,
                   help="pose file format (default: from the extension)")
    p.add_argument("--camera-pose-is-camera-in-target", action="store_true",
                   help="the camera file holds X_TC instead of X_CT")
    from .calibrate.command import _time_offset_arg
    p.add_argument("--time-offset", type=_time_offset_arg, default=None, metavar="auto|SECONDS",
                   help="camera stamp − robot time of the same instant (default: estimated, as "
                        "calibrate does, when both files have timestamps; else 0)")
    p.add_argument("--translation-scale", type=float, default=1.0, metavar="FACTOR",
                   help="multiply every translation read from files (0.001 for millimetres)")
    src = p.add_argument_group("candidate poses (one of)")
    src.add_argument("--candidates", metavar="FILE",
                     help="candidate robot poses X_BE (any pose format, e.g. reachable poses)")
    src.add_argument("--around", metavar="POSE",
                     help="sample candidates around this X_BE (x,y,z,qx,qy,qz,qw)")
    p.add_argument("--max-angle", type=_angle_up_to_180, default=30.0, metavar="DEG",
                   help="--around: largest rotation from POSE (default 30)")
    p.add_argument("--max-distance", type=positive_float, default=0.1, metavar="METRES",
                   help="--around: largest flange displacement from POSE (default 0.1)")
    p.add_argument("--num-candidates", type=int_up_to(100_000, "each costs about 0.5 ms"),
                   default=None, metavar="N",
                   help="--around: candidates to sample (default 500, at most 100 000); "
                        "--feasible: verified candidates to find (default 60)")
    p.add_argument("--seed", type=int, default=0, help="--around: random seed (default 0)")
    p.add_argument("--hand-eye", metavar="POSE",
                   help="rough X_EC (X_BC for eye-to-hand), x,y,z,qx,qy,qz,qw; needed without "
                        "--camera")
    p.add_argument("--target", metavar="POINT",
                   help="target position in the base (on the flange, in E, for eye-to-hand), "
                        "x,y,z; needed without --camera")
    p.add_argument("--intrinsics", metavar="SPEC|FILE",
                   help="camera intrinsics, as for calibrate (an OpenCV or ROS camera_info "
                        "YAML) or fx,fy,cx,cy,W,H (pixels): keep only candidates with the target "
                        "in view")
    p.add_argument("--noise", type=positive_deg_mm, default=None, metavar="DEG,MM",
                   help="camera pose noise per axis, rotation (deg) and translation (mm), as "
                        "calibrate's --max-noise and --robot-accuracy are written (default: from "
                        f"the fit with --camera, else {DEFAULT_ROTATION_SIGMA_DEG:g},"
                        f"{1000 * DEFAULT_TRANSLATION_SIGMA:g})")
    p.add_argument("--fix", metavar="NAME=VALUE,…",
                   help="hand-eye components known (tx,ty,tz in m or tx_mm…, roll,pitch,yaw in "
                        "rad or roll_deg…, of X_EC / X_BC): e.g. tz=0.052 for a SCARA")
    p.add_argument("--mode", choices=("eye-in-hand", "eye-to-hand"), default="eye-in-hand",
                   type=lambda s: s.replace("_", "-"),
                   help="eye-in-hand (camera on the flange, default) or eye-to-hand, as for "
                        "calibrate")
    p.add_argument("--n", type=int, default=5, help="number of poses to suggest (default 5)")
    p.add_argument("--robot-accuracy", default="0.03,0.3", metavar="DEG,MM",
                   help="the robot's pose accuracy per axis (default 0.03,0.3, as calibrate and "
                        "session): the floor it puts under σ is printed")
    p.add_argument("--target-sigma", default=None, metavar="DEG,MM",
                   help="the σ the session will be asked for: refused when below that floor")
    p.add_argument("--out", default="out/plan", metavar="DIR",
                   help="output directory (default out/plan); an existing one must be empty or "
                        "hold this command's earlier output")
    p.add_argument("--force", action="store_true",
                   help="write into a non-empty --out that is not this command's output "
                        "(never overwriting files the tool did not write)")
    from .plan_feasible import add_arguments
    add_arguments(p)
    p.set_defaults(func=run_plan)
    return p


"""``handeye-drake session``: a live calibration that says what to record next and when to stop.

    handeye-drake session --simulate --out out/session      (no hardware: docs/session.md)
    handeye-drake session --samples FILE|- [--follow] --target-sigma 0.1,1.0
    handeye-drake session --bag BAG [--follow] --robot-frames base_link:tool0
                          (--camera-topic TOPIC | --camera-frames CAM:TARGET | --image-topic TOPIC)
                          [--candidates FILE | --feasible] [--hand-eye POSE --target POSE]
                          [--mode eye-in-hand] [--state FILE [--resume]] [--out DIR]

A thin command around ``calibration.session.CalibrationSession``. Each input line is one sample:

- 14 numbers ``x y z qx qy qz qw  x y z qx qy qz qw`` (commas or spaces): X_BE (flange in base)
  then X_CT (target in camera), metres, quaternion scalar last; 15 numbers: a timestamp first;
- or a JSON object ``{"X_BE": [x,y,z,qx,qy,qz,qw] or 4×4, "X_CT": ... }``, or with ``"image":
  PATH`` instead of X_CT (``--target-spec`` and ``--intrinsics`` then needed).

``#`` starts a comment. ``--follow`` keeps reading a growing file (a driver appending to it) until
stop or ``--idle-timeout`` (``--timeout-s``) seconds without a new line; a last line without its
newline waits for it, and the lines available at a poll are fitted once together.
``--simulate``: a simulated UR5e with a rendered camera (``apps.session_simulate``) executes
each suggested pose and appends its line to ``--out``/samples.txt, read by the same reader.

The lines are checked as ``calibrate`` checks pose files (swapped or inverted streams,
quaternion order, units, clock offset): which column is the robot's is told by the poses the
session asked for or by ``--hand-eye`` (the rough mount); without either a swap is a tie and the
session does not stop. ``--target-sigma`` must be above the floor ``--robot-accuracy`` puts
under σ (printed at the start; at or below it: exit 2).

``--bag``: the samples of a ROS bag (``recorded.bag_follow.BagFollower``): each camera message
(a pose topic, a tf pair, or an image with ``--target-spec``; intrinsics from ``--intrinsics`` or
the bag's CameraInfo) with the robot pose from tf interpolated at its stamp; the batch takes the
whole tf stream and estimates the clock offset as ``calibrate`` does. With ``--follow`` the bag
is polled every ``--poll-s`` while the recorder writes it (ROS 2 sqlite3 or MCAP storage; a ROS 1
bag once it is closed), until stop or ``--idle-timeout`` seconds without a new sample. After
each fit one line: σ (deg, mm; tool and 0.5 m in front, mm), the verdict so far, the next pose
(with ``--candidates``: the D-optimal best of those poses; with ``--feasible``: a reachable,
collision-free pose from Drake's IK for the shipped UR5e or ``--urdf``). At stop,
``calibration.json`` is written into ``--out``. ``--state`` must be new or a session state.

Exit status: 0 stop (σ at the target, verdict OK); 1 the input ended before that; 2 bad input.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from ..calibration.api import CalibrationOptions
from ..calibration.session import (CalibrationSession, CandidatePoses, is_session_state,
                                   sigma_floor)
from ..estimation.se3 import quat_wxyz, rotation_angle
from ..recorded.formats import read_poses
from .outputs import prepare_output_dir
from .argtypes import positive_float, positive_int
from .pose_args import _numbers, parse_intrinsics, parse_pose


def _pose(value, what: str) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.shape == (4, 4):
        return a
    if a.shape == (7,):
        return parse_pose(",".join(repr(float(x)) for x in a), what)
    raise ValueError(f"{what}: expected 7 numbers (x,y,z,qx,qy,qz,qw) or a 4×4 matrix")


def parse_sample(line: str, where: str) -> dict | None:
    """One input line → {X_BE, X_CT | image, stamp}; None for blank and comment lines."""
    text = line.split("#", 1)[0].strip()
    if not text:
        return None
    if text.startswith("{"):
        try:
            d = json.loads(text)
        except json.JSONDecodeError as e:
            raise ValueError(f"{where}: not valid JSON ({e.msg})") from None
        if "X_BE" not in d or ("X_CT" in d) == ("image" in d):
            raise ValueError(f"{where}: expected X_BE with X_CT or image")
        out = {"X_BE": _pose(d["X_BE"], f"{where}: X_BE"), "stamp": d.get("stamp")}
        if "X_CT" in d:
            out["X_CT"] = _pose(d["X_CT"], f"{where}: X_CT")
        else:
            out["image"] = str(d["image"])
        return out
    v = _numbers(text, where, (14, 15))
    stamp = float(v[0]) if len(v) == 15 else None
    v = v[-14:]
    return {"X_BE": _pose(v[:7], f"{where}: X_BE"), "X_CT": _pose(v[7:], f"{where}: X_CT"),
            "stamp": stamp}


class LineReader:
    """Complete lines of a (growing) sample file: ``read()`` returns every line complete now,
    as (line, where); a last line without its newline waits for the next read (a driver may
    be writing it) unless ``final``."""

    def __init__(self, path: Path):
        self.path = path
        self.fh = path.open(encoding="utf-8")
        self.k = 0
        self.buf = ""

    #: Longest sample line read (characters): a sample is a few hundred; a file without
    #: newlines (a binary, an image) is not read whole into memory.
    MAX_LINE = 1_000_000

    def read(self, final: bool = False) -> list:
        out = []
        while True:
            try:
                chunk = self.fh.readline(self.MAX_LINE)
            except UnicodeDecodeError:
                raise ValueError(f"--samples {self.path}: line {self.k + 1} is not UTF-8 text "
                                 "(not a sample file?)") from None
            if not chunk:
                break
            self.buf += chunk
            if len(self.buf) >= self.MAX_LINE:
                raise ValueError(f"--samples {self.path}: line {self.k + 1} is longer than "
                                 f"{self.MAX_LINE} characters (not a sample file?)")
            if self.buf.endswith("\n"):
                self.k += 1
                out.append((self.buf, f"{self.path.name} line {self.k}"))
                self.buf = ""
        if final and self.buf:
            self.k += 1
            out.append((self.buf, f"{self.path.name} line {self.k}"))
            self.buf = ""
        return out

    def close(self):
        self.fh.close()


def _line_batches(args, driver=None, pending=None):
    """Lists of (line, where) from --samples: with --follow, every complete line available at
    each poll (the session fits once per list: samples arriving faster than a fit are
    batched), until --idle-timeout; without, one line at a time. ``driver`` (``--simulate``)
    is asked to execute ``pending()`` (the session's next pose) before each read."""
    if args.samples == "-":
        for k, line in enumerate(sys.stdin, start=1):
            yield [(line, f"stdin line {k}")]
        return
    path = Path(args.samples)
    if path.is_dir():
        raise ValueError(f"--samples {args.samples}: a folder; expected the samples file")
    if not path.is_file():
        raise ValueError(f"--samples: file not found: {args.samples!r}")
    reader = LineReader(path)
    try:
        if not args.follow:
            for item in reader.read(final=True):
                yield [item]
            return
        idle = time.monotonic()
        while True:
            if driver is not None:
                pose = pending()
                if pose is None:
                    return                  # the planner has no pose left
                driver.execute(pose)
            lines = reader.read()
            if lines:
                idle = time.monotonic()
                yield lines
                continue
            if driver is None and time.monotonic() - idle > args.idle_timeout:
                rest = reader.read(final=True)
                if rest:
                    yield rest
                return
            if driver is None:
                time.sleep(0.1)
    finally:
        reader.close()


def _bag_samples(args, on_poll):
    """Lists of (sample, where) from --bag, polling a growing bag with --follow;
    ``on_poll(follower)`` after each poll (the robot's whole stream, the CameraInfo)."""
    from ..recorded.bag_follow import BagFollower
    if args.poll_s <= 0:
        raise ValueError(f"--poll-s: must be > 0, got {args.poll_s}")
    follower = BagFollower(args.bag, args.robot_frames, camera_topic=args.camera_topic,
                           camera_frames=args.camera_frames, image_topic=args.image_topic,
                           camera_invert=args.camera_invert,
                           camera_info_topic=args.camera_info_topic,
                           must_exist=not args.follow)
    idle = time.monotonic()
    reported = 0
    while True:
        new = follower.poll()
        on_poll(follower)
        for where, why in follower.dropped[reported:]:
            print(f"{where}: no sample ({why})", file=sys.stderr)
        reported = len(follower.dropped)
        if new:
            yield [(sample, sample["where"]) for sample in new]
            idle = time.monotonic()
        if not args.follow:
            if follower.last_error and not new and reported == 0:
                raise ValueError(f"--bag: {follower.last_error}")
            return
        if time.monotonic() - idle > args.idle_timeout:
            why = f" (last: {follower.last_error})" if follower.last_error else ""
            print(f"--bag: no new sample for {args.idle_timeout:g} s{why}", file=sys.stderr)
            return
        time.sleep(args.poll_s)


def _next_text(pose) -> str:
    if pose is None:
        return ""
    X = np.asarray(pose["X_BE"])
    q = quat_wxyz(X[:3, :3])
    s = (f"  next: X_BE {','.join(f'{x:.4f}' for x in X[:3, 3])},"
         f"{q[1]:.6f},{q[2]:.6f},{q[3]:.6f},{q[0]:.6f}")
    if pose.get("q") is not None:
        s += "  q [" + " ".join(f"{x:+.4f}" for x in np.asarray(pose["q"])) + "] rad"
    return s


def _planner(args, mode):
    if args.candidates and args.feasible:
        raise ValueError("--candidates and --feasible: give one source of next poses")
    if not (args.candidates or args.feasible):
        return None
    if args.hand_eye is None or args.target is None:
        raise ValueError("--hand-eye and --target: the next poses need the rough camera pose "
                         "and the target pose")
    X_H = parse_pose(args.hand_eye, "--hand-eye")
    from .plan_feasible import parse_target_pose
    X_F = parse_target_pose(args.target, mode)
    if args.candidates:
        cands = read_poses(args.candidates, "robot").poses
        return CandidatePoses(cands, X_H, X_F, mode)
    from ..planning import FeasiblePlanner, ViewSpec, as_session_planner
    points = None
    if args.board:
        w, h = _numbers(args.board, "--board", (2,))
        if w <= 0 or h <= 0:
            raise ValueError(f"--board: expected WIDTH,HEIGHT > 0 (m), got {args.board!r}")
        points = np.array([[x, y, 0.0] for x in (0, w) for y in (0, h)])
    view = ViewSpec(intrinsics=parse_intrinsics(args.intrinsics) if args.intrinsics else None,
                    target_points=points)
    planner = FeasiblePlanner(mode, X_H, X_F, urdf=args.urdf, view=view, seed=args.seed)
    cands = planner.sample_candidates(args.num_candidates)
    print(f"planner: {len(cands)} reachable, collision-free views from {cands.attempts} IK "
          "problems")
    return as_session_planner(planner, cands)


def _check_state(args, out) -> None:
    """--state FILE may only be a session state this tool wrote (or new): never the samples
    being read, a directory, or another file (unless --force)."""
    if not args.state:
        return
    p = Path(args.state)
    if p.is_dir():
        raise ValueError(f"--state {args.state}: is a directory; give a file name")
    if args.samples not in (None, "-") and p.exists() and p.resolve() == Path(
            args.samples).resolve():
        raise ValueError(f"--state {args.state}: is the --samples file; the state would "
                         "overwrite the recording — give another file")
    if args.resume or not p.exists() or args.force:
        return
    if not is_session_state(p):
        raise ValueError(f"--state {args.state}: exists and is not a session state written by "
                         "this tool; not overwriting it (give a new file, --resume a session, "
                         "or --force)")


def floor_line(sigma, acc, X_H=None) -> str:
    """The σ floor of --robot-accuracy ``acc`` (deg, mm per axis) as one line; ValueError
    naming --target-sigma when ``sigma`` (deg, mm; None: no target) is at or below it."""
    floor = sigma_floor(None if not any(acc) else (float(acc[0]), float(acc[1]) / 1000.0), X_H)
    text = f"{acc[0]:g},{acc[1]:g}"
    if sigma is not None:
        for k, unit in ((0, "°"), (1, " mm")):
            if sigma[k] <= floor[k]:
                raise ValueError(
                    f"--target-sigma: {sigma[k]:g}{unit} is below the floor {floor[k]:.3g}{unit} "
                    f"that --robot-accuracy {text} (deg,mm per axis, constant over the "
                    f"recording) puts under σ; no number of samples reaches it: ask for more "
                    f"than {floor[k]:.3g}{unit}, or give the robot's measured accuracy")
    return (f"σ floor of --robot-accuracy {text}: {floor[0]:.3g}° / {floor[1]:.3g} mm"
            + ("" if sigma is None else
               f" (the target {sigma[0]:g}° / {sigma[1]:g} mm is above it)"))


def run_session(args) -> int:
    mode = args.mode.replace("-", "_")
    sigma = _numbers(args.target_sigma, "--target-sigma", (2,))
    if not np.all(sigma > 0):
        raise ValueError(f"--target-sigma: expected DEG,MM > 0, got {args.target_sigma!r}")
    acc = _numbers(args.robot_accuracy, "--robot-accuracy", (2,))
    if not np.all(acc >= 0):
        raise ValueError(f"--robot-accuracy: expected DEG,MM ≥ 0, got {args.robot_accuracy!r}")
    if args.resume and not args.state:
        raise ValueError("--resume: needs --state FILE")
    if sum(x is not None and x is not False for x in (args.samples, args.bag,
                                                       args.simulate)) != 1:
        raise ValueError("--samples / --bag / --simulate: give one source of samples")
    if args.bag is None and (args.camera_topic or args.camera_frames or args.image_topic):
        raise ValueError("--camera-topic / --camera-frames / --image-topic: only with --bag")
    if args.bag is not None and sum(x is not None for x in (
            args.camera_topic, args.camera_frames, args.image_topic)) != 1:
        raise ValueError("--bag: give one camera source: --camera-topic, --camera-frames or "
                         "--image-topic")
    if args.idle_timeout <= 0:
        raise ValueError(f"--idle-timeout: must be > 0, got {args.idle_timeout}")
    if args.simulate and (args.candidates or args.feasible or args.resume):
        raise ValueError("--simulate: plans its own poses on the simulated cell; drop "
                         "--candidates / --feasible / --resume")
    if args.max_samples is not None and args.max_samples < 1:
        raise ValueError(f"--max-samples: must be ≥ 1, got {args.max_samples}")
    out = prepare_output_dir(args.out, "session", args.force)
    _check_state(args, out)
    driver = None
    X_guess = parse_pose(args.hand_eye, "--hand-eye") if args.hand_eye else None
    if args.simulate:
        from .session_simulate import SimulatedCell, SimulatedDriver, simulated_planner
        cell = SimulatedCell()
        X_guess = cell.X_EC_guess
        if args.max_samples is None:
            args.max_samples = 40
        args.samples, args.follow = str(out.path("samples.txt")), True
        t0 = time.monotonic()
        _, pool, next_pose = simulated_planner(cell, args.num_candidates, args.seed)
        print(f"simulated cell: UR5e, camera on the flange (true mount unknown to the session), "
              f"{cell.target_spec} board at x,y {cell.X_BT[0, 3]:g},{cell.X_BT[1, 3]:g} m; "
              f"{len(pool)} reachable views planned in {time.monotonic() - t0:.1f} s; samples "
              f"appended to {args.samples}")
        driver = SimulatedDriver(args.samples, cell, seed=args.seed,
                                 supersample=args.supersample)
    else:
        next_pose = _planner(args, mode)
    if args.resume:
        try:
            session = CalibrationSession.resume(args.state, next_pose)
        except ValueError as e:  # the library names its argument "state"
            msg = str(e)
            raise ValueError("--" + msg if msg.startswith("state: ") else msg) from None
        if session.mode != mode:
            raise ValueError(f"--mode: the saved session is {session.mode}, not {mode}")
        print(f"resumed {len(session.X_BE)} samples from {args.state}")
        if session.last is not None:
            print(session.last.line())
    else:
        options = CalibrationOptions(mode=mode, robot_accuracy_deg=float(acc[0]),
                                     robot_accuracy_mm=float(acc[1]))
        print(floor_line(sigma, acc, X_guess))
        session = CalibrationSession(float(sigma[0]), float(sigma[1]), options, next_pose,
                                     max_samples=args.max_samples, hand_eye_guess=X_guess)
    pending = {"pose": session.ask_pose(), "used": False}
    if pending["pose"] is not None:
        print("start:" + _next_text(pending["pose"]))

    def next_for_driver():
        if pending["used"]:          # executed, no sample back (a lost view): another pose
            pending["pose"] = session.ask_pose()
        pending["used"] = True
        return pending["pose"]

    target = intrinsics = None
    if args.target_spec:
        from ..vision.targets import parse_target
        target = parse_target(args.target_spec)
    if args.intrinsics:
        intrinsics = parse_intrinsics(args.intrinsics)
    step = session.last
    if args.image_topic and target is None:
        raise ValueError("--image-topic: image samples need --target-spec")
    info_said = []

    def on_poll(follower):
        nonlocal intrinsics
        # The whole tf stream: the batch estimates the clock offset from it, as calibrate.
        session.robot_stream = follower.robot
        if intrinsics is None and follower.camera_info is not None and not info_said:
            intrinsics = follower.camera_info.intrinsics(
                f"--camera-info-topic {follower.camera_info_from}")
            info_said.append(1)
            print(f"intrinsics from the CameraInfo on {follower.camera_info_from}")

    if args.bag:
        source = _bag_samples(args, on_poll)
    else:
        source = ([(parse_sample(line, where), where) for line, where in batch]
                  for batch in _line_batches(args, driver, next_for_driver))
    for batch in source:
        added = 0
        for sample, where in batch:
            if sample is None:
                continue
            if "image" in sample:
                if target is None or intrinsics is None:
                    raise ValueError(f"{where}: an image sample needs --target-spec and "
                                     "--intrinsics (or the bag's CameraInfo)")
                img = sample["image"]
                if isinstance(img, str):
                    import cv2
                    img = cv2.imread(sample["image"], cv2.IMREAD_GRAYSCALE)
                    if img is None:
                        raise ValueError(f"{where}: cannot read the image {sample['image']!r}")
                session.add(sample["X_BE"], image=img, target=target, intrinsics=intrinsics,
                            stamp=sample["stamp"], evaluate=False)
            else:
                try:
                    session.add(sample["X_BE"], sample["X_CT"], stamp=sample["stamp"],
                                evaluate=False)
                except ValueError as e:
                    raise ValueError(f"{where}: {e}") from None
            added += 1
        if not added:
            continue
        step = session.evaluate()       # one fit for every sample that arrived together
        pending["pose"], pending["used"] = step.next_pose, False
        print(step.line() + (f" (+{added} samples)" if added > 1 else "")
              + _next_text(step.next_pose), flush=True)
        if args.state:
            session.save(args.state)
        if step.stop:
            break
        if args.max_samples is not None and len(session.X_BE) >= args.max_samples:
            break
    files = []
    if driver is not None:
        files.append(out.path("samples.txt"))
        print(f"simulated driver: {driver.frames} frames rendered, {driver.lost} views without "
              "the board")
    if step is not None and step.stop:
        from ..calibration.report import write_json
        files.append(write_json(session.result, out.path("calibration.json")))
        X = session.result.X_hand
        q = quat_wxyz(X[:3, :3])
        name = "X_EC" if mode == "eye_in_hand" else "X_BC"
        print(f"calibrated after {len(session.X_BE)} samples: {name} "
              f"{','.join(f'{x:.5f}' for x in X[:3, 3])},{q[1]:.6f},{q[2]:.6f},{q[3]:.6f},"
              f"{q[0]:.6f}; verdict {session.result.verdict.status}"
              + ("" if session.result.time_offset is None else
                 f"; clock offset {session.result.aligned.time_offset:+.5f} s (camera stamp − "
                 "robot time, estimated)"))
        if driver is not None:
            X_true = driver.cell.X_EC
            rot = np.degrees(rotation_angle(X[:3, :3].T @ X_true[:3, :3]))
            tra = 1000 * np.linalg.norm(X[:3, 3] - X_true[:3, 3])
            print(f"simulated truth: error {rot:.3f}° / {tra:.2f} mm, σ "
                  f"{step.rotation_sigma_deg:.3f}° / {step.translation_sigma_mm:.2f} mm")
    p = out.path("session_steps.json")
    p.write_text(json.dumps({"samples": len(session.X_BE), "stop": bool(step and step.stop),
                             "last": None if step is None else step.to_dict()}, indent=1) + "\n")
    files.append(p)
    out.finish(files)
    if step is None or not step.stop:
        n = len(session.X_BE)
        print(f"input ended after {n} samples before the σ target "
              f"{sigma[0]:g}° / {sigma[1]:g} mm was reached with verdict OK"
              + (f" (last verdict {step.verdict}: {step.message})" if step is not None
                 and step.verdict else ""), file=sys.stderr)
        return 1
    return 0


def add_parser(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "session", help="live calibration: next pose after each sample, stop when good enough",
        description="Reads samples one by one (a file, a growing file with --follow, or stdin) "
                    "and after each prints the estimate's σ, the verdict so far and the next "
                    "pose; stops when σ reaches --target-sigma with verdict OK.")
    p.add_argument("--samples", metavar="FILE",
                   help="sample lines (see the module help), '-' for stdin")
    p.add_argument("--bag", metavar="PATH", help="samples from a ROS bag (ROS 2 directory, "
                   ".db3, .mcap; a finished ROS 1 .bag); with --follow, one being recorded")
    p.add_argument("--simulate", action="store_true",
                   help="no hardware: a simulated UR5e with a rendered camera executes each "
                        "suggested pose and appends its sample line to --out/samples.txt, which "
                        "the session reads like a real driver's file")
    p.add_argument("--max-samples", type=int, default=None, metavar="N",
                   help="end the session after N samples (default: no limit; --simulate 40)")
    p.add_argument("--supersample", type=positive_int, default=2, metavar="N",
                   help="--simulate: the renderer's anti-aliasing factor (default 2)")
    p.add_argument("--follow", action="store_true",
                   help="keep reading the file (or --bag) as it grows (until stop or "
                        "--idle-timeout)")
    p.add_argument("--idle-timeout", "--timeout-s", dest="idle_timeout", type=positive_float,
                   default=60.0, metavar="SECONDS",
                   help="--follow: give up after this long without a new sample (default 60)")
    b = p.add_argument_group("ROS bags (--bag)")
    b.add_argument("--robot-frames", default="base_link:tool0", metavar="BASE:EE",
                   help="X_BE from /tf and /tf_static (default base_link:tool0)")
    b.add_argument("--camera-topic", metavar="TOPIC", help="X_CT poses (PoseStamped, "
                   "PoseWithCovarianceStamped or TransformStamped)")
    b.add_argument("--camera-frames", metavar="CAMERA:TARGET", help="X_CT from tf")
    b.add_argument("--camera-invert", action="store_true",
                   help="the camera topic (frames) hold X_TC, the camera in the target")
    b.add_argument("--image-topic", metavar="TOPIC", help="images of the board (Image or "
                   "CompressedImage; with --target-spec and --intrinsics)")
    b.add_argument("--camera-info-topic", metavar="TOPIC",
                   help="--image-topic: the CameraInfo (default: camera_info beside the image "
                        "topic, as calibrate; 'none' to ignore it); --intrinsics overrides it")
    b.add_argument("--poll-s", type=positive_float, default=0.5, metavar="SECONDS",
                   help="--follow: how often to re-read the bag (default 0.5)")
    p.add_argument("--target-sigma", default="0.1,1.0", metavar="DEG,MM",
                   help="stop when the hand-eye σ (RMS radius) is at most DEG and MM (default "
                        "0.1,1.0; it must be above the floor --robot-accuracy puts under σ, "
                        "≈ √3 × the accuracy)")
    p.add_argument("--robot-accuracy", default="0.03,0.3", metavar="DEG,MM",
                   help="the robot's pose accuracy added to the σ (default 0.03,0.3)")
    p.add_argument("--mode", choices=("eye-in-hand", "eye-to-hand"), default="eye-in-hand",
                   type=lambda s: s.replace("_", "-"),
                   help="eye-in-hand (camera on the flange) or eye-to-hand, as for calibrate")
    g = p.add_argument_group("next poses")
    g.add_argument("--candidates", metavar="FILE", help="poses X_BE the robot can reach (any "
                   "pose format): the next is the D-optimal best of the unvisited ones")
    g.add_argument("--feasible", action="store_true",
                   help="reachable, collision-free poses from Drake's IK (shipped UR5e or "
                        "--urdf, floor at z = 0)")
    g.add_argument("--urdf", default=None, metavar="FILE", help="--feasible: robot model")
    g.add_argument("--num-candidates", type=positive_int, default=60, metavar="N",
                   help="--feasible: views to generate (default 60)")
    g.add_argument("--seed", type=int, default=0, help="--feasible: random seed")
    g.add_argument("--board", metavar="WIDTH,HEIGHT",
                   help="--feasible: the board's size (m) from the target origin along x and y, "
                        "its corners kept in the image (with --intrinsics)")
    g.add_argument("--hand-eye", metavar="POSE", help="rough X_EC (X_BC eye-to-hand), "
                   "x,y,z,qx,qy,qz,qw (also tells the robot's column from the camera's when "
                   "the data fit both alike)")
    g.add_argument("--target", metavar="POSE", help="target pose X_BT (X_ET eye-to-hand), "
                   "x,y,z[,qx,qy,qz,qw]")
    p.add_argument("--target-spec", metavar="SPEC",
                   help="the board of image samples (e.g. chessboard:9x6:0.0236)")
    p.add_argument("--intrinsics", metavar="fx,fy,cx,cy,W,H", help="camera intrinsics (pixels)")
    p.add_argument("--state", metavar="FILE", help="save the session state (JSON) after each "
                   "sample (a new file or an earlier session's state; never another file)")
    p.add_argument("--resume", action="store_true", help="continue the session saved in --state")
    p.add_argument("--out", default="out/session", metavar="DIR",
                   help="output directory (default out/session)")
    p.add_argument("--force", action="store_true",
                   help="write into a non-empty --out that is not this command's output")
    p.set_defaults(func=run_session)
    return p

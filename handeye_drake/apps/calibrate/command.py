"""``handeye-drake calibrate``: the command line of the recorded-data calibration.

    handeye-drake calibrate --robot FILE --camera FILE [...]                 pose files
    handeye-drake calibrate --bag PATH --robot-frames B:E --camera-topic T    a ROS bag
    handeye-drake calibrate --bag PATH --image-topic T --target SPEC          its images
    handeye-drake calibrate --images PATH... --robot FILE --target SPEC      images of a target

Exit status: 0 (verdict OK or WARN), 1 (verdict FAIL — ``calibration.json`` is still written
with the reasons; nothing is exported — or WARN under ``--strict``), 2 (bad input).
"""

from __future__ import annotations

import argparse
import math

from ...estimation.solvers import METHODS
from ...recorded.formats import FORMAT_NAMES, MAX_TRANSLATION
from ..argtypes import non_negative_deg_mm, positive_deg_mm, positive_float
from ..outputs import prepare_output_dir
from ...calibration.api import DEFAULT_ROBOT_ACCURACY, CalibrationOptions, read_inputs, solve
from ...calibration.corners import REFINE_CHOICES
from ...calibration.inputs import DEFAULT_MAX_IMAGES, QUATERNION_ORDERS
from ...calibration.report import table, write_json

DEFAULT_OUT = "out/calibrate"


def _time_offset_arg(text: str):
    if text == "auto":
        return "auto"
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected 'auto' or seconds, got {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
    return v




def _max_images_arg(text: str):
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if v != 0 and v < 3:
        raise argparse.ArgumentTypeError(f"expected 0 (all) or at least 3, got {text!r}")
    return v or None


def _format_arg(text: str):
    from ...recorded.formats import check_format
    try:
        return check_format(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _formats_arg(text: str):
    from ...recorded.exports import parse_formats
    try:
        return parse_formats(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


class _CameraArg(argparse.Action):
    """``--camera FILE`` (the last one given), or repeated ``--camera NAME:DIR…`` of a rig
    (``rig_command``), collected in ``rig_cameras``."""

    def __call__(self, parser, namespace, value, option_string=None):
        from .rig_command import is_rig_camera
        if is_rig_camera(value):
            namespace.rig_cameras = list(getattr(namespace, "rig_cameras", None) or []) + [value]
        else:
            setattr(namespace, self.dest, value)


def add_parser(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "calibrate", help="hand-eye calibration from recorded robot and camera data",
        description="Estimate X_EC (camera in end-effector; X_BC for eye-to-hand) from a robot "
                    "stream (X_BE, end-effector in base) and camera measurements (X_CT, target "
                    "in camera) given as pose files, a ROS bag or images of a calibration "
                    "target; print a verdict (OK / WARN / FAIL) that says whether the result "
                    "can be trusted and why not.")
    src = p.add_argument_group("inputs (one of: --robot with --camera, --bag, --images)")
    src.add_argument("--robot", metavar="FILE", help="robot poses X_BE (end-effector in base)")
    src.add_argument("--camera", metavar="FILE | NAME:DIR[:MOUNT[:INTRINSICS]]",
                     action=_CameraArg,
                     help="camera poses X_CT (target in camera); or, repeated, the cameras of a "
                          "rig calibrated jointly: NAME:DIR of its images (image k with robot "
                          "pose k), MOUNT hand (X_EC, default) or cell (X_BC), its intrinsics")
    src.add_argument("--rig", metavar="YAML",
                     help="a multi-camera rig described in a YAML file (robot, target, board, "
                          "cameras: see docs/multi-camera.md)")
    src.add_argument("--board-mount", choices=("cell", "hand"), default=None,
                     help="rig: where the board is — cell (X_BT, default) or hand (X_ET)")
    src.add_argument("--board", metavar="NAME:SPEC[:cell|hand]", action="append",
                     dest="boards", default=None,
                     help="rig: one of several boards, repeated: its name, its target spec "
                          "(as --target) and where it is — cell (X_BT, default) or hand (X_ET); "
                          "boards must differ in their markers (docs/multi-camera.md)")
    src.add_argument("--bag", metavar="PATH",
                     help="ROS 1 .bag, ROS 2 bag directory, .db3 or .mcap (read without ROS)")
    src.add_argument("--images", nargs="+", metavar="PATH",
                     help="images of the target: files, directories or globs, paired with the "
                          "poses of --robot in order (one each): each argument's files in "
                          "natural file-name order, the arguments in the order given; or in "
                          "time when every image has a stamp (--pairing)")
    fmt = p.add_argument_group("reading")
    fmt.add_argument("--pairing", choices=("auto", "index", "time"), default="auto",
                     help="how images (--images, rig folders) pair with the robot poses: time "
                          "(each image's stamp from its file name or the folder's "
                          "timestamps.txt / times.csv, the robot pose interpolated there, the "
                          "clock offset estimated), index (image k with pose k), or auto "
                          "(default: time when every image has a stamp and the robot's stamps "
                          "are times; docs/multi-camera.md)")
    fmt.add_argument("--format", type=_format_arg, default=None, metavar="FORMAT",
                     help=f"pose file format: {', '.join(FORMAT_NAMES)} (default: from the "
                          "extension: .tum/.txt, .csv, .yaml/.yml). csv-rotvec: x y z rx ry rz "
                          "(UR: rotation vector, rad); csv-euler:ORDER:UNIT: x y z a1 a2 a3, "
                          "turns a1 a2 a3 about the axes of ORDER in turn — lowercase extrinsic "
                          "(fixed axes), UPPERCASE intrinsic (turning axes), as scipy's "
                          "Rotation.from_euler; UNIT deg|rad. KUKA X Y Z A B C: csv-euler:ZYX:deg, "
                          "Fanuc X Y Z W P R: csv-euler:xyz:deg (both mm: --translation-scale "
                          "0.001). Both take an optional leading timestamp")
    for which in ("robot", "camera"):
        fmt.add_argument(f"--{which}-format", type=_format_arg, default=None, metavar="FORMAT",
                         help=f"the {which} file's format, overriding --format (e.g. a KUKA "
                         "robot file with a TUM camera file)")
    fmt.add_argument("--camera-pose-is-camera-in-target", action="store_true",
                     help="the camera poses are X_TC (camera in target), not X_CT")
    for which in ("robot", "camera"):
        fmt.add_argument(f"--{which}-quaternion-order", choices=QUATERNION_ORDERS,
                         default="xyzw", help=f"quaternion order of the {which} TUM file "
                         "(TUM is x y z w; some tools write w x y z)")
    fmt.add_argument("--translation-scale", type=positive_float, default=None, metavar="F",
                     help="multiply every translation of both files (0.001 for millimetres)")
    for which in ("robot", "camera"):
        fmt.add_argument(f"--{which}-translation-scale", type=positive_float, default=None,
                         metavar="F", help=f"multiply the {which} file's translations")
    fmt.add_argument("--max-translation", type=positive_float, default=MAX_TRANSLATION,
                     metavar="METRES", help=f"refuse translations longer than this (default "
                     f"{MAX_TRANSLATION:g}; a units check)")
    fmt.add_argument("--time-scale", type=positive_float, default=1.0, metavar="F",
                     help="multiply every timestamp (1e-9 for nanoseconds, 1e-3 for ms)")
    bag = p.add_argument_group("ROS bags")
    bag.add_argument("--robot-frames", default="base_link:tool0", metavar="BASE:EE",
                     help="X_BE = pose of EE in BASE from /tf and /tf_static "
                          "(default base_link:tool0)")
    cam = bag.add_mutually_exclusive_group()
    cam.add_argument("--camera-topic", metavar="TOPIC",
                     help="PoseStamped / PoseWithCovarianceStamped / TransformStamped topic "
                          "holding X_CT (X_TC with --camera-pose-is-camera-in-target)")
    cam.add_argument("--camera-frames", metavar="CAMERA:TARGET",
                     help="X_CT from tf: the pose of TARGET in CAMERA, whichever way the tf "
                          "tree links them")
    cam.add_argument("--image-topic", metavar="TOPIC",
                     help="sensor_msgs Image or CompressedImage topic: X_CT from the --target "
                          "detected in each image, at its header stamp")
    bag.add_argument("--camera-info-topic", metavar="TOPIC|none",
                     help="--image-topic: CameraInfo with the intrinsics (default: camera_info "
                          "beside the image topic; none: calibrate them from the images); "
                          "--intrinsics overrides it")
    bag.add_argument("--max-images", type=_max_images_arg, default=DEFAULT_MAX_IMAGES,
                     metavar="N", help=f"--image-topic: read at most N images, evenly spaced "
                     f"over the bag (default {DEFAULT_MAX_IMAGES}; 0: all)")
    img = p.add_argument_group("images")
    img.add_argument("--target", metavar="SPEC",
                     help="the target: chessboard:9x6:0.0236, charuco:5x7:0.036:0.018:"
                          "DICT_6X6_250[:legacy], apriltag:36h11:0.048[:ID], "
                          "acircles:7x11:0.02[:DIAMETER][:white], circles:…, ... (docs/targets.md)")
    img.add_argument("--intrinsics", metavar="SPEC|FILE",
                     help="fx,fy,cx,cy[,k1,k2,p1,p2[,k3]], an OpenCV YAML/XML file or a ROS "
                          "camera_info YAML (default: a bag's CameraInfo, else calibrated from "
                          "the images)")
    img.add_argument("--refine-intrinsics", choices=REFINE_CHOICES, default="auto",
                     help="intrinsics refined jointly with the hand-eye transform in the "
                          "corner-level fit: none, focal (fx, fy together), pinhole (fx fy cx "
                          "cy), k1k2 (pinhole + k1 k2), full (+ p1 p2 k3), or auto (default: the "
                          "model whose left-out images are predicted best)")
    est = p.add_argument_group("estimation")
    est.add_argument("--mode", choices=("eye-in-hand", "eye-to-hand"), default="eye-in-hand",
                     help="eye-in-hand (camera on the flange: X_EC, default) or eye-to-hand "
                          "(camera fixed, target on the flange: X_BC)")
    est.add_argument("--method", choices=("auto",) + METHODS, default="auto",
                     help="classical solver of the start (auto: Park and Daniilidis, the one "
                          "the data fit best); the result is the maximum-likelihood fit")
    est.add_argument("--time-offset", type=_time_offset_arg, default=None,
                     metavar="auto|SECONDS",
                     help="camera stamp − robot time of the same instant, or 'auto' (default: "
                          "auto when both streams have timestamps)")
    est.add_argument("--time-offset-range", type=positive_float, default=0.5,
                     metavar="SECONDS", help="search range ± of the offset (default 0.5)")
    est.add_argument("--min-rotation", type=float, default=5.0, metavar="DEG",
                     help="smallest rotation of a motion used by the classical start (default 5)")
    est.add_argument("--max-pair-angle", type=float, default=90.0, metavar="DEG",
                     help="largest rotation of a wide motion pair (default 90)")
    est.add_argument("--holdout", type=float, default=0.2, metavar="FRACTION",
                     help="share of the samples held out for validation (default 0.2)")
    est.add_argument("--seed", type=int, default=0, help="seed of the hold-out split")
    est.add_argument("--fix", metavar="NAME=VALUE,…",
                     help="hand-eye components known from elsewhere (tx,ty,tz in m or tx_mm…; "
                          "roll,pitch,yaw in rad or roll_deg…) for motions that cannot "
                          "determine them, e.g. tz=0.052 for a SCARA")
    est.add_argument("--robot-accuracy", type=non_negative_deg_mm, default=DEFAULT_ROBOT_ACCURACY,
                     metavar="DEG,MM",
                     help="per-axis accuracy of the robot's reported pose over the recorded "
                          "workspace (default 0.03,0.3, an uncalibrated industrial arm): a "
                          "slowly varying robot error is invisible in the residuals, so it is "
                          "added to the σ; 0,0 leaves it out")
    chk = p.add_argument_group("verdict")
    chk.add_argument("--max-noise", type=positive_deg_mm, default=(1.0, 10.0), metavar="DEG,MM",
                     help="largest plausible per-axis noise of a camera pose (default 1,10): "
                          "larger residuals FAIL")
    chk.add_argument("--max-hand-eye-distance", type=positive_float, default=None,
                     metavar="METRES", help="largest plausible camera distance from the "
                     "flange (default 0.5; 5 for eye-to-hand, from the base)")
    chk.add_argument("--strict", action="store_true",
                     help="exit with status 1 on a WARN verdict too")
    out = p.add_argument_group("outputs")
    out.add_argument("--online", action="store_true",
                     help="also replay the recording through the paper's on-line filter and "
                          "plot its convergence")
    out.add_argument("--online-step", type=float, default=10.0, metavar="DEG",
                     help="--online: feed the motion between keyframes rotating ≥ DEG apart "
                          "(default 10; 0: every consecutive motion)")
    out.add_argument("--export", type=_formats_arg, default=None, metavar="FORMATS",
                     help="also write the result as urdf,xacro,ros2,drake,camera_config,json,tum "
                          "(comma-separated) or all; not on a FAIL verdict")
    out.add_argument("--parent-frame", default=None, metavar="LINK",
                     help="--export: link the camera hangs from (default: with --bag, the "
                          "end-effector of --robot-frames, its base for eye-to-hand; else "
                          "tool0, base_link for eye-to-hand)")
    out.add_argument("--child-frame", default=None, metavar="FRAME",
                     help="--export: the camera frame the exports attach (default: "
                          "camera_optical_frame), the optical frame itself (OpenCV/ROS "
                          "optical: x right, y down, z forward); with --mount-offset or "
                          "--camera-urdf, "
                          "the camera's mount link instead (e.g. camera_link): the URDF/xacro "
                          "then hold only the joint, and the camera driver's own description "
                          "declares the link and its optical frame")
    mount = out.add_mutually_exclusive_group()
    mount.add_argument("--mount-offset", metavar="X,Y,Z,QX,QY,QZ,QW",
                       help="--export to a mount link: the optical frame's fixed pose in the "
                            "--child-frame link, X_MC: translation in metres, unit quaternion "
                            "in ROS order (x, y, z, w); e.g. 0,0,0,-0.5,0.5,-0.5,0.5 for a ROS "
                            "camera_link (x forward, z up) and its optical frame at the same "
                            "point")
    mount.add_argument("--camera-urdf", metavar="FILE",
                       help="--export to a mount link: the camera's own URDF, or a plain "
                            "xacro (xacro:property and ${...} arithmetic; expand others with "
                            "`xacro`): X_MC is composed from the fixed joints between the "
                            "--child-frame link and --optical-frame")
    out.add_argument("--optical-frame", default=None, metavar="LINK",
                     help="with --camera-urdf (needed) or --mount-offset: the optical frame's "
                          "name, e.g. camera_color_optical_frame (default with --mount-offset: "
                          "camera_optical_frame)")
    out.add_argument("--compare", default=None, metavar="OTHER/calibration.json",
                     help="compare the answer with another calibration of the same mount (its "
                          "calibration.json): the difference, its σ from both answers' "
                          "covariances, and whether they agree or the mount moved")
    out.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                     help=f"output directory (default {DEFAULT_OUT}); an existing one must be "
                          "empty or hold this command's earlier output")
    out.add_argument("--force", action="store_true",
                     help="write into a non-empty --out that is not this command's output "
                          "(never overwriting files the tool did not write)")
    p.set_defaults(func=run_calibrate_command)
    return p


def _scales(args):
    both = args.translation_scale
    robot = args.robot_translation_scale or both or 1.0
    camera = args.camera_translation_scale or both or 1.0
    return robot, camera


def options_from_args(args) -> CalibrationOptions:
    """The library's ``CalibrationOptions`` of the parsed arguments (the same defaults)."""
    return CalibrationOptions(
        mode=args.mode.replace("-", "_"), method=args.method, time_offset_s=args.time_offset,
        time_offset_range_s=args.time_offset_range, min_rotation_deg=args.min_rotation,
        max_pair_angle_deg=args.max_pair_angle, holdout_fraction=args.holdout, seed=args.seed,
        fixed=args.fix, max_noise_deg=args.max_noise[0], max_noise_mm=args.max_noise[1],
        max_hand_eye_distance_m=args.max_hand_eye_distance,
        robot_accuracy_deg=args.robot_accuracy[0],
        robot_accuracy_mm=args.robot_accuracy[1],
        refine_intrinsics=args.refine_intrinsics, online=args.online,
        online_step_deg=args.online_step)


def run_calibrate_command(args) -> int:
    """Runs ``calibrate`` from parsed arguments; raises ValueError on bad input."""
    rig_cameras = getattr(args, "rig_cameras", None) or []
    if rig_cameras or getattr(args, "rig", None) is not None:
        if args.camera:
            raise ValueError(f"--camera {args.camera}: a rig's cameras are NAME:DIR; a camera "
                             "pose file calibrates one camera")
        # Single-camera options a rig does not read: refused rather than silently ignored.
        for option, given, instead in (
                ("--compare", args.compare is not None,
                 "compare one camera's NAME/calibration.json with calibrate --images"),
                ("--intrinsics", args.intrinsics is not None,
                 "give each camera's as --camera NAME:DIR:MOUNT:INTRINSICS"),
                ("--mode", args.mode.replace("_", "-") != "eye-in-hand",
                 "give each camera's mount as --camera NAME:DIR:hand|cell"),
                *((o, getattr(args, o[2:].replace("-", "_")) not in (None, False, default),
                   "each camera's frame is NAME_optical_frame" if "frame" in o or "mount" in o
                   or "urdf" in o else "a rig reads its robot file and images as they are")
                  for o, default in (
                      ("--format", None), ("--robot-format", None), ("--camera-format", None),
                      ("--camera-pose-is-camera-in-target", False),
                      ("--robot-quaternion-order", "xyzw"),
                      ("--camera-quaternion-order", "xyzw"), ("--translation-scale", None),
                      ("--robot-translation-scale", None), ("--camera-translation-scale", None),
                      ("--time-scale", 1.0), ("--max-translation", MAX_TRANSLATION),
                      ("--camera-topic", None),
                      ("--camera-frames", None), ("--image-topic", None),
                      ("--camera-info-topic", None), ("--max-images", DEFAULT_MAX_IMAGES),
                      ("--child-frame", None), ("--mount-offset", None),
                      ("--camera-urdf", None), ("--optical-frame", None)))):
            if given:
                raise ValueError(f"{option}: not read for a rig of cameras; {instead}")
        from .rig_command import run_rig_command
        return run_rig_command(args, rig_cameras, options_from_args(args))
    if getattr(args, "boards", None):
        raise ValueError(f"--board {args.boards[0]}: names a board of a rig of cameras (--camera "
                         "NAME:DIR… or --rig); one camera takes --target SPEC")
    sources = [bool(args.bag), bool(args.images), bool(args.camera)]
    if sum(sources) != 1:
        raise ValueError("inputs: give one of --robot FILE --camera FILE, --bag PATH, or "
                         "--images PATH... --robot FILE --target SPEC")
    if (args.camera or args.images) and not args.robot:
        raise ValueError("--robot: the robot poses (X_BE) are needed with "
                         + ("--camera" if args.camera else "--images"))
    for option, given in (("--images", args.images), ("--image-topic", args.image_topic)):
        if given and not args.target:
            raise ValueError(f"--target: the calibration target is needed with {option} (e.g. "
                             "chessboard:9x6:0.0236)")
    if args.image_topic and not args.bag:
        raise ValueError("--image-topic: reads the images of a ROS bag; give --bag PATH")
    mode = args.mode.replace("-", "_")
    if args.compare is not None:
        from ...calibration.compare import read_answer
        read_answer(args.compare, "--compare")   # a bad file stops before any work
    child_frame, mount_offset, optical_frame, mount_note = camera_mount_from_args(args)
    from ...recorded.exports import _check_name
    # Frame names checked before anything is computed or written (the exports would refuse
    # them only after the fit, with calibration.json already on disk).
    for option, value in (("--parent-frame", args.parent_frame), ("--child-frame", child_frame),
                          ("--optical-frame", optical_frame)):
        if value is not None:
            _check_name(value, option)
    if args.parent_frame is not None and args.parent_frame == child_frame:
        raise ValueError(f"--child-frame: must differ from --parent-frame, both are "
                         f"{child_frame!r}")
    out = prepare_output_dir(args.out, "calibrate", args.force)
    robot_scale, camera_scale = _scales(args)
    streams = read_inputs(
        args.robot, args.camera, images=args.images, bag=args.bag,
        robot_frames=args.robot_frames, camera_topic=args.camera_topic,
        camera_frames=args.camera_frames, image_topic=args.image_topic,
        camera_info_topic=args.camera_info_topic, target=args.target,
        intrinsics=args.intrinsics, format=args.format,
        camera_pose_is_camera_in_target=args.camera_pose_is_camera_in_target,
        max_images=args.max_images, robot_translation_scale=robot_scale,
        camera_translation_scale=camera_scale, max_translation=args.max_translation,
        time_scale=args.time_scale, robot_quaternion_order=args.robot_quaternion_order,
        camera_quaternion_order=args.camera_quaternion_order,
        robot_format=args.robot_format, camera_format=args.camera_format, drawings_dir=out,
        pairing=args.pairing)
    result = solve(streams, options_from_args(args))
    if args.compare is not None:
        from ...calibration.compare import compare
        result.comparison = compare(result, args.compare, "--compare")
    intrinsics_used = result.intrinsics
    written = [write_json(result, out.path("calibration.json"))]
    if result.online is not None and any(len(o.times) for o in result.online):
        from .plots import plot_online
        written.append(plot_online(result, out.path("online_convergence.png")))
    written += [r.drawing for r in streams.images if r.drawing]
    parent_frame, parent_note = _parent_frame(args, streams, mode)
    if args.export and result.verdict.status != "FAIL":
        from ...recorded.exports import export_texts
        texts = export_texts(result.X_hand, args.export, mode=mode,
                             parent_frame=parent_frame, child_frame=child_frame,
                             X_std=result.covariance, intrinsics=intrinsics_used,
                             mount_offset=mount_offset, optical_frame=optical_frame)
        for name, text in texts.items():
            p = out.path(name)
            p.write_text(text)
            if p.suffix == ".sh":
                p.chmod(0o755)
            written.append(p)
    from .report_html import write_report_html
    written.insert(1, write_report_html(result, streams, out))  # listed first: read it first
    out.finish(written)
    if streams.images:
        print(_image_table(streams))
    print(table(result))
    if args.compare is not None:
        print("compared with " + result.comparison.text)
    if args.export and result.verdict.status == "FAIL":
        print("no export: the verdict is FAIL")
    elif args.export:
        for note in (parent_note, mount_note):
            if note:
                print(note)
    print("wrote: " + ", ".join(str(p) for p in written[:12])
          + (f", … ({len(written) - 12} more)" if len(written) > 12 else ""))
    status = result.verdict.status
    return 1 if status == "FAIL" or (status == "WARN" and args.strict) else 0


def camera_mount_from_args(args):
    """(child frame, X_MC or None, optical frame or None, note) of ``--child-frame``,
    ``--mount-offset`` / ``--camera-urdf`` and ``--optical-frame``; ValueError naming the
    argument (checked before anything is read or written)."""
    from ...recorded.exports import DEFAULT_CHILD_FRAME
    given = "--mount-offset" if args.mount_offset else "--camera-urdf" if args.camera_urdf \
        else None
    if given is None:
        if args.optical_frame is not None:
            raise ValueError("--optical-frame: names the optical frame of a mount link; give "
                             "--camera-urdf FILE or --mount-offset too")
        return args.child_frame or DEFAULT_CHILD_FRAME, None, None, ""
    if not args.export:
        raise ValueError(f"{given}: attaches the exports to a mount link; give --export FORMATS "
                         "too")
    if args.child_frame is None:
        raise ValueError(f"--child-frame: with {given}, name the camera's mount link the "
                         "optical frame's offset is from (e.g. --child-frame camera_link)")
    if args.mount_offset:
        from ..pose_args import parse_pose
        optical = args.optical_frame or DEFAULT_CHILD_FRAME
        return args.child_frame, parse_pose(args.mount_offset, "--mount-offset"), optical, ""
    if args.optical_frame is None:
        raise ValueError("--optical-frame: with --camera-urdf, name the optical frame in it "
                         "(e.g. camera_color_optical_frame)")
    from ...recorded.camera_description import CameraDescription
    description = CameraDescription(args.camera_urdf, {
        "path": "--camera-urdf", "mount": "--child-frame", "optical": "--optical-frame"})
    X_MC = description.offset(args.child_frame, args.optical_frame)
    joints = ", ".join(description.chain(args.child_frame, args.optical_frame))
    note = (f"exports attach the mount link {args.child_frame}; {args.optical_frame} is at "
            f"X_MC from it through the fixed joints {joints} of {args.camera_urdf}")
    above = description.parent_joint(args.child_frame)
    if above is not None:
        note += (f"\nnote: {args.child_frame} already has a parent joint in {args.camera_urdf} "
                 f"({above.name} from {above.parent}); with the exported joint it would have "
                 "two: attach the camera description's root link, or drop that joint")
    return args.child_frame, X_MC, args.optical_frame, note


def _parent_frame(args, streams, mode) -> tuple[str | None, str]:
    """The frame the exports hang the result from, and a note on it: ``--parent-frame`` if
    given, else the frame the robot poses were of — a bag's ``--robot-frames`` end-effector
    (eye-in-hand) or base (eye-to-hand) — else the exports' default (tool0 / base_link)."""
    frames = (streams.inputs or {}).get("bag", {}).get("robot_frames")
    if not frames:
        return args.parent_frame, ""
    own = str(frames[1] if mode == "eye_in_hand" else frames[0]).lstrip("/")
    if args.parent_frame is None:
        which = "end-effector" if mode == "eye_in_hand" else "base"
        return own, (f"exports hang from {own}, the {which} frame of --robot-frames "
                     "(--parent-frame to change)")
    if args.parent_frame.lstrip("/") != own:
        return args.parent_frame, (
            f"note: the exports hang from --parent-frame {args.parent_frame}, but the result is "
            f"the camera in {own} (--robot-frames {':'.join(frames)}); the two must be the same "
            "frame")
    return args.parent_frame, ""


#: Rows of the printed per-image table (all of them are in calibration.json).
TABLE_ROWS = 40


def _image_table(streams) -> str:
    note = streams.inputs["images"].get("intrinsics_note", "")
    records = streams.images
    lines = [f"images: {len(records)}" + (f"; {note}" if note else "")]
    if streams.inputs["images"].get("pairing"):
        lines.append(f"  {streams.inputs['images']['pairing']}")
    if streams.inputs["images"].get("symmetry"):
        lines.append(f"  {streams.inputs['images']['symmetry']['note']}")
    from_bag = records[0].message is not None
    # Image files paired in time: their stamps, not a robot line (the pose is interpolated).
    stamped = not from_bag and records[0].robot_line is None
    lines.append("  " + ("stamp (s)                         message" if from_bag else
                         "image                          stamp (s)" if stamped else
                         "image                          robot line")
                 + "  detected  RMS (px)  note")
    for r in records[:TABLE_ROWS]:
        name = f"{r.stamp:.6f}" if from_bag else r.path.rsplit("/", 1)[-1]
        rms = f"{r.reprojection_rms_px:8.3f}" if r.found else "       -"
        where = r.message if from_bag else f"{r.stamp:.6f}" if stamped else r.robot_line
        lines.append(f"  {name:<30} {where:>10}  {'yes' if r.found else 'no':>8}  "
                     f"{rms}  {r.reason}")
    if len(records) > TABLE_ROWS:
        skipped = sum(not r.found for r in records[TABLE_ROWS:])
        lines.append(f"  … {len(records) - TABLE_ROWS} more ({skipped} skipped): "
                     "inputs.images.per_image in calibration.json")
    return "\n".join(lines)

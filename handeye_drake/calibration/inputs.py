"""The inputs of ``calibrate``, turned into a robot stream (X_BE) and a camera stream (X_CT):
pose files, ROS bags, or images of a calibration target paired with robot poses."""

from __future__ import annotations

import dataclasses
import glob
import os
import re
import stat
from contextlib import closing
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..estimation.consistency import rotation_from_swapped_quaternions, with_rotations
from ..recorded.formats import (MAX_TRANSLATION, PoseStream, infer_format, pose_stream,
                                 read_input, read_poses)

#: Floor (px) of the corner noise behind the uncertainty of self-calibrated intrinsics.
PIXEL_NOISE_FLOOR = 0.25
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm")
QUATERNION_ORDERS = ("xyzw", "wxyz")


@dataclass
class Streams:
    """A robot and a camera stream ready to calibrate, and where they came from."""
    robot: PoseStream
    camera: PoseStream
    inputs: dict
    quaternion_streams: tuple = ()
    images: list = field(default_factory=list)     # ImageRecord per image (--images)
    intrinsics: object = None
    #: ``rng -> (N, 4, 4)`` camera poses re-measured with intrinsics drawn from their
    #: uncertainty (intrinsics calibrated from the same images), else None.
    camera_resampler: object = None
    #: ``vision.detection.TargetDetection`` of each camera sample (image inputs), else [].
    detections: list = field(default_factory=list)
    #: "given" (--intrinsics, CameraInfo) or "self-calibrated" (from the same images).
    intrinsics_source: str = "given"
    #: Which stream is the robot's and which the camera's is known, not read from two files
    #: that may have been given the wrong way round (a live session's typed samples, images).
    roles_known: bool = False


def _reorder(stream: PoseStream, order: str, option: str, fmt: str) -> PoseStream:
    if order not in QUATERNION_ORDERS:
        raise ValueError(f"{option}: expected one of {QUATERNION_ORDERS}, got {order!r}")
    if order == "xyzw":
        return stream
    if fmt != "tum":
        raise ValueError(f"{option}: quaternion order applies to TUM files, not {fmt}")
    return dataclasses.replace(stream, poses=with_rotations(
        stream.poses, rotation_from_swapped_quaternions(stream.poses[:, :3, :3])))


_MM_HINT = "(translation_scale=0.001, command line --translation-scale 0.001)"


def _read_or_error(*args):
    try:
        return read_poses(*args), None
    except ValueError as e:
        return None, e


def _raise_units(robot_err, camera_err, robot_scale: float, camera_scale: float) -> None:
    """The first reading error, its units hint naming the file(s) that need scaling: one file
    in millimetres takes --robot- or --camera-translation-scale (--translation-scale would
    scale the other, metric, file too)."""
    if robot_err is None and camera_err is None:
        return
    mm = {w: e is not None and _MM_HINT in str(e)
          for w, e in (("robot", robot_err), ("camera", camera_err))}
    err = robot_err if robot_err is not None else camera_err
    which = "robot" if err is robot_err else "camera"
    if not mm[which]:
        raise err
    if mm["robot"] and mm["camera"] and robot_scale == camera_scale:
        hint = ("(both files: --translation-scale 0.001 on the command line, "
                "robot_translation_scale=camera_translation_scale=0.001 in the API)")
    elif mm["robot"] and mm["camera"]:
        hint = ("(both files: --robot-translation-scale and --camera-translation-scale "
                "0.001)")
    else:
        other = "camera" if which == "robot" else "robot"
        hint = (f"(this file only — the {other} file reads as metres: "
                f"--{which}-translation-scale 0.001 on the command line, "
                f"{which}_translation_scale=0.001 in the API; --translation-scale would "
                f"scale both)")
    raise ValueError(str(err).replace(_MM_HINT, hint)) from None


def _pose_file(path, stream: str) -> None:
    """A folder given for a pose file is named as such (not as a file without an extension)."""
    if isinstance(path, (str, os.PathLike)) and os.path.isdir(path):
        raise ValueError(f"--{stream} {path}: a folder; expected the {stream} pose file")


def file_streams(robot_path, camera_path, fmt: str | None = None, camera_in_target: bool = False,
                 robot_translation_scale: float = 1.0, camera_translation_scale: float = 1.0,
                 max_translation: float | None = MAX_TRANSLATION, time_scale: float = 1.0,
                 robot_quaternion_order: str = "xyzw",
                 camera_quaternion_order: str = "xyzw", robot_format: str | None = None,
                 camera_format: str | None = None) -> Streams:
    """Reads the robot (X_BE) and camera (X_CT) pose files, each exactly once (one file holding
    both, e.g. OpenCV YAML, is read once). Formats: ``robot_format`` / ``camera_format``, else
    ``fmt`` for both, else from each file's extension."""
    _pose_file(robot_path, "robot")
    _pose_file(camera_path, "camera")
    robot_fmt = robot_format or fmt or infer_format(robot_path)
    camera_fmt = camera_format or fmt or infer_format(camera_path)
    same = str(robot_path) == str(camera_path)
    raw = read_input(robot_path) if same else None
    robot, robot_err = _read_or_error(raw or robot_path, "robot", robot_fmt, False,
                                      robot_translation_scale, max_translation, time_scale)
    camera, camera_err = _read_or_error(raw or camera_path, "camera", camera_fmt,
                                        camera_in_target, camera_translation_scale,
                                        max_translation, time_scale)
    _raise_units(robot_err, camera_err, robot_translation_scale, camera_translation_scale)
    robot = _reorder(robot, robot_quaternion_order, "--robot-quaternion-order", robot_fmt)
    camera = _reorder(camera, camera_quaternion_order, "--camera-quaternion-order", camera_fmt)
    quaternion = tuple(w for w, f in (("robot", robot_fmt), ("camera", camera_fmt))
                       if f == "tum")
    inputs = {"robot": {"path": str(robot_path), "sha256": robot.sha256, "samples": len(robot),
                        "format": robot_fmt, "quaternion_order": robot_quaternion_order,
                        "translation_scale": robot_translation_scale},
              "camera": {"path": str(camera_path), "sha256": camera.sha256,
                         "samples": len(camera), "format": camera_fmt,
                         "quaternion_order": camera_quaternion_order,
                         "translation_scale": camera_translation_scale,
                         "pose_is_camera_in_target": bool(camera_in_target)},
              "time_scale": time_scale}
    return Streams(robot, camera, inputs, quaternion)


def bag_streams(path, robot_frames="base_link:tool0", camera_topic=None, camera_frames=None,
                camera_in_target: bool = False) -> Streams:
    """Robot (tf chain between the two frames) and camera (pose topic or tf) streams of a ROS 1
    ``.bag``, ROS 2 bag directory, ``.db3`` or ``.mcap``."""
    from ..recorded.bags import read_bag
    frames = _frames(robot_frames, "--robot-frames")
    cam_frames = _frames(camera_frames, "--camera-frames") if camera_frames else None
    if camera_topic is None and cam_frames is None:
        raise ValueError("--bag: give --camera-topic (a pose topic holding X_CT), "
                         "--camera-frames CAMERA:TARGET (X_CT from tf) or --image-topic TOPIC "
                         "with --target SPEC (X_CT from the images)")
    data = read_bag(path, frames, camera_topic=camera_topic, camera_frames=cam_frames,
                    camera_invert=camera_in_target)
    if data.camera is None:
        raise ValueError(f"{path}: no camera poses found")
    inputs = {"bag": {"path": str(path), "robot_frames": list(frames),
                      "camera": camera_topic or f"tf {cam_frames[0]}:{cam_frames[1]}",
                      "robot_samples": len(data.robot), "camera_samples": len(data.camera)}}
    return Streams(data.robot, data.camera, inputs, ())


def _frames(text, option: str) -> tuple[str, str]:
    parts = str(text).split(":")
    if len(parts) != 2 or not all(parts):
        raise ValueError(f"{option}: expected PARENT:CHILD, got {text!r}")
    return parts[0], parts[1]


# ------------------------------------------------------------------------------------- images
def _natural_key(path: Path):
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", path.name)]


def _file_kind(path: Path) -> str:
    """The empty string for a regular file (symbolic links followed), else what it is ("a FIFO",
    "a symbolic link loop", …) — found with ``stat``, never by opening it (a FIFO would block
    the open, a device could stream forever)."""
    import errno
    try:
        mode = os.stat(path).st_mode
    except OSError as e:
        return ("a symbolic link loop" if e.errno == errno.ELOOP else
                "a broken symbolic link" if e.errno == errno.ENOENT and os.path.islink(path)
                else f"not readable ({e.strerror or e})")
    if stat.S_ISREG(mode):
        return ""
    return ("a directory" if stat.S_ISDIR(mode) else "a FIFO" if stat.S_ISFIFO(mode)
            else "a socket" if stat.S_ISSOCK(mode) else "a device" if stat.S_ISCHR(mode)
            or stat.S_ISBLK(mode) else "not a regular file")


def _identity(path: Path) -> str:
    """What makes two names the same file (duplicates once): the resolved path, or the path
    itself when it cannot be resolved (a symbolic link loop)."""
    try:
        return str(path.resolve())
    except (OSError, RuntimeError):
        return str(path.absolute())


def image_paths(specs) -> list[Path]:
    """Files, directories (their images) and globs, each argument's files naturally sorted by
    file name (img2 before img10), the arguments in the order given (``dirA dirB``: dirA's
    images, then dirB's); duplicates once, where first met. ``specs``: one path or glob, or a
    list of them. Names that are not regular files (a FIFO, a device, a symbolic link loop) are
    kept in their place, to be skipped with the reason by the reader without being opened."""
    return [q for group in image_groups(specs) for q in group[1]]


def image_groups(specs) -> list[tuple[str, list[Path]]]:
    """[(argument, its files in natural order)] in the order of the arguments, duplicates of
    files already listed left out (see ``image_paths``)."""
    if isinstance(specs, (str, Path)):
        specs = [specs]
    groups, seen = [], set()
    for spec in specs:
        p = Path(spec)
        if p.is_dir():
            found = [q for q in p.iterdir() if q.suffix.lower() in IMAGE_SUFFIXES]
            if not found:
                raise ValueError(f"--images {spec}: the directory holds no image "
                                 f"({', '.join(IMAGE_SUFFIXES)})")
        elif os.path.lexists(p):
            found = [p]
        else:
            found = [Path(m) for m in glob.glob(str(spec)) if not os.path.isdir(m)]
            if not found:
                raise ValueError(f"--images {spec}: no such file, directory or matching glob")
        files = []
        for q in sorted(found, key=_natural_key):
            key = _identity(q)
            if key not in seen:
                seen.add(key)
                files.append(q)
        groups.append((str(spec), files))
    return groups


@dataclass
class ImageRecord:
    """What happened to one image: detected (with its reprojection RMS) or skipped (why).

    Image files: ``path`` and the line of the paired robot pose (``robot_line``). Bag images:
    ``path`` is ``TOPIC#MESSAGE``, ``stamp`` the header stamp (s), ``message`` the message
    number on the topic (1-based), ``robot_line`` None (the robot pose is interpolated at the
    stamp)."""
    path: str
    robot_line: int | None
    found: bool = False
    reason: str = ""
    reprojection_rms_px: float = float("nan")
    num_points: int = 0
    drawing: str = ""
    stamp: float | None = None
    message: int | None = None

    def label(self) -> str:
        """The image in messages: its file name, or message number and stamp."""
        if self.message is None:
            return Path(self.path).name
        return f"message {self.message} (stamp {self.stamp:.6f})"


@dataclass
class _Frame:
    """One image to detect the target in: ``image`` (uint8 grey or RGB) or None when it cannot
    be read (``record.reason`` says why), and the name of its drawing under ``--out``."""
    record: ImageRecord
    image: np.ndarray | None
    drawing: str


def _for_detection(image: np.ndarray) -> np.ndarray:
    """uint8 grey or RGB, what ``detect_target`` and ``draw_detection`` take, from a decoded grey
    or BGR(A) image (OpenCV's order; alpha dropped) of 8 bits or more (scaled so that its largest
    value is 255)."""
    import cv2
    if image.dtype != np.uint8:
        image = cv2.convertScaleAbs(image, alpha=255.0 / max(float(image.max()), 1.0))
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    if image.ndim == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    return image


def _read_image(path: Path, max_bytes: int = 100_000_000):
    """(image, reason): the image as RGB/grey uint8, or None and why not."""
    kind = _file_kind(path)
    if kind:
        return None, f"{kind}, not a regular file: not opened"
    try:
        if path.stat().st_size > max_bytes:
            return None, f"larger than {max_bytes // 1_000_000} MB"
        data = np.fromfile(str(path), dtype=np.uint8)
    except OSError as e:
        return None, f"cannot read ({e.strerror or e})"
    from ..vision.image_files import MAX_IMAGE_PIXELS, decode_quietly, image_size
    size = image_size(data[:1 << 16].tobytes())
    if size is not None and size[0] * size[1] > MAX_IMAGE_PIXELS:
        return None, (f"{size[0]}×{size[1]} pixels: more than {MAX_IMAGE_PIXELS / 1e6:g} "
                      "megapixels, not decoded")
    image, said = decode_quietly(data) if len(data) else (None, "")
    if image is None:
        return None, ("not an image, or a truncated one (OpenCV cannot decode it"
                      + (f": {said}" if said else "") + ")")
    return _for_detection(image), ""


def _file_frames(paths, robot: PoseStream):
    """Frames of image files, each paired with the robot pose of the same rank."""
    for k, p in enumerate(paths):
        image, why = _read_image(p)
        yield _Frame(ImageRecord(str(p), int(robot.lines[k]), reason=why), image,
                     f"detections/{p.stem}.png")


def _bag_frames(path, topic: str, max_images: int | None):
    """Frames of a bag's image topic, streamed (one decoded image in memory at a time); the
    drawings are named by index and header stamp."""
    from ..recorded.bags import iter_images
    with closing(iter_images(path, topic, max_images, what="--image-topic")) as messages:
        for index, m in enumerate(messages):
            reason = m.error or ("" if m.stamp_ns else "header stamp not set (0): the image "
                                 "cannot be placed in time")
            record = ImageRecord(f"{topic}#{m.message}", None, reason=reason, stamp=m.stamp,
                                 message=m.message)
            image = None if reason else _for_detection(m.image)
            sec, nsec = divmod(m.stamp_ns, 1_000_000_000)
            yield _Frame(record, image, f"detections/{index:04d}_{sec}.{nsec:09d}.png")


def _first_size(frames, what: str) -> tuple[int, int]:
    """(width, height) of the first readable frame; ValueError with the first reasons when none
    is readable. Stops reading there."""
    reasons = []
    try:
        for f in frames:
            if f.image is not None:
                return f.image.shape[1], f.image.shape[0]
            reasons.append(f"{f.record.label()}: {f.record.reason}")
    finally:
        frames.close()
    if not reasons:
        raise ValueError(f"{what}: no image (the topic has no message)")
    raise ValueError(f"{what}: no image could be read (" + "; ".join(reasons[:3]) + ")")


def _provisional_intrinsics(width: int, height: int):
    from ..vision.camera_model import CameraIntrinsics
    f = float(max(width, height))
    return CameraIntrinsics(alpha_u=f, alpha_v=f, u0=(width - 1) / 2, v0=(height - 1) / 2,
                            width=width, height=height)


def calibrate_intrinsics(detections, width: int, height: int):
    """Intrinsics from the detected target points of every image (``cv2.calibrateCamera``,
    k1, k2, p1, p2, k3). Returns (CameraIntrinsics, RMS reprojection error in px, standard
    deviations of [fx, fy, cx, cy, k1, k2, p1, p2, k3])."""
    import cv2

    from ..vision.camera_model import CameraIntrinsics
    obj = [d.object_points.astype(np.float32) for d in detections if len(d.ids) >= 6]
    img = [d.image_points.astype(np.float32) for d in detections if len(d.ids) >= 6]
    if len(obj) < 3:
        raise ValueError(f"--intrinsics: not given, and only {len(obj)} images show the target "
                         "well enough to calibrate them (≥ 3 needed); give --intrinsics")
    rms, K, dist, _, _, std, _, _ = cv2.calibrateCameraExtended(obj, img, (width, height),
                                                                 None, None)
    # OpenCV scales its standard deviations by the residual RMS. Corner positions are rarely
    # better than ~0.25 px once lens, print and lighting are real (and rendered images bias
    # them too), so a smaller RMS would make the intrinsics look more certain than they are.
    std = np.ravel(std)[:9] * max(1.0, PIXEL_NOISE_FLOOR / max(float(rms), 1e-9))
    return (CameraIntrinsics.from_matrix(K, width, height, tuple(np.ravel(dist)[:5])), float(rms),
            std)


def _resampler(detections, intrinsics, std):
    """Re-measures X_CT of each detection with intrinsics perturbed by N(0, std²) per parameter:
    how the intrinsics' own uncertainty moves the camera poses (and so the hand-eye result)."""
    import cv2

    from ..vision.detection import _pose
    K0 = np.asarray(intrinsics.K, dtype=float)
    d0 = np.zeros(5)
    d0[:len(intrinsics.distortion)] = np.asarray(intrinsics.distortion)[:5]

    def resample(rng) -> np.ndarray:
        e = rng.normal(size=9) * std
        K = K0.copy()
        K[0, 0] += e[0]
        K[1, 1] += e[1]
        K[0, 2] += e[2]
        K[1, 2] += e[3]
        dist = d0 + e[4:9]
        poses = []
        for det in detections:
            rvec = cv2.Rodrigues(det.X_CT[:3, :3])[0]
            tvec = det.X_CT[:3, 3].reshape(3, 1).copy()
            ok, rvec, tvec = cv2.solvePnP(det.object_points.astype(np.float64),
                                          det.image_points.astype(np.float64), K, dist, rvec,
                                          tvec, True, cv2.SOLVEPNP_ITERATIVE)
            poses.append(_pose(rvec, tvec) if ok else det.X_CT)
        return np.array(poses)

    return resample


def _self_calibrated(frames, target, width: int, height: int):
    """(intrinsics, std, note) calibrated from the target seen in the frames of the given size
    (detected with provisional intrinsics; only the points are kept)."""
    from ..vision.detection import detect_target
    rough = _provisional_intrinsics(width, height)
    first = [detect_target(f.image, target, rough) for f in frames
             if f.image is not None and f.image.shape[:2] == (height, width)]
    intrinsics, rms, std = calibrate_intrinsics(first, width, height)
    note = (f"intrinsics calibrated from the images (cv2.calibrateCamera on "
            f"{sum(len(d.ids) >= 6 for d in first)} images): RMS {rms:.3f} px, fx "
            f"{intrinsics.alpha_u:.1f} ± {std[0]:.2f} px; their uncertainty is added to the "
            "result's σ")
    return intrinsics, std, note


def _given_intrinsics(spec, width: int, height: int):
    from ..vision.intrinsics import load_intrinsics
    if isinstance(spec, (str, Path)) and Path(str(spec)).is_dir():
        raise ValueError(f"--intrinsics {spec}: a folder; expected an intrinsics file (OpenCV "
                         "or ROS camera_info YAML) or fx,fy,cx,cy[,…]")
    try:
        if "," in str(spec) and not Path(str(spec)).exists():
            return load_intrinsics(spec, width=width, height=height)
        return load_intrinsics(spec)
    except ValueError as e:
        raise ValueError(str(e) if str(e).startswith("--intrinsics") else
                         f"--intrinsics: {e}") from None


def _detect_frames(frames, target, intrinsics, drawings_dir=None):
    """Detects the target in every frame, the same way for image files and bag images: an
    unreadable image, or one of another size than the intrinsics', is skipped with the reason;
    with ``drawings_dir`` (an ``apps.outputs.OutputDir``) each image is written with the
    detection drawn. Only the points of each detection are kept, never the image.

    Returns (records in frame order, [(record index, TargetDetection)] of the found ones)."""
    from ..vision.detection import detect_target, draw_detection
    records, found = [], []
    for f in frames:
        rec = f.record
        records.append(rec)
        if f.image is None:
            continue
        if f.image.shape[:2] != (intrinsics.height, intrinsics.width):
            rec.reason = (f"image is {f.image.shape[1]}×{f.image.shape[0]}, the intrinsics are "
                          f"for {intrinsics.width}×{intrinsics.height}")
            continue
        det = detect_target(f.image, target, intrinsics)
        rec.found, rec.reason = det.found, det.reason or det.note
        rec.reprojection_rms_px, rec.num_points = det.reprojection_rms_px, len(det.ids)
        if drawings_dir is not None:
            import cv2
            out = drawings_dir.path(f.drawing)
            cv2.imwrite(str(out), draw_detection(f.image, det, intrinsics))
            rec.drawing = str(out)
        if det.found:
            found.append((len(records) - 1, det))
    return records, found


def _require_found(records, found, target_spec, what: str):
    if len(found) >= 3:
        return
    missed = [r for r in records if not r.found]
    listed = "; ".join(f"{r.label()}: {r.reason}" for r in missed[:3])
    if len(missed) > 3:
        listed += f"; … ({len(missed) - 3} more)"
    hint = ""
    from ..vision.targets import CharucoTarget, format_target, parse_target
    try:
        target = parse_target(target_spec) if isinstance(target_spec, str) else target_spec
    except ValueError:
        target = None
    if isinstance(target, CharucoTarget) and any("ChArUco corners from" in (r.reason or "")
                                                 for r in missed):
        import dataclasses
        swapped = dataclasses.replace(target, squares_x=target.squares_y,
                                      squares_y=target.squares_x)
        hint = (f" — markers were seen but no board: are the squares across and down swapped "
                f"(--target {format_target(swapped)})? or the wrong marker dictionary, or a "
                "board printed before OpenCV 4.6 (…:legacy)?")
    raise ValueError(f"{what}: the target {target_spec} was found in only {len(found)} of "
                     f"{len(records)} images (≥ 3 needed): {listed}{hint}")


#: How images pair with the robot poses: "auto" (in time when every image has a stamp and the
#: robot's stamps are times, by index otherwise), "index" (image k ↔ pose k), "time".
PAIRINGS = ("auto", "index", "time")
#: Image stamps this far (s) outside the robot's time span at most still read as the robot's
#: clock (auto pairing; a clock offset is at most this large — ``--time-offset-range``).
CLOCK_MARGIN_S = 1.0


def robot_stamp_problem(robot: PoseStream) -> str:
    """"" when the robot's stamps place its poses in time, else why not (none, or the indices
    0..N−1 or 1..N a tool wrote in the time column)."""
    if not robot.has_timestamps:
        return f"{robot.source} has no time stamps"
    t = np.asarray(robot.timestamps, float)
    if len(t) > 1 and t[0] in (0.0, 1.0) and np.array_equal(t, t[0] + np.arange(len(t))):
        return (f"the stamps of {robot.source} are the indices {int(t[0])}…{int(t[-1])}, not "
                "times")
    return ""


def choose_pairing(groups, robot: PoseStream, pairing: str = "auto"):
    """("index" | "time", stamps per image (s) or None, note) for the image ``groups``
    (``image_groups``) and the robot stream: time when asked (ValueError naming the folder whose
    stamps are missing or ambiguous, or the robot file), or with "auto" when every image has a
    stamp (``recorded.image_stamps``), the robot's stamps are times and they overlap the robot's
    time span (±``CLOCK_MARGIN_S``: else the camera has another clock); index otherwise, the
    note saying why not time."""
    from ..recorded.image_stamps import image_stamps
    if pairing not in PAIRINGS:
        raise ValueError(f"--pairing: expected one of {', '.join(PAIRINGS)}, got {pairing!r}")
    if pairing == "index":
        return "index", None, "--pairing index"
    found = [image_stamps(spec, files) for spec, files in groups]
    image_why = next((s.problem for s in found if s.problem), "")
    robot_why = robot_stamp_problem(robot)
    if pairing == "time" and (image_why or robot_why):
        raise ValueError(f"--pairing time: {image_why or robot_why}")
    if image_why or robot_why:
        # Images without any stamp pair by index as they always did: nothing to say.
        plain = all(s.unstamped for s in found if s.problem) and image_why
        return "index", None, "" if plain else f"not in time: {image_why or robot_why}"
    stamps = np.concatenate([s.stamps for s in found])
    sources = "; ".join(f"{spec}: {s.source}" for (spec, _), s in zip(groups, found))
    if len(groups) > 1:
        order = np.sort(stamps)
        if np.any(np.diff(order) <= 0):
            why = "two images of different folders have the same stamp: ambiguous"
            if pairing == "time":
                raise ValueError(f"--pairing time: {why} ({sources})")
            return "index", None, f"not in time: {why}"
    t0, t1 = float(robot.timestamps[0]), float(robot.timestamps[-1])
    inside = (stamps >= t0 - CLOCK_MARGIN_S) & (stamps <= t1 + CLOCK_MARGIN_S)
    if pairing == "auto" and not inside.any():
        return "index", None, (f"not in time: the image stamps ({sources}; "
                               f"[{stamps.min():.6f}, {stamps.max():.6f}] s) are nowhere in the "
                               f"time span of {robot.source} ([{t0:.6f}, {t1:.6f}] s): another "
                               "clock")
    return "time", stamps, sources


def pairing_note(groups, how: str = "index", why: str = "") -> str:
    """How the images were paired with the robot poses, for the printout and the JSON."""
    if how == "time":
        return (f"images paired with the robot poses in time: the robot pose interpolated at "
                f"each image's stamp (minus the camera's clock offset), stamps from {why}")
    tail = f" ({why})" if why else ""
    if len(groups) == 1:
        return f"images paired with the robot poses in order: {groups[0][0]} in natural " \
               f"file-name order ({len(groups[0][1])}){tail}"
    parts = ", then ".join(f"{spec} ({len(files)})" for spec, files in groups)
    return (f"images paired with the robot poses in order: {parts} — each argument's files in "
            f"natural file-name order, the arguments in the order given{tail}")


def _stamped_frames(paths, stamps):
    """Frames of image files paired in time: each with its stamp, no robot line."""
    for p, t in zip(paths, stamps):
        image, why = _read_image(p)
        yield _Frame(ImageRecord(str(p), None, reason=why, stamp=float(t)), image,
                     f"detections/{p.stem}.png")


def image_streams(image_specs, robot_path, target_spec, intrinsics_spec=None, fmt=None,
                  robot_translation_scale: float = 1.0, robot_quaternion_order: str = "xyzw",
                  drawings_dir=None, pairing: str = "auto") -> Streams:
    """Detects the target in each image and pairs the images with the robot poses
    (``choose_pairing``): by index, in ``image_paths`` order with the robot poses in file order
    (N images ↔ N poses), or in time, each image's stamp (``recorded.image_stamps``: its file
    name or the folder's stamps file) giving the camera stream's timestamps — the robot pose at
    each is then interpolated, the clock offset estimated, images too far from any robot sample
    dropped (``calibrate_streams``, as for a bag). Images where the target is not found are
    skipped, with the reason. Without ``intrinsics_spec`` the intrinsics are calibrated from the
    same images first. ``drawings_dir``: an ``apps.outputs.OutputDir`` to write each image with
    the detection drawn. The images are read from disk as they are needed (twice when the
    intrinsics are calibrated from them), never all held in memory.
    """
    from ..vision.targets import parse_target
    target = parse_target(target_spec) if isinstance(target_spec, str) else target_spec
    groups = image_groups(image_specs)
    paths = [q for _, files in groups for q in files]
    _pose_file(robot_path, "robot")
    robot_fmt = fmt or infer_format(robot_path)
    robot = read_poses(robot_path, "robot", robot_fmt, False, robot_translation_scale)
    robot = _reorder(robot, robot_quaternion_order, "--robot-quaternion-order", robot_fmt)
    how, stamps, why = choose_pairing(groups, robot, pairing)
    if how == "time":
        order = np.argsort(stamps, kind="stable")
        paths, stamps = [paths[k] for k in order], stamps[order]

        def frames():
            return _stamped_frames(paths, stamps)
    else:
        if len(paths) != len(robot):
            odd = [f"{q.name} ({_file_kind(q)})" for q in paths if _file_kind(q)]
            odd_note = (f" ({len(odd)} of them not regular files: {', '.join(odd[:3])}"
                        f"{', …' if len(odd) > 3 else ''})") if odd else ""
            raise ValueError(f"--images, --robot: {len(paths)} images{odd_note} but "
                             f"{len(robot)} robot poses in {robot_path}; images pair with poses "
                             f"in order, one each" + (f" ({why})" if why else ""))

        def frames():
            return _file_frames(paths, robot)
    w, h = _first_size(frames(), "--images")
    intrinsics_note, intrinsics_std = "", None
    if intrinsics_spec is not None:
        intrinsics = _given_intrinsics(intrinsics_spec, w, h)
    else:
        intrinsics, intrinsics_std, intrinsics_note = _self_calibrated(frames(), target, w, h)
    records, found = _detect_frames(frames(), target, intrinsics, drawings_dir)
    try:
        _require_found(records, found, target_spec, "--images")
    except ValueError as e:
        from .pairing import resolution_hint
        hint = resolution_hint(intrinsics) if intrinsics_spec is not None else ""
        if not hint:
            raise
        raise ValueError(f"--intrinsics: {hint} ({e})") from None
    keep = [k for k, _ in found]
    # Detected poses are at the declared target size: one far off (a square given in inches
    # read as metres) is for the corner-level fit to measure and name, not a pose file's units.
    # In time, the folder is named: an error of the alignment (another clock) says whose.
    source = f"images ({len(paths)})" if how == "index" else \
        f"images ({len(paths)}) of {', '.join(spec for spec, _ in groups)}"
    camera = pose_stream(np.array([d.X_CT for _, d in found]),
                         None if stamps is None else stamps[keep], source=source,
                         lines=[k + 1 for k in keep], max_translation=None)
    robot_kept = robot if how == "time" else PoseStream(
        robot.poses[keep], None, robot.source, tuple(int(robot.lines[k]) for k in keep),
        robot.sha256)
    inputs = {"images": {"count": len(paths), "detected": len(keep), "target": str(target_spec),
                         "intrinsics": str(intrinsics_spec) if intrinsics_spec else
                         "calibrated from the images", "intrinsics_note": intrinsics_note,
                         "pairing": pairing_note(groups, how, why), "paired_by": how},
              "robot": {"path": str(robot_path), "sha256": robot.sha256, "samples": len(robot),
                        "format": robot_fmt, "translation_scale": robot_translation_scale}}
    resampler = None if intrinsics_std is None else _resampler([d for _, d in found], intrinsics,
                                                               intrinsics_std)
    return Streams(robot_kept, camera, inputs, ("robot",) if robot_fmt == "tum" else (),
                   records, intrinsics, resampler, [d for _, d in found],
                   "given" if intrinsics_std is None else "self-calibrated")


#: Default of ``--max-images``: detection costs ~15 ms per 640×480 frame.
DEFAULT_MAX_IMAGES = 500


def bag_image_streams(path, robot_frames, image_topic: str, target_spec, intrinsics_spec=None,
                      camera_info_topic: str | None = None,
                      max_images: int | None = DEFAULT_MAX_IMAGES,
                      drawings_dir=None) -> Streams:
    """Robot poses from tf and camera poses from the target detected in the images of a bag
    (ROS 1 ``.bag``, ROS 2 directory, ``.db3`` or ``.mcap``): X_BE is the pose of
    ``robot_frames[1]`` in ``robot_frames[0]``; each image whose target is found gives X_CT at
    its header stamp. The pairing in time (robot pose interpolated at the stamps, clock offset
    estimated and refined) is ``calibrate_streams``'s, as for a pose topic.

    Intrinsics: ``intrinsics_spec`` (as ``--intrinsics``), else the ``CameraInfo`` on
    ``camera_info_topic`` (default: ``camera_info`` beside the image topic, e.g.
    ``/cam/color/camera_info`` for ``/cam/color/image_raw[/compressed]``; ``"none"`` to ignore
    it), else calibrated from the images with their uncertainty (as for image files).

    Memory: images are streamed, decoded, detected and dropped; at most ``max_images`` (evenly
    spaced over the topic, None: all) are read. Raises ValueError naming the option at fault.
    """
    from ..recorded.bags import (CAMERA_INFO_TYPE, bag_topics, find_camera_info, read_bag,
                                  require_topic)
    from ..vision.targets import parse_target
    if max_images is not None and (isinstance(max_images, bool) or not isinstance(
            max_images, (int, np.integer)) or max_images < 3):
        raise ValueError(f"--max-images: expected an integer ≥ 3, got {max_images!r}")
    target = parse_target(target_spec) if isinstance(target_spec, str) else target_spec
    frames = _frames(robot_frames, "--robot-frames")
    topics = bag_topics(path)
    require_topic(str(path), topics, image_topic, ("sensor_msgs/msg/Image",
                                                   "sensor_msgs/msg/CompressedImage"),
                  "--image-topic")
    notes = []
    info_topic = None
    if camera_info_topic is None:
        info_topic = find_camera_info(image_topic, topics, only_beside=True)
        others = sorted(t for t, (typ, _) in topics.items() if typ == CAMERA_INFO_TYPE)
        if info_topic is None and others and intrinsics_spec is None:
            notes.append(f"no camera_info beside {image_topic} (CameraInfo topics: "
                         f"{', '.join(others)}; --camera-info-topic uses one)")
    elif camera_info_topic.lower() != "none":
        info_topic = require_topic(str(path), topics, camera_info_topic, (CAMERA_INFO_TYPE,),
                                   "--camera-info-topic")
    data = read_bag(path, frames, camera_info_topic=None if intrinsics_spec else info_topic)
    count = topics[image_topic][1]

    def stream():
        return _bag_frames(path, image_topic, max_images)

    w, h = _first_size(stream(), f"--image-topic {image_topic}")
    intrinsics_std, source = None, None
    info = data.camera_info
    if intrinsics_spec is not None:
        intrinsics, source = _given_intrinsics(intrinsics_spec, w, h), "--intrinsics"
        how = str(intrinsics_spec)
    elif info is not None and info.calibrated:
        intrinsics = info.intrinsics(f"--camera-info-topic {info_topic}")
        source, how = f"--camera-info-topic {info_topic}: CameraInfo", f"CameraInfo {info_topic}"
        notes.append(f"intrinsics from the CameraInfo on {info_topic} ({info.width}×"
                     f"{info.height}, {info.distortion_model or 'no distortion model'})")
    else:
        if info is not None:
            notes.append(f"CameraInfo on {info_topic} has K = 0 (an uncalibrated camera)")
        intrinsics, intrinsics_std, note = _self_calibrated(stream(), target, w, h)
        notes.append(note)
        how = "calibrated from the images"
    if source is not None and (intrinsics.width, intrinsics.height) != (w, h):
        raise ValueError(f"{source} is for {intrinsics.width}×{intrinsics.height} images, the "
                         f"images on {image_topic} are {w}×{h}")
    used = min(count, max_images) if max_images is not None else count
    if used < count:
        notes.insert(0, f"{used} of the {count} images on {image_topic} used, evenly spaced "
                        f"over the bag (--max-images {max_images})")
    records, found = _detect_frames(stream(), target, intrinsics, drawings_dir)
    _require_found(records, found, target_spec, f"--image-topic {image_topic}")
    # Stamps order the camera stream; an image stamped like an earlier one is not a new sample.
    found.sort(key=lambda kd: (records[kd[0]].stamp, kd[0]))
    kept, last = [], None
    for k, det in found:
        rec = records[k]
        if rec.stamp == last:
            rec.found = False
            rec.reason = "same header stamp as an earlier image"
            continue
        kept.append((k, det))
        last = rec.stamp
    _require_found(records, kept, target_spec, f"--image-topic {image_topic}")
    camera = pose_stream(np.array([d.X_CT for _, d in kept]),
                         [records[k].stamp for k, _ in kept], source=f"{path}[{image_topic}]",
                         lines=[records[k].message for k, _ in kept], max_translation=None)
    inputs = {"bag": {"path": str(path), "robot_frames": list(frames),
                      "camera": f"{image_topic} (target detected in the images)",
                      "robot_samples": len(data.robot), "camera_samples": len(camera)},
              "images": {"topic": image_topic, "messages": count, "count": len(records),
                         "detected": len(kept), "max_images": max_images,
                         "target": str(target_spec), "intrinsics": how,
                         "intrinsics_note": "; ".join(notes + data.warnings)}}
    resampler = None if intrinsics_std is None else _resampler([d for _, d in kept], intrinsics,
                                                               intrinsics_std)
    return Streams(data.robot, camera, inputs, (), records, intrinsics, resampler,
                   [d for _, d in kept], "given" if intrinsics_std is None else "self-calibrated")


def resolve_symmetric_board(streams: Streams, mode: str) -> Streams:
    """For a board that looks the same after a turn (``targets.target_symmetries``): relabels
    each view's points and X_CT the way the robot's motion says (``calibration.symmetry``),
    drops the views it cannot decide (their records say why) and notes what was done in
    ``streams.inputs["images"]["symmetry"]``. Other boards and pose inputs: ``streams`` as is.
    Bag images pair with the robot pose nearest in time (the clock offset, estimated later, is
    assumed small against the robot's motion between views)."""
    from ..vision.targets import format_target, object_points, parse_target, target_symmetries
    from .symmetry import resolve, undecided_reason
    info = streams.inputs.get("images") if isinstance(streams.inputs, dict) else None
    if not streams.detections or not info or not info.get("target"):
        return streams
    try:
        target = parse_target(info["target"])
    except ValueError:
        # Streams built in code may label their target freely: no board spec, no symmetry known.
        return streams
    symmetries = target_symmetries(target)
    if not symmetries:
        return streams
    turns = np.array([np.eye(4)] + [G for G, _ in symmetries])
    perms = [object_points(target)[0]] + [p for _, p in symmetries]
    cam = streams.camera
    if cam.timestamps is not None and streams.robot.timestamps is not None:
        t = np.asarray(streams.robot.timestamps)
        k = np.clip(np.searchsorted(t, cam.timestamps), 1, len(t) - 1)
        k -= (cam.timestamps - t[k - 1]) < (t[k] - cam.timestamps)
        X_BE = streams.robot.poses[k]
    else:
        X_BE = streams.robot.poses
    labels, decided = resolve(X_BE, cam.poses, turns, mode)
    found_records = [r for r in streams.images if r.found]
    detections = []
    for det, label in zip(streams.detections, labels):
        if label:
            G = turns[label]
            det = dataclasses.replace(det, ids=np.asarray(perms[label])[det.ids],
                                      object_points=det.object_points @ G[:3, :3].T + G[:3, 3],
                                      X_CT=det.X_CT @ _rigid_inverse(G))
        detections.append(det)
    name = format_target(target)
    keep = np.flatnonzero(decided)
    for k in np.flatnonzero(~decided):
        if k < len(found_records):
            found_records[k].found = False
            found_records[k].reason = undecided_reason(name)
    for k in np.flatnonzero(labels & decided):
        if k < len(found_records):
            found_records[k].reason = "; ".join(x for x in (
                found_records[k].reason, "board labelled from its other end by the detector: "
                "turned back (the robot's motion decides)") if x)
    info["symmetry"] = {"turns": len(turns), "turned_back": int(np.sum((labels > 0) & decided)),
                        "undecided": int(np.sum(~decided)), "views": len(labels),
                        "note": (f"{name} looks the same after a turn: {int(np.sum(labels > 0))}"
                                 f" of {len(labels)} views were labelled from the board's other "
                                 f"end and turned back, as the robot's motion says"
                                 + (f"; {int(np.sum(~decided))} views the motion cannot decide "
                                    "left out" if np.any(~decided) else ""))}
    if len(keep) < 3:
        raise ValueError(f"--target {name}: the board looks the same after a turn and the robot's "
                         f"motion decides which way round it is in only {len(keep)} of "
                         f"{len(labels)} views (≥ 3 needed): move the robot so that the views "
                         "differ by turns other than ~90° about the board's normal, or use a board "
                         "whose orientation is printed (chessboard with COLS + ROWS odd, ChArUco)")
    poses = np.array([d.X_CT for d in detections])[keep]
    camera = pose_stream(poses, None if cam.timestamps is None else cam.timestamps[keep],
                         source=cam.source, lines=[cam.lines[k] for k in keep])
    robot = streams.robot
    if cam.timestamps is None or robot.timestamps is None:
        robot = PoseStream(robot.poses[keep], None, robot.source,
                           tuple(int(robot.lines[k]) for k in keep), robot.sha256)
    if "detected" in info:
        info["detected"] = len(keep)
    resampler = streams.camera_resampler
    if resampler is not None:
        undo = np.array([_rigid_inverse(turns[label]) for label in labels[keep]])
        old = resampler

        def resampler(rng):  # the intrinsics-resampled poses, relabelled the same way
            return np.einsum("nab,nbc->nac", old(rng)[keep], undo)
    return dataclasses.replace(streams, robot=robot, camera=camera, camera_resampler=resampler,
                               detections=[detections[k] for k in keep])


def _rigid_inverse(X: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = X[:3, :3].T
    out[:3, 3] = -X[:3, :3].T @ X[:3, 3]
    return out

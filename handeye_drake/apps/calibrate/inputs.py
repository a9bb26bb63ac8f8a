"""The inputs of ``calibrate``, turned into a robot stream (X_BE) and a camera stream (X_CT):
pose files, ROS bags, or images of a calibration target paired with robot poses."""

from __future__ import annotations

import dataclasses
import glob
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...recorded.consistency import rotation_from_swapped_quaternions, with_rotations
from ...recorded.formats import (MAX_TRANSLATION, PoseStream, infer_format, pose_stream,
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


def _reorder(stream: PoseStream, order: str, option: str, fmt: str) -> PoseStream:
    if order not in QUATERNION_ORDERS:
        raise ValueError(f"{option}: expected one of {QUATERNION_ORDERS}, got {order!r}")
    if order == "xyzw":
        return stream
    if fmt != "tum":
        raise ValueError(f"{option}: quaternion order applies to TUM files, not {fmt}")
    return dataclasses.replace(stream, poses=with_rotations(
        stream.poses, rotation_from_swapped_quaternions(stream.poses[:, :3, :3])))


def file_streams(robot_path, camera_path, fmt: str | None = None, camera_in_target: bool = False,
                 robot_translation_scale: float = 1.0, camera_translation_scale: float = 1.0,
                 max_translation: float | None = MAX_TRANSLATION, time_scale: float = 1.0,
                 robot_quaternion_order: str = "xyzw",
                 camera_quaternion_order: str = "xyzw") -> Streams:
    """Reads the robot (X_BE) and camera (X_CT) pose files, each exactly once (one file holding
    both, e.g. OpenCV YAML, is read once)."""
    robot_fmt = fmt or infer_format(robot_path)
    camera_fmt = fmt or infer_format(camera_path)
    same = str(robot_path) == str(camera_path)
    raw = read_input(robot_path) if same else None
    robot = read_poses(raw or robot_path, "robot", robot_fmt, False, robot_translation_scale,
                       max_translation, time_scale)
    camera = read_poses(raw or camera_path, "camera", camera_fmt, camera_in_target,
                        camera_translation_scale, max_translation, time_scale)
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
    from ...recorded.bags import read_bag
    frames = _frames(robot_frames, "--robot-frames")
    cam_frames = _frames(camera_frames, "--camera-frames") if camera_frames else None
    if camera_topic is None and cam_frames is None:
        raise ValueError("--bag: give --camera-topic (a pose topic holding X_CT) or "
                         "--camera-frames CAMERA:TARGET (X_CT from tf)")
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


def image_paths(specs) -> list[Path]:
    """Files, directories (their images) and globs, naturally sorted by file name
    (img2 before img10); duplicates once."""
    out = []
    for spec in specs:
        p = Path(spec)
        if p.is_dir():
            found = [q for q in p.iterdir() if q.suffix.lower() in IMAGE_SUFFIXES]
            if not found:
                raise ValueError(f"--images {spec}: the directory holds no image "
                                 f"({', '.join(IMAGE_SUFFIXES)})")
            out += found
        elif p.is_file():
            out.append(p)
        else:
            matches = [Path(m) for m in glob.glob(str(spec)) if Path(m).is_file()]
            if not matches:
                raise ValueError(f"--images {spec}: no such file, directory or matching glob")
            out += matches
    unique = {str(q.resolve()): q for q in out}
    return sorted(unique.values(), key=_natural_key)


@dataclass
class ImageRecord:
    """What happened to one image: detected (with its reprojection RMS) or skipped (why)."""
    path: str
    robot_line: int
    found: bool
    reason: str
    reprojection_rms_px: float = float("nan")
    num_points: int = 0
    drawing: str = ""


def _read_image(path: Path, max_bytes: int = 100_000_000):
    """(image, reason): the image as RGB/grey uint8, or None and why not."""
    import cv2
    try:
        if path.stat().st_size > max_bytes:
            return None, f"larger than {max_bytes // 1_000_000} MB"
        data = np.fromfile(str(path), dtype=np.uint8)
    except OSError as e:
        return None, f"cannot read ({e.strerror or e})"
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if len(data) else None
    if image is None:
        return None, "not an image, or a truncated one (OpenCV cannot decode it)"
    if image.dtype != np.uint8:
        image = cv2.convertScaleAbs(image, alpha=255.0 / max(float(image.max()), 1.0))
    if image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGBA)
    elif image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    return image, ""


def _provisional_intrinsics(width: int, height: int):
    from ...vision.camera_model import CameraIntrinsics
    f = float(max(width, height))
    return CameraIntrinsics(alpha_u=f, alpha_v=f, u0=(width - 1) / 2, v0=(height - 1) / 2,
                            width=width, height=height)


def calibrate_intrinsics(detections, width: int, height: int):
    """Intrinsics from the detected target points of every image (``cv2.calibrateCamera``,
    k1, k2, p1, p2, k3). Returns (CameraIntrinsics, RMS reprojection error in px, standard
    deviations of [fx, fy, cx, cy, k1, k2, p1, p2, k3])."""
    import cv2

    from ...vision.camera_model import CameraIntrinsics
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

    from ...vision.detection import _pose
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


def image_streams(image_specs, robot_path, target_spec, intrinsics_spec=None, fmt=None,
                  robot_translation_scale: float = 1.0, robot_quaternion_order: str = "xyzw",
                  drawings_dir=None) -> Streams:
    """Detects the target in each image and pairs the images, in natural file-name order, with
    the robot poses in file order (N images ↔ N poses; timestamps are not used for the pairing).
    Images where the target is not found are skipped, with the reason. Without
    ``intrinsics_spec`` the intrinsics are calibrated from the same images first.
    ``drawings_dir``: an ``apps.outputs.OutputDir`` to write each image with the detection drawn.
    """
    from ...vision.detection import detect_target, draw_detection
    from ...vision.intrinsics import load_intrinsics
    from ...vision.targets import parse_target
    target = parse_target(target_spec) if isinstance(target_spec, str) else target_spec
    paths = image_paths(image_specs)
    robot_fmt = fmt or infer_format(robot_path)
    robot = read_poses(robot_path, "robot", robot_fmt, False, robot_translation_scale)
    robot = _reorder(robot, robot_quaternion_order, "--robot-quaternion-order", robot_fmt)
    if len(paths) != len(robot):
        raise ValueError(f"--images, --robot: {len(paths)} images but {len(robot)} robot poses "
                         f"in {robot_path}; images pair with poses in order, one each")
    images, reasons = [], {}
    for k, p in enumerate(paths):
        image, why = _read_image(p)
        images.append(image)
        if image is None:
            reasons[k] = why
    readable = [im for im in images if im is not None]
    if not readable:
        raise ValueError("--images: no image could be read (" + "; ".join(
            f"{paths[k].name}: {r}" for k, r in list(reasons.items())[:3]) + ")")
    intrinsics_note = ""
    if intrinsics_spec is not None:
        h, w = readable[0].shape[:2]
        intrinsics = load_intrinsics(intrinsics_spec, width=w, height=h) \
            if "," in str(intrinsics_spec) and not Path(str(intrinsics_spec)).exists() \
            else load_intrinsics(intrinsics_spec)
    else:
        h, w = readable[0].shape[:2]
        rough = _provisional_intrinsics(w, h)
        first = [detect_target(im, target, rough) for im in images
                 if im is not None and im.shape[:2] == (h, w)]
        intrinsics, rms, intrinsics_std = calibrate_intrinsics(first, w, h)
        intrinsics_note = (f"intrinsics calibrated from the images (cv2.calibrateCamera on "
                           f"{sum(len(d.ids) >= 6 for d in first)} images): RMS {rms:.3f} px, "
                           f"fx {intrinsics.alpha_u:.1f} ± {intrinsics_std[0]:.2f} px; their "
                           "uncertainty is added to the result's σ")
    records, poses, keep, found = [], [], [], []
    for k, (p, image) in enumerate(zip(paths, images)):
        line = int(robot.lines[k])
        if image is None:
            records.append(ImageRecord(str(p), line, False, reasons[k]))
            continue
        if image.shape[:2] != (intrinsics.height, intrinsics.width):
            records.append(ImageRecord(
                str(p), line, False, f"image is {image.shape[1]}×{image.shape[0]}, the "
                f"intrinsics are for {intrinsics.width}×{intrinsics.height}"))
            continue
        det = detect_target(image, target, intrinsics)
        rec = ImageRecord(str(p), line, det.found, det.reason or det.note,
                          det.reprojection_rms_px, len(det.ids))
        if drawings_dir is not None:
            import cv2
            out = drawings_dir.path(f"detections/{p.stem}.png")
            cv2.imwrite(str(out), draw_detection(image, det, intrinsics))
            rec.drawing = str(out)
        records.append(rec)
        if det.found:
            poses.append(det.X_CT)
            keep.append(k)
            found.append(det)
    if len(keep) < 3:
        raise ValueError(f"--images: the target {target_spec} was found in only {len(keep)} of "
                         f"{len(paths)} images (≥ 3 needed): " + "; ".join(
                             f"{Path(r.path).name}: {r.reason}" for r in records
                             if not r.found)[:400])
    camera = pose_stream(np.array(poses), None, source=f"images ({len(paths)})",
                         lines=[k + 1 for k in keep])
    robot_kept = PoseStream(robot.poses[keep], None, robot.source,
                            tuple(int(robot.lines[k]) for k in keep), robot.sha256)
    inputs = {"images": {"count": len(paths), "detected": len(keep), "target": str(target_spec),
                         "intrinsics": str(intrinsics_spec) if intrinsics_spec else
                         "calibrated from the images", "intrinsics_note": intrinsics_note},
              "robot": {"path": str(robot_path), "sha256": robot.sha256, "samples": len(robot),
                        "format": robot_fmt}}
    resampler = None if intrinsics_spec is not None else _resampler(found, intrinsics,
                                                                     intrinsics_std)
    return Streams(robot_kept, camera, inputs, ("robot",) if robot_fmt == "tum" else (),
                   records, intrinsics, resampler)

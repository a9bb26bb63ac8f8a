"""The calibration of a real cell as one call: ``calibrate(robot, camera | images | bag, options)``
→ ``CalibrationResult`` — what ``handeye-drake calibrate`` does, with the same defaults.

Stages, in the order the data flows (each a function of this package, testable alone):
read (``inputs``) → align in time (``align``) → select motion pairs and start (``estimation.
selection``) → fit (``pipeline``: maximum likelihood on the poses; ``corners``: on the pixels, for
image inputs) → check (``checks``, ``changepoint``) → verdict; ``report`` turns the result into
text and JSON, ``recorded.exports`` into robot-description files.

Frames: the robot poses are X_BE (end-effector E in base B), the camera poses X_CT (target T in
camera C). Eye-in-hand gives X_EC and X_BT; eye-to-hand gives X_BC and X_ET. Covariances are of
[δθ (rad); δt (m)] with R = exp(δθ) R̂, t = t̂ + δt.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass

import numpy as np

from .corners import REFINE_CHOICES, calibrate_images
from . import pairing
from .euler_check import check_robot_euler, explain_failure
from .inputs import (DEFAULT_MAX_IMAGES, Streams, bag_image_streams, bag_streams, file_streams,
                     image_streams, resolve_symmetric_board)
from .pipeline import CalibrationResult, calibrate_streams
from ..estimation.se3 import inverse
from ..recorded.formats import MAX_TRANSLATION, PoseStream, pose_stream

#: The robot's pose accuracy assumed unless told (an uncalibrated industrial arm).
DEFAULT_ROBOT_ACCURACY = (0.03, 0.3)          # deg, mm


@dataclass(frozen=True)
class CalibrationOptions:
    """Settings of a calibration; the defaults are the command line's. Units are in the names.

    Attributes:
        mode: "eye_in_hand" (camera on the flange: X_EC) or "eye_to_hand" (camera fixed in the
            cell, target on the flange: X_BC).
        method: classical solver of the start ("auto": Park and Daniilidis, the better).
        time_offset_s: camera stamp − robot time (s), "auto", or None (auto when both streams
            have timestamps).
        time_offset_range_s: ± search range of the offset.
        min_rotation_deg, max_pair_angle_deg: motion-pair selection of the start.
        holdout_fraction: share of the pose-level samples held out to check the fit (never out
            of the answer of image inputs, which is the corner-level fit of every image).
        seed: seeds the hold-out split and the split-half check.
        fixed: hand-eye components held at known values ("tz=0.068", {"tz": 0.068}); metres and
            degrees (``tx``, ``ty``, ``tz``, ``roll_deg``, ``pitch_deg``, ``yaw_deg``).
        max_noise_deg, max_noise_mm: largest plausible per-axis noise of a camera pose.
        max_hand_eye_distance_m: largest plausible hand-eye translation (None: 0.5 m eye-in-hand,
            5 m eye-to-hand).
        robot_accuracy_deg, robot_accuracy_mm: the robot's pose accuracy added to the σ (0, 0:
            left out).
        refine_intrinsics: image inputs: "none", "focal", "pinhole", "k1k2", "full" or "auto".
        online, online_step_deg: also replay the recording through the on-line filters.
    """
    mode: str = "eye_in_hand"
    method: str = "auto"
    time_offset_s: float | str | None = None
    time_offset_range_s: float = 0.5
    min_rotation_deg: float = 5.0
    max_pair_angle_deg: float = 90.0
    holdout_fraction: float = 0.2
    seed: int = 0
    fixed: object = None
    max_noise_deg: float = 1.0
    max_noise_mm: float = 10.0
    max_hand_eye_distance_m: float | None = None
    robot_accuracy_deg: float = DEFAULT_ROBOT_ACCURACY[0]
    robot_accuracy_mm: float = DEFAULT_ROBOT_ACCURACY[1]
    refine_intrinsics: str = "auto"
    online: bool = False
    online_step_deg: float = 10.0

    def __post_init__(self):
        mode = str(self.mode).replace("-", "_")
        if mode not in ("eye_in_hand", "eye_to_hand"):
            raise ValueError(f"mode: expected 'eye_in_hand' or 'eye_to_hand', got {self.mode!r}")
        object.__setattr__(self, "mode", mode)
        if self.refine_intrinsics not in REFINE_CHOICES:
            raise ValueError(f"refine_intrinsics: expected one of {', '.join(REFINE_CHOICES)}, "
                             f"got {self.refine_intrinsics!r}")
        for name in ("robot_accuracy_deg", "robot_accuracy_mm", "max_noise_deg",
                     "max_noise_mm"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not v >= 0:
                raise ValueError(f"{name}: expected a number ≥ 0, got {v!r}")
        # A negative bound would pass through to a verdict that always trips (a nan offset to
        # one that never pairs): checked here, where it is given.
        def number(name, low, high, low_open, allow_none=False):
            v = getattr(self, name)
            if v is None and allow_none:
                return
            ok = not isinstance(v, bool) and isinstance(v, (int, float, np.integer,
                                                             np.floating)) and math.isfinite(v)
            ok = ok and (v > low if low_open else v >= low) and v <= high
            if not ok:
                bound = (f" {'>' if low_open else '≥'} {low:g}" if math.isfinite(low) else "") \
                    + (f" and ≤ {high:g}" if math.isfinite(high) else "")
                raise ValueError(f"{name}: expected a finite number{bound}"
                                 + (" (or None)" if allow_none else "") + f", got {v!r}")
        # (The others are checked, with their own messages, where they are used: the pair
        # selection, the hold-out, the time offset's range, the on-line replay.)
        number("max_hand_eye_distance_m", 0.0, math.inf, True, allow_none=True)
        if self.time_offset_s not in (None, "auto"):
            number("time_offset_s", -math.inf, math.inf, False)   # or "auto"

    @property
    def robot_accuracy(self):
        """(deg, m), or None when left out."""
        if self.robot_accuracy_deg == 0 and self.robot_accuracy_mm == 0:
            return None
        return (float(self.robot_accuracy_deg), float(self.robot_accuracy_mm) / 1000.0)

    def stream_settings(self, streams: Streams, corner_level: bool) -> dict:
        """Keyword arguments of ``pipeline.calibrate_streams`` for these inputs."""
        return dict(
            mode=self.mode, method=self.method, time_offset=self.time_offset_s,
            time_offset_range=self.time_offset_range_s, min_rotation_deg=self.min_rotation_deg,
            max_pair_angle_deg=self.max_pair_angle_deg, holdout_fraction=self.holdout_fraction,
            seed=self.seed, fixed=self.fixed,
            max_noise=(float(self.max_noise_deg), float(self.max_noise_mm) / 1000.0),
            max_hand_eye_distance=self.max_hand_eye_distance_m,
            robot_accuracy=self.robot_accuracy, quaternion_streams=streams.quaternion_streams,
            camera_resampler=None if corner_level else streams.camera_resampler,
            online=self.online, online_step_deg=self.online_step_deg,
            camera_from_images=bool(streams.images) or streams.roles_known)


def solve(streams: Streams, options: CalibrationOptions = CalibrationOptions()
          ) -> CalibrationResult:
    """The stages after reading, on ``Streams`` (``inputs``' readers make them): the pose-level
    fit, and for image inputs the corner-level fit that answers (except with held components,
    which the corner-level fit does not take yet)."""
    # A board that looks the same after a turn: the robot's motion decides each view's labels.
    streams = resolve_symmetric_board(streams, options.mode)
    corner_level = bool(streams.detections) and not options.fixed
    settings = options.stream_settings(streams, corner_level)
    # A robot file of Euler angles: its convention is checked against the data like the other
    # readings (``euler_check``).
    robot_in = streams.inputs.get("robot", {}) if isinstance(streams.inputs, dict) else {}
    euler = (robot_in.get("path"), robot_in.get("format"),
             robot_in.get("translation_scale", 1.0))
    try:
        if corner_level:
            result = calibrate_images(streams, settings, options.refine_intrinsics)
            intrinsics = result.corners.camera_intrinsics(streams.intrinsics) \
                if result.corners is not None else streams.intrinsics
        else:
            result = calibrate_streams(streams.robot, streams.camera, **settings)
            intrinsics = streams.intrinsics
    except ValueError as e:
        explained = explain_failure(e, streams, euler[0], euler[1], euler[2], settings)
        raise (pairing.explain_failure(e, streams) if explained is e else explained) from None
    check_robot_euler(result, streams, *euler)
    pairing.check_pairing(result, streams)
    pairing.check_resolution(result, streams)
    result.inputs = streams.inputs
    if streams.images:
        result.inputs["images"]["per_image"] = [dataclasses.asdict(r) for r in streams.images]
    result.intrinsics = intrinsics
    return result


def _is_path(value) -> bool:
    return isinstance(value, (str, bytes, os.PathLike))


def _array_stream(value, times, name: str, what: str, translation_scale: float,
                  max_translation, invert: bool = False) -> PoseStream:
    """A ``PoseStream`` of poses given in memory: a ``PoseStream``, or an (N, 4, 4) array /
    list of 4×4 with optional timestamps (N,) s; ValueError naming the argument."""
    if isinstance(value, PoseStream):
        if times is not None:
            raise ValueError(f"{name}_timestamps: {name} is a PoseStream, which holds its own")
        return value
    if _is_path(value):
        raise ValueError(f"{name}: a file path ({value!r}) beside poses given as an array: give "
                         "both streams as files, or both as arrays")
    kind = type(value).__name__
    try:
        P = np.array(value)
        # float() of a complex array drops the imaginary part silently (numpy only warns).
        if P.dtype.kind not in "biuf":
            P, kind = None, f"{kind} of {P.dtype}"
        else:
            P = P.astype(float)
    except (TypeError, ValueError, OverflowError):
        P = None
    if P is None or P.ndim != 3 or P.shape[1:] != (4, 4) or len(P) == 0:
        shape = f"shape {P.shape}" if P is not None else kind
        raise ValueError(f"{name}: expected a pose file path, or {what} as an (N, 4, 4) array "
                         f"or a list of 4×4 transforms, got {shape}")
    if times is not None:
        try:
            T = np.array(times, dtype=float)
        except (TypeError, ValueError, OverflowError):
            T = None
        if T is None or T.shape != (len(P),):
            raise ValueError(f"{name}_timestamps: expected {len(P)} times (s), one per pose of "
                             f"{name}, got {'shape ' + str(T.shape) if T is not None else times!r}")
        times = T
    try:
        stream = pose_stream(P, times, source=f"{name} (array)",
                             translation_scale=translation_scale,
                             max_translation=max_translation)
    except ValueError as e:
        raise ValueError(f"{name}: {e}") from None
    if invert:
        stream = dataclasses.replace(stream, poses=np.array([inverse(X) for X in stream.poses]))
    return stream


def _array_streams(robot, camera, robot_timestamps, camera_timestamps, camera_in_target,
                   robot_scale, camera_scale, max_translation) -> Streams:
    if (robot_timestamps is None) != (camera_timestamps is None) and not isinstance(
            robot, PoseStream) and not isinstance(camera, PoseStream):
        given = "robot_timestamps" if robot_timestamps is not None else "camera_timestamps"
        raise ValueError(f"{given}: give the times of both streams or of neither (without "
                         "them the samples pair by index)")
    bound = MAX_TRANSLATION if max_translation is None else max_translation
    r = _array_stream(robot, robot_timestamps, "robot", "X_BE", robot_scale, bound)
    c = _array_stream(camera, camera_timestamps, "camera", "X_CT", camera_scale, bound,
                      camera_in_target)
    inputs = {"robot": {"path": None, "source": r.source, "samples": len(r), "format": "array",
                        "translation_scale": robot_scale},
              "camera": {"path": None, "source": c.source, "samples": len(c),
                         "format": "array", "translation_scale": camera_scale,
                         "pose_is_camera_in_target": bool(camera_in_target)}}
    return Streams(r, c, inputs, ())


def read_inputs(robot=None, camera=None, *, images=None, bag=None,
                robot_frames: str = "base_link:tool0", camera_topic=None, camera_frames=None,
                image_topic=None, camera_info_topic=None, target=None, intrinsics=None,
                format: str | None = None, camera_pose_is_camera_in_target: bool = False,
                max_images: int | None = DEFAULT_MAX_IMAGES, robot_translation_scale: float = 1.0,
                camera_translation_scale: float = 1.0, max_translation: float | None = None,
                time_scale: float = 1.0, robot_quaternion_order: str = "xyzw",
                camera_quaternion_order: str = "xyzw", robot_format: str | None = None,
                camera_format: str | None = None, drawings_dir=None,
                robot_timestamps=None, camera_timestamps=None, pairing: str = "auto") -> Streams:
    """``Streams`` of one of: ``robot`` and ``camera`` pose files — or poses in memory: each an
    (N, 4, 4) array or a list of 4×4 transforms (X_BE, X_CT), or a ``PoseStream``, with
    ``robot_timestamps`` and ``camera_timestamps`` (s) optional (without them the samples pair
    by index); ``images`` of a ``target``
    with the ``robot`` pose file (``pairing``: "auto", "index" or "time", ``inputs.
    choose_pairing``); a ``bag`` with ``robot_frames`` and ``camera_topic``,
    ``camera_frames`` or ``image_topic`` (with ``target``). The other arguments are the reading
    options of the command line (``--format``, ``--robot-translation-scale``, …; None
    ``max_translation``: the readers' default). ValueError naming the argument."""
    given = [camera is not None, images is not None, bag is not None]
    if sum(given) != 1:
        raise ValueError("inputs: give one of camera (with robot), images (with robot and "
                         "target) or bag")
    if (camera is not None or images is not None) and robot is None:
        raise ValueError("robot: the robot poses (X_BE) are needed with "
                         + ("camera" if camera is not None else "images"))
    for name, value in (("robot", robot), ("camera", camera)):
        if value is not None and not _is_path(value) and (images is not None or bag is not None):
            raise ValueError(f"{name}: with images or a bag, give the robot poses as a file "
                             f"path (got {type(value).__name__})")
    if images is None and bag is None and not (_is_path(robot) and _is_path(camera)):
        return _array_streams(robot, camera, robot_timestamps, camera_timestamps,
                              camera_pose_is_camera_in_target, robot_translation_scale,
                              camera_translation_scale, max_translation)
    for name, value in (("robot_timestamps", robot_timestamps),
                        ("camera_timestamps", camera_timestamps)):
        if value is not None:
            raise ValueError(f"{name}: times go with poses given as arrays; a file holds its own")
    if (images is not None or image_topic) and not target:
        raise ValueError("target: the calibration target is needed with images (e.g. "
                         "chessboard:9x6:0.0236)")
    if bag is not None and image_topic:
        return bag_image_streams(bag, robot_frames, image_topic, target, intrinsics,
                                 camera_info_topic, max_images, drawings_dir=drawings_dir)
    if bag is not None:
        return bag_streams(bag, robot_frames, camera_topic, camera_frames,
                           camera_pose_is_camera_in_target)
    if images is not None:
        return image_streams(images, robot, target, intrinsics, robot_format or format,
                             robot_translation_scale, robot_quaternion_order,
                             drawings_dir=drawings_dir, pairing=pairing)
    return file_streams(robot, camera, format, camera_pose_is_camera_in_target,
                        robot_translation_scale, camera_translation_scale,
                        MAX_TRANSLATION if max_translation is None else max_translation,
                        time_scale, robot_quaternion_order, camera_quaternion_order,
                        robot_format, camera_format)


def calibrate(robot=None, camera=None, *, images=None, bag=None,
              options: CalibrationOptions = CalibrationOptions(), **reading) -> CalibrationResult:
    """Calibrates the hand-eye transform from recorded data: ``read_inputs`` (its keyword
    arguments in ``reading``: ``target``, ``intrinsics``, ``robot_frames``, ``image_topic``, …),
    then ``solve``. The command line ``handeye-drake calibrate`` is this call with its
    arguments; the same files give the same result both ways.

    Returns a ``CalibrationResult``: ``X_hand`` (X_EC or X_BC), ``X_fixed``, ``covariance``,
    ``verdict`` (OK / WARN / FAIL with reasons), ``observability``, per-sample residuals,
    ``corners`` (image inputs: the intrinsics used, the pixel-level checks), ``to_json()``,
    ``export(formats)``."""
    if not isinstance(options, CalibrationOptions):
        raise ValueError(f"options: expected a CalibrationOptions, got "
                         f"{type(options).__name__}")
    streams = read_inputs(robot, camera, images=images, bag=bag, **reading)
    return solve(streams, options)


def calibrate_files(robot_path, camera_path, fmt=None, camera_in_target: bool = False,
                    translation_scale: float = 1.0, **kwargs) -> CalibrationResult:
    """``pipeline.calibrate_streams`` on two pose files (``inputs.file_streams`` reads them;
    extra keyword arguments go to ``calibrate_streams``, with its defaults — ``calibrate`` has
    the command line's)."""
    s = file_streams(robot_path, camera_path, fmt, camera_in_target, translation_scale,
                     translation_scale)
    result = calibrate_streams(s.robot, s.camera, quaternion_streams=s.quaternion_streams,
                               **kwargs)
    result.inputs = s.inputs
    return result


__all__ = ["CalibrationOptions", "DEFAULT_ROBOT_ACCURACY", "calibrate", "calibrate_files",
           "read_inputs", "solve"]

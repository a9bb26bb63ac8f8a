"""A ROS bag of the shipped example images, for ``handeye-drake calibrate --bag --image-topic``,
written with ``rosbags`` (ROS 1 ``.bag``, ROS 2 sqlite3 ``.db3`` or ROS 2 ``.mcap``).

The recording a real cell would make while the robot sweeps through the 14 poses of
``data/example_images`` (rendered by ``recorded.example_images``; true X_EC in its
``truth.json``) without stopping:

- the flange passes through pose k at t_k = ``start`` + ``period``·k (s), moving between the
  poses at constant speed (linear translation, constant-rate rotation about a fixed axis), and
  holds still ``hold`` s before the first and after the last pose;
- ``/tf`` at ``tf_rate`` Hz: ``base_link`` → ``wrist_3_link`` (dynamic), ``/tf_static``:
  ``wrist_3_link`` → ``tool0`` (``WRIST_TO_TOOL0``) and ``world`` → ``base_link``; so X_BE is the
  pose of ``tool0`` in ``base_link`` (``--robot-frames base_link:tool0``);
- image k is exposed at t_k and stamped t_k + ``latency`` (the camera clock runs late: the offset
  ``calibrate`` estimates), received 15 ms later; on ``/camera/color/image_raw``
  (``sensor_msgs/Image``: ``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``, ``mono8`` or big-endian
  ``mono16``, rows padded by ``row_padding`` bytes), on ``/camera/color/image_raw/compressed``
  (``sensor_msgs/CompressedImage``, png or jpeg) and its ``CameraInfo`` on
  ``/camera/color/camera_info`` (the shipped intrinsics, ``plumb_bob``).

``example_bag(path, storage, ...)`` returns the ``BagWriter`` with every message added (add
more, then ``write()``) and the truth; ``write_example_bag`` writes it. Run
``python -m handeye_drake.recorded.example_bag OUT [--storage ros1|sqlite3|mcap]``.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from ..estimation.se3 import inverse, make_transform, quat_wxyz, rotation_exp, rotation_from_rpy, \
    rotation_log

IMAGES = Path(__file__).resolve().parent.parent / "data" / "example_images"
STORAGES = ("ros1", "sqlite3", "mcap")
IMAGE_TOPIC = "/camera/color/image_raw"
COMPRESSED_TOPIC = "/camera/color/image_raw/compressed"
CAMERA_INFO_TOPIC = "/camera/color/camera_info"
CAMERA_FRAME = "camera_color_optical_frame"
#: The UR's flange-to-tool0 transform style: a fixed link between the last joint and tool0.
WRIST_TO_TOOL0 = make_transform(rotation_from_rpy([0.0, 0.0, math.radians(30.0)]),
                                [0.0, 0.0, 0.0823])
WORLD_TO_BASE = make_transform(np.eye(3), [0.0, 0.0, 0.8])
EPOCH = 1_700_000_000


def _ns(t: float) -> int:
    return EPOCH * 10**9 + int(round(t * 1e9))


class BagWriter:
    """Messages for one bag (``storage`` in ``STORAGES``), kept until ``write()`` writes them in
    receive-time order as a recorder would. Message builders take 4×4 poses and numpy images."""

    def __init__(self, path, storage: str):
        from rosbags.rosbag1 import Writer as Writer1
        from rosbags.rosbag2 import StoragePlugin, Writer as Writer2
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
        if storage not in STORAGES:
            raise ValueError(f"storage: expected one of {', '.join(STORAGES)}, got {storage!r}")
        self.path = Path(path)
        self.ros1 = storage == "ros1"
        self.store = get_typestore(Stores.ROS1_NOETIC if self.ros1 else Stores.ROS2_HUMBLE)
        if self.ros1:  # not in rosbags' noetic store; a real ROS 1 bag embeds its definition
            self.store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                                   "tf2_msgs/msg/TFMessage"))
            self.writer = Writer1(self.path)
        else:
            plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
            self.writer = Writer2(self.path, version=9, storage_plugin=plugin)
        self.T = self.store.types
        self.buffer = []

    def header(self, ns: int, frame: str):
        stamp = self.T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        if self.ros1:
            return self.T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
        return self.T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def transform(self, ns: int, parent: str, child: str, X: np.ndarray):
        T = self.T
        w, x, y, z = quat_wxyz(X[:3, :3])
        return T["geometry_msgs/msg/TransformStamped"](
            header=self.header(ns, parent), child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=X[0, 3], y=X[1, 3], z=X[2, 3]),
                rotation=T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)))

    def tf(self, transforms):
        return self.T["tf2_msgs/msg/TFMessage"](transforms=list(transforms))

    def pose(self, ns: int, frame: str, X: np.ndarray):
        T = self.T
        w, x, y, z = quat_wxyz(X[:3, :3])
        return T["geometry_msgs/msg/PoseStamped"](
            header=self.header(ns, frame),
            pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=X[0, 3], y=X[1, 3], z=X[2, 3]),
                orientation=T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)))

    def image(self, ns: int, frame: str, pixels: np.ndarray, encoding: str, pad: int = 0,
              bigendian: bool = False):
        """An Image of ``pixels`` already in ``encoding``'s layout ((H, W) or (H, W, C), uint8
        or uint16), each row followed by ``pad`` bytes."""
        h, w = pixels.shape[:2]
        px = pixels.astype(pixels.dtype.newbyteorder(">" if bigendian else "<"))
        rows = np.ascontiguousarray(px).view(np.uint8).reshape(h, -1)
        data = np.hstack([rows, np.full((h, pad), 255, np.uint8)])
        return self.T["sensor_msgs/msg/Image"](
            header=self.header(ns, frame), height=h, width=w, encoding=encoding,
            is_bigendian=int(bigendian), step=data.shape[1], data=data.reshape(-1))

    def compressed(self, ns: int, frame: str, data: bytes, fmt: str):
        return self.T["sensor_msgs/msg/CompressedImage"](
            header=self.header(ns, frame), format=fmt,
            data=np.frombuffer(bytes(data), dtype=np.uint8))

    def camera_info(self, ns: int, frame: str, K, D, width: int, height: int,
                    model: str = "plumb_bob"):
        K = [float(v) for v in np.ravel(K)]
        fields = dict(header=self.header(ns, frame), height=int(height), width=int(width),
                      distortion_model=model, binning_x=0, binning_y=0,
                      roi=self.T["sensor_msgs/msg/RegionOfInterest"](
                          x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))
        arrays = {"D": np.array(D, dtype=float), "K": np.array(K), "R": np.eye(3).reshape(-1),
                  "P": np.array(K[:3] + [0.0] + K[3:6] + [0.0] + K[6:] + [0.0])}
        for key, value in arrays.items():
            fields[key if self.ros1 else key.lower()] = value
        return self.T["sensor_msgs/msg/CameraInfo"](**fields)

    def add(self, topic: str, msgtype: str, receive_ns: int, msg) -> None:
        self.buffer.append((receive_ns, len(self.buffer), topic, msgtype, msg))

    def write(self) -> Path:
        """Writes every message in receive-time order; returns the bag's path."""
        connections = {}
        with self.writer as w:
            for receive_ns, _, topic, msgtype, msg in sorted(self.buffer, key=lambda m: m[:2]):
                if topic not in connections:
                    connections[topic] = w.add_connection(topic, msgtype, typestore=self.store)
                data = self.store.serialize_ros1(msg, msgtype) if self.ros1 else \
                    self.store.serialize_cdr(msg, msgtype)
                w.write(connections[topic], receive_ns, data)
        return self.path


def _encode(grey: np.ndarray, encoding: str) -> tuple[np.ndarray, bool]:
    """The grey image in ``encoding``'s layout, and whether it goes big-endian."""
    if encoding == "mono16":
        return grey.astype(np.uint16) * 257, True
    if encoding == "mono8":
        return grey, False
    alpha = np.full_like(grey, 255)
    layouts = {"rgb8": (grey, grey, grey), "bgr8": (grey, grey, grey),
               "rgba8": (grey, grey, grey, alpha), "bgra8": (grey, grey, grey, alpha)}
    if encoding not in layouts:
        raise ValueError(f"encoding: expected mono8, mono16, rgb8, bgr8, rgba8 or bgra8, got "
                         f"{encoding!r}")
    return np.dstack(layouts[encoding]), False


def _robot_pose(t: float, knots: np.ndarray, X_BE: np.ndarray) -> np.ndarray:
    """X_BE at time t: between two knots, linear translation and constant-rate rotation about
    a fixed axis (SLERP); held outside them."""
    k = int(np.clip(np.searchsorted(knots, t, side="right") - 1, 0, len(knots) - 2))
    s = float(np.clip((t - knots[k]) / (knots[k + 1] - knots[k]), 0.0, 1.0))
    A, B = X_BE[k], X_BE[k + 1]
    R = A[:3, :3] @ rotation_exp(s * rotation_log(A[:3, :3].T @ B[:3, :3]))
    return make_transform(R, (1 - s) * A[:3, 3] + s * B[:3, 3])


def example_bag(path, storage: str = "ros1", encoding: str = "rgb8",
                compression: str = "png", latency: float = 0.035, period: float = 1.2,
                tf_rate: float = 100.0, hold: float = 1.0, row_padding: int = 0,
                jpeg_quality: int = 95, repeat: int = 1) -> tuple[BagWriter, dict]:
    """The ``BagWriter`` of the example recording (module docstring), every message added but
    not written, and the truth: ``X_EC``, ``latency``, ``intrinsics`` (K, D, width, height),
    ``target``, per image ``stamp_ns`` (header), ``exposure_ns`` and ``X_BE``. ``repeat``
    sweeps through the poses that many times (a larger bag of the same images)."""
    import cv2

    from ..vision.intrinsics import load_intrinsics
    truth = json.loads((IMAGES / "truth.json").read_text())
    if isinstance(repeat, bool) or not isinstance(repeat, int) or repeat < 1:
        raise ValueError(f"repeat: expected an integer ≥ 1, got {repeat!r}")
    files = [im["file"] for im in truth["images"]] * repeat
    X_BE = np.array([im["X_BE"] for im in truth["images"]] * repeat)
    knots = hold + period * np.arange(len(X_BE))
    intrinsics = load_intrinsics(IMAGES / "intrinsics.yaml")
    if compression not in ("png", "jpeg"):
        raise ValueError(f"compression: expected png or jpeg, got {compression!r}")
    b = BagWriter(path, storage)
    tf = "tf2_msgs/msg/TFMessage"
    b.add("/tf_static", tf, _ns(0.0), b.tf([
        b.transform(_ns(0.0), "world", "base_link", WORLD_TO_BASE),
        b.transform(_ns(0.0), "wrist_3_link", "tool0", WRIST_TO_TOOL0)]))
    tool0_to_wrist = inverse(WRIST_TO_TOOL0)
    for i in range(int(round((knots[-1] + hold) * tf_rate)) + 1):
        t = i / tf_rate
        ns = _ns(t)
        X = _robot_pose(t, knots, X_BE) @ tool0_to_wrist
        b.add("/tf", tf, ns + 2_000_000, b.tf([b.transform(ns, "base_link", "wrist_3_link", X)]))
    images = []
    for k, t in enumerate(knots):
        grey = cv2.imread(str(IMAGES / files[k]), cv2.IMREAD_GRAYSCALE)
        stamp = _ns(t + latency)
        receive = stamp + 15_000_000
        pixels, big = _encode(grey, encoding)
        b.add(IMAGE_TOPIC, "sensor_msgs/msg/Image", receive,
              b.image(stamp, CAMERA_FRAME, pixels, encoding, row_padding, big))
        ok, data = cv2.imencode(".png" if compression == "png" else ".jpg", grey,
                                [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)]
                                if compression == "jpeg" else [])
        b.add(COMPRESSED_TOPIC, "sensor_msgs/msg/CompressedImage", receive,
              b.compressed(stamp, CAMERA_FRAME, data.tobytes(),
                           f"mono8; {compression} compressed mono8"))
        b.add(CAMERA_INFO_TOPIC, "sensor_msgs/msg/CameraInfo", receive,
              b.camera_info(stamp, CAMERA_FRAME, intrinsics.K, intrinsics.distortion,
                            intrinsics.width, intrinsics.height))
        images.append({"file": files[k], "stamp_ns": stamp,
                       "exposure_ns": _ns(t), "X_BE": X_BE[k].tolist()})
    out = {"X_EC": truth["X_EC"], "latency": float(latency), "target": truth["target"],
           "intrinsics": {"K": intrinsics.K.tolist(), "D": list(intrinsics.distortion),
                          "width": intrinsics.width, "height": intrinsics.height},
           "images": images}
    return b, out


def write_example_bag(path, storage: str = "ros1", **kwargs) -> dict:
    """Writes the example bag (``example_bag``'s arguments) and returns its truth."""
    writer, truth = example_bag(path, storage, **kwargs)
    writer.write()
    return truth


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", help="a .bag file (ros1) or a directory to create (ROS 2)")
    parser.add_argument("--storage", choices=STORAGES, default="ros1")
    parser.add_argument("--encoding", default="rgb8")
    parser.add_argument("--compression", choices=("png", "jpeg"), default="png")
    parser.add_argument("--latency", type=float, default=0.035)
    a = parser.parse_args()
    t = write_example_bag(a.out, a.storage, encoding=a.encoding, compression=a.compression,
                          latency=a.latency)
    print(f"wrote {a.out}: {len(t['images'])} images, camera latency {t['latency']} s")

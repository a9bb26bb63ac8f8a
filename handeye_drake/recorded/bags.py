"""Robot and camera streams from ROS bags, without ROS: ROS 1 ``.bag``, ROS 2 ``.db3`` (a
rosbag2 directory or the ``.db3`` file itself) and ``.mcap`` (directory or file), read with the
pure-Python ``rosbags`` library in one streaming pass.

What ``read_bag`` extracts (times are header stamps, seconds, on the recording's clock):

- ``robot``: X_BE, the pose of ``robot_frames[1]`` (end-effector E, e.g. ``tool0``) in
  ``robot_frames[0]`` (base B, e.g. ``base_link``), composed from ``/tf`` and ``/tf_static``
  along the chain of frames joining them (any number of frames; the tree's direction along the
  chain does not matter). Static transforms are taken once; the chain is sampled at every stamp
  at which one of its dynamic (``/tf``) transforms was published, the other dynamic transforms
  being interpolated there (linear translation, SLERP rotation, like tf2's lookup) — stamps
  outside any dynamic transform's time span are dropped. Interpolating the robot pose at the
  camera stamps, and the clock offset, are left to ``align`` as for pose files.
- ``camera``: X_CT, the target T in the camera C, from a ``geometry_msgs`` ``PoseStamped``,
  ``PoseWithCovarianceStamped`` or ``TransformStamped`` topic (``camera_topic``), or from tf:
  ``camera_frames=(CAMERA, TARGET)`` gives the pose of TARGET in CAMERA (X_CT), whichever way
  the tf tree links them. With ``camera_invert=True`` the topic holds X_TC (the camera in the
  target) and ``camera_frames`` is read as ``(TARGET, CAMERA)``; either is inverted into X_CT.
- ``images``: (stamp, array) from a ``sensor_msgs`` ``Image`` (encodings mono8/8UC1 → (H, W)
  uint8, mono16/16UC1 → (H, W) uint16, rgb8/bgr8/rgba8/bgra8 → (H, W, 3) uint8 in OpenCV's BGR
  order, alpha dropped) or ``CompressedImage`` topic (decoded with ``cv2.imdecode``; OpenCV is
  then needed), evenly thinned to at most ``max_images``. ``read_bag`` keeps them all in memory;
  ``iter_images`` streams them one at a time (a large bag's images never all in memory).
- ``camera_info``: K, D, width, height of the first ``sensor_msgs`` ``CameraInfo`` message
  (``CameraInfo``; ``.intrinsics()`` gives the package's ``CameraIntrinsics``; an all-zero K is
  ROS's "uncalibrated", ``calibrated`` is then False).

Frame names lose a leading "/" (ROS 1 style). Errors are ``ValueError`` naming the bag and the
topic or frame, listing what the bag holds (topics with types and counts; tf frames seen).
Memory: messages are streamed once; tf samples are kept only for the transforms on the
requested chains once these are known (before that, for every transform seen).
"""

from __future__ import annotations

import math
from array import array
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..estimation.interpolation import PoseInterpolator
from .formats import PoseStream, pose_stream

POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped",
              "geometry_msgs/msg/TransformStamped")
IMAGE_TYPE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE_TYPE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO_TYPE = "sensor_msgs/msg/CameraInfo"
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")
ENCODINGS = ("mono8", "8UC1", "mono16", "16UC1", "rgb8", "bgr8", "rgba8", "bgra8")


class UnsupportedEncoding(ValueError):
    """An image encoding (or compressed format) ``decode_image`` cannot read: the whole topic is
    unusable, unlike one corrupt message."""


#: A quaternion in a message whose norm is off by more than this is an error (closer: normalized).
QUATERNION_NORM_TOLERANCE = 1e-3


@dataclass(frozen=True)
class CameraInfo:
    """Intrinsics from a ``sensor_msgs/CameraInfo`` message (ROS: pixel (0, 0) is the centre of
    the first pixel, as in OpenCV).

    Attributes:
        K: 3×3 camera matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]] (pixels).
        D: distortion coefficients as recorded (``plumb_bob``: k1, k2, p1, p2, k3 — OpenCV's
            order).
        width, height: image size (pixels).
        distortion_model: e.g. ``plumb_bob``, ``rational_polynomial``, ``equidistant``.
        frame_id: the camera frame of the message header.
        stamp: header stamp (s) of the message used.
    """

    K: np.ndarray
    D: tuple
    width: int
    height: int
    distortion_model: str
    frame_id: str
    stamp: float

    @property
    def alpha_u(self) -> float:
        return float(self.K[0, 0])

    @property
    def alpha_v(self) -> float:
        return float(self.K[1, 1])

    @property
    def u0(self) -> float:
        return float(self.K[0, 2])

    @property
    def v0(self) -> float:
        return float(self.K[1, 2])

    @property
    def calibrated(self) -> bool:
        """False for ROS's "uncalibrated camera" (K all zeros)."""
        return bool(np.any(self.K != 0))

    def intrinsics(self, source: str = "CameraInfo"):
        """The package's ``vision.camera_model.CameraIntrinsics`` (alpha_u = fx, alpha_v = fy,
        u0 = cx, v0 = cy, width, height, distortion = D; a skew K[0, 1] becomes the axes angle
        θ). Raises ValueError, starting with ``source``, for an uncalibrated camera, a distortion
        model other than OpenCV's pinhole ones (``plumb_bob``, ``rational_polynomial``) or a D
        of a length OpenCV does not take."""
        from ..vision.intrinsics import intrinsics_from_camera_info
        if not self.calibrated:
            raise ValueError(f"{source}: K is all zeros (ROS's uncalibrated camera)")
        return intrinsics_from_camera_info(self.K, self.D, self.width, self.height,
                                           self.distortion_model, source)


@dataclass
class BagData:
    """What ``read_bag`` found.

    Attributes:
        path: the bag.
        robot: X_BE stream (None when ``robot_frames`` is None).
        camera: X_CT stream, or None when no camera source was asked for.
        images: [(stamp s, image array)], sorted by stamp.
        camera_info: the first CameraInfo, or None.
        topics: {topic: (message type, message count)} of the whole bag.
        tf_frames: every tf frame seen (sorted).
        image_count: messages on the image topic (before ``max_images`` thinning).
        warnings: things the caller should know (e.g. CameraInfo changing during the bag).
    """

    path: str
    robot: PoseStream | None
    camera: PoseStream | None
    images: list
    camera_info: CameraInfo | None
    topics: dict
    tf_frames: tuple
    image_count: int = 0
    warnings: list = field(default_factory=list)


# ---------------------------------------------------------------------------------- helpers
def _frame(name) -> str:
    return str(name).lstrip("/")


def _stamp_ns(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _seconds(ns) -> float:
    """Seconds of an integer nanosecond stamp (sec + nanosec·1e-9, as ROS does)."""
    return int(ns) // 1_000_000_000 + (int(ns) % 1_000_000_000) * 1e-9


def _stamp(header) -> float:
    return _seconds(_stamp_ns(header))


def _pose_from(translation, rotation, where: str) -> np.ndarray:
    """4×4 pose from a Vector3/Point and a Quaternion message."""
    q = np.array([rotation.x, rotation.y, rotation.z, rotation.w], dtype=float)
    p = np.array([translation.x, translation.y, translation.z], dtype=float)
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(p))):
        raise ValueError(f"{where}: pose contains NaN or infinite values")
    n = float(np.linalg.norm(q))
    if not abs(n - 1.0) <= QUATERNION_NORM_TOLERANCE:
        raise ValueError(f"{where}: quaternion (x y z w) = {np.round(q, 6).tolist()} has norm "
                         f"{n:.6g}, not 1")
    x, y, z, w = q / n
    X = np.eye(4)
    X[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                 [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                 [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    X[:3, 3] = p
    return X


def _inv(X: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms, (..., 4, 4)."""
    out = np.zeros_like(X)
    Rt = np.swapaxes(X[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -(Rt @ X[..., :3, 3, None])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def _describe_topics(topics: dict) -> str:
    if not topics:
        return "none"
    return ", ".join(f"{t} ({typ}, {n} msgs)" for t, (typ, n) in sorted(topics.items()))


def _short(names, n: int = 40) -> str:
    names = sorted(names)
    more = f", … ({len(names) - n} more)" if len(names) > n else ""
    return "[" + ", ".join(names[:n]) + more + "]"


def _pair(value, name: str):
    """(A, B) from a pair or "A:B"."""
    if isinstance(value, str):
        parts = value.split(":")
        if len(parts) != 2:
            raise ValueError(f"{name}: expected 'PARENT:CHILD', got {value!r}")
        value = parts
    try:
        a, b = value
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected two frame names, got {value!r}") from None
    if not (isinstance(a, str) and isinstance(b, str) and _frame(a) and _frame(b)):
        raise ValueError(f"{name}: expected two non-empty frame names, got {value!r}")
    a, b = _frame(a), _frame(b)
    if a == b:
        raise ValueError(f"{name}: the two frames must differ, both are {a!r}")
    return a, b


# ----------------------------------------------------------------------------------- tf buffer
class _Edge:
    """The samples of one tf transform parent → child (X_parent_child)."""

    __slots__ = ("parent", "static", "stamps", "data", "messages", "X")

    def __init__(self, parent: str, static: bool):
        self.parent = parent
        self.static = static
        self.stamps = array("q")    # header stamp (ns) of each sample
        self.data = array("d")      # tx, ty, tz, qx, qy, qz, qw per sample
        self.messages = array("q")  # message number (1-based, per topic) of each sample
        self.X = None               # static: the pose

    def samples(self):
        """(stamps ns, rows tx..qw, message numbers) sorted by stamp; of samples sharing a
        stamp (a republished transform) the last is kept."""
        ns = np.frombuffer(self.stamps, dtype=np.int64)
        order = np.argsort(ns, kind="stable")
        ns = ns[order]
        d = np.frombuffer(self.data, dtype=float).reshape(-1, 7)[order]
        m = np.frombuffer(self.messages, dtype=np.int64)[order]
        keep = np.append(ns[1:] != ns[:-1], True)
        return ns[keep], d[keep], m[keep]


class _TfBuffer:
    def __init__(self, bag: str):
        self.bag = bag
        self.edges: dict[str, _Edge] = {}       # child → edge
        self.frames_dynamic: set[str] = set()
        self.frames_static: set[str] = set()
        self.chains: dict[tuple[str, str], list | None] = {}
        self._keep: set[str] | None = None      # children to keep once every chain is known

    def want(self, a: str, b: str):
        self.chains[(a, b)] = None

    def add(self, transform, static: bool, message: int, topic: str):
        parent, child = _frame(transform.header.frame_id), _frame(transform.child_frame_id)
        (self.frames_static if static else self.frames_dynamic).update((parent, child))
        if self._keep is not None and child not in self._keep:
            return
        edge = self.edges.get(child)
        if edge is None or edge.parent != parent or edge.static != static:
            if edge is not None and self._keep is not None:
                raise ValueError(
                    f"{self.bag}: {topic} message {message}: frame {child!r} on the requested "
                    f"chain changes parent from {edge.parent!r} "
                    f"({'/tf_static' if edge.static else '/tf'}) to {parent!r} ({topic}); a "
                    "chain through a re-parented frame is not supported")
            edge = self.edges[child] = _Edge(parent, static)
        tr, rot = transform.transform.translation, transform.transform.rotation
        if static:  # like tf2: the latest static transform replaces the previous one
            edge.X = _pose_from(tr, rot, f"{self.bag}: {topic} message {message} ({parent} → "
                                f"{child})")
            return
        values = (tr.x, tr.y, tr.z, rot.x, rot.y, rot.z, rot.w)
        norm = math.sqrt(values[3] ** 2 + values[4] ** 2 + values[5] ** 2 + values[6] ** 2)
        if not (all(map(math.isfinite, values)) and abs(norm - 1.0) <= QUATERNION_NORM_TOLERANCE):
            # the full check, for its message (the fast path above is the common case)
            _pose_from(tr, rot, f"{self.bag}: {topic} message {message} ({parent} → {child})")
        edge.stamps.append(_stamp_ns(transform.header))
        edge.data.extend(values)
        edge.messages.append(message)
        if self._keep is None and self._resolve_all():
            self._keep = {c for path in self.chains.values() for c, _ in path}
            self.edges = {c: e for c, e in self.edges.items() if c in self._keep}

    def _ancestors(self, frame: str) -> list[str]:
        out, seen = [frame], {frame}
        while frame in self.edges:
            frame = self.edges[frame].parent
            if frame in seen:
                raise ValueError(f"{self.bag}: tf has a cycle through frame {frame!r}")
            seen.add(frame)
            out.append(frame)
        return out

    def path(self, a: str, b: str):
        """[(child, +1/−1)]: X_ab = Π over the path of X_edge (−1: inverted), or None."""
        up_a, up_b = self._ancestors(a), self._ancestors(b)
        common = set(up_a) & set(up_b)
        if not common:
            return None
        lca = next(f for f in up_a if f in common)
        return ([(c, -1) for c in up_a[:up_a.index(lca)]] +
                [(c, +1) for c in reversed(up_b[:up_b.index(lca)])])

    def _resolve_all(self) -> bool:
        for key, value in self.chains.items():
            if value is None:
                self.chains[key] = self.path(*key)
        return all(v is not None for v in self.chains.values())

    def _frames_text(self) -> str:
        return (f"frames in /tf: {_short(self.frames_dynamic)}; in /tf_static: "
                f"{_short(self.frames_static)}")

    def stream(self, a: str, b: str, what: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(stamps, X_ab poses, message numbers) along the chain a → b."""
        path = self.path(a, b)
        if path is None:
            seen = self.frames_dynamic | self.frames_static
            missing = [f for f in (a, b) if f not in seen]
            if missing:
                raise ValueError(f"{self.bag}: {what}: frame {missing[0]!r} is not in /tf or "
                                 f"/tf_static; {self._frames_text()}")
            raise ValueError(f"{self.bag}: {what}: no transform chain from {a} to {b} (they "
                             f"are in different tf trees, rooted at {self._ancestors(a)[-1]!r}"
                             f" and {self._ancestors(b)[-1]!r}); {self._frames_text()}")
        dynamic = [c for c, _ in path if not self.edges[c].static]
        if not dynamic:
            raise ValueError(f"{self.bag}: {what}: the chain {a} → {b} only has static "
                             "transforms (/tf_static): it never moves")
        series = {c: self.edges[c].samples() for c in dynamic}
        t0 = max(int(ns[0]) for ns, _, _ in series.values())
        t1 = min(int(ns[-1]) for ns, _, _ in series.values())
        stamps = {}
        for c in dynamic:
            ns, _, m = series[c]
            for t, msg in zip(ns.tolist(), m.tolist()):
                if t0 <= t <= t1 and t not in stamps:
                    stamps[t] = msg
        if not stamps:
            names = ", ".join(f"{self.edges[c].parent} → {c} [{_seconds(series[c][0][0])!r}, "
                              f"{_seconds(series[c][0][-1])!r}] s" for c in dynamic)
            raise ValueError(f"{self.bag}: {what}: the dynamic transforms of the chain {a} → {b}"
                             f" never overlap in time: {names}")
        query = np.array(sorted(stamps), dtype=np.int64)
        messages = np.array([stamps[v] for v in query.tolist()])
        # Interpolate on seconds since the first stamp: exact integer differences, no loss of
        # precision from epoch-sized floats.
        origin = int(query[0])
        rel = (query - origin) * 1e-9
        X = np.broadcast_to(np.eye(4), (len(query), 4, 4)).copy()
        for c, sign in path:
            edge = self.edges[c]
            if edge.static:
                E = np.broadcast_to(edge.X, (len(query), 4, 4))
            else:
                ns, rows, _ = series[c]
                poses = _poses_from_rows(rows)
                E = PoseInterpolator((ns - origin) * 1e-9, poses)(rel) if len(ns) > 1 \
                    else np.broadcast_to(poses[0], (len(query), 4, 4))
            X = X @ (E if sign > 0 else _inv(E))
        return np.array([_seconds(v) for v in query.tolist()]), X, messages


def _poses_from_rows(rows: np.ndarray) -> np.ndarray:
    """(N, 4, 4) poses from rows tx ty tz qx qy qz qw (quaternions normalized)."""
    q = rows[:, 3:7] / np.linalg.norm(rows[:, 3:7], axis=1, keepdims=True)
    x, y, z, w = q.T
    X = np.zeros((len(rows), 4, 4))
    X[:, 0, 0], X[:, 0, 1], X[:, 0, 2] = 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), \
        2 * (x * z + y * w)
    X[:, 1, 0], X[:, 1, 1], X[:, 1, 2] = 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), \
        2 * (y * z - x * w)
    X[:, 2, 0], X[:, 2, 1], X[:, 2, 2] = 2 * (x * z - y * w), 2 * (y * z + x * w), \
        1 - 2 * (x * x + y * y)
    X[:, :3, 3] = rows[:, :3]
    X[:, 3, 3] = 1.0
    return X


# ------------------------------------------------------------------------------------- images
def decode_image(msg, msgtype: str, where: str) -> np.ndarray:
    """An Image or CompressedImage message as a numpy array (see the module docstring).

    Raises:
        UnsupportedEncoding: an encoding (or compressed format) not in ``ENCODINGS`` / png, jpeg.
        ValueError: a message whose data does not hold its image (truncated, corrupt).
    """
    if msgtype == COMPRESSED_IMAGE_TYPE:
        try:
            import cv2  # noqa: F401  (the decoder below needs it)
        except ImportError:
            raise ValueError(f"{where}: decoding sensor_msgs/CompressedImage needs OpenCV (pip "
                             "install opencv-python-headless)") from None
        if "compresseddepth" in str(msg.format).lower():
            raise UnsupportedEncoding(f"{where}: unsupported compressed format {msg.format!r} "
                                      "(a depth image); expected a png or jpeg colour or grey "
                                      "image")
        from ..vision.image_files import MAX_IMAGE_PIXELS, decode_quietly, image_size
        data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
        size = image_size(data[:1 << 16].tobytes())
        if size is not None and size[0] * size[1] > MAX_IMAGE_PIXELS:
            raise ValueError(f"{where}: the compressed image is {size[0]}×{size[1]} pixels, more "
                             f"than {MAX_IMAGE_PIXELS / 1e6:g} megapixels; not decoded")
        img, said = decode_quietly(data)
        if img is None:
            raise ValueError(f"{where}: cannot decode the compressed image (format "
                             f"{msg.format!r}" + (f": {said}" if said else "") + ")")
        return img[:, :, :3].copy() if img.ndim == 3 and img.shape[2] == 4 else img
    enc = str(msg.encoding)
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    channels = {"mono8": 1, "8UC1": 1, "mono16": 1, "16UC1": 1, "rgb8": 3, "bgr8": 3,
                "rgba8": 4, "bgra8": 4}.get(enc)
    if channels is None:
        raise UnsupportedEncoding(f"{where}: unsupported image encoding {enc!r}; supported: "
                                  f"{', '.join(ENCODINGS)} (or a CompressedImage topic)")
    size = 2 if enc in ("mono16", "16UC1") else 1
    row = w * channels * size
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if h < 1 or w < 1 or step < row or len(data) < step * (h - 1) + row:
        raise ValueError(f"{where}: image data of {len(data)} bytes does not hold {h}×{w} "
                         f"{enc} pixels with step {step}")
    if len(data) < step * h:  # a last row without its padding
        data = np.concatenate([data, np.zeros(step * h - len(data), np.uint8)])
    rows = data[:step * h].reshape(h, step)[:, :row]
    if size == 2:
        img = rows.copy().view(">u2" if msg.is_bigendian else "<u2").reshape(h, w)
        return img.astype(np.uint16)
    img = rows.reshape(h, w, channels) if channels > 1 else rows.reshape(h, w)
    if enc in ("rgb8", "rgba8"):
        img = img[:, :, 2::-1]
    elif enc == "bgra8":
        img = img[:, :, :3]
    return np.ascontiguousarray(img)


def _camera_info(msg, where: str) -> CameraInfo:
    K = np.array(getattr(msg, "k", None) if hasattr(msg, "k") else msg.K, dtype=float)
    D = getattr(msg, "d", None) if hasattr(msg, "d") else msg.D
    uncalibrated = K.shape == (9,) and not np.any(K)
    if not uncalibrated and (K.shape != (9,) or not np.all(np.isfinite(K)) or K[0] <= 0
                             or K[4] <= 0 or K[8] != 1):
        raise ValueError(f"{where}: invalid camera matrix K = {K.tolist()} (need fx, fy > 0 and "
                         "K[2, 2] = 1: is the camera calibrated?)")
    return CameraInfo(K.reshape(3, 3), tuple(float(v) for v in D), int(msg.width),
                      int(msg.height), str(msg.distortion_model), _frame(msg.header.frame_id),
                      _stamp(msg.header))


# -------------------------------------------------------------------------------- entry point
def find_camera_info(image_topic: str, topics: dict, only_beside: bool = False) -> str | None:
    """The CameraInfo topic of an image topic: ``camera_info`` in its namespace or an enclosing
    one (``/cam/color/image_raw/compressed`` → ``/cam/color/camera_info``), else (unless
    ``only_beside``) the bag's only CameraInfo topic, else None."""
    infos = [t for t, (typ, _) in topics.items() if typ == CAMERA_INFO_TYPE]
    parts = image_topic.rstrip("/").split("/")
    for k in range(len(parts) - 1, 0, -1):
        candidate = "/".join(parts[:k]) + "/camera_info"
        if candidate in infos:
            return candidate
    return infos[0] if len(infos) == 1 and not only_beside else None


def _open(path: Path):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    store = Stores.ROS1_NOETIC if path.suffix == ".bag" else Stores.ROS2_HUMBLE
    return AnyReader([path], default_typestore=get_typestore(store))


def _opened(path) -> tuple:
    """(open reader, bag name) or ValueError naming the bag."""
    path = Path(path)
    bag = str(path)
    if not path.exists():
        raise ValueError(f"{bag}: no such file or directory")
    try:
        reader = _open(path)
        reader.open()
    except Exception as e:  # rosbags raises its own error types, and OSError
        raise ValueError(f"{bag}: cannot read as a ROS bag (.bag, .db3, .mcap or a rosbag2 "
                         f"directory): {e}") from None
    return reader, bag


def _topics(reader) -> dict:
    return {name: (info.msgtype, int(info.msgcount)) for name, info in reader.topics.items()}


def bag_topics(path) -> dict:
    """{topic: (message type, message count)} of a bag (its index only; no message is read)."""
    reader, _ = _opened(path)
    try:
        return _topics(reader)
    finally:
        reader.close()


def require_topic(bag: str, topics: dict, topic, types, what: str):
    """``topic`` if the bag has it with one of ``types``, else ValueError listing the topics (of
    those types when there are any)."""
    if topic not in topics:
        of_type = {t: v for t, v in topics.items() if v[0] in types}
        kinds = " or ".join(types)
        if of_type:
            listed = (f"topics: {_describe_topics(of_type)} (those of type {kinds}; "
                      f"{len(topics) - len(of_type)} others)")
        else:
            listed = f"none of type {kinds}; topics: {_describe_topics(topics)}"
        raise ValueError(f"{bag}: {what}: no topic {topic!r}; {listed}")
    if topics[topic][0] not in types:
        raise ValueError(f"{bag}: {what}: topic {topic!r} has type {topics[topic][0]}, "
                         f"expected {' or '.join(types)}")
    return topic


def subsample(count: int, max_count: int | None) -> np.ndarray:
    """0-based indices of at most ``max_count`` of ``count`` items, evenly spaced over them
    (first and last included); all of them when ``max_count`` is None or not smaller."""
    if max_count is None or count <= max_count:
        return np.arange(count)
    if max_count == 1:
        return np.zeros(1, dtype=int)
    return np.unique(np.round(np.linspace(0, count - 1, max_count)).astype(int))


def _check_max_images(max_images):
    if max_images is not None and (not isinstance(max_images, (int, np.integer))
                                   or isinstance(max_images, bool) or max_images < 1):
        raise ValueError(f"max_images: expected a positive integer or None, got {max_images!r}")


@dataclass(frozen=True)
class BagImage:
    """One message of an image topic, as ``iter_images`` yields it.

    Attributes:
        message: its number on the topic (1-based, bag order).
        stamp_ns: header stamp (ns since the epoch of the recording's clock; 0 when the driver
            left it unset).
        received_ns: the bag's receive (log) time of the message (ns).
        image: the decoded array (see the module docstring), or None when the message cannot be
            decoded (``error`` says why).
        error: "" or why the message gives no image.
    """

    message: int
    stamp_ns: int
    received_ns: int
    image: np.ndarray | None
    error: str = ""

    @property
    def stamp(self) -> float:
        """Header stamp, seconds."""
        return _seconds(self.stamp_ns)


def iter_images(path, image_topic: str, max_images: int | None = None,
                what: str = "image_topic"):
    """Streams the images of an ``Image`` or ``CompressedImage`` topic in bag order, one decoded
    image at a time (``BagImage``); with ``max_images``, only that many messages, evenly spaced
    over the topic (``subsample``), are deserialized and decoded.

    A message that cannot be decoded (truncated, corrupt) is yielded with ``image=None`` and
    the reason; an unsupported encoding raises ``UnsupportedEncoding`` (naming the bag, topic,
    message and encoding), as does a missing or mistyped topic (ValueError listing the bag's
    image topics; ``what`` names the argument in it)."""
    _check_max_images(max_images)
    reader, bag = _opened(path)
    try:
        topics = _topics(reader)
        require_topic(bag, topics, image_topic, (IMAGE_TYPE, COMPRESSED_IMAGE_TYPE), what)
        chosen = set(subsample(topics[image_topic][1], max_images).tolist())
        connections = [c for c in reader.connections if c.topic == image_topic]
        k = 0
        for connection, received, raw in reader.messages(connections=connections):
            k += 1
            if k - 1 not in chosen:
                continue  # skipped before deserializing
            where = f"{bag}: {image_topic} message {k}"
            try:
                msg = reader.deserialize(raw, connection.msgtype)
            except Exception as e:  # rosbags' own error types on a corrupt message
                yield BagImage(k, 0, int(received), None, f"cannot deserialize it ({e})")
                continue
            try:
                image, error = decode_image(msg, connection.msgtype, where), ""
            except UnsupportedEncoding:
                raise
            except ValueError as e:
                image, error = None, str(e).removeprefix(where + ": ")
            yield BagImage(k, _stamp_ns(msg.header), int(received), image, error)
    finally:
        reader.close()


def read_bag(path, robot_frames=("base_link", "tool0"), camera_topic=None, camera_frames=None,
             image_topic=None, camera_info_topic=None, camera_invert: bool = False,
             max_images: int | None = None) -> BagData:
    """Reads the streams of a ROS bag (see the module docstring for frames and conventions).

    Args:
        path: ROS 1 ``.bag``, ROS 2 bag directory (sqlite3 or mcap storage), ``.db3`` or
            ``.mcap`` file.
        robot_frames: (BASE, END_EFFECTOR) or "BASE:END_EFFECTOR": X_BE = pose of END_EFFECTOR
            in BASE from /tf and /tf_static; None to skip.
        camera_topic: topic of X_CT poses (PoseStamped, PoseWithCovarianceStamped or
            TransformStamped).
        camera_frames: (CAMERA, TARGET) or "CAMERA:TARGET": X_CT = pose of TARGET in CAMERA from
            tf (either tree direction).
        image_topic: an Image or CompressedImage topic.
        camera_info_topic: a CameraInfo topic; default: ``camera_info`` in the image topic's
            namespace or an enclosing one, else the bag's only CameraInfo topic, if any.
        camera_invert: the camera topic holds X_TC (camera in target), or camera_frames is
            (TARGET, CAMERA); inverted into X_CT.
        max_images: keep at most this many images, evenly spaced over the topic (None: all).

    Raises:
        ValueError: unreadable bag, missing or mistyped topic, missing frame or chain (the
            message lists the bag's topics or tf frames), bad message contents.
    """
    if camera_topic is not None and camera_frames is not None:
        raise ValueError("camera_topic, camera_frames: give one camera source, not both")
    robot_pair = None if robot_frames is None else _pair(robot_frames, "robot_frames")
    camera_pair = None if camera_frames is None else _pair(camera_frames, "camera_frames")
    _check_max_images(max_images)
    reader, bag = _opened(path)
    try:
        return _read(reader, bag, robot_pair, camera_topic, camera_pair, image_topic,
                     camera_info_topic, bool(camera_invert), max_images)
    finally:
        reader.close()


def _read(reader, bag, robot_pair, camera_topic, camera_pair, image_topic, camera_info_topic,
          camera_invert, max_images) -> BagData:
    topics = _topics(reader)

    def need(topic, types, what):
        return require_topic(bag, topics, topic, types, what)

    if camera_topic is not None:
        need(camera_topic, POSE_TYPES, "camera_topic")
    if image_topic is not None:
        need(image_topic, (IMAGE_TYPE, COMPRESSED_IMAGE_TYPE), "image_topic")
        if camera_info_topic is None:
            camera_info_topic = find_camera_info(image_topic, topics)
    if camera_info_topic is not None:
        need(camera_info_topic, (CAMERA_INFO_TYPE,), "camera_info_topic")
    tf_topics = [t for t, (typ, _) in topics.items() if typ in TF_TYPES]
    tf = _TfBuffer(bag)
    for pair in (robot_pair, camera_pair):
        if pair is not None:
            if not tf_topics:
                what = "robot_frames" if pair is robot_pair else "camera_frames"
                raise ValueError(f"{bag}: {what}: no /tf or /tf_static topic ({TF_TYPES[0]}); "
                                 f"topics: {_describe_topics(topics)}")
            tf.want(*pair)
    wanted = set(tf_topics if (robot_pair or camera_pair) else []) | {
        t for t in (camera_topic, image_topic, camera_info_topic) if t is not None}
    connections = [c for c in reader.connections if c.topic in wanted]

    image_count = topics[image_topic][1] if image_topic is not None else 0
    chosen = set(subsample(image_count, max_images).tolist())
    counts = dict.fromkeys(wanted, 0)
    camera_rows, images, info, warnings = [], [], None, []
    for connection, _, raw in reader.messages(connections=connections):
        topic = connection.topic
        counts[topic] += 1
        k = counts[topic]
        if topic == image_topic:
            if k - 1 not in chosen:
                continue  # skipped before deserializing: images are the bulk of a bag
        msg = reader.deserialize(raw, connection.msgtype)
        where = f"{bag}: {topic} message {k}"
        if topic in tf_topics:
            static = topic.rstrip("/").endswith("tf_static")
            for transform in msg.transforms:
                tf.add(transform, static, k, topic)
        elif topic == camera_topic:
            if connection.msgtype == "geometry_msgs/msg/TransformStamped":
                X = _pose_from(msg.transform.translation, msg.transform.rotation, where)
            else:
                pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
                X = _pose_from(pose.position, pose.orientation, where)
            camera_rows.append((_stamp(msg.header), k, X))
        elif topic == image_topic:
            images.append((_stamp(msg.header), decode_image(msg, connection.msgtype, where)))
        elif topic == camera_info_topic:
            current = _camera_info(msg, where)
            if info is None:
                info = current
            elif not (np.array_equal(current.K, info.K) and current.D == info.D and
                      (current.width, current.height) == (info.width, info.height)) and \
                    not any(w.startswith(f"{camera_info_topic}: changes") for w in warnings):
                warnings.append(f"{camera_info_topic}: changes during the bag (message {k}); "
                                "the first message is used")

    robot = None
    if robot_pair is not None:
        t, X, msgs = tf.stream(*robot_pair, what="robot_frames")
        robot = pose_stream(X, t, f"{bag}[tf {robot_pair[0]}→{robot_pair[1]}]", msgs)
    camera = None
    if camera_pair is not None:
        t, X, msgs = tf.stream(*camera_pair, what="camera_frames")
        name = f"{bag}[tf {camera_pair[0]}→{camera_pair[1]}]"
        camera = pose_stream(_inv(X) if camera_invert else X, t, name, msgs)
    elif camera_topic is not None:
        if not camera_rows:
            raise ValueError(f"{bag}: camera_topic {camera_topic!r} has no messages")
        camera_rows.sort(key=lambda r: r[0])
        X = np.array([r[2] for r in camera_rows])
        camera = pose_stream(_inv(X) if camera_invert else X, [r[0] for r in camera_rows],
                             f"{bag}[{camera_topic}]", [r[1] for r in camera_rows])
    if image_topic is not None and not images:
        raise ValueError(f"{bag}: image_topic {image_topic!r} has no messages")
    images.sort(key=lambda r: r[0])
    frames = tuple(sorted(tf.frames_dynamic | tf.frames_static))
    return BagData(bag, robot, camera, images, info, topics, frames, image_count, warnings)

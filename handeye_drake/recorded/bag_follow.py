"""Calibration samples from a ROS bag that is still being recorded: poll it, return what is new.

    follower = BagFollower(path, robot_frames="base_link:tool0", camera_topic="/target_pose")
    for sample in follower.poll():      # again and again while the recorder writes
        session.add(sample["X_BE"], sample["X_CT"], stamp=sample["stamp"])

A sample is one camera measurement — a pose message on ``camera_topic``, the tf pose
``camera_frames`` (CAMERA:TARGET), or an image on ``image_topic`` — with the robot pose X_BE
(``robot_frames`` from /tf and /tf_static, as ``bags.read_bag`` composes it) interpolated at the
camera stamp. A camera stamp later than the last robot pose waits for the next poll (the robot's
tf may lag); one earlier than the first robot pose is dropped (``dropped`` says why). Each
camera message is returned once.

What can be read while it grows (each poll re-opens the bag; a poll that finds it mid-write
returns nothing and tries again next time):

- ROS 2, sqlite3 storage (``.db3``, or the bag directory before ``metadata.yaml`` exists): the
  transactions the recorder has committed (rosbag2 commits as it writes);
- ROS 2, MCAP storage (``.mcap``, or its directory): the complete chunks written so far, read
  by a linear scan of the records when the file has no footer yet (rosbags needs the footer);
  chunks compressed with zstd need the ``zstandard`` package (as for rosbags), lz4 ``lz4``;
- a finished bag of any kind ``bags.read_bag`` reads (a ROS 1 ``.bag`` only once it is closed:
  its index is written last).

Cost: each poll reads the bag from the start (tf and pose messages; images already returned
are skipped before they are deserialized), fine for a calibration's minutes of recording.
"""

from __future__ import annotations

import io
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..estimation.interpolation import PoseInterpolator
from . import bags

_MAGIC = b"\x89MCAP0\r\n"


# ------------------------------------------------------------------- a growing MCAP file
class NotReadyYet(FileNotFoundError):
    """The bag exists but holds nothing readable yet (the recorder has just started)."""


@dataclass(frozen=True)
class _Connection:
    id: int
    topic: str
    msgtype: str


@dataclass(frozen=True)
class _TopicInfo:
    msgtype: str
    msgcount: int


def _string(b: io.BytesIO) -> str:
    (n,) = struct.unpack("<I", b.read(4))
    return b.read(n).decode()


def _decompress(data: bytes, compression: str, size: int) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        import zstandard
        return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    if compression == "lz4":
        import lz4.frame
        return lz4.frame.decompress(data)
    raise ValueError(f"MCAP chunk compression {compression!r} is not supported")


class PartialMcapReader:
    """The complete records of an MCAP file being written (no footer or summary yet): schemas,
    channels and messages, top level or inside complete chunks; a trailing record or chunk cut
    short is ignored. Duck-types what ``bags`` uses of rosbags' ``AnyReader`` (``topics``,
    ``connections``, ``messages(connections)``, ``deserialize``, ``close``)."""

    def __init__(self, path):
        from rosbags.typesys import Stores, get_typestore
        self.path = Path(path)
        self.store = get_typestore(Stores.ROS2_HUMBLE)
        data = self.path.read_bytes()
        if len(data) < len(_MAGIC) and _MAGIC.startswith(data):
            raise NotReadyYet(f"{self.path}: nothing written yet")
        if not data.startswith(_MAGIC):
            raise ValueError(f"{self.path}: not an MCAP file (bad magic)")
        schemas, channels, self._messages = {}, {}, []
        self._scan(memoryview(data)[len(_MAGIC):], schemas, channels, top=True)
        self.connections = [_Connection(c, t, schemas.get(s, "")) for c, (t, s) in
                            sorted(channels.items())]
        counts = {}
        for cid, _, _ in self._messages:
            counts[cid] = counts.get(cid, 0) + 1
        self.topics = {c.topic: _TopicInfo(c.msgtype, counts.get(c.id, 0))
                       for c in self.connections}
        self._by_id = {c.id: c for c in self.connections}

    def _scan(self, view, schemas, channels, top: bool):
        pos, n = 0, len(view)
        while pos + 9 <= n:
            op = view[pos]
            (length,) = struct.unpack_from("<Q", view, pos + 1)
            body_start, end = pos + 9, pos + 9 + length
            if end > n:
                return                      # the record being written
            body = io.BytesIO(view[body_start:end])
            if op == 0x03:                  # Schema: id u16, name, encoding, data
                (sid,) = struct.unpack("<H", body.read(2))
                schemas[sid] = _string(body)
            elif op == 0x04:                # Channel: id u16, schema id u16, topic, ...
                cid, sid = struct.unpack("<HH", body.read(4))
                channels[cid] = (_string(body), sid)
            elif op == 0x05:                # Message: channel u16, seq u32, log, publish
                cid, _, log_time, _ = struct.unpack_from("<HIQQ", view, body_start)
                self._messages.append((cid, log_time, bytes(view[body_start + 22:end])))
            elif op == 0x06 and top:        # Chunk: start, end, size, crc, compression, records
                _, _, size, _ = struct.unpack("<QQQI", body.read(28))
                compression = _string(body)
                (clen,) = struct.unpack("<Q", body.read(8))
                records = _decompress(body.read(clen), compression, size)
                self._scan(memoryview(records), schemas, channels, top=False)
            elif op == 0x0F or op == 0x02:  # DataEnd or Footer: the file is complete
                return
            pos = end

    def open(self):
        return self

    def messages(self, connections=()):
        wanted = {c.id for c in connections} if connections else None
        rows = sorted((t, k, cid, raw) for k, (cid, t, raw) in enumerate(self._messages)
                      if wanted is None or cid in wanted)
        for t, _, cid, raw in rows:
            yield self._by_id[cid], t, raw

    def deserialize(self, raw, msgtype):
        return self.store.deserialize_cdr(raw, msgtype)

    def close(self):
        pass


# ----------------------------------------------------------------------------- the follower
def _storage_of(path: Path) -> Path:
    """What to open now: the bag directory once ``metadata.yaml`` exists, else its storage
    file (the recorder writes the metadata last); a file as it is."""
    if path.is_dir():
        if (path / "metadata.yaml").is_file():
            return path
        files = sorted(p for p in path.iterdir() if p.suffix in (".db3", ".mcap"))
        if not files:
            raise NotReadyYet(f"{path}: no .db3 or .mcap file yet")
        if len(files) > 1:
            raise ValueError(f"{path}: {len(files)} storage files without metadata.yaml (a "
                             "split bag being recorded): follow the newest file instead")
        return files[0]
    return path


class _Opened:
    """``bags._opened`` for a bag that may be mid-write: a growing MCAP file falls back to
    ``PartialMcapReader``."""

    def __init__(self, path: Path):
        self.path = path

    def __enter__(self):
        target = _storage_of(self.path)
        try:
            self.reader, self.bag = bags._opened(target)
        except ValueError:
            if target.suffix != ".mcap":
                raise
            self.reader, self.bag = PartialMcapReader(target), str(target)
        return self.reader, self.bag

    def __exit__(self, *exc):
        self.reader.close()


#: What ``bags.read_bag`` says of a recording that has not got that far yet (no camera message,
#: the robot's tf chain not published, or not moving yet); a follower waits for more data.
_NOT_YET = (" has no messages", ": no topic ", "no /tf or /tf_static topic", "is not in /tf",
            "no transform chain", "only has static", "never overlap")


def _not_yet(text: str) -> bool:
    return any(k in text for k in _NOT_YET)


def _mid_write_errors() -> tuple:
    """What SQLite raises when a read meets a transaction the recorder is writing: a page not
    yet consistent ("database disk image is malformed"), a lock. A follower retries at the next
    poll (a bag that stays unreadable ends the session at its timeout, with this error)."""
    import sqlite3
    errors = [sqlite3.DatabaseError]
    try:
        import apsw  # rosbags' SQLite driver
        errors += [apsw.CorruptError, apsw.BusyError, apsw.LockedError]
    except ImportError:
        pass
    return tuple(errors)


class BagFollower:
    """Polls a (growing) bag for new samples (module docstring).

    Args:
        path: the bag (ROS 2 directory, ``.db3``, ``.mcap``; a finished ROS 1 ``.bag``).
        must_exist: False for a live session that may start before the recorder creates the
            bag (polls wait for it; the session's idle timeout ends the wait).
        robot_frames: "BASE:EE" or (BASE, EE): X_BE from tf.
        camera_topic / camera_frames / image_topic: the camera source, exactly one
            (``bags.read_bag``'s meanings; images are returned as arrays for the caller's
            detector).
        camera_invert: the camera topic (or frames) hold X_TC.
        camera_info_topic: with ``image_topic``, the ``CameraInfo`` topic (default:
            ``camera_info`` beside the image topic, as ``calibrate`` finds it; "none": ignore).

    ``camera_info`` is the first ``bags.CameraInfo`` read (None until one is; its topic in
    ``camera_info_from``); ``robot`` the robot's whole tf stream read so far (a
    ``PoseStream`` with timestamps: what the clock offset is estimated from).
    ``poll()`` returns a list of new samples, each {"X_BE", "X_CT" or "image", "stamp",
    "where"}; ``dropped`` lists (where, why) of camera messages that gave none; ``waiting`` is
    True while the bag could not be read or a camera message awaits later robot poses.
    Bad arguments, a missing topic or frame: ValueError naming it (as ``read_bag``).
    """

    def __init__(self, path, robot_frames="base_link:tool0", camera_topic=None,
                 camera_frames=None, image_topic=None, camera_invert: bool = False,
                 camera_info_topic: str | None = None, must_exist: bool = True):
        self.path = Path(path)
        # A live session may start before the recorder has created the bag (must_exist=False):
        # polls then wait for it, as for a bag not readable yet.
        if must_exist and not self.path.exists():
            raise ValueError(f"{self.path}: no such file or directory")
        given = [x is not None for x in (camera_topic, camera_frames, image_topic)]
        if sum(given) != 1:
            raise ValueError("camera_topic, camera_frames, image_topic: give exactly one camera "
                             "source")
        self.robot_frames = bags._pair(robot_frames, "robot_frames")
        self.camera_topic, self.image_topic = camera_topic, image_topic
        self.camera_frames = None if camera_frames is None else bags._pair(camera_frames,
                                                                           "camera_frames")
        self.camera_invert = bool(camera_invert)
        self.camera_info_topic = camera_info_topic
        self.camera_info, self.camera_info_from = None, None
        self.robot = None
        self._done_stamps = set()       # camera stamps (ns) returned or dropped
        self._images_seen = 0           # image messages returned or dropped
        self.dropped = []
        self.waiting = False
        self.last_error = ""

    def _read(self, reader, bag):
        """(robot stream or None, [(stamp s, X_CT, where)]) from an open reader."""
        try:
            data = bags._read(reader, bag, self.robot_frames,
                              self.camera_topic, self.camera_frames, None, None,
                              self.camera_invert, None)
        except ValueError as e:
            # Nothing of the camera or the chain yet is normal at the start of a recording.
            if not _not_yet(str(e)):
                raise
            self.last_error = str(e)
            return None, []
        rows = []
        if data.camera is not None:
            lines = data.camera.lines
            for k, (t, X) in enumerate(zip(data.camera.timestamps, data.camera.poses)):
                rows.append((float(t), X, f"{bag}: camera message {lines[k]}"))
        return data.robot, rows

    def _images(self, reader, bag):
        topics = bags._topics(reader)
        if self.image_topic not in topics:
            return []
        bags.require_topic(bag, topics, self.image_topic,
                           (bags.IMAGE_TYPE, bags.COMPRESSED_IMAGE_TYPE), "image_topic")
        out, k = [], 0
        conns = [c for c in reader.connections if c.topic == self.image_topic]
        for connection, _, raw in reader.messages(connections=conns):
            k += 1
            if k <= self._images_seen:
                continue            # returned before: not deserialized again
            where = f"{bag}: {self.image_topic} message {k}"
            msg = reader.deserialize(raw, connection.msgtype)
            out.append((bags._stamp(msg.header), bags.decode_image(msg, connection.msgtype,
                                                                   where), where, k))
        return out

    def poll(self) -> list[dict]:
        """The samples that became complete since the last poll (bag order)."""
        if not self.path.exists():
            self.waiting, self.last_error = True, f"{self.path}: not there yet"
            return []
        try:
            with _Opened(self.path) as (reader, bag):
                robot, rows = self._read(reader, bag) if self.image_topic is None else (
                    self._read_robot(reader, bag), None)
                images = self._images(reader, bag) if self.image_topic is not None else []
        except FileNotFoundError as e:
            self.waiting, self.last_error = True, str(e)
            return []
        except ValueError as e:
            text = str(e)
            if "cannot read as a ROS bag" in text or "database is locked" in text:
                self.waiting, self.last_error = True, text   # mid-write: next poll
                return []
            raise
        except _mid_write_errors() as e:
            self.waiting = True
            self.last_error = f"{self.path}: unreadable while being written ({e}); retrying"
            return []
        interp = None
        if robot is not None:
            self.robot = robot
        if robot is not None and len(robot.poses):
            interp = PoseInterpolator(robot.timestamps, robot.poses)
        out, waiting = [], False
        items = ([(t, {"X_CT": X}, w, None) for t, X, w in rows] if rows is not None else
                 [(t, {"image": img}, w, k) for t, img, w, k in images])
        for t, payload, where, k in items:
            key = round(t * 1e9)
            if key in self._done_stamps:
                continue
            if interp is None or t > interp.span[1]:
                waiting = True                  # the robot pose at t is not recorded yet
                break                           # keep the order: later ones wait too
            self._done_stamps.add(key)
            if k is not None:
                self._images_seen = k
            if t < interp.span[0]:
                self.dropped.append((where, "before the first robot pose"))
                continue
            out.append({"X_BE": interp(np.array([t]))[0], "stamp": t, "where": where,
                        **payload})
        self.waiting = waiting
        return out

    def _read_robot(self, reader, bag):
        info_topic = None
        if self.camera_info is None and self.camera_info_topic != "none":
            topics = bags._topics(reader)
            info_topic = self.camera_info_topic or bags.find_camera_info(
                self.image_topic, topics, only_beside=True)
            if info_topic is not None and info_topic not in topics:
                info_topic = None       # not recorded yet: next poll
        try:
            data = bags._read(reader, bag, self.robot_frames, None, None, None, info_topic,
                              False, None)
            if data.camera_info is not None:
                self.camera_info, self.camera_info_from = data.camera_info, info_topic
            return data.robot
        except ValueError as e:
            if not _not_yet(str(e)):
                raise
            self.last_error = str(e)
            return None


__all__ = ["BagFollower", "PartialMcapReader"]

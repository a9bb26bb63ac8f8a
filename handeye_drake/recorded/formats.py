"""Readers of recorded pose streams: TUM trajectories, CSV 4×4 matrices, OpenCV FileStorage YAML.

Every reader returns a ``PoseStream``: N rigid poses (N, 4, 4), optional timestamps (seconds,
strictly increasing) and, for each sample, the line of the file it came from, so that every later
error can name ``FILE:LINE``. Frames: the robot stream holds ``X_BE`` (end-effector E in base B,
OpenCV's gripper→base); the camera stream holds ``X_CT`` (target T in camera C, OpenCV's
target→camera), or ``X_TC`` (camera in target) when the file says so (``camera_in_target``).

Formats
-------
``tum``: one pose per line, ``timestamp tx ty tz qx qy qz qw`` (TUM RGB-D convention: Hamilton
quaternion, scalar last), separated by spaces and/or commas; ``#`` starts a comment.

``csv-matrix``: one row-major 4×4 homogeneous matrix per line (16 numbers), optionally preceded
by a timestamp (17 numbers); every line of a file must have the same count; separators and
comments as in ``tum`` (a header line must therefore start with ``#``).

``opencv-yaml``: what ``cv::FileStorage`` writes (``%YAML:1.0`` header, ``!!opencv-matrix``
nodes with ``rows``/``cols``/``dt``/``data``). A small dedicated reader parses it (PyYAML does not
understand ``%YAML:1.0`` and may be absent). Accepted top-level keys:

- robot stream: sequences ``R_gripper2base`` and ``t_gripper2base`` (the inputs of
  ``cv::calibrateHandEye``), or ``robot_poses`` / ``poses``: a sequence of 4×4 matrices;
- camera stream: ``R_target2cam`` and ``t_target2cam`` (X_CT), or ``R_cam2target`` and
  ``t_cam2target`` (X_TC, inverted on reading), or ``camera_poses`` / ``poses`` (4×4 matrices,
  X_CT, or X_TC with ``camera_in_target``);
- optional timestamps (seconds): ``robot_timestamps`` / ``camera_timestamps`` or
  ``timestamps``, as an ``!!opencv-matrix`` (N×1 or 1×N), a flow list ``[ ... ]`` or a block
  sequence of numbers.

Each R is a 3×3 matrix or a Rodrigues rotation vector (3×1 or 1×3, radians), as
``cv::calibrateHandEye`` accepts; each t a 3×1 or 1×3 matrix. Robot and camera keys may live
in the same file.

Checks (``ValueError`` naming the file and line): unreadable/empty files; malformed lines (field
count, non-numbers); NaN/inf; quaternions whose norm is off by more than
``QUATERNION_NORM_TOLERANCE`` (closer ones are normalized); rotation blocks farther than
``ROTATION_TOLERANCE`` from SO(3) (closer ones, e.g. printed with few decimals, are projected on
SO(3) with the SVD); a last matrix row other than [0, 0, 0, 1]; duplicate or decreasing
timestamps; translations longer than ``max_translation`` (default 10 m: millimetres?).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..estimation.orthonormalize import orthonormalize_unchecked
from ..estimation.se3 import inverse
from ..estimation.validation import rotation_defect

FORMATS = ("tum", "csv-matrix", "opencv-yaml")
STREAMS = ("robot", "camera")

#: A quaternion whose norm differs from 1 by at most this is normalized; beyond, an error.
QUATERNION_NORM_TOLERANCE = 1e-3
#: Largest accepted max(‖RᵀR − I‖_F, |det R − 1|) of a rotation block read from a file (what 4
#: printed decimals can cause); accepted blocks are projected on SO(3) (SVD).
ROTATION_TOLERANCE = 1e-3
#: Largest accepted deviation of a matrix's last row from [0, 0, 0, 1].
HOMOGENEOUS_ROW_TOLERANCE = 1e-6
#: Default largest accepted translation norm (metres): a pose farther than 10 m from the robot
#: base or the camera is implausible and usually means millimetres.
MAX_TRANSLATION = 10.0

_SPLIT = re.compile(r"[,\s]+")
_MAX_FILE_BYTES = 200 * 1024 * 1024


@dataclass(frozen=True)
class PoseStream:
    """A validated sequence of rigid poses read from a file.

    Attributes:
        poses: (N, 4, 4) rigid transforms (X_BE for a robot stream, X_CT for a camera stream).
        timestamps: (N,) seconds, strictly increasing, or None when the file has none (samples
            are then paired with the other stream by index).
        source: the file name used in messages.
        lines: for each sample, its line number in ``source`` (1-based).
    """

    poses: np.ndarray
    timestamps: np.ndarray | None
    source: str
    lines: tuple

    def __len__(self) -> int:
        return len(self.poses)

    @property
    def has_timestamps(self) -> bool:
        return self.timestamps is not None

    def where(self, i: int) -> str:
        """``FILE:LINE`` of sample i, for messages."""
        return f"{self.source}:{self.lines[i]}"

    def inverted(self) -> "PoseStream":
        """The same samples with every pose inverted (e.g. X_TC → X_CT)."""
        return PoseStream(np.array([inverse(X) for X in self.poses]).reshape(-1, 4, 4),
                          self.timestamps, self.source, self.lines)


def _err(source: str, line, message: str) -> ValueError:
    where = f"{source}:{line}" if line is not None else source
    return ValueError(f"{where}: {message}")


def _number(token: str, source: str, line: int, what: str) -> float:
    try:
        return float(token)
    except ValueError:
        raise _err(source, line, f"{what}: {token[:40]!r} is not a number") from None


# ----------------------------------------------------------------------------------- validation
def pose_stream(poses, timestamps=None, source: str = "poses", lines=None,
                translation_scale: float = 1.0,
                max_translation: float | None = MAX_TRANSLATION) -> PoseStream:
    """Builds a validated ``PoseStream`` from arrays (what every reader ends with).

    Args:
        poses: (N, 4, 4) homogeneous transforms, N ≥ 1.
        timestamps: None or (N,) finite seconds, strictly increasing.
        source: name used in error messages (a file name).
        lines: line number of each sample in ``source`` (default 1..N).
        translation_scale: factor applied to every translation (e.g. 0.001 for millimetres).
        max_translation: translations longer than this (after scaling) raise ValueError (units
            look wrong); None disables the check.

    Rotation blocks within ``ROTATION_TOLERANCE`` of SO(3) are projected on it.
    """
    source = str(source)
    try:
        P = np.array(poses, dtype=float)
    except (TypeError, ValueError, OverflowError) as e:
        raise _err(source, None, f"poses: expected numbers ({e})") from None
    if P.ndim != 3 or P.shape[1:] != (4, 4):
        raise _err(source, None, f"poses: expected an array of shape (N, 4, 4), got {P.shape}")
    n = len(P)
    if n == 0:
        raise _err(source, None, "no pose samples (the file is empty or only has comments)")
    if lines is None:
        lines = tuple(range(1, n + 1))
    try:
        lines = tuple(int(v) for v in lines)
    except (TypeError, ValueError, OverflowError):
        raise _err(source, None, "lines: expected a sequence of line numbers") from None
    if len(lines) != n:
        raise _err(source, None, f"lines: expected {n} line numbers, got {len(lines)}")
    scale = _finite_positive(translation_scale, "translation_scale")
    if max_translation is not None:
        max_translation = _finite_positive(max_translation, "max_translation")
    out = np.empty_like(P)
    for i in range(n):
        X = P[i]
        if not np.all(np.isfinite(X)):
            raise _err(source, lines[i], "pose contains NaN or infinite values")
        bottom = np.abs(X[3] - [0.0, 0.0, 0.0, 1.0]).max()
        if bottom > HOMOGENEOUS_ROW_TOLERANCE:
            hint = ""
            if np.abs(X[:, 3] - [0.0, 0.0, 0.0, 1.0]).max() <= HOMOGENEOUS_ROW_TOLERANCE:
                hint = " (the last column is [0, 0, 0, 1]: the matrix looks column-major, " \
                       "write it row by row)"
            raise _err(source, lines[i], "last row of a homogeneous transform must be "
                       f"[0, 0, 0, 1], got {np.round(X[3], 6).tolist()}{hint}")
        out[i] = _rigid(X[:3, :3], X[:3, 3] * scale, source, lines[i])
    if max_translation is not None:
        with np.errstate(over="ignore"):  # huge translations: inf, refused below
            norms = np.linalg.norm(out[:, :3, 3], axis=1)
        i = int(np.argmax(norms))
        if norms[i] > max_translation:
            raise _err(source, lines[i], f"translation of length {norms[i]:.6g} exceeds "
                       f"{max_translation:g}: poses are expected in metres — are these "
                       "millimetres? Rescale them (translation_scale=0.001, command line "
                       "--translation-scale 0.001) or raise max_translation")
    t = None
    if timestamps is not None:
        try:
            t = np.array(timestamps, dtype=float).reshape(-1)
        except (TypeError, ValueError, OverflowError) as e:
            raise _err(source, None, f"timestamps: expected numbers ({e})") from None
        if np.ndim(timestamps) != 1 or len(t) != n:
            raise _err(source, None, f"timestamps: expected {n} values (one per pose), got "
                       f"shape {np.shape(timestamps)}")
        for i in range(n):
            if not math.isfinite(t[i]):
                raise _err(source, lines[i], f"timestamp {t[i]} is not finite")
        for i in range(1, n):
            if t[i] == t[i - 1]:
                raise _err(source, lines[i], f"duplicate timestamp {float(t[i])!r} (same as line "
                           f"{lines[i - 1]}); timestamps must be strictly increasing")
            if t[i] < t[i - 1]:
                raise _err(source, lines[i], f"timestamp {float(t[i])!r} is earlier than the "
                           f"previous sample's {float(t[i - 1])!r} (line {lines[i - 1]}); samples "
                           "must be "
                           "sorted by time")
    return PoseStream(out, t, source, lines)


def _finite_positive(value, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise ValueError(f"{name}: must be finite and > 0, got {value!r}")
    return v


def _rigid(R: np.ndarray, t: np.ndarray, source: str, line: int) -> np.ndarray:
    """4×4 rigid transform from a near-rotation (projected on SO(3)) and a translation."""
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(t))):
        raise _err(source, line, "pose contains NaN or infinite values")
    defect = rotation_defect(R) if np.abs(R).max() < 1e3 else math.inf
    if not defect <= ROTATION_TOLERANCE:
        raise _err(source, line, "rotation block is not a rotation matrix: max(‖RᵀR − I‖_F, "
                   f"|det R − 1|) = {defect:.3g} > tolerance {ROTATION_TOLERANCE:g} "
                   f"(det = {np.linalg.det(R) if math.isfinite(defect) else math.nan:.6g})")
    X = np.eye(4)
    X[:3, :3] = orthonormalize_unchecked(R, "svd")
    X[:3, 3] = t
    if not np.all(np.isfinite(X)):
        raise _err(source, line, "pose is not finite after scaling the translation")
    return X


def _quaternion_rotation(q_xyzw: np.ndarray, source: str, line: int) -> np.ndarray:
    with np.errstate(over="ignore"):  # a huge quaternion: inf norm, refused below
        norm = float(np.linalg.norm(q_xyzw))
    if not abs(norm - 1.0) <= QUATERNION_NORM_TOLERANCE:
        raise _err(source, line, f"quaternion (qx qy qz qw) = {np.round(q_xyzw, 6).tolist()} "
                   f"has norm {norm:.6g}, not 1 (tolerance {QUATERNION_NORM_TOLERANCE:g}); "
                   "expected a unit quaternion")
    return Rotation.from_quat(q_xyzw / norm).as_matrix()


# ----------------------------------------------------------------------------------- text files
def read_text(path) -> tuple[str, str]:
    """(text, source name) of a file; OSError and decoding errors become ValueError."""
    p = Path(path)
    try:
        if p.stat().st_size > _MAX_FILE_BYTES:
            raise _err(str(p), None, f"file is larger than {_MAX_FILE_BYTES >> 20} MB")
        data = p.read_bytes()
    except OSError as e:
        raise _err(str(p), None, f"cannot read the file ({e.strerror or e})") from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        raise _err(str(p), line, "not a text file (invalid UTF-8)") from None
    if "\x00" in text:
        line = text[:text.index("\x00")].count("\n") + 1
        raise _err(str(p), line, "not a text file (NUL byte)")
    return text, str(p)


def _data_lines(text: str):
    """(line number, fields) of the non-empty, non-comment lines."""
    for number, raw in enumerate(text.splitlines(), start=1):
        content = raw.split("#", 1)[0].strip()
        if content:
            yield number, [f for f in _SPLIT.split(content) if f]


def parse_tum(text: str, source: str = "<tum>", translation_scale: float = 1.0,
              max_translation: float | None = MAX_TRANSLATION) -> PoseStream:
    """Parses TUM lines ``timestamp tx ty tz qx qy qz qw`` (see the module docstring)."""
    stamps, poses, lines = [], [], []
    for number, fields in _data_lines(text):
        if len(fields) != 8:
            raise _err(source, number, f"expected 8 numbers (timestamp tx ty tz qx qy qz qw), "
                       f"got {len(fields)}")
        v = np.array([_number(f, source, number, "tum field") for f in fields])
        if not np.all(np.isfinite(v)):
            raise _err(source, number, "contains NaN or infinite values")
        X = np.eye(4)
        X[:3, :3] = _quaternion_rotation(v[4:8], source, number)
        X[:3, 3] = v[1:4]
        stamps.append(v[0])
        poses.append(X)
        lines.append(number)
    return pose_stream(np.array(poses).reshape(-1, 4, 4), stamps if poses else None, source,
                       lines, translation_scale, max_translation)


def parse_csv_matrix(text: str, source: str = "<csv>", translation_scale: float = 1.0,
                     max_translation: float | None = MAX_TRANSLATION) -> PoseStream:
    """Parses one row-major 4×4 matrix per line, optionally after a timestamp (16 or 17
    numbers, the same count on every line)."""
    stamps, poses, lines = [], [], []
    count = None
    for number, fields in _data_lines(text):
        if len(fields) not in (16, 17):
            raise _err(source, number, "expected 16 numbers (a row-major 4×4 matrix) or 17 "
                       f"(timestamp + matrix), got {len(fields)} (header lines must start "
                       "with '#')")
        if count is None:
            count = len(fields)
        elif len(fields) != count:
            raise _err(source, number, f"expected {count} numbers like line {lines[0]}, got "
                       f"{len(fields)}: every line must have a timestamp, or none")
        v = np.array([_number(f, source, number, "csv field") for f in fields])
        if not np.all(np.isfinite(v)):
            raise _err(source, number, "contains NaN or infinite values")
        if count == 17:
            stamps.append(v[0])
        poses.append(v[-16:].reshape(4, 4))
        lines.append(number)
    return pose_stream(np.array(poses).reshape(-1, 4, 4), stamps if stamps else None, source,
                       lines, translation_scale, max_translation)


# ----------------------------------------------------------------------------- OpenCV YAML
@dataclass
class _Node:
    value: object  # float | str | list[_Node] | dict[str, _Node] | np.ndarray | None
    line: int


class _YamlReader:
    """Indentation parser of the YAML subset cv::FileStorage writes: block mappings and
    sequences, flow lists of numbers, scalars and ``!!opencv-matrix`` nodes."""

    MAX_DEPTH = 16

    def __init__(self, text: str, source: str):
        self.source = source
        self.lines = []  # (number, indent, content)
        for number, raw in enumerate(text.splitlines(), start=1):
            if "\t" in raw[:len(raw) - len(raw.lstrip())]:
                raise _err(source, number, "tab in indentation (YAML indents with spaces)")
            content = re.sub(r"(^|\s)#.*$", "", raw).rstrip()
            if content.strip():
                self.lines.append((number, len(content) - len(content.lstrip()),
                                   content.strip()))
        if not self.lines:
            raise _err(source, None, "no pose samples (the file is empty or only has comments)")
        number, _, first = self.lines[0]
        if not first.startswith("%YAML"):
            raise _err(source, number, "not an OpenCV YAML file: expected a '%YAML:1.0' header "
                       "on the first line")
        self.lines.pop(0)
        while self.lines and self.lines[0][2] == "---":
            self.lines.pop(0)
        if self.lines and self.lines[-1][2] == "...":
            self.lines.pop()
        self.i = 0

    def parse(self) -> dict:
        if not self.lines:
            raise _err(self.source, None, "no pose samples (the YAML document is empty)")
        number, indent, _ = self.lines[0]
        if indent != 0:
            raise _err(self.source, number, "unexpected indentation of the first key")
        root = self._mapping(0, 0)
        if self.i < len(self.lines):
            raise _err(self.source, self.lines[self.i][0], "unexpected content (check the "
                       "indentation)")
        return root.value

    def _block(self, indent: int, depth: int) -> _Node:
        number, _, content = self.lines[self.i]
        if content == "-" or content.startswith("- "):
            return self._sequence(indent, depth)
        return self._mapping(indent, depth)

    def _mapping(self, indent: int, depth: int) -> _Node:
        if depth > self.MAX_DEPTH:
            raise _err(self.source, self.lines[self.i][0], "structure nested too deeply")
        start = self.lines[self.i][0]
        out: dict[str, _Node] = {}
        while self.i < len(self.lines):
            number, ind, content = self.lines[self.i]
            if ind < indent:
                break
            if ind > indent:
                raise _err(self.source, number, "unexpected indentation")
            if content == "-" or content.startswith("- "):
                raise _err(self.source, number, "a sequence item where a 'key: value' line "
                           "was expected")
            m = re.match(r"^([A-Za-z_][\w\-.]*)\s*:(?:\s+(.*))?$", content)
            if m is None:
                raise _err(self.source, number, f"expected 'key: value', got "
                           f"{content[:60]!r}")
            key = m.group(1)
            if key in out:
                raise _err(self.source, number, f"duplicate key {key!r} (first at line "
                           f"{out[key].line})")
            self.i += 1
            # Messages about a key name the key's line, not its value's first line.
            out[key] = _Node(self._value(m.group(2) or "", number, indent, depth).value, number)
        return _Node(out, start)

    def _sequence(self, indent: int, depth: int) -> _Node:
        if depth > self.MAX_DEPTH:
            raise _err(self.source, self.lines[self.i][0], "structure nested too deeply")
        start = self.lines[self.i][0]
        items = []
        while self.i < len(self.lines):
            number, ind, content = self.lines[self.i]
            if ind < indent:
                break
            if ind > indent:
                raise _err(self.source, number, "unexpected indentation")
            if not (content == "-" or content.startswith("- ")):
                raise _err(self.source, number, "expected a sequence item '- ...'")
            rest = content[1:].strip()
            self.i += 1
            if re.match(r"^[A-Za-z_][\w\-.]*\s*:(\s|$)", rest):
                raise _err(self.source, number, "inline mappings in sequence items are not "
                           "supported; write '-' alone, then the keys indented below")
            items.append(self._value(rest, number, indent, depth))
        return _Node(items, start)

    def _value(self, rest: str, number: int, indent: int, depth: int) -> _Node:
        tag = None
        if rest.startswith("!!"):
            parts = rest.split(None, 1)
            tag, rest = parts[0][2:], (parts[1] if len(parts) > 1 else "")
            if tag != "opencv-matrix":
                raise _err(self.source, number, f"unsupported tag !!{tag} (only "
                           "!!opencv-matrix)")
        if rest.startswith("["):
            node = self._flow_list(rest, number)
        elif rest.startswith("{"):
            raise _err(self.source, number, "flow mappings '{...}' are not supported")
        elif rest:
            node = _Node(_scalar(rest), number)
        elif self.i < len(self.lines) and self.lines[self.i][1] > indent:
            node = self._block(self.lines[self.i][1], depth + 1)
        elif (self.i < len(self.lines) and self.lines[self.i][1] == indent
              and re.match(r"^-(\s|$)", self.lines[self.i][2])):
            node = self._sequence(indent, depth + 1)  # "key:" then "- item" at the same indent
        else:
            node = _Node(None, number)
        if tag == "opencv-matrix":
            return _Node(self._matrix(node, number), number)
        return node

    def _flow_list(self, rest: str, number: int) -> _Node:
        text = rest
        while "]" not in text:
            if self.i >= len(self.lines):
                raise _err(self.source, number, "unterminated '[' list")
            text += " " + self.lines[self.i][2]
            self.i += 1
        body, _, after = text[1:].partition("]")
        if after.strip():
            raise _err(self.source, number, f"unexpected text after ']': {after.strip()[:40]!r}")
        if "[" in body:
            raise _err(self.source, number, "nested lists are not supported")
        tokens = [t.strip() for t in body.split(",")]
        if tokens == [""]:
            return _Node([], number)
        values = []
        for t in tokens:
            v = _scalar(t)
            if not isinstance(v, float):
                raise _err(self.source, number, f"list element {t[:40]!r} is not a number")
            values.append(_Node(v, number))
        return _Node(values, number)

    def _matrix(self, node: _Node, number: int) -> np.ndarray:
        if not isinstance(node.value, dict):
            raise _err(self.source, number, "!!opencv-matrix must be followed by rows, cols, dt "
                       "and data")
        d = node.value
        for key in ("rows", "cols", "data"):
            if key not in d:
                raise _err(self.source, number, f"!!opencv-matrix without '{key}'")
        dims = []
        for key in ("rows", "cols"):
            v = d[key].value
            if not (isinstance(v, float) and v.is_integer() and 1 <= v <= 10_000):
                raise _err(self.source, d[key].line, f"matrix {key} must be an integer in "
                           f"[1, 10000], got {v!r}")
            dims.append(int(v))
        dt = d["dt"].value if "dt" in d else "d"
        if not (isinstance(dt, str) and re.fullmatch(r"1?[ucwsifdh]", dt)):
            raise _err(self.source, d["dt"].line if "dt" in d else number,
                       f"unsupported matrix type dt = {dt!r} (single-channel numbers only)")
        data = d["data"].value
        if not isinstance(data, list) or not all(isinstance(x.value, float) for x in data):
            raise _err(self.source, d["data"].line, "matrix data must be a list of numbers")
        if len(data) != dims[0] * dims[1]:
            raise _err(self.source, d["data"].line, f"matrix data has {len(data)} numbers, "
                       f"rows × cols = {dims[0]} × {dims[1]} = {dims[0] * dims[1]}")
        return np.array([x.value for x in data], dtype=float).reshape(dims)


_YAML_SPECIAL = {".nan": math.nan, ".inf": math.inf, "+.inf": math.inf, "-.inf": -math.inf}


def _scalar(text: str):
    """A YAML scalar: a float when it reads as a number (incl. .nan/.inf), else the string."""
    low = text.lower()
    if low in _YAML_SPECIAL:
        return _YAML_SPECIAL[low]
    if re.fullmatch(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?", text):
        return float(text)
    return text.strip("'\"")


def _seq_of_matrices(root: dict, key: str, source: str) -> list[_Node]:
    node = root[key]
    items = node.value if isinstance(node.value, list) else None
    if items is None:
        if isinstance(node.value, np.ndarray):
            items = [node]  # a single matrix instead of a one-element sequence
        else:
            raise _err(source, node.line, f"{key}: expected a sequence of !!opencv-matrix")
    for item in items:
        if not isinstance(item.value, np.ndarray):
            raise _err(source, item.line, f"{key}: sequence item is not an !!opencv-matrix")
    if not items:
        raise _err(source, node.line, f"{key}: empty sequence, no pose samples")
    return items


def _rotation_block(node: _Node, key: str, source: str) -> np.ndarray:
    M = node.value
    if M.shape == (3, 3):
        return M
    if M.shape in ((3, 1), (1, 3)):
        if not np.all(np.isfinite(M)):
            raise _err(source, node.line, f"{key}: contains NaN or infinite values")
        return Rotation.from_rotvec(M.reshape(3)).as_matrix()
    raise _err(source, node.line, f"{key}: expected a 3×3 rotation matrix or a 3×1 Rodrigues "
               f"vector, got {M.shape[0]}×{M.shape[1]}")


def _numbers(node: _Node, key: str, source: str) -> np.ndarray:
    v = node.value
    if isinstance(v, np.ndarray):
        if 1 not in v.shape:
            raise _err(source, node.line, f"{key}: expected an N×1 or 1×N matrix, got "
                       f"{v.shape[0]}×{v.shape[1]}")
        return v.reshape(-1)
    if isinstance(v, list) and all(isinstance(x.value, float) for x in v):
        return np.array([x.value for x in v], dtype=float)
    raise _err(source, node.line, f"{key}: expected a list of numbers")


def parse_opencv_yaml(text: str, stream: str, source: str = "<yaml>",
                      camera_in_target: bool = False, translation_scale: float = 1.0,
                      max_translation: float | None = MAX_TRANSLATION) -> PoseStream:
    """Parses a cv::FileStorage YAML file and returns its robot (X_BE) or camera (X_CT) stream.

    ``stream`` is "robot" or "camera"; see the module docstring for the accepted keys. With
    ``camera_in_target`` a ``camera_poses``/``poses`` list holds X_TC (inverted on reading);
    the keys ``R_cam2target``/``t_cam2target`` always do (and ``*_target2cam`` never, so the
    flag must agree with them).
    """
    if stream not in STREAMS:
        raise ValueError(f"stream: expected one of {STREAMS}, got {stream!r}")
    root = _YamlReader(text, source).parse()
    if stream == "robot":
        rt_keys, list_keys, stamp_keys = [("R_gripper2base", "t_gripper2base", False)], \
            ("robot_poses", "poses"), ("robot_timestamps", "timestamps")
    else:
        rt_keys = [("R_target2cam", "t_target2cam", False), ("R_cam2target", "t_cam2target", True)]
        list_keys, stamp_keys = ("camera_poses", "poses"), ("camera_timestamps", "timestamps")
    poses, lines, invert = None, None, False
    for R_key, t_key, inverted in rt_keys:
        if R_key in root or t_key in root:
            if R_key not in root or t_key not in root:
                have, missing = (R_key, t_key) if R_key in root else (t_key, R_key)
                raise _err(source, root[have].line, f"{have} without {missing}")
            if stream == "camera" and camera_in_target != inverted:
                raise _err(source, root[R_key].line, f"{R_key} holds "
                           f"{'X_TC (camera in target)' if inverted else 'X_CT (target in camera)'}"
                           f", which contradicts camera_in_target={camera_in_target} "
                           "(--camera-pose-is-camera-in-target)")
            Rs = _seq_of_matrices(root, R_key, source)
            ts = _seq_of_matrices(root, t_key, source)
            if len(Rs) != len(ts):
                raise _err(source, root[t_key].line, f"{R_key} has {len(Rs)} entries but "
                           f"{t_key} has {len(ts)}: mismatched lengths")
            poses, lines = [], []
            for R_node, t_node in zip(Rs, ts):
                R = _rotation_block(R_node, R_key, source)
                if t_node.value.shape not in ((3, 1), (1, 3)):
                    raise _err(source, t_node.line, f"{t_key}: expected a 3×1 translation, got "
                               f"{t_node.value.shape[0]}×{t_node.value.shape[1]}")
                X = np.eye(4)
                X[:3, :3], X[:3, 3] = R, t_node.value.reshape(3)
                poses.append(X)
                lines.append(R_node.line)
            invert = inverted
            break
    if poses is None:
        for key in list_keys:
            if key in root:
                items = _seq_of_matrices(root, key, source)
                for item in items:
                    if item.value.shape != (4, 4):
                        raise _err(source, item.line, f"{key}: expected 4×4 matrices, got "
                                   f"{item.value.shape[0]}×{item.value.shape[1]}")
                poses = [item.value for item in items]
                lines = [item.line for item in items]
                invert = stream == "camera" and camera_in_target
                break
    if poses is None:
        expected = " or ".join(f"{r}/{t}" for r, t, _ in rt_keys)
        raise _err(source, None, f"no {stream} poses: expected the keys {expected}, or a "
                   f"sequence {' or '.join(list_keys)} (found keys: "
                   f"{', '.join(sorted(root)) or 'none'})")
    stamps = None
    for key in stamp_keys:
        if key in root:
            stamps = _numbers(root[key], key, source)
            if len(stamps) != len(poses):
                raise _err(source, root[key].line, f"{key} has {len(stamps)} values for "
                           f"{len(poses)} poses: mismatched lengths")
            break
    result = pose_stream(np.array(poses).reshape(-1, 4, 4), stamps, source, lines,
                         translation_scale, max_translation)
    return result.inverted() if invert else result


# -------------------------------------------------------------------------------- entry point
_EXTENSIONS = {".tum": "tum", ".txt": "tum", ".csv": "csv-matrix", ".yaml": "opencv-yaml",
               ".yml": "opencv-yaml"}


def infer_format(path) -> str:
    """The format implied by a file's extension (.tum/.txt, .csv, .yaml/.yml)."""
    fmt = _EXTENSIONS.get(Path(path).suffix.lower())
    if fmt is None:
        raise ValueError(f"{path}: cannot infer the format from the extension "
                         f"{Path(path).suffix!r}; pass one of {', '.join(FORMATS)} "
                         "(--format)")
    return fmt


def parse_poses(text: str, fmt: str, stream: str, source: str = "<text>",
                camera_in_target: bool = False, translation_scale: float = 1.0,
                max_translation: float | None = MAX_TRANSLATION) -> PoseStream:
    """Parses the text of a pose file into the canonical stream: X_BE for ``stream="robot"``,
    X_CT for ``stream="camera"`` (camera-in-target files are inverted)."""
    if fmt not in FORMATS:
        raise ValueError(f"format: expected one of {', '.join(FORMATS)}, got {fmt!r}")
    if stream not in STREAMS:
        raise ValueError(f"stream: expected one of {STREAMS}, got {stream!r}")
    if fmt == "opencv-yaml":
        return parse_opencv_yaml(text, stream, source, camera_in_target, translation_scale,
                                 max_translation)
    parse = parse_tum if fmt == "tum" else parse_csv_matrix
    result = parse(text, source, translation_scale, max_translation)
    return result.inverted() if stream == "camera" and camera_in_target else result


def read_poses(path, stream: str, fmt: str | None = None, camera_in_target: bool = False,
               translation_scale: float = 1.0,
               max_translation: float | None = MAX_TRANSLATION) -> PoseStream:
    """Reads a pose file: X_BE (``stream="robot"``) or X_CT (``stream="camera"``).

    Args:
        path: the file.
        stream: "robot" or "camera".
        fmt: one of ``FORMATS``; None infers it from the extension (``infer_format``).
        camera_in_target: the camera file holds X_TC (camera in target); inverted on reading.
        translation_scale: factor applied to translations (0.001 for a file in millimetres).
        max_translation: plausibility bound on translation lengths (metres); None disables it.

    Raises:
        ValueError: naming the file (and line) for every problem listed in the module
            docstring.
    """
    fmt = infer_format(path) if fmt is None else fmt
    text, source = read_text(path)
    return parse_poses(text, fmt, stream, source, camera_in_target, translation_scale,
                       max_translation)

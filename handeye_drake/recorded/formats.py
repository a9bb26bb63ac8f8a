"""Readers of recorded pose streams: TUM trajectories, CSV 4×4 matrices, OpenCV FileStorage YAML.

Every reader returns a ``PoseStream``: N rigid poses (N, 4, 4), optional timestamps (seconds,
strictly increasing) and, for each sample, the line of the file it came from, so that every later
error can name ``FILE:LINE``. Frames: the robot stream holds ``X_BE`` (end-effector E in base B,
OpenCV's gripper→base); the camera stream holds ``X_CT`` (target T in camera C, OpenCV's
target→camera), or ``X_TC`` (camera in target) when the file says so (``camera_in_target``).

Formats
-------
``tum``: one pose per line, ``timestamp tx ty tz qx qy qz qw`` (TUM RGB-D convention: Hamilton
quaternion, scalar last), separated by spaces, tabs and/or commas; ``#`` starts a comment.

``csv-matrix``: one row-major 4×4 homogeneous matrix per line (16 numbers), optionally preceded
by a timestamp (17 numbers); every line of a file must have the same count; separators and
comments as in ``tum`` (a header line must therefore start with ``#``).

``csv-rotvec``: one pose per line, ``x y z rx ry rz`` (Universal Robots' pose: translation, then
the rotation vector — axis × angle, radians), optionally preceded by a timestamp (7 numbers);
separators, comments and the same-count rule as ``csv-matrix``.

``csv-euler:ORDER:UNIT``: one pose per line, ``x y z a1 a2 a3`` (optionally after a timestamp):
the rotation is three turns by a1, a2, a3 about the axes ORDER names, in that order — lowercase
``xyz``-letters are extrinsic (about the fixed parent axes: R = R_3(a3) · R_2(a2) · R_1(a1)),
UPPERCASE intrinsic (about the axes as they turn: R = R_1(a1) · R_2(a2) · R_3(a3)), exactly
``scipy.spatial.transform.Rotation.from_euler(ORDER, [a1, a2, a3])``; UNIT is ``deg`` or ``rad``.
KUKA's X Y Z A B C is ``csv-euler:ZYX:deg`` (A about z, then B about the new y, then C about the
newest x); Fanuc's X Y Z W P R is ``csv-euler:xyz:deg`` (W about the fixed x, P about the fixed
y, R about the fixed z). Both robots write millimetres: ``translation_scale=0.001``.

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

Reading
-------
``read_input`` reads an input exactly once, computing its SHA-256, under a byte cap
(``MAX_FILE_BYTES``) that holds for pipes, FIFOs and devices too (their reported size is 0): a
regular file is read in one call after its size is checked, anything else in chunks, stopping
at the cap or at the first chunk holding a NUL byte or invalid UTF-8 (so ``/dev/zero`` or
``/dev/urandom`` fail at once); ``read_poses`` parses those bytes and records the digest and the
byte count in the ``PoseStream``. TUM and CSV text is parsed in blocks of lines by numpy (a fast
path for plain ASCII numbers); a block the fast path does not accept (other characters, a wrong
field count, a token that is not a number) is re-read line by line, which either accepts it (e.g.
Unicode spaces, ``1_000``) or raises the precise ``FILE:LINE`` error. Reads and parses lasting
more than ``PROGRESS_DELAY_S`` show a progress bar on stderr when it is a terminal.

Checks (``ValueError`` naming the file and line): unreadable/empty files; binary content (the
line and byte offset of the first NUL or invalid UTF-8 byte); malformed lines (field count,
non-numbers; in each block of lines these come first, then the value checks, in line order);
NaN/inf; quaternions whose norm is off by more than ``QUATERNION_NORM_TOLERANCE`` (closer ones
are normalized); rotation blocks farther than ``ROTATION_TOLERANCE`` from SO(3) (closer ones,
e.g. printed with few decimals, are projected on SO(3): the nearest rotation); a last matrix row
other than [0, 0, 0, 1]; duplicate or decreasing timestamps; timestamps that are not seconds (beyond
``MAX_TIMESTAMP_SECONDS`` or with a median period beyond ``MAX_PERIOD_SECONDS``: the message
says whether they look like milliseconds, microseconds or nanoseconds and which ``time_scale``
fixes them); translations longer than ``max_translation`` (default 10 m: millimetres?); angles
that are not in the declared unit (a rotation vector or a radian angle beyond 2π: degrees; every
angle of a ``deg`` file within ±π: radians).
"""

from __future__ import annotations

import codecs
import dataclasses
import hashlib
import math
import os
import re
import stat
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

FORMATS = ("tum", "csv-matrix", "opencv-yaml", "csv-rotvec")
#: The parameterized format (``csv-euler:ORDER:UNIT``), its units, and every format's name.
EULER_FORMAT = "csv-euler"
ANGLE_UNITS = ("deg", "rad")
FORMAT_NAMES = FORMATS + ("csv-euler:ORDER:UNIT",)
#: A rotation vector or radian angle beyond 2π (+ this) is not in radians.
_TWO_PI = 2 * math.pi + 1e-6
STREAMS = ("robot", "camera")

#: A quaternion whose norm differs from 1 by at most this is normalized; beyond, an error.
QUATERNION_NORM_TOLERANCE = 1e-3
#: Largest accepted max(‖RᵀR − I‖_F, |det R − 1|) of a rotation block read from a file (what 4
#: printed decimals can cause); accepted blocks are projected on SO(3) (the nearest rotation).
ROTATION_TOLERANCE = 1e-3
#: Largest accepted deviation of a matrix's last row from [0, 0, 0, 1].
HOMOGENEOUS_ROW_TOLERANCE = 1e-6
#: Default largest accepted translation norm (metres): a pose farther than 10 m from the robot
#: base or the camera is implausible and usually means millimetres.
MAX_TRANSLATION = 10.0
#: Largest input read (bytes), for regular files and streams alike.
MAX_FILE_BYTES = 200 * 1024 * 1024
_MAX_FILE_BYTES = MAX_FILE_BYTES
#: Timestamps beyond ±1e11 s (3000 years) are not seconds: Unix time is 1.7e9 s, 1.7e12 ms,
#: 1.7e15 µs, 1.7e18 ns.
MAX_TIMESTAMP_SECONDS = 1e11
#: A median sampling period beyond 1e4 s (close to 3 hours) means the timestamps are not seconds.
MAX_PERIOD_SECONDS = 1e4
#: Reads and parses lasting longer than this (s) show a progress bar on stderr (terminals only).
PROGRESS_DELAY_S = 2.0

# Rotation blocks this close to SO(3) are kept as read (a quaternion's matrix is exact to
# rounding); farther ones, up to ROTATION_TOLERANCE, are projected on SO(3).
_PROJECTION_THRESHOLD = 1e-12
_READ_CHUNK = 1 << 20
_PARSE_CHUNK = 1 << 22
_BLOCK = 1 << 16  # poses validated at a time: bounded temporaries


# --------------------------------------------------------------------------------- line numbers
class LineNumbers(Sequence):
    """Read-only line numbers (1-based) of the samples of a stream, stored as one int64 array.

    Behaves like the tuple of ints it replaces (indexing gives ``int``, ``==`` compares with
    tuples and lists, iteration yields ``int``), without one Python object per sample;
    ``np.asarray(lines)`` gives the array, and indexing with a slice, a mask or an index array
    gives another ``LineNumbers``.
    """

    __slots__ = ("_a",)

    def __init__(self, values=()):
        a = np.asarray(values, dtype=np.int64).reshape(-1).view()  # no copy of an int64 array
        a.flags.writeable = False
        self._a = a

    def __len__(self) -> int:
        return len(self._a)

    def __getitem__(self, i):
        if isinstance(i, (int, np.integer)):
            return int(self._a[i])
        return LineNumbers(self._a[i])

    def __iter__(self):
        return iter(self._a.tolist())

    def __contains__(self, value) -> bool:
        try:
            return bool(np.any(self._a == int(value)))
        except (TypeError, ValueError, OverflowError):
            return False

    def __eq__(self, other):
        if isinstance(other, (LineNumbers, tuple, list)):
            b = np.asarray(other)
            return len(b) == len(self._a) and (len(b) == 0 or bool(np.array_equal(self._a, b)))
        return NotImplemented

    def __hash__(self) -> int:
        return hash(self._a.tobytes())

    def __array__(self, dtype=None, copy=None):
        return self._a if dtype is None else self._a.astype(dtype)

    def __repr__(self) -> str:
        if len(self._a) > 12:
            head = ", ".join(map(str, self._a[:6].tolist()))
            tail = ", ".join(map(str, self._a[-3:].tolist()))
            return f"LineNumbers([{head}, …, {tail}], {len(self._a)} lines)"
        return f"LineNumbers({self._a.tolist()})"


def _as_lines(lines, n: int, source: str) -> LineNumbers:
    if lines is None:
        return LineNumbers(np.arange(1, n + 1))
    if isinstance(lines, LineNumbers):
        a = np.asarray(lines)
    else:
        try:
            a = np.asarray(lines)
            if a.dtype.kind not in "iu":
                a = np.array([int(v) for v in np.asarray(lines, dtype=object).reshape(-1)],
                             dtype=np.int64)
        except (TypeError, ValueError, OverflowError):
            raise _err(source, None, "lines: expected a sequence of line numbers") from None
    if a.ndim != 1:
        raise _err(source, None, "lines: expected a sequence of line numbers")
    if len(a) != n:
        raise _err(source, None, f"lines: expected {n} line numbers, got {len(a)}")
    return LineNumbers(a)


@dataclass(frozen=True)
class PoseStream:
    """A validated sequence of rigid poses read from a file.

    Attributes:
        poses: (N, 4, 4) rigid transforms (X_BE for a robot stream, X_CT for a camera stream).
        timestamps: (N,) seconds, strictly increasing, or None when the file has none (samples
            are then paired with the other stream by index).
        source: the file name used in messages.
        lines: for each sample, its line number in ``source`` (1-based; ``LineNumbers``).
        sha256: hex SHA-256 of the bytes read (``read_poses``), None for parsed text.
        bytes_read: size of the input read (``read_poses``), None for parsed text.
    """

    poses: np.ndarray
    timestamps: np.ndarray | None
    source: str
    lines: LineNumbers
    sha256: str | None = None
    bytes_read: int | None = None

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
        return dataclasses.replace(self, poses=invert_poses(self.poses))


def invert_poses(X: np.ndarray) -> np.ndarray:
    """Inverses of a stack of rigid transforms (N, 4, 4) (uses Rᵀ: rigid input only)."""
    X = np.asarray(X, dtype=float).reshape(-1, 4, 4)
    out = np.zeros_like(X)
    Rt = np.swapaxes(X[:, :3, :3], 1, 2)
    out[:, :3, :3] = Rt
    with np.errstate(over="ignore", invalid="ignore"):  # huge translations: inf, refused later
        out[:, :3, 3] = -np.einsum("nij,nj->ni", Rt, X[:, :3, 3])
    out[:, 3, 3] = 1.0
    return out


def _err(source: str, line, message: str) -> ValueError:
    where = f"{source}:{line}" if line is not None else source
    return ValueError(f"{where}: {message}")


def _fmt(values) -> str:
    """Numbers for messages (``:.6g``: no overflow on huge values, unlike ``np.round``)."""
    return "[" + ", ".join(f"{float(v):.6g}" for v in np.asarray(values).reshape(-1)) + "]"


# ------------------------------------------------------------------------------------ progress
class _NoProgress:
    def update(self, n=1):
        pass

    def close(self):
        pass


def _progress(total, desc: str, enabled, unit: str = "B"):
    """A tqdm bar on stderr shown after ``PROGRESS_DELAY_S`` (``enabled`` None: on terminals
    only, so logs and captured output stay clean); stdout is never touched."""
    if enabled is None:
        enabled = hasattr(sys.stderr, "isatty") and sys.stderr.isatty()
    if not enabled:
        return _NoProgress()
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit=unit, unit_scale=unit == "B", unit_divisor=1024,
                delay=PROGRESS_DELAY_S, file=sys.stderr, leave=False, mininterval=0.5)


# ---------------------------------------------------------------------------------- raw input
@dataclass(frozen=True)
class InputFile:
    """The bytes of one input, read once (``read_input``).

    Attributes:
        data: the content (at most ``max_bytes``).
        source: the path as given, for messages.
        sha256: hex SHA-256 of ``data`` (what was actually read, also for pipes).
        size: ``len(data)``.
    """

    data: bytes
    source: str
    sha256: str
    size: int


_MAGIC = ((b"\xff\xfe", "UTF-16 text? save it as UTF-8"),
          (b"\xfe\xff", "UTF-16 text? save it as UTF-8"),
          (b"\x1f\x8b", "a gzip file: decompress it first"),
          (b"PK\x03\x04", "a zip archive: extract it first"),
          (b"\x89PNG", "a PNG image"),
          (b"#ROSBAG", "a ROS 1 bag: export the poses to a TUM or CSV file first"),
          (b"\x28\xb5\x2f\xfd", "zstd-compressed: decompress it first"),
          (b"SQLite format 3", "an SQLite database (a ROS 2 bag?): export the poses first"))


def _binary_error(source: str, data, offset: int, what: str) -> ValueError:
    line = data.count(b"\n", 0, offset) + 1
    hint = next((f"; {h}" for magic, h in _MAGIC if data.startswith(magic)), "")
    return _err(source, line, f"not a text file ({what} at byte offset {offset}{hint})")


def _first_bad_byte(data, start: int = 0):
    """(offset, description) of the first NUL byte or invalid UTF-8 sequence at or after
    ``start`` in ``data`` (decoded from 0, so offsets are absolute), or None."""
    nul = data.find(b"\x00", start)
    bad = None
    if not data[start:].isascii():
        try:
            bytes(data).decode("utf-8")
        except UnicodeDecodeError as e:
            bad = (e.start, f"invalid UTF-8 byte 0x{data[e.start]:02x}")
    if nul >= 0 and (bad is None or nul < bad[0]):
        return nul, "NUL byte"
    return bad


def _size(n: int) -> str:
    return f"{n / 2**20:g} MB" if n >= 2**20 else f"{n} bytes"


def read_input(path, max_bytes: int = MAX_FILE_BYTES, progress: bool | None = None) -> InputFile:
    """Reads a file, pipe, FIFO or device exactly once, checking it is text on the way.

    A regular file is read in one call (its size, checked first, bounds it). Anything else
    (pipe, FIFO, ``/dev/fd/N``, device) is read in chunks until end of file, at most
    ``max_bytes`` (+1 to detect more), hashing them; a chunk with a NUL byte or invalid UTF-8
    stops the read at once, so ``/dev/zero`` and ``/dev/urandom`` fail after one chunk.

    Raises:
        ValueError: ``PATH: cannot read the file (...)``; ``PATH: larger than N MB``;
            ``PATH:LINE: not a text file (NUL byte | invalid UTF-8 byte 0x.. at byte offset K)``.
    """
    source = str(path)
    h = hashlib.sha256()
    buf = bytearray()
    decoder = codecs.getincrementaldecoder("utf-8")()
    try:
        with open(path, "rb") as f:
            st = os.fstat(f.fileno())
            regular = stat.S_ISREG(st.st_mode)
            if regular and st.st_size > max_bytes:
                raise _err(source, None, f"file is larger than {_size(max_bytes)}")
            if regular:  # one read of the size it has (no buffer of the cap's size); a file
                data = f.read(st.st_size + 1)  # growing meanwhile still stops at the cap
                if len(data) > st.st_size:
                    data += f.read(max_bytes + 1 - len(data))
                if len(data) > max_bytes:
                    raise _err(source, None, f"file is larger than {_size(max_bytes)}")
                bad = _first_bad_byte(data)
                if bad is not None:
                    raise _binary_error(source, data, *bad)
                return InputFile(data, source, hashlib.sha256(data).hexdigest(), len(data))
            bar = _progress(None, f"reading {Path(source).name}", progress)
            try:
                while True:
                    chunk = f.read(min(_READ_CHUNK, max_bytes + 1 - len(buf)))
                    if not chunk:
                        break
                    start = len(buf)
                    buf += chunk
                    h.update(chunk)
                    bar.update(len(chunk))
                    if len(buf) > max_bytes:
                        raise _err(source, None, f"larger than {_size(max_bytes)}: reading "
                                   "stopped there (a device or a stream that does not end?)")
                    if b"\x00" in chunk or not chunk.isascii():
                        try:
                            decoder.decode(chunk)
                        except UnicodeDecodeError:
                            raise _binary_error(source, buf, *_first_bad_byte(buf)) from None
                        nul = chunk.find(b"\x00")
                        if nul >= 0:
                            raise _binary_error(source, buf, start + nul, "NUL byte")
                try:
                    decoder.decode(b"", final=True)
                except UnicodeDecodeError:
                    raise _binary_error(source, buf, *_first_bad_byte(buf)) from None
            finally:
                bar.close()
    except OSError as e:
        raise _err(source, None, f"cannot read the file ({e.strerror or e})") from None
    data = bytes(buf)
    del buf
    return InputFile(data, source, h.hexdigest(), len(data))


def read_text(path) -> tuple[str, str]:
    """(text, source name) of a file read once (``read_input``); a leading BOM is dropped."""
    raw = read_input(path)
    return _decode(raw.data, raw.source), raw.source


def _decode(data, source: str) -> str:
    bad = _first_bad_byte(data)
    if bad is not None:
        raise _binary_error(source, data, *bad)
    return bytes(data).decode("utf-8-sig")


def _as_bytes(text, source: str) -> bytes:
    """UTF-8 bytes of a parser's input (str or bytes), without a leading BOM."""
    if isinstance(text, str):
        data = text.encode("utf-8", "surrogatepass")  # surrogates: reported as non-numbers
    elif isinstance(text, (bytes, bytearray, memoryview)):
        data = bytes(text)
        bad = _first_bad_byte(data)
        if bad is not None:
            raise _binary_error(source, data, *bad)
    else:
        raise ValueError(f"text: expected str or bytes, got {type(text).__name__}")
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]
    if b"\x00" in data:
        raise _binary_error(source, data, data.index(b"\x00"), "NUL byte")
    return data


# ----------------------------------------------------------------------------------- validation
def _finite_positive(value, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise ValueError(f"{name}: must be finite and > 0, got {value!r}")
    return v


def _row_norms(v: np.ndarray) -> np.ndarray:
    """Euclidean norms of the rows of a finite (n, k) array, without overflow or underflow
    warnings (1e308 and 1e-320 are fine)."""
    with np.errstate(over="ignore", under="ignore"):
        norms = np.sqrt(np.einsum("ij,ij->i", v, v))
    redo = ~((norms > 1e-150) & (norms < 1e150))  # overflowed or underflowed: rescale
    if redo.any():
        w = v[redo]
        m = np.abs(w).max(axis=1, initial=0.0)
        safe = np.where(m > 0, m, 1.0)
        with np.errstate(under="ignore", over="ignore"):  # inf for norms beyond 1.8e308
            norms[redo] = m * np.sqrt(np.sum((w / safe[:, None]) ** 2, axis=1))
    return norms


def _rotation_defects(R: np.ndarray) -> np.ndarray:
    """max(‖RᵀR − I‖_F, |det R − 1|) of a stack of finite 3×3 blocks; inf for entries ≥ 1e3
    (far from any rotation; computing them could overflow)."""
    defect = np.full(len(R), math.inf)
    ok = np.abs(R).max(axis=(1, 2), initial=0.0) < 1e3
    if ok.any():
        Rk = R[ok]
        G = np.einsum("nki,nkj->nij", Rk, Rk)
        G[:, [0, 1, 2], [0, 1, 2]] -= 1.0
        defect[ok] = np.maximum(np.sqrt(np.einsum("nij,nij->n", G, G)),
                                np.abs(np.linalg.det(Rk) - 1.0))
    return defect


def _pose_error(X: np.ndarray, source: str, line) -> ValueError:
    """The message for a pose failing ``_check_poses`` (checks in the order of the docstring)."""
    if not np.all(np.isfinite(X)):
        return _err(source, line, "pose contains NaN or infinite values")
    bottom = np.abs(X[3] - [0.0, 0.0, 0.0, 1.0]).max()
    if bottom > HOMOGENEOUS_ROW_TOLERANCE:
        hint = ""
        if np.abs(X[:, 3] - [0.0, 0.0, 0.0, 1.0]).max() <= HOMOGENEOUS_ROW_TOLERANCE:
            hint = " (the last column is [0, 0, 0, 1]: the matrix looks column-major, " \
                   "write it row by row)"
        return _err(source, line, "last row of a homogeneous transform must be "
                    f"[0, 0, 0, 1], got {_fmt(X[3])}{hint}")
    R = X[:3, :3]
    defect = float(_rotation_defects(R[None])[0])
    det = f"{np.linalg.det(R):.6g}" if math.isfinite(defect) else "nan"
    return _err(source, line, "rotation block is not a rotation matrix: max(‖RᵀR − I‖_F, "
                f"|det R − 1|) = {defect:.3g} > tolerance {ROTATION_TOLERANCE:g} (det = {det})")


def _project_rotations(R: np.ndarray) -> np.ndarray:
    """Nearest rotations (Frobenius: the orthogonal polar factor, what the SVD's U Vᵀ gives) of a
    stack of near-rotations (defect ≤ ``ROTATION_TOLERANCE``, det > 0), by Newton–Schulz
    iterations X ← X (3 I − XᵀX) / 2: quadratic convergence, 3–4 steps from 1e-3, and 4× faster
    than a batched SVD."""
    X = R.copy()
    for _ in range(8):
        G = np.swapaxes(X, 1, 2) @ X
        X = 1.5 * X - 0.5 * (X @ G)
        G[:, [0, 1, 2], [0, 1, 2]] -= 1.0
        if np.abs(G).max() < 1e-14:  # the step just taken squared this: ~1e-28
            break
    return X


def _check_poses(P: np.ndarray, lines: LineNumbers, source: str, scale: float,
                 exact_rotations: bool = False) -> None:
    """Validates a stack of poses in place, block by block: finite, last row [0, 0, 0, 1],
    rotation within ``ROTATION_TOLERANCE`` (projected on SO(3) when not exact; not checked with
    ``exact_rotations``, for rotations made from unit quaternions), translation scaled by
    ``scale`` and still finite."""
    lines_a = np.asarray(lines)
    for s in range(0, len(P), _BLOCK):
        blk = P[s:s + _BLOCK]
        finite = np.isfinite(blk).all(axis=(1, 2))
        bad = ~finite
        good = np.flatnonzero(finite)
        if len(good):
            G = blk[good]
            row_bad = np.abs(G[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1) > \
                HOMOGENEOUS_ROW_TOLERANCE
            defect = np.zeros(len(G)) if exact_rotations else _rotation_defects(G[:, :3, :3])
            bad[good] = row_bad | ~(defect <= ROTATION_TOLERANCE)
        if bad.any():
            k = int(np.argmax(bad))
            raise _pose_error(blk[k], source, int(lines_a[s + k]))
        near = defect > _PROJECTION_THRESHOLD
        if near.any():
            blk[near, :3, :3] = _project_rotations(blk[near, :3, :3])
        blk[:, 3] = [0.0, 0.0, 0.0, 1.0]
        if scale != 1.0:
            with np.errstate(over="ignore"):
                blk[:, :3, 3] *= scale
            fin = np.isfinite(blk[:, :3, 3]).all(axis=1)
            if not fin.all():
                raise _err(source, int(lines_a[s + int(np.argmin(fin))]),
                           "pose is not finite after scaling the translation")


_UNITS = (("milliseconds", 1e-3), ("microseconds", 1e-6), ("nanoseconds", 1e-9))


def time_unit_hint(timestamps) -> str | None:
    """Why timestamps do not look like seconds, and the ``time_scale`` that fixes them; None
    when they do (|t| < ``MAX_TIMESTAMP_SECONDS`` and median period < ``MAX_PERIOD_SECONDS``).

    Huge values are read as Unix time (1.7e9 s today): 1e12–1e14 ms, 1e15–1e17 µs, ≥ 1e18 ns.
    A long period is read in the unit that gives a sampling rate closest to 30 Hz.
    """
    t = np.asarray(timestamps, dtype=float)
    if t.size == 0 or not np.all(np.isfinite(t)):
        return None
    m = float(np.abs(t).max())
    if m >= MAX_TIMESTAMP_SECONDS:
        k = max(1, round(math.log10(m / 1.7e9) / 3))
        if k > 3:
            return (f"timestamps up to {m:.4g} are not seconds ({m / 3.156e7:.3g} years), nor "
                    "Unix time in milliseconds, microseconds or nanoseconds: implausible times")
        unit, scale = _UNITS[k - 1]
        return (f"timestamps up to {m:.4g} are not seconds ({m / 3.156e7:.3g} years): they look "
                f"like Unix time in {unit} — rescale them with time_scale={scale:g} (command "
                f"line --time-scale {scale:g})")
    if t.size > 1:
        period = float(np.median(np.diff(t)))
        if period >= MAX_PERIOD_SECONDS:
            unit, scale = min(_UNITS, key=lambda u: abs(math.log10(period * u[1] * 30.0)))
            return (f"a median sampling period of {period:.4g} s ({period / 3600:.3g} hours) is "
                    f"implausible: the timestamps look like {unit} ({1 / (period * scale):.3g} Hz)"
                    f" — rescale them with time_scale={scale:g} (command line --time-scale "
                    f"{scale:g})")
    return None


def slow_clock_hint(timestamps) -> str | None:
    """A hint when the sampling period is 1 s or more (timestamps in milliseconds?), for
    messages about alignment and time offsets; None otherwise."""
    t = np.asarray(timestamps, dtype=float)
    if t.size < 2:
        return None
    period = float(np.median(np.diff(t)))
    if not period >= 1.0:
        return None
    unit, scale = min(_UNITS, key=lambda u: abs(math.log10(period * u[1] * 30.0)))
    return (f"its median sampling period is {period:.4g} s: if the timestamps are in {unit} "
            f"({1 / (period * scale):.3g} Hz), rescale them with time_scale={scale:g} (command "
            f"line --time-scale {scale:g})")


def _check_timestamps(t: np.ndarray, lines: LineNumbers, source: str) -> None:
    lines_a = np.asarray(lines)
    fin = np.isfinite(t)
    if not fin.all():
        k = int(np.argmin(fin))
        raise _err(source, int(lines_a[k]), f"timestamp {t[k]} is not finite")
    d = np.diff(t)
    bad = np.flatnonzero(~(d > 0))
    if len(bad):
        i = int(bad[0]) + 1
        li, lp = int(lines_a[i]), int(lines_a[i - 1])
        more = f" ({len(bad)} such places in the file)" if len(bad) > 1 else ""
        if t[i] == t[i - 1]:
            raise _err(source, li, f"duplicate timestamp {float(t[i])!r} (same as line {lp}); "
                       f"timestamps must be strictly increasing{more}")
        restart = " — the timestamps start over: recordings concatenated?" \
            if i > 1 and t[i] <= t[0] else ""
        raise _err(source, li, f"timestamp {float(t[i])!r} is earlier than the previous "
                   f"sample's {float(t[i - 1])!r} (line {lp}); samples must be sorted by "
                   f"time{more}{restart}")
    hint = time_unit_hint(t)
    if hint is not None:
        raise _err(source, None, hint)


def _finish(P: np.ndarray, timestamps, lines: LineNumbers, source: str, scale: float,
            max_translation, time_scale: float, checked: bool = False) -> PoseStream:
    """Validates (in place; ``checked``: ``_check_poses`` already done) and wraps N ≥ 1 poses
    with their timestamps and lines."""
    if not checked:
        _check_poses(P, lines, source, scale)
    if max_translation is not None:
        norms = _row_norms(P[:, :3, 3])
        i = int(np.argmax(norms))
        if norms[i] > max_translation:
            raise _err(source, lines[i], f"translation of length {norms[i]:.6g} exceeds "
                       f"{max_translation:g}: poses are expected in metres — are these "
                       "millimetres? Rescale them (translation_scale=0.001, command line "
                       "--translation-scale 0.001) or raise max_translation")
    t = None
    if timestamps is not None:
        t = np.asarray(timestamps, dtype=float)
        if time_scale != 1.0:
            fin = np.isfinite(t)
            with np.errstate(over="ignore"):
                t = t * time_scale
            lost = fin & ~np.isfinite(t)
            if lost.any():
                k = int(np.argmax(lost))
                raise _err(source, lines[k], f"timestamp is not finite after time_scale = "
                           f"{time_scale:g}")
        _check_timestamps(t, lines, source)
    return PoseStream(P, t, source, lines)


def pose_stream(poses, timestamps=None, source: str = "poses", lines=None,
                translation_scale: float = 1.0,
                max_translation: float | None = MAX_TRANSLATION,
                time_scale: float = 1.0) -> PoseStream:
    """Builds a validated ``PoseStream`` from arrays (what every reader ends with).

    Args:
        poses: (N, 4, 4) homogeneous transforms, N ≥ 1.
        timestamps: None or (N,) finite seconds (after ``time_scale``), strictly increasing.
        source: name used in error messages (a file name).
        lines: line number of each sample in ``source`` (default 1..N).
        translation_scale: factor applied to every translation (e.g. 0.001 for millimetres).
        max_translation: translations longer than this (after scaling) raise ValueError (units
            look wrong); None disables the check.
        time_scale: factor applied to every timestamp (1e-9 for nanoseconds, 1e-3 for ms).

    Rotation blocks within ``ROTATION_TOLERANCE`` of SO(3) are projected on it (the nearest
    rotation in Frobenius norm).
    """
    source = str(source)
    try:
        P = np.array(poses, dtype=float)
    except (TypeError, ValueError, OverflowError) as e:
        raise _err(source, None, f"poses: expected an (N, 4, 4) array of numbers "
                   f"({str(e).splitlines()[0][:120]})") from None
    if P.ndim != 3 or P.shape[1:] != (4, 4):
        raise _err(source, None, f"poses: expected an array of shape (N, 4, 4), got {P.shape}")
    n = len(P)
    if n == 0:
        raise _err(source, None, "no pose samples (the file is empty or only has comments)")
    lines = _as_lines(lines, n, source)
    scale = _finite_positive(translation_scale, "translation_scale")
    time_scale = _finite_positive(time_scale, "time_scale")
    if max_translation is not None:
        max_translation = _finite_positive(max_translation, "max_translation")
    t = None
    if timestamps is not None:
        try:
            t = np.array(timestamps, dtype=float)
        except (TypeError, ValueError, OverflowError) as e:
            raise _err(source, None, f"timestamps: expected numbers "
                       f"({str(e).splitlines()[0][:120]})") from None
        if t.ndim != 1 or len(t) != n:
            raise _err(source, None, f"timestamps: expected {n} values (one per pose), got "
                       f"shape {t.shape}")
    return _finish(P, t, lines, source, scale, max_translation, time_scale)


# ---------------------------------------------------------------------------- TUM and CSV text
_SPLIT = re.compile(r"[,\s\ufeff]+")  # a BOM (files concatenated) counts as a separator
_COMMENT = re.compile(rb"#[^\n]*")
_SEPARATORS = bytes.maketrans(b",\t", b"  ")
_FAST_CHARS = b"0123456789+-.eEnNaAiIfFtTyY \n"  # numbers, nan, inf(inity), separators
#: Poses the table reader makes room for at first (9 MB); it doubles as the data lines come.
_FIRST_CAPACITY = 65536
_BREAK_BYTES = b"\r\x0b\x0c\x1c\x1d\x1e"  # str.splitlines' ASCII line breaks besides \n
_BREAKS_TO_NL = bytes.maketrans(_BREAK_BYTES, b"\n" * len(_BREAK_BYTES))
_UNICODE_BREAKS = (b"\xc2\x85", b"\xe2\x80\xa8", b"\xe2\x80\xa9")


#: Field counts of the six-number CSV kinds (pose, or timestamp + pose) and their layout.
_SIX = {"rotvec": "x y z rx ry rz", "euler": "x y z a1 a2 a3"}


class _Table:
    """What a TUM or CSV file must look like: the allowed field counts and the messages."""

    def __init__(self, kind: str, source: str):
        self.kind, self.source = kind, source
        self.count = 8 if kind == "tum" else None  # csv: fixed by the first data line
        self.first_line = None

    @property
    def counts(self) -> tuple:
        return (8,) if self.kind == "tum" else (6, 7) if self.kind in _SIX else (16, 17)

    def check_count(self, number: int, got: int, content: str) -> None:
        if self.kind == "tum":
            if got != 8:
                raise _err(self.source, number, "expected 8 numbers (timestamp tx ty tz qx qy qz "
                           f"qw), got {got}{self._hint(number, content)}")
        elif self.kind in _SIX and got not in (6, 7):
            raise _err(self.source, number, f"expected 6 numbers ({_SIX[self.kind]}) or 7 "
                       f"(timestamp + those), got {got} (header lines must start with "
                       f"'#'){self._hint(number, content, header=False)}")
        elif self.kind not in _SIX and got not in (16, 17):
            raise _err(self.source, number, "expected 16 numbers (a row-major 4×4 matrix) or "
                       f"17 (timestamp + matrix), got {got} (header lines must start with "
                       f"'#'){self._hint(number, content, header=False)}")
        elif self.count is not None and got != self.count:
            raise _err(self.source, number, f"expected {self.count} numbers like line "
                       f"{self.first_line}, got {got}: every line must have a timestamp, or "
                       f"none{self._hint(number, content)}")
        if self.count is None:
            self.count = got

    def _hint(self, number: int, content: str, header: bool = True) -> str:
        if ";" in content:
            return " (';' is not a separator: use spaces, tabs or commas)"
        if "." not in content and re.search(r"\d,\d", content) and \
                re.search(r"\d\s+[-+]?\d", content):
            return " (decimal commas? write 0.5, not 0,5: commas separate fields)"
        if header and _looks_like_header(self, content):
            return " (a header line? comment it out with '#')"
        return ""

    def number(self, token: str, number: int) -> float:
        try:
            return float(token)
        except ValueError:
            hint = ""
            if ";" in token:
                hint = " (';' is not a separator: use spaces, tabs or commas)"
            elif re.fullmatch(r"\d{4}-\d\d-\d\d([T ].*)?|\d+:\d\d(:\d\d)?(\.\d*)?", token):
                hint = " (dates and clock times are not read: write seconds as a number)"
            elif _looks_like_header(self, token):
                hint = " (a header line? comment it out with '#')"
            what = "tum field" if self.kind == "tum" else "csv field"
            raise _err(self.source, number, f"{what}: {token[:40]!r} is not a number"
                       f"{hint}") from None

    def slow(self, text: str, first_number: int):
        """Line-by-line parse of ``text`` (its first line is line ``first_number``): (values
        (n, count), line numbers); raises the precise error of the first bad line."""
        rows, numbers = [], []
        for number, raw in enumerate(text.splitlines(), start=first_number):
            content = raw.split("#", 1)[0].strip().strip("\ufeff")
            if not content:
                continue
            fields = [f for f in _SPLIT.split(content) if f]
            if not fields:
                continue
            self.check_count(number, len(fields), content)
            rows.append([self.number(f, number) for f in fields])
            numbers.append(number)
            if self.first_line is None:
                self.first_line = number
        if not rows:
            return np.zeros((0, self.count or 0)), np.zeros(0, dtype=np.int64)
        return np.array(rows, dtype=float), np.array(numbers, dtype=np.int64)

    def fast(self, chunk: bytes):
        """numpy parse of a chunk of normalized lines (``\\n`` only): (values, 0-based line
        indices in the chunk), or None when the chunk needs the line-by-line parse."""
        if b"#" in chunk:
            chunk = _strip_comments(chunk)
        chunk = chunk.translate(_SEPARATORS)
        if chunk.translate(None, _FAST_CHARS):
            return None  # other characters: letters, control bytes, non-ASCII
        a = np.frombuffer(chunk, dtype=np.uint8)
        tok = a > 32
        starts = np.flatnonzero(tok[1:] & ~tok[:-1]) + 1
        if len(a) and tok[0]:
            starts = np.r_[0, starts]
        if len(starts) == 0:
            return np.zeros((0, self.count or 0)), np.zeros(0, dtype=np.int64)
        newlines = np.flatnonzero(a == 10)
        per_line = np.bincount(np.searchsorted(newlines, starts), minlength=len(newlines) + 1)
        data_lines = np.flatnonzero(per_line)
        counts = per_line[data_lines]
        k = self.count if self.count is not None else int(counts[0])
        if k not in self.counts or np.any(counts != k):
            return None
        try:
            v = np.fromstring(chunk, dtype=float, sep=" ")
        except ValueError:
            return None  # a token that is not a number
        if len(v) != len(starts):
            return None
        return v.reshape(-1, k), data_lines


def _strip_comments(chunk: bytes) -> bytes:
    """``chunk`` without its comments (``#`` to the end of the line), in memory proportional to
    the chunk whatever the number of comments (``re.sub`` keeps an object per match: 200 MB for
    a 4 MiB chunk of short comment lines)."""
    a = np.frombuffer(chunk, dtype=np.uint8)
    hashes = np.cumsum(a == 35, dtype=np.int32)
    newline = a == 10
    at_line_start = np.maximum.accumulate(np.where(newline, hashes, 0))
    return a[newline | (hashes == at_line_start)].tobytes()


def _looks_like_header(table: _Table, content: str) -> bool:
    """The first data line starts with a word that is not a number (nan, inf)."""
    m = re.match(r"[A-Za-z_]\w*", content)
    return table.first_line is None and m is not None and \
        m.group(0).lower() not in ("nan", "inf", "infinity")


def _normalize_breaks(data: bytes) -> bytes:
    """Every ASCII line break str.splitlines knows (\\r\\n, \\r, \\v, \\f, \\x1c–\\x1e) as \\n,
    so that line numbers agree with the line-by-line parse."""
    if not any(bytes([c]) in data for c in _BREAK_BYTES):
        return data
    return data.replace(b"\r\n", b"\n").translate(_BREAKS_TO_NL)


def _table_chunks(table: _Table, data: bytes, progress):
    """Yields (values (n, k), line numbers (n,)) of the data lines of normalized ``data``, a
    chunk of about ``_PARSE_CHUNK`` bytes at a time, in order."""
    if not data.isascii() and any(b in data for b in _UNICODE_BREAKS):
        # Unicode line breaks (NEL, LS, PS) count as line ends for str.splitlines: parse the
        # whole text line by line so that line numbers stay the same everywhere.
        v, numbers = table.slow(data.decode("utf-8", "surrogatepass"), 1)
        if len(v):
            yield v, numbers
        return
    bar = _progress(len(data), f"parsing {Path(table.source).name}", progress)
    pos, line0 = 0, 1
    try:
        while pos < len(data):
            end = data.find(b"\n", pos + _PARSE_CHUNK)
            end = len(data) if end < 0 else end + 1
            chunk = data[pos:end]
            res = table.fast(chunk)
            if res is not None:
                v, rel = res
                if len(v) and table.first_line is None:
                    table.count, table.first_line = v.shape[1], line0 + int(rel[0])
                numbers = line0 + rel
            else:
                v, numbers = table.slow(chunk.decode("utf-8", "surrogatepass"), line0)
            if len(v):
                yield v, numbers
            line0 += chunk.count(b"\n")
            bar.update(len(chunk))
            pos = end
    finally:
        bar.close()


def _six_rotations(v: np.ndarray, kind: str, euler, source: str, lines) -> np.ndarray:
    """Rotation matrices (m, 3, 3) of the last three columns of ``v`` (rotation vectors, or Euler
    angles ``euler`` = (ORDER, UNIT)), with the unit checks of the module docstring."""
    a = v[:, -3:]
    if kind == "rotvec":
        norm = _row_norms(a)
        bad = norm > _TWO_PI
        if bad.any():
            k = int(np.argmax(bad))
            raise _err(source, lines[k], f"rotation vector (rx ry rz) = {_fmt(a[k])} has norm "
                       f"{norm[k]:.6g}, more than 2π: csv-rotvec takes radians (a UR pose) — "
                       "are these degrees?")
        return Rotation.from_rotvec(a).as_matrix()
    order, unit = euler
    if unit == "rad":
        bad = np.abs(a).max(axis=1) > _TWO_PI
        if bad.any():
            k = int(np.argmax(bad))
            raise _err(source, lines[k], f"Euler angles {_fmt(a[k])} exceed 2π rad: degrees? "
                       f"use --format csv-euler:{order}:deg")
    return Rotation.from_euler(order, a, degrees=unit == "deg").as_matrix()


def _parse_table(text, source: str, kind: str, translation_scale, max_translation, time_scale,
                 progress, euler=None) -> PoseStream:
    """TUM or CSV text → PoseStream. Each chunk is converted and validated as it comes (poses
    written into arrays sized by the line count: no per-line objects, no full copy of the
    numbers), so errors come in line order, chunk by chunk (syntax errors of a chunk first)."""
    source = str(source)
    scale = _finite_positive(translation_scale, "translation_scale")
    time_scale = _finite_positive(time_scale, "time_scale")
    if max_translation is not None:
        max_translation = _finite_positive(max_translation, "max_translation")
    table = _Table(kind, source)
    data = _normalize_breaks(_as_bytes(text, source))
    # At most one pose per line, and a data line holds ≥ 8 (tum), 6 (csv-rotvec, csv-euler) or
    # 16 (csv) numbers of ≥ 1 byte each with their separators: the arrays start small and grow
    # by doubling up to that bound, so blank lines or comments cost nothing (200 MiB of blank
    # lines once asked for 25 GiB).
    bound = min(data.count(b"\n") + 1, len(data) // (2 * min(table.counts)) + 1)
    capacity = min(bound, _FIRST_CAPACITY)
    P, t = np.empty((capacity, 4, 4)), np.empty(capacity)
    lines = np.empty(capacity, dtype=np.int64)
    n = 0
    largest_angle = 0.0
    for v, numbers in _table_chunks(table, data, progress):
        m = len(v)
        if n + m > capacity:
            capacity = max(n + m, min(bound, 2 * capacity))
            P, t, lines = (np.resize(a, (capacity,) + a.shape[1:]) for a in (P, t, lines))
        chunk_lines = LineNumbers(numbers)
        fin = np.isfinite(v).all(axis=1)
        X = P[n:n + m]
        if kind == "tum":
            q = v[:, 4:8]
            norm = np.zeros(m)
            norm[fin] = _row_norms(q[fin])
            bad = ~fin | ~(np.abs(norm - 1.0) <= QUATERNION_NORM_TOLERANCE)
            if bad.any():
                k = int(np.argmax(bad))
                if not fin[k]:
                    raise _err(source, chunk_lines[k], "contains NaN or infinite values")
                raise _err(source, chunk_lines[k], f"quaternion (qx qy qz qw) = {_fmt(q[k])} has "
                           f"norm {norm[k]:.6g}, not 1 (tolerance "
                           f"{QUATERNION_NORM_TOLERANCE:g}); expected a unit quaternion")
            X[:, :3, :3] = Rotation.from_quat(q / norm[:, None]).as_matrix()
            X[:, :3, 3] = v[:, 1:4]
            X[:, 3] = [0.0, 0.0, 0.0, 1.0]
        elif kind in _SIX:
            if not fin.all():
                raise _err(source, chunk_lines[int(np.argmin(fin))],
                           "contains NaN or infinite values")
            X[:, :3, :3] = _six_rotations(v, kind, euler, source, chunk_lines)
            X[:, :3, 3] = v[:, -6:-3]
            X[:, 3] = [0.0, 0.0, 0.0, 1.0]
            largest_angle = max(largest_angle, float(np.abs(v[:, -3:]).max()))
        else:
            if not fin.all():
                raise _err(source, chunk_lines[int(np.argmin(fin))],
                           "contains NaN or infinite values")
            X[:] = v[:, -16:].reshape(m, 4, 4)
        _check_poses(X, chunk_lines, source, scale, exact_rotations=kind != "csv")
        t[n:n + m] = v[:, 0]
        lines[n:n + m] = numbers
        n += m
    if n == 0:
        raise _err(source, None, "no pose samples (the file is empty or only has comments)")
    if kind == "euler" and euler[1] == "deg" and n >= 3 and largest_angle <= math.pi + 1e-9:
        # As degrees every turn would be under 3.2°: too little for a calibration — radians.
        raise _err(source, None, f"every Euler angle is within ±π ({largest_angle:.4g} at most) "
                   f"read as degrees: radians? use --format csv-euler:{euler[0]}:rad")
    stamped = kind == "tum" or table.count in (7, 17)
    return _finish(P[:n], t[:n] if stamped else None, LineNumbers(lines[:n]), source, 1.0,
                   max_translation, time_scale, checked=True)


def parse_tum(text, source: str = "<tum>", translation_scale: float = 1.0,
              max_translation: float | None = MAX_TRANSLATION, time_scale: float = 1.0,
              progress: bool | None = None) -> PoseStream:
    """Parses TUM lines ``timestamp tx ty tz qx qy qz qw`` (see the module docstring); ``text``
    is a str or UTF-8 bytes."""
    return _parse_table(text, source, "tum", translation_scale, max_translation, time_scale,
                        progress)


def parse_csv_matrix(text, source: str = "<csv>", translation_scale: float = 1.0,
                     max_translation: float | None = MAX_TRANSLATION, time_scale: float = 1.0,
                     progress: bool | None = None) -> PoseStream:
    """Parses one row-major 4×4 matrix per line, optionally after a timestamp (16 or 17
    numbers, the same count on every line); ``text`` is a str or UTF-8 bytes."""
    return _parse_table(text, source, "csv", translation_scale, max_translation, time_scale,
                        progress)


def parse_csv_rotvec(text, source: str = "<csv>", translation_scale: float = 1.0,
                     max_translation: float | None = MAX_TRANSLATION, time_scale: float = 1.0,
                     progress: bool | None = None) -> PoseStream:
    """Parses ``x y z rx ry rz`` lines (a UR pose: metres, rotation vector in radians),
    optionally after a timestamp (6 or 7 numbers, the same count on every line)."""
    return _parse_table(text, source, "rotvec", translation_scale, max_translation, time_scale,
                        progress)


def parse_csv_euler(text, order: str, unit: str, source: str = "<csv>",
                    translation_scale: float = 1.0,
                    max_translation: float | None = MAX_TRANSLATION, time_scale: float = 1.0,
                    progress: bool | None = None) -> PoseStream:
    """Parses ``x y z a1 a2 a3`` lines, optionally after a timestamp: the rotation is
    ``Rotation.from_euler(order, [a1, a2, a3], degrees=unit == "deg")`` (lowercase order:
    extrinsic, about the fixed axes; uppercase: intrinsic; see the module docstring)."""
    order, unit = _euler_parameters(f"{EULER_FORMAT}:{order}:{unit}")
    return _parse_table(text, source, "euler", translation_scale, max_translation, time_scale,
                        progress, euler=(order, unit))


def _euler_parameters(fmt: str) -> tuple[str, str]:
    """(ORDER, UNIT) of ``csv-euler:ORDER:UNIT``; ValueError naming what is wrong."""
    parts = str(fmt).split(":")
    example = "e.g. csv-euler:ZYX:deg (KUKA A B C) or csv-euler:xyz:deg (Fanuc W P R)"
    if len(parts) != 3 or parts[0] != EULER_FORMAT:
        raise ValueError(f"format: expected csv-euler:ORDER:UNIT, {example}; got {fmt!r}")
    order, unit = parts[1], parts[2].lower()
    if len(order) != 3 or not (set(order) <= set("xyz") or set(order) <= set("XYZ")):
        raise ValueError(f"format {fmt!r}: ORDER must be three of x, y, z, all lowercase "
                         f"(extrinsic: about the fixed axes) or all uppercase (intrinsic: about "
                         f"the turning axes), {example}")
    if order[0].lower() == order[1].lower() or order[1].lower() == order[2].lower():
        raise ValueError(f"format {fmt!r}: ORDER {order!r} turns twice in a row about one axis "
                         f"(no two neighbouring letters may be the same), {example}")
    if unit not in ANGLE_UNITS:
        raise ValueError(f"format {fmt!r}: UNIT must be deg or rad, {example}")
    return order, unit


def check_format(fmt: str) -> str:
    """``fmt`` if it is one of ``FORMATS`` or a valid ``csv-euler:ORDER:UNIT`` (its unit in
    lowercase), else ValueError naming the formats."""
    if fmt in FORMATS:
        return fmt
    if isinstance(fmt, str) and fmt.split(":", 1)[0] == EULER_FORMAT:
        order, unit = _euler_parameters(fmt)
        return f"{EULER_FORMAT}:{order}:{unit}"
    raise ValueError(f"format: expected one of {', '.join(FORMAT_NAMES)}, got {fmt!r}")


# ----------------------------------------------------------------------------- OpenCV YAML
@dataclass
class _Node:
    value: object  # float | str | list[_Node] | dict[str, _Node] | np.ndarray | _Numbers | None
    line: int


class _Numbers:
    """A flow list of numbers ``[ a, b, ... ]`` (one array, not a node per number)."""

    __slots__ = ("array",)

    def __init__(self, array: np.ndarray):
        self.array = array

    def __len__(self) -> int:
        return len(self.array)


_FLOW_NUMBERS = re.compile(r"[0-9eE+\-.,\s]*")
_EMPTY_ELEMENT = re.compile(r"(^|,)\s*(,|$)")


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
            content = (re.sub(r"(^|\s)#.*$", "", raw) if "#" in raw else raw).rstrip()
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
        parts = [rest]
        while "]" not in parts[-1]:  # a list spanning lines: linear in its length
            if self.i >= len(self.lines):
                raise _err(self.source, number, "unterminated '[' list")
            parts.append(self.lines[self.i][2])
            self.i += 1
        text = " ".join(parts)
        body, _, after = text[1:].partition("]")
        if after.strip():
            raise _err(self.source, number, f"unexpected text after ']': {after.strip()[:40]!r}")
        if "[" in body:
            raise _err(self.source, number, "nested lists are not supported")
        if not body.strip():
            return _Node(_Numbers(np.zeros(0)), number)
        if _FLOW_NUMBERS.fullmatch(body) and not _EMPTY_ELEMENT.search(body):
            try:  # plain decimal numbers: numpy parses them at once
                values = np.fromstring(body, dtype=float, sep=",")
                if len(values) == body.count(",") + 1:
                    return _Node(_Numbers(values), number)
            except ValueError:
                pass
        values = []
        for t in body.split(","):
            t = t.strip()
            v = _scalar(t)
            if not isinstance(v, float):
                raise _err(self.source, number, f"list element {t[:40]!r} is not a number")
            values.append(v)
        return _Node(_Numbers(np.array(values, dtype=float)), number)

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
        data = _number_array(d["data"].value)
        if data is None:
            raise _err(self.source, d["data"].line, "matrix data must be a list of numbers")
        if len(data) != dims[0] * dims[1]:
            raise _err(self.source, d["data"].line, f"matrix data has {len(data)} numbers, "
                       f"rows × cols = {dims[0]} × {dims[1]} = {dims[0] * dims[1]}")
        return data.reshape(dims)


_YAML_SPECIAL = {".nan": math.nan, ".inf": math.inf, "+.inf": math.inf, "-.inf": -math.inf}


def _scalar(text: str):
    """A YAML scalar: a float when it reads as a number (incl. .nan/.inf), else the string."""
    low = text.lower()
    if low in _YAML_SPECIAL:
        return _YAML_SPECIAL[low]
    if re.fullmatch(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?", text):
        return float(text)
    return text.strip("'\"")


def _number_array(value) -> np.ndarray | None:
    """The numbers of a flow list or of a block sequence of numbers; None otherwise."""
    if isinstance(value, _Numbers):
        return value.array
    if isinstance(value, list) and all(isinstance(x.value, float) for x in value):
        return np.array([x.value for x in value], dtype=float)
    return None


def _seq_of_matrices(root: dict, key: str, source: str) -> list[_Node]:
    node = root[key]
    items = node.value if isinstance(node.value, list) else None
    if isinstance(node.value, _Numbers) and len(node.value) == 0:
        items = []
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


def _numbers(node: _Node, key: str, source: str) -> np.ndarray:
    v = node.value
    if isinstance(v, np.ndarray):
        if 1 not in v.shape:
            raise _err(source, node.line, f"{key}: expected an N×1 or 1×N matrix, got "
                       f"{v.shape[0]}×{v.shape[1]}")
        return v.reshape(-1)
    values = _number_array(v)
    if values is None:
        raise _err(source, node.line, f"{key}: expected a list of numbers")
    return values


def _check_rodrigues_radians(rotvecs: np.ndarray, lines, key: str, source: str) -> None:
    """Rodrigues vectors are in radians: their length (the rotation angle) is at most π (what
    ``cv::Rodrigues`` writes), never beyond 2π. Vectors longer than 2π, or most of them longer
    than π, are in degrees: refused naming the unit (read as radians they would be arbitrary
    rotations)."""
    norms = np.linalg.norm(rotvecs, axis=1)
    over = norms > math.pi + 1e-6
    if np.any(norms > 2 * math.pi) or (len(norms) >= 3 and np.mean(over) >= 0.5):
        k = int(np.argmax(norms))
        raise _err(source, lines[k], f"{key}: Rodrigues vectors of length up to "
                   f"{norms[k]:.4g} ({int(over.sum())} of {len(norms)} longer than π) — they look "
                   "like degrees; a Rodrigues vector is in radians (its length is the rotation "
                   "angle, at most π): convert them (× π/180)")


def parse_opencv_yaml(text, stream: str, source: str = "<yaml>",
                      camera_in_target: bool = False, translation_scale: float = 1.0,
                      max_translation: float | None = MAX_TRANSLATION,
                      time_scale: float = 1.0) -> PoseStream:
    """Parses a cv::FileStorage YAML file and returns its robot (X_BE) or camera (X_CT) stream.

    ``stream`` is "robot" or "camera"; see the module docstring for the accepted keys. With
    ``camera_in_target`` a ``camera_poses``/``poses`` list holds X_TC (inverted on reading);
    the keys ``R_cam2target``/``t_cam2target`` always do (and ``*_target2cam`` never, so the
    flag must agree with them). ``text`` is a str or UTF-8 bytes.
    """
    if stream not in STREAMS:
        raise ValueError(f"stream: expected one of {STREAMS}, got {stream!r}")
    source = str(source)
    if not isinstance(text, str):
        text = _decode(_as_bytes(text, source), source)
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
            poses = np.zeros((len(Rs), 4, 4))
            poses[:, 3, 3] = 1.0
            rotvec_index, rotvecs = [], []
            for k, (R_node, t_node) in enumerate(zip(Rs, ts)):
                M = R_node.value
                if M.shape == (3, 3):
                    poses[k, :3, :3] = M
                elif M.shape in ((3, 1), (1, 3)):
                    if not np.all(np.isfinite(M)):
                        raise _err(source, R_node.line, f"{R_key}: contains NaN or infinite "
                                   "values")
                    rotvec_index.append(k)
                    rotvecs.append(M.reshape(3))
                else:
                    raise _err(source, R_node.line, f"{R_key}: expected a 3×3 rotation matrix "
                               f"or a 3×1 Rodrigues vector, got {M.shape[0]}×{M.shape[1]}")
                if t_node.value.shape not in ((3, 1), (1, 3)):
                    raise _err(source, t_node.line, f"{t_key}: expected a 3×1 translation, got "
                               f"{t_node.value.shape[0]}×{t_node.value.shape[1]}")
                poses[k, :3, 3] = t_node.value.reshape(3)
            if rotvecs:
                _check_rodrigues_radians(np.array(rotvecs), [Rs[k].line for k in rotvec_index],
                                         R_key, source)
                poses[rotvec_index, :3, :3] = Rotation.from_rotvec(np.array(rotvecs)).as_matrix()
            lines = [R_node.line for R_node in Rs]
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
                poses = np.array([item.value for item in items]).reshape(-1, 4, 4)
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
    result = pose_stream(poses, stamps, source, lines, translation_scale, max_translation,
                         time_scale)
    return result.inverted() if invert else result


# -------------------------------------------------------------------------------- entry point
_EXTENSIONS = {".tum": "tum", ".txt": "tum", ".csv": "csv-matrix", ".yaml": "opencv-yaml",
               ".yml": "opencv-yaml"}


def infer_format(path) -> str:
    """The format implied by a file's extension (.tum/.txt, .csv, .yaml/.yml)."""
    fmt = _EXTENSIONS.get(Path(path).suffix.lower())
    if fmt is None:
        raise ValueError(f"{path}: cannot infer the format from the extension "
                         f"{Path(path).suffix!r}; pass one of {', '.join(FORMAT_NAMES)} "
                         "(--format)")
    return fmt


def parse_poses(text, fmt: str, stream: str, source: str = "<text>",
                camera_in_target: bool = False, translation_scale: float = 1.0,
                max_translation: float | None = MAX_TRANSLATION, time_scale: float = 1.0,
                progress: bool | None = None) -> PoseStream:
    """Parses the text (str or UTF-8 bytes) of a pose file into the canonical stream: X_BE for
    ``stream="robot"``, X_CT for ``stream="camera"`` (camera-in-target files are inverted)."""
    fmt = check_format(fmt)
    if stream not in STREAMS:
        raise ValueError(f"stream: expected one of {STREAMS}, got {stream!r}")
    if fmt == "opencv-yaml":
        return parse_opencv_yaml(text, stream, source, camera_in_target, translation_scale,
                                 max_translation, time_scale)
    if fmt.startswith(EULER_FORMAT + ":"):
        _, order, unit = fmt.split(":")
        result = parse_csv_euler(text, order, unit, source, translation_scale, max_translation,
                                 time_scale, progress)
    else:
        parse = {"tum": parse_tum, "csv-matrix": parse_csv_matrix,
                 "csv-rotvec": parse_csv_rotvec}[fmt]
        result = parse(text, source, translation_scale, max_translation, time_scale, progress)
    return result.inverted() if stream == "camera" and camera_in_target else result


def read_poses(path, stream: str, fmt: str | None = None, camera_in_target: bool = False,
               translation_scale: float = 1.0,
               max_translation: float | None = MAX_TRANSLATION, time_scale: float = 1.0,
               max_bytes: int = MAX_FILE_BYTES, progress: bool | None = None) -> PoseStream:
    """Reads a pose file once: X_BE (``stream="robot"``) or X_CT (``stream="camera"``).

    Args:
        path: the file (or a pipe, FIFO, ``/dev/fd/N``: read once, up to ``max_bytes``); or an
            ``InputFile`` already read by ``read_input``.
        stream: "robot" or "camera".
        fmt: one of ``FORMATS`` or ``csv-euler:ORDER:UNIT``; None infers it from the extension
            (``infer_format``).
        camera_in_target: the camera file holds X_TC (camera in target); inverted on reading.
        translation_scale: factor applied to translations (0.001 for a file in millimetres).
        max_translation: plausibility bound on translation lengths (metres); None disables it.
        time_scale: factor applied to timestamps (1e-9 for nanoseconds, 1e-3 for milliseconds).
        max_bytes: the input cap (bytes).
        progress: progress bars on stderr for long reads (None: when stderr is a terminal).

    Returns:
        The stream, with ``sha256`` and ``bytes_read`` of what was read.

    Raises:
        ValueError: naming the file (and line) for every problem listed in the module
            docstring.
    """
    raw = path if isinstance(path, InputFile) else None
    fmt = infer_format(raw.source if raw else path) if fmt is None else check_format(fmt)
    if stream not in STREAMS:
        raise ValueError(f"stream: expected one of {STREAMS}, got {stream!r}")
    if raw is None:
        raw = read_input(path, max_bytes, progress)
    result = parse_poses(raw.data, fmt, stream, raw.source, camera_in_target,
                         translation_scale, max_translation, time_scale, progress)
    return dataclasses.replace(result, sha256=raw.sha256, bytes_read=raw.size)

"""Calibration targets: spec strings, object points, exact-scale rendering and printable files
(numpy/OpenCV only).

Five target types, each parsed from a short spec string (``parse_target``) and written back by
``format_target`` (its exact inverse on canonical specs):

* chessboard: ``chessboard:COLSxROWS:SQUARE``, e.g. ``chessboard:9x6:0.0236``;
* ChArUco: ``charuco:SQUARESXxSQUARESY:SQUARE:MARKER:DICT[:legacy]``, e.g.
  ``charuco:5x7:0.036195:0.018256:DICT_6X6_250``;
* one AprilTag: ``apriltag:FAMILY:SIZE[:ID]``, e.g. ``apriltag:36h11:0.048:10``;
* AprilTag grid: ``aprilgrid:FAMILY:TAGSXxTAGSY:SIZE:SPACING[:FIRST_ID]``, e.g.
  ``aprilgrid:36h11:6x6:0.088:0.3``;
* circle grid, symmetric ``circles:COLSxROWS:SPACING[:DIAMETER][:white]`` or asymmetric
  ``acircles:COLSxROWS:SPACING[:DIAMETER][:white]``, e.g. ``acircles:7x11:0.02:0.015:white``
  (COLS circles in each row, ROWS rows; ``white``: white circles on black, else black on white).

Lengths are metres. COLSxROWS of a chessboard counts INNER corners (a 9x6 board has 10x7
squares). DICT is any ``cv2.aruco.DICT_*`` name (case-insensitive on input, written back in
OpenCV's spelling, e.g. ``DICT_APRILTAG_36h11``). FAMILY is one of 16h5, 25h9, 36h10, 36h11
(OpenCV's ``DICT_APRILTAG_*``). The SIZE of a tag is the edge of its black border (the outer
white ring is not part of it). SPACING of a grid is Kalibr's ``tagSpacing``: the gap between two
tags divided by SIZE. ``:legacy`` selects the ChArUco layout of OpenCV < 4.6 (boards with an even
number of rows printed before 4.6 differ; OpenCV's ``setLegacyPattern(True)``).

The target frame T
------------------
For every type T lies in the printed plane, x along the columns of the printed image (to the
right), y along its rows (downwards), z = x × y pointing INTO the board, away from a camera that
looks at the printed face. A camera seeing the front of the target therefore has the target's
z axis pointing away from it (``X_CT[:3, 2] · X_CT[:3, 3] > 0``).

* chessboard: origin at the first inner corner, the one diagonally adjacent to the black corner
  square at the top-left of the printed image; inner corner (i, j) (i-th column, j-th row) is at
  (i·SQUARE, j·SQUARE, 0) and has id j·COLS + i — the order of ``cv2.findChessboardCorners``
  for pattern size (COLS, ROWS) (``findChessboardCornersSB`` starts from the other end; the
  detector relabels its corners from the printed colours). The printed board extends one
  square beyond the inner corners on every side. When COLS + ROWS is odd the corner colours fix
  the orientation (the detector uses them); when it is even the board looks the same after a
  half turn and the pose is only defined up to that turn — prefer COLS + ROWS odd (9x6, 7x4…).
* ChArUco: OpenCV's ``CharucoBoard`` frame: origin at the top-left outer corner of the board,
  chessboard corners at ((i+1)·SQUARE, (j+1)·SQUARE, 0) with id j·(SQUARESX−1) + i, the ids of
  ``CharucoBoard.getChessboardCorners()`` and of ``CharucoDetector``.
* one AprilTag: origin at the tag centre; the four corners of the black border in OpenCV's
  ArUco order (top-left, top-right, bottom-right, bottom-left of the printed tag) are at
  (∓SIZE/2, ∓SIZE/2, 0) with ids ID·4 + k, k = 0…3.
* AprilTag grid (OpenCV's ``GridBoard`` with an AprilTag dictionary, Kalibr's sizing): origin at
  the top-left corner of the top-left tag, tags numbered row-major from the top-left starting at
  FIRST_ID; the tag in column c and row r has its top-left corner at (c, r)·SIZE·(1 + SPACING);
  corner k of tag `id` has id ``id·4 + k`` (ArUco corner order). The corner squares Kalibr adds
  between tags are not drawn (OpenCV's ArUco detector would merge them with the tags' borders).
* circle grid: origin at the centre of the top-left circle, circle (i, j) (i-th in its row, j-th
  row) has id j·COLS + i — the order of ``cv2.findCirclesGrid`` for pattern size (COLS, ROWS).
  Symmetric: centre (i·SPACING, j·SPACING, 0). Asymmetric (OpenCV's layout, odd rows shifted
  right by SPACING): centre ((2i + j mod 2)·SPACING, j·SPACING, 0) — SPACING is the distance
  between rows and half the distance between neighbours in a row. DIAMETER defaults to half the
  nearest centre distance (SPACING/2, resp. SPACING·√2/2). The printed pattern extends one
  SPACING beyond the outermost centres (black for white circles). A symmetric grid, and an
  asymmetric one with an even number of rows, looks the same after a half turn (also after a
  quarter turn when a symmetric grid is square): ``target_symmetries``.

Rendered images (``render_target``) use OpenCV's pixel convention: the centre of pixel
(col, row) is at (col, row), so pixel (col, row) covers [col − ½, col + ½] × [row − ½, row + ½].
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
import struct
import zlib
from pathlib import Path

import numpy as np

# --------------------------------------------------------------------------------------------
# Dataclasses


@dataclasses.dataclass(frozen=True)
class ChessboardTarget:
    """Chessboard with ``cols`` × ``rows`` INNER corners and squares of side ``square`` (m)."""

    cols: int
    rows: int
    square: float


@dataclasses.dataclass(frozen=True)
class CharucoTarget:
    """ChArUco board of ``squares_x`` × ``squares_y`` squares (side ``square``, m) with ArUco
    markers of side ``marker`` (m) from ``dictionary`` (a ``cv2.aruco.DICT_*`` name); ``legacy``:
    the pattern of OpenCV < 4.6."""

    squares_x: int
    squares_y: int
    square: float
    marker: float
    dictionary: str
    legacy: bool = False


@dataclasses.dataclass(frozen=True)
class AprilTagTarget:
    """One AprilTag of ``family`` (16h5, 25h9, 36h10, 36h11), black-border edge ``size`` (m)."""

    family: str
    size: float
    id: int = 0


@dataclasses.dataclass(frozen=True)
class AprilGridTarget:
    """Grid of ``tags_x`` × ``tags_y`` AprilTags of black-border edge ``size`` (m), separated by
    gaps of ``spacing``·``size`` (Kalibr's tagSpacing ratio), ids row-major from ``first_id``."""

    family: str
    tags_x: int
    tags_y: int
    size: float
    spacing: float
    first_id: int = 0


@dataclasses.dataclass(frozen=True)
class CircleGridTarget:
    """Grid of ``cols`` circles per row × ``rows`` rows, centre pitch ``spacing`` (m; see the
    module docstring for the asymmetric layout), circle ``diameter`` (m; None: half the nearest
    centre distance), ``white`` circles on black (else black on white)."""

    cols: int
    rows: int
    spacing: float
    asymmetric: bool = False
    diameter: float | None = None
    white: bool = False


Target = ChessboardTarget | CharucoTarget | AprilTagTarget | AprilGridTarget | CircleGridTarget
TARGET_TYPES = (ChessboardTarget, CharucoTarget, AprilTagTarget, AprilGridTarget,
                CircleGridTarget)

APRILTAG_FAMILIES = ("16h5", "25h9", "36h10", "36h11")

SPEC_FORMS = {
    "chessboard": "chessboard:COLSxROWS:SQUARE (inner corners, square side in m), "
                  "e.g. chessboard:9x6:0.0236",
    "charuco": "charuco:SQUARESXxSQUARESY:SQUARE:MARKER:DICT[:legacy] (m), "
               "e.g. charuco:5x7:0.036195:0.018256:DICT_6X6_250",
    "apriltag": "apriltag:FAMILY:SIZE[:ID] (FAMILY one of 16h5, 25h9, 36h10, 36h11; SIZE = black "
                "border edge in m), e.g. apriltag:36h11:0.048:10",
    "aprilgrid": "aprilgrid:FAMILY:TAGSXxTAGSY:SIZE:SPACING[:FIRST_ID] (SPACING = gap / SIZE), "
                 "e.g. aprilgrid:36h11:6x6:0.088:0.3",
    "circles": "circles:COLSxROWS:SPACING[:DIAMETER][:white] (symmetric circle grid; COLS "
               "circles per row, centre pitch and diameter in m; white: white circles on black), "
               "e.g. circles:4x11:0.02",
    "acircles": "acircles:COLSxROWS:SPACING[:DIAMETER][:white] (asymmetric circle grid, OpenCV's "
                "layout: SPACING = row distance = half the pitch in a row, m), "
                "e.g. acircles:7x11:0.02:0.015:white",
}


# --------------------------------------------------------------------------------------------
# Dictionaries


def _aruco():
    import cv2
    return cv2.aruco


def dictionary_names() -> list[str]:
    """Every ``cv2.aruco.DICT_*`` name in OpenCV's canonical spelling (AprilTag and MIP names
    with a lowercase ``h``)."""
    return list(_dictionary_names())


@functools.lru_cache(maxsize=None)
def _dictionary_names() -> tuple[str, ...]:
    names = [n for n in dir(_aruco()) if n.startswith("DICT_")]
    canonical = {}
    for n in names:
        key = n.upper()
        # Both DICT_APRILTAG_36H11 and DICT_APRILTAG_36h11 exist; keep the lowercase one.
        if key not in canonical or n != key:
            canonical[key] = n
    return tuple(sorted(canonical.values()))


def canonical_dictionary(name: str) -> str:
    """The canonical ``DICT_*`` name of ``name`` (case-insensitive, ``DICT_`` prefix optional);
    ValueError listing the valid names otherwise."""
    lookup = {n.upper(): n for n in _dictionary_names()}
    key = str(name).strip().upper()
    if not key.startswith("DICT_"):
        key = "DICT_" + key
    if key not in lookup:
        raise ValueError(f"dictionary: unknown ArUco dictionary {name!r}, expected one of "
                         f"{', '.join(dictionary_names())}")
    return lookup[key]


def apriltag_dictionary_name(family: str) -> str:
    """``cv2.aruco`` dictionary name of an AprilTag family (``36h11`` →
    ``DICT_APRILTAG_36h11``)."""
    if family not in APRILTAG_FAMILIES:
        raise ValueError(f"family: unknown AprilTag family {family!r}, expected one of "
                         f"{', '.join(APRILTAG_FAMILIES)}")
    return f"DICT_APRILTAG_{family}"


def target_dictionary_name(target) -> str | None:
    """The ``cv2.aruco`` dictionary name a target's markers come from (None for a chessboard)."""
    if isinstance(target, CharucoTarget):
        return target.dictionary
    if isinstance(target, (AprilTagTarget, AprilGridTarget)):
        return apriltag_dictionary_name(target.family)
    return None


def get_dictionary(name: str):
    """``cv2.aruco.Dictionary`` of a ``DICT_*`` name (any case). Shared between calls: do not
    modify it."""
    return _predefined_dictionary(canonical_dictionary(name))


@functools.lru_cache(maxsize=64)
def _predefined_dictionary(name: str):
    aruco = _aruco()
    return aruco.getPredefinedDictionary(getattr(aruco, name))


def _dictionary_size(name: str) -> int:
    return int(get_dictionary(name).bytesList.shape[0])


# --------------------------------------------------------------------------------------------
# Validation of the fields (shared by the constructors' users and the spec parser)


def _fail(what: str, problem: str):
    raise ValueError(f"{what}: {problem}")


def _int_field(value, what: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        else:
            _fail(what, f"expected an integer, got {value!r}")
    value = int(value)
    if value < minimum:
        _fail(what, f"must be ≥ {minimum}, got {value}")
    return value


def _positive(value, what: str, unit: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = None
    if v is None or not math.isfinite(v) or v <= 0:
        _fail(what, f"expected a finite number > 0 ({unit}), got {value!r}")
    return v


def _length_field(value, what: str) -> float:
    return _positive(value, what, "metres")


def validate_target(target) -> Target:
    """Checks a target's fields (sizes, counts, dictionary capacity) and returns it with
    normalized field types (ints, floats, bool), or raises ValueError naming the field. Also
    accepts a spec string."""
    if isinstance(target, str):
        return _parse_cached(target)
    if isinstance(target, TARGET_TYPES):
        try:
            hash(target)
        except TypeError:  # a field of the wrong type (e.g. a list): report it uncached
            return _validate(target)
        return _validate_cached(target)
    return _validate(target)


@functools.lru_cache(maxsize=256)
def _validate_cached(target) -> Target:
    return _validate(target)


@functools.lru_cache(maxsize=256)
def _parse_cached(spec: str) -> Target:
    return parse_target(spec)


def _validate(target) -> Target:
    name = type(target).__name__
    if isinstance(target, ChessboardTarget):
        # OpenCV's chessboard detectors need more than 2 corners in each direction.
        target = ChessboardTarget(_int_field(target.cols, f"{name}.cols", 3),
                                  _int_field(target.rows, f"{name}.rows", 3),
                                  _length_field(target.square, f"{name}.square"))
    elif isinstance(target, CharucoTarget):
        sx = _int_field(target.squares_x, f"{name}.squares_x", 2)
        sy = _int_field(target.squares_y, f"{name}.squares_y", 2)
        square = _length_field(target.square, f"{name}.square")
        marker = _length_field(target.marker, f"{name}.marker")
        if marker >= square:
            _fail(f"{name}.marker", f"marker side {marker!r} m must be smaller than the square "
                                    f"side {square!r} m")
        dict_name = canonical_dictionary(target.dictionary)
        if dict_name != target.dictionary:
            _fail(f"{name}.dictionary", f"use OpenCV's spelling {dict_name!r}, got "
                                        f"{target.dictionary!r}")
        needed = (sx * sy) // 2
        if needed > _dictionary_size(dict_name):
            _fail(f"{name}.dictionary", f"{dict_name} has {_dictionary_size(dict_name)} markers, "
                                        f"a {sx}x{sy} board needs {needed}")
        if not isinstance(target.legacy, (bool, np.bool_)):
            _fail(f"{name}.legacy", f"expected a bool, got {target.legacy!r}")
        target = CharucoTarget(sx, sy, square, marker, dict_name, bool(target.legacy))
    elif isinstance(target, AprilTagTarget):
        apriltag_dictionary_name(target.family)
        size = _length_field(target.size, f"{name}.size")
        tag_id = _int_field(target.id, f"{name}.id", 0)
        n = _dictionary_size(apriltag_dictionary_name(target.family))
        if tag_id >= n:
            _fail(f"{name}.id", f"family {target.family} has ids 0…{n - 1}, got {tag_id}")
        target = AprilTagTarget(target.family, size, tag_id)
    elif isinstance(target, AprilGridTarget):
        apriltag_dictionary_name(target.family)
        tx = _int_field(target.tags_x, f"{name}.tags_x", 1)
        ty = _int_field(target.tags_y, f"{name}.tags_y", 1)
        size = _length_field(target.size, f"{name}.size")
        spacing = _length_field(target.spacing, f"{name}.spacing")
        first = _int_field(target.first_id, f"{name}.first_id", 0)
        n = _dictionary_size(apriltag_dictionary_name(target.family))
        if first + tx * ty > n:
            _fail(f"{name}.first_id", f"family {target.family} has ids 0…{n - 1}; a {tx}x{ty} "
                                      f"grid from id {first} needs up to {first + tx * ty - 1}")
        target = AprilGridTarget(target.family, tx, ty, size, spacing, first)
    elif isinstance(target, CircleGridTarget):
        # findCirclesGrid needs at least 2 circles each way; a pose needs 4 non-collinear.
        cols = _int_field(target.cols, f"{name}.cols", 2)
        rows = _int_field(target.rows, f"{name}.rows", 2)
        spacing = _length_field(target.spacing, f"{name}.spacing")
        for flag in ("asymmetric", "white"):
            if not isinstance(getattr(target, flag), (bool, np.bool_)):
                _fail(f"{name}.{flag}", f"expected a bool, got {getattr(target, flag)!r}")
        asym = bool(target.asymmetric)
        nearest = spacing * (math.sqrt(2.0) if asym else 1.0)
        diameter = (0.5 * nearest if target.diameter is None else
                    _length_field(target.diameter, f"{name}.diameter"))
        if diameter >= nearest:
            _fail(f"{name}.diameter", f"{diameter!r} m: circles would touch (the nearest centres "
                                      f"are {nearest:.6g} m apart)")
        target = CircleGridTarget(cols, rows, spacing, asym, diameter, bool(target.white))
    else:
        raise ValueError(f"target: expected one of {', '.join(t.__name__ for t in TARGET_TYPES)} "
                         f"or a spec string, got {type(target).__name__}")
    _check_extent(target)
    return target


#: The largest pattern accepted (m, either side): sizes are in metres, and a board larger than
#: this is a spec written in millimetres (charuco:7x5:40:30:… is 280 m × 200 m), named as such
#: when read in millimetres it is a board of 2 cm to 10 m.
MAX_TARGET_EXTENT = 10.0


def _scaled(target, factor: float):
    if isinstance(target, ChessboardTarget):
        return dataclasses.replace(target, square=target.square * factor)
    if isinstance(target, CharucoTarget):
        return dataclasses.replace(target, square=target.square * factor,
                                   marker=target.marker * factor)
    if isinstance(target, CircleGridTarget):
        return dataclasses.replace(target, spacing=target.spacing * factor,
                                   diameter=target.diameter * factor)
    return dataclasses.replace(target, size=target.size * factor)


def _width_height(target) -> tuple[float, float]:
    x0, y0, x1, y1 = _extent(target)
    return x1 - x0, y1 - y0


def _check_extent(target) -> None:
    w, h = _width_height(target)
    if max(w, h) <= MAX_TARGET_EXTENT:
        return
    board = f"{w:.4g} m × {h:.4g} m"
    in_metres = _scaled(target, 0.001)
    if 0.02 <= max(_width_height(in_metres)) <= MAX_TARGET_EXTENT:
        _fail(type(target).__name__,
              f"the sizes look like millimetres (the pattern would be {board}); sizes are in "
              f"metres: {format_target(in_metres)}")
    _fail(type(target).__name__, f"the pattern would be {board}, larger than the "
                                 f"{MAX_TARGET_EXTENT:g} m a target may be (sizes are in metres)")


# --------------------------------------------------------------------------------------------
# Spec strings

_SIZE_RE = re.compile(r"^(\d+)[xX](\d+)$")


def _format_length(v: float) -> str:
    s = repr(float(v))
    return s[:-2] if s.endswith(".0") else s


def parse_target(spec: str) -> Target:
    """Parses a target spec string (see the module docstring). ValueError naming the spec, the
    bad field and the expected form otherwise."""
    if isinstance(spec, TARGET_TYPES):
        return validate_target(spec)
    if not isinstance(spec, str):
        raise ValueError(f"target spec: expected a string, got {type(spec).__name__}")
    fields = spec.strip().split(":")
    kind = fields[0].strip().lower()
    if kind not in SPEC_FORMS:
        raise ValueError(f"target spec {spec!r}: unknown target type {fields[0]!r}; expected one "
                         f"of: " + "; ".join(SPEC_FORMS.values()))
    form = SPEC_FORMS[kind]

    def bad(index: int, label: str, problem: str):
        raise ValueError(f"target spec {spec!r}: field {index + 1} ({label}) {problem}; expected "
                         f"{form}")

    def count(min_n: int, max_n: int):
        if not min_n <= len(fields) <= max_n:
            raise ValueError(f"target spec {spec!r}: expected {min_n}"
                             f"{'' if min_n == max_n else f' to {max_n}'} ':'-separated fields, "
                             f"got {len(fields)}; expected {form}")

    def grid(index: int, label: str, minimum: int) -> tuple[int, int]:
        m = _SIZE_RE.match(fields[index].strip())
        if not m:
            bad(index, label, f"{fields[index]!r} is not of the form NxM")
        a, b = int(m.group(1)), int(m.group(2))
        if a < minimum or b < minimum:
            bad(index, label, f"{fields[index]!r}: both numbers must be ≥ {minimum}")
        return a, b

    def length(index: int, label: str) -> float:
        try:
            v = float(fields[index])
        except ValueError:
            v = float("nan")
        if not math.isfinite(v) or v <= 0:
            bad(index, label, f"{fields[index]!r} is not a length > 0 in metres")
        return v

    def integer(index: int, label: str) -> int:
        text = fields[index].strip()
        if not text.isdigit():
            bad(index, label, f"{fields[index]!r} is not a non-negative integer")
        return int(text)

    def family(index: int) -> str:
        f = fields[index].strip().lower()
        f = f[3:] if f.startswith("tag") else f
        if f not in APRILTAG_FAMILIES:
            bad(index, "FAMILY", f"{fields[index]!r} is not one of {', '.join(APRILTAG_FAMILIES)}")
        return f

    try:
        if kind == "chessboard":
            count(3, 3)
            cols, rows = grid(1, "COLSxROWS", 3)
            target = ChessboardTarget(cols, rows, length(2, "SQUARE"))
        elif kind == "charuco":
            count(5, 6)
            sx, sy = grid(1, "SQUARESXxSQUARESY", 2)
            square, marker = length(2, "SQUARE"), length(3, "MARKER")
            if marker >= square:
                bad(3, "MARKER", f"{fields[3]!r} must be smaller than SQUARE {fields[2]!r}")
            try:
                dictionary = canonical_dictionary(fields[4])
            except ValueError as e:
                bad(4, "DICT", str(e).removeprefix("dictionary: "))
            legacy = False
            if len(fields) == 6:
                if fields[5].strip().lower() != "legacy":
                    bad(5, "legacy", f"{fields[5]!r} must be 'legacy' or absent")
                legacy = True
            target = CharucoTarget(sx, sy, square, marker, dictionary, legacy)
        elif kind == "apriltag":
            count(3, 4)
            fam = family(1)
            size = length(2, "SIZE")
            tag_id = integer(3, "ID") if len(fields) == 4 else 0
            n = _dictionary_size(apriltag_dictionary_name(fam))
            if tag_id >= n:
                bad(3, "ID", f"{tag_id} is out of range: family {fam} has ids 0…{n - 1}")
            target = AprilTagTarget(fam, size, tag_id)
        elif kind == "aprilgrid":
            count(5, 6)
            fam = family(1)
            tx, ty = grid(2, "TAGSXxTAGSY", 1)
            size = length(3, "SIZE")
            spacing = length(4, "SPACING")
            first = integer(5, "FIRST_ID") if len(fields) == 6 else 0
            n = _dictionary_size(apriltag_dictionary_name(fam))
            if first + tx * ty > n:
                bad(5 if len(fields) == 6 else 2, "FIRST_ID" if len(fields) == 6 else "TAGSXxTAGSY",
                    f"needs ids up to {first + tx * ty - 1} but family {fam} has ids 0…{n - 1}")
            target = AprilGridTarget(fam, tx, ty, size, spacing, first)
        else:
            count(3, 5)
            cols, rows = grid(1, "COLSxROWS", 2)
            spacing = length(2, "SPACING")
            white = False
            last = len(fields) - 1
            if last >= 3 and fields[last].strip().lower() in ("white", "black"):
                white = fields[last].strip().lower() == "white"
                last -= 1
            if last > 3:
                bad(4, "white", f"{fields[4]!r} must be 'white', 'black' or absent")
            diameter = length(3, "DIAMETER") if last == 3 else None
            target = CircleGridTarget(cols, rows, spacing, kind == "acircles", diameter, white)
        return _validate(target)
    except ValueError as e:
        if str(e).startswith(f"target spec {spec!r}"):
            raise
        raise ValueError(f"target spec {spec!r}: {e}; expected {form}") from None


def format_target(target) -> str:
    """The spec string of a target; ``parse_target(format_target(t)) == t`` and
    ``format_target(parse_target(s)) == s`` for canonical specs."""
    target = validate_target(target)
    if isinstance(target, ChessboardTarget):
        return f"chessboard:{target.cols}x{target.rows}:{_format_length(target.square)}"
    if isinstance(target, CharucoTarget):
        return (f"charuco:{target.squares_x}x{target.squares_y}:{_format_length(target.square)}:"
                f"{_format_length(target.marker)}:{target.dictionary}"
                + (":legacy" if target.legacy else ""))
    if isinstance(target, AprilTagTarget):
        return (f"apriltag:{target.family}:{_format_length(target.size)}"
                + (f":{target.id}" if target.id else ""))
    if isinstance(target, CircleGridTarget):
        kind = "acircles" if target.asymmetric else "circles"
        default = _validate(dataclasses.replace(target, diameter=None)).diameter
        return (f"{kind}:{target.cols}x{target.rows}:{_format_length(target.spacing)}"
                + ("" if target.diameter == default else f":{_format_length(target.diameter)}")
                + (":white" if target.white else ""))
    return (f"aprilgrid:{target.family}:{target.tags_x}x{target.tags_y}:"
            f"{_format_length(target.size)}:{_format_length(target.spacing)}"
            + (f":{target.first_id}" if target.first_id else ""))


# --------------------------------------------------------------------------------------------
# OpenCV board objects


def charuco_board(target: CharucoTarget, legacy: bool | None = None):
    """``cv2.aruco.CharucoBoard`` of a ChArUco target (``legacy`` overrides the target's)."""
    aruco = _aruco()
    board = aruco.CharucoBoard((target.squares_x, target.squares_y), float(target.square),
                               float(target.marker), get_dictionary(target.dictionary))
    board.setLegacyPattern(bool(target.legacy if legacy is None else legacy))
    return board


def grid_board(target: AprilGridTarget):
    """``cv2.aruco.GridBoard`` of an AprilTag grid."""
    aruco = _aruco()
    ids = np.arange(target.first_id, target.first_id + target.tags_x * target.tags_y,
                    dtype=np.int32)
    return aruco.GridBoard((target.tags_x, target.tags_y), float(target.size),
                           float(target.size * target.spacing),
                           get_dictionary(apriltag_dictionary_name(target.family)), ids)


def _tag_top_left_corners(target) -> tuple[np.ndarray, np.ndarray]:
    """(tag ids (M,), top-left corners (M, 2) in T) of the tags of an AprilTag target."""
    if isinstance(target, AprilTagTarget):
        return np.array([target.id]), np.array([[-0.5 * target.size, -0.5 * target.size]])
    pitch = target.size * (1.0 + target.spacing)
    r, c = np.divmod(np.arange(target.tags_x * target.tags_y), target.tags_x)
    ids = target.first_id + np.arange(target.tags_x * target.tags_y)
    return ids, np.stack([c * pitch, r * pitch], axis=1)


_CORNER_OFFSETS = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])  # ArUco order


def _charuco_marker_squares(target: CharucoTarget) -> tuple[np.ndarray, np.ndarray]:
    """(marker ids, (i, j) square indices) of the markers of a ChArUco board, from OpenCV."""
    board = charuco_board(target)
    ids = np.asarray(board.getIds()).ravel()
    centres = np.array([np.asarray(p)[:, :2].mean(axis=0) for p in board.getObjPoints()])
    squares = np.floor(centres / target.square).astype(int)
    return ids, squares


# --------------------------------------------------------------------------------------------
# Geometry


def object_points(target) -> tuple[np.ndarray, np.ndarray]:
    """Every point the detector can report, in T.

    Returns:
        (ids (N,) int, p_TQ (N, 3) float, metres), ids in increasing order: chessboard corners
        0…COLS·ROWS−1, ChArUco corners 0…(SQUARESX−1)(SQUARESY−1)−1, AprilTag corners
        tag_id·4 + k (see the module docstring for the positions)."""
    ids, p = _object_points(validate_target(target))
    return ids.copy(), p.copy()


@functools.lru_cache(maxsize=64)
def _object_points(target) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(target, ChessboardTarget):
        j, i = np.divmod(np.arange(target.cols * target.rows), target.cols)
        p = np.stack([i * target.square, j * target.square, np.zeros(i.size)], axis=1)
        return np.arange(i.size), p
    if isinstance(target, CircleGridTarget):
        return np.arange(target.cols * target.rows), _circle_centres(target)
    if isinstance(target, CharucoTarget):
        nx = target.squares_x - 1
        j, i = np.divmod(np.arange(nx * (target.squares_y - 1)), nx)
        p = np.stack([(i + 1) * target.square, (j + 1) * target.square, np.zeros(i.size)], axis=1)
        return np.arange(i.size), p
    tag_ids, top_left = _tag_top_left_corners(target)
    corners = top_left[:, None, :] + target.size * _CORNER_OFFSETS[None]
    ids = (4 * tag_ids[:, None] + np.arange(4)[None]).ravel()
    p = np.concatenate([corners.reshape(-1, 2), np.zeros((ids.size, 1))], axis=1)
    return ids, p


def _circle_centres(target: CircleGridTarget) -> np.ndarray:
    """(COLS·ROWS, 3) circle centres in T, in id order."""
    j, i = np.divmod(np.arange(target.cols * target.rows), target.cols)
    x = (2 * i + j % 2) if target.asymmetric else i
    return np.stack([x * target.spacing, j * target.spacing, np.zeros(i.size)], axis=1)


def circles(target) -> np.ndarray:
    """(N, 3) [x, y, radius] (m, in T) of the circles of a circle grid, in id order (the
    circles are white on a black ``pattern_extent`` when ``target.white``, else black)."""
    target = validate_target(target)
    if not isinstance(target, CircleGridTarget):
        raise ValueError(f"target: {format_target(target)} is not a circle grid")
    c = _circle_centres(target)
    return np.column_stack([c[:, :2], np.full(len(c), 0.5 * target.diameter)])


def target_symmetries(target) -> list[tuple[np.ndarray, np.ndarray]]:
    """The rigid motions of the plane that map the target's points onto themselves, printed
    colours included, other than the identity: [(G, perm)] with G the 4×4 pose of the moved
    board in T and ``perm[k]`` the id that point k lands on (``G p_k = p_perm[k]``). A detector
    cannot tell these views apart: with labels read off by one of them, the true pose is
    ``X_CT · G⁻¹`` and the true id of point k is ``perm[k]``. Empty for boards whose orientation
    is printed (ChArUco, tags, chessboards with COLS + ROWS odd, asymmetric grids of odd ROWS)."""
    target = validate_target(target)
    if isinstance(target, ChessboardTarget):
        turns = [] if (target.cols + target.rows) % 2 else [2]
        # A square board with an odd square count per side keeps its colours after a quarter
        # turn too (the corner squares are all black).
        if target.cols == target.rows and target.cols % 2 == 0:
            turns = [1, 2, 3]
    elif isinstance(target, CircleGridTarget):
        if target.asymmetric:
            turns = [2] if target.rows % 2 == 0 else []
        else:
            turns = [1, 2, 3] if target.cols == target.rows else [2]
    else:
        turns = []
    if not turns:
        return []
    ids, p = object_points(target)
    centre = 0.5 * (p.min(axis=0) + p.max(axis=0))
    out = []
    for k in turns:
        c, s = np.round(math.cos(k * math.pi / 2)), np.round(math.sin(k * math.pi / 2))
        G = np.eye(4)
        G[:2, :2] = [[c, -s], [s, c]]
        G[:3, 3] = centre - G[:3, :3] @ centre
        q = p @ G[:3, :3].T + G[:3, 3]
        d = np.linalg.norm(q[:, None, :2] - p[None, :, :2], axis=2)
        perm = np.argmin(d, axis=1)
        if np.max(d[np.arange(len(q)), perm]) > 1e-9 * max(1.0, float(np.ptp(p))):
            continue
        out.append((G, ids[perm]))
    return out


def pattern_extent(target) -> tuple[float, float, float, float]:
    """(x_min, y_min, x_max, y_max) in T (m) of the printed pattern: the outer squares of a
    chessboard, the whole ChArUco board, the black borders of the tags; no white margin."""
    return _extent(validate_target(target))


def _extent(target) -> tuple[float, float, float, float]:
    if isinstance(target, ChessboardTarget):
        s = target.square
        return (-s, -s, target.cols * s, target.rows * s)
    if isinstance(target, CharucoTarget):
        return (0.0, 0.0, target.squares_x * target.square, target.squares_y * target.square)
    if isinstance(target, CircleGridTarget):
        s = target.spacing
        width = 2 * (target.cols - 1) + (target.rows > 1) if target.asymmetric else target.cols - 1
        return (-s, -s, (width + 1) * s, target.rows * s)
    if isinstance(target, AprilTagTarget):
        h = 0.5 * target.size
        return (-h, -h, h, h)
    pitch = target.size * (1.0 + target.spacing)
    return (0.0, 0.0, (target.tags_x - 1) * pitch + target.size,
            (target.tags_y - 1) * pitch + target.size)


def _marker_rectangles(bits: np.ndarray, x0: float, y0: float, cell: float) -> list:
    """Black rectangles (x0, y0, x1, y1) of a marker bit image (0 = black), one per horizontal
    run of black cells."""
    rects = []
    for r, row in enumerate(bits):
        c = 0
        n = row.size
        while c < n:
            if row[c] == 0:
                start = c
                while c < n and row[c] == 0:
                    c += 1
                rects.append((x0 + start * cell, y0 + r * cell, x0 + c * cell, y0 + (r + 1) * cell))
            else:
                c += 1
    return rects


def _marker_bits(dictionary, marker_id: int) -> np.ndarray:
    n = dictionary.markerSize + 2
    return (dictionary.generateImageMarker(int(marker_id), n, borderBits=1) > 127).astype(np.uint8)


def black_rectangles(target) -> np.ndarray:
    """(M, 4) array of the non-overlapping black rectangles [x0, y0, x1, y1] (m, in T) that make
    up the printed pattern (everything else inside ``pattern_extent`` is white)."""
    target = validate_target(target)
    rects = []
    if isinstance(target, CircleGridTarget):
        # The circles themselves are ``circles``; a white-circle board is printed on black.
        if target.white:
            rects.append(pattern_extent(target))
    elif isinstance(target, ChessboardTarget):
        s = target.square
        for j in range(target.rows + 1):
            for i in range(target.cols + 1):
                if (i + j) % 2 == 0:  # the top-left square is black
                    rects.append(((i - 1) * s, (j - 1) * s, i * s, j * s))
    elif isinstance(target, CharucoTarget):
        s, m = target.square, target.marker
        ids, squares = _charuco_marker_squares(target)
        white = {tuple(sq) for sq in squares}
        for j in range(target.squares_y):
            for i in range(target.squares_x):
                if (i, j) not in white:
                    rects.append((i * s, j * s, (i + 1) * s, (j + 1) * s))
        dictionary = get_dictionary(target.dictionary)
        cell = m / (dictionary.markerSize + 2)
        offset = 0.5 * (s - m)
        for marker_id, (i, j) in zip(ids, squares):
            rects += _marker_rectangles(_marker_bits(dictionary, marker_id), i * s + offset,
                                        j * s + offset, cell)
    else:
        dictionary = get_dictionary(apriltag_dictionary_name(target.family))
        cell = target.size / (dictionary.markerSize + 2)
        for tag_id, (x0, y0) in zip(*_tag_top_left_corners(target)):
            rects += _marker_rectangles(_marker_bits(dictionary, tag_id), x0, y0, cell)
    return np.array(rects, dtype=float).reshape(-1, 4)


# --------------------------------------------------------------------------------------------
# Rendering


def _coverage(e0: float, e1: float) -> tuple[int, np.ndarray]:
    """First pixel index and per-pixel coverage of the interval [e0, e1) in pixel-edge units
    (pixel k covers [k, k + 1))."""
    k0 = int(math.floor(e0))
    k1 = max(int(math.ceil(e1)), k0 + 1)
    k = np.arange(k0, k1)
    return k0, np.clip(np.minimum(e1, k + 1) - np.maximum(e0, k), 0.0, 1.0)


_SUB = (np.arange(4) + 0.5) / 4.0  # 4×4 sub-pixel samples


def _add_disc(dark: np.ndarray, cx: float, cy: float, r: float, sign: float) -> None:
    """Adds ``sign`` × the fraction of each pixel covered by the disc of centre (cx, cy) and
    radius r (pixel-edge units: pixel k covers [k, k + 1)): 4×4 sub-samples per pixel, each
    covered by the linear ramp of its distance to the circle over a sub-sample's width (the
    rendered disc is symmetric about its centre, so its grey centroid is the true one)."""
    h, w = dark.shape
    c0, c1 = max(int(math.floor(cx - r - 1)), 0), min(int(math.ceil(cx + r + 1)), w)
    r0, r1 = max(int(math.floor(cy - r - 1)), 0), min(int(math.ceil(cy + r + 1)), h)
    if c0 >= c1 or r0 >= r1:
        return
    xs = (np.arange(c0, c1)[:, None] + _SUB[None]).ravel() - cx    # (W·4,)
    ys = (np.arange(r0, r1)[:, None] + _SUB[None]).ravel() - cy
    d = np.hypot(ys[:, None], xs[None, :])
    cover = np.clip((r - d) * 4.0 + 0.5, 0.0, 1.0)
    cover = cover.reshape(r1 - r0, 4, c1 - c0, 4).mean(axis=(1, 3))
    dark[r0:r1, c0:c1] += sign * cover


def render_target(target, pixels_per_metre: float,
                  margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Grey image of the pattern, exactly to scale, with a white margin around it.

    Each pixel's grey level is the exact white fraction of its square (box-filter anti-aliasing),
    so edges fall at their true sub-pixel positions at any scale.

    Args:
        target: a target or a spec string.
        pixels_per_metre: resolution (> 0); e.g. dpi / 0.0254.
        margin: white border around ``pattern_extent`` in metres (≥ 0).

    Returns:
        (image, A): uint8 (H, W) image (0 black, 255 white) and the 3×3 affine map of
        (x_T, y_T, 1) in metres to (col, row, 1) in OpenCV pixel coordinates (pixel centres at
        integers). The image covers [x_min − margin, …) × [y_min − margin, …); W and H are rounded
        up to whole pixels, the extra fraction is white.
    """
    target = validate_target(target)
    ppm = _positive(pixels_per_metre, "pixels_per_metre", "pixels per metre")
    try:
        margin = float(margin)
    except (TypeError, ValueError):
        raise ValueError(f"margin: expected a length in metres, got {margin!r}") from None
    if not math.isfinite(margin) or margin < 0:
        raise ValueError(f"margin: must be a finite length ≥ 0 m, got {margin!r}")
    x_min, y_min, x_max, y_max = pattern_extent(target)
    left, top = x_min - margin, y_min - margin
    width = int(math.ceil((x_max - x_min + 2 * margin) * ppm - 1e-9))
    height = int(math.ceil((y_max - y_min + 2 * margin) * ppm - 1e-9))
    if width * height > 200_000_000:
        raise ValueError(f"pixels_per_metre: {ppm:g} px/m makes a {width}×{height} image, more "
                         f"than 2e8 pixels; lower the resolution")
    dark = np.zeros((height, width))
    for x0, y0, x1, y1 in black_rectangles(target):
        c0, cx = _coverage((x0 - left) * ppm, (x1 - left) * ppm)
        r0, cy = _coverage((y0 - top) * ppm, (y1 - top) * ppm)
        # (An edge on the last pixel boundary can round one pixel past it: nothing to cover.)
        cx, cy = cx[:max(width - c0, 0)], cy[:max(height - r0, 0)]
        dark[r0:r0 + cy.size, c0:c0 + cx.size] += cy[:, None] * cx[None, :]
    if isinstance(target, CircleGridTarget):
        sign = -1.0 if target.white else 1.0
        for x, y, radius in circles(target):
            _add_disc(dark, (x - left) * ppm, (y - top) * ppm, radius * ppm, sign)
    image = np.round(255.0 * (1.0 - np.clip(dark, 0.0, 1.0))).astype(np.uint8)
    A = np.array([[ppm, 0.0, -left * ppm - 0.5],
                  [0.0, ppm, -top * ppm - 0.5],
                  [0.0, 0.0, 1.0]])
    return image, A


# --------------------------------------------------------------------------------------------
# Printable files


def target_caption(target) -> str:
    """One line for the printed sheet: the spec and the sizes to check after printing."""
    target = validate_target(target)
    mm = lambda v: f"{1000 * v:.3f}".rstrip("0").rstrip(".")  # noqa: E731
    if isinstance(target, ChessboardTarget):
        sizes = f"square {mm(target.square)} mm"
    elif isinstance(target, CharucoTarget):
        sizes = f"square {mm(target.square)} mm, marker {mm(target.marker)} mm"
    elif isinstance(target, AprilTagTarget):
        sizes = f"tag (black border) {mm(target.size)} mm"
    elif isinstance(target, CircleGridTarget):
        pitch = 2 * target.spacing if target.asymmetric else target.spacing
        sizes = (f"circle diameter {mm(target.diameter)} mm, centres {mm(pitch)} mm apart in a "
                 f"row" + (f", rows {mm(target.spacing)} mm apart" if target.asymmetric else ""))
    else:
        sizes = (f"tag (black border) {mm(target.size)} mm, gap "
                 f"{mm(target.size * target.spacing)} mm")
    return f"{format_target(target)}  |  print at 100% (no fit to page): {sizes}"


def _png_with_dpi(image: np.ndarray, dpi: float) -> bytes:
    import cv2
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise ValueError("image: OpenCV could not encode the PNG")
    data = buf.tobytes()
    ppm = int(round(dpi / 0.0254))
    body = b"pHYs" + struct.pack(">IIB", ppm, ppm, 1)  # unit 1 = metre
    chunk = struct.pack(">I", 9) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)
    ihdr_end = 8 + 25  # signature + IHDR chunk (13-byte payload)
    return data[:ihdr_end] + chunk + data[ihdr_end:]


def png_pixels_per_metre(path) -> tuple[int, int] | None:
    """(x, y) pixels per metre of a PNG's pHYs chunk, None when it has none (metre unit only)."""
    data = Path(path).read_bytes()
    pos = 8
    while pos + 8 <= len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        if kind == b"pHYs":
            x, y, unit = struct.unpack(">IIB", data[pos + 8:pos + 17])
            return (x, y) if unit == 1 else None
        if kind == b"IDAT":
            return None
        pos += 12 + length
    return None


def _caption_strip(text: str, width: int, ppm: float) -> np.ndarray:
    import cv2
    height = max(int(round(0.008 * ppm)), 12)
    strip = np.full((height, width), 255, np.uint8)
    font = cv2.FONT_HERSHEY_SIMPLEX
    (tw, th), _ = cv2.getTextSize(text, font, 1.0, 1)
    scale = min(0.45 * height / th, 0.98 * width / tw)
    thickness = max(1, int(round(scale * 1.5)))
    (tw, th), _ = cv2.getTextSize(text, font, scale, thickness)
    cv2.putText(strip, text, (max(0, (width - tw) // 2), (height + th) // 2), font, scale, 0,
                thickness, cv2.LINE_AA)
    return strip


def _svg(target, margin: float, caption: str) -> str:
    x_min, y_min, x_max, y_max = pattern_extent(target)
    w_mm = 1000 * (x_max - x_min + 2 * margin)
    caption_mm = 8.0
    h_mm = 1000 * (y_max - y_min + 2 * margin) + caption_mm
    lines = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w_mm:.6f}mm" height="{h_mm:.6f}mm" '
             f'viewBox="0 0 {w_mm:.6f} {h_mm:.6f}" shape-rendering="crispEdges">',
             f'<rect x="0" y="0" width="{w_mm:.6f}" height="{h_mm:.6f}" fill="#ffffff"/>']
    for x0, y0, x1, y1 in black_rectangles(target):
        lines.append(f'<rect x="{1000 * (x0 - x_min + margin):.6f}" '
                     f'y="{1000 * (y0 - y_min + margin):.6f}" width="{1000 * (x1 - x0):.6f}" '
                     f'height="{1000 * (y1 - y0):.6f}" fill="#000000"/>')
    if isinstance(target, CircleGridTarget):
        fill = "#ffffff" if target.white else "#000000"
        for x, y, r in circles(target):
            lines.append(f'<circle cx="{1000 * (x - x_min + margin):.6f}" '
                         f'cy="{1000 * (y - y_min + margin):.6f}" r="{1000 * r:.6f}" '
                         f'fill="{fill}" shape-rendering="geometricPrecision"/>')
    size = min(3.0, 1.6 * w_mm / max(len(caption), 1))
    lines.append(f'<text x="{w_mm / 2:.3f}" y="{h_mm - caption_mm / 2 + size / 3:.3f}" '
                 f'font-family="sans-serif" font-size="{size:.3f}" text-anchor="middle">'
                 f'{caption.replace("&", "&amp;").replace("<", "&lt;")}</text>')
    lines.append("</svg>")
    return "\n".join(lines) + "\n"


def _pdf(target, margin: float, caption: str, path: Path) -> None:
    from matplotlib.collections import PolyCollection
    from matplotlib.figure import Figure

    x_min, y_min, x_max, y_max = pattern_extent(target)
    caption_m = 0.008
    w = x_max - x_min + 2 * margin
    h = y_max - y_min + 2 * margin + caption_m
    fig = Figure(figsize=(w / 0.0254, h / 0.0254))
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(0.0, w)
    ax.set_ylim(h, 0.0)
    ax.set_axis_off()
    polys = [[(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
             for x0, y0, x1, y1 in black_rectangles(target) - [x_min - margin, y_min - margin] * 2]
    ax.add_collection(PolyCollection(polys, facecolors="black", edgecolors="none",
                                     linewidths=0, antialiaseds=False))
    if isinstance(target, CircleGridTarget):
        from matplotlib.patches import Circle
        for x, y, r in circles(target):
            ax.add_patch(Circle((x - x_min + margin, y - y_min + margin), r, linewidth=0,
                                facecolor="white" if target.white else "black"))
    points = min(8.5, 1.6 * w / 0.0254 * 72 / max(len(caption), 1))
    ax.text(w / 2, h - caption_m / 2, caption, ha="center", va="center", fontsize=points)
    fig.savefig(path, format="pdf")


def object_points_description(target) -> str:
    """Where the target frame T is on the printed sheet (see the module docstring)."""
    target = validate_target(target)
    axes = "x to the right along the columns, y down along the rows, z into the board"
    if isinstance(target, ChessboardTarget):
        where = ("origin at the first inner corner (diagonally next to the black corner square "
                 "at the top left)")
    elif isinstance(target, CharucoTarget):
        where = "origin at the top-left outer corner of the board"
    elif isinstance(target, AprilTagTarget):
        where = "origin at the tag centre"
    elif isinstance(target, CircleGridTarget):
        where = "origin at the centre of the top-left circle"
    else:
        where = "origin at the top-left corner of the top-left tag"
    return f"{where}; {axes} (as printed)"


def write_printable(target, path, dpi: float = 300, margin: float = 0.01) -> list[Path]:
    """Writes the target at true scale for printing: ``path`` as a PNG whose pHYs chunk carries
    ``dpi``, plus an SVG and a PDF (same stem) sized in millimetres. Each has a white ``margin``
    (m) around the pattern and a caption line below it with the spec and the sizes to check.

    Returns the written paths (PNG, SVG, PDF)."""
    target = validate_target(target)
    dpi = _positive(dpi, "dpi", "dots per inch")
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise ValueError(f"path: expected a .png file name, got {str(path)!r}")
    if not path.parent.is_dir():
        raise ValueError(f"path: directory {str(path.parent)!r} does not exist")
    ppm = dpi / 0.0254
    image, _ = render_target(target, ppm, margin)
    caption = target_caption(target)
    page = np.vstack([image, _caption_strip(f"{caption}  |  {dpi:g} dpi", image.shape[1], ppm)])
    path.write_bytes(_png_with_dpi(page, dpi))
    svg = path.with_suffix(".svg")
    svg.write_text(_svg(target, margin, caption), encoding="utf-8")
    pdf = path.with_suffix(".pdf")
    _pdf(target, margin, caption, pdf)
    return [path, svg, pdf]


__all__ = [
    "APRILTAG_FAMILIES",
    "AprilGridTarget",
    "AprilTagTarget",
    "CharucoTarget",
    "ChessboardTarget",
    "CircleGridTarget",
    "Target",
    "apriltag_dictionary_name",
    "black_rectangles",
    "canonical_dictionary",
    "charuco_board",
    "circles",
    "dictionary_names",
    "format_target",
    "get_dictionary",
    "object_points_description",
    "grid_board",
    "object_points",
    "parse_target",
    "pattern_extent",
    "png_pixels_per_metre",
    "render_target",
    "target_caption",
    "target_dictionary_name",
    "target_symmetries",
    "validate_target",
    "write_printable",
]

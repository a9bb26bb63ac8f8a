"""Time stamps of image files, for pairing images with a robot pose stream in time.

Where a folder's stamps come from, first match wins:

1. a stamps file in the folder, ``timestamps.txt`` or ``times.csv`` (both present: ambiguous).
   One line per image, fields separated by commas or blanks, ``#`` starts a comment, a first
   line without numbers is a header. Either two fields, the image's file name and its stamp in
   either order (TUM RGB-D ``rgb.txt``: ``1305031102.175304 rgb/1305031102.175304.png``; EuRoC
   ``data.csv``: ``1403636579763555584,1403636579763555584.png``; lines naming other files are
   ignored), or one field per line, the stamps of the images in natural file-name order (KITTI
   ``times.txt``; as many lines as images);
2. the file names, all of one folder following one convention, with any prefix that ends in a
   non-digit (``frame_``, ``left``, ``cam0-``):

   - ``<seconds>.<fraction>`` — ``1700000000.125.png``, ``frame_12.500.png`` (TUM RGB-D);
   - ``<seconds>_<nanoseconds>`` with 9 digits of nanoseconds — ``1700000000_125000000.png``
     (bag extraction scripts writing ``header.stamp.sec`` and ``nanosec``);
   - ``<nanoseconds>`` of 18 or 19 digits (an epoch time in ns, 2001–2286) —
     ``1700000000125000000.png``, ``frame_1700000000125000000.png`` (EuRoC, Kalibr's
     ``bagextractor``).

   A name of a shorter whole number (``img_007.png``, ``frame0042.jpg`` — the frame numbers of
   ``image_view extract_images``) holds no stamp: it orders the images, it does not place them
   in time. Whole numbers of 11–17 digits are refused as ambiguous (microseconds since the epoch,
   or nanoseconds since boot?): a stamps file says which.

Units in a stamps file: numbers with a decimal point or exponent are seconds; whole numbers of
18–19 digits nanoseconds; other whole numbers need the unit in the header (``# timestamp [ns]``,
``[us]``, ``[ms]``, ``[s]``). Stamps are seconds, on the camera's clock (the offset to the robot's
clock is the caller's business). No image library is imported here.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: The stamps files looked for in an image folder, in this order.
STAMP_FILES = ("timestamps.txt", "times.csv")
#: Largest stamps file read (bytes): a stamp per image, never a data set.
MAX_STAMP_FILE_BYTES = 20_000_000

_PREFIX = r"(?:.*[^\d.])?"
_NAME_RULES = (
    ("<seconds>.<fraction>", re.compile(_PREFIX + r"(?P<s>\d+)\.(?P<f>\d{1,9})")),
    ("<seconds>_<nanoseconds>", re.compile(_PREFIX + r"(?P<s>\d+)_(?P<ns>\d{9})")),
    ("<nanoseconds>", re.compile(_PREFIX + r"(?P<ns>\d{18,19})")),
)
_AMBIGUOUS_INT = re.compile(_PREFIX + r"(?P<i>\d{11,17})")
_UNITS = {"ns": 1e-9, "us": 1e-6, "µs": 1e-6, "ms": 1e-3, "s": 1.0, "sec": 1.0}


@dataclass(frozen=True)
class ImageStamps:
    """The stamps of one folder's images.

    Attributes:
        stamps: (N,) seconds, one per file in the order given; None when not every image has one.
        source: where they came from ("file names <seconds>.<fraction>", "timestamps.txt", …).
        problem: why there are none ("" when there are): names no stamp, which image misses
            one, which convention is ambiguous — a sentence naming the folder.
        unstamped: no image of the folder carries a stamp at all (frame numbers, no stamps
            file), as against stamps that are there but missing for some or ambiguous.
    """
    stamps: np.ndarray | None
    source: str
    problem: str = ""
    unstamped: bool = False


def stamp_from_name(name: str) -> tuple[float, str] | None:
    """(seconds, convention) of an image file name (with its extension) following a convention
    of the module docstring, else None."""
    stem = Path(name).stem
    for rule, rx in _NAME_RULES:
        m = rx.fullmatch(stem)
        if m is None:
            continue
        if "f" in m.groupdict() and m.group("f") is not None:
            f = m.group("f")
            return int(m.group("s")) + int(f) / 10.0 ** len(f), rule
        if m.groupdict().get("s") is not None:
            return int(m.group("s")) + int(m.group("ns")) * 1e-9, rule
        ns = int(m.group("ns"))
        return ns // 1_000_000_000 + (ns % 1_000_000_000) * 1e-9, rule
    return None


def _number(text: str, unit: float | None) -> float | None:
    """Seconds of one field of a stamps file (module docstring's units), None when it is not a
    number; ValueError when it is a whole number of no known unit."""
    t = text.strip()
    if not re.fullmatch(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?", t):
        return None
    if unit is not None:
        if re.fullmatch(r"\d+", t) and unit < 1.0:
            return int(t) * unit   # ns as integers: exact before the one rounding to float
        return float(t) * unit
    if re.fullmatch(r"[+-]?\d+", t):
        if len(t.lstrip("+-")) in (18, 19):
            ns = int(t)
            return ns // 1_000_000_000 + (ns % 1_000_000_000) * 1e-9
        raise ValueError(f"the whole number {t} has no unit (seconds? nanoseconds?)")
    return float(t)


def _header_unit(line: str) -> float | None:
    m = re.search(r"[\[(]\s*(ns|us|µs|ms|s|sec)\s*[\])]", line)
    return _UNITS[m.group(1)] if m else None


def read_stamp_file(path, files) -> np.ndarray:
    """Stamps (s) of ``files`` (Paths, natural file-name order) from a stamps file (module
    docstring). ValueError naming the file and line when it does not give exactly one stamp per
    image."""
    path = Path(path)
    if path.stat().st_size > MAX_STAMP_FILE_BYTES:
        raise ValueError(f"{path}: larger than {MAX_STAMP_FILE_BYTES // 1_000_000} MB, not a "
                         "stamps file")
    names = {f.name: k for f, k in zip(files, range(len(files)))}
    unit, single, by_name = None, [], {}
    seen_data = False
    with open(path, encoding="utf-8", errors="replace") as fh:
        for number, raw in enumerate(fh, 1):
            line = raw.strip()
            if line.startswith("#"):
                if not seen_data:
                    unit = _header_unit(line) or unit
                continue
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            fields = [x for x in re.split(r"[,\s]+", line) if x]
            try:
                values = [_number(x, unit) for x in fields]
            except ValueError as e:
                raise ValueError(f"{path}:{number}: {e} — write seconds with a decimal point, "
                                 "or name the unit in a header line (# timestamp [ns])") \
                    from None
            if not seen_data and all(v is None for v in values):
                unit = _header_unit(line) or unit    # a header line
                seen_data = True
                continue
            seen_data = True
            if len(fields) == 1 and values[0] is not None:
                single.append(values[0])
                continue
            named = [x for x in fields if Path(x).name in names]
            stamps = [v for v in values if v is not None]
            if len(fields) >= 2 and not named and any(
                    Path(x).suffix for x, v in zip(fields, values) if v is None):
                continue                              # a line about another file
            if len(named) != 1 or len(stamps) != 1:
                raise ValueError(f"{path}:{number}: expected an image file name and its stamp "
                                 f"(or one stamp per line), got {line[:80]!r}")
            key = Path(named[0]).name
            if key in by_name:
                raise ValueError(f"{path}:{number}: {key} is stamped twice")
            by_name[key] = stamps[0]
    if single and by_name:
        raise ValueError(f"{path}: mixes lines of one stamp with lines of a file name and a stamp")
    if single:
        if len(single) != len(files):
            raise ValueError(f"{path}: {len(single)} stamps for {len(files)} images (one stamp "
                             "per line, in natural file-name order, is one per image)")
        return np.array(single, float)
    missing = [f.name for f in files if f.name not in by_name]
    if missing:
        raise ValueError(f"{path}: no stamp for {len(missing)} of {len(files)} images ("
                         + ", ".join(missing[:3]) + (", …" if len(missing) > 3 else "") + ")")
    return np.array([by_name[f.name] for f in files], float)


def folder_of(spec, files) -> Path | None:
    """The folder whose stamps file stamps ``files`` (one ``--images`` argument): the argument
    when it is a directory, else the one directory all its files are in (None when several)."""
    p = Path(spec)
    if p.is_dir():
        return p
    parents = {f.parent for f in files}
    return parents.pop() if len(parents) == 1 else None


def image_stamps(spec, files) -> ImageStamps:
    """The stamps of ``files`` (one ``--images`` argument ``spec``: a folder, files or a glob),
    from a stamps file in their folder, else from their names (module docstring). Never raises
    for stamps that are missing or ambiguous: ``problem`` says which and where, for the caller
    to report when time pairing is asked for."""
    files = [Path(f) for f in files]
    folder = folder_of(spec, files)
    if folder is not None:
        present = [folder / n for n in STAMP_FILES if os.path.isfile(folder / n)]
        if len(present) > 1:
            return ImageStamps(None, "", f"{folder}: holds both {present[0].name} and "
                               f"{present[1].name}: which stamps the images is ambiguous")
        if present:
            try:
                t = read_stamp_file(present[0], files)
            except (ValueError, OSError) as e:
                return ImageStamps(None, str(present[0]), str(e))
            return _checked(ImageStamps(t, str(present[0])), files, spec)
    where = folder if folder is not None else spec
    if not files:
        return ImageStamps(None, "", f"{where}: no image")
    parsed = [stamp_from_name(f.name) for f in files]
    rules = {p[1] for p in parsed if p is not None}
    unstamped = [f.name for f, p in zip(files, parsed) if p is None]
    if not rules:
        odd = [f.name for f in files if _AMBIGUOUS_INT.fullmatch(f.stem)]
        if odd:
            return ImageStamps(None, "", (
                f"{where}: file names such as {odd[0]} hold a whole number of "
                f"{len(_AMBIGUOUS_INT.fullmatch(Path(odd[0]).stem).group('i'))} digits: "
                "microseconds or nanoseconds? ambiguous — add a stamps file "
                f"({' or '.join(STAMP_FILES)}) saying which"))
        return ImageStamps(None, "", (
            f"{where}: no time stamp in the file names (e.g. {files[0].name}: a frame number "
            f"orders images, it does not place them in time) and no {' or '.join(STAMP_FILES)}"),
            unstamped=True)
    if len(rules) > 1:
        return ImageStamps(None, "", f"{where}: file names follow different stamp conventions "
                           f"({', '.join(sorted(rules))}): ambiguous")
    if unstamped:
        return ImageStamps(None, "", f"{where}: {len(unstamped)} of {len(files)} images have no "
                           f"time stamp in their name ({', '.join(unstamped[:3])}"
                           f"{', …' if len(unstamped) > 3 else ''})")
    return _checked(ImageStamps(np.array([p[0] for p in parsed]),
                                f"file names {rules.pop()}"), files, spec)


def _checked(s: ImageStamps, files, spec) -> ImageStamps:
    """Stamps that place every image at its own finite instant, else the problem said."""
    t = s.stamps
    where = folder_of(spec, files) or spec
    if not np.all(np.isfinite(t)):
        return ImageStamps(None, s.source, f"{where}: a stamp is not finite ({s.source})")
    order = np.argsort(t, kind="stable")
    same = np.flatnonzero(np.diff(t[order]) <= 0)
    if len(same):
        a, b = files[order[same[0]]].name, files[order[same[0] + 1]].name
        return ImageStamps(None, s.source, f"{where}: {a} and {b} have the same stamp "
                           f"{t[order[same[0]]]:.9f} s ({s.source}): ambiguous")
    return s


__all__ = ["ImageStamps", "MAX_STAMP_FILE_BYTES", "STAMP_FILES", "folder_of", "image_stamps",
           "read_stamp_file", "stamp_from_name"]

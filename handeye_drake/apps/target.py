"""``handeye-drake target``: a calibration target to print, at true scale.

Writes the pattern that ``calibrate --target SPEC`` (and the rendered camera) detects, as a PNG
whose metadata carries the resolution, plus an SVG and a PDF sized in millimetres. A caption under
the pattern repeats the spec and the sizes to measure on the print: a printer that scales the page
changes them, and the calibration's translations scale with them.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from .argtypes import non_negative_float, positive_float
from .outputs import prepare_output_dir

DEFAULT_OUT = "out/target"


#: Paper sizes (mm) checked for the printed page, smallest first.
PAPER_SIZES_MM = {"A4": (210, 297), "US Letter": (216, 279), "A3": (297, 420)}


def _page_mm(png: Path, dpi: float) -> tuple[float, float]:
    """Width and height (mm) of the written page, from the PNG's pixel size at ``dpi``."""
    import struct
    width, height = struct.unpack(">II", png.read_bytes()[16:24])  # the IHDR chunk
    return width / dpi * 25.4, height / dpi * 25.4


#: The smallest square, marker or tag (m) written: a printer's edge spread (≈ 0.05 mm) is 2.5 % of
#: 2 mm, beyond the scale a calibration answers with both readings (docs/target-scale.md); and a
#: smaller pattern is a spec in the wrong unit far more often than a wanted one.
MIN_ELEMENT_M = 0.002
#: The fewest printed pixels across the smallest element at --dpi.
MIN_ELEMENT_PX = 8


def _smallest_element(target) -> tuple[str, float]:
    """(name, size in m) of the target's smallest printed square, marker, tag or circle."""
    # A circle grid's diameter is set by validation (None: half the nearest centre distance).
    sizes = [(name, getattr(target, name)) for name in ("square", "marker", "size", "diameter")
             if getattr(target, name, None) is not None]
    return min(sizes, key=lambda v: v[1])


def _check_printable(target, spec: str, dpi: float) -> None:
    name, size = _smallest_element(target)
    if size < MIN_ELEMENT_M:
        raise ValueError(
            f"SPEC {spec}: its {name} would be {1000 * size:.3g} mm, too small to print at true "
            f"scale (≥ {1000 * MIN_ELEMENT_M:g} mm) or to detect — sizes are in metres "
            f"(a 2 cm {name} is 0.02)")
    if size * dpi / 0.0254 < MIN_ELEMENT_PX:
        raise ValueError(f"--dpi {dpi:g}: the {name} of {1000 * size:.3g} mm would be "
                         f"{size * dpi / 0.0254:.1f} px wide (≥ {MIN_ELEMENT_PX} px needed): "
                         "raise --dpi")


def run_target(args) -> int:
    from ..vision.targets import (object_points_description, parse_target, target_caption,
                                  write_printable)
    target = parse_target(args.spec)
    _check_printable(target, args.spec, args.dpi)
    if Path(args.out).suffix.lower() in (".png", ".svg", ".pdf"):
        raise ValueError(f"--out {args.out}: a folder, like every command's --out (target.png, "
                         "target.svg and target.pdf are written into it)")
    out = prepare_output_dir(args.out, "target", args.force)
    png = out.path("target.png")
    for name in ("target.svg", "target.pdf"):
        out.path(name)
    written = write_printable(target, png, dpi=args.dpi, margin=args.margin)
    out.finish(written)
    print(f"target: {target_caption(target)}")
    w_mm, h_mm = _page_mm(png, args.dpi)
    fits = next((name for name, (a, b) in PAPER_SIZES_MM.items()
                 if (w_mm <= a and h_mm <= b) or (w_mm <= b and h_mm <= a)), None)
    print(f"page: {w_mm:.0f} × {h_mm:.0f} mm" + (f" (fits {fits})" if fits else
                                                 " (larger than A3: print on a plotter)"))
    print(f"frame T: {object_points_description(target)}")
    print("wrote: " + ", ".join(str(p) for p in written))
    return 0


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Adds the ``target`` subcommand to an argparse ``subparsers`` object."""
    p = subparsers.add_parser(
        "target", help="write a calibration target to print (PNG, SVG, PDF at true scale)",
        description="Write the calibration target SPEC at true scale: a PNG (with its dpi), an "
                    "SVG and a PDF beside it. SPEC: chessboard:COLSxROWS:SQUARE (inner corners), "
                    "charuco:SQUARESXxSQUARESY:SQUARE:MARKER:DICT[:legacy], "
                    "apriltag:FAMILY:SIZE[:ID], aprilgrid:FAMILY:COLSxROWS:SIZE:SPACING[:FIRST_ID]"
                    ", circles:COLSxROWS:SPACING[:DIAMETER][:white], "
                    "acircles:COLSxROWS:SPACING[:DIAMETER][:white] (circle grids, white: white "
                    "circles on black); sizes in metres.")
    p.add_argument("spec", metavar="SPEC", help="the target, e.g. chessboard:9x6:0.0236")
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                   help=f"output directory (default {DEFAULT_OUT}): target.png (with its dpi), "
                        "target.svg, target.pdf; an existing one must be empty or hold this "
                        "command's earlier output")
    p.add_argument("--dpi", type=positive_float, default=300.0, help="PNG resolution (default 300)")
    p.add_argument("--margin", type=non_negative_float, default=0.01, metavar="METRES",
                   help="white margin around the pattern (default 0.01)")
    p.add_argument("--force", action="store_true",
                   help="write into a non-empty --out that is not this command's output (never "
                        "overwriting files the tool did not write)")
    p.set_defaults(func=run_target)
    return p

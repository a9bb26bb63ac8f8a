"""The robot's surroundings for planning: a floor (or table) plane and boxes, in the robot base B.

YAML (all lengths in metres, in B)::

    floor_z: 0.0            # top of the floor/table plane; null: no floor
    boxes:
      - name: fixture
        center: [0.5, 0.3, 0.1]
        size: [0.2, 0.2, 0.2]
        rpy_deg: [0, 0, 30]  # optional
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Box:
    """A box obstacle: centre (m, in B), full side lengths (m) and roll-pitch-yaw (deg)."""
    name: str
    center: tuple
    size: tuple
    rpy_deg: tuple = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Cell:
    """Obstacles around the robot, in the base frame B: ``floor_z`` the height (m) of the top of
    the floor/table plane the robot stands on (None: no floor), ``boxes`` more obstacles."""
    floor_z: float | None = 0.0
    boxes: tuple = field(default_factory=tuple)


def _vector(value, n, what):
    try:
        v = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected {n} numbers, got {value!r}") from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{what}: expected {n} finite numbers, got {value!r}")
    return tuple(float(x) for x in v)


def cell_from_dict(data: dict, source: str = "cell") -> Cell:
    """A ``Cell`` from the YAML's mapping; ValueError naming the field."""
    if not isinstance(data, dict):
        raise ValueError(f"{source}: expected a mapping with floor_z and boxes")
    unknown = set(data) - {"floor_z", "boxes"}
    if unknown:
        raise ValueError(f"{source}: unknown field(s) {sorted(unknown)}; known: floor_z, boxes")
    floor = data.get("floor_z", 0.0)
    if floor is not None:
        floor = _vector([floor], 1, f"{source}: floor_z")[0]
    boxes = []
    for i, b in enumerate(data.get("boxes") or []):
        where = f"{source}: boxes[{i}]"
        if not isinstance(b, dict) or "center" not in b or "size" not in b:
            raise ValueError(f"{where}: expected a mapping with center and size")
        size = _vector(b["size"], 3, f"{where}.size")
        if min(size) <= 0:
            raise ValueError(f"{where}.size: side lengths must be > 0, got {list(size)}")
        boxes.append(Box(str(b.get("name", f"box{i}")), _vector(b["center"], 3, f"{where}.center"),
                         size, _vector(b.get("rpy_deg", (0, 0, 0)), 3, f"{where}.rpy_deg")))
    return Cell(floor, tuple(boxes))


def load_cell(path) -> Cell:
    """Reads a cell YAML file (module docstring); ValueError naming the file."""
    import yaml
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"--cell: file not found: {str(p)!r}")
    try:
        data = yaml.safe_load(p.read_text()) or {}
    except yaml.YAMLError as e:
        raise ValueError(f"--cell: {p.name}: not valid YAML ({' '.join(str(e).split())})") \
            from None
    return cell_from_dict(data, p.name)


__all__ = ["Box", "Cell", "cell_from_dict", "load_cell"]

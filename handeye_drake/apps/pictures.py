"""Writes a Diagram's GraphViz picture: always ``.dot``; ``.svg``/``.png`` when the system
``dot`` program (package graphviz) is installed."""

from __future__ import annotations

import shutil
from pathlib import Path

import pydot


def _stable_dot(text: str) -> str:
    """Drake lists a diagram's edges in an order that changes from run to run (an unordered
    container): the edge lines, sorted in place, make the picture the same every time."""
    lines = text.split("\n")
    edges = [i for i, line in enumerate(lines) if " -> " in line]
    for i, line in zip(edges, sorted(lines[i] for i in edges)):
        lines[i] = line
    return "\n".join(lines)


def render_diagram(diagram, stem, max_depth: int = 1, formats=("svg",)) -> list[Path]:
    """Writes ``stem.dot`` and, if graphviz is present, ``stem.<fmt>`` for each format.
    Returns the paths written."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    dot_path = stem.with_suffix(".dot")
    dot_path.write_text(_stable_dot(diagram.GetGraphvizString(max_depth=max_depth)))
    written = [dot_path]
    if shutil.which("dot") is None:
        return written
    (graph,) = pydot.graph_from_dot_data(dot_path.read_text())
    for fmt in formats:
        out = stem.with_suffix(f".{fmt}")
        graph.write(str(out), format=fmt)
        written.append(out)
    return written

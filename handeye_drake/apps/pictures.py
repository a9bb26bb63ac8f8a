"""Writes a Diagram's GraphViz picture: always ``.dot``; ``.svg``/``.png`` when the system
``dot`` program (package graphviz) is installed."""

from __future__ import annotations

import shutil
from pathlib import Path

import pydot


def render_diagram(diagram, stem, max_depth: int = 1, formats=("svg",)) -> list[Path]:
    """Writes ``stem.dot`` and, if graphviz is present, ``stem.<fmt>`` for each format.
    Returns the paths written."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    dot_path = stem.with_suffix(".dot")
    dot_path.write_text(diagram.GetGraphvizString(max_depth=max_depth))
    written = [dot_path]
    if shutil.which("dot") is None:
        return written
    (graph,) = pydot.graph_from_dot_data(dot_path.read_text())
    for fmt in formats:
        out = stem.with_suffix(f".{fmt}")
        graph.write(str(out), format=fmt)
        written.append(out)
    return written

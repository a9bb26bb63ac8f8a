"""Writes a Diagram's GraphViz pictures: always ``.dot``; ``.svg``/``.png`` when the system
``dot`` program (package graphviz) is installed.

Two pictures of each diagram: a compact one (``stem.svg``: one box per subsystem with its name
and class, one arrow per pair of connected subsystems labelled with the signals it carries,
laid out top to bottom so that it reads at page width) and Drake's own full picture beside it
(``stem_full.svg``: every port of every subsystem, ``Diagram.GetGraphvizString``), which is
several thousand pixels wide for a diagram holding a ``MultibodyPlant``."""

from __future__ import annotations

import html
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


def compact_dot(diagram, title: str | None = None) -> str:
    """The compact GraphViz picture of ``diagram``'s top level: a box per subsystem (its name,
    its class underneath), an arrow per connected pair of subsystems labelled with the signals
    (``output → input`` when the names differ), and the diagram's exported inputs and outputs
    as two lists. Deterministic (sorted), laid out top to bottom."""
    from pydrake.systems.framework import InputPortIndex, OutputPortIndex
    systems = list(diagram.GetSystems())
    index = {id(s): k for k, s in enumerate(systems)}
    edges: dict[tuple[int, int], list[str]] = {}
    for (dst, i), (src, o) in diagram.connection_map().items():
        out_name, in_name = src.get_output_port(o).get_name(), dst.get_input_port(i).get_name()
        label = out_name if out_name == in_name else f"{out_name} →\n{in_name}"
        edges.setdefault((index[id(src)], index[id(dst)]), []).append(label)

    def q(text: str) -> str:
        return html.escape(text, quote=True)

    # size: scaled down (never up) to fit a page width of 10.2 in (≈ 980 px).
    lines = ["digraph compact {", '  rankdir=TB; newrank=true; nodesep=0.2; ranksep=0.4; '
             'size="10.2,40";',
             '  node [shape=box, style="rounded,filled", fillcolor="#f4f6fb", color="#4a5a80", '
             'fontname="Helvetica", fontsize=12, margin="0.12,0.05"];',
             '  edge [fontname="Helvetica", fontsize=10, color="#4a5a80", fontcolor="#333333"];']
    if title:
        lines.append(f'  labelloc=t; fontname="Helvetica"; fontsize=15; label=<{q(title)}>;')
    for k, s in enumerate(systems):
        lines.append(f'  s{k} [label=<<b>{q(s.get_name())}</b><br/><font point-size="10">'
                     f"{q(type(s).__name__)}</font>>];")
    for (a, b), labels in sorted(edges.items()):
        text = "<br/>".join(q(x).replace("\n", "<br/>") for x in sorted(labels))
        lines.append(f"  s{a} -> s{b} [label=<{text}>];")
    for kind, n, locate in (("inputs", diagram.num_input_ports(), None),
                            ("outputs", diagram.num_output_ports(), True)):
        if n == 0:
            continue
        names = [(diagram.get_input_port(k) if locate is None else
                  diagram.get_output_port(k)).get_name() for k in range(n)]
        rows = "".join(f"<tr><td>{q(x)}</td></tr>" for x in names)
        colour = "#2e7d32" if locate else "#1f4fb4"
        lines.append(f'  {kind} [shape=plaintext, style="", label=<<table border="1" '
                     f'cellborder="0" color="{colour}"><tr><td><b>diagram {kind}</b></td></tr>'
                     f"{rows}</table>>];")
        for k in range(n):
            if locate:
                src, _ = diagram.get_output_port_locator(OutputPortIndex(k))
                lines.append(f'  s{index[id(src)]} -> {kind} [style=dashed, color="{colour}", '
                             "arrowsize=0.6];")
            else:
                for dst, _ in diagram.GetInputPortLocators(InputPortIndex(k)):
                    lines.append(f'  {kind} -> s{index[id(dst)]} [style=dashed, '
                                 f'color="{colour}", arrowsize=0.6];')
    lines.append("}")
    # One dashed arrow per exported port would repeat: keep each once.
    seen, unique = set(), []
    for line in lines:
        if "style=dashed" in line and line in seen:
            continue
        seen.add(line)
        unique.append(line)
    return "\n".join(unique) + "\n"


def render_diagram(diagram, stem, max_depth: int = 1, formats=("svg",)) -> list[Path]:
    """Writes the compact picture as ``stem.dot`` (``compact_dot``) and Drake's full one as
    ``stem_full.dot`` (``GetGraphvizString(max_depth)``), and, if graphviz is present,
    ``stem.<fmt>`` and ``stem_full.<fmt>`` for each format. Returns the paths written."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    full = stem.with_name(stem.name + "_full")
    texts = {stem: compact_dot(diagram),
             full: _stable_dot(diagram.GetGraphvizString(max_depth=max_depth))}
    written = []
    for path, text in texts.items():
        dot_path = path.with_suffix(".dot")
        dot_path.write_text(text)
        written.append(dot_path)
    if shutil.which("dot") is None:
        return written
    for path in texts:
        (graph,) = pydot.graph_from_dot_data(path.with_suffix(".dot").read_text())
        for fmt in formats:
            out = path.with_suffix(f".{fmt}")
            graph.write(str(out), format=fmt)
            written.append(out)
    return written

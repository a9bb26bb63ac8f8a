"""The diagram pictures (``apps.pictures``): a compact top-level picture that reads at page width,
Drake's full one beside it, and the committed pictures in diagrams/ are what ``make diagrams``
writes."""

import re
import shutil
from pathlib import Path

import pytest

from handeye_drake.apps.pictures import compact_dot, render_diagram
from handeye_drake.scenario import load_scenario
from handeye_drake.simulation import build_diagram

DIAGRAMS = Path(__file__).resolve().parents[2] / "diagrams"
PAGE_WIDTH_PX = 1000


def _width_px(svg: Path) -> float:
    m = re.search(r'<svg width="([\d.]+)pt"', svg.read_text())
    return float(m.group(1)) * 4 / 3


@pytest.fixture(scope="module")
def loop():
    return build_diagram(load_scenario(), with_loggers=False)


def test_compact_picture_has_every_subsystem_and_connection(loop):
    dot = compact_dot(loop.diagram)
    systems = list(loop.diagram.GetSystems())
    for s in systems:
        assert f"<b>{s.get_name()}</b>" in dot and type(s).__name__ in dot
    pairs = {(id(src), id(dst)) for (dst, _), (src, _) in loop.diagram.connection_map().items()}
    assert len(re.findall(r"^  s\d+ -> s\d+ \[label=", dot, re.M)) == len(pairs)
    assert "query →<br/>geometry_query" in dot and "X_CE_estimate" in dot
    for name in ("X_EC_estimate", "feature_error", "X_WC"):        # the exported outputs
        assert f"<td>{name}</td>" in dot
    # No port list of the plant's dozens of ports, unlike Drake's full picture.
    full = loop.diagram.GetGraphvizString(max_depth=1)
    assert "spatial_velocities" in full and "spatial_velocities" not in dot


@pytest.mark.skipif(shutil.which("dot") is None, reason="graphviz (dot) not installed")
def test_render_writes_both_and_the_compact_one_fits_a_page(loop, tmp_path):
    written = render_diagram(loop.diagram, tmp_path / "diagram")
    assert sorted(p.name for p in written) == ["diagram.dot", "diagram.svg", "diagram_full.dot",
                                               "diagram_full.svg"]
    compact, full = _width_px(tmp_path / "diagram.svg"), _width_px(tmp_path / "diagram_full.svg")
    assert compact <= PAGE_WIDTH_PX < full


def test_committed_pictures_are_current_and_compact(loop):
    """diagrams/closed_loop.dot is what ``make diagrams`` writes today, and each committed
    compact picture fits the page width."""
    assert (DIAGRAMS / "closed_loop.dot").read_text() == compact_dot(loop.diagram)
    for name in ("closed_loop", "rendered_loop", "calibrator_alone"):
        assert (DIAGRAMS / f"{name}_full.dot").exists()
        assert _width_px(DIAGRAMS / f"{name}.svg") <= PAGE_WIDTH_PX
        assert _width_px(DIAGRAMS / f"{name}_full.svg") > PAGE_WIDTH_PX

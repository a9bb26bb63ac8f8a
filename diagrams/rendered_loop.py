"""The closed loop on rendered images (scenarios/rendered.yaml): the arm, a rendered camera on
the flange (RgbdSensor through SceneGraph), the target detector, IBVS and the calibrator.

Run: ``python diagrams/rendered_loop.py`` — writes rendered_loop.dot (compact) and
rendered_loop_full.dot (every port), and their .svg with graphviz,
here.
"""
from pathlib import Path

from handeye_drake.apps.pictures import render_diagram
from handeye_drake.scenario import load_scenario
from handeye_drake.simulation import build_diagram

if __name__ == "__main__":
    scenario = load_scenario(Path(__file__).resolve().parent.parent / "scenarios" /
                             "rendered.yaml")
    loop = build_diagram(scenario, with_loggers=False)
    written = render_diagram(loop.diagram, Path(__file__).with_name("rendered_loop"))
    print("wrote: " + ", ".join(map(str, written)))

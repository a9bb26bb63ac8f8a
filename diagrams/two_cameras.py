"""The two-camera loop (scenarios/two_cameras.yaml): the arm, a rendered camera on the flange and
one fixed in the cell (both RgbdSensors rendering the perception scene), a target detector on
each, IBVS on the hand camera, the hand camera's on-line calibrator and the cell camera's
calibrator fed by it.

Run: ``python diagrams/two_cameras.py`` — writes two_cameras.dot (compact) and
two_cameras_full.dot (every port), and their .svg with graphviz, here.
"""
from pathlib import Path

from handeye_drake.apps.pictures import render_diagram
from handeye_drake.scenario import load_scenario
from handeye_drake.simulation import build_diagram

if __name__ == "__main__":
    scenario = load_scenario(Path(__file__).resolve().parent.parent / "scenarios" /
                             "two_cameras.yaml")
    loop = build_diagram(scenario, with_loggers=False)
    written = render_diagram(loop.diagram, Path(__file__).with_name("two_cameras"))
    print("wrote: " + ", ".join(map(str, written)))

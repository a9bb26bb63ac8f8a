"""The full closed loop of the default scenario: arm, camera, IBVS and Kalman calibrator.

Run: ``python diagrams/closed_loop.py`` — writes closed_loop.dot (compact) and
closed_loop_full.dot (every port), and their .svg with graphviz, here.
"""
from pathlib import Path

from handeye_drake.apps.pictures import render_diagram
from handeye_drake.scenario import load_scenario
from handeye_drake.simulation import build_diagram

if __name__ == "__main__":
    loop = build_diagram(load_scenario(), with_loggers=False)
    written = render_diagram(loop.diagram, Path(__file__).with_name("closed_loop"))
    print("wrote: " + ", ".join(map(str, written)))

"""Reachable, collision-free next poses for a hand-eye calibration, with Drake.

A floor above ``estimation`` (which keeps the information math, Drake-free, in
``estimation.planning``) and beside ``systems``: nothing in ``estimation``, ``calibration``,
``vision`` or ``systems`` imports it; ``apps`` and benchmarks do.

- ``cell``: the robot's surroundings (a floor plane, boxes from a YAML file);
- ``feasible``: ``FeasiblePlanner`` — candidate poses from ``InverseKinematics`` (joint limits,
  minimum distance to the cell and between the arm's links, the target in the camera's view at a
  distance and tilt), ranked by the D-optimal information gain, ordered into a short tour, and
  a time-parameterized trajectory checked densely for collisions; ``as_session_planner`` plugs
  it into ``calibration.session.CalibrationSession``;
- ``preview``: a self-contained Meshcat HTML animation of a tour and a PNG picture.

Frames (monogram notation, X_AB is the pose of B in A): B robot base (= the world W of the
planning plant), E end-effector (flange), C camera, T target. Eye-in-hand: X_EC (camera on the
flange) and X_BT (target in the cell); eye-to-hand: X_BC (camera in the cell) and X_ET (target on
the flange). Lengths in metres, angles in radians unless the name says ``_deg``.
"""

from .cell import Box, Cell, load_cell
from .feasible import (CandidateSet, FeasiblePlanner, Feasibility, InfeasibleError, Tour,
                       ViewSpec, as_session_planner)

__all__ = ["Box", "CandidateSet", "Cell", "FeasiblePlanner", "Feasibility", "InfeasibleError",
           "Tour", "ViewSpec", "as_session_planner", "load_cell"]

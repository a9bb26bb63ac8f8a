"""The feasible planner's clearance margin, on a pose that did not come out of its IK: a box
placed a known gap in front of the camera body (the gap computed here from the box geometry)
fails the check when the gap is under ``min_distance_m`` and passes it when over, and the
distance reported is that gap."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handeye_drake.estimation.se3 import make_transform, rotation_exp
from handeye_drake.planning import Cell, FeasiblePlanner
from handeye_drake.planning.cell import Box
from handeye_drake.planning.feasible import UR5E_HOME_Q

X_EC = make_transform(rotation_exp(np.array([0.0, 0.0, math.pi / 2])), [0.0, -0.05, 0.04])
X_BT = make_transform(rotation_exp(np.array([math.pi, 0.0, 0.0])), [-0.45, -0.15, 0.0])
CAMERA = (0.09, 0.06, 0.05)
GAP = 0.0029


@pytest.fixture(scope="module")
def planner():
    """Margin 10 mm; a 2 cm cube 2.9 mm in front of the camera body at the home pose."""
    bare = FeasiblePlanner("eye_in_hand", X_EC, X_BT, camera_size_m=CAMERA)
    X_BC = bare.X_BE(UR5E_HOME_Q) @ X_EC
    z = X_BC[:3, 2]
    centre = X_BC[:3, 3] + z * (CAMERA[2] / 2 + GAP + 0.01)
    rpy = Rotation.from_matrix(X_BC[:3, :3]).as_euler("xyz", degrees=True)  # roll-pitch-yaw
    box = Box("probe", tuple(centre), (0.02, 0.02, 0.02), tuple(rpy))
    return FeasiblePlanner("eye_in_hand", X_EC, X_BT, camera_size_m=CAMERA,
                           cell=Cell(0.0, (box,)), min_distance_m=0.01)


def test_a_pose_closer_than_the_margin_fails_the_check(planner):
    f = planner.check(UR5E_HOME_Q)
    assert f.min_distance_m == pytest.approx(GAP, abs=2e-4)
    assert any("camera" in n for n in f.closest_pair)
    assert any("box_probe" in n for n in f.closest_pair)
    assert not f.ok
    assert any(r.startswith("collision") for r in f.reasons), f.reasons
    close = planner.colliding_pairs(UR5E_HOME_Q, bound=planner.min_distance_m)
    assert close and close[0][2] == pytest.approx(GAP, abs=2e-4)
    assert not planner.colliding_pairs(UR5E_HOME_Q, bound=GAP / 2)


def test_the_same_pose_passes_with_a_margin_under_the_gap(planner):
    loose = FeasiblePlanner("eye_in_hand", X_EC, X_BT, camera_size_m=CAMERA,
                            cell=planner.cell, min_distance_m=0.002)
    f = loose.check(UR5E_HOME_Q)
    assert f.min_distance_m == pytest.approx(GAP, abs=2e-4)
    assert not any(r.startswith("collision") for r in f.reasons), f.reasons

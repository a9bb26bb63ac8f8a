"""The cell camera's on-line calibrator (``systems.cell_camera_calibrator``): X_BC composed from the
hand camera's X_EC and the frames both cameras see the board in, its covariance from both; and
the two-camera scenario builds into one diagram with both rendered cameras."""

import math
from pathlib import Path

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from handeye_drake.estimation.se3 import (inverse, make_transform, pose_to_vector, rotation_exp,
                                          vector_to_pose)
from handeye_drake.systems.cell_camera_calibrator import CellCameraCalibrator

X_EC = make_transform(rotation_exp([0.05, -0.02, 1.6]), [0.04, -0.03, 0.06])
X_BT = make_transform(rotation_exp([math.pi, 0.0, 0.3]), [-0.5, -0.1, 0.0])
X_BC = make_transform(rotation_exp([2.3, 0.2, -0.9]), [-1.0, -0.4, 0.6])
X_BE = make_transform(rotation_exp([2.9, 0.3, 0.1]), [-0.45, -0.12, 0.42])


def _run(X_EC_input, cov_EC, cov_cell, found=1.0, steps=3):
    builder = DiagramBuilder()
    cal = builder.AddSystem(CellCameraCalibrator(0.1, offset=0.01))
    X_CT_hand = inverse(X_BE @ X_EC) @ X_BT
    X_CT_cell = inverse(X_BC) @ X_BT
    for name, value in (("X_BE", pose_to_vector(X_BE)), ("X_CT_hand", pose_to_vector(X_CT_hand)),
                        ("hand_valid", [1.0]), ("X_EC", pose_to_vector(X_EC_input)),
                        ("X_EC_covariance", cov_EC.reshape(36)),
                        ("X_CT_cell", pose_to_vector(X_CT_cell)), ("cell_valid", [found]),
                        ("X_CT_cell_covariance", cov_cell.reshape(36))):
        src = builder.AddSystem(ConstantVectorSource(np.asarray(value, float)))
        builder.Connect(src.get_output_port(), cal.get_input_port_by_name(name))
    diagram = builder.Build()
    sim = Simulator(diagram)
    sim.AdvanceTo(0.1 * steps)
    ctx = cal.GetMyContextFromRoot(sim.get_context())
    out = {n: np.asarray(cal.get_output_port_by_name(n).Eval(ctx)) for n in
           ("X_BC_estimate", "X_BC_std", "X_BC_covariance", "frames")}
    return vector_to_pose(out["X_BC_estimate"]), out


def test_composes_the_hand_estimate_with_both_views():
    cov = np.diag([1e-6] * 3 + [1e-8] * 3)
    X, out = _run(X_EC, cov, np.zeros((6, 6)))
    assert np.abs(X - X_BC).max() < 1e-9 and out["frames"][0] == 3    # updates at 0.01, 0.11, 0.21 s
    # The covariance is the hand camera's X_EC's carried to X_BC: a rotation σ of 1 mrad about
    # E becomes 1 mrad about B (a rotation carried by a rigid chain keeps its size) and moves
    # the far camera by ~ its distance from the flange.
    sd = np.sqrt(np.diag(out["X_BC_covariance"].reshape(6, 6)))
    assert np.allclose(np.linalg.norm(sd[:3]), math.sqrt(3) * 1e-3, rtol=1e-3)
    lever = np.linalg.norm(X_BC[:3, 3] - (X_BE @ X_EC)[:3, 3])
    assert 0.5 * lever * 1e-3 < np.linalg.norm(sd[3:]) < 2.0 * lever * 1e-3


def test_follows_a_wrong_hand_estimate_and_waits_for_the_board():
    X_EC_off = make_transform(rotation_exp([0.0, 0.0, 0.01]), [0.0, 0.0, 0.005]) @ X_EC
    X, _ = _run(X_EC_off, np.zeros((6, 6)), np.zeros((6, 6)))
    assert np.linalg.norm(X[:3, 3] - X_BC[:3, 3]) > 0.005
    X, out = _run(X_EC, np.zeros((6, 6)), np.zeros((6, 6)), found=0.0)
    assert out["frames"][0] == 0 and np.array_equal(X, np.eye(4))
    assert np.all(out["X_BC_std"] >= 10.0)       # unknown until a frame with both cameras


def test_rejects_bad_arguments():
    with pytest.raises(ValueError, match="capacity"):
        CellCameraCalibrator(0.1, capacity=0)


def test_two_camera_scenario_builds_one_loop():
    from handeye_drake.scenario import load_scenario
    from handeye_drake.simulation import build_diagram
    scenario = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" /
                             "two_cameras.yaml")
    loop = build_diagram(scenario, with_loggers=False)
    names = {s.get_name() for s in loop.diagram.GetSystems()}
    assert {"rgbd_sensor_hand_camera", "rgbd_sensor_cell_camera", "cell_camera_detector",
            "cell_camera_calibrator", "calibrator", "servo"} <= names
    assert len(loop.cell_cameras) == 1
    assert loop.diagram.HasOutputPort("cell_camera_X_BC_estimate")

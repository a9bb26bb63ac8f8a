"""The hand-eye calibrator in your own Drake diagram: your MultibodyPlant, your controller, your
camera — no project scenario.

A UR5e (the URDF shipped with the package, parsed by Drake's ``Parser``) is driven by Drake's
``InverseDynamicsController`` along a joint trajectory: two self-calibration rotations of the
wrist, then a slow sweep. "Your camera" is a small LeafSystem that sees a target fixed in the
world from the flange and reports its pose X_CT with noise, as a PnP detector would. The
calibrator (``add_hand_eye_calibrator``) is wired to the robot's flange pose X_BE, to the camera
and to a phase signal saying which self-calibration motion runs.

    .venv/bin/python examples/calibrator_in_your_diagram.py
"""

from __future__ import annotations

import numpy as np
from pydrake.common import RandomDistribution, RandomGenerator
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.controllers import InverseDynamicsController
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import RandomSource, TrajectorySource
from pydrake.trajectories import PiecewisePolynomial

from handeye_drake.estimation.configs import TargetFilter
from handeye_drake.estimation.se3 import (inverse, make_transform, pose_to_vector,
                                          rotation_exp)
from handeye_drake.systems import EndEffectorPoseSensor, add_hand_eye_calibrator
from handeye_drake.systems.arm import UR5E_URDF

#: The truth of this example: the camera on the flange, the target in the world.
X_EC_TRUE = make_transform(rotation_exp([0.0, 0.0, np.pi / 2]), [0.045, -0.012, 0.068])
X_WT = make_transform(rotation_exp([np.pi, 0.0, 0.0]), [0.45, 0.1, -0.1])
PERIOD = 1 / 30          # the camera's rate (s)
NOISE = (0.002, 0.0005)  # the camera pose's noise (rad, m)


class MyPoseCamera(LeafSystem):
    """Your camera: from the plant's body poses, the target's pose in the camera X_CT with
    SO(3) × R³ noise (input ``noise``, 6 standard normal samples per period).

    Input ports: body_poses (the plant's), noise (6). Output port: X_CT (12, [vec_row(R); p])."""

    def __init__(self, plant: MultibodyPlant, flange: str):
        super().__init__()
        self._body = plant.GetFrameByName(flange).body().index()
        self._X_BodyE = plant.GetFrameByName(flange).GetFixedPoseInBodyFrame().GetAsMatrix4()
        self.DeclareAbstractInputPort("body_poses", AbstractValue.Make([RigidTransform()]))
        self.DeclareVectorInputPort("noise", 6)
        self.DeclareVectorOutputPort("X_CT", 12, self._CalcX_CT)

    def _CalcX_CT(self, context, output):
        X_WE = self.get_input_port(0).Eval(context)[int(self._body)].GetAsMatrix4() \
            @ self._X_BodyE
        X_CT = inverse(X_WE @ X_EC_TRUE) @ X_WT
        n = self.get_input_port(1).Eval(context)
        noisy = make_transform(rotation_exp(NOISE[0] * n[:3]) @ X_CT[:3, :3],
                               X_CT[:3, 3] + NOISE[1] * n[3:])
        output.SetFromVector(pose_to_vector(noisy))


def joint_plan(plant: MultibodyPlant):
    """Joint positions over time: home, two wrist rotations of 25° about different axes
    (phase 0 and 1), then a slow sweep (phase 2) — and the phase signal that goes with it."""
    q0 = np.array([0.0, -1.9, 1.9, -1.57, -1.57, 0.0])
    knots = [q0, q0 + [0, 0, 0, 0.44, 0, 0], q0 + [0, 0, 0, 0.44, 0.44, 0]]
    rng = np.random.default_rng(1)
    for _ in range(6):
        knots.append(q0 + rng.uniform(-0.25, 0.25, 6))
    times = [0.0, 1.5, 3.0] + [3.0 + 1.5 * k for k in range(1, 7)]
    q = PiecewisePolynomial.CubicShapePreserving(times, np.array(knots).T, True)
    phase = PiecewisePolynomial.ZeroOrderHold([0.0, 1.5, 3.0, times[-1]],
                                              np.array([[0.0, 1.0, 2.0, 2.0]]))
    return q, phase, times[-1]


def build(with_phase: bool = True, X_EC_guess=None, told_noise=NOISE):
    """The diagram. ``with_phase`` False: no self-calibration motions (M = 0), the calibrator
    starts from ``X_EC_guess``. ``told_noise``: the camera noise (rad, m) the calibrator is
    told — the camera's own (``NOISE``) unless you do not know it; a σ that understates it is
    corrected on-line from the measurements (the reported ``X_EC_std`` is scaled)."""
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, time_step=0.002)
    (arm,) = Parser(plant).AddModels(UR5E_URDF)
    plant.WeldFrames(plant.world_frame(), plant.GetFrameByName("base_link", arm))
    plant.Finalize()
    q, phase, duration = joint_plan(plant)
    # Your controller: Drake's inverse dynamics on a copy of the arm, tracking [q; q̇].
    control = MultibodyPlant(time_step=0.0)
    (carm,) = Parser(control).AddModels(UR5E_URDF)
    control.WeldFrames(control.world_frame(), control.GetFrameByName("base_link", carm))
    control.Finalize()
    n = control.num_positions()
    controller = builder.AddNamedSystem("controller", InverseDynamicsController(
        control, kp=[400.0] * n, ki=[1.0] * n, kd=[40.0] * n, has_reference_acceleration=False))
    desired = builder.AddNamedSystem("plan", TrajectorySource(q, output_derivative_order=1))
    builder.Connect(desired.get_output_port(), controller.get_input_port_desired_state())
    builder.Connect(plant.get_state_output_port(arm), controller.get_input_port_estimated_state())
    builder.Connect(controller.get_output_port_control(), plant.get_actuation_input_port(arm))
    # Your sensors: the flange pose the robot reports (X_BE), your camera (X_CT).
    flange = builder.AddNamedSystem("flange_pose", EndEffectorPoseSensor(
        plant, "base_link", "tool0"))
    builder.Connect(plant.get_body_poses_output_port(), flange.get_body_poses_input_port())
    camera = builder.AddNamedSystem("my_camera", MyPoseCamera(plant, "tool0"))
    builder.Connect(plant.get_body_poses_output_port(), camera.get_input_port(0))
    noise = builder.AddNamedSystem("camera_noise", RandomSource(
        RandomDistribution.kGaussian, 6, PERIOD))
    builder.Connect(noise.get_output_port(), camera.get_input_port(1))
    phase_port = builder.AddNamedSystem("phase", TrajectorySource(phase)).get_output_port() \
        if with_phase else None
    calibrator = add_hand_eye_calibrator(
        builder, estimator=TargetFilter(rotation_sigma=told_noise[0],
                                        translation_sigma=told_noise[1]),
        period=PERIOD, X_EC_initial_guess=np.eye(4) if X_EC_guess is None else X_EC_guess,
        X_BE=flange.get_X_BE_output_port(), X_CT=camera.get_output_port(), phase=phase_port)
    diagram = builder.Build()
    return diagram, plant, arm, calibrator, q, duration


def run(seed: int = 0, with_phase: bool = True, X_EC_guess=None, told_noise=NOISE):
    """Simulates the example; returns (X_EC estimate, its 6 standard deviations (deg, m),
    status vector)."""
    diagram, plant, arm, calibrator, q, duration = build(with_phase, X_EC_guess, told_noise)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), arm, q.value(0.0).ravel())
    diagram.SetRandomContext(context, RandomGenerator(seed))
    simulator.AdvanceTo(duration)
    c = calibrator.GetMyContextFromRoot(context)
    X = calibrator.get_X_EC_output_port().Eval(c)
    return (np.vstack([np.hstack([X[:9].reshape(3, 3), X[9:, None]]), [0, 0, 0, 1]]),
            calibrator.get_X_EC_std_output_port().Eval(c),
            calibrator.get_status_output_port().Eval(c))


if __name__ == "__main__":
    from handeye_drake.estimation.errors import rotation_error_deg
    X_EC, std, status = run()
    print(f"status {status[0]:.0f} after {status[1]:.0f} updates")
    print(f"X_EC error: {rotation_error_deg(X_EC_TRUE, X_EC):.4f}° / "
          f"{1000 * np.linalg.norm(X_EC[:3, 3] - X_EC_TRUE[:3, 3]):.3f} mm; "
          f"1σ {np.linalg.norm(std[:3]):.4f}° / {1000 * np.linalg.norm(std[3:]):.3f} mm")

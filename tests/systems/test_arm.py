"""The robot arm: DH-exact UR5e model, PD-driven plant, differential-IK driver, pose sensor."""

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.inverse_kinematics import DifferentialInverseKinematicsStatus
from pydrake.multibody.plant import MultibodyPlantConfig
from pydrake.multibody.tree import FixedOffsetFrame, JacobianWrtVariable
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from handeye_drake.estimation.se3 import (
    inverse,
    make_transform,
    rotation_exp,
    rotation_log,
    vector_to_pose,
)
from handeye_drake.systems.arm import (
    UR5E_HOME_Q,
    UR5E_JOINT_NAMES,
    UR5E_URDF,
    DifferentialIkDriver,
    EndEffectorPoseSensor,
    add_arm,
    make_control_plant,
)

DT = 0.002

# Universal Robots' published UR5e DH table (standard DH), typed in independently of the URDF.
DH_D = [0.1625, 0.0, 0.0, 0.1333, 0.0997, 0.0996]
DH_A = [0.0, -0.425, -0.3922, 0.0, 0.0, 0.0]
DH_ALPHA = [np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0]

# A generic, well-conditioned pose (smallest Jacobian singular value 0.23) whose R_WE mixes all
# axes, so expressing the twist in the wrong frame would show.
Q_GENERIC = np.array([0.3, -1.4, 1.6, -1.8, -1.4, 0.5])

STUCK = float(int(DifferentialInverseKinematicsStatus.kStuck))
NO_SOLUTION = float(int(DifferentialInverseKinematicsStatus.kNoSolutionFound))


def dh_forward_kinematics(q):
    X = np.eye(4)
    for qi, d, a, alpha in zip(q, DH_D, DH_A, DH_ALPHA):
        ct, st, ca, sa = np.cos(qi), np.sin(qi), np.cos(alpha), np.sin(alpha)
        X = X @ np.array([[ct, -st * ca, st * sa, a * ct],
                          [st, ct * ca, -ct * sa, a * st],
                          [0.0, sa, ca, d],
                          [0.0, 0.0, 0.0, 1.0]])
    return X


def build_loop(V_WE_E, q0, X_WB=None, log=False):
    """add_arm + DifferentialIkDriver + EndEffectorPoseSensor, constant twist command."""
    builder = DiagramBuilder()
    arm = add_arm(builder, plant_config=MultibodyPlantConfig(time_step=DT), X_WB=X_WB, q0=q0)
    driver = builder.AddSystem(DifferentialIkDriver(
        make_control_plant(X_WB=X_WB), arm.ee_frame, DT, q0))
    builder.Connect(driver.get_desired_state_output_port(),
                    arm.plant.get_desired_state_input_port(arm.model_instance))
    sensor = builder.AddSystem(EndEffectorPoseSensor(arm.plant, arm.base_frame, arm.ee_frame))
    builder.Connect(arm.plant.get_body_poses_output_port(), sensor.get_body_poses_input_port())
    source = builder.AddSystem(ConstantVectorSource(np.asarray(V_WE_E, dtype=float)))
    builder.Connect(source.get_output_port(), driver.get_V_WE_E_command_input_port())
    logs = None
    if log:
        logs = (LogVectorOutput(driver.get_desired_state_output_port(), builder),
                LogVectorOutput(arm.plant.get_state_output_port(arm.model_instance), builder),
                LogVectorOutput(driver.get_status_output_port(), builder))
    diagram = builder.Build()
    return diagram, arm, driver, sensor, logs


def commanded_pose(q):
    """X_WE of the control plant at joint positions q (the driver's own kinematics)."""
    plant = make_control_plant()
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    return plant.CalcRelativeTransform(context, plant.world_frame(),
                                       plant.GetFrameByName("tool0")).GetAsMatrix4()


# --- model ---------------------------------------------------------------------------------------

def test_urdf_forward_kinematics_equals_published_dh_product():
    plant = make_control_plant()
    context = plant.CreateDefaultContext()
    frame_B, frame_E = plant.GetFrameByName("base_link"), plant.GetFrameByName("tool0")
    assert plant.num_positions() == 6 and plant.num_actuators() == 6
    assert [plant.get_joint_actuator(i).joint().name()
            for i in plant.GetJointActuatorIndices()] == list(UR5E_JOINT_NAMES)
    rng = np.random.default_rng(7)
    lower, upper = plant.GetPositionLowerLimits(), plant.GetPositionUpperLimits()
    for q in [np.zeros(6), UR5E_HOME_Q] + [rng.uniform(lower, upper) for _ in range(20)]:
        plant.SetPositions(context, q)
        X_BE = plant.CalcRelativeTransform(context, frame_B, frame_E).GetAsMatrix4()
        np.testing.assert_allclose(X_BE, dh_forward_kinematics(q), atol=1e-9, rtol=0)
    # Hand-computed: at q = 0 the arm is stretched along -x_B:
    # p = (a2 + a3, -(d4 + d6), d1 - d5) = (-0.8172, -0.2329, 0.0628).
    plant.SetPositions(context, np.zeros(6))
    np.testing.assert_allclose(
        plant.CalcRelativeTransform(context, frame_B, frame_E).translation(),
        [-0.8172, -0.2329, 0.0628], atol=1e-12)


def test_model_limits_masses_and_home_pose():
    plant = make_control_plant()
    np.testing.assert_allclose(plant.GetPositionUpperLimits(),
                               [2 * np.pi, 2 * np.pi, np.pi, 2 * np.pi, 2 * np.pi, 2 * np.pi])
    np.testing.assert_allclose(plant.GetPositionLowerLimits(), -plant.GetPositionUpperLimits())
    np.testing.assert_allclose(plant.GetVelocityUpperLimits(), np.full(6, np.pi))
    np.testing.assert_allclose(plant.GetEffortUpperLimits(), [150, 150, 150, 28, 28, 28])
    masses = [plant.GetBodyByName(n).default_mass() for n in (
        "shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link",
        "wrist_3_link")]
    np.testing.assert_allclose(masses, [3.761, 8.058, 2.846, 1.37, 1.3, 0.365])
    # Home: flange z points straight down, well away from singularities.
    X_WE = commanded_pose(UR5E_HOME_Q)
    np.testing.assert_allclose(X_WE[:3, 2], [0, 0, -1], atol=1e-12)
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, UR5E_HOME_Q)
    J = plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kV,
                                          plant.GetFrameByName("tool0"), [0, 0, 0],
                                          plant.world_frame(), plant.world_frame())
    assert np.linalg.svd(J, compute_uv=False).min() > 0.2


# --- closed loop: driver + PD plant + sensor -----------------------------------------------------

def test_constant_rotation_about_own_z_axis():
    """ω_E = [0, 0, 0.2] rad/s for 1 s → E turns 0.2 rad about its own z, origin fixed.

    Measured (2 ms, kp = 1e5): the commanded joints are exact (1e-9 asserted); the simulated E
    turns 0.19968 rad about z (≈ one step of lag, 0.2 rad/s · 2 ms = 4e-4 rad), with a 5e-4 rad
    gravity sag about x and y (shoulder and elbow carry ≈ 20 N·m each at kp = 1e5 N·m/rad), total
    orientation error 5.8e-4 rad; its origin moves 0.25 mm.
    """
    diagram, arm, driver, sensor, _ = build_loop([0, 0, 0.2, 0, 0, 0], Q_GENERIC)
    simulator = Simulator(diagram)
    sensor_context = sensor.GetMyContextFromRoot(simulator.get_context())
    X_WE0 = vector_to_pose(sensor.get_X_WE_output_port().Eval(sensor_context))
    np.testing.assert_allclose(X_WE0, commanded_pose(Q_GENERIC), atol=1e-12)
    simulator.AdvanceTo(1.0)
    driver_context = driver.GetMyContextFromRoot(simulator.get_context())
    # 500 periodic updates (t = 0 … 0.998 s) of 0.2 rad/s · 2 ms.
    q_cmd = driver.get_desired_state_output_port().Eval(driver_context)[:6]
    D_cmd = inverse(commanded_pose(Q_GENERIC)) @ commanded_pose(q_cmd)
    np.testing.assert_allclose(rotation_log(D_cmd[:3, :3]), [0, 0, 0.2], atol=1e-9)
    np.testing.assert_allclose(D_cmd[:3, 3], 0, atol=1e-9)
    assert driver.get_status_output_port().Eval(driver_context)[0] == 0.0

    X_WE1 = vector_to_pose(sensor.get_X_WE_output_port().Eval(sensor_context))
    D = inverse(X_WE0) @ X_WE1
    assert np.linalg.norm(rotation_log(D[:3, :3]) - [0, 0, 0.2]) < 1.5e-3
    assert np.linalg.norm(D[:3, 3]) < 1e-3


def test_constant_translation_along_own_x_axis():
    """v_E = [0.05, 0, 0] m/s for 1 s → E moves 5 cm along its own (initial) x, no rotation.

    Measured: the commanded motion is 5 cm to 6e-6 m and 1.2e-6 rad (explicit Euler on the joint
    velocities); the simulated E moves 4.993 cm along x (≈ one step of lag) with 0.22 mm of
    gravity sag along z and 4.5e-4 rad of rotation: error 2.4e-4 m.
    """
    diagram, arm, driver, sensor, _ = build_loop([0, 0, 0, 0.05, 0, 0], Q_GENERIC)
    simulator = Simulator(diagram)
    sensor_context = sensor.GetMyContextFromRoot(simulator.get_context())
    X_WE0 = vector_to_pose(sensor.get_X_WE_output_port().Eval(sensor_context))
    simulator.AdvanceTo(1.0)
    driver_context = driver.GetMyContextFromRoot(simulator.get_context())
    q_cmd = driver.get_desired_state_output_port().Eval(driver_context)[:6]
    D_cmd = inverse(commanded_pose(Q_GENERIC)) @ commanded_pose(q_cmd)
    np.testing.assert_allclose(D_cmd[:3, 3], [0.05, 0, 0], atol=2e-5)
    np.testing.assert_allclose(rotation_log(D_cmd[:3, :3]), 0, atol=2e-5)

    X_WE1 = vector_to_pose(sensor.get_X_WE_output_port().Eval(sensor_context))
    D = inverse(X_WE0) @ X_WE1
    assert np.linalg.norm(D[:3, 3] - [0.05, 0, 0]) < 1e-3
    assert np.linalg.norm(rotation_log(D[:3, :3])) < 1e-3
    # In the world the motion is along E's x axis, not W's.
    np.testing.assert_allclose(X_WE1[:3, 3] - X_WE0[:3, 3], 0.05 * X_WE0[:3, 0], atol=1e-3)


def test_joint_limits_are_never_exceeded():
    """Wrist 3 starts 0.05 rad below its +2π limit and is spun at 1 rad/s for 0.3 s: the command
    stops exactly at the limit, the driver reports kStuck, and neither the command nor the
    simulated joint ever passes the limit."""
    upper = 2 * np.pi
    q0 = Q_GENERIC.copy()
    q0[5] = upper - 0.05
    diagram, arm, driver, sensor, (cmd_log, state_log, status_log) = build_loop(
        [0, 0, 1.0, 0, 0, 0], q0, log=True)
    simulator = Simulator(diagram)
    simulator.AdvanceTo(0.3)
    context = simulator.get_context()
    q_cmd = cmd_log.FindLog(context).data()[:6]
    q_sim = state_log.FindLog(context).data()[:6]
    status = status_log.FindLog(context).data()[0]
    lower = -np.array([2 * np.pi, 2 * np.pi, np.pi, 2 * np.pi, 2 * np.pi, 2 * np.pi])
    assert np.all(q_cmd <= -lower[:, None]) and np.all(q_cmd >= lower[:, None])
    assert q_cmd[5].max() == upper
    assert q_sim[5].max() <= upper + 1e-6  # SAP also enforces the URDF limit on the plant
    assert status[-1] == STUCK
    # It ran freely (status 0) until the limit was reached after ≈ 0.05 s.
    assert np.all(status[:20] == 0.0)


def test_infeasible_command_at_singularity_reports_stuck_and_holds():
    """At q = 0 (elbow and wrist singular) a twist along a direction the Jacobian cannot produce
    is infeasible: status kStuck, the command holds, outputs stay finite."""
    plant = make_control_plant()
    context = plant.CreateDefaultContext()
    J_WE_E = plant.CalcJacobianSpatialVelocity(context, JacobianWrtVariable.kV,
                                               plant.GetFrameByName("tool0"), [0, 0, 0],
                                               plant.world_frame(), plant.GetFrameByName("tool0"))
    U, s, _ = np.linalg.svd(J_WE_E)
    assert s[-1] < 1e-12  # really singular
    V_bad = 10.0 * U[:, -1]
    diagram, arm, driver, sensor, _ = build_loop(V_bad, np.zeros(6))
    simulator = Simulator(diagram)
    simulator.AdvanceTo(0.05)
    driver_context = driver.GetMyContextFromRoot(simulator.get_context())
    x_d = driver.get_desired_state_output_port().Eval(driver_context)
    assert driver.get_status_output_port().Eval(driver_context)[0] == STUCK
    assert np.all(np.isfinite(x_d))
    np.testing.assert_allclose(x_d[:6], 0, atol=1e-3)
    sensor_context = sensor.GetMyContextFromRoot(simulator.get_context())
    assert np.all(np.isfinite(sensor.get_X_BE_output_port().Eval(sensor_context)))


def test_non_finite_command_holds_position_and_reports_no_solution():
    diagram, arm, driver, sensor, _ = build_loop([np.nan, 0, 0, 0, 0, 0], Q_GENERIC)
    simulator = Simulator(diagram)
    simulator.AdvanceTo(0.02)
    driver_context = driver.GetMyContextFromRoot(simulator.get_context())
    np.testing.assert_array_equal(driver.get_desired_state_output_port().Eval(driver_context),
                                  np.concatenate([Q_GENERIC, np.zeros(6)]))
    assert driver.get_status_output_port().Eval(driver_context)[0] == NO_SOLUTION


def test_set_initial_positions():
    diagram, arm, driver, sensor, _ = build_loop(np.zeros(6), Q_GENERIC)
    context = diagram.CreateDefaultContext()
    driver_context = driver.GetMyContextFromRoot(context)
    np.testing.assert_array_equal(driver.get_desired_state_output_port().Eval(driver_context),
                                  np.concatenate([Q_GENERIC, np.zeros(6)]))
    driver.SetInitialPositions(driver_context, UR5E_HOME_Q)
    np.testing.assert_array_equal(driver.get_desired_state_output_port().Eval(driver_context),
                                  np.concatenate([UR5E_HOME_Q, np.zeros(6)]))
    with pytest.raises(ValueError, match="q: joint 2 = 4 rad is outside its limits"):
        driver.SetInitialPositions(driver_context, [0, 0, 4.0, 0, 0, 0])
    # The plant starts at add_arm's q0.
    np.testing.assert_array_equal(arm.plant.GetPositions(arm.plant.GetMyContextFromRoot(context)),
                                  Q_GENERIC)


# --- sensor --------------------------------------------------------------------------------------

def test_sensor_matches_calc_relative_transform_with_offset_frames():
    X_WB = RigidTransform(RollPitchYaw(0.1, -0.2, 0.7), [0.3, -0.4, 0.8])
    builder = DiagramBuilder()
    arm = add_arm(builder, X_WB=X_WB, finalize=False)
    plant = arm.plant
    # A camera-like frame fixed on the flange body and a non-body frame on the base.
    X_W3C = RigidTransform(RollPitchYaw(0.3, 0.2, -0.5), [0.02, -0.05, 0.13])
    plant.AddFrame(FixedOffsetFrame("cam", plant.GetFrameByName("wrist_3_link"), X_W3C))
    plant.AddFrame(FixedOffsetFrame("mount", plant.GetFrameByName("base_link"),
                                    RigidTransform([0.0, 0.0, 0.05])))
    plant.Finalize()
    s_tool = builder.AddSystem(EndEffectorPoseSensor(plant, "base_link", "tool0"))
    s_cam = builder.AddSystem(EndEffectorPoseSensor(plant, "mount", "cam"))
    for s in (s_tool, s_cam):
        builder.Connect(plant.get_body_poses_output_port(), s.get_body_poses_input_port())
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyContextFromRoot(context)
    rng = np.random.default_rng(3)
    for _ in range(3):
        plant.SetPositions(plant_context, rng.uniform(-3, 3, 6))
        for s, b, e in ((s_tool, "base_link", "tool0"), (s_cam, "mount", "cam")):
            sc = s.GetMyContextFromRoot(context)
            frame_B, frame_E = plant.GetFrameByName(b), plant.GetFrameByName(e)
            X_BE = plant.CalcRelativeTransform(plant_context, frame_B, frame_E).GetAsMatrix4()
            X_WE = plant.CalcRelativeTransform(plant_context, plant.world_frame(),
                                               frame_E).GetAsMatrix4()
            np.testing.assert_allclose(vector_to_pose(s.get_X_BE_output_port().Eval(sc)), X_BE,
                                       atol=1e-12)
            np.testing.assert_allclose(vector_to_pose(s.get_X_WE_output_port().Eval(sc)), X_WE,
                                       atol=1e-12)
        # The flange in the base is the DH product, independent of where the base is welded.
        X_BE_tool = s_tool.get_X_BE_output_port().Eval(s_tool.GetMyContextFromRoot(context))
        np.testing.assert_allclose(vector_to_pose(X_BE_tool),
                                   dh_forward_kinematics(plant.GetPositions(plant_context)),
                                   atol=1e-9)


# --- argument checking ---------------------------------------------------------------------------

def test_driver_rejects_bad_arguments():
    plant = make_control_plant()
    with pytest.raises(ValueError, match=r"q0: expected shape \(6,\)"):
        DifferentialIkDriver(plant, "tool0", DT, np.zeros(5))
    with pytest.raises(ValueError, match="q0: contains NaN"):
        DifferentialIkDriver(plant, "tool0", DT, [np.nan, 0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="q0: joint 2 .* outside its limits"):
        DifferentialIkDriver(plant, "tool0", DT, [0, 0, 3.5, 0, 0, 0])
    for bad in (0.0, -0.002, np.inf):
        with pytest.raises(ValueError, match="time_step: must be finite and > 0"):
            DifferentialIkDriver(plant, "tool0", bad, UR5E_HOME_Q)
    with pytest.raises(ValueError, match="ee_frame_name: no frame named 'flange'"):
        DifferentialIkDriver(plant, "flange", DT, UR5E_HOME_Q)
    with pytest.raises(ValueError, match="velocity_scale: must be in"):
        DifferentialIkDriver(plant, "tool0", DT, UR5E_HOME_Q, velocity_scale=1.5)
    with pytest.raises(ValueError, match="control_plant: expected a finalized MultibodyPlant"):
        DifferentialIkDriver("ur5e", "tool0", DT, UR5E_HOME_Q)


def test_sensor_and_add_arm_reject_bad_arguments(tmp_path):
    builder = DiagramBuilder()
    arm = add_arm(builder)
    with pytest.raises(ValueError, match="base_frame_name: no frame named 'base'"):
        EndEffectorPoseSensor(arm.plant, "base", "tool0")
    with pytest.raises(ValueError, match="ee_frame_name: no frame named 'tool1'"):
        EndEffectorPoseSensor(arm.plant, "base_link", "tool1")
    with pytest.raises(ValueError, match="ee_frame: no frame named 'hand'"):
        add_arm(DiagramBuilder(), ee_frame="hand")
    with pytest.raises(ValueError, match="base_frame: no frame named 'pedestal'"):
        add_arm(DiagramBuilder(), base_frame="pedestal")
    with pytest.raises(ValueError, match="urdf: model file not found"):
        add_arm(DiagramBuilder(), urdf=tmp_path / "missing.urdf")
    with pytest.raises(ValueError, match="plant_config.time_step: must be finite and > 0"):
        add_arm(DiagramBuilder(), plant_config=MultibodyPlantConfig(time_step=0.0))
    with pytest.raises(ValueError, match="kp: gains must be ≥ 0"):
        add_arm(DiagramBuilder(), kp=-1.0)
    with pytest.raises(ValueError, match=r"kd: expected shape \(6,\)"):
        add_arm(DiagramBuilder(), kd=[1.0, 2.0])
    with pytest.raises(ValueError, match="X_WB"):
        add_arm(DiagramBuilder(), X_WB=np.eye(3))
    with pytest.raises(ValueError, match="urdf: model file not found"):
        make_control_plant(urdf="/nonexistent/arm.urdf")
    assert UR5E_URDF.endswith("ur5e.urdf")


def test_pd_gains_and_default_positions_are_applied():
    builder = DiagramBuilder()
    arm = add_arm(builder, kp=[1, 2, 3, 4, 5, 6], kd=7.0, q0=Q_GENERIC)
    gains = [arm.plant.get_joint_actuator(i).get_controller_gains()
             for i in arm.plant.GetJointActuatorIndices(arm.model_instance)]
    assert [g.p for g in gains] == [1, 2, 3, 4, 5, 6] and all(g.d == 7.0 for g in gains)
    np.testing.assert_array_equal(arm.plant.GetDefaultPositions(arm.model_instance), Q_GENERIC)
    assert arm.plant.time_step() == DT and arm.plant.is_finalized()


def test_the_pose_tracking_driver_reaches_a_commanded_pose_from_the_start_state():
    """add_pose_tracking_driver: Drake's integrator starts from the plant's state (no set-up
    call) and drives the flange to a pose commanded in the base frame B (based off the world
    here, so B ≠ W matters), under the joint velocity limits scaled by velocity_scale."""
    from pydrake.common.value import AbstractValue
    from pydrake.systems.primitives import ConstantValueSource

    from handeye_drake.estimation.se3 import rotation_angle
    from handeye_drake.systems.arm import add_pose_tracking_driver

    X_WB = make_transform(rotation_exp([0.0, 0.0, 0.3]), [0.2, -0.1, 0.05])
    builder = DiagramBuilder()
    arm = add_arm(builder, plant_config=MultibodyPlantConfig(time_step=DT), X_WB=X_WB,
                  q0=UR5E_HOME_Q)
    driver = add_pose_tracking_driver(builder, arm, make_control_plant(X_WB=X_WB), 0.01,
                                      velocity_scale=0.5)
    X_BE0 = dh_forward_kinematics(UR5E_HOME_Q)
    X_BE_goal = X_BE0 @ make_transform(rotation_exp([0.1, -0.05, 0.08]), [0.02, -0.03, 0.04])
    goal = builder.AddSystem(ConstantValueSource(AbstractValue.Make(RigidTransform(X_BE_goal))))
    builder.Connect(goal.get_output_port(), driver.X_BE_desired_input_port())
    sensor = builder.AddSystem(EndEffectorPoseSensor(arm.plant, arm.base_frame, arm.ee_frame))
    builder.Connect(arm.plant.get_body_poses_output_port(), sensor.get_body_poses_input_port())
    desired = LogVectorOutput(driver.interpolator.get_output_port(), builder)  # [q; v] set point
    state = LogVectorOutput(arm.plant.get_state_output_port(arm.model_instance), builder)
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(1.0)
    context = simulator.get_context()
    X_BE = vector_to_pose(sensor.get_X_BE_output_port().Eval(
        sensor.GetMyContextFromRoot(context)))
    assert np.linalg.norm(X_BE[:3, 3] - X_BE_goal[:3, 3]) < 1e-3
    assert rotation_angle(X_BE[:3, :3].T @ X_BE_goal[:3, :3]) < np.radians(0.1)
    v_d = desired.FindLog(context).data()[6:]
    limit = 0.5 * make_control_plant().GetVelocityUpperLimits()
    assert np.all(np.abs(v_d) <= limit[:, None] * (1 + 1e-9))
    assert np.abs(v_d).max() > 0.5 * limit.max()  # the limit was what bounded the motion
    # It started from the plant's state: no jump of the set point at the first step.
    q = state.FindLog(context).data()[:6]
    np.testing.assert_allclose(q[:, 0], UR5E_HOME_Q, atol=1e-12)
    np.testing.assert_allclose(desired.FindLog(context).data()[:6, 0], UR5E_HOME_Q, atol=1e-2)

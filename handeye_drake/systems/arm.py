"""The robot arm of the simulation: a PD-controlled MultibodyPlant arm, its drivers — Drake's C++
differential-IK integrator tracking a commanded end-effector pose (``add_pose_tracking_driver``),
or a Python differential-IK driver turning a commanded twist into joint set points
(``DifferentialIkDriver``) — and an end-effector pose sensor.

Everything here is generic: any URDF/SDFormat arm whose joints are all 1-DOF and actuated plugs in
the same way (``urdf=..., base_frame=..., ee_frame=...``); the bundled model is a UR5e
(``UR5E_URDF``, built from Universal Robots' published DH table, see the comment in the file).

Frames: W world, B robot base (``base_frame``, welded to W at ``X_WB``), E end-effector
(``ee_frame``, the UR5e flange ``tool0`` = DH frame 6). Twists are [ω; v] (rad/s, m/s), poses on
ports are 12-vectors [vec_row(R); p] (see ``handeye_drake.estimation.se3.pose_to_vector``).

Typical wiring (a servo commanding a pose X_BE_desired)::

    arm = add_arm(builder)
    driver = add_pose_tracking_driver(builder, arm, make_control_plant(), 0.01)
    builder.Connect(servo.get_X_BE_desired_output_port(), driver.X_BE_desired_input_port())

or (a servo commanding a twist)::

    arm = add_arm(builder)
    driver = builder.AddSystem(DifferentialIkDriver(make_control_plant(), arm.ee_frame, 0.002,
                                                    UR5E_HOME_Q))
    builder.Connect(driver.get_desired_state_output_port(),
                    arm.plant.get_desired_state_input_port(arm.model_instance))
    sensor = builder.AddSystem(EndEffectorPoseSensor(arm.plant, arm.base_frame, arm.ee_frame))
    builder.Connect(arm.plant.get_body_poses_output_port(), sensor.get_body_poses_input_port())
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import SceneGraph
from pydrake.math import RigidTransform
from pydrake.multibody.inverse_kinematics import (
    DifferentialInverseKinematicsIntegrator,
    DifferentialInverseKinematicsParameters,
    DifferentialInverseKinematicsStatus,
    DoDifferentialInverseKinematics,
)
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlant, MultibodyPlant, MultibodyPlantConfig
from pydrake.multibody.tree import ModelInstanceIndex, PdControllerGains
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import MatrixGain, StateInterpolatorWithDiscreteDerivative

from ..estimation import kernels
from ..estimation.se3 import inverse, pose_to_vector
from ..estimation.validation import as_matrix, as_transform, check_positive

#: The bundled UR5e model (DH-exact kinematics, published masses; see the file's header comment).
UR5E_URDF = str(Path(__file__).resolve().parent.parent / "models" / "ur5e.urdf")

#: UR5e joint order of the model (= actuator order).
UR5E_JOINT_NAMES = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
                    "wrist_2_joint", "wrist_3_joint")

#: UR5e "home" configuration [rad]: upper arm up, forearm horizontal, flange pointing straight down
#: (tool0 z = -z_B) at p_BE ≈ (-0.49, -0.13, 0.49) m. Away from all three UR singularities
#: (elbow q3 ≠ 0, wrist q5 ≠ 0, wrist centre off the base axis): the smallest singular value of
#: the 6×6 Jacobian is 0.22.
UR5E_HOME_Q = np.array([0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0])

#: Default PD gains of the joint actuators, N·m/rad and N·m·s/rad. Drake's discrete SAP solver
#: applies them implicitly, so they are stable at 2 ms; with gravity on, the static error is
#: gravity torque / kp ≲ 0.2 mrad at the UR5e's home pose (20 N·m on shoulder and elbow).
DEFAULT_KP = 1.0e5
DEFAULT_KD = 2.0e3

#: The arm's plant: discrete (SAP applies the PD gains implicitly), 2 ms, with live output ports.
#: Sampled ports (Drake's default) make each plant step an unrestricted update, after which the
#: simulator asks every system for its witness functions again: through pybind11 for each
#: Python system, at each 2 ms step. The ports read here (state, body poses) are kinematic and
#: live in either mode; live ports also make the plant's step a discrete update computed
#: simultaneously with the camera's, so a sample at a step time sees the state at that time.
DEFAULT_PLANT_CONFIG = MultibodyPlantConfig(time_step=0.002, use_sampled_output_ports=False)

_STATUS_SOLUTION_FOUND = float(int(DifferentialInverseKinematicsStatus.kSolutionFound))
_STATUS_NO_SOLUTION = float(int(DifferentialInverseKinematicsStatus.kNoSolutionFound))


@dataclass(frozen=True, eq=False)
class ArmHandles:
    """What ``add_arm`` created: the plant (finalized unless ``finalize=False``), its scene graph,
    the arm's model instance, the names of the base (B) and end-effector (E) frames, the model file
    and the base pose X_WB (4×4), so a matching control plant is ``make_control_plant(h.urdf,
    h.base_frame, h.X_WB)``."""

    plant: MultibodyPlant
    scene_graph: SceneGraph
    model_instance: ModelInstanceIndex
    base_frame: str
    ee_frame: str
    urdf: str
    X_WB: np.ndarray


def _resolve_model_file(urdf) -> str:
    path = Path(UR5E_URDF if urdf is None else urdf)
    if not path.is_file():
        raise ValueError(f"urdf: model file not found: {str(path)!r}")
    return str(path)


def _as_X_WB(X_WB) -> np.ndarray:
    return np.eye(4) if X_WB is None else as_transform(X_WB, "X_WB")


def _check_frame(plant: MultibodyPlant, name, arg: str, model_instance=None):
    """The frame called ``name`` (in ``model_instance`` if given) or ValueError naming ``arg``."""
    if not isinstance(name, str) or not name:
        raise ValueError(f"{arg}: expected a frame name (non-empty str), got {name!r}")
    try:
        found = (plant.HasFrameNamed(name) if model_instance is None
                 else plant.HasFrameNamed(name, model_instance))
    except RuntimeError as e:  # the name exists in several model instances
        raise ValueError(f"{arg}: frame name {name!r} is ambiguous ({e})") from None
    if not found:
        known = sorted({plant.get_frame(i).name() for i in plant.GetFrameIndices(model_instance)}
                       if model_instance is not None else
                       {plant.get_frame(i).name() for m in range(plant.num_model_instances())
                        for i in plant.GetFrameIndices(ModelInstanceIndex(m))})
        raise ValueError(f"{arg}: no frame named {name!r} in the plant; known frames: {known}")
    return (plant.GetFrameByName(name) if model_instance is None
            else plant.GetFrameByName(name, model_instance))


def frame_in_body(plant: MultibodyPlant, name: str, arg: str):
    """(body index (int), X_BodyF 4×4): where the frame called ``name`` of a finalized ``plant``
    sits, to read its pose from the plant's ``body_poses`` output (X_WF = X_WBody · X_BodyF).
    ValueError naming ``arg`` for an unknown or ambiguous name."""
    if not isinstance(plant, MultibodyPlant) or not plant.is_finalized():
        raise ValueError(f"plant: expected a finalized MultibodyPlant, got {type(plant).__name__}")
    frame = _check_frame(plant, name, arg)
    return int(frame.body().index()), frame.GetFixedPoseInBodyFrame().GetAsMatrix4()


class EndEffectorPoseInput:
    """The end-effector pose input of a system that rides on the hand (``HandEyeCamera``,
    ``HandCameraPose``): without ``plant`` a vector port ``X_WE`` (12, [vec_row(R); p (m)]);
    with the arm's finalized ``plant`` an abstract port ``body_poses`` (connect
    ``plant.get_body_poses_output_port()``), B and E resolved once (``frame_in_body``)."""

    def __init__(self, system, plant, base_frame_name: str, ee_frame_name: str):
        self._owner = type(system).__name__
        if plant is None:
            self.frames = None
            self.port = system.DeclareVectorInputPort("X_WE", 12)
        else:
            # (body index, pose of the frame in its body) of B and E.
            self.frames = (frame_in_body(plant, base_frame_name, "base_frame_name"),
                           frame_in_body(plant, ee_frame_name, "ee_frame_name"))
            self.port = system.DeclareAbstractInputPort(
                "body_poses", AbstractValue.Make([RigidTransform()]))

    def X_WE_port(self):
        if self.frames is not None:
            raise ValueError(f"this {self._owner} reads the plant's body poses (constructed "
                             "with a plant): use get_body_poses_input_port")
        return self.port

    def body_poses_port(self):
        if self.frames is None:
            raise ValueError(f"this {self._owner} takes X_WE (constructed without a plant): "
                             "use get_X_WE_input_port")
        return self.port

    def Eval(self, context):
        """(x_WE, X_WE, X_BE): the pose vector as read, and with a plant the 4×4 X_WE and X_BE
        of the arithmetic of ``EndEffectorPoseSensor`` (both None without a plant)."""
        if self.frames is None:
            return self.port.Eval(context), None, None
        poses = self.port.Eval(context)
        (iB, X_BodyB), (iE, X_BodyE) = self.frames
        return kernels.hand_poses(poses[iE].GetAsMatrix4(), X_BodyE,
                                  poses[iB].GetAsMatrix4(), X_BodyB)


def _per_actuator(value, name: str, n: int) -> np.ndarray:
    v = np.full(n, value, dtype=float) if np.ndim(value) == 0 else value
    v = as_matrix(v, name, (n,))
    if np.any(v < 0):
        raise ValueError(f"{name}: gains must be ≥ 0, got {v.tolist()}")
    return v


def _parse_arm(plant: MultibodyPlant, urdf, base_frame, X_WB):
    model_file = _resolve_model_file(urdf)
    X_WB = _as_X_WB(X_WB)
    models = Parser(plant).AddModels(model_file)
    if len(models) != 1:
        raise ValueError(f"urdf: expected exactly one model in {model_file!r}, got {len(models)}")
    model_instance = models[0]
    frame_B = _check_frame(plant, base_frame, "base_frame", model_instance)
    plant.WeldFrames(plant.world_frame(), frame_B, RigidTransform(X_WB))
    return model_file, X_WB, model_instance


def add_arm(builder: DiagramBuilder, plant_config: MultibodyPlantConfig | None = None,
            urdf=None, base_frame: str = "base_link", ee_frame: str = "tool0", X_WB=None,
            kp=DEFAULT_KP, kd=DEFAULT_KD, q0=None, finalize: bool = True) -> ArmHandles:
    """Adds a discrete MultibodyPlant + SceneGraph holding the arm to ``builder``, configured by
    Drake's ``plant_config`` (default: ``DEFAULT_PLANT_CONFIG``, a 2 ms discrete plant).

    The base frame is welded to the world at ``X_WB`` (4×4 or RigidTransform; identity if None).
    Every joint actuator gets a PD controller (``kp``, ``kd``: scalars or one per actuator, in
    actuator order), so ``plant.get_desired_state_input_port(model_instance)`` ([q_d; v_d], rad and
    rad/s, 2·n_actuators) drives the arm; Drake's SAP solver applies PD implicitly and clamps the
    torque at each joint's effort limit. Gravity stays on. The actuation input port
    (feed-forward torque) may be left unconnected.

    ``q0`` sets the plant's default joint positions (default: ``UR5E_HOME_Q`` for the bundled
    UR5e, the model's own defaults otherwise). With ``finalize=False`` the caller may add more
    models before calling ``plant.Finalize()``.
    """
    plant_config = DEFAULT_PLANT_CONFIG if plant_config is None else plant_config
    check_positive(plant_config.time_step, "plant_config.time_step")
    plant, scene_graph = AddMultibodyPlant(plant_config, builder)
    model_file, X_WB, model_instance = _parse_arm(plant, urdf, base_frame, X_WB)
    _check_frame(plant, ee_frame, "ee_frame", model_instance)
    # (GetJointActuatorIndices(model_instance) is empty before Finalize(); filter the full list.)
    actuators = [a for a in map(plant.get_joint_actuator, plant.GetJointActuatorIndices())
                 if a.model_instance() == model_instance]
    if not actuators:
        raise ValueError(f"urdf: the model in {model_file!r} has no actuators (add a "
                         "<transmission> per joint)")
    kp = _per_actuator(kp, "kp", len(actuators))
    kd = _per_actuator(kd, "kd", len(actuators))
    for actuator, p, d in zip(actuators, kp, kd):
        actuator.set_controller_gains(PdControllerGains(p=p, d=d))
    if finalize:
        plant.Finalize()
        if q0 is None and urdf is None:
            q0 = UR5E_HOME_Q
        if q0 is not None:
            plant.SetDefaultPositions(model_instance, as_matrix(
                q0, "q0", (plant.num_positions(model_instance),)))
    elif q0 is not None:
        raise ValueError("q0: default positions can only be set on a finalized plant; pass "
                         "finalize=True or call plant.SetDefaultPositions after Finalize()")
    return ArmHandles(plant=plant, scene_graph=scene_graph, model_instance=model_instance,
                      base_frame=base_frame, ee_frame=ee_frame, urdf=model_file, X_WB=X_WB)


def make_control_plant(urdf=None, base_frame: str = "base_link", X_WB=None) -> MultibodyPlant:
    """A separate finalized continuous-time MultibodyPlant of the arm alone (no SceneGraph), base
    welded at ``X_WB``: the controller's kinematic model (Jacobians, limits)."""
    plant = MultibodyPlant(time_step=0.0)
    _parse_arm(plant, urdf, base_frame, X_WB)
    plant.Finalize()
    return plant


def _check_arm_plant(control_plant) -> int:
    """n, for a finalized plant whose joints are all 1-DOF and actuated; else ValueError."""
    if not isinstance(control_plant, MultibodyPlant) or not control_plant.is_finalized():
        raise ValueError("control_plant: expected a finalized MultibodyPlant, got "
                         f"{type(control_plant).__name__}")
    n = control_plant.num_positions()
    if n == 0 or control_plant.num_velocities() != n or control_plant.num_actuators() != n:
        raise ValueError(
            "control_plant: needs an arm whose joints are all 1-DOF and actuated, got "
            f"{n} positions, {control_plant.num_velocities()} velocities, "
            f"{control_plant.num_actuators()} actuators")
    return n


def _actuator_permutation(control_plant) -> np.ndarray:
    """(2n × 2n) P with [q; v] in actuator order = P · [q; v] in joint (state) order."""
    n = control_plant.num_positions()
    actuators = [control_plant.get_joint_actuator(i)
                 for i in control_plant.GetJointActuatorIndices()]
    P = np.zeros((2 * n, 2 * n))
    for k, a in enumerate(actuators):
        P[k, a.joint().position_start()] = 1.0
        P[n + k, n + a.joint().velocity_start()] = 1.0
    return P


@dataclass(frozen=True, eq=False)
class PoseTrackingDriver:
    """What ``add_pose_tracking_driver`` added: Drake's ``DifferentialInverseKinematicsIntegrator``
    (``integrator``, its ``joint_positions`` output the commanded q) and the
    ``StateInterpolatorWithDiscreteDerivative`` (``interpolator``) that makes [q; v] of it."""

    integrator: DifferentialInverseKinematicsIntegrator
    interpolator: StateInterpolatorWithDiscreteDerivative
    time_step: float

    def X_BE_desired_input_port(self):
        """The integrator's ``X_AE_desired`` (abstract RigidTransform): E in the base frame B."""
        return self.integrator.GetInputPort("X_AE_desired")


def add_pose_tracking_driver(builder: DiagramBuilder, arm: ArmHandles,
                             control_plant: MultibodyPlant, time_step: float,
                             velocity_scale: float = 1.0) -> PoseTrackingDriver:
    """Drives ``arm`` toward a commanded end-effector pose with Drake's C++ systems only.

    Every ``time_step`` the ``DifferentialInverseKinematicsIntegrator`` (frame A = the arm's
    base B, E = ``arm.ee_frame`` of ``control_plant``) solves Drake's differential IK toward the
    pose on its ``X_AE_desired`` input under the plant's joint position limits and
    ``velocity_scale`` × its joint velocity limits, and integrates its joint command q; a
    ``StateInterpolatorWithDiscreteDerivative`` at the same step turns q into the set point
    [q (rad); v (rad/s)] of the plant's PD controllers (a C++ ``MatrixGain`` reorders it when the
    actuator order differs from the joint order). The integrator starts from the plant's state at
    initialization (its ``robot_state`` input is the plant's state; ``use_robot_state`` stays
    unconnected, so it integrates its own command, open loop like a robot's position interface).
    A pose the limits do not let it reach is approached as far as they allow (Drake's kStuck).

    ``control_plant``: the arm alone, finalized, every joint 1-DOF and actuated, actuators in the
    same order as in ``arm.plant`` (``make_control_plant(arm.urdf, arm.base_frame, arm.X_WB)``).
    """
    n = _check_arm_plant(control_plant)
    time_step = check_positive(time_step, "time_step")
    velocity_scale = check_positive(velocity_scale, "velocity_scale")
    if velocity_scale > 1.0:
        raise ValueError(f"velocity_scale: must be in (0, 1], got {velocity_scale!r}")
    frame_B = _check_frame(control_plant, arm.base_frame, "base_frame")
    frame_E = _check_frame(control_plant, arm.ee_frame, "ee_frame")
    params = DifferentialInverseKinematicsParameters(n, n)
    params.set_joint_position_limits((control_plant.GetPositionLowerLimits(),
                                      control_plant.GetPositionUpperLimits()))
    params.set_joint_velocity_limits(
        (velocity_scale * control_plant.GetVelocityLowerLimits(),
         velocity_scale * control_plant.GetVelocityUpperLimits()))
    integrator = builder.AddNamedSystem("diff_ik", DifferentialInverseKinematicsIntegrator(
        control_plant, frame_B, frame_E, time_step, params))
    builder.Connect(arm.plant.get_state_output_port(arm.model_instance),
                    integrator.GetInputPort("robot_state"))
    interpolator = builder.AddNamedSystem("desired_state", StateInterpolatorWithDiscreteDerivative(
        n, time_step, suppress_initial_transient=True))
    builder.Connect(integrator.GetOutputPort("joint_positions"), interpolator.get_input_port())
    desired = arm.plant.get_desired_state_input_port(arm.model_instance)
    P = _actuator_permutation(control_plant)
    if np.array_equal(P, np.eye(2 * n)):
        builder.Connect(interpolator.get_output_port(), desired)
    else:
        reorder = builder.AddNamedSystem("actuator_order", MatrixGain(P))
        builder.Connect(interpolator.get_output_port(), reorder.get_input_port())
        builder.Connect(reorder.get_output_port(), desired)
    return PoseTrackingDriver(integrator=integrator, interpolator=interpolator,
                              time_step=time_step)


class DifferentialIkDriver(LeafSystem):
    """Turns a commanded end-effector twist into joint position/velocity set points.

    Every ``time_step`` it expresses the commanded twist in W (rotation R_WE of the control plant
    at the commanded joints q_cmd), solves Drake's differential IK
    (``DoDifferentialInverseKinematics``) under the plant's joint position limits and
    ``velocity_scale`` × its joint velocity limits, then integrates q_cmd += time_step · v_cmd and
    clips q_cmd to the position limits. A twist beyond what the limits allow is scaled down as a
    whole (direction kept, so the servo's motion stays a screw about the same axis); when the
    scale falls below ``get_maximum_scaling_to_report_stuck()`` (1 %), e.g. pushing into a joint
    limit or along a singular direction, Drake reports kStuck and the scaled (feasible) velocity
    is still applied. If no solution is found, or the command is not finite, it holds position
    (v_cmd = 0) and reports kNoSolutionFound.

    The control plant must be finalized and hold only the arm: every joint 1-DOF and actuated
    (n positions = n velocities = n actuators), with actuators in the same order as in the
    simulated plant (true when both are parsed from the same file).

    Input ports:
      - ``V_WE_E_command`` (6): spatial velocity of E in W expressed in E, [ω (rad/s); v (m/s)]
        (the visual servo's twist).
    Output ports (read the discrete state: they change only at the periodic updates):
      - ``desired_state`` (2n): [q_cmd (rad); v_cmd (rad/s)] in actuator order; connect to
        ``plant.get_desired_state_input_port(model_instance)``.
      - ``status`` (1): last DifferentialInverseKinematicsStatus as a float: 0 kSolutionFound,
        1 kNoSolutionFound, 2 kStuck.
    Discrete state: group 0 = [q_cmd; v_cmd] (2n, joint order of the control plant), group 1 =
    [status], group 2 = the desired_state output (actuator order).
    """

    def __init__(self, control_plant: MultibodyPlant, ee_frame_name: str, time_step: float, q0,
                 velocity_scale: float = 1.0):
        super().__init__()
        n = _check_arm_plant(control_plant)
        self._plant = control_plant
        self._frame_E = _check_frame(control_plant, ee_frame_name, "ee_frame_name")
        self._dt = check_positive(time_step, "time_step")
        velocity_scale = check_positive(velocity_scale, "velocity_scale")
        if velocity_scale > 1.0:
            raise ValueError(f"velocity_scale: must be in (0, 1], got {velocity_scale!r}")
        self._n = n
        self._q_lower = control_plant.GetPositionLowerLimits()
        self._q_upper = control_plant.GetPositionUpperLimits()
        q0 = self._check_q(q0, "q0")

        # Desired-state ports are in actuator order; the IK works in position/velocity order.
        actuators = [control_plant.get_joint_actuator(i)
                     for i in control_plant.GetJointActuatorIndices()]
        self._q_of_actuator = np.array([a.joint().position_start() for a in actuators])
        self._v_of_actuator = np.array([a.joint().velocity_start() for a in actuators])

        params = DifferentialInverseKinematicsParameters(n, n)
        params.set_time_step(self._dt)
        params.set_joint_position_limits((self._q_lower, self._q_upper))
        params.set_joint_velocity_limits(
            (velocity_scale * control_plant.GetVelocityLowerLimits(),
             velocity_scale * control_plant.GetVelocityUpperLimits()))
        self._params = params
        self._plant_context = control_plant.CreateDefaultContext()
        control_plant.SetVelocities(self._plant_context, np.zeros(n))
        self._world_frame = control_plant.world_frame()

        self._V_port = self.DeclareVectorInputPort("V_WE_E_command", 6)
        self._cmd_index = self.DeclareDiscreteState(np.concatenate([q0, np.zeros(n)]))
        self._status_index = self.DeclareDiscreteState(np.array([_STATUS_SOLUTION_FOUND]))
        self.DeclarePeriodicDiscreteUpdateEvent(self._dt, 0.0, self._UpdateCommand)
        # The set points in actuator order, kept as state too: the plant reads them at each of
        # its steps without calling Python.
        self._desired_index = self.DeclareDiscreteState(
            self._ActuatorOrder(np.concatenate([q0, np.zeros(n)])))
        self._desired_state_port = self.DeclareStateOutputPort("desired_state",
                                                               self._desired_index)
        self._status_port = self.DeclareStateOutputPort("status", self._status_index)

    def _check_q(self, q, name: str) -> np.ndarray:
        q = as_matrix(q, name, (self._n,))
        bad = np.flatnonzero((q < self._q_lower) | (q > self._q_upper))
        if bad.size:
            i = int(bad[0])
            raise ValueError(f"{name}: joint {i} = {q[i]:.6g} rad is outside its limits "
                             f"[{self._q_lower[i]:.6g}, {self._q_upper[i]:.6g}]")
        return q

    def get_V_WE_E_command_input_port(self):
        return self._V_port

    def get_desired_state_output_port(self):
        return self._desired_state_port

    def get_status_output_port(self):
        return self._status_port

    @property
    def time_step(self) -> float:
        return self._dt

    def SetInitialPositions(self, context, q) -> None:
        """Sets q_cmd = q (rad, control-plant joint order), v_cmd = 0, status = solution found,
        in this system's ``context``. Set the simulated plant to the same q to start at rest."""
        q = self._check_q(q, "q")
        x = np.concatenate([q, np.zeros(self._n)])
        context.SetDiscreteState(self._cmd_index, x)
        context.SetDiscreteState(self._desired_index, self._ActuatorOrder(x))
        context.SetDiscreteState(self._status_index, np.array([_STATUS_SOLUTION_FOUND]))

    def _UpdateCommand(self, context, discrete_state) -> None:
        n = self._n
        q = context.get_discrete_state(self._cmd_index).get_value()[:n].copy()
        V_WE_E = self._V_port.Eval(context)
        v = np.zeros(n)
        status = _STATUS_NO_SOLUTION
        if np.isfinite(V_WE_E).all():
            # (The private context's velocities stay zero: set once, in the constructor.)
            self._plant.SetPositions(self._plant_context, q)
            # DoDifferentialInverseKinematics takes V_WE expressed in W (about E's origin): only a
            # rotation, no change of reference point.
            R_WE = self._plant.CalcRelativeRotationMatrix(
                self._plant_context, self._world_frame, self._frame_E).matrix()
            V_WE_W = np.concatenate([R_WE @ V_WE_E[:3], R_WE @ V_WE_E[3:]])
            result = DoDifferentialInverseKinematics(
                self._plant, self._plant_context, V_WE_W, self._frame_E, self._params)
            status = float(int(result.status))
            if (result.joint_velocities is not None and status != _STATUS_NO_SOLUTION
                    and np.isfinite(result.joint_velocities).all()):
                v = np.asarray(result.joint_velocities, dtype=float).reshape(n)
            else:
                status = _STATUS_NO_SOLUTION
        q_next = np.clip(q + self._dt * v, self._q_lower, self._q_upper)
        x = np.concatenate([q_next, v])
        discrete_state.set_value(self._cmd_index, x)
        discrete_state.set_value(self._desired_index, self._ActuatorOrder(x))
        discrete_state.set_value(self._status_index, np.array([status]))

    def _ActuatorOrder(self, x) -> np.ndarray:
        """[q_cmd; v_cmd] (joint order) → the desired-state port's actuator order."""
        n = self._n
        return np.concatenate([x[:n][self._q_of_actuator], x[n:][self._v_of_actuator]])


class EndEffectorPoseSensor(LeafSystem):
    """Reports the end-effector pose in the world and in the robot base, as a robot controller
    would (exact: no noise).

    Input ports:
      - ``body_poses`` (abstract, list of RigidTransform X_W·Body indexed by BodyIndex): connect
        ``plant.get_body_poses_output_port()``.
    Output ports (12-vectors [vec_row(R); p (m)]):
      - ``X_WE``: pose of E in the world W.
      - ``X_BE``: pose of E in the robot base frame B (the flange pose a robot reports).
    Frames that are not body frames (fixed-offset frames) are composed with their fixed pose in
    their body.
    """

    def __init__(self, plant: MultibodyPlant, base_frame_name: str, ee_frame_name: str,
                 model_instance: ModelInstanceIndex | None = None):
        super().__init__()
        if not isinstance(plant, MultibodyPlant) or not plant.is_finalized():
            raise ValueError("plant: expected a finalized MultibodyPlant, got "
                             f"{type(plant).__name__}")
        frame_B = _check_frame(plant, base_frame_name, "base_frame_name", model_instance)
        frame_E = _check_frame(plant, ee_frame_name, "ee_frame_name", model_instance)
        # Body index and fixed pose of each frame in its body, resolved once.
        self._B = (int(frame_B.body().index()), frame_B.GetFixedPoseInBodyFrame().GetAsMatrix4())
        self._E = (int(frame_E.body().index()), frame_E.GetFixedPoseInBodyFrame().GetAsMatrix4())
        self._body_poses_port = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()]))
        self._X_WE_port = self.DeclareVectorOutputPort("X_WE", 12, self._CalcX_WE)
        self._X_BE_port = self.DeclareVectorOutputPort("X_BE", 12, self._CalcX_BE)

    def get_body_poses_input_port(self):
        return self._body_poses_port

    def get_X_WE_output_port(self):
        return self._X_WE_port

    def get_X_BE_output_port(self):
        return self._X_BE_port

    @staticmethod
    def _frame_pose(poses, frame) -> np.ndarray:
        body_index, X_BodyF = frame
        return poses[body_index].GetAsMatrix4() @ X_BodyF

    def _CalcX_WE(self, context, output) -> None:
        poses = self._body_poses_port.Eval(context)
        output.SetFromVector(pose_to_vector(self._frame_pose(poses, self._E)))

    def _CalcX_BE(self, context, output) -> None:
        poses = self._body_poses_port.Eval(context)  # (one conversion of the list to Python)
        X_WB = self._frame_pose(poses, self._B)
        X_WE = self._frame_pose(poses, self._E)
        output.SetFromVector(pose_to_vector(inverse(X_WB) @ X_WE))

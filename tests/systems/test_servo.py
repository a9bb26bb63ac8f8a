"""VisualServoController: phases, IBVS command, degraded cases, closed loop with an ideal arm."""

import math

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput
from scipy.linalg import expm

from handeye_drake.estimation.se3 import (
    inverse,
    make_transform,
    pose_to_vector,
    rotation_exp,
    skew,
    vector_to_pose,
)
from handeye_drake.systems.camera import HandEyeCamera
from handeye_drake.systems.servo import (
    STATUS_INVALID_ESTIMATE,
    STATUS_OK,
    STATUS_TOO_FEW_VISIBLE,
    SelfCalibrationMotion,
    VisualServoController,
)
from handeye_drake.vision import (
    CameraIntrinsics,
    end_effector_interaction_matrix,
    ibvs_twist,
    project_points,
)

PERIOD = 0.05
CAM = CameraIntrinsics(alpha_u=800.0, alpha_v=800.0, u0=320.0, v0=240.0, width=640, height=480)
P_TQ = np.array([[-0.05, -0.05, 0], [0.05, -0.05, 0], [0.05, 0.05, 0], [-0.05, 0.05, 0],
                 [0.0, 0.0, -0.03]])
X_WT = make_transform(np.eye(3), [0.0, 0.0, 0.6])  # desired camera pose: the world frame
X_EC = make_transform(rotation_exp([0.1, -0.2, 0.3]), [0.05, -0.02, 0.1])
X_CE = inverse(X_EC)
X_WE_DESIRED = X_CE


def twist_exp(V):
    M = np.zeros((4, 4))
    M[:3, :3] = skew(V[:3])
    M[:3, 3] = V[3:]
    return expm(M)


def measure(X_WE):
    """Noise-free (uv N×2, Z N, X_CT) seen from end-effector pose X_WE."""
    X_CT = inverse(X_WE @ X_EC) @ X_WT
    p_CQ = P_TQ @ X_CT[:3, :3].T + X_CT[:3, 3]
    return project_points(p_CQ, CAM)[0], p_CQ[:, 2], X_CT


UV_STAR = measure(X_WE_DESIRED)[0]
X_WE_START = X_WE_DESIRED @ twist_exp([0.05, -0.04, 0.03, 0.02, 0.015, -0.03])


def servo_with_fixed_inputs(uv, visible, X_CT, X_CE_estimate, **kwargs):
    """Runs the servo alone with constant inputs; returns (diagram, servo, loggers)."""
    args = dict(intrinsics=CAM, p_TQ=P_TQ, desired_features=UV_STAR.reshape(-1), gain=1.0,
                period=PERIOD)
    args.update(kwargs)
    builder = DiagramBuilder()
    servo = builder.AddSystem(VisualServoController(**args))
    for name, value in (("features", np.reshape(uv, -1)), ("visible", visible),
                        ("X_CT_measured", pose_to_vector(X_CT)),
                        ("X_CE_estimate", np.asarray(X_CE_estimate, float).reshape(-1)
                         if np.size(X_CE_estimate) == 12 else pose_to_vector(X_CE_estimate))):
        source = builder.AddSystem(ConstantVectorSource(np.asarray(value, float)))
        builder.Connect(source.get_output_port(), servo.GetInputPort(name))
    loggers = {name: LogVectorOutput(servo.GetOutputPort(name), builder, PERIOD)
               for name in ("V_WE_E_command", "phase", "feature_error", "status")}
    return builder.Build(), servo, loggers


def run(diagram, loggers, t_final):
    simulator = Simulator(diagram)
    simulator.AdvanceTo(t_final)
    context = simulator.get_context()
    first = next(iter(loggers.values())).FindLog(context)
    return first.sample_times(), {name: log.FindLog(context).data().T
                                  for name, log in loggers.items()}


def test_self_calibration_phases_and_twists():
    motions = [SelfCalibrationMotion(axis_E=(1, 0, 0), angle=0.2, pivot_E=(0, 0, 0.5),
                                     duration=0.2),
               SelfCalibrationMotion(axis_E=(0, 1, 1), angle=-0.3, pivot_E=(0.1, 0, 0.4),
                                     duration=0.3)]
    uv, Z, X_CT = measure(X_WE_START)
    diagram, servo, loggers = servo_with_fixed_inputs(uv, np.ones(5), X_CT, X_CE,
                                                      self_calibration_motions=motions)
    assert servo.num_phases == 3 and servo.servo_start_time == pytest.approx(0.5)
    times, logs = run(diagram, loggers, 1.0)
    phase = logs["phase"][:, 0]
    # A discrete update at sample j holds its result on (t_j, t_j+1]: the value logged at t_k
    # (k ≥ 1) is the one computed at sample k − 1; at t = 0 it is the initialization update's.
    t = np.maximum(np.round(times / PERIOD).astype(int) - 1, 0)
    expected_phase = np.where(t < 4, 0, np.where(t < 10, 1, 2))
    np.testing.assert_array_equal(phase, expected_phase)
    V = logs["V_WE_E_command"]
    w0 = 0.2 / 0.2 * np.array([1.0, 0, 0])
    w1 = -0.3 / 0.3 * np.array([0, 1, 1]) / math.sqrt(2)
    np.testing.assert_allclose(V[t < 4] - np.r_[w0, -np.cross(w0, [0, 0, 0.5])], 0.0,
                               atol=1e-15)
    np.testing.assert_allclose(V[(t >= 4) & (t < 10)] - np.r_[w1, -np.cross(w1, [0.1, 0, 0.4])],
                               0.0, atol=1e-15)
    # Each motion is executed exactly: commanded rotation integrated over its phase = its angle.
    one_per_sample = np.unique(t, return_index=True)[1]
    V_unique, phase_unique = V[one_per_sample], phase[one_per_sample]
    np.testing.assert_allclose(PERIOD * V_unique[phase_unique == 0, :3].sum(axis=0),
                               [0.2, 0, 0], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(PERIOD * V_unique[phase_unique == 1, :3].sum(0)),
                               0.3, atol=1e-12)
    # Then the servo law takes over.
    V_ibvs = ibvs_twist(uv, UV_STAR, Z, CAM, X_CE, 1.0)
    assert (t >= 10).sum() >= 10
    np.testing.assert_allclose(V[t >= 10] - V_ibvs, 0.0, atol=1e-12 * np.abs(V_ibvs).max())
    assert np.all(logs["status"] == STATUS_OK)
    assert servo.phase_at(0.0) == 0 and servo.phase_at(0.2) == 1 and servo.phase_at(0.5) == 2
    assert servo.phase_at(0.2 - 1e-12) == 1  # sample times off by rounding land in the right phase


def test_the_commanded_pose_integrates_the_held_twist():
    """X_BE_desired(t) = X_k · exp(V_k (t − t_k)): along a self-calibration motion, the start
    pose moved by the motion's screw for t (its rotation about the pivot, exactly); then the
    servo's twists, period after period."""
    motion = SelfCalibrationMotion(axis_E=(0, 1, 1), angle=-0.3, pivot_E=(0.1, 0, 0.4),
                                   duration=0.3)
    X0 = make_transform(rotation_exp([0.3, -0.2, 0.1]), [0.4, -0.1, 0.5])
    uv, Z, X_CT = measure(X_WE_START)
    diagram, servo, _ = servo_with_fixed_inputs(uv, np.ones(5), X_CT, X_CE,
                                                self_calibration_motions=[motion],
                                                X_BE_initial=X0)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    servo_context = servo.GetMyContextFromRoot(context)
    port = servo.get_X_BE_desired_output_port()
    simulator.Initialize()
    np.testing.assert_allclose(port.Eval(servo_context).GetAsMatrix4(), X0, atol=1e-15)
    V = motion.twist_E()
    for t in (0.02, 0.05, 0.17, 0.3):  # inside periods and on their boundaries
        simulator.AdvanceTo(t)
        np.testing.assert_allclose(port.Eval(servo_context).GetAsMatrix4(),
                                   X0 @ twist_exp(V * t), atol=1e-13)
    # The pivot does not move, and the hand turned by the motion's angle.
    X_end = port.Eval(servo_context).GetAsMatrix4()
    p_pivot = X0[:3, :3] @ np.array([0.1, 0, 0.4]) + X0[:3, 3]
    np.testing.assert_allclose(X_end[:3, :3] @ np.array([0.1, 0, 0.4]) + X_end[:3, 3], p_pivot,
                               atol=1e-13)
    assert np.degrees(np.arccos((np.trace(X0[:3, :3].T @ X_end[:3, :3]) - 1) / 2)) == \
        pytest.approx(np.degrees(0.3), abs=1e-9)
    # The servo phase: the twist held on (t_k, t_k+1] moves the pose reached at t_k.
    simulator.AdvanceTo(0.5)
    X_k = port.Eval(servo_context).GetAsMatrix4()
    V_k = servo.get_command_output_port().Eval(servo_context)
    assert np.linalg.norm(V_k) > 0
    simulator.AdvanceTo(0.5 + 0.6 * PERIOD)
    np.testing.assert_allclose(port.Eval(servo_context).GetAsMatrix4(),
                               X_k @ twist_exp(V_k * 0.6 * PERIOD), atol=1e-13)
    # SetDesiredPose restarts it.
    servo.SetDesiredPose(servo.GetMyMutableContextFromRoot(context), np.eye(4))
    np.testing.assert_allclose(port.Eval(servo_context).GetAsMatrix4(), np.eye(4), atol=1e-15)


def test_servo_command_matches_ibvs_and_feature_error():
    uv, Z, X_CT = measure(X_WE_START)
    diagram, servo, loggers = servo_with_fixed_inputs(uv, np.ones(5), X_CT, X_CE, gain=0.7)
    simulator = Simulator(diagram)
    simulator.Initialize()  # the initialization update makes the outputs valid at t = 0
    context = servo.GetMyContextFromRoot(simulator.get_context())
    V = servo.GetOutputPort("V_WE_E_command").Eval(context)
    np.testing.assert_allclose(V, ibvs_twist(uv, UV_STAR, Z, CAM, X_CE, 0.7), rtol=1e-12)
    rms = math.sqrt(np.mean(np.sum((uv - UV_STAR) ** 2, axis=1)))
    assert servo.GetOutputPort("feature_error").Eval(context)[0] == pytest.approx(rms, rel=1e-12)
    assert rms > 5.0
    assert servo.GetOutputPort("phase").Eval(context)[0] == 0.0  # no self-calibration: servo
    assert servo.GetOutputPort("status").Eval(context)[0] == STATUS_OK
    # One step of the commanded twist reduces the error by exp(−λ dt) to first order.
    dt = 1e-3
    uv1 = measure(X_WE_START @ twist_exp(dt * V))[0]
    ratio = np.linalg.norm(uv1 - UV_STAR) / np.linalg.norm(uv - UV_STAR)
    assert ratio == pytest.approx(math.exp(-0.7 * dt), abs=1e-4)


def test_too_few_visible_points_gives_zero_command():
    uv, Z, X_CT = measure(X_WE_START)
    visible = np.array([1.0, 0.0, 0.0, 1.0, 0.0])
    diagram, servo, loggers = servo_with_fixed_inputs(uv, visible, X_CT, X_CE)
    times, logs = run(diagram, loggers, 0.2)
    np.testing.assert_array_equal(logs["V_WE_E_command"], 0.0)
    assert np.all(logs["status"] == STATUS_TOO_FEW_VISIBLE)
    rms_two = math.sqrt(np.mean(np.sum((uv - UV_STAR)[[0, 3]] ** 2, axis=1)))
    np.testing.assert_allclose(logs["feature_error"], rms_two, rtol=1e-12)
    # Three visible points are enough (default min_visible = 3)...
    visible[1] = 1.0
    diagram, servo, loggers = servo_with_fixed_inputs(uv, visible, X_CT, X_CE)
    times, logs = run(diagram, loggers, 0.1)
    assert np.all(logs["status"] == STATUS_OK)
    np.testing.assert_allclose(
        logs["V_WE_E_command"][-1],
        ibvs_twist(uv, UV_STAR, Z, CAM, X_CE, 1.0, visible=visible), rtol=1e-12)
    # ... unless more are required.
    diagram, servo, loggers = servo_with_fixed_inputs(uv, visible, X_CT, X_CE, min_visible=4)
    times, logs = run(diagram, loggers, 0.1)
    assert np.all(logs["status"] == STATUS_TOO_FEW_VISIBLE)
    np.testing.assert_array_equal(logs["V_WE_E_command"], 0.0)


def test_invalid_estimate_gives_zero_command():
    uv, Z, X_CT = measure(X_WE_START)
    diagram, servo, loggers = servo_with_fixed_inputs(uv, np.ones(5), X_CT, np.zeros(12))
    times, logs = run(diagram, loggers, 0.1)
    assert np.all(logs["status"] == STATUS_INVALID_ESTIMATE)
    np.testing.assert_array_equal(logs["V_WE_E_command"], 0.0)


def test_saturation_scales_whole_twist():
    uv, Z, X_CT = measure(X_WE_START)
    diagram, servo, loggers = servo_with_fixed_inputs(uv, np.ones(5), X_CT, X_CE, gain=50.0,
                                                      max_angular_speed=0.1,
                                                      max_linear_speed=0.02)
    times, logs = run(diagram, loggers, 0.05)
    V = logs["V_WE_E_command"][-1]
    V_free = ibvs_twist(uv, UV_STAR, Z, CAM, X_CE, 50.0)
    assert np.linalg.norm(V[:3]) <= 0.1 + 1e-12 and np.linalg.norm(V[3:]) <= 0.02 + 1e-12
    assert max(np.linalg.norm(V[:3]) / 0.1, np.linalg.norm(V[3:]) / 0.02) == pytest.approx(1.0)
    scale = np.linalg.norm(V) / np.linalg.norm(V_free)
    assert scale < 1
    np.testing.assert_allclose(V, scale * V_free, rtol=1e-12)


class IdealArm(LeafSystem):
    """Test plant: the end-effector follows the commanded body twist exactly, sampled."""

    def __init__(self, X_WE0, period):
        LeafSystem.__init__(self)
        self._V = self.DeclareVectorInputPort("V_WE_E", 6)
        self._x = self.DeclareDiscreteState(pose_to_vector(X_WE0))
        self._period = period
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._Step)
        self.DeclareStateOutputPort("X_WE", self._x)

    def _Step(self, context, discrete_state):
        X = vector_to_pose(context.get_discrete_state(self._x).get_value())
        X = X @ twist_exp(self._period * self._V.Eval(context))
        discrete_state.get_mutable_vector(self._x).SetFromVector(pose_to_vector(X))


@pytest.mark.parametrize("X_CE_estimate, converges_exponentially", [
    (X_CE, True),
    # A rough hand-eye estimate (5°, 1 cm off) still converges, more slowly and curved.
    (X_CE @ make_transform(rotation_exp([0.0, 0.087, 0.0]), [0.01, 0.0, 0.0]), False),
])
def test_closed_loop_with_camera_converges(X_CE_estimate, converges_exponentially):
    gain = 2.0
    motions = [SelfCalibrationMotion(axis_E=(1, 0, 0), angle=0.05, pivot_E=(0.0, 0.0, 0.0),
                                     duration=0.1)]
    builder = DiagramBuilder()
    camera = builder.AddSystem(HandEyeCamera(CAM, X_EC, P_TQ, X_WT, PERIOD))
    servo = builder.AddSystem(VisualServoController(
        CAM, P_TQ, UV_STAR, gain, PERIOD, self_calibration_motions=motions))
    arm = builder.AddSystem(IdealArm(X_WE_START, PERIOD))
    estimate = builder.AddSystem(ConstantVectorSource(pose_to_vector(X_CE_estimate)))
    builder.Connect(arm.GetOutputPort("X_WE"), camera.GetInputPort("X_WE"))
    for name in ("features", "visible", "X_CT_measured"):
        builder.Connect(camera.GetOutputPort(name), servo.GetInputPort(name))
    builder.Connect(estimate.get_output_port(), servo.GetInputPort("X_CE_estimate"))
    builder.Connect(servo.GetOutputPort("V_WE_E_command"), arm.GetInputPort("V_WE_E"))
    error_log = LogVectorOutput(servo.GetOutputPort("feature_error"), builder, PERIOD)
    status_log = LogVectorOutput(servo.GetOutputPort("status"), builder, PERIOD)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.AdvanceTo(2.5)
    context = simulator.get_context()
    times = error_log.FindLog(context).sample_times()
    error = error_log.FindLog(context).data()[0]
    status = status_log.FindLog(context).data()[0]
    # At t = 0 the camera's first image is not there yet (simultaneous initialization updates).
    assert status[0] == STATUS_TOO_FEW_VISIBLE and np.all(status[1:] == STATUS_OK)
    servo_on = times >= 0.3  # self-calibration done and the loop's two-sample latency flushed
    e = error[servo_on]
    assert e[0] > 5.0
    assert np.all(np.diff(e) <= 1e-9)  # monotone decrease
    decay = e[-1] / e[0]
    elapsed = times[servo_on][-1] - times[servo_on][0]
    if converges_exponentially:
        # Camera → servo → arm, all sampled at the same period, is a two-sample latency:
        # e_{k+1} = e_k − λ·dt·e_{k−2}, so e decays like z^k with z the dominant root of
        # z³ − z² + λ·dt (≈ e^{−1.43 λ t} here, faster than the continuous-time e^{−λ t}).
        z = max(abs(np.roots([1.0, -1.0, 0.0, gain * PERIOD])))
        assert math.log(decay) / elapsed == pytest.approx(math.log(z) / PERIOD, rel=0.02)
    else:
        assert decay < 0.05


@pytest.mark.parametrize("kwargs, match", [
    (dict(intrinsics=None), "intrinsics"),
    (dict(p_TQ=P_TQ[:2]), "p_TQ.*at least 3"),
    (dict(p_TQ=np.zeros((5, 2))), "p_TQ"),
    (dict(desired_features=np.zeros(8)), "desired_features"),
    (dict(desired_features=np.full(10, np.nan)), "desired_features"),
    (dict(gain=0.0), "gain"),
    (dict(period=-0.1), "period"),
    (dict(max_angular_speed=0.0), "max_angular_speed"),
    (dict(max_linear_speed=-1.0), "max_linear_speed"),
    (dict(min_visible=2), "min_visible"),
    (dict(min_visible=6), "min_visible"),
    (dict(min_visible="three"), "min_visible"),
    (dict(self_calibration_motions=[(1, 0, 0)]), r"self_calibration_motions\[0\]"),
    (dict(self_calibration_motions=[SelfCalibrationMotion((1, 0, 0), 0.1, duration=0.12)]),
     r"self_calibration_motions\[0\]\.duration.*whole number of periods"),
    (dict(self_calibration_motions=[SelfCalibrationMotion((1, 0, 0), 0.1, duration=0.1),
                                    SelfCalibrationMotion((0, 1, 0), 2.0, duration=0.1)]),
     r"self_calibration_motions\[1\].*exceeds max_angular_speed"),
])
def test_constructor_validation(kwargs, match):
    args = dict(intrinsics=CAM, p_TQ=P_TQ, desired_features=UV_STAR.reshape(-1), gain=1.0,
                period=PERIOD)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        VisualServoController(**args)


def test_ports_and_infinite_limits():
    servo = VisualServoController(CAM, P_TQ, UV_STAR, 1.0, PERIOD, max_angular_speed=math.inf,
                                  max_linear_speed=math.inf)
    sizes = {servo.get_input_port(i).get_name(): servo.get_input_port(i).size()
             for i in range(servo.num_input_ports())}
    assert sizes == {"features": 10, "visible": 5, "X_CT_measured": 12, "X_CE_estimate": 12}
    sizes = {servo.get_output_port(i).get_name(): servo.get_output_port(i).size()
             for i in range(servo.num_output_ports())}
    assert sizes == {"V_WE_E_command": 6, "phase": 1, "feature_error": 1, "status": 1,
                     "X_BE_desired": 0}  # (abstract: a RigidTransform)
    assert not servo.HasAnyDirectFeedthrough()


@pytest.mark.parametrize("port", ["features", "visible", "X_CT_measured"])
def test_nan_input_raises_naming_the_input(port):
    uv, Z, X_CT = measure(X_WE_START)
    uv, visible, X_CT = uv.copy(), np.ones(5), X_CT.copy()
    if port == "features":
        uv[0, 0] = np.nan
    elif port == "visible":
        visible[2] = np.inf
    else:
        X_CT[2, 3] = np.nan
    diagram, servo, loggers = servo_with_fixed_inputs(uv, visible, X_CT, X_CE)
    with pytest.raises(Exception, match=f"{port} input.*NaN or infinite"):
        Simulator(diagram).Initialize()


def test_end_effector_matrix_is_what_the_servo_inverts():
    # Sanity link between the pure law and the paper's Lᵀ: L_E · V = −λ (s − s*) when s − s* is
    # in the range of L_E (here: 3 points, L_E square and invertible).
    uv, Z, _ = measure(X_WE_START)
    L = end_effector_interaction_matrix(uv[:3], Z[:3], CAM, X_CE)
    V = ibvs_twist(uv[:3], UV_STAR[:3], Z[:3], CAM, X_CE, 1.5)
    np.testing.assert_allclose(L @ V, -1.5 * (uv[:3] - UV_STAR[:3]).reshape(-1), rtol=1e-8)


@pytest.mark.parametrize("visible", [[1, 1, 1, 1, 1], [1, 0, 1, 1, 1]])
def test_per_sample_law_equals_ibvs_twist_and_saturation(visible):
    """The servo's update compiles ibvs_twist + saturate_twist (no per-sample checks of the
    arguments): their result to rounding, saturated or not."""
    from handeye_drake.vision import saturate_twist
    uv, Z, X_CT = measure(X_WE_START)
    uv = uv + np.random.default_rng(3).normal(scale=2.0, size=uv.shape)
    usable = np.array(visible, bool)
    for max_w, max_v in ((math.inf, math.inf), (0.01, 0.005)):
        servo = VisualServoController(CAM, P_TQ, UV_STAR.reshape(-1), 0.7, PERIOD,
                                      max_angular_speed=max_w, max_linear_speed=max_v)
        expected = saturate_twist(ibvs_twist(uv, UV_STAR, Z, CAM, X_CE, 0.7, visible=usable),
                                  max_w, max_v)
        ours = servo._ServoTwist(uv.reshape(-1), Z, pose_to_vector(X_CE), usable)
        np.testing.assert_allclose(ours, expected, rtol=1e-12, atol=1e-15)
        assert np.max(np.abs(ours - expected)) <= 1e-12 * np.max(np.abs(expected))

"""HandEyeCamera as a Drake system: exact projection, noise statistics, seeds, validation."""

import math

import numpy as np
import pytest
from pydrake.common import RandomGenerator
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import AddRandomInputs, ConstantVectorSource, LogVectorOutput

from handeye_drake.estimation.se3 import (
    inverse,
    make_transform,
    pose_to_vector,
    rotation_exp,
    rotation_log,
    vector_to_pose,
)
from handeye_drake.estimation.validation import rotation_defect
from handeye_drake.systems.camera import HandEyeCamera
from handeye_drake.vision import CameraIntrinsics, project_points

PERIOD = 0.05
CAM = CameraIntrinsics(alpha_u=800.0, alpha_v=700.0, theta=math.radians(85), u0=320.0, v0=240.0,
                       width=640, height=480)
X_EC = make_transform(rotation_exp([0.1, -0.2, 0.3]), [0.05, -0.02, 0.1])
X_WE = make_transform(rotation_exp([0.3, 0.1, -0.4]), [0.4, -0.1, 0.3])
X_WC = X_WE @ X_EC
# Target 0.6 ahead of the camera, tilted. Points 0-3 visible, 4 outside the image (in front),
# 5 behind the camera.
X_CT_true = make_transform(rotation_exp([0.2, -0.1, 0.05]), [0.02, -0.01, 0.6])
X_WT = X_WC @ X_CT_true
P_TQ = np.array([[-0.05, -0.05, 0], [0.05, -0.05, 0], [0.05, 0.05, 0], [-0.05, 0.05, 0],
                 [0.8, 0.0, 0.0], [0.0, 0.0, -1.0]])


def expected_projection():
    p_CQ = P_TQ @ X_CT_true[:3, :3].T + X_CT_true[:3, 3]
    return project_points(p_CQ, CAM)


def build(noise=True, **camera_kwargs):
    builder = DiagramBuilder()
    camera = builder.AddSystem(HandEyeCamera(CAM, X_EC, P_TQ, X_WT, PERIOD, **camera_kwargs))
    source = builder.AddSystem(ConstantVectorSource(pose_to_vector(X_WE)))
    builder.Connect(source.get_output_port(), camera.GetInputPort("X_WE"))
    if noise:
        assert AddRandomInputs(PERIOD, builder) == 2
    loggers = {name: LogVectorOutput(camera.GetOutputPort(name), builder, PERIOD)
               for name in ("features", "visible", "X_CT_measured", "X_WC")}
    diagram = builder.Build()
    return diagram, camera, loggers


def run(diagram, loggers, steps, seed=None):
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    if seed is not None:
        diagram.SetRandomContext(context, RandomGenerator(seed))
    simulator.AdvanceTo(steps * PERIOD)
    return {name: log.FindLog(context).data().T for name, log in loggers.items()}


def test_noiseless_outputs_are_exact_projection():
    diagram, camera, loggers = build(noise=False)
    # Valid right after initialization (initialization update), before any step.
    simulator = Simulator(diagram)
    simulator.Initialize()
    context = camera.GetMyContextFromRoot(simulator.get_context())
    uv, in_front, in_image = expected_projection()
    assert in_image.tolist() == [True] * 4 + [False, False] and in_front[4] and not in_front[5]
    np.testing.assert_allclose(camera.GetOutputPort("features").Eval(context), uv.reshape(-1),
                               atol=1e-9)
    assert uv[4, 0] > CAM.width and np.all(uv[5] == 0)  # invisible: noiseless if in front, else 0
    np.testing.assert_array_equal(camera.GetOutputPort("visible").Eval(context),
                                  [1, 1, 1, 1, 0, 0])
    np.testing.assert_allclose(vector_to_pose(camera.GetOutputPort("X_CT_measured").Eval(context)),
                               X_CT_true, atol=1e-12)
    np.testing.assert_allclose(vector_to_pose(camera.GetOutputPort("X_WC").Eval(context)), X_WC,
                               atol=1e-12)
    # Also after many periods, and whatever drives the (unused) noise ports.
    diagram, camera, loggers = build(noise=True)
    logs = run(diagram, loggers, 20, seed=3)
    assert logs["features"].shape[0] >= 20
    np.testing.assert_allclose(logs["features"], np.tile(uv.reshape(-1), (len(logs["features"]),
                                                                          1)), atol=1e-9)


def test_pixel_noise_statistics():
    sigma = 2.0
    diagram, camera, loggers = build(pixel_sigma=sigma)
    logs = run(diagram, loggers, 400, seed=11)
    uv, _, _ = expected_projection()
    residual = logs["features"] - uv.reshape(-1)
    visible = residual[:, :8]
    assert visible.std() == pytest.approx(sigma, rel=0.1)
    assert abs(visible.mean()) < 0.1 * sigma
    # Each image gets a fresh sample (the logger runs at the camera's rate).
    assert np.all(np.abs(np.diff(visible, axis=0)).max(axis=1) > 0)
    # Consecutive samples are uncorrelated.
    assert abs(np.corrcoef(visible[:-1, 0], visible[1:, 0])[0, 1]) < 0.2
    # Invisible points carry no noise; the pose is untouched when its sigmas are 0.
    np.testing.assert_allclose(residual[:, 8:], 0.0, atol=1e-9)
    np.testing.assert_allclose(logs["X_CT_measured"] - pose_to_vector(X_CT_true), 0.0,
                               atol=1e-12)


def test_seed_reproducibility():
    diagram, camera, loggers = build(pixel_sigma=1.0, rotation_sigma=0.01, translation_sigma=0.01)
    a = run(diagram, loggers, 10, seed=7)
    b = run(diagram, loggers, 10, seed=7)
    c = run(diagram, loggers, 10, seed=8)
    for name in ("features", "X_CT_measured"):
        np.testing.assert_array_equal(a[name], b[name])
        assert np.abs(a[name] - c[name]).max() > 1e-3


@pytest.mark.parametrize("model", ["paper", "so3"])
def test_pose_noise_models(model):
    rotation_sigma, translation_sigma = 0.02, 0.005
    diagram, camera, loggers = build(pose_noise_model=model, rotation_sigma=rotation_sigma,
                                     translation_sigma=translation_sigma)
    logs = run(diagram, loggers, 200, seed=5)
    X = logs["X_CT_measured"]
    defects = [rotation_defect(x[:9].reshape(3, 3)) for x in X]
    dp = X[:, 9:] - X_CT_true[:3, 3]
    assert dp.std() == pytest.approx(translation_sigma, rel=0.1)
    if model == "paper":
        assert min(defects) > 1e-3  # additive coefficient noise: not a rotation any more
        dR = X[:, :9] - X_CT_true[:3, :3].reshape(9)
        assert dR.std() == pytest.approx(rotation_sigma, rel=0.1)
    else:
        assert max(defects) < 1e-12
        rotvecs = np.array([
            rotation_log(x[:9].reshape(3, 3) @ X_CT_true[:3, :3].T) for x in X])
        assert rotvecs.std() == pytest.approx(rotation_sigma, rel=0.1)
    # The pixels are noise-free (pixel_sigma = 0) and the true pose is still reported exactly.
    np.testing.assert_allclose(logs["X_WC"] - pose_to_vector(X_WC), 0.0, atol=1e-12)


def test_check_target_visible():
    camera = HandEyeCamera(CAM, X_EC, P_TQ[:4], RigidTransform(X_WT), PERIOD)
    assert camera.CheckTargetVisible(X_WE).tolist() == [True] * 4
    assert camera.CheckTargetVisible(RigidTransform(X_WE)).all()
    # Turn the camera around: the target is behind it.
    X_WE_away = X_WC @ make_transform(rotation_exp([0.0, math.pi, 0.0]), [0, 0, 0]) @ inverse(X_EC)
    with pytest.raises(ValueError, match=r"only 0 of 4.*behind the camera: \[0, 1, 2, 3\]"):
        camera.CheckTargetVisible(X_WE_away)
    full = HandEyeCamera(CAM, X_EC, P_TQ, X_WT, PERIOD)
    with pytest.raises(ValueError, match=r"only 4 of 6.*behind the camera: \[5\].*image: \[4\]"):
        full.CheckTargetVisible(X_WE)
    assert full.CheckTargetVisible(X_WE, min_visible=4).sum() == 4


def test_unconnected_noise_with_nonzero_sigma_raises():
    diagram, camera, loggers = build(noise=False, pixel_sigma=1.0)
    simulator = Simulator(diagram)
    with pytest.raises(Exception, match="pixel_noise.*not connected"):
        simulator.Initialize()


@pytest.mark.parametrize("kwargs, match", [
    (dict(intrinsics=CAM.K), "intrinsics"),
    (dict(X_EC=np.diag([2.0, 1.0, 1.0, 1.0])), "X_EC.*not a rotation"),
    (dict(X_WT=np.eye(3)), "X_WT"),
    (dict(p_TQ=np.zeros((4, 2))), "p_TQ"),
    (dict(p_TQ=[[0.0, np.nan, 0.0]]), "p_TQ"),
    (dict(period=0.0), "period"),
    (dict(pixel_sigma=-1.0), "pixel_sigma"),
    (dict(rotation_sigma=-0.1), "rotation_sigma"),
    (dict(translation_sigma=float("nan")), "translation_sigma"),
    (dict(pose_noise_model="rpy"), "pose_noise_model"),
])
def test_constructor_validation(kwargs, match):
    args = dict(intrinsics=CAM, X_EC=X_EC, p_TQ=P_TQ, X_WT=X_WT, period=PERIOD)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        HandEyeCamera(**args)


def test_ports():
    camera = HandEyeCamera(CAM, X_EC, P_TQ, X_WT, PERIOD)
    sizes = {camera.get_input_port(i).get_name(): camera.get_input_port(i).size()
             for i in range(camera.num_input_ports())}
    assert sizes == {"X_WE": 12, "pixel_noise": 12, "pose_noise": 12}
    sizes = {camera.get_output_port(i).get_name(): camera.get_output_port(i).size()
             for i in range(camera.num_output_ports())}
    assert sizes == {"features": 12, "visible": 6, "X_CT_measured": 12, "X_WC": 12, "X_BE": 12}
    with pytest.raises(ValueError, match="use get_X_WE_input_port"):
        camera.get_body_poses_input_port()
    # Outputs read state only: no direct feedthrough, so feedback loops are not algebraic.
    assert not camera.HasAnyDirectFeedthrough()


@pytest.mark.parametrize("model", ["paper", "so3"])
def test_per_sample_path_equals_project_points_and_apply_pose_noise(model):
    """The camera's update inlines project_points / apply_pose_noise (no per-sample checks): it
    must produce their results from the same noise samples, to rounding (numpy's products go
    through BLAS, whose kernels and so whose last bits depend on the CPU)."""
    from handeye_drake.vision.camera_model import apply_pose_noise
    rng = np.random.default_rng(7)
    camera = HandEyeCamera(CAM, X_EC, P_TQ, X_WT, PERIOD, pixel_sigma=0.7,
                           pose_noise_model=model, rotation_sigma=0.01, translation_sigma=0.002)
    context = camera.CreateDefaultContext()
    pixel_noise, pose_noise = rng.normal(size=2 * len(P_TQ)), rng.normal(size=12)
    camera.GetInputPort("X_WE").FixValue(context, pose_to_vector(X_WE))
    camera.GetInputPort("pixel_noise").FixValue(context, pixel_noise)
    camera.GetInputPort("pose_noise").FixValue(context, pose_noise)
    state = context.get_discrete_state().Clone()
    camera._UpdateImage(context, state)
    X_CT = inverse(X_WE @ X_EC) @ X_WT
    uv, _, in_image = project_points(P_TQ @ X_CT[:3, :3].T + X_CT[:3, 3], CAM)
    uv[in_image] += 0.7 * pixel_noise.reshape(-1, 2)[in_image]
    np.testing.assert_allclose(state.get_vector(0).get_value(), uv.reshape(-1), rtol=1e-14,
                               atol=1e-12)
    np.testing.assert_array_equal(state.get_vector(1).get_value(), in_image.astype(float))
    np.testing.assert_allclose(state.get_vector(2).get_value(), pose_to_vector(
        apply_pose_noise(X_CT, pose_noise, model, 0.01, 0.002)), rtol=1e-14, atol=1e-15)


def test_with_a_plant_it_reads_the_body_poses_as_the_pose_sensor_does():
    """Given the arm's plant, the camera samples the end-effector pose from its body poses —
    bit-identical to the X_WE and X_BE of an EndEffectorPoseSensor, X_BE held with the image."""
    from handeye_drake.systems.arm import UR5E_HOME_Q, EndEffectorPoseSensor, add_arm
    builder = DiagramBuilder()
    X_WB = make_transform(rotation_exp([0.0, 0.0, 0.4]), [0.1, 0.2, 0.05])
    arm = add_arm(builder, X_WB=X_WB)
    camera = builder.AddSystem(HandEyeCamera(CAM, X_EC, P_TQ, X_WT, PERIOD, plant=arm.plant))
    sensor = builder.AddSystem(EndEffectorPoseSensor(arm.plant, "base_link", "tool0"))
    for system in (camera, sensor):
        builder.Connect(arm.plant.get_body_poses_output_port(),
                        system.get_body_poses_input_port())
    with pytest.raises(ValueError, match="use get_body_poses_input_port"):
        camera.get_X_WE_input_port()
    simulator = Simulator(builder.Build())
    context = simulator.get_mutable_context()
    q = UR5E_HOME_Q + np.array([0.1, -0.2, 0.15, 0.05, -0.1, 0.3])
    arm.plant.SetPositions(arm.plant.GetMyMutableContextFromRoot(context), q)
    simulator.Initialize()  # the camera's initialization sample (the plant has not stepped)
    camera_context = camera.GetMyContextFromRoot(context)
    sensor_context = sensor.GetMyContextFromRoot(context)
    X_WE_sensor = sensor.get_X_WE_output_port().Eval(sensor_context)
    np.testing.assert_array_equal(camera.get_X_BE_output_port().Eval(camera_context),
                                  sensor.get_X_BE_output_port().Eval(sensor_context))
    np.testing.assert_array_equal(camera.get_X_WC_output_port().Eval(camera_context),
                                  pose_to_vector(vector_to_pose(X_WE_sensor) @ X_EC))
    # X_BE is the pose in the base, not in the world.
    np.testing.assert_allclose(X_WB @ vector_to_pose(
        camera.get_X_BE_output_port().Eval(camera_context)), vector_to_pose(X_WE_sensor),
        atol=1e-15)
    with pytest.raises(ValueError, match="ee_frame_name: no frame named 'flange'"):
        HandEyeCamera(CAM, X_EC, P_TQ, X_WT, PERIOD, plant=arm.plant, ee_frame_name="flange")


@pytest.mark.parametrize("noise", ["unconnected", "nan", "fixed"])
def test_with_a_plant_its_noise_inputs_are_checked_as_without(noise):
    """The plant path's single compiled call keeps the general path's checks: a noise input
    left unconnected or holding NaN is named; fixed noise enters as it does without a plant."""
    from handeye_drake.systems.arm import add_arm
    builder = DiagramBuilder()
    arm = add_arm(builder)
    X_WE_start = arm.plant.CalcRelativeTransform(
        arm.plant.CreateDefaultContext(), arm.plant.world_frame(),
        arm.plant.GetFrameByName("tool0")).GetAsMatrix4()
    X_WT_seen = X_WE_start @ X_EC @ X_CT_true  # the target in view at the start pose
    camera = builder.AddSystem(HandEyeCamera(CAM, X_EC, P_TQ[:4], X_WT_seen, PERIOD,
                                             pixel_sigma=0.7, plant=arm.plant))
    builder.Connect(arm.plant.get_body_poses_output_port(), camera.get_body_poses_input_port())
    simulator = Simulator(builder.Build())
    context = camera.GetMyMutableContextFromRoot(simulator.get_mutable_context())
    pixel_noise = np.linspace(-1.0, 1.0, 8)
    if noise == "nan":
        pixel_noise[5] = np.nan
    if noise != "unconnected":
        camera.get_pixel_noise_input_port().FixValue(context, pixel_noise)
    if noise == "unconnected":
        with pytest.raises(ValueError, match="pixel_noise input.*not connected"):
            simulator.Initialize()
        return
    if noise == "nan":
        with pytest.raises(ValueError, match="pixel_noise input"):
            simulator.Initialize()
        return
    simulator.Initialize()
    uv = camera.get_features_output_port().Eval(context)
    visible = camera.get_visible_output_port().Eval(context) > 0.5
    X_WE = vector_to_pose(camera.get_X_WC_output_port().Eval(context)) @ inverse(X_EC)
    expected, _, in_image = project_points(
        (inverse(X_WE @ X_EC) @ X_WT_seen @ np.c_[P_TQ[:4], np.ones(4)].T).T[:, :3], CAM)
    np.testing.assert_array_equal(visible, in_image)
    assert visible.any()
    expected[in_image] += 0.7 * pixel_noise.reshape(-1, 2)[in_image]
    np.testing.assert_allclose(uv, expected.reshape(-1), atol=1e-9)

"""The perception-only SceneGraph: the same images as rendering in the plant's SceneGraph, bit
for bit, posed by the plant's body poses only when a camera renders."""

import numpy as np
import pytest
from pydrake.geometry import (
    Box,
    GeometryFrame,
    GeometryInstance,
    PerceptionProperties,
    SceneGraph,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from handeye_drake.estimation.se3 import make_transform
from handeye_drake.systems.arm import UR5E_HOME_Q, add_arm
from handeye_drake.systems.perception_scene import PerceptionScenePoses, \
    add_perception_scene_graph
from handeye_drake.systems.rendered_camera import add_rendered_camera, add_target_geometry, \
    mount_rendered_camera
from handeye_drake.vision.camera_model import CameraIntrinsics
from handeye_drake.vision.detection import detect_target
from handeye_drake.vision.targets import parse_target

CHARUCO = parse_target("charuco:7x5:0.04:0.03:DICT_5X5_100")
INTRINSICS = CameraIntrinsics(alpha_u=300.0, alpha_v=300.0, u0=160.0, v0=120.0, width=320,
                              height=240)
# A camera in the cell looking along −x_W at the arm (x_C = +y_W, y_C = −z_W), 1.8 m away.
R_WC = np.array([[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
X_WC_CELL = make_transform(R_WC, [1.8, 0.0, 0.45])
# The board 0.6 m in front of it, top left, facing it.
X_WT = make_transform(R_WC, [1.2, -0.29, 0.63])
X_EC = make_transform(np.eye(3), [0.0, 0.05, 0.06])
Q_A = UR5E_HOME_Q + np.array([0.3, -0.2, 0.25, 0.1, -0.3, 0.5])
Q_B = UR5E_HOME_Q + np.array([-0.4, 0.15, -0.3, 0.4, 0.2, -0.6])


def build(perception: bool):
    """Arm, board, a cell camera and a flange camera, rendering in the plant's SceneGraph or in
    a perception scene."""
    builder = DiagramBuilder()
    arm = add_arm(builder, q0=UR5E_HOME_Q)
    add_target_geometry(arm.scene_graph, CHARUCO, X_WT)
    scene = arm.scene_graph
    if perception:
        scene = add_perception_scene_graph(builder, arm.plant, arm.scene_graph,
                                           bodies=[arm.plant.GetFrameByName("tool0").body()])
    graph = scene.scene_graph if perception else scene
    cell = add_rendered_camera(builder, graph, graph.world_frame_id(), X_WC_CELL, INTRINSICS,
                               name="cell")
    flange = mount_rendered_camera(builder, scene, arm.plant, "tool0", X_EC, INTRINSICS,
                                   name="flange")
    return builder.Build(), arm, scene, (cell, flange)


def images(built, q):
    diagram, arm, _, cameras = built
    context = diagram.CreateDefaultContext()
    arm.plant.SetPositions(arm.plant.GetMyMutableContextFromRoot(context), q)
    return [camera.EvalColorImage(context) for camera in cameras]


def test_renders_the_same_images_as_the_plants_scene_graph():
    plant_scene, perception_scene = build(False), build(True)
    assert plant_scene[1].scene_graph.RendererCount() == 1
    assert perception_scene[1].scene_graph.RendererCount() == 0  # the plant's: none
    assert perception_scene[2].scene_graph.RendererCount() == 1
    for q in (Q_A, Q_B):
        for ours, theirs in zip(images(perception_scene, q), images(plant_scene, q)):
            assert ours.shape == theirs.shape and np.array_equal(ours, theirs)
    cell_a, flange_a = images(perception_scene, Q_A)
    cell_b, flange_b = images(perception_scene, Q_B)
    # The arm is in the cell camera's view and moves with q; the board (anchored, textured) is
    # there too, detected at its pose.
    assert np.count_nonzero(np.any(cell_a != cell_b, axis=2)) > 500
    assert not np.array_equal(flange_a, flange_b)
    detection = detect_target(cell_a, CHARUCO, INTRINSICS)
    assert detection.found, detection.reason
    X_CT = np.linalg.inv(X_WC_CELL) @ X_WT
    assert np.abs(detection.X_CT[:3, 3] - X_CT[:3, 3]).max() < 0.01


def test_poses_are_the_plants_body_poses():
    diagram, arm, scene, _ = build(True)
    context = diagram.CreateDefaultContext()
    plant_context = arm.plant.GetMyMutableContextFromRoot(context)
    arm.plant.SetPositions(plant_context, Q_A)
    poses = scene.poses.get_output_port().Eval(scene.poses.GetMyContextFromRoot(context))
    bodies = [arm.plant.get_body(i) for i in arm.plant.GetBodyIndices(
        arm.plant.GetModelInstanceByName("ur5e"))]
    checked = 0
    for body in bodies:
        try:
            frame_id = scene.frame_id(body)
        except ValueError:
            continue  # a body without visual geometry
        expected = arm.plant.EvalBodyPoseInWorld(plant_context, body).GetAsMatrix4()
        assert np.array_equal(poses.value(frame_id).GetAsMatrix4(), expected)
        checked += 1
    assert checked >= 6 and len(poses.ids()) == checked


def test_the_loop_renders_from_the_perception_scene_only_when_its_camera_does(monkeypatch):
    from handeye_drake.apps.speed import rendered_scenario
    from handeye_drake.simulation import build_diagram
    calls = []
    original = PerceptionScenePoses._CalcFramePoses
    monkeypatch.setattr(PerceptionScenePoses, "_CalcFramePoses",
                        lambda self, context, output: (calls.append(context.get_time()),
                                                       original(self, context, output)))
    scenario = rendered_scenario(duration=0.2)
    loop = build_diagram(scenario, with_loggers=False)
    names = {system.get_name() for system in loop.diagram.GetSystems()}
    assert {"scene_graph", "perception_scene_graph", "perception_scene_graph_poses"} <= names
    assert loop.scene_graph.RendererCount() == 0
    simulator = Simulator(loop.diagram)
    simulator.AdvanceTo(scenario.duration)
    frames = round(scenario.duration / scenario.period) + 1
    plant_steps = round(scenario.duration / scenario.plant_config.time_step)
    # A pose update per rendered frame (and the initialization's), not per plant step.
    assert 0 < len(calls) <= frames + 2 < plant_steps


def test_refuses_what_it_cannot_mirror():
    builder = DiagramBuilder()
    arm = add_arm(builder, q0=UR5E_HOME_Q)
    with pytest.raises(ValueError, match="builder: expected a DiagramBuilder"):
        add_perception_scene_graph(None, arm.plant, arm.scene_graph)
    with pytest.raises(ValueError, match="plant: expected a MultibodyPlant"):
        add_perception_scene_graph(builder, arm.scene_graph, arm.scene_graph)
    with pytest.raises(ValueError, match="scene_graph: expected a SceneGraph"):
        add_perception_scene_graph(builder, arm.plant, arm.plant)
    lone = MultibodyPlant(0.0)
    lone.Finalize()
    with pytest.raises(ValueError, match="plant: not registered with a SceneGraph"):
        add_perception_scene_graph(builder, lone, arm.scene_graph)

    # Perception geometry on a frame of another source: no body pose to put it at.
    other = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(other, 0.001)
    plant.Finalize()
    source = scene_graph.RegisterSource("mover")
    frame = scene_graph.RegisterFrame(source, GeometryFrame("mover_frame"))
    instance = GeometryInstance(RigidTransform(), Box(0.1, 0.1, 0.1), "box")
    instance.set_perception_properties(PerceptionProperties())
    scene_graph.RegisterGeometry(source, frame, instance)
    with pytest.raises(ValueError, match="'box' is on frame 'mover_frame', which is not a body"):
        add_perception_scene_graph(other, plant, scene_graph)


def test_a_camera_needs_its_body_in_the_scene():
    builder = DiagramBuilder()
    arm = add_arm(builder, q0=UR5E_HOME_Q)
    scene = add_perception_scene_graph(builder, arm.plant, arm.scene_graph)  # no bodies listed
    # tool0 is a body of its own (welded to wrist_3_link) without geometry: no frame, unless
    # listed.
    with pytest.raises(ValueError, match="body: 'tool0' has no frame in the perception scene"):
        mount_rendered_camera(builder, scene, arm.plant, "tool0", X_EC, INTRINSICS)
    assert scene.frame_id(arm.plant.GetBodyByName("wrist_3_link")) is not None
    listed = add_perception_scene_graph(builder, arm.plant, arm.scene_graph,
                                        bodies=[arm.plant.GetBodyByName("tool0")],
                                        name="with_tool0")
    assert listed.frame_id(arm.plant.GetBodyByName("tool0")) is not None
    other = DiagramBuilder()
    other_arm = add_arm(other, q0=UR5E_HOME_Q)
    with pytest.raises(ValueError, match="scene_graph: this PerceptionScene mirrors another"):
        mount_rendered_camera(builder, scene, other_arm.plant, "tool0", X_EC, INTRINSICS)
    assert isinstance(scene.scene_graph, SceneGraph)

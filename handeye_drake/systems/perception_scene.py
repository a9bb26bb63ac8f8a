"""A second SceneGraph that only renders: a copy of a plant's perception geometry whose poses
update when a camera renders, not at every step of the plant.

Why: a SceneGraph updates the poses of every geometry in every one of its render engines each
time any of its queries needs current poses — and a discrete MultibodyPlant with collision
geometry asks for contact queries at every step. A camera at 30 Hz on a plant stepping at
500 Hz thus pays ≈ 16 render-engine pose updates per frame that no image uses (measured: the
UR5e arm with a RenderEngineVtk in its SceneGraph simulates 35 % slower, without rendering a
frame). Here the plant's SceneGraph keeps proximity and illustration (contact, Meshcat) and no
renderer; the cameras render from this one, whose poses come from the plant's body poses
through ``PerceptionScenePoses``, evaluated only when an image is.

The copy is of the geometry registered with the perception role when
``add_perception_scene_graph`` is called (shapes, poses in their frames, perception properties,
in registration order, so RenderEngineVtk draws the same scene: the images are the same, bit for
bit, as rendering in the plant's SceneGraph — checked by the tests). Geometry added to the
plant's SceneGraph later is not copied.

Frames: W world; each plant body with perception geometry gets a frame in the new SceneGraph at
the body's pose X_WBody; geometry G keeps its X_BodyG. Geometry on frames that are not the
plant's bodies (another source's moving frames) cannot be mirrored and is refused.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pydrake.common.value import AbstractValue
from pydrake.geometry import (
    FrameId,
    FramePoseVector,
    GeometryFrame,
    GeometryInstance,
    PerceptionProperties,
    Role,
    SceneGraph,
    SourceId,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.framework import DiagramBuilder, LeafSystem


class PerceptionScenePoses(LeafSystem):
    """The poses of a MultibodyPlant's bodies as a SceneGraph geometry source
    (``add_perception_scene_graph`` builds and wires it).

    Input port:
        body_poses (abstract, list of RigidTransform X_WBody by BodyIndex): connect
            ``plant.get_body_poses_output_port()``.
    Output port:
        geometry_pose (abstract FramePoseVector): X_WBody of each mirrored body, keyed by its
            frame in the perception SceneGraph (m); computed only when evaluated, i.e. when a
            camera renders.
    """

    def __init__(self, frames: dict):
        """``frames``: {FrameId in the perception SceneGraph: BodyIndex (int) in the plant}."""
        LeafSystem.__init__(self)
        self._frames = [(frame_id, int(index)) for frame_id, index in frames.items()]
        self._body_poses_port = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()]))
        model = FramePoseVector()
        for frame_id, _ in self._frames:
            model.set_value(frame_id, RigidTransform())
        self.DeclareAbstractOutputPort(
            "geometry_pose", lambda: AbstractValue.Make(model), self._CalcFramePoses,
            prerequisites_of_calc={self.input_port_ticket(self._body_poses_port.get_index())})

    def get_body_poses_input_port(self):
        return self._body_poses_port

    def _CalcFramePoses(self, context, output) -> None:
        poses = self._body_poses_port.Eval(context)
        value = output.get_mutable_value()
        for frame_id, index in self._frames:
            value.set_value(frame_id, poses[index])


@dataclass
class PerceptionScene:
    """What ``add_perception_scene_graph`` built: the perception-only ``scene_graph`` (add
    renderers and cameras to it: ``mount_rendered_camera`` takes this object in place of a
    SceneGraph), its geometry source ``source_id``, the ``poses`` system and the frame of each
    mirrored plant body."""
    scene_graph: SceneGraph
    source_id: SourceId
    poses: PerceptionScenePoses
    plant: MultibodyPlant
    _frames: dict = field(default_factory=dict)  # BodyIndex (int) → FrameId

    def frame_id(self, body) -> FrameId:
        """The perception SceneGraph's frame of plant ``body`` (a Body or its BodyIndex): bodies
        with perception geometry have one, and those listed in ``add_perception_scene_graph(...,
        bodies=...)`` (camera mounts)."""
        index = int(body.index()) if hasattr(body, "index") else int(body)
        if index not in self._frames:
            name = self.plant.get_body(BodyIndex(index)).name()
            raise ValueError(f"body: {name!r} has no frame in the perception scene graph; "
                             "list it in add_perception_scene_graph(..., bodies=[...])")
        return self._frames[index]


def add_perception_scene_graph(builder: DiagramBuilder, plant: MultibodyPlant,
                               scene_graph: SceneGraph, bodies=(),
                               name: str = "perception_scene_graph") -> PerceptionScene:
    """Adds a SceneGraph called ``name`` holding a copy of the perception geometry now
    registered in ``scene_graph`` (the one ``plant`` is registered with), posed by the plant's
    body poses (``PerceptionScenePoses``, wired here). ``bodies``: plant bodies (Body objects)
    that get a frame even without perception geometry — the bodies cameras are mounted on.
    Returns the ``PerceptionScene``; add the renderer and cameras to it, not to ``scene_graph``
    (a renderer there would again be updated at every plant step)."""
    if not isinstance(builder, DiagramBuilder):
        raise ValueError(f"builder: expected a DiagramBuilder, got {type(builder).__name__}")
    if not isinstance(plant, MultibodyPlant):
        raise ValueError(f"plant: expected a MultibodyPlant, got {type(plant).__name__}")
    if not isinstance(scene_graph, SceneGraph):
        raise ValueError(f"scene_graph: expected a SceneGraph, got {type(scene_graph).__name__}")
    if not plant.geometry_source_is_registered():
        raise ValueError("plant: not registered with a SceneGraph (AddMultibodyPlantSceneGraph)")
    inspector = scene_graph.model_inspector()
    world = inspector.world_frame_id()
    perception = builder.AddNamedSystem(name, SceneGraph())
    source_id = perception.RegisterSource(plant.get_name())  # its port: "plant_pose"
    frames: dict = {}  # BodyIndex (int) → FrameId in `perception`

    def frame_of(body) -> FrameId:
        index = int(body.index())
        if index not in frames:
            frames[index] = perception.RegisterFrame(
                source_id, GeometryFrame(f"{body.model_instance()}::{body.name()}"))
        return frames[index]

    for body in bodies:
        frame_of(body)
    for geometry_id in inspector.GetAllGeometryIds(Role.kPerception):
        frame_id = inspector.GetFrameId(geometry_id)
        instance = GeometryInstance(inspector.GetPoseInFrame(geometry_id),
                                    inspector.GetShape(geometry_id),
                                    inspector.GetName(geometry_id))
        instance.set_perception_properties(
            PerceptionProperties(inspector.GetPerceptionProperties(geometry_id)))
        if frame_id == world:
            perception.RegisterAnchoredGeometry(source_id, instance)
            continue
        body = plant.GetBodyFromFrameId(frame_id)
        if body is None:
            raise ValueError(
                f"scene_graph: perception geometry {inspector.GetName(geometry_id)!r} is on "
                f"frame {inspector.GetName(frame_id)!r}, which is not a body of the plant: it "
                "cannot be posed from the plant's body poses")
        perception.RegisterGeometry(source_id, frame_of(body), instance)
    poses = builder.AddNamedSystem(f"{name}_poses", PerceptionScenePoses(
        {frame_id: index for index, frame_id in frames.items()}))
    builder.Connect(plant.get_body_poses_output_port(), poses.get_body_poses_input_port())
    builder.Connect(poses.get_output_port(), perception.get_source_pose_port(source_id))
    return PerceptionScene(scene_graph=perception, source_id=source_id, poses=poses,
                           plant=plant, _frames=frames)

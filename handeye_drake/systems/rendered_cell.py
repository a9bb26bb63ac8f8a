"""A robot cell whose camera renders: one Drake ``Diagram`` with the arm's ``MultibodyPlant`` (the
shipped UR5e or any URDF), the calibration board as textured geometry, an ``RgbdSensor`` on the
flange at the true camera mount and the project's ``TargetDetector`` on its images — for
executing calibration poses kinematically and measuring X_CT from rendered images.

    cell = RenderedHandCell(target, intrinsics, X_EC, X_BT)
    shot = cell.observe(q)          # moves the plant to q, renders one frame, detects the board
    shot.found, shot.X_BE, shot.X_CT, shot.detection, cell.frames

Kinematic: ``observe`` sets the plant's joint positions (no dynamics), then takes one frame
through the diagram — ``diagram.ExecuteForcedEvents`` runs the detector's forced update (the
same detection its periodic camera event runs in a simulation: the sensor renders the current
scene graph poses, ``detect_target`` finds the corners and solves the pose, IPPE/solvePnP) — and
reads the detector's output ports. Only ``observe`` renders, so a loop renders exactly one frame
per sample (``frames`` counts them, ``seconds`` their render and detection time). Moving along a
path without images: ``set_q``.

Frames: B robot base (= world W, welded at the identity), E flange (``ee_frame``), C camera
(OpenCV axes), T target (``vision.targets``; z_T into the board). A visual floor (perception
role only, no collision: collisions are the planner's business) lies ``floor_gap_m`` below the
board's back face so that the board is seen on a grey table, not in the sky.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Box as DrakeBox
from pydrake.geometry import GeometryInstance, PerceptionProperties, Rgba
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import DiagramBuilder

from ..estimation.se3 import inverse, vector_to_pose
from ..estimation.validation import as_transform
from ..vision.camera_model import CameraIntrinsics
from .rendered_camera import DEFAULT_THICKNESS, add_target_geometry, mount_rendered_camera
from .target_detector import TargetDetector


@dataclass(frozen=True)
class Shot:
    """One rendered and detected frame: the joint angles ``q`` (rad), the true flange pose
    ``X_BE`` (forward kinematics), the true ``X_CT_true`` (from the cell's true mount and
    board pose), and the detector's ``found``, ``X_CT`` (None when not found), ``detection``
    (the ``TargetDetection``) and ``image`` (H×W×4 RGBA, only with ``keep_image``)."""

    q: np.ndarray
    X_BE: np.ndarray
    X_CT_true: np.ndarray
    found: bool
    X_CT: np.ndarray | None
    detection: object
    image: np.ndarray | None = None


class RenderedHandCell:
    """An eye-in-hand cell with a rendered camera (module docstring).

    Args:
        target: the board (a ``vision.targets`` target or spec string).
        intrinsics: the camera (``CameraIntrinsics``; no skew, no distortion).
        X_EC: the true camera mount on ``ee_frame`` (4×4).
        X_BT: the true board pose in the base (4×4).
        urdf, base_frame, ee_frame: the arm (default: the shipped UR5e, base_link, tool0).
        supersample: the sensor's anti-aliasing factor (``mount_rendered_camera``).
        detect_options: passed to ``TargetDetector`` (``detect_target`` options).
        floor_gap_m: the visual floor's top this far below the board's back face; None: no floor.
    """

    def __init__(self, target, intrinsics: CameraIntrinsics, X_EC, X_BT, urdf=None,
                 base_frame: str = "base_link", ee_frame: str = "tool0", supersample: int = 1,
                 detect_options: dict | None = None, floor_gap_m: float | None = 0.001):
        from .arm import _check_frame, _resolve_model_file
        self.X_EC = as_transform(X_EC, "X_EC", rigid=True)
        self.X_BT = as_transform(X_BT, "X_BT", rigid=True)
        self.intrinsics = intrinsics
        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        model_file = _resolve_model_file(urdf)
        models = Parser(plant).AddModels(model_file)
        base = _check_frame(plant, base_frame, "base_frame", models[0])
        self._ee = _check_frame(plant, ee_frame, "ee_frame", models[0])
        plant.WeldFrames(plant.world_frame(), base, RigidTransform())
        plant.Finalize()
        self._base = base
        add_target_geometry(scene_graph, target, self.X_BT)
        if floor_gap_m is not None:
            # The table: its top below the board's back face (the board's normal +z_T points
            # down into the table when the board lies face up).
            n = self.X_BT[:3, 2]
            top = float(self.X_BT[2, 3] + (DEFAULT_THICKNESS + floor_gap_m) * np.sign(n[2] or 1))
            source = scene_graph.RegisterSource("table")
            table = GeometryInstance(RigidTransform([0.0, 0.0, top - 0.05]),
                                     DrakeBox(4.0, 4.0, 0.1), "table")
            props = PerceptionProperties()
            props.AddProperty("phong", "diffuse", Rgba(0.55, 0.55, 0.5, 1.0))
            table.set_perception_properties(props)
            scene_graph.RegisterAnchoredGeometry(source, table)
        self.camera = mount_rendered_camera(builder, scene_graph, plant, self._ee, self.X_EC,
                                            intrinsics, supersample=supersample)
        self.detector = builder.AddNamedSystem("target_detector", TargetDetector(
            target, intrinsics, 1.0, **(detect_options or {})))
        builder.Connect(self.camera.color_image_output_port(),
                        self.detector.get_color_image_input_port())
        self.diagram = builder.Build()
        self.plant, self.scene_graph = plant, scene_graph
        self.context = self.diagram.CreateDefaultContext()
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        self.detector_context = self.detector.GetMyContextFromRoot(self.context)
        self.frames = 0
        self.seconds = 0.0

    def set_q(self, q) -> None:
        """Moves the arm to joint angles ``q`` (rad) without rendering."""
        self.plant.SetPositions(self.plant_context, np.asarray(q, float))

    def X_BE(self, q=None) -> np.ndarray:
        """The flange pose at ``q`` (or the current configuration), 4×4."""
        if q is not None:
            self.set_q(q)
        return self.plant.CalcRelativeTransform(self.plant_context, self._base,
                                                self._ee).GetAsMatrix4()

    def observe(self, q, keep_image: bool = False) -> Shot:
        """Moves the arm to ``q``, renders one frame and detects the board in it (``Shot``)."""
        t0 = time.perf_counter()
        X_BE = self.X_BE(q)
        self.diagram.ExecuteForcedEvents(self.context)
        self.frames += 1
        self.seconds += time.perf_counter() - t0
        det = self.detector.get_detection_output_port().Eval(self.detector_context)
        found = bool(self.detector.get_found_output_port().Eval(self.detector_context)[0])
        X_CT = None
        if found:
            X_CT = vector_to_pose(self.detector.get_X_CT_measured_output_port().Eval(
                self.detector_context))
        image = self.camera.EvalColorImage(self.context) if keep_image else None
        return Shot(np.asarray(q, float).copy(), X_BE,
                    inverse(X_BE @ self.X_EC) @ self.X_BT, found, X_CT, det, image)


__all__ = ["RenderedHandCell", "Shot"]

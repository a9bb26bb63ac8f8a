"""Meshcat replay of a closed-loop run: the arm, the target points, and the true and estimated
camera frames (X_WC and X_WE · X_EC_estimate), recorded into a self-contained HTML file."""

from __future__ import annotations

import numpy as np
from pydrake.geometry import (
    Cylinder,
    Meshcat,
    MeshcatVisualizer,
    MeshcatVisualizerParams,
    Rgba,
    Sphere,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.systems.framework import LeafSystem

from ..estimation.se3 import vector_to_pose


def _add_triad(meshcat: Meshcat, path: str, length: float = 0.06, radius: float = 0.003,
               opacity: float = 1.0) -> None:
    """Red/green/blue cylinders along x/y/z (like manipulation's AddMeshcatTriad)."""
    for axis, rgba, X in (
            ("x", Rgba(1, 0, 0, opacity),
             RigidTransform(RotationMatrix.MakeYRotation(np.pi / 2), [length / 2, 0, 0])),
            ("y", Rgba(0, 1, 0, opacity),
             RigidTransform(RotationMatrix.MakeXRotation(np.pi / 2), [0, length / 2, 0])),
            ("z", Rgba(0, 0, 1, opacity), RigidTransform([0, 0, length / 2]))):
        meshcat.SetObject(f"{path}/{axis}", Cylinder(radius, length), rgba)
        meshcat.SetTransform(f"{path}/{axis}", X)


class CameraFramesVisualizer(LeafSystem):
    """Publishes the true camera frame and the estimated one (X_WE · X_EC_estimate) to Meshcat
    at every ``period``, into the current recording.

    Input ports: ``X_WC`` (12, true camera pose), ``X_WE`` (12), ``X_EC_estimate`` (12).
    """

    def __init__(self, meshcat: Meshcat, period: float):
        super().__init__()
        self._meshcat = meshcat
        self._X_WC_port = self.DeclareVectorInputPort("X_WC", 12)
        self._X_WE_port = self.DeclareVectorInputPort("X_WE", 12)
        self._X_EC_port = self.DeclareVectorInputPort("X_EC_estimate", 12)
        _add_triad(meshcat, "camera/true", length=0.08)
        _add_triad(meshcat, "camera/estimated", length=0.08, radius=0.002, opacity=0.5)
        self.DeclarePeriodicPublishEvent(period, 0.0, self._PublishFrames)

    def get_X_WC_input_port(self):
        return self._X_WC_port

    def get_X_WE_input_port(self):
        return self._X_WE_port

    def get_X_EC_input_port(self):
        return self._X_EC_port

    def _PublishFrames(self, context):
        t = context.get_time()
        X_WC = vector_to_pose(self._X_WC_port.Eval(context))
        X_WC_est = vector_to_pose(self._X_WE_port.Eval(context)) @ vector_to_pose(
            self._X_EC_port.Eval(context))
        self._meshcat.SetTransform("camera/true", RigidTransform(X_WC), t)
        self._meshcat.SetTransform("camera/estimated", RigidTransform(X_WC_est), t)


def add_meshcat_visualization(builder, scene_graph, meshcat: Meshcat, X_WT, p_TQ, period: float,
                              X_WC_port, X_WE_port, X_EC_estimate_port) -> None:
    """Arm (illustration geometry), target points and both camera frames in ``meshcat``."""
    MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat, MeshcatVisualizerParams())
    # Look at the workspace between the arm's base and the target.
    p_WT = np.asarray(X_WT, dtype=float)[:3, 3]
    meshcat.SetCameraPose(p_WT + np.array([0.9, -0.9, 0.7]), 0.5 * p_WT + np.array([0, 0, 0.2]))
    for i, p in enumerate(np.asarray(p_TQ, dtype=float)):
        meshcat.SetObject(f"target/point{i}", Sphere(0.008), Rgba(0.9, 0.5, 0.0, 1.0))
        meshcat.SetTransform(f"target/point{i}", RigidTransform(p))
    meshcat.SetTransform("target", RigidTransform(np.asarray(X_WT, dtype=float)))
    _add_triad(meshcat, "target/frame", length=0.05)
    frames = builder.AddNamedSystem("camera_frames_visualizer",
                                    CameraFramesVisualizer(meshcat, period))
    builder.Connect(X_WC_port, frames.get_X_WC_input_port())
    builder.Connect(X_WE_port, frames.get_X_WE_input_port())
    builder.Connect(X_EC_estimate_port, frames.get_X_EC_input_port())

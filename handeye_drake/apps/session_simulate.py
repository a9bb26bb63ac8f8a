"""``handeye-drake session --simulate``: a simulated robot driver for the live session, so that a
session can be run end to end without hardware.

The cell (``SimulatedCell``): the shipped UR5e (Drake ``MultibodyPlant``) with a camera on its
flange at a true mount ``X_EC`` that the session does not know (it gets the rough
``X_EC_guess``, a few degrees and millimetres off, as from a drawing), and a ChArUco board of 8 × 6
squares of 25 mm lying face up on the table at ``X_BT``. The camera renders
(``systems.rendered_cell.RenderedHandCell``: RenderVtk, 640 × 480, 2× supersampled) and the
project's detector measures X_CT from each image (corners, IPPE/solvePnP). The robot reports its
flange pose X_BE through a perturbed kinematic model (joint zero offsets, ``joint_offset_deg``
per joint, drawn once: errors that repeat with the joint angles), with a constant error (a
calibration-less arm: drawn once per seed from ``robot_accuracy`` per axis — absorbed by the
hand-eye transform, so it is what the session's σ floor is for) and a per-sample jitter
(``robot_noise``).

``SimulatedDriver.execute(pose)`` does what a real driver does for the session: moves the arm
along the suggested path to the suggested joint angles, takes one frame, and appends one sample
line (14 numbers: X_BE then X_CT, ``x y z qx qy qz qw`` each, metres) to the samples file — the
same file format the session reads from a real driver, and the session reads it through the
same reader. A frame where the board is not found appends nothing (a lost view).

Frames: B robot base (= world), E flange (tool0), C camera (OpenCV axes), T board.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..estimation.se3 import make_transform, quat_wxyz, rotation_exp
from ..vision.camera_model import CameraIntrinsics


def _rpy(r, p, y) -> np.ndarray:
    """Rotation matrix of roll, pitch, yaw in degrees (x, y, z fixed axes: Rz Ry Rx)."""
    r, p, y = np.radians([r, p, y])
    return rotation_exp(np.array([0.0, 0.0, y])) @ rotation_exp(np.array([0.0, p, 0.0])) @ \
        rotation_exp(np.array([r, 0.0, 0.0]))


@dataclass(frozen=True)
class SimulatedCell:
    """The simulated cell's truth and what the session is told (module docstring). Units: m,
    deg (per axis for the noise and accuracy)."""
    intrinsics: CameraIntrinsics = field(default_factory=lambda: CameraIntrinsics(
        alpha_u=800, alpha_v=800, u0=320, v0=240, width=640, height=480))
    #: The board: ChArUco 8 × 6 squares of 25 mm (0.2 × 0.15 m from its origin along x, y).
    target_spec: str = "charuco:8x6:0.025:0.019:DICT_5X5_100"
    board_size_m: tuple = (0.2, 0.15)
    X_BT: np.ndarray = field(default_factory=lambda: make_transform(
        rotation_exp(np.array([math.pi, 0.0, 0.0])), [-0.45, -0.15, 0.0]))
    X_EC: np.ndarray = field(default_factory=lambda: make_transform(_rpy(4, -3, 92),
                                                                    [0.04, -0.03, 0.06]))
    X_EC_guess: np.ndarray = field(default_factory=lambda: make_transform(
        _rpy(2, -2, 91), [0.035, -0.025, 0.055]))
    robot_accuracy: tuple = (0.03, 0.3)        # deg, mm per axis: the constant flange error
    robot_noise: tuple = (0.01, 0.05)          # deg, mm per axis: per-sample jitter
    joint_offset_deg: float = 0.005            # per joint: the reports' kinematic model error

    @property
    def board_points(self) -> np.ndarray:
        w, h = self.board_size_m
        return np.array([[x, y, 0.0] for x in (0, w) for y in (0, h)])


def sample_line(X_BE, X_CT) -> str:
    """The session's sample line: X_BE then X_CT, each ``x y z qx qy qz qw`` (metres,
    quaternion scalar last)."""
    def seven(X):
        q = quat_wxyz(X[:3, :3])
        return [*X[:3, 3], q[1], q[2], q[3], q[0]]
    return " ".join(f"{v:.9f}" for v in seven(X_BE) + seven(X_CT))


def _perturbed(X, deg, mm, rng) -> np.ndarray:
    """X · exp(e): an error of the flange frame, per-axis σ deg and mm."""
    E = make_transform(rotation_exp(rng.normal(0, math.radians(deg), 3)),
                       rng.normal(0, mm / 1000.0, 3))
    return X @ E


class SimulatedDriver:
    """Moves the simulated arm to the session's poses and appends their samples to a file.

    Args:
        samples_path: the samples file to append to (created empty).
        cell: ``SimulatedCell``.
        seed: the robot's constant error and jitter.
        supersample: the renderer's anti-aliasing factor.

    ``execute(pose)`` (a ``as_session_planner`` dict: ``q``, ``path``) returns True when a
    sample line was appended, False for a lost view. ``frames``, ``lost``; ``robot_error``
    is the constant flange error (4×4) the arm's reports carry.
    """

    def __init__(self, samples_path, cell: SimulatedCell = SimulatedCell(), seed: int = 0,
                 supersample: int = 2):
        from ..systems.rendered_cell import RenderedHandCell
        self.path = Path(samples_path)
        self.cell = cell
        self.rng = np.random.default_rng(seed)
        self.robot_error = _perturbed(np.eye(4), *cell.robot_accuracy, self.rng)
        self.joint_offsets = None
        self.render = RenderedHandCell(cell.target_spec, cell.intrinsics, cell.X_EC, cell.X_BT,
                                       supersample=supersample)
        self.path.write_text("")
        self.lost = 0

    @property
    def frames(self) -> int:
        return self.render.frames

    def execute(self, pose) -> bool:
        q = np.asarray(pose["q"], float)
        if self.joint_offsets is None:
            self.joint_offsets = self.rng.normal(0, math.radians(self.cell.joint_offset_deg),
                                                 len(q))
        # What the controller reports: its kinematic model at its encoders' angles.
        X_BE_model = self.render.X_BE(q + self.joint_offsets)
        for q_via in pose.get("path", [q])[:-1]:
            self.render.set_q(q_via)               # move through, no frame
        shot = self.render.observe(q)
        if not shot.found:
            self.lost += 1
            return False
        X_BE = _perturbed(X_BE_model @ self.robot_error, *self.cell.robot_noise, self.rng)
        with self.path.open("a") as fh:
            fh.write(sample_line(X_BE, shot.X_CT) + "\n")
        return True


def simulated_planner(cell: SimulatedCell, num_candidates: int, seed: int):
    """The session's planner on the simulated cell: ``planning.FeasiblePlanner`` with the rough
    mount, views 0.3–0.7 m from the board, ≤ 40° tilt, the board 60 px inside the image, 2 cm
    clearance; ``num_candidates`` reachable views. Returns (planner, next-pose callable)."""
    from ..planning import FeasiblePlanner, ViewSpec, as_session_planner
    view = ViewSpec(distance_range_m=(0.3, 0.7), max_tilt_deg=40, intrinsics=cell.intrinsics,
                    target_points=cell.board_points, margin_px=60)
    planner = FeasiblePlanner("eye_in_hand", cell.X_EC_guess, cell.X_BT, view=view,
                              min_distance_m=0.02, seed=seed)
    pool = planner.sample_candidates(num_candidates)
    return planner, pool, as_session_planner(planner, pool)


__all__ = ["SimulatedCell", "SimulatedDriver", "sample_line", "simulated_planner"]

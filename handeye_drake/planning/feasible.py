"""Feasible calibration poses with Drake: inverse kinematics with the camera's view, minimum
distance to the cell and between links, D-optimal ranking, a short tour and a checked trajectory.

Frames (X_AB: pose of B in A): B robot base (welded at the origin of the plant's world W, so
W = B), E end-effector (``ee_frame``, the UR5e flange ``tool0``), C camera (z the optical axis),
T target (z INTO the board: a board is seen face-on when z_C is parallel to z_T). Eye-in-hand:
``X_HC`` = X_EC, ``X_FT`` = X_BT; eye-to-hand: ``X_HC`` = X_BC, ``X_FT`` = X_ET. Joint angles in
rad, lengths in m, times in s.

A candidate is accepted only when a double-precision check of the solved configuration confirms
it: joint limits, signed distance ≥ ``min_distance_m`` for every pair of geometries that may
collide (the cell vs the arm, camera and target; the arm's links against each other except
those joined by a joint), the target centre at a distance in ``view.distance_range_m``, inside
the view cone (and, with intrinsics, every target point inside the image by ``margin_px``), and
the angle between z_C and z_T at most ``view.max_tilt_deg``.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from pydrake.geometry import Box as DrakeBox
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, CoulombFriction
from pydrake.solvers import SnoptSolver, SolverOptions, Solve
from pydrake.systems.framework import DiagramBuilder
from pydrake.trajectories import PiecewisePolynomial

from ..estimation.observability import check_mode
from ..estimation.planning import plan_next_poses
from ..estimation.se3 import inverse, make_transform, rotation_angle, rotation_exp
from ..estimation.validation import as_transform
from ..vision.camera_model import CameraIntrinsics, project_points
from .cell import Cell

#: The shipped UR5e's "home" (upper arm up, forearm level, flange down), rad.
UR5E_HOME_Q = np.array([0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0])


#: SNOPT's iteration limits: a view that needs more is treated as unreachable (keeps a failing
#: request to a fraction of a second per attempt).
_SOLVER_OPTIONS = SolverOptions()
_SOLVER_OPTIONS.SetOption(SnoptSolver.id(), "Major iterations limit", 100)
_SOLVER_OPTIONS.SetOption(SnoptSolver.id(), "Iterations limit", 3000)


class InfeasibleError(ValueError):
    """A planning request that cannot be met; the message is one line giving the reason."""


@dataclass(frozen=True)
class ViewSpec:
    """What counts as a usable view of the target.

    Attributes:
        distance_range_m: (min, max) distance from the camera centre to the target centre (m).
        max_tilt_deg: largest angle between the optical axis z_C and the board normal z_T (deg).
        cone_half_angle_deg: the target centre within this angle of the optical axis (deg);
            None: from ``intrinsics`` (70 % of the smaller half field of view), else 15°.
        intrinsics: ``CameraIntrinsics`` (pixels) to check that every ``target_points`` point
            projects inside the image by ``margin_px``; None: the cone alone.
        target_points: (N, 3) points on the target (m, in T) that must be in view; their mean is
            the target centre aimed at. None: the origin of T only.
        margin_px: margin inside the image border (pixels).
    """
    distance_range_m: tuple = (0.3, 0.7)
    max_tilt_deg: float = 40.0
    cone_half_angle_deg: float | None = None
    intrinsics: CameraIntrinsics | None = None
    target_points: np.ndarray | None = None
    margin_px: float = 10.0

    def validated(self) -> "ViewSpec":
        lo, hi = (float(x) for x in self.distance_range_m)
        if not (0 < lo <= hi and math.isfinite(hi)):
            raise ValueError(f"distance_range_m: expected 0 < min ≤ max, got {self.distance_range_m}")
        if not (0 < self.max_tilt_deg < 90):
            raise ValueError(f"max_tilt_deg: expected a value in (0, 90), got {self.max_tilt_deg}")
        if self.cone_half_angle_deg is not None and not (0 < self.cone_half_angle_deg < 90):
            raise ValueError("cone_half_angle_deg: expected a value in (0, 90), got "
                             f"{self.cone_half_angle_deg}")
        return self

    @property
    def points(self) -> np.ndarray:
        return np.zeros((1, 3)) if self.target_points is None else np.asarray(
            self.target_points, float).reshape(-1, 3)

    @property
    def center(self) -> np.ndarray:
        return self.points.mean(axis=0)

    @property
    def cone_rad(self) -> float:
        if self.cone_half_angle_deg is not None:
            return math.radians(self.cone_half_angle_deg)
        if self.intrinsics is not None:
            k = self.intrinsics
            half = min(math.atan2(k.width / 2, k.alpha_u), math.atan2(k.height / 2, k.alpha_v))
            return 0.7 * half
        return math.radians(15.0)


@dataclass
class Feasibility:
    """The double-precision check of one configuration (``FeasiblePlanner.check``)."""
    within_limits: bool
    min_distance_m: float            # smallest signed distance over the checked pairs
    closest_pair: tuple              # names of the two geometries at min_distance_m
    target_distance_m: float
    off_axis_deg: float              # target centre from the optical axis
    tilt_deg: float                  # between z_C and z_T
    in_image: bool                   # every target point inside the image (True without intrinsics)
    reasons: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.reasons


@dataclass
class CandidateSet:
    """Verified candidates: ``q`` (K, n) joint angles (rad) and ``X_BE`` (K, 4, 4), from
    ``attempts`` IK problems; ``rejected`` counts why the others failed."""
    q: np.ndarray
    X_BE: np.ndarray
    attempts: int
    rejected: Counter

    def __len__(self):
        return len(self.q)


@dataclass
class Tour:
    """An ordered tour through chosen configurations and its trajectory.

    Attributes:
        order: indices (into the configurations given) in the visiting order.
        waypoints: (M, n) the joint configurations the trajectory passes, in order (the start,
            the poses, and any detour through the start pose).
        trajectory: ``PiecewisePolynomial`` q(t) (rad), stopping ``dwell_s`` at every pose.
        pose_times: time (s) at which each pose of ``order`` is reached.
        min_distance_m: smallest signed distance along the trajectory, checked every
            ``check_step_rad`` of joint motion.
        dropped: indices whose segment could not be made collision-free (not in ``order``).
        detours: number of segments routed back through the start configuration.
    """
    order: list
    waypoints: np.ndarray
    trajectory: PiecewisePolynomial
    pose_times: list
    min_distance_m: float
    dropped: list
    detours: int
    check_step_rad: float

    @property
    def duration_s(self) -> float:
        return float(self.trajectory.end_time())


def _look_rotation(z, roll):
    """A rotation whose z axis is the unit vector ``z``, turned by ``roll`` (rad) about it."""
    z = z / np.linalg.norm(z)
    a = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(a, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.column_stack([x, y, z])
    return R @ rotation_exp(np.array([0.0, 0.0, roll]))


class FeasiblePlanner:
    """Reachable, collision-free views of the target for one robot in one cell (module docstring).

    Args:
        mode: "eye_in_hand" or "eye_to_hand".
        X_HC: the camera's pose, X_EC (eye-in-hand) or X_BC (eye-to-hand), 4×4; a rough value is
            enough (the view and collision margins absorb centimetres).
        X_FT: the target's pose, X_BT (eye-in-hand) or X_ET (eye-to-hand), 4×4.
        urdf: the robot's URDF/SDFormat file (default: the shipped UR5e); it needs collision
            geometry for the distance checks.
        base_frame, ee_frame: names of B and E in the model.
        cell: ``Cell`` (floor plane, boxes), in B.
        view: ``ViewSpec``.
        min_distance_m: smallest allowed signed distance between geometries (m).
        q_nominal: configuration the IK prefers (rad; default the UR5e home for 6 joints, else
            the middle of the joint limits).
        camera_size_m: the camera body, a box centred on C (m), eye-in-hand on the flange.
        target_size_m: the target board, a box (m) centred on the target centre, 2 mm thick
            behind the board face unless given.
        meshcat: a ``pydrake.geometry.Meshcat`` to preview in (a ``MeshcatVisualizer`` is added
            to the planner's diagram; ``preview.write_html`` records a tour into it), or None.
        seed: seeds the viewpoint sampling.

    Raises:
        ValueError naming the argument: unknown frames, a model without collision geometry,
        bad poses.
    """

    def __init__(self, mode, X_HC, X_FT, urdf=None, base_frame: str = "base_link",
                 ee_frame: str = "tool0", cell: Cell = Cell(), view: ViewSpec = ViewSpec(),
                 min_distance_m: float = 0.01, q_nominal=None,
                 camera_size_m=(0.09, 0.06, 0.05), target_size_m=None, meshcat=None,
                 seed: int = 0):
        from ..systems.arm import UR5E_URDF, _check_frame, _resolve_model_file
        self.mode = check_mode(mode)
        self.X_HC = as_transform(X_HC, "X_HC")
        self.X_FT = as_transform(X_FT, "X_FT")
        self.view = view.validated()
        if not (isinstance(min_distance_m, (int, float)) and 0 <= min_distance_m < 0.5):
            raise ValueError(f"min_distance_m: expected a value in [0, 0.5), got {min_distance_m!r}")
        self.min_distance_m = float(min_distance_m)
        self.cell = cell
        self.urdf = _resolve_model_file(urdf)
        self.rng = np.random.default_rng(seed)

        builder = DiagramBuilder()
        plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        try:
            models = Parser(plant).AddModels(self.urdf)
        except Exception as e:  # the parser's RuntimeError: a malformed file
            raise ValueError(f"urdf: cannot parse {self.urdf!r}: "
                             f"{' '.join(str(e).split())[:200]}") from None
        base = _check_frame(plant, base_frame, "base_frame (in --urdf)", models[0])
        ee = _check_frame(plant, ee_frame, "ee_frame (in --urdf)", models[0])
        plant.WeldFrames(plant.world_frame(), base, RigidTransform())
        self._robot_collision = []
        for b in plant.GetBodyIndices(models[0]):
            self._robot_collision += plant.GetCollisionGeometriesForBody(plant.get_body(b))
        if not self._robot_collision:
            raise ValueError(f"urdf: {self.urdf!r} has no collision geometry: the minimum-"
                             "distance constraints need some (add <collision> shapes to its links)")
        world = plant.world_body()
        friction = CoulombFriction(0.5, 0.5)
        cell_ids = []

        def add(body, X, size, name, color):
            shape = DrakeBox(*size)
            X = RigidTransform(np.asarray(X, float))
            gid = plant.RegisterCollisionGeometry(body, X, shape, name, friction)
            plant.RegisterVisualGeometry(body, X, shape, name, np.asarray(color, float))
            return gid

        if cell.floor_z is not None:
            cell_ids.append(add(world, make_transform(np.eye(3), [0, 0, cell.floor_z - 0.05]),
                                (4.0, 4.0, 0.1), "floor", (0.8, 0.8, 0.75, 1.0)))
        for b in cell.boxes:
            R = RollPitchYaw(np.radians(b.rpy_deg)).ToRotationMatrix().matrix()
            cell_ids.append(add(world, make_transform(R, b.center), b.size, f"box_{b.name}",
                                (0.7, 0.5, 0.3, 1.0)))
        ee_body = ee.body()
        X_bodyE = ee.GetFixedPoseInBodyFrame().GetAsMatrix4()
        c = self.view.center
        board = tuple(target_size_m) if target_size_m is not None else self._board_size()
        X_T_board = make_transform(np.eye(3), [c[0], c[1], c[2] + board[2] / 2])
        if self.mode == "eye_in_hand":
            self._camera_id = add(ee_body, X_bodyE @ self.X_HC, camera_size_m, "camera",
                                  (0.1, 0.1, 0.1, 1.0))
            self._target_id = add(world, self.X_FT @ X_T_board, board, "target",
                                  (0.95, 0.95, 0.95, 1.0))
        else:
            self._camera_id = add(world, self.X_HC, camera_size_m, "camera", (0.1, 0.1, 0.1, 1.0))
            self._target_id = add(ee_body, X_bodyE @ self.X_FT @ X_T_board, board, "target",
                                  (0.95, 0.95, 0.95, 1.0))
        plant.Finalize()
        if meshcat is not None:
            from pydrake.geometry import MeshcatVisualizer, MeshcatVisualizerParams
            self.visualizer = MeshcatVisualizer.AddToBuilder(builder, scene_graph, meshcat,
                                                             MeshcatVisualizerParams())
        else:
            self.visualizer = None
        self.meshcat = meshcat
        self.diagram = builder.Build()
        self.plant, self.scene_graph = plant, scene_graph
        self.base_frame, self.ee_frame = base, ee
        self.context = self.diagram.CreateDefaultContext()
        self.plant_context = plant.GetMyMutableContextFromRoot(self.context)
        self.sg_context = scene_graph.GetMyContextFromRoot(self.context)
        inspector = scene_graph.model_inspector()
        self._names = {}
        self._cell_ids = cell_ids
        # The camera sees the target: the board is not an obstacle of the camera's own ray, but
        # the distance range already keeps them apart; the camera body vs the board is checked.
        self.lower = plant.GetPositionLowerLimits()
        self.upper = plant.GetPositionUpperLimits()
        n = plant.num_positions()
        if q_nominal is None:
            q_nominal = UR5E_HOME_Q if (n == 6 and self.urdf == UR5E_URDF) else np.where(
                np.isfinite(self.lower + self.upper), 0.5 * (self.lower + self.upper), 0.0)
        self.q_nominal = np.asarray(q_nominal, float).reshape(-1)
        if self.q_nominal.shape != (n,):
            raise ValueError(f"q_nominal: expected {n} joint angles, got {self.q_nominal.shape}")
        self.velocity_limits = np.where(np.isfinite(plant.GetVelocityUpperLimits()),
                                        plant.GetVelocityUpperLimits(), 1.0)
        self._inspector = inspector

    # ---------------------------------------------------------------------------- geometry
    def _board_size(self):
        p = self.view.points
        ext = p.max(axis=0) - p.min(axis=0)
        return (max(ext[0] + 0.04, 0.05), max(ext[1] + 0.04, 0.05), 0.002)

    def _name(self, gid) -> str:
        if gid not in self._names:
            frame = self._inspector.GetFrameId(gid)
            body = self.plant.GetBodyFromFrameId(frame)
            self._names[gid] = (self._inspector.GetName(gid) if body is None or
                                body.index() == self.plant.world_body().index()
                                else body.name() + "/" + self._inspector.GetName(gid).split(
                                    "::")[-1])
        return self._names[gid]

    def set_q(self, q):
        self.plant.SetPositions(self.plant_context, np.asarray(q, float))

    def X_BE(self, q) -> np.ndarray:
        """Forward kinematics: the end-effector pose X_BE (4×4) at joint angles q (rad)."""
        self.set_q(q)
        return self.plant.CalcRelativeTransform(self.plant_context, self.base_frame,
                                                self.ee_frame).GetAsMatrix4()

    def camera_target(self, q):
        """(X_BC, X_BT) at q: the camera and the target in the base (4×4)."""
        X_BE = self.X_BE(q)
        if self.mode == "eye_in_hand":
            return X_BE @ self.X_HC, self.X_FT
        return self.X_HC, X_BE @ self.X_FT

    def min_distance(self, q):
        """(smallest signed distance (m) over the pairs that may collide, the two geometry names)
        at q."""
        self.set_q(q)
        query = self.scene_graph.get_query_output_port().Eval(self.sg_context)
        pairs = query.ComputeSignedDistancePairwiseClosestPoints(0.5)
        if not pairs:
            return math.inf, ("", "")
        best = min(pairs, key=lambda p: p.distance)
        return float(best.distance), (self._name(best.id_A), self._name(best.id_B))

    def colliding_pairs(self, q, bound: float = 0.0) -> list:
        """[(geometry A, geometry B, signed distance m)] of every checked pair closer than
        ``bound`` at q, closest first."""
        self.set_q(q)
        query = self.scene_graph.get_query_output_port().Eval(self.sg_context)
        pairs = query.ComputeSignedDistancePairwiseClosestPoints(max(bound, 0.0) + 1e-9)
        return sorted(((self._name(p.id_A), self._name(p.id_B), float(p.distance))
                       for p in pairs if p.distance < bound), key=lambda x: x[2])

    def check(self, q) -> Feasibility:
        """The double-precision check of configuration q (module docstring)."""
        q = np.asarray(q, float)
        reasons = []
        within = bool(np.all(q >= self.lower - 1e-9) and np.all(q <= self.upper + 1e-9))
        if not within:
            reasons.append("joint limits")
        d, pair = self.min_distance(q)
        if d < self.min_distance_m - 1e-4:
            reasons.append(f"collision ({pair[0]} – {pair[1]} at {1000 * d:.0f} mm)")
        X_BC, X_BT = self.camera_target(q)
        X_CT = inverse(X_BC) @ X_BT
        c = X_CT[:3, :3] @ self.view.center + X_CT[:3, 3]
        dist = float(np.linalg.norm(c))
        off = math.degrees(math.atan2(np.linalg.norm(c[:2]), c[2]))
        tilt = math.degrees(math.acos(np.clip(X_CT[:3, 2] @ np.array([0, 0, 1.0]), -1, 1)))
        lo, hi = self.view.distance_range_m
        if not (lo - 1e-3 <= dist <= hi + 1e-3):
            reasons.append(f"target at {dist:.3f} m, outside [{lo:g}, {hi:g}]")
        if off > math.degrees(self.view.cone_rad) + 0.05:
            reasons.append(f"target {off:.1f}° off the optical axis")
        if tilt > self.view.max_tilt_deg + 0.05:
            reasons.append(f"board tilted {tilt:.1f}°")
        in_image = True
        if self.view.intrinsics is not None:
            P = (X_CT[:3, :3] @ self.view.points.T).T + X_CT[:3, 3]
            uv, front, inside = project_points(P, self.view.intrinsics)
            k = self.view.intrinsics
            m = self.view.margin_px
            uv = np.asarray(uv)
            in_image = bool(np.all(front) and np.all(uv[:, 0] >= m) and np.all(uv[:, 1] >= m)
                            and np.all(uv[:, 0] <= k.width - 1 - m)
                            and np.all(uv[:, 1] <= k.height - 1 - m))
            if not in_image:
                reasons.append("target points outside the image")
        return Feasibility(within, d, pair, dist, off, tilt, in_image, reasons)

    def in_view(self, X_BE, X_HC=None, X_FT=None) -> bool:
        """Every target point in front of the camera and inside the image by ``margin_px`` at the
        flange pose X_BE, with the given (or the planner's) camera and target poses."""
        X_HC = self.X_HC if X_HC is None else np.asarray(X_HC, float)
        X_FT = self.X_FT if X_FT is None else np.asarray(X_FT, float)
        if self.mode == "eye_in_hand":
            X_CT = inverse(np.asarray(X_BE) @ X_HC) @ X_FT
        else:
            X_CT = inverse(X_HC) @ np.asarray(X_BE) @ X_FT
        k, m = self.view.intrinsics, self.view.margin_px
        P = (X_CT[:3, :3] @ self.view.points.T).T + X_CT[:3, 3]
        if k is None:
            c = X_CT[:3, :3] @ self.view.center + X_CT[:3, 3]
            return bool(c[2] > 0 and math.atan2(np.linalg.norm(c[:2]), c[2]) <= self.view.cone_rad)
        uv, front, _ = project_points(P, k)
        uv = np.asarray(uv)
        return bool(np.all(front) and np.all(uv[:, 0] >= m) and np.all(uv[:, 1] >= m)
                    and np.all(uv[:, 0] <= k.width - 1 - m) and np.all(uv[:, 1] <= k.height - 1 - m))

    # ------------------------------------------------------------------------------- IK
    def _corner_points(self):
        """The target points each held in view by a gaze cone (with intrinsics and several)."""
        if self.view.intrinsics is None or len(self.view.points) < 2:
            return []
        return list(self.view.points)

    def _image_cone(self) -> float:
        """Half-angle of the cone inscribed in the image, less the margin (rad): a target point
        inside it is inside the image (conservative: the image's corners are left out)."""
        k, m = self.view.intrinsics, self.view.margin_px
        return 0.95 * min(math.atan2(k.width / 2 - m, k.alpha_u),
                          math.atan2(k.height / 2 - m, k.alpha_v))

    def _desired_X_BE(self, rng):
        """A random viewpoint satisfying the view spec: (X_BE desired, )."""
        lo, hi = self.view.distance_range_m
        d = rng.uniform(lo, hi)
        max_tilt = math.radians(self.view.max_tilt_deg)
        # Uniform on the spherical cap of the tilt (cos θ uniform).
        tilt = math.acos(rng.uniform(math.cos(max_tilt), 1.0))
        az = rng.uniform(0.0, 2 * math.pi)
        roll = rng.uniform(-math.pi, math.pi)
        dir_T = np.array([math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az),
                          math.cos(tilt)])
        if self.mode == "eye_in_hand":
            X_BT = self.X_FT
            p_BTc = X_BT[:3, :3] @ self.view.center + X_BT[:3, 3]
            z_B = X_BT[:3, :3] @ dir_T          # the optical axis, into the board
            X_BC = make_transform(_look_rotation(z_B, roll), p_BTc - d * z_B)
            return X_BC @ inverse(self.X_HC)
        # Eye-to-hand: the board centre on a ray inside 60 % of the cone, the board turned so
        # that z_T makes the tilt with the ray (dir_T is the ray in T), rolled about it.
        X_BC = self.X_HC
        cone = 0.6 * self.view.cone_rad
        a = math.acos(rng.uniform(math.cos(cone), 1.0))
        b = rng.uniform(0, 2 * math.pi)
        ray_C = np.array([math.sin(a) * math.cos(b), math.sin(a) * math.sin(b), math.cos(a)])
        ray_B = X_BC[:3, :3] @ ray_C
        p_BTc = X_BC[:3, 3] + d * ray_B
        # R_BT with R_BT dir_T = ray_B: look rotation of the ray times the inverse of dir_T's.
        R_BT = _look_rotation(ray_B, roll) @ _look_rotation(dir_T, 0.0).T
        X_BT = make_transform(R_BT, p_BTc - R_BT @ self.view.center)
        return X_BT @ inverse(self.X_FT)

    def solve_ik(self, X_BE_desired=None, q_seed=None, position_tolerance_m: float = 0.03,
                 angle_tolerance_deg: float = 10.0, collision: bool = True):
        """Inverse kinematics for one view: joint limits, the view (gaze cone, distance range,
        tilt), the minimum distance (``collision``), and, with ``X_BE_desired``, the flange
        within ``position_tolerance_m`` and ``angle_tolerance_deg`` of it; the cost is the
        squared distance to ``q_nominal``. Returns (q or None, solver succeeded)."""
        plant, W = self.plant, self.plant.world_frame()
        ik = InverseKinematics(plant, self.plant_context, with_joint_limits=True)
        q = ik.q()
        ee = self.ee_frame
        c_T = self.view.center
        lo, hi = self.view.distance_range_m
        if self.mode == "eye_in_hand":
            p_EC, z_E = self.X_HC[:3, 3], self.X_HC[:3, 2]
            p_BT = self.X_FT[:3, :3] @ c_T + self.X_FT[:3, 3]
            ik.AddGazeTargetConstraint(ee, p_EC, z_E, W, p_BT, self.view.cone_rad)
            for p_T in self._corner_points():
                ik.AddGazeTargetConstraint(ee, p_EC, z_E, W, self.X_FT[:3, :3] @ p_T
                                           + self.X_FT[:3, 3], self._image_cone())
            ik.AddPointToPointDistanceConstraint(ee, p_EC, W, p_BT, lo, hi)
            ik.AddAngleBetweenVectorsConstraint(W, self.X_FT[:3, 2], ee, z_E, 0.0,
                                                math.radians(self.view.max_tilt_deg))
        else:
            p_BC, z_B = self.X_HC[:3, 3], self.X_HC[:3, 2]
            p_ET = self.X_FT[:3, :3] @ c_T + self.X_FT[:3, 3]
            ik.AddGazeTargetConstraint(W, p_BC, z_B, ee, p_ET, self.view.cone_rad)
            for p_T in self._corner_points():
                ik.AddGazeTargetConstraint(W, p_BC, z_B, ee, self.X_FT[:3, :3] @ p_T
                                           + self.X_FT[:3, 3], self._image_cone())
            ik.AddPointToPointDistanceConstraint(W, p_BC, ee, p_ET, lo, hi)
            ik.AddAngleBetweenVectorsConstraint(W, z_B, ee, self.X_FT[:3, 2], 0.0,
                                                math.radians(self.view.max_tilt_deg))
        if collision:
            ik.AddMinimumDistanceLowerBoundConstraint(self.min_distance_m, 0.05)
        if X_BE_desired is not None:
            X = np.asarray(X_BE_desired, float)
            tol = position_tolerance_m
            ik.AddPositionConstraint(ee, np.zeros(3), W, X[:3, 3] - tol, X[:3, 3] + tol)
            ik.AddOrientationConstraint(W, RotationMatrix(X[:3, :3]), ee, RotationMatrix(),
                                        math.radians(angle_tolerance_deg))
        prog = ik.get_mutable_prog()
        prog.AddQuadraticErrorCost(np.eye(len(self.q_nominal)), self.q_nominal, q)
        seed = self.q_nominal if q_seed is None else np.asarray(q_seed, float)
        prog.SetInitialGuess(q, seed)
        result = Solve(prog, solver_options=_SOLVER_OPTIONS)
        if not result.is_success():
            return None, False
        return result.GetSolution(q), True

    def sample_candidates(self, n: int = 60, max_attempts: int | None = None,
                          rng=None) -> CandidateSet:
        """Up to ``n`` verified candidates from random viewpoints (``_desired_X_BE``), each solved
        from the nominal configuration and, if that fails, from a random one.

        Raises:
            InfeasibleError: no candidate at all, with the reason (the target out of reach, or
                no view without collision, or the view constraints).
        """
        if isinstance(n, bool) or int(n) != n or n < 1:
            raise ValueError(f"n: expected an integer ≥ 1, got {n!r}")
        self.check_reach()
        rng = self.rng if rng is None else rng
        max_attempts = 4 * n if max_attempts is None else int(max_attempts)
        qs, Xs = [], []
        rejected = Counter()
        attempts = 0
        while len(qs) < n and attempts < max_attempts:
            attempts += 1
            X_des = self._desired_X_BE(rng)
            q, ok = self.solve_ik(X_des, self.q_nominal)
            if not ok:
                lo, hi = self.lower, self.upper
                seed = np.clip(self.q_nominal + rng.normal(0, 0.6, len(self.q_nominal)), lo, hi)
                q, ok = self.solve_ik(X_des, seed)
            if not ok:
                rejected["IK found no solution"] += 1
                continue
            f = self.check(q)
            if not f.ok:
                rejected["; ".join(f.reasons)] += 1
                continue
            qs.append(q)
            Xs.append(self.X_BE(q))
        if not qs:
            raise InfeasibleError(self.diagnose(rejected, attempts))
        return CandidateSet(np.array(qs), np.array(Xs), attempts, rejected)

    def diagnose(self, rejected=None, attempts=0) -> str:
        """One line: why no view of the target was found."""
        what = f"no feasible view in {attempts} attempts" if attempts else "no feasible view"
        # Reachable at all (view constraints, no collision)?
        q, ok = self.solve_ik(None, self.q_nominal, collision=False)
        if not ok:
            reach = self._reach_hint()
            return (f"{what}: target out of reach — no joint configuration puts the camera "
                    f"{self.view.distance_range_m[0]:g}–{self.view.distance_range_m[1]:g} m from "
                    f"the target within {self.view.max_tilt_deg:g}° tilt{reach}")
        d, pair = self.min_distance(q)
        if d < self.min_distance_m:
            # The view the robot reaches collides (and the sampled views with the clearance
            # constraint all failed).
            how = (f"into {pair[1]} by {-1000 * d:.0f} mm" if d < 0 else
                   f"within {1000 * d:.0f} mm of {pair[1]}")
            return (f"{what}: no view without collision — IK with the clearance failed, and the "
                    f"view reached without it brings {pair[0]} {how} (minimum clearance "
                    f"{1000 * self.min_distance_m:g} mm)")
        common = rejected.most_common(1)[0][0] if rejected else "random viewpoints rejected"
        return (f"{what}: views exist near the nominal configuration but the sampled viewpoints "
                f"failed ({common}); widen the distance range or the tilt")

    def reach_bound_m(self) -> float:
        """An upper bound (m) of the flange origin's distance from the base origin over every
        configuration: the lengths of the kinematic chain's fixed offsets added up (revolute
        joints do not move a child's origin off its joint frame; a prismatic joint adds its
        largest travel). inf when the chain has a joint it cannot bound (floating)."""
        if getattr(self, "_reach", None) is not None:
            return self._reach
        plant = self.plant
        by_child = {}
        for j in plant.GetJointIndices():
            joint = plant.get_joint(j)
            by_child[joint.child_body().index()] = joint
        base_body = self.base_frame.body().index()
        total = float(np.linalg.norm(self.ee_frame.GetFixedPoseInBodyFrame().translation()))
        total += float(np.linalg.norm(self.base_frame.GetFixedPoseInBodyFrame().translation()))
        body = self.ee_frame.body().index()
        for _ in range(plant.num_bodies()):
            if body == base_body or body not in by_child:
                break
            joint = by_child[body]
            total += float(np.linalg.norm(joint.frame_on_parent().GetFixedPoseInBodyFrame()
                                          .translation()))
            total += float(np.linalg.norm(joint.frame_on_child().GetFixedPoseInBodyFrame()
                                          .translation()))
            kind = joint.type_name().lower()
            if "prismatic" in kind:
                lim = np.concatenate([joint.position_lower_limits(),
                                      joint.position_upper_limits()])
                total += float(np.max(np.abs(lim))) if np.all(np.isfinite(lim)) else math.inf
            elif "revolute" not in kind and "weld" not in kind:
                total = math.inf
            body = joint.parent_body().index()
        if body != base_body:
            total = math.inf          # the flange is not below the base in the tree
        self._reach = total
        return total

    def check_reach(self) -> None:
        """InfeasibleError at once (no IK) when no configuration can bring the camera within
        the distance range of the target: the target (eye-in-hand) or the camera (eye-to-hand)
        farther from the base than the arm's reach, the hand-eye offset and the range allow."""
        reach = self.reach_bound_m()
        if not math.isfinite(reach):
            return
        hi = self.view.distance_range_m[1]
        if self.mode == "eye_in_hand":
            p = self.X_FT[:3, :3] @ self.view.center + self.X_FT[:3, 3]
            carried = float(np.linalg.norm(self.X_HC[:3, 3]))
            what, offset = "target centre", "camera"
        else:
            p = self.X_HC[:3, 3]
            carried = float(np.linalg.norm(self.X_FT[:3, :3] @ self.view.center
                                           + self.X_FT[:3, 3]))
            what, offset = "camera", "target"
        far = float(np.linalg.norm(p))
        if far - hi > reach + carried:
            raise InfeasibleError(
                f"target out of reach: the {what} is {far:.2f} m from the base origin, but the "
                f"arm's flange reaches at most {reach:.2f} m (its link offsets added up), "
                f"{reach + carried + hi:.2f} m with the {offset} offset and the {hi:g} m "
                "viewing distance — check --target / --hand-eye (units, frame)")

    def _reach_hint(self) -> str:
        if self.mode != "eye_in_hand":
            return ""
        p = self.X_FT[:3, :3] @ self.view.center + self.X_FT[:3, 3]
        return f" (target centre {np.linalg.norm(p):.2f} m from the base origin)"

    # -------------------------------------------------------------------------- ranking
    def rank(self, candidates: CandidateSet, n: int, samples_X_BE=(), X_HC=None, X_FT=None,
             rotation_sigma: float = 0.002, translation_sigma: float = 0.001):
        """The D-optimal choice of ``n`` candidates (``estimation.planning.plan_next_poses``) with
        the given or the planner's own camera/target poses; returns its ``Plan``."""
        if len(candidates) == 0:
            raise InfeasibleError("candidates: the candidate set is empty — nothing to rank")
        X_HC = self.X_HC if X_HC is None else X_HC
        X_FT = self.X_FT if X_FT is None else X_FT
        return plan_next_poses(candidates.X_BE, inverse(X_HC), X_FT, samples_X_BE,
                               rotation_sigma, translation_sigma, n=min(n, len(candidates)),
                               mode=self.mode)

    # ------------------------------------------------------------------------------ tour
    def joint_distance(self, q1, q2) -> float:
        """Time-like distance: the largest joint move over its velocity limit (s)."""
        return float(np.max(np.abs(np.asarray(q2) - np.asarray(q1)) / self.velocity_limits))

    def order_tour(self, q_start, Q) -> list:
        """Indices of the configurations ``Q`` in a short visiting order from ``q_start``:
        nearest neighbour, then 2-opt on the joint distance (open tour)."""
        Q = np.asarray(Q, float)
        if len(Q) == 0:
            return []
        left = list(range(len(Q)))
        order, cur = [], np.asarray(q_start, float)
        while left:
            k = min(left, key=lambda i: self.joint_distance(cur, Q[i]))
            order.append(k)
            left.remove(k)
            cur = Q[k]
        pts = [np.asarray(q_start, float)] + [Q[i] for i in order]

        def length(p):
            return sum(self.joint_distance(p[i], p[i + 1]) for i in range(len(p) - 1))

        improved = True
        while improved:
            improved = False
            for i in range(1, len(pts) - 1):
                for j in range(i + 1, len(pts)):
                    new = pts[:i] + pts[i:j + 1][::-1] + pts[j + 1:]
                    if length(new) < length(pts) - 1e-9:
                        pts, order = new, order[:i - 1] + order[i - 1:j][::-1] + order[j:]
                        improved = True
        return order

    def segment(self, q0, q1, max_speed_fraction: float = 0.5,
                max_acceleration: float = 2.0):
        """(duration s, s(τ) samples) of a rest-to-rest straight joint move with a quintic time
        law: peak speed 1.875 |Δq|/T ≤ fraction × the velocity limit, peak acceleration
        5.77 |Δq|/T² ≤ ``max_acceleration`` (rad/s²)."""
        dq = np.abs(np.asarray(q1) - np.asarray(q0))
        v = max_speed_fraction * self.velocity_limits
        T = max(float(np.max(1.875 * dq / v)), float(np.sqrt(np.max(5.7735 * dq)
                                                              / max_acceleration)), 0.2)
        return T

    def check_segment(self, q0, q1, step_rad: float = 0.01):
        """(smallest signed distance (m), geometry pair) along the straight joint move q0 → q1,
        checked every ``step_rad`` of the largest joint's motion (both ends included)."""
        q0, q1 = np.asarray(q0, float), np.asarray(q1, float)
        k = max(int(math.ceil(np.max(np.abs(q1 - q0)) / step_rad)), 1)
        best = (math.inf, ("", ""))
        for s in np.linspace(0.0, 1.0, k + 1):
            d = self.min_distance(q0 + s * (q1 - q0))
            if d[0] < best[0]:
                best = d
        return best

    def plan_tour(self, q_start, Q, dwell_s: float = 1.0, step_rad: float = 0.01,
                  order=None) -> Tour:
        """A collision-free trajectory from ``q_start`` through the configurations ``Q`` in a short
        order (``order_tour`` unless given). A straight joint move that comes closer than
        ``min_distance_m`` to a collision is routed back through ``q_start``; a pose that cannot be
        reached either way is dropped (``Tour.dropped``). Rest-to-rest quintic moves (``segment``),
        ``dwell_s`` at each pose for the image."""
        Q = np.asarray(Q, float)
        q_start = np.asarray(q_start, float)
        order = self.order_tour(q_start, Q) if order is None else list(order)
        way, kept, dropped, detours = [q_start], [], [], 0
        worst = self.min_distance(q_start)[0]
        ok_d = self.min_distance_m - 1e-4
        for i in order:
            cur = way[-1]
            d = self.check_segment(cur, Q[i], step_rad)[0]
            if d >= ok_d:
                way.append(Q[i])
            else:
                d1 = self.check_segment(cur, q_start, step_rad)[0]
                d2 = self.check_segment(q_start, Q[i], step_rad)[0]
                if min(d1, d2) < ok_d:
                    dropped.append(int(i))
                    continue
                detours += 1
                d = min(d1, d2)
                if not np.allclose(cur, q_start):
                    way.append(q_start)
                way.append(Q[i])
            worst = min(worst, d)
            kept.append(int(i))
        traj, times = self._trajectory(way, dwell_s)
        # The time each kept pose is reached: the waypoints that are poses (not the start).
        pose_times, j = [], 1
        for i in kept:
            while not np.allclose(way[j], Q[i]):
                j += 1
            pose_times.append(times[j])
            j += 1
        return Tour(kept, np.array(way), traj, pose_times, float(worst), dropped, detours,
                    step_rad)

    def _trajectory(self, way, dwell_s):
        """PiecewisePolynomial through the waypoints (cubic Hermite on dense quintic samples,
        exact positions and velocities at the samples) and the arrival time of each."""
        ts, qs, vs, arrive = [0.0], [way[0]], [np.zeros_like(way[0])], [0.0]
        t = 0.0
        for a, b in zip(way[:-1], way[1:]):
            if np.allclose(a, b):
                arrive.append(t)
                continue
            T = self.segment(a, b)
            for s in np.linspace(0, 1, 21)[1:]:
                h = 10 * s**3 - 15 * s**4 + 6 * s**5
                hd = (30 * s**2 - 60 * s**3 + 30 * s**4) / T
                ts.append(t + s * T)
                qs.append(a + h * (b - a))
                vs.append(hd * (b - a))
            t += T
            arrive.append(t)
            if dwell_s > 0:
                t += dwell_s
                ts.append(t)
                qs.append(b)
                vs.append(np.zeros_like(b))
        if len(ts) == 1:
            ts.append(1e-3)
            qs.append(way[0])
            vs.append(np.zeros_like(way[0]))
        traj = PiecewisePolynomial.CubicHermite(np.array(ts), np.array(qs).T, np.array(vs).T)
        return traj, arrive

    def check_trajectory(self, traj, step_rad: float = 0.01):
        """(smallest signed distance (m), its time s, geometry pair) along q(t), sampled so that no
        joint moves more than ``step_rad`` between samples (velocity limit × dt)."""
        dt = step_rad / float(np.max(self.velocity_limits))
        ts = np.arange(traj.start_time(), traj.end_time() + dt, dt)
        best = (math.inf, 0.0, ("", ""))
        for t in ts:
            d, pair = self.min_distance(traj.value(min(t, traj.end_time())).ravel())
            if d < best[0]:
                best = (d, float(t), pair)
        return best


def as_session_planner(planner: FeasiblePlanner, candidates: CandidateSet, q_start=None,
                       rotation_sigma: float = 0.002, translation_sigma: float = 0.001,
                       replan_after: int | None = None):
    """A next-pose callable for ``calibration.session.CalibrationSession``: at each call, the
    D-optimal best of the not yet visited feasible candidates given the samples so far and the
    current estimates (or the planner's own poses before any), with its joint configuration and
    the collision-free path to it from the previous suggestion.

    The callable takes ``(samples_X_BE, X_H, X_F, rotation_sigma, translation_sigma)`` (X_H:
    X_EC or X_BC; X_F: X_BT or X_ET; None before an estimate) and returns a dict with
    ``X_BE`` (4×4), ``q`` (rad), ``index``, ``path`` (the joint configurations to move through:
    the pose, or the start configuration then the pose when the straight move is not clear) and
    ``min_path_distance_m`` (the smallest clearance along it, m); or None when every candidate
    has been visited. With an estimate X_H and intrinsics, candidates whose image would not hold
    every target point by the margin through that estimate are passed over.

    ``replan_after`` = N: once N samples are in and an estimate X_H exists, the IK of every
    unvisited candidate is solved again (once) with the estimate as the camera mount: the flange
    pose that puts the camera where the candidate's view was aimed through the planner's rough
    mount (X_BE X_HC_rough = X_BE' X_H; eye-in-hand only), within 5 mm / 1°, joint limits, clearance and the view
    re-checked through the estimate; a candidate whose re-solve fails keeps its old solution.
    The planner's rough mount aims the views a few degrees off (the 60 px image margin absorbs
    it); re-solved views are centred as intended. ``candidates`` itself is not modified (the
    callable works on a copy, ``next_pose.candidates``); ``next_pose.replanned`` counts the
    candidates re-solved."""
    if replan_after is not None and (isinstance(replan_after, bool)
                                     or not isinstance(replan_after, int) or replan_after < 1):
        raise ValueError(f"replan_after: expected None or an integer ≥ 1, got {replan_after!r}")
    if replan_after is not None and planner.mode != "eye_in_hand":
        raise ValueError("replan_after: re-solving with the estimated mount is for eye-in-hand")
    visited = set()
    state = {"q": planner.q_nominal if q_start is None else np.asarray(q_start, float),
             "replanned": False}
    candidates = CandidateSet(np.array(candidates.q, float), np.array(candidates.X_BE, float),
                              candidates.attempts, candidates.rejected)

    def resolve(X_H, free):
        X_rough = planner.X_HC
        planner.X_HC = np.asarray(X_H, float)   # the view constraints and checks use it
        count = 0
        try:
            for i in free:
                X_des = candidates.X_BE[i] @ X_rough @ inverse(planner.X_HC)
                q, ok = planner.solve_ik(X_des, candidates.q[i], position_tolerance_m=0.005,
                                         angle_tolerance_deg=1.0)
                if ok and planner.check(q).ok:
                    candidates.q[i] = q
                    candidates.X_BE[i] = planner.X_BE(q)
                    count += 1
        finally:
            planner.X_HC = X_rough
        next_pose.replanned = count

    def next_pose(samples_X_BE, X_H=None, X_F=None, rotation_sigma=rotation_sigma,
                  translation_sigma=translation_sigma):
        # A candidate a sample already lies at (e.g. after a resumed session) is visited.
        for X in samples_X_BE:
            near = np.linalg.norm(candidates.X_BE[:, :3, 3] - np.asarray(X)[:3, 3], axis=1)
            for i in np.flatnonzero(near < 0.002):
                if rotation_angle(candidates.X_BE[i, :3, :3].T @ np.asarray(X)[:3, :3]) < 0.01:
                    visited.add(int(i))
        free = [i for i in range(len(candidates)) if i not in visited]
        if not free:
            return None
        if (replan_after is not None and not state["replanned"] and X_H is not None
                and len(samples_X_BE) >= replan_after):
            state["replanned"] = True
            resolve(X_H, free)
        X_HC = planner.X_HC if X_H is None else X_H
        X_FT = planner.X_FT if X_F is None else X_F
        visible = np.zeros(len(candidates), bool)
        visible[free] = True
        if X_H is not None and planner.view.intrinsics is not None:
            # With an estimate of the mount, keep the candidates whose image holds the target
            # by the margin through the estimate (the IK aimed them with the rough mount).
            seen = np.array([planner.in_view(candidates.X_BE[i], X_HC, X_FT) for i in free])
            if seen.any():
                visible[np.asarray(free)[~seen]] = False
        order = plan_next_poses(candidates.X_BE, inverse(X_HC), X_FT, samples_X_BE,
                                rotation_sigma, translation_sigma, n=min(3, len(free)),
                                mode=planner.mode, visibility=visible, exchange=False).indices
        for i in order:
            d = planner.check_segment(state["q"], candidates.q[i])[0]
            path = [candidates.q[i]]
            if d < planner.min_distance_m - 1e-4:
                d1 = planner.check_segment(state["q"], planner.q_nominal)[0]
                d2 = planner.check_segment(planner.q_nominal, candidates.q[i])[0]
                if min(d1, d2) < planner.min_distance_m - 1e-4:
                    continue
                d, path = min(d1, d2), [planner.q_nominal, candidates.q[i]]
            visited.add(int(i))
            state["q"] = candidates.q[i]
            return {"X_BE": candidates.X_BE[i], "q": candidates.q[i], "index": int(i),
                    "path": path, "min_path_distance_m": float(d)}
        visited.update(int(i) for i in order)   # unreachable from here: try the next ones
        return next_pose(samples_X_BE, X_H, X_F, rotation_sigma, translation_sigma)

    next_pose.replanned = 0
    next_pose.candidates = candidates
    return next_pose


__all__ = ["CandidateSet", "FeasiblePlanner", "Feasibility", "InfeasibleError", "Tour",
           "UR5E_HOME_Q", "ViewSpec", "as_session_planner"]

"""``planning.FeasiblePlanner``: IK candidates that respect the joint limits, the clearance and the
view; collisions found on known-colliding poses; tours checked densely; eye-to-hand; refusals as
one-line reasons; ``handeye-drake plan --feasible``."""

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from handeye_drake.apps.cli import main
from handeye_drake.estimation.se3 import make_transform, rotation_angle, rotation_exp
from handeye_drake.planning import (CandidateSet, Cell, FeasiblePlanner, InfeasibleError,
                                    ViewSpec)
from handeye_drake.planning.cell import Box, load_cell
from handeye_drake.planning.feasible import UR5E_HOME_Q
from handeye_drake.systems.arm import UR5E_URDF
from handeye_drake.vision.camera_model import CameraIntrinsics

FACE_UP = rotation_exp(np.array([math.pi, 0.0, 0.0]))
X_EC = make_transform(rotation_exp(np.array([0.0, 0.0, math.pi / 2])), [0.0, -0.05, 0.04])
X_BT = make_transform(FACE_UP, [-0.45, -0.15, 0.0])
K = CameraIntrinsics(alpha_u=800, alpha_v=800, u0=320, v0=240, width=640, height=480)
BOARD = np.array([[x, y, 0.0] for x in (0, 0.2) for y in (0, 0.15)])
HAND_EYE = "0,-0.05,0.04,0,0,0.7071068,0.7071068"


@pytest.fixture(scope="module")
def planner():
    return FeasiblePlanner("eye_in_hand", X_EC, X_BT, view=ViewSpec(
        distance_range_m=(0.3, 0.6), max_tilt_deg=35, intrinsics=K, target_points=BOARD),
        min_distance_m=0.015, seed=1)


def test_candidates_respect_limits_clearance_and_view(planner):
    c = planner.sample_candidates(6)
    assert len(c) == 6 and c.q.shape == (6, 6) and c.X_BE.shape == (6, 4, 4)
    for q, X in zip(c.q, c.X_BE):
        f = planner.check(q)
        assert f.ok, f.reasons
        assert np.all(q >= planner.lower) and np.all(q <= planner.upper)
        assert f.min_distance_m >= 0.015 - 1e-4
        assert 0.3 - 1e-3 <= f.target_distance_m <= 0.6 + 1e-3 and f.tilt_deg <= 35.05
        assert f.in_image
        assert np.allclose(planner.X_BE(q), X)
        # The view, recomputed here from the flange pose and the mount: every corner in front of
        # the camera and inside the image.
        X_CB = np.linalg.inv(X @ X_EC)
        P = (X_CB[:3, :3] @ (X_BT[:3, :3] @ BOARD.T + X_BT[:3, 3:])).T + X_CB[:3, 3]
        u = 800 * P[:, 0] / P[:, 2] + 320
        v = 800 * P[:, 1] / P[:, 2] + 240
        assert np.all(P[:, 2] > 0) and np.all((u > 0) & (u < 640) & (v > 0) & (v < 480))


def test_known_colliding_poses_are_found(planner):
    into_floor = np.array([0.0, 0.6, 0.0, -1.57, -1.57, 0.0])   # upper arm below the table
    f = planner.check(into_floor)
    assert not f.ok and f.min_distance_m < 0 and "floor" in f.closest_pair
    folded = np.array([0.0, -1.57, 2.9, -1.57, -1.57, 0.0])     # forearm folded onto the shoulder
    assert not planner.check(folded).ok
    pairs = {frozenset(p[:2]) for p in planner.colliding_pairs(folded)}
    assert frozenset({"shoulder_link/Cylinder", "forearm_link/Capsule"}) in pairs
    assert planner.check(UR5E_HOME_Q).min_distance_m > 0.015
    # The dense segment check sees the collision between two collision-free ends.
    d, _ = planner.check_segment(UR5E_HOME_Q, into_floor)
    assert d < 0
    over = UR5E_HOME_Q.copy()
    over[1] = -np.pi / 2 + 2.3       # the same joint swept through the floor and back up
    assert planner.check_segment(UR5E_HOME_Q, over)[0] < 0


def test_a_box_in_the_cell_is_an_obstacle():
    box = Cell(0.0, (Box("post", (-0.49, -0.13, 0.40), (0.1, 0.1, 0.1)),))
    p = FeasiblePlanner("eye_in_hand", X_EC, X_BT, cell=box)
    f = p.check(UR5E_HOME_Q)     # the flange sits just above the post's top
    assert not f.ok and "box_post" in f.closest_pair


def test_tour_is_collision_free_when_checked_densely(planner):
    c = planner.sample_candidates(5)
    tour = planner.plan_tour(UR5E_HOME_Q, c.q)
    assert sorted(tour.order + tour.dropped) == list(range(5))
    d, t, pair = planner.check_trajectory(tour.trajectory, step_rad=0.01)
    assert d >= planner.min_distance_m - 1e-3, (d, t, pair)
    for i, t in zip(tour.order, tour.pose_times):
        assert np.allclose(tour.trajectory.value(t).ravel(), c.q[i], atol=1e-9)
    # Joint speeds within half the limits.
    dq = tour.trajectory.derivative(1)
    ts = np.linspace(0, tour.duration_s, 400)
    assert max(np.max(np.abs(dq.value(t))) for t in ts) <= 0.5 * math.pi * 1.01


def test_eye_to_hand_views_the_board_on_the_flange():
    X_BC = make_transform(rotation_exp(np.array([0.0, math.pi * 0.75, 0.0])) @ rotation_exp(
        np.array([0.0, 0.0, math.pi / 2])), [-0.9, -0.2, 0.8])
    X_ET = make_transform(FACE_UP, [-0.05, -0.05, 0.01])
    p = FeasiblePlanner("eye_to_hand", X_BC, X_ET, view=ViewSpec(distance_range_m=(0.4, 0.8)),
                        seed=2)
    c = p.sample_candidates(3)
    for q in c.q:
        f = p.check(q)
        assert f.ok and 0.4 - 1e-3 <= f.target_distance_m <= 0.8 + 1e-3
        X_BC_, X_BT_ = p.camera_target(q)
        assert np.allclose(X_BC_, X_BC)


def test_unreachable_target_is_one_line():
    far = make_transform(FACE_UP, [3.0, 0.0, 0.0])
    p = FeasiblePlanner("eye_in_hand", X_EC, far)
    with pytest.raises(InfeasibleError, match="target out of reach") as e:
        p.sample_candidates(2, max_attempts=2)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("mode, where", [("eye_in_hand", [7.0, 0.0, 0.0]),
                                         ("eye_in_hand", [0.0, -2.5, 1.0]),
                                         ("eye_to_hand", [0.0, 6.0, 0.5])])
def test_far_beyond_reach_is_refused_by_the_reach_bound_before_any_ik(mode, where):
    """Issue 37: a target 7 m away was refused only after ~50 s of IK. The reach bound (the
    chain's offsets added up) refuses it before any IK problem: IK is made to fail loudly."""
    if mode == "eye_in_hand":
        p = FeasiblePlanner(mode, X_EC, make_transform(FACE_UP, where))
    else:
        p = FeasiblePlanner(mode, make_transform(FACE_UP, where), X_EC)
    # The bound is an upper bound of the reach: no sampled configuration exceeds it.
    rng = np.random.default_rng(0)
    reach = p.reach_bound_m()
    assert max(np.linalg.norm(p.X_BE(rng.uniform(p.lower, p.upper))[:3, 3])
               for _ in range(200)) <= reach
    p.solve_ik = None           # any IK call would raise TypeError
    with pytest.raises(InfeasibleError, match="target out of reach") as e:
        p.sample_candidates(2, max_attempts=2)
    assert "\n" not in str(e.value) and "m from the base origin" in str(e.value)


def test_no_view_without_collision_is_one_line():
    # The board under a big box: every view of it puts the camera into the box.
    roof = Cell(0.0, (Box("roof", (-0.45, -0.15, 0.25), (1.2, 1.2, 0.3)),))
    p = FeasiblePlanner("eye_in_hand", X_EC, X_BT, cell=roof, q_nominal=UR5E_HOME_Q)
    with pytest.raises(InfeasibleError, match="collision") as e:
        p.sample_candidates(2, max_attempts=1)
    assert "\n" not in str(e.value)


def test_empty_candidate_set_is_refused(planner):
    empty = CandidateSet(np.zeros((0, 6)), np.zeros((0, 4, 4)), 0, {})
    with pytest.raises(InfeasibleError, match="candidate set is empty"):
        planner.rank(empty, 3)


def test_model_without_the_named_frames_or_collision_geometry(tmp_path):
    with pytest.raises(ValueError, match=r"ee_frame.*no frame named 'flange'.*tool0"):
        FeasiblePlanner("eye_in_hand", X_EC, X_BT, ee_frame="flange")
    bare = tmp_path / "bare.urdf"
    bare.write_text(re.sub(r"<collision>.*?</collision>", "", Path(UR5E_URDF).read_text()))
    with pytest.raises(ValueError, match="no collision geometry"):
        FeasiblePlanner("eye_in_hand", X_EC, X_BT, urdf=bare)


def test_cell_yaml(tmp_path):
    y = tmp_path / "cell.yaml"
    y.write_text("floor_z: -0.01\nboxes:\n  - {name: post, center: [0.5, 0, 0.1], "
                 "size: [0.1, 0.1, 0.2]}\n")
    c = load_cell(y)
    assert c.floor_z == -0.01 and c.boxes[0].name == "post" and c.boxes[0].size == (0.1, 0.1, 0.2)
    y.write_text("boxes:\n  - {center: [0.5, 0], size: [0.1, 0.1, 0.2]}\n")
    with pytest.raises(ValueError, match=r"boxes\[0\].center: expected 3"):
        load_cell(y)


def test_cli_writes_joints_trajectory_and_preview(tmp_path, capsys):
    out = tmp_path / "plan"
    code = main(["plan", "--feasible", f"--hand-eye={HAND_EYE}", "--target=-0.45,-0.15,0",
                 "--intrinsics", "800,800,320,240,640,480", "--board", "0.2,0.15",
                 "--n", "3", "--num-candidates", "6", "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    assert "verified candidates" in text and "smallest clearance" in text
    joints = json.loads((out / "joints.json").read_text())
    assert len(joints["poses"]) == 3 and len(joints["poses"][0]["q_rad"]) == 6
    rows = (out / "joints.csv").read_text().splitlines()
    assert rows[0].startswith("rank,shoulder_pan_joint_rad") and len(rows) == 4
    traj = np.loadtxt(out / "trajectory.csv", delimiter=",", skiprows=1)
    assert traj.shape[1] == 7 and np.all(np.diff(traj[:, 0]) > 0)
    plan = json.loads((out / "plan.json").read_text())
    assert plan["trajectory"]["min_clearance_m"] >= 0.01 - 1e-3
    assert "<html" in (out / "tour.html").read_text()[:2000].lower()
    assert (out / "tour.png").stat().st_size > 10000


@pytest.mark.parametrize("argv, message", [
    (["--target=3,0,0"], "target out of reach"),
    (["--target=-0.45,-0.15,0", "--ee-frame", "flange"], "no frame named 'flange'"),
    (["--target=-0.45,-0.15,0", "--distance-range", "0.5,0.2"], "--distance-range"),
    (["--target=-0.45,-0.15,0", "--candidates", "x.tum"], "drop --candidates"),
])
def test_cli_refusals_are_one_line(tmp_path, capsys, argv, message):
    code = main(["plan", "--feasible", f"--hand-eye={HAND_EYE}", "--no-preview",
                 "--num-candidates", "2", "--out", str(tmp_path / "o"), *argv])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1, err


def test_nothing_below_the_applications_imports_the_planner():
    from tests.calibration.test_api import _import_graph
    graph = _import_graph()
    users = {m for m, deps in graph.items() if any(d.startswith("handeye_drake.planning")
                                                  for d in deps)}
    assert users and all(m.startswith(("handeye_drake.apps", "handeye_drake.planning"))
                         for m in users), users
    # The planner floor imports estimation, vision and systems, never calibration or apps.
    for m, deps in graph.items():
        if m.startswith("handeye_drake.planning"):
            assert not any(d.startswith(("handeye_drake.apps", "handeye_drake.calibration"))
                           for d in deps), (m, deps)


def test_the_session_visits_only_feasible_poses_and_stops(planner):
    from handeye_drake.calibration import CalibrationOptions
    from handeye_drake.calibration.session import CalibrationSession
    from handeye_drake.estimation.se3 import inverse
    from handeye_drake.planning import as_session_planner
    cands = planner.sample_candidates(25)
    next_pose = as_session_planner(planner, cands)
    s = CalibrationSession(0.3, 1.5, CalibrationOptions(robot_accuracy_deg=0.01,
                                                        robot_accuracy_mm=0.05),
                           next_pose=next_pose)
    rng = np.random.default_rng(0)
    pose = next_pose([], None, None)
    q_prev = planner.q_nominal
    for _ in range(25):
        assert planner.check(pose["q"]).ok
        assert planner.check_segment(q_prev, pose["q"])[0] >= planner.min_distance_m - 1e-4 \
            or len(pose["path"]) == 2
        X_BE = planner.X_BE(pose["q"])
        X_CT = inverse(X_BE @ X_EC) @ X_BT
        X_CT = make_transform(rotation_exp(rng.normal(0, 5e-4, 3)) @ X_CT[:3, :3],
                              X_CT[:3, 3] + rng.normal(0, 3e-4, 3))
        step = s.add(X_BE, X_CT)
        if step.stop:
            break
        q_prev, pose = pose["q"], step.next_pose
    assert step.stop and step.next_pose is None


def test_cli_session_suggests_feasible_poses(tmp_path, capsys):
    from tests.calibration.test_session import _line, samples
    f = tmp_path / "samples.txt"
    f.write_text("\n".join(_line(*x) for x in samples(3, seed=1)) + "\n")
    code = main(["session", "--samples", str(f), "--feasible", "--num-candidates", "5",
                 f"--hand-eye={HAND_EYE}", "--target=-0.45,-0.15,0",
                 "--intrinsics", "800,800,320,240,640,480", "--board", "0.2,0.15",
                 "--out", str(tmp_path / "o")])
    text = capsys.readouterr().out
    assert code == 1      # three samples: the input ends before the target
    assert "planner: 5 reachable, collision-free views" in text
    nexts = [line for line in text.splitlines() if "next: X_BE" in line]
    assert len(nexts) == 4 and all(" q [" in line for line in nexts)


def test_replan_re_solves_the_views_with_the_estimated_mount(planner):
    """The planner aims its views with a rough mount; with the true mount as the estimate,
    re-solved candidates put the camera where the rough mount aimed it, and the caller's
    candidate set is left as it was."""
    from handeye_drake.planning import as_session_planner
    cands = planner.sample_candidates(6)
    before = cands.X_BE.copy()
    X_true = X_EC @ make_transform(rotation_exp(np.radians([2.0, -1.5, 1.0])), [0.006, 0, -0.004])
    next_pose = as_session_planner(planner, cands, replan_after=2)
    with pytest.raises(ValueError, match="replan_after"):
        as_session_planner(planner, cands, replan_after=0)
    first = next_pose([], None, None)
    assert next_pose.replanned == 0
    second = next_pose([first["X_BE"]], X_true, X_BT)
    assert next_pose.replanned == 0                       # one sample < replan_after
    third = next_pose([first["X_BE"], second["X_BE"]], X_true, X_BT)
    assert 1 <= next_pose.replanned <= 4
    assert np.array_equal(cands.X_BE, before)             # the caller's set untouched
    new = next_pose.candidates
    changed = [i for i in range(len(cands)) if not np.allclose(new.X_BE[i], before[i])]
    assert len(changed) == next_pose.replanned
    for i in changed:
        # The re-solved flange pose puts the true camera (nearly) where the rough one was aimed:
        # within the IK's 5 mm box and 1° of X_BE' = X_BE X_EC_rough inv(X_EC_estimate).
        aimed, got = before[i] @ X_EC @ np.linalg.inv(X_true), new.X_BE[i]
        assert np.linalg.norm(got[:3, 3] - aimed[:3, 3]) <= 0.0051 * math.sqrt(3)
        assert math.degrees(rotation_angle(got[:3, :3].T @ aimed[:3, :3])) <= 1.01
        f = planner.check(new.q[i])               # limits and clearance (view: rough mount)
        assert f.within_limits and f.min_distance_m >= planner.min_distance_m - 1e-4
        assert planner.in_view(new.X_BE[i], X_true, X_BT)   # the view through the estimate
        assert np.allclose(planner.X_BE(new.q[i]), new.X_BE[i])
    assert third["index"] not in (first["index"], second["index"])

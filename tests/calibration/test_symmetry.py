"""A board that looks the same after a turn: the robot's motion decides which way round it is in
each view (calibration/symmetry.py), in both modes; a recording whose motions cannot decide says
so instead of answering."""

import math

import numpy as np
import pytest

from handeye_drake.calibration.symmetry import resolve
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp
from handeye_drake.vision.targets import target_symmetries

X_EC = make_transform(rotation_exp([0.05, -0.04, 1.6]), [0.04, -0.05, 0.07])
X_BT = make_transform(rotation_exp([math.pi, 0.0, 0.2]), [0.5, -0.1, 0.0])
X_BC = make_transform(rotation_exp([2.2, 0.3, 0.1]), [0.9, 0.4, 0.8])
X_ET = make_transform(rotation_exp([0.1, 0.05, -0.2]), [0.02, -0.03, 0.09])


def _views(mode, n, rng, roll_only=False):
    """(X_BE, true X_CT) of n views with realistic pose noise (0.05°, 0.3 mm robot; 0.02°,
    0.1 mm camera)."""
    X_BE, X_CT = [], []
    for k in range(n):
        if roll_only:   # the camera only turns about the board's normal, in quarter turns
            R = rotation_exp([0.0, 0.0, (k % 2) * math.pi / 2 + rng.normal(0, 0.01)])
            X = make_transform(R, [0.0, 0.0, 0.5]) @ make_transform(np.eye(3), [-0.1, -0.07, 0])
        else:
            R = rotation_exp(rng.normal(0, 0.35, 3) + [0.0, 0.0, rng.uniform(-math.pi, math.pi)])
            X = make_transform(R, rng.normal(0, 0.03, 3) + [0.0, 0.0, 0.5])
        if mode == "eye_in_hand":
            E = X_BT @ inverse(X) @ inverse(X_EC)
        else:
            E = X_BC @ X @ inverse(X_ET)
        noise = make_transform(rotation_exp(rng.normal(0, math.radians(0.05), 3)),
                               rng.normal(0, 0.0003, 3))
        X_BE.append(E @ noise)
        X_CT.append(X @ make_transform(rotation_exp(rng.normal(0, math.radians(0.02), 3)),
                                       rng.normal(0, 0.0001, 3)))
    return np.array(X_BE), np.array(X_CT)


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
@pytest.mark.parametrize("spec", ["chessboard:8x6:0.025", "chessboard:7x5:0.03",
                                  "circles:4x4:0.03"])
def test_the_robot_decides_every_view(mode, spec):
    rng = np.random.default_rng(7)
    X_BE, X_true = _views(mode, 14, rng)
    turns = np.array([np.eye(4)] + [G for G, _ in target_symmetries(spec)])
    # The detector labels about a third of the views from another end: X_CT = X_true · G.
    applied = rng.integers(0, len(turns), 14) * (rng.random(14) < 0.4)
    applied[0] = 0
    X_CT = np.einsum("nab,nbc->nac", X_true, turns[applied])
    labels, decided = resolve(X_BE, X_CT, turns, mode)
    np.testing.assert_array_equal(labels, applied)
    assert decided.all()
    # Each view relabelled is the true pose again.
    fixed = np.einsum("nab,nbc->nac", X_CT, np.array([inverse(turns[k]) for k in labels]))
    np.testing.assert_allclose(fixed, X_true, atol=1e-12)


def test_motions_that_turn_the_board_by_quarter_turns_cannot_decide():
    # Views at 0° and 90° about the board's normal, alternately: each group's views agree among
    # themselves, but turning one group by a half turn against the other costs nothing.
    rng = np.random.default_rng(2)
    X_BE, X_true = _views("eye_in_hand", 9, rng, roll_only=True)
    turns = np.array([np.eye(4)] + [G for G, _ in target_symmetries("chessboard:8x6:0.025")])
    labels, decided = resolve(X_BE, X_true, turns, "eye_in_hand")
    np.testing.assert_array_equal(decided, np.arange(9) % 2 == 0)   # the larger group
    np.testing.assert_array_equal(labels[decided], 0)


def test_an_undecidable_recording_is_refused_with_the_cause(tmp_path):
    from handeye_drake.calibration.inputs import Streams, resolve_symmetric_board
    from handeye_drake.recorded.formats import pose_stream
    from handeye_drake.vision.detection import TargetDetection
    from handeye_drake.vision.targets import object_points
    rng = np.random.default_rng(2)
    X_BE, X_CT = _views("eye_in_hand", 4, rng, roll_only=True)
    spec = "chessboard:8x6:0.025"
    ids, p = object_points(spec)
    dets = [TargetDetection(True, "", ids, np.zeros((len(ids), 2)), p, X, 0.1, np.eye(6), 0.1)
            for X in X_CT]
    streams = Streams(pose_stream(X_BE), pose_stream(X_CT), {"images": {"target": spec}},
                      detections=dets)
    with pytest.raises(ValueError, match=r"--target chessboard:8x6:0.025: the board looks the "
                                         r"same after a turn and the robot's motion decides "
                                         r"which way round it is in only 2 of 4 views"):
        resolve_symmetric_board(streams, "eye_in_hand")


def test_stamped_streams_pair_by_nearest_time_and_keep_the_robot_stream():
    """The bag path: the robot stream (tf, denser than the images) is kept whole; each image
    is judged against the robot pose nearest its stamp."""
    from handeye_drake.calibration.inputs import Streams, resolve_symmetric_board
    from handeye_drake.recorded.formats import pose_stream
    from handeye_drake.vision.detection import TargetDetection
    from handeye_drake.vision.targets import object_points
    rng = np.random.default_rng(4)
    spec = "chessboard:7x5:0.03"
    X_BE, X_true = _views("eye_in_hand", 10, rng)
    turns = np.array([np.eye(4)] + [G for G, _ in target_symmetries(spec)])
    flipped = np.arange(10) % 3 == 1
    X_CT = np.array([X @ turns[1] if f else X for X, f in zip(X_true, flipped)])
    stamps = 10.0 + np.arange(10) * 2.0
    # tf every 0.5 s: the pose at each image stamp, and others in between.
    robot_t = np.sort(np.concatenate([stamps, stamps + 0.5, stamps + 1.0]))
    robot = np.array([X_BE[min(int((t - 10.0 + 0.25) // 2.0), 9)] for t in robot_t])
    ids, p = object_points(spec)
    dets = [TargetDetection(True, "", ids, np.zeros((len(ids), 2)), p, X, 0.1, np.eye(6), 0.1)
            for X in X_CT]
    streams = Streams(pose_stream(robot, robot_t), pose_stream(X_CT, stamps),
                      {"images": {"target": spec}}, detections=dets)
    out = resolve_symmetric_board(streams, "eye_in_hand")
    assert len(out.robot) == len(robot_t) and len(out.camera) == 10
    assert out.inputs["images"]["symmetry"]["turned_back"] == int(flipped.sum())
    np.testing.assert_allclose(out.camera.poses, X_true, atol=1e-9)
    perm = target_symmetries(spec)[0][1]
    for det, f in zip(out.detections, flipped):
        np.testing.assert_array_equal(det.ids, perm if f else ids)
        # Relabelled points and object points agree: id k sits at object point k.
        np.testing.assert_allclose(det.object_points, p[det.ids], atol=1e-12)

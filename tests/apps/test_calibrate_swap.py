"""Robot and camera files swapped, at every target distance, both modes: AX = ZB fits both
readings alike (the target's pose takes the hand-eye transform's place), so neither the
hand-eye distance limit nor the median residuals (of different points, in different frames)
decide; the stream that carries the noise does (its roughness about a smooth motion). The
right order is never called swapped, the swapped one never OK; without timestamps to tell,
both are a WARN that says so."""

import math

import numpy as np
import pytest

from handeye_drake.calibration import calibrate_streams
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp, rotation_from_rpy
from handeye_drake.recorded import example as ex
from handeye_drake.recorded.formats import pose_stream

ACCURACY = (0.03, 3e-4)


def _recording(mode, distance, seed, timestamps=True, duration=10.0):
    """The shipped recording's motion around a target ``distance`` m from the base (eye-in-
    hand; eye-to-hand: the camera 0.5 m above it, the target on the flange), seeded."""
    rng = np.random.default_rng(seed)
    heading = rng.uniform(-math.pi, math.pi)
    target = distance * np.array([math.cos(heading), math.sin(heading), 0.0])
    X_BT = make_transform(rotation_exp([0, 0, rng.uniform(-1, 1)]), target)
    X_H = make_transform(rotation_from_rpy(np.radians([1.5, -2.0, 90.0]) + 0.1 * rng.normal(
        size=3)), [0.045, -0.012, 0.068] + 0.01 * rng.normal(size=3))

    def cam(t):  # X_BC(t) around the target
        X = ex.camera_pose(t + rng_phase)
        return make_transform(X[:3, :3], X[:3, 3] - ex.X_BT[:3, 3] + X_BT[:3, 3])
    rng_phase = rng.uniform(0, 50)
    if timestamps:
        t_r = np.arange(int(duration * 50) + 1) / 50.0
        t_c = 0.1 + np.arange(int((duration - 0.2) * 15)) / 15.0
    else:
        t_c = np.arange(40) * duration / 40
        t_r = t_c
    noise = [make_transform(rotation_exp(np.radians(0.1) * rng.normal(size=3)),
                            0.0005 * rng.normal(size=3)) for _ in t_c]
    if mode == "eye_in_hand":
        robot = [cam(t) @ inverse(X_H) for t in t_r]
        camera = [N @ inverse(cam(t)) @ X_BT for N, t in zip(noise, t_c)]
        truth = X_H
    else:  # the camera fixed 0.5 m above the target, the target moved on the flange
        X_BC = make_transform(rotation_from_rpy([math.pi, 0, 0]), target + [0, 0, 0.5])
        robot = [X_BC @ inverse(cam(t)) @ X_BT @ inverse(X_H) for t in t_r]
        camera = [N @ inverse(cam(t)) @ X_BT for N, t in zip(noise, t_c)]
        truth = X_BC
    stamps = (t_r, t_c + 0.02) if timestamps else (None, None)
    return (pose_stream(robot, stamps[0], "robot"), pose_stream(camera, stamps[1], "camera"),
            truth)


def _run(robot, camera, mode):
    try:
        return calibrate_streams(robot, camera, mode=mode, robot_accuracy=ACCURACY), ""
    except ValueError as e:
        return None, str(e)


def _codes(r):
    return [x.code for x in r.verdict.reasons]


CASES = [(mode, d, seed) for mode in ("eye_in_hand", "eye_to_hand")
         for seed, d in enumerate((0.12, 0.3, 0.45, 0.75))]


@pytest.mark.parametrize("mode,distance,seed", CASES)
def test_timestamped_streams_are_told_apart_by_the_one_that_carries_the_noise(mode, distance,
                                                                              seed):
    robot, camera, truth = _recording(mode, distance, seed)
    r, error = _run(robot, camera, mode)
    assert r is not None, error
    assert "swapped_streams" not in _codes(r) and "swap_ambiguous" not in _codes(r)
    assert r.verdict.status == "OK", r.verdict.reasons
    assert np.linalg.norm(r.X_hand[:3, 3] - truth[:3, 3]) < 0.003
    r, error = _run(camera, robot, mode)  # the files given the other way round
    if r is None:
        assert "the robot and camera files are swapped" in error, error
    else:
        assert r.verdict.status == "FAIL" and "swapped_streams" in _codes(r), r.verdict.reasons


@pytest.mark.parametrize("mode,distance,seed", CASES[::2] + CASES[1::4])
def test_without_timestamps_a_swap_is_never_ok_and_the_right_order_never_called_swapped(
        mode, distance, seed):
    robot, camera, _ = _recording(mode, distance, seed, timestamps=False)
    r, error = _run(robot, camera, mode)
    assert r is not None, error
    assert "swapped_streams" not in _codes(r)
    r, error = _run(camera, robot, mode)
    assert r is None or r.verdict.status != "OK", r.verdict.reasons


@pytest.mark.parametrize("seed", range(3))
def test_a_sparse_robot_stream_is_not_taken_for_the_camera(seed):
    """The roughness is compared at the same spacing: a robot logged at 2 Hz beside a 15 Hz
    camera is not 'rougher' for its longer interpolation intervals."""
    from handeye_drake.calibration.checks import swap_evidence
    robot, camera, _ = _recording("eye_in_hand", 0.3, seed)
    sparse = pose_stream(robot.poses[::25], robot.timestamps[::25], "robot")
    assert swap_evidence(sparse, camera)["reading"] != "swapped"
    assert swap_evidence(robot, camera)["reading"] == "as_read"
    assert swap_evidence(camera, robot)["reading"] == "swapped"

"""A recording where something fixed moved: found, located and named; never on good data."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import handeye_drake
from handeye_drake.calibration.changepoint import find_move
from handeye_drake.calibration.inputs import file_streams
from handeye_drake.estimation.se3 import make_transform, rotation_exp
from handeye_drake.calibration.align import align_streams
from tests.fixtures import synthetic_streams

DATA = Path(handeye_drake.__file__).parent / "data"
OFFSET = 0.0203  # the example's clock offset


@pytest.fixture(scope="module")
def example():
    return file_streams(str(DATA / "example_robot.tum"), str(DATA / "example_camera.tum"))


def _moved(example, start, left=None, right=None):
    """The example with every camera pose from sample ``start`` on moved: X_CT · right (the
    target moved) or left · X_CT (the camera moved on the flange)."""
    P = example.camera.poses.copy()
    for k in range(start, len(P)):
        P[k] = (left if left is not None else np.eye(4)) @ P[k] @ (
            right if right is not None else np.eye(4))
    a = align_streams(example.robot, dataclasses.replace(example.camera, poses=P), OFFSET)
    return a, np.asarray(a.X_BE), np.asarray(a.X_CT)


def test_a_bumped_target_is_found_at_the_right_sample(example):
    n = len(example.camera.poses)
    bump = make_transform(rotation_exp([0, 0, np.radians(0.3)]), [0.005, 0, 0])
    a, X_R, X_CT = _moved(example, n // 2, right=bump)
    move = find_move(X_R, X_CT)
    assert move is not None and move.what == "target"
    line = example.camera.lines[n // 2]
    text = move.message(a.camera_lines, "X_EC")
    assert f"lines {line - 1} and {line}" in text and "the target moved" in text
    assert 3e-3 < move.translation < 7e-3


def test_a_camera_that_slipped_on_its_mount_is_found(example):
    n = len(example.camera.poses)
    slip = make_transform(rotation_exp([0.01, 0, 0]), [0.004, 0, 0])
    a, X_R, X_CT = _moved(example, n // 3, left=slip)
    move = find_move(X_R, X_CT)
    assert move is not None and move.what == "camera"
    line = example.camera.lines[n // 3]
    assert f"lines {line - 1} and {line}" in move.message(a.camera_lines, "X_EC")


@pytest.mark.parametrize("seed", range(4))
def test_nothing_moves_in_good_recordings(seed, example):
    if seed == 0:
        a = align_streams(example.robot, example.camera, OFFSET)
    else:
        robot, camera, _ = synthetic_streams(0.02, seed=seed, duration=20.0)
        a = align_streams(robot, camera, 0.02)
    assert find_move(np.asarray(a.X_BE), np.asarray(a.X_CT)) is None


def test_the_command_names_a_bumped_target(example, tmp_path, capsys):
    from handeye_drake.apps.cli import main
    from tests.apps.test_calibrate import _tum
    n = len(example.camera.poses)
    bump = make_transform(rotation_exp([0, 0, np.radians(0.3)]), [0.005, 0, 0])
    P = example.camera.poses.copy()
    P[n // 2:] = P[n // 2:] @ bump
    camera = _tum(tmp_path / "camera.tum", example.camera.timestamps, P)
    assert main(["calibrate", "--robot", str(DATA / "example_robot.tum"), "--camera", camera,
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    # The rewritten file has one header line: sample k is on line k + 2.
    assert err.count("\n") == 1 and "likely cause: the target moved" in err
    assert f"lines {n // 2 + 1} and {n // 2 + 2}" in err

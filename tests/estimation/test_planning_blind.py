"""Issue 37, family 3: the planner never plans blind. Poses where the camera cannot see the
target are refused (the target behind the camera, outside the view; the --around pose, the
candidates, the recorded poses under the guesses), and the recording a plan starts from gets
calibrate's checks (swapped, inverted, millimetre files refuse the plan naming the cause). Each
wrong setup is generated in variants; the right setups still plan."""

import json
import math

import numpy as np
import pytest

from handeye_drake.apps.cli import main as cli_main
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp
from handeye_drake.vision.camera_model import apply_pose_noise

from .test_planning import CAMERA, P_BT, SR, X_BE0, X_BT, X_CE, X_EC, _candidates, _pose_arg, _tum


def _plan(tmp_path, *argv, name="out"):
    out = tmp_path / name
    return cli_main(["plan", *map(str, argv), "--out", str(out)]), out


def _blind_hand_eye(kind, rng):
    """A rough X_EC that puts the target out of view at X_BE0: the camera turned to look back
    (behind), or sideways (outside any lens's view)."""
    if kind == "behind":
        R = rotation_exp(np.array([math.pi, 0, 0]) + 0.1 * rng.normal(size=3))
    else:
        R = rotation_exp(np.array([0, math.pi / 2 * rng.choice([-1, 1]), 0])
                         + 0.05 * rng.normal(size=3))
    return X_EC @ make_transform(R, [0, 0, 0])


@pytest.mark.parametrize("kind, seed", [("behind", 0), ("behind", 1), ("sideways", 2)])
@pytest.mark.parametrize("intrinsics", [False, True])
def test_around_a_pose_that_cannot_see_the_target_is_refused(tmp_path, capsys, kind, seed,
                                                             intrinsics):
    X = _blind_hand_eye(kind, np.random.default_rng(seed))
    extra = ["--intrinsics", f"{CAMERA.alpha_u},{CAMERA.alpha_v},320,240,640,480"] \
        if intrinsics else []
    code, out = _plan(tmp_path, "--around", _pose_arg(X_BE0), "--hand-eye", _pose_arg(X),
                      "--target", ",".join(map(str, P_BT)), "--num-candidates", 50, *extra)
    err = capsys.readouterr().err
    assert code == 2 and "--around" in err and err.count("\n") == 1, err
    assert ("behind the camera" in err) == (kind == "behind"), err
    assert not (out / "next_poses.tum").exists()


@pytest.mark.parametrize("kind", ["behind", "sideways"])
def test_candidates_that_cannot_see_the_target_are_refused(tmp_path, capsys, kind):
    _tum(tmp_path / "cands.tum", _candidates(3, 30))
    X = _blind_hand_eye(kind, np.random.default_rng(4))
    code, out = _plan(tmp_path, "--candidates", tmp_path / "cands.tum", "--hand-eye",
                      _pose_arg(X), "--target", ",".join(map(str, P_BT)), "--n", 3)
    err = capsys.readouterr().err
    assert code == 2 and "--candidates" in err and "none of the 30" in err, err
    assert not (out / "next_poses.tum").exists()


def test_blind_candidates_are_left_out_and_said(tmp_path, capsys):
    good = list(_candidates(3, 20))
    flipped = [X @ make_transform(rotation_exp([math.pi, 0, 0]), [0, 0, 0]) for X in good[:8]]
    _tum(tmp_path / "cands.tum", flipped + good)
    code, out = _plan(tmp_path, "--candidates", tmp_path / "cands.tum", "--hand-eye",
                      _pose_arg(X_EC), "--target", ",".join(map(str, P_BT)), "--n", 4)
    assert code == 0
    assert "8 of 28 candidates left out" in capsys.readouterr().out
    picks = [s["candidate"] for s in json.loads((out / "plan.json").read_text())["next_poses"]]
    assert min(picks) >= 8


def test_guesses_contradicted_by_the_recorded_poses_are_refused(tmp_path, capsys):
    _tum(tmp_path / "robot.tum", _candidates(5, 10))
    _tum(tmp_path / "cands.tum", _candidates(6, 20))
    X = _blind_hand_eye("behind", np.random.default_rng(7))
    code, _ = _plan(tmp_path, "--robot", tmp_path / "robot.tum", "--candidates",
                    tmp_path / "cands.tum", "--hand-eye", _pose_arg(X), "--target",
                    ",".join(map(str, P_BT)))
    err = capsys.readouterr().err
    assert code == 2 and "recorded poses" in err and "--hand-eye" in err, err


def _recording(tmp_path, seed, n=12):
    rng = np.random.default_rng(seed)
    robot = list(_candidates(seed + 20, n))
    camera = [apply_pose_noise(X_CE @ inverse(x) @ X_BT, rng.normal(size=12), "so3", SR, 0.0005)
              for x in robot]
    return robot, camera


@pytest.mark.parametrize("mistake, seed", [("swapped", 0), ("swapped", 1), ("inverted", 2),
                                           ("millimetres", 3), ("quaternion wxyz", 4)])
def test_a_recording_calibrate_would_fail_refuses_the_plan_naming_the_cause(
        tmp_path, capsys, mistake, seed):
    robot, camera = _recording(tmp_path, seed)
    if mistake == "swapped":
        robot, camera = camera, robot
    elif mistake == "inverted":
        camera = [inverse(X) for X in camera]
    elif mistake == "millimetres":
        robot = [make_transform(X[:3, :3], 1000 * X[:3, 3]) for X in robot]
    else:
        from handeye_drake.estimation.consistency import (rotation_from_swapped_quaternions,
                                                          with_rotations)
        camera = list(with_rotations(np.array(camera), rotation_from_swapped_quaternions(
            np.array(camera)[:, :3, :3])))
    _tum(tmp_path / "robot.tum", robot)
    _tum(tmp_path / "camera.tum", camera)
    argv = ["--robot", tmp_path / "robot.tum", "--camera", tmp_path / "camera.tum", "--around",
            _pose_arg(X_BE0), "--num-candidates", 40, "--n", 3]
    if mistake == "millimetres":
        argv += ["--translation-scale", 1.0]
    code, out = _plan(tmp_path, *argv)
    err = capsys.readouterr().err
    assert code == 2 and "calibrate" in err and err.count("\n") == 1, err
    word = {"swapped": "swap", "inverted": "invert", "millimetres": "millimetre",
            "quaternion wxyz": "quaternion"}[mistake]
    assert word in err.lower(), err
    assert not (out / "next_poses.tum").exists()


def test_a_right_recording_still_plans(tmp_path, capsys):
    robot, camera = _recording(tmp_path, 9)
    _tum(tmp_path / "robot.tum", robot)
    _tum(tmp_path / "camera.tum", camera)
    code, out = _plan(tmp_path, "--robot", tmp_path / "robot.tum", "--camera",
                      tmp_path / "camera.tum", "--around", _pose_arg(X_BE0),
                      "--num-candidates", 40, "--n", 3)
    assert code == 0, capsys.readouterr().err
    assert len(json.loads((out / "plan.json").read_text())["next_poses"]) == 3

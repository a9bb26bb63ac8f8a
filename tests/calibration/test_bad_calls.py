"""Issue 37, families 5 and 6: bad calls and odd files get a clear refusal naming the argument
(the API: ValueError; the command line: one line, exit 2), in bounded time, with no user file
touched — and the natural Python call with poses in memory works."""

import math

import numpy as np
import pytest

from handeye_drake.apps.cli import main
from handeye_drake.calibration import CalibrationOptions, calibrate
from handeye_drake.calibration.align import estimate_time_offset
from tests.fixtures import synthetic_streams


@pytest.fixture(scope="module")
def streams():
    return synthetic_streams(0.02, seed=3, duration=10.0)


# ------------------------------------------------------------------ the time offset's range
@pytest.mark.parametrize("search_range", [2000.0, 5e3, 1e6, 1e9])
def test_a_wide_time_offset_range_is_searched_not_recursed(streams, search_range):
    robot, camera, _ = streams
    est = estimate_time_offset(robot, camera, search_range)
    assert abs(est.offset - 0.02) < 0.005, est.offset


def test_cli_wide_time_offset_range(tmp_path, capsys):
    from handeye_drake.estimation.se3 import quat_wxyz
    robot, camera, _ = synthetic_streams(0.02, seed=4, duration=6.0)
    files = []
    for name, s in (("robot", robot), ("camera", camera)):
        lines = [f"{t:.6f} " + " ".join(f"{v:.9f}" for v in (*X[:3, 3], *quat_wxyz(X[:3, :3])[1:],
                                                             quat_wxyz(X[:3, :3])[0]))
                 for t, X in zip(s.timestamps, s.poses)]
        files.append(tmp_path / f"{name}.tum")
        files[-1].write_text("\n".join(lines) + "\n")
    code = main(["calibrate", "--robot", str(files[0]), "--camera", str(files[1]),
                 "--time-offset-range", "2500", "--out", str(tmp_path / "o")])
    out = capsys.readouterr()
    assert code == 0 and "Traceback" not in out.err, out.err
    line = next(s for s in out.out.splitlines() if s.startswith("time offset:"))
    assert abs(float(line.split()[2]) - 0.02) < 0.02, line      # stamped 0.02 s late


# ------------------------------------------------------------------ poses in memory
def test_calibrate_takes_pose_arrays_with_and_without_times(streams):
    robot, camera, X_EC = streams
    r = calibrate(robot.poses, camera.poses, robot_timestamps=robot.timestamps,
                  camera_timestamps=camera.timestamps)
    assert r.verdict.status == "OK", r.verdict
    assert np.linalg.norm(r.X_hand[:3, 3] - X_EC[:3, 3]) < 5 * np.linalg.norm(
        r.translation_std) + 1e-4
    # Lists of 4×4, paired by index (the camera's instants picked from the robot's stream).
    idx = np.searchsorted(robot.timestamps, camera.timestamps - 0.02)
    idx = np.clip(idx, 0, len(robot) - 1)
    keep = np.abs(robot.timestamps[idx] - (camera.timestamps - 0.02)) < 1e-9
    r2 = calibrate([X for X in robot.poses[idx[keep]]], list(camera.poses[keep]))
    assert r2.verdict.status in ("OK", "WARN"), r2.verdict
    assert np.linalg.norm(r2.X_hand[:3, 3] - X_EC[:3, 3]) < 0.005


@pytest.mark.parametrize("kwargs, name", [
    (dict(robot=np.zeros((5, 3, 3)), camera=np.zeros((5, 4, 4))), "robot"),
    (dict(robot=np.tile(np.eye(4), (5, 1, 1)), camera="camera.tum"), "camera"),
    (dict(robot=np.tile(np.eye(4), (5, 1, 1)), camera=[[1, 2], [3]]), "camera"),
    (dict(robot=np.tile(np.eye(4), (5, 1, 1)), camera=np.tile(np.eye(4), (5, 1, 1)),
          robot_timestamps=np.arange(5.0)), "robot_timestamps"),
    (dict(robot=np.tile(np.eye(4), (5, 1, 1)), camera=np.tile(np.eye(4), (5, 1, 1)),
          robot_timestamps=np.arange(4.0), camera_timestamps=np.arange(5.0)),
     "robot_timestamps"),
    (dict(robot=np.tile(np.eye(4), (5, 1, 1)), camera=np.tile(np.eye(4), (5, 1, 1)),
          robot_timestamps=np.zeros(5), camera_timestamps=np.arange(5.0)), "robot"),
    (dict(robot=np.full((5, 4, 4), np.nan), camera=np.tile(np.eye(4), (5, 1, 1))), "robot"),
    (dict(robot=np.tile(np.eye(4), (5, 1, 1)), images="x", target="chessboard:9x6:0.02"),
     "robot"),
])
def test_bad_pose_arrays_are_refused_naming_the_argument(kwargs, name):
    with pytest.raises(ValueError) as e:
        calibrate(**kwargs)
    assert str(e.value).startswith(name), e.value


@pytest.mark.parametrize("field, value", [
    ("max_hand_eye_distance_m", -1), ("max_hand_eye_distance_m", 0.0),
    ("max_hand_eye_distance_m", math.inf), ("max_hand_eye_distance_m", math.nan),
    ("max_hand_eye_distance_m", "1"), ("time_offset_s", math.nan), ("time_offset_s", "later"),
    ("time_offset_s", math.inf)])
def test_options_refuse_impossible_numbers(field, value):
    with pytest.raises(ValueError, match=f"^{field}"):
        CalibrationOptions(**{field: value})


@pytest.mark.parametrize("field, value", [
    ("time_offset_range_s", -0.5), ("min_rotation_deg", math.nan), ("holdout_fraction", 0.9),
    ("seed", -1), ("online_step_deg", 120.0)])
def test_the_other_options_are_refused_where_used(field, value):
    robot, camera, _ = synthetic_streams(0.02, seed=3, duration=4.0)
    with pytest.raises(ValueError, match=f"^{field.removesuffix('_s')}"):
        calibrate(robot.poses, camera.poses, robot_timestamps=robot.timestamps,
                  camera_timestamps=camera.timestamps, options=CalibrationOptions(
                      **{field: value}, online=field == "online_step_deg"))


def test_options_accept_the_ordinary_values():
    CalibrationOptions(max_hand_eye_distance_m=2.0, time_offset_s=-0.03, holdout_fraction=0,
                       min_rotation_deg=0)
    CalibrationOptions(time_offset_s="auto")


# ------------------------------------------------------------------ files and names
@pytest.mark.parametrize("kind", ["file", "symlink"])
def test_a_file_or_link_named_detections_in_out_is_refused_not_a_traceback(tmp_path, capsys,
                                                                          kind):
    from tests.apps.test_calibrate import IMAGES
    out = tmp_path / "out"
    out.mkdir()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "img_000.png").write_text("mine")
    if kind == "file":
        (out / "detections").write_text("mine")
    else:
        (out / "detections").symlink_to(elsewhere, target_is_directory=True)
    code = main(["calibrate", "--images", str(IMAGES), "--robot", str(IMAGES / "robot_poses.tum"),
                 "--target", "charuco:7x5:0.04:0.03:DICT_5X5_100", "--intrinsics",
                 str(IMAGES / "intrinsics.yaml"), "--refine-intrinsics", "none", "--out",
                 str(out), "--force"])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err and "detections" in err, err
    assert len(err.strip().splitlines()) == 1
    assert (elsewhere / "img_000.png").read_text() == "mine"
    assert sorted(p.name for p in elsewhere.iterdir()) == ["img_000.png"]
    if kind == "file":
        assert (out / "detections").read_text() == "mine"


def test_a_directory_named_calibration_json_is_refused(tmp_path, capsys):
    from tests.apps.test_calibrate import CAMERA, ROBOT
    out = tmp_path / "out"
    (out / "calibration.json").mkdir(parents=True)
    code = main(["calibrate", "--robot", ROBOT, "--camera", CAMERA, "--out", str(out),
                 "--force"])
    err = capsys.readouterr().err
    assert code == 2 and "calibration.json" in err and "Traceback" not in err, err
    assert (out / "calibration.json").is_dir()


@pytest.mark.parametrize("option, value", [("--parent-frame", "my tool"),
                                           ("--child-frame", "cam'era"),
                                           ("--parent-frame", "")])
def test_bad_frame_names_are_refused_before_anything_is_written(tmp_path, capsys, option,
                                                                value):
    from tests.apps.test_calibrate import DATA
    out = tmp_path / "o"
    code = main(["calibrate", "--robot", str(DATA / "example_robot.tum"), "--camera",
                 str(DATA / "example_camera.tum"), "--export", "urdf", option, value,
                 "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and option in err and "Traceback" not in err, err
    assert not out.exists()

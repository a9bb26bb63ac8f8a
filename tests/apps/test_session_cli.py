"""``handeye-drake session``: --simulate end to end on the rendered UR5e cell, the σ floor of
--robot-accuracy said at the start, --state never overwriting a foreign file, a partial line
under --follow waiting for its end, samples arriving together fitted once, and the session on
the shipped example bag agreeing with ``calibrate`` on it (clock offset and CameraInfo read)."""

import json
import threading
import time

import numpy as np
import pytest

from handeye_drake.apps.cli import main
from handeye_drake.calibration import CalibrationOptions, calibrate
from handeye_drake.estimation.se3 import rotation_angle
from tests.calibration.test_session import GUESS, _line, _seven, samples


def test_simulate_runs_to_stop_through_the_samples_file(tmp_path, capsys):
    # The README's command with fewer candidate views (the same path; planning 60 views is
    # most of its time).
    out = tmp_path / "session"
    code = main(["session", "--simulate", "--num-candidates", "25", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "stop: σ" in text and "verdict OK" in text
    # The samples went through the file a real driver writes: 14 numbers a line.
    lines = (out / "samples.txt").read_text().splitlines()
    assert lines and all(len(x.split()) == 14 for x in lines)
    steps = json.loads((out / "session_steps.json").read_text())
    assert steps["stop"] and steps["samples"] == len(lines)
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["verdict"]["status"] == "OK"
    # The simulated truth is within 3σ of the answer.
    err = next(x for x in text.splitlines() if x.startswith("simulated truth"))
    rot, tra = float(err.split()[3].rstrip("°")), float(err.split()[5])
    last = steps["last"]
    assert rot <= 3 * last["rotation_sigma_deg"] and tra <= 3 * last["translation_sigma_mm"]


def test_a_target_below_the_robot_accuracy_floor_is_said_at_the_start(tmp_path, capsys):
    f = tmp_path / "samples.txt"
    f.write_text("\n".join(_line(*x) for x in samples(5, seed=1)) + "\n")
    code = main(["session", "--samples", str(f), "--target-sigma", "0.1,0.5",
                 "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "--target-sigma: 0.5 mm is below the floor 0.52 mm" in err
    assert "--robot-accuracy 0.03,0.3" in err
    # Above the floor: the start says what the floor is.
    code = main(["session", "--samples", str(f), "--out", str(tmp_path / "o2")])
    assert "σ floor of --robot-accuracy 0.03,0.3: 0.052° / 0.52" in capsys.readouterr().out


def test_state_never_overwrites_a_foreign_file(tmp_path, capsys):
    f = tmp_path / "samples.txt"
    text = "\n".join(_line(*x) for x in samples(5, seed=1)) + "\n"
    f.write_text(text)
    mine = tmp_path / "notes.json"
    mine.write_text('{"my": "data"}\n')
    (tmp_path / "dir").mkdir()
    for state, what in ((f, "is the --samples file"), (mine, "is not a session state"),
                        (tmp_path / "dir", "is a directory")):
        code = main(["session", "--samples", str(f), "--state", str(state),
                     "--out", str(tmp_path / "o")])
        err = capsys.readouterr().err
        assert code == 2 and what in err and err.count("\n") == 1, err
    assert f.read_text() == text and mine.read_text() == '{"my": "data"}\n'
    assert not (tmp_path / "dir.tmp").exists() and not list((tmp_path / "dir").iterdir())
    # A session state the tool wrote may be started over.
    state = tmp_path / "state.json"
    assert main(["session", "--samples", str(f), "--state", str(state), "--robot-accuracy",
                 "0,0", "--out", str(tmp_path / "o3")]) == 1
    assert json.loads(state.read_text())["format"] == "handeye_drake session state"
    assert main(["session", "--samples", str(f), "--state", str(state), "--robot-accuracy",
                 "0,0", "--out", str(tmp_path / "o3")]) == 1


def test_follow_waits_for_a_partial_line_and_fits_arrivals_together(tmp_path, capsys):
    data = samples(30, seed=1)
    lines = [_line(*x) + "\n" for x in data]
    f = tmp_path / "samples.txt"
    # 12 lines at once (they arrive faster than a fit), then a line written in two parts.
    f.write_text("".join(lines[:12]) + lines[12][:40])

    def driver():
        time.sleep(0.6)
        with f.open("a") as fh:
            fh.write(lines[12][40:])
            fh.flush()
            for x in lines[13:]:
                time.sleep(0.05)
                fh.write(x)
                fh.flush()

    t = threading.Thread(target=driver)
    t.start()
    code = main(["session", "--samples", str(f), "--follow", "--idle-timeout", "3",
                 "--target-sigma", "0.2,1.0", "--robot-accuracy", "0.02,0.1", "--hand-eye",
                 _seven(GUESS), "--out", str(tmp_path / "o")])
    t.join()
    out = capsys.readouterr()
    assert code == 0, out.out + out.err
    steps = [x for x in out.out.splitlines() if x.startswith("[")]
    # The first 12 samples were fitted once, not one by one; the partial line did not abort.
    assert steps[0].startswith("[ 12]") and "(+12 samples)" in steps[0]
    assert "stop: σ" in steps[-1]


@pytest.fixture(scope="module")
def example_bag(tmp_path_factory):
    from handeye_drake.recorded.example_bag import write_example_bag
    path = tmp_path_factory.mktemp("bag") / "cell.bag"
    write_example_bag(path)
    return path


def test_session_on_the_example_bag_agrees_with_calibrate(example_bag, tmp_path, capsys):
    spec = "charuco:7x5:0.04:0.03:DICT_5X5_100"
    ref = calibrate(bag=example_bag, image_topic="/camera/color/image_raw", target=spec,
                    options=CalibrationOptions())
    out = tmp_path / "o"
    code = main(["session", "--bag", str(example_bag), "--image-topic",
                 "/camera/color/image_raw", "--target-spec", spec, "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "intrinsics from the CameraInfo on /camera/color/camera_info" in text
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["verdict"]["status"] == "OK"
    # The clock offset estimated as calibrate does (the camera 35 ms late), not assumed 0.
    assert doc["time_offset"]["mode"].startswith("auto")
    assert abs(doc["time_offset"]["value_s"] - ref.time_offset.offset) < 1e-3
    X = np.array(doc["X_EC"]["matrix"])
    sr = np.degrees(np.sqrt(np.trace(ref.covariance[:3, :3])))
    st = np.sqrt(np.trace(ref.covariance[3:, 3:]))
    assert np.degrees(rotation_angle(X[:3, :3].T @ ref.X_hand[:3, :3])) <= sr
    assert np.linalg.norm(X[:3, 3] - ref.X_hand[:3, 3]) <= st


def test_plan_says_the_floor_and_refuses_a_target_below_it(tmp_path, capsys):
    args = ["plan", "--hand-eye=0.035,-0.025,0.055,0,0,0.7071068,0.7071068",
            "--target=-0.45,-0.15,0", "--around=-0.3,-0.2,0.5,1,0,0,0", "--num-candidates", "50"]
    assert main(args + ["--target-sigma", "0.1,0.5", "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert "--target-sigma: 0.5 mm is below the floor 0.522 mm" in err and err.count("\n") == 1
    assert main(args + ["--out", str(tmp_path / "b")]) == 0
    assert "σ floor of --robot-accuracy 0.03,0.3: 0.052° / 0.522 mm" in capsys.readouterr().out

"""Hostile-but-plausible inputs to the newest command-line surfaces (circle-grid targets,
``calibrate --compare``, the rig CLI, ``session``) and to ``calibrate()`` in Python: each ends in
one error line naming the argument (exit 2) or a sensible result, and no user file is touched.
Every case here was a traceback, a message naming nothing, or a silent wrong answer before."""

import json
import shutil
from pathlib import Path

import pytest

from handeye_drake.apps.cli import main

DATA = Path(__file__).resolve().parents[2] / "handeye_drake" / "data" / "example_images"
TARGET = "charuco:7x5:0.04:0.03:DICT_5X5_100"


def _error(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


# --- handeye-drake target: circle grids -----------------------------------------------------

@pytest.mark.parametrize("spec", ["circles:4x11:0.02", "acircles:4x11:0.02:0.02:white"])
def test_target_writes_circle_grids(tmp_path, capsys, spec):
    # Was "error: min() arg is an empty sequence": the printable-size check knew squares,
    # markers and tags but not a circle's diameter.
    assert main(["target", spec, "--out", str(tmp_path / "t")]) == 0
    assert "circle diameter" in capsys.readouterr().out
    assert (tmp_path / "t" / "target.png").is_file()


def test_target_refuses_circles_too_small_to_print(tmp_path, capsys):
    assert main(["target", "circles:4x11:0.002", "--out", str(tmp_path / "t")]) == 2
    assert "its diameter would be 1 mm" in _error(capsys)


# --- calibrate --compare --------------------------------------------------------------------

def test_compare_reads_an_output_folder(tmp_path):
    from handeye_drake.calibration.compare import read_answer
    (tmp_path / "other").mkdir()
    with pytest.raises(ValueError, match="--compare: .*a folder without a calibration.json"):
        read_answer(tmp_path / "other")
    doc = {"mode": "eye_in_hand", "X_EC": {
        "matrix": [[1, 0, 0, 0.1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
        "std": {"covariance": (1e-6 * __import__("numpy").eye(6)).tolist()}},
        "verdict": {"status": "OK"}}
    (tmp_path / "other" / "calibration.json").write_text(json.dumps(doc))
    mode, X, _, status = read_answer(tmp_path / "other")
    assert mode == "eye_in_hand" and X[0, 3] == 0.1 and status == "OK"


# --- the rig CLI ----------------------------------------------------------------------------

@pytest.fixture
def rig_dir(tmp_path):
    """Two camera folders holding image names only (every case fails before an image is read)
    and a robot file: what the rig's input checks look at."""
    rig = tmp_path / "rig"
    for cam in ("wrist", "cell"):
        (rig / cam).mkdir(parents=True)
        for k in range(3):
            (rig / cam / f"img_{k:03d}.png").write_bytes(b"")
        shutil.copy(DATA / "intrinsics.yaml", rig / cam / "intrinsics.yaml")
    shutil.copy(DATA / "robot_poses.tum", rig / "robot_poses.tum")
    (rig / "empty").mkdir()
    return rig


def _rig_yaml(rig, cameras: str, extra: str = "") -> Path:
    p = rig / "rig.yaml"
    p.write_text(f"robot: robot_poses.tum\ntarget: {TARGET}\n{extra}cameras:\n{cameras}")
    return p


@pytest.mark.parametrize("cameras, extra, expected", [
    # YAML keeps the last of two equal keys: one camera silently calibrated under the other's
    # name from the other's folder.
    ("  wrist: {images: wrist, mount: hand}\n  wrist: {images: cell, mount: cell}\n", "",
     "key 'wrist' given twice"),
    # Misspelt keys fell back silently to defaults (board in the cell, intrinsics calibrated).
    ("  wrist: {images: wrist}\n", "bord: hand\n", "unknown key 'bord'"),
    ("  wrist: {images: wrist, intrinsic: wrist/intrinsics.yaml}\n", "",
     "camera wrist: unknown key 'intrinsic'"),
    # A folder without images and a missing intrinsics file were FAIL verdicts (exit 1).
    ("  wrist: {images: wrist}\n  blind: {images: empty}\n", "",
     "camera blind: .*holds no image"),
    ("  wrist: {images: wrist, intrinsics: nowhere.yaml}\n", "",
     "camera wrist: intrinsics .*nowhere.yaml.*no such file"),
    ("  wrist: {images: wrist}\n", "robot: [1, 2]\n", "key 'robot' given twice"),
    ("  wrist: {images: wrist}\n", "board: 3\n", "board: expected a string"),
])
def test_rig_yaml_bad_input(rig_dir, tmp_path, capsys, cameras, extra, expected):
    import re
    rig = _rig_yaml(rig_dir, cameras, extra)
    assert main(["calibrate", "--rig", str(rig), "--out", str(tmp_path / "out")]) == 2
    line = _error(capsys)
    assert line.startswith(f"handeye-drake: error: --rig {rig}") and re.search(expected, line)
    assert not (tmp_path / "out").exists()


def test_rig_yaml_folder(rig_dir, capsys):
    assert main(["calibrate", "--rig", str(rig_dir), "--out", str(rig_dir / "o")]) == 2
    assert "a folder; expected the rig's YAML file" in _error(capsys)


@pytest.mark.parametrize("cameras, expected", [
    (["wrist:{r}/wrist:hand:{r}/nowhere.yaml"], "--camera wrist:.*nowhere.yaml.*no such file"),
    (["wrist:{r}/empty"], "--camera wrist:.*holds no image"),
    (["wrist:{r}/wrist", "w2:{r}/wrist/"], "--camera: cameras wrist and w2 read the same images"),
])
def test_rig_cameras_bad_input(rig_dir, tmp_path, capsys, cameras, expected):
    import re
    argv = ["calibrate", "--robot", str(rig_dir / "robot_poses.tum"), "--target", TARGET,
            "--out", str(tmp_path / "out")]
    for c in cameras:
        argv += ["--camera", c.format(r=rig_dir)]
    assert main(argv) == 2
    assert re.search(expected, _error(capsys))


@pytest.fixture(scope="module")
def example_bag(tmp_path_factory):
    from handeye_drake.recorded.example_bag import write_example_bag
    path = tmp_path_factory.mktemp("bag") / "cell.bag"
    write_example_bag(path)
    return path


@pytest.mark.parametrize("cameras, expected", [
    # A topic not in the bag was a FAIL verdict after reading the other cameras' images.
    (["wrist:/no/such/topic:hand", "cell:/camera/color/image_raw:cell"],
     "--camera wrist:/no/such/topic:hand: .*no topic '/no/such/topic'"),
    (["a:/camera/color/image_raw", "b:/camera/color/image_raw"],
     "--camera: cameras a and b read the same topic"),
])
def test_rig_bag_bad_topics(example_bag, tmp_path, capsys, cameras, expected):
    import re
    argv = ["calibrate", "--bag", str(example_bag), "--robot-frames", "base_link:tool0",
            "--target", TARGET, "--out", str(tmp_path / "out")]
    for c in cameras:
        argv += ["--camera", c]
    assert main(argv) == 2
    assert re.search(expected, _error(capsys))


# --- session --------------------------------------------------------------------------------

@pytest.mark.parametrize("argv, expected", [
    # NaN compared false with every elapsed time: --follow never gave up.
    (["--follow", "--timeout-s", "nan"], "argument --idle-timeout/--timeout-s: expected a "
                                         "positive number, got 'nan'"),
    (["--follow", "--poll-s", "inf"], "argument --poll-s: expected a positive number"),
    # Was "n: expected an integer ≥ 1", naming no argument.
    (["--feasible", "--num-candidates", "-3"], "argument --num-candidates: expected a positive"),
])
def test_session_bad_numbers(tmp_path, capsys, argv, expected):
    samples = tmp_path / "samples.txt"
    samples.write_text("0 0 0.5 0 0 0 1  0 0 0.5 0 0 0 1\n")
    assert main(["session", "--samples", str(samples), *argv,
                 "--out", str(tmp_path / "out")]) == 2
    assert expected in _error(capsys)


@pytest.mark.parametrize("content, expected", [
    (b"\xff\xfe\x00garbage\n", "line 1 is not UTF-8 text"),       # was the codec's message alone
    (b"1" * 1_200_000, "line 1 is longer than 1000000 characters"),  # was read whole
    (None, "a folder; expected the samples file"),                  # was "file not found"
])
def test_session_samples_not_a_sample_file(tmp_path, capsys, content, expected):
    samples = tmp_path / "samples.txt"
    if content is None:
        samples.mkdir()
    else:
        samples.write_bytes(content)
    assert main(["session", "--samples", str(samples), "--out", str(tmp_path / "out")]) == 2
    line = _error(capsys)
    assert line.startswith(f"handeye-drake: error: --samples {samples}") and expected in line
    assert content is None or samples.read_bytes() == content


# --- calibrate() in Python ------------------------------------------------------------------

def test_calibrate_refuses_complex_poses():
    # A complex array was cast to float with a warning: its imaginary parts dropped, an answer
    # reported OK from numbers that were not the poses given.
    import numpy as np
    from handeye_drake.calibration import calibrate
    X = np.tile(np.eye(4), (5, 1, 1)).astype(complex)
    X[:, 0, 3] += 1j
    with pytest.raises(ValueError, match=r"^robot: .*got ndarray of complex128"):
        calibrate(X, np.tile(np.eye(4), (5, 1, 1)))


# --- plan -----------------------------------------------------------------------------------

@pytest.mark.parametrize("argv, expected", [
    # Were "max_angle_deg: …" / "max_distance: …" / "CameraIntrinsics.width: …", naming
    # no argument of the command.
    (["--max-angle", "nan"], "argument --max-angle: expected a positive number"),
    (["--max-angle", "720"], "argument --max-angle: expected an angle in (0, 180] degrees"),
    (["--max-distance", "inf"], "argument --max-distance: expected a positive number"),
    (["--intrinsics", "800,800,320,240,0,0"], "--intrinsics 800,800,320,240,0,0: "),
])
def test_plan_bad_numbers(tmp_path, capsys, argv, expected):
    assert main(["plan", "--around", "0.4,0,0.5,1,0,0,0",
                 "--hand-eye", "0.045,-0.012,0.068,0,0,0.7071068,0.7071068",
                 "--target", "0.4,0,0", *argv, "--out", str(tmp_path / "p")]) == 2
    assert expected in _error(capsys)


def test_rig_camera_names_as_in_the_yaml(rig_dir, tmp_path, capsys):
    # A unicode name was taken for a camera pose file ("a rig's cameras are NAME:DIR; a camera
    # pose file calibrates one camera") though the rig YAML takes it; a bad name before a
    # folder is named as a bad name.
    from handeye_drake.apps.calibrate.rig_command import is_rig_camera
    assert is_rig_camera(f"kaméra:{rig_dir / 'wrist'}")
    assert not is_rig_camera(str(DATA / "robot_poses.tum"))
    argv = ["calibrate", "--robot", str(rig_dir / "robot_poses.tum"), "--target", TARGET,
            "--camera", f"../x:{rig_dir / 'wrist'}", "--out", str(tmp_path / "out")]
    assert main(argv) == 2
    assert "camera name: expected letters, digits, _ or -, got '../x'" in _error(capsys)


def test_compare_with_a_rig(tmp_path, capsys):
    from handeye_drake.calibration.compare import read_answer
    import numpy as np
    X = np.eye(4)
    X[0, 3] = 0.05
    cam = {"camera": "wrist", "mount": "hand", "mode": "eye_in_hand",
           "verdict": {"status": "OK", "reasons": []}, "X_EC": X.tolist(),
           "covariance": (1e-6 * np.eye(6)).tolist()}
    (tmp_path / "wrist.json").write_text(json.dumps(cam))
    # A rig camera's NAME/calibration.json was "not a calibration.json".
    mode, X_read, C, status = read_answer(tmp_path / "wrist.json")
    assert mode == "eye_in_hand" and np.allclose(X_read, X) and C[0, 0] == 1e-6
    (tmp_path / "rig.json").write_text(json.dumps({"rig": {}, "cameras": {"wrist": cam},
                                                   "relative": []}))
    with pytest.raises(ValueError, match="a rig's calibration.json; give one camera's.*wrist"):
        read_answer(tmp_path / "rig.json")


# --- calibrate: a folder where a file is expected -------------------------------------------

@pytest.mark.parametrize("which, expected", [
    # Was "…: cannot infer the format from the extension ''" (a wrong cause, no argument).
    ("--robot", "--robot {d}: a folder; expected the robot pose file"),
    # Was "intrinsics '…': no such file, and not a fx,fy,cx,cy… string".
    ("--intrinsics", "--intrinsics {d}: a folder; expected an intrinsics file"),
])
def test_calibrate_images_folder_for_a_file(tmp_path, capsys, which, expected):
    args = {"--images": str(DATA), "--robot": str(DATA / "robot_poses.tum"),
            "--target": TARGET, "--intrinsics": str(DATA / "intrinsics.yaml")}
    args[which] = str(DATA)
    argv = ["calibrate", *[x for kv in args.items() for x in kv], "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    assert expected.format(d=DATA) in _error(capsys)


def test_calibrate_camera_pose_folder(tmp_path, capsys):
    argv = ["calibrate", "--robot", str(DATA.parent / "example_robot.tum"),
            "--camera", str(tmp_path), "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    assert f"--camera {tmp_path}: a folder; expected the camera pose file" in _error(capsys)


def test_rig_yaml_too_large(tmp_path, capsys):
    big = tmp_path / "rig.yaml"
    big.write_text("# " + "x" * 1_100_000 + "\n")
    assert main(["calibrate", "--rig", str(big), "--out", str(tmp_path / "o")]) == 2
    assert "larger than 1000000 bytes; not a rig YAML" in _error(capsys)


def test_session_resume_names_state(tmp_path, capsys):
    samples = tmp_path / "samples.txt"
    samples.write_text("0 0 0.5 0 0 0 1  0 0 0.5 0 0 0 1\n")
    state = tmp_path / "calibration.json"
    state.write_text('{"mode": "eye_in_hand"}')
    assert main(["session", "--samples", str(samples), "--resume", "--state", str(state),
                 "--out", str(tmp_path / "o")]) == 2
    assert _error(capsys).startswith("handeye-drake: error: --state: calibration.json is not a "
                                     "session state")
    assert state.read_text() == '{"mode": "eye_in_hand"}'


@pytest.mark.parametrize("extra, expected", [
    # Each was silently ignored: a rig run that printed no comparison, or used the cameras'
    # own intrinsics / mounts instead of those given.
    (["--compare", "{r}/other.json"], "--compare: not read for a rig of cameras"),
    (["--intrinsics", "{r}/wrist/intrinsics.yaml"], "--intrinsics: not read for a rig"),
    (["--mode", "eye-to-hand"], "--mode: not read for a rig of cameras"),
])
def test_rig_refuses_single_camera_options(rig_dir, tmp_path, capsys, extra, expected):
    rig = _rig_yaml(rig_dir, "  wrist: {images: wrist}\n")
    argv = ["calibrate", "--rig", str(rig), *[x.format(r=rig_dir) for x in extra],
            "--out", str(tmp_path / "out")]
    assert main(argv) == 2
    assert expected in _error(capsys)


# --- calibrate_rig() in Python --------------------------------------------------------------

def test_calibrate_rig_api_misuse(rig_dir):
    # Were AttributeError / TypeError tracebacks, and a target of None a FAIL verdict.
    from handeye_drake.calibration import CalibrationOptions
    from handeye_drake.calibration.rig import RigCamera, calibrate_rig
    robot = rig_dir / "robot_poses.tum"
    w = RigCamera("wrist", rig_dir / "wrist")
    for cameras in (["wrist"], w):
        with pytest.raises(ValueError, match="^cameras: expected a list of RigCamera"):
            calibrate_rig(cameras, robot, TARGET)
    with pytest.raises(ValueError, match="^options: expected a CalibrationOptions, got dict"):
        calibrate_rig([w], robot, TARGET, "cell", {"mode": "eye_in_hand"})
    with pytest.raises(ValueError, match="^target: the board spec is needed"):
        calibrate_rig([w], robot, None, "cell", CalibrationOptions())
    with pytest.raises(ValueError, match="^camera name: .*got 5"):
        RigCamera(5, rig_dir / "wrist")

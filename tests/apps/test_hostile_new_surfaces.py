"""Hostile-but-plausible inputs to the newest command-line surfaces (circle-grid targets,
``calibrate --compare``, the rig CLI, ``session``) and to ``calibrate()`` in Python: each ends in
one error line naming the argument (exit 2) or a sensible result, and no user file is touched.
Every case here was a traceback, a message naming nothing, or a silent wrong answer before."""

import json
import re
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


def test_rig_yaml_empty_name(tmp_path, capsys):
    # Was "inputs: give one of …": an empty --rig read as no --rig.
    assert main(["calibrate", "--rig", "", "--out", str(tmp_path / "out")]) == 2
    assert _error(capsys) == "handeye-drake: error: --rig: empty; expected the rig's YAML file"


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


@pytest.fixture
def rig_pngs(tmp_path):
    """Three cameras of three small readable PNGs each (no board in them) and a robot file of
    three poses: what the rig's checks of counts, sizes and the robot file look at."""
    import cv2
    import numpy as np
    rig = tmp_path / "rig"
    for cam in ("wrist", "wrist2", "cell"):
        (rig / cam).mkdir(parents=True)
        for k in range(3):
            cv2.imwrite(str(rig / cam / f"img_{k}.png"), np.full((48, 64), 128, np.uint8))
    lines = (DATA / "robot_poses.tum").read_text().splitlines()
    (rig / "robot.tum").write_text("\n".join(lines[:5]) + "\n")   # 2 comments, 3 poses
    from handeye_drake.vision.camera_model import CameraIntrinsics
    from handeye_drake.vision.intrinsics import write_intrinsics_yaml
    for name, f in (("i64", 1), ("i640", 10)):
        write_intrinsics_yaml(CameraIntrinsics(alpha_u=60.0 * f, alpha_v=60.0 * f,
                                               u0=32.0 * f - 0.5, v0=24.0 * f - 0.5,
                                               width=64 * f, height=48 * f),
                              rig / f"{name}.yaml")
    return rig


def _rig_argv(rig, tmp_path, *cameras, extra=()):
    argv = ["calibrate", "--robot", str(rig / "robot.tum"), "--target", TARGET, *extra,
            "--out", str(tmp_path / "out")]
    return argv + [f"--camera={c.format(r=rig)}" for c in cameras]


@pytest.mark.parametrize("cameras, extra, expected", [
    # Were a FAIL verdict (exit 1) blaming the camera for not seeing the board, or a traceback.
    (["w:{r}/wrist:hand:{r}/i640.yaml"], (),
     r"^--camera w:\S+: the intrinsics are for 640×480 images, the camera's are 64×48"),
    (["w:{r}/wrist:hand:1,2,3"], (), r"^--camera w:\S+: intrinsics '1,2,3': expected 4, 8"),
    (["w:{r}/robot.tum"], (), r"^--camera w:\S+: \S+robot.tum is not a folder"),
    (["w:{r}/wrist", "w2:{r}/wrist2"], ("--board-mount", "hand"),
     r"^--camera: every camera is on the board's mount \(hand\)"),
    (["w:{r}/wrist:cell:{r}/i64.yaml"], (), r"^--camera: every camera is on the board's mount"),
    (["w" * 70 + ":{r}/wrist"], (), r"camera name: at most 64 characters"),   # OSError before
    # Read as camera pose files "w:" and ":…/wrist": errors naming no argument.
    (["w:"], (), r"^--camera w:: expected NAME:DIR"),
    ([":{r}/wrist"], (), r"^--camera :\S+: camera name: .*got ''"),
    (["w:{r}/wrist"], ("--target", "charuco:7x5"), r"^--target charuco:7x5: target spec"),
    # Silently ignored before: the rig reads its files as they are.
    (["w:{r}/wrist"], ("--robot-translation-scale", "0.001"),
     r"^--robot-translation-scale: not read for a rig"),
    (["w:{r}/wrist"], ("--max-images", "5"), r"^--max-images: not read for a rig"),
    (["w:{r}/wrist"], ("--image-topic", "/x"), r"^--image-topic: not read for a rig"),
    # One parent link for a hand and a cell camera: one of the two exports was wrong.
    (["w:{r}/wrist", "c:{r}/cell:cell:{r}/i64.yaml"],
     ("--export", "urdf", "--parent-frame", "flange"),
     r"^--parent-frame flange: one parent for cameras on the hand and in the cell"),
    # Refused by the exports only after the fit, calibration.json already written.
    (["-w:{r}/wrist"], ("--export", "urdf"),
     r"^--camera -w:\S+: camera name: expected a frame/link name.*'-w_optical_frame'"),
])
def test_rig_cameras_refused_before_reading(rig_pngs, tmp_path, capsys, cameras, extra,
                                            expected):
    import re
    assert main(_rig_argv(rig_pngs, tmp_path, *cameras, extra=extra)) == 2
    line = _error(capsys)
    assert re.search(expected, line.removeprefix("handeye-drake: error: ")), line
    assert not (tmp_path / "out").exists()


def test_rig_images_that_do_not_pair_or_read(rig_pngs, tmp_path, capsys):
    import cv2
    import numpy as np
    r = rig_pngs
    # One image more than robot poses: was a FAIL verdict (exit 1) after reading every camera.
    cv2.imwrite(str(r / "wrist2" / "img_3.png"), np.zeros((48, 64), np.uint8))
    assert main(_rig_argv(r, tmp_path, "w:{r}/wrist", "w2:{r}/wrist2")) == 2
    assert re.search(r"^--camera w2:\S+: .*4 images but 3 robot poses",
                     _error(capsys).removeprefix("handeye-drake: error: "))
    # An image of another size in one camera's folder: was skipped without a word.
    (r / "wrist2" / "img_3.png").unlink()
    cv2.imwrite(str(r / "wrist2" / "img_1.png"), np.zeros((24, 32), np.uint8))
    assert main(_rig_argv(r, tmp_path, "w:{r}/wrist", "w2:{r}/wrist2")) == 2
    assert "--camera w2:" in (line := _error(capsys)) and \
        "images of different sizes (img_0.png 64×48, img_1.png 32×24)" in line
    # Files that are not images: was a FAIL verdict naming no argument.
    for k in range(3):
        (r / "wrist2" / f"img_{k}.png").write_text("not a png")
    assert main(_rig_argv(r, tmp_path, "w:{r}/wrist", "w2:{r}/wrist2")) == 2
    assert re.search(r"^--camera w2:\S+: .*no image could be read",
                     _error(capsys).removeprefix("handeye-drake: error: "))
    # The robot file's errors name --robot (were a FAIL verdict per camera).
    argv = _rig_argv(r, tmp_path, "w:{r}/wrist")
    argv[argv.index("--robot") + 1] = str(r / "wrist")
    assert main(argv) == 2
    assert re.search(r"^--robot \S+wrist: a folder",
                     _error(capsys).removeprefix("handeye-drake: error: "))
    assert not (tmp_path / "out").exists()



@pytest.mark.parametrize("cameras, expected", [
    # YAML reads ~ and yes as None and True: cameras silently named "None" and "True".
    ("  ~: {images: wrist}\n", "camera name None: expected letters"),
    ("  yes: {images: wrist}\n", "camera name True: expected letters"),
    # A list of numbers for intrinsics was read as the text "[612, …]" (a FAIL verdict).
    ("  wrist: {images: wrist, intrinsics: [612, 611, 318, 243]}\n",
     "camera wrist: intrinsics: expected a string, got [612"),
    ("  wrist: {images: [wrist, cell]}\n", "camera wrist: images: expected a string"),
])
def test_rig_yaml_wrong_types(rig_dir, tmp_path, capsys, cameras, expected):
    rig = _rig_yaml(rig_dir, cameras)
    assert main(["calibrate", "--rig", str(rig), "--out", str(tmp_path / "out")]) == 2
    line = _error(capsys)
    assert line.startswith(f"handeye-drake: error: --rig {rig}: ") and expected in line


@pytest.mark.parametrize("extra, expected", [
    # Were merged with the YAML's (--camera), won over it (--target) or ignored (--bag).
    (["--camera", "w2:{r}/cell"], "--camera w2:{r}/cell: the rig's cameras are in --rig"),
    (["--target", "charuco:5x7:0.04:0.03:DICT_5X5_100"],
     f"--target charuco:5x7:0.04:0.03:DICT_5X5_100: --rig {{y}} gives target: {TARGET}"),
    (["--bag", "{r}/robot_poses.tum"], "--bag: a rig YAML (--rig {y}) reads image folders"),
])
def test_rig_yaml_and_command_line_disagree(rig_dir, tmp_path, capsys, extra, expected):
    rig = _rig_yaml(rig_dir, "  wrist: {images: wrist}\n  cell: {images: cell, mount: cell}\n")
    argv = ["calibrate", "--rig", str(rig), *[x.format(r=rig_dir) for x in extra],
            "--out", str(tmp_path / "out")]
    assert main(argv) == 2
    assert _error(capsys).startswith("handeye-drake: error: " + expected.format(r=rig_dir, y=rig))


def test_rig_out_with_a_user_file_refused_before_the_fit(rig_pngs, tmp_path, capsys):
    # --force into a folder holding the user's cell/calibration.json: was refused only when
    # that file came to be written, after the fit, calibration.json and report.txt written.
    out = tmp_path / "out"
    (out / "cell").mkdir(parents=True)
    (out / "cell" / "calibration.json").write_text("mine")
    argv = _rig_argv(rig_pngs, tmp_path, "w:{r}/wrist:hand:{r}/i64.yaml",
                     "cell:{r}/cell:cell:{r}/i64.yaml", extra=("--force",))
    assert main(argv) == 2
    assert "cell/calibration.json exists and was not written by" in _error(capsys)
    assert sorted(p.name for p in out.rglob("*")) == ["calibration.json", "cell"]
    assert (out / "cell" / "calibration.json").read_text() == "mine"


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


def test_calibrate_rig_bad_input_is_an_error_a_blind_camera_a_verdict(rig_pngs):
    # Unreadable images, counts that do not pair and a rig with nothing to place the board were
    # FAIL verdicts blaming the camera ("does not see the board"); a camera whose images are
    # readable but show no board stays a verdict, with or without its intrinsics.
    from handeye_drake.calibration.rig import RigCamera, calibrate_rig
    r = rig_pngs
    robot = r / "robot.tum"
    res = calibrate_rig([RigCamera("w", r / "wrist"), RigCamera("c", r / "cell", "cell",
                                                                 str(r / "i64.yaml"))],
                        robot, TARGET)
    assert res.verdict.status == "FAIL"
    assert "camera w does not see the board" in res.cameras["w"].verdict.reasons[0].message
    with pytest.raises(ValueError, match="^cameras: every camera is on the board's mount"):
        calibrate_rig([RigCamera("c", r / "cell", "cell", str(r / "i64.yaml"))], robot, TARGET)
    with pytest.raises(ValueError, match="^camera name: at most 64 characters"):
        RigCamera("c" * 65, r / "cell")
    (r / "wrist2" / "img_0.png").unlink()
    with pytest.raises(ValueError, match=r"^camera w2: --images, --robot: 2 images but 3"):
        calibrate_rig([RigCamera("w", r / "wrist"), RigCamera("w2", r / "wrist2")], robot,
                      TARGET)
    for k in range(3):
        (r / "wrist" / f"img_{k}.png").write_text("not a png")
    with pytest.raises(ValueError, match=r"^camera w: --images: no image could be read"):
        calibrate_rig([RigCamera("w", r / "wrist")], robot, TARGET)


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

"""Time stamps of image files (``recorded.image_stamps``) and the choice between pairing images
with the robot poses by index or in time (``calibration.inputs.choose_pairing``): file-name
conventions, stamps files, and a clear error naming the folder when time pairing is asked for
and the stamps are missing or ambiguous (command line: one line, exit 2). No image is decoded:
the choice is made before."""

import numpy as np
import pytest

from handeye_drake.calibration.inputs import choose_pairing, image_groups, robot_stamp_problem
from handeye_drake.recorded.formats import pose_stream
from handeye_drake.recorded.image_stamps import image_stamps, read_stamp_file, stamp_from_name

T0 = 1764800000.0


@pytest.mark.parametrize("name, seconds, rule", [
    ("1764800000.125.png", T0 + 0.125, "<seconds>.<fraction>"),
    ("rgb_12.500000.jpg", 12.5, "<seconds>.<fraction>"),
    ("1764800000_125000000.png", T0 + 0.125, "<seconds>_<nanoseconds>"),
    ("cam0-1764800000_000000001.png", T0 + 1e-9, "<seconds>_<nanoseconds>"),
    ("1764800000125000000.png", T0 + 0.125, "<nanoseconds>"),
    ("frame_1764800000125000000.png", T0 + 0.125, "<nanoseconds>")])
def test_file_name_conventions(name, seconds, rule):
    t, r = stamp_from_name(name)
    assert r == rule and abs(t - seconds) < 1e-6


@pytest.mark.parametrize("name", ["img_000.png", "frame0042.jpg", "left0007.png", "7.png",
                                  "1764800000125000.png", "board.png"])
def test_frame_numbers_and_other_names_hold_no_stamp(name):
    assert stamp_from_name(name) is None


def _touch(folder, names):
    folder.mkdir(parents=True, exist_ok=True)
    for n in names:
        (folder / n).write_bytes(b"")
    return sorted(folder / n for n in names)


def _stamps(folder):
    (spec, files), = image_groups([str(folder)])
    return image_stamps(spec, files)


def test_stamps_file_two_columns_either_order_header_unit_and_other_files(tmp_path):
    files = _touch(tmp_path / "a", ["img_000.png", "img_001.png", "img_002.png"])
    (tmp_path / "a" / "timestamps.txt").write_text(
        "# image stamp\nimg_000.png 1764800000.5\n1764800001.25, img_001.png\n"
        "img_002.png 1764800002.0  # last\ndepth_000.png 1764800000.5\n")
    assert np.allclose(read_stamp_file(tmp_path / "a" / "timestamps.txt", files),
                       T0 + np.array([0.5, 1.25, 2.0]))
    # EuRoC data.csv as times.csv: a header naming nanoseconds, integer stamps.
    files = _touch(tmp_path / "b", ["x.png", "y.png"])
    (tmp_path / "b" / "times.csv").write_text(
        "#timestamp [ns],filename\n1764800000000000100,x.png\n1764800000500000000,y.png\n")
    s = _stamps(tmp_path / "b")
    assert s.problem == "" and np.allclose(s.stamps - T0, [1e-7, 0.5], atol=1e-6)
    # KITTI times.txt style: one stamp per line, in natural file-name order.
    _touch(tmp_path / "c", ["0.png", "1.png", "2.png"])
    (tmp_path / "c" / "times.csv").write_text("0.0\n0.1\n0.25\n")
    assert np.allclose(_stamps(tmp_path / "c").stamps, [0.0, 0.1, 0.25])


@pytest.mark.parametrize("names, text, why", [
    (["a.png", "b.png"], "a.png 1764800000.5\n", "no stamp for 1 of 2 images (b.png)"),
    (["a.png", "b.png"], "a.png 1764800000\nb.png 1764800001\n", "has no unit"),
    (["a.png", "b.png"], "a.png 1.0\nb.png 1.0\n", "same stamp"),
    (["a.png", "b.png"], "1.0\n", "1 stamps for 2 images"),
    (["a.png", "b.png"], "a.png 1.0\na.png 2.0\n", "a.png is stamped twice")])
def test_bad_stamps_files_say_why_and_where(tmp_path, names, text, why):
    _touch(tmp_path / "cam", names)
    (tmp_path / "cam" / "timestamps.txt").write_text(text)
    s = _stamps(tmp_path / "cam")
    assert s.stamps is None and why in s.problem and str(tmp_path / "cam") in s.problem


@pytest.mark.parametrize("names, why", [
    (["img_000.png", "img_001.png"], "no time stamp in the file names"),
    (["1764800000.5.png", "frame_1764800001000000000.png"], "different stamp conventions"),
    (["1764800000.5.png", "img_001.png"], "1 of 2 images have no time stamp"),
    (["1764800000000001.png", "1764800000000002.png"], "microseconds or nanoseconds"),
    (["1764800000.5.png", "1764800000.500.png"], "the same stamp")])
def test_missing_or_ambiguous_stamps_in_names_name_the_folder(tmp_path, names, why):
    _touch(tmp_path / "cam", names)
    s = _stamps(tmp_path / "cam")
    assert s.stamps is None and why in s.problem and str(tmp_path / "cam") in s.problem


def test_both_stamps_files_are_ambiguous(tmp_path):
    _touch(tmp_path / "cam", ["a.png"])
    (tmp_path / "cam" / "timestamps.txt").write_text("a.png 1.0\n")
    (tmp_path / "cam" / "times.csv").write_text("a.png,1.0\n")
    assert "ambiguous" in _stamps(tmp_path / "cam").problem


def _robot(times):
    return pose_stream(np.repeat(np.eye(4)[None], len(times), axis=0), times, source="robot.tum")


def test_auto_pairs_in_time_only_with_stamped_images_and_a_timed_robot(tmp_path):
    stamped = tmp_path / "stamped"
    _touch(stamped, [f"{T0 + 0.5 * k:.6f}.png" for k in range(4)])
    plain = tmp_path / "plain"
    _touch(plain, [f"img_{k:03d}.png" for k in range(4)])
    timed = _robot(T0 + 0.01 * np.arange(300))
    indices = _robot(np.arange(4.0))
    assert robot_stamp_problem(timed) == "" and "indices 0…3" in robot_stamp_problem(indices)
    how, t, note = choose_pairing(image_groups([str(stamped)]), timed)
    assert how == "time" and np.allclose(t, T0 + 0.5 * np.arange(4)) and "<seconds>" in note
    # Frame numbers: index as always, nothing to add; stamped images with an index-stamped
    # robot file: index, saying why not time.
    assert choose_pairing(image_groups([str(plain)]), timed) == ("index", None, "")
    how, _, note = choose_pairing(image_groups([str(stamped)]), indices)
    assert how == "index" and "indices 0…3, not times" in note
    # Stamps on another clock (no overlap with the robot's span): index, saying so.
    how, _, note = choose_pairing(image_groups([str(stamped)]), _robot(np.arange(10.0) * 0.3))
    assert how == "index" and "another clock" in note
    with pytest.raises(ValueError, match=f"--pairing time: {plain}: no time stamp"):
        choose_pairing(image_groups([str(plain)]), timed, "time")
    with pytest.raises(ValueError, match="--pairing time: the stamps of robot.tum are the ind"):
        choose_pairing(image_groups([str(stamped)]), indices, "time")
    assert choose_pairing(image_groups([str(stamped)]), timed, "index")[0] == "index"
    with pytest.raises(ValueError, match="--pairing: expected one of"):
        choose_pairing(image_groups([str(stamped)]), timed, "nearest")


def _cli(*argv):
    from handeye_drake.apps.cli import main
    return main(list(map(str, argv)))


def test_command_line_time_pairing_without_stamps_is_one_line_naming_the_folder(tmp_path,
                                                                               capsys):
    cam = tmp_path / "wrist"
    _touch(cam, [f"img_{k:03d}.png" for k in range(4)])
    mixed = tmp_path / "cell"
    _touch(mixed, ["1764800000.5.png", "frame_1764800001000000000.png"])
    robot = tmp_path / "robot.tum"
    robot.write_text("".join(f"{T0 + 0.01 * k:.6f} 0 0 0.5 0 0 0 1\n" for k in range(300)))
    target = "charuco:7x5:0.04:0.03:DICT_5X5_100"
    assert _cli("calibrate", "--images", cam, "--robot", robot, "--target", target,
                "--pairing", "time", "--out", tmp_path / "o1") == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"--pairing time: {cam}: no time stamp" in err, err
    assert _cli("calibrate", "--robot", robot, "--target", target, "--pairing", "time",
                "--camera", f"cell:{mixed}:hand", "--out", tmp_path / "o2") == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "cell" in err and "--pairing time" in err and str(mixed) in err
    assert "different stamp conventions" in err, err

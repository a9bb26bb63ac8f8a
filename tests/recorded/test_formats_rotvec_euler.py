"""Robot poses as a UR rotation vector (``csv-rotvec``) or Euler angles
(``csv-euler:ORDER:UNIT``): round trips through the files, the conventions against
scipy.spatial.transform.Rotation and against elementary rotations written out by hand (KUKA
A B C, Fanuc W P R), the unit and order checks, the command line."""

import json
import math
from pathlib import Path

import handeye_drake
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handeye_drake.apps.cli import main
from handeye_drake.recorded.formats import check_format, parse_poses, read_poses

ORDERS = ["xyz", "zyx", "xzy", "zxz", "XYZ", "ZYX", "YXZ", "ZYZ"]


def _poses(n=40, seed=0):
    rng = np.random.default_rng(seed)
    R = Rotation.random(n, random_state=seed)
    t = rng.uniform(-0.8, 0.8, size=(n, 3))
    return R, t


def _write(rows, stamps=None, fmt="{:.12g}"):
    lines = ["# a comment line"]
    for k, row in enumerate(rows):
        values = ([stamps[k]] if stamps is not None else []) + list(row)
        lines.append(", ".join(fmt.format(v) for v in values))
    return "\n".join(lines) + "\n"


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


@pytest.mark.parametrize("stamped", [False, True])
def test_rotvec_round_trip(stamped):
    R, t = _poses()
    stamps = 0.02 * np.arange(len(t)) + 100.0 if stamped else None
    text = _write(np.hstack([t, R.as_rotvec()]), stamps)
    s = parse_poses(text, "csv-rotvec", "robot")
    assert np.abs(s.poses[:, :3, :3] - R.as_matrix()).max() < 1e-10
    assert np.abs(s.poses[:, :3, 3] - t).max() < 1e-11
    assert list(s.lines) == list(range(2, 2 + len(t)))
    if stamped:
        np.testing.assert_allclose(s.timestamps, stamps)
    else:
        assert s.timestamps is None


@pytest.mark.parametrize("order", ORDERS)
@pytest.mark.parametrize("unit", ["deg", "rad"])
def test_euler_round_trip_is_scipy_from_euler(order, unit):
    R, t = _poses(seed=len(order) + ORDERS.index(order))
    angles = R.as_euler(order, degrees=unit == "deg")
    s = parse_poses(_write(np.hstack([t, angles])), f"csv-euler:{order}:{unit}", "robot")
    np.testing.assert_allclose(s.poses[:, :3, :3],
                               Rotation.from_euler(order, angles, degrees=unit == "deg")
                               .as_matrix(), atol=1e-12)
    assert np.abs(s.poses[:, :3, :3] - R.as_matrix()).max() < 1e-9
    assert np.abs(s.poses[:, :3, 3] - t).max() < 1e-11


def test_kuka_abc_and_fanuc_wpr_as_their_manuals_define_them():
    """KUKA: A about z, then B about the new y, then C about the newest x (intrinsic Z-Y'-X'');
    Fanuc: W about the fixed x, P about the fixed y, R about the fixed z (extrinsic x-y-z). Both
    are R = Rz · Ry · Rx, with the columns in opposite orders."""
    rng = np.random.default_rng(3)
    abc = rng.uniform(-170, 170, size=(25, 3))
    abc[:, 1] = rng.uniform(-85, 85, size=25)
    t_mm = rng.uniform(-900, 900, size=(25, 3))
    kuka = parse_poses(_write(np.hstack([t_mm, abc])), "csv-euler:ZYX:deg", "robot",
                       translation_scale=1e-3)
    wpr = abc[:, ::-1]  # W P R = C B A
    fanuc = parse_poses(_write(np.hstack([t_mm, wpr])), "csv-euler:xyz:deg", "robot",
                        translation_scale=1e-3)
    for k, (a, b, c) in enumerate(np.radians(abc)):
        by_hand = _rz(a) @ _ry(b) @ _rx(c)
        np.testing.assert_allclose(kuka.poses[k, :3, :3], by_hand, atol=1e-12)
        np.testing.assert_allclose(fanuc.poses[k, :3, :3], by_hand, atol=1e-12)
    np.testing.assert_allclose(kuka.poses[:, :3, 3], t_mm / 1000, atol=1e-12)
    # The same numbers read with the other convention are another rotation.
    other = parse_poses(_write(np.hstack([t_mm, abc])), "csv-euler:zyx:deg", "robot",
                        translation_scale=1e-3)
    assert np.abs(other.poses[:, :3, :3] - kuka.poses[:, :3, :3]).max() > 0.5


def test_unit_checks_name_the_other_unit():
    R, t = _poses(10)
    deg_as_rad = _write(np.hstack([t, R.as_euler("ZYX", degrees=True)]))
    with pytest.raises(ValueError, match=r"<text>:\d+: Euler angles .* exceed 2π rad: degrees\? "
                                         r"use --format csv-euler:ZYX:deg"):
        parse_poses(deg_as_rad, "csv-euler:ZYX:rad", "robot")
    rad_as_deg = _write(np.hstack([t, R.as_euler("ZYX")]))
    with pytest.raises(ValueError, match=r"within ±π .* radians\? use --format "
                                         r"csv-euler:ZYX:rad"):
        parse_poses(rad_as_deg, "csv-euler:ZYX:deg", "robot")
    rotvec_deg = _write(np.hstack([t, np.degrees(R.as_rotvec())]))
    with pytest.raises(ValueError, match=r"rotation vector .* more than 2π: csv-rotvec takes "
                                         r"radians"):
        parse_poses(rotvec_deg, "csv-rotvec", "robot")
    mm = _write(np.hstack([1000 * t + 2000, R.as_rotvec()]))
    with pytest.raises(ValueError, match=r"millimetres\?.*--translation-scale 0\.001"):
        parse_poses(mm, "csv-rotvec", "robot")


@pytest.mark.parametrize("fmt, message", [
    ("csv-euler:zYx:deg", "all lowercase .* or all uppercase"),
    ("csv-euler:zzx:deg", "twice in a row"),
    ("csv-euler:abc:deg", "three of x, y, z"),
    ("csv-euler:zyx:grad", "UNIT must be deg or rad"),
    ("csv-euler:zyx", "expected csv-euler:ORDER:UNIT"),
    ("csv-euler", "expected csv-euler:ORDER:UNIT"),
    ("csv-quat", "expected one of tum, csv-matrix, opencv-yaml, csv-rotvec, "
                 "csv-euler:ORDER:UNIT"),
])
def test_bad_format_names(fmt, message):
    with pytest.raises(ValueError, match=message):
        check_format(fmt)


def test_field_counts_are_checked_line_by_line():
    R, t = _poses(5)
    rows = np.hstack([t, R.as_rotvec()])
    text = _write(rows) + "1 2 3 4 5\n"
    with pytest.raises(ValueError, match=r"<text>:7: expected 6 numbers \(x y z rx ry rz\) or 7"):
        parse_poses(text, "csv-rotvec", "robot")
    mixed = _write(rows[:2], [0.0, 1.0]) + _write(rows[2:])
    with pytest.raises(ValueError, match="every line must have a timestamp, or none"):
        parse_poses(mixed, "csv-euler:xyz:rad", "robot")


def test_command_line_reads_both_and_rejects_a_bad_format(tmp_path, capsys):
    """The shipped recording's robot file rewritten as UR and KUKA files reads back as the TUM
    original, and calibrates with a TUM camera file (--robot-format); a bad format is a one-line
    error naming the option."""
    data = Path(handeye_drake.__file__).parent / "data"
    robot = read_poses(data / "example_robot.tum", "robot")
    R = Rotation.from_matrix(robot.poses[:, :3, :3])
    t = robot.poses[:, :3, 3]
    ur = tmp_path / "robot_ur.csv"
    ur.write_text(_write(np.hstack([t, R.as_rotvec()]), robot.timestamps, "{:.9f}"))
    kuka = tmp_path / "robot_kuka.csv"
    kuka.write_text(_write(np.hstack([1000 * t, R.as_euler("ZYX", degrees=True)]),
                           robot.timestamps, "{:.7f}"))
    for path, fmt, scale in ((ur, "csv-rotvec", 1.0), (kuka, "csv-euler:ZYX:deg", 1e-3)):
        s = read_poses(path, "robot", fmt, translation_scale=scale)
        assert np.abs(s.poses - robot.poses).max() < 1e-6
        np.testing.assert_allclose(s.timestamps, robot.timestamps)
    code = main(["calibrate", "--robot", str(kuka), "--camera", str(data / "example_camera.tum"),
                 "--robot-format", "csv-euler:ZYX:deg", "--robot-translation-scale", "0.001",
                 "--out", str(tmp_path / "out")])
    doc = json.loads((tmp_path / "out" / "calibration.json").read_text())
    assert code == 0 and doc["verdict"]["status"] == "OK"
    assert doc["inputs"]["robot"]["format"] == "csv-euler:ZYX:deg"
    X_true = np.array(json.loads((data / "example_truth.json").read_text())["X_EC"])
    assert np.linalg.norm(np.array(doc["X_EC"]["matrix"])[:3, 3] - X_true[:3, 3]) < 2e-3
    capsys.readouterr()
    code = main(["calibrate", "--robot", str(kuka), "--camera", str(data / "example_camera.tum"),
                 "--robot-format", "csv-euler:zYx:deg", "--out", str(tmp_path / "out2")])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("handeye-drake calibrate: error: argument --robot-format: format "
                              "'csv-euler:zYx:deg': ORDER must be")
    assert "Traceback" not in "\n".join(err)

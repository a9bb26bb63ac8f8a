"""Multi-camera rigs with several boards (``calibration.rig``, ``--board``) on one rendered cell
(RenderEngineVtk, rendered once per module): two ChArUco boards on the table of different
dictionaries, two hand cameras that see the first board in images 0–7 and the second in 8–11, a
cell camera that sees only the first, a cell camera that sees only the second. Each camera and
each board's pose within its σ of the truth; the command line agrees with the library; a board
no camera sees, a board moved half-way and two boards a detection cannot tell apart are named."""

import json

import numpy as np
import pytest
from scipy.stats import chi2

from handeye_drake.calibration.api import CalibrationOptions
from handeye_drake.calibration.rig import (RigBoard, RigCamera, calibrate_rig, check_boards,
                                           marker_ids)
from handeye_drake.estimation.rig_bundle import tangent
from handeye_drake.estimation.se3 import make_transform, rotation_exp
from handeye_drake.recorded.example_rig import (TWO_BOARD_RIG, generate_example_rig,
                                                relative_truth, two_boards)

#: χ²(6) bound of a 6-dof error whitened by its covariance (1 in 1000 by chance).
BOUND = float(chi2.ppf(0.999, 6))
OPTIONS = CalibrationOptions(refine_intrinsics="none")
NAMES = ("wrist", "wrist2", "cell", "side")


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    out = tmp_path_factory.mktemp("rig_boards")
    truth = generate_example_rig(out, seed=3, num_images=8, cameras=TWO_BOARD_RIG,
                                 boards=two_boards(), board_images={"side": 4}, supersample=2)
    return out, truth


def _cams(out, truth, names, folders=None):
    folders = folders or {}
    return [RigCamera(n, out / folders.get(n, n), truth["cameras"][n]["mount"],
                      str(out / n / "intrinsics.yaml")) for n in names]


def _boards(truth):
    return [RigBoard(n, b["target"], b["mount"]) for n, b in truth["boards"].items()]


def _nees(X, C, X_true):
    e = tangent(X, np.asarray(X_true))
    return float(e @ np.linalg.solve(C, e))


@pytest.fixture(scope="module")
def result(rig):
    out, truth = rig
    return calibrate_rig(_cams(out, truth, NAMES), out / "robot_poses.tum", _boards(truth),
                         options=OPTIONS)


def test_two_boards_and_mixed_cameras_within_sigma(rig, result):
    out, truth = rig
    r = result
    assert r.verdict.status in ("OK", "WARN"), r.lines()
    # Who sees what: the hand cameras both boards, each cell camera one.
    assert r.cameras["wrist"].boards == {"table": 8, "side": 4}
    assert r.cameras["cell"].boards == {"table": 12}
    assert r.cameras["side"].boards == {"side": 12}
    for name, c in r.cameras.items():
        assert c.verdict.status != "FAIL", (name, c.verdict.reasons)
        assert _nees(c.X, c.covariance, truth["cameras"][name][c.key]) < BOUND, name
        assert np.max(c.sigma()[1]) < (0.004 if c.mount == "cell" else 0.001), name
    for name, b in r.boards.items():
        assert b.verdict.status == "OK", (name, b.verdict.reasons)
        assert _nees(b.X, b.covariance, truth["boards"][name]["X_BT"]) < BOUND, name
        assert np.max(b.sigma()[1]) < 0.001, name
    # The cell camera that never sees the table board is placed through the side board's pose,
    # which only the hand cameras' four images of it give.
    X, C = r.relative[("wrist", "wrist2")]
    assert _nees(X, C, relative_truth(truth, "wrist", "wrist2")) < BOUND
    X, C = r.relative[("cell", "side")]
    assert _nees(X, C, relative_truth(truth, "cell", "side")) < BOUND
    # Each hand camera's view of each board was checked against the rest of the rig.
    for name in ("wrist", "wrist2"):
        a = r.cameras[name].agreements
        assert set(a) == {"table", "side"}
        assert all(v["chi2"] < v["threshold"] for v in a.values()), a
    # One-board fields stay: the first board's.
    assert r.board_mount == "cell" and np.array_equal(r.X_board, r.boards["table"].X)
    j = r.to_json()
    assert set(j["boards"]) == {"table", "side"} and j["boards"]["side"]["X_BT"] is not None
    assert j["cameras"]["side"]["boards"] == {"side": 12}
    assert any(line.startswith("board side (cell, X_BT, charuco:5x4") for line in r.lines())


def _cli(*argv):
    from handeye_drake.apps.cli import main
    return main(list(map(str, argv)))


def test_command_line_with_two_boards_agrees_with_the_library(rig, result, tmp_path, capsys):
    out, truth = rig
    args = ["calibrate", "--robot", out / "robot_poses.tum", "--refine-intrinsics", "none",
            "--out", tmp_path / "o", "--export", "urdf"]
    for n, b in truth["boards"].items():
        args += ["--board", f"{n}:{b['target']}:{b['mount']}"]
    for n in NAMES:
        args += ["--camera", f"{n}:{out / n}:{truth['cameras'][n]['mount']}:"
                             f"{out / n / 'intrinsics.yaml'}"]
    assert _cli(*args) == 0
    printed = capsys.readouterr().out
    assert "board side (cell, X_BT" in printed and "seen by wrist in 4, wrist2 in 4, side" \
        in printed
    j = json.loads((tmp_path / "o" / "calibration.json").read_text())
    lib = result.to_json()
    for n in NAMES:
        key = result.cameras[n].key
        assert np.allclose(j["cameras"][n][key], lib["cameras"][n][key], atol=1e-9), n
    for n in ("table", "side"):
        assert np.allclose(j["boards"][n]["X_BT"], lib["boards"][n]["X_BT"], atol=1e-9), n
        assert np.allclose(j["boards"][n]["covariance"], lib["boards"][n]["covariance"],
                           rtol=1e-6)
    assert (tmp_path / "o" / "side" / "handeye.urdf").is_file()


def test_rig_yaml_with_boards(rig, tmp_path):
    from handeye_drake.apps.calibrate.rig_command import read_rig_yaml
    out, truth = rig
    (tmp_path / "rig.yaml").write_text(
        f"robot: {out / 'robot_poses.tum'}\nboards:\n"
        + "".join(f"  {n}: {{target: '{b['target']}', mount: cell}}\n"
                  for n, b in truth["boards"].items())
        + f"cameras:\n  side: {{images: {out / 'side'}, mount: cell, intrinsics: "
          f"{out / 'side' / 'intrinsics.yaml'}, boards: [side]}}\n")
    doc = read_rig_yaml(tmp_path / "rig.yaml")
    assert [(b.name, b.mount) for b in doc["boards"]] == [("table", "cell"), ("side", "cell")]
    assert doc["boards"][1].target == truth["boards"]["side"]["target"]
    assert doc["cameras"][0].boards == ("side",)
    (tmp_path / "bad.yaml").write_text(
        f"robot: x.tum\ntarget: charuco:7x5:0.04:0.03:DICT_5X5_100\nboards:\n  a: "
        f"charuco:7x5:0.04:0.03:DICT_5X5_100\ncameras:\n  side: {{images: {out / 'side'}}}\n")
    with pytest.raises(ValueError, match="either target .* or boards"):
        read_rig_yaml(tmp_path / "bad.yaml")


def test_a_board_no_camera_sees_is_named(rig):
    out, truth = rig
    boards = _boards(truth) + [RigBoard("shelf", "aprilgrid:36h11:4x3:0.03:0.3", "cell")]
    r = calibrate_rig(_cams(out, truth, ["wrist", "side"]), out / "robot_poses.tum", boards,
                      options=OPTIONS)
    assert r.verdict.status == "FAIL"
    assert r.verdict.reasons[0].code == "boards"
    assert "board shelf" in r.verdict.reasons[0].message
    assert r.boards["shelf"].verdict.reasons[0].code == "board_not_seen"
    assert r.boards["shelf"].X is None and r.boards["shelf"].seen_by == {}
    # The rest is calibrated, within σ.
    for name, c in r.cameras.items():
        assert c.verdict.status != "FAIL" and \
            _nees(c.X, c.covariance, truth["cameras"][name][c.key]) < BOUND, name
    assert _nees(r.boards["side"].X, r.boards["side"].covariance,
                 truth["boards"]["side"]["X_BT"]) < BOUND


def test_a_board_moved_half_way_is_named(tmp_path):
    """The side board pushed 1° / 8 mm between images 9 and 10 (rendered): the wrist camera's
    images of the table board place the camera, so the board is named, not the camera; the cell
    camera that sees only that board sees its view jump — explained by the board, not blamed on
    the camera."""
    out = tmp_path / "rig"
    push = make_transform(rotation_exp(np.radians([0.0, 0.0, 1.0])), [0.008, 0.0, 0.0])
    truth = generate_example_rig(out, seed=3, num_images=8, cameras={
        n: TWO_BOARD_RIG[n] for n in ("wrist", "side")}, boards=two_boards(),
        board_images={"side": 4}, supersample=2, moved_board=("side", 10, push))
    r = calibrate_rig(_cams(out, truth, ["wrist", "side"]), out / "robot_poses.tum",
                      _boards(truth), options=OPTIONS)
    assert r.verdict.status == "FAIL"
    why = r.boards["side"].verdict.reasons[0]
    assert why.code == "board_moved", r.lines()
    assert why.message.startswith("board side moved") and "between images 9 and 10" in \
        why.message
    assert r.cameras["wrist"].verdict.status != "FAIL"
    assert _nees(r.cameras["wrist"].X, r.cameras["wrist"].covariance,
                 truth["cameras"]["wrist"]["X_EC"]) < BOUND
    assert r.boards["side"].X is None and r.boards["table"].X is not None
    why = r.cameras["side"].verdict.reasons[0]
    assert why.code == "board_moved" and "board side moved" in why.message


def test_boards_a_detection_cannot_tell_apart_are_refused(tmp_path, capsys):
    spec = "charuco:7x5:0.04:0.03:DICT_5X5_100"
    assert marker_ids(spec)[0] == "DICT_5X5_100" and len(marker_ids(spec)[1]) == 17
    assert marker_ids("chessboard:9x6:0.02") is None
    with pytest.raises(ValueError, match="boards a and b are the same board"):
        check_boards([RigBoard("a", spec), RigBoard("b", spec, "hand")])
    with pytest.raises(ValueError, match="boards a and b are boards whose markers overlap"):
        check_boards([RigBoard("a", spec), RigBoard("b", "charuco:5x4:0.03:0.022:DICT_5X5_100")])
    with pytest.raises(ValueError, match="board b .* has no coded markers"):
        check_boards([RigBoard("a", spec), RigBoard("b", "chessboard:9x6:0.02")])
    # Aprilgrids of one family apart by FIRST_ID are told apart.
    check_boards([RigBoard("a", "aprilgrid:36h11:3x3:0.03:0.3"),
                  RigBoard("b", "aprilgrid:36h11:3x3:0.03:0.3:9")])
    with pytest.raises(ValueError, match="target, boards"):
        calibrate_rig([RigCamera("w", tmp_path)], None, spec, boards=[RigBoard("a", spec)])
    with pytest.raises(ValueError, match="camera w: boards: c not among"):
        calibrate_rig([RigCamera("w", tmp_path, boards=["c"])], tmp_path / "r.tum",
                      [RigBoard("a", spec)])


@pytest.mark.parametrize("board, expected", [
    (["table:charuco:7x5:0.04:0.03:DICT_5X5_100", "side:charuco:7x5:0.04:0.03:DICT_5X5_100"],
     "--board: boards table and side are the same board"),
    (["charuco:7x5:0.04:0.03:DICT_5X5_100"], "the board's name comes first"),
    (["t:charuco:7x5:0.04:0.03:DICT_5X5_100:wall"], "mount 'wall': expected cell or hand"),
    (["t:charuco:7x5:0.04:0.03"], "--board t:charuco:7x5:0.04:0.03: board t: target spec"),
    (["t"], "--board t: expected NAME:SPEC"),
])
def test_command_line_bad_boards_are_one_line(rig, tmp_path, capsys, board, expected):
    out, truth = rig
    args = ["calibrate", "--robot", out / "robot_poses.tum",
            "--camera", f"wrist:{out / 'wrist'}", "--out", tmp_path / "o"]
    for b in board:
        args += ["--board", b]
    assert _cli(*args) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and expected in err, err
    assert not (tmp_path / "o").exists()


def test_command_line_board_with_target_or_one_camera_is_refused(rig, tmp_path, capsys):
    out, truth = rig
    spec = "charuco:7x5:0.04:0.03:DICT_5X5_100"
    assert _cli("calibrate", "--robot", out / "robot_poses.tum", "--target", spec, "--board",
                f"t:{spec}", "--camera", f"wrist:{out / 'wrist'}", "--out", tmp_path / "o") == 2
    assert "not both" in capsys.readouterr().err
    assert _cli("calibrate", "--robot", out / "robot_poses.tum", "--images", out / "wrist",
                "--board", f"t:{spec}", "--out", tmp_path / "o") == 2
    assert "--board t:" in capsys.readouterr().err

"""Multi-camera rigs calibrated jointly (``calibration.rig``) on a rendered cell: two hand cameras
and cell cameras watching one board fixed in the cell (mixed modes), rendered once per module;
each answer within its σ of the truth, and bad rigs (a camera that never sees the board, swapped
folders, a camera knocked half-way) FAIL naming the camera."""

import dataclasses
import math

import cv2
import numpy as np
import pytest
from scipy.stats import chi2

from handeye_drake.calibration.api import CalibrationOptions
from handeye_drake.calibration.rig import RigCamera, calibrate_rig
from handeye_drake.estimation.rig_bundle import tangent
from handeye_drake.estimation.se3 import make_transform, rotation_exp
from handeye_drake.recorded.example_rig import (TRUE_X_BC_CELL, TRUE_X_EC, TRUE_X_EC2,
                                                generate_example_rig, relative_truth)

#: χ²(6) bound of a 6-dof error whitened by its covariance (1 in 1000 by chance).
BOUND = float(chi2.ppf(0.999, 6))
OPTIONS = CalibrationOptions(refine_intrinsics="none")
#: The knocked camera: 1° and 8 mm off from image 4 on.
KNOCK = make_transform(rotation_exp(np.radians([0.0, 1.0, 0.0])), [0.008, 0.0, 0.0])


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    out = tmp_path_factory.mktemp("rig")
    cameras = {"wrist": ("hand", TRUE_X_EC), "wrist2": ("hand", TRUE_X_EC2),
               "cell": ("cell", TRUE_X_BC_CELL), "knocked": ("cell", TRUE_X_BC_CELL),
               "slipped": ("hand", TRUE_X_EC2)}
    truth = generate_example_rig(out, seed=3, num_images=8, cameras=cameras,
                                 moved={"knocked": (4, KNOCK), "slipped": (4, KNOCK)},
                                 supersample=2)
    return out, truth


def _cams(out, truth, names, folders=None):
    folders = folders or {}
    return [RigCamera(n, out / folders.get(n, n), truth["cameras"][n]["mount"],
                      str(out / folders.get(n, n) / "intrinsics.yaml")) for n in names]


def _nees(X, C, X_true):
    e = tangent(X, X_true)
    return float(e @ np.linalg.solve(C, e))


def _check_within_sigma(result, truth):
    for name, c in result.cameras.items():
        assert c.verdict.status != "FAIL", (name, c.verdict.reasons)
        X_true = np.asarray(truth["cameras"][name][c.key])
        assert _nees(c.X, c.covariance, X_true) < BOUND, name
        # The camera's σ are not vacuous: a few mm at most (cell camera: one view at 0.9 m).
        assert np.max(c.sigma()[1]) < (0.004 if c.mount == "cell" else 0.001), name


def _check_jackknife_note(result):
    """The report says what the jackknife did, in one note with content: the cameras whose σ it
    widened and by how much, or that it widened none (it once printed "σ widened by a
    delete-one-instant jackknife: " with nothing after it)."""
    lines = result.lines()
    assert all(line.split(":", 1)[1].strip() for line in lines if line.startswith("note:"))
    (note,) = [line for line in lines if "jackknife" in line]
    assert not note.rstrip().endswith(":"), note
    widened = {n: c.variance_factor for n, c in result.cameras.items() if c.variance_factor > 1}
    if widened or "→" in note or "board " in note:
        assert note.startswith("note: σ widened by a delete-one-instant jackknife: "), note
        for name, v in widened.items():
            assert f"{name} ×{math.sqrt(v):.2f}" in note, note
    else:
        assert note == "note: σ checked by a delete-one-instant jackknife: not widened", note
    return note


@pytest.fixture(scope="module")
def three(rig):
    out, truth = rig
    return calibrate_rig(_cams(out, truth, ["wrist", "wrist2", "cell"]), out / "robot_poses.tum",
                         truth["target"], options=OPTIONS)


def test_three_camera_mixed_rig_within_sigma(rig, three):
    out, truth = rig
    r = three
    assert r.verdict.status in ("OK", "WARN"), r.lines()
    _check_within_sigma(r, truth)
    _check_jackknife_note(r)
    X, C = r.relative[("wrist", "wrist2")]
    assert _nees(X, C, relative_truth(truth, "wrist", "wrist2")) < BOUND
    # The camera-to-camera σ has no robot term: it is tighter than either camera's.
    assert np.trace(C[3:, 3:]) < np.trace(r.cameras["wrist"].covariance[3:, 3:])
    assert np.linalg.norm(tangent(r.X_board, np.asarray(truth["X_BT"]))[3:]) < 0.001
    # The two moving cameras agree about the board: χ² on 6 dof under scipy's 10⁻⁴ point.
    for name in ("wrist", "wrist2"):
        a = r.cameras[name].agreement
        assert a["threshold"] == pytest.approx(chi2.isf(1e-4, 6)) and a["chi2"] < a["threshold"]
    j = r.to_json()
    assert set(j["cameras"]) == {"wrist", "wrist2", "cell"} and j["relative"][0]["from"] == "wrist"
    texts = r.export("cell", "urdf,ros2")
    assert "cell_optical_frame" in texts["handeye.urdf"]


def test_agreement_weighs_the_camera_and_the_others(rig, three):
    """The agreement χ² compares two uncertain board poses: the camera's own (its single-camera
    fit) and the others' joint fit — both covariances count. Without the camera's own (the
    larger here: one camera against the joint fit) the χ² grows several-fold and more good
    cameras are called disagreeing."""
    out, truth = rig
    for name in ("wrist", "wrist2"):
        c = three.cameras[name]
        a = c.agreement
        X_o, C_o = np.asarray(a["others_X_board"]), np.asarray(a["others_covariance"])
        C_own = c.alone.fit.fixed_covariance
        d = tangent(c.alone.X_fixed, X_o)
        assert a["chi2"] == pytest.approx(float(d @ np.linalg.solve(C_own + C_o, d)), rel=1e-6)
        assert a["translation_m"] == pytest.approx(np.linalg.norm(d[3:]))
        # Each board pose is within its own σ of the truth (the sum is not a fudge).
        for X, C in ((c.alone.X_fixed, C_own), (X_o, C_o)):
            assert _nees(X, C, np.asarray(truth["X_BT"])) < BOUND, name


def test_two_camera_mixed_rig_within_sigma(rig):
    out, truth = rig
    r = calibrate_rig(_cams(out, truth, ["wrist2", "cell"]), out / "robot_poses.tum",
                      truth["target"], options=OPTIONS)
    assert r.verdict.status in ("OK", "WARN"), r.lines()
    _check_within_sigma(r, truth)
    _check_jackknife_note(r)
    assert not r.relative          # one on the hand, one in the cell: no fixed transform


def test_camera_that_never_sees_the_board_is_named(rig, tmp_path):
    out, truth = rig
    blank = tmp_path / "blank"
    blank.mkdir()
    for k in range(8):
        cv2.imwrite(str(blank / f"img_{k:03d}.png"), np.full((480, 640), 80, np.uint8))
    cams = _cams(out, truth, ["wrist", "cell"]) + [
        RigCamera("blind", blank, "hand", str(out / "wrist" / "intrinsics.yaml"))]
    r = calibrate_rig(cams, out / "robot_poses.tum", truth["target"], options=OPTIONS)
    assert r.verdict.status == "FAIL"
    assert r.cameras["blind"].verdict.status == "FAIL" and r.cameras["blind"].X is None
    assert "camera blind does not see the board" in r.verdict.reasons[0].message
    # The others are still calibrated, within σ.
    assert r.cameras["wrist"].verdict.status != "FAIL" and r.cameras["cell"].X is not None
    assert _nees(r.cameras["wrist"].X, r.cameras["wrist"].covariance,
                 TRUE_X_EC) < BOUND


def test_swapped_folders_are_named(rig):
    out, truth = rig
    cams = _cams(out, truth, ["wrist", "wrist2", "cell"],
                 folders={"wrist2": "cell", "cell": "wrist2"})
    r = calibrate_rig(cams, out / "robot_poses.tum", truth["target"], options=OPTIONS)
    assert r.verdict.status == "FAIL"
    assert r.cameras["cell"].verdict.reasons[0].code == "fixed_view_moves"
    assert "swapped" in r.cameras["cell"].verdict.reasons[0].message
    assert r.cameras["wrist2"].verdict.status == "FAIL"
    assert r.cameras["wrist"].verdict.status != "FAIL"
    assert _nees(r.cameras["wrist"].X, r.cameras["wrist"].covariance, TRUE_X_EC) < BOUND


def test_camera_knocked_half_way_is_named(rig):
    out, truth = rig
    r = calibrate_rig(_cams(out, truth, ["wrist", "knocked"]), out / "robot_poses.tum",
                      truth["target"], options=OPTIONS)
    assert r.verdict.status == "FAIL"
    why = r.cameras["knocked"].verdict.reasons[0]
    assert why.code == "camera_moved" and "camera knocked moved" in why.message
    assert "between images 3 and 4" in why.message
    assert r.cameras["wrist"].verdict.status != "FAIL"


def test_hand_camera_that_slipped_half_way_is_named(rig):
    out, truth = rig
    r = calibrate_rig(_cams(out, truth, ["wrist", "slipped"]), out / "robot_poses.tum",
                      truth["target"], options=OPTIONS)
    why = r.cameras["slipped"].verdict.reasons[0]
    assert r.verdict.status == "FAIL" and why.code == "camera_moved"
    assert "camera slipped moved" in why.message and "between images 3 and 4" in why.message
    assert r.cameras["wrist"].verdict.status != "FAIL"
    assert _nees(r.cameras["wrist"].X, r.cameras["wrist"].covariance, TRUE_X_EC) < BOUND


def test_camera_with_wrong_intrinsics_is_named(rig):
    out, truth = rig
    i = truth["intrinsics"]
    wrong = f"{1.03 * i['fx']},{1.03 * i['fy']},{i['cx']},{i['cy']}"     # focal 3 % long
    cams = _cams(out, truth, ["wrist", "cell"]) + [
        RigCamera("wrist2", out / "wrist2", "hand", wrong)]
    r = calibrate_rig(cams, out / "robot_poses.tum", truth["target"], options=OPTIONS)
    why = r.cameras["wrist2"].verdict.reasons[0]
    assert r.verdict.status == "FAIL" and why.code == "intrinsics"
    assert why.message.startswith("camera wrist2: the intrinsics") and "do not fit the images" in why.message
    assert r.cameras["cell"].verdict.status != "FAIL"
    _check_within_sigma(dataclasses.replace(r, cameras={n: r.cameras[n]
                                                        for n in ("wrist", "cell")}), truth)


def test_rig_camera_arguments_are_checked():
    with pytest.raises(ValueError, match="mount must be one of"):
        RigCamera("a", "dir", "wall")
    with pytest.raises(ValueError, match="camera name"):
        RigCamera("a:b", "dir")


def _cli(*argv):
    from handeye_drake.apps.cli import main
    return main(list(map(str, argv)))


def test_command_line_rig_cameras_and_yaml_agree(rig, tmp_path, capsys):
    out, truth = rig
    cams = [f"{n}:{out / n}:{truth['cameras'][n]['mount']}:{out / n / 'intrinsics.yaml'}"
            for n in ("wrist", "cell")]
    args = ["calibrate", "--robot", out / "robot_poses.tum", "--target", truth["target"],
            "--refine-intrinsics", "none", "--export", "urdf,ros2,drake"]
    for c in cams:
        args += ["--camera", c]
    assert _cli(*args, "--out", tmp_path / "a") == 0
    printed = capsys.readouterr().out
    assert "camera wrist (hand, X_EC)" in printed and "camera cell (cell, X_BC)" in printed
    (note,) = [line for line in printed.splitlines() if "jackknife" in line]
    assert not note.rstrip().endswith(":"), note
    a = tmp_path / "a"
    for n in ("wrist", "cell"):
        assert (a / n / "calibration.json").is_file() and (a / n / "handeye.urdf").is_file()
        assert (a / n / "handeye_directives.yaml").is_file()
    assert "<parent link=\"base_link\"/>" in (a / "cell" / "handeye.urdf").read_text()
    (tmp_path / "rig.yaml").write_text(
        f"robot: {out / 'robot_poses.tum'}\ntarget: {truth['target']}\nboard: cell\ncameras:\n"
        + "".join(f"  {n}: {{images: {out / n}, mount: {truth['cameras'][n]['mount']}, "
                  f"intrinsics: {out / n / 'intrinsics.yaml'}}}\n" for n in ("wrist", "cell")))
    assert _cli("calibrate", "--rig", tmp_path / "rig.yaml", "--refine-intrinsics", "none",
                "--out", tmp_path / "b") == 0
    import json
    ja = json.loads((a / "calibration.json").read_text())
    jb = json.loads((tmp_path / "b" / "calibration.json").read_text())
    assert ja["cameras"]["cell"]["X_BC"] == jb["cameras"]["cell"]["X_BC"]
    assert ja["cameras"]["wrist"]["X_EC"] == jb["cameras"]["wrist"]["X_EC"]


def test_command_line_rig_bad_camera_is_one_line(rig, tmp_path, capsys):
    out, truth = rig
    assert _cli("calibrate", "--robot", out / "robot_poses.tum", "--target", truth["target"],
                "--camera", f"wrist:{tmp_path / 'missing'}", "--out", tmp_path / "o") == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--camera wrist:" in err and "not found" in err


def test_rig_from_a_bag_with_an_image_topic_per_camera(rig, tmp_path):
    """The same rig recorded as a bag (tf, one image topic and CameraInfo per camera, the camera
    clock 35 ms late), through the command line (--bag, NAME:TOPIC cameras): images pair with
    the robot in time; each camera within σ."""
    import json
    from handeye_drake.recorded.example_rig import write_rig_bag
    out, truth = rig
    bag = tmp_path / "rig.mcap"
    topics = write_rig_bag(out, bag, "mcap", names=["wrist", "cell"])
    assert _cli("calibrate", "--bag", bag, "--target", truth["target"], "--refine-intrinsics",
                "none", "--camera", f"wrist:{topics['wrist']}:hand",
                "--camera", f"cell:{topics['cell']}:cell", "--out", tmp_path / "o") == 0
    j = json.loads((tmp_path / "o" / "calibration.json").read_text())
    assert j["rig"]["verdict"]["status"] in ("OK", "WARN")
    for name in ("wrist", "cell"):
        c = j["cameras"][name]
        key = "X_EC" if c["mount"] == "hand" else "X_BC"
        assert _nees(np.asarray(c[key]), np.asarray(c["covariance"]),
                     np.asarray(truth["cameras"][name][key])) < BOUND, name
    assert abs(j["cameras"]["wrist"]["alone"]["time_offset_s"] - 0.035) < 0.01


@pytest.fixture(scope="module")
def hand_board_rig(tmp_path_factory):
    out = tmp_path_factory.mktemp("rig_hand_board")
    truth = generate_example_rig(out, seed=3, num_images=10, board_mount="hand", supersample=2)
    return out, truth


def test_two_cell_cameras_sharing_a_board_on_the_flange_within_sigma(hand_board_rig, tmp_path):
    """Two cameras fixed in the cell watch one board on the flange (eye-to-hand, both can
    calibrate alone; the arm hides the board in some images): jointly, each within σ, and the
    transform between them."""
    out, truth = hand_board_rig
    cams = _cams(out, truth, ["cell_a", "cell_b"])
    r = calibrate_rig(cams, out / "robot_poses.tum", truth["target"], board_mount="hand",
                      options=OPTIONS)
    assert r.verdict.status in ("OK", "WARN"), r.lines()
    _check_within_sigma(r, truth)
    assert all(c.alone is not None for c in r.cameras.values())
    X, C = r.relative[("cell_a", "cell_b")]
    assert _nees(X, C, relative_truth(truth, "cell_a", "cell_b")) < BOUND
    assert np.linalg.norm(tangent(r.X_board, np.asarray(truth["X_ET"]))[3:]) < 0.002


def _scaled_spec(spec: str, factor: float) -> str:
    kind, grid, square, marker, *rest = spec.split(":")
    return ":".join([kind, grid, f"{float(square) * factor:.9g}", f"{float(marker) * factor:.9g}",
                     *rest])


def test_a_board_printed_half_a_percent_large_is_answered_with_both_readings(rig):
    """The print is 0.5 % larger than declared (or — the same pixels — the robot's translations
    0.5 % long): the joint fit's board scale finds the factor, the rig WARNs naming it, and every
    answer (each camera, the board, the camera-to-camera transform) covers both readings."""
    out, truth = rig
    r = calibrate_rig(_cams(out, truth, ["wrist", "wrist2", "cell"]), out / "robot_poses.tum",
                      _scaled_spec(truth["target"], 1 / 1.005), options=OPTIONS)
    assert r.verdict.status == "WARN", r.lines()
    rig_scale = [w for w in r.verdict.reasons if w.code == "target_scale"
                 and "jointly" in w.message]
    assert rig_scale and "1.005" in rig_scale[0].message, r.lines()
    s = r.board_scale
    assert s["significant"] and abs(s["factor"] - 1.005) < max(4 * s["std"], 0.001), s
    _check_within_sigma(r, truth)
    for name, c in r.cameras.items():
        # Both readings are held and the answer lies between them (their midpoint).
        p, q = c.readings["print"][:3, 3], c.readings["robot"][:3, 3]
        assert np.allclose(c.X[:3, 3], 0.5 * (p + q)) and np.allclose(q, p / s["factor"]), name
        assert "readings" in r.to_json()["cameras"][name]
    X, C = r.relative[("wrist", "wrist2")]
    assert _nees(X, C, relative_truth(truth, "wrist", "wrist2")) < BOUND


def test_the_board_scale_is_not_named_when_the_print_is_right(rig):
    out, truth = rig
    r = calibrate_rig(_cams(out, truth, ["wrist", "wrist2", "cell"]), out / "robot_poses.tum",
                      truth["target"], options=OPTIONS)
    assert not r.board_scale["significant"] and abs(r.board_scale["factor"] - 1) < 0.002
    assert not any(w.code in ("target_scale", "target_size") for w in r.verdict.reasons)

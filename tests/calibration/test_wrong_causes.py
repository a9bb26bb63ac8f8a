"""Issue 37, family 4: refusals name the right cause, each recognised by the reading that
explains the data best — images paired with the poses shifted (not a clock offset), intrinsics
of another image resolution (not an ambiguous pose or unsynchronized streams), one pose file in
millimetres (that file's scale, not both), a wrong distortion (the intrinsics, not a moved
target). Each in generated variants."""

import numpy as np
import pytest

from handeye_drake.calibration import CalibrationOptions, calibrate, solve
from handeye_drake.calibration.pairing import pairing_shift, resolution_hint
from handeye_drake.recorded.formats import read_poses
from handeye_drake.vision.camera_model import CameraIntrinsics
from tests.corner_synth import TRUTH, corner_streams


def _outcome(streams, **options):
    """('refused', message) or (status, first reason code and message)."""
    try:
        r = solve(streams, CalibrationOptions(**options))
    except ValueError as e:
        return "refused", str(e)
    first = r.verdict.reasons[0] if r.verdict.reasons else None
    return r.verdict.status, (first.code + ": " + first.message) if first else ""


@pytest.mark.parametrize("shift, seed", [(1, 0), (-1, 1), (2, 2), (-3, 3)])
def test_images_paired_with_poses_shifted_are_named_not_a_clock_offset(shift, seed):
    streams, _ = corner_streams(TRUTH, n=12, seed=seed, shift_pairs=shift)
    status, message = _outcome(streams)
    assert status in ("refused", "FAIL"), (status, message)
    n = "one" if abs(shift) == 1 else str(abs(shift))
    assert f"shifted by {n}" in message, message
    assert f"robot pose i {'−' if shift > 0 else '+'} {abs(shift)}" in message, message
    assert "--time-offset" not in message.split("(as paired")[0]


def test_image_files_paired_shifted_are_named(tmp_path, capsys):
    """The rendered example with its first image missing: image i pairs with robot pose i + 1."""
    import shutil
    from handeye_drake.apps.cli import main
    from tests.apps.test_calibrate import IMAGES
    folder = tmp_path / "images"
    folder.mkdir()
    for k in range(1, 14):
        shutil.copy(IMAGES / f"img_{k:03d}.png", folder)
    lines = (IMAGES / "robot_poses.tum").read_text().splitlines()
    poses = [s for s in lines if not s.startswith("#")]
    (tmp_path / "robot.tum").write_text("\n".join(poses[:13]) + "\n")
    code = main(["calibrate", "--images", str(folder), "--robot", str(tmp_path / "robot.tum"),
                 "--target", "charuco:7x5:0.04:0.03:DICT_5X5_100", "--intrinsics",
                 str(IMAGES / "intrinsics.yaml"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and "images are paired with the robot poses shifted by one" in err, err
    assert "one image missing there" in err


def test_right_pairing_is_not_read_as_a_shift():
    for seed in range(5):
        streams, _ = corner_streams(TRUTH, n=12, seed=seed)
        assert pairing_shift(streams.robot.poses, streams.camera.poses) is None


@pytest.mark.parametrize("factor", [0.5, 1.5])
def test_intrinsics_of_another_resolution_are_named(factor):
    """The given fx, fy, cx, cy of a camera calibrated at another resolution: whatever follows
    (no detection, motions that disagree, a refined set far from them), the cause named is the
    resolution, with the factor to scale them by."""
    given = TRUTH.copy()
    given[:4] *= factor
    streams, _ = corner_streams(given, n=10, seed=int(factor * 10))
    status, message = _outcome(streams)
    assert status != "OK", message
    assert "another image resolution" in message, message
    assert f"by {1 / factor:.3g}"[:6] in message or f"{1 / factor:.4g}" in message, message


def test_intrinsics_of_twice_the_resolution_are_named_when_no_pose_is_detected(tmp_path,
                                                                              capsys):
    """The rendered example images with the intrinsics of a 1280×960 calibration: every
    detection is refused as ambiguous; the cause named is the resolution."""
    from handeye_drake.apps.cli import main
    from tests.apps.test_calibrate import IMAGES
    code = main(["calibrate", "--images", str(IMAGES), "--robot", str(IMAGES / "robot_poses.tum"),
                 "--target", "charuco:7x5:0.04:0.03:DICT_5X5_100", "--intrinsics",
                 "1224,1223,637.7,486.9", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and "--intrinsics: intrinsics of another image resolution" in err, err
    assert "1280×960" in err and "0.5" in err


def test_principal_points_of_this_resolution_are_not_read_as_another():
    for cx, cy in ((320, 240), (300, 260), (352, 220), (319.5, 239.5)):
        K = CameraIntrinsics(alpha_u=600, alpha_v=600, u0=cx, v0=cy, width=640, height=480)
        assert resolution_hint(K) == ""
    K = CameraIntrinsics(alpha_u=1200, alpha_v=1200, u0=639.5, v0=479.5, width=640, height=480)
    assert "1280×960" in resolution_hint(K)


def _tum(path, stream, scale=1.0):
    from handeye_drake.estimation.se3 import quat_wxyz
    lines = []
    for t, X in zip(stream.timestamps, stream.poses):
        w, x, y, z = quat_wxyz(X[:3, :3])
        p = scale * X[:3, 3]
        lines.append(f"{t:.6f} {p[0]:.6f} {p[1]:.6f} {p[2]:.6f} {x:.9f} {y:.9f} {z:.9f} {w:.9f}")
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("which", ["robot", "camera", "both"])
def test_one_file_in_millimetres_gets_its_own_scale(tmp_path, which):
    from tests.apps.test_calibrate import CAMERA, ROBOT
    streams = {"robot": read_poses(ROBOT, "robot"), "camera": read_poses(CAMERA, "camera")}
    files = {}
    for name, s in streams.items():
        files[name] = tmp_path / f"{name}.tum"
        _tum(files[name], s, 1000.0 if which in (name, "both") else 1.0)
    with pytest.raises(ValueError) as e:
        calibrate(files["robot"], files["camera"])
    text = str(e.value)
    if which == "both":
        assert "both files" in text and "--translation-scale 0.001" in text
    else:
        assert f"--{which}-translation-scale 0.001" in text and "this file only" in text
        assert str(files[which]) in text
        # The scale named is the one that reads the data.
        r = calibrate(files["robot"], files["camera"],
                      **{f"{which}_translation_scale": 0.001})
        assert r.verdict.status == "OK"


@pytest.mark.parametrize("model, seed", [("none", 0), ("focal", 1), ("auto", 3)])
def test_a_wrong_distortion_is_named_not_a_moved_target(model, seed):
    given = TRUTH.copy()
    given[4:6] = -given[4:6]        # distortion of the wrong sign
    streams, _ = corner_streams(given, n=10, seed=seed)
    status, message = _outcome(streams, refine_intrinsics=model)
    assert status in ("WARN", "FAIL"), message
    assert message.startswith("intrinsics:") and "k1" in message, message
    assert "moved" not in message

"""``--fix``: a held value is a hypothesis like any other, tested against what the data say
about that component (the fit with it free): > 5σ off FAILs naming the value and the data's
value ± σ; a component the data determine gets a note; a held component has σ exactly 0 (the
robot-accuracy term included) and the observability line never advises fixing it again."""

import math

import numpy as np
import pytest

from handeye_drake.calibration import calibrate_streams
from handeye_drake.calibration.report import table
from handeye_drake.apps.cli import main
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp, rpy
from handeye_drake.recorded.formats import pose_stream
from tests.apps.test_calibrate import CAMERA, ROBOT, _scara_streams

ACCURACY = (0.03, 3e-4)  # the command's default --robot-accuracy


def _streams(mode, seed, n=40):
    """A recording with well spread rotations; truth X_H (X_EC or X_BC)."""
    rng = np.random.default_rng(seed)
    if mode == "eye_in_hand":
        X_H = make_transform(rotation_exp(rng.normal(size=3) * 0.8),
                             rng.uniform(-0.08, 0.08, 3) + [0, 0, 0.06])
        X_F = make_transform(rotation_exp([math.pi, 0, 0]), [0.5, 0.05, 0.0])
    else:
        X_H = make_transform(rotation_exp([2.5, 0.3, -0.4] + 0.2 * rng.normal(size=3)),
                             [0.9, -0.2, 0.6] + 0.1 * rng.normal(size=3))
        X_F = make_transform(rotation_exp(0.3 * rng.normal(size=3)), [0.02, 0.01, 0.08])
    X_BE = [make_transform(rotation_exp(0.5 * rng.normal(size=3)),
                           [0.5, 0.0, 0.4] + 0.1 * rng.normal(size=3)) for _ in range(n)]
    noise = [make_transform(rotation_exp(np.radians(0.05) * rng.normal(size=3)),
                            0.0005 * rng.normal(size=3)) for _ in range(n)]
    if mode == "eye_in_hand":
        X_CT = [N @ inverse(X @ X_H) @ X_F for N, X in zip(noise, X_BE)]
    else:
        X_CT = [N @ inverse(X_H) @ X @ X_F for N, X in zip(noise, X_BE)]
    return pose_stream(X_BE, None, "robot"), pose_stream(X_CT, None, "camera"), X_H


def _truth(X_H, c):
    if c.startswith("t"):
        return float(X_H["xyz".index(c[1]), 3])
    return float(rpy(X_H[:3, :3])[("roll", "pitch", "yaw").index(c)])


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
@pytest.mark.parametrize("c", ["tx", "ty", "tz", "roll", "pitch", "yaw"])
def test_a_wrong_value_held_on_a_determined_component_fails_naming_it(mode, c):
    seed = 3 * ("xyzrpy".index(c[-1] if c.startswith("t") else c[0])) + (mode == "eye_to_hand")
    robot, camera, X_H = _streams(mode, seed)
    truth = _truth(X_H, c)
    delta = 0.005 if c.startswith("t") else math.radians(1.0)
    sign = 1 if seed % 2 else -1
    r = calibrate_streams(robot, camera, mode=mode, fixed={c: truth + sign * delta},
                          robot_accuracy=ACCURACY)
    assert r.verdict.status == "FAIL"
    reason = next(x for x in r.verdict.reasons if x.code == "fixed_value")
    assert f"with {c} free the data give {c} =" in reason.message and "--fix " + c in \
        reason.message
    t = r.fixed_tests[0]
    assert t.sigmas > 5 and abs(t.data_value - truth) < 4 * t.data_std
    # The right value: no fixed_value reason, a note that the data determine it anyway.
    r = calibrate_streams(robot, camera, mode=mode, fixed={c: truth}, robot_accuracy=ACCURACY)
    assert r.verdict.status != "FAIL"
    assert not any(x.code == "fixed_value" for x in r.verdict.reasons)
    assert any(f"the data determine {c} themselves" in w for w in r.warnings)
    i = ("tx", "ty", "tz").index(c) if c.startswith("t") else None
    if i is not None:
        assert r.translation_std[i] == 0.0


def test_the_shipped_recording_with_a_wrong_fix_fails_and_exports_nothing(tmp_path, capsys):
    out = tmp_path / "o"
    code = main(["calibrate", "--robot", ROBOT, "--camera", CAMERA, "--fix", "tx=0.055",
                 "--export", "urdf", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 1 and "FAIL: the value held does not fit the data" in text
    assert "--fix tx=0.055" in text and ("tx = 44.9" in text or "tx = 45.0" in text)
    # The held value is the cause: no target-scale warning (pose files have no target) that
    # the distorted fit would otherwise give.
    assert "FAIL (1 reason)" in text and "translations are" not in text
    assert not (out / "handeye.urdf").exists()
    code = main(["calibrate", "--robot", ROBOT, "--camera", CAMERA, "--fix", "tz_mm=68",
                 "--out", str(tmp_path / "right")])
    text = capsys.readouterr().out
    assert code == 0 and "note: --fix tz=0.068: the data determine tz themselves" in text
    tline = next(line for line in text.splitlines() if line.strip().startswith("translation (mm)"))
    assert tline.rstrip().endswith("0.000]")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_scara_with_tz_held_has_zero_sigma_on_it_and_no_advice_to_fix_it(seed):
    robot, camera, X_EC = _scara_streams(seed)
    for tz in (float(X_EC[2, 3]), float(X_EC[2, 3]) + 0.01):
        r = calibrate_streams(robot, camera, fixed={"tz": tz}, robot_accuracy=ACCURACY)
        assert r.translation_std[2] == 0.0
        text = table(r)
        assert "fix tz" not in text and "--fix tz=VALUE" not in text
        assert r.observability.translation_std[2] == 0.0
        # The data cannot say anything about tz here: no test, no note, no FAIL from it.
        assert r.fixed_tests[0].data_value is None
        assert r.verdict.status in ("OK", "WARN")


# --------------------------------------------- a new user's finding: identical timestamps
@pytest.mark.parametrize("seed", range(4))
def test_streams_with_identical_timestamps_keep_every_sample_with_offset_zero(seed):
    """Two files stamped 0..N alike are paired sample by sample: offset 0, no sample lost at
    the ends (an estimated ±0.2 ms used to push one outside the robot's span)."""
    robot, camera, X_H = _streams("eye_in_hand", seed, n=30)
    t = np.arange(30, dtype=float)
    r = calibrate_streams(pose_stream(robot.poses, t, "robot"),
                          pose_stream(camera.poses, t, "camera"), robot_accuracy=ACCURACY)
    assert r.aligned.time_offset == 0.0 and len(r.aligned.X_BE) == 30
    assert "same timestamps" in r.time_offset_mode
    assert r.verdict.status != "FAIL", r.verdict.reasons
    # A fraction of a millisecond off still keeps the end samples (taken at the span's end).
    from handeye_drake.calibration.align import align_streams
    a = align_streams(pose_stream(robot.poses, t, "robot"),
                      pose_stream(camera.poses, t + 2e-4 * (1 if seed % 2 else -1), "camera"))
    assert len(a.X_BE) == 30


def test_images_with_a_wrong_fix_fail_and_a_right_one_passes(tmp_path, capsys):
    from tests.apps.test_calibrate import IMAGES
    args = ["calibrate", "--images", str(IMAGES), "--robot", str(IMAGES / "robot_poses.tum"),
            "--target", "charuco:7x5:0.04:0.03:DICT_5X5_100", "--intrinsics",
            str(IMAGES / "intrinsics.yaml")]
    assert main(args + ["--fix", "roll_deg=-2", "--out", str(tmp_path / "wrong")]) == 1
    assert "with roll free the data give roll = -2.9" in capsys.readouterr().out
    assert main(args + ["--fix", "roll_deg=-3", "--out", str(tmp_path / "right")]) == 0
    assert "the data determine roll themselves" in capsys.readouterr().out


def test_self_calibrated_intrinsics_with_a_fix_say_their_uncertainty_once(tmp_path, capsys):
    # held components are fitted at pose level, where the camera poses' systematic uncertainty
    # is a verdict reason: the notes do not repeat it
    from tests.apps.test_calibrate import IMAGES
    main(["calibrate", "--images", str(IMAGES), "--robot", str(IMAGES / "robot_poses.tum"),
          "--target", "charuco:7x5:0.04:0.03:DICT_5X5_100", "--fix", "tz=0.0639",
          "--out", str(tmp_path / "out")])
    out = capsys.readouterr().out
    assert out.count("the camera poses' systematic uncertainty (intrinsics calibrated from the "
                     "same images) is included in the σ") == 1, out
    assert "WARN: the camera poses' systematic uncertainty" in out

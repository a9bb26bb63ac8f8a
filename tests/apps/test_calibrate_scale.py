"""A scale on the camera's translations (a detector given the wrong square size, a target
printed at another scale) is tested by the maximum-likelihood fit: a factor ≠ 1 by more than 5σ
FAILs naming it (nothing exported), whatever the quick fits' medians say; the right scale is
never blamed."""

import re

import numpy as np
import pytest

from handeye_drake.calibration import calibrate_streams
from handeye_drake.apps.cli import main
from handeye_drake.estimation.consistency import with_scaled_translations
from handeye_drake.recorded.formats import pose_stream
from tests.apps.test_calibrate import CAMERA, ROBOT, _rewrite
from tests.apps.test_calibrate_fixed import _streams

ACCURACY = (0.03, 3e-4)


def _scaled(stream, factor):
    return pose_stream(with_scaled_translations(stream.poses, factor), stream.timestamps,
                       "camera")


def _outcome(robot, camera, mode):
    """("FAIL"/"WARN"/"OK", the camera_scale reason or the error text)."""
    try:
        r = calibrate_streams(robot, camera, mode=mode, robot_accuracy=ACCURACY)
    except ValueError as e:
        return "ERROR", str(e)
    reason = next((x for x in r.verdict.reasons if x.code == "camera_scale"), None)
    return r.verdict.status, reason.message if reason else "", r


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
@pytest.mark.parametrize("seed", [0, 1])
def test_a_scaled_camera_stream_fails_naming_the_factor(mode, seed):
    rng = np.random.default_rng(100 + seed)
    robot, camera, _ = _streams(mode, seed, n=40)
    factors = [rng.uniform(0.9, 0.97), rng.uniform(0.97, 0.99), rng.uniform(1.01, 1.03),
               rng.uniform(1.03, 1.1)]
    for factor in factors:
        out = _outcome(robot, _scaled(camera, factor), mode)
        text = out[1]
        m = re.search(r"camera's translations are ([0-9.]+)× their true size", text)
        assert out[0] in ("FAIL", "ERROR") and m, (factor, out[:2])
        assert abs(float(m.group(1)) / factor - 1) < 0.01, (factor, text)
    # The right scale: no scale reason, whatever the seed.
    status, text, r = _outcome(robot, camera, mode)
    assert status != "FAIL" and text == "", text
    assert r.scale_test is not None and r.scale_test["sigmas"] < 5


def test_the_shipped_recording_with_a_2_percent_scale_fails_and_exports_nothing(tmp_path,
                                                                                  capsys):
    camera = _rewrite(CAMERA, tmp_path / "c.tum", scale=0.98)
    out = tmp_path / "o"
    code = main(["calibrate", "--robot", ROBOT, "--camera", camera, "--export", "urdf",
                 "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 1 and re.search(r"FAIL: the camera's translations are 0\.9[78]\d*× their "
                                   r"true size", text)
    assert re.search(r"--camera-translation-scale 1\.02\d* for pose files", text)
    assert not (out / "handeye.urdf").exists()


@pytest.mark.parametrize("seed", [0, 1])
def test_a_scaled_robot_stream_fails_and_the_message_names_that_reading_too(seed):
    """A robot stream's translations off by k look exactly like the camera's off by 1/k: the
    FAIL names both readings (the data cannot tell them apart), never an OK."""
    rng = np.random.default_rng(200 + seed)
    robot, camera, _ = _streams("eye_in_hand", seed, n=40)
    for k in (rng.uniform(0.93, 0.98), rng.uniform(1.02, 1.07)):
        scaled = pose_stream(with_scaled_translations(robot.poses, k), None, "robot")
        out = _outcome(scaled, camera, "eye_in_hand")
        assert out[0] in ("FAIL", "ERROR"), (k, out[:2])
        if out[0] == "FAIL":
            m = re.search(r"robot's translations are ([0-9.]+)× theirs", out[1])
            assert m and abs(float(m.group(1)) / k - 1) < 0.01, (k, out[1])

"""Image folders paired with the robot in time (``recorded.image_stamps``,
``inputs.choose_pairing``) on a rendered recording made as real cells make them
(``example_rig.generate_stamped_rig``, rendered once per module): the arm moving without
stopping, its pose stream at 100 Hz with epoch stamps and a pose error repeating with the joint
angles, two hand cameras free-running at 0.35 s and 0.5 s with frames dropped, clocks +30 ms and
−20 ms off the robot's, one named by ``frame_<ns>.png``, the other by a ``timestamps.txt``."""

import json

import numpy as np
import pytest
from scipy.stats import chi2

from handeye_drake.calibration.api import CalibrationOptions
from handeye_drake.calibration.rig import RigCamera, calibrate_rig
from handeye_drake.estimation.rig_bundle import tangent
from handeye_drake.recorded.example_rig import DEFAULT_RIG, generate_stamped_rig, relative_truth

BOUND = float(chi2.ppf(0.999, 6))
OPTIONS = CalibrationOptions(refine_intrinsics="none")
#: The estimated clock offsets' allowance (s): a tenth of the offsets, 1/115 of the fastest
#: camera period (the offset search's own precision is a fraction of a millisecond).
OFFSET_TOLERANCE = 0.003


@pytest.fixture(scope="module")
def stamped(tmp_path_factory):
    out = tmp_path_factory.mktemp("stamped_rig")
    truth = generate_stamped_rig(
        out, seed=3, num_poses=8, cameras={"wrist": DEFAULT_RIG["wrist"],
                                           "wrist2": DEFAULT_RIG["wrist2"]},
        periods={"wrist": 0.35, "wrist2": 0.5}, offsets={"wrist": 0.03, "wrist2": -0.02},
        styles={"wrist": "nanoseconds", "wrist2": "file"}, drop=0.15,
        robot_error=(0.02, 0.0002), supersample=2)
    return out, truth


def _nees(X, C, X_true):
    e = tangent(X, X_true)
    return float(e @ np.linalg.solve(C, e))


def test_two_cameras_at_different_rates_paired_in_time_within_sigma(stamped):
    out, truth = stamped
    cams = truth["cameras"]
    # The recording is what the test claims: rates differ, frames dropped, a denser robot.
    n = {k: len(c["files"]) for k, c in cams.items()}
    span = truth["knot_times"][-1] - truth["knot_times"][0]
    assert n["wrist"] != n["wrist2"] and truth["robot_samples"] > 10 * max(n.values())
    for k, c in cams.items():
        assert len(c["files"]) < span / c["period_s"]   # some dropped
    r = calibrate_rig([RigCamera(k, out / k, "hand", str(out / k / "intrinsics.yaml"))
                       for k in cams], out / "robot_poses.tum", truth["target"],
                      options=OPTIONS)
    assert r.verdict.status in ("OK", "WARN"), r.lines()
    for k, c in r.cameras.items():
        assert "paired in time" in c.timing(), k
        assert c.streams.inputs["images"]["paired_by"] == "time"
        assert _nees(c.X, c.covariance, np.asarray(cams[k]["X_EC"])) < BOUND, k
        assert np.max(c.sigma()[1]) < 0.001, k
        # Each camera's own clock offset, estimated on its own.
        assert abs(c.alone.aligned.time_offset - cams[k]["time_offset_s"]) < OFFSET_TOLERANCE
        assert len(c.alone.aligned) == c.detected
    (a, b), (X, C) = next(iter(r.relative.items()))
    assert _nees(X, C, relative_truth(truth, a, b)) < BOUND
    doc = r.to_json()
    assert "in time" in doc["cameras"]["wrist2"]["pairing"]
    assert "timestamps.txt" in doc["cameras"]["wrist2"]["pairing"]


def test_single_camera_images_pair_in_time_and_refuse_images_in_a_robot_gap(stamped, tmp_path,
                                                                              capsys):
    """``calibrate --images`` pairs in time too (auto); images where the robot stream has a gap
    of 0.6 s (its samples missing) are dropped, not paired with a pose 0.3 s away; a given
    offset is used as given."""
    from handeye_drake.apps.cli import main
    out, truth = stamped
    cam = truth["cameras"]["wrist2"]
    lines = (out / "robot_poses.tum").read_text().splitlines()
    t_gap = cam["true_times"][len(cam["true_times"]) // 2]
    kept = [x for x in lines if x.startswith("#") or abs(float(x.split()[0]) - t_gap) > 0.3]
    (tmp_path / "robot.tum").write_text("\n".join(kept) + "\n")
    args = ["calibrate", "--images", str(out / "wrist2"), "--robot", str(tmp_path / "robot.tum"),
            "--target", truth["target"], "--intrinsics", str(out / "wrist2" / "intrinsics.yaml"),
            "--refine-intrinsics", "none", "--out", str(tmp_path / "o")]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "images paired with the robot poses in time" in printed
    assert "timestamps.txt" in printed and "stamp (s)" in printed
    doc = json.loads((tmp_path / "o" / "calibration.json").read_text())
    assert doc["verdict"]["status"] in ("OK", "WARN"), doc["verdict"]
    X = np.array(doc["X_EC"]["matrix"])
    C = np.array(doc["X_EC"]["std"]["covariance"])
    assert _nees(X, C, np.asarray(cam["X_EC"])) < BOUND
    assert abs(doc["time_offset"]["value_s"] - cam["time_offset_s"]) < OFFSET_TOLERANCE
    gap = doc["alignment"]["dropped_in_robot_gaps"]
    assert gap["count"] == 1 and f"dropped 1 in robot gaps" in printed, gap

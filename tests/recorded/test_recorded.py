"""Recorded data (``handeye_drake.recorded``): readers, alignment, time offset, pair selection and
outliers, the shipped example, the filter long run."""

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest

import handeye_drake
from handeye_drake import rotation_error_deg
from handeye_drake.estimation.se3 import (
    inverse,
    make_transform,
    rotation_exp,
)
from handeye_drake.calibration.align import align_streams, estimate_time_offset
from handeye_drake.estimation.interpolation import interpolate_poses
from handeye_drake.estimation.selection import form_pairs, robust_hand_eye
from handeye_drake.recorded import parse_poses, pose_stream, read_poses
from handeye_drake.recorded.example import generate_example
from handeye_drake.estimation.selection import InconsistentMotions

DATA = Path(handeye_drake.__file__).parent / "data"
ROOT = Path(__file__).resolve().parents[2]


def Rz(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def Rx(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


# ------------------------------------------------------------------------------------ formats
def test_tum_snippet():
    text = ("# timestamp tx ty tz qx qy qz qw\n"
            "0.0 1 2 3 0 0 0 1\n"
            "\n"
            "0.5, 1.5, 2.0, 3.0, 0, 0, 0.70710678, 0.70710678   # 90° about z\n")
    s = parse_poses(text, "tum", "robot", "snippet.tum")
    assert s.lines == (2, 4) and s.where(1) == "snippet.tum:4"
    np.testing.assert_array_equal(s.timestamps, [0.0, 0.5])
    np.testing.assert_allclose(s.poses[0], make_transform(np.eye(3), [1, 2, 3]))
    np.testing.assert_allclose(s.poses[1], make_transform(Rz(90), [1.5, 2, 3]), atol=1e-8)


def test_tum_camera_in_target_is_inverted():
    text = "0.0 0.1 0.2 0.5 0 0 0.38268343 0.92387953\n"  # 45° about z
    X_TC = make_transform(Rz(45), [0.1, 0.2, 0.5])
    s = parse_poses(text, "tum", "camera", "c.tum", camera_in_target=True)
    np.testing.assert_allclose(s.poses[0], inverse(X_TC), atol=1e-8)
    np.testing.assert_allclose(s.poses[0] @ X_TC, np.eye(4), atol=1e-8)


def test_csv_matrix_snippets():
    rows = "1 0 0 0.1  0 0 -1 0.2  0 1 0 0.3  0 0 0 1"  # 90° about x
    s = parse_poses(f"# 4x4 row-major\n{rows}\n{rows.replace('0.1', '0.4')}\n", "csv-matrix",
                    "robot", "m.csv")
    assert s.timestamps is None and s.lines == (2, 3)
    np.testing.assert_allclose(s.poses[0], make_transform(Rx(90), [0.1, 0.2, 0.3]), atol=1e-15)
    assert s.poses[1, 0, 3] == 0.4
    s = parse_poses(f"2.5,{rows.replace(' ', ',').replace(',,', ',')}\n", "csv-matrix", "robot",
                    "t.csv")
    np.testing.assert_array_equal(s.timestamps, [2.5])
    np.testing.assert_allclose(s.poses[0], make_transform(Rx(90), [0.1, 0.2, 0.3]), atol=1e-15)


YAML_SNIPPET = """%YAML:1.0
---
timestamps: [ 0., 0.5 ]
R_gripper2base:
   - !!opencv-matrix
      rows: 3
      cols: 3
      dt: d
      data: [ 1., 0., 0., 0., 0., -1., 0., 1., 0. ]
   - !!opencv-matrix
      rows: 3
      cols: 1
      dt: d
      data: [ 0., 0., 1.5707963267948966 ]
t_gripper2base:
   - !!opencv-matrix
      rows: 3
      cols: 1
      dt: d
      data: [ 0.1, 0.2,
          0.3 ]
   - !!opencv-matrix
      rows: 3
      cols: 1
      dt: d
      data: [ 0.4, 0.5, 0.6 ]
camera_poses:
   - !!opencv-matrix
      rows: 4
      cols: 4
      dt: f
      data: [ 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0.5, 0., 0., 0., 1. ]
   - !!opencv-matrix
      rows: 4
      cols: 4
      dt: d
      data: [ 0., -1., 0., 0., 1., 0., 0., 0., 0., 0., 1., 0.5, 0., 0., 0., 1. ]
"""


def test_opencv_yaml_snippet_agrees_with_cv2(tmp_path):
    cv2 = pytest.importorskip("cv2")  # the test extra; the reader itself does not use it
    path = tmp_path / "poses.yaml"
    path.write_text(YAML_SNIPPET)
    robot = read_poses(path, "robot")
    camera = read_poses(path, "camera")
    np.testing.assert_allclose(robot.poses[0], make_transform(Rx(90), [0.1, 0.2, 0.3]),
                               atol=1e-15)
    np.testing.assert_allclose(robot.poses[1], make_transform(Rz(90), [0.4, 0.5, 0.6]),
                               atol=1e-15)
    np.testing.assert_array_equal(robot.timestamps, [0.0, 0.5])
    np.testing.assert_array_equal(camera.timestamps, [0.0, 0.5])
    assert robot.lines == (5, 10) and camera.lines == (28, 33)
    # OpenCV reads the same file to the same numbers.
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    node = fs.getNode("camera_poses")
    for k in range(2):
        np.testing.assert_allclose(camera.poses[k], node.at(k).mat(), atol=1e-15)
    R_node, t_node = fs.getNode("R_gripper2base"), fs.getNode("t_gripper2base")
    np.testing.assert_allclose(robot.poses[0, :3, :3], R_node.at(0).mat())
    np.testing.assert_allclose(robot.poses[1, :3, :3], cv2.Rodrigues(R_node.at(1).mat())[0],
                               atol=1e-15)
    np.testing.assert_allclose(robot.poses[0, :3, 3], t_node.at(0).mat().ravel())
    fs.release()


def test_opencv_yaml_written_by_cv2(tmp_path):
    """cv2.FileStorage's own output (target2cam keys, Rodrigues vectors, timestamps matrix)."""
    cv2 = pytest.importorskip("cv2")  # the test extra; the reader itself does not use it
    rng = np.random.default_rng(3)
    X_CT = [make_transform(rotation_exp(rng.normal(size=3)), rng.normal(size=3)) for _ in range(3)]
    path = str(tmp_path / "cv.yaml")
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
    fs.write("camera_timestamps", np.array([[0.1], [0.2], [0.35]]))
    for key, values in (("R_target2cam", [cv2.Rodrigues(X[:3, :3])[0] for X in X_CT]),
                        ("t_target2cam", [X[:3, 3:4] for X in X_CT])):
        fs.startWriteStruct(key, cv2.FileNode_SEQ)
        for v in values:
            fs.write("", v)
        fs.endWriteStruct()
    fs.release()
    s = read_poses(path, "camera")
    np.testing.assert_allclose(s.poses, np.array(X_CT), atol=1e-12)
    np.testing.assert_array_equal(s.timestamps, [0.1, 0.2, 0.35])
    # The cam2target keys hold X_TC: read inverted, and they require the flag to agree.
    text = Path(path).read_text().replace("target2cam", "cam2target")
    s = parse_poses(text, "opencv-yaml", "camera", "x.yaml", camera_in_target=True)
    np.testing.assert_allclose(s.poses, np.array([inverse(X) for X in X_CT]), atol=1e-12)


# ---------------------------------------------------------------------------------- alignment
def test_interpolation_known_values():
    X0 = make_transform(np.eye(3), [1.0, 2.0, 3.0])
    X1 = make_transform(Rz(90), [3.0, 2.0, 1.0])
    X = interpolate_poses([0.0, 1.0], [X0, X1], [0.0, 0.25, 1.0])
    np.testing.assert_allclose(X[0], X0, atol=1e-15)
    np.testing.assert_allclose(X[1], make_transform(Rz(22.5), [1.5, 2.0, 2.5]), atol=1e-15)
    np.testing.assert_allclose(X[2], X1, atol=1e-15)
    with pytest.raises(ValueError, match=r"query_times\[0\] = 1.5 is outside the interpolated "
                                         r"time span \[0.0, 1.0\]"):
        interpolate_poses([0.0, 1.0], [X0, X1], [1.5])


def test_align_streams_interpolates_and_reports_dropped_samples():
    X0 = make_transform(np.eye(3), [1.0, 2.0, 3.0])
    robot = pose_stream([X0, make_transform(Rz(90), [3.0, 2.0, 1.0]), X0, X0],
                        [0.0, 1.0, 2.0, 10.0], "r.tum", [3, 4, 5, 6])
    camera = pose_stream([np.eye(4)] * 6, [0.1, 0.35, 0.6, 1.1, 5.0, 12.0], "c.tum",
                         [10, 11, 12, 13, 14, 15])
    a = align_streams(robot, camera, time_offset=0.1)
    # Robot instants t − 0.1: −0.0 (exact sample), 0.25, 0.5, 1.0; 4.9 lies in the 2 → 10 s gap
    # (> 5 × the median period 1 s), 11.9 after the robot's last sample.
    assert a.camera_lines == (10, 11, 12, 13)
    assert a.dropped_gap == (14,) and a.dropped_outside == (15,)
    np.testing.assert_allclose(a.X_BE[1], make_transform(Rz(22.5), [1.5, 2.0, 2.5]), atol=1e-14)
    np.testing.assert_allclose(a.X_BE[2], make_transform(Rz(45), [2.0, 2.0, 2.0]), atol=1e-14)
    np.testing.assert_allclose(a.X_BE[3], make_transform(Rz(90), [3.0, 2.0, 1.0]), atol=1e-14)


from tests.fixtures import aligned_synthetic, synthetic_streams  # noqa: E402


@pytest.mark.parametrize("offset", [-0.037, 0.0, 0.061])
def test_time_offset_recovered(offset):
    robot, camera, _ = synthetic_streams(offset, seed=int(1000 * abs(offset)))
    est = estimate_time_offset(robot, camera, search_range=0.25)
    assert abs(est.offset - offset) < 0.005, est.offset
    assert est.residual_rms_deg < 0.3  # θ_A − θ_B at the offset: noise only


def test_time_offset_on_shipped_example():
    truth = json.loads((DATA / "example_truth.json").read_text())
    est = estimate_time_offset(read_poses(DATA / "example_robot.tum", "robot"),
                               read_poses(DATA / "example_camera.tum", "camera"))
    assert abs(est.offset - truth["time_offset_s"]) < 0.005


@pytest.mark.parametrize("seed", range(6))
def test_a_range_wide_for_the_recording_still_finds_the_offset(seed):
    # ±R wider than the camera's margin inside the robot's 12 s: the offset once came out of
    # fewer samples (±8 s on the example: off by 4 ms) or none at all (±10 s: refused)
    rng = np.random.default_rng(seed)
    offset, R = float(rng.uniform(-2, 2)), float(rng.uniform(3, 60))
    robot, camera, _ = synthetic_streams(offset, seed=seed)
    est = estimate_time_offset(robot, camera, search_range=R)
    assert abs(est.offset - offset) < 0.005 and est.search_range == R, (offset, R, est.offset)


@pytest.mark.parametrize("R", [8.0, 10.0, 30.0])
def test_a_wide_range_on_the_shipped_example_finds_its_offset(R):
    truth = json.loads((DATA / "example_truth.json").read_text())
    est = estimate_time_offset(read_poses(DATA / "example_robot.tum", "robot"),
                               read_poses(DATA / "example_camera.tum", "camera"), R)
    assert abs(est.offset - truth["time_offset_s"]) < 0.002, est.offset


def test_time_offset_unobservable_without_rotation_speed_changes():
    """A constant rotation speed makes |θ_A| independent of the offset: refused, explained."""
    t = np.arange(0, 10, 0.02)
    X = [make_transform(Rz(20 * s), [0.1, 0, 0]) for s in t]
    tc = np.arange(1, 9, 1 / 15)
    Y = [make_transform(Rz(20 * s), [0.1, 0, 0]) for s in tc]
    with pytest.raises(ValueError, match="cost is flat .* rotation speed is too uniform"):
        estimate_time_offset(pose_stream(X, t, "r"), pose_stream(Y, tc, "c"))


# ---------------------------------------------------------------------------------- selection
def test_form_pairs():
    X_BE, X_CT, _ = aligned_synthetic(40)
    p = form_pairs(X_BE, X_CT, max_pair_angle_deg=60.0, min_rotation_deg=5.0)
    assert np.array_equal(p.index[:39], np.c_[np.arange(39), np.arange(1, 40)])
    assert p.consecutive[:39].all() and not p.consecutive[39:].any()
    wide = p.index[~p.consecutive]
    assert len(np.unique(wide)) == wide.size  # a matching: no sample twice
    assert np.all(wide[:, 1] >= wide[:, 0] + 2)
    angles = np.degrees(p.angle_B[~p.consecutive])
    assert np.all((angles >= 5.0) & (angles <= 60.0 + 1e-9))
    assert angles[0] == pytest.approx(angles.max())  # greedy: the largest rotation first
    k = 45
    i, j = p.index[k]
    np.testing.assert_allclose(p.A[k], X_CT[i] @ inverse(X_CT[j]), atol=1e-14)
    np.testing.assert_allclose(p.B[k], inverse(X_BE[i]) @ X_BE[j], atol=1e-14)


def test_outlier_rejection_removes_injected_outliers():
    injected = [17, 58, 93]
    X_BE, X_CT, X_EC = aligned_synthetic(outliers=injected)
    fit = robust_hand_eye(X_BE, X_CT, "daniilidis", holdout_fraction=0.0)
    assert fit.outlier_samples.tolist() == injected
    touching = np.isin(fit.pairs.index, injected).any(axis=1)
    # Every pair through an outlier is rejected, and (almost) only those.
    assert not fit.inlier[touching].any()
    assert (~fit.inlier & ~touching).sum() <= 2
    assert rotation_error_deg(X_EC, inverse(fit.X_CE)) < 0.1
    assert np.linalg.norm(inverse(fit.X_CE)[:3, 3] - X_EC[:3, 3]) < 1e-3
    # Without the outlier tests the same data gives a visibly worse solution.
    from handeye_drake import solve_ax_xb
    p = fit.pairs
    X_all = inverse(solve_ax_xb(list(p.A[fit.usable]), list(p.B[fit.usable])))
    assert rotation_error_deg(X_EC, X_all) > 3 * rotation_error_deg(X_EC, inverse(fit.X_CE))


@pytest.mark.parametrize("invert", ["camera", "robot"])
def test_convention_mix_up_is_diagnosed(invert):
    X_BE, X_CT, _ = aligned_synthetic()
    if invert == "camera":
        X_CT = np.array([inverse(X) for X in X_CT])
    else:
        X_BE = np.array([inverse(X) for X in X_BE])
    with pytest.raises(InconsistentMotions, match=r"inconsistent motions: no hand-eye transform "
                       r"fits them .*the camera poses fit when inverted.*toggle "
                       r"--camera-pose-is-camera-in-target — or the robot poses fit when "
                       r"inverted"):
        robust_hand_eye(X_BE, X_CT)


def test_holdout_split():
    X_BE, X_CT, _ = aligned_synthetic()
    fit = robust_hand_eye(X_BE, X_CT, "tsai", holdout_fraction=0.2, seed=5)
    usable_inliers = fit.inlier & fit.usable
    assert fit.held_out.sum() == round(0.2 * usable_inliers.sum())
    assert not (fit.held_out & fit.fit).any()
    assert np.array_equal(fit.held_out | fit.fit, usable_inliers)
    other = robust_hand_eye(X_BE, X_CT, "tsai", holdout_fraction=0.2, seed=6)
    assert not np.array_equal(other.held_out, fit.held_out)


def test_shipped_example_is_what_the_generator_writes(tmp_path):
    truth = generate_example(tmp_path, seed=0)
    for name in ("example_robot.tum", "example_camera.tum", "example_truth.json"):
        assert (tmp_path / name).read_bytes() == (DATA / name).read_bytes(), name
    assert sum((DATA / n).stat().st_size for n in ("example_robot.tum", "example_camera.tum",
                                                   "example_truth.json")) < 200_000
    assert truth["time_offset_s"] == 0.02 and len(truth["outlier_camera_lines"]) == 2


# ------------------------------------------------------------------------- filter long run
def test_filter_long_run_10k():
    spec = importlib.util.spec_from_file_location("filter_long_run",
                                                  ROOT / "benchmarks" / "filter_long_run.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    result = bench.run(10**4, seed=1, check_every=2500)
    assert [c["updates"] for c in result["checks"]] == [2500, 5000, 7500, 10000]
    assert result["failures"] == []
    final = result["final"]
    assert final["asymmetry"] == 0.0  # kalman_step symmetrizes P
    assert final["min_eigenvalue"] > 0.0
    assert final["rotation_error_deg"] < 0.05 and final["translation_error"] < 1e-3


@pytest.mark.parametrize("seed", range(4))
def test_opencv_yaml_rodrigues_vectors_in_degrees_are_refused_naming_the_unit(tmp_path, seed):
    """Rotation vectors written in degrees (a common slip) are named as such, with the line;
    the same vectors in radians (length ≤ π, as cv::Rodrigues writes them) read as before."""
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 12))
    rvecs = [rotation_exp(rng.normal(size=3) * 0.8) for _ in range(n)]
    rvecs = [cv2.Rodrigues(R)[0] for R in rvecs]
    ts = [rng.normal(size=(3, 1)) * 0.2 for _ in range(n)]

    def write(vectors, name):
        path = str(tmp_path / name)
        fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
        for key, values in (("R_target2cam", vectors), ("t_target2cam", ts)):
            fs.startWriteStruct(key, cv2.FileNode_SEQ)
            for v in values:
                fs.write("", v)
            fs.endWriteStruct()
        fs.release()
        return path
    s = read_poses(write(rvecs, "rad.yaml"), "camera")
    np.testing.assert_allclose(s.poses[:, :3, :3], [cv2.Rodrigues(v)[0] for v in rvecs],
                               atol=1e-12)
    with pytest.raises(ValueError, match=r"deg\.yaml:\d+: R_target2cam: Rodrigues vectors of "
                                         r"length up to .*look like degrees.*radians"):
        read_poses(write([np.degrees(v) for v in rvecs], "deg.yaml"), "camera")

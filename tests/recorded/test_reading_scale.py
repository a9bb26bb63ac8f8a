"""Pose-file readers and alignment at scale, issue 11: the fast paths give exactly what the
line-by-line paths give (values, line numbers, errors), across chunk boundaries; the subsampling
rules of the time-offset search and of the pair formation keep the answers. Speed and memory
are measured by ``benchmarks/read_scale.py`` and ``benchmarks/calibrate_scale.py``, not here."""

import math
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

import handeye_drake.calibration.align as align
import handeye_drake.recorded.formats as formats
import handeye_drake.estimation.selection as selection
from handeye_drake import rotation_error_deg
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp, rotation_from_rpy
from handeye_drake.calibration.align import estimate_time_offset
from handeye_drake.estimation.interpolation import PoseInterpolator
from handeye_drake.estimation.selection import form_pairs, robust_hand_eye
from handeye_drake.recorded import parse_poses, pose_stream, read_poses
from handeye_drake.recorded.example import camera_pose

pytestmark = pytest.mark.filterwarnings("error")


def random_tum(n: int, seed: int = 0) -> str:
    """n TUM lines with numbers written in many ways, comments and blank lines."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    p = rng.normal(size=(n, 3))
    t = np.cumsum(rng.uniform(0.001, 0.1, n))
    fmts = ["{!r}", "{:.6f}", "{:.3e}", "{:.17g}", "{:+.4E}", "{:.9f}"]
    out = ["# generated"]
    for k in range(n):
        vals = [t[k], *p[k], *q[k]]
        fs = [fmts[(k + j) % len(fmts)] for j in range(8)]
        fs[0] = "{!r}"
        sep = [" ", "\t", ", ", "  ", ","][k % 5]
        line = sep.join(f.format(float(v)) for f, v in zip(fs, vals))
        if k % 97 == 0:
            line += "   # a comment"
        out.append(line)
        if k % 131 == 0:
            out.append("   ")
    return "\n".join(out) + "\n"


def no_fast_path(monkeypatch):
    monkeypatch.setattr(formats._Table, "fast", lambda self, chunk: None)


@pytest.mark.parametrize("chunk", [formats._PARSE_CHUNK, 997])
def test_fast_path_equals_line_by_line_path_exactly(monkeypatch, chunk):
    text = random_tum(3000)
    monkeypatch.setattr(formats, "_PARSE_CHUNK", chunk)  # small: many chunk boundaries
    fast = parse_poses(text, "tum", "robot", "r.tum")
    no_fast_path(monkeypatch)
    slow = parse_poses(text, "tum", "robot", "r.tum")
    np.testing.assert_array_equal(fast.poses, slow.poses)
    np.testing.assert_array_equal(fast.timestamps, slow.timestamps)
    assert fast.lines == slow.lines and len(fast) == 3000


def test_fast_path_numbers_are_pythons_floats():
    """numpy's text parser rounds like float(): the same double for every token."""
    text = random_tum(2000, seed=3)
    s = parse_poses(text, "tum", "robot", "r.tum")
    rows = [re.split(r"[,\s]+", ln.split("#")[0].strip()) for ln in text.splitlines()
            if ln.split("#")[0].strip()]
    t = np.array([float(r[0]) for r in rows])
    p = np.array([[float(v) for v in r[1:4]] for r in rows])
    np.testing.assert_array_equal(s.timestamps, t)
    np.testing.assert_array_equal(s.poses[:, :3, 3], p)


def test_csv_with_timestamps_across_chunks(monkeypatch):
    rng = np.random.default_rng(1)
    R = Rotation.random(500, random_state=2).as_matrix()
    X = np.zeros((500, 4, 4))
    X[:, :3, :3], X[:, :3, 3], X[:, 3, 3] = R, rng.normal(size=(500, 3)), 1.0
    text = "# t, r00 ... r33\n" + "".join(
        f"{0.01 * k!r}," + ",".join(repr(float(v)) for v in X[k].reshape(-1)) + "\n"
        for k in range(500))
    monkeypatch.setattr(formats, "_PARSE_CHUNK", 1500)
    s = parse_poses(text, "csv-matrix", "robot", "m.csv")
    np.testing.assert_allclose(s.poses, X, atol=1e-15)
    np.testing.assert_array_equal(s.timestamps, 0.01 * np.arange(500))
    assert s.lines[0] == 2 and s.lines[-1] == 501
    # A line without its timestamp far from the first line, in a later chunk.
    lines = text.splitlines()
    lines[400] = lines[400].split(",", 1)[1]
    with pytest.raises(ValueError, match=r"^m.csv:401: expected 17 numbers like line 2, got 16: "
                                         r"every line must have a timestamp, or none$"):
        parse_poses("\n".join(lines) + "\n", "csv-matrix", "robot", "m.csv")


@pytest.mark.parametrize("line, message", [
    ("{t} 0.1 0.2 0.3 0 0 0", "expected 8 numbers (timestamp tx ty tz qx qy qz qw), got 7"),
    ("{t} 0.1 x 0.3 0 0 0 1", "tum field: 'x' is not a number"),
    ("{t} 0.1 0.2 0.3 0 0 0 nan", "contains NaN or infinite values"),
    ("{t} 0.1 0.2 0.3 0 0 0 2", "quaternion (qx qy qz qw) = [0, 0, 0, 2] has norm 2"),
    ("{t} 0.1 0.2 0.3 0 0 0 1 ", None),  # trailing space: fine
])
def test_errors_in_a_later_chunk_name_their_line(monkeypatch, line, message):
    monkeypatch.setattr(formats, "_PARSE_CHUNK", 2000)
    text = random_tum(3000, seed=5).splitlines()
    k = 2500
    t = float(re.split(r"[,\s]+", text[k].strip())[0])
    text[k] = line.format(t=repr(t))
    joined = "\n".join(text) + "\n"
    if message is None:
        assert len(parse_poses(joined, "tum", "robot", "r.tum")) == 3000
        return
    with pytest.raises(ValueError, match=f"^r.tum:{k + 1}: " + re.escape(message)):
        parse_poses(joined, "tum", "robot", "r.tum")


def test_one_decreasing_timestamp_among_many_is_found():
    text = random_tum(5000, seed=7).splitlines()
    fields = re.split(r"([,\s]+)", text[3210].strip(), maxsplit=1)
    text[3210] = "50.0" + "".join(fields[1:])
    with pytest.raises(ValueError, match=r"^r.tum:3211: timestamp 50\.0 is earlier than the "
                                         r"previous sample's 158\.72\d* \(line 3210\); samples "
                                         r"must be sorted by time$"):
        parse_poses("\n".join(text) + "\n", "tum", "robot", "r.tum")


# --------------------------------------------------------------------------------- alignment
def test_lazy_interpolator_matches_scipy_slerp():
    rng = np.random.default_rng(2)
    n = 400
    times = np.cumsum(rng.uniform(0.01, 0.05, n))
    rots = Rotation.from_rotvec(np.cumsum(rng.normal(scale=0.3, size=(n, 3)), axis=0))
    X = np.zeros((n, 4, 4))
    X[:, :3, :3], X[:, :3, 3], X[:, 3, 3] = rots.as_matrix(), rng.normal(size=(n, 3)), 1.0
    interp = PoseInterpolator(times, X)
    q = np.sort(rng.uniform(times[0], times[-1], 3000))
    Y = interp(q)
    np.testing.assert_allclose(Y[:, :3, :3], Slerp(times, rots)(q).as_matrix(), atol=1e-12)
    for k in (0, 1234, 2999):
        i = np.searchsorted(times, q[k]) - 1
        s = (q[k] - times[i]) / (times[i + 1] - times[i])
        np.testing.assert_allclose(Y[k, :3, 3], (1 - s) * X[i, :3, 3] + s * X[i + 1, :3, 3],
                                   atol=1e-12)
    assert interp._segment_known.sum() <= n - 1
    # Queries touching few intervals compute only those.
    fresh = PoseInterpolator(times, X)
    fresh.rotations(times[[10, 20]] + 1e-3)
    assert fresh._segment_known.sum() == 2


def streams(offset, seed=0, duration=12.0, camera_rate=15.0):
    rng = np.random.default_rng(seed)
    X_EC = make_transform(rotation_from_rpy(np.radians([10, -5, 30])), [0.02, 0.05, 0.1])
    X_BT = make_transform(np.eye(3), [0.55, 0.05, 0.0])
    t_r = np.arange(int(duration * 50) + 1) / 50.0
    t_c = 0.3 + np.arange(int((duration - 0.6) * camera_rate)) / camera_rate
    X_BE = [camera_pose(t) @ inverse(X_EC) for t in t_r]
    X_CT = [make_transform(rotation_exp(np.radians(0.1) * rng.normal(size=3)),
                           0.0005 * rng.normal(size=3)) @ inverse(camera_pose(t)) @ X_BT
            for t in t_c]
    return pose_stream(X_BE, t_r, "robot"), pose_stream(X_CT, t_c + offset, "camera"), X_EC


def test_offset_search_on_evenly_spaced_anchors(monkeypatch):
    robot, camera, _ = streams(0.043, seed=3, duration=30.0)
    full = estimate_time_offset(robot, camera, search_range=0.25)
    monkeypatch.setattr(align, "MAX_OFFSET_ANCHORS", 60)  # of 438 usable camera samples
    capped = estimate_time_offset(robot, camera, search_range=0.25)
    assert capped.num_motions < 0.2 * full.num_motions
    assert abs(full.offset - 0.043) < 0.005 and abs(capped.offset - 0.043) < 0.005


def test_consecutive_pairs_capped_at_evenly_spaced_starts(monkeypatch):
    robot, camera, X_EC = streams(0.0, seed=1, duration=20.0, camera_rate=6.0)
    a = align.align_streams(robot, camera)
    monkeypatch.setattr(selection, "MAX_CONSECUTIVE_PAIRS", 25)
    p = form_pairs(a.X_BE, a.X_CT)
    starts = p.index[p.consecutive, 0]
    M = len(a)
    np.testing.assert_array_equal(starts, np.unique(np.linspace(0, M - 2, 25).round()))
    np.testing.assert_array_equal(p.index[p.consecutive, 1], starts + 1)
    fit = robust_hand_eye(a.X_BE, a.X_CT)
    assert rotation_error_deg(X_EC, inverse(fit.X_CE)) < 0.2


# ---------------------------------------------------------------------------------- YAML
def test_yaml_multiline_lists_read_all_numbers():
    values = np.round(np.random.default_rng(0).uniform(0, 100, 2000).cumsum(), 6)
    rows = [", ".join(repr(float(v)) for v in values[i:i + 5]) for i in range(0, 2000, 5)]
    body = ",\n      ".join(rows)
    text = (f"%YAML:1.0\ntimestamps: [ {body} ]\nposes:\n" + "".join(
        "  - !!opencv-matrix\n    rows: 4\n    cols: 4\n    dt: d\n    data: [ 1., 0., 0., "
        f"{k}., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1. ]\n" for k in range(2000)))
    s = parse_poses(text, "opencv-yaml", "robot", "y.yaml", max_translation=None)
    np.testing.assert_array_equal(s.timestamps, values)
    np.testing.assert_array_equal(s.poses[:, 0, 3], np.arange(2000.0))
    assert s.lines[0] == 403  # the list spans lines 2–401; "poses:" is line 402
    # YAML specials still take the element-by-element path.
    special = text.replace(repr(float(values[3])), ".nan", 1)
    with pytest.raises(ValueError, match=r"^y.yaml:418: timestamp nan is not finite$"):  # 4th pose
        parse_poses(special, "opencv-yaml", "robot", "y.yaml", max_translation=None)


def test_yaml_large_matrix_written_by_cv2(tmp_path):
    cv2 = pytest.importorskip("cv2")
    n = 3000
    stamps = np.cumsum(np.random.default_rng(1).uniform(0.01, 0.1, n)).reshape(n, 1)
    X = np.array([make_transform(rotation_exp([0.001 * k, 0.2, 0.0]), [0.001 * k, 0, 0.5])
                  for k in range(n)])
    path = str(tmp_path / "cv.yaml")
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
    fs.write("camera_timestamps", stamps)
    fs.startWriteStruct("camera_poses", cv2.FileNode_SEQ)
    for M in X:
        fs.write("", M)
    fs.endWriteStruct()
    fs.release()
    s = read_poses(path, "camera")
    np.testing.assert_array_equal(s.timestamps, stamps.reshape(-1))
    np.testing.assert_allclose(s.poses, X, atol=1e-15)


# -------------------------------------------------------------------------------- progress
def test_progress_goes_to_stderr_only(tmp_path, capsys, monkeypatch):
    p = tmp_path / "r.tum"
    p.write_text(random_tum(200))
    monkeypatch.setattr(formats, "PROGRESS_DELAY_S", 0.0)
    s = read_poses(p, "robot", progress=True)
    captured = capsys.readouterr()
    assert len(s) == 200 and captured.out == "" and "parsing r.tum" in captured.err
    read_poses(p, "robot")  # default: only when stderr is a terminal (not here)
    assert capsys.readouterr().err == ""


def test_streams_hold_arrays_not_per_pose_objects():
    s = parse_poses(random_tum(1000), "tum", "robot", "r.tum")
    assert isinstance(s.poses, np.ndarray) and s.poses.shape == (1000, 4, 4)
    assert np.asarray(s.lines).dtype == np.int64 and len(s.lines) == 1000
    assert math.isclose(float(np.abs(np.linalg.det(s.poses[:, :3, :3]) - 1).max()), 0.0,
                        abs_tol=1e-14)

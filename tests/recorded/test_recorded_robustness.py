"""Robustness of the recorded-data pipeline and of the estimation core.

1. Every class of bad input of issue 6 raises a ValueError naming the file and the line (or the
   files involved), and the ``calibrate`` command turns it into one ``handeye-drake: error:``
   line on stderr with exit code 2.
2. Property-based tests (hypothesis): arbitrary inputs (random arrays with NaN/inf/huge/tiny
   entries, random lists, random text) give either a result without NaN or a ValueError, never
   another exception.
"""

import math
import os
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import handeye_drake
from handeye_drake import (
    HandEyeKalmanFilter,
    calibrate_hand_eye,
    linear_system,
    orthonormalize,
    relative_motions,
    rotation_error_deg,
    solve_ax_xb,
)
from handeye_drake.calibration import calibrate_streams
from handeye_drake.apps.cli import main
from handeye_drake.estimation.configs import PaperFilter
from handeye_drake.estimation.se3 import inverse, make_transform, quat_wxyz, rotation_exp
from handeye_drake.calibration.align import align_streams, estimate_time_offset
from handeye_drake.estimation.interpolation import interpolate_poses
from handeye_drake.estimation.selection import robust_hand_eye
from handeye_drake.recorded import parse_poses, pose_stream, read_poses

# ------------------------------------------------------------------------------ bad input files
GOOD_TUM = "0.0 0.1 0.2 0.3 0 0 0 1\n0.1 0.1 0.2 0.3 0 0 0 1\n"
R90X = "1 0 0 0 0 0 -1 0 0 1 0 0 0 0 0 1"


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


BAD_FILES = [
    # (id, file name, content, format, stream, expected message regex; {file} = the path)
    ("empty", "a.tum", "", "tum", "robot", r"{file}: no pose samples"),
    ("comments only", "a.tum", "# nothing\n\n  # here\n", "tum", "robot",
     r"{file}: no pose samples"),
    ("field count", "a.tum", GOOD_TUM + "0.2 1 2 3 0 0 1\n", "tum", "robot",
     r"{file}:3: expected 8 numbers .* got 7"),
    ("not a number", "a.tum", "# header\n0.0 0.1 zero 0.3 0 0 0 1\n", "tum", "robot",
     r"{file}:2: .*'zero' is not a number"),
    ("nan", "a.tum", GOOD_TUM + "0.2 nan 0 0 0 0 0 1\n", "tum", "robot",
     r"{file}:3: contains NaN or infinite"),
    ("inf", "a.csv", f"1e999 {R90X}\n", "csv-matrix", "robot",
     r"{file}:1: contains NaN or infinite"),
    ("quaternion norm", "a.tum", GOOD_TUM + "0.2 0 0 0 0 0 0 1.01\n", "tum", "camera",
     r"{file}:3: quaternion .* norm 1\.01, not 1 \(tolerance 0\.001\)"),
    ("zero quaternion", "a.tum", "0 0 0 0 0 0 0 0\n", "tum", "camera",
     r"{file}:1: quaternion .* norm 0"),
    ("non-rotation", "a.csv", "2 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n", "csv-matrix", "robot",
     r"{file}:1: rotation block is not a rotation matrix: .* > tolerance 0\.001"),
    ("reflection", "a.csv", "-1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n", "csv-matrix", "robot",
     r"{file}:1: rotation block is not a rotation matrix.*det = -1"),
    ("last row", "a.csv", "1 0 0 0 0 1 0 0 0 0 1 0 0.5 0 0 1\n", "csv-matrix", "robot",
     r"{file}:1: last row .* must be \[0, 0, 0, 1\]"),
    ("column-major", "a.csv", "1 0 0 0 0 1 0 0 0 0 1 0 0.5 0.2 0.1 1\n", "csv-matrix", "robot",
     r"{file}:1: last row .*column-major"),
    ("mixed counts", "a.csv", f"0.0 {R90X}\n{R90X}\n", "csv-matrix", "robot",
     r"{file}:2: expected 17 numbers like line 1, got 16"),
    ("csv header", "a.csv", f"t,r00,r01\n0.0 {R90X}\n", "csv-matrix", "robot",
     r"{file}:1: expected 16 numbers .*got 3 \(header lines must start with '#'"),
    ("unsorted", "a.tum", GOOD_TUM + "0.05 0 0 0 0 0 0 1\n", "tum", "robot",
     r"{file}:3: timestamp 0\.05 is earlier than the previous sample's 0\.1 \(line 2\)"),
    ("duplicate", "a.tum", GOOD_TUM + "0.1 0 0 0 0 0 0 1\n", "tum", "robot",
     r"{file}:3: duplicate timestamp 0\.1 \(same as line 2\)"),
    ("millimetres", "a.tum", "0 450.0 -120.5 300.0 0 0 0 1\n", "tum", "robot",
     r"{file}:1: translation of length 554\.094 exceeds 10.*millimetres\?"),
    ("yaml header", "a.yaml", "R_gripper2base: []\n", "opencv-yaml", "robot",
     r"{file}:1: not an OpenCV YAML file"),
    ("yaml R without t", "a.yaml",
     "%YAML:1.0\n---\nR_gripper2base:\n   - !!opencv-matrix\n      rows: 3\n      cols: 1\n"
     "      dt: d\n      data: [ 0., 0., 0. ]\n", "opencv-yaml", "robot",
     r"{file}:3: R_gripper2base without t_gripper2base"),
    ("yaml data count", "a.yaml",
     "%YAML:1.0\nposes:\n   - !!opencv-matrix\n      rows: 4\n      cols: 4\n      dt: d\n"
     "      data: [ 1., 0., 0. ]\n", "opencv-yaml", "robot",
     r"{file}:7: matrix data has 3 numbers, rows × cols = 4 × 4 = 16"),
    ("yaml shape", "a.yaml",
     "%YAML:1.0\nposes:\n   - !!opencv-matrix\n      rows: 3\n      cols: 3\n      dt: d\n"
     "      data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]\n", "opencv-yaml", "robot",
     r"{file}:3: poses: expected 4×4 matrices, got 3×3"),
    ("yaml lengths", "a.yaml",
     "%YAML:1.0\nR_target2cam:\n  - !!opencv-matrix\n    rows: 3\n    cols: 1\n    dt: d\n"
     "    data: [ 0., 0., 0.1 ]\n  - !!opencv-matrix\n    rows: 3\n    cols: 1\n    dt: d\n"
     "    data: [ 0., 0., 0.2 ]\nt_target2cam:\n  - !!opencv-matrix\n    rows: 3\n    cols: 1\n"
     "    dt: d\n    data: [ 0., 0., 0.5 ]\n", "opencv-yaml", "camera",
     r"{file}:13: R_target2cam has 2 entries but t_target2cam has 1: mismatched lengths"),
    ("yaml tag", "a.yaml", "%YAML:1.0\nposes: !!binary abc\n", "opencv-yaml", "robot",
     r"{file}:2: unsupported tag !!binary"),
    ("yaml tab", "a.yaml", "%YAML:1.0\nposes:\n\t- 1\n", "opencv-yaml", "robot",
     r"{file}:3: tab in indentation"),
    ("yaml no keys", "a.yaml", "%YAML:1.0\nfoo: 1\n", "opencv-yaml", "camera",
     r"{file}: no camera poses: expected the keys R_target2cam/t_target2cam or "
     r"R_cam2target.*found keys: foo"),
    ("yaml nan", "a.yaml",
     "%YAML:1.0\nposes:\n   - !!opencv-matrix\n      rows: 4\n      cols: 4\n      dt: d\n"
     "      data: [ 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., .Nan, 0., 0., 0., 1. ]\n",
     "opencv-yaml", "robot", r"{file}:3: pose contains NaN or infinite values"),
    ("yaml stamps", "a.yaml",
     "%YAML:1.0\ntimestamps: [ 0., 1. ]\nposes:\n   - !!opencv-matrix\n      rows: 4\n"
     "      cols: 4\n      dt: d\n      data: [ 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0.,"
     " 0., 0., 0., 1. ]\n", "opencv-yaml", "robot",
     r"{file}:2: timestamps has 2 values for 1 poses: mismatched lengths"),
]


@pytest.mark.parametrize("case", BAD_FILES, ids=[c[0] for c in BAD_FILES])
def test_bad_file_raises_value_error_naming_file_and_line(tmp_path, case):
    _, name, text, fmt, stream, pattern = case
    path = write(tmp_path, name, text)
    with pytest.raises(ValueError, match=pattern.format(file=re.escape(str(path)))):
        read_poses(path, stream, fmt)


def test_unreadable_files(tmp_path):
    missing = tmp_path / "missing.tum"
    with pytest.raises(ValueError, match=re.escape(str(missing)) + r": cannot read the file"):
        read_poses(missing, "robot")
    with pytest.raises(ValueError, match=r": cannot read the file"):
        read_poses(tmp_path, "robot", "tum")  # a directory
    binary = tmp_path / "b.tum"
    binary.write_bytes(b"0 0 0 0 0 0 0 1\n\xff\xfe\x00\x01")
    with pytest.raises(ValueError, match=re.escape(str(binary)) + r":2: not a text file"):
        read_poses(binary, "robot")
    with pytest.raises(ValueError, match=r"cannot infer the format from the extension '\.dat'"):
        read_poses(tmp_path / "x.dat", "robot")


def test_quaternion_and_rotation_tolerances(tmp_path):
    # Within the tolerance: normalized / projected, not refused.
    s = parse_poses("0 0 0 0 0 0 0 1.0009\n", "tum", "robot", "q.tum")
    np.testing.assert_allclose(s.poses[0], np.eye(4), atol=1e-15)
    R = "0.7071 -0.7071 0 0 0.7071 0.7071 0 0 0 0 1 0"  # 45° about z, 4 decimals
    s = parse_poses(R + " 0 0 0 1\n", "csv-matrix", "robot", "r.csv")
    c = math.cos(math.pi / 4)
    np.testing.assert_allclose(s.poses[0, :3, :3], [[c, -c, 0], [c, c, 0], [0, 0, 1]],
                               atol=1e-12)
    # Just beyond: refused.
    with pytest.raises(ValueError, match=r"q.tum:1: quaternion .* norm 1\.0011"):
        parse_poses("0 0 0 0 0 0 0 1.0011\n", "tum", "robot", "q.tum")


def test_translation_scale_accepts_millimetres():
    s = parse_poses("0 450.0 -120.5 300.0 0 0 0 1\n", "tum", "robot", "mm.tum",
                    translation_scale=0.001)
    np.testing.assert_allclose(s.poses[0, :3, 3], [0.45, -0.1205, 0.3])


def test_camera_in_target_flag_contradicting_yaml_keys():
    text = ("%YAML:1.0\nR_target2cam:\n  - !!opencv-matrix\n    rows: 3\n    cols: 1\n    dt: d\n"
            "    data: [ 0., 0., 0.1 ]\nt_target2cam:\n  - !!opencv-matrix\n    rows: 3\n"
            "    cols: 1\n    dt: d\n    data: [ 0., 0., 0.5 ]\n")
    with pytest.raises(ValueError, match=r"c.yaml:2: R_target2cam holds X_CT .* contradicts "
                                         r"camera_in_target=True"):
        parse_poses(text, "opencv-yaml", "camera", "c.yaml", camera_in_target=True)


# ------------------------------------------------------------------- stream-level bad inputs
def _tum(poses, times, header=""):
    lines = [header] if header else []
    for t, X in zip(times, poses):
        w, x, y, z = quat_wxyz(X[:3, :3])
        p = X[:3, 3]
        lines.append(f"{t:.6f} {p[0]:.9f} {p[1]:.9f} {p[2]:.9f} {x:.12f} {y:.12f} {z:.12f} "
                     f"{w:.12f}")
    return "\n".join(lines) + "\n"


def _recording(rotvec_fn, n=40, rate=10.0, X_EC=None):
    """Exact robot and camera poses of a motion whose camera orientation is exp(rotvec_fn(t))."""
    X_EC = make_transform(rotation_exp([0.1, -0.2, 1.5]), [0.05, -0.02, 0.07]) \
        if X_EC is None else X_EC
    X_BT = make_transform(np.eye(3), [0.6, 0.0, 0.0])
    t = np.arange(n) / rate
    X_BC = [make_transform(rotation_exp(rotvec_fn(s)), [0.1 * s, 0.05 * math.sin(s), 0.3])
            for s in t]
    X_BE = [X @ inverse(X_EC) for X in X_BC]
    X_CT = [inverse(X) @ X_BT for X in X_BC]
    return t, X_BE, X_CT


def _calibrate_text(tmp_path, robot_text, camera_text, *extra):
    r = write(tmp_path, "robot.tum", robot_text)
    c = write(tmp_path, "camera.tum", camera_text)
    return r, c, ["calibrate", "--robot", str(r), "--camera", str(c), "--out",
                  str(tmp_path / "out"), *extra]


def test_degenerate_pure_translation(tmp_path, capsys):
    t, X_BE, X_CT = _recording(lambda s: [0.0, 0.0, 0.0])
    r, c, argv = _calibrate_text(tmp_path, _tum(X_BE, t), _tum(X_CT, t))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("handeye-drake: error: degenerate motion")
    assert "pure translation" in err and "largest rotation 0°" in err


def test_degenerate_parallel_axes(tmp_path, capsys):
    t, X_BE, X_CT = _recording(lambda s: [0.0, 0.0, 0.6 * math.sin(s)])
    r, c, argv = _calibrate_text(tmp_path, _tum(X_BE, t), _tum(X_CT, t))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "(near-)parallel" in err
    assert "is unobservable" in err and "--fix" in err


def test_too_few_samples(tmp_path, capsys):
    t, X_BE, X_CT = _recording(lambda s: [0.5 * math.sin(s), 0.4 * math.cos(2 * s), 0.0], n=2)
    r, c, argv = _calibrate_text(tmp_path, _tum(X_BE, t), _tum(X_CT, t))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "only 2 of 2 camera samples" in err or "too few samples" in err


def test_streams_that_do_not_overlap(tmp_path, capsys):
    t, X_BE, X_CT = _recording(lambda s: [0.5 * math.sin(s), 0.4 * math.cos(2 * s), 0.0])
    r, c, argv = _calibrate_text(tmp_path, _tum(X_BE, t), _tum(X_CT, t + 1.7e9))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert re.search(r"camera.tum: only 0 of 40 camera samples fall inside the robot's time "
                     r"span .* same clock and time unit\?", err)


def test_index_paired_streams_of_different_lengths(tmp_path, capsys):
    flat = " ".join(map(str, np.eye(4).reshape(-1)))
    r = write(tmp_path, "r.csv", (flat + "\n") * 5)
    c = write(tmp_path, "c.csv", (flat + "\n") * 4)
    assert main(["calibrate", "--robot", str(r), "--camera", str(c), "--out",
                 str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert f"{r} has 5 poses and {c} has 4: mismatched lengths" in err


def test_one_stream_without_timestamps(tmp_path, capsys):
    flat = " ".join(map(str, np.eye(4).reshape(-1)))
    r = write(tmp_path, "r.csv", "".join(f"{k} {flat}\n" for k in range(5)))
    c = write(tmp_path, "c.csv", (flat + "\n") * 5)
    assert main(["calibrate", "--robot", str(r), "--camera", str(c), "--out",
                 str(tmp_path / "o")]) == 2
    assert f"{c}: has no timestamps but {r} has" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()     # a failed run leaves no folder


def test_mismatched_streams_explained(tmp_path, capsys):
    """Camera poses of another recording: rotation angles of A and B disagree."""
    t, X_BE, _ = _recording(lambda s: [0.5 * math.sin(s), 0.4 * math.cos(2 * s), 0.1 * s])
    _, _, X_CT = _recording(lambda s: [0.1 * math.cos(3 * s), 0.9 * math.sin(s), -0.3 * s])
    r, c, argv = _calibrate_text(tmp_path, _tum(X_BE, t), _tum(X_CT, t))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "camera and robot motions do not match" in err and "synchronized" in err


def test_wrong_camera_convention_flag_is_diagnosed(tmp_path, capsys):
    data = Path(handeye_drake.__file__).parent / "data"
    assert main(["calibrate", "--robot", str(data / "example_robot.tum"), "--camera",
                 str(data / "example_camera.tum"), "--camera-pose-is-camera-in-target",
                 "--time-offset", "0.02", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(
        "handeye-drake: error: no hand-eye transform fits the data as read")
    assert "likely cause" in err and "drop --camera-pose-is-camera-in-target" in err
    assert not (tmp_path / "calibration.json").exists()


@pytest.mark.parametrize("case", [c for c in BAD_FILES if c[4] == "robot" and c[3] == "tum"],
                         ids=[c[0] for c in BAD_FILES if c[4] == "robot" and c[3] == "tum"])
def test_command_reports_one_line_and_exit_code_2(tmp_path, capsys, case):
    _, name, text, fmt, stream, pattern = case
    r = write(tmp_path, "robot.tum", text)
    c = write(tmp_path, "camera.tum", GOOD_TUM)
    assert main(["calibrate", "--robot", str(r), "--camera", str(c), "--out",
                 str(tmp_path / "o")]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.count("\n") == 1 and "Traceback" not in captured.err
    assert re.match("handeye-drake: error: " + pattern.format(file=re.escape(str(r))),
                    captured.err)


def test_command_argument_errors_are_one_line_usage_errors(tmp_path, capsys):
    assert main(["calibrate", "--robot", "r.tum", "--camera", "c.tum", "--time-offset",
                 "soon"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("handeye-drake calibrate: error: ")
    assert "--time-offset: expected 'auto' or seconds, got 'soon'" in err
    assert main(["calibrate", "--no-such-option"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unrecognized arguments: --no-such-option" in err


def test_command_bad_numeric_options(tmp_path, capsys):
    t, X_BE, X_CT = _recording(lambda s: [0.5 * math.sin(s), 0.4 * math.cos(2 * s), 0.1 * s])
    r, c, argv = _calibrate_text(tmp_path, _tum(X_BE, t), _tum(X_CT, t))
    for extra, message in ((["--holdout", "0.9"], "holdout_fraction: must be in [0, 0.5], "
                                                  "got 0.9"),
                           (["--min-rotation", "nan"], "min_rotation_deg: must be a number"),
                           (["--translation-scale", "-1"], "--translation-scale: expected a "
                                                           "positive number, got '-1'"),
                           (["--max-noise", "1"], "--max-noise: expected DEG,MM"),
                           (["--time-offset", "auto", "--time-offset-range", "0"],
                            "--time-offset-range: expected a positive number, got '0'"),
                           (["--online", "--online-step", "120"],
                            "online_step_deg: must be a number in [0, 90], got 120.0")):
        assert main(argv + extra) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err, (extra, err)


# ----------------------------------------------------------------------- property-based tests
SPECIAL = [0.0, -0.0, 5e-324, 1e-308, 1e-300, 1e-150, 1e150, 1e300, 1e308, -1e308, math.nan,
           math.inf, -math.inf, 1.0, -1.0]
any_float = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from(SPECIAL))
big_or_small = st.one_of(st.floats(-10.0, 10.0), st.sampled_from(SPECIAL[:10]))


def _pose(rotvec, translation):
    return make_transform(rotation_exp(rotvec), translation)


rotvecs = arrays(np.float64, 3, elements=st.floats(-4.0, 4.0))
translations = arrays(np.float64, 3, elements=big_or_small)
rigid_poses = st.builds(_pose, rotvecs, translations)
noisy_poses = st.builds(lambda X, E: X + np.pad(E, ((0, 1), (0, 0))), rigid_poses,
                        arrays(np.float64, (3, 4), elements=st.floats(-0.1, 0.1)))
garbage = arrays(np.float64, st.sampled_from([(), (3,), (3, 3), (4, 4), (4, 4), (2, 4, 4), (4, 3)]),
                 elements=any_float)
junk = st.one_of(st.none(), st.text(max_size=5), st.integers(), st.lists(st.integers(), max_size=3))
any_pose = st.one_of(rigid_poses, rigid_poses, noisy_poses, garbage, junk)
pose_lists = st.one_of(st.lists(any_pose, max_size=6), st.lists(rigid_poses, min_size=2,
                                                                max_size=6), garbage, junk)

#: Modest by default (the file runs in seconds); HANDEYE_FUZZ_EXAMPLES=2000 for a deeper hunt.
FUZZ_EXAMPLES = int(os.environ.get("HANDEYE_FUZZ_EXAMPLES", "60"))
PROPERTY = settings(max_examples=FUZZ_EXAMPLES, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


def _finite(*values):
    for v in values:
        if isinstance(v, (list, tuple)):
            _finite(*v)
        else:
            assert np.all(np.isfinite(np.asarray(v, dtype=float))), v


def _value_error_or_finite(fn, *args, **kwargs):
    try:
        out = fn(*args, **kwargs)
    except ValueError:
        return None
    _finite(out)
    return out


# Explicit examples: inputs that once escaped as TypeError / OverflowError / inf from the core
# (a 0-d array as a pose list, translations near ±1e308, a sigma whose square overflows).
HUGE = make_transform(np.eye(3), [1e308, 0.0, 0.0])
MINUS_HUGE = make_transform(np.eye(3), [-1e308, 0.0, 0.0])


@PROPERTY
@example(np.array(0.0), None, False)
@example([HUGE, MINUS_HUGE], [np.eye(4), np.eye(4)], True)
@given(pose_lists, pose_lists, st.booleans())
def test_relative_motions_arbitrary(X_BE, X_CT, rigid):
    _value_error_or_finite(relative_motions, X_BE, X_CT, rigid_camera=rigid)


@PROPERTY
@given(any_pose, any_pose)
def test_linear_system_arbitrary(A, B):
    _value_error_or_finite(linear_system, A, B)


@PROPERTY
@given(st.one_of(garbage, arrays(np.float64, (3, 3), elements=big_or_small), junk),
       st.sampled_from(["svd", "qr", "horn", "gram"]))
def test_orthonormalize_arbitrary(M, method):
    R = _value_error_or_finite(orthonormalize, M, method)
    if R is not None:
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-9)


def _consistent_pairs(X, Bs):
    """Motion pairs A = X B X⁻¹ (exact) plus arbitrary extra ones."""
    X_inv = np.linalg.inv(X)
    with np.errstate(over="ignore", invalid="ignore"):  # the test's own arithmetic
        return [X @ B @ X_inv for B in Bs], list(Bs)


@PROPERTY
@given(rigid_poses, st.lists(rigid_poses, max_size=5), st.lists(any_pose, max_size=2),
       st.sampled_from(["tsai", "park", "horaud", "andreff", "daniilidis", "nope"]),
       st.booleans())
def test_solve_ax_xb_arbitrary(X, Bs, extra, method, orthonormalize_inputs):
    A_list, B_list = _consistent_pairs(X, Bs)
    A_list += extra
    B_list += extra[::-1]
    _value_error_or_finite(solve_ax_xb, A_list, B_list, method,
                           orthonormalize_inputs=orthonormalize_inputs)


METHOD_NAMES = ["tsai", "park", "horaud", "andreff", "daniilidis"]


@PROPERTY
@example([], np.array(0.0), "tsai", "all")
@given(pose_lists, pose_lists, st.sampled_from(METHOD_NAMES),
       st.sampled_from(["all", "consecutive", "some"]))
def test_calibrate_hand_eye_arbitrary(X_BE, X_CT, method, pairs):
    _value_error_or_finite(calibrate_hand_eye, X_BE, X_CT, method, pairs)


def _kalman_sequence(X0, motions, noise_model, sigma):
    try:
        kf = HandEyeKalmanFilter(PaperFilter(rotation_coefficient_sigma=sigma,
                                             translation_sigma=sigma,
                                             noise_covariance=noise_model), X0)
    except ValueError:
        return
    for A, B in motions:
        try:
            kf.update_motion(A, B)
        except ValueError:
            pass
        # Whether or not the update was accepted, the state stays finite and usable.
        _finite(kf.state, kf.covariance)
        _value_error_or_finite(lambda: kf.X_CE)


@PROPERTY
@example(np.eye(4), [(np.eye(4), np.eye(4))], "diagonal", 1e300)
@given(rigid_poses, st.lists(st.tuples(any_pose, any_pose), max_size=4),
       st.sampled_from(["diagonal", "exact", "full"]), big_or_small)
def test_kalman_update_arbitrary(X0, motions, noise_model, sigma):
    _kalman_sequence(X0, motions, noise_model, sigma)


# Text made of the tokens the readers care about, so that the fuzzing reaches deep branches.
TOKENS = ["0", "1", "-1", "0.5", "1e400", "nan", ".Nan", "-.Inf", "1e-320", "0.70710678", "#",
          ",", "[", "]", "- ", "-", ":", "rows:", "cols:", "dt: d", "data:", "4", "3",
          "!!opencv-matrix", "poses:", "R_gripper2base:", "t_gripper2base:", "R_target2cam:",
          "t_target2cam:", "timestamps:", "%YAML:1.0", "---", "\t", "  ", "x", "{", "}"]
token_text = st.lists(st.lists(st.sampled_from(TOKENS), max_size=12).map(" ".join),
                      max_size=25).map("\n".join)


@PROPERTY
@given(st.one_of(st.text(max_size=300), token_text),
       st.sampled_from(["tum", "csv-matrix", "opencv-yaml"]), st.sampled_from(["robot", "camera"]),
       st.booleans())
def test_readers_on_arbitrary_text(text, fmt, stream, camera_in_target):
    s = _value_error_or_finite(lambda: parse_poses(text, fmt, stream, "fuzz",
                                                   camera_in_target).poses)
    if s is not None:
        np.testing.assert_allclose(s[:, 3], np.tile([0, 0, 0, 1.0], (len(s), 1)))


def _matrix_lines(rows):
    return "\n".join(" ".join(repr(float(v)) for v in row) for row in rows)


@PROPERTY
@given(arrays(np.float64, st.tuples(st.integers(1, 4), st.sampled_from([8, 16, 17])),
              elements=any_float))
def test_readers_on_arbitrary_numbers(rows):
    fmt = "tum" if rows.shape[1] == 8 else "csv-matrix"
    _value_error_or_finite(lambda: parse_poses(_matrix_lines(rows), fmt, "robot", "n").poses)


@PROPERTY
@given(st.one_of(garbage, arrays(np.float64, st.tuples(st.integers(0, 4), st.just(4),
                                                      st.just(4)), elements=any_float), junk),
       st.one_of(st.none(), garbage, junk))
def test_pose_stream_arbitrary(poses, timestamps):
    _value_error_or_finite(lambda: pose_stream(poses, timestamps).poses)


@PROPERTY
@given(arrays(np.float64, st.integers(1, 5), elements=st.one_of(st.floats(-5, 5), st.sampled_from(
    SPECIAL))), st.lists(rigid_poses, min_size=1, max_size=5),
    st.one_of(arrays(np.float64, st.integers(0, 4), elements=any_float), garbage, junk))
def test_interpolation_arbitrary(times, poses, query):
    n = min(len(times), len(poses))
    _value_error_or_finite(interpolate_poses, times[:n], np.array(poses[:n]), query)
    _value_error_or_finite(interpolate_poses, query, np.array(poses[:n]), times)


@PROPERTY
@given(st.lists(rigid_poses, min_size=1, max_size=8), st.lists(rigid_poses, min_size=1, max_size=8),
       st.floats(-3, 3), st.one_of(st.floats(0.01, 3), st.sampled_from(SPECIAL)), st.booleans())
def test_alignment_and_offset_arbitrary(robot, camera, offset, search, timestamps):
    try:
        r = pose_stream(robot, np.arange(len(robot)) * 0.3 if timestamps else None, "r")
        c = pose_stream(camera, np.arange(len(camera)) * 0.2 + 0.1 if timestamps else None, "c")
    except ValueError:
        return
    a = _value_error_or_finite(lambda: align_streams(r, c, offset).X_BE)
    if a is not None:
        assert len(a) >= 3
    _value_error_or_finite(lambda: estimate_time_offset(r, c, search).offset)


@settings(max_examples=max(25, FUZZ_EXAMPLES // 3), deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(rigid_poses, min_size=0, max_size=10), st.integers(0, 3),
       st.sampled_from(["daniilidis", "tsai", "park"]))
def test_robust_hand_eye_arbitrary(robot, shift, method):
    camera = robot[shift:] + robot[:shift]  # arbitrary (mostly inconsistent) camera poses
    if not robot:
        X_BE = X_CT = np.zeros((0, 4, 4))
    else:
        X_BE, X_CT = np.array(robot), np.array([inverse(X) for X in camera])
    fit = _value_error_or_finite(lambda: robust_hand_eye(X_BE, X_CT, method).X_CE)
    if fit is not None:
        np.testing.assert_allclose(fit[3], [0, 0, 0, 1])


realistic_poses = st.builds(_pose, arrays(np.float64, 3, elements=st.floats(-0.6, 0.6)),
                           arrays(np.float64, 3, elements=st.floats(-1.0, 1.0)))


_rng = np.random.default_rng(11)
CONSISTENT_ROBOT = [_pose(_rng.uniform(-0.6, 0.6, 3), _rng.uniform(-0.5, 0.5, 3))
                    for _ in range(12)]


@settings(max_examples=max(20, FUZZ_EXAMPLES // 3), deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@example(CONSISTENT_ROBOT, 0, _pose([0.1, 0.2, 1.4], [0.05, 0.0, 0.1]), False, None, "auto",
         True)
@example(CONSISTENT_ROBOT, 0, _pose([0.1, 0.2, 1.4], [0.05, 0.0, 0.1]), True, 0.0, "park",
         False)
@given(st.lists(st.one_of(rigid_poses, realistic_poses), min_size=1, max_size=12),
       st.integers(0, 5), st.one_of(rigid_poses, realistic_poses),
       st.booleans(), st.one_of(st.none(), st.just("auto"), st.floats(-1, 1), any_float),
       st.sampled_from(["auto", "park", "other"]), st.booleans())
def test_calibrate_streams_arbitrary(robot, shift, X_EC, timestamps, offset, method, online):
    # shift 0: consistent hand-eye data (target at the base origin); otherwise mismatched.
    with np.errstate(all="ignore"):  # generated poses may overflow: the library must refuse them
        camera = [inverse(X @ X_EC) for X in robot[shift:] + robot[:shift]]
    stamps = (lambda n, t0: np.arange(n) * 0.1 + t0) if timestamps else (lambda n, t0: None)
    try:
        r = pose_stream(robot, stamps(len(robot), 0.0), "r")
        c = pose_stream(camera, stamps(len(camera), 0.0), "c")
    except ValueError:
        return
    try:
        res = calibrate_streams(r, c, time_offset=offset, method=method, online=online)
    except ValueError:
        assert robot is not CONSISTENT_ROBOT or method == "other"
        return
    _finite(res.X_EC, res.covariance, res.fit.X_H)
    if robot is CONSISTENT_ROBOT:  # the explicit examples: exact data, exact answer
        assert rotation_error_deg(X_EC, res.X_EC) < 1e-6

"""Pose-file readers and alignment, issue 11: inputs read once (streams, devices, FIFOs), binary
input, and messages that name the real cause. One regression test per class: the bad input and
the exact error. No warning may escape (``filterwarnings("error")`` below)."""

import hashlib
import math
import os
import re
import threading
from pathlib import Path

import numpy as np
import pytest

from handeye_drake.estimation.se3 import inverse, make_transform, quat_wxyz, rotation_exp
from handeye_drake.calibration.align import align_streams, estimate_time_offset
from handeye_drake.estimation.selection import robust_hand_eye
from handeye_drake.recorded import parse_poses, pose_stream, read_poses
from handeye_drake.calibration import calibrate_files
from handeye_drake.apps.cli import main
from handeye_drake.recorded.example import data_dir
from handeye_drake.recorded.formats import LineNumbers, read_input, time_unit_hint

pytestmark = pytest.mark.filterwarnings("error")

DATA = data_dir()
ROBOT = (DATA / "example_robot.tum").read_text()
CAMERA = (DATA / "example_camera.tum").read_text()
GOOD = "0.0 0.1 0.2 0.3 0 0 0 1\n0.1 0.1 0.2 0.3 0 0 0 1\n"


def rescaled(text: str, factor: float, offset: float = 0.0) -> str:
    """The same TUM text with timestamps t → factor·t + offset (integers)."""
    out = []
    for ln in text.splitlines():
        if ln and not ln.startswith("#"):
            t, rest = ln.split(" ", 1)
            ln = f"{float(t) * factor + offset:.0f} {rest}"
        out.append(ln)
    return "\n".join(out) + "\n"


def one_error_line(capsys) -> str:
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1, captured
    assert "Traceback" not in captured.err
    return captured.err.removeprefix("handeye-drake: error: ").strip()


# ------------------------------------------------------------------ devices, FIFOs, pipes, caps
@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom"])
def test_devices_fail_at_once_with_one_line(tmp_path, capsys, device):
    if not os.path.exists(device):
        pytest.skip(f"no {device}")
    camera = tmp_path / "camera.tum"
    camera.write_text(GOOD)
    assert main(["calibrate", "--robot", device, "--camera", str(camera), "--format", "tum",
                 "--out", str(tmp_path / "o")]) == 2
    err = one_error_line(capsys)
    assert re.fullmatch(re.escape(device) + r":\d+: not a text file \((NUL byte|invalid UTF-8 "
                        r"byte 0x[0-9a-f]{2}) at byte offset \d+\)", err), err


def _feed(path, data: bytes):
    def run():
        with open(path, "wb") as f:
            f.write(data)
    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def test_fifo_is_read_once_and_hashed(tmp_path):
    fifo = tmp_path / "camera.fifo"
    os.mkfifo(fifo)
    writer = _feed(fifo, CAMERA.encode())
    s = read_poses(fifo, "camera", "tum")
    writer.join(5)
    assert not writer.is_alive() and len(s) == 304
    assert s.sha256 == hashlib.sha256(CAMERA.encode()).hexdigest()
    assert s.bytes_read == len(CAMERA.encode())


def test_calibrate_on_a_fifo_records_the_digest_of_what_was_read(tmp_path):
    """A FIFO can be read once: the digest must come from that read (it used to hang after the
    calibration, re-reading the FIFO to hash it)."""
    fifo = tmp_path / "robot.fifo"
    os.mkfifo(fifo)
    writer = _feed(fifo, ROBOT.encode())
    res = calibrate_files(fifo, DATA / "example_camera.tum", "tum", time_offset=0.02)
    writer.join(5)
    assert res.inputs["robot"]["sha256"] == hashlib.sha256(ROBOT.encode()).hexdigest()
    assert res.inputs["camera"]["sha256"] == hashlib.sha256(CAMERA.encode()).hexdigest()


def test_pipe_path_hashes_what_was_read():
    """A process substitution ``<(cat FILE)`` is a /dev/fd/N pipe: read once, hashed."""
    r, w = os.pipe()
    try:
        writer = threading.Thread(target=lambda: (os.write(w, GOOD.encode()), os.close(w)),
                                  daemon=True)
        writer.start()
        s = read_poses(f"/dev/fd/{r}", "robot", "tum")
        writer.join(5)
    finally:
        os.close(r)
    assert len(s) == 2 and s.sha256 == hashlib.sha256(GOOD.encode()).hexdigest()


def test_stream_byte_cap_holds_without_a_size(tmp_path):
    fifo = tmp_path / "big.fifo"
    os.mkfifo(fifo)
    writer = _feed(fifo, GOOD.encode() * 200)  # 9.6 kB of valid text
    with pytest.raises(ValueError, match=re.escape(f"{fifo}: larger than 1000 bytes: reading "
                                                   "stopped there (a device or a stream that "
                                                   "does not end?)")):
        read_input(fifo, max_bytes=1000)
    writer.join(5)


def test_regular_file_cap_is_checked_before_reading(tmp_path):
    p = tmp_path / "big.tum"
    p.write_text(GOOD * 100)
    with pytest.raises(ValueError, match=re.escape(f"{p}: file is larger than 1000 bytes")):
        read_input(p, max_bytes=1000)


# ---------------------------------------------------------------------------------- binary input
@pytest.mark.parametrize("data, message", [
    (GOOD.encode() + b"0.2 \xff 0 0 0 0 0 1\n",
     ":3: not a text file (invalid UTF-8 byte 0xff at byte offset 52)"),
    (GOOD.encode() + b"\x00", ":3: not a text file (NUL byte at byte offset 48)"),
    (GOOD.encode() + "0.2 0 0 0 0 0 0 1 # 90°".encode()[:-1],
     ":3: not a text file (invalid UTF-8 byte 0xc2 at byte offset 70)"),
    (GOOD.encode("utf-16"), ":1: not a text file (invalid UTF-8 byte 0xff at byte offset 0; "
                            "UTF-16 text? save it as UTF-8)"),
    (b"\x1f\x8b\x08\x00", ":1: not a text file (invalid UTF-8 byte 0x8b at byte offset 1; a "
                          "gzip file: decompress it first)"),
], ids=["invalid UTF-8", "NUL", "truncated UTF-8", "UTF-16", "gzip"])
def test_binary_input_names_file_line_and_byte_offset(tmp_path, data, message):
    p = tmp_path / "robot.tum"
    p.write_bytes(data)
    with pytest.raises(ValueError, match=re.escape(str(p) + message) + "$"):
        read_poses(p, "robot")
    with pytest.raises(ValueError, match=re.escape("r.tum" + message) + "$"):
        parse_poses(data, "tum", "robot", "r.tum")  # bytes given to the parser directly


# -------------------------------------------------------------------------------- time units
def test_nanosecond_unix_timestamps_are_refused_with_the_fix():
    text = rescaled(ROBOT, 1e9, 1.7e18)
    with pytest.raises(ValueError, match=re.escape(
            "r.tum: timestamps up to 1.7e+18 are not seconds (5.39e+10 years): they look like "
            "Unix time in nanoseconds — rescale them with time_scale=1e-09 (command line "
            "--time-scale 1e-09)")):
        parse_poses(text, "tum", "robot", "r.tum")
    s = parse_poses(text, "tum", "robot", "r.tum", time_scale=1e-9)
    ref = parse_poses(ROBOT, "tum", "robot", "r.tum")
    np.testing.assert_allclose(s.timestamps - s.timestamps[0], ref.timestamps, atol=1e-6)


def test_relative_nano_and_microsecond_timestamps_are_refused_with_the_fix():
    with pytest.raises(ValueError, match=re.escape(
            "r.tum: a median sampling period of 2e+07 s (5.56e+03 hours) is implausible: the "
            "timestamps look like nanoseconds (50 Hz) — rescale them with time_scale=1e-09")):
        parse_poses(rescaled(ROBOT, 1e9), "tum", "robot", "r.tum")
    with pytest.raises(ValueError, match=r"look like microseconds \(50 Hz\) — rescale them with "
                                         r"time_scale=1e-06"):
        parse_poses(rescaled(ROBOT, 1e6), "tum", "robot", "r.tum")
    with pytest.raises(ValueError, match=r"timestamps up to 1e\+308 are not seconds .*nor Unix "
                                         r"time in milliseconds, microseconds or nanoseconds"):
        parse_poses("0 0 0 0 0 0 0 1\n1e308 0 0 0 0 0 0 1\n", "tum", "robot", "r.tum")
    assert time_unit_hint(np.arange(10) * 0.02 + 1.7e9) is None  # Unix seconds are fine


def test_millisecond_timestamps_in_both_files_are_named_by_the_offset_search():
    robot = parse_poses(rescaled(ROBOT, 1e3), "tum", "robot", "r.tum")
    camera = parse_poses(rescaled(CAMERA, 1e3, 1e3), "tum", "camera", "c.tum")
    with pytest.raises(ValueError, match=re.escape(
            "(r.tum: its median sampling period is 20 s: if the timestamps are in milliseconds "
            "(50 Hz), rescale them with time_scale=0.001 (command line --time-scale 0.001); "
            "c.tum: its median sampling period is 67 s: if the timestamps are in milliseconds")):
        estimate_time_offset(robot, camera)


def test_seconds_against_milliseconds_is_named_by_the_alignment():
    robot = parse_poses(ROBOT, "tum", "robot", "r.tum")
    camera = parse_poses(rescaled(CAMERA, 1e3, 1e3), "tum", "camera", "c.tum")
    with pytest.raises(ValueError, match=r"c.tum: only 0 of 304 camera samples fall inside .* "
                                         r"at least 3 are needed — c.tum: its median sampling "
                                         r"period is 67 s: if the timestamps are in milliseconds"):
        align_streams(robot, camera)


def test_time_scale_overflow_is_an_error():
    with pytest.raises(ValueError, match=r"r.tum:2: timestamp is not finite after time_scale = "
                                         r"1e\+300"):
        parse_poses("0 0 0 0 0 0 0 1\n1e10 0 0 0 0 0 0 1\n", "tum", "robot", "r.tum",
                    time_scale=1e300)


# ------------------------------------------------------------------------- too few samples
def test_two_samples_are_too_few_not_a_clock_problem(tmp_path, capsys):
    camera = tmp_path / "camera.tum"
    camera.write_text("\n".join(CAMERA.splitlines()[103:105]) + "\n")
    assert main(["calibrate", "--robot", str(DATA / "example_robot.tum"), "--camera",
                 str(camera), "--out", str(tmp_path / "o")]) == 2
    assert one_error_line(capsys) == (f"{camera}: too few samples: only 2, at least 3 are "
                                      "needed (2 motions)")


def test_one_robot_sample_is_too_few():
    robot = pose_stream([np.eye(4)], [0.0], "r.tum")
    camera = pose_stream([np.eye(4)] * 3, [0.0, 0.1, 0.2], "c.tum")
    with pytest.raises(ValueError, match=r"^r.tum: too few samples: only 1, at least 2 are "
                                         r"needed \(to interpolate"):
        align_streams(robot, camera)


def test_three_noisy_poses_are_too_few_to_find_outliers():
    """2° of noise on three camera poses: this draw used to fail as "too many outliers"."""
    rng = np.random.default_rng(2)
    X_EC = make_transform(rotation_exp([0.1, -0.2, 1.5]), [0.05, -0.02, 0.07])
    X_BT = make_transform(np.eye(3), [0.6, 0.0, 0.0])
    X_BC = [make_transform(rotation_exp(v), [0.1 * k, 0.0, 0.3])
            for k, v in enumerate([[0.0, 0.0, 0.0], [0.4, 0.1, 0.0], [0.1, 0.5, 0.2]])]
    X_BE = np.array([X @ inverse(X_EC) for X in X_BC])
    noise = [make_transform(rotation_exp(np.radians(2.0) * rng.normal(size=3)), [0, 0, 0])
             for _ in range(3)]
    X_CT = np.array([N @ inverse(X) @ X_BT for N, X in zip(noise, X_BC)])
    with pytest.raises(ValueError, match=r"^too few samples to tell noise from outliers: 3 "
                                         r"aligned samples give 3 motion pairs, and 3 fail the "
                                         r"screw-angle test .* record more samples"):
        robust_hand_eye(X_BE, X_CT)


# ------------------------------------------------------------------- huge values: no warnings
HUGE_CASES = [
    ("tum", "0 0 0 0 1e308 0 0 1\n", r"r:1: quaternion \(qx qy qz qw\) = \[1e\+308, 0, 0, 1\] "
                                     r"has norm 1e\+308, not 1"),
    ("tum", "0 0 0 0 -1e308 -1e308 0 1\n", r"r:1: quaternion .* has norm 1\.41421e\+308"),
    ("tum", "0 0 0 0 1e-320 0 0 0\n", r"r:1: quaternion .* has norm 9\.99989e-321"),
    ("tum", "0 1e308 1e308 0 0 0 0 1\n", r"r:1: translation of length 1\.41421e\+308 exceeds 10"),
    ("csv-matrix", "1e308 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n",
     r"r:1: rotation block is not a rotation matrix: .* = inf > tolerance 0\.001 \(det = nan\)"),
    ("csv-matrix", "1 0 0 0 0 1 0 0 0 0 1 0 0 0 1e308 1\n",
     r"r:1: last row of a homogeneous transform must be \[0, 0, 0, 1\], got \[0, 0, 1e\+308, 1\]"),
    ("csv-matrix", "1 0 0 1e300 0 1 0 0 0 0 1 0 0 0 0 1\n", r"r:1: translation of length 1e\+300"),
]


@pytest.mark.parametrize("fmt, text, pattern", HUGE_CASES, ids=[c[2][:30] for c in HUGE_CASES])
def test_huge_and_tiny_values_give_the_error_and_no_warning(fmt, text, pattern):
    with pytest.raises(ValueError, match=pattern):
        parse_poses(text, fmt, "robot", "r")


def test_translation_scale_overflow_is_an_error():
    with pytest.raises(ValueError, match=r"^r:1: pose is not finite after scaling the "
                                         r"translation$"):
        parse_poses("0 1e200 0 0 0 0 0 1\n", "tum", "robot", "r", translation_scale=1e200,
                    max_translation=None)


# -------------------------------------------------------------- layouts that read the same
def _variants():
    base = GOOD + "0.2 -1.5e-3 2E+0 .5 0 0 0.70710678 0.70710678\n"
    yield "crlf", base.replace("\n", "\r\n")
    yield "cr", base.replace("\n", "\r")
    yield "tabs", base.replace(" ", "\t")
    yield "commas", base.replace(" ", ",")
    yield "mixed", base.replace(" ", " ,\t ", 3)
    yield "blank lines", base.replace("\n", "\n  \t \n\n")
    yield "BOM lines", "\ufeff" + base.replace("\n", "\n\ufeff\n\ufeff \n")
    yield "NBSP", base.replace(" ", "\xa0")
    yield "comments", "# header °\n" + base.replace("\n", "  # note ° é\n")
    yield "form feeds", base.replace("\n", "\n\x0c\n")
    yield "no final newline", base.rstrip("\n")
    yield "bytes", base.encode()


@pytest.mark.parametrize("name, text", list(_variants()), ids=[v[0] for v in _variants()])
def test_layout_variants_read_exactly_like_plain_text(name, text):
    ref = parse_poses(GOOD + "0.2 -1.5e-3 2E+0 .5 0 0 0.70710678 0.70710678\n", "tum", "robot")
    s = parse_poses(text, "tum", "robot")
    np.testing.assert_array_equal(s.poses, ref.poses)
    np.testing.assert_array_equal(s.timestamps, ref.timestamps)
    expected_lines = {"blank lines": (1, 4, 7), "BOM lines": (1, 4, 7), "comments": (2, 3, 4),
                      "form feeds": (1, 4, 7), "cr": (1, 2, 3)}
    assert s.lines == expected_lines.get(name, (1, 2, 3))


# ------------------------------------------------------------------------- helpful messages
@pytest.mark.parametrize("text, message", [
    ("timestamp tx ty tz qx qy qz qw\n" + GOOD,
     "r:1: tum field: 'timestamp' is not a number (a header line? comment it out with '#')"),
    ("time x y z\n" + GOOD,
     "r:1: expected 8 numbers (timestamp tx ty tz qx qy qz qw), got 4 (a header line? comment it "
     "out with '#')"),
    ("0,0 0,1 0,2 0,3 0 0 0 1\n",
     "r:1: expected 8 numbers (timestamp tx ty tz qx qy qz qw), got 12 (decimal commas? write "
     "0.5, not 0,5: commas separate fields)"),
    ("0.0;0.1;0.2;0.3;0;0;0;1\n",
     "r:1: expected 8 numbers (timestamp tx ty tz qx qy qz qw), got 1 (';' is not a separator: "
     "use spaces, tabs or commas)"),
    (GOOD + "2024-05-01T12:00:00 0 0 0 0 0 0 1\n",
     "r:3: tum field: '2024-05-01T12:00:00' is not a number (dates and clock times are not read: "
     "write seconds as a number)"),
    (GOOD + "0.2 0.1 0.2 0.3 0 0 0 1 0\n",
     "r:3: expected 8 numbers (timestamp tx ty tz qx qy qz qw), got 9"),
    (GOOD + GOOD, "r:3: timestamp 0.0 is earlier than the previous sample's 0.1 (line 2); samples "
                  "must be sorted by time — the timestamps start over: recordings concatenated?"),
    (GOOD + "0.05 0 0 0 0 0 0 1\n0.3 0 0 0 0 0 0 1\n0.2 0 0 0 0 0 0 1\n",
     "r:3: timestamp 0.05 is earlier than the previous sample's 0.1 (line 2); samples must be "
     "sorted by time (2 such places in the file)"),
], ids=["header", "short header", "decimal commas", "semicolons", "date", "9 fields",
        "concatenated", "two places"])
def test_messages_name_the_likely_cause(text, message):
    with pytest.raises(ValueError, match="^" + re.escape(message) + "$"):
        parse_poses(text, "tum", "robot", "r")


def test_ragged_poses_name_the_argument_and_source():
    with pytest.raises(ValueError, match=r"^cam\.json: poses: expected an \(N, 4, 4\) array of "
                                         r"numbers \(setting an array element with a sequence"):
        pose_stream([np.eye(4), np.eye(3)], None, "cam.json")
    with pytest.raises(ValueError, match=r"^cam\.json: timestamps: expected 2 values \(one per "
                                         r"pose\), got shape \(3,\)"):
        pose_stream([np.eye(4)] * 2, [0.0, 1.0, 2.0], "cam.json")


def test_yaml_ragged_matrix_data_names_the_line():
    text = ("%YAML:1.0\nposes:\n   - !!opencv-matrix\n      rows: 4\n      cols: 4\n"
            "      dt: d\n      data: [ 1., 0., 0., 0., 0., 1., 0., 0.,\n          0., 0., 1., 0.,"
            " 0., 0., 1. ]\n")
    with pytest.raises(ValueError, match=r"^y.yaml:7: matrix data has 15 numbers, rows × cols = "
                                         r"4 × 4 = 16$"):
        parse_poses(text, "opencv-yaml", "robot", "y.yaml")
    with pytest.raises(ValueError, match=r"^y.yaml:7: list element '' is not a number$"):
        parse_poses(text.replace("1. ]", ", 1. ]"), "opencv-yaml", "robot", "y.yaml")


# ------------------------------------------------------------------------------ line numbers
def test_line_numbers_behave_like_the_tuple_they_replace():
    s = parse_poses("# c\n" + GOOD, "tum", "robot", "r")
    assert isinstance(s.lines, LineNumbers)
    assert s.lines == (2, 3) and s.lines == [2, 3] and s.lines != (2, 4)
    assert s.lines[1] == 3 and type(s.lines[1]) is int and list(s.lines) == [2, 3]
    assert s.lines[[True, False]] == (2,) and 3 in s.lines and 4 not in s.lines
    assert np.asarray(s.lines).dtype == np.int64 and s.where(0) == "r:2"
    with pytest.raises(ValueError):
        np.asarray(s.lines)[0] = 5  # read-only


def test_quaternion_stream_round_trip_is_exact_to_rounding():
    """TUM rotations come from the unit quaternion as read, not re-projected."""
    R = rotation_exp([0.3, -1.2, 2.0])
    w, x, y, z = map(float, quat_wxyz(R))
    s = parse_poses(f"0 1 2 3 {x!r} {y!r} {z!r} {w!r}\n", "tum", "robot")
    np.testing.assert_allclose(s.poses[0, :3, :3], R, atol=1e-15)
    assert math.isclose(np.linalg.det(s.poses[0, :3, :3]), 1.0, abs_tol=1e-15)


def test_reading_twice_the_same_path_is_not_needed(tmp_path):
    """``read_poses`` accepts an ``InputFile``: one read for a file holding both streams."""
    p = Path(tmp_path / "both.yaml")
    p.write_text("%YAML:1.0\nrobot_poses:\n  - !!opencv-matrix\n    rows: 4\n    cols: 4\n"
                 "    dt: d\n    data: [ 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., "
                 "0., 1. ]\ncamera_poses:\n  - !!opencv-matrix\n    rows: 4\n    cols: 4\n"
                 "    dt: d\n    data: [ 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0.5, 0., 0.,"
                 " 0., 1. ]\n")
    raw = read_input(p)
    robot, camera = read_poses(raw, "robot"), read_poses(raw, "camera")
    assert robot.sha256 == camera.sha256 == hashlib.sha256(p.read_bytes()).hexdigest()
    assert camera.poses[0, 2, 3] == 0.5 and robot.lines == (3,) and camera.lines == (9,)


# ------------------------------------------------------------ blank lines and comments: memory
@pytest.mark.parametrize("line", [b"\n", b"# a comment\n", b" \t\r\n"])
def test_blank_lines_and_comments_cost_memory_bounded_by_the_file(tmp_path, line):
    # 200 MiB of blank lines once asked for 25 GiB (room for a pose per line); 16 MiB here
    import tracemalloc
    path = tmp_path / "robot.tum"
    size = 16 << 20
    path.write_bytes(line * (size // len(line)) + GOOD.encode())
    tracemalloc.start()
    try:
        stream = read_poses(path, "robot", "tum")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(stream) == 2 and stream.lines[0] == size // len(line) + 1
    assert peak < size + 100e6, f"{peak / 1e6:.0f} MB to read {size >> 20} MiB"


@pytest.mark.parametrize("seed", [0, 1])
def test_many_poses_among_blank_lines_and_comments_read_exactly(seed):
    # more poses than the reader first makes room for (it grows), among generated noise lines
    rng = np.random.default_rng(seed)
    n = 70_000 + int(rng.integers(0, 20_000))
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    xyz = rng.uniform(-1, 1, (n, 3))
    rows = [f"{k * 0.01:.2f} {x:.6f} {y:.6f} {z:.6f} {a:.9f} {b:.9f} {c:.9f} {d:.9f}"
            for k, ((x, y, z), (a, b, c, d)) in enumerate(zip(xyz, q))]
    noise = ["", "# comment", "   ", "#"]
    out, numbers = [], []
    for row in rows:
        for _ in range(int(rng.integers(0, 3))):
            out.append(noise[int(rng.integers(0, len(noise)))])
        out.append(row + (" # end" if rng.random() < 0.1 else ""))
        numbers.append(len(out))
    stream = parse_poses("\n".join(out) + "\n", "tum", "robot")
    plain = parse_poses("\n".join(rows) + "\n", "tum", "robot")
    assert len(stream) == n and list(stream.lines) == numbers
    assert np.array_equal(stream.poses, plain.poses)
    assert np.array_equal(stream.timestamps, plain.timestamps)


@pytest.mark.parametrize("seed", range(4))
def test_a_sparse_stream_in_seconds_gets_no_unit_hint(seed):
    # one camera pose every 1–3 s beside a 50 Hz robot over the same span: both in seconds
    from handeye_drake.calibration.align import _units_hint
    rng = np.random.default_rng(seed)
    period = float(rng.uniform(1.0, 3.0))
    t_r = np.arange(0, 60, 0.02)
    t_c = np.arange(0.5, 59, period)
    robot = pose_stream(np.tile(np.eye(4), (len(t_r), 1, 1)), t_r, "robot")
    camera = pose_stream(np.tile(np.eye(4), (len(t_c), 1, 1)), t_c, "camera")
    assert _units_hint(robot, camera) == ""
    # the same camera stamped in milliseconds still gets its hint
    hint = _units_hint(robot, pose_stream(camera.poses, 1000 * t_c, "camera"))
    assert hint.startswith("camera: its median sampling period is") and "--time-scale" in hint

"""Pose files of every table format read the same whatever their line length: the shortest
lines the format allows (one-character numbers, one space), and long ones (17-digit numbers,
runs of spaces and tabs), with and without timestamps, many more lines than the readers' first
guess of the line count. Each pose is checked against scipy's rotation of the written numbers,
not against the reader's own output."""

import math
import zlib

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handeye_drake.recorded.formats import read_poses

N = 40        # lines: well above the ≥ 32 bytes a line the reader once assumed


def _rows(rng, n):
    """n poses as (t, translation (3,), rotation vector (3,)) with small integer parts, so that
    the short form can write them with one character a number."""
    out = []
    for k in range(n):
        out.append((k + 1, rng.integers(0, 6, 3).astype(float),
                    rng.integers(-1, 2, 3).astype(float)))
    return out


def _short(x):
    return f"{x:.0f}" if float(x).is_integer() and 0 <= x <= 9 else repr(float(x))


def _long(x):
    return f"{x:.17g}"


def _text(fmt, rows, form, stamped):
    num = _short if form == "short" else _long
    sep = " " if form == "short" else " \t  "
    lines = []
    for t, p, r in rows:
        R = Rotation.from_rotvec(r)
        if fmt == "tum":
            q = R.as_quat()     # x y z w
            vals = [t, *p, *q]
        elif fmt == "csv-matrix":
            X = np.eye(4)
            X[:3, :3], X[:3, 3] = R.as_matrix(), p
            vals = ([t] if stamped else []) + list(X.ravel())
        elif fmt == "csv-rotvec":
            vals = ([t] if stamped else []) + [*p, *r]
        else:
            vals = ([t] if stamped else []) + [*p, *R.as_euler("xyz")]
        lines.append(sep.join(num(v) for v in vals))
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("stamped", [False, True])
@pytest.mark.parametrize("form", ["short", "long"])
@pytest.mark.parametrize("fmt", ["tum", "csv-matrix", "csv-rotvec", "csv-euler:xyz:rad"])
def test_short_and_long_lines_of_every_format(tmp_path, fmt, form, stamped):
    if fmt == "tum" and not stamped:
        pytest.skip("TUM lines always carry a timestamp")
    rng = np.random.default_rng(zlib.crc32(f"{fmt}{form}{stamped}".encode()))
    rows = _rows(rng, N)
    if form == "short" and fmt in ("tum", "csv-matrix", "csv-euler:xyz:rad"):
        # Quaternions, matrices and Euler angles of integer rotation vectors are not
        # one-character numbers: use quarter turns about z (exact 0, ±1 entries; ±π/2 angles
        # written in full) and identities.
        rows = [(t, p, np.array([0.0, 0.0, (k % 2) * math.pi / 2])) for k, (t, p, _) in
                enumerate(rows)]
    text = _text(fmt.split(":")[0], rows, form, stamped)
    if form == "short" and fmt in ("csv-rotvec",):
        assert len(text) / N < 24         # really short: well under the old assumption
    path = tmp_path / "poses.txt"
    path.write_text(text)
    s = read_poses(path, "robot", fmt)
    assert len(s) == N
    for k, (t, p, r) in enumerate(rows):
        np.testing.assert_allclose(s.poses[k][:3, 3], p, atol=1e-12)
        np.testing.assert_allclose(s.poses[k][:3, :3], Rotation.from_rotvec(r).as_matrix(),
                                   atol=1e-6 if form == "short" else 1e-12)
        np.testing.assert_allclose(s.poses[k][3], [0, 0, 0, 1])
    if stamped:
        np.testing.assert_allclose(s.timestamps, [r[0] for r in rows])
    else:
        assert s.timestamps is None
    assert list(s.lines) == list(range(1, N + 1))


@pytest.mark.parametrize("fmt,line", [("csv-rotvec", "0 0 0.5 0 0 1"),
                                      ("csv-euler:xyz:rad", "0 0 0.5 0 0 1"),
                                      ("csv-euler:xyz:deg", "0 0 0.5 0 0 90")])
def test_the_issue_file_of_twenty_short_lines(tmp_path, fmt, line):
    path = tmp_path / "short.csv"
    path.write_text("".join(f"{k} {line}\n" for k in range(20)))
    s = read_poses(path, "robot", fmt)
    assert len(s) == 20 and np.allclose(s.timestamps, np.arange(20))
    angle = math.radians(90) if fmt.endswith("deg") else 1.0
    np.testing.assert_allclose(s.poses[:, :3, :3],
                               np.broadcast_to(Rotation.from_rotvec([0, 0, angle]).as_matrix(),
                                               (20, 3, 3)), atol=1e-12)
    np.testing.assert_allclose(s.poses[:, :3, 3], np.broadcast_to([0, 0, 0.5], (20, 3)))

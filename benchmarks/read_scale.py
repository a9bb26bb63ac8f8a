"""Speed and memory of the pose-file readers against numpy's own text parsing of the same text.

    python benchmarks/read_scale.py [--lines 10000 100000 1000000] [--formats tum csv yaml]

For each format and size (lines of the file), a file is generated (TUM: ``t tx ty tz qx qy qz
qw``; CSV: 17 numbers, timestamp + row-major matrix; YAML: lines/6 poses as ``!!opencv-matrix``
nodes of 5 lines each, and a ``timestamps`` flow list of one number a line: a list spanning
lines/6 lines, the case that was quadratic) and, in a fresh process, read with ``read_poses``
(read once + hash + parse + validate), then parsed by ``np.fromstring(text, sep=" ")``
(comments, and for YAML every non-numeric character, replaced by spaces beforehand) and
``np.loadtxt`` — references measured in the same run, so the ratios do not depend on the
machine's load. Prints time per line, MB/s, the ratios, and the reader's peak resident memory
above the interpreter's (``VmHWM``), in MB and bytes per line.
"""

from __future__ import annotations

import argparse
import io
import json
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation


def make_text(fmt: str, n: int) -> str:
    rng = np.random.default_rng(0)
    t = np.arange(n) * 0.02
    p = rng.uniform(-1, 1, (n, 3))
    if fmt == "yaml":
        m = n // 6
        return ("%YAML:1.0\ntimestamps: [ " + ",\n    ".join(f"{v:.6f}" for v in t[:m])
                + " ]\nposes:\n" + "".join(
                    "  - !!opencv-matrix\n    rows: 4\n    cols: 4\n    dt: d\n    data: [ 1., "
                    f"0., 0., {p[k, 0]:.6f}, 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1. ]\n"
                    for k in range(m)))
    q = Rotation.random(n, random_state=1).as_quat()
    if fmt == "tum":
        body = "\n".join(f"{t[k]:.6f} {p[k, 0]:.6f} {p[k, 1]:.6f} {p[k, 2]:.6f} {q[k, 0]:.8f} "
                         f"{q[k, 1]:.8f} {q[k, 2]:.8f} {q[k, 3]:.8f}" for k in range(n))
        return "# timestamp tx ty tz qx qy qz qw\n" + body + "\n"
    R = Rotation.from_quat(q).as_matrix()
    body = "\n".join(f"{t[k]:.6f}," + ",".join(f"{v:.9f}" for v in (*R[k, 0], p[k, 0],
                                                                     *R[k, 1], p[k, 1],
                                                                     *R[k, 2], p[k, 2]))
                     + ",0,0,0,1" for k in range(n))
    return "# t, r00 r01 r02 tx r10 ... 0 0 0 1\n" + body + "\n"


def _peak_rss_kb() -> int:
    """VmHWM: this process's peak resident set (ru_maxrss would include the parent's, as Linux
    keeps it across exec)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def child(path: str, fmt: str, n: int) -> dict:
    """Runs in a fresh interpreter: ours first (for a clean peak RSS), then the references."""
    from handeye_drake.recorded.formats import read_poses
    base_rss = _peak_rss_kb()
    t0 = time.perf_counter()
    if fmt == "yaml":
        s = read_poses(path, "robot", "opencv-yaml")
        assert len(s) == n // 6
    else:
        s = read_poses(path, "robot", "tum" if fmt == "tum" else "csv-matrix")
        assert len(s) == n
    ours = time.perf_counter() - t0
    peak = _peak_rss_kb() - base_rss
    del s
    data = Path(path).read_bytes()
    t0 = time.perf_counter()
    if fmt == "yaml":
        ref = np.fromstring(re.sub(rb"[^0-9.\-]+|(?<![0-9])[.\-]|[.\-](?![0-9])", b" ",
                                   data[9:]), sep=" ")
        assert ref.size == (n // 6) * 19
    else:
        ref = np.fromstring(re.sub(rb"#[^\n]*", b"", data).replace(b",", b" "), sep=" ")
        assert ref.size == n * {"tum": 8, "csv": 17}[fmt]
    fromstring = time.perf_counter() - t0
    loadtxt = None
    if fmt != "yaml":
        t0 = time.perf_counter()
        np.loadtxt(io.BytesIO(data), delimiter="," if fmt == "csv" else None)
        loadtxt = time.perf_counter() - t0
    return {"ours_s": ours, "fromstring_s": fromstring, "loadtxt_s": loadtxt,
            "peak_mb": peak / 1024, "bytes": len(data)}


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        print(json.dumps(child(sys.argv[2], sys.argv[3], int(sys.argv[4]))))
        sys.exit(0)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lines", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    parser.add_argument("--formats", nargs="+", default=["tum", "csv", "yaml"])
    a = parser.parse_args()
    print("| format | lines | MB | ours µs/line | ours MB/s | ÷ np.fromstring | ÷ np.loadtxt | "
          "peak MB above interpreter (bytes/line) |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as d:
        for fmt in a.formats:
            for n in a.lines:
                path = Path(d) / f"x.{'yaml' if fmt == 'yaml' else 'tum' if fmt == 'tum' else 'csv'}"
                path.write_text(make_text(fmt, n))
                out = subprocess.run([sys.executable, __file__, "--child", str(path), fmt,
                                      str(n)], capture_output=True, text=True, check=True)
                r = json.loads(out.stdout)
                lines = path.read_text().count("\n")
                mb = r["bytes"] / 1e6
                lt = f"{r['ours_s'] / r['loadtxt_s']:.2f}" if r["loadtxt_s"] else "–"
                print(f"| {fmt} | {lines} | {mb:.1f} | {1e6 * r['ours_s'] / lines:.2f} | "
                      f"{mb / r['ours_s']:.1f} | {r['ours_s'] / r['fromstring_s']:.2f} | {lt} | "
                      f"{r['peak_mb']:.0f} ({r['peak_mb'] * 2**20 / lines:.0f}) |", flush=True)

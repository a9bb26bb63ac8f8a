"""Adversarial inputs for ``handeye-drake calibrate``: what each one gives, in one table.

    python benchmarks/reading_adversarial.py [--only SUBSTRING] [--timeout 120]

Each case writes a robot and/or a camera file (derived from the shipped example recording, or
special files: devices, a FIFO, a process substitution, big generated files) and runs
``python -W error -m handeye_drake.apps.cli calibrate`` on them (so any warning would surface as a
traceback), with a timeout. It prints, per case: the exit code, the wall time, whether stderr
holds a traceback, and the first line of stderr (or the X_EC error against the truth when the
command succeeds). Big inputs (10⁶ lines) live here, not in the tests.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from handeye_drake.recorded.example import data_dir

DATA = data_dir()
ROBOT = (DATA / "example_robot.tum").read_text()
CAMERA = (DATA / "example_camera.tum").read_text()
TRUTH = json.loads((DATA / "example_truth.json").read_text())


def data_lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln and not ln.startswith("#")]


def rescale_time(text: str, factor: float, offset: float = 0.0, fmt: str = "{:.0f}") -> str:
    out = []
    for ln in text.splitlines():
        if ln.startswith("#") or not ln:
            out.append(ln)
            continue
        t, rest = ln.split(" ", 1)
        out.append(fmt.format(float(t) * factor + offset) + " " + rest)
    return "\n".join(out) + "\n"


def edit_line(text: str, k: int, fn) -> str:
    """Applies fn to the k-th data line (0-based)."""
    lines = text.splitlines()
    idx = [i for i, ln in enumerate(lines) if ln and not ln.startswith("#")]
    lines[idx[k]] = fn(lines[idx[k]])
    return "\n".join(lines) + "\n"


def big_robot(n: int) -> str:
    """n robot lines at 50 Hz (the example's motion): the benchmark generator."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from calibrate_scale import ROBOT_RATE, _write_tum, camera_poses
    from handeye_drake.recorded.example import TRUE_X_EC
    t = np.arange(n) / ROBOT_RATE
    d = Path(tempfile.mkdtemp())
    _write_tum(d / "r.tum", [], t, camera_poses(t) @ np.linalg.inv(TRUE_X_EC))
    text = (d / "r.tum").read_text()
    shutil.rmtree(d)
    return text


def cases():
    two = "\n".join(data_lines(CAMERA)[100:102]) + "\n"
    three = "\n".join(data_lines(CAMERA)[100:109:4]) + "\n"
    yield "two camera samples", {"camera": two}
    yield "three camera samples 0.27 s apart (noise 0.1°)", {"camera": three}
    yield "nanosecond Unix stamps in both files", {
        "robot": rescale_time(ROBOT, 1e9, 1.7e18), "camera": rescale_time(CAMERA, 1e9, 1.7e18)}
    yield "nanosecond stamps from 0 in both files", {
        "robot": rescale_time(ROBOT, 1e9), "camera": rescale_time(CAMERA, 1e9, 1e9)}
    yield "microsecond stamps from 0 in both files", {
        "robot": rescale_time(ROBOT, 1e6), "camera": rescale_time(CAMERA, 1e6, 1e6)}
    yield "millisecond stamps from 0 in both files", {
        "robot": rescale_time(ROBOT, 1e3), "camera": rescale_time(CAMERA, 1e3, 1e3)}
    yield "robot in seconds, camera in milliseconds", {
        "camera": rescale_time(CAMERA, 1e3, 1e3)}
    yield "nanosecond stamps, --time-scale 1e-9", {
        "robot": rescale_time(ROBOT, 1e9, 1.7e18), "camera": rescale_time(CAMERA, 1e9, 1.7e18),
        "args": ["--time-scale", "1e-9"]}
    yield "quaternion component 1e308", {
        "camera": edit_line(CAMERA, 5, lambda ln: " ".join(ln.split()[:4] + ["1e308"]
                                                           + ln.split()[5:]))}
    yield "translation 1e308", {
        "robot": edit_line(ROBOT, 7, lambda ln: " ".join(ln.split()[:1] + ["1e308"]
                                                         + ln.split()[2:]))}
    yield "timestamp 1e308 (last line)", {
        "robot": edit_line(ROBOT, -1, lambda ln: "1e308 " + ln.split(" ", 1)[1])}
    yield "timestamp -1e308 (first line)", {
        "robot": edit_line(ROBOT, 0, lambda ln: "-1e308 " + ln.split(" ", 1)[1])}
    yield "translation 5e-324 (denormal)", {
        "robot": edit_line(ROBOT, 7, lambda ln: " ".join(ln.split()[:1] + ["5e-324"]
                                                         + ln.split()[2:]))}
    yield "translation 1e200 with --translation-scale 1e200", {
        "robot": edit_line(ROBOT, 7, lambda ln: " ".join(ln.split()[:1] + ["1e200"]
                                                         + ln.split()[2:])),
        "args": ["--translation-scale", "1e200"]}
    yield "CRLF line ends", {"robot": ROBOT.replace("\n", "\r\n"),
                             "camera": CAMERA.replace("\n", "\r\n")}
    yield "old Mac CR line ends", {"robot": ROBOT.replace("\n", "\r")}
    yield "tabs and commas mixed", {
        "robot": ROBOT.replace(" ", "\t", 2).replace(" ", ", ")}
    yield "whitespace-only and BOM-only lines, BOM at start", {
        "robot": "\ufeff" + ROBOT.replace("\n", "\n   \t \n\ufeff\n", 5)}
    yield "two files concatenated (BOM mid-file, timestamps restart)", {
        "robot": ROBOT + "\ufeff" + ROBOT}
    yield "scientific notation everywhere", {
        "robot": rescale_time(ROBOT, 1.0, 0.0, "{:.6e}")}
    yield "header line without '#'", {
        "robot": "timestamp tx ty tz qx qy qz qw\n" + ROBOT}
    yield "decimal commas", {"robot": "\n".join(
        ln.replace(".", ",") if not ln.startswith("#") else ln
        for ln in ROBOT.splitlines()) + "\n"}
    yield "semicolon separators", {"robot": "\n".join(
        ln.replace(" ", ";") if not ln.startswith("#") else ln
        for ln in ROBOT.splitlines()) + "\n"}
    yield "ISO dates as timestamps", {
        "robot": edit_line(ROBOT, 0, lambda ln: "2024-05-01T12:00:00 " + ln.split(" ", 1)[1])}
    yield "NBSP separators (Unicode spaces)", {"robot": ROBOT.replace(" ", "\xa0")}
    yield "Latin-1 degree sign in a comment", {
        "robot": b"# 90\xb0 about z\n" + ROBOT.encode()}
    yield "UTF-16 file", {"robot": ROBOT.encode("utf-16")}
    yield "gzip file", {"robot": __import__("gzip").compress(ROBOT.encode())}
    yield "PNG image", {"robot": b"\x89PNG\r\n\x1a\n" + bytes(range(256))}
    yield "/dev/zero as robot", {"robot": Path("/dev/zero"), "args": ["--format", "tum"]}
    yield "/dev/urandom as robot", {"robot": Path("/dev/urandom"), "args": ["--format", "tum"]}
    yield "/dev/null as robot", {"robot": Path("/dev/null"), "args": ["--format", "tum"]}
    yield "a directory as robot", {"robot": Path(tempfile.gettempdir())}
    yield "FIFO as camera", {"camera": "fifo"}
    yield "process substitution as camera", {"camera": "procsub"}
    yield "one decreasing timestamp in 10⁶ lines", {"robot": "big:decrease"}
    yield "one duplicate timestamp in 10⁶ lines", {"robot": "big:duplicate"}
    yield "7 fields on one line of 10⁶", {"robot": "big:seven"}
    yield "NaN on the last of 10⁶ lines", {"robot": "big:nan"}
    yield "10⁶ robot lines (the example camera)", {"robot": "big:"}


def _big(kind: str, n: int = 10**6) -> str:
    text = _big.cache if getattr(_big, "cache", None) else big_robot(n)
    _big.cache = text
    if not kind:
        return text
    lines = text.splitlines()
    k = n // 2 + 12345
    if kind == "decrease":
        t0, rest = lines[k].split(" ", 1)
        lines[k] = f"{float(t0) - 0.05:.6f} {rest}"
    elif kind == "duplicate":
        lines[k] = lines[k - 1].split(" ", 1)[0] + " " + lines[k].split(" ", 1)[1]
    elif kind == "seven":
        lines[k] = " ".join(lines[k].split()[:7])
    elif kind == "nan":
        lines[-1] = " ".join(lines[-1].split()[:3] + ["nan"] + lines[-1].split()[4:])
    return "\n".join(lines) + "\n"


def run_case(name, spec, tmp: Path, timeout: float) -> dict:
    d = tmp / re.sub(r"\W+", "_", name)[:40]
    d.mkdir(parents=True, exist_ok=True)
    paths, writers, shell = {}, [], False
    for stream, default in (("robot", ROBOT), ("camera", CAMERA)):
        v = spec.get(stream, default)
        if isinstance(v, Path):
            paths[stream] = str(v)
            continue
        if isinstance(v, str) and v.startswith("big:"):
            v = _big(v[4:])
        if v in ("fifo", "procsub"):
            src = d / f"{stream}_src.tum"
            src.write_text(default)
            if v == "fifo":
                fifo = d / f"{stream}.fifo"
                os.mkfifo(fifo)

                def feed(fifo=fifo, src=src):
                    with open(fifo, "wb") as f:
                        f.write(src.read_bytes())
                writers.append(threading.Thread(target=feed, daemon=True))
                paths[stream] = str(fifo)
            else:
                paths[stream] = f"<(cat {src})"
                shell = True
            spec.setdefault("expect_sha", {})[stream] = hashlib.sha256(
                src.read_bytes()).hexdigest()
            continue
        p = d / f"{stream}.tum"
        p.write_bytes(v if isinstance(v, bytes) else v.encode("utf-8"))
        paths[stream] = str(p)
    out = d / "out"
    args = ["calibrate", "--robot", paths["robot"], "--camera", paths["camera"], "--out",
            str(out), *spec.get("args", [])]
    if any(a.endswith(".fifo") or a.startswith("<(") for a in args):
        args += ["--format", "tum"] if "--format" not in args else []
    cmd = [sys.executable, "-W", "error", "-m", "handeye_drake.apps.cli", *args]
    for w in writers:
        w.start()
    t0 = time.perf_counter()
    try:
        if shell:
            p = subprocess.run(["bash", "-c", " ".join(cmd)], capture_output=True, text=True,
                               timeout=timeout)
        else:
            p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        rc, err = p.returncode, p.stderr
    except subprocess.TimeoutExpired:
        rc, err = "timeout", ""
    wall = time.perf_counter() - t0
    res = {"case": name, "rc": rc, "wall_s": round(wall, 1), "traceback": "Traceback" in err,
           "stderr": err.strip().splitlines()[0][:1200] if err.strip() else ""}
    if rc == 0:
        cal = json.loads((out / "calibration.json").read_text())
        X, T = np.array(cal["X_EC"]["matrix"]), np.array(TRUTH["X_EC"])
        c = (np.trace(T[:3, :3].T @ X[:3, :3]) - 1) / 2
        res["result"] = (f"X_EC off by {np.degrees(np.arccos(np.clip(c, -1, 1))):.3f}° / "
                         f"{1000 * np.linalg.norm(X[:3, 3] - T[:3, 3]):.2f} mm, offset "
                         f"{cal['time_offset']['value_s']:.4g} s ({cal['time_offset']['mode']})"
                         + (f", warnings: {cal['warnings']}" if cal["warnings"] else ""))
        for stream, sha in spec.get("expect_sha", {}).items():
            res["result"] += (f"; {stream} sha256 "
                              f"{'matches' if cal['inputs'][stream]['sha256'] == sha else 'WRONG'}")
    return res


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="")
    parser.add_argument("--timeout", type=float, default=120.0)
    a = parser.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="handeye_adversarial_"))
    try:
        print("| case | rc | wall (s) | what it gives |")
        print("|---|---|---|---|")
        for name, spec in cases():
            if a.only not in name:
                continue
            r = run_case(name, spec, tmp, a.timeout)
            what = r.get("result") or r["stderr"].replace("handeye-drake: error: ", "")
            what = what.replace(str(tmp), "DIR").replace("|", "\\|")
            tb = " **traceback**" if r["traceback"] else ""
            print(f"| {name} | {r['rc']} | {r['wall_s']} | {what}{tb} |", flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

"""How fast ``handeye-drake session --follow`` keeps up with a driver writing samples at a high
rate: a thread appends ``--seconds`` of sample lines at ``--rate`` Hz to a file while the session
follows it (the command's own code, in this process); measured: the time from the first line to
the session's end, against the time the input took to write (ratio 1: it keeps up).

Reference, in the same run: the same samples fitted one by one (``CalibrationSession.add`` with
a fit whenever one is due, what the session did before it drained arrivals), timed alone.

Samples: the simulated cell of ``session --simulate`` (``apps.session_simulate``), its true
X_CT with 0.05° / 0.3 mm noise per axis and the robot's X_BE with 0.02° / 0.1 mm, views 0.3–0.6 m
from the board. The σ target is unreachable (0.001° / 0.01 mm with --robot-accuracy 0,0), so
the session runs to the end of the input.

    .venv/bin/python benchmarks/session_follow_rate.py [--rate 20 --seconds 10]
"""
import argparse
import contextlib
import io
import math
import os
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from handeye_drake.apps.cli import main
from handeye_drake.apps.session_simulate import SimulatedCell, sample_line
from handeye_drake.calibration import CalibrationOptions, CalibrationSession
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp


def _look(z, roll):
    z = z / np.linalg.norm(z)
    a = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
    x = np.cross(a, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z]) @ rotation_exp(np.array([0, 0, roll]))


def samples(n, seed=0):
    cell = SimulatedCell()
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        d = rng.uniform(0.3, 0.6)
        tilt = math.acos(rng.uniform(math.cos(0.6), 1))
        az = rng.uniform(0, 2 * math.pi)
        dirT = np.array([math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az),
                         math.cos(tilt)])
        z = cell.X_BT[:3, :3] @ dirT
        X_BC = make_transform(_look(z, rng.uniform(-3, 3)), cell.X_BT[:3, 3] - d * z)
        X_BE = X_BC @ inverse(cell.X_EC)
        X_CT = inverse(X_BE @ cell.X_EC) @ cell.X_BT
        X_BE = make_transform(rotation_exp(rng.normal(0, math.radians(0.02), 3)) @ X_BE[:3, :3],
                              X_BE[:3, 3] + rng.normal(0, 1e-4, 3))
        X_CT = make_transform(rotation_exp(rng.normal(0, math.radians(0.05), 3)) @ X_CT[:3, :3],
                              X_CT[:3, 3] + rng.normal(0, 3e-4, 3))
        out.append((X_BE, X_CT))
    return out


def main_():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rate", type=float, default=20.0, help="lines per second (default 20)")
    ap.add_argument("--seconds", type=float, default=10.0, help="input length (default 10)")
    args = ap.parse_args()
    n = int(round(args.rate * args.seconds))
    data = samples(n)
    cell = SimulatedCell()
    options = CalibrationOptions(robot_accuracy_deg=0, robot_accuracy_mm=0)

    # Reference: one by one.
    t0 = time.perf_counter()
    s = CalibrationSession(0.001, 0.01, options, hand_eye_guess=cell.X_EC_guess)
    for a, b in data:
        s.add(a, b)
    one_by_one = time.perf_counter() - t0

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "samples.txt"
        path.write_text("")
        started = threading.Event()

        def driver():
            with path.open("a") as fh:
                t_start = time.perf_counter()
                started.set()
                for k, (a, b) in enumerate(data):
                    delay = t_start + k / args.rate - time.perf_counter()
                    if delay > 0:
                        time.sleep(delay)
                    fh.write(sample_line(a, b) + "\n")
                    fh.flush()

        q = cell.X_EC_guess
        from handeye_drake.estimation.se3 import quat_wxyz
        w = quat_wxyz(q[:3, :3])
        guess = ",".join(f"{v:.6f}" for v in [*q[:3, 3], w[1], w[2], w[3], w[0]])
        thread = threading.Thread(target=driver)
        thread.start()
        started.wait()
        t0 = time.perf_counter()
        out = io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
            main(["session", "--samples", str(path), "--follow", "--idle-timeout", "1.5",
                  "--target-sigma", "0.001,0.01", "--robot-accuracy", "0,0",
                  f"--hand-eye={guess}", "--out", str(Path(tmp) / "out")])
        followed = time.perf_counter() - t0 - 1.5      # less the idle timeout that ends it
        thread.join()
        fits = sum(1 for line in out.getvalue().splitlines() if line.startswith("["))
    load = os.getloadavg()
    print(f"{n} samples written at {args.rate:g} Hz over {args.seconds:g} s")
    print(f"session --follow: done {followed:.1f} s after the first line "
          f"({followed / args.seconds:.2f}× the input's duration; {fits} output lines, "
          "each a fit of the samples that had arrived)")
    print(f"reference, one fit per sample when due, alone: {one_by_one:.1f} s "
          f"({one_by_one / args.seconds:.2f}× the input's duration)")
    print(f"load average {load[0]:.2f}, {load[1]:.2f}, {load[2]:.2f}")


if __name__ == "__main__":
    main_()

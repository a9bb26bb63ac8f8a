"""The target's scale as an unknown of the image answer (docs/target-scale.md): verdict, scale found
and the answer's error against its σ, for a print off by a factor and for a robot whose
translations are scaled by it, eye-in-hand and eye-to-hand, default settings
(``--refine-intrinsics auto``).

    python benchmarks/target_scale.py [--factors 1.003 1.005 1.01 1.02 1.05] [--seed 7] [--n 14]
        [--modes eye_in_hand eye_to_hand rendered]

One synthesized image set per mode (``tests/image_synth.py``: 640×480, the board 0.35–0.5 m from
the camera; eye-to-hand the camera 1.27 m from the robot base). "print f": the board's true sizes
f× those declared (--target divided by f); "robot f": the robot file's translations f× true.
"rendered": the shipped Drake-rendered set (``handeye_drake/data/example_images``, eye-in-hand,
UR5e, 14 images). Each row: verdict and reason codes, the scale found ± σ, the translation error
of the answer and its σ (norms, mm), error/σ, and the error of each reading's answer (mm).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from handeye_drake.apps.cli import main  # noqa: E402
from tests.image_synth import synthesize  # noqa: E402

SPEC = "charuco:7x5:{:.9g}:{:.9g}:DICT_5X5_100"


def run_case(root: Path, folder: Path, truth: dict, mode: str, reading: str, factor: float):
    spec, robot = truth["spec"], folder / "robot_poses.tum"
    if reading == "print":
        spec = SPEC.format(0.04 / factor, 0.03 / factor)
    elif factor != 1.0:
        out = []
        for line in robot.read_text().splitlines():
            f = line.split()
            if not line.startswith("#"):
                f[1:4] = [f"{float(v) * factor:.12f}" for v in f[1:4]]
            out.append(" ".join(f))
        robot = root / f"robot_{mode}_{factor}.tum"
        robot.write_text("\n".join(out) + "\n")
    out = root / f"out_{mode}_{reading}_{factor}"
    if mode == "rendered":
        mode = "eye_in_hand"
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(["calibrate", "--images", str(folder), "--robot", str(robot), "--target",
                     spec, "--intrinsics", truth["intrinsics"], "--mode",
                     mode.replace("_", "-"), "--out", str(out)])
    doc = json.loads((out / "calibration.json").read_text())
    key = "X_EC" if mode == "eye_in_hand" else "X_BC"
    t_true = truth["X_hand"][:3, 3]
    X = np.array(doc[key]["matrix"])
    err = np.linalg.norm(X[:3, 3] - t_true)
    sigma = np.linalg.norm(doc[key]["std"]["translation_m"])
    s = doc["corner_level"]["scale"]
    readings = s.get("readings") or {}
    each = {r: np.linalg.norm(np.array(v[key])[:3, 3] - t_true)
            for r, v in readings.items() if isinstance(v, dict) and key in v}
    return {"code": code, "status": doc["verdict"]["status"],
            "reasons": [r["code"] for r in doc["verdict"]["reasons"]],
            "factor": s.get("factor"), "std": s.get("std"), "err_mm": 1000 * err,
            "sigma_mm": 1000 * sigma, "each_mm": {k: 1000 * v for k, v in each.items()},
            "model": doc["intrinsics"]["refined"]}


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--factors", type=float, nargs="+", default=[1.003, 1.005, 1.01, 1.02, 1.05])
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--n", type=int, default=14)
    p.add_argument("--modes", nargs="+", default=["eye_in_hand", "eye_to_hand"])
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        print(f"{'mode':12s} {'reading':8s} {'true':>6s}  {'verdict':7s} {'reasons':22s} "
              f"{'scale ± σ':>20s} {'err mm':>8s} {'σ mm':>8s} {'err/σ':>6s}  each reading's "
              "error (mm)")
        for mode in a.modes:
            if mode == "rendered":
                from handeye_drake.recorded.example import data_dir
                folder = data_dir() / "example_images"
                t = json.loads((folder / "truth.json").read_text())
                truth = {"X_hand": np.array(t["X_EC"]), "spec": t["target"],
                         "intrinsics": str(folder / "intrinsics.yaml")}
            else:
                folder = root / mode
                truth = synthesize(folder, mode, n=a.n, seed=a.seed)
            for factor in [1.0] + a.factors:
                for reading in (("print",) if factor == 1.0 else ("print", "robot")):
                    r = run_case(root, folder, truth, mode, reading, factor)
                    scale = (f"{r['factor']:.5f} ± {r['std']:.5f}" if r["factor"] is not None
                             else "-")
                    each = " ".join(f"{k} {v:.3f}" for k, v in r["each_mm"].items())
                    print(f"{mode:12s} {reading:8s} {factor:6.3f}  {r['status']:7s} "
                          f"{','.join(r['reasons']) or '-':22s} {scale:>20s} "
                          f"{r['err_mm']:8.3f} {r['sigma_mm']:8.3f} "
                          f"{r['err_mm'] / r['sigma_mm']:6.2f}  {each}", flush=True)

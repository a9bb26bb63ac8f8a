"""Multi-camera rig: the checks of ``tests/calibration/test_rig.py`` on other seeds.

    OPENBLAS_NUM_THREADS=1 nice python benchmarks/rig_seeds.py [--seeds 0 1 2 4] [--images 8 12]
        [--refine none auto] [--checks three two blind swapped knocked slipped focal bag]

The test renders one cell (seed 3, 8 images) and checks it; this script renders the same cell
(``recorded.example_rig.generate_example_rig``: ``wrist`` and ``wrist2`` on the hand, ``cell``,
``knocked`` (a cell camera moved 1° / 8 mm from image N/2 on) and ``slipped`` (a hand camera moved
as much) — anti-aliasing 2) at each seed and number of images, and runs the same checks with
each ``--refine-intrinsics``:

- three: wrist + wrist2 + cell — verdict OK/WARN, each camera NEES < χ²(6) 0.999 quantile and σ
  not vacuous (≤ 1 mm hand, ≤ 4 mm cell), X_wrist_wrist2 NEES and its σ below wrist's, the board
  within 1 mm, the two hand cameras agree (χ² under the 10⁻⁴ point);
- two: wrist2 + cell, as above;
- blind: wrist + cell + a camera of blank images: FAIL naming it, the others within σ;
- swapped: wrist2's and cell's folders swapped: cell FAILs ``fixed_view_moves`` "swapped",
  wrist2 FAILs, wrist within σ;
- knocked / slipped: FAIL ``camera_moved`` naming the camera and the images N/2−1 and N/2,
  wrist not FAIL (and within σ);
- focal: wrist2 given a focal length 3 % long: with ``none`` FAIL ``intrinsics`` naming it, with
  ``auto`` WARN ``intrinsics`` naming it (the refined ones used, wrist2 within σ); wrist and cell
  within σ;
- bag: wrist + cell written as a bag (camera clock 35 ms late) through the command line: within
  σ and the offset within 10 ms.

Printed: the time to render each cell and to run each row, then a table (one row per seed,
number of images and refine mode; ``ok`` or ``FAIL`` per check; the largest NEES of an answer
that must be within σ, naming it, and the largest agreement χ² of a good rig's hand camera) and
every failing check's details.
"""
import argparse
import contextlib
import io
import json
import math
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from scipy.stats import chi2

from handeye_drake.calibration.api import CalibrationOptions
from handeye_drake.calibration.rig import RigCamera, calibrate_rig
from handeye_drake.estimation.rig_bundle import tangent
from handeye_drake.estimation.se3 import make_transform, rotation_exp
from handeye_drake.recorded.example_rig import (TRUE_X_BC_CELL, TRUE_X_EC, TRUE_X_EC2,
                                                generate_example_rig, relative_truth)

BOUND = float(chi2.ppf(0.999, 6))
KNOCK = make_transform(rotation_exp(np.radians([0.0, 1.0, 0.0])), [0.008, 0.0, 0.0])
CHECKS = ("three", "two", "blind", "swapped", "knocked", "slipped", "focal", "bag")
#: Every NEES of an answer that must be within σ, (check, answer, NEES), of the current row.
NEES = []
#: Every agreement χ² of a good rig's camera, of the current row.
AGREEMENT = []


def render(out, seed, n):
    cameras = {"wrist": ("hand", TRUE_X_EC), "wrist2": ("hand", TRUE_X_EC2),
               "cell": ("cell", TRUE_X_BC_CELL), "knocked": ("cell", TRUE_X_BC_CELL),
               "slipped": ("hand", TRUE_X_EC2)}
    k = n // 2
    return generate_example_rig(out, seed=seed, num_images=n, cameras=cameras,
                                moved={"knocked": (k, KNOCK), "slipped": (k, KNOCK)},
                                supersample=2)


def _cams(out, truth, names, folders=None):
    folders = folders or {}
    return [RigCamera(n, out / folders.get(n, n), truth["cameras"][n]["mount"],
                      str(out / folders.get(n, n) / "intrinsics.yaml")) for n in names]


def _nees(X, C, X_true):
    e = tangent(X, X_true)
    return float(e @ np.linalg.solve(C, e))


def _within(r, truth, names, bad):
    """Appends to ``bad`` what is wrong with cameras ``names`` of result ``r`` (not FAIL, NEES,
    σ not vacuous)."""
    for name in names:
        c = r.cameras[name]
        if c.verdict.status == "FAIL":
            bad.append(f"{name} FAIL: {c.verdict.reasons[0].code}: "
                       f"{c.verdict.reasons[0].message[:160]}")
            continue
        if c.X is None:
            bad.append(f"{name} has no answer")
            continue
        nees = _nees(c.X, c.covariance, np.asarray(truth["cameras"][name][c.key]))
        NEES.append((name, nees))
        if nees >= BOUND:
            e = tangent(c.X, np.asarray(truth["cameras"][name][c.key]))
            sr, st = c.sigma()
            bad.append(f"{name} NEES {nees:.1f} (error {np.degrees(np.linalg.norm(e[:3])):.3f}° "
                       f"/ {1000 * np.linalg.norm(e[3:]):.2f} mm, σ max {max(sr):.3f}° / "
                       f"{1000 * max(st):.2f} mm, jackknife ×{math.sqrt(c.variance_factor):.2f})")
        lim = 0.004 if c.mount == "cell" else 0.001
        if np.max(c.sigma()[1]) >= lim:
            bad.append(f"{name} σ vacuous: {1000 * np.max(c.sigma()[1]):.2f} mm")


def check_three(out, truth, opts, n):
    bad = []
    r = calibrate_rig(_cams(out, truth, ["wrist", "wrist2", "cell"]), out / "robot_poses.tum",
                      truth["target"], options=opts)
    if r.verdict.status == "FAIL":
        bad.append("rig FAIL: " + r.verdict.reasons[0].message[:200])
    _within(r, truth, ["wrist", "wrist2", "cell"], bad)
    if ("wrist", "wrist2") in r.relative:
        X, C = r.relative[("wrist", "wrist2")]
        nees = _nees(X, C, relative_truth(truth, "wrist", "wrist2"))
        NEES.append(("wrist→wrist2", nees))
        if nees >= BOUND:
            bad.append(f"X_wrist_wrist2 NEES {nees:.1f}")
        if r.cameras["wrist"].covariance is not None and not (
                np.trace(C[3:, 3:]) < np.trace(r.cameras["wrist"].covariance[3:, 3:])):
            bad.append("X_wrist_wrist2 σ not below wrist's")
    else:
        bad.append("no X_wrist_wrist2")
    if r.X_board is not None:
        eb = np.linalg.norm(tangent(r.X_board, np.asarray(truth["X_BT"]))[3:])
        if eb >= 0.001:
            bad.append(f"board {1000 * eb:.2f} mm off")
    for name in ("wrist", "wrist2"):
        a = r.cameras[name].agreement
        AGREEMENT.append(a.get("chi2", math.nan))
        if not a or a["chi2"] >= a["threshold"]:
            bad.append(f"{name} agreement χ² {a.get('chi2', math.nan):.1f}")
    return bad


def check_two(out, truth, opts, n):
    bad = []
    r = calibrate_rig(_cams(out, truth, ["wrist2", "cell"]), out / "robot_poses.tum",
                      truth["target"], options=opts)
    if r.verdict.status == "FAIL":
        bad.append("rig FAIL: " + r.verdict.reasons[0].message[:200])
    _within(r, truth, ["wrist2", "cell"], bad)
    return bad


def check_blind(out, truth, opts, n):
    bad = []
    blank = out / "blank"
    blank.mkdir(exist_ok=True)
    for k in range(n):
        cv2.imwrite(str(blank / f"img_{k:03d}.png"), np.full((480, 640), 80, np.uint8))
    cams = _cams(out, truth, ["wrist", "cell"]) + [
        RigCamera("blind", blank, "hand", str(out / "wrist" / "intrinsics.yaml"))]
    r = calibrate_rig(cams, out / "robot_poses.tum", truth["target"], options=opts)
    if r.verdict.status != "FAIL" or r.cameras["blind"].verdict.status != "FAIL" or \
            "camera blind does not see the board" not in r.verdict.reasons[0].message:
        bad.append(f"blind not named: {r.verdict.line()}")
    _within(r, truth, ["wrist", "cell"], bad)
    return bad


def check_swapped(out, truth, opts, n):
    bad = []
    cams = _cams(out, truth, ["wrist", "wrist2", "cell"],
                 folders={"wrist2": "cell", "cell": "wrist2"})
    r = calibrate_rig(cams, out / "robot_poses.tum", truth["target"], options=opts)
    c = r.cameras["cell"].verdict
    if r.verdict.status != "FAIL" or not c.reasons or c.reasons[0].code != "fixed_view_moves" \
            or "swapped" not in c.reasons[0].message:
        bad.append(f"cell not named swapped: {c.line()}")
    if r.cameras["wrist2"].verdict.status != "FAIL":
        bad.append(f"wrist2 (cell's images) not FAIL: {r.cameras['wrist2'].verdict.line()}")
    _within(r, truth, ["wrist"], bad)
    return bad


def _moved(out, truth, opts, n, name):
    bad = []
    r = calibrate_rig(_cams(out, truth, ["wrist", name]), out / "robot_poses.tum",
                      truth["target"], options=opts)
    v = r.cameras[name].verdict
    why = v.reasons[0] if v.reasons else None
    k = n // 2
    if r.verdict.status != "FAIL" or why is None or why.code != "camera_moved" or \
            f"camera {name} moved" not in why.message or \
            f"between images {k - 1} and {k}" not in why.message:
        bad.append(f"{name} not named moved between {k - 1} and {k}: {v.status} "
                   + "; ".join(f"{x.code}: {x.message[:120]}" for x in v.reasons[:2]))
    _within(r, truth, ["wrist"], bad)
    return bad


def check_knocked(out, truth, opts, n):
    return _moved(out, truth, opts, n, "knocked")


def check_slipped(out, truth, opts, n):
    return _moved(out, truth, opts, n, "slipped")


def check_focal(out, truth, opts, n):
    bad = []
    i = truth["intrinsics"]
    wrong = f"{1.03 * i['fx']},{1.03 * i['fy']},{i['cx']},{i['cy']}"
    cams = _cams(out, truth, ["wrist", "cell"]) + [
        RigCamera("wrist2", out / "wrist2", "hand", wrong)]
    r = calibrate_rig(cams, out / "robot_poses.tum", truth["target"], options=opts)
    v = r.cameras["wrist2"].verdict
    named = [x for x in v.reasons if x.code == "intrinsics"
             and x.message.startswith("camera wrist2: the intrinsics")]
    if opts.refine_intrinsics == "none":
        if r.verdict.status != "FAIL" or not v.reasons or v.reasons[0].code != "intrinsics" \
                or not named:
            bad.append(f"wrist2 not FAIL intrinsics: {v.status} "
                       + "; ".join(f"{x.code}" for x in v.reasons))
        _within(r, truth, ["wrist", "cell"], bad)
    else:
        if v.status != "WARN" or not named:
            bad.append(f"wrist2 not WARN intrinsics: {v.status} "
                       + "; ".join(f"{x.code}: {x.message[:100]}" for x in v.reasons[:2]))
        _within(r, truth, ["wrist", "cell"] + (["wrist2"] if v.status != "FAIL" else []), bad)
    return bad


def check_bag(out, truth, opts, n):
    from handeye_drake.apps.cli import main as cli
    from handeye_drake.recorded.example_rig import write_rig_bag
    bad = []
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "rig.mcap"
        topics = write_rig_bag(out, bag, "mcap", names=["wrist", "cell"])
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            rc = cli(["calibrate", "--bag", str(bag), "--target", truth["target"],
                      "--refine-intrinsics", opts.refine_intrinsics,
                      "--camera", f"wrist:{topics['wrist']}:hand",
                      "--camera", f"cell:{topics['cell']}:cell", "--out", f"{tmp}/o"])
        if rc != 0:
            bad.append(f"exit {rc}")
        p = Path(tmp) / "o" / "calibration.json"
        if not p.is_file():
            return bad + ["no calibration.json"]
        j = json.loads(p.read_text())
        if j["rig"]["verdict"]["status"] not in ("OK", "WARN"):
            bad.append(f"rig {j['rig']['verdict']['status']}: "
                       + "; ".join(x["message"][:150] for x in j["rig"]["verdict"]["reasons"]))
        for name in ("wrist", "cell"):
            c = j["cameras"][name]
            key = "X_EC" if c["mount"] == "hand" else "X_BC"
            if key not in c:
                bad.append(f"{name} no answer")
                continue
            nees = _nees(np.asarray(c[key]), np.asarray(c["covariance"]),
                         np.asarray(truth["cameras"][name][key]))
            NEES.append((name, nees))
            if nees >= BOUND:
                bad.append(f"{name} NEES {nees:.1f}")
        off = j["cameras"]["wrist"].get("alone", {}).get("time_offset_s")
        if off is None or abs(off - 0.035) >= 0.01:
            bad.append(f"offset {off}")
    return bad


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 4])
    p.add_argument("--images", type=int, nargs="+", default=[8, 12])
    p.add_argument("--refine", nargs="+", default=["none", "auto"],
                   choices=("none", "focal", "pinhole", "k1k2", "full", "auto"))
    p.add_argument("--checks", nargs="+", default=list(CHECKS), choices=CHECKS)
    a = p.parse_args()
    fns = {c: globals()[f"check_{c}"] for c in a.checks}
    rows, details = [], []
    for seed in a.seeds:
        for n in a.images:
            with tempfile.TemporaryDirectory() as tmp:
                out = Path(tmp)
                t0 = time.perf_counter()
                truth = render(out, seed, n)
                t_render = time.perf_counter() - t0
                for refine in a.refine:
                    opts = CalibrationOptions(refine_intrinsics=refine)
                    t0 = time.perf_counter()
                    cells = []
                    NEES.clear()
                    AGREEMENT.clear()
                    for name, fn in fns.items():
                        try:
                            bad = fn(out, truth, opts, n)
                        except Exception as e:            # a crash is a failing check too
                            bad = [f"raised {type(e).__name__}: {str(e)[:200]}"]
                        cells.append("ok" if not bad else "FAIL")
                        details += [f"seed {seed}, {n} images, {refine}, {name}: {b}"
                                    for b in bad]
                    t_checks = time.perf_counter() - t0
                    worst = max(NEES, key=lambda x: x[1], default=("—", math.nan))
                    cells.append(f"{worst[1]:.1f} {worst[0]}")
                    cells.append(f"{max(AGREEMENT, default=math.nan):.1f}")
                    rows.append((seed, n, refine, cells, t_render, t_checks))
                    print(f"seed {seed}, {n} images, refine {refine}: render {t_render:.1f} s, "
                          f"checks {t_checks:.1f} s: "
                          + " ".join(f"{c}={v}" for c, v in zip(
                              a.checks + ["max NEES", "max agreement χ²"], cells)), flush=True)
    print()
    print("| seed | images | refine | " + " | ".join(a.checks)
          + f" | max NEES (< {BOUND:.1f}) | max agreement χ² (< {chi2.isf(1e-4, 6):.1f}) |")
    print("|---|---|---|" + "---|" * (len(a.checks) + 2))
    for seed, n, refine, cells, _, _ in rows:
        print(f"| {seed} | {n} | {refine} | " + " | ".join(cells) + " |")
    failing = sum(c == "FAIL" for r in rows for c in r[3])
    print(f"\n{failing} failing checks of {len(rows) * len(a.checks)}; render "
          f"{np.mean([r[4] for r in rows]):.1f} s per cell on average")
    for d in details:
        print("  " + d)


if __name__ == "__main__":
    main()

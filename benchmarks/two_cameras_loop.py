"""The two-camera Drake loop (``scenarios/two_cameras.yaml``): is each camera's σ honest?

    OPENBLAS_NUM_THREADS=1 python benchmarks/two_cameras_loop.py [--scenario FILE] [--variants 0 1 2 3 4]

A rendered run has no random source (the renderer and the detector are deterministic; the seed
only drives the point-feature camera's noise), so runs differing only in ``seed`` are identical:
the scenario is varied instead. Variant 0 is the scenario as written; the others move the cell
camera (distance to the board's centre, azimuth, elevation; always looking at the centre), and
change the desired roll about the optical axis, the true X_EC and the board's yaw about its
centre (as ``benchmarks/rendered_loop.py --consistency`` does for one camera). The cell camera
stays within what the in-loop detector reads: at 1.0 m and 35° above the table the board's
detector finds 3 of the board's markers, too few (the cell camera then has no X_BC).

Printed per variant, through ``simulation.run_scenario`` (what ``handeye-drake simulate`` runs):
the final X_EC's and X_BC's errors to the truth (rotation deg, translation mm), their largest
per-axis σ, their NEES (error whitened by the final covariance: χ²(6), mean 6 when σ is honest,
22.5 its 0.999 quantile), and in how many frames each camera found the board; then where the
X_BC error comes from: X_BC recomposed as the cell calibrator does (chordal mean over the last
300 frames with both cameras of X_BE,k · X_EC · X_CT,hand,k · X_CT,cell,k⁻¹) with the truth for
all but one of X_EC (the final estimate), the hand camera's measured views, the cell camera's
measured view — the translation error (mm) each leaves alone.
"""

from __future__ import annotations

import argparse
import copy
import math
import time
from pathlib import Path

import numpy as np
from pydrake.common.schema import Rotation

from handeye_drake.estimation.se3 import make_transform, rotation_from_rpy, rotation_log
from handeye_drake.scenario import load_scenario, transform_matrix
from handeye_drake.simulation import run_scenario
from handeye_drake.vision.targets import pattern_extent

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_SCENARIO = ROOT / "scenarios" / "two_cameras.yaml"

#: (desired roll deg, true X_EC rpy deg, board yaw deg, cell camera: distance m, azimuth
#: offset deg, elevation deg); variant 0 = the scenario as written.
VARIANTS = [None,
            (-20, [4, -3, 92], 20, 0.75, 25, 50),
            (35, [-3, 5, 88], 20, 0.90, -20, 45),
            (15, [2, 2, 95], 10, 0.85, 40, 45),
            (30, [-5, -4, 90], 30, 0.95, -35, 55)]


def _tangent(X_true, X_est):
    return np.concatenate([rotation_log(X_true[:3, :3] @ X_est[:3, :3].T),
                           X_true[:3, 3] - X_est[:3, 3]])


def _look_at(p, aim):
    """X_WC of a camera at p whose optical axis z_C points at aim, image y_C down-ish."""
    z = (aim - p) / np.linalg.norm(aim - p)
    x = np.cross(z, [0.0, 0.0, -1.0])
    x /= np.linalg.norm(x)
    return make_transform(np.column_stack([x, np.cross(z, x), z]), p)


def _set_pose(t, X):
    t.translation = list(map(float, X[:3, 3]))
    rpy = _rpy_deg(X[:3, :3])
    t.rotation = Rotation.Rpy(deg=rpy)


def _rpy_deg(R):
    from pydrake.math import RollPitchYaw, RotationMatrix
    return list(np.degrees(RollPitchYaw(RotationMatrix(R)).vector()))


def variant(base, k):
    s = copy.deepcopy(base)
    s.camera.model.frames_to_save = []
    if VARIANTS[k] is None:
        return "as written", s.validate()
    roll, xec_rpy, yaw, dist, az, elev = VARIANTS[k]
    x0, y0, x1, y1 = pattern_extent(s.camera.model.parsed_target())
    centre_T = np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.0])
    X_WT = transform_matrix(s.target.X_WT, "target.X_WT")
    centre_W = X_WT[:3, :3] @ centre_T + X_WT[:3, 3]
    s.servo.X_TC_desired.rotation = Rotation.Rpy(deg=[0, 0, roll])
    s.camera.sensor.X_PB.rotation = Rotation.Rpy(deg=xec_rpy)
    s.target.X_WT.rotation = Rotation.Rpy(deg=[180, 0, yaw])
    s.target.X_WT.translation = list(centre_W - rotation_from_rpy(np.radians([180, 0, yaw]))
                                     @ centre_T)
    X_WC0 = transform_matrix(s.cell_cameras[0].X_WC, "cell_cameras[0].X_WC")
    d0 = X_WC0[:3, 3] - centre_W
    a = math.atan2(d0[1], d0[0]) + math.radians(az)
    e = math.radians(elev)
    p = centre_W + dist * np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a),
                                    math.sin(e)])
    _set_pose(s.cell_cameras[0].X_WC, _look_at(p, centre_W))
    return (f"roll {roll}°, X_EC rpy {xec_rpy}, board yaw {yaw}°, cell camera {dist:g} m "
            f"azimuth {az:+d}° elevation {elev}°"), s.validate()


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default=str(DEFAULT_SCENARIO))
    parser.add_argument("--variants", type=int, nargs="+", default=list(range(len(VARIANTS))))
    args = parser.parse_args()
    base = load_scenario(args.scenario)
    print("| variant | X_EC error (deg / mm) | σ max (deg / mm) | NEES | found | "
          "X_BC error (deg / mm) | σ max (deg / mm) | NEES | found | wall (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    for k in args.variants:
        name, s = variant(base, k)
        start = time.perf_counter()
        r = run_scenario(s)
        wall = time.perf_counter() - start
        cells = []
        e = _tangent(r.X_EC_true, r.X_EC_estimates[-1])
        C = r.X_EC_covariance
        cells.append((e, C, r.detector_found[1:]))
        for c in r.cell_cameras.values():
            cells.append((_tangent(c["X_BC_true"], c["X_BC_estimates"][-1]),
                          c["X_BC_covariance"], c["found"][1:]))
        text = []
        for e, C, found in cells:
            sd = np.sqrt(np.maximum(np.diag(C), 0.0))
            try:
                nees = f"{float(e @ np.linalg.solve(C, e)):.2f}"
            except np.linalg.LinAlgError:
                nees = "— (no covariance)"
            text.append(f"{math.degrees(np.linalg.norm(e[:3])):.4f} / "
                        f"{1000 * np.linalg.norm(e[3:]):.3f} | "
                        f"{math.degrees(sd[:3].max()):.4f} / {1000 * sd[3:].max():.3f} | "
                        f"{nees} | {int((found > 0.5).sum())}/{found.size}")
        print(f"| {k}: {name} | " + " | ".join(text) + f" | {wall:.0f} |"
              + (f" WARNING: {r.diagnostics}" if r.diagnostics else ""), flush=True)
        rows.append((k, r))
    print()
    print("| variant | cell camera | X_BC error (mm) | from X_EC alone | from the hand views "
          "alone | from the cell view alone |")
    print("|---|---|---|---|---|---|")
    for k, r in rows:
        for name, c in r.cell_cameras.items():
            print(f"| {k} | {name} | " + " | ".join(f"{v:.2f}" for v in _sources(r, c)) + " |")


def _sources(r, c):
    """Translation errors (mm) of X_BC recomposed from the kept frames: as measured, then with
    only the X_EC estimate / only the hand views / only the cell view measured."""
    from handeye_drake.estimation.se3 import inverse
    from handeye_drake.systems.cell_camera_calibrator import _mean_pose
    both = np.flatnonzero((r.detector_found > 0.5) & (c["found"] > 0.5))
    both = both[both > 0][-300:]
    if both.size == 0:
        return [math.nan] * 4
    s = r.scenario
    X_BT = inverse(transform_matrix(s.arm.X_WB, "arm.X_WB")) @ transform_matrix(
        s.target.X_WT, "target.X_WT")
    A = r.X_BE_samples[both]
    hand = r.X_CT_samples[both]
    hand_true = np.array([inverse(a @ r.X_EC_true) @ X_BT for a in A])
    cell = c["X_CT_samples"][both]
    cell_true = np.repeat((inverse(c["X_BC_true"]) @ X_BT)[None], both.size, axis=0)

    def error(X_EC, H, V):
        X = _mean_pose(A @ X_EC[None] @ H @ np.array([inverse(v) for v in V]))
        return 1000 * np.linalg.norm(X[:3, 3] - c["X_BC_true"][:3, 3])

    X_EC = r.X_EC_estimates[-1]
    return [error(X_EC, hand, cell), error(X_EC, hand_true, cell_true),
            error(r.X_EC_true, hand, cell_true), error(r.X_EC_true, hand_true, cell)]


if __name__ == "__main__":
    main()

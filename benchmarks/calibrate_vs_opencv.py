"""``handeye-drake calibrate`` against OpenCV's five ``cv2.calibrateHandEye`` methods on
held-out data: is the default answer the best one?

    OPENBLAS_NUM_THREADS=1 python benchmarks/calibrate_vs_opencv.py [--seeds 20] [--json FILE]
        [--datasets recording images simulated]

Every method is scored on the same samples, by the pose residuals (``estimation.consistency.
pose_residuals``: angle (deg) and distance (mm) between each measured X_CT and the one the model
X_CT = X_EC⁻¹ · X_BE⁻¹ · X_BT predicts) of samples none of them was fitted on.

- Ours: ``calibrate_streams`` with its defaults (clock offset estimated and refined, outliers
  rejected, maximum likelihood of X_EC and X_BT on the raw poses), which holds out 20 % of the
  inlying samples (seeded). Its held-out samples are the test set of every method.
- OpenCV, same samples: the synchronized samples our pipeline fitted (after our time alignment,
  our clock offset and our outlier rejection, i.e. OpenCV is handed our cleaned data), all five
  methods. OpenCV estimates X_EC only; each of its X_EC gets the maximum-likelihood X_BT with
  X_EC held (``target_for``: under the isotropic pose noise of our fit the rotation and
  translation of X_BT decouple, and the ML estimate is the geodesic (Karcher) mean of the
  rotations R_BE·R_EC·R_CT and the arithmetic mean of the translations each sample implies).
- OpenCV, naive: its usual front end — each camera sample paired with the robot sample nearest
  its time stamp (no offset, no interpolation, no outlier rejection), every sample except the
  held-out ones; X_BT fitted on those same pairs; scored on the same held-out samples.

Held-out samples are scored with the robot pose our alignment interpolated at the estimated
instant (the best available estimate of where the robot was); the error against the true X_EC,
where known, does not depend on that choice.

Datasets:

- ``recording``: the shipped ``data/example_robot.tum`` / ``example_camera.tum`` (truth in
  ``example_truth.json``).
- ``images``: the shipped image set (``data/example_images``: 14 rendered ChArUco images,
  ``vision.detection.detect_target`` with the shipped intrinsics, via ``image_streams``). Too few
  samples for a 20 % split: leave-one-out — for each image, ours fits the other 13
  (``holdout_fraction=0``), OpenCV gets the samples ours kept, and the left-out image is scored.
- ``simulated``: ``--seeds`` recordings of 20 s (robot 100 Hz, camera 15 Hz) with, per seed, a
  random hand-eye transform and trajectory, a clock offset of 10–50 ms, anisotropic pose noise
  of a PnP camera (rotation 0.15° / 0.15° / 0.05° and translation 0.3 / 0.3 / 1.0 mm about /
  along the camera's x, y, z), a configuration-dependent error of the reported robot pose (a
  smooth random function of the true pose, RMS 0.3 mm / 0.03°: a stand-in for kinematic
  errors), and 3 gross outliers (10–20°, 3–8 cm). Neither the anisotropy nor the robot error is
  in our pipeline's model.

Prints one table per dataset and the ratio ours / best OpenCV of the held-out medians (the best
OpenCV method chosen separately for rotation and translation, with hindsight).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from handeye_drake.apps.accuracy import OPENCV_METHODS, opencv_calibrate  # noqa: E402
from handeye_drake.calibration import calibrate_streams, file_streams, image_streams  # noqa
from handeye_drake.estimation.errors import rotation_error_deg  # noqa: E402
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_from_rpy  # noqa
from handeye_drake.estimation.consistency import pose_residuals  # noqa: E402
from handeye_drake.recorded.formats import pose_stream  # noqa: E402

DATA = ROOT / "handeye_drake" / "data"
DATASETS = ("recording", "images", "simulated")


# ---------------------------------------------------------------------------------------------
# Scoring.

def target_for(X_BE, X_CT, X_EC, iterations: int = 20) -> np.ndarray:
    """ML target pose X_BT with X_EC held, under isotropic noise on X_CT (R = exp(n_r) R̂,
    t = t̂ + n_t): the Karcher mean of the implied rotations, the mean of the implied
    translations (the two decouple)."""
    X_B_T = X_BE @ X_EC[None] @ X_CT
    R = Rotation.from_matrix(X_B_T[:, :3, :3])
    mean = R.mean()  # chordal mean: the start
    for _ in range(iterations):
        step = (mean.inv() * R).as_rotvec().mean(axis=0)  # residuals in the mean's frame
        mean = mean * Rotation.from_rotvec(step)
        if np.linalg.norm(step) < 1e-14:
            break
    # (The angle between rotations is bi-invariant: the same mean minimizes the residual
    # angles of X_CT, whichever side the noise is on.)
    return make_transform(mean.as_matrix(), X_B_T[:, :3, 3].mean(axis=0))


def residuals(X_BE, X_CT, X_EC, X_BT):
    """(rotation deg, translation mm) per sample."""
    deg, m = pose_residuals(X_BE, X_CT, X_EC, X_BT)
    return deg, 1000.0 * m


def stats(deg, mm) -> dict:
    return {"n": int(len(deg)), "rot_median": float(np.median(deg)),
            "rot_rms": float(np.sqrt(np.mean(deg**2))), "trans_median": float(np.median(mm)),
            "trans_rms": float(np.sqrt(np.mean(mm**2)))}


def truth_error(X_EC_true, X_EC) -> dict:
    if X_EC_true is None:
        return {}
    return {"err_rot_deg": rotation_error_deg(X_EC_true, X_EC),
            "err_trans_mm": 1000.0 * float(np.linalg.norm(X_EC_true[:3, 3] - X_EC[:3, 3]))}


def nearest_pairs(robot, camera, keep_camera=None):
    """OpenCV's usual front end: each camera sample with the robot sample nearest its stamp
    (no offset, no interpolation), inside the robot's time span. Returns (X_BE, X_CT)."""
    t_r, t_c = robot.timestamps, camera.timestamps
    idx = np.arange(len(camera)) if keep_camera is None else np.asarray(keep_camera)
    idx = idx[(t_c[idx] >= t_r[0]) & (t_c[idx] <= t_r[-1])]
    j = np.clip(np.searchsorted(t_r, t_c[idx]), 1, len(t_r) - 1)
    j -= (t_c[idx] - t_r[j - 1]) < (t_r[j] - t_c[idx])
    return robot.poses[j], camera.poses[idx]


def opencv_rows(X_BE_fit, X_CT_fit, X_BE_test, X_CT_test, X_EC_true, label: str) -> dict:
    rows = {}
    for name, X_EC in opencv_calibrate(list(X_BE_fit), list(X_CT_fit)).items():
        method = name.removeprefix("opencv_")
        key = f"OpenCV {method}{label}"
        if X_EC is None:
            rows[key] = {"failed": True}
            continue
        X_BT = target_for(X_BE_fit, X_CT_fit, X_EC)
        rows[key] = {**stats(*residuals(X_BE_test, X_CT_test, X_EC, X_BT)),
                     **truth_error(X_EC_true, X_EC)}
    return rows


def ratios(rows: dict, ours: str = "ours (calibrate)", suffix: str = "") -> dict:
    """ours / best OpenCV (with ``suffix``) of the held-out median and RMS, per component."""
    cv = {k: v for k, v in rows.items() if k.startswith("OpenCV") and k.endswith(suffix)
          and not v.get("failed") and (suffix or "naive" not in k)}
    out = {}
    for q in ("rot_median", "trans_median", "rot_rms", "trans_rms"):
        best = min(cv, key=lambda k: cv[k][q])
        out[q] = {"ratio": rows[ours][q] / cv[best][q], "best": best}
    return out


# ---------------------------------------------------------------------------------------------
# Datasets.

def compare_recording(robot, camera, X_EC_true=None, seed: int = 0) -> dict:
    """Ours with a 20 % hold-out; OpenCV (same fit samples, and naive pairing) scored on it."""
    start = time.perf_counter()
    r = calibrate_streams(robot, camera, seed=seed)
    seconds = time.perf_counter() - start
    X_BE, X_CT = np.asarray(r.aligned.X_BE), np.asarray(r.aligned.X_CT)
    fit = np.flatnonzero(r.sample_used == "fit")
    held = np.flatnonzero(r.sample_used == "held_out")
    rows = {"ours (calibrate)": {**stats(r.residual_deg[held], 1000.0 * r.residual_m[held]),
                                 **truth_error(X_EC_true, r.X_EC)}}
    # Check: our held-out residuals are those of pose_residuals at our result.
    d, mm = residuals(X_BE[held], X_CT[held], r.X_EC, r.X_fixed)
    assert np.allclose(d, r.residual_deg[held]) and np.allclose(mm, 1000 * r.residual_m[held])
    X_BT0 = target_for(X_BE[fit], X_CT[fit], r.classical_X_H)
    rows["ours, classical start"] = {
        **stats(*residuals(X_BE[held], X_CT[held], r.classical_X_H, X_BT0)),
        **truth_error(X_EC_true, r.classical_X_H)}
    rows.update(opencv_rows(X_BE[fit], X_CT[fit], X_BE[held], X_CT[held], X_EC_true, ""))
    info = {"samples": len(X_BE), "fit": len(fit), "held_out": len(held),
            "outliers": int(np.sum(r.sample_used == "outlier")),
            "time_offset_s": r.aligned.time_offset, "verdict": r.verdict.status,
            "verdict_causes": _causes(r.verdict), "classical_method": r.method,
            "ours_seconds": seconds}
    if robot.has_timestamps:
        held_camera = set(np.asarray(r.aligned.camera_index)[held].tolist())
        keep = np.array([k for k in range(len(camera)) if k not in held_camera])
        X_BE_n, X_CT_n = nearest_pairs(robot, camera, keep)
        info["naive_pairs"] = len(X_BE_n)
        rows.update(opencv_rows(X_BE_n, X_CT_n, X_BE[held], X_CT[held], X_EC_true,
                                ", naive pairing"))
    return {"info": info, "rows": rows, "ratios": ratios(rows),
            "ratios_naive": ratios(rows, suffix=", naive pairing")
            if robot.has_timestamps else None}


def _causes(verdict) -> list:
    return [r.to_dict() if hasattr(r, "to_dict") else str(r) for r in verdict.reasons]


def shipped_recording() -> dict:
    s = file_streams(DATA / "example_robot.tum", DATA / "example_camera.tum")
    truth = json.loads((DATA / "example_truth.json").read_text())
    return compare_recording(s.robot, s.camera, np.array(truth["X_EC"]))


def shipped_images() -> dict:
    """Leave-one-out over the shipped image set."""
    d = DATA / "example_images"
    truth = json.loads((d / "truth.json").read_text())
    s = image_streams([str(p) for p in sorted(d.glob("img_*.png"))], d / "robot_poses.tum",
                      truth["target"], str(d / "intrinsics.yaml"))
    X_EC_true = np.array(truth["X_EC"])
    X_BE, X_CT = s.robot.poses, s.camera.poses
    n = len(X_BE)
    names = None
    res = {}
    full = calibrate_streams(s.robot, s.camera, holdout_fraction=0.0)
    for i in range(n):
        others = np.setdiff1d(np.arange(n), [i])
        r = calibrate_streams(pose_stream(X_BE[others]), pose_stream(X_CT[others]),
                              holdout_fraction=0.0)
        fit = others[r.sample_used == "fit"]
        rows = {"ours (calibrate)": residuals(X_BE[[i]], X_CT[[i]], r.X_EC, r.X_fixed)}
        X_BT0 = target_for(X_BE[fit], X_CT[fit], r.classical_X_H)
        rows["ours, classical start"] = residuals(X_BE[[i]], X_CT[[i]], r.classical_X_H, X_BT0)
        for name, X_EC in opencv_calibrate(list(X_BE[fit]), list(X_CT[fit])).items():
            key = f"OpenCV {name.removeprefix('opencv_')}"
            rows[key] = None if X_EC is None else residuals(
                X_BE[[i]], X_CT[[i]], X_EC, target_for(X_BE[fit], X_CT[fit], X_EC))
        names = names or list(rows)
        for k, v in rows.items():
            res.setdefault(k, []).append((np.nan, np.nan) if v is None else (v[0][0], v[1][0]))
    out_rows = {}
    fit_all = np.flatnonzero(full.sample_used == "fit")
    cv_full = opencv_calibrate(list(X_BE[fit_all]), list(X_CT[fit_all]))
    for k in names:
        a = np.array(res[k])
        if np.isnan(a).any():
            out_rows[k] = {"failed": True}
            continue
        if k == "ours (calibrate)":
            X = full.X_EC
        elif k == "ours, classical start":
            X = full.classical_X_H
        else:
            X = cv_full[f"opencv_{k.removeprefix('OpenCV ')}"]
        out_rows[k] = {**stats(a[:, 0], a[:, 1]), **truth_error(X_EC_true, X)}
    info = {"samples": n, "fit_all": len(fit_all), "held_out": "leave-one-out",
            "verdict": full.verdict.status}
    return {"info": info, "rows": out_rows, "ratios": ratios(out_rows), "ratios_naive": None}


def _smooth_field(rng, n_features: int = 4):
    """A smooth random function R⁶ → R⁶ (sum of sines of random projections), returned with
    a normalizer so that its RMS over given inputs can be set."""
    K = rng.normal(size=(n_features, 6))
    phase = rng.uniform(0, 2 * np.pi, n_features)
    C = rng.normal(size=(n_features, 6))

    def f(z):
        return np.sin(z @ K.T + phase) @ C
    return f


def simulate_recording(seed: int, duration: float = 20.0, robot_rate: float = 100.0,
                       camera_rate: float = 15.0, num_outliers: int = 3):
    """(robot stream, camera stream, X_EC_true, clock offset) of a simulated recording."""
    rng = np.random.default_rng(10_000 + seed)
    X_EC = make_transform(rotation_from_rpy(np.radians(
        rng.uniform(-5, 5, 3) + [0.0, 0.0, rng.choice([0.0, 90.0, 180.0, -90.0])])),
        rng.uniform([-0.06, -0.06, 0.03], [0.06, 0.06, 0.10]))
    X_BT = make_transform(rotation_from_rpy([0.0, 0.0, rng.uniform(-np.pi, np.pi)]),
                          [rng.uniform(0.4, 0.6), rng.uniform(-0.15, 0.15), 0.0])
    amp = np.radians(rng.uniform([18, 15, 20], [28, 25, 35]))
    freq = rng.uniform(0.05, 0.25, 3)
    ph = rng.uniform(0, 2 * np.pi, 6)
    dist = rng.uniform(0.4, 0.6)

    def X_BC(t):
        a = amp[None] * np.sin(2 * np.pi * freq[None] * t[:, None] + ph[None, :3])
        R = Rotation.from_euler("xyz", [np.pi, 0, 0]).as_matrix()[None] @ \
            Rotation.from_euler("xyz", a).as_matrix()
        d = dist + 0.05 * np.sin(2 * np.pi * 0.13 * t + ph[3])
        off = np.stack([0.03 * np.sin(2 * np.pi * 0.19 * t + ph[4]),
                        0.03 * np.cos(2 * np.pi * 0.23 * t + ph[5]), 0 * t], axis=1)
        X = np.zeros((len(t), 4, 4))
        X[:, :3, :3] = R
        X[:, :3, 3] = X_BT[:3, 3] + off - d[:, None] * R[:, :, 2]
        X[:, 3, 3] = 1.0
        return X

    offset = rng.uniform(0.01, 0.05)
    t_r = np.arange(int(duration * robot_rate) + 1) / robot_rate
    X_BE_true = X_BC(t_r) @ inverse(X_EC)[None]
    # Robot model error: reported = true · exp(e), e a smooth function of the true pose.
    z = np.concatenate([(X_BE_true[:, :3, 3] - X_BE_true[:, :3, 3].mean(0)) / 0.1,
                        Rotation.from_matrix(X_BE_true[:, :3, :3]).as_rotvec() / 0.5], axis=1)
    fr, ft = _smooth_field(rng), _smooth_field(rng)
    er, et = fr(z)[:, :3], ft(z)[:, :3]
    er *= np.radians(0.03) / np.sqrt(np.mean(np.sum(er**2, 1)))
    et *= 0.0003 / np.sqrt(np.mean(np.sum(et**2, 1)))
    X_BE = X_BE_true.copy()
    X_BE[:, :3, :3] = X_BE_true[:, :3, :3] @ Rotation.from_rotvec(er).as_matrix()
    X_BE[:, :3, 3] += np.einsum("nij,nj->ni", X_BE_true[:, :3, :3], et)

    instants = np.arange(int(duration * camera_rate) + 1) / camera_rate
    instants = instants[(instants > 0.2) & (instants < duration - 0.2)]
    X_CT = inverse(X_EC)[None] @ np.linalg.inv(X_BC(instants) @ inverse(X_EC)[None]) @ \
        X_BT[None]
    n = len(instants)
    # PnP-like noise in C: tilt about x, y worse than roll about z; depth worse than lateral.
    nr = rng.normal(size=(n, 3)) * np.radians([0.15, 0.15, 0.05])
    nt = rng.normal(size=(n, 3)) * np.array([0.0003, 0.0003, 0.001])
    X_CT[:, :3, :3] = Rotation.from_rotvec(nr).as_matrix() @ X_CT[:, :3, :3]
    X_CT[:, :3, 3] += nt
    bad = rng.choice(np.arange(n // 10, n - n // 10), num_outliers, replace=False)
    for k in bad:
        axis = rng.normal(size=3)
        direction = rng.normal(size=3)
        G = make_transform(Rotation.from_rotvec(np.radians(rng.uniform(10, 20)) * axis
                                                / np.linalg.norm(axis)).as_matrix(),
                           rng.uniform(0.03, 0.08) * direction / np.linalg.norm(direction))
        X_CT[k] = G @ X_CT[k]
    robot = pose_stream(X_BE, t_r, source=f"sim{seed}_robot")
    camera = pose_stream(X_CT, instants + offset, source=f"sim{seed}_camera")
    return robot, camera, X_EC, offset


def simulated(seeds: int, log=print) -> dict:
    runs = []
    for seed in range(seeds):
        robot, camera, X_EC, offset = simulate_recording(seed)
        out = compare_recording(robot, camera, X_EC, seed=0)
        out["info"]["true_offset_s"] = offset
        runs.append(out)
        q = out["ratios"]
        log(f"  seed {seed:2d}: ratio ours/best OpenCV of held-out medians: rotation "
            f"{q['rot_median']['ratio']:.3f}, translation {q['trans_median']['ratio']:.3f}; "
            f"ours vs truth {out['rows']['ours (calibrate)']['err_rot_deg']:.4f}° / "
            f"{out['rows']['ours (calibrate)']['err_trans_mm']:.3f} mm; offset "
            f"{out['info']['time_offset_s']:.4f} s (true {offset:.4f}), "
            f"verdict {out['info']['verdict']}", flush=True)
    return {"runs": runs}


# ---------------------------------------------------------------------------------------------
# Printing.

def table(result: dict) -> str:
    lines = ["| method | held-out n | rot median (°) | rot RMS (°) | trans median (mm) | "
             "trans RMS (mm) | error vs truth rot (°) / trans (mm) |",
             "|---|---|---|---|---|---|---|"]
    for k, v in result["rows"].items():
        if v.get("failed"):
            lines.append(f"| {k} | failed (cv2.error) | | | | | |")
            continue
        truth = (f"{v['err_rot_deg']:.4f} / {v['err_trans_mm']:.3f}" if "err_rot_deg" in v
                 else "—")
        lines.append(f"| {k} | {v['n']} | {v['rot_median']:.4f} | {v['rot_rms']:.4f} | "
                     f"{v['trans_median']:.3f} | {v['trans_rms']:.3f} | {truth} |")
    return "\n".join(lines)


def ratio_text(q: dict, what: str) -> str:
    return (f"ours / best OpenCV ({what}), held-out median: rotation "
            f"{q['rot_median']['ratio']:.4f} (best: {q['rot_median']['best']}), translation "
            f"{q['trans_median']['ratio']:.4f} (best: {q['trans_median']['best']}); RMS: "
            f"rotation {q['rot_rms']['ratio']:.3f}, translation {q['trans_rms']['ratio']:.3f}")


def summarize_simulated(sim: dict) -> str:
    runs = sim["runs"]
    lines = [f"over {len(runs)} seeds:"]
    for suffix, key in (("same samples", "ratios"), ("naive pairing", "ratios_naive")):
        for q in ("rot_median", "trans_median", "rot_rms", "trans_rms"):
            r = np.array([run[key][q]["ratio"] for run in runs])
            lines.append(f"  ours / best OpenCV ({suffix}), held-out {q.replace('_', ' ')}: "
                         f"median {np.median(r):.3f}, worst {r.max():.3f}, best {r.min():.3f}; "
                         f"ours better in {int(np.sum(r < 1))} of {len(r)}")
    lines.append("  ours / each OpenCV method (same samples), held-out medians: median ratio over "
                 "seeds (rotation, translation); seeds where ours is lower; same for the error "
                 "vs truth:")
    ours = "ours (calibrate)"
    for k in [k for k in runs[0]["rows"] if k.startswith("OpenCV") and "naive" not in k]:
        ok = [run for run in runs if not run["rows"][k].get("failed")]
        parts = []
        for q in ("rot_median", "trans_median", "err_rot_deg", "err_trans_mm"):
            r = np.array([run["rows"][ours][q] / run["rows"][k][q] for run in ok])
            parts.append(f"{np.median(r):.3f} ({int(np.sum(r < 1))}/{len(r)})")
        lines.append(f"    vs {k}: held-out rot {parts[0]}, trans {parts[1]}; truth rot "
                     f"{parts[2]}, trans {parts[3]}")
    names = [k for k in runs[0]["rows"] if "err_rot_deg" in runs[0]["rows"][k]]
    lines.append("  error vs truth, median over seeds (rotation ° / translation mm):")
    for k in names:
        e = np.array([[run["rows"][k].get("err_rot_deg", np.nan),
                       run["rows"][k].get("err_trans_mm", np.nan)] for run in runs])
        lines.append(f"    {k}: {np.nanmedian(e[:, 0]):.4f} / {np.nanmedian(e[:, 1]):.3f} "
                     f"(worst {np.nanmax(e[:, 0]):.4f} / {np.nanmax(e[:, 1]):.3f})")
    held = np.array([[run["rows"][k]["rot_median"], run["rows"][k]["trans_median"]]
                     for run in runs for k in ("ours (calibrate)",)])
    lines.append(f"  ours held-out medians, median over seeds: {np.median(held[:, 0]):.4f}° / "
                 f"{np.median(held[:, 1]):.3f} mm")
    verdicts = [run["info"]["verdict"] for run in runs]
    lines.append("  verdicts: " + ", ".join(f"{v} × {verdicts.count(v)}"
                                             for v in sorted(set(verdicts))))
    return "\n".join(lines)


def _jsonable(o):
    if isinstance(o, dict):
        return {k: _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    return o


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--datasets", nargs="+", choices=DATASETS, default=list(DATASETS))
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--json", help="also write every figure as JSON")
    args = parser.parse_args()
    report = {}
    start = time.perf_counter()
    if "recording" in args.datasets:
        print("## shipped recording (example_robot.tum / example_camera.tum), 20 % held out")
        r = report["recording"] = shipped_recording()
        print(json.dumps(_jsonable(r["info"])))
        print(table(r))
        print(ratio_text(r["ratios"], "same samples"))
        print(ratio_text(r["ratios_naive"], "naive pairing"))
        print(flush=True)
    if "images" in args.datasets:
        print("## shipped image set (example_images, detect_target), leave-one-out")
        r = report["images"] = shipped_images()
        print(json.dumps(_jsonable(r["info"])))
        print(table(r))
        print(ratio_text(r["ratios"], "same samples"))
        print(flush=True)
    if "simulated" in args.datasets:
        print(f"## simulated recordings ({args.seeds} seeds), 20 % held out")
        r = report["simulated"] = simulated(args.seeds)
        print("seed 0:")
        print(table(r["runs"][0]))
        print(summarize_simulated(r))
    print(f"({time.perf_counter() - start:.0f} s)")
    if args.json:
        Path(args.json).write_text(json.dumps(_jsonable(report), indent=1) + "\n")

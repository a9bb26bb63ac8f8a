"""What ``calibrate`` prints and writes: the summary table, ``calibration.json`` and the plots.

Units everywhere: degrees for angles, millimetres in the printed text, metres in the JSON
(keys say the unit: ``_deg``, ``_m``, ``_mm``). Quaternions say their order in the key
(``quaternion_wxyz``, ``quaternion_xyzw``); roll-pitch-yaw is extrinsic X-Y-Z (Drake's
RollPitchYaw, URDF ``rpy``).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..estimation.se3 import quat_wxyz, rpy
from .naming import fixed_name, hand_name, tangent_std
from .task_space import task_sigmas

#: Sample line numbers listed in the JSON per category; beyond, a count.
MAX_LISTED = 200


def rpy_std_deg(X, covariance) -> np.ndarray:
    """Roll-pitch-yaw standard deviations (deg), first-order propagation of the covariance."""
    R = X[:3, :3]
    J = np.zeros((3, 3))
    h = 1e-6
    for k in range(3):
        d = np.zeros(3)
        d[k] = h
        plus = rpy(Rotation.from_rotvec(d).as_matrix() @ R)
        minus = rpy(Rotation.from_rotvec(-d).as_matrix() @ R)
        J[:, k] = np.angle(np.exp(1j * (plus - minus))) / (2 * h)
    return np.degrees(np.sqrt(np.maximum(np.diag(J @ covariance[:3, :3] @ J.T), 0.0)))


def _pose_dict(X, covariance) -> dict:
    q = quat_wxyz(X[:3, :3])
    r_std, t_std = tangent_std(covariance)
    return {"matrix": X.tolist(), "translation_m": X[:3, 3].tolist(),
            "quaternion_wxyz": q.tolist(), "quaternion_xyzw": [q[1], q[2], q[3], q[0]],
            "rpy_deg": np.degrees(rpy(X[:3, :3])).tolist(),
            "std": {"rotation_deg": r_std.tolist(), "translation_m": t_std.tolist(),
                    "rpy_deg": rpy_std_deg(X, covariance).tolist(),
                    "covariance": np.asarray(covariance).tolist(),
                    "error_state": "R = exp([dtheta]x) R_hat (dtheta in rad about the axes of "
                                   "the frame the pose is expressed in), t = t_hat + dt (m)"}}


def _listed(values) -> dict:
    values = [int(v) for v in values]
    return {"count": len(values), "lines": values[:MAX_LISTED],
            "more": max(0, len(values) - MAX_LISTED)}


def _finite(v):
    return None if v is None or not math.isfinite(v) else v


def _noise_dict(fit) -> dict:
    n = fit.noise
    out = {"rotation_deg_xyz": np.degrees(n.rotation).tolist(),
           "translation_m_xyz": n.translation.tolist(),
           "rotation_deg": math.degrees(fit.rotation_sigma),
           "translation_m": fit.translation_sigma,
           "frame": "camera C (x right, y down, z forward): rotation about, translation along "
                    "its axes; rotation_deg / translation_m: RMS over the three axes",
           "from": "1.4826 × median |residual| per axis of the fit samples (residuals in C)"}
    if n.scale is not None:
        out["per_sample_covariances"] = {
            "scale": n.scale,
            "definition": "the fit whitens each sample by its given covariance times scale²; "
                          "scale² = median whitened residual² / median of χ²(6)"}
    return out


def _held_out_dict(result) -> dict | None:
    from .checks import held_out_test
    t = held_out_test(result)
    if t is None:
        return None
    return {"ratio": t["ratio"], "bound_99.9%": t["bound"], "dof": list(t["dof"]),
            "worst_line": t["worst_line"], "worst_whitened_sq": t["worst_whitened_sq"],
            "definition": "mean whitened residual² per dof, held-out over fit (F-test)"}


def to_dict(result) -> dict:
    r, a, fit = result, result.aligned, result.fit
    hand, fixed = hand_name(r.mode), fixed_name(r.mode)
    used = r.sample_used
    lines = np.asarray(a.camera_lines)
    times = a.camera_times
    samples = [{"line": int(lines[k]),
                "time_s": None if times is None else float(times[k]),
                "used": str(used[k]), "rotation_residual_deg": float(r.residual_deg[k]),
                "translation_residual_mm": 1000.0 * float(r.residual_m[k])}
               for k in range(len(used))][:5000]
    out = {
        "verdict": r.verdict.to_dict(),
        "mode": r.mode,
        "inputs": r.inputs,
        "method": {"start": r.method, "final": "maximum likelihood (AX = ZB on the raw poses)"
                   if r.corners is None else "corner-level maximum likelihood (every detected "
                   "corner through the chain and the camera model)"},
        "settings": {k: (list(v) if isinstance(v, tuple) else v) for k, v in r.settings.items()},
        "seed": r.seed,
        hand: _pose_dict(fit.X_H, fit.covariance),
        fixed: _pose_dict(fit.X_F, fit.fixed_covariance),
        "task_space_sigma": task_sigmas(r.mode, fit.X_H, fit.covariance, a.X_BE),
        "fixed_components": r.settings["fixed"] or None,
        "fixed_component_tests": [t.to_dict() for t in r.fixed_tests] or None,
        "camera_scale_test": r.scale_test,
        "robot_accuracy": None if not r.settings.get("robot_accuracy") else {
            "rotation_deg": r.settings["robot_accuracy"][0],
            "translation_m": r.settings["robot_accuracy"][1]},
        "noise_per_axis": _noise_dict(fit),
        "held_out_test": _held_out_dict(r),
        "comparison": None if getattr(r, "comparison", None) is None else
        r.comparison.to_dict(),
        "time_offset": {
            "mode": r.time_offset_mode, "value_s": a.time_offset,
            "convention": "camera stamp - robot time of the same instant",
            **({} if r.time_offset is None else {
                "search_range_s": r.time_offset.search_range,
                "motions_compared": r.time_offset.num_motions,
                "angle_residual_rms_deg": r.time_offset.residual_rms_deg}),
            "refinement": r.time_offset_refined},
        "alignment": {"camera_samples": len(r.camera), "robot_samples": len(r.robot),
                      "aligned": len(a),
                      "dropped_outside_robot_span": _listed(a.dropped_outside),
                      "dropped_in_robot_gaps": _listed(a.dropped_gap)},
        "samples": {"fit": int(np.sum(used == "fit")),
                    "held_out": int(np.sum(used == "held_out")),
                    "outliers": _listed(lines[used == "outlier"]),
                    "per_sample": samples},
        "residuals": {"fit": r.fit_residuals, "held_out": r.held_out_residuals,
                      "definition": "per sample: angle and distance between the measured X_CT "
                                    "and the one the result predicts"},
        f"{fixed}_spread": {"rotation_rms_deg": r.spread.rotation_rms_deg,
                            "translation_rms_m": r.spread.translation_rms,
                            "rotation_max_deg": r.spread.rotation_max_deg,
                            "translation_max_m": r.spread.translation_max,
                            "definition": f"{fixed} implied by each fit sample, around their mean"},
        "split_half_check": None if r.split is None else {
            "nees": r.split.nees, "threshold_99.9%": r.split.threshold,
            "rotation_diff_deg": r.split.rotation_diff_deg,
            "translation_diff_m": r.split.translation_diff},
        "observability": None if r.observability is None else r.observability.to_dict(),
        "alternatives_tried": [{k: (_finite(v) if isinstance(v, float) else v)
                                for k, v in h.to_dict().items()} for h in r.hypotheses],
        "classical_start": None if r.classical is None else {
            hand: r.classical_X_H.tolist(), "motion_pairs": len(r.classical.pairs),
            "inlier_pairs": int(r.classical.inlier.sum())},
        "start": {"method": r.method, hand: r.classical_X_H.tolist()},
        "warnings": list(r.warnings),
        "online": None,
    }
    if r.corners is not None:
        out.update(r.corners.to_dict())
    if r.online is not None:
        out["online"] = [{
            "filter": o.label, "updates": int(len(o.times)), "keyframe_step_deg": o.step_deg,
            "skipped_updates": o.skipped, "init_pairs": o.init_pairs,
            "X_H_init": o.X_H_init.tolist(), "X_H": o.X_H.tolist(),
            "std": {"rotation_deg": o.rotation_std_deg.tolist(),
                    "translation_m": o.translation_std.tolist()},
            "final_diff_to_batch": {
                "rotation_deg": float(o.rotation_diff_deg[-1]) if len(o.times) else None,
                "translation_m": float(o.translation_diff[-1]) if len(o.times) else None,
                "nees": o.final_nees(r.fit.X_H)},
            "diagnostics": list(o.diagnostics)} for o in r.online]
    return out


def _vec(v, fmt: str) -> str:
    return "[" + " ".join(fmt.format(x) for x in v) + "]"


def _short(values, n: int = 8) -> str:
    values = [int(v) for v in values]
    s = ", ".join(str(v) for v in values[:n])
    return s + (f", … ({len(values) - n} more)" if len(values) > n else "")


def table(result) -> str:
    """The human-readable summary printed by the command."""
    r, a, fit = result, result.aligned, result.fit
    hand, fixed = hand_name(r.mode), fixed_name(r.mode)
    lines = [f"robot:  {r.robot.source} ({len(r.robot)} poses)",
             f"camera: {r.camera.source} ({len(r.camera)} poses)",
             f"mode: {r.mode.replace('_', '-')}"]
    if r.time_offset is not None:
        refined = r.time_offset_refined or {}
        lines.append(f"time offset: {a.time_offset:+.5f} s (camera stamp − robot time; estimated "
                     f"±{r.time_offset.search_range:g} s over {r.time_offset.num_motions} "
                     f"motions" + (f", refined by {1000 * refined['change_s']:+.2f} ms with the "
                                   "fit" if refined.get("refined") else "") + ")")
    elif r.camera.has_timestamps:
        lines.append(f"time offset: {a.time_offset:+.5f} s ({r.time_offset_mode})")
    else:
        lines.append("time offset: none (no timestamps, samples paired by index)")
    dropped = ""
    if a.dropped_outside:
        dropped += (f"; dropped {len(a.dropped_outside)} outside the robot's time span "
                    f"(lines {_short(a.dropped_outside)})")
    if a.dropped_gap:
        dropped += f"; dropped {len(a.dropped_gap)} in robot gaps (lines {_short(a.dropped_gap)})"
    lines.append(f"aligned: {len(a)} of {len(r.camera)} camera samples{dropped}")
    used = r.sample_used
    outl = np.asarray(a.camera_lines)[used == "outlier"]
    lines.append(f"samples: {int(np.sum(used == 'fit'))} fit, {int(np.sum(used == 'held_out'))} "
                 f"held out, {len(outl)} outliers" + (f" (lines {_short(outl)})" if len(outl)
                                                      else ""))
    pose_level = "maximum likelihood on the raw poses (AX = ZB)"
    if r.classical is not None:
        lines.append(f"start: {r.method} on {int(r.classical.inlier.sum())} of "
                     f"{len(r.classical.pairs)} motion pairs; "
                     + ("then " if r.corners is not None else "result: ") + pose_level)
    else:
        lines.append(f"start: {r.method}; " + ("then " if r.corners is not None else
                                                "result: ") + pose_level)
    if r.corners is not None:
        lines += r.corners.lines()
    lines.append("")
    r_std, t_std = tangent_std(fit.covariance)
    target = ("camera in end-effector frame" if r.mode == "eye_in_hand" else
              "camera in robot base frame")
    accuracy = r.settings.get("robot_accuracy")
    lines.append(f"{hand} ({target}); ± 1σ" + (
        f" (including the robot's accuracy {accuracy[0]:g}° / {1000 * accuracy[1]:g} mm, "
        "--robot-accuracy)" if accuracy else ""))
    for row in fit.X_H:
        lines.append("  [" + " ".join(f"{v:+.6f}" for v in row) + "]")
    lines.append(f"  translation (mm)       {_vec(1000 * fit.X_H[:3, 3], '{:+9.3f}')}  ± "
                 f"{_vec(1000 * t_std, '{:.3f}')}")
    lines.append(f"  quaternion (w x y z)   {_vec(quat_wxyz(fit.X_H[:3, :3]), '{:+.6f}')}")
    lines.append(f"  roll-pitch-yaw (deg)   {_vec(np.degrees(rpy(fit.X_H[:3, :3])), '{:+9.4f}')}"
                 f"  ± {_vec(rpy_std_deg(fit.X_H, fit.covariance), '{:.4f}')}")
    ts = task_sigmas(r.mode, fit.X_H, fit.covariance, a.X_BE)
    lines.append(f"  σ of a point {ts['point_in_front_distance_m']:g} m in front of the camera "
                 f"{1000 * ts['point_in_front_m']:.3f} mm; of the tool-centre point (flange "
                 f"origin) {1000 * ts['tool_centre_point_m']:.3f} mm")
    if r.settings["fixed"]:
        lines.append(f"  held at known values: {', '.join(f'{k}={v:g}' for k, v in r.settings['fixed'].items())}")
    lines.append(f"{fixed} translation (mm) {_vec(1000 * fit.X_F[:3, 3], '{:+9.2f}')}")
    lines.append("")
    n = fit.noise
    lines.append(f"noise per axis of the camera (from the residuals): rotation "
                 f"{_vec(np.degrees(n.rotation), '{:.4f}')}° / translation "
                 f"{_vec(1000 * n.translation, '{:.4f}')} mm about / along x y z"
                 + ("" if n.scale is None else
                    f"; per-sample covariances × {n.scale:.3g} (σ factor from the residuals)"))
    lines.append("residuals per sample     rotation (deg)            translation (mm)")
    lines.append("                         median   rms      max     median   rms      max")
    for name, s in (("fit", r.fit_residuals), ("held out", r.held_out_residuals)):
        if s.get("count", 0):
            rd, tm = s["rotation_deg"], s["translation_m"]
            lines.append(f"  {name:<9}({s['count']:>5}) {rd['median']:8.4f} {rd['rms']:8.4f} "
                         f"{rd['max']:8.4f}  {1000 * tm['median']:8.3f} {1000 * tm['rms']:8.3f} "
                         f"{1000 * tm['max']:8.3f}")
        else:
            lines.append(f"  {name:<9}(none)")
    lines.append(f"{fixed} implied by each sample: spread {r.spread.rotation_rms_deg:.4f}° / "
                 f"{1000 * r.spread.translation_rms:.3f} mm RMS")
    if r.split is not None:
        lines.append(f"split-half check: halves {r.split.rotation_diff_deg:.4f}° / "
                     f"{1000 * r.split.translation_diff:.3f} mm apart, NEES {r.split.nees:.3g} "
                     f"(≤ {r.split.threshold:.3g} expected)")
    if r.observability is not None:
        for line in r.observability.lines():
            lines.append(line)
    if r.online is not None:
        lines.append(f"on-line replay (keyframes ≥ {r.online[0].step_deg:g}° apart, from the same "
                     "two-motion start): difference to the batch result at the end, and the "
                     "filter's own 1σ")
        for o in r.online:
            if not len(o.times):
                lines.append(f"  {o.label}: no motion fused")
                continue
            lines.append(
                f"  {o.label:<38} {len(o.times):4d} motions: {o.rotation_diff_deg[-1]:.4f}° / "
                f"{1000 * o.translation_diff[-1]:.3f} mm; σ {np.linalg.norm(o.rotation_std_deg):.3g}°"
                f" / {1000 * np.linalg.norm(o.translation_std):.3g} mm; NEES "
                f"{o.final_nees(r.fit.X_H):.3g}")
            for d in o.diagnostics:
                lines.append(f"    not to be trusted: {d}")
    lines.append("")
    lines.append(r.verdict.line())
    for reason in r.verdict.reasons:
        lines.append(f"  {reason.level}: {reason.message}")
    for w in r.warnings:  # a note the verdict already gives as a reason is not said twice
        if not any(w in reason.message for reason in r.verdict.reasons):
            lines.append(f"  note: {w}")
    return "\n".join(lines)


def _strict_json(value):
    """Non-finite floats (a skipped image's RMS, an unbounded σ) as null: strict JSON."""
    if isinstance(value, dict):
        return {k: _strict_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_strict_json(v) for v in value]
    if isinstance(value, float):
        return _finite(value)
    return value


def write_json(result, path) -> Path:
    doc = _strict_json(to_dict(result))
    Path(path).write_text(json.dumps(doc, indent=2, allow_nan=False) + "\n")
    return Path(path)

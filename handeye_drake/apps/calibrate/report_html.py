"""``report.html``: the verification report ``calibrate`` writes beside ``calibration.json``.

One self-contained file a person opens in a browser to decide whether to trust a calibration:
no network, no script — the CSS is inline, the plots are embedded (matplotlib, SVG/PNG as data
URIs), the images as downscaled JPEG (at most ``MAX_IMAGE_WIDTH`` px wide). In reading order:

1. the verdict and its reasons (then the notes);
2. the result: X_EC (eye-in-hand) or X_BC (eye-to-hand) with its 1σ, the task-space σ, the fixed
   pose X_BT / X_ET, the camera noise per axis;
3. image inputs: one panel per image, worst first (an index links to every panel), with the
   detected corners, the corners predicted through the calibrated chain
   X_CT = X_H⁻¹ · X_R⁻¹ · X_F (X_R: the robot-side pose of the image, ``result.aligned.X_BE``)
   and projected with the intrinsics the answer used, and the residual vectors
   (detected − predicted, px) magnified by one factor for all images; pose-file inputs get the
   pose residual components per sample instead;
4. residuals per sample (angle and distance between measured and predicted X_CT), outliers
   marked;
5. the robot, camera and target poses in the base frame B, as a static 3D picture;
6. the checks: observability, held-out test, split halves, and the alternatives tried.

Frames: monogram X_AB = pose of frame B in frame A (B: robot base, E: flange, C: camera optical
frame, T: target). Units: mm and degrees in the text, px in image panels.
"""

from __future__ import annotations

import base64
import html
import io
import math
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from ...estimation.se3 import inverse, quat_wxyz, rpy
from ...calibration.naming import fixed_name, hand_name, tangent_std
from ...calibration.pipeline import residual_vectors

#: Widest embedded image (px); wider images are downscaled (the corners stay in image pixels).
MAX_IMAGE_WIDTH = 640
#: Narrower images beyond this many panels, to keep the file small.
MANY_IMAGES = 60
MANY_IMAGE_WIDTH = 400
JPEG_QUALITY = 80
#: Panels drawn at most; the remaining images stay in the index with their numbers.
MAX_PANELS = 300
#: Magnified residual vectors: the 95th percentile of their lengths is drawn this long (px).
ARROW_PX = 25.0

_STATUS_COLOURS = {"OK": "#1b7f3b", "WARN": "#a86400", "FAIL": "#b3261e"}

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;
 margin:0;color:#1d1d1f;background:#f6f6f4;font-size:15px;line-height:1.45}
main{max-width:1180px;margin:0 auto;padding:12px 24px 48px}
h1{font-size:22px;margin:8px 0 4px}h2{font-size:19px;margin:28px 0 8px;
 border-bottom:1px solid #ccc;padding-bottom:3px}h3{font-size:16px;margin:14px 0 6px}
.sub{color:#555;font-size:13px;margin:0 0 10px}
nav{font-size:14px;margin:8px 0 6px}nav a{margin-right:14px}
.verdict{border-radius:8px;padding:12px 18px;color:#fff;margin:10px 0}
.verdict .status{font-size:28px;font-weight:700;letter-spacing:.5px}
.verdict ul{margin:6px 0 2px 0;padding-left:20px}.verdict li{margin:3px 0}
.lvl{font-weight:700;padding:0 5px;border-radius:3px;background:rgba(255,255,255,.25)}
.notes{background:#fff;border:1px solid #ddd;border-radius:6px;padding:6px 14px;font-size:14px}
.cards{display:flex;flex-wrap:wrap;gap:14px;align-items:flex-start}
.card{background:#fff;border:1px solid #ddd;border-radius:8px;padding:10px 16px;flex:1 1 300px}
.card.wide{flex:2 1 560px}
.refused .card{background:repeating-linear-gradient(135deg,#fff,#fff 12px,#fbeceb 12px,
 #fbeceb 24px);border:2px dashed #b3261e;color:#6b6b6b}
.refused .big{text-decoration:line-through;text-decoration-color:#b3261e}
.refusal{color:#b3261e;font-weight:700;font-size:17px;margin:6px 0}
table{border-collapse:collapse;font-size:14px;background:#fff}
td,th{border:1px solid #ddd;padding:3px 8px;text-align:left;vertical-align:top}
th{background:#eee}th.row{white-space:nowrap;font-weight:600;background:#f4f4f2}td.n{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
.big{font-size:16px;font-variant-numeric:tabular-nums}
pre{background:#fff;border:1px solid #ddd;padding:8px;font-size:13px;overflow-x:auto;
 white-space:pre-wrap}
img.plot{max-width:100%;height:auto;background:#fff;border:1px solid #ddd}
.panels{display:flex;flex-wrap:wrap;gap:14px}
.panel{background:#fff;border:1px solid #ddd;border-radius:6px;padding:6px 8px;
 flex:0 1 560px;max-width:100%}
.panel svg{width:100%;height:auto;display:block;background:#000}
.panel .cap{font-size:13px;margin:4px 0}
.bad{color:#b3261e;font-weight:600}.warn{color:#a86400;font-weight:600}
.legend span{margin-right:14px;white-space:nowrap}
.index{max-height:330px;overflow-y:auto;display:inline-block}
.err{color:#b3261e}
"""


def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _num(v, fmt="{:.3g}") -> str:
    try:
        v = float(v)
    except (TypeError, ValueError):
        return "–"
    return "∞" if math.isinf(v) else ("–" if math.isnan(v) else fmt.format(v))


def _fig_uri(fig, fmt: str = "svg", dpi: int = 100, tight: bool = True) -> str:
    """A matplotlib figure as a data URI (SVG text kept as text: small, sharp at any zoom);
    ``tight`` crops it (one more draw: not for figures laid out already)."""
    import matplotlib.pyplot as plt
    buf = io.BytesIO()
    with plt.rc_context({"svg.fonttype": "none"}):
        fig.savefig(buf, format=fmt, dpi=dpi, bbox_inches="tight" if tight else None)
    plt.close(fig)
    mime = "image/svg+xml" if fmt == "svg" else "image/png"
    return f"data:{mime};base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _img(uri: str, alt: str) -> str:
    return f'<img class="plot" src="{uri}" alt="{_e(alt)}">'


def _section(title: str, anchor: str, build) -> str:
    """A section; a drawing that fails is reported in the page (the calibration stands)."""
    try:
        body = build()
    except Exception as e:  # noqa: BLE001 — a broken plot must not lose the report
        body = f'<p class="err">this part could not be drawn: {_e(type(e).__name__)}: {_e(e)}</p>'
    if not body:
        return ""
    return f'<section id="{anchor}"><h2>{_e(title)}</h2>{body}</section>'


# ------------------------------------------------------------------------------- the numbers
def _predicted_X_CT(result) -> np.ndarray:
    """(M, 4, 4) X_CT of every aligned sample through the result: X_H⁻¹ · X_R⁻¹ · X_F (for a
    corner-level answer the fit's own chain, at the target scale it found: the answer's midpoint
    between the scale's two readings is not one the pixels show)."""
    X_R = np.asarray(result.aligned.X_BE, float)
    fit = result.corners.fit if result.corners is not None else result.fit
    return inverse(fit.X_H)[None] @ np.linalg.inv(X_R) @ fit.X_F[None]


def _pose_residuals(result):
    """(deg, m) per aligned sample at the final answer (for image inputs the corner-level one,
    not the pose-level fit the stored residuals were computed with)."""
    from ...estimation.consistency import pose_residuals
    a = result.aligned
    return pose_residuals(np.asarray(a.X_BE), np.asarray(a.X_CT), result.fit.X_H,
                          result.fit.X_F)


def _sample_status(result) -> np.ndarray:
    """(M,) per aligned sample: "fit", "held_out", "outlier", "excluded"; for a corner-level
    answer every image is in it ("fit") unless that fit rejected it ("outlier")."""
    if result.corners is not None:
        used = np.asarray(result.corners.fit.image_used, bool)
        return np.where(used, "fit", "outlier").astype(object)
    return np.asarray(result.sample_used, dtype=object)


def _intrinsics_vector(result, streams):
    """([fx fy cx cy k1 k2 p1 p2 k3], target scale) the answer's camera model: the corner-level
    fit's, else the intrinsics the detections were made with."""
    from ...estimation.reprojection import intrinsics_vector
    if result.corners is not None:
        f = result.corners.fit
        return np.asarray(f.intrinsics, float), float(f.scale)
    I = streams.intrinsics
    return intrinsics_vector(I.K, I.distortion), 1.0


def image_residuals(result, streams) -> list[dict]:
    """Per aligned image sample: the detected corners, the corners predicted through the
    calibrated chain (no per-image pose error: what the calibration alone says), and the
    residuals detected − predicted (px).

    Returns one dict per aligned sample k: ``sample`` k, ``line`` (camera line: image number
    for --images, message number for bags), ``detected`` (n, 2), ``predicted`` (n, 2),
    ``residuals`` (n, 2), ``rms_px`` (RMS of the residual norms), ``max_px``, ``fit_rms_px``
    (the corner-level fit's own, with the image's pose error; NaN without it), ``status``
    (``_sample_status``)."""
    from ...estimation.reprojection import project
    a = result.aligned
    v, scale = _intrinsics_vector(result, streams)
    X_CT = _predicted_X_CT(result)
    status = _sample_status(result)
    fit_rms = (np.asarray(result.corners.fit.image_rms_px, float) if result.corners is not None
               else np.full(len(a), np.nan))
    out = []
    for k, j in enumerate(np.asarray(a.camera_index, int)):
        det = streams.detections[j]
        P = scale * np.asarray(det.object_points, float)
        p_C = P @ X_CT[k, :3, :3].T + X_CT[k, :3, 3]
        predicted = project(p_C, v, jacobians=False)[0]
        detected = np.asarray(det.image_points, float).reshape(-1, 2)
        r = detected - predicted
        norms = np.linalg.norm(r, axis=1)
        out.append({"sample": k, "line": int(a.camera_lines[k]), "detected": detected,
                    "predicted": predicted, "residuals": r,
                    "rms_px": float(np.sqrt(np.mean(norms ** 2))) if len(norms) else math.nan,
                    "max_px": float(norms.max()) if len(norms) else math.nan,
                    "fit_rms_px": float(fit_rms[k]), "status": str(status[k])})
    return out


def _record_of_line(streams) -> dict:
    """Camera line → ``ImageRecord``: the image's rank + 1 for files, the message for bags."""
    return {(r.message if r.message is not None else k + 1): r
            for k, r in enumerate(streams.images)}


def _step_down(raw: float) -> float:
    """The largest 1-2-5 step ≤ raw (0.1 … 5e5)."""
    steps = [m * 10 ** e for e in range(-1, 6) for m in (1, 2, 5)]
    return float(max([s for s in steps if s <= raw] or [steps[0]]))


def magnification(samples) -> float:
    """One factor for the panels (1-2-5 steps): the 75th percentile of the residual lengths over
    every corner drawn ``ARROW_PX`` long (a percentile a few bad images do not set)."""
    norms = np.concatenate([np.linalg.norm(s["residuals"], axis=1) for s in samples]
                           or [np.zeros(0)])
    norms = norms[np.isfinite(norms)]
    if not len(norms) or np.percentile(norms, 75) <= 0:
        return 1.0
    return _step_down(ARROW_PX / float(np.percentile(norms, 75)))


def panel_magnification(sample, mag: float) -> float:
    """``mag``, or a smaller factor for an image whose residuals would be drawn longer than
    4 × ``ARROW_PX`` with it (they would leave the picture)."""
    norms = np.linalg.norm(sample["residuals"], axis=1)
    norms = norms[np.isfinite(norms)]
    if not len(norms) or mag * float(np.percentile(norms, 95)) <= 4 * ARROW_PX:
        return mag
    return min(mag, _step_down(ARROW_PX / float(np.percentile(norms, 95))))


def off_the_chain(samples) -> set:
    """Samples whose corners the calibrated chain predicts far worse than the others' (RMS beyond
    4 × the median image's and 0.5 px): a robot pose or an image that does not fit, even when
    the fit absorbed it in that image's pose error."""
    rms = np.array([s["rms_px"] for s in samples], float)
    if not np.isfinite(rms).any():
        return set()
    bound = max(4 * float(np.nanmedian(rms)), 0.5)
    return {s["sample"] for s in samples if np.isfinite(s["rms_px"]) and s["rms_px"] > bound}


def _jpeg_uri(path: str, width: int) -> tuple[str, int, int]:
    """(data URI, original width, original height) of an image file, downscaled to ``width``."""
    import cv2
    data = np.fromfile(str(path), dtype=np.uint8)
    image = cv2.imdecode(data, cv2.IMREAD_COLOR) if len(data) else None
    if image is None:
        raise ValueError(f"cannot read {path}")
    h, w = image.shape[:2]
    if w > width:
        image = cv2.resize(image, (width, max(1, round(h * width / w))),
                           interpolation=cv2.INTER_AREA)
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise ValueError(f"cannot encode {path}")
    return "data:image/jpeg;base64," + base64.b64encode(buf.tobytes()).decode("ascii"), w, h


def _panel_svg(sample, uri, w, h, mag) -> str:
    """The image with detected corners (green rings), predicted ones (red crosses) and the
    residual vectors × mag (yellow), in image pixels (OpenCV centres: +0.5 in SVG)."""
    s = max(w, h) / 560.0  # marks keep their size on screen whatever the image size
    parts = [f'<svg viewBox="0 0 {w} {h}" xmlns="http://www.w3.org/2000/svg" role="img">',
             f'<image href="{uri}" x="0" y="0" width="{w}" height="{h}"/>']
    arrows, rings, crosses = [], [], []
    for (u, v), (pu, pv), (du, dv) in zip(sample["detected"], sample["predicted"],
                                          sample["residuals"]):
        if not all(map(math.isfinite, (u, v, pu, pv))):
            continue
        pu, pv, u, v = pu + 0.5, pv + 0.5, u + 0.5, v + 0.5
        arrows.append(f"M{pu:.2f} {pv:.2f}L{pu + mag * du:.2f} {pv + mag * dv:.2f}")
        rings.append(f'<circle cx="{u:.2f}" cy="{v:.2f}" r="{6 * s:.2f}"/>')
        c = 5 * s
        crosses.append(f"M{pu - c:.2f} {pv:.2f}H{pu + c:.2f}M{pu:.2f} {pv - c:.2f}V{pv + c:.2f}")
    parts.append(f'<g fill="none" stroke="#2ee66b" stroke-width="{1.8 * s:.2f}">'
                 + "".join(rings) + "</g>")
    parts.append(f'<path d="{"".join(crosses)}" stroke="#ff3b30" stroke-width="{1.6 * s:.2f}" '
                 'fill="none"/>')
    parts.append(f'<path d="{"".join(arrows)}" stroke="#ffd60a" stroke-width="{2.6 * s:.2f}" '
                 'fill="none" stroke-linecap="round"/>')
    parts.append("</svg>")
    return "".join(parts)


# -------------------------------------------------------------------------------- the parts
def _verdict_html(result) -> str:
    v = result.verdict
    colour = _STATUS_COLOURS.get(v.status, "#444")
    items = "".join(f'<li><span class="lvl">{_e(r.level)}</span> {_e(r.message)} '
                    f'<small>({_e(r.code)})</small></li>' for r in v.reasons)
    what = {"OK": "the result is consistent with its data and can be used",
            "WARN": "the result can be used with care: read the reasons",
            "FAIL": "do not use this result: the reasons say what is wrong"}.get(v.status, "")
    out = (f'<div class="verdict" style="background:{colour}"><div class="status">verdict: '
           f'{_e(v.status)}</div><div>{_e(what)}</div>'
           + (f"<ul>{items}</ul>" if items else "") + "</div>")
    if result.warnings:
        out += ('<div class="notes"><b>Notes</b><ul>'
                + "".join(f"<li>{_e(w)}</li>" for w in result.warnings) + "</ul></div>")
    return out


def _pose_rows(X, covariance) -> str:
    from ...calibration.report import rpy_std_deg
    r_std, t_std = tangent_std(covariance)
    t, q = 1000 * X[:3, 3], quat_wxyz(X[:3, :3])
    ang, ang_std = np.degrees(rpy(X[:3, :3])), rpy_std_deg(X, covariance)
    rows = [("translation x y z (mm)", " ".join(f"{v:+.3f}" for v in t),
             " ".join(f"{v:.3f}" for v in 1000 * t_std)),
            ("roll pitch yaw (deg)", " ".join(f"{v:+.4f}" for v in ang),
             " ".join(f"{v:.4f}" for v in ang_std)),
            ("rotation about x y z (deg)", "", " ".join(f"{v:.4f}" for v in r_std)),
            ("quaternion w x y z", " ".join(f"{v:+.6f}" for v in q), "")]
    body = "".join(f'<tr><th class="row">{_e(a)}</th><td class="n big">{_e(b)}</td>'
                   f'<td class="n">{_e(c)}</td></tr>' for a, b, c in rows)
    matrix = "\n".join(" ".join(f"{v:+.6f}" for v in row) for row in X)
    return (f"<table><tr><th></th><th>value</th><th>± 1σ</th></tr>{body}</table>"
            f"<details><summary>4×4 matrix</summary><pre>{_e(matrix)}</pre></details>")


def _result_html(result) -> str:
    from ...calibration.task_space import task_sigmas
    fit, mode = result.fit, result.mode
    hand, fixed = hand_name(mode), fixed_name(mode)
    what = ("camera C in the end-effector (flange) frame E" if mode == "eye_in_hand" else
            "camera C in the robot base frame B")
    fixed_what = ("target T in the robot base B" if mode == "eye_in_hand" else
                  "target T on the flange E")
    ts = task_sigmas(mode, fit.X_H, fit.covariance, result.aligned.X_BE)
    accuracy = result.settings.get("robot_accuracy")
    acc = (f"; the σ include the robot's accuracy {accuracy[0]:g}° / {1000 * accuracy[1]:g} mm "
           "(--robot-accuracy)" if accuracy else "")
    n = fit.noise
    noise = (f"rotation {' '.join(f'{v:.4f}' for v in np.degrees(n.rotation))}° about, "
             f"translation {' '.join(f'{v:.4f}' for v in 1000 * n.translation)} mm along the "
             "camera's x y z")
    if result.corners is not None:
        f = result.corners.fit
        noise = (f"corners: {f.pixel_sigma:.3f} px per coordinate (RMS {f.rms_px:.3f} px); "
                 "pose-level: " + noise)
    held = result.settings.get("fixed") or {}
    refused = result.verdict is not None and result.verdict.status == "FAIL"
    # A FAIL's transform is shown for diagnosis only: struck through, hatched, and said so.
    banner = ('<p class="refusal">REFUSED — verdict FAIL: this is not a calibration; the '
              "transform the fit reached is shown struck through, for diagnosis only "
              "(the verdict's reasons say what is wrong).</p>" if refused else "")
    return (
        banner + f'<div class="cards{" refused" if refused else ""}"><div class="card wide">'
        f"<h3>{_e(hand)}: {_e(what)}{' — refused' if refused else ''}</h3>"
        f"{_pose_rows(fit.X_H, fit.covariance)}"
        '<p class="sub">roll-pitch-yaw: extrinsic X-Y-Z (URDF rpy); rotation σ: about the axes '
        f'of {"E" if mode == "eye_in_hand" else "B"}; 1σ from the fit{_e(acc)}.</p>'
        + (f"<p>held at known values (--fix): {_e(', '.join(f'{k}={v:g}' for k, v in held.items()))}</p>"
           if held else "")
        + '</div><div class="card"><h3>What the σ mean at the tool</h3>'
        f'<p class="big">point {ts["point_in_front_distance_m"]:g} m in front of the camera: '
        f'<b>{1000 * ts["point_in_front_m"]:.3f} mm</b><br>tool-centre point (flange origin): '
        f'<b>{1000 * ts["tool_centre_point_m"]:.3f} mm</b></p>'
        '<p class="sub">σ (RMS radius, √trace of the position covariance) of a point located '
        "through the calibrated transform.</p>"
        f"<h3>{_e(fixed)}: {_e(fixed_what)}</h3>"
        f'<p class="n big">translation {" ".join(f"{v:+.2f}" for v in 1000 * fit.X_F[:3, 3])} mm</p>'
        f"<h3>Measurement noise (from the residuals)</h3><p>{_e(noise)}</p>"
        "</div></div>")


def _inputs_html(result, streams) -> str:
    a = result.aligned
    used = result.sample_used
    rows = [("mode", result.mode.replace("_", "-")),
            ("robot", f"{result.robot.source} ({len(result.robot)} poses)"),
            ("camera", f"{result.camera.source} ({len(result.camera)} poses)"),
            ("aligned samples", f"{len(a)} (pose level: {int(np.sum(used == 'fit'))} fit, "
                                f"{int(np.sum(used == 'held_out'))} held out, "
                                f"{int(np.sum(used == 'outlier'))} outliers)"),
            ("time offset", "none (samples paired by index)" if a.camera_times is None else
             f"{a.time_offset:+.5f} s (camera stamp − robot time; {result.time_offset_mode})"),
            ("start", result.method),
            ("answer", "corner-level maximum likelihood" if result.corners is not None else
             "pose-level maximum likelihood (AX = ZB on the raw poses)")]
    images = (streams.inputs or {}).get("images") if streams is not None else None
    if images:
        rows.append(("images", f"{images.get('count')} ({images.get('detected')} with the "
                               f"target {images.get('target')}); intrinsics: "
                               f"{images.get('intrinsics')}"))
    out = "<table>" + "".join(f'<tr><th class="row">{_e(k)}</th><td>{_e(v)}</td></tr>'
                              for k, v in rows) + "</table>"
    if result.corners is not None:
        out += ("<h3>Corner-level fit</h3><pre>" + _e("\n".join(result.corners.lines()))
                + "</pre>")
    return out


def _images_html(result, streams) -> str:
    samples = image_residuals(result, streams)
    records = _record_of_line(streams)
    order = sorted(samples, key=lambda s: -s["rms_px"] if math.isfinite(s["rms_px"]) else 0)
    mag = magnification(samples)
    width = MAX_IMAGE_WIDTH if len(order) <= MANY_IMAGES else MANY_IMAGE_WIDTH
    from_bag = any(r.message is not None for r in streams.images)

    def name(s):
        r = records.get(s["line"])
        return (r.label() if r is not None else f"line {s['line']}")

    far = off_the_chain(samples)

    def status(s):
        if s["status"] == "outlier":
            text = '<span class="bad">rejected (outlier)</span>'
        else:
            text = {"fit": "in the answer" if result.corners is not None else "fit",
                    "held_out": "held out", "excluded": "excluded"}.get(s["status"], s["status"])
        if s["sample"] in far:
            text += ('; <span class="bad">far off the calibrated chain: check this image\'s '
                     "robot pose</span>")
        return text

    rms_all = np.array([s["rms_px"] for s in samples], float)
    out = [f'<p>{len(samples)} images in the calibration, worst first by the RMS of '
           "detected − predicted corners, the prediction through the calibrated chain "
           f"X_CT = {hand_name(result.mode)}⁻¹ · X_R⁻¹ · {fixed_name(result.mode)} (X_R = "
           + ("X_BE" if result.mode == "eye_in_hand" else "X_EB") + ", the robot's pose) and the "
           "intrinsics the answer used (no per-image pose error: what the calibration alone "
           f"predicts). Median {np.nanmedian(rms_all):.3f} px, worst {np.nanmax(rms_all):.3f} "
           'px. The fit\'s own RMS includes each image\'s estimated pose error.</p>'
           '<p class="legend"><span style="color:#1a9e47">◯ detected corner</span>'
           '<span style="color:#d62d20">+ predicted corner</span>'
           f'<span style="color:#b89600">— residual × {mag:g}</span></p>']
    if far:
        names = ", ".join(name(s) for s in order if s["sample"] in far)
        out.append(f'<p class="bad">{len(far)} image{"s" * (len(far) > 1)} far off the '
                   f"calibrated chain ({_e(names)}): the robot pose recorded with "
                   f"{'them' if len(far) > 1 else 'it'} does not fit the others — check "
                   "the pairing of images and poses, or record again.</p>")
    def short(s):  # plot ticks: a bag image by its message number
        r = records.get(s["line"])
        return f"msg {r.message}" if r is not None and r.message is not None else name(s)

    plot = _img(_image_rms_plot(samples, short), "RMS px per image")
    rows = []
    for rank, s in enumerate(order, 1):
        link = f'<a href="#img-{s["sample"]}">{_e(name(s))}</a>' if rank <= MAX_PANELS \
            else _e(name(s))
        rows.append(f'<tr><td class="n">{rank}</td><td>{link}</td><td class="n">'
                    f'{_num(s["rms_px"], "{:.3f}")}</td><td class="n">'
                    f'{_num(s["max_px"], "{:.3f}")}</td><td class="n">'
                    f'{_num(s["fit_rms_px"], "{:.3f}")}</td><td>{status(s)}</td></tr>')
    skipped = [r for r in streams.images if not r.found]
    aligned_lines = {s["line"] for s in samples}
    for k, r in enumerate(streams.images):
        key = r.message if r.message is not None else k + 1
        if r.found and key not in aligned_lines:
            skipped.append(r)
    for r in skipped:
        why = r.reason or "detected, but not paired with a robot pose (outside its time span)"
        rows.append(f'<tr><td class="n">–</td><td>{_e(r.label())}</td><td colspan="3"></td>'
                    f'<td class="warn">not used: {_e(why)}</td></tr>')
    out.append(f'<div class="cards"><div>{plot}</div><div><h3>Index</h3><div class="index">'
               "<table><tr><th>#</th><th>image</th><th>RMS (px)</th><th>max (px)</th>"
               "<th>fit RMS (px)</th><th>status</th></tr>" + "".join(rows)
               + "</table></div></div></div>")
    panels = []
    for rank, s in enumerate(order[:MAX_PANELS], 1):
        r = records.get(s["line"])
        source = (r.drawing if from_bag else r.path) if r is not None else ""
        try:
            uri, w, h = _jpeg_uri(source, width)
            m = panel_magnification(s, mag)
            picture = _panel_svg(s, uri, w, h, m)
        except (ValueError, OSError) as e:
            picture = f'<p class="err">image not embedded: {_e(e)}</p>'
        where = "" if r is None or r.robot_line is None else f", robot line {r.robot_line}"
        panels.append(
            f'<div class="panel" id="img-{s["sample"]}">{picture}<div class="cap">'
            f'<b>#{rank} {_e(name(s))}</b>{_e(where)} — RMS {_num(s["rms_px"], "{:.3f}")} px, '
            f'max {_num(s["max_px"], "{:.3f}")} px over {len(s["residuals"])} corners; '
            f'{status(s)}' + ("" if m == mag else f"; residuals × {m:g} here")
            + ' <a href="#images">↑ index</a></div></div>')
    if len(order) > MAX_PANELS:
        panels.append(f"<p>{len(order) - MAX_PANELS} more images: see the index.</p>")
    if from_bag:
        out.append('<p class="sub">Bag images: the drawings written under detections/ (the '
                   "detector's own marks are in them too).</p>")
    out.append(f'<div class="panels">{"".join(panels)}</div>')
    return "".join(out)


def _image_rms_plot(samples, name) -> str:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    x = np.arange(len(samples))
    rms = np.array([s["rms_px"] for s in samples])
    fit_rms = np.array([s["fit_rms_px"] for s in samples])
    bad = np.array([s["status"] == "outlier" for s in samples])
    fig, ax = plt.subplots(figsize=(6.4, 3.0) if len(samples) <= 40 else (11, 3.0))
    ax.bar(x, rms, color=np.where(bad, "#d62d20", "#4878a8"),
           label="detected − predicted through the calibration")
    if np.isfinite(fit_rms).any():
        ax.plot(x, fit_rms, "k_", ms=12, mew=2, label="fit (with the image's pose error)")
    if bad.any():
        ax.plot(x[bad], rms[bad] * 1.04, "v", color="#d62d20", label="rejected as outlier")
    ax.set_xticks(x)
    ax.set_xticklabels([name(s) for s in samples], rotation=90 if len(x) > 14 else 45,
                       ha="right", fontsize=7 if len(x) > 30 else 8)
    if len(x) > 80:
        ax.set_xticks(x[::max(1, len(x) // 40)])
        ax.set_xticklabels([name(samples[i]) for i in x[::max(1, len(x) // 40)]], rotation=90,
                           fontsize=7)
    ax.set_ylabel("RMS (px)")
    ax.set_title("Corner residuals per image", pad=26)
    ax.grid(True, axis="y", alpha=0.3)
    top = np.nanmax(np.concatenate([rms, fit_rms])) if len(rms) else 1.0
    ax.set_ylim(0, 1.12 * top if np.isfinite(top) and top > 0 else 1.0)
    # Above the axes, under the title: inside them it hid the top tick labels and tall bars.
    ax.legend(fontsize=7.5, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=2,
              frameon=False, borderaxespad=0.2, columnspacing=1.2)
    return _fig_uri(fig)


_MARKS = {"fit": dict(marker="o", color="#4878a8", ms=4, ls="none", label="fit"),
          "held_out": dict(marker="o", mfc="none", color="#1a9e47", ms=5, ls="none",
                           label="held out (validation)"),
          "outlier": dict(marker="x", color="#d62d20", ms=8, mew=2, ls="none", label="outlier"),
          "excluded": dict(marker=".", color="0.6", ls="none", label="excluded")}


def _sample_axis(result):
    a = result.aligned
    if a.camera_times is not None:
        return np.asarray(a.camera_times, float) - float(a.camera_times[0]), "camera time (s)"
    if isinstance(result.inputs, dict) and "images" in result.inputs:
        # Image k is the k-th file (1-based in the stream): numbered from 0 as the files
        # (img_000, ...) and the detections/ drawings are.
        return np.asarray(a.camera_lines, float) - 1, "image number (from 0, as the files)"
    return np.asarray(a.camera_lines, float), "camera file line"


def _residual_norms_plot(result) -> str:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    deg, dist = _pose_residuals(result)
    status = _sample_status(result)
    x, xlabel = _sample_axis(result)
    fig, axes = plt.subplots(2, 1, figsize=(10, 4.6), sharex=True)
    for ax, y, label in ((axes[0], deg, "rotation (deg)"), (axes[1], 1000 * dist,
                                                             "translation (mm)")):
        for s, style in _MARKS.items():
            m = status == s
            if m.any():
                ax.plot(x[m], y[m], **style)
        pos = y[np.isfinite(y) & (y > 0)]
        if len(pos) and pos.max() > 20 * np.median(pos):
            ax.set_yscale("log")  # outliers far above: the others stay readable
            from matplotlib.ticker import FuncFormatter
            ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))  # not 10^x
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].set_title("Pose residual per sample: measured X_CT against the one the result "
                      "predicts")
    axes[0].legend(fontsize=8, ncol=4, loc="upper right")
    axes[1].set_xlabel(xlabel)
    return _fig_uri(fig)


def _residual_components_plot(result) -> str:
    """Pose-file inputs: the residual components about / along the camera's axes, with the
    noise level the fit estimated (±3σ)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    a = result.aligned
    r = residual_vectors(np.asarray(a.X_BE), np.asarray(a.X_CT), result.fit.X_H,
                         result.fit.X_F)
    status = _sample_status(result)
    x, xlabel = _sample_axis(result)
    n = result.fit.noise
    sig = np.concatenate([np.degrees(n.rotation), 1000 * n.translation])
    vals = np.concatenate([np.degrees(r[:, :3]), 1000 * r[:, 3:]], axis=1)
    fig, axes = plt.subplots(2, 3, figsize=(11, 4.8), sharex=True)
    names = [f"rotation about C {c} (deg)" for c in "xyz"] + \
        [f"translation along C {c} (mm)" for c in "xyz"]
    for i, ax in enumerate(axes.ravel()):
        inl = status != "outlier"
        lim = np.nanpercentile(np.abs(vals[inl, i]), 99.5) if inl.any() else 1.0
        lim = max(lim, 4 * sig[i]) * 1.3
        # Points beyond the axis (outliers) are drawn on its edge, so they stay marked.
        shown = np.clip(vals[:, i], -0.96 * lim, 0.96 * lim)
        for s, style in _MARKS.items():
            m = status == s
            if m.any():
                ax.plot(x[m], shown[m], **{**style, "ms": 3 if s == "fit" else style.get("ms")})
        ax.axhspan(-3 * sig[i], 3 * sig[i], color="#4878a8", alpha=0.08, lw=0)
        ax.set_title(names[i], fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.set_ylim(-lim, lim)
    for ax in axes[1]:
        ax.set_xlabel(xlabel, fontsize=9)
    axes[0, 0].legend(fontsize=7, loc="lower left")
    fig.suptitle("Pose residual components (measured − predicted X_CT, in the camera frame)\n"
                 "band: ±3σ of the noise the fit estimated; points beyond an axis are drawn on "
                 "its edge", fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 0.92))
    return _fig_uri(fig, tight=False)


def _poses_3d_plot(result, streams) -> str:
    """The base frame B, the flange E and camera C of every sample, and the target T, in B
    (eye-in-hand: X_BC = X_BE · X_EC, one X_BT; eye-to-hand: one X_BC, X_BT = X_BE · X_ET),
    seen obliquely and from above. Lines are batched per colour (one collection each): a few
    hundred separate 3D lines take seconds to draw."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Line3DCollection
    mode, fit = result.mode, result.fit
    X_R = np.asarray(result.aligned.X_BE, float)
    X_BE = X_R if mode == "eye_in_hand" else np.linalg.inv(X_R)
    if mode == "eye_in_hand":
        X_BC, X_BT = X_BE @ fit.X_H[None], fit.X_F[None]
    else:
        X_BC, X_BT = fit.X_H[None], X_BE @ fit.X_F[None]
    status = _sample_status(result)
    drawn = _drawn(status)
    corners_T = _target_outline(streams)
    points = np.concatenate([X_BE[:, :3, 3], X_BC[:, :3, 3], X_BT[:, :3, 3],
                             np.zeros((1, 3))])
    span = float(np.max(np.ptp(points, axis=0))) or 0.5
    size = 0.06 * span
    colours = {"fit": "#2f6db0", "held_out": "#1a9e47", "outlier": "#d62d20",
               "excluded": "0.6"}
    axis_colours = ("#d62d20", "#1a9e47", "#2455c3")
    tips = np.array([[-0.6, -0.45, 1], [0.6, -0.45, 1], [0.6, 0.45, 1], [-0.6, 0.45, 1]]) * size

    def frame(X, length):
        return [[(X[:3, 3], X[:3, 3] + length * X[:3, i])] for i in range(3)]

    def frustum(X):
        w = tips @ X[:3, :3].T + X[:3, 3]
        return [(X[:3, 3], p) for p in w] + [(w[i], w[(i + 1) % 4]) for i in range(4)]

    def outline(T):
        w = corners_T @ T[:3, :3].T + T[:3, 3]
        return [(w[i], w[(i + 1) % 4]) for i in range(4)]

    # (segments, colour, width, alpha) of everything drawn, and the legend entries.
    groups, legend = [], [("flange E", dict(marker="o", color="0.3", ms=3, ls="none"))]
    frames = [(np.eye(4), 2 * size, 2.5)]
    targets = X_BT if len(X_BT) == 1 else X_BT[drawn]
    groups.append(([seg for T in targets for seg in outline(T)], "k",
                   1.5 if len(X_BT) == 1 else 0.7, 1.0))
    if mode == "eye_in_hand":
        frames.append((X_BT[0], 1.5 * size, 1.5))
        target = X_BT[0][:3, 3]
        for s_, c in colours.items():
            ks = [k for k in drawn if status[k] == s_]
            if not ks:
                continue
            groups.append(([seg for k in ks for seg in frustum(X_BC[k])], c,
                           1.6 if s_ == "outlier" else 0.9, 1.0))
            # The optical axis, as long as the distance to the target: where the camera looks.
            groups.append(([(X_BC[k][:3, 3], X_BC[k][:3, 3] + float(np.linalg.norm(
                target - X_BC[k][:3, 3])) * X_BC[k][:3, 2]) for k in ks], c, 0.4, 0.5))
            legend.append((f"camera C ({s_.replace('_', ' ')})", dict(color=c)))
        groups.append(([(X_BE[k, :3, 3], X_BC[k][:3, 3]) for k in drawn], "0.55", 0.6, 1.0))
        labels = [(X_BT[0][:3, 3], "  T")]
    else:
        groups.append((frustum(X_BC[0]), "#2f6db0", 1.5, 1.0))
        frames.append((X_BC[0], 1.5 * size, 1.5))
        bad = [k for k in range(len(X_BT)) if status[k] == "outlier"]
        if bad:
            groups.append(([seg for k in bad for seg in outline(X_BT[k])], "#d62d20", 1.5, 1.0))
            legend.append(("target T (outlier)", dict(color="#d62d20")))
        legend.append(("target T per sample", dict(color="k")))
        labels = [(X_BC[0][:3, 3], "  C")]
    for X, length, lw in frames:
        for i, seg in enumerate(frame(X, length)):
            groups.append((seg, axis_colours[i], lw, 1.0))
    fig = plt.figure(figsize=(12.5, 6))
    for n, (elev, azim, title) in enumerate(((25, -60, "oblique"), (89, -90, "from above"))):
        ax = fig.add_subplot(1, 2, n + 1, projection="3d")
        for segments, colour, lw, alpha in groups:
            if segments:
                ax.add_collection3d(Line3DCollection(np.asarray(segments, float), colors=colour,
                                                     linewidths=lw, alpha=alpha))
        ax.plot(X_BE[:, 0, 3], X_BE[:, 1, 3], X_BE[:, 2, 3], "o", color="0.3", ms=2.5)
        ax.text(0, 0, 0, "  B", fontsize=10)
        for p, text in labels:
            ax.text(*p, text, fontsize=10)
        lo, hi = points.min(axis=0) - size, points.max(axis=0) + size
        centre, half = (lo + hi) / 2, float(np.max(hi - lo)) / 2
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(centre[2] - half, centre[2] + half)
        ax.set_box_aspect((1, 1, 1))
        ax.set_xlabel("x_B (m)")
        ax.set_ylabel("y_B (m)")
        if n == 0:
            ax.set_zlabel("z_B (m)")
            for label, style in legend:
                ax.plot([], [], label=label, **style)
            ax.legend(fontsize=8, loc="upper left")
        else:
            # Seen from above the z axis is edge-on: its ticks would pile up in a corner.
            ax.set_zticks([])
            ax.tick_params(axis="y", pad=8)   # clear of the tick marks (they hid the minus)
            ax.set_xlabel("x_B (m)", labelpad=10)
            ax.set_ylabel("y_B (m)", labelpad=22)
        ax.view_init(elev=elev, azim=azim)
        ax.set_title(title, fontsize=10)
    fig.suptitle("Poses in the robot base B through the result (axes: x red, y green, z blue)",
                 fontsize=11)
    fig.subplots_adjust(left=0.0, right=1.0, top=0.92, bottom=0.02, wspace=0.0)
    return _fig_uri(fig, "png", dpi=100, tight=False)


def _drawn(status, most: int = 60) -> np.ndarray:
    """Samples drawn in the 3D picture: at most ``most`` evenly spaced, and every outlier."""
    n = len(status)
    idx = np.unique(np.linspace(0, n - 1, min(n, most)).round().astype(int)) if n else \
        np.zeros(0, int)
    return np.union1d(idx, np.flatnonzero(np.asarray(status) == "outlier")).astype(int)


def _target_outline(streams) -> np.ndarray:
    """(4, 3) corners in T of the target's detected extent (a 0.1 m square for pose files)."""
    dets = getattr(streams, "detections", None) or []
    if dets:
        P = np.concatenate([np.asarray(d.object_points, float) for d in dets])
        lo, hi = P.min(axis=0), P.max(axis=0)
    else:
        lo, hi = np.array([-0.05, -0.05, 0]), np.array([0.05, 0.05, 0])
    return np.array([[lo[0], lo[1], 0], [hi[0], lo[1], 0], [hi[0], hi[1], 0], [lo[0], hi[1], 0]])


def _checks_html(result) -> str:
    from ...calibration.checks import held_out_test
    out = []
    if result.observability is not None:
        o = result.observability
        state = ("not observable" if not o.observable else "weakly observable" if o.weak
                 else "observable")
        out.append(f"<h3>Observability: {_e(state)}</h3><pre>"
                   + _e("\n".join(o.lines())) + "</pre>")
    rows = []
    t = held_out_test(result)
    if t is not None:
        ok = t["ratio"] <= t["bound"]
        rows.append(("held-out samples (F-test)", f"mean whitened residual² {t['ratio']:.3g}× "
                     f"the fit's (99.9 % bound {t['bound']:.3g}); worst line {t['worst_line']}",
                     ok))
    if result.split is not None:
        s = result.split
        rows.append(("split halves", f"{s.rotation_diff_deg:.4f}° / "
                     f"{1000 * s.translation_diff:.3f} mm apart, NEES {s.nees:.3g} "
                     f"(≤ {s.threshold:.3g})", s.consistent))
    sp = result.spread
    rows.append((f"{fixed_name(result.mode)} implied per sample",
                 f"spread {sp.rotation_rms_deg:.4f}° / {1000 * sp.translation_rms:.3f} mm RMS",
                 None))
    if result.corners is not None and result.corners.scale.get("factor") is not None:
        sc = result.corners.scale
        rows.append(("target scale from the pixels", f"{sc['factor']:.5f} ± {sc['std']:.5f} "
                     "(1 = the declared size)", not sc.get("significant", False)))
    body = "".join(f"<tr><th>{_e(a)}</th><td>{_e(b)}</td><td>"
                   + ("" if ok is None else ("pass" if ok else '<span class="bad">fail</span>'))
                   + "</td></tr>" for a, b, ok in rows)
    out.append(f"<h3>Consistency</h3><table>{body}</table>")
    return "".join(out)


#: Names of the alternatives whose description is only set when they apply.
_ALTERNATIVE_NAMES = {"camera_scale": "the camera's translations at another scale (a wrong "
                                      "target size, or a target printed at another scale)",
                      "camera_focal": "the camera's depths at another scale (a wrong focal "
                                      "length in the intrinsics that measured the poses)"}


def _alternatives_html(result) -> str:
    from ...calibration.checks import explaining
    hyps = result.hypotheses or []
    if not hyps:
        return "<p>none tried</p>"
    max_deg, max_m = result.settings["max_noise"]
    explains = {h.code for h in explaining(hyps, max_deg, max_m,
                                           result.settings["max_hand_eye_distance_m"])}
    rows = []
    for h in hyps:
        mark = ("the reference" if h.code == "as_read" else
                '<span class="bad">yes: explains the data better</span>' if h.code in explains
                else "no")
        # An alternative that was not fitted (its reading did not apply: e.g. the best camera
        # scale is the one given) has no residuals: "–", not an infinitely bad fit.
        values = (h.rotation_deg, 1000 * h.translation_m, h.hand_eye_distance)
        fitted = not h.error or all(math.isfinite(float(v)) for v in values)
        err = (f'<br><small class="err">{"" if fitted else "not fitted: "}{_e(h.error)}'
               "</small>" if h.error else "")
        description = h.description or _ALTERNATIVE_NAMES.get(h.code, h.code.replace("_", " "))
        numbers = "".join(f'<td class="n">{_num(v, "{:.3g}") if fitted else "–"}</td>'
                          for v in values)
        rows.append(f"<tr><td>{_e(description)}{err}</td>{numbers}"
                    f"<td>{mark}</td><td>{_e(h.fix) or '–'}</td></tr>")
    return ("<p>The usual mistakes, each undone and re-fitted quickly on a subset of the samples "
            "(median pose residuals): one that fits far better than the data as read is named "
            "by the verdict.</p><table><tr><th>reading</th><th>rotation (deg)</th>"
            "<th>translation (mm)</th><th>|t| of the hand-eye (m)</th><th>better than as read?</th>"
            "<th>fix</th></tr>"
            + "".join(rows) + "</table>")


# ------------------------------------------------------------------------------- the entry
def write_report_html(result, streams, out_dir) -> Path:
    """Writes ``report.html`` (see the module docstring) into ``out_dir`` (an
    ``apps.outputs.OutputDir`` or a directory path) and returns its path.

    Args:
        result: the ``pipeline.CalibrationResult`` (any verdict, FAIL included).
        streams: the ``inputs.Streams`` it was computed from (images, detections, intrinsics).
    """
    path = out_dir.path("report.html") if hasattr(out_dir, "path") else \
        Path(out_dir) / "report.html"
    path.write_text(build_report_html(result, streams), encoding="utf-8")
    return path


def build_report_html(result, streams) -> str:
    """The text of ``report.html``."""
    from ... import __version__
    hand = hand_name(result.mode)
    has_images = result is not None and bool(getattr(streams, "detections", None))
    parts = [_section("Verdict", "verdict", lambda: _verdict_html(result)),
             _section(f"Result: {hand}", "result", lambda: _result_html(result))]
    if has_images:
        parts.append(_section("Images: detected and predicted corners", "images",
                              lambda: _images_html(result, streams)))
    else:
        parts.append(_section("Pose residuals", "pose-residuals",
                              lambda: _img(_residual_components_plot(result),
                                           "pose residual components")))
    parts += [
        _section("Residuals per sample", "residuals",
                 lambda: _img(_residual_norms_plot(result), "residuals per sample")),
        _section("Poses around the target", "poses",
                 lambda: _img(_poses_3d_plot(result, streams), "poses in 3D")),
        _section("Checks", "checks", lambda: _checks_html(result)),
        _section("Alternatives tried", "alternatives", lambda: _alternatives_html(result)),
        _section("Inputs and method", "inputs", lambda: _inputs_html(result, streams))]
    nav = [("verdict", "Verdict"), ("result", "Result")] + (
        [("images", "Images")] if has_images else [("pose-residuals", "Pose residuals")]) + [
        ("residuals", "Residuals"), ("poses", "Poses"), ("checks", "Checks"),
        ("alternatives", "Alternatives"), ("inputs", "Inputs")]
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    status = result.verdict.status
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{_e(status)} — hand-eye calibration report</title><style>{_CSS}</style>"
        "</head><body><main>"
        f"<h1>Hand-eye calibration: {_e(hand)} ({_e(result.mode.replace('_', '-'))})</h1>"
        f'<p class="sub">handeye-drake {_e(__version__)} calibrate, {_e(stamp)}; frames: '
        "X_AB is the pose of B in A (B robot base, E flange, C camera optical frame, T target)"
        "</p><nav>" + "".join(f'<a href="#{a}">{_e(t)}</a>' for a, t in nav) + "</nav>"
        + "".join(parts) + "</main></body></html>\n")


__all__ = ["build_report_html", "image_residuals", "magnification", "write_report_html"]

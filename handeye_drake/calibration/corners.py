"""The answer for image inputs: the corner-level maximum-likelihood fit
(``estimation.reprojection``) over every inlier image, started from the pose-level result, with
the intrinsics refined as chosen (``--refine-intrinsics``, default ``auto``: the model whose
left-out images are predicted best), and the pixel-level checks of the verdict: the target's
scale (a wrong declared size, named with its factor), the given intrinsics against what the
images say, the pixel noise.

Frames as ``pipeline``: X_H is X_EC (eye-in-hand) or X_BC (eye-to-hand), X_F is X_BT or X_ET;
covariances [δθ (rad); δt (m)] with R = exp(δθ) R̂.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ..estimation.reprojection import (INTRINSICS_MODELS, INTRINSICS_NAMES, CornerData,
                                        CornerFit, cross_validate, fit_corners,
                                        intrinsics_matrix, intrinsics_vector,
                                        select_intrinsics_model)
from ..estimation.se3 import rotation_log
from ..estimation.consistency import with_scaled_translations
from .checks import Reason, Verdict, _quick_fit
from .held_intrinsics import apply_held_check
from .pipeline import calibrate_streams, robot_error_covariance

REFINE_CHOICES = INTRINSICS_MODELS + ("auto",)
#: A target scale this many σ from 1 (and more than ``SCALE_MIN_ERROR`` off) FAILs the verdict.
SCALE_SIGMAS = 5.0
SCALE_MIN_ERROR = 0.002
#: Given intrinsics this many σ from the refined ones, with the hand-eye result moved this many σ
#: by the difference: the given ones do not fit the images.
INTRINSICS_SIGMAS = 5.0
#: Pixel noise (px per coordinate) beyond which the corners do not fit any detector's noise.
MAX_PIXEL_SIGMA = 3.0
#: Fraction of images rejected by the corner-level fit: WARN beyond the first, FAIL beyond the
#: second.
IMAGE_OUTLIER_FRACTIONS = (0.1, 0.3)


@dataclass
class CornerStage:
    """What the corner-level stage did (``CalibrationResult.corners``)."""
    fit: CornerFit
    requested: str
    model: str
    why: str
    models: dict
    cv: dict
    scale: dict
    intrinsics_given: np.ndarray
    intrinsics_source: str
    pose_level_X_H: np.ndarray
    image_lines: list
    corner_image: np.ndarray = None      # (N,) image of each corner
    #: Factor on the covariances from the left-out images' prediction errors (≥ 1).
    variance_factor: float = 1.0
    reasons: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    def to_dict(self) -> dict:
        f = self.fit
        K, dist = intrinsics_matrix(f.intrinsics)
        sd = np.sqrt(np.maximum(np.diag(f.intrinsics_covariance), 0.0))
        cv_images = self.cv["image_rms_px"]
        return {
            "intrinsics": {"K": K.tolist(), "distortion": dist.tolist(),
                           "distortion_order": "k1 k2 p1 p2 k3",
                           "refined": self.model, "requested": self.requested,
                           "why": self.why, "source": self.intrinsics_source,
                           "sigma": {n: float(s) for n, s in zip(INTRINSICS_NAMES, sd)},
                           "given": dict(zip(INTRINSICS_NAMES,
                                             map(float, self.intrinsics_given)))},
            "corner_level": {
                "images_used": int(f.image_used.sum()), "images": len(f.image_used),
                "corners_used": int((f.corner_used & f.image_used[self.corner_image]).sum()),
                "corners": len(f.corner_used),
                "rms_px": f.rms_px, "pixel_sigma_px": f.pixel_sigma,
                "pose_error_sigma": {"frame": f.pose_error_frame,
                                     "rotation_deg": np.degrees(f.pose_sigma[:3]).tolist(),
                                     "translation_m": f.pose_sigma[3:].tolist()},
                "cross_validation": {"method": self.cv["method"],
                                     "rms_px": self.cv["rms_px"],
                                     "chi2_per_dof": self.cv.get("chi2_per_dof"),
                                     "covariance_factor": self.variance_factor},
                "models": self.models, "scale": self.scale,
                "per_image": [{"line": int(line), "used": bool(u), "rms_px": float(rms),
                               "predicted_rms_px": None if not np.isfinite(p) else float(p),
                               "pose_error_chi2": float(c)}
                              for line, u, rms, p, c in zip(self.image_lines, f.image_used,
                                                            f.image_rms_px, cv_images,
                                                            f.image_pose_chi2)],
                "pose_level_difference": _difference(self.pose_level_X_H, f.X_H),
                "held_intrinsics_test": getattr(self, "held", None),
                "notes": list(self.notes)}}

    def camera_intrinsics(self, like):
        """The intrinsics the answer was fitted with, as a ``CameraIntrinsics`` of ``like``'s
        image size."""
        from ..vision.camera_model import CameraIntrinsics
        K, dist = intrinsics_matrix(self.fit.intrinsics)
        return CameraIntrinsics.from_matrix(K, like.width, like.height, tuple(dist))

    def lines(self) -> list[str]:
        f = self.fit
        used = int(f.image_used.sum())
        rejected = [int(line) for line, u in zip(self.image_lines, f.image_used) if not u]
        n_c = int(f.corner_used.sum())
        out = [f"result: corner-level maximum likelihood on {used} of {len(f.image_used)} images "
               f"({n_c} of {len(f.corner_used)} corners), started from the pose-level fit"
               + (f"; images rejected: lines {', '.join(map(str, rejected))}" if rejected
                  else "")]
        v = f.intrinsics
        sd = np.sqrt(np.maximum(np.diag(f.intrinsics_covariance), 0.0))
        out.append(f"intrinsics ({self.model}; {self.why}): fx {v[0]:.2f} fy {v[1]:.2f} cx "
                   f"{v[2]:.2f} cy {v[3]:.2f} k1 {v[4]:+.4f} k2 {v[5]:+.4f} p1 {v[6]:+.5f} p2 "
                   f"{v[7]:+.5f} k3 {v[8]:+.4f}"
                   + ("" if self.model == "none" else
                      f"  (σ fx {sd[0]:.2f} cx {sd[2]:.2f} cy {sd[3]:.2f} px)"))
        out.append(f"pixels: RMS {f.rms_px:.3f} px over the corners (noise {f.pixel_sigma:.3f} px "
                   f"per coordinate; per-image pose error {np.degrees(np.linalg.norm(f.pose_sigma[:3])):.3g}° / "
                   f"{1000 * np.linalg.norm(f.pose_sigma[3:]):.3g} mm about the {f.pose_error_frame}); "
                   f"{self.cv['method']} prediction of left-out images {self.cv['rms_px']:.3f} px "
                   f"(χ²/dof {self.cv.get('chi2_per_dof', math.nan):.2f}"
                   + (f": σ widened ×{math.sqrt(self.variance_factor):.2f})"
                      if self.variance_factor > 1 else ")"))
        row = ", ".join(f"{m} {o['cv_rms_px']:.3f}" for m, o in self.models.items()
                        if o.get("cv_rms_px") is not None)
        if row:
            out.append(f"  left-out prediction (px) per intrinsics model: {row}")
        s = self.scale
        if s.get("factor") is not None:
            out.append(f"target scale from the pixels: {s['factor']:.5f} ± {s['std']:.5f} "
                       f"(1 = the declared size)")
        d = _difference(self.pose_level_X_H, f.X_H)
        out.append(f"pose-level result to corner-level: {d['rotation_deg']:.4f}° / "
                   f"{1000 * d['translation_m']:.3f} mm")
        return out


def _difference(X1, X2) -> dict:
    return {"rotation_deg": float(np.degrees(np.linalg.norm(rotation_log(
        X1[:3, :3] @ X2[:3, :3].T)))), "translation_m": float(np.linalg.norm(
            X1[:3, 3] - X2[:3, 3]))}


def _tangent(X1, X2) -> np.ndarray:
    return np.concatenate([rotation_log(X1[:3, :3] @ X2[:3, :3].T), X1[:3, 3] - X2[:3, 3]])


def corner_data(result, detections) -> tuple[CornerData, list]:
    """The aligned samples of a ``CalibrationResult`` with the corners of their detections
    (``detections[k]`` is the detection of camera sample k). Returns (data, camera lines)."""
    a = result.aligned
    X_R = np.asarray(a.X_BE)
    index = np.asarray(a.camera_index)
    dets = [detections[int(k)] for k in index]
    return (CornerData.from_lists(X_R, [d.object_points for d in dets],
                                  [d.image_points for d in dets]),
            [int(v) for v in np.asarray(a.camera_lines)])


def refine_with_corners(result, detections, intrinsics, refine: str = "auto",
                        robot_accuracy=None, intrinsics_source: str = "given",
                        scale0: float = 1.0) -> CornerStage:
    """Replaces the pose-level answer of ``result`` (a ``CalibrationResult`` of image inputs)
    with the corner-level fit and adds the pixel-level checks to its verdict.

    Args:
        detections: the ``vision.detection.TargetDetection`` of every camera sample.
        intrinsics: ``CameraIntrinsics`` the detections were made with.
        refine: one of ``REFINE_CHOICES``.
        robot_accuracy: (deg, m) or None, added to the covariance as for the pose-level fit.
        intrinsics_source: "given" (by the user or a CameraInfo) or "self-calibrated" (from the
            same images: "auto" then only offers the models that refine fx, fy, cx, cy).
        scale0: the target scale the camera poses were scaled by before the pose-level fit.
    """
    if refine not in REFINE_CHOICES:
        raise ValueError(f"--refine-intrinsics: expected one of {', '.join(REFINE_CHOICES)}, "
                         f"got {refine!r}")
    v0 = intrinsics_vector(intrinsics.K, intrinsics.distortion)
    data, lines = corner_data(result, detections)
    fit0 = result.fit
    frame = "camera" if result.mode == "eye_in_hand" else "target"
    n = fit0.noise
    ps0 = np.concatenate([n.rotation, n.translation]) if frame == "camera" else \
        np.repeat([np.linalg.norm(n.rotation) / math.sqrt(3),
                   np.linalg.norm(n.translation) / math.sqrt(3)], 3)
    rms = [d.reprojection_rms_px for d in detections if np.isfinite(d.reprojection_rms_px)]
    px0 = max(float(np.median(rms)) / math.sqrt(2) if rms else 0.3, 0.05)
    X_H0, X_F0 = fit0.X_H, fit0.X_F      # fitted to camera poses scaled by scale0
    kwargs = dict(pixel_sigma0=px0, pose_sigma0=ps0, pose_error_frame=frame)
    models = {}
    # Intrinsics from the same images: every model offered refines the principal point and
    # focal lengths they were estimated with (holding them would leave their error out of σ).
    candidates = INTRINSICS_MODELS if intrinsics_source == "given" else INTRINSICS_MODELS[2:]
    if refine == "auto":
        chosen, tried = select_intrinsics_model(
            data, X_H0, X_F0, v0, candidates, seed=result.seed,
            zero_fixed_distortion=intrinsics_source != "given", **kwargs) \
            if scale0 == 1.0 else _select_scaled(data, X_H0, X_F0, v0, candidates, scale0,
                                                 result.seed, kwargs)
        for m, o in tried.items():
            models[m] = {"cv_rms_px": None if o["cv"] is None else float(o["cv"]["rms_px"]),
                         "fit_rms_px": None if o["fit"] is None else float(o["fit"].rms_px),
                         "error": o["error"]}
        fit, cv = tried[chosen]["fit"], tried[chosen]["cv"]
        best = min(o["cv_rms_px"] for o in models.values() if o["cv_rms_px"] is not None)
        why = (f"auto: the smallest error predicting left-out images ({cv['rms_px']:.3f} px)"
               if cv["rms_px"] <= best * (1 + 1e-12) else
               f"auto: within 4 % of the best left-out prediction ({best:.3f} px) with fewer "
               "parameters")
    else:
        chosen = refine
        fit = fit_corners(data, X_H0, X_F0, v0, chosen, scale0=scale0, **kwargs)
        cv = cross_validate(data, fit, seed=result.seed)
        models[chosen] = {"cv_rms_px": float(cv["rms_px"]), "fit_rms_px": float(fit.rms_px),
                          "error": ""}
        why = "--refine-intrinsics " + refine
        if intrinsics_source != "given" and chosen == "none":
            why += " (intrinsics calibrated from the same images: their uncertainty is not in σ)"
    # The images left out must be predicted as well as the noise model says (whitened by the
    # predictive covariance of a new image); when they are worse, every σ is widened by the
    # factor they show (an a-posteriori variance factor, never a narrowing).
    factor = cv.get("chi2_per_dof", math.nan)
    inflation = float(factor) if np.isfinite(factor) and factor > 1.0 else 1.0
    if inflation > 1.0:
        fit.covariance = fit.covariance * inflation
        fit.fixed_covariance = fit.fixed_covariance * inflation
        fit.intrinsics_covariance = fit.intrinsics_covariance * inflation
        fit.covariance_full = fit.covariance_full * inflation
    stage = CornerStage(fit, refine, chosen, why, models, cv, {}, v0, intrinsics_source,
                        X_H0.copy(), lines, data.image, inflation)
    _scale_check(stage, data, kwargs)
    if intrinsics_source == "given":
        _intrinsics_check(stage, data, kwargs, tried if refine == "auto" else None)
        # The intrinsics the model holds fixed, tested against the pixels (held_intrinsics).
        full = tried.get("full", {}).get("fit") if refine == "auto" else None
        apply_held_check(stage, data, robot_accuracy, result.settings["max_noise"], full)
    _pixel_checks(stage, result.settings["max_noise"])
    _apply(result, stage, robot_accuracy)
    return stage


#: Target scales tried when the pose-level fit finds no answer at the declared size.
SCALE_SEARCH = np.exp(np.linspace(math.log(0.02), math.log(50.0), 57))


def calibrate_images(streams, settings: dict, refine: str = "auto"):
    """The calibration of image inputs: ``calibrate_streams`` on the detected poses (the start),
    then ``refine_with_corners``. When no hand-eye transform fits the poses at the declared
    target size, the target's scale is searched (a size off by a large factor breaks the
    pose-level start) and the corner-level fit measures it.

    Args:
        streams: ``inputs.Streams`` of ``image_streams`` or ``bag_image_streams``.
        settings: keyword arguments of ``calibrate_streams``.
        refine: ``--refine-intrinsics``."""
    scale0 = 1.0
    try:
        result = calibrate_streams(streams.robot, streams.camera, **settings)
    except ValueError:
        found = _search_scale(streams, settings)
        if found is None or not _explained(found[1]):
            raise
        scale0, result = found
    else:
        if result.verdict.status == "FAIL":
            # A target size off by a large factor reads like other mistakes (millimetres) at
            # pose level; the scale that explains the poses, if any, is measured from pixels.
            # Only a scale under which the poses pass the checks explains them (the scale's own
            # remainder aside: the pixels measure it exactly).
            found = _search_scale(streams, settings)
            if found is not None and _explained(found[1]):
                scale0, result = found
    try:
        refine_with_corners(result, streams.detections, streams.intrinsics, refine,
                            settings.get("robot_accuracy"), streams.intrinsics_source, scale0)
    except ValueError as e:
        if scale0 != 1.0:
            raise
        result.warnings.append(f"corner-level fit not done ({e}): the result is the pose-level "
                               "fit")
    return result


def _explained(result) -> bool:
    """The poses pass the checks, but for their own remaining scale (the pixels measure it)."""
    return all(r.code == "camera_scale" for r in result.verdict.reasons if r.level == "FAIL")


def _search_scale(streams, settings):
    """(scale, CalibrationResult of the camera poses scaled by it) for the scale whose quick
    pose fit leaves the smallest translation residuals, when one gives an answer; else None."""
    mode = settings.get("mode", "eye_in_hand")
    offset = settings.get("time_offset")
    offset = offset if isinstance(offset, (int, float)) else 0.0
    def cost(c):
        scaled = dataclasses.replace(streams.camera, poses=with_scaled_translations(
            streams.camera.poses, float(c)))
        try:
            value = _quick_fit(streams.robot, scaled, mode, offset)[1]
        except ValueError:
            return math.inf, scaled
        return (value if np.isfinite(value) else math.inf), scaled

    costs = [cost(c)[0] for c in SCALE_SEARCH]
    k = int(np.argmin(costs))
    if not np.isfinite(costs[k]):
        return None
    # Golden section on log c between the grid neighbours of the best point.
    lo = math.log(SCALE_SEARCH[max(k - 1, 0)])
    hi = math.log(SCALE_SEARCH[min(k + 1, len(SCALE_SEARCH) - 1)])
    g = (math.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
    f1, f2 = cost(math.exp(x1))[0], cost(math.exp(x2))[0]
    for _ in range(16):
        if f1 < f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - g * (hi - lo)
            f1 = cost(math.exp(x1))[0]
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + g * (hi - lo)
            f2 = cost(math.exp(x2))[0]
    c = math.exp(0.5 * (lo + hi))
    if abs(math.log(c)) < math.log(1.5):
        return None
    try:
        return c, calibrate_streams(streams.robot, cost(c)[1], **settings)
    except ValueError:
        return None


def _select_scaled(data, X_H0, X_F0, v0, candidates, scale0, seed, kwargs):
    """``select_intrinsics_model`` for a target whose declared size is off by ``scale0``."""
    tried = {}
    for m in candidates:
        try:
            f = fit_corners(data, X_H0, X_F0, v0, m, scale0=scale0, free_scale=True, **kwargs)
            tried[m] = {"fit": f, "cv": cross_validate(data, f, free_scale=True, seed=seed),
                        "error": ""}
        except ValueError as e:
            tried[m] = {"fit": None, "cv": None, "error": str(e)}
    ok = [(o["cv"]["rms_px"], m) for m, o in tried.items() if o["cv"] is not None]
    if not ok:
        raise ValueError("corner-level fit failed for every intrinsics model")
    return min(ok)[1], tried


def _scale_check(stage: CornerStage, data, kwargs) -> None:
    """Fits the target's scale too: a declared size that the pixels contradict FAILs, named with
    its factor (never blamed on the robot's units: robot poses are metric by construction here
    — a scale on the target alone is what the pixels measure)."""
    f = stage.fit
    try:
        g = fit_corners(data, f.X_H, f.X_F, f.intrinsics, stage.model, free_scale=True,
                        scale0=f.scale, pixel_sigma0=f.pixel_sigma, pose_sigma0=f.pose_sigma,
                        pose_error_frame=f.pose_error_frame)
    except ValueError as e:
        stage.scale = {"factor": None, "std": None, "error": str(e)}
        return
    g.scale_std *= math.sqrt(stage.variance_factor)
    z = (g.scale - 1.0) / max(g.scale_std, 1e-12)
    significant = abs(z) > SCALE_SIGMAS and abs(g.scale - 1.0) > SCALE_MIN_ERROR
    explained_by = ""
    if significant and stage.model not in ("k1k2", "full"):
        # A focal length or principal point held wrong also moves the camera poses' scale:
        # the scale is named only if it stays with the intrinsics refined too.
        try:
            c = fit_corners(data, g.X_H, g.X_F, f.intrinsics, "k1k2", free_scale=True,
                            scale0=g.scale, pixel_sigma0=f.pixel_sigma,
                            pose_sigma0=f.pose_sigma, pose_error_frame=f.pose_error_frame)
            zc = (c.scale - 1.0) / max(c.scale_std, 1e-12)
            if not (abs(zc) > SCALE_SIGMAS and abs(c.scale - 1.0) > SCALE_MIN_ERROR):
                significant, explained_by = False, "intrinsics"
        except ValueError:
            pass
    stage.scale = {"factor": float(g.scale), "std": float(g.scale_std), "z": float(z),
                   "significant": bool(significant),
                   "explained_by_intrinsics": explained_by == "intrinsics",
                   "meaning": "the target's true sizes are factor × those declared"}
    if significant:
        stage.reasons.append(Reason(
            "FAIL", "target_size",
            f"the target's declared size is wrong: the pixels say its sizes are "
            f"{g.scale:.4g}× those declared (± {g.scale_std:.2g}, {abs(z):.0f}σ from 1) — "
            f"multiply the square (and marker) sizes of --target by {g.scale:.4g}, or measure "
            "the printed target"))


def _intrinsics_check(stage: CornerStage, data, kwargs, tried) -> None:
    """Given intrinsics against the images: refined where the images determine them, do they
    move beyond their σ, and does that move the hand-eye result beyond its σ?"""
    f = stage.fit
    if stage.model == "none":
        # The user's intrinsics held: try them refined, and say so when they do not fit.
        try:
            alt = fit_corners(data, f.X_H, f.X_F, f.intrinsics, "k1k2",
                              pixel_sigma0=f.pixel_sigma, pose_sigma0=f.pose_sigma,
                              pose_error_frame=f.pose_error_frame)
            cv_alt = cross_validate(data, alt)
        except ValueError:
            return
        held, other = f, alt
        level, how = "FAIL", ("--refine-intrinsics auto (or recalibrate the camera)")
        better = cv_alt["rms_px"] < 0.9 * stage.cv["rms_px"]
        if not better:
            return
    else:
        base = (tried or {}).get("none")
        held = base["fit"] if base and base["fit"] is not None else None
        if held is None:
            try:
                held = fit_corners(data, f.X_H, f.X_F, stage.intrinsics_given, "none",
                                   pixel_sigma0=f.pixel_sigma, pose_sigma0=f.pose_sigma,
                                   pose_error_frame=f.pose_error_frame)
            except ValueError:
                return
        other = f
        level, how = "WARN", ("the answer uses the refined intrinsics; update the camera's "
                              "calibration")
    d = _tangent(held.X_H, other.X_H)
    nees = float(d @ np.linalg.solve(other.covariance, d))
    sd = np.sqrt(np.maximum(np.diag(other.intrinsics_covariance), 0.0))
    diff = other.intrinsics - stage.intrinsics_given
    z = np.where(sd > 0, np.abs(diff) / np.where(sd > 0, sd, 1.0), 0.0)
    if nees <= INTRINSICS_SIGMAS ** 2 or np.max(z) <= INTRINSICS_SIGMAS:
        return
    worst = [i for i in np.argsort(-z) if z[i] > INTRINSICS_SIGMAS][:4]
    what = ", ".join(f"{INTRINSICS_NAMES[i]} {stage.intrinsics_given[i]:.4g} → "
                     f"{other.intrinsics[i]:.4g} ± {sd[i]:.2g}" for i in worst)
    stage.reasons.append(Reason(
        level, "intrinsics",
        f"the intrinsics given do not fit the images: refined, {what}; with the given ones "
        f"{hand_name_for(stage)} would be {np.degrees(np.linalg.norm(d[:3])):.3g}° / "
        f"{1000 * np.linalg.norm(d[3:]):.3g} mm away ({math.sqrt(nees):.1f}σ) — {how}"))


def hand_name_for(stage: CornerStage) -> str:
    return "X_EC" if stage.fit.pose_error_frame == "camera" else "X_BC"


def _pixel_checks(stage: CornerStage, max_noise) -> None:
    """The pixels against plausible noise: the corners' scatter, the per-image pose error each
    image needs (bounded like a camera pose's noise, ``max_noise`` (deg, m) per axis), the
    images rejected."""
    f = stage.fit
    rot_deg, trans_m = np.degrees(np.max(f.pose_sigma[:3])), float(np.max(f.pose_sigma[3:]))
    if rot_deg > max_noise[0] or trans_m > max_noise[1]:
        stage.reasons.append(Reason(
            "FAIL", "pixel_residuals",
            f"the images do not fit one hand-eye transform: each needs its own pose error of "
            f"{rot_deg:.3g}° / {1000 * trans_m:.3g} mm per axis (plausible: ≤ {max_noise[0]:g}° "
            f"/ {1000 * max_noise[1]:g} mm, --max-noise); left-out images are predicted "
            f"{stage.cv['rms_px']:.3g} px off"))
    if f.pixel_sigma > MAX_PIXEL_SIGMA:
        stage.reasons.append(Reason(
            "FAIL", "pixel_residuals",
            f"the corners do not fit: pixel noise {f.pixel_sigma:.3g} px per coordinate after "
            f"the fit (plausible: ≤ {MAX_PIXEL_SIGMA:g} px) — images paired with the wrong robot "
            "poses, a moving target, or a wrong camera model"))
    K = len(f.image_used)
    out = K - int(f.image_used.sum())
    if out > IMAGE_OUTLIER_FRACTIONS[1] * K:
        stage.reasons.append(Reason("FAIL", "image_outliers",
                                    f"{out} of {K} images do not fit the others (corner-level)"))
    elif out > IMAGE_OUTLIER_FRACTIONS[0] * K:
        stage.reasons.append(Reason("WARN", "image_outliers",
                                    f"{out} of {K} images do not fit the others (corner-level)"))


#: Pose-level reasons the pixel-level checks supersede: the scale and intrinsics readings, and
#: the self-calibrated intrinsics' warning (their uncertainty is in the joint fit).
SUPERSEDED = ("camera_scale", "self_calibrated_intrinsics")
#: With a wrong target size or intrinsics, these reasons are its consequences, not other causes.
CONSEQUENCES = ("residuals", "sigma", "held_out", "camera_scale", "robot_millimetres",
                "camera_millimetres", "implausible_result", "outliers", "weak", "other_mode",
                "swapped_streams", "intrinsics", "image_outliers", "pixel_residuals")


def _apply(result, stage: CornerStage, robot_accuracy) -> None:
    """The corner-level answer and verdict into the ``CalibrationResult``."""
    f = stage.fit
    result.fit.X_H, result.fit.X_F = f.X_H.copy(), f.X_F.copy()
    cov = f.covariance.copy()
    if robot_accuracy is not None and any(robot_accuracy):
        cov = cov + robot_error_covariance(f.X_H, robot_accuracy)
    result.fit.covariance = cov
    result.fit.fixed_covariance = f.fixed_covariance.copy()
    reasons = [r for r in result.verdict.reasons if r.code not in SUPERSEDED]
    named = [r for r in stage.reasons if r.code in ("target_size", "intrinsics")]
    if named and (not any(r.code == "pixel_residuals" for r in stage.reasons)
                  or getattr(stage, "explained", False)):
        # The pose-level checks ran on poses measured with the wrong size or intrinsics: what
        # they flag are consequences of the cause the pixels name.
        reasons = [r for r in reasons if r.code not in CONSEQUENCES] + named[:1]
    else:
        reasons += stage.reasons
    result.warnings = [w for w in result.warnings
                       if not w.startswith("the camera poses' systematic uncertainty")]
    if stage.intrinsics_source != "given" and stage.model != "none":
        stage.notes.append("intrinsics calibrated from the same images, refined jointly: their "
                           "uncertainty is in the σ")
    status = "FAIL" if any(r.level == "FAIL" for r in reasons) else (
        "WARN" if reasons else "OK")
    result.verdict = Verdict(status, reasons)
    result.corners = stage


__all__ = ["CornerStage", "REFINE_CHOICES", "calibrate_images", "corner_data",
           "refine_with_corners"]

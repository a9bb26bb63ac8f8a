"""The answer for image inputs: the corner-level maximum-likelihood fit
(``estimation.reprojection``) over every inlier image, started from the pose-level result, with
the intrinsics refined as chosen (``--refine-intrinsics``, default ``auto``: the model whose
left-out images are predicted best), and the pixel-level checks of the verdict: the target's
scale (an unknown of the answer: a print off or the robot's translations scaled give the same
pixels, so the answer's σ covers both readings and a WARN names them up to ``SCALE_WARN_MAX``;
beyond, or a unit mistake, a FAIL names the factor — docs/target-scale.md), the given intrinsics
against what the images say, the pixel noise.

Frames as ``pipeline``: X_H is X_EC (eye-in-hand) or X_BC (eye-to-hand), X_F is X_BT or X_ET;
covariances [δθ (rad); δt (m)] with R = exp(δθ) R̂.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ..estimation.reprojection import (INTRINSICS_MODELS, INTRINSICS_NAMES, LOO_MAX_IMAGES,
                                        POSE_SIGMA_FLOOR, CornerData, CornerFit,
                                        cross_validate, fit_corners, intrinsics_matrix,
                                        intrinsics_vector, predict, scale_midpoint,
                                        select_intrinsics_model)
from ..estimation.se3 import rotation_log
from ..estimation.consistency import with_scaled_translations
from .checks import Reason, Verdict, _quick_fit
from .held_intrinsics import apply_held_check
from .pipeline import calibrate_streams, robot_error_covariance

REFINE_CHOICES = INTRINSICS_MODELS + ("auto",)
#: The target's scale s (true sizes / declared) is an unknown of the answer (docs/target-scale.md):
#: this many σ from 1 and more than ``SCALE_MIN_ERROR`` off, it is named — a WARN with both
#: readings (the print s× the declared size, or the robot's translations s× their true
#: lengths) up to ``SCALE_WARN_MAX`` off, a FAIL beyond (a size given or printed wrongly, not a
#: tolerance of a print or of a robot).
SCALE_SIGMAS = 5.0
SCALE_MIN_ERROR = 0.002
SCALE_WARN_MAX = 0.03
#: Factors that are a unit mistake (true / declared), named as such: inches, millimetres and
#: centimetres given as metres or the other way, within ``UNIT_TOLERANCE``.
UNIT_FACTORS = {0.0254: "inches given as metres", 1 / 0.0254: "metres given for inches",
                0.001: "millimetres given as metres", 1000.0: "metres given for millimetres",
                0.01: "centimetres given as metres", 100.0: "metres given for centimetres",
                25.4: "inches given for millimetres", 1 / 25.4: "millimetres given for inches",
                2.54: "inches given for centimetres", 1 / 2.54: "centimetres given for inches",
                10.0: "a decimal place off", 0.1: "a decimal place off"}
UNIT_TOLERANCE = 0.03
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
    #: The robot error that repeats over the recording, in the σ (``systematic_robot_level``).
    robot_level: dict = field(default_factory=dict)
    reasons: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    #: The fit with the target's scale free (``_scale_check``), and the answer from it that
    #: covers both readings of the scale: (X_H, X_F, cov_H, cov_F) (``scale_readings``).
    scale_fit: CornerFit = None
    scale_cv: dict = None
    scale_variance_factor: float = 1.0
    answer: tuple = None
    data: CornerData = None
    #: The plain corner bundle predicted left-out images better than the per-image robot-error
    #: weights (``_weighting``): the answer with the scale free is chosen the same way.
    plain_bundle: bool = False

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
                "systematic_robot_error": self.robot_level or None,
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
        lv = self.robot_level
        if lv and (lv["rotation_deg"] or lv["translation_m"]):
            out.append(f"σ holds a robot error repeating over the recording of "
                       f"{lv['rotation_deg']:.3g}° / {1000 * lv['translation_m']:.3g} mm per axis "
                       "(the larger of --robot-accuracy and the images' per-image pose error)")
        row = ", ".join(f"{m} {o['cv_rms_px']:.3f}" for m, o in self.models.items()
                        if o.get("cv_rms_px") is not None)
        if row:
            out.append(f"  left-out prediction (px) per intrinsics model: {row}")
        s = self.scale
        if s.get("factor") is not None:
            out.append(f"target scale from the pixels: {s['factor']:.5f} ± {s['std']:.5f} "
                       f"(1 = the declared size; an unknown of the answer)")
            rd = s.get("readings") or {}
            if "robot" in rd:
                hand = hand_name_for(self)
                mm = lambda X: " ".join(f"{1000 * v:+.2f}" for v in np.asarray(X)[:3, 3])
                out.append(f"  {hand} translation (mm) if the print is {s['factor']:.5g}× the "
                           f"declared size [{mm(rd['print'][hand])}], if the robot's "
                           f"translations are {s['factor']:.5g}× long [{mm(rd['robot'][hand])}] "
                           f"({1000 * rd['apart_m']:.3g} mm apart): the answer is their "
                           "midpoint, its σ covers both")
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
    weighting = ""
    if scale0 == 1.0:
        fit, cv, weighting = _weighting(data, fit, cv, result.seed)
        if weighting:
            why += "; " + weighting
    # The images left out must be predicted as well as the noise model says (whitened by the
    # predictive covariance of a new image); when they are worse, every σ is widened by the
    # factor they show (an a-posteriori variance factor, never a narrowing).
    factor = cv.get("chi2_per_dof", math.nan)
    inflation = float(factor) if np.isfinite(factor) and factor > 1.0 else 1.0
    _inflate(fit, inflation)
    stage = CornerStage(fit, refine, chosen, why, models, cv, {}, v0, intrinsics_source,
                        X_H0.copy(), lines, data.image, inflation, data=data,
                        plain_bundle=bool(weighting))
    _scale_check(stage, data, kwargs, result.seed)
    # The target's scale is an unknown of the answer: the checks below judge the fit with it.
    _use_scale(stage, "X_EC" if result.mode == "eye_in_hand" else "X_BC")
    if intrinsics_source == "given":
        _intrinsics_check(stage, data, kwargs, tried if refine == "auto" and
                          stage.scale_fit is None else None)
        # The intrinsics the model holds fixed, tested against the pixels (held_intrinsics).
        full = tried.get("full", {}).get("fit") if refine == "auto" else None
        apply_held_check(stage, data, robot_accuracy, result.settings["max_noise"], full)
    _pixel_checks(stage, result.settings["max_noise"])
    _apply(result, stage, robot_accuracy, data)
    return stage


def _weighting(data, fit, cv, seed):
    """The answer of the per-image robot-error model, or of a plain corner bundle (every corner
    of every image alike, the robot poses as exact, the same intrinsics model) when that
    predicts left-out images better: (fit, cross-validation, note or "").

    The per-image model weighs each image by how well its pose is known under Σ_e; on a real
    arm whose error repeats with the joint angles (a smooth error field, not independent draws)
    or with partly seen boards, that weighting can predict new images worse than equal weights
    (``benchmarks/loo_vs_bundle.py``). Which of the two predicts better is what the left-out
    images say, as for the intrinsics model. The σ is the per-image model's (with the
    repeating robot error added in ``_apply``) widened by the two answers' difference: the plain
    bundle's own, robot taken as exact, would be far too small. The noise levels, per-image errors and the images and corners the
    per-image model rejected stay as its own (the checks judge the data by them)."""
    if data.num_images < 4 or data.num_images > LOO_MAX_IMAGES:
        return fit, cv, ""
    floor = np.repeat(POSE_SIGMA_FLOOR, 3)
    # Both judged on every corner of every image, as a user's own left-out test counts them:
    # the per-image model without the images and corners it rejected, the plain bundle on all.
    try:
        cv_model = cross_validate(data, fit, every_corner=True)
        plain = fit_corners(data, fit.X_H, fit.X_F, fit.intrinsics, fit.model,
                            pixel_sigma0=fit.pixel_sigma, pose_sigma0=floor,
                            estimate_noise=False, robust=False, scale0=fit.scale,
                            pose_error_frame=fit.pose_error_frame)
        cv_plain = cross_validate(data, plain, every_corner=True)
    except ValueError:
        return fit, cv, ""
    if not cv_plain["rms_px"] < cv_model["rms_px"]:
        return fit, cv, ""
    # The plain bundle's poses and intrinsics, its residuals (no per-image error) on every corner.
    uv = np.empty_like(data.image_points)
    for k in range(data.num_images):
        sel = data.image == k
        uv[sel] = predict(plain, data.X_R[k], data.object_points[sel])
    r = data.image_points - uv
    ok = fit.corner_used & fit.image_used[data.image]
    n2 = np.sum(r ** 2, axis=1)
    K = data.num_images
    img_rms = np.sqrt(np.bincount(data.image, n2 * ok, K)
                      / np.maximum(np.bincount(data.image, ok.astype(float), K), 1))
    # The two weightings of the same data disagree by d: the answer is uncertain by at least
    # that (with errors that repeat, the pixel-best answer can sit further from the truth).
    d_H, d_F = _tangent(plain.X_H, fit.X_H), _tangent(plain.X_F, fit.X_F)
    full = fit.covariance_full.copy()
    full[:6, :6] += np.outer(d_H, d_H)
    full[6:12, 6:12] += np.outer(d_F, d_F)
    chosen = dataclasses.replace(fit, X_H=plain.X_H, X_F=plain.X_F, intrinsics=plain.intrinsics,
                                 scale=plain.scale, residuals=r, image_rms_px=img_rms,
                                 rms_px=float(math.sqrt(np.mean(n2[ok]))),
                                 covariance=fit.covariance + np.outer(d_H, d_H),
                                 fixed_covariance=fit.fixed_covariance + np.outer(d_F, d_F),
                                 covariance_full=full)
    # The predictive χ² stays the per-image model's (the plain bundle's noise model has no robot
    # error, so its χ² says nothing about σ).
    new_cv = dict(cv, rms_px=cv_plain["rms_px"], image_rms_px=cv_plain["image_rms_px"],
                  method=cv_plain["method"], weighted_rms_px=cv_model["rms_px"])
    return chosen, new_cv, (f"every corner of every image weighted alike (robot poses as "
                            f"exact): left-out "
                            f"images predicted {cv_plain['rms_px']:.3f} px, with the per-image "
                            f"robot-error weights {cv_model['rms_px']:.3f} px")


#: Target scales tried when the pose-level fit finds no answer at the declared size (a square of
#: 0.1 mm declared for 25 mm is 250×; millimetres for metres 1000×).
SCALE_SEARCH = np.exp(np.linspace(math.log(1e-3), math.log(2e3), 111))


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


def _scale_check(stage: CornerStage, data, kwargs, seed: int = 0) -> None:
    """Fits the target's scale s too (true sizes / declared: a print off, a wrong size given, or
    — the same pixels — the robot's translations s× their true lengths). Sets ``stage.scale``
    and, when the fit converges and the intrinsics do not explain the scale instead,
    ``stage.scale_fit`` (the fit with s free, its σ widened by its own left-out images)."""
    f = stage.fit
    try:
        g = fit_corners(data, f.X_H, f.X_F, f.intrinsics, stage.model, free_scale=True,
                        scale0=f.scale, pixel_sigma0=f.pixel_sigma, pose_sigma0=f.pose_sigma,
                        pose_error_frame=f.pose_error_frame)
    except ValueError as e:
        stage.scale = {"factor": None, "std": None, "error": str(e)}
        return
    # The free-scale fit's own left-out images set its variance factor (the fixed-size fit's
    # is inflated by the very scale error it leaves unmodelled).
    factor = math.nan
    try:
        stage.scale_cv = cross_validate(data, g, free_scale=True, seed=seed)
        factor = stage.scale_cv.get("chi2_per_dof", math.nan)
    except ValueError:
        pass
    inflation = float(factor) if np.isfinite(factor) and factor > 1.0 else 1.0
    if not np.isfinite(factor):
        inflation = stage.variance_factor
    _inflate(g, inflation)
    stage.scale_variance_factor = inflation
    if stage.plain_bundle and stage.scale_cv is not None:
        # At the declared size the plain bundle predicted left-out images better; the answer at
        # the fitted scale is held to the same test (its σ stays the weighted fit's, widened).
        g, stage.scale_cv, _ = _weighting(data, g, stage.scale_cv, seed)
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
            zc = (c.scale - 1.0) / max(c.scale_std * math.sqrt(inflation), 1e-12)
            if not (abs(zc) > SCALE_SIGMAS and abs(c.scale - 1.0) > SCALE_MIN_ERROR):
                significant, explained_by = False, "intrinsics"
        except ValueError:
            pass
    stage.scale = {"factor": float(g.scale), "std": float(g.scale_std), "z": float(z),
                   "significant": bool(significant),
                   "explained_by_intrinsics": explained_by == "intrinsics",
                   "meaning": "the target's true sizes are factor × those declared, or the "
                              "robot's translations are factor × their true lengths"}
    if explained_by:
        return
    stage.scale_fit = g
    unit = _unit_mistake(g.scale)
    if not significant:
        return
    f_s, sd = g.scale, g.scale_std
    span = _span_mm(data)
    off = abs(f_s - 1.0)
    if unit is None and off <= SCALE_WARN_MAX:
        return  # named with both readings by ``_use_scale`` (it knows the answers)
    what = (f"the sizes look like {unit}" if unit is not None else
            "a size given wrongly (a digit or a unit off, the square's size for the marker's)"
            if abs(math.log(f_s)) > math.log(1.5) else
            f"{100 * off:.3g} % is beyond a print's or a robot's tolerance (≤ "
            f"{100 * SCALE_WARN_MAX:g} % is answered with both readings): a size given wrongly "
            "(square for marker size, a ruler misread) or a print scaled to fit the page")
    robot = ("" if unit is not None or abs(math.log(f_s)) > math.log(1.5) else
             f"; or the robot's translations are {f_s:.4g}× their true lengths: the pixels "
             "cannot tell the two apart")
    stage.reasons.append(Reason(
        "FAIL", "target_size",
        f"the target's declared size is wrong: the pixels say its sizes are {f_s:.4g}× those "
        f"declared (± {sd:.2g}, {abs(z):.0f}σ from 1{robot}) — {what}; "
        f"multiply the square (and marker) sizes of --target by {f_s:.4g} (a circle grid's "
        f"SPACING and DIAMETER), or measure the printed target (its outermost detected points "
        f"{span:.4g} mm apart as declared)"))


def _inflate(fit: CornerFit, factor: float) -> None:
    if factor > 1.0:
        fit.covariance = fit.covariance * factor
        fit.fixed_covariance = fit.fixed_covariance * factor
        fit.intrinsics_covariance = fit.intrinsics_covariance * factor
        fit.covariance_full = fit.covariance_full * factor
        fit.scale_std = fit.scale_std * math.sqrt(factor)


def _unit_mistake(factor: float) -> str | None:
    """The unit mistake a target scale (true / declared) looks like, if any."""
    for u, name in UNIT_FACTORS.items():
        if abs(math.log(factor / u)) < math.log(1.0 + UNIT_TOLERANCE):
            return name
    return None


def _span_mm(data) -> float:
    """The largest distance (mm) between the target's detected corners, as declared."""
    P = np.unique(np.round(data.object_points, 9), axis=0)
    lo, hi = P.min(axis=0), P.max(axis=0)
    return float(1000 * np.linalg.norm(hi - lo))


def scale_readings(X_H, X_F, scale: float, covariance_full: np.ndarray):
    """The two readings of a target scale s ≠ 1 found with the scale free (X_H, X_F: the fit's,
    i.e. the reading "the print is s× its declared size"; the other reading, "the robot's
    translations are s× their true lengths", has the same rotations and every translation
    divided by s: the whole cell scaled by 1/s shows the same pixels), and the answer that covers
    both: the midpoint of the translations, with covariance the mean of the readings' plus the
    spread of their means (a 50/50 mixture: ¼ (t_A − t_B)(t_A − t_B)ᵀ, so each reading is 1σ
    from the answer along their difference).

    ``covariance_full``: the fit's G×G covariance of [δθ_H, δt_H, δθ_F, δt_F, …, s].
    Returns {"print": (X_H, X_F), "robot": (X_H, X_F), "answer": (X_H, X_F, cov_H, cov_F)}."""
    s = float(scale)
    out = {"print": (X_H.copy(), X_F.copy())}
    robot, answer, covs = [], [], []
    C = np.asarray(covariance_full)
    for i, X in ((0, X_H), (6, X_F)):
        idx = np.r_[np.arange(i, i + 6), C.shape[0] - 1]
        X_B, X_M, C_M = scale_midpoint(X, C[np.ix_(idx, idx)], s)
        robot.append(X_B)
        answer.append(X_M)
        covs.append(C_M)
    out["robot"] = tuple(robot)
    out["answer"] = (answer[0], answer[1], covs[0], covs[1])
    return out


def _use_scale(stage: CornerStage, hand: str) -> None:
    """The answer with the target's scale free (``stage.scale_fit``): both readings in
    ``stage.scale``, the answer covering both in ``stage.answer``, the fit with the scale free
    as ``stage.fit`` (the reading that matches the pixels as they are: predictions), and the
    WARN naming the factor, both readings and what tells them apart."""
    g = stage.scale_fit
    if g is None:
        return
    stage.fit = g
    if stage.scale_cv is not None:   # the answer's own left-out prediction and σ factor
        stage.cv, stage.variance_factor = stage.scale_cv, stage.scale_variance_factor
    if _unit_mistake(g.scale) is not None or abs(math.log(g.scale)) > math.log(1.5):
        # A unit or a size given wrongly: no robot is that far off; the answer is the one at
        # the pixels' scale (and the verdict a FAIL naming the factor).
        stage.scale["readings"] = {"print": {"meaning": "the target's true sizes are factor × "
                                             "those declared", hand: g.X_H.tolist()}}
        return
    r = scale_readings(g.X_H, g.X_F, g.scale, g.covariance_full)
    stage.answer = r["answer"]
    t_p, t_r = r["print"][0][:3, 3], r["robot"][0][:3, 3]
    apart = float(np.linalg.norm(t_p - t_r))
    stage.scale["readings"] = {
        "print": {"meaning": "the target's true sizes are factor × those declared; the robot "
                             "is right", hand: r["print"][0].tolist()},
        "robot": {"meaning": "the target is as declared; the robot's translations are factor "
                             "× their true lengths", hand: r["robot"][0].tolist()},
        "apart_m": apart,
        "answer": "the midpoint of the two readings' translations; its σ covers both"}
    s, sd, z = g.scale, g.scale_std, stage.scale["z"]
    if not stage.scale["significant"] or abs(s - 1.0) > SCALE_WARN_MAX             or _unit_mistake(s) is not None:
        return
    span = _span_mm(stage.data)
    mm = lambda t: "[" + " ".join(f"{1000 * v:+.1f}" for v in t) + "] mm"
    stage.reasons.append(Reason(
        "WARN", "target_scale",
        f"the target's sizes and the robot's translations disagree by a factor {s:.4g} (± "
        f"{sd:.2g}, {abs(z):.0f}σ from 1): either the target is printed {s:.4g}× its declared "
        f"size, or the robot's translations are {s:.4g}× their true lengths (its kinematic "
        f"model) — the pixels cannot tell the two apart. {hand} translation {mm(t_p)} if the "
        f"print is off, {mm(t_r)} if the robot is ({1000 * apart:.3g} mm apart); the answer is "
        f"their midpoint, its σ covers both. To tell them apart, measure the printed target: "
        f"its outer corners are {span:.5g} mm apart as declared, {span * s:.5g} mm if the print "
        f"is off (then multiply the sizes of --target by {s:.5g}); if it is as declared, the "
        f"robot's translations are {s:.4g}× long (check its kinematic model, or move it a "
        f"measured distance)"))


def _intrinsics_check(stage: CornerStage, data, kwargs, tried) -> None:
    """Given intrinsics against the images: refined where the images determine them, do they
    move beyond their σ, and does that move the hand-eye result beyond its σ?"""
    f = stage.fit
    fs = stage.scale_fit is not None     # the scale free in the answer: in these fits too
    if stage.model == "none":
        # The user's intrinsics held: try them refined, and say so when they do not fit.
        try:
            alt = fit_corners(data, f.X_H, f.X_F, f.intrinsics, "k1k2", free_scale=fs,
                              scale0=f.scale, pixel_sigma0=f.pixel_sigma,
                              pose_sigma0=f.pose_sigma, pose_error_frame=f.pose_error_frame)
            cv_alt = cross_validate(data, alt, free_scale=fs)
        except ValueError:
            return
        held, other = f, alt
        level, how = "FAIL", ("--refine-intrinsics auto (or recalibrate the camera)")
        own = stage.scale_cv if fs and stage.scale_cv is not None else stage.cv
        better = cv_alt["rms_px"] < 0.9 * own["rms_px"]
        if not better:
            return
    else:
        base = (tried or {}).get("none")
        held = base["fit"] if base and base["fit"] is not None else None
        if held is None:
            try:
                held = fit_corners(data, f.X_H, f.X_F, stage.intrinsics_given, "none",
                                   free_scale=fs, scale0=f.scale,
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


#: Pose-level reasons the pixel-level checks supersede: the scale and focal-length readings of
#: the poses, and the self-calibrated intrinsics' warning (their uncertainty is in the joint fit).
SUPERSEDED = ("camera_scale", "camera_focal", "self_calibrated_intrinsics")
#: With a wrong target size or intrinsics, these reasons are its consequences, not other causes.
CONSEQUENCES = ("residuals", "sigma", "held_out", "camera_scale", "robot_millimetres",
                "camera_millimetres", "implausible_result", "outliers", "weak", "other_mode",
                "swapped_streams", "intrinsics", "image_outliers", "pixel_residuals")


def systematic_robot_level(fit, robot_accuracy=None, depth: float = 0.0) -> tuple[float, float]:
    """(deg, m) per axis of the robot error that repeats over the recording, for the σ: the
    larger of ``robot_accuracy`` (given) and what the images' per-image pose error shows.

    A real arm's pose error at the millimetre level is kinematic: it repeats with the joint
    angles, so over one recording it does not average out as the per-image model assumes, and
    its constant and smooth parts are taken up by the hand-eye and fixed poses, unseen in any
    residual. The images' scatter measures its size, but only what is left of it: and the
    pixels tell a rotation of an image's pose from a translation only through perspective (a
    turn about x by δ moves the board like a shift along y by δ · ``depth``, the distance (m)
    from the camera to the target). So the level takes each part as large as both together,
    σ_r² + (σ_t / depth)² and σ_t² + (σ_r · depth)², constant over the recording
    (``pipeline.robot_error_covariance``). With independent per-image errors this is
    conservative by about √(images); with errors that repeat it keeps the truth inside the σ
    (``tests/calibration/test_compare.py``, ``benchmarks/loo_vs_bundle.py`` prints NEES)."""
    ps = np.asarray(fit.pose_sigma, float)
    sr = math.sqrt(float(np.mean(ps[:3] ** 2)))
    st = math.sqrt(float(np.mean(ps[3:] ** 2)))
    est_r = math.hypot(sr, st / depth) if depth > 0 else sr
    est_t = math.hypot(st, sr * depth)
    given = (0.0, 0.0) if not robot_accuracy else tuple(float(v) for v in robot_accuracy)
    return max(given[0], math.degrees(est_r)), max(given[1], est_t)


def _target_distance(fit, data) -> float:
    """Median distance (m) from the camera to the target's origin over the images used."""
    X_CT = fit.X_CT(data.X_R[fit.image_used])
    return float(np.median(np.linalg.norm(X_CT[:, :3, 3], axis=1))) if len(X_CT) else 0.0


def _apply(result, stage: CornerStage, robot_accuracy, data=None) -> None:
    """The corner-level answer and verdict into the ``CalibrationResult``."""
    f = stage.fit
    result.fit.X_H, result.fit.X_F = f.X_H.copy(), f.X_F.copy()
    cov = f.covariance.copy()
    fixed_cov = f.fixed_covariance.copy()
    if stage.answer is not None:     # the target's scale free: the answer covers both readings
        result.fit.X_H, result.fit.X_F = stage.answer[0].copy(), stage.answer[1].copy()
        cov, fixed_cov = stage.answer[2].copy(), stage.answer[3].copy()
    level = systematic_robot_level(f, robot_accuracy,
                                   0.0 if data is None else _target_distance(f, data))
    stage.robot_level = {"rotation_deg": level[0], "translation_m": level[1],
                         "given": None if not robot_accuracy else [float(v) for v in
                                                                   robot_accuracy]}
    if any(level):
        cov = cov + robot_error_covariance(f.X_H, level)
    result.fit.covariance = cov
    result.fit.fixed_covariance = fixed_cov
    reasons = [r for r in result.verdict.reasons if r.code not in SUPERSEDED]
    named = [r for r in stage.reasons if r.code in ("target_size", "intrinsics")]
    scaled = any(r.code == "target_scale" for r in stage.reasons)
    if (named or scaled) and (not any(r.code == "pixel_residuals" for r in stage.reasons)
                              or getattr(stage, "explained", False)):
        # The pose-level checks ran on poses measured with the wrong size or intrinsics: what
        # they flag are consequences of the cause the pixels name. (A scale answered with both
        # readings is in the fit the pixel-level checks judged: their reasons all stand.)
        reasons = [r for r in reasons if r.code not in CONSEQUENCES] + (
            named[:1] if named and named[0].code == "target_size" or not scaled
            else stage.reasons)
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

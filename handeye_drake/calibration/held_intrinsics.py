"""The intrinsics a restricted model holds fixed, tested against the pixels (issue 37).

``--refine-intrinsics focal`` (or ``pinhole``, ``k1k2``, ``none``) holds the other intrinsics at
the values given. A held value that is wrong (a principal point 30 px off, a tangential term, a
distortion of the wrong sign) does not show in the restricted fit's own checks: each image's
pose error and the pixel noise, both estimated, absorb it, and the answer moves many σ with a
verdict OK. The held values are hypotheses, as ``--fix`` values are, and are tested the same way:

1. the held parameters released too (the ``full`` model, robust, its noise levels estimated);
2. a likelihood-ratio test at those noise levels on the same inlier corners: the drop of the
   χ² (pixels and per-image pose errors, the latter marginalized by their prior) from the
   restricted model to the released one is χ²(m) under the held values (m released
   parameters) — beyond its 1 − 1e-6 quantile the pixels contradict them;
3. a contradiction that matters: released, the hand-eye answer moves more than
   ``MOVE_SIGMAS`` of its own σ (a statistically significant but immaterial gain — rendered
   images' interpolation artifacts — is no reason to refuse a recording);
4. the parameter named: greedy forward selection, the held parameter whose release explains
   most of the χ² drop first, then the next while what is left still contradicts.

The reason names the parameter, its given and released values with σ, how far the answer moves,
and the ``--refine-intrinsics`` model that releases it.

Frames and covariances as ``corners``: X_H is X_EC (eye-in-hand) or X_BC (eye-to-hand),
[δθ (rad); δt (m)] with R = exp(δθ) R̂.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import chi2

from ..estimation.reprojection import (INTRINSICS_MODELS, INTRINSICS_NAMES, CornerData,
                                        _selection, fit_corners)
from ..estimation.se3 import rotation_log
from .checks import Reason

#: Probability of the χ² quantile beyond which the held values are contradicted.
LR_PROBABILITY = 1.0 - 1e-6
#: The release must move the answer more than this many of its σ to matter; one that matters is
#: a FAIL (the answer at the held values would sit outside its own 3σ: never a WARN).
MOVE_SIGMAS = 3.0
FAIL_SIGMAS = MOVE_SIGMAS
#: Pixel noise (px) beyond which no detector's corners fit (``corners.MAX_PIXEL_SIGMA``).
MAX_PIXEL_SIGMA = 3.0
#: Greedy steps of the naming.
MAX_NAMED = 3
#: The smallest ``--refine-intrinsics`` model that refines each parameter.
_MODEL_OF = {"fx": "focal", "fy": "pinhole", "cx": "pinhole", "cy": "pinhole", "k1": "k1k2",
             "k2": "k1k2", "p1": "full", "p2": "full", "k3": "full"}


def _tangent(X1, X2) -> np.ndarray:
    return np.concatenate([rotation_log(X1[:3, :3] @ X2[:3, :3].T), X1[:3, 3] - X2[:3, 3]])


def held_parameters(model: str, v0) -> list[str]:
    """Names of the intrinsics ``model`` does not refine (the focal model's fy/fx ratio as fy)."""
    S = _selection(model, np.asarray(v0, float))
    out = []
    for i, name in enumerate(INTRINSICS_NAMES):
        col = np.zeros((9, 1))
        col[i, 0] = 1.0
        if np.linalg.matrix_rank(np.hstack([S, col])) > S.shape[1]:
            out.append(name)
    if "fx" in out and "fy" in out and S[0].any():
        out.remove("fx")              # the focal model: one of the two is held (their ratio)
    return out


#: Parameters released together as one unit too (a focal length error is in both, a principal
#: point error may be in both coordinates, a distortion in both terms of a pair).
PAIRS = (("fx", "fy"), ("cx", "cy"), ("k1", "k2"), ("p1", "p2"))
#: Penalty per released parameter when units of different sizes compete (the χ²(1) quantile
#: of 0.999): a pair is named only when it explains clearly more than its better half.
UNIT_PENALTY = float(chi2.ppf(0.999, 1))


def _units(held) -> list[tuple[str, ...]]:
    return [(n,) for n in held] + [p for p in PAIRS if p[0] in held and p[1] in held]


def _inliers(data: CornerData, fit) -> CornerData:
    use = np.flatnonzero(fit.image_used)
    sub = data.subset(use)
    keep = fit.corner_used[np.isin(data.image, use)]
    return CornerData(sub.X_R, sub.image[keep], sub.object_points[keep], sub.image_points[keep])


def _plausible(fit, max_noise) -> bool:
    return bool(math.degrees(float(np.max(fit.pose_sigma[:3]))) <= max_noise[0]
                and float(np.max(fit.pose_sigma[3:])) <= max_noise[1]
                and fit.pixel_sigma <= MAX_PIXEL_SIGMA)


def check_held_intrinsics(data: CornerData, fit, model: str, given, covariance,
                         released=None, max_noise=(1.0, 0.01)) -> dict | None:
    """Tests the intrinsics ``model`` holds fixed (see the module docstring).

    Args:
        data: the corners of every image (``corners.corner_data``).
        fit: the ``CornerFit`` of ``model`` (the answer).
        given: the intrinsics vector given by the user (9).
        covariance: 6×6 covariance of the answer X_H (as reported: robot accuracy included).
        released: a ``CornerFit`` of the ``full`` model on the same data, if one was made.
        max_noise: (deg, m) plausible per-axis pose error of an image (``--max-noise``).

    Returns None when nothing is held or the fits fail, else a dict: "statistic" (χ² drop),
    "dof", "bound", "move_sigmas", "move_deg", "move_m", "contradicted" (bool), "named"
    ([{name, given, released, std}]), "model" (the --refine-intrinsics that releases them),
    "released_fit" (the full model's fit)."""
    if model == "full" or model.split("+")[0] not in INTRINSICS_MODELS:
        return None
    held = held_parameters(model, fit.intrinsics)
    if not held:
        return None
    frame = fit.pose_error_frame
    # Every fit at the answer's target scale (the scale is an unknown of the answer: a fit at the
    # declared size would credit the intrinsics with the scale's misfit).
    scale = float(getattr(fit, "scale", 1.0))
    if released is not None and abs(float(getattr(released, "scale", 1.0)) - scale) > 1e-9:
        released = None
    try:
        if released is None:
            released = fit_corners(data, fit.X_H, fit.X_F, fit.intrinsics, "full",
                                   pixel_sigma0=fit.pixel_sigma, pose_sigma0=fit.pose_sigma,
                                   pose_error_frame=frame, scale0=scale)
        sub = _inliers(data, released)
        noise = dict(pixel_sigma0=released.pixel_sigma, pose_sigma0=released.pose_sigma,
                     estimate_noise=False, robust=False, pose_error_frame=frame, scale0=scale)
        top = fit_corners(sub, released.X_H, released.X_F, released.intrinsics, "full", **noise)
        c_top = _chi2(top)

        def restricted(name, start):
            g = fit_corners(sub, start.X_H, start.X_F, start.intrinsics, name, **noise)
            return g, _chi2(g)

        base, c_base = restricted(model, fit)
    except ValueError:
        return None
    m = 9 - _selection(model, fit.intrinsics).shape[1]
    stat = max(c_base - c_top, 0.0)
    bound = float(chi2.ppf(LR_PROBABILITY, m))
    d = _tangent(fit.X_H, released.X_H)
    P = np.asarray(covariance, float)
    move = math.sqrt(max(float(d @ np.linalg.solve(P, d)), 0.0))
    out = {"held": held, "statistic": stat, "dof": m, "bound": bound, "move_sigmas": move,
           "move_deg": math.degrees(float(np.linalg.norm(d[:3]))),
           "move_m": float(np.linalg.norm(d[3:])), "contradicted": False, "named": [],
           "model": None, "released_fit": released}
    # The restricted fit's own pixel-level plausibility (``corners._pixel_checks``' bounds):
    # when it fails them and the released fit passes, the held values are the likeliest cause
    # however wide the (noise-inflated) σ of the answer.
    out["restricted_plausible"] = _plausible(fit, max_noise)
    out["released_plausible"] = _plausible(released, max_noise)
    explains = not out["restricted_plausible"] and out["released_plausible"]
    out["matters"] = bool(move > MOVE_SIGMAS or explains)
    if not stat > bound:
        return out
    out["contradicted"] = True
    # Which held parameter(s) the pixels ask to release: forward selection by χ² drop.
    current, c_cur, cur_fit, named = model, c_base, base, []
    left = list(held)
    for _ in range(MAX_NAMED):
        trials = []
        for unit in _units(left):
            try:
                g, c = restricted(current + "".join("+" + n for n in unit), cur_fit)
            except ValueError:
                continue
            trials.append((c + UNIT_PENALTY * len(unit), unit, g, c))
        if not trials:
            break
        _, unit, g, c = min(trials, key=lambda t: t[0])
        named += [(n, g) for n in unit]
        left = [n for n in left if n not in unit]
        current, c_cur, cur_fit = current + "".join("+" + n for n in unit), c, g
        rest = max(c_cur - c_top, 0.0)
        d_rest = _tangent(g.X_H, top.X_H)
        free_left = 9 - _selection(current, fit.intrinsics).shape[1]
        if free_left <= 0 or rest <= chi2.ppf(LR_PROBABILITY, free_left) or (
                out["matters"] and math.sqrt(max(float(d_rest @ np.linalg.solve(P, d_rest)),
                                                 0.0)) <= MOVE_SIGMAS):
            break
    if not named:
        return out
    last = named[-1][1]
    sd = np.sqrt(np.maximum(np.diag(last.intrinsics_covariance), 0.0))
    out["named"] = [{"name": n, "given": float(given[INTRINSICS_NAMES.index(n)]),
                     "released": float(last.intrinsics[INTRINSICS_NAMES.index(n)]),
                     "std": float(sd[INTRINSICS_NAMES.index(n)])} for n, _ in named]
    order = list(INTRINSICS_MODELS)
    need = max((order.index(_MODEL_OF[n]) for n, _ in named), default=0)
    need = max(need, order.index(model.split("+")[0]))
    if need == order.index("focal") and any(n == "fy" for n, _ in named):
        need = order.index("pinhole")
    out["model"] = order[need]
    return out


def _chi2(fit) -> float:
    used = fit.corner_used
    r2 = float(np.sum(fit.residuals[used] ** 2)) / fit.pixel_sigma ** 2
    e2 = float(np.sum(fit.image_errors[fit.image_used] ** 2 / fit.pose_sigma ** 2))
    return r2 + e2


def held_reason(test: dict, hand: str, model: str) -> Reason:
    """The verdict's reason for a contradicted held value (``check_held_intrinsics``)."""
    what = ", ".join(f"{n['name']} {n['given']:.4g} → {n['released']:.4g} ± {n['std']:.2g}"
                     for n in test["named"])
    names = " and ".join(n["name"] for n in test["named"])
    level = "FAIL" if test["move_sigmas"] > FAIL_SIGMAS or not test.get(
        "restricted_plausible", True) else "WARN"
    moves = (f"with them released {hand} moves {test['move_deg']:.3g}° / "
             f"{1000 * test['move_m']:.3g} mm ({test['move_sigmas']:.1f}σ of the answer)")
    if not test.get("matters", True):
        moves += ": the answer stands, within its σ"
    return Reason(
        level, "intrinsics",
        f"the intrinsics held fixed (--refine-intrinsics {model}) do not fit the images: "
        f"released, {what} (χ² {test['statistic']:.4g} lower, bound {test['bound']:.3g} for "
        f"{test['dof']} held parameters); {moves} — correct {names} in --intrinsics, or "
        f"--refine-intrinsics {test['model']} (it refines {names})")


__all__ = ["held_parameters", "held_reason", "check_held_intrinsics"]


def apply_held_check(stage, data, robot_accuracy, max_noise, released=None) -> None:
    """``check_held_intrinsics`` on a ``corners.CornerStage``: the test into ``stage.held``
    (calibration.json), and when the pixels contradict a held value, its reason in place of
    the refined-intrinsics reason (those moved to make up for it). ``stage.explained`` tells
    ``corners._apply`` that the released model fits the pixels with plausible noise, so the
    pixel-level misfit is a consequence of the held value, not another cause."""
    from .pipeline import robot_error_covariance
    f = stage.fit
    cov = f.covariance.copy()
    if robot_accuracy is not None and any(robot_accuracy):
        cov = cov + robot_error_covariance(f.X_H, robot_accuracy)
    test = check_held_intrinsics(data, f, stage.model, stage.intrinsics_given, cov, released,
                                 max_noise)
    if test is None:
        return
    stage.held = {k: v for k, v in test.items() if k != "released_fit"}
    if not test["contradicted"] or not test["named"]:
        # Nothing named: no held parameter's release explains the pixels (the other checks stand).
        return
    stage.explained = bool(test["released_plausible"] and not test["restricted_plausible"])
    hand = "X_EC" if f.pose_error_frame == "camera" else "X_BC"
    others = [r for r in stage.reasons if r.code != "intrinsics"]
    if any(r.code == "target_size" for r in others) and _scale_explained(data, test):
        # A scale the held value made up for: with it released the declared size fits.
        others = [r for r in others if r.code != "target_size"]
        stage.scale["explained_by_intrinsics"] = True
    stage.reasons = [held_reason(test, hand, stage.model)] + others


def _scale_explained(data, test) -> bool:
    """The target's scale, fitted with every intrinsic released, is within 5σ (or 0.2 %) of 1."""
    g = test["released_fit"]
    try:
        c = fit_corners(data, g.X_H, g.X_F, g.intrinsics, "full", free_scale=True,
                        pixel_sigma0=g.pixel_sigma, pose_sigma0=g.pose_sigma,
                        pose_error_frame=g.pose_error_frame)
    except ValueError:
        return False
    return abs(c.scale - 1.0) <= max(5.0 * c.scale_std, 0.002)

"""Multi-camera rigs: N cameras on one robot — on the hand (X_EC) or fixed in the cell (X_BC), in
any mix — calibrated jointly from their images of one board: each camera's images paired with
the robot poses by index (image k of every camera taken at robot pose k), or from a bag, one
image topic per camera paired with the robot's tf in time.

Stages (``calibrate_rig``):

1. read: each camera's images detected with its own intrinsics (``inputs.image_streams`` or
   ``bag_image_streams``); a camera that does not see the board in ≥ 3 images FAILs by name and
   is left out;
2. alone: a camera that moves relative to the board (hand camera with the board in the cell,
   cell camera with the board on the hand) is calibrated alone by the single-camera pipeline
   (``corners.calibrate_images``: pose-level start, corner-level fit, its verdict); a camera on
   the board's mount (a cell camera watching a board fixed in the cell) sees one view: its images
   must all show the board in the same place (else it moved, or its images are a hand camera's);
3. moved: with the board placed by another camera, each image of a moving camera gives its own
   mount pose; one clean step in them names a camera that slipped half-way;
4. agree: each moving camera's board pose (from its own fit) against the board pose of the
   others' joint fit (χ² on 6 dof with both covariances): a camera whose data contradict the
   others' (wrong intrinsics, swapped topics, moved) is named; it is left out of the answer;
5. jointly: one corner-level maximum-likelihood fit of every camera that passed
   (``estimation.rig_bundle.fit_rig``), the board's pose one unknown for all, each camera's
   intrinsics refined with the model its own fit chose, its σ widened by its own cross-validation
   factor, then by a delete-one-instant jackknife (``jackknife_factors``) where the answers move
   more than their covariance says; the robot's accuracy added as for one camera.

Frames: B base, E flange, T board, C_i camera i. Answers X_EC (hand cameras) or X_BC (cell
cameras); the board X_BT (board in the cell) or X_ET (board on the hand); camera-to-camera
X_{C_a C_b} for two cameras on one mount. Covariances [δθ (rad); δt (m)], R = exp(δθ) R̂.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from ..estimation.reprojection import (CornerData, intrinsics_matrix, intrinsics_vector,
                                       scale_midpoint)
from ..estimation.rig_bundle import (MOUNTS, RigBlock, fit_rig, jackknife_factors,
                                     pose_error_frame, tangent)
from ..estimation.se3 import inverse
from .checks import Reason, Verdict
from .pipeline import robot_error_covariance

#: A moving camera's board pose this far (χ², 6 dof, tail probability) from the others' FAILs.
AGREEMENT_P = 1e-4
#: A move is one step that the split into before and after explains: the spread of all the
#: images at least this many times that within either part (noise spreads both alike).
MOVE_CONTRAST = 3.0
#: A fixed view (camera on the board's mount) whose board pose changes by more than this
#: between images (deg, m) is not fixed: PnP of one view of a board at 1 m repeats to ~0.1 mm.
FIXED_VIEW_TOLERANCE = (0.2, 0.002)


@dataclass
class RigCamera:
    """One camera of the rig: ``name``, ``images`` (a directory or files; image k pairs with
    robot pose k — or a bag, with ``topic``), ``mount`` "hand" (eye-in-hand: X_EC) or "cell" (X_BC), ``intrinsics`` (as
    ``--intrinsics``; None: calibrated from its images — a fixed view needs them given)."""
    name: str
    images: object
    mount: str = "hand"
    intrinsics: object = None
    #: With a bag (``images`` its path): the camera's image topic; its images pair with the
    #: robot's tf in time (as ``calibrate --bag --image-topic``), not by index.
    topic: str | None = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.replace("_", "").replace(
                "-", "").isalnum():
            raise ValueError(f"camera name: expected letters, digits, _ or -, got {self.name!r}")
        if self.mount not in MOUNTS:
            raise ValueError(f"camera {self.name}: mount must be one of {MOUNTS}, got "
                             f"{self.mount!r}")


@dataclass(eq=False)
class CameraResult:
    """Per camera: ``X`` (X_EC or X_BC, 4×4) and ``covariance`` (6×6) of the joint fit (None when
    it is not in the answer), ``alone`` (the single-camera ``CalibrationResult`` or None),
    ``verdict``, ``intrinsics`` vector used, ``images`` / ``detected`` counts, block statistics."""
    name: str
    mount: str
    verdict: Verdict
    X: np.ndarray | None = None
    covariance: np.ndarray | None = None
    alone: object = None
    intrinsics: np.ndarray | None = None
    intrinsics_model: str = "none"
    images: int = 0
    detected: int = 0
    pixel_rms_px: float = math.nan
    agreement: dict = field(default_factory=dict)
    #: Factor (≥ 1) on the joint fit's covariance from the jackknife over instants.
    variance_factor: float = 1.0
    #: With the board's scale s free: {"print": X as fitted (the board s× its declared size),
    #: "robot": translation / s (the robot's translations s× long)}; ``X`` is their midpoint.
    readings: dict = field(default_factory=dict)
    streams: object = field(default=None, repr=False)

    @property
    def key(self) -> str:
        return "X_EC" if self.mount == "hand" else "X_BC"

    @property
    def mode(self) -> str:
        return "eye_in_hand" if self.mount == "hand" else "eye_to_hand"

    def sigma(self) -> tuple[np.ndarray, np.ndarray] | None:
        if self.covariance is None:
            return None
        d = np.sqrt(np.maximum(np.diag(self.covariance), 0.0))
        return np.degrees(d[:3]), d[3:]


@dataclass
class RigResult:
    """The rig's answer: ``cameras`` {name: CameraResult}, ``board_mount``, ``X_board`` (X_BT or
    X_ET) and its covariance, ``relative`` {(a, b): (X_CaCb, covariance)} for cameras on one
    mount, ``verdict`` of the rig, ``fit`` (the ``RigFit``)."""
    cameras: dict
    board_mount: str
    verdict: Verdict
    X_board: np.ndarray | None = None
    board_covariance: np.ndarray | None = None
    relative: dict = field(default_factory=dict)
    fit: object = None
    notes: list = field(default_factory=list)
    #: Reasons of the rig as a whole (not of one camera): the board's scale.
    reasons: list = field(default_factory=list)
    #: The board's scale (true sizes / declared) found by the joint fit: {"factor", "std", "z",
    #: "significant", "readings"} — the answers cover both readings (``_scale_readings``).
    board_scale: dict = field(default_factory=dict)

    def lines(self) -> list[str]:
        out = [f"rig {self.verdict.line()}"]
        out += [f"  {r.level}: {r.message}" for r in self.verdict.reasons]
        for name, c in self.cameras.items():
            out.append(f"camera {name} ({c.mount}, {c.key}): {c.verdict.line()}; board found in "
                       f"{c.detected} of {c.images} images")
            out += [f"  {r.level}: {r.message}" for r in c.verdict.reasons]
            if c.X is not None and c.covariance is not None:
                sr, st = c.sigma()
                p = c.X[:3, 3]
                out.append(f"  {c.key} translation [{p[0]:+.5f} {p[1]:+.5f} {p[2]:+.5f}] m "
                           f"(σ {1000 * st[0]:.3f} {1000 * st[1]:.3f} {1000 * st[2]:.3f} mm), "
                           f"rotation σ {sr[0]:.4f} {sr[1]:.4f} {sr[2]:.4f}°; pixels RMS "
                           f"{c.pixel_rms_px:.3f} px, intrinsics {c.intrinsics_model}")
        if self.board_scale.get("factor") is not None:
            b = self.board_scale
            out.append(f"board scale {b['factor']:.5f} ± {b['std']:.2g} (true sizes / declared, "
                       "or the robot's translations that × their true lengths; the answers "
                       "cover both readings)")
        for (a, b), (X, C) in self.relative.items():
            d = np.sqrt(np.maximum(np.diag(C), 0.0))
            out.append(f"X_{a}_{b} (camera {b} in camera {a}): translation "
                       f"[{X[0, 3]:+.5f} {X[1, 3]:+.5f} {X[2, 3]:+.5f}] m, σ "
                       f"{1000 * np.linalg.norm(d[3:]):.3f} mm / "
                       f"{np.degrees(np.linalg.norm(d[:3])):.4f}°")
        out += [f"note: {n}" for n in self.notes]
        return out

    def to_json(self) -> dict:
        def cam(c: CameraResult):
            d = {"mount": c.mount, "mode": c.mode, "verdict": c.verdict.to_dict(),
                 "images": c.images, "detected": c.detected, "agreement": c.agreement}
            if c.X is not None and c.covariance is not None:
                K, dist = intrinsics_matrix(c.intrinsics)
                sr, st = c.sigma()
                d.update({c.key: c.X.tolist(), "covariance": c.covariance.tolist(),
                          "sigma": {"rotation_deg": sr.tolist(), "translation_m": st.tolist()},
                          "intrinsics": {"K": K.tolist(), "distortion": dist.tolist(),
                                         "model": c.intrinsics_model},
                          "pixel_rms_px": c.pixel_rms_px,
                          "jackknife_variance_factor": c.variance_factor})
                if c.readings:
                    d["readings"] = {k: v.tolist() for k, v in c.readings.items()}
            if c.alone is not None:
                off = c.alone.time_offset
                d["alone"] = {"verdict": c.alone.verdict.to_dict(),
                              c.key: c.alone.X_hand.tolist(),
                              "covariance": c.alone.covariance.tolist(),
                              "time_offset_s": None if off is None else float(off.offset)}
            return d
        return {"rig": {"verdict": self.verdict.to_dict(), "board_mount": self.board_mount,
                        ("X_BT" if self.board_mount == "cell" else "X_ET"):
                        None if self.X_board is None else self.X_board.tolist(),
                        "board_covariance": None if self.board_covariance is None
                        else self.board_covariance.tolist(), "notes": self.notes,
                        "board_scale": self.board_scale},
                "cameras": {n: cam(c) for n, c in self.cameras.items()},
                "relative": [{"from": a, "to": b, "X": X.tolist(), "covariance": C.tolist()}
                             for (a, b), (X, C) in self.relative.items()]}

    def export(self, name: str, formats="all", parent_frame: str | None = None) -> dict:
        """{file name: text} of camera ``name``'s frame (``recorded.exports.export_texts``;
        child frame ``NAME_optical_frame``). ValueError when its verdict is FAIL."""
        from ..recorded.exports import export_texts
        c = self.cameras[name]
        if c.X is None or c.covariance is None or c.verdict.status == "FAIL":
            raise ValueError(f"export: camera {name} has no answer (verdict {c.verdict.status})")
        K, dist = intrinsics_matrix(c.intrinsics)
        from ..vision.camera_model import CameraIntrinsics
        I = c.streams.intrinsics if c.streams is not None else None
        intr = None if I is None else CameraIntrinsics.from_matrix(K, I.width, I.height,
                                                                    tuple(dist))
        return export_texts(c.X, formats, mode=c.mode, parent_frame=parent_frame,
                            child_frame=f"{name}_optical_frame", X_std=c.covariance,
                            intrinsics=intr)


def _fail(code, message):
    return Verdict("FAIL", [Reason("FAIL", code, message)])


def _fixed_view_check(name, X_CT, lines, covariances=None) -> Reason | None:
    """A camera on the board's mount sees one view: its board poses must agree (module
    docstring) — within ``FIXED_VIEW_TOLERANCE`` or 6 σ of the two detections' own uncertainty
    (a board partly hidden by the arm is measured less well), whichever is larger; else it moved
    during the recording (one jump) or it is not where it is declared (its views change with the
    robot: on the hand, or another camera's images)."""
    n = len(X_CT)
    if n < 2:
        return None
    tol_deg, tol_m = FIXED_VIEW_TOLERANCE
    if covariances is None:
        sd = np.zeros((n, 2))
    else:
        sd = np.array([[math.sqrt(max(np.trace(C[:3, :3]), 0.0)),
                        math.sqrt(max(np.trace(C[3:, 3:]), 0.0))] if C is not None
                       else [0.0, 0.0] for C in covariances])

    def spread(idx):
        r = idx[len(idx) // 2]
        worst = 0.0
        for k in idx:
            d = tangent(X_CT[k], X_CT[r])
            allow_r = max(math.radians(tol_deg), 6.0 * math.hypot(sd[k, 0], sd[r, 0]))
            allow_t = max(tol_m, 6.0 * math.hypot(sd[k, 1], sd[r, 1]))
            worst = max(worst, np.linalg.norm(d[:3]) / allow_r, np.linalg.norm(d[3:]) / allow_t)
        return worst

    every = list(range(n))
    if spread(every) <= 1.0:
        return None
    best = min(((max(spread(every[:k]), spread(every[k:])), k) for k in range(2, n - 1)),
               default=(math.inf, 0))
    if best[0] <= 1.0 and spread(every) >= MOVE_CONTRAST * best[0]:
        k = best[1]
        d = tangent(X_CT[k], X_CT[k - 1])
        return Reason("FAIL", "camera_moved",
                      f"camera {name} moved during the recording: its view of the board jumps by "
                      f"{np.degrees(np.linalg.norm(d[:3])):.3g}° / {1000 * np.linalg.norm(d[3:]):.3g}"
                      f" mm between images {lines[k - 1]} and {lines[k]} and is steady before and "
                      "after — record again, or calibrate the two parts apart")
    return Reason("FAIL", "fixed_view_moves",
                  f"camera {name} is declared on the board's mount (a fixed view), but its view of "
                  "the board changes from image to image with the robot: is it on the other mount "
                  "(--camera …:hand / :cell), or are its images another camera's (swapped "
                  "topics or folders)?")


def _moved_checks(results, moving, board_mount) -> None:
    """A moving camera that moved on its mount half-way: with the board placed by another
    camera, each of its images gives its own mount pose X_c,k = X_R,k⁻¹ · X_b · X_CT,k⁻¹; a
    single jump in them (``_fixed_view_check``'s test) names the move, which the camera alone may
    only see as residuals too large. Cameras FAILed alone get the named cause first."""
    ok = [c for c in moving]
    for c in results.values():
        if c.alone is None or c.mount == board_mount:
            continue
        others = [o for o in ok if o is not c]
        if not others:
            continue
        X_b = others[0].alone.X_fixed
        a = c.alone.aligned
        X_R = np.asarray(a.X_BE)
        X_CT = np.asarray(a.X_CT)
        X_c = np.array([inverse(R) @ X_b @ inverse(T) for R, T in zip(X_R, X_CT)])
        dets = c.streams.detections
        covs = [getattr(dets[int(k)], "covariance", None) for k in a.camera_index]
        why = _fixed_view_check(c.name, X_c, list(np.asarray(a.camera_lines, int) - 1), covs)
        if why is not None and why.code == "camera_moved":
            why = Reason("FAIL", "camera_moved", why.message.replace(
                "its view of the board jumps", f"its pose on the {c.mount} (from the board as "
                f"camera {others[0].name} places it) jumps"))
            c.verdict = Verdict("FAIL", [why] + [r for r in c.verdict.reasons])
            if c in moving:
                moving.remove(c)


def _settings(options, streams, mode):
    s = options.stream_settings(streams, True)
    s["mode"] = mode
    return s


def _start_fixed(X_board, X_CT):
    """X_c of a fixed view from the board pose and its median view: X_c = X_b · X_CT⁻¹."""
    ref = X_CT[len(X_CT) // 2]
    return X_board @ inverse(ref)


def _blocks(cams, board_mount):
    """RigBlocks of the cameras (list of CameraResult with streams), camera index = position: a
    moving camera's corners with the robot-side pose its own calibration paired with each image
    (``corners.corner_data``: by index for image folders, in time for bags), a fixed view's with
    X_R = I."""
    from .corners import corner_data
    blocks = []
    for i, c in enumerate(cams):
        s = c.streams
        if c.mount == board_mount:
            data = CornerData.from_lists(np.repeat(np.eye(4)[None], len(s.detections), axis=0),
                                         [d.object_points for d in s.detections],
                                         [d.image_points for d in s.detections])
            instants = np.asarray(s.camera.lines, int) - 1
        else:
            data, _ = corner_data(c.alone, s.detections)
            instants = np.asarray(c.alone.aligned.camera_lines, int) - 1
        blocks.append(RigBlock(i, 0, data, instants, pose_error_frame(c.mount, board_mount),
                               c.mount == board_mount))
    return blocks


def _scale_readings(fit, rig):
    """The board's scale s found by the joint fit (free: a print off by a fraction of a percent
    is the rule; the same pixels as the robot's translations s× long — the two readings of the
    single-camera answer, ``corners._use_scale``): fills ``rig.board_scale`` and the rig's
    reasons (WARN naming the factor beyond 0.2 % and 5σ, FAIL beyond 3 % or a unit factor) and
    returns scale(X, C7) → (answer X, 6×6 covariance, readings) — the midpoint of the two
    readings, its σ covering both."""
    from .corners import SCALE_MIN_ERROR, SCALE_SIGMAS, SCALE_WARN_MAX, _unit_mistake
    if ("scale", 0) not in fit.columns:
        return lambda X, C: (X, C, {})
    s, sd = float(fit.scales[0]), fit.scale_std(0)
    z = (s - 1.0) / max(sd, 1e-12)
    significant = abs(z) > SCALE_SIGMAS and abs(s - 1.0) > SCALE_MIN_ERROR
    rig.board_scale = {"factor": s, "std": sd, "z": z, "significant": bool(significant),
                       "meaning": "the board's true sizes are factor × those declared, or the "
                                  "robot's translations are factor × their true lengths"}
    unit = _unit_mistake(s)
    if significant and (unit is not None or abs(s - 1.0) > SCALE_WARN_MAX):
        what = f"the sizes look like {unit}" if unit is not None else \
            f"{100 * abs(s - 1.0):.3g} % is beyond a print's or a robot's tolerance"
        rig.reasons.append(Reason(
            "FAIL", "target_size", f"the board's declared size is wrong: the cameras jointly say "
            f"its sizes are {s:.4g}× those declared (± {sd:.2g}, {abs(z):.0f}σ from 1) — {what}; "
            f"multiply the sizes of --target by {s:.4g} or measure the printed board"))
    elif significant:
        rig.reasons.append(Reason(
            "WARN", "target_scale", f"the board's scale: the cameras jointly say its sizes are "
            f"{s:.4g}× those declared (± {sd:.2g}, {abs(z):.0f}σ from 1) — a print "
            f"{100 * abs(s - 1.0):.2g} % {'large' if s > 1 else 'small'}, or the robot's "
            f"translations {s:.4g}× their true lengths: the pixels cannot tell the two apart; "
            "every answer is the midpoint of the two readings (its σ covers both; "
            "calibration.json holds each camera's readings) — measure the printed board's outer "
            "corners to tell them apart"))

    def scale(X, C):
        X_robot, X_mid, C_mid = scale_midpoint(X, C, s)
        return X_mid, C_mid, {"print": X.copy(), "robot": X_robot}
    return scale


def _joint(cams, board_mount, X_board0, factors, free_scale=True):
    blocks = _blocks(cams, board_mount)
    px0 = [max(float(np.median([d.reprojection_rms_px for d in c.streams.detections])) /
               math.sqrt(2), 0.05) for c in cams]
    # The robot error that repeats over the recording, as each camera's own calibration
    # measured it (the largest): in every answer's σ, the camera-to-camera transforms' too.
    levels = [c.alone.corners.robot_level for c in cams
              if c.alone is not None and c.alone.corners is not None
              and c.alone.corners.robot_level]
    level = None if not levels else (max(v["rotation_deg"] for v in levels),
                                     max(v["translation_m"] for v in levels))
    fit = fit_rig(blocks, [c.X for c in cams], [X_board0], [c.intrinsics for c in cams],
                  [c.intrinsics_model for c in cams], px0, None, variance_factors=factors,
                  free_scale=free_scale, robot_level=level)
    fit.rig_blocks = [dataclasses.replace(b, variance_factor=f)
                      for b, f in zip(blocks, [max(float(v), 1.0) for v in factors])]
    return fit


def calibrate_rig(cameras, robot, target, board_mount: str = "cell", options=None,
                  robot_frames: str = "base_link:tool0") -> RigResult:
    """Calibrates the rig (module docstring).

    Args:
        cameras: ``RigCamera`` list (distinct names).
        robot: the robot pose file (X_BE), one pose per image index (None when every camera
            reads a bag: the robot's poses are its tf, ``robot_frames`` BASE:EE).
        target: the board spec (e.g. ``charuco:7x5:0.04:0.03:DICT_5X5_100``).
        board_mount: "cell" (the board fixed in the cell: X_BT) or "hand" (on the flange: X_ET).
        options: ``api.CalibrationOptions`` (its mode is ignored: each camera's mount decides).
    """
    from .api import CalibrationOptions
    from .corners import calibrate_images
    from .inputs import bag_image_streams, image_streams
    options = options or CalibrationOptions()
    if not isinstance(options, CalibrationOptions):
        raise ValueError(f"options: expected a CalibrationOptions, got {type(options).__name__}")
    if board_mount not in MOUNTS:
        raise ValueError(f"board_mount: expected one of {MOUNTS}, got {board_mount!r}")
    if isinstance(cameras, RigCamera) or not isinstance(cameras, (list, tuple)) or not all(
            isinstance(c, RigCamera) for c in cameras):
        raise ValueError(f"cameras: expected a list of RigCamera, got {cameras!r:.200}")
    if target is None or (isinstance(target, str) and not target.strip()):
        raise ValueError("target: the board spec is needed (e.g. "
                         "charuco:7x5:0.04:0.03:DICT_5X5_100)")
    names = [c.name for c in cameras]
    if len(set(names)) != len(names) or not cameras:
        raise ValueError(f"cameras: expected distinct names, got {names}")
    if robot is None and any(c.topic is None for c in cameras):
        raise ValueError("robot: the robot poses (X_BE) are needed with image folders")
    results, moving, fixed = {}, [], []
    for cam in cameras:
        res = CameraResult(cam.name, cam.mount, Verdict("OK"))
        results[cam.name] = res
        try:
            if cam.topic is not None:
                s = bag_image_streams(cam.images, robot_frames, cam.topic, target,
                                      cam.intrinsics)
            else:
                s = image_streams([str(cam.images)] if isinstance(cam.images, (str, Path))
                                  else cam.images, robot, target, cam.intrinsics)
        except ValueError as e:
            res.verdict = _fail("no_board", f"camera {cam.name}: {e}" if "found in only" not in
                                str(e) else f"camera {cam.name} does not see the board: {e}")
            continue
        res.streams = s
        res.images, res.detected = len(s.images), len(s.detections)
        res.intrinsics = intrinsics_vector(s.intrinsics.K, s.intrinsics.distortion)
        if cam.mount == board_mount:
            if s.intrinsics_source != "given":
                res.verdict = _fail("intrinsics_needed",
                                    f"camera {cam.name} sees one fixed view of the board: its "
                                    "intrinsics cannot be calibrated from it — give them "
                                    "(--camera NAME:DIR:MOUNT:INTRINSICS)")
                continue
            why = _fixed_view_check(cam.name, np.asarray(s.camera.poses),
                                    list(np.asarray(s.camera.lines, int) - 1),
                                    [getattr(d, "covariance", None) for d in s.detections])
            if why is not None:
                res.verdict = Verdict("FAIL", [why])
                continue
            fixed.append(res)
        else:
            mode = "eye_in_hand" if cam.mount == "hand" else "eye_to_hand"
            try:
                alone = calibrate_images(s, _settings(options, s, mode), options.refine_intrinsics)
            except ValueError as e:
                res.verdict = _fail("alone", f"camera {cam.name} alone: {e}")
                continue
            res.alone = alone
            if alone.verdict.status == "FAIL":
                res.verdict = Verdict("FAIL", [Reason(
                    "FAIL", r.code, f"camera {cam.name}: {r.message}")
                    for r in alone.verdict.reasons if r.level == "FAIL"])
                continue
            res.verdict = Verdict(alone.verdict.status, [Reason(
                r.level, r.code, f"camera {cam.name}: {r.message}")
                for r in alone.verdict.reasons])
            res.X = alone.X_hand.copy()
            if alone.corners is not None:
                res.intrinsics = alone.corners.fit.intrinsics.copy()
                res.intrinsics_model = alone.corners.model
            moving.append(res)
    _moved_checks(results, moving, board_mount)
    moving = [c for c in moving if c.verdict.status != "FAIL"]
    rig = RigResult(results, board_mount, Verdict("OK"))
    if not moving:
        rig.verdict = _fail("no_moving_camera",
                            "no camera that moves relative to the board calibrated: the board's "
                            "pose is not determined" + "".join(
                                f"; {r.message}" for c in results.values()
                                for r in c.verdict.reasons))
        return rig
    X_board0 = moving[0].alone.X_fixed.copy()
    for r in fixed:
        r.X = _start_fixed(X_board0, np.asarray(r.streams.camera.poses))
    factors = {c.name: (c.alone.corners.variance_factor if c.alone.corners is not None else 1.0)
               for c in moving}
    # Agreement: each moving camera's board against the others' joint fit.
    if len(moving) >= 2:
        thr = float(chi2.isf(AGREEMENT_P, 6))
        for c in moving:
            others = [o for o in moving if o is not c]
            try:
                # At the declared scale: a print's scale moves every camera's board alike.
                f = _joint(others, board_mount, X_board0,
                           [factors[o.name] for o in others], free_scale=False)
            except ValueError:
                continue
            d = tangent(c.alone.X_fixed, f.X_boards[0])
            C = c.alone.fit.fixed_covariance + f.board_covariance(0)
            q = float(d @ np.linalg.solve(C, d))
            c.agreement = {"chi2": q, "threshold": thr,
                           "rotation_deg": float(np.degrees(np.linalg.norm(d[:3]))),
                           "translation_m": float(np.linalg.norm(d[3:]))}
        bad = [c for c in moving if c.agreement and c.agreement["chi2"] > thr]
        if bad:
            worst = max(bad, key=lambda c: c.agreement["chi2"])
            a = worst.agreement
            if len(moving) == 2:
                other = next(o for o in moving if o is not worst)
                msg = (f"cameras {moving[0].name} and {moving[1].name} disagree about the board: "
                       f"{a['rotation_deg']:.3g}° / {1000 * a['translation_m']:.3g} mm apart "
                       f"(χ² {a['chi2']:.0f}, 6 dof, > {thr:.0f}) — one of them has wrong "
                       "intrinsics, images of another camera (swapped topics) or moved; with two "
                       "cameras the data do not say which")
                for c in (worst, other):
                    c.verdict = Verdict("FAIL", [Reason("FAIL", "rig_disagreement", msg)]
                                        + c.verdict.reasons)
                moving = []
            else:
                msg = (f"camera {worst.name} contradicts the others about the board: "
                       f"{a['rotation_deg']:.3g}° / {1000 * a['translation_m']:.3g} mm from their "
                       f"joint fit (χ² {a['chi2']:.0f}, 6 dof, > {thr:.0f}) — wrong intrinsics, "
                       "another camera's images (swapped topics), or a camera that moved; it is "
                       "left out of the rig's answer")
                worst.verdict = Verdict("FAIL", [Reason("FAIL", "rig_disagreement", msg)]
                                        + worst.verdict.reasons)
                moving = [c for c in moving if c is not worst]
    cams = moving + fixed
    if not moving:
        for c in fixed:
            c.verdict = _fail("not_determined",
                              f"camera {c.name} sees one fixed view of the board: with no camera "
                              "that moves relative to the board left to place it, its pose is "
                              "not determined")
        cams = []
    if cams:
        try:
            fit = _joint(cams, board_mount, X_board0,
                         [factors.get(c.name, 1.0) for c in cams])
        except ValueError as e:
            for c in cams:
                c.verdict = _fail("joint", f"camera {c.name}: the joint fit failed ({e})")
            cams = []
        else:
            rig.fit = fit
            pairs = [(i, j) for i in range(len(cams)) for j in range(i + 1, len(cams))
                     if cams[j].mount == cams[i].mount]
            # What the corners' noise model misses shows in how the answers move when each
            # instant is left out: their σ are widened by it (never narrowed).
            jack = jackknife_factors(fit.rig_blocks, fit, pairs)
            if jack:
                rig.notes.append("σ widened by a delete-one-instant jackknife: " + ", ".join(
                    f"{cams[k[1]].name if k[0] == 'camera' else cams[k[1]].name + '→' + cams[k[2]].name}"
                    f" ×{math.sqrt(v):.2f}" for k, v in jack.items() if v > 1.0) or
                    "σ checked by a delete-one-instant jackknife: not widened")
            scale = _scale_readings(fit, rig)
            for i, c in enumerate(cams):
                c.variance_factor = jack.get(("camera", i), 1.0)
                c.X, c.covariance, c.readings = scale(
                    fit.X_cameras[i], fit.with_scale("camera", i) * c.variance_factor)
                if options.robot_accuracy is not None:
                    # As the single-camera answer: the robot's pose error, constant over the
                    # recording, moves every camera's answer — a moving camera's about the
                    # flange, a fixed view's through the board's pose in B (not the
                    # camera-to-camera transforms on one mount, where it cancels).
                    c.covariance = c.covariance + robot_error_covariance(
                        c.X, options.robot_accuracy)
                c.intrinsics = fit.intrinsics[i]
                c.pixel_rms_px = fit.blocks[i].rms_px
            rig.X_board, rig.board_covariance, _ = scale(fit.X_boards[0],
                                                         fit.with_scale("board", 0))
            for i, j in pairs:
                X, C = fit.relative(i, j, board=0)
                rig.relative[(cams[i].name, cams[j].name)] = scale(
                    X, C * jack.get(("pair", i, j), 1.0))[:2]
    for c in results.values():
        if c not in cams:
            c.X, c.covariance = None, None
    reasons = [Reason(r.level, r.code, r.message) for c in results.values()
               for r in c.verdict.reasons if r.level == "FAIL"]
    warns = [r for c in results.values() for r in c.verdict.reasons if r.level == "WARN"]
    reasons += [r for r in rig.reasons if r.level == "FAIL"]
    warns += [r for r in rig.reasons if r.level == "WARN"]
    failed = [n for n, c in results.items() if c.verdict.status == "FAIL"]
    if failed or reasons:
        first = [results[n].verdict.reasons[0].message for n in failed
                 if results[n].verdict.reasons]
        rig.verdict = Verdict("FAIL", ([Reason(
            "FAIL", "cameras", f"camera{'s' * (len(failed) > 1)} {', '.join(failed)} "
            f"FAIL{'' if len(failed) > 1 else 's'}: " + "; ".join(first))] if failed else [])
            + reasons)
    else:
        rig.verdict = Verdict("WARN" if warns else "OK", warns)
    if any(c.mount == board_mount for c in cams):
        rig.notes.append("cameras on the board's mount see one view each: their images count as "
                         "one (their corner errors repeat), so their σ come from the board's pose "
                         "and that view")
    return rig


__all__ = ["AGREEMENT_P", "CameraResult", "FIXED_VIEW_TOLERANCE", "RigCamera", "RigResult",
           "calibrate_rig"]

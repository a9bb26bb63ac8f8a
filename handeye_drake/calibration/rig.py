"""Multi-camera rigs: N cameras on one robot — on the hand (X_EC) or fixed in the cell (X_BC), in
any mix — calibrated jointly from their images of one or more boards, each board in the cell
(X_BT) or on the hand (X_ET): each camera's images paired with the robot poses by index (image k
of every camera taken at robot pose k), or from a bag, one image topic per camera paired with the
robot's tf in time. Each board's pose is one unknown shared by every camera that sees it; a
camera may see one board or several (in different images or the same).

Stages (``calibrate_rig``):

1. read: each camera's images detected, with its own intrinsics, for every board it may see
   (``inputs.image_streams`` or ``bag_image_streams`` per board; boards are told apart by their
   markers — several boards must carry disjoint marker ids, ``check_boards``); a (camera, board)
   pair with ≥ 3 detections is a block. A camera with no block FAILs by name and is left out; a
   board with none FAILs by name;
2. alone: each block in which the camera moves relative to the board (hand camera, cell board;
   cell camera, hand board) is calibrated alone by the single-camera pipeline
   (``corners.calibrate_images``); the camera's answer starts from its largest block that
   passes, its other blocks join the joint fit (one that cannot be calibrated alone for want of
   motion is placed by the camera's answer). A block on the board's mount (a cell camera
   watching a board fixed in the cell) sees one view: its images must all show the board in the
   same place (else the camera moved, or — when its view of another board stays put — the board
   moved);
3. moved: with a board placed by another camera, each image of a moving camera gives its own
   mount pose; one clean step in them names a camera that slipped half-way; with the camera
   placed by its images of another board, each image of a board gives the board's pose; one
   clean step names a board that was moved half-way;
4. agree: each block's board pose (from its own fit) against the board pose of the rest of the
   rig's joint fit (χ² on 6 dof with both covariances): a camera whose data contradict the
   others' (wrong intrinsics, swapped topics, moved) — or, when the camera agrees with the rest
   about another board, the board — is named and left out of the answer;
5. jointly: one corner-level maximum-likelihood fit of every block that passed
   (``estimation.rig_bundle.fit_rig``), each board's pose one unknown for all, each camera's
   intrinsics refined with the model its own fit chose, its σ widened by its own cross-validation
   factor, then by a delete-one-instant jackknife (``jackknife_factors``) where the answers move
   more than their covariance says; the robot's accuracy added as for one camera.

Frames: B base, E flange, T_j board j, C_i camera i. Answers X_EC (hand cameras) or X_BC (cell
cameras); each board X_BT (board in the cell) or X_ET (board on the hand); camera-to-camera
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
                                     pose_error_frame, robot_side, tangent)
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
#: FAIL codes of a camera's block alone that only say its images of that board do not determine
#: the camera by themselves (few, little motion): the camera placed by another board, the block
#: still measures the board.
_WEAK_ALONE = ("unobservable", "sigma", "too_few_samples", "weak")
#: The board name of a one-board rig (``calibrate_rig(…, target=SPEC)``).
DEFAULT_BOARD = "board"


def _check_name(name, what: str) -> None:
    if not isinstance(name, str) or not name or not name.replace("_", "").replace(
            "-", "").isalnum():
        raise ValueError(f"{what} name: expected letters, digits, _ or -, got {name!r}")
    if len(name) > 64:
        # It names a folder and a frame in the outputs: a file system takes ≤ 255 bytes.
        raise ValueError(f"{what} name: at most 64 characters, got {len(name)} "
                         f"({name[:20]}…)")


@dataclass
class RigCamera:
    """One camera of the rig: ``name``, ``images`` (a directory or files; image k pairs with
    robot pose k — or a bag, with ``topic``), ``mount`` "hand" (eye-in-hand: X_EC) or "cell"
    (X_BC), ``intrinsics`` (as ``--intrinsics``; None: calibrated from its images — a fixed view
    needs them given), ``boards`` the names of the boards it may see (None: every board)."""
    name: str
    images: object
    mount: str = "hand"
    intrinsics: object = None
    #: With a bag (``images`` its path): the camera's image topic; its images pair with the
    #: robot's tf in time (as ``calibrate --bag --image-topic``), not by index.
    topic: str | None = None
    boards: tuple | None = None
    #: Images paired in time: this camera's clock offset (s, camera stamp − robot time), or None
    #: for the options' ``time_offset_s`` (default: estimated, each camera on its own).
    time_offset: float | None = None

    def __post_init__(self):
        _check_name(self.name, "camera")
        if self.mount not in MOUNTS:
            raise ValueError(f"camera {self.name}: mount must be one of {MOUNTS}, got "
                             f"{self.mount!r}")
        if self.time_offset is not None and not (
                isinstance(self.time_offset, (int, float)) and not isinstance(
                    self.time_offset, bool) and math.isfinite(self.time_offset)):
            raise ValueError(f"camera {self.name}: time_offset: expected seconds, got "
                             f"{self.time_offset!r}")
        if self.boards is not None:
            if isinstance(self.boards, str) or not self.boards or not all(
                    isinstance(b, str) for b in self.boards):
                raise ValueError(f"camera {self.name}: boards: expected a list of board names, "
                                 f"got {self.boards!r}")
            self.boards = tuple(self.boards)


@dataclass
class RigBoard:
    """One board of the rig: ``name``, ``target`` (a spec, e.g.
    ``charuco:7x5:0.04:0.03:DICT_5X5_100``, or a ``vision.targets`` target), ``mount`` "cell"
    (fixed in the cell: X_BT) or "hand" (on the flange: X_ET)."""
    name: str
    target: object
    mount: str = "cell"

    def __post_init__(self):
        from ..vision.targets import format_target, parse_target
        _check_name(self.name, "board")
        if self.mount not in MOUNTS:
            raise ValueError(f"board {self.name}: mount must be one of {MOUNTS}, got "
                             f"{self.mount!r}")
        if self.target is None or (isinstance(self.target, str) and not self.target.strip()):
            raise ValueError(f"board {self.name}: the board spec is needed (e.g. "
                             "charuco:7x5:0.04:0.03:DICT_5X5_100)")
        try:
            self.target = format_target(parse_target(self.target))
        except ValueError as e:
            raise ValueError(f"board {self.name}: {e}") from None

    @property
    def key(self) -> str:
        return "X_BT" if self.mount == "cell" else "X_ET"


def marker_ids(target) -> tuple[str, frozenset] | None:
    """(dictionary, marker ids) a detection of ``target`` reads, or None for a target without
    coded markers (chessboard, circle grid: nothing in an image says which board it is)."""
    from ..vision.targets import (AprilGridTarget, AprilTagTarget, CharucoTarget,
                                  apriltag_dictionary_name, charuco_board, parse_target)
    t = parse_target(target)
    if isinstance(t, CharucoTarget):
        return t.dictionary, frozenset(int(i) for i in np.asarray(charuco_board(t).getIds())
                                       .ravel())
    if isinstance(t, AprilTagTarget):
        return apriltag_dictionary_name(t.family), frozenset([t.id])
    if isinstance(t, AprilGridTarget):
        return apriltag_dictionary_name(t.family), frozenset(
            range(t.first_id, t.first_id + t.tags_x * t.tags_y))
    return None


def check_boards(boards) -> list:
    """The boards of a rig, checked: distinct names and, with several, boards a detection tells
    apart — each with coded markers, no marker (dictionary, id) on two boards. Two identical
    boards (or two sharing marker ids) are refused naming them: a corner seen could belong to
    either, and no pose of either could be trusted. ValueError naming ``boards``."""
    if isinstance(boards, RigBoard) or not isinstance(boards, (list, tuple)) or not boards \
            or not all(isinstance(b, RigBoard) for b in boards):
        raise ValueError(f"boards: expected a non-empty list of RigBoard, got {boards!r:.200}")
    names = [b.name for b in boards]
    if len(set(names)) != len(names):
        raise ValueError(f"boards: expected distinct names, got {', '.join(names)}")
    if len(boards) == 1:
        return list(boards)
    ids = {}
    for b in boards:
        m = marker_ids(b.target)
        if m is None:
            raise ValueError(f"boards: board {b.name} ({b.target}) has no coded markers: with "
                             "several boards each must carry marker ids (ChArUco, AprilTag, "
                             "aprilgrid) so that a detection says which board it is")
        ids[b.name] = m
    for i, a in enumerate(boards):
        for b in boards[i + 1:]:
            (da, ia), (db, ib) = ids[a.name], ids[b.name]
            common = ia & ib if da == db else frozenset()
            if not common:
                continue
            what = ("the same board" if a.target == b.target else
                    f"boards whose markers overlap (ids {min(common)}…{max(common)})")
            raise ValueError(
                f"boards: boards {a.name} and {b.name} are {what} of dictionary {da}: a "
                f"detection cannot tell which of the two it sees — use boards of different "
                f"dictionaries (or, for aprilgrids, a FIRST_ID past the other's ids), or "
                f"calibrate with one of them")
    return list(boards)


@dataclass(eq=False)
class CameraResult:
    """Per camera: ``X`` (X_EC or X_BC, 4×4) and ``covariance`` (6×6) of the joint fit (None when
    it is not in the answer), ``alone`` (the single-camera ``CalibrationResult`` of its largest
    block that passes, or None; ``alone_by_board`` every block's), ``verdict``, ``intrinsics``
    vector used, ``images`` / ``detected`` counts (``boards``: images in which each board was
    found), block statistics; ``agreement`` of that block with the rest (``agreements`` per
    board)."""
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
    boards: dict = field(default_factory=dict)
    agreements: dict = field(default_factory=dict)
    alone_by_board: dict = field(default_factory=dict, repr=False)

    @property
    def key(self) -> str:
        return "X_EC" if self.mount == "hand" else "X_BC"

    @property
    def mode(self) -> str:
        return "eye_in_hand" if self.mount == "hand" else "eye_to_hand"

    def timing(self) -> str:
        """How its images were placed in time (image folders paired by time), else ""."""
        info = self.streams.inputs.get("images", {}) if self.streams is not None else {}
        if info.get("paired_by") != "time" or "bag" in self.streams.inputs:
            return ""
        if self.alone is None and self.verdict.status != "FAIL":
            return "stamped images: one fixed view of the board, no robot pose paired with them"
        text = "paired in time"
        a = self.alone.aligned if self.alone is not None else None
        if a is not None:
            text += (f": clock offset {a.time_offset:+.4f} s (camera stamp − robot time; "
                     f"{self.alone.time_offset_mode}), {len(a)} of {self.detected} detected "
                     "images within the robot's samples")
        return text

    def sigma(self) -> tuple[np.ndarray, np.ndarray] | None:
        if self.covariance is None:
            return None
        d = np.sqrt(np.maximum(np.diag(self.covariance), 0.0))
        return np.degrees(d[:3]), d[3:]


@dataclass(eq=False)
class BoardResult:
    """Per board: ``X`` (X_BT or X_ET by ``mount``) and ``covariance`` (6×6, [δθ; δt]) of the
    joint fit (None when no camera determines it), ``verdict``, ``seen_by`` {camera: images in
    which it was found}, ``variance_factor`` of the jackknife."""
    name: str
    mount: str
    target: str
    verdict: Verdict
    X: np.ndarray | None = None
    covariance: np.ndarray | None = None
    seen_by: dict = field(default_factory=dict)
    variance_factor: float = 1.0

    @property
    def key(self) -> str:
        return "X_BT" if self.mount == "cell" else "X_ET"

    def sigma(self) -> tuple[np.ndarray, np.ndarray] | None:
        if self.covariance is None:
            return None
        d = np.sqrt(np.maximum(np.diag(self.covariance), 0.0))
        return np.degrees(d[:3]), d[3:]

    def to_dict(self) -> dict:
        d = {"mount": self.mount, "target": self.target, "verdict": self.verdict.to_dict(),
             "seen_by": dict(self.seen_by), self.key: None if self.X is None else self.X.tolist(),
             "covariance": None if self.covariance is None else self.covariance.tolist()}
        if self.covariance is not None:
            sr, st = self.sigma()
            d["sigma"] = {"rotation_deg": sr.tolist(), "translation_m": st.tolist()}
            d["jackknife_variance_factor"] = self.variance_factor
        return d


@dataclass
class RigResult:
    """The rig's answer: ``cameras`` {name: CameraResult}, ``boards`` {name: BoardResult}, ``verdict`` of
    the rig, ``relative`` {(a, b): (X_CaCb, covariance)} for cameras on one mount, ``fit`` (the
    ``RigFit``). ``board_mount``, ``X_board`` (X_BT or X_ET) and ``board_covariance`` are the
    first board's (a one-board rig's board)."""
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
    #: "significant"} — the answers cover both readings (``_scale_readings``); {} with several
    #: boards (their scales held at the declared ones).
    board_scale: dict = field(default_factory=dict)
    boards: dict = field(default_factory=dict)

    def lines(self) -> list[str]:
        out = [f"rig {self.verdict.line()}"]
        out += [f"  {r.level}: {r.message}" for r in self.verdict.reasons]
        for name, c in self.cameras.items():
            seen = (f"board found in {c.detected} of {c.images} images" if len(self.boards) <= 1
                    else f"a board found in {c.detected} of {c.images} images (" + ", ".join(
                        f"{b} {n}" for b, n in c.boards.items()) + ")")
            out.append(f"camera {name} ({c.mount}, {c.key}): {c.verdict.line()}; {seen}")
            timing = c.timing()
            if timing:
                out.append(f"  {timing}")
            out += [f"  {r.level}: {r.message}" for r in c.verdict.reasons]
            if c.X is not None and c.covariance is not None:
                sr, st = c.sigma()
                p = c.X[:3, 3]
                out.append(f"  {c.key} translation [{p[0]:+.5f} {p[1]:+.5f} {p[2]:+.5f}] m "
                           f"(σ {1000 * st[0]:.3f} {1000 * st[1]:.3f} {1000 * st[2]:.3f} mm), "
                           f"rotation σ {sr[0]:.4f} {sr[1]:.4f} {sr[2]:.4f}°; pixels RMS "
                           f"{c.pixel_rms_px:.3f} px, intrinsics {c.intrinsics_model}")
        if len(self.boards) > 1:
            for name, b in self.boards.items():
                out.append(f"board {name} ({b.mount}, {b.key}, {b.target}): {b.verdict.line()}; "
                           "seen by " + (", ".join(f"{c} in {n}" for c, n in b.seen_by.items())
                                         or "no camera"))
                out += [f"  {r.level}: {r.message}" for r in b.verdict.reasons]
                if b.X is not None and b.covariance is not None:
                    sr, st = b.sigma()
                    p = b.X[:3, 3]
                    out.append(f"  {b.key} translation [{p[0]:+.5f} {p[1]:+.5f} {p[2]:+.5f}] m "
                               f"(σ {1000 * st[0]:.3f} {1000 * st[1]:.3f} {1000 * st[2]:.3f} "
                               f"mm), rotation σ {sr[0]:.4f} {sr[1]:.4f} {sr[2]:.4f}°")
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
            if c.streams is not None and "pairing" in c.streams.inputs.get("images", {}):
                d["pairing"] = c.streams.inputs["images"]["pairing"]
            if len(self.boards) > 1:
                d["boards"] = dict(c.boards)
                d["agreements"] = dict(c.agreements)
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
                "boards": {n: b.to_dict() for n, b in self.boards.items()},
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


def _add_fail(obj, code, message):
    """Puts a FAIL reason first in ``obj.verdict`` (a camera's or a board's)."""
    obj.verdict = Verdict("FAIL", [Reason("FAIL", code, message)] + list(obj.verdict.reasons))


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




@dataclass(eq=False)
class _Block:
    """The images of board ``board`` camera ``cam`` detected: ``streams``; ``alone`` its
    single-camera calibration when it moves relative to the board and passed alone; ``placed``:
    a moving block without its own answer (the camera placed by another of its blocks)."""
    cam: CameraResult
    board: RigBoard
    streams: object
    topic: str | None = None
    alone: object = None
    placed: bool = False
    agreement: dict = field(default_factory=dict)
    #: Its single-camera calibration whatever its verdict (None: it raised).
    tried: object = None

    @property
    def fixed(self) -> bool:
        return self.cam.mount == self.board.mount

    @property
    def label(self) -> str:
        return f"camera {self.cam.name}, board {self.board.name}"

    def pairs(self):
        """(X_R (K, 4, 4), X_CT (K, 4, 4), image indices (K,), detection indices (K,)) of the
        block's images paired with the robot: as its own calibration paired them, else by index
        (image folders); None for a bag's block without its own calibration (no time pairing)."""
        if self.tried is not None:
            a = self.tried.aligned
            return (np.asarray(a.X_BE), np.asarray(a.X_CT), np.asarray(a.camera_lines, int) - 1,
                    np.asarray(a.camera_index, int))
        if self.topic is not None and not self.fixed:
            return None
        s = self.streams
        n = len(s.detections)
        X_R = (np.repeat(np.eye(4)[None], n, axis=0) if self.fixed else
               robot_side(self.cam.mount, self.board.mount, np.asarray(s.robot.poses)))
        return X_R, np.asarray(s.camera.poses), np.asarray(s.camera.lines, int) - 1, \
            np.arange(n)


def _streams(cam: RigCamera, board: RigBoard, robot, robot_frames, pairing="auto"):
    from .inputs import bag_image_streams, image_streams
    if cam.topic is not None:
        return bag_image_streams(cam.images, robot_frames, cam.topic, board.target,
                                 cam.intrinsics)
    return image_streams([str(cam.images)] if isinstance(cam.images, (str, Path))
                         else cam.images, robot, board.target, cam.intrinsics,
                         pairing=pairing)


def _covs(k: _Block, index):
    dets = k.streams.detections
    return [getattr(dets[int(i)], "covariance", None) for i in index]


def _moved_checks(primary: dict, moving: list, failed: dict) -> None:
    """A moving camera that moved on its mount half-way: with its board placed by another
    camera, each of its images gives its own mount pose X_c,k = X_R,k⁻¹ · X_b · X_CT,k⁻¹; a
    single jump in them (``_fixed_view_check``'s test) names the move, which the camera alone may
    only see as residuals too large. ``primary`` {camera name: its main block}; a camera that
    moved is FAILed and dropped from ``primary``; ``failed`` {camera name: its largest block},
    cameras FAILed alone, get the named cause first."""
    for name, k in list(primary.items()) + list(failed.items()):
        c = k.cam
        others = [o for o in moving if o.board is k.board and o.cam is not c
                  and o.alone is not None and o.cam.name in primary]
        if not others:
            continue
        X_b = others[0].alone.X_fixed
        X_R, X_CT, lines, index = k.pairs()
        X_c = np.array([inverse(R) @ X_b @ inverse(T) for R, T in zip(X_R, X_CT)])
        why = _fixed_view_check(c.name, X_c, list(lines), _covs(k, index))
        if why is not None and why.code == "camera_moved":
            why = Reason("FAIL", "camera_moved", why.message.replace(
                "its view of the board jumps", f"its pose on the {c.mount} (from the board "
                f"{'' if k.board.name == DEFAULT_BOARD else k.board.name + ' '}as camera "
                f"{others[0].cam.name} places it) jumps"))
            c.verdict = Verdict("FAIL", [why] + [r for r in c.verdict.reasons])
            primary.pop(name, None)


def _board_moved(k: _Block, X_c, by: str) -> Reason | None:
    """A board moved half-way: with camera ``k.cam`` at ``X_c`` (placed by its images of board
    ``by``), each image of board ``k.board`` gives the board's pose X_b,k = X_R,k · X_c · X_CT,k;
    one clean jump in them names the board."""
    p = k.pairs()
    if p is None:
        return None
    X_R, X_CT, lines, index = p
    X_b = np.array([R @ X_c @ T for R, T in zip(X_R, X_CT)])
    why = _fixed_view_check(k.cam.name, X_b, list(lines), _covs(k, index))
    if why is None or why.code != "camera_moved":
        return None
    return Reason("FAIL", "board_moved", why.message.replace(
        f"camera {k.cam.name} moved", f"board {k.board.name} moved").replace(
        "its view of the board jumps", f"its pose seen by camera {k.cam.name} (placed by its "
        f"images of board {by}) jumps"))


def _rig_block(k: _Block, ci: int, bi: int) -> RigBlock:
    """The ``RigBlock`` of a block: a moving block's corners with the robot-side pose its own
    calibration paired with each image (``corners.corner_data``: by index for image folders, in
    time for bags), or by index; a fixed view's with X_R = I."""
    from .corners import corner_data
    s = k.streams
    if k.fixed:
        data = CornerData.from_lists(np.repeat(np.eye(4)[None], len(s.detections), axis=0),
                                     [d.object_points for d in s.detections],
                                     [d.image_points for d in s.detections])
        instants = np.asarray(s.camera.lines, int) - 1
    elif k.alone is not None:
        data, _ = corner_data(k.alone, s.detections)
        instants = np.asarray(k.alone.aligned.camera_lines, int) - 1
    else:
        X_R, _, instants, index = k.pairs()
        dets = [s.detections[int(i)] for i in index]
        data = CornerData.from_lists(X_R, [d.object_points for d in dets],
                                     [d.image_points for d in dets])
    return RigBlock(ci, bi, data, instants, pose_error_frame(k.cam.mount, k.board.mount),
                    k.fixed)


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


def _block_times(k: _Block):
    """Robot-clock times (s) of a block's images, None when paired by index (or placed)."""
    if k.fixed:
        t = k.streams.camera.timestamps
        return None if t is None else np.asarray(t, float)
    if k.alone is None:
        return None
    a = k.alone.aligned
    return None if a.camera_times is None else np.asarray(a.camera_times, float) - a.time_offset


def _joint(blocks, X_boards0: dict, factors: dict, covariance: bool = True,
           free_scale: bool = True):
    """``fit_rig`` of ``blocks`` (their cameras in order of first appearance, with ``X`` and
    ``intrinsics`` set; boards started at ``X_boards0`` {name: X}). Returns (fit, cameras,
    boards); ``fit.rig_blocks`` the RigBlocks with their variance factors."""
    cams, boards = [], []
    for k in blocks:
        if k.cam not in cams:
            cams.append(k.cam)
        if k.board not in boards:
            boards.append(k.board)
    rb = [_rig_block(k, cams.index(k.cam), boards.index(k.board)) for k in blocks]
    times = [_block_times(k) for k in blocks]
    if rb and all(t is not None and len(t) == b.data.num_images for t, b in zip(times, rb)):
        # Paired in time: cameras at different rates share no image index; the images taken
        # together are those in one bin a camera period wide on the robot's clock.
        periods = [float(np.median(np.diff(t))) for t in times if len(t) > 1]
        width = min(periods) if periods else 1.0
        t0 = min(float(t.min()) for t in times if len(t))
        rb = [dataclasses.replace(b, instants=np.floor((t - t0) / width).astype(int))
              for b, t in zip(rb, times)]
    px0 = [max(float(np.median([d.reprojection_rms_px for d in k.streams.detections])) /
               math.sqrt(2), 0.05) for k in blocks]
    f = [max(float(factors.get(k.cam.name, 1.0)), 1.0) for k in blocks]
    # The robot error that repeats over the recording, as each camera's own calibration
    # measured it (the largest): in the camera-to-camera transforms' σ (``fit_rig``).
    levels = [k.alone.corners.robot_level for k in blocks
              if k.alone is not None and k.alone.corners is not None
              and k.alone.corners.robot_level]
    level = None if not levels else (max(v["rotation_deg"] for v in levels),
                                     max(v["translation_m"] for v in levels))
    # One board: its scale is an unknown (``_scale_readings``); with several, held (each
    # answer would need its own reading of every board's scale).
    fit = fit_rig(rb, [c.X for c in cams], [X_boards0[b.name] for b in boards],
                  [c.intrinsics for c in cams], [c.intrinsics_model for c in cams], px0, None,
                  variance_factors=f, covariance=covariance,
                  free_scale=free_scale and len(boards) == 1, robot_level=level)
    fit.rig_blocks = [dataclasses.replace(b, variance_factor=v) for b, v in zip(rb, f)]
    return fit, cams, boards


def _board_pose_error_term(fit, b: int, robot_accuracy=None) -> np.ndarray:
    """6×6 covariance of board ``b``'s pose from one image's pose error: a block's fitted
    per-image level σ_e (the robot's error, as it moves the camera or the board) carried to the
    board pose that image implies (X_b = X_R · X_c · Exp(e) · X_CT for a camera on the robot,
    X_b · Exp(e) for a board on it), averaged over the block's images — not divided by their
    number: a robot's pose error repeats with its joint angles, so the errors of a recording's
    images are alike and do not average out (the fit's own covariance treats them as
    independent). The smallest such term over the blocks that move relative to the board (the
    best-placed camera's); zeros when none does. ``robot_accuracy`` (deg, m): instead the
    robot's absolute accuracy, a flange error e (per axis) at each image, X_b = X_BE · Exp(e) ·
    X_EC · X_CT (hand camera) or Exp(e) · X_ET (board on the hand)."""
    from ..estimation.se3 import make_transform, rotation_exp
    h = 1e-7
    best = None
    X_b = fit.X_boards[b]
    for rb, res in zip(fit.rig_blocks, fit.blocks):
        if rb.board != b or rb.fixed_view:
            continue
        X_c = fit.X_cameras[rb.camera]
        if robot_accuracy is None:
            S = np.diag(np.asarray(res.pose_sigma, float) ** 2)
            frame = rb.frame
        else:
            deg, m = (float(v) for v in robot_accuracy)
            S = np.diag(np.repeat([math.radians(deg) ** 2, m ** 2], 3))
            frame = "flange" if rb.frame == "camera" else "target"
        Cs = []
        for X_R in np.asarray(rb.data.X_R)[np.asarray(res.image_used, bool)]:
            X_CT = inverse(X_c) @ inverse(X_R) @ X_b
            J = np.zeros((6, 6))
            for i in range(6):
                d = np.zeros(6)
                d[i] = h
                imp = []
                for sgn in (1.0, -1.0):
                    E = make_transform(rotation_exp(sgn * d[:3]), sgn * d[3:])
                    imp.append(X_R @ X_c @ E @ X_CT if frame == "camera" else
                               X_R @ E @ X_c @ X_CT if frame == "flange" else
                               E @ X_b if robot_accuracy is not None else X_b @ E)
                J[:, i] = (tangent(imp[0], X_b) - tangent(imp[1], X_b)) / (2 * h)
            Cs.append(J @ S @ J.T)
        if not Cs:
            continue
        C = np.mean(Cs, axis=0)
        if best is None or np.trace(C[3:, 3:]) < np.trace(best[3:, 3:]):
            best = C
    return np.zeros((6, 6)) if best is None else 0.5 * (best + best.T)


def _boards_of(target, board_mount, boards) -> list:
    if boards is None:
        if isinstance(target, RigBoard):
            boards = [target]
        elif isinstance(target, (list, tuple)):
            boards = list(target)
        else:
            if board_mount not in MOUNTS:
                raise ValueError(f"board_mount: expected one of {MOUNTS}, got {board_mount!r}")
            if target is None or (isinstance(target, str) and not target.strip()):
                raise ValueError("target: the board spec is needed (e.g. "
                                 "charuco:7x5:0.04:0.03:DICT_5X5_100)")
            try:
                return [RigBoard(DEFAULT_BOARD, target, board_mount)]
            except ValueError as e:
                raise ValueError(f"target: {e}".replace(f"board {DEFAULT_BOARD}: ", "")) \
                    from None
    elif target is not None:
        raise ValueError("target, boards: give the board spec (one board) or the boards, not "
                         "both")
    return check_boards(boards)


def _settings(options, streams, mode, time_offset=None):
    s = options.stream_settings(streams, True)
    s["mode"] = mode
    if time_offset is not None:
        s["time_offset"] = float(time_offset)
    return s


def _prefix(k: _Block, single: bool) -> str:
    return f"camera {k.cam.name}" if single else f"camera {k.cam.name} (board {k.board.name})"


def calibrate_rig(cameras, robot, target=None, board_mount: str = "cell", options=None,
                  robot_frames: str = "base_link:tool0", boards=None,
                  pairing: str = "auto") -> RigResult:
    """Calibrates the rig (module docstring).

    Args:
        cameras: ``RigCamera`` list (distinct names).
        robot: the robot pose file (X_BE), one pose per image index, or timestamped poses at
            any rate for images paired in time (None when every camera reads a bag: the robot's
            poses are its tf, ``robot_frames`` BASE:EE).
        target: one board's spec (e.g. ``charuco:7x5:0.04:0.03:DICT_5X5_100``; its name
            ``DEFAULT_BOARD``), or a list of ``RigBoard``.
        board_mount: the one board's mount: "cell" (fixed in the cell: X_BT) or "hand" (on the
            flange: X_ET); a ``RigBoard`` carries its own.
        options: ``api.CalibrationOptions`` (its mode is ignored: each camera's mount decides).
        boards: ``RigBoard`` list (instead of ``target``): several boards, told apart by their
            markers (``check_boards``: two identical boards are refused, naming them).
        pairing: image folders: "auto", "index" or "time" (``inputs.choose_pairing``, per
            camera; "time" refuses a folder without stamps, naming it).
    """
    from .api import CalibrationOptions
    from .corners import calibrate_images
    options = options or CalibrationOptions()
    if not isinstance(options, CalibrationOptions):
        raise ValueError(f"options: expected a CalibrationOptions, got {type(options).__name__}")
    boards = _boards_of(target, board_mount, boards)
    single = len(boards) == 1
    if isinstance(cameras, RigCamera) or not isinstance(cameras, (list, tuple)) or not all(
            isinstance(c, RigCamera) for c in cameras):
        raise ValueError(f"cameras: expected a list of RigCamera, got {cameras!r:.200}")
    names = [c.name for c in cameras]
    if len(set(names)) != len(names) or not cameras:
        raise ValueError(f"cameras: expected distinct names, got {names}")
    board_names = [b.name for b in boards]
    for c in cameras:
        unknown = [b for b in (c.boards or ()) if b not in board_names]
        if unknown:
            raise ValueError(f"camera {c.name}: boards: {', '.join(unknown)} not among the rig's "
                             f"boards ({', '.join(board_names)})")
    if robot is None and any(c.topic is None for c in cameras):
        raise ValueError("robot: the robot poses (X_BE) are needed with image folders")
    if single and all(c.mount == boards[0].mount for c in cameras):
        # Nothing places the board then: no answer can come out, whatever the images show.
        raise ValueError(f"cameras: every camera is on the board's mount ({boards[0].mount}); "
                         "at least one must move relative to the board (a camera on the other "
                         "mount, or the board on the other mount)")
    rig_cameras = {c.name: c for c in cameras}
    results = {}
    board_results = {b.name: BoardResult(b.name, b.mount, b.target, Verdict("OK"))
                     for b in boards}
    by_camera = {}                     # camera name → its blocks
    # 1. read
    for cam in cameras:
        res = CameraResult(cam.name, cam.mount, Verdict("OK"))
        results[cam.name] = res
        blks, errors = [], {}
        for b in boards:
            if cam.boards is not None and b.name not in cam.boards:
                continue
            try:
                s = _streams(cam, b, robot, robot_frames, pairing)
            except ValueError as e:
                # Only a camera whose images do not show the board is a verdict; anything else
                # is bad input (unreadable images, counts that do not pair, wrong-size
                # intrinsics, the robot's file or frames): an error naming the camera.
                blind = ("found in only" in str(e) or "images show the target" in str(e)) and \
                    "another image resolution" not in str(e)
                if not blind:
                    raise ValueError(f"camera {cam.name}: {e}") from None
                errors[b.name] = str(e)
                continue
            blks.append(_Block(res, b, s, cam.topic))
            res.boards[b.name] = len(s.detections)
            board_results[b.name].seen_by[cam.name] = len(s.detections)
        if not blks:
            if single:
                e = next(iter(errors.values()))
                res.verdict = _fail("no_board", f"camera {cam.name} does not see the board: {e}")
            else:
                res.verdict = _fail("no_board", f"camera {cam.name} does not see any of the "
                                    "boards: " + "; ".join(f"board {n}: {e}"
                                                           for n, e in errors.items()))
            continue
        blks.sort(key=lambda k: -len(k.streams.detections))
        s = blks[0].streams
        res.streams = s
        res.images = len(s.images)
        res.detected = len({int(v) for k in blks for v in k.streams.camera.lines})
        res.intrinsics = intrinsics_vector(s.intrinsics.K, s.intrinsics.distortion)
        by_camera[cam.name] = blks
    # 2. alone, and each fixed view steady
    primary, placed, fixed, moving_alone, failed_main, suspect = {}, [], [], [], {}, []
    jumped = {}                        # camera name → its one view, which jumped
    for name, blks in by_camera.items():
        res = results[name]
        steady, jumps = [], []
        for k in [k for k in blks if k.fixed]:
            if k.streams.intrinsics_source != "given":
                jumps.append((k, Reason("FAIL", "intrinsics_needed", (
                    f"camera {name} sees one fixed view of the board"
                    + ("" if single else f" {k.board.name}") + ": its intrinsics cannot be "
                    "calibrated from it — give them (--camera NAME:DIR:MOUNT:INTRINSICS)"))))
                continue
            s = k.streams
            why = _fixed_view_check(name, np.asarray(s.camera.poses),
                                    list(np.asarray(s.camera.lines, int) - 1),
                                    [getattr(d, "covariance", None) for d in s.detections])
            (jumps.append((k, why)) if why is not None else steady.append(k))
        moving = [k for k in blks if not k.fixed]
        passed, failed = [], []
        for k in moving:
            mode = "eye_in_hand" if res.mount == "hand" else "eye_to_hand"
            try:
                alone = calibrate_images(k.streams, _settings(options, k.streams, mode,
                                                              rig_cameras[name].time_offset),
                                         options.refine_intrinsics)
            except ValueError as e:
                failed.append((k, None, str(e)))
                continue
            res.alone_by_board[k.board.name] = alone
            k.tried = alone
            if alone.verdict.status == "FAIL":
                failed.append((k, alone, None))
            else:
                k.alone = alone
                passed.append(k)
        if jumps and not (steady or passed):
            # Every view of the camera jumps (or its only one): the camera, not a board.
            k, why = jumps[0]
            res.verdict = (Verdict("FAIL", [why]) if why.code != "intrinsics_needed"
                           else _fail(why.code, why.message))
            if why.code == "camera_moved":
                jumped[name] = k
            continue
        by = (passed or steady)[0].board.name if (passed or steady) else None
        for k, why in jumps:
            if why.code == "intrinsics_needed":
                res.verdict = Verdict(res.verdict.status, list(res.verdict.reasons) + [Reason(
                    "WARN", why.code, why.message + "; its images of that board are left out")])
                if res.verdict.status == "OK":
                    res.verdict = Verdict("WARN", res.verdict.reasons)
                continue
            msg = why.message.replace(f"camera {name} moved", f"board {k.board.name} moved")
            if why.code == "camera_moved":
                msg = msg.replace("its view of the board jumps", f"camera {name}'s view of it "
                                  f"jumps (its view of board {by} does not)")
                code = "board_moved"
            else:
                msg = (f"board {k.board.name}: camera {name} (on the {res.mount}) sees it move "
                       f"from image to image while its view of board {by} stays put: is board "
                       f"{k.board.name} on the other mount (--board …:"
                       f"{'hand' if k.board.mount == 'cell' else 'cell'}), or did it move?")
                code = "board_moves"
            _add_fail(board_results[k.board.name], code, msg)
        if moving and not passed and not steady:
            k, alone, err = max(failed, key=lambda f: len(f[0].streams.detections))
            if alone is not None:
                failed_main[name] = k
            if alone is None:
                res.verdict = _fail("alone", f"{_prefix(k, single)} alone: {err}")
            else:
                res.verdict = Verdict("FAIL", [Reason("FAIL", r.code, f"{_prefix(k, single)}: "
                                                      f"{r.message}")
                                               for r in alone.verdict.reasons
                                               if r.level == "FAIL"])
            continue
        if passed:
            main = passed[0]
            primary[name] = main
            res.alone = main.alone
            res.X = main.alone.X_hand.copy()
            res.verdict = Verdict(main.alone.verdict.status, [Reason(
                r.level, r.code, f"{_prefix(main, single)}: {r.message}")
                for r in main.alone.verdict.reasons])
            if main.alone.corners is not None:
                res.intrinsics = main.alone.corners.fit.intrinsics.copy()
                res.intrinsics_model = main.alone.corners.model
            res.streams = main.streams
            moving_alone += passed
            for k, alone, err in failed:
                codes = {r.code for r in alone.verdict.reasons if r.level == "FAIL"} \
                    if alone is not None else set()
                if alone is None or codes <= set(_WEAK_ALONE):
                    # Too little of it to calibrate the camera alone: the camera, placed by its
                    # other board, still measures this board.
                    if k.pairs() is not None:
                        k.placed = True
                        placed.append(k)
                    continue
                suspect.append(k)
        elif failed:
            res.verdict = Verdict("WARN", list(res.verdict.reasons) + [Reason(
                "WARN", "alone", f"camera {name}: its images of board{'s' * (len(failed) > 1)} "
                f"{', '.join(f[0].board.name for f in failed)} do not calibrate it alone; left "
                "out (the camera is placed by its fixed view)")])
        fixed += steady
    # 3. moved: cameras that slipped, boards that were moved
    all_moving = moving_alone + placed
    _moved_checks(primary, moving_alone, failed_main)
    keep = []
    for k in all_moving:
        if k.cam.name not in primary:
            continue
        main = primary[k.cam.name]
        if k is not main and k.board is not main.board:
            why = _board_moved(k, main.alone.X_hand, main.board.name)
            if why is not None:
                _add_fail(board_results[k.board.name], why.code, why.message)
                continue
        keep.append(k)
    for k in suspect:
        # A camera's images of one board fail alone while its images of another pass: the
        # board moved (one clean jump, named), else its images of that board are refused.
        if k.cam.name not in primary:
            continue
        main = primary[k.cam.name]
        why = _board_moved(k, main.alone.X_hand, main.board.name)
        if why is None:
            why = Reason("FAIL", "board_alone", (
                f"board {k.board.name}: camera {k.cam.name}'s images of it do not calibrate ("
                + "; ".join(r.message for r in k.tried.verdict.reasons if r.level == "FAIL")
                + f") while its images of board {main.board.name} do: did board "
                f"{k.board.name} move during the recording, or is its spec wrong?"))
        _add_fail(board_results[k.board.name], why.code, why.message)
    for name, k in jumped.items():
        # A fixed camera whose one view jumped when another camera saw its board move: the
        # board's move explains it (the camera may well be where it was).
        b = board_results[k.board.name]
        if b.verdict.reasons and b.verdict.reasons[0].code == "board_moved":
            r = results[name]
            r.verdict = _fail("board_moved", r.verdict.reasons[0].message.replace(
                f"camera {name} moved during the recording: its view of the board jumps",
                f"camera {name}'s view of board {b.name} jumps").replace(
                " — record again", f": board {b.name} moved (another camera sees it move), "
                f"which explains it; with no steady view of a board, camera {name}'s pose is "
                "not determined — record again"))
    moving_alone = [k for k in keep if not k.placed]
    placed = [k for k in keep if k.placed]
    fixed = [k for k in fixed if results[k.cam.name].verdict.status != "FAIL"]
    rig = RigResult(results, boards[0].mount, Verdict("OK"), boards=board_results)
    if not moving_alone:
        rig.verdict = _fail("no_moving_camera",
                            ("no camera that moves relative to the board calibrated: the "
                             "board's pose is not determined" if single else
                             "no camera that moves relative to a board calibrated: the boards' "
                             "poses are not determined") + "".join(
                                f"; {r.message}" for c in results.values()
                                for r in c.verdict.reasons))
        for b in board_results.values():
            b.verdict = _fail("not_determined", f"board {b.name}: no camera places it")
        return rig
    factors = {k.cam.name: (k.alone.corners.variance_factor if k.alone.corners is not None
                            else 1.0) for k in primary.values()}
    X_b0 = {}
    for k in moving_alone:
        if k.board.name not in X_b0:
            X_b0[k.board.name] = k.alone.X_fixed.copy()
    # 4. agreement: each block's board against the rest's joint fit
    moving_cams = [n for n in by_camera if n in primary]
    thr = float(chi2.isf(AGREEMENT_P, 6))
    checked = []
    for k in moving_alone:
        rest = [o for o in moving_alone if o is not k]
        if k.board not in [o.board for o in rest]:
            continue
        own = [o for o in rest if o.cam is k.cam]
        rest += [o for o in placed if (o.cam is not k.cam or own) and o.board.name in X_b0]
        try:
            # At the declared scale: a print's scale moves every camera's board alike.
            f, _, bs = _joint(rest, X_b0, factors, free_scale=False)
        except ValueError:
            continue
        bi = bs.index(k.board)
        d = tangent(k.alone.X_fixed, f.X_boards[bi])
        C = k.alone.fit.fixed_covariance + f.board_covariance(bi)
        q = float(d @ np.linalg.solve(C, d))
        k.agreement = {"chi2": q, "threshold": thr,
                       "rotation_deg": float(np.degrees(np.linalg.norm(d[:3]))),
                       "translation_m": float(np.linalg.norm(d[3:])),
                       # The others' joint board pose and its covariance (the camera's own is
                       # its ``alone.fit``'s): the χ² can be checked from outside.
                       "others_X_board": f.X_boards[bi].tolist(),
                       "others_covariance": f.board_covariance(bi).tolist()}
        k.cam.agreements[k.board.name] = k.agreement
        if k is primary[k.cam.name]:
            k.cam.agreement = k.agreement
        checked.append(k)
    bad = [k for k in checked if k.agreement["chi2"] > thr]
    if bad:
        worst = max(bad, key=lambda k: k.agreement["chi2"])
        a = worst.agreement
        c = worst.cam
        where = "" if single else f" {worst.board.name}"
        agreeing = [o for o in checked if o.cam is c and o not in bad]
        if agreeing:
            _add_fail(board_results[worst.board.name], "board_disagreement", (
                f"board {worst.board.name}: camera {c.name}'s images of it place it "
                f"{a['rotation_deg']:.3g}° / {1000 * a['translation_m']:.3g} mm from where the "
                f"rest of the rig does (χ² {a['chi2']:.0f}, 6 dof, > {thr:.0f}), while camera "
                f"{c.name} agrees with the rest about board {agreeing[0].board.name}: did board "
                f"{worst.board.name} move during the recording? Its images from camera {c.name} "
                "are left out"))
            moving_alone = [k for k in moving_alone if k is not worst]
        elif len(moving_cams) == 2:
            other = results[next(n for n in moving_cams if n != c.name)]
            msg = (f"cameras {moving_cams[0]} and {moving_cams[1]} disagree about the board"
                   f"{where}: {a['rotation_deg']:.3g}° / {1000 * a['translation_m']:.3g} mm apart "
                   f"(χ² {a['chi2']:.0f}, 6 dof, > {thr:.0f}) — one of them has wrong "
                   "intrinsics, images of another camera (swapped topics) or moved; with two "
                   "cameras the data do not say which")
            for r in (c, other):
                r.verdict = Verdict("FAIL", [Reason("FAIL", "rig_disagreement", msg)]
                                    + r.verdict.reasons)
            moving_alone, placed, primary = [], [], {}
        else:
            msg = (f"camera {c.name} contradicts the others about the board{where}: "
                   f"{a['rotation_deg']:.3g}° / {1000 * a['translation_m']:.3g} mm from their "
                   f"joint fit (χ² {a['chi2']:.0f}, 6 dof, > {thr:.0f}) — wrong intrinsics, "
                   "another camera's images (swapped topics), or a camera that moved; it is "
                   "left out of the rig's answer")
            c.verdict = Verdict("FAIL", [Reason("FAIL", "rig_disagreement", msg)]
                                + c.verdict.reasons)
            primary.pop(c.name, None)
            moving_alone = [k for k in moving_alone if k.cam is not c]
            placed = [k for k in placed if k.cam is not c]
    # What the moving blocks determine, then what the fixed views and placed blocks reach.
    det_cams = {k.cam.name for k in moving_alone}
    X_b0 = {}
    for k in moving_alone:
        X_b0.setdefault(k.board.name, k.alone.X_fixed.copy())
    cams_blocks = list(moving_alone)
    pending = placed + fixed
    changed = True
    while changed:
        changed = False
        for k in list(pending):
            cam_ok, board_ok = k.cam.name in det_cams, k.board.name in X_b0
            if not (cam_ok or board_ok) or (k.placed and not cam_ok):
                continue
            X_R, X_CT, _, _ = k.pairs()
            mid = len(X_CT) // 2
            if not cam_ok:
                k.cam.X = inverse(X_R[mid]) @ X_b0[k.board.name] @ inverse(X_CT[mid])
                det_cams.add(k.cam.name)
            elif not board_ok:
                X_b0[k.board.name] = X_R[mid] @ k.cam.X @ X_CT[mid]
            cams_blocks.append(k)
            pending.remove(k)
            changed = True
    for k in pending:
        if k.fixed and not any(o.cam is k.cam for o in cams_blocks):
            r = results[k.cam.name]
            if r.verdict.status != "FAIL":
                r.verdict = _fail("not_determined", (
                    f"camera {k.cam.name} sees one fixed view of the board"
                    + ("" if single else f" {k.board.name}") + ": with no camera that moves "
                    "relative to the board left to place it, its pose is not determined"))
    for b in board_results.values():
        if b.name in X_b0:
            continue
        if not b.seen_by:
            if not single:
                _add_fail(b, "board_not_seen", f"board {b.name} ({b.target}) is not seen by "
                          "any camera (found in < 3 images of each): its pose is not "
                          "determined — is it in view, and is its spec (dictionary, size) right?")
        elif b.verdict.status != "FAIL":
            _add_fail(b, "not_determined", f"board {b.name}: no camera that moves relative to "
                      "it, or that another board places, sees it: its pose is not determined")
    # 5. jointly
    order = {n: i for i, n in enumerate(results)}
    cams_blocks.sort(key=lambda k: (k.fixed, order[k.cam.name], board_names.index(k.board.name)))
    cams = []
    if cams_blocks:
        try:
            fit, cams, bs = _joint(cams_blocks, X_b0, factors)
        except ValueError as e:
            for k in cams_blocks:
                _add_fail(k.cam, "joint", f"camera {k.cam.name}: the joint fit failed ({e})")
            cams, bs = [], []
        else:
            rig.fit = fit
            scale = _scale_readings(fit, rig)
            pairs = [(i, j) for i in range(len(cams)) for j in range(i + 1, len(cams))
                     if cams[j].mount == cams[i].mount]
            # What the corners' noise model misses shows in how the answers move when each
            # instant is left out: their σ are widened by it (never narrowed).
            jack = jackknife_factors(fit.rig_blocks, fit, pairs)
            if jack:
                def what(key):
                    if key[0] == "camera":
                        return cams[key[1]].name
                    if key[0] == "board":
                        return f"board {bs[key[1]].name}"
                    return f"{cams[key[1]].name}→{cams[key[2]].name}"
                widened = [f"{what(k)} ×{math.sqrt(v):.2f}" for k, v in jack.items() if v > 1.0]
                rig.notes.append("σ widened by a delete-one-instant jackknife: " + ", ".join(
                    widened) if widened else "σ checked by a delete-one-instant jackknife: not "
                    "widened")
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
                used = [j for j, rb in enumerate(fit.rig_blocks) if rb.camera == i]
                n2 = [fit.blocks[j].rms_px ** 2 * max(int(np.sum(fit.blocks[j].corner_used)), 1)
                      for j in used]
                c.pixel_rms_px = fit.blocks[used[0]].rms_px if len(used) == 1 else math.sqrt(
                    sum(n2) / sum(max(int(np.sum(fit.blocks[j].corner_used)), 1)
                                  for j in used))
            for i, b in enumerate(bs):
                br = board_results[b.name]
                br.variance_factor = jack.get(("board", i), 1.0)
                br.X, C_b, _ = scale(fit.X_boards[i], fit.with_scale("board", i, i))
                br.covariance = C_b * br.variance_factor + _board_pose_error_term(fit, i)
                if options.robot_accuracy is not None:
                    # As for the cameras: the robot's absolute accuracy moves the board's pose
                    # as the images place it (not averaged over them: it repeats).
                    br.covariance = br.covariance + _board_pose_error_term(
                        fit, i, options.robot_accuracy)
            for i, j in pairs:
                X, C = fit.relative(i, j, board=0)
                rig.relative[(cams[i].name, cams[j].name)] = scale(
                    X, C * jack.get(("pair", i, j), 1.0))[:2]
    for c in results.values():
        if c not in cams:
            c.X, c.covariance = None, None
    first = board_results[boards[0].name]
    rig.X_board, rig.board_covariance = first.X, first.covariance
    reasons = [Reason(r.level, r.code, r.message) for c in results.values()
               for r in c.verdict.reasons if r.level == "FAIL"]
    warns = [r for c in results.values() for r in c.verdict.reasons if r.level == "WARN"]
    reasons += [r for r in rig.reasons if r.level == "FAIL"]
    warns += [r for r in rig.reasons if r.level == "WARN"]
    failed = [n for n, c in results.items() if c.verdict.status == "FAIL"]
    failed_boards = [] if single else [n for n, b in board_results.items()
                                       if b.verdict.status == "FAIL"]
    head = []
    if failed:
        first_msgs = [results[n].verdict.reasons[0].message for n in failed
                      if results[n].verdict.reasons]
        head.append(Reason("FAIL", "cameras", f"camera{'s' * (len(failed) > 1)} "
                           f"{', '.join(failed)} FAIL{'' if len(failed) > 1 else 's'}: "
                           + "; ".join(first_msgs)))
    if failed_boards:
        msgs = [board_results[n].verdict.reasons[0].message for n in failed_boards]
        head.append(Reason("FAIL", "boards", f"board{'s' * (len(failed_boards) > 1)} "
                           f"{', '.join(failed_boards)} FAIL"
                           f"{'' if len(failed_boards) > 1 else 's'}: " + "; ".join(msgs)))
        reasons += [r for n in failed_boards for r in board_results[n].verdict.reasons]
    if any(r.level == "FAIL" for r in rig.reasons):
        head += [r for r in rig.reasons if r.level == "FAIL"]
        reasons = [r for r in reasons if r not in rig.reasons]
    if head:
        rig.verdict = Verdict("FAIL", head + reasons)
    else:
        rig.verdict = Verdict("WARN" if warns else "OK", warns)
    if any(k.fixed for k in cams_blocks) and cams:
        rig.notes.append(f"cameras on {'the' if single else 'a'} board's mount see one view each: their images count as "
                         "one (their corner errors repeat), so their σ come from the board's pose "
                         "and that view")
    return rig


__all__ = ["AGREEMENT_P", "BoardResult", "CameraResult", "DEFAULT_BOARD", "FIXED_VIEW_TOLERANCE",
           "RigBoard", "RigCamera", "RigResult", "calibrate_rig", "check_boards", "marker_ids"]

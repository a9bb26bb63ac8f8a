"""Calibration-target detection and pose estimation from one image (numpy/OpenCV, no Drake).

``detect_target(image, target, intrinsics)`` finds the target's points in the image, estimates
``X_CT`` (the target frame T of ``vision.targets`` in the OpenCV camera frame C) and its
uncertainty:

1. points: chessboard — ``cv2.findChessboardCornersSB`` (image normalized, then OpenCV's
   default flags), falling back on the classic
   ``findChessboardCorners`` with its fast check (``thorough=False``: the classic one only),
   then ``cornerSubPix``; when no complete board is
   found the reason says what is seen (no contrast, a part of the board at an image edge, edges
   too blurred, a larger board than the spec). The corner order is tied to the printed colours
   (see ``vision.targets``), so the OpenCV detectors, which disagree on it, give the same ids;
   a board that looks the same after a half turn is labelled from the end nearest the image's
   top-left corner, and ``calibration.symmetry`` lets the robot's motion decide. Circle grids —
   ``cv2.findCirclesGrid`` with a blob detector for circles of any size, the stated polarity
   first, then the other; the blob centroids are moved to the images of the circles' centres
   by the shift perspective and distortion predict at the estimated pose
   (``correct_circle_centres``; docs/targets.md). ChArUco — ``cv2.aruco.CharucoDetector``
   (its corners are refined by ``cornerSubPix``); when markers are found but no board, the
   other legacy setting is tried and ``note`` says which one matched. AprilTag (one tag or a grid) — ``cv2.aruco.ArucoDetector``
   with the ``DICT_APRILTAG_*`` dictionary, then each corner is moved to the intersection of the
   two border edges, fitted to sub-pixel edge points (OpenCV's ``CORNER_REFINE_SUBPIX`` is biased
   by ~0.2 px towards the tag centre on these outer corners; the APRILTAG method is 40× slower);
2. pose: ``cv2.solvePnPGeneric`` with ``SOLVEPNP_IPPE`` (planar) gives the two candidate poses,
   each refined by ``cv2.solvePnPRefineLM``; poses that see the printed face from behind are
   discarded. If the second pose explains the points almost as well as the best one
   (reprojection RMS ratio < ``ambiguity_ratio``) while being a genuinely different pose
   (outside the best one's 99.9 % covariance ellipsoid), the detection is "not found" with the
   reason "ambiguous pose (IPPE ratio …)" — a coin flip between two poses is never reported as a
   measurement (typically a single small tag far away and tilted by a few to ~15°: e.g. a 5 cm
   tag at 1 m tilted by 10°; seen exactly head-on the two poses merge and the covariance covers
   the tilt uncertainty; a grid or a board avoids the problem);
3. uncertainty: ``covariance`` = σ² (JᵀJ)⁻¹ with J the 2n×6 Jacobian of the distorted pixel
   coordinates with respect to the error state [δθ; δt] of ``X_CT`` (R = exp([δθ]×) R̂,
   t = t̂ + δt, δθ in radians about C's axes; the convention of ``estimation.manifold``) and
   σ = ``pixel_sigma`` the per-coordinate pixel noise estimated from the residuals,
   σ² = Σr² / (2n − 6), floored at ``min_pixel_sigma``.

"Not found" is a normal result (``found=False`` with a ``reason``), never an exception; only bad
arguments raise ValueError.

Images are uint8: grey (H, W), colour (H, W, 3) in RGB order (Drake, imageio, PIL; a BGR image
from ``cv2.imread`` gives the same grey levels up to the red/blue weights, irrelevant for
black-and-white targets) or RGBA (H, W, 4) as Drake's ``ImageRgba8U`` renders it.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from .camera_model import CameraIntrinsics
from .targets import (
    AprilTagTarget,
    CharucoTarget,
    ChessboardTarget,
    CircleGridTarget,
    charuco_board,
    circles,
    get_dictionary,
    object_points as target_object_points,
    target_dictionary_name,
    target_symmetries,
    validate_target,
)

#: χ²(6) 99.9 % quantile: a second IPPE pose farther than this (Mahalanobis², under the best
#: pose's covariance) is a distinct pose, not the same one seen twice.
_CHI2_6_999 = 22.458


@dataclasses.dataclass
class TargetDetection:
    """Result of ``detect_target``.

    Attributes:
        found: a pose was estimated (all fields below are then filled).
        reason: "" when found; otherwise why not (no markers, too few points, ambiguous…).
        ids: (n,) int ids of the detected points, into ``targets.object_points(target)``
            (filled also when not found, for drawing).
        image_points: (n, 2) pixels (distorted, as seen in the image; OpenCV pixel centres).
        object_points: (n, 3) the same points in T, metres.
        X_CT: 4×4 pose of T in the camera frame C (metres), None when not found.
        reprojection_rms_px: sqrt(mean ‖r_i‖²) over the points of the reprojection residuals
            r_i (px, per point like ``cv2.calibrateCamera``'s RMS); NaN when not found.
        covariance: 6×6 covariance of [δθ; δt] of X_CT (rad², m²; see the module docstring),
            None when not found.
        pixel_sigma: per-coordinate pixel noise (px) used for the covariance; NaN when not found.
        note: remarks that do not prevent detection (legacy ChArUco pattern, symmetric board…).
    """

    found: bool
    reason: str
    ids: np.ndarray
    image_points: np.ndarray
    object_points: np.ndarray
    X_CT: np.ndarray | None
    reprojection_rms_px: float
    covariance: np.ndarray | None
    pixel_sigma: float
    note: str = ""


# --------------------------------------------------------------------------------------------
# Argument checks


def as_grey_image(image, intrinsics: CameraIntrinsics | None = None) -> np.ndarray:
    """uint8 grey (H, W) view/copy of a uint8 grey, RGB or RGBA image; ValueError naming the
    problem (dtype, shape, size different from the intrinsics')."""
    import cv2
    if not isinstance(image, np.ndarray):
        raise ValueError(f"image: expected a numpy array, got {type(image).__name__}")
    if image.dtype != np.uint8:
        raise ValueError(f"image: expected dtype uint8, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 2:
        grey = image
    elif image.ndim == 3 and image.shape[2] == 3:
        grey = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY)
    elif image.ndim == 3 and image.shape[2] == 4:
        grey = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGBA2GRAY)
    else:
        raise ValueError(f"image: expected shape (H, W), (H, W, 3) RGB or (H, W, 4) RGBA, got "
                         f"{image.shape}")
    if intrinsics is not None and grey.shape != (intrinsics.height, intrinsics.width):
        raise ValueError(f"image: size {grey.shape[1]}×{grey.shape[0]} (width×height) differs "
                         f"from the intrinsics' {intrinsics.width}×{intrinsics.height}")
    return np.ascontiguousarray(grey)


def _check_intrinsics(intrinsics) -> CameraIntrinsics:
    if not isinstance(intrinsics, CameraIntrinsics):
        raise ValueError(f"intrinsics: expected a CameraIntrinsics, got "
                         f"{type(intrinsics).__name__}")
    return intrinsics


def _positive(value, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    if not math.isfinite(v) or v <= 0:
        raise ValueError(f"{name}: expected a finite number > 0, got {value!r}")
    return v


# --------------------------------------------------------------------------------------------
# Point detection: each returns (ids, image points, reason, note)


def _subpix_window(points: np.ndarray, grid_cols: int) -> int:
    """Half-size of the cornerSubPix window: ~30 % of the smallest corner spacing, 2…7 px."""
    grid = points.reshape(-1, grid_cols, 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=1), axis=2).min(),
                  np.linalg.norm(np.diff(grid, axis=0), axis=2).min()
                  if grid.shape[0] > 1 else np.inf)
    return int(np.clip(round(0.3 * spacing), 2, 7))


def _sb_flags():
    import cv2
    return cv2.CALIB_CB_NORMALIZE_IMAGE


def _find_chessboard(grey, size, thorough: bool):
    """(corners (n, 1, 2) float32 or None, which detector found them). Thorough: OpenCV's
    sector-based ``findChessboardCornersSB`` (finds boards under blur, strong distortion, steep
    views; image normalized, then OpenCV's default flags), then the classic
    ``findChessboardCorners`` (adaptive threshold), which finds some
    boards SB misses (uneven light); not thorough (a real-time loop): the classic one only. The
    classic detector always runs with its fast check: without it, it can search for tens of
    seconds in an image holding part of a board (measured: 26 s on a 1280×720 view with half
    the board out of the image, 0.04 s with the check). SB's exhaustive search is not tried: it
    costs several SB runs per missed image. Whichever found them, the corners are refined by
    ``cornerSubPix`` (window ~30 % of the corner spacing), which beats SB's own sub-pixel
    estimate, with or without ``CALIB_CB_ACCURACY`` (``benchmarks/board_detection.py``)."""
    import cv2
    n = size[0] * size[1]
    attempts = []
    if thorough:
        # With the histogram equalized (found 14 of 16 unkind views against 12 without), then
        # as OpenCV's default call does (a board either finds is a board).
        attempts.append(("findChessboardCornersSB",
                         lambda: cv2.findChessboardCornersSB(grey, size, flags=_sb_flags())))
        attempts.append(("findChessboardCornersSB",
                         lambda: cv2.findChessboardCornersSB(grey, size, flags=0)))
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    attempts.append(("findChessboardCorners",
                     lambda: cv2.findChessboardCorners(grey, size, flags=flags)))
    for which, attempt in attempts:
        found, corners = attempt()
        if found and corners is not None and len(corners) == n:
            corners = np.asarray(corners, np.float32).reshape(-1, 1, 2)
            w = _subpix_window(corners.reshape(-1, 2), size[0])
            corners = cv2.cornerSubPix(grey, corners, (w, w), (-1, -1),
                                       (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 40,
                                        1e-3))
            return corners, which
    return None, ""


def _edge_reason(points: np.ndarray, shape, spacing: float) -> str:
    """Which image borders points lie within ~one grid spacing of ("" if none)."""
    h, w = shape
    m = max(1.5 * spacing, 4.0)
    sides = [name for name, near in (("left", points[:, 0] < m),
                                     ("right", points[:, 0] > w - 1 - m),
                                     ("top", points[:, 1] < m),
                                     ("bottom", points[:, 1] > h - 1 - m)) if np.any(near)]
    return " and ".join(sides)


def _chessboard_miss_reason(grey, target: ChessboardTarget, thorough: bool) -> str:
    """Why no complete board was found, from what is visible (runs only on a miss): the grey
    range, then the largest board part ``findChessboardCornersSB`` finds (a 3×3 pattern with
    ``CALIB_CB_LARGER``): where it is, how sharp (``estimateChessboardSharpness``)."""
    import cv2
    spec = f"chessboard {target.cols}x{target.rows}"
    flat = _no_contrast_reason(grey, spec, 25.0)
    if flat:
        return flat
    if not thorough:
        return (f"{spec} not found by the fast detector (all {target.cols * target.rows} inner "
                f"corners must be visible, with a white border around the board)")
    found, corners, meta = cv2.findChessboardCornersSBWithMeta(
        grey, (3, 3), flags=_sb_flags() | cv2.CALIB_CB_LARGER)
    if not found or corners is None or meta is None:
        return (f"{spec} not found: no chessboard corners seen (board out of view, too small, "
                f"too blurred, or glare on it?)")
    part = np.asarray(corners, float).reshape(-1, 2)
    rows_seen, cols_seen = meta.shape[:2]
    grid = part.reshape(rows_seen, cols_seen, 2)
    spacing = float(np.median(np.linalg.norm(np.diff(grid, axis=1), axis=2)))
    seen = (f"a block of {max(cols_seen, rows_seen)}×{min(cols_seen, rows_seen)} of its inner "
            f"corners")
    sides = _edge_reason(part, grey.shape, spacing)
    if sides:
        return (f"{spec} not found: only {seen} is seen, at the image's {sides} edge — the board "
                f"is partly out of view")
    try:
        sharpness = float(cv2.estimateChessboardSharpness(
            grey, (cols_seen, rows_seen), part.reshape(-1, 1, 2).astype(np.float32))[0][0])
    except cv2.error:
        sharpness = float("nan")
    if sharpness > 0.25 * spacing:
        return (f"{spec} not found: only {seen} is seen and its edges are {sharpness:.1f} px wide "
                f"for squares of {spacing:.0f} px — too blurred (motion or focus)")
    if {cols_seen, rows_seen} != {target.cols, target.rows} and \
            max(cols_seen, rows_seen) > max(target.cols, target.rows):
        return (f"{spec} not found: a {cols_seen}x{rows_seen} board is seen — COLSxROWS counts "
                f"INNER corners (squares − 1); is the spec right?")
    return (f"{spec} not found: only {seen} is seen, away from the image's edges — the rest "
            f"out of view, hidden (glare, an occluder) or too blurred, or COLSxROWS (inner "
            f"corners) wrong?")


def _canonical_order(points: np.ndarray, target) -> np.ndarray:
    """Points (n, 2) of a complete grid relabelled, among the board's symmetric labellings
    (``targets.target_symmetries``), so that point 0 is the one nearest the image's top-left
    corner: the two OpenCV chessboard detectors (which start from opposite ends) then agree,
    and the order follows the image, as OpenCV's does. Which way round the board really is in
    each view is left to the robot's motion (``calibration.symmetry``)."""
    best, best_key = points, float(points[0].sum())
    for _, perm in target_symmetries(target):
        relabelled = np.empty_like(points)
        relabelled[perm] = points
        key = float(relabelled[0].sum())
        if key < best_key - 1e-6:
            best, best_key = relabelled, key
    return best


#: Below this grey-level range (1–99 %) an image holds no board (a lens cap, a black frame):
#: not searched (the classic detector can take seconds over sensor noise).
_MIN_RANGE = 8.0


def _no_contrast_reason(grey, what: str, threshold: float) -> str:
    lo, hi = np.percentile(grey[::2, ::2], [1, 99])
    if hi - lo >= threshold:
        return ""
    return (f"{what} not found: the image has almost no contrast (grey levels 1–99 % between "
            f"{lo:.0f} and {hi:.0f}: too dark, overexposed or covered?)")


def _detect_chessboard(grey, target: ChessboardTarget, thorough: bool):
    size = (target.cols, target.rows)
    flat = thorough and _no_contrast_reason(grey, f"chessboard {target.cols}x{target.rows}",
                                            _MIN_RANGE)
    if flat:
        return np.zeros(0, int), np.zeros((0, 2)), flat, ""
    corners, which = _find_chessboard(grey, size, thorough)
    n = target.cols * target.rows
    if corners is None:
        return (np.zeros(0, int), np.zeros((0, 2)), _chessboard_miss_reason(grey, target, thorough),
                "")
    corners = _canonical_order(corners.reshape(-1, 2), target)
    note = ""
    if (target.cols + target.rows) % 2 == 0:
        note = (f"chessboard {target.cols}x{target.rows} looks the same after a half turn: its "
                f"orientation in each view is decided by the robot's motion (prefer COLS + ROWS "
                f"odd)")
    if which != "findChessboardCornersSB":
        note = "; ".join(x for x in (note, f"found by the fallback {which}") if x)
    return np.arange(n), corners.reshape(-1, 2).astype(float), "", note


def _blob_detector(white: bool, max_area: float, min_area: float = 9.0):
    """``cv2.SimpleBlobDetector`` for the circles of a grid: dark (or ``white``) blobs of
    9 px² up to ``max_area`` px² (OpenCV's default stops at 5000 px², a circle of 80 px: too
    small for a board filling a large image), round to elliptic (steep views: inertia ratio
    ≥ 0.05), convex, thresholds every 10 grey levels."""
    import cv2
    p = cv2.SimpleBlobDetector_Params()
    p.filterByColor = True
    p.blobColor = 255 if white else 0
    p.minThreshold, p.maxThreshold, p.thresholdStep = 10.0, 245.0, 10.0
    p.minRepeatability = 2
    p.minDistBetweenBlobs = 2.0
    p.filterByArea = True
    p.minArea, p.maxArea = float(min_area), float(max(max_area, 100.0))
    p.filterByCircularity = True
    p.minCircularity = 0.5
    p.filterByConvexity = True
    p.minConvexity = 0.85
    p.filterByInertia = True
    p.minInertiaRatio = 0.05
    return cv2.SimpleBlobDetector_create(p)


def _mirrored(points: np.ndarray, cols: int) -> bool:
    """The grid's labels run the wrong way round for its printed face: seen from the front,
    T's x (along a row) then y (down the rows) turn clockwise on the image (u right, v down),
    so the quadrilateral of the four corner points has a positive signed area."""
    q = points[[0, cols - 1, len(points) - 1, len(points) - cols]]
    x, y = q[:, 0], q[:, 1]
    return float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)) < 0.0


def _detect_circles(grey, target: CircleGridTarget, thorough: bool):
    """Circle centres with ``cv2.findCirclesGrid`` (the stated polarity first, then the other
    one; the default grid finder, then ``CALIB_CB_CLUSTERING``, which copes better with strong
    perspective and distortion). The points are the blobs' centroids, i.e. the centres of the
    circles' images, not yet the images of the circles' centres (``_circle_centre_shift``)."""
    import cv2
    size = (target.cols, target.rows)
    n = target.cols * target.rows
    base = cv2.CALIB_CB_ASYMMETRIC_GRID if target.asymmetric else cv2.CALIB_CB_SYMMETRIC_GRID
    max_area = grey.size / n
    tries = [(target.white, base, 9.0), (target.white, base | cv2.CALIB_CB_CLUSTERING, 9.0)]
    if thorough:
        tries += [(target.white, base, None), (not target.white, base, 9.0),
                  (not target.white, base | cv2.CALIB_CB_CLUSTERING, 9.0)]
    for white, flags, min_area in tries:
        if min_area is None:
            # Small blobs in the way (specks, a board edge's dark line): keep blobs of at least
            # ~15 % of the area of the n-th largest one (far circles look smaller, not 7× so).
            sizes = sorted((k.size for k in _blob_detector(white, max_area).detect(grey)),
                           reverse=True)
            if len(sizes) <= n:
                continue
            min_area = max(9.0, 0.15 * math.pi / 4.0 * sizes[n - 1] ** 2)
        try:
            found, centres = cv2.findCirclesGrid(
                grey, size, flags=flags, blobDetector=_blob_detector(white, max_area, min_area))
        except cv2.error:
            found, centres = False, None
        if found and centres is not None and len(centres) == n:
            pts = np.asarray(centres, float).reshape(-1, 2)
            if not target.asymmetric and _mirrored(pts, target.cols):
                # findCirclesGrid may read a symmetric grid's rows right to left (a mirror
                # image: no pose of the printed face fits); read them left to right.
                pts = pts.reshape(target.rows, target.cols, 2)[:, ::-1].reshape(-1, 2)
            pts = _canonical_order(pts, target)
            notes = []
            if white != target.white:
                notes.append(f"the circles are {'white on black' if white else 'black on white'}"
                             f"; the spec says otherwise ({'remove' if target.white else 'add'} "
                             f"':white')")
            if target_symmetries(target):
                notes.append(f"this circle grid looks the same after a "
                             f"{'quarter' if len(target_symmetries(target)) == 3 else 'half'} "
                             f"turn: its orientation in each view is decided by the robot's "
                             f"motion")
            return np.arange(n), pts, "", "; ".join(notes)
    kind = "asymmetric" if target.asymmetric else "symmetric"
    flat = _no_contrast_reason(grey, "", 25.0)
    if flat:
        why = flat.removeprefix(" not found: ")
    else:
        blobs = _blob_detector(target.white, max_area).detect(grey)
        why = (f"{len(blobs)} {'white' if target.white else 'black'} blobs seen, "
               f"{n} circles needed in a {target.cols}x{target.rows} {kind} grid "
               + ("— board partly out of view, too small or too blurred?" if len(blobs) < n
                  else "— other blobs in the way, or COLSxROWS wrong?"))
        if len(blobs) >= n and thorough and target.cols != target.rows:
            # COLS and ROWS the other way round (circles per row, rows)?
            found, _ = cv2.findCirclesGrid(grey, (target.rows, target.cols), flags=base,
                                           blobDetector=_blob_detector(target.white, max_area))
            if found:
                why = (f"the grid is found as {target.rows}x{target.cols}: COLS counts the "
                       f"circles in a row, ROWS the rows — swap them in the spec")
    return (np.zeros(0, int), np.zeros((0, 2)),
            f"{kind} circle grid {target.cols}x{target.rows} not found: {why}", "")


_CIRCLE_SAMPLES = 64


def _circle_centre_shift(X_CT, target: CircleGridTarget, intrinsics) -> np.ndarray:
    """(n, 2) px: centroid of each circle's image (its rim projected through the lens, as a
    64-gon, area centroid) minus the image of its centre. Perspective (and distortion) move the
    first away from the second; the measured blob centres are the first."""
    import cv2
    c = circles(target)
    a = np.linspace(0.0, 2.0 * np.pi, _CIRCLE_SAMPLES, endpoint=False)
    rim = np.zeros((len(c), _CIRCLE_SAMPLES + 1, 3))
    rim[:, :-1, 0] = c[:, :1] + c[:, 2:] * np.cos(a)
    rim[:, :-1, 1] = c[:, 1:2] + c[:, 2:] * np.sin(a)
    rim[:, -1, :2] = c[:, :2]
    rvec, _ = cv2.Rodrigues(X_CT[:3, :3])
    uv, _ = cv2.projectPoints(rim.reshape(-1, 1, 3), rvec, X_CT[:3, 3], intrinsics.K,
                              intrinsics.distortion_coefficients)
    uv = uv.reshape(len(c), _CIRCLE_SAMPLES + 1, 2)
    poly, centre = uv[:, :-1], uv[:, -1]
    x, y = poly[..., 0] - centre[:, :1], poly[..., 1] - centre[:, 1:]
    xn, yn = np.roll(x, -1, axis=1), np.roll(y, -1, axis=1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum(axis=1)
    cx = ((x + xn) * cross).sum(axis=1) / (6.0 * area)
    cy = ((y + yn) * cross).sum(axis=1) / (6.0 * area)
    return np.stack([cx, cy], axis=1)


@functools.lru_cache(maxsize=16)
def _charuco_detector(target: CharucoTarget, legacy: bool, intrinsics: CameraIntrinsics):
    import cv2
    aruco = cv2.aruco
    params = aruco.CharucoParameters()
    params.cameraMatrix = intrinsics.K
    if intrinsics.distortion:
        params.distCoeffs = intrinsics.distortion_coefficients
    return aruco.CharucoDetector(charuco_board(target, legacy), params)


@functools.lru_cache(maxsize=16)
def _aruco_detector(dictionary_name: str):
    import cv2
    aruco = cv2.aruco
    params = aruco.DetectorParameters()
    params.cornerRefinementMethod = aruco.CORNER_REFINE_NONE  # corners refined by edge fits
    return aruco.ArucoDetector(get_dictionary(dictionary_name), params)


def _charuco_once(grey, target: CharucoTarget, legacy: bool, intrinsics: CameraIntrinsics):
    detector = _charuco_detector(target, legacy, intrinsics)
    corners, ids, _, marker_ids = detector.detectBoard(grey)
    n_markers = 0 if marker_ids is None else len(marker_ids)
    if ids is None or corners is None or len(ids) == 0:
        return np.zeros(0, int), np.zeros((0, 2)), n_markers
    return np.asarray(ids).ravel().astype(int), np.asarray(corners, float).reshape(-1, 2), \
        n_markers


def _detect_charuco(grey, target: CharucoTarget, intrinsics, min_points: int):
    ids, pts, n_markers = _charuco_once(grey, target, target.legacy, intrinsics)
    note = ""
    # The legacy layout only differs for an even number of rows; retry with the other one when
    # markers are seen but (almost) no board.
    if len(ids) < min_points and n_markers > 0 and target.squares_y % 2 == 0:
        ids2, pts2, _ = _charuco_once(grey, target, not target.legacy, intrinsics)
        if len(ids2) >= min_points and len(ids2) > len(ids):
            ids, pts = ids2, pts2
            note = ("board found with the legacy ChArUco pattern (OpenCV < 4.6); use ':legacy' "
                    "in the spec" if not target.legacy else
                    "board found with the current ChArUco pattern (OpenCV ≥ 4.6); remove "
                    "':legacy' from the spec")
    if n_markers == 0:
        return ids, pts, "no markers detected", note
    if len(ids) < min_points:
        return ids, pts, (f"only {len(ids)} ChArUco corners from {n_markers} markers "
                          f"(need {min_points})"), note
    order = np.argsort(ids)
    return ids[order], pts[order], "", note


def _undistort(points: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    """Ideal (undistorted) pixel coordinates of distorted pixels (..., 2)."""
    import cv2
    if not intrinsics.distortion:
        return points
    shape = points.shape
    flat = np.ascontiguousarray(points.reshape(-1, 1, 2), dtype=np.float64)
    return cv2.undistortPoints(flat, intrinsics.K, intrinsics.distortion_coefficients,
                               P=intrinsics.K).reshape(shape)


def _distort(points: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    """Distorted pixels of ideal pixel coordinates (N, 2)."""
    import cv2
    if not intrinsics.distortion:
        return points
    xy = (points - intrinsics.K[:2, 2]) @ np.linalg.inv(intrinsics.K[:2, :2]).T
    uv, _ = cv2.projectPoints(np.c_[xy, np.ones(len(xy))].reshape(-1, 1, 3), np.zeros(3),
                              np.zeros(3), intrinsics.K, intrinsics.distortion_coefficients)
    return uv.reshape(-1, 2)


_EDGE_SAMPLES = 32   # points along each border edge
_PROFILE_STEPS = 17  # samples across it


def _refine_tag_corners(grey, corners: np.ndarray, bits: int,
                        intrinsics: CameraIntrinsics) -> np.ndarray:
    """Tag corners (M, 4, 2) moved to the intersections of the tags' fitted outer border edges.

    Along each edge the grey profile across it (black inside, white outside) is sampled at 32
    places over ±0.45 cell; the edge lies where the integrated darkness of the profile equals the
    distance from the profile's dark end (exact for a symmetric blur, whatever the grey levels).
    Lines are fitted to these points in undistorted pixel coordinates (distortion does not bend
    them there), with one 3-MAD outlier pass, and intersected. A tag whose edges cannot
    be measured (image border, low contrast) keeps ArUco's corners."""
    import cv2
    original = np.asarray(corners, float).reshape(-1, 4, 2)
    out = original.copy()
    ok = np.ones(len(out), bool)
    h, w = grey.shape
    t = np.linspace(0.12, 0.88, _EDGE_SAMPLES)
    u = np.linspace(-1.0, 1.0, _PROFILE_STEPS)
    for _ in range(2):
        a = out                                   # (M, 4, 2) edge k runs from corner k to k+1
        b = np.roll(out, -1, axis=1)
        d = b - a
        length = np.linalg.norm(d, axis=2)        # (M, 4)
        d = d / np.maximum(length, 1e-9)[..., None]
        normal = np.stack([-d[..., 1], d[..., 0]], axis=2)
        outward = np.einsum("mkc,mkc->mk", normal, 0.5 * (a + b) - out.mean(axis=1)[:, None])
        normal *= np.where(outward < 0, -1.0, 1.0)[..., None]
        cell = length.mean(axis=1) / (bits + 2)   # (M,)
        r = np.clip(0.45 * cell, 1.0, 4.0)[:, None].repeat(4, axis=1)  # (M, 4)
        base = a[:, :, None, :] + (t[None, None, :, None] * length[..., None, None]) \
            * d[:, :, None, :]                    # (M, 4, S, 2)
        offsets = r[..., None] * u                # (M, 4, P)
        pts = base[:, :, :, None, :] + offsets[:, :, None, :, None] * normal[:, :, None, None, :]
        inside = np.all((pts[..., 0] >= 0) & (pts[..., 0] <= w - 1) & (pts[..., 1] >= 0)
                        & (pts[..., 1] <= h - 1), axis=3)              # (M, 4, S)
        flat = pts.reshape(-1, _PROFILE_STEPS, 2).astype(np.float32)
        prof = cv2.remap(grey, flat[..., 0], flat[..., 1], cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE).astype(float)
        prof = prof.reshape(pts.shape[:4])                             # (M, 4, S, P)
        k = max(1, _PROFILE_STEPS // 5)
        dark = prof[..., :k].mean(axis=3)
        light = prof[..., -k:].mean(axis=3)
        contrast = light - dark
        valid = inside & (contrast > 20.0) & (length[..., None] > 4.0)
        frac = np.clip((light[..., None] - prof) / np.maximum(contrast, 1e-9)[..., None], 0, 1)
        step = 2.0 * r / (_PROFILE_STEPS - 1)
        offset = -r[..., None] + step[..., None] * 0.5 * (frac[..., 1:] + frac[..., :-1]).sum(3)
        edge = base + offset[..., None] * normal[:, :, None, :]       # (M, 4, S, 2)
        edge = _undistort(edge, intrinsics)
        for _pass in range(2):                                         # fit, reject, refit
            wgt = valid.astype(float)
            n = wgt.sum(axis=2)
            ok &= np.all(n >= 4, axis=1)
            n = np.maximum(n, 1.0)
            mean = (edge * wgt[..., None]).sum(axis=2) / n[..., None]  # (M, 4, 2)
            c = edge - mean[:, :, None, :]
            sxx = (wgt * c[..., 0] ** 2).sum(2)
            syy = (wgt * c[..., 1] ** 2).sum(2)
            sxy = (wgt * c[..., 0] * c[..., 1]).sum(2)
            angle = 0.5 * np.arctan2(2 * sxy, sxx - syy)               # principal direction
            direction = np.stack([np.cos(angle), np.sin(angle)], axis=2)
            dist = c[..., 0] * -direction[..., 1, None] + c[..., 1] * direction[..., 0, None]
            # Median |distance| of the valid points (invalid ones sorted last as +inf).
            ranked = np.sort(np.where(valid, np.abs(dist), np.inf), axis=2)
            middle = np.maximum(valid.sum(axis=2) - 1, 0) // 2
            mad = 1.4826 * np.take_along_axis(ranked, middle[..., None], axis=2)[..., 0]
            mad = np.where(np.isfinite(mad), mad, 0.0)
            valid = valid & (np.abs(dist) <= np.maximum(3.0 * mad, 0.05)[..., None])
        # Corner k joins edge k−1 and edge k: p1 + s1 d1 = p2 + s2 d2.
        p1, d1 = np.roll(mean, 1, axis=1), np.roll(direction, 1, axis=1)
        p2, d2 = mean, direction
        det = d1[..., 0] * -d2[..., 1] + d2[..., 0] * d1[..., 1]
        ok &= np.all(np.abs(det) > 1e-6, axis=1)
        rhs = p2 - p1
        s1 = (rhs[..., 0] * -d2[..., 1] + d2[..., 0] * rhs[..., 1]) / np.where(
            np.abs(det) > 1e-6, det, 1.0)
        new = p1 + s1[..., None] * d1
        new = _distort(new.reshape(-1, 2), intrinsics).reshape(-1, 4, 2)
        # A corner that moved by more than 3 px was not refined but lost: keep ArUco's.
        ok &= np.all(np.linalg.norm(new - original, axis=2) <= 3.0, axis=1) \
            & np.all(np.isfinite(new), axis=(1, 2))
        out = np.where(ok[:, None, None], new, original)
    return out


def _detect_tags(grey, target, intrinsics, min_points: int):
    dictionary = get_dictionary(target_dictionary_name(target))
    corners, marker_ids, _ = _aruco_detector(target_dictionary_name(target)).detectMarkers(grey)
    if marker_ids is None or len(marker_ids) == 0:
        return np.zeros(0, int), np.zeros((0, 2)), "no markers detected", ""
    marker_ids = np.asarray(marker_ids).ravel()
    if isinstance(target, AprilTagTarget):
        wanted = {target.id}
    else:
        n = target.tags_x * target.tags_y
        wanted = set(range(target.first_id, target.first_id + n))
    counts = {}
    for m in marker_ids.tolist():
        counts[int(m)] = counts.get(int(m), 0) + 1
    # A tag id seen twice cannot be told apart: neither copy is used.
    use = [i for i, m in enumerate(marker_ids.tolist()) if int(m) in wanted and counts[int(m)] == 1]
    ids, pts = [], []
    if use:
        refined = _refine_tag_corners(grey, np.array([np.asarray(corners[i], float).reshape(4, 2)
                                                      for i in use]),
                                      dictionary.markerSize, intrinsics)
        for i, c in zip(use, refined):
            ids += [4 * int(marker_ids[i]) + k for k in range(4)]
            pts += list(c)
    if not ids:
        others = ", ".join(str(int(m)) for m in sorted(set(marker_ids.tolist()))[:10])
        what = (f"tag {target.id}" if isinstance(target, AprilTagTarget)
                else f"tags {target.first_id}…{target.first_id + len(wanted) - 1}")
        return (np.zeros(0, int), np.zeros((0, 2)),
                f"{what} not detected (detected ids: {others})", "")
    ids, pts = np.array(ids), np.array(pts, float)
    order = np.argsort(ids)
    ids, pts = ids[order], pts[order]
    if len(ids) < min_points:
        return ids, pts, f"only {len(ids)} tag corners (need {min_points})", ""
    return ids, pts, "", ""


# --------------------------------------------------------------------------------------------
# Pose and uncertainty


def _skew_rows(v: np.ndarray) -> np.ndarray:
    """(N, 3, 3) skew matrices of N vectors."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], 1), np.stack([v[:, 2], z, -v[:, 0]], 1),
                     np.stack([-v[:, 1], v[:, 0], z], 1)], axis=1)


def project_with_jacobian(X_CT: np.ndarray, p_TQ: np.ndarray, intrinsics: CameraIntrinsics):
    """Distorted pixels (N, 2) of target points and the (2N, 6) Jacobian of [u0, v0, u1, …] with
    respect to the left perturbation [δθ; δt] of X_CT (R = exp([δθ]×) R̂, t = t̂ + δt)."""
    import cv2
    R, t = X_CT[:3, :3], X_CT[:3, 3]
    rvec, _ = cv2.Rodrigues(R)
    uv, jac = cv2.projectPoints(np.asarray(p_TQ, float).reshape(-1, 1, 3), rvec, t,
                                intrinsics.K, intrinsics.distortion_coefficients)
    n = len(p_TQ)
    J_t = jac[:, 3:6].reshape(n, 2, 3)  # ∂uv/∂t = ∂uv/∂p_C
    Rp = np.asarray(p_TQ, float) @ R.T
    J_theta = -J_t @ _skew_rows(Rp)  # ∂p_C/∂δθ = −[R p]×
    return uv.reshape(-1, 2), np.concatenate([J_theta, J_t], axis=2).reshape(2 * n, 6)


def _pose(rvec, tvec) -> np.ndarray:
    import cv2
    X = np.eye(4)
    X[:3, :3] = cv2.Rodrigues(np.asarray(rvec, float).reshape(3))[0]
    X[:3, 3] = np.asarray(tvec, float).reshape(3)
    return X


def _not_found(reason, ids, pts, obj, note="") -> TargetDetection:
    return TargetDetection(False, reason, np.asarray(ids, int),
                           np.asarray(pts, float).reshape(-1, 2),
                           np.asarray(obj, float).reshape(-1, 3), None, math.nan, None, math.nan,
                           note)


def _sees_front(X_CT: np.ndarray) -> bool:
    """The camera centre lies on the printed side of the plane (T's z points away from it)."""
    return float(X_CT[:3, 2] @ X_CT[:3, 3]) > 0.0


def _solve_pose(obj, pts, intrinsics):
    """Candidate poses: IPPE's two solutions, each LM-refined, seen from the front; sorted by
    reprojection RMS. Returns a list of (X_CT, rms)."""
    import cv2
    dist = intrinsics.distortion_coefficients
    try:
        n_sol, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, pts, intrinsics.K, dist,
                                                     flags=cv2.SOLVEPNP_IPPE)
    except cv2.error:
        return []
    out = []
    for rvec, tvec in zip(rvecs[:n_sol], tvecs[:n_sol]):
        rvec, tvec = cv2.solvePnPRefineLM(obj, pts, intrinsics.K, dist, rvec.copy(), tvec.copy(),
                                          (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50,
                                           1e-12))
        X = _pose(rvec, tvec)
        if not np.all(np.isfinite(X)):
            continue
        uv, _ = cv2.projectPoints(obj.reshape(-1, 1, 3), rvec, tvec, intrinsics.K, dist)
        rms = float(np.sqrt(np.mean(np.sum((uv.reshape(-1, 2) - pts) ** 2, axis=1))))
        out.append((X, rms))
    out.sort(key=lambda c: c[1])
    return out


def _tangent_difference(X_a, X_b) -> np.ndarray:
    """δ with X_a = X_b ⊕ δ: [log(R_a R_bᵀ); t_a − t_b]."""
    import cv2
    rvec, _ = cv2.Rodrigues(X_a[:3, :3] @ X_b[:3, :3].T)
    return np.concatenate([rvec.ravel(), X_a[:3, 3] - X_b[:3, 3]])


def _chessboard_reversed(grey, target: ChessboardTarget, X_CT, intrinsics) -> bool:
    """True when the detected corner order runs from the board's white corner square, i.e. the
    detector labelled the board from the other end (only decidable when COLS + ROWS is odd)."""
    import cv2
    s = target.square
    # Centres of the outer corner squares next to corner 0 (black when printed) and to the last
    # corner (white when COLS + ROWS is odd), sampled on a small grid inside each square.
    g = np.linspace(-0.25, 0.25, 5) * s
    offsets = np.array([[x, y, 0.0] for x in g for y in g])
    first = offsets + [-0.5 * s, -0.5 * s, 0.0]
    last = offsets + [(target.cols - 0.5) * s, (target.rows - 0.5) * s, 0.0]
    rvec, _ = cv2.Rodrigues(X_CT[:3, :3])
    uv, _ = cv2.projectPoints(np.vstack([first, last]).reshape(-1, 1, 3), rvec, X_CT[:3, 3],
                              intrinsics.K, intrinsics.distortion_coefficients)
    uv = uv.reshape(-1, 2).astype(np.float32)
    values = cv2.remap(grey, uv[:, 0].reshape(1, -1), uv[:, 1].reshape(1, -1), cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_REPLICATE).ravel().astype(float)
    m = len(offsets)
    return float(np.median(values[:m])) > float(np.median(values[m:]))


def detect_target(image, target, intrinsics: CameraIntrinsics, min_points: int | None = None,
                  min_pixel_sigma: float = 0.05, ambiguity_ratio: float = 3.0,
                  max_reprojection_rms_px: float = 5.0, thorough: bool = True,
                  correct_circle_centres: bool = True) -> TargetDetection:
    """Detects ``target`` in ``image`` and estimates ``X_CT`` with its covariance.

    Args:
        image: uint8 grey (H, W), RGB (H, W, 3) or RGBA (H, W, 4); its size must be the
            intrinsics' width × height.
        target: a ``vision.targets`` target or spec string.
        intrinsics: the camera, with its distortion.
        min_points: fewest points to attempt a pose (≥ 4); default 4, and every inner corner for
            a chessboard (OpenCV only reports complete chessboards).
        min_pixel_sigma: floor (px) of the per-coordinate pixel noise used for the covariance.
        ambiguity_ratio: a second IPPE pose whose reprojection RMS is below this many times the
            best one's (itself floored at √2·min_pixel_sigma) makes the pose ambiguous (if the
            two poses differ beyond the covariance).
        max_reprojection_rms_px: above this RMS the correspondences are deemed wrong.
        thorough: chessboards: ``findChessboardCornersSB`` first, the classic detector as
            the fallback, and a probe that names why a board was missed (SB costs a few hundred
            ms on a 1280×720 frame; a real-time loop may pass False: the classic detector with
            its fast check only). Circle grids: also try the other polarity and, on a miss,
            COLS and ROWS swapped.
        correct_circle_centres: circle grids: move each measured circle centroid to where the
            circle's centre projects, by the shift the perspective and the lens predict at the
            estimated pose (``image_points`` are then the corrected points). False keeps the
            blob centroids (to measure what the correction is worth).

    Returns:
        A ``TargetDetection``; ``found=False`` with a ``reason`` when the target is not (or not
        reliably) seen.
    """
    target = validate_target(target)
    intrinsics = _check_intrinsics(intrinsics)
    grey = as_grey_image(image, intrinsics)
    min_pixel_sigma = _positive(min_pixel_sigma, "min_pixel_sigma")
    ambiguity_ratio = _positive(ambiguity_ratio, "ambiguity_ratio")
    max_rms = _positive(max_reprojection_rms_px, "max_reprojection_rms_px")
    if min_points is not None:
        if isinstance(min_points, bool) or not isinstance(min_points, (int, np.integer)) \
                or min_points < 4:
            raise ValueError(f"min_points: expected an integer ≥ 4 (a planar pose needs 4 "
                             f"points), got {min_points!r}")
    if isinstance(target, ChessboardTarget):
        need = target.cols * target.rows
        ids, pts, reason, note = _detect_chessboard(grey, target, bool(thorough))
    elif isinstance(target, CircleGridTarget):
        need = target.cols * target.rows
        ids, pts, reason, note = _detect_circles(grey, target, bool(thorough))
    else:
        need = 4 if min_points is None else int(min_points)
        if isinstance(target, CharucoTarget):
            ids, pts, reason, note = _detect_charuco(grey, target, intrinsics, need)
        else:
            ids, pts, reason, note = _detect_tags(grey, target, intrinsics, need)
    all_ids, all_p = target_object_points(target)
    lookup = {int(i): k for k, i in enumerate(all_ids)}
    obj = all_p[[lookup[int(i)] for i in ids]] if len(ids) else np.zeros((0, 3))
    if reason:
        return _not_found(reason, ids, pts, obj, note)
    if min_points is not None and len(ids) < min_points:
        return _not_found(f"only {len(ids)} points (need {min_points})", ids, pts, obj, note)
    centred = obj[:, :2] - obj[:, :2].mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    if sv[1] < 1e-3 * sv[0]:
        return _not_found(f"the {len(ids)} detected points are collinear", ids, pts, obj, note)

    candidates = _solve_pose(obj, pts, intrinsics)
    if isinstance(target, ChessboardTarget) and candidates and \
            (target.cols + target.rows) % 2 == 1 and \
            _chessboard_reversed(grey, target, candidates[0][0], intrinsics):
        # Same corners, labelled from the other end of the board.
        pts = pts[::-1].copy()
        candidates = _solve_pose(obj, pts, intrinsics)
    if isinstance(target, CircleGridTarget) and candidates and correct_circle_centres:
        # The measured points are the circles' image centroids: move them to where the circle
        # centres project, by the shift predicted at the current pose, twice (the second pass
        # changes the points by well under 1 % of the shift).
        measured = pts
        for _ in range(2):
            front_now = [c for c in candidates if _sees_front(c[0])] or candidates
            pts = measured - _circle_centre_shift(front_now[0][0], target, intrinsics)
            candidates = _solve_pose(obj, pts, intrinsics)
            if not candidates:
                break
    front = [c for c in candidates if _sees_front(c[0])]
    if not front:
        reason = ("pose estimation failed" if not candidates else
                  "the only pose fitting the points sees the target from behind (mirrored "
                  "labelling)")
        return _not_found(reason, ids, pts, obj, note)
    X_CT, rms = front[0]
    if rms > max_rms:
        return _not_found(f"reprojection RMS {rms:.2f} px > {max_rms:g} px (wrong "
                          f"correspondences or intrinsics?)", ids, pts, obj, note)

    n = len(ids)
    uv, J = project_with_jacobian(X_CT, obj, intrinsics)
    residual = (pts - uv).ravel()
    dof = 2 * n - 6
    sigma = math.sqrt(float(residual @ residual) / dof) if dof > 0 else 0.0
    sigma = max(sigma, min_pixel_sigma)
    JtJ = J.T @ J
    if np.linalg.cond(JtJ) > 1e12:
        return _not_found("degenerate geometry (pose not observable from these points)", ids,
                          pts, obj, note)
    covariance = sigma ** 2 * np.linalg.inv(JtJ)
    covariance = 0.5 * (covariance + covariance.T)

    if len(front) > 1:
        X_alt, rms_alt = front[1]
        ratio = rms_alt / max(rms, math.sqrt(2.0) * min_pixel_sigma)
        delta = _tangent_difference(X_alt, X_CT)
        distinct = float(delta @ np.linalg.solve(covariance, delta)) > _CHI2_6_999
        if ratio < ambiguity_ratio and distinct:
            return _not_found(f"ambiguous pose (IPPE ratio {ratio:.2f}; the second solution "
                              f"fits with {rms_alt:.2f} px vs {rms:.2f} px)", ids, pts, obj, note)
    return TargetDetection(True, "", np.asarray(ids, int), pts, obj, X_CT, rms, covariance, sigma,
                           note)


# --------------------------------------------------------------------------------------------
# Drawing


def _as_bgr(image) -> np.ndarray:
    import cv2
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8:
        raise ValueError("image: expected a uint8 numpy array")
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2BGR)
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGBA2BGR)
    raise ValueError(f"image: expected shape (H, W), (H, W, 3) RGB or (H, W, 4) RGBA, got "
                     f"{image.shape}")


def draw_detection(image, detection: TargetDetection, intrinsics: CameraIntrinsics,
                   axis_length: float | None = None) -> np.ndarray:
    """BGR uint8 copy of ``image`` (grey, RGB or RGBA) with the detected points (green when
    found, red otherwise), the reprojected target axes (x red, y green, z blue, pointing into the
    board; ``axis_length`` m, default half the detected points' extent) and a status line."""
    import cv2
    intrinsics = _check_intrinsics(intrinsics)
    if not isinstance(detection, TargetDetection):
        raise ValueError(f"detection: expected a TargetDetection, got "
                         f"{type(detection).__name__}")
    out = _as_bgr(image)
    scale = max(out.shape[:2]) / 640.0
    radius = max(2, int(round(3 * scale)))
    colour = (0, 200, 0) if detection.found else (0, 0, 255)
    for u, v in np.asarray(detection.image_points, float).reshape(-1, 2):
        cv2.circle(out, (int(round(u * 16)), int(round(v * 16))), radius * 16, colour,
                   max(1, int(scale)), cv2.LINE_AA, shift=4)
    if detection.found:
        if axis_length is None:
            extent = np.ptp(detection.object_points[:, :2], axis=0)
            axis_length = 0.5 * float(max(extent.max(), 1e-3))
        axis_length = _positive(axis_length, "axis_length")
        rvec, _ = cv2.Rodrigues(detection.X_CT[:3, :3])
        cv2.drawFrameAxes(out, intrinsics.K, intrinsics.distortion_coefficients, rvec,
                          detection.X_CT[:3, 3], axis_length, max(2, int(round(2 * scale))))
        text = (f"{len(detection.ids)} points, RMS {detection.reprojection_rms_px:.2f} px, "
                f"z {detection.X_CT[2, 3]:.3f} m")
    else:
        text = f"not found: {detection.reason}"
    for thickness, c in ((3, (0, 0, 0)), (1, (255, 255, 255))):
        cv2.putText(out, text, (int(8 * scale), int(20 * scale)), cv2.FONT_HERSHEY_SIMPLEX,
                    0.5 * scale, c, max(1, int(thickness * scale)), cv2.LINE_AA)
    if detection.note:
        for thickness, c in ((3, (0, 0, 0)), (1, (0, 255, 255))):
            cv2.putText(out, detection.note[:110], (int(8 * scale), int(40 * scale)),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.4 * scale, c,
                        max(1, int(thickness * scale)), cv2.LINE_AA)
    return out


__all__ = [
    "TargetDetection",
    "as_grey_image",
    "detect_target",
    "draw_detection",
    "project_with_jacobian",
]

"""The chessboard detector chain (findChessboardCornersSB first, the classic detector as the
fallback) in unkind views like the real 22-image set of issue 33 (1280×720, k1 −0.18, 9x11
inner corners), and the per-image reasons when no board is found."""

import cv2
import numpy as np

from handeye_drake.vision import detection
from handeye_drake.vision.detection import detect_target
from handeye_drake.vision.targets import object_points, parse_target
from tests.vision.unkind import board_pose, intrinsics, view

K = intrinsics()
SPEC = "chessboard:9x11:0.025"


def _errors(det, X):
    _, p = object_points(SPEC)
    truth = cv2.projectPoints(p, cv2.Rodrigues(X[:3, :3])[0], X[:3, 3], K.K,
                              K.distortion_coefficients)[0].reshape(-1, 2)
    # 9 + 11 is even: the labels may start from either end (the robot decides, not the image).
    return min(np.abs(det.image_points - truth).max(),
               np.abs(det.image_points[::-1] - truth).max())


def test_sb_finds_the_board_in_unkind_views():
    for blur, offset, tilt in ((0.0, (0.1, 0.05), (0.5, -0.3)), (2.5, (-0.12, 0.0), (0.2, 0.6)),
                               (4.0, (0.0, -0.06), (-0.6, 0.1))):
        X = board_pose(SPEC, distance=0.7, tilt=tilt, offset=offset, roll=2.0)
        det = detect_target(view(SPEC, K, X, blur_px=blur, noise=2.0), SPEC, K)
        assert det.found, det.reason
        assert "fallback" not in det.note              # SB found it
        assert _errors(det, X) < 0.5


def test_the_classic_detector_is_the_fallback(monkeypatch):
    X = board_pose(SPEC, distance=0.7)
    image = view(SPEC, K, X, noise=2.0)
    monkeypatch.setattr(cv2, "findChessboardCornersSB", lambda *a, **k: (False, None))
    det = detect_target(image, SPEC, K)
    assert det.found and det.note.endswith("found by the fallback findChessboardCorners")
    assert _errors(det, X) < 0.2
    monkeypatch.undo()
    assert detection._find_chessboard(image, (9, 11), True)[1] == "findChessboardCornersSB"


def test_a_missed_board_says_why():
    # Half the board out of the image (SB reports the largest block it locks on to: at the
    # image's edge here, or inside the image, when it says so).
    for offset in ((0.45, 0.0), (0.0, 0.3)):
        X = board_pose(SPEC, distance=0.6, offset=offset)
        det = detect_target(view(SPEC, K, X, noise=2.0), SPEC, K)
        assert not det.found and det.reason.startswith("chessboard 9x11 not found: only a block "
                                                       "of "), det.reason
        assert ("edge — the board is partly out of view" in det.reason
                or "away from the image's edges — the rest out of view" in det.reason)
    # A spec with a row too many: the board seen is named with its size.
    # (The reason alone: the classic detector searches ~10 s for a 9x12 board in this view.)
    X = board_pose(SPEC, distance=0.7)
    reason = detection._chessboard_miss_reason(view(SPEC, K, X, noise=2.0),
                                               parse_target("chessboard:9x12:0.025"), True)
    assert reason == ("chessboard 9x12 not found: only a block of 11×9 of its inner corners "
                          "is seen, away from the image's edges — the rest out of view, hidden "
                          "(glare, an occluder) or too blurred, or COLSxROWS (inner corners) "
                          "wrong?")
    # Even a very dark view (grey levels 0–12) is found by SB; a lens cap is not.
    assert detect_target((view(SPEC, K, X, noise=0.0) * 0.05).astype(np.uint8), SPEC, K).found
    capped = np.random.default_rng(0).integers(0, 4, (K.height, K.width)).astype(np.uint8)
    det = detect_target(capped, SPEC, K)
    assert not det.found and det.reason.startswith("chessboard 9x11 not found: the image has "
                                                   "almost no contrast")

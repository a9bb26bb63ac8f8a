"""detect_target on synthetic camera images of printed targets (tests/vision/synthetic.py): the
pattern rendered exactly to scale, imaged at a known X_CT through a known camera (and lens
distortion), area-sampled, blurred and noisy."""

import math

import cv2
import numpy as np
import pytest
from tests.vision.synthetic import CAMERA, look_at_pose, project, synthetic_image

from handeye_drake.estimation.se3 import make_transform, rotation_exp, rotation_log
from handeye_drake.estimation.manifold import retract_pose
from handeye_drake.vision.camera_model import CameraIntrinsics
from handeye_drake.vision.detection import (
    TargetDetection,
    detect_target,
    draw_detection,
    project_with_jacobian,
)
from handeye_drake.vision.targets import object_points, parse_target

CHESSBOARD = "chessboard:9x6:0.0236"
CHARUCO = "charuco:5x7:0.036195:0.018256:DICT_6X6_250"
APRILTAG = "apriltag:36h11:0.1:10"
APRILGRID = "aprilgrid:36h11:4x3:0.04:0.3:5"

DISTORTED = CameraIntrinsics(alpha_u=600.0, alpha_v=602.0, u0=318.5, v0=241.0, width=640,
                             height=480, distortion=(-0.28, 0.09, 0.001, -0.0007, -0.012))


def pose_error(X_true, X_est):
    """(rotation error in degrees, translation error in mm)."""
    return (math.degrees(np.linalg.norm(rotation_log(X_true[:3, :3] @ X_est[:3, :3].T))),
            1000.0 * np.linalg.norm(X_true[:3, 3] - X_est[:3, 3]))


def random_view(rng, target, distance=0.5, tilt_sigma=0.3, offset_sigma=0.01):
    return look_at_pose(target, distance, tilt=rng.normal(0.0, tilt_sigma, 3),
                        roll=rng.uniform(-np.pi, np.pi),
                        offset=rng.normal(0.0, offset_sigma, 2))


# Worst errors over 8 random views at 0.5 m (tilts ~N(0, 17°) per axis, any roll), 640×480,
# fx = 600 px, blur σ 0.5 px, noise σ 2 grey levels — measured: chessboard 9x6 (23.6 mm)
# 0.032° / 0.057 mm, ChArUco 5x7 (36 mm) 0.023° / 0.076 mm, one 100 mm AprilTag 0.077° /
# 0.113 mm, 4x3 AprilTag grid (40 mm tags) 0.006° / 0.013 mm. The bounds leave a margin of ~2×.
ACCURACY_BOUNDS = {CHESSBOARD: (0.06, 0.12), CHARUCO: (0.05, 0.15), APRILTAG: (0.15, 0.25),
                   APRILGRID: (0.015, 0.03)}


@pytest.mark.parametrize("spec", [CHESSBOARD, CHARUCO, APRILTAG, APRILGRID])
def test_pose_accuracy_at_half_a_metre(spec):
    target = parse_target(spec)
    all_ids, all_points = object_points(target)
    rng = np.random.default_rng(11)
    worst = np.zeros(2)
    for _ in range(8):
        X_CT = random_view(rng, target)
        image = synthetic_image(target, X_CT, rng=rng)
        det = detect_target(image, target, CAMERA)
        assert det.found, det.reason
        worst = np.maximum(worst, pose_error(X_CT, det.X_CT))
        # The reported points are where the true corners project, within a fraction of a pixel.
        truth = project(X_CT, det.object_points)
        assert np.abs(det.image_points - truth).max() < 0.2
        np.testing.assert_array_equal(det.object_points,
                                      all_points[np.searchsorted(all_ids, det.ids)])
        assert det.reprojection_rms_px < 0.1
        assert det.covariance.shape == (6, 6) and det.pixel_sigma >= 0.05
        assert np.all(np.linalg.eigvalsh(det.covariance) > 0)
        if spec in (CHESSBOARD, APRILTAG, APRILGRID):
            assert len(det.ids) == len(all_ids)  # every point is in view
    print(f"{spec}: worst rotation {worst[0]:.3f} deg, translation {worst[1]:.3f} mm")
    assert worst[0] < ACCURACY_BOUNDS[spec][0]
    assert worst[1] < ACCURACY_BOUNDS[spec][1]


def mean_nees(spec, seed, **kwargs):
    """Mean over 30 noisy random views at 0.5 m of eᵀ P⁻¹ e, e = X_true ⊖ X_CT."""
    target = parse_target(spec)
    rng = np.random.default_rng(seed)
    nees = []
    for _ in range(30):
        X_CT = random_view(rng, target)
        image = synthetic_image(target, X_CT, rng=rng, noise_sigma=6.0, blur_sigma=0.8)
        det = detect_target(image, target, CAMERA, **kwargs)
        assert det.found, det.reason
        e = np.concatenate([rotation_log(X_CT[:3, :3] @ det.X_CT[:3, :3].T),
                            X_CT[:3, 3] - det.X_CT[:3, 3]])
        nees.append(e @ np.linalg.solve(det.covariance, e))
    return float(np.mean(nees))


def test_chessboard_covariance_matches_the_errors():
    # With the floor lowered the covariance comes from the residuals alone. If it is right, the
    # NEES summed over 30 views is χ²(180): its mean lies in [4.57, 7.69] with 99 % probability
    # (6.12 expected once σ is estimated from 102 residual degrees of freedom). Measured: 5.67
    # here; seeds 5–9 give 5.41–6.54.
    nees = mean_nees(CHESSBOARD, seed=5, min_pixel_sigma=1e-3)
    print(f"chessboard: mean NEES {nees:.2f}")
    assert 4.57 < nees < 7.69


def test_charuco_covariance_is_not_optimistic_with_the_default_floor():
    # CharucoDetector's corners share a per-view offset of a few hundredths of a pixel, which
    # the residuals cannot reveal: with the floor lowered to the residual noise (σ ≈ 0.03 px
    # here) the mean NEES is 5.8–10.4 over seeds 5–9 (slightly optimistic). The default floor,
    # 0.05 px, covers it: measured 2.3–3.7 (conservative by ~2× in variance), never above the
    # χ²(180) 99 % bound.
    nees = mean_nees(CHARUCO, seed=8)
    print(f"ChArUco: mean NEES {nees:.2f} with min_pixel_sigma = 0.05 px")
    assert 1.5 < nees < 7.69


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(2)
    _, p_TQ = object_points(parse_target(CHARUCO))
    X_CT = make_transform(rotation_exp([2.8, 0.3, -0.2]), [0.05, -0.08, 0.6])
    uv, J = project_with_jacobian(X_CT, p_TQ, DISTORTED)
    assert J.shape == (2 * len(p_TQ), 6)
    np.testing.assert_allclose(uv, project(X_CT, p_TQ, DISTORTED), atol=1e-9)
    h = 1e-6
    J_fd = np.empty_like(J)
    for k in range(6):
        delta = np.zeros(6)
        delta[k] = h
        plus, _ = project_with_jacobian(retract_pose(X_CT, delta), p_TQ, DISTORTED)
        minus, _ = project_with_jacobian(retract_pose(X_CT, -delta), p_TQ, DISTORTED)
        J_fd[:, k] = (plus - minus).ravel() / (2 * h)
    np.testing.assert_allclose(J, J_fd, rtol=1e-5, atol=1e-4 * np.abs(J).max())
    del rng


@pytest.mark.parametrize("printed, spec, note", [
    ("charuco:6x6:0.03:0.022:DICT_5X5_100:legacy", "charuco:6x6:0.03:0.022:DICT_5X5_100",
     "board found with the legacy ChArUco pattern (OpenCV < 4.6); use ':legacy' in the spec"),
    ("charuco:6x6:0.03:0.022:DICT_5X5_100", "charuco:6x6:0.03:0.022:DICT_5X5_100:legacy",
     "board found with the current ChArUco pattern (OpenCV ≥ 4.6); remove ':legacy' from the "
     "spec"),
])
def test_charuco_legacy_pattern_is_retried(printed, spec, note):
    X_CT = look_at_pose(parse_target(printed), 0.5, tilt=(0.3, -0.2, 0.0), roll=0.4)
    image = synthetic_image(parse_target(printed), X_CT)
    det = detect_target(image, spec, CAMERA)
    assert det.found and det.note == note
    assert len(det.ids) == 25
    rot, trans = pose_error(X_CT, det.X_CT)
    assert rot < 0.1 and trans < 0.2
    # With the matching spec there is nothing to say.
    exact = detect_target(image, printed, CAMERA)
    assert exact.found and exact.note == ""
    np.testing.assert_allclose(exact.X_CT, det.X_CT, atol=1e-12)


def test_single_apriltag_found_when_tilted_and_ambiguous_when_facing():
    target = parse_target("apriltag:36h11:0.05:3")
    rng = np.random.default_rng(7)
    X_CT = look_at_pose(target, 0.5, tilt=(0.45, 0.2, 0.0), roll=1.0)
    det = detect_target(synthetic_image(target, X_CT, rng=rng, noise_sigma=3.0), target, CAMERA)
    assert det.found, det.reason
    np.testing.assert_array_equal(det.ids, [12, 13, 14, 15])
    rot, trans = pose_error(X_CT, det.X_CT)
    assert rot < 0.3 and trans < 0.3
    # 1 m away and tilted by 10°, the 30-pixel tag fits two poses 20° apart about equally well:
    # refused rather than guessed.
    X_CT = look_at_pose(target, 1.0, tilt=(math.radians(10.0), 0.0, 0.0), roll=0.3)
    det = detect_target(synthetic_image(target, X_CT, rng=rng, noise_sigma=3.0), target, CAMERA)
    assert not det.found
    assert det.reason.startswith("ambiguous pose (IPPE ratio ")
    assert det.X_CT is None and det.covariance is None and math.isnan(det.reprojection_rms_px)
    assert len(det.ids) == 4  # the corners are still reported, for drawing


def test_apriltag_with_another_id():
    target = parse_target("apriltag:36h11:0.1:10")
    image = synthetic_image(target, look_at_pose(target, 0.5, tilt=(0.3, 0.0, 0.0)))
    det = detect_target(image, "apriltag:36h11:0.1:11", CAMERA)
    assert not det.found
    assert det.reason == "tag 11 not detected (detected ids: 10)"


@pytest.mark.parametrize("spec", [CHESSBOARD, APRILGRID, CHARUCO])
def test_lens_distortion_is_handled(spec):
    target = parse_target(spec)
    pinhole = CameraIntrinsics(alpha_u=600.0, alpha_v=602.0, u0=318.5, v0=241.0, width=640,
                               height=480)
    # Off-centre, where k1 = −0.28 moves the corners by several pixels.
    X_CT = look_at_pose(target, 0.45, tilt=(0.25, -0.2, 0.0), roll=0.3, offset=(0.08, 0.05))
    image = synthetic_image(target, X_CT, intrinsics=DISTORTED)
    ideal = project(X_CT, object_points(target)[1], pinhole)
    actual = project(X_CT, object_points(target)[1], DISTORTED)
    assert np.linalg.norm(ideal - actual, axis=1).max() > 10.0
    det = detect_target(image, target, DISTORTED)
    assert det.found, det.reason
    rot, trans = pose_error(X_CT, det.X_CT)
    print(f"{spec}: {rot:.4f} deg, {trans:.4f} mm")
    assert rot < 0.1 and trans < 0.2
    assert det.reprojection_rms_px < 0.1
    # Ignoring the distortion costs two orders of magnitude (or the detection).
    wrong = detect_target(image, target, pinhole)
    assert not wrong.found or pose_error(X_CT, wrong.X_CT)[1] > 10.0


def test_chessboard_orientation_comes_from_the_print():
    # OpenCV's classic and SB detectors label this board from opposite ends; the detector reads
    # the corner colours, so a half turn of the board is a half turn of X_CT.
    target = parse_target(CHESSBOARD)
    for roll in (0.0, math.pi / 2, math.pi, -2.5):
        X_CT = look_at_pose(target, 0.5, tilt=(0.2, 0.1, 0.0), roll=roll)
        det = detect_target(synthetic_image(target, X_CT), target, CAMERA)
        assert det.found
        rot, trans = pose_error(X_CT, det.X_CT)
        assert rot < 0.1 and trans < 0.2
    grey = synthetic_image(target, look_at_pose(target, 0.5, tilt=(0.2, 0.1, 0.0), roll=0.4))
    classic = cv2.findChessboardCorners(grey, (9, 6))[1].reshape(-1, 2)
    sb = cv2.findChessboardCornersSB(grey, (9, 6))[1].reshape(-1, 2)
    assert np.abs(classic - sb[::-1]).max() < 1.0  # the two OpenCV orders are reversed


def test_symmetric_chessboard_is_flagged():
    target = parse_target("chessboard:8x6:0.025")
    X_CT = look_at_pose(target, 0.5, tilt=(0.2, 0.1, 0.0), roll=0.2)
    det = detect_target(synthetic_image(target, X_CT), target, CAMERA)
    assert det.found
    assert det.note.startswith("chessboard 8x6 looks the same after a half turn")
    assert pose_error(X_CT, det.X_CT)[0] < 0.1  # small roll: OpenCV's image order is right


def test_not_found_reasons():
    blank = np.full((480, 640), 200, np.uint8)
    for spec, reason in [
        (CHESSBOARD, "chessboard 9x6 not found: the image has almost no contrast (grey "
                     "levels 1–99 % between 200 and 200: too dark, overexposed or covered?)"),
        (CHARUCO, "no markers detected"),
        (APRILTAG, "no markers detected"),
        (APRILGRID, "no markers detected"),
    ]:
        det = detect_target(blank, spec, CAMERA)
        assert isinstance(det, TargetDetection)
        assert (det.found, det.reason) == (False, reason)
        assert det.ids.shape == (0,) and det.image_points.shape == (0, 2)
        assert det.X_CT is None and det.covariance is None
        assert math.isnan(det.reprojection_rms_px) and math.isnan(det.pixel_sigma)
    # Half of a chessboard out of view: not found; half of a ChArUco board: found from the rest.
    chess = parse_target(CHESSBOARD)
    X_CT = look_at_pose(chess, 0.4, tilt=(0.1, 0.1, 0.0), offset=(0.17, 0.0))
    assert project(X_CT, object_points(chess)[1])[:, 0].min() < 0
    det = detect_target(synthetic_image(chess, X_CT), chess, CAMERA)
    assert not det.found and det.reason.startswith("chessboard 9x6 not found: only a block of ")
    assert "at the image's left edge — the board is partly out of view" in det.reason
    charuco = parse_target(CHARUCO)
    X_CT = look_at_pose(charuco, 0.35, tilt=(0.1, 0.1, 0.0), offset=(0.0, 0.09))
    det = detect_target(synthetic_image(charuco, X_CT), charuco, CAMERA)
    assert det.found and 6 <= len(det.ids) < 24
    assert pose_error(X_CT, det.X_CT)[1] < 0.5
    few = detect_target(synthetic_image(charuco, X_CT), charuco, CAMERA, min_points=30)
    assert not few.found
    assert few.reason.startswith(f"only {len(det.ids)} ChArUco corners from ")
    assert few.reason.endswith("(need 30)")


def test_colour_images_give_the_grey_result():
    target = parse_target(CHARUCO)
    grey = synthetic_image(target, look_at_pose(target, 0.5, tilt=(0.2, 0.3, 0.0)))
    rgb = np.repeat(grey[:, :, None], 3, axis=2)
    rgba = np.concatenate([rgb, np.full_like(grey[:, :, None], 255)], axis=2)
    reference = detect_target(grey, target, CAMERA)
    for image in (rgb, rgba, grey[:, :, None]):
        det = detect_target(image, target, CAMERA)
        np.testing.assert_array_equal(det.X_CT, reference.X_CT)


@pytest.mark.parametrize("image, kwargs, message", [
    (np.zeros((480, 641), np.uint8), {}, r"^image: size 641×480 \(width×height\) differs from the "
                                         r"intrinsics' 640×480$"),
    (np.zeros((480, 640), np.float32), {}, r"^image: expected dtype uint8, got float32$"),
    (np.zeros((480, 640, 2), np.uint8), {}, r"^image: expected shape \(H, W\), \(H, W, 3\) RGB"),
    ([[0]], {}, r"^image: expected a numpy array, got list$"),
    (np.zeros((480, 640), np.uint8), {"min_points": 3}, r"^min_points: expected an integer ≥ 4"),
    (np.zeros((480, 640), np.uint8), {"min_pixel_sigma": 0.0},
     r"^min_pixel_sigma: expected a finite number > 0, got 0.0$"),
    (np.zeros((480, 640), np.uint8), {"intrinsics": "600,600,320,240"},
     r"^intrinsics: expected a CameraIntrinsics, got str$"),
    (np.zeros((480, 640), np.uint8), {"target": "chessboard:9x6"},
     r"^target spec 'chessboard:9x6': expected 3 ':'-separated fields"),
])
def test_bad_arguments_raise(image, kwargs, message):
    args = {"target": CHESSBOARD, "intrinsics": CAMERA}
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        detect_target(image, args.pop("target"), args.pop("intrinsics"), **args)


def test_draw_detection():
    target = parse_target(CHESSBOARD)
    X_CT = look_at_pose(target, 0.5, tilt=(0.2, 0.1, 0.0), roll=0.3)
    grey = synthetic_image(target, X_CT)
    det = detect_target(grey, target, CAMERA)
    drawn = draw_detection(grey, det, CAMERA, axis_length=0.05)
    assert drawn.shape == (480, 640, 3) and drawn.dtype == np.uint8
    assert np.array_equal(grey, synthetic_image(target, X_CT))  # input untouched
    # A green circle around each corner (BGR), the T x axis in red from the origin.
    u, v = np.round(det.image_points[10] + [3, 0]).astype(int)
    patch = drawn[v - 1:v + 2, u - 1:u + 2].reshape(-1, 3)
    assert any(b < 60 and g > 150 and r < 60 for b, g, r in patch)
    tip = project(X_CT, [[0.025, 0.0, 0.0]])[0]
    u, v = np.round(tip).astype(int)
    patch = drawn[v - 1:v + 2, u - 1:u + 2].reshape(-1, 3)
    assert any(b < 60 and g < 60 and r > 200 for b, g, r in patch)
    # Not found: the reason is written on the image, in colour from an RGB input.
    blank = np.full((480, 640, 3), 200, np.uint8)
    miss = draw_detection(blank, detect_target(blank, target, CAMERA), CAMERA)
    assert miss.shape == (480, 640, 3) and (miss != 200).any()
    with pytest.raises(ValueError, match=r"^detection: expected a TargetDetection"):
        draw_detection(grey, None, CAMERA)

"""Classical hand-eye solvers: exact recovery, frame conventions, input errors, noise behaviour."""

import numpy as np
import pytest

from handeye_drake.estimation.linear_model import relative_motions
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_angle, rotation_exp
from handeye_drake.estimation.solvers import METHODS, calibrate_hand_eye, solve_ax_xb
from handeye_drake.estimation.validation import rotation_defect
from tests.fixtures import random_pose, simulate_poses


def axis_angle(rng, lo_deg, hi_deg):
    """A rotation about a random axis by an angle drawn uniformly in [lo, hi] degrees."""
    n = rng.normal(size=3)
    return rotation_exp(n / np.linalg.norm(n) * np.radians(rng.uniform(lo_deg, hi_deg)))


def random_X_CE(rng):
    # θ_X ≤ 120°: Tsai–Lenz parametrizes R_X by tan(θ_X/2), singular at 180°.
    return make_transform(axis_angle(rng, 20, 120), 0.2 * rng.normal(size=3))


def exact_motions(rng, X_CE, n, lo_deg=30, hi_deg=150):
    """Robot motions B_k with large rotations and the exact camera motions A_k = X B_k X⁻¹."""
    B = [make_transform(axis_angle(rng, lo_deg, hi_deg), 0.3 * rng.normal(size=3))
         for _ in range(n)]
    return [X_CE @ b @ inverse(X_CE) for b in B], B


def perturb(X, rng, rotation_sigma, translation_sigma):
    """X with rotation-vector noise (rad, per axis) and translation noise (m); stays rigid."""
    return make_transform(X[:3, :3] @ rotation_exp(rotation_sigma * rng.normal(size=3)),
                          X[:3, 3] + translation_sigma * rng.normal(size=3))


def to_rigid_transforms(Xs):
    from pydrake.math import RigidTransform, RotationMatrix
    return [RigidTransform(RotationMatrix(X[:3, :3]), X[:3, 3]) for X in Xs]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_two_motions_recover_X_exactly(method, seed):
    rng = np.random.default_rng(seed)
    X_CE = random_X_CE(rng)
    A, B = exact_motions(rng, X_CE, 2)
    np.testing.assert_allclose(solve_ax_xb(A, B, method), X_CE, atol=1e-8)


@pytest.mark.parametrize("method", METHODS)
def test_ten_motions_recover_X_exactly(method):
    rng = np.random.default_rng(7)
    X_CE = random_X_CE(rng)
    A, B = exact_motions(rng, X_CE, 10, lo_deg=5, hi_deg=175)
    np.testing.assert_allclose(solve_ax_xb(A, B, method), X_CE, atol=1e-8)


def test_hand_built_example():
    # X_CE = 90° about z, t = (0.1, 0, 0); B1 = 90° about x, B2 = 90° about y (pure rotations).
    # Then A_k = X B_k X⁻¹ rotates about R_X·axis = y resp. −x, through the point p_C = t_X.
    Rz = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    X_CE = make_transform(Rz, [0.1, 0, 0])
    Rx = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    Ry = np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])
    B = [make_transform(Rx, [0, 0, 0]), make_transform(Ry, [0, 0, 0])]
    # A1: 90° about y_C through (0.1, 0, 0): t = p − R_y p = (0.1, 0, 0.1).
    A1 = make_transform(Ry, [0.1, 0, 0.1])
    # A2: −90° about x_C (= Rxᵀ) through (0.1, 0, 0): the point is on the axis, t = 0.
    A2 = make_transform(Rx.T, [0, 0, 0])
    np.testing.assert_allclose(X_CE @ B[0] @ inverse(X_CE), A1, atol=1e-15)
    np.testing.assert_allclose(X_CE @ B[1] @ inverse(X_CE), A2, atol=1e-15)
    for method in METHODS:
        np.testing.assert_allclose(solve_ax_xb([A1, A2], B, method), X_CE, atol=1e-12)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("pairs", ["all", "consecutive"])
def test_calibrate_hand_eye_returns_X_EC(method, pairs):
    # X_BT fixed, X_CT = inv(X_BE X_EC) X_BT: OpenCV's gripper→base / target→camera inputs.
    rng = np.random.default_rng(3)
    X_EC = random_pose(rng, rotation_scale=1.5, translation_scale=0.1)
    X_BE, X_CT = simulate_poses(rng, X_EC, 6)
    np.testing.assert_allclose(calibrate_hand_eye(X_BE, X_CT, method, pairs=pairs), X_EC,
                               atol=1e-8)
    # Same answer from pydrake RigidTransform inputs.
    X_hat = calibrate_hand_eye(to_rigid_transforms(X_BE), to_rigid_transforms(X_CT), method,
                               pairs=pairs)
    np.testing.assert_allclose(X_hat, X_EC, atol=1e-8)


def test_pairs_are_documented_motions():
    rng = np.random.default_rng(4)
    X_EC = random_pose(rng, rotation_scale=1.5, translation_scale=0.1)
    X_BE, X_CT = simulate_poses(rng, X_EC, 5)
    X_CT = [perturb(X, rng, 0.01, 0.002) for X in X_CT]  # noise: the pair sets now differ
    A, B = relative_motions(X_BE, X_CT)
    consecutive = calibrate_hand_eye(X_BE, X_CT, "park", pairs="consecutive")
    np.testing.assert_allclose(consecutive, inverse(solve_ax_xb(A, B, "park")), atol=1e-12)
    idx = [(i, j) for i in range(5) for j in range(i + 1, 5)]
    A = [X_CT[j] @ inverse(X_CT[i]) for i, j in idx]
    B = [inverse(X_BE[j]) @ X_BE[i] for i, j in idx]
    all_pairs = calibrate_hand_eye(X_BE, X_CT, "park")
    np.testing.assert_allclose(all_pairs, inverse(solve_ax_xb(A, B, "park")), atol=1e-12)
    assert np.abs(all_pairs - consecutive).max() > 1e-5


def test_orthonormalize_inputs_projects_noisy_camera_motions():
    rng = np.random.default_rng(5)
    X_CE = random_X_CE(rng)
    A, B = exact_motions(rng, X_CE, 4)
    A_noisy = [a.copy() for a in A]
    for a in A_noisy:  # the paper's model: additive noise on the rotation coefficients
        a[:3, :3] += 1e-4 * rng.normal(size=(3, 3))
    with pytest.raises(ValueError, match=r"A_list\[0\] \(rotation block\): not a rotation"):
        solve_ax_xb(A_noisy, B, "daniilidis")
    X_hat = solve_ax_xb(A_noisy, B, "daniilidis", orthonormalize_inputs=True)
    assert rotation_defect(X_hat[:3, :3]) < 1e-12
    assert np.degrees(rotation_angle(X_CE[:3, :3].T @ X_hat[:3, :3])) < 0.05
    assert np.linalg.norm(X_hat[:3, 3] - X_CE[:3, 3]) < 1e-3


# --------------------------------------------------------------------------- bad input


@pytest.fixture
def good():
    rng = np.random.default_rng(11)
    return exact_motions(rng, random_X_CE(rng), 3)


def test_wrong_shape(good):
    A, B = good
    with pytest.raises(ValueError, match=r"A_list\[0\]: expected shape \(4, 4\), got \(3, 3\)"):
        solve_ax_xb([a[:3, :3] for a in A], B)
    with pytest.raises(ValueError, match=r"B_list: expected a sequence of 4×4 transforms"):
        solve_ax_xb(A, np.eye(4))


@pytest.mark.parametrize("bad_value", [np.nan, np.inf])
def test_non_finite(good, bad_value):
    A, B = good
    B = [b.copy() for b in B]
    B[1][0, 3] = bad_value
    with pytest.raises(ValueError, match=r"B_list\[1\]: contains NaN or infinite values"):
        solve_ax_xb(A, B)
    X_BE, X_CT = simulate_poses(np.random.default_rng(0), np.eye(4), 4)
    X_CT[2] = X_CT[2].copy()
    X_CT[2][1, 1] = bad_value
    with pytest.raises(ValueError, match=r"X_CT_list\[2\]: contains NaN or infinite"):
        calibrate_hand_eye(X_BE, X_CT)


def test_non_rigid(good):
    A, B = good
    A = [a.copy() for a in A]
    A[2][:3, :3] *= 1.01  # scaled rotation
    with pytest.raises(ValueError, match=r"A_list\[2\] \(rotation block\): not a rotation matrix"):
        solve_ax_xb(A, B)
    A[2] = good[0][2].copy()
    A[2][3] = [0, 0, 1, 1]
    with pytest.raises(ValueError, match=r"A_list\[2\]: last row of a homogeneous transform"):
        solve_ax_xb(A, B)


def test_mismatched_lengths(good):
    A, B = good
    with pytest.raises(ValueError, match="A_list and B_list must have the same length, got 3 "
                                         "and 2"):
        solve_ax_xb(A, B[:2])
    X_BE, X_CT = simulate_poses(np.random.default_rng(0), np.eye(4), 4)
    with pytest.raises(ValueError, match="X_BE_list and X_CT_list must have the same length"):
        calibrate_hand_eye(X_BE, X_CT[:3])


def test_one_motion(good):
    A, B = good
    with pytest.raises(ValueError, match="need at least 2 motions with non-parallel rotation "
                                         "axes, got 1"):
        solve_ax_xb(A[:1], B[:1])
    X_BE, X_CT = simulate_poses(np.random.default_rng(0), np.eye(4), 2)
    with pytest.raises(ValueError, match="need at least 3 samples .*got 2"):
        calibrate_hand_eye(X_BE, X_CT)


def test_pure_translation():
    rng = np.random.default_rng(12)
    X_CE = random_X_CE(rng)
    A, B = exact_motions(rng, X_CE, 3)
    B[1] = make_transform(np.eye(3), [0.1, 0.2, 0.0])
    A[1] = X_CE @ B[1] @ inverse(X_CE)
    with pytest.raises(ValueError, match=r"motion 1 \(A_list\[1\], B_list\[1\]\): rotation "
                                         r"angle is 0° \(camera, A\) / 0° \(robot, B\), below "
                                         r"min_angle"):
        solve_ax_xb(A, B, "tsai")
    # In calibrate_hand_eye the error names the two samples.
    rng = np.random.default_rng(2)
    X_EC = random_pose(rng)
    X_BE, X_CT = simulate_poses(rng, X_EC, 4)
    X_BE[3] = make_transform(X_BE[1][:3, :3], X_BE[1][:3, 3] + [0.05, 0, 0])
    X_CT[3] = inverse(X_BE[3] @ X_EC) @ X_BE[1] @ X_EC @ X_CT[1]
    with pytest.raises(ValueError, match="motion between samples 1 and 3 of X_BE_list/X_CT_list"
                                         ": rotation angle is"):
        calibrate_hand_eye(X_BE, X_CT)


def test_parallel_axes():
    rng = np.random.default_rng(6)
    X_CE = random_X_CE(rng)
    axis = np.array([0.0, 0.6, 0.8])
    B = [make_transform(rotation_exp(0.7 * axis), [0.1, 0.0, 0.3]),
         make_transform(rotation_exp(-1.9 * axis), [0.0, -0.2, 0.1])]
    A = [X_CE @ b @ inverse(X_CE) for b in B]
    for method in METHODS:
        with pytest.raises(ValueError, match=r"all rotation axes of the 2 motions are "
                                             r"\(near-\)parallel: every axis lies within 0.000° "
                                             r"\(robot, B\) / 0.000° \(camera, A\) of "
                                             r"their common direction, below 1°"):
            solve_ax_xb(A, B, method)


def test_unknown_method(good):
    with pytest.raises(ValueError, match="unknown hand-eye method 'shah'; valid methods are "
                                         "'tsai', 'park', 'horaud', 'andreff', 'daniilidis'"):
        solve_ax_xb(*good, method="shah")
    X_BE, X_CT = simulate_poses(np.random.default_rng(0), np.eye(4), 3)
    with pytest.raises(ValueError, match="unknown hand-eye method 'TSAI'"):
        calibrate_hand_eye(X_BE, X_CT, method="TSAI")
    with pytest.raises(ValueError, match=r"pairs: expected one of \('all', 'consecutive'\)"):
        calibrate_hand_eye(X_BE, X_CT, pairs="random")
    with pytest.raises(ValueError, match="min_angle: must be finite and > 0"):
        solve_ax_xb(*good, min_angle=-1.0)


def test_inconsistent_rotation_angles():
    rng = np.random.default_rng(8)
    X_CE = random_X_CE(rng)
    A, B = exact_motions(rng, X_CE, 3, lo_deg=30, hi_deg=40)
    # Camera motions that rotate by 90–100° while the robot turned 30–40°: not the same motions.
    A_wrong, _ = exact_motions(rng, X_CE, 3, lo_deg=90, hi_deg=100)
    with pytest.raises(ValueError, match="all 3 motions disagree grossly .*wrong frame "
                                         "convention"):
        solve_ax_xb(A_wrong, B)
    # One inconsistent motion among three is noise for the solver, not a convention error.
    X_hat = solve_ax_xb([A_wrong[0], A[1], A[2]], B, "park")
    assert rotation_defect(X_hat[:3, :3]) < 1e-12


# --------------------------------------------------------------------------- noise


@pytest.mark.parametrize("method", METHODS)
def test_error_decreases_with_more_motions(method):
    """Rotation noise 0.5° and translation noise 1 mm on the camera motions, 10 seeds averaged."""
    counts = (3, 10, 30)
    rot_err, trans_err = np.zeros(len(counts)), np.zeros(len(counts))
    for seed in range(10):
        rng = np.random.default_rng(100 + seed)
        X_CE = random_X_CE(rng)
        A, B = exact_motions(rng, X_CE, max(counts), lo_deg=20, hi_deg=90)
        A = [perturb(a, rng, np.radians(0.5), 1e-3) for a in A]
        for i, n in enumerate(counts):
            X_hat = solve_ax_xb(A[:n], B[:n], method)
            assert rotation_defect(X_hat[:3, :3]) < 1e-12
            rot_err[i] += rotation_angle(X_CE[:3, :3].T @ X_hat[:3, :3]) / 10
            trans_err[i] += np.linalg.norm(X_hat[:3, 3] - X_CE[:3, 3]) / 10
    assert np.all(np.diff(rot_err) < 0), rot_err
    assert np.all(np.diff(trans_err) < 0), trans_err
    # ~1/√n: 3 → 30 motions should cut the error by ~3; require at least a factor 2.
    assert rot_err[-1] < 0.5 * rot_err[0], rot_err
    assert trans_err[-1] < 0.5 * trans_err[0], trans_err

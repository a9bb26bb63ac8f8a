"""Relative motions, the paper's linear model, orthonormalization, the error measures."""

import numpy as np
import pytest

from handeye_drake import (
    linear_system,
    orthonormalize,
    relative_motions,
    rotation_error_deg,
    rotation_error_quat,
    translation_error_rel,
)
from handeye_drake.estimation.linear_model import state_from_transform
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp, rotation_log
from tests.fixtures import motion_pairs, random_pose, simulate_poses


# ---------------------------------------------------------------- relative motions, linear model
def test_relative_motions_satisfy_ax_xb(rng):
    X_EC = random_pose(rng)
    X_BE, X_CT = simulate_poses(rng, X_EC, 6)
    A_list, B_list = relative_motions(X_BE, X_CT)
    assert len(A_list) == len(B_list) == 5
    X_CE = inverse(X_EC)
    for A, B in zip(A_list, B_list):
        np.testing.assert_allclose(A @ X_CE, X_CE @ B, atol=1e-12)
    # A is the camera motion X_{C0 C1}: the camera pose C1 seen from C0.
    np.testing.assert_allclose(A_list[0], X_CT[0] @ inverse(X_CT[1]), atol=1e-14)


def test_linear_system_exact_on_true_state(rng):
    X_CE = random_pose(rng, translation_scale=100.0)
    x = state_from_transform(X_CE)
    for A, B in motion_pairs(rng, X_CE, 20):
        C, y = linear_system(A, B)
        assert C.shape == (12, 12) and y.shape == (12,)
        np.testing.assert_allclose(C @ x, y, atol=1e-12 * max(1.0, np.abs(y).max()))


def test_linear_system_blocks_match_the_paper(rng):
    A, B = random_pose(rng), random_pose(rng)
    C, y = linear_system(A, B)
    np.testing.assert_array_equal(C[:9, 9:], 0)
    np.testing.assert_allclose(C[:9, :9], np.eye(9) - np.kron(A[:3, :3], B[:3, :3]))
    np.testing.assert_allclose(C[9:, :9], np.kron(np.eye(3), B[:3, 3][None, :]))
    np.testing.assert_allclose(C[9:, 9:], np.eye(3) - A[:3, :3])
    np.testing.assert_allclose(y, np.r_[np.zeros(9), A[:3, 3]])


@pytest.mark.parametrize("bad, message", [
    (np.eye(3), r"expected shape \(4, 4\)"),
    (np.full((4, 4), np.nan), "NaN or infinite"),
    (np.diag([1.0, 1.0, 1.0, 2.0]), r"last row"),
    ("not a matrix", "numeric array"),
])
def test_linear_system_rejects_bad_input(bad, message):
    with pytest.raises(ValueError, match=message):
        linear_system(bad, np.eye(4))
    with pytest.raises(ValueError, match=message):
        linear_system(np.eye(4), bad)


def test_robot_motion_must_be_rigid():
    B = np.eye(4)
    B[:3, :3] *= 1.1
    with pytest.raises(ValueError, match="not a rotation"):
        linear_system(np.eye(4), B)


def test_relative_motions_input_errors(rng):
    X_BE, X_CT = simulate_poses(rng, random_pose(rng), 4)
    with pytest.raises(ValueError, match="same length"):
        relative_motions(X_BE, X_CT[:3])
    with pytest.raises(ValueError, match="at least 2"):
        relative_motions(X_BE[:1], X_CT[:1])
    bad = [X.copy() for X in X_BE]
    bad[2][0, 0] = np.inf
    with pytest.raises(ValueError, match=r"X_BE_list\[2\].*NaN or infinite"):
        relative_motions(bad, X_CT)


# ---------------------------------------------------------------------------- orthonormalize
@pytest.mark.parametrize("method", ["svd", "qr", "horn"])
def test_orthonormalize_returns_proper_rotation(method, rng):
    reflections = 0
    for _ in range(50):
        M = rng.normal(size=(3, 3))
        if np.linalg.det(M) < 0:  # a reflection has no meaningful nearest rotation: refused
            reflections += 1
            with pytest.raises(ValueError, match="M: a reflection"):
                orthonormalize(M, method)
            continue
        R = orthonormalize(M, method)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(orthonormalize(1e200 * M, method), R, atol=1e-12)
    assert 10 < reflections < 40
    R_true = rotation_exp(rng.normal(size=3))
    np.testing.assert_allclose(orthonormalize(R_true, method), R_true, atol=1e-12)


def test_horn_and_svd_reach_the_nearest_rotation(rng):
    for _ in range(20):
        R = rotation_exp(rng.normal(size=3))
        M = R + 0.2 * rng.normal(size=(3, 3))
        R_svd, R_horn, R_qr = (orthonormalize(M, m) for m in ("svd", "horn", "qr"))
        np.testing.assert_allclose(R_horn, R_svd, atol=1e-10)
        # No rotation is nearer than the Procrustes solution; QR (Gram–Schmidt) is not optimal.
        d_svd = np.linalg.norm(M - R_svd)
        assert d_svd <= np.linalg.norm(M - R_qr) + 1e-12
        for _ in range(20):
            R_other = rotation_exp(rng.normal(size=3) * 0.05) @ R_svd
            assert d_svd <= np.linalg.norm(M - R_other) + 1e-12


def test_orthonormalize_errors():
    with pytest.raises(ValueError, match="method"):
        orthonormalize(np.eye(3), "gram")
    with pytest.raises(ValueError, match="rank-deficient"):
        orthonormalize(np.diag([1.0, 1.0, 0.0]))
    with pytest.raises(ValueError, match="NaN"):
        orthonormalize(np.full((3, 3), np.nan))


# ------------------------------------------------------------------------------------ errors
def test_error_measures_on_known_values():
    X = make_transform(np.eye(3), [3.0, 0.0, 4.0])
    Y = make_transform(rotation_exp([0.0, 0.0, np.radians(10.0)]), [3.0, 0.5, 4.0])
    assert rotation_error_deg(X, Y) == pytest.approx(10.0, abs=1e-10)
    # q = [1, 0, 0, 0], q̂ = [cos 5°, 0, 0, sin 5°] ⇒ ‖q − q̂‖ = 2 sin(2.5°).
    assert rotation_error_quat(X, Y) == pytest.approx(2 * np.sin(np.radians(2.5)), abs=1e-12)
    assert translation_error_rel(X, Y) == pytest.approx(0.1)


def test_quaternion_error_is_sign_safe():
    # A rotation by ~360° has q ≈ [−1, 0, 0, 0]: still zero error against the identity.
    Y = make_transform(rotation_exp([0.0, 0.0, 2 * np.pi - 1e-9]), np.ones(3))
    assert rotation_error_quat(np.eye(4) + np.diag([0, 0, 0, 0]), Y) < 1e-8


def test_relative_translation_error_undefined_for_zero_translation():
    with pytest.raises(ValueError, match="translation is zero"):
        translation_error_rel(np.eye(4), np.eye(4))


def test_core_import_does_not_load_drake():
    import subprocess
    import sys
    code = ("import sys, handeye_drake; handeye_drake.HandEyeKalmanFilter; "
            "assert not any(m.startswith('pydrake') for m in sys.modules), 'pydrake loaded'")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_rotation_exp_log_match_scipy_near_zero_and_pi(rng):
    """The 3×3 formulas of se3 against scipy's Rotation to 1e-12, including θ → 0 and θ → π
    (and the projection of a slightly non-orthonormal matrix, which goes through scipy)."""
    from scipy.spatial.transform import Rotation
    from handeye_drake.estimation.se3 import rotation_angle
    angles = [0.0, 1e-15, 1e-12, 1e-9, 1e-6, 1e-4, 9.99e-4, 1e-3, 1.001e-3, 0.1, 1.0, 2.0, 3.0,
              np.pi - 1e-3, np.pi - 1e-6, np.pi - 1e-9, np.pi - 1e-12, np.pi]
    for angle in angles:
        for _ in range(20):
            axis = rng.normal(size=3)
            w = angle * axis / np.linalg.norm(axis)
            R = rotation_exp(w)
            np.testing.assert_allclose(R, Rotation.from_rotvec(w).as_matrix(), atol=1e-12,
                                       rtol=0)
            R_scipy = Rotation.from_rotvec(w).as_matrix()
            np.testing.assert_allclose(rotation_log(R_scipy), Rotation.from_matrix(
                R_scipy).as_rotvec(), atol=1e-12, rtol=0)
            assert rotation_angle(R_scipy) == pytest.approx(angle, abs=1e-7)
            if angle < np.pi - 1e-6:  # (at π the axis sign is a convention)
                np.testing.assert_allclose(rotation_log(R), w, atol=1e-9, rtol=0)
    noisy = rotation_exp([0.3, -0.2, 1.0]) + 1e-6 * rng.normal(size=(3, 3))
    np.testing.assert_allclose(rotation_log(noisy), Rotation.from_matrix(noisy).as_rotvec(),
                               atol=1e-12, rtol=0)
    with pytest.raises(ValueError):
        rotation_log(np.diag([1.0, 1.0, -1.0]))

"""Linear model, orthonormalization, the paper's Kalman filter and the error measures."""

import numpy as np
import pytest
from conftest import random_pose, simulate_poses

from handeye_drake import (HandEyeKalmanFilter, linear_system, orthonormalize, relative_motions,
                           rotation_error_deg, rotation_error_quat, translation_error_rel)
from handeye_drake.estimation.kalman import measurement_covariance
from handeye_drake.estimation.linear_model import state_from_transform
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp


def motion_pairs(rng, X_CE, n, rotation_sigma_deg=3.6, translation_sigma=1.0):
    """Paper §8 robot motions and the exact camera motions A = X B X⁻¹."""
    pairs = []
    for _ in range(n):
        B = make_transform(rotation_exp(np.radians(rotation_sigma_deg) * rng.normal(size=3)),
                           translation_sigma * rng.normal(size=3))
        pairs.append((X_CE @ B @ inverse(X_CE), B))
    return pairs


def noisy(A, rng, rotation_sigma, translation_sigma):
    A = A.copy()
    A[:3, :3] += rotation_sigma * rng.normal(size=(3, 3))
    A[:3, 3] += translation_sigma * rng.normal(size=3)
    return A


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
    for _ in range(50):
        M = rng.normal(size=(3, 3))  # includes det < 0 inputs
        R = orthonormalize(M, method)
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
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


# ------------------------------------------------------------------------------ Kalman filter
@pytest.mark.parametrize("noise_model", ["paper", "full"])
def test_filter_stays_at_truth_on_noise_free_data(noise_model, rng):
    X_CE = random_pose(rng, translation_scale=100.0)
    kf = HandEyeKalmanFilter(X_CE, noise_model=noise_model)
    for A, B in motion_pairs(rng, X_CE, 200):
        kf.update(A, B)
    np.testing.assert_allclose(kf.X_CE, X_CE, atol=1e-8 * 100)
    np.testing.assert_allclose(kf.X_EC, inverse(X_CE), atol=1e-8 * 100)
    assert kf.num_updates == 200


def test_filter_converges_from_wrong_initial_estimate(rng):
    X_CE = random_pose(rng, translation_scale=1.0)
    X0 = make_transform(rotation_exp([0.1, -0.1, 0.05]) @ X_CE[:3, :3], X_CE[:3, 3] + 0.2)
    kf = HandEyeKalmanFilter(X0, rotation_sigma=0.01, translation_sigma=0.01)
    before = rotation_error_deg(X_CE, kf.X_CE), translation_error_rel(X_CE, kf.X_CE)
    for A, B in motion_pairs(rng, X_CE, 300, rotation_sigma_deg=10.0, translation_sigma=0.3):
        kf.update(noisy(A, rng, 0.001, 0.001), B)
    after = rotation_error_deg(X_CE, kf.X_CE), translation_error_rel(X_CE, kf.X_CE)
    assert after[0] < 0.2 * before[0] and after[1] < 0.2 * before[1]


def test_recursive_equals_batch_weighted_least_squares(rng):
    """Zero process noise: the Kalman recursion is the batch WLS solution with the same prior."""
    X_CE = random_pose(rng, translation_scale=3.0)
    X0 = make_transform(rotation_exp([0.2, 0.1, -0.1]) @ X_CE[:3, :3], X_CE[:3, 3] + 0.5)
    P0 = np.diag(rng.uniform(0.5, 2.0, size=12))
    sr, st = 0.02, 0.05
    kf = HandEyeKalmanFilter(X0, P0=P0, rotation_sigma=sr, translation_sigma=st)
    G2 = measurement_covariance("paper", sr, st)
    info = np.linalg.inv(P0)
    vec = info @ state_from_transform(X0)
    for A, B in motion_pairs(rng, X_CE, 40, rotation_sigma_deg=8.0):
        A = noisy(A, rng, sr, st)
        kf.update(A, B)
        C, y = linear_system(A, B)
        info += C.T @ np.linalg.solve(G2, C)
        vec += C.T @ np.linalg.solve(G2, y)
    x_batch = np.linalg.solve(info, vec)
    np.testing.assert_allclose(kf.state, x_batch, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(kf.covariance, np.linalg.inv(info), rtol=1e-7, atol=1e-10)


def test_covariance_stays_symmetric_psd_over_long_runs(rng):
    X_CE = random_pose(rng, translation_scale=100.0)
    kf = HandEyeKalmanFilter(X_CE, rotation_sigma=0.01, translation_sigma=0.1, noise_model="full",
                             process_cov=1e-12)
    for A, B in motion_pairs(rng, X_CE, 5000):
        kf.update(noisy(A, rng, 0.01, 0.1), B)
    P = kf.covariance
    assert np.all(np.isfinite(kf.state))
    np.testing.assert_array_equal(P, P.T)
    assert np.linalg.eigvalsh(P).min() >= -1e-12 * np.abs(P).max()


def test_full_noise_model_beats_paper_model_when_translation_is_large(rng):
    """PAPER §5's diagonal G2 ignores the Δ t_X term, which dominates when ‖t_X‖ ≫ σ_t/σ_r."""
    errors = {"paper": [], "full": []}
    for seed in range(6):
        r = np.random.default_rng(seed)
        X_CE = random_pose(r, translation_scale=100.0)
        X0 = make_transform(rotation_exp(r.normal(size=3) * 0.05) @ X_CE[:3, :3],
                            X_CE[:3, 3] + r.normal(size=3) * 5)
        filters = {m: HandEyeKalmanFilter(X0, P0=np.diag([0.01] * 9 + [25.0] * 3),
                                          rotation_sigma=0.01, translation_sigma=0.1,
                                          noise_model=m) for m in errors}
        for A, B in motion_pairs(r, X_CE, 100):
            A = noisy(A, r, 0.01, 0.1)
            for f in filters.values():
                f.update(A, B)
        for m, f in filters.items():
            errors[m].append(translation_error_rel(X_CE, f.X_CE))
    assert np.mean(errors["full"]) < np.mean(errors["paper"])


def test_filter_rejects_bad_input_and_keeps_state(rng):
    X_CE = random_pose(rng)
    kf = HandEyeKalmanFilter(X_CE)
    x0 = kf.state
    A, B = motion_pairs(rng, X_CE, 1)[0]
    bad_A = A.copy()
    bad_A[0, 3] = np.nan
    with pytest.raises(ValueError, match="A: contains NaN"):
        kf.update(bad_A, B)
    with pytest.raises(ValueError, match="B.*not a rotation"):
        kf.update(A, np.diag([2.0, 1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="B: expected shape"):
        kf.update(A, np.eye(3))
    np.testing.assert_array_equal(kf.state, x0)
    assert kf.num_updates == 0


@pytest.mark.parametrize("kwargs, message", [
    (dict(X_CE_init=np.eye(3)), "X_CE_init"),
    (dict(X_CE_init=np.diag([1.0, 1.0, -1.0, 1.0])), "X_CE_init.*not a rotation"),
    (dict(noise_model="gaussian"), "noise_model"),
    (dict(orthonormalization="gram"), "orthonormalization"),
    (dict(rotation_sigma=-1.0), "rotation_sigma"),
    (dict(translation_sigma=np.nan), "translation_sigma"),
    (dict(P0=-np.eye(12)), "P0.*positive semi-definite"),
    (dict(P0=np.ones((12, 3))), "P0"),
    (dict(process_cov=np.triu(np.ones((12, 12)))), "process_cov.*symmetric"),
])
def test_filter_constructor_errors(kwargs, message):
    args = dict(X_CE_init=np.eye(4))
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        HandEyeKalmanFilter(**args)


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

"""The compiled per-sample kernels against the numpy / scipy formulas they replace."""

import math

import numpy as np
import pytest
import scipy.linalg

from handeye_drake.estimation import kernels
from handeye_drake.estimation.estimator import rotation_vector_between
from handeye_drake.estimation.orthonormalize import orthonormalize_unchecked
from handeye_drake.estimation.se3 import (
    inverse,
    inverse_tangent_jacobian,
    make_transform,
    pose_to_vector,
    rotation_exp,
    rotation_log,
)
from handeye_drake.vision.camera_model import (
    MIN_DEPTH,
    CameraIntrinsics,
    apply_pose_noise,
    project_points,
)


def random_pose(rng, scale=1.0):
    return make_transform(rotation_exp(rng.normal(size=3) * 2.0), scale * rng.normal(size=3))


@pytest.mark.parametrize("sigma", [0.0, 1e-6, 0.002, 0.05, 0.3])
def test_project_to_rotation_is_the_svd_projection(sigma):
    rng = np.random.default_rng(1)
    for _ in range(200):
        M = rotation_exp(rng.normal(size=3) * 2.0) + sigma * rng.normal(size=(3, 3))
        ours = kernels.project_to_rotation(M)
        np.testing.assert_allclose(ours, orthonormalize_unchecked(M, "svd"), atol=2e-14)
        np.testing.assert_allclose(ours @ ours.T, np.eye(3), atol=1e-14)


def test_project_to_rotation_of_reflections_and_singular_matrices_takes_the_svd():
    # det ≤ 0: no polar factor in SO(3); the SVD's U diag(1, 1, −1) Vᵀ is the answer.
    for M in (-np.eye(3), np.diag([1.0, 1.0, 0.0]), np.diag([2.0, -1.0, 0.5])):
        np.testing.assert_allclose(kernels.project_to_rotation(M),
                                   orthonormalize_unchecked(M, "svd"), atol=1e-14)


def test_rotation_log_exp_and_inverse_match_se3():
    rng = np.random.default_rng(2)
    for _ in range(200):
        w = rng.normal(size=3) * rng.choice([1e-6, 1e-3, 1.0, 3.0])
        R = rotation_exp(w)
        np.testing.assert_allclose(kernels.rotation_exp(w), R, atol=1e-15)
        np.testing.assert_allclose(kernels.rotation_log(R), rotation_log(R), atol=1e-14)
        assert kernels.is_orthonormal(R)
        X = make_transform(R, rng.normal(size=3))
        np.testing.assert_allclose(kernels.inverse_pose(X), inverse(X), atol=1e-15)
    assert not kernels.is_orthonormal(np.diag([1.0, 1.0, -1.0]))
    assert not kernels.is_orthonormal(np.eye(3) * 1.001)


def test_estimate_outputs_are_the_calibrators_formulas():
    rng = np.random.default_rng(3)
    X_CE = random_pose(rng, 0.1)
    A = rng.normal(size=(12, 12))
    P = A @ A.T * 1e-4
    x_CE, x_EC, std, cov = kernels.estimate_outputs(X_CE, P)
    J = inverse_tangent_jacobian(X_CE)
    expected = J @ P[:6, :6] @ J.T
    np.testing.assert_array_equal(x_CE, pose_to_vector(X_CE))
    np.testing.assert_allclose(x_EC, pose_to_vector(inverse(X_CE)), atol=1e-15)
    np.testing.assert_allclose(cov, expected.reshape(36), rtol=1e-12, atol=1e-18)
    d = np.diag(expected)
    np.testing.assert_allclose(std, np.concatenate([np.degrees(np.sqrt(d[:3])),
                                                    np.sqrt(d[3:])]), rtol=1e-12)


@pytest.mark.parametrize("orthonormalize", [False, True])
def test_twist_motion_is_the_se3_exponential(orthonormalize):
    # X0 · exp(V s) against scipy's matrix exponential of the 4×4 twist.
    rng = np.random.default_rng(4)
    for scale in (1e-7, 1e-3, 0.3, 2.0):
        X0 = random_pose(rng)
        V = rng.normal(size=6) * scale
        s = 0.0333
        x = np.concatenate([pose_to_vector(X0), [1.0], V])
        R, p = kernels.twist_motion(x, s, orthonormalize)
        T = np.zeros((4, 4))
        a, b = V[:3] * s, V[3:] * s
        T[:3, :3] = [[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]]
        T[:3, 3] = b
        expected = X0 @ scipy.linalg.expm(T)
        np.testing.assert_allclose(R, expected[:3, :3], atol=1e-13)
        np.testing.assert_allclose(p, expected[:3, 3], atol=1e-13)



def test_twist_motion_of_a_zero_twist_is_the_start_pose_bit_for_bit():
    """The servo's commanded pose skips its zero-twist test on this: exp(0 · s) is the identity
    exactly, so X0 comes back unchanged at any s."""
    rng = np.random.default_rng(6)
    for s in (1e-9, 0.0111, 0.0333, 5.0):
        x = np.concatenate([pose_to_vector(random_pose(rng)), [1.0], np.zeros(6)])
        R, p = kernels.twist_motion(x, s, False)
        np.testing.assert_array_equal(R.reshape(9), x[:9])
        np.testing.assert_array_equal(p, x[9:12])

def test_servo_errors_depths_and_usable_points():
    rng = np.random.default_rng(5)
    X_CT = make_transform(rotation_exp([0.1, -0.05, 0.02]), [0.0, 0.0, 0.5])
    p_TQ = rng.normal(size=(5, 3)) * 0.1
    p_TQ[4] = [0.0, 0.0, -0.6]  # behind the camera
    features, desired = rng.normal(size=10) * 50, rng.normal(size=10) * 50
    visible = np.array([1.0, 0.0, 1.0, 1.0, 1.0])
    Z, usable, count, rms = kernels.servo_errors(features, visible, pose_to_vector(X_CT), p_TQ,
                                                 desired, MIN_DEPTH)
    np.testing.assert_allclose(Z, (p_TQ @ X_CT[:3, :3].T + X_CT[:3, 3])[:, 2], atol=1e-15)
    np.testing.assert_array_equal(usable, [True, False, True, True, False])
    assert count == 3
    e = (features - desired).reshape(5, 2)[usable]
    assert rms == pytest.approx(math.sqrt(np.mean(np.sum(e ** 2, axis=1))), rel=1e-14)
    _, _, count, rms = kernels.servo_errors(features, np.zeros(5), pose_to_vector(X_CT), p_TQ,
                                            desired, MIN_DEPTH)
    assert (count, rms) == (0, -1.0)


@pytest.mark.parametrize("model", ["paper", "so3"])
def test_camera_sample_is_project_points_plus_noise(model):
    rng = np.random.default_rng(6)
    # (a skewed camera: K's off-diagonal entry is used)
    K = CameraIntrinsics(alpha_u=800.0, alpha_v=780.0, theta=math.pi / 2 - 0.01, u0=320.0,
                         v0=240.0, width=640, height=480)
    X_EC = random_pose(rng, 0.05)
    X_WT = np.eye(4)
    # Points in front, one outside the image, one behind the camera.
    X_WC = make_transform(rotation_exp([math.pi, 0.0, 0.0]), [0.0, 0.0, 0.6])
    X_WE = X_WC @ inverse(X_EC)
    p_TQ = np.array([[0.0, 0.0, 0.0], [0.05, 0.02, 0.0], [-0.03, 0.04, 0.0],
                     [2.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    pixel_noise, pose_noise = rng.normal(size=10), rng.normal(size=12)
    uv, visible, x_CT, x_WC = kernels.camera_sample(
        X_WE, X_EC, X_WT, p_TQ, np.ascontiguousarray(K.K[:2, :2]),
        np.array([K.u0, K.v0]), 640.0, 480.0, MIN_DEPTH, 0.5, pixel_noise, 0.01, 0.002,
        model == "paper", pose_noise)
    X_CT = inverse(X_WE @ X_EC) @ X_WT
    p_CQ = p_TQ @ X_CT[:3, :3].T + X_CT[:3, 3]
    expected_uv, _, in_image = project_points(p_CQ, K)
    np.testing.assert_array_equal(visible, in_image.astype(float))
    np.testing.assert_array_equal(visible, [1.0, 1.0, 1.0, 0.0, 0.0])
    noisy = np.where(in_image[:, None], expected_uv + 0.5 * pixel_noise.reshape(5, 2),
                     expected_uv)
    noisy[~(p_CQ[:, 2] > MIN_DEPTH)] = 0.0
    np.testing.assert_allclose(uv, noisy.reshape(-1), atol=1e-10)
    np.testing.assert_allclose(x_CT, pose_to_vector(
        apply_pose_noise(X_CT, pose_noise, model, 0.01, 0.002)), atol=1e-14)
    np.testing.assert_allclose(x_WC, pose_to_vector(X_WE @ X_EC), atol=1e-15)


def test_excitation_term_matches_rotation_vector_between():
    rng = np.random.default_rng(7)
    R0, R1 = rotation_exp(rng.normal(size=3)), rotation_exp(rng.normal(size=3))
    phi, ok = kernels.rotation_between(R0, R1)
    assert ok
    np.testing.assert_allclose(phi, rotation_vector_between(R0, R1), atol=1e-14)
    assert not kernels.rotation_between(R0, 1.01 * R1)[1]


def test_sample_poses_are_vector_to_pose_and_say_whether_finite():
    rng = np.random.default_rng(8)
    X, Y = random_pose(rng), random_pose(rng)
    A, B, finite = kernels.sample_poses(pose_to_vector(X), pose_to_vector(Y))
    np.testing.assert_array_equal(A, X)
    np.testing.assert_array_equal(B, Y)
    assert finite
    bad = pose_to_vector(Y)
    bad[10] = np.nan
    assert not kernels.sample_poses(pose_to_vector(X), bad)[2]


@pytest.mark.parametrize("max_rejections", [None, 3])
def test_target_filter_vector_step_equals_its_update_bit_for_bit(max_rejections):
    """The calibrator's compiled step on the state vector gives, sample by sample, exactly the
    object's ``_update`` (state vector and outputs), and leaves to it what it does not handle:
    the first (target-placing) sample and a rejection that would start the inflation
    recovery. Outliers exercise the rejected path."""
    from handeye_drake.apps.speed import sample_poses
    from handeye_drake.estimation.configs import TargetFilter
    from handeye_drake.estimation.manifold import HandEyeTargetFilter
    from handeye_drake.systems.calibrator import HandEyeCalibrator

    X_BE, X_CT, X_CE, _ = sample_poses(80, seed=3)
    rng = np.random.default_rng(5)
    for k in (20, 21, 22, 23, 40):  # a run of gross outliers, then one more
        X_CT[k] = X_CT[k] @ make_transform(rotation_exp(rng.normal(size=3) * 0.3), [0.05] * 3)
    config = TargetFilter(rotation_sigma=0.002, translation_sigma=0.0005,
                          max_consecutive_rejections=max_rejections).validated()
    step = HandEyeTargetFilter.vector_step(config)
    f = HandEyeTargetFilter(config, X_CE @ make_transform(rotation_exp([0.01, 0, 0]),
                                                          [0.003, 0, 0]))
    codes = []
    for k in range(len(X_BE)):
        v = f.to_vector()
        code, v_new, x_CE, x_EC, std, cov, status = step(
            v, pose_to_vector(X_BE[k]), pose_to_vector(X_CT[k]), 1.0)
        fused = f._update(X_BE[k], X_CT[k])
        codes.append(code)
        if code == 2:
            assert v_new is v
            continue
        assert code == (0 if fused else 1)
        assert v_new.tobytes() == f.to_vector().tobytes(), k
        expected = HandEyeCalibrator._OutputValues(f, 1.0)
        for name, got in (("X_CE_estimate", x_CE), ("X_EC_estimate", x_EC),
                          ("X_EC_std", std), ("X_EC_covariance", cov), ("status", status)):
            assert got.tobytes() == expected[name].tobytes(), (k, name)
    assert codes[0] == 2 and codes.count(0) > 40 and codes.count(1) >= 3
    # With a lock-out limit of 3, the third rejection in a row is left to the object (which
    # may inflate P); without a limit no rejection is.
    assert (2 in codes[1:]) == (max_rejections is not None)


def test_camera_step_is_hand_poses_then_camera_sample_bit_for_bit_with_its_checks():
    rng = np.random.default_rng(11)
    K = CameraIntrinsics(alpha_u=800.0, alpha_v=780.0, theta=math.pi / 2 - 0.01, u0=320.0,
                         v0=240.0, width=640, height=480)
    X_EC, X_BodyE, X_BodyB = random_pose(rng, 0.05), random_pose(rng, 0.1), random_pose(rng, 0.1)
    X_WC = make_transform(rotation_exp([math.pi, 0.0, 0.0]), [0.0, 0.0, 0.6])
    X_WBodyE = X_WC @ inverse(X_EC) @ inverse(X_BodyE)
    X_WBodyB = random_pose(rng, 0.3)
    p_TQ = np.array([[0.0, 0.0, 0.0], [0.05, 0.02, 0.0], [-0.03, 0.04, 0.0], [2.0, 0.0, 0.0]])
    K2, c = np.ascontiguousarray(K.K[:2, :2]), np.array([K.u0, K.v0])
    pixel_noise, pose_noise = rng.normal(size=8), rng.normal(size=12)

    def step(X_WBodyE=X_WBodyE, pixel_noise=pixel_noise, pose_noise=pose_noise):
        return kernels.camera_step(X_WBodyE, X_BodyE, X_WBodyB, X_BodyB, X_EC, np.eye(4), p_TQ,
                                   K2, c, 640.0, 480.0, MIN_DEPTH, 0.5, pixel_noise, 0.01, 0.002,
                                   False, pose_noise, 1e-5)

    out = step()
    _, X_WE, X_BE = kernels.hand_poses(X_WBodyE, X_BodyE, X_WBodyB, X_BodyB)
    uv, visible, x_CT, x_WC = kernels.camera_sample(
        X_WE, X_EC, np.eye(4), p_TQ, K2, c, 640.0, 480.0, MIN_DEPTH, 0.5, pixel_noise, 0.01,
        0.002, False, pose_noise)
    np.testing.assert_array_equal(out, np.concatenate(
        [uv, visible, x_CT, x_WC, pose_to_vector(X_BE), [1.0, 1.0, 1.0]]))
    assert visible.tolist() == [1.0, 1.0, 1.0, 0.0]
    # Each check fails on its own defect.
    bad = X_WBodyE.copy()
    bad[0, 3] = np.nan
    assert step(X_WBodyE=bad)[-3:].tolist()[0] == 0.0
    scaled = X_WBodyE.copy()
    scaled[:3, :3] *= 1.01
    assert step(X_WBodyE=scaled)[-3:].tolist() == [1.0, 0.0, 1.0]
    for noise in ("pixel", "pose"):
        kwargs = {"pixel_noise": pixel_noise.copy(), "pose_noise": pose_noise.copy()}
        kwargs[f"{noise}_noise"][3] = np.inf
        assert step(**kwargs)[-3:].tolist() == [1.0, 1.0, 0.0]


def test_servo_sample_is_servo_errors_and_says_whether_its_inputs_are_finite():
    rng = np.random.default_rng(12)
    p_TQ = rng.normal(scale=0.05, size=(4, 3))
    x_CT = pose_to_vector(make_transform(np.eye(3), [0.0, 0.0, 0.5]))
    features, desired = rng.uniform(100, 500, size=8), rng.uniform(100, 500, size=8)
    visible = np.array([1.0, 0.0, 1.0, 1.0])
    Z, usable, count, rms, finite = kernels.servo_sample(features, visible, x_CT, p_TQ, desired,
                                                         MIN_DEPTH)
    Z0, usable0, count0, rms0 = kernels.servo_errors(features, visible, x_CT, p_TQ, desired,
                                                     MIN_DEPTH)
    np.testing.assert_array_equal(Z, Z0)
    np.testing.assert_array_equal(usable, usable0)
    assert (count, rms, finite) == (count0, rms0, True) and count == 3
    for k, a in enumerate((features, visible, x_CT)):
        args = [features.copy(), visible.copy(), x_CT.copy()]
        args[k][-1] = np.nan
        assert not kernels.servo_sample(*args, p_TQ, desired, MIN_DEPTH)[4], k


def test_all_finite():
    a, b = np.ones(3), np.zeros(12)
    assert kernels.all_finite(a, b)
    for bad in (np.nan, np.inf, -np.inf):
        c = b.copy()
        c[7] = bad
        assert not kernels.all_finite(a, c) and not kernels.all_finite(c, a)


def test_rotation_fast_test_accepts_only_what_is_clearly_within_the_tolerance():
    from handeye_drake.estimation.validation import rotation_defect
    rng = np.random.default_rng(13)
    R = rotation_exp(rng.normal(size=3))
    x = pose_to_vector(make_transform(R, [0.1, 0.2, 0.3]))
    assert kernels.rotation_fast_test(x, 1e-5)
    for scale, tolerance in ((1.0 + 1e-7, 1e-5), (1.01, 1e-5), (1.05, 0.25), (1.1, 0.25)):
        y = x.copy()
        y[:9] *= scale
        defect = rotation_defect((scale * R))
        # Accepted exactly when the defect is below 0.999 × the tolerance (frob or det).
        assert bool(kernels.rotation_fast_test(y, tolerance)) == (defect <= 0.999 * tolerance), \
            (scale, defect)
    reflected = x.copy()
    reflected[:3] *= -1.0  # det −1, orthogonal
    assert not kernels.rotation_fast_test(reflected, 0.25)

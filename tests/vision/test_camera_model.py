"""Pinhole projection, interaction matrices and the IBVS law (pure numpy, no Drake)."""

import math

import numpy as np
import pytest
from scipy.linalg import expm

from handeye_drake.estimation.se3 import (
    inverse,
    make_transform,
    rotation_exp,
    skew,
    twist_transform,
)
from handeye_drake.estimation.validation import rotation_defect
from handeye_drake.vision import (
    CameraIntrinsics,
    SelfCalibrationMotion,
    apply_pose_noise,
    default_self_calibration_motions,
    end_effector_interaction_matrix,
    ibvs_twist,
    normalized_from_pixels,
    pixel_interaction_matrix,
    point_interaction_matrix,
    project_points,
    saturate_twist,
    target_visibility,
)

CAM = CameraIntrinsics(alpha_u=800.0, alpha_v=600.0, theta=math.pi / 2, u0=320.0, v0=240.0,
                       width=640, height=480)
SKEWED = CameraIntrinsics(alpha_u=800.0, alpha_v=600.0, theta=math.pi / 3, u0=320.0, v0=240.0,
                          width=640, height=480)


def twist_exp(V):
    """exp of the twist V = [ω; v] as a 4×4 pose (body twist: X(h) = X · twist_exp(h V))."""
    M = np.zeros((4, 4))
    M[:3, :3] = skew(V[:3])
    M[:3, 3] = V[3:]
    return expm(M)


def transform_points(X, p):
    return p @ X[:3, :3].T + X[:3, 3]


# ---------------------------------------------------------------------------------------------
# Intrinsics and projection


def test_K_matrix_values():
    np.testing.assert_allclose(CAM.K, [[800, 0, 320], [0, 600, 240], [0, 0, 1]], atol=1e-12)
    # θ = 60°: cot = 1/√3, sin = √3/2.
    np.testing.assert_allclose(
        SKEWED.K, [[800, -800 / math.sqrt(3), 320], [0, 1200 / math.sqrt(3), 240], [0, 0, 1]],
        rtol=1e-14)


def test_from_fov():
    cam = CameraIntrinsics.from_fov(640, 480, math.radians(90))
    assert cam.alpha_u == pytest.approx(240.0) and cam.alpha_v == pytest.approx(240.0)
    assert (cam.u0, cam.v0, cam.width, cam.height) == (320.0, 240.0, 640, 480)


def test_project_hand_computed():
    # x = 0.05, y = -0.025.
    p_CQ = np.array([[0.1, -0.05, 2.0], [0.0, 0.0, 1.0]])
    uv, in_front, in_image = project_points(p_CQ, CAM)
    np.testing.assert_allclose(uv, [[360.0, 225.0], [320.0, 240.0]], atol=1e-12)
    assert in_front.tolist() == [True, True] and in_image.tolist() == [True, True]
    # Skewed axes: u = 800·0.05 + (800/√3)·0.025 + 320, v = −(1200/√3)·0.025 + 240.
    uv, _, _ = project_points(p_CQ[:1], SKEWED)
    np.testing.assert_allclose(uv, [[371.5470053837925, 222.67949192431124]], rtol=1e-14)


def test_normalized_from_pixels_inverts_projection():
    rng = np.random.default_rng(1)
    p = np.column_stack([rng.uniform(-0.3, 0.3, (20, 2)), rng.uniform(0.5, 3, 20)])
    for cam in (CAM, SKEWED):
        uv, _, _ = project_points(p, cam)
        np.testing.assert_allclose(normalized_from_pixels(uv, cam), p[:, :2] / p[:, 2:],
                                   atol=1e-13)


def test_visibility_behind_and_outside():
    p_CQ = np.array([
        [0.0, 0.0, -1.0],   # behind the camera
        [0.0, 0.0, 0.0],    # at the optical centre: never divided by 0
        [0.0, 0.0, 1e-9],   # closer than MIN_DEPTH
        [1.0, 0.0, 1.0],    # in front but u = 1120 > width
        [0.0, -0.5, 1.0],   # in front but v = −60 < 0
        [-0.4, -0.4, 1.0],  # u = 0, v = 0: first pixel, inside
        [0.4, 0.0, 1.0],    # u = 640 = width: just outside
    ])
    with np.errstate(all="raise"):
        uv, in_front, in_image = project_points(p_CQ, CAM)
    assert in_front.tolist() == [False, False, False, True, True, True, True]
    assert in_image.tolist() == [False, False, False, False, False, True, False]
    np.testing.assert_array_equal(uv[:3], 0.0)
    np.testing.assert_allclose(uv[3:], [[1120, 240], [320, -60], [0, 0], [640, 240]])


def test_target_visibility_matches_geometry():
    X_WE = make_transform(rotation_exp([0.1, -0.2, 0.3]), [0.2, 0.1, -0.3])
    X_EC = make_transform(rotation_exp([0.0, 0.4, 0.0]), [0.05, 0.0, 0.1])
    X_WT = X_WE @ X_EC @ make_transform(np.eye(3), [0.0, 0.0, 0.7])  # target 0.7 ahead of C
    p_TQ = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.0, -2.0]])  # last one behind
    uv, in_front, in_image = target_visibility(CAM, X_WE, X_EC, p_TQ, X_WT)
    np.testing.assert_allclose(uv[:2], [[320, 240], [320 + 800 * 0.1 / 0.7, 240]], atol=1e-9)
    assert in_front.tolist() == [True, True, False] and in_image.tolist() == [True, True, False]


@pytest.mark.parametrize("kwargs, match", [
    (dict(alpha_u=0.0), "alpha_u"),
    (dict(alpha_v=-5.0), "alpha_v"),
    (dict(theta=0.0), "theta"),
    (dict(theta=math.pi), "theta"),
    (dict(theta=math.pi - 1e-4), "theta"),
    (dict(u0=float("nan")), "u0"),
    (dict(alpha_u=float("inf")), "alpha_u"),
    (dict(width=0), "width"),
    (dict(height=0.5), "height"),
    (dict(width=640.5), "width"),
    (dict(v0="a"), "v0"),
])
def test_intrinsics_validation(kwargs, match):
    args = dict(alpha_u=800.0, alpha_v=600.0, theta=math.pi / 2, u0=320.0, v0=240.0,
                width=640, height=480)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        CameraIntrinsics(**args)


def test_projection_validation():
    with pytest.raises(ValueError, match="p_CQ.*shape"):
        project_points(np.zeros((3, 2)), CAM)
    with pytest.raises(ValueError, match="p_CQ.*NaN"):
        project_points([[0.0, np.nan, 1.0]], CAM)
    with pytest.raises(ValueError, match="intrinsics"):
        project_points([[0.0, 0.0, 1.0]], CAM.K)
    with pytest.raises(ValueError, match="uv"):
        normalized_from_pixels(np.zeros((2, 3)), CAM)


# ---------------------------------------------------------------------------------------------
# Interaction matrices


def test_point_interaction_matrix_layout():
    # Espiau–Chaumette–Rives in [v; ω] order, written out at x = 0.2, y = −0.1, Z = 2.
    x, y, Z = 0.2, -0.1, 2.0
    L_v_w = np.array([[-1 / Z, 0, x / Z, x * y, -(1 + x * x), y],
                      [0, -1 / Z, y / Z, 1 + y * y, -x * y, -x]])
    np.testing.assert_allclose(point_interaction_matrix(x, y, Z),
                               np.hstack([L_v_w[:, 3:], L_v_w[:, :3]]), atol=1e-15)


def test_point_interaction_matrix_finite_difference():
    rng = np.random.default_rng(2)
    X_WC = make_transform(rotation_exp(rng.normal(size=3)), rng.normal(size=3))
    h = 1e-5
    for _ in range(10):
        p_CQ = np.array([*rng.uniform(-0.5, 0.5, 2), rng.uniform(0.5, 3.0)])
        p_WQ = transform_points(X_WC, p_CQ)
        V_C = rng.normal(size=6)

        def s(t):
            p = transform_points(inverse(X_WC @ twist_exp(t * V_C)), p_WQ)
            return p[:2] / p[2]

        s_dot = (s(h) - s(-h)) / (2 * h)
        L = point_interaction_matrix(p_CQ[0] / p_CQ[2], p_CQ[1] / p_CQ[2], p_CQ[2])
        np.testing.assert_allclose(L @ V_C, s_dot, atol=1e-7)


def test_pixel_interaction_matrix_finite_difference():
    rng = np.random.default_rng(3)
    X_WC = make_transform(rotation_exp(rng.normal(size=3)), rng.normal(size=3))
    p_CQ = np.column_stack([rng.uniform(-0.3, 0.3, (5, 2)), rng.uniform(0.5, 2.0, 5)])
    p_WQ = transform_points(X_WC, p_CQ)
    V_C = rng.normal(size=6)
    h = 1e-5

    def uv(t):
        return project_points(transform_points(inverse(X_WC @ twist_exp(t * V_C)), p_WQ),
                              SKEWED)[0].reshape(-1)

    uv0 = uv(0.0).reshape(-1, 2)
    L = pixel_interaction_matrix(uv0, p_CQ[:, 2], SKEWED)
    assert L.shape == (10, 6)
    # Pixel velocities are O(1000) px/s; central differences are accurate to ~1e-4 px/s.
    np.testing.assert_allclose(L @ V_C, (uv(h) - uv(-h)) / (2 * h), rtol=1e-5, atol=1e-4)


def test_end_effector_interaction_matrix_finite_difference():
    """The end-effector moves by V_E (in E) and the camera follows through X_EC."""
    rng = np.random.default_rng(4)
    X_WE = make_transform(rotation_exp(rng.normal(size=3)), rng.normal(size=3))
    X_EC = make_transform(rotation_exp(rng.normal(size=3)), [0.05, -0.1, 0.15])
    X_WC = X_WE @ X_EC
    p_CQ = np.column_stack([rng.uniform(-0.3, 0.3, (4, 2)), rng.uniform(0.5, 2.0, 4)])
    p_WQ = transform_points(X_WC, p_CQ)
    V_E = rng.normal(size=6)
    h = 1e-5

    def uv(t):
        X_WC_t = X_WE @ twist_exp(t * V_E) @ X_EC
        return project_points(transform_points(inverse(X_WC_t), p_WQ), SKEWED)[0].reshape(-1)

    uv0 = uv(0.0).reshape(-1, 2)
    L_E = end_effector_interaction_matrix(uv0, p_CQ[:, 2], SKEWED, inverse(X_EC))
    np.testing.assert_allclose(L_E @ V_E, (uv(h) - uv(-h)) / (2 * h), rtol=1e-5, atol=1e-4)
    # With a wrong hand-eye estimate the prediction is wrong: X_CE is really used.
    X_EC_wrong = X_EC @ make_transform(rotation_exp([0.2, 0.0, 0.0]), [0.0, 0.02, 0.0])
    L_wrong = end_effector_interaction_matrix(uv0, p_CQ[:, 2], SKEWED, inverse(X_EC_wrong))
    assert np.linalg.norm(L_wrong @ V_E - L_E @ V_E) > 1.0


def test_twist_transform_carries_end_effector_twist_to_camera():
    rng = np.random.default_rng(5)
    X_WE = make_transform(rotation_exp(rng.normal(size=3)), rng.normal(size=3))
    X_CE = make_transform(rotation_exp(rng.normal(size=3)), rng.normal(size=3))
    X_EC = inverse(X_CE)
    V_E = rng.normal(size=6)
    V_C = twist_transform(X_CE) @ V_E
    # The camera's pose moves exactly by exp(h V_C) when E moves by exp(h V_E), for any h.
    for h in (1e-3, 0.1, 1.0):
        X_WC_h = X_WE @ twist_exp(h * V_E) @ X_EC
        np.testing.assert_allclose(X_WC_h, X_WE @ X_EC @ twist_exp(h * V_C), atol=1e-12)
    # And it equals the paper's form (§7), written in [v; ω] order:
    # [[R, −R[−Rᵀt]×], [0, R]].
    R, t = X_CE[:3, :3], X_CE[:3, 3]
    paper_v_w = np.block([[R, -R @ skew(-R.T @ t)], [np.zeros((3, 3)), R]])
    v_w = paper_v_w @ np.concatenate([V_E[3:], V_E[:3]])
    np.testing.assert_allclose(np.concatenate([v_w[3:], v_w[:3]]), V_C, atol=1e-12)


def test_interaction_matrix_validation():
    with pytest.raises(ValueError, match="Z.*> 0"):
        point_interaction_matrix(0.1, 0.1, 0.0)
    with pytest.raises(ValueError, match="finite"):
        point_interaction_matrix(np.nan, 0.1, 1.0)
    with pytest.raises(ValueError, match="Z.*> 0"):
        pixel_interaction_matrix([[320, 240], [300, 200]], [1.0, -1.0], CAM)
    with pytest.raises(ValueError, match=r"Z: expected shape \(2,\)"):
        pixel_interaction_matrix([[320, 240], [300, 200]], [1.0], CAM)
    with pytest.raises(ValueError, match="uv.*NaN"):
        pixel_interaction_matrix([[np.nan, 240]], [1.0], CAM)
    with pytest.raises(ValueError, match="X_CE"):
        end_effector_interaction_matrix([[320, 240]], [1.0], CAM, np.eye(3))
    with pytest.raises(ValueError, match="X_CE.*NaN"):
        end_effector_interaction_matrix([[320, 240]], [1.0], CAM, np.full((4, 4), np.nan))


# ---------------------------------------------------------------------------------------------
# IBVS law, saturation, self-calibration motions, pose noise


def _servo_scene(rng, perturbation):
    """Desired camera pose looking at a 5-point target 0.6 ahead, and a perturbed E pose."""
    p_TQ = np.array([[-0.05, -0.05, 0], [0.05, -0.05, 0], [0.05, 0.05, 0], [-0.05, 0.05, 0],
                     [0.0, 0.0, -0.03]])
    X_WT = make_transform(np.eye(3), [0.0, 0.0, 0.6])
    X_EC = make_transform(rotation_exp([0.1, -0.2, 0.3]), [0.05, -0.02, 0.1])
    X_WE_desired = inverse(X_EC)  # camera at the world origin
    X_WE = X_WE_desired @ twist_exp(perturbation * rng.normal(size=6))

    def uv_and_Z(X_WE_):
        p_CQ = transform_points(inverse(X_WE_ @ X_EC) @ X_WT, p_TQ)
        return project_points(p_CQ, CAM)[0], p_CQ[:, 2]

    return X_EC, X_WE, uv_and_Z(X_WE_desired)[0], uv_and_Z


def test_ibvs_step_decays_error_exponentially():
    rng = np.random.default_rng(6)
    gain, dt = 2.0, 1e-3
    X_EC, X_WE, uv_star, uv_and_Z = _servo_scene(rng, 0.01)
    uv, Z = uv_and_Z(X_WE)
    e0 = (uv - uv_star).reshape(-1)
    V_E = ibvs_twist(uv, uv_star, Z, CAM, inverse(X_EC), gain)
    uv1, _ = uv_and_Z(X_WE @ twist_exp(dt * V_E))
    e1 = (uv1 - uv_star).reshape(-1)
    # First order: e1 = e0 − λ dt L L⁺ e0 (= e0 e^{−λ dt} when e0 is in the range of L, which
    # holds to first order in the perturbation).
    L = end_effector_interaction_matrix(uv, Z, CAM, inverse(X_EC))
    np.testing.assert_allclose(e1, e0 - gain * dt * L @ np.linalg.pinv(L) @ e0,
                               atol=50 * (gain * dt) ** 2 * np.linalg.norm(e0))
    ratio = np.linalg.norm(e1) / np.linalg.norm(e0)
    assert ratio == pytest.approx(math.exp(-gain * dt), abs=2e-4)
    # A flat 2N feature vector and an all-true visibility mask give the same twist.
    np.testing.assert_allclose(
        ibvs_twist(uv.reshape(-1), uv_star.reshape(-1), Z, CAM, inverse(X_EC), gain,
                   visible=np.ones(5)), V_E, rtol=1e-12)


def test_ibvs_uses_only_visible_points():
    rng = np.random.default_rng(7)
    X_EC, X_WE, uv_star, uv_and_Z = _servo_scene(rng, 0.05)
    uv, Z = uv_and_Z(X_WE)
    visible = np.array([1, 1, 0, 1, 1], bool)
    garbage = uv.copy()
    garbage[2] = [1e4, -1e4]
    Z_bad = Z.copy()
    Z_bad[2] = -1.0  # an unused point may even be behind the camera
    V = ibvs_twist(garbage, uv_star, Z_bad, CAM, inverse(X_EC), 1.0, visible=visible)
    V_ref = ibvs_twist(uv[visible], uv_star[visible], Z[visible], CAM, inverse(X_EC), 1.0)
    np.testing.assert_allclose(V, V_ref, rtol=1e-12)
    with pytest.raises(ValueError, match="visible"):
        ibvs_twist(uv, uv_star, Z, CAM, inverse(X_EC), 1.0, visible=np.zeros(5))
    with pytest.raises(ValueError, match="gain"):
        ibvs_twist(uv, uv_star, Z, CAM, inverse(X_EC), 0.0)
    with pytest.raises(ValueError, match="uv_desired"):
        ibvs_twist(uv, uv_star[:4], Z, CAM, inverse(X_EC), 1.0)


def test_saturate_twist_keeps_direction():
    V = np.array([0.0, 0.0, 2.0, 0.3, 0.4, 0.0])  # ‖ω‖ = 2, ‖v‖ = 0.5
    np.testing.assert_allclose(saturate_twist(V, 1.0, 1.0), V / 2)
    np.testing.assert_allclose(saturate_twist(V, 4.0, 0.1), V / 5)
    np.testing.assert_allclose(saturate_twist(V, 1.0, 0.1), V / 5)
    np.testing.assert_array_equal(saturate_twist(V), V)
    np.testing.assert_array_equal(saturate_twist(V, 3.0, 1.0), V)


def test_self_calibration_motion_twist_is_rotation_about_pivot():
    motion = SelfCalibrationMotion(axis_E=(0.0, 2.0, 0.0), angle=0.3, pivot_E=(0.1, 0.0, 0.5),
                                   duration=1.5)
    assert motion.axis_E == (0.0, 1.0, 0.0)
    V = motion.twist_E()
    np.testing.assert_allclose(V[:3], [0.0, 0.2, 0.0])
    np.testing.assert_allclose(V[3:], -np.cross([0.0, 0.2, 0.0], [0.1, 0.0, 0.5]))
    X_WE = make_transform(rotation_exp([0.3, 0.2, -0.1]), [0.4, 0.0, 0.5])
    X_WE_end = X_WE @ twist_exp(motion.duration * V)
    # The pivot does not move and E turned by `angle` about `axis`.
    pivot = np.array(motion.pivot_E)
    np.testing.assert_allclose(transform_points(X_WE_end, pivot), transform_points(X_WE, pivot),
                               atol=1e-12)
    np.testing.assert_allclose(X_WE[:3, :3].T @ X_WE_end[:3, :3], rotation_exp([0, 0.3, 0]),
                               atol=1e-12)
    with pytest.raises(ValueError, match="axis_E.*non-zero"):
        SelfCalibrationMotion(axis_E=(0.0, 0.0, 1e-12), angle=0.3)
    with pytest.raises(ValueError, match="duration"):
        SelfCalibrationMotion(axis_E=(1.0, 0.0, 0.0), angle=0.3, duration=0.0)
    with pytest.raises(ValueError, match="pivot_E"):
        SelfCalibrationMotion(axis_E=(1.0, 0.0, 0.0), angle=0.3, pivot_E=(0.0, 0.0))
    motions = default_self_calibration_motions((0.0, 0.0, 0.5), angle=0.2, duration=2.0)
    assert [m.axis_E for m in motions] == [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0)]
    assert all(m.angle == 0.2 and m.duration == 2.0 for m in motions)


def test_pose_noise_models():
    rng = np.random.default_rng(8)
    X_CT = make_transform(rotation_exp([0.2, 0.5, -0.1]), [0.1, 0.0, 0.6])
    noise = rng.normal(size=12)
    X_paper = apply_pose_noise(X_CT, noise, "paper", 0.05, 0.01)
    np.testing.assert_allclose(X_paper[:3, :3], X_CT[:3, :3] + 0.05 * noise[:9].reshape(3, 3))
    np.testing.assert_allclose(X_paper[:3, 3], X_CT[:3, 3] + 0.01 * noise[9:])
    assert rotation_defect(X_paper[:3, :3]) > 1e-2  # not re-orthonormalized
    X_so3 = apply_pose_noise(X_CT, noise, "so3", 0.05, 0.01)
    assert rotation_defect(X_so3[:3, :3]) < 1e-12
    np.testing.assert_allclose(X_so3[:3, :3] @ X_CT[:3, :3].T, rotation_exp(0.05 * noise[:3]),
                               atol=1e-12)
    np.testing.assert_allclose(X_so3[:3, 3], X_paper[:3, 3])
    np.testing.assert_array_equal(apply_pose_noise(X_CT, noise, "paper", 0.0, 0.0), X_CT)
    with pytest.raises(ValueError, match="model"):
        apply_pose_noise(X_CT, noise, "rpy", 0.05, 0.01)
    with pytest.raises(ValueError, match="rotation_sigma"):
        apply_pose_noise(X_CT, noise, "so3", -1.0, 0.01)
    with pytest.raises(ValueError, match="noise"):
        apply_pose_noise(X_CT, noise[:9], "so3", 0.05, 0.01)


def test_vision_package_does_not_load_drake():
    import subprocess
    import sys
    code = ("import sys, handeye_drake.vision; "
            "assert not any(m.startswith('pydrake') for m in sys.modules), 'pydrake loaded'")
    subprocess.run([sys.executable, "-c", code], check=True)

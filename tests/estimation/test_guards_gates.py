"""The estimation's rejection gates, each tested with a planted error between the right bound
and a wrong one (10× off, or the wrong degrees of freedom), so the sample must be rejected, and
with clean data, where (almost) nothing may be:

- ``ml.robust_initial_estimate``: the rotation-angle gate (|θ_A − θ_B| against √χ²₃ σ) and the
  whitened-residual gate (χ² with 6 dof for "so3");
- ``reprojection.fit_corners``: the corner gate (χ²₂ of the pixel error) and the image gate
  (χ²₆ of the per-image pose error)."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from handeye_drake.estimation import ml
from handeye_drake.estimation import reprojection as rp
from handeye_drake.estimation.se3 import make_transform, rotation_exp

from .test_ml import _motions, _noisy, _pose
from .test_reprojection import V_TRUE, _scene

SR, ST = 0.01, 0.002


@pytest.fixture(scope="module")
def motions():
    rng = np.random.default_rng(21)
    X_CE = _pose(rng, 1.5, 0.2)
    A, B = _motions(rng, X_CE, 60)
    return _noisy(rng, A, "so3", SR, ST), B


def test_clean_motions_are_kept(motions):
    # χ²₆ at 0.999: about 0.06 of 60 clean motions rejected; a 1-dof threshold (10.8) would drop
    # ~9 % of them.
    A, B = motions
    r = ml.robust_initial_estimate(A, B, SR, ST, "so3")
    assert r.inliers.sum() >= 59, np.flatnonzero(~r.inliers)


def test_a_motion_whose_rotation_angle_is_8_sigma_off_fails_the_angle_gate(motions):
    A, B = list(motions[0]), motions[1]
    sigma_axis = math.sqrt(ml.rotation_noise_variance("so3", SR))
    bound = math.sqrt(chi2.ppf(0.999, 3)) * sigma_axis
    k = 5
    axis = Rotation.from_matrix(A[k][:3, :3]).as_rotvec()
    axis /= np.linalg.norm(axis)
    A[k] = make_transform(rotation_exp(axis * 2 * bound) @ A[k][:3, :3], A[k][:3, 3])
    # One round: the angle gate alone decides (the residual gate would catch it later).
    r = ml.robust_initial_estimate(A, B, SR, ST, "so3", max_rounds=1)
    assert not r.inliers[k]
    assert r.inliers.sum() >= 58


@pytest.fixture(scope="module")
def scene():
    return _scene(np.random.default_rng(31), 14)


def test_a_corner_45_whitened_is_rejected_and_clean_ones_kept(scene):
    # Pixel noise 0.1 px: a corner moved (0.47, 0.47) px has whitened error² ≈ 45, over χ²₂'s
    # 1 − 10⁻⁶ quantile 27.6 (and under a 20-dof 65.4).
    data, X_H, X_F = scene
    U = data.image_points.copy()
    bad = np.flatnonzero(data.image == 3)[10]
    U[bad] += [0.474, 0.474]
    d = rp.CornerData(data.X_R, data.image, data.object_points, U)
    f = rp.fit_corners(d, X_H, X_F, V_TRUE, "none", pixel_sigma0=0.1)
    assert abs(f.pixel_sigma - 0.1) < 0.02
    assert not f.corner_used[bad]
    assert (~f.corner_used).sum() <= 2, np.flatnonzero(~f.corner_used)
    assert f.image_used.all()


def test_an_image_whose_pose_is_9_sigma_off_is_rejected(scene):
    # Per-image robot error 0.5 mrad per axis: an image turned 4.5 mrad more has pose error²
    # ≈ 81 + 6, over χ²₆'s 1 − 10⁻⁶ quantile 38 (and under a 60-dof 127).
    data, X_H, X_F = scene
    X_R = data.X_R.copy()
    k = 6
    X_R[k] = X_R[k] @ make_transform(rotation_exp(np.array([4.5e-3, 0.0, 0.0])), np.zeros(3))
    d = rp.CornerData(X_R, data.image, data.object_points, data.image_points)
    f = rp.fit_corners(d, X_H, X_F, V_TRUE, "none", pixel_sigma0=0.1)
    assert not f.image_used[k]
    assert f.image_used.sum() == data.num_images - 1


def test_intrinsics_vector_and_matrix_are_opencvs_layout():
    K = np.array([[612.0, 0.0, 321.0], [0.0, 611.0, 239.0], [0.0, 0.0, 1.0]])
    d = np.array([-0.1, 0.05, 0.001, -0.0005, 0.002])
    v = rp.intrinsics_vector(K, d)
    np.testing.assert_array_equal(v, [612.0, 611.0, 321.0, 239.0, *d])
    K2, d2 = rp.intrinsics_matrix(v)
    np.testing.assert_array_equal(K2, K)
    np.testing.assert_array_equal(np.ravel(d2), d)

"""Anisotropic and per-sample camera noise in the maximum-likelihood pose form
(``ml.refine_ml_poses``, ``observability.refine_ml_poses_fixed``): a scalar σ is the isotropic
special case (identical results), per-axis σ are a diagonal per-sample covariance (identical
results), the anisotropic fit is more accurate than the isotropic one on anisotropic data and
its covariance is honest (NEES), and bad noise arguments raise ValueError naming them."""

import numpy as np
import pytest
from scipy.stats import chi2

from handeye_drake.estimation import ml
from handeye_drake.estimation.observability import refine_ml_poses_fixed
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp, rotation_log

#: PnP-like noise: tilt about x, y worse than roll about z, depth worse than lateral.
SIGMA_R = np.radians([0.15, 0.15, 0.04])
SIGMA_T = np.array([0.0003, 0.0003, 0.0015])


def _scene(rng, K):
    """(X_BE (K), X_CE, X_BT): a camera on the flange looking at a target ~0.5 m away."""
    X_EC = make_transform(rotation_exp([0.05, -0.03, 1.5]), [0.04, -0.01, 0.07])
    X_BT = make_transform(rotation_exp([0.0, 0.0, 0.4]), [0.5, 0.0, 0.0])
    X_BE = []
    for _ in range(K):
        R_TC = rotation_exp([np.pi, 0, 0]) @ rotation_exp(rng.normal(size=3) * 0.35)
        p_TC = -0.5 * R_TC[:, 2] + rng.normal(size=3) * [0.05, 0.05, 0.02]
        X_BE.append(X_BT @ make_transform(R_TC, p_TC) @ inverse(X_EC))
    return np.array(X_BE), inverse(X_EC), X_BT


def _measure(rng, X_BE, X_CE, X_BT, sr, st, covariances=None):
    out = []
    for k, X in enumerate(X_BE):
        X_CT = X_CE @ inverse(X) @ X_BT
        if covariances is None:
            n = np.concatenate([sr * rng.normal(size=3), st * rng.normal(size=3)])
        else:
            n = np.linalg.cholesky(covariances[k]) @ rng.normal(size=6)
        out.append(make_transform(rotation_exp(n[:3]) @ X_CT[:3, :3], X_CT[:3, 3] + n[3:]))
    return np.array(out)


def _error(X_CE_true, X_CE):
    return np.concatenate([rotation_log(X_CE_true[:3, :3] @ X_CE[:3, :3].T),
                           X_CE_true[:3, 3] - X_CE[:3, 3]])


def test_a_scalar_sigma_is_isotropic_and_per_axis_sigma_is_a_diagonal_covariance():
    rng = np.random.default_rng(0)
    X_BE, X_CE, X_BT = _scene(rng, 20)
    X_CT = _measure(rng, X_BE, X_CE, X_BT, SIGMA_R, SIGMA_T)
    start = X_CE @ make_transform(rotation_exp([0.02, -0.01, 0.03]), [0.004, 0.002, -0.003])
    scalar = ml.refine_ml_poses(X_BE, X_CT, start, 0.002, 0.0005)
    three = ml.refine_ml_poses(X_BE, X_CT, start, [0.002] * 3, [0.0005] * 3)
    np.testing.assert_allclose(three.X_CE, scalar.X_CE, atol=1e-12)
    np.testing.assert_allclose(three.full_covariance, scalar.full_covariance, rtol=1e-9)
    assert three.cost == pytest.approx(scalar.cost, rel=1e-9)

    axes = ml.refine_ml_poses(X_BE, X_CT, start, SIGMA_R, SIGMA_T)
    C = np.broadcast_to(np.diag(np.concatenate([SIGMA_R, SIGMA_T]) ** 2), (20, 6, 6))
    per_sample = ml.refine_ml_poses(X_BE, X_CT, start, None, None, covariances=C)
    np.testing.assert_allclose(per_sample.X_CE, axes.X_CE, atol=1e-12)
    np.testing.assert_allclose(per_sample.full_covariance, axes.full_covariance, rtol=1e-8,
                               atol=1e-16)
    assert per_sample.cost == pytest.approx(axes.cost, rel=1e-9)
    # The anisotropic weighting moves the estimate (it is not the isotropic one).
    assert np.linalg.norm(_error(axes.X_CE, scalar.X_CE)[3:]) > 1e-6

    # The fit with held components takes the same noise arguments (nothing held: same fit).
    fixed = refine_ml_poses_fixed(X_BE, X_CT, start, SIGMA_R, SIGMA_T)
    np.testing.assert_allclose(fixed.X_CH, axes.X_CE, atol=1e-9)
    np.testing.assert_allclose(fixed.covariance, axes.covariance, rtol=1e-6, atol=1e-16)
    fixed_c = refine_ml_poses_fixed(X_BE, X_CT, start, None, None, covariances=C)
    np.testing.assert_allclose(fixed_c.X_CH, axes.X_CE, atol=1e-9)
    # Eye-to-hand is the same model with the robot poses inverted: the same fit.
    e2h = refine_ml_poses_fixed(np.array([inverse(X) for X in X_BE]), X_CT, start, SIGMA_R,
                                SIGMA_T, mode="eye_to_hand")
    np.testing.assert_allclose(e2h.X_CH, axes.X_CE, atol=1e-9)


def test_per_axis_weighting_beats_isotropic_and_its_covariance_is_honest():
    """Monte Carlo, 150 recordings of 25 samples with PnP-like anisotropic noise: the per-axis
    ML error is smaller than the isotropic ML's (its σ is the RMS of the axes), and its NEES
    against the truth is χ²(6) (mean within the 99.9 % band of 150 draws)."""
    rng = np.random.default_rng(3)
    iso_sq, axes_sq, nees = [], [], []
    for _ in range(150):
        X_BE, X_CE, X_BT = _scene(rng, 25)
        X_CT = _measure(rng, X_BE, X_CE, X_BT, SIGMA_R, SIGMA_T)
        iso = ml.refine_ml_poses(X_BE, X_CT, X_CE, np.sqrt(np.mean(SIGMA_R**2)),
                                 np.sqrt(np.mean(SIGMA_T**2)))
        axes = ml.refine_ml_poses(X_BE, X_CT, X_CE, SIGMA_R, SIGMA_T)
        e_iso, e_axes = _error(X_CE, iso.X_CE), _error(X_CE, axes.X_CE)
        iso_sq.append(e_iso**2)
        axes_sq.append(e_axes**2)
        nees.append(e_axes @ np.linalg.solve(axes.covariance, e_axes))
    rms_iso, rms_axes = np.sqrt(np.mean(iso_sq, 0)), np.sqrt(np.mean(axes_sq, 0))
    # Both clearly better (measured: 0.61 and 0.64 of the isotropic RMS error).
    assert np.linalg.norm(rms_axes[3:]) < 0.8 * np.linalg.norm(rms_iso[3:])
    assert np.linalg.norm(rms_axes[:3]) < 0.8 * np.linalg.norm(rms_iso[:3])
    lo, hi = chi2.ppf([0.0005, 0.9995], 6 * 150) / 150
    assert lo < np.mean(nees) < hi


def test_per_sample_covariances_with_correlations_are_used_and_honest():
    """Each sample with its own full covariance (correlated tilt / lateral translation, as a
    PnP pose has): the per-sample ML error is smaller than the best diagonal fit's, NEES χ²(6)."""
    rng = np.random.default_rng(5)
    diag_sq, full_sq, nees = [], [], []
    for _ in range(100):
        X_BE, X_CE, X_BT = _scene(rng, 25)
        C = []
        for _ in range(25):
            s = np.concatenate([SIGMA_R, SIGMA_T]) * rng.uniform(0.5, 2.0, 6)
            corr = np.eye(6)
            corr[0, 4] = corr[4, 0] = rng.uniform(0.6, 0.9)   # tilt about x ↔ y translation
            corr[1, 3] = corr[3, 1] = -rng.uniform(0.6, 0.9)  # tilt about y ↔ x translation
            C.append(corr * np.outer(s, s))
        C = np.array(C)
        X_CT = _measure(rng, X_BE, X_CE, X_BT, None, None, covariances=C)
        d = np.sqrt(np.median(np.diagonal(C, axis1=1, axis2=2), axis=0))
        diag = ml.refine_ml_poses(X_BE, X_CT, X_CE, d[:3], d[3:])
        full = ml.refine_ml_poses(X_BE, X_CT, X_CE, None, None, covariances=C)
        e_full = _error(X_CE, full.X_CE)
        diag_sq.append(_error(X_CE, diag.X_CE) ** 2)
        full_sq.append(e_full**2)
        nees.append(e_full @ np.linalg.solve(full.covariance, e_full))
    assert np.sum(np.mean(full_sq, 0)) < 0.8 * np.sum(np.mean(diag_sq, 0))
    lo, hi = chi2.ppf([0.0005, 0.9995], 6 * 100) / 100
    assert lo < np.mean(nees) < hi


def test_bad_noise_arguments_name_the_problem():
    rng = np.random.default_rng(0)
    X_BE, X_CE, X_BT = _scene(rng, 6)
    X_CT = _measure(rng, X_BE, X_CE, X_BT, SIGMA_R, SIGMA_T)
    with pytest.raises(ValueError, match=r"rotation_sigma: expected shape \(3,\)"):
        ml.refine_ml_poses(X_BE, X_CT, X_CE, [0.1, 0.1], 0.001)
    with pytest.raises(ValueError, match=r"translation_sigma: per-axis standard deviations "
                                         r"must be > 0"):
        ml.refine_ml_poses(X_BE, X_CT, X_CE, 0.001, [0.001, 0.0, 0.001])
    with pytest.raises(ValueError, match="rotation_sigma: expected a positive number "
                                         r"\(one σ: this form is isotropic\)"):
        ml.refine_ml_poses(X_BE, X_CT, X_CE, SIGMA_R, 0.001, noise_model="paper")
    with pytest.raises(ValueError, match="rotation_sigma: expected a positive number "
                                         r"\(one σ: this form is isotropic\)"):
        A = [X_CT[0] @ inverse(X_CT[1])] * 3
        ml.refine_ml(A, A, X_CE, SIGMA_R, 0.001)
    C = np.broadcast_to(np.eye(6) * 1e-6, (6, 6, 6)).copy()
    C[2, 0, 0] = -1e-6
    with pytest.raises(ValueError, match=r"covariances\[2\]: not positive definite"):
        ml.refine_ml_poses(X_BE, X_CT, X_CE, None, None, covariances=C)
    C[2, 0, 0], C[4, 0, 1] = 1e-6, 1e-7
    with pytest.raises(ValueError, match=r"covariances\[4\]: not symmetric"):
        ml.refine_ml_poses(X_BE, X_CT, X_CE, None, None, covariances=C)
    with pytest.raises(ValueError, match=r"covariances: expected shape \(6, 6, 6\)"):
        ml.refine_ml_poses(X_BE, X_CT, X_CE, None, None, covariances=C[:5])
    with pytest.raises(ValueError, match="covariances: per-sample covariances need "
                                         "noise_model 'so3'"):
        ml.refine_ml_poses(X_BE, X_CT, X_CE, None, None, "paper", covariances=C[:6])
    with pytest.raises(ValueError, match=r"covariances: expected shape \(6, 6, 6\)"):
        refine_ml_poses_fixed(X_BE, X_CT, X_CE, None, None, covariances=C[:5])


def test_pose_residual_vectors_are_the_noise_in_the_camera_frame():
    rng = np.random.default_rng(2)
    X_BE, X_CE, X_BT = _scene(rng, 5)
    n = rng.normal(size=(5, 6)) * 1e-3
    X_CT = []
    for k, X in enumerate(X_BE):
        P = X_CE @ inverse(X) @ X_BT
        X_CT.append(make_transform(rotation_exp(n[k, :3]) @ P[:3, :3], P[:3, 3] + n[k, 3:]))
    r = ml.pose_residual_vectors(np.array([inverse(X) for X in X_BE]), np.array(X_CT), X_CE,
                                 X_BT)
    np.testing.assert_allclose(r, n, atol=1e-14)

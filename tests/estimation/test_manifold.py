"""Error-state EKFs on SE(3) (``estimation.manifold``): exact rotations, statistical consistency
(NEES / NIS against χ² bands over seeded Monte-Carlo runs), the NIS gate against wrong camera
measurements, its lock-out recovery, and the reported uncertainty of X_EC."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from handeye_drake.estimation.manifold import ManifoldHandEyeFilter, covariance_inflation
from handeye_drake.estimation.ml import rotation_noise_variance
from handeye_drake.estimation.orthonormalize import orthonormalize_unchecked
from handeye_drake.estimation.se3 import (
    inverse,
    inverse_tangent_jacobian,
    make_transform,
    retract_pose,
    rotation_exp,
)
from handeye_drake.estimation.validation import rotation_defect
from tests.fixtures import manifold_filter, random_small_pose, tangent_error, target_filter

RUNS = 200


_pose = random_small_pose
_perturb = retract_pose
_error = tangent_error


def _so3_motion(rng, X_CE, B, sr, st):
    """A measured exactly under the filters' "so3" model: R_A = exp(n_r) R̃_A, t_A = t̃_A + n_t."""
    A = X_CE @ B @ inverse(X_CE)
    return make_transform(rotation_exp(rng.normal(size=3) * sr) @ A[:3, :3],
                          A[:3, 3] + rng.normal(size=3) * st)


def _so3_pose(rng, X, sr, st):
    return make_transform(rotation_exp(rng.normal(size=3) * sr) @ X[:3, :3],
                          X[:3, 3] + rng.normal(size=3) * st)


def _random_wrong_pose(rng):
    from scipy.spatial.transform import Rotation
    return make_transform(Rotation.random(random_state=rng).as_matrix(), rng.normal(size=3) * 0.3)


def _nees_band(dof, runs=RUNS, p=0.95):
    return chi2.ppf([(1 - p) / 2, (1 + p) / 2], dof * runs) / runs


# ---------------------------------------------------------------------------------------------
# Exact rotation at every step.

@pytest.mark.parametrize("noise_model", ["so3", "paper"])
def test_manifold_filter_keeps_an_exact_rotation_at_every_step(noise_model):
    rng = np.random.default_rng(1)
    X_CE = _pose(rng, 1.0, 0.1)
    f = manifold_filter(_perturb(X_CE, [0.1, -0.1, 0.05, 0.02, 0.0, -0.01]),
                        P0=np.diag([0.01] * 3 + [1e-3] * 3),
                        rotation_sigma=0.05 / np.sqrt(2.0) if noise_model == "paper" else 0.05,
                        translation_sigma=0.01)
    for _ in range(50):
        B = _pose(rng, 0.3, 0.1)
        if noise_model == "paper":  # additive coefficient noise: A_meas is not orthonormal
            A_meas = X_CE @ B @ inverse(X_CE)
            A_meas[:3, :3] += 0.05 * rng.normal(size=(3, 3))
            assert rotation_defect(A_meas[:3, :3]) > 1e-3
        else:
            A_meas = _so3_motion(rng, X_CE, B, 0.05, 0.01)
        f.update_motion(A_meas, B)
        assert rotation_defect(f.X_CE[:3, :3]) < 1e-12
        np.testing.assert_allclose(f.X_CE @ f.X_EC, np.eye(4), atol=1e-12)
        assert np.all(np.linalg.eigvalsh(f.covariance) > 0)
    assert f.num_updates + f.num_rejected == 50


def test_target_filter_keeps_exact_rotations_at_every_step():
    rng = np.random.default_rng(2)
    X_CE, X_BT = _pose(rng, 1.0, 0.1), _pose(rng, 1.0, 0.5)
    f = target_filter(_perturb(X_CE, [0.05, 0.02, -0.03, 0.01, 0.01, 0.0]),
                      P0=np.diag([0.01] * 3 + [1e-3] * 3), rotation_sigma=0.01 / np.sqrt(2.0),
                      translation_sigma=0.002)
    for _ in range(40):
        X_BE = _pose(rng, 0.5, 0.2)
        X_CT = X_CE @ inverse(X_BE) @ X_BT
        X_CT[:3, :3] += 0.01 * rng.normal(size=(3, 3))
        f.update(X_BE, X_CT)
        assert rotation_defect(f.X_CE[:3, :3]) < 1e-12
        assert rotation_defect(f.X_BT[:3, :3]) < 1e-12


# ---------------------------------------------------------------------------------------------
# Consistency: NEES over seeded runs in the 95 % χ² band.

def test_manifold_filter_nees_and_reported_x_ec_std_are_consistent():
    """Initial error drawn from P0, measurements drawn from the filter's own "so3" model: the
    average NEES of 200 runs must lie in χ²(6·200)/200's 95 % band; so must the NEES of X_EC with
    ``X_EC_covariance``, and each X_EC error coordinate divided by the reported std
    (``X_EC_rotation_std_deg``, ``X_EC_translation_std``) must have unit variance."""
    rng = np.random.default_rng(20240601)
    sr, st, K = 0.01, 0.002, 8
    P0 = np.diag([0.05**2] * 3 + [0.01**2] * 3)
    L = np.linalg.cholesky(P0)
    nees, nees_EC, z2 = [], [], []
    for _ in range(RUNS):
        X_CE = _pose(rng, 1.5, 0.1)
        X_init = _perturb(X_CE, -(L @ rng.normal(size=6)))  # truth = init ⊕ δ, δ ~ N(0, P0)
        f = manifold_filter(X_init, P0=P0, rotation_sigma=sr, translation_sigma=st)
        for _ in range(K):
            B = _pose(rng, 0.4, 0.1)
            f.update_motion(_so3_motion(rng, X_CE, B, sr, st), B)
        e = _error(X_CE, f.X_CE)
        nees.append(e @ np.linalg.solve(f.covariance, e))
        e_EC = _error(inverse(X_CE), f.X_EC)
        nees_EC.append(e_EC @ np.linalg.solve(f.X_EC_covariance, e_EC))
        std = np.concatenate([np.radians(f.X_EC_rotation_std_deg), f.X_EC_translation_std])
        z2.append((e_EC / std) ** 2)
    lo, hi = _nees_band(6)
    assert lo < np.mean(nees) < hi, (np.mean(nees), lo, hi)
    assert lo < np.mean(nees_EC) < hi, (np.mean(nees_EC), lo, hi)
    lo1, hi1 = chi2.ppf([0.0025, 0.9975], RUNS) / RUNS  # per coordinate (6 tests: Bonferroni)
    assert np.all((lo1 < np.mean(z2, axis=0)) & (np.mean(z2, axis=0) < hi1)), np.mean(z2, axis=0)


def test_target_filter_nees_is_consistent_full_state_and_hand_eye_block():
    """HandEyeTargetFilter, 200 seeded runs, poses measured under its "so3" model. (a) Initial
    X_CE and X_BT errors drawn from P0 and target_prior_cov: the full 12-D NEES is in χ²(12)'s
    band. (b) Default start (X_BT implied by the first sample): the 6-D X_CE block NEES is in
    χ²(6)'s band."""
    rng = np.random.default_rng(77)
    sr, st, K = 0.01, 0.002, 6
    P0 = np.diag([0.03**2] * 3 + [0.01**2] * 3)
    P_T = np.diag([0.05**2] * 3 + [0.02**2] * 3)
    nees_full, nees_block = [], []
    for run in range(2 * RUNS):
        X_CE, X_BT = _pose(rng, 1.5, 0.1), _pose(rng, 1.5, 0.5)
        X_CE0 = _perturb(X_CE, -(np.linalg.cholesky(P0) @ rng.normal(size=6)))
        full = run < RUNS
        if full:
            X_BT0 = _perturb(X_BT, -(np.linalg.cholesky(P_T) @ rng.normal(size=6)))
            f = target_filter(X_CE0, P0=P0, rotation_sigma=sr, translation_sigma=st,
                              X_BT_init=X_BT0, target_prior_cov=P_T)
        else:
            f = target_filter(X_CE0, P0=P0, rotation_sigma=sr, translation_sigma=st)
        for _ in range(K):
            X_BE = _pose(rng, 0.4, 0.2)
            f.update(X_BE, _so3_pose(rng, X_CE @ inverse(X_BE) @ X_BT, sr, st))
        e = np.concatenate([_error(X_CE, f.X_CE), _error(X_BT, f.X_BT)])
        if full:
            nees_full.append(e @ np.linalg.solve(f.covariance, e))
        else:
            nees_block.append(e[:6] @ np.linalg.solve(f.X_CE_covariance, e[:6]))
    lo, hi = _nees_band(12)
    assert lo < np.mean(nees_full) < hi, (np.mean(nees_full), lo, hi)
    lo, hi = _nees_band(6)
    assert lo < np.mean(nees_block) < hi, (np.mean(nees_block), lo, hi)


def test_x_ec_covariance_uses_the_inverse_tangent_jacobian():
    """inverse_tangent_jacobian against finite differences of the inversion, and the reported
    std against the square roots of J P Jᵀ's diagonal."""
    rng = np.random.default_rng(5)
    X = _pose(rng, 1.0, 0.3)
    J = inverse_tangent_jacobian(X)
    h = 1e-6
    J_fd = np.zeros((6, 6))
    for i in range(6):
        d = np.zeros(6)
        d[i] = h
        J_fd[:, i] = (_error(inverse(_perturb(X, d)), inverse(X))
                      - _error(inverse(_perturb(X, -d)), inverse(X))) / (2 * h)
    np.testing.assert_allclose(J, J_fd, atol=1e-8)
    M = rng.normal(size=(6, 6))
    P0 = M @ M.T + 0.1 * np.eye(6)
    f = manifold_filter(X, P0=P0)
    np.testing.assert_allclose(f.X_EC_covariance, J @ P0 @ J.T, rtol=1e-12)
    np.testing.assert_allclose(f.X_EC_rotation_std_deg,
                               np.degrees(np.sqrt(np.diag(J @ P0 @ J.T)[:3])), rtol=1e-12)
    np.testing.assert_allclose(f.X_EC_translation_std, np.sqrt(np.diag(J @ P0 @ J.T)[3:]),
                               rtol=1e-12)


def test_paper_noise_maps_to_half_the_coefficient_variance_per_axis():
    """rotation_noise_variance("paper", σ) = σ²/2: project R + σN onto SO(3) (as the filter
    does) and measure the variance of the rotation-vector error."""
    rng = np.random.default_rng(9)
    sigma = 0.01
    R = rotation_exp([0.3, -1.0, 2.0])
    noisy = R[None] + sigma * rng.normal(size=(20000, 3, 3))
    U, _, Vt = np.linalg.svd(noisy)
    projected = U @ Vt  # det = +1: the noise is far too small to reflect R
    for k in range(3):
        np.testing.assert_allclose(projected[k], orthonormalize_unchecked(noisy[k], "svd"),
                                   atol=1e-14)
    vecs = Rotation.from_matrix(projected @ R.T).as_rotvec()
    assert rotation_noise_variance("paper", sigma) == pytest.approx(sigma**2 / 2)
    np.testing.assert_allclose(vecs.var(axis=0), sigma**2 / 2, rtol=0.05)
    assert rotation_noise_variance("so3", sigma) == pytest.approx(sigma**2)


# ---------------------------------------------------------------------------------------------
# The NIS gate.

def _converged_filter(rng, X_CE, sr, st, **kwargs):
    f = manifold_filter(X_CE, P0=np.diag([1e-4] * 3 + [1e-6] * 3), rotation_sigma=sr,
                        translation_sigma=st, **kwargs)
    return f


def test_gate_accepts_consistent_measurements_at_the_expected_rate():
    """A consistent filter fed 2000 measurements from its own model: at gate probability 0.999
    about 0.1 % are rejected (≤ 1 % asserted), and the mean NIS is χ²(6)'s mean."""
    rng = np.random.default_rng(11)
    sr, st = 0.01, 0.002
    X_CE = _pose(rng, 1.5, 0.1)
    f = _converged_filter(rng, X_CE, sr, st, gate_probability=0.999)
    nis = []
    for _ in range(2000):
        B = _pose(rng, 0.3, 0.1)
        accepted = f.update_motion(_so3_motion(rng, X_CE, B, sr, st), B)
        assert accepted == (not f.last_rejected)
        nis.append(f.last_nis)
    assert f.num_rejected <= 20
    assert f.num_rejected + f.num_updates == 2000
    assert f.num_inflations == 0
    lo, hi = chi2.ppf([0.0005, 0.9995], 6 * 2000) / 2000
    assert lo < np.mean(nis) < hi


def test_gate_rejects_wrong_camera_measurements_and_keeps_the_estimate_clean():
    """Random poses injected as camera motions are all rejected (update returns False), and —
    since a rejected measurement leaves the state untouched — the final estimate is identical to
    the run without them."""
    rng = np.random.default_rng(12)
    sr, st = 0.01, 0.002
    X_CE = _pose(rng, 1.5, 0.1)
    X_init = _perturb(X_CE, [0.02, -0.01, 0.01, 0.005, 0.0, -0.005])
    P0 = np.diag([0.02**2] * 3 + [0.01**2] * 3)
    motions = []
    for _ in range(60):
        B = _pose(rng, 0.3, 0.1)
        motions.append((_so3_motion(rng, X_CE, B, sr, st), B))
    wrong_at = set(range(5, 60, 6))  # 10 wrong measurements, none consecutive
    clean = manifold_filter(X_init, P0=P0, rotation_sigma=sr, translation_sigma=st)
    dirty = manifold_filter(X_init, P0=P0, rotation_sigma=sr, translation_sigma=st)
    for k, (A, B) in enumerate(motions):
        clean.update_motion(A, B)
        if k in wrong_at:
            assert dirty.update_motion(_random_wrong_pose(rng), B) is False
            assert dirty.last_rejected and dirty.last_nis > chi2.ppf(0.999, 6)
        dirty.update_motion(A, B)
    assert dirty.num_rejected == clean.num_rejected + len(wrong_at)
    np.testing.assert_array_equal(dirty.X_CE, clean.X_CE)
    np.testing.assert_array_equal(dirty.covariance, clean.covariance)
    assert np.linalg.norm(_error(X_CE, dirty.X_CE)[:3]) < 0.01


def test_target_filter_gate_rejects_a_wrong_target_pose():
    rng = np.random.default_rng(13)
    sr, st = 0.005, 0.001
    X_CE, X_BT = _pose(rng, 1.5, 0.1), _pose(rng, 1.5, 0.5)
    f = target_filter(X_CE, P0=np.diag([1e-4] * 3 + [1e-5] * 3), rotation_sigma=sr,
                      translation_sigma=st, X_BT_init=X_BT,
                      target_prior_cov=np.diag([1e-4] * 3 + [1e-5] * 3))
    for _ in range(10):
        X_BE = _pose(rng, 0.4, 0.2)
        f.update(X_BE, _so3_pose(rng, X_CE @ inverse(X_BE) @ X_BT, sr, st))
    before = (f.X_CE, f.X_BT, f.covariance)
    rejected_before = f.num_rejected
    assert f.update(_pose(rng, 0.4, 0.2), _random_wrong_pose(rng)) is False
    assert f.num_rejected == rejected_before + 1
    np.testing.assert_array_equal(f.X_CE, before[0])
    np.testing.assert_array_equal(f.X_BT, before[1])
    np.testing.assert_array_equal(f.covariance, before[2])


def test_gate_lock_out_is_recovered_and_true_outliers_stay_rejected():
    """A start 15° off with a P0 that claims 0.3°: every measurement fails the gate. Without the
    recovery the estimate freezes for good; with it (default, 5 rejections in a row) the filter
    inflates its covariance and converges. A burst of 10 wrong poses fed to a consistent filter
    is still rejected in full: no state error explains a camera rotation whose angle differs
    from the robot's."""
    rng = np.random.default_rng(14)
    sr, st = 0.01, 0.002
    X_CE = _pose(rng, 1.5, 0.1)
    X_bad = _perturb(X_CE, [0.2, -0.15, 0.1, 0.02, -0.02, 0.01])
    P0 = np.diag([np.radians(0.3)**2] * 3 + [0.001**2] * 3)
    stuck = manifold_filter(X_bad, P0=P0, rotation_sigma=sr, translation_sigma=st,
                            max_consecutive_rejections=None)
    recovered = manifold_filter(X_bad, P0=P0, rotation_sigma=sr, translation_sigma=st)
    for _ in range(60):
        B = _pose(rng, 0.3, 0.1)
        A = _so3_motion(rng, X_CE, B, sr, st)
        stuck.update_motion(A, B)
        recovered.update_motion(A, B)
    assert stuck.num_rejected >= 55
    np.testing.assert_allclose(stuck.X_CE, X_bad, atol=0.02)  # (almost) frozen at the bad start
    assert recovered.num_inflations >= 1
    assert np.degrees(np.linalg.norm(_error(X_CE, recovered.X_CE)[:3])) < 0.5
    assert np.linalg.norm(_error(X_CE, recovered.X_CE)[3:]) < 0.005

    inflations = recovered.num_inflations
    rejected = recovered.num_rejected
    estimate = recovered.X_CE
    for _ in range(10):
        assert recovered.update_motion(_random_wrong_pose(rng), _pose(rng, 0.3, 0.1)) is False
    assert recovered.num_rejected == rejected + 10
    assert recovered.num_inflations == inflations
    np.testing.assert_array_equal(recovered.X_CE, estimate)


def test_covariance_inflation_hand_computed():
    # NIS(s) = 9 / (s·1 + 1) ≤ 1  ⇔  s ≥ 8.
    s = covariance_inflation(np.array([3.0]), np.eye(1), np.eye(1), np.eye(1), 1.0)
    assert s == pytest.approx(8.0, rel=1e-9)
    assert covariance_inflation(np.array([0.5]), np.eye(1), np.eye(1), np.eye(1), 1.0) == 1.0
    # An innovation in a direction the state does not affect cannot be explained.
    assert covariance_inflation(np.array([0.0, 5.0]), np.array([[1.0], [0.0]]), np.eye(1),
                                np.eye(2), 1.0) is None


@pytest.mark.parametrize("value", [0, -1, 2.5])
def test_max_consecutive_rejections_is_validated(value):
    with pytest.raises(ValueError, match="ManifoldFilter.max_consecutive_rejections"):
        manifold_filter(np.eye(4), max_consecutive_rejections=value)
    with pytest.raises(ValueError, match="TargetFilter.max_consecutive_rejections"):
        target_filter(np.eye(4), max_consecutive_rejections=value)


def test_from_motions_start_matches_batch_ml():
    """Seeded from 10 motions by the robust ML start-up, the on-line filter ends at the batch ML
    estimate of all motions (the benchmark's ``manifold_ml_start``), and skips a wrong motion."""
    from handeye_drake import rotation_error_deg
    from handeye_drake.estimation.ml import refine_ml
    from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp
    rng = np.random.default_rng(11)
    X_CE = make_transform(rotation_exp(rng.normal(size=3)), rng.normal(size=3))
    A_list, B_list = [], []
    for _ in range(60):
        B = make_transform(rotation_exp(rng.normal(size=3) * 0.2), rng.normal(size=3) * 0.3)
        A = X_CE @ B @ inverse(X_CE)
        A = make_transform(rotation_exp(rng.normal(size=3) * 0.005) @ A[:3, :3],
                           A[:3, 3] + rng.normal(size=3) * 0.002)
        A_list.append(A)
        B_list.append(B)
    A_bad = list(A_list)
    A_bad[3] = make_transform(rotation_exp([1.0, 0.0, 0.0]), [0.5, 0.0, 0.0])  # a wrong motion
    from handeye_drake.estimation.configs import ManifoldFilter
    f = ManifoldHandEyeFilter.from_motions(
        ManifoldFilter(rotation_sigma=0.005, translation_sigma=0.002), A_bad[:10], B_list[:10])
    assert not f.start_up.inliers[3] and f.start_up.inliers.sum() == 9
    for A, B in zip(A_list[10:], B_list[10:]):
        f.update_motion(A, B)
    keep = [k for k in range(60) if k != 3]
    ml = refine_ml([A_list[k] for k in keep], [B_list[k] for k in keep], X_CE, 0.005, 0.002)
    assert rotation_error_deg(ml.X_CE, f.X_CE) < 0.2 * rotation_error_deg(X_CE, ml.X_CE) + 1e-3
    assert np.linalg.norm(ml.X_CE[:3, 3] - f.X_CE[:3, 3]) < 0.5e-3

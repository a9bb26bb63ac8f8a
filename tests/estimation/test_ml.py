"""Maximum-likelihood reference (``estimation.ml``): exact recovery on noise-free data, analytic
Jacobians against finite differences, efficiency (Monte-Carlo errors against the Cramér–Rao
bound), better than the linear solution on noisy data, robust start-up, input validation — and
the benchmark's pure helpers."""

import numpy as np
import pytest
from scipy.stats import chi2

from handeye_drake.estimation import ml
from handeye_drake.estimation.se3 import (
    inverse,
    inverse_tangent_jacobian,
    make_transform,
    retract_pose,
    rotation_exp,
)
from handeye_drake.estimation.solvers import solve_ax_xb
from handeye_drake.estimation.validation import rotation_defect
from tests.fixtures import manifold_filter, random_small_pose, tangent_error

_pose = random_small_pose
_perturb = retract_pose
_error = tangent_error


def _motions(rng, X_CE, K, rotation_scale=0.3, translation_scale=0.2):
    B = [_pose(rng, rotation_scale, translation_scale) for _ in range(K)]
    return [X_CE @ b @ inverse(X_CE) for b in B], B


def _noisy(rng, A, noise_model, sr, st):
    out = []
    for a in A:
        a = a.copy()
        if noise_model == "so3":
            a[:3, :3] = rotation_exp(rng.normal(size=3) * sr) @ a[:3, :3]
        else:
            a[:3, :3] += sr * rng.normal(size=(3, 3))
        a[:3, 3] += st * rng.normal(size=3)
        out.append(a)
    return out


# ---------------------------------------------------------------------------------------------
# Exactness.

@pytest.mark.parametrize("noise_model", ["so3", "paper"])
def test_refine_ml_recovers_the_truth_on_noise_free_data(noise_model):
    rng = np.random.default_rng(1)
    X_CE = _pose(rng, 1.5, 0.3)
    A, B = _motions(rng, X_CE, 8)
    start = _perturb(X_CE, [0.3, -0.2, 0.25, 0.1, -0.05, 0.08])  # ~25° off
    r = ml.refine_ml(A, B, start, 0.01, 0.001, noise_model)
    np.testing.assert_allclose(r.X_CE, X_CE, atol=1e-9)
    np.testing.assert_allclose(r.X_EC, inverse(X_CE), atol=1e-9)
    assert rotation_defect(r.X_CE[:3, :3]) < 1e-12
    assert r.cost < 1e-15
    assert r.residuals.shape == (8, 2) and np.all(r.residuals < 1e-7)
    assert r.num_iterations >= 1
    # On noise-free data the covariance is (JᵀJ)⁻¹ at the truth: the Cramér–Rao bound.
    np.testing.assert_allclose(r.covariance, ml.cramer_rao_bound(A, B, X_CE, 0.01, 0.001,
                                                                 noise_model), rtol=1e-6)


@pytest.mark.parametrize("noise_model", ["so3", "paper"])
def test_refine_ml_poses_recovers_hand_eye_and_target_on_noise_free_data(noise_model):
    rng = np.random.default_rng(2)
    X_CE, X_BT = _pose(rng, 1.5, 0.1), _pose(rng, 1.5, 0.5)
    X_BE = [_pose(rng, 0.5, 0.3) for _ in range(6)]
    X_CT = [X_CE @ inverse(x) @ X_BT for x in X_BE]
    r = ml.refine_ml_poses(X_BE, X_CT, _perturb(X_CE, [0.2, 0.1, -0.2, 0.05, 0.02, -0.03]),
                           0.002, 0.0005, noise_model)
    np.testing.assert_allclose(r.X_CE, X_CE, atol=1e-9)
    np.testing.assert_allclose(r.X_BT, X_BT, atol=1e-9)
    assert r.full_covariance.shape == (12, 12)
    np.testing.assert_array_equal(r.covariance, r.full_covariance[:6, :6])
    assert r.residuals.shape == (6, 2) and np.all(r.residuals < 1e-7)


def test_refine_ml_poses_default_target_start_is_the_first_sample():
    rng = np.random.default_rng(3)
    X_CE, X_BT = _pose(rng, 1.5, 0.1), _pose(rng, 1.5, 0.5)
    X_BE = [_pose(rng, 0.5, 0.3) for _ in range(5)]
    X_CT = _noisy(rng, [X_CE @ inverse(x) @ X_BT for x in X_BE], "so3", 0.01, 0.002)
    X0 = _perturb(X_CE, [0.05, 0.0, 0.0, 0.01, 0.0, 0.0])
    a = ml.refine_ml_poses(X_BE, X_CT, X0, 0.01, 0.002)
    b = ml.refine_ml_poses(X_BE, X_CT, X0, 0.01, 0.002, X_BT_init=X_BE[0] @ inverse(X0) @ X_CT[0])
    np.testing.assert_allclose(a.X_CE, b.X_CE, atol=1e-12)
    np.testing.assert_allclose(a.X_BT, b.X_BT, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# Jacobians against finite differences.

@pytest.mark.parametrize("noise_model", ["so3", "paper"])
def test_motion_jacobian_matches_finite_differences(noise_model):
    rng = np.random.default_rng(4)
    X_CE = _pose(rng, 1.5, 0.3)
    A, B = _motions(rng, X_CE, 5)
    data = ml._motion_data(_noisy(rng, A, noise_model, 0.05, 0.01), B, noise_model)
    X = _perturb(X_CE, [0.1, -0.1, 0.05, 0.02, 0.01, -0.02])
    r, H = ml._motion_terms(X, data, noise_model, 0.01, 0.001)
    h, H_fd = 1e-6, np.zeros_like(H)
    for i in range(6):
        d = np.zeros(6)
        d[i] = h
        plus = ml._motion_terms(_perturb(X, d), data, noise_model, 0.01, 0.001)[0]
        minus = ml._motion_terms(_perturb(X, -d), data, noise_model, 0.01, 0.001)[0]
        H_fd[:, i] = (plus - minus) / (2 * h)
    np.testing.assert_allclose(H, H_fd, atol=1e-6 * np.abs(H).max())


@pytest.mark.parametrize("noise_model", ["so3", "paper"])
def test_pose_jacobian_matches_finite_differences(noise_model):
    rng = np.random.default_rng(5)
    X_CE, X_BT = _pose(rng, 1.5, 0.1), _pose(rng, 1.5, 0.5)
    X_BE = [_pose(rng, 0.5, 0.3) for _ in range(4)]
    X_CT = _noisy(rng, [X_CE @ inverse(x) @ X_BT for x in X_BE], noise_model, 0.05, 0.01)
    R_m = np.array([x[:3, :3] for x in X_CT])
    R_p = ml._project_stack(R_m)
    X_EB = [inverse(x) for x in X_BE]
    data = (R_m if noise_model == "paper" else R_p, R_p, np.array([x[:3, 3] for x in X_CT]),
            np.array([x[:3, :3] for x in X_EB]), np.array([x[:3, 3] for x in X_EB]))
    est = (_perturb(X_CE, [0.1, 0.0, -0.1, 0.01, 0.0, 0.02]),
           _perturb(X_BT, [0.0, 0.1, 0.1, -0.02, 0.03, 0.0]))
    r, H = ml._pose_terms(est, data, noise_model, 0.01, 0.001)
    h, H_fd = 1e-6, np.zeros_like(H)
    for i in range(12):
        d = np.zeros(12)
        d[i] = h
        plus = ml._pose_terms(ml._retract_all(est, d), data, noise_model, 0.01, 0.001)[0]
        minus = ml._pose_terms(ml._retract_all(est, -d), data, noise_model, 0.01, 0.001)[0]
        H_fd[:, i] = (plus - minus) / (2 * h)
    np.testing.assert_allclose(H, H_fd, atol=1e-6 * np.abs(H).max())


def test_left_jacobian_first_order_identity():
    """exp(φ + h) ≈ exp(J_l(φ) h) exp(φ), to second order in h; J_l(0) = I."""
    rng = np.random.default_rng(6)
    np.testing.assert_allclose(ml.left_jacobian(np.zeros(3)), np.eye(3), atol=1e-15)
    for phi in (rng.normal(size=3), 1e-8 * rng.normal(size=3), np.array([0.0, 0.0, 3.0])):
        h = 1e-6 * rng.normal(size=3)
        lhs = rotation_exp(phi + h)
        rhs = rotation_exp(ml.left_jacobian(phi) @ h) @ rotation_exp(phi)
        np.testing.assert_allclose(lhs, rhs, atol=1e-11)


# ---------------------------------------------------------------------------------------------
# Statistics.

def test_ml_is_efficient_errors_match_the_cramer_rao_bound():
    """200 seeded noisy data sets (so3 noise, drawn from the model): the NEES of the ML errors
    with the Cramér–Rao bound lies in χ²(6·200)/200's 95 % band, the covariance reported at the
    estimate is close to the bound, and the cost (χ² of the whitened residuals) averages its
    degrees of freedom m − 6."""
    rng = np.random.default_rng(7)
    sr, st, K, runs = 0.01, 0.002, 8, 200
    X_CE = _pose(rng, 1.5, 0.2)
    A, B = _motions(rng, X_CE, K)
    crb = ml.cramer_rao_bound(A, B, X_CE, sr, st)
    nees, costs = [], []
    for _ in range(runs):
        r = ml.refine_ml(_noisy(rng, A, "so3", sr, st), B, X_CE, sr, st)
        e = _error(X_CE, r.X_CE)
        nees.append(e @ np.linalg.solve(crb, e))
        costs.append(r.cost)
        # Whitened by the bound, the covariance at the estimate is ≈ I (first order in noise).
        W = np.linalg.inv(np.linalg.cholesky(crb))
        np.testing.assert_allclose(W @ r.covariance @ W.T, np.eye(6), atol=0.05)
    lo, hi = chi2.ppf([0.025, 0.975], 6 * runs) / runs
    assert lo < np.mean(nees) < hi, np.mean(nees)
    dof = 6 * K - 6
    lo, hi = chi2.ppf([0.025, 0.975], dof * runs) / runs
    assert lo < np.mean(costs) < hi, (np.mean(costs), dof)


def test_ml_covariance_propagates_to_x_ec():
    rng = np.random.default_rng(8)
    X_CE = _pose(rng, 1.5, 0.3)
    A, B = _motions(rng, X_CE, 6)
    r = ml.refine_ml(_noisy(rng, A, "so3", 0.01, 0.002), B, X_CE, 0.01, 0.002)
    J = inverse_tangent_jacobian(r.X_CE)
    np.testing.assert_allclose(r.X_EC_covariance, J @ r.covariance @ J.T, rtol=1e-12)
    np.testing.assert_allclose(r.X_EC_rotation_std_deg,
                               np.degrees(np.sqrt(np.diag(r.X_EC_covariance)[:3])), rtol=1e-12)
    np.testing.assert_allclose(r.X_EC_translation_std, np.sqrt(np.diag(r.X_EC_covariance)[3:]),
                               rtol=1e-12)


@pytest.mark.parametrize("noise_model", ["paper", "so3"])
def test_ml_beats_the_linear_andreff_solution_on_noisy_data(noise_model):
    """30 seeded data sets of small motions (docs/method.md §8-like, scaled down): the ML reference's
    mean rotation and translation errors are below the linear (Andreff) solution's."""
    rng = np.random.default_rng(10)
    sr, st = 0.02, 0.01
    err_ml, err_lin = [], []
    for _ in range(30):
        X_CE = make_transform(rotation_exp(rng.normal(size=3)), rng.normal(size=3) * 2.0)
        A, B = _motions(rng, X_CE, 30, rotation_scale=0.1, translation_scale=0.5)
        A_meas = _noisy(rng, A, noise_model, sr, st)
        X_lin = solve_ax_xb(A_meas, B, "andreff", orthonormalize_inputs=True)
        r = ml.refine_ml(A_meas, B, X_lin, sr, st, noise_model)
        err_ml.append(np.abs(_error(X_CE, r.X_CE)))
        err_lin.append(np.abs(_error(X_CE, X_lin)))
    err_ml, err_lin = np.array(err_ml), np.array(err_lin)
    rot_ml, rot_lin = np.linalg.norm(err_ml[:, :3], axis=1), np.linalg.norm(err_lin[:, :3], axis=1)
    tr_ml, tr_lin = np.linalg.norm(err_ml[:, 3:], axis=1), np.linalg.norm(err_lin[:, 3:], axis=1)
    assert rot_ml.mean() < 0.5 * rot_lin.mean()
    assert tr_ml.mean() < 0.5 * tr_lin.mean()


# ---------------------------------------------------------------------------------------------
# Robust start-up for the on-line filter.

def test_robust_initial_estimate_drops_wrong_motions_and_seeds_a_consistent_filter():
    """12 motions of which 2 are random wrong poses: they are flagged, the estimate equals the
    ML of the 10 good motions, and a filter seeded with it (X, covariance as P0) then accepts
    the following consistent motions."""
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(11)
    sr, st = 0.01, 0.002
    X_CE = _pose(rng, 1.5, 0.2)
    A, B = _motions(rng, X_CE, 12)
    A = _noisy(rng, A, "so3", sr, st)
    bad = [3, 8]
    for k in bad:
        A[k] = make_transform(Rotation.random(random_state=rng).as_matrix(), rng.normal(size=3))
    r = ml.robust_initial_estimate(A, B, sr, st, "so3")
    expected = np.ones(12, dtype=bool)
    expected[bad] = False
    np.testing.assert_array_equal(r.inliers, expected)
    good = [k for k in range(12) if k not in bad]
    ref = ml.refine_ml([A[k] for k in good], [B[k] for k in good], X_CE, sr, st)
    np.testing.assert_allclose(r.X_CE, ref.X_CE, atol=1e-9)
    np.testing.assert_allclose(r.covariance, ref.covariance, rtol=1e-6)
    f = manifold_filter(r.X_CE, P0=r.covariance, rotation_sigma=sr, translation_sigma=st)
    A2, B2 = _motions(rng, X_CE, 20)
    for a, b in zip(_noisy(rng, A2, "so3", sr, st), B2):
        f.update_motion(a, b)
    assert f.num_rejected <= 1
    assert np.linalg.norm(_error(X_CE, f.X_CE)[:3]) < np.linalg.norm(
        _error(X_CE, r.X_CE)[:3]) + 3 * np.sqrt(np.trace(f.covariance[:3, :3]))


# ---------------------------------------------------------------------------------------------
# Input validation.

def _valid(rng=None):
    rng = rng or np.random.default_rng(12)
    X_CE = _pose(rng, 1.5, 0.3)
    A, B = _motions(rng, X_CE, 4)
    return X_CE, A, B


@pytest.mark.parametrize("change, message", [
    (dict(noise_model="rpy"), "noise_model"),
    (dict(rotation_sigma=0.0), "rotation_sigma"),
    (dict(translation_sigma=-1.0), "translation_sigma"),
    (dict(rotation_sigma=float("nan")), "rotation_sigma"),
])
def test_refine_ml_rejects_bad_parameters(change, message):
    X_CE, A, B = _valid()
    kwargs = dict(rotation_sigma=0.01, translation_sigma=0.01, noise_model="so3")
    kwargs.update(change)
    with pytest.raises(ValueError, match=message):
        ml.refine_ml(A, B, X_CE, **kwargs)
    with pytest.raises(ValueError, match=message):
        ml.cramer_rao_bound(A, B, X_CE, **kwargs)


def test_refine_ml_rejects_bad_data():
    X_CE, A, B = _valid()
    A_nan = [a.copy() for a in A]
    A_nan[1][0, 3] = np.nan
    with pytest.raises(ValueError, match=r"A_list\[1\].*NaN"):
        ml.refine_ml(A_nan, B, X_CE, 0.01, 0.01)
    with pytest.raises(ValueError, match="same length"):
        ml.refine_ml(A, B[:3], X_CE, 0.01, 0.01)
    with pytest.raises(ValueError, match="at least 2 motions"):
        ml.refine_ml(A[:1], B[:1], X_CE, 0.01, 0.01)
    with pytest.raises(ValueError, match="X_CE_init"):
        ml.refine_ml(A, B, np.eye(3), 0.01, 0.01)
    A_scaled = [a.copy() for a in A]
    A_scaled[0][:3, :3] *= 1.1  # not a rotation: only the "paper" model accepts raw blocks
    with pytest.raises(ValueError, match=r"A_list\[0\].*rotation"):
        ml.refine_ml(A_scaled, B, X_CE, 0.01, 0.01, "so3")
    ml.refine_ml(A_scaled, B, X_CE, 0.01, 0.01, "paper")
    with pytest.raises(ValueError, match=r"B_list\[2\]"):
        ml.refine_ml(A, B[:2] + [np.diag([2.0, 1.0, 1.0, 1.0])] + B[3:], X_CE, 0.01, 0.01)


def test_refine_ml_refuses_motions_that_do_not_determine_x():
    """All rotations about one axis: the rotation about it (and the translation along it) is
    unobservable; the Fisher information is singular."""
    X_CE = make_transform(rotation_exp([0.2, 0.3, 0.1]), [0.1, 0.2, 0.3])
    B = [make_transform(rotation_exp([0.0, 0.0, a]), [0.1 * a, 0.0, 0.0]) for a in (0.3, 0.5, 0.9)]
    A = [X_CE @ b @ inverse(X_CE) for b in B]
    with pytest.raises(ValueError, match="do not determine"):
        ml.refine_ml(A, B, X_CE, 0.01, 0.01)
    with pytest.raises(ValueError, match="do not determine"):
        ml.cramer_rao_bound(A, B, X_CE, 0.01, 0.01)


def test_refine_ml_poses_rejects_bad_data():
    rng = np.random.default_rng(13)
    X_CE, X_BT = _pose(rng, 1.5, 0.1), _pose(rng, 1.5, 0.5)
    X_BE = [_pose(rng, 0.5, 0.3) for _ in range(4)]
    X_CT = [X_CE @ inverse(x) @ X_BT for x in X_BE]
    with pytest.raises(ValueError, match="at least 3 samples"):
        ml.refine_ml_poses(X_BE[:2], X_CT[:2], X_CE, 0.01, 0.01)
    with pytest.raises(ValueError, match="same length"):
        ml.refine_ml_poses(X_BE, X_CT[:3], X_CE, 0.01, 0.01)
    bad = [x.copy() for x in X_CT]
    bad[2][1, 1] = np.inf
    with pytest.raises(ValueError, match=r"X_CT_list\[2\]"):
        ml.refine_ml_poses(X_BE, bad, X_CE, 0.01, 0.01)
    with pytest.raises(ValueError, match="X_BT_init"):
        ml.refine_ml_poses(X_BE, X_CT, X_CE, 0.01, 0.01, X_BT_init=np.zeros((4, 4)))
    with pytest.raises(ValueError, match="noise_model"):
        ml.refine_ml_poses(X_BE, X_CT, X_CE, 0.01, 0.01, noise_model="paper_full")


def test_robust_initial_estimate_rejects_bad_parameters():
    X_CE, A, B = _valid()
    with pytest.raises(ValueError, match="method"):
        ml.robust_initial_estimate(A, B, 0.01, 0.01, method="svd")
    with pytest.raises(ValueError, match="gate_probability"):
        ml.robust_initial_estimate(A, B, 0.01, 0.01, gate_probability=1.0)
    with pytest.raises(ValueError, match="max_rounds"):
        ml.robust_initial_estimate(A, B, 0.01, 0.01, max_rounds=0)
    # Camera rotations that never match the robot's: nothing consistent to start from.
    wrong = [make_transform(rotation_exp([2.0, 0.0, 0.0]), a[:3, 3]) for a in A]
    with pytest.raises(ValueError, match="rotation angles"):
        ml.robust_initial_estimate(wrong, B, 0.01, 0.01)

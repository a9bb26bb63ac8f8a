"""The on-line estimator interface (``estimation.estimator``, ``estimation.startup``): the exact
state round trip, every term of each filter's update against a straight-line reference, the
start-up, and what the estimators say when the data cannot determine X."""

import numpy as np
import pytest
import scipy.linalg

from handeye_drake import rotation_error_deg
from handeye_drake.estimation.configs import ManifoldFilter, PaperFilter, TargetFilter
from handeye_drake.estimation.kalman import HandEyeKalmanFilter
from handeye_drake.estimation.linear_model import linear_system
from handeye_drake.estimation.manifold import HandEyeTargetFilter, ManifoldHandEyeFilter
from handeye_drake.estimation.se3 import (
    inverse,
    make_transform,
    retract_pose,
    rotation_exp,
    rotation_log,
)
from handeye_drake.estimation.startup import (
    estimator_type,
    make_estimator,
    start_estimator,
    two_motion_estimate,
)
from tests.fixtures import random_small_pose, simulate_poses

SO3 = 0.004, 0.001  # rad, m

CONFIGS = {
    "paper": PaperFilter(rotation_coefficient_sigma=0.006, translation_sigma=0.002,
                         process_variances=[1e-6] * 12),
    "paper_exact": PaperFilter(noise_covariance="exact", rotation_coefficient_sigma=0.006,
                               translation_sigma=0.002, process_variances=[1e-6] * 12),
    "manifold": ManifoldFilter(rotation_sigma=0.006, translation_sigma=0.002,
                               process_variances=[1e-5] * 6),
    "target": TargetFilter(rotation_sigma=SO3[0], translation_sigma=SO3[1],
                           process_variances=[1e-5] * 6),
}


def _noisy_pose(rng, X, sr=SO3[0], st=SO3[1]):
    return make_transform(rotation_exp(sr * rng.normal(size=3)) @ X[:3, :3],
                          X[:3, 3] + st * rng.normal(size=3))


def _samples(seed=0, n=30, X_EC=None):
    rng = np.random.default_rng(seed)
    X_EC = random_small_pose(rng, 1.0, 0.05) if X_EC is None else X_EC
    X_BE, X_CT = simulate_poses(rng, X_EC, n, rotation_scale=0.6, translation_scale=0.2)
    return X_EC, X_BE, [_noisy_pose(rng, X) for X in X_CT]


@pytest.mark.parametrize("name", list(CONFIGS))
def test_state_round_trips_exactly_and_steps_identically(name):
    config = CONFIGS[name]
    X_EC, X_BE, X_CT = _samples()
    est = make_estimator(config, retract_pose(inverse(X_EC), [0.01, -0.01, 0.02, 0.003, 0, 0]))
    for X_be, X_ct in zip(X_BE[:15], X_CT[:15]):
        est.update(X_be, X_ct)
    v = est.to_vector()
    assert v.shape == (est.vector_size(config),)
    copy = type(est).from_vector(config.validated(), v)
    np.testing.assert_array_equal(copy.to_vector(), v)
    for attr in ("X_CE", "X_EC", "covariance", "X_CE_covariance", "X_EC_rotation_std_deg"):
        np.testing.assert_array_equal(getattr(copy, attr), getattr(est, attr))
    assert (copy.num_updates, copy.num_rejected, copy.num_skipped) == (
        est.num_updates, est.num_rejected, est.num_skipped)
    for X_be, X_ct in zip(X_BE[15:], X_CT[15:]):
        assert est.update(X_be, X_ct) == copy.update(X_be, X_ct)
        np.testing.assert_array_equal(copy.to_vector(), est.to_vector())
    assert est.num_updates >= 25


def test_from_vector_rejects_a_wrong_size():
    config = CONFIGS["target"].validated()
    with pytest.raises(ValueError, match=f"vector: expected {HandEyeTargetFilter.vector_size()} "
                                         "values"):
        HandEyeTargetFilter.from_vector(config, np.zeros(10))


# ------------------------------------------------------------ each update against a reference
def _fd_jacobian(residual, retract, estimate, measurement, n, h=1e-7):
    """∂z/∂δ by central differences: z(x̂ ⊕ δ) ≈ z − H δ, so H = −∂z/∂δ."""
    H = np.zeros((6, n))
    for i in range(n):
        d = np.zeros(n)
        d[i] = h
        H[:, i] = -(residual(retract(estimate, d), measurement)
                    - residual(retract(estimate, -d), measurement)) / (2 * h)
    return H


def _reference_ekf(P, G1, Rn, z, H):
    """A textbook EKF step: prior P + G1, gain, correction δ, posterior (I − K H) P⁻."""
    P_prior = P + G1
    S = H @ P_prior @ H.T + Rn
    K = P_prior @ H.T @ np.linalg.inv(S)
    return K @ z, (np.eye(len(P)) - K @ H) @ P_prior


def test_paper_filter_update_matches_the_papers_recursion_term_by_term():
    """x ← x + K (y − C x), P ← P + G1 − K S Kᵀ with K = P Cᵀ S⁻¹, S = C P Cᵀ + G2: with
    non-zero G1, so dropping the process noise (or any term) changes the result."""
    config = CONFIGS["paper"]
    X_EC, X_BE, X_CT = _samples(1, 3)
    X0 = retract_pose(inverse(X_EC), [0.02, 0.0, -0.01, 0.005, 0.0, 0.002])
    f = HandEyeKalmanFilter(config, X0)
    x, P = f.state, f.covariance
    A, B = X_CT[0] @ inverse(X_CT[1]), inverse(X_BE[0]) @ X_BE[1]
    assert f.update_motion(A, B)
    C, y = linear_system(A, B)
    G2 = np.diag([config.rotation_coefficient_sigma**2] * 9 + [config.translation_sigma**2] * 3)
    G1 = np.diag(config.process_variances)
    S = C @ P @ C.T + G2
    K = P @ C.T @ np.linalg.inv(S)
    np.testing.assert_allclose(f.state, x + K @ (y - C @ x), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(f.covariance, P + G1 - K @ S @ K.T, rtol=1e-7, atol=1e-14)


def test_manifold_filter_update_matches_a_textbook_ekf_step():
    """One plain EKF step (iterations = 1) with the measurement Jacobian by finite differences:
    prior covariance P + G1, gain, retraction of the correction, posterior covariance."""
    config = ManifoldFilter(rotation_sigma=0.006, translation_sigma=0.002,
                            process_variances=[2e-5] * 3 + [1e-6] * 3, iterations=1,
                            gate_probability=None)
    X_EC, X_BE, X_CT = _samples(2, 3)
    X0 = retract_pose(inverse(X_EC), [0.02, 0.01, -0.01, 0.004, 0.0, 0.002])
    f = ManifoldHandEyeFilter(config, X0)
    P = f.covariance
    A, B = X_CT[0] @ inverse(X_CT[1]), inverse(X_BE[0]) @ X_BE[1]
    assert f.update_motion(A, B)

    def residual(X, m):
        R_Am, t_Am, R_B, t_B = m
        R, t = X[:3, :3], X[:3, 3]
        R_A = R @ R_B @ R.T
        return np.concatenate([rotation_log(R_Am @ R_A.T), t_Am - (R @ t_B + t - R_A @ t)])

    m = (A[:3, :3], A[:3, 3], B[:3, :3], B[:3, 3])
    H = _fd_jacobian(residual, retract_pose, X0, m, 6)
    Rn = np.diag([0.006**2] * 3 + [0.002**2] * 3)
    delta, P_new = _reference_ekf(P, np.diag(config.process_variances), Rn, residual(X0, m), H)
    # Tolerances: the finite-difference Jacobian's error; every term of the update moves the
    # result by orders of magnitude more (e.g. the process noise changes δ by ~1e-3).
    np.testing.assert_allclose(f.X_CE, retract_pose(X0, delta), atol=1e-6)
    np.testing.assert_allclose(f.covariance, P_new, rtol=1e-4, atol=1e-10)


def test_target_filter_update_matches_a_textbook_ekf_step():
    """The same for AX = ZB on raw poses (12-D state, process noise on X_CE only)."""
    config = TargetFilter(rotation_sigma=SO3[0], translation_sigma=SO3[1],
                          process_variances=[2e-5] * 3 + [1e-6] * 3, iterations=1,
                          gate_probability=None)
    X_EC, X_BE, X_CT = _samples(3, 3)
    X0 = retract_pose(inverse(X_EC), [0.02, 0.01, -0.01, 0.004, 0.0, 0.002])
    f = HandEyeTargetFilter(config, X0)
    assert not f.update(X_BE[0], X_CT[0])  # places the target, fuses nothing
    assert f.num_skipped == 1 and f.num_updates == 0
    est, P = (f.X_CE, f.X_BT), f.covariance
    assert f.update(X_BE[1], X_CT[1])

    def retract(e, d):
        return retract_pose(e[0], d[:6]), retract_pose(e[1], d[6:])

    def residual(e, m):
        X_CE, X_BT = e
        X_pred = X_CE @ inverse(m[0]) @ X_BT
        return np.concatenate([rotation_log(m[1][:3, :3] @ X_pred[:3, :3].T),
                               m[1][:3, 3] - X_pred[:3, 3]])

    m = (X_BE[1], X_CT[1])
    H = _fd_jacobian(residual, retract, est, m, 12)
    G1 = scipy.linalg.block_diag(np.diag(config.process_variances), np.zeros((6, 6)))
    Rn = np.diag([SO3[0]**2] * 3 + [SO3[1]**2] * 3)
    delta, P_new = _reference_ekf(P, G1, Rn, residual(est, m), H)
    X_CE_ref, X_BT_ref = retract(est, delta)
    np.testing.assert_allclose(f.X_CE, X_CE_ref, atol=1e-6)
    np.testing.assert_allclose(f.X_BT, X_BT_ref, atol=1e-6)
    np.testing.assert_allclose(f.covariance, P_new, rtol=1e-4, atol=1e-9)


def test_process_noise_is_added_even_when_a_measurement_is_rejected():
    config = ManifoldFilter(rotation_sigma=0.006, translation_sigma=0.002,
                            process_variances=[3e-6] * 6)
    X_EC, X_BE, X_CT = _samples(4, 3)
    f = ManifoldHandEyeFilter(config, inverse(X_EC))
    P = f.covariance
    wrong = make_transform(rotation_exp([2.0, 0.0, 0.0]), [0.5, 0.0, 0.0])
    assert f.update_motion(wrong, inverse(X_BE[0]) @ X_BE[1]) is False
    np.testing.assert_allclose(f.covariance, P + 3e-6 * np.eye(6), rtol=1e-12)


def test_iterations_refine_a_large_update():
    """The iterated update ends closer to the ML point of the prior and one measurement than a
    single EKF step when the prior is far off."""
    X_EC, X_BE, X_CT = _samples(5, 3)
    X0 = retract_pose(inverse(X_EC), [0.2, -0.15, 0.1, 0.03, 0.0, 0.01])
    errors = {}
    for it in (1, 5):
        config = TargetFilter(rotation_sigma=SO3[0], translation_sigma=SO3[1], iterations=it,
                              initial_variances=[0.05] * 3 + [1e-3] * 3, gate_probability=None)
        f = HandEyeTargetFilter(config, X0, X_BT_init=X_BE[0] @ X_EC @ X_CT[0])
        for X_be, X_ct in zip(X_BE, X_CT):
            f.update(X_be, X_ct)
        errors[it] = rotation_error_deg(inverse(X_EC), f.X_CE)
    assert errors[5] < errors[1]


# ------------------------------------------------------------------------------- start-up
def test_two_motion_estimate_and_the_registry():
    X_EC, X_BE, X_CT = _samples(6, 3)
    exact = [inverse(X_be @ X_EC) @ (X_BE[0] @ X_EC @ X_CT[0]) for X_be in X_BE]
    np.testing.assert_allclose(two_motion_estimate(X_BE, exact), inverse(X_EC), atol=1e-8)
    for config, kind in ((CONFIGS["paper"], HandEyeKalmanFilter),
                         (CONFIGS["manifold"], ManifoldHandEyeFilter),
                         (CONFIGS["target"], HandEyeTargetFilter)):
        assert estimator_type(config) is kind
    with pytest.raises(ValueError, match="estimator: expected settings of type"):
        estimator_type(object())
    with pytest.raises(ValueError, match="rotation angle is 0"):
        two_motion_estimate([np.eye(4)] * 3, [np.eye(4)] * 3)


@pytest.mark.parametrize("name", ["manifold", "target", "paper"])
def test_start_estimator_replays_the_self_calibration_samples(name):
    config = CONFIGS[name]
    X_EC, X_BE, X_CT = _samples(7, 12)
    X0 = retract_pose(inverse(X_EC), [0.01, 0.0, 0.0, 0.002, 0.0, 0.0])
    start = start_estimator(config, X0, X_BE, X_CT)
    replay = config.replay_self_calibration
    manual = make_estimator(config, X0)
    for X_be, X_ct in zip(X_BE if replay else [], X_CT if replay else []):
        manual.update(X_be, X_ct)
    np.testing.assert_array_equal(start.estimator.to_vector(), manual.to_vector())
    assert start.replayed == (12 if replay else 0)


def test_manifold_ml_start_uses_the_buffered_motions():
    X_EC, X_BE, X_CT = _samples(8, 12)
    config = ManifoldFilter(rotation_sigma=0.006, translation_sigma=0.002, start="ml")
    X_far = retract_pose(inverse(X_EC), [0.3, 0.0, 0.0, 0.05, 0.0, 0.0])
    start = start_estimator(config, X_far, X_BE, X_CT)
    assert rotation_error_deg(inverse(X_EC), start.estimator.X_CE) < 1.0
    # The last buffered sample is the start of the next motion pair.
    assert start.estimator.update(X_BE[0], X_CT[0]) in (True, False)
    assert start.estimator.num_updates + start.estimator.num_rejected == 1


def test_a_failed_two_motion_start_widens_the_initial_covariance():
    config = CONFIGS["target"]
    wide = start_estimator(config, np.eye(4), from_guess=True).estimator
    narrow = start_estimator(config, np.eye(4)).estimator
    np.testing.assert_allclose(wide.X_CE_covariance, 100.0 * narrow.X_CE_covariance)


# ------------------------------------------------- what the estimators say about their data
def _single_axis_samples(seed, n=40, angle_scale=0.5):
    """Robot rotations about the base z axis only (SCARA-like), translations in x, y, z."""
    rng = np.random.default_rng(seed)
    X_EC = random_small_pose(rng, 1.0, 0.05)
    X_BT = make_transform(rotation_exp([3.0, 0.0, 0.2]), [0.5, 0.0, -0.3])
    X_BE = [make_transform(rotation_exp([0.0, 0.0, angle_scale * rng.normal()]),
                           [0.5, 0.0, 0.3] + 0.1 * rng.normal(size=3)) for _ in range(n)]
    X_CT = [_noisy_pose(rng, inverse(X @ X_EC) @ X_BT) for X in X_BE]
    return X_EC, X_BE, X_CT


@pytest.mark.parametrize("name", ["target", "manifold", "paper"])
def test_single_axis_motions_are_reported_not_observable(name):
    config = CONFIGS[name]
    X_EC, X_BE, X_CT = _single_axis_samples(9)
    est = make_estimator(config, inverse(X_EC))
    for X_be, X_ct in zip(X_BE, X_CT):
        est.update(X_be, X_ct)
    messages = est.diagnostics()
    assert any("not observable" in m for m in messages), messages
    assert any("[0.0, 0.0, 1.0]" in m or "[-0.0, -0.0, 1.0]" in m or "[0.0, 0.0, -1.0]" in m
               for m in messages), messages


@pytest.mark.parametrize("name", ["target", "manifold", "paper"])
def test_tiny_rotations_are_reported_not_observable(name):
    config = CONFIGS[name]
    X_EC, X_BE, X_CT = _single_axis_samples(10, angle_scale=1e-6)
    rng = np.random.default_rng(10)
    X_BE = [make_transform(rotation_exp(1e-6 * rng.normal(size=3)) @ X[:3, :3], X[:3, 3])
            for X in X_BE]
    est = make_estimator(config, inverse(X_EC))
    for X_be, X_ct in zip(X_BE, X_CT):
        est.update(X_be, X_ct)
    assert any("not observable" in m for m in est.diagnostics())


@pytest.mark.parametrize("name", ["target", "manifold", "paper"])
def test_well_excited_data_gives_no_diagnostics(name):
    config = CONFIGS[name]
    X_EC, X_BE, X_CT = _samples(11, 40)
    est = make_estimator(config, inverse(X_EC))
    for X_be, X_ct in zip(X_BE, X_CT):
        est.update(X_be, X_ct)
    assert est.diagnostics() == []


def test_target_filter_with_an_outlier_first_sample_recovers():
    """A wrong first camera pose (30°, 0.3 m off) only places the target with its prior
    covariance; the good samples then move the target, not X: the estimate stays right."""
    X_EC, X_BE, X_CT = _samples(12, 30)
    bad = make_transform(rotation_exp([np.radians(30.0), 0, 0]) @ X_CT[0][:3, :3],
                         X_CT[0][:3, 3] + [0.3, 0.0, 0.0])
    runs = {}
    for name, first in (("outlier first", bad), ("clean", X_CT[0])):
        f = HandEyeTargetFilter(CONFIGS["target"], inverse(X_EC))
        f.update(X_BE[0], first)
        for X_be, X_ct in zip(X_BE[1:], X_CT[1:]):
            f.update(X_be, X_ct)
        runs[name] = f
    f = runs["outlier first"]
    assert rotation_error_deg(runs["clean"].X_CE, f.X_CE) < 0.01
    assert rotation_error_deg(inverse(X_EC), f.X_CE) < 3 * max(f.X_EC_rotation_std_deg)
    assert f.num_rejected == 0 and f.diagnostics() == []


def test_a_filter_that_rejects_everything_says_so():
    X_EC, X_BE, X_CT = _samples(13, 20)
    f = HandEyeTargetFilter(CONFIGS["target"], inverse(X_EC),
                            X_BT_init=X_BE[0] @ X_EC @ X_CT[0] @ make_transform(
                                np.eye(3), [5.0, 0.0, 0.0]))
    f2 = HandEyeTargetFilter(TargetFilter(rotation_sigma=1e-6, translation_sigma=1e-7,
                                          target_prior_variances=[1e-12] * 6,
                                          max_consecutive_rejections=None), inverse(X_EC),
                             X_BT_init=X_BE[0] @ X_EC @ X_CT[0] @ make_transform(
                                 np.eye(3), [5.0, 0.0, 0.0]))
    for X_be, X_ct in zip(X_BE, X_CT):
        f.update(X_be, X_ct)
        f2.update(X_be, X_ct)
    assert f2.num_updates == 0 and f2.num_rejected == 20
    assert any("rejected 20 of 20" in m for m in f2.diagnostics())
    assert any("no sample accepted" in m for m in f2.diagnostics())


# ---------------------------------------------------------- settings: arbitrary values are refused
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

ANYTHING = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=5),
                     st.lists(st.floats(), max_size=13), st.just(float("inf")),
                     st.just(10**400), st.just([1e308] * 12))


@settings(max_examples=300, deadline=None)
@given(st.sampled_from([PaperFilter, ManifoldFilter, TargetFilter]), st.data())
def test_any_settings_value_is_accepted_or_a_value_error_naming_the_field(kind, data):
    """Each field set to an arbitrary value (None, inf, 10⁴⁰⁰, strings, wrong lists): building the
    estimator either works or raises ValueError naming that field — never TypeError,
    OverflowError or AttributeError."""
    import dataclasses
    base = {"PaperFilter": dict(rotation_coefficient_sigma=0.01, translation_sigma=0.01),
            "ManifoldFilter": dict(rotation_sigma=0.01, translation_sigma=0.01),
            "TargetFilter": dict(rotation_sigma=0.01, translation_sigma=0.01)}[kind.__name__]
    field = data.draw(st.sampled_from([f.name for f in dataclasses.fields(kind)]))
    value = data.draw(ANYTHING)
    config = kind(**{**base, field: value})
    try:
        est = make_estimator(config, np.eye(4))
    except ValueError as e:
        assert f"{kind.__name__}.{field}" in str(e), str(e)
    else:
        assert np.all(np.isfinite(est.to_vector()[:12]))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_wrong_noise_model_is_reported_not_trusted(seed):
    """Poses whose error accumulates (visual odometry: each pose = the previous one + a noisy
    motion) fed to the pose filter, which assumes independent pose noise of the same size: its
    σ end far too small, and its consistency test (mean NIS) says so. With independent pose
    noise, the same filter passes the test."""
    from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp
    X_EC = make_transform(rotation_exp([0.1, -0.2, 1.5]), [0.045, -0.012, 0.068])
    X_BT = make_transform(rotation_exp([np.pi, 0, 0]), [0.5, 0.0, 0.0])
    sr, st = 0.002, 0.001
    messages = {}
    for accumulating in (False, True):
        rng = np.random.default_rng(seed)
        drift = np.eye(4)
        f = HandEyeTargetFilter(TargetFilter(rotation_sigma=sr, translation_sigma=st),
                                inverse(X_EC))
        for _ in range(200):
            X_BE = make_transform(rotation_exp(0.3 * rng.normal(size=3)),
                                  [0.5, 0.0, 0.45] + 0.05 * rng.normal(size=3))
            noise = make_transform(rotation_exp(sr * rng.normal(size=3)), st * rng.normal(size=3))
            drift = noise @ drift if accumulating else noise
            f.update(X_BE, drift @ inverse(X_BE @ X_EC) @ X_BT)
        messages[accumulating] = f.consistency_message()
        assert (f.mean_nis > 9.0) == accumulating, f.mean_nis
    assert messages[False] == ""
    assert "do not fit the noise model" in messages[True]
    assert "σ reported are too small" in messages[True]

"""The paper's Kalman filter (``estimation.kalman``)."""

import numpy as np
import pytest

from handeye_drake import rotation_error_deg, translation_error_rel
from handeye_drake.estimation.configs import PaperFilter
from handeye_drake.estimation.kalman import HandEyeKalmanFilter, measurement_covariance
from handeye_drake.estimation.linear_model import linear_system, state_from_transform
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp
from tests.fixtures import motion_pairs, noisy, paper_filter, random_pose


@pytest.mark.parametrize("noise_covariance", ["diagonal", "exact"])
def test_filter_stays_at_truth_on_noise_free_data(noise_covariance, rng):
    X_CE = random_pose(rng, translation_scale=100.0)
    kf = paper_filter(X_CE, noise_covariance=noise_covariance)
    for A, B in motion_pairs(rng, X_CE, 200):
        kf.update_motion(A, B)
    np.testing.assert_allclose(kf.X_CE, X_CE, atol=1e-8 * 100)
    np.testing.assert_allclose(kf.X_EC, inverse(X_CE), atol=1e-8 * 100)
    assert kf.num_updates == 200


def test_filter_converges_from_wrong_initial_estimate(rng):
    X_CE = random_pose(rng, translation_scale=1.0)
    X0 = make_transform(rotation_exp([0.1, -0.1, 0.05]) @ X_CE[:3, :3], X_CE[:3, 3] + 0.2)
    kf = paper_filter(X0, rotation_sigma=0.01, translation_sigma=0.01)
    before = rotation_error_deg(X_CE, kf.X_CE), translation_error_rel(X_CE, kf.X_CE)
    for A, B in motion_pairs(rng, X_CE, 300, rotation_sigma_deg=10.0, translation_sigma=0.3):
        kf.update_motion(noisy(A, rng, 0.001, 0.001), B)
    after = rotation_error_deg(X_CE, kf.X_CE), translation_error_rel(X_CE, kf.X_CE)
    assert after[0] < 0.2 * before[0] and after[1] < 0.2 * before[1]


def test_recursive_equals_batch_weighted_least_squares(rng):
    """Zero process noise: the Kalman recursion is the batch WLS solution with the same prior."""
    X_CE = random_pose(rng, translation_scale=3.0)
    X0 = make_transform(rotation_exp([0.2, 0.1, -0.1]) @ X_CE[:3, :3], X_CE[:3, 3] + 0.5)
    P0 = np.diag(rng.uniform(0.5, 2.0, size=12))
    sr, st = 0.02, 0.05
    kf = paper_filter(X0, P0=P0, rotation_sigma=sr, translation_sigma=st)
    G2 = measurement_covariance("diagonal", sr, st)
    info = np.linalg.inv(P0)
    vec = info @ state_from_transform(X0)
    for A, B in motion_pairs(rng, X_CE, 40, rotation_sigma_deg=8.0):
        A = noisy(A, rng, sr, st)
        kf.update_motion(A, B)
        C, y = linear_system(A, B)
        info += C.T @ np.linalg.solve(G2, C)
        vec += C.T @ np.linalg.solve(G2, y)
    x_batch = np.linalg.solve(info, vec)
    np.testing.assert_allclose(kf.state, x_batch, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(kf.covariance, np.linalg.inv(info), rtol=1e-7, atol=1e-10)


def test_covariance_stays_symmetric_psd_over_long_runs(rng):
    X_CE = random_pose(rng, translation_scale=100.0)
    kf = paper_filter(X_CE, rotation_sigma=0.01, translation_sigma=0.1, noise_covariance="exact",
                      process_variances=[1e-12] * 12)
    for A, B in motion_pairs(rng, X_CE, 5000):
        kf.update_motion(noisy(A, rng, 0.01, 0.1), B)
    P = kf.covariance
    assert np.all(np.isfinite(kf.state))
    np.testing.assert_array_equal(P, P.T)
    assert np.linalg.eigvalsh(P).min() >= -1e-12 * np.abs(P).max()


def test_exact_noise_covariance_beats_the_diagonal_one_when_translation_is_large(rng):
    """The paper's diagonal G2 ignores the Δ t_X term, which dominates when ‖t_X‖ ≫ σ_t/σ_r."""
    errors = {"diagonal": [], "exact": []}
    for seed in range(6):
        r = np.random.default_rng(seed)
        X_CE = random_pose(r, translation_scale=100.0)
        X0 = make_transform(rotation_exp(r.normal(size=3) * 0.05) @ X_CE[:3, :3],
                            X_CE[:3, 3] + r.normal(size=3) * 5)
        filters = {m: paper_filter(X0, P0=[0.01] * 9 + [25.0] * 3, rotation_sigma=0.01,
                                   translation_sigma=0.1, noise_covariance=m) for m in errors}
        for A, B in motion_pairs(r, X_CE, 100):
            A = noisy(A, r, 0.01, 0.1)
            for f in filters.values():
                f.update_motion(A, B)
        for m, f in filters.items():
            errors[m].append(translation_error_rel(X_CE, f.X_CE))
    assert np.mean(errors["exact"]) < np.mean(errors["diagonal"])


def test_filter_rejects_bad_input_and_keeps_state(rng):
    X_CE = random_pose(rng)
    kf = paper_filter(X_CE)
    x0 = kf.state
    A, B = motion_pairs(rng, X_CE, 1)[0]
    bad_A = A.copy()
    bad_A[0, 3] = np.nan
    with pytest.raises(ValueError, match="A: contains NaN"):
        kf.update_motion(bad_A, B)
    with pytest.raises(ValueError, match="B.*not a rotation"):
        kf.update_motion(A, np.diag([2.0, 1.0, 1.0, 1.0]))
    with pytest.raises(ValueError, match="B: expected shape"):
        kf.update_motion(A, np.eye(3))
    zero = A.copy()
    zero[:3, :3] = 0.0
    with pytest.raises(ValueError, match="A: rotation block is not a .*rotation"):
        kf.update_motion(zero, B)
    reflection = A.copy()
    reflection[:3, 2] *= -1.0
    with pytest.raises(ValueError, match="A: rotation block is not a .*rotation.*reflection"):
        kf.update_motion(reflection, B)
    np.testing.assert_array_equal(kf.state, x0)
    assert kf.num_updates == 0


def test_a_gross_camera_error_is_refused_and_leaves_the_estimate(rng):
    """A camera translation of 1e6 (a wrong measurement no tuning explains) used to move the
    filter to 180° for good; now it is refused, gate or no gate."""
    X_CE = random_pose(rng, translation_scale=1.0)
    kf = paper_filter(X_CE, P0=1e-4, rotation_sigma=0.01, translation_sigma=0.01)
    pairs = motion_pairs(rng, X_CE, 20)
    for A, B in pairs[:10]:
        kf.update_motion(noisy(A, rng, 0.01, 0.01), B)
    before = kf.X_CE
    A, B = pairs[10]
    wrong = A.copy()
    wrong[:3, 3] += 1e6
    assert kf.update_motion(wrong, B) is False
    assert kf.num_rejected == 1 and kf.last_nis > 12 * 1e6
    np.testing.assert_array_equal(kf.X_CE, before)
    for A, B in pairs[11:]:
        assert kf.update_motion(noisy(A, rng, 0.01, 0.01), B)
    assert rotation_error_deg(X_CE, kf.X_CE) < 2.0


@pytest.mark.parametrize("settings, message", [
    (dict(noise_covariance="gaussian"), "PaperFilter.noise_covariance"),
    (dict(orthonormalization="gram"), "PaperFilter.orthonormalization"),
    (dict(rotation_coefficient_sigma=-1.0), "PaperFilter.rotation_coefficient_sigma"),
    (dict(translation_sigma=np.nan), "PaperFilter.translation_sigma"),
    (dict(translation_sigma=None), "PaperFilter.translation_sigma: not set"),
    (dict(initial_variances=[-1.0] * 12), r"PaperFilter.initial_variances\[0\]"),
    (dict(initial_variances=[1.0] * 3), "PaperFilter.initial_variances: needs 12"),
    (dict(process_variances=[1.0] * 6), "PaperFilter.process_variances: needs 12"),
    (dict(gate_probability=1.5), "PaperFilter.gate_probability"),
])
def test_filter_settings_errors_name_the_field(settings, message):
    args = dict(rotation_coefficient_sigma=0.01, translation_sigma=0.01)
    args.update(settings)
    with pytest.raises(ValueError, match=message):
        HandEyeKalmanFilter(PaperFilter(**args), np.eye(4))


@pytest.mark.parametrize("X, message", [
    (np.eye(3), "X_CE_init"), (np.diag([1.0, 1.0, -1.0, 1.0]), "X_CE_init.*not a rotation")])
def test_filter_initial_estimate_errors(X, message):
    with pytest.raises(ValueError, match=message):
        paper_filter(X)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_errors_in_variables_bias_is_reported(seed):
    """Many small noisy motions from a broad prior shrink the raw rotation block (the noise sits
    in the measurement matrix): the filter must say its estimate is biased. Large motions from a
    tight prior do not, and end within their σ."""
    X = make_transform(rotation_exp([0.3, -0.2, 1.2]), [0.05, -0.02, 0.08])
    for P0, deg, n, sigma, biased in ((1.0, 1.0, 300, 0.003, True),
                                      (1e-4, 30.0, 100, 0.001, False)):
        rng = np.random.default_rng(seed)
        f = paper_filter(X, P0=P0, rotation_sigma=sigma, translation_sigma=sigma,
                         noise_covariance="exact")
        for A, B in motion_pairs(rng, X, n, rotation_sigma_deg=deg, translation_sigma=0.05):
            f.update_motion(noisy(A, rng, sigma, sigma), B)
        messages = [m for m in f.diagnostics() if "errors in variables" in m]
        assert bool(messages) == biased, (P0, f.rotation_block_singular_values())
        if not biased:
            err = f.X_CE[:3, 3] - X[:3, 3]
            assert np.linalg.norm(err) < 4 * np.sqrt(np.trace(f.X_CE_covariance[3:, 3:]))

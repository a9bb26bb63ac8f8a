"""The σ of the observability report (``observability.analyze_observability``) against the
covariance of the maximum-likelihood fit (``ml.refine_ml_poses``, an independent path: the
Gauss–Newton Jacobian of the fit, not the information matrix), eye-in-hand and eye-to-hand:
the per-axis σ, every principal direction's information and σ, the condition number —
values, not directions (issue 22's blind spot: the report's σ were only bounded from above)."""

import math

import numpy as np
import pytest

from handeye_drake.estimation import ml
from handeye_drake.estimation import observability as ob
from handeye_drake.estimation.manifold import retract_pose
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp, rotation_from_rpy

SR, ST = 0.002, 0.001
R_DOWN = rotation_exp([math.pi, 0.0, 0.0])

CASES = {
    # mode: (X_HC, X_FT), neither at a symmetry point
    "eye_in_hand": (make_transform(rotation_from_rpy(np.radians([17.0, -23.0, 80.0])),
                                   [0.045, -0.012, 0.068]),
                    make_transform(rotation_exp([2.9, 0.2, 0.3]), [0.55, 0.05, 0.0])),
    "eye_to_hand": (make_transform(rotation_from_rpy(np.radians([-140.0, 25.0, -65.0])),
                                   [0.9, -0.2, 0.6]),
                    make_transform(rotation_exp([0.1, -0.2, 0.3]), [0.02, 0.01, 0.08])),
}


def _poses(rng, K, spread=0.4):
    return [make_transform(rotation_exp(spread * rng.normal(size=3)) @ R_DOWN,
                           [0.5, 0.05, 0.45] + rng.uniform(-0.1, 0.1, 3)) for _ in range(K)]


def _ml_covariance(mode, X_BE, X_HC, X_FT):
    """The ML covariance of X_HC (about / along H's axes) on exact data at the truth, from
    ``ml.refine_ml_poses`` (eye-to-hand: the same model with the robot poses inverted)."""
    Y = [inverse(x) for x in X_BE] if mode == "eye_in_hand" else X_BE
    X_CT = [inverse(X_HC) @ y @ X_FT for y in Y]
    robot = X_BE if mode == "eye_in_hand" else [inverse(x) for x in X_BE]  # refine: Y = X⁻¹
    r = ml.refine_ml_poses(robot, X_CT, retract_pose(inverse(X_HC), [0.01, 0, 0, 0.005, 0, 0]),
                           SR, ST)
    np.testing.assert_allclose(r.X_EC, X_HC, atol=1e-9)
    return r.X_EC_covariance


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
@pytest.mark.parametrize("spread", [0.4, 0.08])
def test_report_sigma_is_the_ml_covariance(mode, spread):
    """spread 0.4 rad: well determined; 0.08 rad: a weaker, less even recording."""
    X_HC, X_FT = CASES[mode]
    X_BE = _poses(np.random.default_rng(40), 12, spread)
    cov = _ml_covariance(mode, X_BE, X_HC, X_FT)
    rep = ob.observability_report(X_BE, inverse(X_HC), X_FT, SR, ST, mode)
    assert rep.frame == ("E" if mode == "eye_in_hand" else "B")
    np.testing.assert_allclose(rep.rotation_std_deg, np.degrees(np.sqrt(np.diag(cov)[:3])),
                               rtol=1e-6)
    np.testing.assert_allclose(rep.translation_std, np.sqrt(np.diag(cov)[3:]), rtol=1e-6)
    np.testing.assert_allclose(rep.information, np.linalg.inv(cov), rtol=1e-6,
                               atol=1e-9 * np.abs(rep.information).max())
    # Each principal direction v (normalized [δθ; δt / L]) has variance 1 / λ.
    L = rep.length_scale
    D_inv = np.diag([1, 1, 1, 1 / L, 1 / L, 1 / L])
    cov_n = D_inv @ cov @ D_inv
    lams = []
    for d in rep.directions:
        v = d.vector
        assert d.information == pytest.approx(1.0 / (v @ cov_n @ v), rel=1e-6)
        s = 1.0 / math.sqrt(d.information)
        assert d.rotation_std_deg == pytest.approx(math.degrees(np.linalg.norm(v[:3]) * s),
                                                   rel=1e-9)
        assert d.translation_std == pytest.approx(np.linalg.norm(v[3:]) * s * L, rel=1e-9)
        lams.append(d.information)
    assert lams == sorted(lams)  # least determined first
    w = np.linalg.eigvalsh(cov_n)
    assert rep.condition_number == pytest.approx(w[-1] / w[0], rel=1e-6)
    # The length scale: the median camera–target distance.
    Y = [inverse(x) for x in X_BE] if mode == "eye_in_hand" else X_BE
    dist = [np.linalg.norm((inverse(X_HC) @ y @ X_FT)[:3, 3]) for y in Y]
    assert L == pytest.approx(float(np.median(dist)), rel=1e-12)


def test_hand_eye_std_is_the_report_sigma_with_and_without_held_components():
    X_HC, X_FT = CASES["eye_in_hand"]
    X_BE = _poses(np.random.default_rng(41), 10)
    info = ob.information_matrix(X_BE, inverse(X_HC), X_FT, SR, ST)
    rep = ob.analyze_observability(info, inverse(X_HC))
    rot, tra = ob.hand_eye_std(info, inverse(X_HC))
    np.testing.assert_allclose(rot, rep.rotation_std_deg, rtol=1e-9)
    np.testing.assert_allclose(tra, rep.translation_std, rtol=1e-9)
    # Holding tz: conditioning on it, the others' variance is Σ_aa − Σ_az Σ_zz⁻¹ Σ_za.
    cov = np.linalg.inv(rep.information)
    a = [0, 1, 2, 3, 4]
    cond = cov[np.ix_(a, a)] - np.outer(cov[a, 5], cov[5, a]) / cov[5, 5]
    rot, tra = ob.hand_eye_std(info, inverse(X_HC), ("tz",))
    np.testing.assert_allclose(rot, np.degrees(np.sqrt(np.diag(cond)[:3])), rtol=1e-6)
    np.testing.assert_allclose(tra[:2], np.sqrt(np.diag(cond)[3:]), rtol=1e-6)
    assert tra[2] == 0.0


def test_weak_direction_message_gives_the_ml_sigma_and_the_perpendicular_bound():
    """Nearly parallel rotation axes (2° tilt): "translation along E z is weakly determined
    (σ X mm vs ≤ Y mm along the perpendicular axes)" — X the σ of the error along the weak
    direction, Y the largest σ across it, both from the ML covariance."""
    import re
    from tests.estimation.test_observability import scara_poses
    X_HC, X_FT = CASES["eye_in_hand"]
    X_BE = scara_poses(np.random.default_rng(5), 20, tilt_deg=2.0)
    cov = _ml_covariance("eye_in_hand", X_BE, X_HC, X_FT)
    rep = ob.observability_report(X_BE, inverse(X_HC), X_FT, SR, ST)
    (d,) = rep.weak
    assert d.kind == "translation" and d.name == "translation along E z"
    msg = next(m for m in rep.messages if m.startswith("translation along E z is weakly"))
    x_mm, y_mm = (float(v) for v in re.search(r"σ ([0-9.]+) mm vs ≤ ([0-9.]+) mm along the "
                                              r"perpendicular axes", msg).groups())
    # X: the std of the error component along the direction, given the rest (1/√λ).
    v = np.concatenate([np.zeros(3), d.translation_axis])
    L = rep.length_scale
    D_inv = np.diag([1, 1, 1, 1 / L, 1 / L, 1 / L])
    lam = 1.0 / (d.vector @ D_inv @ cov @ D_inv @ d.vector)
    assert x_mm == pytest.approx(1000 * np.linalg.norm(d.vector[3:]) * L / math.sqrt(lam),
                                 rel=6e-3)  # printed to 3 digits
    assert x_mm > 5 * y_mm
    # Y: the largest σ of translations perpendicular to the weak axis (marginal, from Σ_tt).
    a = d.translation_axis
    P = np.eye(3) - np.outer(a, a)
    assert y_mm == pytest.approx(1000 * math.sqrt(np.linalg.eigvalsh(P @ cov[3:, 3:] @ P)[-1]),
                                 rel=6e-3)  # printed to 3 digits
    assert abs(v @ d.vector) > 0.99

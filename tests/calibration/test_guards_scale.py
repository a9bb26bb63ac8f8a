"""The target-scale readings and the repeating robot error level, against formulas computed
here: the robot reading's translations t / s, the answer at their midpoint with covariance the
midpoint map's Jacobian (finite differences here) applied to the fit's plus ¼ (t_A − t_B)(…)ᵀ;
the robot level √(σ_r² + (σ_t / depth)²), √(σ_t² + (σ_r · depth)²) and at least the given
accuracy."""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handeye_drake.calibration.corners import scale_readings, systematic_robot_level


def _pose(euler_deg, t):
    X = np.eye(4)
    X[:3, :3] = Rotation.from_euler("xyz", euler_deg, degrees=True).as_matrix()
    X[:3, 3] = t
    return X


@pytest.mark.parametrize("s", [1.02, 0.985])
def test_scale_readings_midpoint_and_covariance(s):
    rng = np.random.default_rng(3)
    X_H, X_F = _pose([5, -10, 20], [0.03, -0.05, 0.12]), _pose([170, 5, -30], [0.6, 0.1, -0.02])
    G = 13                                                   # [θ_H t_H θ_F t_F s]
    A = rng.normal(size=(G, G)) * 1e-3
    C = A @ A.T + np.diag(np.full(G, 1e-8))
    r = scale_readings(X_H, X_F, s, C)
    for k, (X, i) in enumerate(((X_H, 0), (X_F, 6))):
        t = X[:3, 3]
        np.testing.assert_allclose(r["print"][k], X)
        np.testing.assert_allclose(r["robot"][k][:3, 3], t / s, rtol=1e-12)
        np.testing.assert_allclose(r["robot"][k][:3, :3], X[:3, :3])
        np.testing.assert_allclose(r["answer"][k][:3, 3], 0.5 * (t + t / s), rtol=1e-12)
        # Jacobian of m(t, s) = ½ (t + t / s) by central differences; rotation passes through.
        mid = lambda tt, ss: 0.5 * (tt + tt / ss)
        h = 1e-6
        J = np.zeros((6, G))
        J[:3, i:i + 3] = np.eye(3)
        for a in range(3):
            e = np.zeros(3)
            e[a] = h
            J[3:, i + 3 + a] = (mid(t + e, s) - mid(t - e, s)) / (2 * h)
        J[3:, -1] = (mid(t, s + h) - mid(t, s - h)) / (2 * h)
        spread = np.concatenate([np.zeros(3), t - t / s])      # print minus robot reading
        expected = J @ C @ J.T + 0.25 * np.outer(spread, spread)
        np.testing.assert_allclose(r["answer"][2 + k], expected, rtol=1e-5, atol=1e-14)


@pytest.mark.parametrize("depth", [0.0, 0.6])
def test_systematic_robot_level_formula(depth):
    sr, st = math.radians(0.05), 0.8e-3                       # per axis, rad and m
    fit = SimpleNamespace(pose_sigma=np.array([sr, sr, sr, st, st, st]))
    rot, tra = systematic_robot_level(fit, None, depth)
    er = math.hypot(sr, st / depth) if depth > 0 else sr
    assert rot == pytest.approx(math.degrees(er), rel=1e-12)
    assert tra == pytest.approx(math.hypot(st, sr * depth), rel=1e-12)
    # A given accuracy counts when it is the larger, on each axis alone.
    big = (10 * math.degrees(er), 10 * tra)
    assert systematic_robot_level(fit, (big[0], 1e-9), depth) == pytest.approx((big[0], tra))
    assert systematic_robot_level(fit, (1e-9, big[1]), depth) == pytest.approx(
        (math.degrees(er), big[1]))

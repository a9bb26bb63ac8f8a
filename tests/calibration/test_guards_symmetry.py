"""``symmetry.pair_costs`` against a planted error of known size: the robot motion between two
views (in the flange frame, X_EiEj = X_BEi⁻¹ X_BEj) turned δ more about its own screw axis and
slid ε more along it changes its angle by exactly δ and its slide by exactly ε, so the pair's
cost at the right labelling is (δ / 1°)² + (ε / 5 mm)² and at the board's other turn far more."""

import math

import numpy as np
import pytest

from handeye_drake.calibration.symmetry import pair_costs
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp, rotation_log

TURNS = np.array([np.eye(4), make_transform(rotation_exp([0.0, 0.0, math.pi]), [0.175, 0.125, 0])])


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
def test_pair_cost_of_a_planted_angle_and_slide(mode):
    rng = np.random.default_rng(11)
    X_hand = make_transform(rotation_exp([0.3, -0.2, 0.5]), [0.04, -0.03, 0.09])
    X_fixed = make_transform(rotation_exp([2.9, 0.1, -0.2]), [0.6, 0.1, 0.05])
    X_BE = np.array([make_transform(rotation_exp(rng.normal(scale=0.5, size=3)),
                                    [0.4, 0, 0.5] + rng.normal(scale=0.1, size=3))
                     for _ in range(3)])
    if mode == "eye_in_hand":      # X_CT = X_EC⁻¹ X_BE⁻¹ X_BT
        X_CT = np.array([inverse(X_hand) @ inverse(X) @ X_fixed for X in X_BE])
    else:                          # X_CT = X_BC⁻¹ X_BE X_ET
        X_CT = np.array([inverse(X_hand) @ X @ X_fixed for X in X_BE])
    A = inverse(X_BE[0]) @ X_BE[1]
    w = rotation_log(A[:3, :3])
    u = w / np.linalg.norm(w)
    assert math.radians(20) < np.linalg.norm(w) < math.radians(170)   # a screw: slide counts
    slide = float(u @ A[:3, 3])
    delta, eps = math.radians(0.5), math.copysign(0.002, slide)
    X_BE[1] = X_BE[1] @ make_transform(rotation_exp(delta * u), eps * u)
    cost = pair_costs(X_BE, X_CT, TURNS, mode)
    assert cost[0, 1, 0] == pytest.approx(0.5 ** 2 + (2.0 / 5.0) ** 2, rel=1e-3)
    assert cost[0, 1, 1] > 10.0
    assert cost[0, 2, 0] < 1e-9 and cost[1, 1, 1] == 0.0


def test_the_turn_most_views_are_detected_in_is_as_detected():
    # The first view (the first reference of the search) detected turned, the others not: the
    # labels undo the turn in the first view only (not in all the others, relative to it).
    from handeye_drake.calibration.symmetry import resolve
    from handeye_drake.vision.targets import target_symmetries
    from tests.calibration.test_symmetry import _views
    X_BE, X_true = _views("eye_in_hand", 8, np.random.default_rng(4))
    turns = np.array([np.eye(4)] + [G for G, _ in target_symmetries("chessboard:8x6:0.025")])
    applied = np.zeros(8, int)
    applied[0] = 1
    X_CT = np.einsum("nab,nbc->nac", X_true, turns[applied])
    labels, decided = resolve(X_BE, X_CT, turns, "eye_in_hand")
    assert decided.all()
    np.testing.assert_array_equal(labels, applied)

"""The held-intrinsics test's degrees of freedom and bound against counts made here: a model
holds 9 − (parameters it refines) intrinsics (none 9, k1k2 p1 p2 k3 = 3), and the bound is
scipy's χ² quantile at 1 − 10⁻⁶ on that many dof; a contradiction whose release moves the
answer more than 3σ is a FAIL."""

import pytest
from scipy.stats import chi2

from handeye_drake.calibration.held_intrinsics import held_reason
from tests.calibration.test_held_intrinsics import TRUTH, _run

HELD = {"none": 9, "k1k2": 3}


@pytest.mark.parametrize("model", sorted(HELD))
def test_held_dof_and_bound(model):
    result = _run(model, TRUTH, seed=1)[0]
    test = result.corners.held
    assert test["dof"] == HELD[model]
    assert test["bound"] == pytest.approx(chi2.ppf(1.0 - 1e-6, HELD[model]), rel=1e-9)
    assert not test["contradicted"]


@pytest.mark.parametrize("move, level", [(3.2, "FAIL"), (2.8, "WARN")])
def test_a_held_contradiction_moving_the_answer_beyond_3_sigma_is_a_fail(move, level):
    # The answer at the held values would sit outside its own 3σ: never a WARN.
    test = {"named": [{"name": "cx", "given": 320.0, "released": 345.0, "std": 0.5}],
            "move_sigmas": move, "move_deg": 0.1, "move_m": 0.002, "statistic": 900.0,
            "bound": 37.3, "dof": 9, "model": "pinhole", "restricted_plausible": True,
            "matters": move > 3.0}
    assert held_reason(test, "X_EC", "none").level == level

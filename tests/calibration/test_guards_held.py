"""The held-intrinsics test's degrees of freedom and bound against counts made here: a model
holds 9 − (parameters it refines) intrinsics (none 9, k1k2 p1 p2 k3 = 3), and the bound is
scipy's χ² quantile at 1 − 10⁻⁶ on that many dof."""

import pytest
from scipy.stats import chi2

from tests.calibration.test_held_intrinsics import TRUTH, _run

HELD = {"none": 9, "k1k2": 3}


@pytest.mark.parametrize("model", sorted(HELD))
def test_held_dof_and_bound(model):
    result = _run(model, TRUTH, seed=1)[0]
    test = result.corners.held
    assert test["dof"] == HELD[model]
    assert test["bound"] == pytest.approx(chi2.ppf(1.0 - 1e-6, HELD[model]), rel=1e-9)
    assert not test["contradicted"]

"""``compare`` against numbers computed here: the χ² bound is scipy's 99.9 % point on 6 dof, the
difference is log(R_this R_otherᵀ) about the parent's axes, its covariance the sum of both
answers', and the part named as moved is the one with the larger own χ² (planted differences
on both sides of the bound)."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from handeye_drake.calibration import compare

BOUND = chi2.ppf(0.999, 6)          # 22.46; on 3 dof it would be 16.27


def _answer(R, t, sd):
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, t
    return {"mode": "eye_in_hand", "verdict": {"status": "OK"},
            "X_EC": {"matrix": X.tolist(), "std": {"covariance": np.diag(np.square(sd)).tolist()}}}


SD = np.array([1e-3, 2e-3, 4e-3, 1e-3, 2e-3, 3e-3])        # rad, m


@pytest.mark.parametrize("q", [0.85 * BOUND, 1.15 * BOUND])
def test_bound_is_chi2_6_dof_and_the_covariance_is_the_sum(q):
    # A translation along y worth χ² = q with C = C_a + C_b = 2 diag(SD²).
    dy = math.sqrt(q * 2.0) * SD[4]
    R = Rotation.from_euler("xyz", [10, -20, 30], degrees=True).as_matrix()
    c = compare(_answer(R, [0.1, 0.2 + dy, 0.3], SD), _answer(R, [0.1, 0.2, 0.3], SD))
    assert c.threshold == pytest.approx(BOUND, rel=1e-9)
    assert c.chi2 == pytest.approx(q, rel=1e-6)
    np.testing.assert_allclose(np.diag(c.covariance), 2 * SD ** 2, rtol=1e-9)
    assert c.consistent == (q <= BOUND)
    if not c.consistent:
        assert c.cause == "mount_moved" and "(translation mostly)" in c.text
    assert c.to_dict()["dof"] == 6


def test_difference_is_about_the_parent_axes_and_the_rotation_is_named():
    # this = Rz(α) · other: the difference is α about the parent's z, whatever the other's
    # orientation (here x turned 90°, which would put R_thisᵀ R_other's axis on y).
    R_o = Rotation.from_euler("x", 90, degrees=True).as_matrix()
    a = 6.0 * SD[2]                                  # χ² = 36 / 2 = 18 < bound; rotation only
    R_t = Rotation.from_euler("z", a).as_matrix() @ R_o
    c = compare(_answer(R_t, [0, 0, 0.1], SD), _answer(R_o, [0, 0, 0.1], SD))
    np.testing.assert_allclose(c.difference, [0, 0, a, 0, 0, 0], atol=1e-12)
    assert c.rotation_deg == pytest.approx(math.degrees(a))
    assert c.consistent and c.chi2 == pytest.approx(18.0, rel=1e-6)
    # Rotation and translation both moved, rotation's own χ² the larger: rotation named.
    b = 8.0 * SD[2]                                  # rotation χ² 32, translation χ² 8
    R_t = Rotation.from_euler("z", b).as_matrix() @ R_o
    c = compare(_answer(R_t, [0, 0, 0.1 + 4.0 * SD[5]], SD), _answer(R_o, [0, 0, 0.1], SD))
    assert not c.consistent and "(rotation mostly)" in c.text
    c = compare(_answer(R_o, [0, 0, 0.1 + 8.0 * SD[5]], SD),
                _answer(Rotation.from_euler("z", -4.0 * SD[2]).as_matrix() @ R_o, [0, 0, 0.1], SD))
    assert not c.consistent and "(translation mostly)" in c.text

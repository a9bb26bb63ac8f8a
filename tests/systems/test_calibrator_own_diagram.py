"""The calibrator placed into a user's own diagram (their MultibodyPlant, controller and camera;
no project scenario): ``examples/calibrator_in_your_diagram.py``, run here."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from handeye_drake.estimation.configs import TargetFilter
from handeye_drake.estimation.errors import rotation_error_deg
from handeye_drake.estimation.se3 import make_transform, rotation_exp
from handeye_drake.systems.calibrator import (STATUS_FILTERING, STATUS_INIT_FAILED,
                                             HandEyeCalibrator)

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "calibrator_in_your_diagram.py"


def _example():
    spec = importlib.util.spec_from_file_location("calibrator_in_your_diagram", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _within(module, X, std, k=3.0):
    return (rotation_error_deg(module.X_EC_TRUE, X) < k * np.linalg.norm(std[:3])
            and np.linalg.norm(X[:3, 3] - module.X_EC_TRUE[:3, 3]) < k * np.linalg.norm(std[3:]))


def test_your_plant_your_camera_with_two_self_calibration_motions():
    ex = _example()
    X, std, status = ex.run(seed=0)
    assert status[0] == STATUS_FILTERING and status[1] > 200
    assert _within(ex, X, std)
    assert np.linalg.norm(std[3:]) < 1e-3     # it did learn: sub-millimetre


def test_without_self_calibration_motions_it_starts_from_the_guess():
    ex = _example()
    guess = ex.X_EC_TRUE @ make_transform(rotation_exp([0.03, -0.02, 0.02]), [0.01, -0.008, 0.005])
    X, std, status = ex.run(seed=1, with_phase=False, X_EC_guess=guess)
    assert status[0] == STATUS_INIT_FAILED      # "started from a guess", said on the status
    assert _within(ex, X, std)
    assert rotation_error_deg(ex.X_EC_TRUE, X) < 0.2 * rotation_error_deg(ex.X_EC_TRUE, guess)


@pytest.mark.parametrize("seed,factor", [(1, 1.5), (1, 3.0)])
def test_a_camera_noisier_than_told_never_gives_a_sigma_below_the_error(seed, factor):
    # The calibrator told a fraction of the camera's noise: its σ covers the error (the noise
    # estimated on-line from the innovations), or, when the gate refuses a large share of the
    # measurements, it is nan (refused: no basis) — never a small σ on a wrong estimate.
    ex = _example()
    X, std, status = ex.run(seed=seed, told_noise=(ex.NOISE[0] / factor,
                                                    ex.NOISE[1] / factor))
    assert status[0] == STATUS_FILTERING
    if np.isnan(std).any():
        assert np.isnan(std).all() and status[2] > 0.25 * (status[1] + status[2])
    else:
        assert _within(ex, X, std)
    if factor == 3.0:
        assert np.isnan(std).all()      # (its estimate is 17° / 130 mm off)


def test_construction_says_what_it_needs():
    with pytest.raises(ValueError, match="exactly one of X_EC_initial_guess"):
        HandEyeCalibrator(0.1, estimator=TargetFilter(rotation_sigma=0.002,
                                                       translation_sigma=0.001))
    with pytest.raises(ValueError, match="TargetFilter\\(rotation_sigma"):
        HandEyeCalibrator(0.1, X_EC_initial_guess=np.eye(4))
    with pytest.raises(ValueError, match="rotation_sigma: not set"):
        HandEyeCalibrator(0.1, X_EC_initial_guess=np.eye(4), estimator=TargetFilter())
    with pytest.raises(ValueError, match="or 0"):
        HandEyeCalibrator(0.1, X_EC_initial_guess=np.eye(4), num_self_calibration_motions=1,
                          estimator=TargetFilter(rotation_sigma=0.002, translation_sigma=0.001))
    # Both conventions give the same system.
    X_EC = make_transform(rotation_exp([0, 0, 1.0]), [0.01, 0.02, 0.03])
    a = HandEyeCalibrator(0.1, X_EC_initial_guess=X_EC, estimator=TargetFilter(
        rotation_sigma=0.002, translation_sigma=0.001))
    b = HandEyeCalibrator(0.1, X_CE_initial_guess=np.linalg.inv(X_EC), estimator=TargetFilter(
        rotation_sigma=0.002, translation_sigma=0.001))
    ca, cb = a.CreateDefaultContext(), b.CreateDefaultContext()
    np.testing.assert_allclose(a.get_X_EC_output_port().Eval(ca),
                               b.get_X_EC_output_port().Eval(cb), atol=1e-12)

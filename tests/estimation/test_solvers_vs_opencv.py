"""Our classical solvers against OpenCV's ``cv2.calibrateHandEye`` on the same poses.

OpenCV's inputs are R/t_gripper2base = X_BE, R/t_target2cam = X_CT; its output
R/t_cam2gripper = X_EC, which ``calibrate_hand_eye`` also returns. Both use every pair of samples.

Tolerances:
- "park", "horaud", "daniilidis" follow OpenCV's formulation step by step (same motions, same
  equations, same unknown), so they must agree to rounding: we require 1e-9 (rad and m) — about
  five orders of magnitude below the smallest estimation error in these tests (≥ 1e-4), so the
  brief's ‖ours − OpenCV‖ ≤ 0.05·error + 1e-6 holds a fortiori.
- "tsai": OpenCV 4.14 drops the pairs whose gripper or camera rotation has sin(θ/2) outside
  [0.15, 0.85]; applied to the motions we pass to ``solve_ax_xb`` it gives OpenCV's result to
  rounding (same 1e-9). ``calibrate_hand_eye`` keeps all pairs, so there only comparable error
  is required.
- "andreff": ours takes the rotation from the null space of the homogeneous block and re-solves
  the translation (Andreff 2001, docs/method.md §3); OpenCV solves the full inhomogeneous system in one
  least squares. Different estimators: we require ours ≤ 1.5 × OpenCV's error + 1e-6, averaged
  over seeds (the mean over 5 seeds is stable to ~20%, so 1.5 catches a real regression, not
  chance).
"""

import numpy as np
import pytest

from handeye_drake.estimation.se3 import inverse, make_transform, rotation_angle, rotation_exp
from handeye_drake.estimation.solvers import METHODS, calibrate_hand_eye, solve_ax_xb

cv2 = pytest.importorskip("cv2")
if not hasattr(cv2, "calibrateHandEye"):
    pytest.skip("this OpenCV build has no calibrateHandEye", allow_module_level=True)

CV_METHODS = {
    "tsai": cv2.CALIB_HAND_EYE_TSAI,
    "park": cv2.CALIB_HAND_EYE_PARK,
    "horaud": cv2.CALIB_HAND_EYE_HORAUD,
    "andreff": cv2.CALIB_HAND_EYE_ANDREFF,
    "daniilidis": cv2.CALIB_HAND_EYE_DANIILIDIS,
}
SAME_FORMULATION = ("park", "horaud", "daniilidis")
#: (rotation-vector noise per axis in degrees, translation noise per axis in m) on X_CT.
NOISE_LEVELS = [(0.1, 2e-4), (0.5, 1e-3), (2.0, 5e-3)]
SEEDS = range(5)
ROUNDING = 1e-9


def axis_angle(rng, lo_deg, hi_deg):
    n = rng.normal(size=3)
    return rotation_exp(n / np.linalg.norm(n) * np.radians(rng.uniform(lo_deg, hi_deg)))


def make_dataset(seed, n=15, rotation_noise_deg=0.5, translation_noise=1e-3, lo_deg=20,
                 hi_deg=55):
    """Eye-in-hand poses: X_BE tilted lo–hi degrees about random axes from a camera-down
    nominal, a target fixed in the base, and X_CT = inv(X_BE X_EC) X_BT with rotation-vector
    noise (right-multiplied) and translation noise. Returns (X_EC, X_BE list, X_CT list)."""
    rng = np.random.default_rng(seed)
    X_EC = make_transform(axis_angle(rng, 20, 120), 0.1 * rng.normal(size=3))
    X_BT = make_transform(axis_angle(rng, 0, 180), [0.6, 0.1, 0.0])
    R_down = rotation_exp([np.pi, 0.0, 0.0])
    X_BE = [make_transform(R_down @ axis_angle(rng, lo_deg, hi_deg),
                           np.array([0.6, 0.1, 0.5]) + 0.1 * rng.normal(size=3))
            for _ in range(n)]
    X_CT = []
    for X in X_BE:
        X_CT_exact = inverse(X @ X_EC) @ X_BT
        noise = rotation_exp(np.radians(rotation_noise_deg) * rng.normal(size=3))
        X_CT.append(make_transform(X_CT_exact[:3, :3] @ noise,
                                   X_CT_exact[:3, 3] + translation_noise * rng.normal(size=3)))
    return X_EC, X_BE, X_CT


def opencv_X_EC(X_BE, X_CT, method):
    R, t = cv2.calibrateHandEye([X[:3, :3] for X in X_BE], [X[:3, 3] for X in X_BE],
                                [X[:3, :3] for X in X_CT], [X[:3, 3] for X in X_CT],
                                method=CV_METHODS[method])
    return make_transform(R, t.ravel())


def errors(X_ref, X):
    """(rotation error in rad, translation error in m) of X against X_ref."""
    return (rotation_angle(X_ref[:3, :3].T @ X[:3, :3]),
            float(np.linalg.norm(X_ref[:3, 3] - X[:3, 3])))


@pytest.mark.parametrize("method", METHODS)
def test_noise_free_agrees_with_opencv(method):
    for lo, hi in [(20, 55), (60, 90)]:
        X_EC, X_BE, X_CT = make_dataset(0, 10, 0.0, 0.0, lo, hi)
        ours, theirs = calibrate_hand_eye(X_BE, X_CT, method), opencv_X_EC(X_BE, X_CT, method)
        assert max(errors(X_EC, ours)) < 1e-9
        assert max(errors(ours, theirs)) < 1e-6


@pytest.mark.parametrize("method", SAME_FORMULATION)
@pytest.mark.parametrize("noise", NOISE_LEVELS)
def test_same_formulation_agrees_to_rounding(method, noise):
    for seed in SEEDS:
        X_EC, X_BE, X_CT = make_dataset(seed, 15, *noise)
        ours, theirs = calibrate_hand_eye(X_BE, X_CT, method), opencv_X_EC(X_BE, X_CT, method)
        (d_rot, d_trans), (e_rot, e_trans) = errors(theirs, ours), errors(X_EC, ours)
        assert e_rot > 1e-5 and e_trans > 1e-5  # noise really moved the estimate
        assert d_rot <= ROUNDING and d_trans <= ROUNDING, (seed, d_rot, d_trans)
        assert d_rot <= 0.05 * e_rot + 1e-6 and d_trans <= 0.05 * e_trans + 1e-6


def opencv_tsai_pairs(X_BE, X_CT):
    """All pairs i < j as OpenCV forms them (A = X_CjCi, B = X_EjEi), minus those its Tsai drops:
    sin(θ/2) of the gripper or camera rotation outside [0.15, 0.85]."""
    A, B, dropped = [], [], 0
    for i in range(len(X_BE)):
        for j in range(i + 1, len(X_BE)):
            a, b = X_CT[j] @ inverse(X_CT[i]), inverse(X_BE[j]) @ X_BE[i]
            s = [np.sin(rotation_angle(X[:3, :3]) / 2) for X in (a, b)]
            if 0.15 <= min(s) and max(s) <= 0.85:
                A.append(a)
                B.append(b)
            else:
                dropped += 1
    return A, B, dropped


@pytest.mark.parametrize("noise", NOISE_LEVELS)
def test_tsai_matches_opencv_on_the_pairs_it_keeps(noise):
    # 10–90° tilts: relative rotations from ~0° to ~180°, so both ends of the band are hit.
    for seed in SEEDS:
        X_EC, X_BE, X_CT = make_dataset(seed, 12, *noise, lo_deg=10, hi_deg=90)
        A, B, dropped = opencv_tsai_pairs(X_BE, X_CT)
        assert dropped > 0
        ours = inverse(solve_ax_xb(A, B, "tsai"))
        theirs = opencv_X_EC(X_BE, X_CT, "tsai")
        assert max(errors(theirs, ours)) <= ROUNDING, (seed, errors(theirs, ours))


@pytest.mark.parametrize("method", ["tsai", "andreff"])
@pytest.mark.parametrize("noise", NOISE_LEVELS)
def test_different_formulation_comparable_error(method, noise):
    ours_err, cv_err = np.zeros(2), np.zeros(2)
    for seed in SEEDS:
        X_EC, X_BE, X_CT = make_dataset(seed, 15, *noise)
        ours_err += errors(X_EC, calibrate_hand_eye(X_BE, X_CT, method))
        cv_err += errors(X_EC, opencv_X_EC(X_BE, X_CT, method))
    ours_err, cv_err = ours_err / len(SEEDS), cv_err / len(SEEDS)
    assert np.all(ours_err <= 1.5 * cv_err + 1e-6), (ours_err, cv_err)


@pytest.mark.parametrize("method", METHODS)
def test_large_rotations_comparable_error(method):
    """60–90° tilts (relative rotations up to ~180°): every method still matches OpenCV's
    accuracy, and both estimate the rotation to a fraction of the 0.5° pose noise."""
    ours_err, cv_err = np.zeros(2), np.zeros(2)
    for seed in SEEDS:
        X_EC, X_BE, X_CT = make_dataset(seed, 15, 0.5, 1e-3, lo_deg=60, hi_deg=90)
        ours_err += errors(X_EC, calibrate_hand_eye(X_BE, X_CT, method))
        cv_err += errors(X_EC, opencv_X_EC(X_BE, X_CT, method))
    ours_err, cv_err = ours_err / len(SEEDS), cv_err / len(SEEDS)
    assert np.all(ours_err <= 1.5 * cv_err + 1e-6), (ours_err, cv_err)
    assert ours_err[0] < np.radians(0.5) and cv_err[0] < np.radians(0.5)

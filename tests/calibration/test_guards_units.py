"""The verdict's bounds, each tested on both sides of the line with data whose truth is known
here (the noise drawn, the outliers planted, the camera's distance set), so that a bound
changed 10× or a comparison inverted fails: the noise limit (--max-noise), the plausible
hand-eye distance, the outlier fractions, the fewest samples, the held-out minimum, the
split-half χ² bound."""

import math

import numpy as np
import pytest
from scipy.stats import chi2

from handeye_drake.calibration import CalibrationOptions
from handeye_drake.calibration.api import solve
from handeye_drake.calibration.checks import held_out_test
from handeye_drake.calibration.inputs import Streams
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp
from handeye_drake.recorded.formats import pose_stream

X_BT = make_transform(rotation_exp(np.array([math.pi, 0.0, 0.0])), [-0.45, -0.15, 0.0])


def _look(z, roll):
    z = z / np.linalg.norm(z)
    a = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
    x = np.cross(a, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z]) @ rotation_exp(np.array([0, 0, roll]))


def _samples(n, seed, X_EC, camera=(0.05, 0.3)):
    """n eye-in-hand (X_BE, X_CT), the camera 0.3–0.6 m from the board, camera noise per axis
    (deg, mm); the robot exact."""
    rng = np.random.default_rng(seed)
    X_BE, X_CT = [], []
    for _ in range(n):
        d = rng.uniform(0.3, 0.6)
        tilt = math.acos(rng.uniform(math.cos(0.6), 1))
        az = rng.uniform(0, 2 * math.pi)
        z = X_BT[:3, :3] @ np.array([math.sin(tilt) * math.cos(az),
                                     math.sin(tilt) * math.sin(az), math.cos(tilt)])
        X_BC = make_transform(_look(z, rng.uniform(-3, 3)), X_BT[:3, 3] - d * z)
        X_BE.append(X_BC @ inverse(X_EC))
        T = inverse(X_BC) @ X_BT
        X_CT.append(make_transform(
            rotation_exp(rng.normal(0, math.radians(camera[0]), 3)) @ T[:3, :3],
            T[:3, 3] + rng.normal(0, camera[1] / 1e3, 3)))
    return np.array(X_BE), np.array(X_CT)


def _solve(X_BE, X_CT, **options):
    streams = Streams(robot=pose_stream(X_BE, None, "robot"),
                      camera=pose_stream(X_CT, None, "camera"), inputs={"test": {}},
                      roles_known=True)
    return solve(streams, CalibrationOptions(time_offset_s=0.0, **options))


X_EC = make_transform(rotation_exp(np.array([0.05, -0.03, 1.6])), [0.04, -0.03, 0.06])


def _codes(result):
    return {r.code: r.level for r in result.verdict.reasons}


@pytest.fixture(scope="module")
def clean():
    return _samples(30, 1, X_EC)


def test_noise_limit_is_per_axis_in_the_units_given(clean):
    # Camera noise 0.3 mm per axis drawn: a limit of 0.6 mm passes, 0.15 mm fails; likewise
    # 0.05° against 0.1° and 0.025°.
    X_BE, X_CT = clean
    assert _solve(X_BE, X_CT, max_noise_deg=0.1, max_noise_mm=0.6).verdict.status == "OK"
    r = _solve(X_BE, X_CT, max_noise_deg=0.1, max_noise_mm=0.15)
    assert _codes(r).get("residuals") == "FAIL", r.verdict
    r = _solve(X_BE, X_CT, max_noise_deg=0.025, max_noise_mm=0.6)
    assert _codes(r).get("residuals") == "FAIL", r.verdict


@pytest.mark.parametrize("distance,fails", [(0.3, False), (0.7, True)])
def test_plausible_hand_eye_distance_is_half_a_metre_eye_in_hand(distance, fails):
    X = make_transform(X_EC[:3, :3], X_EC[:3, 3] / np.linalg.norm(X_EC[:3, 3]) * distance)
    r = _solve(*_samples(30, 2, X))
    assert np.linalg.norm(r.X_hand[:3, 3]) == pytest.approx(distance, abs=0.01)
    assert ("implausible_result" in _codes(r)) == fails, r.verdict
    if not fails:
        assert r.verdict.status == "OK", r.verdict


@pytest.mark.parametrize("planted,level", [(2, None), (5, "WARN")])
def test_outlier_fractions(planted, level):
    # 30 samples: 2 outliers (7 %) are tolerated, 5 (17 % > 10 %) warn.
    X_BE, X_CT = _samples(30, 3, X_EC)
    X_CT = X_CT.copy()
    rng = np.random.default_rng(0)
    for k in rng.choice(30, planted, replace=False):
        X_CT[k] = X_CT[k] @ make_transform(rotation_exp(rng.normal(size=3) * 0.05),
                                           rng.normal(size=3) * 0.02)
    r = _solve(X_BE, X_CT)
    assert int(np.sum(r.sample_used == "outlier")) == planted
    assert _codes(r).get("outliers") == level, r.verdict


@pytest.mark.parametrize("n", [9, 14])
def test_fewest_samples_warns_under_eight_fitted(n):
    r = _solve(*_samples(n, 4, X_EC))
    n_fit = int(np.sum(r.sample_used == "fit"))
    assert ("too_few_samples" in _codes(r)) == (n_fit < 8), (n_fit, r.verdict)


def test_held_out_test_needs_three_held_out_samples():
    X_BE, X_CT = _samples(30, 5, X_EC)
    for frac, n_expected in ((0.07, 2), (0.1, 3)):
        r = _solve(X_BE, X_CT, holdout_fraction=frac)
        n_h = int(np.sum(r.sample_used == "held_out"))
        assert n_h == n_expected
        assert (held_out_test(r) is None) == (n_h < 3)


def test_split_half_bound_is_the_chi2_6_quantile(clean):
    r = _solve(*clean)
    assert r.split is not None
    assert r.split.threshold == pytest.approx(chi2.ppf(0.999, 6))
    assert r.split.consistent == (r.split.nees <= r.split.threshold)


def test_outlier_threshold_is_the_chi2_6_quantile():
    # Camera noise 0.3 mm per axis: a sample 3 mm off along one axis (whitened residual² ≈ 100,
    # over χ²₆'s 1 − 10⁻⁶ quantile 38) is an outlier; one 1.2 mm off (≈ 16 + 6) is not.
    X_BE, X_CT = _samples(30, 6, X_EC)
    X_CT = X_CT.copy()
    X_CT[7, 0, 3] += 0.003
    X_CT[19, 1, 3] += 0.0012
    r = _solve(X_BE, X_CT)
    assert list(np.flatnonzero(r.sample_used == "outlier")) == [7], r.sample_used


def test_residual_summary_and_noise_in_their_units(clean):
    # Recomputed here: the angle (deg) and distance (m) between each measured X_CT and the
    # model's X_EC⁻¹ X_BE⁻¹ X_BT; the summary of the fitted samples is their median, RMS, max.
    X_BE, X_CT = clean
    r = _solve(X_BE, X_CT)
    doc = r.to_json()
    pred = np.linalg.inv(r.X_hand)[None] @ np.linalg.inv(X_BE) @ r.X_fixed[None]
    R_err = np.transpose(pred[:, :3, :3], (0, 2, 1)) @ X_CT[:, :3, :3]
    deg = np.degrees(np.arccos(np.clip((np.trace(R_err, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    m = np.linalg.norm(X_CT[:, :3, 3] - pred[:, :3, 3], axis=1)
    fit = np.asarray(r.sample_used) == "fit"
    s = doc["residuals"]["fit"]
    assert s["count"] == fit.sum()
    for key, v in (("rotation_deg", deg[fit]), ("translation_m", m[fit])):
        assert s[key]["median"] == pytest.approx(np.median(v), rel=1e-6)
        assert s[key]["rms"] == pytest.approx(np.sqrt(np.mean(v ** 2)), rel=1e-6)
        assert s[key]["max"] == pytest.approx(np.max(v), rel=1e-6)
    # The camera noise drawn: 0.05° and 0.3 mm per axis (estimates within 30 %).
    n = doc["noise_per_axis"]
    assert 0.035 < n["rotation_deg"] < 0.065 and 0.21e-3 < n["translation_m"] < 0.39e-3, n
    assert np.all((np.array(n["rotation_deg_xyz"]) > 0.03) & (np.array(n["rotation_deg_xyz"]) < 0.07))


def test_candidate_poses_visited_within_the_given_distance_and_angle():
    from handeye_drake.calibration.session import CandidatePoses
    cands, _ = _samples(3, 8, X_EC)
    p = CandidatePoses(cands, X_EC, X_BT, visited_deg=0.5, visited_m=0.002)
    near = [make_transform(rotation_exp(np.array([0.0, 0.0, math.radians(0.3)])) @ C[:3, :3],
                           C[:3, 3] + [0.0012, 0.0, 0.0]) for C in cands]
    assert p(near) is None                     # every candidate within 2 mm and 0.5°: visited
    far_t = make_transform(cands[1][:3, :3], cands[1][:3, 3] + [0.0, 0.003, 0.0])
    far_r = make_transform(rotation_exp(np.array([math.radians(0.7), 0.0, 0.0]))
                           @ cands[1][:3, :3], cands[1][:3, 3])
    for other in (far_t, far_r):
        assert p([near[0], near[2], other])["index"] == 1

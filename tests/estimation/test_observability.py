"""Observability analysis and partial calibration (``estimation.observability``): the Fisher
information against the ML covariance, plain-words reports on SCARA-like, general and
near-degenerate recordings (eye-in-hand and eye-to-hand), the partial ML fit with fixed
components (consistency over seeded runs), and the ``--fix`` parser."""

import math

from tests.fixtures import tangent_error
import numpy as np
import pytest
from scipy.stats import chi2

from handeye_drake.estimation import ml
from handeye_drake.estimation import observability as ob
from handeye_drake.estimation.manifold import retract_pose
from handeye_drake.estimation.se3 import (inverse, make_transform, rotation_exp,
                                          rotation_from_rpy, rpy)
from handeye_drake.vision.camera_model import apply_pose_noise

X_EC = make_transform(rotation_from_rpy(np.radians([1.5, -2.0, 90.0])), [0.045, -0.012, 0.068])
X_CE = inverse(X_EC)
X_BT = make_transform(rotation_exp([math.pi, 0.0, 0.3]), [0.5, 0.05, 0.0])
R_DOWN = rotation_exp([math.pi, 0.0, 0.0])  # flange z pointing down, along −B z
SR, ST = 0.002, 0.001


def scara_poses(rng, K, tilt_deg=0.0):
    """End-effector poses of a SCARA-like robot: every rotation about the base z axis (tilted
    by tilt_deg in a random direction per pose when > 0), translations in x, y, z."""
    out = []
    for _ in range(K):
        axis = np.array([0.0, 0.0, 1.0])
        if tilt_deg:
            d = rng.normal(size=2)
            d /= np.linalg.norm(d)
            s = math.sin(math.radians(tilt_deg))
            axis = np.array([s * d[0], s * d[1], math.cos(math.radians(tilt_deg))])
        out.append(make_transform(rotation_exp(rng.uniform(-1.0, 1.0) * axis) @ R_DOWN,
                                  [0.5, 0.05, 0.45] + rng.uniform(-0.1, 0.1, 3)))
    return out


def general_poses(rng, K):
    return [make_transform(rotation_exp(0.3 * rng.normal(size=3)) @ R_DOWN,
                           [0.5, 0.05, 0.45] + rng.uniform(-0.1, 0.1, 3)) for _ in range(K)]


def measure(rng, X_BE, sr=SR, st=ST, X_CE=X_CE, X_BT=X_BT):
    return [apply_pose_noise(X_CE @ inverse(x) @ X_BT, rng.normal(size=12), "so3", sr, st)
            for x in X_BE]


# ---------------------------------------------------------------------------------------------
# The information matrix.

def test_information_matrix_is_the_inverse_of_the_ml_covariance_at_the_truth():
    rng = np.random.default_rng(0)
    X_BE = general_poses(rng, 8)
    exact = [X_CE @ inverse(x) @ X_BT for x in X_BE]
    r = ml.refine_ml_poses(X_BE, exact, retract_pose(X_CE, [0.02, 0, 0, 0.01, 0, 0]), SR, ST)
    info = ob.information_matrix(X_BE, X_CE, X_BT, SR, ST)
    np.testing.assert_allclose(np.linalg.inv(info), r.full_covariance, rtol=1e-6, atol=1e-18)
    # The hand-eye marginal (Schur complement) is the inverse of the X_CE block.
    np.testing.assert_allclose(np.linalg.inv(ob.marginal_information(info)), r.covariance,
                               rtol=1e-6, atol=1e-18)
    # ... and hand_eye_std gives the X_EC standard deviations of the ML result.
    rot, tra = ob.hand_eye_std(info, X_CE)
    np.testing.assert_allclose(rot, r.X_EC_rotation_std_deg, rtol=1e-6)
    np.testing.assert_allclose(tra, r.X_EC_translation_std, rtol=1e-6)
    assert ob.information_matrix([], X_CE, X_BT, SR, ST).shape == (12, 12)


def test_eye_to_hand_is_the_eye_in_hand_model_with_the_robot_pose_inverted():
    rng = np.random.default_rng(1)
    X_BE = general_poses(rng, 6)
    X_CB, X_ET = inverse(X_EC), X_BT  # any two poses: the model is symmetric
    a = ob.information_matrix(X_BE, X_CB, X_ET, SR, ST, mode="eye_to_hand")
    b = ob.information_matrix([inverse(x) for x in X_BE], X_CB, X_ET, SR, ST)
    np.testing.assert_allclose(a, b, rtol=1e-12)
    # A noise-free eye-to-hand recording is fitted exactly (fixed={} is the plain ML fit).
    X_BC = make_transform(rotation_exp([2.5, 0.3, -0.2]), [1.2, 0.1, 0.8])
    X_ET = make_transform(rotation_exp([0.1, 0.2, 0.3]), [0.0, 0.02, 0.1])
    X_CT = [inverse(X_BC) @ x @ X_ET for x in X_BE]
    r = ob.refine_ml_poses_fixed(X_BE, X_CT, retract_pose(inverse(X_BC), [0.05, 0, 0, 0.02, 0, 0]),
                                 SR, ST, mode="eye_to_hand")
    np.testing.assert_allclose(r.X_HC, X_BC, atol=1e-9)
    np.testing.assert_allclose(r.X_FT, X_ET, atol=1e-9)
    assert r.frame == "B" and r.cost < 1e-15


# ---------------------------------------------------------------------------------------------
# Reports.

def test_scara_recording_reports_translation_along_z_unobservable():
    rng = np.random.default_rng(2)
    X_BE = scara_poses(rng, 20)
    rep = ob.observability_report(X_BE, X_CE, X_BT, SR, ST)
    assert not rep.observable and not rep.ok
    (d,) = rep.unobservable
    assert d.kind == "translation" and d.name == "translation along E z"
    assert abs(d.translation_axis[2]) > 1 - 1e-9
    assert rep.translation_std[2] == math.inf and rep.condition_number == math.inf
    assert np.all(np.isfinite(rep.translation_std[:2])) and np.all(rep.translation_std[:2] < 1e-3)
    assert np.all(np.isfinite(rep.rotation_std_deg)) and np.all(rep.rotation_std_deg < 0.2)
    assert rep.messages[0] == (
        "translation along the rotation axis (E z) is unobservable: every rotation is about "
        "parallel axes — typical of 4-DOF/SCARA robots (axis spread 0.00° about E z)")
    assert rep.suggested_fixes() == ["tz"] and "--fix tz=VALUE" in rep.messages[1]
    assert rep.motion.parallel_axes and rep.motion.axis_condition_number == math.inf
    assert rep.to_dict()["translation_std_m"][2] is None
    assert "unobservable" in rep.summary()


def test_scara_eye_to_hand_names_the_base_axis():
    rng = np.random.default_rng(3)
    X_BE = scara_poses(rng, 15)
    X_CB = make_transform(rotation_exp([2.6, 0.0, 0.4]), [0.1, -0.2, 1.1])
    rep = ob.observability_report(X_BE, X_CB, make_transform(np.eye(3), [0, 0, 0.05]), SR, ST,
                                  mode="eye_to_hand")
    assert [d.name for d in rep.unobservable] == ["translation along B z"]
    assert rep.messages[0].startswith("translation along the rotation axis (B z) is "
                                      "unobservable")


def test_general_recording_reports_everything_observable():
    rng = np.random.default_rng(4)
    rep = ob.observability_report(general_poses(rng, 20), X_CE, X_BT, SR, ST)
    assert rep.ok and rep.messages == [] and rep.suggested_fixes() == []
    assert all(d.status == "ok" for d in rep.directions)
    assert 1.0 <= rep.condition_number < 10.0
    assert rep.motion.axis_spread_deg > 30.0 and rep.motion.axis_condition_number < 2.0
    assert rep.summary().endswith("every direction is well determined")


def test_nearly_parallel_axes_report_a_weak_translation_along_the_axis():
    rng = np.random.default_rng(5)
    rep = ob.observability_report(scara_poses(rng, 20, tilt_deg=2.0), X_CE, X_BT, SR, ST)
    assert rep.observable and not rep.ok
    (d,) = rep.weak
    assert d.name == "translation along E z"
    # σ along z an order of magnitude above x, y (which stay sub-millimetre).
    assert rep.translation_std[2] > 10 * max(rep.translation_std[:2])
    assert 1.0 < rep.motion.axis_spread_deg < 3.0
    assert rep.messages[0].startswith(f"translation along E z is weakly determined (σ "
                                      f"{1000 * d.translation_std:.3g} mm vs ≤ ")
    assert "the rotation axes are nearly parallel" in rep.messages[0]
    # An absolute limit makes more directions weak; a looser ratio none.
    assert not ob.observability_report(scara_poses(rng, 20, 2.0), X_CE, X_BT, SR, ST,
                                       weak_ratio=1000.0).weak


def test_no_rotation_is_named_as_the_cause():
    X_BE = [make_transform(R_DOWN, [0.5 + 0.05 * k, 0.02 * k * k, 0.4]) for k in range(5)]
    rep = ob.observability_report(X_BE, X_CE, X_BT, SR, ST)
    assert len(rep.unobservable) == 3  # the whole camera position on the hand
    assert rep.motion.num_motions == 0
    assert rep.messages[0] == ("the camera position in E (translation along every axis) is "
                               "unobservable: the robot does not rotate between the samples")
    assert rep.suggested_fixes() == ["tx", "ty", "tz"]


def test_recording_observability_works_without_a_hand_eye_estimate():
    """From the samples alone, also when the classical solvers refuse them (parallel axes)."""
    rng = np.random.default_rng(12)
    X_BE = scara_poses(rng, 20)
    rep, X_CH, X_FT = ob.recording_observability(X_BE, measure(rng, X_BE), SR, ST)
    truth = ob.observability_report(X_BE, X_CE, X_BT, SR, ST)
    assert [d.name for d in rep.unobservable] == ["translation along E z"]
    assert rep.messages == truth.messages
    # The observable part of the linearization point is the ML estimate: rotation within 0.5°,
    # and the σ of the other directions within 20 % of those at the truth.
    assert np.degrees(np.linalg.norm(tangent_error(X_CE, X_CH)[:3])) < 0.5
    # Where the data is silent the point stays at the start (zero offset along E z).
    assert abs(inverse(X_CH)[2, 3]) < 0.01
    np.testing.assert_allclose(inverse(X_CH)[:2, 3], X_EC[:2, 3], atol=0.003)
    np.testing.assert_allclose(rep.rotation_std_deg, truth.rotation_std_deg, rtol=0.2)
    np.testing.assert_allclose(rep.translation_std[:2], truth.translation_std[:2], rtol=0.2)
    X_BE = general_poses(rng, 10)
    rep, X_CH, _ = ob.recording_observability(X_BE, measure(rng, X_BE), SR, ST)
    assert rep.ok and np.linalg.norm(tangent_error(X_CE, X_CH)[3:]) < 0.005


def test_analyze_observability_rejects_bad_input():
    info = ob.information_matrix(general_poses(np.random.default_rng(6), 5), X_CE, X_BT, SR, ST)
    with pytest.raises(ValueError, match=r"info: expected shape \(12, 12\)"):
        ob.analyze_observability(info[:6, :6], X_CE)
    bad = info.copy()
    bad[0, 1] += 1.0
    with pytest.raises(ValueError, match="info: an information matrix must be symmetric"):
        ob.analyze_observability(bad, X_CE)
    bad = info.copy()
    bad[3, 3] = np.nan
    with pytest.raises(ValueError, match="info: contains NaN"):
        ob.analyze_observability(bad, X_CE)
    with pytest.raises(ValueError, match="info: .* positive semi-definite"):
        ob.analyze_observability(-info, X_CE)
    with pytest.raises(ValueError, match="mode: expected one of"):
        ob.analyze_observability(info, X_CE, mode="eye_on_hand")
    with pytest.raises(ValueError, match="weak_ratio: must be > 1"):
        ob.analyze_observability(info, X_CE, weak_ratio=1.0)
    with pytest.raises(ValueError, match="X_CH"):
        ob.analyze_observability(info, np.zeros((4, 4)))


# ---------------------------------------------------------------------------------------------
# Partial calibration.

def _nees(r):
    e = tangent_error(X_EC, r.X_HC)
    return float(e @ np.linalg.pinv(r.X_HC_covariance, rcond=1e-10, hermitian=True) @ e)


def test_fixing_tz_on_scara_data_gives_a_consistent_partial_calibration():
    """30 seeded SCARA recordings, tz held at its true value: the other five components are
    estimated within their σ — the NEES (5 degrees of freedom each) lies in the 99 % χ² band."""
    nees = []
    for seed in range(30):
        rng = np.random.default_rng(100 + seed)
        X_BE = scara_poses(rng, 12)
        X_CT = measure(rng, X_BE)
        start = retract_pose(X_CE, np.concatenate([0.03 * rng.normal(size=3),
                                                   0.01 * rng.normal(size=3)]))
        r = ob.refine_ml_poses_fixed(X_BE, X_CT, start, SR, ST, fixed={"tz": X_EC[2, 3]})
        assert r.X_HC[2, 3] == X_EC[2, 3] and r.parameter_std["tz"] == 0.0
        assert np.all(r.X_HC_covariance[5] == 0.0)
        assert np.linalg.matrix_rank(r.X_HC_covariance, tol=1e-14) == 5
        nees.append(_nees(r))
    lo, hi = chi2.ppf([0.005, 0.995], 5 * len(nees))
    assert lo <= sum(nees) <= hi, (sum(nees), lo, hi)
    assert r.dof == 6 * 12 - 11


def test_fixed_fit_without_a_start_handles_parallel_axes():
    rng = np.random.default_rng(7)
    X_BE = scara_poses(rng, 15)
    X_CT = measure(rng, X_BE)
    auto = ob.refine_ml_poses_fixed(X_BE, X_CT, None, SR, ST, fixed="tz=0.068")
    given = ob.refine_ml_poses_fixed(X_BE, X_CT, X_CE, SR, ST, fixed={"tz": 0.068})
    np.testing.assert_allclose(auto.X_HC, given.X_HC, atol=1e-9)
    assert auto.cost == pytest.approx(given.cost, rel=1e-9)
    assert _nees(auto) < chi2.ppf(0.999, 5)


def test_fixing_a_component_that_does_not_help_names_the_one_to_fix():
    rng = np.random.default_rng(8)
    X_BE = scara_poses(rng, 10)
    with pytest.raises(ValueError, match=r"with tx fixed, the free components \(ty, tz, roll, "
                       r"pitch, yaw\) are still not determined by the data: translation along "
                       r"E z is unobservable \(fix tz\)"):
        ob.refine_ml_poses_fixed(X_BE, measure(rng, X_BE), X_CE, SR, ST, fixed={"tx": 0.045})


def test_no_fixed_component_is_the_ordinary_ml_fit():
    rng = np.random.default_rng(9)
    X_BE = general_poses(rng, 10)
    X_CT = measure(rng, X_BE)
    a = ob.refine_ml_poses_fixed(X_BE, X_CT, X_CE, SR, ST)
    b = ml.refine_ml_poses(X_BE, X_CT, X_CE, SR, ST)
    np.testing.assert_allclose(a.X_HC, b.X_EC, atol=1e-10)
    np.testing.assert_allclose(a.X_HC_covariance, b.X_EC_covariance, rtol=1e-6, atol=1e-16)
    np.testing.assert_allclose(a.full_covariance, b.full_covariance, rtol=1e-6, atol=1e-16)
    assert a.cost == pytest.approx(b.cost, rel=1e-9)


def test_fixing_yaw_holds_the_rotation_about_the_flange_z_axis():
    rng = np.random.default_rng(10)
    X_BE = general_poses(rng, 10)
    X_CT = measure(rng, X_BE)
    free = ob.refine_ml_poses_fixed(X_BE, X_CT, X_CE, SR, ST)
    r = ob.refine_ml_poses_fixed(X_BE, X_CT, X_CE, SR, ST, fixed="yaw_deg=90")
    assert rpy(r.X_HC[:3, :3])[2] == pytest.approx(math.pi / 2, abs=1e-12)
    assert r.parameter_std["yaw"] == 0.0
    # With yaw held, δθ = E(rpy) [δroll; δpitch; 0]: the rotation about E z is only the
    # −sin(pitch) δroll that a roll change brings.
    pitch = r.parameters["pitch"]
    assert r.X_HC_rotation_std_deg[2] == pytest.approx(
        abs(math.sin(pitch)) * math.degrees(r.parameter_std["roll"]), rel=1e-6)
    # ... and can only shrink the others.
    assert np.all(r.X_HC_translation_std <= free.X_HC_translation_std * (1 + 1e-9))
    assert r.parameter_std["roll"] <= free.parameter_std["roll"] * (1 + 1e-9)


def test_refine_ml_poses_fixed_rejects_bad_input():
    rng = np.random.default_rng(11)
    X_BE = general_poses(rng, 4)
    X_CT = measure(rng, X_BE)
    with pytest.raises(ValueError, match="at least 3 samples"):
        ob.refine_ml_poses_fixed(X_BE[:2], X_CT[:2], X_CE, SR, ST)
    with pytest.raises(ValueError, match="same length"):
        ob.refine_ml_poses_fixed(X_BE, X_CT[:3], X_CE, SR, ST)
    with pytest.raises(ValueError, match="fixed: unknown component 'tw'"):
        ob.refine_ml_poses_fixed(X_BE, X_CT, X_CE, SR, ST, fixed={"tw": 0.0})
    with pytest.raises(ValueError, match="mode: expected one of"):
        ob.refine_ml_poses_fixed(X_BE, X_CT, X_CE, SR, ST, mode="hand_in_eye")
    with pytest.raises(ValueError, match="rotation_sigma"):
        ob.refine_ml_poses_fixed(X_BE, X_CT, X_CE, -1.0, ST)


# ---------------------------------------------------------------------------------------------
# --fix parsing.

def test_parse_fixed_reads_units_and_names():
    assert ob.parse_fixed("tz=0.052, yaw_deg=90") == {"tz": 0.052, "yaw": math.pi / 2}
    assert ob.parse_fixed("tx_mm=45,roll=0.1,pitch_deg=-2") == pytest.approx(
        {"tx": 0.045, "roll": 0.1, "pitch": math.radians(-2)})


@pytest.mark.parametrize("text, message", [
    ("", "empty item"),
    ("tz=1,,", "empty item"),
    ("tz", "'tz' has no '='"),
    ("tq=1", "unknown component 'tq'; valid names: tx, tx_mm, ty"),
    ("tz_deg=1", "unknown component 'tz_deg'"),
    ("yaw_mm=1", "unknown component 'yaw_mm'"),
    ("tz=abc", "tz='abc': the value is not a number"),
    ("tz=nan", "tz=nan: the value must be finite"),
    ("tz=0.05,tz_mm=50", "tz is given twice"),
    ("tz=52", "--fix: tz=52 m is implausible .* use tz_mm= for millimetres"),
    ("yaw=90", "--fix: yaw=90 rad is beyond ±π; .* use yaw_deg= for degrees"),
    ("pitch_deg=90,roll=0.1", "gimbal lock"),
])
def test_parse_fixed_errors(text, message):
    with pytest.raises(ValueError, match=message):
        ob.parse_fixed(text)

"""Partial calibration (``observability.refine_ml_poses_fixed``, ``--fix``) with values away
from every symmetry point: each angle and translation component held, alone and in groups,
eye-in-hand and eye-to-hand — the held component comes out at the given value and the others
at the truth (issue 22: a negated held angle passed the only test, yaw = 90°, where
π − v = v)."""

import math

import numpy as np
import pytest

from handeye_drake.estimation import observability as ob
from handeye_drake.estimation.manifold import retract_pose
from handeye_drake.estimation.se3 import (inverse, make_transform, rotation_exp,
                                          rotation_from_rpy, rpy)
from handeye_drake.vision.camera_model import apply_pose_noise
from tests.fixtures import tangent_error

SR, ST = 0.002, 0.001
R_DOWN = rotation_exp([math.pi, 0.0, 0.0])

#: No angle at 0 or ±90°, none the negative or the supplement of another; translations with
#: distinct magnitudes and signs.
TRUTH = {
    "eye_in_hand": dict(rpy_deg=[17.0, -23.0, 80.0], t=[0.045, -0.012, 0.068]),
    "eye_to_hand": dict(rpy_deg=[-140.0, 25.0, -65.0], t=[0.9, -0.2, 0.6]),
}


def _truth(mode):
    d = TRUTH[mode]
    return make_transform(rotation_from_rpy(np.radians(d["rpy_deg"])), d["t"])


def _recording(mode, rng, K=12, noise=False):
    """Robot poses X_BE, camera poses X_CT (exact or noisy) and the truth X_HC, X_FT."""
    X_HC = _truth(mode)
    X_FT = make_transform(rotation_exp([math.pi, 0.0, 0.3]), [0.55, 0.05, 0.0]) \
        if mode == "eye_in_hand" else make_transform(rotation_exp([0.1, -0.2, 0.3]),
                                                     [0.02, 0.01, 0.08])
    X_BE = [make_transform(rotation_exp(0.4 * rng.normal(size=3)) @ R_DOWN,
                           [0.5, 0.05, 0.45] + rng.uniform(-0.1, 0.1, 3)) for _ in range(K)]
    Y = [inverse(x) for x in X_BE] if mode == "eye_in_hand" else X_BE
    X_CT = [inverse(X_HC) @ y @ X_FT for y in Y]
    if noise:
        X_CT = [apply_pose_noise(x, rng.normal(size=12), "so3", SR, ST) for x in X_CT]
    return X_BE, X_CT, X_HC, X_FT


def _values(X_HC):
    return dict(zip(ob.COMPONENTS, [*X_HC[:3, 3], *rpy(X_HC[:3, :3])]))


def test_the_truth_is_away_from_the_symmetry_points():
    for mode in TRUTH:
        v = _values(_truth(mode))
        np.testing.assert_allclose(np.degrees([v["roll"], v["pitch"], v["yaw"]]),
                                   TRUTH[mode]["rpy_deg"], atol=1e-9)
        for c in ("roll", "pitch", "yaw"):
            a = v[c]
            assert min(abs(a), abs(abs(a) - math.pi / 2), abs(abs(a) - math.pi)) > 0.15
            assert abs(math.pi - abs(a) - abs(a)) > 0.3     # π − v ≠ ±v (by ≥ 17°)
        assert len({round(abs(v[c]), 6) for c in ("tx", "ty", "tz")}) == 3


HELD = [("tx",), ("ty",), ("tz",), ("roll",), ("pitch",), ("yaw",), ("roll", "pitch", "yaw"),
        ("tx", "ty", "tz"), ("pitch", "tz"), ("roll", "yaw", "tx")]


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
@pytest.mark.parametrize("held", HELD, ids=lambda h: "+".join(h))
def test_held_components_come_out_at_the_given_values_and_the_rest_at_the_truth(mode, held):
    """Exact data, a start 3° / 2 cm off: the held components equal the given values to 1e-12,
    the free ones are the truth (1e-7), the fit is exact and the held σ are zero."""
    rng = np.random.default_rng(20 + len(held))
    X_BE, X_CT, X_HC, X_FT = _recording(mode, rng)
    truth = _values(X_HC)
    start = retract_pose(inverse(X_HC), [0.03, -0.04, 0.02, 0.02, -0.01, 0.015])
    fixed = {c: truth[c] for c in held}
    r = ob.refine_ml_poses_fixed(X_BE, X_CT, start, SR, ST, fixed=fixed, mode=mode)
    for c in held:
        assert r.parameters[c] == pytest.approx(truth[c], abs=1e-12), c
        assert r.parameter_std[c] == 0.0
    for c in ob.COMPONENTS:
        assert r.parameters[c] == pytest.approx(truth[c], abs=1e-7), c
    np.testing.assert_allclose(r.X_HC, X_HC, atol=1e-7)
    np.testing.assert_allclose(r.X_FT, X_FT, atol=1e-7)
    assert r.cost < 1e-12
    assert all(r.parameter_std[c] > 0 for c in ob.COMPONENTS if c not in held)


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
def test_a_held_angle_off_the_truth_is_kept_at_the_given_value(mode):
    """yaw held 2° off the truth (noisy data, no start given): yaw comes out at the given value
    (not at −v or π − v), and roll / pitch stay within a few degrees of the truth."""
    rng = np.random.default_rng(31)
    X_BE, X_CT, X_HC, _ = _recording(mode, rng, K=15, noise=True)
    truth = _values(X_HC)
    given = truth["yaw"] + math.radians(2.0)
    r = ob.refine_ml_poses_fixed(X_BE, X_CT, None, SR, ST, fixed={"yaw": given}, mode=mode)
    assert r.parameters["yaw"] == pytest.approx(given, abs=1e-12)
    assert rpy(r.X_HC[:3, :3])[2] == pytest.approx(given, abs=1e-9)
    for c in ("roll", "pitch"):
        assert abs(r.parameters[c] - truth[c]) < math.radians(3.0), c
    # The free fit lands at the truth within its σ; holding yaw wrong moves the rotation about
    # H z by the 2° (not by 160° or 180° − 2 yaw).
    assert 1.5 < np.degrees(abs(tangent_error(X_HC, r.X_HC)[2])) < 2.5


def test_parse_fixed_reads_non_symmetric_values_with_their_sign():
    v = ob.parse_fixed("tx_mm=45,ty=-0.012,tz_mm=68,roll_deg=17,pitch_deg=-23,yaw_deg=80")
    assert v == pytest.approx({"tx": 0.045, "ty": -0.012, "tz": 0.068,
                               "roll": math.radians(17), "pitch": math.radians(-23),
                               "yaw": math.radians(80)}, abs=1e-15)
    assert ob.parse_fixed("yaw_deg=-100") == pytest.approx({"yaw": math.radians(-100)})


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
@pytest.mark.parametrize("held", [(), ("tz",), ("yaw",)], ids=lambda h: "+".join(h) or "none")
def test_parameter_std_is_the_propagated_covariance(mode, held):
    """The σ of roll, pitch, yaw: E⁻¹ C E⁻ᵀ of the rotation covariance (δθ = E d(r, p, y),
    R = Rz(y) Ry(p) Rx(r)), E written out here; translations: √diag; held ones 0."""
    rng = np.random.default_rng(33)
    X_BE, X_CT, X_HC, _ = _recording(mode, rng, K=12, noise=True)
    truth = _values(X_HC)
    r = ob.refine_ml_poses_fixed(X_BE, X_CT, inverse(X_HC), SR, ST, mode=mode,
                                 fixed={c: truth[c] for c in held})
    roll, pitch, yaw = (r.parameters[c] for c in ("roll", "pitch", "yaw"))
    E = np.array([[math.cos(yaw) * math.cos(pitch), -math.sin(yaw), 0.0],
                  [math.sin(yaw) * math.cos(pitch), math.cos(yaw), 0.0],
                  [-math.sin(pitch), 0.0, 1.0]])
    C = r.X_HC_covariance
    Ei = np.linalg.inv(E)
    expected = np.sqrt(np.maximum(np.diag(Ei @ C[:3, :3] @ Ei.T), 0.0))
    for c, v in zip(("roll", "pitch", "yaw"), expected):
        assert r.parameter_std[c] == pytest.approx(0.0 if c in held else v, rel=1e-9,
                                                   abs=1e-12), c
    for i, c in enumerate(("tx", "ty", "tz")):
        assert r.parameter_std[c] == pytest.approx(
            0.0 if c in held else math.sqrt(C[3 + i, 3 + i]), rel=1e-12), c
    if "yaw" in held:  # the held angle really is held in the covariance, not only in the report
        assert expected[2] < 1e-6 * expected[:2].max()

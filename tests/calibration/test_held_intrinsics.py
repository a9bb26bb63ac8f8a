"""Issue 37, family 2: a restricted intrinsics model must not hide the errors of what it holds
fixed. For each restricted model × each parameter it holds, a realistic wrong value (drawn per
case: a principal point 20–35 px off, a focal length 2.5–4 % off, a distortion of the wrong
sign, a tangential term 0.003–0.006 off) on small synthetic corner sets: never OK with an answer
outside its σ, and the named cause is the parameter that was wrong."""

import zlib

import numpy as np
import pytest

from handeye_drake import rotation_error_deg
from handeye_drake.calibration import CalibrationOptions, solve
from handeye_drake.calibration.held_intrinsics import held_parameters
from handeye_drake.estimation.se3 import rotation_log
from tests.corner_synth import TRUTH, corner_streams

NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
#: √NEES of the truth beyond which an answer is outside its σ (√ of χ²(6)'s 0.999 quantile).
OUTSIDE = 4.7


def _wrong(kind, rng):
    """(perturbed intrinsics, the parameter(s) made wrong)."""
    v = TRUTH.copy()
    sign = rng.choice([-1.0, 1.0])
    if kind == "focal":
        v[:2] *= 1 + sign * rng.uniform(0.025, 0.04)
        return v, ("fx", "fy")
    if kind in ("cx", "cy"):
        v[NAMES.index(kind)] += sign * rng.uniform(20, 35)
        return v, (kind,)
    if kind == "k1flip":
        v[4:6] = -v[4:6]
        return v, ("k1", "k2")
    v[NAMES.index(kind)] += sign * rng.uniform(0.003, 0.006)
    return v, (kind,)


#: Each restricted model with perturbations of parameters it holds fixed: every kind of wrong
#: value in some model, every model with some (the full matrix × seeds, with the table of
#: verdicts: ``benchmarks/held_intrinsics.py``).
CASES = [("none", "focal"), ("none", "cy"), ("none", "p1"), ("focal", "cx"),
         ("focal", "k1flip"), ("focal", "p2"), ("pinhole", "p1"), ("k1k2", "p2")]


def _run(model, given, mode="eye_in_hand", seed=0):
    streams, truth = corner_streams(given, mode, n=11, seed=seed)
    result = solve(streams, CalibrationOptions(mode=mode, refine_intrinsics=model))
    X, T = result.X_hand, truth["X_hand"]
    d = np.concatenate([rotation_log(T[:3, :3] @ X[:3, :3].T), T[:3, 3] - X[:3, 3]])
    nees = float(d @ np.linalg.solve(result.covariance, d))
    return result, np.sqrt(nees), rotation_error_deg(T, X), np.linalg.norm(d[3:])


@pytest.mark.parametrize("model, kind", CASES)
def test_a_wrong_held_intrinsic_is_never_ok_and_is_named(model, kind):
    rng = np.random.default_rng(zlib.crc32(f"{model}-{kind}".encode()))
    given, wrong = _wrong(kind, rng)
    assert set(wrong) & set(held_parameters(model, given)), "the case must perturb a held one"
    result, sig, deg, m = _run(model, given, seed=int(rng.integers(1000)))
    status = result.verdict.status
    assert not (status == "OK" and sig > OUTSIDE), (status, sig, deg, m)
    assert status != "OK", (model, kind, sig)
    reasons = result.verdict.reasons
    assert reasons[0].code == "intrinsics", [(r.code, r.message) for r in reasons]
    test = result.corners.held
    named = [n["name"] for n in test["named"]]
    assert named and set(named) <= set(wrong) | {"fx", "fy"} & set(wrong), (named, wrong)
    assert named[0] in wrong and named[0] in reasons[0].message
    # The released value is back near the truth (within 5σ or 2 % of the error made).
    for n in test["named"]:
        i = NAMES.index(n["name"])
        assert abs(n["released"] - TRUTH[i]) < max(5 * n["std"], 0.1 * abs(given[i] - TRUTH[i]))
    if sig > OUTSIDE:
        assert status == "FAIL" or test["move_sigmas"] > 3, (status, sig, test)


@pytest.mark.parametrize("seed, model", list(enumerate(["none", "focal", "pinhole", "k1k2"])))
def test_intrinsics_given_right_pass_the_held_test(seed, model):
    result, sig, _, _ = _run(model, TRUTH, seed=seed)
    assert result.verdict.status == "OK", result.verdict
    assert sig < OUTSIDE
    test = result.corners.held
    assert not test["contradicted"] and test["statistic"] < test["bound"]


@pytest.mark.parametrize("model, kind", [("focal", "cy")])
def test_eye_to_hand_too(model, kind):
    given, wrong = _wrong(kind, np.random.default_rng(5))
    result, sig, _, _ = _run(model, given, "eye_to_hand", seed=3)
    assert result.verdict.status != "OK"
    assert result.corners.held["named"][0]["name"] in wrong

"""``FeasiblePlanner.check``'s view bounds on poses that did not come out of its IK: at the home
configuration the target is placed (through X_BT) where this test wants it relative to the
camera — a tilt, an angle off the optical axis, a distance, a pixel position computed here with
the pinhole model — once inside each bound and once outside."""

import math

import numpy as np
import pytest

from handeye_drake.estimation.se3 import make_transform, rotation_exp
from handeye_drake.planning import FeasiblePlanner, ViewSpec
from handeye_drake.planning.feasible import UR5E_HOME_Q
from handeye_drake.vision.camera_model import CameraIntrinsics

X_EC = make_transform(rotation_exp(np.array([0.0, 0.0, math.pi / 2])), [0.0, -0.05, 0.04])
K = CameraIntrinsics(alpha_u=800, alpha_v=800, u0=320, v0=240, width=640, height=480)
VIEW = dict(distance_range_m=(0.3, 0.6), max_tilt_deg=35.0, cone_half_angle_deg=10.0)


@pytest.fixture(scope="module")
def X_BC_home():
    p = FeasiblePlanner("eye_in_hand", X_EC, np.eye(4))
    return p.X_BE(UR5E_HOME_Q) @ X_EC


def _check(X_BC, X_CT, **view):
    p = FeasiblePlanner("eye_in_hand", X_EC, X_BC @ X_CT, view=ViewSpec(**{**VIEW, **view}))
    return p.check(UR5E_HOME_Q)


def _target(distance=0.45, off_deg=0.0, tilt_deg=0.0):
    """X_CT: the target origin `distance` from C, `off_deg` from z_C (towards x_C), its normal
    z_T `tilt_deg` from z_C."""
    a = math.radians(off_deg)
    p = distance * np.array([math.sin(a), 0.0, math.cos(a)])
    return make_transform(rotation_exp(np.array([math.radians(tilt_deg), 0.0, 0.0])), p)


def _has(f, start):
    return any(r.startswith(start) for r in f.reasons)


@pytest.mark.parametrize("tilt,fails", [(20.0, False), (50.0, True)])
def test_tilt_bound(X_BC_home, tilt, fails):
    f = _check(X_BC_home, _target(tilt_deg=tilt))
    assert f.tilt_deg == pytest.approx(tilt, abs=1e-6)
    assert _has(f, "board tilted") == fails, f.reasons


@pytest.mark.parametrize("off,fails", [(6.0, False), (14.0, True)])
def test_off_axis_cone(X_BC_home, off, fails):
    f = _check(X_BC_home, _target(off_deg=off))
    assert f.off_axis_deg == pytest.approx(off, abs=1e-6)
    assert any("off the optical axis" in r for r in f.reasons) == fails, f.reasons


@pytest.mark.parametrize("distance,fails", [(0.5, False), (0.7, True), (0.25, True)])
def test_distance_range(X_BC_home, distance, fails):
    f = _check(X_BC_home, _target(distance=distance))
    assert f.target_distance_m == pytest.approx(distance, abs=1e-9)
    assert any("outside [0.3, 0.6]" in r for r in f.reasons) == fails, f.reasons


@pytest.mark.parametrize("u,inside", [(10.0, False), (30.0, True), (610.0, True),
                                      (630.0, False)])
def test_image_margin(X_BC_home, u, inside):
    # One target point at pixel (u, 240) by the pinhole model, 20 px margin.
    z = 0.45
    X_CT = make_transform(np.eye(3), [(u - 320) / 800 * z, 0.0, z])
    f = _check(X_BC_home, X_CT, intrinsics=K, margin_px=20.0, cone_half_angle_deg=30.0,
               target_points=np.zeros((1, 3)))
    assert f.in_image == inside
    assert _has(f, "target points outside the image") == (not inside), f.reasons

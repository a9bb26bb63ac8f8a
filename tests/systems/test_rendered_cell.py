"""RenderedHandCell: one frame rendered and detected per observe, X_CT close to the truth."""

import math

import numpy as np
import pytest

from handeye_drake.estimation.se3 import inverse, make_transform, rotation_angle, rotation_exp
from handeye_drake.planning import FeasiblePlanner, ViewSpec
from handeye_drake.systems.rendered_cell import RenderedHandCell
from handeye_drake.vision.camera_model import CameraIntrinsics

K = CameraIntrinsics(alpha_u=800, alpha_v=800, u0=320, v0=240, width=640, height=480)
SPEC = "charuco:8x6:0.025:0.019:DICT_5X5_100"
X_BT = make_transform(rotation_exp(np.array([math.pi, 0.0, 0.0])), [-0.45, -0.15, 0.0])
X_EC = make_transform(rotation_exp(np.array([0.0, 0.0, math.pi / 2])), [0.04, -0.03, 0.06])


@pytest.fixture(scope="module")
def views():
    board = np.array([[x, y, 0.0] for x in (0, 0.2) for y in (0, 0.15)])
    planner = FeasiblePlanner("eye_in_hand", X_EC, X_BT, view=ViewSpec(
        distance_range_m=(0.35, 0.6), max_tilt_deg=30, intrinsics=K, target_points=board,
        margin_px=40), min_distance_m=0.01, seed=3)
    return planner, planner.sample_candidates(2)


def test_observe_renders_one_frame_and_measures_X_CT(views):
    planner, pool = views
    cell = RenderedHandCell(SPEC, K, X_EC, X_BT, supersample=2)
    for q in pool.q:
        shot = cell.observe(q)
        assert np.allclose(shot.X_BE, planner.X_BE(q), atol=1e-9)
        assert np.allclose(shot.X_CT_true, inverse(shot.X_BE @ X_EC) @ X_BT)
        assert shot.found, shot.detection.reason
        assert len(shot.detection.ids) == 35
        E = inverse(shot.X_CT_true) @ shot.X_CT
        assert math.degrees(rotation_angle(E[:3, :3])) < 0.5
        assert np.linalg.norm(E[:3, 3]) < 0.002
    assert cell.frames == len(pool.q)


def test_no_board_in_view_is_not_found(views):
    _, pool = views
    cell = RenderedHandCell(SPEC, K, X_EC, X_BT)
    q = pool.q[0].copy()
    q[0] += math.pi / 2        # the shoulder turned a quarter: the camera looks elsewhere
    shot = cell.observe(q)
    assert not shot.found and shot.X_CT is None
    assert shot.detection is not None and shot.detection.reason
    assert cell.frames == 1


def test_bad_mount_is_one_line_error():
    with pytest.raises(ValueError, match="X_EC"):
        RenderedHandCell(SPEC, K, np.eye(3), X_BT)

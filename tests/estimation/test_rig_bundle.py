"""The joint corner-level fit of a rig (``estimation.rig_bundle``) on synthetic corners: two cell
cameras watching a board on the flange (eye-to-hand, the board shared) and a hand camera
watching a board in the cell (corners kept wherever they project: no image bounds), fitted in one
problem; answers within σ; a camera whose board no other camera places is refused."""

import math

import numpy as np
import pytest
from scipy.stats import chi2

from handeye_drake.estimation.reprojection import CornerData, project
from handeye_drake.estimation.rig_bundle import (RigBlock, fit_rig, pose_error_frame,
                                                 robot_side, tangent)
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp

BOUND = float(chi2.ppf(0.999, 6))
V = np.array([600.0, 600.0, 320.0, 240.0, -0.1, 0.02, 0.0, 0.0, 0.0])
X_ET = make_transform(rotation_exp([0.1, 0.05, -0.2]), [0.02, -0.03, 0.12])
_R_BT = rotation_exp([0.0, 0.0, 0.3]) @ rotation_exp([math.pi, 0.0, 0.0])
X_BT = make_transform(_R_BT, np.array([0.5, 0.1, 0.0]) - _R_BT @ [0.075, 0.06, 0.0])
X_EC = make_transform(rotation_exp([0.04, -0.05, 1.57]), [0.035, -0.05, 0.07])
GRID = np.array([[x, y, 0.0] for x in np.arange(6) * 0.03 for y in np.arange(5) * 0.03])


def _look_at(p, aim):
    z = np.asarray(aim, float) - p
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, -1.0])
    x /= np.linalg.norm(x)
    return make_transform(np.column_stack([x, np.cross(z, x), z]), p)


def _rig(seed=0, n=12, px=0.2):
    rng = np.random.default_rng(seed)
    centre = np.array([0.5, 0.1, 0.45])
    X_BE = []
    for _ in range(n):
        R = rotation_exp(rng.normal(0, 0.2, 3)) @ rotation_exp([math.pi, 0, 0])
        X_BE.append(make_transform(R, centre + rng.uniform(-0.06, 0.06, 3)))
    X_BE = np.array(X_BE)
    # The board on the flange faces up-ish: the cell cameras look at it from above.
    X_BT_hand = X_BE @ X_ET
    cams = [_look_at(np.array([0.9, 0.5, 1.3]), centre), _look_at(np.array([0.1, 0.6, 1.2]),
                                                                   centre)]
    blocks, truths = [], []
    for c, X_BC in enumerate(cams):
        U, P = [], []
        for X in X_BT_hand:
            X_CT = inverse(X_BC) @ X
            p = GRID @ X_CT[:3, :3].T + X_CT[:3, 3]
            U.append(project(p, V, False)[0] + rng.normal(0, px, (len(GRID), 2)))
            P.append(GRID)
        data = CornerData.from_lists(robot_side("cell", "hand", X_BE), P, U)
        blocks.append(RigBlock(c, 0, data, np.arange(n), pose_error_frame("cell", "hand")))
        truths.append(X_BC)
    # A hand camera watching a second board, in the cell.
    U = []
    for X in X_BE:
        X_CT = inverse(X @ X_EC) @ X_BT
        p = GRID @ X_CT[:3, :3].T + X_CT[:3, 3]
        U.append(project(p, V, False)[0] + rng.normal(0, px, (len(GRID), 2)))
    data = CornerData.from_lists(robot_side("hand", "cell", X_BE), [GRID] * n, U)
    blocks.append(RigBlock(2, 1, data, np.arange(n), pose_error_frame("hand", "cell")))
    truths.append(X_EC)
    return blocks, truths, [X_ET, X_BT]


def _perturb(X, rng, rot=0.01, trans=0.005):
    return make_transform(rotation_exp(rng.normal(0, rot, 3)), rng.normal(0, trans, 3)) @ X


def test_two_cell_cameras_sharing_a_hand_board_and_a_hand_camera_within_sigma():
    blocks, truths, boards = _rig()
    rng = np.random.default_rng(1)
    fit = fit_rig(blocks, [_perturb(X, rng) for X in truths], [_perturb(X, rng) for X in boards],
                  [V] * 3, ["none", "none", "pinhole"], [0.3] * 3)
    for c, X in enumerate(truths):
        e = tangent(fit.X_cameras[c], X)
        assert e @ np.linalg.solve(fit.camera_covariance(c), e) < BOUND, c
        assert np.linalg.norm(e[3:]) < 0.002
    for b, X in enumerate(boards):
        e = tangent(fit.X_boards[b], X)
        assert e @ np.linalg.solve(fit.board_covariance(b), e) < BOUND, b
    X, C = fit.relative(0, 1)
    e = tangent(X, inverse(truths[0]) @ truths[1])
    assert e @ np.linalg.solve(C, e) < BOUND
    # The pixel noise is estimated per camera: 0.2 px given.
    assert all(abs(b.pixel_sigma / 0.2 - 1) < 0.15 for b in fit.blocks)
    assert np.all(np.sqrt(np.diag(fit.intrinsics_covariance(2)))[:4] > 0)


def test_a_fixed_view_alone_does_not_determine_its_camera():
    blocks, truths, boards = _rig(n=6)
    # A cell camera seeing a cell board that no moving camera sees: X_BC and X_BT only appear
    # as X_BC⁻¹ X_BT.
    d = blocks[2].data
    fixed = RigBlock(0, 0, CornerData(np.repeat(np.eye(4)[None], d.num_images, 0), d.image,
                                      d.object_points, d.image_points), np.arange(6),
                     "camera", fixed_view=True)
    with pytest.raises(ValueError, match="do not determine"):
        fit_rig([fixed], [truths[0]], [boards[1]], [V])

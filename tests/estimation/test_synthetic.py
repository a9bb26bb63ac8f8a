"""Synthetic data (``estimation.synthetic``)."""

import numpy as np

from handeye_drake import orthonormalize
from handeye_drake.estimation import synthetic
from handeye_drake.estimation.se3 import inverse, make_transform
from handeye_drake.estimation.validation import rotation_defect


def test_pose_chain_reproduces_the_motions_and_outliers_are_injected():
    rng = np.random.default_rng(14)
    X_CE, A, B = synthetic.paper_motions(rng, 0.05, 0.1, 12)
    assert len(A) == len(B) == 12
    assert max(rotation_defect(a[:3, :3]) for a in A) > 1e-2  # paper noise: not orthonormal
    A_rigid = [make_transform(orthonormalize(a[:3, :3]), a[:3, 3]) for a in A]
    X_BE, X_CT = synthetic.chain_poses(A_rigid, B)
    for k in range(12):
        np.testing.assert_allclose(X_CT[k] @ inverse(X_CT[k + 1]), A_rigid[k], atol=1e-10)
        np.testing.assert_allclose(inverse(X_BE[k]) @ X_BE[k + 1], B[k], atol=1e-10)
    X_CT_bad, idx = synthetic.inject_wrong_poses(X_CT, 0.25, rng)
    assert len(idx) == 3 and 0 not in idx  # round(0.25 · 13)
    changed = [k for k in range(13) if not np.allclose(X_CT_bad[k], X_CT[k])]
    assert changed == sorted(idx.tolist())

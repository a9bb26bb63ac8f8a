import numpy as np
import pytest

from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp


def random_pose(rng, rotation_scale=np.pi, translation_scale=1.0):
    return make_transform(rotation_exp(rng.normal(size=3) * rotation_scale / 2),
                          rng.normal(size=3) * translation_scale)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def simulate_poses(rng, X_EC, n, rotation_scale=0.5, translation_scale=0.3):
    """Robot poses X_BE and exact target-in-camera poses X_CT for a fixed target X_BT."""
    X_BT = make_transform(rotation_exp(rng.normal(size=3)), [0.8, 0.1, 0.2])
    X_BE = [random_pose(rng, rotation_scale, translation_scale) for _ in range(n)]
    X_CT = [inverse(X @ X_EC) @ X_BT for X in X_BE]
    return X_BE, X_CT

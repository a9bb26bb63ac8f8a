import os

import numpy as np
import pytest
from hypothesis import settings

# The property-based tests run the same examples on every run (a red CI is then a real
# regression, not a new random draw); HYPOTHESIS_PROFILE=explore draws new ones.
settings.register_profile("repeatable", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))


@pytest.fixture
def rng():
    return np.random.default_rng(12345)

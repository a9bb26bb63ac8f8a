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


# The suite must leave the working tree as it found it (no file written outside tmp_path): the
# state of `git status` before and after, compared when the session ends.
def _tree_state(root):
    """`git status` lines, and every path under the ignored ``out/`` (where the commands write
    by default: a test must not leave anything there either)."""
    import subprocess
    from pathlib import Path
    try:
        out = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=root,
                             capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.SubprocessError):
        return None
    if out.returncode != 0:
        return None
    default_out = Path(root) / "out"
    extra = sorted(f"out: {p.relative_to(root)}" for p in default_out.rglob("*")) \
        if default_out.is_dir() else []
    return out.stdout + "".join(line + "\n" for line in extra)


def pytest_sessionstart(session):
    session.config._tree_before = _tree_state(session.config.rootpath)


def pytest_sessionfinish(session, exitstatus):
    before = getattr(session.config, "_tree_before", None)
    after = _tree_state(session.config.rootpath)
    if before is None or after is None or before == after:
        return
    new = sorted(set(after.splitlines()) - set(before.splitlines()))
    print("\nthe test session changed the working tree:\n  " + "\n  ".join(new[:20]))
    session.exitstatus = 1

"""The README's code runs and says what it claims."""

import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parent.parent / "README.md"


def test_readme_core_example_runs_and_is_accurate():
    text = README.read_text()
    section = text[text.index("## Using the estimation core"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    namespace = {}
    exec(compile(code, "README.md", "exec"), namespace)
    he, X_true = namespace["he"], namespace["X_EC_true"]
    assert he.rotation_error_deg(X_true, namespace["X_EC"]) < 0.2
    assert he.rotation_error_deg(X_true, namespace["kf"].X_EC) < 0.5
    f = namespace["f"]
    assert he.rotation_error_deg(X_true, f.X_EC) < 0.1
    assert np.linalg.norm(X_true[:3, 3] - f.X_EC[:3, 3]) < 2e-3
    assert np.all(f.X_EC_rotation_std_deg > 0) and np.all(f.X_EC_rotation_std_deg < 0.1)

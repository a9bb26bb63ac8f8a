"""Every benchmark and diagram script imports (their imports break silently otherwise: they are
run by hand, not by the suite). Importing runs nothing: each has a ``__main__`` guard."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCRIPTS = sorted((ROOT / "benchmarks").glob("*.py")) + sorted((ROOT / "diagrams").glob("*.py"))


@pytest.mark.parametrize("path", SCRIPTS, ids=[f"{p.parent.name}/{p.name}" for p in SCRIPTS])
def test_script_imports(path):
    assert '__name__ == "__main__"' in path.read_text()
    spec = importlib.util.spec_from_file_location(f"_script_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.__name__ == f"_script_{path.stem}"

"""Mutation testing of estimation/ and calibration/ on a budget (``make mutation``; docs/testing.md).

For each module of ``GROUPS`` cosmic-ray enumerates its one-line mutants (operators swapped,
comparisons inverted, numbers changed, booleans flipped, loops skipped); a seeded random sample
of ``--per-module`` of them is run against the module's own test files, each mutant in a copy of
the package (``--out``/tree: the working tree is never mutated), until ``--budget-min`` is
spent. A mutant is *killed* when a test fails (or times out), *survives* when every test
passes. Prints per-module counts, the score killed / (killed + survived) and the diff of every
survivor; writes them to ``--out``/report.txt and report.json.

    python tools/mutation.py [--per-module 6] [--budget-min 25] [--seed 0] [--only reprojection]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: module → the test files that guard it (fast ones: each mutant runs them once).
GROUPS = {
    "handeye_drake/estimation/reprojection.py": [
        "tests/estimation/test_guards_cross_validation.py", "tests/estimation/test_reprojection.py"],
    "handeye_drake/estimation/ml.py": [
        "tests/estimation/test_ml.py", "tests/estimation/test_ml_anisotropic.py"],
    "handeye_drake/estimation/se3.py": [
        "tests/estimation/test_manifold.py", "tests/estimation/test_ml.py"],
    "handeye_drake/estimation/manifold.py": ["tests/estimation/test_manifold.py"],
    "handeye_drake/estimation/observability.py": [
        "tests/estimation/test_observability.py", "tests/estimation/test_observability_values.py"],
    "handeye_drake/estimation/planning.py": [
        "tests/estimation/test_planning.py", "tests/estimation/test_planning_exchange.py"],
    "handeye_drake/calibration/checks.py": [
        "tests/calibration/test_guards_statistics.py", "tests/calibration/test_guards_units.py"],
    "handeye_drake/calibration/task_space.py": ["tests/calibration/test_guards_statistics.py"],
    "handeye_drake/calibration/session.py": [
        "tests/calibration/test_guards_statistics.py", "tests/calibration/test_session.py"],
    "handeye_drake/calibration/corners.py": ["tests/apps/test_guards_images.py"],
}

#: Operators left out: bitwise and identity replacements (mostly crash at once or mean nothing
#: on floats), variable insertion/replacement and decorator removal (numba's @njit).
EXCLUDED_OPERATORS = [r".*_(BitOr|BitAnd|BitXor|LShift|RShift|FloorDiv|Mod|Is|IsNot|Invert)$",
                      r"core/Variable.*", r"core/RemoveDecorator"]


def _pytest(basetemp: Path, tests: list[str]) -> list[str]:
    # A private --basetemp: pytest prunes the shared /tmp/pytest-of-USER directories, and a
    # concurrent pytest run would otherwise fail a mutant's run at its end (a false kill).
    return [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider",
            f"--basetemp={basetemp}", *tests]


def _config(module: str, tests: list[str], timeout: float, basetemp: Path) -> str:
    command = " ".join(_pytest(basetemp, tests))
    ops = ", ".join(json.dumps(e) for e in EXCLUDED_OPERATORS)
    return (f'[cosmic-ray]\nmodule-path = "{module}"\ntimeout = {timeout:.0f}\n'
            f'excluded-modules = []\ntest-command = "{command}"\n\n'
            f'[cosmic-ray.distributor]\nname = "local"\n\n'
            f'[cosmic-ray.filters.operators-filter]\nexclude-operators = [{ops}]\n')


def _copy_tree(dest: Path) -> None:
    if dest.exists():
        shutil.rmtree(dest)
    dest.mkdir(parents=True)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", ".pytest_cache")
    for name in ("handeye_drake", "tests"):
        shutil.copytree(ROOT / name, dest / name, ignore=ignore)
    shutil.copy(ROOT / "pyproject.toml", dest / "pyproject.toml")


def _run(cmd, cwd, env, timeout=None):
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--per-module", type=int, default=6, help="mutants sampled per module")
    ap.add_argument("--budget-min", type=float, default=25.0,
                    help="stop starting mutants after this many minutes")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", default="", help="run only modules whose path contains this")
    ap.add_argument("--out", default=str(ROOT / "out" / "mutation"))
    args = ap.parse_args(argv)
    try:
        from cosmic_ray.work_db import WorkDB, use_db
        from cosmic_ray.work_item import WorkerOutcome, WorkResult
    except ImportError:
        print("cosmic-ray is not installed: pip install -e '.[mutation]' (make mutation does)",
              file=sys.stderr)
        return 2
    out = Path(args.out).resolve()
    tree = out / "tree"
    _copy_tree(tree)
    env = dict(os.environ, PYTHONPATH=str(tree), OPENBLAS_NUM_THREADS="1",
               PYTHONDONTWRITEBYTECODE="1")
    cr = [sys.executable, "-m", "cosmic_ray.cli"]
    start = time.monotonic()
    deadline = start + 60.0 * args.budget_min
    rows, survivors = [], []
    groups = {m: t for m, t in GROUPS.items() if args.only in m}
    for module, tests in groups.items():
        name = Path(module).stem
        missing = [t for t in tests if not (tree / t).exists()]
        if missing:
            print(f"{name}: skipped, missing {missing}")
            continue
        # The unmutated tests must pass; their time sets the per-mutant timeout.
        t0 = time.monotonic()
        base = _run(_pytest(out / "pytest-tmp", tests), tree, env)
        base_s = time.monotonic() - t0
        if base.returncode != 0:
            print(f"{name}: the unmutated tests fail; skipped\n{base.stdout[-2000:]}")
            continue
        cfg = out / f"{name}.toml"
        db = out / f"{name}.sqlite"
        cfg.write_text(_config(module, tests, max(60.0, 3 * base_s), out / "pytest-tmp"))
        if db.exists():
            db.unlink()
        _run(cr + ["init", str(cfg), str(db)], tree, env).check_returncode()
        _run([sys.executable, "-m", "cosmic_ray.tools.filters.operators_filter", str(db),
              str(cfg)], tree, env)
        with use_db(str(db), WorkDB.Mode.open) as wdb:
            # Job ids are random: sample from the mutants in source order, so that a seed
            # always picks the same mutants of the same code.
            items = sorted(wdb.pending_work_items, key=lambda w: (
                w.mutations[0].start_pos, w.mutations[0].operator_name,
                w.mutations[0].occurrence))
            pending = [w.job_id for w in items]
            total = wdb.num_work_items
            keep = set(random.Random(f"{args.seed}:{module}").sample(
                pending, min(args.per_module, len(pending))))
            for job in pending:
                if job not in keep:
                    wdb.set_result(job, WorkResult(output="not sampled",
                                                   worker_outcome=WorkerOutcome.SKIPPED))
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            print(f"{name}: budget spent, not run")
            continue
        try:
            _run(cr + ["exec", str(cfg), str(db)], tree, env, timeout=remaining)
        except subprocess.TimeoutExpired:
            print(f"{name}: budget spent during the run")
        killed = survived = incompetent = 0
        with use_db(str(db), WorkDB.Mode.open) as wdb:
            items = {w.job_id: w for w in wdb.work_items}
            for job, r in wdb.results:
                if job not in keep:
                    continue
                if r.worker_outcome != WorkerOutcome.NORMAL:
                    incompetent += 1
                elif r.test_outcome.value == "survived":
                    survived += 1
                    m = items[job].mutations[0]
                    survivors.append({"module": module, "operator": m.operator_name,
                                      "line": m.start_pos[0], "diff": r.diff})
                elif r.test_outcome.value == "killed":
                    killed += 1
                else:
                    incompetent += 1
        run = killed + survived + incompetent
        rows.append({"module": module, "mutants": total, "sampled": len(keep), "run": run,
                     "killed": killed, "survived": survived, "incompetent": incompetent,
                     "tests": tests, "test_seconds": round(base_s, 1)})
        print(f"{name:14s} {total:5d} mutants, {len(keep)} sampled: {killed} killed, "
              f"{survived} survived, {incompetent} incompetent ({base_s:.0f} s a run)",
              flush=True)
    k = sum(r["killed"] for r in rows)
    s = sum(r["survived"] for r in rows)
    score = k / (k + s) if k + s else float("nan")
    minutes = (time.monotonic() - start) / 60
    lines = [f"score: {k} killed / {k + s} = {100 * score:.1f} % "
             f"(seed {args.seed}, {args.per_module} per module, {minutes:.1f} min)"]
    for sv in survivors:
        lines += [f"SURVIVED {sv['module']}:{sv['line']} {sv['operator']}", sv["diff"] or ""]
    print("\n".join(lines))
    out.mkdir(parents=True, exist_ok=True)
    (out / "report.txt").write_text("\n".join(lines) + "\n")
    (out / "report.json").write_text(json.dumps({"score": score, "killed": k, "survived": s,
                                                 "modules": rows, "survivors": survivors,
                                                 "seed": args.seed,
                                                 "per_module": args.per_module,
                                                 "minutes": minutes}, indent=1) + "\n")
    shutil.rmtree(tree, ignore_errors=True)
    shutil.rmtree(out / "pytest-tmp", ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

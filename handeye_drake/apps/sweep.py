"""``handeye-drake sweep``: Monte Carlo runs of the closed loop over a grid of settings and seeds.

    handeye-drake sweep [--scenario FILE] --seeds 0:200
                        [--set calibrator.estimator=!PaperFilter,!TargetFilter]
                        [--set camera.model.pose_noise.rotation_sigma=0.001,0.002,0.005]
                        --out DIR [--workers N | --scheduler tcp://HOST:8786 | --dask-local N]
                        [--resume] [--force] [--no-progress] [--no-plots]

The grid is every combination of the ``--set`` values times every seed. ``--set PATH=V1,V2,...``
addresses the typed scenario (``handeye_drake.scenario``): dotted field names, list indices
(``servo.self_calibration[0].angle_deg=10,20``), values in YAML (``0.002``, ``[1, 0, 0]``,
``true``), a tagged union's variant by its tag (``calibrator.estimator=!PaperFilter``). A single
value is a plain override (``--set duration=5``). Each run is built inside its worker from the
scenario's YAML text and its overrides (Drake objects do not pickle), and checked by
``scenario.load_scenario`` — so a wrong path or value is a one-line error naming it, before any
run starts.

Output (``--out``, the policy of ``apps.outputs``):

- ``results.csv``: one row per run, appended as runs finish (never rewritten): every swept value,
  the seed, ``status`` ("ok" or "error: ..."), the two-motion and final hand-eye errors
  (rotation in degrees, translation in % of ‖t_EC‖), the final feature error (px), the filter's
  counters and diagnostics, simulated and wall time. A run that raises is recorded with its error;
  the sweep goes on. A sweep killed mid-way loses at most the runs in flight: ``--resume`` reads
  the table and runs only the missing (setting, seed) pairs (with more ``--seeds``, it extends
  the sweep).
- ``sweep.json``: the sweep's definition (scenario text, ``--set`` values, seeds), which
  ``--resume`` checks.
- ``errors.png``: box plots of the two-motion and final errors per setting; ``summary.md``: the
  per-setting medians and quartiles (also printed).

Python API: ``SweepSpec``, ``run_sweep(spec, out, executor=...)``.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import math
import os
import re
import socket
import time
import traceback
from concurrent.futures import as_completed
from dataclasses import dataclass, field
from pathlib import Path

from .executors import add_executor_arguments, make_executor
from .outputs import prepare_output_dir
from .progress import progress_bar

DEFAULT_OUT = "out/sweep"
RESULTS = "results.csv"
SPEC = "sweep.json"
#: Result columns after the swept values and the seed (``wall_time_s`` and ``worker`` vary from
#: run to run; every other column is reproducible).
METRICS = ("status", "two_motion_rotation_error_deg", "two_motion_translation_error_pct",
           "final_rotation_error_deg", "final_translation_error_pct", "final_feature_error_px",
           "final_X_EC_rotation_std_deg", "filter_updates", "rejected_measurements",
           "diagnostics", "simulated_time_s", "wall_time_s", "worker")
_INDEX = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)((?:\[\d+\])*)$")


# ---------------------------------------------------------------------------------------------
# Paths and values of --set.

def parse_path(path: str) -> list:
    """``a.b[0].c`` → ["a", "b", 0, "c"]; raises ValueError naming the path."""
    if not path:
        raise ValueError("--set: empty path")
    parts = []
    for piece in path.split("."):
        m = _INDEX.match(piece)
        if not m:
            raise ValueError(f"--set {path}: {piece!r} is not a field name (with optional "
                             "[index])")
        parts.append(m.group(1))
        parts += [int(i) for i in re.findall(r"\[(\d+)\]", m.group(2))]
    return parts


def split_values(text: str) -> list[str]:
    """Splits ``V1,V2,...`` at the commas outside brackets and braces."""
    values, depth, start = [], 0, 0
    for i, ch in enumerate(text):
        if ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            values.append(text[start:i].strip())
            start = i + 1
    values.append(text[start:].strip())
    if any(v == "" for v in values):
        raise ValueError(f"--set: empty value in {text!r}")
    return values


def parse_value(text: str, where: str):
    """A YAML value; ``!Tag`` alone is the tagged variant with its defaults."""
    from pydrake.common.yaml import yaml_load_data
    source = text + " {}" if re.fullmatch(r"![A-Za-z_][A-Za-z0-9_]*", text) else text
    try:
        return yaml_load_data(f"value: {source}\n")["value"]
    except Exception as e:  # noqa: BLE001 - the YAML parser's errors
        raise ValueError(f"--set {where}={text}: not a YAML value ({' '.join(str(e).split())})") \
            from None


def parse_set(option: str) -> tuple[str, list[str]]:
    """``PATH=V1,V2`` → (path, [values]) with the path checked for syntax."""
    if "=" not in option:
        raise ValueError(f"--set {option}: expected PATH=VALUE[,VALUE...]")
    path, values = option.split("=", 1)
    path = path.strip()
    parse_path(path)
    if path == "seed":
        raise ValueError("--set seed: seeds are swept with --seeds")
    values = split_values(values)
    for v in values:
        parse_value(v, path)
    return path, values


def apply_override(data: dict, path: str, value_text: str) -> None:
    """Sets ``path`` in the scenario's plain YAML data (``yaml_load_data`` form) to the parsed
    value; a tag replaces a tagged mapping. Raises ValueError naming the path."""
    parts = parse_path(path)
    value = parse_value(value_text, path)
    node = data
    for i, key in enumerate(parts[:-1]):
        here = ".".join(str(p) for p in parts[:i + 1])
        if isinstance(key, int):
            if not isinstance(node, list):
                raise ValueError(f"--set {path}: {here!r} is not a list")
            if not 0 <= key < len(node):
                raise ValueError(f"--set {path}: index {key} out of range (the list has "
                                 f"{len(node)} items)")
            node = node[key]
        else:
            if not isinstance(node, dict):
                raise ValueError(f"--set {path}: {here!r} is not a group of fields")
            node = node.setdefault(key, {})
    last = parts[-1]
    if isinstance(last, int):
        if not isinstance(node, list) or not 0 <= last < len(node):
            raise ValueError(f"--set {path}: index {last} out of range or not a list")
        node[last] = value
    else:
        if not isinstance(node, dict):
            raise ValueError(f"--set {path}: the parent of {last!r} is not a group of fields")
        node[last] = value


def scenario_text(base_text: str, overrides, seed: int | None = None) -> str:
    """The YAML text of the base scenario with the overrides (and seed) applied."""
    from pydrake.common.yaml import yaml_dump, yaml_load_data
    data = yaml_load_data(base_text)
    for path, value in overrides:
        apply_override(data, path, value)
    if seed is not None:
        data["seed"] = int(seed)
    return yaml_dump(data)


def build_scenario(base_text: str, overrides, seed: int | None = None):
    """The typed, validated scenario of one run; errors name the ``--set`` options."""
    from ..scenario import load_scenario
    text = scenario_text(base_text, overrides, seed)
    try:
        return load_scenario(text=text)
    except ValueError as e:
        given = " ".join(f"--set {p}={v}" for p, v in overrides)
        raise ValueError(f"{given or 'scenario'}: {str(e).removeprefix('scenario: ')}") \
            from None


#: The most runs one sweep takes (seeds × settings): a closed-loop run costs about a second, so
#: this is already more than a day on one core; a larger sweep is refused before anything runs.
MAX_RUNS = 100_000


def parse_seeds(text: str) -> list[int]:
    """``START:STOP`` (STOP excluded), ``A,B,C`` or ``N``; at most ``MAX_RUNS`` seeds (counted
    before the list is made)."""
    try:
        if ":" in text:
            start, stop = (int(v) for v in text.split(":", 1))
            if stop - start > MAX_RUNS:
                raise OverflowError
            seeds = list(range(start, stop))
        else:
            seeds = [int(v) for v in text.split(",")]
    except ValueError:
        raise ValueError(f"--seeds {text}: expected START:STOP, A,B,C or N") from None
    except OverflowError:
        raise ValueError(f"--seeds {text}: {stop - start} seeds; a sweep takes at most "
                         f"{MAX_RUNS} runs (about a second each)") from None
    if not seeds or min(seeds) < 0 or max(seeds) > 2**32 - 1:
        raise ValueError(f"--seeds {text}: needs at least one seed in [0, 2^32 − 1]")
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"--seeds {text}: repeated seeds")
    return seeds


# ---------------------------------------------------------------------------------------------
# The sweep.

@dataclass
class SweepSpec:
    """A sweep: the base scenario (full YAML text), the swept paths and values, the seeds."""
    base_text: str
    sets: list = field(default_factory=list)   # [(path, [value texts])]
    seeds: list = field(default_factory=list)

    @classmethod
    def from_options(cls, scenario_file, set_options, seeds) -> "SweepSpec":
        from ..scenario import dump_scenario, load_scenario
        base = dump_scenario(load_scenario(scenario_file))
        sets = [parse_set(o) for o in set_options]
        paths = [p for p, _ in sets]
        if len(set(paths)) != len(paths):
            raise ValueError(f"--set: a path given twice ({', '.join(paths)})")
        spec = cls(base, sets, parse_seeds(seeds) if isinstance(seeds, str) else list(seeds))
        runs = math.prod(len(values) for _, values in sets) * len(spec.seeds)
        if runs > MAX_RUNS:
            raise ValueError(f"--set, --seeds: {runs} runs ({' × '.join(str(len(v)) for _, v in sets)}"
                             f" settings × {len(spec.seeds)} seeds); a sweep takes at most "
                             f"{MAX_RUNS} runs (about a second each)")
        for setting in spec.settings():
            build_scenario(spec.base_text, setting)  # every value checked before any run
        return spec

    @property
    def columns(self) -> list[str]:
        return [p for p, _ in self.sets] + ["seed"] + list(METRICS)

    def settings(self) -> list[list]:
        """Every combination of the swept values: [[(path, value), ...], ...]."""
        if not self.sets:
            return [[]]
        return [list(zip([p for p, _ in self.sets], combo))
                for combo in itertools.product(*[values for _, values in self.sets])]

    def tasks(self) -> list[tuple]:
        """(key, base text, overrides, seed) of every run, settings outermost."""
        return [(run_key(setting, seed), self.base_text, setting, seed)
                for setting in self.settings() for seed in self.seeds]

    def to_json(self) -> dict:
        return {"scenario": self.base_text, "sets": [[p, v] for p, v in self.sets],
                "seeds": self.seeds}


def run_key(setting, seed) -> tuple:
    return tuple(str(v) for _, v in setting) + (str(int(seed)),)


def run_one(base_text: str, overrides, seed: int) -> dict:
    """One closed-loop run (executed in a worker): the row of the results table. Exceptions
    become an "error: ..." status; KeyboardInterrupt propagates."""
    row = {p: v for p, v in overrides}
    row["seed"] = int(seed)
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    start = time.perf_counter()
    try:
        from ..simulation import run_scenario
        scenario = build_scenario(base_text, overrides, seed)
        s = run_scenario(scenario).summary()
        row.update({
            "status": "ok",
            "two_motion_rotation_error_deg": s["two_motion_rotation_error_deg"],
            "two_motion_translation_error_pct": None if s["two_motion_translation_error_rel"]
            is None else 100.0 * s["two_motion_translation_error_rel"],
            "final_rotation_error_deg": s["final_rotation_error_deg"],
            "final_translation_error_pct": 100.0 * s["final_translation_error_rel"],
            "final_feature_error_px": s["final_feature_error_px"],
            "final_X_EC_rotation_std_deg": max(s["final_X_EC_rotation_std_deg"]),
            "filter_updates": s["filter_updates"],
            "rejected_measurements": s["rejected_measurements"],
            "diagnostics": "; ".join(s["diagnostics"]),
            "simulated_time_s": s["simulated_time_s"]})
    except Exception as e:  # noqa: BLE001 - recorded, the sweep goes on
        frame = traceback.extract_tb(e.__traceback__)[-1] if e.__traceback__ else None
        where = f" ({Path(frame.filename).name}:{frame.lineno})" if frame else ""
        row["status"] = "error: " + " ".join(f"{type(e).__name__}: {e}".split()) + where
    row["wall_time_s"] = time.perf_counter() - start
    return row


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)
    return str(value)


class ResultsTable:
    """``results.csv``, appended one flushed row at a time."""

    def __init__(self, path: Path, columns: list[str]):
        self.path = Path(path)
        self.columns = columns

    def read(self) -> list[dict]:
        if not self.path.is_file():
            return []
        with open(self.path, newline="") as f:
            reader = csv.DictReader(f)
            if reader.fieldnames is not None and list(reader.fieldnames) != self.columns:
                raise ValueError(f"--resume: {self.path} has columns {reader.fieldnames}, not "
                                 f"those of this sweep {self.columns}")
            # A row cut by a kill (fewer cells) is dropped: that run is run again.
            return [r for r in reader if None not in r.values() and r.get("status")]

    def start(self, keep: list[dict]) -> None:
        """Rewrites the file with the complete rows ``keep`` only (drops a torn last line)."""
        tmp = self.path.with_suffix(".tmp")
        with open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, self.columns)
            w.writeheader()
            w.writerows(keep)
        os.replace(tmp, self.path)

    def append(self, row: dict) -> None:
        with open(self.path, "a", newline="") as f:
            csv.DictWriter(f, self.columns).writerow({c: _cell(row.get(c)) for c in self.columns})
            f.flush()
            os.fsync(f.fileno())


@dataclass
class SweepReport:
    rows: list
    done_before: int
    ran: int
    failed: int
    written: list
    wall_time: float
    executor: str
    interrupted: bool = False


def run_sweep(spec: SweepSpec, out, executor=None, resume: bool = False, force: bool = False,
              progress: bool = True, plots: bool = True, executor_name: str = "") -> SweepReport:
    """Runs the runs of ``spec`` missing from ``out``'s table (all of them without ``resume``)
    on ``executor`` (any ``concurrent.futures.Executor``; None: serially here), appending a row
    per finished run. A KeyboardInterrupt stops it (rows already written stay; ``interrupted``
    set) after cancelling the runs not started."""
    out_dir = prepare_output_dir(out, "sweep", force)
    table = ResultsTable(out_dir.root / RESULTS, spec.columns)
    spec_path = out_dir.root / SPEC
    done = []
    if table.path.is_file():
        if not resume and not force:
            raise ValueError(f"--out {out}: holds a sweep's results ({RESULTS}); pass --resume "
                             "to complete it, or --force to start over")
        if resume:
            try:
                earlier = json.loads(spec_path.read_text())
            except (OSError, ValueError):
                earlier = None
            mine = spec.to_json()
            if not isinstance(earlier, dict) or any(earlier.get(k) != mine[k]
                                                    for k in ("scenario", "sets")):
                raise ValueError(f"--resume: {out} holds another sweep (its {SPEC} differs: "
                                 "other scenario or --set values; --seeds may change)")
            done = table.read()
    table.start(done)
    spec_path.write_text(json.dumps(spec.to_json(), indent=1) + "\n")
    out_dir.finish([table.path, spec_path])  # the manifest first: a killed sweep can resume
    columns_swept = [p for p, _ in spec.sets]
    seen = {tuple(r[c] for c in columns_swept) + (str(r["seed"]),) for r in done}
    todo = [t for t in spec.tasks() if t[0] not in seen]
    rows = [dict(r) for r in done]
    failed = 0
    label = f"sweep ({len(done)} done before" if done else "sweep ("
    bar = progress_bar(len(todo), f"{label}{', ' if done else ''}0 failed)", unit="runs",
                       enabled=progress)
    start = time.perf_counter()
    interrupted = False

    def finished(row):
        nonlocal failed
        table.append(row)
        rows.append({c: _cell(row.get(c)) for c in spec.columns})
        failed += not str(row.get("status", "")).startswith("ok")
        bar.set_description_str(f"{label}{', ' if done else ''}{failed} failed)", refresh=False)
        bar.update()

    try:
        if executor is None:
            for _, base, setting, seed in todo:
                finished(run_one(base, setting, seed))
        else:
            futures = {executor.submit(run_one, base, setting, seed): (setting, seed)
                       for _, base, setting, seed in todo}
            try:
                for fut in as_completed(futures):
                    try:
                        row = fut.result()
                    except KeyboardInterrupt:
                        raise
                    except BaseException as e:  # noqa: BLE001 - a worker lost, not the sweep
                        setting, seed = futures[fut]
                        row = {p: v for p, v in setting}
                        row.update(seed=seed, status="error: worker failed: "
                                   + " ".join(f"{type(e).__name__}: {e}".split()))
                    finished(row)
            except BaseException:
                for fut in futures:
                    fut.cancel()
                raise
    except KeyboardInterrupt:
        interrupted = True
    finally:
        bar.close()
    wall = time.perf_counter() - start
    written = [table.path, spec_path]
    if plots and not interrupted:
        written += write_summary(spec, rows, out_dir.root)
    out_dir.finish(written)
    return SweepReport(rows=rows, done_before=len(done), ran=len(rows) - len(done),
                       failed=failed, written=written, wall_time=wall,
                       executor=executor_name, interrupted=interrupted)


# ---------------------------------------------------------------------------------------------
# Summary: per-setting statistics and box plots.

def _number(text):
    try:
        v = float(text)
    except (TypeError, ValueError):
        return math.nan
    return v


def setting_label(spec: SweepSpec, row: dict) -> str:
    return ", ".join(f"{p.split('.')[-1]}={row[p]}" for p, _ in spec.sets) or "scenario"


def summarize(spec: SweepSpec, rows: list[dict]) -> list[dict]:
    """Per setting: runs, failures, quartiles of the final and two-motion errors."""
    import numpy as np
    groups: dict[str, list[dict]] = {}
    for setting in spec.settings():
        label = ", ".join(f"{p.split('.')[-1]}={v}" for p, v in setting) or "scenario"
        groups[label] = []
    for r in rows:
        groups.setdefault(setting_label(spec, r), []).append(r)
    out = []
    for label, rs in groups.items():
        ok = [r for r in rs if str(r.get("status")) == "ok"]
        entry = {"setting": label, "runs": len(rs), "failed": len(rs) - len(ok)}
        for key in ("final_rotation_error_deg", "final_translation_error_pct",
                    "two_motion_rotation_error_deg", "final_feature_error_px"):
            v = np.array([_number(r.get(key)) for r in ok])
            v = v[np.isfinite(v)]
            entry[key] = (np.percentile(v, [25, 50, 75]).tolist() if len(v) else None)
        out.append(entry)
    return out


def format_summary(stats: list[dict]) -> str:
    lines = ["| setting | runs | failed | final rot. (deg) median [IQR] | final trans. (%) "
             "median [IQR] | two-motion rot. (deg) median | feature error (px) median |",
             "|---|---|---|---|---|---|---|"]

    def q(v, digits=3):
        return "–" if v is None else f"{v[1]:.{digits}g} [{v[0]:.{digits}g}, {v[2]:.{digits}g}]"

    def median(v):
        return "–" if v is None else f"{v[1]:.3g}"

    for s in stats:
        lines.append(f"| {s['setting']} | {s['runs']} | {s['failed']} | "
                     f"{q(s['final_rotation_error_deg'])} | "
                     f"{q(s['final_translation_error_pct'])} | "
                     f"{median(s['two_motion_rotation_error_deg'])} | "
                     f"{median(s['final_feature_error_px'])} |")
    return "\n".join(lines)


def write_summary(spec: SweepSpec, rows: list[dict], root: Path) -> list[Path]:
    """``summary.md`` and ``errors.png`` (box plots of the two-motion and final errors per
    setting, log scale)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    stats = summarize(spec, rows)
    summary = root / "summary.md"
    summary.write_text(f"# Sweep: {len(rows)} runs\n\n{format_summary(stats)}\n")
    labels = [s["setting"] for s in stats]
    fig, axes = plt.subplots(1, 2, figsize=(max(8.0, 1.6 * len(labels) + 4), 4.5))
    for ax, (final, initial, title) in zip(axes, (
            ("final_rotation_error_deg", "two_motion_rotation_error_deg",
             "rotation error of X_EC (deg)"),
            ("final_translation_error_pct", "two_motion_translation_error_pct",
             "translation error of X_EC (% of ‖t_EC‖)"))):
        data_final, data_initial = [], []
        for s in stats:
            ok = [r for r in rows if setting_label(spec, r) == s["setting"]
                  and str(r.get("status")) == "ok"]
            data_final.append([v for v in (_number(r.get(final)) for r in ok) if v > 0])
            data_initial.append([v for v in (_number(r.get(initial)) for r in ok) if v > 0])
        x = np.arange(len(labels))
        for data, offset, color, name in ((data_initial, -0.18, "0.7", "two-motion start"),
                                          (data_final, 0.18, "tab:blue", "on-line, final")):
            keep = [i for i, d in enumerate(data) if d]
            if keep:
                b = ax.boxplot([data[i] for i in keep], positions=x[keep] + offset, widths=0.3,
                               patch_artist=True, manage_ticks=False)
                for patch in b["boxes"]:
                    patch.set_facecolor(color)
                ax.plot([], [], "s", color=color, label=name)
        ax.set_yscale("log")
        ax.set_xticks(x)
        ax.set_xticklabels(labels, rotation=20, ha="right", fontsize=8)
        ax.set_title(title, fontsize=10)
        ax.grid(True, axis="y", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{len(rows)} closed-loop runs ({len(spec.seeds)} seeds per setting)")
    fig.tight_layout()
    plot = root / "errors.png"
    fig.savefig(plot, dpi=110)
    plt.close(fig)
    return [summary, plot]


# ---------------------------------------------------------------------------------------------
# Command line.

def _command(args) -> int:
    spec = SweepSpec.from_options(args.scenario, args.set or [], args.seeds)
    n = len(spec.settings()) * len(spec.seeds)
    with make_executor(args.workers, args.scheduler, args.dask_local) as (executor, where):
        report = run_sweep(spec, args.out, executor, resume=args.resume, force=args.force,
                           progress=not args.no_progress, plots=not args.no_plots,
                           executor_name=where)
    print(f"sweep: {n} runs ({len(spec.settings())} settings × {len(spec.seeds)} seeds) on "
          f"{where}: {report.ran} run now ({report.failed} failed), {report.done_before} done "
          f"before; {report.wall_time:.1f} s wall")
    if report.interrupted:
        print(f"interrupted: {len(report.rows)} of {n} runs are in {args.out}/{RESULTS}; "
              "complete them with --resume")
        return 130
    print(format_summary(summarize(spec, report.rows)))
    print("wrote: " + ", ".join(str(p) for p in report.written))
    return 0


def add_parser(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "sweep", help="Monte Carlo runs of the closed loop over settings × seeds (local "
        "processes or Dask)", description="Runs the closed loop for every combination of the "
        "--set values and every seed, appending one row per run to OUT/results.csv, then "
        "writes box plots and a summary of the errors per setting.")
    p.add_argument("--scenario", metavar="FILE",
                   help="base scenario YAML (default: the built-in scenario)")
    p.add_argument("--seeds", required=True, metavar="SEEDS",
                   help="seeds: START:STOP (STOP excluded), A,B,C or N")
    p.add_argument("--set", action="append", metavar="PATH=V1[,V2...]",
                   help="a scenario field to sweep (or override, with one value): dotted path, "
                        "list indices, YAML values, !Tag for a variant; repeatable")
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                   help=f"output directory (default {DEFAULT_OUT})")
    p.add_argument("--resume", action="store_true",
                   help="complete the sweep in --out: run only the runs missing from its table")
    p.add_argument("--force", action="store_true",
                   help="start over in a --out holding results (or write into a non-empty "
                        "directory that is not this command's; files the tool did not write are "
                        "never touched)")
    add_executor_arguments(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.add_argument("--no-plots", action="store_true", help="skip errors.png and summary.md")
    p.set_defaults(func=_command)
    return p

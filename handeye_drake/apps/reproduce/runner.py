"""Reproduce the paper's experiments (its section 3, Figures 2–10) with one command.

    handeye-drake reproduce [fig2 … fig10 | all] [--runs N] [--seed S] [--workers W] [--out DIR]
                            [--scheduler tcp://HOST:8786 | --dask-local N]
                            [--motions K] [--duration T] [--no-progress]

For each requested figure it writes ``DIR/figN.png`` (laid out like the paper's figure) and
``DIR/figN.csv`` (the numbers behind it), then ``DIR/summary.md``: each level's final mean / RMS
error, plus the settings and timings. The experiments are described in
``handeye_drake.apps.reproduce.experiments``.

Python API::

    from handeye_drake.apps.reproduce import run_sweep, reproduce
    result = run_sweep("fig3", runs=50, seed=0)                 # serial, in this process
    with ProcessPoolExecutor(4) as ex:                          # or a Dask / Ray executor
        result = run_sweep("fig9", runs=500, seed=0, executor=ex)

Reproducibility: run r of an experiment draws from ``default_rng(SeedSequence(seed,
spawn_key=(experiment code, r)))`` (and, for Fig. 10, a Drake ``RandomGenerator`` seeded from it),
so the CSVs depend on ``--seed`` and ``--runs`` only — not on ``--workers`` or the executor.
"""

from __future__ import annotations

import argparse
import multiprocessing
import time
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

from ..argtypes import non_negative_int, positive_int
from ..executors import add_executor_arguments, make_executor
from ..outputs import prepare_output_dir
from ..progress import progress_bar
from .experiments import EXPERIMENTS, FIGURES, SweepResult

DEFAULT_OUT = "out/reproduce"

#: All figures, in the paper's order.
ALL_FIGURES = tuple(sorted(FIGURES, key=lambda f: int(f.removeprefix("fig"))))

#: Order in which experiments are submitted: the long ones first, for load balance.
_SUBMIT_ORDER = ("realistic", "two_motion", "rotation_noise", "translation_noise",
                 "initial_estimate", "orthonormalization")


def _experiment_names(figures) -> list[str]:
    """Experiment names for figure names ("fig3"), experiment names, or "all"."""
    if isinstance(figures, str):
        figures = [figures]
    names = []
    for f in figures:
        if f == "all":
            candidates = list(EXPERIMENTS)
        elif f in FIGURES:
            candidates = [FIGURES[f]]
        elif f in EXPERIMENTS:
            candidates = [f]
        else:
            raise ValueError(f"figures: unknown figure {f!r}; expected one of "
                             f"{', '.join(ALL_FIGURES)}, 'all' or an experiment name "
                             f"({', '.join(EXPERIMENTS)})")
        names += [c for c in candidates if c not in names]
    if not names:
        raise ValueError("figures: no figure requested")
    return names


def _check_runs(runs) -> int | None:
    if runs is None:
        return None
    if isinstance(runs, bool) or int(runs) != runs or runs < 1:
        raise ValueError(f"runs: expected a positive integer, got {runs!r}")
    return int(runs)


def run_sweeps(figures, runs: int | None = None, seed: int = 0, executor: Executor | None = None,
               progress: bool = False, **options) -> dict[str, SweepResult]:
    """Runs several experiments, their tasks interleaved on one executor.

    Args:
        figures: figure names ("fig2" … "fig10"), experiment names, or "all" (a str or a list).
        runs: simulations per level (default: each experiment's, the paper's counts where given:
            Fig. 2 1000 matrices, Figs 3–8 50, Fig. 9 500, Fig. 10 10 closed-loop runs).
        seed: base seed (non-negative integer).
        executor: any ``concurrent.futures.Executor`` (process pool, thread pool, Dask, Ray…);
            None runs the tasks one after another in this process.
        progress: draw a progress bar on stderr.
        options: ``motions`` (robot motions per run of Figs 3–8, default 100), ``duration``
            (simulated seconds of Fig. 10's runs, default the scenario's 12 s).

    Returns:
        {experiment name: SweepResult}.
    """
    names = _experiment_names(figures)
    runs = _check_runs(runs)
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise ValueError(f"seed: expected a non-negative integer, got {seed!r}")
    if options.get("motions") is not None:
        m = options["motions"]
        if isinstance(m, bool) or int(m) != m or m < 1:
            raise ValueError(f"motions: expected a positive integer, got {m!r}")
    if options.get("duration") is not None and not float(options["duration"]) > 4.5:
        raise ValueError("duration: Fig. 10 runs need more than the 4 s of self-calibration "
                         f"motions plus some servoing, got {options['duration']!r}")
    options = {k: v for k, v in options.items() if v is not None}
    counts = {n: runs or EXPERIMENTS[n].default_runs for n in names}
    order = sorted(names, key=_SUBMIT_ORDER.index)
    jobs = [(n, t) for n in order for t in EXPERIMENTS[n].tasks(counts[n], int(seed), options)]
    bar = progress_bar(len(jobs), "reproduce " + ",".join(
        f for n in names for f in EXPERIMENTS[n].figures), unit="tasks", enabled=progress)
    outputs: dict[str, dict] = {n: {} for n in names}
    try:
        if executor is None:
            for n, t in jobs:
                outputs[n][t.key] = t.fn(*t.args)
                bar.update()
        else:
            futures = {executor.submit(t.fn, *t.args): (n, t.key) for n, t in jobs}
            try:
                for fut in as_completed(futures):
                    n, key = futures[fut]
                    outputs[n][key] = fut.result()
                    bar.update()
            except BaseException:
                for fut in futures:
                    fut.cancel()
                raise
    finally:
        bar.close()
    return {n: EXPERIMENTS[n].assemble(outputs[n], counts[n], int(seed), options) for n in names}


def run_sweep(figure: str, runs: int | None = None, seed: int = 0,
              executor: Executor | None = None, progress: bool = False,
              **options) -> SweepResult:
    """Runs the experiment behind one figure ("fig2" … "fig10", or an experiment name); see
    ``run_sweeps`` for the arguments. Figures 3/4, 5/6 and 7/8 come from the same sweep."""
    (result,) = run_sweeps([figure], runs, seed, executor, progress, **options).values()
    return result


def write_figures(results: dict[str, SweepResult], figures, out,
                  plots: bool = True) -> list[Path]:
    """PNG (unless ``plots`` is False) + CSV of each requested figure ("all" or names)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for f in _figure_list(figures, results):
        result = results[FIGURES[f]]
        written += EXPERIMENTS[result.experiment].write(result, f, out, plot=plots)
    return written


def _figure_list(figures, results) -> list[str]:
    if isinstance(figures, str):
        figures = [figures]
    wanted = set()
    for f in figures:
        if f == "all":
            wanted |= {g for n in results for g in EXPERIMENTS[n].figures}
        elif f in FIGURES:
            wanted.add(f)
        elif f in EXPERIMENTS:
            wanted |= set(EXPERIMENTS[f].figures)
    return [f for f in ALL_FIGURES if f in wanted and FIGURES[f] in results]


def summary_markdown(results: dict[str, SweepResult], figures, header: str = "") -> str:
    """The summary.md text: ``header``, then one table per figure."""
    parts = [header] if header else []
    for f in _figure_list(figures, results):
        result = results[FIGURES[f]]
        parts.append(EXPERIMENTS[result.experiment].summary(result, f))
    return "\n".join(parts)


@dataclass
class ReproduceReport:
    results: dict
    written: list = field(default_factory=list)
    wall_time: float = 0.0


def reproduce(figures=("all",), runs: int | None = None, seed: int = 0, workers: int = 1,
              out=DEFAULT_OUT, executor: Executor | None = None, progress: bool = True,
              motions: int | None = None, duration: float | None = None,
              command: str = "", force: bool = False) -> ReproduceReport:
    """Runs the requested figures and writes PNGs, CSVs and ``summary.md`` into ``out`` (with
    the policy of ``apps.outputs``: a new or empty directory, or this command's earlier output
    whose stale files are removed; ``force`` for another non-empty directory).

    With no ``executor`` and ``workers`` > 1 a process pool (spawn start method: Drake and BLAS
    threads do not survive a fork) of that many workers is used, and shut down afterwards.
    """
    if isinstance(workers, bool) or int(workers) != workers or workers < 1:
        raise ValueError(f"workers: expected a positive integer, got {workers!r}")
    _experiment_names(figures)
    out_dir = prepare_output_dir(out, "reproduce", force)
    start = time.perf_counter()
    own_pool = executor is None and workers > 1
    if own_pool:
        executor = ProcessPoolExecutor(max_workers=int(workers),
                                       mp_context=multiprocessing.get_context("spawn"))
    try:
        results = run_sweeps(figures, runs, seed, executor, progress, motions=motions,
                             duration=duration)
    finally:
        if own_pool:
            executor.shutdown(cancel_futures=True)
    compute = time.perf_counter() - start
    written = write_figures(results, figures, out_dir.root)
    wall = time.perf_counter() - start
    header = [
        "# Reproduction of the paper's simulations (Figures 2–10)", "",
        f"- command: `{command or 'reproduce'}`",
        f"- seed {seed}; runs per level: " + ", ".join(
            f"{'/'.join(r.figures)} {r.runs}" for r in results.values()),
        f"- wall time {wall:.1f} s ({compute:.1f} s computing, "
        f"{'executor ' + type(executor).__name__ if executor is not None else 'serial'}"
        f"{f', {workers} workers' if own_pool else ''}); task time per experiment: " + ", ".join(
            f"{n} {r.cpu_time:.1f} s" for n, r in results.items()),
        "- errors: rotation ‖q − q̂‖ between unit quaternions (sign-safe), translation "
        "‖t − t̂‖ / ‖t‖; \"initial\" = before the first filter update, \"final\" = after the last.",
        ""]
    text = summary_markdown(results, figures, "\n".join(header))
    summary = out_dir.path("summary.md")
    summary.write_text(text)
    written.append(summary)
    out_dir.finish(written)
    return ReproduceReport(results=results, written=written, wall_time=wall)


# ---------------------------------------------------------------------------------------------
# Command line.

def _figure_name(text: str) -> str:
    if text not in ALL_FIGURES and text != "all":
        raise argparse.ArgumentTypeError(f"unknown figure {text!r}; choose from "
                                         f"{', '.join(ALL_FIGURES)} or all")
    return text


def _command(args) -> int:
    figures = args.figures or ["all"]
    command = "handeye-drake reproduce " + " ".join(
        figures + [f"--{k} {getattr(args, k)}" for k in ("runs", "seed", "workers", "motions",
                                                          "duration")
                   if getattr(args, k) is not None] + [f"--out {args.out}"])
    # Dask when asked (--scheduler / --dask-local); else reproduce's own process pool.
    with make_executor(1, args.scheduler, args.dask_local) as (executor, where):
        report = reproduce(figures, runs=args.runs, seed=args.seed, workers=args.workers,
                           out=args.out, executor=executor, progress=not args.no_progress,
                           motions=args.motions, duration=args.duration, command=command,
                           force=args.force)
    print(f"reproduced {', '.join(_figure_list(figures, report.results))} in "
          f"{report.wall_time:.1f} s wall")
    print("wrote: " + ", ".join(str(p) for p in report.written))
    return 0


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Adds the ``reproduce`` subcommand to an argparse ``subparsers`` object; its ``func``
    default runs it and returns the exit code."""
    p = subparsers.add_parser(
        "reproduce", help="reproduce the paper's experiments (Figures 2–10)",
        description="Runs the paper's simulations and writes, per figure, a PNG laid out like "
                    "the paper's and the numbers behind it as CSV, plus summary.md.")
    # Checked by ``type`` rather than ``choices``: argparse rejects an empty nargs="*" list
    # against choices (Python < 3.12).
    p.add_argument("figures", nargs="*", type=_figure_name, default=["all"], metavar="FIGURE",
                   help=f"figures to reproduce: {', '.join(ALL_FIGURES)} or all (default all)")
    p.add_argument("--runs", type=positive_int,
                   help="simulations per level (default: the paper's — 50 for Figs 3–8, 500 "
                        "for Fig. 9; 1000 matrices for Fig. 2, 10 closed-loop runs for Fig. 10)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="base seed (default 0)")
    add_executor_arguments(p, workers_help="local worker processes (default: the number of "
                           "CPUs)")
    p.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                   help=f"output directory (default {DEFAULT_OUT}); an existing one must be "
                        "empty or hold this command's earlier output, whose stale files are "
                        "removed")
    p.add_argument("--force", action="store_true",
                   help="write into a non-empty --out that is not this command's output "
                        "(never overwriting files the tool did not write)")
    p.add_argument("--motions", type=positive_int,
                   help="robot motions per run in Figs 3–8 (default 100)")
    p.add_argument("--duration", type=float,
                   help="simulated seconds of each Fig. 10 run (default: the scenario's 12 s)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=_command)
    return p


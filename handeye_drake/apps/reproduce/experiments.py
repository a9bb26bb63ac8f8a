"""The paper's experiments (its section 3, Figures 2–10), one module per experiment.

An experiment produces one ``SweepResult`` from independent tasks (``common.Task``) that any
``concurrent.futures.Executor`` can run, and writes each of its figures as a PNG, the numbers
behind it as CSV, and a markdown section for ``summary.md``. ``handeye_drake.apps.reproduce.runner`` drives
them.

    experiment          figures        what
    orthonormalization  fig2           SVD vs QR vs Horn projection onto SO(3)
    rotation_noise      fig3, fig4     paper filter, noise on R_A's coefficients
    translation_noise   fig5, fig6     paper filter, noise on t_A
    initial_estimate    fig7, fig8     paper filter, perturbed initial estimate
    two_motion          fig9           two-motion Tsai–Lenz vs Daniilidis
    realistic           fig10          full Drake closed loop, paper filter vs ours

All but ``realistic`` are numpy/scipy only; ``realistic`` builds its Drake diagrams inside the
task, so inside each worker.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Callable

from . import filter_sweeps, orthonormalization, realistic, two_motion
from .common import SweepResult, Task


@dataclass(frozen=True)
class Experiment:
    """Hooks of one experiment.

    tasks(runs, seed, options) -> list[Task]; assemble({key: task result}, runs, seed, options)
    -> SweepResult; write(result, figure, out_dir, plot=True) -> written paths (CSV, and the PNG
    unless plot is False); summary(result, figure) -> markdown.
    """
    name: str
    figures: tuple
    default_runs: int
    tasks: Callable
    assemble: Callable
    write: Callable
    summary: Callable


def _sweep(kind: str) -> Experiment:
    return Experiment(name=kind, figures=filter_sweeps.SWEEPS[kind][1],
                      default_runs=filter_sweeps.DEFAULT_RUNS,
                      tasks=partial(filter_sweeps.tasks, kind),
                      assemble=partial(filter_sweeps.assemble, kind),
                      write=filter_sweeps.write, summary=filter_sweeps.summary)


def _module(m) -> Experiment:
    return Experiment(name=m.NAME, figures=m.FIGURES, default_runs=m.DEFAULT_RUNS, tasks=m.tasks,
                      assemble=m.assemble, write=m.write, summary=m.summary)


EXPERIMENTS: dict[str, Experiment] = {e.name: e for e in (
    _module(orthonormalization), _sweep("rotation_noise"), _sweep("translation_noise"),
    _sweep("initial_estimate"), _module(two_motion), _module(realistic))}

#: "fig2" … "fig10" → the experiment producing it.
FIGURES: dict[str, str] = {f: e.name for e in EXPERIMENTS.values() for f in e.figures}

__all__ = ["EXPERIMENTS", "FIGURES", "Experiment", "SweepResult", "Task"]

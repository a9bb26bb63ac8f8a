"""Reproduce the paper's experiments (its section 3, Figures 2–10): ``handeye-drake reproduce``.

``runner`` drives the experiments (any ``concurrent.futures.Executor``), ``experiments`` lists
them, one module per experiment (``orthonormalization``, ``filter_sweeps``, ``two_motion``,
``realistic``).
"""

from .experiments import EXPERIMENTS, FIGURES, Experiment, SweepResult, Task
from .runner import ALL_FIGURES, add_parser, reproduce, run_sweep, run_sweeps

__all__ = ["ALL_FIGURES", "EXPERIMENTS", "FIGURES", "Experiment", "SweepResult", "Task",
           "add_parser", "reproduce", "run_sweep", "run_sweeps"]

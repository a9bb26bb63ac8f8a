"""``handeye-drake calibrate``: the command line of the recorded-data calibration. The
calibration itself is the library ``handeye_drake.calibration``; this package parses arguments,
calls it, prints and writes (``command``), and draws its pictures (``plots``)."""

from .command import add_parser, run_calibrate_command

__all__ = ["add_parser", "run_calibrate_command"]

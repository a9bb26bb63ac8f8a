"""``handeye-drake``: the command line. One parser built from each application's ``add_parser``;
no application imports this module back.

    handeye-drake simulate    closed-loop simulation of a scenario
    handeye-drake scenario    the default scenario as YAML
    handeye-drake calibrate   hand-eye calibration from recorded poses, images or a bag
    handeye-drake target      a calibration target to print, at true scale
    handeye-drake plan        the next robot poses to record (D-optimal design; --feasible: IK)
    handeye-drake session     live calibration: the next pose after each sample, stop when good
    handeye-drake reproduce   the paper's experiments (Figures 2–10)
    handeye-drake sweep       Monte Carlo runs over settings × seeds (local processes or Dask)
    handeye-drake benchmark   accuracy against OpenCV and the maximum-likelihood limit; speed

Exit status: 0 success, 1 a result that should not be trusted under ``--strict``, 2 bad input
(one ``handeye-drake: error: ...`` line, no traceback), 130 interrupted.
"""

from __future__ import annotations

import argparse
import sys

from . import accuracy, calibrate, plan, reproduce, session, simulate, speed, sweep, target
from .outputs import remove_empty_created

APPLICATIONS = (simulate, calibrate, target, plan, session, reproduce, sweep)
#: Sub-commands of ``handeye-drake benchmark``.
BENCHMARKS = (accuracy, speed)


class _DefaultsFormatter(argparse.HelpFormatter):
    """Every option's help ends with its default, unless the text already states it."""

    def _get_help_string(self, action):
        text = action.help or ""
        if (action.option_strings and "default" not in text.lower()
                and not any(action.default is v for v in (None, False, argparse.SUPPRESS))
                and not isinstance(action, (argparse._StoreTrueAction, argparse._VersionAction,
                                            argparse._HelpAction))):
            text += " (default: %(default)s)"
        return text


class _Parser(argparse.ArgumentParser):
    """Usage errors as one line (``handeye-drake calibrate: error: ...``, exit 2); ``--help``
    still prints the usage, with every default."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", _DefaultsFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())}\n")


def make_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="handeye-drake",
        description="On-line hand-eye calibration embedded in visual servoing (Drake).")
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    for app in APPLICATIONS:
        app.add_parser(sub)
    bench = sub.add_parser("benchmark", help="benchmarks of the estimators",
                           description="Benchmarks that print ratios against a reference "
                                       "measured in the same run.")
    bench_sub = bench.add_subparsers(dest="benchmark_command", required=True)
    for app in BENCHMARKS:
        app.add_parser(bench_sub)
    return parser


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("handeye_drake")
    except PackageNotFoundError:  # a source tree that was not installed
        return "unknown (not installed)"


def main(argv=None) -> int:
    try:
        args = make_parser().parse_args(argv)
    except SystemExit as e:  # --help (0) or a usage error (2, already printed)
        return e.code if isinstance(e.code, int) else 2
    try:
        return args.func(args)
    except ValueError as e:
        # One line, whatever the message's layout: the command never prints a traceback for bad
        # input; the output folders it created and left empty go with it.
        remove_empty_created()
        print("handeye-drake: error: " + " ".join(str(e).split()), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        remove_empty_created()
        print("handeye-drake: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

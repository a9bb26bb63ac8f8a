"""``handeye-drake``: the command line. One parser built from each application's ``add_parser``;
no application imports this module back.

    handeye-drake simulate    closed-loop simulation of a scenario
    handeye-drake scenario    the default scenario as YAML
    handeye-drake calibrate   hand-eye calibration from recorded robot and camera poses
    handeye-drake plan        the next robot poses to record (D-optimal design)
    handeye-drake reproduce   the paper's experiments (Figures 2–10)
    handeye-drake benchmark   accuracy against OpenCV and the maximum-likelihood limit

Exit status: 0 success, 1 a result that should not be trusted under ``--strict``, 2 bad input
(one ``handeye-drake: error: ...`` line, no traceback), 130 interrupted.
"""

from __future__ import annotations

import argparse
import sys

from . import accuracy, calibrate, plan, reproduce, simulate

APPLICATIONS = (simulate, calibrate, plan, reproduce)
#: Sub-commands of ``handeye-drake benchmark``.
BENCHMARKS = (accuracy,)


def make_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="handeye-drake",
        description="On-line hand-eye calibration embedded in visual servoing (Drake).")
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


def main(argv=None) -> int:
    args = make_parser().parse_args(argv)
    try:
        return args.func(args)
    except ValueError as e:
        # One line, whatever the message's layout: the command never prints a traceback for bad
        # input.
        print("handeye-drake: error: " + " ".join(str(e).split()), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("handeye-drake: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

"""``handeye-drake`` command line.

    handeye-drake simulate [--scenario FILE] [--out DIR] [--meshcat-html FILE] [--seed N]
                           [--no-feedback] [--no-meshcat]
    handeye-drake scenario            # prints the default scenario as YAML (a template to edit)
    handeye-drake reproduce [fig2 … fig10 | all] [--runs N] [--seed S] [--workers W] [--out DIR]
    handeye-drake calibrate --robot FILE --camera FILE [--format tum|csv-matrix|opencv-yaml] …
    handeye-drake benchmark accuracy [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def _simulate(args) -> int:
    from ..simulation import build_diagram, run_scenario
    from .pictures import render_diagram
    from .plots import write_run_plots
    from ..scenario import load_scenario

    scenario = load_scenario(args.scenario)
    if args.seed is not None:
        scenario.seed = args.seed
    if args.duration is not None:
        scenario.duration = args.duration
        scenario.validate()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    meshcat = None
    if not args.no_meshcat:
        from pydrake.geometry import Meshcat
        meshcat = Meshcat()
    result = run_scenario(scenario, feedback=not args.no_feedback, meshcat=meshcat)
    written = write_run_plots(result, out)
    written += render_diagram(build_diagram(scenario, with_loggers=False).diagram,
                              out / "diagram")
    if meshcat is not None:
        html = Path(args.meshcat_html) if args.meshcat_html else out / "replay.html"
        html.parent.mkdir(parents=True, exist_ok=True)
        html.write_text(meshcat.StaticHtml())
        written.append(html)
    summary = result.summary()
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    written.append(out / "summary.json")

    print(f"scenario: {args.scenario or 'built-in default'} (seed {scenario.seed}, "
          f"{'feedback' if not args.no_feedback else 'NO feedback, fixed guess'})")
    print(f"  two-motion estimate (Daniilidis): rotation {summary['two_motion_rotation_error_deg']:.3f}"
          f" deg, translation {100 * summary['two_motion_translation_error_rel']:.2f} %")
    print(f"  final on-line estimate:           rotation {summary['final_rotation_error_deg']:.3f}"
          f" deg, translation {100 * summary['final_translation_error_rel']:.2f} % "
          f"({summary['filter_updates']} Kalman updates)")
    print(f"  final feature error: {summary['final_feature_error_px']:.3f} px (RMS)")
    print(f"  simulated {summary['simulated_time_s']:.2f} s in {summary['wall_time_s']:.2f} s wall "
          f"(real-time factor {summary['real_time_factor']:.2f})")
    print("wrote: " + ", ".join(str(p) for p in written))
    return 0


def _print_scenario(args) -> int:
    from ..scenario import Scenario, dump_scenario
    print(dump_scenario(Scenario()), end="")
    return 0


def make_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="handeye-drake",
        description="On-line hand-eye calibration embedded in visual servoing (Drake).")
    sub = parser.add_subparsers(dest="command", required=True)

    sim = sub.add_parser("simulate", help="run the closed-loop simulation of a scenario")
    sim.add_argument("--scenario", help="scenario YAML (default: the built-in scenario)")
    sim.add_argument("--out", default="out/simulate", help="output directory")
    sim.add_argument("--meshcat-html", help="path of the Meshcat HTML replay "
                     "(default: OUT/replay.html)")
    sim.add_argument("--no-meshcat", action="store_true", help="skip the Meshcat replay")
    sim.add_argument("--seed", type=int, help="override the scenario's seed")
    sim.add_argument("--duration", type=float, help="override the scenario's duration (s)")
    sim.add_argument("--no-feedback", action="store_true",
                     help="feed the servo the fixed initial guess instead of the estimate")
    sim.set_defaults(func=_simulate)

    sc = sub.add_parser("scenario", help="print the default scenario as YAML")
    sc.set_defaults(func=_print_scenario)

    from .reproduce import add_reproduce_parser
    add_reproduce_parser(sub)
    from .calibrate import add_calibrate_parser
    add_calibrate_parser(sub)
    from .accuracy import add_benchmark_parser
    add_benchmark_parser(sub)
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


if __name__ == "__main__":
    sys.exit(main())

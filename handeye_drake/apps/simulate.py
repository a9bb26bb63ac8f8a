"""``handeye-drake simulate``: the closed-loop simulation of a scenario, and ``handeye-drake
scenario``: the default scenario as YAML, a template to edit.

    handeye-drake simulate [--scenario FILE] [--out DIR] [--seed N] [--duration T]
                           [--no-feedback] [--no-meshcat] [--meshcat-html FILE] [--strict]
                           [--force] [--no-progress]

Writes into ``--out`` (default ``out/simulate``): ``summary.json``, three PNG plots, the
diagram (``diagram.dot``/``.svg``), a Meshcat replay (``replay.html``) and, for a rendered camera
(``camera.model: !RenderedImages``), the frames of ``camera.model.frames_to_save`` with the
detection drawn (``frames/frame_NNN.png``).
"""

from __future__ import annotations

import json

from .outputs import check_output_file, prepare_output_dir
from .progress import progress_bar

DEFAULT_OUT = "out/simulate"


def add_parser(subparsers) -> None:
    sim = subparsers.add_parser(
        "simulate", help="run the closed-loop simulation of a scenario",
        description="Simulate the closed loop (arm, camera, visual servo, on-line hand-eye "
                    "calibrator) of a scenario and report the hand-eye and servo errors.")
    sim.add_argument("--scenario", metavar="FILE",
                     help="scenario YAML (default: the built-in scenario; `handeye-drake "
                          "scenario` prints it)")
    sim.add_argument("--out", default=DEFAULT_OUT, metavar="DIR",
                     help=f"output directory (default {DEFAULT_OUT}); an existing one must be "
                          "empty or hold this command's earlier output")
    sim.add_argument("--meshcat-html", metavar="FILE",
                     help="path of the Meshcat HTML replay (default: OUT/replay.html)")
    sim.add_argument("--no-meshcat", action="store_true", help="skip the Meshcat replay")
    sim.add_argument("--seed", type=int, help="override the scenario's seed")
    sim.add_argument("--duration", type=float, metavar="SECONDS",
                     help="override the scenario's duration")
    sim.add_argument("--no-feedback", action="store_true",
                     help="feed the servo the fixed initial guess instead of the estimate")
    sim.add_argument("--strict", action="store_true",
                     help="exit with status 1 when the run's result should not be trusted "
                          "(diagnostics are printed as WARNING lines in any case)")
    sim.add_argument("--force", action="store_true",
                     help="write into a non-empty --out that is not this command's output "
                          "(never overwriting files the tool did not write)")
    sim.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    sim.set_defaults(func=run_simulate)

    sc = subparsers.add_parser("scenario", help="print the default scenario as YAML",
                               description="Print the default scenario as YAML (a template).")
    sc.set_defaults(func=run_print_scenario)


def run_print_scenario(args) -> int:
    from ..scenario import Scenario, dump_scenario
    print(dump_scenario(Scenario()), end="")
    return 0


def _quiet_meshcat():
    """A Meshcat for recording a static replay, without its "listening for connections" line
    (nothing can connect to a batch run's server)."""
    import logging

    from pydrake.geometry import Meshcat
    drake_log = logging.getLogger("drake")  # pydrake forwards Drake's C++ log here
    level = drake_log.level
    drake_log.setLevel(logging.WARNING)
    try:
        return Meshcat()
    finally:
        drake_log.setLevel(level)


def write_saved_frames(result, out) -> list:
    """The rendered frames kept by ``camera.model.frames_to_save``, with the detection drawn,
    as ``frames/frame_NNN.png`` (NNN: the index in frames_to_save)."""
    import cv2

    from ..simulation import intrinsics_of
    intrinsics = intrinsics_of(result.scenario)
    written = []
    for frame in result.frames:
        path = out.path(f"frames/frame_{frame.index:03d}.png")
        if not cv2.imwrite(str(path), frame.drawn(intrinsics)):
            raise ValueError(f"--out {out.root}: could not write {path}")
        written.append(path)
    return written


def run_simulate(args) -> int:
    from ..scenario import load_scenario
    from ..simulation import build_diagram, run_scenario
    from .pictures import render_diagram
    from .plots import write_run_plots

    scenario = load_scenario(args.scenario)
    if args.seed is not None:
        scenario.seed = args.seed
    if args.duration is not None:
        scenario.duration = args.duration
    scenario.validate()
    out = prepare_output_dir(args.out, "simulate", args.force)
    html = None
    if not args.no_meshcat:
        html = (check_output_file(args.meshcat_html, "--meshcat-html", args.force)
                if args.meshcat_html else out.path("replay.html"))
    summary_path = out.path("summary.json")

    meshcat = None if args.no_meshcat else _quiet_meshcat()
    with progress_bar(round(scenario.duration, 3), "simulate", unit="s",
                      enabled=not args.no_progress) as bar:
        def advance(t):
            bar.update(round(t, 3) - bar.n)
        result = run_scenario(scenario, feedback=not args.no_feedback, meshcat=meshcat,
                              progress=advance)
    written = write_run_plots(result, out.root)
    written += write_saved_frames(result, out)
    written += render_diagram(build_diagram(scenario, with_loggers=False).diagram,
                              out.root / "diagram")
    if html is not None:
        html.write_text(meshcat.StaticHtml())
        written.append(html)
    summary = result.summary()
    summary_path.write_text(json.dumps(summary, indent=2) + "\n")
    written.append(summary_path)
    out.finish(written)

    name = type(scenario.calibrator.estimator).__name__
    print(f"scenario: {args.scenario or 'built-in default'} (seed {scenario.seed}, "
          f"{'feedback' if not args.no_feedback else 'NO feedback, fixed guess'}, "
          f"estimator {name})")
    if summary["two_motion_solution_found"]:
        print(f"  two-motion estimate ({scenario.calibrator.init_method}): rotation "
              f"{summary['two_motion_rotation_error_deg']:.3f} deg, translation "
              f"{100 * summary['two_motion_translation_error_rel']:.2f} %")
    else:
        print(f"  two-motion estimate ({scenario.calibrator.init_method}): FAILED, the "
              "estimator started from X_EC_guess")
    std = summary["final_X_EC_rotation_std_deg"]
    print(f"  final on-line estimate:           rotation {summary['final_rotation_error_deg']:.3f}"
          f" deg, translation {100 * summary['final_translation_error_rel']:.2f} % "
          f"({summary['filter_updates']} updates; 1σ {max(std):.3f} deg)")
    print(f"  final feature error: {summary['final_feature_error_px']:.3f} px (RMS)")
    if "detector_frames" in summary:
        rms = summary["reprojection_rms_px_median"]
        print(f"  detector: board found in {summary['detector_found_frames']} of "
              f"{summary['detector_frames']} frames"
              + (f", reprojection RMS {rms:.3f} px (median)" if rms is not None else ""))
        saved = {f.index for f in result.frames}
        missed = [t for i, t in enumerate(scenario.camera.model.frames_to_save)
                  if i not in saved]
        if missed:
            print(f"  frames_to_save: no frame at {', '.join(f'{t:g}' for t in missed)} s "
                  f"(the run ended at {result.sim_time:g} s)")
    for name, c in summary.get("cell_cameras", {}).items():
        nees = c["final_nees"]
        if c["frames_used"] == 0:
            print(f"  cell camera {name}: board found in {c['detector_found_frames']} of "
                  f"{c['detector_frames']} frames; no X_BC (no frame where both cameras found "
                  "the board)")
            continue
        print(f"  cell camera {name}: board found in {c['detector_found_frames']} of "
              f"{c['detector_frames']} frames; X_BC {c['final_rotation_error_deg']:.3f} deg / "
              f"{1000 * c['final_translation_error_m']:.2f} mm from the truth (1σ "
              f"{max(c['final_X_BC_rotation_std_deg']):.3f} deg / "
              f"{1000 * max(c['final_X_BC_translation_std']):.2f} mm per axis at most"
              + (f", NEES {nees:.1f}" if nees is not None else "")
              + f"; from the last {c['frames_used']} frames with both cameras)")
    print(f"  simulated {summary['simulated_time_s']:.2f} s in {summary['wall_time_s']:.2f} s wall "
          f"(real-time factor {summary['real_time_factor']:.2f})"
          + (" — INTERRUPTED, results so far saved" if result.interrupted else ""))
    for d in result.diagnostics:
        print(f"WARNING: {d}")
    print("wrote: " + ", ".join(str(p) for p in written))
    if result.interrupted:
        return 130
    return 1 if (args.strict and result.diagnostics) else 0

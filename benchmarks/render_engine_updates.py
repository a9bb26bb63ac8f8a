"""What a renderer in the plant's SceneGraph costs a simulation that renders nothing.

    OPENBLAS_NUM_THREADS=1 python benchmarks/render_engine_updates.py [--repeats N]

A SceneGraph updates the poses of every geometry in each of its render engines whenever a query
needs current poses, and a discrete MultibodyPlant with collision geometry queries at every step
(500 Hz here). This script simulates the rendered scenario's arm making the rendered loop's own
motion (its commanded poses recorded from ``run_scenario`` and replayed into the same driver, as
``benchmark speed``'s replay row) for the loop's 4 s, without evaluating any image, in three
set-ups: the arm alone; with the board, a RenderEngineVtk and the loop's RgbdSensor in the
plant's SceneGraph (how the rendered loop was built before ``systems.perception_scene``); and with
them in a perception scene graph (``add_perception_scene_graph``, the loop now). Interleaved
(A B C, C B A, ...), garbage collection off while timing; prints each median (Initialize +
AdvanceTo, wall s) and its ratio to the arm alone.
"""

from __future__ import annotations

import argparse
import gc
import statistics


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats: must be ≥ 1, got {args.repeats}")

    from handeye_drake.apps.speed import (
        arm_reference_diagram,
        load_average,
        pin_blas_threads,
        record_commanded_poses,
        rendered_scenario,
        simulate_reference,
    )
    from handeye_drake.scenario import transform_matrix
    from handeye_drake.simulation import camera_pose_on_hand, intrinsics_of
    from handeye_drake.systems.perception_scene import add_perception_scene_graph
    from handeye_drake.systems.rendered_camera import add_target_geometry, \
        mount_rendered_camera

    print(f"BLAS: {pin_blas_threads()}; {load_average()}")
    scenario = rendered_scenario()
    poses = record_commanded_poses(scenario)
    a, sensor, model = scenario.arm, scenario.camera.sensor, scenario.camera.model

    def build(camera: str | None):
        def add_camera(builder, handles, control):
            add_target_geometry(handles.scene_graph, model.parsed_target(),
                                transform_matrix(scenario.target.X_WT, "target.X_WT"))
            scene = handles.scene_graph
            if camera == "perception":
                hand = handles.plant.GetFrameByName(a.ee_frame).body()
                scene = add_perception_scene_graph(builder, handles.plant, handles.scene_graph,
                                                   bodies=[hand])
            mount_rendered_camera(builder, scene, handles.plant, a.ee_frame,
                                  camera_pose_on_hand(scenario, control), intrinsics_of(scenario),
                                  supersample=model.supersample, name="camera",
                                  clipping_near=sensor.clipping_near,
                                  clipping_far=sensor.clipping_far)

        diagram, integrator, _, q0 = arm_reference_diagram(
            scenario, commanded_poses=poses, extend=None if camera is None else add_camera)
        return lambda: simulate_reference(scenario, diagram, integrator, q0)[0]

    setups = {"the arm alone": build(None),
              "+ renderer and RgbdSensor in the plant's SceneGraph": build("plant"),
              "+ renderer and RgbdSensor in a perception scene graph": build("perception")}
    for run in setups.values():
        run()  # warm
    times = {name: [] for name in setups}
    order = list(setups)
    for r in range(args.repeats):
        for name in (order if r % 2 == 0 else order[::-1]):
            gc.collect()
            gc.disable()
            try:
                times[name].append(setups[name]())
            finally:
                gc.enable()
    alone = statistics.median(times["the arm alone"])
    print(f"the rendered loop's arm motion, {scenario.duration:g} s simulated, no image rendered:")
    for name, t in times.items():
        m = statistics.median(t)
        print(f"  {name:56s} {m:.3f} s  {m / alone:.2f}×")
    print(load_average())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

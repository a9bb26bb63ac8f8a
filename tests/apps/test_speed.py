"""benchmark speed: the references compute what the library computes (no timing assertions)."""

import numpy as np
import pytest

from handeye_drake.apps import speed


def test_references_equal_the_library_and_rows_carry_their_reference():
    rows = speed.estimator_section(repeats=1, num_samples=40, log=lambda s: None)
    assert len(rows) == 6  # 3 estimators × (validated update, unchecked _update)
    for row in rows:
        assert row["reference"] == "straight-line numpy reference"
        assert row["value_us"] > 0 and row["reference_us"] > 0 and row["target"] == 1.5
        assert row["ratio"] == pytest.approx(row["value_us"] / row["reference_us"])


def test_the_reference_check_catches_a_different_computation():
    X_BE, X_CT, X_CE, _ = speed.sample_poses(20)
    P0 = np.diag([1e-4] * 6 + [1.0] * 6)
    Rn = np.diag([0.002**2] * 3 + [0.0005**2] * 3)
    X, _, P, _, n = speed.reference_target_filter(X_BE, X_CT, X_CE, P0, Rn, np.inf, 3)
    assert n == 19
    speed._close("X_CE", X, X)
    with pytest.raises(AssertionError, match="disagree on P"):
        speed._close("P", P * (1 + 1e-6), P)


def test_calibrator_in_a_diagram_equals_the_bare_estimator():
    (row,) = speed.calibrator_section(repeats=1, num_samples=30, log=lambda s: None)
    assert "estimate logged: 30 samples" in row["what"] and row["ratio"] > 0


def test_recordings_follow_the_example_pose_model(tmp_path):
    from handeye_drake.recorded.example import TRUE_X_EC, X_BT, camera_pose
    from handeye_drake.estimation.se3 import inverse
    robot, camera, X_BE, X_CT = speed.write_recording(tmp_path, 50)
    lines = [l for l in camera.read_text().splitlines() if not l.startswith("#")]
    assert len(lines) == 50 and float(lines[1].split()[0]) == pytest.approx(1 / 15 + 0.02, abs=1e-6)
    np.testing.assert_allclose(X_BE[7], camera_pose(7 / 15) @ inverse(TRUE_X_EC), atol=1e-12)
    # X_CT: the true pose up to the example's noise (0.1°, 0.5 mm).
    X_true = inverse(camera_pose(7 / 15)) @ X_BT
    assert np.abs(X_CT[7] - X_true).max() < 0.01
    assert sum(1 for l in robot.read_text().splitlines() if not l.startswith("#")) >= 49 / 15 * 50


def test_rendered_section_times_the_loop_against_the_same_frames_rendered_and_detected():
    lines = []
    (row,) = speed.rendered_section(1, log=lines.append, duration=0.2)
    # 0.2 s at 30 Hz: the frame at initialization and the periodic ones at 0, …, 1/6 s.
    assert row["frames"] == 7 and row["found_frames"] == 7
    assert row["max_X_CT_difference"] <= 1e-9 and row["target"] == 1.3
    assert row["ratio"] == pytest.approx(row["value_us"] / row["reference_us"])
    assert set(row["per_frame_ms"]) == {"loop", "render", "detect", "rest"}
    assert row["per_frame_ms"]["loop"] == pytest.approx(1e3 * row["value_us"] / 7)
    assert "detections equal to the loop's" in lines[-1]


def test_the_rendered_reference_renders_and_detects_what_the_loop_did():
    from handeye_drake.estimation.se3 import rotation_angle
    from handeye_drake.scenario import transform_matrix
    from handeye_drake.simulation import run_scenario
    from handeye_drake.systems.arm import make_control_plant

    scenario = speed.rendered_scenario(duration=0.2)
    result = run_scenario(scenario)
    a = scenario.arm
    plant = make_control_plant(urdf=a.urdf or None, base_frame=a.base_frame,
                               X_WB=transform_matrix(a.X_WB, "arm.X_WB"))
    Q = speed.arm_positions_reaching(plant, a.base_frame, a.ee_frame, result.X_BE_samples,
                                     np.radians(a.q0_deg))
    # The joint positions reach the logged poses.
    context = plant.CreateDefaultContext()
    for q, X in zip(Q, result.X_BE_samples):
        plant.SetPositions(context, q)
        X_q = plant.CalcRelativeTransform(context, plant.GetFrameByName(a.base_frame),
                                          plant.GetFrameByName(a.ee_frame)).GetAsMatrix4()
        assert np.abs(X_q[:3, 3] - X[:3, 3]).max() < 1e-11
        assert rotation_angle(X_q[:3, :3].T @ X[:3, :3]) < 1e-11
    seconds, (render, detect, detections) = speed.rendered_reference(scenario)(Q)
    assert len(detections) == len(result.times) == 7 and 0 < render + detect <= seconds
    assert speed.check_same_detections(detections, result.detector_found,
                                       result.X_CT_samples) <= 1e-9
    # The check catches a different computation: a moved pose, a lost frame.
    moved = result.X_CT_samples.copy()
    moved[3, 0, 3] += 1e-6
    with pytest.raises(AssertionError, match="disagree on X_CT"):
        speed.check_same_detections(detections, result.detector_found, moved)
    lost = result.detector_found.copy()
    lost[2] = 0.0
    with pytest.raises(AssertionError, match=r"where the target was found: \[2\]"):
        speed.check_same_detections(detections, lost, result.X_CT_samples)


def test_corners_section_times_our_fit_and_opencvs_on_the_same_corners():
    from handeye_drake.apps.speed_corners import _corner_set, corners_section
    rows = corners_section((8, 16), log=lambda s: None)
    assert [r["images"] for r in rows[:2]] == [8, 16]
    for r in rows[:2]:
        assert r["corners"] == 48 * r["images"] and r["seconds"] > 0
        assert r["ratio"] == pytest.approx(r["seconds"] / r["reference_seconds"])
    assert rows[2]["cost_per_image_growth"] == pytest.approx(
        rows[1]["ms_per_image"] / rows[0]["ms_per_image"])
    # The synthetic set is what the section says: every corner inside the 640×480 image.
    X_BE, board, img, v, X_EC, X_BT = _corner_set(5, seed=3)
    assert len(img) == 5 and all((u >= 0).all() and (u[:, 0] < 640).all() for u in img)


def test_the_replayed_reference_moves_the_arm_as_the_loop_did():
    """The loop section's "loop's own motion" reference: the loop's driver tracking the poses
    the servo commanded in a run moves the arm exactly as in the loop (same joint positions
    along the way), so that row compares the same motion."""
    from pydrake.common import RandomGenerator
    from pydrake.systems.analysis import ApplySimulatorConfig, Simulator

    from handeye_drake.scenario import load_scenario
    from handeye_drake.simulation import build_diagram

    scenario = load_scenario()
    scenario.duration = 3.0
    times, poses = speed.record_commanded_poses(scenario)
    step = scenario.period / 3.0
    assert len(times) == pytest.approx(scenario.duration / step, abs=2)
    assert np.all(np.diff(times) > 0.9 * step)
    diagram, ik, plant, q0 = speed.arm_reference_diagram(scenario, commanded_poses=(times, poses))
    loop = build_diagram(scenario, with_loggers=False)
    simulators = []
    for d, seed_or_ik in ((diagram, ik), (loop.diagram, None)):
        simulator = Simulator(d)
        ApplySimulatorConfig(scenario.simulator_config, simulator)
        context = simulator.get_mutable_context()
        if seed_or_ik is None:
            d.SetRandomContext(context, RandomGenerator(int(scenario.seed)))
        else:
            seed_or_ik.SetPositions(seed_or_ik.GetMyMutableContextFromRoot(context), q0)
        simulator.Initialize()
        simulators.append(simulator)
    worst, q_start = 0.0, None
    for t in np.linspace(0.1, scenario.duration, 30):
        q = []
        for simulator, p in zip(simulators, (plant, loop.plant)):
            simulator.AdvanceTo(t)
            q.append(p.GetPositions(p.GetMyContextFromRoot(simulator.get_context())))
        q_start = q[1] if q_start is None else q_start
        worst = max(worst, np.abs(q[0] - q[1]).max())
    moved = np.abs(q[1] - q_start).max()
    assert moved > 0.05 and worst < 1e-9, (moved, worst)


def test_the_replay_reference_takes_what_a_variant_adds():
    """``extend`` (benchmarks/render_engine_updates.py adds a camera with it) is called with the
    builder, the arm's handles and the control plant before the replay diagram is built."""
    from pydrake.math import RigidTransform
    from pydrake.systems.primitives import PassThrough

    from handeye_drake.scenario import load_scenario

    seen = []

    def extend(builder, handles, control):
        seen.append((handles.plant.is_finalized(), control.num_positions()))
        builder.AddNamedSystem("added_by_extend", PassThrough(1))

    diagram, _, _, _ = speed.arm_reference_diagram(
        load_scenario(), commanded_poses=([0.0], [RigidTransform()]), extend=extend)
    assert seen == [(True, 6)]
    assert "added_by_extend" in {s.get_name() for s in diagram.GetSystems()}


def test_callback_timer_counts_each_call_and_restores_the_methods():
    class Thing:
        def _Work(self, n):
            return sum(range(n))

    original = Thing._Work
    with speed._Timed({Thing: ["_Work"]}) as timed:
        assert Thing()._Work(10_000) == sum(range(10_000))
        assert Thing._Work is not original
    assert Thing._Work is original and timed.seconds["Thing"] > 0.0

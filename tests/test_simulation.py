"""The full Drake diagram (``handeye_drake.simulation``): arm, camera, IBVS and calibrator in
closed loop."""

from pathlib import Path

import numpy as np
import pytest

from handeye_drake.estimation.configs import PaperFilter, TargetFilter
from handeye_drake.estimation.errors import rotation_error_deg
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp
from handeye_drake.scenario import TwistCommand, load_scenario
from handeye_drake.simulation import build_diagram, run_scenario
from handeye_drake.systems.calibrator import STATUS_FILTERING, STATUS_INIT_FAILED


def _servo_iae(result):
    """Integrated RMS feature error over the servo phase (px·s)."""
    m = result.times >= result.servo_start_time
    return float(np.trapezoid(result.feature_error_px[m], result.times[m]))


@pytest.fixture(scope="module")
def default_run():
    return run_scenario(load_scenario())


def test_default_scenario_converges_and_refines(default_run):
    r = default_run
    assert isinstance(r.scenario.calibrator.estimator, TargetFilter)
    # The servo reaches the desired image to within 2 px RMS (pixel noise is 0.5 px).
    assert r.feature_error_px[-1] < 2.0
    # The on-line estimate ends better than the two-motion (Daniilidis) solution in both parts.
    assert r.rotation_error_deg[-1] < r.initial_rotation_error_deg
    assert r.translation_error_rel[-1] < r.initial_translation_error_rel
    # ... by a wide margin, and with a standard deviation consistent with its actual error.
    assert r.rotation_error_deg[-1] < 0.5 * r.initial_rotation_error_deg
    assert r.translation_error_rel[-1] < 0.5 * r.initial_translation_error_rel
    std_deg = np.linalg.norm(r.X_EC_std[-1, :3])
    assert r.rotation_error_deg[-1] < 4 * std_deg
    # Bookkeeping: filtering, one update per sample after servo start, nothing NaN, arm fine.
    assert r.calibrator_status[-1, 0] == STATUS_FILTERING
    assert r.filter_updates > 300
    for name in ("features", "X_EC_estimates", "X_WC", "X_EC_std", "feature_error_px"):
        assert np.all(np.isfinite(getattr(r, name))), name
    # The servo commands a pose (Drake's integrator tracks it): each self-calibration motion
    # turns the hand by its configured 20° (robot poses sampled at the camera trigger).
    assert r.ik_status is None
    k = [int(np.argmin(np.abs(r.times - t - r.scenario.period))) for t in (0.0, 2.0, 4.0)]
    for a, b in zip(k, k[1:]):
        assert rotation_error_deg(r.X_BE_samples[a], r.X_BE_samples[b]) == pytest.approx(
            20.0, abs=0.1)
    # Self-calibration took the configured 2 × 2 s, and the estimate was the guess until then.
    assert r.servo_start_time == pytest.approx(4.0, abs=2.5 * r.scenario.period)
    np.testing.assert_allclose(r.X_EC_estimates[0], r.scenario.X_EC_guess_matrix(), atol=1e-12)
    assert r.diagnostics == [] and r.summary()["two_motion_solution_found"]


def test_paper_estimator_runs_in_the_loop():
    """The paper's filter in the same loop: stays finite and near its two-motion start."""
    s = load_scenario()
    s.calibrator.estimator = PaperFilter(rotation_coefficient_sigma=0.004, translation_sigma=0.003,
                                         min_rotation_deg=1.0)
    r = run_scenario(s)
    assert r.feature_error_px[-1] < 3.0
    assert np.all(np.isfinite(r.X_EC_estimates))
    assert r.filter_updates > 10
    assert r.rotation_error_deg[-1] < 2 * r.initial_rotation_error_deg + 0.2
    assert r.translation_error_rel[-1] < 2 * r.initial_translation_error_rel + 0.05


def test_feedback_is_real(default_run):
    s = default_run.scenario
    # The user's rough guess fed to the servo for the whole run (calibrator open loop).
    guess = run_scenario(s, feedback=False)
    assert _servo_iae(guess) > 1.1 * _servo_iae(default_run)
    assert guess.feature_error_px[-1] > 1.3 * default_run.feature_error_px[-1]
    # A 40° wrong hand-eye rotation: the servo is clearly worse.
    X_wrong = default_run.X_EC_true @ make_transform(rotation_exp(np.radians([0, 0, 40])),
                                                     np.zeros(3))
    wrong = run_scenario(s, feedback=False, X_CE_fixed=inverse(X_wrong))
    assert _servo_iae(wrong) > 1.4 * _servo_iae(default_run)
    assert wrong.feature_error_px[-1] > 2.0 * default_run.feature_error_px[-1]


def test_same_seed_same_logs_different_seed_different_noise():
    s = load_scenario()
    s.duration = 5.0
    a, b = run_scenario(s), run_scenario(s)
    np.testing.assert_array_equal(a.features, b.features)
    np.testing.assert_array_equal(a.X_EC_estimates, b.X_EC_estimates)
    np.testing.assert_array_equal(a.X_CT_samples, b.X_CT_samples)
    s.seed = 1
    c = run_scenario(s)
    assert not np.array_equal(a.features, c.features)
    assert not np.array_equal(a.X_CT_samples, c.X_CT_samples)
    # Same robot start, so the difference is the noise: a fraction of a pixel at first.
    assert 0 < np.abs(a.features[1] - c.features[1]).max() < 5.0


def test_diagram_structure():
    loop = build_diagram(load_scenario())
    names = {s.get_name() for s in loop.diagram.GetSystems()}
    assert {"plant", "scene_graph", "diff_ik", "desired_state", "camera", "servo", "calibrator",
            "pixel_noise_source", "pose_noise_source"} <= names
    # The camera reads the plant's body poses and samples the robot pose with its image: no
    # separate pose sensor or sampler (each Python system costs time at every step).
    assert not {"ee_sensor", "robot_pose_sampler"} & names
    assert loop.ee_sensor is None
    for port in ("X_EC_estimate", "features", "feature_error", "V_WE_E_command", "X_WC"):
        assert loop.diagram.HasOutputPort(port)
    dot = loop.diagram.GetGraphvizString(max_depth=1)
    assert "calibrator" in dot and "servo" in dot


def test_bring_your_own_arm(tmp_path):
    """Another arm plugs in through the scenario alone: a UR10e (its published DH lengths) with
    its flange renamed, based where its flange starts at the UR5e's start pose."""
    from handeye_drake.systems.arm import UR5E_URDF, make_control_plant
    text = Path(UR5E_URDF).read_text()
    for joint_origin_ur5e, joint_origin_ur10e in (
            ('xyz="0 0 0.1625"', 'xyz="0 0 0.1807"'), ('xyz="-0.425 0 0"', 'xyz="-0.6127 0 0"'),
            ('xyz="-0.3922 0 0"', 'xyz="-0.57155 0 0"'), ('xyz="0 0 0.1333"', 'xyz="0 0 0.17415"'),
            ('xyz="0 0 0.0997"', 'xyz="0 0 0.11985"'), ('xyz="0 0 0.0996"', 'xyz="0 0 0.11655"')):
        assert text.count(joint_origin_ur5e) >= 1
        text = text.replace(joint_origin_ur5e, joint_origin_ur10e)
    text = text.replace('"tool0"', '"flange"').replace('name="ur5e"', 'name="ur10e"')
    urdf = tmp_path / "ur10e.urdf"
    urdf.write_text(text)

    s = load_scenario()
    q0 = np.radians(s.arm.q0_deg)

    def flange_pose(path, frame):
        plant = make_control_plant(urdf=path)
        context = plant.CreateDefaultContext()
        plant.SetPositions(context, q0)
        return plant.CalcRelativeTransform(context, plant.world_frame(),
                                           plant.GetFrameByName(frame)).GetAsMatrix4()
    X_W_ur5e = flange_pose(UR5E_URDF, "tool0")
    X_B_ur10e = flange_pose(str(urdf), "flange")
    assert np.linalg.norm(X_W_ur5e[:3, 3] - X_B_ur10e[:3, 3]) > 0.1  # really another arm
    X_WB = X_W_ur5e @ inverse(X_B_ur10e)
    from handeye_drake.estimation.se3 import rpy
    s = load_scenario(text=f"""
arm:
  urdf: {urdf}
  ee_frame: flange
  X_WB:
    translation: {X_WB[:3, 3].tolist()}
    rotation: !Rpy {{ deg: {np.degrees(rpy(X_WB[:3, :3])).tolist()} }}
""")
    r = run_scenario(s)
    assert r.feature_error_px[-1] < 2.0
    assert r.rotation_error_deg[-1] < r.initial_rotation_error_deg
    assert r.translation_error_rel[-1] < r.initial_translation_error_rel


def test_the_twist_driver_gives_the_same_loop(default_run):
    """``arm.driver: !TwistCommand`` (the Python differential-IK driver on the servo's twist):
    every IK step solved, and the run ends where the pose-commanded one does — the same
    calibration to within its reported σ, the same image to within the pixel noise."""
    s = load_scenario()
    s.arm.driver = TwistCommand()
    r = run_scenario(s)
    assert np.all(r.ik_status == 0)
    assert r.ik_status.shape == r.times.shape
    std_deg = np.linalg.norm(r.X_EC_std[-1, :3])
    assert abs(r.rotation_error_deg[-1] - default_run.rotation_error_deg[-1]) < std_deg
    assert abs(r.feature_error_px[-1] - default_run.feature_error_px[-1]) < 0.5
    assert r.diagnostics == []


def test_a_failed_two_motion_start_is_reported():
    """Self-calibration angles of 0°: the two-motion solve fails; the run says so (status,
    diagnostics, summary) instead of printing a two-motion error of the guess as if solved."""
    s = load_scenario(text="""
servo:
  self_calibration:
    - {axis_C: [1, 0, 0], angle_deg: 0.0}
    - {axis_C: [0, 1, 0], angle_deg: 0.0}
duration: 6.0
""")
    r = run_scenario(s)
    assert r.calibrator_mode == STATUS_INIT_FAILED
    assert not r.summary()["two_motion_solution_found"]
    assert any("two-motion solution failed" in d for d in r.diagnostics)


def test_calibrator_updates_on_a_driver_step_with_the_same_results(default_run, monkeypatch):
    """The loop's calibrator updates at the driver's first step after each trigger (no
    simulator step of its own); any instant between two triggers reads the same held sample,
    so its class default (half a period) gives the very same run."""
    from handeye_drake.simulation import DRIVER_STEPS_PER_PERIOD
    from handeye_drake.systems import calibrator as calibrator_module

    scenario = load_scenario()
    assert build_diagram(scenario).calibrator._offset == pytest.approx(
        scenario.period / DRIVER_STEPS_PER_PERIOD)
    original = calibrator_module.HandEyeCalibrator.__init__

    def class_default(self, *args, **kwargs):
        kwargs.pop("offset", None)
        original(self, *args, **kwargs)

    monkeypatch.setattr(calibrator_module.HandEyeCalibrator, "__init__", class_default)
    assert build_diagram(scenario).calibrator._offset == pytest.approx(0.5 * scenario.period)
    half = run_scenario(scenario)
    for name in ("X_EC_estimates", "X_EC_std", "calibrator_status", "features", "X_WC"):
        np.testing.assert_array_equal(getattr(half, name), getattr(default_run, name))


def test_the_plant_steps_by_discrete_updates_with_live_output_ports():
    """The arm's plant reports its ports live (no sampling state): its 2 ms step is a discrete
    update, not an unrestricted one after which the simulator would ask every (Python) system
    for its witness functions again. The only unrestricted updates left are the noise sources'
    (one per camera sample each); the scenario's default is the arm's."""
    from pydrake.common import RandomGenerator
    from pydrake.systems.analysis import ApplySimulatorConfig, Simulator

    from handeye_drake.systems.arm import DEFAULT_PLANT_CONFIG

    scenario = load_scenario()
    assert scenario.plant_config.use_sampled_output_ports is False
    assert DEFAULT_PLANT_CONFIG.use_sampled_output_ports is False
    assert scenario.plant_config.time_step == DEFAULT_PLANT_CONFIG.time_step
    scenario.duration = 1.0
    built = build_diagram(scenario, with_loggers=False)
    simulator = Simulator(built.diagram)
    ApplySimulatorConfig(scenario.simulator_config, simulator)
    built.diagram.SetRandomContext(simulator.get_mutable_context(), RandomGenerator(0))
    simulator.AdvanceTo(scenario.duration)
    plant_steps = round(scenario.duration / scenario.plant_config.time_step)
    camera_samples = round(scenario.duration / scenario.period)
    assert simulator.get_num_discrete_updates() >= plant_steps
    assert simulator.get_num_unrestricted_updates() <= camera_samples + 1

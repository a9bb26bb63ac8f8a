"""Scenarios (``handeye_drake.scenario``): typed YAML, variants selected by tag, estimator noise
derived from the camera, and errors that name the file and the field."""

import math

import numpy as np
import pytest

from handeye_drake.estimation.configs import ManifoldFilter, PaperFilter, TargetFilter
from handeye_drake.scenario import CoefficientPoseNoise, Scenario, dump_scenario, load_scenario
from handeye_drake.simulation import build_diagram, camera_pose_on_hand


def test_the_default_scenario_round_trips_through_yaml(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text(dump_scenario(Scenario()))
    s = load_scenario(path)
    assert s.camera.sensor.fps == Scenario().camera.sensor.fps == 30.0
    assert dump_scenario(s) == dump_scenario(Scenario())
    with pytest.raises(ValueError, match="no such file"):
        load_scenario(tmp_path / "missing.yaml")


def test_estimators_are_selected_by_tag_and_noise_defaults_to_the_camera():
    s = load_scenario()
    assert isinstance(s.calibrator.estimator, TargetFilter)
    c = s.estimator_config()
    assert (c.rotation_sigma, c.translation_sigma) == (0.002, 0.0005)  # the camera's pose noise
    m = load_scenario(text="calibrator:\n  estimator: !ManifoldFilter {min_rotation_deg: 1.0}\n")
    c = m.estimator_config()
    assert isinstance(c, ManifoldFilter) and c.min_rotation_deg == 1.0
    # A motion differenced from two poses: √2 σ_r; t_A: √(2σ_t² + 4/3 σ_r² d²), d = 0.35 m.
    assert c.rotation_sigma == pytest.approx(math.sqrt(2) * 0.002)
    assert c.translation_sigma == pytest.approx(math.sqrt(2 * 0.0005**2 + 4 / 3 * 0.002**2
                                                          * 0.35**2))
    p = load_scenario(text="calibrator:\n  estimator: !PaperFilter {translation_sigma: 0.003}\n")
    c = p.estimator_config()
    assert isinstance(c, PaperFilter) and c.translation_sigma == 0.003  # set: kept
    assert c.rotation_coefficient_sigma == pytest.approx(math.sqrt(2 * 4 / 3) * 0.002)
    # The paper's coefficient pose noise: the target filter gets its rotation-vector part.
    k = load_scenario(text="camera:\n  model:\n    pose_noise: !CoefficientPoseNoise\n"
                           "      rotation_coefficient_sigma: 0.004\n")
    assert isinstance(k.camera.model.pose_noise, CoefficientPoseNoise)
    assert k.estimator_config().rotation_sigma == pytest.approx(0.004 / math.sqrt(2))


def test_the_camera_pose_is_drakes_camera_config_on_the_flange():
    s = load_scenario(text="""
camera:
  sensor:
    X_PB: {base_frame: wrist_3_link, translation: [0.01, 0.0, 0.1], rotation: !Rpy {deg: [0, 0, 0]}}
""")
    loop = build_diagram(s, with_loggers=False)
    plant = loop.plant
    X_E_wrist = plant.CalcRelativeTransform(plant.CreateDefaultContext(),
                                            plant.GetFrameByName("tool0"),
                                            plant.GetFrameByName("wrist_3_link")).GetAsMatrix4()
    X_EC = X_E_wrist @ np.array([[1, 0, 0, 0.01], [0, 1, 0, 0], [0, 0, 1, 0.1], [0, 0, 0, 1.0]])
    np.testing.assert_allclose(loop.X_EC_true, X_EC, atol=1e-12)
    with pytest.raises(ValueError, match="camera.sensor.X_PB.base_frame: 'base_link' is not "
                                         "fixed to the end-effector"):
        build_diagram(load_scenario(text="camera:\n  sensor:\n    X_PB: {base_frame: base_link}\n"))
    assert camera_pose_on_hand(Scenario(), loop.plant).shape == (4, 4)


@pytest.mark.parametrize("yaml, message", [
    ("camera:\n  model:\n    pixel_sigm: 0.5\n",
     r"^scenario: camera.model.pixel_sigm: unknown field; did you mean 'pixel_sigma'\?$"),
    ("servo:\n  gain: fast\n", r"^scenario: servo.gain: expected a number, got 'fast'$"),
    ("seed: -1\n", r"seed: expected an integer in \[0, 4294967295\], got -1"),
    (f"seed: {2**64 + 1}\n", r"seed: expected an integer in \[0, 4294967295\]"),
    ("seed: 1.5\n", r"seed: expected an integer, got 1.5"),
    ("calibrator:\n  estimator: !KalmanFilter {}\n",
     r"calibrator.estimator: unknown type tag !KalmanFilter; expected one of !ManifoldFilter, "
     r"!PaperFilter, !TargetFilter"),
    ("calibrator:\n  estimator: !PaperFilter {initial_variances: [1, 2, 3]}\n",
     r"calibrator.estimator.initial_variances: needs 12 variances"),
    ("calibrator:\n  estimator: !TargetFilter {gate_probability: 1.5}\n",
     r"calibrator.estimator.gate_probability: must be < 1"),
    ("target:\n  points: [[0, 0, 0], [1, 0]]\n", r"target.points\[1\]\[1\]|target.points"),
    ("target:\n  points: [[0, 0, 0], [1, 0, 0]]\n", "target.points: needs at least 3"),
    ("duration: 0\n", "duration: must be finite and > 0"),
    ("duration: 1e9\n", "duration: 1e\\+09 s is longer than"),
    ("plant_config:\n  time_step: 1e-300\n", "plant_config.time_step: 1e-300 s is below"),
    ("camera:\n  sensor:\n    fps: -30\n", "camera.sensor.fps"),
    ("camera:\n  sensor:\n    fps: 1e9\n", r"^scenario: camera.sensor.fps: 1e\+09 frames per second is "
     r"beyond the 1000 a simulated camera may run at \(cameras run at 5–120\)$"),
    ("camera:\n  sensor:\n    fps: 1e5\n", r"^scenario: camera.sensor.fps: 100000 frames per second is "
     "beyond the 1000"),
    ("camera:\n  sensor:\n    fps: 1000.5\n", "^scenario: camera.sensor.fps: 1000.5 frames per second"),
    ("camera:\n  axes_angle_deg: 0\n", "camera.axes_angle_deg"),
    ("servo:\n  self_calibration: []\n", "at least 2 motions"),
    ("X_EC_guess:\n  rotation: !Uniform {}\n", "X_EC_guess: expected a deterministic pose"),
    ("a: [1, 2\n", r"^scenario: not a valid scenario YAML file"),
    ("seed: !!python/object/apply:os.system ['true']\n", "^scenario: not a valid scenario YAML"),
    ("- 1\n- 2\n", "expected a mapping of scenario fields"),
    ("", "empty"),
])
def test_invalid_scenarios_name_the_field(yaml, message):
    with pytest.raises(ValueError, match=message):
        load_scenario(text=yaml)


def test_errors_name_the_file_and_the_line_of_bad_bytes(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("servo:\n  gian: 0.8\n")
    with pytest.raises(ValueError, match=rf"^{path}: servo.gian: unknown field; did you mean "
                                         r"'gain'\?$"):
        load_scenario(path)
    path.write_bytes(b"seed: 1\nname: \xff\xfe\n")
    with pytest.raises(ValueError, match=rf"^{path}:2: not UTF-8 text"):
        load_scenario(path)


@pytest.mark.parametrize("yaml, message", [
    ("target:\n  X_WT:\n    translation: [-0.47, -0.10, 1.5]\n", "behind the camera"),
    ("arm:\n  q0_deg: [0, 0]\n", "arm.q0_deg: expected 6 joint angles"),
])
def test_scenarios_that_cannot_run_fail_before_simulating(yaml, message):
    with pytest.raises(ValueError, match=message):
        build_diagram(load_scenario(text=yaml))

"""The closed loop with a rendered camera (``camera.model: !RenderedImages``): Drake renders the
board (RgbdSensor, RenderEngineVtk through EGL), ``TargetDetector`` measures each frame, and the
servo and the calibrator take their measurements from it.

Runs are short (self-calibration 2 × 1.2 s, servo gain 1.5) to keep the file fast: four
simulations, about 16 s of simulated time in all.
"""

import json

import cv2
import numpy as np
import pytest

from handeye_drake.apps.cli import main
from handeye_drake.estimation.configs import ManifoldFilter, TargetFilter
from handeye_drake.estimation.se3 import inverse, rotation_log
from handeye_drake.scenario import (
    RENDERED_PIXEL_SIGMA,
    RenderedImages,
    default_feature_ids,
    dump_scenario,
    load_scenario,
    transform_matrix,
)
from handeye_drake.simulation import build_diagram, desired_features, intrinsics_of, run_scenario
from handeye_drake.systems.calibrator import STATUS_COLLECTING, STATUS_FILTERING
from handeye_drake.systems.camera_pose import HandCameraPose
from handeye_drake.systems.frame_recorder import FrameRecorder
from handeye_drake.systems.servo import STATUS_TOO_FEW_VISIBLE
from handeye_drake.systems.trigger_sampler import CameraTriggerSampler
from handeye_drake.vision.detection import project_with_jacobian
from handeye_drake.vision.targets import object_points, parse_target

# The board face up on the table (z_T into the board), its centre where the default camera
# looks; the desired view 0.35 m above its centre, rolled 25° about the optical axis.
BOARD = """
target:
  X_WT: {translation: [-0.561, -0.06927, 0.0], rotation: !Rpy {deg: [180, 0, 20]}}
"""
DESIRED = """
servo:
  gain: 1.5
  X_TC_desired: {translation: [0.075, 0.06, -0.35], rotation: !Rpy {deg: [0, 0, 25]}}
"""
# Two 20° rotations about the camera's x and y axes through a point 0.45 m ahead (the board
# stays in view).
NOMINAL = BOARD + DESIRED + """
  self_calibration:
    - {axis_C: [1, 0, 0], angle_deg: 20.0, pivot_distance: 0.45, duration: 1.2}
    - {axis_C: [0, 1, 0], angle_deg: 20.0, pivot_distance: 0.45, duration: 1.2}
duration: 6.0
camera:
  model: !RenderedImages {frames_to_save: [0.0, 0.5, 5.95]}
"""
# A 30° rotation about the camera centre moves the board out of the image (lost from 0.43 s);
# the next one turns back (found again at 2.1 s); a third rotates about y.
LOST = BOARD + DESIRED + """
  self_calibration:
    - {axis_C: [1, 0, 0], angle_deg: 30.0, pivot_distance: 0.0, duration: 1.2}
    - {axis_C: [1, 0, 0], angle_deg: -30.0, pivot_distance: 0.0, duration: 1.2}
    - {axis_C: [0, 1, 0], angle_deg: 20.0, pivot_distance: 0.45, duration: 1.2}
duration: 7.2
camera:
  model: !RenderedImages {frames_to_save: []}
"""


def measurement_errors(r):
    """Errors [δθ (rad); δt (m)] of the found X_CT samples against the truth (from the robot
    pose sampled when the image was taken), and their log indices (index 0, before the first
    trigger, left out)."""
    X_WT = transform_matrix(r.scenario.target.X_WT, "target.X_WT")
    errors, rows = [], []
    for k in range(1, len(r.times)):
        if r.detector_found[k] > 0.5:
            X_CT_true = inverse(r.X_BE_samples[k] @ r.X_EC_true) @ X_WT
            X_CT = r.X_CT_samples[k]
            errors.append(np.concatenate([rotation_log(X_CT_true[:3, :3] @ X_CT[:3, :3].T),
                                          X_CT_true[:3, 3] - X_CT[:3, 3]]))
            rows.append(k)
    return np.array(errors), np.array(rows)


@pytest.fixture(scope="module")
def nominal():
    return run_scenario(load_scenario(text=NOMINAL))


@pytest.fixture(scope="module")
def lost():
    return run_scenario(load_scenario(text=LOST))


def test_the_detector_recovers_the_true_target_pose_on_rendered_frames(nominal):
    r = nominal
    assert np.all(r.detector_found == 1.0) and np.all(r.detector_num_points == 12)
    E, rows = measurement_errors(r)
    rotation_deg = np.degrees(np.linalg.norm(E[:, :3], axis=1))
    translation_mm = 1e3 * np.linalg.norm(E[:, 3:], axis=1)
    depth = r.X_CT_samples[rows, 2, 3]
    assert 0.34 < depth.min() and depth.max() < 0.47  # the board 0.35–0.45 m away
    # 180 frames at 0.35–0.45 m (fx = 800 px, one sample per pixel), measured: rotation RMS
    # 0.064°, max 0.17°; translation RMS 0.10 mm, max 0.34 mm.
    assert np.sqrt(np.mean(rotation_deg**2)) < 0.1 and rotation_deg.max() < 0.3
    assert np.sqrt(np.mean(translation_mm**2)) < 0.15 and translation_mm.max() < 0.5
    # The corners fit the pose to a few hundredths of a pixel (measured median 0.029 px).
    assert np.median(r.reprojection_rms_px) < 0.04
    # The detector's covariance covers its errors: mean NEES 6 would be consistent; measured
    # 0.41, its pixel noise being floored at RENDERED_PIXEL_SIGMA = 0.1 px (the residuals say
    # 0.03 px) because the errors repeat from frame to frame (see scenario.py).
    nees = [e @ np.linalg.solve(r.detector_covariance[k], e) for e, k in zip(E, rows)]
    # Both ways (measured 0.41): a covariance 1.7× larger or 2.4× smaller falls outside.
    assert 0.25 < np.mean(nees) < 1.0
    # No frame outside the 99.9 % ellipsoid (χ²(6) 22.5; measured max 1.5): the robot pose
    # paired with each image is the one it was rendered from. (Sampled by a ZeroOrderHold, it
    # was one 2 ms plant step late every third frame: NEES 200–1300 on those frames.)
    assert max(nees) < 22.5


def test_the_rendered_loop_converges_and_the_calibrator_beats_its_two_motion_start(nominal):
    r = nominal
    assert r.calibrator_mode == STATUS_FILTERING and r.diagnostics == []
    # From 157 px to below 1.5 px in 3.6 s of servoing (measured 0.92 px).
    assert r.feature_error_px[0] > 100 and r.feature_error_px[-1] < 1.5
    # Measured: two-motion 0.172° / 2.17 %, final 0.019° / 0.20 %.
    assert r.rotation_error_deg[-1] < 0.5 * r.initial_rotation_error_deg
    assert r.translation_error_rel[-1] < 0.5 * r.initial_translation_error_rel
    assert r.rotation_error_deg[-1] < 0.05 and r.translation_error_rel[-1] < 0.005
    # The standard deviation the calibrator reports covers its error.
    assert r.rotation_error_deg[-1] < 3 * np.linalg.norm(r.X_EC_std[-1, :3])
    # Every frame used: one update per frame but the first (it initializes the target pose),
    # none rejected (log 0 is the initialization, log 1 repeats the frame at t = 0).
    assert r.calibrator_status[-1, 1] == len(r.times) - 2 and r.calibrator_status[-1, 2] == 0
    # The servo's features are the board's outer corners, desired where s* says.
    ids = default_feature_ids(parse_target(r.scenario.camera.model.target))
    assert ids == [0, 3, 11, 8]
    np.testing.assert_allclose(r.features[-1], r.desired_features, atol=1.5)


def test_saved_frames_are_the_detectors_frames(nominal):
    r = nominal
    assert [f.index for f in r.frames] == [0, 1, 2]
    period = r.scenario.period
    for frame, requested in zip(r.frames, (0.0, 0.5, 5.95)):
        assert frame.requested_time == requested
        # The first camera trigger at or after the requested time.
        assert requested - 1e-9 <= frame.time < requested + period
        assert frame.image.shape == (480, 640, 4) and frame.image.dtype == np.uint8
        assert frame.detection.found
        # Logs at t_k hold what was measured at the trigger before (Drake publishes before the
        # updates of the same instant): the loop's measurement of this frame is the next log.
        k = int(round(frame.time / period)) + 1
        np.testing.assert_array_equal(frame.detection.X_CT, r.X_CT_samples[k])
        drawn = frame.drawn(intrinsics_of(r.scenario))
        assert drawn.shape == (480, 640, 3)
        assert not np.array_equal(drawn, cv2.cvtColor(frame.image, cv2.COLOR_RGBA2BGR))


def test_a_lost_board_is_skipped_and_the_loop_recovers(lost):
    r = lost
    found = r.detector_found > 0.5
    # Found, then lost for a while (the first self-calibration rotation), then found again.
    changes = np.flatnonzero(np.diff(found.astype(int)))
    assert len(changes) == 2 and found[0] and not found[changes[0] + 1] and found[-1]
    lost_frames = ~found
    assert lost_frames.sum() >= 40  # measured 50 frames, 0.43–2.1 s
    assert np.all(r.phase[lost_frames] < len(r.scenario.servo.self_calibration))
    # While lost the servo sees no usable feature (the detector holds stale pixels with
    # visible = 0) and its command is exactly the self-calibration twist: no jump.
    assert np.all(r.servo_status[lost_frames] == STATUS_TOO_FEW_VISIBLE)
    for k in np.flatnonzero(lost_frames):
        same_phase = np.flatnonzero(found & (r.phase == r.phase[k]))
        np.testing.assert_array_equal(r.V_WE_E_command[k], r.V_WE_E_command[same_phase[-1]])
        assert np.linalg.norm(r.V_WE_E_command[k][:3]) > 0.4  # 30° in 1.2 s
    # The calibrator skipped the lost frames: one update per found frame but the first, as
    # without loss (log 0 is the initialization), none rejected.
    assert r.calibrator_status[-1, 1] == found[1:].sum() - 1 and r.calibrator_status[-1, 2] == 0
    assert r.calibrator_mode == STATUS_FILTERING
    # The end is converged and calibrated (measured: 0.83 px; 0.23° / 3.0 % → 0.011° / 0.39 %).
    assert r.feature_error_px[-1] < 1.5
    assert r.rotation_error_deg[-1] < 0.5 * r.initial_rotation_error_deg
    assert r.translation_error_rel[-1] < 0.5 * r.initial_translation_error_rel
    assert r.diagnostics == []


def test_a_board_lost_in_the_servo_phase_stops_the_servo():
    """The second self-calibration rotation ends with the board out of view: the servo phase
    starts blind, its command is zero and the arm holds still; the calibrator never gets the
    last key frame and says why."""
    s = load_scenario(text=BOARD + DESIRED + """
  self_calibration:
    - {axis_C: [0, 1, 0], angle_deg: 10.0, pivot_distance: 0.45, duration: 0.6}
    - {axis_C: [1, 0, 0], angle_deg: 30.0, pivot_distance: 0.0, duration: 1.2}
duration: 2.5
camera:
  model: !RenderedImages {frames_to_save: []}
""")
    r = run_scenario(s)
    servoing = r.phase == 2
    assert servoing.sum() >= 2
    assert np.all(r.detector_found[servoing] == 0.0)
    assert np.all(r.servo_status[servoing] == STATUS_TOO_FEW_VISIBLE)
    assert np.all(r.V_WE_E_command[servoing] == 0.0)
    # The camera comes to rest where the last self-calibration motion left it: the arm catches
    # up its tracking lag with steps that only shrink (no jump; measured 0.53° and 0.13 mm in
    # all with the pose command, 0.26° and 0.18 mm with the twist driver), then stays still.
    X_WC = r.X_WC[servoing]
    steps_deg = [np.degrees(np.linalg.norm(rotation_log(b[:3, :3] @ a[:3, :3].T)))
                 for a, b in zip(X_WC[:-1], X_WC[1:])]
    assert np.all(np.diff(steps_deg[:6]) < 0) and sum(steps_deg) < 0.7
    assert np.linalg.norm(X_WC[-1][:3, 3] - X_WC[0][:3, 3]) < 0.3e-3
    assert max(steps_deg[-8:]) < 1e-6
    assert r.calibrator_mode == STATUS_COLLECTING
    assert any("does not find the board at the end" in d for d in r.diagnostics)


def test_rendered_scenarios_are_validated_with_the_field_path():
    base = BOARD + "servo:\n  X_TC_desired: {translation: [0.075, 0.06, -0.35]}\n"
    for yaml, message in [
        ("camera:\n  model: !RenderedImages {target: 'charuco:5x4:0.03'}\n",
         "camera.model.target: "),
        ("camera:\n  model: !RenderedImages {feature_ids: [0, 3, 99]}\n",
         r"camera.model.feature_ids: \[99\] are not points"),
        ("camera:\n  model: !RenderedImages {feature_ids: [0, 1, 2]}\n",
         "camera.model.feature_ids: the points .* are on one line"),
        ("camera:\n  model: !RenderedImages {feature_ids: [0, 0, 5]}\n",
         "camera.model.feature_ids: needs at least 3 distinct"),
        ("camera:\n  model: !RenderedImages {supersample: 0}\n", "camera.model.supersample"),
        ("camera:\n  model: !RenderedImages {frames_to_save: [-1.0]}\n",
         r"camera.model.frames_to_save\[0\]"),
        ("camera:\n  model: !RenderedImages {supersampel: 2}\n",
         "camera.model.supersampel: unknown field; did you mean 'supersample'"),
        ("camera:\n  axes_angle_deg: 80\n  model: !RenderedImages {}\n",
         "camera.axes_angle_deg: a rendered camera has no skew"),
        ("camera:\n  sensor: {clipping_far: 0.3}\n  model: !RenderedImages {}\n",
         r"servo.X_TC_desired: the board at 0.35 m is outside the camera's clipping range"),
        ("camera:\n  model: !RenderedImages {use_detector_covariance: true}\n"
         "calibrator:\n  estimator: !ManifoldFilter {}\n",
         "camera.model.use_detector_covariance: only the !TargetFilter"),
    ]:
        with pytest.raises(ValueError, match=message):
            load_scenario(text=base + yaml)


def test_rendered_runs_are_reproducible_and_round_trip_through_yaml():
    s = load_scenario(text=NOMINAL.replace("[0.0, 0.5, 5.95]", "[0.1]"))
    s.duration = 0.2
    a, b = run_scenario(s), run_scenario(s)
    np.testing.assert_array_equal(a.X_CT_samples, b.X_CT_samples)
    np.testing.assert_array_equal(a.frames[0].image, b.frames[0].image)
    text = dump_scenario(s)
    assert "!RenderedImages" in text and dump_scenario(load_scenario(text=text)) == text


def test_the_estimator_noise_of_a_rendered_camera():
    s = load_scenario(text=BOARD + "camera:\n  model: !RenderedImages {}\n" + DESIRED)
    c = s.estimator_config()
    assert isinstance(c, TargetFilter) and not c.use_measurement_covariance
    # The largest standard deviations of the PnP covariance of the 12 corners at the desired
    # view, with RENDERED_PIXEL_SIGMA px per coordinate.
    X_CT = inverse(transform_matrix(s.servo.X_TC_desired, "servo.X_TC_desired"))
    _, J = project_with_jacobian(X_CT, object_points(parse_target(s.camera.model.target))[1],
                                 intrinsics_of(s))
    std = RENDERED_PIXEL_SIGMA * np.sqrt(np.diag(np.linalg.inv(J.T @ J)))
    assert (c.rotation_sigma, c.translation_sigma) == pytest.approx((std[:3].max(),
                                                                     std[3:].max()))
    assert 0.002 < c.rotation_sigma < 0.01 and 1e-4 < c.translation_sigma < 1e-3
    s.camera.model.use_detector_covariance = True
    assert s.estimator_config().use_measurement_covariance
    s.calibrator.estimator = ManifoldFilter()
    with pytest.raises(ValueError, match="use_detector_covariance"):
        s.validate()


def test_default_feature_ids_are_the_outer_corners():
    for spec, ids in [("chessboard:9x6:0.02", [0, 8, 53, 45]),
                      ("charuco:5x4:0.03:0.022:DICT_5X5_100", [0, 3, 11, 8]),
                      ("apriltag:36h11:0.05:3", [12, 13, 14, 15]),
                      ("aprilgrid:36h11:3x2:0.04:0.3", [0, 9, 22, 15])]:
        assert default_feature_ids(parse_target(spec)) == ids, spec
    s = load_scenario(text=BOARD + "camera:\n  model: !RenderedImages {feature_ids: [1, 4, 6]}"
                      + "\n" + DESIRED)
    assert isinstance(s.camera.model, RenderedImages)
    p = s.camera.model.feature_points_T()
    np.testing.assert_array_equal(p, object_points(parse_target(s.camera.model.target))[1][
        [1, 4, 6]])
    assert desired_features(s).shape == (6,)


def test_simulate_writes_the_rendered_frames(tmp_path, capsys):
    scenario = tmp_path / "rendered.yaml"
    scenario.write_text(NOMINAL.replace("[0.0, 0.5, 5.95]", "[0.0, 0.1, 9.0]"))
    out = tmp_path / "out"
    assert main(["simulate", "--scenario", str(scenario), "--duration", "0.3", "--out", str(out),
                 "--no-progress", "--no-meshcat"]) == 0
    stdout = capsys.readouterr().out
    assert sorted(p.name for p in (out / "frames").iterdir()) == ["frame_000.png",
                                                                   "frame_001.png"]
    image = cv2.imread(str(out / "frames" / "frame_001.png"))
    assert image.shape == (480, 640, 3)
    assert "detector: board found in 9 of 9 frames" in stdout
    assert "frames_to_save: no frame at 9 s" in stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["detector_found_frames"] == summary["detector_frames"] == 9
    manifest = json.loads((out / ".handeye-drake-output.json").read_text())
    assert "frames/frame_000.png" in manifest["files"]


def test_the_rendered_loop_is_built_from_drakes_camera_fields():
    s = load_scenario(text=BOARD + """
camera:
  sensor: {width: 320, height: 240, focal: !FocalLength {x: 400.0, y: 400.0}, center_x: 160.0,
           center_y: 120.0, clipping_near: 0.05, clipping_far: 3.0, fps: 15.0,
           X_PB: {translation: [0.04, -0.03, 0.06], rotation: !Rpy {deg: [4, -3, 92]}}}
  model: !RenderedImages {supersample: 2}
""" + DESIRED)
    loop = build_diagram(s, with_loggers=False)
    config = loop.camera.rendered.config
    # Rendered at 2× and averaged down; Drake's half pixel added to the principal point.
    assert (config.width, config.height) == (640, 480)
    assert (config.focal_x(), config.center_x, config.center_y) == (800.0, 321.0, 241.0)
    assert (config.clipping_near, config.clipping_far) == (0.05, 3.0)
    assert loop.camera.detector.period == pytest.approx(1 / 15)
    assert loop.camera.rendered.intrinsics.width == 320
    # One sampler of the trigger instant (X_WC and X_BE from the plant's body poses): no pose
    # sensor or separate robot-pose sampler.
    names = {system.get_name() for system in loop.diagram.GetSystems()}
    assert "camera_pose" in names and not {"ee_sensor", "robot_pose_sampler"} & names


def test_the_loop_systems_refuse_bad_arguments():
    with pytest.raises(ValueError, match="size: expected an integer ≥ 1"):
        CameraTriggerSampler(0.1, 0)
    with pytest.raises(ValueError, match="period"):
        CameraTriggerSampler(0.0, 12)
    with pytest.raises(ValueError, match=r"times\[1\]: expected a finite time ≥ 0 s"):
        FrameRecorder([0.0, -1.0], 0.1)
    with pytest.raises(ValueError, match="times: expected a list of times"):
        FrameRecorder(["soon"], 0.1)
    with pytest.raises(ValueError, match="X_EC"):
        HandCameraPose(np.zeros((4, 4)), 0.1)

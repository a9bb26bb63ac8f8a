"""The calibrator system alone (``systems.calibrator``): its steps are the estimator classes'
steps, for every estimator; the start-up; what it reports."""

import math

import numpy as np
import pytest
from pydrake.common import RandomGenerator
from pydrake.systems.analysis import Simulator

from handeye_drake import rotation_error_deg
from handeye_drake.estimation.configs import ManifoldFilter, PaperFilter, TargetFilter
from handeye_drake.estimation.se3 import (
    inverse,
    make_transform,
    pose_to_vector,
    rotation_exp,
    vector_to_pose,
)
from handeye_drake.estimation.startup import start_estimator, two_motion_estimate
from handeye_drake.estimation.synthetic import pose_dataset
from handeye_drake.simulation import build_calibrator_bench
from handeye_drake.systems.calibrator import (
    STATUS_COLLECTING,
    STATUS_FILTERING,
    STATUS_INIT_FAILED,
    HandEyeCalibrator,
)

# Every estimator, with non-zero process noise so that every term of its update matters.
ESTIMATORS = {
    "target": TargetFilter(rotation_sigma=0.004, translation_sigma=0.05,
                           process_variances=[1e-6] * 6),
    "manifold": ManifoldFilter(rotation_sigma=0.01, translation_sigma=0.2,
                               initial_variances=[1e-2] * 3 + [100.0] * 3,
                               process_variances=[1e-6] * 6),
    "manifold_ml_start": ManifoldFilter(rotation_sigma=0.01, translation_sigma=0.2,
                                        start="ml", process_variances=[1e-6] * 6),
    "paper": PaperFilter(rotation_coefficient_sigma=0.01, translation_sigma=0.15,
                         initial_variances=[1e-2] * 9 + [100.0] * 3,
                         process_variances=[1e-8] * 12),
    "paper_exact": PaperFilter(noise_covariance="exact", rotation_coefficient_sigma=0.01,
                               translation_sigma=0.15,
                               initial_variances=[1e-2] * 9 + [100.0] * 3,
                               process_variances=[1e-8] * 12, replay_self_calibration=True),
}


@pytest.mark.parametrize("name", list(ESTIMATORS))
def test_calibrator_steps_are_the_estimator_class_steps(name):
    """The system stepped through a self-calibration (phases 0, 1, then servoing) and 30 more
    noisy samples; the same samples through the estimator class (two-motion start, replay,
    updates): the state vector the system ends with is bit-identical to the class's, after every
    step."""
    rng = np.random.default_rng(5)
    X_EC = make_transform(rotation_exp(rng.normal(size=3)), rng.normal(0.0, 10.0, 3))
    X_BE, X_CT = pose_dataset(rng, X_EC, 36, rotation_scale=0.4, translation_scale=5.0)
    X_CT = [make_transform(rotation_exp(0.004 * rng.normal(size=3)) @ X[:3, :3],
                           X[:3, 3] + 0.05 * rng.normal(size=3)) for X in X_CT]
    phases = [0, 0, 1, 1, 2] + [2] * 31
    config = ESTIMATORS[name]
    sys = HandEyeCalibrator(0.1, np.eye(4), config, max_self_calibration_samples=8)
    context = sys.CreateDefaultContext()
    est = None
    for k, phase in enumerate(phases):
        _step(sys, context, X_BE[k], X_CT[k], phase)
        if k == 4:  # key frames: the first sample and the first of each new phase
            keys = [0, 2, 4]
            X_CE0 = two_motion_estimate([X_BE[i] for i in keys], [X_CT[i] for i in keys])
            start = start_estimator(config, X_CE0, X_BE[:5], X_CT[:5])
            est = start.estimator
            if not start.used_samples:
                est.update(X_BE[k], X_CT[k])
            np.testing.assert_array_equal(vector_to_pose(
                sys.get_two_motion_output_port().Eval(context)), inverse(X_CE0))
        elif k > 4:
            est.update(X_BE[k], X_CT[k])
        if est is not None:
            np.testing.assert_array_equal(sys.estimator(context).to_vector(), est.to_vector())
    status = sys.get_status_output_port().Eval(context)
    assert status[0] == STATUS_FILTERING and status[1] == est.num_updates > 20
    np.testing.assert_array_equal(vector_to_pose(sys.get_X_CE_output_port().Eval(context)),
                                  est.X_CE)
    # The σ outputs: the estimator's, scaled by the noise the innovations show (nan: refused,
    # the gate rejecting a large share of the measurements of this data set).
    scale = sys._noise_scale(est.to_vector())
    np.testing.assert_array_equal(sys.get_X_EC_std_output_port().Eval(context),
                                  np.concatenate([est.X_EC_rotation_std_deg,
                                                  est.X_EC_translation_std]) * math.sqrt(scale))
    np.testing.assert_array_equal(sys.get_X_EC_covariance_output_port().Eval(context),
                                  est.X_EC_covariance.reshape(36) * scale)
    assert sys.estimator_config == config.validated()


@pytest.mark.parametrize("noise", ["so3", "paper"])
def test_calibrator_runs_in_the_papers_bench(noise):
    """The calibrator fed by the paper's random motions in a Drake diagram (``PaperMotionSource``,
    noise on the measured camera *motions*, the paper's setting, ‖t_X‖ ≈ 170): the motion-pair
    estimators end closer to X than their two-motion start. With the paper's coefficient noise
    the chained camera poses are far from rigid, so a motion must be formed with the general
    inverse of the poses before its rotation is projected."""
    rng = np.random.default_rng(0)
    X_EC = make_transform(rotation_exp(rng.uniform(0, 2 * np.pi, 3)), rng.normal(0, 100, 3))
    sr = 0.01 if noise == "paper" else 0.01 / np.sqrt(2)
    estimators = {
        "manifold": ManifoldFilter(rotation_sigma=0.01 / np.sqrt(2), translation_sigma=0.1,
                                   initial_variances=[0.01] * 3 + [100.0] * 3),
        "paper_exact": PaperFilter(noise_covariance="exact", rotation_coefficient_sigma=0.01,
                                   translation_sigma=0.1, initial_variances=[1.0] * 12)}
    for name, estimator in estimators.items():
        bench = build_calibrator_bench(X_EC, estimator, period=0.1, pose_noise_model=noise,
                                       camera_rotation_sigma=sr, camera_translation_sigma=0.1)
        simulator = Simulator(bench.diagram)
        context = simulator.get_mutable_context()
        bench.diagram.SetRandomContext(context, RandomGenerator(0))
        simulator.AdvanceTo(10.3)
        X_EC_est = vector_to_pose(bench.loggers["X_EC_estimate"].FindLog(context).data()[:, -1])
        X_EC_two = vector_to_pose(bench.loggers["X_EC_two_motion"].FindLog(context).data()[:, -1])
        assert rotation_error_deg(X_EC, X_EC_est) < 0.75 * rotation_error_deg(X_EC, X_EC_two), \
            name


# ------------------------------------------------------------------------- fixed-input steps
def _poses(rng, X_EC, n, X_BT):
    X_BE = [make_transform(rotation_exp(rng.normal(size=3) * 0.4), rng.normal(size=3) * 0.2)
            for _ in range(n)]
    return X_BE, [inverse(X @ X_EC) @ X_BT for X in X_BE]


def _step(system, context, X_BE, X_CT, phase, valid=None):
    system.get_X_BE_input_port().FixValue(context, pose_to_vector(X_BE))
    system.get_X_CT_input_port().FixValue(context, pose_to_vector(X_CT))
    system.get_phase_input_port().FixValue(context, [float(phase)])
    if valid is not None:
        system.get_X_CT_valid_input_port().FixValue(context, [float(valid)])
    context.SetDiscreteState(system.EvalUniquePeriodicDiscreteUpdate(context))


def test_calibrator_outputs_the_guess_while_collecting():
    X_CE_guess = make_transform(rotation_exp([0.0, 0.0, 0.3]), [0.01, 0.02, 0.03])
    sys = HandEyeCalibrator(0.1, X_CE_guess, ESTIMATORS["target"])
    context = sys.CreateDefaultContext()
    np.testing.assert_allclose(vector_to_pose(sys.get_X_CE_output_port().Eval(context)),
                               X_CE_guess, atol=1e-14)
    np.testing.assert_allclose(vector_to_pose(sys.get_X_EC_output_port().Eval(context)),
                               inverse(X_CE_guess), atol=1e-14)
    assert sys.get_status_output_port().Eval(context)[0] == STATUS_COLLECTING


def test_calibrator_reports_degenerate_self_calibration():
    """Two rotations about the same axis: the classical solver refuses, the status says so, and
    the estimator starts from the guess with a 10× wider standard deviation."""
    X_EC = make_transform(rotation_exp([0.1, -0.2, 1.5]), [0.05, -0.03, 0.07])
    X_BT = make_transform(np.eye(3), [0.6, 0.1, 0.0])
    X_BE = [make_transform(rotation_exp([0.0, 0.0, a]), [0.1, 0.0, 0.0]) for a in (0, 0.3, 0.6)]
    X_CT = [inverse(X @ X_EC) @ X_BT for X in X_BE]
    sys = HandEyeCalibrator(0.1, np.eye(4), ESTIMATORS["manifold"])
    context = sys.CreateDefaultContext()
    for k, phase in enumerate([0, 1, 2]):
        _step(sys, context, X_BE[k], X_CT[k], phase)
    assert sys.get_status_output_port().Eval(context)[0] == STATUS_INIT_FAILED
    assert np.all(np.isfinite(sys.get_X_CE_output_port().Eval(context)))
    std = sys.get_X_EC_std_output_port().Eval(context)
    assert std[0] == pytest.approx(10 * np.degrees(np.sqrt(1e-2)), rel=1e-9)


def _target_calibrator(seed, n):
    """A target-filter calibrator, its context and n consistent samples (X_BE, X_CT)."""
    rng = np.random.default_rng(seed)
    X_EC = make_transform(rotation_exp([0.1, -0.2, 1.5]), [0.05, -0.03, 0.07])
    X_BT = make_transform(rotation_exp([3.0, 0.1, 0.2]), [0.6, 0.1, 0.0])
    X_BE, X_CT = _poses(rng, X_EC, n, X_BT)
    sys = HandEyeCalibrator(0.1, np.eye(4), ESTIMATORS["target"])
    return sys, sys.CreateDefaultContext(), X_BE, X_CT


def test_samples_flagged_invalid_are_skipped():
    sys, context, X_BE, X_CT = _target_calibrator(3, 6)
    for k, phase in enumerate([0, 1, 2]):
        _step(sys, context, X_BE[k], X_CT[k], phase, valid=1)
    before = sys.estimator(context).to_vector()
    wrong = make_transform(rotation_exp([1.0, 0.0, 0.0]), [1.0, 0.0, 0.0])
    _step(sys, context, X_BE[3], wrong, 2, valid=0)  # e.g. the target was not detected
    np.testing.assert_array_equal(sys.estimator(context).to_vector(), before)
    _step(sys, context, X_BE[3], X_CT[3], 2, valid=1)
    assert sys.estimator(context).num_updates > 0


@pytest.mark.parametrize("port", ["X_BE", "X_CT"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_non_finite_input_pose_is_an_error_naming_it(port, bad):
    """Collecting or filtering, a NaN or infinite pose entry raises (it would poison the
    estimate), naming the inputs."""
    sys, context, X_BE, X_CT = _target_calibrator(4, 4)
    for k, phase in enumerate([0, 1, 2, 2]):  # the last: the filtering mode
        poses = {"X_BE": X_BE[k].copy(), "X_CT": X_CT[k].copy()}
        poses[port][1, 3] = bad
        with pytest.raises(ValueError, match="non-finite pose on the X_BE or X_CT_measured"):
            _step(sys, context, poses["X_BE"], poses["X_CT"], phase)
        _step(sys, context, X_BE[k], X_CT[k], phase)
    assert sys.get_status_output_port().Eval(context)[0] == STATUS_FILTERING
    assert sys.estimator(context).num_updates == 1


@pytest.mark.parametrize("kwargs, message", [
    (dict(period=0.0), "period"),
    (dict(X_CE_initial_guess=np.diag([1.0, 1.0, 2.0, 1.0])), "X_CE_initial_guess"),
    (dict(estimator="magic"), "estimator: expected settings of type"),
    (dict(init_method="magic"), "init_method"),
    (dict(num_self_calibration_motions=1), "num_self_calibration_motions"),
    (dict(max_self_calibration_samples=-1), "max_self_calibration_samples"),
    (dict(estimator=TargetFilter(rotation_sigma=0.0, translation_sigma=0.001)),
     "TargetFilter.rotation_sigma"),
    (dict(estimator=TargetFilter(rotation_sigma=0.01)), "TargetFilter.translation_sigma: not set"),
])
def test_calibrator_constructor_errors(kwargs, message):
    args = dict(period=0.1, X_CE_initial_guess=np.eye(4), estimator=ESTIMATORS["target"])
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        HandEyeCalibrator(**args)


@pytest.mark.parametrize("recovery", [5, None])
def test_calibrator_recovers_from_gate_lock_out(recovery):
    """A wrong start with an over-confident P0: every consistent sample fails the NIS gate. With
    the recovery the covariance is inflated after 5 rejections in a row and the estimate
    converges; without it, the estimate stays frozen at the wrong start."""
    rng = np.random.default_rng(7)
    X_EC = make_transform(rotation_exp([0.1, -0.2, 1.5]), [0.05, -0.03, 0.07])
    X_BT = make_transform(rotation_exp([3.0, 0.1, 0.2]), [0.6, 0.1, 0.0])
    X_BE, X_CT = _poses(rng, X_EC, 40, X_BT)
    X_CT_keys = list(X_CT[:3])
    X_CT_keys[2] = make_transform(rotation_exp([0.0, 0.05, 0.0]) @ X_CT[2][:3, :3], X_CT[2][:3, 3])
    config = TargetFilter(rotation_sigma=0.001, translation_sigma=0.0005,
                          initial_variances=[1e-10] * 6, max_consecutive_rejections=recovery)
    sys = HandEyeCalibrator(0.1, np.eye(4), config)
    context = sys.CreateDefaultContext()
    for k, phase in enumerate([0, 1, 2]):
        _step(sys, context, X_BE[k], X_CT_keys[k], phase)
    X_CE_start = vector_to_pose(sys.get_X_CE_output_port().Eval(context))
    assert rotation_error_deg(inverse(X_EC), X_CE_start) > 1.0
    for k in range(3, 40):
        _step(sys, context, X_BE[k], X_CT[k], 2)
    X_CE_end = vector_to_pose(sys.get_X_CE_output_port().Eval(context))
    status = sys.get_status_output_port().Eval(context)
    if recovery:
        assert rotation_error_deg(inverse(X_EC), X_CE_end) < 0.05
        assert status[1] > 20  # accepted
    else:
        np.testing.assert_allclose(X_CE_end, X_CE_start, atol=1e-8)
        assert rotation_error_deg(inverse(X_EC), X_CE_end) > 1.0
        assert status[2] > 30  # rejected
        assert any("rejected" in m for m in sys.estimator(context).diagnostics())

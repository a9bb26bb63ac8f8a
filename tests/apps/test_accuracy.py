"""The accuracy benchmark's pure helpers (``apps.accuracy``)."""

import numpy as np
import pytest

from handeye_drake.estimation.se3 import make_transform


def test_benchmark_summary_statistics_hand_computed():
    from handeye_drake.apps.accuracy import summarize
    errors = [{"a": [1.0, 0.01], "ml": [1.0, 0.01]},
              {"a": [2.0, 0.02], "ml": [0.5, 0.01]},
              {"a": None, "ml": [0.5, 0.03]}]
    s = summarize(errors, "ml")
    assert s["a"]["runs"] == 2 and s["a"]["failures"] == 1
    assert s["a"]["rotation_deg"]["median"] == pytest.approx(1.5)
    assert s["a"]["rotation_deg"]["rms"] == pytest.approx(np.sqrt(2.5))
    assert s["a"]["translation_pct"]["median"] == pytest.approx(1.5)
    assert s["ml"]["rotation_deg"]["median"] == pytest.approx(0.5)
    assert s["a"]["ratio_to_ml"]["rotation"] == pytest.approx(3.0)
    assert s["a"]["ratio_to_ml"]["translation"] == pytest.approx(1.5)


def test_benchmark_motion_noise_from_pose_noise():
    from handeye_drake.apps.accuracy import motion_noise_from_pose_noise
    X_CT = [make_transform(np.eye(3), [0.0, 0.0, 0.5])] * 3
    sr, st = motion_noise_from_pose_noise(X_CT, 0.002, 0.0005)
    assert sr == pytest.approx(np.sqrt(2) * 0.002)
    assert st == pytest.approx(np.sqrt(2 * 0.0005**2 + 4 / 3 * 0.002**2 * 0.25))


def test_benchmark_motion_noise_away_from_the_symmetric_case():
    """Distinct poses (rotated, translations off the axes, distances 0.4 / 0.5 / 0.9 m: the
    median, 0.5, is neither the mean nor the largest), and the formula against the spread of
    motions differenced from noisy poses (RMS over the axes, within 3 % both ways)."""
    from handeye_drake.apps.accuracy import motion_noise_from_pose_noise
    from handeye_drake.estimation.se3 import inverse, rotation_exp
    from handeye_drake.vision.camera_model import apply_pose_noise
    dirs = np.array([[0.3, -0.4, 0.866], [-0.6, 0.0, 0.8], [0.48, 0.6, 0.64]])
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    X_CT = [make_transform(rotation_exp(w), d * r) for w, d, r in
            zip([[0.2, -0.1, 0.3], [2.9, 0.1, -0.2], [-0.3, 0.4, 1.2]], dirs, [0.9, 0.4, 0.5])]
    sr, st = motion_noise_from_pose_noise(X_CT, 0.002, 0.0005)
    assert sr == pytest.approx(np.sqrt(2) * 0.002, rel=1e-12)
    assert st == pytest.approx(np.sqrt(2 * 0.0005**2 + 4 / 3 * 0.002**2 * 0.5**2), rel=1e-12)
    # The so3 pose noise (R = exp(n) R̃, t = t̃ + e; ``apply_pose_noise``), vectorized.
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(4)
    a, b = X_CT[2], make_transform(rotation_exp([0.1, 0.5, -0.2]), dirs[0] * 0.5)  # both at 0.5 m
    N = 20000
    Ra = (Rotation.from_rotvec(0.002 * rng.normal(size=(N, 3))) * Rotation.from_matrix(a[:3, :3]))
    Rb = (Rotation.from_rotvec(0.002 * rng.normal(size=(N, 3))) * Rotation.from_matrix(b[:3, :3]))
    ta = a[:3, 3] + 0.0005 * rng.normal(size=(N, 3))
    tb = b[:3, 3] + 0.0005 * rng.normal(size=(N, 3))
    t_A = ta - (Ra * Rb.inv()).apply(tb)            # translation of a · b⁻¹
    err = t_A - (a @ inverse(b))[:3, 3]
    assert np.sqrt(np.mean(err ** 2)) == pytest.approx(st, rel=0.03)
    one = apply_pose_noise(a, np.r_[np.ones(3), np.zeros(6), np.ones(3)], "so3",
                           0.002, 0.0005)          # the model: exp(n) R̃, t̃ + e
    np.testing.assert_allclose(one[:3, :3], rotation_exp(0.002 * np.ones(3)) @ a[:3, :3],
                               atol=1e-12)
    np.testing.assert_allclose(one[:3, 3], a[:3, 3] + 0.0005 * np.ones(3), atol=1e-12)


def test_benchmark_cli_parser_and_argument_checks():

    from handeye_drake.apps.accuracy import run_accuracy_benchmark
    from handeye_drake.apps.cli import make_parser
    parser = make_parser()
    args = parser.parse_args(["benchmark", "accuracy", "--runs", "3", "--seed", "7",
                              "--settings", "paper", "large", "--json", "out.json"])
    assert (args.runs, args.seed, args.settings, args.json, args.workers) == (
        3, 7, ["paper", "large"], "out.json", 2)
    assert callable(args.func)
    with pytest.raises(SystemExit):
        parser.parse_args(["benchmark", "accuracy", "--settings", "nope"])
    with pytest.raises(ValueError, match="runs"):
        run_accuracy_benchmark(runs=-1)
    with pytest.raises(ValueError, match="noise_levels"):
        run_accuracy_benchmark(noise_levels=[0.0])
    with pytest.raises(ValueError, match="settings"):
        run_accuracy_benchmark(settings=["closed-loop"])

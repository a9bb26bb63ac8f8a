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

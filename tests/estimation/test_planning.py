"""Next-pose planning (``estimation.planning``) and the ``plan`` command: the greedy gain against
brute-force log-determinants, the planner against random choices, the pose that resolves a
SCARA recording's unobservable direction, candidate sampling limits and visibility, and the
command's outputs and errors."""

import json
import math

import numpy as np
import pytest

from handeye_drake.apps.cli import main as cli_main
from handeye_drake.estimation import observability as ob
from handeye_drake.estimation import planning as pl
from handeye_drake.estimation.se3 import (inverse, make_transform, quat_wxyz, rotation_exp,
                                          rotation_from_rpy, rotation_log)
from handeye_drake.recorded.formats import read_poses
from handeye_drake.vision.camera_model import CameraIntrinsics, apply_pose_noise

X_EC = make_transform(rotation_from_rpy(np.radians([1.5, -2.0, 90.0])), [0.045, -0.012, 0.068])
X_CE = inverse(X_EC)
P_BT = np.array([0.55, 0.05, 0.0])
X_BT = make_transform(rotation_exp([math.pi, 0.0, 0.3]), P_BT)
X_BC0 = make_transform(rotation_exp([math.pi, 0.0, 0.0]), P_BT + [0.0, 0.0, 0.45])
X_BE0 = X_BC0 @ X_CE
CAMERA = CameraIntrinsics.from_fov(640, 480, math.radians(50.0))
CORNERS = P_BT + np.array([[0.1, 0.1, 0], [-0.1, 0.1, 0], [0.1, -0.1, 0], [-0.1, -0.1, 0]])
SR, ST = 0.002, 0.001


def _candidates(seed, n=120, max_angle=30.0, max_distance=0.15):
    return pl.sample_candidate_poses(X_BE0, P_BT, n, max_angle, max_distance,
                                     np.random.default_rng(seed), X_HC=X_EC, intrinsics=CAMERA,
                                     p_FQ=CORNERS, margin_px=10.0)


def _log_det(X_BE):
    S = ob.marginal_information(ob.information_matrix(list(X_BE), X_CE, X_BT, SR, ST))
    return np.linalg.slogdet(S)[1]


# ---------------------------------------------------------------------------------------------
# The planner.

def test_greedy_gain_is_the_log_det_increase_of_the_hand_eye_marginal():
    C = _candidates(0, 40)
    samples = list(C[:4])
    brute = [_log_det(samples + [c]) for c in C[4:]]
    # With a negligible prior the gain is the data's log det increase.
    plan = pl.plan_next_poses(C[4:], X_CE, X_BT, samples, SR, ST, n=1, exchange=False,
                              prior_rotation_std=1e4, prior_translation_std=1e4)
    assert plan.indices == [int(np.argmax(brute))]
    assert plan.log_det_gain[0] == pytest.approx(max(brute) - _log_det(samples), abs=1e-7)
    # The default weak prior (1 rad, 1 m) picks the same pose.
    assert pl.suggest_next_poses(C[4:], X_CE, X_BT, samples, SR, ST, n=1) == plan.indices


def test_planner_beats_every_random_choice_and_exchange_improves_greedy():
    C = _candidates(1)
    plan = pl.plan_next_poses(C, X_CE, X_BT, (), SR, ST, n=5)
    greedy = pl.plan_next_poses(C, X_CE, X_BT, (), SR, ST, n=5, exchange=False)
    best = _log_det(C[plan.indices])
    assert best >= _log_det(C[greedy.indices]) - 1e-9
    rng = np.random.default_rng(2)
    random = [_log_det(C[rng.choice(len(C), 5, replace=False)]) for _ in range(50)]
    assert best > max(random)
    # Predicted σ (data only) after the 5 poses, row by row: undetermined with fewer than 3.
    assert np.all(np.isinf(plan.rotation_std_deg[:3]))
    assert np.all(np.isinf(plan.translation_std[:3]))
    rot, tra = ob.hand_eye_std(ob.information_matrix(list(C[plan.indices]), X_CE, X_BT, SR, ST),
                               X_CE)
    np.testing.assert_allclose(plan.rotation_std_deg[-1], rot, rtol=1e-9)
    np.testing.assert_allclose(plan.translation_std[-1], tra, rtol=1e-9)
    assert np.all(np.diff(plan.translation_std[3:], axis=0) <= 1e-12)
    assert pl.suggest_next_poses(C, X_CE, X_BT, (), SR, ST, n=5) == plan.indices


def test_planner_picks_the_tilted_pose_that_a_scara_recording_lacks():
    rng = np.random.default_rng(3)
    R_down = rotation_exp([math.pi, 0.0, 0.0])

    def scara():
        return make_transform(rotation_exp([0.0, 0.0, rng.uniform(-1, 1)]) @ R_down,
                              [0.5, 0.05, 0.45] + rng.uniform(-0.1, 0.1, 3))
    samples = [scara() for _ in range(10)]
    assert ob.observability_report(samples, X_CE, X_BT, SR, ST).unobservable
    candidates = [scara() for _ in range(30)]
    tilted = make_transform(rotation_exp([0.3, 0.0, 0.0]) @ candidates[7][:3, :3],
                            candidates[7][:3, 3])
    candidates.insert(12, tilted)
    plan = pl.plan_next_poses(candidates, X_CE, X_BT, samples, SR, ST, n=2)
    assert plan.indices[0] == 12
    assert plan.translation_std[0, 2] == math.inf and plan.translation_std[1, 2] < 0.01
    # With tz known, the planner ranks the others for the five free components: tz stays 0.
    fixed = pl.plan_next_poses(candidates, X_CE, X_BT, samples, SR, ST, n=2, fixed=("tz",))
    assert fixed.translation_std[0, 2] == 0.0 and np.all(np.isfinite(fixed.translation_std[0]))


def test_planner_respects_visibility_and_rejects_bad_input():
    C = _candidates(4, 30)
    mask = np.zeros(30, bool)
    mask[[3, 8, 20]] = True
    assert sorted(pl.suggest_next_poses(C, X_CE, X_BT, (), SR, ST, n=3, visibility=mask)) == \
        [3, 8, 20]
    far = [i for i, c in enumerate(C) if c[2, 3] > X_BE0[2, 3]]
    picks = pl.suggest_next_poses(C, X_CE, X_BT, (), SR, ST, n=2,
                                  visibility=lambda X: X[2, 3] > X_BE0[2, 3])
    assert set(picks) <= set(far)
    with pytest.raises(ValueError, match="n: asked for 4 poses but only 3 of 30 candidates"):
        pl.suggest_next_poses(C, X_CE, X_BT, (), SR, ST, n=4, visibility=mask)
    with pytest.raises(ValueError, match="visibility: expected 30 booleans"):
        pl.suggest_next_poses(C, X_CE, X_BT, (), SR, ST, n=1, visibility=[True])
    with pytest.raises(ValueError, match=r"n: expected an integer ≥ 1, got 0"):
        pl.suggest_next_poses(C, X_CE, X_BT, (), SR, ST, n=0)
    with pytest.raises(ValueError, match="fixed: unknown component"):
        pl.suggest_next_poses(C, X_CE, X_BT, (), SR, ST, fixed=("z",))
    with pytest.raises(ValueError, match="candidates_X_BE: no candidate poses"):
        pl.suggest_next_poses([], X_CE, X_BT, (), SR, ST)
    with pytest.raises(ValueError, match=r"candidates_X_BE\[1\]"):
        pl.suggest_next_poses([C[0], np.eye(3)], X_CE, X_BT, (), SR, ST, n=1)


# ---------------------------------------------------------------------------------------------
# Candidates.

def test_sampled_candidates_respect_the_limits_and_look_at_the_target():
    C = _candidates(5, 200, max_angle=25.0, max_distance=0.1)
    assert C.shape == (200, 4, 4)
    for X in C:
        assert np.linalg.norm(rotation_log(X[:3, :3] @ X_BE0[:3, :3].T)) <= math.radians(25) + 1e-12
        assert np.linalg.norm(X[:3, 3] - X_BE0[:3, 3]) <= 0.1 + 1e-12
        X_BC = X @ X_EC
        d = (P_BT - X_BC[:3, 3]) / np.linalg.norm(P_BT - X_BC[:3, 3])
        assert X_BC[:3, 2] @ d == pytest.approx(1.0, abs=1e-12)  # optical axis on the target
        p_C = (inverse(X_BC) @ np.c_[CORNERS, np.ones(4)].T)[:3].T
        uv = p_C[:, :2] / p_C[:, 2:] * CAMERA.alpha_u + [CAMERA.u0, CAMERA.v0]
        assert np.all((uv >= 10) & (uv <= [630, 470]))
    # Reproducible from the seed, and the rotations spread over the allowed range.
    np.testing.assert_array_equal(C, _candidates(5, 200, max_angle=25.0, max_distance=0.1))
    angles = [np.degrees(np.linalg.norm(rotation_log(X[:3, :3] @ X_BE0[:3, :3].T))) for X in C]
    assert max(angles) > 20.0


def test_candidate_sampling_errors_name_the_cause():
    rng = np.random.default_rng(6)
    away = make_transform(np.eye(3), P_BT + [0, 0, 0.45]) @ X_CE  # camera looking up
    with pytest.raises(ValueError, match=r"only 0 of 5 candidates found in 100 draws "
                       r"\(rejected: 100 by the view test\)"):
        pl.sample_candidate_poses(away, P_BT, 5, 10, 0.05, rng, intrinsics=CAMERA,
                                  X_HC=X_EC, mode="eye_to_hand", p_FQ=CORNERS, max_attempts=100)
    with pytest.raises(ValueError, match="max_angle_deg: must be ≤ 180"):
        pl.sample_candidate_poses(X_BE0, P_BT, 5, 200, 0.1, rng)
    with pytest.raises(ValueError, match="max_distance: must be finite and > 0"):
        pl.sample_candidate_poses(X_BE0, P_BT, 5, 20, 0.0, rng)
    with pytest.raises(ValueError, match="X_HC: needed with intrinsics"):
        pl.sample_candidate_poses(X_BE0, P_BT, 5, 20, 0.1, rng, intrinsics=CAMERA)
    with pytest.raises(ValueError, match="rng: expected a numpy.random.Generator"):
        pl.sample_candidate_poses(X_BE0, P_BT, 5, 20, 0.1, 0)
    with pytest.raises(ValueError, match="p_FT"):
        pl.sample_candidate_poses(X_BE0, [1.0, 2.0], 5, 20, 0.1, rng)


# ---------------------------------------------------------------------------------------------
# The command.

def _tum(path, X_list, t0=0.0):
    lines = []
    for k, X in enumerate(X_list):
        w, x, y, z = quat_wxyz(X[:3, :3])
        lines.append(f"{t0 + 0.1 * k:.3f} {X[0, 3]:.9f} {X[1, 3]:.9f} {X[2, 3]:.9f} "
                     f"{x:.12f} {y:.12f} {z:.12f} {w:.12f}")
    path.write_text("\n".join(lines) + "\n")


def _pose_arg(X):
    w, x, y, z = quat_wxyz(X[:3, :3])
    return ",".join(f"{v:.12g}" for v in [*X[:3, 3], x, y, z, w])


def test_plan_command_from_a_recording(tmp_path, capsys):
    rng = np.random.default_rng(7)
    recorded = list(_candidates(8, 8))
    X_CT = [apply_pose_noise(X_CE @ inverse(x) @ X_BT, rng.normal(size=12), "so3", SR, 0.0005)
            for x in recorded]
    _tum(tmp_path / "robot.tum", recorded)
    _tum(tmp_path / "camera.tum", X_CT)
    out = tmp_path / "out"
    fx = CAMERA.alpha_u
    assert cli_main(["plan", "--robot", str(tmp_path / "robot.tum"), "--camera",
                          str(tmp_path / "camera.tum"), "--around", _pose_arg(X_BE0),
                          "--max-angle", "30", "--max-distance", "0.15", "--n", "4",
                          "--num-candidates", "150", "--intrinsics",
                          f"{fx},{fx},320,240,640,480", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "estimates from fit of 8 recorded samples" in text
    assert "every direction is well determined" in text
    poses = read_poses(out / "next_poses.tum", "robot")
    assert len(poses) == 4 and list(poses.timestamps) == [1, 2, 3, 4]
    result = json.loads((out / "plan.json").read_text())
    assert result["num_samples"] == 8 and len(result["next_poses"]) == 4
    np.testing.assert_allclose(result["X_EC_estimate"], X_EC, atol=0.01)
    # The noise estimated from the residuals is the simulated one within a factor 1.5.
    assert 1 / 1.5 < result["rotation_sigma_rad"] / SR < 1.5
    after = [max(s["translation_std_m"]) for s in result["next_poses"]]
    assert max(result["std_now"]["translation_m"]) > after[0] > after[-1]
    for k, step in enumerate(result["next_poses"]):
        np.testing.assert_allclose(step["X_BE_xyz"], poses.poses[k][:3, 3], atol=1e-6)


def test_plan_command_on_a_scara_style_recording_picks_poses_that_fix_its_height(tmp_path,
                                                                                  capsys):
    """Every recorded rotation about the vertical: the camera height on the flange is
    unobservable; the plan still runs (from the fit of the rest) and its first tilted pose
    makes the height observable."""
    rng = np.random.default_rng(10)
    R_down = rotation_exp([math.pi, 0.0, 0.0])
    recorded = [make_transform(rotation_exp([0.0, 0.0, rng.uniform(-1, 1)]) @ R_down,
                               [0.5, 0.05, 0.45] + rng.uniform(-0.1, 0.1, 3)) for _ in range(12)]
    X_CT = [apply_pose_noise(X_CE @ inverse(x) @ X_BT, rng.normal(size=12), "so3", SR, ST)
            for x in recorded]
    _tum(tmp_path / "robot.tum", recorded)
    _tum(tmp_path / "camera.tum", X_CT)
    out = tmp_path / "out"
    assert cli_main(["plan", "--robot", str(tmp_path / "robot.tum"), "--camera",
                          str(tmp_path / "camera.tum"), "--around", _pose_arg(recorded[0]),
                          "--max-angle", "20", "--num-candidates", "60", "--n", "2",
                          "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert ("translation along the rotation axis (E z) is unobservable: every rotation is about "
            "parallel axes — typical of 4-DOF/SCARA robots") in text
    result = json.loads((out / "plan.json").read_text())
    assert result["std_now"]["translation_m"][2] is None
    assert result["next_poses"][0]["translation_std_m"][2] < 0.01
    assert result["observability"]["suggested_fixes"] == ["tz"]


def test_plan_command_from_guesses_and_candidate_file(tmp_path, capsys):
    C = _candidates(9, 25)
    _tum(tmp_path / "cands.tum", C)
    out = tmp_path / "o"
    code = cli_main(["plan", "--candidates", str(tmp_path / "cands.tum"), "--hand-eye",
                          _pose_arg(X_EC), "--target", "0.55,0.05,0.0", "--n", "3",
                          "--out", str(out)])
    assert code == 0
    picks = [s["candidate"] for s in json.loads((out / "plan.json").read_text())["next_poses"]]
    assert picks == pl.suggest_next_poses(C, X_CE, make_transform(np.eye(3), P_BT), (),
                                          math.radians(0.1), 0.001, n=3)
    assert "(0 samples)" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["--around", "0,0,0.4,1,0,0,0", "--target", "0.5,0,0"], "--hand-eye and --target"),
    (["--hand-eye", "0,0,0.1,0,0,0,1", "--target", "0.5,0,0"], "give candidate poses"),
    (["--around", "0,0,0.4,1,0,0,2", "--hand-eye", "0,0,0.1,0,0,0,1", "--target", "0.5,0,0"],
     "--around: the quaternion .* has norm 2.23607"),
    (["--around", "0,0,0.4,1,0,0,0", "--hand-eye", "0,0,0.1,0,0,1", "--target", "0.5,0,0"],
     "--hand-eye: expected 7 comma-separated numbers, got 6"),
    (["--around", "0,0,0.4,1,0,0,0", "--hand-eye", "0,0,0.1,0,0,0,1", "--target", "0.5,0,0",
      "--fix", "tz=5cm"], "--fix: tz='5cm': the value is not a number"),
    (["--camera", "c.tum", "--around", "0,0,0.4,1,0,0,0"], "--camera: needs --robot"),
])
def test_plan_command_errors_are_one_line(argv, message, tmp_path, capsys):
    assert cli_main(["plan", *argv, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("handeye-drake: error: ") and err.count("\n") == 1
    assert __import__("re").search(message, err), err


@pytest.mark.parametrize("n", ["100000000", "100001"])
def test_plan_bounds_the_number_of_candidates(n, tmp_path, capsys):
    code = cli_main(["plan", "--around", "0,0,0.4,1,0,0,0", "--hand-eye", "0,0,0.1,0,0,0,1",
                     "--target", "0.5,0,0", "--num-candidates", n, "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and err == ("handeye-drake plan: error: argument --num-candidates: expected "
                                 f"at most 100 000 (each costs about 0.5 ms), got '{n}'\n")
    assert not (tmp_path / "o").exists()


def test_plan_takes_calibrates_intrinsics_and_noise_spelling(tmp_path, capsys):
    """The same vocabulary as calibrate: --intrinsics as an OpenCV YAML file, --noise DEG,MM."""
    from handeye_drake.vision.intrinsics import write_intrinsics_yaml
    C = _candidates(9, 25)
    _tum(tmp_path / "cands.tum", C)
    yaml = tmp_path / "camera.yaml"
    write_intrinsics_yaml(CAMERA, yaml)
    base = ["plan", "--candidates", str(tmp_path / "cands.tum"), "--hand-eye", _pose_arg(X_EC),
            "--target", "0.55,0.05,0.0", "--n", "3"]
    assert cli_main([*base, "--intrinsics", str(yaml), "--noise", "0.1,1",
                     "--out", str(tmp_path / "a")]) == 0
    assert cli_main([*base, "--intrinsics",
                     f"{CAMERA.alpha_u},{CAMERA.alpha_v},{CAMERA.u0},{CAMERA.v0},"
                     f"{CAMERA.width},{CAMERA.height}", "--noise", "0.1,1",
                     "--out", str(tmp_path / "b")]) == 0
    a = json.loads((tmp_path / "a" / "plan.json").read_text())
    b = json.loads((tmp_path / "b" / "plan.json").read_text())
    assert a["next_poses"] == b["next_poses"]
    assert a["rotation_sigma_rad"] == pytest.approx(math.radians(0.1))
    assert a["translation_sigma_m"] == pytest.approx(0.001)
    capsys.readouterr()
    assert cli_main([*base, "--noise", "0.1", "--out", str(tmp_path / "c")]) == 2
    assert "--noise: expected DEG,MM" in capsys.readouterr().err

"""``calibration.session.CalibrationSession``: the stop rule (σ at the target with verdict OK,
decided by the batch), save/resume, eye-to-hand, image samples, bad inputs, no Drake; and the
``handeye-drake session`` command."""

import json
import math
import subprocess
import sys

import cv2
import numpy as np
import pytest

from handeye_drake.apps.cli import main
from handeye_drake.calibration import CalibrationOptions
from handeye_drake.calibration.session import CalibrationSession, CandidatePoses
from handeye_drake.estimation.se3 import inverse, make_transform, quat_wxyz, rotation_angle, \
    rotation_exp
from handeye_drake.vision.camera_model import CameraIntrinsics
from tests import image_synth

X_EC = make_transform(rotation_exp(np.array([0.05, -0.03, 1.6])), [0.04, -0.03, 0.06])
X_BT = make_transform(rotation_exp(np.array([math.pi, 0.0, 0.0])), [-0.45, -0.15, 0.0])
X_BC = make_transform(rotation_exp(np.array([2.2, 0.3, 0.1])), [0.9, 0.4, 0.8])
X_ET = make_transform(rotation_exp(np.array([0.1, 0.05, -0.2])), [0.02, -0.03, 0.09])
OPTIONS = CalibrationOptions(robot_accuracy_deg=0.02, robot_accuracy_mm=0.1)
E2H = CalibrationOptions(mode="eye_to_hand", robot_accuracy_deg=0.02, robot_accuracy_mm=0.1)
NO_ROBOT_ERROR = CalibrationOptions(robot_accuracy_deg=0, robot_accuracy_mm=0)
# Rough mounts (a drawing): a few degrees and millimetres off. Typed samples fit the swapped
# reading as well; the rough mount tells which column is the robot's.
GUESS = make_transform(rotation_exp(np.array([0.05, -0.03, 1.6])) @ rotation_exp(
    np.array([0.04, -0.03, 0.02])), [0.035, -0.025, 0.055])
GUESS_E2H = make_transform(rotation_exp(np.array([2.2, 0.3, 0.1])) @ rotation_exp(
    np.array([0.03, 0.02, -0.04])), [0.88, 0.42, 0.79])


def _look(z, roll):
    z = z / np.linalg.norm(z)
    a = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
    x = np.cross(a, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z]) @ rotation_exp(np.array([0, 0, roll]))


def samples(n, seed=0, mode="eye_in_hand", camera=(0.05, 0.3), robot=(0.02, 0.1)):
    """n noisy (X_BE, X_CT): the camera 0.3–0.6 m from the board, tilted ≤ 35°."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        d = rng.uniform(0.3, 0.6)
        tilt = math.acos(rng.uniform(math.cos(0.6), 1))
        az = rng.uniform(0, 2 * math.pi)
        dirT = np.array([math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az),
                         math.cos(tilt)])
        if mode == "eye_in_hand":
            z = X_BT[:3, :3] @ dirT
            X_BC_k = make_transform(_look(z, rng.uniform(-3, 3)), X_BT[:3, 3] - d * z)
            X_BE = X_BC_k @ inverse(X_EC)
            X_CT = inverse(X_BE @ X_EC) @ X_BT
        else:
            X_CT = make_transform(_look(dirT, rng.uniform(-3, 3)).T, [0, 0, d])
            X_BE = X_BC @ X_CT @ inverse(X_ET)
        noisy_BE = make_transform(rotation_exp(rng.normal(0, math.radians(robot[0]), 3))
                                  @ X_BE[:3, :3], X_BE[:3, 3] + rng.normal(0, robot[1] / 1e3, 3))
        noisy_CT = make_transform(rotation_exp(rng.normal(0, math.radians(camera[0]), 3))
                                  @ X_CT[:3, :3], X_CT[:3, 3] + rng.normal(0, camera[1] / 1e3, 3))
        out.append((noisy_BE, noisy_CT))
    return out


def _error(X, X_true):
    return (math.degrees(rotation_angle(X[:3, :3].T @ X_true[:3, :3])),
            1000 * np.linalg.norm(X[:3, 3] - X_true[:3, 3]))


def test_stops_when_the_batch_sigma_reaches_the_target_with_verdict_ok():
    s = CalibrationSession(0.2, 1.0, OPTIONS, hand_eye_guess=GUESS)
    steps = []
    for x in samples(30, seed=1):
        steps.append(s.add(*x))
        if steps[-1].stop:
            break
    assert steps[0].status == "collecting" and steps[0].rotation_sigma_deg is None
    stop = next(k for k, st in enumerate(steps) if st.stop)
    st = steps[stop]
    assert st.source == "batch" and st.verdict == "OK"
    assert st.rotation_sigma_deg <= 0.2 and st.translation_sigma_mm <= 1.0
    assert st.tcp_sigma_mm > 0 and st.front_sigma_mm > 0
    # Before the stop, never "stop"; the σ it stops at are those of the batch result.
    assert not any(x.stop for x in steps[:stop])
    r = s.result
    cov = r.covariance
    assert math.isclose(st.rotation_sigma_deg, math.degrees(math.sqrt(np.trace(cov[:3, :3]))))
    # The true error within 3σ at stop.
    rot, tra = _error(r.X_hand, X_EC)
    assert rot <= 3 * st.rotation_sigma_deg and tra <= 3 * st.translation_sigma_mm


def test_never_stops_short_of_the_target():
    s = CalibrationSession(0.001, 0.001, NO_ROBOT_ERROR, max_samples=10, hand_eye_guess=GUESS)
    steps = [s.add(*x) for x in samples(10, seed=2)]
    assert not any(x.stop for x in steps)
    assert steps[-1].status == "continue" and "was not reached" in steps[-1].message


def test_a_failed_verdict_never_stops():
    # The camera poses written inverted (X_TC for X_CT): small σ maybe, but the verdict FAILs.
    s = CalibrationSession(5.0, 50.0, OPTIONS)
    steps = [s.add(a, inverse(b)) for a, b in samples(12, seed=3)]
    assert not any(x.stop for x in steps)
    assert steps[-1].verdict in ("FAIL", "WARN") and steps[-1].reasons


def test_save_and_resume_give_the_uninterrupted_answer(tmp_path):
    data = samples(14, seed=4)
    whole = CalibrationSession(0.01, 0.01, NO_ROBOT_ERROR, hand_eye_guess=GUESS)
    for x in data:
        whole.add(*x)
    first = CalibrationSession(0.01, 0.01, NO_ROBOT_ERROR, hand_eye_guess=GUESS)
    for x in data[:7]:
        first.add(*x)
    state = tmp_path / "state.json"
    first.save(state)
    again = CalibrationSession.resume(state)
    assert len(again.X_BE) == 7 and again.target == (0.01, 0.01)
    for x in data[7:]:
        again.add(*x)
    a, b = whole.finish(), again.finish()
    assert np.allclose(a.X_hand, b.X_hand, atol=1e-12)
    assert np.allclose(a.covariance, b.covariance, rtol=1e-9, atol=1e-18)
    state.write_text("{}")
    with pytest.raises(ValueError, match="state: state.json is not a session state"):
        CalibrationSession.resume(state)


def test_eye_to_hand():
    s = CalibrationSession(0.2, 1.0, E2H, hand_eye_guess=GUESS_E2H)
    for x in samples(30, seed=5, mode="eye_to_hand"):
        st = s.add(*x)
        if st.stop:
            break
    assert st.stop and st.X_hand is not None
    rot, tra = _error(st.X_hand, X_BC)
    assert rot <= 3 * st.rotation_sigma_deg and tra <= 3 * st.translation_sigma_mm
    # The filter between batches estimates the same X_BC.
    X_f = s._filter.X_EC
    assert _error(X_f, X_BC)[0] < 0.5 and _error(X_f, X_BC)[1] < 5


def test_next_pose_from_candidates_skips_visited_ones():
    data = samples(6, seed=6)
    cands = np.array([x[0] for x in samples(8, seed=7)])
    planner = CandidatePoses(cands, X_EC, X_BT)
    s = CalibrationSession(0.05, 0.2, OPTIONS, next_pose=planner)
    st = s.add(*data[0])
    first = st.next_pose["index"]
    # Record the suggested pose: it is not suggested again.
    X = cands[first]
    st = s.add(X, inverse(X @ X_EC) @ X_BT)
    assert st.next_pose["index"] != first
    with pytest.raises(ValueError, match="candidates_X_BE: the candidate set is empty"):
        CandidatePoses(np.zeros((0, 4, 4)), X_EC, X_BT)


def test_image_samples_and_an_image_without_the_target(tmp_path):
    truth = image_synth.synthesize(tmp_path, n=2, seed=0)
    K = image_synth.K
    intr = CameraIntrinsics(alpha_u=K[0, 0], alpha_v=K[1, 1], u0=K[0, 2], v0=K[1, 2],
                            width=image_synth.WIDTH, height=image_synth.HEIGHT)
    s = CalibrationSession(0.1, 0.5, OPTIONS)
    img = cv2.imread(str(tmp_path / "img_000.png"), cv2.IMREAD_GRAYSCALE)
    st = s.add(truth["X_BE"][0], image=img, target=truth["spec"], intrinsics=intr)
    assert st.num_samples == 1 and s.sources == ["image"]
    X_CT = s.X_CT[0]
    expected = inverse(truth["X_BE"][0] @ truth["X_hand"]) @ truth["X_fixed"]
    assert _error(X_CT, expected)[1] < 2.0
    st = s.add(truth["X_BE"][1], image=np.zeros_like(img), target=truth["spec"], intrinsics=intr)
    assert st.num_samples == 1 and st.message.startswith("sample skipped: target not found")


def test_bad_inputs_name_the_argument():
    with pytest.raises(ValueError, match="target_sigma_deg: expected a finite number > 0"):
        CalibrationSession(-1, 0.5)
    with pytest.raises(ValueError, match="next_pose: expected a callable"):
        CalibrationSession(next_pose=3)
    s = CalibrationSession()
    with pytest.raises(ValueError, match="X_CT / image"):
        s.add(np.eye(4))
    with pytest.raises(ValueError, match="X_BE"):
        s.add(np.zeros((3, 3)), np.eye(4))
    with pytest.raises(ValueError, match="session: no calibration yet"):
        s.finish()


def test_the_session_imports_without_drake_or_apps():
    code = ("import sys, handeye_drake.calibration, handeye_drake.calibration.session; "
            "bad = [m for m in sys.modules if m.startswith(('handeye_drake.apps', 'pydrake', "
            "'handeye_drake.planning'))]; print(bad); sys.exit(1 if bad else 0)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr


def _seven(X) -> str:
    q = quat_wxyz(X[:3, :3])
    return ",".join(f"{v:.10f}" for v in [*X[:3, 3], q[1], q[2], q[3], q[0]])


def _line(X_BE, X_CT):
    def seven(X):
        q = quat_wxyz(X[:3, :3])
        return [*X[:3, 3], q[1], q[2], q[3], q[0]]
    return " ".join(f"{v:.10f}" for v in seven(X_BE) + seven(X_CT))


def test_cli_stops_and_writes_the_calibration(tmp_path, capsys):
    f = tmp_path / "samples.txt"
    f.write_text("# X_BE then X_CT\n" + "\n".join(_line(*x) for x in samples(30, seed=1))
                 + "\n")
    out = tmp_path / "out"
    state = tmp_path / "state.json"
    code = main(["session", "--samples", str(f), "--target-sigma", "0.2,1.0",
                 "--robot-accuracy", "0.02,0.1", "--hand-eye", _seven(GUESS), "--state",
                 str(state), "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "stop: σ" in text and "calibrated after" in text
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["verdict"]["status"] == "OK"
    assert json.loads(state.read_text())["version"] == 1


def test_cli_input_ending_before_the_target_and_bad_input(tmp_path, capsys):
    f = tmp_path / "samples.txt"
    f.write_text("\n".join(_line(*x) for x in samples(5, seed=1)) + "\n")
    code = main(["session", "--samples", str(f), "--target-sigma", "0.001,0.001",
                 "--robot-accuracy", "0,0", "--out", str(tmp_path / "o1")])
    assert code == 1 and "input ended after 5 samples" in capsys.readouterr().err
    f.write_text("1 2 3\n")
    code = main(["session", "--samples", str(f), "--out", str(tmp_path / "o2")])
    err = capsys.readouterr().err
    assert code == 2 and "samples.txt line 1" in err and err.count("\n") == 1
    code = main(["session", "--samples", str(f), "--target-sigma", "0,1",
                 "--out", str(tmp_path / "o3")])
    err = capsys.readouterr().err
    assert code == 2 and "--target-sigma" in err and err.count("\n") == 1

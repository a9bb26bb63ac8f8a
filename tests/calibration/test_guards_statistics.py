"""Numbers a user reads, each checked against an independent computation (not the code's own
output): the held-out F bound and its degrees of freedom, the session's stop rule against σ
recomputed from the batch covariance, and the task-space σ against a Monte Carlo of the
calibrated transform. Each test here failed on a one-line bug that every other test passed
(docs/testing.md)."""

import dataclasses
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import f as f_distribution

from handeye_drake.calibration.api import solve
from handeye_drake.calibration.checks import held_out_test
from handeye_drake.calibration.inputs import Streams
from handeye_drake.calibration.session import CalibrationSession
from handeye_drake.calibration.task_space import POINT_DISTANCE, task_sigmas
from handeye_drake.estimation.se3 import make_transform, rotation_exp
from handeye_drake.recorded.formats import pose_stream

from .test_session import E2H, GUESS, GUESS_E2H, NO_ROBOT_ERROR, OPTIONS, samples


def _solve(n, seed, mode="eye_in_hand", **kw):
    S = samples(n, seed=seed, mode=mode, **kw)
    streams = Streams(robot=pose_stream(np.array([a for a, _ in S]), None, "robot"),
                      camera=pose_stream(np.array([b for _, b in S]), None, "camera"),
                      inputs={"test": {}}, roles_known=True)
    opt = OPTIONS if mode == "eye_in_hand" else E2H
    return solve(streams, dataclasses.replace(opt, time_offset_s=0.0)), S


@pytest.fixture(scope="module")
def result():
    return _solve(30, seed=3)[0]


# ------------------------------------------------------------------------------ held-out test
def test_held_out_bound_is_the_f_quantile_of_the_held_out_and_fit_dof(result):
    used = np.asarray(result.sample_used)
    n_h, n_f = int(np.sum(used == "held_out")), int(np.sum(used == "fit"))
    assert n_h >= 3 and n_f != n_h          # the two degrees of freedom must differ to tell
    h = held_out_test(result)
    # 12 parameters (X_EC and X_BT, nothing held): the fit keeps 6 n_f − 12 dof.
    assert (h["held_out"], h["fit"]) == (n_h, n_f)
    assert h["dof"] == (6 * n_h, 6 * n_f - 12)
    assert h["bound"] == pytest.approx(f_distribution.ppf(0.999, 6 * n_h, 6 * n_f - 12),
                                       rel=1e-9)
    # The ratio recomputed from the whitened residuals: held-out mean per dof, inflated by the
    # estimate's own error (1 + 12 / (6 n_f)), over the fit's residual per dof.
    w = np.asarray(result.whitened_sq)
    ratio = (np.mean(w[used == "held_out"]) / 6 / (1 + 12 / (6 * n_f))) / (
        np.sum(w[used == "fit"]) / (6 * n_f - 12))
    assert h["ratio"] == pytest.approx(ratio, rel=1e-9)
    worst = np.flatnonzero(used == "held_out")[np.argmax(w[used == "held_out"])]
    assert h["worst_whitened_sq"] == pytest.approx(w[worst])
    # calibration.json says the same.
    doc = result.to_json()
    held = doc.get("held_out") or doc.get("validation", {}).get("held_out")
    if held is not None and "bound" in held:
        assert held["bound"] == pytest.approx(h["bound"], rel=1e-6)


# ------------------------------------------------------------------------------ stop rule
def _radius_deg_mm(cov):
    return (math.degrees(math.sqrt(np.trace(cov[:3, :3]))),
            1000 * math.sqrt(np.trace(cov[3:, 3:])))


def test_the_session_stops_exactly_when_the_recomputed_sigma_reaches_a_sub_unit_target():
    # Targets below 1 (deg, mm): σ² ≤ target is reached before σ ≤ target (on these samples at
    # the 11th, σ 0.077° / 0.63 mm; σ itself at the 16th).
    target = (0.06, 0.5)
    s = CalibrationSession(*target, OPTIONS, batch_every=3, hand_eye_guess=GUESS)
    stopped, squares_below = None, False
    for x in samples(24, seed=5):
        st = s.add(*x)
        if st.source == "batch":
            rot, tra = _radius_deg_mm(s.result.covariance)
            # The step reports the batch σ (RMS radius, √trace of the 3×3 blocks).
            assert st.rotation_sigma_deg == pytest.approx(rot, rel=1e-6)
            assert st.translation_sigma_mm == pytest.approx(tra, rel=1e-6)
            reached = rot <= target[0] and tra <= target[1] and st.verdict == "OK"
            assert st.stop == reached, (st.num_samples, rot, tra, st.verdict)
            squares_below |= (st.verdict == "OK" and not reached and rot ** 2 <= target[0]
                              and tra ** 2 <= target[1])
        else:
            assert not st.stop
        if st.stop:
            stopped = st
            break
    assert stopped is not None, "the target was never reached"
    assert squares_below        # the samples do tell σ from σ²


# ------------------------------------------------------------------------------ task space
def _monte_carlo(X_H, cov, p_H, n=40000, seed=0):
    """RMS radius (m) of R p_H + t − (R̂ p_H + t̂) with R = exp(δθ) R̂, t = t̂ + δt,
    [δθ; δt] ~ N(0, cov)."""
    d = np.random.default_rng(seed).multivariate_normal(np.zeros(6), cov, size=n)
    R = Rotation.from_rotvec(d[:, :3]).as_matrix() @ X_H[:3, :3]
    p = R @ p_H + X_H[:3, 3] + d[:, 3:]
    p0 = X_H[:3, :3] @ p_H + X_H[:3, 3]
    return math.sqrt(np.mean(np.sum((p - p0) ** 2, axis=1)))


def _skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def _covariance(X_H, q_tool):
    """A covariance that tells points apart: rotation far worse about the camera's optical axis
    than about the others (so a point on that axis is hardly moved by it, another point is), and
    a translation error correlated with the rotation error so as to cancel most of the tool
    point's (whose rotated camera coordinates are q_tool): a sign error doubles that term."""
    u = X_H[:3, :3][:, 2]
    S_th = 1e-6 * np.eye(3) + 2.5e-5 * np.outer(u, u)
    B = 0.7 * _skew(q_tool)
    S_n = 0.04e-6 * np.eye(3)
    return np.block([[S_th, S_th @ B.T], [B @ S_th, B @ S_th @ B.T + S_n]])


@pytest.mark.parametrize("mode", ["eye_in_hand", "eye_to_hand"])
def test_task_space_sigmas_are_the_monte_carlo_of_the_points(mode):
    X_H = make_transform(rotation_exp(np.array([0.4, -1.1, 2.0])),
                         [0.04, -0.03, 0.06] if mode == "eye_in_hand" else [0.9, 0.4, 0.8])
    rng = np.random.default_rng(7)
    # A flange pointing down, turned ≤ ~20° about it: its poses (and their inverses) do not
    # average out to the origin.
    down = rotation_exp(np.array([math.pi, 0.0, 0.0]))
    X_BE = np.array([make_transform(down @ rotation_exp(rng.normal(size=3) * 0.2),
                                    [0.3, -0.2, 0.4] + rng.normal(size=3) * 0.05)
                     for _ in range(8)])
    X_R = np.linalg.inv(X_BE) if mode == "eye_to_hand" else X_BE   # robot-side: X_EB
    p_tool = np.zeros(3) if mode == "eye_in_hand" else X_BE[:, :3, 3].mean(axis=0)
    cov = _covariance(X_H, p_tool - X_H[:3, 3])
    ts = task_sigmas(mode, X_H, cov, X_R)
    assert ts["point_in_front_distance_m"] == POINT_DISTANCE == 0.5
    # A point 0.5 m along the camera's optical axis (z_C), located in the parent frame.
    mc_front = _monte_carlo(X_H, cov, np.array([0.0, 0.0, 0.5]))
    assert ts["point_in_front_m"] == pytest.approx(mc_front, rel=0.02)
    # The tool point (the flange origin; eye-to-hand its mean position in B) as the camera
    # locates it: its camera coordinates from the estimate, through the perturbed transform.
    p_C = X_H[:3, :3].T @ (p_tool - X_H[:3, 3])
    mc_tool = _monte_carlo(X_H, cov, p_C)
    assert ts["tool_centre_point_m"] == pytest.approx(mc_tool, rel=0.02)


def test_session_task_space_sigma_eye_to_hand_is_at_the_flange():
    # No robot error: a tiny σ target is allowed (never reached in 10 samples).
    s = CalibrationSession(0.001, 0.001, dataclasses.replace(NO_ROBOT_ERROR, mode="eye_to_hand"),
                           batch_every=3, hand_eye_guess=GUESS_E2H)
    S = samples(10, seed=2, mode="eye_to_hand")
    for x in S:
        st = s.add(*x)
    assert st.source == "batch"
    X_BE = np.array([a for a, _ in S])
    X_H, cov = s.result.X_hand, s.result.covariance
    p_C = X_H[:3, :3].T @ (X_BE[:, :3, 3].mean(axis=0) - X_H[:3, 3])
    assert st.tcp_sigma_mm == pytest.approx(1000 * _monte_carlo(X_H, cov, p_C), rel=0.02)
    assert st.front_sigma_mm == pytest.approx(
        1000 * _monte_carlo(X_H, cov, np.array([0.0, 0.0, 0.5])), rel=0.02)

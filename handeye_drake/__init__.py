"""handeye_drake: on-line hand-eye calibration embedded in visual servoing, as Drake systems.

The names exported here are the estimation core (numpy/scipy only; importing them does not load
Drake). Frames: robot poses ``X_BE`` (end-effector in base, OpenCV's gripper→base), camera poses
``X_CT`` (target in camera, OpenCV's target→camera); motions A = X_{C(k−1)C(k)}, B = X_{E(k−1)E(k)};
the paper's X is ``X_CE``, the camera-on-the-hand transform is ``X_EC`` = inv(X_CE).

- on-line estimators (``estimation.estimator.OnlineEstimator``), each built from its settings:
  ``HandEyeTargetFilter(TargetFilter(...), X_CE0)``, ``ManifoldHandEyeFilter(ManifoldFilter(...),
  X_CE0)``, ``HandEyeKalmanFilter(PaperFilter(...), X_CE0)`` (the paper's filter);
- classical solvers (``calibrate_hand_eye``, ``solve_ax_xb``), the paper's linear model, errors.

The Drake systems live in ``handeye_drake.systems``, the closed loop in
``handeye_drake.simulation`` (scenarios in ``handeye_drake.scenario``), the command-line
applications in ``handeye_drake.apps``.
"""

from .estimation.configs import ManifoldFilter, PaperFilter, TargetFilter
from .estimation.errors import rotation_error_deg, rotation_error_quat, translation_error_rel
from .estimation.kalman import HandEyeKalmanFilter, kalman_step, measurement_covariance
from .estimation.linear_model import linear_system, relative_motions
from .estimation.manifold import HandEyeTargetFilter, ManifoldHandEyeFilter
from .estimation.orthonormalize import orthonormalize
from .estimation.solvers import METHODS as SOLVER_METHODS
from .estimation.solvers import calibrate_hand_eye, solve_ax_xb
from .estimation.startup import make_estimator, start_estimator, two_motion_estimate

__version__ = "0.2.0"

__all__ = [
    "HandEyeKalmanFilter",
    "HandEyeTargetFilter",
    "ManifoldFilter",
    "ManifoldHandEyeFilter",
    "PaperFilter",
    "SOLVER_METHODS",
    "TargetFilter",
    "calibrate_hand_eye",
    "kalman_step",
    "linear_system",
    "make_estimator",
    "measurement_covariance",
    "orthonormalize",
    "relative_motions",
    "rotation_error_deg",
    "rotation_error_quat",
    "solve_ax_xb",
    "start_estimator",
    "translation_error_rel",
    "two_motion_estimate",
]

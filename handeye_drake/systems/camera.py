"""Simulated hand-eye camera: projects a rigid target of point features and measures its pose.

The math lives in ``handeye_drake.vision.camera_model``; this module only wraps it as a sampled
Drake system with its noise on random input ports.
"""

from __future__ import annotations

import numpy as np
from pydrake.common import RandomDistribution
from pydrake.systems.framework import LeafSystem

from ..estimation import kernels
from ..estimation.se3 import pose_to_vector, vector_to_pose
from ..estimation.validation import (
    ROTATION_TOLERANCE,
    as_matrix,
    as_transform,
    check_positive,
    rotation_defect,
)
from ..vision.camera_model import (
    MIN_DEPTH,
    POSE_NOISE_MODELS,
    CameraIntrinsics,
    as_points,
    target_visibility,
)
from .arm import EndEffectorPoseInput

_IDENTITY_POSE = pose_to_vector(np.eye(4))
_NO_NOISE = np.zeros(0)  # (the kernel does not read the noise of a zero sigma)


class HandEyeCamera(LeafSystem):
    """A camera rigidly mounted on the end-effector (pose X_EC), looking at a fixed target T
    (pose X_WT) made of N points p_TQ. Every ``period`` seconds (and at initialization) it samples
    the end-effector pose and holds, until the next sample:

    * the noisy pixels of the points (noise N(0, pixel_sigma²) per coordinate, on visible points),
    * which points are visible (in front of the camera and inside the image),
    * a noisy measurement of the target pose X_CT (what a pose-from-image estimator would return;
      the camera motion A of docs/method.md §2 is built from two of them),
    * the true camera pose X_WC (for logging and visualization).

    Invisible points are reported through ``visible``; their ``features`` entries hold the
    noiseless projection if the point is in front of the camera, else 0.

    With ``plant`` (the arm's MultibodyPlant) it reads the end-effector pose from the plant
    itself, so the loop needs no separate pose sensor, and also holds the robot pose X_BE of the
    same instant (E in the robot base B, what the robot reports at the camera trigger).

    Input ports:
        X_WE (12): end-effector pose in world, [vec_row(R); p] (length unit of the poses);
            without ``plant``.
        body_poses (abstract, list of RigidTransform X_W·Body by BodyIndex): with ``plant``,
            instead of X_WE; connect ``plant.get_body_poses_output_port()``.
        pixel_noise (2N, random Gaussian): standard-normal samples, scaled by pixel_sigma inside.
        pose_noise (12, random Gaussian): standard-normal samples; the first 9 ("paper") or the
            first 3 ("so3") perturb the rotation, the last 3 the translation (see
            ``apply_pose_noise``).
    The noise ports only need a connection (e.g. ``AddRandomInputs(period, builder)``) when their
    sigma is non-zero. Use a RandomSource sampling interval equal to ``period`` so that every
    image gets a fresh sample.

    Output ports (all read the discrete state):
        features (2N): noisy pixels [u0, v0, u1, v1, …] (px).
        visible (N): 1.0 if the point is visible, else 0.0.
        X_CT_measured (12): noisy pose of T in C, [vec_row(R); p]; R is not orthonormal under the
            "paper" noise model.
        X_WC (12): true pose of C in W.
        X_BE (12): the end-effector pose in the base frame B at the sample (with ``plant``;
            without one B = W: the X_WE sample).
    """

    def __init__(self, intrinsics: CameraIntrinsics, X_EC, p_TQ, X_WT, period: float,
                 pixel_sigma: float = 0.0, pose_noise_model: str = "paper",
                 rotation_sigma: float = 0.0, translation_sigma: float = 0.0, plant=None,
                 base_frame_name: str = "base_link", ee_frame_name: str = "tool0"):
        LeafSystem.__init__(self)
        if not isinstance(intrinsics, CameraIntrinsics):
            raise ValueError(f"intrinsics: expected a CameraIntrinsics, got "
                             f"{type(intrinsics).__name__}")
        self._intrinsics = intrinsics
        self._X_EC = as_transform(X_EC, "X_EC")
        self._X_WT = as_transform(X_WT, "X_WT")
        self._p_TQ = as_points(p_TQ, "p_TQ", 3)
        self._period = check_positive(period, "period")
        self._pixel_sigma = check_positive(pixel_sigma, "pixel_sigma", allow_zero=True)
        if pose_noise_model not in POSE_NOISE_MODELS:
            raise ValueError(f"pose_noise_model: unknown model {pose_noise_model!r}, expected "
                             f"one of {POSE_NOISE_MODELS}")
        self._pose_noise_model = pose_noise_model
        self._rotation_sigma = check_positive(rotation_sigma, "rotation_sigma", allow_zero=True)
        self._translation_sigma = check_positive(translation_sigma, "translation_sigma",
                                                 allow_zero=True)
        n = self._p_TQ.shape[0]
        # (contiguous float arrays: what the compiled kernel takes)
        self._K2 = np.ascontiguousarray(intrinsics.K[:2, :2], dtype=float)
        self._principal_point = np.array([intrinsics.u0, intrinsics.v0], dtype=float)
        self._p_TQ = np.ascontiguousarray(self._p_TQ, dtype=float)

        self._ee_input = EndEffectorPoseInput(self, plant, base_frame_name, ee_frame_name)
        self._X_WE_port, self._frames = self._ee_input.port, self._ee_input.frames
        self._num_points = n
        self._pixel_noise_port = self.DeclareVectorInputPort(
            "pixel_noise", 2 * n, RandomDistribution.kGaussian)
        self._pose_noise_port = self.DeclareVectorInputPort(
            "pose_noise", 12, RandomDistribution.kGaussian)

        # One discrete group per output, so each output depends on its own group only.
        self._features_index = self.DeclareDiscreteState(2 * n)
        self._visible_index = self.DeclareDiscreteState(n)
        self._X_CT_index = self.DeclareDiscreteState(_IDENTITY_POSE)
        self._X_WC_index = self.DeclareDiscreteState(_IDENTITY_POSE)
        self._X_BE_index = self.DeclareDiscreteState(_IDENTITY_POSE)
        self.DeclarePeriodicDiscreteUpdateEvent(self._period, 0.0, self._UpdateImage)
        self.DeclareInitializationDiscreteUpdateEvent(self._UpdateImage)

        self._features_port = self.DeclareStateOutputPort("features", self._features_index)
        self._visible_port = self.DeclareStateOutputPort("visible", self._visible_index)
        self._X_CT_port = self.DeclareStateOutputPort("X_CT_measured", self._X_CT_index)
        self._X_WC_port = self.DeclareStateOutputPort("X_WC", self._X_WC_index)
        self._X_BE_port = self.DeclareStateOutputPort("X_BE", self._X_BE_index)


    # Ports, as members so users can wire them by handle.
    def get_X_WE_input_port(self):
        return self._ee_input.X_WE_port()

    def get_pixel_noise_input_port(self):
        return self._pixel_noise_port

    def get_pose_noise_input_port(self):
        return self._pose_noise_port

    def get_features_output_port(self):
        return self._features_port

    def get_visible_output_port(self):
        return self._visible_port

    def get_X_CT_output_port(self):
        return self._X_CT_port

    def get_X_WC_output_port(self):
        return self._X_WC_port

    def get_X_BE_output_port(self):
        return self._X_BE_port

    def get_body_poses_input_port(self):
        return self._ee_input.body_poses_port()

    # Read-only accessors (numpy copies) for scenarios and tests.
    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self._intrinsics

    @property
    def num_points(self) -> int:
        return self._p_TQ.shape[0]

    @property
    def period(self) -> float:
        return self._period

    @property
    def p_TQ(self) -> np.ndarray:
        return self._p_TQ.copy()

    @property
    def X_EC(self) -> np.ndarray:
        return self._X_EC.copy()

    @property
    def X_WT(self) -> np.ndarray:
        return self._X_WT.copy()

    def CheckTargetVisible(self, X_WE, min_visible: int | None = None) -> np.ndarray:
        """Returns the N visibility flags at end-effector pose X_WE (4×4 or RigidTransform) and
        raises ValueError if fewer than ``min_visible`` points (default: all) are visible, saying
        which points are behind the camera or outside the image."""
        uv, in_front, in_image = target_visibility(self._intrinsics, X_WE, self._X_EC,
                                                   self._p_TQ, self._X_WT)
        n = self.num_points
        min_visible = n if min_visible is None else int(min_visible)
        if int(in_image.sum()) < min_visible:
            behind = np.flatnonzero(~in_front).tolist()
            outside = np.flatnonzero(in_front & ~in_image).tolist()
            raise ValueError(
                f"X_WE: only {int(in_image.sum())} of {n} target points are visible, need "
                f"{min_visible}; behind the camera: {behind}; outside the "
                f"{self._intrinsics.width}×{self._intrinsics.height} image: {outside} "
                f"(pixels {np.round(uv[outside], 1).tolist()})")
        return in_image

    def _UpdateImage(self, context, discrete_state):
        if self._frames is not None and self._UpdateFromBodyPoses(context, discrete_state):
            return
        # The general path: the arithmetic of ``project_points`` and ``apply_pose_noise`` on
        # the settings checked once in the constructor, compiled (``kernels.camera_sample``;
        # tests check it equals them to rounding).
        x, X_WE_plant, X_BE = self._ee_input.Eval(context)
        if not np.isfinite(x).all():
            raise ValueError(f"X_WE input of {self.get_name()!r}: contains NaN or infinite "
                             f"values at t = {context.get_time()}")
        X_WE = vector_to_pose(x) if X_BE is None else X_WE_plant
        if not _is_rotation(x):
            raise ValueError(f"X_WE input of {self.get_name()!r}: rotation block is not a "
                             f"rotation matrix at t = {context.get_time()}: {x[:9].tolist()}")
        pixel_noise = (self._EvalNoise(self._pixel_noise_port, context, 2 * self.num_points)
                       if self._pixel_sigma > 0 else _NO_NOISE)
        pose_noise = (self._EvalNoise(self._pose_noise_port, context, 12)
                      if self._rotation_sigma > 0 or self._translation_sigma > 0 else _NO_NOISE)
        uv, visible, x_CT, x_WC = kernels.camera_sample(
            X_WE, self._X_EC, self._X_WT, self._p_TQ, self._K2, self._principal_point,
            float(self._intrinsics.width), float(self._intrinsics.height), MIN_DEPTH,
            self._pixel_sigma, pixel_noise, self._rotation_sigma, self._translation_sigma,
            self._pose_noise_model == "paper", pose_noise)
        discrete_state.set_value(self._features_index, uv)
        discrete_state.set_value(self._visible_index, visible)
        discrete_state.set_value(self._X_CT_index, x_CT)
        discrete_state.set_value(self._X_WC_index, x_WC)
        discrete_state.set_value(self._X_BE_index, x if X_BE is None else pose_to_vector(X_BE))

    def _UpdateFromBodyPoses(self, context, discrete_state) -> bool:
        """The per-sample path with a plant: one compiled call (``kernels.camera_step``, the
        same arithmetic as the general path below) and the fewest calls into Drake. False leaves
        the sample to the general path, which raises the right error (a disconnected noise
        input, a non-finite or non-rotation pose, non-finite noise) or decides a rotation
        the fast test cannot."""
        try:
            pixel_noise = (self._pixel_noise_port.Eval(context) if self._pixel_sigma > 0
                           else _NO_NOISE)
            pose_noise = (self._pose_noise_port.Eval(context)
                          if self._rotation_sigma > 0 or self._translation_sigma > 0
                          else _NO_NOISE)
        except RuntimeError:  # a noise input not connected: said below, by name
            return False
        poses = self._ee_input.port.Eval(context)
        (iB, X_BodyB), (iE, X_BodyE) = self._frames
        out = kernels.camera_step(
            poses[iE].GetAsMatrix4(), X_BodyE, poses[iB].GetAsMatrix4(), X_BodyB, self._X_EC,
            self._X_WT, self._p_TQ, self._K2, self._principal_point,
            float(self._intrinsics.width), float(self._intrinsics.height), MIN_DEPTH,
            self._pixel_sigma, pixel_noise, self._rotation_sigma, self._translation_sigma,
            self._pose_noise_model == "paper", pose_noise, ROTATION_TOLERANCE)
        n = self._num_points
        k = 3 * n
        if not (out[k + 36] and out[k + 37] and out[k + 38]):
            return False
        discrete_state.set_value(self._features_index, out[:2 * n])
        discrete_state.set_value(self._visible_index, out[2 * n:k])
        discrete_state.set_value(self._X_CT_index, out[k:k + 12])
        discrete_state.set_value(self._X_WC_index, out[k + 12:k + 24])
        discrete_state.set_value(self._X_BE_index, out[k + 24:k + 36])
        return True

    def _EvalNoise(self, port, context, size):
        if not port.HasValue(context):
            raise ValueError(
                f"{port.get_name()} input of {self.get_name()!r} is not connected but its sigma "
                f"is non-zero; connect a RandomSource (e.g. AddRandomInputs(period, builder))")
        noise = port.Eval(context)
        if not np.isfinite(noise).all():
            return as_matrix(noise, f"{port.get_name()} input", (size,))  # raises, naming it
        return noise


def _is_rotation(x) -> bool:
    """``rotation_defect(R) ≤ ROTATION_TOLERANCE`` for R = the first 9 entries of a pose
    vector (row-major): the compiled fast test, the exact one where it cannot decide."""
    if kernels.rotation_fast_test(x, ROTATION_TOLERANCE):
        return True
    return rotation_defect(np.reshape(x[:9], (3, 3))) <= ROTATION_TOLERANCE

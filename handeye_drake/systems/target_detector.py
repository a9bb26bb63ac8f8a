"""A Drake system that detects the calibration target in camera images and measures its pose.

The detection math is ``handeye_drake.vision.detection.detect_target``; this module samples the
image once per camera period and holds the result on its output ports.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem
from pydrake.systems.sensors import ImageGrey8U, ImageRgba8U

from ..estimation.se3 import pose_to_vector
from ..estimation.validation import check_positive
from ..vision.camera_model import CameraIntrinsics
from ..vision.detection import TargetDetection, as_grey_image, detect_target
from ..vision.targets import object_points, validate_target

_INPUT_TYPES = {"rgba": ("color_image", ImageRgba8U), "grey": ("grey_image", ImageGrey8U)}


class _HeldDetection(TargetDetection):
    """The detection held in the detector's abstract state. Drake deep-copies abstract state
    (``copy.deepcopy``) whenever it clones a state — twice a frame — which copied every array of
    the detection; a held detection is never modified (the next frame's replaces it), so the
    copies share it. Treat the ``detection`` output as read-only."""

    def __deepcopy__(self, memo):
        return self

    @classmethod
    def of(cls, detection: TargetDetection) -> "_HeldDetection":
        return cls(**{f.name: getattr(detection, f.name)
                      for f in dataclasses.fields(TargetDetection)})


class TargetDetector(LeafSystem):
    """Every ``period`` seconds (first at ``offset``, once at initialization, and at each
    ``ExecuteForcedEvents`` on its context or the diagram's) reads the camera image, runs
    ``detect_target(image, target, intrinsics)`` and holds the result until the next sample,
    so the outputs are cheap to evaluate and the image is rendered and detected once per frame.

    ``feature_ids`` chooses the N target points reported as image features (ids as in
    ``object_points(target)``; default: all of them, in that order), e.g. the four outer corners
    for IBVS; ``feature_points_T`` gives their coordinates p_TQ in the target frame.
    ``detect_options`` (min_points, min_pixel_sigma, ambiguity_ratio, max_reprojection_rms_px)
    go to ``detect_target``.

    Input port (abstract, one of):
        color_image: ``ImageRgba8U`` (``RgbdSensor.color_image_output_port()``), converted to
            grey inside; with ``input_type="grey"`` the port is ``grey_image``, ``ImageGrey8U``.
            Its size must equal the intrinsics' width × height.

    Output ports (all read the state; frames: C camera (OpenCV axes), T target):
        X_CT_measured (12): pose of T in C, [vec_row(R); p (m)] (``pose_to_vector``) of the last
            frame where the target was found (identity until the first one).
        features (2N): [u0, v0, u1, v1, …] (px, pixel centres at integers) of the feature points;
            a point not detected in this frame keeps its last detected value (0 until then).
        visible (N): 1.0 if the feature point was detected in this frame, else 0.0.
        reprojection_rms (1): RMS reprojection error of the pose over the detected points (px),
            of the last frame where the target was found (0 until then).
        covariance (36): row-major 6×6 covariance of X_CT_measured's error [δθ (rad); δt (m)]
            (left perturbation, R = exp([δθ]×) R̂, t = t̂ + δt), of the last found frame (0 until
            then).
        found (1): 1.0 if the target was found in this frame, else 0.0.
        num_points (1): number of target points detected in this frame (0 when not found).
        detection (abstract): the ``TargetDetection`` of this frame (None before the first
            sample; read-only: shared, not copied, between state copies), e.g. for
            ``draw_detection``.
    """

    def __init__(self, target, intrinsics: CameraIntrinsics, period: float, offset: float = 0.0,
                 feature_ids=None, input_type: str = "rgba", **detect_options):
        LeafSystem.__init__(self)
        self._target = validate_target(target)
        if not isinstance(intrinsics, CameraIntrinsics):
            raise ValueError(f"intrinsics: expected a CameraIntrinsics, got "
                             f"{type(intrinsics).__name__}")
        self._intrinsics = intrinsics
        self._period = check_positive(period, "period")
        self._offset = check_positive(offset, "offset", allow_zero=True)
        if input_type not in _INPUT_TYPES:
            raise ValueError(f"input_type: expected one of {sorted(_INPUT_TYPES)}, got "
                             f"{input_type!r}")
        self._input_type = input_type
        self._detect_options = dict(detect_options)
        # Checks the options here (on a blank image) rather than at the first frame.
        try:
            detect_target(np.zeros((intrinsics.height, intrinsics.width), np.uint8),
                          self._target, intrinsics, **self._detect_options)
        except TypeError as e:
            raise ValueError(f"detect_options: {e}") from None
        ids, p_TQ = object_points(self._target)
        ids = np.asarray(ids, dtype=int)
        if feature_ids is None:
            feature_ids = ids
        try:
            feature_ids = np.array(feature_ids, dtype=int).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"feature_ids: expected a list of integer point ids, got "
                             f"{feature_ids!r}") from None
        row_of_id = {int(i): k for k, i in enumerate(ids)}
        unknown = [int(i) for i in feature_ids if int(i) not in row_of_id]
        if unknown:
            raise ValueError(f"feature_ids: ids {unknown} are not points of the target (valid: "
                             f"{ids.min()}…{ids.max()}, see object_points)")
        if feature_ids.size == 0 or len(set(feature_ids.tolist())) != feature_ids.size:
            raise ValueError(f"feature_ids: expected a non-empty list of distinct ids, got "
                             f"{feature_ids.tolist()}")
        self._feature_ids = feature_ids
        self._p_TQ = np.asarray(p_TQ, dtype=float)[[row_of_id[int(i)] for i in feature_ids]]
        n = feature_ids.size

        port_name, image_type = _INPUT_TYPES[input_type]
        self._image_port = self.DeclareAbstractInputPort(port_name,
                                                         AbstractValue.Make(image_type()))
        # One group per output, so each output depends on its own state only.
        self._X_CT_index = self.DeclareDiscreteState(pose_to_vector(np.eye(4)))
        self._features_index = self.DeclareDiscreteState(2 * n)
        self._visible_index = self.DeclareDiscreteState(n)
        self._rms_index = self.DeclareDiscreteState(1)
        self._covariance_index = self.DeclareDiscreteState(36)
        self._found_index = self.DeclareDiscreteState(1)
        self._num_points_index = self.DeclareDiscreteState(1)
        self._detection_index = self.DeclareAbstractState(AbstractValue.Make(None))
        self.DeclarePeriodicUnrestrictedUpdateEvent(self._period, self._offset, self._Detect)
        self.DeclareInitializationUnrestrictedUpdateEvent(self._Detect)
        # And on demand (``ExecuteForcedEvents``): one frame where a kinematic loop wants it.
        self.DeclareForcedUnrestrictedUpdateEvent(self._Detect)

        self._X_CT_port = self.DeclareStateOutputPort("X_CT_measured", self._X_CT_index)
        self._features_port = self.DeclareStateOutputPort("features", self._features_index)
        self._visible_port = self.DeclareStateOutputPort("visible", self._visible_index)
        self._rms_port = self.DeclareStateOutputPort("reprojection_rms", self._rms_index)
        self._covariance_port = self.DeclareStateOutputPort("covariance",
                                                            self._covariance_index)
        self._found_port = self.DeclareStateOutputPort("found", self._found_index)
        self._num_points_port = self.DeclareStateOutputPort("num_points",
                                                            self._num_points_index)
        self._detection_port = self.DeclareStateOutputPort("detection", self._detection_index)

    # Read-only accessors for the wiring code and tests.
    @property
    def target(self):
        return self._target

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self._intrinsics

    @property
    def period(self) -> float:
        return self._period

    @property
    def offset(self) -> float:
        return self._offset

    @property
    def feature_ids(self) -> np.ndarray:
        return self._feature_ids.copy()

    @property
    def feature_points_T(self) -> np.ndarray:
        """N×3 coordinates p_TQ (m) of the feature points, in ``feature_ids`` order."""
        return self._p_TQ.copy()

    def get_image_input_port(self):
        return self._image_port

    def get_color_image_input_port(self):
        if self._input_type != "rgba":
            raise ValueError("this TargetDetector takes grey images: use get_image_input_port")
        return self._image_port

    def get_X_CT_measured_output_port(self):
        return self._X_CT_port

    def get_features_output_port(self):
        return self._features_port

    def get_visible_output_port(self):
        return self._visible_port

    def get_reprojection_rms_output_port(self):
        return self._rms_port

    def get_covariance_output_port(self):
        return self._covariance_port

    def get_found_output_port(self):
        return self._found_port

    def get_num_points_output_port(self):
        return self._num_points_port

    def get_detection_output_port(self):
        return self._detection_port

    def _GreyImage(self, context) -> np.ndarray:
        image = self._image_port.Eval(context)
        width, height = image.width(), image.height()
        if (width, height) != (self._intrinsics.width, self._intrinsics.height):
            raise ValueError(
                f"{self._image_port.get_name()} input of {self.get_name()!r}: image is "
                f"{width}×{height} px but the intrinsics are {self._intrinsics.width}×"
                f"{self._intrinsics.height}")
        return as_grey_image(image.data)

    def _Detect(self, context, state) -> None:
        detection = detect_target(self._GreyImage(context), self._target, self._intrinsics,
                                  **self._detect_options)
        discrete = state.get_mutable_discrete_state()
        n = self._feature_ids.size
        visible = np.zeros(n)
        features = discrete.get_vector(self._features_index).get_value().copy()
        if detection.found:
            rows = {int(i): k for k, i in enumerate(np.asarray(detection.ids).reshape(-1))}
            points = np.asarray(detection.image_points, dtype=float).reshape(-1, 2)
            for k, feature_id in enumerate(self._feature_ids):
                row = rows.get(int(feature_id))
                if row is not None:
                    features[2 * k:2 * k + 2] = points[row]
                    visible[k] = 1.0
            discrete.get_mutable_vector(self._X_CT_index).SetFromVector(
                pose_to_vector(detection.X_CT))
            discrete.get_mutable_vector(self._rms_index).SetFromVector(
                [detection.reprojection_rms_px])
            discrete.get_mutable_vector(self._covariance_index).SetFromVector(
                np.asarray(detection.covariance, dtype=float).reshape(36))
            num_points = points.shape[0]
        else:
            num_points = 0
        discrete.get_mutable_vector(self._features_index).SetFromVector(features)
        discrete.get_mutable_vector(self._visible_index).SetFromVector(visible)
        discrete.get_mutable_vector(self._found_index).SetFromVector(
            [1.0 if detection.found else 0.0])
        discrete.get_mutable_vector(self._num_points_index).SetFromVector([float(num_points)])
        state.get_mutable_abstract_state(self._detection_index).set_value(
            _HeldDetection.of(detection))

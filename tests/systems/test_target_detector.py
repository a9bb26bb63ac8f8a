"""TargetDetector: detection once per camera period, held outputs, feature visibility, lost target.

The closed-loop-like test moves a camera on a free floating body (gravity off, zero velocity, so
it stays where the test puts it) in front of a ChArUco board and steps a Simulator.
"""

import copy
import math

import cv2
import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.multibody.tree import SpatialInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource
from pydrake.systems.sensors import ImageGrey8U

from tests.fixtures import tangent_error
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp, rotation_log, \
    vector_to_pose
from handeye_drake.systems.rendered_camera import add_target_geometry, mount_rendered_camera
from handeye_drake.systems.target_detector import TargetDetector
from handeye_drake.vision.detection import TargetDetection
from handeye_drake.vision.camera_model import CameraIntrinsics
from handeye_drake.vision.targets import object_points, parse_target, pattern_extent, \
    render_target

CHARUCO = parse_target("charuco:7x5:0.04:0.03:DICT_5X5_100")
INTRINSICS = CameraIntrinsics(alpha_u=605.0, alpha_v=598.0, u0=331.3, v0=228.7, width=640,
                              height=480)
X_WT = make_transform(rotation_exp([math.pi, 0.0, 0.0]), [0.1, 0.2, 0.0])  # face up
# The four outer inner corners of the 6×4 ChArUco corner grid: left column ids 0 and 18.
FEATURE_IDS = [0, 5, 18, 23]
PERIOD = 0.1


def pose_errors(X_true, X_est):
    rotation = math.degrees(np.linalg.norm(rotation_log(X_est[:3, :3] @ X_true[:3, :3].T)))
    return rotation, 1000.0 * np.linalg.norm(X_est[:3, 3] - X_true[:3, 3])


def X_TC_looking_at(x_T, y_T, distance, rotvec=(0.15, -0.1, 0.3)):
    R = rotation_exp(rotvec)
    return make_transform(R, np.array([x_T, y_T, 0.0]) - distance * R[:, 2])


def project(X_CT, p_TQ):
    p_CQ = p_TQ @ X_CT[:3, :3].T + X_CT[:3, 3]
    uv = p_CQ @ INTRINSICS.K.T
    return uv[:, :2] / uv[:, 2:]


@pytest.fixture(scope="module")
def floating_camera_loop():
    builder = DiagramBuilder()
    plant, scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
    plant.mutable_gravity_field().set_gravity_vector([0.0, 0.0, 0.0])
    body = plant.AddRigidBody("camera_body", SpatialInertia.SolidBoxWithMass(0.2, 0.05, 0.05, 0.05))
    plant.Finalize()
    add_target_geometry(scene_graph, CHARUCO, X_WT)
    camera = mount_rendered_camera(builder, scene_graph, plant, body.body_frame(), np.eye(4),
                                   INTRINSICS)
    detector = builder.AddSystem(TargetDetector(CHARUCO, INTRINSICS, PERIOD,
                                                feature_ids=FEATURE_IDS))
    builder.Connect(camera.color_image_output_port(), detector.get_color_image_input_port())
    diagram = builder.Build()
    return diagram, plant, body, detector


def outputs(detector, context):
    c = detector.GetMyContextFromRoot(context)
    get = lambda port: port.Eval(c).copy()  # noqa: E731
    return {
        "X_CT": get(detector.get_X_CT_measured_output_port()),
        "features": get(detector.get_features_output_port()),
        "visible": get(detector.get_visible_output_port()),
        "rms": get(detector.get_reprojection_rms_output_port()),
        "covariance": get(detector.get_covariance_output_port()),
        "found": get(detector.get_found_output_port()),
        "num_points": get(detector.get_num_points_output_port()),
        "detection": detector.get_detection_output_port().Eval(c),
    }


def test_detector_holds_updates_and_loses_the_target(floating_camera_loop):
    diagram, plant, body, detector = floating_camera_loop
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    x0, y0, x1, y1 = pattern_extent(CHARUCO)
    p_TQ = detector.feature_points_T
    assert np.array_equal(p_TQ, object_points(CHARUCO)[1][FEATURE_IDS])

    def place(X_TC):
        plant.SetFreeBodyPose(plant_context, body, RigidTransform(X_WT @ X_TC))

    # Frame A (initialization event): the whole board in view.
    X_TC_a = X_TC_looking_at(0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5)
    place(X_TC_a)
    simulator.Initialize()
    a = outputs(detector, context)
    assert a["found"][0] == 1.0 and a["num_points"][0] == 24
    assert np.array_equal(a["visible"], np.ones(4))
    assert np.array_equal(vector_to_pose(a["X_CT"]), a["detection"].X_CT)
    rotation_deg, translation_mm = pose_errors(inverse(X_TC_a), vector_to_pose(a["X_CT"]))
    assert rotation_deg < 0.1 and translation_mm < 0.3, (rotation_deg, translation_mm)
    assert np.abs(a["features"] - project(inverse(X_TC_a), p_TQ).ravel()).max() < 0.2
    covariance = a["covariance"].reshape(6, 6)
    assert np.array_equal(covariance, a["detection"].covariance)
    assert np.array_equal(covariance, covariance.T) and np.all(np.linalg.eigvalsh(covariance) > 0)
    assert a["rms"][0] == a["detection"].reprojection_rms_px < 0.1

    # Frame B at t = 0.1: the left part of the board (ids 0, 18) is out of the image.
    simulator.AdvanceTo(0.5 * PERIOD)
    X_TC_b = X_TC_looking_at(0.36, 0.5 * (y0 + y1), 0.45, rotvec=(0.1, 0.15, 0.35))
    place(X_TC_b)
    truth_b = project(inverse(X_TC_b), p_TQ)
    assert truth_b[0, 0] < 0 and truth_b[2, 0] < 0 and np.all(truth_b[[1, 3], 0] > 20)
    simulator.AdvanceTo(1.5 * PERIOD)
    b = outputs(detector, context)
    assert b["found"][0] == 1.0 and 4 <= b["num_points"][0] < 24
    # The held detection is shared between Drake's state copies, never modified: frame A's is
    # still frame A's, and a copy of frame B's is itself.
    assert np.array_equal(vector_to_pose(a["X_CT"]), a["detection"].X_CT)
    assert not np.array_equal(a["detection"].X_CT, b["detection"].X_CT)
    assert isinstance(b["detection"], TargetDetection)
    assert copy.deepcopy(b["detection"]) is b["detection"]
    assert np.array_equal(b["visible"], [0.0, 1.0, 0.0, 1.0])
    features = b["features"].reshape(4, 2)
    rows = [list(b["detection"].ids).index(i) for i in (5, 23)]
    assert np.array_equal(features[[1, 3]], b["detection"].image_points[rows])  # updated
    assert np.abs(features[[1, 3]] - truth_b[[1, 3]]).max() < 0.3
    assert np.array_equal(features[[0, 2]], a["features"].reshape(4, 2)[[0, 2]])  # held
    # 8 corners in a corner of the image: a less certain pose (measured 0.14°, 0.65 mm), still
    # within its own covariance (χ²(6) 99.9 % quantile 22.5).
    rotation_deg, translation_mm = pose_errors(inverse(X_TC_b), vector_to_pose(b["X_CT"]))
    assert rotation_deg < 0.3 and translation_mm < 1.5, (rotation_deg, translation_mm)
    error = tangent_error(inverse(X_TC_b), vector_to_pose(b["X_CT"]))
    assert error @ np.linalg.solve(b["covariance"].reshape(6, 6), error) < 22.5

    # Frame C at t = 0.2: the camera looks away; the pose, covariance, RMS and features hold.
    X_TC_c = X_TC_a @ make_transform(rotation_exp([math.pi / 2, 0.0, 0.0]), np.zeros(3))
    place(X_TC_c)
    simulator.AdvanceTo(2.5 * PERIOD)
    c = outputs(detector, context)
    assert c["found"][0] == 0.0 and c["num_points"][0] == 0
    assert not c["detection"].found and c["detection"].reason
    assert np.array_equal(c["visible"], np.zeros(4))
    for name in ("X_CT", "features", "rms", "covariance"):
        assert np.array_equal(c[name], b[name]), name

    # Back to frame A at t = 0.3: found again.
    place(X_TC_a)
    simulator.AdvanceTo(3.5 * PERIOD)
    d = outputs(detector, context)
    assert d["found"][0] == 1.0
    assert np.abs(d["X_CT"] - a["X_CT"]).max() < 1e-9


def synthetic_grey_image(X_CT):
    """The board warped into the image by the homography of X_CT (no Drake rendering)."""
    image, A = render_target(CHARUCO, 4000.0, 0.02)
    H = INTRINSICS.K @ np.column_stack([X_CT[:3, 0], X_CT[:3, 1], X_CT[:3, 3]]) @ \
        np.linalg.inv(A)
    return cv2.warpPerspective(image, H, (INTRINSICS.width, INTRINSICS.height),
                               flags=cv2.INTER_AREA, borderValue=160)


def grey_loop(image: np.ndarray, period=PERIOD, **kwargs):
    builder = DiagramBuilder()
    value = ImageGrey8U(image.shape[1], image.shape[0])
    value.mutable_data[:, :, 0] = image
    source = builder.AddSystem(ConstantValueSource(AbstractValue.Make(value)))
    detector = builder.AddSystem(TargetDetector(CHARUCO, INTRINSICS, period, input_type="grey",
                                                **kwargs))
    builder.Connect(source.get_output_port(), detector.get_image_input_port())
    diagram = builder.Build()
    return diagram, detector


def test_detector_samples_at_period_and_offset():
    """Initialization, then every period from the offset: each update stores a new
    TargetDetection object, evaluations in between return the held one."""
    diagram, detector = grey_loop(np.full((480, 640), 128, np.uint8), period=0.1, offset=0.05)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    detection = lambda: detector.get_detection_output_port().Eval(  # noqa: E731
        detector.GetMyContextFromRoot(context))
    simulator.Initialize()
    first = detection()
    assert not first.found
    simulator.AdvanceTo(0.049)
    assert detection() is first
    simulator.AdvanceTo(0.051)
    second = detection()
    assert second is not first
    simulator.AdvanceTo(0.149)
    assert detection() is second
    simulator.AdvanceTo(0.151)
    assert detection() is not second
    assert (detector.period, detector.offset) == (0.1, 0.05)


def test_detector_ports():
    detector = TargetDetector(CHARUCO, INTRINSICS, period=1 / 30)
    assert [detector.get_output_port(i).get_name() for i in range(detector.num_output_ports())] \
        == ["X_CT_measured", "features", "visible", "reprojection_rms", "covariance", "found",
            "num_points", "detection"]
    sizes = [detector.get_output_port(i).size() for i in range(detector.num_output_ports() - 1)]
    n = len(object_points(CHARUCO)[0])
    assert sizes == [12, 2 * n, n, 1, 36, 1, 1]
    assert detector.get_input_port(0).get_name() == "color_image"


def test_detector_takes_grey_images():
    """The grey input path (the synthetic image is a homography warp, accurate to ~0.1°)."""
    x0, y0, x1, y1 = pattern_extent(CHARUCO)
    X_CT = inverse(X_TC_looking_at(0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5))
    diagram, detector = grey_loop(synthetic_grey_image(X_CT), feature_ids=[7])
    context = diagram.CreateDefaultContext()
    diagram.ExecuteInitializationEvents(context)
    out = outputs(detector, context)
    assert out["found"][0] == 1.0 and out["visible"][0] == 1.0
    rotation_deg, translation_mm = pose_errors(X_CT, vector_to_pose(out["X_CT"]))
    assert rotation_deg < 0.2 and translation_mm < 0.5
    with pytest.raises(ValueError, match="use get_image_input_port"):
        detector.get_color_image_input_port()


def test_detector_rejects_an_image_of_the_wrong_size():
    diagram, detector = grey_loop(np.full((240, 320), 128, np.uint8))
    context = diagram.CreateDefaultContext()
    with pytest.raises(ValueError, match=r"grey_image input of .*: image is 320×240 px but the "
                                         r"intrinsics are 640×480"):
        diagram.ExecuteInitializationEvents(context)


def test_detector_rejects_bad_arguments():
    with pytest.raises(ValueError, match=r"feature_ids: ids \[24, 99\] are not points"):
        TargetDetector(CHARUCO, INTRINSICS, PERIOD, feature_ids=[0, 24, 99])
    with pytest.raises(ValueError, match="feature_ids: expected a non-empty list of distinct"):
        TargetDetector(CHARUCO, INTRINSICS, PERIOD, feature_ids=[3, 3])
    with pytest.raises(ValueError, match="period: must be finite and > 0"):
        TargetDetector(CHARUCO, INTRINSICS, 0.0)
    with pytest.raises(ValueError, match="input_type: expected one of"):
        TargetDetector(CHARUCO, INTRINSICS, PERIOD, input_type="bgr")
    with pytest.raises(ValueError, match="intrinsics: expected a CameraIntrinsics"):
        TargetDetector(CHARUCO, None, PERIOD)
    with pytest.raises(ValueError, match="detect_options: .*unexpected keyword"):
        TargetDetector(CHARUCO, INTRINSICS, PERIOD, max_points=3)
    with pytest.raises(ValueError, match="min_points: expected an integer ≥ 4"):
        TargetDetector(CHARUCO, INTRINSICS, PERIOD, min_points=2)

import math

import numpy as np
import pytest

from handeye_drake.vision.camera_model import CameraIntrinsics, project_points
from handeye_drake.vision.intrinsics import (intrinsics_from_camera_info, load_intrinsics,
                                             write_intrinsics_yaml)

OPENCV_SAMPLE = """%YAML:1.0
---
calibration_time: "Mon 01 Jan 2024 10:00:00 CET"
nframes: 20
image_width: 1280
image_height: 720
board_width: 9
board_height: 6
square_size: 2.3600000888109207e-02
flags: 0
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 9.1234567890123456e+02, 0., 6.4012e+02, 0.,
       9.1365e+02, 3.6071e+02, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 5
   cols: 1
   dt: d
   data: [ -1.2e-01, 3.4e-02, 1.0e-04, -2.0e-04, 5.0e-03 ]
avg_reprojection_error: 2.1e-01
"""

OPENCV_XML = """<?xml version="1.0"?>
<opencv_storage>
<image_width>640</image_width>
<image_height>480</image_height>
<camera_matrix type_id="opencv-matrix">
  <rows>3</rows>
  <cols>3</cols>
  <dt>d</dt>
  <data>
    600. 0. 320. 0. 601. 240. 0. 0. 1.</data></camera_matrix>
<distortion_coefficients type_id="opencv-matrix">
  <rows>1</rows>
  <cols>5</cols>
  <dt>d</dt>
  <data>
    0.1 -0.2 0. 0. 0.05</data></distortion_coefficients>
</opencv_storage>
"""

ROS_CAMERA_INFO = """image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [600.1, 0, 320.5, 0, 601.2, 240.5, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.1, 0.01, 0.001, -0.001, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [600, 0, 320, 0, 0, 600, 240, 0, 0, 0, 1, 0]
"""


def test_distortion_field_and_matrix_constructor():
    cam = CameraIntrinsics.from_matrix([[600, 0, 320], [0, 610, 240], [0, 0, 1]], 640, 480,
                                       [0.1, -0.2, 0.001, 0.002, 0.03])
    assert cam.distortion == (0.1, -0.2, 0.001, 0.002, 0.03)
    np.testing.assert_array_equal(cam.K, [[600, 0, 320], [0, 610, 240], [0, 0, 1]])
    np.testing.assert_array_equal(cam.distortion_coefficients, cam.distortion)
    assert CameraIntrinsics(600, 600).distortion_coefficients is None
    # Skew: K[0,1] = −α_u cot θ round-trips through the Faugeras parameters.
    K = np.array([[800.0, -50.0, 320.0], [0.0, 700.0, 240.0], [0.0, 0.0, 1.0]])
    skewed = CameraIntrinsics.from_matrix(K, 640, 480)
    np.testing.assert_allclose(skewed.K, K, atol=1e-12)
    assert skewed.theta == pytest.approx(math.atan2(800.0, 50.0))
    # The pinhole projection is unchanged by the new field's default.
    uv, _, _ = project_points([[0.1, -0.05, 1.0]], CameraIntrinsics(600, 610))
    np.testing.assert_allclose(uv, [[380.0, 209.5]])


@pytest.mark.parametrize("distortion, message", [
    ((0.1, 0.2, 0.3), r"distortion: OpenCV takes 0, 4, 5, 8, 12, 14 coefficients .*got 3"),
    ((0.1, float("nan"), 0, 0), r"distortion: must be finite"),
    ("0.1,0.2", r"distortion: expected a sequence of numbers"),
])
def test_distortion_validation(distortion, message):
    with pytest.raises(ValueError, match=r"CameraIntrinsics\." + message):
        CameraIntrinsics(600, 600, distortion=distortion)


def test_from_matrix_errors():
    with pytest.raises(ValueError, match=r"K: expected an upper-triangular intrinsic matrix"):
        CameraIntrinsics.from_matrix([[600, 0, 320], [0, 600, 240], [0, 0, 2]], 640, 480)
    with pytest.raises(ValueError, match=r"K: focal lengths .* must be > 0"):
        CameraIntrinsics.from_matrix([[-600, 0, 320], [0, 600, 240], [0, 0, 1]], 640, 480)


def test_spec_string():
    cam = load_intrinsics("600,601.5,320,240", 640, 480)
    assert (cam.alpha_u, cam.alpha_v, cam.u0, cam.v0, cam.width, cam.height) == \
        (600.0, 601.5, 320.0, 240.0, 640, 480)
    assert cam.theta == math.pi / 2 and cam.distortion == ()
    cam = load_intrinsics("600, 601.5, 320, 240, -0.1, 0.01, 0.001, 0.002, 0.003", 640, 480)
    assert cam.distortion == (-0.1, 0.01, 0.001, 0.002, 0.003)
    assert len(load_intrinsics("600,600,320,240,0,0,0,0", 640, 480).distortion) == 4


@pytest.mark.parametrize("spec, width, height, message", [
    ("600,600,320,240", None, None, r"^width: intrinsics '600,600,320,240' has no image width; "
                                    r"pass width and height$"),
    ("600,600,320,240", 640, None, r"^height: .* has no image height"),
    ("600,600,320", 640, 480, r"expected 4, 8, 9 or 12 numbers, got 3; expected fx,fy,cx,cy"),
    ("600,600,320,240,0.1", 640, 480, r"expected 4, 8, 9 or 12 numbers, got 5"),
    ("600,abc,320,240", 640, 480, r"'abc' is not a number"),
    ("600,inf,320,240", 640, 480, r"values must be finite"),
    ("-600,600,320,240", 640, 480, r"focal lengths .* must be > 0"),
    ("600,600,320,240", 640.5, 480, r"^width: image size must be an integer ≥ 1 pixel, got 640.5"),
    ("missing_file.yaml", None, None, r"no such file, and not a fx,fy,cx,cy"),
    ("cam,1.yaml", 640, 480, r"^intrinsics 'cam,1.yaml': no such file, and not a fx,fy,cx,cy"),
])
def test_spec_errors(spec, width, height, message):
    with pytest.raises(ValueError, match=message):
        load_intrinsics(spec, width, height)


def test_opencv_calibration_sample_yaml(tmp_path):
    path = tmp_path / "camera.yaml"
    path.write_text(OPENCV_SAMPLE)
    cam = load_intrinsics(path)
    np.testing.assert_array_equal(cam.K, [[912.34567890123456, 0, 640.12], [0, 913.65, 360.71],
                                          [0, 0, 1]])
    assert cam.distortion == (-0.12, 0.034, 1e-4, -2e-4, 5e-3)
    assert (cam.width, cam.height) == (1280, 720)
    assert load_intrinsics(str(path), 1280, 720) == cam  # agreeing arguments are fine
    with pytest.raises(ValueError, match=r"^width: intrinsics file '.*camera.yaml' says image "
                                         r"width 1280, the argument says 640$"):
        load_intrinsics(path, 640, 480)


def test_opencv_xml(tmp_path):
    path = tmp_path / "camera.xml"
    path.write_text(OPENCV_XML)
    cam = load_intrinsics(path)
    assert cam == CameraIntrinsics(600, 601, u0=320, v0=240, width=640, height=480,
                                   distortion=(0.1, -0.2, 0.0, 0.0, 0.05))


def test_ros_camera_info(tmp_path):
    path = tmp_path / "ost.yaml"
    path.write_text(ROS_CAMERA_INFO)
    cam = load_intrinsics(path)
    assert cam == CameraIntrinsics(600.1, 601.2, u0=320.5, v0=240.5, width=640, height=480,
                                   distortion=(-0.1, 0.01, 0.001, -0.001, 0.0))
    # A CameraInfo message dump (ROS 2 field names).
    path.write_text("height: 480\nwidth: 640\ndistortion_model: rational_polynomial\n"
                    "d: [0.1, 0.01, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0]\n"
                    "k: [600.0, 0.0, 320.0, 0.0, 600.0, 240.0, 0.0, 0.0, 1.0]\n")
    cam = load_intrinsics(path)
    assert cam.distortion == (0.1, 0.01, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0) and cam.width == 640


def test_camera_info_message_fields():
    K = [600.0, 0.0, 320.0, 0.0, 601.0, 240.0, 0.0, 0.0, 1.0]
    D = [0.1, 0.01, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0]
    cam = intrinsics_from_camera_info(K, D, 640, 480, "rational_polynomial")
    assert cam == CameraIntrinsics(600.0, 601.0, u0=320.0, v0=240.0, width=640, height=480,
                                   distortion=tuple(D))
    assert intrinsics_from_camera_info(K, [], 640, 480, "").distortion == ()
    for args, message in [
            ((K, [0.1, 0.01, 0.0, 0.0], 640, 480, "equidistant", "/cam/camera_info"),
             "/cam/camera_info: field distortion_model: 'equidistant' is not supported"),
            ((K, [0.1] * 6, 640, 480, "plumb_bob"),
             "CameraInfo: field D: OpenCV takes 0, 4, 5, 8, 12, 14 coefficients, got 6"),
            ((K, [], 0, 480, "plumb_bob"), "CameraInfo: field width: image size must be"),
            ((K[:6], [], 640, 480, ""), "CameraInfo: field K: expected a 3×3 matrix")]:
        with pytest.raises(ValueError) as info:
            intrinsics_from_camera_info(*args)
        assert str(info.value).startswith(message), str(info.value)


@pytest.mark.parametrize("text, message", [
    (ROS_CAMERA_INFO.replace("plumb_bob", "equidistant"),
     r"field distortion_model: 'equidistant' is not supported"),
    (ROS_CAMERA_INFO.replace("data: [600.1, 0, 320.5, 0, 601.2, 240.5, 0, 0, 1]",
                             "data: [600.1, 0, 320.5, 0, 601.2, 240.5]"),
     r"field camera_matrix: rows × cols = 9 but data has 6 numbers"),
    (ROS_CAMERA_INFO.replace("camera_matrix:", "camera_matrx:"), r"field camera_matrix is missing"),
    (ROS_CAMERA_INFO.replace("data: [-0.1, 0.01, 0.001, -0.001, 0]", "data: [-0.1, 0.01, x]"),
     r"field distortion_coefficients: data must be a list of numbers"),
    (ROS_CAMERA_INFO.replace("image_width: 640", "image_width: wide"),
     r"field image_width: expected a number, got 'wide'"),
    (ROS_CAMERA_INFO.replace("image_height: 480\n", ""), r"has no image height"),
    ("camera_matrix: [1, 2\n", r"not valid YAML"),
    ("- 1\n- 2\n", r"expected a YAML mapping with camera_matrix"),
    (OPENCV_SAMPLE.replace("rows: 5", "rows: 3").replace(
        "-1.2e-01, 3.4e-02, 1.0e-04, -2.0e-04, 5.0e-03", "1, 2, 3"),
     r"field distortion_coefficients: OpenCV takes 0, 4, 5, 8, 12, 14 coefficients, got 3"),
    (OPENCV_SAMPLE.replace("data: [ -1.2e-01", "data: [ -1.2e-01, ").replace("]\navg", "\navg"),
     r"not a valid OpenCV YAML/XML file"),
    (OPENCV_SAMPLE.replace("0., 0., 1. ]", "0., 0., 2. ]"),
     r"field camera_matrix/distortion_coefficients: K: expected an upper-triangular"),
])
def test_file_errors_name_file_and_field(tmp_path, text, message):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ValueError) as info:
        load_intrinsics(path)
    assert str(info.value).startswith(f"intrinsics file {str(path)!r}") or \
        "has no image" in str(info.value)
    assert __import__("re").search(message, str(info.value)), str(info.value)


def test_binary_file_is_an_error(tmp_path):
    path = tmp_path / "camera.yaml"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\xff\xfe")
    with pytest.raises(ValueError, match=r"intrinsics file .*: cannot read it as text"):
        load_intrinsics(path)


@pytest.mark.parametrize("distortion", [(), (0.1, -0.2, 0.001, 0.002),
                                        (-0.12345678901234567, 0.1, 1e-17, 0, 0.3),
                                        tuple(np.linspace(-0.1, 0.1, 8))])
def test_write_read_round_trip_is_exact(tmp_path, distortion):
    cam = CameraIntrinsics(alpha_u=612.3456789012345, alpha_v=611.1, u0=319.75, v0=241.125,
                           width=640, height=480, distortion=distortion)
    for name in ("cam.yaml", "cam.xml"):
        path = write_intrinsics_yaml(cam, tmp_path / name)
        assert load_intrinsics(path) == cam
    text = (tmp_path / "cam.yaml").read_text()
    assert text.startswith("%YAML:1.0") and "camera_matrix: !!opencv-matrix" in text
    assert ("distortion_coefficients" in text) == bool(distortion)


def test_write_errors(tmp_path):
    cam = CameraIntrinsics(600, 600)
    with pytest.raises(ValueError, match=r"path: expected a .yaml, .yml or .xml file name"):
        write_intrinsics_yaml(cam, tmp_path / "cam.json")
    with pytest.raises(ValueError, match=r"intrinsics: expected a CameraIntrinsics, got dict"):
        write_intrinsics_yaml({}, tmp_path / "cam.yaml")

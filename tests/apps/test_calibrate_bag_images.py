"""``handeye-drake calibrate --bag --image-topic``: hand-eye calibration from the images of real
ROS 1 .bag, ROS 2 sqlite3 and ROS 2 MCAP files (written by rosbags from the shipped rendered
images, ``recorded.example_bag``: the robot sweeps through the 14 poses without stopping, tf at
100 Hz, image stamps 35 ms late), through the target detector, the clock offset estimate and the
maximum-likelihood fit; the errors a user meets, each as one line with exit status 2."""

import json
import tracemalloc

import cv2
import numpy as np
import pytest

from handeye_drake import rotation_error_deg
from handeye_drake.calibration import bag_image_streams
from handeye_drake.apps.cli import main
from handeye_drake.recorded import bags
from handeye_drake.recorded.example_bag import (CAMERA_FRAME, CAMERA_INFO_TOPIC, COMPRESSED_TOPIC,
                                                IMAGE_TOPIC, IMAGES, example_bag,
                                                write_example_bag)
from handeye_drake.vision.intrinsics import load_intrinsics
from tests.apps.test_calibrate import _within

#: Per storage: how its images are encoded (every Image path and both compressions are covered).
FORMATS = {"ros1": dict(encoding="rgb8", row_padding=8, compression="png"),
           "sqlite3": dict(encoding="bgra8", compression="jpeg", jpeg_quality=80),
           "mcap": dict(encoding="mono16", compression="png")}
SHIPPED = load_intrinsics(IMAGES / "intrinsics.yaml")
#: Header stamp of a damaged CompressedImage between images 7 and 8 (skipped with its reason).
DAMAGED_NS = 1_700_000_009_000_000_000


def _extras(b, truth):
    """Topics for the error cases: a depth image, CameraInfo for another size, a fisheye one,
    an uncalibrated one (K = 0); images without stamps, and images 1-4 with the first two
    stamped alike."""
    grey = [cv2.imread(str(IMAGES / im["file"]), cv2.IMREAD_GRAYSCALE) for im in truth["images"]]
    for k, stamp in enumerate([0, 0, 2, 3]):
        ns = truth["images"][stamp]["stamp_ns"]
        for topic, header_ns in (("/camera/restamped/image_raw", ns),
                                 ("/camera/unstamped/image_raw", 0)):
            b.add(topic, "sensor_msgs/msg/Image", ns + k,
                  b.image(header_ns, CAMERA_FRAME, grey[k], "mono8"))
    for k in range(3):
        ns = 1_700_000_001_000_000_000 + k * 10**8
        depth = np.full((6, 8), 1.5, np.float32)
        b.add("/camera/depth/image_raw", "sensor_msgs/msg/Image", ns,
              b.image(ns, CAMERA_FRAME, depth.view(np.uint8).reshape(6, 32), "32FC1"))
        for topic, info in (("/camera/small/camera_info", (SHIPPED.K / 2 + np.diag([0, 0, .5]),
                                                           [0.0] * 5, 320, 240, "plumb_bob")),
                            ("/camera/fisheye/camera_info", (SHIPPED.K, [0.1, 0.01, 0.0, 0.0],
                                                             640, 480, "equidistant")),
                            ("/camera/uncalibrated/camera_info", (np.zeros(9), [], 640, 480,
                                                                  ""))):
            b.add(topic, "sensor_msgs/msg/CameraInfo", ns, b.camera_info(ns, CAMERA_FRAME, *info))


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """{storage: (bag path, truth)}, each written once."""
    out = {}
    for storage, options in FORMATS.items():
        root = tmp_path_factory.mktemp(storage)
        path = root / ("cell.bag" if storage == "ros1" else "cell")
        writer, truth = example_bag(path, storage, **options)
        writer.add(COMPRESSED_TOPIC, "sensor_msgs/msg/CompressedImage", DAMAGED_NS,
                   writer.compressed(DAMAGED_NS, CAMERA_FRAME, b"\x89PNG\r\n\x1a\n cut",
                                     "mono8; png compressed mono8"))
        if storage == "ros1":
            _extras(writer, truth)
        writer.write()
        out[storage] = (path, truth)
    return out


def _run(tmp_path, *args, name="out"):
    """(exit code, calibration.json or None) of the command."""
    out = tmp_path / name
    code = main(["calibrate", *map(str, args), "--out", str(out)])
    path = out / "calibration.json"
    return code, (json.loads(path.read_text()) if path.exists() else None)


def _seconds(ns):
    return bags._seconds(ns)


@pytest.mark.parametrize("storage", FORMATS)
@pytest.mark.parametrize("topic", [IMAGE_TOPIC, COMPRESSED_TOPIC])
def test_the_images_of_each_format_give_X_EC_within_its_sigma(recordings, storage, topic,
                                                               tmp_path, capsys):
    path, truth = recordings[storage]
    code, doc = _run(tmp_path, "--bag", path, "--robot-frames", "base_link:tool0",
                     "--image-topic", topic, "--target", truth["target"])
    printed = capsys.readouterr().out
    assert code == 0, printed
    assert doc["verdict"]["status"] == "OK"
    # The clock offset is the camera's 35 ms latency (the robot moves 10–30°/s at the images).
    assert abs(doc["time_offset"]["value_s"] - truth["latency"]) < 0.001
    X_EC, X = np.array(truth["X_EC"]), np.array(doc["X_EC"]["matrix"])
    # Measured: 0.015–0.027° and 0.12–0.22 mm, σ 0.017° / 0.13 mm (JPEG: 0.017° / 0.13 mm).
    assert rotation_error_deg(X_EC, X) < 0.05
    assert np.linalg.norm(X[:3, 3] - X_EC[:3, 3]) < 5e-4
    assert _within(X_EC, X, doc["X_EC"])
    images = doc["inputs"]["images"]
    assert images["intrinsics"] == f"CameraInfo {CAMERA_INFO_TOPIC}"
    per_image = images["per_image"]
    found = [p for p in per_image if p["found"]]
    assert [p["stamp"] for p in found] == [_seconds(im["stamp_ns"]) for im in truth["images"]]
    assert [p["message"] for p in found] == (list(range(1, 15)) if topic == IMAGE_TOPIC else
                                             list(range(1, 8)) + list(range(9, 16)))
    assert all(p["robot_line"] is None and p["reprojection_rms_px"] < 0.2 for p in found)
    skipped = [p for p in per_image if not p["found"]]
    if topic == COMPRESSED_TOPIC:  # the damaged message, with why
        assert [(p["message"], p["stamp"]) for p in skipped] == [(8, _seconds(DAMAGED_NS))]
        assert "cannot decode the compressed image" in skipped[0]["reason"]
    else:
        assert skipped == []
    # Drawings named by index and stamp; the table printed with the stamps.
    first = tmp_path / "out" / "detections" / "0000_1700000001.035000000.png"
    assert first.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert found[0]["drawing"] == str(first)
    assert "1700000001.035000" in printed and "stamp (s)" in printed


def test_camera_info_gives_the_shipped_intrinsics_in_every_format(recordings):
    for storage, (path, _) in recordings.items():
        info = bags.read_bag(path, robot_frames=None,
                             camera_info_topic=CAMERA_INFO_TOPIC).camera_info
        assert info.intrinsics() == SHIPPED, storage
    path, _ = recordings["ros1"]
    info = bags.read_bag(path, None, camera_info_topic="/camera/uncalibrated/camera_info"
                         ).camera_info
    assert not info.calibrated
    with pytest.raises(ValueError, match=r"^CameraInfo: K is all zeros \(ROS's uncalibrated "
                       r"camera\)$"):
        info.intrinsics()
    # The one the calibration used, found beside the compressed topic.
    path, truth = recordings["mcap"]
    streams = bag_image_streams(path, "base_link:tool0", COMPRESSED_TOPIC, truth["target"])
    assert streams.intrinsics == SHIPPED and streams.camera_resampler is None


def test_max_images_reads_an_even_subset_and_says_so(recordings):
    path, truth = recordings["mcap"]
    streams = bag_image_streams(path, "base_link:tool0", IMAGE_TOPIC, truth["target"],
                                max_images=5)
    # Messages 1, 4, 7, 11, 14 of 14: round(linspace(0, 13, 5)) + 1.
    assert [r.message for r in streams.images] == [1, 4, 7, 11, 14]
    assert streams.camera.timestamps.tolist() == [
        _seconds(truth["images"][k - 1]["stamp_ns"]) for k in (1, 4, 7, 11, 14)]
    assert streams.inputs["images"]["intrinsics_note"].startswith(
        f"5 of the 14 images on {IMAGE_TOPIC} used, evenly spaced over the bag (--max-images 5)")


def test_an_image_stamped_like_an_earlier_one_is_not_a_new_sample(recordings):
    path, truth = recordings["ros1"]
    streams = bag_image_streams(path, "base_link:tool0", "/camera/restamped/image_raw",
                                truth["target"])
    assert [(r.message, r.found, r.reason) for r in streams.images] == [
        (1, True, ""), (2, False, "same header stamp as an earlier image"), (3, True, ""),
        (4, True, "")]
    assert streams.camera.timestamps.tolist() == [
        _seconds(truth["images"][k]["stamp_ns"]) for k in (0, 2, 3)]
    assert [streams.camera.lines[k] for k in range(3)] == [1, 3, 4]


def test_images_are_streamed_not_held(tmp_path):
    """Twice the images (+14 mono8 images, 4.3 MB) raise the peak of traced memory by less than
    2 MB (measured 0.16 MB, against 4.2 MB when the decoded images are kept): no image
    outlives its detection."""
    peaks = []
    for repeat in (1, 2):
        path = tmp_path / f"sweep{repeat}"
        truth = write_example_bag(path, "mcap", encoding="mono8", repeat=repeat)
        tracemalloc.start()
        try:
            streams = bag_image_streams(path, "base_link:tool0", IMAGE_TOPIC, truth["target"])
            peaks.append(tracemalloc.get_traced_memory()[1])
        finally:
            tracemalloc.stop()
        assert sum(r.found for r in streams.images) == 14 * repeat
    assert peaks[1] - peaks[0] < 2e6, peaks


def test_without_usable_camera_info_the_intrinsics_come_from_the_images(recordings, tmp_path):
    path, truth = recordings["ros1"]
    code, doc = _run(tmp_path, "--bag", path, "--image-topic", IMAGE_TOPIC, "--target",
                     truth["target"], "--camera-info-topic", "/camera/uncalibrated/camera_info")
    assert code == 0
    images = doc["inputs"]["images"]
    assert images["intrinsics"] == "calibrated from the images"
    assert images["intrinsics_note"].startswith(
        "CameraInfo on /camera/uncalibrated/camera_info has K = 0 (an uncalibrated camera); "
        "intrinsics calibrated from the images (cv2.calibrateCamera on 14 images)")
    X_EC, X = np.array(truth["X_EC"]), np.array(doc["X_EC"]["matrix"])
    # Measured 0.081° / 2.2 mm; σ 0.56° / 3.4 mm with the intrinsics' uncertainty.
    assert rotation_error_deg(X_EC, X) < 0.3 and np.linalg.norm(X[:3, 3] - X_EC[:3, 3]) < 5e-3
    assert _within(X_EC, X, doc["X_EC"], k=3.0)
    # Refined jointly with the hand-eye transform (their uncertainty in the σ), said so.
    assert doc["intrinsics"]["refined"] in ("pinhole", "k1k2", "full")
    assert any("intrinsics calibrated from the same images" in n
               for n in doc["corner_level"]["notes"])
    # "none" ignores the CameraInfo beside the topic.
    streams = bag_image_streams(path, "base_link:tool0", IMAGE_TOPIC, truth["target"],
                                camera_info_topic="none")
    assert streams.inputs["images"]["intrinsics"] == "calibrated from the images"
    assert streams.camera_resampler is not None and streams.intrinsics != SHIPPED


@pytest.mark.parametrize("args, message", [
    (("--image-topic", "/camera/image"),
     "--image-topic: no topic '/camera/image'; topics: /camera/color/image_raw "
     "(sensor_msgs/msg/Image, 14 msgs), /camera/color/image_raw/compressed "
     "(sensor_msgs/msg/CompressedImage, 15 msgs), /camera/depth/image_raw (sensor_msgs/msg/Image, "
     "3 msgs), /camera/restamped/image_raw (sensor_msgs/msg/Image, 4 msgs), "
     "/camera/unstamped/image_raw (sensor_msgs/msg/Image, 4 msgs) (those of type "
     "sensor_msgs/msg/Image or sensor_msgs/msg/CompressedImage; 6 others)"),
    (("--image-topic", "/camera/depth/image_raw"),
     "/camera/depth/image_raw message 1: unsupported image encoding '32FC1'; supported: mono8, "
     "8UC1, mono16, 16UC1, rgb8, bgr8, rgba8, bgra8 (or a CompressedImage topic)"),
    (("--image-topic", IMAGE_TOPIC, "--camera-info-topic", "/camera/small/camera_info"),
     "--camera-info-topic /camera/small/camera_info: CameraInfo is for 320×240 images, the "
     "images on /camera/color/image_raw are 640×480"),
    (("--image-topic", IMAGE_TOPIC, "--camera-info-topic", "/camera/fisheye/camera_info"),
     "--camera-info-topic /camera/fisheye/camera_info: field distortion_model: 'equidistant' is "
     "not supported"),
    (("--image-topic", IMAGE_TOPIC, "--camera-info-topic", IMAGE_TOPIC),
     "--camera-info-topic: topic '/camera/color/image_raw' has type sensor_msgs/msg/Image, "
     "expected sensor_msgs/msg/CameraInfo"),
    (("--image-topic", IMAGE_TOPIC, "--intrinsics", "/nowhere/intrinsics.yaml"),
     "intrinsics '/nowhere/intrinsics.yaml': no such file"),
    (("--image-topic", "/camera/unstamped/image_raw"),
     "--image-topic /camera/unstamped/image_raw: no image could be read (message 1 (stamp "
     "0.000000): header stamp not set (0): the image cannot be placed in time; message 2"),
])
def test_errors_are_one_line(recordings, tmp_path, capsys, args, message):
    path, truth = recordings["ros1"]
    code, doc = _run(tmp_path, "--bag", path, "--target", truth["target"], *args)
    err = capsys.readouterr().err
    assert code == 2 and doc is None
    assert err.count("\n") == 1 and err.startswith("handeye-drake: error: ")
    assert message in err, err


def test_a_target_in_no_image_and_missing_options(recordings, tmp_path, capsys):
    path, truth = recordings["ros1"]
    code, _ = _run(tmp_path, "--bag", path, "--image-topic", IMAGE_TOPIC, "--target",
                   "apriltag:36h11:0.05")
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert ("--image-topic /camera/color/image_raw: the target apriltag:36h11:0.05 was found in "
            "only 0 of 14 images (≥ 3 needed): message 1 (stamp 1700000001.035000): ") in err
    code, _ = _run(tmp_path, "--bag", path, "--image-topic", IMAGE_TOPIC, name="no_target")
    assert code == 2 and "--target: the calibration target is needed with --image-topic" in \
        capsys.readouterr().err
    code, _ = _run(tmp_path, "--image-topic", IMAGE_TOPIC, "--target", truth["target"],
                   "--robot", IMAGES / "robot_poses.tum", name="no_bag")
    assert code == 2 and "give one of" in capsys.readouterr().err
    code, _ = _run(tmp_path, "--bag", path, "--image-topic", IMAGE_TOPIC, "--target",
                   truth["target"], "--max-images", "2", name="few")
    assert code == 2 and "--max-images: expected 0 (all) or at least 3, got '2'" in \
        capsys.readouterr().err


@pytest.mark.parametrize("latency", [0.5, 0.8])
def test_a_latency_beyond_the_range_is_not_blamed_on_milliseconds(tmp_path, capsys, latency):
    # images every 1.2 s beside tf at 100 Hz, in seconds, stamped `latency` s late: once hinted
    # "if the timestamps are in milliseconds (833 Hz)"
    path = tmp_path / "late.bag"
    write_example_bag(path, "ros1", latency=latency)
    argv = ["calibrate", "--bag", str(path), "--robot-frames", "base_link:tool0", "--image-topic",
            IMAGE_TOPIC, "--target", "charuco:7x5:0.04:0.03:DICT_5X5_100", "--intrinsics",
            str(IMAGES / "intrinsics.yaml")]
    assert main(argv + ["--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the best offset lies on the search bound" in err
    assert "milliseconds" not in err and "--time-scale" not in err
    assert main(argv + ["--time-offset-range", "1", "--out", str(tmp_path / "b")]) == 0
    doc = json.loads((tmp_path / "b" / "calibration.json").read_text())
    assert abs(doc["time_offset"]["value_s"] - latency) < 0.005

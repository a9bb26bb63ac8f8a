"""ROS bags without ROS: real ROS 1 .bag, ROS 2 sqlite3 (.db3) and ROS 2 MCAP files written with
rosbags' own writers from a simulated recording (the example's trajectory and true X_EC), read
back with ``recorded.bags.read_bag`` and checked against the truth: poses to 1e-9, stamps, images
and intrinsics exactly; then ``calibrate_streams`` on the recovered streams recovers X_EC."""

import math
import re

import cv2
import numpy as np
import pytest
from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp, rotation_from_rpy
from handeye_drake.recorded import bags
from handeye_drake.calibration import calibrate_streams
from handeye_drake.recorded.example import TRUE_X_EC, X_BT, camera_pose
from handeye_drake.recorded.example_bag import BagWriter
from handeye_drake.vision.camera_model import CameraIntrinsics

EPOCH_NS = 1_700_000_000 * 10**9
DURATION = 12.0
ROBOT_RATE = 50.0
CAMERA_RATE = 10.0
IMAGE_RATE = 2.0
CAMERA_LATENCY = 0.02          # camera stamps are late by this (the clock offset to estimate)
ROTATION_NOISE = math.radians(0.1)
TRANSLATION_NOISE = 0.0005
K = [612.5, 0.0, 319.75, 0.0, 611.25, 241.125, 0.0, 0.0, 1.0]
D = [0.1, -0.25, 0.001, -0.002, 0.05]
IMAGE_ENCODINGS = ("rgb8", "bgr8", "rgba8", "bgra8", "mono8", "mono16")
FORMATS = ("ros1", "sqlite3", "mcap")


# ------------------------------------------------------------------------------- simulation
def _rz(a):
    return make_transform(rotation_from_rpy([0.0, 0.0, a]), [0.0, 0.0, 0.0])


def _ry(a):
    return make_transform(rotation_from_rpy([0.0, a, 0.0]), [0.0, 0.0, 0.0])


def _shift(x, y, z):
    return make_transform(np.eye(3), [x, y, z])


STATIC = {  # child: (parent, X_parent_child), published once on /tf_static
    "base_link": ("world", _shift(0.0, 0.0, 0.8)),
    "base": ("base_link", make_transform(rotation_from_rpy([0.0, 0.0, math.pi]), [0, 0, 0])),
    "flange": ("wrist_3_link", make_transform(rotation_from_rpy([-math.pi / 2, 0, -math.pi / 2]),
                                              [0.0, 0.0996, 0.0])),
    "tool0": ("flange", make_transform(rotation_from_rpy([math.pi / 2, 0, math.pi / 2]),
                                       [0.0, 0.0, 0.0])),
    # an old guess of the camera mount, as a cell would publish it: part of the tree, not of
    # the robot chain
    "camera_optical_frame": ("tool0", make_transform(np.eye(3), [0.05, 0.0, 0.07])),
}
DYNAMIC_PARENTS = {"shoulder_link": "base", "upper_arm_link": "shoulder_link",
                   "forearm_link": "upper_arm_link", "wrist_3_link": "forearm_link"}


def _joint_edges(t):
    """X_parent_child of the first three dynamic joints at time t."""
    return {"shoulder_link": _rz(0.4 * math.sin(0.5 * t)) @ _shift(0.0, 0.0, 0.163),
            "upper_arm_link": _shift(0.0, 0.138, 0.0) @ _ry(-0.3 + 0.2 * math.cos(0.4 * t)),
            "forearm_link": _shift(0.0, -0.131, 0.425) @ _ry(0.9 + 0.1 * math.sin(0.3 * t))}


def robot_truth(t):
    """X_BE (tool0 in base_link) and every dynamic edge at time t: the last joint closes the
    chain onto the example's trajectory."""
    X_BE = camera_pose(t) @ inverse(TRUE_X_EC)
    edges = _joint_edges(t)
    prefix = STATIC["base"][1] @ edges["shoulder_link"] @ edges["upper_arm_link"] @ \
        edges["forearm_link"]
    suffix = STATIC["flange"][1] @ STATIC["tool0"][1]
    edges["wrist_3_link"] = inverse(prefix) @ X_BE @ inverse(suffix)
    return X_BE, edges


def _ns(t):
    return EPOCH_NS + int(round(t * 1e9))


def _seconds(ns):
    return ns // 10**9 + (ns % 10**9) * 1e-9


def simulate(seed=0):
    rng = np.random.default_rng(seed)
    robot_ns = [_ns(k / ROBOT_RATE) for k in range(int(DURATION * ROBOT_RATE) + 1)]
    camera = []
    for k in range(int(DURATION * CAMERA_RATE) + 1):
        instant = k / CAMERA_RATE
        X_CT = inverse(camera_pose(instant)) @ X_BT
        X_CT = make_transform(rotation_exp(ROTATION_NOISE * rng.normal(size=3)),
                              TRANSLATION_NOISE * rng.normal(size=3)) @ X_CT
        camera.append((_ns(instant + CAMERA_LATENCY), X_CT))
    images = []
    for k in range(int(DURATION * IMAGE_RATE) + 1):
        rgb = rng.integers(0, 256, size=(6, 8, 3), dtype=np.uint8)
        mono16 = rng.integers(0, 65536, size=(6, 8), dtype=np.uint16)
        images.append((_ns(k / IMAGE_RATE + CAMERA_LATENCY), rgb, mono16))
    return {"robot_ns": robot_ns, "camera": camera, "images": images}


# ---------------------------------------------------------------------------------- writing
class _Bag(BagWriter):
    """The package's bag writer with this recording's image and camera info messages."""

    def image(self, ns, encoding, rgb, mono16, pad=0):
        if encoding == "mono16":  # big-endian on the wire
            return super().image(ns, "camera_optical_frame", mono16, encoding, pad, True)
        bgr = rgb[:, :, ::-1]
        pixels = {"rgb8": rgb, "bgr8": bgr, "mono8": rgb[:, :, 0],
                  "rgba8": np.dstack([rgb, np.full((6, 8), 7, np.uint8)]),
                  "bgra8": np.dstack([bgr, np.full((6, 8), 9, np.uint8)])}[encoding]
        return super().image(ns, "camera_optical_frame", pixels, encoding, pad)

    def compressed(self, ns, rgb):
        ok, png = cv2.imencode(".png", np.ascontiguousarray(rgb[:, :, ::-1]))
        assert ok
        return super().compressed(ns, "camera_optical_frame", png.tobytes(),
                                  "bgr8; png compressed bgr8")

    def camera_info(self, ns):
        return super().camera_info(ns, "camera_optical_frame", K, D, 640, 480)


def write_recording(path, fmt, sim, leading_slash=False):
    """The simulated cell: /tf_static once, /tf at 50 Hz in two messages per stamp plus an
    unrelated conveyor frame at 7 Hz, the camera's X_CT on /camera/target_pose (received out
    of stamp order) and as tf camera_optical_frame → target, images and camera info."""
    b = _Bag(path, fmt)
    name = (lambda f: "/" + f) if leading_slash else (lambda f: f)
    tf, tf_static = "tf2_msgs/msg/TFMessage", "/tf_static"
    t0 = sim["robot_ns"][0]
    b.add(tf_static, tf, t0, b.tf([b.transform(t0, name(p), name(c), X)
                                   for c, (p, X) in STATIC.items()]))
    for ns in sim["robot_ns"]:
        _, edges = robot_truth((ns - EPOCH_NS) * 1e-9)
        msgs = [b.transform(ns, name(DYNAMIC_PARENTS[c]), name(c), X) for c, X in edges.items()]
        b.add("/tf", tf, ns + 1_000_000, b.tf(msgs[:2]))
        b.add("/tf", tf, ns + 2_000_000, b.tf(msgs[2:]))
    for k in range(int(DURATION * 7)):
        ns = EPOCH_NS + k * 10**9 // 7
        b.add("/tf", tf, ns, b.tf([b.transform(ns, "base_link", "conveyor",
                                               _shift(0.001 * k, 0.0, 0.0))]))
    rng = np.random.default_rng(1)
    for ns, X_CT in sim["camera"]:
        receive = ns + int(rng.uniform(0.0, 0.25e9))  # detector latency: arrival order shuffled
        b.add("/camera/target_pose", "geometry_msgs/msg/PoseStamped", receive,
              b.pose(ns, "camera_optical_frame", X_CT))
        b.add("/tf", tf, receive, b.tf([b.transform(ns, "camera_optical_frame", "target",
                                                    X_CT)]))
    for k, (ns, rgb, mono16) in enumerate(sim["images"]):
        for enc in IMAGE_ENCODINGS:
            b.add(f"/camera/{enc}/image_raw", "sensor_msgs/msg/Image", ns + 30_000_000,
                  b.image(ns, enc, rgb, mono16, pad=3 if enc == "rgb8" else 0))
        b.add("/camera/color/image_raw/compressed", "sensor_msgs/msg/CompressedImage",
              ns + 30_000_000, b.compressed(ns, rgb))
        b.add("/camera/rgb8/camera_info", "sensor_msgs/msg/CameraInfo", ns + 30_000_000,
              b.camera_info(ns))
    b.write()
    return path


# ------------------------------------------------------------------------------------ tests
@pytest.fixture(scope="module")
def sim():
    return simulate()


@pytest.fixture(scope="module", params=FORMATS)
def recording(request, sim, tmp_path_factory):
    fmt = request.param
    root = tmp_path_factory.mktemp(fmt)
    path = write_recording(root / ("cell.bag" if fmt == "ros1" else "cell"), fmt, sim,
                           leading_slash=fmt == "ros1")
    return fmt, path


def _max_diff(A, B):
    return float(np.abs(np.asarray(A) - np.asarray(B)).max())


def _expected_image(enc, rgb, mono16):
    if enc == "mono8":
        return rgb[:, :, 0]
    if enc == "mono16":
        return mono16
    return rgb[:, :, ::-1]  # every colour encoding comes back as BGR


def test_bag_files_are_what_they_claim(recording):
    fmt, path = recording
    if fmt == "ros1":
        assert path.read_bytes()[:13] == b"#ROSBAG V2.0\n"
    else:
        (storage,) = [p for p in path.iterdir() if p.name != "metadata.yaml"]
        assert storage.suffix == {"sqlite3": ".db3", "mcap": ".mcap"}[fmt]
        head = storage.read_bytes()[:16]
        assert head.startswith(b"SQLite format 3\x00" if fmt == "sqlite3" else b"\x89MCAP0\r\n")


def test_robot_and_camera_streams_match_the_truth(recording, sim):
    fmt, path = recording
    data = bags.read_bag(path, robot_frames="base_link:tool0",
                         camera_topic="/camera/target_pose")
    robot = data.robot
    assert robot.timestamps.tolist() == [_seconds(ns) for ns in sim["robot_ns"]]
    truth = np.array([robot_truth((ns - EPOCH_NS) * 1e-9)[0] for ns in sim["robot_ns"]])
    assert _max_diff(robot.poses, truth) < 1e-9
    camera = data.camera
    assert camera.timestamps.tolist() == [_seconds(ns) for ns, _ in sim["camera"]]
    assert _max_diff(camera.poses, [X for _, X in sim["camera"]]) < 1e-9
    assert "base_link" in data.tf_frames and "conveyor" in data.tf_frames
    assert data.topics["/camera/target_pose"] == ("geometry_msgs/msg/PoseStamped",
                                                  len(sim["camera"]))
    assert data.camera_info is None and data.images == []


def test_camera_from_tf_frames_either_way(recording, sim):
    _, path = recording
    truth = np.array([X for _, X in sim["camera"]])
    stamps = [_seconds(ns) for ns, _ in sim["camera"]]
    direct = bags.read_bag(path, robot_frames=None,
                           camera_frames=("camera_optical_frame", "target"))
    inverted = bags.read_bag(path, robot_frames=None, camera_frames="target:camera_optical_frame",
                             camera_invert=True)
    for data in (direct, inverted):
        assert data.robot is None
        assert data.camera.timestamps.tolist() == stamps
        assert _max_diff(data.camera.poses, truth) < 1e-9
    # Without the flag the reversed pair is X_TC, the inverse.
    swapped = bags.read_bag(path, robot_frames=None, camera_frames="target:camera_optical_frame")
    assert _max_diff(swapped.camera.poses, [inverse(X) for X in truth]) < 1e-9


@pytest.mark.parametrize("encoding", IMAGE_ENCODINGS + ("compressed",))
def test_images_and_camera_info(recording, sim, encoding):
    _, path = recording
    topic = "/camera/color/image_raw/compressed" if encoding == "compressed" else \
        f"/camera/{encoding}/image_raw"
    data = bags.read_bag(path, robot_frames=None, image_topic=topic,
                         camera_info_topic="/camera/rgb8/camera_info" if encoding != "rgb8"
                         else None)  # rgb8: found beside the image topic
    assert [s for s, _ in data.images] == [_seconds(ns) for ns, _, _ in sim["images"]]
    enc = "rgb8" if encoding == "compressed" else encoding
    for (_, img), (_, rgb, mono16) in zip(data.images, sim["images"]):
        expected = _expected_image(enc, rgb, mono16)
        assert img.dtype == expected.dtype and img.shape == expected.shape
        assert np.array_equal(img, expected)
    info = data.camera_info
    assert info.K.reshape(-1).tolist() == K and list(info.D) == D
    assert (info.width, info.height, info.distortion_model, info.frame_id) == \
        (640, 480, "plumb_bob", "camera_optical_frame")
    intr = info.intrinsics()
    assert isinstance(intr, CameraIntrinsics)
    assert (intr.alpha_u, intr.alpha_v, intr.u0, intr.v0, intr.width, intr.height) == \
        (612.5, 611.25, 319.75, 241.125, 640, 480)
    # (CameraIntrinsics.K writes −fx·cot(π/2) = −3.8e-14 for the zero skew)
    assert _max_diff(intr.K, np.array(K).reshape(3, 3)) < 1e-12


def test_camera_info_found_next_to_the_image_topic(recording):
    _, path = recording
    data = bags.read_bag(path, robot_frames=None, image_topic="/camera/rgb8/image_raw",
                         max_images=4)
    assert data.camera_info is not None and data.camera_info.K[0, 0] == 612.5
    assert data.image_count == 25 and len(data.images) == 4
    stamps = [s for s, _ in data.images]
    step = stamps[1] - stamps[0]
    assert step == pytest.approx(4.0, abs=1e-6)  # messages 1, 9, 17, 25 of 25 at 2 Hz
    assert np.allclose(np.diff(stamps), step, atol=1e-6)


def test_calibration_from_the_bag_recovers_X_EC(recording):
    fmt, path = recording
    data = bags.read_bag(path, ("base_link", "tool0"), camera_topic="/camera/target_pose")
    result = calibrate_streams(data.robot, data.camera)
    assert result.aligned.time_offset == pytest.approx(CAMERA_LATENCY, abs=0.005)
    R_err = np.degrees(np.linalg.norm(cv2.Rodrigues(result.X_EC[:3, :3] @
                                                    TRUE_X_EC[:3, :3].T)[0]))
    t_err = np.linalg.norm(result.X_EC[:3, 3] - TRUE_X_EC[:3, 3])
    # Camera noise is 0.1° and 0.5 mm per sample over 121 samples (σ of X_EC ≈ 0.05°, 0.5 mm).
    assert R_err < 0.15, R_err
    assert t_err < 0.0015, t_err
    assert R_err < 4 * np.linalg.norm(result.rotation_std_deg)
    assert t_err < 4 * np.linalg.norm(result.translation_std)


def test_storage_file_and_string_path_read_the_same(recording):
    """A rosbag2 recording reads from its directory or from its .db3/.mcap file alone (no
    metadata.yaml); a ROS 1 bag from its path as a string."""
    fmt, path = recording
    storage = path if fmt == "ros1" else \
        next(p for p in path.iterdir() if p.name != "metadata.yaml")
    a = bags.read_bag(path, camera_topic="/camera/target_pose")
    b = bags.read_bag(str(storage), camera_topic="/camera/target_pose")
    assert b.path == str(storage)
    assert np.array_equal(a.robot.poses, b.robot.poses)
    assert np.array_equal(a.camera.timestamps, b.camera.timestamps)
    assert a.topics == b.topics


def test_errors_name_the_bag_and_list_what_is_there(recording):
    _, path = recording
    with pytest.raises(ValueError, match=r"camera_topic: no topic '/camera/pose'; topics: .*"
                       r"/camera/target_pose \(geometry_msgs/msg/PoseStamped, 121 msgs\)"):
        bags.read_bag(path, camera_topic="/camera/pose")
    with pytest.raises(ValueError, match=r"robot_frames: frame 'tool1' is not in /tf or "
                       r"/tf_static; frames in /tf: \[.*wrist_3_link.*\]; in /tf_static: "
                       r"\[.*tool0.*\]"):
        bags.read_bag(path, robot_frames="base_link:tool1")
    with pytest.raises(ValueError, match=r"topic '/camera/rgb8/image_raw' has type "
                       r"sensor_msgs/msg/Image, expected geometry_msgs/msg/PoseStamped"):
        bags.read_bag(path, camera_topic="/camera/rgb8/image_raw")
    with pytest.raises(ValueError, match=r"only has static transforms"):
        bags.read_bag(path, robot_frames="world:base")
    with pytest.raises(ValueError, match="^" + re.escape(str(path)) + ": robot_frames"):
        bags.read_bag(path, robot_frames="base_link:tool1")


def _tiny_bag(path, fmt, transforms_at):
    b = _Bag(path, fmt)
    for ns, items in transforms_at:
        topic = "/tf_static" if ns is None else "/tf"
        stamp = EPOCH_NS if ns is None else ns
        b.add(topic, "tf2_msgs/msg/TFMessage", stamp,
              b.tf([b.transform(stamp, p, c, X) for p, c, X in items]))
    b.write()
    return path


def test_disconnected_trees_and_interpolation_between_publishers(tmp_path):
    """Two dynamic transforms published at different rates: the chain is sampled at the union of
    their stamps inside their common span, each interpolated (exact here: constant-rate rotation
    about a fixed axis and linear translation). Disconnected frames name both tree roots."""
    def a(t):
        return make_transform(rotation_exp([0.0, 0.0, 0.3 * t]), [0.1 * t, 0.0, 0.2])

    def b_(t):
        return make_transform(rotation_exp(np.array([1.0, 2.0, 2.0]) / 3 * (0.5 - 0.2 * t)),
                              [0.0, -0.05 * t, 0.1])

    msgs = [(None, [("base_link", "mid", _shift(0.0, 0.0, 0.5))])]
    msgs += [(_ns(k * 0.1), [("mid", "arm", a(k * 0.1))]) for k in range(0, 31)]
    msgs += [(_ns(0.05 + k * 0.25), [("arm", "tool0", b_(0.05 + k * 0.25))])
             for k in range(0, 12)]
    msgs += [(_ns(k * 0.1), [("camera", "target", _shift(0, 0, 1))]) for k in range(3)]
    path = _tiny_bag(tmp_path / "rates", "mcap", msgs)
    robot = bags.read_bag(path).robot
    expected_t = sorted({round(k * 0.1, 9) for k in range(31) if 0.05 <= k * 0.1 <= 2.8} |
                        {round(0.05 + k * 0.25, 9) for k in range(12)})
    assert robot.timestamps.tolist() == [_seconds(_ns(t)) for t in expected_t]
    truth = [_shift(0, 0, 0.5) @ a(t) @ b_(t) for t in expected_t]
    assert _max_diff(robot.poses, truth) < 1e-9
    with pytest.raises(ValueError, match=r"no transform chain from base_link to target \(they "
                       r"are in different tf trees, rooted at 'base_link' and 'camera'\)"):
        bags.read_bag(path, robot_frames="base_link:target")


def test_reparented_chain_frame_and_bad_quaternions_are_errors(tmp_path):
    msgs = [(None, [("base_link", "mid", _shift(0.0, 0.0, 0.5))])]
    msgs += [(_ns(k * 0.1), [("mid", "tool0", _shift(0.1 * k, 0, 0))]) for k in range(5)]
    msgs += [(_ns(0.5), [("base_link", "tool0", _shift(0, 0, 0))])]
    path = _tiny_bag(tmp_path / "reparent", "sqlite3", msgs)
    with pytest.raises(ValueError, match=r"/tf message 6: frame 'tool0' on the requested chain "
                       r"changes parent from 'mid' \(/tf\) to 'base_link' \(/tf\)"):
        bags.read_bag(path)
    b = _Bag(tmp_path / "zero_q.bag", "ros1")
    for k in range(3):
        msg = b.pose(_ns(k * 0.1), "camera", _shift(0, 0, 1))
        if k == 2:
            msg.pose.orientation.w = 0.0  # an uninitialized pose
        b.add("/detections", "geometry_msgs/msg/PoseStamped", _ns(k * 0.1), msg)
    b.write()
    with pytest.raises(ValueError, match=r"zero_q\.bag: /detections message 3: quaternion "
                       r"\(x y z w\) = \[0\.0, 0\.0, 0\.0, 0\.0\] has norm 0, not 1"):
        bags.read_bag(tmp_path / "zero_q.bag", robot_frames=None, camera_topic="/detections")


def test_bad_arguments(tmp_path, recording):
    _, path = recording
    with pytest.raises(ValueError, match=r"robot_frames: expected 'PARENT:CHILD', got 'tool0'"):
        bags.read_bag(path, robot_frames="tool0")
    with pytest.raises(ValueError, match=r"camera_topic, camera_frames: give one camera source"):
        bags.read_bag(path, camera_topic="/a", camera_frames="c:t")
    with pytest.raises(ValueError, match=r"max_images: expected a positive integer"):
        bags.read_bag(path, max_images=0)
    with pytest.raises(ValueError, match=r"nothing\.bag: no such file or directory"):
        bags.read_bag(tmp_path / "nothing.bag")
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"not a bag at all")
    with pytest.raises(ValueError, match=r"junk\.bag: cannot read as a ROS bag"):
        bags.read_bag(junk)


def test_camera_info_topic_is_looked_up_in_enclosing_namespaces():
    info, image = "sensor_msgs/msg/CameraInfo", "sensor_msgs/msg/Image"
    topics = {"/cam/color/camera_info": (info, 1), "/cam/depth/camera_info": (info, 1),
              "/cam/color/image_raw": (image, 1)}
    find = bags.find_camera_info
    assert find("/cam/color/image_raw/compressed", topics) == "/cam/color/camera_info"
    assert find("/cam/color/image_raw", topics) == "/cam/color/camera_info"
    assert find("/other/image", topics) is None  # two candidates, none beside it
    assert find("/other/image", {"/x/camera_info": (info, 1)}) == "/x/camera_info"

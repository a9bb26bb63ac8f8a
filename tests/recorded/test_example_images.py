"""The rendered example image set for ``calibrate --images``: reachable, diverse poses; images the
detector measures against the truth; files readable by the package's own readers; deterministic.
"""

import json
import math

import cv2
import numpy as np
import pytest

from handeye_drake.estimation.se3 import inverse, rotation_log
from handeye_drake.recorded.example_images import (
    TARGET_SPEC,
    TRUE_X_EC,
    example_intrinsics,
    generate_example_images,
    sample_robot_poses,
)
from handeye_drake.recorded.formats import read_poses
from handeye_drake.systems.arm import make_control_plant
from handeye_drake.vision.detection import detect_target
from handeye_drake.vision.intrinsics import load_intrinsics


def test_sampled_poses_are_reachable_and_rotate_about_varied_axes():
    qs, X_BEs = sample_robot_poses(seed=0, num_images=14)
    plant = make_control_plant()
    assert np.all(qs >= plant.GetPositionLowerLimits()) and np.all(
        qs <= plant.GetPositionUpperLimits())
    context = plant.CreateDefaultContext()
    for q, X_BE in zip(qs, X_BEs):   # X_BE is the forward kinematics of q
        plant.SetPositions(context, q)
        X = plant.CalcRelativeTransform(context, plant.world_frame(),
                                        plant.GetFrameByName("tool0")).GetAsMatrix4()
        assert np.abs(X - X_BE).max() < 1e-12
    motions = np.array([rotation_log(X_BEs[i][:3, :3].T @ X_BEs[i + 1][:3, :3])
                        for i in range(len(X_BEs) - 1)])
    angles = np.degrees(np.linalg.norm(motions, axis=1))
    assert np.all((angles >= 15.0) & (angles <= 40.0)), angles
    # Unit rotation axes span all three directions (measured singular values 2.43, 1.98, 1.78).
    axes = motions / np.linalg.norm(motions, axis=1, keepdims=True)
    assert np.linalg.svd(axes, compute_uv=False).min() > 1.0


def test_sample_robot_poses_rejects_bad_count():
    with pytest.raises(ValueError, match="num_images: expected an integer ≥ 1, got 0"):
        sample_robot_poses(0, 0)


def test_generated_images_match_truth_and_are_deterministic(tmp_path):
    """3 images: files, truth, detection (measured on the full 14-image set: ≤ 0.052° and
    ≤ 0.25 mm, reprojection RMS ≤ 0.065 px); a second run of 2 images gives the same bytes."""
    truth = generate_example_images(tmp_path / "a", seed=0, num_images=3)
    a = tmp_path / "a"
    assert sorted(p.name for p in a.iterdir()) == [
        "img_000.png", "img_001.png", "img_002.png", "intrinsics.yaml", "robot_poses.tum",
        "truth.json"]
    assert json.loads((a / "truth.json").read_text()) == truth
    assert truth["target"] == TARGET_SPEC and np.array_equal(truth["X_EC"], TRUE_X_EC)
    assert sum(p.stat().st_size for p in a.iterdir()) < 3 * 40_000   # ~25 kB per image

    intrinsics = load_intrinsics(a / "intrinsics.yaml")
    assert intrinsics == example_intrinsics()
    robot = read_poses(a / "robot_poses.tum", "robot")
    X_BT = np.array(truth["X_BT"])
    for k, (image, X_BE) in enumerate(zip(truth["images"], robot.poses)):
        assert np.abs(X_BE - np.array(image["X_BE"])).max() < 1e-8   # 9 decimals in the file
        X_CT = np.array(image["X_CT"])
        assert np.allclose(X_CT, inverse(np.array(image["X_BE"]) @ TRUE_X_EC) @ X_BT,
                           atol=1e-12)
        grey = cv2.imread(str(a / image["file"]), cv2.IMREAD_UNCHANGED)
        assert grey.shape == (480, 640) and grey.dtype == np.uint8
        detection = detect_target(grey, TARGET_SPEC, intrinsics)
        assert detection.found and len(detection.ids) == 24, detection.reason
        rotation_deg = math.degrees(np.linalg.norm(
            rotation_log(detection.X_CT[:3, :3] @ X_CT[:3, :3].T)))
        translation_mm = 1000 * np.linalg.norm(detection.X_CT[:3, 3] - X_CT[:3, 3])
        assert rotation_deg < 0.1 and translation_mm < 0.4, (k, rotation_deg, translation_mm)
        assert detection.reprojection_rms_px < 0.1

    generate_example_images(tmp_path / "b", seed=0, num_images=2)
    for name in ("img_000.png", "img_001.png", "intrinsics.yaml"):
        assert (tmp_path / "b" / name).read_bytes() == (a / name).read_bytes(), name
    assert (tmp_path / "b" / "robot_poses.tum").read_text().splitlines() == \
        (a / "robot_poses.tum").read_text().splitlines()[:4]

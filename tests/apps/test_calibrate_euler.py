"""A robot file of Euler angles read with the wrong convention (``--robot-format``) is named —
by the verdict when a calibration comes out, by the error when none does — never turned into an
answer."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handeye_drake.apps.cli import main
from handeye_drake.recorded.formats import read_poses

from .test_calibrate import CAMERA, IMAGES, ROBOT

TARGET = "charuco:7x5:0.04:0.03:DICT_5X5_100"


def _kuka(src, dst, stamped=True):
    """``src`` (TUM) written as a KUKA file: [t] X Y Z (mm) A B C (deg, intrinsic Z-Y'-X'')."""
    r = read_poses(src, "robot")
    R = Rotation.from_matrix(r.poses[:, :3, :3])
    abc = R.as_euler("ZYX", degrees=True)
    rows = [([r.timestamps[k]] if stamped else []) + [*(1000 * r.poses[k, :3, 3]), *abc[k]]
            for k in range(len(r))]
    dst.write_text("\n".join(" ".join(f"{v:.7f}" for v in row) for row in rows) + "\n")
    return str(dst)


def test_pose_files_with_the_wrong_order_name_the_right_one(tmp_path, capsys):
    kuka = _kuka(ROBOT, tmp_path / "kuka.csv")
    code = main(["calibrate", "--robot", kuka, "--camera", CAMERA, "--robot-format",
                 "csv-euler:xyz:deg", "--robot-translation-scale", "0.001",
                 "--out", str(tmp_path / "wrong")])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "likely cause: the robot file's Euler angles are ZYX:deg, not xyz:deg" in err
    assert "--robot-format csv-euler:ZYX:deg" in err and "Traceback" not in err


@pytest.mark.parametrize("fmt, ok", [("csv-euler:ZYX:deg", True), ("csv-euler:zyx:deg", False)])
def test_images_with_the_wrong_convention_fail_naming_it(tmp_path, fmt, ok):
    kuka = _kuka(IMAGES / "robot_poses.tum", tmp_path / "kuka.csv", stamped=False)
    out = tmp_path / "out"
    code = main(["calibrate", "--images", str(IMAGES), "--robot", kuka, "--robot-format", fmt,
                 "--robot-translation-scale", "0.001", "--target", TARGET, "--intrinsics",
                 str(IMAGES / "intrinsics.yaml"), "--out", str(out)])
    doc = json.loads((out / "calibration.json").read_text())
    codes = [r["code"] for r in doc["verdict"]["reasons"]]
    if ok:
        assert code == 0 and doc["verdict"]["status"] == "OK" and codes == []
        truth = np.array(json.loads((IMAGES / "truth.json").read_text())["X_EC"])
        assert np.linalg.norm(np.array(doc["X_EC"]["matrix"])[:3, 3] - truth[:3, 3]) < 1e-3
    else:
        assert code == 1 and doc["verdict"]["status"] == "FAIL"
        assert "robot_euler_convention" in codes
        reason = next(r for r in doc["verdict"]["reasons"]
                      if r["code"] == "robot_euler_convention")
        assert reason["message"].endswith("--robot-format csv-euler:ZYX:deg")
        assert "--robot-format csv-euler:ZYX:deg" in (out / "report.html").read_text()
    # The conventions tried are listed with the other alternatives.
    assert any(a["code"] == "robot_euler_convention" for a in doc["alternatives_tried"])

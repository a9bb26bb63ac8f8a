"""``report.html`` of ``calibrate``: written on every verdict, self-contained (no network, no
script), the image panels worst first with the corners predicted through the calibrated chain,
pose residual plots for pose files, eye-to-hand too."""

import base64
import json
import re

import numpy as np
import pytest

from handeye_drake.apps.calibrate.report_html import (image_residuals, magnification,
                                                      off_the_chain)
from handeye_drake.apps.cli import main
from handeye_drake.estimation.reprojection import predict

from . import eye_to_hand_images
from .test_calibrate import CAMERA, IMAGES, ROBOT

TARGET = "charuco:7x5:0.04:0.03:DICT_5X5_100"


def _calibrate(out, *args):
    code = main(["calibrate", *map(str, args), "--out", str(out)])
    return code, (out / "report.html").read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def images_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("images") / "out"
    code, text = _calibrate(out, "--images", IMAGES, "--robot", IMAGES / "robot_poses.tum",
                            "--target", TARGET, "--intrinsics", IMAGES / "intrinsics.yaml")
    return code, text, out


def _data_uris(text, mime):
    return re.findall(rf'data:{re.escape(mime)};base64,([A-Za-z0-9+/=]+)', text)


def assert_self_contained(text):
    """No script, no stylesheet or resource loaded from anywhere: every src/href is a data URI
    or an in-page anchor."""
    assert "<script" not in text.lower() and "<link" not in text.lower()
    refs = re.findall(r'(?:src|href)="([^"]*)"', text)
    assert refs and all(r.startswith(("data:", "#")) for r in refs), \
        [r for r in refs if not r.startswith(("data:", "#"))][:3]
    assert "url(" not in text and "@import" not in text
    assert "could not be drawn" not in text


def test_images_report_is_self_contained_with_every_image_worst_first(images_report):
    code, text, out = images_report
    assert code == 0 and "verdict: OK" in text
    assert_self_contained(text)
    # Listed in the manifest: a later run into the same --out replaces it.
    manifest = json.loads((out / ".handeye-drake-output.json").read_text())
    assert "report.html" in json.dumps(manifest)
    # The verdict comes before the result, the result before the images.
    assert text.index("verdict: OK") < text.index("X_EC: camera C in the end-effector") \
        < text.index('id="images"')
    # One panel per image, each reachable from the index, ranked by decreasing RMS.
    panels = re.findall(r'<div class="panel" id="(img-\d+)">', text)
    assert len(panels) == 14 and len(set(panels)) == 14
    links = re.findall(r'<a href="#(img-\d+)">', text)
    assert set(links) == set(panels)
    index = text[text.index("<h3>Index</h3>"):text.index('<div class="panels">')]
    rms = [float(v) for v in re.findall(r'</a></td><td class="n">([0-9.]+)</td>', index)]
    assert len(rms) == 14 and rms == sorted(rms, reverse=True) and rms[0] < 0.2
    # The images are embedded as JPEG no wider than 640 px.
    import cv2
    jpegs = _data_uris(text, "image/jpeg")
    assert len(jpegs) == 14
    first = cv2.imdecode(np.frombuffer(base64.b64decode(jpegs[0]), np.uint8), cv2.IMREAD_COLOR)
    assert first is not None and first.shape[1] <= 640
    # The task-space σ and the observability summary are shown.
    doc = json.loads((out / "calibration.json").read_text())
    ts = doc["task_space_sigma"]
    assert f"{1000 * ts['point_in_front_m']:.3f} mm" in text
    assert "Observability: observable" in text and "Alternatives tried" in text
    assert len(text.encode()) < 3_000_000


def test_residual_plots_number_images_from_0_as_the_files(images_report):
    _, text, _ = images_report
    svgs = [base64.b64decode(v).decode() for v in _data_uris(text, "image/svg+xml")]
    norms = next(s for s in svgs if "Pose residual per sample" in s)
    assert "image number (from 0, as the files)" in norms


def test_predicted_corners_are_the_calibrated_chain(tmp_path):
    """The panels' predictions are ``reprojection.predict`` of the answer (X_H⁻¹ X_R⁻¹ X_F,
    the answer's intrinsics), and their residuals are what the fit explains with its per-image
    pose error: the chain alone leaves at most a little more."""
    from handeye_drake.calibration.corners import calibrate_images
    from handeye_drake.calibration.inputs import image_streams
    streams = image_streams(str(IMAGES), str(IMAGES / "robot_poses.tum"), TARGET,
                            str(IMAGES / "intrinsics.yaml"))
    result = calibrate_images(streams, {"mode": "eye_in_hand"})
    samples = image_residuals(result, streams)
    fit = result.corners.fit
    X_R = np.asarray(result.aligned.X_BE)
    assert len(samples) == 14
    for s in samples:
        det = streams.detections[int(result.aligned.camera_index[s["sample"]])]
        np.testing.assert_allclose(s["predicted"],
                                   predict(fit, X_R[s["sample"]], det.object_points), atol=1e-9)
        np.testing.assert_allclose(s["residuals"], det.image_points - s["predicted"])
        assert s["fit_rms_px"] <= s["rms_px"] * 1.05 and s["rms_px"] < 0.2
    # One magnification for all panels: the typical residual drawn 10-25 px long.
    m = magnification(samples)
    p75 = np.percentile(np.concatenate([np.linalg.norm(s["residuals"], axis=1)
                                        for s in samples]), 75)
    assert 10 <= m * p75 <= 25
    assert not off_the_chain(samples)


def test_an_image_whose_robot_pose_is_off_is_flagged_first(tmp_path):
    """One robot pose 10 mm off: the corner-level fit may absorb it in that image's pose
    error, but the chain's prediction does not — the report ranks it first and says so."""
    lines = (IMAGES / "robot_poses.tum").read_text().splitlines()
    data = [k for k, line in enumerate(lines) if line.strip() and not line.startswith("#")]
    row = lines[data[5]].split()
    row[1] = f"{float(row[1]) + 0.010:.9f}"
    lines[data[5]] = " ".join(row)
    robot = tmp_path / "robot.tum"
    robot.write_text("\n".join(lines) + "\n")
    _, text = _calibrate(tmp_path / "out", "--images", IMAGES, "--robot", robot, "--target",
                         TARGET, "--intrinsics", IMAGES / "intrinsics.yaml")
    index = text[text.index("<h3>Index</h3>"):text.index('<div class="panels">')]
    first = re.search(r'<a href="#img-\d+">([^<]+)</a></td><td class="n">([0-9.]+)</td>', index)
    assert first.group(1) == "img_005.png" and float(first.group(2)) > 5
    assert "1 image far off the calibrated chain (img_005.png)" in text
    assert index.count("far off the calibrated chain") == 1
    assert "residuals × " in text[text.index('id="img-5"'):][:200000].split("</div></div>")[0]


def test_a_failed_calibration_still_writes_its_report(tmp_path):
    # The board 11 % larger than printed: the verdict FAILs and names the size.
    code, text = _calibrate(tmp_path / "out", "--images", IMAGES,
                            "--robot", IMAGES / "robot_poses.tum", "--target",
                            "charuco:7x5:0.0444:0.0333:DICT_5X5_100",
                            "--intrinsics", IMAGES / "intrinsics.yaml")
    assert code == 1
    assert "verdict: FAIL" in text and "the target&#x27;s declared size is wrong" in text
    assert text.index("verdict: FAIL") < text.index("Result: X_EC")
    # The refused transform does not look like an answer: a banner, struck through, hatched.
    result = text[text.index('id="result"'):text.index('id="images"')]
    assert "REFUSED — verdict FAIL: this is not a calibration" in result
    assert '<div class="cards refused">' in result and "— refused</h3>" in result
    assert_self_contained(text)
    assert len(re.findall(r'<div class="panel" id="img-\d+">', text)) == 14


def test_pose_files_get_pose_residual_plots_with_the_outliers_marked(tmp_path):
    code, text = _calibrate(tmp_path / "out", "--robot", ROBOT, "--camera", CAMERA)
    assert code == 0 and "verdict: OK" in text
    assert_self_contained(text)
    assert 'id="pose-residuals"' in text and 'class="panel"' not in text
    svgs = [base64.b64decode(v).decode() for v in _data_uris(text, "image/svg+xml")]
    components = next(s for s in svgs if "rotation about C x (deg)" in s)
    norms = next(s for s in svgs if "Pose residual per sample" in s)
    # The shipped recording has two wrong camera poses: both plots mark outliers.
    assert "outlier" in components and "outlier" in norms and "held out" in norms
    # An answer is not marked refused; a log axis reads in plain numbers (mm), not 10^x.
    assert "REFUSED" not in text and "cards refused" not in text
    assert "translation (mm)" in norms and "10^{" not in norms
    assert len(_data_uris(text, "image/png")) == 1  # the 3D picture


def test_eye_to_hand_images_report(tmp_path):
    truth = eye_to_hand_images.write_set(tmp_path / "set", n=10)
    code, text = _calibrate(tmp_path / "out", "--images", tmp_path / "set", "--robot",
                            tmp_path / "set" / "robot_poses.tum", "--target", truth["target"],
                            "--intrinsics", truth["intrinsics"], "--mode", "eye-to-hand")
    assert code == 0, text[:2000]
    assert "X_BC: camera C in the robot base frame B" in text and "X_ET: target T on the" in text
    doc = json.loads((tmp_path / "out" / "calibration.json").read_text())
    X = np.array(doc["X_BC"]["matrix"])
    assert np.linalg.norm(X[:3, 3] - truth["X_BC"][:3, 3]) < 3 * np.linalg.norm(
        doc["X_BC"]["std"]["translation_m"])
    assert len(re.findall(r'<div class="panel" id="img-\d+">', text)) == 10
    assert_self_contained(text)


def test_an_alternative_that_was_not_fitted_shows_no_residuals():
    """The camera-scale reading is not fitted when the best scale is the one given: its row
    names the reading and says why, with "–" for its residuals (not ∞, an infinitely bad fit)."""
    import math
    from types import SimpleNamespace

    from handeye_drake.apps.calibrate.report_html import _alternatives_html
    from handeye_drake.calibration.checks import Hypothesis
    hyps = [Hypothesis("as_read", "the data as read", "", 0.03, 8e-5, 0.09),
            Hypothesis("robot_millimetres", "the robot file's translations are in millimetres",
                       "--robot-translation-scale 0.001", 0.03, 0.04, 0.5),
            Hypothesis("camera_scale", "", "", math.inf, math.inf, math.inf,
                       error="the best camera translation scale is 0.9997: as given")]
    result = SimpleNamespace(hypotheses=hyps, settings={"max_noise": (1.0, 0.01),
                                                        "max_hand_eye_distance_m": 0.5})
    rows = re.findall(r"<tr><td>.*?</tr>", _alternatives_html(result))
    assert len(rows) == 3 and "∞" not in "".join(rows)
    # No empty column: each row says whether it explains the data better than as read.
    assert "<th>better than as read?</th>" in _alternatives_html(result)
    assert all("<td></td>" not in r for r in rows)
    assert "<td>the reference</td>" in rows[0] and "<td>no</td>" in rows[1]
    assert "the camera&#x27;s translations at another scale" in rows[2]
    assert "not fitted: the best camera translation scale is 0.9997: as given" in rows[2]
    assert rows[2].count('<td class="n">–</td>') == 3
    assert '<td class="n">40</td>' in rows[1]                     # 0.04 m in mm

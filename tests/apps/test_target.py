"""``handeye-drake target``: the printable target, and its refusals."""

import cv2
import numpy as np

from handeye_drake.apps.cli import main
from handeye_drake.vision.detection import detect_target
from handeye_drake.vision.intrinsics import parse_intrinsics_spec
from handeye_drake.vision.targets import parse_target


def test_the_printed_chessboard_is_detected_at_its_true_scale(tmp_path, capsys):
    out_dir = tmp_path / "board"
    assert main(["target", "chessboard:9x6:0.0236", "--out", str(out_dir), "--dpi", "200"]) == 0
    png = out_dir / "target.png"
    out = capsys.readouterr().out
    assert "square 23.6 mm" in out and "origin at the first inner corner" in out
    assert "page: 256 × 193 mm (fits A4)" in out  # 10 × 7 squares of 23.6 mm, 10 mm margins, a caption
    assert png.with_suffix(".svg").exists() and png.with_suffix(".pdf").exists()
    image = cv2.imread(str(png), cv2.IMREAD_GRAYSCALE)
    # Seen by a fronto-parallel camera 1 m away with f = ppm pixels, one metre on the paper is
    # ppm pixels: the detected pose puts the board 1 m away, its corners 23.6 mm apart.
    ppm = 200 / 0.0254
    h, w = image.shape
    K = parse_intrinsics_spec(f"{ppm},{ppm},{(w - 1) / 2},{(h - 1) / 2}", w, h)
    det = detect_target(image, parse_target("chessboard:9x6:0.0236"), K)
    assert det.found and len(det.ids) == 54
    assert abs(det.X_CT[2, 3] - 1.0) < 2e-3
    assert np.allclose(det.X_CT[:3, 2], [0, 0, 1], atol=1e-3)  # z into the board


def test_refusals_are_one_line(tmp_path, capsys):
    out = tmp_path / "b"
    assert main(["target", "apriltag:36h11:0.048:10", "--out", str(out)]) == 0
    # The same command again reuses its own output folder (its manifest), like every command.
    assert main(["target", "apriltag:36h11:0.048:10", "--out", str(out)]) == 0
    other = tmp_path / "someone_elses"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    capsys.readouterr()
    for argv, message in (
            (["apriltag:36h11:0.048:10", "--out", str(other)], "the directory is not empty"),
            (["chessboard:9", "--out", str(tmp_path / "c")], "target spec 'chessboard:9'"),
            (["chessboard:9x6:0.02", "--out", str(tmp_path / "c.png")], "a folder, like every"),
            (["chessboard:9x6:0.02", "--out", str(tmp_path / "c"), "--dpi", "-3"],
             "--dpi: expected a positive number")):
        assert main(["target", *argv]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err, err
    # --force writes beside the other files and never touches them.
    assert main(["target", "apriltag:36h11:0.048:10", "--out", str(other), "--force"]) == 0
    assert (other / "notes.txt").read_text() == "mine" and (other / "target.pdf").exists()
    assert not (tmp_path / "c").exists()


def test_a_spec_in_millimetres_is_refused_not_drawn(tmp_path, capsys):
    # charuco:7x5:40:30 once proposed a 3307323×2362441 image
    out = tmp_path / "t"
    assert main(["target", "charuco:7x5:40:30:DICT_5X5_100", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and not out.exists()
    assert ("the sizes look like millimetres (the pattern would be 280 m × 200 m); sizes are in "
            "metres: charuco:7x5:0.04:0.03:DICT_5X5_100") in err


def test_calibrate_with_a_target_in_millimetres_names_the_units(tmp_path, capsys):
    from handeye_drake.recorded.example import data_dir
    images = data_dir() / "example_images"
    code = main(["calibrate", "--images", str(images), "--robot", str(images / "robot_poses.tum"),
                 "--target", "charuco:7x5:40:30:DICT_5X5_100", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "translation-scale" not in err
    assert "sizes are in metres: charuco:7x5:0.04:0.03:DICT_5X5_100" in err

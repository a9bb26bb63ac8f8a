"""``--images`` (issue 21): names that are not regular files (a FIFO, a symbolic link loop) are
skipped with the reason without being opened, so the pairing with the robot poses is kept and
nothing blocks; several arguments keep their own order (each one's files naturally sorted, the
arguments in the order given) and the printout says how the images were paired."""

import json
import os
import shutil
import threading

import numpy as np
import pytest

from handeye_drake import rotation_error_deg
from handeye_drake.apps.cli import main
from handeye_drake.calibration.inputs import image_paths
from handeye_drake.recorded.example import data_dir

IMAGES = data_dir() / "example_images"
TRUTH = json.loads((IMAGES / "truth.json").read_text())
NAMES = sorted(p.name for p in IMAGES.glob("img_*.png"))


def _run_with_deadline(argv, seconds=120):
    """main(argv) in a thread; fails (instead of hanging the suite) past ``seconds``."""
    box = {}
    thread = threading.Thread(target=lambda: box.setdefault("code", main(argv)), daemon=True)
    thread.start()
    thread.join(seconds)
    assert not thread.is_alive(), f"calibrate still running after {seconds} s: it blocked"
    return box["code"]


def _copy(folder, names, rename=None):
    folder.mkdir()
    for k, name in enumerate(names):
        shutil.copy(IMAGES / name, folder / (rename(k) if rename else name))
    return folder


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fifo_and_symlink_loop_named_like_images_are_skipped_unopened(tmp_path, capsys, seed):
    rng = np.random.default_rng(seed)
    fifo_at, loop_at = rng.choice(len(NAMES), 2, replace=False)
    folder = _copy(tmp_path / "images", NAMES)
    (folder / NAMES[fifo_at]).unlink()
    os.mkfifo(folder / NAMES[fifo_at])
    (folder / NAMES[loop_at]).unlink()
    os.symlink(NAMES[loop_at], folder / NAMES[loop_at])          # points at itself
    out = tmp_path / "out"
    code = _run_with_deadline(["calibrate", "--images", str(folder), "--robot",
                               str(IMAGES / "robot_poses.tum"), "--target", TRUTH["target"],
                               "--intrinsics", str(IMAGES / "intrinsics.yaml"),
                               "--out", str(out)])
    printed = capsys.readouterr()
    assert "Traceback" not in printed.err and code == 0, printed.err
    per_image = {_name(r["path"]): r
                 for r in json.loads((out / "calibration.json").read_text())["inputs"]["images"]
                 ["per_image"]}
    assert per_image[NAMES[fifo_at]]["reason"] == "a FIFO, not a regular file: not opened"
    assert per_image[NAMES[loop_at]]["reason"] == ("a symbolic link loop, not a regular file: "
                                                   "not opened")
    assert sum(r["found"] for r in per_image.values()) == len(NAMES) - 2
    assert f"{NAMES[fifo_at]}" in printed.out and "a FIFO" in printed.out


def _name(path: str) -> str:
    return path.rsplit("/", 1)[-1]


def test_a_count_mismatch_names_the_files_that_are_not_regular(tmp_path, capsys):
    folder = _copy(tmp_path / "images", NAMES)
    os.symlink("img_loop.png", folder / "img_loop.png")
    code = main(["calibrate", "--images", str(folder), "--robot", str(IMAGES / "robot_poses.tum"),
                 "--target", TRUTH["target"], "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert (f"--images, --robot: {len(NAMES) + 1} images (1 of them not regular files: "
            "img_loop.png (a symbolic link loop)) but 14 robot poses") in err


def test_each_argument_keeps_its_order(tmp_path):
    a = tmp_path / "a"
    b = tmp_path / "b"
    for folder in (a, b):
        folder.mkdir()
        for name in ("img10.png", "img2.png", "img1.png"):
            (folder / name).write_bytes(b"")
    listed = image_paths([str(b), str(a), str(b / "img1.png"), str(a / "img*.png")])
    assert [str(p.relative_to(tmp_path)) for p in listed] == [
        "b/img1.png", "b/img2.png", "b/img10.png", "a/img1.png", "a/img2.png", "a/img10.png"]


def test_two_directories_with_the_same_names_pair_in_argument_order(tmp_path, capsys):
    # dirA holds the first 7 images, dirB the last 7, both named img_000 … img_006: sorted
    # across both, the pairing interleaves and the fit fails
    half = len(NAMES) // 2
    first = _copy(tmp_path / "dirA", NAMES[:half], lambda k: f"img_{k:03d}.png")
    second = _copy(tmp_path / "dirB", NAMES[half:], lambda k: f"img_{k:03d}.png")
    out = tmp_path / "out"
    code = main(["calibrate", "--images", str(first), str(second), "--robot",
                 str(IMAGES / "robot_poses.tum"), "--target", TRUTH["target"], "--intrinsics",
                 str(IMAGES / "intrinsics.yaml"), "--out", str(out)])
    printed = capsys.readouterr().out
    assert code == 0, printed
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["verdict"]["status"] == "OK"
    X = np.array(doc["X_EC"]["matrix"])
    X_true = np.array(TRUTH["X_EC"])
    assert rotation_error_deg(X, X_true) < 0.1
    assert np.linalg.norm(X[:3, 3] - X_true[:3, 3]) < 1e-3
    pairing = (f"images paired with the robot poses in order: {first} ({half}), then {second} "
               f"({len(NAMES) - half})")
    assert pairing in printed and doc["inputs"]["images"]["pairing"].startswith(pairing)

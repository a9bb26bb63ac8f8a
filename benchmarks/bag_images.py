"""Hand-eye calibration from the images of a ROS bag: accuracy per format and time per image.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bag_images.py [--repeat 20] [--out DIR]

For each storage (ROS 1 .bag, ROS 2 sqlite3, ROS 2 MCAP) the example bag of the shipped images is
written (``recorded.example_bag``: 14 rendered 640×480 images of a ChArUco board, the robot
sweeping through their poses without stopping, tf at 100 Hz, camera stamps 35 ms late) and
``handeye-drake calibrate --bag … --image-topic … --target …`` is run in-process on its
``sensor_msgs/Image`` topic and on its ``CompressedImage`` topic. Printed per run: the errors of
X_EC against the truth and the result's σ (rotation in degrees, translation in mm; norms of the
per-axis values), the estimated clock offset, the verdict, and the wall time per image of the
whole command.

Time per image, on a larger bag (the 14 images swept ``--repeat`` times, mono8 Image topic,
MCAP): ``bag_image_streams`` (read, decode, detect, no drawing), with drawings, and as the
reference measured in the same run on the same bag, reading and decoding alone
(``recorded.bags.iter_images``); and the peak of traced Python memory against the bag's image
bytes (the images are streamed, never all held) and against reading the robot's tf alone.
"""
import argparse
import contextlib
import io
import json
import shutil
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

from handeye_drake import rotation_error_deg
from handeye_drake.calibration import bag_image_streams
from handeye_drake.apps.cli import main
from handeye_drake.apps.outputs import prepare_output_dir
from handeye_drake.recorded.bags import iter_images, read_bag
from handeye_drake.recorded.example_bag import COMPRESSED_TOPIC, IMAGE_TOPIC, write_example_bag

FORMATS = {"ros1": dict(encoding="rgb8", row_padding=8, compression="png"),
           "sqlite3": dict(encoding="bgra8", compression="jpeg", jpeg_quality=80),
           "mcap": dict(encoding="mono16", compression="png")}


def _bag(root: Path, storage: str) -> Path:
    return root / ("cell.bag" if storage == "ros1" else f"cell_{storage}")


def accuracy(root: Path) -> None:
    print("storage  topic (encoding)                           rot err (deg)  σ (deg)  "
          "trans err (mm)  σ (mm)  offset (s)  verdict  ms/image")
    for storage, options in FORMATS.items():
        path = _bag(root, storage)
        truth = write_example_bag(path, storage, **options)
        X_EC = np.array(truth["X_EC"])
        for topic, kind in ((IMAGE_TOPIC, options["encoding"]),
                            (COMPRESSED_TOPIC, options["compression"])):
            out = root / f"out_{storage}_{kind}"
            t = time.perf_counter()
            code = _quiet(path, topic, truth["target"], out)
            wall = time.perf_counter() - t
            doc = json.loads((out / "calibration.json").read_text())
            X = np.array(doc["X_EC"]["matrix"])
            std = doc["X_EC"]["std"]
            print(f"{storage:<8} {topic + ' (' + kind + ')':<42} "
                  f"{rotation_error_deg(X_EC, X):13.4f} "
                  f"{np.linalg.norm(std['rotation_deg']):8.4f} "
                  f"{1000 * np.linalg.norm(X[:3, 3] - X_EC[:3, 3]):15.3f} "
                  f"{1000 * np.linalg.norm(std['translation_m']):7.3f} "
                  f"{doc['time_offset']['value_s']:11.5f}  {doc['verdict']['status']:<7} "
                  f"{1000 * wall / len(doc['inputs']['images']['per_image']):8.1f}"
                  + ("" if code == 0 else f"  (exit {code})"))


def _quiet(path, topic, target, out) -> int:
    """The command, its printout discarded."""
    with contextlib.redirect_stdout(io.StringIO()):
        return main(["calibrate", "--bag", str(path), "--robot-frames", "base_link:tool0",
                     "--image-topic", topic, "--target", target, "--out", str(out)])


def throughput(root: Path, repeat: int) -> None:
    path = root / "sweep"
    t = time.perf_counter()
    truth = write_example_bag(path, "mcap", encoding="mono8", repeat=repeat)
    n = len(truth["images"])
    print(f"\nlarger bag: {n} mono8 640×480 images (MCAP, {_size(path) / 1e6:.1f} MB, written "
          f"in {time.perf_counter() - t:.1f} s)")
    t = time.perf_counter()
    for _ in iter_images(path, IMAGE_TOPIC):
        pass
    decode = (time.perf_counter() - t) / n
    t = time.perf_counter()
    streams = bag_image_streams(path, "base_link:tool0", IMAGE_TOPIC, truth["target"],
                                max_images=None)
    detect = (time.perf_counter() - t) / n
    out = prepare_output_dir(root / "out_sweep", "calibrate")
    t = time.perf_counter()
    bag_image_streams(path, "base_link:tool0", IMAGE_TOPIC, truth["target"], max_images=None,
                      drawings_dir=out)
    drawn = (time.perf_counter() - t) / n
    found = sum(r.found for r in streams.images)
    print(f"  read + decode (reference, iter_images):  {1000 * decode:6.2f} ms/image")
    print(f"  bag_image_streams (+ tf, detection):     {1000 * detect:6.2f} ms/image "
          f"({detect / decode:.1f}× the reference); target found in {found} of {n}")
    print(f"  with a drawing per image:                {1000 * drawn:6.2f} ms/image "
          f"({drawn / decode:.1f}× the reference)")
    tracemalloc.start()
    robot = read_bag(path, "base_link:tool0").robot
    tf_peak = tracemalloc.get_traced_memory()[1]
    del robot
    tracemalloc.reset_peak()
    bag_image_streams(path, "base_link:tool0", IMAGE_TOPIC, truth["target"], max_images=None)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    print(f"  peak traced memory: {peak / 1e6:.1f} MB for {n * 640 * 480 / 1e6:.1f} MB of "
          f"decoded images; reading the robot's tf alone (read_bag): {tf_peak / 1e6:.1f} MB")


def _size(path: Path) -> int:
    return sum(p.stat().st_size for p in Path(path).rglob("*") if p.is_file()) \
        if Path(path).is_dir() else Path(path).stat().st_size


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=20,
                        help="sweeps of the larger bag (14 images each; default 20)")
    parser.add_argument("--out", default=None, help="keep the bags here (default: a temporary "
                        "directory, removed)")
    a = parser.parse_args()
    root = Path(a.out) if a.out else Path(tempfile.mkdtemp(prefix="bag_images_"))
    root.mkdir(parents=True, exist_ok=True)
    try:
        accuracy(root)
        throughput(root, a.repeat)
    finally:
        if not a.out:
            shutil.rmtree(root)

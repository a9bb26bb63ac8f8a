"""Time per frame of the rendered camera and of the target detector (640×480).

    python benchmarks/rendered_camera_speed.py [--frames N]

A UR5e with a camera on its flange looks at a board on the table (chessboard 9x6 of 30 mm, then
ChArUco 7x5 of 40 mm); each frame moves the wrist a little (so SceneGraph's poses change and the
sensor renders anew), renders through Drake's RgbdSensor (RenderEngineVtk, EGL) with 1, 2 and
3 × 3 supersampling, and runs ``detect_target`` on the image. Prints the median milliseconds of
rendering (including the copy out of Drake and the area downsampling) and of detection, and the
ratio of their sum to a 30 Hz camera period (> 1: the rendered loop runs slower than real time
from the camera alone). The first frame of each camera (EGL/VTK set-up) is not counted.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pydrake.systems.framework import DiagramBuilder  # noqa: E402

from handeye_drake.estimation.se3 import inverse, make_transform, rotation_exp  # noqa: E402
from handeye_drake.systems.arm import UR5E_HOME_Q, add_arm  # noqa: E402
from handeye_drake.systems.rendered_camera import (  # noqa: E402
    add_target_geometry,
    mount_rendered_camera,
)
from handeye_drake.vision.camera_model import CameraIntrinsics  # noqa: E402
from handeye_drake.vision.detection import detect_target  # noqa: E402
from handeye_drake.vision.targets import parse_target, pattern_extent  # noqa: E402

INTRINSICS = CameraIntrinsics(alpha_u=600.0, alpha_v=600.0, u0=319.5, v0=239.5, width=640,
                              height=480)
X_EC = make_transform(rotation_exp(np.radians([2.0, -3.0, 90.0])), [0.045, -0.012, 0.068])
CAMERA_PERIOD = 1.0 / 30.0


def measure(target_spec: str, supersample: int, frames: int) -> tuple[list, list, int]:
    target = parse_target(target_spec)
    builder = DiagramBuilder()
    arm = add_arm(builder)
    plant = arm.plant
    context0 = plant.CreateDefaultContext()
    X_WE = plant.CalcRelativeTransform(context0, plant.world_frame(),
                                       plant.GetFrameByName("tool0")).GetAsMatrix4()
    # Board 0.45 m along the optical axis, seen 20° off its normal.
    x0, y0, x1, y1 = pattern_extent(target)
    R_TC = rotation_exp([0.3, -0.2, 0.4])
    X_TC = make_transform(R_TC, np.array([0.5 * (x0 + x1), 0.5 * (y0 + y1), 0]) - 0.45 * R_TC[:, 2])
    add_target_geometry(arm.scene_graph, target, X_WE @ X_EC @ inverse(X_TC))
    camera = mount_rendered_camera(builder, arm.scene_graph, plant, "tool0", X_EC, INTRINSICS,
                                   supersample=supersample)
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    render_ms, detect_ms, found = [], [], 0
    for k in range(frames + 1):
        q = UR5E_HOME_Q + np.array([0, 0, 0, 0.002 * k, -0.002 * k, 0.003 * k])
        plant.SetPositions(plant_context, arm.model_instance, q)
        t0 = time.perf_counter()
        image = camera.EvalColorImage(context)
        t1 = time.perf_counter()
        detection = detect_target(image, target, INTRINSICS)
        t2 = time.perf_counter()
        if k > 0:
            render_ms.append(1000 * (t1 - t0))
            detect_ms.append(1000 * (t2 - t1))
            found += detection.found
    return render_ms, detect_ms, found


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=20)
    args = parser.parse_args()
    print(f"{args.frames} frames per row, 640×480, medians; camera period "
          f"{1000 * CAMERA_PERIOD:.1f} ms")
    print(f"{'target':<12} {'supersample':>11} {'render ms':>10} {'detect ms':>10} "
          f"{'(render+detect)/period':>23} {'found':>6}")
    for spec, name in (("chessboard:9x6:0.03", "chessboard"),
                       ("charuco:7x5:0.04:0.03:DICT_5X5_100", "charuco")):
        for k in (1, 2, 3):
            render_ms, detect_ms, found = measure(spec, k, args.frames)
            r, d = statistics.median(render_ms), statistics.median(detect_ms)
            print(f"{name:<12} {k:>11} {r:>10.1f} {d:>10.1f} "
                  f"{(r + d) / (1000 * CAMERA_PERIOD):>23.2f} {found:>3}/{args.frames}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

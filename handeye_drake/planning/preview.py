"""Previews of a planned tour: a Meshcat animation saved as one self-contained HTML file (opens
offline in a browser: ``Meshcat.StaticHtml``), and a PNG picture (matplotlib) of the arm's
link origins at every pose with the camera's optical axis, the target and the cell.

Frames: everything is drawn in the robot base B (m)."""

from __future__ import annotations

import numpy as np


def _link_points(planner, q) -> np.ndarray:
    """(K, 3) origins of the arm's bodies in B at q, base to flange."""
    planner.set_q(q)
    plant, ctx = planner.plant, planner.plant_context
    pts = []
    for b in plant.GetBodyIndices(planner.ee_frame.body().model_instance()):
        body = plant.get_body(b)
        pts.append(plant.EvalBodyPoseInWorld(ctx, body).translation())
    X = plant.CalcRelativeTransform(ctx, plant.world_frame(), planner.ee_frame).translation()
    pts.append(X)
    return np.array(pts)


def write_picture(planner, tour, path) -> None:
    """PNG: the arm (link origins joined) at each pose of ``tour`` (numbered in the visiting order),
    its optical axis as far as the target, the flange's path, the target points."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=(7, 6))
    ax = fig.add_subplot(projection="3d")
    colors = plt.cm.viridis(np.linspace(0, 1, max(len(tour.waypoints), 2)))
    for k, q in enumerate(tour.waypoints):
        p = _link_points(planner, q)
        ax.plot(p[:, 0], p[:, 1], p[:, 2], "-o", color=colors[k], ms=2, lw=1.5,
                alpha=0.4 if k == 0 else 0.9)
        X_BC, X_BT = planner.camera_target(q)
        a = X_BC[:3, 3]
        # The optical axis, drawn as far as the target centre's depth.
        c = X_BT[:3, :3] @ planner.view.center + X_BT[:3, 3]
        b = a + max(float((c - a) @ X_BC[:3, 2]), 0.05) * X_BC[:3, 2]
        ax.plot([a[0], b[0]], [a[1], b[1]], [a[2], b[2]], color="crimson", lw=1)
        if k:
            ax.text(*p[-1], str(k), fontsize=8)
    # The path of the flange along the trajectory.
    ts = np.linspace(0, tour.trajectory.end_time(), 200)
    flange = np.array([_link_points(planner, tour.trajectory.value(t).ravel())[-1] for t in ts])
    ax.plot(flange[:, 0], flange[:, 1], flange[:, 2], ":", color="grey", lw=1)
    X_BT = planner.camera_target(tour.waypoints[-1])[1]
    P = (X_BT[:3, :3] @ planner.view.points.T).T + X_BT[:3, 3]
    ax.scatter(P[:, 0], P[:, 1], P[:, 2], color="black", marker="s", s=12, label="target")
    ax.set_xlabel("x_B (m)")
    ax.set_ylabel("y_B (m)")
    ax.set_zlabel("z_B (m)")
    ax.set_title(f"planned tour: {len(tour.order)} poses, {tour.duration_s:.0f} s, "
                 f"clearance ≥ {1000 * tour.min_distance_m:.0f} mm")
    pts = np.vstack([_link_points(planner, q) for q in tour.waypoints] + [P])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    half = 0.5 * float(np.max(hi - lo)) + 0.05
    mid = 0.5 * (lo + hi)
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(max(mid[2] - half, -0.05), max(mid[2] - half, -0.05) + 2 * half)
    ax.view_init(elev=22, azim=-50)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_html(planner, tour, path, meshcat, fps: float = 20.0) -> None:
    """The tour as a Meshcat animation (``planner`` built with this ``meshcat``), saved as one
    HTML file that opens without a server."""
    vis = planner.visualizer
    if vis is None:
        raise ValueError("meshcat: the planner was built without a Meshcat visualizer")
    ctx = planner.context
    vis.StartRecording(set_transforms_while_recording=False)
    traj = tour.trajectory
    for t in np.arange(0.0, traj.end_time() + 1e-9, 1.0 / fps):
        ctx.SetTime(float(t))
        planner.set_q(traj.value(t).ravel())
        planner.diagram.ForcedPublish(ctx)
    vis.StopRecording()
    vis.PublishRecording()
    path.write_text(meshcat.StaticHtml())


def write_preview(planner, tour, html_path, png_path, meshcat=None) -> list:
    """Both previews (the HTML only with ``meshcat``); returns the paths written."""
    written = []
    if meshcat is not None:
        write_html(planner, tour, html_path, meshcat)
        written.append(html_path)
    write_picture(planner, tour, png_path)
    written.append(png_path)
    return written


__all__ = ["write_html", "write_picture", "write_preview"]

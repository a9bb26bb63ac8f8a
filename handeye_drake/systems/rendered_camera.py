"""A rendered camera: the calibration target as textured geometry in SceneGraph and a Drake
``RgbdSensor`` (RenderEngineVtk, headless through EGL) that renders it with given intrinsics.

Frames: W world, P the SceneGraph frame the camera (or the target) rides on, C the camera's optical
frame (OpenCV's: +x right along image columns, +y down along rows, +z forward), T the target
frame (``handeye_drake.vision.targets``: object points on the plane z_T = 0, +z_T pointing into
the board, i.e. away from a camera that sees the printed face).

Four facts this module takes care of, each checked by ``tests/test_rendered_camera.py``:

* Drake's colour camera frame is OpenCV's, and the sensor body frame B coincides with it here
  (``X_BC`` = identity), so ``X_PC`` places the optical frame C exactly.
* RenderEngineVtk renders the scene of a ``CameraInfo`` with principal point (cx, cy) as an
  OpenCV camera would with (cx − ½, cy − ½) (OpenGL puts pixel centres at half-integers; Drake's
  ``CameraInfo`` documents (0, 0) as the centre of the first pixel). ``camera_config`` adds the
  half pixel back, so images follow the ``CameraIntrinsics`` given (K with pixel centres at
  integers, as OpenCV and ``handeye_drake.vision`` use).
* The target texture is an in-memory OBJ + MTL + PNG (nothing written unless ``texture_dir`` is
  given): a thin slab whose front face (z_T = 0, facing −z_T) carries the image texel for texel at
  true scale, the rest grey. Texel centres sit where ``render_target``'s pixel map says.
* RenderEngineVtk takes one sample per pixel (no anti-aliasing): board edges along the pixel
  grid render as hard steps, which costs corner accuracy (reprojection RMS up to 0.3 px, pose
  errors up to 0.45° on a near-frontal ChArUco view). ``supersample=k`` renders k× larger and
  averages k × k blocks (``ImageAreaDownsampler``), at ≈ k² the render time.

Drake's ``ApplyCameraConfig`` is not used: it needs a MultibodyPlant named "plant" (to resolve the
parent frame by name, so no SceneGraph-only diagrams), always adds an LCM image publisher unless
the bus is ``memq://null``, and knows nothing of the half pixel. ``camera_config`` returns a real
``CameraConfig`` (same fields, half pixel included) and ``add_rendered_camera`` builds the sensor
the way ``ApplyCameraConfig`` does (``CameraConfig.MakeCameras`` and an ``RgbdSensor``), so a
config from here also works with ``ApplyCameraConfig``.

Typical wiring (camera on the UR5e flange, target on the table)::

    arm = add_arm(builder)                      # plant + scene graph
    add_target_geometry(arm.scene_graph, target, X_WT)
    camera = mount_rendered_camera(builder, arm.scene_graph, arm.plant, "tool0", X_EC,
                                   intrinsics, supersample=1)
    detector = builder.AddSystem(TargetDetector(target, intrinsics, period))
    builder.Connect(camera.color_image_output_port(), detector.get_color_image_input_port())
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.common import MemoryFile
from pydrake.geometry import (
    FrameId,
    GeometryInstance,
    IllustrationProperties,
    InMemoryMesh,
    MakeRenderEngineVtk,
    Mesh,
    PerceptionProperties,
    RenderEngineVtkParams,
    Rgba,
    SceneGraph,
    SourceId,
)
from pydrake.math import RigidTransform
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import Frame
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.sensors import CameraConfig, RgbdSensor

from ..estimation.validation import as_matrix, as_transform, check_positive
from ..vision.camera_model import CameraIntrinsics
from ..vision.targets import render_target
from .image_downsampler import ImageAreaDownsampler
from .perception_scene import PerceptionScene

#: Name of the RenderEngineVtk instance the cameras of this module share.
RENDERER_NAME = "handeye_vtk"

#: Default background (RGB in [0, 1]): Drake's light blue.
DEFAULT_BACKGROUND = (0.8, 0.898, 1.0)

#: Default texture resolution: ~7 texels per mm. Detection accuracy is flat between 1500 and
#: 8000 texels/m at 0.4–0.6 m with fx = 600 px (measured), so this keeps textures small.
DEFAULT_PIXELS_PER_METRE = 3000.0

#: Default white border around the printed pattern (m): the quiet zone chessboard detection
#: needs around the outer squares.
DEFAULT_MARGIN = 0.02

#: Default board thickness (m): the slab behind the printed face, so the board has a grey back
#: and edges instead of a mirrored texture seen from behind.
DEFAULT_THICKNESS = 0.003

# Colour of the back and edges of a board (linear RGB).
_BACK_COLOUR = (0.45, 0.45, 0.45)


def add_vtk_renderer(scene_graph: SceneGraph, name: str = RENDERER_NAME,
                     background=DEFAULT_BACKGROUND, backend: str = "EGL") -> str:
    """Adds a RenderEngineVtk called ``name`` to ``scene_graph`` unless one of that name exists
    (then its settings are left as they are). ``background``: RGB in [0, 1]; ``backend``: "EGL"
    renders headless, "GLX" needs an X display. Returns ``name``."""
    if not isinstance(scene_graph, SceneGraph):
        raise ValueError(f"scene_graph: expected a SceneGraph, got {type(scene_graph).__name__}")
    if not isinstance(name, str) or not name:
        raise ValueError(f"name: expected a non-empty renderer name, got {name!r}")
    if not scene_graph.HasRenderer(name):
        params = RenderEngineVtkParams(backend=backend,
                                       default_clear_color=_as_rgb(background, "background"))
        scene_graph.AddRenderer(name, MakeRenderEngineVtk(params))
    return name


def _as_rgb(value, name: str) -> np.ndarray:
    rgb = as_matrix(value, name, (3,))
    if np.any(rgb < 0) or np.any(rgb > 1):
        raise ValueError(f"{name}: RGB components must lie in [0, 1], got {rgb.tolist()}")
    return rgb


def _pinhole(intrinsics) -> tuple[float, float, float, float, int, int]:
    """(fx, fy, cx, cy, width, height) of a skew-free, distortion-free CameraIntrinsics."""
    if not isinstance(intrinsics, CameraIntrinsics):
        raise ValueError(f"intrinsics: expected a CameraIntrinsics, got "
                         f"{type(intrinsics).__name__}")
    K = intrinsics.K
    if abs(K[0, 1]) > 1e-9 * K[0, 0]:
        raise ValueError(f"intrinsics: Drake cameras have no skew; got θ = {intrinsics.theta!r} "
                         f"rad (K[0, 1] = {K[0, 1]:.6g}), need π/2")
    distortion = getattr(intrinsics, "distortion", None)
    if distortion is not None and np.any(np.asarray(distortion, dtype=float) != 0):
        raise ValueError("intrinsics: a rendered camera is distortion-free; got distortion "
                         f"{np.asarray(distortion, dtype=float).tolist()}")
    return (float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]),
            int(intrinsics.width), int(intrinsics.height))


def camera_config(intrinsics: CameraIntrinsics, name: str = "camera",
                  clipping_near: float = 0.01, clipping_far: float = 10.0,
                  z_near: float | None = None, z_far: float | None = None,
                  renderer_name: str = RENDERER_NAME, background=DEFAULT_BACKGROUND,
                  fps: float = 30.0, depth: bool = False) -> CameraConfig:
    """Drake's ``CameraConfig`` of a camera whose colour images follow ``intrinsics`` (pixels,
    OpenCV's convention: K with pixel centres at integers; no skew, no distortion).

    ``center_x``/``center_y`` hold cx + ½, cy + ½ (see the module docstring). Clipping planes
    ``clipping_near`` < ``clipping_far`` and the depth range [``z_near``, ``z_far``] (default: the
    clipping range) are in metres along +z_C. The renderer is RenderEngineVtk with the EGL
    backend (headless). The pose fields (``X_PB``, ``X_BC``, ``X_BD``) stay identity:
    ``add_rendered_camera`` takes the pose as an argument."""
    fx, fy, cx, cy, width, height = _pinhole(intrinsics)
    near = check_positive(clipping_near, "clipping_near")
    far = check_positive(clipping_far, "clipping_far")
    if not near < far:
        raise ValueError(f"clipping_near: must be < clipping_far, got {near!r} ≥ {far!r}")
    z_near = near if z_near is None else check_positive(z_near, "z_near")
    z_far = far if z_far is None else check_positive(z_far, "z_far")
    if not near <= z_near < z_far <= far:
        raise ValueError(f"z_near, z_far: depth range [{z_near!r}, {z_far!r}] must be non-empty "
                         f"and lie inside the clipping range [{near!r}, {far!r}]")
    rgb = _as_rgb(background, "background")
    if not isinstance(name, str) or not name:
        raise ValueError(f"name: expected a non-empty camera name, got {name!r}")
    return CameraConfig(
        width=width, height=height, focal=CameraConfig.FocalLength(x=fx, y=fy),
        center_x=cx + 0.5, center_y=cy + 0.5, clipping_near=near, clipping_far=far,
        z_near=z_near, z_far=z_far, renderer_name=renderer_name,
        renderer_class=RenderEngineVtkParams(backend="EGL", default_clear_color=rgb),
        background=Rgba(*rgb, 1.0), name=name, fps=check_positive(fps, "fps"), rgb=True,
        depth=bool(depth))


@dataclass(frozen=True, eq=False)
class RenderedCamera:
    """What ``add_rendered_camera`` built: the ``RgbdSensor`` (rendering ``supersample`` times
    the image size, with ``config``), the ``ImageAreaDownsampler`` that averages it down (None
    when ``supersample`` is 1) and the ``intrinsics`` of the output images."""

    sensor: RgbdSensor
    downsampler: ImageAreaDownsampler | None
    intrinsics: CameraIntrinsics
    config: CameraConfig
    supersample: int

    def color_image_output_port(self):
        """The colour image (abstract ``ImageRgba8U``, width × height of ``intrinsics``)."""
        if self.downsampler is None:
            return self.sensor.color_image_output_port()
        return self.downsampler.get_output_port()

    def EvalColorImage(self, root_context) -> np.ndarray:
        """A copy of the colour image (H×W×4 uint8 RGBA) in the diagram's ``root_context``
        (renders a frame unless cached)."""
        system = self.sensor if self.downsampler is None else self.downsampler
        return np.array(self.color_image_output_port().Eval(
            system.GetMyContextFromRoot(root_context)).data)


def _supersampled(intrinsics: CameraIntrinsics, k: int) -> CameraIntrinsics:
    """The camera whose k × k block averages are images of ``intrinsics`` (pixel centres at
    integers in both: u_in + ½ = k (u + ½))."""
    return CameraIntrinsics(alpha_u=k * intrinsics.alpha_u, alpha_v=k * intrinsics.alpha_v,
                            u0=k * (intrinsics.u0 + 0.5) - 0.5, v0=k * (intrinsics.v0 + 0.5) - 0.5,
                            width=k * intrinsics.width, height=k * intrinsics.height)


def add_rendered_camera(builder: DiagramBuilder, scene_graph: SceneGraph, parent_frame_id,
                        X_PC, intrinsics: CameraIntrinsics, supersample: int = 1,
                        **config_kwargs) -> RenderedCamera:
    """Adds a rendered camera whose optical frame C sits at ``X_PC`` (4×4 or RigidTransform, m)
    in the SceneGraph frame ``parent_frame_id`` (``scene_graph.world_frame_id()`` for a fixed
    camera, ``plant.GetBodyFrameIdOrThrow(body.index())`` for one on a body; see
    ``mount_rendered_camera``), connects it to the scene graph's query port and returns its
    ``RenderedCamera`` handle; connect ``handle.color_image_output_port()`` (``ImageRgba8U``,
    width × height of ``intrinsics``, row 0 at the top) to the detector.

    ``supersample`` = k > 1 renders k× larger and averages k × k blocks (anti-aliasing: edges
    along the pixel grid otherwise render as hard steps; costs ≈ k² render time).
    ``config_kwargs`` go to ``camera_config`` (name, clipping_near, clipping_far, z_near, z_far,
    renderer_name, background, fps). The renderer is added on first use (``add_vtk_renderer``).

    Frames render on demand: each evaluation of the image port at a new context time or pose
    renders one frame; ``TargetDetector`` samples it once per period. The sensor's depth image
    (``handle.sensor.depth_image_32F_output_port()``, metres along +z_C) renders only if
    evaluated, at the supersampled size.
    """
    if not isinstance(builder, DiagramBuilder):
        raise ValueError(f"builder: expected a DiagramBuilder, got {type(builder).__name__}")
    if not isinstance(parent_frame_id, FrameId):
        raise ValueError(f"parent_frame_id: expected a pydrake.geometry.FrameId, got "
                         f"{type(parent_frame_id).__name__}")
    if isinstance(supersample, bool) or not isinstance(supersample, (int, np.integer)) or not (
            1 <= supersample <= 8):
        raise ValueError(f"supersample: expected an integer in [1, 8], got {supersample!r}")
    k = int(supersample)
    X_PC = as_transform(X_PC, "X_PC")
    _pinhole(intrinsics)
    config = camera_config(_supersampled(intrinsics, k) if k > 1 else intrinsics,
                           **config_kwargs)
    bg = config.background
    add_vtk_renderer(scene_graph, config.renderer_name, (bg.r(), bg.g(), bg.b()))
    color_camera, depth_camera = config.MakeCameras()
    sensor = builder.AddSystem(RgbdSensor(parent_frame_id, RigidTransform(X_PC), color_camera,
                                          depth_camera))
    sensor.set_name(f"rgbd_sensor_{config.name}")
    builder.Connect(scene_graph.get_query_output_port(), sensor.query_object_input_port())
    downsampler = None
    if k > 1:
        downsampler = builder.AddSystem(ImageAreaDownsampler(intrinsics.width,
                                                             intrinsics.height, k))
        downsampler.set_name(f"downsampler_{config.name}")
        builder.Connect(sensor.color_image_output_port(), downsampler.get_input_port())
    return RenderedCamera(sensor=sensor, downsampler=downsampler, intrinsics=intrinsics,
                          config=config, supersample=k)


def mount_rendered_camera(builder: DiagramBuilder, scene_graph: SceneGraph | PerceptionScene,
                          plant: MultibodyPlant, frame, X_FC, intrinsics: CameraIntrinsics,
                          supersample: int = 1, **config_kwargs) -> RenderedCamera:
    """``add_rendered_camera`` on a MultibodyPlant frame F (a ``Frame`` or its name, e.g. the
    UR5e flange "tool0", a fixed frame on body "wrist_3_link"), with the camera's optical frame
    at ``X_FC`` in F (for a hand camera F = E and X_FC = X_EC). The parent is F's body frame in
    SceneGraph and X_PC = X_BodyF · X_FC, as ``ApplyCameraConfig`` resolves ``X_PB.base_frame``.
    ``plant`` must be connected to ``scene_graph`` (``AddMultibodyPlantSceneGraph``), or
    ``scene_graph`` is a ``PerceptionScene`` of ``plant`` (``add_perception_scene_graph``, with
    F's body among its frames): the camera then renders there, and the plant's own SceneGraph
    gets no renderer to update at every plant step."""
    if not isinstance(plant, MultibodyPlant):
        raise ValueError(f"plant: expected a MultibodyPlant, got {type(plant).__name__}")
    if isinstance(frame, str):
        if not plant.HasFrameNamed(frame):
            raise ValueError(f"frame: no frame named {frame!r} in the plant")
        frame = plant.GetFrameByName(frame)
    elif not isinstance(frame, Frame):
        raise ValueError(f"frame: expected a frame name or a pydrake Frame, got "
                         f"{type(frame).__name__}")
    X_FC = as_transform(X_FC, "X_FC")
    X_BodyF = frame.GetFixedPoseInBodyFrame().GetAsMatrix4()
    if isinstance(scene_graph, PerceptionScene):
        if scene_graph.plant is not plant:
            raise ValueError("scene_graph: this PerceptionScene mirrors another plant")
        return add_rendered_camera(builder, scene_graph.scene_graph,
                                   scene_graph.frame_id(frame.body()), X_BodyF @ X_FC,
                                   intrinsics, supersample, **config_kwargs)
    try:
        parent = plant.GetBodyFrameIdOrThrow(frame.body().index())
    except RuntimeError as e:
        raise ValueError(f"plant: body {frame.body().name()!r} has no SceneGraph frame; "
                         f"register the plant with the scene graph first ({e})") from None
    return add_rendered_camera(builder, scene_graph, parent, X_BodyF @ X_FC, intrinsics,
                               supersample, **config_kwargs)


def _board_obj(image_shape, px_from_T: np.ndarray, thickness: float) -> str:
    """OBJ text of the slab. The texture's outer texel edges (pixel coordinates −½ and w − ½,
    texel centres at integers) map through T_from_px to the corners of the front face;
    u = (col + ½)/w, v = 1 − (row + ½)/h (OBJ's v axis points up the image)."""
    h, w = image_shape
    T_from_px = np.linalg.inv(px_from_T)
    px = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]])
    xy = (np.column_stack([px, np.ones(4)]) @ T_from_px.T)[:, :2]
    uv = np.column_stack([(px[:, 0] + 0.5) / w, 1.0 - (px[:, 1] + 0.5) / h])
    vertices = np.vstack([np.column_stack([xy, np.zeros(4)]),             # 0..3 front
                          np.column_stack([xy, np.full(4, thickness)])])  # 4..7 back
    normals = [np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, 1.0])]
    centre = vertices.mean(axis=0)

    def triangle(i, j, k, n, uv_index=None):
        # Counter-clockwise seen from outside (along −n), so the face normal points along n.
        a, b, c = vertices[[i, j, k]]
        if np.dot(np.cross(b - a, c - a), normals[n]) < 0:
            j, k = k, j
        if uv_index is None:
            return f"f {i + 1}//{n + 1} {j + 1}//{n + 1} {k + 1}//{n + 1}"
        return (f"f {i + 1}/{uv_index[i] + 1}/{n + 1} {j + 1}/{uv_index[j] + 1}/{n + 1} "
                f"{k + 1}/{uv_index[k] + 1}/{n + 1}")

    faces = ["usemtl front", triangle(0, 1, 2, 0, range(4)), triangle(0, 2, 3, 0, range(4)),
             "usemtl back", triangle(4, 5, 6, 1), triangle(4, 6, 7, 1)]
    for j in range(4):
        i0, i1 = j, (j + 1) % 4
        n = 0.5 * (vertices[i0] + vertices[i1]) - centre
        n[2] = 0.0
        normals.append(n / np.linalg.norm(n))
        faces += [triangle(i0, i0 + 4, i1 + 4, len(normals) - 1),
                  triangle(i0, i1 + 4, i1, len(normals) - 1)]
    lines = ["mtllib board.mtl"]
    lines += ["v {:.9g} {:.9g} {:.9g}".format(*v) for v in vertices]
    lines += ["vt {:.9g} {:.9g}".format(*t) for t in uv]
    lines += ["vn {:.9g} {:.9g} {:.9g}".format(*n) for n in normals]
    return "\n".join(lines + faces) + "\n"


def _board_mtl() -> str:
    r, g, b = _BACK_COLOUR
    return ("newmtl front\nKa 0 0 0\nKd 1 1 1\nKs 0 0 0\nmap_Kd board.png\n"
            f"newmtl back\nKa 0 0 0\nKd {r} {g} {b}\nKs 0 0 0\n")


def _encode_png(image: np.ndarray) -> bytes:
    import cv2  # OpenCV is a dependency of the vision package; only needed here.
    ok, data = cv2.imencode(".png", image)
    if not ok:  # pragma: no cover - cv2 encodes any uint8 grey/BGR image
        raise ValueError("image: OpenCV could not encode the texture as PNG")
    return data.tobytes()


def textured_board_mesh(image, px_from_T, thickness: float = DEFAULT_THICKNESS,
                        texture_dir=None, name: str = "board") -> Mesh:
    """An in-memory ``Mesh`` of a board of ``thickness`` (m) in frame T whose front face
    (z_T = 0, outward normal −z_T) shows ``image`` (H×W uint8 grey, or H×W×3 uint8 BGR as OpenCV
    stores it) at true scale: ``px_from_T`` (3×3, affine: last row [0, 0, 1]) maps (x_T, y_T, 1)
    in metres to (col, row, 1) in texels, texel centres at integers (``render_target``'s map).
    The back (z_T = thickness) and the edges are grey.

    With ``texture_dir`` set, the OBJ, MTL and PNG are also written there as ``{name}.obj``,
    ``{name}.mtl`` (referring to ``board.png`` renamed ``{name}.png``) for inspection; the
    returned mesh does not depend on those files."""
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim not in (2, 3) or (
            image.ndim == 3 and image.shape[2] != 3) or min(image.shape[:2]) < 1:
        raise ValueError(f"image: expected an H×W or H×W×3 uint8 array, got {image.dtype} "
                         f"{image.shape}")
    M = as_matrix(px_from_T, "px_from_T", (3, 3))
    if np.any(M[2] != [0.0, 0.0, 1.0]):
        raise ValueError(f"px_from_T: must be affine (last row [0, 0, 1]), got {M[2].tolist()}")
    if abs(np.linalg.det(M[:2, :2])) < 1e-12:
        raise ValueError("px_from_T: singular map from the target plane to texels")
    thickness = check_positive(thickness, "thickness")
    obj = _board_obj(image.shape[:2], M, thickness)
    mtl = _board_mtl()
    png = _encode_png(image)
    if texture_dir is not None:
        out = Path(texture_dir)
        out.mkdir(parents=True, exist_ok=True)
        (out / f"{name}.obj").write_text(obj.replace("mtllib board.mtl", f"mtllib {name}.mtl"))
        (out / f"{name}.mtl").write_text(mtl.replace("board.png", f"{name}.png"))
        (out / f"{name}.png").write_bytes(png)
    return Mesh(InMemoryMesh(
        mesh_file=MemoryFile(obj, ".obj", f"{name}.obj"),
        supporting_files={"board.mtl": MemoryFile(mtl, ".mtl", "board.mtl"),
                          "board.png": MemoryFile(png, ".png", "board.png")}))


def add_textured_board(scene_graph: SceneGraph, image, px_from_T, X_PT, name: str = "target",
                       frame_id: FrameId | None = None, source_id: SourceId | None = None,
                       thickness: float = DEFAULT_THICKNESS, texture_dir=None,
                       illustration: bool = True):
    """Registers the board of ``textured_board_mesh(image, px_from_T, thickness)`` at ``X_PT``
    (4×4 or RigidTransform, m) with the perception role (and illustration, for Meshcat, unless
    ``illustration=False``). Returns its ``GeometryId``.

    Fixed in the world (``frame_id`` None): anchored geometry, X_PT = X_WT, registered under a
    new source called ``name`` unless ``source_id`` is given. On a moving frame (e.g. a target on
    the flange, eye-to-hand): ``frame_id`` and the ``source_id`` that owns it (for a plant body:
    ``plant.GetBodyFrameIdOrThrow(body.index())`` and ``plant.get_source_id()``)."""
    if not isinstance(scene_graph, SceneGraph):
        raise ValueError(f"scene_graph: expected a SceneGraph, got {type(scene_graph).__name__}")
    X_PT = as_transform(X_PT, "X_PT")
    mesh = textured_board_mesh(image, px_from_T, thickness, texture_dir, name)
    instance = GeometryInstance(RigidTransform(X_PT), mesh, name)
    instance.set_perception_properties(PerceptionProperties())
    if illustration:
        instance.set_illustration_properties(IllustrationProperties())
    if frame_id is None:
        if source_id is None:
            source_id = scene_graph.RegisterSource(name)
        return scene_graph.RegisterAnchoredGeometry(source_id, instance)
    if not isinstance(frame_id, FrameId):
        raise ValueError(f"frame_id: expected a pydrake.geometry.FrameId, got "
                         f"{type(frame_id).__name__}")
    if not isinstance(source_id, SourceId):
        raise ValueError("source_id: a board on a frame needs the SourceId that owns the frame")
    try:
        return scene_graph.RegisterGeometry(source_id, frame_id, instance)
    except RuntimeError as e:
        raise ValueError(f"frame_id: cannot register the board on this frame ({e})") from None


def add_target_geometry(scene_graph: SceneGraph, target, X_WT, texture_dir=None,
                        pixels_per_metre: float = DEFAULT_PIXELS_PER_METRE,
                        margin: float = DEFAULT_MARGIN, name: str = "target",
                        frame_id: FrameId | None = None, source_id: SourceId | None = None,
                        thickness: float = DEFAULT_THICKNESS, illustration: bool = True):
    """Registers the calibration ``target`` (a target or a spec string, see
    ``handeye_drake.vision.targets``) as a textured board at ``X_WT`` (4×4 or RigidTransform, m;
    X_PT on ``frame_id`` if given, see ``add_textured_board``) and returns its ``GeometryId``.

    The texture is ``render_target(target, pixels_per_metre, margin)``: the printed pattern at
    true scale with a white border of ``margin`` metres, on the front face (z_T = 0, seen from
    the −z_T side). ``texture_dir``: also write the OBJ/MTL/PNG there (default: nothing written;
    the mesh lives in memory)."""
    image, px_from_T = render_target(target, pixels_per_metre, margin)
    return add_textured_board(scene_graph, image, px_from_T, X_WT, name=name,
                              frame_id=frame_id, source_id=source_id, thickness=thickness,
                              texture_dir=texture_dir, illustration=illustration)

"""Camera intrinsics from a short string or a calibration file (numpy/OpenCV/PyYAML, no Drake).

``load_intrinsics`` accepts:

* ``"fx,fy,cx,cy[,k1,k2,p1,p2[,k3[,k4,k5,k6]]]"`` — pixels, OpenCV's distortion order; the image
  size comes from the ``width`` and ``height`` arguments;
* an OpenCV YAML or XML file as OpenCV's calibration samples write it (``camera_matrix``,
  ``distortion_coefficients``, ``image_width``, ``image_height``; read with ``cv2.FileStorage``,
  recognised by its ``%YAML`` header or XML);
* a ROS ``camera_info`` YAML (``camera_matrix: {rows, cols, data}``,
  ``distortion_coefficients: {data}``, ``distortion_model: plumb_bob`` or
  ``rational_polynomial``, ``image_width``, ``image_height``), or the dump of a
  ``sensor_msgs/CameraInfo`` message (``width``, ``height``, ``K``/``k``, ``D``/``d``,
  ``distortion_model``).

``write_intrinsics_yaml`` writes the OpenCV format back (exact round trip of every double).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .camera_model import DISTORTION_LENGTHS, CameraIntrinsics

#: ROS distortion models that are OpenCV's pinhole model (``equidistant`` is the fisheye model,
#: which ``cv2.solvePnP`` does not take).
ROS_DISTORTION_MODELS = ("plumb_bob", "rational_polynomial")

_SPEC_FORM = "fx,fy,cx,cy[,k1,k2,p1,p2[,k3[,k4,k5,k6]]] (pixels)"


def _check_size(value, name: str) -> int | None:
    if value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = float("nan")
    if not math.isfinite(v) or v < 1 or v != round(v):
        raise ValueError(f"{name}: image size must be an integer ≥ 1 pixel, got {value!r}")
    return int(v)


def _resolve_size(source: str, file_w, file_h, width, height) -> tuple[int, int]:
    """Image size from the file and/or the arguments; they must agree when both are given."""
    out = []
    for name, in_file, arg in (("width", file_w, width), ("height", file_h, height)):
        if in_file is not None and arg is not None and in_file != arg:
            raise ValueError(f"{name}: {source} says image {name} {in_file}, the argument says "
                             f"{arg}")
        value = in_file if in_file is not None else arg
        if value is None:
            raise ValueError(f"{name}: {source} has no image {name}; pass width and height")
        out.append(value)
    return out[0], out[1]


def parse_intrinsics_spec(spec: str, width: int | None = None,
                          height: int | None = None) -> CameraIntrinsics:
    """Intrinsics from ``"fx,fy,cx,cy[,k1,k2,p1,p2[,k3[,k4,k5,k6]]]"`` and the image size."""
    parts = [p.strip() for p in str(spec).split(",")]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        bad = next(p for p in parts if not _is_float(p))
        raise ValueError(f"intrinsics {spec!r}: {bad!r} is not a number; expected "
                         f"{_SPEC_FORM}") from None
    if len(values) - 4 not in DISTORTION_LENGTHS[:4]:
        raise ValueError(f"intrinsics {spec!r}: expected 4, 8, 9 or 12 numbers, got "
                         f"{len(values)}; expected {_SPEC_FORM}")
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"intrinsics {spec!r}: values must be finite; expected {_SPEC_FORM}")
    w, h = _resolve_size(f"intrinsics {spec!r}", None, None, _check_size(width, "width"),
                         _check_size(height, "height"))
    fx, fy, cx, cy = values[:4]
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    try:
        return CameraIntrinsics.from_matrix(K, w, h, tuple(values[4:]))
    except ValueError as e:
        raise ValueError(f"intrinsics {spec!r}: {e}") from None


def _is_float(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


# --------------------------------------------------------------------------------------------
# OpenCV FileStorage files


def _fs_number(node, source: str, name: str) -> float | None:
    if node.empty() or node.isNone():
        return None
    if node.isInt() or node.isReal():
        return node.real()
    raise ValueError(f"{source}: field {name}: expected a number")


def _fs_matrix(node, source: str, name: str) -> np.ndarray | None:
    if node.empty() or node.isNone():
        return None
    if node.isSeq():
        values = []
        for i in range(node.size()):
            item = node.at(i)
            if not (item.isInt() or item.isReal()):
                raise ValueError(f"{source}: field {name}: element {i} is not a number")
            values.append(item.real())
        return np.array(values, dtype=float)
    if node.isMap():
        try:
            m = node.mat()
        except Exception:  # noqa: BLE001 - cv2 raises cv2.error or SystemError
            m = None
        if m is None:
            raise ValueError(f"{source}: field {name}: not an OpenCV matrix (!!opencv-matrix "
                             f"with rows, cols, dt, data)")
        return np.asarray(m, dtype=float).ravel()
    raise ValueError(f"{source}: field {name}: expected a matrix")


def _read_opencv_file(path: Path, source: str) -> dict:
    import cv2
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        opened = fs.isOpened()
    except Exception as e:  # noqa: BLE001 - cv2 reports parse errors as cv2.error/SystemError
        cause = e.__cause__ if e.__cause__ is not None else e
        message = str(cause).strip().splitlines()[-1] if str(cause).strip() else type(e).__name__
        raise ValueError(f"{source}: not a valid OpenCV YAML/XML file ({message})") from None
    if not opened:
        raise ValueError(f"{source}: OpenCV could not open it")
    try:
        return {
            "K": _fs_matrix(fs.getNode("camera_matrix"), source, "camera_matrix"),
            "dist": _fs_matrix(fs.getNode("distortion_coefficients"), source,
                               "distortion_coefficients"),
            "width": _fs_number(fs.getNode("image_width"), source, "image_width"),
            "height": _fs_number(fs.getNode("image_height"), source, "image_height"),
            "model": None,
        }
    finally:
        fs.release()


# --------------------------------------------------------------------------------------------
# Plain YAML (ROS camera_info)


def _yaml_matrix(value, source: str, name: str) -> np.ndarray | None:
    if value is None:
        return None
    if isinstance(value, dict):
        if "data" not in value:
            raise ValueError(f"{source}: field {name}: expected a mapping with 'data' "
                             f"(and rows, cols)")
        data = value["data"]
    else:
        data = value
    try:
        m = np.array(data, dtype=float).ravel()
    except (TypeError, ValueError):
        raise ValueError(f"{source}: field {name}: data must be a list of numbers") from None
    if isinstance(value, dict) and "rows" in value and "cols" in value:
        try:
            expected = int(value["rows"]) * int(value["cols"])
        except (TypeError, ValueError):
            raise ValueError(f"{source}: field {name}: rows and cols must be integers") from None
        if expected != m.size:
            raise ValueError(f"{source}: field {name}: rows × cols = {expected} but data has "
                             f"{m.size} numbers")
    return m


def _read_plain_yaml(text: str, source: str) -> dict:
    import yaml
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise ValueError(f"{source}: not valid YAML ({str(e).splitlines()[0]})") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{source}: expected a YAML mapping with camera_matrix (ROS "
                         f"camera_info), got {type(doc).__name__}")

    def first(*keys):
        for k in keys:
            if k in doc:
                return k, doc[k]
        return keys[0], None

    k_name, k_value = first("camera_matrix", "K", "k")
    d_name, d_value = first("distortion_coefficients", "D", "d")
    w_name, w_value = first("image_width", "width")
    h_name, h_value = first("image_height", "height")
    numbers = {}
    for name, value in ((w_name, w_value), (h_name, h_value)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise ValueError(f"{source}: field {name}: expected a number, got {value!r}")
        numbers[name] = value
    model = doc.get("distortion_model")
    return {"K": _yaml_matrix(k_value, source, k_name),
            "dist": _yaml_matrix(d_value, source, d_name),
            "width": numbers[w_name], "height": numbers[h_name], "model": model,
            "names": (k_name, d_name, w_name, h_name)}


# --------------------------------------------------------------------------------------------


def _intrinsics_from_fields(fields: dict, source: str, width, height) -> CameraIntrinsics:
    k_name, d_name, w_name, h_name = fields.get(
        "names", ("camera_matrix", "distortion_coefficients", "image_width", "image_height"))
    K = fields["K"]
    if K is None:
        raise ValueError(f"{source}: field {k_name} is missing")
    if K.size != 9:
        raise ValueError(f"{source}: field {k_name}: expected a 3×3 matrix (9 numbers), got "
                         f"{K.size}")
    model = fields.get("model")
    if model is not None and model not in ROS_DISTORTION_MODELS:
        raise ValueError(f"{source}: field distortion_model: {model!r} is not supported, "
                         f"expected one of {', '.join(ROS_DISTORTION_MODELS)} (OpenCV's pinhole "
                         f"model)")
    dist = fields["dist"]
    dist = () if dist is None else tuple(dist.tolist())
    if len(dist) not in DISTORTION_LENGTHS:
        raise ValueError(f"{source}: field {d_name}: OpenCV takes "
                         f"{', '.join(map(str, DISTORTION_LENGTHS))} coefficients, got "
                         f"{len(dist)}")
    sizes = []
    for name, value in ((w_name, fields["width"]), (h_name, fields["height"])):
        try:
            sizes.append(_check_size(value, name))
        except ValueError as e:
            raise ValueError(f"{source}: field {e}") from None
    w, h = _resolve_size(source, sizes[0], sizes[1], _check_size(width, "width"),
                         _check_size(height, "height"))
    try:
        return CameraIntrinsics.from_matrix(K.reshape(3, 3), w, h, dist)
    except ValueError as e:
        raise ValueError(f"{source}: field {k_name}/{d_name}: {e}") from None


def load_intrinsics(spec_or_path, width: int | None = None,
                    height: int | None = None) -> CameraIntrinsics:
    """Camera intrinsics from a ``"fx,fy,cx,cy[,k1,k2,p1,p2[,k3]]"`` string or a file (OpenCV
    YAML/XML, ROS camera_info YAML); see the module docstring.

    ``width``/``height`` give the image size when the source has none, and must agree with the
    file when both give it. Raises one ValueError naming the file (or string) and the field."""
    if isinstance(spec_or_path, CameraIntrinsics):
        return spec_or_path
    if not isinstance(spec_or_path, (str, Path)):
        raise ValueError(f"intrinsics: expected a 'fx,fy,cx,cy[,…]' string or a file path, got "
                         f"{type(spec_or_path).__name__}")
    path = Path(spec_or_path)
    text_arg = str(spec_or_path).strip()
    if not path.is_file():
        looks_like_file = "/" in text_arg or path.suffix.lower() in (".yaml", ".yml", ".xml")
        if "," in text_arg and not looks_like_file:
            return parse_intrinsics_spec(text_arg, width, height)
        raise ValueError(f"intrinsics {text_arg!r}: no such file, and not a {_SPEC_FORM} string")
    source = f"intrinsics file {str(path)!r}"
    try:
        raw = path.read_bytes()[:10_000_000]
        text = raw.decode("utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"{source}: cannot read it as text ({e})") from None
    head = text.lstrip()
    if head.startswith("%YAML") or head.startswith("<?xml") or head.startswith("<opencv_storage"):
        fields = _read_opencv_file(path, source)
    else:
        fields = _read_plain_yaml(text, source)
    return _intrinsics_from_fields(fields, source, width, height)


def intrinsics_from_camera_info(K, D, width, height, distortion_model: str = "",
                                source: str = "CameraInfo") -> CameraIntrinsics:
    """Intrinsics from the fields of a ``sensor_msgs/CameraInfo`` message: K (9 numbers, row
    major), D, width, height (pixels), distortion_model (``plumb_bob``, ``rational_polynomial``
    or empty). Checked like a camera_info YAML file; errors start with ``source``."""
    try:
        K = np.asarray(K, dtype=float).ravel()
        D = np.asarray(D if D is not None else (), dtype=float).ravel()
    except (TypeError, ValueError):
        raise ValueError(f"{source}: K and D must be numbers") from None
    fields = {"K": K, "dist": D if D.size else None, "width": width, "height": height,
              "model": str(distortion_model) or None, "names": ("K", "D", "width", "height")}
    return _intrinsics_from_fields(fields, source, None, None)


def write_intrinsics_yaml(intrinsics: CameraIntrinsics, path) -> Path:
    """Writes ``intrinsics`` as OpenCV's calibration sample does (``image_width``,
    ``image_height``, ``camera_matrix``, ``distortion_coefficients`` — omitted when there is no
    distortion); ``load_intrinsics`` reads it back exactly. Returns the path."""
    import cv2
    if not isinstance(intrinsics, CameraIntrinsics):
        raise ValueError(f"intrinsics: expected a CameraIntrinsics, got "
                         f"{type(intrinsics).__name__}")
    path = Path(path)
    if path.suffix.lower() not in (".yaml", ".yml", ".xml"):
        raise ValueError(f"path: expected a .yaml, .yml or .xml file name, got {str(path)!r}")
    if not path.parent.is_dir():
        raise ValueError(f"path: directory {str(path.parent)!r} does not exist")
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    try:
        fs.write("image_width", int(intrinsics.width))
        fs.write("image_height", int(intrinsics.height))
        fs.write("camera_matrix", intrinsics.K)
        if intrinsics.distortion:
            fs.write("distortion_coefficients",
                     np.array(intrinsics.distortion, dtype=float).reshape(-1, 1))
    finally:
        fs.release()
    return path


__all__ = [
    "ROS_DISTORTION_MODELS",
    "intrinsics_from_camera_info",
    "load_intrinsics",
    "parse_intrinsics_spec",
    "write_intrinsics_yaml",
]

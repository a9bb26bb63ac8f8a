"""The optical frame's fixed pose in a camera's mount link, read from the camera's own URDF/xacro.

A camera driver's description (e.g. ``realsense2_description``) declares a chain of links
``camera_link`` → … → ``camera_color_optical_frame`` joined by fixed joints. To attach such a
camera to a calibrated robot, the hand-eye export names the *mount* link as its child and
the camera's description supplies the rest; the export needs X_{mount,optical}, the composition of
the fixed joints' ``<origin xyz rpy>`` along the path between the two links (up to their common
ancestor and down again, so the optical frame may be above or below the mount).

URDF files are read as they are. Plain xacro files are evaluated here without ROS: top-level
``<xacro:property name value>`` with numbers or text, and ``${...}`` expressions of numbers,
properties, ``pi``, ``+ - * / ** %`` and the math functions xacro offers (``radians``, ``sin``,
``sqrt``, …). Anything else of xacro — macros, includes, conditionals, ``$(arg …)``/``$(find …)``
— is refused with a one-line error: expand the file with ``xacro FILE > camera.urdf`` first.

Errors are ValueErrors that name the argument (``argument_names`` maps ``path``, ``mount`` and
``optical`` to the caller's names, e.g. ``--camera-urdf``, ``--child-frame``,
``--optical-frame``). Nothing here imports Drake or ROS.
"""

from __future__ import annotations

import ast
import math
import operator
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

_DEFAULT_NAMES = {"path": "camera_urdf", "mount": "mount_frame", "optical": "optical_frame"}
_EXPR = re.compile(r"\$\{([^{}]*)\}")
_BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
           ast.Div: operator.truediv, ast.Pow: operator.pow, ast.Mod: operator.mod,
           ast.FloorDiv: operator.floordiv}
_UNARY = {ast.USub: operator.neg, ast.UAdd: operator.pos}
_FUNCTIONS = {name: getattr(math, name) for name in (
    "radians", "degrees", "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sqrt", "exp",
    "log", "floor", "ceil", "fabs", "hypot")}
_FUNCTIONS.update(abs=abs, min=min, max=max, float=float, int=int)
_CONSTANTS = {"pi": math.pi, "e": math.e, "inf": math.inf}


@dataclass(frozen=True)
class Joint:
    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray          # 4×4 X_{parent,child} at q = 0


class CameraDescription:
    """The links and joints of a camera URDF (or plain xacro) file."""

    def __init__(self, path, argument_names: dict | None = None):
        self.names = {**_DEFAULT_NAMES, **(argument_names or {})}
        self.path = Path(path)
        arg = self.names["path"]
        try:
            text = self.path.read_text()
        except (OSError, UnicodeDecodeError) as e:
            raise ValueError(f"{arg}: cannot read {path} "
                             f"({getattr(e, 'strerror', None) or e})") from None
        try:
            root = ET.fromstring(text)
        except ET.ParseError as e:
            raise ValueError(f"{arg}: {path} is not well-formed XML ({e})") from None
        if _local(root.tag) != "robot":
            raise ValueError(f"{arg}: {path} is not a URDF/xacro file (root element "
                             f"<{_local(root.tag)}>, expected <robot>)")
        evaluate = _Xacro(root, f"{arg}: {path}")
        self.links: list[str] = []
        self.joints: list[Joint] = []
        for e in root:
            tag = _local(e.tag)
            if tag == "link":
                self.links.append(evaluate(_attr(e, "name", f"{arg}: {path}: <link>")))
            elif tag == "joint":
                self.joints.append(self._joint(e, evaluate))
        self._parent_joint: dict[str, Joint] = {}
        for j in self.joints:
            other = self._parent_joint.get(j.child)
            if other is not None:
                raise ValueError(f"{arg}: {path}: link {j.child!r} is the child of two joints "
                                 f"({other.name!r} and {j.name!r}); a URDF is a tree")
            self._parent_joint[j.child] = j
        known = set(self.links) | {j.parent for j in self.joints} | \
            {j.child for j in self.joints}
        self.all_links = sorted(known)

    def _joint(self, e, evaluate) -> Joint:
        where = f"{self.names['path']}: {self.path}"
        name = evaluate(_attr(e, "name", f"{where}: <joint>"))
        jtype = evaluate(_attr(e, "type", f"{where}: joint {name!r}"))
        links = []
        for which in ("parent", "child"):
            el = e.find(which)
            if el is None:
                raise ValueError(f"{where}: joint {name!r} has no <{which} link=...>")
            links.append(evaluate(_attr(el, "link", f"{where}: joint {name!r} <{which}>")))
        origin = e.find("origin")
        xyz = _vector(evaluate(origin.get("xyz", "0 0 0")) if origin is not None else "0 0 0",
                      f"{where}: joint {name!r} origin xyz")
        rpy = _vector(evaluate(origin.get("rpy", "0 0 0")) if origin is not None else "0 0 0",
                      f"{where}: joint {name!r} origin rpy")
        X = np.eye(4)
        X[:3, :3] = _rotation_from_rpy(rpy)
        X[:3, 3] = xyz
        return Joint(name, jtype, links[0], links[1], X)

    def parent_joint(self, link: str) -> Joint | None:
        """The joint whose child is ``link`` (None for a root link)."""
        return self._parent_joint.get(link)

    def _check_link(self, link: str, which: str) -> None:
        if link not in self.all_links:
            shown = ", ".join(self.all_links[:12]) + (" …" if len(self.all_links) > 12 else "")
            raise ValueError(f"{self.names[which]}: no link {link!r} in {self.path} "
                             f"(its links: {shown or 'none'})")

    def _ancestors(self, link: str) -> list[Joint]:
        """The joints from ``link`` up to its root, nearest first."""
        chain, seen = [], {link}
        j = self._parent_joint.get(link)
        while j is not None:
            chain.append(j)
            if j.parent in seen:
                raise ValueError(f"{self.names['path']}: {self.path}: the joints form a cycle "
                                 f"through {j.parent!r}")
            seen.add(j.parent)
            j = self._parent_joint.get(j.parent)
        return chain

    def offset(self, mount: str, optical: str) -> np.ndarray:
        """X_{mount,optical} (4×4, metres): the fixed joints' origins composed along the path
        from ``mount`` to ``optical``. ValueError for an unknown link, no path of joints
        between them, or a joint on the path that is not fixed."""
        self._check_link(mount, "mount")
        self._check_link(optical, "optical")
        if mount == optical:
            raise ValueError(f"{self.names['mount']}: the mount link and "
                             f"{self.names['optical']} are both {mount!r}")
        up_mount, up_optical = self._ancestors(mount), self._ancestors(optical)
        above_mount = [mount] + [j.parent for j in up_mount]
        above_optical = [optical] + [j.parent for j in up_optical]
        common = next((link for link in above_optical if link in above_mount), None)
        if common is None:
            raise ValueError(f"{self.names['optical']}: no chain of joints between {mount!r} "
                             f"and {optical!r} in {self.path} (they are in separate trees, "
                             f"rooted at {above_mount[-1]!r} and {above_optical[-1]!r})")
        path_mount = up_mount[:above_mount.index(common)]
        path_optical = up_optical[:above_optical.index(common)]
        moving = [j for j in path_mount + path_optical if j.type != "fixed"]
        if moving:
            j = moving[0]
            raise ValueError(f"{self.names['path']}: joint {j.name!r} ({j.type}, {j.parent} → "
                             f"{j.child}) between {mount!r} and {optical!r} in {self.path} is "
                             "not fixed; the optical frame's offset must be a fixed transform")
        X_common_mount, X_common_optical = np.eye(4), np.eye(4)
        for j in reversed(path_mount):
            X_common_mount = X_common_mount @ j.origin
        for j in reversed(path_optical):
            X_common_optical = X_common_optical @ j.origin
        R, p = X_common_mount[:3, :3], X_common_mount[:3, 3]
        X_mount_common = np.eye(4)
        X_mount_common[:3, :3] = R.T
        X_mount_common[:3, 3] = -R.T @ p
        return X_mount_common @ X_common_optical

    def chain(self, mount: str, optical: str) -> list[str]:
        """Names of the joints on the path between the two links (for messages)."""
        self.offset(mount, optical)
        up_m, up_o = self._ancestors(mount), self._ancestors(optical)
        names_m = [mount] + [j.parent for j in up_m]
        names_o = [optical] + [j.parent for j in up_o]
        common = next(link for link in names_o if link in names_m)
        return [j.name for j in up_m[:names_m.index(common)]] + \
            [j.name for j in reversed(up_o[:names_o.index(common)])]


def read_camera_offset(path, mount: str, optical: str,
                       argument_names: dict | None = None) -> np.ndarray:
    """X_{mount,optical} from a camera URDF/xacro file (see ``CameraDescription.offset``)."""
    return CameraDescription(path, argument_names).offset(mount, optical)


# ------------------------------------------------------------------------------------- xacro
def _local(tag) -> str:
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def _is_xacro(tag) -> bool:
    return isinstance(tag, str) and tag.startswith("{") and "xacro" in tag.split("}", 1)[0]


def _attr(e, name: str, where: str) -> str:
    v = e.get(name)
    if v is None:
        raise ValueError(f"{where} has no {name}=")
    return v


def _vector(text: str, where: str) -> np.ndarray:
    try:
        v = np.array([float(s) for s in text.split()], dtype=float)
    except ValueError:
        raise ValueError(f"{where}: expected 3 numbers, got {text!r}") from None
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{where}: expected 3 finite numbers, got {text!r}")
    return v


def _rotation_from_rpy(rpy) -> np.ndarray:
    from .exports import rotation_from_rpy
    return rotation_from_rpy(rpy)


class _Xacro:
    """``${...}`` substitution of a plain xacro file (properties evaluated lazily, so a property
    may use one defined after it). Refuses every other xacro construct."""

    def __init__(self, root, where: str):
        self.where = where
        self.raw: dict[str, str] = {}
        self.values: dict[str, object] = {}
        self.busy: set[str] = set()
        for e in root.iter():
            if "$(" in " ".join(e.attrib.values()):
                raise ValueError(f"{where}: uses $(...) substitution args "
                                 f"({next(v for v in e.attrib.values() if '$(' in v)!r}), "
                                 "which need ROS; expand it with `xacro FILE > camera.urdf` "
                                 "and pass that")
            if not _is_xacro(e.tag):
                continue
            tag = _local(e.tag)
            if tag != "property":
                raise ValueError(f"{where}: <xacro:{tag}> is not supported (only "
                                 "xacro:property and ${...} arithmetic); expand it with "
                                 "`xacro FILE > camera.urdf` and pass that")
            name, value = e.get("name"), e.get("value")
            if name is None or value is None:
                raise ValueError(f"{where}: <xacro:property> needs name= and value= (block "
                                 "properties are not supported)")
            self.raw[name] = value

    def __call__(self, text: str) -> str:
        if "${" not in text:
            return text
        parts = _EXPR.split(text)
        out = []
        for k, part in enumerate(parts):
            if k % 2 == 0:
                if "${" in part:
                    raise ValueError(f"{self.where}: cannot evaluate {text!r} (unbalanced "
                                     "${...})")
                out.append(part)
            else:
                out.append(_format(self._eval(part, text)))
        return "".join(out)

    def _property(self, name: str, text: str):
        if name in self.values:
            return self.values[name]
        if name not in self.raw:
            if name in _CONSTANTS:
                return _CONSTANTS[name]
            raise ValueError(f"{self.where}: cannot evaluate {text!r}: no property {name!r}")
        if name in self.busy:
            raise ValueError(f"{self.where}: property {name!r} refers to itself")
        self.busy.add(name)
        raw = self.raw[name]
        m = _EXPR.fullmatch(raw.strip())
        if m:
            value = self._eval(m.group(1), raw)
        else:
            expanded = self(raw)
            try:
                value = float(expanded)
            except ValueError:
                value = expanded
        self.busy.discard(name)
        self.values[name] = value
        return value

    def _eval(self, expr: str, text: str):
        try:
            tree = ast.parse(expr.strip(), mode="eval")
        except SyntaxError:
            raise ValueError(f"{self.where}: cannot evaluate {text!r} (not an expression of "
                             "numbers, properties, pi and + - * / **)") from None
        try:
            return self._node(tree.body, text)
        except (TypeError, ZeroDivisionError, OverflowError) as e:
            raise ValueError(f"{self.where}: cannot evaluate {text!r} ({e})") from None

    def _number(self, n, text):
        value = self._node(n, text)
        if not _is_number(value):
            raise ValueError(f"{self.where}: cannot evaluate {text!r} (arithmetic on "
                             f"{value!r}, not a number)")
        return value

    def _node(self, n, text):
        if isinstance(n, ast.Constant) and isinstance(n.value, (int, float)) \
                and not isinstance(n.value, bool):
            return n.value
        if isinstance(n, ast.Constant) and isinstance(n.value, str):
            return n.value
        if isinstance(n, ast.Name):
            return self._property(n.id, text)
        if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) \
                and n.value.id == "math" and (n.attr in _CONSTANTS or n.attr in _FUNCTIONS):
            return _CONSTANTS.get(n.attr, _FUNCTIONS.get(n.attr))
        if isinstance(n, ast.BinOp) and type(n.op) in _BINARY:
            # Numbers only, and powers in floats: bounded time and memory (an int 9**9**9 or a
            # string repeated 10**9 times would not be); an overflow or a complex power is
            # refused.
            a, b = self._number(n.left, text), self._number(n.right, text)
            if isinstance(n.op, ast.Pow):
                a, b = float(a), float(b)
            value = _BINARY[type(n.op)](a, b)
            if not _is_number(value):
                raise ValueError(f"{self.where}: cannot evaluate {text!r} (not a real number)")
            return value
        if isinstance(n, ast.UnaryOp) and type(n.op) in _UNARY:
            return _UNARY[type(n.op)](self._number(n.operand, text))
        if isinstance(n, ast.Call) and not n.keywords:
            f = n.func
            fn = None
            if isinstance(f, ast.Name) and f.id in _FUNCTIONS:
                fn = _FUNCTIONS[f.id]
            elif isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) \
                    and f.value.id == "math" and f.attr in _FUNCTIONS:
                fn = _FUNCTIONS[f.attr]
            if fn is not None:
                args = [self._number(a, text) for a in n.args]
                try:
                    return fn(*args)
                except ValueError as e:  # math's domain errors: sqrt(-1), log(0), ...
                    raise ValueError(f"{self.where}: cannot evaluate {text!r} ({e})") from None
        raise ValueError(f"{self.where}: cannot evaluate {text!r} (only numbers, properties, "
                         "pi, + - * / ** % and math functions)")


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _format(value) -> str:
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        return str(value)
    if isinstance(value, str):
        return value
    return repr(float(value)) if isinstance(value, float) else str(value)


__all__ = ["CameraDescription", "Joint", "read_camera_offset"]

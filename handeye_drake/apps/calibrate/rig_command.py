"""``handeye-drake calibrate`` of a multi-camera rig (``calibration.rig``):

    handeye-drake calibrate --robot FILE --target SPEC \\
        --camera wrist:DIR[:hand|cell[:INTRINSICS]] --camera cell:DIR:cell:cell.yaml ...
    handeye-drake calibrate --robot FILE --board table:SPEC[:cell|hand] --board side:SPEC2 \\
        --camera wrist:DIR --camera cell:DIR:cell:cell.yaml ...
    handeye-drake calibrate --rig rig.yaml
    handeye-drake calibrate --bag PATH --robot-frames base_link:tool0 --target SPEC \\
        --camera wrist:/wrist/image_raw:hand --camera cell:/cell/image_raw:cell

Image k of every camera pairs with robot pose k; from a bag, each camera's images pair with the
robot's tf in time (its clock offset estimated, as ``--bag --image-topic``). ``--board-mount``
says where the board is (cell: X_BT, default; hand: X_ET). Several boards: ``--board
NAME:SPEC[:cell|hand]``, repeated, instead of ``--target`` (the mount, last, cannot be read as a
field of a spec). A rig YAML holds the same (paths relative to the file; several boards as
``boards: {NAME: {target: SPEC, mount: cell}, …}`` instead of ``target`` and ``board``, and a
camera's ``boards: [NAME, …]`` limits the boards it looks for)::

    robot: robot_poses.tum
    target: charuco:7x5:0.04:0.03:DICT_5X5_100
    board: cell
    cameras:
      wrist: {images: wrist, mount: hand, intrinsics: wrist/intrinsics.yaml}
      cell: {images: cell, mount: cell, intrinsics: cell/intrinsics.yaml}

Writes ``calibration.json`` (the rig: verdict, board, camera-to-camera transforms, every
camera), ``report.txt``, and per camera ``NAME/calibration.json`` and with ``--export`` its frame
(``NAME/handeye.urdf``, … : one frame per camera, ``NAME_optical_frame``).
"""

from __future__ import annotations

import json
from pathlib import Path

from ...calibration.rig import RigBoard, RigCamera, calibrate_rig, check_boards

#: Largest rig YAML read (bytes): a rig of many cameras is a few kB.
_MAX_RIG_BYTES = 1_000_000
_RIG_KEYS = ("robot", "target", "board", "boards", "cameras")
_CAMERA_KEYS = ("images", "mount", "intrinsics", "boards")
_BOARD_KEYS = ("target", "mount")


def _unique_key_loader():
    import yaml

    class Loader(yaml.SafeLoader):
        """A safe loader that refuses a key given twice (YAML keeps the last one silently: two
        cameras of one name would be one camera)."""

    def mapping(loader, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = loader.construct_object(key_node, deep=deep)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"key {key!r} given twice", key_node.start_mark)
            seen.add(key)
        return loader.construct_mapping(node, deep=deep)

    Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, mapping)
    return Loader


def check_rig_camera(cam: RigCamera, where: str) -> None:
    """Bad input as an error naming ``where`` before any fit: a camera folder without images, an
    intrinsics file that does not exist or does not read (they would become a FAIL verdict)."""
    from ...calibration.inputs import image_paths
    from ...vision.intrinsics import load_intrinsics
    if cam.topic is None:
        try:
            image_paths(cam.images)
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None
    else:
        from ...recorded.bags import (COMPRESSED_IMAGE_TYPE, IMAGE_TYPE, bag_topics,
                                      require_topic)
        try:
            require_topic(str(cam.images), bag_topics(cam.images), cam.topic,
                          (IMAGE_TYPE, COMPRESSED_IMAGE_TYPE), "image topic")
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None
    intr = cam.intrinsics
    if isinstance(intr, (str, Path)):
        text = str(intr).strip()
        try:
            if Path(text).is_file():
                load_intrinsics(text)
            elif "," not in text or "/" in text or Path(text).suffix.lower() in (
                    ".yaml", ".yml", ".xml"):
                load_intrinsics(text)  # raises: no such file, and not a spec
        except ValueError as e:
            if Path(text).is_file() and "no image width" in str(e):
                return  # a file without the image size: taken from the images later
            raise ValueError(f"{where}: {e}") from None




def is_rig_camera(text: str) -> bool:
    """``--camera`` names a rig camera (NAME:DIR…) rather than a camera pose file: a name before
    the first colon and no file of that whole name."""
    name, sep, rest = str(text).partition(":")
    if not (sep and name and rest) or Path(text).is_file():
        return False
    # The names RigCamera takes (unicode letters too, as in a rig YAML); a name it refuses
    # before an existing folder is a rig camera with a bad name, said so by RigCamera.
    return (name.replace("_", "").replace("-", "").isalnum()
            or Path(rest.split(":")[0]).is_dir())


def parse_rig_camera(text: str, bag=None) -> RigCamera:
    """``NAME:DIR[:MOUNT[:INTRINSICS]]`` → ``RigCamera`` (ValueError naming ``--camera``); with
    ``bag``, ``NAME:TOPIC[:MOUNT[:INTRINSICS]]`` (the camera's image topic in the bag)."""
    parts = str(text).split(":")
    name, folder = parts[0], parts[1] if len(parts) > 1 else ""
    mount = parts[2] if len(parts) > 2 and parts[2] else "hand"
    intrinsics = ":".join(parts[3:]) or None
    if not folder:
        raise ValueError(f"--camera {text}: expected NAME:{'TOPIC' if bag else 'DIR'}"
                         "[:hand|cell[:INTRINSICS]]")
    if bag is None and not Path(folder).exists():
        raise ValueError(f"--camera {text}: {folder} not found")
    try:
        if bag is not None:
            cam = RigCamera(name, bag, mount, intrinsics, topic=folder)
        else:
            cam = RigCamera(name, folder, mount, intrinsics)
    except ValueError as e:
        raise ValueError(f"--camera {text}: {e}") from None
    check_rig_camera(cam, f"--camera {text}")
    return cam


def parse_rig_board(text: str) -> RigBoard:
    """``NAME:SPEC[:cell|hand]`` → ``RigBoard`` (ValueError naming ``--board``). The mount is
    the last field when it reads ``cell`` or ``hand`` — no target spec ends so (their last
    fields are numbers, ``legacy``, ``white`` or ``black``)."""
    from ...vision.targets import SPEC_FORMS
    form = "expected NAME:SPEC[:cell|hand], e.g. table:charuco:7x5:0.04:0.03:DICT_5X5_100:cell"
    name, sep, rest = str(text).partition(":")
    if not sep or not rest:
        raise ValueError(f"--board {text}: {form}")
    if name.strip().lower() in SPEC_FORMS:
        raise ValueError(f"--board {text}: the board's name comes first ({form})")
    spec, mount = rest, "cell"
    head, sep, last = rest.rpartition(":")
    if sep and last.strip().lower() in ("cell", "hand"):
        spec, mount = head, last.strip().lower()
    try:
        return RigBoard(name, spec, mount)
    except ValueError as e:
        if sep and mount == "cell" and spec == rest:
            try:
                RigBoard(name, head, "cell")
            except ValueError:
                pass
            else:   # the spec without its last field reads: that field was meant as the mount
                raise ValueError(f"--board {text}: mount {last!r}: expected cell or hand") \
                    from None
        raise ValueError(f"--board {text}: {e}") from None


def read_rig_yaml(path) -> dict:
    """{"robot", "target", "board", "boards": [RigBoard] | None, "cameras": [RigCamera]} of a
    rig YAML (module docstring)."""
    import yaml
    p = Path(path)
    if p.is_dir():
        raise ValueError(f"--rig {path}: a folder; expected the rig's YAML file")
    if p.is_file() and p.stat().st_size > _MAX_RIG_BYTES:
        raise ValueError(f"--rig {path}: larger than {_MAX_RIG_BYTES} bytes; not a rig YAML")
    try:
        doc = yaml.load(p.read_text(encoding="utf-8"), Loader=_unique_key_loader())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as e:
        raise ValueError(f"--rig {path}: {' '.join(str(e).split())}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("cameras"), dict) or not doc["cameras"]:
        raise ValueError(f"--rig {path}: expected a mapping with 'cameras: {{NAME: {{images: "
                         "DIR, mount: hand|cell, intrinsics: FILE}}'")
    # A misspelt key (bord:, intrinsic:) would silently fall back to a default.
    unknown = sorted(str(k) for k in doc if k not in _RIG_KEYS)
    if unknown:
        raise ValueError(f"--rig {path}: unknown key {', '.join(map(repr, unknown))} (expected "
                         f"{', '.join(_RIG_KEYS)})")
    for key in ("robot", "target", "board"):
        if doc.get(key) is not None and not isinstance(doc[key], str):
            raise ValueError(f"--rig {path}: {key}: expected a string, got {doc[key]!r}")
    boards = None
    if doc.get("boards") is not None:
        if doc.get("target") is not None or doc.get("board") is not None:
            raise ValueError(f"--rig {path}: give either target (and board) or boards, not both")
        if not isinstance(doc["boards"], dict) or not doc["boards"]:
            raise ValueError(f"--rig {path}: boards: expected {{NAME: {{target: SPEC, mount: "
                             "cell|hand}}, …}}")
        boards = []
        for name, b in doc["boards"].items():
            if isinstance(b, str):
                b = {"target": b}
            if not isinstance(b, dict) or "target" not in b:
                raise ValueError(f"--rig {path}: board {name}: expected {{target: SPEC, mount: "
                                 "cell|hand}}")
            unknown = sorted(str(k) for k in b if k not in _BOARD_KEYS)
            if unknown:
                raise ValueError(f"--rig {path}: board {name}: unknown key "
                                 f"{', '.join(map(repr, unknown))} (expected "
                                 f"{', '.join(_BOARD_KEYS)})")
            try:
                boards.append(RigBoard(str(name), b["target"], b.get("mount", "cell")))
            except ValueError as e:
                raise ValueError(f"--rig {path}: {e}") from None
        try:
            check_boards(boards)
        except ValueError as e:
            raise ValueError(f"--rig {path}: {e}") from None
    base = p.parent

    def rel(v):
        return None if v is None else str(base / str(v)) if not Path(str(v)).is_absolute() \
            else str(v)

    cams = []
    for name, c in doc["cameras"].items():
        if not isinstance(c, dict) or "images" not in c:
            raise ValueError(f"--rig {path}: camera {name}: expected {{images: DIR, …}}")
        unknown = sorted(str(k) for k in c if k not in _CAMERA_KEYS)
        if unknown:
            raise ValueError(f"--rig {path}: camera {name}: unknown key "
                             f"{', '.join(map(repr, unknown))} (expected "
                             f"{', '.join(_CAMERA_KEYS)})")
        intr = c.get("intrinsics")
        if intr is not None and not Path(rel(intr)).exists():
            intr_arg = str(intr)              # an inline spec (fx,fy,cx,cy,…)
        else:
            intr_arg = rel(intr)
        try:
            seen = c.get("boards")
            cams.append(RigCamera(str(name), rel(c["images"]), c.get("mount", "hand"), intr_arg,
                                  boards=[str(v) for v in seen] if isinstance(seen, list)
                                  else seen))
        except ValueError as e:
            raise ValueError(f"--rig {path}: {e}") from None
        check_rig_camera(cams[-1], f"--rig {path}: camera {name}")
    names = [b.name for b in boards or []]
    for cam in cams:
        unknown = [b for b in cam.boards or () if b not in names]
        if unknown:
            raise ValueError(f"--rig {path}: camera {cam.name}: boards: {', '.join(unknown)} "
                             f"not among the boards ({', '.join(names) or 'none: give boards:'})")
    return {"robot": rel(doc.get("robot")), "target": doc.get("target"),
            "board": doc.get("board"), "boards": boards, "cameras": cams}


def run_rig_command(args, rig_cameras, options) -> int:
    """The rig calibration of parsed arguments (``command.run_calibrate_command`` hands over
    when ``--camera NAME:DIR`` or ``--rig`` is given)."""
    from ..outputs import prepare_output_dir
    robot, target, board = args.robot, args.target, getattr(args, "board_mount", None)
    given = list(getattr(args, "boards", None) or [])
    if given and target:
        raise ValueError(f"--board {given[0]}: give several boards as --board NAME:SPEC[:MOUNT] "
                         "or one as --target SPEC, not both")
    if given and board:
        raise ValueError(f"--board-mount: with --board, each board's mount is given in it "
                         f"(--board NAME:SPEC:{board})")
    boards = [parse_rig_board(t) for t in given] or None
    if boards:
        try:
            check_boards(boards)
        except ValueError as e:
            raise ValueError(f"--board: {str(e).removeprefix('boards: ')}") from None
    cams = [parse_rig_camera(t, args.bag) for t in rig_cameras]
    if getattr(args, "rig", None):
        doc = read_rig_yaml(args.rig)
        cams += doc["cameras"]
        robot = robot or doc["robot"]
        if not (boards or target):
            boards, target, board = doc["boards"], doc["target"], board or doc["board"]
    board = board or "cell"
    if not robot and not args.bag:
        raise ValueError("--robot: the robot poses (X_BE) are needed with a rig of image "
                         "folders")
    names = [b.name for b in boards or []]
    for c in cams:
        unknown = [b for b in c.boards or () if b not in names]
        if unknown:
            raise ValueError(f"--rig: camera {c.name} looks for board {', '.join(unknown)}, "
                             f"not among the boards given ({', '.join(names) or 'one --target'})")
    if boards:
        target = boards
    elif not target:
        raise ValueError("--target: the calibration target is needed with a rig (e.g. "
                         "charuco:7x5:0.04:0.03:DICT_5X5_100)")
    if board not in ("cell", "hand"):
        raise ValueError(f"--board-mount: expected cell or hand, got {board!r}")
    if not boards:
        try:
            RigBoard("board", target, board)
        except ValueError as e:
            raise ValueError(f"--target {target}: {str(e).removeprefix('board board: ')}") \
                from None
    if args.images:
        raise ValueError("--camera NAME:DIR: a rig takes its images from each camera's "
                         "directory; leave out --images")
    names = [c.name for c in cams]
    if len(set(names)) != len(names):
        raise ValueError(f"--camera: camera names must differ, got {', '.join(names)}")
    # Two cameras cannot take the same images: one source given twice is a typo.
    sources = {}
    for c in cams:
        key = (str(Path(c.images).resolve()), c.topic)
        if key in sources:
            raise ValueError(f"--camera: cameras {sources[key]} and {c.name} read the same "
                             f"{'topic ' + c.topic if c.topic else 'images ' + str(c.images)}")
        sources[key] = c.name
    out = prepare_output_dir(args.out, "calibrate", args.force)
    result = calibrate_rig(cams, robot, target, board, options,
                           robot_frames=args.robot_frames)
    written = []
    p = out.path("calibration.json")
    p.write_text(json.dumps(result.to_json(), indent=1) + "\n")
    written.append(p)
    lines = result.lines()
    p = out.path("report.txt")
    p.write_text("\n".join(lines) + "\n")
    written.append(p)
    doc = result.to_json()
    for name, cam in result.cameras.items():
        p = out.path(f"{name}/calibration.json")
        p.write_text(json.dumps({"camera": name, **doc["cameras"][name],
                                 "rig_verdict": doc["rig"]["verdict"]}, indent=1) + "\n")
        written.append(p)
        if args.export and cam.verdict.status != "FAIL" and cam.X is not None:
            for fname, text in result.export(name, args.export, args.parent_frame).items():
                q = out.path(f"{name}/{fname}")
                q.write_text(text)
                if q.suffix == ".sh":
                    q.chmod(0o755)
                written.append(q)
    out.finish(written)
    print("\n".join(lines))
    if args.export and result.verdict.status == "FAIL":
        print("no export of the cameras that FAIL")
    print("wrote: " + ", ".join(str(w) for w in written[:12])
          + (f", … ({len(written) - 12} more)" if len(written) > 12 else ""))
    status = result.verdict.status
    return 1 if status == "FAIL" or (status == "WARN" and args.strict) else 0


__all__ = ["is_rig_camera", "parse_rig_board", "parse_rig_camera", "read_rig_yaml",
           "run_rig_command"]

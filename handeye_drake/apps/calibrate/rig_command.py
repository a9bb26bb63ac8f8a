"""``handeye-drake calibrate`` of a multi-camera rig (``calibration.rig``):

    handeye-drake calibrate --robot FILE --target SPEC \\
        --camera wrist:DIR[:hand|cell[:INTRINSICS]] --camera cell:DIR:cell:cell.yaml ...
    handeye-drake calibrate --robot FILE --board table:SPEC[:cell|hand] --board side:SPEC2 \\
        --camera wrist:DIR --camera cell:DIR:cell:cell.yaml ...
    handeye-drake calibrate --rig rig.yaml
    handeye-drake calibrate --bag PATH --robot-frames base_link:tool0 --target SPEC \\
        --camera wrist:/wrist/image_raw:hand --camera cell:/cell/image_raw:cell

Image k of every camera pairs with robot pose k, or in time when every image has a stamp (file
names, a stamps file: ``--pairing``, docs/multi-camera.md); from a bag, each camera's images pair with the
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
      cell: {images: cell, mount: cell, intrinsics: cell/intrinsics.yaml, time_offset: 0.03}

(``time_offset``, images paired in time: that camera's clock offset in s, else estimated.) Writes ``calibration.json`` (the rig: verdict, board, camera-to-camera transforms, every
camera), ``report.txt``, and per camera ``NAME/calibration.json`` and with ``--export`` its frame
(``NAME/handeye.urdf``, … : one frame per camera, ``NAME_optical_frame``).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from ...calibration.rig import RigBoard, RigCamera, calibrate_rig, check_boards

#: Largest rig YAML read (bytes): a rig of many cameras is a few kB.
_MAX_RIG_BYTES = 1_000_000
_RIG_KEYS = ("robot", "target", "board", "boards", "cameras")
_CAMERA_KEYS = ("images", "mount", "intrinsics", "time_offset", "boards")
_BOARD_KEYS = ("target", "mount")


def _is(path, test: str = "exists") -> bool:
    """``Path(path).exists()`` / ``is_file()`` / ``is_dir()``, a name the system refuses (too
    long, a NUL) being not there rather than an OSError."""
    try:
        return getattr(Path(path), test)()
    except (OSError, ValueError):
        return False


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
    """Bad input as an error naming ``where`` before any fit: a camera folder that is not a
    folder or holds no images, an intrinsics file or string that does not read (they would
    become a FAIL verdict)."""
    from ...calibration.inputs import image_paths
    from ...vision.intrinsics import load_intrinsics
    if cam.topic is None:
        if not _is(cam.images, "is_dir"):
            raise ValueError(f"{where}: {cam.images} is not a folder; expected the folder of "
                             "the camera's images")
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
    if isinstance(cam.intrinsics, (str, Path)):
        try:
            load_intrinsics(str(cam.intrinsics).strip())
        except (ValueError, OSError) as e:
            # A file or fx,fy,cx,cy string without the image size: taken from the images later.
            if "no image width" not in str(e):
                raise ValueError(f"{where}: {e}") from None


def check_rig_images(cam: RigCamera, where: str, poses: int) -> None:
    """A camera folder against the robot file (image k pairs with pose k): as many images as
    poses, all of one size (read from their headers), the size of the given intrinsics."""
    from ...calibration.inputs import _file_kind, image_paths
    from ...vision.image_files import image_size
    from ...vision.intrinsics import load_intrinsics
    paths = image_paths(cam.images)
    if poses is not None and len(paths) != poses:
        raise ValueError(f"{where}: {len(paths)} images but {poses} robot poses; image k pairs "
                         "with robot pose k, one each")
    sizes = {}
    for q in paths:
        try:
            if not _file_kind(q):   # a FIFO or device is never opened
                with open(q, "rb") as f:
                    size = image_size(f.read(1 << 16))
                if size is not None:
                    sizes.setdefault(tuple(size), q.name)
        except OSError:
            pass                    # unreadable: skipped with its reason by the reader
    if len(sizes) > 1:
        (a, qa), (b, qb) = list(sizes.items())[:2]
        raise ValueError(f"{where}: images of different sizes ({qa} {a[0]}×{a[1]}, {qb} "
                         f"{b[0]}×{b[1]}); one camera's images have one size — two cameras' "
                         "images mixed?")
    if sizes and isinstance(cam.intrinsics, (str, Path)):
        (w, h), first = next(iter(sizes.items()))
        try:
            intr = load_intrinsics(str(cam.intrinsics).strip())
        except (ValueError, OSError):
            return                  # no image size in them (checked by check_rig_camera)
        if (intr.width, intr.height) != (w, h):
            raise ValueError(f"{where}: the intrinsics are for {intr.width}×{intr.height} "
                             f"images, the camera's are {w}×{h} ({first})")


def is_rig_camera(text: str) -> bool:
    """``--camera`` names a rig camera (NAME:DIR…) rather than a camera pose file: a name before
    the first colon and no file of that whole name."""
    name, sep, rest = str(text).partition(":")
    if not sep or _is(text, "is_file"):
        return False
    # The names RigCamera takes (unicode letters too, as in a rig YAML); a name it refuses
    # before an existing folder is a rig camera with a bad name, said so by RigCamera (and a
    # name without its folder, "wrist:", by parse_rig_camera).
    folder = rest.split(":")[0]
    return (name.replace("_", "").replace("-", "").isalnum()
            or (folder != "" and _is(folder, "is_dir")))


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
    if bag is None and not _is(folder, "exists"):
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
        if name is None or isinstance(name, bool):
            # YAML reads ~, null, yes, no, true as these: a camera silently named "None".
            raise ValueError(f"--rig {path}: camera name {name!r}: expected letters, digits, _ "
                             "or - (quote it)")
        for key in ("images", "mount", "intrinsics"):   # time_offset, boards: checked below
            if c.get(key) is not None and not isinstance(c[key], str):
                raise ValueError(f"--rig {path}: camera {name}: {key}: expected a string, got "
                                 f"{c[key]!r:.80}")
        unknown = sorted(str(k) for k in c if k not in _CAMERA_KEYS)
        if unknown:
            raise ValueError(f"--rig {path}: camera {name}: unknown key "
                             f"{', '.join(map(repr, unknown))} (expected "
                             f"{', '.join(_CAMERA_KEYS)})")
        intr = c.get("intrinsics")
        if intr is not None and not _is(rel(intr), "exists"):
            intr_arg = str(intr)              # an inline spec (fx,fy,cx,cy,…)
        else:
            intr_arg = rel(intr)
        try:
            seen = c.get("boards")
            cams.append(RigCamera(str(name), rel(c["images"]), c.get("mount", "hand"), intr_arg,
                                  time_offset=c.get("time_offset"),
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


def _robot_poses(robot) -> int:
    """The number of poses in the robot file (its errors named ``--robot``)."""
    from ...recorded.formats import infer_format, read_poses
    try:
        if _is(robot, "is_dir"):
            raise ValueError("a folder; expected the robot pose file")
        return len(read_poses(robot, "robot", infer_format(robot)))
    except ValueError as e:
        text = str(e)
        raise ValueError(text if text.startswith("--robot") else f"--robot {text}"
                         if text.startswith(f"{robot}:") else f"--robot {robot}: {text}") from None


def _check_free(out, names) -> None:
    """Every file the rig writes, checked before the fit as ``OutputDir.path`` checks it when
    writing (else a user's file is found only after the fit, half the outputs written)."""
    for name in names:
        p = out.root / name
        for q in reversed(p.parents[:len(Path(name).parts) - 1]):
            if q.is_symlink() or (os.path.lexists(q) and not q.is_dir()):
                raise ValueError(f"--out {out.root}: {q.relative_to(out.root)} exists and is not "
                                 f"a directory; the rig writes {name} there — not touching it "
                                 "(choose another --out)")
        if p.is_symlink() or p.is_dir() or (os.path.lexists(p) and name not in out.earlier):
            raise ValueError(f"--out {out.root}: {name} exists and was not written by "
                             "'handeye-drake calibrate'; not overwriting it (choose another --out)")


def _named(error: ValueError, where: dict) -> str:
    """A library error "camera NAME: …" with the argument that gave camera NAME."""
    text = str(error)
    for name, arg in where.items():
        if text.startswith(f"camera {name}: "):
            rest = text[len(f"camera {name}: "):]
            if "robot_frames:" in rest:
                return f"--robot-frames: {rest}"
            return f"{arg}: {rest}"
    return text


def run_rig_command(args, rig_cameras, options) -> int:
    """The rig calibration of parsed arguments (``command.run_calibrate_command`` hands over
    when ``--camera NAME:DIR`` or ``--rig`` is given)."""
    from ..outputs import prepare_output_dir
    robot, target, board = args.robot, args.target, getattr(args, "board_mount", None)
    rig = getattr(args, "rig", None)
    if rig is not None and not str(rig).strip():
        raise ValueError("--rig: empty; expected the rig's YAML file")
    if rig and rig_cameras:
        raise ValueError(f"--camera {rig_cameras[0]}: the rig's cameras are in --rig {rig}; "
                         "give them in one place")
    if rig and args.bag:
        raise ValueError(f"--bag: a rig YAML (--rig {rig}) reads image folders; for a bag give "
                         "--camera NAME:TOPIC[:MOUNT] per camera")
    if args.bag and robot:
        raise ValueError("--robot: not read with --bag; the robot's poses are the bag's tf "
                         "(--robot-frames BASE:EE)")
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
    where = {c.name: f"--camera {t}" for c, t in zip(cams, rig_cameras)}
    if rig:
        doc = read_rig_yaml(rig)
        cams += doc["cameras"]
        where = {c.name: f"--rig {rig}: camera {c.name}" for c in cams}
        # Given on the command line and in the file: which one holds is not to be guessed.
        for option, given, key in (("--robot", robot, "robot"), ("--target", target, "target"),
                                   ("--board-mount", board, "board")):
            mine = doc.get(key)
            if given and mine and (Path(given).resolve() != Path(mine).resolve()
                                   if key == "robot" else given != mine):
                raise ValueError(f"{option} {given}: --rig {rig} gives {key}: {mine}; give it "
                                 "in one place")
        robot = robot or doc["robot"]
        if not (boards or target):
            boards, target, board = doc["boards"], doc["target"], board or doc["board"]
        board = board or doc.get("board")
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
        raise ValueError(f"{'--board-mount' if args.board_mount else f'--rig {rig}: board'}: "
                         f"expected cell or hand, got {board!r}")
    if not boards:
        try:
            RigBoard("board", target, board)
        except ValueError as e:
            raise ValueError(f"--target {target}: {str(e).removeprefix('board board: ')}") \
                from None
    if args.images:
        raise ValueError("--images: a rig takes its images from each camera's folder "
                         "(--camera NAME:DIR or --rig); leave out --images")
    names = [c.name for c in cams]
    who = f"--rig {rig}" if rig else "--camera"
    if len(set(names)) != len(names):
        raise ValueError(f"{who}: camera names must differ, got {', '.join(names)}")
    # Two cameras cannot take the same images: one source given twice is a typo.
    sources = {}
    for c in cams:
        key = (str(Path(c.images).resolve()), c.topic)
        if key in sources:
            raise ValueError(f"{who}: cameras {sources[key]} and {c.name} read the same "
                             f"{'topic ' + c.topic if c.topic else 'images ' + str(c.images)}")
        sources[key] = c.name
    if not boards and all(c.mount == board for c in cams):
        raise ValueError(f"{who}: every camera is on the board's mount ({board}): each sees one "
                         "fixed view, nothing places the board; a rig needs a camera on the "
                         f"other mount (or --board-mount {'hand' if board == 'cell' else 'cell'}"
                         " if the board is there)")
    if args.parent_frame is not None:
        from ...recorded.exports import _check_name
        _check_name(args.parent_frame, "--parent-frame")
        if len({c.mount for c in cams}) > 1:
            raise ValueError(f"--parent-frame {args.parent_frame}: one parent for cameras on "
                             "the hand and in the cell; their frames hang from different links")
    if not boards:
        from ...vision.targets import parse_target
        try:
            parse_target(target)
        except ValueError as e:
            raise ValueError(f"--target {target}: {e}") from None
    if not args.bag:
        poses = _robot_poses(robot)
        for c in cams:
            # Paired in time (or may be: auto), counts need not match; the pairing says.
            check_rig_images(c, where[c.name], poses if getattr(args, "pairing", "auto") ==
                             "index" else None)
    if args.export:
        from ...recorded.exports import _check_name
        for c in cams:   # the exports' frame NAME_optical_frame, refused before the fit
            _check_name(f"{c.name}_optical_frame", f"{where[c.name]}: camera name")
    out = prepare_output_dir(args.out, "calibrate", args.force)
    from ...recorded.exports import FILE_NAMES, parse_formats
    files = [f for fmt in parse_formats(args.export) for f in FILE_NAMES[fmt]] \
        if args.export else []
    _check_free(out, ["calibration.json", "report.txt"] + [
        f"{c.name}/{f}" for c in cams for f in ["calibration.json"] + files])
    try:
        result = calibrate_rig(cams, robot, target, board, options,
                               robot_frames=args.robot_frames,
                               pairing=getattr(args, "pairing", "auto"))
    except ValueError as e:
        raise ValueError(_named(e, where)) from None
    base, ee = (args.robot_frames.split(":") + [""])[:2] if args.bag else (None, None)
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
            # From a bag the parent is the robot's own frame (--robot-frames), not tool0.
            parent = args.parent_frame or ((ee if cam.mount == "hand" else base) or None)
            for fname, text in result.export(name, args.export, parent).items():
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

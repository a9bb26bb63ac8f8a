"""Where the commands write, and what they may overwrite.

Policy, the same for every command (``simulate``, ``calibrate``, ``reproduce``, ...):

- ``--out DIR`` must be a directory or not exist. It is checked — with every other output path —
  before any computing starts, so a bad path never costs a run.
- A new or empty directory is used as is. A directory holding this command's earlier output
  (its ``.handeye-drake-output.json`` manifest names the command) is reused: the files the new run
  writes replace the old ones, and the files of the earlier run that the new one does not write
  again are removed, so no stale result sits beside fresh ones. Only a file inside ``--out``
  (no ``..``, no absolute path, no symbolic link on the way), recorded in the manifest with its
  SHA-256 and unchanged since, is ever removed: a hand-edited or copied manifest cannot make a
  run delete anything else.
- Any other non-empty directory is refused unless ``--force`` is given; even then, no file the
  tool did not write is ever deleted or overwritten (a file of the same name is refused).
- Files outside ``--out`` given explicitly (``--meshcat-html FILE``, ``--json FILE``) are written
  only if they do not exist, unless ``--force``.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

MANIFEST = ".handeye-drake-output.json"
#: Directories this process created for its outputs, outermost first (``remove_empty_created``).
_CREATED: list = []


def _manifest(path: Path) -> dict | None:
    try:
        data = json.loads((path / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) and isinstance(data.get("files"), list) else None


def _sha256(path: Path) -> str | None:
    try:
        h = hashlib.sha256()
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
        return h.hexdigest()
    except OSError:
        return None


def _inside(root: Path, name) -> Path | None:
    """``root / name`` when ``name`` is a relative path that stays inside ``root`` with no
    symbolic link on the way (a manifest's entry); else None."""
    if not isinstance(name, str) or not name or "\0" in name:
        return None
    rel = Path(name)
    if rel.is_absolute() or rel.drive or any(part in ("..", "") for part in rel.parts):
        return None
    p = root
    for part in rel.parts:
        p = p / part
        if p.is_symlink():
            return None
    try:
        if not p.resolve().is_relative_to(root.resolve()):
            return None
    except (OSError, RuntimeError):
        return None
    return p


@dataclass
class OutputDir:
    """An output directory claimed by one command run (see the module docstring).

    ``prepare_output_dir`` creates it; ``path(name)`` gives a file path inside it (refusing names
    that belong to someone else); ``finish(written)`` writes the manifest and removes the earlier
    run's files that were not written again.
    """
    root: Path
    command: str
    force: bool = False
    earlier: list = field(default_factory=list)
    claimed: set = field(default_factory=set)
    hashes: dict = field(default_factory=dict)  # earlier files' SHA-256 from the manifest

    def path(self, name: str) -> Path:
        p = self.root / name
        if p.exists() and name not in self.earlier and name not in self.claimed \
                and not p.is_dir():
            raise ValueError(f"--out {self.root}: {name} exists and was not written by "
                             f"'handeye-drake {self.command}'; not overwriting it (choose another "
                             "--out)")
        # A folder of the name that is a file (someone's "detections" file): refused by name,
        # never replaced, never a traceback from mkdir.
        q = self.root
        for part in Path(name).parts[:-1]:
            q = q / part
            if q.is_symlink() or (os.path.lexists(q) and not q.is_dir()):
                what = "a symbolic link" if q.is_symlink() else "not a directory"
                raise ValueError(f"--out {self.root}: {q.relative_to(self.root)} exists and is "
                                 f"{what}; 'handeye-drake {self.command}' writes {name} there "
                                 "— not touching it (choose another --out)")
        if p.is_symlink() or p.is_dir():
            raise ValueError(f"--out {self.root}: {name} exists and is "
                             f"{'a symbolic link' if p.is_symlink() else 'a directory'}; not "
                             "writing through it (choose another --out)")
        p.parent.mkdir(parents=True, exist_ok=True)
        if name not in self.claimed:
            # Claimed in the manifest before it is written: a run that stops half-way (an
            # error, Ctrl-C) leaves a directory that the next run of the command may reuse.
            self.claimed.add(name)
            self._write_manifest(sorted(set(self.earlier) | self.claimed))
        return p

    def _write_manifest(self, names, hashes=None) -> None:
        names = list(names)
        hashes = {n: h for n, h in (self.hashes if hashes is None else hashes).items()
                  if n in names and h}
        (self.root / MANIFEST).write_text(json.dumps(
            {"command": self.command, "files": names, "sha256": hashes}, indent=1) + "\n")

    def finish(self, written) -> None:
        names = sorted({str(Path(w).resolve().relative_to(self.root.resolve()))
                        for w in written if Path(w).resolve().is_relative_to(self.root.resolve())})
        for stale in set(self.earlier) - set(names):
            # Removed only when the tool wrote it (its hash is in the manifest) and nobody
            # changed it since; anything else stays where it is.
            p = _inside(self.root, stale)
            if p is not None and p.is_file() and self.hashes.get(stale) \
                    and _sha256(p) == self.hashes[stale]:
                p.unlink()
        self.hashes = {n: _sha256(self.root / n) for n in names}
        self._write_manifest(names)


def prepare_output_dir(out, command: str, force: bool = False) -> OutputDir:
    """Checks and creates ``out`` for ``command`` (raises ValueError naming ``--out``)."""
    root = Path(out)
    if root.exists() and not root.is_dir():
        raise ValueError(f"--out {out}: exists and is not a directory")
    earlier, hashes = [], {}
    if root.is_dir():
        entries = [e for e in os.listdir(root) if e != MANIFEST]
        manifest = _manifest(root)
        if manifest is not None and manifest.get("command") == command:
            # Entries that would lead outside --out (../x, /abs, a symbolic link) are not the
            # tool's output: dropped, never touched.
            earlier = [f for f in manifest["files"] if _inside(root, f) is not None]
            given = manifest.get("sha256")
            hashes = {f: h for f, h in given.items() if f in earlier and isinstance(h, str)} \
                if isinstance(given, dict) else {}
        elif entries and not force:
            owner = (f"the output of 'handeye-drake {manifest['command']}'" if manifest
                     else "not an output directory of this tool")
            raise ValueError(f"--out {out}: the directory is not empty and is {owner}; choose "
                             "an empty or new directory, or pass --force (files the tool did not "
                             "write are never overwritten or deleted)")
    missing = [p for p in [root, *root.parents] if not p.exists()]
    try:
        root.mkdir(parents=True, exist_ok=True)
        _CREATED.extend(reversed(missing))
        probe = root / ".handeye-drake-write-test"
        probe.write_text("")
        probe.unlink()
    except OSError as e:
        raise ValueError(f"--out {out}: cannot write there ({e.strerror or e})") from None
    return OutputDir(root=root, command=command, force=force, earlier=earlier, hashes=hashes)


def remove_empty_created() -> None:
    """Removes the output directories this process created that are still empty (a command that
    failed before writing anything leaves no folder behind). Only empty directories: never a
    file."""
    for d in reversed(_CREATED):
        try:
            d.rmdir()
        except OSError:
            pass
    _CREATED.clear()


def check_output_file(path, option: str, force: bool = False) -> Path:
    """An explicit output file outside ``--out``: its directory must exist and be writable, and
    the file must not exist (unless ``force``). Raises ValueError naming ``option``."""
    p = Path(path)
    if p.is_dir():
        raise ValueError(f"{option} {path}: is a directory, expected a file name")
    if p.exists() and not force:
        raise ValueError(f"{option} {path}: exists; not overwriting it (pass --force)")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise ValueError(f"{option} {path}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise ValueError(f"{option} {path}: directory {parent} is not writable")
    return p

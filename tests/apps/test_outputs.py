"""``apps.outputs``: a re-run removes its earlier run's stale files, and nothing else — never a
file outside ``--out`` (a manifest listing ``../x``, an absolute path or a path through a
symbolic link), never a file the tool did not write or that changed since."""

import json
import os

import numpy as np
import pytest

from handeye_drake.apps.outputs import MANIFEST, prepare_output_dir


def _run(out, names, command="calibrate"):
    d = prepare_output_dir(out, command)
    written = []
    for n in names:
        p = d.path(n)
        p.write_text(f"result {n}")
        written.append(p)
    d.finish(written)
    return d


def _edit_manifest(out, files):
    m = json.loads((out / MANIFEST).read_text())
    m["files"] = list(m["files"]) + list(files)
    (out / MANIFEST).write_text(json.dumps(m))


def test_stale_files_of_the_tool_are_removed_and_nothing_else(tmp_path):
    out = tmp_path / "out"
    _run(out, ["a.json", "b.urdf", "sub/c.png"])
    _run(out, ["a.json"])
    assert sorted(p.name for p in out.rglob("*") if p.is_file()) == [MANIFEST, "a.json"]
    # A file the tool wrote but the user changed since is not the tool's any more: kept.
    _run(out, ["a.json", "b.urdf"])
    (out / "b.urdf").write_text("edited by hand")
    _run(out, ["a.json"])
    assert (out / "b.urdf").read_text() == "edited by hand"


def test_a_manifest_cannot_make_a_run_delete_outside_out(tmp_path):
    """Traversal (../x, a/../../x), absolute paths, symbolic links (to a file or a directory
    outside) and a copied manifest with the victims' true hashes: all kept."""
    victims = tmp_path / "victims"
    victims.mkdir()
    files = {n: victims / n for n in ("x", "y", "z", "w")}
    for n, p in files.items():
        p.write_text(f"precious {n}")
    out = tmp_path / "run" / "out"
    _run(out, ["a.json"])
    (out / "link").symlink_to(files["z"])
    (out / "dirlink").symlink_to(victims, target_is_directory=True)
    entries = ["../../victims/x", "sub/../../../victims/x", str(files["y"]), "link",
               "dirlink/w", "", ".", 7, None]
    m = json.loads((out / MANIFEST).read_text())
    import hashlib
    m["files"] += entries
    m["sha256"].update({e: hashlib.sha256(files[os.path.basename(str(e))].read_bytes())
                        .hexdigest() for e in entries if isinstance(e, str)
                        and os.path.basename(e) in files})
    (out / MANIFEST).write_text(json.dumps(m))
    _run(out, ["a.json"])
    for n, p in files.items():
        assert p.read_text() == f"precious {n}"
    assert (out / "link").is_symlink() and (out / "dirlink").is_symlink()
    assert json.loads((out / MANIFEST).read_text())["files"] == ["a.json"]


@pytest.mark.parametrize("seed", range(6))
def test_generated_manifests_touch_only_unchanged_files_of_the_tool(tmp_path, seed):
    rng = np.random.default_rng(seed)
    outside = tmp_path / "outside"
    outside.mkdir()
    out = tmp_path / "o" / "out"
    names = [f"f{i}.txt" for i in range(6)]
    _run(out, names)
    for i in range(4):
        (outside / f"v{i}").write_text("keep")
    forms = [lambda i: f"../../outside/v{i}", lambda i: str(outside / f"v{i}"),
             lambda i: f"./x/../../../outside/v{i}", lambda i: f"{'../' * 5}outside/v{i}"]
    _edit_manifest(out, [forms[int(rng.integers(len(forms)))](i) for i in range(4)])
    keep = set(rng.choice(names, size=2, replace=False))
    edited = str(rng.choice(sorted(set(names) - keep)))
    (out / edited).write_text("changed")
    _run(out, sorted(keep))
    left = {p.name for p in out.iterdir()} - {MANIFEST}
    assert left == keep | {edited}
    assert all((outside / f"v{i}").read_text() == "keep" for i in range(4))

"""MkDocs hook (mkdocs.yml `hooks:`): the pages of docs/ may link to files of the repository
outside docs/ (``../diagrams/closed_loop.svg``, as GitHub shows them). Each such file that
exists is copied into the site under ``_repo/`` and the link rewritten to it; a link to a file
that does not exist is left as written, so the strict build reports it."""

from __future__ import annotations

import posixpath
import re
from pathlib import Path

from mkdocs.structure.files import File

# Markdown links and images `](target)`, and HTML `src="target"` / `href="target"`.
LINK = re.compile(r'(\]\(|(?:src|href)=")(\.\./[^)"\s#]+)')
PREFIX = "_repo"


def _outside_targets(page_path: Path, docs_dir: Path, root: Path, text: str):
    """(link as written, repository-relative path) for links leaving docs/ to an existing file."""
    for m in LINK.finditer(text):
        target = (page_path.parent / m.group(2)).resolve()
        if target.is_file() and root in target.parents and docs_dir not in target.parents:
            yield m.group(2), target.relative_to(root).as_posix()


def on_files(files, config):
    docs_dir = Path(config["docs_dir"]).resolve()
    root = Path(config["config_file_path"]).resolve().parent
    seen = set()
    for page in docs_dir.rglob("*.md"):
        for _, rel in _outside_targets(page, docs_dir, root, page.read_text(encoding="utf-8")):
            if rel not in seen:
                seen.add(rel)
                files.append(File.generated(config, f"{PREFIX}/{rel}",
                                            abs_src_path=str(root / rel)))
    return files


def on_page_markdown(markdown, page, config, files):
    docs_dir = Path(config["docs_dir"]).resolve()
    root = Path(config["config_file_path"]).resolve().parent
    page_path = docs_dir / page.file.src_uri
    page_dir = posixpath.dirname(page.file.src_uri)
    for written, rel in set(_outside_targets(page_path, docs_dir, root, markdown)):
        new = posixpath.relpath(f"{PREFIX}/{rel}", page_dir or ".")
        markdown = re.sub(r'(\]\(|(?:src|href)=")' + re.escape(written) + r'(?=[)"#])',
                          lambda m: m.group(1) + new, markdown)
    return markdown

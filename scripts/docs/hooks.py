"""MkDocs hooks for RealPen's documentation site (``mkdocs.yml``: ``hooks``).

- ``<!-- include: FILE -->`` in a page is replaced by that file of the repository (the README
  on the home page, ``CHANGELOG.md`` on the changelog page), so each stays one file in one place.
- A relative link to a file outside ``docs/`` (``../firmware/pico/README.md``, the README's
  ``docs/live.md``) is mended: into the site when it names a page of ``docs/``, to the
  repository when ``repo_url`` is set, else it keeps its text and shows the path as code.
"""

from __future__ import annotations

import posixpath
import re
from pathlib import Path

__all__ = ["on_page_markdown"]

INCLUDE = re.compile(r"<!--\s*include:\s*(?P<file>[^\s>]+)\s*-->")
# An inline Markdown link or image: [text](target) — code blocks are skipped by the caller.
LINK = re.compile(r"(?P<bang>!?)\[(?P<text>[^\]\n]*)\]\((?P<target>[^)\s]+)\)")
FENCE = re.compile(r"^(```|~~~)")


def on_page_markdown(markdown: str, page, config, files, **kwargs) -> str:
    docs_dir = Path(config["docs_dir"]).resolve()
    root = docs_dir.parent
    page_dir = (docs_dir / page.file.src_uri).parent

    def include(match: re.Match[str]) -> str:
        source = root / match["file"]
        return _mend_links(source.read_text(encoding="utf-8"), source.parent, docs_dir, page_dir,
                           root, config.get("repo_url"))

    markdown = INCLUDE.sub(include, markdown)
    return _mend_links(markdown, page_dir, docs_dir, page_dir, root, config.get("repo_url"))


def _mend_links(markdown: str, source_dir: Path, docs_dir: Path, page_dir: Path, root: Path,
                repo_url: str | None) -> str:
    """Links of a text written in ``source_dir``, as seen from a page in ``page_dir``."""

    def mend(match: re.Match[str]) -> str:
        target = match["target"]
        if re.match(r"[a-z][a-z0-9+.-]*:|#|/", target):
            return match[0]
        path, hash_, anchor = target.partition("#")
        resolved = Path(posixpath.normpath((source_dir / path).as_posix()))
        if resolved.is_relative_to(docs_dir):
            relative = posixpath.relpath(resolved.as_posix(), page_dir.as_posix())
            return f"{match['bang']}[{match['text']}]({relative}{hash_}{anchor})"
        in_repo = posixpath.relpath(resolved.as_posix(), root.as_posix())
        if repo_url:
            url = f"{repo_url.rstrip('/')}/blob/main/{in_repo}{hash_}{anchor}"
            return f"{match['bang']}[{match['text']}]({url})"
        if match["text"].strip("`") == in_repo:
            return f"`{in_repo}`"
        return f"{match['text']} (`{in_repo}`)"

    out, fenced = [], False
    for line in markdown.split("\n"):
        if FENCE.match(line.lstrip()):
            fenced = not fenced
        out.append(line if fenced else LINK.sub(mend, line))
    return "\n".join(out)

"""MkDocs hook: on the site, a link to a file of the repository outside docs/ becomes that file's path.

The pages link to the repository's other files (the lab notebook in experiments/, the README, the changelog)
by relative paths, which work wherever the Markdown is read in the repository: a code host, an editor. The
site holds only docs/, and the project has no public repository address to point at instead, so there such a
link becomes its text and the file's path: ``[the lab notebook](../experiments/notebook.md)`` reads "the lab
notebook, `experiments/notebook.md` in the repository". A file that a page shows whole
(``<!-- include-file: PATH -->``, e.g. the changelog) is linked to that page instead. Runs after ``hooks.py``
(``mkdocs.yml``), whose README sections and included files arrive with their links made relative to the page.
"""

from __future__ import annotations

import posixpath
import re
from pathlib import Path

LINK = re.compile(r"(?<!!)\[([^\]\n]+)\]\(([^()\s]+)\)")
NOT_A_FILE = re.compile(r"^(?:[a-zA-Z][a-zA-Z0-9+.-]*:|#|/)")  # a URL (https:, mailto:), an anchor, site-absolute
FENCE = re.compile(r"^\s*(```|~~~)")
INCLUDE_FILE = re.compile(r"^<!-- include-file: (.+?) -->$", re.M)


def repository_path(target: str, page: str) -> str | None:
    """The repository path a relative link ``target`` of the page ``page`` (a path under docs/) points at, if that
    is outside docs/; else None (a page of the site, a URL, an anchor)."""
    path = target.split("#", 1)[0]
    if not path or NOT_A_FILE.match(target):
        return None
    resolved = posixpath.normpath(posixpath.join("docs", posixpath.dirname(page), path))
    return None if resolved == "docs" or resolved.startswith("docs/") else resolved


def included_files(docs_dir: str) -> dict[str, str]:
    """Repository path -> the page (relative to docs/) that shows that file whole."""
    return {match.group(1): page.relative_to(docs_dir).as_posix()
            for page in sorted(Path(docs_dir).rglob("*.md")) for match in INCLUDE_FILE.finditer(page.read_text())}


def outside_links(markdown: str, page: str, included: dict[str, str] | None = None) -> str:
    """``markdown`` of the page ``page`` with each link to a file outside docs/ replaced by its text and path, or
    by a link to the page that shows the file (``included``: repository path -> page); code blocks left alone."""

    included = {} if included is None else included

    def replace(match: re.Match) -> str:
        text, target = match.groups()
        path = repository_path(target, page)
        if path is None:
            return match.group(0)
        if path in included:
            anchor = target[len(target.split("#", 1)[0]):]
            return f"[{text}]({posixpath.relpath(included[path], posixpath.dirname(page) or '.')}{anchor})"
        return f"`{path}`" if text.strip("`").rstrip("/") == path else f"{text}, `{path}` in the repository"

    lines, fenced = markdown.split("\n"), False
    for k, line in enumerate(lines):
        if FENCE.match(line):
            fenced = not fenced
        elif not fenced:
            lines[k] = LINK.sub(replace, line)
    return "\n".join(lines)


def on_page_markdown(markdown: str, page, config, files) -> str:
    return outside_links(markdown, page.file.src_uri, included_files(config["docs_dir"]))

"""MkDocs hook: on the site, a link to a file of the repository outside docs/ becomes that file's path.

The pages link to the repository's other files (the lab notebook in experiments/, the README, the changelog)
by relative paths, which work wherever the Markdown is read in the repository: a code host, an editor. The
site holds only docs/, and the project has no public repository address to point at instead, so there such a
link becomes its text and the file's path: ``[the lab notebook](../experiments/notebook.md)`` reads "the lab
notebook, `experiments/notebook.md` in the repository". Runs after ``hooks.py`` (``mkdocs.yml``), whose README
sections and included files arrive with their links made relative to the page.
"""

from __future__ import annotations

import posixpath
import re

LINK = re.compile(r"(?<!!)\[([^\]\n]+)\]\(([^()\s]+)\)")
NOT_A_FILE = re.compile(r"^(?:[a-zA-Z][a-zA-Z0-9+.-]*:|#|/)")  # a URL (https:, mailto:), an anchor, site-absolute
FENCE = re.compile(r"^\s*(```|~~~)")


def repository_path(target: str, page: str) -> str | None:
    """The repository path a relative link ``target`` of the page ``page`` (a path under docs/) points at, if that
    is outside docs/; else None (a page of the site, a URL, an anchor)."""
    path = target.split("#", 1)[0]
    if not path or NOT_A_FILE.match(target):
        return None
    resolved = posixpath.normpath(posixpath.join("docs", posixpath.dirname(page), path))
    return None if resolved == "docs" or resolved.startswith("docs/") else resolved


def outside_links(markdown: str, page: str) -> str:
    """``markdown`` of the page ``page`` with each link to a file outside docs/ replaced by its text and path
    (code blocks left as they are)."""

    def replace(match: re.Match) -> str:
        text, target = match.groups()
        path = repository_path(target, page)
        if path is None:
            return match.group(0)
        return f"`{path}`" if text.strip("`") == path else f"{text}, `{path}` in the repository"

    lines, fenced = markdown.split("\n"), False
    for k, line in enumerate(lines):
        if FENCE.match(line):
            fenced = not fenced
        elif not fenced:
            lines[k] = LINK.sub(replace, line)
    return "\n".join(lines)


def on_page_markdown(markdown: str, page, config, files) -> str:
    return outside_links(markdown, page.file.src_uri)

"""MkDocs hooks: environment pages from the env docstrings, and README sections in the results page.

A page line ``<!-- env-docstring: module:Class -->`` (or ``module``) becomes that object's runtime
docstring (the env docstrings are assembled at import from the config's arguments table and the info
fields, so they cannot be read statically); ``<!-- readme-section: Title -->`` becomes that ``## Title``
section of the README, so the results live in one place; ``<!-- include-file: PATH -->`` becomes the
file at PATH (relative to the repository root), e.g. the changelog.
"""

from __future__ import annotations

import importlib
import inspect
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ENV_DOC = re.compile(r"^<!-- env-docstring: ([\w.]+)(?::(\w+))? -->$", re.M)
README_SECTION = re.compile(r"^<!-- readme-section: (.+?) -->$", re.M)
INCLUDE_FILE = re.compile(r"^<!-- include-file: (.+?) -->$", re.M)


def _docstring(match: re.Match) -> str:
    target = importlib.import_module(match.group(1))
    if match.group(2):
        target = getattr(target, match.group(2))
    text = inspect.cleandoc(target.__doc__ or "")
    # Docstring sections are "## Title" headings: one level below the page title, as they are.
    text = re.sub(r"``([^`]+)``", r"`\1`", text)
    return text


def _readme_section(match: re.Match) -> str:
    title = match.group(1)
    readme = (ROOT / "README.md").read_text()
    start = readme.find(f"\n## {title}\n")
    if start < 0:
        raise ValueError(f"docs: README has no section '## {title}'")
    end = readme.find("\n## ", start + 1)
    return _site_links(readme[start + 1:end if end > 0 else None])


def _site_links(text: str) -> str:
    """Links relative to the repository root, made relative to docs/ (or absolute outside docs/)."""
    text = re.sub(r"\]\(docs/([^)]+)\)", r"](\1)", text)
    return re.sub(r"\]\((?!https?:|#|[\w-]+\.md)([^)]+)\)",
                  r"](https://github.com/continuum-gym/continuum-gym/blob/main/\1)", text)


def _include_file(match: re.Match) -> str:
    return _site_links((ROOT / match.group(1)).read_text())


def on_page_markdown(markdown: str, page, config, files) -> str:
    markdown = ENV_DOC.sub(_docstring, markdown)
    markdown = INCLUDE_FILE.sub(_include_file, markdown)
    return README_SECTION.sub(_readme_section, markdown)

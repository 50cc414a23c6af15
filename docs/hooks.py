"""MkDocs hooks: environment pages from the env docstrings, and README sections in the results page.

A page line ``<!-- env-docstring: module:Class -->`` (or ``module``) becomes that object's runtime
docstring (the env docstrings are assembled at import from the config's arguments table and the info
fields, so they cannot be read statically); ``<!-- readme-section: Title -->`` becomes that ``## Title``
section of the README, so the results live in one place.
"""

from __future__ import annotations

import importlib
import inspect
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ENV_DOC = re.compile(r"^<!-- env-docstring: ([\w.]+)(?::(\w+))? -->$", re.M)
README_SECTION = re.compile(r"^<!-- readme-section: (.+?) -->$", re.M)


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
    section = readme[start + 1:end if end > 0 else None]
    # README links are relative to the repository root; on the site they are relative to docs/.
    section = re.sub(r"\]\(docs/([^)]+)\)", r"](\1)", section)
    section = re.sub(r"\]\((?!https?:|#|\w+\.md)([^)]+)\)", r"](https://github.com/continuum-gym/continuum-gym/blob/main/\1)", section)
    return section


def on_page_markdown(markdown: str, page, config, files) -> str:
    markdown = ENV_DOC.sub(_docstring, markdown)
    return README_SECTION.sub(_readme_section, markdown)

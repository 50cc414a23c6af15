"""The documentation's Python examples run as they are written (README and tutorials, block by block)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs" / "tutorials").glob("*.md"))]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def test_the_tutorials_exist_and_hold_examples():
    names = {page.name for page in PAGES}
    assert {"extend.md", "evaluate.md", "train.md", "read-results.md"} <= names
    for page in PAGES[1:]:
        assert BLOCK.findall(page.read_text()), f"{page.name} has no python example"


@pytest.mark.parametrize("page", PAGES, ids=lambda page: page.name)
def test_every_python_block_of_a_page_runs(page, monkeypatch, tmp_path, capsys):
    monkeypatch.setenv("CONTINUUM_GYM_CACHE", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    from continuum_gym import registry

    tables = (registry.ROBOTS, registry.TASKS, registry.CONTROLLERS, registry.REWARD_TERMS)
    before = [{env: dict(names) for env, names in table.items()} for table in tables]
    namespace: dict = {"__name__": f"docs_{page.stem}"}
    try:
        for index, code in enumerate(BLOCK.findall(page.read_text())):
            try:
                exec(compile(code, f"{page.name} (python block {index + 1})", "exec"), namespace)
            except Exception as error:  # the failing block, named
                raise AssertionError(f"{page.name}: python block {index + 1} failed: {error!r}\n{code}") from error
    finally:  # a page's registrations must not leak into the other tests of this process
        for table, saved in zip(tables, before):
            for env in list(table):
                table[env].clear()
                table[env].update(saved.get(env, {}))

"""The documentation's examples run as they are written: the Python blocks of the README and the
tutorials block by block, and the shell blocks of the variant tutorial through the command line."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs" / "tutorials").glob("*.md"))]
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)
SHELL = re.compile(r"^```bash\n(.*?)^```", re.S | re.M)
EXAMPLES = ROOT / "examples"  # the variant tutorial's plug-in package (my_lab)


def _examples_on_the_path(monkeypatch) -> None:
    """As the variant tutorial asks its reader: examples/ importable here and in child processes."""
    monkeypatch.syspath_prepend(str(EXAMPLES))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in (str(EXAMPLES), os.environ.get("PYTHONPATH")) if p))


def _forget_my_lab() -> None:
    """Forget the example packages (my_lab's variant, my_reach's environment) so that no other test sees them."""
    from continuum_gym.envs.spec import ENV_IDS, ENV_SPECS

    for name in [m for m in sys.modules if m.split(".")[0] in ("my_lab", "my_reach")]:
        del sys.modules[name]
    for env_id in ("MyLab/Occlusion2Seg-v0", "MyLab/EndoscopeReach-v0"):
        gym.registry.pop(env_id, None)
        ENV_SPECS.pop(env_id, None)
        if env_id in ENV_IDS:
            ENV_IDS.remove(env_id)


def test_the_tutorials_exist_and_hold_examples():
    names = {page.name for page in PAGES}
    assert {"extend.md", "evaluate.md", "train.md", "read-results.md", "variant.md"} <= names
    for page in PAGES[1:]:
        assert BLOCK.findall(page.read_text()), f"{page.name} has no python example"


@pytest.mark.parametrize("page", PAGES, ids=lambda page: page.name)
def test_every_python_block_of_a_page_runs(page, monkeypatch, tmp_path, capsys):
    monkeypatch.setenv("CONTINUUM_GYM_CACHE", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    _examples_on_the_path(monkeypatch)
    from continuum_gym import registry

    tables = (registry.ROBOTS, registry.TASKS, registry.CONTROLLERS, registry.REWARD_TERMS, registry.ORIGINS)
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
        _forget_my_lab()


def test_the_variant_tutorials_shell_blocks_run_as_written(tmp_path):
    """Each shell block in a fresh bash, in one working folder, with the venv's commands on the PATH."""
    page = ROOT / "docs" / "tutorials" / "variant.md"
    blocks = SHELL.findall(page.read_text())
    assert len(blocks) >= 3
    env = {key: value for key, value in os.environ.items() if key != "CONTINUUM_GYM_PLUGINS"}
    env.update(CONTINUUM_GYM_ROOT=str(ROOT), CONTINUUM_GYM_CACHE=str(tmp_path / "cache"),
               PATH=os.pathsep.join((str(Path(sys.executable).parent), env.get("PATH", ""))))
    outputs = []
    for index, code in enumerate(blocks):
        result = subprocess.run(["bash", "-euo", "pipefail", "-c", code], cwd=tmp_path, env=env, capture_output=True,
                                text=True, timeout=900)
        assert result.returncode == 0, f"variant.md: shell block {index + 1} failed:\n{code}\n{result.stderr[-3000:]}"
        outputs.append(result.stdout)
    assert "registered MyLab/Occlusion2Seg-v0" in outputs[0]
    assert "MyLab/Occlusion2Seg-v0: " in outputs[1] and "its first gym.make compiles nothing" in outputs[1]
    assert "config.yml" in outputs[2] and "model.zip" in outputs[2]
    import json

    table = json.loads((tmp_path / "results" / "variant" / "results.json").read_text())["MyLab/Occlusion2Seg-v0"]
    assert {"projected_gradient", "mylab_dls", "residual_mylab_dls", "offline_optimum"} <= set(table)
    assert "headroom_closed" in table["residual_mylab_dls"]


def test_the_column_table_of_the_extension_tutorial_names_every_kernel_column():
    """The metric and flag columns a reward term reads are the envs' declarations: the table lists each once,
    in column order."""
    import importlib

    text = (ROOT / "docs" / "tutorials" / "extend.md").read_text()
    rows = {"OcclusionAvoidance": "continuum_gym.envs.occlusion", "ViewTracking": "continuum_gym.envs.view_tracking"}
    for env, package in rows.items():
        line = next(line for line in text.splitlines() if line.startswith(f"| {env} ("))
        _, metrics_cell, flags_cell = line.strip("|").split(" | ")
        outputs = importlib.import_module(package + ".outputs")
        for name, cell, columns in (("Metric", metrics_cell, outputs.Metric), ("Flag", flags_cell, outputs.Flag)):
            assert [int(c) for c in columns] == list(range(len(columns)))
            assert re.findall(r"`([A-Z_]+)`", cell) == list(columns.names()), f"{env} {name} table"

"""Docs read in the repository (on a code host, without the site's build) show their text, not placeholders.

The environment pages hold their env's docstring and the variant tutorial holds the plug-in module it walks
through, generated between markers by ``make docs-text`` (``python docs/hooks.py``); the site's build
generates the same. A test fails as soon as the text is stale.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted((ROOT / "docs").rglob("*.md"))


def _hooks():
    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "docs" / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_pages_read_on_a_code_host_hold_the_generated_text():
    occlusion = (ROOT / "docs" / "environments" / "occlusion-avoidance.md").read_text()
    assert "## Action Space" in occlusion and "residual_scale" in occlusion and "reward_terms" in occlusion
    assert "## Observation Space" in (ROOT / "docs" / "environments" / "view-tracking.md").read_text()
    assert "compute_reward(achieved_goal, desired_goal, info)`, vectorised" in (
        ROOT / "docs" / "environments" / "goal.md").read_text()
    variant = (ROOT / "docs" / "tutorials" / "variant.md").read_text()
    assert "def damped_least_squares(" in variant and "--8<--" not in variant


@pytest.mark.parametrize("page", PAGES, ids=lambda page: str(page.relative_to(ROOT / "docs")))
def test_the_generated_text_of_every_page_is_current(page):
    text = page.read_text()
    assert _hooks().generate(text) == text, (f"{page.relative_to(ROOT)} is stale: its generated text no longer "
                                             "matches its source; run `make docs-text` (python docs/hooks.py)")


def test_a_stale_region_is_regenerated_and_an_old_placeholder_filled(tmp_path):
    hooks = _hooks()
    source = ROOT / "examples" / "my_lab" / "plugins.py"
    stale = "<!-- include-code: examples/my_lab/plugins.py -->\n```py\nold\n```\n<!-- /include-code -->\n"
    fresh = hooks.generate(stale)
    assert "old" not in fresh and source.read_text().strip() in fresh and hooks.generate(fresh) == fresh
    placeholder = "# Page\n\n<!-- env-docstring: continuum_gym.envs.goal -->\n\nafter\n"
    filled = hooks.generate(placeholder)
    assert "<!-- /env-docstring -->" in filled and filled.endswith("\nafter\n") and hooks.generate(filled) == filled
    site = hooks.generate(filled, markers=False)  # what the site shows: the text, no markers
    assert "env-docstring" not in site and "Goal" in site

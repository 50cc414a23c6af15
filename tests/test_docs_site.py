"""The docs site builds with every warning an error: broken links and anchors, pages missing from the
navigation, API objects that cannot be found, docstrings whose parameters lack types."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_docs_site_builds_strictly_with_the_env_pages(tmp_path):
    site = tmp_path / "site"
    result = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
                            cwd=ROOT, capture_output=True, text=True, timeout=600,
                            env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert result.returncode == 0, result.stderr[-4000:]
    occlusion = (site / "environments" / "occlusion-avoidance" / "index.html").read_text()
    # The env page is the runtime docstring: its assembled arguments table and info fields are there.
    assert "Action Space" in occlusion and "residual_scale" in occlusion and "reward_terms" in occlusion
    assert "env-docstring" not in occlusion
    results = (site / "results" / "index.html").read_text()
    assert "readme-section" not in results and "headroom" in results.lower()
    api = (site / "api" / "index.html").read_text()
    assert "evaluate_policy" in api and "MultiBackboneRobot" in api
    # Links that leave docs/ (docs/site_links.py): the notebook by its path, the changelog to its page.
    assert "<code>experiments/notebook.md</code> in the repository" in results and "optimum-experiments" not in results
    assert 'href="../changelog/"' in (site / "performance" / "index.html").read_text()


def _site_links():
    spec = importlib.util.spec_from_file_location("site_links", ROOT / "docs" / "site_links.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_link_that_leaves_docs_becomes_the_files_path_or_the_page_that_shows_it():
    links = _site_links()
    page = "tutorials/extend.md"
    markdown = ("[the notebook](../../experiments/notebook.md#campaign-6) [train](train.md) [api](../api.md#x) "
                "[out](https://example.org/a.md) [`examples/my_reach`](../../examples/my_reach/) ![a](../img/a.png)\n"
                "```\n[in code](../../README.md)\n```\n[log](../../CHANGELOG.md#unreleased)")
    out = links.outside_links(markdown, page, {"CHANGELOG.md": "changelog.md"})
    assert out.split("\n") == [
        "the notebook, `experiments/notebook.md` in the repository [train](train.md) [api](../api.md#x) "
        "[out](https://example.org/a.md) `examples/my_reach` ![a](../img/a.png)",
        "```", "[in code](../../README.md)", "```", "[log](../changelog.md#unreleased)"]
    assert links.outside_links("[n](../experiments/notebook.md)", "results.md") == "n, `experiments/notebook.md` in the repository"

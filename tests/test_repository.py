"""The repository's layout: no address that does not exist, experiments outside the product, and
experiments/README.md naming, for every shipped artifact, the experiment that made it (issue 55)."""

from __future__ import annotations

import ast
import os
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = ROOT / "experiments"
README = EXPERIMENTS / "README.md"
#: The address the docs and the dataset metadata once linked to: there is no such repository.
DEAD_ADDRESS = "github.com/" + "continuum-gym"
#: Directories that are not the repository's own files (environments, caches, build and run outputs).
NOT_OURS = {".git", ".venv", "venv", "build", "dist", "results", "runs", "out", "site", "__pycache__", ".pytest_cache",
            ".ruff_cache", ".mypy_cache", "_precompiled", ".hypothesis"}
#: Where paths named in experiments/README.md live (from the root, or from experiments/).
PATH_TOKEN = re.compile(r"^(?:experiments|continuum_gym|benchmarks|scripts|docs|reference-runs|tests|optimum|figures"
                        r"|reference_runs)/")


def _text_files():
    for directory, subdirectories, files in os.walk(ROOT):
        subdirectories[:] = sorted(d for d in subdirectories if d not in NOT_OURS and not d.endswith(".egg-info"))
        for name in sorted(files):
            path = Path(directory) / name
            data = path.read_bytes()
            if b"\0" in data[:8192]:
                continue  # binary: model.zip, npz, png
            yield path, data.decode("utf-8", errors="replace")


def test_no_file_points_at_the_address_of_a_repository_that_does_not_exist():
    found = [str(path.relative_to(ROOT)) for path, text in _text_files() if DEAD_ADDRESS in text]
    assert not found, f"{DEAD_ADDRESS} (no such repository) in: {found}; link relatively, or leave the field out"


def test_the_checks_see_a_text_file_and_skip_what_is_not_ours():
    files = {str(path.relative_to(ROOT)) for path, _ in _text_files()}
    assert {"pyproject.toml", "mkdocs.yml", "docs/results.md", "continuum_gym/evaluation/datasets.py",
            "experiments/README.md"} <= files
    assert not any(name.startswith(".git/") or name.endswith(".zip") for name in files)


def test_the_wheel_packages_only_the_library():
    find = (ROOT / "pyproject.toml").read_text().split("[tool.setuptools.packages.find]\n", 1)[1].split("\n[", 1)[0]
    # experiments/, scripts/ and benchmarks/ stay out of the wheel
    assert find.strip() == 'include = ["continuum_gym*"]', find
    assert not list(EXPERIMENTS.rglob("__init__.py"))


def _imports(tree: ast.AST) -> set[str]:
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names.add(node.module.split(".")[0])
    return names


def test_the_suite_imports_no_experiment_code():
    experiment_modules = {path.stem for path in EXPERIMENTS.rglob("*.py")} | {"experiments"}
    offenders = {}
    for path in sorted((ROOT / "tests").rglob("*.py")):
        tree = ast.parse(path.read_text())
        strings = [n.value for n in ast.walk(tree) if isinstance(n, ast.Constant) and isinstance(n.value, str)]
        hits = (_imports(tree) & experiment_modules) | {s for s in strings if s.startswith("experiments/")
                                                        and s.endswith(".py")}
        if hits and path.name != "test_repository.py":
            offenders[str(path.relative_to(ROOT))] = sorted(hits)
    assert not offenders, f"tests importing experiment code (its tests live beside it in experiments/): {offenders}"


def test_scripts_holds_only_what_the_makefile_runs():
    makefile = (ROOT / "Makefile").read_text()
    scripts = sorted(path.name for path in (ROOT / "scripts").iterdir() if path.suffix == ".py")
    assert scripts and all(f"scripts/{name}" in makefile for name in scripts), scripts


def _expand(token: str) -> list[str]:
    """``a{0,1}b`` -> [``a0b``, ``a1b``] (one brace group, as the README writes seeds)."""
    match = re.search(r"\{([^{}]+)\}", token)
    if match is None:
        return [token]
    return [token[:match.start()] + option + token[match.end():] for option in match.group(1).split(",")]


def _readme_paths(text: str | None = None) -> dict[str, list[Path]]:
    """Each repository path named in code spans of ``text`` (default: experiments/README.md) -> the files or
    directories it matches."""
    found: dict[str, list[Path]] = {}
    for span in re.findall(r"`([^`]+)`", README.read_text() if text is None else text):
        for token in span.split():
            token = token.rstrip(";,")
            if PATH_TOKEN.match(token) and "<" not in token:  # <run>, <name>: placeholders
                found[token] = [match for base in (ROOT, EXPERIMENTS) for pattern in _expand(token)
                                for match in base.glob(pattern.rstrip("/"))]
    return found


def test_every_path_experiments_readme_names_exists():
    paths = _readme_paths()
    assert len(paths) > 20
    missing = sorted(token for token, matches in paths.items() if not matches)
    assert not missing, f"experiments/README.md names paths that do not exist: {missing}"


def test_every_kept_experiment_made_something_the_readme_names():
    named = {path.resolve() for matches in _readme_paths().values() for path in matches}
    kept = [path for path in EXPERIMENTS.rglob("*") if path.suffix in (".py", ".yml", ".sh")
            and not path.name.startswith("test_")]
    dead = sorted(str(path.relative_to(ROOT)) for path in kept if path.resolve() not in named)
    assert kept and not dead, f"experiment files no shipped artifact's line names (delete them: git keeps them): {dead}"


@pytest.mark.parametrize("artifact", ["continuum_gym/agents/policies", "continuum_gym/agents/policies_model_error",
                                      "continuum_gym/envs/view_tracking/distilled_view.npz"])
def test_every_shipped_artifact_has_its_line_in_experiments_readme(artifact):
    table = README.read_text().split("| artifact |", 1)[1].split("\n\n", 1)[0]
    first_column = "\n".join(row.split(" | ", 1)[0] for row in table.splitlines()[2:])
    named = {path.resolve() for matches in _readme_paths(first_column).values() for path in matches}
    target = ROOT / artifact
    runs = [zip_file.parent for zip_file in target.rglob("model.zip")] if target.is_dir() else [target]
    assert runs
    unnamed = [str(run.relative_to(ROOT)) for run in runs
               if not any(run.resolve() == path or path in run.resolve().parents for path in named)]
    assert not unnamed, f"shipped without a line in experiments/README.md: {unnamed}"

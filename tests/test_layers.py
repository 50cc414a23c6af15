"""The package's layers, read from its sources: every import (function-level ones included) points down.

robots <- geometry <- baselines <- envs <- registry <- agents / evaluation / render / config files <- the
command line (the environments name their pybullet scene in their spec; they do not import the renderer).
No import cycle between modules, no private name imported from another module, and nothing below the
environments imports gymnasium, torch or stable-baselines3.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import networkx as nx
import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "continuum_gym"

#: Layer of each module (by longest matching prefix); a module may import its own layer and those below.
LAYERS = {
    "continuum_gym.validation": 0,
    "continuum_gym.plugins": 0,
    "continuum_gym.robots": 1,
    "continuum_gym.geometry": 2,
    "continuum_gym.camera": 2,  # the batched renderer: robots, geometry and validation only (no pybullet)
    "continuum_gym.baselines": 3,
    "continuum_gym.envs": 4,
    "continuum_gym.registry": 5,
    "continuum_gym.config_files": 6,
    "continuum_gym.precompile": 6,
    "continuum_gym.agents": 6,
    "continuum_gym.evaluation": 6,
    "continuum_gym.render": 6,
    # the pybullet scenes draw robots from their kinematics (the core is read by attribute, never imported): below
    # the environments, which name their scene in their spec; the command that records episodes stays above
    "continuum_gym.render.scene": 3,
    "continuum_gym.render.occlusion_scene": 3,
    "continuum_gym.render.view_scene": 3,
    "continuum_gym.render.meshes": 3,
    "continuum_gym.render.camera": 3,
    "continuum_gym.render.textures": 3,
    "continuum_gym.render.occlusion": 3,
    "continuum_gym.cli": 7,
    "continuum_gym": 4,  # the package root registers the ids (envs.registration) and nothing else
}
#: Third-party frameworks that the layers below the environments must not need.
FRAMEWORKS = ("gymnasium", "torch", "stable_baselines3")


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        if "_precompiled" in path.parts:
            continue
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


MODULES = _modules()


def _layer(module: str) -> int:
    prefix = max((p for p in LAYERS if module == p or module.startswith(p + ".")), key=len)
    return LAYERS[prefix]


def _imports(name: str, path: Path):
    """(imported module, imported names, line) of every import statement in the module, at any depth."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, (), node.lineno
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            for alias in node.names:
                full = f"{base}.{alias.name}"
                if full in MODULES:
                    yield full, (), node.lineno
                else:
                    yield base, (alias.name,), node.lineno


def _owner(module: str) -> str | None:
    while module and module not in MODULES:
        module = module.rpartition(".")[0]
    return module or None


#: A "module:name" reference (or a bare module path) to one of the package's modules, in a string constant.
REFERENCE = re.compile(r"^(continuum_gym(?:\.\w+)+)(?::[\w.]+)?$")


def _references(name: str, path: Path):
    """(module, (), line) of every string constant that names a module of the package: "module:name" references
    (an entry point, a row declaration, a scene) are imported when used, so they are dependencies as imports are."""
    for value, line in _strings(ast.parse(path.read_text())):
        match = REFERENCE.match(value)
        if match and _owner(match.group(1)):
            yield match.group(1), (), line


def _graph(references: bool = True) -> nx.DiGraph:
    graph = nx.DiGraph()
    for name, path in MODULES.items():
        graph.add_node(name)
        edges = list(_imports(name, path)) + (list(_references(name, path)) if references else [])
        for target, _, line in edges:
            owner = _owner(target) if target.startswith("continuum_gym") else None
            if owner and owner not in (name, "continuum_gym"):  # the root is imported before any submodule
                graph.add_edge(name, owner, line=line)
    return graph


def test_the_layer_map_covers_every_module():
    assert len(MODULES) > 80
    for name in MODULES:
        assert any(name == p or name.startswith(p + ".") for p in LAYERS), name


def test_no_import_cycle_between_modules():
    cycles = sorted(nx.simple_cycles(_graph(references=False)), key=len)
    assert cycles == [], f"{len(cycles)} import cycles, e.g. {' -> '.join(cycles[0] + cycles[0][:1])}"


def test_every_import_points_down_the_layers():
    graph = _graph()
    upward = [f"{a} (layer {_layer(a)}, line {graph.edges[a, b]['line']}) imports {b} (layer {_layer(b)})"
              for a, b in graph.edges if _layer(b) > _layer(a)]
    assert upward == []


def test_no_private_name_crosses_modules():
    crossing = []
    for name, path in MODULES.items():
        for target, names, line in _imports(name, path):
            if not target.startswith("continuum_gym"):
                continue
            private = [n for n in names if n.startswith("_") and not n.startswith("__")]
            private += [target.rpartition(".")[2]] if target.rpartition(".")[2].startswith("_") else []
            crossing += [f"{name}:{line} imports {target}.{n}" for n in private]
    assert crossing == []


@pytest.mark.parametrize("layer", ["continuum_gym.robots", "continuum_gym.geometry", "continuum_gym.camera",
                                   "continuum_gym.baselines"])
def test_the_layers_below_the_environments_need_no_rl_framework(layer):
    found = [f"{name}:{line} imports {target}" for name, path in MODULES.items()
             if name == layer or name.startswith(layer + ".")
             for target, _, line in _imports(name, path) if target.split(".")[0] in FRAMEWORKS]
    assert found == []


def test_the_checks_see_what_they_look_for(tmp_path):
    """The graph is built from real import statements: a known downward edge and a known function-level one."""
    graph = _graph()
    assert graph.has_edge("continuum_gym.envs.occlusion.kernel", "continuum_gym.envs.occlusion.controller")
    assert graph.has_edge("continuum_gym.envs.registered", "continuum_gym.plugins")
    # a function-level import (inside CustomController.predict) is an edge too
    assert graph.has_edge("continuum_gym.envs.registered", "continuum_gym.envs.custom")
    assert _layer("continuum_gym.envs.spec") == 4 and _layer("continuum_gym.agents.train") == 6


#: The environments' own packages: everything specific to one environment lives in one of them.
ENV_PACKAGES = ("continuum_gym.envs.occlusion", "continuum_gym.envs.view_tracking")
#: Modules outside them that may name one environment's modules, and why.
ENV_NAMING = {
    "continuum_gym.envs.spec": "BUILTIN_ENVS lists the library's environment packages",
    "continuum_gym.envs": "re-exports the environments' classes (continuum_gym.envs.OcclusionConfig, ...)",
    # one environment's own pieces in the layers above the environments, each named by its spec
    # (scene, optimum, warm_ups) or by its module name
    "continuum_gym.render.occlusion_scene": "the OcclusionAvoidance scene (spec.scene)",
    "continuum_gym.render.view_scene": "the ViewTracking scene (spec.scene)",
    "continuum_gym.evaluation.optimum.occlusion": "the OcclusionAvoidance optimum (spec.optimum)",
    "continuum_gym.evaluation.optimum.rate_bound": "the OcclusionAvoidance hold tasks' rate-limited bound",
    "continuum_gym.evaluation.optimum.optima": "files the two environments' optima by id (register_optimum)",
    "continuum_gym.evaluation.reproduction": "reproduces both papers; its warm-ups of each env's robots (precompile)",
}


def _strings(tree: ast.AST) -> list[tuple[str, int]]:
    """String constants that are not docstrings."""
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                  and node.body and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    return [(node.value, node.lineno) for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings]


def _outside_the_env_packages():
    return {name: path for name, path in MODULES.items()
            if not any(name == p or name.startswith(p + ".") for p in ENV_PACKAGES)}


def test_no_environment_id_outside_its_package():
    """The rest of the library reaches an environment through its spec: no module names an id."""
    found = [f"{name}:{line} {value!r}" for name, path in _outside_the_env_packages().items()
             for value, line in _strings(ast.parse(path.read_text())) if "ContinuumGym/" in value]
    assert found == []


def test_only_the_listed_modules_import_an_environment_package():
    found = []
    for name, path in _outside_the_env_packages().items():
        for target, _names, line in _imports(name, path):
            if any(target == p or target.startswith(p + ".") for p in ENV_PACKAGES) and name not in ENV_NAMING:
                found.append(f"{name}:{line} imports {target}")
        for value, line in _strings(ast.parse(path.read_text())):
            if any(p in value for p in ENV_PACKAGES) and name not in ENV_NAMING:
                found.append(f"{name}:{line} names {value!r}")
    assert found == []


def test_the_environment_checks_see_what_they_look_for():
    """They read string constants and imports: an id in code is seen, one in a docstring is not."""
    code = ast.parse('"""ContinuumGym/Doc-v0"""\nX = "ContinuumGym/Code-v0"\n')
    assert [value for value, _ in _strings(code)] == ["ContinuumGym/Code-v0"]
    inside = [name for name in MODULES if name.startswith(ENV_PACKAGES[0] + ".")]
    assert {"continuum_gym.envs.occlusion.spec", "continuum_gym.envs.occlusion.env"} <= set(inside)
    assert any("ContinuumGym/" in value for value, _ in _strings(ast.parse(MODULES[
        "continuum_gym.envs.occlusion.config"].read_text())))
    # a "module:name" reference in a string is an edge of the layer graph, as an import is
    graph = _graph()
    assert graph.has_edge("continuum_gym.envs.occlusion.spec", "continuum_gym.envs.occlusion.env")
    assert not _graph(references=False).has_edge("continuum_gym.envs.occlusion.spec", "continuum_gym.envs.occlusion.env")

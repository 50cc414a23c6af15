"""Type hints on the public API: every public function of the typed packages is fully annotated.

``make test`` runs mypy on the same packages (``[tool.mypy] files`` in pyproject.toml); this test
counts the hints themselves (mypy accepts an unannotated function silently) and keeps both lists equal.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
import tomllib

ROOT = Path(__file__).resolve().parents[1]
KERNEL_DECORATORS = {"kernel", "njit", "jit"}  # numba compiles these from their own typing, not from hints


def typed_files() -> list[Path]:
    patterns = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["mypy"]["files"]
    files: list[Path] = []
    for pattern in patterns:
        path = ROOT / pattern
        files += sorted(path.rglob("*.py")) if path.is_dir() else sorted(ROOT.glob(pattern))
    return files


def _is_kernel(node: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    for decorator in node.decorator_list:
        target = decorator.func if isinstance(decorator, ast.Call) else decorator
        if getattr(target, "id", getattr(target, "attr", None)) in KERNEL_DECORATORS:
            return True
    return False


def unannotated(source: str) -> list[str]:
    """'name:line' of each public function or method (and ``__init__``) lacking a parameter or return hint."""
    missing = []

    def visit(node: ast.AST, public: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef):
                visit(child, public and not child.name.startswith("_"))
            elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                if not public or (child.name.startswith("_") and child.name != "__init__") or _is_kernel(child):
                    continue
                arguments = child.args
                params = [*arguments.posonlyargs, *arguments.args, *arguments.kwonlyargs]
                params = [p for p in params if p.arg not in ("self", "cls")]
                params += [p for p in (arguments.vararg, arguments.kwarg) if p is not None]
                if any(p.annotation is None for p in params) or child.returns is None:
                    missing.append(f"{child.name}:{child.lineno}")

    visit(ast.parse(source), True)
    return missing


def test_the_counter_sees_what_is_missing():
    source = ("def f(x: int) -> int: ...\ndef g(x) -> int: ...\ndef h(x: int): ...\ndef _p(x): ...\n"
              "def v(*args, **kw: int) -> None: ...\nclass C:\n    def m(self, y: str) -> None: ...\n"
              "    def n(self): ...\n    def __init__(self, z): ...\nclass _D:\n    def q(self): ...\n"
              "@kernel\ndef k(x): ...\n@kernel(inline='always')\ndef k2(x): ...\n")
    assert unannotated(source) == ["g:2", "h:3", "v:5", "n:8", "__init__:9"]


@pytest.mark.parametrize("path", typed_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_public_function_of_the_typed_packages_is_annotated(path):
    assert unannotated(path.read_text()) == []

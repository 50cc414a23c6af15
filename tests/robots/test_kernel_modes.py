"""Every kernel's compile mode is in its declaration, and the modes are used as ``robots.compiled.kernel`` says.

Three modes: a *leaf* (``@kernel(inline="always")``) is inlined into its caller; a *borrowing* row kernel
(``@kernel(borrows=True)``) runs without reference counts and may not allocate; an *entry* (``@kernel``)
counts references and may allocate. A borrowing kernel may call leaves and other borrowing kernels, and an
entry only if it returns no array (nothing would free it): checked here on the kernels' source, without
compiling anything; ``tests/envs/test_borrowing_kernels.py`` counts the allocations of every step path.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
import textwrap
import types

import numpy as np
from numba.core.registry import CPUDispatcher

import continuum_gym


def package_kernels() -> dict[str, CPUDispatcher]:
    found = {}
    for info in pkgutil.walk_packages(continuum_gym.__path__, "continuum_gym."):
        if info.name.endswith(("cli", "__main__")) or "._precompiled" in info.name:
            continue
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.py_func.__module__ == module.__name__:
                found[f"{module.__name__}.{name}"] = value
    return found


def mode(dispatcher: CPUDispatcher) -> str:
    options = dispatcher.targetoptions
    if options.get("inline") == "always":
        return "leaf"
    return "borrowing" if options.get("_nrt") is False else "entry"


def called_kernels(dispatcher: CPUDispatcher) -> dict[str, CPUDispatcher]:
    """The kernels a kernel's code names (global names, nested code included)."""
    names: set[str] = set()
    stack = [dispatcher.py_func.__code__]
    while stack:
        code = stack.pop()
        names.update(code.co_names)
        stack.extend(c for c in code.co_consts if isinstance(c, types.CodeType))
    globals_ = dispatcher.py_func.__globals__
    return {n: globals_[n] for n in names if isinstance(globals_.get(n), CPUDispatcher)}


ARRAY_MAKERS = {"empty", "zeros", "ones", "full", "array", "copy", "empty_like", "zeros_like", "ones_like",
               "arange", "linspace", "concatenate", "stack", "dot", "outer"}


def may_return_new_array(func) -> bool:
    """Whether a kernel's source could return a new array: a return of (a name bound to) a numpy array maker,
    ``.copy()`` or an operator on arrays is caught; returns of arithmetic on scalars and of nothing are not."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(func)))
    made = set()

    def makes_array(node) -> bool:
        return isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in ARRAY_MAKERS

    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and makes_array(node.value):
            made.update(t.id for t in node.targets if isinstance(t, ast.Name))
    for node in ast.walk(tree):
        if isinstance(node, ast.Return) and node.value is not None:
            for part in ast.walk(node.value):
                if makes_array(part) or (isinstance(part, ast.Name) and part.id in made):
                    return True
    return False


def test_every_kernel_of_the_package_declares_its_mode_through_kernel():
    kernels = package_kernels()
    assert len(kernels) > 100
    undeclared = [name for name, d in kernels.items() if "_nrt" not in d.targetoptions]
    assert not undeclared, f"declared with numba.njit, not robots.compiled.kernel: {undeclared}"
    modes = {m: sum(mode(d) == m for d in kernels.values()) for m in ("leaf", "borrowing", "entry")}
    assert all(modes.values()), modes


def test_borrowing_kernels_call_only_leaves_borrowers_and_entries_that_return_no_array():
    checked = []
    for name, d in package_kernels().items():
        if mode(d) != "borrowing":
            continue
        for callee_name, callee in called_kernels(d).items():
            if mode(callee) == "entry":
                assert not may_return_new_array(callee.py_func), f"{name} calls {callee_name}, which returns an array"
                checked.append(callee_name)
    assert len(set(checked)) >= 3  # the check reaches the entries the borrowing kernels call today


def test_the_check_catches_an_entry_that_returns_a_new_array():
    def fresh(n):
        out = np.empty(n)
        out[:] = 1.0
        return out

    def scaled(x):
        return 2.0 * x

    def ones(n):
        return np.ones(n)

    assert may_return_new_array(fresh) and may_return_new_array(ones) and not may_return_new_array(scaled)

"""Compiled kernels that start in a second: numba's JIT with a precompiled set shipped in the install.

Every kernel of the package is declared with :func:`kernel` (``numba.njit`` with caching). Its compiled
code is looked up in two places before numba compiles it:

1. the *precompiled set*, ``continuum_gym/_precompiled/`` (or ``CONTINUUM_GYM_PRECOMPILED_DIR``), written
   once per install by ``continuum-gym precompile`` (``make setup`` runs it). It is read only, and valid
   only for the exact package code, numba, llvmlite, numpy and Python it was built with: one digest of
   all of them stamps every entry, so edited code, another numba or a different CPU makes the set miss
   as a whole and never serves stale code (numba's own cache checks only the kernel's own file, not the
   kernels it calls). The digest covers what kernels are compiled from: each module's syntax tree
   without docstrings and comments, so editing those (or a test) keeps the set; entries are named by
   module and function, not by line number as in numba's own cache;
2. numba's own cache (``NUMBA_CACHE_DIR`` or ``__pycache__``), where anything compiled at run time goes.

Why not an ahead-of-time extension module: ``numba.pycc`` is deprecated, exports plain C functions
that other kernels cannot call without a Python round trip, and would need every signature spelled
out. The precompiled set holds exactly what numba's JIT would have produced (the same object code, so
results are bit for bit those of a JIT compile), for the signatures the envs actually use.

``continuum-gym precompile --portable`` builds the set for LLVM's generic x86-64 CPU instead of this
machine's, so it can be shipped to other machines (e.g. inside a wheel or a container image); it loads
on any CPU of the same architecture. The kernels are scalar code, so the generic build gives up little or
no speed against a native one, and computes the same bits.

``CONTINUUM_GYM_PRECOMPILED=0`` ignores the set (measuring a JIT cold start, debugging a kernel).

A compile is never silent: when a kernel (the package's or a user's plug-in) is compiled because neither
place has it, one line on stderr names it (not the kernels it compiles along the way) and says whether it is
cached afterwards; a kernel loaded from a cache says nothing. ``CONTINUUM_GYM_COMPILE_MESSAGES=0`` silences it.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import json
import os
import platform
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import llvmlite
import numba
import numpy as np
from numba.core import event as numba_event
from numba.core.caching import FunctionCache, IndexDataCacheFile, NullCache  # numba >= 0.49; tested with 0.68

PACKAGE_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_PRECOMPILED_DIR = PACKAGE_ROOT / "_precompiled"
PORTABLE_CPU = "generic"

# The layer a ``continuum-gym precompile`` worker writes; a module global, not thread-local: batch
# chunks compile on worker threads.
_writing: dict[str, str | None] = {"layer": None}


def precompiled_dir() -> Path:
    """Directory of the precompiled set: ``CONTINUUM_GYM_PRECOMPILED_DIR`` or ``continuum_gym/_precompiled``."""
    override = os.environ.get("CONTINUUM_GYM_PRECOMPILED_DIR")
    return Path(override) if override else DEFAULT_PRECOMPILED_DIR


def precompiled_enabled() -> bool:
    """False when ``CONTINUUM_GYM_PRECOMPILED=0``: kernels then come from numba's cache or its compiler."""
    value = os.environ.get("CONTINUUM_GYM_PRECOMPILED", "1").strip().lower()
    if value not in ("0", "1", "false", "true", "no", "yes", ""):
        raise ValueError(f"CONTINUUM_GYM_PRECOMPILED must be 0 or 1; got {value!r}")
    return value not in ("0", "false", "no")


#: The precompiled set's manifest: its digest, per-source hashes (``sources``), CPU, numba version, ...
MANIFEST = "manifest.json"


def code_hash(source: bytes) -> str:
    """sha256 of a module's code as a compiler sees it: its syntax tree without docstrings and comments.

    ``ast.dump`` leaves out line numbers, so moving code or editing a docstring or a comment keeps the
    hash; any change to a statement, a name or a constant (which kernels freeze at compile time) changes it.
    """
    tree = ast.parse(source)
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and body \
                and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                and isinstance(body[0].value.value, str):
            body[0] = ast.Pass()
    return hashlib.sha256(ast.dump(tree).encode()).hexdigest()


def source_hashes(known: dict | None = None) -> dict[str, list[str]]:
    """{module path: [sha256 of its bytes, :func:`code_hash`]} for every ``.py`` file of the package.

    ``known`` (a manifest's ``sources``) saves parsing files whose bytes are unchanged since it was written.
    """
    known = known or {}
    hashes = {}
    for path in sorted(PACKAGE_ROOT.rglob("*.py")):
        name = path.relative_to(PACKAGE_ROOT).as_posix()
        data = path.read_bytes()
        raw = hashlib.sha256(data).hexdigest()
        entry = known.get(name)
        hashes[name] = [raw, entry[1] if isinstance(entry, list) and len(entry) == 2 and entry[0] == raw
                        else code_hash(data)]
    return hashes


def digest_of(hashes: dict) -> str:
    """The digest of a package's :func:`source_hashes` and of this compiler stack's versions."""
    digest = hashlib.sha256()
    for part in (sys.version, numba.__version__, llvmlite.__version__, np.__version__, platform.machine()):
        digest.update(part.encode() + b"\0")
    for name, (_, code) in sorted(hashes.items()):
        digest.update(f"{name}\0{code}\0".encode())
    return digest.hexdigest()


@functools.cache
def source_digest() -> str:
    """The digest that stamps the precompiled set: the package's code and the compiler stack's versions.

    Any edited statement, another numba, llvmlite, numpy or Python gives another digest, and the whole
    set misses instead of serving code compiled from other sources. Docstrings and comments are not
    part of it (:func:`code_hash`). Only files whose bytes changed since the set was built are parsed,
    so the digest costs milliseconds on an unedited install.
    """
    try:
        known = json.loads((precompiled_dir() / MANIFEST).read_text()).get("sources")
    except (OSError, ValueError, AttributeError):
        known = None
    return digest_of(source_hashes(known if isinstance(known, dict) else None))


def portable_magic(codegen: Any) -> tuple[str, str, str]:
    """numba's codegen key for LLVM's generic CPU of this target triple (``NUMBA_CPU_NAME=generic``)."""
    return (codegen.magic_tuple()[0], PORTABLE_CPU, "")


class writing_precompiled:
    """Context in which compiled kernels go to ``layer`` of the precompiled set (``continuum-gym precompile``).

    The set is a directory of layers, one per precompile worker (they run in parallel, so each writes
    its own); a kernel is looked up in every layer.
    """

    def __init__(self, layer: str) -> None:
        self.layer = layer

    def __enter__(self) -> writing_precompiled:
        _writing["layer"] = self.layer
        return self

    def __exit__(self, *exc) -> None:
        _writing["layer"] = None


class PrecompiledFirstCache(FunctionCache):
    """numba's per-function cache, consulted after the precompiled set (see the module docstring)."""

    def __init__(self, py_func: Callable, cache_key: Callable[[Any], bytes] | None = None) -> None:
        super().__init__(py_func)
        self._cache_key = cache_key
        self._module_dir = py_func.__module__.replace(".", "-")
        # numba names its entries <module>.<qualname>-<first line>: in the set, without the line, so that
        # code moving within its file keeps its entries (the index key holds the bytecode's hash anyway).
        qualname = py_func.__qualname__.replace("<locals>", "").replace("<", "").replace(">", "")
        self._filename_base = f"{py_func.__module__}.{qualname}-py{sys.version_info[0]}{sys.version_info[1]}"
        self._set_dir = precompiled_dir()
        self._layers: dict[str, IndexDataCacheFile] = {}

    def _index_key(self, sig, codegen):
        """numba's key (signature, CPU, the function's bytecode), and what ``cache_key`` says the compiled code
        depends on beyond its own file (the library's batched loop: the env's row functions)."""
        key = super()._index_key(sig, codegen)
        if self._cache_key is None:
            return key
        from numba.core import sigutils

        args, _ = sigutils.normalize_signature(sig)
        return (*key[:2], (*key[2], hashlib.sha256(self._cache_key(args)).hexdigest()))

    def _layer(self, name: str) -> IndexDataCacheFile:
        if name not in self._layers:
            self._layers[name] = IndexDataCacheFile(
                cache_path=str(self._set_dir / name / self._module_dir),
                filename_base=self._filename_base,
                source_stamp=source_digest(),
            )
        return self._layers[name]

    def _layer_names(self) -> list:
        writing = _writing["layer"]
        if writing is not None:
            return [writing]
        try:
            return sorted(entry.name for entry in os.scandir(self._set_dir) if entry.is_dir())
        except FileNotFoundError:
            return []

    def _load_overload(self, sig, target_context):
        if not self._enabled:
            return None
        writing = _writing["layer"] is not None
        if writing or precompiled_enabled():
            codegen = target_context.codegen()
            sig_key, host_magic, code_hashes = self._index_key(sig, codegen)
            for name in self._layer_names():
                for magic in (host_magic, portable_magic(codegen)):
                    data = self._layer(name).load((sig_key, magic, code_hashes))
                    if data is not None:
                        return self._impl.rebuild(target_context, data)
        if writing:
            return None  # compile, so that the set gets this signature
        return super()._load_overload(sig, target_context)

    def _save_overload(self, sig, data):
        layer = _writing["layer"]
        if layer is None:
            return super()._save_overload(sig, data)
        if not self._enabled or not self._impl.check_cachable(data):
            return None
        (self._set_dir / layer / self._module_dir).mkdir(parents=True, exist_ok=True)
        self._layer(layer).save(self._index_key(sig, data.codegen), self._impl.reduce(data))
        return None


def compile_messages_enabled() -> bool:
    """False when ``CONTINUUM_GYM_COMPILE_MESSAGES=0``: compiles are not announced on stderr."""
    value = os.environ.get("CONTINUUM_GYM_COMPILE_MESSAGES", "1").strip().lower()
    return value not in ("0", "false", "no")


class CompileAnnouncer(numba_event.Listener):
    """Says on stderr which kernel numba compiles, once per compile that a user waits for.

    numba fires ``numba:compile`` only when it compiles (after both caches missed); the kernels compiled
    inside that compile (its callees) are part of it and not named. numba's own uncached helpers (typed
    lists), which compile in every process in a fraction of a second, are not named either.
    """

    def __init__(self) -> None:
        self._local = threading.local()
        self.count = 0  #: compiles named so far in this process (silenced or not)

    def on_start(self, event: numba_event.Event) -> None:
        stack = self._local.__dict__.setdefault("stack", [])
        dispatcher = (event.data or {}).get("dispatcher")
        py_func = getattr(dispatcher, "py_func", None)  # None for numba's lifted loops: part of their function
        cached = not isinstance(getattr(dispatcher, "_cache", None), NullCache)
        module = getattr(py_func, "__module__", None) or ""
        named = py_func is not None and (cached or not module.startswith("numba")) and not any(stack)
        stack.append(named)
        self.count += named
        if named and compile_messages_enabled():
            where = ("once: cached on disk afterwards; `continuum-gym precompile` compiles ahead of time" if cached
                     else "not cached: it compiles again in every process; declare it @njit(cache=True)")
            print(f"continuum-gym: compiling {module}.{getattr(py_func, '__qualname__', '?')} with numba "
                  f"(seconds to minutes, {where})", file=sys.stderr, flush=True)

    def on_end(self, event: numba_event.Event) -> None:
        stack = self._local.__dict__.get("stack")
        if stack:
            stack.pop()


def _announcer() -> Any:
    """The process's one announcer, registered with numba once (also if this module is imported again)."""
    for listener in getattr(numba_event, "_registered", {}).get("numba:compile", []):
        if type(listener).__name__ == CompileAnnouncer.__name__:
            return listener
    listener = CompileAnnouncer()
    numba_event.register("numba:compile", listener)
    return listener


#: Counts and announces the compiles of this process (``ANNOUNCER.count``).
ANNOUNCER = _announcer()


def kernel(func: Callable | None = None, *, borrows: bool = False, cache_key: Callable[[Any], bytes] | None = None,
           **options: Any) -> Any:
    """``numba.njit(cache=True, **options)`` whose compiled code also comes from the precompiled set.

    Use as ``@kernel`` or ``@kernel(inline="always")``; options are numba's.

    ``cache_key(argument types) -> bytes`` adds to the kernel's cache key what its compiled code depends on
    besides its own source file (numba checks only that file): the library's batched loop names the modules of
    the row functions it inlines for those types (``envs/rows.py``).

    ``borrows=True`` compiles the kernel without numba's reference counting (numba's ``_nrt=False``):
    it only borrows the arrays it is passed, for the duration of the call. A kernel that calls another
    (not inlined) one otherwise keeps an atomic incref / decref of every array it reads from its
    bundles, because the call may raise. In a step kernel those atomics cost nearly as much as the
    arithmetic around them, so the step kernels' per-row functions borrow (the same bits: the arithmetic
    is the same code). A borrowing kernel cannot allocate (numba refuses to type
    ``np.empty`` there) and must not call a kernel that returns a new array (nothing would free it):
    ``tests/envs/test_borrowing_kernels.py`` steps every step path with numba's allocation statistics on
    and requires as many frees as allocations. A borrowing kernel that takes the registered plug-in slots
    (numba typed lists) is declared ``no_cpython_wrapper=True`` (numba's option): it is called only from
    other kernels, and a Python entry would unbox those lists, which needs reference counting.
    """
    # Explicit either way: a kernel that leaves it unset inherits its caller's setting, so an allocating
    # kernel called from a borrowing one would be typed without reference counting, and fail.
    options["_nrt"] = not borrows

    def decorate(py_func: Callable):
        dispatcher = numba.njit(cache=True, **options)(py_func)
        # numba has no public hook for a dispatcher's cache class; enable_caching() sets this attribute.
        # Should a future numba change it, kernels keep numba's own cache (tests/robots/test_compiled.py
        # fails then, so it does not go unnoticed).
        if isinstance(getattr(dispatcher, "_cache", None), FunctionCache):
            dispatcher._cache = PrecompiledFirstCache(py_func, cache_key)
        return dispatcher

    return decorate if func is None else decorate(func)

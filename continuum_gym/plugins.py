"""Where a researcher's plug-ins come from, so that any process can rebuild them by importing.

A plug-in (robot, task family, controller, reward term) exists once the code that registers it has
run. Another process has not run that code: a worker of ``AsyncVectorEnv`` or SB3's
``SubprocVecEnv``, a Ray trial, a fresh interpreter unpickling an env, a colleague reading a run's
``config.yml``. So each registration records the importable module that made it (its *origin*), and a
lookup that misses imports what it knows of before it gives up:

1. the module of a ``"module:name"`` reference (accepted wherever a registered name is);
2. the modules named in the environment variable ``CONTINUUM_GYM_PLUGINS`` (comma-separated): every
   registration from an importable module adds it, so child processes, which inherit the environment,
   import it too;
3. the entry points of the group ``continuum_gym.plugins`` that installed packages declare
   (``[project.entry-points."continuum_gym.plugins"] my_lab = "my_lab.plugins"``).

A registration made in ``__main__`` or a notebook has no importable origin: it works in its own
process, and a lookup elsewhere fails with an error that says so and how to fix it.
"""

from __future__ import annotations

import importlib
import os
import sys
from collections.abc import Callable, Iterable, Mapping
from importlib import metadata
from types import ModuleType
from typing import Any

from continuum_gym.validation import closest, describe

#: Environment variable listing plug-in modules (comma-separated) that every process imports on a miss.
ENV_VAR = "CONTINUUM_GYM_PLUGINS"
#: Entry-point group of installed packages that provide plug-ins.
ENTRY_POINT_GROUP = "continuum_gym.plugins"

_FIX = ("register it at import of an importable module (not __main__ or a notebook) and import that module: "
        "`continuum-gym --import MODULE` on the command line, an entry point in the group "
        f"'{ENTRY_POINT_GROUP}', the environment variable {ENV_VAR}=MODULE, or the reference 'MODULE:NAME' "
        "in place of the name")

_loaded_entry_points = False


def caller_origin(depth: int = 2) -> str | None:
    """The importable module whose code called the registering function ``depth`` frames up, or None.

    None for code run as a script, in a notebook or through ``exec``: no other process can import it.
    """
    frame = sys._getframe(depth)
    name = frame.f_globals.get("__name__")
    module = sys.modules.get(name) if isinstance(name, str) else None
    if module is None or module.__dict__ is not frame.f_globals:
        return None
    spec = getattr(module, "__spec__", None)
    if spec is None or not spec.name or spec.name == "__main__":
        return None
    return spec.name  # for `python -m my_lab.run`, __main__'s spec names my_lab.run


def remember(origin: str | None) -> None:
    """Add ``origin`` to ``CONTINUUM_GYM_PLUGINS`` so that child processes import it on a miss."""
    if not origin:
        return
    known = [m for m in os.environ.get(ENV_VAR, "").split(",") if m]
    if origin not in known:
        os.environ[ENV_VAR] = ",".join([*known, origin])


def import_modules(modules: Iterable[str], what: str = "plug-in module") -> list[ModuleType]:
    """Import each module, with an error that names it and why it failed."""
    imported = []
    for name in modules:
        if not isinstance(name, str) or not name or any(part == "" or not part.isidentifier()
                                                        for part in name.split(".")):
            raise ValueError(f"{what} must be a dotted module name such as my_lab.plugins; got {describe(name)}")
        try:
            imported.append(importlib.import_module(name))
        except ImportError as error:
            raise ValueError(f"{what} {name!r} cannot be imported ({error}); it must be importable in this "
                             "process: install its package or add its folder to PYTHONPATH") from error
    return imported


def load_entry_points() -> list[str]:
    """Import every entry point of the group ``continuum_gym.plugins`` once; a callable one is called."""
    global _loaded_entry_points
    if _loaded_entry_points:
        return []
    _loaded_entry_points = True
    names = []
    for entry in metadata.entry_points(group=ENTRY_POINT_GROUP):
        try:
            loaded = entry.load()
        except Exception as error:  # a broken plug-in package is named, not hidden
            raise ValueError(f"entry point {entry.name!r} = {entry.value!r} of the group '{ENTRY_POINT_GROUP}' "
                             f"failed to load: {error!r}") from error
        if callable(loaded) and not isinstance(loaded, ModuleType):
            loaded()
        names.append(entry.value)
    return names


def load_known() -> None:
    """Import the modules of ``CONTINUUM_GYM_PLUGINS`` and the installed entry points."""
    modules = [m.strip() for m in os.environ.get(ENV_VAR, "").split(",") if m.strip()]
    import_modules([m for m in modules if m not in sys.modules], f"module of {ENV_VAR}")
    load_entry_points()


def load_object(reference: str) -> Any:
    """The object a ``"module:name"`` reference names, its module imported now."""
    module, _, name = reference.partition(":")
    return getattr(importlib.import_module(module), name)


def lazy_exports(package: str, exports: dict[str, str]) -> Callable[[str], Any]:
    """A package's module ``__getattr__``: ``name`` from its submodule ``exports[name]``, imported on first use (so
    that importing the package registers its ids without compiling anything)."""
    def __getattr__(name: str) -> Any:
        if name in exports:
            return getattr(importlib.import_module(f"{package}.{exports[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__


def split_reference(value: str) -> tuple[str | None, str]:
    """``"my_lab.plugins:dls"`` -> ``("my_lab.plugins", "dls")``; a plain name -> ``(None, name)``."""
    if ":" not in value:
        return None, value
    module, _, name = value.partition(":")
    return module, name


def lookup(table: Mapping[str, Any], value: str, what: str, env_id: str) -> str:
    """The registered name ``value`` refers to, importing its origin if needed.

    ``value`` is a name or a ``"module:name"`` reference; ``table`` is the registry's table of ``env_id``
    (filled by the imports). Raises ``ValueError`` naming what is missing and where registration must happen.
    """
    module, name = split_reference(value)
    if module is not None:
        import_modules([module], f"module of the {what} reference {value!r}")
    if name in table:
        return name
    load_known()
    if name in table:
        return name
    where = f" by {module}" if module else ""
    raise ValueError(f"{what} {name!r} is not registered in this process{where}{closest(name, table)} (registered "
                     f"for {env_id}: {sorted(table)}). A plug-in exists in the process whose code registered it; "
                     f"for other processes (vector-env workers, Ray trials, a fresh interpreter), {_FIX}")


def reference(name: str, origin: str | None) -> str:
    """``"origin:name"`` when the plug-in's module is importable, else the bare name."""
    return f"{origin}:{name}" if origin else name


__all__ = ["load_object", "lazy_exports", "ENV_VAR", "ENTRY_POINT_GROUP", "caller_origin", "remember", "import_modules",
           "load_entry_points", "load_known", "split_reference", "lookup", "reference"]

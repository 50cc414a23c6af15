"""The library's front ends of an environment, made from its spec and row functions: no env writes its own.

``front_ends(spec, rows, module, doc)`` returns the env's batched core class (``BatchedCore`` bound to the
spec), its ``gymnasium.Env`` (a core of one) and its native ``VectorEnv``, named after the env and placed in
``module`` (so that they pickle and their entry points, e.g. ``continuum_gym.envs.occlusion:OcclusionAvoidanceEnv``,
import them). The SB3 adapter and the goal front end take the core class from the spec.
"""

from __future__ import annotations

from typing import Any

from gymnasium.vector import VectorEnv

from continuum_gym.envs.batched import BatchedCore
from continuum_gym.envs.declared import info_fields
from continuum_gym.envs.info import fields_table
from continuum_gym.envs.single import ContinuumEnv
from continuum_gym.envs.vector import ContinuumVectorEnv


def env_docstring(template: str, rows: Any, config_class: Any, observation: str = "") -> str:
    """An env's docstring: ``{info}`` filled with the table of its ``info`` entries (from its declared columns),
    ``{arguments}`` with its config's keyword table (``EnvConfig.arguments_table``), indented as the docstring is,
    and ``{observation}`` with ``observation`` (its layout's ``Layout.table``)."""
    arguments = "\n".join("    " + line for line in config_class.arguments_table().splitlines())
    fields = info_fields((rows.metrics, rows.flags), rows.info)
    return template.replace("{info}", fields_table(fields)).replace("{arguments}", arguments) \
        .replace("{observation}", observation)


def front_ends(spec: Any, rows: Any, module: str, doc: str, core_name: str = "") -> tuple[type, type, type]:
    """(core class, env class, vector env class) of ``spec`` (an ``EnvSpec``), in ``module``. The core class is
    named ``core_name`` (default ``<ShortName>Core``): the module must bind it under that name so that it pickles."""
    core = type(core_name or f"{spec.short_name}Core", (BatchedCore,), {"spec": spec, "rows": rows, "__module__": module,
                                                "__doc__": f"The batched core of {spec.env_id} (``BatchedCore``)."})
    env_name = spec.entry_point.rpartition(":")[2]
    vector_name = spec.vector_entry_point.rpartition(":")[2]
    env = type(env_name, (ContinuumEnv,), {"core_class": core, "__doc__": doc, "__module__": module})
    # VectorEnv listed again: clients such as skrl look for it among the direct bases
    vector = type(vector_name, (ContinuumVectorEnv, VectorEnv), {
        "core_class": core, "__module__": module,
        "__doc__": f"Native batched vector version of {spec.env_id} (one compiled call per step).\n\n    " + doc})
    for cls in (core, env, vector):
        cls.__qualname__ = cls.__name__
    return core, env, vector


__all__ = ["front_ends", "env_docstring"]

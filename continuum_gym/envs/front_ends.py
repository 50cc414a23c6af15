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

#: The docstring sections every env shares, filled in by ``env_docstring``.
_SHARED = {
    "{image_modes}": """    With ``obs_mode`` other than ``"state"`` (``"rgb"``, ``"depth"``, ``"segmentation"``, ``"rgbd"``,
    ``"rgb+depth+segmentation"``; ``image_size``, default 64) the observation is a ``Dict`` of the endoscope's
    images (``rgb`` (H, W, 3) uint8, ``depth`` (H, W, 1) float32 m along the optical axis, ``segmentation``
    (H, W, 1) uint8 ids) and ``state``, what a real system measures (the env's docs page, "Image observations").""",
    "{info_intro}": """    One layout for the single env, the native vector env and the SB3 adapter: numpy scalars
    (float64, bool_, int64) and arrays in the single env, (N, ...) arrays with Gymnasium's ``_<key>``
    masks in the vector env.""",
    "{info_terms}": """    - ``reward_terms``: the weighted reward terms, read by name like a dict (``info["reward_terms"]["{term}"]``;
      their sum is the reward) and a float64 array in ``reward_terms.names`` order; ``action_clipped``: the
      action was clipped to [-1, 1]. In an image ``obs_mode`` the env's pixel metric is added.""",
    "{threads}": """    ``num_threads``: threads a batch of {min_rows} rows or more is stepped on (1 to ``NUMBA_NUM_THREADS``;
    default 1 when torch is loaded in the process, so a learner's own threads are not oversubscribed,
    else all of numba's threads); results do not depend on it.""",
    "{version_history}": """    ## Version History
    - v0 (continuum-gym 0.1): initial release. Later in 0.1, with the same dynamics and rewards: robots,
      tasks, controllers and reward terms as plug-ins; ``info`` holds numpy scalars, and the weighted
      reward terms ``reward_terms`` a named float64 array (still read like the former dict); the vector env
      takes ``autoreset_mode``, ``reset_mask``, ``render_mode``, ``camera`` and ``pixel_occlusion``.
      In 0.3, still v0 with the same state observations and rewards: ``obs_mode`` and ``image_size``
      (image observations), and the research helpers moved out of the env options into named base
      controllers and helpers (CHANGELOG.md).""",
}


def env_docstring(template: str, rows: Any, config_class: Any, observation: str = "") -> str:
    """An env's docstring: ``{info}`` filled with the table of its ``info`` entries (from its declared columns),
    ``{arguments}`` with its config's keyword table (``EnvConfig.arguments_table``), indented as the docstring is,
    ``{observation}`` with ``observation`` (its layout's ``Layout.table``), and the sections every env shares
    (``{image_modes}``, ``{info_intro}``, ``{info_terms}``, ``{threads}``, ``{version_history}``)."""
    arguments = "\n".join("    " + line for line in config_class.arguments_table().splitlines())
    fields = info_fields((rows.metrics, rows.flags), rows.info)
    for key, text in _SHARED.items():
        template = template.replace(key, text)
    return template.replace("{info}", fields_table(fields)).replace("{arguments}", arguments) \
        .replace("{observation}", observation).replace("{min_rows}", str(rows.parallel_min_rows)) \
        .replace("{term}", rows.reward_terms[0] if rows.reward_terms else "")


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

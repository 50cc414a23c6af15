"""continuum-gym: Gymnasium environments for continuum surgical robots beside an endoscope.

``import continuum_gym`` registers the ``ContinuumGym/`` environment ids with Gymnasium, then imports the
researcher's plug-in modules this process is told of (the environment variable ``CONTINUUM_GYM_PLUGINS`` and
the entry points of the group ``continuum_gym.plugins``; see ``continuum_gym.plugins``), so that their ids work
with a plain ``gym.make`` as they do in the command line's processes.
``save_config(env, path)`` and ``make_from_config(path)`` write an env's configuration and make the
same env from it (``continuum_gym.config_files``; loaded on first use).
"""

__version__ = "0.2.0"

from continuum_gym.envs.spec import ENV_IDS, register_envs  # noqa: E402

register_envs()

_EXPORTS = {"save_config": "config_files", "make_from_config": "config_files", "load_config": "config_files"}
__all__ = ["__version__", "ENV_IDS", *sorted(_EXPORTS)]


def __getattr__(name: str):
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _load_plugins() -> None:
    """Import the plug-in modules this process is told of; one that fails is named in a warning, not fatal here
    (the ids of the library stay usable, and a lookup of that plug-in's names raises the full error)."""
    from continuum_gym import plugins

    try:
        plugins.load_known()
    except ValueError as error:
        import warnings

        warnings.warn(f"continuum_gym: a plug-in module was not loaded: {error}", stacklevel=3)


_load_plugins()

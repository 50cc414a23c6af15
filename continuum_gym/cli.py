"""The ``continuum-gym`` console script: one entry point, one module per subcommand.

Each subcommand module exposes ``add_arguments(parser)`` and ``run(args) -> int``; it is imported only
when its subcommand runs, so ``continuum-gym demo`` never pays for torch or pybullet.

A researcher's plug-ins (registered ids, robots, tasks, controllers, reward terms) are imported before
any argument is read: the modules given by ``--import MODULE`` (repeatable, before or after the
subcommand) and the entry points of the group ``continuum_gym.plugins`` of installed packages. Their
modules are passed on to every process the command starts (``CONTINUUM_GYM_PLUGINS``).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

IMPORT_FLAG = "--import"
IMPORT_HELP = ("import MODULE first (repeatable): a module that registers your own env ids, robots, tasks, "
               "controllers or reward terms, e.g. my_lab.plugins")

SUBCOMMANDS = {
    "demo": ("continuum_gym.evaluation.demo", "draw both robots with their view cone/frustums; print tip poses"),
    "reproduce": ("continuum_gym.evaluation.reproduce", "reproduce both papers' results: figures, table, JSON"),
    "train": ("continuum_gym.agents.train", "train a residual or pure-RL policy with stable-baselines3"),
    "evaluate": ("continuum_gym.evaluation.evaluate", "compare baselines and learned policies on held-out tasks"),
    "optimum": ("continuum_gym.evaluation.optimum", "offline optima and strong references (the ceiling)"),
    "render": ("continuum_gym.render.record", "record an episode: external and endoscope views"),
    "sweep": ("continuum_gym.agents.sweep", "multi-seed training and sweeps on Ray Tune"),
    "dataset": ("continuum_gym.evaluation.datasets", "record the baselines' episodes as Minari datasets (offline RL)"),
    "precompile": ("continuum_gym.precompile", "compile the kernels once per install: a first step in about a second"),
}


def split_imports(argv: list[str]) -> tuple[list[str], str | None]:
    """The ``--import`` modules of ``argv`` and the subcommand (the first word that is not an option's)."""
    modules, command, k = [], None, 0
    while k < len(argv):
        arg = argv[k]
        if arg == IMPORT_FLAG:
            if k + 1 >= len(argv):
                raise ValueError(f"{IMPORT_FLAG} needs a module name, e.g. {IMPORT_FLAG} my_lab.plugins")
            modules.append(argv[k + 1])
            k += 2
            continue
        if arg.startswith(IMPORT_FLAG + "="):
            modules.append(arg.split("=", 1)[1])
        elif command is None and not arg.startswith("-"):
            command = arg
        k += 1
    return modules, command


def load_plugins(modules: list[str]) -> None:
    """Import the ``--import`` modules and the installed plug-in entry points; children import them too."""
    import os

    from continuum_gym import plugins

    if modules and os.getcwd() not in sys.path:  # as `python -m` does: a module beside the user is found
        sys.path.insert(0, os.getcwd())
        os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (os.getcwd(), os.environ.get("PYTHONPATH")) if p)
    for module in plugins.import_modules(modules, f"{IMPORT_FLAG} module"):
        plugins.remember(module.__name__)
    plugins.load_known()  # CONTINUUM_GYM_PLUGINS and the installed entry points


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = argparse.ArgumentParser(prog="continuum-gym", description=__doc__.splitlines()[0])
    parser.add_argument(IMPORT_FLAG, action="append", default=[], metavar="MODULE", help=IMPORT_HELP)
    wanted = None
    try:
        modules, wanted = split_imports(argv)
        load_plugins(modules)  # before any parser is built: ids and names are checked against the registry
    except ValueError as error:
        parser.exit(2, f"continuum-gym{' ' + wanted if wanted else ''}: {error}\n")
    # Build only the parser of the requested subcommand: importing every module would import torch.
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module_name, help_text) in SUBCOMMANDS.items():
        subparser = sub.add_parser(name, help=help_text, description=help_text)
        subparser.add_argument(IMPORT_FLAG, action="append", default=[], metavar="MODULE", help=IMPORT_HELP,
                               dest="sub_imports")
        if name == wanted:
            try:
                module = importlib.import_module(module_name)
            except ModuleNotFoundError as error:
                if error.name != module_name:
                    raise
                parser.exit(2, f"continuum-gym: the '{name}' command is not available in this version\n")
            module.add_arguments(subparser)
            subparser.set_defaults(_run=module.run)
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    return int(args._run(args) or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

"""The ``continuum-gym`` console script: one entry point, one module per subcommand.

Each subcommand module exposes ``add_arguments(parser)`` and ``run(args) -> int``; it is imported only
when its subcommand runs, so ``continuum-gym demo`` never pays for torch or pybullet.
"""

from __future__ import annotations

import argparse
import importlib
import sys

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


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    # Build only the parser of the requested subcommand: importing every module would import torch.
    wanted = next((arg for arg in argv if not arg.startswith("-")), None)
    parser = argparse.ArgumentParser(prog="continuum-gym", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module_name, help_text) in SUBCOMMANDS.items():
        subparser = sub.add_parser(name, help=help_text, description=help_text)
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

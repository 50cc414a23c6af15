"""Copy trained runs into the package as shipped policies (model, config, learning curve, command).

    python experiments/ship_policies.py RUN_DIR [RUN_DIR ...] [--dest continuum_gym/agents/policies]

A run that was stopped before its end ships its newest verified checkpoint
(``checkpoints/step_<n>/model.zip``); the step count it reached is recorded in ``shipped.yml`` beside it.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import zipfile
from pathlib import Path

import yaml

from continuum_gym.agents.checkpoint import CHECKPOINTS, MODEL, find_resumable

DEST = Path(__file__).resolve().parents[1] / "continuum_gym" / "agents" / "policies"


def ship(run: Path, dest: Path) -> Path:
    config = yaml.safe_load((run / "config.yml").read_text())
    model = run / "model.zip"
    source, steps = "model.zip", None
    if model.exists():  # the steps the model was trained for (a whole number of rollouts past the budget)
        with zipfile.ZipFile(model) as archive:
            steps = int(json.loads(archive.read("data"))["num_timesteps"])
    else:
        unit, _ = find_resumable(run / CHECKPOINTS)
        if unit is None:
            raise FileNotFoundError(f"{run}: neither model.zip nor a verified checkpoint")
        model = unit.file(MODEL)
        source, steps = str(model.relative_to(run)), int(unit.state()["num_timesteps"])
    target = dest / config["env_id"].split("/")[-1] / run.name
    target.mkdir(parents=True, exist_ok=True)
    shutil.copy2(model, target / "model.zip")
    for name in ("config.yml", "args.yml", "command.txt", "evaluations.npz"):
        if (run / name).exists():
            shutil.copy2(run / name, target / name)
    (target / "shipped.yml").write_text(yaml.safe_dump({"source": source, "num_timesteps": steps}))
    return target


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--dest", type=Path, default=DEST)
    args = parser.parse_args(argv)
    for run in args.runs:
        print("shipped", ship(run, args.dest))
    return 0


if __name__ == "__main__":
    sys.exit(main())

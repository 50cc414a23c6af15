"""Copy the finished runs of the reference-results campaign into the repository (``reference-runs/``).

    python experiments/reference_runs/collect_reference_runs.py [--campaign ~/campaigns/reference] [--into reference-runs]

A run is finished when ``continuum-gym train`` has written its final ``model.zip`` beside its
``config.yml`` (checkpoints live in ``checkpoints/`` until then). Only what evaluation and
reproduction need is copied: ``model.zip``, ``config.yml``, ``args.yml``, ``command.txt`` and the
validation learning curve ``evaluations.npz`` (no checkpoints, replay buffers or TensorBoard logs), to
``reference-runs/<env>/<run>/``. A run already in the repository is left as it is: committed runs are
final, and a campaign restarted elsewhere trains only the seeds that are missing there.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]
FILES = ("model.zip", "config.yml", "args.yml", "command.txt", "evaluations.npz")


def finished_runs(campaign: Path) -> list[Path]:
    """Run directories under ``campaign`` whose final model is written."""
    return sorted(config.parent for config in campaign.rglob("config.yml")
                  if (config.parent / "model.zip").is_file() and config.parent.parent.name != "checkpoints")


def collect(campaign: Path, into: Path) -> list[Path]:
    """Copy each finished run not yet in ``into``; returns the new run folders."""
    added = []
    for run in finished_runs(campaign):
        config = yaml.safe_load((run / "config.yml").read_text())
        target = into / config["env_id"].split("/")[-1] / run.name
        if target.exists():
            continue
        target.mkdir(parents=True)
        for name in FILES:
            if (run / name).is_file():
                shutil.copy2(run / name, target / name)
        slim(target / "model.zip", config.get("algo", "ppo"))
        added.append(target)
    return added


def slim(path: Path, algo: str) -> None:
    """``path`` saved again without the last observation batch (``agents.train.FINAL_EXCLUDE``), as the trainer
    writes a final model since 0.3: runs of an earlier trainer kept it (20 MB of an image policy's 22 MB zip)."""
    from stable_baselines3 import PPO, SAC, TD3

    from continuum_gym.agents.train import save_model_atomic

    model = {"ppo": PPO, "sac": SAC, "td3": TD3}[algo].load(path, device="cpu")
    save_model_atomic(model, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaign", default=str(Path.home() / "campaigns" / "reference"))
    parser.add_argument("--into", default=str(ROOT / "reference-runs"))
    args = parser.parse_args(argv)
    campaign = Path(args.campaign).expanduser()
    if not campaign.is_dir():
        print(f"collect_reference_runs: no campaign folder {campaign}", file=sys.stderr)
        return 2
    for target in collect(campaign, Path(args.into)):
        print(f"added {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

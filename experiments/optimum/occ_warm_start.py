"""Issue 38, Campaign 9: start a run from a trained policy, so that ``run_queue.py`` fine-tunes it with new env options.

Writes the model of ``--from`` (a run directory with ``model.zip``) as the step-0 checkpoint of the run
``<root>/runs/<tag>/<run name>`` (the name ``continuum-gym train`` gives seed ``--seed``), then
``python experiments/optimum/run_queue.py <tag>:<seed> --src ...`` trains it for the ``n_timesteps`` of
``experiments/optimum/<tag>.yml`` with that file's env options (e.g. ``arc_plan: true``) from there.

    PYTHONPATH=. python experiments/optimum/occ_warm_start.py --tag occ_ep10_plan_ft --seed 0 \
        --from continuum_gym/agents/policies/OcclusionAvoidance-v0/OcclusionAvoidance_ppo_projected_gradient_seed0
"""

from __future__ import annotations

import argparse
from pathlib import Path

import yaml

HERE = Path(__file__).resolve().parent
ROOT = Path.home() / "campaigns" / "optimum"
ENV = "ContinuumGym/OcclusionAvoidance-v0"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tag", required=True, help="config tag: experiments/optimum/<tag>.yml")
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--from", dest="source", type=Path, required=True, help="run directory with model.zip")
    parser.add_argument("--root", type=Path, default=ROOT)
    args = parser.parse_args(argv)
    from stable_baselines3 import PPO

    from continuum_gym.agents.checkpoint import CHECKPOINTS, MODEL, write_unit
    from continuum_gym.agents.train import run_name

    hp = yaml.safe_load((HERE / f"{args.tag}.yml").read_text())[ENV]
    model = PPO.load(args.source / "model.zip", device="cpu")
    model.num_timesteps = 0  # the fine-tune's own budget counts from here
    run_dir = args.root / "runs" / args.tag / run_name(ENV, "ppo", "projected_gradient", args.seed)
    if (run_dir / CHECKPOINTS).exists():
        raise SystemExit(f"{run_dir} already has checkpoints: nothing overwritten")
    write_unit(run_dir / CHECKPOINTS, 0, {MODEL: model.save},
               {"algo": "ppo", "seed": args.seed, "total_timesteps": int(float(hp["n_timesteps"])),
                "elapsed_s": 0.0, "evaluations": [], "burn_in_steps": int(hp.get("burn_in_steps", 0)),
                "warm_started_from": str(args.source)})
    print(f"step-0 checkpoint of {run_dir}: the model of {args.source}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

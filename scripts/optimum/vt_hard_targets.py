"""Issue 38, Campaign 11: the training ``pan_tilt`` targets a ViewTracking residual settles near OR 0.8 on.

Runs a policy (with its config's env keywords, the overlap polish included) on training ``pan_tilt`` ids
0..count-1 and writes the ids whose final OR lies in ``[--low, --high]``: the edge of the reachable views, where
coverage is won or lost by 0.01-0.02 of OR (Campaign 6). ``vt_hard_mix.py`` fine-tunes on them. Training ids
only: the validation and test targets are drawn from other streams.

    PYTHONPATH=. python scripts/optimum/vt_hard_targets.py \
        continuum_gym/agents/policies/ViewTracking-v0/ViewTracking_ppo_dimension_reduced_seed0 \
        --count 8192 --out ~/campaigns/optimum/c11/hard_seed0.npy
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

VIEW = "ContinuumGym/ViewTracking-v0"


def main(argv: list[str] | None = None) -> int:
    from continuum_gym.envs.spec import get_spec
    from continuum_gym.evaluation.evaluate import load_policy, policy_env_kwargs
    from continuum_gym.evaluation.rollout import make_core, run_episodes

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="run directory (model.zip + config.yml)")
    parser.add_argument("--count", type=int, default=8192, help="training pan_tilt ids 0..count-1")
    parser.add_argument("--low", type=float, default=0.70, help="lowest final OR kept")
    parser.add_argument("--high", type=float, default=0.84, help="highest final OR kept")
    parser.add_argument("--out", type=Path, required=True, help=".npy of the kept ids (a .json summary beside it)")
    args = parser.parse_args(argv)
    if not 0.0 <= args.low < args.high <= 1.0:
        raise SystemExit(f"--low {args.low} and --high {args.high} must satisfy 0 <= low < high <= 1")

    model, config = load_policy(args.run)
    kwargs = dict(policy_env_kwargs(get_spec(VIEW), config), task="pan_tilt", task_split="train")
    ids = np.arange(args.count)
    final = run_episodes(make_core(VIEW, args.count, **kwargs), model, ids)["final_or"]
    keep = ids[(final >= args.low) & (final <= args.high)]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    np.save(args.out, keep)
    summary = {"run": str(args.run), "count": args.count, "band": [args.low, args.high], "kept": int(len(keep)),
               "coverage": float(100 * np.mean(final > 0.8)), "near_miss": int(np.sum((final > 0.75) & (final <= 0.8)))}
    args.out.with_suffix(".json").write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

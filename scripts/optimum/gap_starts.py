"""Issue 38, Campaign 4: the train split's hold starts on which a trained residual stays far from the optimum.

For each of the 512 train hold starts: the residual's final-step VOI (deterministic policy, the run's policy
keywords) and the offline hold optimum of the start (``env_hold_test_optimum(512, split="train")``, computed once
into ``<root>/results/train_hold_optimum.json``, about 6 CPU-minutes). The *gap* is final VOI - optimum: a large
gap is a start where the residual settles in a local minimum of VOI along the self-motion arc instead of
travelling to the best point. ``occ_wrapped.py``'s ``gap`` curriculum draws half its hold episodes from the
``--frac`` of starts with the largest gap. Train split only: nothing here reads validation or test tasks.

    PYTHONPATH=~/campaigns/optimum/src python scripts/optimum/gap_starts.py ~/campaigns/optimum/runs/occ_ep10/*seed0
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

ROOT = Path.home() / "campaigns" / "optimum"
OCC = "ContinuumGym/OcclusionAvoidance-v0"
N_TRAIN = 512


def train_optimum(root: Path) -> np.ndarray:
    path = root / "results" / "train_hold_optimum.json"
    if not path.exists():
        from continuum_gym.evaluation.optimum import env_hold_test_optimum

        path.write_text(json.dumps(env_hold_test_optimum(N_TRAIN, workers=1, progress=True, split="train")))
    return np.asarray(json.loads(path.read_text())["optimum_voi"], dtype=float)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="a trained OcclusionAvoidance run directory (config.yml + model.zip)")
    parser.add_argument("--frac", type=float, default=0.25, help="fraction of the starts called hard")
    parser.add_argument("--root", type=Path, default=ROOT)
    args = parser.parse_args(argv)
    from continuum_gym.envs.spec import get_spec
    from continuum_gym.evaluation.evaluate import load_policy, policy_env_kwargs
    from continuum_gym.evaluation.rollout import make_core, run_episodes

    optimum = train_optimum(args.root)
    model, config = load_policy(args.run)
    kwargs = policy_env_kwargs(get_spec(OCC), config)
    final, mean = [], []
    for first in range(0, N_TRAIN, 128):
        core = make_core(OCC, 128, **dict(kwargs, task="hold", task_split="train"))
        out = run_episodes(core, model, np.arange(first, first + 128), record=True)
        final.append(out["trace_voi"][-1])
        mean.append(out["mean_voi"])
    final, mean = np.concatenate(final), np.concatenate(mean)
    gap = final - optimum
    hard = np.argsort(gap)[::-1][:int(round(args.frac * N_TRAIN))]
    out = {"run": str(args.run), "frac": args.frac, "hard_starts": sorted(int(i) for i in hard),
           "final_voi_mean": float(final.mean()), "mean_voi_mean": float(mean.mean()),
           "optimum_mean": float(optimum.mean()), "gap_mean": float(gap.mean()),
           "hard_gap_mean": float(gap[hard].mean()), "final_voi": final.round(6).tolist(), "gap": gap.round(6).tolist()}
    (args.root / "results" / "gap_hard_starts.json").write_text(json.dumps(out))
    print({k: v for k, v in out.items() if not isinstance(v, list)})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

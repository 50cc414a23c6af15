"""Issue 38's check on cases never seen: OcclusionAvoidance hold tasks from fresh starts.

The env's hold tasks start from a pool of paper-like configurations drawn from one fixed seed per split
(``continuum_gym.envs.occlusion.tasks.hold_start_pool``). This draws the pool exactly as the env does, from
a seed the project never used (``--seed``), and scores the projected gradient, the shipped residual
policies and the offline hold optimum on the first ``--tasks`` of those starts: mean VOI, headroom closed
= (base - method) / (base - optimum), and the fraction of steps with the tip in view. Deterministic
policies, built with the policy keywords of their config, as ``continuum-gym evaluate`` does.

    python experiments/optimum/fresh_holds.py [--seed 20261204] [--tasks 128] [--policies DIR] [--json fresh_holds.json]
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
from pathlib import Path

import numpy as np

OCC = "ContinuumGym/OcclusionAvoidance-v0"
POLICIES = Path(__file__).resolve().parents[2] / "continuum_gym" / "agents" / "policies" / "OcclusionAvoidance-v0"
SPLIT = "test"  # the split's code enters the seed; the pool itself is new


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=20261204,
                        help="pool seed (the env's own, HOLD_POOL_SEED = 20251125, is a control)")
    parser.add_argument("--tasks", type=int, default=128, help="hold starts scored (the pool has 128)")
    parser.add_argument("--policies", type=Path, default=POLICIES, help="directory of the residual runs to score")
    parser.add_argument("--json", type=Path, help="also write the numbers here")
    args = parser.parse_args(argv)

    import continuum_gym.envs.occlusion.tasks as occlusion_tasks
    from continuum_gym.envs.benchmark import benchmark_of
    from continuum_gym.envs.spec import get_spec
    from continuum_gym.evaluation.methods import load_policy, policy_env_kwargs
    from continuum_gym.evaluation.optimum.occlusion import env_hold_test_optimum
    from continuum_gym.evaluation.rollout import ZeroResidual, make_core, run_episodes

    if args.seed == occlusion_tasks.HOLD_POOL_SEED:  # a control: the test split's own hold tasks
        print("control run: the env's own pool (the test split's hold tasks, as continuum-gym evaluate scores them)")
    # The env's task generator and the optimum both read the pool through this name: the fresh pool, same draw.
    occlusion_tasks.hold_start_pool = functools.partial(occlusion_tasks.hold_start_pool, seed=args.seed)
    spec = get_spec(OCC)
    ids = np.arange(args.tasks)

    def score(policy, env_kwargs: dict) -> dict:
        core = make_core(OCC, args.tasks, **dict(env_kwargs, task="hold", task_split=SPLIT))
        per = run_episodes(core, policy if policy is not None else ZeroResidual(core.single_action_space.shape[0]), ids)
        return {"voi": per["mean_voi"], "in_view": per["tip_in_view_fraction"]}

    base = score(None, {"base_controller": benchmark_of(spec).headline_baseline})
    optimum = np.asarray(env_hold_test_optimum(args.tasks, workers=2, progress=True, split=SPLIT)["optimum_voi"],
                         dtype=float)
    rows = {"projected_gradient": base}
    for run in sorted(args.policies.glob(f"*_{benchmark_of(spec).headline_baseline}_seed*")):
        model, config = load_policy(run)
        rows[run.name] = score(model, policy_env_kwargs(spec, config))
    base_voi, optimum_voi = float(np.mean(base["voi"])), float(np.nanmean(optimum))
    out = {"seed": args.seed, "tasks": args.tasks, "optimum_mean_voi": optimum_voi, "rows": {}}
    print(f"fresh hold starts: pool seed {args.seed}, tasks 0-{args.tasks - 1}; optimum mean VOI {optimum_voi:.4f}")
    print("| method | mean VOI | headroom closed | tip in view (mean / min) |\n|---|---|---|---|")
    for name, row in rows.items():
        voi = float(np.mean(row["voi"]))
        headroom = (base_voi - voi) / (base_voi - optimum_voi)
        out["rows"][name] = {"mean_voi": voi, "headroom_closed": headroom,
                             "tip_in_view_mean": float(np.mean(row["in_view"])),
                             "tip_in_view_min": float(np.min(row["in_view"]))}
        print(f"| {name} | {voi:.4f} | {headroom:.3f} | {np.mean(row['in_view']):.4f} / {np.min(row['in_view']):.4f} |")
    learned = [v["headroom_closed"] for k, v in out["rows"].items() if k != "projected_gradient"]
    print(f"residual mean headroom closed: {np.mean(learned):.3f} over {len(learned)} seeds")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

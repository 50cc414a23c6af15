"""Where the ViewTracking residual loses coverage (issue 38, Campaign 6), on validation ``pan_tilt`` targets.

For each target: the policy's final OR and its OR trace (``run_episodes(record=True)``), the offline optimum
(``view_tracking_optimum``) and the best OR a joint-rate residual of the policy's scale can hold
(``residual_reach.holdable_optimum``). Each target the policy misses (final OR <= 0.8) falls in one class:

* ``unreachable``: even the optimum is <= 0.8;
* ``not holdable``: the optimum is above 0.8 but no configuration a residual of this scale can hold is;
* ``near miss``: holdable, policy final OR in (0.75, 0.8];
* ``far miss``: holdable, policy final OR <= 0.75.

    PYTHONPATH=. python scripts/optimum/vt_failures.py \
        continuum_gym/agents/policies/ViewTracking-v0/ViewTracking_ppo_dimension_reduced_seed0 --count 1024
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

VIEW = "ContinuumGym/ViewTracking-v0"


def main(argv: list[str] | None = None) -> int:
    from continuum_gym.envs.spec import get_spec
    from continuum_gym.envs.view_tracking.tasks import view_tasks
    from continuum_gym.evaluation.evaluate import load_policy, policy_env_kwargs
    from continuum_gym.evaluation.optimum.view import view_tracking_optimum
    from continuum_gym.evaluation.residual_reach import holdable_optimum
    from continuum_gym.evaluation.rollout import make_core, run_episodes

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="run directory (model.zip + config.yml)")
    parser.add_argument("--count", type=int, default=512, help="validation pan_tilt ids 0..count-1")
    parser.add_argument("--effort", default="standard", help="view_tracking_optimum effort (quick/standard/heavy)")
    parser.add_argument("--reference", type=Path, default=None,
                        help="an earlier output for the same targets and residual scale: reuse its optimum and holdable OR")
    parser.add_argument("--out", type=Path, default=Path.home() / "campaigns/optimum/analysis/vt_failures.npz")
    args = parser.parse_args(argv)

    model, config = load_policy(args.run)
    kwargs = dict(policy_env_kwargs(get_spec(VIEW), config), task="pan_tilt", task_split="validation")
    core = make_core(VIEW, args.count, **kwargs)
    ids = np.arange(args.count)
    result = run_episodes(core, model, ids, record=True)
    final = result["final_or"]
    trace = result["trace_or"]
    targets = view_tasks("pan_tilt", "validation", ids, core.task_context).centre
    if args.reference is not None:
        ref = np.load(args.reference)
        if not np.array_equal(ref["targets"], targets):
            raise SystemExit(f"--reference {args.reference} holds other targets")
        opt, held, effort = {"overlap": ref["optimum"], "q": ref["q_opt"]}, ref["held"], ref["effort"]
    else:
        opt = view_tracking_optimum(targets, effort=args.effort, workers=1, progress=True, baselines=False)
        _, held, effort = holdable_optimum(opt["q"], targets, float(kwargs["residual_scale"]))
    miss = final <= 0.8
    classes = {"unreachable": miss & (opt["overlap"] <= 0.8),
               "not holdable": miss & (opt["overlap"] > 0.8) & ((held <= 0.8) | (effort > 1.0))}
    holdable = miss & ~classes["unreachable"] & ~classes["not holdable"]
    classes["near miss"] = holdable & (final > 0.75)
    classes["far miss"] = holdable & (final <= 0.75)
    summary = {"run": str(args.run), "count": args.count, "coverage": float(100 * np.mean(~miss)),
               "optimum_coverage": float(100 * np.mean(opt["overlap"] > 0.8)),
               "holdable_coverage": float(100 * np.mean((held > 0.8) & (effort <= 1.0))),
               **{name: int(mask.sum()) for name, mask in classes.items()}}
    print(json.dumps(summary, indent=1))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    np.savez(args.out, final=final, targets=targets, optimum=opt["overlap"], q_opt=opt["q"], held=held,
             effort=effort, trace=trace.astype(np.float32))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

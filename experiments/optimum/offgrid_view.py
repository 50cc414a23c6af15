"""Issue 38: ViewTracking coverage on off-grid targets (the issue's "same figure within 1 point" check).

The reported coverage is the share of the 21 x 21 ``coverage`` grid's targets whose final OR is above 0.8. This
check draws targets the grid does not contain: the **test** split's ``pan_tilt`` tasks (the coverage map's
region, drawn at random), ids 0 to ``--count`` - 1, and reports the same share, per policy and over the policies,
next to the 21 x 21 grid's figure computed here in the same way. Test split: run once per shipped candidate.

    PYTHONPATH=. python experiments/optimum/offgrid_view.py continuum_gym/agents/policies/ViewTracking-v0/*dimension*
    PYTHONPATH=. python experiments/optimum/offgrid_view.py --base continuum_gym.envs.view_tracking.distilled:distilled_optimum
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

ENV = "ContinuumGym/ViewTracking-v0"


def coverage(policy, env_kwargs: dict, task: str, count: int) -> float:
    """% of ``task`` test ids 0..count-1 whose final OR is above the coverage threshold."""
    from continuum_gym.envs.spec import get_spec
    from continuum_gym.evaluation.rollout import make_core, run_episodes

    metric = get_spec(ENV).metric("coverage_percent")
    core = make_core(ENV, count, **dict(env_kwargs, task=task, task_split="test"))
    final = run_episodes(core, policy, np.arange(count))[metric.grid_metric]
    return float(100.0 * np.mean(final > metric.threshold))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="*", type=Path, help="policy directories (model.zip + config.yml)")
    parser.add_argument("--base", action="append", default=[],
                        help="a base controller (name or module:name) with a zero residual (repeatable)")
    parser.add_argument("--count", type=int, default=1000, help="off-grid targets (test pan_tilt ids 0..count-1)")
    args = parser.parse_args(argv)
    from continuum_gym.envs.spec import get_spec
    from continuum_gym.evaluation.methods import load_policy, policy_env_kwargs
    from continuum_gym.evaluation.rollout import ZeroResidual

    rows = []
    jobs = [(base, None) for base in args.base] + [(None, run) for run in args.runs]
    for base, run in jobs:
        if run is None:
            model, kwargs = ZeroResidual(6), {"base_controller": base}
        else:
            model, config = load_policy(run)
            kwargs = policy_env_kwargs(get_spec(ENV), config)
        row = {"run": str(run or base), "grid_21x21": coverage(model, kwargs, "coverage", 441),
               f"off_grid_{args.count}": coverage(model, kwargs, "pan_tilt", args.count)}
        rows.append(row)
        print(json.dumps(row), flush=True)
    grid = np.mean([r["grid_21x21"] for r in rows])
    off = np.mean([r[f"off_grid_{args.count}"] for r in rows])
    print(f"mean over {len(rows)} policies: 21 x 21 grid {grid:.2f} %, off-grid {off:.2f} % "
          f"(difference {off - grid:+.2f} points)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

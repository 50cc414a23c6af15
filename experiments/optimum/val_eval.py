"""Validation-split measurements of the issue 38 campaign (experiments/notebook.md, "Validation measurement").

Scores trained runs (``RUN_DIR`` with ``config.yml`` + ``model.zip``), single checkpoints
(``RUN_DIR/checkpoints/step_<n>/model.zip``, with the run's ``config.yml``) or the analytic base
(``--base ENV``) on **validation** tasks only, through the library's evaluation path
(``continuum_gym.evaluation``: ``load_policy``, ``policy_env_kwargs``, ``make_core``, ``run_episodes``, ``ZeroResidual``):
deterministic policy, in the env built with the policy keywords of its config, as ``continuum-gym evaluate`` does.

* ViewTracking: ``mean_or`` = mean episode OR over validation ``static`` ids 0-31 + ``random`` ids 0-31;
  ``coverage`` = % of validation ``pan_tilt`` ids 0-4095 whose final OR is above the coverage threshold (0.8),
  the proxy for the test-only 21 x 21 coverage grid.
* ViewTracking ``--selection``: the coverage proxy on pan_tilt ids 4096-5119 only (disjoint from the reported
  ids), to choose among checkpoints; written to ``val_view_selection.jsonl``.
* OcclusionAvoidance: ``mean_voi`` over validation ``hold`` ids 0-31 + ``random`` ids 0-31; ``hold_voi`` over
  the hold tasks; ``headroom`` = (base - method) / (base - optimum) on the hold tasks, with the base (projected
  gradient, zero residual) measured here on the same tasks and the optimum the validation hold optimum of
  ``continuum_gym.evaluation.references.load_references(spec, {}, 32, 21, "validation")`` (user cache; computed
  once, minutes); ``tip_in_view`` (mean and minimum over episodes of the fraction of steps with the tip in view).

Each measurement appends one JSON line to ``<root>/results/val_<env>.jsonl`` and saves the per-task values to
``<root>/results/arrays/<tag>_<run>[_step<n>].npz``.

    python experiments/optimum/val_eval.py --tag occ_ep10 ~/campaigns/optimum/runs/occ_ep10/*seed*
    python experiments/optimum/val_eval.py --tag shipped continuum_gym/agents/policies/ViewTracking-v0/*dimension*
    python experiments/optimum/val_eval.py --base ContinuumGym/OcclusionAvoidance-v0
    python experiments/optimum/val_eval.py --pending occ_ep10   # the finished runs of runs/occ_ep10/ not yet scored
    python experiments/optimum/val_eval.py --selection --tag vt_mix_s3_lin20m RUN/checkpoints/step_*/model.zip RUN
"""

from __future__ import annotations

import argparse
import json
import re
import time
from pathlib import Path

import numpy as np

ROOT = Path.home() / "campaigns" / "optimum"
SPLIT = "validation"
VIEW, OCC = "ContinuumGym/ViewTracking-v0", "ContinuumGym/OcclusionAvoidance-v0"
# (task, number of ids from 0) per env: the protocol's non-grid task sets that have validation instances,
# and the coverage proxy.
TASKS = {VIEW: [("static", 32), ("random", 32), ("pan_tilt", 4096)], OCC: [("hold", 32), ("random", 32)]}
# --selection (ViewTracking): coverage on validation pan_tilt ids disjoint from the reported ones, for
# choosing a checkpoint without selecting on the ids it is then reported on.
SELECTION = ("pan_tilt", 1024, 4096)


def rollout(env_id: str, policy, env_kwargs: dict, task: str, count: int, first: int = 0) -> dict:
    """Per-episode metrics of ``policy`` (None: the zero residual, i.e. the base) on validation ids first..first+count-1."""
    from continuum_gym.evaluation.rollout import ZeroResidual, make_core, run_episodes

    core = make_core(env_id, count, **dict(env_kwargs, task=task, task_split=SPLIT))
    if policy is None:
        policy = ZeroResidual(core.single_action_space.shape[0])
    return run_episodes(core, policy, np.arange(first, first + count))


def hold_optimum() -> float:
    """Mean offline-optimum VOI of validation hold ids 0-31 (library cache, computed once when missing)."""
    from continuum_gym.envs.benchmark import benchmark_of
    from continuum_gym.envs.spec import get_spec
    from continuum_gym.evaluation.references import load_references

    spec = get_spec(OCC)
    ref = next(r for r in benchmark_of(spec).references if r.task == "hold")
    cache = load_references(spec, {}, 32, 21, SPLIT, progress=False, workers=1)
    return float(np.mean(np.asarray(cache[ref.cache_key][ref.values], dtype=float)[:32]))


def measure(env_id: str, policy, env_kwargs: dict, selection: bool = False) -> tuple[dict, dict]:
    """(summary, per-task arrays) of one policy on the env's validation task sets (or on ``SELECTION``)."""
    from continuum_gym.envs.spec import get_spec

    spec = get_spec(env_id)
    if selection:
        task, count, first = SELECTION
        coverage = spec.metric("coverage_percent")
        final = rollout(env_id, policy, env_kwargs, task, count, first)[coverage.grid_metric]
        return ({"selection_coverage": float(100.0 * np.mean(final > coverage.threshold)),
                 "selection_ids": f"{task} {first}-{first + count - 1}"}, {"selection_final_or": final})
    per = {task: rollout(env_id, policy, env_kwargs, task, count) for task, count in TASKS[env_id]}
    arrays = {}
    if env_id == VIEW:
        coverage = spec.metric("coverage_percent")
        final = per["pan_tilt"][coverage.grid_metric]
        summary = {"mean_or": float(np.mean(np.concatenate([per[t]["mean_or"] for t in ("static", "random")]))),
                   "coverage": float(100.0 * np.mean(final > coverage.threshold)),
                   "static_or": float(np.mean(per["static"]["mean_or"])),
                   "random_or": float(np.mean(per["random"]["mean_or"]))}
        arrays = {"pan_tilt_final_or": final, "static_or": per["static"]["mean_or"],
                  "random_or": per["random"]["mean_or"]}
    else:
        in_view = np.concatenate([per[t]["tip_in_view_fraction"] for t in ("hold", "random")])
        summary = {"mean_voi": float(np.mean(np.concatenate([per[t]["mean_voi"] for t in ("hold", "random")]))),
                   "hold_voi": float(np.mean(per["hold"]["mean_voi"])),
                   "random_voi": float(np.mean(per["random"]["mean_voi"])),
                   "tip_in_view_mean": float(np.mean(in_view)), "tip_in_view_min": float(np.min(in_view))}
        arrays = {"hold_voi": per["hold"]["mean_voi"], "random_voi": per["random"]["mean_voi"], "in_view": in_view}
    return summary, arrays


def occ_reference(root: Path) -> dict:
    """Validation hold VOI of the base (projected gradient) and of the offline optimum, cached in results/."""
    path = root / "results" / "occ_reference.json"
    if path.exists():
        return json.loads(path.read_text())
    from continuum_gym.envs.benchmark import benchmark_of

    base = benchmark_of(OCC).headline_baseline
    summary, _ = measure(OCC, None, {"base_controller": base})
    out = {"base": base, "base_hold_voi": summary["hold_voi"], "base_mean_voi": summary["mean_voi"],
           "optimum_hold_voi": hold_optimum(), "split": SPLIT}
    path.write_text(json.dumps(out, indent=1))
    return out


def load(target: Path):
    """(model, config, run dir, checkpoint step or None) of a run directory or a checkpoint's model.zip."""
    import yaml
    from stable_baselines3 import PPO, SAC, TD3

    from continuum_gym.evaluation.methods import load_policy

    if target.is_dir():
        model, config = load_policy(target)
        return model, config, target, None
    match = re.search(r"step_0*(\d+)$", target.parent.name)
    run = target.parents[2]
    config = yaml.safe_load((run / "config.yml").read_text())
    algo = {"ppo": PPO, "sac": SAC, "td3": TD3}[config["algo"]]
    return algo.load(target, device="cpu"), config, run, int(match.group(1)) if match else None


def pending(root: Path, tag: str) -> list[Path]:
    """Finished run directories of ``<root>/runs/<tag>/`` without a final-model result in either JSONL file."""
    done = set()
    for short in ("occ", "view"):
        path = root / "results" / f"val_{short}.jsonl"
        if path.exists():
            done |= {(r["tag"], r["run"]) for r in map(json.loads, path.read_text().splitlines())
                     if r["step"] is None}
    return [m.parent for m in sorted((root / "runs" / tag).glob("*/model.zip"))
            if (tag, str(m.parent.resolve())) not in done]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("targets", nargs="*", type=Path, help="run directories or checkpoint model.zip files")
    parser.add_argument("--tag", default="", help="label recorded with each result (e.g. the config tag)")
    parser.add_argument("--base", default=None, help="score the analytic base (zero residual) of this env id")
    parser.add_argument("--selection", action="store_true",
                        help="ViewTracking only: coverage on pan_tilt ids 4096-5119 (disjoint from the reported "
                        "0-4095), to <root>/results/val_view_selection.jsonl")
    parser.add_argument("--pending", default=None, metavar="TAG",
                        help="also score every finished run of <root>/runs/TAG/ that has no final result yet")
    parser.add_argument("--root", type=Path, default=ROOT, help=f"campaign directory (default {ROOT})")
    parser.add_argument("--base-controller", default=None,
                        help="with --base: this (e.g. registered) controller instead of the env's headline baseline")
    parser.add_argument("--polish", type=float, default=None,
                        help="the env's overlap_polish (for --base and the runs); with --base the residual scale is "
                        "set to the shipped residuals' 3, which the polish's step is a fraction of")
    parser.add_argument("--import", dest="imports", action="append", default=[],
                        help="plug-in module to import first (registered controllers, tasks)")
    args = parser.parse_args(argv)
    import importlib

    for module in args.imports:
        importlib.import_module(module)
    if args.pending:
        args.tag = args.tag or args.pending
        args.targets += pending(args.root, args.pending)
    from continuum_gym.envs.spec import get_spec
    from continuum_gym.evaluation.methods import policy_env_kwargs

    (args.root / "results" / "arrays").mkdir(parents=True, exist_ok=True)
    jobs = [(None, None) for _ in range(1 if args.base else 0)] + [(t, None) for t in args.targets]
    for target, _ in jobs:
        start = time.time()
        if target is None:
            env_id = args.base
            from continuum_gym.envs.benchmark import benchmark_of

            kwargs = {"base_controller": args.base_controller or benchmark_of(env_id).headline_baseline}
            if args.polish is not None:
                kwargs.update(overlap_polish=args.polish, residual_scale=3.0)
            model, run, step, name = None, None, None, "base"
        else:
            model, config, run, step = load(target.expanduser().resolve())
            env_id = config["env_id"]
            kwargs = policy_env_kwargs(get_spec(env_id), config)
            if args.polish is not None:
                kwargs["overlap_polish"] = args.polish
            name = run.name
        if args.selection and env_id != VIEW:
            raise SystemExit(f"--selection is defined for {VIEW} only")
        summary, arrays = measure(env_id, model, kwargs, args.selection)
        if env_id == OCC:
            ref = occ_reference(args.root)
            summary["headroom"] = (ref["base_hold_voi"] - summary["hold_voi"]) / (ref["base_hold_voi"] -
                                                                                  ref["optimum_hold_voi"])
            summary.update(base_hold_voi=ref["base_hold_voi"], optimum_hold_voi=ref["optimum_hold_voi"])
        seed = re.search(r"seed(\d+)$", name)
        record = {"tag": args.tag or ("base" if model is None else ""), "env_id": env_id, "split": SPLIT,
                  "run": str(run) if run else None, "seed": int(seed.group(1)) if seed else None, "step": step,
                  **summary, "eval_s": round(time.time() - start, 1),
                  "at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        short = ("view" if env_id == VIEW else "occ") + ("_selection" if args.selection else "")
        with open(args.root / "results" / f"val_{short}.jsonl", "a") as f:
            f.write(json.dumps(record) + "\n")
        suffix = (f"_step{step}" if step is not None else "") + ("_selection" if args.selection else "")
        np.savez(args.root / "results" / "arrays" / f"{args.tag or 'x'}_{name}{suffix}.npz", **arrays)
        print(json.dumps(record), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

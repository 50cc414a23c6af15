"""``continuum-gym optimum``: compute the offline optima, print their table, write JSON, figures and the cache."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from continuum_gym.envs.benchmark import benchmark_of
from continuum_gym.envs.spec import ENV_SPECS
from continuum_gym.evaluation.optimum.cache import CACHE_PATH, load_optimum_cache
from continuum_gym.evaluation.optimum.optima import optimum_of
from continuum_gym.evaluation.optimum.protocol import (
    COVERAGE_GRID,
    ENV_HOLD_TASKS,
    GLOBAL_CHECK_SAMPLE,
    HOLD_N_STARTS,
    HOLD_STARTS_SEED,
)
from continuum_gym.validation import integer

#: Tasks of each environment id (from its spec); ``all`` means every id.
ENV_TASKS = {env_id: benchmark_of(spec).optimum_tasks for env_id, spec in ENV_SPECS.items() if benchmark_of(spec).optimum_tasks}
TASKS = tuple(task for tasks in ENV_TASKS.values() for task in tasks)
#: The ids of the two papers' environments, found by the optimum tasks this command computes for them.
VIEW_TRACKING_ID = next(env_id for env_id, tasks in ENV_TASKS.items() if "coverage" in tasks)
OCCLUSION_ID = next(env_id for env_id, tasks in ENV_TASKS.items() if "hold" in tasks)


# ====================================================================== CLI
def resolve_tasks(env: str, task: str = "all") -> tuple[str, ...]:
    """Tasks to run for an env id (or ``all``) and a task name (or ``all``); ValueError names the bad one."""
    valid_envs = (*ENV_TASKS, "all")
    if env not in valid_envs:
        raise ValueError(f"env must be one of {', '.join(valid_envs)}; got {env!r}")
    available = TASKS if env == "all" else ENV_TASKS[env]
    if task == "all":
        return tuple(available)
    if task not in TASKS:
        raise ValueError(f"task must be one of {', '.join((*TASKS, 'all'))}; got {task!r}")
    if task not in available:
        raise ValueError(f"task {task!r} does not belong to env {env!r}; its tasks: {', '.join(available)}")
    return (task,)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", required=True,
                        help="environment id: " + ", ".join(f"{env_id} ({', '.join(tasks)})" for env_id, tasks in
                                                            ENV_TASKS.items()) + ", all, "
                             "or your registered id (its variant's ceiling, as evaluate uses it)")
    parser.add_argument("--task", default="all", help="coverage, hold, circle or all (default: the env's tasks)")
    parser.add_argument("--grid", type=int, default=COVERAGE_GRID, help="coverage grid points per axis (default 21)")
    parser.add_argument("--json", help="write the results as nested JSON to this path")
    parser.add_argument("--out", help="directory for the figures (PNG; a registered variant's are named after its id)")
    parser.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    parser.add_argument("--write-cache", action="store_true",
                        help=f"merge the results into the shipped cache {CACHE_PATH.name}")
    parser.add_argument("--n-starts", type=int, default=HOLD_N_STARTS, help="hold starts (default 59)")
    parser.add_argument("--seed", type=int, default=HOLD_STARTS_SEED, help="hold-start seed (default 2026)")
    parser.add_argument("--global-check", type=int, default=GLOBAL_CHECK_SAMPLE,
                        help="grid points re-solved by a heavy search to measure the optimality gap (0: skip)")
    parser.add_argument("--env-hold-tasks", type=int, default=ENV_HOLD_TASKS,
                        help="held-out hold tasks of the environment to solve (default 32, evaluate's --episodes)")
    parser.add_argument("--no-progress", action="store_true", help="hide progress bars")


def run(args: argparse.Namespace) -> int:
    if args.env not in (*ENV_TASKS, "all"):
        return run_variant(args)
    try:
        tasks = resolve_tasks(args.env, args.task)
        if "coverage" in tasks:
            integer(args.grid, "--grid (points per axis)", low=2)
        workers = integer(args.workers, "--workers", low=1)
        n_starts = integer(args.n_starts, "--n-starts", low=1)
        integer(args.global_check, "--global-check", low=0)
        integer(args.env_hold_tasks, "--env-hold-tasks", low=1)
        integer(args.seed, "--seed (hold-start seed)", low=0, high=2**32 - 1)
    except ValueError as error:
        print(f"continuum-gym optimum: error: {error}", file=sys.stderr)
        return 2
    from continuum_gym.evaluation.io import write_json_atomic
    from continuum_gym.evaluation.optimum.figures import (
        draw_circle,
        draw_coverage_maps,
        draw_hold,
    )
    from continuum_gym.evaluation.optimum.occlusion import (
        circle_optimum,
        env_hold_test_optimum,
        hold_study,
    )
    from continuum_gym.evaluation.optimum.rate_bound import env_hold_rate_bound
    from continuum_gym.evaluation.optimum.view import coverage_optimum

    progress = not args.no_progress
    results: dict[str, Any] = {}
    started = time.perf_counter()
    if "coverage" in tasks:
        results["coverage"] = coverage_optimum(args.grid, workers=workers, progress=progress,
                                               global_check=args.global_check)
    if "hold" in tasks:
        results["hold"] = hold_study(n_starts, args.seed, workers=workers, progress=progress)
        results["hold_test"] = env_hold_test_optimum(args.env_hold_tasks, workers=workers, progress=progress)
        results["hold_test_rate_bound"] = env_hold_rate_bound(args.env_hold_tasks, workers=workers,
                                                              progress=progress, traces=False)
    if "circle" in tasks:
        t0 = time.perf_counter()
        results["circle"] = circle_optimum(progress=progress)
        results["circle"]["wall_time_s"] = round(time.perf_counter() - t0, 1)
    results["meta"] = {"command": "continuum-gym " + " ".join(sys.argv[1:]), "tasks": list(tasks),
                       "wall_time_s": round(time.perf_counter() - started, 1)}
    print(summary_table(results))
    if args.json:
        write_json_atomic(args.json, results)
        print(f"wrote {args.json}")
    if args.write_cache:
        merged = load_optimum_cache() if CACHE_PATH.exists() else {}
        merged.update({k: v for k, v in results.items() if k != "meta"})
        write_json_atomic(CACHE_PATH, merged)
        CACHE_PATH.chmod(0o644)  # a shipped package file (the atomic temp file is created 0600)
        print(f"updated {CACHE_PATH}")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        if "coverage" in results:
            print("wrote", draw_coverage_maps(results["coverage"], out / "optimum_coverage_maps.png"))
        if "hold" in results:
            print("wrote", draw_hold(results["hold"], out / "optimum_hold.png"))
        if "circle" in results:
            print("wrote", draw_circle(results["circle"], out / "optimum_circle.png"))
    return 0


def run_variant(args: argparse.Namespace) -> int:
    """A user's registered id: the ceiling of its own variant, as ``evaluate`` uses it (computed once, cached).

    The variant's robot, cone or endoscope and limits come from the keywords the id was registered with;
    OcclusionAvoidance variants get the hold optimum of their held-out hold tasks, ViewTracking variants
    the coverage optimum on their grid.
    """
    from continuum_gym.envs.spec import get_spec, registered_kwargs
    from continuum_gym.evaluation.io import write_json_atomic
    from continuum_gym.evaluation.references import load_references

    try:
        spec = get_spec(args.env)
        workers = integer(args.workers, "--workers", low=1)
        grid = integer(args.grid, "--grid (points per axis)", low=2)
        episodes = integer(args.env_hold_tasks, "--env-hold-tasks", low=1)
        if args.task not in ("all", *benchmark_of(spec).optimum_tasks):
            raise ValueError(f"task {args.task!r} does not belong to {args.env!r}; its tasks: "
                             f"{', '.join(benchmark_of(spec).optimum_tasks)} or all")
        if args.write_cache:
            raise ValueError("--write-cache updates the shipped cache of the paper's environments; a variant's "
                             "optimum is kept in the user cache ($CONTINUUM_GYM_CACHE) by itself")
        if args.out and Path(args.out).exists() and not Path(args.out).is_dir():
            raise ValueError(f"--out must be a directory for the figures; {args.out!r} is an existing file")
    except ValueError as error:
        print(f"continuum-gym optimum: error: {error}", file=sys.stderr)
        return 2
    if not benchmark_of(spec).physics or optimum_of(spec.env_id) is None:
        print(f"continuum-gym optimum: {args.env} has no known offline optimum: its environment "
              f"({spec.short_name}) registers none (evaluation.optimum.register_optimum) or its Benchmark names no "
              f"physics it depends on; nothing "
              "computed, nothing written", file=sys.stderr)
        return 1
    started = time.perf_counter()
    results = load_references(spec, registered_kwargs(args.env), episodes=episodes, grid=grid, split="test",
                              progress=not args.no_progress, workers=workers) or {}
    rows = ["| variant | quantity | value |", "|---|---|---|"]
    if "hold_test" in results:
        voi = results["hold_test"]["optimum_voi"]
        rows.append(f"| {args.env} | hold optimum mean VOI ({len(voi)} held-out hold tasks) | "
                    f"{sum(voi) / len(voi):.3f} |")
    if "hold_test_rate_bound" in results:
        b = results["hold_test_rate_bound"]
        rows.append(f"| {args.env} | rate-limited bound / planned trajectory, episode-mean VOI | "
                    f"{b['mean_of_mean_voi_bound']:.3f} / {b['mean_of_mean_voi_plan']:.3f} |")
    if "coverage" in results:
        c = results["coverage"]
        rows.append(f"| {args.env} | coverage {c['grid']}x{c['grid']}, offline optimum OR > 0.8 | "
                    f"{c['optimum_percent']:.1f} % |")
    print("\n".join(rows))
    results["meta"] = {"command": "continuum-gym " + " ".join(sys.argv[1:]), "env_id": args.env,
                       "wall_time_s": round(time.perf_counter() - started, 1)}
    if args.json:
        write_json_atomic(args.json, results)
        print(f"wrote {args.json}")
    if args.out:
        written = variant_figures(args.env, spec, results, Path(args.out))
        for path in written:
            print(f"wrote {path}")
        if not written:
            print(f"continuum-gym optimum: the optimum of {args.env} has nothing to draw (it holds "
                  f"{sorted(k for k in results if k != 'meta')}); no figure written to {args.out}", file=sys.stderr)
            return 1
    return 0


def variant_figures(env_id: str, spec: Any, results: dict, out: Path) -> list[Path]:
    """The figures of a variant's optimum (those of its env's table rows), named after its id; the paths written."""
    from continuum_gym.evaluation.optimum.figures import draw_coverage_maps, draw_hold_test

    keys = {row.cache_key for row in benchmark_of(spec).references} & set(results)
    short = env_id.split("/")[-1].rsplit("-v", 1)[0]
    written = []
    if keys:
        out.mkdir(parents=True, exist_ok=True)
    if "coverage" in keys:
        written.append(draw_coverage_maps(results["coverage"], out / f"{short}_optimum_coverage_maps.png"))
    if "hold_test" in keys:
        hold = results["hold_test"]
        written.append(draw_hold_test(hold, results.get("hold_test_rate_bound") if "hold_test_rate_bound" in keys
                                      else None, out / f"{short}_optimum_hold_test.png",
                                      f"{env_id}: offline optimum of {len(hold['optimum_voi'])} held-out hold tasks"))
    return written


def summary_table(results: dict) -> str:
    """A short Markdown table of the headline numbers."""
    rows = ["| task | quantity | value |", "|---|---|---|"]
    if "coverage" in results:
        c = results["coverage"]
        rows += [f"| coverage {c['grid']}x{c['grid']} | offline optimum, OR > 0.8 | {c['optimum_percent']:.1f} % "
                 f"(mean OR {c['optimum_mean_or']:.3f}) |",
                 f"| | unreachable (optimum OR <= 0.8) | {c['unreachable_percent']:.1f} % |",
                 f"| | bounded least squares | {c['bounded_least_squares_percent']:.1f} % |",
                 f"| | dimension-reduced IK / RMRC | {c['dimension_reduced_percent']:.1f} % / "
                 f"{c['resolved_rate_percent']:.1f} % |"]
        if "global_check" in c:
            g = c["global_check"]
            rows.append(f"| | heavy-search gap on {len(g['indices'])} points | max {g['max_gap']:.2e}, "
                        f"mean {g['mean_gap']:.2e} |")
        rows.append(f"| | wall time | {c['wall_time_s']:.0f} s ({c['workers']} workers) |")
    if "hold" in results:
        h = results["hold"]
        rows += [f"| hold ({h['n_starts']} starts) | optimum VOI median / mean | {h['optimum_median_voi']:.3f} / "
                 f"{h['optimum_mean_voi']:.3f} |",
                 f"| | projected gradient median / mean | {h['projected_gradient_median_voi']:.3f} / "
                 f"{h['projected_gradient_mean_voi']:.3f} |",
                 f"| | self-motion only (centring gamma) median | {h['centring_gamma_median_voi']:.3f} |",
                 f"| | optimum <= PG | {100 * h['fraction_optimum_le_projected_gradient']:.0f} % of starts |",
                 f"| | wall time | {h['wall_time_s']:.0f} s |"]
    if "hold_test" in results:
        voi = results["hold_test"]["optimum_voi"]
        rows.append(f"| env hold tasks ({len(voi)}, test) | optimum mean VOI | {sum(voi) / len(voi):.3f} |")
    if "hold_test_rate_bound" in results:
        b = results["hold_test_rate_bound"]
        rows.append(f"| | rate-limited bound on the episode-mean VOI ({b['steps']} steps of {b['dt']:g} s) | "
                    f"{b['mean_of_mean_voi_bound']:.3f} |")
        rows.append(f"| | planned trajectory along the self-motion arc (achievable episode-mean VOI) | "
                    f"{b['mean_of_mean_voi_plan']:.3f} |")
    if "circle" in results:
        c = results["circle"]
        rows += [f"| circle | optimum mean VOI (gamma free) | {c['optimum_mean_voi']:.3f} |",
                 f"| | optimum mean VOI (centring gamma) | {c['centring_gamma_mean_voi']:.3f} |",
                 f"| | wall time | {c.get('wall_time_s', float('nan')):.0f} s |"]
    return "\n".join(rows)

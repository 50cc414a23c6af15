"""Offline optima and strong references: the ceiling for every comparison (issue 8).

``continuum-gym optimum --env ID [--task coverage|hold|circle|all] [--grid N] [--json PATH] [--out DIR]``

**View tracking** (paper 001, ``ContinuumGym/ViewTracking-v0``):

- :func:`bounded_least_squares` — a pose fit within the joint limits: scipy ``least_squares`` (trf, bounds)
  on the target-point error (m) and the orientation error log(R_target R^T) (rad) scaled by
  ``LSQ_ORIENTATION_WEIGHT`` = 0.05 m/rad (1 rad of orientation error costs as much as 5 cm of
  position error; 0.05 gives 82.5 % on the 21 x 21 grid, 0.1 gives 81.2 %, 0.01 gives 71.7 %).
  One start (Psi0), like the baselines. It is the strong reference a skeptic would ask for.
- :func:`view_tracking_optimum` — the largest overlap ratio OR reachable within the joint limits:
  L-BFGS-B on -OR (OR is piecewise smooth) from the DR, RMRC and bounded-LSQ solutions and random
  starts, plus scipy's ``differential_evolution`` (vectorised population, seeded, no polish), then
  L-BFGS-B and Nelder-Mead polishing of the best. Every candidate is a real configuration within the
  limits, and the raw starts are candidates too, so the optimum is never below any of them.

  *Roll.* The frustum is square, so it is symmetric under image rolls of 90 degrees: OR does not see
  roll flips (paper-notes §4). The optimum maximises OR only; it may reach it with the continuum image
  rolled by about 90 or 180 degrees against the da Vinci image. ``roll_error`` reports that roll
  (angle of the continuum camera's x axis in the da Vinci image plane) for each solution.

**Occlusion avoidance** (paper 000, ``ContinuumGym/OcclusionAvoidance-v0``), within the env's limits
(``OcclusionLimits``: bends |pi/2 - theta| <= 90 degrees, insertion 0-40 mm) and its visibility
requirement (tip within ``visibility`` = 0.7 of the cone half-angle beta from the view axis):

- :func:`trace_self_motion` — the one-dimensional self-motion set of a held tip pose (7 joints, 6-D
  pose), traced by predictor-corrector continuation from q0 in both directions.
- :func:`hold_optimum` — the lowest VOI over the arc of that set containing q0 and the feasible
  endoscope rotations gamma (the tip is fixed, so the feasible gamma set is the same for the whole arc).
- :func:`hold_rate_bound` / :func:`env_hold_rate_bound` — what an *episode* can reach: a lower bound on the
  VOI after each control step of a hold task, for any controller that holds the tip within the rate limits
  (its mean bounds the episode-mean VOI the evaluation scores; the hold optimum is its floor);
  :func:`hold_arc_plan` — a feasible trajectory along the arc from the task's start, an episode-mean VOI that
  is achievable. The best episode any controller can make lies between the two.
- :func:`circle_optimum` — for task (b), a time-connected lower bound: at sampled times the arc is the
  connected component reached from the previous time's optimum, minimised over the arc and gamma.

Results for the evaluation's task sets are shipped in ``data/optimum_cache.json``
(:func:`load_optimum_cache`); regenerate with
``continuum-gym optimum --env all --task all --write-cache``.
"""

import importlib

#: Public name -> submodule; loaded on first use, so ``continuum-gym optimum --help`` imports no solver.
_EXPORTS = {
    "CACHE_PATH": "cache", "cache_value": "cache", "load_optimum_cache": "cache",
    "ENV_TASKS": "cli", "OCCLUSION_ID": "cli", "VIEW_TRACKING_ID": "cli", "add_arguments": "cli",
    "resolve_tasks": "cli", "run": "cli", "summary_table": "cli",
    "draw_circle": "figures", "draw_coverage_maps": "figures", "draw_hold": "figures",
    "centring_gamma": "occlusion", "circle_optimum": "occlusion", "env_hold_test_optimum": "occlusion",
    "feasible_gamma_intervals": "occlusion", "hold_optimum": "occlusion", "hold_study": "occlusion",
    "projected_gradient_hold": "occlusion",
    "arc_travel": "rate_bound", "env_hold_rate_bound": "rate_bound", "hold_rate_bound": "rate_bound",
    # the planner and the self-motion tracer live with the controllers (the env's arc_plan base runs them)
    "GAMMA_RESOLUTION": "continuum_gym.baselines.arc_plan", "gamma_grid": "continuum_gym.baselines.arc_plan",
    "hold_arc_plan": "continuum_gym.baselines.arc_plan",
    "HOLD_N_STARTS": "protocol", "HOLD_STARTS_SEED": "protocol", "LSQ_ORIENTATION_WEIGHT": "protocol",
    "VISIBILITY": "protocol",
    "SelfMotion": "continuum_gym.baselines.self_motion", "trace_self_motion": "continuum_gym.baselines.self_motion",
    "INSERTION_SCALE": "continuum_gym.baselines.self_motion", "TRACE_STEP": "continuum_gym.baselines.self_motion",
    "OPTIMA": "optima", "register_optimum": "optima", "optimum_of": "optima",
    "bounded_least_squares": "view", "coverage_optimum": "view", "overlap_of_configuration": "view",
    "view_tracking_optimum": "view",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        module = _EXPORTS[name]
        return getattr(importlib.import_module(module if "." in module else f"{__name__}.{module}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

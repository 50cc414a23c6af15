"""The fixed settings of the offline-optimum study (seeds, grids, starts, visibility), in one light module.

Changing one changes the shipped cache's numbers: regenerate it with
``continuum-gym optimum --env all --task all --write-cache``.
"""

#: Orientation weight of the bounded least-squares fit (m per rad of orientation error).
LSQ_ORIENTATION_WEIGHT = 0.05
#: Hold starts: ``sample_hold_starts(MultiBackboneRobot(), HOLD_N_STARTS, np.random.default_rng(HOLD_STARTS_SEED))``.
HOLD_STARTS_SEED = 2026
HOLD_N_STARTS = 59
#: Tip within this fraction of the cone half-angle from the view axis (the evaluation's requirement).
VISIBILITY = 0.7
#: Sampling interval (s) of the circle's time-connected bound.
CIRCLE_SAMPLE_DT = 0.1
#: Default coverage grid (points per axis) and global-optimality check sample size.
COVERAGE_GRID = 21
GLOBAL_CHECK_SAMPLE = 10
#: Seed of every random start and of differential evolution (per point: seed + index).
OPTIMUM_SEED = 0
#: Held-out hold tasks of the environment the cache covers (evaluate's default --episodes).
ENV_HOLD_TASKS = 32

#!/usr/bin/env bash
# Issue 56's reference campaign: residual PPO from pixels (ppo_pixels.yml), seeds 0-2 per env, CPUS trials at a time
# (default 1), niced, resumable at any moment (`--resume` never re-runs a finished trial; an interrupted one continues
# from its newest checkpoint). Usage: [CPUS=n] [NICE=n] bash experiments/pixels/run_campaign.sh [OUT] [ENV ...]
# Run it from a checkout that nothing edits while it runs (e.g. `git worktree add`): Ray's trial workers import
# continuum_gym from the driver's working directory, ahead of PYTHONPATH; each run's config.yml records that commit.
set -euo pipefail
out=${1:-$HOME/campaigns/pixels}
shift || true
envs=("${@:-ContinuumGym/OcclusionAvoidance-v0}")
[ $# -eq 0 ] && envs=(ContinuumGym/OcclusionAvoidance-v0 ContinuumGym/ViewTracking-v0)
export OMP_NUM_THREADS=1 RAY_OVERRIDE_RESOURCES="{\"CPU\": ${CPUS:-1}}"   # Ray sees CPUS CPUs: that many trials at once
for env in "${envs[@]}"; do
  short=${env#ContinuumGym/}; short=${short%-v0}
  nice -n ${NICE:-10} continuum-gym sweep --env "$env" --algo ppo --hyperparams ppo_pixels.yml --seeds 0 1 2 \
    --out "$out" --name "${short}_ppo_rgbd" --cpus-per-trial 1 --resume
done

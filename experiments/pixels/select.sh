#!/usr/bin/env bash
# Link the runs the pixel table compares into OUT/<env>/: per env, the PPO residuals from pixels (`*_rgbd_seed*`)
# and the PPO state residuals on the same base (reference-runs/, 5 seeds), so that one evaluation puts the base,
# the state residual and the pixel residual on the same test episodes. Usage:
#   bash experiments/pixels/select.sh OUT [ENV ...]       (ENV: OcclusionAvoidance, ViewTracking; default both)
#   continuum-gym evaluate --policies OUT --env ContinuumGym/<ENV>-v0 --pixel-metrics --split test --json OUT/results.json
#   python experiments/pixels/report.py OUT/results.json [MORE.json ...]
# Each env's base is its benchmark's headline base (`benchmark_of(spec).headline_baseline`).
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
out=${1:?usage: select.sh OUT [ENV ...]}
shift
envs=("$@")
[ ${#envs[@]} -eq 0 ] && envs=(OcclusionAvoidance ViewTracking)
for env in "${envs[@]}"; do
  b=$(python -c "import sys; from continuum_gym.envs.benchmark import benchmark_of
print(benchmark_of(f'ContinuumGym/{sys.argv[1]}-v0').headline_baseline)" "$env")
  mkdir -p "$out/$env-v0"
  n=0
  for run in "$root/reference-runs/$env-v0/${env}_ppo_${b}_seed"* "$root/reference-runs/$env-v0/${env}_ppo_${b}_rgbd_seed"*; do
    [ -f "$run/model.zip" ] || continue
    ln -sfn "$run" "$out/$env-v0/$(basename "$run")"
    n=$((n + 1))
  done
  echo "$env: $n runs linked into $out/$env-v0"
done

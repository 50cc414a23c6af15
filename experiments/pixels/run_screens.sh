#!/usr/bin/env bash
# Issue 56's validation screens: two lanes of niced training runs, seed 0, the validation curve (16 episodes
# every 50k steps) in each run's evaluations.npz; compared at 200k steps (the machine was shared: a screen got
# about a third of a core). Usage: bash experiments/pixels/run_screens.sh OUT
set -euo pipefail
out=${1:-$HOME/campaigns/pixels/screens}
here=$(cd "$(dirname "$0")" && pwd)
export OMP_NUM_THREADS=1
lane() {
  for name in "$@"; do
    case $name in occ_*) env=ContinuumGym/OcclusionAvoidance-v0 ;; *) env=ContinuumGym/ViewTracking-v0 ;; esac
    /usr/bin/time -f "$name cpu_s=%U+%S wall_s=%e" nice -n 10 continuum-gym train --env "$env" \
      --hyperparams "$here/screens/$name.yml" --steps 200000 --out "$out/$name" --no-progress --resume \
      >>"$out/$name.log" 2>&1
  done
}
mkdir -p "$out"
lane ${LANE_A-occ_small occ_small_shift} &
lane ${LANE_B-occ_nature vt_small} &
wait

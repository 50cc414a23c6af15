#!/bin/bash
# Issue 38, Campaign 3: train each item (tag:seeds) one at a time, then score it on validation.
#   scripts/optimum/screen_chain.sh occ_ep10:0-4 occ_cur:0 ...
# Tags with an entry in occ_wrapped.py's SETTINGS train through occ_wrapped.py (niced, OMP_NUM_THREADS=1, the
# frozen src); every other tag through run_queue.py. After each item: val_eval.py --pending TAG.
# Halts before an item (or a seed of a wrapped tag) when <root>/STOP exists.
cd "$(dirname "$0")/../.." && source .venv/bin/activate
R=~/campaigns/optimum
WRAPPED=$(python -c "import sys; sys.path.insert(0, 'scripts/optimum'); import occ_wrapped; print(' '.join(occ_wrapped.SETTINGS))")
for item in "$@"; do
  [ -e $R/STOP ] && { echo "STOP: halting before $item"; exit 0; }
  tag=${item%%:*}
  if [[ " $WRAPPED " == *" $tag "* ]]; then
    for s in $(python -c "import sys; sys.path.insert(0, 'scripts/optimum'); import run_queue as q; print(' '.join(str(s) for _, s in q.parse_item('$item')))"); do
      [ -e $R/STOP ] && { echo "STOP: halting before $tag $s"; exit 0; }
      ls $R/runs/$tag/*_seed$s/model.zip >/dev/null 2>&1 && { echo "skip $tag $s"; continue; }
      echo "$(date -u +%T) train $tag seed $s"
      OMP_NUM_THREADS=1 PYTHONPATH=$R/src nice -n 15 python scripts/optimum/occ_wrapped.py $tag --seed $s > $R/logs/${tag}_seed$s.log 2>&1
      echo "$(date -u +%T) done $tag seed $s rc=$?"
    done
  else
    python scripts/optimum/run_queue.py "$item"
  fi
  OMP_NUM_THREADS=1 PYTHONPATH=$R/src nice -n 15 python scripts/optimum/val_eval.py --pending "$tag"
done
echo "chain done $(date -u +%T)"

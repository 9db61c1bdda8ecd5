#!/usr/bin/env bash
# Two command lines at once, one per GPU of a 2-GPU machine, under one deadline; after `source setup.sh`.
#   bash benchmarks/device/pair.sh LIMIT_S 'GPU 0 commands' 'GPU 1 commands'
# Each line runs in `bash -c` with CUDA_VISIBLE_DEVICES set and `left` (a function: the minutes left before the
# deadline, LIMIT_S minus a 45 s margin for packing, from this script's start) to pass as --time-limit "$(left)".
# Output goes to runs/gpu0.log and runs/gpu1.log (appended) without MuJoCo Warp's per-world solver-cap lines.
set -uo pipefail
limit=${1:?LIMIT_S}
export DEADLINE=$(( $(date +%s) + limit - 45 ))
left() { python3 -c "import time; print(round(max($DEADLINE - time.time(), 6) / 60, 3))"; }
export -f left
mkdir -p runs
pids=()
for gpu in 0 1; do
  cmd=${2:?GPU 0 commands}; [ "$gpu" = 1 ] && cmd=${3:-true}
  ( CUDA_VISIBLE_DEVICES=$gpu bash -c "$cmd" 2>&1 \
      | grep --line-buffered -v -e 'solver iterations limit reached' -e 'linesearch iterations limit reached' \
             -e 'To disable the print warning: m.opt.warn_overflow &= ~mjw.OverflowType.\(LS_\)\?ITERATIONS' \
      >> "runs/gpu$gpu.log"; exit "${PIPESTATUS[0]}" ) &
  pids+=($!)
done
for gpu in 0 1; do wait "${pids[$gpu]}"; echo "pair: GPU $gpu exited $?"; done
tail -n 5 runs/gpu0.log runs/gpu1.log

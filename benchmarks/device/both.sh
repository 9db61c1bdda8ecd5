#!/usr/bin/env bash
# Issue 63's whole runs and Experiment 4's mixed archive on a 2 x H200, after `source benchmarks/device/setup.sh`;
# run it again on the same warm machine until `six` and `alone` say done.
#   GPU 1: benchmarks/population.py --parts six    (the six map treatments at gpu-short, one 60-trial population)
#   GPU 0: benchmarks/population.py --parts alone  (the CPPN map treatment alone, 10 trials: the peer), then
#          docs/results/exp4/run.py archive mixed  (the humanoid's mixed archive) with the time left
# Usage: bash benchmarks/device/both.sh LIMIT_S. Returns in $OUT: population.tar.gz (the JSONs and every run file
# but checkpoints and full walkers; finished runs' walkers actor-only under runs/ship), exp4.tar.gz, the logs.
set -uo pipefail
here=$(dirname "$0")
pop='python3 benchmarks/population.py --preset gpu-short --backend warp --out runs/population --time-limit "$(left)"'
bash "$here/pair.sh" "${1:?LIMIT_S}" \
  "$pop --parts alone && python3 docs/results/exp4/run.py archive mixed --time-limit \"\$(left)\" --pack $OUT/exp4.tar.gz" \
  "$pop --parts six"
python3 "$here/ship.py" runs/population/six runs/population/alone --to runs/ship
tar czf "$OUT/population.tar.gz" --exclude='checkpoint*.npz' --exclude='runs/population/*/policy.msgpack' \
  runs/population runs/ship 2>/dev/null
cp runs/gpu0.log runs/gpu1.log "$OUT/"
ls -la "$OUT"

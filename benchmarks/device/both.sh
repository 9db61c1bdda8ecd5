#!/usr/bin/env bash
# Issue 63's whole runs and Experiment 4's ant archives on a 2 x H200, after `source benchmarks/device/setup.sh`;
# run it again on the same warm machine until `six` and `alone` say done.
#   GPU 1: benchmarks/population.py --parts six    (the six map treatments at gpu-short, one 60-trial population)
#   GPU 0: benchmarks/population.py --parts alone  (the CPPN map treatment alone, 10 trials: the peer), then
#          Experiment 4's archives for the ant (docs/results/exp4/run.py archive steps|mixed --robot ant), each
#          resumable from what exp4.tar.gz brings back
# Usage: bash benchmarks/device/both.sh LIMIT_S. Returns in $OUT: population.tar.gz (the JSONs and every run file
# but checkpoints and full walkers; finished runs' walkers actor-only under runs/ship), exp4.tar.gz, the logs.
set -uo pipefail
here=$(dirname "$0")
exp4='python3 docs/results/exp4/run.py archive'
# Experiment 4's folder: every packed archive in docs/results/exp4/archives/ (in git; a partial one resumes), or
# EXP4_TAR: what an earlier call's exp4.tar.gz holds
bash "$here/exp4_unpack.sh" || exit 1
pop='python3 benchmarks/population.py --preset gpu-short --backend warp --out runs/population --time-limit "$(left)"'
bash "$here/pair.sh" "${1:?LIMIT_S}" \
  "$pop --parts alone && $exp4 steps --robot ant --time-limit \"\$(left)\" --pack $OUT/exp4.tar.gz && $exp4 mixed --robot ant --time-limit \"\$(left)\" --pack $OUT/exp4.tar.gz" \
  "$pop --parts six"
python3 "$here/ship.py" runs/population/six runs/population/alone --to runs/ship
tar czf "$OUT/population.tar.gz" --exclude='checkpoint*.npz' --exclude='runs/population/*/policy.msgpack' \
  runs/population runs/ship 2>/dev/null
cp runs/gpu0.log runs/gpu1.log "$OUT/"
ls -la "$OUT"

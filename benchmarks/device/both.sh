#!/usr/bin/env bash
# On a 2 x H200 machine, after `source benchmarks/device/setup.sh`: issue 63's whole runs and Experiment 4's mixed
# archive, resumable across calls (run it again on the same warm machine until `six` and `alone` say done).
#   GPU 1: benchmarks/population.py --parts six    (the six map treatments at gpu-short, one 60-trial population)
#   GPU 0: benchmarks/population.py --parts alone  (the CPPN map treatment alone, 10 trials: the peer), then
#          docs/results/exp4/run.py archive mixed  (the humanoid's mixed archive) with the time left
# Usage: bash benchmarks/device/both.sh LIMIT_S   (LIMIT_S: this script's seconds, packing included)
# Returns in $OUT: population.tar.gz (the JSONs, every run file but checkpoints and full walkers; finished runs'
# walkers actor-only under runs/ship), exp4.tar.gz (run.py --pack), six.log, gpu0.log.
set -uo pipefail
limit=${1:?LIMIT_S}
t0=$(date +%s)
margin=50
mins=$(python3 -c "print(round(($limit - $margin) / 60, 3))")
mkdir -p runs
common=(--preset gpu-short --backend warp --time-limit "$mins" --out runs/population)
CUDA_VISIBLE_DEVICES=1 python3 benchmarks/population.py --parts six "${common[@]}" >> runs/six.log 2>&1 &
six=$!
(
  export CUDA_VISIBLE_DEVICES=0
  python3 benchmarks/population.py --parts alone "${common[@]}"
  rc=$?
  left=$((limit - margin - $(date +%s) + t0))
  if [ "$rc" = 0 ] && [ "$left" -gt 120 ]; then
    python3 docs/results/exp4/run.py archive mixed --time-limit "$(python3 -c "print(round($left / 60, 3))")" \
      --pack "$OUT/exp4.tar.gz"
  fi
) >> runs/gpu0.log 2>&1 &
gpu0=$!
wait $six; echo "both: six exited $?"; wait $gpu0; echo "both: gpu0 exited $?"
python3 benchmarks/device/ship.py runs/population/six runs/population/alone --to runs/ship
tar czf "$OUT/population.tar.gz" --exclude='checkpoint*.npz' --exclude='runs/population/*/policy.msgpack' \
  runs/population runs/ship 2>/dev/null
cp runs/six.log runs/gpu0.log "$OUT/"
tail -n 4 runs/six.log runs/gpu0.log
ls -la "$OUT"; echo "both: $(( $(date +%s) - t0 )) s"

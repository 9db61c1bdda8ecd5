#!/usr/bin/env bash
# Experiment 4's ant on a 2 x H200, after `source benchmarks/device/setup.sh`: its two chosen treatments, one per
# GPU (`run.py train ant --ant A B --shard K/2`), then, once both are trained and time is left, its held-out walks
# (`run.py evaluate --part K/2`, v2 then v1; the humanoid's walks come done in humanoid-heldout.tar.gz). Run it
# again on the same warm machine until both parts say done: a train's checkpoints do not come back, so both
# treatments must finish on one machine; the walks resume anywhere through the returned exp4.tar.gz (EXP4_TAR).
# Returns in $OUT: exp4.tar.gz (run.py's pack), the logs.
# Usage: bash benchmarks/device/exp4_ant.sh LIMIT_S [OBS/TREATMENT OBS/TREATMENT]
#   (default: blind/mixed-dr blind/mixed-levels, chosen from the humanoid's results in docs/results/exp4.md)
set -uo pipefail
here=$(dirname "$0")
limit=${1:?LIMIT_S}; shift
ant=${*:-blind/mixed-dr blind/mixed-levels}
set -- $ant
[ $# = 2 ] || { echo "exp4_ant.sh: give two OBS/TREATMENT (the ant's treatments), got: $ant" >&2; exit 2; }
start=$(date +%s)
run='python3 docs/results/exp4/run.py'
bash "$here/exp4_unpack.sh" || exit 1
bash "$here/pair.sh" "$limit" \
  "$run train ant --ant $ant --shard 0/2 --time-limit \"\$(left)\"" \
  "$run train ant --ant $ant --shard 1/2 --time-limit \"\$(left)\""
rest=$(( limit - ($(date +%s) - start) ))
if grep -q "train ant $1: done" runs/gpu0.log && grep -q "train ant $2: done" runs/gpu1.log && [ "$rest" -gt 150 ]
then exec bash "$here/exp4_eval.sh" "$rest"  # the walks left (the ant's), one part per GPU, then the pack
fi
$run --plan --pack "$OUT/exp4.tar.gz"
cp runs/gpu0.log runs/gpu1.log "$OUT/"
ls -la "$OUT"

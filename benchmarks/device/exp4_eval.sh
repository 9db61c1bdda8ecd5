#!/usr/bin/env bash
# Experiment 4's held-out walks (suite v2, then v1) on a 2 x H200, after `source benchmarks/device/setup.sh`: one
# `run.py evaluate --part K/2` per GPU into one store (every second walk each), under one deadline; run it again on
# the same warm machine, or on a fresh one with the returned exp4.tar.gz carried and EXP4_TAR set to it, until
# both parts say done. Returns in $OUT: exp4.tar.gz (run.py's pack: the trained walkers actor-only and the stores),
# the logs.
# Usage: bash benchmarks/device/exp4_eval.sh LIMIT_S
set -uo pipefail
here=$(dirname "$0")
limit=${1:?LIMIT_S}
run='python3 docs/results/exp4/run.py'
bash "$here/exp4_unpack.sh" || exit 1
bash "$here/pair.sh" "$limit" \
  "$run evaluate --part 0/2 --time-limit \"\$(left)\"" \
  "$run evaluate --part 1/2 --time-limit \"\$(left)\""
$run --plan --pack "$OUT/exp4.tar.gz"
cp runs/gpu0.log runs/gpu1.log "$OUT/"
ls -la "$OUT"

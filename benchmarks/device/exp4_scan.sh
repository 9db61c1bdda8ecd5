#!/usr/bin/env bash
# Experiment 4's perceptive humanoid retrained with the height scan's Adam steps scaled (docs/results/exp4/scan_diag)
# on a 2 x H200, after `source benchmarks/device/setup.sh`: one or two treatments, one per GPU (`run.py train humanoid
# perceptive --scan-lr-scale C --treatments T1 T2 --shard K/2`: one `learn --scan-lr-scale C` run each), then, once
# both are trained and time is left, their held-out walks (`run.py evaluate --part K/2`, v2 then v1; every other walk
# comes done in the shipped tars). Run it again on the same warm machine until both parts say done: a train's
# checkpoints do not come back, so both treatments must finish on one machine; the walks resume anywhere through the
# returned exp4.tar.gz (EXP4_TAR). Then, on the CPU, `run.py write` (its pages and the comparison with scale 1 and
# the blind walkers). Returns in $OUT: exp4.tar.gz (run.py's pack), the logs.
# Usage: bash benchmarks/device/exp4_scan.sh LIMIT_S [C] [TREATMENT [TREATMENT]]
#   (default: C 0.1, mixed-dr mixed-plr: the perceptive humanoid's best two at scale 1 by suite v2's IQM,
#   docs/results/exp4/humanoid-perceptive/v2/intervals.csv)
set -uo pipefail
here=$(dirname "$0")
limit=${1:?LIMIT_S}; shift
scale=0.1
case ${1:-} in [0-9.]*) scale=$1; shift;; esac
python3 -c "import math, sys; c = float(sys.argv[1]); sys.exit(not (math.isfinite(c) and c > 0 and c != 1))" \
  "$scale" 2>/dev/null || { echo "exp4_scan.sh: C must be a finite number > 0 other than 1, got $scale" >&2; exit 2; }
treatments=${*:-mixed-dr mixed-plr}
set -- $treatments
for t in "$@"; do
  case $t in steps-map|mixed-map|mixed-dr|mixed-plr|mixed-levels) ;;
    *) echo "exp4_scan.sh: TREATMENT must be one of steps-map mixed-map mixed-dr mixed-plr mixed-levels, got $t" >&2
       exit 2;; esac
done
[ $# -ge 1 ] && [ $# -le 2 ] || { echo "exp4_scan.sh: give one or two treatments (one per GPU), got: $treatments" >&2
                                  exit 2; }
start=$(date +%s)
run='python3 docs/results/exp4/run.py'
train="$run train humanoid perceptive --scan-lr-scale $scale --treatments $treatments"
bash "$here/exp4_unpack.sh" || exit 1
bash "$here/pair.sh" "$limit" \
  "$train --shard 0/2 --time-limit \"\$(left)\"" \
  "$( [ $# = 2 ] && echo "$train --shard 1/2 --time-limit \"\$(left)\"" )"
rest=$(( limit - ($(date +%s) - start) ))
done=1
for t in "$@"; do
  cat runs/gpu0.log runs/gpu1.log 2>/dev/null | grep -q "train humanoid perceptive-scan[^/]*/$t: done" || done=0
done
if [ "$done" = 1 ] && [ "$rest" -gt 150 ]
then exec bash "$here/exp4_eval.sh" "$rest"  # the walks left (the retrained walkers'), one part per GPU, then the pack
fi
$run --plan --pack "$OUT/exp4.tar.gz"
cp runs/gpu0.log runs/gpu1.log "$OUT/"
ls -la "$OUT"

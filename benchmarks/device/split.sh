#!/usr/bin/env bash
# Issue 63's two-GPU split and its interleaved evaluation orders on a 2 x H200, after `source
# benchmarks/device/setup.sh`. Usage: bash benchmarks/device/split.sh split|orders LIMIT_S
#   split:  benchmarks/population.py --parts split --devices 0,1 (the six map treatments at gpu-short, three per GPU
#           as two 30-trial populations), resumable: run it again on the same warm machine until it says done.
#           Returns population.tar.gz (runs/population's JSONs and run files but checkpoints and full walkers;
#           finished runs' walkers actor-only under runs/ship) and split.log.
#   orders: benchmarks/eval_order.py, the six as one 60-trial population on GPU 0 (3 rounds of 2 chunks) and the
#           CPPN map treatment alone on GPU 1 (5 rounds of 3 chunks), interleaved orders; returns eval_order.tar.gz
#           and the GPU logs.
# Each stops LIMIT_S seconds after it starts, less 45 s for packing (`--time-limit` from the deadline).
set -uo pipefail
here=$(dirname "$0")
what=${1:-}
limit=${2:-}
case "$what" in split|orders) ;; *) echo "split.sh: the first argument must be split or orders, got '$what'" >&2; exit 2 ;; esac
[[ "$limit" =~ ^[0-9]+$ ]] || { echo "split.sh: LIMIT_S must be a whole number of seconds, got '$limit'" >&2; exit 2; }
deadline=$(( $(date +%s) + limit - 45 ))
minutes() { python3 -c "import time; print(round(max($deadline - time.time(), 6) / 60, 3))"; }
mkdir -p runs
case "$what" in
  split)
    python3 benchmarks/population.py --parts split --devices 0,1 --preset gpu-short --backend warp \
      --out runs/population --time-limit "$(minutes)" 2>&1 \
      | grep --line-buffered -v -e 'iterations limit reached' -e 'warn_overflow' | tee -a runs/split.log | tail -n 40
    python3 "$here/ship.py" runs/population/split --to runs/ship
    tar czf "$OUT/population.tar.gz" --exclude='checkpoint*.npz' --exclude='runs/population/*/policy.msgpack' \
      --exclude='runs/population/split/*/policies' runs/population runs/ship 2>/dev/null
    cp runs/split.log "$OUT/" ;;
  orders)
    eo='python3 benchmarks/eval_order.py --preset gpu-short --backend warp --time-limit "$(left)"'
    bash "$here/pair.sh" "$limit" \
      "$eo --chunks 2 --rounds 3 --out runs/eval_order --work /tmp/eo" \
      "$eo --chunks 3 --rounds 5 --archives cppn=jaxterrain/assets/archives/cppn_headings.npz --out runs/eval_order_alone --work /tmp/eo_alone"
    tar czf "$OUT/eval_order.tar.gz" runs/eval_order runs/eval_order_alone 2>/dev/null
    cp runs/gpu0.log runs/gpu1.log "$OUT/" ;;
esac
ls -la "$OUT"

#!/usr/bin/env bash
# One GPU-machine command that runs the stage benchmarks and leaves JSON + logs under $OUT (or ./bench-out).
# Usage (on the device, after installing the wheels): bash benchmarks/run_all.sh [stage ...]
# stages: any benchmarks/<stage>.py, e.g. generators features rollouts map_elites scaling (default: generators features)
set -uo pipefail
out=${OUT:-bench-out}; mkdir -p "$out"
export PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
stages=("$@"); [ ${#stages[@]} -gt 0 ] || stages=(generators features)
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader | tee "$out/gpu.txt"
for s in "${stages[@]}"; do
  echo "=== $s"
  python3 "benchmarks/$s.py" --out "$out/$s.json" 2>&1 | tee "$out/$s.log"
done

#!/usr/bin/env bash
# Walk trained walkers on the held-out suite v1 (`evaluate --preset gpu --no-repeat`, the base policy beside them),
# resumable: a second call continues the same folder. After `source benchmarks/device/setup.sh`, inside a pair.sh
# line (it takes `left` for --time-limit when there is one).
#   bash benchmarks/device/heldout.sh OUT_DIR POLICY_DIR...
# e.g. issue 63's population walkers:
#   bash benchmarks/device/heldout.sh runs/pop_heldout docs/results/population/*/*/policies/trial_*
set -uo pipefail
out=${1:?OUT_DIR}; shift
limit=()
if declare -F left >/dev/null; then limit=(--time-limit "$(left)"); fi
if [ -f "$out/config.json" ]; then
  exec python3 -m experiments evaluate --resume "$out" "${limit[@]}"
fi
[ $# -gt 0 ] || { echo "heldout.sh: no POLICY_DIR given" >&2; exit 2; }
exec python3 -m experiments evaluate --preset gpu --no-repeat --policy "$@" --out "$out" "${limit[@]}"

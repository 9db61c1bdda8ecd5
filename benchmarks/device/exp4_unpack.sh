#!/usr/bin/env bash
# Experiment 4's store, once per machine, from the repository root: every shipped archive in
# docs/results/exp4/archives/ (or the files of EXP4_TAR, e.g. an earlier call's returned exp4.tar.gz) unpacked into
# runs/exp4, then the marker runs/exp4/.unpacked. The marker, not the folder, says it is done: separate.sh unpacks
# the humanoid's mixed archive alone into runs/exp4/archive/, and that folder must not pass for the whole store.
# Usage: bash benchmarks/device/exp4_unpack.sh   (exp4.sh, exp4_ant.sh, exp4_eval.sh, exp4_scan.sh, both.sh call it)
set -uo pipefail
[ -f runs/exp4/.unpacked ] && exit 0
for t in ${EXP4_TAR:-docs/results/exp4/archives/*.tar.gz}; do
  tar xzf "$t" || { echo "exp4_unpack.sh: could not unpack $t" >&2; exit 1; }
done
mkdir -p runs/exp4 && touch runs/exp4/.unpacked

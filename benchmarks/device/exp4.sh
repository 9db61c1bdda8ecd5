#!/usr/bin/env bash
# Experiment 4's humanoid training for one observation set on a 2 x H200, after `source benchmarks/device/setup.sh`;
# run it again on the same warm machine until both shards say done (a train's checkpoints do not come back: both
# shards must finish on one machine: GPU 0's, about 15-19 min of device time).
#   GPU 0: docs/results/exp4/run.py train humanoid OBS --shard 0/2  (the two map treatments, then terrain levels)
#   GPU 1: docs/results/exp4/run.py train humanoid OBS --shard 1/2  (DR and PLR, one population), then $EXTRA1
#          with the time left (default: the ant's mixed archive, `archive mixed --robot ant`)
# Once both shards are done, the same train without --shard writes the tables. Returns in $OUT: exp4.tar.gz
# (run.py's pack: archives, finished treatments with actor-only walkers; unfinished train checkpoints only while
# they fit), the logs, and extra.tar.gz of the folders in $EXTRA_OUT (space separated) when set.
# e.g. issue 63's population walkers on the held-out suite with GPU 1's spare time:
#   EXTRA1='bash benchmarks/device/heldout.sh runs/pop_heldout docs/results/population/*/*/policies/trial_*' \
#   EXTRA_OUT=runs/pop_heldout bash benchmarks/device/exp4.sh 450 blind
# Usage: bash benchmarks/device/exp4.sh LIMIT_S OBS   (OBS: blind or perceptive)
set -uo pipefail
here=$(dirname "$0")
limit=${1:?LIMIT_S}; obs=${2:?OBS}
case "$obs" in blind|perceptive) ;; *) echo "exp4.sh: OBS must be blind or perceptive, got $obs" >&2; exit 2 ;; esac
run='python3 docs/results/exp4/run.py'
# Experiment 4's folder: every packed archive in docs/results/exp4/archives/ (in git; a partial one resumes), or
# EXP4_TAR: what an earlier call's exp4.tar.gz holds
bash "$here/exp4_unpack.sh" || exit 1
extra=${EXTRA1:-"$run archive mixed --robot ant --time-limit \"\$(left)\""}
bash "$here/pair.sh" "$limit" \
  "$run train humanoid $obs --shard 0/2 --time-limit \"\$(left)\"" \
  "$run train humanoid $obs --shard 1/2 --time-limit \"\$(left)\" && $extra"
if python3 - "$obs" <<'PY'
import sys
from pathlib import Path
sys.path.insert(0, "docs/results/exp4")
import run  # noqa: E402
out, obs = Path("runs/exp4"), sys.argv[1]
folder = run.train_folder(out, "humanoid", obs)
sys.exit(0 if all(run.treatment_done(folder / t) for t in run.humanoid_choice(out)) else 1)
PY
then $run train humanoid "$obs" --pack "$OUT/exp4.tar.gz"  # the tables (nothing compiles), then the pack
else $run --plan --pack "$OUT/exp4.tar.gz"
fi
[ -z "${EXTRA_OUT:-}" ] || tar czf "$OUT/extra.tar.gz" --exclude='checkpoint*.npz' $EXTRA_OUT
cp runs/gpu0.log runs/gpu1.log "$OUT/"
ls -la "$OUT"

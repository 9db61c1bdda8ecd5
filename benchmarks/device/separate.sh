#!/usr/bin/env bash
# Issue 64 item 3: the five paper generators' separate archives at gpu-short (the runs the mixed archive is set
# against; `steps` ships), on a 2 x H200 after `source benchmarks/device/setup.sh`, then `shares`: the mixed
# archive (docs/results/exp4/archives/humanoid-mixed.tar.gz) beside the combined archive of the six separate runs.
#   GPU 0: evolve --generator perlin, worley, gan      GPU 1: evolve --generator diamond_square, cppn
# Each `evolve` resumes its folder (runs/sep-GEN) and stops at the deadline; run this again (on the same machine,
# or a fresh one with the returned separate.tar.gz unpacked in the repository root) until both GPUs say done.
# Returns in $OUT: separate.tar.gz (runs/sep-*, checkpoints of unfinished runs included; runs/shares once all are
# done), the logs; a fresh machine first unpacks PARTIAL (default the committed
# docs/results/mixed_archive/separate.tar.gz) when no runs/sep-* is there. PRESET=smoke, MIXED=RUN and
# STEPS=ARCHIVE (smoke-size runs) check the wiring on a CPU.
# GENS0 / GENS1 (space-separated generators) change which GPU evolves which; FIRST0 / FIRST1 run a command line on
# that GPU before its generators (e.g. a benchmark; `left` gives its minutes), and EXTRA_OUT names more paths to pack
# into separate.tar.gz (e.g. that benchmark's output folder).
# Usage: bash benchmarks/device/separate.sh LIMIT_S
set -uo pipefail
here=$(dirname "$0")
limit=${1:?LIMIT_S}
export PRESET=${PRESET:-gpu-short}
mixed=${MIXED:-runs/exp4/archive/humanoid-mixed}
# the committed set of separate runs (all five done since 2026-11-30; a partial set works too): the runs it finished
# stay done, the rest resume from its checkpoints
partial=${PARTIAL:-docs/results/mixed_archive/separate.tar.gz}
ls -d runs/sep-* >/dev/null 2>&1 || [ ! -f "$partial" ] || tar xzf "$partial"
[ -n "${MIXED:-}" ] || [ -f "$mixed/archive.npz" ] || tar xzf docs/results/exp4/archives/humanoid-mixed.tar.gz
# one generator's separate archive: fresh, resumed, or done (evolve exits 0 when it finished, 3 at the time limit;
# done.json marks a finished one, as docs/results/exp4/run.py's archive stage does)
evolve_one() {
  local d="runs/sep-$1" t0=$SECONDS
  if [ -f "$d/done.json" ]; then echo "separate $1: done ($d)"; return 0; fi
  if [ -f "$d/config.json" ]; then python3 -m experiments evolve --resume "$d" --time-limit "$(left)"
  else python3 -m experiments evolve --preset "$PRESET" --generator "$1" --out "$d" --time-limit "$(left)"; fi
  local rc=$?
  [ "$rc" = 0 ] || return "$rc"
  echo "{\"seconds_this_command\": $((SECONDS - t0))}" > "$d/done.json"
  echo "separate $1: done ($d, $((SECONDS - t0)) s this command)"
}
export -f evolve_one
line() {  # "FIRST; evolve_one A && evolve_one B ..." (FIRST's exit status does not stop the generators)
  local out=${1:+$1; }true g
  for g in $2; do out="$out && evolve_one $g"; done
  echo "$out"
}
bash "$here/pair.sh" "$limit" "$(line "${FIRST0:-}" "${GENS0-perlin worley gan}")" \
  "$(line "${FIRST1:-}" "${GENS1-diamond_square cppn}")"
gens="perlin worley gan diamond_square cppn"
if all=1; for g in $gens; do [ -f "runs/sep-$g/done.json" ] || all=0; done; [ "$all" = 1 ]; then
  python3 -m experiments shares --mixed "$mixed" --separate $(for g in $gens; do echo "runs/sep-$g"; done) \
    "${STEPS:-docs/results/steps_gpushort/archive.npz}" --out runs/shares || echo "separate: shares failed"
fi
tar czf "$OUT/separate.tar.gz" $(ls -d runs/sep-* 2>/dev/null) $( [ -d runs/shares ] && echo runs/shares ) ${EXTRA_OUT:-}
cp runs/gpu0.log runs/gpu1.log "$OUT/"
ls -la "$OUT"

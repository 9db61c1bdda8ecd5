#!/usr/bin/env bash
# Shrink the working tree that travels to the device machine (at most 64 MiB with what `carry` names; the tracked
# tree alone is ~54 MB) and put it back. Usage, from anywhere in the repo:
#   benchmarks/device/state.sh tiny     # only benchmarks/device/ stays: for the call that carries .wps1 (58 MB)
#   benchmarks/device/state.sh medium   # the code a run needs (jaxterrain, experiments, benchmarks, three docs files)
#   benchmarks/device/state.sh restore  # every tracked file back; `git status` must then be clean
# The files taken away are kept in ONE tar beside the repo (../jt-stash.tar). Never commit between a shrink and
# `restore`: git would record the removals.
set -euo pipefail
top=$(git rev-parse --show-toplevel); cd "$top"
stash="${JT_STASH:-$top/../jt-stash.tar}"
medium='^(\.gitignore$|jaxterrain/|experiments/|benchmarks/|pyproject\.toml$|docs/results/exp4/run\.py$|docs/results/steps_gpushort/archive\.npz$|docs/results/suite_v2/reevaluate\.py$|docs/results/eval_order/run\.py$|docs/results/exp4/archives/|docs/results/mixed_archive/separate\.tar\.gz$)'
tiny='^(\.gitignore$|benchmarks/device/)'
back() { if [ -f "$stash" ]; then tar xf "$stash" && rm -f "$stash"; fi; }
case "${1:-}" in
  restore)
    back
    rm -f benchmarks/device/.commit
    if [ -n "$(git status --porcelain --untracked-files=no)" ]; then
      echo "state: tracked files differ from HEAD after restore:"; git status --short --untracked-files=no; exit 1
    fi
    echo "state: restored; $(git ls-files | wc -l) tracked files" ;;
  tiny|medium)
    back
    keep=$([ "$1" = tiny ] && echo "$tiny" || echo "$medium")
    git ls-files -z | grep -zEv "$keep" | tar --null -cf "$stash" -T -
    git ls-files -z | grep -zEv "$keep" | xargs -0 rm -f
    find . -path ./.git -prune -o -type d -empty -print0 | xargs -0 -r rmdir -p --ignore-fail-on-non-empty 2>/dev/null || true
    git rev-parse HEAD > benchmarks/device/.commit
    echo "state: $1; $(git ls-files -z | grep -zE "$keep" | xargs -0 du -cb | tail -1 | cut -f1) bytes of tracked files stay" ;;
  *) echo "usage: $0 tiny|medium|restore" >&2; exit 2 ;;
esac

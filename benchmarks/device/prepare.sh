#!/usr/bin/env bash
# Here, once per checkout: what the device machine's image lacks, as ignored folders to `carry`.
#   .whl/        the wheels of ../shared/tools/device-wheels (mujoco, mujoco-mjx, brax, qdax, ...; ~18 MB)
#   .wps1 .wps2  MuJoCo Warp (warp-lang 1.19.0 without its CPU compiler, examples and tests) as ONE tar.xz in two
#                parts, 58 MB and ~25 MB: the 149 MB wheel does not fit a call
set -euo pipefail
top=$(git rev-parse --show-toplevel); cd "$top"
for d in /.whl/ /.wps1/ /.wps2/ /runs/; do grep -qxF "$d" .git/info/exclude 2>/dev/null || echo "$d" >> .git/info/exclude; done
[ -d .whl ] && ls .whl/mujoco_mjx-*.whl >/dev/null 2>&1 || ../shared/tools/device-wheels >/dev/null
if [ ! -f .wps1/part.00 ]; then
  tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
  python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    --platform manylinux_2_28_x86_64 -d "$tmp" warp-lang==1.19.0 2>&1 | grep -v '^WARNING: Location' || true
  mkdir "$tmp/x" && (cd "$tmp/x" && unzip -q "$tmp"/warp_lang-*.whl && rm -rf warp/bin/warp-clang.so warp/examples warp/tests)
  tar cf - -C "$tmp/x" . | xz -T2 -6 > "$tmp/warp.tar.xz"
  rm -rf .wps1 .wps2 && mkdir .wps1 .wps2
  split -b 58m -d "$tmp/warp.tar.xz" "$tmp/part."
  mv "$tmp/part.00" .wps1/ && mv "$tmp"/part.0[1-9] .wps2/
fi
du -sh .whl .wps1 .wps2

# Source on the device machine, in the repository root: `source benchmarks/device/setup.sh`.
# Installs (once per machine) the carried wheels (.whl) and MuJoCo Warp (/root/wp/part.*, copied there from
# .wps1 and .wps2 by earlier calls) into /tmp/site, applies jaxterrain's heightfield patch to MJX's vendored
# MuJoCo Warp, and imports every module a run uses before anything starts. Returns 5 (install) or 6 (import).
export PYTHONUNBUFFERED=1 NCCL_NVLS_ENABLE=0 TORCH_SYMM_MEM_DISABLE_MULTICAST=1 NVSHMEM_DISABLE_NVLS=1
export PYTHONPATH=/tmp/site:$PWD
if [ ! -f /tmp/site/.jt-ready ]; then
  mkdir -p /tmp/site
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
    || { echo "setup: wheels failed"; return 5; }
  cat /root/wp/part.* | xz -d | tar x -C /tmp/site || { echo "setup: warp parts missing or damaged"; return 5; }
  touch /tmp/site/.jt-ready
fi
python3 -m experiments warp-patch >/dev/null && python3 -m experiments warp-patch --check \
  || { echo "setup: the heightfield patch failed"; return 5; }
python3 - <<'PY' || { echo "setup: an import failed"; return 6; }
import jax, warp, mujoco, mujoco.mjx, brax, qdax, trimesh  # noqa: F401
import jaxterrain, experiments.curriculum, experiments.evolve, experiments.generalise  # noqa: F401
from jaxterrain.curriculum import batch, runner  # noqa: F401
from jaxterrain.runtime import statistics  # noqa: F401
print("setup:", jax.__version__, jax.devices(), "warp", warp.__version__)
PY

# issue 47 done-when: the humanoid's shipped policy on the same terrains, the tree before robot specs (708dd37^) vs
# this one, on the GPU, alternating (old new old new): python3 .dev/hum_check.py TREE LABEL OUT_DIR [N] [SIZE]
import json, sys, time
from pathlib import Path
tree, label, out = sys.argv[1], sys.argv[2], Path(sys.argv[3])
n = int(sys.argv[4]) if len(sys.argv) > 4 else 64
size = int(sys.argv[5]) if len(sys.argv) > 5 else 256
sys.path.insert(0, tree)
import jax, jax.numpy as jnp, numpy as np
import jaxterrain
from jaxterrain import difficulty
assert Path(jaxterrain.__file__).resolve().is_relative_to(Path(tree).resolve()), jaxterrain.__file__
out.mkdir(parents=True, exist_ok=True)
maps_f = out / f"terrains_{n}_{size}.npy"
if not maps_f.exists():
    from jaxterrain import generators
    gen = generators.get("perlin", size=size)
    np.save(maps_f, np.clip(np.asarray(gen.render(gen.sample(jax.random.PRNGKey(0), n)), np.float32), 0, 1))
maps = jnp.asarray(np.load(maps_f))
t = time.time()
d = np.asarray(difficulty.rollout_distances(maps, jax.random.PRNGKey(1), 20))
dt = time.time() - t
fit = np.sort(d, axis=1)[:, -5:].mean(1)
runs = sorted(out.glob(f"{label}_*.npy"))
np.save(out / f"{label}_{len(runs)}.npy", d)
print(json.dumps({"label": label, "run": len(runs), "tree": jaxterrain.__file__, "device": str(jax.devices()[0]),
                  "mean_all": float(d.mean()), "mean_best5": float(fit.mean()), "seconds": round(dt, 1)}), flush=True)

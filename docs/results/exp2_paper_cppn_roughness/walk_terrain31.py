"""Why walks on terrain 31 (cell (2, 3) of the CPPN HEADINGS archive, the roughness baseline's second terrain) end:
the base policy, then a policy of the paper-budget baseline at chunk 650 (``policies_chunk650.npz``: the 10 trials'
policy nets and observation normalisers from its checkpoint). Per heading, 8 deterministic walks of at most 64 env
steps on the MJX-JAX walker (a CPU: about 1 min): the step a walk ended at, the torso's height above the terrain under
it (a fall is outside ``healthy_z_range`` = (1.0, 2.0) m), invalid physics, the largest |observation|, the distance.

    python docs/results/exp2_paper_cppn_roughness/walk_terrain31.py [TRIAL]


Pinned: it reads private functions of the package as they were at commit f770ea6; run it at that commit
(``git worktree add /tmp/at-f770ea6 f770ea6``). Kept as the record of how its figures were made."""
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain import qd as A, difficulty as D, rl
from jaxterrain.qd import bank as B

STEPS, WALKS = 64, 8
arch = A.load("docs/results/exp2_cppn_headings_archive.npz")
maps = B._render_filled(arch, np.array([152]), 8)  # bank terrain 31 = archive cell 152
terrains_m, cfg, policy = D._resolve(maps, D.HEADINGS, None, None, None)
env = D.make_env(cfg)
act = rl.policy_fn(policy.config, env.action_size)


def trial_params(trial: int):
    """(params, normaliser) of ``trial`` from policies_chunk650.npz (the value net, unused by a walk, is the base's)."""
    z = np.load(Path(__file__).with_name("policies_chunk650.npz"))
    flat, tree = jax.tree_util.tree_flatten_with_path((policy.params, policy.normaliser))
    leaves = []
    for path, leaf in flat:
        name = "".join(str(p) for p in path)
        key = "leaf:.policy." + ("params" + name[3:] if name.startswith("[0]") else "normaliser" + name[3:])
        leaves.append(jnp.asarray(z[key][trial]) if key in z else leaf)
    return jax.tree_util.tree_unflatten(tree, leaves)


def walks(params):
    def walk(terrain, key):
        def body(carry, _):
            s, alive = carry
            s2 = env.step(s, act(params, s.obs), terrain)
            rec = (alive, s2.metrics["torso_height"], s2.failed, jnp.max(jnp.abs(s2.obs)), s2.distance)
            return (s2, alive & (s2.done == 0)), rec
        return jax.lax.scan(body, (env.reset(key, terrain), jnp.bool_(True)), None, length=STEPS)[1]
    return jax.jit(jax.vmap(walk, in_axes=(None, 0)))


def report(name, params):
    print(name)
    fn = walks(params)
    for h in range(4):  # heading h walks the map turned by jnp.rot90(., h), as the HEADINGS protocol does
        alive, height, failed, obs, dist = [np.asarray(x) for x in
                                            fn(jnp.rot90(terrains_m[0], h), jax.random.split(jax.random.key(h), WALKS))]
        steps = alive.sum(1)
        ended = steps < STEPS
        last = np.minimum(steps, STEPS) - 1
        end_h = height[np.arange(WALKS), last]
        print(f"  heading {h}: ended {int(ended.sum())}/{WALKS}, at steps {sorted(steps[ended].tolist())}; torso above "
              f"terrain at the end {end_h.min():.2f}-{end_h.max():.2f} m; invalid physics {int(failed.max())}; "
              f"max |obs| {obs.max():.1f}; distance {dist[np.arange(WALKS), last].mean():.3f}")


report("base policy", (policy.params, policy.normaliser))
trial = int(sys.argv[1]) if len(sys.argv) > 1 else 0
report(f"roughness baseline, trial {trial}, chunk 650", trial_params(trial))

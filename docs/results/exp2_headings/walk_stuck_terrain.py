"""Base policy's 80 HEADINGS walks on the CPPN terrain the roughness baseline stuck on (cell 152 = bins (2, 3)), with
the steps of each walk (the difficulty module's compiled program; run from the repository root on a CPU: 34 s).

Pinned: it reads private functions of the package as they were at commit 3068652; run it at that commit
(``git worktree add /tmp/at-3068652 3068652``). Kept as the record of how its figures were made."""
import time
import jax, numpy as np
from jaxterrain import qd as A, difficulty as D
from jaxterrain.qd import bank as B
arch = A.load("docs/results/exp2_cppn_headings_archive.npz")
maps = B._render_filled(arch, np.array([152]), 8)
print("stored fitness", float(arch.fitness[152]))
protocol = D.HEADINGS
terrains_m, env_config, policy = D._resolve(maps, protocol, None, None, None)
apply, params, with_params = D._policy_program(policy, None)
fn = D._program(env_config, protocol.attempts, protocol.headings, apply, with_params, None, True)
t = time.time()
d, steps = fn(terrains_m, jax.random.key(0), params)[:2]
d, steps = np.asarray(d).reshape(4, 20), np.asarray(steps).reshape(4, 20)
print(f"walked in {time.time() - t:.0f} s")
for h in range(4):
    o = np.argsort(-d[h])
    print(f"heading {h}: best5 mean {d[h][o[:5]].mean():.3f}  distances {np.round(np.sort(d[h])[::-1], 2).tolist()}")
    print(f"           steps {steps[h].tolist()}")

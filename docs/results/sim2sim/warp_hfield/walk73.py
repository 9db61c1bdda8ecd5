"""antwarp73.py for either robot; saves per-map steps and fitness. Usage: walk73.py ROBOT OUT.npz"""
import sys, time
sys.path.insert(0, "docs/results/sim2sim")
import numpy as np
import ant_budget as ab
from jaxterrain import difficulty, rl
from jaxterrain.rl.checkpoint import BASE_POLICY_DIR
robot, out = sys.argv[1], sys.argv[2]
h, labels = ab.maps("sim2sim", False)
policy = rl.load_policy(BASE_POLICY_DIR.parent / "base_policy_ant" if robot == "ant" else BASE_POLICY_DIR)
base = difficulty.default_env_config(tuple(h.shape[1:]), policy=policy)
cfg = base._replace(backend="warp", tiles=1, warp_contacts=16, warp_njmax=96)
t0 = time.perf_counter()
fit, steps = ab.walk(h, cfg, policy, 5)
np.savez(out, fit=fit, steps=steps, labels=np.array(labels))
ms = steps.mean(1)
print(f"{robot} 73 maps x 5 walks warp: {time.perf_counter() - t0:.0f} s; mean fitness {fit.mean():.4f}; walks <= 5 steps {(steps <= 5).mean():.4f}")
for i in np.argsort(ms)[:8]:
    print(labels[i], "mean steps", ms[i], "fitness", round(float(fit[i]), 3))

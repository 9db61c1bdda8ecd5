"""Standalone MuJoCo Warp repro: a sphere (r 0.08 m) whose centre is 0.1 m under a heightfield's surface, at many
places of a large heightfield (2304 x 2304 samples, 0.04 m apart, +-46 m). Prints Warp's deepest contact depth per
place next to MuJoCo C's. Run with the stock and the patched mujoco_warp on PYTHONPATH."""
import numpy as np, mujoco, sys
import mujoco_warp as mjw
import os
n = int(os.environ.get("N", "2304")); half = (n - 1) * 0.02
xml = f"""<mujoco><asset><hfield name="hf" nrow="{n}" ncol="{n}" size="{half} {half} 1 0.1"/></asset>
<worldbody><geom type="hfield" hfield="hf"/><body><freejoint/><geom type="sphere" size="0.08"/></body></worldbody></mujoco>"""
m = mujoco.MjModel.from_xml_string(xml)
g = np.linspace(-half, half, n)
X, Y = np.meshgrid(g, g)
m.hfield_data[:] = (0.5 + 0.2 * np.sin(X * 1.7) * np.cos(Y * 2.3) + 0.1 * np.sin(X * 5.1 + Y * 3.7)).ravel()
def surf(x, y):
    return float((0.5 + 0.2 * np.sin(x * 1.7) * np.cos(y * 2.3) + 0.1 * np.sin(x * 5.1 + y * 3.7)))
rng = np.random.default_rng(0)
mw = mjw.put_model(m)
bad = 0
for k in range(int(sys.argv[1]) if len(sys.argv) > 1 else 40):
    x, y = rng.uniform(-0.95 * half, 0.95 * half, 2)
    d = mujoco.MjData(m); d.qpos[:3] = (x, y, surf(x, y) - 0.10); mujoco.mj_forward(m, d)
    dw = mjw.put_data(m, d, nworld=1, naconmax=256, njmax=1024); mjw.forward(mw, dw)
    nc = int(dw.nacon.numpy()[0]); wd = dw.contact.dist.numpy()[:nc]
    cd = d.contact.dist[:d.ncon] if d.ncon else np.array([np.nan])
    w = wd.min() if nc else np.nan
    bad += bool(nc and w < -0.5)
    print(f"sphere at ({x:+7.2f},{y:+7.2f}) centre 0.10 m under the surface: Warp deepest {w:+9.4f} m ({nc} contacts), C deepest {np.min(cd):+.4f} m")
print("places with a Warp depth beyond 0.5 m:", bad, "mjw", mjw.__file__)

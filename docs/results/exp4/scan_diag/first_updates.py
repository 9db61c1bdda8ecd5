"""How far one PPO update (CPU, small batch) moves the first layer's pre-activations through the scan block vs the
blind block, from the perceptive base policy: as shipped, and with the scan's normalised input scaled by 0.1
(its normaliser std x 10)."""
import sys, numpy as np, jax, jax.numpy as jnp
from jaxterrain import rl, suite
from jaxterrain.rl import ppo, networks as nets
from jaxterrain.walker import WalkerEnv, WalkerConfig
B = 45
env = WalkerEnv(WalkerConfig(observation="perceptive"))
base = rl.load_policy(rl.base_policy_dir('humanoid', 'perceptive'))
cfg = base.config._replace(num_envs=32, num_unrolls=2, unroll_length=10, num_minibatches=4, update_epochs=4,
                           update_normaliser=False)
s = suite.load("v2", families=["stairs_up"], seeds=1, generator_names=[])
terrains = {"flat": jnp.zeros((256, 256)), "stairs_up2": jnp.asarray(s.heightmaps[int(np.flatnonzero(s.level == 2)[0])] * s.scale.height)}
upd = jax.jit(lambda st, k, t: ppo.update(st, k, t, env=env, config=cfg))
W = lambda p: p["policy"]["params"]["mlp"]["hidden_0"]["kernel"]
for scale in (1.0, 0.1):
    norm = base.normaliser
    if scale != 1.0:
        norm = norm._replace(m2=norm.m2.at[B:].multiply(1.0 / scale ** 2))
    for tn, t in terrains.items():
        st = ppo.init(jax.random.PRNGKey(0), env, cfg, t, params=base.params, normaliser=norm)
        obs = []
        for i in range(3):
            st, m = upd(st, jax.random.PRNGKey(10 + i), t)
            obs.append(st.env_state.obs)
        z = nets.normalize(norm, jnp.concatenate(obs))
        dW = W(st.params) - W(base.params)
        ds = z[:, B:] @ dW[B:]; db = z[:, :B] @ dW[:B]
        rms = lambda x: float(jnp.sqrt(jnp.mean(x ** 2)))
        cm = float(jnp.mean(jnp.abs((dW[B:] / nets.stats_std(norm)[B:, None]).sum(0))))
        print(f"scan x{scale:<4} {tn:11s} after 3 updates ({3 * cfg.update_epochs * cfg.num_minibatches} Adam steps): "
              f"mean|dW| scan {float(jnp.mean(jnp.abs(dW[B:]))):.5f} blind {float(jnp.mean(jnp.abs(dW[:B]))):.5f}; "
              f"RMS pre-activation change: scan {rms(ds):.4f}, blind {rms(db):.4f} (ratio {rms(ds) / rms(db):.2f}); "
              f"scan common-mode gain {cm:.2f}/m", flush=True)

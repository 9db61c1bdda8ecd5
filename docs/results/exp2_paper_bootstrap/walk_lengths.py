"""How long a curriculum's evaluation walks last, from a treatment's checkpoint.

    python docs/results/exp2_paper_bootstrap/walk_lengths.py RUN/TREATMENT [--trials 0,1,...] [--backend jax|warp]
        [--out F.json]

Restores each trial's policy (params, normaliser) and current terrain from ``TREATMENT/checkpoint.npz`` of a
``curriculum`` / ``learn`` run, walks the treatment's evaluation (its protocol's attempts and headings, laid out on
tiles as the learn block lays them out) with the deterministic policy, and records when each walk ended and how
(fell, reached the goal, or the episode limit); on MJX-JAX also the feet's contacts with the terrain per step
(``dist < 0``; at most 8: two feet, up to four heightfield contacts each). Printed per trial: the walk lengths
(median, 90th percentile, max), the outcome counts and the contacts per step. Over all trials: the walks' loop
length (its longest walk: the sequential env steps the evaluation adds to a chunk beyond the PPO steps it rides
along under ``--overlap``).

Why: the Perlin map treatment's chunks took about 4, 6 and 8.6 s on the GPU as its evaluation fell (exp2_paper.md).
Two suspects: longer walks (the loop runs until its longest walk ends) and more contacts per step (more constraint
rows for the solver). ``--backend`` (default ``jax``, which every machine has) picks the physics; the run's was
``warp``. Timed: ``compile_s`` (trace and compile) and ``seconds`` (the walks alone).
"""
import argparse
import json
import pathlib
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[3]))

from experiments import learn  # noqa: E402
from jaxterrain import rl  # noqa: E402
from jaxterrain.curriculum import walker as W  # noqa: E402


def restore_policies(npz, like):
    """``(params, normaliser)`` of every trial ([T, ...] leaves) from the checkpoint, shaped like ``like``'s."""
    def read(prefix, tree):
        return jax.tree_util.tree_map_with_path(
            lambda path, _: jnp.asarray(npz[f"leaf:.policy.{prefix}" + jax.tree_util.keystr(path)]), tree)

    return read("params", like.params), read("normaliser", like.normaliser)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("treatment", type=pathlib.Path)
    p.add_argument("--trials", default=None, help="comma-separated trial indices (default: all)")
    p.add_argument("--backend", choices=("jax", "warp"), default="jax")
    p.add_argument("--out", type=pathlib.Path, default=None)
    a = p.parse_args()
    cfg = {**json.loads((a.treatment / "config.json").read_text()), "backend": a.backend}
    npz = np.load(a.treatment / "checkpoint.npz")
    trials = [int(t) for t in a.trials.split(",")] if a.trials else list(range(int(cfg["trials"])))
    cfg["trials"] = len(trials)
    config, arch, policy, env = learn.validate(cfg)
    bank, ppo, harness, start, _, _ = learn.inputs(cfg, config, arch, policy, env)
    params, normaliser = restore_policies(npz, start)
    pick = jnp.asarray(trials)
    params, normaliser = jax.tree.map(lambda x: x[pick], (params, normaliser))
    terrain = np.asarray(npz["leaf:.terrain"])[trials]
    keys = jax.random.split(jax.random.key(7), len(trials))
    protocol = config.protocol.validate()
    attempts, headings = protocol.attempts, protocol.headings
    tile, _ = harness.layout(bank.heightmaps[jnp.asarray(terrain)])
    act = rl.policy_fn(ppo, env.action_size)
    ride = config.updates_per_chunk * ppo.unroll_length * ppo.num_unrolls  # the PPO steps the walks ride along

    @jax.jit
    def walk(data, index, keys, params):
        """[B, R] end step (0-based; -1: not ended), fell (a fall ends it), reached (the goal), contacts summed over
        its steps; [] the loop's steps."""
        reset_keys = jax.vmap(lambda k: W._walk_keys(k, attempts, headings))(keys)
        world, inner = W._walk_tiles(W.Tile(W.TileBank(data), index), attempts, headings)
        reset = jax.vmap(jax.vmap(env.reset, in_axes=(0, inner)), in_axes=(0, W.TILE_AXES))
        step = jax.vmap(jax.vmap(env.step, in_axes=(0, 0, inner)), in_axes=(0, 0, W.TILE_AXES))
        policy = jax.vmap(jax.vmap(act, in_axes=(None, 0)), in_axes=(0, 0))
        state = reset(reset_keys, world)
        shape = reset_keys.shape[:2]
        zeros = jnp.zeros(shape, jnp.float32)
        carry = (jnp.int32(0), state, jnp.full(shape, -1, jnp.int32), zeros > 0, zeros > 0, zeros)

        def cond(c):
            return (c[0] < env.config.episode_length) & jnp.any(c[2] < 0)

        def body(c):
            t, s, end, fell, reached, contacts = c
            running = end < 0
            s = step(s, policy(params, s.obs), world)
            if a.backend == "jax":
                contacts = contacts + jnp.where(running, jnp.sum(s.data._impl.contact.dist < 0, axis=-1), 0)
            new = running & (s.done > 0)
            return (t + 1, s, jnp.where(new, t, end), fell | (new & (s.truncation == 0)),
                    reached | (new & (s.truncation > 0) & (t + 1 < env.config.episode_length)), contacts)

        t, _, end, fell, reached, contacts = jax.lax.while_loop(cond, body, carry)
        return end, fell, reached, contacts, t

    args = (tile.bank.data, tile.index, keys, (params, normaliser))
    t0 = time.perf_counter()
    compiled = walk.lower(*args).compile()
    compile_s = time.perf_counter() - t0
    end, fell, reached, contacts, loop = jax.block_until_ready(compiled(*args))
    seconds = time.perf_counter() - t0 - compile_s
    end, fell, reached, contacts = np.asarray(end), np.asarray(fell), np.asarray(reached), np.asarray(contacts)
    length = np.where(end < 0, env.config.episode_length, end + 1)
    per_step = float(contacts.sum() / length.sum()) if a.backend == "jax" else None
    rows = []
    for i, t in enumerate(trials):
        rows.append({"trial": t, "terrain": int(terrain[i]), "median": float(np.median(length[i])),
                     "p90": float(np.percentile(length[i], 90)), "max": int(length[i].max()),
                     "fell": int(fell[i].sum()), "reached": int(reached[i].sum()),
                     "limit": int((~fell[i] & ~reached[i]).sum()),
                     "contacts_per_step": float(contacts[i].sum() / length[i].sum()) if per_step is not None else None})
        print(json.dumps(rows[-1]))
    out = {"treatment": str(a.treatment), "chunk": int(np.asarray(npz["leaf:.chunk"]).max()),
           "walks_per_trial": attempts, "episode_length": env.config.episode_length, "loop_steps": int(loop),
           "ride_steps": ride, "walks_past_ride": float((length > ride).mean()), "mean_length": float(length.mean()),
           "contacts_per_step": per_step,
           "backend": a.backend, "compile_s": compile_s, "seconds": seconds, "trials": rows}
    print(json.dumps({k: v for k, v in out.items() if k != "trials"}))
    if a.out:
        a.out.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()

"""How a treatment's trial states come back from its checkpoint, alone (:mod:`.runner`) or in a population
(:mod:`.batch`): the env states they carry, and where those envs stand.

    states = restore_states(folder, fresh_states, {"trials": T, "offset": o}, tiled=bool(env.tiles))

A checkpoint carries the trials' env states (:data:`ENV_STATES`), so a run resumed after any chunk continues its
envs where they were. On a tiled walker (MuJoCo Warp, or ``overlap``) an env lives on its trial's tile, whose place
in the heightfield follows the trial's index among all trials the program steps (and Warp's contact buffers their
count): a checkpoint records that placement (``meta["population"]``; a run alone: its own trials, at 0), and one
restored elsewhere restarts its envs on the trials' current terrains instead.

On MuJoCo Warp the env states are stored in the form the blocks carry them (``walker.carry_rows``): every env's own
physics (``qpos``, ``qvel``, warm starts, constraint rows, ...) with the trial axis, and the buffers Warp shares
between all envs of a physics call (contacts, ``nacon``, ...) as empty ``[trials, 0, ...]`` leaves. Those buffers
are scratch that every step's collision rebuilds and every chunk takes from a fresh ``reset`` (``env.select``), so
a restored Warp run continues its envs exactly as an uninterrupted one. Warp checkpoints written before that form
(2026-11-29, when a block returned those buffers cut to ``[trials, ...]`` and the next block was refused) restart
their envs on the trials' current terrains (one line); MJX-JAX checkpoints (no shared buffers) read as before.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import jax.numpy as jnp
import numpy as np

from jaxterrain.curriculum.core import CHECKPOINT_COMPAT
from jaxterrain.runtime import driver

__all__ = ["ENV_STATES", "strip_envs", "restore_states"]

ENV_STATES = ".policy.env_state"
"""The checkpoint leaves of the trials' env states (``State.policy.env_state``). Checkpoints written before they
were carried (2026-11-29) lack them and stored ``restart`` True: restored, their envs restart on the current
terrains, as they did at every block then."""


def strip_envs(states):
    """The carried state without the envs' physics: what a report reads from a checkpoint (the env states of a
    MuJoCo Warp run have another structure than MJX-JAX's, and nothing is stepped)."""
    return states._replace(policy=states.policy._replace(env_state=None))


def restore_states(folder: Path, states, placement: dict, tiled: bool, say: Callable = print):
    """``driver.restore`` of ``folder``'s checkpoint into the structure of ``states`` (the run's fresh trial
    states): ``(states, done, history, meta)``, or None without a checkpoint. The env states come back too, except
    on a tiled walker (``tiled``) when the checkpoint's placement (``meta["population"]``, where its trials sat:
    ``{"trials": T, "offset": o}``; written alone: its own trials at 0) is not ``placement``, or when its env states
    have other shapes than ``states``' (a MuJoCo Warp checkpoint written before the carried form, see the module
    docstring; everything else must fit): then the envs restart on the trials' current terrains (``restart`` True;
    one line to ``say``)."""
    folder = Path(folder)
    meta = driver.read_meta(folder)
    if meta is None:
        return None
    before = meta.get("population") or {"trials": int(np.asarray(states.done).shape[0]), "offset": 0}
    if not tiled:
        return driver.restore(folder, like=states, **CHECKPOINT_COMPAT, optional=(ENV_STATES,))
    if before == placement:
        try:
            return driver.restore(folder, like=states, **CHECKPOINT_COMPAT, optional=(ENV_STATES,))
        except ValueError as err:  # the env states only (else the stripped restore below raises too)
            try:
                s, done, history, saved = driver.restore(folder, like=strip_envs(states), **CHECKPOINT_COMPAT)
            except ValueError:
                raise err from None
        say(f"{folder.name}: its env states were stored in another form (a MuJoCo Warp checkpoint written before "
            f"2026-11-29's fix): they restart on the current terrains")
    else:
        say(f"{folder.name}: its envs walked on other tiles (trials {before}, now {placement}): they restart on the "
            f"current terrains")
        s, done, history, saved = driver.restore(folder, like=strip_envs(states), **CHECKPOINT_COMPAT)
    s = s._replace(policy=s.policy._replace(env_state=states.policy.env_state), restart=jnp.ones_like(s.restart))
    return s, done, history, saved

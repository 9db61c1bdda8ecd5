"""The real harness: PPO (``jaxterrain.rl``) on the MJX walker, evaluated by the difficulty protocol.

    policy = rl.load_policy()                                    # the shipped base policy (or a file)
    env = walker_env(policy, bank.heightmaps.shape[1:], scale)   # the walker it was trained on, on the bank's terrains
    check_policy(policy, env)                                    # ValueError naming the file on a mismatch
    ppo = fine_tuning_ppo(config, policy, env)                   # fine-tuning PPO (CurriculumConfig.ppo_config)
    harness = walker_harness(env, ppo, config)
    start = start_state(env, ppo, policy, bank.heightmaps.shape[1:])   # the policy's params, value net, normaliser

``harness.train`` runs ``config.updates_per_chunk`` PPO updates (``rl.run_updates``, one chunk =
``epochs_per_chunk x steps_per_epoch`` env steps) with all ``num_envs`` envs on the current terrain;
``harness.evaluate`` walks the updated deterministic policy under ``config.protocol`` on it
(``difficulty.protocol_distances``: ``attempts`` walks, the mean of the ``best`` distances per heading, the mean over
``headings``); ``harness.reset`` restarts the envs on a new terrain (``rl.reset_envs``). With ``headings`` > 1 the
PPO envs are spread over the headings too (env e on the terrain turned for heading ``e % headings``), so the policy
trains on the directions it is evaluated in.

On tiles (MuJoCo Warp, whose heightfield every env shares): build the walker with one tile per trial and enough
Warp worlds for the envs stepped together, then the harness lays the trials' terrains out as tiles::

    env = walker_env(policy, shape, scale, backend="warp", trials=T, worlds=T * max(num_envs, attempts))
    harness = walker_harness(env, ppo, config)      # layout: [T, H, W] -> (env.make_bank(...).at(arange(T)), TILE_AXES)

Every chunk, :func:`jaxterrain.curriculum.run_trials` gathers the T trials' current terrains (``[T, H, W]``) into
ONE bank of T tiles outside the trial vmap; trial i trains, restarts and is evaluated on ``bank.at(i)`` (its PPO envs
and its ``attempts`` walks all on tile i); policy states are merged with ``env.select`` (``Harness.where``).

With ``CurriculumConfig.overlap`` (tiles only) the harness also has ``train_evaluate``: the evaluation's walks of the
policy a chunk starts from ride along that chunk's PPO envs (``rl.ride_updates``: ``num_envs + attempts`` envs per
trial in each physics call, so Warp needs ``worlds = T * (num_envs + attempts)``), and those still walking after it
walk on alone (:func:`finish_walks`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import jax
import jax.numpy as jnp

from jaxterrain import difficulty, rl
from jaxterrain.curriculum.config import CurriculumConfig
from jaxterrain.curriculum.core import Harness
from jaxterrain.rl import networks as nets
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import TILE_AXES, Tile, TileBank, parse_randomisation, scan_size
from jaxterrain.walker.layout import make_env

__all__ = ["walker_env_config", "walker_env", "check_policy", "fine_tuning_ppo", "walker_harness", "tile_layout",
           "select_policy", "tile_distances", "start_state"]


def walker_env_config(policy, shape: tuple[int, int], scale: TerrainScale, episode_length: Optional[int] = None,
                      backend: str = "jax", tiles: int = 0, worlds: Optional[int] = None,
                      healthy_reward: Optional[float] = None, randomisation=None, spawn: Optional[str] = None):
    """The :class:`~jaxterrain.walker.WalkerConfig` of the curriculum: the bank's terrain shape and scale, the
    contact solver the policy was trained with, and (optionally) a shorter ``episode_length``.

    ``healthy_reward``: the fine-tuning reward's per-step bonus for staying up (None: the walker's 5.0, brax's
    humanoid and the base policy's training reward). Evaluations measure distance, which it does not change.

    ``backend``: "jax" (MJX) or "warp" (MuJoCo Warp, needs ``tiles >= 1``). ``tiles``: 0 for the classic layout (a
    ``[H, W]`` terrain per trial), else the trials run together (one tile each). ``worlds``: MuJoCo Warp's contact
    buffers, for at least this many envs stepped together (trials x max(PPO envs, evaluation walks)); None keeps
    the walker's default. ``randomisation``: physics randomisation of the fine-tuning walker (a
    :class:`~jaxterrain.walker.Randomisation` or a ``--randomise`` spec; None: off). ``spawn``: the reset's rule
    (``jaxterrain.walker.SPAWNS``; None: the walker's default, ``feet``)."""
    config = difficulty.default_env_config(tuple(shape), scale, policy)
    if spawn is not None:
        config = config._replace(spawn=spawn)
    if randomisation is not None:
        config = config._replace(randomisation=parse_randomisation(randomisation))
    if episode_length is not None:
        config = config._replace(episode_length=int(episode_length))
    if backend != "jax" or tiles:
        config = config._replace(backend=backend, tiles=int(tiles))
    if worlds is not None:
        config = config._replace(warp_worlds=int(worlds))
    if healthy_reward is not None:
        config = config._replace(healthy_reward=float(healthy_reward))
    return config


def walker_env(policy, shape: tuple[int, int], scale: TerrainScale, episode_length: Optional[int] = None,
               backend: str = "jax", tiles: int = 0, worlds: Optional[int] = None,
               healthy_reward: Optional[float] = None, randomisation=None, spawn: Optional[str] = None):
    """The cached :class:`~jaxterrain.walker.WalkerEnv` of :func:`walker_env_config` (builds the MuJoCo model;
    compiles nothing)."""
    return make_env(walker_env_config(policy, shape, scale, episode_length, backend, tiles, worlds,
                                                 healthy_reward, randomisation, spawn))


def check_policy(policy, env) -> None:
    """``ValueError`` naming the policy's file when it does not fit the walker: another observation set
    (:func:`jaxterrain.difficulty.check_observation`), observation / action sizes, or parameters that are not those
    of its own PPOConfig's networks. Uses shapes only (nothing is compiled)."""
    where = str(getattr(policy, "path", None) or "the policy")
    difficulty.check_observation(policy, env.config)
    obs, act = getattr(policy, "observation_size", None), getattr(policy, "action_size", None)
    if obs != env.observation_size or act != env.action_size:
        raise ValueError(f"{where}: policy for observations {obs} / actions {act}, but the walker has "
                         f"{env.observation_size} / {env.action_size} (observation {env.config.observation})")

    like = jax.eval_shape(lambda k: nets.init_params(k, policy.config, obs, act), jax.random.key(0))
    shapes = lambda t: jax.tree.map(lambda x: tuple(x.shape), t)  # noqa: E731
    try:
        same = shapes(like) == shapes(policy.params)
    except Exception:  # noqa: BLE001 - any structural difference is a mismatch
        same = False
    if not same:
        raise ValueError(f"{where}: its parameters do not match the networks of its own config.json "
                         f"(policy_hidden={policy.config.policy_hidden}, value_hidden={policy.config.value_hidden})")
    if tuple(policy.normaliser.mean.shape) != (obs,):
        raise ValueError(f"{where}: normaliser of size {policy.normaliser.mean.shape}, expected ({obs},)")


def fine_tuning_ppo(config: CurriculumConfig, policy, env) -> rl.PPOConfig:
    """The fine-tuning :class:`jaxterrain.rl.PPOConfig` of a curriculum on walker ``env`` from ``policy``:
    :meth:`CurriculumConfig.ppo_config` of the policy's own, with ``scan_inputs`` the walker's height scan entries
    (:func:`jaxterrain.walker.scan_size`: the last ones of its observation, those ``scan_lr_scale`` applies to; 0
    for a blind walker, which refuses a ``scan_lr_scale`` other than 1 with ``ValueError``)."""
    return config.ppo_config(policy.config, scan_size(env.config))


def walker_harness(env, ppo: rl.PPOConfig, config: CurriculumConfig) -> Harness:
    """The :class:`~jaxterrain.curriculum.core.Harness` of PPO fine-tuning on ``env`` (pure functions; the policy
    state is an ``rl.TrainState``)."""
    rl.validate_config(ppo)
    updates = config.steps_per_chunk // ppo.steps_per_update
    if updates * ppo.steps_per_update != config.steps_per_chunk:
        raise ValueError(f"PPO's {ppo.steps_per_update} env steps per update must divide a chunk's "
                         f"{config.steps_per_chunk}")
    act = rl.policy_fn(ppo, env.action_size)
    protocol = config.protocol.validate()

    def spread(terrain):
        """The trial's terrain for its PPO envs: env e walks heading ``e % headings`` (all +x for one heading). On
        tiles a Tile per env; in the classic layout per-env turned copies, ``[num_envs, H, W]`` (131 MB per trial
        for 500 envs at 256 x 256). A per-env terrain (a selector of several terrains: ``[num_envs, H, W]`` or a
        Tile with index [num_envs]) is turned env by env."""
        if protocol.headings == 1:
            return terrain
        heading = jnp.arange(ppo.num_envs, dtype=jnp.int32) % protocol.headings
        if env.tiles:
            return Tile(terrain.bank, terrain.index + heading)
        if terrain.ndim == 3:
            turned = difficulty.rotate_headings(terrain, protocol.headings)  # [E x headings, H, W]
            return turned[jnp.arange(ppo.num_envs) * protocol.headings + heading]
        return difficulty.rotate_headings(terrain[None], protocol.headings)[heading]

    def keyed(state: rl.TrainState, key) -> rl.TrainState:
        """``state`` with PPO's stream set to ``key`` (raw [2] uint32)."""
        return state._replace(key=rl.raw_key(key))

    def train(state: rl.TrainState, key, terrain):
        return rl.run_updates(keyed(state, key), spread(terrain), env=env, config=ppo, num_updates=updates)[0]

    def evaluate(state: rl.TrainState, key, terrain):
        params = (state.params, state.normaliser)
        if env.tiles:
            d = tile_distances(env, act, terrain, key, protocol.attempts, params, protocol.headings)[None]
        else:
            d, _ = difficulty.protocol_distances(env, act, terrain[None], key, protocol, policy_params=params)
        return difficulty.aggregate(d, protocol)[0]

    def reset(state: rl.TrainState, key, terrain):
        return rl.reset_envs(state, key, spread(terrain), env=env, config=ppo)

    def train_evaluate(state: rl.TrainState, key, terrain, eval_key):
        """``train`` with ``evaluate``'s walks of the starting policy riding along (``rl.ride_updates``), then
        those still walking walk on alone (:func:`finish_walks`): ``(train(...), evaluate(state, eval_key, ...))``
        in ``updates x num_unrolls x unroll_length`` shared physics steps plus the rest of the longest walk."""
        params = (state.params, state.normaliser)
        world, inner = _walk_tiles(terrain, protocol.attempts, protocol.headings)
        riders = jax.vmap(env.reset, in_axes=(0, inner))(_walk_keys(eval_key, protocol.attempts,
                                                                    protocol.headings), world)
        ride = rl.Ride(act=jax.vmap(lambda obs: act(params, obs)), terrains=world, record=_record_ride,
                       park=lambda carry, states, start: _park_riders(env, carry, states, start))
        zeros = jnp.zeros((protocol.attempts,), jnp.float32)
        per_env = rl.collect.per_env_mask(env, terrain)  # traced once, for both
        state, riders, (ended, final), _ = rl.ride_updates(keyed(state, key), spread(terrain), riders, ride,
                                                           (zeros > 0, zeros), env=env, config=ppo,
                                                           num_updates=updates, per_env=per_env)
        d = finish_walks(env, act, terrain, riders, ended, final, params, protocol.attempts, protocol.headings,
                         ride_steps=updates * ppo.num_unrolls * ppo.unroll_length, per_env=per_env)
        return state, difficulty.aggregate(d[None], protocol)[0]

    def progress(state: rl.TrainState):
        return state.episode.progress

    if not env.tiles:
        if config.overlap:
            raise ValueError("CurriculumConfig.overlap needs a tiled walker (walker_env(..., tiles=trials x "
                             "headings)): its evaluation walks share the PPO envs' physics calls on their tiles")
        return Harness(train=train, evaluate=evaluate, reset=reset, progress=progress)
    return Harness(train=train, evaluate=evaluate, reset=reset, layout=tile_layout(env, protocol.headings),
                   where=lambda pred, a, b: select_policy(env, pred, a, b),
                   train_evaluate=train_evaluate if config.overlap else None,
                   pick=lambda terrains, index: Tile(terrains.bank, terrains.index[index]), progress=progress)


def tile_layout(env, headings: int = 1):
    """The ``Harness.layout`` of a tiled walker (``env.tiles >= 1``): ``terrains [k, H, W]`` metres (the current
    terrains of k trials, e.g. one device's share) -> ``(Tile, TILE_AXES)`` with trial i on tile ``i * headings`` of
    ONE bank: tiles ``i * headings + h`` hold its terrain turned for heading h (``difficulty.rotate_headings``), so
    heading h of a trial (its PPO envs ``e % headings == h``, its evaluation walks of heading h) is tile
    ``index + h``; tiles past ``k * headings`` are flat. Jit-able; ``ValueError`` when ``k * headings > env.tiles``.
    """

    def layout(terrains):
        k = terrains.shape[0]
        if k * headings > env.tiles:
            raise ValueError(f"{k} trials x {headings} heading(s) need {k * headings} tiles but the walker has "
                             f"tiles={env.tiles}: build it with walker_env(..., tiles=trials * headings)")
        turned = difficulty.rotate_headings(terrains, headings)
        if k * headings < env.tiles:
            turned = jnp.concatenate([turned, jnp.zeros((env.tiles - k * headings,) + turned.shape[1:], turned.dtype)])
        return env.make_bank(turned).at(jnp.arange(k, dtype=jnp.int32) * headings), TILE_AXES

    return layout


def select_policy(env, pred, on_true: rl.TrainState, on_false: rl.TrainState) -> rl.TrainState:
    """``on_true`` where ``pred`` ([] bool) else ``on_false``, the env states merged by ``env.select`` (MuJoCo
    Warp's contact buffers are shared by every env and stay so), every other leaf by ``jnp.where``."""
    rest = jax.tree.map(lambda a, b: jnp.where(pred, a, b), on_true._replace(env_state=None),
                        on_false._replace(env_state=None))
    return rest._replace(env_state=env.select(pred, on_true.env_state, on_false.env_state))


def tile_distances(env, policy, tile, key, attempts: int, policy_params=None, headings: int = 1) -> jax.Array:
    """``[attempts]`` normalised distances (0 where a walk failed) of ``attempts`` walks of ``policy(obs)`` (or
    ``policy(policy_params, obs)``) on ``tile`` (a :class:`~jaxterrain.walker.Tile`, index []) of a tiled ``env``,
    until every walk has ended or the episode limit: the loop of ``walker.rollout.batched_distances`` for one terrain
    (keys ``split(key, (1, attempts))``, the same vmap nesting) with the tile in place of ``terrain[None]``.

    ``headings`` > 1: attempt ``a`` walks tile ``index + a // (attempts // headings)`` (the trial's terrain turned
    for that heading, :func:`tile_layout`), keyed ``split(key, (headings, attempts // headings))`` in heading-major
    order: ``difficulty.protocol_distances`` of one terrain, feed them to ``difficulty.aggregate``.

    Under ``jax.vmap`` (the curriculum's trials; the bank shared, one tile index per trial) a custom batching rule
    runs ONE loop over all trials' walks until every walk of every trial has ended: a plain while loop would get a
    per-trial predicate, which ``jax.vmap`` turns into a per-leaf select of the loop state, and that splits MuJoCo
    Warp's contact buffers (shared by all envs). Walks that ended keep their distance, so the distances are those of
    the per-trial loops. Supports one level of vmap."""
    act = (lambda p, obs: policy(obs)) if policy_params is None else policy
    params = () if policy_params is None else policy_params

    @jax.custom_batching.custom_vmap
    def walks(data, index, key, params):
        return _tile_walks(env, act, attempts, headings, data, index[None], key[None], params, None)[0]

    @walks.def_vmap
    def walks_batched(axis_size, in_batched, data, index, key, params):
        data_b, index_b, key_b, params_b = in_batched
        if data_b:
            raise ValueError("tile_distances under vmap: the tile bank must be shared (in_axes TILE_AXES), one "
                             "heightfield for every env")
        index = index if index_b else jnp.broadcast_to(index, (axis_size,))
        key = key if key_b else jnp.broadcast_to(key, (axis_size,) + key.shape)
        axes = jax.tree.map(lambda b: 0 if b else None, params_b)
        return _tile_walks(env, act, attempts, headings, data, index, key, params, axes), True

    return walks(tile.bank.data, jnp.asarray(tile.index, jnp.int32), key, params)


def _walk_keys(key, attempts: int, headings: int) -> jax.Array:
    """``[attempts]`` reset keys of one evaluation: ``split(key, (headings, attempts // headings))`` flattened."""
    return jax.random.split(key, (headings, attempts // headings)).reshape(attempts)


def _record_walks(ended, final, failed, distance, done):
    """After a step of walks (all [..., R]): ``(ended, final)``, a walk's distance (0 if it failed) frozen at the
    step that ended it."""
    return ended | (done > 0), jnp.where(ended, final, jnp.where(failed > 0, 0.0, distance))


def _record_ride(carry, states, start: int):
    """``rl.Ride.record`` of evaluation walks: :func:`_record_walks` of rows ``start ..`` (the riders)."""
    return _record_walks(*carry, states.failed[start:], states.distance[start:], states.done[start:])


def _park_riders(env, carry, states, start: int):
    """``rl.Ride.park`` of evaluation walks: the riders (rows ``start ..`` of ``states``) whose walk ended, parked."""
    ended = carry[0]
    return env.park(states, jnp.concatenate([jnp.zeros((start,), bool), ended]))


def finish_walks(env, act, tile: Tile, riders, ended, final, params, attempts: int, headings: int = 1,
                 ride_steps: int = 0, per_env=None) -> jax.Array:
    """``[attempts]`` distances of one trial's evaluation walks that rode ``ride_steps`` steps along PPO
    (``riders``: their env states [attempts], ``ended`` / ``final`` [attempts] their record so far): the walks not
    yet ended walk on (every walk steps, as in :func:`tile_distances`) until all have ended or the episode limit.
    Under ``jax.vmap`` over trials ONE loop runs for all trials' walks (a custom batching rule, as
    :func:`tile_distances`'s). So the distances are those of :func:`tile_distances` with the same key.
    ``per_env``: ``rl.collect.per_env_mask(env, tile)`` where the caller has it (else traced here)."""
    if per_env is None:
        per_env = rl.collect.per_env_mask(env, Tile(tile.bank, jnp.zeros((), jnp.int32)))

    def one(per_env, x):  # a trial axis of size 1 on the per-env leaves
        return jax.tree.map(lambda p, v: v[None] if p else v, per_env, x)

    @jax.custom_batching.custom_vmap
    def walk_on(data, index, riders, ended, final, params):
        riders = one(per_env, riders)
        carry = (jnp.int32(ride_steps), riders, ended[None], final[None])
        return _walk_loop(env, act, _walk_tiles(Tile(TileBank(data), index[None]), attempts, headings), params, None,
                          carry)[3][0]

    @walk_on.def_vmap
    def walk_on_batched(axis_size, in_batched, data, index, riders, ended, final, params):
        data_b, index_b, riders_b, ended_b, final_b, params_b = in_batched
        if data_b:
            raise ValueError("finish_walks under vmap: the tile bank must be shared (in_axes TILE_AXES)")
        grow = lambda b, x: x if b else jnp.broadcast_to(x, (axis_size,) + x.shape)  # noqa: E731
        riders = jax.tree.map(lambda p, b, x: grow(b, x) if p else x, per_env, riders_b, riders)
        index, ended, final = grow(index_b, index), grow(ended_b, ended), grow(final_b, final)
        axes = jax.tree.map(lambda b: 0 if b else None, params_b)
        out = _walk_loop(env, act, _walk_tiles(Tile(TileBank(data), index), attempts, headings), params, axes,
                         (jnp.int32(ride_steps), riders, ended, final))
        return out[3], True

    return walk_on(tile.bank.data, jnp.asarray(tile.index, jnp.int32), riders, ended, final, params)


def _walk_tiles(tile: Tile, attempts: int, headings: int):
    """``(world, inner in_axes)``: the tiles of the ``attempts`` walks of the trials at ``tile.index`` ([] one trial,
    [B] B trials): the trial's tile itself for one heading (in_axes None over the walks), else walk a on
    ``index + a // (attempts // headings)`` (``TILE_AXES``)."""
    if headings == 1:
        return tile, None
    per = attempts // headings
    return Tile(tile.bank, tile.index[..., None] + jnp.arange(attempts, dtype=jnp.int32) // per), TILE_AXES


def _walk_loop(env, act, world_inner, params, params_axes, carry):
    """The walks' loop: ``carry = (t, states [B, R], ended [B, R], final [B, R])`` stepped (trial b's walks on
    ``world`` with vmap axes ``inner`` over R) until every walk has ended or ``t`` reaches the episode limit. A walk
    that ended is parked (``WalkerEnv.park``) while the others walk on: on MuJoCo Warp a fallen walker lying on the
    terrain would cost the solver more than a walking one."""
    world, inner = world_inner
    step = jax.vmap(jax.vmap(env.step, in_axes=(0, 0, inner)), in_axes=(0, 0, TILE_AXES))
    policy = jax.vmap(jax.vmap(act, in_axes=(None, 0)), in_axes=(params_axes, 0))
    horizon = env.config.episode_length

    def cond(carry):
        t, _, ended, _ = carry
        return (t < horizon) & ~jnp.all(ended)

    def body(carry):
        t, state, ended, final = carry
        state = step(state, policy(params, state.obs), world)
        ended, final = _record_walks(ended, final, state.failed, state.distance, state.done)
        return t + 1, env.park(state, ended), ended, final  # an ended walk steps on out of the way

    return jax.lax.while_loop(cond, body, carry)


def _tile_walks(env, act, attempts: int, headings: int, data, index, keys, params, params_axes, steps: bool = False):
    """``[B, attempts]`` distances of ``attempts`` walks of ``act(params_b, obs)`` on the bank ``data``: trial b's
    attempt a on tile ``index[b] + a // (attempts // headings)``, keyed ``split(keys[b], (headings, attempts //
    headings))`` flattened (for one heading ``split(keys[b], (1, attempts))[0]``, as before headings existed);
    ``params_axes``: vmap axes of ``params`` over B (None: shared). ``steps``: also return the loop's iterations
    ([] int32: the sequential env steps until every walk ended, at most the episode length)."""
    reset_keys = jax.vmap(lambda k: _walk_keys(k, attempts, headings))(keys)
    world, inner = _walk_tiles(Tile(TileBank(data), index), attempts, headings)
    reset = jax.vmap(jax.vmap(env.reset, in_axes=(0, inner)), in_axes=(0, TILE_AXES))
    zeros = jnp.zeros(reset_keys.shape[:2], jnp.float32)
    carry = (jnp.int32(0), reset(reset_keys, world), zeros > 0, zeros)
    t, _, _, final = _walk_loop(env, act, (world, inner), params, params_axes, carry)
    return (final, t) if steps else final


_STATE_SHAPES: dict = {}  # (walker config, PPOConfig, terrain shape) -> the rl.TrainState's shapes (eval_shape)


def start_state(env, ppo: rl.PPOConfig, policy, shape: tuple[int, int]) -> rl.TrainState:
    """The starting ``rl.TrainState``: the policy's params (policy AND value net) and normaliser, a fresh Adam state,
    and zeros for the ``ppo.num_envs`` env states (only their structure counts: the curriculum restarts the envs on
    its first terrain before training). Traces the env (``jax.eval_shape``) once per walker config, PPOConfig and
    terrain shape in a process (the MJX reset's trace takes seconds on a CPU, and every ``learn --resume``,
    ``--report`` or ``--export-policies`` of a treatment, and every treatment of ``curriculum``, starts here); compiles
    nothing. A tiled env's (its envs on one tile) has the same structure; MuJoCo Warp's shared contact buffers stay
    unbatched."""
    sig = (env.config, ppo, tuple(shape))  # a WalkerEnv is built from its config alone
    like = _STATE_SHAPES.get(sig)
    if like is None:
        terrain = (lambda: env.flat_bank().at(0)) if env.tiles else (lambda: jnp.zeros(tuple(shape), jnp.float32))
        like = _STATE_SHAPES[sig] = jax.eval_shape(lambda k: rl.init(k, env, ppo, terrain()), jax.random.key(0))
    zeros = jax.tree.map(lambda x: jnp.zeros(x.shape, x.dtype), like)
    params = jax.tree.map(jnp.asarray, policy.params)
    return zeros._replace(params=params, normaliser=policy.normaliser,
                          opt_state=rl.make_optimizer(ppo).init(params))


def load_policy(path: Optional[str | Path]) -> Any:
    """``rl.load_policy(path)`` with every failure as ``ValueError`` naming the file (None: the base policy)."""
    try:
        return rl.load_policy(path)
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise ValueError(f"policy {path or rl.BASE_POLICY_DIR}: cannot be loaded ({type(err).__name__}: "
                         f"{str(err).splitlines()[0] if str(err) else ''})") from err
    except Exception as err:  # noqa: BLE001 - msgpack raises its own exception types on a corrupt file
        raise ValueError(f"policy {path}: not a readable policy ({type(err).__name__})") from err

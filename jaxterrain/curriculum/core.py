"""The map-based curriculum (and its baselines) as one state pytree and pure functions over it: one trial.

    harness = Harness(train=..., evaluate=..., reset=...)               # injected pure functions (see Harness)
    state = init(key, bank, policy_state, config=config, harness=harness)
    state = step(state, key, bank, config=config, harness=harness)      # one chunk: train, evaluate, update, switch
    states = init_trials(keys [T], bank, policy_state, config=..., harness=...)    # T trials, leading axis [T]

The loops over many trials (``run_trials``, ``make_runner``, ``run_live``) and over the trials of several
treatments at once (``run_population``) are in :mod:`jaxterrain.curriculum.population`; they run the phases of
:func:`step` (:func:`chunk_keys`, :func:`terrain_maps`, :func:`chunk_physics`, :func:`chunk_update`,
:func:`chunk_result`) on a trial axis.

One chunk (:func:`step`) trains the policy on the current terrain for ``epochs_per_chunk`` epochs
(``harness.train``), evaluates it there (``harness.evaluate``), records epoch / terrain / evaluation / hardest
terrain traversed in the history buffers, and when the terrain is finished (threshold reached or ``max_evals``
evaluations spent) adds one observation to the GP, removes terrains (the selector's rule), picks the next terrain
and marks the envs for a restart on it (``restart``: ``harness.reset`` runs at the start of the next chunk, the
one place a reset is compiled). Everything is data (indices and masks, ``jnp.where``): the same code
runs under ``vmap`` over trials, a trial that is done keeps its state unchanged, and nothing re-compiles when the
terrain changes (the terrain is an index into the bank). Decisions and their reasons: :mod:`.config`.

Terrain layouts. By default every trial indexes the bank inside its own (vmapped) step and hands the harness one
``[H, W]`` map. A walker whose heightfield is shared by every env (MuJoCo Warp: one bank of tiles, see
:mod:`jaxterrain.walker.tiles`) cannot take per-trial maps; its harness sets ``Harness.layout`` instead:

    terrain, in_axes = harness.layout(bank.heightmaps[states.terrain])    # [T, H, W] -> e.g. Tile(bank of T, [T])
    jax.vmap(step, in_axes=(0, ..., in_axes))(states, ..., terrain)       # trial i gets terrain i (bank.at(i))

The trial loops do this once per chunk, OUTSIDE the trial vmap, so the T trials' current terrains become
one small bank rebuilt every chunk; ``step`` on a single trial still works (``layout(heightmaps[terrain][None])``,
trial 0 of it). ``Harness.where`` merges two policy states where a per-leaf ``jnp.where`` would not do (the
walker's env states under MuJoCo Warp).

Overlap (``config.overlap``, a harness with ``train_evaluate``): a step trains the next chunk while the pending
chunk's evaluation runs in the same physics calls; the curriculum is the plain one, a terrain switch costing one
step more (:func:`step`). ``State.pending`` marks a trained chunk whose evaluation is still to come. With
``config.eval_lag`` too, a switch keeps the chunk trained meanwhile (recorded with evaluation NaN) instead of
training it again: no step more, the selector a chunk late (:func:`chunk_update`).
"""

from __future__ import annotations

import functools
from typing import Any, Callable, NamedTuple, Optional

import jax
import jax.numpy as jnp

from jaxterrain.curriculum.config import CurriculumConfig
from jaxterrain.curriculum.selectors import (Outcome, Selector, get_selector, gp_params, removal_mask,
                                             roughness_sequence, select, terrain_hardness)
from jaxterrain.qd import TerrainBank
from jaxterrain.walker import carry_rows

__all__ = ["Harness", "History", "State", "Physics", "init", "step", "chunk_keys", "terrain_maps", "chunk_physics",
           "chunk_update", "chunk_result", "init_trials", "terrain_hardness", "roughness_sequence", "select",
           "removal_mask", "gp_params"]
# terrain_hardness, roughness_sequence, select, removal_mask and gp_params live in .selectors (re-exported here)



class Harness(NamedTuple):
    """The pure functions a curriculum drives (fakes in tests, PPO and the walker in :mod:`.walker`).

    train: ``(policy_state, key, terrain [H, W]) -> policy_state``, one chunk of training on one terrain.
    evaluate: ``(policy_state, key, terrain [H, W]) -> fitness []`` float32 in [0, 1].
    reset: ``(policy_state, key, terrain [H, W]) -> policy_state``, restart the envs on a new terrain (None: the
      state is kept as it is).
    layout: ``terrains [T, H, W] -> (terrain, in_axes)`` (None: the classic layout, ``terrain`` = one ``[H, W]`` map
      per trial): the T trials' current terrains as ONE pytree, and its ``jax.vmap`` in_axes over the trials;
      trial i's slice is the ``terrain`` that train / evaluate / reset receive (the walker's: ``bank.at(i)``, a
      :class:`~jaxterrain.walker.Tile` of a bank of the T terrains). Called once per chunk outside the trial vmap.
    where: ``(pred [] bool, on_true, on_false) -> policy_state`` merging two policy states (None: ``jnp.where``
      leaf by leaf; the walker's merges its env states with ``env.select``).
    train_evaluate: ``(policy_state, train_key, terrain, eval_key) -> (policy_state, fitness [])``, ``train`` and,
      in the same physics calls, ``evaluate`` of the policy it STARTS from (``CurriculumConfig.overlap``): equal to
      ``(train(p, train_key, terrain), evaluate(p, eval_key, terrain))``. None: no overlap.
    pick: ``(terrains, index) -> terrain``, for selectors of several terrains a chunk (``Selector.slots`` K > 1):
      ``terrains`` is the trial's K terrains (``[K, H, W]``, or its slice of ``layout`` of all trials' ``[T x K, H,
      W]`` with the leading axis split into ``[T, K]``), ``index`` [] or [E] int32 slots; the result is one terrain
      (evaluate) or one per env (train / reset: then ``[E, H, W]``, or the walker's ``Tile`` with index [E]).
      None: ``terrains[index]``.
    progress: ``policy_state -> [E] float32``, each env's furthest normalised distance since its envs' last
      restart (``Outcome.progress``; selectors with ``Selector.progress`` need it). None: no such selector runs.
    """

    train: Callable
    evaluate: Callable
    reset: Optional[Callable] = None
    layout: Optional[Callable] = None
    where: Optional[Callable] = None
    train_evaluate: Optional[Callable] = None
    pick: Optional[Callable] = None
    progress: Optional[Callable] = None


class History(NamedTuple):
    """Per-chunk records, fixed length ``C = config.max_chunks``; entries after the last chunk hold -1 / NaN.

    epoch: [C] int32 epochs done after the chunk. terrain: [C] int32 bank index trained in the chunk.
    evaluation: [C] float32 fitness of the updated policy on it. hardest: [C] float32 hardest terrain traversed so
    far (distance in cells, 0 before any).
    """

    epoch: jax.Array
    terrain: jax.Array
    evaluation: jax.Array
    hardest: jax.Array


class State(NamedTuple):
    """One trial's curriculum (a pytree; :func:`init_trials` adds a leading trial axis to every leaf).

    policy: the harness's policy state (``jaxterrain.rl.TrainState`` with the walker). key: [2] uint32, the trial's
    key (chunk ``c`` uses ``fold_in(key, c)``, so a resumed run continues the same stream). selector: the
    selector's state (:mod:`.selectors`; e.g. ``SequenceState`` for map / roughness / random, with the GP's
    observations). terrain: [] int32 the terrain the current chunk is evaluated on (one-terrain selectors: the
    terrain trained; the selector's ``assign`` holds the rest). chunk, epoch, env_steps: [] int32
    counters. hardest: [] float32 hardest terrain traversed (distance, cells). done: [] bool. restart: [] bool, the
    envs restart on the current terrain (``harness.reset``) before the next chunk trains (set by :func:`init` and on
    a terrain switch; set it yourself to restart them, e.g. after restoring a state saved without env states).
    history: History. pending: None, or with ``config.overlap`` [] bool: ``policy`` has trained one chunk more than
    ``chunk`` counts (chunk ``chunk``, on ``terrain``) and its evaluation is pending (:func:`step`).
    """

    policy: Any
    key: jax.Array
    selector: Any
    terrain: jax.Array
    chunk: jax.Array
    epoch: jax.Array
    env_steps: jax.Array
    hardest: jax.Array
    done: jax.Array
    restart: jax.Array
    history: History
    pending: Any = None


# Checkpoints written before the selector protocol (2026-11-28) hold a sequence selector's state at the top level
# of State; ``driver.restore(folder, like, **CHECKPOINT_COMPAT)`` reads them into ``State.selector``.
CHECKPOINT_COMPAT = {
    "aliases": {".selector.current": ".terrain", **{f".selector.{name}": f".{name}" for name in (
        "available", "terrain_evals", "terrain_best", "obs_index", "obs_y", "obs_count")}},
    "defaults": (".episode.progress",),
}


# ----------------------------------------------------------------------------------------------------------------
# Pure helpers
# ----------------------------------------------------------------------------------------------------------------
def _where_tree(pred, on_true, on_false):
    return jax.tree.map(lambda a, b: jnp.where(pred, a, b), on_true, on_false)


def _where_policy(harness: Harness, pred, on_true, on_false):
    """Two policy states merged by ``pred`` []: ``harness.where`` when set, else :func:`_where_tree`."""
    if harness.where is None:
        return _where_tree(pred, on_true, on_false)
    return harness.where(pred, on_true, on_false)


def _take(tree, axes, i: int):
    """Element ``i`` along ``axes`` (a vmap ``in_axes`` prefix of ``tree``; None = shared, kept whole)."""
    return jax.tree.map(lambda a, x: x if a is None else jax.tree.map(lambda v: jnp.take(v, i, axis=a), x), axes,
                        tree, is_leaf=lambda a: a is None)


def _assigned_maps(selector: Selector, selector_state, bank: TerrainBank) -> jax.Array:
    """``[K, H, W]``: the maps of a trial's K slots, ``selector.maps`` or the bank's maps of its assignment."""
    if selector.maps is not None:
        return selector.maps(selector_state, bank)
    return bank.heightmaps[selector.assign(selector_state).terrains]


def _current_terrain(bank: TerrainBank, index, harness: Harness, slots: int = 1, maps=None):
    """One trial's terrain argument for the harness: ``bank.heightmaps[index]`` [H, W], or with ``harness.layout``
    trial 0 of ``layout(bank.heightmaps[index][None])``. ``slots`` > 1: ``maps`` is the trial's [K, H, W] slot
    maps (:func:`_assigned_maps`) and the result their slotted form (``[K, H, W]``, or ``layout``'s of the K
    maps, K tiles)."""
    maps = bank.heightmaps[index] if maps is None else maps
    if harness.layout is None:
        return maps
    if slots > 1:
        return harness.layout(maps)[0]
    terrain, axes = harness.layout(maps[None])
    return _take(terrain, axes, 0)


def _pick(harness: Harness, terrains, index):
    return terrains[index] if harness.pick is None else harness.pick(terrains, index)


def _split_terrain(terrain, assignment, harness: Harness, slots: int):
    """``(train terrain, evaluation terrain)`` of a trial's terrain argument: the same one for one-terrain
    selectors; for K slots the per-env terrains (``pick(terrain, env_slot)``) and the evaluated slot's."""
    if slots == 1 and assignment.env_slot is None:
        return terrain, terrain
    env_slot = assignment.env_slot
    if env_slot is None:
        raise ValueError("a selector of several slots must assign every env a slot (Assignment.env_slot)")
    return _pick(harness, terrain, env_slot), _pick(harness, terrain, assignment.evaluated)


def _raw(key):
    return jax.random.key_data(key) if jnp.issubdtype(key.dtype, jax.dtypes.prng_key) else key


def _typed(key):
    return key if jnp.issubdtype(key.dtype, jax.dtypes.prng_key) else jax.random.wrap_key_data(key)


# ----------------------------------------------------------------------------------------------------------------
# init / step
# ----------------------------------------------------------------------------------------------------------------
def _evaluated_terrain(selector: Selector, selector_state) -> jax.Array:
    a = selector.assign(selector_state)
    return a.terrains[a.evaluated]


def init(key: jax.Array, bank: TerrainBank, policy: Any, *, config: CurriculumConfig, harness: Harness) -> State:
    """A trial at its start: the selector's state (``selector.init``: map's first terrain is the prior's argmax),
    its envs due for a restart on the first assignment (the first :func:`step` calls ``harness.reset``).
    ``policy``: the starting policy state (the base policy's params and normaliser in an ``rl.TrainState``; its env
    state only gives the structure). Pure; vmap over ``key`` for trials."""
    key = _typed(key)
    trial_key, select_key = jax.random.split(key)
    del key
    selector = get_selector(config)
    chosen = selector.init(select_key, bank)
    c = config.max_chunks
    zi, zf = jnp.zeros((), jnp.int32), jnp.zeros((), jnp.float32)
    history = History(epoch=jnp.full((c,), -1, jnp.int32), terrain=jnp.full((c,), -1, jnp.int32),
                      evaluation=jnp.full((c,), jnp.nan, jnp.float32), hardest=jnp.full((c,), jnp.nan, jnp.float32))
    return State(policy=policy, key=_raw(trial_key), selector=chosen, terrain=_evaluated_terrain(selector, chosen),
                 chunk=zi, epoch=zi, env_steps=zi, hardest=zf, done=jnp.zeros((), bool), restart=jnp.ones((), bool),
                 history=history, pending=jnp.zeros((), bool) if config.overlap else None)


def step(state: State, key: jax.Array, bank: TerrainBank, *, config: CurriculumConfig, harness: Harness,
         terrain: Any = None) -> State:
    """One chunk of one trial (pure; see the module docstring). A trial that is ``done`` is returned unchanged.
    The composition of the chunk's phases, which a population of trials runs on other axes
    (:func:`jaxterrain.curriculum.population.run_population`): :func:`chunk_keys`, :func:`terrain_maps`,
    :func:`chunk_physics` (the harness's work), :func:`chunk_update` (the selector's) and :func:`chunk_result`.

    ``terrain``: the current terrain ``state.terrain`` as the harness takes it; None (the default) builds it here,
    ``bank.heightmaps[state.terrain]`` [H, W] (through ``harness.layout`` when set). The population loop passes
    trial i's slice of the layout of all trials' terrains.

    With ``config.overlap`` a call is one step of the overlapped loop instead (``key`` unused: chunk c's keys are
    ``fold_in(state.key, c)``, as the trial loops give them): ``harness.train_evaluate`` trains the next chunk
    while the walks of the pending evaluation ride along. Not pending (the start, after a switch): train chunk
    ``chunk`` and mark it pending. Pending: evaluate the policy of chunk ``chunk`` (the curriculum's update of a
    chunk, below) while chunk ``chunk + 1`` trains on the same terrain; keep that training when the trial stays on
    its terrain, else drop it (the next step trains chunk ``chunk + 1`` again, on the new terrain, after the
    restart). Every chunk has the keys, starting policy, terrain and evaluation of the plain loop, so the records,
    the GP and the choices are the plain loop's (given the same env states at block starts); a terrain switch costs
    one step more. With ``config.eval_lag`` as well, that training is kept on a switch (:func:`chunk_update`)."""
    selector = get_selector(config)
    keys = chunk_keys(state, config, key)
    if terrain is None:
        terrain = _current_terrain(bank, state.terrain, harness, 1 if config.overlap else selector.slots,
                                   terrain_maps(state, bank, config=config))
    physics = chunk_physics(state.policy, state.restart, keys, terrain, selector.assign(state.selector),
                            config=config, harness=harness, progress=selector.progress)
    new, use_trained = chunk_update(state, physics.fitness, physics.progress, keys, bank, config=config)
    return chunk_result(state, new, physics, use_trained, state.done, harness)


class Physics(NamedTuple):
    """What a chunk's physics gives back (:func:`chunk_physics`). start: the policy state the chunk started from
    (its envs restarted where ``State.restart``). trained: after the chunk's training. fitness: [] float32 the
    evaluation (plain: of ``trained``; overlap: of ``start``). progress: [E] float32 each env's furthest distance
    (``Harness.progress`` of ``trained``), or None."""

    start: Any
    trained: Any
    fitness: jax.Array
    progress: Any = None


def chunk_keys(state: State, config: CurriculumConfig, key: Optional[jax.Array] = None) -> jax.Array:
    """``[4, 2]`` uint32: the (train, eval, select, reset) keys of the chunk a trial is at: ``split(key, 4)``,
    ``key`` by default ``fold_in(state.key, state.chunk)``. With ``config.overlap`` (``key`` unused): eval and
    select of chunk ``chunk``, train and reset of the chunk trained next (``chunk + pending``)."""
    if config.overlap:
        train, _, _, reset = _chunk_keys(state, state.chunk + state.pending.astype(jnp.int32))
        _, evaluate, select_key, _ = _chunk_keys(state, state.chunk)
        return _raw(jnp.stack([train, evaluate, select_key, reset]))
    key = jax.random.fold_in(_typed(state.key), state.chunk) if key is None else _typed(key)
    return _raw(jax.random.split(key, 4))


def terrain_maps(state: State, bank: TerrainBank, *, config: CurriculumConfig) -> jax.Array:
    """The maps a trial's chunk is on: ``[H, W]`` ``bank.heightmaps[state.terrain]`` (one-terrain selectors), or
    ``[K, H, W]`` its K slots' maps (``Selector.slots`` K > 1). Pure; vmap it over trials."""
    selector = get_selector(config)
    if selector.slots > 1 and not config.overlap:
        return _assigned_maps(selector, state.selector, bank)
    return bank.heightmaps[state.terrain]


def chunk_physics(policy: Any, restart: jax.Array, keys: jax.Array, terrain: Any, assignment: Any, *,
                  config: CurriculumConfig, harness: Harness, progress: bool = False) -> Physics:
    """A chunk's harness work for one trial: the envs restarted where ``restart`` ([] bool), the training and the
    evaluation (plain: ``harness.train`` then ``harness.evaluate`` of the trained policy; ``config.overlap``:
    ``harness.train_evaluate``, the evaluation of the starting policy riding along). ``keys``: :func:`chunk_keys`;
    ``terrain``: the trial's terrain argument (one ``[H, W]`` map, or its slice of ``harness.layout``); for K > 1
    slots the trial's K terrains, which ``assignment`` (``Selector.assign``) deals to the envs. ``progress``: also
    ``harness.progress`` of the trained policy (a selector that reads ``Outcome.progress`` runs). Pure."""
    train_key, eval_key, _, reset_key = (_typed(keys[i]) for i in range(4))
    if config.overlap:
        if harness.train_evaluate is None:
            raise ValueError("CurriculumConfig.overlap needs a harness with train_evaluate (the walker's on tiles)")
        start = _restart(policy, restart, reset_key, terrain, harness)
        trained, fitness = harness.train_evaluate(start, train_key, terrain, eval_key)
        return Physics(start, trained, fitness)
    trained_on, evaluated_on = _split_terrain(terrain, assignment, harness, get_selector(config).slots)
    start = _restart(policy, restart, reset_key, trained_on, harness)
    trained = harness.train(start, train_key, trained_on)
    fitness = harness.evaluate(trained, eval_key, evaluated_on)
    if not progress:
        return Physics(start, trained, fitness)
    if harness.progress is None:
        raise ValueError(f"selector {config.selector!r} needs a harness with progress (each env's distance)")
    return Physics(start, trained, fitness, harness.progress(trained))


def chunk_update(state: State, fitness: jax.Array, progress: Any, keys: jax.Array, bank: TerrainBank, *,
                 config: CurriculumConfig) -> tuple[State, Optional[jax.Array]]:
    """A trial's curriculum after its chunk's physics (``fitness`` [], ``progress`` [E] or None, ``keys``
    :func:`chunk_keys`): ``(new, use_trained)``. ``new``: the state's counters, history, selector (its next
    terrains) and done, ``policy`` None (``state.policy`` is not read). ``use_trained``: None (plain: the policy
    after the chunk is the trained one), or with ``config.overlap`` [] bool: the trained policy (True) or the
    starting one (the training dropped on a terrain switch). Pure; vmap it over trials.

    ``config.eval_lag`` (with overlap): on a terrain switch the chunk trained while the evaluation ran (chunk
    ``state.chunk + 1``, on the terrain just finished) is kept: it is recorded with evaluation NaN and the hardest
    record unchanged, its epochs counted, and the next step trains the chunk after it on the new terrain (nothing
    pending). The training is dropped only when the trial is done. So every history row holds its own chunk's
    terrain and, where evaluated, the evaluation of the policy after that chunk with that chunk's keys; the selector
    decides for a policy one chunk further on than the one it read."""
    selector = get_selector(config)
    bare = state._replace(policy=None)
    new = _evaluated(bare, None, fitness, bank, _typed(keys[2]), config, selector,
                     progress if selector.progress else None)
    if not config.overlap:
        return new, None
    stays = ~new.done & ~new.restart  # the chunk just trained was trained on the right terrain
    started = bare._replace(restart=jnp.zeros((), bool), pending=jnp.ones((), bool))
    if not config.eval_lag:
        return _where_tree(state.pending, new._replace(pending=stays), started), ~state.pending | stays
    # eval_lag: on a switch the chunk trained meanwhile (on the old terrain) is kept, recorded unevaluated
    switched = ~new.done & new.restart
    after = _where_tree(switched, _unevaluated(new, state.terrain, config)._replace(pending=jnp.zeros((), bool)),
                        new._replace(pending=stays))
    return _where_tree(state.pending, after, started), ~state.pending | ~new.done


def chunk_result(state: State, new: State, physics: Physics, use_trained, hold, harness: Harness) -> State:
    """The trial after its chunk: ``new`` (:func:`chunk_update`) with the policy it ends with, or ``state``
    unchanged where ``hold`` ([] bool: the trial is done, or not stepped)."""
    policy = physics.trained if use_trained is None else _where_policy(harness, use_trained, physics.trained,
                                                                       physics.start)
    kept = _where_tree(hold, state._replace(policy=None), new)
    return kept._replace(policy=_where_policy(harness, hold, state.policy, policy))


def _restart(policy, restart, key, terrain, harness: Harness):
    """``policy`` with its envs restarted on ``terrain`` where ``restart``."""
    if harness.reset is None:
        return policy
    return _where_policy(harness, restart, harness.reset(policy, key, terrain), policy)


def _evaluated(state: State, policy, fitness, bank: TerrainBank, select_key, config: CurriculumConfig,
               selector: Selector, progress=None) -> State:
    """The curriculum's update after chunk ``state.chunk`` evaluated on ``state.terrain`` ended with ``policy``
    evaluated at ``fitness``: counters, the hardest terrain traversed, history, the selector's update (its next
    terrains; map: the GP observation when the terrain is finished), done."""
    hardness = terrain_hardness(bank, config.distance_origin)
    t = state.terrain
    fitness = jnp.asarray(fitness, jnp.float32).reshape(())
    reached = fitness >= config.threshold * config.max_fitness
    chosen, decision = selector.update(state.selector, select_key, bank, Outcome(t, fitness, progress))
    credited = decision.finished if config.credit == "finished" else reached
    hardest = jnp.where(credited, jnp.maximum(state.hardest, hardness[t]), state.hardest)
    epoch = state.epoch + config.epochs_per_chunk
    done = decision.exhausted | (epoch >= config.max_epochs)

    c = state.chunk
    h = state.history
    history = History(epoch=h.epoch.at[c].set(epoch, mode="drop"), terrain=h.terrain.at[c].set(t, mode="drop"),
                      evaluation=h.evaluation.at[c].set(fitness, mode="drop"),
                      hardest=h.hardest.at[c].set(hardest, mode="drop"))
    return state._replace(policy=policy, selector=chosen, terrain=_evaluated_terrain(selector, chosen), chunk=c + 1,
                          epoch=epoch, env_steps=state.env_steps + config.steps_per_chunk, hardest=hardest, done=done,
                          restart=decision.restart, history=history)


def _unevaluated(state: State, terrain, config: CurriculumConfig) -> State:
    """``state`` after one more chunk trained on ``terrain`` and not evaluated (``CurriculumConfig.eval_lag``: the
    chunk trained while the evaluation that finished ``terrain`` was walked): counters on, its history row with
    ``evaluation`` NaN and the hardest record unchanged, done when the epochs are spent."""
    c, h = state.chunk, state.history
    epoch = state.epoch + config.epochs_per_chunk
    history = History(epoch=h.epoch.at[c].set(epoch, mode="drop"), terrain=h.terrain.at[c].set(terrain, mode="drop"),
                      evaluation=h.evaluation.at[c].set(jnp.nan, mode="drop"),
                      hardest=h.hardest.at[c].set(state.hardest, mode="drop"))
    return state._replace(chunk=c + 1, epoch=epoch, env_steps=state.env_steps + config.steps_per_chunk,
                          done=state.done | (epoch >= config.max_epochs), history=history)


def _chunk_keys(state: State, chunk):
    """Chunk ``chunk``'s ``(train, eval, select, reset)`` keys: ``split(fold_in(state.key, chunk), 4)``."""
    return jax.random.split(jax.random.fold_in(_typed(state.key), chunk), 4)


# ----------------------------------------------------------------------------------------------------------------
# Many trials at once (the loops over them: jaxterrain.curriculum.population)
# ----------------------------------------------------------------------------------------------------------------
def init_trials(keys: jax.Array, bank: TerrainBank, policy: Any, *, config: CurriculumConfig,
                harness: Harness) -> State:
    """:func:`init` vmapped over ``keys`` [T] (typed or raw [T, 2]); the bank and starting policy are shared. The
    starting policy's env state (``policy.env_state``, where it has one) is carried in the form of
    :func:`~jaxterrain.walker.carry_rows`, so a block that gathers or slices trials returns the shapes it takes on
    MuJoCo Warp too (its envs restart at the first chunk anyway)."""
    fn = functools.partial(init, config=config, harness=harness)
    states = jax.vmap(fn, in_axes=(0, None, None))(keys, bank, policy)
    env_state = getattr(policy, "env_state", None)
    if env_state is None or getattr(states.policy, "env_state", None) is None:
        return states
    return states._replace(policy=states.policy._replace(env_state=carry_rows(env_state, states.done.shape[0])))

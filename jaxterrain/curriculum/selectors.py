"""Curricula as selectors: which terrains a trial trains on, as a pytree state and pure functions over it.

    selector = get_selector(config)                       # config.selector: map, roughness, random, dr, levels, plr, accel
    s = selector.init(key, bank)                          # the selector's state (rides in core.State.selector)
    a = selector.assign(s)                                # Assignment: the trial's K terrains, env -> terrain, evaluated
    s, decision = selector.update(s, key, bank, outcome)  # after a chunk: Outcome(terrain, fitness, progress)

The shape is optax's ``GradientTransformation`` and JaxUED's ``LevelSampler``: a :class:`Selector` is a NamedTuple of
pure functions, built once from the (static) :class:`~jaxterrain.curriculum.CurriculumConfig`; its state is any
pytree of arrays. The trial loop (:mod:`.core`, jitted and vmapped over trials) never knows which selector runs:
each chunk it trains the envs on the assignment, evaluates the policy on the assignment's ``evaluated`` terrain,
credits the hardest terrain traversed, and hands the selector the :class:`Outcome`; the selector's
:class:`Decision` says whether the envs restart (new terrains) and whether the trial has run out of terrains.

Two kinds ship:

- **Sequence selectors** (``slots = 1``: every env on one terrain until it is finished, the paper's Experiment 2):
  ``map`` (the IT&E GP: UCB choice and the removal rule), ``roughness`` (standard CL: every ``roughness_stride``-th
  terrain in order of roughness) and ``random`` (uniform among the terrains not yet trained). A terrain is finished
  at ``threshold x max_fitness`` or after ``max_evals`` evaluations (:class:`SequenceState`).
- **Per-env selectors** (``slots = K > 1``: the trial's envs spread over K terrains, each env on its own, new
  terrains every chunk and the envs restarted on them): ``dr`` (domain randomisation: K terrains drawn uniformly
  from the bank every chunk, envs dealt round-robin) and ``levels`` (legged_gym's terrain curriculum: ``levels``
  difficulty levels, each env moved up or down by how far it walked, :class:`LevelsState`), ``plr``
  (prioritised level replay: JaxUED's level buffer over the bank's terrains, :class:`PLRState`) and ``accel``
  (PLR over a generator's genomes, rendered in the loop, the replayed levels edited by the generator's ``mutate``
  and re-inserted, :class:`AccelState`; ``Selector.maps`` gives the loop its maps).

Where ours differ from the field's (decisions, with reasons):

- Terrains are re-drawn and levels moved at chunk boundaries (every ``epochs_per_chunk x steps_per_epoch`` env
  steps: 320 steps of each of the 500 envs at the paper's sizes, about 1.5 walks), not at each env's own reset as
  in legged_gym (``_update_terrain_curriculum`` runs in ``reset_idx``): the terrains of a chunk are one bank of
  tiles shared by every env on MuJoCo Warp, rebuilt once per chunk.
- ``levels``: legged_gym's levels are columns of a terrain grid made at increasing difficulty; ours are bands of
  equal size of the bank ordered by hardness (``terrain_hardness``: the cell's distance from (0, 0)), level 0 the
  easiest. Each chunk level l's terrain is drawn uniformly from band l. Its rule (legged_gym's defaults): an env
  moves up when it walked far (``progress >= levels_promote``, default ``threshold``: it crossed the terrain, where
  legged_gym asks for more than half its 8 m tile from the tile's centre, i.e. to the tile's edge), down when it
  walked less than ``levels_demote`` (0.5) of the course (legged_gym: less than half the distance its command
  asked for), and past the top it goes to a random level (``randint(0, levels)``; below 0 it stays at 0). Envs
  start at random levels ``0 .. levels_init`` (default ``levels // 2``: legged_gym's ``max_init_terrain_level =
  5`` of 10).
  ``progress`` is each env's furthest normalised distance since the chunk's restart (``Outcome.progress``).
- ``plr`` keeps JaxUED's ``LevelSampler`` and the defaults of its ``maze_plr.py`` (replay probability 0.8 once the
  buffer is half full, rank prioritisation at temperature 0.3, staleness coefficient 0.3, duplicates updated, not
  added), with a level = a bank terrain (so the buffer holds at most the bank's N) and three differences: (0) the
  buffer is sized to the run (:func:`plr_buffer_capacity`: half full after the first tenth of its chunks; 128 at
  ``gpu-short``), not 4 000 levels: JaxUED's buffer fills to half in its first 0.2 % of updates, while at 8 new
  levels a chunk a 4 000 buffer would need 250 chunks, more than a 75-chunk run has; (1) a terrain's score is
  its *learnability* ``p (1 - p)`` (p: the fraction of its envs that reached the threshold in the chunk; Rutherford et al. 2024's SFL), not MaxMC or the positive value loss, which
  need per-level value estimates that our chunk does not expose; (2) new terrains are trained on (PLR's
  "exploratory gradient updates", JaxUED's ``--exploratory_grad_updates``), not only scored as robust PLR does:
  a chunk's PPO rollouts are the only rollouts it makes, and scoring without training would spend a chunk's
  budget on evaluation.
- ``accel`` keeps JaxUED's ``accel`` branch structure (a chunk on new levels or, with the replay probability, on
  buffer replays; the chunk after a replay on the replayed levels, each edited; new and edited levels scored and
  inserted, replayed ones re-scored) with ``plr``'s buffer defaults and its differences (a buffer sized to the
  run, learnability scores, edited and new levels trained on, where robust ACCEL only scores them), and: a level is a genome of
  ``accel_generator`` (JaxUED: a maze), a new level is the generator's random ``sample`` (JaxUED's ACCEL starts
  from empty mazes), an edit is ``accel_edits`` (default 1) applications of the generator's own ``mutate`` (the
  paper's operator; JaxUED edits 5 maze tiles), and the buffer's capacity is :func:`plr_buffer_capacity` genomes (not bound
  by the bank). The policy is also evaluated each chunk on one bank terrain drawn uniformly (an extra slot no env
  trains on), so the paper's "hardest terrain traversed" is recorded on the archive as for ``dr``.
- Per-env selectors evaluate (for the record of the hardest terrain traversed, the paper's metric) one terrain a
  chunk: ``dr`` and ``plr`` their first slot, ``levels`` the terrain of the highest level an env stands on (so a
  ``levels`` trial whose envs reached the top band is evaluated there, and credits nothing until it walks it),
  ``accel`` a uniform bank terrain in an extra slot.

A selector of your own: a function ``(config) -> Selector`` registered with :func:`register_selector` (or named as
``module:object`` in ``CurriculumConfig.selector``), e.g. from a plugin module.
"""

from __future__ import annotations

import functools
import importlib
import math
from typing import Any, Callable, NamedTuple, Optional

import jax
import jax.numpy as jnp

from jaxterrain import generators
from jaxterrain.curriculum import gp
from jaxterrain.qd import GRID_BINS, MAX_DISTANCE_50, TerrainBank
from jaxterrain.terrain import TerrainScale

__all__ = ["Selector", "Assignment", "Outcome", "Decision", "SequenceState", "DRState", "LevelsState", "PLRState",
           "get_selector", "register_selector", "selector_names", "sequence_selector", "dr_selector",
           "levels_selector", "plr_selector", "accel_selector", "accel_generator", "LevelBuffer", "AccelState",
           "ACCEL_NEW", "ACCEL_REPLAY", "ACCEL_EDIT", "plr_buffer_capacity", "PLR_FILL_FRACTION", "plr_weights", "plr_insert", "plr_sample", "learnability", "terrain_hardness", "roughness_sequence", "select", "removal_mask", "gp_params",
           "level_bands", "levels_rule"]


class Assignment(NamedTuple):
    """The terrains of a trial's next chunk.

    terrains: [K] int32 bank indices (K = ``Selector.slots``). env_slot: [E] int32, env e trains on
    ``terrains[env_slot[e]]`` (E = the PPO envs of a trial), or None: every env on ``terrains[0]`` (K = 1).
    evaluated: [] int32 slot whose terrain the policy is evaluated on after the chunk."""

    terrains: jax.Array
    env_slot: Optional[jax.Array]
    evaluated: jax.Array


class Outcome(NamedTuple):
    """What a chunk showed. terrain: [] int32 the evaluated bank index. fitness: [] float32 its evaluation (the
    difficulty protocol, in [0, 1]). progress: [E] float32 each PPO env's furthest normalised distance since the
    chunk's restart, or None when the selector does not need it (sequence selectors)."""

    terrain: jax.Array
    fitness: jax.Array
    progress: Optional[jax.Array] = None


class Decision(NamedTuple):
    """What the loop does next. finished: [] bool the evaluated terrain's stint ended (``credit = "finished"``
    credits it). restart: [] bool the envs restart on the new assignment before the next chunk. exhausted: [] bool no
    terrain is left, the trial ends."""

    finished: jax.Array
    restart: jax.Array
    exhausted: jax.Array


class Selector(NamedTuple):
    """A curriculum's choice of terrains (pure functions; ``jax.vmap`` them over trials).

    name: its ``CurriculumConfig.selector``. slots: K terrains per chunk (static; 1 = every env on one terrain).
    progress: whether :func:`update` reads ``Outcome.progress`` (the loop computes it only then).
    init: ``(key, bank) -> state``. assign: ``state -> Assignment``. update: ``(state, key, bank, Outcome) ->
    (state, Decision)``. summary: ``state -> {name: [] array}``, what a treatment's ``summary.json`` records per
    trial (e.g. terrains finished, final levels). maps: None (the assignment's terrains are
    ``bank.heightmaps[Assignment.terrains]``), or ``(state, bank) -> [K, H, W]`` float32 metres, the slots' maps
    for selectors whose levels are not bank terrains (``accel``: genomes rendered in the loop; their
    ``Assignment.terrains`` entries are -1, except the evaluated slot, which must be a bank terrain)."""

    name: str
    slots: int
    init: Callable
    assign: Callable
    update: Callable
    summary: Callable
    progress: bool = False
    maps: Optional[Callable] = None


# ----------------------------------------------------------------------------------------------------------------
# Pure helpers
# ----------------------------------------------------------------------------------------------------------------
def gp_params(config) -> gp.GPParams:
    return gp.GPParams(rho=config.rho, sigma_f=config.sigma_f, noise=config.noise)


def terrain_hardness(bank: TerrainBank, origin: str = "origin") -> jax.Array:
    """``[N]`` float32 hardness of each terrain in cells: ``bank.distance`` (from cell (0, 0)) for ``"origin"``,
    ``70.71 - hypot(50 - b0, 50 - b1)`` for ``"top_right"`` (see :mod:`.config`)."""
    if origin == "origin":
        return jnp.asarray(bank.distance, jnp.float32)
    b = jnp.asarray(bank.bins, jnp.float32)
    return MAX_DISTANCE_50 - jnp.hypot(GRID_BINS - b[:, 0], GRID_BINS - b[:, 1])


def roughness_sequence(bank: TerrainBank, stride: int) -> tuple[jax.Array, jax.Array]:
    """Standard CL's terrains: ``(rank [N] int32, member [N] bool)``. ``rank`` is each terrain's position in the
    order of increasing descriptor 0 (roughness; ties by index); ``member`` marks every ``stride``-th of that order
    (positions 0, stride, 2 stride, ...)."""
    order = jnp.argsort(jnp.asarray(bank.descriptors)[:, 0], stable=True)
    rank = jnp.zeros(order.shape[0], jnp.int32).at[order].set(jnp.arange(order.shape[0], dtype=jnp.int32))
    return rank, (rank % stride) == 0


PLR_FILL_FRACTION = 0.1
"""``plr_capacity=None``: the buffer reaches ``plr_min_fill`` after this fraction of the run's chunks."""


def plr_buffer_capacity(config) -> int:
    """Entries of ``plr``'s and ``accel``'s level buffer: ``plr_capacity``, or with None the buffer that the new levels
    of the run's first ``PLR_FILL_FRACTION`` of chunks (``terrains_per_chunk`` each, at least one chunk) fill to
    ``plr_min_fill``: ``ceil(K x ceil(chunks / 10) / plr_min_fill)`` (``gpu-short``, 75 chunks of 8: 128; the
    paper's budget, 750 chunks: 1 200). ``plr`` bounds it further by the bank's terrains."""
    if config.plr_capacity is not None:
        return int(config.plr_capacity)
    new = int(config.terrains_per_chunk) * max(1, math.ceil(config.max_chunks * PLR_FILL_FRACTION))
    return max(int(config.terrains_per_chunk), math.ceil(new / config.plr_min_fill) if config.plr_min_fill > 0 else new)


def select(score: jax.Array, available: jax.Array, hardness: jax.Array) -> jax.Array:
    """``[] int32``: the available terrain of highest ``score`` [N]; ties to the smallest ``hardness``, then the lowest
    index. 0 when none is available (check ``available.any()``)."""
    s = jnp.where(available, jnp.nan_to_num(score, nan=-jnp.inf), -jnp.inf)
    cand = available & (s == jnp.max(s))
    return jnp.argmin(jnp.where(cand, hardness, jnp.inf)).astype(jnp.int32)


def removal_mask(mean: jax.Array, trained: jax.Array, hardness: jax.Array, margin: float, ties: str) -> jax.Array:
    """``[N] bool``: terrains the map curriculum removes after finishing terrain ``trained`` ([] int32).

    ``mean`` [N] is the updated GP's posterior mean. Removed: ``trained`` itself; terrains predicted clearly easier,
    ``mean > mean[trained] + margin``; and of the ties (``|mean - mean[trained]| <= margin``) none (``"keep"``),
    all (``"remove"``) or those no further from the origin (``hardness <= hardness[trained]``, ``"nearer"``).
    """
    mu_t = mean[trained]
    tie = jnp.abs(mean - mu_t) <= margin
    if ties == "nearer":
        tie = tie & (hardness <= hardness[trained])
    elif ties == "keep":
        tie = jnp.zeros_like(tie)
    elif ties != "remove":
        raise ValueError(f"removal_ties must be nearer, keep or remove, got {ties!r}")
    return (mean > mu_t + margin) | tie | (jnp.arange(mean.shape[0]) == trained)


def _posterior(bank: TerrainBank, obs_index, obs_y, config):
    mask = obs_index >= 0
    idx = jnp.maximum(obs_index, 0)
    return gp.posterior(bank.points[idx], obs_y, mask, bank.fitness[idx], bank.points, bank.fitness,
                        gp_params(config))


# ----------------------------------------------------------------------------------------------------------------
# Sequence selectors: map (IT&E), roughness (standard CL), random
# ----------------------------------------------------------------------------------------------------------------
class SequenceState(NamedTuple):
    """A sequence selector's state. current: [] int32 the terrain trained now. available: [N] bool terrains still
    on offer. terrain_evals: [] int32 evaluations spent on ``current``. terrain_best: [] float32 its best so far.
    obs_index: [M] int32 bank index of each GP observation (-1 = empty slot; ``map`` reads them, the others record
    the finished terrains there too). obs_y: [M] float32 observed fitness. obs_count: [] int32 terrains finished."""

    current: jax.Array
    available: jax.Array
    terrain_evals: jax.Array
    terrain_best: jax.Array
    obs_index: jax.Array
    obs_y: jax.Array
    obs_count: jax.Array


def sequence_selector(config) -> Selector:
    """``map``, ``roughness`` or ``random`` (``config.selector``): one terrain at a time, each finished at the
    threshold or after ``max_evals`` evaluations; the run ends when none is left (see :mod:`.config`)."""
    kind = config.selector

    def initial(bank, key):
        n = bank.fitness.shape[0]
        if kind == "roughness":
            rank, member = roughness_sequence(bank, config.roughness_stride)
            return member, -rank.astype(jnp.float32)
        if kind == "random":
            return jnp.ones(n, bool), jax.random.uniform(key, (n,))
        return jnp.ones(n, bool), gp.ucb(bank.fitness, jnp.full((n,), config.sigma_f, jnp.float32), config.kappa)

    def init(key, bank):
        n = bank.fitness.shape[0]
        m = config.observation_slots(n)
        available, score = initial(bank, key)
        first = select(score, available, terrain_hardness(bank, config.distance_origin))
        zi = jnp.zeros((), jnp.int32)
        return SequenceState(current=first, available=available, terrain_evals=zi,
                             terrain_best=jnp.full((), -jnp.inf, jnp.float32), obs_index=jnp.full((m,), -1, jnp.int32),
                             obs_y=jnp.zeros((m,), jnp.float32), obs_count=zi)

    def assign(s):
        return Assignment(terrains=s.current[None], env_slot=None, evaluated=jnp.zeros((), jnp.int32))

    def next_terrain(s, bank, key, trained, finished, obs_index, obs_y, hardness):
        n = bank.fitness.shape[0]
        used = jnp.arange(n) == trained
        if kind == "map":
            mean, var = _posterior(bank, obs_index, obs_y, config)
            remove = removal_mask(mean, trained, hardness, config.removal_margin, config.removal_ties)
            score = gp.ucb(mean, var, config.kappa)
        elif kind == "roughness":
            remove, score = used, -roughness_sequence(bank, config.roughness_stride)[0].astype(jnp.float32)
        else:
            remove, score = used, jax.random.uniform(key, (n,))
        available = jnp.where(finished, s.available & ~remove, s.available)
        return available, select(score, available, hardness)

    def update(s, key, bank, outcome):
        hardness = terrain_hardness(bank, config.distance_origin)
        t, fitness = s.current, outcome.fitness
        evals = s.terrain_evals + 1
        best = jnp.maximum(s.terrain_best, fitness)
        finished = (fitness >= config.threshold * config.max_fitness) | (evals >= config.max_evals)
        slot = jnp.where(finished, s.obs_count, s.obs_index.shape[0])  # out of range -> dropped
        y = fitness if config.gp_evaluation == "final" else best
        obs_index = s.obs_index.at[slot].set(t, mode="drop")
        obs_y = s.obs_y.at[slot].set(y, mode="drop")
        available, nxt = next_terrain(s, bank, key, t, finished, obs_index, obs_y, hardness)
        switch = finished & jnp.any(available)
        new = SequenceState(current=jnp.where(switch, nxt, t), available=available,
                            terrain_evals=jnp.where(finished, 0, evals),
                            terrain_best=jnp.where(finished, -jnp.inf, best), obs_index=obs_index, obs_y=obs_y,
                            obs_count=s.obs_count + finished.astype(jnp.int32))
        return new, Decision(finished=finished, restart=switch, exhausted=finished & ~jnp.any(available))

    return Selector(kind, 1, init, assign, update, lambda s: {"terrains_finished": s.obs_count})


# ----------------------------------------------------------------------------------------------------------------
# Per-env selectors: domain randomisation, terrain levels
# ----------------------------------------------------------------------------------------------------------------
class DRState(NamedTuple):
    """``dr``'s state. terrains: [K] int32 this chunk's terrains (uniform draws from the bank, with replacement).
    draws: [] int32 chunks drawn."""

    terrains: jax.Array
    draws: jax.Array


def _round_robin(num_envs: int, slots: int) -> jax.Array:
    return jnp.arange(num_envs, dtype=jnp.int32) % slots


def dr_selector(config) -> Selector:
    """Domain randomisation: every chunk ``config.terrains_per_chunk`` terrains drawn uniformly from the bank, env e on terrain
    ``e % slots``, the envs restarted on them; evaluated on the first. No terrain is ever used up: the trial runs to
    ``max_epochs``."""
    k, e = int(config.terrains_per_chunk), int(config.ppo.num_envs)

    def draw(key, bank):
        return jax.random.randint(key, (k,), 0, bank.fitness.shape[0], dtype=jnp.int32)

    def init(key, bank):
        return DRState(terrains=draw(key, bank), draws=jnp.ones((), jnp.int32))

    def assign(s):
        return Assignment(terrains=s.terrains, env_slot=_round_robin(e, k), evaluated=jnp.zeros((), jnp.int32))

    def update(s, key, bank, outcome):
        reached = outcome.fitness >= config.threshold * config.max_fitness
        new = DRState(terrains=draw(key, bank), draws=s.draws + 1)
        return new, Decision(finished=reached, restart=jnp.ones((), bool), exhausted=jnp.zeros((), bool))

    return Selector("dr", k, init, assign, update, lambda s: {"terrains_drawn": s.draws * k})


class LevelsState(NamedTuple):
    """``levels``' state. level: [E] int32 each env's level (0 = easiest). terrains: [L] int32 this chunk's terrain
    of each level (drawn from its band). moves: [] int32 level changes so far (up or down, over all envs)."""

    level: jax.Array
    terrains: jax.Array
    moves: jax.Array


def level_bands(hardness: jax.Array, levels: int) -> tuple[jax.Array, jax.Array]:
    """``(order [N] int32, start [L + 1] int32)``: the terrains sorted by ``hardness`` (stable: ties by index) and
    band l = ``order[start[l]:start[l + 1]]``, L bands of equal size (``floor(l N / L)``; every band has at least
    one terrain when N >= L, else bands repeat terrains: band l = ``order[floor(l N / L)]``)."""
    n = hardness.shape[0]
    order = jnp.argsort(hardness, stable=True).astype(jnp.int32)
    start = (jnp.arange(levels + 1, dtype=jnp.int32) * n) // levels
    return order, start


def _draw_levels(key, bank, config) -> jax.Array:
    """``[L]`` int32: one terrain of each level's band, uniform within the band."""
    levels = int(config.levels)
    order, start = level_bands(terrain_hardness(bank, config.distance_origin), levels)
    lo, hi = start[:-1], jnp.maximum(start[1:], start[:-1] + 1)
    pos = lo + jnp.floor(jax.random.uniform(key, (levels,)) * (hi - lo)).astype(jnp.int32)
    return order[jnp.minimum(pos, order.shape[0] - 1)]


def levels_rule(level, progress, key, levels: int, promote: float, demote: float) -> jax.Array:
    """legged_gym's ``_update_terrain_curriculum`` over ``level`` [E] int32 with ``progress`` [E] float32: up one
    where ``progress >= promote``, down one where ``progress < demote`` (not both: up wins), clipped at 0, and an env
    moved past the top (``level >= levels``) to ``randint(key, 0, levels)``."""
    up = progress >= promote
    down = ~up & (progress < demote)
    moved = level + up.astype(jnp.int32) - down.astype(jnp.int32)
    top = jax.random.randint(key, level.shape, 0, levels, dtype=jnp.int32)
    return jnp.where(moved >= levels, top, jnp.maximum(moved, 0))


def levels_selector(config) -> Selector:
    """legged_gym's terrain levels over the bank's hardness bands (see the module docstring)."""
    levels, e = int(config.levels), int(config.ppo.num_envs)
    promote = float(config.threshold * config.max_fitness if config.levels_promote is None else config.levels_promote)
    demote = float(config.levels_demote)

    def init(key, bank):
        level_key, draw_key = jax.random.split(key)
        top = levels // 2 if config.levels_init is None else int(config.levels_init)
        level = jax.random.randint(level_key, (e,), 0, top + 1, dtype=jnp.int32)
        return LevelsState(level=level, terrains=_draw_levels(draw_key, bank, config), moves=jnp.zeros((), jnp.int32))

    def assign(s):
        return Assignment(terrains=s.terrains, env_slot=s.level, evaluated=jnp.max(s.level))

    def update(s, key, bank, outcome):
        rule_key, draw_key = jax.random.split(key)
        level = levels_rule(s.level, outcome.progress, rule_key, levels, promote, demote)
        reached = outcome.fitness >= config.threshold * config.max_fitness
        new = LevelsState(level=level, terrains=_draw_levels(draw_key, bank, config),
                          moves=s.moves + jnp.sum(level != s.level).astype(jnp.int32))
        return new, Decision(finished=reached, restart=jnp.ones((), bool), exhausted=jnp.zeros((), bool))

    def summary(s):
        return {"mean_level": jnp.mean(s.level.astype(jnp.float32)), "max_level": jnp.max(s.level),
                "level_moves": s.moves}

    return Selector("levels", levels, init, assign, update, summary, progress=True)


# ----------------------------------------------------------------------------------------------------------------
# Prioritised level replay over the bank's terrains
# ----------------------------------------------------------------------------------------------------------------
class PLRState(NamedTuple):
    """``plr``'s state: JaxUED's level buffer (``LevelSampler``'s ``Sampler``) over bank terrains, and the chunk's
    assignment. levels: [C] int32 bank index of each buffer entry (-1 empty). scores: [C] float32 (-inf empty).
    timestamps: [C] int32 the episode count when the entry was last sampled or inserted. size: [] int32 entries.
    episode_count: [] int32. terrains: [K] int32 this chunk's terrains. entry: [K] int32 their buffer entries
    (replay), -1 for new terrains. replay: [] bool this chunk replays. replays: [] int32 replay chunks so far."""

    levels: jax.Array
    scores: jax.Array
    timestamps: jax.Array
    size: jax.Array
    episode_count: jax.Array
    terrains: jax.Array
    entry: jax.Array
    replay: jax.Array
    replays: jax.Array


def plr_weights(s: PLRState, temperature: float, staleness_coeff: float) -> jax.Array:
    """``[C]`` replay distribution of a buffer: ``(1 - staleness_coeff) x`` rank prioritisation (``(1 / rank) **
    (1 / temperature)``, normalised; rank 1 = highest score) ``+ staleness_coeff x`` staleness (``episode_count -
    timestamps``, normalised; uniform over the entries while all are 0), both over the filled entries only
    (JaxUED ``LevelSampler.level_weights`` with ``prioritization="rank"``)."""
    c = s.scores.shape[0]
    mask = jnp.arange(c) < s.size
    order = jnp.argsort(-jnp.where(mask, s.scores, -jnp.inf))
    ranks = jnp.zeros(c, jnp.int32).at[order].set(jnp.arange(c, dtype=jnp.int32) + 1)
    w_s = jnp.where(mask, 1.0 / ranks, 0.0) ** (1.0 / temperature)
    w_s = w_s / jnp.maximum(w_s.sum(), 1e-30)
    stale = jnp.where(mask, s.episode_count - s.timestamps, 0).astype(jnp.float32)
    w_c = jnp.where(stale.sum() > 0, stale / jnp.maximum(stale.sum(), 1e-30),
                    mask / jnp.maximum(s.size, 1).astype(jnp.float32))
    return (1.0 - staleness_coeff) * w_s + staleness_coeff * w_c


def _same_level(levels, level) -> jax.Array:
    """``[C]`` bool: entry c of ``levels`` (a pytree, leading axis C: bank indices [C] or genomes) equals ``level``
    (the same pytree without the C axis) in every leaf."""
    def eq(a, b):
        return jnp.all((a == b).reshape(a.shape[0], -1), axis=1)
    return functools.reduce(jnp.logical_and, jax.tree.leaves(jax.tree.map(eq, levels, level)))


def plr_insert(s, level, score, temperature: float, staleness_coeff: float):
    """One level into the buffer with its score (JaxUED ``insert`` with ``duplicate_check``): a level already there
    gets the new score and timestamp; else it fills the next empty entry, or, when full, replaces the entry of
    lowest replay weight if its score is lower; the episode count grows by one either way. ``s``: a
    :class:`PLRState` (levels = bank indices [C]) or :class:`LevelBuffer` (levels = a genome pytree [C, ...]);
    ``level`` one level of the same kind."""
    c = s.scores.shape[0]
    found = _same_level(s.levels, level) & (jnp.arange(c) < s.size)
    there = jnp.any(found)
    idx = jnp.where(there, jnp.argmax(found),
                    jnp.where(s.size < c, s.size, jnp.argmin(plr_weights(s, temperature, staleness_coeff))))
    write = there | (s.scores[idx] < score)
    count = s.episode_count + 1
    levels = jax.tree.map(lambda a, b: a.at[idx].set(jnp.where(write, b, a[idx])), s.levels, level)
    return s._replace(levels=levels,
                      scores=s.scores.at[idx].set(jnp.where(write, score, s.scores[idx])),
                      timestamps=s.timestamps.at[idx].set(jnp.where(write, count, s.timestamps[idx])),
                      size=jnp.where(write & ~there, jnp.minimum(s.size + 1, c), s.size), episode_count=count)


def plr_sample(s, key, num: int, temperature: float, staleness_coeff: float):
    """``(state, entries [num] int32)``: ``num`` replays drawn one after another from :func:`plr_weights`, each
    marking its entry as just seen (JaxUED ``sample_replay_levels``). ``s``: :class:`PLRState` or
    :class:`LevelBuffer`."""
    def one(s, k):
        idx = jax.random.choice(k, s.scores.shape[0], p=plr_weights(s, temperature, staleness_coeff))
        count = s.episode_count + 1
        return s._replace(timestamps=s.timestamps.at[idx].set(count), episode_count=count), idx.astype(jnp.int32)

    return jax.lax.scan(one, s, jax.random.split(key, num))


def learnability(progress, env_slot, slots: int, threshold: float) -> jax.Array:
    """``[K]`` score of each terrain of a chunk: ``p (1 - p)``, p the fraction of its envs whose furthest progress
    reached ``threshold`` (the learnability of SFL, Rutherford et al. 2024: highest for terrains walked sometimes)."""
    success = (progress >= threshold).astype(jnp.float32)
    count = jnp.zeros(slots, jnp.float32).at[env_slot].add(1.0)
    p = jnp.zeros(slots, jnp.float32).at[env_slot].add(success) / jnp.maximum(count, 1.0)
    return p * (1.0 - p)


def plr_selector(config) -> Selector:
    """Prioritised level replay over the bank's terrains (JaxUED's ``LevelSampler`` and its defaults; see the module
    docstring for where ours differ). Every chunk trains the envs on ``terrains_per_chunk`` terrains, env e on
    terrain ``e % K``: with probability ``plr_replay_prob`` (once the buffer is ``plr_min_fill`` full) K replays
    from the buffer, else K new terrains drawn uniformly from the bank; after the chunk each terrain's score
    (:func:`learnability` of its envs' progress) updates its replayed entry or is inserted (:func:`plr_insert`)."""
    k, e = int(config.terrains_per_chunk), int(config.ppo.num_envs)
    temperature, stale = float(config.plr_temperature), float(config.plr_staleness)
    threshold = float(config.threshold * config.max_fitness)

    def new(key, bank):
        return jax.random.randint(key, (k,), 0, bank.fitness.shape[0], dtype=jnp.int32)

    def init(key, bank):
        c = min(plr_buffer_capacity(config), int(bank.fitness.shape[0]))
        zi = jnp.zeros((), jnp.int32)
        return PLRState(levels=jnp.full((c,), -1, jnp.int32), scores=jnp.full((c,), -jnp.inf, jnp.float32),
                        timestamps=jnp.zeros((c,), jnp.int32), size=zi, episode_count=zi, terrains=new(key, bank),
                        entry=jnp.full((k,), -1, jnp.int32), replay=jnp.zeros((), bool), replays=zi)

    def assign(s):
        return Assignment(terrains=s.terrains, env_slot=_round_robin(e, k), evaluated=jnp.zeros((), jnp.int32))

    def update(s, key, bank, outcome):
        decide_key, sample_key, new_key = jax.random.split(key, 3)
        scores = learnability(outcome.progress, _round_robin(e, k), k, threshold)
        # replayed entries take their new scores; new terrains go in one by one
        replayed = s._replace(scores=s.scores.at[jnp.where(s.replay, s.entry, s.scores.shape[0])].set(
            scores, mode="drop"))
        inserted = jax.lax.fori_loop(0, k, lambda i, b: plr_insert(b, s.terrains[i], scores[i], temperature, stale),
                                     s)
        buf = _where_levels(s.replay, replayed, inserted)
        replay = ((buf.size / buf.levels.shape[0]) >= config.plr_min_fill) & (
            jax.random.uniform(decide_key) < config.plr_replay_prob)
        sampled, entry = plr_sample(buf, sample_key, k, temperature, stale)
        nxt = _where_levels(replay, sampled, buf)
        nxt = nxt._replace(terrains=jnp.where(replay, buf.levels[entry], new(new_key, bank)),
                           entry=jnp.where(replay, entry, -1), replay=replay,
                           replays=s.replays + replay.astype(jnp.int32))
        reached = outcome.fitness >= threshold
        return nxt, Decision(finished=reached, restart=jnp.ones((), bool), exhausted=jnp.zeros((), bool))

    def summary(s):
        filled = jnp.arange(s.scores.shape[0]) < s.size
        return {"buffer_size": s.size, "replay_chunks": s.replays,
                "buffer_mean_score": jnp.sum(jnp.where(filled, s.scores, 0.0)) / jnp.maximum(s.size, 1)}

    return Selector("plr", k, init, assign, update, summary, progress=True)


# ----------------------------------------------------------------------------------------------------------------
# ACCEL: PLR over generator genomes, replayed levels edited by the generator's mutate
# ----------------------------------------------------------------------------------------------------------------
ACCEL_NEW, ACCEL_REPLAY, ACCEL_EDIT = 0, 1, 2
"""``AccelState.mode``: this chunk trains on new levels (the generator's fresh samples), on replayed buffer levels,
or on edits (``mutate``) of the levels the previous chunk replayed."""


class LevelBuffer(NamedTuple):
    """A PLR level buffer whose levels are any pytree (JaxUED's ``Sampler``). levels: genomes, every leaf with a
    leading axis C. scores: [C] float32 (-inf empty). timestamps: [C] int32. size: [] int32 entries filled.
    episode_count: [] int32. :func:`plr_weights`, :func:`plr_insert` and :func:`plr_sample` take it."""

    levels: Any
    scores: jax.Array
    timestamps: jax.Array
    size: jax.Array
    episode_count: jax.Array


class AccelState(NamedTuple):
    """``accel``'s state. buffer: :class:`LevelBuffer` of genomes. genomes: the chunk's K levels (leading axis K).
    terrain: [] int32 the bank terrain the policy is evaluated on (the paper's metric; not trained on). entry: [K]
    int32 the replayed levels' buffer entries (-1 for new and edited levels). mode: [] int32 ``ACCEL_NEW``,
    ``ACCEL_REPLAY`` or ``ACCEL_EDIT``. replays, edits: [] int32 chunks of each kind so far."""

    buffer: LevelBuffer
    genomes: Any
    terrain: jax.Array
    entry: jax.Array
    mode: jax.Array
    replays: jax.Array
    edits: jax.Array


def _take_levels(levels, index):
    return jax.tree.map(lambda a: a[index], levels)


def _where_levels(pred, a, b):
    return jax.tree.map(lambda x, y: jnp.where(pred, x, y), a, b)


def accel_generator(config, size: Optional[int] = None):
    """The :class:`jaxterrain.generators.Generator` whose genomes are ``accel``'s levels
    (``config.accel_generator``), rendering ``size`` x ``size`` maps (None: its default, 256);
    ``ValueError`` naming the field when it is unset or unknown."""
    name = config.accel_generator
    if name is None or name not in generators.names():
        raise ValueError(f"CurriculumConfig.accel_generator must be one of {', '.join(generators.names())} (the "
                         f"generator whose genomes are accel's levels), got {name!r}")
    return generators.get(name) if size is None else generators.get(name, size=int(size))


def accel_selector(config) -> Selector:
    """ACCEL (Parker-Holder et al. 2022; JaxUED's ``accel`` branch): PLR whose levels are genomes of
    ``config.accel_generator``. A chunk trains on K = ``terrains_per_chunk`` levels, rendered in the loop (env e on
    level ``e % K``): new levels (``generator.sample``), or with probability ``plr_replay_prob`` (once the buffer is
    ``plr_min_fill`` full) K replays from the buffer; the chunk after a replay trains on the replayed levels each
    edited by ``accel_edits`` applications of the generator's ``mutate``. After a chunk each level's
    :func:`learnability` updates its replayed entry, or the level (new or edited) is inserted with it
    (:func:`plr_insert`). The policy is evaluated on one more slot, a bank terrain drawn uniformly each chunk, not
    trained on: the paper's "hardest terrain traversed" on the archive, as ``dr`` records it. Levels are rendered
    at ``TerrainScale()``'s height (1 m per unit), the scale ``qd.bank.from_archive`` renders the archive at."""
    k, e = int(config.terrains_per_chunk), int(config.ppo.num_envs)
    temperature, stale = float(config.plr_temperature), float(config.plr_staleness)
    threshold = float(config.threshold * config.max_fitness)
    edits, height = int(config.accel_edits), float(TerrainScale().height)

    def fresh(key):
        return accel_generator(config).sample(key, k)

    def edit(key, genomes):
        mutate = accel_generator(config).mutate
        return jax.lax.fori_loop(0, edits, lambda i, g: mutate(jax.random.fold_in(key, i), g), genomes)

    def draw(key, bank):
        return jax.random.randint(key, (), 0, bank.fitness.shape[0], dtype=jnp.int32)

    def init(key, bank):
        new_key, eval_key = jax.random.split(key)
        genomes = fresh(new_key)
        c = plr_buffer_capacity(config)
        buffer = LevelBuffer(levels=jax.tree.map(lambda a: jnp.zeros((c,) + a.shape[1:], a.dtype), genomes),
                             scores=jnp.full((c,), -jnp.inf, jnp.float32), timestamps=jnp.zeros((c,), jnp.int32),
                             size=jnp.zeros((), jnp.int32), episode_count=jnp.zeros((), jnp.int32))
        zi = jnp.zeros((), jnp.int32)
        return AccelState(buffer=buffer, genomes=genomes, terrain=draw(eval_key, bank),
                          entry=jnp.full((k,), -1, jnp.int32), mode=jnp.full((), ACCEL_NEW, jnp.int32), replays=zi,
                          edits=zi)

    def assign(s):
        terrains = jnp.concatenate([jnp.full((k,), -1, jnp.int32), s.terrain[None]])
        return Assignment(terrains=terrains, env_slot=_round_robin(e, k), evaluated=jnp.full((), k, jnp.int32))

    def maps(s, bank):
        h, w = bank.heightmaps.shape[1:]
        if h != w:
            raise ValueError(f"accel renders square maps; the bank's are {h} x {w}")
        gen = accel_generator(config, None if h == 256 else h)
        rendered = jax.vmap(gen.render_one)(s.genomes).astype(jnp.float32) * height
        return jnp.concatenate([rendered, bank.heightmaps[s.terrain][None]])

    def update(s, key, bank, outcome):
        decide_key, sample_key, new_key, edit_key, eval_key = jax.random.split(key, 5)
        scores = learnability(outcome.progress, _round_robin(e, k), k, threshold)
        b = s.buffer
        replayed = b._replace(scores=b.scores.at[jnp.where(s.mode == ACCEL_REPLAY, s.entry, b.scores.shape[0])].set(
            scores, mode="drop"))
        inserted = jax.lax.fori_loop(
            0, k, lambda i, buf: plr_insert(buf, _take_levels(s.genomes, i), scores[i], temperature, stale), b)
        buf = _where_levels(s.mode == ACCEL_REPLAY, replayed, inserted)
        edit_next = s.mode == ACCEL_REPLAY  # the chunk after a replay trains on its levels, edited
        replay = ~edit_next & ((buf.size / buf.scores.shape[0]) >= config.plr_min_fill) & (
            jax.random.uniform(decide_key) < config.plr_replay_prob)
        sampled, entry = plr_sample(buf, sample_key, k, temperature, stale)
        genomes = _where_levels(edit_next, edit(edit_key, s.genomes),
                                _where_levels(replay, _take_levels(buf.levels, entry), fresh(new_key)))
        mode = jnp.where(edit_next, ACCEL_EDIT, jnp.where(replay, ACCEL_REPLAY, ACCEL_NEW)).astype(jnp.int32)
        new = AccelState(buffer=_where_levels(replay, sampled, buf), genomes=genomes, terrain=draw(eval_key, bank),
                         entry=jnp.where(replay, entry, -1), mode=mode,
                         replays=s.replays + replay.astype(jnp.int32), edits=s.edits + edit_next.astype(jnp.int32))
        reached = outcome.fitness >= threshold
        return new, Decision(finished=reached, restart=jnp.ones((), bool), exhausted=jnp.zeros((), bool))

    def summary(s):
        b = s.buffer
        filled = jnp.arange(b.scores.shape[0]) < b.size
        return {"buffer_size": b.size, "replay_chunks": s.replays, "edit_chunks": s.edits,
                "buffer_mean_score": jnp.sum(jnp.where(filled, b.scores, 0.0)) / jnp.maximum(b.size, 1)}

    return Selector("accel", k + 1, init, assign, update, summary, progress=True, maps=maps)


# ----------------------------------------------------------------------------------------------------------------
# Registry
# ----------------------------------------------------------------------------------------------------------------
_REGISTRY: dict[str, Callable[[Any], Selector]] = {
    "map": sequence_selector, "roughness": sequence_selector, "random": sequence_selector,
    "dr": dr_selector, "levels": levels_selector, "plr": plr_selector, "accel": accel_selector,
}


def register_selector(name: str, factory: Callable[[Any], Selector]) -> None:
    """Make ``CurriculumConfig(selector=name)`` (and ``learn --curriculum name``) build ``factory(config)``."""
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"selector name must be an identifier, got {name!r}")
    if not callable(factory):
        raise ValueError(f"selector {name!r}: the factory must be callable (config -> Selector)")
    _REGISTRY[name] = factory


def selector_names() -> tuple[str, ...]:
    """The registered selector names (the built-in ones first)."""
    return tuple(_REGISTRY)


def _imported(spec: str) -> Callable[[Any], Selector]:
    """``module:object`` -> the object (a factory ``config -> Selector``, or a :class:`Selector`); ``ValueError``
    naming ``spec`` when the module does not import (whatever it raises: it is the user's code) or lacks the
    object, or the object is neither callable nor a Selector."""
    module, _, attr = spec.partition(":")
    try:
        obj = getattr(importlib.import_module(module), attr)
    except Exception as err:  # noqa: BLE001 - any failure of the user's module is reported in one line
        text = str(err).splitlines()[0] if str(err) else ""
        raise ValueError(f"CurriculumConfig.selector {spec!r}: cannot import it ({type(err).__name__}: {text})") \
            from None
    if not isinstance(obj, Selector) and not callable(obj):
        raise ValueError(f"CurriculumConfig.selector {spec!r}: {type(obj).__name__} is neither a Selector nor a "
                         f"factory (config -> Selector)")
    return (lambda config: obj) if isinstance(obj, Selector) else obj


def resolve_factory(name: str) -> Callable[[Any], Selector]:
    """The factory of a selector name (registered, or ``module:object``); ``ValueError`` naming the choices."""
    if isinstance(name, str) and name in _REGISTRY:
        return _REGISTRY[name]
    if isinstance(name, str) and ":" in name:
        return _imported(name)
    raise ValueError(f"CurriculumConfig.selector must be one of {', '.join(_REGISTRY)} or module:object, "
                     f"got {name!r}")


def get_selector(config) -> Selector:
    """The :class:`Selector` of ``config.selector`` built for ``config``."""
    selector = resolve_factory(config.selector)(config)
    if not isinstance(selector, Selector):
        raise ValueError(f"CurriculumConfig.selector {config.selector!r}: its factory returned "
                         f"{type(selector).__name__}, not a jaxterrain.curriculum.Selector")
    return selector

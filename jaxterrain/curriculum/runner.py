"""The Experiment 2 treatment runner: a typed run (:class:`~jaxterrain.curriculum.run_config.LearnConfig`) -> a
validated curriculum, its compiled trial blocks, a run driven chunk by chunk with checkpoints and time limits, and
its outputs (:mod:`jaxterrain.curriculum.outputs`).

    run, config, arch, policy, env = runner.validate(run)    # BadInput naming LearnConfig.<field>, nothing compiled
    summary = runner.run_treatment(run, folder, time_limit_s=540)   # None: stopped by the time limit (checkpointed)
    summary = runner.report_treatment(run, folder)       # the outputs of the last checkpoint, without training
    paths = runner.export_treatment(run, folder)         # its walkers, folder/policies/trial_K/, without training

A run's ``config.json`` is its serialised form (``run_config.to_flat`` / ``from_flat``, which also reads the
``config.json`` of every earlier version); ``run_config.PRESETS`` are the ``learn`` command's presets.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import re
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.curriculum import walker as W
from jaxterrain.curriculum.config import RECIPES, CurriculumConfig, validate_config
from jaxterrain.curriculum.checkpoints import ENV_STATES, restore_states, strip_envs
from jaxterrain.curriculum.core import CHECKPOINT_COMPAT, init_trials
from jaxterrain.curriculum.population import mesh_rows, run_live, run_trials
from jaxterrain.curriculum.outputs import PARTIAL, export_policies, write_outputs
from jaxterrain.curriculum.progress import ChunkMetrics, ChunkProgress, chunk_metrics
from jaxterrain.curriculum.run_config import LearnConfig, to_flat
from jaxterrain.curriculum.selectors import get_selector, selector_params
from jaxterrain.qd.archive_io import load as load_archive_file
from jaxterrain.runtime import driver, estimates, sharding, xla
from jaxterrain.curriculum.own_terrains import OwnTerrains, bank_of, check_terrains, rank_terrains
from jaxterrain.terrain import TerrainScale
from jaxterrain.difficulty import policy_observation, policy_robot, robot_base_policy
from jaxterrain.walker import carry_rows, robots, tiles
from jaxterrain.walker.layout import resolve_backend

__all__ = ["BadInput", "ChunkMetrics", "ChunkProgress", "PARTIAL", "FAST_COMPILE", "PROGRAMS", "curriculum_config",
           "resolve", "start_policy", "check_scan_lr", "load_archive", "archive_digest", "check_resumable",
           "physics_of", "selector_slots", "walker_layout", "validate", "make_env", "strip_envs", "ENV_STATES",
           "compiled", "make_block", "chunk_metrics", "inputs", "setup", "run_treatment", "report_run", "restored",
           "report_treatment", "export_treatment"]

class BadInput(ValueError):
    """A bad parameter or file, reported as one line before anything is compiled."""


# ----------------------------------------------------------------------------------------------------------------
# Validation (before anything is compiled)
# ----------------------------------------------------------------------------------------------------------------
def curriculum_config(run: LearnConfig) -> CurriculumConfig:
    """The validated :class:`jaxterrain.curriculum.CurriculumConfig` of a (resolved: :func:`resolve`) run;
    :class:`BadInput` naming the field as ``LearnConfig.<path>`` (``LearnConfig.curriculum.params.capacity``)."""
    if run.recipe is not None and run.recipe not in RECIPES:
        raise BadInput(f"LearnConfig.recipe must be one of {', '.join(RECIPES)}, got {run.recipe!r}")
    try:
        return validate_config(run.curriculum)
    except (ValueError, TypeError) as err:
        raise BadInput(re.sub(r"\bCurriculumConfig\.", "LearnConfig.curriculum.", str(err))) from None


def resolve(run: LearnConfig, arch) -> LearnConfig:
    """``run`` with what it takes from the archive: the evaluation protocol's ``attempts`` / ``best`` / ``headings``
    that ``run.protocol`` leaves None taken from the archive's config (the curriculum then evaluates under the
    protocol its prior, the archive's fitness, was measured under), written into ``run.curriculum``; and for
    ``accel`` without a generator, the archive's generator (:class:`BadInput` when the archive holds several)."""
    fields = {k: getattr(arch.config, k, 1 if k == "headings" else None) for k in ("attempts", "best", "headings")}
    given = run.protocol._asdict()
    curriculum = run.curriculum._replace(**{k: int(fields[k]) if given[k] is None else given[k] for k in fields})
    params = selector_params(curriculum) if curriculum.selector == "accel" else None
    if params is not None and params.generator is None:
        source = np.asarray(arch.source)
        names = sorted({arch.generator_names[int(i)] for i in source[source >= 0]})
        if len(names) != 1:
            raise BadInput(f"LearnConfig.curriculum.params.generator: the archive holds {', '.join(names)}; name the "
                           f"generator whose genomes are accel's levels")
        curriculum = curriculum._replace(params=params._replace(generator=names[0]))
    return run._replace(curriculum=curriculum)


def load_archive(path, descriptors):
    """``qd.load`` with one-line errors naming the file (``LearnConfig.archive PATH: ...``): unreadable, other
    descriptors, < 2 filled cells."""
    try:
        arch = load_archive_file(path)
    except (OSError, ValueError) as err:
        raise BadInput(f"LearnConfig.archive {path}: {str(err).splitlines()[0]}") from None
    if tuple(arch.config.descriptors) != tuple(descriptors):
        raise BadInput(f"LearnConfig.archive {path}: descriptors {tuple(arch.config.descriptors)}, the curriculum "
                       f"expects {tuple(descriptors)}")
    filled = int(arch.filled.sum())
    if filled < 2:
        raise BadInput(f"LearnConfig.archive {path}: {filled} filled cell(s); a curriculum needs at least 2")
    return arch


def archive_digest(arch) -> str:
    """sha256 (hex) of what a treatment reads from an archive: its generator names, elite sources, fitness (the GP's
    prior), descriptors, genomes and stored heightmaps. Stored in every checkpoint (``meta["archive_sha256"]``) so
    that a resumed treatment can tell that the archive under its path has changed (:func:`check_resumable`)."""
    h = hashlib.sha256(json.dumps(list(arch.generator_names)).encode())
    arrays = [arch.source, arch.fitness, arch.descriptors, *jax.tree.leaves(arch.genomes)]
    for a in arrays + ([] if arch.heightmaps is None else [arch.heightmaps]):
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def check_resumable(folder: Path, run: LearnConfig, arch, physics: bool = True) -> str:
    """``arch``'s :func:`archive_digest`, after checking it against ``folder``'s checkpoint: :class:`BadInput` when
    that was written for another archive than the one now at ``run.archive`` (its terrain indices, GP observations
    and removed cells would refer to other terrains), or on other physics than ``run.walker.backend`` resolves to
    here (``auto`` on a machine without MuJoCo Warp would silently continue a Warp run on MJX: one run, two
    simulators; ``physics=False``, for a report that only reads the checkpoint, skips this). Reads only the
    checkpoint's header; checkpoints written before the digest (or the backend) was recorded are not checked for
    it."""
    digest = arch.folder.digest if isinstance(arch, OwnTerrains) else archive_digest(arch)
    try:
        meta = driver.read_meta(folder)
    except ValueError as err:
        raise BadInput(str(err)) from None
    stored = (meta or {}).get("archive_sha256")
    if stored is not None and stored != digest and isinstance(arch, OwnTerrains):
        raise BadInput(f"LearnConfig.terrains {run.terrains}: its files are not the ones {folder} was checkpointed "
                       f"with (sha256 {stored[:12]}... then, {digest[:12]}... now); put those files back or start a "
                       f"new run")
    if stored is not None and stored != digest:
        raise BadInput(f"LearnConfig.archive {run.archive}: it is not the archive {folder} was checkpointed with "
                       f"(sha256 {stored[:12]}... then, {digest[:12]}... now); put that file back or start a new run")
    then, now = (meta or {}).get("backend"), physics_of(run)
    if physics and then is not None and then != now:
        raise BadInput(f"LearnConfig.walker.backend {run.walker.backend}: it runs the walker on {now} here, but "
                       f"{folder} was checkpointed on {then}; continue it where {then} runs (warp: a GPU with MuJoCo "
                       f"Warp installed) or start a new run")
    return digest


def physics_of(run: LearnConfig) -> str:
    """The walker backend a run runs on here, ``jax`` or ``warp`` (:func:`resolve_backend` of
    ``run.walker.backend``)."""
    return resolve_backend(run.walker.backend)


def selector_slots(run: LearnConfig) -> int:
    """``Selector.slots`` of a run's curriculum (1 for map / roughness / random): a trial's terrains per chunk.
    :class:`BadInput` for an unknown curriculum."""
    try:
        return int(get_selector(run.curriculum).slots)
    except (ValueError, TypeError) as err:
        raise BadInput(f"LearnConfig.curriculum.selector: {err}") from None


def walker_layout(run: LearnConfig) -> dict:
    """The walker's ``backend`` / ``tiles`` / ``worlds`` of a (resolved) run: warp walks on one tile per trial (per
    heading, per selector slot) with contact buffers for every env stepped at once (``trials x max(num_envs,
    attempts)``: the PPO envs, then the evaluation walks; with ``overlap`` ``trials x (num_envs + attempts)``,
    stepped together); jax on tiles too with ``overlap``. :class:`BadInput` for an unknown backend, or warp where
    MuJoCo Warp does not import."""
    backend = physics_of(run)
    slots = selector_slots(run)  # a trial's terrains per chunk: one tile each
    c = run.curriculum
    trials, headings = int(run.trials), int(c.headings or 1) * slots
    overlap = bool(c.overlap)  # the evaluation walks ride along PPO's envs on tiles
    if backend == "jax":
        return dict(tiles=trials * headings) if overlap else {}
    if backend != "warp":
        raise BadInput(f"LearnConfig.walker.backend must be jax or warp, got {backend!r}")

    ok, why = tiles.warp_available()
    if not ok:
        raise BadInput(f"LearnConfig.walker.backend warp: {why}")
    envs, attempts = int(c.ppo.num_envs), int(c.attempts)
    return dict(backend="warp", tiles=trials * headings,
                worlds=trials * (envs + attempts if overlap else max(envs, attempts)))


def start_policy(run: LearnConfig):
    """The policy a run starts from: ``walker.policy``, else the shipped base policy of ``walker.robot`` (default
    the humanoid's; ``walker.observation`` perceptive: its perceptive twin). :class:`BadInput` for an unknown robot,
    a robot without a shipped base policy, a policy that does not load, or a policy of another robot than
    ``walker.robot`` or of another observation set than ``walker.observation``."""
    robot, path = run.walker.robot or "humanoid", run.walker.policy
    observation = run.walker.observation or "blind"
    try:
        robots.get(robot)
    except ValueError as err:
        raise BadInput(f"LearnConfig.walker.robot: {err}") from None
    if path is None and (robot != "humanoid" or observation != "blind"):
        try:
            return robot_base_policy(robot, observation)
        except ValueError as err:
            field = "observation" if observation != "blind" else "robot"
            raise BadInput(f"LearnConfig.walker.{field}: {err}") from None
    try:
        policy = W.load_policy(path)
    except ValueError as err:
        raise BadInput(f"LearnConfig.walker.policy: {err}") from None
    if run.walker.robot is not None and policy_robot(policy) != robot:
        raise BadInput(f"LearnConfig.walker.policy {path}: it walks the {policy_robot(policy)}, not "
                       f"LearnConfig.walker.robot {robot}")
    seen = policy_observation(policy)["observation"]
    if run.walker.observation is not None and seen != observation:
        raise BadInput(f"LearnConfig.walker.policy {path}: it observes {seen}, not LearnConfig.walker.observation "
                       f"{observation}")
    return policy


def check_scan_lr(run: LearnConfig, policy) -> None:
    """:class:`BadInput` when ``curriculum.ppo.scan_lr_scale`` is not 1 and the start ``policy`` (whose observation
    set the walker takes) sees no height scan: the scale would be accepted and ignored."""
    if (scale := run.curriculum.ppo.scan_lr_scale) != 1.0 and policy_observation(policy)["observation"] == "blind":
        raise BadInput(f"LearnConfig.curriculum.ppo.scan_lr_scale {scale!r} must be 1.0 for a blind walker (it scales "
                       f"Adam's steps on weights reading a height scan: LearnConfig.walker.observation perceptive)")


def _check_top(run: LearnConfig) -> None:
    """The run's own integers: ``trials``, ``budget.chunks_per_call``, ``walker.episode_length`` (>= 1)."""
    if not isinstance(run, LearnConfig):
        raise BadInput(f"a run is a jaxterrain.curriculum.run_config.LearnConfig, got {type(run).__name__}")
    for path, value in (("trials", run.trials), ("budget.chunks_per_call", run.budget.chunks_per_call),
                        ("walker.episode_length", run.walker.episode_length)):
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise BadInput(f"LearnConfig.{path} must be an integer >= 1, got {value!r}")


def validate(run: LearnConfig):
    """``(resolved run, CurriculumConfig, archive, policy, env)`` or :class:`BadInput` naming the field
    (``LearnConfig.<path>``) or file. The one check of a run: the archive (or the folder of ``terrains``:
    :func:`check_terrains`, an unranked :class:`OwnTerrains` as ``arch``), the curriculum (its selector's params
    by the selector's own rule), the policy and the walker env, built here."""
    _check_top(run)
    try:
        own = check_terrains(run)
    except ValueError as err:
        raise BadInput(str(err)) from None
    arch = own if own is not None else load_archive(run.archive, run.descriptors)
    run = resolve(run, arch)
    config = curriculum_config(run)
    policy = start_policy(run)
    check_scan_lr(run, policy)
    archive_robot = getattr(arch.config, "robot", None) or "humanoid"
    if own is None and archive_robot != policy_robot(policy):
        raise BadInput(f"LearnConfig.archive {run.archive}: its fitness is the {archive_robot}'s, but the policy walks "
                       f"the {policy_robot(policy)} (evolve an archive with --robot {policy_robot(policy)})")
    env = make_env(run, arch, policy)
    return run, config, arch, policy, env


def make_env(run: LearnConfig, arch, policy):
    """The walker env of a (resolved) run on ``arch``'s maps, checked against ``policy``: the one place a
    treatment's env is built. :class:`BadInput` when the policy does not fit it."""
    shape = (256, 256) if arch.heightmaps is None else tuple(arch.heightmaps.shape[1:])
    try:
        env = W.walker_env(policy, shape, TerrainScale(), run.walker.episode_length, **walker_layout(run),
                           healthy_reward=run.walker.healthy_reward, randomisation=run.walker.randomise,
                           spawn=run.walker.spawn)
    except ValueError as err:  # e.g. maps too small for the walker's start and goal margins
        where = f"LearnConfig.archive {run.archive}" if run.archive else f"LearnConfig.terrains {run.terrains}"
        raise BadInput(f"{where}: its {shape[0]} x {shape[1]} maps cannot hold the walker: {err}") from None
    try:
        W.check_policy(policy, env)
    except ValueError as err:
        raise BadInput(f"LearnConfig.walker.policy: {err}") from None
    return env


# ----------------------------------------------------------------------------------------------------------------
# The treatment
# ----------------------------------------------------------------------------------------------------------------
FAST_COMPILE = xla.FAST_CPU_COMPILE


def compiled(fn, fast: bool, *args):
    """``jax.jit(fn)`` compiled for ``args``; with ``fast`` (the CPU smoke preset) at XLA's lowest backend
    optimisation and with its classic elemental emitter instead of the fusion emitters, which compiles the walker's
    programs several times faster on a CPU (the options this jax's XLA knows: ``runtime.xla.known_options``)."""
    lowered = jax.jit(fn).lower(*args)
    return lowered.compile(xla.known_options(FAST_COMPILE) if fast and jax.default_backend() == "cpu" else None)


_LISTENERS: list = []  # the running treatment's progress function (compiled blocks call _chunk_done, shared by all)


def _chunk_done(chunk, hardest, done, history) -> None:
    """Host side of a block's per-chunk callback: hands ``(chunk [T], hardest [T], done [T], history)`` to the
    listeners of the treatment running now (none: nothing). Compiled programs are shared between treatments, so they
    call this one function and the listeners change."""
    for listen in list(_LISTENERS):
        listen(np.asarray(chunk), np.asarray(hardest), np.asarray(done), history)


def make_block(config, harness):
    """``(states, bank, n, rows=None) -> states`` (jit it): up to ``n`` chunks of every trial, the physics of
    ``rows`` only (``run_trials``: [R] trial indices holding every running trial, each on its own tile; None: all).
    The trials' env states ride in ``states`` from block to block (and into every checkpoint), so where the blocks
    are cut changes nothing: a run stopped after any chunk and resumed equals the uninterrupted run. Envs restart
    only where the curriculum says (``State.restart``: the start, a terrain switch)."""
    def block(states, bank, n, rows=None):
        return run_trials(states, bank, jnp.asarray(n, jnp.int32), rows, config=config, harness=harness,
                          on_chunk=_chunk_done)

    return block


PROGRAMS: dict = {}  # (config, ppo, walker, trials, bank shape, fast, mesh) -> (init, block, {rows: compiled block})


def inputs(run: LearnConfig, config, arch, policy, env):
    """What a treatment's programs start from: ``(bank, ppo, harness, start, keys, init)``: the archive's terrain
    bank, the fine-tuning PPOConfig, the walker harness, the starting policy state, the trials' keys [trials] and
    ``init(keys, bank, start)`` -> the initial trial states, their env states zeros due for a restart on the first
    terrains (pure: jit or ``eval_shape`` it). The env states are in the form a block carries
    (``walker.carry_rows``: MuJoCo Warp's buffers shared by every env empty, ``[trials, 0, ...]``), so a block
    returns them with the shapes it was compiled for, on either backend."""
    bank = bank_of(arch)
    ppo = W.fine_tuning_ppo(config, policy, env)
    harness = W.walker_harness(env, ppo, config)
    start = W.start_state(env, ppo, policy, bank.heightmaps.shape[1:])
    keys = jax.random.split(jax.random.fold_in(jax.random.key(int(run.seed)), 2), int(run.trials))

    def init(k, b, s):
        states = init_trials(k, b, s, config=config, harness=harness)  # restart: True (the first chunk resets)
        envs = carry_rows(jax.tree.map(jnp.zeros_like, s.env_state), states.done.shape[0])
        return states._replace(policy=states.policy._replace(env_state=envs))

    return bank, ppo, harness, start, keys, init


def setup(run: LearnConfig, config, arch, policy, env, mesh=None):
    """Bank, the block ``run(states, bank, n) -> states`` and the initial (stripped) trial states. ``run`` computes
    the running trials only when ``run.budget.compact`` (``curriculum.run_live``; default on), each on the tile of
    its own index as in a block of every trial, and compiles the block once per number of rows it meets (every
    trial's here, fewer at the first call that needs them); compiled programs are reused by later treatments with
    the same settings and bank shape (``experiments curriculum``). ``mesh``: the rows split over its devices
    (``population.mesh_rows``: padded, the states and bank whole on each device)."""
    bank, ppo, harness, start, keys, init_fn = inputs(run, config, arch, policy, env)
    fast = bool(run.budget.fast_compile)
    sig = (config, ppo, env.config, int(run.trials), tuple(bank.heightmaps.shape), fast, mesh)
    fresh = sig not in PROGRAMS  # a treatment of the same shape as an earlier one reuses its programs
    physics = physics_of(run)
    note = (estimates.compiling("curriculum-block", f"{int(run.trials)} trials, {physics} physics",
                                then=estimates.first_chunk_note(physics)) if fresh else contextlib.nullcontext())
    with note:  # what compiles and about how long it takes here, then how long it took
        if fresh:
            PROGRAMS[sig] = (compiled(init_fn, fast, keys, bank, start),
                             make_block(config, harness), {})
        init, block, blocks = PROGRAMS[sig]  # blocks: number of rows (None: all) -> the block compiled for it
        states = init(keys, bank, start)
        if mesh is not None:  # the rows split over the devices; inputs whole on the mesh (whence the init's)
            block = mesh_rows(block, mesh)
            bank, states = sharding.replicate((bank, states), mesh)
            place = functools.partial(sharding.replicate, mesh=mesh)
        else:
            place = lambda tree: tree  # noqa: E731

        def program(size):
            if size not in blocks:
                rows = None if size is None else jnp.zeros((size,), jnp.int32)
                blocks[size] = compiled(block, fast, states, bank, jnp.int32(1), rows)
            return blocks[size]

        def rows_block(s, b, n, rows=None):
            size = None if rows is None else int(rows.shape[0])
            return program(size)(*place((s, b)), jnp.int32(n), None if rows is None else place(rows))

        program(None)  # the block of every trial now: set-up includes its compile
    compact = bool(run.budget.compact)
    return bank, (functools.partial(run_live, rows_block) if compact else rows_block), states


def run_treatment(run: LearnConfig, folder: Path, time_limit_s: float | None = None, desc: str = "",
                  mesh=None, progress: bool | str = True) -> dict | None:
    """Run (or continue) one treatment in ``folder``; its summary dict when finished, None when the time limit
    stopped it (checkpointed; call again to continue). ``time_limit_s`` counts from this call, its set-up and
    compilation included. Validates ``run`` once (:func:`validate`): :class:`BadInput` naming the field before
    compiling anything. Its checkpoints record ``run`` as given (``to_flat``), before what it takes from the
    archive."""
    folder = Path(folder)
    if (folder / "summary.json").exists():
        return json.loads((folder / "summary.json").read_text())
    given = run
    run, config, arch, policy, env = validate(run)
    digest = check_resumable(folder, run, arch)
    t0 = time.perf_counter()
    if isinstance(arch, OwnTerrains):  # a folder's terrains, ranked (measured once for the difficulty order)
        arch = rank_terrains(run, arch, policy, folder)
    bank, block, states = setup(run, config, arch, policy, env, mesh)
    restored = restore_states(folder, states, {"trials": int(run.trials), "offset": 0}, bool(env.tiles))
    done, history, before = 0, None, 0.0  # before: wall seconds of the commands that ran it so far
    if restored is not None:
        states, done, history, saved = restored
        before = float(saved.get("wall_s", 0.0))
        print(f"resuming at chunk {done} of {config.max_chunks} ({before / 60:.1f} min of wall time so far)",
              flush=True)

    every = int(run.budget.policy_every or 0)  # snapshots of the walkers along the run
    ppo = W.fine_tuning_ppo(config, policy, env)

    one_device = mesh is None or mesh.size == 1  # several: each callback sees its device's rows only
    metrics_csv = ChunkMetrics(folder) if one_device else None

    def chunk_fn(s, a, b):
        if not bool(np.all(np.asarray(s.done))):
            if metrics_csv is not None:
                metrics_csv.begin(s, b)
            s = block(s, bank, b - a)
        if every and b // every > a // every:
            export_policies(folder, run, config, ppo, env, policy, bank, s, subdir=f"chunk_{b:05d}",
                            names=arch.generator_names)
        return s, chunk_metrics(s, a, b)

    unit = "rank" if isinstance(arch, OwnTerrains) else "cells"  # a folder's hardness is its terrains' rank
    _LISTENERS[:] = [ChunkProgress(desc or config.selector, config.max_chunks, done, unit=unit)] + (
        [metrics_csv] if metrics_csv is not None else [])
    try:
        states, done, _ = driver.run_chunks(
            chunk_fn, states, total=config.max_chunks, every=int(run.budget.chunks_per_call), start=done,
            history=history, run_dir=folder, key_metric="hardest", desc=desc or config.selector, progress=progress,
            time_limit_s=None if time_limit_s is None else max(time_limit_s - (time.perf_counter() - t0), 1e-3),
            unit="chunk", meta={"config": to_flat(given, "learn"), "archive_sha256": digest,
                                "backend": physics_of(run)},
            wall_s=before + time.perf_counter() - t0, fit_to_limit=True)  # the block's length is traced
    finally:
        _LISTENERS.clear()
    if done < config.max_chunks and not bool(np.all(np.asarray(states.done))):
        return None
    export_policies(folder, run, config, ppo, env, policy, bank, states, names=arch.generator_names)
    return write_outputs(folder, run, config, bank, states, seconds=before + time.perf_counter() - t0,
                         names=arch.generator_names)


def report_run(run: LearnConfig) -> LearnConfig:
    """``run`` as :func:`report_treatment` validates it: on the MJX-JAX backend, which every machine has."""
    return run._replace(walker=run.walker._replace(backend="jax"))


def restored(run: LearnConfig, folder: Path) -> tuple:
    """``(resolved run, config, arch, policy, env, bank, states, chunks done, saved meta)`` of ``folder``'s last
    checkpoint, read
    without compiling or stepping anything: the checkpoint is read into the shapes of the initial states
    (``jax.eval_shape``), through the MJX-JAX layout (:func:`report_run`: a Warp run reads on a machine without
    MuJoCo Warp). :class:`BadInput` when the folder has no checkpoint or another archive's."""
    folder = Path(folder)
    if not (folder / driver.CHECKPOINT_NAME).exists():
        raise BadInput(f"{folder} has no checkpoint ({driver.CHECKPOINT_NAME})")
    resolved, config, arch, policy, env = validate(report_run(run))
    check_resumable(folder, run, arch, physics=False)
    if isinstance(arch, OwnTerrains):
        try:
            arch = rank_terrains(resolved, arch, policy, folder, measure=False)
        except ValueError as err:
            raise BadInput(str(err)) from None
    bank, _, _, start, keys, init = inputs(resolved, config, arch, policy, env)
    shapes = jax.eval_shape(init, keys, bank, start)

    def zeros(spec):
        if jnp.issubdtype(spec.dtype, jax.dtypes.prng_key):
            data = jax.eval_shape(jax.random.key_data, spec)
            return jax.random.wrap_key_data(jnp.zeros(data.shape, data.dtype))
        return jnp.zeros(spec.shape, spec.dtype)

    like = strip_envs(jax.tree.map(zeros, shapes))  # the env states are not read (Warp's are shaped otherwise)
    states, done, _, saved = driver.restore(folder, like=like, **CHECKPOINT_COMPAT)
    return resolved, config, arch, policy, env, bank, states, done, saved


def report_treatment(run: LearnConfig, folder: Path) -> dict | None:
    """The outputs of a treatment as it stands, without training: a finished one's summary; for one with a
    checkpoint, its history / sequences / milestones / curve as of that checkpoint and ``summary_partial.json``
    (the summary with ``"partial": true`` and ``"chunks_done"``; ``summary.json`` stays the mark of a finished run,
    so ``--resume`` still continues it); when that checkpoint is the run's end (every chunk done, or every trial)
    but its outputs were never written (a run stopped after its last checkpoint), the finished outputs and
    ``summary.json``, as the run would have written them; None without a checkpoint. Compiles nothing and steps no physics
    (:func:`restored`)."""
    folder = Path(folder)
    if (folder / "summary.json").exists():
        return json.loads((folder / "summary.json").read_text())
    if not (folder / driver.CHECKPOINT_NAME).exists():
        return None
    resolved, config, arch, _, _, bank, states, done, saved = restored(run, folder)
    finished = done >= config.max_chunks or bool(np.all(np.asarray(states.done)))  # run_treatment's end
    return write_outputs(folder, resolved, config, bank, states, seconds=saved.get("wall_s"),
                         chunks_done=None if finished else done, names=arch.generator_names)


def export_treatment(run: LearnConfig, folder: Path) -> list[Path]:
    """Every trial's walker of ``folder``'s last checkpoint as ``folder/policies/trial_K/``
    (:func:`~jaxterrain.curriculum.outputs.export_policies`), for runs made before treatments wrote them, or of a
    run stopped by its time limit. Compiles nothing (:func:`restored`)."""
    resolved, config, arch, policy, env, bank, states, _, _ = restored(run, folder)
    return export_policies(folder, resolved, config, W.fine_tuning_ppo(config, policy, env), env, policy, bank, states,
                           names=arch.generator_names)

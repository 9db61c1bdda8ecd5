"""The Experiment 2 treatment runner: a flat treatment config (the ``learn`` command's ``config.json``) -> a
validated curriculum, its compiled trial blocks, a run driven chunk by chunk with checkpoints and time limits, and
its outputs (:mod:`jaxterrain.curriculum.outputs`).

    config, arch, policy, env = runner.validate(cfg)     # BadInput naming the parameter, before anything compiles
    summary = runner.run_treatment(cfg, folder, time_limit_s=540)   # None: stopped by the time limit (checkpointed)
    summary = runner.report_treatment(cfg, folder)       # the outputs of the last checkpoint, without training
    paths = runner.export_treatment(cfg, folder)         # its walkers, folder/policies/trial_K/, without training

``cfg`` is flat: the curriculum's fields and its fine-tuning PPO's side by side (``CurriculumConfig.from_json_dict``),
``curriculum`` (the selector), ``archive`` (a path), ``trials``, ``seed``, ``backend`` (``auto`` / ``jax`` /
``warp``), ``chunks_per_call``, ``fast_compile``, ``compact`` and ``episode_length``; the ``learn`` command's
presets give every key.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import re
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.curriculum import walker as W
from jaxterrain.curriculum.config import RECIPES, CurriculumConfig, FINE_TUNED, validate_config
from jaxterrain.curriculum.core import CHECKPOINT_COMPAT, init_trials, live_rows, run_live, run_trials
from jaxterrain.curriculum.outputs import PARTIAL, export_policies, write_outputs
from jaxterrain.curriculum.selectors import flat_name, get_selector, selector_fields
from jaxterrain.qd.archive_io import load as load_archive_file
from jaxterrain.qd.bank import from_archive
from jaxterrain.runtime import driver, estimates, sharding, xla
from jaxterrain.terrain import TerrainScale
from jaxterrain.difficulty import policy_robot, robot_base_policy
from jaxterrain.walker import robots, tiles
from jaxterrain.walker.layout import resolve_backend

__all__ = ["BadInput", "ChunkMetrics", "ChunkProgress", "LEGACY_TRUNCATION", "PARTIAL", "FAST_COMPILE", "PROGRAMS", "curriculum_config",
           "with_protocol", "with_accel_generator", "start_policy", "load_archive", "archive_digest", "check_resumable", "physics_of", "selector_slots", "walker_layout",
           "validate", "strip_envs", "ENV_STATES", "compiled", "make_block", "chunk_metrics", "inputs", "setup", "run_treatment",
           "report_cfg", "restored", "report_treatment", "export_treatment"]

LEGACY_TRUNCATION = "mask"
"""``truncation`` of a config saved without one: every run before the presets' default became ``bootstrap``."""


class BadInput(ValueError):
    """A bad parameter or file, reported as one line before anything is compiled."""


# ----------------------------------------------------------------------------------------------------------------
# Validation (before anything is compiled)
# ----------------------------------------------------------------------------------------------------------------
def curriculum_config(cfg: dict):
    """The :class:`jaxterrain.curriculum.CurriculumConfig` of a learn config dict (validated). The dict is flat: the
    curriculum's fields and its fine-tuning PPO's (``num_envs``, ..., ``learning_rate``: ``CurriculumConfig.ppo``)
    side by side, with ``curriculum`` as the selector; ``CurriculumConfig.from_json_dict`` reads that layout."""
    if cfg.get("recipe") is not None and cfg["recipe"] not in RECIPES:
        raise BadInput(f"--recipe must be one of {', '.join(RECIPES)}, got {cfg['recipe']!r}")
    own = selector_fields()  # the selectors' params, flat (CurriculumConfig.from_json_dict takes the run's)
    fields = {k: v for k, v in cfg.items()
              if k in FINE_TUNED or k in own or (k in CurriculumConfig._fields and k not in ("ppo", "params"))}
    fields.setdefault("truncation", LEGACY_TRUNCATION)
    try:
        return validate_config(CurriculumConfig.from_json_dict({**fields, "selector": cfg["curriculum"]}))
    except (ValueError, TypeError) as err:  # a field is its flag's name: --levels-init (CurriculumConfig.levels_init)
        err = re.sub(r"CurriculumConfig\.ppo\b", "--recipe / --num-envs (the update's shape)", str(err))
        err = re.sub(r"CurriculumConfig\.params\.([a-z_]+)\b",  # a selector's own: its flat key (plr_capacity)
                     lambda m: "CurriculumConfig." + flat_name(cfg["curriculum"], m.group(1)), err)
        raise BadInput(re.sub(r"CurriculumConfig\.selector\b", "--curriculum", re.sub(
            r"CurriculumConfig\.(?!selector\b)([a-z_]+)\b", lambda m: f"--{m.group(1).replace('_', '-')}",
            err))) from None


def with_protocol(cfg: dict, arch) -> dict:
    """``cfg`` with the evaluation protocol's ``attempts`` / ``best`` / ``headings`` that are None (the presets'
    "the archive's") taken from the archive's config: the curriculum then evaluates under the protocol its prior,
    the archive's fitness, was measured under."""
    fields = {k: getattr(arch.config, k, 1 if k == "headings" else None) for k in ("attempts", "best", "headings")}
    return {**cfg, **{k: int(v) for k, v in fields.items() if cfg.get(k) is None}}


def with_accel_generator(cfg: dict, arch) -> dict:
    """``cfg`` with ``accel_generator`` set to the archive's generator when the curriculum is ``accel`` and none was
    given; :class:`BadInput` when the archive holds several generators (``--accel-generator`` must choose)."""
    if cfg.get("curriculum") != "accel" or cfg.get("accel_generator") is not None:
        return cfg
    names = sorted({arch.generator_names[int(i)] for i in np.asarray(arch.source)[np.asarray(arch.source) >= 0]})
    if len(names) != 1:
        raise BadInput(f"--accel-generator: the archive holds {', '.join(names)}; name the generator whose genomes "
                       f"are accel's levels")
    return {**cfg, "accel_generator": names[0]}


def load_archive(path, descriptors):
    """``qd.load`` with one-line errors naming the file: unreadable, other descriptors, < 2 filled cells."""
    try:
        arch = load_archive_file(path)
    except (OSError, ValueError) as err:
        raise BadInput(f"--archive {path}: {str(err).splitlines()[0]}") from None
    if tuple(arch.config.descriptors) != tuple(descriptors):
        raise BadInput(f"--archive {path}: descriptors {tuple(arch.config.descriptors)}, the curriculum expects "
                       f"{tuple(descriptors)}")
    filled = int(arch.filled.sum())
    if filled < 2:
        raise BadInput(f"--archive {path}: {filled} filled cell(s); a curriculum needs at least 2")
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


def check_resumable(folder: Path, cfg: dict, arch, physics: bool = True) -> str:
    """``arch``'s :func:`archive_digest`, after checking it against ``folder``'s checkpoint: :class:`BadInput` when
    that was written for another archive than the one now at ``cfg["archive"]`` (its terrain indices, GP
    observations and removed cells would refer to other terrains), or on other physics than ``cfg["backend"]``
    resolves to here (``auto`` on a machine without MuJoCo Warp would silently continue a Warp run on MJX: one run,
    two simulators; ``physics=False``, for a report that only reads the checkpoint, skips this). Reads only the
    checkpoint's header; checkpoints written before the digest (or the backend) was
    recorded are not checked for it."""
    digest = archive_digest(arch)
    try:
        meta = driver.read_meta(folder)
    except ValueError as err:
        raise BadInput(str(err)) from None
    stored = (meta or {}).get("archive_sha256")
    if stored is not None and stored != digest:
        raise BadInput(f"--archive {cfg['archive']}: it is not the archive {folder} was checkpointed with (sha256 "
                       f"{stored[:12]}... then, {digest[:12]}... now); put that file back or start a new run")
    then, now = (meta or {}).get("backend"), physics_of(cfg)
    if physics and then is not None and then != now:
        raise BadInput(f"--backend {cfg.get('backend', 'jax')}: it runs the walker on {now} here, but {folder} was "
                       f"checkpointed on {then}; continue it where {then} runs (warp: a GPU with MuJoCo Warp "
                       f"installed) or start a new run")
    return digest


def physics_of(cfg: dict) -> str:
    """The walker backend a learn config runs on here, ``jax`` or ``warp`` (:func:`resolve_backend` of its
    ``backend``; a config saved before ``--backend`` existed ran on "jax")."""
    return resolve_backend(cfg.get("backend", "jax"))


def selector_slots(cfg: dict) -> int:
    """``Selector.slots`` of a learn config's curriculum (1 for map / roughness / random): a trial's terrains per
    chunk. :class:`BadInput` for an unknown curriculum."""
    fields = {k: cfg[k] for k in ("terrains_per_chunk", "levels") if cfg.get(k) is not None}
    try:
        return int(get_selector(CurriculumConfig.from_json_dict({"selector": cfg["curriculum"], **fields})).slots)
    except (ValueError, TypeError) as err:
        raise BadInput(f"--curriculum: {err}") from None


def walker_layout(cfg: dict) -> dict:
    """The walker's ``backend`` / ``tiles`` / ``worlds`` of a learn config (a config saved before ``--backend``
    existed runs on "jax"): warp walks on one tile per trial (per heading, per selector slot) with contact buffers for every env stepped
    at once (``trials x max(num_envs, attempts)``: the PPO envs, then the evaluation walks; with ``overlap``
    ``trials x (num_envs + attempts)``, stepped together); jax on tiles too with ``overlap``. :class:`BadInput` for
    an unknown backend, or warp where MuJoCo Warp does not import."""
    backend = physics_of(cfg)
    slots = selector_slots(cfg)  # a trial's terrains per chunk: one tile each
    trials, headings = int(cfg["trials"]), int(cfg.get("headings") or 1) * slots
    overlap = bool(cfg.get("overlap", False))  # the evaluation walks ride along PPO's envs on tiles
    if backend == "jax":
        return dict(tiles=trials * headings) if overlap else {}
    if backend != "warp":
        raise BadInput(f"--backend must be jax or warp, got {backend!r}")

    ok, why = tiles.warp_available()
    if not ok:
        raise BadInput(f"--backend warp: {why}")
    envs, attempts = int(cfg["num_envs"]), int(cfg["attempts"])
    return dict(backend="warp", tiles=trials * headings,
                worlds=trials * (envs + attempts if overlap else max(envs, attempts)))


def start_policy(cfg: dict):
    """The policy a learn config starts from: ``--policy``, else the shipped base policy of ``--robot`` (default the
    humanoid's). :class:`BadInput` for an unknown robot, a robot without a shipped base policy, a policy that does
    not load, or a ``--policy`` of another robot than ``--robot``."""
    robot, path = cfg.get("robot") or "humanoid", cfg.get("policy")
    try:
        robots.get(robot)
        if path is None and robot != "humanoid":
            return robot_base_policy(robot)
    except ValueError as err:
        raise BadInput(f"--robot: {err}") from None
    try:
        policy = W.load_policy(path)
    except ValueError as err:
        raise BadInput(f"--policy: {err}") from None
    if cfg.get("robot") is not None and policy_robot(policy) != robot:
        raise BadInput(f"--policy {path}: it walks the {policy_robot(policy)}, not --robot {robot}")
    return policy


def validate(cfg: dict):
    """``(CurriculumConfig, archive, policy, env)`` or :class:`BadInput` naming the parameter or file."""
    trials = cfg.get("trials")
    if not isinstance(trials, int) or isinstance(trials, bool) or trials < 1:
        raise BadInput(f"--trials must be an integer >= 1, got {trials!r}")
    chunks = cfg.get("chunks_per_call")
    if not isinstance(chunks, int) or chunks < 1:
        raise BadInput(f"--chunks-per-call must be an integer >= 1, got {chunks!r}")
    if not isinstance(cfg.get("episode_length"), int) or cfg["episode_length"] < 1:
        raise BadInput(f"episode_length must be an integer >= 1, got {cfg.get('episode_length')!r}")
    arch = load_archive(cfg["archive"], cfg["descriptors"])
    cfg = with_accel_generator(with_protocol(cfg, arch), arch)
    config = curriculum_config(cfg)
    policy = start_policy(cfg)
    archive_robot = getattr(arch.config, "robot", None) or "humanoid"
    if archive_robot != policy_robot(policy):
        raise BadInput(f"--archive {cfg['archive']}: its fitness is the {archive_robot}'s, but the policy walks the "
                       f"{policy_robot(policy)} (evolve an archive with --robot {policy_robot(policy)})")
    shape = (256, 256) if arch.heightmaps is None else tuple(arch.heightmaps.shape[1:])
    env = W.walker_env(policy, shape, TerrainScale(), cfg["episode_length"], **walker_layout(cfg),
                       healthy_reward=cfg.get("healthy_reward"))
    try:
        W.check_policy(policy, env)
    except ValueError as err:
        raise BadInput(f"--policy: {err}") from None
    return config, arch, policy, env


# ----------------------------------------------------------------------------------------------------------------
# The treatment
# ----------------------------------------------------------------------------------------------------------------
def strip_envs(states):
    """The carried state without the envs' physics: what a report reads from a checkpoint (the env states of a
    MuJoCo Warp run have another structure than MJX-JAX's, and nothing is stepped)."""
    return states._replace(policy=states.policy._replace(env_state=None))


ENV_STATES = ".policy.env_state"
"""The checkpoint leaves of the trials' env states (``State.policy.env_state``). Checkpoints written before they
were carried (2026-11-29) lack them and stored ``restart`` True: restored, their envs restart on the current
terrains, as they did at every block then."""


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


class ChunkMetrics:
    """A treatment's ``metrics.csv`` inside its compiled blocks: after every chunk, the rows (:func:`chunk_metrics`)
    of the chunks that every trial still running has finished, up to the block's end, from the block's per-chunk
    callback; the driver writes the same rows again at the block's end, with TensorBoard's. Call :meth:`begin`
    before each block: the trials' history so far and the rows the block computes (``compact``: ``core.live_rows``,
    else all), so a block of fewer rows updates its own trials. Not for a mesh of several devices (a callback there
    sees one device's rows): there metrics.csv moves per block."""

    def __init__(self, folder: Path, compact: bool):
        self.folder, self.compact = Path(folder), bool(compact)
        self.history = self.rows = None
        self.stop = self.written = 0

    def begin(self, states, stop: int) -> None:
        """Before a block that ends at chunk ``stop``: host copies of ``states.history`` and the block's rows."""
        self.history = type(states.history)(*(np.array(x) for x in states.history))  # [T, C] each
        done = np.asarray(states.done, bool)
        self.rows = live_rows(done) if self.compact else np.arange(done.size)
        self.stop, self.written = int(stop), int(np.min(np.asarray(states.chunk)))

    def __call__(self, chunk, hardest, done, history) -> None:
        if self.history is None or chunk.shape[0] != self.rows.size:
            return
        for full, part in zip(self.history, history):
            full[self.rows] = np.asarray(part)
        running = ~np.asarray(done, bool)
        upto = min(int(np.min(chunk[running])) if running.any() else int(np.max(chunk)), self.stop)
        if upto <= self.written:
            return
        self.written = upto
        metrics = history_metrics(self.history, 0, upto)
        driver.write_metrics_csv(self.folder, {k: [float(x) for x in v] for k, v in metrics.items()})


class ChunkProgress:
    """A treatment's progress inside its compiled blocks: one line on stderr at most every ``every_s`` seconds (the
    driver's :data:`~jaxterrain.runtime.driver.PLAIN_EVERY_S`), ``desc: chunk C of N, hardest H cells (mean of the
    trials), S s/chunk``; through ``tqdm.write`` (above a progress bar) when stderr is a terminal."""

    def __init__(self, desc: str, total: int, start: int, every_s: float | None = None):
        self.desc, self.total, self.start = desc, int(total), int(start)
        self.every_s = float(driver.PLAIN_EVERY_S if every_s is None else every_s)
        self.t0 = self.last = time.perf_counter()
        self.lines: list[str] = []

    def __call__(self, chunk, hardest, done, history=None) -> None:
        now = time.perf_counter()
        reached = int(np.max(chunk)) if chunk.size else self.start
        if now - self.last < self.every_s and reached < self.total:
            return
        self.last = now
        rate = (now - self.t0) / max(reached - self.start, 1)
        line = (f"{self.desc}: chunk {reached} of {self.total}, hardest {float(np.mean(hardest)):.2f} cells (mean of "
                f"{hardest.size} trials, {int(np.sum(~done))} running), {rate:.1f} s/chunk")
        self.lines.append(line)
        if sys.stderr.isatty():
            try:
                from tqdm import tqdm

                tqdm.write(line, file=sys.stderr)
                return
            except ImportError:
                pass
        print(line, file=sys.stderr, flush=True)


def make_block(config, harness):
    """``(states, bank, n) -> states`` (jit it): up to ``n`` chunks of every trial. The trials' env states ride in
    ``states`` from block to block (and into every checkpoint), so where the blocks are cut changes nothing: a run
    stopped after any chunk and resumed equals the uninterrupted run. Envs restart only where the curriculum says
    (``State.restart``: the start, a terrain switch)."""
    def block(states, bank, n):
        return run_trials(states, bank, jnp.asarray(n, jnp.int32), config=config, harness=harness,
                          on_chunk=_chunk_done)

    return block


def chunk_metrics(states, start: int, stop: int) -> dict:
    """Per-chunk ``[stop - start]`` metrics over trials: hardest (mean, a finished trial keeps its last value),
    evaluation (mean of the trials still running), trials still running."""
    return history_metrics(states.history, start, stop)


def history_metrics(h, start: int, stop: int) -> dict:
    """:func:`chunk_metrics` of the trials' ``History`` ``h`` (leaves ``[T, C]``, host or device arrays)."""
    hardest = np.asarray(h.hardest, np.float64)
    epoch = np.asarray(h.epoch)
    carried = np.zeros_like(hardest)
    for t in range(hardest.shape[0]):
        n = int(np.sum(epoch[t] >= 0))
        carried[t, :n] = hardest[t, :n]
        carried[t, n:] = hardest[t, n - 1] if n else 0.0
    ev = np.asarray(h.evaluation, np.float64)[:, start:stop]
    running = np.sum(epoch[:, start:stop] >= 0, axis=0)
    evaluation = np.where(running > 0, np.nansum(ev, axis=0) / np.maximum(running, 1), np.nan)
    return {"hardest": carried[:, start:stop].mean(axis=0), "evaluation": evaluation,
            "trials_running": running.astype(np.float64)}


PROGRAMS: dict = {}  # (config, ppo, walker, trials, bank shape, fast, mesh) -> (init, block, {rows: compiled block})


def inputs(cfg: dict, config, arch, policy, env):
    """What a treatment's programs start from: ``(bank, ppo, harness, start, keys, init)``: the archive's terrain
    bank, the fine-tuning PPOConfig, the walker harness, the starting policy state, the trials' keys [trials] and
    ``init(keys, bank, start)`` -> the initial trial states, their env states zeros due for a restart on the first
    terrains (pure: jit or ``eval_shape`` it)."""
    bank = from_archive(arch)
    ppo = config.ppo_config(policy.config)
    harness = W.walker_harness(env, ppo, config)
    start = W.start_state(env, ppo, policy, bank.heightmaps.shape[1:])
    keys = jax.random.split(jax.random.fold_in(jax.random.key(int(cfg["seed"])), 2), int(cfg["trials"]))

    def init(k, b, s):
        states = init_trials(k, b, s, config=config, harness=harness)  # restart: True (the first chunk resets)
        zeros = jax.tree.map(jnp.zeros_like, s.env_state)  # vmap broadcasts (MuJoCo Warp's shared buffers too)
        envs = jax.vmap(lambda _: zeros)(jnp.arange(states.done.shape[0]))
        return states._replace(policy=states.policy._replace(env_state=envs))

    return bank, ppo, harness, start, keys, init


def setup(cfg: dict, config, arch, policy, env, mesh=None):
    """Bank, the block ``run(states, bank, n) -> states`` and the initial (stripped) trial states. ``run`` computes
    the running trials only when ``cfg["compact"]`` (``curriculum.run_live``; default on) and compiles the block
    once per trial count it meets (every trial's here, fewer at the first call that needs them); compiled programs
    are reused by later treatments with the same settings and bank shape (``experiments curriculum``). ``mesh``:
    the trials split over its devices (``sharding.map_rows``: padded, the bank replicated)."""
    bank, ppo, harness, start, keys, init_fn = inputs(cfg, config, arch, policy, env)
    fast = bool(cfg.get("fast_compile", False))
    sig = (config, ppo, env.config, int(cfg["trials"]), tuple(bank.heightmaps.shape), fast, mesh)
    fresh = sig not in PROGRAMS  # a treatment of the same shape as an earlier one reuses its programs
    note = (estimates.compiling("curriculum-block", f"{int(cfg['trials'])} trials, {physics_of(cfg)} physics")
            if fresh else contextlib.nullcontext())
    with note:  # what compiles and about how long it takes here, then how long it took
        if fresh:
            PROGRAMS[sig] = (compiled(init_fn, fast, keys, bank, start),
                             make_block(config, harness), {})
        init, block, blocks = PROGRAMS[sig]  # blocks: trial count -> the block compiled for it
        states = init(keys, bank, start)
        if mesh is not None:  # the trials split over the devices; inputs whole on the mesh (whence the init's)
            block = sharding.map_rows(block, mesh, replicated=(1, 2))
            bank, states = sharding.replicate((bank, states), mesh)
            place = functools.partial(sharding.replicate, mesh=mesh)
        else:
            place = lambda tree: tree  # noqa: E731

        def program(rows: int):
            if rows not in blocks:
                like = jax.tree.map(lambda x: x[:rows], states)
                blocks[rows] = compiled(block, fast, like, bank, jax.numpy.int32(1))
            return blocks[rows]

        def rows_block(s, b, n):
            return program(int(s.done.shape[0]))(*place((s, b)), jax.numpy.int32(n))

        program(int(states.done.shape[0]))  # the block of every trial now: set-up includes its compile
    compact = bool(cfg.get("compact", True))
    return bank, (functools.partial(run_live, rows_block) if compact else rows_block), states


def run_treatment(cfg: dict, folder: Path, time_limit_s: float | None = None, desc: str = "",
                  mesh=None, progress: bool | str = True) -> dict | None:
    """Run (or continue) one treatment in ``folder``; its summary dict when finished, None when the time limit
    stopped it (checkpointed; call again to continue). ``time_limit_s`` counts from this call, its set-up and
    compilation included. Raises :class:`BadInput` before compiling anything."""
    folder = Path(folder)
    if (folder / "summary.json").exists():
        return json.loads((folder / "summary.json").read_text())
    config, arch, policy, env = validate(cfg)
    digest = check_resumable(folder, cfg, arch)
    t0 = time.perf_counter()
    bank, block, states = setup(cfg, config, arch, policy, env, mesh)
    restored = driver.restore(folder, like=states, **CHECKPOINT_COMPAT, optional=(ENV_STATES,))
    done, history, before = 0, None, 0.0  # before: wall seconds of the commands that ran it so far
    if restored is not None:
        states, done, history, saved = restored
        before = float(saved.get("wall_s", 0.0))
        print(f"resuming at chunk {done} of {config.max_chunks} ({before / 60:.1f} min of wall time so far)",
              flush=True)

    every = int(cfg.get("policy_every") or 0)  # snapshots of the walkers along the run
    ppo = config.ppo_config(policy.config)

    one_device = mesh is None or mesh.size == 1  # several: each callback sees its device's rows only
    metrics_csv = ChunkMetrics(folder, cfg.get("compact", True)) if one_device else None

    def chunk_fn(s, a, b):
        if not bool(np.all(np.asarray(s.done))):
            if metrics_csv is not None:
                metrics_csv.begin(s, b)
            s = block(s, bank, b - a)
        if every and b // every > a // every:
            export_policies(folder, cfg, config, ppo, env, policy, bank, s, subdir=f"chunk_{b:05d}",
                            names=arch.generator_names)
        return s, chunk_metrics(s, a, b)

    _LISTENERS[:] = [ChunkProgress(desc or cfg["curriculum"], config.max_chunks, done)] + (
        [metrics_csv] if metrics_csv is not None else [])
    try:
        states, done, _ = driver.run_chunks(
            chunk_fn, states, total=config.max_chunks, every=int(cfg["chunks_per_call"]), start=done,
            history=history, run_dir=folder, key_metric="hardest", desc=desc or cfg["curriculum"], progress=progress,
            time_limit_s=None if time_limit_s is None else max(time_limit_s - (time.perf_counter() - t0), 1e-3),
            unit="chunk", meta={"config": cfg, "archive_sha256": digest, "backend": physics_of(cfg)},
            wall_s=before + time.perf_counter() - t0, fit_to_limit=True)  # the block's length is traced
    finally:
        _LISTENERS.clear()
    if done < config.max_chunks and not bool(np.all(np.asarray(states.done))):
        return None
    export_policies(folder, cfg, config, ppo, env, policy, bank, states, names=arch.generator_names)
    return write_outputs(folder, cfg, config, bank, states, seconds=before + time.perf_counter() - t0,
                         names=arch.generator_names)


def report_cfg(cfg: dict) -> dict:
    """``cfg`` as :func:`report_treatment` validates it: on the MJX-JAX backend, which every machine has."""
    return {**cfg, "backend": "jax"}


def restored(cfg: dict, folder: Path) -> tuple:
    """``(config, arch, policy, env, bank, states, chunks done, saved meta)`` of ``folder``'s last checkpoint, read
    without compiling or stepping anything: the checkpoint is read into the shapes of the initial states
    (``jax.eval_shape``), through the MJX-JAX layout (:func:`report_cfg`: a Warp run reads on a machine without
    MuJoCo Warp). :class:`BadInput` when the folder has no checkpoint or another archive's."""
    folder = Path(folder)
    if not (folder / driver.CHECKPOINT_NAME).exists():
        raise BadInput(f"{folder} has no checkpoint ({driver.CHECKPOINT_NAME})")
    config, arch, policy, env = validate(report_cfg(cfg))
    check_resumable(folder, cfg, arch, physics=False)
    bank, _, _, start, keys, init = inputs(cfg, config, arch, policy, env)
    shapes = jax.eval_shape(init, keys, bank, start)

    def zeros(spec):
        if jnp.issubdtype(spec.dtype, jax.dtypes.prng_key):
            data = jax.eval_shape(jax.random.key_data, spec)
            return jax.random.wrap_key_data(jnp.zeros(data.shape, data.dtype))
        return jnp.zeros(spec.shape, spec.dtype)

    like = strip_envs(jax.tree.map(zeros, shapes))  # the env states are not read (Warp's are shaped otherwise)
    states, done, _, saved = driver.restore(folder, like=like, **CHECKPOINT_COMPAT)
    return config, arch, policy, env, bank, states, done, saved


def report_treatment(cfg: dict, folder: Path) -> dict | None:
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
    config, arch, _, _, bank, states, done, saved = restored(cfg, folder)
    finished = done >= config.max_chunks or bool(np.all(np.asarray(states.done)))  # run_treatment's end
    return write_outputs(folder, cfg, config, bank, states, seconds=saved.get("wall_s"),
                         chunks_done=None if finished else done, names=arch.generator_names)


def export_treatment(cfg: dict, folder: Path) -> list[Path]:
    """Every trial's walker of ``folder``'s last checkpoint as ``folder/policies/trial_K/``
    (:func:`~jaxterrain.curriculum.outputs.export_policies`), for runs made before treatments wrote them, or of a
    run stopped by its time limit. Compiles nothing (:func:`restored`)."""
    config, arch, policy, env, bank, states, _, _ = restored(cfg, folder)
    return export_policies(folder, cfg, config, config.ppo_config(policy.config), env, policy, bank, states,
                           names=arch.generator_names)

"""``python -m experiments learn``: one Experiment 2 treatment, PPO from the base policy on an archive curriculum.

    python -m experiments learn --archive docs/results/exp2_cppn_headings_archive.npz --curriculum map --trials 10 \\
        --preset gpu-short --out runs/learn-cppn --time-limit 9
    python -m experiments learn --resume runs/learn-cppn --time-limit 9          # until it says "done"

``--curriculum``: ``map`` (the paper's IT&E map-based curriculum), ``roughness`` (standard CL: the terrains sorted by
roughness, every fifth, in order) or ``random`` (uniform over the archive). Every trial starts from the shipped base
policy (``--policy DIR`` for another), and the ``--trials`` trials run together (vmap) in one jitted function per
block of ``chunks_per_call`` chunks (a chunk = 40 epochs of 4 000 env steps + one evaluation; the curriculum's
choices: ``jaxterrain.curriculum.config``). At the start of every block each trial's envs restart on its current
terrain, so a checkpoint needs no physics state of thousands of envs and a resumed run equals an uninterrupted one.
Once some trials have finished (the map curriculum can empty a trial's map long before the epoch budget), a block
computes only the trials still running, padded with finished ones to a power of two (``curriculum.run_live``; the
same states, one compile per block size); ``--no-compact`` keeps every trial in every block (the smoke preset's
default, so that the CPU tests compile one block).

``--backend``: the walker's physics, ``auto`` (the default: ``warp`` on a GPU where MuJoCo Warp imports, else
``jax``; the two are compared in benchmarks/RESULTS.md), ``jax`` (MJX; every trial's envs on their own ``[H, W]``
heightfield) or ``warp`` (MuJoCo Warp, ``pip install 'jaxterrain[warp]'``; Warp shares one heightfield across all
envs, so the walker holds one tile per trial, ``WalkerConfig(tiles=trials)``, rebuilt from the trials' current
terrains at every chunk, and contact buffers for ``trials x max(num_envs, attempts)`` envs, ``trials x (num_envs +
attempts)`` with ``--overlap``; see
``jaxterrain.curriculum.walker``). It is saved in ``config.json``, so ``--resume`` keeps it.

Evaluation protocol: each evaluation walks under the protocol the archive's fitness was measured under (its
``EvolveConfig``'s ``attempts`` / ``best`` / ``headings``: 20 / 5 / 1 for the paper's, 80 / 5 / 4 for an archive evolved
or reseated under ``difficulty.HEADINGS``), so the GP's prior and its observations agree; ``--protocol paper|headings``
or ``--attempts`` / ``--best`` / ``--headings`` override it. With several headings the PPO envs also train in every
heading (``jaxterrain.curriculum.walker``).

Fine-tuning: the reward is the base policy's own (brax's humanoid: 1.25 x forward velocity + 5.0 per step for
staying up - control cost); ``--healthy-reward`` changes the per-step bonus for PPO only (evaluations measure
distance). The observation normaliser keeps merging the fine-tuning data, as brax's PPO does;
``--freeze-normaliser`` keeps the base policy's statistics. Why both exist: docs/results/exp2_headings.md.

Presets: ``paper`` (30 000 epochs, the paper's budget), ``gpu-short`` (3 000 epochs, a tenth), ``smoke`` (CPU,
about a minute after compiling: 2 trials of 4 one-epoch chunks of 80 env steps on 4 envs, 2 walks per evaluation
along +x whatever the archive's protocol, 100-step episodes; the archive's terrains are used as they are). The
default archive is the CPPN's shipped paper-budget archive, reseated under ``difficulty.HEADINGS`` (``CPPN_ARCHIVE``).

``--resume RUN --report`` writes the outputs below from the last checkpoint without training (``summary_partial.json``
instead of ``summary.json``, which marks a finished run): the per-trial history survives a machine that is given
back with the checkpoint on it.

Writes into the run folder: ``config.json``, ``checkpoint.npz`` + ``metrics.csv`` + ``tb/`` (the driver's),
``history.csv`` (one row per trial and chunk), ``sequences.csv`` (each trial's terrains in order), ``milestones.csv``
/ ``.md`` (Table 2's row), ``curve.png`` (hardest terrain traversed vs epoch, mean +- 1 standard error) and
``summary.json``.
"""

from __future__ import annotations

import argparse
import csv
import functools
import io
import json
import shutil
import sys
import time
from pathlib import Path

from experiments import common

LEGACY_TRUNCATION = "mask"
"""``truncation`` of a config saved without one: every run before the presets' default became ``bootstrap``."""
CPPN_ARCHIVE = "docs/results/exp2_cppn_headings_archive.npz"  # paper budget, after the insertion fix, HEADINGS
_PAPER = dict(archive=CPPN_ARCHIVE, curriculum="map", trials=10, descriptors=["roughness", "tpi"], policy=None,
              epochs_per_chunk=40, steps_per_epoch=4000, max_epochs=30000, threshold=0.9, max_fitness=1.0,
              max_evals=100, attempts=None, best=None, headings=None, kappa=0.05, rho=0.4, sigma_f=1.0, noise=0.001,
              gp_evaluation="final", removal_margin=0.05, removal_ties="nearer", credit="threshold",
              distance_origin="origin", roughness_stride=5, max_observations=None, num_envs=500, unroll_length=10,
              num_unrolls=8, num_minibatches=8, update_epochs=8, learning_rate=3e-4, episode_length=1000,
              chunks_per_call=25, fast_compile=False, backend="auto", healthy_reward=None, update_normaliser=True,
              truncation="bootstrap", overlap=False, compact=True)
PRESETS: dict[str, dict] = {
    "paper": _PAPER,
    "gpu-short": {**_PAPER, "max_epochs": 3000},
    "smoke": {**_PAPER, "trials": 2, "epochs_per_chunk": 1, "steps_per_epoch": 80, "max_epochs": 4, "max_evals": 2,
              "attempts": 2, "best": 1, "headings": 1, "num_envs": 4, "num_unrolls": 2, "num_minibatches": 2,
              "update_epochs": 1, "episode_length": 100, "chunks_per_call": 2, "fast_compile": True,
              "compact": False},
}


class BadInput(ValueError):
    """A bad parameter or file, reported as one line before anything is compiled."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke")
    common.add_devices_argument(parser)  # the trials are split over the devices (curriculum.make_runner)
    parser.add_argument("--archive", default=None, help=f"archive .npz (default {CPPN_ARCHIVE})")
    parser.add_argument("--curriculum", choices=["map", "roughness", "random"], default=None)
    parser.add_argument("--trials", type=int, default=None, help="trials run together (paper: 10)")
    parser.add_argument("--threshold", type=float, default=None, help="fraction of the maximum fitness, in (0, 1]")
    parser.add_argument("--max-epochs", type=int, default=None)
    parser.add_argument("--policy", default=None, help="policy folder to start from (default: the base policy)")
    parser.add_argument("--chunks-per-call", type=int, default=None, help="chunks per jitted call / checkpoint")
    parser.add_argument("--num-envs", type=int, default=None, help="PPO envs per trial (all on its terrain)")
    add_fine_tuning_arguments(parser)
    parser.add_argument("--report", action="store_true",
                        help="with --resume: write the outputs of the last checkpoint (history, sequences, "
                             "milestones, curve, summary_partial.json) without training, and stop")
    parser.add_argument("--attempts", type=int, default=None,
                        help="evaluation walks in total (default: the archive's protocol, e.g. 20)")
    parser.add_argument("--best", type=int, default=None, help="best walks averaged per heading (default: archive's)")
    parser.add_argument("--headings", type=int, choices=(1, 2, 4), default=None,
                        help="evaluation headings (default: the archive's protocol: 1 = the paper's +x)")
    common.add_protocol_argument(parser)
    parser.add_argument("--backend", choices=BACKENDS, default=None,
                        help="walker physics: auto (default: warp on a GPU where it imports, else jax), jax (MJX) or "
                             "warp (MuJoCo Warp on one tile per trial)")


def add_fine_tuning_arguments(parser: argparse.ArgumentParser, scope: str = "") -> None:
    """``--freeze-normaliser``, ``--healthy-reward``, ``--learning-rate``, ``--truncation``, ``--max-evals``,
    ``--overlap`` and ``--compact`` / ``--no-compact`` (config ``update_normaliser`` / ``healthy_reward`` /
    ``learning_rate`` / ``truncation`` / ``max_evals`` / ``overlap`` / ``compact``, read back by
    :func:`fine_tuning_overrides`), shared with ``curriculum`` (``scope`` is added to the help, e.g. ", in every
    treatment")."""
    parser.add_argument("--freeze-normaliser", dest="update_normaliser", action="store_const", const=False,
                        default=None, help=f"keep the base policy's observation statistics fixed during fine-tuning"
                                           f"{scope} (default: they keep merging the fine-tuning data, as brax's PPO)")
    parser.add_argument("--healthy-reward", type=float, default=None,
                        help=f"fine-tuning reward per step for staying up, >= 0{scope} (default: the walker's 5.0, the "
                             f"base policy's; evaluations measure distance and do not use it)")
    parser.add_argument("--learning-rate", type=float, default=None,
                        help=f"fine-tuning PPO's Adam learning rate, > 0{scope} (default: every preset's 3e-4)")
    parser.add_argument("--truncation", choices=("mask", "bootstrap"), default=None,
                        help=f"what fine-tuning PPO learns from a walk that ends at the goal or the time limit{scope}: "
                             f"bootstrap (default: r + gamma V(final observation); keeps the value net from diverging "
                             f"and standard CL learning, docs/results/exp2_paper.md) or mask (brax's: nothing; the "
                             f"runs before 2026-11-27)")
    parser.add_argument("--max-evals", type=int, default=None,
                        help=f"evaluations (chunks) spent on one terrain before it is left anyway, >= 1{scope} "
                             f"(default: the paper's 100 in every preset; gpu-short keeps it, so one terrain that "
                             f"never reaches the threshold can take all 75 of its chunks)")
    parser.add_argument("--overlap", action="store_const", const=True, default=None,
                        help=f"evaluate each chunk's policy while the next chunk trains, in the same physics calls"
                             f"{scope} (the same curriculum; the walker on one tile per trial, on either backend; "
                             f"CurriculumConfig.overlap)")
    parser.add_argument("--compact", action=argparse.BooleanOptionalAction, default=None,
                        help=f"once some trials have finished, compute only the running ones in each block (the "
                             f"same results; one compile per block size){scope} (default: on, off in smoke)")


def fine_tuning_overrides(args) -> dict:
    """The config values of :func:`add_fine_tuning_arguments`' flags (None = not given)."""
    return dict(healthy_reward=args.healthy_reward, update_normaliser=args.update_normaliser,
                learning_rate=args.learning_rate, truncation=args.truncation, max_evals=args.max_evals,
                overlap=args.overlap, compact=args.compact)


def overrides(args) -> dict:
    return dict(archive=args.archive, curriculum=args.curriculum, trials=args.trials, threshold=args.threshold,
                max_epochs=args.max_epochs, policy=args.policy, chunks_per_call=args.chunks_per_call,
                num_envs=args.num_envs, backend=args.backend, **fine_tuning_overrides(args),
                **common.protocol_overrides(args))


# ----------------------------------------------------------------------------------------------------------------
# Validation (before anything is compiled)
# ----------------------------------------------------------------------------------------------------------------
def curriculum_config(cfg: dict):
    """The :class:`jaxterrain.curriculum.CurriculumConfig` of a learn config dict (validated). The dict is flat: the
    curriculum's fields and its fine-tuning PPO's (``num_envs``, ..., ``learning_rate``: ``CurriculumConfig.ppo``)
    side by side, with ``curriculum`` as the selector; ``CurriculumConfig.from_json_dict`` reads that layout."""
    from jaxterrain.curriculum import CurriculumConfig, validate_config
    from jaxterrain.curriculum.config import FINE_TUNED

    fields = {k: v for k, v in cfg.items() if k in FINE_TUNED or (k in CurriculumConfig._fields and k != "ppo")}
    fields.setdefault("truncation", LEGACY_TRUNCATION)
    try:
        return validate_config(CurriculumConfig.from_json_dict({**fields, "selector": cfg["curriculum"]}))
    except (ValueError, TypeError) as err:
        raise BadInput(str(err)) from None


def with_protocol(cfg: dict, arch) -> dict:
    """``cfg`` with the evaluation protocol's ``attempts`` / ``best`` / ``headings`` that are None (the presets'
    "the archive's") taken from the archive's config: the curriculum then evaluates under the protocol its prior,
    the archive's fitness, was measured under."""
    fields = {k: getattr(arch.config, k, 1 if k == "headings" else None) for k in ("attempts", "best", "headings")}
    return {**cfg, **{k: int(v) for k, v in fields.items() if cfg.get(k) is None}}


def load_archive(path, descriptors):
    """``archive.load`` with one-line errors naming the file: unreadable, other descriptors, < 2 filled cells."""
    from jaxterrain import archive as A

    try:
        arch = A.load(path)
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
    import hashlib

    import jax
    import numpy as np

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
    from jaxterrain import driver

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


BACKENDS = ("auto", "jax", "warp")


def resolve_backend(backend: str) -> str:
    """``auto`` -> ``warp`` where JAX runs on a GPU and MuJoCo Warp imports (2.1x MJX-JAX per curriculum chunk on an
    H100), else ``jax``; other values unchanged."""
    if backend != "auto":
        return backend
    import jax

    from jaxterrain.walker import warp_available

    return "warp" if jax.default_backend() == "gpu" and warp_available()[0] else "jax"


def physics_of(cfg: dict) -> str:
    """The walker backend a learn config runs on here, ``jax`` or ``warp`` (:func:`resolve_backend` of its
    ``backend``; a config saved before ``--backend`` existed ran on "jax")."""
    return resolve_backend(cfg.get("backend", "jax"))


def walker_layout(cfg: dict) -> dict:
    """The walker's ``backend`` / ``tiles`` / ``worlds`` of a learn config (a config saved before ``--backend``
    existed runs on "jax"): warp walks on one tile per trial (per heading) with contact buffers for every env stepped
    at once (``trials x max(num_envs, attempts)``: the PPO envs, then the evaluation walks; with ``overlap``
    ``trials x (num_envs + attempts)``, stepped together); jax on tiles too with ``overlap``. :class:`BadInput` for
    an unknown backend, or warp where MuJoCo Warp does not import."""
    backend = physics_of(cfg)
    trials, headings = int(cfg["trials"]), int(cfg.get("headings") or 1)
    overlap = bool(cfg.get("overlap", False))  # the evaluation walks ride along PPO's envs on tiles
    if backend == "jax":
        return dict(tiles=trials * headings) if overlap else {}
    if backend != "warp":
        raise BadInput(f"--backend must be jax or warp, got {backend!r}")
    from jaxterrain.walker import warp_available

    ok, why = warp_available()
    if not ok:
        raise BadInput(f"--backend warp: {why}")
    envs, attempts = int(cfg["num_envs"]), int(cfg["attempts"])
    return dict(backend="warp", tiles=trials * headings,
                worlds=trials * (envs + attempts if overlap else max(envs, attempts)))


def validate(cfg: dict):
    """``(CurriculumConfig, archive, policy, env)`` or :class:`BadInput` naming the parameter or file."""
    from jaxterrain.curriculum import walker as W
    from jaxterrain.terrain import TerrainScale

    trials = cfg.get("trials")
    if not isinstance(trials, int) or isinstance(trials, bool) or trials < 1:
        raise BadInput(f"--trials must be an integer >= 1, got {trials!r}")
    chunks = cfg.get("chunks_per_call")
    if not isinstance(chunks, int) or chunks < 1:
        raise BadInput(f"--chunks-per-call must be an integer >= 1, got {chunks!r}")
    if not isinstance(cfg.get("episode_length"), int) or cfg["episode_length"] < 1:
        raise BadInput(f"episode_length must be an integer >= 1, got {cfg.get('episode_length')!r}")
    arch = load_archive(cfg["archive"], cfg["descriptors"])
    cfg = with_protocol(cfg, arch)
    config = curriculum_config(cfg)
    try:
        policy = W.load_policy(cfg.get("policy"))
    except ValueError as err:
        raise BadInput(f"--policy: {err}") from None
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
    """The carried state without the envs' physics (restarted at every block)."""
    return states._replace(policy=states.policy._replace(env_state=None))


FAST_COMPILE = {"xla_backend_optimization_level": 0, "xla_llvm_disable_expensive_passes": True,
                "xla_cpu_use_fusion_emitters": False}


def compiled(fn, fast: bool, *args):
    """``jax.jit(fn)`` compiled for ``args``; with ``fast`` (the CPU smoke preset) at XLA's lowest backend
    optimisation and with its classic elemental emitter instead of the fusion emitters, which compiles the walker's
    programs several times faster on a CPU."""
    import jax

    lowered = jax.jit(fn).lower(*args)
    return lowered.compile(FAST_COMPILE if fast and jax.default_backend() == "cpu" else None)


def make_block(config, harness, env_like):
    """``(states, bank, n) -> states`` (jit it): restart every trial's envs on its terrain, up to ``n`` chunks.
    ``states`` come without env states (:func:`strip_envs`); ``env_like`` gives one trial's env-state shapes."""
    import jax
    import jax.numpy as jnp

    from jaxterrain import curriculum as C

    def block(states, bank, n):
        trials = states.done.shape[0]
        zeros = jax.tree.map(jnp.zeros_like, env_like)  # vmap broadcasts (MuJoCo Warp's shared buffers stay shared)
        envs = jax.vmap(lambda _: zeros)(jnp.arange(trials))
        states = states._replace(policy=states.policy._replace(env_state=envs),
                                 restart=jnp.ones_like(states.restart))  # envs restart on the current terrains
        states = C.run_trials(states, bank, jnp.asarray(n, jnp.int32), config=config, harness=harness)
        return strip_envs(states)._replace(restart=jnp.ones_like(states.restart))  # no envs: all restart next

    return block


def chunk_metrics(states, start: int, stop: int) -> dict:
    """Per-chunk ``[stop - start]`` metrics over trials: hardest (mean, a finished trial keeps its last value),
    evaluation (mean of the trials still running), trials still running."""
    import numpy as np

    h = states.history
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


_PROGRAMS: dict = {}  # (config, ppo, walker, trials, bank shape, fast, mesh) -> (init, block, {rows: compiled block})


def inputs(cfg: dict, config, arch, policy, env):
    """What a treatment's programs start from: ``(bank, ppo, harness, start, keys, init)``: the archive's terrain
    bank, the fine-tuning PPOConfig, the walker harness, the starting policy state, the trials' keys [trials] and
    ``init(keys, bank, start)`` -> the initial trial states without env states (pure: jit or ``eval_shape`` it)."""
    import jax

    from jaxterrain import bank as B
    from jaxterrain import curriculum as C
    from jaxterrain.curriculum import walker as W

    bank = B.from_archive(arch)
    ppo = config.ppo_config(policy.config)
    harness = W.walker_harness(env, ppo, config)
    start = W.start_state(env, ppo, policy, bank.heightmaps.shape[1:])
    keys = jax.random.split(jax.random.fold_in(jax.random.key(int(cfg["seed"])), 2), int(cfg["trials"]))

    def init(k, b, s):
        return strip_envs(C.init_trials(k, b, s, config=config, harness=harness))

    return bank, ppo, harness, start, keys, init


def setup(cfg: dict, config, arch, policy, env, mesh=None):
    """Bank, the block ``run(states, bank, n) -> states`` and the initial (stripped) trial states. ``run`` computes
    the running trials only when ``cfg["compact"]`` (``curriculum.run_live``; default on) and compiles the block
    once per trial count it meets (every trial's here, fewer at the first call that needs them); compiled programs
    are reused by later treatments with the same settings and bank shape (``experiments curriculum``). ``mesh``:
    the trials split over its devices (``sharding.map_rows``: padded, the bank replicated)."""
    import jax

    from jaxterrain import curriculum as C

    bank, ppo, harness, start, keys, init_fn = inputs(cfg, config, arch, policy, env)
    fast = bool(cfg.get("fast_compile", False))
    sig = (config, ppo, env.config, int(cfg["trials"]), tuple(bank.heightmaps.shape), fast, mesh)
    if sig not in _PROGRAMS:
        _PROGRAMS[sig] = (compiled(init_fn, fast, keys, bank, start), make_block(config, harness, start.env_state),
                          {})
    init, block, blocks = _PROGRAMS[sig]  # blocks: trial count -> the block compiled for it
    states = init(keys, bank, start)
    if mesh is not None:  # the trials split over the devices; inputs whole on the mesh (whence the init's)
        from jaxterrain import sharding

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
    return bank, (functools.partial(C.run_live, rows_block) if compact else rows_block), states


def run_treatment(cfg: dict, folder: Path, time_limit_s: float | None = None, desc: str = "",
                  mesh=None) -> dict | None:
    """Run (or continue) one treatment in ``folder``; its summary dict when finished, None when the time limit
    stopped it (checkpointed; call again to continue). ``time_limit_s`` counts from this call, its set-up and
    compilation included. Raises :class:`BadInput` before compiling anything."""
    import numpy as np

    from jaxterrain import driver

    folder = Path(folder)
    if (folder / "summary.json").exists():
        return json.loads((folder / "summary.json").read_text())
    config, arch, policy, env = validate(cfg)
    digest = check_resumable(folder, cfg, arch)
    t0 = time.perf_counter()
    bank, block, states = setup(cfg, config, arch, policy, env, mesh)
    restored = driver.restore(folder, like=states)
    done, history, before = 0, None, 0.0  # before: wall seconds of the commands that ran it so far
    if restored is not None:
        states, done, history, saved = restored
        before = float(saved.get("wall_s", 0.0))
        print(f"resuming at chunk {done} of {config.max_chunks} ({before / 60:.1f} min of wall time so far)",
              flush=True)

    def chunk_fn(s, a, b):
        if not bool(np.all(np.asarray(s.done))):
            s = block(s, bank, b - a)
        return s, chunk_metrics(s, a, b)

    states, done, _ = driver.run_chunks(
        chunk_fn, states, total=config.max_chunks, every=int(cfg["chunks_per_call"]), start=done, history=history,
        run_dir=folder, key_metric="hardest", desc=desc or cfg["curriculum"],
        time_limit_s=None if time_limit_s is None else max(time_limit_s - (time.perf_counter() - t0), 1e-3),
        unit="chunk", meta={"config": cfg, "archive_sha256": digest, "backend": physics_of(cfg)},
        wall_s=before + time.perf_counter() - t0)
    if done < config.max_chunks and not bool(np.all(np.asarray(states.done))):
        return None
    return write_outputs(folder, cfg, config, bank, states, seconds=before + time.perf_counter() - t0,
                         names=arch.generator_names)


PARTIAL = "summary_partial.json"


def report_cfg(cfg: dict) -> dict:
    """``cfg`` as :func:`report_treatment` validates it: on the MJX-JAX backend, which every machine has."""
    return {**cfg, "backend": "jax"}


def report_treatment(cfg: dict, folder: Path) -> dict | None:
    """The outputs of a treatment as it stands, without training: a finished one's summary; for one with a
    checkpoint, its history / sequences / milestones / curve as of that checkpoint and ``summary_partial.json``
    (the summary with ``"partial": true`` and ``"chunks_done"``; ``summary.json`` stays the mark of a finished run,
    so ``--resume`` still continues it); None without a checkpoint. Compiles nothing: the checkpoint is read into
    the shapes of the initial states (``jax.eval_shape``). Steps no physics either, so a run of any backend is
    reported through the MJX-JAX layout (a Warp run's states have its shapes): a GPU run reads on a laptop without
    MuJoCo Warp."""
    import jax
    import jax.numpy as jnp

    from jaxterrain import driver

    folder = Path(folder)
    if (folder / "summary.json").exists():
        return json.loads((folder / "summary.json").read_text())
    if not (folder / driver.CHECKPOINT_NAME).exists():
        return None
    config, arch, policy, env = validate(report_cfg(cfg))
    check_resumable(folder, cfg, arch, physics=False)
    bank, _, _, start, keys, init = inputs(cfg, config, arch, policy, env)
    shapes = jax.eval_shape(init, keys, bank, start)

    def zeros(spec):
        if jnp.issubdtype(spec.dtype, jax.dtypes.prng_key):
            data = jax.eval_shape(jax.random.key_data, spec)
            return jax.random.wrap_key_data(jnp.zeros(data.shape, data.dtype))
        return jnp.zeros(spec.shape, spec.dtype)

    states, done, _, saved = driver.restore(folder, like=jax.tree.map(zeros, shapes))
    return write_outputs(folder, cfg, config, bank, states, seconds=saved.get("wall_s"), chunks_done=done,
                         names=arch.generator_names)


# ----------------------------------------------------------------------------------------------------------------
# Outputs
# ----------------------------------------------------------------------------------------------------------------
def _csv(path: Path, header: list, rows: list) -> None:
    from jaxterrain.io import atomic_write_text

    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(header)
    w.writerows(rows)
    atomic_write_text(path, buf.getvalue())


def histories(states) -> dict:
    """Host numpy history arrays [T, C] of the trial states."""
    import numpy as np

    h = states.history
    return {"epoch": np.asarray(h.epoch), "terrain": np.asarray(h.terrain),
            "evaluation": np.asarray(h.evaluation, np.float64), "hardest": np.asarray(h.hardest, np.float64)}


SEQUENCE_COLUMNS = ("trial", "order", "terrain", "cell", "bin0", "bin1", "distance", "prior", "chunks",
                    "final_evaluation", "best_evaluation", "reached", "end_epoch", "generator")
"""The columns of ``sequences.csv`` (:func:`sequence_rows`)."""


def sequence_rows(hist: dict, bank, config, names: tuple = ()) -> list:
    """``sequences.csv`` rows: trial, order, terrain, cell, bin0, bin1, distance, prior, chunks, final and best
    evaluation, reached (the threshold), end epoch, generator (``names[bank.source[terrain]]``; the id where
    ``names`` lacks it)."""
    import numpy as np

    from jaxterrain.curriculum import terrain_runs

    cell, bins, source = np.asarray(bank.cell), np.asarray(bank.bins), np.asarray(bank.source)
    dist, prior = np.asarray(bank.distance), np.asarray(bank.fitness)
    name = lambda k: names[source[k]] if 0 <= source[k] < len(names) else str(int(source[k]))  # noqa: E731
    rows = []
    for t in range(hist["terrain"].shape[0]):
        for i, r in enumerate(terrain_runs(hist["terrain"][t], hist["evaluation"][t], hist["epoch"][t])):
            k = r["terrain"]
            rows.append([t, i, k, int(cell[k]), int(bins[k, 0]), int(bins[k, 1]), f"{dist[k]:.3f}", f"{prior[k]:.4f}",
                         r["chunks"], f"{r['final_evaluation']:.4f}", f"{r['best_evaluation']:.4f}",
                         int(r["best_evaluation"] >= config.threshold * config.max_fitness), r["end_epoch"], name(k)])
    return rows


def generator_counts(rows: list) -> dict:
    """Per generator, over every trial's terrain sequence (``sequence_rows``): the terrains trained, the chunks
    spent on them and the terrains finished (threshold reached) - which generators a combined archive's curriculum
    actually uses."""
    col = SEQUENCE_COLUMNS.index
    out: dict = {}
    for r in rows:
        c = out.setdefault(r[col("generator")], {"terrains": 0, "chunks": 0, "finished": 0})
        c["terrains"] += 1
        c["chunks"] += int(r[col("chunks")])
        c["finished"] += int(r[col("reached")])
    return dict(sorted(out.items()))


def milestone_rows(label: str, hist: dict) -> tuple[list, list]:
    """Table 2 row of one treatment: (CSV row with mean epochs and counts, Markdown cells)."""
    from jaxterrain.curriculum import MILESTONES, first_epochs, format_milestone, milestone_summary

    trials = hist["epoch"].shape[0]
    mean, reached = milestone_summary(first_epochs(hist["epoch"], hist["hardest"]))
    cells = [format_milestone(m, r, trials) for m, r in zip(mean, reached)]
    csv_row = [label] + [("" if r == 0 else f"{m:.1f}") for m, r in zip(mean, reached)] + [int(r) for r in reached]
    assert len(cells) == len(MILESTONES)
    return csv_row, cells


def summary_curve(summary: dict) -> tuple:
    """(epoch, mean, se), each [K] float: a treatment's hardest-terrain curve from its ``summary.json`` dict, in the
    form :func:`plot_curves` takes."""
    import numpy as np

    return tuple(np.asarray(summary["curve"][k], float) for k in ("epoch", "mean", "se"))


def plot_curves(ax, curves: dict, title: str = "") -> None:
    """Figure 7 style: hardest terrain traversed (cells) vs epoch, mean +- 1 standard error, one line per label."""
    from jaxterrain.bank import MAX_DISTANCE_50

    for label, (grid, mean, se) in curves.items():
        ax.step(grid, mean, where="post", label=label)
        ax.fill_between(grid, mean - se, mean + se, step="post", alpha=0.25)
    ax.set_xlabel("epoch")
    ax.set_ylabel("hardest terrain traversed (cells from (0, 0))")
    ax.set_ylim(0, MAX_DISTANCE_50)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7)


def write_outputs(folder: Path, cfg: dict, config, bank, states, seconds: float | None,
                  chunks_done: int | None = None, names: tuple = ()) -> dict:
    """history.csv, sequences.csv, milestones.csv/.md, curve.png and summary.json; returns the summary. With
    ``chunks_done`` (an unfinished run's last checkpoint, :func:`report_treatment`) the summary goes to
    ``summary_partial.json`` with ``"partial": true`` and ``"chunks_done"``, and the curve's title says so; without
    it, ``summary.json``, and a ``summary_partial.json`` left by an earlier report is removed. ``seconds``: the wall
    time of every command that ran the treatment, summed over resumes (each from its set-up and compilation on; the
    interpreter's start-up and imports are not in it), None where unknown. ``names``: the archive's generator names
    (``sequences.csv``'s ``generator`` column, the summary's ``generators``: :func:`generator_counts`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from jaxterrain.curriculum import MILESTONES, hardest_curve

    hist = histories(states)
    cell, bins, dist = np.asarray(bank.cell), np.asarray(bank.bins), np.asarray(bank.distance)
    rows = []
    for t in range(hist["epoch"].shape[0]):
        for c in np.flatnonzero(hist["epoch"][t] >= 0):
            k = int(hist["terrain"][t, c])
            rows.append([t, c, int(hist["epoch"][t, c]), int(hist["epoch"][t, c]) * config.steps_per_epoch, k,
                         int(cell[k]), int(bins[k, 0]), int(bins[k, 1]), f"{dist[k]:.3f}",
                         f"{hist['evaluation'][t, c]:.4f}", f"{hist['hardest'][t, c]:.3f}"])
    _csv(folder / "history.csv", ["trial", "chunk", "epoch", "env_steps", "terrain", "cell", "bin0", "bin1",
                                  "distance", "evaluation", "hardest"], rows)
    sequences = sequence_rows(hist, bank, config, names)
    _csv(folder / "sequences.csv", list(SEQUENCE_COLUMNS), sequences)
    label = f"{Path(cfg['archive']).stem} {cfg['curriculum']}"
    pct = [f"{round(100 * m)}%" for m in MILESTONES]
    csv_row, cells = milestone_rows(label, hist)
    _csv(folder / "milestones.csv", ["treatment"] + [f"epochs_{p}" for p in pct] + [f"trials_{p}" for p in pct],
         [csv_row])
    from jaxterrain.io import atomic_write_text

    atomic_write_text(folder / "milestones.md", "| treatment | " + " | ".join(pct) + " |\n|---|" + "---|" * len(pct)
                      + f"\n| {label} | " + " | ".join(cells) + " |\n")
    grid, mean, se = hardest_curve(hist["epoch"], hist["hardest"])
    fig, ax = plt.subplots(figsize=(6, 3.5))
    upto = "" if chunks_done is None else f", partial: {chunks_done} of {config.max_chunks} chunks"
    plot_curves(ax, {label: (grid, mean, se)}, f"{label}: {hist['epoch'].shape[0]} trials{upto}, mean +- 1 s.e.")
    fig.tight_layout()
    common.save_figure(fig, folder / "curve.png")
    final = np.asarray(states.hardest, np.float64)
    summary = {
        "label": label, "trials": int(final.size), "hardest": final.tolist(), "hardest_mean": float(final.mean()),
        "hardest_se": float(final.std(ddof=1) / np.sqrt(final.size)) if final.size > 1 else 0.0,
        "epochs": np.asarray(states.epoch).tolist(), "epochs_max": int(np.max(np.asarray(states.epoch))),
        "terrains_finished": np.asarray(states.obs_count).tolist(),
        "ended_without_terrains": [bool(d and e < config.max_epochs)
                                   for d, e in zip(np.asarray(states.done), np.asarray(states.epoch))],
        "milestones": dict(zip(pct, cells)), "seconds": seconds, "bank_terrains": int(bank.size),
        "generators": generator_counts(sequences),
        "milestone_epochs": [None if v == "" else float(v) for v in csv_row[1:1 + len(pct)]],
        "milestone_trials": csv_row[1 + len(pct):],
        "curve": {"epoch": grid.tolist(), "mean": mean.tolist(), "se": se.tolist()},
    }
    if chunks_done is not None:
        summary.update(partial=True, chunks_done=int(chunks_done))
    atomic_write_text(folder / ("summary.json" if chunks_done is None else PARTIAL), json.dumps(summary, indent=2)
                      + "\n")
    if chunks_done is None:  # finished: an earlier --report's partial summary is out of date
        (folder / PARTIAL).unlink(missing_ok=True)
    return summary


def main(args) -> int:
    if args.report and args.resume is None:
        raise common.UsageError("--report needs --resume RUN (the run to report on)")
    mesh = common.device_mesh(args.devices)
    folder, cfg = common.setup_run("learn", args, PRESETS, "smoke", overrides(args))
    try:  # cheap: files and values, before the run folder fills up or anything compiles
        check_resumable(folder, cfg, validate(report_cfg(cfg) if args.report else cfg)[1], physics=not args.report)
    except BadInput as err:
        print(f"learn: {err}", file=sys.stderr)
        if args.resume is None and {p.name for p in folder.iterdir()} <= {common.CONFIG_NAME,
                                                                          common.PROVENANCE_NAME}:
            shutil.rmtree(folder)
        return 2
    if args.report:
        summary = report_treatment(cfg, folder)
        if summary is None:
            print(f"learn: {folder} has no checkpoint yet: nothing to report", file=sys.stderr)
            return 2
        state = f"partial, {summary['chunks_done']} chunks" if summary.get("partial") else "finished"
        print(f"report ({state}): hardest traversed {summary['hardest_mean']:.2f} +- {summary['hardest_se']:.2f} "
              f"cells -> {folder}", flush=True)
        return 0
    limit = None if args.time_limit is None else 60.0 * args.time_limit
    summary = run_treatment(cfg, folder, limit, mesh=mesh)
    if summary is None:
        print(f"time limit reached; continue with: python -m experiments learn --resume {folder}", flush=True)
        return 3
    print(f"done: hardest traversed {summary['hardest_mean']:.2f} +- {summary['hardest_se']:.2f} cells "
          f"(of 70.71) after {summary['epochs_max']} epochs -> {folder}", flush=True)
    return 0

"""An ``evaluate`` run as one call: an :class:`~jaxterrain.suite.run_config.EvaluateRun` validated once, the base
policy and every policy folder walked on the same terrains with the same key, the tables written.

    from jaxterrain.suite import run_config as R, runs
    run = R.PRESETS["smoke"]._replace(policies=("runs/learn/policies/trial_0",))
    ready = runs.validate_evaluate(run)          # ValueError naming EvaluateRun.<path>; the policies loaded
    result = runs.evaluate_run(ready, "runs/eval")
    result.fitness                                # [P, N]: the base policy (its keys), then each policy

Writes into the folder: ``fitness.csv``, ``levels.csv``, ``summary.md``, ``levels.png``, ``suite.png``
(:func:`jaxterrain.suite.write_evaluation`) and ``timing.json`` (seconds, backend, device, the walkers' ``spawn``
rule; on MuJoCo Warp also ``warp_hfield``, its heightfield collision: ``jaxterrain.runtime.provenance.warp_hfield``);
``videos=`` (e.g.
``jaxterrain.report.compare.evaluation_videos``) adds the run's videos when ``run.videos.on``.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
import warnings
from pathlib import Path
from typing import Callable, NamedTuple, Optional

import jax
import numpy as np

from jaxterrain import difficulty
from jaxterrain.qd import load as load_archive
from jaxterrain.rl import load_policy
from jaxterrain.runtime import provenance, schema
from jaxterrain.runtime.estimates import compiling
from jaxterrain.runtime.io import atomic_save_npz, atomic_write_text
from jaxterrain.suite.evaluation import check_policies, evaluate_policies
from jaxterrain.suite.families import FAMILIES
from jaxterrain.suite.folder import TERRAIN_SIDE, folder_suite, load_folder
from jaxterrain.suite.heldout import LEVELS, VERSIONS, Suite, archive_suite, load
from jaxterrain.suite.outputs import write_evaluation
from jaxterrain.suite.run_config import RULES, EvaluateRun
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker import (WalkerConfig, min_terrain_side, parse_randomisation, randomisation_label,
                               resolve_backend, robots)

__all__ = ["MUJOCO_STEPS_PER_CORE_S", "MUJOCO_MAX_HOURS", "TerrainError", "Prepared", "EvaluationResult", "base_names",
           "is_base", "parse_picks", "load_policies", "terrains_of", "fit_size", "mujoco_workers", "check_physics",
           "video_picks", "check_video_format", "validate_evaluate", "PROGRESS", "evaluate_run"]

MUJOCO_STEPS_PER_CORE_S = 1000
"""MuJoCo C humanoid env steps per second per core, measured (``docs/results/sim2sim.md``)."""
MUJOCO_MAX_HOURS = 24.0
"""``engine`` ``mujoco`` refuses evaluations whose walks could take longer than this."""
_OWNER = "EvaluateRun"


class TerrainError(ValueError):
    """The terrains of a run cannot be built (e.g. a size that holds none of its families): one line naming the
    field, raised by :func:`terrains_of`, so also by :func:`evaluate_run`, which builds them when it walks."""


class Prepared(NamedTuple):
    """A validated evaluation (:func:`validate_evaluate`): the run (its ``terrains.size`` raised where asked), the
    policies loaded (the base policy first) and the terrains where validation built them (None: built when walked)."""

    run: EvaluateRun
    policies: list
    suite: Optional[Suite]


class EvaluationResult(NamedTuple):
    """What :func:`evaluate_run` made: the rows' ``names`` (``base``, its extra keys, the policy folders), the
    ``policies``, the ``suite`` walked, ``fitness`` [P, N] and ``timing`` (``timing.json``'s content)."""

    names: list
    policies: list
    suite: Suite
    fitness: np.ndarray
    timing: dict


def base_names(keys: int) -> list[str]:
    """The ``fitness.csv`` names of the base policy's ``keys`` evaluations: ``base`` (the key every policy walks
    with), then ``base:key1`` .. ``base:key{keys-1}`` (``jax.random.fold_in`` of that key by 1 .. keys-1)."""
    return ["base"] + [f"base:key{k}" for k in range(1, keys)]


def is_base(name: str) -> bool:
    """Whether a ``fitness.csv`` policy name is one of the base policy's evaluations (:func:`base_names`)."""
    return name == "base" or (name.startswith("base:key") and name[8:].isdigit())


def parse_picks(text: str) -> list[tuple[str, int]]:
    """``"FAMILY:LEVEL,FAMILY:LEVEL,..."`` as ``[(family, level)]`` (a family may hold a colon itself:
    ``gen:perlin:3``); ValueError saying the format for an empty item, a missing colon or a level that is not an
    integer >= 0."""
    out = []
    for item in str(text).split(","):
        name, sep, lv = item.strip().rpartition(":")
        if not sep or not name or not lv.strip().isdigit():
            raise ValueError(f"terrains must be FAMILY:LEVEL[,FAMILY:LEVEL...] with LEVEL an integer >= 0 (e.g. "
                             f"slope_up:5,gen:perlin:3); got {item.strip()!r} in {text!r}")
        out.append((name, int(lv)))
    return out


def load_policies(run: EvaluateRun) -> list:
    """The base policy of ``run.base`` (the robot's, default the humanoid's; its blind or perceptive one) and every
    folder of ``run.policies``, loaded; ``ValueError`` naming the field for a folder that does not load or a robot
    without a shipped base policy."""
    robot, observation = run.base.robot, run.base.observation
    try:
        out = [difficulty.robot_base_policy("humanoid" if robot is None else robot, observation or "blind")]
    except ValueError as err:
        raise ValueError(f"{_OWNER}.base.{'observation' if observation else 'robot'}: {err}") from None
    for p in run.policies:
        try:
            out.append(load_policy(p))
        except (OSError, ValueError) as err:
            raise ValueError(f"{_OWNER}.policies {p}: {str(err).splitlines()[0]}") from None
    return out


def _folder_suite(t) -> Suite:
    """``terrains.folder`` as a suite, one family per file; ``ValueError`` naming the field."""
    try:
        return folder_suite(load_folder(t.folder, t.height, t.size or TERRAIN_SIDE))  # else the curriculum's 256
    except ValueError as err:
        msg = str(err).replace("give a terrain height M", f"give {_OWNER}.terrains.height M")
        if msg.startswith("terrain height"):
            raise ValueError(f"{_OWNER}.terrains.height{msg[len('terrain height'):]}") from None
        if msg.startswith("terrains "):
            raise ValueError(f"{_OWNER}.terrains.folder{msg[len('terrains'):]}") from None
        raise ValueError(f"{_OWNER}.terrains.folder: {msg}") from None


def terrains_of(run: EvaluateRun) -> Suite:
    """What ``run`` walks: the folder's terrains, the archive's elites as a one-family suite, or the suite version
    built at the run's size, seeds, samples, families and generators; :class:`TerrainError` naming the field."""
    t = run.terrains
    try:
        if t.folder:
            return _folder_suite(t)
        if t.archive:
            try:
                return archive_suite(load_archive(t.archive))
            except (OSError, ValueError) as err:
                raise ValueError(f"{_OWNER}.terrains.archive {t.archive}: {str(err).splitlines()[0]}") from None
        try:
            robot = None if VERSIONS[t.suite]["robot"] is None else (run.base.robot or "humanoid")
            return load(t.suite, robot=robot, size=t.size, seeds=t.seeds, samples=t.samples, families=t.families,
                        generator_names=t.generators)
        except ValueError as err:
            raise ValueError(f"{_OWNER}.terrains.{err}") from None
    except ValueError as err:
        raise TerrainError(str(err)) from None


def _check_terrains(run: EvaluateRun) -> None:
    """The suite version and families known, a size of >= 32 pixels, an archive that reads, a folder (not with an
    archive) whose files read, a height only with a folder; ``ValueError`` naming the field."""
    t = run.terrains
    if t.suite not in VERSIONS:
        raise ValueError(f"{_OWNER}.terrains.suite must be one of {', '.join(VERSIONS)}; got {t.suite!r}")
    unknown = [f for f in t.families or () if f not in FAMILIES]
    if unknown:
        raise ValueError(f"{_OWNER}.terrains.families: unknown {', '.join(map(repr, unknown))}; choose from "
                         f"{', '.join(FAMILIES)}")
    if t.size is not None and t.size < 32:
        raise ValueError(f"{_OWNER}.terrains.size must be an integer >= 32 pixels; got {t.size}")
    if t.archive and not Path(t.archive).is_file():
        raise ValueError(f"{_OWNER}.terrains.archive {t.archive}: no such file")
    if t.archive:
        try:
            load_archive(t.archive)
        except (OSError, ValueError) as err:
            raise ValueError(f"{_OWNER}.terrains.archive {t.archive}: {str(err).splitlines()[0]}") from None
    if t.folder and t.archive:
        raise ValueError(f"{_OWNER}.terrains.folder (a folder of heightmaps) is walked instead of "
                         f"{_OWNER}.terrains.archive: give one")
    if t.height is not None and not t.folder:
        raise ValueError(f"{_OWNER}.terrains.height applies to {_OWNER}.terrains.folder (a folder of heightmaps), "
                         f"which is not given")
    if t.folder:
        _folder_suite(t)


def fit_size(run: EvaluateRun, policies, raise_size: bool = False,
             note: Callable[[str], None] = print) -> tuple[EvaluateRun, int]:
    """A terrain side every policy's robot can walk (``walker.min_terrain_side``): a ``terrains.size`` below it is
    refused (``ValueError`` naming it) or, with ``raise_size`` (a preset's size, not the user's), raised to the next
    multiple of 32 that fits (``note`` says so). Returns the run and a side the policies can be checked on: the
    size, or the robots' minimum where the suite's own size (None) or an archive's terrains are walked."""
    size = run.terrains.size
    names = sorted({difficulty.policy_robot(p) for p in policies})
    need = max(min_terrain_side(WalkerConfig(robot=r)) for r in names)
    if size is None or run.terrains.archive:
        return run, need
    if size >= need:
        return run, size
    if not raise_size:
        raise ValueError(f"{_OWNER}.terrains.size must be >= {need} pixels for robot {', '.join(names)} (its episode "
                         f"margins at 4 cm a pixel); got {size}")
    side = -(-need // 32) * 32
    note(f"evaluate: {_OWNER}.terrains.size {side} (the {run.preset or 'smoke'} preset's {size} pixels are too small "
         f"for robot {', '.join(names)})")
    return schema.replace(run, {"terrains.size": side}), side


def mujoco_workers(run: EvaluateRun) -> int:
    """The CPU processes of engine ``mujoco``: ``physics.workers``, else every core."""
    return int(run.physics.workers or os.cpu_count() or 1)


def check_physics(run: EvaluateRun) -> None:
    """The fields that do not apply to the engine: ``mujoco`` with the ``warp`` backend, MJX's ``slots`` / ``chunk``
    or a randomisation; ``workers`` with MJX. The randomisation spec parsed. ``ValueError`` naming the field."""
    p, o = run.physics, _OWNER
    if p.engine == "mujoco":
        if p.backend == "warp":
            raise ValueError(f"{o}.physics.backend warp is an MJX backend; {o}.physics.engine mujoco steps MuJoCo's C "
                             f"engine on the CPU (drop {o}.physics.backend)")
        for field in ("slots", "chunk"):
            if getattr(p, field) is not None:
                raise ValueError(f"{o}.physics.{field} batches MJX's walks; {o}.physics.engine mujoco walks on CPU "
                                 f"processes ({o}.physics.workers)")
        if p.randomise is not None:
            raise ValueError(f"{o}.physics.randomise randomises MJX's walks; {o}.physics.engine mujoco walks the "
                             "nominal physics")
    elif p.workers is not None:
        raise ValueError(f"{o}.physics.workers sets the CPU processes of {o}.physics.engine mujoco; MJX walks on the "
                         "accelerator")
    try:
        parse_randomisation(p.randomise)
    except ValueError as err:
        raise ValueError(f"{o}.physics.randomise: {err}") from None
    if run.videos.on and p.spawn != "feet":
        raise ValueError(f"{o}.videos.on sets the walkers down by the default spawn rule (feet); evaluate with "
                         f"{o}.physics.spawn {p.spawn} without {o}.videos.on")
    if run.videos.on and p.randomise is not None:
        raise ValueError(f"{o}.videos.on draws the walks under the nominal physics; evaluate with "
                         f"{o}.physics.randomise without {o}.videos.on (and the videos in a run without it)")


def video_picks(run: EvaluateRun) -> Optional[list]:
    """The ``(family, level)`` pairs of ``videos.terrains`` (None: the default picks); ``ValueError`` naming the
    field for a malformed list, a family this evaluation does not walk, a level the family lacks or terrains
    without ``videos.on``."""
    v, t, o = run.videos, run.terrains, _OWNER
    if v.terrains is None:
        return None
    if not v.on:
        raise ValueError(f"{o}.videos.terrains chooses the terrains of {o}.videos.on, which is off: give "
                         f"{o}.videos.on too")
    try:
        picks = parse_picks(v.terrains)
    except ValueError as err:
        raise ValueError(f"{o}.videos.{err}") from None
    if t.archive:
        levels = {"archive": LEVELS}
    elif t.folder:
        levels = {name: 1 for name in _folder_suite(t).family}
    else:
        fams = t.families or VERSIONS[t.suite]["families"]
        gens = VERSIONS[t.suite]["generators"] if t.generators is None else t.generators
        levels = {**{f: FAMILIES[f].levels for f in fams}, **{f"gen:{g}": LEVELS for g in gens}}
    for fam, lv in picks:
        if fam not in levels:
            raise ValueError(f"{o}.videos.terrains: family {fam!r} is not walked here; choose from "
                             f"{', '.join(levels)}")
        if lv >= levels[fam]:
            raise ValueError(f"{o}.videos.terrains: {fam} has levels 0 to {levels[fam] - 1}; got {lv}")
    return picks


def check_video_format(run: EvaluateRun) -> None:
    """``videos.format`` (checked against ``VIDEO_FORMATS`` by ``RULES``) applies: ``mp4`` / ``both`` only with
    ``videos.on`` (else it would be ignored), and only where ``imageio-ffmpeg`` (the optional extra
    ``jaxterrain[video]``, the MP4 writer of ``report.encode.mp4_bytes``) imports and finds its ffmpeg binary.
    ``ValueError`` naming the field, in one line (imageio-ffmpeg runs ``ffmpeg -version`` once to find it)."""
    v, o = run.videos, _OWNER
    if v.format == "gif":
        return
    if not v.on:
        raise ValueError(f"{o}.videos.format chooses the files of {o}.videos.on, which is off: give {o}.videos.on "
                         "too")
    try:
        import imageio_ffmpeg

        with warnings.catch_warnings():  # JAX's warning of os.fork(): the child process execs ffmpeg at once
            warnings.filterwarnings("ignore", message=r"os\.fork\(\) was called", category=RuntimeWarning)
            imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError) as err:
        why = "is not installed" if isinstance(err, ImportError) else "finds no ffmpeg binary"
        raise ValueError(f"{o}.videos.format {v.format} writes MP4 with imageio-ffmpeg, which {why}: "
                         "pip install 'jaxterrain[video]'") from None


def validate_evaluate(run: EvaluateRun, raise_size: bool = False,
                      note: Callable[[str], None] = print) -> Prepared:
    """Check ``run`` once, before anything compiles (module docstring): its fields (``run_config.RULES``), the
    engine's fields (:func:`check_physics`), the video format (:func:`check_video_format`: MP4 needs the
    extra ``jaxterrain[video]``), the robot, the policies (loaded: :func:`load_policies`; each for the
    robot of a ``v2`` suite, each fitting the walker at the run's size: ``suite.check_policies``), the terrains,
    the video picks and, for ``mujoco``, the walks' cost (at most :data:`MUJOCO_MAX_HOURS`). ``raise_size``: raise a
    size too small for the robots (:func:`fit_size`). ``ValueError`` naming ``EvaluateRun.<path>``."""
    schema.check(run, RULES, _OWNER)
    check_physics(run)
    check_video_format(run)
    if run.base.robot is not None:
        try:
            robots.get(run.base.robot)
        except (TypeError, ValueError) as err:
            raise ValueError(f"{_OWNER}.base.robot: {err}") from None
    policies = load_policies(run)
    _check_terrains(run)
    t = run.terrains
    if VERSIONS[t.suite]["robot"] is not None and not (t.archive or t.folder):  # v2: levels per robot
        robot = run.base.robot or "humanoid"
        other = [str(getattr(p, "path", p)) for p in policies[1:] if difficulty.policy_robot(p) != robot]
        if other:
            raise ValueError(f"{_OWNER}.terrains.suite {t.suite} holds the levels of robot {robot} "
                             f"({_OWNER}.base.robot); these policies walk another robot: {', '.join(other)}")
    video_picks(run)
    run, side = fit_size(run, policies, raise_size, note)
    check_policies(policies, (side, side), TerrainScale())  # another robot or observation set: one line
    built = None
    if run.physics.engine == "mujoco":  # the CPU engine's cost, on the terrains
        built = terrains_of(run)
        steps = len(policies) * built.size * int(run.walks.attempts) * WalkerConfig().episode_length
        hours = steps / (MUJOCO_STEPS_PER_CORE_S * mujoco_workers(run)) / 3600
        if hours > MUJOCO_MAX_HOURS:
            raise ValueError(f"{_OWNER}.physics.engine mujoco: {len(policies)} policies x {built.size} terrains x "
                             f"{run.walks.attempts} walks could take up to {hours:.0f} h on {mujoco_workers(run)} CPU "
                             f"processes (more than {MUJOCO_MAX_HOURS:.0f} h): walk fewer terrains "
                             f"({_OWNER}.terrains.seeds, {_OWNER}.terrains.samples, {_OWNER}.terrains.families) or "
                             f"walks ({_OWNER}.walks.attempts)")
    return Prepared(run, policies, built)


PROGRESS = "walked.npz"
"""The file of an unfinished :func:`evaluate_run`: ``fitness`` [R, N] (the rows walked), ``stamp`` (JSON: the
rows' names, the suite's name and size, the seed) and, once ``repeat``'s walk is done, ``repeat`` (JSON:
``{"equal": bool, "walk_s": seconds}``), removed once the evaluation is written."""


def _load_progress(folder: Path, stamp: dict, note: Callable[[str], None]) -> tuple[list, Optional[dict]]:
    """The rows ``folder/PROGRESS`` holds when it was written for the same rows, suite and seed (``stamp``), and its
    ``repeat`` walk's result (None: not walked yet); else none (a note says why it is not used)."""
    path = folder / PROGRESS
    if not path.exists():
        return [], None
    with np.load(path) as z:
        saved, fitness = json.loads(str(z["stamp"])), np.asarray(z["fitness"])
        repeat = json.loads(str(z["repeat"])) if "repeat" in z.files else None
    if saved != stamp or fitness.ndim != 2 or fitness.shape[1] != stamp["terrains"]:
        note(f"evaluate: {path} was written for another run (policies, suite or seed differ); walking every row")
        return [], None
    return list(fitness), repeat


def evaluate_run(run: EvaluateRun | Prepared, folder, videos: Optional[Callable] = None,
                 say: Callable[[str], None] = print, note: Callable[[str], None] = print,
                 time_limit_s: Optional[float] = None) -> Optional[EvaluationResult]:
    """Walk the base policy (with ``base.keys`` keys) and every policy of ``run`` (an :class:`EvaluateRun`, validated
    here, or :func:`validate_evaluate`'s :class:`Prepared`) on its terrains with the same key and write the
    evaluation into ``folder`` (module docstring). ``videos(prepared, folder, names, suite, fitness, say, note)``:
    called when ``run.videos.on`` (``jaxterrain.report.compare.evaluation_videos``), its seconds recorded in
    ``timing.json``.
    ``say``: progress lines; ``note``: what was dropped or changed (stderr on the command line).

    Resumable: the rows walked so far (one per walk of a policy on the whole suite, the base policy's keys first) are
    kept in ``folder/walked.npz`` (:data:`PROGRESS`, written atomically after every row); a later call on the same
    folder and run walks only the rows left. ``time_limit_s``: seconds from now after which no further row starts;
    returns None when rows are left (call again to continue), so a limit is honoured to within one row. ``repeat``
    walks the first row a call walks a second time (compiled: the base policy's row), once per run: its result is
    kept in :data:`PROGRESS` for the calls after, and a call resuming a file without it (one an older version
    wrote) walks its own first row twice."""
    t0 = time.perf_counter()
    ready = run if isinstance(run, Prepared) else validate_evaluate(run, note=note)
    run, policies = ready.run, ready.policies
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    n_keys = int(run.base.keys)
    names = base_names(n_keys) + [str(p) for p in run.policies]
    s = ready.suite if ready.suite is not None else terrains_of(run)
    build_s = time.perf_counter() - t0
    protocol = difficulty.Protocol(int(run.walks.attempts), int(run.walks.best), int(run.walks.headings))
    p = run.physics
    backend = resolve_backend(p.backend) if p.engine == "mjx" else "jax"
    walk = dict(engine=p.engine, workers=mujoco_workers(run), spawn=p.spawn)
    if p.randomise is not None:
        walk["randomisation"] = parse_randomisation(p.randomise)
    for fam, why in s.dropped.items():
        note(f"evaluate: family {fam} dropped at {_OWNER}.terrains.size {run.terrains.size}: {why}")
    on = backend if p.engine == "mjx" else f"MuJoCo C ({walk['workers']} CPU processes)"
    say(f"{s.name}: {s.size} terrains, {len(s.families())} families; {len(policies)} policies on {on}, "
        f"{protocol.attempts} walks each (best {protocol.best} per heading, {protocol.headings} headings)"
        + (f", randomised physics: {randomisation_label(walk['randomisation'])}" if "randomisation" in walk else ""))
    key = jax.random.fold_in(jax.random.key(int(run.seed)), 3)

    def walked(chosen, k):
        return evaluate_policies(chosen, s.heightmaps, k, protocol, backend, s.scale, p.slots, p.chunk, **walk)

    # the rows in order: the base policy with each key (runs of the comparator), then every other policy with the
    # first key (the same compiled program, their weights as data)
    jobs = [(0, jax.random.fold_in(key, k) if k else key) for k in range(n_keys)]
    jobs += [(i, key) for i in range(1, len(policies))]
    # the rows' identity: policy folders relative to the run folder (as config.json keeps them: a resumed run's are
    # resolved from there, a fresh run's are as given)
    rows_of = [n if is_base(n) else os.path.relpath(Path(n).resolve(), folder.resolve()) for n in names]
    stamp = {"names": rows_of, "suite": s.name, "terrains": int(s.size), "seed": int(run.seed)}
    rows, done = _load_progress(folder, stamp, note)  # done: the repeat walk of an earlier call (None: not walked)
    resumed = len(rows)
    if resumed:
        say(f"resuming: {resumed} of {len(jobs)} policy rows already walked ({folder / PROGRESS})")
    t1 = time.perf_counter()
    first_s = None
    again, walk_s = (None, None) if done is None else (bool(done["equal"]), float(done["walk_s"]))
    while len(rows) < len(jobs):
        if time_limit_s is not None and rows[resumed:] and time.perf_counter() - t0 > time_limit_s:
            say(f"time limit: {len(rows)} of {len(jobs)} policy rows walked, kept in {folder / PROGRESS}")
            return None
        i, k = jobs[len(rows)]
        t2 = time.perf_counter()
        fresh = first_s is None  # this process's first walk compiles
        with (compiling("suite-walk", f"{s.size} terrains x {protocol.attempts} walks, {backend} physics") if fresh
              else contextlib.nullcontext()):
            row = walked(policies[i:i + 1], k)
        if fresh:
            first_s = time.perf_counter() - t2  # compile + one walk of the suite
            if run.repeat and again is None:  # the same walks again, compiled: one policy on the whole suite
                t3 = time.perf_counter()
                repeat = walked(policies[i:i + 1], k)
                walk_s = time.perf_counter() - t3
                again = bool((row == repeat).all())
        rows.append(row[0])
        if len(rows) < len(jobs):
            kept = {} if again is None else {"repeat": np.array(json.dumps({"equal": again, "walk_s": walk_s}))}
            atomic_save_npz(folder / PROGRESS, fitness=np.stack(rows), stamp=np.array(json.dumps(stamp)), **kept)
        say(f"walked {names[len(rows) - 1]} ({len(rows)} of {len(jobs)}) in {time.perf_counter() - t2:.1f} s")
    fitness = np.stack(rows).astype(np.float32)
    write_evaluation(folder, names, s, fitness)
    (folder / PROGRESS).unlink(missing_ok=True)
    videos_s = None
    if run.videos.on and videos is not None:
        t3 = time.perf_counter()
        videos(ready, folder, names, s, fitness, say, note)
        videos_s = round(time.perf_counter() - t3, 3)
    timing = {"suite": s.name, "terrains": s.size, "policies": len(policies), "base_keys": n_keys, "backend": backend,
              "engine": p.engine, "workers": walk["workers"] if p.engine == "mujoco" else None,
              "walks_per_terrain": protocol.attempts, "build_s": round(build_s, 3),
              "first_call_s": None if first_s is None else round(first_s, 3),
              "walk_s_one_policy": None if walk_s is None else round(walk_s, 3),
              "all_policies_s": round(time.perf_counter() - t1, 3), "rows_resumed": resumed,
              "repeat_equal": again,
              "videos_s": videos_s, "device": provenance.device(),
              **({"warp_hfield": provenance.warp_hfield()} if backend == "warp" else {}),
              "spawn": p.spawn}  # the walkers' spawn rule
    atomic_write_text(folder / "timing.json", json.dumps(timing, indent=2) + "\n")
    said = "" if walk_s is None else f", {walk_s:.1f} s compiled"
    first = "" if first_s is None else f": {first_s:.1f} s the first call{said}"
    say(f"{len(policies)} policies on {s.size} terrains{first} -> {folder}")
    return EvaluationResult(names, policies, s, fitness, timing)

"""An ``evaluate`` run (walkers on terrains they never saw) as one frozen, typed config, nested where the concepts
nest, with its presets and its serialised form.

    from jaxterrain.suite import run_config as R, runs
    run = R.PRESETS["smoke"]._replace(policies=("runs/learn/policies/trial_0",))
    result = runs.evaluate_run(run, "runs/eval")       # validates once, walks every policy, writes the tables
    flat = R.to_flat(run)                               # config.json; R.from_flat(flat) == run

The shape (each field consumed where ``docs/CONTRIBUTING.md`` says)::

    EvaluateRun
      policies                  policy folders walked beside the base policy
      base: BaseWalker          robot, observation (the base policy walked beside), keys (its evaluation keys)
      terrains: Terrains        suite (v1 / v2), archive, folder (your own heightmaps), height, size, seeds,
                                samples, families, generators: what is walked
      walks: Walks              attempts, best, headings: the protocol
      physics: Physics          engine (mjx / mujoco), backend, workers, slots, chunk, randomise, spawn
      videos: Videos            on, terrains, frames, width, height, starts, format (report.compare.write_videos)
      repeat, seed, preset      walk the base policy twice to time the compiled call; the root key; the preset

The serialised form is ``config.json``'s flat dict (:func:`to_flat` / :func:`from_flat` through :data:`FIELDS`,
``{flat key: field path}``, whose keys are the flags' names: ``terrain_folder`` and ``samples`` are ``--terrains``,
``slots`` ``--rollout-slots``). Standard library only (``jaxterrain.runtime.schema``): ``--help`` reads the presets
without importing JAX.
"""

from __future__ import annotations

from typing import NamedTuple, Optional

from jaxterrain.runtime.schema import at_least, at_most, from_flat as _from_flat, int_in, one_of, positive
from jaxterrain.runtime.schema import replace, to_flat as _to_flat, walks

__all__ = ["HELP", "BaseWalker", "Terrains", "Walks", "Physics", "Videos", "VIDEO_FORMATS", "EvaluateRun", "FIELDS", "LEGACY",
           "RULES", "PRESETS", "FLAT_PRESETS", "CONSUMERS", "from_flat", "to_flat"]


class BaseWalker(NamedTuple):
    """The base policy walked beside the policies (always, as ``base``): ``robot``'s (None: the humanoid's),
    ``observation`` ``blind`` / ``perceptive`` (None: blind), walked with ``keys`` independent evaluation keys
    (rows ``base``, ``base:key1``, ...: runs of the comparator)."""

    robot: Optional[str] = None
    observation: Optional[str] = None
    keys: int = 1


class Terrains(NamedTuple):
    """What is walked: the held-out ``suite`` (``v1``; ``v2``: levels calibrated for the base robot) built at
    ``size`` pixels (None: the version's) with ``seeds`` terrains per family level, ``samples`` of each of
    ``generators`` and the ``families`` (None: the version's); or an ``archive``'s elites; or ``folder``, your own
    heightmaps (images at ``height`` metres of full grey)."""

    suite: str = "v1"
    archive: Optional[str] = None
    folder: Optional[str] = None
    height: Optional[float] = None
    size: Optional[int] = None
    seeds: Optional[int] = None
    samples: Optional[int] = None
    families: Optional[tuple] = None
    generators: Optional[tuple] = None


class Walks(NamedTuple):
    """The protocol: ``attempts`` walks per terrain in total, the ``best`` per heading averaged over ``headings``."""

    attempts: int = 80
    best: int = 5
    headings: int = 4


class Physics(NamedTuple):
    """How the walks are computed: ``engine`` ``mjx`` (on the accelerator, ``backend`` ``auto`` / ``jax`` /
    ``warp``, a rollout pool of ``slots`` env slots, ``chunk`` terrains per call) or ``mujoco`` (MuJoCo's C engine
    on ``workers`` CPU processes, None: every core); ``randomise``: a physics randomisation spec every walk draws
    from (None: the nominal physics; MJX only); ``spawn``: how every walker is set down at a reset
    (``jaxterrain.walker.SPAWNS``: ``feet``, or ``patch`` as every evaluation before 2026-11-29)."""

    engine: str = "mjx"
    backend: str = "auto"
    workers: Optional[int] = None
    slots: Optional[int] = None
    chunk: Optional[int] = None
    randomise: Optional[str] = None
    spawn: str = "feet"


class Videos(NamedTuple):
    """``on``: videos of each walker beside the base policy after the evaluation, on ``terrains`` (``FAMILY:LEVEL,
    ...``; None: per family the hardest level passed and the first failed), at most ``frames`` frames of ``width``
    x ``height`` pixels, from the best of ``starts`` reset poses, written as ``format``: ``gif`` (Pillow), ``mp4``
    (H.264; the optional extra ``jaxterrain[video]``) or ``both``."""

    on: bool = False
    terrains: Optional[str] = None
    frames: int = 75
    width: int = 320
    height: int = 240
    starts: int = 8
    format: str = "gif"


VIDEO_FORMATS = ("gif", "mp4", "both")
"""The values of ``Videos.format``: the files each video is written as (``both``: a GIF and an MP4)."""


class EvaluateRun(NamedTuple):
    """One evaluation (the module docstring shows the shape). Frozen; ``_replace`` or ``schema.replace`` to
    change."""

    policies: tuple = ()
    base: BaseWalker = BaseWalker()
    terrains: Terrains = Terrains()
    walks: Walks = Walks()
    physics: Physics = Physics()
    videos: Videos = Videos()
    repeat: bool = True
    seed: int = 0
    preset: Optional[str] = None


FIELDS: dict[str, str] = {
    "policy": "policies", **{k: f"base.{k}" for k in BaseWalker._fields},
    "suite": "terrains.suite", "archive": "terrains.archive", "terrain_folder": "terrains.folder",
    "terrain_height": "terrains.height", **{k: f"terrains.{k}" for k in ("size", "seeds", "samples", "families",
                                                                            "generators")},
    **{k: f"walks.{k}" for k in Walks._fields}, **{k: f"physics.{k}" for k in Physics._fields},
    "videos": "videos.on", **{f"video_{k}": f"videos.{k}" for k in Videos._fields if k != "on"},
    "repeat": "repeat", "seed": "seed", "preset": "preset"}
"""``{flat key: field path}`` of :class:`EvaluateRun`: ``config.json``'s keys, which are the flags' names."""

LEGACY = {"terrain_folder": None, "terrain_height": None, "robot": None, "observation": None, "keys": 1,
          "videos": False, "video_terrains": None, "video_frames": 75, "video_width": 320, "video_height": 240,
          "video_starts": 8, "video_format": "gif", "engine": "mjx", "workers": None, "randomise": None, "seed": 0,
          "spawn": "patch"}
"""The value a ``config.json`` key had in the runs made before it was written (what :func:`from_flat` fills in)."""

RULES = {
    "base.observation": one_of(("blind", "perceptive")), "base.keys": at_least(1),
    "terrains.height": positive(), "terrains.size": at_least(1), "terrains.seeds": at_least(1),
    "terrains.samples": at_least(1), "walks.attempts": at_least(1),
    "walks.best": (at_least(1), at_most("walks.attempts")), "walks.headings": walks("walks.attempts", "walks.best"),
    "physics.engine": one_of(("mjx", "mujoco")), "physics.backend": one_of(("auto", "jax", "warp")),
    "physics.workers": at_least(1), "physics.slots": at_least(1), "physics.chunk": at_least(1),
    "physics.spawn": one_of(("feet", "patch")),
    "videos.frames": int_in(1, 4096), "videos.width": int_in(16, 4096), "videos.height": int_in(16, 4096),
    "videos.starts": int_in(1, 4096), "videos.format": one_of(VIDEO_FORMATS), "repeat": one_of((True, False)),
}
"""The checks of single fields (the rest, against the suite, the policies and the engine:
``suite.runs.validate_evaluate``)."""


def from_flat(flat: dict) -> EvaluateRun:
    """The :class:`EvaluateRun` of a flat config (``config.json``, a preset's flat form, a command line's values);
    keys of older versions' files take :data:`LEGACY`'s values; ``ValueError`` naming unknown keys."""
    return _from_flat(EvaluateRun, flat, FIELDS, LEGACY)


def to_flat(run: EvaluateRun, command: Optional[str] = None) -> dict:
    """The serialised form of ``run`` (``preset`` left out when None), with ``command`` added when given."""
    out = _to_flat(run, FIELDS, omit_none=("preset",))
    return out if command is None else {**out, "command": command}


_GPU = EvaluateRun(preset="gpu")
PRESETS: dict[str, EvaluateRun] = {
    # suite v1 at 256 x 256, 3 terrains per level, the HEADINGS protocol; the base policy walks twice (timed)
    "gpu": _GPU,
    "gpu-short": _GPU._replace(preset="gpu-short"),
    "paper": replace(_GPU, {"walks": Walks(20, 5, 1), "preset": "paper"}),
    # a CPU in minutes: three families and Perlin samples at 128 x 128, one terrain per level, 2 walks along +x
    "smoke": replace(_GPU, {"terrains.size": 128, "terrains.seeds": 1, "terrains.samples": 4,
                            "terrains.families": ("flat", "stairs_up", "gaps"), "terrains.generators": ("perlin",),
                            "walks": Walks(2, 1, 1), "physics.backend": "jax", "repeat": False, "preset": "smoke"}),
}
"""The presets, typed (``preset`` set to the name)."""

FLAT_PRESETS: dict[str, dict] = {name: {k: v for k, v in to_flat(p).items() if k not in ("preset", "seed")}
                                 for name, p in PRESETS.items()}
"""The presets in their flat form, without ``preset`` and ``seed`` (what a fresh run's ``config.json`` adds)."""

CONSUMERS = {
    "": "suite.runs.evaluate_run",
    "policies": "suite.runs.load_policies (rl.load_policy)",
    "base": "suite.runs.load_policies (difficulty.robot_base_policy), base_names",
    "terrains": "suite.runs.terrains_of (suite.load / archive_suite / folder_suite)",
    "walks": "suite.runs.evaluate_run (difficulty.Protocol)",
    "physics": "suite.runs.evaluate_run (suite.evaluate_policies)",
    "videos": "report.compare.evaluation_videos (write_videos)",
    "repeat": "suite.runs.evaluate_run (timing.json)",
    "seed": "suite.runs.evaluate_run (the walks' key)",
    "preset": "recorded",
}
"""Where each field of :class:`EvaluateRun` is consumed (``docs/CONTRIBUTING.md``; a test checks the functions)."""

HELP = {
    "policy": "policy folders to evaluate beside the base policy (e.g. RUN/policies/trial_0)",
    "keys": "walk the base policy with K independent evaluation keys (rows base, base:key1, ..., base:key{K-1}; key "
            "0 is the one every --policy walks with): generalise reads them as K runs of the comparator (give K = "
            "the treatments' trials)",
    "robot": "the base policy walked beside is this robot's shipped one (default humanoid); each --policy walks the "
             "robot it was trained on",
    "observation": "the base policy walked beside: the robot's blind one (default, the paper's) or its perceptive "
                   "twin; each --policy walks with the observation set it records",
    "suite": "held-out suite version (default v1; v2: levels calibrated for the robot of --robot)",
    "archive": "walk an archive's elites instead of the suite",
    "size": "suite heightmap side in pixels (v1: 256)",
    "seeds": "suite terrains per family level (v1: 3)",
    "samples": "terrains sampled per generator, {range}: the suite's generator terrains (v1: 96); or DIR, a folder of "
               "heightmaps: walk your own terrains instead of the suite (.png, .tif/.tiff, .npy, .npz; "
               "jaxterrain.suite.folder), one family per file",
    "terrain_height": "--terrains DIR: metres of an image's full grey (default 1.0), and the relief every metre file "
                      "is rescaled to (default: its own metres)",
    "families": "suite families to build (default: all of the version's; smoke: flat stairs_up gaps)",
    "generators": "generators to sample (default: the version's five; smoke: perlin)",
    "repeat": "walk the base policy twice and time the second, compiled call (timing.json)",
    "attempts": "walks per terrain in total",
    "best": "best walks averaged per heading",
    "headings": "walking headings",
    "backend": "walker physics: {backend}",
    "engine": "physics engine: mjx (default; MJX on the accelerator, --backend picks jax or warp) or mujoco (MuJoCo's "
              "C engine on the CPU cores, the same starts and protocol: sim2sim)",
    "workers": "--engine mujoco: CPU processes walking (default: every core)",
    "slots": "{slots}: an int (default: all walks at once)",
    "randomise": "physics randomisation of every walk (a randomised protocol: every policy, the base policy included, "
                 "meets the same draws; default: the nominal physics; MJX only) {randomise}",
    "chunk": "terrains per call (bounds device memory)",
    "spawn": "how every walker is set down at a reset: feet (default: the body lifted until every foot clears the "
             "terrain under it) or patch (only the lowest foot clear of a 0.5 m patch under the torso: every "
             "evaluation before 2026-11-29, which cut the ant's feet into rising ground)",
    "videos": "after the evaluation, videos of each --policy walker beside the base policy (the base policy alone "
              "without --policy) on chosen terrains, one walk along +x each from the same start (of --video-starts), "
              "into videos/<walker>/<family>_L<level>.gif (or .mp4: --video-format) with videos/videos.csv; needs an "
              "OpenGL backend for MuJoCo's renderer (without one: a line saying why, the evaluation is still "
              "written)",
    "video_terrains": "terrains of the videos, e.g. slope_up:5,gen:perlin:3 (each level's seed-0 terrain); default: "
                      "per family the hardest level the walker passes and the first it fails",
    "video_frames": "most frames per video, evenly spaced over the longer walk, played at 15 a second (a walk "
                    "shorter than frames / 15 s gets fewer and plays in real time)",
    "video_starts": "reset poses each policy walks every video terrain from; the video shows the one the walker went "
                    "farthest from, the base policy from the same one",
    "video_width": "pixels of each panel's width",
    "video_height": "pixels of each panel's height",
    "video_format": "files of each video: gif (Pillow), mp4 (H.264, 12 times smaller than the GIF on a 47-frame video "
                    "of two walkers; needs pip install 'jaxterrain[video]') or both",
}
"""``evaluate``'s flags: each flat key's help, the field's documentation as the command line's ``--help`` shows it
(``experiments.cli_gen`` adds the type, the choices, the allowed range of the field's rule where the text says
``{range}`` or at its end, and every preset's value; ``{backend}``, ``{randomise}`` and ``{slots}`` are
phrases every command shares, ``experiments.common.PHRASES``). The keys are the flags the command exposes, in
``--help``'s order."""

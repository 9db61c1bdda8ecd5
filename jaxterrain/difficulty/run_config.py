"""A ``train-base-policy`` run (the flat-ground walker whose walks define difficulty) as one frozen, typed config,
nested where the concepts nest, with its presets and its serialised form.

    from jaxterrain.difficulty import base_policy, run_config as R
    run = R.PRESETS["smoke"]
    result = base_policy.train_base_policy(run, "runs/walker")     # validates once, trains, evaluates
    flat = R.to_flat(run)                                          # config.json; R.from_flat(flat) == run

The shape (each field consumed where ``docs/CONTRIBUTING.md`` says)::

    BasePolicyRun
      walker: BaseWalker        robot, observation, scan_noise, randomise, solver, spawn (the trained walker's env)
      ppo: PPOSettings          num_envs (None: the preset's PPOConfig's)
      schedule: Schedule        env_steps, updates_per_chunk, time_budget (seconds; runs before --time-limit)
      evaluation: FlatEvaluation  attempts, best (the flat-ground check of the trained walker)
      seed, preset              the root key; the preset, whose walker and PPO shapes the run trains
                                (``base_policy.shapes``: ``smoke`` a tiny one, the others brax's recipe)

The serialised form is ``config.json``'s flat dict (:func:`to_flat` / :func:`from_flat` through :data:`FIELDS`,
``{flat key: field path}``, whose keys are the flags' names); :data:`EXTENDABLE` are the keys a resumed run may
change. Standard library only (``jaxterrain.runtime.schema``): ``--help`` reads the presets without importing JAX.
"""

from __future__ import annotations

from typing import NamedTuple, Optional

from jaxterrain.runtime.schema import at_least, at_most, from_flat as _from_flat, non_negative, one_of, positive
from jaxterrain.runtime.schema import replace, to_flat as _to_flat

__all__ = ["HELP", "BaseWalker", "PPOSettings", "Schedule", "FlatEvaluation", "BasePolicyRun", "FIELDS", "LEGACY",
           "SPAWNS", "RULES", "EXTENDABLE", "PRESETS", "FLAT_PRESETS", "CONSUMERS", "from_flat", "to_flat"]


class BaseWalker(NamedTuple):
    """The walker trained: ``robot`` (``walker.robots``), ``observation`` (``blind`` / ``perceptive``: a height
    scan, its heights with Gaussian noise of std ``scan_noise`` metres), ``randomise`` (a physics randomisation
    spec, ``walker.parse_randomisation``; None: off) and the contact ``solver`` (``walker.parse_solver``: ``sound``,
    ``fast``, ``xml`` or ``ITERATIONS,LS_ITERATIONS,EULERDAMP``; None: sound) and the ``spawn`` rule that sets
    the walker down at a reset (``walker.SPAWNS``: ``feet``, or ``patch`` as every run before 2026-11-29; on the
    flat ground it trains on both set it down at the same height), all recorded with the policy."""

    robot: str = "humanoid"
    observation: str = "blind"
    scan_noise: float = 0.0
    randomise: Optional[str] = None
    solver: Optional[str] = None
    spawn: str = "feet"


class PPOSettings(NamedTuple):
    """The preset's ``PPOConfig`` changed: ``num_envs`` (None: the preset's)."""

    num_envs: Optional[int] = None


class Schedule(NamedTuple):
    """How long and in what pieces: ``env_steps`` in total (rounded up to whole PPO updates), ``updates_per_chunk``
    per jitted chunk and checkpoint, ``time_budget`` seconds for the process (None: none; the runs before
    ``--time-limit`` replaced it)."""

    env_steps: float = 410 * 122_880
    updates_per_chunk: int = 10
    time_budget: Optional[float] = None


class FlatEvaluation(NamedTuple):
    """The trained walker's check on flat ground: ``attempts`` walks, the mean of the ``best`` and of all."""

    attempts: int = 20
    best: int = 5


class BasePolicyRun(NamedTuple):
    """One base-policy training run (the module docstring shows the shape). Frozen; ``_replace`` or
    ``schema.replace`` to change. ``preset`` picks the walker and PPO shapes (``smoke``: a 16 x 32 heightfield,
    30-step episodes, tiny networks; the others: ``WalkerConfig()`` and ``PPOConfig()``; None: smoke's, as the runs
    of a ``config.json`` without a preset ran)."""

    walker: BaseWalker = BaseWalker()
    ppo: PPOSettings = PPOSettings()
    schedule: Schedule = Schedule()
    evaluation: FlatEvaluation = FlatEvaluation()
    seed: int = 0
    preset: Optional[str] = None


FIELDS: dict[str, str] = {
    **{k: f"walker.{k}" for k in BaseWalker._fields}, "num_envs": "ppo.num_envs",
    **{k: f"schedule.{k}" for k in Schedule._fields}, "eval_attempts": "evaluation.attempts",
    "eval_best": "evaluation.best", "seed": "seed", "preset": "preset"}
"""``{flat key: field path}`` of :class:`BasePolicyRun`: ``config.json``'s keys, which are the flags' names."""

LEGACY = {"robot": "humanoid", "observation": "blind", "scan_noise": 0.0, "randomise": None, "solver": None,
          "num_envs": None, "time_budget": None, "seed": 0, "spawn": "patch"}
"""The value a ``config.json`` key had in the runs made before it was written (what :func:`from_flat` fills in)."""

SPAWNS = ("feet", "patch")
"""How the walker is set down at a reset (``jaxterrain.walker.SPAWNS``; a literal, a test keeps them equal)."""

RULES = {
    "walker.observation": one_of(("blind", "perceptive")), "walker.scan_noise": non_negative(),
    "walker.spawn": one_of(SPAWNS),
    "ppo.num_envs": at_least(1), "schedule.env_steps": positive(), "schedule.updates_per_chunk": at_least(1),
    "schedule.time_budget": positive(), "evaluation.attempts": at_least(1),
    "evaluation.best": (at_least(1), at_most("evaluation.attempts")),
}
"""The checks of single fields (the rest, against the registries: ``difficulty.base_policy.validate_base_run``)."""

EXTENDABLE = ("env_steps", "time_budget", "updates_per_chunk", "eval_attempts", "eval_best")
"""The flat keys a resumed run may change (how long it lasts, how it is chunked and evaluated); the rest is the
run's."""


def from_flat(flat: dict) -> BasePolicyRun:
    """The :class:`BasePolicyRun` of a flat config (``config.json``, a preset's flat form, a command line's values);
    keys of older versions' files take :data:`LEGACY`'s values; ``ValueError`` naming unknown keys."""
    return _from_flat(BasePolicyRun, flat, FIELDS, LEGACY)


def to_flat(run: BasePolicyRun, command: Optional[str] = None) -> dict:
    """The serialised form of ``run`` (``preset`` left out when None), with ``command`` added when given."""
    out = _to_flat(run, FIELDS, omit_none=("preset",))
    return out if command is None else {**out, "command": command}


_GPU = BasePolicyRun()
PRESETS: dict[str, BasePolicyRun] = {
    # 4 updates of 8 envs x 5 steps on a tiny walker: the plumbing (training, checkpoints, resume, export, evaluation)
    "smoke": replace(_GPU, {"schedule.env_steps": 4 * 40, "schedule.updates_per_chunk": 2, "preset": "smoke"}),
    # brax's MJX-humanoid recipe: 410 updates of 122 880 env steps = 50.4 M (41 whole chunks of 10)
    "gpu": _GPU._replace(preset="gpu"),
    "gpu-short": replace(_GPU, {"schedule.env_steps": 41 * 122_880, "preset": "gpu-short"}),
    "paper": _GPU._replace(preset="paper"),
}
"""The presets, typed (``preset`` set to the name): ``smoke`` (CPU, a minute), ``gpu`` (50.4 M env steps on one
GPU), ``gpu-short`` (a tenth), ``paper`` (``gpu``'s)."""

FLAT_PRESETS: dict[str, dict] = {name: {k: v for k, v in to_flat(p).items() if k not in ("preset", "seed")}
                                 for name, p in PRESETS.items()}
"""The presets in their flat form, without ``preset`` and ``seed`` (what a fresh run's ``config.json`` adds)."""

CONSUMERS = {
    "": "difficulty.base_policy.train_base_policy",
    "walker": "difficulty.base_policy.resolve_settings (the WalkerConfig)",
    "ppo": "difficulty.base_policy.resolve_settings (the PPOConfig)",
    "schedule": "difficulty.base_policy.resolve_settings (updates), train_chunks (runtime.driver.run_chunks)",
    "evaluation": "difficulty.base_policy.evaluate_flat",
    "seed": "difficulty.base_policy.train_base_policy (rl.init's key, evaluate_flat's)",
    "preset": "difficulty.base_policy.shapes",
}
"""Where each field of :class:`BasePolicyRun` is consumed (``docs/CONTRIBUTING.md``; a test checks the functions)."""

HELP = {
    "env_steps": "total env steps to train (default: smoke 4 updates, gpu 410 updates = 50.4e6)",
    "time_budget": "seconds: --time-limit's predecessor, kept so that older command lines (the base policy's "
                   "PROVENANCE.md) still run",
    "updates_per_chunk": "PPO updates per jitted chunk = per checkpoint",
    "num_envs": "override PPOConfig.num_envs",
    "solver": "walker contact solver: sound (default: Newton 4 iterations / 16 line-search), fast, xml, or "
              "ITERATIONS,LS_ITERATIONS,EULERDAMP such as 4,16,0; recorded with the policy, and difficulty.evaluate "
              "then walks it under the same options",
    "robot": "the body to train: humanoid (default, the paper's), ant (brax's quadruped) or a robot a --plugin "
             "registered (jaxterrain.walker.robots); recorded with the policy",
    "observation": "what the walker observes: blind (the paper's: torso height, orientation, joints) or perceptive "
                   "(plus a height scan around and ahead of the torso, the robot's default grid); recorded with the "
                   "policy, and every command walks it with the same set",
    "scan_noise": "perceptive: std of Gaussian noise on each scanned height, in metres",
    "randomise": "physics randomisation of the training walker (recorded with the policy; the flat-ground evaluation "
                 "walks the nominal physics) {randomise}",
    "spawn": "how the walker is set down at each reset: feet (default: the body lifted until every foot clears the "
             "terrain under it) or patch (only the lowest foot clear of a 0.5 m patch under the torso: every run "
             "before 2026-11-29; a run saved before reads as patch, or resumed, as the rule its provenance.jsonl says "
             "it started with); on the flat ground the walker trains and is evaluated on, both rules set it down at "
             "the same height; recorded with the policy",
    "eval_attempts": "flat-ground evaluation walks",
    "eval_best": "of which the best are averaged",
}
"""``train-base-policy``'s flags: each flat key's help, the field's documentation as the command line's ``--help`` shows it
(``experiments.cli_gen`` adds the type, the choices, the allowed range of the field's rule where the text says
``{range}`` or at its end, and every preset's value; ``{backend}``, ``{randomise}`` and ``{slots}`` are
phrases every command shares, ``experiments.common.PHRASES``). The keys are the flags the command exposes, in
``--help``'s order."""

"""One curriculum run (``learn``, and each treatment of ``curriculum``) as one frozen, typed config, nested where the
concepts nest, with its presets and its serialised form.

    from jaxterrain.curriculum import run_config as R, runner
    config = R.PRESETS["smoke"]._replace(trials=1)
    config = config._replace(curriculum=config.curriculum._replace(selector="plr", params=PLRParams(capacity=8)))
    summary = runner.run_treatment(config, "runs/mine")        # validates once, then runs (None: time limit)
    flat = R.to_flat(config)                                   # config.json; R.from_flat(flat) == config

The shape (each field consumed where ``docs/CONTRIBUTING.md`` says)::

    LearnConfig
      archive, descriptors          the archive and the descriptors it must have (runner.load_archive)
      terrains, terrain_height,     or a folder of your own heightmaps instead of the archive, the metres of an
      terrain_order                 image's full grey, and how its terrains rank by hardness (own_terrains)
      trials, seed                  trials run together (vmap) and the root key (runner.inputs)
      recipe                        the name of the fine-tuning recipe its PPO shape came from (recorded; RECIPES)
      preset                        the preset it was made from (recorded)
      curriculum: CurriculumConfig  selector + params (selectors.*Params), threshold, budget in epochs, ppo
                                    (FINE_TUNED fields), overlap, credit, ... (curriculum.core, .walker, .outputs)
      protocol: ProtocolOverride    attempts / best / headings; None = the archive's (runner.resolve)
      walker: WalkerSettings        backend, episode_length, healthy_reward, robot, policy, observation, randomise,
                                    spawn
                                    (runner: the env)
      budget: Budget                chunks_per_call, compact, fast_compile, policy_every (runner.setup, run_treatment)

The run's protocol is ``protocol`` where given, else the archive's: :func:`jaxterrain.curriculum.runner.resolve`
writes it into ``curriculum.attempts`` / ``best`` / ``headings`` before the run (:func:`from_flat` writes the given
ones there too; the others hold ``CurriculumConfig``'s defaults until resolved).

The serialised form is the flat dict of ``config.json`` (:func:`to_flat`; every key a command-line flag's name, so
the one field -> flag table is :data:`FLAT_FIELDS` with ``--`` + dashes); :func:`from_flat` reads it, and every
``config.json`` written before (a key it lacks takes the value that version ran with: ``truncation`` ``mask``,
``backend`` ``jax``, ``overlap`` / ``eval_lag`` / ``fast_compile`` off, ``compact`` on, ``spawn`` ``patch``,
``scan_lr_scale`` 1.0; the keys of other selectors' params are dropped). The presets' flat forms live in
:mod:`.presets` (no JAX: ``--help`` reads them).
"""

from __future__ import annotations

from typing import NamedTuple, Optional

from jaxterrain.curriculum.config import FINE_TUNED, SELECTORS, CurriculumConfig
from jaxterrain.curriculum.presets import CPPN_ARCHIVE, FLAT_PRESETS
from jaxterrain.curriculum.selectors.protocol import selector_fields, selector_spec

__all__ = ["LearnConfig", "ProtocolOverride", "WalkerSettings", "Budget", "PRESETS", "CPPN_ARCHIVE", "from_flat",
           "to_flat", "FLAT_FIELDS", "field_of", "LEGACY", "RENAMED", "CONSUMERS"]


class ProtocolOverride(NamedTuple):
    """The evaluation protocol of a run, field by field; None = the archive's (``EvolveConfig.attempts`` / ``best``
    / ``headings``, under which the GP's prior was measured)."""

    attempts: Optional[int] = None
    best: Optional[int] = None
    headings: Optional[int] = None


class WalkerSettings(NamedTuple):
    """The walker the run trains: ``backend`` (``auto`` / ``jax`` / ``warp``), ``episode_length`` (steps),
    ``healthy_reward`` (PPO's per-step bonus; None = the walker's 5.0), ``robot`` (None = the humanoid, or the
    ``policy``'s), ``policy`` (a policy folder to start from; None = the robot's shipped base policy),
    ``observation`` (``blind`` / ``perceptive``: the start policy's observation set; None = the ``policy``'s, or
    the blind base policy), ``randomise`` (a ``--randomise`` spec of physics randomisation,
    ``jaxterrain.walker.parse_randomisation``; None = off), ``spawn`` (``jaxterrain.walker.SPAWNS``: how the walker
    is set down at a reset; ``feet``, or ``patch`` as every run before 2026-11-29)."""

    backend: str = "auto"
    episode_length: int = 1000
    healthy_reward: Optional[float] = None
    robot: Optional[str] = None
    policy: Optional[str] = None
    observation: Optional[str] = None
    randomise: Optional[str] = None
    spawn: str = "feet"


class Budget(NamedTuple):
    """How the run is cut and computed (none changes its result): ``chunks_per_call`` chunks per jitted block and
    checkpoint, ``compact`` (compute only the running trials), ``fast_compile`` (XLA's quick CPU options),
    ``policy_every`` (walker snapshots every N chunks; None: only the final ones)."""

    chunks_per_call: int = 25
    compact: bool = True
    fast_compile: bool = False
    policy_every: Optional[int] = None


class LearnConfig(NamedTuple):
    """One curriculum run (the module docstring shows the shape). Hashable and frozen; ``_replace`` to change.

    ``terrains``: a folder of heightmaps (``jaxterrain.suite.folder``) trained on instead of ``archive`` (which, with
    ``descriptors``, is then not read); ``terrain_height``: metres of an image's full grey, or the relief a metre
    file is rescaled to (None: 1 m for images, metre files as they are); ``terrain_order``: ``name`` (hardness = the
    file-name order) or ``difficulty`` (the base policy walked on each terrain before the run, hardest last)."""

    archive: str = CPPN_ARCHIVE
    descriptors: tuple = ("roughness", "tpi")
    terrains: Optional[str] = None
    terrain_height: Optional[float] = None
    terrain_order: str = "name"
    trials: int = 10
    seed: int = 0
    recipe: Optional[str] = "paper"
    preset: Optional[str] = None
    curriculum: CurriculumConfig = CurriculumConfig()
    protocol: ProtocolOverride = ProtocolOverride()
    walker: WalkerSettings = WalkerSettings()
    budget: Budget = Budget()


_TOP = ("archive", "descriptors", "terrains", "terrain_height", "terrain_order", "trials", "seed", "recipe", "preset")
_CURRICULUM = ("epochs_per_chunk", "steps_per_epoch", "max_epochs", "threshold", "max_fitness", "max_evals",
               "credit", "distance_origin", "overlap", "eval_lag")
LEGACY = {"truncation": "mask", "backend": "jax", "overlap": False, "eval_lag": False, "fast_compile": False,
          "compact": True, "spawn": "patch", "scan_lr_scale": 1.0,
          "seed": 0, "terrains": None, "terrain_height": None, "terrain_order": "name"}
"""The value a ``config.json`` key had in the runs made before it was written (what :func:`from_flat` fills in)."""

RENAMED = {"dr_terrains": "terrains_per_chunk"}
"""Flat keys of older versions under their current names (``dr_terrains``: before ``plr`` shared the field)."""

FLAT_FIELDS: dict[str, str] = {
    **{k: k for k in _TOP if k != "preset"}, "curriculum": "curriculum.selector",
    **{k: f"curriculum.{k}" for k in _CURRICULUM}, **{k: f"curriculum.ppo.{k}" for k in FINE_TUNED},
    **{k: f"protocol.{k}" for k in ProtocolOverride._fields}, **{k: f"walker.{k}" for k in WalkerSettings._fields},
    **{k: f"budget.{k}" for k in Budget._fields},
}
"""``{flat key: typed field}`` of every ``config.json`` key but the selectors' params (``kappa``:
``curriculum.params.kappa``, by :func:`field_of`): the one table between the serialised form (whose keys are the
command line's flag names, ``--`` + dashes) and the typed fields."""


def field_of(key: str, selector: str = "map") -> str:
    """The typed field (dotted path) of flat key ``key`` in a run of ``selector``."""
    if key in FLAT_FIELDS:
        return FLAT_FIELDS[key]
    spec = selector_spec(selector) if isinstance(selector, str) else None
    if spec is not None and key in spec.flat:
        return f"curriculum.params.{spec.flat[key]}"
    return key


def from_flat(flat: dict) -> LearnConfig:
    """The :class:`LearnConfig` of a flat config (``config.json``, a preset's :mod:`.presets` form, or a command
    line's settings); keys a config of an older version lacks take :data:`LEGACY`'s values, the defaults otherwise.
    ``ValueError`` naming unknown keys. ``command`` (the command that wrote it) is not part of the run."""
    d = {k: v for k, v in flat.items() if k != "command"}
    for old, new in RENAMED.items():
        if old in d:
            value = d.pop(old)
            d.setdefault(new, value)
    own = selector_fields()
    unknown = set(d) - set(FLAT_FIELDS) - set(own) - {"preset"}
    if unknown:
        raise ValueError(f"LearnConfig: unknown config keys {sorted(unknown)}")
    get = lambda key, default=None: d[key] if key in d else LEGACY.get(key, default)  # noqa: E731
    selector = d.get("curriculum", "map")
    curriculum = {"selector": selector, **{k: d[k] for k in _CURRICULUM if k in d},
                  **{k: d[k] for k in ProtocolOverride._fields if d.get(k) is not None},
                  **{k: d[k] for k in FINE_TUNED if k in d}, **{k: v for k, v in d.items() if k in own}}
    curriculum.setdefault("truncation", LEGACY["truncation"])
    curriculum.setdefault("overlap", LEGACY["overlap"])
    curriculum.setdefault("eval_lag", LEGACY["eval_lag"])
    curriculum.setdefault("scan_lr_scale", LEGACY["scan_lr_scale"])
    base = LearnConfig()
    return LearnConfig(
        archive=d.get("archive", base.archive), descriptors=tuple(d.get("descriptors", base.descriptors)),
        terrains=get("terrains"), terrain_height=get("terrain_height"), terrain_order=get("terrain_order"),
        trials=d.get("trials", base.trials), seed=get("seed"), recipe=d.get("recipe"), preset=d.get("preset"),
        curriculum=CurriculumConfig.from_json_dict(curriculum),
        protocol=ProtocolOverride(**{k: d.get(k) for k in ProtocolOverride._fields}),
        walker=WalkerSettings(**{k: get(k, getattr(base.walker, k)) for k in WalkerSettings._fields}),
        budget=Budget(**{k: get(k, getattr(base.budget, k)) for k in Budget._fields}))


def _params_flat(config: LearnConfig) -> dict:
    """Every built-in selector's params under their flat keys: the run's own, the others' defaults (a flat config
    holds every key, as the presets do)."""
    out = {}
    for name in SELECTORS + ((config.curriculum.selector,) if config.curriculum.selector not in SELECTORS else ()):
        spec = selector_spec(name) if ":" not in name else None
        if spec is None or spec.params is None:
            continue
        own = name == config.curriculum.selector and config.curriculum.params is not None
        params = config.curriculum.params if own else spec.params()
        for key, field in spec.flat.items():
            if own or key not in out:
                out[key] = getattr(params, field)
    return out


def to_flat(config: LearnConfig, command: Optional[str] = None) -> dict:
    """The serialised form of ``config``: ``config.json``'s flat dict (:func:`from_flat` reads it back), with
    ``command`` added when given."""
    c = config.curriculum
    out = {k: getattr(config, k) for k in _TOP if not (k == "preset" and config.preset is None)}
    out["descriptors"] = list(config.descriptors)
    out.update(curriculum=c.selector, **{k: getattr(c, k) for k in _CURRICULUM},
               **{k: getattr(c.ppo, k) for k in FINE_TUNED}, **config.protocol._asdict(), **config.walker._asdict(),
               **config.budget._asdict(), **_params_flat(config))
    if command is not None:
        out["command"] = command
    return out


PRESETS: dict[str, LearnConfig] = {name: from_flat({**flat, "preset": name}) for name, flat in FLAT_PRESETS.items()}
"""The typed presets (``smoke``, ``gpu-short``, ``gpu``, ``paper``: :mod:`.presets`), ``preset`` set to the name."""

CONSUMERS = {
    "": "curriculum.runner.run_treatment",
    "archive": "curriculum.runner.load_archive", "descriptors": "curriculum.runner.load_archive",
    "terrains": "curriculum.own_terrains.load_terrains", "terrain_height": "curriculum.own_terrains.load_terrains",
    "terrain_order": "curriculum.own_terrains.rank_terrains",
    "trials": "curriculum.runner.inputs (keys), setup (vmap)", "seed": "curriculum.runner.inputs (the root key)",
    "recipe": "curriculum.runner.validate (RECIPES; recorded)", "preset": "recorded",
    "curriculum": "curriculum.core.step (the trial loop; outputs.write_outputs)",
    "curriculum.selector": "curriculum.selectors.get_selector", "curriculum.params": "curriculum.selectors.get_selector",
    "curriculum.attempts": "curriculum.walker.walker_harness (evaluations)",
    "curriculum.best": "curriculum.walker.walker_harness", "curriculum.headings": "curriculum.walker.walker_harness",
    "curriculum.ppo": "curriculum.walker.walker_harness (rl.ppo)",
    "curriculum.ppo.scan_inputs": "curriculum.walker.fine_tuning_ppo (the walker's scan size; not a flag)",
    "curriculum.ppo.scan_lr_scale": "curriculum.walker.fine_tuning_ppo (rl.make_optimizer)",
    "curriculum.overlap": "curriculum.core.step, runner.walker_layout",
    "curriculum.eval_lag": "curriculum.core.chunk_update",
    "protocol": "curriculum.runner.resolve",
    "walker": "curriculum.runner.make_env", "walker.backend": "curriculum.runner.walker_layout",
    "walker.robot": "curriculum.runner.start_policy", "walker.policy": "curriculum.runner.start_policy",
    "walker.observation": "curriculum.runner.start_policy", "walker.spawn": "curriculum.runner.make_env",
    "budget": "curriculum.runner.setup (compiled blocks), run_treatment (driver.run_chunks)",
}
"""Where each field of :class:`LearnConfig` is consumed (``docs/CONTRIBUTING.md``; a test checks the functions)."""

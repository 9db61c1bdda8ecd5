"""The curriculum's one typed config: every number of the paper's Experiment 2 and every choice it leaves open.

The paper (Howard et al. 2022, section 4.2) fixes: PPO from the base policy, at most 30 000 epochs, training in
chunks of 40 epochs, an evaluation after every chunk, a terrain is finished at 90 % of the maximum fitness or after
100 evaluations, the IT&E GP (rho 0.4, kappa 0.05, noise 0.001, Matern kernel, prior = the archive's fitness),
terrains predicted easier than the one just trained are removed, the run ends when no terrain is left, and the
"hardest terrain traversed" is the Euclidean distance of its cell from (0, 0). Where it is silent we chose:

``gp_evaluation = "final"`` - which evaluation enters the GP. One observation per finished terrain: the evaluation
  that finished it (the policy as it leaves the terrain, which is the policy the next choice is made for). IT&E adds
  one observation per trial too. Adding every chunk's evaluation would put up to 100 observations of a changing
  policy at the SAME point (a stale, nearly singular kernel matrix). ``"best"`` adds the best evaluation instead.

``ppo = FINE_TUNING``: ``num_envs = 500, unroll_length = 10, num_unrolls = 8, num_minibatches = 8, update_epochs = 8,
  learning_rate = 3e-4`` (the :data:`FINE_TUNED` fields of a ``PPOConfig``) - PPO for fine-tuning, with all envs on
  the one current terrain. The paper used SpinningUp's PPO defaults (one env, 4 000 steps per epoch); we keep the
  recipe the base policy was trained with (brax's MJX humanoid PPO: its networks, normaliser, clipping, discount,
  learning rate), so that its value net and normaliser carry over, and size one update as 10 epochs (500 x 10 x 8 =
  40 000 env steps; 4 updates per 40-epoch chunk, 64 Adam steps per update: about brax's ratio of Adam steps to env
  steps). 500 envs make each env walk 320 steps per chunk, longer than one traversal (about 210 steps at the base
  policy's 2.9 m/s), so the first chunk on a new terrain already sees whole walks; 10 trials x 500 envs fill a GPU.
  Adam's state starts fresh (none is shipped with the base policy). ``update_normaliser = True``: the observation
  normaliser keeps merging the fine-tuning data, as brax's PPO does (the base policy's statistics cover 20 M
  observations; a ``gpu-short`` trial adds 12 M). False freezes the base policy's statistics
  (``learn --no-update-normaliser``). ``truncation = "bootstrap"``: a walk that ends at the goal or the time limit
  trains its last step towards ``r + gamma V(final observation)`` (SB3, Pardo et al. 2018), not the base policy's
  (brax's) ``"mask"`` (``learn --truncation mask``), under which that step's state is never trained yet the step
  before bootstraps from it. On the roughness baseline's second terrain, where the last states before the goal
  line are unlike any other, ``mask`` lets the value net diverge and fine-tuning ruin the walker; ``bootstrap``
  keeps standard CL learning, leaves the map treatments where they were and costs nothing measurable on the GPU
  (``docs/results/exp2_paper.md``). Runs saved before 2026-11-27 (no ``truncation`` in their config) used ``mask``
  and resume with it (``experiments learn``). ``scan_lr_scale = 1.0``: a perceptive walker's Adam steps on the
  first-layer weights that read its height scan as every other weight's; ``learn --scan-lr-scale 0.1`` shrinks
  them (``rl.PPOConfig.scan_lr_scale``; the scan's 153 correlated inputs otherwise move the first layer 8-10x as
  far as the blind ones, ``docs/results/exp4/scan_diag/``). Its ``scan_inputs`` is the walker's scan size, set by
  :meth:`CurriculumConfig.ppo_config`; a blind walker refuses any other scale. Runs saved before it used 1.0.

``max_fitness = 1.0`` - "maximum fitness" is the maximum of the normalised distance (the far edge), so the threshold
  is fitness >= 0.9. (IT&E's own stop rule compares with the GP's maximum mean; that is a different quantity.)

``removal_margin = 0.05, removal_ties = "nearer"`` - the removal rule. After a terrain T is finished, an available
  terrain x is removed when the updated GP predicts it clearly easier, ``mu(x) > mu(T) + margin``; terrains within
  the margin of T (``|mu(x) - mu(T)| <= margin``) are ties, removed only when their cell is no further from the
  origin than T's (the map's own difficulty breaks the tie); T itself is always removed. Why: the base policy's
  fitness saturates at 1.0 on many cells, and one evaluation of T reads a little below its prior (0.98 for a prior
  of 1.0 is evaluation noise). The literal rule (``margin 0, ties "remove"``) would then remove every other cell
  at 1.0 as "easier" and empty the map after the first terrain; within the margin, the descriptors decide.
  ``"keep"`` keeps all ties, ``"remove"`` removes all ties (the literal "at least as easy").

``credit = "threshold"`` - a terrain counts as traversed (for the hardest-terrain record) only when an evaluation on
  it reached the threshold; one left after 100 evaluations without reaching it is not credited. ``"finished"``
  credits every finished terrain.

``distance_origin = "origin"`` - the hardest terrain is measured from cell (0, 0), as the paper's Figure 7 caption
  and its "feature distance from (0, 0)" say: ``TerrainBank.distance = hypot(b0 + 1, b1 + 1)`` in cells (70.71 at
  the far corner of 50 x 50). Its Table 2 text says "distance from the top-right corner"; ``"top_right"`` reads that
  as ``70.71 - hypot(bins - b0, bins - b1)`` (0 at (0, 0), 69.3 in the top-right cell) for comparison.

``attempts, best, headings`` - each evaluation walks the protocol the archive's fitness was measured under
  (``difficulty.Protocol(attempts, best, headings)``; the paper's 20 / 5 / 1 by default, ``HEADINGS`` = 80 / 5 / 4):
  the GP's prior is the archive's fitness and its observations are the evaluations, so both must measure the same
  thing. ``experiments learn`` reads them from the archive's ``EvolveConfig``. With more than one heading the
  PPO envs are spread over the headings as well (env e on heading ``e % headings``): the policy trains in the
  directions it is judged in. On tiles (MuJoCo Warp) a trial's terrain takes one tile per heading, turned
  (``curriculum.walker.tile_layout``).

Ties in the choice of the next terrain (equal scores) go to the terrain nearest the origin, then the lowest index.
The first terrain of the map curriculum is the argmax of the prior (no observation yet: the UCB is the prior + kappa).

Baselines share everything but the ``selector`` and its ``params`` (each selector's own NamedTuple, defined and
checked in its module of :mod:`.selectors`; None = its defaults): ``"roughness"`` (standard CL, the paper's Figure
7b: the terrains sorted by descriptor 0 (roughness) ascending, every ``RoughnessParams.stride``-th one, in order,
each finished by the same threshold / 100-evaluation rule) and ``"random"`` (uniformly random among the available
terrains, each removed after it is finished, no GP). The field's curricula spread a trial's envs over several
terrains at once: ``"dr"`` (domain randomisation, ``DRParams.terrains_per_chunk`` terrains a chunk), ``"levels"``
(legged_gym's terrain levels: ``LevelsParams``), ``"plr"`` (prioritised level replay: ``PLRParams``) and
``"accel"`` (PLR over a generator's genomes whose replayed levels are edited by its ``mutate``: ``AccelParams``);
their rules and where they differ from the field's are in their modules. The map curriculum's GP and removal rule
above are ``MapParams`` (``kappa``, ``rho``, ``sigma_f``, ``noise``, ``gp_evaluation``, ``removal_margin``,
``removal_ties``, ``max_observations``). Any other name is a registered selector (``selectors.register_selector``)
or ``module:object``.
"""

from __future__ import annotations

from typing import Any, NamedTuple, Optional

from jaxterrain.curriculum.selectors.base import float_in
from jaxterrain.curriculum.selectors.protocol import params_from_flat, selector_fields, selector_spec, validate_selector
from jaxterrain.difficulty import Protocol
from jaxterrain.rl.config import PPOConfig, validate_config as validate_ppo_config
from jaxterrain.runtime.validation import int_at_least, known_fields, one_of, walks

__all__ = ["CurriculumConfig", "validate_config", "SELECTORS", "SELECTOR_FIELDS", "FINE_TUNED", "FINE_TUNING",
           "RECIPES", "recipe", "CREDITS", "DISTANCE_ORIGINS"]

SELECTORS = ("map", "roughness", "random", "dr", "levels", "plr", "accel")  # built in; selectors.selector_names() adds registered ones
SELECTOR_FIELDS: dict[str, tuple[str, ...]] = selector_fields(SELECTORS)
"""The flat config keys (``learn``'s ``config.json`` and flags) of the built-in selectors' params, and which selectors
read each (``plr_capacity``: ``plr``, ``accel``): any other built-in selector ignores them (``experiments learn``
refuses such a flag given with another ``--curriculum``; a registered or ``module:object`` selector has its own).
Each selector's module owns its params (:mod:`.selectors`)."""
CREDITS = ("threshold", "finished")
DISTANCE_ORIGINS = ("origin", "top_right")
# The PPOConfig fields that fine-tuning sets (how much is collected per update, how it is trained on); every other
# field (networks, normaliser, clipping, discount, ...) is the base policy's, whose params and normaliser carry over.
# scan_lr_scale: Adam's step on the first-layer weights that read a perceptive walker's height scan; its scan_inputs
# (the scan's size) is not set here: ppo_config takes it from the walker (0 for a blind one, which refuses a scale).
FINE_TUNED = ("num_envs", "unroll_length", "num_unrolls", "num_minibatches", "update_epochs", "learning_rate",
              "update_normaliser", "truncation", "scan_lr_scale")
FINE_TUNING = PPOConfig(num_envs=500, unroll_length=10, num_unrolls=8, num_minibatches=8, update_epochs=8,
                        learning_rate=3e-4, update_normaliser=True, truncation="bootstrap", scan_lr_scale=1.0)

RECIPES: dict[str, dict[str, int]] = {
    "paper": {"num_envs": 500, "unroll_length": 10, "num_unrolls": 8, "num_minibatches": 8, "update_epochs": 8},
    "wide": {"num_envs": 4000, "unroll_length": 10, "num_unrolls": 1, "num_minibatches": 8, "update_epochs": 8},
}
"""How fine-tuning PPO collects a chunk's env steps (``learn --recipe NAME``; the :data:`FINE_TUNED` fields that
shape an update). Both take 40 000 env steps per update (4 updates per 160 000-step chunk) and train on them alike
(8 epochs of 8 minibatches of 5 000, GAE over 10-step segments); they differ in where the steps come from:

- ``paper`` (:data:`FINE_TUNING`): 500 envs per trial, 8 consecutive 10-step segments each per update: every env
  walks 320 steps a chunk (longer than a traversal), but the chunk is 320 sequential env steps, and 10 trials are
  5 000 envs, a third of a GPU's walker throughput (``benchmarks/RESULTS.md``).
- ``wide``: 4 000 envs per trial, one 10-step segment each per update (legged_gym and Isaac Lab: 4 096 envs x 24
  steps): 40 sequential env steps a chunk, 40 000 envs for 10 trials. Each env walks only 40 steps a chunk, so on a
  terrain new to the trial (all envs restart there) the first chunk sees only the first ~1.2 m of the course; whole
  walks take ~5 chunks. Measured (``gpu-short``, CPPN and Perlin maps, 10 trials each, one H200, 2026-11-28): 1.35x
  faster per chunk at 10 trials, the hardest archive cell within noise, but the held-out IQM lower with intervals
  apart (0.333 against 0.346, 0.379 against 0.403; ``docs/results/wide_recipe.md``), so ``paper`` stays the default.
"""


def recipe(name: str) -> dict[str, int]:
    """The :data:`RECIPES` entry ``name`` (a copy); ``ValueError`` naming the choices."""
    if name not in RECIPES:
        raise ValueError(f"recipe must be one of {', '.join(RECIPES)}, got {name!r}")
    return dict(RECIPES[name])


class CurriculumConfig(NamedTuple):
    """Static settings of one curriculum treatment (hashable; changing one re-compiles). Defaults: the paper, plus
    the choices of the module docstring.

    Fields:
      selector: ``map`` (IT&E GP + UCB + removal), ``roughness`` (standard CL), ``random``, ``dr`` (domain
        randomisation), ``levels`` (legged_gym's terrain levels), ``plr`` (prioritised level replay), ``accel``
        (PLR with edits of generator genomes), a registered name or ``module:object``
        (:mod:`.selectors`).
      epochs_per_chunk: epochs trained between two evaluations (paper: 40).
      steps_per_epoch: env steps per epoch (SpinningUp's epoch: 4 000).
      max_epochs: the run stops after this many epochs (paper: 30 000).
      threshold: a terrain is learnt at fitness >= threshold x max_fitness, in (0, 1] (paper: 0.9).
      max_fitness: the maximum fitness (the normalised distance's 1.0), > 0.
      max_evals: evaluations (chunks) spent on one terrain before it is left anyway (paper: 100, i.e. 4 000 of its
        30 000 epochs). Scale it with a shorter ``max_epochs``: at 3 000 epochs, 100 evaluations let one terrain
        that never reaches the threshold take the whole run.
      attempts, best, headings: the difficulty protocol of each evaluation,
        ``difficulty.Protocol(attempts, best, headings)``: ``attempts`` walks in total, ``attempts // headings``
        per heading (1: the paper's +x; 2 or 4: the map also turned, ``difficulty.HEADINGS`` is 80, 5, 4), the mean
        over headings of each heading's best ``best``. Use the protocol the archive's fitness (the GP's prior) was
        measured under: ``experiments learn`` takes it from the archive unless told otherwise.
      credit: ``threshold`` or ``finished``: which terrains count for the hardest-terrain record.
      distance_origin: ``origin`` or ``top_right``: how a cell's hardness (distance) is measured.
      ppo: a :class:`jaxterrain.rl.PPOConfig` whose :data:`FINE_TUNED` fields (``num_envs, unroll_length,
        num_unrolls, num_minibatches, update_epochs, learning_rate, update_normaliser, truncation,
        scan_lr_scale``) are the fine-tuning PPO's (the base policy's recipe otherwise, :meth:`ppo_config`, which
        takes ``scan_inputs`` from the walker); its other fields must keep ``PPOConfig``'s defaults. Default
        :data:`FINE_TUNING`; e.g. ``ppo=FINE_TUNING._replace(num_envs=64)``.
        ``steps_per_update`` (``num_envs x unroll_length x num_unrolls``) must divide a chunk's env steps.
      overlap: evaluate each chunk's policy while the next chunk trains, its walks stepped in the same physics
        calls as the PPO envs (``rl.ride_updates``); the next chunk trains on the current terrain on the chance that
        the evaluation keeps the trial there, and trains again when it does not. The same curriculum (the same
        keys, policies, evaluations and choices, given the same env states) in
        fewer physics calls: see :func:`jaxterrain.curriculum.core.step`. Needs a harness with ``train_evaluate``
        (the walker's on tiles). One-terrain selectors only (``map``, ``roughness``, ``random``).
      eval_lag: with ``overlap``, what a terrain switch does to the chunk trained while the evaluation that ended
        the terrain was walked: False (the default) drops it and trains that chunk again on the new terrain (one
        step more per switch; the plain loop's curriculum); True keeps it (no step more): the trial trains one chunk
        more on the terrain it just finished, that chunk is never evaluated (``History.evaluation`` NaN in its row)
        and the selector sees every evaluation one chunk late (it decides for a policy trained one chunk past the
        one it evaluated). Each row of the history still holds its own chunk's terrain and that chunk's policy's
        evaluation there (with its keys); ``history.csv``'s ``seen_epoch`` says when the selector saw it. Needs
        ``overlap``.
      params: the selector's own parameters, a NamedTuple its module defines (:mod:`.selectors`:
        ``MapParams`` for ``map`` (the GP's kappa, rho, sigma_f, noise, gp_evaluation, the removal rule's margin and
        ties, max_observations), ``RoughnessParams``, ``DRParams``, ``LevelsParams``, ``PLRParams``,
        ``AccelParams``; ``random`` has none), or None (the default): that selector's defaults
        (:func:`.selectors.selector_params`). :meth:`from_json_dict` also reads them flat, under their
        ``config.json`` keys (``kappa``, ``plr_capacity``, ``levels_init``, ...: ``selectors.SelectorSpec.flat``).
    """

    selector: str = "map"
    epochs_per_chunk: int = 40
    steps_per_epoch: int = 4000
    max_epochs: int = 30000
    threshold: float = 0.9
    max_fitness: float = 1.0
    max_evals: int = 100
    attempts: int = 20
    best: int = 5
    headings: int = 1
    credit: str = "threshold"
    distance_origin: str = "origin"
    ppo: PPOConfig = FINE_TUNING
    overlap: bool = False
    eval_lag: bool = False
    params: Any = None

    @property
    def max_chunks(self) -> int:
        """Chunks of ``epochs_per_chunk`` until ``max_epochs`` (the length of the history buffers)."""
        return -(-self.max_epochs // self.epochs_per_chunk)

    @property
    def steps_per_chunk(self) -> int:
        """Env steps trained per chunk."""
        return self.epochs_per_chunk * self.steps_per_epoch

    @property
    def steps_per_update(self) -> int:
        """Env steps of one PPO update."""
        return self.ppo.steps_per_update

    @property
    def updates_per_chunk(self) -> int:
        """PPO updates per chunk."""
        return self.steps_per_chunk // self.steps_per_update

    def observation_slots(self, num_terrains: int, max_observations: Optional[int] = None) -> int:
        """``M``, the GP's padded observation count for a bank of ``num_terrains``: ``max_observations`` (``map``'s
        ``MapParams.max_observations``), or with None ``min(N, max_chunks)``."""
        if max_observations is not None:
            return int(max_observations)
        return max(1, min(int(num_terrains), self.max_chunks))

    @property
    def protocol(self):
        """The evaluation's :class:`jaxterrain.difficulty.Protocol` (``attempts``, ``best``, ``headings``)."""

        return Protocol(int(self.attempts), int(self.best), int(self.headings))

    def ppo_config(self, base: PPOConfig, scan_inputs: int = 0) -> PPOConfig:
        """The fine-tuning :class:`jaxterrain.rl.PPOConfig`: ``base`` (the base policy's) with the :data:`FINE_TUNED`
        fields of :attr:`ppo` and ``scan_inputs``, the walker's height scan entries (``walker.scan_size``; 0: blind).
        ``ValueError`` when ``ppo.scan_lr_scale`` is not 1 and there is no scan to scale."""
        if scan_inputs == 0 and self.ppo.scan_lr_scale != 1.0:
            raise ValueError(f"CurriculumConfig.ppo.scan_lr_scale {self.ppo.scan_lr_scale!r}: scales Adam's step on "
                             f"the weights that read a height scan, and this walker has none (blind): it must be 1.0")
        return base._replace(**{name: getattr(self.ppo, name) for name in FINE_TUNED}, scan_inputs=int(scan_inputs))

    def to_json_dict(self) -> dict:
        """A JSON-serialisable dict: the fields, with ``ppo`` as ``{name: value}`` of its :data:`FINE_TUNED` fields
        (the only ones it may set) and ``params`` as ``{field: value}`` (or None)."""
        params = None if self.params is None else dict(self.params._asdict())
        return {**self._asdict(), "ppo": {name: getattr(self.ppo, name) for name in FINE_TUNED}, "params": params}

    @classmethod
    def from_json_dict(cls, d: dict) -> "CurriculumConfig":
        """Inverse of :meth:`to_json_dict`; also reads the flat layout (the :data:`FINE_TUNED` fields beside the
        others, as ``experiments learn``'s ``config.json`` and configs written before ``ppo`` existed hold them).
        The selector's params are read nested (``"params": {field: value}``) or flat, under their ``config.json``
        keys (``plr_capacity``, ...; the layout of every config before the selectors owned their params): the keys
        of the run's selector go into its params, those of the other built-in selectors are dropped (a flat config
        holds every selector's). Missing fields take their defaults; unknown keys, or ``d`` not a dict, raise
        ``ValueError``."""
        if not isinstance(d, dict):
            raise ValueError(f"CurriculumConfig.from_json_dict: needs a dict of fields (as to_json_dict writes); got "
                             f"{type(d).__name__}")
        d = dict(d)
        ppo = {name: d.pop(name) for name in FINE_TUNED if name in d}
        nested = d.pop("ppo", None) or {}
        known_fields("CurriculumConfig.ppo", FINE_TUNED, nested)
        selector = d.get("selector", cls._field_defaults["selector"])
        flat = {key: d.pop(key) for key in list(d) if key in selector_fields()}
        params = d.pop("params", None)
        known_fields("CurriculumConfig", cls._fields, d)
        if isinstance(params, dict):
            kind = selector_spec(selector).params
            if kind is None:
                raise ValueError(f"CurriculumConfig.params: selector {selector!r} takes none, got {params!r}")
            known_fields("CurriculumConfig.params", kind._fields, params)
            params = kind(**params)
        elif params is None:
            params = params_from_flat(selector, flat)
        return cls(**d, ppo=FINE_TUNING._replace(**{**ppo, **nested}), params=params)


def _float_in(config, name: str, lo: float, hi: Optional[float], lo_open: bool) -> None:
    float_in("CurriculumConfig", config, name, lo, hi, lo_open)


def validate_config(config: CurriculumConfig) -> CurriculumConfig:
    """Raise ``ValueError`` naming the first bad field and its allowed range (``CurriculumConfig.<field>``, or
    ``CurriculumConfig.params.<field>`` for the selector's own, checked by its module); return ``config``
    unchanged."""
    for name in ("epochs_per_chunk", "steps_per_epoch", "max_epochs", "max_evals", "attempts", "best"):
        int_at_least("CurriculumConfig", config, name, 1)
    walks("CurriculumConfig", config)
    _float_in(config, "threshold", 0.0, 1.0, lo_open=True)
    _float_in(config, "max_fitness", 0.0, None, lo_open=True)
    one_of("CurriculumConfig", config, "credit", CREDITS)
    one_of("CurriculumConfig", config, "distance_origin", DISTANCE_ORIGINS)
    validate_selector(config)
    if config.overlap and config.selector not in ("map", "roughness", "random"):  # one terrain a trial
        raise ValueError(f"CurriculumConfig.overlap needs a one-terrain selector (map, roughness, random), got "
                         f"selector={config.selector!r}")
    if not isinstance(config.overlap, bool):
        raise ValueError(f"CurriculumConfig.overlap must be True or False, got {config.overlap!r}")
    if not isinstance(config.eval_lag, bool):
        raise ValueError(f"CurriculumConfig.eval_lag must be True or False, got {config.eval_lag!r}")
    if config.eval_lag and not config.overlap:
        raise ValueError("CurriculumConfig.eval_lag needs CurriculumConfig.overlap (each evaluation riding along the "
                         "next chunk's training); overlap is False")
    _check_ppo(config.ppo)
    if config.steps_per_chunk % config.steps_per_update:
        raise ValueError(
            f"CurriculumConfig.ppo: num_envs x unroll_length x num_unrolls ({config.steps_per_update}) must divide "
            f"epochs_per_chunk x steps_per_epoch ({config.steps_per_chunk})")
    return config


def _check_ppo(ppo) -> None:
    """``CurriculumConfig.ppo``: a valid ``PPOConfig`` that sets nothing but the :data:`FINE_TUNED` fields."""
    if not isinstance(ppo, PPOConfig):
        raise ValueError(f"CurriculumConfig.ppo must be a jaxterrain.rl.PPOConfig, got {type(ppo).__name__}")
    try:
        validate_ppo_config(ppo)
    except ValueError as err:
        raise ValueError(f"CurriculumConfig.ppo: {err}") from None
    for name in PPOConfig._fields:
        if name not in FINE_TUNED and getattr(ppo, name) != PPOConfig._field_defaults[name]:
            raise ValueError(f"CurriculumConfig.ppo.{name} must keep PPOConfig's default "
                             f"({PPOConfig._field_defaults[name]!r}): fine-tuning uses the base policy's; only "
                             f"{', '.join(FINE_TUNED)} are set here, got {getattr(ppo, name)!r}")

"""``map``: the paper's IT&E map-based curriculum (Howard et al. 2022, Experiment 2). A GP over the archive's
descriptor space, its prior the archive's fitness, its observations the evaluations of finished terrains; the next
terrain is the UCB argmax among those left, and after a terrain T is finished the terrains the updated GP predicts
clearly easier than T are removed (:func:`removal_mask`; the margin and ties are our choices, documented in
:mod:`jaxterrain.curriculum.config`). The first terrain is the argmax of the prior (no observation yet: the UCB is
the prior + kappa)."""

from __future__ import annotations

from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp

from jaxterrain.curriculum import gp
from jaxterrain.curriculum.selectors.base import float_in
from jaxterrain.curriculum.selectors.protocol import Selector, register_selector
from jaxterrain.curriculum.selectors.sequence import sequence_selector
from jaxterrain.qd import TerrainBank
from jaxterrain.runtime.validation import int_at_least, one_of

__all__ = ["MapParams", "map_selector", "gp_params", "removal_mask", "validate_map", "GP_EVALUATIONS",
           "REMOVAL_TIES", "FLAT"]

GP_EVALUATIONS = ("final", "best")
REMOVAL_TIES = ("nearer", "keep", "remove")
OWNER = "CurriculumConfig.params"


class MapParams(NamedTuple):
    """``map``'s parameters (defaults: IT&E's and the choices of :mod:`jaxterrain.curriculum.config`).

    kappa: UCB exploration weight (IT&E: 0.05), >= 0. rho, sigma_f, noise: GP length scale, signal variance,
    observation noise (IT&E: 0.4, 1, 0.001), > 0. gp_evaluation: ``final`` or ``best`` evaluation of a finished
    terrain enters the GP. removal_margin: fitness margin of the removal rule, >= 0. removal_ties: ``nearer``,
    ``keep`` or ``remove``: terrains predicted within the margin of the one just trained. max_observations: GP
    observation slots ``M``; None = ``min(N terrains, max chunks)``, which can never fill up (one observation per
    finished terrain, each terrain finished at most once)."""

    kappa: float = 0.05
    rho: float = 0.4
    sigma_f: float = 1.0
    noise: float = 0.001
    gp_evaluation: str = "final"
    removal_margin: float = 0.05
    removal_ties: str = "nearer"
    max_observations: Optional[int] = None


FLAT = {name: name for name in MapParams._fields}
"""``learn``'s config keys of :class:`MapParams` (the same names)."""


def gp_params(params) -> gp.GPParams:
    """The GP's hyper-parameters of :class:`MapParams` (anything with ``rho``, ``sigma_f``, ``noise``)."""
    return gp.GPParams(rho=params.rho, sigma_f=params.sigma_f, noise=params.noise)


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


def _posterior(bank: TerrainBank, obs_index, obs_y, params: MapParams):
    mask = obs_index >= 0
    idx = jnp.maximum(obs_index, 0)
    return gp.posterior(bank.points[idx], obs_y, mask, bank.fitness[idx], bank.points, bank.fitness,
                        gp_params(params))


def map_selector(config) -> Selector:
    """The IT&E map-based curriculum of ``config`` (its ``params``: :class:`MapParams`, None for the defaults)."""
    p = config.params if config.params is not None else MapParams()

    def initial(bank, key):
        n = bank.fitness.shape[0]
        return jnp.ones(n, bool), gp.ucb(bank.fitness, jnp.full((n,), p.sigma_f, jnp.float32), p.kappa)

    def following(s, bank, key, trained, obs_index, obs_y, hardness):
        mean, var = _posterior(bank, obs_index, obs_y, p)
        return removal_mask(mean, trained, hardness, p.removal_margin, p.removal_ties), gp.ucb(mean, var, p.kappa)

    return sequence_selector(config, "map", initial, following, p.gp_evaluation, p.max_observations)


def validate_map(config, p: MapParams) -> None:
    """``ValueError`` naming the first bad field of :class:`MapParams` (``CurriculumConfig.params.<field>``)."""
    float_in(OWNER, p, "kappa", 0.0, None, lo_open=False)
    for name in ("rho", "sigma_f", "noise"):
        float_in(OWNER, p, name, 0.0, None, lo_open=True)
    float_in(OWNER, p, "removal_margin", 0.0, None, lo_open=False)
    one_of(OWNER, p, "gp_evaluation", GP_EVALUATIONS)
    one_of(OWNER, p, "removal_ties", REMOVAL_TIES)
    if p.max_observations is not None:
        int_at_least(OWNER, p, "max_observations", 1)


register_selector("map", map_selector, MapParams, validate_map, FLAT)

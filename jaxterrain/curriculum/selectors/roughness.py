"""``roughness``: standard CL, the paper's Figure 7b baseline. The terrains sorted by descriptor 0 (roughness)
ascending, every ``stride``-th one (:func:`~jaxterrain.curriculum.selectors.base.roughness_sequence`), trained in
that order, each finished by the sequence rule (threshold or ``max_evals``)."""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

from jaxterrain.curriculum.selectors.base import roughness_sequence
from jaxterrain.curriculum.selectors.protocol import Selector, register_selector
from jaxterrain.curriculum.selectors.sequence import sequence_selector
from jaxterrain.runtime.validation import int_at_least

__all__ = ["RoughnessParams", "roughness_selector", "validate_roughness"]


class RoughnessParams(NamedTuple):
    """``roughness``' parameters. stride: every ``stride``-th terrain of the roughness order is trained (paper: 5),
    >= 1."""

    stride: int = 5


def roughness_selector(config) -> Selector:
    """Standard CL of ``config`` (its ``params``: :class:`RoughnessParams`, None for the defaults)."""
    stride = (config.params if config.params is not None else RoughnessParams()).stride

    def initial(bank, key):
        rank, member = roughness_sequence(bank, stride)
        return member, -rank.astype(jnp.float32)

    def following(s, bank, key, trained, obs_index, obs_y, hardness):
        used = jnp.arange(bank.fitness.shape[0]) == trained
        return used, -roughness_sequence(bank, stride)[0].astype(jnp.float32)

    return sequence_selector(config, "roughness", initial, following)


def validate_roughness(config, p: RoughnessParams) -> None:
    """``CurriculumConfig.params.stride`` must be an integer >= 1."""
    int_at_least("CurriculumConfig.params", p, "stride", 1)


register_selector("roughness", roughness_selector, RoughnessParams, validate_roughness, {"roughness_stride": "stride"})

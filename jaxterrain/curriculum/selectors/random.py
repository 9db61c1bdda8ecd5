"""``random``: uniformly random among the terrains not yet trained, each removed after it is finished (the
sequence rule), no GP. No parameters of its own."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxterrain.curriculum.selectors.protocol import Selector, register_selector
from jaxterrain.curriculum.selectors.sequence import sequence_selector

__all__ = ["random_selector"]


def random_selector(config) -> Selector:
    """The random order of ``config`` (``config.params`` unused: None)."""

    def initial(bank, key):
        n = bank.fitness.shape[0]
        return jnp.ones(n, bool), jax.random.uniform(key, (n,))

    def following(s, bank, key, trained, obs_index, obs_y, hardness):
        n = bank.fitness.shape[0]
        return jnp.arange(n) == trained, jax.random.uniform(key, (n,))

    return sequence_selector(config, "random", initial, following)


register_selector("random", random_selector)

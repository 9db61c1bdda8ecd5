"""The difficulty protocol (:class:`Protocol`, :data:`PAPER`, :data:`HEADINGS`) and the pure functions that turn a
protocol's walked distances into a fitness (:func:`best_of`, :func:`rotate_headings`, :func:`aggregate`,
:func:`heading_scores`). This module holds no walker, no policy and no compiled program (those are
:mod:`jaxterrain.difficulty.evaluation`'s).
"""

from __future__ import annotations

import numbers
import operator
from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.walker import WalkerConfig

__all__ = ["RULES", "HEADING_TURNS", "Protocol", "PAPER", "HEADINGS", "protocol_env_config", "protocol_from", "best_of",
           "rotate_headings", "aggregate", "by_heading", "heading_scores"]

# ----------------------------------------------------------------------------------------------------------------
# The protocol
# ----------------------------------------------------------------------------------------------------------------
RULES = ("mean", "min")
HEADING_TURNS = {1: (0,), 2: (0, 1), 4: (0, 1, 2, 3)}
"""Quarter turns (``jnp.rot90`` k) of the map per number of headings: 2 headings walk +x and +y (both axes)."""


class Protocol(NamedTuple):
    """How terrain difficulty is measured: ``Protocol()`` is the paper's protocol exactly (same numbers as before
    for the same key); hashable, so it can key compiled functions.

    Attributes:
      attempts: rollouts per terrain in total, >= 1, a multiple of ``headings``; each heading gets
        ``per_heading = attempts // headings`` of them.
      best: the best (largest) distances kept PER HEADING, in [1, per_heading]; the heading's score is their mean.
      headings: 1, 2 or 4. The walker always walks +x along the map's centre line; heading ``k`` walks the map
        rotated by ``jnp.rot90(map, k)`` (``HEADING_TURNS``: 1 -> k = 0; 2 -> k = 0, 1; 4 -> k = 0, 1, 2, 3), which
        is walking the ORIGINAL map along +x, +y, -x, -y (rows are y, columns x). Maps must be square for
        ``headings > 1``.
      start_spread: metres; > 0 starts each walk at a lateral offset uniform in ``[-start_spread, start_spread]``
        (``WalkerConfig.start_spread``, drawn from the reset key), so the attempts cross the map along different
        lines. 0 (default) starts on the centre line and draws nothing (the paper's walk, bit for bit).
      rule: how the per-heading scores make one fitness, ``"mean"`` (default) or ``"min"``.

    Why ``rule="mean"`` (the mean over headings of each heading's best-``best`` mean):

    - It is the fitness of a heading drawn at random: a property of the terrain as a whole, not of one line across
      it. A terrain the walker crosses along x but not along y (the CPPN's ridges parallel to +x) scores about 0.5,
      below the curriculum's 0.9 threshold, instead of 1.
    - It is graded: one, two or three hard headings out of four give about 0.75, 0.5 and 0.25. ``"min"`` maps every
      terrain with ONE impassable heading to about 0, which flattens the hard half of an archive into ties that
      neither MAP-Elites nor the curriculum's GP can rank.
    - It is unbiased under noise: averaging four estimates reduces their variance, while the minimum of four noisy
      estimates is biased low (it picks the unluckiest heading), the more so the noisier the policy on a terrain.
    ``"min"`` stays available for a worst-case definition (every direction must be passable).

    With ``headings=4`` the paper's 20 attempts become 5 per heading; ``HEADINGS`` keeps the paper's per-direction
    rule instead (20 attempts per heading, best 5), at 4x the rollouts: see its docstring.
    """

    attempts: int = 20
    best: int = 5
    headings: int = 1
    start_spread: float = 0.0
    rule: str = "mean"

    @property
    def per_heading(self) -> int:
        """Rollouts per heading, ``attempts // headings``."""
        return self.attempts // self.headings

    def validate(self) -> "Protocol":
        """This protocol with plain Python types, or ``ValueError`` naming the field and its allowed values."""
        def is_int(v):
            return isinstance(v, numbers.Integral) and not isinstance(v, bool)

        if not is_int(self.attempts) or int(self.attempts) < 1:
            raise ValueError(f"protocol.attempts must be an int >= 1, got {self.attempts!r}")
        if not is_int(self.headings) or int(self.headings) not in HEADING_TURNS:
            raise ValueError(f"protocol.headings must be one of {sorted(HEADING_TURNS)}, got {self.headings!r}")
        attempts, headings = int(self.attempts), int(self.headings)
        if attempts % headings:
            raise ValueError(f"protocol.attempts must be a multiple of protocol.headings={headings}, got {attempts}")
        if not is_int(self.best) or not 1 <= int(self.best) <= attempts // headings:
            raise ValueError(f"protocol.best must be an int in [1, attempts / headings = {attempts // headings}] "
                             f"(the best attempts kept per heading), got {self.best!r}")
        try:
            spread = float("nan") if isinstance(self.start_spread, (str, bytes, bool)) else float(self.start_spread)
        except (TypeError, ValueError):
            spread = float("nan")
        if not (spread >= 0.0 and spread < float("inf")):
            raise ValueError(f"protocol.start_spread must be a finite number >= 0 (metres), got {self.start_spread!r}")
        if self.rule not in RULES:
            raise ValueError(f"protocol.rule must be one of {RULES}, got {self.rule!r}")
        return Protocol(attempts, int(self.best), headings, spread, str(self.rule))


PAPER = Protocol()
"""The paper's protocol: 20 attempts along +x from the centre of the start edge, mean of the best 5."""

HEADINGS = Protocol(attempts=80, best=5, headings=4)
"""The four-heading protocol: the paper's rule (best 5 of 20) in each of the four headings, then the mean over
headings (``rule="mean"``, see :class:`Protocol`). Heading 0 alone is the paper's protocol, so the two differ only
by the three added headings. It costs 4x the rollouts but fewer env steps than that, since walks across a hard
heading end early: on the shipped CPPN / Perlin archives 2.9x / 3.5x the env steps and 2.1x / 2.2x the seconds of
the paper's protocol on an H100 (``docs/results/gradient.md``). ``Protocol(20, 5, headings=4)`` (best 5 of 5 per
heading) costs the paper's 20 rollouts but also drops the paper's best-of filter, so it scores every terrain lower,
heading or not."""


def protocol_env_config(config: WalkerConfig, protocol: Protocol) -> WalkerConfig:
    """``config`` with the protocol's ``start_spread``; ``ValueError`` if ``config`` already sets another one."""
    spread = float(protocol.start_spread)
    if config.start_spread not in (0.0, spread):
        raise ValueError(f"env_config.start_spread={config.start_spread} differs from protocol.start_spread={spread};"
                         " set it in one of them")
    return config._replace(start_spread=spread)


def protocol_from(protocol: Optional[Protocol], attempts: Optional[int], best: Optional[int]) -> Protocol:
    """The protocol of a call: ``protocol`` (``attempts`` / ``best`` must then agree) or the paper's with them."""
    if protocol is None:
        return Protocol(20 if attempts is None else attempts, 5 if best is None else best).validate()
    if not isinstance(protocol, Protocol):
        raise ValueError(f"protocol must be a difficulty.Protocol, got {type(protocol).__name__}")
    for name, value in (("attempts", attempts), ("best", best)):
        if value is not None and value != getattr(protocol, name):
            raise ValueError(f"{name}={value!r} conflicts with protocol.{name}={getattr(protocol, name)!r}; "
                             "give one of them")
    return protocol.validate()


# ----------------------------------------------------------------------------------------------------------------
# From a protocol's distances to a fitness (pure; jit / vmap them yourself)
# ----------------------------------------------------------------------------------------------------------------
def _check_distances(distances, where: str = "distances") -> tuple:
    """The static shape of ``distances`` (a real array, traced or not), or ``ValueError`` naming it."""
    shape, dtype = getattr(distances, "shape", None), getattr(distances, "dtype", None)
    if shape is None or dtype is None:
        try:
            distances = np.asarray(distances)
        except (TypeError, ValueError):
            raise ValueError(f"{where} must be a real array [B, attempts]; got {type(distances).__name__}") from None
        shape, dtype = distances.shape, distances.dtype
    if np.dtype(dtype).kind not in "biuf":
        raise ValueError(f"{where} must be a real array [B, attempts]; got dtype {dtype}")
    return tuple(shape)


def best_of(distances: jax.Array, best: int) -> jax.Array:
    """``[B, attempts]`` -> ``[B]``: mean of the ``best`` largest distances per row (NaN counted as 0).
    (Any leading axes ``[..., attempts]`` are kept.) ``best`` must be an int in ``[1, attempts]``."""
    shape = _check_distances(distances)
    if len(shape) < 1:
        raise ValueError(f"distances must have shape [B, attempts]; got shape {shape}")
    try:
        k = None if isinstance(best, (bool, np.bool_)) else operator.index(best)  # ints, numpy / concrete jax ints
    except TypeError:
        k = None
    if k is None or not 1 <= k <= shape[-1]:
        raise ValueError(f"best must be an int in [1, attempts = {shape[-1]}] (distances' last axis), got {best!r}")
    d = jnp.nan_to_num(jnp.asarray(distances, jnp.float32), nan=0.0, posinf=0.0, neginf=0.0)
    return jnp.mean(jax.lax.top_k(d, k)[0], axis=-1)


def rotate_headings(terrains: jax.Array, headings: int) -> jax.Array:
    """``[B, H, W]`` -> ``[B * headings, H, W]``: row ``b * headings + i`` is terrain ``b`` turned by
    ``jnp.rot90(., HEADING_TURNS[headings][i])``, so that walking +x on it walks the original along +x, +y, -x or -y
    (rows are y, columns x: ``rot90(m, 1)[i, j] = m[j, W - 1 - i]``, its +x is the original's +y). ``headings`` must
    be 1, 2 or 4; for more than 1 the maps must be square (H == W)."""
    if isinstance(headings, bool) or headings not in HEADING_TURNS:
        raise ValueError(f"headings must be one of {sorted(HEADING_TURNS)}, got {headings!r}")
    if len(getattr(terrains, "shape", ())) != 3:
        raise ValueError(f"terrains must have shape [B, H, W]; got "
                         f"{tuple(terrains.shape) if hasattr(terrains, 'shape') else type(terrains).__name__}")
    if headings == 1:
        return terrains
    b, h, w = terrains.shape
    if h != w:
        raise ValueError(f"headings={headings} needs square maps (rotations keep the env's shape), got {h} x {w}")
    turned = jnp.stack([jnp.rot90(terrains, k, axes=(-2, -1)) for k in HEADING_TURNS[headings]], axis=1)
    return turned.reshape(b * headings, h, w)


def aggregate(distances: jax.Array, protocol: Protocol) -> jax.Array:
    """``[B, attempts]`` distances, heading-major (attempt ``a`` on heading ``a // per_heading``) -> fitness ``[B]``:
    per heading the mean of the ``protocol.best`` largest, then ``protocol.rule`` over headings. With one heading
    this is :func:`best_of` exactly. ``ValueError`` for a bad protocol or distances of another shape."""
    protocol = _check_protocol_distances(distances, protocol)
    if protocol.headings == 1:
        return best_of(distances, protocol.best)
    per = heading_scores(distances, protocol)  # [B, headings]
    return jnp.mean(per, axis=-1) if protocol.rule == "mean" else jnp.min(per, axis=-1)


def by_heading(distances: jax.Array, protocol: Protocol) -> jax.Array:
    """``[B, attempts]`` -> ``[B, headings, per_heading]``: the attempts of each heading."""
    protocol = _check_protocol_distances(distances, protocol)
    d = jnp.asarray(distances)
    return d.reshape(d.shape[0], protocol.headings, protocol.per_heading)


def heading_scores(distances: jax.Array, protocol: Protocol) -> jax.Array:
    """``[B, attempts]`` -> ``[B, headings]``: each heading's mean of its ``protocol.best`` largest distances."""
    protocol = _check_protocol_distances(distances, protocol)
    return best_of(by_heading(distances, protocol), protocol.best)


def _check_protocol_distances(distances, protocol) -> "Protocol":
    """``protocol`` validated (plain Python fields), after checking that ``distances`` is ``[B, protocol.attempts]``
    (static shapes: also under jit); ``ValueError`` naming the argument otherwise."""
    if not isinstance(protocol, Protocol):
        raise ValueError(f"protocol must be a difficulty.Protocol, got {type(protocol).__name__}")
    protocol = protocol.validate()
    shape = _check_distances(distances)
    if len(shape) != 2 or shape[1] != protocol.attempts:
        raise ValueError(f"distances must have shape [B, protocol.attempts = {protocol.attempts}] (heading-major); "
                         f"got shape {shape}")
    return protocol


# The public home of the protocol is jaxterrain.difficulty (docs, pickles and error messages name it).

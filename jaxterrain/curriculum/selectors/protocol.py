"""The selector protocol and its registry: what every curriculum is (:class:`Selector`, a NamedTuple of pure
functions over its own pytree state), what it is told and tells the trial loop (:class:`Assignment`,
:class:`Outcome`, :class:`Decision`), and the names a ``CurriculumConfig.selector`` can take.

Each algorithm is one module of :mod:`jaxterrain.curriculum.selectors` that owns its parameters (a NamedTuple, the
``CurriculumConfig.params`` of a run of it) and registers itself here with :func:`register_selector`: its factory
``config -> Selector``, its params type, their check and their flat names (the keys of ``learn``'s ``config.json``,
e.g. ``plr_capacity`` for ``PLRParams.capacity``). A plugin registers the same way (params optional); a
``module:object`` name is imported when first resolved.
"""

from __future__ import annotations

import importlib
from typing import Any, Callable, NamedTuple, Optional

import jax
import jax.numpy as jnp

__all__ = ["Assignment", "Outcome", "Decision", "Selector", "SelectorSpec", "register_selector", "selector_names",
           "selector_spec", "resolve_factory", "get_selector", "selector_params", "params_from_flat",
           "validate_selector", "selector_fields", "flat_name", "round_robin"]


class Assignment(NamedTuple):
    """The terrains of a trial's next chunk.

    terrains: [K] int32 bank indices (K = ``Selector.slots``). env_slot: [E] int32, env e trains on
    ``terrains[env_slot[e]]`` (E = the PPO envs of a trial), or None: every env on ``terrains[0]`` (K = 1).
    evaluated: [] int32 slot whose terrain the policy is evaluated on after the chunk."""

    terrains: jax.Array
    env_slot: Optional[jax.Array]
    evaluated: jax.Array


class Outcome(NamedTuple):
    """What a chunk showed. terrain: [] int32 the evaluated bank index. fitness: [] float32 its evaluation (the
    difficulty protocol, in [0, 1]). progress: [E] float32 each PPO env's furthest normalised distance since the
    chunk's restart, or None when the selector does not need it (sequence selectors)."""

    terrain: jax.Array
    fitness: jax.Array
    progress: Optional[jax.Array] = None


class Decision(NamedTuple):
    """What the loop does next. finished: [] bool the evaluated terrain's stint ended (``credit = "finished"``
    credits it). restart: [] bool the envs restart on the new assignment before the next chunk. exhausted: [] bool no
    terrain is left, the trial ends."""

    finished: jax.Array
    restart: jax.Array
    exhausted: jax.Array


class Selector(NamedTuple):
    """A curriculum's choice of terrains (pure functions; ``jax.vmap`` them over trials).

    name: its ``CurriculumConfig.selector``. slots: K terrains per chunk (static; 1 = every env on one terrain).
    progress: whether :func:`update` reads ``Outcome.progress`` (the loop computes it only then).
    init: ``(key, bank) -> state``. assign: ``state -> Assignment``. update: ``(state, key, bank, Outcome) ->
    (state, Decision)``. summary: ``state -> {name: [] array}``, what a treatment's ``summary.json`` records per
    trial (e.g. terrains finished, final levels). maps: None (the assignment's terrains are
    ``bank.heightmaps[Assignment.terrains]``), or ``(state, bank) -> [K, H, W]`` float32 metres, the slots' maps
    for selectors whose levels are not bank terrains (``accel``: genomes rendered in the loop; their
    ``Assignment.terrains`` entries are -1, except the evaluated slot, which must be a bank terrain)."""

    name: str
    slots: int
    init: Callable
    assign: Callable
    update: Callable
    summary: Callable
    progress: bool = False
    maps: Optional[Callable] = None


class SelectorSpec(NamedTuple):
    """A registered selector. factory: ``config -> Selector``. params: the NamedTuple type of its
    ``CurriculumConfig.params`` (None: it takes none; ``params=None`` in a config means ``params()``, the defaults).
    validate: ``(config, params) -> None``, raising ``ValueError`` naming ``CurriculumConfig.params.<field>``, or
    None. flat: ``{flat key: params field}``, the names its fields have in a flat config (``learn``'s
    ``config.json`` and flags: ``plr_capacity`` is ``PLRParams.capacity``)."""

    factory: Callable[[Any], Selector]
    params: Optional[type] = None
    validate: Optional[Callable[[Any, Any], None]] = None
    flat: dict = {}


_REGISTRY: dict[str, SelectorSpec] = {}


def register_selector(name: str, factory: Callable[[Any], Selector], params: Optional[type] = None,
                      validate: Optional[Callable[[Any, Any], None]] = None, flat: Optional[dict] = None) -> None:
    """Make ``CurriculumConfig(selector=name)`` (and ``learn --curriculum name``) build ``factory(config)``;
    ``params`` / ``validate`` / ``flat``: see :class:`SelectorSpec` (a plugin may leave them out)."""
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"selector name must be an identifier, got {name!r}")
    if not callable(factory):
        raise ValueError(f"selector {name!r}: the factory must be callable (config -> Selector)")
    _REGISTRY[name] = SelectorSpec(factory, params, validate, dict(flat or {}))


def selector_names() -> tuple[str, ...]:
    """The registered selector names (the built-in ones first)."""
    return tuple(_REGISTRY)


def _imported(spec: str) -> Callable[[Any], Selector]:
    """``module:object`` -> the object (a factory ``config -> Selector``, or a :class:`Selector`); ``ValueError``
    naming ``spec`` when the module does not import (whatever it raises: it is the user's code) or lacks the
    object, or the object is neither callable nor a Selector."""
    module, _, attr = spec.partition(":")
    try:
        obj = getattr(importlib.import_module(module), attr)
    except Exception as err:  # noqa: BLE001 - any failure of the user's module is reported in one line
        text = str(err).splitlines()[0] if str(err) else ""
        raise ValueError(f"CurriculumConfig.selector {spec!r}: cannot import it ({type(err).__name__}: {text})") \
            from None
    if not isinstance(obj, Selector) and not callable(obj):
        raise ValueError(f"CurriculumConfig.selector {spec!r}: {type(obj).__name__} is neither a Selector nor a "
                         f"factory (config -> Selector)")
    return (lambda config: obj) if isinstance(obj, Selector) else obj


def selector_spec(name: str) -> SelectorSpec:
    """The :class:`SelectorSpec` of a selector name (registered, or ``module:object``: a spec without params);
    ``ValueError`` naming the choices."""
    if isinstance(name, str) and name in _REGISTRY:
        return _REGISTRY[name]
    if isinstance(name, str) and ":" in name:
        return SelectorSpec(_imported(name))
    raise ValueError(f"CurriculumConfig.selector must be one of {', '.join(_REGISTRY)} or module:object, "
                     f"got {name!r}")


def resolve_factory(name: str) -> Callable[[Any], Selector]:
    """The factory of a selector name (registered, or ``module:object``); ``ValueError`` naming the choices."""
    return selector_spec(name).factory


def selector_params(config) -> Any:
    """``config.params``, or the selector's default params when it is None (None for a selector without params)."""
    if config.params is not None:
        return config.params
    params = selector_spec(config.selector).params
    return None if params is None else params()


def params_from_flat(selector: str, flat: dict) -> Any:
    """The params of ``selector`` from a flat config's keys (:attr:`SelectorSpec.flat`; keys of other selectors
    are not read), None when it has no params type or none of its keys is in ``flat``."""
    spec = _REGISTRY.get(selector) if isinstance(selector, str) else None
    if spec is None or spec.params is None:
        return None
    given = {field: flat[key] for key, field in spec.flat.items() if key in flat}
    return spec.params(**given) if given else None


def validate_selector(config) -> None:
    """The selector's name resolves and ``config.params`` is its params type (or None), checked by its own rule:
    ``ValueError`` naming ``CurriculumConfig.selector`` or ``CurriculumConfig.params.<field>``."""
    spec = selector_spec(config.selector)
    if config.params is not None and spec.params is not None and not isinstance(config.params, spec.params):
        raise ValueError(f"CurriculumConfig.params must be a {spec.params.__name__} for selector "
                         f"{config.selector!r} (or None: its defaults), got {type(config.params).__name__}")
    if spec.validate is not None:
        spec.validate(config, selector_params(config))


def selector_fields(names=None) -> dict[str, tuple[str, ...]]:
    """``{flat key: (selectors that read it)}`` over the registered selectors (or ``names``), in order."""
    out: dict[str, tuple[str, ...]] = {}
    for name in names or selector_names():
        for key in _REGISTRY[name].flat:
            out[key] = out.get(key, ()) + (name,)
    return out


def flat_name(selector: str, field: str) -> str:
    """The flat key (``learn``'s config key) of ``selector``'s params field ``field``; ``field`` itself when it
    has none."""
    spec = _REGISTRY.get(selector)
    for key, f in (spec.flat if spec is not None else {}).items():
        if f == field:
            return key
    return field


def round_robin(num_envs: int, slots: int) -> jax.Array:
    """``[num_envs]`` int32: env e on slot ``e % slots``."""
    return jnp.arange(num_envs, dtype=jnp.int32) % slots


def get_selector(config) -> Selector:
    """The :class:`Selector` of ``config.selector`` built for ``config`` (its ``params``)."""
    selector = resolve_factory(config.selector)(config)
    if not isinstance(selector, Selector):
        raise ValueError(f"CurriculumConfig.selector {config.selector!r}: its factory returned "
                         f"{type(selector).__name__}, not a jaxterrain.curriculum.Selector")
    return selector

"""Host-side checks of config fields shared by the typed configs (:class:`jaxterrain.rl.PPOConfig`,
:class:`jaxterrain.curriculum.CurriculumConfig`), so that every config words its errors alike: each raises
``ValueError`` naming ``Owner.field``, what it allows and the value it got."""

from __future__ import annotations

from typing import Any, Iterable


def int_at_least(owner: str, config: Any, name: str, lo: int) -> None:
    """``config.name`` must be a Python ``int`` (not a bool) >= ``lo``."""
    v = getattr(config, name)
    if not isinstance(v, int) or isinstance(v, bool) or v < lo:
        raise ValueError(f"{owner}.{name} must be an integer >= {lo}, got {v!r}")


def one_of(owner: str, config: Any, name: str, options: tuple) -> None:
    """``config.name`` must be one of ``options``."""
    v = getattr(config, name)
    if v not in options:
        raise ValueError(f"{owner}.{name} must be one of {options}, got {v!r}")


def known_fields(owner: str, fields: Iterable[str], d: dict) -> None:
    """Every key of ``d`` (a config read from JSON) must be one of ``fields``."""
    unknown = set(d) - set(fields)
    if unknown:
        raise ValueError(f"{owner}: unknown fields {sorted(unknown)}")

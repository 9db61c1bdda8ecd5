"""Host-side checks of config fields shared by the typed configs (:class:`jaxterrain.rl.PPOConfig`,
:class:`jaxterrain.curriculum.CurriculumConfig`), so that every config words its errors alike: each raises
``ValueError`` naming ``Owner.field``, what it allows and the value it got."""

from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np

__all__ = ["int_at_least", "one_of", "known_fields", "walks", "concrete", "positive"]


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


def walks(owner: str, config: Any) -> None:
    """A config's walker protocol: ``config.headings`` in (1, 2, 4), ``config.attempts`` (walks in total, already
    an int >= 1) a multiple of it, ``config.best`` (per heading) at most ``attempts / headings``."""
    one_of(owner, config, "headings", (1, 2, 4))
    per = config.attempts // config.headings
    if config.attempts % config.headings:
        raise ValueError(f"{owner}.attempts must be a multiple of headings ({config.headings}), got {config.attempts}")
    if config.best > per:
        raise ValueError(f"{owner}.best must be <= attempts / headings ({per}), got {config.best}")


def concrete(value: Any) -> bool:
    """Whether ``value`` has a value on the host now (a Python number or a concrete array), not a JAX tracer inside
    ``jit`` / ``vmap``: checks of values run only on concrete ones, shapes always."""
    try:
        np.asarray(value)
    except Exception:  # a tracer (jax.errors.TracerArrayConversionError and kin)
        return False
    return True


def positive(where: str, value: Any, allow_zero: bool = False) -> None:
    """``value`` (a number or a concrete [] array; tracers pass unchecked) must be a finite real number > 0
    (``>= 0`` with ``allow_zero``); ValueError naming ``where`` otherwise (a string, a bool, NaN, a negative)."""
    if not concrete(value):
        return
    bound = ">= 0" if allow_zero else "> 0"
    if isinstance(value, (str, bytes, bool)) or np.ndim(value) != 0:
        raise ValueError(f"{where} must be a finite number {bound}; got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{where} must be a finite number {bound}; got {value!r}") from None
    if not math.isfinite(v) or (v < 0 if allow_zero else v <= 0):
        raise ValueError(f"{where} must be a finite number {bound}; got {value!r}")

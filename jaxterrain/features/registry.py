"""The descriptor registry: names -> ``heightmaps[B, H, W] -> [B]`` functions, the built-in features and any a user
or plugin registers (:func:`register_descriptor`); :func:`descriptors` computes several at once.

    descriptors(h, names=("tri", "tpi", "roughness"), window=30, stride=2)   # [B, len(names)] float32
"""

from __future__ import annotations

from typing import Callable, Iterable, NamedTuple, Sequence

import jax
import jax.numpy as jnp

from jaxterrain.features.kernels import (
    BUILTIN,
    as_batch,
    builtin_descriptors,
    check_heights,
    check_window,
    chunked_builtin_descriptors,
)

__all__ = ["Descriptor", "register_descriptor", "unregister_descriptor", "descriptor_names", "descriptors"]




class Descriptor(NamedTuple):
    """A registered descriptor: ``fn(heightmaps[B, H, W]) -> [B]``, or ``fn(heightmaps, window, stride) -> [B]``
    when ``windowed`` (the built-in features)."""

    fn: Callable
    windowed: bool


def _builtin_fn(name: str) -> Callable:
    def fn(heightmaps, window: int = 30, stride: int = 2):
        h, _ = as_batch(heightmaps)
        window, stride = check_window(h.shape, window, stride)
        return builtin_descriptors(h, (name,), window, stride)[name]

    fn.__name__ = f"{name}_descriptor"
    return fn


_REGISTRY: dict[str, Descriptor] = {name: Descriptor(_builtin_fn(name), True) for name in BUILTIN}


def register_descriptor(name: str, fn: Callable, *, windowed: bool = False, overwrite: bool = False) -> None:
    """Add a descriptor usable by name in :func:`descriptors`.

    Args:
      name: a new name (``overwrite=True`` to replace an existing non-built-in one).
      fn: ``fn(heightmaps[B, H, W] float32) -> [B]`` (e.g. a learned traversability model with its parameters
        closed over), or with ``windowed=True`` ``fn(heightmaps, window, stride) -> [B]``. It must be traceable
        (jit / vmap-able) if callers jit :func:`descriptors`.
    """
    if not isinstance(name, str) or not name:
        raise ValueError(f"name must be a non-empty string; got {name!r}")
    if not callable(fn):
        raise ValueError(f"fn must be callable heightmaps[B, H, W] -> [B]; got {fn!r}")
    if name in BUILTIN:
        raise ValueError(f"name {name!r} is a built-in descriptor and cannot be replaced; built-ins: {BUILTIN}")
    if name in _REGISTRY and not overwrite:
        raise ValueError(f"descriptor {name!r} is already registered; pass overwrite=True to replace it")
    _REGISTRY[name] = Descriptor(fn, bool(windowed))


def unregister_descriptor(name: str) -> None:
    """Remove a descriptor added with :func:`register_descriptor` (built-ins cannot be removed)."""
    if name in BUILTIN:
        raise ValueError(f"name {name!r} is a built-in descriptor and cannot be removed")
    if name not in _REGISTRY:
        raise ValueError(f"unknown descriptor {name!r}; registered: {descriptor_names()}")
    del _REGISTRY[name]


def descriptor_names() -> tuple[str, ...]:
    """Names accepted by :func:`descriptors`: the built-ins ``tri`` (Wilson), ``tri_riley``, ``tpi`` (mean |TPI|), ``tpi_signed``,
    ``roughness``, ``faces`` (vertical-face density) and ``max_step`` (largest step per window), then registered ones in
    registration order."""
    return tuple(_REGISTRY)


def descriptors(
    heightmaps, names: Sequence[str] = ("tri", "tpi", "roughness"), window: int = 30, stride: int = 2
) -> jax.Array:
    """Scalar descriptors: the mean over the map of each named feature (paper: window 30, stride 2).

    Built-in names are computed together (shared shifted views; under ``jit`` XLA fuses them); other names call
    their registered function on the whole batch. Not jitted: callers jit with
    ``static_argnames=("names", "window", "stride")`` (``names`` as a tuple).

    Args:
      heightmaps: ``[B, H, W]`` (or ``[H, W]``) float heightmaps in [0, 1]; concrete input holding NaN or values
        outside [0, 1] raises ``ValueError`` (not checked under jit, where values are unknown).
      names: descriptor names, see :func:`descriptor_names`.
      window, stride: as in :func:`tri`; only used by windowed descriptors.

    Returns:
      ``[B, len(names)]`` float32 in the order of ``names`` (``[len(names)]`` for a single map).
    """
    if isinstance(names, str):
        names = (names,)
    if names is None or not isinstance(names, Iterable) or not all(isinstance(n, str) for n in names):
        raise ValueError(f"names must be a sequence of descriptor names out of {descriptor_names()}; got {names!r}")
    names = tuple(names)
    if not names:
        raise ValueError(f"names must name at least one descriptor out of {descriptor_names()}")
    unknown = [n for n in names if n not in _REGISTRY]
    if unknown:
        raise ValueError(f"unknown descriptor name(s) {unknown}; valid names: {descriptor_names()}")
    h, single = as_batch(heightmaps)
    check_heights(h, single)
    if any(_REGISTRY[n].windowed for n in names):
        window, stride = check_window(h.shape, window, stride)
    builtin = chunked_builtin_descriptors(h, [n for n in dict.fromkeys(names) if n in BUILTIN], window, stride)
    cols = []
    for n in names:
        if n in builtin:
            col = builtin[n]
        else:
            d = _REGISTRY[n]
            col = d.fn(h, window, stride) if d.windowed else d.fn(h)
            col = jnp.asarray(col)
            if col.shape != (h.shape[0],):
                raise ValueError(
                    f"descriptor {n!r} returned shape {tuple(col.shape)}; it must return [B] = ({h.shape[0]},)"
                )
        cols.append(col.astype(jnp.float32))
    out = jnp.stack(cols, axis=-1)
    return out[0] if single else out

"""Batches over devices with JAX's own runtime: a mesh of every visible device, padding, and row-parallel maps.

    mesh = sharding.make_mesh()                                  # all visible devices (all hosts), axis "batch"
    f = sharding.map_rows(per_row_batch_fn, mesh)                # rows split over devices, padded, unpadded again
    out = f(terrains, keys)                                      # same values as per_row_batch_fn(terrains, keys)

A batch whose length does not divide over the devices is PADDED with copies of its last row to the next multiple
(the copies compute real, finite values) and the padding is cut off the result: never an error. A function that
treats every row independently (its row ``i`` depends only on row ``i`` of each input, e.g. keys derived per row
before the call) then gives the same values sharded and unsharded, bit for bit on CPU.

Several hosts: call :func:`initialize` first in every process (one process per host, each seeing its local
devices); ``make_mesh()`` then spans all hosts' devices and the same programs run unchanged.
"""

from __future__ import annotations

import os
from typing import Any, Callable, Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P

__all__ = ["AXIS", "SPLITS", "default_split", "initialize", "make_mesh", "setup", "map_rows", "split_rows", "tracing",
           "pad_rows", "padded_length", "replicate",
           "replicated", "rows", "row_keys", "shard_rows"]

AXIS = "batch"


def initialize(coordinator: Optional[str] = None, num_processes: Optional[int] = None,
               process_id: Optional[int] = None) -> None:
    """Join a multi-process (multi-host) run through ``jax.distributed.initialize``.

    Arguments default to the environment variables ``JAXTERRAIN_COORDINATOR`` (``host:port`` of process 0),
    ``JAXTERRAIN_NUM_PROCESSES`` and ``JAXTERRAIN_PROCESS_ID``; when none is set and no argument is given this
    does nothing (one process). Launch example, two hosts::

        # on host A (process 0) and host B (process 1), the same command but the id:
        JAXTERRAIN_COORDINATOR=hostA:1234 JAXTERRAIN_NUM_PROCESSES=2 JAXTERRAIN_PROCESS_ID=0 python -m experiments ...
    """
    coordinator = coordinator or os.environ.get("JAXTERRAIN_COORDINATOR")
    if num_processes is None and "JAXTERRAIN_NUM_PROCESSES" in os.environ:
        num_processes = int(os.environ["JAXTERRAIN_NUM_PROCESSES"])
    if process_id is None and "JAXTERRAIN_PROCESS_ID" in os.environ:
        process_id = int(os.environ["JAXTERRAIN_PROCESS_ID"])
    if coordinator is None and num_processes is None and process_id is None:
        return
    if jax.distributed.is_initialized():
        return
    if coordinator is None or num_processes is None or process_id is None:
        raise ValueError("initialize: give the coordinator address, num_processes and process_id together "
                         f"(got {coordinator!r}, {num_processes!r}, {process_id!r})")
    if not 0 <= process_id < num_processes:
        raise ValueError(f"initialize: process_id must be in [0, num_processes={num_processes}); got {process_id}")
    jax.config.update("jax_cpu_collectives_implementation", "gloo")  # CPU processes reach each other (GPUs: NCCL)
    jax.distributed.initialize(coordinator_address=coordinator, num_processes=num_processes, process_id=process_id)


def setup(num_devices: Optional[int] = None) -> Mesh:
    """What a command does first: :func:`initialize` from the environment (nothing when the variables are unset),
    then :func:`make_mesh` over the first ``num_devices`` devices of all processes (None: all of them)."""
    initialize()
    return make_mesh(num_devices)


def make_mesh(num_devices: Optional[int] = None, devices: Optional[Sequence[Any]] = None) -> Mesh:
    """A 1-D :class:`~jax.sharding.Mesh` with axis ``"batch"`` over ``devices`` (default: every visible device of
    every process) or the first ``num_devices`` of them. ``ValueError`` if more are asked for than exist."""
    devices = list(jax.devices() if devices is None else devices)
    if num_devices is not None:
        if not isinstance(num_devices, int) or not 1 <= num_devices <= len(devices):
            raise ValueError(f"num_devices must be an integer in [1, {len(devices)}] (visible devices); "
                             f"got {num_devices!r}")
        devices = devices[:num_devices]
    return Mesh(np.asarray(devices), (AXIS,))


def replicated(mesh: Mesh) -> NamedSharding:
    """The sharding of a value held whole on every device of ``mesh`` (e.g. a repertoire, policy parameters)."""
    return NamedSharding(mesh, P())


def rows(mesh: Mesh) -> NamedSharding:
    """The sharding of a value whose leading axis (rows) is split over the devices of ``mesh``."""
    return NamedSharding(mesh, P(AXIS))


def row_keys(key: jax.Array, n: int) -> jax.Array:
    """``[n]`` keys, one per row: ``jax.random.split(key, n)``, drawn for the whole batch BEFORE it is split over
    devices, so that row ``i`` gets the same key on any number of devices."""
    return jax.random.split(key, n)


def padded_length(n: int, mesh: Mesh) -> int:
    """The smallest multiple of the mesh's device count that is >= ``n`` (and >= 1)."""
    d = mesh.devices.size
    return max(1, -(-int(n) // d)) * d


def pad_rows(tree: Any, length: int) -> Any:
    """Pad every leaf's leading axis to ``length`` with copies of its last row (finite, like real rows)."""

    def pad(x):
        x = jnp.asarray(x)
        extra = length - x.shape[0]
        if extra < 0:
            raise ValueError(f"pad_rows: a leaf has {x.shape[0]} rows, more than length={length}")
        if extra == 0:
            return x
        return jnp.concatenate([x, jnp.repeat(x[-1:], extra, axis=0)], axis=0)

    return jax.tree.map(pad, tree)


def shard_rows(tree: Any, mesh: Mesh) -> tuple[Any, jax.Array]:
    """Pad ``tree``'s leading axis (:func:`padded_length`) and place it split over the mesh.

    Returns ``(tree, mask)``: ``mask`` [padded] bool is True for real rows (sharded like the rows)."""
    n = jax.tree.leaves(tree)[0].shape[0]
    length = padded_length(n, mesh)
    spec = NamedSharding(mesh, P(AXIS))
    tree = jax.device_put(pad_rows(tree, length), spec)
    mask = jax.device_put(jnp.arange(length) < n, spec)
    return tree, mask


def _elsewhere(x: Any, sharding: NamedSharding) -> bool:
    """Whether ``x`` is an array committed to devices other than ``sharding``'s (a jitted program over the mesh
    refuses it; uncommitted arrays, NumPy values and tracers it takes as they are)."""
    return (isinstance(x, jax.Array) and not isinstance(x, jax.core.Tracer) and getattr(x, "committed", False)
            and x.sharding.device_set != sharding.device_set)


def _put(x: Any, sharding: NamedSharding) -> Any:
    """``jax.device_put(x, sharding)``; across processes, an array held by this process's devices alone goes
    through the host first (``device_put`` sends only host values, and uncommitted arrays other than PRNG keys, to
    other processes' devices)."""
    local = (isinstance(x, jax.Array) and not isinstance(x, jax.core.Tracer) and x.is_fully_addressable
             and x.sharding.device_set != sharding.device_set)
    if sharding.is_fully_addressable or not local:
        return jax.device_put(x, sharding)
    if jnp.issubdtype(x.dtype, jax.dtypes.prng_key):
        data = jax.device_put(np.asarray(jax.random.key_data(x)), sharding)
        return jax.random.wrap_key_data(data, impl=jax.random.key_impl(x))
    return jax.device_put(np.asarray(x), sharding)


def replicate(tree: Any, mesh: Mesh) -> Any:
    """Place every leaf of ``tree`` whole on every device of the mesh (of every process; each process passes the
    same values)."""
    whole = NamedSharding(mesh, P())
    return jax.tree.map(lambda x: _put(x, whole), tree)


SPLITS = ("shard_map", "dispatch")


def default_split(mesh: Mesh) -> str:
    """How :func:`map_rows` splits rows over ``mesh`` unless told (its ``split`` argument, one of :data:`SPLITS`):
    ``"dispatch"`` for a mesh of this process's GPUs and ``"shard_map"`` otherwise (CPU, several processes). Why
    GPUs dispatch: JAX 0.11.2's CUDA plugin crashes compiling the walker's physics step inside ``shard_map`` (a
    segfault in Shardy's ``ManualComputationUnusedInputsPattern``; under GSPMD a failed ``!IsManualLeaf()`` check),
    measured on 2 H200s on 2026-11-23 (benchmarks/RESULTS.md). A function of the mesh alone: no environment
    variable changes it (the ``JAXTERRAIN_SPLIT`` of earlier versions is gone; pass ``split=`` instead)."""
    devices = list(mesh.devices.flat)
    local = all(d.process_index == jax.process_index() for d in devices)
    return "dispatch" if local and len(devices) > 1 and devices[0].platform == "gpu" else "shard_map"


def map_rows(fn: Callable, mesh: Mesh, replicated: tuple[int, ...] = (), mask: bool = False,
             split: Optional[str] = None) -> Callable:
    """``fn(*args)`` with the rows (leading axis) of every argument split over the mesh's devices.

    ``fn`` maps batched arguments to a batched result (a pytree of arrays whose leading axis is the rows) and must
    treat rows independently; arguments whose positions are in ``replicated`` (e.g. policy parameters) are passed
    whole to every device. The returned function pads the rows to a multiple of the device count, runs ``fn`` on
    each device's rows under ``jax.shard_map`` inside one ``jit``, and returns the real rows only, whole on every
    device (replicated: any process of a multi-host run can read them). Arguments already placed elsewhere (e.g.
    the output of a program compiled for one device) are first put whole on the mesh. With ``mask``, ``fn`` gets
    one more, last argument: ``[rows] bool``, False on the padding rows (e.g. to skip their work).

    ``split`` (None: :func:`default_split`): ``"shard_map"`` compiles ONE program over the mesh (any number of
    processes); ``"dispatch"`` (this process's devices only) compiles ``jax.jit(fn)`` once per device, sends each
    device its rows and lets JAX's asynchronous dispatch run them all at once, then gathers the real rows on the
    mesh's first device. Both give the same values: the rows are independent.
    Inside a ``jit`` trace (tracer arguments) there is nothing to dispatch: the call takes the ``shard_map`` path.
    """
    split = _resolve_split(mesh, split)
    sharded = _shard_map_rows(fn, mesh, frozenset(replicated), mask)
    if split == "shard_map":
        return sharded
    dispatched = _dispatch_rows(fn, mesh, frozenset(replicated), mask)
    return lambda *args: (sharded if tracing(args) else dispatched)(*args)


def tracing(tree: Any) -> bool:
    """Whether any leaf of ``tree`` is a tracer (the call is being traced by ``jit``, ``vmap``, ...)."""
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(tree))


def split_rows(fn: Callable, mesh: Mesh, split: Optional[str] = None) -> Callable:
    """``fn(tree)`` run on each device's share of ``tree``: every leaf's leading axis (a multiple of the device
    count, e.g. padded with :func:`pad_rows`) cut into equal consecutive parts, part ``i`` on device ``i``; the
    outputs' leading axes concatenated in device order. ``split`` as in :func:`map_rows` (``"dispatch"`` only
    outside a trace)."""
    split = _resolve_split(mesh, split)
    sharded = jax.shard_map(fn, mesh=mesh, in_specs=(P(AXIS),), out_specs=P(AXIS), check_vma=False)
    if split == "shard_map":
        return sharded
    devices, jitted = list(mesh.devices.flat), jax.jit(fn)
    return lambda tree: sharded(tree) if tracing(tree) else _dispatch(jitted, devices, [tree], [True])


def _resolve_split(mesh: Mesh, split: Optional[str]) -> str:
    split = default_split(mesh) if split is None else split
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    return split


def _dispatch(jitted: Callable, devices: list, args: list, split: list) -> Any:
    """``jitted`` called on every device at once: ``args[i]`` cut along its leading axis into ``len(devices)``
    equal consecutive parts where ``split[i]`` (part ``k`` to device ``k``), else passed whole; the outputs'
    leaves concatenated along axis 0 on the first device. One thread per device, so that first calls compile at
    the same time and later calls only enqueue work (JAX runs the devices' programs at once)."""
    from concurrent.futures import ThreadPoolExecutor

    if any(d.process_index != jax.process_index() for d in devices):
        raise ValueError("split='dispatch' needs a mesh of this process's devices; use 'shard_map'")
    d = len(devices)

    def part(x, k):
        n = x.shape[0] // d
        return x[k * n:(k + 1) * n]

    def call(k):
        mine = [jax.tree.map(lambda x: part(x, k), a) if cut else a for a, cut in zip(args, split)]
        return jitted(*jax.device_put(mine, devices[k]))

    with ThreadPoolExecutor(d) as pool:
        outs = list(pool.map(call, range(d)))
    return jax.tree.map(lambda *xs: jnp.concatenate([jax.device_put(x, devices[0]) for x in xs]), *outs)


def _shard_map_rows(fn: Callable, mesh: Mesh, replicated: frozenset, mask: bool) -> Callable:
    """:func:`map_rows` with ``split="shard_map"``."""
    whole = NamedSharding(mesh, P())

    def run(*args):
        batched = [a for i, a in enumerate(args) if i not in replicated]
        n = jax.tree.leaves(batched)[0].shape[0]
        length = padded_length(n, mesh)
        specs = tuple(P() if i in replicated else P(AXIS) for i in range(len(args)))
        padded = tuple(a if i in replicated else pad_rows(a, length) for i, a in enumerate(args))
        if mask:
            specs, padded = specs + (P(AXIS),), padded + (jnp.arange(length) < n,)
        out = jax.shard_map(fn, mesh=mesh, in_specs=specs, out_specs=P(AXIS), check_vma=False)(*padded)
        return jax.tree.map(lambda x: x[:n], out)

    jitted = jax.jit(run, out_shardings=whole)

    def call(*args):
        return jitted(*jax.tree.map(lambda x: _put(x, whole) if _elsewhere(x, whole) else x, args))

    return call


def _dispatch_rows(fn: Callable, mesh: Mesh, replicated: frozenset, mask: bool) -> Callable:
    """:func:`map_rows` with ``split="dispatch"``: one single-device program per device of ``mesh`` (this
    process's), each device's rows sent to it (:func:`_dispatch`), the real rows gathered on the first device."""
    devices, jitted = list(mesh.devices.flat), jax.jit(fn)

    def call(*args):
        batched = [a for i, a in enumerate(args) if i not in replicated]
        n = jax.tree.leaves(batched)[0].shape[0]
        length = padded_length(n, mesh)
        padded = [a if i in replicated else pad_rows(a, length) for i, a in enumerate(args)]
        rows = [i not in replicated for i in range(len(args))]
        if mask:
            padded, rows = padded + [jnp.arange(length) < n], rows + [True]
        return jax.tree.map(lambda x: x[:n], _dispatch(jitted, devices, padded, rows))

    return call

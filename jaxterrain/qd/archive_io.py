"""The archive file (``save`` / ``load``): one uncompressed ``.npz`` whose members and JSON header the docstring of
:mod:`jaxterrain.qd.archive` describes."""

from __future__ import annotations

import importlib
import json
import os
import zipfile
from pathlib import Path

import jax
import numpy as np

from jaxterrain.qd.config import Archive, config_from_dict, config_to_dict, resolve_config
from jaxterrain.runtime.io import atomic_save_npz

__all__ = ["FORMAT", "VERSION", "save", "load"]

FORMAT = "jaxterrain-archive"
VERSION = 1


# ----------------------------------------------------------------------------------------------------------------
# Pytree <-> JSON + flat arrays
# ----------------------------------------------------------------------------------------------------------------


def _flatten(tree, leaves: list):
    if tree is None:
        return {"type": "none"}
    if isinstance(tree, tuple) and hasattr(tree, "_fields"):
        cls = type(tree)
        return {
            "type": "namedtuple",
            "class": f"{cls.__module__}:{cls.__qualname__}",
            "fields": list(tree._fields),
            "children": [_flatten(c, leaves) for c in tree],
        }
    if isinstance(tree, (tuple, list)):
        return {"type": type(tree).__name__, "children": [_flatten(c, leaves) for c in tree]}
    if isinstance(tree, dict):
        keys = list(tree)
        if not all(isinstance(k, str) for k in keys):
            raise ValueError(f"archive genomes: dict keys must be strings to be saved; got {keys!r}")
        return {"type": "dict", "keys": keys, "children": [_flatten(tree[k], leaves) for k in keys]}
    if isinstance(tree, (np.ndarray, jax.Array, np.generic, float, int, bool)):
        leaves.append(np.asarray(tree))
        return {"type": "leaf", "index": len(leaves) - 1}
    raise ValueError(
        f"archive genomes: cannot save a pytree node of type {type(tree).__name__}; use arrays in "
        "tuples, lists, dicts or NamedTuples"
    )


def _unflatten(node, leaves: list):
    kind = node["type"]
    if kind == "none":
        return None
    if kind == "leaf":
        return leaves[node["index"]]
    children = [_unflatten(c, leaves) for c in node.get("children", [])]
    if kind == "tuple":
        return tuple(children)
    if kind == "list":
        return children
    if kind == "dict":
        return dict(zip(node["keys"], children))
    if kind == "namedtuple":
        module, _, qualname = node["class"].partition(":")
        try:
            obj = importlib.import_module(module)
            for part in qualname.split("."):
                obj = getattr(obj, part)
        except (ImportError, AttributeError) as err:
            raise ValueError(f"genome class {node['class']} cannot be imported: {err}") from err
        return obj(*children)
    raise ValueError(f"unknown genome tree node type {kind!r}")


def _count_leaves(node) -> int:
    if node["type"] == "leaf":
        return 1
    return sum(_count_leaves(c) for c in node.get("children", []))


# ----------------------------------------------------------------------------------------------------------------
# save / load
# ----------------------------------------------------------------------------------------------------------------


def save(path: str | os.PathLike, archive: Archive) -> Path:
    """Write ``archive`` to ``path`` (.npz, format in the docstring of :mod:`jaxterrain.qd.archive`), atomically."""
    cells = archive.fitness.shape[0]
    arrays: dict[str, np.ndarray] = {}
    trees = []
    for i, g in enumerate(archive.genomes):
        leaves: list = []
        trees.append(_flatten(g, leaves))
        for k, leaf in enumerate(leaves):
            if leaf.ndim < 1 or leaf.shape[0] != cells:
                raise ValueError(f"save: genome leaf {k} of generator {i} has shape {leaf.shape}; needs [{cells}, ...]")
            arrays[f"genome_{i}_{k}"] = leaf
    filled = archive.source >= 0
    hm_header = None
    if archive.heightmaps is not None:
        hm = np.asarray(archive.heightmaps)[filled]
        hm_header = {"shape": list(hm.shape), "dtype": "uint16", "scale": 65535}
        arrays["heightmaps"] = hm.astype(np.uint16)
    header = {
        "format": FORMAT,
        "version": VERSION,
        "generator_names": list(archive.generator_names),
        "descriptor_names": list(archive.config.descriptors),
        "ranges": [list(r) for r in archive.config.ranges],
        "bins": archive.config.bins,
        "cells": cells,
        "config": config_to_dict(archive.config),
        "genomes": trees,
        "heightmaps": hm_header,
        "metrics": sorted(archive.metrics),
    }
    arrays["header"] = np.frombuffer(json.dumps(header).encode("utf-8"), np.uint8)
    arrays["fitness"] = np.asarray(archive.fitness, np.float32)
    arrays["descriptors"] = np.asarray(archive.descriptors, np.float32)
    arrays["centroids"] = np.asarray(archive.centroids, np.float32)
    arrays["source"] = np.asarray(archive.source, np.int32)
    for name, values in archive.metrics.items():
        arrays[f"metric_{name}"] = np.asarray(values, np.float32)
    return atomic_save_npz(path, **arrays)


def _open_npz(path: Path, what: str):
    if not path.exists():
        raise FileNotFoundError(f"{what} file {str(path)!r} does not exist")
    with open(path, "rb") as f:
        magic = f.read(6)
    if magic == b"\x93NUMPY":  # a lone .npy array (e.g. renamed to .npz)
        raise ValueError(f"{str(path)!r}: one .npy array, not an .npz {what} file")
    if not magic.startswith(b"PK"):  # np.load would try to unpickle it and say so
        raise ValueError(f"{str(path)!r}: not an .npz {what} file (no zip header)")
    try:
        data = np.load(path, allow_pickle=False)
        members = {name: data[name] for name in data.files}  # reads (and CRC-checks) every member
        header = json.loads(bytes(members.pop("header")).decode("utf-8"))
    except (zipfile.BadZipFile, EOFError, OSError, KeyError, ValueError, UnicodeDecodeError) as err:
        raise ValueError(f"{str(path)!r} is not a readable {what} file (truncated or corrupt?): {err}") from err
    if not isinstance(header, dict):
        raise ValueError(f"{str(path)!r}: the header is not a JSON object")
    return header, members


def _need(path, members, name, shape, dtype):
    if name not in members:
        raise ValueError(f"{str(path)!r}: member {name!r} is missing")
    a = members[name]
    if tuple(a.shape) != tuple(shape) or (dtype is not None and a.dtype != np.dtype(dtype)):
        raise ValueError(
            f"{str(path)!r}: member {name!r} has shape {a.shape} dtype {a.dtype}; expected {tuple(shape)} {dtype}"
        )
    return a


def load(path: str | os.PathLike) -> Archive:
    """Read an archive written by :func:`save`; ``ValueError`` for a wrong, truncated or corrupt file."""
    path = Path(path)
    header, m = _open_npz(path, "archive")
    if header.get("format") != FORMAT:
        raise ValueError(f"{str(path)!r} is not a jaxterrain archive (format {header.get('format')!r})")
    if header.get("version") != VERSION:
        raise ValueError(
            f"{str(path)!r}: archive format version {header.get('version')!r}; this reader knows {VERSION}"
        )
    missing = [k for k in ("config", "cells", "generator_names", "genomes", "metrics", "heightmaps") if k not in header]
    if missing:
        raise ValueError(f"{str(path)!r}: incomplete header (no field {', '.join(map(repr, missing))})")
    cells, names, trees = header["cells"], header["generator_names"], header["genomes"]
    metric_names, hm_header = header["metrics"], header["heightmaps"]
    if not isinstance(cells, int) or isinstance(cells, bool) or cells < 1:
        raise ValueError(f"{str(path)!r}: header field 'cells' must be an integer >= 1; got {cells!r}")
    for field, value in (("generator_names", names), ("metrics", metric_names)):
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise ValueError(f"{str(path)!r}: header field {field!r} must be a list of names; got {value!r}")
    if not isinstance(trees, list):
        raise ValueError(f"{str(path)!r}: header field 'genomes' must be a list (one tree per generator); got "
                         f"{trees!r}")
    shape = None if not isinstance(hm_header, dict) else hm_header.get("shape")
    if hm_header is not None and not (isinstance(shape, list) and len(shape) == 3 and all(
            isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in shape)):
        raise ValueError(f"{str(path)!r}: header field 'heightmaps' must be null or {{\"shape\": [N, H, W], ...}}; got "
                         f"{hm_header!r}")
    names = tuple(names)
    if not isinstance(header["config"], dict):
        raise ValueError(f"{str(path)!r}: header field 'config' must be a JSON object (the EvolveConfig); got "
                         f"{header['config']!r}")
    try:
        config = resolve_config(config_from_dict(header["config"]))
    except (KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{str(path)!r}: header field 'config': {err}") from err
    if cells != config.bins**2 or len(trees) != len(names):
        raise ValueError(f"{str(path)!r}: header is inconsistent (cells {cells}, bins {config.bins})")
    fitness = _need(path, m, "fitness", (cells,), np.float32)
    descriptors = _need(path, m, "descriptors", (cells, 2), np.float32)
    centroids = _need(path, m, "centroids", (cells, 2), np.float32)
    source = _need(path, m, "source", (cells,), np.int32)
    if np.any(source >= len(names)) or np.any(source < -1):
        raise ValueError(f"{str(path)!r}: source ids outside [-1, {len(names) - 1}]")
    genomes = []
    for i, tree in enumerate(trees):
        leaves = []
        try:
            count = _count_leaves(tree)
        except (KeyError, TypeError, AttributeError) as err:
            raise ValueError(f"{str(path)!r}: header field 'genomes' [{i}] is not a genome tree ({err!r})") from None
        for k in range(count):
            name = f"genome_{i}_{k}"
            if name not in m:
                raise ValueError(f"{str(path)!r}: member {name!r} is missing")
            if m[name].ndim < 1 or m[name].shape[0] != cells:
                raise ValueError(f"{str(path)!r}: member {name!r} has shape {m[name].shape}; expected [{cells}, ...]")
            leaves.append(m[name])
        try:
            genomes.append(_unflatten(tree, leaves))
        except (KeyError, TypeError, IndexError, ValueError) as err:
            raise ValueError(f"{str(path)!r}: header field 'genomes' [{i}]: {err}") from None
    maps = None
    if hm_header is not None:
        n_filled = int(np.sum(source >= 0))
        shape = tuple(hm_header["shape"])
        hm = _need(path, m, "heightmaps", (n_filled,) + shape[1:], np.uint16)
        maps = np.zeros((cells,) + shape[1:], np.uint16)
        maps[source >= 0] = hm
    metrics = {name: _need(path, m, f"metric_{name}", m.get(f"metric_{name}", np.zeros(0)).shape, np.float32)
               for name in metric_names}
    return Archive(tuple(genomes), names, source, fitness, descriptors, centroids, maps, config, metrics)


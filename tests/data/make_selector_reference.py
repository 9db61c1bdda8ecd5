"""Writes ``selector_reference.npz``: the histories and final states of the map, roughness and random curricula
(the keyed fake harness of ``tests/curriculum/test_curriculum.py``, 3 trials to the end, plain and overlapped) as
``jaxterrain.curriculum`` computed them BEFORE the selector protocol (commit cb463e4, 2026-11-28). The protocol's
versions must reproduce them bit for bit (``tests/curriculum/test_selectors.py``). Run from the repository root:
``python tests/data/make_selector_reference.py``; do not re-run it after changing the curriculum."""

import sys
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "curriculum"))
from test_curriculum import KEYED_START, keyed_harness, small, toy_bank, toy_grid  # noqa: E402

from jaxterrain import curriculum as C  # noqa: E402

CASES = {  # name -> (selector, config fields, overlap)
    "map": ("map", dict(max_evals=3, max_epochs=30), False),
    "map_overlap": ("map", dict(max_evals=3, max_epochs=30), True),
    "map_keep_best": ("map", dict(max_evals=2, max_epochs=30, removal_ties="keep", gp_evaluation="best",
                                  credit="finished"), False),
    "roughness": ("roughness", dict(max_evals=3, max_epochs=30, roughness_stride=3), False),
    "random": ("random", dict(max_evals=3, max_epochs=30), False),
    "random_overlap": ("random", dict(max_evals=3, max_epochs=30), True),
}


def run(selector, fields, overlap):
    bank = toy_bank(toy_grid(4), descriptor0=np.random.default_rng(3).permutation(16).astype(np.float32))
    config, harness = small(selector, overlap=overlap, **fields), keyed_harness(0.04, overlap)
    keys = jax.random.split(jax.random.key(5), 3)
    states = C.init_trials(keys, bank, KEYED_START, config=config, harness=harness)
    return C.make_runner(config, harness)(states, bank, 100)


if __name__ == "__main__":
    out = {}
    for name, (selector, fields, overlap) in CASES.items():
        s = run(selector, fields, overlap)
        for field in ("epoch", "terrain", "evaluation", "hardest"):
            out[f"{name}/history.{field}"] = np.asarray(getattr(s.history, field))
        for field in ("terrain", "chunk", "epoch", "hardest", "done"):
            out[f"{name}/{field}"] = np.asarray(getattr(s, field))
        for field, value in s.policy.items():
            out[f"{name}/policy.{field}"] = np.asarray(value)
        out[f"{name}/key"] = np.asarray(s.key)
        for field in ("obs_index", "obs_y", "obs_count", "available", "terrain_evals", "terrain_best"):
            out[f"{name}/selector.{field}"] = np.asarray(getattr(s, field))
    np.savez_compressed(Path(__file__).with_name("selector_reference.npz"), **out)
    print(len(out), "arrays")

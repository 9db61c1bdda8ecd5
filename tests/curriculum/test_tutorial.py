"""docs/tutorials/curriculum.md runs as written: its Python blocks, in order, in a module of their own (so the
selector is importable as ``module:object``), and the toy run prints what the text says; its population of two
treatments gives the first one's run alone."""

from __future__ import annotations

import re
import sys
import types
from pathlib import Path

import numpy as np

TUTORIAL = Path(__file__).resolve().parents[2] / "docs" / "tutorials" / "curriculum.md"


def test_the_curriculum_tutorial_runs_and_its_selector_walks_the_terrains_easiest_first():
    blocks = re.findall(r"```python\n(.*?)```", TUTORIAL.read_text(), flags=re.S)
    assert len(blocks) == 3
    module = types.ModuleType("tutorial_curriculum")
    sys.modules[module.__name__] = module
    try:
        for block in blocks:
            exec(compile(block, str(TUTORIAL), "exec"), module.__dict__)
    finally:
        del sys.modules[module.__name__]
    terrain = np.asarray(module.states.history.terrain)
    np.testing.assert_array_equal(terrain[0], [0] * 9 + [1, 2, 3, 4] + [-1] * 7)
    np.testing.assert_array_equal(terrain[1], terrain[0])  # the toy harness ignores keys
    assert np.all(np.asarray(module.states.done))
    from curriculum_archives import tree_equal  # the population's first treatment: the run alone's, bit for bit

    assert tree_equal(module.mine, module.states) and np.all(np.asarray(module.theirs.done))
    assert not np.array_equal(np.asarray(module.theirs.history.terrain), terrain)

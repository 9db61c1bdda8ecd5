"""Import a script that is not a package module (``docs/results/**/*.py``, ``benchmarks/*.py``, ``docs/hooks/*.py``,
``tests/data/*.py``) as a module for its tests; a script that puts folders on ``sys.path`` leaves it as it was."""

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def load_script(path, name: str):
    """The module of the script at ``path`` (relative to the repository root, or absolute), named ``name``,
    executed once per call."""
    spec = importlib.util.spec_from_file_location(name, ROOT / path)
    module = importlib.util.module_from_spec(spec)
    saved = list(sys.path)
    spec.loader.exec_module(module)
    sys.path[:] = saved
    return module

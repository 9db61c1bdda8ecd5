"""Import a script of benchmarks/ as a module (the scripts put benchmarks/ on sys.path; that is undone here)."""

import importlib.util
import sys
from pathlib import Path


def load_benchmark(name: str):
    """The module of ``benchmarks/<name>.py``."""
    path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"{name}_benchmark", path)
    module = importlib.util.module_from_spec(spec)
    saved = list(sys.path)
    spec.loader.exec_module(module)
    sys.path[:] = saved
    return module

"""Every dotted ``jaxterrain.*`` name the docs, the README and the docstrings mention exists, and every ``>>>`` import
line of a docstring runs (issue 60, item 6: examples had gone stale when the package moved into stage subpackages).
Names that are not importable by design are listed with why."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NOT_MODULES = {
    "jaxterrain.plugins": "the entry-point group of plugins (pyproject), not a module",
    "jaxterrain.rl.policy": "the format tag of a policy's config.json (rl.checkpoint.POLICY_FORMAT)",
    "jaxterrain.onnx": "the format tag of an exported policy's metadata (rl.onnx.ONNX_FORMAT)",
}
NAME = re.compile(r"\bjaxterrain(?:\.[A-Za-z_]\w*)+")
IMPORT = re.compile(r"^\s*>>> ((?:from jaxterrain[\w.]* import [\w ,]+)|(?:import jaxterrain[\w. ,]*))", re.M)


def sources() -> list[Path]:
    return sorted([*ROOT.glob("docs/**/*.md"), ROOT / "README.md", *ROOT.glob("jaxterrain/**/*.py")])


def resolves(name: str) -> bool:
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for part in parts[i:]:
                obj = getattr(obj, part)
        except AttributeError:
            return False
        return True
    return False


def test_every_dotted_name_in_the_docs_exists():
    missing = {}
    for path in sources():
        for name in NAME.findall(path.read_text()):
            if name not in NOT_MODULES and not resolves(name):
                missing.setdefault(name, str(path.relative_to(ROOT)))
    assert not missing, missing


def test_every_docstring_import_line_runs():
    lines = [(path, line) for path in ROOT.glob("jaxterrain/**/*.py") for line in IMPORT.findall(path.read_text())]
    assert len(lines) >= 5  # the module docstrings' examples
    for path, line in lines:
        try:
            exec(line.split("#")[0], {})
        except ImportError as err:
            raise AssertionError(f"{path.relative_to(ROOT)}: {line!r}: {err}") from None


def test_the_checker_finds_a_stale_name():
    assert resolves("jaxterrain.qd.map_elites.insert") and not resolves("jaxterrain.map_elites.insert")
    assert not resolves("jaxterrain.sharding.initialize") and resolves("jaxterrain.runtime.sharding.initialize")

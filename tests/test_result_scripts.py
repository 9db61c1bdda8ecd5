"""The scripts that made the shipped results (``docs/results/**/*.py``) and the benchmarks still name only what the
package has: every ``from jaxterrain... / experiments... import NAME`` resolves, and every ``module.attribute`` read off
a package module they import exists. A function that moves without its callers being updated fails here, not
months later when someone re-runs a results page's script. A diagnostic that reads private functions says in its
docstring "Pinned: ... at commit SHA" and is checked only for that line (it runs at that commit)."""

from __future__ import annotations

import ast
import importlib
import importlib.util
from pathlib import Path

import re

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted([*ROOT.glob("docs/results/**/*.py"), *ROOT.glob("benchmarks/*.py")])
OURS = ("jaxterrain", "experiments")


PINNED = re.compile(r"Pinned: .* at commit ([0-9a-f]{7,40})", re.S)


def _has(module, name: str) -> bool:
    """``module.name`` exists: an attribute, or a submodule not imported yet."""
    if hasattr(module, name):
        return True
    try:
        return importlib.util.find_spec(f"{module.__name__}.{name}") is not None
    except ModuleNotFoundError:  # module is not a package
        return False


def _ours(module: str | None) -> bool:
    return module is not None and module.split(".")[0] in OURS


def package_names(tree: ast.AST) -> tuple[list[tuple[str, str]], dict[str, str]]:
    """``([(module, name) imported by from-imports], {alias: module} of the package modules bound to a name)``."""
    names, modules = [], {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and _ours(node.module):
            for a in node.names:
                names.append((node.module, a.name))
                full = f"{node.module}.{a.name}"
                try:
                    importlib.import_module(full)
                    modules[a.asname or a.name] = full
                except ImportError:
                    pass
        elif isinstance(node, ast.Import):
            for a in node.names:
                if _ours(a.name) and a.asname:
                    modules[a.asname] = a.name
    return names, modules


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_the_script_names_only_what_the_package_has(script):
    tree = ast.parse(script.read_text(), filename=str(script))
    pinned = PINNED.search(ast.get_docstring(tree) or "")
    if pinned:
        pytest.skip(f"pinned to commit {pinned.group(1)}")
    names, modules = package_names(tree)
    for module, name in names:
        assert _has(importlib.import_module(module), name), f"{script.name}: from {module} import {name}: no such name"
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in modules \
                and isinstance(node.ctx, ast.Load):
            assert _has(importlib.import_module(modules[node.value.id]), node.attr), \
                f"{script.name}: {node.value.id}.{node.attr}: {modules[node.value.id]} has no {node.attr}"

"""The package's shape, as rules a move cannot quietly break (issue 44): imports run one way down the data flow,
every module says what it exports, and the command line and benchmarks use only public names.

Read with ``ast`` (nothing is imported), so a broken rule names the file and line."""

from __future__ import annotations

import ast
import importlib
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PKG = ROOT / "jaxterrain"

# The stages in the order the data flows; a stage imports only stages before it. ``features.learned`` (the learned
# traversability descriptor) is trained on the walker's walks, so it sits after ``difficulty``.
FLOW = ("runtime", "generators", "terrain", "features", "generators.gan_train", "walker", "rl", "difficulty",
        "features.learned", "qd", "suite", "curriculum", "report")
# Stages inside a subpackage that sit later in the flow: a model trained on what later stages make (the GAN on real
# elevation tiles, scored with the features; the traversability CNN on the walker's walks).
LATER = ("generators.gan_train", "features.learned")
# Function-level imports of jaxterrain modules that are allowed (optional dependencies, documented heavy imports).
ALLOWED_INNER: set[tuple[str, str]] = set()


def module_name(path: pathlib.Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted(PKG.rglob("*.py"))}


def is_package(mod: str) -> bool:
    return MODULES[mod].name == "__init__.py"


def stage(mod: str) -> str | None:
    """The FLOW stage of a module (None for the top-level package)."""
    parts = mod.split(".")[1:]
    if not parts:
        return None
    for s in LATER:
        if parts[:2] == s.split("."):
            return s
    return parts[0]


def imports(path: pathlib.Path):
    """``(line, target module, imported names, inside a function)`` for every jaxterrain import of ``path``."""
    tree = ast.parse(path.read_text())
    inner = {id(n) for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
             for n in ast.walk(f)}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").split(".")[0] == "jaxterrain":
            yield node.lineno, node.module, [a.name for a in node.names], id(node) in inner
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "jaxterrain":
                    yield node.lineno, a.name, [], id(node) in inner


def edges(mod: str) -> set[str]:
    """The jaxterrain modules ``mod`` imports at module level: the target of ``import X`` / ``from X import name``,
    the submodule of ``from X import sub``, and the packages above each (their ``__init__`` runs first), except
    the packages above ``mod`` itself, which are already being imported when ``mod`` is."""
    ancestors = {".".join(mod.split(".")[:k]) for k in range(1, mod.count(".") + 1)}
    explicit, out = set(), set()
    for _, target, names, inner in imports(MODULES[mod]):
        if inner:
            continue
        subs = {f"{target}.{n}" for n in names if f"{target}.{n}" in MODULES}
        if not names or len(subs) < len(names):  # a name defined in target's own code
            explicit.add(target)
        explicit |= subs
    for t in explicit:
        out |= {p for p in (".".join(t.split(".")[:k]) for k in range(1, t.count(".") + 2)) if p in MODULES}
    return (out - ancestors - {mod}) | (explicit - {mod})


def test_module_imports_have_no_cycle():
    graph = {m: edges(m) for m in MODULES}
    state: dict[str, int] = {}

    def visit(m, path):
        state[m] = 1
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                cycle = path[path.index(n):] + [n] if n in path else [m, n]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if n not in state:
                visit(n, path + [n])
        state[m] = 2

    for m in MODULES:
        if m not in state:
            visit(m, [m])


def test_stages_import_only_earlier_stages():
    order = {s: i for i, s in enumerate(FLOW)}
    bad = []
    for m, path in MODULES.items():
        s = stage(m)
        if s is None:
            continue
        for line, target, names, _ in imports(path):
            targets = [target] + [f"{target}.{n}" for n in names if f"{target}.{n}" in MODULES]
            for t in targets:
                ts = stage(t)
                if ts is not None and ts != s and order[ts] > order[s]:
                    bad.append(f"{path.relative_to(ROOT)}:{line}: stage {s} imports {t} (stage {ts}, later)")
    assert not bad, "\n".join(bad)


def test_no_function_level_imports_of_the_package():
    bad = [f"{p.relative_to(ROOT)}:{line}: imports {t} inside a function"
           for m, p in MODULES.items() for line, t, _, inner in imports(p) if inner and (m, t) not in ALLOWED_INNER]
    assert not bad, "\n".join(bad)


def test_no_module_imports_another_modules_private_names():
    bad = [f"{p.relative_to(ROOT)}:{line}: from {t} import {n}"
           for p in [*MODULES.values(), *ROOT.glob("experiments/*.py"), *ROOT.glob("benchmarks/*.py")]
           for line, t, names, _ in imports(p) for n in names if n.startswith("_") and f"{t}.{n}" not in MODULES]
    assert not bad, "\n".join(bad)


def test_private_modules_are_imported_only_inside_their_subpackage():
    bad = []
    for p in [*MODULES.values(), *ROOT.glob("experiments/*.py"), *ROOT.glob("benchmarks/*.py")]:
        here = module_name(p) if p.is_relative_to(PKG) else ""
        for line, t, names, _ in imports(p):
            for full in [t] + [f"{t}.{n}" for n in names]:
                parts = full.split(".")
                private = [i for i, part in enumerate(parts) if part.startswith("_")]
                if private and ".".join(parts[:private[0] + 1]) not in MODULES:
                    continue  # a private name, not a module: the test above
                if private and not here.startswith(".".join(parts[:private[0]]) + "."):
                    bad.append(f"{p.relative_to(ROOT)}:{line}: imports private module {full}")
    assert not bad, "\n".join(bad)


def test_every_public_module_and_package_declares_all():
    missing = [str(p.relative_to(ROOT)) for m, p in MODULES.items()
               if not any(part.startswith("_") for part in m.split(".")[1:])
               and not any(isinstance(n, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in n.targets)
                           for n in ast.parse(p.read_text()).body)]
    assert not missing, "no __all__ in: " + ", ".join(missing)


def test_the_package_root_holds_subpackages_and_at_most_four_modules():
    modules = sorted(p.name for p in PKG.glob("*.py"))
    assert len(modules) <= 4, modules
    assert modules == ["__init__.py"]


@pytest.mark.parametrize("folder", ["experiments", "benchmarks"])
def test_commands_and_benchmarks_import_only_public_names(folder):
    """Every ``from jaxterrain.X import name`` of the command line and the benchmarks names a submodule of X or a
    name in X's ``__all__``."""
    bad = []
    for p in sorted((ROOT / folder).glob("*.py")):
        for line, t, names, _ in imports(p):
            if t not in MODULES:
                bad.append(f"{p.relative_to(ROOT)}:{line}: no module {t}")
                continue
            public = set(importlib.import_module(t).__all__)
            bad += [f"{p.relative_to(ROOT)}:{line}: {t}.{n} is not public" for n in names
                    if n not in public and f"{t}.{n}" not in MODULES]
    assert not bad, "\n".join(bad)


def test_a_packages_submodule_names_are_its_submodules():
    """``from jaxterrain.qd import grid`` gives the module ``qd/grid.py``, never a function of the same name that the
    package's ``__init__`` happened to import last."""
    bad = []
    for m in MODULES:
        if not is_package(m):
            continue
        pkg = importlib.import_module(m)
        for sub in (s for s in MODULES if s.rsplit(".", 1)[0] == m and s != m):
            name = sub.rsplit(".", 1)[1]
            if hasattr(pkg, name) and getattr(pkg, name) is not importlib.import_module(sub):
                bad.append(f"{m}.{name} is {getattr(pkg, name)!r}, not the module {sub}")
    assert not bad, "\n".join(bad)


def test_top_level_names_every_stage_in_flow_order():
    import jaxterrain

    stages = [s for s in FLOW if "." not in s]
    assert [n for n in jaxterrain.__all__ if n in stages] == stages


def test_only_integration_tests_import_the_command_line():
    """The library's tests import the library only: ``experiments`` (the command line) is imported, at any level,
    by tests under tests/integration/ alone; a command's work that a test needs belongs in a library driver."""
    tests = ROOT / "tests"
    bad = []
    for p in sorted(tests.rglob("*.py")):
        if p.is_relative_to(tests / "integration"):
            continue
        for node in ast.walk(ast.parse(p.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else [])
            bad += [f"{p.relative_to(ROOT)}:{node.lineno}: imports {n}" for n in names
                    if n.split(".")[0] == "experiments"]
    assert not bad, "\n".join(bad)


def test_no_library_module_is_over_500_lines():
    long = {f"{p.relative_to(ROOT)}: {n} lines" for p in PKG.rglob("*.py")
            if (n := len(p.read_text().splitlines())) > 500}
    assert not long, "\n".join(sorted(long))


# Typed run configs read by ``--help`` (``experiments.common.library_file``): the standard library and
# ``jaxterrain.runtime.schema`` only, so that the command line's help imports no JAX.
JAX_FREE = ("jaxterrain.runtime.schema", "jaxterrain.runtime.estimates", "jaxterrain.curriculum.presets",
            "jaxterrain.qd.run_config", "jaxterrain.difficulty.run_config", "jaxterrain.suite.run_config")


def test_the_config_modules_import_only_the_standard_library():
    import sys

    bad = []
    for mod in JAX_FREE:
        for node in ast.parse(MODULES[mod].read_text()).body:  # module level: what reading the file runs
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) and node.level == 0 else [])
            bad += [f"{mod}: imports {n}" for n in names
                    if n.split(".")[0] not in sys.stdlib_module_names and n != "jaxterrain.runtime.schema"]
    assert not bad, "\n".join(bad)

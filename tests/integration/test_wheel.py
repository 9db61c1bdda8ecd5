"""The package as a user installs it: a wheel (not editable) used from a folder that is not the repository. Its
default inputs (the base policy, the shipped archives) are package data, so commands run from anywhere."""

from __future__ import annotations

import filecmp
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """``(site folder, env)``: the wheel built from this checkout, installed (without its dependencies, which this
    environment has) into a folder that comes first on ``PYTHONPATH``."""
    root = tmp_path_factory.mktemp("wheel")
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(root / "dist"),
                            str(ROOT)], capture_output=True, text=True, timeout=600)
    assert built.returncode == 0, built.stderr[-2000:]
    wheel = next((root / "dist").glob("jaxterrain-*.whl"))
    site = root / "site"
    done = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site),
                           str(wheel)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    env = {**os.environ, "PYTHONPATH": str(site), "MPLBACKEND": "Agg"}
    return site, env


def run(env, cwd, *args, timeout=900):
    return subprocess.run([sys.executable, *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)


def test_the_wheel_carries_every_default_input_and_is_the_one_imported(installed, tmp_path):
    site, env = installed
    for g in ("cppn", "perlin", "worley", "diamond_square", "gan"):
        shipped = site / "jaxterrain" / "assets" / "archives" / f"{g}_headings.npz"
        assert filecmp.cmp(shipped, ROOT / "docs" / "results" / f"exp2_{g}_headings_archive.npz", shallow=False), g
    assert (site / "jaxterrain" / "assets" / "base_policy" / "policy.msgpack").is_file()
    patch = site / "jaxterrain" / "assets" / "patches" / "mjx_vendored_hfield_local_origin.patch"  # warp-patch's
    assert filecmp.cmp(patch, ROOT / "docs/results/sim2sim/warp_hfield" / patch.name, shallow=False)
    probe = run(env, tmp_path, "-c", "import jaxterrain, experiments.learn as l, experiments.curriculum as c; "
                "print(jaxterrain.__file__); print(l.CPPN_ARCHIVE); print(*c.DEFAULT_ARCHIVES.values())")
    assert probe.returncode == 0, probe.stderr[-2000:]
    lines = probe.stdout.split()
    assert all(line.startswith(str(site)) for line in lines) and all(Path(p).is_file() for p in lines[1:])
    helped = run(env, tmp_path, "-m", "experiments", "learn", "--help")
    assert helped.returncode == 0 and "cppn_headings.npz" in helped.stdout


@pytest.mark.slow
def test_quickstart_and_learn_run_from_an_empty_folder(installed, tmp_path):
    _, env = installed
    for args in (("quickstart", "--out", "q"), ("learn", "--preset", "smoke", "--out", "l")):
        done = run(env, tmp_path, "-m", "experiments", *args, timeout=1800)
        assert done.returncode == 0, done.stderr[-3000:]
    assert (tmp_path / "l" / "policies" / "trial_0" / "policy.msgpack").is_file()
    assert any((tmp_path / "q").rglob("*.png"))


def test_the_wheel_has_the_jaxterrain_console_script_and_names_its_version(installed, tmp_path):
    """``jaxterrain <command>`` beside ``python -m experiments``; a run from the wheel records the package's version
    (no git checkout to ask)."""
    site, env = installed
    env = {k: v for k, v in env.items() if k != "JAXTERRAIN_COMMIT"}
    script = site / "bin" / "jaxterrain"
    assert script.is_file()
    helped = subprocess.run([str(script), "learn", "--help"], cwd=tmp_path, env=env, capture_output=True, text=True,
                            timeout=300)
    assert helped.returncode == 0, helped.stderr[-2000:]
    assert helped.stdout.startswith("usage: jaxterrain learn") and "--update-normaliser" in helped.stdout
    probe = run(env, tmp_path, "-c", "from jaxterrain.runtime import provenance; print(provenance.git_commit())")
    assert probe.stdout.strip() == "jaxterrain 0.1.0 (installed package, no git checkout)", probe.stderr[-2000:]


def test_the_console_script_is_declared_and_runs_help(capsys):
    """Without building a wheel: pyproject's [project.scripts] names experiments.__main__:console, which runs."""
    import tomllib

    from experiments import __main__ as cli

    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts == {"jaxterrain": "experiments.__main__:console"}
    with pytest.MonkeyPatch.context() as m:
        m.setattr(sys, "argv", ["jaxterrain", "evaluate", "--help"])
        with pytest.raises(SystemExit) as exc:
            cli.console()
    assert exc.value.code == 0 and capsys.readouterr().out.startswith("usage: jaxterrain evaluate")

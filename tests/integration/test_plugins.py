"""Plugins through the front door: ``python -m experiments --plugin MODULE ...`` (before or after the command) and
the ``jaxterrain.plugins`` entry points import a module whose generators, curricula and robots every command then
takes by name; a plugin that does not import is one line and exit status 2. A tiny plugin (a generator of inclined
planes, a curriculum and a robot) runs ``evolve`` and ``learn`` at smoke size (``-m slow``)."""

from __future__ import annotations

import json
import sys
import textwrap

import pytest

from experiments import __main__ as front

PLUGIN = textwrap.dedent('''
    """A test plugin: the ``planes`` generator (inclined planes, slope and direction genes), the
    ``plugin_hardest_first`` curriculum (the hardest terrain of the archive, every chunk) and the ``low_ant`` robot."""
    import jax.numpy as jnp

    from jaxterrain import curriculum, generators
    from jaxterrain.curriculum import selectors as S
    from jaxterrain.generators import base

    PLANES = base.spec(("slope", 0.0, 1.0, False), ("angle", 0.0, 6.283, False))


    @generators.register("planes")
    def planes(size: int = 256) -> generators.Generator:
        x = jnp.linspace(-0.5, 0.5, size)

        def render_one(genome):
            plane = genome[0] * (jnp.cos(genome[1]) * x[None, :] + jnp.sin(genome[1]) * x[:, None])
            return (0.5 + plane).clip(0.0, 1.0)

        return base.vector_generator("planes", PLANES, render_one, size)


    def plugin_hardest_first(config) -> S.Selector:
        def init(key, bank):
            return jnp.argmax(S.terrain_hardness(bank)).astype(jnp.int32)

        def update(state, key, bank, outcome):
            no = jnp.zeros((), bool)
            return state, S.Decision(finished=no, restart=no, exhausted=no)

        return S.Selector("plugin_hardest_first", 1, init,
                          lambda s: S.Assignment(s[None], None, jnp.zeros((), jnp.int32)), update,
                          lambda s: {"hardest_index": s})


    curriculum.register_selector("plugin_hardest_first", plugin_hardest_first)

    # a robot: brax's ant crouched lower (its own start pose), under a name of its own
    from jaxterrain.walker import register_robot, robots

    register_robot(robots.ANT._replace(name="low_ant", start_joints=(0.0, 0.8, 0.0, -0.8, 0.0, -0.8, 0.0, 0.8)))
''')


def run(argv) -> int:
    """``python -m experiments`` with ``argv``: its exit status (``--print-config`` may exit through SystemExit)."""
    try:
        return front.main(argv)
    except SystemExit as stop:
        return int(stop.code or 0)


@pytest.fixture()
def plugin(tmp_path, monkeypatch):
    """The plugin module, importable; what it registers is taken out of the registries again afterwards."""
    from jaxterrain.curriculum import selectors
    from jaxterrain.generators import registry
    from jaxterrain.walker import robots

    monkeypatch.setattr(registry, "_FACTORIES", dict(registry._FACTORIES))
    monkeypatch.setattr(selectors.protocol, "_REGISTRY", dict(selectors.protocol._REGISTRY))
    monkeypatch.setattr(robots, "_REGISTRY", dict(robots._REGISTRY))
    (tmp_path / "jt_test_plugin.py").write_text(PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield "jt_test_plugin"
    sys.modules.pop("jt_test_plugin", None)


def test_split_plugins_takes_every_plugin_flag_wherever_it_stands():
    assert front.split_plugins(["--plugin", "a", "learn", "--plugin=b.c", "--trials", "2"]) == (
        ["a", "b.c"], ["learn", "--trials", "2"])
    assert front.split_plugins(["learn", "--", "--plugin", "x"]) == ([], ["learn", "--", "--plugin", "x"])
    with pytest.raises(front.PluginError, match="--plugin needs a module name"):
        front.split_plugins(["learn", "--plugin"])


@pytest.mark.parametrize("argv, message", [
    (["--plugin", "no_such_plugin_xyz", "learn"], "--plugin no_such_plugin_xyz: cannot import it (ModuleNotFound"),
    (["learn", "--plugin=not a module"], "--plugin 'not a module': not a module name"),
])
def test_a_plugin_that_does_not_import_is_one_line_and_status_2(argv, message, capsys):
    assert front.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_a_plugins_generator_curriculum_and_robot_are_names_every_command_takes(plugin, capsys):
    assert run(["evaluate", "--robot", "low_ant"]) == 2  # without the plugin the robot is unknown
    assert "robot must be one of humanoid, ant, got 'low_ant'" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # without the plugin the names are unknown
        front.main(["learn", "--curriculum", "plugin_hardest_first", "--print-config"])
    assert "plugin_hardest_first" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        front.main(["evolve", "--generator", "planes", "--print-config"])  # unknown generator: one line
    assert "unknown generator 'planes'" in capsys.readouterr().err
    assert run(["--plugin", plugin, "learn", "--curriculum", "plugin_hardest_first", "--print-config"]) == 0
    assert json.loads(capsys.readouterr().out)["curriculum"] == "plugin_hardest_first"
    assert run(["evolve", "--plugin", plugin, "--generator", "planes", "--print-config"]) == 0
    assert json.loads(capsys.readouterr().out)["generator"] == "planes"
    # the plugin's robot: a name --robot takes (it has no base policy yet: evaluate says how to train one)
    assert run(["--plugin", plugin, "evaluate", "--robot", "low_ant"]) == 2
    assert "train-base-policy --robot low_ant" in capsys.readouterr().err
    assert run(["--plugin", plugin, "train-base-policy", "--robot", "low_ant", "--print-config"]) == 0
    assert json.loads(capsys.readouterr().out)["robot"] == "low_ant"


def test_installed_plugins_load_from_their_entry_points(plugin, monkeypatch):
    from importlib import metadata

    calls = []
    point = metadata.EntryPoint(name="test", value="jt_test_plugin:plugin_hardest_first", group=front.PLUGIN_GROUP)
    monkeypatch.setattr(metadata, "entry_points", lambda group=None: [point] if group == front.PLUGIN_GROUP else [])
    monkeypatch.setattr(point.__class__, "load", lambda self: (lambda: calls.append(self.value)))
    assert front.load_plugins([]) == ["jt_test_plugin:plugin_hardest_first"] and calls == ["jt_test_plugin:plugin_hardest_first"]


@pytest.mark.slow
def test_evolve_and_learn_run_on_the_plugins_generator_and_curriculum(plugin, tmp_path):
    evolved = tmp_path / "evolve"
    assert front.main(["--plugin", plugin, "evolve", "--generator", "planes", "--preset", "smoke", "--size", "128",
                       "--out", str(evolved)]) == 0  # 128 px: 5.1 m, long enough a track for the walker
    archive = next(evolved.glob("*.npz"))
    learned = tmp_path / "learn"
    assert front.main(["--plugin", plugin, "learn", "--preset", "smoke", "--archive", str(archive), "--curriculum",
                       "plugin_hardest_first", "--out", str(learned)]) == 0
    summary = json.loads((learned / "summary.json").read_text())
    assert summary["epochs"] == [4, 4] and len(summary["hardest_index"]) == 2

"""``python -m experiments <command>`` (installed: ``jaxterrain <command>``): every experiment of the paper, and the
training jobs behind them.

Each command lives in its own module of this package, which defines ``add_arguments(parser)`` and ``main(args)``;
this file only maps command names to modules. Command modules import jax and the library inside ``main`` only, so
``--help`` stays fast.

Plugins: ``--plugin MODULE`` (before or after the command, repeatable) imports MODULE first, and every installed
package's ``jaxterrain.plugins`` entry points are loaded (an entry point naming a callable is called with no
arguments): a module that registers generators (``jaxterrain.generators.register``), descriptors
(``jaxterrain.features.register_descriptor``) or curricula (``jaxterrain.curriculum.register_selector``) makes their names
valid in every command, e.g. ``python -m experiments --plugin mylab.terrains evolve --generator ridges``.
"""

from __future__ import annotations

import argparse
import importlib
import sys

COMMANDS = {
    "quickstart": ("experiments.quickstart", "small end-to-end run on CPU: terrains, descriptors, figures"),
    "train-gan": ("experiments.train_gan", "train the DCGAN terrain generator on real DEM tiles"),
    "train-base-policy": ("experiments.train_base_policy", "train the flat-ground base walker with PPO"),
    "perceptive-policy": ("experiments.perceptive_policy", "the perceptive twin of a blind policy (network surgery)"),
    "features": ("experiments.features", "Experiment 1a: correlations of features with difficulty"),
    "evolve": ("experiments.evolve", "MAP-Elites archive for one generator and descriptor pair"),
    "difficulty-spread": ("experiments.difficulty_spread", "fitness spread of random terrains per generator and height scale"),
    "coverage": ("experiments.coverage", "Experiment 1b: archives of all generators, coverage table and figures"),
    "shares": ("experiments.shares", "who holds an archive's cells: each generator's share per distance band, a mixed "
                                     "archive beside the combined archive of separate runs"),
    "gradient": ("experiments.gradient", "difficulty gradient of archives: fitness against distance from cell (0, 0)"),
    "learn": ("experiments.learn", "Experiment 2, one treatment: PPO from the base policy on a curriculum over an archive"),
    "curriculum": ("experiments.curriculum", "Experiment 2: every treatment, Figure 7 and Table 2"),
    "train-traversability": ("experiments.train_traversability", "train the learned traversability patch classifier on base-policy walks"),
    "evaluate": ("experiments.evaluate", "walkers (the base policy and --policy folders) on the held-out suite or an archive"),
    "generalise": ("experiments.generalise", "Experiment 3: treatments' walkers on the held-out suite, rliable intervals"),
    "report": ("experiments.report", "one self-contained HTML page (and Markdown) of run folders, with walker videos"),
    "export": ("experiments.export", "terrains of an archive as OBJ / STL meshes, PNG, .npy or MJCF"),
    "export-policy": ("experiments.export_policy", "a walker as one ONNX file: normaliser and network, with its metadata"),
    "warp-patch": ("experiments.warp_patch", "patch MJX's vendored MuJoCo Warp heightfield collision (the "
                                             "local-origin fix every --backend warp run needs); --check, --revert"),
}


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """``--help`` shows each option's default, except where there is none to show (None, a flag's False) or the
    help text already states it."""

    def _get_help_string(self, action):
        text = action.help or ""
        if any(action.default is v for v in (None, False, argparse.SUPPRESS)) or "default" in text.lower():
            return text
        return super()._get_help_string(action)


PLUGIN_GROUP = "jaxterrain.plugins"
"""The entry-point group of installed plugins (``[project.entry-points."jaxterrain.plugins"]``)."""


def split_plugins(argv: list[str]) -> tuple[list[str], list[str]]:
    """``(plugin modules, the other arguments)`` of a command line: every ``--plugin MODULE`` / ``--plugin=MODULE``,
    wherever it stands (before ``--``)."""
    plugins, rest, i = [], [], 0
    while i < len(argv):
        arg = argv[i]
        if arg == "--":
            rest += argv[i:]
            break
        if arg == "--plugin":
            if i + 1 >= len(argv) or argv[i + 1].startswith("-"):
                raise PluginError("--plugin needs a module name, e.g. --plugin mylab.terrains")
            plugins.append(argv[i + 1])
            i += 2
            continue
        if arg.startswith("--plugin="):
            plugins.append(arg.split("=", 1)[1])
        else:
            rest.append(arg)
        i += 1
    return plugins, rest


class PluginError(Exception):
    """A plugin that cannot be loaded: one line naming it."""


def load_plugins(modules: list[str]) -> list[str]:
    """Import ``modules`` (``--plugin``) and every ``jaxterrain.plugins`` entry point; the names loaded, in order.
    :class:`PluginError` naming the plugin when one does not import."""
    from importlib import metadata

    loaded = []
    for name in modules:
        if not name or not all(part.isidentifier() for part in name.split(".")):
            raise PluginError(f"--plugin {name!r}: not a module name (dotted identifiers, e.g. mylab.terrains)")
        try:
            importlib.import_module(name)
        except Exception as err:  # noqa: BLE001 - any failure of the user's module is reported in one line
            raise PluginError(f"--plugin {name}: cannot import it ({type(err).__name__}: "
                              f"{str(err).splitlines()[0] if str(err) else ''})") from None
        loaded.append(name)
    for point in metadata.entry_points(group=PLUGIN_GROUP):
        try:
            obj = point.load()
            if callable(obj):
                obj()
        except Exception as err:  # noqa: BLE001
            raise PluginError(f"plugin {point.name} ({point.value}, entry point {PLUGIN_GROUP}): cannot load it "
                              f"({type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''})") from None
        loaded.append(point.value)
    return loaded


def build_parser(prog: str = "python -m experiments") -> tuple[argparse.ArgumentParser, dict]:
    """The parser of ``python -m experiments`` (or ``prog``: ``jaxterrain``, the console script) and ``{name: (module,
    its subparser)}`` of every command built, each flag's help ending with every preset's value (the docs'
    command-line page is written from the same parsers)."""
    from experiments.common import show_preset_values

    parser = argparse.ArgumentParser(prog=prog, description="every experiment of the paper, and the training jobs "
                                                              "behind them")
    parser.add_argument("--plugin", action="append", default=[], metavar="MODULE",
                        help="import MODULE first: its generators, descriptors and curricula become valid names in "
                             "every command (also after the command; repeatable). Installed packages' "
                             f"{PLUGIN_GROUP} entry points load too")
    sub = parser.add_subparsers(dest="command", required=True, metavar="command")
    commands = {}
    for name, (module_name, help_text) in COMMANDS.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as err:
            if err.name == module_name:  # command not built yet
                continue
            raise
        command = sub.add_parser(name, help=help_text, description=help_text, formatter_class=HelpFormatter)
        module.add_arguments(command)
        if hasattr(module, "PRESETS"):
            show_preset_values(command, module.PRESETS)
        commands[name] = (module, command)
    return parser, commands


def main(argv: list[str] | None = None, prog: str = "python -m experiments") -> int:
    try:
        plugins, argv = split_plugins(list(sys.argv[1:] if argv is None else argv))
        load_plugins(plugins)
    except PluginError as err:
        print(f"{prog}: error: {err}", file=sys.stderr)
        return 2
    parser, commands = build_parser(prog)
    available = {name: module for name, (module, _) in commands.items()}
    args = parser.parse_args(argv)
    args.plugin = plugins
    from experiments.common import UsageError, check_args

    try:  # bad flag values: one line naming the flag, exit status 2 (as argparse), before any JAX work
        check_args(args.command, args, getattr(available[args.command], "TYPED", None))
        return int(available[args.command].main(args) or 0)
    except UsageError as err:
        parser.exit(2, f"{parser.prog} {args.command}: error: {err}\n")


def console() -> None:
    """The ``jaxterrain`` console script (``[project.scripts]``): ``jaxterrain <command> ...`` is
    ``python -m experiments <command> ...``."""
    sys.exit(main(prog="jaxterrain"))


if __name__ == "__main__":
    sys.exit(main())

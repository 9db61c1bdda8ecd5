"""Helpers shared by the experiment commands: run folders, presets and saved configs.

Every command works the same way:

* its settings are one flat dict: the preset's values (``--preset``), replaced by a saved config (``--config FILE``),
  replaced by the options given on the command line (options left out keep ``None`` in argparse and change
  nothing);
* it writes them to ``<run folder>/config.json`` before doing any work, so ``--config <run folder>/config.json``
  re-runs it exactly;
* every start and every ``--resume`` appends one line to ``<run folder>/provenance.jsonl`` (:func:`record_provenance`:
  when, the code's commit, the devices, jax's version; a run on MuJoCo Warp also its heightfield collision,
  ``warp_hfield``), so a run continued on other machines names each of them;
* ``--resume [FOLDER]`` continues the run in FOLDER with the config saved there; finished pieces (archives,
  checkpoints) are reused. The folder is FOLDER, else ``--out`` (``--out RUN --resume`` continues RUN), else the
  newest ``runs/<command>-*``; ``--resume A --out B`` (two runs), a folder without ``config.json`` (no run to
  continue) and another command's run are one-line usage errors (:func:`resume_folder`), the same in every command.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import math
import sys
import time
from pathlib import Path
from typing import Any, Callable, NamedTuple

CONFIG_NAME = "config.json"
PROVENANCE_NAME = "provenance.jsonl"


class UsageError(ValueError):
    """A bad command-line value or run folder, found before any JAX work; ``python -m experiments`` prints it as one
    line ``... <command>: error: <message>`` and exits with status 2 (as argparse does)."""


# Option values of the commands whose settings are no typed config of the library yet, checked by name (argparse
# dest = config key): the smallest value, and the kind. The long commands' flags are checked by their config's
# declared rules instead (``experiments.cli_gen``: evolve, coverage, train-base-policy, evaluate, learn, curriculum).
_INT_MIN = {
    **dict.fromkeys(("n", "size", "samples", "batch_size", "attempts", "best", "steps", "sample_every", "ckpt_every",
                     "log_every", "batch", "stride", "calibrate_window", "devices", "chunk", "sample", "walk_batch",
                     "horizon", "eval_attempts", "eval_best", "terrains"), 1),
    "windows": 2,
    **dict.fromkeys(("mutation_steps", "walk", "quality_samples"), 0),
}
_FLOAT_POSITIVE = ("time_limit", "lr", "learning_rate", "heights", "band_width")
_FLOAT_NONNEGATIVE = ("r1", "scan_noise")
_FLOAT_UNIT = ("threshold",)  # in (0, 1]
_AT_MOST = (("best", "attempts"), ("eval_best", "eval_attempts"), ("windows", "size"))  # key (each of a list) <= bound


SELECTOR_NAMES = ("map", "roughness", "random", "dr", "levels", "plr", "accel")
"""The built-in curricula (``jaxterrain.curriculum.SELECTORS``; literal here so that ``--help`` imports no JAX)."""


def selector_name(text: str) -> str:
    """argparse type of ``--curriculum`` / ``--baseline``: a built-in curriculum, ``module:object``, or the name a
    plugin registered (``--plugin``; checked against the registry when the command runs)."""
    if text in SELECTOR_NAMES or (":" in text and all(text.partition(":")[::2])):
        return text
    if text.isidentifier() and "jaxterrain.curriculum.selectors" in sys.modules:  # a plugin may have registered it
        from jaxterrain.curriculum import selectors

        if text in selectors.selector_names():
            return text
    raise argparse.ArgumentTypeError(f"choose from {', '.join(SELECTOR_NAMES)}, a name registered by a --plugin, or "
                                     f"module:object; got {text!r}")


PRESET_NAMES = ("smoke", "gpu-short", "gpu", "paper")
"""The presets every long command takes, each with one meaning:

- ``smoke``: a CPU, tiny sizes: the command runs end to end (a check, not a result); most of its time is compiling,
  minutes on 2 CPU cores (``learn`` 6-10, ``evaluate`` 4-6: ``jaxterrain.runtime.estimates.SMOKE_MINUTES``);
- ``gpu-short``: one GPU, minutes: a tenth of ``gpu``'s budget;
- ``gpu``: one GPU, the full budget: the paper's protocol at GPU batch sizes;
- ``paper``: the paper's settings as it states them (where it states none, ``gpu``'s).

A command may add its own, described by its ``PRESET_NOTES`` (``coverage``'s ``paper-batched``,
``train-traversability``'s ``cpu``, ``gradient``'s ``default``)."""
PRESET_HELP = {
    "smoke": "tiny sizes on a CPU, a check that the command runs end to end, not a result; mostly compiling: {smoke}",
    "gpu-short": "a tenth of gpu's budget",
    "gpu": "the full budget on one GPU",
    "paper": "the paper's own settings",
}
"""Each preset's meaning in ``--help`` (``{smoke}``: the command's minutes, :func:`smoke_minutes`)."""


def library_file(name: str):
    """The library module ``name`` (``"runtime.estimates"``, ``"qd.run_config"``: one that imports only the standard
    library and ``jaxterrain.runtime.schema``), read from its file without running the package's ``__init__`` (which
    imports JAX), so ``--help`` stays fast. It is registered under its own name (``jaxterrain.qd.run_config``), so the
    package imported later uses the same module (the same classes); ``runtime.schema`` is read first, so a config
    module's ``from jaxterrain.runtime.schema import ...`` finds it."""
    import importlib
    import importlib.util

    full = f"jaxterrain.{name}"
    if full in sys.modules:
        return sys.modules[full]
    if "jaxterrain" in sys.modules:  # the package is imported: the ordinary import
        return importlib.import_module(full)
    if name != "runtime.schema":
        library_file("runtime.schema")
    spec = importlib.util.find_spec("jaxterrain")
    path = Path(spec.origin).parent.joinpath(*name.split(".")).with_suffix(".py")
    spec = importlib.util.spec_from_file_location(full, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[full] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[full]
        raise
    return module


def _estimates():
    """``jaxterrain.runtime.estimates`` (:func:`library_file`)."""
    return library_file("runtime.estimates")


def smoke_minutes(command: str) -> str:
    """How long ``command --preset smoke`` takes on 2 CPU cores, in words (``estimates.SMOKE_MINUTES``, where
    measured)."""
    est = _estimates()
    if command in est.SMOKE_MINUTES:
        low, high = est.SMOKE_MINUTES[command]
        return f"about {low:.0f}-{high:.0f} min on {est.CPU_NOTE}"
    return f"minutes on {est.CPU_NOTE}"


def preset_help(command: str, presets: dict[str, dict], default_preset: str,
                notes: dict[str, str] | None = None) -> str:
    """``--preset``'s help: every preset of ``presets`` with its meaning (:data:`PRESET_HELP`, then the command's
    ``notes`` for its own presets), and the default."""
    if all(p == next(iter(presets.values())) for p in presets.values()):  # gradient: one set of settings
        return f"every preset gives the same settings: {command} has one set (default {default_preset})"
    notes = {**{k: v.format(smoke=smoke_minutes(command)) for k, v in PRESET_HELP.items()}, **(notes or {})}
    order = [n for n in PRESET_NAMES if n in presets] + sorted(n for n in presets if n not in PRESET_NAMES)
    missing = [n for n in order if n not in notes]
    if missing:
        raise ValueError(f"presets {missing} of {command} have no meaning in its PRESET_NOTES")
    return "; ".join(f"{n}: {notes[n]}" for n in order) + f" (default {default_preset})"


def with_preset_names(presets: dict[str, dict], same: dict[str, Any] | None = None) -> dict[str, dict]:
    """``presets`` with every name of :data:`PRESET_NAMES` it lacks made from another preset: ``same`` maps a name
    to the preset it copies (``{"gpu": "paper"}``) or to ``(preset, changes)`` (``{"gpu-short": ("gpu",
    {"steps": 1200})}``); ValueError when one is still missing."""
    out = dict(presets)
    for name, made in (same or {}).items():
        other, changes = (made, {}) if isinstance(made, str) else made
        if name in out:
            raise ValueError(f"preset {name!r} exists; it cannot also be made from {other!r}")
        out[name] = {**presets[other], **changes}
    missing = [n for n in PRESET_NAMES if n not in out]
    if missing:
        raise ValueError(f"presets {missing} missing: every long command takes {', '.join(PRESET_NAMES)}")
    return out


def show_preset_values(parser: argparse.ArgumentParser, presets: dict[str, dict]) -> None:
    """Append to the help of every option that a preset sets the value each preset gives it (``[every preset: V]``
    or ``[smoke: a; gpu-short: b; ...]``), so ``--help`` shows what a flag left out will be."""
    order = [n for n in PRESET_NAMES if n in presets] + sorted(n for n in presets if n not in PRESET_NAMES)
    for action in parser._actions:
        if action.dest in ("preset", "help") or action.help == argparse.SUPPRESS or not any(
                action.dest in presets[n] for n in order):
            continue  # a hidden option (a deprecated alias) stays hidden
        shown = {n: _short(presets[n].get(action.dest)) for n in order}
        text = (f"every preset: {next(iter(shown.values()))}" if len(set(shown.values())) == 1
                else "; ".join(f"{n}: {v}" for n, v in shown.items()))
        action.help = f"{action.help or ''} [{text.replace('%', '%%')}]".strip()


def _short(value: Any) -> str:
    text = "-" if value is None else (" ".join(map(str, value)) if isinstance(value, (list, tuple)) else str(value))
    if isinstance(value, (list, tuple)) and not value:
        text = "none"
    if isinstance(value, str) and "/" in value:  # a path: its file name
        text = Path(value).name
    if isinstance(value, dict):
        text = " ".join(f"{k}={Path(str(v)).name}" for k, v in value.items())
    return text if len(text) <= 48 else text[:45] + "..."


def shipped(relative: str) -> str:
    """The absolute path of a file shipped in the package's ``assets/`` (e.g. ``"archives/cppn_headings.npz"``),
    found without importing jaxterrain (``--help`` imports no JAX): commands' default inputs work from any folder
    and from an installed wheel."""
    import importlib.util

    spec = importlib.util.find_spec("jaxterrain")
    if spec is None or spec.origin is None:
        raise UsageError("jaxterrain is not installed (pip install -e .)")
    return str(Path(spec.origin).parent / "assets" / relative)


FLAG_NAMES = {"n": "--terrains", "samples": "--terrains", "slots": "--rollout-slots", "rollout_backend": "--backend",
              "lr": "--learning-rate", "ckpt_every": "--checkpoint-every", "terrain_folder": "--terrains"}
"""Config keys whose flag has another name (the key kept so that older runs' ``config.json`` still read): terrains
sampled per generator is ``--terrains`` in every command, the rollout pool's env slots ``--rollout-slots``, the
walker's physics ``--backend``. The older spellings (``--n``, ``--samples``, ``--slots``, ``--rollout-backend``, ...)
still parse as hidden deprecated aliases (:func:`add_deprecated_alias`)."""


class _Deprecated(argparse.Action):
    """A hidden old spelling of an option: stores what the new one would, and says once on stderr which to use."""

    def __init__(self, option_strings, dest, new: str = "", const=None, nargs=None, **kwargs):
        self.new = new
        super().__init__(option_strings, dest, nargs=nargs, const=const, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"{parser.prog}: note: {option_string} is deprecated; use {self.new}", file=sys.stderr)
        setattr(namespace, self.dest, self.const if self.nargs == 0 else values)


def add_deprecated_alias(parser: argparse.ArgumentParser, old: str, new: str, dest: str, const: Any = None,
                         **kwargs) -> None:
    """Keep ``old`` working as a hidden alias of option ``new`` (same ``dest``): a value option when ``kwargs`` give
    its ``type`` / ``nargs`` / ``choices``, else a switch that stores ``const`` (``--freeze-normaliser`` is
    ``--no-update-normaliser``). Not shown in ``--help`` nor in the docs' command-line page; using it prints one note
    naming ``new``. Only for spellings that shipped docs or scripts use."""
    if "type" not in kwargs and "nargs" not in kwargs and "choices" not in kwargs:
        kwargs["nargs"] = 0
    parser.add_argument(old, dest=dest, action=_Deprecated, new=new, const=const, default=None,
                        help=argparse.SUPPRESS, **kwargs)


def count_or_folder(value: str) -> int | str:
    """``--terrains``' value where it takes either: an integer (terrains sampled per generator) or a folder of
    heightmaps (any other text)."""
    try:
        return int(value)
    except ValueError:
        return value


def add_terrains_argument(parser: argparse.ArgumentParser, dest: str, what: str, default: Any = None,
                          aliases: tuple[str, ...] = (), folder: str | None = None) -> None:
    """``--terrains N``: terrains sampled per generator, one flag in every command (``dest``: the config key, ``n`` or
    ``samples`` in older commands, kept so saved configs read); ``what`` says what the command does with them.
    ``aliases``: older spellings kept hidden (:func:`add_deprecated_alias`). ``folder``: what the command does with
    ``--terrains DIR``, a folder of heightmaps, where it also takes one (:func:`count_or_folder`: the command splits
    the two)."""
    if folder is not None:
        parser.add_argument("--terrains", dest=dest, type=count_or_folder, default=default, metavar="N|DIR",
                            help=f"terrains sampled per generator, >= 1: {what}; or DIR, a folder of heightmaps: "
                                 f"{folder}")
    else:
        parser.add_argument("--terrains", dest=dest, type=int, default=default, metavar="N",
                            help=f"terrains sampled per generator, >= 1: {what}")
    for old in aliases:
        add_deprecated_alias(parser, old, "--terrains", dest, type=int, metavar="N")


def slots_help(what: str) -> str:
    """``--rollout-slots``' help, the same words in every command that walks many terrains."""
    return f"{PHRASES['slots']}: {what}"


def add_slots_argument(parser: argparse.ArgumentParser, dest: str, what: str, type: Callable = int,
                       aliases: tuple[str, ...] = ()) -> None:
    """``--rollout-slots``: the env slots of the walker's rollout pool (speed and memory only), one flag in every
    command that walks many terrains (``dest``: the config key, ``slots`` in ``evaluate`` / ``gradient``)."""
    parser.add_argument("--rollout-slots", dest=dest, type=type, default=None, metavar="SLOTS", help=slots_help(what))
    for old in aliases:
        add_deprecated_alias(parser, old, "--rollout-slots", dest, type=type, metavar="SLOTS")


BACKEND_NAMES = ("auto", "jax", "warp")
"""``--backend`` choices of every command that walks: ``jaxterrain.walker.layout.BACKEND_CHOICES`` (a literal, so that
``--help`` imports no JAX; a test keeps the two equal)."""


RANDOMISATION_PRESET_NAMES = ("legged-gym",)
"""``--randomise`` preset names: ``jaxterrain.walker.RANDOMISATION_PRESETS`` (a literal, so that ``--help`` imports no
JAX; a test keeps the two equal)."""

PHRASES = {
    "backend": "auto (warp on a GPU where MuJoCo Warp imports, else jax), jax (MJX) or warp (MuJoCo Warp)",
    "randomise": f"(default off): a preset ({', '.join(RANDOMISATION_PRESET_NAMES)}) and/or comma-separated "
                 f"KEY=VALUE items, friction=LOW:HIGH (scale of the friction coefficient, 1.0 here), mass=LOW:HIGH "
                 f"(scale of each body's mass), added-mass=LOW:HIGH (kg on the torso), motor=LOW:HIGH (scale of the "
                 f"motors' force), obs-noise=STD, delay=STEPS or LOW:HIGH (env steps), push=EVERY:VELOCITY (env "
                 f"steps, m/s), drawn per env at reset; e.g. friction=0.5:1.25,push=200:0.5 or "
                 f"legged-gym,obs-noise=0.01 (jaxterrain.walker.randomisation)",
    "slots": "env slots of the walker's rollout pool (speed and device memory only; results do not change)",
}
"""Phrases every command's help shares, written ``{name}`` in a field's help (the config modules' ``HELP``) and
filled in by ``experiments.cli_gen``: ``--backend``'s choices, ``--randomise``'s spec, ``--rollout-slots``."""


def add_progress_argument(parser: argparse.ArgumentParser) -> None:
    """``--progress`` / ``--no-progress``, on every command that draws a progress bar (``jaxterrain.runtime.driver``):
    ``--no-progress`` prints plain lines instead, as it does anyway where stderr is not a terminal. It is a display
    choice, not a setting of the run (not in ``config.json``)."""
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=True,
                        help="a progress bar on a terminal; --no-progress: plain progress lines instead (as in a log "
                             "file)")


def progress_mode(args: argparse.Namespace) -> bool | str:
    """The ``progress`` argument of ``jaxterrain.runtime.driver.run_chunks`` for ``--progress`` / ``--no-progress``:
    True (a bar on a terminal, plain lines in a log file) or ``"plain"`` (plain lines always)."""
    return "plain" if getattr(args, "progress", True) is False else True


def flag(key: str) -> str:
    """The command-line flag of a config key / argparse dest: ``batch_size`` -> ``--batch-size``."""
    return FLAG_NAMES.get(key, "--" + key.replace("_", "-"))


def _bad(where: str, what: str, value: Any) -> UsageError:
    return UsageError(f"{where} must be {what}; got {value!r}")


def check_values(values: dict, where=flag) -> None:
    """Check option values by name (see ``_INT_MIN`` and friends; unknown names and ``None`` pass).

    ``where(key)`` names a value in the message (default: its flag). Fitness names are checked against
    :data:`FITNESSES`, generator and descriptor names against their registries (importing the library, which
    registers the learned ``traversability`` descriptor; running nothing), a ``size`` against each generator named
    (``generators.get(name, size=size)``: diamond-square takes powers of two), a ``robot`` against the registered
    robots and a ``module:object`` curriculum (``curriculum`` / ``baseline``) by importing it. Raises
    :class:`UsageError`."""
    for key, value in values.items():
        if value is None:
            continue
        items = value if isinstance(value, (list, tuple)) else [value]
        # Numbers only: a string (e.g. ``--slots auto``) is the command's to parse.
        numbers = [v for v in items if isinstance(v, (int, float)) and not isinstance(v, bool)]
        if key in _INT_MIN:
            low = _INT_MIN[key]
            for v in numbers:
                if not (math.isfinite(v) and v == int(v) and v >= low):
                    raise _bad(where(key), f"{'integers' if isinstance(value, list) else 'an integer'} >= {low}", value)
        elif key in _FLOAT_POSITIVE or key in _FLOAT_NONNEGATIVE:
            positive = key in _FLOAT_POSITIVE
            for v in numbers:
                if not math.isfinite(v) or (v <= 0 if positive else v < 0):
                    raise _bad(where(key), f"{'finite numbers' if isinstance(value, list) else 'a finite number'} "
                                           f"{'> 0' if positive else '>= 0'}", value)
        elif key in _FLOAT_UNIT:
            for v in numbers:
                if not (math.isfinite(v) and 0.0 < v <= 1.0):
                    raise _bad(where(key), "a number in (0, 1]", value)
        elif key in ("descriptors", "extra_descriptors") and items:
            import jaxterrain  # noqa: F401 - registers the learned descriptor (features.learned)
            from jaxterrain import features

            for v in items:
                if v not in features.descriptor_names():
                    raise UsageError(f"{where(key)}: unknown descriptor {v!r}; choose from "
                                     f"{', '.join(features.descriptor_names())}")
        elif key == "fitness" and (not isinstance(value, str) or value not in FITNESS_NAMES):
            raise UsageError(f"{where(key)}: unknown fitness {value!r}; choose from {', '.join(FITNESS_NAMES)}")
        elif key in ("generator", "generators", "mix") and items:
            from jaxterrain import generators

            if key == "generator" and value == "mixed":  # evolve --generator mixed: its --mix names are checked
                continue
            for v in items:
                if v not in generators.names():
                    names = ", ".join(generators.names())
                    raise UsageError(f"{where(key)}: unknown generator {v!r}; choose from {names} (or one a --plugin "
                                     f"registers)")
            size = values.get("size")
            if isinstance(size, int) and not isinstance(size, bool) and size >= 1:
                for v in items:
                    try:
                        generators.get(v, size=size)
                    except (ValueError, OSError) as err:  # e.g. diamond-square's powers of two, missing weights
                        text = str(err).splitlines()[0].removeprefix(f"{v}: ")
                        raise UsageError(f"{where('size')} {size} does not suit generator {v!r} ({where(key)}): {text}") \
                            from None
        elif key == "randomise":
            from jaxterrain.walker import parse_randomisation

            try:
                parse_randomisation(value)
            except ValueError as err:
                raise UsageError(f"{where(key)}: {err}") from None
        elif key == "robot":
            from jaxterrain.walker import robots

            try:
                robots.get(value)
            except (TypeError, ValueError) as err:  # e.g. --robot '' (which used to walk the humanoid)
                raise UsageError(f"{where(key)}: {err}") from None
        elif key in ("curriculum", "baseline"):
            for v in items:
                if isinstance(v, str) and ":" in v:  # module:object: the user's module, imported once here
                    from jaxterrain.curriculum import selectors

                    try:
                        selectors.resolve_factory(v)
                    except ValueError as err:
                        raise UsageError(f"{where(key)} {str(err).split(' ', 1)[1]}") from None
    for key, bound in _AT_MOST:
        v, b = values.get(key), values.get(bound)
        for item in v if isinstance(v, (list, tuple)) else [v]:
            if isinstance(item, int) and isinstance(b, int) and not isinstance(item, bool) and item > b:
                raise UsageError(f"{where(key)} must be <= {where(bound)} ({b}); got {v}")
    heads, attempts, best = values.get("headings"), values.get("attempts"), values.get("best")
    if heads is not None:  # the walker protocol: attempts in total over the headings, best per heading
        if heads not in (1, 2, 4) or isinstance(heads, bool):
            raise _bad(where("headings"), "1, 2 or 4", heads)
        if isinstance(attempts, int) and attempts % heads:
            raise UsageError(f"{where('attempts')} must be a multiple of {where('headings')} ({heads}); got {attempts}")
        if isinstance(attempts, int) and isinstance(best, int) and best > attempts // heads:
            raise UsageError(f"{where('best')} must be <= {where('attempts')} / {where('headings')} "
                             f"({attempts // heads}); got {best}")


def check_rules(values: dict, rules: dict, where: Callable[[str], str] = flag) -> None:
    """Run the declared ``rules`` (``{flat key: (rule, ...)}``: ``jaxterrain.runtime.schema``'s, the ones the
    command's flags are made from, ``experiments.cli_gen``) on a flat config ``values`` (a None value passes);
    :class:`UsageError` whose message names the key by ``where(key)`` (its flag, or the preset or file it came
    from)."""
    view = argparse.Namespace(**values)
    for key, rule in rules.items():
        if values.get(key) is not None:
            for one in rule:
                try:
                    one(values[key], key, view, where)
                except ValueError as err:
                    raise UsageError(str(err)) from None


def check_out(out: Any, where: str = "--out") -> None:
    """A run folder given by the user must be a folder or not exist yet (its parents: folders or missing)."""
    if out is None:
        return
    path = Path(out)
    for p in (path, *path.parents):
        if p.exists() and not p.is_dir():
            what = "is a file" if p == path else f"lies under {p}, which is a file"
            raise UsageError(f"{where} {str(path)!r} {what}; give a new or existing run folder")


def check_resume(command: str, resume: Any, flags: str | None = None) -> None:
    """``--resume FOLDER`` must not be a file, nor a run folder whose ``config.json`` names another command (a
    folder without one: :func:`resume_folder`). ``flags`` names the folder in the message (default
    ``--resume 'FOLDER'``)."""
    if not isinstance(resume, (str, Path)) or resume == "latest":
        return  # a flag (store_true) or the newest run (``latest_run`` checks it)
    folder = Path(resume)
    flags = flags or f"--resume {str(folder)!r}"
    if folder.exists() and not folder.is_dir():
        raise UsageError(f"{flags} is a file; give a run folder")
    config_path = folder / CONFIG_NAME
    if not config_path.is_file():
        return
    try:
        saved = json.loads(config_path.read_text())
    except (OSError, ValueError) as err:
        raise UsageError(f"{flags}: cannot read {config_path} ({err})") from None
    other = saved.get("command") if isinstance(saved, dict) else None
    if isinstance(other, str) and other != command:
        raise UsageError(f"{flags} is a run of {other!r}, not of {command!r}")


def check_args(command: str, args: argparse.Namespace, typed: Typed | None = None) -> None:
    """Check a parsed command line before the command runs (``python -m experiments`` calls this): numbers by
    option name (sizes, counts >= 1, ...), fitness and generator names, ``--out`` (not a file), ``--resume`` (with
    ``--out``: one run folder of this command, :func:`resume_folder`), ``--config`` and ``--data`` (exist). Raises
    :class:`UsageError` naming the flag. A command whose run is a typed config (``typed``, :class:`Typed`) has its
    config's values checked once, by the library, on the resolved config (:func:`setup_typed`): here only its other
    flags (``--time-limit``, ``--devices``, ...)."""
    values = vars(args)
    if values.get("one_piece") and values.get("time_limit") is not None:
        raise UsageError(f"--time-limit: {command} runs in one piece (nothing to stop at and resume); drop the flag")
    if values.get("unseeded") and values.get("seed") is not None:
        raise UsageError(f"--seed: {command} draws nothing at random (its tables are the same for every seed); drop "
                         f"the flag")
    check_values({k: v for k, v in values.items() if typed is None or k not in typed.fields})
    check_out(values.get("out"))
    check_resume(command, values.get("resume"))
    if values.get("resume") is not None:
        resume_folder(command, values["resume"], values.get("out"))
    for key in ("config", "data", "quality_only"):
        path = values.get(key)
        if isinstance(path, (str, Path)) and not Path(path).exists():
            raise UsageError(f"{flag(key)} {str(path)!r}: no such file or folder")


def refuse_given(flags: dict[str, Any], why: str) -> None:
    """The first of ``flags`` (``{flag: its parsed value}``, None: not given) that was given, refused in one line
    ``<flag>: <why>``: a flag this run would accept and ignore (:class:`UsageError`)."""
    for name, value in flags.items():
        if value is not None:
            raise UsageError(f"{name}: {why}")


def add_run_arguments(parser: argparse.ArgumentParser, presets: dict[str, dict], default_preset: str,
                      notes: dict[str, str] | None = None, time_limit: bool = True, seed: bool = True) -> None:
    """Add ``--preset``, ``--config``, ``--resume``, ``--out``, ``--seed``, ``--time-limit`` and ``--print-config``.
    ``notes``: the meaning of the command's own presets (those beyond :data:`PRESET_NAMES`); ``time_limit``: False for
    a command that runs in one piece (its ``--time-limit`` is hidden and refused in one line by :func:`check_args`,
    never accepted and ignored); ``seed``: False for a command that draws nothing at random (its ``--seed`` hidden
    and refused the same way)."""
    command = parser.prog.split()[-1]
    parser.add_argument("--preset", choices=sorted(presets), default=None,
                        help=preset_help(command, presets, default_preset, notes).replace("%", "%%"))
    parser.add_argument("--config", type=Path, default=None, help="re-run from a saved config.json")
    parser.add_argument("--resume", nargs="?", const="latest", default=None, metavar="FOLDER",
                        help="continue the run in FOLDER (default: the newest run of this command)")
    parser.add_argument("--out", type=Path, default=None, help="run folder (default runs/<command>-<timestamp>)")
    parser.add_argument("--seed", type=int, default=None,
                        help="PRNG seed of the run (every random draw derives from it; default 0)" if seed
                        else argparse.SUPPRESS)
    if not seed:
        parser.set_defaults(unseeded=True)
    parser.add_argument("--time-limit", type=float, default=None, metavar="MIN",
                        help="stop cleanly after about MIN minutes (after a checkpoint); continue with --resume"
                        if time_limit else argparse.SUPPRESS)
    parser.set_defaults(one_piece=not time_limit)
    parser.add_argument("--print-config", action="store_true",
                        help="print the resolved configuration (preset, --config and flags) as JSON and exit, "
                             "before any run folder is made or anything compiles")


def print_config(args: argparse.Namespace, config: dict) -> None:
    """``--print-config``: print ``config`` as sorted JSON and exit with status 0 (nothing written)."""
    if getattr(args, "print_config", False):
        print(json.dumps(config, indent=2, sort_keys=True, default=str))
        raise SystemExit(0)


def add_devices_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--devices N``: the work of a long command split over devices (:func:`device_mesh`)."""
    parser.add_argument("--devices", type=int, default=None, metavar="N",
                        help="split the work over the first N devices of all processes (default: every visible "
                             "device); several processes or hosts: the JAXTERRAIN_* variables of the README")


def device_mesh(devices: int | None):
    """The ``jax.sharding.Mesh`` of ``--devices``: ``jaxterrain.runtime.sharding.setup`` joins a multi-process run when
    ``JAXTERRAIN_COORDINATOR`` / ``JAXTERRAIN_NUM_PROCESSES`` / ``JAXTERRAIN_PROCESS_ID`` are set, then takes the
    first ``devices`` devices of all processes (None: all). More than exist is a :class:`UsageError`."""
    from jaxterrain.runtime import sharding

    try:
        return sharding.setup(devices)
    except ValueError as err:
        raise UsageError(f"--devices: {err}") from None


def timestamp() -> str:
    """UTC time as ``YYYYmmdd-HHMMSS``, the suffix of default run folders."""
    return _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%d-%H%M%S")


def run_folder(name: str, out: str | Path | None = None) -> Path:
    """``out``, or the default run folder ``runs/<name>-<UTC time>``; not created here."""
    return Path(out) if out else Path("runs") / f"{name}-{timestamp()}"


def latest_run(command: str, root: Path = Path("runs")) -> Path:
    runs = sorted(p for p in root.glob(f"{command}-*") if (p / CONFIG_NAME).exists())
    if not runs:
        raise UsageError(f"--resume: no run of {command!r} with a {CONFIG_NAME} under {root}/; give its folder")
    return runs[-1]


PATH_KEYS = ("archive", "archives", "policy", "data", "out", "assets_dir")
"""Config keys that hold file or folder paths (a path, a list of them or a ``{name: path}`` dict): ``config.json``
records them relative to its run folder (:func:`write_config`), marked by :data:`PATHS_KEY`."""
PATHS_KEY = "paths_relative_to_this_folder"


def _paths(config: dict, convert: Callable[[str], str]) -> dict:
    out = dict(config)
    for key in PATH_KEYS:
        value = out.get(key)
        if isinstance(value, (str, Path)):
            out[key] = convert(str(value))
        elif isinstance(value, list):
            out[key] = [convert(str(v)) if isinstance(v, (str, Path)) else v for v in value]
        elif isinstance(value, dict):
            out[key] = {k: convert(str(v)) if isinstance(v, (str, Path)) else v for k, v in value.items()}
    return out


def load_config(path: str | Path) -> dict:
    """A saved ``config.json`` (or the one in folder ``path``) as a dict, its paths as this machine reads them:
    a config written by :func:`write_config` records them relative to its folder (or ``<jaxterrain>/...``), an older
    one absolute or relative to where it ran, read as they are."""
    path = Path(path)
    if path.is_dir():
        path = path / CONFIG_NAME
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise SystemExit(f"cannot read config {path}: {err}") from err
    if not isinstance(data, dict):
        raise SystemExit(f"config {path} must hold a JSON object")
    if data.pop(PATHS_KEY, False):
        from jaxterrain.runtime.provenance import resolve_recorded

        data = _paths(data, lambda v: resolve_recorded(v, path.parent))
    return data


def write_config(folder: Path, config: dict) -> Path:
    """Write ``config`` as ``folder/config.json``, its paths (:data:`PATH_KEYS`) relative to ``folder`` or
    ``<jaxterrain>/...`` for the package's own files (``jaxterrain.runtime.provenance.portable_path``): no machine's
    absolute path. :func:`load_config` reads them back."""
    from jaxterrain.runtime.io import atomic_write_text
    from jaxterrain.runtime.provenance import portable_path

    saved = {**_paths(config, lambda v: portable_path(v, folder)), PATHS_KEY: True}
    return atomic_write_text(Path(folder) / CONFIG_NAME, json.dumps(saved, indent=2, sort_keys=True) + "\n")


def save_figure(fig, path: str | Path, dpi: int = 120) -> Path:
    """Write a matplotlib figure as PNG atomically (never a half-written file), then close it
    (:func:`jaxterrain.runtime.io.save_figure`)."""
    from jaxterrain.runtime.io import save_figure as save

    return save(fig, path, dpi)


def setup_run(command: str, args: argparse.Namespace, presets: dict[str, dict], default_preset: str,
              overrides: dict[str, Any], extendable: tuple[str, ...] = (),
              check: Callable[[dict], None] | None = None, rules: dict | None = None) -> tuple[Path, dict]:
    """Resolve the settings and the run folder; write the config there. Returns ``(folder, config)``.

    ``overrides`` maps config keys to the values given on the command line (``None`` = not given). ``--resume``
    continues the run in :func:`resume_folder` (``--resume FOLDER``, or ``--out RUN --resume``, or the newest run)
    with the config saved there; options given on the command line are ignored (a note on stderr says which),
    except the keys of ``extendable`` (how long the run lasts and how often it logs, e.g. ``steps``): those replace
    the saved values, are checked as a fresh config is, and are written back to the run's ``config.json``.
    ``check(config)``: the command's own checks of the resolved config (raise :class:`UsageError`), run before any
    folder is made. Values are checked by the declared ``rules`` (``{flat key: (rule, ...)}``,
    :func:`check_rules`; those the command's flags are made from), then by name (:func:`check_values`: the names
    against the registries); a command whose run is a typed config of the library uses :func:`setup_typed`.
    """

    def settle(config: dict, where, resumed: bool, changed: bool) -> dict:
        if not resumed:
            unknown = set(config) - set(presets[default_preset]) - {"preset", "seed", "command"}
            if unknown:
                raise SystemExit(f"unknown config key(s) {sorted(unknown)}; known: {sorted(presets[default_preset])}")
        if not resumed or changed:
            check_rules(config, rules or {}, where)
            check_values(config, where)
        if not resumed and check is not None:
            check(config)
        return config

    return prepare_run(command, args, presets, default_preset, overrides, extendable, settle, preset_by_flag=False)


def prepare_run(command: str, args: argparse.Namespace, presets: dict[str, dict], default_preset: str,
                overrides: dict[str, Any], extendable: tuple[str, ...], settle: Callable[..., dict],
                preset_by_flag: bool) -> tuple[Path, dict]:
    """The one resolution of a run's settings (:func:`setup_run`, :func:`setup_typed`): the preset's, a saved
    ``--config``'s or, with ``--resume``, the run's own; the flags given (on a resumed run only those of
    ``extendable``; the others are ignored with a note); ``settle(config, where, resumed, changed)`` checks them and
    returns the flat config to record (``where(key)``: how a message names a key: its flag where given on the
    command line, or, with ``preset_by_flag``, set by a preset; else ``FILE: key 'k'`` / ``preset 'P': 'k'``);
    ``--print-config`` prints it; then the run folder is made (or found) and ``config.json`` written."""
    resumed = args.resume is not None
    given = {k: v for k, v in overrides.items() if v is not None}
    if resumed:
        folder = resume_folder(command, args.resume, getattr(args, "out", None))
        config = load_config(folder)
        if command in SPAWN_CONFIGS and "spawn" not in config:  # saved before the key: the rule it started with
            config.update(started_spawn(folder))
        ignored = sorted(k for k in given if k not in extendable)
        if ignored:
            print(f"--resume: ignoring {ignored}; the run continues with its saved config", file=sys.stderr)
        given = {k: v for k, v in given.items() if k in extendable}
        source = f"{folder / CONFIG_NAME}: key"
    elif args.config is not None:
        config = load_config(args.config)
        if args.preset is not None:
            config = {**presets[args.preset], **config, "preset": args.preset}
        source = f"{args.config}: key"
    else:
        preset = args.preset or default_preset
        config, source = {**presets[preset], "preset": preset}, None if preset_by_flag else f"preset {preset!r}:"
    config.update(given)
    if not resumed:
        if args.seed is not None:
            config["seed"] = given["seed"] = args.seed
        config.setdefault("seed", 0)
    where = lambda k: flag(k) if k in given or source is None else f"{source} {k!r}"  # noqa: E731
    flat = {**settle(config, where, resumed, bool(given)), "command": command}
    print_config(args, flat)
    if resumed:
        if given:
            write_config(folder, flat)
        record_provenance(folder, command, vars(args), resumed=True, backend=physics(flat), spawn=spawn_rule(command, flat))
        print(f"resuming {folder}", flush=True)
        return folder, flat
    check_out(args.out)
    folder = run_folder(command, args.out)
    folder.mkdir(parents=True, exist_ok=True)
    write_config(folder, flat)
    record_provenance(folder, command, vars(args), backend=physics(flat), spawn=spawn_rule(command, flat))
    print(f"run folder {folder}", flush=True)
    return folder, flat


def physics(flat: dict) -> str | None:
    """The walker backend a run's flat config names (``backend``, evolve's ``rollout_backend``; None for MuJoCo C
    walks, ``engine: mujoco``, and for commands without one)."""
    if flat.get("engine", "mjx") != "mjx":
        return None
    backend = flat.get("backend", flat.get("rollout_backend"))
    return backend if isinstance(backend, str) else None


STOCK_WARP_NOTE = ("note: this run walks on MuJoCo Warp's stock heightfield collision, which launches a foot buried "
                   "far from the heightfield's centre (docs/results/sim2sim/warp_hfield/REPORT.md); "
                   "'python -m experiments warp-patch' applies the fix (recorded as warp_hfield in provenance.jsonl)")
"""What a Warp run on the stock heightfield kernel is told, once, when its run folder is made or resumed."""


def warp_importable() -> bool:
    """Whether the walker can run on MuJoCo Warp here (``jaxterrain.walker.tiles.warp_available``: warp-lang and
    MJX's MuJoCo Warp import), the check whose failure refuses a Warp run; called only for a Warp run."""
    from jaxterrain.walker import tiles

    return tiles.warp_available()[0]


SPAWN_CONFIGS = {"learn": "jaxterrain.curriculum.run_config", "curriculum": "jaxterrain.curriculum.run_config",
                 "evaluate": "jaxterrain.suite.run_config", "evolve": "jaxterrain.qd.run_config",
                 "coverage": "jaxterrain.qd.run_config", "train-base-policy": "jaxterrain.difficulty.run_config"}
"""The commands with a ``spawn`` setting, and the run-config module whose ``LEGACY`` says what a ``config.json``
written before the key ran with."""


def spawn_rule(command: str, flat: dict) -> str | None:
    """The spawn rule ``command``'s flat config makes its walkers use: its ``spawn``, or for a ``config.json``
    written before the key existed its run config's ``LEGACY`` value (the rule it ran with); None for commands
    whose walkers take the library's default (:data:`SPAWN_CONFIGS` lists those that do not)."""
    if command not in SPAWN_CONFIGS:
        return None
    if "spawn" in flat:
        return flat["spawn"]
    import importlib

    return importlib.import_module(SPAWN_CONFIGS[command]).LEGACY["spawn"]


def started_spawn(folder: Path) -> dict:
    """``{"spawn": rule}``, the spawn rule a run folder's ``provenance.jsonl`` records for the process that started the
    run (its first line, not resumed; lines written since 2026-11-29 say the rule, the library's default then), or
    ``{}`` where none does: a resumed run whose ``config.json`` was saved before its command had the key continues
    under the rule it started with, and one started before the rule was recorded reads its run config's ``LEGACY``
    (``patch``)."""
    try:
        first = json.loads((Path(folder) / PROVENANCE_NAME).read_text().splitlines()[0])
    except (OSError, IndexError, ValueError):
        return {}
    spawn = first.get("spawn") if isinstance(first, dict) and not first.get("resumed") else None
    return {"spawn": spawn} if spawn in ("feet", "patch") else {}


def record_provenance(folder: Path, command: str, options: dict | None = None, resumed: bool = False,
                      backend: str | None = None, spawn: str | None = None) -> dict:
    """Append one JSON line to ``folder/provenance.jsonl`` and return it: the UTC time, the command, the options
    given (those not None), whether it resumed the run, the code's commit (``jaxterrain.runtime.provenance.git_commit``:
    ``git`` of the checkout, or ``$JAXTERRAIN_COMMIT`` on a machine that received the tree without ``.git``), the
    JAX devices, the process count and jax's version; where the run's walker ``backend`` (its config's, ``auto``
    resolved here by ``jaxterrain.walker.resolve_backend``) is ``warp``, also ``warp_hfield``: which heightfield
    collision MuJoCo Warp runs (``provenance.warp_hfield``: ``"local-origin patch"`` after ``warp-patch``, or
    ``"stock"``); and ``spawn``, the walkers' spawn rule (``spawn``, the run's own, e.g. :func:`spawn_rule`; None:
    the library's default, ``WalkerConfig().spawn``). One ``write`` of a line opened
    for appending, so processes that share a run folder (``--shard``)
    each add theirs; in a multi-process JAX run only process 0 writes."""
    import os

    import jax

    from jaxterrain.runtime import provenance
    from jaxterrain.walker import WalkerConfig, resolve_backend

    given = {k: v for k, v in (options or {}).items() if v is not None}
    line = {"time": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"), "command": command,
            "options": given, "resumed": bool(resumed), "commit": provenance.git_commit(),
            "devices": provenance.device(), "processes": jax.process_count(), "jax": jax.__version__}
    if isinstance(backend, str) and resolve_backend(backend) == "warp":
        line["warp_hfield"] = provenance.warp_hfield()
        if line["warp_hfield"] == "stock" and warp_importable():  # without warp the run is refused anyway
            print(STOCK_WARP_NOTE, file=sys.stderr, flush=True)
    line["spawn"] = spawn or WalkerConfig().spawn  # the walkers' spawn rule
    if jax.process_index() == 0:
        fd = os.open(Path(folder) / PROVENANCE_NAME, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        try:
            os.write(fd, (json.dumps(line, default=str) + "\n").encode())
        finally:
            os.close(fd)
    return line


class TimeUp(Exception):
    """Raised from a progress callback when ``--time-limit`` is reached (after a checkpoint was written)."""


class Clock:
    """``--time-limit`` bookkeeping: ``check()`` raises :class:`TimeUp` once the limit has passed."""

    def __init__(self, minutes: float | None):
        self.start = time.perf_counter()
        self.limit = None if minutes is None else 60.0 * minutes

    def elapsed(self) -> float:
        return time.perf_counter() - self.start

    def check(self) -> None:
        if self.limit is not None and self.elapsed() > self.limit:
            raise TimeUp


FITNESS_NAMES = ("difficulty", "slope")
"""``--fitness`` choices: the names of ``jaxterrain.difficulty.FITNESSES`` (a literal, so ``--help`` imports no
JAX; a test checks that the two agree)."""


def fitness_of(name: str):
    """``jaxterrain.difficulty.FITNESSES[name]`` (None: the walker's fitness, built from the run's config); an
    unknown name is a :class:`UsageError` naming ``--fitness``."""
    if name not in FITNESS_NAMES:
        raise UsageError(f"--fitness: unknown fitness {name!r}; choose from {', '.join(FITNESS_NAMES)}")
    from jaxterrain.difficulty import FITNESSES

    return FITNESSES[name]


def generator_available(name: str, size: int) -> tuple[bool, str]:
    """Whether generator ``name`` can be built and render at ``size`` (e.g. the GAN needs weights), and why not:
    ``jaxterrain.features.alignment.generator_available``."""
    from jaxterrain.features.alignment import generator_available as available

    return available(name, size)


def resume_folder(command: str, resume: Any, out: Any = None) -> Path:
    """The run folder that ``--resume`` names, the same rule in every command: ``--resume FOLDER`` is FOLDER;
    ``--resume`` alone is ``--out`` when given (``--out RUN --resume`` continues RUN), else the newest run of
    ``command`` (:func:`latest_run`). A :class:`UsageError` (one line naming the flags) when ``--resume FOLDER`` and
    ``--out`` name two folders, when the folder holds no ``config.json`` (no run to continue: start one with
    ``--out`` alone) or when it is a file or another command's run (:func:`check_resume`)."""
    if resume not in (None, "latest"):
        if out is not None and Path(out).resolve() != Path(resume).resolve():
            raise UsageError(f"--resume {resume} and --out {out} name different runs; give one of them")
        folder, flags = Path(resume), f"--resume {str(resume)!r}"
    elif out is not None:
        folder, flags = Path(out), f"--out {str(out)!r} --resume"
    else:
        return latest_run(command)
    check_resume(command, folder, flags)
    if not (folder / CONFIG_NAME).is_file():
        raise UsageError(f"{flags}: no {CONFIG_NAME} in {str(folder)!r}, so no run to continue; start one with "
                         f"--out {folder} (without --resume)")
    return folder


def setup_resumable_run(command: str, args: argparse.Namespace, presets: dict[str, dict], default_preset: str,
                        overrides: dict[str, Any], extendable: tuple[str, ...] = (),
                        check: Callable[[dict], None] | None = None) -> tuple[Path, dict]:
    """:func:`setup_run` (its name in the training commands: ``train-gan``, ``train-base-policy``,
    ``train-traversability``, ``features``)."""
    return setup_run(command, args, presets, default_preset, overrides, extendable, check)


def say(line: str) -> None:
    """Print ``line`` to stdout above the progress bar of ``jaxterrain.runtime.driver.run_chunks`` (``tqdm.write``), or
    plainly without tqdm."""
    try:
        from tqdm.auto import tqdm

        tqdm.write(line, file=sys.stdout)
    except ImportError:  # pragma: no cover
        print(line, flush=True)


def parse_shard(text: str) -> tuple[int, int]:
    """``"I/N"`` -> ``(I, N)`` with ``0 <= I < N``; anything else is an argparse error naming ``--shard``."""
    try:
        i, n = (int(v) for v in text.split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--shard must be I/N (two integers), got {text!r}") from None
    if not (n >= 1 and 0 <= i < n):
        raise argparse.ArgumentTypeError(f"--shard I/N needs N >= 1 and 0 <= I < N, got {text!r}")
    return i, n


PROTOCOL_NAMES = ("headings", "paper")
"""``--protocol`` choices: the names of ``jaxterrain.difficulty.PROTOCOLS`` (a literal, so ``--help`` imports no JAX;
a test checks that the two agree)."""


def add_protocol_argument(parser: argparse.ArgumentParser) -> None:
    """``--protocol paper|headings``: sets ``attempts``, ``best`` and ``headings`` together
    (``jaxterrain.difficulty.PROTOCOLS``);
    ``--attempts`` / ``--best`` / ``--headings``, where the command has them, override single fields."""
    parser.add_argument("--protocol", choices=PROTOCOL_NAMES, default=None,
                        help="the walker fitness: paper (20 walks along +x, best 5) or headings (20 walks in each "
                             "of 4 headings, best 5 per heading, mean over headings)")


def protocol_overrides(args: argparse.Namespace) -> dict:
    """The config overrides of ``--protocol`` and of the single-field flags the command has (given ones win)."""
    name = getattr(args, "protocol", None)
    out = {}
    if name is not None:
        from jaxterrain.difficulty import PROTOCOLS

        p = PROTOCOLS[name]
        out = dict(attempts=int(p.attempts), best=int(p.best), headings=int(p.headings))
    for key in ("attempts", "best", "headings"):
        if getattr(args, key, None) is not None:
            out[key] = getattr(args, key)
    return out


# ----------------------------------------------------------------------------------------------------------------
# Commands whose run is a typed config of the library (evolve, coverage, train-base-policy, evaluate)
# ----------------------------------------------------------------------------------------------------------------


class Typed(NamedTuple):
    """A command's run as a typed config of the library (``jaxterrain.qd.run_config.EvolveRun``, ...): ``owner``,
    the config's name in the library's messages (``EvolveRun.map_elites.bins must be ...``); ``fields``, its
    ``{flat key: field path}`` table (the flat keys are ``config.json``'s and the flags' names: :func:`flag`);
    ``from_flat`` / ``to_flat``, its serialised form; ``rules``, its declared checks of single fields (``{field path:
    rule}``, ``jaxterrain.runtime.schema``), from which ``experiments.cli_gen`` makes each flag's type, choices and
    range. A field becomes a flag in one place: its flat key through :func:`flag` (``cli_gen`` makes the options,
    :func:`flags_in` names the fields in messages)."""

    owner: str
    fields: dict
    from_flat: Callable[[dict], Any]
    to_flat: Callable[..., dict]
    rules: dict = {}


def flags_in(text: str, typed: Typed, where: Callable[[str], str] = flag) -> str:
    """A library message with its fields (``<owner>.<path>``) named as this command's flags:
    ``EvolveRun.map_elites.bins`` -> ``--bins`` (``where(flat key)``, by default :func:`flag`); a path that is no
    flat key (a part) -> the flag of its last name."""
    inverse = {path: key for key, path in typed.fields.items()}
    schema = library_file("runtime.schema")
    return schema.rename_fields(text, typed.owner, lambda path: where(inverse.get(path, path.rsplit(".", 1)[-1])))


def typed_run(typed: Typed, config: dict, where: Callable[[str], str] = flag,
              validate: Callable[[Any], Any] | None = None):
    """The typed run of a flat ``config`` (``typed.from_flat``), checked by the library's ``validate`` (which
    returns the run to record, e.g. with a size it raised); :class:`UsageError` naming the flags (:func:`flags_in`
    with ``where``) for an unknown key or a bad value."""
    try:
        run = typed.from_flat({k: v for k, v in config.items() if k != "command"})
        return run if validate is None else validate(run)
    except (ValueError, TypeError) as err:
        raise UsageError(flags_in(str(err).splitlines()[0] if str(err) else repr(err), typed, where)) from None


def setup_typed(command: str, args: argparse.Namespace, presets: dict[str, dict], default_preset: str, typed: Typed,
                overrides: dict[str, Any], validate: Callable[[Any], Any], extendable: tuple[str, ...] = (),
                check: Callable[[Any], None] | None = None) -> tuple[Path, Any]:
    """:func:`setup_run` for a command whose run is a typed config of the library: the flat settings resolved as there
    (the preset, ``--config``, the flags; or ``--resume``'s saved ones with the ``extendable`` keys given), read into
    the typed run and validated ONCE, by the library's ``validate`` (which returns the run to record; its errors name
    the flags: a value given on the command line or set by a preset by its flag, one read from a file as ``FILE: key
    'k'``), then, for a new run, ``check(run)`` (the command's checks of the flags themselves, e.g. one accepted and
    ignored); ``--print-config`` prints the run's flat form; the run folder is made and ``config.json`` written only
    then. Returns ``(folder, run)``."""
    runs = []

    def settle(config: dict, where, resumed: bool, changed: bool) -> dict:
        runs.append(typed_run(typed, config, where, validate))
        if not resumed and check is not None:
            check(runs[-1])
        return typed.to_flat(runs[-1])

    folder, _ = prepare_run(command, args, presets, default_preset, overrides, extendable, settle, preset_by_flag=True)
    return folder, runs[-1]


def flag_values(args: argparse.Namespace, typed: Typed) -> dict:
    """The config values given on the command line, ``{flat key: value}`` (None: not given) of every field with a
    flag of the same name (``args``' dest = the flat key), ``--protocol`` resolved (:func:`protocol_overrides`)."""
    out = {k: getattr(args, k) for k in typed.fields if k not in ("seed", "preset") and hasattr(args, k)}
    out.update(protocol_overrides(args))
    return out


def minutes_to_seconds(minutes: float | None) -> float | None:
    """``--time-limit MIN`` as the library's ``time_limit_s``."""
    return None if minutes is None else 60.0 * minutes

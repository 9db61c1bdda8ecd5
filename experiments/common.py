"""Helpers shared by the experiment commands: run folders, presets and saved configs.

Every command works the same way:

* its settings are one flat dict: the preset's values (``--preset``), replaced by a saved config (``--config FILE``),
  replaced by the options given on the command line (options left out keep ``None`` in argparse and change
  nothing);
* it writes them to ``<run folder>/config.json`` before doing any work, so ``--config <run folder>/config.json``
  re-runs it exactly;
* ``--resume [FOLDER]`` continues the run in FOLDER (default: the newest ``runs/<command>-*``) with the config saved
  there; finished pieces (archives, checkpoints) are reused.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import sys
import time
from pathlib import Path
from typing import Any

CONFIG_NAME = "config.json"


def add_run_arguments(parser: argparse.ArgumentParser, presets: dict[str, dict], default_preset: str) -> None:
    """Add ``--preset``, ``--config``, ``--resume``, ``--out``, ``--seed`` and ``--time-limit``."""
    parser.add_argument("--preset", choices=sorted(presets), default=None,
                        help=f"settings preset (default {default_preset})")
    parser.add_argument("--config", type=Path, default=None, help="re-run from a saved config.json")
    parser.add_argument("--resume", nargs="?", const="latest", default=None, metavar="FOLDER",
                        help="continue the run in FOLDER (default: the newest run of this command)")
    parser.add_argument("--out", type=Path, default=None, help="run folder (default runs/<command>-<timestamp>)")
    parser.add_argument("--seed", type=int, default=None, help="PRNG seed")
    parser.add_argument("--time-limit", type=float, default=None, metavar="MIN",
                        help="stop cleanly after about MIN minutes (after a checkpoint); continue with --resume")


def timestamp() -> str:
    """UTC time as ``YYYYmmdd-HHMMSS``, the suffix of default run folders."""
    return _dt.datetime.now(_dt.timezone.utc).strftime("%Y%m%d-%H%M%S")


def run_folder(name: str, out: str | Path | None = None) -> Path:
    """``out``, or the default run folder ``runs/<name>-<UTC time>``; not created here."""
    return Path(out) if out else Path("runs") / f"{name}-{timestamp()}"


def latest_run(command: str, root: Path = Path("runs")) -> Path:
    runs = sorted(p for p in root.glob(f"{command}-*") if (p / CONFIG_NAME).exists())
    if not runs:
        raise SystemExit(f"--resume: no run of {command!r} with a {CONFIG_NAME} under {root}/")
    return runs[-1]


def load_config(path: str | Path) -> dict:
    path = Path(path)
    if path.is_dir():
        path = path / CONFIG_NAME
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise SystemExit(f"cannot read config {path}: {err}") from err
    if not isinstance(data, dict):
        raise SystemExit(f"config {path} must hold a JSON object")
    return data


def write_config(folder: Path, config: dict) -> Path:
    from jaxterrain.io import atomic_write_text

    return atomic_write_text(Path(folder) / CONFIG_NAME, json.dumps(config, indent=2, sort_keys=True) + "\n")


def save_figure(fig, path: str | Path, dpi: int = 120) -> Path:
    """Write a matplotlib figure as PNG atomically (never a half-written file), then close it."""
    import io

    import matplotlib.pyplot as plt

    from jaxterrain.io import atomic_write_bytes

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    return atomic_write_bytes(path, buf.getvalue())


def setup_run(command: str, args: argparse.Namespace, presets: dict[str, dict], default_preset: str,
              overrides: dict[str, Any]) -> tuple[Path, dict]:
    """Resolve the settings and the run folder; write the config there. Returns ``(folder, config)``.

    ``overrides`` maps config keys to the values given on the command line (``None`` = not given).
    """
    if args.resume is not None:
        folder = latest_run(command) if args.resume == "latest" else Path(args.resume)
        config = load_config(folder)
        given = {k: v for k, v in overrides.items() if v is not None}
        if given:
            print(f"--resume: ignoring {sorted(given)}; the run continues with its saved config", file=sys.stderr)
        print(f"resuming {folder}", flush=True)
        return folder, config
    if args.config is not None:
        config = load_config(args.config)
        if args.preset is not None:
            config = {**presets[args.preset], **config, "preset": args.preset}
    else:
        preset = args.preset or default_preset
        config = {**presets[preset], "preset": preset}
    for key, value in overrides.items():
        if value is not None:
            config[key] = value
    if args.seed is not None:
        config["seed"] = args.seed
    config.setdefault("seed", 0)
    unknown = set(config) - set(presets[default_preset]) - {"preset", "seed", "command"}
    if unknown:
        raise SystemExit(f"unknown config key(s) {sorted(unknown)}; known: {sorted(presets[default_preset])}")
    folder = run_folder(command, args.out)
    folder.mkdir(parents=True, exist_ok=True)
    config["command"] = command
    write_config(folder, config)
    print(f"run folder {folder}", flush=True)
    return folder, config


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


def slope_fitness(heightmaps, key=None):
    """Cheap stand-in fitness for smoke runs, tests and benchmarks: ``1 - mean slope`` in [0, 1].

    ``heightmaps [B, H, W]`` in [0, 1] are scaled to metres with the default ``TerrainScale``; the slope of a pixel is
    ``(|dz/dx| + |dz/dy|) / 2`` (rise over run), clipped to 1. Returns ``[B]`` float32.
    """
    import jax.numpy as jnp

    from jaxterrain.terrain import TerrainScale

    scale = TerrainScale()
    h = jnp.asarray(heightmaps, jnp.float32) * (scale.height / scale.cell_size)
    dx = jnp.mean(jnp.abs(jnp.diff(h, axis=-1)), axis=(-2, -1))
    dy = jnp.mean(jnp.abs(jnp.diff(h, axis=-2)), axis=(-2, -1))
    return 1.0 - jnp.clip((dx + dy) / 2.0, 0.0, 1.0)


def fitness_function(name: str, attempts: int, best: int, size: int, slots: int | None = None):
    """Traceable ``(heightmaps[B, size, size], key) -> [B]``: ``"difficulty"`` (the walker's base policy, pure
    version of ``difficulty.evaluate``; ``slots``: its rollout pool) or ``"slope"`` (cheap, :func:`slope_fitness`)."""
    if name == "slope":
        return slope_fitness
    if name == "difficulty":
        from jaxterrain.archive import difficulty_fitness

        return difficulty_fitness(size, attempts, best, slots=slots)
    raise SystemExit(f"unknown fitness {name!r}; choose difficulty or slope")


def generator_available(name: str, size: int) -> tuple[bool, str]:
    """Whether generator ``name`` can be built and render at ``size`` (e.g. the GAN needs weights)."""
    try:
        import jax

        from jaxterrain import generators

        gen = generators.get(name, size=size)
        gen.render(gen.sample(jax.random.key(0), 1))
        return True, ""
    except Exception as err:  # noqa: BLE001 - any failure means "skip this generator", reported to the user
        msg = str(err).splitlines()[0] if str(err) else ""
        return False, f"{type(err).__name__}: {msg[:100]}{'...' if len(msg) > 100 else ''}"

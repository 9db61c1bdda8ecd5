"""``python -m experiments train-gan``: train the DCGAN terrain generator (paper 3.1.4) on real DEM tiles.

    python -m experiments train-gan --preset smoke                 # seconds on CPU, 64 x 64, checks the pipeline
    python -m experiments train-gan --preset gpu --export-assets   # the shipped weights: 256 x 256 on one H100
    python -m experiments train-gan --data my_tiles/ --steps 20000 # your own GeoTIFF / .npy / .npz DEM tiles
    python -m experiments train-gan --out runs/x --resume          # continue from the latest checkpoint of runs/x

Training: standard non-saturating GAN loss, Adam(2e-4, b1=0.5) for both networks, one discriminator and one
generator update per step, batches of random DEM patches cut, augmented and normalised on the device inside the
jit-compiled step (``jaxterrain.dem.random_patches``); latents from N(0, 1) truncated to [-3, 3] (the genome range).
R1 penalty on real data (``--r1``, lazily every 8 steps; on in the gpu preset: without it the
discriminator wins after ~3000 steps and the samples lose relief). The run folder gets ``run.json`` (arguments), ``log.jsonl``,
``samples/step_<8-digit step>.png`` (a fixed-latent grid, plus ``real.png``), ``checkpoints/`` (params + optimiser states +
step + key, written atomically; the 3 latest kept), ``final/`` (``generator.msgpack`` + ``config.json``, loadable with
``generators.get("gan", weights="<run>/final")``) and ``quality.json`` (see
:func:`jaxterrain.generators.gan_train.quality_check`). The training state, step, checkpoints and quality check are
library code in :mod:`jaxterrain.generators.gan_train`; this module only wires them to the command line.
``--export-assets`` copies ``final/`` into ``jaxterrain/assets/gan/`` with ``PROVENANCE.md`` and a sample grid.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, NamedTuple

PRESETS: dict[str, dict[str, Any]] = {
    # tiny: a few seconds of steps on CPU at 64 x 64
    "smoke": dict(
        size=64, channels=(64, 32, 16, 8), disc_channels=(16, 32, 64), batch_size=8, steps=20,
        sample_every=10, ckpt_every=10, log_every=5, quality_samples=32, r1=0.0,
    ),
    # the shipped weights: 256 x 256, default architecture; about 4 minutes on one H100 (see README / PROVENANCE)
    "gpu": dict(
        size=256, channels=(256, 128, 64, 32, 16, 8), disc_channels=(16, 32, 64, 128, 256, 256), batch_size=64,
        steps=12000, sample_every=2000, ckpt_every=2000, log_every=500, quality_samples=512, r1=1.0,
    ),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--preset", choices=sorted(PRESETS), default="smoke", help="size of the run (default smoke)")
    parser.add_argument("--steps", type=int, help="total training steps (default: the preset's)")
    parser.add_argument("--batch-size", type=int, help="patches per step (default: the preset's)")
    parser.add_argument("--size", type=int, help="heightmap side; must fit the preset's architecture")
    parser.add_argument("--data", help="folder / file of DEM tiles (.tif .tiff .npy .npz); default: matplotlib DEMs")
    parser.add_argument("--out", help="run folder (default runs/train-gan-<timestamp>)")
    parser.add_argument("--resume", action="store_true", help="continue from the latest checkpoint in --out")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--lr", type=float, default=2e-4, help="Adam learning rate of both networks (2e-4)")
    parser.add_argument("--r1", type=float, help="R1 penalty weight on real data, applied lazily every 8 steps "
                        "(0 = off; default: the preset's)")
    parser.add_argument("--sample-every", type=int, help="steps between sample grids")
    parser.add_argument("--ckpt-every", type=int, help="steps between checkpoints")
    parser.add_argument("--log-every", type=int, help="steps between log lines")
    parser.add_argument("--quality-samples", type=int, help="terrains per set in the quality check (0 = skip)")
    parser.add_argument("--quality-only", metavar="WEIGHTS", help="only run the quality check of these weights")
    parser.add_argument("--export-assets", action="store_true", help="copy the result into jaxterrain/assets/gan/")
    parser.add_argument("--no-progress", action="store_true", help="log lines only, no progress bar")


# ----------------------------------------------------------------------------------------------------------------
# Samples and quality
# ----------------------------------------------------------------------------------------------------------------


def save_grid(path: Path, maps, cols: int = 4) -> Path:
    """Save ``[N, H, W]`` maps in [0, 1] as one PNG grid (matplotlib 'terrain' colours, 2 px gaps)."""
    import io

    import numpy as np
    from matplotlib import colormaps
    from PIL import Image

    from jaxterrain.io import atomic_write_bytes

    maps = np.clip(np.asarray(maps, np.float32), 0.0, 1.0)
    n, h, w = maps.shape
    rows = -(-n // cols)
    grid = np.ones((rows * (h + 2) + 2, cols * (w + 2) + 2, 3), np.uint8) * 255
    rgb = (colormaps["terrain"](maps)[..., :3] * 255).astype(np.uint8)
    for i in range(n):
        r, c = divmod(i, cols)
        grid[2 + r * (h + 2): 2 + r * (h + 2) + h, 2 + c * (w + 2): 2 + c * (w + 2) + w] = rgb[i]
    buf = io.BytesIO()
    Image.fromarray(grid).save(buf, format="PNG")
    return atomic_write_bytes(path, buf.getvalue())


# ----------------------------------------------------------------------------------------------------------------
# Provenance and export
# ----------------------------------------------------------------------------------------------------------------


def _git_commit() -> str:
    root = Path(__file__).resolve().parent.parent
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=10)
        commit = head.stdout.strip() if head.returncode == 0 else "none (no commit yet)"
        dirty = subprocess.run(["git", "status", "--porcelain"], cwd=root, capture_output=True, text=True, timeout=10)
        if dirty.stdout.strip():
            commit += " (working tree has uncommitted changes)"
        return commit
    except (OSError, subprocess.SubprocessError):
        return "unknown (git not available)"


def _device() -> str:
    import jax

    d = jax.devices()[0]
    return f"{jax.device_count()} x {getattr(d, 'device_kind', d.platform)} ({d.platform})"


def export_assets(run_dir: Path, asset_dir: Path, provenance: str) -> Path:
    """Copy ``final/`` (weights + config), the last sample grid and quality.json into ``asset_dir``."""
    from jaxterrain.io import atomic_write_bytes, atomic_write_text

    asset_dir.mkdir(parents=True, exist_ok=True)
    for name in ("generator.msgpack", "config.json"):
        atomic_write_bytes(asset_dir / name, (run_dir / "final" / name).read_bytes())
    grids = sorted((run_dir / "samples").glob("step_*.png"))
    if grids:
        atomic_write_bytes(asset_dir / "samples.png", grids[-1].read_bytes())
    if (run_dir / "samples" / "real.png").exists():
        atomic_write_bytes(asset_dir / "real_patches.png", (run_dir / "samples" / "real.png").read_bytes())
    if (run_dir / "quality.json").exists():
        atomic_write_bytes(asset_dir / "quality.json", (run_dir / "quality.json").read_bytes())
    atomic_write_text(asset_dir / "PROVENANCE.md", provenance)
    return asset_dir


def provenance_text(args, config, data_desc, state_step, wall, quality, metrics) -> str:
    import flax
    import jax
    import optax

    from jaxterrain.generators import gan_train
    from jaxterrain.generators.gan import generator_flops

    q = "not run"
    if quality:
        q = "```json\n" + json.dumps({k: quality.get(k) for k in ("mean_w1", "w1", "gan_closer_than_perlin")},
                                     indent=2) + "\n```"
    return f"""# Provenance of the shipped GAN generator weights

- Command: `python -m experiments {' '.join(sys.argv[1:]) if sys.argv[1:] else 'train-gan'}`
  (`{' '.join(sys.argv)}`)
- Preset: {args.preset}; steps: {state_step}; batch size: {args.batch_size}; Adam lr {args.lr}, b1 0.5, b2 0.999;
  loss: non-saturating GAN; R1 weight: {args.r1} (lazy, every {gan_train.R1_EVERY} steps); seed: {args.seed}
- Architecture (`config.json`): {json.dumps(config.to_json())}
  - generator parameters: {gan_train.generator_params(config)} ; FLOPs per sample: {generator_flops(config) / 1e6:.1f} M
- Data: {data_desc}
  - patches: random crops of {list(_scales())} cells (those that fit in the tile), resampled to {config.size} x
    {config.size}, random flips and 90-degree rotations, each patch min-max normalised to [0, 1].
- Latents: N(0, 1) truncated to [-3, 3] (the genome range).
- Commit: {_git_commit()}
- Device: {_device()}; jax {jax.__version__}, flax {flax.__version__}, optax {optax.__version__}
- Date (UTC): {time.strftime('%Y-%m-%d %H:%M:%S', time.gmtime())}; training wall time: {wall:.0f} s
- Last logged metrics: {json.dumps({k: round(float(v), 4) for k, v in (metrics or {}).items()})}
- Quality check (Wasserstein-1 of TRI/TPI/roughness distributions to training patches, in units of the real
  patches' std; lower is closer): {q}
"""


def _scales():
    from jaxterrain import dem

    return dem.DEFAULT_SCALES


# ----------------------------------------------------------------------------------------------------------------
# The command
# ----------------------------------------------------------------------------------------------------------------


def _resolve(args) -> dict:
    preset = dict(PRESETS[args.preset])
    for name in ("steps", "batch_size", "size", "sample_every", "ckpt_every", "log_every", "quality_samples", "r1"):
        if getattr(args, name, None) is not None:
            preset[name] = getattr(args, name)
        setattr(args, name, preset[name])
    for name in ("steps", "batch_size", "sample_every", "ckpt_every", "log_every"):
        if preset[name] < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 1; got {preset[name]}")
    if preset["r1"] < 0:
        raise ValueError(f"--r1 must be >= 0; got {preset['r1']}")
    if preset["quality_samples"] < 0:
        raise ValueError(f"--quality-samples must be >= 0; got {preset['quality_samples']}")
    return preset


class TrainingData(NamedTuple):
    """The DEM tiles a run trains on (``tiles``: ``jaxterrain.dem.DemTiles``), how many, and a one-line description."""

    tiles: Any
    num_tiles: int
    description: str


class TrainOutcome(NamedTuple):
    """The result of :func:`train`: the final state, the wall time of the loop (s) and the last logged metrics."""

    state: Any  # jaxterrain.generators.gan_train.GanTrainState
    wall: float
    last_metrics: dict[str, float] | None


def make_config(preset: dict):
    """The checked ``GanConfig`` of the resolved ``preset`` (see :func:`_resolve`)."""
    from jaxterrain.generators.gan import GanConfig

    return GanConfig(size=preset["size"], channels=tuple(preset["channels"]),
                     disc_channels=tuple(preset["disc_channels"])).check()


def prepare_run_dir(args) -> Path:
    """The run folder (``--out`` or ``runs/train-gan-<UTC time>``), created; ``--resume`` needs ``--out``."""
    from experiments.common import run_folder

    run_dir = run_folder("train-gan", args.out)
    if args.resume and not args.out:
        raise ValueError("--resume needs --out RUN_DIR (the run to continue)")
    run_dir.mkdir(parents=True, exist_ok=True)
    return run_dir


def load_training_data(data: str | None) -> TrainingData:
    """Load the DEM tiles of ``--data`` (default: matplotlib's sample DEMs) and stack them for the device."""
    from jaxterrain import dem

    dems = dem.load_dems(data, min(dem.DEFAULT_SCALES))
    tiles = dem.stack_tiles([z for _, z in dems])
    description = (f"{'matplotlib sample DEMs' if data is None else data}: "
                   + ", ".join(f"{n} ({z.shape[0]} x {z.shape[1]})" for n, z in dems))
    return TrainingData(tiles, len(dems), description)


def run_quality_only(args, run_dir: Path, tiles) -> None:
    """``--quality-only WEIGHTS``: write the :func:`quality_check` of those weights to ``run_dir/quality.json``."""
    import jax

    from jaxterrain.generators import gan_train
    from jaxterrain.generators.gan import load_generator
    from jaxterrain.io import atomic_write_text

    cfg, variables = load_generator(args.quality_only)
    report = gan_train.quality_check(jax.random.PRNGKey(args.seed + 1), cfg, variables, tiles,
                                     max(args.quality_samples, 8))
    atomic_write_text(run_dir / "quality.json", json.dumps(report, indent=2) + "\n")
    print(json.dumps(report["mean_w1"]), "gan_closer_than_perlin:", report["gan_closer_than_perlin"])


def write_run_json(args, run_dir: Path, preset: dict, config, data_desc: str) -> None:
    """Write ``run.json`` (argv, resolved options, config); on ``--resume`` first check the config is the same."""
    from jaxterrain.io import atomic_write_text

    run_json = run_dir / "run.json"
    if args.resume and run_json.exists():
        saved = json.loads(run_json.read_text())
        if saved.get("config") != config.to_json():
            raise ValueError(f"--resume: {run_dir} was trained with config {saved.get('config')}, "
                             f"not {config.to_json()}; use the same --preset/--size")
    atomic_write_text(run_json, json.dumps({"argv": sys.argv, "preset": args.preset, "resolved": {
        k: v for k, v in preset.items() if k not in ("channels", "disc_channels")} | {"lr": args.lr, "r1": args.r1,
        "seed": args.seed, "data": data_desc}, "config": config.to_json()}, indent=2) + "\n")


def init_or_resume(args, run_dir: Path, config) -> gan_train.GanTrainState:
    """A fresh :class:`~jaxterrain.generators.gan_train.GanTrainState` from ``--seed``, or with ``--resume``
    the latest checkpoint in ``run_dir``."""
    import jax

    from jaxterrain.generators import gan_train

    state = gan_train.init_state(jax.random.PRNGKey(args.seed), config, args.lr)
    if args.resume:
        ckpt = gan_train.latest_checkpoint(run_dir)
        if ckpt is None:
            print(f"--resume: no checkpoint in {run_dir}/checkpoints; starting from scratch", flush=True)
        else:
            state = gan_train.restore_checkpoint(ckpt, state)
            print(f"resumed from {ckpt} at step {int(state.step)}", flush=True)
    return state


def _progress_bar(args, start: int):
    """A tqdm bar over the steps still to train, or None (``--no-progress``, nothing to train, or no tqdm)."""
    if args.no_progress or start >= args.steps:
        return None
    try:
        from tqdm import tqdm

        return tqdm(total=args.steps, initial=start, desc="train-gan", mininterval=2.0, file=sys.stdout)
    except ImportError:
        return None


def _log_metrics(say, log_path: Path, step: int, total: int, start: int, t0: float, metrics) -> dict[str, float]:
    """Print and append to ``log.jsonl`` one log line for ``step``; raise on non-finite losses. The host metrics."""
    import numpy as np

    m = {k: float(v) for k, v in metrics.items()}
    rate = (step - start) / max(time.time() - t0, 1e-9)
    line = f"step {step}/{total}  " + "  ".join(f"{k} {v:.4f}" for k, v in m.items()) + f"  {rate:.1f} steps/s"
    say(line)
    with open(log_path, "a") as f:
        f.write(json.dumps({"step": step, "time": time.time() - t0, **m}) + "\n")
    if not all(np.isfinite(list(m.values()))):
        raise FloatingPointError(f"train-gan: non-finite losses at step {step}: {m}")
    return m


def train(args, run_dir: Path, config, state: gan_train.GanTrainState, tiles) -> TrainOutcome:
    """Train from ``state.step`` to ``--steps``: log lines, sample grids and checkpoints at their intervals."""
    import jax

    from jaxterrain.generators import gan_train

    step_fn = gan_train.jitted_step(config, args.batch_size, float(args.lr), float(args.r1),
                                    jax.default_backend() != "cpu")
    sample_fn, real_fn = gan_train.jitted_samples(config)
    if not (run_dir / "samples" / "real.png").exists():
        save_grid(run_dir / "samples" / "real.png", real_fn(jax.random.PRNGKey(7), tiles))

    start = int(state.step)
    bar = _progress_bar(args, start)
    say = bar.write if bar is not None else (lambda s: print(s, flush=True))
    t0, last = time.time(), None
    for step in range(start + 1, args.steps + 1):
        state, metrics = step_fn(state, tiles)
        if bar is not None:
            bar.update(1)
        if step % args.log_every == 0 or step == args.steps:
            last = _log_metrics(say, run_dir / "log.jsonl", step, args.steps, start, t0, metrics)
        if step % args.sample_every == 0 or step == args.steps:
            save_grid(run_dir / "samples" / f"step_{step:08d}.png", sample_fn(state.g_params, state.g_stats))
        if step % args.ckpt_every == 0 or step == args.steps:
            gan_train.save_checkpoint(run_dir, state)
    if bar is not None:
        bar.close()
    wall = time.time() - t0
    if start < args.steps:
        say(f"trained {args.steps - start} steps in {wall:.1f} s")
    return TrainOutcome(state, wall, last)


def run_quality(args, run_dir: Path, config, variables, tiles) -> dict | None:
    """The :func:`quality_check` of the trained generator, written to ``quality.json`` (None if skipped)."""
    import jax

    from jaxterrain.generators import gan_train

    from jaxterrain.io import atomic_write_text

    if args.quality_samples <= 0:
        return None
    try:
        quality = gan_train.quality_check(jax.random.PRNGKey(args.seed + 1), config, variables, tiles,
                                          args.quality_samples)
    except ImportError as err:
        print(f"quality check skipped: {err}", flush=True)
        return None
    atomic_write_text(run_dir / "quality.json", json.dumps(quality, indent=2) + "\n")
    print(f"quality (mean W1 to training patches, lower = closer): {json.dumps(quality['mean_w1'])}  "
          f"gan_closer_than_perlin: {quality['gan_closer_than_perlin']}", flush=True)
    return quality


def main(args: argparse.Namespace) -> int:
    """Resolve the options, load the data, train (or resume), save ``final/``, check quality, optionally export."""
    from jaxterrain.generators.gan import ASSET_DIR, save_generator

    preset = _resolve(args)
    config = make_config(preset)
    run_dir = prepare_run_dir(args)
    data = load_training_data(args.data)
    print(f"train-gan: {run_dir}  device {_device()}  data {data.num_tiles} tiles", flush=True)
    if args.quality_only:
        run_quality_only(args, run_dir, data.tiles)
        return 0

    write_run_json(args, run_dir, preset, config, data.description)
    state = init_or_resume(args, run_dir, config)
    outcome = train(args, run_dir, config, state, data.tiles)
    variables = {"params": outcome.state.g_params, "batch_stats": outcome.state.g_stats}
    save_generator(run_dir / "final", config, variables)
    quality = run_quality(args, run_dir, config, variables, data.tiles)
    if args.export_assets:
        text = provenance_text(args, config, data.description, int(outcome.state.step), outcome.wall, quality,
                               outcome.last_metrics)
        out = export_assets(run_dir, ASSET_DIR, text)
        print(f"exported the generator to {out}", flush=True)
    print(f"done: {run_dir / 'final'}", flush=True)
    return 0

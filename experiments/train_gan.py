"""``python -m experiments train-gan``: train the DCGAN terrain generator (paper 3.1.4) on real DEM tiles.

    python -m experiments train-gan --preset smoke                 # seconds on CPU, 64 x 64, checks the pipeline
    python -m experiments train-gan --preset gpu --export-assets   # the shipped weights: 256 x 256 on one H100
    python -m experiments train-gan --data my_tiles/ --steps 20000 # your own GeoTIFF / .npy / .npz DEM tiles
    python -m experiments train-gan --resume runs/x                # continue run x from its checkpoint

Training (:mod:`jaxterrain.generators.gan_train`, library code; this module only wires it to the command line):
the non-saturating GAN loss, Adam(2e-4, b1=0.5) for both networks, one discriminator and one generator update per
step on random DEM patches cut, augmented and normalised on the device (``jaxterrain.terrain.dem.random_patches``);
latents from N(0, 1) truncated to [-3, 3] (the genome range). R1 penalty on real data (``--r1``, lazily every 8
steps; on in the gpu preset: without it the discriminator wins after ~3000 steps and the samples lose relief).

The loop is ``jaxterrain.runtime.driver.run_chunks``, as in ``evolve``: every ``--ckpt-every`` steps it writes
``checkpoint.npz`` (params, batch statistics, optimiser states, step and key; the previous one kept as
``checkpoint.prev.npz``), ``metrics.csv`` and TensorBoard events (``tb/``); ``--time-limit MIN`` stops after a
checkpoint (exit code 3, as ``evolve``) and ``--resume FOLDER`` continues the run bit-identically with the
settings saved in its ``config.json`` (``experiments.common.setup_resumable_run``: ``--steps``, ``--ckpt-every``,
``--sample-every``, ``--log-every`` and ``--quality-samples`` given with it replace the saved ones, e.g. to train
longer; the other options are the run's). The run folder also gets ``config.json`` (the settings, as in every
command: ``--config RUN/config.json`` re-runs them), ``log.jsonl`` (every ``--log-every`` steps),
``samples/step_<8-digit step>.png`` (a fixed-latent grid, plus ``real.png``), ``final/`` (``generator.msgpack`` +
``config.json``, loadable with ``generators.get("gan", weights="<run>/final")``) and ``quality.json``
(:func:`jaxterrain.generators.gan_train.quality_check`). ``--export-assets`` copies ``final/`` into
``jaxterrain/assets/gan/`` with ``PROVENANCE.md`` and a sample grid.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any, NamedTuple

from experiments import common

PRESETS: dict[str, dict[str, Any]] = common.with_preset_names({
    # tiny: a few seconds of steps on CPU at 64 x 64
    "smoke": dict(
        size=64, channels=(64, 32, 16, 8), disc_channels=(16, 32, 64), batch_size=8, steps=20,
        sample_every=10, ckpt_every=10, log_every=5, quality_samples=32, r1=0.0, lr=2e-4, data=None,
    ),
    # the shipped weights: 256 x 256, default architecture; about 4 minutes on one H100 (see README / PROVENANCE)
    "gpu": dict(
        size=256, channels=(256, 128, 64, 32, 16, 8), disc_channels=(16, 32, 64, 128, 256, 256), batch_size=64,
        steps=12000, sample_every=2000, ckpt_every=2000, log_every=500, quality_samples=512, r1=1.0, lr=2e-4,
        data=None,
    ),
}, {"gpu-short": ("gpu", {"steps": 1200, "sample_every": 200, "ckpt_every": 200, "log_every": 50}), "paper": "gpu"})


# What ``--resume`` may change (how long the run lasts and how often it logs); the rest is the run's.
EXTENDABLE = ("steps", "sample_every", "ckpt_every", "log_every", "quality_samples")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "smoke")
    parser.add_argument("--steps", type=int, default=None, help="total training steps (default: the preset's)")
    parser.add_argument("--batch-size", type=int, default=None, help="patches per step (default: the preset's)")
    parser.add_argument("--size", type=int, default=None, help="heightmap side; must fit the preset's architecture")
    parser.add_argument("--data", default=None,
                        help="folder / file of DEM tiles (.tif .tiff .npy .npz); default: matplotlib DEMs")
    parser.add_argument("--learning-rate", dest="lr", type=float, default=None, help="Adam learning rate of both networks (default 2e-4)")
    common.add_deprecated_alias(parser, "--lr", "--learning-rate", "lr", type=float)
    parser.add_argument("--r1", type=float, default=None, help="R1 penalty weight on real data, applied lazily "
                        "every 8 steps (0 = off; default: the preset's)")
    parser.add_argument("--sample-every", type=int, default=None, help="steps between sample grids")
    parser.add_argument("--checkpoint-every", dest="ckpt_every", type=int, default=None, help="steps between checkpoints")
    common.add_deprecated_alias(parser, "--ckpt-every", "--checkpoint-every", "ckpt_every", type=int)
    parser.add_argument("--log-every", type=int, default=None, help="steps between log lines")
    parser.add_argument("--quality-samples", type=int, default=None,
                        help="terrains per set in the quality check (0 = skip)")
    parser.add_argument("--quality-only", metavar="WEIGHTS", help="only run the quality check of these weights")
    parser.add_argument("--export-assets", action="store_true", help="copy the result into jaxterrain/assets/gan/")
    common.add_progress_argument(parser)


def overrides(args) -> dict:
    """The settings given on the command line (None: not given)."""
    return {name: getattr(args, name) for name in ("steps", "batch_size", "size", "data", "lr", "r1", "sample_every",
                                                    "ckpt_every", "log_every", "quality_samples")}


# ----------------------------------------------------------------------------------------------------------------
# Provenance and export
# ----------------------------------------------------------------------------------------------------------------


def export_assets(run_dir: Path, asset_dir: Path, provenance: str) -> Path:
    """Copy ``final/`` (weights + config), the last sample grid and quality.json into ``asset_dir``."""
    from jaxterrain.runtime.io import atomic_write_bytes, atomic_write_text

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


def provenance_text(cfg: dict, config, data_desc, state_step, wall, quality, metrics) -> str:
    import flax
    import jax
    import optax

    from jaxterrain.runtime import provenance
    from jaxterrain.generators import gan_train
    from jaxterrain.generators.gan import generator_flops

    q = "not run"
    if quality:
        q = "```json\n" + json.dumps({k: quality.get(k) for k in ("mean_w1", "w1", "gan_closer_than_perlin")},
                                     indent=2) + "\n```"
    return f"""# Provenance of the shipped GAN generator weights

- Command: `python -m experiments {' '.join(sys.argv[1:]) if sys.argv[1:] else 'train-gan'}`
  (`{' '.join(sys.argv)}`)
- Preset: {cfg['preset']}; steps: {state_step}; batch size: {cfg['batch_size']}; Adam lr {cfg['lr']}, b1 0.5, b2 0.999;
  loss: non-saturating GAN; R1 weight: {cfg['r1']} (lazy, every {gan_train.R1_EVERY} steps); seed: {cfg['seed']}
- Architecture (`config.json`): {json.dumps(config.to_json())}
  - generator parameters: {gan_train.generator_params(config)} ; FLOPs per sample: {generator_flops(config) / 1e6:.1f} M
- Data: {data_desc}
  - patches: random crops of {list(_scales())} cells (those that fit in the tile), resampled to {config.size} x
    {config.size}, random flips and 90-degree rotations, each patch min-max normalised to [0, 1].
- Latents: N(0, 1) truncated to [-3, 3] (the genome range).
- Commit: {provenance.git_commit()}
- Device: {provenance.device()}; jax {jax.__version__}, flax {flax.__version__}, optax {optax.__version__}
- Date (UTC): {time.strftime('%Y-%m-%d %H:%M:%S', time.gmtime())}; training wall time: {wall:.0f} s
- Last logged metrics: {json.dumps({k: round(float(v), 4) for k, v in (metrics or {}).items()})}
- Quality check (Wasserstein-1 of TRI/TPI/roughness distributions to training patches, in units of the real
  patches' std; lower is closer): {q}
"""


def _scales():
    from jaxterrain.terrain import dem

    return dem.DEFAULT_SCALES


# ----------------------------------------------------------------------------------------------------------------
# The command
# ----------------------------------------------------------------------------------------------------------------


class TrainingData(NamedTuple):
    """The DEM tiles a run trains on (``tiles``: ``jaxterrain.terrain.dem.DemTiles``), how many, and a one-line description."""

    tiles: Any
    num_tiles: int
    description: str


def gan_run(cfg: dict):
    """The library's ``GanRun`` of the run's settings ``cfg``."""
    from jaxterrain.generators.gan_train import GanRun

    return GanRun(make_config(cfg), steps=int(cfg["steps"]), batch_size=int(cfg["batch_size"]), lr=float(cfg["lr"]),
                  r1=float(cfg["r1"]), seed=int(cfg["seed"]), sample_every=int(cfg["sample_every"]),
                  ckpt_every=int(cfg["ckpt_every"]), log_every=int(cfg["log_every"]),
                  quality_samples=int(cfg["quality_samples"]))


def make_config(cfg: dict):
    """The checked ``GanConfig`` of the run's settings ``cfg`` (size, channels, disc_channels)."""
    from jaxterrain.generators.gan import GanConfig

    return GanConfig(size=int(cfg["size"]), channels=tuple(cfg["channels"]),
                     disc_channels=tuple(cfg["disc_channels"])).check()


def check_config(cfg: dict) -> None:
    """Before a run folder: the size fits the architecture (``GanConfig.check``) and ``--data`` reads as DEM tiles
    (:func:`read_dems`), each as a one-line error."""
    try:
        make_config(cfg)
    except ValueError as err:
        raise common.UsageError(f"--size / the preset's architecture: {str(err).splitlines()[0]}") from None
    read_dems(cfg.get("data"))


_DEMS: dict = {}  # the tiles read by check_config, reused by load_training_data (read once)


def read_dems(data: str | None) -> list:
    """``dem.load_dems`` of ``--data`` (None: matplotlib's sample DEMs), read once per run; a file or folder that
    holds no readable DEM tile (an unknown extension, a damaged or too small tile) is a :class:`UsageError` naming
    ``--data`` and the file."""
    from jaxterrain.terrain import dem

    if data not in _DEMS:
        try:
            _DEMS[data] = dem.load_dems(data, min(dem.DEFAULT_SCALES))
        except (OSError, ValueError) as err:
            raise common.UsageError(f"--data {data}: {str(err).splitlines()[0]}") from None
    return _DEMS[data]


def load_training_data(data: str | None) -> TrainingData:
    """Load the DEM tiles of ``--data`` (default: matplotlib's sample DEMs) and stack them for the device."""
    from jaxterrain.terrain import dem

    dems = read_dems(data)
    tiles = dem.stack_tiles([z for _, z in dems])
    description = (f"{'matplotlib sample DEMs' if data is None else data}: "
                   + ", ".join(f"{n} ({z.shape[0]} x {z.shape[1]})" for n, z in dems))
    return TrainingData(tiles, len(dems), description)


def run_quality_only(weights: str, cfg: dict, run_dir: Path, tiles) -> None:
    """``--quality-only WEIGHTS``: write the :func:`quality_check` of those weights to ``run_dir/quality.json``."""
    import jax

    from jaxterrain.generators import gan_train
    from jaxterrain.generators.gan import load_generator
    from jaxterrain.runtime.io import atomic_write_text

    gan_cfg, variables = load_generator(weights)
    report = gan_train.quality_check(jax.random.PRNGKey(int(cfg["seed"]) + 1), gan_cfg, variables, tiles,
                                     max(int(cfg["quality_samples"]), 8))
    atomic_write_text(run_dir / "quality.json", json.dumps(report, indent=2) + "\n")
    print(json.dumps(report["mean_w1"]), "gan_closer_than_perlin:", report["gan_closer_than_perlin"])


def check_quality_only(args: argparse.Namespace) -> None:
    """``--quality-only WEIGHTS`` checks those weights and trains nothing: the training's flags (the weights
    record their own architecture, so ``--size`` too) would be accepted and ignored;
    :class:`~experiments.common.UsageError`."""
    if args.quality_only is not None:
        common.refuse_given({"--steps": args.steps, "--batch-size": args.batch_size, "--size": args.size,
                             "--learning-rate": args.lr, "--r1": args.r1, "--sample-every": args.sample_every,
                             "--checkpoint-every": args.ckpt_every, "--log-every": args.log_every,
                             "--time-limit": args.time_limit, "--export-assets": args.export_assets or None},
                            "--quality-only checks the given weights and trains nothing: drop one of them")


def main(args: argparse.Namespace) -> int:
    """Resolve the settings and the run folder, load the data, train (or resume) with
    ``jaxterrain.generators.gan_train.train_gan``, optionally export."""
    from jaxterrain.runtime import provenance
    from jaxterrain.generators.gan import ASSET_DIR
    from jaxterrain.generators.gan_train import train_gan

    check_quality_only(args)
    run_dir, cfg = common.setup_resumable_run("train-gan", args, PRESETS, "smoke", overrides(args), EXTENDABLE,
                                              check=check_config)
    config = make_config(cfg)
    data = load_training_data(cfg.get("data"))
    print(f"train-gan: {run_dir}  device {provenance.device()}  data {data.num_tiles} tiles", flush=True)
    if args.quality_only:
        run_quality_only(args.quality_only, cfg, run_dir, data.tiles)
        return 0
    result = train_gan(gan_run(cfg), data.tiles, run_dir, resume=args.resume is not None,
                       time_limit_s=args.time_limit * 60.0 if args.time_limit else None,
                       progress=common.progress_mode(args), say=common.say)
    if result.done < int(cfg["steps"]):
        print(f"time limit reached at step {result.done} of {cfg['steps']}; continue with: "
              f"python -m experiments train-gan --resume {run_dir}", flush=True)
        return 3  # as evolve: stopped by the time limit, resumable
    if args.export_assets:
        text = provenance_text(cfg, config, data.description, int(result.state.step), result.wall, result.quality,
                               result.last_metrics)
        out = export_assets(run_dir, ASSET_DIR, text)
        print(f"exported the generator to {out}", flush=True)
    print(f"done: {run_dir / 'final'}", flush=True)
    return 0

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
``generators.get("gan", weights="<run>/final")``) and ``quality.json`` (see :func:`quality_check`).
``--export-assets`` copies ``final/`` into ``jaxterrain/assets/gan/`` with ``PROVENANCE.md`` and a sample grid.
"""

from __future__ import annotations

import argparse
import functools
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
# Training state and step (pure functions; the command below only wires them up)
# ----------------------------------------------------------------------------------------------------------------


R1_EVERY = 8  # lazy R1 regularisation interval


class TrainState(NamedTuple):
    """Everything a checkpoint holds. ``key`` is a raw uint32[2] key; ``step`` an int32 scalar."""

    step: Any
    key: Any
    g_params: Any
    g_stats: Any
    d_params: Any
    g_opt: Any
    d_opt: Any


def make_optimizer(lr: float = 2e-4):
    import optax

    return optax.adam(lr, b1=0.5, b2=0.999)


def init_state(key, config, lr: float = 2e-4) -> TrainState:
    """A fresh :class:`TrainState` for the ``GanConfig`` ``config`` (``key``: a raw uint32[2] PRNG key)."""
    import jax.numpy as jnp
    import numpy as np

    from jaxterrain.generators.gan import init_variables

    gv, dv = init_variables(key, config)
    # the run's raw uint32[2] key, derived on the host (no compilation)
    bits = np.random.default_rng(np.asarray(key).astype(np.uint64).tolist() + [1]).integers(0, 2**32, 2, np.uint32)
    opt = make_optimizer(lr)
    return TrainState(
        jnp.zeros((), jnp.int32), jnp.asarray(bits), gv["params"], gv["batch_stats"], dv["params"],
        opt.init(gv["params"]), opt.init(dv["params"]),
    )


@functools.lru_cache(maxsize=8)
def _jitted_step(config, batch_size: int, lr: float, r1: float, donate: bool):
    """One jit-compiled train step per setting, reused across runs in one process (tests, resume)."""
    import jax

    return jax.jit(make_train_step(config, batch_size, lr, r1), donate_argnums=(0,) if donate else ())


@functools.lru_cache(maxsize=8)
def _jitted_samples(config, n: int = 16):
    """``(params, batch_stats) -> [n, size, size]`` for a fixed set of latents, and the real-patch grid function."""
    import jax

    from jaxterrain import dem
    from jaxterrain.generators.gan import make_modules, sample_latents

    gen, _ = make_modules(config)
    z = sample_latents(jax.random.PRNGKey(12345), n, config.latent)
    fake = jax.jit(lambda p, s: gen.apply({"params": p, "batch_stats": s}, z, train=False))
    real = jax.jit(lambda k, tiles: dem.random_patches(k, tiles, n, config.size))
    return fake, real


def make_train_step(config, batch_size: int, lr: float = 2e-4, r1: float = 0.0, scales=None):
    """``train_step(state, tiles) -> (state, metrics)``: one discriminator and one generator Adam update.

    Pure (jit it); the real batch ``[batch_size, size, size]`` is cut from ``tiles`` inside. Metrics: ``d_loss``,
    ``g_loss``, ``d_real`` / ``d_fake`` (mean discriminator probabilities), ``r1``.
    """
    import jax
    import jax.numpy as jnp
    import optax

    from jaxterrain import dem
    from jaxterrain.generators.gan import make_modules, sample_latents

    gen, disc = make_modules(config)
    opt = make_optimizer(lr)
    scales = tuple(scales or dem.DEFAULT_SCALES)

    def train_step(state: TrainState, tiles: dem.DemTiles):
        key, data_key, z_key, z2_key = jax.random.split(state.key, 4)
        real = dem.random_patches(data_key, tiles, batch_size, config.size, scales)
        z = sample_latents(z_key, batch_size, config.latent)
        fake, _ = gen.apply(
            {"params": state.g_params, "batch_stats": state.g_stats}, z, train=True, mutable=["batch_stats"]
        )
        fake = jax.lax.stop_gradient(fake)

        def d_loss_fn(dp):
            d = lambda x: disc.apply({"params": dp}, x)  # noqa: E731
            lr_, lf = d(real), d(fake)
            loss = jax.nn.softplus(-lr_).mean() + jax.nn.softplus(lf).mean()
            penalty = jnp.zeros(())
            if r1 > 0:  # lazy R1 (StyleGAN2): every R1_EVERY steps, weighted by R1_EVERY

                def r1_penalty():
                    g = jax.grad(lambda x: d(x).sum())(real)
                    return jnp.mean(jnp.sum(g**2, axis=(1, 2)))

                penalty = jax.lax.cond(state.step % R1_EVERY == 0, r1_penalty, lambda: jnp.zeros(()))
            total = loss + 0.5 * r1 * R1_EVERY * penalty
            return total, (loss, jax.nn.sigmoid(lr_).mean(), jax.nn.sigmoid(lf).mean(), penalty)

        (_, (d_loss, d_real, d_fake, penalty)), d_grads = jax.value_and_grad(d_loss_fn, has_aux=True)(state.d_params)
        d_updates, d_opt = opt.update(d_grads, state.d_opt, state.d_params)
        d_params = optax.apply_updates(state.d_params, d_updates)

        z2 = sample_latents(z2_key, batch_size, config.latent)

        def g_loss_fn(gp):
            out, new = gen.apply(
                {"params": gp, "batch_stats": state.g_stats}, z2, train=True, mutable=["batch_stats"]
            )
            lf = disc.apply({"params": d_params}, out)
            return jax.nn.softplus(-lf).mean(), new["batch_stats"]

        (g_loss, g_stats), g_grads = jax.value_and_grad(g_loss_fn, has_aux=True)(state.g_params)
        g_updates, g_opt = opt.update(g_grads, state.g_opt, state.g_params)
        g_params = optax.apply_updates(state.g_params, g_updates)
        new_state = TrainState(
            state.step + 1, key, g_params, g_stats, d_params, g_opt, d_opt
        )
        metrics = dict(d_loss=d_loss, g_loss=g_loss, d_real=d_real, d_fake=d_fake, r1=penalty)
        return new_state, metrics

    return train_step


# ----------------------------------------------------------------------------------------------------------------
# Checkpoints
# ----------------------------------------------------------------------------------------------------------------


def save_checkpoint(run_dir: Path, state: TrainState, keep: int = 3) -> Path:
    """Write ``checkpoints/ckpt_<8-digit step>.msgpack`` atomically; keep the ``keep`` latest."""
    import jax
    import numpy as np
    from flax import serialization

    from jaxterrain.io import atomic_write_bytes

    host = jax.tree_util.tree_map(np.asarray, state)
    step = int(host.step)
    path = atomic_write_bytes(run_dir / "checkpoints" / f"ckpt_{step:08d}.msgpack", serialization.to_bytes(host))
    for old in sorted((run_dir / "checkpoints").glob("ckpt_*.msgpack"))[:-keep]:
        old.unlink()
    return path


def latest_checkpoint(run_dir: Path) -> Path | None:
    ckpts = sorted((Path(run_dir) / "checkpoints").glob("ckpt_*.msgpack"))
    return ckpts[-1] if ckpts else None


def restore_checkpoint(path: Path, template: TrainState) -> TrainState:
    """The :class:`TrainState` stored at ``path`` (``template`` gives the structure, e.g. :func:`init_state`)."""
    import jax.numpy as jnp
    import jax
    from flax import serialization

    restored = serialization.from_bytes(template, Path(path).read_bytes())
    return jax.tree_util.tree_map(jnp.asarray, restored)


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


def wasserstein1(a, b):
    """Per-column Wasserstein-1 distance between the empirical distributions of ``a[N, D]`` and ``b[M, D]``. [D]."""
    import numpy as np

    a, b = np.sort(np.asarray(a, np.float64), 0), np.sort(np.asarray(b, np.float64), 0)
    q = np.linspace(0.0, 1.0, 1001)[1:-1]
    qa, qb = np.quantile(a, q, axis=0), np.quantile(b, q, axis=0)
    return np.mean(np.abs(qa - qb), axis=0)


def _render_batches(fn, inputs, chunk: int = 128):
    import numpy as np

    return np.concatenate([np.asarray(fn(inputs[i: i + chunk])) for i in range(0, len(inputs), chunk)])


def quality_check(key, config, variables, tiles, n: int = 512, names=("tri", "tpi", "roughness"), descriptors=None):
    """Do GAN samples resemble the training patches more than Perlin terrains do?

    Draws ``n`` GAN terrains (truncated-normal latents), ``2 n`` training patches (``real`` and an independent
    ``real_b``) and ``n`` Perlin terrains (uniform genomes), all ``[n, size, size]`` in [0, 1]; computes
    ``descriptors`` (default ``jaxterrain.features.descriptors``, window 30, stride 2) and, per feature, the
    Wasserstein-1 distance to ``real`` divided by the standard deviation of ``real`` (so features are comparable).
    ``real_b`` gives the sampling-noise floor. Returns a JSON-able dict with ``w1`` per set and feature, their
    means, and ``gan_closer_than_perlin``.
    """
    import jax
    import numpy as np

    from jaxterrain import dem
    from jaxterrain.generators.gan import make_modules, sample_latents

    if descriptors is None:
        from jaxterrain.features import descriptors
    gen, _ = make_modules(config)
    k_z, k_real, k_real_b, k_perlin = jax.random.split(key, 4)
    del key
    g_fn = jax.jit(lambda z: gen.apply(variables, z, train=False))
    sets = {"gan": _render_batches(g_fn, sample_latents(k_z, n, config.latent))}
    patch_fn = jax.jit(lambda k: dem.random_patches(k, tiles, min(n, 128), config.size))
    for name, k in (("real", k_real), ("real_b", k_real_b)):
        ks = jax.random.split(k, -(-n // min(n, 128)))
        sets[name] = np.concatenate([np.asarray(patch_fn(kk)) for kk in ks])[:n]
    perlin_error = None
    try:
        from jaxterrain import generators

        perlin = generators.get("perlin", size=config.size)
        genomes = perlin.sample(k_perlin, n)
        sets["perlin"] = _render_batches(perlin.render, genomes)
    except Exception as err:  # noqa: BLE001 - the check still reports the GAN part
        perlin_error = f"{type(err).__name__}: {err}"
    feats = {}
    for name, maps in sets.items():
        feats[name] = _render_batches(lambda m: descriptors(m, names=tuple(names), window=30, stride=2), maps, 64)
    scale = np.std(feats["real"], axis=0) + 1e-12
    report: dict[str, Any] = {"n": int(n), "size": int(config.size), "features": list(names), "window": 30,
                              "stride": 2, "distance": "Wasserstein-1 per feature / std of real patches' feature",
                              "feature_mean": {}, "feature_std": {}, "w1": {}, "mean_w1": {}}
    for name, f in feats.items():
        report["feature_mean"][name] = [float(x) for x in np.mean(f, 0)]
        report["feature_std"][name] = [float(x) for x in np.std(f, 0)]
        if name != "real":
            w = wasserstein1(f, feats["real"]) / scale
            report["w1"][name] = {feat: float(x) for feat, x in zip(names, w)}
            report["mean_w1"][name] = float(np.mean(w))
    if "perlin" in report["mean_w1"]:
        report["gan_closer_than_perlin"] = bool(report["mean_w1"]["gan"] < report["mean_w1"]["perlin"])
    else:
        report["gan_closer_than_perlin"] = None
        report["perlin_error"] = perlin_error
    return report


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

    from jaxterrain.generators.gan import generator_flops

    q = "not run"
    if quality:
        q = "```json\n" + json.dumps({k: quality.get(k) for k in ("mean_w1", "w1", "gan_closer_than_perlin")},
                                     indent=2) + "\n```"
    return f"""# Provenance of the shipped GAN generator weights

- Command: `python -m experiments {' '.join(sys.argv[1:]) if sys.argv[1:] else 'train-gan'}`
  (`{' '.join(sys.argv)}`)
- Preset: {args.preset}; steps: {state_step}; batch size: {args.batch_size}; Adam lr {args.lr}, b1 0.5, b2 0.999;
  loss: non-saturating GAN; R1 weight: {args.r1} (lazy, every {R1_EVERY} steps); seed: {args.seed}
- Architecture (`config.json`): {json.dumps(config.to_json())}
  - generator parameters: {state_params(config)} ; FLOPs per sample: {generator_flops(config) / 1e6:.1f} M
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


def state_params(config) -> int:
    import jax
    import jax.numpy as jnp

    from jaxterrain.generators.gan import count_params, make_modules

    gen, _ = make_modules(config)
    shapes = jax.eval_shape(lambda: gen.init(jax.random.PRNGKey(0), jnp.zeros((1, config.latent)), train=False))
    return count_params(jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape), shapes["params"]))


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

    state: TrainState
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

    from jaxterrain.generators.gan import load_generator
    from jaxterrain.io import atomic_write_text

    cfg, variables = load_generator(args.quality_only)
    report = quality_check(jax.random.PRNGKey(args.seed + 1), cfg, variables, tiles, max(args.quality_samples, 8))
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


def init_or_resume(args, run_dir: Path, config) -> TrainState:
    """A fresh :class:`TrainState` from ``--seed``, or with ``--resume`` the latest checkpoint in ``run_dir``."""
    import jax

    state = init_state(jax.random.PRNGKey(args.seed), config, args.lr)
    if args.resume:
        ckpt = latest_checkpoint(run_dir)
        if ckpt is None:
            print(f"--resume: no checkpoint in {run_dir}/checkpoints; starting from scratch", flush=True)
        else:
            state = restore_checkpoint(ckpt, state)
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


def train(args, run_dir: Path, config, state: TrainState, tiles) -> TrainOutcome:
    """Train from ``state.step`` to ``--steps``: log lines, sample grids and checkpoints at their intervals."""
    import jax

    step_fn = _jitted_step(config, args.batch_size, float(args.lr), float(args.r1), jax.default_backend() != "cpu")
    sample_fn, real_fn = _jitted_samples(config)
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
            save_checkpoint(run_dir, state)
    if bar is not None:
        bar.close()
    wall = time.time() - t0
    if start < args.steps:
        say(f"trained {args.steps - start} steps in {wall:.1f} s")
    return TrainOutcome(state, wall, last)


def run_quality(args, run_dir: Path, config, variables, tiles) -> dict | None:
    """The :func:`quality_check` of the trained generator, written to ``quality.json`` (None if skipped)."""
    import jax

    from jaxterrain.io import atomic_write_text

    if args.quality_samples <= 0:
        return None
    try:
        quality = quality_check(jax.random.PRNGKey(args.seed + 1), config, variables, tiles, args.quality_samples)
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

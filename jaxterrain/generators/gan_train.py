"""Training the DCGAN of :mod:`jaxterrain.generators.gan`: its state, the R1-regularised step and the
quality check. ``python -m experiments train-gan`` is the command around these functions.

    state = init_state(jax.random.PRNGKey(0), config)              # GanTrainState (a pytree)
    step = jitted_step(config, batch_size=64, lr=2e-4, r1=1.0)     # (state, tiles) -> (state, metrics)
    state, metrics = step(state, tiles)                            # tiles: jaxterrain.terrain.dem.DemTiles
    report = quality_check(key, config, variables, tiles)          # W1 of TRI / TPI / roughness to real patches
    result = train_gan(GanRun(config, steps=20), tiles, "runs/gan")  # the whole run, files and all: GanResult

Training: the non-saturating GAN loss, Adam(lr, b1=0.5, b2=0.999) for both networks, one discriminator and one
generator update per step, batches of random DEM patches cut, augmented and normalised on the device inside the
step (``jaxterrain.terrain.dem.random_patches``), latents from N(0, 1) truncated to [-3, 3] (the genome range), and an
optional R1 penalty on real data applied lazily every :data:`R1_EVERY` steps (StyleGAN2). The state is a plain
pytree: :func:`train_gan` runs the loop through ``jaxterrain.runtime.driver`` (checkpoints, ``metrics.csv``, a time
limit, resume), writes the sample grids, ``log.jsonl``, ``final/`` and ``quality.json`` into its folder, and returns
a :class:`GanResult`; ``python -m experiments train-gan`` is flags and files around it.
"""

from __future__ import annotations

import functools
import io
import json
import time
from pathlib import Path
from typing import Any, Callable, NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxterrain import features, generators
from jaxterrain.generators.gan import (GanConfig, count_params, init_variables, make_modules, sample_latents,
                                       save_generator)
from jaxterrain.runtime import driver, estimates
from jaxterrain.runtime.io import atomic_write_bytes, atomic_write_text
from jaxterrain.terrain import dem

__all__ = ["R1_EVERY", "GanTrainState", "gan_optimizer", "init_state", "make_train_step", "jitted_step",
           "jitted_samples", "wasserstein1", "quality_check", "generator_params", "GanRun", "GanResult", "train_gan",
           "save_grid"]

R1_EVERY = 8  # lazy R1 regularisation interval


class GanTrainState(NamedTuple):
    """Everything a GAN checkpoint holds.

    step: [] int32 steps done. key: [2] uint32 raw PRNG key of the run. g_params / g_stats: the generator's flax
    ``params`` and ``batch_stats``. d_params: the discriminator's ``params``. g_opt / d_opt: their Adam states.
    """

    step: Any
    key: Any
    g_params: Any
    g_stats: Any
    d_params: Any
    g_opt: Any
    d_opt: Any


def gan_optimizer(lr: float = 2e-4) -> optax.GradientTransformation:
    """Adam(``lr``, b1=0.5, b2=0.999), the DCGAN setting, for both networks."""
    return optax.adam(lr, b1=0.5, b2=0.999)


def init_state(key: jax.Array, config: GanConfig, lr: float = 2e-4) -> GanTrainState:
    """A fresh :class:`GanTrainState` for ``config`` (``key``: a raw uint32[2] PRNG key); no XLA compilation."""
    gv, dv = init_variables(key, config)
    # the run's raw uint32[2] key, derived on the host (no compilation)
    bits = np.random.default_rng(np.asarray(key).astype(np.uint64).tolist() + [1]).integers(0, 2**32, 2, np.uint32)
    opt = gan_optimizer(lr)
    return GanTrainState(
        jnp.zeros((), jnp.int32), jnp.asarray(bits), gv["params"], gv["batch_stats"], dv["params"],
        opt.init(gv["params"]), opt.init(dv["params"]),
    )


def _d_loss_fn(disc, real: jax.Array, fake: jax.Array, step: jax.Array, r1: float):
    """``d_params -> (loss + R1 term, (loss, D(real), D(fake), penalty))`` on ``[B, S, S]`` real / fake maps."""

    def d_loss_fn(dp):
        d = lambda x: disc.apply({"params": dp}, x)  # noqa: E731
        lr_, lf = d(real), d(fake)
        loss = jax.nn.softplus(-lr_).mean() + jax.nn.softplus(lf).mean()
        penalty = jnp.zeros(())
        if r1 > 0:  # lazy R1 (StyleGAN2): every R1_EVERY steps, weighted by R1_EVERY
            def r1_penalty():
                g = jax.grad(lambda x: d(x).sum())(real)
                return jnp.mean(jnp.sum(g**2, axis=(1, 2)))

            penalty = jax.lax.cond(step % R1_EVERY == 0, r1_penalty, lambda: jnp.zeros(()))
        total = loss + 0.5 * r1 * R1_EVERY * penalty
        return total, (loss, jax.nn.sigmoid(lr_).mean(), jax.nn.sigmoid(lf).mean(), penalty)

    return d_loss_fn


def make_train_step(config: GanConfig, batch_size: int, lr: float = 2e-4, r1: float = 0.0,
                    scales=None) -> Callable[[GanTrainState, dem.DemTiles], tuple[GanTrainState, dict]]:
    """``train_step(state, tiles) -> (state, metrics)``: one discriminator and one generator Adam update.

    Pure (jit it); the real batch ``[batch_size, size, size]`` is cut from ``tiles`` inside (crops of ``scales``
    cells, default ``dem.DEFAULT_SCALES``). ``r1``: weight of the lazy R1 penalty (0 = off). Metrics, [] float32
    each: ``d_loss``, ``g_loss``, ``d_real`` / ``d_fake`` (mean discriminator probabilities), ``r1``.
    """
    if batch_size < 1:
        raise ValueError(f"batch_size must be >= 1, got {batch_size}")
    if r1 < 0:
        raise ValueError(f"r1 must be >= 0, got {r1}")
    gen, disc = make_modules(config)
    opt = gan_optimizer(lr)
    scales = tuple(scales or dem.DEFAULT_SCALES)

    def train_step(state: GanTrainState, tiles: dem.DemTiles):
        key, data_key, z_key, z2_key = jax.random.split(state.key, 4)
        real = dem.random_patches(data_key, tiles, batch_size, config.size, scales)
        z = sample_latents(z_key, batch_size, config.latent)
        fake, _ = gen.apply(
            {"params": state.g_params, "batch_stats": state.g_stats}, z, train=True, mutable=["batch_stats"]
        )
        fake = jax.lax.stop_gradient(fake)
        d_loss_fn = _d_loss_fn(disc, real, fake, state.step, r1)
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
        new_state = GanTrainState(state.step + 1, key, g_params, g_stats, d_params, g_opt, d_opt)
        metrics = dict(d_loss=d_loss, g_loss=g_loss, d_real=d_real, d_fake=d_fake, r1=penalty)
        return new_state, metrics

    return train_step


@functools.lru_cache(maxsize=8)
def jitted_step(config: GanConfig, batch_size: int, lr: float, r1: float, donate: bool = False):
    """:func:`make_train_step` jit-compiled (``donate``: donate the state's buffers); one per setting, reused
    across runs in one process (tests, resume). The cache key is the static setting, nothing else."""
    return jax.jit(make_train_step(config, batch_size, lr, r1), donate_argnums=(0,) if donate else ())


@functools.lru_cache(maxsize=8)
def jitted_samples(config: GanConfig, n: int = 16):
    """``(fake, real)``: ``fake(params, batch_stats) -> [n, size, size]`` for a fixed set of ``n`` latents (the
    same grid at every step) and ``real(key, tiles) -> [n, size, size]`` training patches."""
    gen, _ = make_modules(config)
    z = sample_latents(jax.random.PRNGKey(12345), n, config.latent)
    fake = jax.jit(lambda p, s: gen.apply({"params": p, "batch_stats": s}, z, train=False))
    real = jax.jit(lambda k, tiles: dem.random_patches(k, tiles, n, config.size))
    return fake, real


def generator_params(config: GanConfig) -> int:
    """Number of the generator's trainable parameters (shapes only: nothing is compiled)."""
    gen, _ = make_modules(config)
    shapes = jax.eval_shape(lambda: gen.init(jax.random.PRNGKey(0), jnp.zeros((1, config.latent)), train=False))
    return count_params(shapes["params"])


# ----------------------------------------------------------------------------------------------------------------
# Quality
# ----------------------------------------------------------------------------------------------------------------
def wasserstein1(a, b) -> np.ndarray:
    """Per-column Wasserstein-1 distance between the empirical distributions of ``a[N, D]`` and ``b[M, D]``. [D]."""
    a, b = np.sort(np.asarray(a, np.float64), 0), np.sort(np.asarray(b, np.float64), 0)
    q = np.linspace(0.0, 1.0, 1001)[1:-1]
    qa, qb = np.quantile(a, q, axis=0), np.quantile(b, q, axis=0)
    return np.mean(np.abs(qa - qb), axis=0)


def _render_batches(fn, inputs, chunk: int = 128) -> np.ndarray:
    return np.concatenate([np.asarray(fn(inputs[i: i + chunk])) for i in range(0, len(inputs), chunk)])


def _quality_sets(key: jax.Array, config: GanConfig, variables: dict, tiles, n: int) -> tuple[dict, str | None]:
    """``{"gan", "real", "real_b"[, "perlin"]}`` -> ``[n, size, size]`` maps, and the Perlin error (or None)."""
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
        perlin = generators.get("perlin", size=config.size)
        genomes = perlin.sample(k_perlin, n)
        sets["perlin"] = _render_batches(perlin.render, genomes)
    except Exception as err:  # noqa: BLE001 - the check still reports the GAN part
        perlin_error = f"{type(err).__name__}: {err}"
    return sets, perlin_error


def quality_check(key: jax.Array, config: GanConfig, variables: dict, tiles, n: int = 512,
                  names=("tri", "tpi", "roughness"), descriptors=None) -> dict:
    """Do GAN samples resemble the training patches more than Perlin terrains do?

    Draws ``n`` GAN terrains (truncated-normal latents), ``2 n`` training patches (``real`` and an independent
    ``real_b``) and ``n`` Perlin terrains (uniform genomes), all ``[n, size, size]`` in [0, 1]; computes
    ``descriptors`` (default ``jaxterrain.features.descriptors``, window 30, stride 2) and, per feature, the
    Wasserstein-1 distance to ``real`` divided by the standard deviation of ``real`` (so features are comparable).
    ``real_b`` gives the sampling-noise floor. Returns a JSON-able dict with ``w1`` per set and feature, their
    means, and ``gan_closer_than_perlin``.
    """
    if descriptors is None:
        descriptors = features.descriptors
    sets, perlin_error = _quality_sets(key, config, variables, tiles, n)
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
# The run: a driver that owns the loop and its files
# ----------------------------------------------------------------------------------------------------------------
class GanRun(NamedTuple):
    """The settings of one training run (``train-gan``'s presets fill them).

    config: the architecture. steps: total steps (a resumed run continues to it). batch_size: patches per step.
    lr: Adam's learning rate. r1: the R1 weight (0: off). seed: the run's key. sample_every / ckpt_every /
    log_every: steps between sample grids, checkpoints and log lines. quality_samples: terrains per set in the final
    :func:`quality_check` (0: skip)."""

    config: GanConfig
    steps: int
    batch_size: int = 8
    lr: float = 2e-4
    r1: float = 0.0
    seed: int = 0
    sample_every: int = 10
    ckpt_every: int = 10
    log_every: int = 5
    quality_samples: int = 0


class GanResult(NamedTuple):
    """What :func:`train_gan` returns. state: the :class:`GanTrainState` reached. done: steps done (< ``steps``
    after a time-limit stop: resumable). wall: seconds of the loop. history: metric name -> one float per step of the
    run (resumed runs included). last_metrics: the last step's (None: no step). variables: the generator's flax
    variables (``final/``), None unless finished. quality: the :func:`quality_check` report (None: skipped or not
    finished)."""

    state: GanTrainState
    done: int
    wall: float
    history: dict
    last_metrics: Optional[dict]
    variables: Optional[dict]
    quality: Optional[dict]


def save_grid(path, maps, cols: int = 4) -> Path:
    """Save ``[N, H, W]`` maps in [0, 1] as one PNG grid (matplotlib 'terrain' colours, 2 px gaps), atomically."""
    from matplotlib import colormaps
    from PIL import Image

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


def _log_metrics(say, log_path: Path, step: int, total: int, start: int, t0: float, metrics) -> None:
    """Say and append to ``log.jsonl`` one log line for ``step``; raise on non-finite losses."""
    m = {k: float(v) for k, v in metrics.items()}
    rate = (step - start) / max(time.time() - t0, 1e-9)
    say(f"step {step}/{total}  " + "  ".join(f"{k} {v:.4f}" for k, v in m.items()) + f"  {rate:.1f} steps/s")
    with open(log_path, "a") as f:
        f.write(json.dumps({"step": step, "time": time.time() - t0, **m}) + "\n")
    if not all(np.isfinite(list(m.values()))):
        raise FloatingPointError(f"train-gan: non-finite losses at step {step}: {m}")


def _chunk(run: GanRun, folder: Path, tiles, start: int, say):
    """The ``runtime.driver`` chunk ``(state, a, b) -> (state, metrics [b - a])``: steps ``a + 1 .. b`` of the jitted
    step, with log lines and sample grids at their intervals (``start``: where this call began)."""
    step_fn = jitted_step(run.config, int(run.batch_size), float(run.lr), float(run.r1),
                          jax.default_backend() != "cpu")
    sample_fn, _ = jitted_samples(run.config)
    t0 = time.time()

    def chunk(state, a: int, b: int):
        done = []
        for step in range(a + 1, b + 1):
            state, metrics = step_fn(state, tiles)
            done.append(metrics)
            if step % run.log_every == 0 or step == run.steps:
                _log_metrics(say, folder / "log.jsonl", step, run.steps, start, t0, metrics)
            if step % run.sample_every == 0 or step == run.steps:
                save_grid(folder / "samples" / f"step_{step:08d}.png", sample_fn(state.g_params, state.g_stats))
        return state, {k: jnp.stack([m[k] for m in done]) for k in done[0]}

    return chunk


def _start(run: GanRun, folder: Path, resume: bool, say) -> tuple[GanTrainState, int, Optional[dict]]:
    """``(state, steps done, history)``: fresh from the run's seed, or with ``resume`` the folder's checkpoint."""
    state = init_state(jax.random.PRNGKey(int(run.seed)), run.config, float(run.lr))
    restored = driver.restore(folder, like=state) if resume else None
    if restored is None:
        if resume:
            say(f"--resume: no checkpoint in {folder}; starting from scratch")
        return state, 0, None
    state, done, history, _ = restored
    say(f"resumed from {folder / driver.CHECKPOINT_NAME} at step {done}")
    return state, done, history


def train_gan(run: GanRun, tiles: dem.DemTiles, folder, *, resume: bool = False,
              time_limit_s: Optional[float] = None, progress: bool | str = True, say: Callable[[str], None] = print,
              meta: Optional[dict] = None) -> GanResult:
    """Train the GAN of ``run`` on ``tiles`` (``dem.stack_tiles``) into ``folder``, or with ``resume`` continue the
    folder's run, to ``run.steps`` through ``jaxterrain.runtime.driver.run_chunks``: ``checkpoint.npz``,
    ``metrics.csv`` and TensorBoard events every ``ckpt_every`` steps, ``log.jsonl`` lines, sample grids
    (``samples/real.png``, ``samples/step_*.png``); stops after ``time_limit_s`` seconds at a checkpoint. Finished,
    it writes ``final/`` (``gan.save_generator``) and ``quality.json``. ``say`` prints a line (the command's goes
    above its progress bar); ``meta`` joins the checkpoint's meta. Same seed, same bytes."""
    folder = Path(folder)
    state, start, history = _start(run, folder, resume, say)
    _, real_fn = jitted_samples(run.config)
    if not (folder / "samples" / "real.png").exists():
        save_grid(folder / "samples" / "real.png", real_fn(jax.random.PRNGKey(7), tiles))
    estimates.announce("gan-step", f"batch {run.batch_size}, {run.config.size} x {run.config.size}")
    t0 = time.time()
    state, done, history = driver.run_chunks(
        _chunk(run, folder, tiles, start, say), state, total=int(run.steps), every=int(run.ckpt_every), start=start,
        history=history, run_dir=folder, key_metric="g_loss", time_limit_s=time_limit_s, progress=progress,
        desc="train-gan", meta={"command": "train-gan", **(meta or {}), "config": run.config.to_json()})
    wall = time.time() - t0
    if start < done:
        say(f"trained {done - start} steps in {wall:.1f} s")
    last = {k: v[-1] for k, v in history.items() if v} or None
    if done < run.steps:
        return GanResult(state, done, wall, history, last, None, None)
    variables = {"params": state.g_params, "batch_stats": state.g_stats}
    save_generator(folder / "final", run.config, variables)
    return GanResult(state, done, wall, history, last, variables, _quality(run, folder, variables, tiles, say))


def _quality(run: GanRun, folder: Path, variables: dict, tiles, say) -> Optional[dict]:
    """The :func:`quality_check` of the trained generator, written to ``quality.json`` (None: skipped)."""
    if int(run.quality_samples) <= 0:
        return None
    try:
        quality = quality_check(jax.random.PRNGKey(int(run.seed) + 1), run.config, variables, tiles,
                                int(run.quality_samples))
    except ImportError as err:
        say(f"quality check skipped: {err}")
        return None
    atomic_write_text(folder / "quality.json", json.dumps(quality, indent=2) + "\n")
    say(f"quality (mean W1 to training patches, lower = closer): {json.dumps(quality['mean_w1'])}  "
        f"gan_closer_than_perlin: {quality['gan_closer_than_perlin']}")
    return quality

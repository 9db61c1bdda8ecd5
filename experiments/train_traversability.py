"""``python -m experiments train-traversability``: the learned traversability model (paper 3.2 item 4).

1. Data: for every generator, render terrains, flatten each by a random amplitude (so that the walks span easy to
   hard), let the shipped base policy walk them (:func:`jaxterrain.features.learned.walk`, lateral starts spread over
   ``start_spread`` m), label windows of the walks (:func:`~jaxterrain.features.learned.window_labels`) and cut the
   32 x 32 patch of each labelled window (:func:`~jaxterrain.features.learned.extract_patches`). Classes are balanced
   per generator (the rarer class kept whole, the other subsampled). ``data_<generator>.npz`` per generator.
2. Held-out evaluation: for each generator in turn, train on the other generators' patches and report accuracy
   and ROC AUC on the left-out generator's patches (``heldout.csv``, ``heldout.md``).
3. The final model: trained on every generator's patches but ``test_fraction`` of them, evaluated on those
   (``model/``: ``weights.msgpack`` + ``config.json``). ``--export-assets`` copies it to
   ``jaxterrain/assets/traversability/`` with a ``PROVENANCE.md``.

Presets: ``smoke`` (seconds of walking; a tiny model; tests), ``cpu`` (a few thousand patches and a few minutes of
training on a 2-core CPU: the shipped model), ``gpu`` (64x the walks and 8x the training steps; ready, not run yet:
on the GPU machine, whose commands stop at 10 minutes, run it as
``train-traversability --preset gpu --time-limit 8 --out RUN --export-assets``, then ``--resume RUN
--export-assets`` until it exits 0).
``--resume RUN`` reuses what is written: the data files, the final model (``model/``) and the held-out rows
(``heldout.json``); ``--time-limit MIN`` stops between generators' walks and between held-out models (exit code 3).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from experiments import common

_LABEL = dict(window=30, threshold=0.3, every=4, warmup=8)
PRESETS: dict[str, dict] = common.with_preset_names({
    "smoke": dict(generators=["perlin", "diamond_square"], terrains=4, attempts=2, horizon=60, walk_batch=4,
                  amplitude=[0.8, 1.0], start_spread=3.0, label=_LABEL, channels=[4, 4, 4, 4], input_scale=10.0,
                  steps=20, batch=32, learning_rate=2e-3, weight_decay=1e-4, test_fraction=0.2, heldout=True),
    "cpu": dict(generators=["cppn", "diamond_square", "gan", "perlin", "worley"], terrains=32, attempts=4,
                horizon=240, walk_batch=16, amplitude=[0.2, 1.0], start_spread=3.0, label=_LABEL,
                channels=[16, 32, 32, 64], input_scale=10.0, steps=1500, batch=128, learning_rate=2e-3,
                weight_decay=1e-4, test_fraction=0.1, heldout=True),
    "gpu": dict(generators=["cppn", "diamond_square", "gan", "perlin", "worley"], terrains=1024, attempts=8,
                horizon=400, walk_batch=1024, amplitude=[0.2, 1.0], start_spread=3.0, label=_LABEL,
                channels=[16, 32, 32, 64], input_scale=10.0, steps=12000, batch=512, learning_rate=2e-3,
                weight_decay=1e-4, test_fraction=0.1, heldout=True),
}, {"gpu-short": ("gpu", {"terrains": 128, "steps": 1200}), "paper": "gpu"})


def add_arguments(parser: argparse.ArgumentParser) -> None:
    common.add_run_arguments(parser, PRESETS, "cpu", {"cpu": "a few thousand patches and minutes of training on "
                                                              "2 CPU cores: the shipped model"})
    parser.add_argument("--generators", nargs="+", default=None, help="generator names (default: all five)")
    common.add_terrains_argument(parser, "terrains", "each walked by the base policy, its patches labelled")
    parser.add_argument("--attempts", type=int, default=None, help="walks per terrain")
    parser.add_argument("--steps", type=int, default=None, help="training steps (minibatches)")
    parser.add_argument("--heldout", action=argparse.BooleanOptionalAction, default=None,
                        help="also train one model per generator left out and score it on that generator "
                             "(--no-heldout: skip it)")
    parser.add_argument("--export-assets", action="store_true",
                        help="copy the final model to jaxterrain/assets/traversability/ with a PROVENANCE.md")


def overrides(args) -> dict:
    return dict(generators=args.generators, terrains=args.terrains, attempts=args.attempts, steps=args.steps,
                heldout=args.heldout)


def collect(name: str, cfg: dict, key, balance_key, progress=print) -> dict:
    """Labelled patches of one generator, balanced with ``balance_key``: ``{"patches" [N, 32, 32] metres,
    "labels" [N], "terrain" [N], "all_labels" (every labelled window, before balancing), "amplitude" [terrains],
    "walks", "mean_end"}``."""
    import jax
    import numpy as np

    from jaxterrain import generators
    from jaxterrain.features import learned as trav

    gen = generators.get(name)
    label_cfg = trav.LabelConfig(**cfg["label"])
    n, bs = int(cfg["terrains"]), int(cfg["walk_batch"])
    k_gen, k_amp, k_walk = jax.random.split(key, 3)
    lo, hi = cfg["amplitude"]
    amplitude = np.asarray(jax.random.uniform(k_amp, (n,), minval=lo, maxval=hi))
    heights, terrain, xy, labels, ends = [], [], [], [], []
    for s in range(0, n, bs):
        count = min(bs, n - s)
        maps = gen.render(gen.sample(jax.random.fold_in(k_gen, s), bs))[:count] * amplitude[s:s + count, None, None]
        if count < bs:  # one compiled walk program: pad the last batch
            maps = jax.numpy.concatenate([maps, jax.numpy.repeat(maps[-1:], bs - count, 0)])
        walks = trav.walk(jax.random.fold_in(k_walk, s), maps, int(cfg["attempts"]), int(cfg["horizon"]),
                          start_spread=float(cfg["start_spread"]))
        walks = jax.tree.map(lambda a: a[:count], walks)
        starts, lab = trav.window_labels(walks, label_cfg)
        t, c, lab = trav.labelled_centres(walks, starts, lab, label_cfg)
        heights.append(np.asarray(maps[:count]))  # metres at the default scale (1.0 m per unit)
        terrain.append(t + s)
        xy.append(c)
        labels.append(lab)
        ends.append(np.asarray(walks.end))
        progress(f"  [{name}] {s + count}/{n} terrains walked, {sum(map(len, labels))} labelled windows")
    heights, terrain, xy, labels = (np.concatenate(v) for v in (heights, terrain, xy, labels))
    keep = trav.balanced_indices(balance_key, labels)
    patches = [np.asarray(trav.extract_patches_batch(heights, terrain[keep[i:i + 4096]], xy[keep[i:i + 4096]]))
               for i in range(0, len(keep), 4096)]
    return {"patches": np.concatenate(patches) if patches else np.zeros((0, trav.PATCH, trav.PATCH), np.float32),
            "labels": labels[keep], "terrain": terrain[keep], "all_labels": labels, "amplitude": amplitude,
            "mean_end": np.float64(np.concatenate(ends).mean()), "walks": np.int64(n * int(cfg["attempts"]))}


def _train_eval(key, train_x, train_y, test_x, test_y, cfg: dict, log=None):
    import numpy as np

    from jaxterrain.features import learned as trav

    mcfg = trav.ModelConfig(tuple(cfg["channels"]), float(cfg["input_scale"]))
    tcfg = trav.TrainConfig(steps=int(cfg["steps"]), batch=int(cfg["batch"]),
                            learning_rate=float(cfg["learning_rate"]), weight_decay=float(cfg["weight_decay"]))
    params = trav.train(key, train_x, train_y, tcfg, mcfg, log=log)
    scores = np.concatenate([np.asarray(trav.apply_patches(params, test_x[i:i + 512], mcfg))
                             for i in range(0, len(test_x), 512)]) if len(test_x) else np.zeros(0)
    return params, mcfg, {"n_train": int(len(train_y)), "n_test": int(len(test_y)),
                          "accuracy": trav.accuracy(scores, test_y), "auc": trav.roc_auc(scores, test_y)}


def load_or_collect(folder: Path, names, cfg: dict, key, clock: common.Clock | None = None) -> dict:
    """``{generator: balanced {"patches", "labels"}}`` plus counts, walking only generators without a data file
    (``clock``: raises :class:`common.TimeUp` before walking another generator once the time limit has passed)."""
    import time

    import jax
    import numpy as np

    from jaxterrain.runtime.io import atomic_save_npz

    data, walked = {}, False
    for gi, name in enumerate(names):
        path = folder / f"data_{name}.npz"
        if not path.exists():
            if clock is not None and walked:
                clock.check()
            walked = True
            t0 = time.time()
            raw = collect(name, cfg, jax.random.fold_in(key, gi), jax.random.fold_in(key, 100 + gi),
                          progress=lambda m: print(m, flush=True))
            atomic_save_npz(path, **raw, seconds=np.float64(time.time() - t0))
        with np.load(path) as f:
            data[name] = {k: f[k] for k in f.files}
        d = data[name]
        print(f"[{name}] {int(d['walks'])} walks (mean length {float(d['mean_end']):.0f} steps), "
              f"{len(d['all_labels'])} labelled windows ({int(d['all_labels'].sum())} positive); "
              f"balanced: {len(d['labels'])} patches", flush=True)
    return data


def heldout(data: dict, cfg: dict, key, folder: Path, clock: common.Clock | None = None) -> list[dict]:
    """Leave-one-generator-out: a model per generator trained on the others, scored on it. Rows so far are kept in
    ``folder/heldout.json`` and reused (``--resume``); ``clock`` raises :class:`common.TimeUp` between models."""
    import jax
    import numpy as np

    from jaxterrain.runtime.io import atomic_write_text

    path = folder / "heldout.json"
    rows = json.loads(path.read_text()) if path.exists() else []
    done = {r["left_out"] for r in rows}
    for gi, left in enumerate(data):
        others = [g for g in data if g != left and len(data[g]["labels"])]
        if left in done or not others or not len(data[left]["labels"]):
            continue
        if clock is not None and len(rows) > len(done):
            clock.check()
        tx = np.concatenate([data[g]["patches"] for g in others])
        ty = np.concatenate([data[g]["labels"] for g in others])
        _, _, m = _train_eval(jax.random.fold_in(key, gi), tx, ty, data[left]["patches"], data[left]["labels"], cfg)
        rows.append({"left_out": left, **m})
        atomic_write_text(path, json.dumps(rows, indent=2) + "\n")
        print(f"  held out {left}: accuracy {m['accuracy']:.3f}, ROC AUC {m['auc']:.3f} "
              f"(train {m['n_train']}, test {m['n_test']})", flush=True)
    return rows


def final_model(data: dict, cfg: dict, key):
    """Train on every generator but a random ``test_fraction`` of the patches; returns (params, config, metrics)."""
    import jax
    import numpy as np

    x = np.concatenate([d["patches"] for d in data.values()])
    y = np.concatenate([d["labels"] for d in data.values()])
    if min((y == 1).sum(), (y == 0).sum()) < 2:
        raise SystemExit(f"only {len(y)} balanced patches: too few walks fell (or advanced) to train on; "
                         "walk more terrains (--terrains) or for longer (horizon)")
    perm = np.asarray(jax.random.permutation(jax.random.fold_in(key, 1), len(y)))
    n_test = int(round(float(cfg["test_fraction"]) * len(y)))
    test, tr = perm[:n_test], perm[n_test:]
    log = lambda s, loss: print(f"  final model step {s}: loss {loss:.4f}", flush=True)  # noqa: E731
    return _train_eval(jax.random.fold_in(key, 2), x[tr], y[tr], x[test], y[test], cfg, log=log)


def _table(rows: list[dict]) -> str:
    lines = ["| left-out generator | train patches | test patches | accuracy | ROC AUC |", "|---|---|---|---|---|"]
    lines += [f"| {r['left_out']} | {r['n_train']} | {r['n_test']} | {r['accuracy']:.3f} | {r['auc']:.3f} |"
              for r in rows]
    return "\n".join(lines) + "\n"


def provenance(cfg: dict, data: dict, rows: list[dict], final: dict, seconds: dict, date: str) -> str:
    """PROVENANCE.md of an exported model."""
    import jax

    from jaxterrain.runtime.provenance import device, git_commit

    walk_s = (f"{sum(float(d['seconds']) for d in data.values()):.0f} s" if all("seconds" in d for d in data.values())
              else "not recorded (data files of an earlier version of the command)")
    counts = "\n".join(f"  - {g}: {int(d['walks'])} walks, {len(d['all_labels'])} labelled windows "
                       f"({int(d['all_labels'].sum())} positive), {len(d['labels'])} balanced patches"
                       for g, d in data.items())
    return f"""# Traversability model provenance

Patch classifier of `jaxterrain.features.learned` (`PatchCNN`), loaded by `traversability.load()` and behind the
`"traversability"` descriptor.

- Command: `python -m experiments train-traversability --preset {cfg.get('preset')} --export-assets`
  (config: `config.json` of the run, copied below)
- Device: {device()}; jax {jax.__version__}
- Date: {date}
- Commit: {git_commit()}
- Time: walking and labelling {walk_s}, final model {seconds['final']:.0f} s, held-out models
  {seconds['heldout']:.0f} s
- Data: {sum(int(d['walks']) for d in data.values())} walks of the shipped base policy, {cfg['terrains']} terrains
  per generator x {cfg['attempts']} attempts, horizon {cfg['horizon']} env steps, amplitude uniform in
  {cfg['amplitude']}, lateral start spread {cfg['start_spread']} m; labels {cfg['label']};
  {sum(len(d['labels']) for d in data.values())} balanced patches of 32 x 32 pixels:
{counts}
- Training: {cfg['steps']} Adam steps of {cfg['batch']} patches (plus their mirror images across the walking line),
  learning rate {cfg['learning_rate']} (cosine decay), weight decay {cfg['weight_decay']}; channels {cfg['channels']}.
- Final model: trained on {final['n_train']} patches of all generators, tested on {final['n_test']} others:
  accuracy {final['accuracy']:.3f}, ROC AUC {final['auc']:.3f}.

Held out by generator (a model trained on the other generators, tested on the balanced patches of the one left
out):

{_table(rows) if rows else "(not run yet)"}

This model was trained on a CPU at a small scale (a few thousand patches, minutes of training). The `gpu` preset
(64x the walks, 8x the training steps) is ready for a GPU run; re-export its model with `--export-assets`.

Config:

```json
{json.dumps(cfg, indent=2, sort_keys=True)}
```
"""


def export(folder: Path, params, mcfg, cfg: dict, data: dict, rows: list, final: dict, seconds: dict, date: str,
           to_assets: bool) -> None:
    """Write ``folder/model/`` (weights, config.json, PROVENANCE.md) and, with ``to_assets``, copy it to
    ``jaxterrain/assets/traversability/``."""
    import shutil

    from jaxterrain.features import learned as trav
    from jaxterrain.runtime.io import atomic_write_text
    from jaxterrain.runtime.provenance import device, git_commit

    trav.save(folder / "model", params, mcfg, extra={"label": cfg["label"], "final": final, "heldout": rows,
                                                      "device": device(), "date": date, "commit": git_commit(),
                                                      "seconds": seconds})
    atomic_write_text(folder / "model" / "PROVENANCE.md", provenance(cfg, data, rows, final, seconds, date))
    if to_assets:
        trav.ASSET_DIR.mkdir(parents=True, exist_ok=True)
        for name in (trav.model.WEIGHTS_NAME, trav.model.CONFIG_NAME, "PROVENANCE.md"):
            shutil.copyfile(folder / "model" / name, trav.ASSET_DIR / name)
        trav.shipped.cache_clear()
        trav.model._shipped_descriptor.cache_clear()
        print(f"exported to {trav.ASSET_DIR}", flush=True)


def main(args) -> int:
    import datetime
    import time

    import jax

    from jaxterrain.features import learned as trav
    from jaxterrain.runtime.io import atomic_write_text
    from jaxterrain.runtime.provenance import device

    folder, cfg = common.setup_resumable_run("train-traversability", args, PRESETS, "cpu", overrides(args))
    print(f"train-traversability: {folder}  device {device()}", flush=True)
    key = jax.random.key(int(cfg["seed"]))
    clock = common.Clock(args.time_limit)
    t0 = time.time()
    try:
        from jaxterrain.runtime import estimates

        estimates.announce("walks", f"{cfg['attempts']} walks a terrain")
        data = load_or_collect(folder, list(cfg["generators"]), cfg, jax.random.fold_in(key, 0), clock)
    except common.TimeUp:
        print(f"time limit reached; continue with: python -m experiments train-traversability --resume {folder}",
              flush=True)
        return 3
    seconds = {"data": time.time() - t0}
    t0 = time.time()
    if (folder / "model" / trav.model.WEIGHTS_NAME).exists():  # --resume after the final model: keep it
        saved = trav.load(folder / "model")
        params, mcfg, final = saved.params, saved.config, saved.meta["final"]
        seconds["final"] = float(saved.meta.get("seconds", {}).get("final", 0.0))
    else:
        params, mcfg, final = final_model(data, cfg, jax.random.fold_in(key, 2))
        seconds["final"] = time.time() - t0
    print(f"final model: accuracy {final['accuracy']:.3f}, ROC AUC {final['auc']:.3f} on {final['n_test']} "
          f"held-back patches", flush=True)
    date = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    seconds["heldout"], rows = 0.0, []
    export(folder, params, mcfg, cfg, data, rows, final, seconds, date, args.export_assets)  # usable at once
    if cfg.get("heldout"):
        t0 = time.time()
        try:
            rows = heldout(data, cfg, jax.random.fold_in(key, 1), folder, clock)
        except common.TimeUp:
            print(f"time limit reached after the final model (exported); held-out models continue with: "
                  f"python -m experiments train-traversability --resume {folder}", flush=True)
            return 3
        seconds["heldout"] = time.time() - t0
        atomic_write_text(folder / "heldout.md", _table(rows))
        export(folder, params, mcfg, cfg, data, rows, final, seconds, date, args.export_assets)
    print(f"done -> {folder}", flush=True)
    return 0

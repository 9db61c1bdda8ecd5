"""Training the learned traversability model on labelled patches, and its metrics (ROC AUC, accuracy)."""

from __future__ import annotations

from typing import Any, Callable, NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

from jaxterrain.features.learned.model import ModelConfig, PATCH, apply_patches, init_params

__all__ = ["TrainConfig", "train", "roc_auc", "accuracy"]


class TrainConfig(NamedTuple):
    """:func:`train`: Adam at ``learning_rate`` (cosine decay to 0), ``steps`` minibatches of ``batch`` patches,
    L2 ``weight_decay``; ``flip_y`` adds the patches mirrored across the walking line (the humanoid is symmetric)."""

    steps: int = 2000
    batch: int = 128
    learning_rate: float = 2e-3
    weight_decay: float = 1e-4
    flip_y: bool = True


# ----------------------------------------------------------------------------------------------------------------
# Training and metrics


def _loss(params, patches, labels, config: ModelConfig, weight_decay: float):
    logits = apply_patches(params, patches, config)
    bce = jnp.mean(jnp.maximum(logits, 0) - logits * labels + jnp.log1p(jnp.exp(-jnp.abs(logits))))
    l2 = sum(jnp.sum(jnp.square(w)) for p, w in jax.tree_util.tree_leaves_with_path(params)
             if jax.tree_util.keystr(p).endswith("['kernel']"))
    return bce + weight_decay * l2


def train(key: jax.Array, patches, labels, config: TrainConfig = TrainConfig(),
          model_config: ModelConfig = ModelConfig(), log: Optional[Callable[[int, float], None]] = None) -> Any:
    """Fit :class:`PatchCNN` to binary ``labels [N]`` of ``patches [N, 32, 32]`` (metres) by minibatch Adam on
    the logistic loss. Returns the params. ``log(step, loss)`` is called every 200 steps and at the end."""
    import optax

    p = jnp.asarray(patches, jnp.float32)
    y = jnp.asarray(labels, jnp.float32)
    if p.ndim != 3 or p.shape[0] != y.shape[0] or p.shape[0] < 2:
        raise ValueError(f"patches [N, {PATCH}, {PATCH}] and labels [N] need the same N >= 2; got "
                         f"{tuple(p.shape)} and {tuple(y.shape)}")
    if config.flip_y:
        p, y = jnp.concatenate([p, p[:, ::-1, :]]), jnp.concatenate([y, y])
    k_init, k_data = jax.random.split(key)
    params = init_params(k_init, model_config)
    opt = optax.adam(optax.cosine_decay_schedule(config.learning_rate, config.steps))
    batch = min(int(config.batch), p.shape[0])

    @jax.jit
    def update(params, opt_state, k):
        idx = jax.random.choice(k, p.shape[0], (batch,), replace=False)
        loss, grads = jax.value_and_grad(_loss)(params, p[idx], y[idx], model_config, config.weight_decay)
        updates, opt_state = opt.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, loss

    opt_state = opt.init(params)
    for s in range(int(config.steps)):
        params, opt_state, loss = update(params, opt_state, jax.random.fold_in(k_data, s))
        if log is not None and ((s + 1) % 200 == 0 or s + 1 == config.steps):
            log(s + 1, float(loss))
    return params


def roc_auc(scores, labels) -> float:
    """Area under the ROC curve of ``scores [N]`` for binary ``labels [N]`` (Mann-Whitney U, ties counted 1/2);
    NaN when a class is missing."""
    from scipy.stats import rankdata

    s, y = np.asarray(scores, np.float64), np.asarray(labels).astype(bool)
    n1, n0 = int(y.sum()), int((~y).sum())
    if n1 == 0 or n0 == 0:
        return float("nan")
    ranks = rankdata(s)
    return float((ranks[y].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


def accuracy(scores, labels, threshold: float = 0.0) -> float:
    """Fraction of ``scores > threshold`` (logits: 0) that equal binary ``labels``."""
    return float(np.mean((np.asarray(scores) > threshold) == np.asarray(labels).astype(bool)))

"""The Intelligent Trial and Error Gaussian process (Cully et al. 2015, as in resibots/ITE + limbo) as pure functions.

    mean, var = gp.posterior(obs_x, obs_y, obs_mask, obs_prior, cells_x, prior_mean, gp.GPParams())
    score = gp.ucb(mean, var, kappa=0.05)

Inputs are the archive's descriptors normalised to [0, 1] (``TerrainBank.points``); the prior mean of a cell is the
archive's fitness of its elite (the base policy's). Kernel: Matern 5/2 on the L2 distance ``d``,
``k = sigma_f (1 + sqrt5 d / rho + 5 d^2 / (3 rho^2)) exp(-sqrt5 d / rho)`` with ``rho = 0.4``, ``sigma_f = 1``;
observation noise 0.001 on the diagonal. Posterior (``chi`` the observed points, ``m`` the prior mean)::

    mu(x)      = m(x) + k(x, chi) K^-1 (y - m(chi)),     K = k(chi, chi) + noise I
    sigma^2(x) = k(x, x) - k(x, chi) K^-1 k(chi, x)

Observations live in padded arrays of a fixed length ``M`` with a mask, so a jitted curriculum never re-compiles as
observations arrive: masked rows and columns of ``K`` become the identity, masked residuals and cross-covariances 0,
which gives exactly the posterior of the unmasked observations alone.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from jaxterrain.runtime import validation

__all__ = ["GPParams", "matern52", "posterior", "ucb"]

_SQRT5 = 5.0 ** 0.5


class GPParams(NamedTuple):
    """IT&E's recommended hyperparameters (the paper keeps them): length scale ``rho``, signal variance ``sigma_f``,
    observation ``noise`` (variance). Floats or [] arrays (they may be traced)."""

    rho: float = 0.4
    sigma_f: float = 1.0
    noise: float = 0.001


def matern52(xa: jax.Array, xb: jax.Array, params: GPParams) -> jax.Array:
    """``[A, D]``, ``[B, D]`` -> ``[A, B]`` Matern 5/2 covariance on the Euclidean (L2) distance."""
    diff = xa[:, None, :] - xb[None, :, :]
    d = jnp.sqrt(jnp.maximum(jnp.sum(diff * diff, axis=-1), 0.0))
    r = _SQRT5 * d / params.rho
    return params.sigma_f * (1.0 + r + r * r / 3.0) * jnp.exp(-r)


def posterior(obs_x: jax.Array, obs_y: jax.Array, obs_mask: jax.Array, obs_prior: jax.Array, cells_x: jax.Array,
              prior_mean: jax.Array, params: GPParams = GPParams()) -> tuple[jax.Array, jax.Array]:
    """Posterior mean and variance of every cell given the masked observations.

    Args:
      obs_x: [M, D] float32, observed points (padding rows: any finite value).
      obs_y: [M] float32, observed values (fitness).
      obs_mask: [M] bool, which of the ``M`` slots hold an observation.
      obs_prior: [M] float32, the prior mean at each observed point.
      cells_x: [N, D] float32, points to predict.
      prior_mean: [N] float32, the prior mean at each of them.
      params: :class:`GPParams`.

    Returns ``(mean [N], variance [N])`` float32; the variance is clipped at 0. With no observation the posterior
    is the prior (mean = ``prior_mean``, variance = ``sigma_f``).
    """
    _check(obs_x, obs_y, obs_mask, obs_prior, cells_x, prior_mean, params)
    obs_mask = jnp.asarray(obs_mask, bool)
    m = obs_x.shape[0]
    pair = obs_mask[:, None] & obs_mask[None, :]
    eye = jnp.eye(m, dtype=jnp.float32)
    k = jnp.where(pair, matern52(obs_x, obs_x, params), 0.0) + eye * jnp.where(obs_mask, params.noise, 1.0)
    chol = jnp.linalg.cholesky(k)
    residual = jnp.where(obs_mask, obs_y - obs_prior, 0.0)
    alpha = jax.scipy.linalg.cho_solve((chol, True), residual)
    k_star = jnp.where(obs_mask[None, :], matern52(cells_x, obs_x, params), 0.0)  # [N, M]
    mean = prior_mean + k_star @ alpha
    v = jax.scipy.linalg.solve_triangular(chol, k_star.T, lower=True)  # [M, N]
    var = params.sigma_f - jnp.sum(v * v, axis=0)
    return mean, jnp.maximum(var, 0.0)


def _check(obs_x, obs_y, obs_mask, obs_prior, cells_x, prior_mean, params: GPParams) -> None:
    """Shapes always (they are static), hyperparameter values where concrete: ValueError naming the argument."""
    if jnp.ndim(obs_x) != 2 or jnp.ndim(cells_x) != 2 or jnp.shape(obs_x)[1] != jnp.shape(cells_x)[1]:
        raise ValueError(f"gp.posterior: obs_x [M, D] and cells_x [N, D] must share D; got {jnp.shape(obs_x)} and "
                         f"{jnp.shape(cells_x)}")
    m, n = jnp.shape(obs_x)[0], jnp.shape(cells_x)[0]
    for name, x, size in (("obs_y", obs_y, m), ("obs_mask", obs_mask, m), ("obs_prior", obs_prior, m),
                          ("prior_mean", prior_mean, n)):
        if jnp.shape(x) != (size,):
            raise ValueError(f"gp.posterior: {name} must have shape ({size},); got {jnp.shape(x)}")
    for name in ("rho", "sigma_f", "noise"):
        validation.positive(f"GPParams.{name}", getattr(params, name))


def ucb(mean: jax.Array, variance: jax.Array, kappa: float = 0.05) -> jax.Array:
    """``[N]`` upper confidence bound ``mean + kappa * sqrt(variance)`` (IT&E's acquisition; the paper's kappa)."""
    return mean + kappa * jnp.sqrt(jnp.maximum(variance, 0.0))

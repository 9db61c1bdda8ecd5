"""Public functions refuse bad input with a ValueError that names the parameter (issue 49's probe of the API:
each of these used to return something wrong, or fail with an error that did not name the problem)."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import features, generators, rl
from jaxterrain.curriculum import gp
from jaxterrain.terrain import TerrainScale

MAPS = np.random.default_rng(0).random((2, 32, 32)).astype(np.float32)


def _posterior(params=gp.GPParams(), obs_y=jnp.zeros(3)):
    return gp.posterior(jnp.zeros((3, 2)), obs_y, jnp.ones(3, bool), jnp.zeros(3), jnp.zeros((5, 2)), jnp.zeros(5),
                        params)


@pytest.mark.parametrize("call, message", [
    (lambda: generators.get("perlin", size=2.5), r"size must be an integer >= 1 \(pixels\); got 2.5"),
    (lambda: generators.get("perlin", size=0), "size must be an integer >= 1"),
    (lambda: _posterior(gp.GPParams(rho=0.0)), r"GPParams.rho must be a finite number > 0; got 0.0"),
    (lambda: _posterior(gp.GPParams(noise=-1.0)), r"GPParams.noise must be a finite number > 0"),
    (lambda: _posterior(obs_y=jnp.zeros(4)), r"obs_y must have shape \(3,\); got \(4,\)"),
    (lambda: features.is_traversable(MAPS, robot_height=jnp.float32(-1)), "robot_height .* must be a finite number > 0"),
    (lambda: TerrainScale(cell_size="0.04"), "TerrainScale.cell_size must be a finite number of metres > 0"),
    (lambda: features.descriptors(MAPS, names=None), "names must be a sequence of descriptor names"),
])
def test_bad_input_is_refused_naming_the_parameter(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_good_input_still_passes_also_under_jit():
    assert generators.get("perlin", size=np.int64(16)).render(generators.get("perlin", size=16).sample(
        jax.random.key(0), 1)).shape == (1, 16, 16)
    mean, var = jax.jit(lambda r: _posterior(gp.GPParams(rho=r)))(0.4)  # traced hyperparameters: not checked
    assert mean.shape == (5,) and bool(jnp.all(var >= 0))
    assert jax.jit(lambda h: features.is_traversable(MAPS, robot_height=h))(1.5).shape == (2,)


@pytest.mark.parametrize("field, value, message", [
    ("min_std", -1.0, r"PPOConfig.min_std must be a finite number >= 0.0"),
    ("learning_rate", "fast", r"PPOConfig.learning_rate must be a finite number, got 'fast'"),
    ("num_envs", "many", r"PPOConfig.num_envs must be an integer >= 1"),
])
def test_a_policy_config_with_a_bad_field_is_refused_naming_file_and_field(tmp_path, field, value, message):
    base = rl.load_policy()
    folder = tmp_path / "policy"
    rl.save_policy(folder, base.params, base.normaliser, base.config, base.observation_size, base.action_size,
                   actor_only=True)
    meta = json.loads((folder / "config.json").read_text())
    meta["ppo_config"][field] = value
    (folder / "config.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=message) as err:
        rl.load_policy(folder)
    assert "config.json" in str(err.value)

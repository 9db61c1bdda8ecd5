"""Public functions refuse bad input with a ValueError that names the parameter (issue 49's probe of the API:
each of these used to return something wrong, or fail with an error that did not name the problem)."""

from __future__ import annotations

import json
import re

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


def _archive_with(tmp_path, **header_changes):
    """A copy of a shipped archive with header fields changed."""
    from pathlib import Path

    src = np.load(Path(__file__).resolve().parents[2] / "docs" / "results" / "exp2_perlin_headings_archive.npz")
    members = {k: src[k] for k in src.files}
    header = {**json.loads(bytes(members["header"]).decode()), **header_changes}
    members["header"] = np.frombuffer(json.dumps(header).encode(), np.uint8)
    path = tmp_path / "bad.npz"
    np.savez(path, **members)
    return path


@pytest.mark.parametrize("changes, message", [
    (dict(cells="many"), "header field 'cells' must be an integer >= 1; got 'many'"),
    (dict(cells=2.5), "header field 'cells' must be an integer >= 1; got 2.5"),
    (dict(generator_names="perlin"), "header field 'generator_names' must be a list of names"),
    (dict(genomes=None), "header field 'genomes' must be a list"),
    (dict(heightmaps=[1, 2]), "header field 'heightmaps' must be null or"),
    (dict(config=[]), "header field 'config'"),
])
def test_an_archive_with_a_bad_header_field_names_file_and_field(tmp_path, changes, message):
    """issue 59: a bad header field (``cells='many'``) used to end in int()'s own error, naming neither."""
    from jaxterrain import qd

    path = _archive_with(tmp_path, **changes)
    with pytest.raises(ValueError, match=re.escape(message)) as err:
        qd.load(path)
    assert str(path) in str(err.value)


def test_an_npy_renamed_npz_and_random_bytes_are_not_archives(tmp_path):
    from jaxterrain import qd

    np.save(tmp_path / "a.npy", np.zeros(3))
    (tmp_path / "a.npy").rename(tmp_path / "a.npz")
    (tmp_path / "r.npz").write_bytes(np.random.default_rng(0).bytes(500))
    with pytest.raises(ValueError, match=r"a.npz': one .npy array, not an .npz archive file"):
        qd.load(tmp_path / "a.npz")
    with pytest.raises(ValueError, match=r"r.npz': not an .npz archive file \(no zip header\)"):
        qd.load(tmp_path / "r.npz")


@pytest.mark.parametrize("field, value, message", [
    ("action_size", 17.9, "field 'action_size' must be an integer >= 1; got 17.9"),
    ("action_size", -1, "field 'action_size' must be an integer >= 1; got -1"),
    ("observation_size", [45], "field 'observation_size' must be an integer >= 1; got [45]"),
    ("observation_size", None, "field 'observation_size' must be an integer >= 1; got None"),
    ("observation_size", True, "field 'observation_size' must be an integer >= 1; got True"),
    ("walker_config", "humanoid", "field 'walker_config' must be a JSON object"),
    ("walker_config", {"robot": 3}, "field 'walker_config.robot' must be a robot name or absent; got 3"),
])
def test_a_policy_with_bad_sizes_or_walker_config_names_file_and_field(tmp_path, field, value, message):
    """issue 59: ``action_size: 17.9`` was truncated, ``-1`` failed inside JAX, a string ``walker_config`` failed
    later with an AttributeError."""
    base = rl.load_policy()
    folder = tmp_path / "policy"
    rl.save_policy(folder, base.params, base.normaliser, base.config, base.observation_size, base.action_size,
                   actor_only=True)
    meta = json.loads((folder / "config.json").read_text())
    meta[field] = value
    (folder / "config.json").write_text(json.dumps(meta))
    with pytest.raises(ValueError, match=re.escape(message)) as err:
        rl.load_policy(folder)
    assert str(folder / "config.json") in str(err.value)


def _no_policies():
    from jaxterrain import suite

    return suite.evaluate_policies([], np.zeros((1, 64, 64), np.float32), jax.random.key(0))


def _curriculum(**fields):
    from jaxterrain.curriculum import CurriculumConfig, validate_config

    return validate_config(CurriculumConfig(**fields))


def _levels(**fields):
    from jaxterrain.curriculum.selectors import LevelsParams

    return LevelsParams(**fields)


def _npy_text(tmp_path):
    from jaxterrain import terrain

    (tmp_path / "t.txt").write_text("1 2 3\n")
    return terrain.load_npy(tmp_path / "t.txt")


@pytest.mark.parametrize("call, message", [
    (lambda tmp: generators.get(["perlin"]), r"generators.get: name must be a generator name \(a str, one of cppn"),
    (lambda tmp: TerrainScale(height=None), r"TerrainScale.height must be a finite number of metres > 0; got None"),
    (lambda tmp: TerrainScale(cell_size=np.array([0.04, 0.04])),
     r"TerrainScale.cell_size must be a finite number of metres > 0 \(a scalar\); got an array of shape \(2,\)"),
    (lambda tmp: TerrainScale(cell_size=[0.04]), r"TerrainScale.cell_size must be a finite number of metres > 0"),
    (lambda tmp: _curriculum(threshold="0.9"), r"CurriculumConfig.threshold must be a number, got '0.9'"),
    (lambda tmp: _curriculum(selector="levels", params=_levels(demote=True)),
     r"CurriculumConfig.params.demote must be a number, got True"),
    (lambda tmp: __import__("jaxterrain.curriculum").curriculum.CurriculumConfig.from_json_dict([1, 2]),
     r"CurriculumConfig.from_json_dict: needs a dict of fields .*; got list"),
    (lambda tmp: _no_policies(), r"policies: give at least one policy"),
    (lambda tmp: _npy_text(tmp), r"t.txt: not a .npy heightmap"),
])
def test_issue_59_library_inputs_are_refused_naming_the_argument(tmp_path, call, message):
    with pytest.raises(ValueError, match=message):
        call(tmp_path)


def test_terrain_scale_still_takes_scalars_tracers_and_pytree_rebuilds():
    """The stricter constructor keeps every real use: NumPy / JAX scalars, ``[]`` tracers under jit / vmap, JAX's own
    rebuilding of the pytree (placeholders) and ``_make`` for per-field ``in_axes``."""
    s = TerrainScale(np.float32(0.05), jnp.float32(2.0))
    assert jax.tree.map(lambda x: x * 2, TerrainScale(0.05, 2.0)) == (0.1, 4.0)
    assert float(jax.jit(lambda s: s.height * 2)(s)) == 4.0
    assert jax.vmap(lambda h: TerrainScale(height=h).height)(jnp.ones(3)).shape == (3,)
    axes = TerrainScale._make((None, 0))
    out = jax.vmap(lambda s: s.height, in_axes=(axes,))(TerrainScale._make((0.04, jnp.ones(3))))
    assert out.shape == (3,)
    assert jax.eval_shape(lambda s: s, s).height.shape == ()
    assert [str(k[0]) for k, _ in jax.tree_util.tree_flatten_with_path(s)[0]] == [".cell_size", ".height"]


def test_suite_load_takes_one_family_name_as_a_list_of_one():
    """issue 59: ``families='flat'`` used to be split into the letters f, l, a, t."""
    from jaxterrain import suite

    s = suite.load("v1", families="flat", generator_names=(), size=32, seeds=1)
    assert s.families() == ("flat",) or list(s.families()) == ["flat"]

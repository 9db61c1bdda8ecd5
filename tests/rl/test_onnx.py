"""ONNX export of walkers (``jaxterrain.rl.onnx``, ``export-policy --onnx``): the file's actions are the JAX
policy's (onnxruntime, max abs difference <= 1e-5) for both shipped base policies and a trained walker, on random
observations and on the walker's own; its metadata is enough to drive the robot in plain MuJoCo."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from jaxterrain import rl
from jaxterrain.rl import networks as nets
from jaxterrain.rl import onnx as rl_onnx
from jaxterrain.rl.config import PPOConfig
from jaxterrain.walker import WalkerConfig, WalkerEnv

onnx = pytest.importorskip("onnx", reason="needs the onnx extra: pip install 'jaxterrain[onnx]'")
ort = pytest.importorskip("onnxruntime", reason="needs the onnx extra: pip install 'jaxterrain[onnx]'")

ROOT = Path(__file__).resolve().parents[2]
TOL = 1e-5
POLICIES = {
    "humanoid": rl.base_policy_dir("humanoid"),
    "ant": rl.base_policy_dir("ant"),
    "trained": ROOT / "docs" / "results" / "exp3_gpushort" / "diamond_square-map" / "policies" / "trial_0",
}


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """``{name: (policy, path of its .onnx)}`` for the three policies, exported once."""
    out = tmp_path_factory.mktemp("onnx")
    return {name: (rl.load_policy(folder), rl.export_onnx(folder, out / f"{name}.onnx"))
            for name, folder in POLICIES.items()}


def run(path, obs):
    return rl_onnx.run_onnx(path, np.asarray(obs, np.float32))


def jax_actions(policy, obs):
    return np.asarray(jax.jit(policy)(jnp.asarray(obs, jnp.float32)))


def max_diff(policy, path, obs) -> float:
    return float(np.max(np.abs(run(path, obs) - jax_actions(policy, obs))))


@pytest.mark.parametrize("name", sorted(POLICIES))
def test_onnxruntime_gives_the_jax_policys_actions_on_random_observations(exported, name):
    policy, path = exported[name]
    mean, std = (np.asarray(v) for v in (policy.normaliser.mean, nets.stats_std(policy.normaliser)))
    z = np.random.default_rng(1).standard_normal((256, policy.observation_size)).astype(np.float32)
    for scale in (1.0, 3.0):  # the training distribution, and well outside it
        assert max_diff(policy, path, mean + scale * std * z) <= TOL
    assert max_diff(policy, path, mean[None] + std[None] * z[:1]) <= TOL  # a batch of one: the batch axis is dynamic


def obs_from_mujoco(meta: dict, data: mujoco.MjData, ground: float = 0.0) -> np.ndarray:
    """The observation as the file's metadata describes it, from a MuJoCo C ``MjData`` on flat ground at
    ``ground`` m: what a user driving the robot outside jaxterrain computes."""
    blocks = {b["name"]: b for b in meta["observation"]["layout"]}
    assert list(blocks) == ["torso_height", "torso_quat", "joint_pos", "root_linvel", "root_angvel", "joint_vel"]
    return np.concatenate([[data.qpos[2] - ground], data.qpos[3:], data.qvel]).astype(np.float32)


@pytest.mark.parametrize("name", ["humanoid", "ant"])
def test_real_observations_match_and_the_metadata_drives_the_robot_in_plain_mujoco(exported, name):
    """The env's reset observations are the layout the metadata names; the file's actions match JAX on them and
    along a 100-step walk in MuJoCo's C engine driven only by the metadata (ctrl mapping, control dt), where the
    robot stays up (torso height inside the walker's healthy range)."""
    policy, path = exported[name]
    meta = rl.read_onnx_metadata(path)
    config = rl_onnx.walker_config_of(policy.meta)
    env = WalkerEnv(config)
    reset = jax.jit(env.reset)  # one compile (~5 s on a CPU), four resets
    states = [reset(key, env.flat_terrain()) for key in jax.random.split(jax.random.key(0), 4)]
    m = env.mj_model
    d = mujoco.MjData(m)
    for state in states:  # the layout: torso height, quaternion, joint angles, qvel, from qpos / qvel alone
        d.qpos[:], d.qvel[:] = np.asarray(state.data.qpos), np.asarray(state.data.qvel)
        np.testing.assert_allclose(obs_from_mujoco(meta, d), np.asarray(state.obs), atol=1e-6)
    assert max_diff(policy, path, np.stack([s.obs for s in states])) <= TOL

    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    lo, hi = np.asarray(meta["action"]["ctrlrange"], np.float32).T
    n_frames = round(meta["control"]["dt"] / m.opt.timestep)
    assert n_frames == config.n_frames and m.opt.timestep == pytest.approx(meta["control"]["timestep"])
    d.qpos[:], d.qvel[:] = np.asarray(states[0].data.qpos), np.asarray(states[0].data.qvel)
    mujoco.mj_forward(m, d)
    seen = []
    for _ in range(100):
        obs = obs_from_mujoco(meta, d)
        seen.append(obs)
        action = session.run(["action"], {"obs": obs[None]})[0][0]
        d.ctrl[:] = lo + (np.clip(action, -1, 1) + 1) * (hi - lo) / 2
        for _ in range(n_frames):
            mujoco.mj_step(m, d)
    low, high = meta["walker_config"]["healthy_z_range"]
    assert low < d.qpos[2] < high, f"{name} fell in plain MuJoCo: torso at {d.qpos[2]:.2f} m"
    assert max_diff(policy, path, np.stack(seen)) <= TOL


def test_metadata_names_the_robot_layout_action_mapping_control_step_and_provenance(exported):
    for name in ("humanoid", "ant"):
        policy, path = exported[name]
        meta = rl.read_onnx_metadata(path)
        env = WalkerEnv(rl_onnx.walker_config_of(policy.meta))
        m = env.mj_model
        assert meta["format"] == rl_onnx.ONNX_FORMAT and meta["robot"] == name
        obs = meta["observation"]
        assert obs["size"] == policy.observation_size == env.observation_size == len(obs["names"])
        assert [b["start"] for b in obs["layout"]] == list(np.cumsum([0] + [b["size"] for b in obs["layout"]])[:-1])
        assert obs["normalised_in_graph"] is True
        np.testing.assert_array_equal(np.float32(obs["mean"]), np.asarray(policy.normaliser.mean))
        np.testing.assert_array_equal(np.float32(obs["std"]), np.asarray(nets.stats_std(policy.normaliser)))
        act = meta["action"]
        assert act["size"] == policy.action_size == m.nu and act["range"] == [-1.0, 1.0]
        np.testing.assert_array_equal(np.float32(act["ctrlrange"]), m.actuator_ctrlrange.astype(np.float32))
        assert [a["joint"] for a in act["actuators"]] == [m.joint(int(j)).name for j in m.actuator_trnid[:, 0]]
        assert meta["control"] == {"dt": pytest.approx(env.dt), "timestep": 0.003, "n_frames": 5}
        assert meta["height_scan"] is None and meta["walker_config"]["robot"] == name
        prov = meta["provenance"]
        assert prov["source"] == f"<jaxterrain>/assets/{POLICIES[name].name}"
        assert prov["policy_config"]["provenance"] == policy.meta["provenance"]
        assert prov["commit"] and prov["opset"] == rl_onnx.OPSET
        assert meta["verification"]["max_abs_diff"] <= TOL and meta["verification"]["observations"] == 64
    humanoid = rl.read_onnx_metadata(exported["humanoid"][1])["action"]["actuators"]
    assert [a["joint"] for a in humanoid[:2]] == ["abdomen_y", "abdomen_z"]  # actuator order is not joint order
    trained = rl.read_onnx_metadata(exported["trained"][1])
    assert trained["robot"] == "humanoid" and "curriculum" in trained["provenance"]["policy_config"]


def test_the_graph_has_a_dynamic_or_fixed_batch_and_the_same_policy_exports_the_same_bytes(exported, tmp_path):
    policy, path = exported["ant"]
    dims = lambda p: [[d.dim_param or d.dim_value for d in v.type.tensor_type.shape.dim]  # noqa: E731
                      for v in (*onnx.load(str(p)).graph.input, *onnx.load(str(p)).graph.output)]
    assert dims(path) == [["batch", 27], ["batch", 8]]
    fixed = rl.export_onnx(policy, tmp_path / "fixed.onnx", batch=3)
    assert dims(fixed) == [[3, 27], [3, 8]]
    assert rl.read_onnx_metadata(fixed)["verification"]["observations"] == 3
    again = rl.export_onnx(POLICIES["ant"], tmp_path / "again.onnx")
    assert again.read_bytes() == path.read_bytes()


def synthetic_policy(folder, activation, distribution, normalise, height_scan):
    """A policy of the given network with random numpy parameters and statistics, saved for a walker (no training,
    nothing compiled): every branch of the graph."""
    config = PPOConfig(activation=activation, action_distribution=distribution, normalize_observations=normalise,
                       policy_hidden=(8, 8), value_hidden=(4,))
    env_obs = 45 + (40 if height_scan else 0)
    rng = np.random.default_rng(3)
    shapes = jax.eval_shape(lambda: nets.init_params(jax.random.key(0), config, env_obs, 17))
    params = jax.tree_util.tree_map(lambda s: (rng.standard_normal(s.shape) / np.sqrt(max(s.shape[0], 1)))
                                    .astype(np.float32), shapes)  # means beyond [-1, 1] too: the clip matters
    stats = nets.RunningStats(np.float32(32), (1 + rng.standard_normal(env_obs)).astype(np.float32),
                              (32 * rng.uniform(0.5, 4, env_obs)).astype(np.float32))
    return rl.save_policy(folder, params, stats, config, env_obs, 17, actor_only=True,
                          extra={"walker_config": {"observation": "perceptive", "scan_x": [0.0, 1.4],
                                                            "scan_y": [-0.4, 0.4], "scan_points": [8, 5]}
                                 if height_scan else {"height_scan": False}})  # blind: the old record still reads


@pytest.mark.parametrize("activation,distribution,normalise,height_scan", [
    ("swish", "normal", True, True), ("relu", "tanh_normal", False, False), ("tanh", "normal", True, False),
    ("elu", "tanh_normal", True, False)])
def test_every_network_form_exports_and_matches(tmp_path, activation, distribution, normalise, height_scan):
    folder = synthetic_policy(tmp_path / "p", activation, distribution, normalise, height_scan)
    path = rl.export_onnx(folder, tmp_path / "p.onnx")
    policy = rl.load_policy(folder)
    z = np.random.default_rng(2).standard_normal((64, policy.observation_size)).astype(np.float32) * 4
    assert max_diff(policy, path, z) <= TOL
    meta = rl.read_onnx_metadata(path)
    assert meta["network"] == {"policy_hidden": [8, 8], "activation": activation, "action_distribution": distribution,
                               "normalize_observations": normalise}
    assert meta["observation"]["normalised_in_graph"] is normalise and (meta["observation"]["mean"] is None) != normalise
    if height_scan:
        assert meta["height_scan"] == {"scan_x": [0.0, 1.4], "scan_y": [-0.4, 0.4], "scan_points": [8, 5]}
        block = meta["observation"]["layout"][-1]
        assert (block["name"], block["start"], block["size"]) == ("height_scan", 45, 40)
        assert meta["observation"]["names"][45] == "scan:0.000,-0.400"
    else:
        assert meta["height_scan"] is None


def test_a_policy_that_does_not_fit_its_walker_a_bad_batch_and_a_failed_check_write_nothing(tmp_path, monkeypatch):
    folder = synthetic_policy(tmp_path / "p", "swish", "tanh_normal", True, False)
    config = json.loads((folder / "config.json").read_text())
    config["walker_config"] = {"robot": "ant"}  # 45 observations, 17 actions: not the ant's
    (folder / "config.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match="its walker \\(ant"):
        rl.export_onnx(folder, tmp_path / "a.onnx")
    with pytest.raises(ValueError, match="batch must be None"):
        rl.export_onnx(POLICIES["ant"], tmp_path / "b.onnx", batch=0)
    real = rl_onnx.run_onnx
    monkeypatch.setattr(rl_onnx, "run_onnx", lambda model, obs: real(model, obs) + 1e-3)
    with pytest.raises(RuntimeError, match="differ from the JAX policy's by 0.001"):
        rl.export_onnx(POLICIES["ant"], tmp_path / "c.onnx")
    assert not list(tmp_path.glob("*.onnx"))


def test_without_the_extra_one_line_names_it(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "onnx", None)
    with pytest.raises(ImportError, match=r"^ONNX export needs the onnx extra: pip install 'jaxterrain\[onnx\]'$"):
        rl.export_onnx(POLICIES["ant"], tmp_path / "a.onnx")
    assert not (tmp_path / "a.onnx").exists()

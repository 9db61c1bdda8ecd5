"""ONNX export of a walker: the policy network and its observation normaliser in one graph, with what a user needs
to drive the robot elsewhere (MuJoCo in C, Isaac, hardware) in the file's metadata.

    path = export_onnx("runs/learn-x/policies/trial_0", "walker.onnx")     # or a load_policy() policy
    meta = read_onnx_metadata("walker.onnx")                              # {"robot": "humanoid", ...}

    import onnxruntime as ort                                            # plain numpy from here on
    session = ort.InferenceSession("walker.onnx")
    action = session.run(None, {"obs": obs})[0]                          # obs [B, O] float32 -> action [B, A]
    ctrl = lo + (action + 1) * (hi - lo) / 2                             # lo, hi: meta["action"]["ctrlrange"]

The graph (ONNX opset :data:`OPSET`): input ``obs [batch, O]`` float32, the raw observation of
:class:`~jaxterrain.walker.WalkerEnv` (physical units, no scaling by the user); ``(obs - mean) / std`` with the
normaliser's statistics as constants (when ``PPOConfig.normalize_observations``); the policy MLP (``Dense`` =
``MatMul`` + ``Add``, the activation between layers); the deterministic action, ``tanh`` of the Gaussian's mean
(``tanh_normal``) or its mean clipped to [-1, 1] (``normal``); output ``action [batch, A]`` in [-1, 1], the same
action as :func:`jaxterrain.rl.load_policy`'s ``policy(obs)``. ``batch`` is a dynamic axis unless a fixed batch is
asked for. The graph is written from the policy's parameters with the ``onnx`` package's helpers (no JAX tracing
tool), and by default checked with onnxruntime against the JAX policy before the file is written
(:data:`VERIFY_TOLERANCE`).

Metadata (``metadata_props``; every value a JSON string, :func:`read_onnx_metadata` decodes them):

- ``format``: :data:`ONNX_FORMAT`; ``robot``: the robot's name;
- ``observation``: ``size``, ``names`` (one per element), ``layout`` (blocks: name, start, size, unit, meaning),
  ``normalised_in_graph`` and the normaliser's ``mean`` / ``std`` (already applied inside the graph), ``clip``
  (the env clips every observation to [-1e4, 1e4]);
- ``action``: ``size``, ``range`` [-1, 1], ``actuators`` (per action element: actuator name, the joint it drives,
  ``ctrlrange``, gear), ``ctrlrange`` ([A, 2]) and ``ctrl`` (the mapping ``ctrl = lo + (a + 1) (hi - lo) / 2`` after
  clipping ``a`` to [-1, 1], as :meth:`WalkerEnv.step`);
- ``control``: ``dt`` (s per action = ``timestep * n_frames``), ``timestep``, ``n_frames``;
- ``height_scan``: the scan grid (``scan_x``, ``scan_y``, ``scan_points``) when the walker observes one, else null;
- ``walker_config``: the :class:`~jaxterrain.walker.WalkerConfig` the policy was trained in (robot defaults
  resolved);
- ``network``: hidden sizes, activation, action distribution;
- ``provenance``: the source folder (``<jaxterrain>/...`` for the shipped policies), the policy's ``config.json``
  without its ``ppo_config`` (its training provenance, curriculum, ...), the exporting jaxterrain's version and git
  commit, the onnx version and opset;
- ``verification``: onnxruntime's version and the largest absolute difference from the JAX policy over the checked
  observations (null when not checked).

No date is written: exporting the same policy with the same code gives the same bytes.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Callable, Optional

import jax
import mujoco
import numpy as np

from jaxterrain.rl import networks as nets
from jaxterrain.rl.checkpoint import load_policy
from jaxterrain.runtime import provenance
from jaxterrain.runtime.io import atomic_write_bytes
from jaxterrain.terrain import TerrainScale
from jaxterrain.walker.config import WalkerConfig, resolve_config
from jaxterrain.walker.model import SolverOptions, build_model
from jaxterrain.walker.randomisation import randomisation_from_json, randomisation_json
from jaxterrain.walker.robots import get as get_robot

__all__ = ["ONNX_FORMAT", "OPSET", "VERIFY_TOLERANCE", "MISSING_EXTRA", "INPUT_NAME", "OUTPUT_NAME", "onnx_modules",
           "walker_config_of", "observation_layout", "action_layout", "onnx_metadata", "policy_graph", "export_onnx",
           "read_onnx_metadata", "run_onnx"]

ONNX_FORMAT = "jaxterrain.onnx/1"
OPSET = 17
VERIFY_TOLERANCE = 1e-5
"""Largest absolute difference in an action element allowed between onnxruntime and the JAX policy."""
MISSING_EXTRA = "ONNX export needs the onnx extra: pip install 'jaxterrain[onnx]'"
INPUT_NAME, OUTPUT_NAME = "obs", "action"
OBS_CLIP = 1e4  # WalkerEnv._obs clips every observation to [-OBS_CLIP, OBS_CLIP]


def onnx_modules(runtime: bool = False):
    """``onnx`` (and ``onnxruntime`` with ``runtime``), the optional extra ``jaxterrain[onnx]``; ``ImportError``
    with :data:`MISSING_EXTRA` (one line) where they are not installed."""
    try:
        import onnx
        if runtime:
            import onnxruntime
            return onnx, onnxruntime
    except ImportError:
        raise ImportError(MISSING_EXTRA) from None
    return onnx


# ----------------------------------------------------------------------------------------------------------------
# The walker a policy drives: observation and action layout
# ----------------------------------------------------------------------------------------------------------------
def walker_config_of(meta: dict) -> WalkerConfig:
    """The :class:`WalkerConfig` recorded in a policy's ``config.json`` (``meta["walker_config"]``; absent: the
    defaults, the humanoid), robot defaults resolved. ``ValueError`` naming a field that is not a WalkerConfig's."""
    recorded = dict(meta.get("walker_config") or {})
    if "height_scan" in recorded:  # the observation set's old name (policies saved before observation sets)
        recorded.setdefault("observation", "perceptive" if recorded.pop("height_scan") else "blind")
    unknown = sorted(set(recorded) - set(WalkerConfig._fields))
    if unknown:
        raise ValueError(f"walker_config: unknown field(s) {', '.join(unknown)} (WalkerConfig has "
                         f"{', '.join(WalkerConfig._fields)})")
    kwargs: dict[str, Any] = {}
    for key, value in recorded.items():
        if key == "scale":
            value = TerrainScale(**value)
        elif key == "solver":
            value = SolverOptions(**value)
        elif key == "randomisation":
            value = randomisation_from_json(value)
        elif isinstance(value, list):
            value = tuple(value)
        kwargs[key] = value
    return resolve_config(WalkerConfig(**kwargs))


def _model(config: WalkerConfig) -> mujoco.MjModel:
    return build_model(config.terrain_shape, config.scale, config.solver, config.timestep, get_robot(config.robot))


def observation_layout(config: WalkerConfig, model: Optional[mujoco.MjModel] = None) -> dict:
    """The observation of :class:`~jaxterrain.walker.WalkerEnv` for ``config``: ``{"size", "names" [O], "layout"
    [blocks]}`` (each block ``{"name", "start", "size", "unit", "meaning"}``), in the order ``WalkerEnv._obs``
    concatenates them. ``model``: the robot's MjModel (built from ``config`` when None)."""
    m = _model(config) if model is None else model
    joints = [m.joint(j).name or f"joint_{j}" for j in range(1, m.njnt)]
    blocks = [
        ("torso_height", ["torso_height"], "m",
         "torso z minus the terrain height under the torso (a flat floor at 0: the torso's z)"),
        ("torso_quat", ["torso_quat_w", "torso_quat_x", "torso_quat_y", "torso_quat_z"], "1",
         "torso orientation, MuJoCo's qpos[3:7] (w, x, y, z), world frame"),
        ("joint_pos", [f"joint_pos:{n}" for n in joints], "rad", "hinge joint angles, qpos[7:], in the model's joint order"),
        ("root_linvel", ["root_vel_x", "root_vel_y", "root_vel_z"], "m/s",
         "free joint's linear velocity, qvel[0:3] (MuJoCo: world frame)"),
        ("root_angvel", ["root_angvel_x", "root_angvel_y", "root_angvel_z"], "rad/s",
         "free joint's angular velocity, qvel[3:6] (MuJoCo: torso's local frame)"),
        ("joint_vel", [f"joint_vel:{n}" for n in joints], "rad/s", "hinge joint velocities, qvel[6:]"),
    ]
    if config.observation == "perceptive":
        nx, ny = config.scan_points
        xs, ys = np.linspace(*config.scan_x, nx), np.linspace(*config.scan_y, ny)
        blocks.append(("height_scan", [f"scan:{x:.3f},{y:.3f}" for x in xs for y in ys], "m",
                       f"terrain height minus torso z at {nx} x {ny} points (x-major: x in scan_x, y in scan_y) in the "
                       "torso's heading frame (yaw only), relative to the torso's x, y"))
    layout, names, start = [], [], 0
    for name, items, unit, meaning in blocks:
        layout.append({"name": name, "start": start, "size": len(items), "unit": unit, "meaning": meaning})
        names += items
        start += len(items)
    return {"size": start, "names": names, "layout": layout}


def action_layout(config: WalkerConfig, model: Optional[mujoco.MjModel] = None) -> dict:
    """The action of :class:`~jaxterrain.walker.WalkerEnv` for ``config``: ``{"size", "range", "actuators" [A]
    (name, joint, ctrlrange, gear), "ctrlrange" [A, 2], "ctrl"}``, in the model's actuator order (which is not
    always the joint order: the humanoid's first two actuators drive abdomen_y, abdomen_z)."""
    m = _model(config) if model is None else model
    actuators = []
    for i in range(m.nu):
        joint = int(m.actuator_trnid[i, 0])
        actuators.append({"name": m.actuator(i).name, "joint": m.joint(joint).name,
                          "ctrlrange": [float(v) for v in np.asarray(m.actuator_ctrlrange[i], np.float32)],
                          "gear": float(m.actuator_gear[i, 0])})
    return {"size": int(m.nu), "range": [-1.0, 1.0], "actuators": actuators,
            "ctrlrange": [a["ctrlrange"] for a in actuators],
            "ctrl": "a = clip(action, -1, 1); ctrl = lo + (a + 1) * (hi - lo) / 2 per actuator (lo, hi = ctrlrange), "
                    "held for control.dt seconds (n_frames physics steps)"}


def _load(policy) -> Callable:
    """A :func:`load_policy` policy from a policy, a folder or a ``config.json`` / ``policy.msgpack`` path."""
    if callable(policy) and hasattr(policy, "params"):
        return policy
    if isinstance(policy, (str, os.PathLike)):
        return load_policy(policy)
    raise ValueError(f"policy must be a policy folder or a jaxterrain.rl.load_policy() policy; got "
                     f"{type(policy).__name__}")


def _network(policy) -> dict:
    c = policy.config
    return {"policy_hidden": [int(h) for h in c.policy_hidden], "activation": c.activation,
            "action_distribution": c.action_distribution,
            "normalize_observations": bool(c.normalize_observations)}


def _normaliser(policy) -> tuple[np.ndarray, np.ndarray]:
    """``(mean [O], std [O])`` float32 of the policy's observation normaliser (``stats_std``, as the JAX policy)."""
    stats = policy.normaliser
    return (np.asarray(jax.device_get(stats.mean), np.float32),
            np.asarray(jax.device_get(nets.stats_std(stats)), np.float32))


def onnx_metadata(policy, verification: Optional[dict] = None, base: str | os.PathLike | None = None) -> dict:
    """The metadata of :func:`export_onnx` as a dict of JSON-serialisable values (see the module docstring);
    ``policy``: a :func:`load_policy` policy or a policy folder. ``provenance.source`` is the policy's folder as
    ``<jaxterrain>/...`` (a shipped policy) or relative to ``base`` (the exported file's folder; None: the current
    folder). ``verification``: the result of the onnxruntime check, or None. ``ValueError`` where the policy's
    observation or action size is not its walker's."""
    policy = _load(policy)
    meta = dict(policy.meta or {})
    config = walker_config_of(meta)
    model = _model(config)
    obs, act = observation_layout(config, model), action_layout(config, model)
    if obs["size"] != policy.observation_size or act["size"] != policy.action_size:
        raise ValueError(f"{policy.path}: the policy takes {policy.observation_size} observations and gives "
                         f"{policy.action_size} actions, its walker ({config.robot}, observation="
                         f"{config.observation}) has {obs['size']} and {act['size']}")
    normalised = bool(policy.config.normalize_observations)
    mean, std = _normaliser(policy)
    obs.update({"dtype": "float32", "normalised_in_graph": normalised, "clip": [-OBS_CLIP, OBS_CLIP],
                "scaling": "raw physical units (see layout); the graph computes (obs - mean) / std itself"
                if normalised else "raw physical units (see layout); the policy was trained without normalisation",
                "mean": [float(v) for v in mean] if normalised else None,
                "std": [float(v) for v in std] if normalised else None})
    scan = ({"scan_x": list(config.scan_x), "scan_y": list(config.scan_y), "scan_points": list(config.scan_points)}
            if config.observation == "perceptive" else None)
    walker = config._asdict()
    walker["scale"], walker["solver"] = config.scale._asdict(), config.solver._asdict()
    randomised = randomisation_json(walker.pop("randomisation"))  # recorded only when on, as in config.json
    if randomised is not None:
        walker["randomisation"] = randomised
    path = getattr(policy, "path", None)
    source = {k: v for k, v in meta.items() if k != "ppo_config"}
    onnx = onnx_modules()
    return {
        "format": ONNX_FORMAT,
        "robot": config.robot,
        "observation": obs,
        "action": act,
        "control": {"dt": float(config.timestep * config.n_frames), "timestep": float(config.timestep),
                    "n_frames": int(config.n_frames)},
        "height_scan": scan,
        "walker_config": json.loads(json.dumps(walker)),
        "network": _network(policy),
        "provenance": {
            "source": provenance.portable_path(path, Path.cwd() if base is None else base) if path is not None
            else None,
            "policy_config": source,
            "jaxterrain": provenance.package_version(),
            "commit": provenance.git_commit(),
            "onnx": onnx.__version__,
            "opset": OPSET,
        },
        "verification": verification,
    }


# ----------------------------------------------------------------------------------------------------------------
# The graph
# ----------------------------------------------------------------------------------------------------------------
def policy_graph(policy, batch: Optional[int] = None):
    """The ONNX ``ModelProto`` of ``policy``'s deterministic action (no metadata): ``obs [batch, O]`` float32 ->
    ``action [batch, A]``; ``batch`` None: a dynamic axis named ``batch``, else that fixed size (>= 1)."""
    onnx = onnx_modules()
    from onnx import TensorProto, helper, numpy_helper

    policy = _load(policy)
    if batch is not None and (not isinstance(batch, (int, np.integer)) or isinstance(batch, bool) or batch < 1):
        raise ValueError(f"batch must be None (a dynamic batch axis) or an integer >= 1; got {batch!r}")
    c, size_a = policy.config, int(policy.action_size)
    layers = policy.params["policy"]["params"]["mlp"]
    n_layers = len(c.policy_hidden) + 1
    if sorted(layers) != sorted(f"hidden_{i}" for i in range(n_layers)):
        raise ValueError(f"policy network layers {sorted(layers)} are not the {n_layers} Dense layers of its config")
    inits, nodes = [], []

    def const(name, value):
        inits.append(numpy_helper.from_array(np.asarray(value, np.float32), name))
        return name

    x = INPUT_NAME
    if c.normalize_observations:
        mean, std = _normaliser(policy)
        nodes += [helper.make_node("Sub", [x, const("obs_mean", mean)], ["obs_centred"], name="normalise_sub"),
                  helper.make_node("Div", ["obs_centred", const("obs_std", std)], ["obs_normalised"],
                                   name="normalise_div")]
        x = "obs_normalised"
    for i in range(n_layers):
        layer = layers[f"hidden_{i}"]
        kernel = const(f"hidden_{i}.kernel", jax.device_get(layer["kernel"]))
        bias = const(f"hidden_{i}.bias", jax.device_get(layer["bias"]))
        nodes += [helper.make_node("MatMul", [x, kernel], [f"hidden_{i}.matmul"], name=f"hidden_{i}_matmul"),
                  helper.make_node("Add", [f"hidden_{i}.matmul", bias], [f"hidden_{i}.out"], name=f"hidden_{i}_add")]
        x = f"hidden_{i}.out"
        if i < n_layers - 1:
            out = f"hidden_{i}.act"
            if c.activation == "swish":  # flax nn.swish = x * sigmoid(x)
                nodes += [helper.make_node("Sigmoid", [x], [f"hidden_{i}.sigmoid"], name=f"hidden_{i}_sigmoid"),
                          helper.make_node("Mul", [x, f"hidden_{i}.sigmoid"], [out], name=f"hidden_{i}_swish")]
            elif c.activation == "relu":
                nodes.append(helper.make_node("Relu", [x], [out], name=f"hidden_{i}_relu"))
            elif c.activation == "tanh":
                nodes.append(helper.make_node("Tanh", [x], [out], name=f"hidden_{i}_tanh"))
            elif c.activation == "elu":
                nodes.append(helper.make_node("Elu", [x], [out], alpha=1.0, name=f"hidden_{i}_elu"))
            else:
                raise ValueError(f"activation {c.activation!r} has no ONNX form here (swish, relu, tanh, elu)")
            x = out
    if c.action_distribution == "tanh_normal":  # the MLP gives [loc, raw scale]: the action is tanh(loc)
        inits += [numpy_helper.from_array(np.array([v], np.int64), n)
                  for n, v in (("slice_start", 0), ("slice_end", size_a), ("slice_axis", -1))]
        nodes += [helper.make_node("Slice", [x, "slice_start", "slice_end", "slice_axis"], ["loc"], name="loc"),
                  helper.make_node("Tanh", ["loc"], [OUTPUT_NAME], name="squash")]
    elif c.action_distribution == "normal":
        nodes.append(helper.make_node("Clip", [x, const("action_lo", -1.0), const("action_hi", 1.0)], [OUTPUT_NAME],
                                      name="clip"))
    else:
        raise ValueError(f"action_distribution {c.action_distribution!r} has no ONNX form here (tanh_normal, normal)")
    dim = "batch" if batch is None else int(batch)
    graph = helper.make_graph(
        nodes, "jaxterrain_policy",
        [helper.make_tensor_value_info(INPUT_NAME, TensorProto.FLOAT, [dim, int(policy.observation_size)])],
        [helper.make_tensor_value_info(OUTPUT_NAME, TensorProto.FLOAT, [dim, size_a])], initializer=inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)], producer_name="jaxterrain",
                              producer_version=provenance.package_version())
    model.ir_version = min(model.ir_version, 8)  # opset 17's IR: onnxruntime releases since 1.13 read it
    onnx.checker.check_model(model, full_check=True)
    return model


def _check_observations(policy, n: int, seed: int = 0) -> np.ndarray:
    """``[n, O]`` float32 observations around the normaliser's statistics (mean + std * N(0, 1)), a fixed draw."""
    mean, std = _normaliser(policy)
    if not policy.config.normalize_observations:
        mean, std = np.zeros_like(mean), np.ones_like(std)
    z = np.random.default_rng(seed).standard_normal((n, mean.shape[0])).astype(np.float32)
    return (mean + std * z).astype(np.float32)


def run_onnx(model_or_path, obs: np.ndarray) -> np.ndarray:
    """``action [B, A]`` of an exported policy (a path or a ``ModelProto``) for ``obs [B, O]`` with onnxruntime on
    the CPU."""
    _, ort = onnx_modules(runtime=True)
    data = model_or_path.SerializeToString() if hasattr(model_or_path, "SerializeToString") else str(model_or_path)
    options = ort.SessionOptions()
    options.log_severity_level = 3
    session = ort.InferenceSession(data, options, providers=["CPUExecutionProvider"])
    return session.run([OUTPUT_NAME], {INPUT_NAME: np.asarray(obs, np.float32)})[0]


def export_onnx(policy, path: str | os.PathLike, batch: Optional[int] = None, verify: bool = True,
                verify_samples: int = 64) -> Path:
    """Write ``policy`` (a policy folder, a ``config.json`` / ``policy.msgpack`` in one, or a :func:`load_policy`
    policy; a shipped base policy: ``jaxterrain.rl.base_policy_dir("ant")``) to ``path`` as one
    ONNX file, atomically: the normaliser and the policy network in one graph, with the metadata of
    :func:`onnx_metadata`. ``batch``: None for a dynamic batch axis, else a fixed batch size.

    ``verify`` (default): before writing, run the graph with onnxruntime on ``verify_samples`` observations (a fixed
    draw around the normaliser's statistics) and compare with the JAX policy; ``RuntimeError`` when an action
    differs by more than :data:`VERIFY_TOLERANCE` (nothing is written), else the difference goes into the metadata.
    ``ImportError`` (:data:`MISSING_EXTRA`) without the onnx extra. Returns ``path``."""
    onnx_modules(runtime=verify)
    if not isinstance(verify_samples, (int, np.integer)) or isinstance(verify_samples, bool) or verify_samples < 1:
        raise ValueError(f"verify_samples must be an integer >= 1; got {verify_samples!r}")
    policy = _load(policy)
    path = Path(path)
    model = policy_graph(policy, batch)
    verification = None
    if verify:
        import onnxruntime

        n = int(verify_samples) if batch is None else int(batch)
        obs = _check_observations(policy, n)
        got = run_onnx(model, obs)
        want = np.asarray(jax.jit(policy)(obs))
        diff = float(np.max(np.abs(got - want)))
        if not diff <= VERIFY_TOLERANCE:
            raise RuntimeError(f"ONNX export of {policy.path}: onnxruntime's actions differ from the JAX policy's by "
                               f"{diff:.3g} > {VERIFY_TOLERANCE:g} over {n} observations; nothing written")
        verification = {"onnxruntime": onnxruntime.__version__, "observations": n, "max_abs_diff": diff,
                        "tolerance": VERIFY_TOLERANCE, "draw": "mean + std * N(0, 1) per element, numpy seed 0"}
    meta = onnx_metadata(policy, verification, base=path.parent)
    del model.metadata_props[:]
    for key, value in meta.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, json.dumps(value, sort_keys=True)
    model.doc_string = (f"jaxterrain walker policy ({meta['robot']}): obs [batch, {policy.observation_size}] float32 "
                        f"raw observation -> action [batch, {policy.action_size}] in [-1, 1]; normaliser inside. "
                        f"metadata_props hold JSON: observation, action, control, provenance.")
    return atomic_write_bytes(path, model.SerializeToString())


def read_onnx_metadata(path: str | os.PathLike) -> dict:
    """The metadata of an exported file (``metadata_props``, each value decoded from JSON)."""
    onnx = onnx_modules()
    model = onnx.load(str(path), load_external_data=False)
    return {p.key: json.loads(p.value) for p in model.metadata_props}


"""Physics randomisation of the walker (domain randomisation, as legged_gym / MuJoCo Playground do it): friction,
body masses, an added torso mass, motor strength, observation noise, action delay and pushes.

    cfg = WalkerConfig(randomisation=parse_randomisation("friction=0.5:1.25,push=1000:1"))
    cfg = WalkerConfig(randomisation=parse_randomisation("legged-gym"))       # a preset (PRESETS)
    env = WalkerEnv(cfg); state = env.reset(key, terrain)                     # state.random: this env's draws

A :class:`Randomisation` is a field of :class:`~jaxterrain.walker.WalkerConfig` (default: everything off, and then
the walker is exactly the unrandomised one: ``WalkerState.random`` is None, nothing is drawn, no model field is
replaced). Ranges are ``(low, high)`` pairs, drawn uniformly **per env at reset** from the reset key (a stream of its
own, ``fold_in(key, 2)``: the start pose of a key is the same with and without randomisation) and kept in the env
state (:class:`Draws`), so a walk is a pure function of its reset key:

- ``friction`` (scale, one per env): every geom's sliding friction times the draw. Both robots and the terrain have
  friction 1.0 and MuJoCo takes the larger of the two geoms', so the draw is the contact's friction coefficient
  itself (legged_gym's ``friction_range``).
- ``mass`` (scale, one per body and env): each body's mass and rotational inertia times its draw.
- ``added_mass`` (kg, one per env): added to the torso (its inertia scaled by the same ratio): legged_gym's
  ``added_mass_range`` on the base.
- ``motor`` (scale, one per env): every actuator's force times the draw (``actuator_gainprm`` and
  ``actuator_biasprm``, so the control and its cost are unchanged).
- ``obs_noise`` (std): Gaussian noise added to every observation entry, fresh at every env step (its key is
  ``fold_in`` of the env's ``seed`` and the step count: the observation stays a function of the state).
- ``delay`` (env steps, an integer range, one per env): the motors get the action given that many env steps
  earlier (0: this step's; before the first actions, zero actions).
- ``push_every`` / ``push_velocity``: every ``push_every`` env steps (0: never), at a phase drawn per env (as
  legged_gym's global step counter is unaligned with episodes), the torso's x and y velocities each get a uniform
  kick in ``[-push_velocity, push_velocity]`` m/s, after that step's physics (the next observation sees it).

Friction, masses and motors are model fields (``geom_friction``, ``body_mass``, ``body_inertia``,
``actuator_gainprm``, ``actuator_biasprm``) replaced per env inside ``step``: under ``jax.vmap`` the model is batched,
as brax's domain randomisation does. MJX-JAX takes it; MuJoCo Warp (``backend="warp"``) takes these five fields
batched too (MJX's Warp bridge, ``mujoco/mjx/warp/ffi.py``, passes a batched Model leaf as one value per world, and
MuJoCo Warp reads these fields as ``field[worldid % field.shape[0]]``; read from the sources, not run here). The
masses' derived constants (``body_invweight0``, ``dof_invweight0``, which set the constraints' regularisation) keep
their nominal values, as in brax and Playground.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["Randomisation", "Draws", "PRESETS", "SPEC_KEYS", "parse_randomisation", "check_randomisation",
           "is_active", "randomisation_json", "randomisation_from_json", "randomisation_label", "draw",
           "randomised_model", "delayed_action", "push", "noisy_obs"]

MAX_DELAY = 100  # env steps (1.5 s at the walker's 0.015 s): the delay buffer is this long at most


class Randomisation(NamedTuple):
    """Physics randomisation of the walker (all off by default; see the module docstring). Ranges ``(low, high)``
    are drawn uniformly per env at reset; None or 0 is off."""

    friction: Optional[tuple[float, float]] = None  # scale of every geom's sliding friction (= the coefficient)
    mass: Optional[tuple[float, float]] = None  # scale of each body's mass and inertia (a draw per body)
    added_mass: Optional[tuple[float, float]] = None  # kg added to the torso
    motor: Optional[tuple[float, float]] = None  # scale of every actuator's force
    obs_noise: float = 0.0  # std of Gaussian noise on every observation entry
    delay: tuple[int, int] = (0, 0)  # env steps between an action and the motors (integers, low <= high)
    push_every: int = 0  # env steps between pushes (0: no pushes)
    push_velocity: float = 0.0  # m/s: the largest kick of the torso's x and y velocity


class Draws(NamedTuple):
    """One env's randomisation (``WalkerState.random``; leading axes under vmap): ``seed`` [] uint32 (the stream
    of its observation noise and pushes), ``friction`` [] and ``motor`` [] scales, ``mass`` [nbody] scales (the
    added torso mass included), ``delay`` [] int32 env steps, ``actions`` [max delay, A] the last actions given
    (newest first), ``push_phase`` [] int32 (a push after the steps ``s`` with ``(s + push_phase) % push_every ==
    0``)."""

    seed: jax.Array
    friction: jax.Array
    mass: jax.Array
    motor: jax.Array
    delay: jax.Array
    actions: jax.Array
    push_phase: jax.Array


PRESETS = {
    "legged-gym": Randomisation(friction=(0.5, 1.25), added_mass=(-1.0, 1.0), push_every=1000, push_velocity=1.0),
}
"""Named randomisations (``--randomise NAME``). ``legged-gym``: legged_gym's ``LeggedRobotCfg.domain_rand``
(friction 0.5-1.25, base mass +-1 kg, a push every 15 s of up to 1 m/s on each horizontal axis), mapped to this
walker: friction as the contact coefficient (both robots' geoms and the terrain have 1.0), the mass on the torso,
15 s = 1000 env steps of 0.015 s (the humanoid's whole episode, so a walk that lasts its 1000 steps is pushed once,
at a random time) and the push added to the torso's velocity (legged_gym sets the base's velocity to the draw).
legged_gym leaves the base mass off by default (``randomize_base_mass = False``); its range is used here."""

SPEC_KEYS = {"friction": "friction", "mass": "mass", "added-mass": "added_mass", "motor": "motor",
             "obs-noise": "obs_noise", "delay": "delay", "push": "push"}
"""``--randomise`` keys and the :class:`Randomisation` fields they set (``push=EVERY:VELOCITY`` sets two)."""


def _bad(name: str, want: str, value) -> ValueError:
    return ValueError(f"randomisation.{name} must be {want}, got {value!r}")


def _range(name: str, value, lo: float, lo_open: bool, want: str) -> tuple[float, float]:
    try:
        if isinstance(value, (str, bytes)) or len(value) != 2:
            raise TypeError
        a, b = (float(v) for v in value)
        if any(isinstance(v, (bool, np.bool_, str, bytes)) for v in value):
            raise TypeError
    except (TypeError, ValueError):
        raise _bad(name, want, value) from None
    if not (math.isfinite(a) and math.isfinite(b) and a <= b and (a > lo if lo_open else a >= lo)):
        raise _bad(name, want, value)
    return a, b


def check_randomisation(r) -> Randomisation:
    """``r`` with its ranges as float (delay: int) tuples, or ``ValueError`` naming the field and what it allows
    (``randomisation.friction must be (low, high) with 0 < low <= high, ...``). The one check of a randomisation;
    :class:`~jaxterrain.walker.WalkerConfig` runs it (``added_mass`` against the robot's torso: ``WalkerEnv``)."""
    if not isinstance(r, Randomisation):
        raise ValueError(f"randomisation must be a walker.Randomisation, got {type(r).__name__}")
    out = {}
    for name, lo, lo_open, want in (("friction", 0.0, True, "(low, high) with 0 < low <= high (a scale of the "
                                     "friction coefficient, 1.0 here)"),
                                    ("mass", 0.0, True, "(low, high) with 0 < low <= high (a scale of each body's "
                                     "mass)"),
                                    ("added_mass", -math.inf, False, "(low, high) kg with low <= high, finite"),
                                    ("motor", 0.0, True, "(low, high) with 0 < low <= high (a scale of the motors' "
                                     "force)")):
        value = getattr(r, name)
        out[name] = None if value is None else _range(name, value, lo, lo_open, want)
    for name in ("obs_noise", "push_velocity"):
        value = getattr(r, name)
        try:
            ok = not isinstance(value, (bool, str, bytes)) and math.isfinite(float(value)) and float(value) >= 0
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise _bad(name, "a finite number >= 0" + (" (m/s)" if name == "push_velocity" else ""), value)
        out[name] = float(value)
    delay = r.delay
    try:
        ok = (not isinstance(delay, (str, bytes)) and len(delay) == 2
              and all(isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)) for v in delay)
              and 0 <= delay[0] <= delay[1] <= MAX_DELAY)
    except TypeError:
        ok = False
    if not ok:
        raise _bad("delay", f"(low, high) env steps, integers with 0 <= low <= high <= {MAX_DELAY}", delay)
    out["delay"] = (int(delay[0]), int(delay[1]))
    every = r.push_every
    if not isinstance(every, (int, np.integer)) or isinstance(every, (bool, np.bool_)) or every < 0:
        raise _bad("push_every", "an integer >= 0 (env steps between pushes; 0: none)", every)
    out["push_every"] = int(every)
    if (out["push_every"] > 0) != (out["push_velocity"] > 0):
        raise ValueError(f"randomisation.push_every and push_velocity must both be > 0 (pushes) or both 0 (none), "
                         f"got {every!r} and {r.push_velocity!r}")
    return Randomisation(**out)


def is_active(r: Randomisation) -> bool:
    """Whether ``r`` randomises anything (the default :class:`Randomisation` does not)."""
    return r != Randomisation()


def _number(key: str, text: str, part: str) -> float:
    try:
        v = float(part)
    except ValueError:
        raise ValueError(f"item {key}={text}: {part!r} is not a number") from None
    return v


def _pair(key: str, text: str) -> tuple[float, float]:
    parts = text.split(":")
    if len(parts) == 1:
        parts = parts * 2
    if len(parts) != 2:
        raise ValueError(f"item {key}={text}: give LOW:HIGH (or one value)")
    return _number(key, text, parts[0]), _number(key, text, parts[1])


def parse_randomisation(spec) -> Randomisation:
    """A :class:`Randomisation` from a ``--randomise`` spec: comma-separated items, each a preset name
    (:data:`PRESETS`; ``off`` / ``none``: nothing) or ``KEY=VALUE``, later items overriding earlier ones:
    ``friction=LOW:HIGH``, ``mass=LOW:HIGH``, ``added-mass=LOW:HIGH`` (kg), ``motor=LOW:HIGH``, ``obs-noise=STD``,
    ``delay=N`` or ``delay=LOW:HIGH`` (env steps), ``push=EVERY:VELOCITY`` (env steps, m/s); a single value of a
    range is that value at both ends. E.g. ``friction=0.5:1.25,mass=0.9:1.1,motor=0.9:1.1,obs-noise=0.01,delay=1,
    push=200:0.5`` or ``legged-gym,obs-noise=0.01``. None or a Randomisation is returned checked. ``ValueError``
    naming the item or field otherwise (one line)."""
    if spec is None:
        return Randomisation()
    if isinstance(spec, Randomisation):
        return check_randomisation(spec)
    if not isinstance(spec, str) or not spec.strip():
        raise ValueError(f"a randomisation spec is a preset ({', '.join(PRESETS)}, off) or KEY=VALUE items "
                         f"({', '.join(SPEC_KEYS)}), got {spec!r}")
    fields = Randomisation()._asdict()
    for item in spec.split(","):
        item = item.strip()
        if item in ("off", "none"):
            fields = Randomisation()._asdict()
            continue
        if item in PRESETS:
            fields.update({k: v for k, v in PRESETS[item]._asdict().items() if v != getattr(Randomisation(), k)})
            continue
        key, eq, value = item.partition("=")
        if not eq or key not in SPEC_KEYS:
            raise ValueError(f"unknown item {item!r}; give a preset ({', '.join(PRESETS)}, off) or KEY=VALUE with "
                             f"KEY one of {', '.join(SPEC_KEYS)}")
        if key == "obs-noise":
            fields["obs_noise"] = _number(key, value, value)
        elif key == "delay":
            lo, hi = _pair(key, value)
            if lo != int(lo) or hi != int(hi):
                raise ValueError(f"item delay={value}: env steps are integers")
            fields["delay"] = (int(lo), int(hi))
        elif key == "push":
            every, velocity = _pair(key, value) if ":" in value else (None, None)
            if every is None or every != int(every):
                raise ValueError(f"item push={value}: give EVERY:VELOCITY (an integer of env steps, m/s)")
            fields["push_every"], fields["push_velocity"] = int(every), velocity
        else:
            fields[SPEC_KEYS[key]] = _pair(key, value)
    return check_randomisation(Randomisation(**fields))


def randomisation_json(r: Randomisation) -> Optional[dict]:
    """``r`` as a JSON object (ranges as lists), or None when it randomises nothing (policy files and run configs
    then carry no ``randomisation`` key: those written before it existed read the same)."""
    if not is_active(r):
        return None
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in r._asdict().items()}


def randomisation_from_json(value) -> Randomisation:
    """Inverse of :func:`randomisation_json` (None: off); ``ValueError`` naming an unknown field or a bad value."""
    if value is None:
        return Randomisation()
    if not isinstance(value, dict):
        raise ValueError(f"walker_config.randomisation must be a JSON object of Randomisation fields, got {value!r}")
    unknown = sorted(set(value) - set(Randomisation._fields))
    if unknown:
        raise ValueError(f"walker_config.randomisation: unknown field(s) {', '.join(unknown)} (Randomisation has "
                         f"{', '.join(Randomisation._fields)})")
    return check_randomisation(Randomisation(**{k: tuple(v) if isinstance(v, list) else v for k, v in value.items()}))


def randomisation_label(r: Randomisation) -> str:
    """One line: ``off`` or the active fields, e.g. ``friction 0.5-1.25, push every 1000 steps at 1 m/s``."""
    if not is_active(r):
        return "off"
    parts = []
    for name, unit in (("friction", ""), ("mass", ""), ("added_mass", " kg"), ("motor", "")):
        v = getattr(r, name)
        if v is not None:
            parts.append(f"{name.replace('_', ' ')} {v[0]:g}-{v[1]:g}{unit}")
    if r.obs_noise:
        parts.append(f"obs noise {r.obs_noise:g}")
    if r.delay != (0, 0):
        parts.append(f"delay {r.delay[0]}" + ("" if r.delay[0] == r.delay[1] else f"-{r.delay[1]}") + " steps")
    if r.push_every:
        parts.append(f"push every {r.push_every} steps at {r.push_velocity:g} m/s")
    return ", ".join(parts)


# ----------------------------------------------------------------------------------------------------------------
# Inside the env (pure, per env; vmap adds the env axes)
# ----------------------------------------------------------------------------------------------------------------
def draw(key: jax.Array, r: Randomisation, nbody: int, torso: int, torso_mass: float, action_size: int) -> Draws:
    """One env's :class:`Draws` from ``key`` (the reset key's randomisation stream). ``torso``: the torso's body id,
    ``torso_mass`` its nominal mass (kg). Off fields draw nothing (their scale is 1)."""
    k_seed, k_fric, k_mass, k_add, k_motor, k_delay, k_phase = jax.random.split(key, 7)
    one = jnp.ones((), jnp.float32)

    def uniform(k, rng, shape=()):
        return jax.random.uniform(k, shape, jnp.float32, minval=rng[0], maxval=rng[1])

    mass = jnp.ones((nbody,), jnp.float32)
    if r.mass is not None:
        mass = uniform(k_mass, r.mass, (nbody,))
    if r.added_mass is not None:
        mass = mass.at[torso].multiply(1.0 + uniform(k_add, r.added_mass) / torso_mass)
    lo, hi = r.delay
    return Draws(seed=jax.random.bits(k_seed, (), jnp.uint32),
                 friction=one if r.friction is None else uniform(k_fric, r.friction),
                 mass=mass,
                 motor=one if r.motor is None else uniform(k_motor, r.motor),
                 delay=jax.random.randint(k_delay, (), lo, hi + 1, jnp.int32),
                 actions=jnp.zeros((hi, action_size), jnp.float32),
                 push_phase=(jax.random.randint(k_phase, (), 0, r.push_every, jnp.int32) if r.push_every
                             else jnp.zeros((), jnp.int32)))


def randomised_model(m, d: Draws, r: Randomisation):
    """The mjx.Model ``m`` with this env's friction, masses and motor strength (only the fields ``r`` randomises
    are replaced, so an env without them steps the shared model)."""
    fields = {}
    if r.friction is not None:
        fields["geom_friction"] = m.geom_friction.at[:, 0].multiply(d.friction)
    if r.mass is not None or r.added_mass is not None:
        fields["body_mass"] = m.body_mass * d.mass
        fields["body_inertia"] = m.body_inertia * d.mass[:, None]
    if r.motor is not None:
        fields["actuator_gainprm"] = m.actuator_gainprm.at[:, :3].multiply(d.motor)
        fields["actuator_biasprm"] = m.actuator_biasprm.at[:, :3].multiply(d.motor)
    return m.replace(**fields) if fields else m


def delayed_action(d: Draws, action: jax.Array) -> tuple[jax.Array, Draws]:
    """``(the action the motors get [A], d with action pushed into its buffer)``: the action given ``d.delay`` env
    steps ago (this one for a delay of 0)."""
    if d.actions.shape[0] == 0:
        return action, d
    past = jnp.concatenate([action[None], d.actions], axis=0)  # [hi + 1, A], index k: k steps ago
    applied = jax.lax.dynamic_index_in_dim(past, d.delay, axis=0, keepdims=False)
    return applied, d._replace(actions=past[:-1])


def _key(d: Draws, steps: jax.Array, stream: int) -> jax.Array:
    return jax.random.fold_in(jax.random.fold_in(jax.random.PRNGKey(stream), d.seed), steps)


def push(qvel: jax.Array, d: Draws, steps: jax.Array, r: Randomisation) -> jax.Array:
    """``qvel`` with the torso's x, y velocity kicked when ``steps`` (env steps since reset, this one counted) is a
    push step of this env."""
    if not r.push_every:
        return qvel
    now = (steps + d.push_phase) % r.push_every == 0
    kick = jax.random.uniform(_key(d, steps, 0x9054), (2,), jnp.float32, -r.push_velocity, r.push_velocity)
    return qvel.at[:2].add(jnp.where(now, kick, 0.0).astype(qvel.dtype))


def noisy_obs(obs: jax.Array, d: Draws, steps: jax.Array, r: Randomisation) -> jax.Array:
    """``obs`` [O] plus Gaussian noise of std ``r.obs_noise`` (fresh at every env step), clipped to +-1e4 as the
    walker's observations are."""
    if not r.obs_noise:
        return obs
    noise = r.obs_noise * jax.random.normal(_key(d, steps, 0x0B5E), obs.shape, jnp.float32)
    return jnp.clip(obs + noise, -1e4, 1e4)

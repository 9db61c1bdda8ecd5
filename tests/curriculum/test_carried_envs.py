"""The trials' env states carried from one curriculum block to the next (and into checkpoints) keep one structure and
shape in and out of a block, on MJX-JAX and on MuJoCo Warp.

MuJoCo Warp's ``mjx.Data`` holds buffers shared by every env of a physics call (contacts ``[naconmax, ...]``,
``nacon``, ...) that ``jax.vmap`` leaves unbatched; a block cuts its states row by row (members concatenated, the
running rows gathered, members sliced out again), so those buffers came back cut to ``[trials, ...]`` and the next
call of the same compiled block was refused (2026-11-29, H200: ``float32[240000]`` compiled, ``float32[10]`` given).
``walker.carry_rows`` puts them on the row axis, empty. Pure-JAX tests here (a stand-in for Warp's Data, no physics);
the Warp block itself, traced with ``jax.eval_shape`` at tiny size, where warp-lang imports (slow).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.interpreters import batching

from jaxterrain.curriculum import run_config, runner
from jaxterrain.curriculum.checkpoints import restore_states
from jaxterrain.curriculum.population import run_population
from jaxterrain.runtime import driver
from jaxterrain.walker import carry_rows, warp_available

from curriculum_archives import tiny_archive_file, tree_equal


@jax.tree_util.register_dataclass
@dataclasses.dataclass
class Buffers:
    """A stand-in for MuJoCo Warp's ``Data._impl``: ``own`` per env, ``shared`` by every env (vmap passes it whole,
    as MJX's ``DATA_NON_VMAP`` fields)."""

    own: jax.Array
    shared: jax.Array


batching.register_vmappable(Buffers, int, int, lambda cont, _, d, axis: Buffers(cont(d.own, axis), d.shared),
                            lambda cont, size, d, axis: Buffers(cont(size, d.own, axis), d.shared), None)


def _shapes(tree):
    return [(tuple(x.shape), str(x.dtype)) for x in jax.tree.leaves(tree)]


def _block_rows(members, rows=None):
    """What a population block does to its carried states, row by row: the members concatenated, ``rows`` gathered
    and written back, each member sliced out again (``curriculum.population.run_population``)."""
    whole = jax.tree.map(lambda *xs: jnp.concatenate(xs), *members)
    if rows is not None:
        whole = jax.tree.map(lambda w, part: w.at[rows].set(part), whole, jax.tree.map(lambda x: x[rows], whole))
    edges = np.cumsum([0] + [jax.tree.leaves(m)[0].shape[0] for m in members])
    return [jax.tree.map(lambda x: x[int(a):int(b)], whole) for a, b in zip(edges[:-1], edges[1:])]


def test_carry_rows_puts_the_shared_buffers_on_the_row_axis():
    """MJX-JAX-like states (every leaf batched by vmap): ``carry_rows`` is vmap's broadcast, bit for bit. A Warp-like
    state: its own leaves broadcast, the shared buffer an empty ``[rows, 0, ...]`` of its dtype; then a block's
    row-wise concatenation, gathers and slices return every member's carried states with the shapes they came in
    with, where the broadcast form (the bug) comes back cut to the member's rows."""
    plain = {"qpos": jnp.arange(6.0).reshape(2, 3), "steps": jnp.array([1, 2], jnp.int32)}
    assert tree_equal(carry_rows(plain, 3), jax.vmap(lambda _: plain)(jnp.arange(3)))
    assert _shapes(carry_rows(plain, 3)) == _shapes(jax.vmap(lambda _: plain)(jnp.arange(3)))

    warp = {"obs": jnp.ones((2, 5)), "data": Buffers(jnp.arange(4.0).reshape(2, 2), jnp.zeros((6, 3), jnp.int32))}
    carried = carry_rows(warp, 3)
    assert carried["data"].shared.shape == (3, 0, 3) and carried["data"].shared.dtype == jnp.int32
    np.testing.assert_array_equal(carried["data"].own, np.broadcast_to(np.arange(4.0).reshape(2, 2), (3, 2, 2)))
    assert carried["obs"].shape == (3, 2, 5)
    assert _shapes(jax.eval_shape(functools.partial(carry_rows, rows=3), warp)) == _shapes(carried)

    members = [carry_rows(warp, 3), carry_rows(warp, 2)]
    for rows in (None, jnp.array([0, 2, 4], jnp.int32)):
        out = jax.eval_shape(_block_rows, members, rows)
        assert [_shapes(m) for m in out] == [_shapes(m) for m in members]
    broadcast = [jax.vmap(lambda _: warp)(jnp.arange(n)) for n in (3, 2)]  # the pre-fix form
    assert broadcast[0]["data"].shared.shape == (6, 3)
    cut = jax.eval_shape(_block_rows, broadcast, None)[0]["data"].shared
    assert cut.shape == (3, 3)  # refused by the compiled block's next call


class _Policy(NamedTuple):
    params: jax.Array
    env_state: dict


class _Trials(NamedTuple):
    done: jax.Array
    restart: jax.Array
    policy: _Policy


def _trials(params, qpos, contacts) -> _Trials:
    return _Trials(jnp.zeros(2, bool), jnp.zeros(2, bool), _Policy(jnp.asarray(params, jnp.float32),
                                                                    {"qpos": jnp.asarray(qpos, jnp.float32),
                                                                     "contacts": jnp.asarray(contacts, jnp.float32)}))


def test_a_checkpoint_of_env_states_in_another_form_restarts_them_on_a_tiled_walker(tmp_path):
    """``restore_states``: a checkpoint in the carried form comes back whole; one whose env states have other shapes
    (a MuJoCo Warp checkpoint of the cut form, ``contacts`` [2, 3]) comes back with everything else, its envs
    restarting (fresh env states, ``restart`` True, one line) on a tiled walker, and is refused on the classic one
    (MJX-JAX checkpoints read exactly as before); a leaf outside the env states that does not fit is refused
    everywhere."""
    fresh = _trials([0.0, 0.0], np.zeros((2, 4)), np.zeros((2, 0)))  # contacts: carry_rows' empty [2, 0]
    placement = {"trials": 2, "offset": 0}
    kept = _trials([1.0, 2.0], np.arange(8.0).reshape(2, 4), np.zeros((2, 0)))
    driver.write_checkpoint(tmp_path / "kept", kept, 3, {}, {"population": placement})
    lines = []
    s, done, _, _ = restore_states(tmp_path / "kept", fresh, placement, tiled=True, say=lines.append)
    assert done == 3 and tree_equal(s, kept) and not lines

    driver.write_checkpoint(tmp_path / "cut", kept._replace(policy=kept.policy._replace(
        env_state={**kept.policy.env_state, "contacts": jnp.ones((2, 3))})), 3, {}, {})
    s, done, _, _ = restore_states(tmp_path / "cut", fresh, placement, tiled=True, say=lines.append)
    assert done == 3 and tree_equal(s.policy.params, kept.policy.params)
    assert tree_equal(s.policy.env_state, fresh.policy.env_state) and np.all(np.asarray(s.restart))
    assert len(lines) == 1 and "another form" in lines[0] and "restart" in lines[0]
    with pytest.raises(ValueError, match="contacts"):
        restore_states(tmp_path / "cut", fresh, placement, tiled=False)

    driver.write_checkpoint(tmp_path / "other", kept._replace(policy=kept.policy._replace(
        params=jnp.ones(3))), 3, {}, {})
    with pytest.raises(ValueError, match="params"):
        restore_states(tmp_path / "other", fresh, placement, tiled=True, say=lines.append)


# ---------------------------------------------------------------------------------------------------------------
# MuJoCo Warp (where warp-lang imports; traced only, nothing runs)
# ---------------------------------------------------------------------------------------------------------------
def _flat(tree):
    return [(jax.tree_util.keystr(p), tuple(x.shape), str(x.dtype))
            for p, x in jax.tree_util.tree_flatten_with_path(tree)[0]]


@pytest.mark.slow
def test_a_warp_block_returns_the_env_states_it_takes(tmp_path):
    """On ``backend="warp"`` (the smoke preset on a 4-cell archive), traced with ``jax.eval_shape``: the solo
    runner's block (``runner.inputs`` + ``runner.make_block``) and a 2-treatment population's block
    (``run_population`` of two members' ``runner.inputs``, as ``batch`` compiles it; also on 2 gathered rows)
    return states with exactly the leaves, shapes and dtypes they take, MuJoCo Warp's shared contact buffers
    included. A carried state is not physics: ``WalkerEnv.step`` refuses it until merged into a reset state."""
    pytest.importorskip("warp")
    ok, why = warp_available()
    if not ok:
        pytest.skip(why)
    archive = tiny_archive_file(tmp_path, 4, "four.npz")

    def validated(trials, seed):
        run = run_config.PRESETS["smoke"]
        return runner.validate(run._replace(archive=archive, trials=trials, seed=seed,
                                            walker=run.walker._replace(backend="warp")))

    run, config, arch, policy, env = validated(2, 0)
    assert env.config.backend == "warp" and env.tiles == 2
    bank, _, harness, start, keys, init = runner.inputs(run, config, arch, policy, env)
    states = jax.eval_shape(init, keys, bank, start)
    assert _flat(jax.eval_shape(runner.make_block(config, harness), states, bank, jnp.int32(1))) == _flat(states)
    shared = states.policy.env_state.data._impl.contact__pos
    assert shared.shape == (2, 0, 3)  # carry_rows' form of the [naconmax, 3] buffer

    members = (validated(2, 0), validated(1, 1))
    env = runner.make_env(members[0][0]._replace(trials=3), members[0][2], members[0][3])  # the population's walker
    ins = [runner.inputs(r, c, a, p, env) for r, c, a, p, _ in members]
    states = tuple(jax.eval_shape(i[5], i[4], i[0], i[3]) for i in ins)
    banks = tuple(i[0] for i in ins)
    block = functools.partial(run_population, configs=tuple(m[1] for m in members), harness=ins[0][2])
    for rows in (None, jnp.array([0, 2], jnp.int32)):
        out = jax.eval_shape(block, states, banks, np.zeros(2, np.int32), rows)
        assert [_flat(s) for s in out] == [_flat(s) for s in states]

    reset = jax.vmap(env.reset, in_axes=(0, None))
    keys = jax.random.split(jax.random.key(0), 2)

    def step(carried: bool):
        tile = env.flat_bank().at(0)
        fresh = reset(keys, tile)
        state = jax.tree.map(lambda x: x[0], carry_rows(fresh, 1)) if carried else fresh
        return jax.vmap(env.step, in_axes=(0, 0, None))(state, jnp.zeros((2, env.action_size)), tile)

    with pytest.raises(ValueError, match="carried state"):
        jax.eval_shape(lambda: step(True))
    naconmax = env.config.warp_contacts * env.config.warp_worlds
    assert jax.eval_shape(lambda: step(False)).data._impl.contact__pos.shape == (naconmax, 3)


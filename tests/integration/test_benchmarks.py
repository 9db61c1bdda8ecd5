"""The pool model of benchmarks/rollout_order.py, whose step counts RESULTS.md reports; benchmarks/curriculum.py's parts
(slow)."""


import argparse

import numpy as np
import pytest

from benchmark_loader import load_benchmark

rollout_order = load_benchmark("rollout_order")


def test_pool_model_by_hand():
    lengths = np.array([10, 3, 3, 20])
    # 2 slots, refill every 8: job 0 holds slot A to 16; jobs 1, 2 take slot B at 0 and 8; job 3 starts at 16 -> 40
    assert rollout_order.pool_steps(lengths, np.arange(4), 2) == 40
    # longest first: job 3 on A until 24, job 0 on B until 16, job 1 at 16 -> 24, job 2 at 24 -> 32
    assert rollout_order.pool_steps(lengths, np.array([3, 0, 1, 2]), 2) == 32


def test_pool_model_bounds():
    rng = np.random.default_rng(0)
    lengths = rng.integers(1, 400, 5000)
    for slots in (64, 512, 8192):
        steps = rollout_order.pool_steps(lengths, np.arange(lengths.size), slots)
        assert steps % 8 == 0
        assert steps >= max(-(-lengths.sum() // slots), -(-lengths.max() // 8) * 8)
    # one slot per job: the longest rollout, rounded up to the refill interval
    assert rollout_order.pool_steps(lengths, np.arange(lengths.size), 10**6) == -(-lengths.max() // 8) * 8


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["jax", "warp"])
def test_curriculum_parts_on_the_learn_commands_layout(backend):
    """benchmarks/curriculum.py --parts times train and evaluate on the terrains as the block lays them out: one
    tile per trial and heading on Warp (it passed bare maps once, which only the classic layout accepts)."""
    from jaxterrain.walker import warp_available

    if backend == "warp" and not warp_available()[0]:
        pytest.skip(warp_available()[1])
    curriculum = load_benchmark("curriculum")
    args = argparse.Namespace(preset="smoke", archive=None, backend=backend, num_envs=None, num_unrolls=None, recipe=None,
                              robot=None, headings=2, chunks=1, parts=True, start=None)
    row = curriculum.measure_block(args, 2)
    assert row["chunks_done"] == 1 and row["chunk_reached"] == 2  # one timed chunk after an untimed one
    assert row["train_s_per_chunk"] > 0 and row["eval_s_per_chunk"] > 0
    assert 0.0 <= row["eval_fitness_mean"] <= 1.0
    assert row["train_seq_steps"] == 20  # smoke: 80 env steps a chunk = 1 update of 4 envs x unroll 10 x 2 unrolls
    if backend == "warp":
        assert 1 <= row["eval_seq_steps"] <= 100  # smoke episodes are 100 steps


@pytest.mark.slow
def test_curriculum_parts_from_restored_states():
    """benchmarks/curriculum.py --parts with --start's restored states times each trial's policy on its current
    terrain: trial states holding the base policy on terrains [0, 1] give the row of the default (the base policy on
    the bank's first terrains) exactly, on the CPU; after a chunk of the block (trained policies, the GP's picks) the
    row is another one."""
    import jax.numpy as jnp

    curriculum = load_benchmark("curriculum")
    args = argparse.Namespace(preset="smoke", archive=None, backend=None, num_envs=None, num_unrolls=None, recipe=None,
                              robot=None, headings=None)
    cfg = curriculum.learn_cfg(args, 2)
    run, config, arch, policy, env = curriculum.runner.validate(curriculum.run_config.from_flat(cfg))
    bank, block, states = curriculum.runner.setup(run, config, arch, policy, env)
    keys = ("eval_fitness_mean", "train_seq_steps")
    default = curriculum.measure_parts(cfg, config, bank, policy, env, 2)
    first = states._replace(terrain=jnp.arange(2, dtype=states.terrain.dtype) % bank.heightmaps.shape[0])
    assert np.all(np.asarray(states.chunk) == 0)  # the base policy, untrained
    same = curriculum.measure_parts(cfg, config, bank, policy, env, 2, first)
    assert {k: same[k] for k in keys} == {k: default[k] for k in keys}
    later = block(states, bank, 1)
    assert np.all(np.asarray(later.chunk) == 1)
    moved = curriculum.measure_parts(cfg, config, bank, policy, env, 2, later)
    assert 0.0 <= moved["eval_fitness_mean"] <= 1.0 and moved["eval_fitness_mean"] != default["eval_fitness_mean"]


@pytest.mark.slow
def test_curriculum_bare_ppo_on_a_tiled_walker(monkeypatch):
    """benchmarks/curriculum.py's bare-PPO peer runs on a tiled walker (Warp's layout; here MJX tiles, which
    ``--overlap`` brings): it once handed such an env an ``[H, W]`` array. Both truncation modes, labelled."""
    curriculum = load_benchmark("curriculum")
    plain = curriculum.learn_cfg
    monkeypatch.setattr(curriculum, "learn_cfg", lambda args, trials, overlap=False, truncation=None: plain(
        args, trials, True, truncation))  # overlap: the walker on tiles
    args = argparse.Namespace(preset="smoke", archive=None, backend=None, num_envs=None, num_unrolls=None, recipe=None,
                              robot=None, headings=None, repeats=1)
    for truncation in ("mask", "bootstrap"):
        row = curriculum.measure_ppo(args, truncation)
        assert row["truncation"] == truncation and row["env_steps_per_s"] > 0


@pytest.mark.parametrize("saved_overlap", [False, True])
def test_curriculum_start_reads_plain_and_overlapped_checkpoints(tmp_path, saved_overlap):
    """benchmarks/curriculum.py --start: a plain run's checkpoint or an --overlap run's (with its pending leaf)
    starts a plain block and an overlapped one. Stand-in states: a NamedTuple with the fields start_states uses."""
    from typing import NamedTuple

    import jax.numpy as jnp

    from jaxterrain.runtime import driver

    class S(NamedTuple):
        chunk: jnp.ndarray
        pending: object

    curriculum = load_benchmark("curriculum")
    saved = S(jnp.array([7, 9]), jnp.array([True, False]) if saved_overlap else None)
    driver.save_checkpoint(tmp_path / driver.CHECKPOINT_NAME, saved, done=7,
                           meta={"config": {"overlap": saved_overlap}})
    plain = curriculum.start_states(tmp_path, S(jnp.zeros(2, jnp.int32), None))
    assert plain.pending is None and plain.chunk.tolist() == [7, 9]
    over = curriculum.start_states(tmp_path, S(jnp.zeros(2, jnp.int32), jnp.zeros(2, bool)))
    assert over.chunk.tolist() == [7, 9] and over.pending.tolist() == ([True, False] if saved_overlap else [False] * 2)
    with pytest.raises(SystemExit, match="no checkpoint there"):
        curriculum.start_states(tmp_path / "none", S(jnp.zeros(2, jnp.int32), None))


@pytest.mark.slow
def test_curriculum_devices_split_the_trials_without_changing_them(tmp_path):
    """benchmarks/curriculum.py --devices 1,2 times the learn block on one device and with its trials split over two
    (learn --devices 2), and prints their ratio; a trial's chunks depend only on its own state, so both reach the
    same hardest cells (on 2 forced CPU devices, a subprocess)."""
    import json
    from pathlib import Path

    from devices import run_on_devices

    script = Path(__file__).resolve().parents[2] / "benchmarks" / "curriculum.py"
    out = tmp_path / "devices.json"
    run_on_devices(f"import sys, runpy; sys.argv = ['curriculum.py', '--preset', 'smoke', '--trials', '2', "
                   f"'--chunks', '1', '--skip-ppo', '--devices', '1,2', '--out', {str(out)!r}]; "
                   f"runpy.run_path({str(script)!r}, run_name='__main__')", devices=2, timeout=1200)
    result = json.loads(out.read_text())
    rows = result["rows"]
    assert [r["devices"] for r in rows] == [1, 2] and all(r["robot"] == "humanoid" for r in rows)
    assert rows[0]["hardest_mean"] == rows[1]["hardest_mean"] and rows[0]["switches"] == rows[1]["switches"]
    ratio = result["ratios"]["devices_2_vs_1_T2"]
    assert ratio == rows[1]["env_steps_per_s"] / rows[0]["env_steps_per_s"] > 0


@pytest.mark.slow
def test_evaluate_policies_benchmark_walks_shipped_walkers_through_one_program(tmp_path):
    """``benchmarks/evaluate_policies.py`` at CPU size (6 terrains, the paper's 20 walks): two shipped walkers
    through the shared program and one through a program of its own; the JSON names them and its totals add up.
    One MJX compile more than the shared one: minutes of CPU."""
    import json

    bench = load_benchmark("evaluate_policies")
    out = tmp_path / "ep.json"
    assert bench.main(["--walkers", "2", "--peer", "1", "--size", "128", "--seeds", "1", "--samples", "1",
                       "--families", "flat", "--protocol", "paper", "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["terrains"] == 6 and len(r["walkers"]) == 3 and len(r["shared_s"]) == 2 and len(r["fresh_s"]) == 1
    assert r["shared_total_s"] == pytest.approx(sum(r["shared_s"]), abs=0.2)
    assert r["first_call_s"] > r["walk_s"] > 0  # the first walker compiled, the second did not
    assert all(w.startswith("docs/results/exp3_gpushort/") for w in r["walkers"])


def two_archives(tmp_path) -> tuple[str, str]:
    """Two 4-terrain archives (the second's fitness scaled: other cells, other choices), as paths."""
    from curriculum_archives import tiny_archive_file
    from jaxterrain import qd as A

    a = tiny_archive_file(tmp_path, 4, "a.npz")
    arch = A.load(a)
    b = str(A.save(tmp_path / "b.npz", arch._replace(fitness=np.where(arch.source >= 0, 0.7 * arch.fitness + 0.1,
                                                                      arch.fitness).astype(np.float32))))
    return a, b


@pytest.mark.slow
def test_population_benchmark_at_cpu_size(tmp_path, monkeypatch):
    """``benchmarks/population.py`` at CPU size (the smoke preset on two 4-terrain archives and their combination, one
    trial each; the peak at 8 envs on 48 x 48 terrains): every part writes its JSON, the ratios are the measured
    figures' quotients, six's hardest cells against alone's and a peer folder's, a part done before is skipped, and a
    command out of time says so (exit 3). As on the GPU machine (``tests/gpu_image.py``). Three programs compile:
    minutes of CPU."""
    import json

    from gpu_image import image

    bench = load_benchmark("population")
    a, b = two_archives(tmp_path)
    image(monkeypatch)
    out = tmp_path / "bench"
    tiny = ["--preset", "smoke", "--archives", f"a={a}", f"b={b}", "--trials", "1", "--backend", "jax",
            "--peak-envs", "8", "--peak-size", "48", "--peak-layout", "classic", "--chunks", "2", "--out", str(out)]
    assert bench.main(["--parts", "six", "--time-limit", "1e-9", *tiny]) == 3
    assert bench.main(["--parts", "peak,chunk,alone,six,report", *tiny]) == 0
    got = {p: json.loads((out / f"{p}.json").read_text()) for p in ("peak", "chunk", "alone", "six", "population")}
    assert got["peak"]["done"] and got["peak"]["peak_physics_steps_per_s"] > 0 and got["peak"]["envs"] == 8
    chunk = got["chunk"]
    assert chunk["treatments"] == ["a map", "b map", "combined map"] and chunk["population"]["trials"] == 3
    assert chunk["alone"]["trials"] == 1 and chunk["population"]["chunks_timed"] == 2
    assert chunk["population_vs_alone_s_per_chunk"] == pytest.approx(chunk["population"]["s_per_chunk"]
                                                                     / chunk["alone"]["s_per_chunk"])
    assert got["six"]["done"] and set(got["six"]["hardest_mean"]) == {"a map", "b map", "combined map"}
    assert got["alone"]["treatments"] == ["a map"] and got["alone"]["wall_s"] > 0
    report = got["population"]
    assert report["six_vs_alone_wall"] == pytest.approx(got["six"]["wall_s"] / got["alone"]["wall_s"])
    assert report["population_of_peak"] == pytest.approx(chunk["population"]["physics_steps_per_s"]
                                                         / got["peak"]["peak_physics_steps_per_s"])
    alone = [r for r in report["hardest"] if r["peer"] == "alone"]
    assert [r["treatment"] for r in alone] == ["a-map"] and 0 <= alone[0]["p_six_better"][0] <= 1
    assert bench.main(["--parts", "report", "--sequential", str(out / "six"), *tiny]) == 0  # six against itself
    seq = [r for r in json.loads((out / "population.json").read_text())["hardest"] if r["peer"] == "sequential"]
    assert [r["treatment"] for r in seq] == ["a-map", "b-map", "combined-map"]
    assert all(r["p_six_better"][0] == 0.5 and r["six"] == r["peer_mean"] and not r["differ"] for r in seq)
    assert bench.main(["--parts", "chunk", *tiny]) == 0  # done before: skipped
    assert json.loads((out / "chunk.json").read_text()) == chunk


@pytest.mark.slow
def test_population_benchmark_splits_the_six_over_processes(tmp_path, capsys, monkeypatch):
    """``population.py --parts split --devices 0,1`` at CPU size: two processes (``CUDA_VISIBLE_DEVICES`` 0 and 1;
    both on the CPU here) run the treatments ``t % 2 == I`` into one ``split/`` folder, each its JSON; the part is
    done with the slowest process's wall time and every treatment's hardest cell; bad ``--devices`` in one line. As
    on the GPU machine (``tests/gpu_image.py``)."""
    import json

    from gpu_image import image

    bench = load_benchmark("population")
    a, b = two_archives(tmp_path)
    image(monkeypatch)
    out = tmp_path / "bench"
    tiny = ["--preset", "smoke", "--archives", f"a={a}", f"b={b}", "--trials", "1", "--backend", "jax",
            "--out", str(out)]
    for bad in ("0,0", "x", "-1"):
        with pytest.raises(SystemExit) as err:
            bench.parse_args(["--parts", "split", "--devices", bad, *tiny])
        assert err.value.code == 2 and "--devices must be distinct GPU indices" in capsys.readouterr().err
    assert bench.main(["--parts", "split", "--devices", "0,1", *tiny]) == 0
    shards = [json.loads((out / f"split{i}of2.json").read_text()) for i in range(2)]
    assert [s["treatments"] for s in shards] == [["a map", "combined map"], ["b map"]]
    split = json.loads((out / "split.json").read_text())
    assert split["done"] and split["returncodes"] == [0, 0] and split["devices"] == [0, 1]
    assert split["wall_s"] == max(s["wall_s"] for s in shards) > 0
    assert set(split["hardest_mean"]) == {"a map", "b map", "combined map"}
    assert all((out / "split" / t.replace(" ", "-") / "summary.json").exists() for t in split["treatments"])
    assert bench.main(["--parts", "split", *tiny]) == 0  # done before: skipped, its JSON untouched
    assert json.loads((out / "split.json").read_text()) == split


@pytest.mark.slow
def test_eval_order_benchmark_at_cpu_size(tmp_path, capsys):
    """``benchmarks/eval_order.py`` at CPU size (the smoke preset on one 4-terrain archive, one trial, the sequential
    and the lagged order): two interleaved rounds of one chunk each, the ratios the measured figures' quotients, the
    lag's unevaluated chunks counted; a command that finds it done only prints it; bad orders in one line (exit 2).
    Two programs compile: minutes of CPU."""
    import json

    from curriculum_archives import tiny_archive_file

    bench = load_benchmark("eval_order")
    a = tiny_archive_file(tmp_path, 4, "a.npz")
    out = tmp_path / "bench"
    tiny = ["--preset", "smoke", "--archives", f"a={a}", "--trials", "1", "--backend", "jax", "--chunks", "1",
            "--rounds", "2", "--out", str(out)]
    for bad in ("lag,sequential", "sequential,sequential", "sequential,fast"):
        with pytest.raises(SystemExit) as err:
            bench.parse_args(["--orders", bad, *tiny])
        assert err.value.code == 2 and "--orders must list distinct orders" in capsys.readouterr().err
    assert bench.main(["--orders", "sequential,lag", *tiny]) == 0
    r = json.loads((out / "eval_order.json").read_text())
    assert r["done"] and r["orders"] == ["sequential", "lag"] and len(r["rounds"]) == 2
    assert r["setup"]["lag"]["treatments"] == ["a map"] and r["setup"]["lag"]["trials"] == 1
    for got in r["rounds"]:
        lag, seq = got["lag"], got["sequential"]
        assert lag["vs_sequential"] == pytest.approx(lag["s_per_chunk"] / seq["s_per_chunk"])
        assert got["sequential"]["unevaluated"] == 0
    assert r["median_vs_sequential"]["lag"] == pytest.approx(r["median_s_per_chunk"]["lag"]
                                                             / r["median_s_per_chunk"]["sequential"])
    assert "| lag |" in (out / "eval_order.md").read_text()
    assert bench.main(["--orders", "sequential,lag", *tiny]) == 0
    assert "done before" in capsys.readouterr().out


def test_population_report_sets_six_against_split_trial_by_trial(tmp_path):
    """``population.py --parts report`` once ``six`` and ``split`` are done: their wall-time ratio, and per treatment
    six's hardest cells against split's (means over trials, P(a trial of six beats a trial of split)); a treatment
    whose six trials all beat split's is flagged as a difference."""
    import json

    bench = load_benchmark("population")
    for part, wall in (("six", 120.0), ("split", 80.0)):
        (tmp_path / f"{part}.json").write_text(json.dumps({"done": True, "wall_s": wall, "devices": [0, 1]}))
        for name, hardest in (("a-map", [5.0, 6.0, 7.0, 8.0]), ("b-map", [3.0, 3.0, 4.0, 4.0])):
            if part == "split" and name == "b-map":
                hardest = [1.0, 1.0, 2.0, 2.0]  # every six trial (3-4) above every split trial (1-2)
            folder = tmp_path / part / name
            folder.mkdir(parents=True)
            (folder / "summary.json").write_text(json.dumps({"hardest": hardest}))
    report = bench.part_report(tmp_path)
    assert report["six_vs_split_wall"] == pytest.approx(1.5)
    rows = {(r["treatment"], r["peer"]): r for r in report["hardest"]}
    assert set(rows) == {("a-map", "split"), ("b-map", "split")}
    assert rows["a-map", "split"]["six"][0] == pytest.approx(6.5) and not rows["a-map", "split"]["differ"]
    assert rows["b-map", "split"]["p_six_better"][0] == pytest.approx(1.0) and rows["b-map", "split"]["differ"]

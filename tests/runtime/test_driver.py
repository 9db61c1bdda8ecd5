"""The one host loop: chunks, checkpoints (one format, typed keys), resume equals uninterrupted, time limit, logs."""

from __future__ import annotations

import csv
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain.runtime import driver


class State(NamedTuple):
    key: jax.Array
    total: jax.Array
    params: dict


def make_state(seed=0):
    return State(jax.random.key(seed), jnp.zeros((), jnp.float32), {"w": jnp.arange(3, dtype=jnp.float32)})


@jax.jit
def _scan(state, steps):
    def body(s, t):
        k = jax.random.fold_in(s.key, t)
        x = jax.random.uniform(k)
        return s._replace(total=s.total + x, params={"w": s.params["w"] * 0.5 + x}), {"x": x, "t": t}

    return jax.lax.scan(body, state, steps)


def chunk(state, start, stop):
    return _scan(state, jnp.arange(start, stop))


def test_resume_equals_uninterrupted(tmp_path):
    full, done, hist = driver.run_chunks(chunk, make_state(), total=10, every=3, progress=False)
    assert done == 10 and hist["t"] == list(range(10))
    run = tmp_path / "run"
    part, done_a, _ = driver.run_chunks(chunk, make_state(), total=4, every=3, run_dir=run, progress=False,
                                        meta={"seed": 0})
    assert done_a == 4
    state, done_b, history, meta = driver.restore(run, like=make_state())
    assert done_b == 4 and meta.pop("wall_s") >= 0 and meta == {"seed": 0} and history["t"] == [0, 1, 2, 3]
    assert jnp.issubdtype(state.key.dtype, jax.dtypes.prng_key)
    resumed, done_c, hist_c = driver.run_chunks(chunk, state, total=10, every=3, start=done_b, history=history,
                                                run_dir=run, progress=False)
    assert done_c == 10
    np.testing.assert_array_equal(np.asarray(resumed.params["w"]), np.asarray(full.params["w"]))
    assert float(resumed.total) == float(full.total)
    assert hist_c["x"] == hist["x"]
    rows = list(csv.reader((run / driver.METRICS_NAME).open()))
    assert rows[0] == ["step", "t", "x"] and len(rows) == 11 and rows[-1][0] == "10"
    assert float(rows[3][2]) == hist["x"][2]
    assert any((run / "tb").iterdir())


def test_time_limit_stops_after_a_chunk(tmp_path):
    calls = []

    def slow(state, start, stop):
        calls.append((start, stop))
        import time

        time.sleep(0.05)
        return chunk(state, start, stop)

    _, done, hist = driver.run_chunks(slow, make_state(), total=100, every=2, time_limit_s=0.01,
                                      run_dir=tmp_path, progress=False)
    assert done == 2 and calls == [(0, 2)] and len(hist["x"]) == 2
    assert driver.restore(tmp_path, make_state())[1] == 2


def test_wall_time_adds_up_over_resumes(tmp_path):
    import time

    def slow(state, start, stop):
        time.sleep(0.05)
        return chunk(state, start, stop)

    driver.run_chunks(slow, make_state(), total=2, every=1, run_dir=tmp_path, progress=False, wall_s=100.0)
    state, done, history, meta = driver.restore(tmp_path, make_state())
    assert 100.1 <= meta["wall_s"] < 150  # the 100 s passed in, then two chunks of >= 0.05 s
    driver.run_chunks(slow, state, total=3, every=1, start=done, history=history, run_dir=tmp_path,
                      progress=False, wall_s=meta["wall_s"])
    assert driver.read_meta(tmp_path)["wall_s"] >= meta["wall_s"] + 0.05
    for bad in (-1.0, float("nan"), "1"):
        with pytest.raises(ValueError, match="wall_s must be a finite number of seconds >= 0"):
            driver.run_chunks(slow, make_state(), total=1, every=1, progress=False, wall_s=bad)


def test_time_limit_skips_a_chunk_predicted_to_end_past_it():
    import time

    def timed(state, start, stop):
        time.sleep(0.2)
        return chunk(state, start, stop)

    chunk(make_state(), 0, 1)  # compiled before the clock starts (alone, this test's first chunk would compile)
    # after 2 chunks (0.4 s) the 3rd would end at 0.6 s > 0.5 s: stop there, not after it
    _, done, _ = driver.run_chunks(timed, make_state(), total=10, every=1, time_limit_s=0.5, progress=False)
    assert done == 2


def test_time_limit_shortens_the_last_chunk_when_any_length_runs_without_recompiling():
    """fit_to_limit: the first chunk under a time limit is one step (a probe of the rate, so a long first chunk
    cannot overrun it: issue 59), and a chunk predicted to end past the limit runs the steps that still fit (the
    curriculum's block, whose length is traced), so the limit holds to within one step, not one chunk of ``every``
    steps, the first chunk included."""
    import time

    calls = []

    def per_step(state, start, stop):
        calls.append((start, stop))
        time.sleep(0.1 * (stop - start))
        return state, {"x": np.zeros(stop - start, np.float32)}  # no compile: the rate is the sleep's

    # a probe of one step (0.1 s: the rate), then 5 steps (0.6 s in all); 0.25 s are left: 2 more steps fit
    start = time.perf_counter()
    _, done, hist = driver.run_chunks(per_step, make_state(), total=20, every=5, time_limit_s=0.85, progress=False,
                                      fit_to_limit=True)
    seconds = time.perf_counter() - start
    assert calls[:2] == [(0, 1), (1, 6)] and calls[2][0] == 6 and done == calls[-1][1] and len(hist["x"]) == done
    assert 7 <= done <= 8 and seconds < 0.85 + 0.1 + 0.05  # within one step of the limit
    calls.clear()  # without it, the chunk that does not fit is skipped whole
    _, done, _ = driver.run_chunks(per_step, make_state(), total=20, every=5, time_limit_s=0.8, progress=False)
    assert calls == [(0, 5)] and done == 5


def test_progress_callable_and_batched_metrics():
    seen = []

    def batched(state, start, stop):
        n = stop - start
        return state, {"m": jnp.stack([jnp.arange(n, dtype=jnp.float32), 2 + jnp.arange(n, dtype=jnp.float32)])}

    _, _, hist = driver.run_chunks(batched, make_state(), total=3, every=2, progress=seen.append)
    assert hist["m"] == [1.0, 2.0, 1.0]  # mean over the leading (trial) axis
    assert [s["done"] for s in seen] == [2, 3]


def test_without_a_terminal_progress_is_plain_lines(capsys, monkeypatch):
    """stderr not a terminal (pytest captures it; a log file, a batch job): no tqdm bar and no carriage return, but a
    line at the first chunk, at most one per PLAIN_EVERY_S seconds after, and one at the end."""
    monkeypatch.setattr(driver, "PLAIN_EVERY_S", 3600.0)
    driver.run_chunks(chunk, make_state(), total=6, every=2, desc="demo", unit="step", key_metric="x")
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert "\r" not in err and len(lines) == 2, err  # the first chunk and the last; the middle one throttled
    assert lines[0].startswith("demo: 2/6 steps (33 %)") and lines[1].startswith("demo: 6/6 steps (100 %)")
    assert ", x " in lines[1] and "ETA 0 s" in lines[1]


def test_bad_checkpoints_name_the_file_and_leaf(tmp_path):
    path = tmp_path / "c.npz"
    driver.save_checkpoint(path, make_state(), done=1)
    other = make_state()._replace(params={"w": jnp.zeros(4)})
    with pytest.raises(ValueError, match=r"leaf .*'w'.*\(3,\)"):
        driver.load_checkpoint(path, other)
    with pytest.raises(ValueError, match="no leaf"):
        driver.load_checkpoint(path, {"other": jnp.zeros(1)})
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(ValueError, match="c.npz.*not readable"):
        driver.load_checkpoint(path, make_state())
    with pytest.raises(ValueError, match="every must be an integer >= 1"):
        driver.run_chunks(chunk, make_state(), total=3, every=0)
    assert driver.restore(tmp_path / "none", make_state()) is None


_KILL_SCRIPT = """
import sys, time
import jax, jax.numpy as jnp
sys.path.insert(0, {tests!r})
from test_driver import chunk, make_state
from jaxterrain.runtime import driver

def slow(state, start, stop):
    time.sleep(0.02)
    return chunk(state, start, stop)

restored = driver.restore({run!r}, make_state())
state, done, history = (make_state(), 0, None) if restored is None else restored[:3]
print("start", done, flush=True)
driver.run_chunks(slow, state, total=400, every=1, start=done, history=history, run_dir={run!r}, progress=False)
print("finished", flush=True)
"""


def test_sigkill_at_any_moment_resumes_to_the_same_result(tmp_path):
    """SIGKILL the run repeatedly at arbitrary moments (often inside a checkpoint write); every restart resumes
    from a readable checkpoint and the final state equals an uninterrupted run's."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    run = tmp_path / "run"
    script = tmp_path / "run.py"
    script.write_text(_KILL_SCRIPT.format(tests=str(Path(__file__).resolve().parent), run=str(run)))
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    kills = 0
    for delay in (2.5, 2.7, 2.9, 3.1):
        proc = subprocess.Popen([sys.executable, str(script)], env=env, stdout=subprocess.PIPE, text=True)
        time.sleep(delay)
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
            kills += 1
        proc.wait()
    out = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=300)
    assert "finished" in out.stdout, out.stderr[-2000:]
    assert kills >= 1
    state, done, history, _ = driver.restore(run, make_state())
    full, _, full_hist = driver.run_chunks(chunk, make_state(), total=400, every=1, progress=False)
    assert done == 400 and history["x"] == full_hist["x"]
    np.testing.assert_array_equal(np.asarray(state.params["w"]), np.asarray(full.params["w"]))


def test_damaged_latest_checkpoint_names_the_previous_one(tmp_path):
    driver.run_chunks(chunk, make_state(), total=3, every=1, run_dir=tmp_path, progress=False)
    assert driver.load_checkpoint(tmp_path / driver.PREVIOUS_NAME, make_state())[1] == 2
    latest = tmp_path / driver.CHECKPOINT_NAME
    latest.write_bytes(latest.read_bytes()[:-200])
    with pytest.raises(ValueError, match=r"checkpoint.npz.*mv .*checkpoint.prev.npz"):
        driver.restore(tmp_path, make_state())


def test_optional_subtrees_absent_from_an_older_checkpoint_take_the_templates_values(tmp_path):
    """``optional`` prefixes: a checkpoint written before a subtree existed (the curriculum's env states) restores
    with the template's values there and the stored values everywhere else; a leaf outside the prefixes stays
    required, and a stored subtree is read, not replaced."""
    old = {"a": jnp.arange(3.0), "envs": None}
    driver.save_checkpoint(tmp_path / "c.npz", old, done=2)
    like = {"a": jnp.zeros(3), "envs": {"q": jnp.full((2, 4), 7.0), "v": jnp.ones(2)}}
    state, done, _, _ = driver.load_checkpoint(tmp_path / "c.npz", like, optional=("['envs']",))
    assert done == 2 and state["a"].tolist() == [0.0, 1.0, 2.0]
    np.testing.assert_array_equal(state["envs"]["q"], np.full((2, 4), 7.0))
    with pytest.raises(ValueError, match=r"has no leaf \"\['envs'\]\['q'\]\""):
        driver.load_checkpoint(tmp_path / "c.npz", like)
    with pytest.raises(ValueError, match="has no leaf"):  # a prefix of a NAME is not a prefix of the path
        driver.load_checkpoint(tmp_path / "c.npz", like, optional=("['env",))
    new = {"a": jnp.arange(3.0), "envs": {"q": jnp.zeros((2, 4)), "v": jnp.arange(2.0)}}
    driver.save_checkpoint(tmp_path / "n.npz", new, done=3)
    state, _, _, _ = driver.load_checkpoint(tmp_path / "n.npz", like, optional=("['envs']",))
    assert state["envs"]["v"].tolist() == [0.0, 1.0] and float(state["envs"]["q"].max()) == 0.0

"""Curriculum trials over 4 forced CPU devices (a subprocess: XLA_FLAGS must precede jax's start): 5 trials (padded
to 8) split over the devices, the bank replicated, run the chunks of the one-device runner exactly; so do blocks of
the running trials only (``run_live``)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from devices import run_on_devices

TESTS = str(Path(__file__).resolve().parents[1] / "curriculum")  # the unit tests whose fixtures the script reuses

SCRIPT = textwrap.dedent("""
    import sys
    import os; sys.path[:0] = [TESTS, os.path.dirname(TESTS)]  # the unit tests and the helpers beside them
    import jax, numpy as np
    from jaxterrain import curriculum as C
    from jaxterrain.runtime import sharding as SH
    from test_curriculum import toy_bank, fake_harness, small, START, tree_equal

    assert len(jax.devices()) == 4
    bank = toy_bank(np.linspace(1.0, 0.2, 9).reshape(3, 3))
    config, harness = small("random", max_evals=2, max_epochs=6), fake_harness(0.3)
    states = C.init_trials(jax.random.split(jax.random.key(0), 5), bank, START, config=config, harness=harness)
    four = C.make_runner(config, harness, mesh=SH.make_mesh())(states, bank, 4)
    one = C.make_runner(config, harness)(states, bank, 4)  # donates (deletes) states: last
    assert tree_equal(one, four)
    terrains = np.asarray(four.history.terrain)
    assert (terrains[:, :4] >= 0).all() and len({tuple(t) for t in terrains}) > 1  # 4 chunks; the trials differ
    assert np.asarray(four.policy["resets"]).min() >= 1

    # run_live over the mesh: the running trials only (a smaller block, padded to the devices) = the one-device run
    # (without overlap: with it each device's loop runs until ITS trials have done the block, see make_runner)
    from test_curriculum import keyed_harness, KEYED_START, toy_grid
    bank = toy_bank(toy_grid(4))
    config, harness = small("map", max_evals=3, max_epochs=60), keyed_harness(0.03, overlap=False)
    init = lambda: C.init_trials(jax.random.split(jax.random.key(3), 5), bank, KEYED_START, config=config,
                                 harness=harness)
    mesh_run, one_run = C.make_runner(config, harness, mesh=SH.make_mesh()), C.make_runner(config, harness)
    live, whole, sizes = init(), init(), []
    while not np.all(np.asarray(whole.done)):
        sizes.append(C.live_rows(live.done).size)
        live, whole = C.run_live(mesh_run, live, bank, 3), one_run(whole, bank, 3)
        assert tree_equal(live, whole)
    assert min(sizes) < 5, sizes
    print("ok")
""").replace("TESTS", repr(TESTS))


@pytest.mark.slow  # 10-70 s on 2 CPU cores; the default suite keeps under 15 min (2026-11-29)
def test_sharded_trials_equal_the_one_device_runner():
    assert run_on_devices(SCRIPT).strip().endswith("ok")


LEARN_SCRIPT = textwrap.dedent("""
    import contextlib, io, json, sys
    from pathlib import Path
    import os; sys.path[:0] = [TESTS, os.path.dirname(TESTS)]  # the unit tests and the helpers beside them
    import jax
    from experiments.__main__ import main
    from test_curriculum import tiny_archive_file

    assert len(jax.devices()) == 2
    root = Path(ROOT)
    archive = tiny_archive_file(root, 4, "four.npz")
    run = lambda *a: main(["learn", "--preset", "smoke", "--archive", archive, "--devices", "2", *a])
    with contextlib.redirect_stderr(io.StringIO()):
        assert run("--out", str(root / "whole")) == 0
        assert run("--out", str(root / "parts"), "--time-limit", "1e-6") == 3  # one chunk: inside the first block
        assert main(["learn", "--resume", str(root / "parts")]) == 0
    for name in ("history.csv", "sequences.csv", "milestones.csv"):
        assert (root / "parts" / name).read_text() == (root / "whole" / name).read_text(), name
    print("ok")
""")


@pytest.mark.slow
def test_sharded_learn_stopped_inside_a_block_resumes_to_the_uninterrupted_run(tmp_path):
    """``learn --devices 2`` (the trials split over 2 forced CPU devices): stopped by ``--time-limit`` after its first
    chunk, inside the uninterrupted run's first block (the env states of both devices' trials ride in the
    checkpoint), and resumed, it writes the uninterrupted sharded run's history, sequences and milestones exactly.
    Minutes of CPU (one more smoke program)."""
    script = f"TESTS = {TESTS!r}\nROOT = {str(tmp_path)!r}\n" + LEARN_SCRIPT
    assert run_on_devices(script, devices=2, timeout=1500).strip().endswith("ok")

"""``learn --backend warp`` end to end where warp-lang imports (Warp's CPU backend without a GPU): the trials' env
states ride from block to block and through a checkpoint in the carried form (``walker.carry_rows``;
``tests/curriculum/test_carried_envs.py`` has the blocks' shapes)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from curriculum_archives import tiny_archive_file
from experiments import common
from experiments.__main__ import main
from jaxterrain.runtime import driver, provenance
from jaxterrain.walker import warp_available


@pytest.mark.slow
def test_a_warp_smoke_run_stopped_after_its_first_chunk_resumes_to_the_uninterrupted_run(tmp_path):
    """``learn --preset smoke --backend warp`` (2 trials, 4 chunks in blocks of 2): stopped by ``--time-limit``
    after its first chunk (its checkpoint holds the Warp env states in the carried form) and resumed, it ends with
    the uninterrupted run's history, byte for byte (Warp's CPU kernels). Before the fix no such run finished (an
    H200 refused the second block; here the block did not compile: rows gathered from Warp's empty
    ``contact__elem``). Three smoke runs on Warp's CPU backend: 193 s on 2 shared cores (2026-11-29)."""
    pytest.importorskip("warp")
    ok, why = warp_available()
    if not ok:
        pytest.skip(why)
    archive = tiny_archive_file(tmp_path, 4, "four.npz")
    whole, parts = tmp_path / "whole", tmp_path / "parts"
    smoke = ["learn", "--preset", "smoke", "--archive", archive, "--backend", "warp", "--out"]
    assert main(smoke + [str(whole)]) == 0
    assert main(smoke + [str(parts), "--time-limit", "1e-6"]) == 3
    assert driver.read_meta(parts)["backend"] == "warp" and not (parts / "summary.json").exists()
    with np.load(parts / driver.CHECKPOINT_NAME) as stored:
        assert stored["leaf:.policy.env_state.data._impl.contact__pos"].shape == (2, 0, 3)
        assert stored["leaf:.policy.env_state.data.qpos"].shape[:2] == (2, 4)  # 2 trials x 4 envs, kept
    assert main(["learn", "--resume", str(parts)]) == 0
    assert (parts / "history.csv").read_text() == (whole / "history.csv").read_text()
    # which heightfield collision trained it: in the run's provenance lines and in every exported walker
    kernel = provenance.warp_hfield()
    assert kernel in ("stock", "local-origin patch")
    lines = [json.loads(x) for x in (parts / common.PROVENANCE_NAME).read_text().splitlines()]
    assert [line["warp_hfield"] for line in lines] == [kernel, kernel]
    walker = json.loads((whole / "policies" / "trial_0" / "config.json").read_text())
    assert walker["provenance"]["warp_hfield"] == kernel

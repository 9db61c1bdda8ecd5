"""The one table of first-call times: every program has both platforms, the notes say the right figure for the
platform they run on, the measured figures stand in it, and ``--help`` reads it without importing JAX."""

from __future__ import annotations

import subprocess
import sys

from jaxterrain.runtime import estimates


def test_every_program_has_an_estimate_on_both_platforms():
    assert set(estimates.ESTIMATES) == {(p, k) for p in estimates.PROGRAMS for k in ("cpu", "gpu")}
    for (program, platform), e in estimates.ESTIMATES.items():
        assert 0 < e.low_s < e.high_s and e.source, (program, platform)


def test_the_measured_figures_lie_inside_their_estimates():
    block = estimates.ESTIMATES[("curriculum-block", "cpu")]
    assert block.low_s <= 532 - 36 <= block.high_s  # learn --preset smoke: 532 s, 36 s of them chunks (2 cores)
    walk = estimates.ESTIMATES[("suite-walk", "cpu")]
    assert walk.low_s <= 210 <= walk.high_s  # evaluate --preset smoke's first call
    low, high = estimates.SMOKE_MINUTES["learn"]
    assert low * 60 <= 532 <= high * 60


def test_the_note_names_the_program_and_this_platform_first():
    cpu = estimates.first_call_note("curriculum-block", "2 trials, jax physics", platform="cpu")
    assert cpu.startswith("compiling the curriculum block") and "(2 trials, jax physics; cpu)" in cpu
    assert cpu.index("5-9 min on 2 CPU cores") < cpu.index("on a GPU")
    gpu = estimates.first_call_note("suite-walk", platform="cuda")
    assert "(gpu)" in gpu and gpu.index("on a GPU") < gpu.index("2-4 min on 2 CPU cores")


def test_compiling_says_before_and_after(capsys):
    with estimates.compiling("walks", "4 terrains", platform="cpu"):
        print("the call")
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("compiling the base policy's walks (4 terrains; cpu)") and lines[1] == "the call"
    assert lines[2].startswith("compiled walks in ")


def test_a_warp_curriculum_block_says_its_first_chunk_builds_the_kernels():
    """MuJoCo Warp builds its kernels at their first launch, after the XLA compile that ``compiling`` times: the note
    says so after the compile's estimate (measured: first chunks of 72-90 s against 5 s on a fresh 2 x H200)."""
    warp = estimates.first_call_note("curriculum-block", "20 trials, warp physics", platform="gpu",
                                     then=estimates.first_chunk_note("warp"))
    assert warp.endswith("; " + estimates.WARP_FIRST_CHUNK) and "65-90 s more on an H200" in warp
    assert estimates.first_chunk_note("jax") == ""
    assert estimates.first_call_note("curriculum-block", platform="gpu", then="") == \
        estimates.first_call_note("curriculum-block", platform="gpu")

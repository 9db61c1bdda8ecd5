"""jaxterrain.features.alignment (Experiment 1a, Figure 4): the driver's values, correlations and files on a tiny
set, a time-limited run resumed to the uninterrupted values, and a skipped generator. The command around it:
``python -m experiments features`` (tests/integration)."""

from __future__ import annotations

import csv

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain.features import alignment as AL

SETTINGS = AL.AlignmentSettings(generators=("perlin",), samples=2, mutation_steps=1, size=32, windows=(5,), batch=2,
                                figure_window=5, calibrate=True, calibrate_window=5)


@jax.jit
def slope(heightmaps, key):
    """A cheap stand-in fitness in [0, 1]: 1 - 10 x the mean step along x (the ``slope`` fitness's idea)."""
    del key
    return jnp.clip(1.0 - 10.0 * jnp.mean(jnp.abs(jnp.diff(heightmaps, axis=-1)), axis=(1, 2)), 0.0, 1.0)


def test_alignment_returns_what_it_writes_and_resumes_to_the_same_values(tmp_path):
    lines = []
    whole = AL.feature_alignment(SETTINGS, slope, 0, tmp_path / "a", progress=False, say=lines.append)
    assert set(whole.values) == {"perlin"}
    for values in whole.values.values():  # 2 genomes + 2 mutants each; difficulty = 1 - fitness
        assert list(values) == AL.columns(SETTINGS) + ["difficulty"] and values["fitness"].shape == (4,)
        np.testing.assert_array_equal(values["difficulty"], 1.0 - values["fitness"])
    rows = list(csv.reader(open(tmp_path / "a" / "correlations.csv")))[1:]
    assert [tuple(r) for r in rows] == [tuple(r) for r in whole.correlations] and len(rows) == 4 * 4  # tri, tpi, roughness at 5, difficulty
    for name in ("values_perlin.csv", "figure4.png", "figure4.csv", "correlations.png", "ranges.json"):
        assert (tmp_path / "a" / name).stat().st_size > 0, name
    assert any(line.startswith("[perlin] strongest |r| with difficulty") for line in lines)
    # stopped after its first batch (of 2), then resumed: the same values
    assert AL.feature_alignment(SETTINGS, slope, 0, tmp_path / "b", time_limit_s=1e-9, progress=False,
                                say=lambda line: None) is None
    resumed = AL.feature_alignment(SETTINGS, slope, 0, tmp_path / "b", resume=True, progress=False,
                                   say=lambda line: None)
    for g in whole.values:
        for c in whole.values[g]:
            np.testing.assert_array_equal(resumed.values[g][c], whole.values[g][c])


def test_a_generator_that_cannot_render_is_skipped_and_none_left_is_an_error(tmp_path):
    ok, why = AL.generator_available("no_such_generator", 32)
    assert not ok and why
    with pytest.raises(ValueError, match="no generator of \\['no_such_generator'\\] renders at size 32"):
        AL.feature_alignment(SETTINGS._replace(generators=("no_such_generator",)), slope, 0, tmp_path,
                             say=lambda line: None)

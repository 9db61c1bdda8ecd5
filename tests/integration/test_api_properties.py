"""Property tests (hypothesis) of the public entry points that take shapes or a config (issue 49, "every public
function that takes shapes or a config checks them and names the parameter"): valid input gives the documented
shape / dtype / range; invalid input (wrong rank, wrong trailing size, a NaN where values are documented finite, a
zero or negative size, an out-of-range config field, a wrong type) gives a one-line ``ValueError`` that names the
parameter (or ``Owner.field``).

:mod:`tests.integration.test_properties` holds the generators' genomes, the heights / windows / strides of the
features, ``TerrainScale`` and the files; this module the rest of the API: difficulty, statistics, the MAP-Elites
config and grid, the PPO and walker configs (checked without building an env), the held-out suite, the terrain's
sizes and the generators' keys and options.

Cheap by construction: small arrays (at most 64 x 64), few distinct shapes (each new shape is a new XLA compile),
no env, no MJX; ``derandomize=True`` (the same inputs on every run) and no example database.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from jaxterrain import difficulty, features, generators, qd, rl, suite, walker
from jaxterrain.runtime import statistics
from jaxterrain.terrain import TerrainScale, hfield_size, to_metres, validate_scale


def bounded(n: int):
    return settings(max_examples=n, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                           HealthCheck.filter_too_much])


def refused(call, match: str) -> str:
    """``call()`` must raise a one-line ``ValueError`` matching ``match``; its message."""
    with pytest.raises(ValueError, match=match) as err:
        call()
    message = str(err.value)
    assert "\n" not in message, f"not one line: {message!r}"
    return message


# Values that are not numbers / not integers, for "wrong type" fields
NOT_NUMBERS = st.sampled_from([None, "1", b"1", [1.0], (1.0,), {"v": 1}, object()])
NOT_INTS = st.one_of(NOT_NUMBERS, st.booleans(), st.floats(allow_nan=True, allow_infinity=True))
NON_FINITE = st.sampled_from([math.nan, math.inf, -math.inf])


# ----------------------------------------------------------------------------------------------------------------
# difficulty: Protocol, best_of, aggregate, rotate_headings, validate_heightmaps


@bounded(25)
@given(b=st.integers(1, 3), attempts=st.sampled_from([1, 3, 6]), data=st.data())
def test_best_of_is_the_mean_of_the_best_per_row(b, attempts, data):
    values = st.one_of(st.floats(0.0, 1.0, width=32), NON_FINITE)
    d = np.asarray(data.draw(st.lists(st.lists(values, min_size=attempts, max_size=attempts), min_size=b, max_size=b)),
                   np.float32)
    best = data.draw(st.integers(1, attempts))
    out = np.asarray(difficulty.best_of(d, best))
    assert out.shape == (b,) and out.dtype == np.float32 and np.isfinite(out).all()
    clean = np.sort(np.nan_to_num(d, nan=0.0, posinf=0.0, neginf=0.0), axis=1)[:, attempts - best:]
    np.testing.assert_allclose(out, clean.mean(axis=1), rtol=1e-6, atol=1e-7)


@bounded(30)
@given(best=st.one_of(st.integers(-5, 0), st.integers(7, 50), NOT_INTS))
def test_best_of_refuses_a_best_outside_one_to_attempts(best):
    d = np.zeros((2, 6), np.float32)
    refused(lambda: difficulty.best_of(d, best), r"best must be an int in \[1, attempts = 6\]")


@st.composite
def protocols(draw, valid: bool = True):
    headings = draw(st.sampled_from([1, 2, 4]))
    per = draw(st.sampled_from([1, 3]))
    return difficulty.Protocol(per * headings, draw(st.integers(1, per)), headings,
                               draw(st.sampled_from([0.0, 0.25])), draw(st.sampled_from(["mean", "min"])))


@bounded(12)
@given(protocol=protocols(), b=st.sampled_from([1, 3]), seed=st.integers(0, 2**31 - 1))
def test_aggregate_gives_one_fitness_per_terrain_within_the_distances(protocol, b, seed):
    d = np.random.default_rng(seed).random((b, protocol.attempts)).astype(np.float32)
    fit = np.asarray(difficulty.aggregate(d, protocol))
    assert fit.shape == (b,) and fit.dtype == np.float32
    assert (fit >= d.min(axis=1) - 1e-6).all() and (fit <= d.max(axis=1) + 1e-6).all()
    scores = np.asarray(difficulty.heading_scores(d, protocol))
    assert scores.shape == (b, protocol.headings)
    if protocol.headings == 1:
        np.testing.assert_array_equal(fit, np.asarray(difficulty.best_of(d, protocol.best)))
    # the same under jit (shapes are static: the checks run while tracing), up to XLA's fusion of the mean
    np.testing.assert_allclose(np.asarray(jax.jit(lambda x: difficulty.aggregate(x, protocol))(d)), fit, rtol=1e-6)


@bounded(40)
@given(protocol=protocols(), shape=st.lists(st.integers(0, 9), min_size=0, max_size=3),
       call=st.sampled_from(["aggregate", "heading_scores"]))
def test_aggregate_refuses_distances_of_another_shape(protocol, shape, call):
    assume(not (len(shape) == 2 and shape[1] == protocol.attempts))
    fn = getattr(difficulty, call)
    refused(lambda: fn(np.zeros(shape, np.float32), protocol), r"distances must have shape \[B, protocol.attempts")


PROTOCOL_BREAKS = {
    "attempts": st.one_of(st.integers(-5, 0), st.sampled_from([2.0, "20", None, True])),
    "best": st.one_of(st.integers(-5, 0), st.integers(21, 99), st.sampled_from([2.0, "5", None])),
    "headings": st.one_of(st.integers(-2, 0), st.sampled_from([3, 5, 8, 2.0, "4", None])),
    "start_spread": st.one_of(st.floats(max_value=-1e-9), NON_FINITE, st.sampled_from(["0", None])),
    "rule": st.sampled_from(["max", "", None, 1, "MEAN"]),
}


@bounded(50)
@given(field=st.sampled_from(sorted(PROTOCOL_BREAKS)), data=st.data(),
       call=st.sampled_from(["validate", "aggregate"]))
def test_a_bad_protocol_field_is_named(field, data, call):
    value = data.draw(PROTOCOL_BREAKS[field])
    protocol = difficulty.Protocol()._replace(**{field: value})
    if call == "validate":
        refused(protocol.validate, rf"^protocol\.{field}")
    else:  # aggregate validates the protocol before it reads the distances
        refused(lambda: difficulty.aggregate(np.zeros((2, 20), np.float32), protocol), rf"^protocol\.{field}")


@bounded(15)
@given(value=st.sampled_from([(20, 5, 1), None, {"attempts": 20}, "paper"]))
def test_aggregate_refuses_what_is_not_a_protocol(value):
    d = np.zeros((1, 20), np.float32)
    refused(lambda: difficulty.aggregate(d, value), "protocol must be a difficulty.Protocol")


@bounded(20)
@given(headings=st.sampled_from([1, 2, 4]), b=st.integers(1, 2), n=st.sampled_from([4, 6]),
       seed=st.integers(0, 2**31 - 1))
def test_rotate_headings_turns_every_map(headings, b, n, seed):
    t = np.random.default_rng(seed).random((b, n, n)).astype(np.float32)
    out = np.asarray(difficulty.rotate_headings(t, headings))
    assert out.shape == (b * headings, n, n)
    for i, k in enumerate(difficulty.HEADING_TURNS[headings]):
        np.testing.assert_array_equal(out[i::headings], np.rot90(t, k, axes=(1, 2)))


@bounded(30)
@given(shape=st.lists(st.integers(1, 5), min_size=0, max_size=4), headings=st.sampled_from([1, 2, 4]))
def test_rotate_headings_refuses_other_ranks_and_non_square_maps(shape, headings):
    if len(shape) == 3 and (headings == 1 or shape[1] == shape[2]):
        shape = shape + [1]
    t = jnp.zeros(shape, jnp.float32)
    refused(lambda: difficulty.rotate_headings(t, headings), r"terrains must have shape \[B, H, W\]|square maps")


@bounded(20)
@given(b=st.integers(1, 2), h=st.sampled_from([4, 9]), w=st.sampled_from([4, 7]),
       dtype=st.sampled_from(["float32", "float64"]), seed=st.integers(0, 2**31 - 1))
def test_valid_heightmaps_pass_as_float32(b, h, w, dtype, seed):
    x = np.random.default_rng(seed).random((b, h, w)).astype(dtype)
    out = difficulty.validate_heightmaps(x)
    assert out.shape == (b, h, w) and out.dtype == jnp.float32


HEIGHTMAP_BREAKS = st.sampled_from(["rank", "small", "empty", "dtype", "nan", "inf", "above", "below", "list"])


@bounded(40)
@given(kind=HEIGHTMAP_BREAKS, name=st.sampled_from(["heightmaps", "terrains"]))
def test_bad_heightmaps_name_the_argument(kind, name):
    good = np.full((2, 8, 8), 0.5, np.float32)
    bad = {"rank": good[0], "small": good[:, :3], "empty": good[:0], "dtype": good.astype(np.complex64),
           "nan": np.where(np.eye(8, dtype=bool), np.nan, good), "inf": np.where(np.eye(8, dtype=bool), np.inf, good),
           "above": good + 0.6, "below": good - 0.6, "list": good.tolist()}[kind]
    refused(lambda: difficulty.validate_heightmaps(bad, name=name), rf"^{name} ")


# ----------------------------------------------------------------------------------------------------------------
# runtime.statistics


BAD_SCORES = st.sampled_from(["scalar", "vector", "cube", "no runs", "no tasks", "nan", "inf", "text", "ragged"])


def bad_scores(kind: str):
    return {"scalar": 0.5, "vector": [0.1, 0.2], "cube": np.zeros((2, 2, 2)), "no runs": np.zeros((0, 3)),
            "no tasks": np.zeros((3, 0)), "nan": [[0.1, math.nan]], "inf": [[math.inf, 0.2]], "text": [["a", "b"]],
            "ragged": [[0.1], [0.2, 0.3]]}[kind]


@bounded(40)
@given(kind=BAD_SCORES, call=st.sampled_from(["iqm", "poi_x", "poi_y", "interval", "improvement"]))
def test_bad_score_matrices_name_scores(kind, call):
    bad, ok = bad_scores(kind), np.full((2, 2), 0.5)
    calls = {"iqm": lambda: statistics.iqm(bad),
             "poi_x": lambda: statistics.probability_of_improvement(bad, ok),
             "poi_y": lambda: statistics.probability_of_improvement(ok, bad),
             "interval": lambda: statistics.interval_estimates({"a": bad}, reps=2),
             "improvement": lambda: statistics.improvement({"a": (ok, bad)}, reps=2)}
    refused(calls[call], r"^scores must be")


BOOTSTRAP_BREAKS = {
    "reps": st.one_of(st.integers(-3, 0), NOT_INTS),
    "seed": st.one_of(st.integers(max_value=-1), st.integers(min_value=2**32), NOT_INTS),
    "confidence": st.one_of(st.floats(max_value=0.0), st.floats(min_value=1.0), NON_FINITE, NOT_NUMBERS,
                            st.booleans()),
}


@bounded(60)
@given(field=st.sampled_from(sorted(BOOTSTRAP_BREAKS)), data=st.data(),
       call=st.sampled_from(["interval_estimates", "improvement"]))
def test_bad_bootstrap_settings_are_named_before_any_bootstrap(field, data, call):
    """Refused up front (no rliable import, no resampling): ``reps``, ``seed``, ``confidence`` by name."""
    kwargs = {"reps": 2, "seed": 0, "confidence": 0.9, field: data.draw(BOOTSTRAP_BREAKS[field])}
    x = np.full((2, 3), 0.5)
    arg = {"a": x} if call == "interval_estimates" else {"a": (x, x)}
    refused(lambda: getattr(statistics, call)(arg, **kwargs), rf"^{field} must be")


@bounded(20)
@given(value=st.sampled_from([[np.zeros((2, 2))], np.zeros((2, 2)), None, "scores"]),
       call=st.sampled_from(["interval_estimates", "improvement"]))
def test_the_estimates_take_mappings_by_name(value, call):
    refused(lambda: getattr(statistics, call)(value, reps=2), r"^(scores|pairs) must be a mapping")


@bounded(40)
@given(n=st.integers(3, 12), data=st.data())
def test_rank_correlations_are_bounded_and_non_finite_samples_are_refused(n, data):
    x = np.asarray(data.draw(st.lists(st.integers(0, 5), min_size=n, max_size=n)), np.float64)
    y = np.asarray(data.draw(st.lists(st.integers(0, 5), min_size=n, max_size=n)), np.float64)
    r = statistics.rank_correlation(x, y)
    assert r["n"] == n
    if np.ptp(x) and np.ptp(y):
        assert -1 - 1e-9 <= r["spearman"] <= 1 + 1e-9 and -1 - 1e-9 <= r["kendall"] <= 1 + 1e-9
        assert 0.0 <= r["spearman_p"] <= 1.0 + 1e-9 and 0.0 <= r["kendall_p"] <= 1.0 + 1e-9
    else:
        assert math.isnan(r["spearman"])
    which, bad = data.draw(st.sampled_from(["x", "y"])), data.draw(NON_FINITE)
    i = data.draw(st.integers(0, n - 1))
    (x if which == "x" else y)[i] = bad
    refused(lambda: statistics.rank_correlation(x, y), rf"rank_correlation: {which} must be finite")
    refused(lambda: statistics.rank_correlation(x[:2], y[:2]), "equal length >= 3")


# ----------------------------------------------------------------------------------------------------------------
# qd: EvolveConfig (resolve_config, its JSON form), the grid


@st.composite
def evolve_configs(draw):
    headings = draw(st.sampled_from([1, 2, 4]))
    per = draw(st.integers(1, 5))
    names = tuple(draw(st.permutations(["tri", "tpi", "roughness"]))[:2])
    ranges = draw(st.one_of(st.none(), st.tuples(*[st.tuples(st.floats(-1, 0), st.floats(0.5, 2))] * 2)))
    return qd.EvolveConfig(
        generations=draw(st.integers(0, 50)), batch_size=draw(st.integers(1, 64)),
        initial_population=draw(st.integers(1, 64)), bins=draw(st.integers(1, 60)), descriptors=names,
        ranges=ranges, window=draw(st.integers(2, 30)), stride=draw(st.integers(1, 4)), attempts=per * headings,
        best=draw(st.integers(1, per)), headings=headings, checkpoint_every=draw(st.integers(1, 100)),
        robot_height=draw(st.one_of(st.none(), st.floats(0.1, 3.0))), traversable_window=draw(st.integers(2, 30)),
        out_of_range=draw(st.sampled_from(["clip", "reject"])), store_heightmaps=draw(st.booleans()),
        rollout_slots=draw(st.one_of(st.none(), st.integers(1, 512))),
        scale=TerrainScale(draw(st.floats(0.01, 0.1)), draw(st.floats(0.25, 2.0))),
        rollout_backend=draw(st.sampled_from(["jax", "warp"])), robot=draw(st.sampled_from(["humanoid", "ant"])),
        spawn=draw(st.sampled_from(["feet", "patch"])))


@bounded(40)
@given(config=evolve_configs())
def test_valid_evolve_configs_resolve_and_survive_their_json_form(config):
    resolved = qd.resolve_config(config)
    assert resolved._replace(ranges=config.ranges) == config
    assert len(resolved.ranges) == 2 and all(hi > lo for lo, hi in resolved.ranges)
    if config.ranges is None:
        assert resolved.ranges == tuple(qd.DEFAULT_RANGES[n] for n in config.descriptors)
    assert qd.resolve_config(qd.config_from_dict(qd.config_to_dict(resolved))) == resolved
    if config.bins <= 8:
        c = np.asarray(qd.centroids_for(resolved))
        (lo0, hi0), (lo1, hi1) = resolved.ranges
        assert c.shape == (config.bins ** 2, 2)
        assert (c[:, 0] >= lo0).all() and (c[:, 0] <= hi0).all() and (c[:, 1] >= lo1).all() and (c[:, 1] <= hi1).all()


INT_FIELDS = {"generations": 0, "batch_size": 1, "initial_population": 1, "bins": 1, "window": 2, "stride": 1,
              "attempts": 1, "best": 1, "headings": 1, "checkpoint_every": 1, "traversable_window": 2}
EVOLVE_BREAKS = {
    **{f: st.one_of(st.integers(lo - 5, lo - 1), NOT_INTS) for f, lo in INT_FIELDS.items()},
    "headings": st.one_of(st.integers(-2, 0), st.sampled_from([3, 5, 2.0, "4", None, True])),
    "best": st.one_of(st.integers(-2, 0), st.integers(21, 99), NOT_INTS),
    "descriptors": st.sampled_from([None, "tr", ("tri",), ("tri", "tri"), ("tri", "tpi", "roughness"), ("tri", 3),
                                    5]),
    "ranges": st.sampled_from(["x", ((0, 1),), ((1, 0), (0, 1)), ((0, math.nan), (0, 1)), ((0, "a"), (0, 1)),
                               ((0, 1, 2), (0, 1)), ((0, math.inf), (0, 1)), 5]),
    "robot_height": st.one_of(st.floats(max_value=0.0), NON_FINITE, st.sampled_from(["1.5", [1.5], True])),
    "out_of_range": st.sampled_from(["wrap", None, "", 1]),
    "store_heightmaps": st.sampled_from(["yes", 1, None, 0.0]),
    "rollout_slots": st.one_of(st.integers(-3, 0), st.sampled_from([2.5, "8", True])),
    "scale": st.sampled_from([None, (0.04,), (0.0, 1.0), {"cell_size": -1.0}, {"bogus": 1.0}, "1m",
                              TerrainScale._make((0.04, None)), TerrainScale._make(([0.04], 1.0))]),
    "rollout_backend": st.sampled_from(["mjx", None, "JAX"]),
    "robot": st.sampled_from(["dog", None, ""]),
    "spawn": st.sampled_from(["torso", None, "", 1, ["feet"]]),
}


@bounded(120)
@given(field=st.sampled_from(sorted(EVOLVE_BREAKS)), data=st.data())
def test_a_bad_evolve_config_field_is_named(field, data):
    value = data.draw(EVOLVE_BREAKS[field], label=field)
    config = qd.EvolveConfig()._replace(**{field: value})
    # headings=2 / 4 and best=21+ break the attempts / headings / best rule: named by the field the rule reports
    match = {"headings": r"EvolveConfig\.(headings|attempts)", "best": r"EvolveConfig\.best",
             "attempts": r"EvolveConfig\.(attempts|best)"}.get(field, rf"EvolveConfig\.{field}")
    refused(lambda: qd.resolve_config(config), match)


@bounded(15)
@given(value=st.sampled_from([None, {}, (5000, 20), "config", qd.Archive]))
def test_resolve_config_refuses_what_is_not_an_evolve_config(value):
    refused(lambda: qd.resolve_config(value), "config must be a qd.EvolveConfig")


@bounded(20)
@given(d=st.sampled_from([{"binz": 5}, {"ranges": "ab"}, {"ranges": [[0, "x"], [0, 1]]}, {"scale": {"x": 1.0}},
                          {"scale": {"cell_size": 0.0, "height": 1.0}}]))
def test_config_from_dict_names_the_field(d):
    refused(lambda: qd.resolve_config(qd.config_from_dict(d)), r"EvolveConfig|TerrainScale")


@bounded(40)
@given(bins=st.integers(1, 60), data=st.data())
def test_cells_and_bins_round_trip(bins, data):
    cells = np.asarray(data.draw(st.lists(st.integers(0, bins * bins - 1), min_size=1, max_size=6)))
    b = qd.cell_bins(cells, bins)
    assert b.shape == cells.shape + (2,) and b.dtype == np.int32
    assert (b >= 0).all() and (b < bins).all()
    np.testing.assert_array_equal(qd.cell_of(b, bins), cells)
    d = qd.cell_distance(b)
    assert d.shape == cells.shape and d.dtype == np.float32
    assert (d >= math.sqrt(2) - 1e-5).all() and (d <= math.hypot(bins, bins) + 1e-4).all()


@bounded(60)
@given(call=st.sampled_from(["cell_bins", "cell_of", "cell_distance"]),
       kind=st.sampled_from(["bins", "negative", "too large", "fraction", "nan", "text", "shape"]),
       bins=st.one_of(st.integers(-3, 0), NOT_INTS))
def test_bad_cells_and_bins_are_named(call, kind, bins):
    if call == "cell_bins":
        arg, good = {"negative": [-1], "too large": [2500], "fraction": [2.5], "nan": [math.nan], "text": ["a"],
                     "shape": [3], "bins": [3]}[kind], 50
        fn, match = (lambda: qd.cell_bins(arg, bins)) if kind == "bins" else (lambda: qd.cell_bins(arg, good)), "cells"
    else:
        arg = {"negative": [[-1, 0]], "too large": [[50, 0]], "fraction": [[0.5, 0]], "nan": [[math.nan, 0]],
               "text": [["a", "b"]], "shape": [[1, 2, 3]], "bins": [[1, 2]]}[kind]
        if call == "cell_of":
            fn = (lambda: qd.cell_of(np.asarray(arg), bins)) if kind == "bins" else (lambda: qd.cell_of(arg, 50))
            match = "cell_bins_"
        else:
            if kind in ("too large", "bins"):  # no grid size to exceed
                arg = [[-2, 0]]
            fn, match = (lambda: qd.cell_distance(arg)), "bins"
    if kind == "bins":
        match = r"bins must be an integer >= 1" if call != "cell_distance" else "bins"
    elif call == "cell_bins" and kind == "shape":
        return  # any shape of cell indices is valid
    refused(fn, rf"^{match}")


# ----------------------------------------------------------------------------------------------------------------
# features: names, shapes, windows


@bounded(25)
@given(names=st.sampled_from([None, 5, 3.0, (1,), ("tri", None), (), [], ("nope",), ("tri", "TRI")]))
def test_bad_descriptor_names_are_named(names):
    h = np.full((1, 8, 8), 0.5, np.float32)
    refused(lambda: features.descriptors(h, names=names, window=3, stride=1),
            r"^(names must|unknown descriptor name)")


@bounded(40)
@given(h=st.integers(2, 40), w=st.integers(2, 40), lead=st.lists(st.integers(1, 3), max_size=2), data=st.data())
def test_output_shape_follows_the_formula(h, w, lead, data):
    window = data.draw(st.integers(2, min(h, w)))
    stride = data.draw(st.integers(1, 5))
    assert features.output_shape(tuple(lead) + (h, w), window, stride) == ((h - window) // stride + 1,
                                                                            (w - window) // stride + 1)
    assert features.window_centre(window) == window // 2


@bounded(40)
@given(shape=st.one_of(st.sampled_from([16, "ab", None, (16,), (), (16.0, 16), (True, 16), ("16", "16")]),
                       st.lists(st.integers(-3, 1), min_size=2, max_size=3)))
def test_output_shape_names_a_bad_shape(shape):
    refused(lambda: features.output_shape(shape, 3, 1), r"^(shape must be|heightmaps of)")


@bounded(30)
@given(window=st.one_of(st.integers(-5, 0), NOT_INTS))
def test_window_centre_names_window(window):
    refused(lambda: features.window_centre(window), "^window must be an integer")


@bounded(20)
@given(shape=st.lists(st.integers(1, 4), min_size=0, max_size=4).filter(lambda s: len(s) != 3))
def test_check_heights_names_a_bad_rank(shape):
    refused(lambda: features.check_heights(jnp.full(shape, 0.5)), r"^heightmaps must have shape \[B, H, W\]")


# ----------------------------------------------------------------------------------------------------------------
# terrain: sizes in metres


@bounded(40)
@given(h=st.integers(2, 64), w=st.integers(2, 64), cell=st.floats(0.005, 0.2), height=st.floats(0.1, 5.0),
       base=st.floats(0.01, 1.0), lead=st.lists(st.integers(1, 4), max_size=2))
def test_hfield_size_spans_the_samples(h, w, cell, height, base, lead):
    rx, ry, ez, bz = hfield_size(tuple(lead) + (h, w), TerrainScale(cell, height), base)
    assert all(isinstance(v, float) for v in (rx, ry, ez, bz))
    assert rx == pytest.approx((w - 1) * cell / 2) and ry == pytest.approx((h - 1) * cell / 2)
    assert (ez, bz) == (pytest.approx(height), pytest.approx(base))


@bounded(40)
@given(shape=st.one_of(st.sampled_from([16, "ab", None, (16,), (16.5, 16), (True, 16), (math.nan, 4)]),
                       st.lists(st.integers(-3, 1), min_size=2, max_size=3)),
       base=st.one_of(st.floats(max_value=0.0), NON_FINITE, NOT_NUMBERS), which=st.sampled_from(["shape", "base"]))
def test_hfield_size_names_shape_and_base(shape, base, which):
    if which == "shape":
        refused(lambda: hfield_size(shape), r"^shape must be \[\.\.\., H, W\]")
    else:
        refused(lambda: hfield_size((8, 8), base=base), r"^base must be a finite number")


@bounded(20)
@given(lead=st.sampled_from([(), (2,)]), height=st.floats(0.1, 4.0), seed=st.integers(0, 2**31 - 1))
def test_to_metres_scales_and_keeps_the_shape(lead, height, seed):
    x = np.random.default_rng(seed).random(lead + (8, 8)).astype(np.float32)
    out = to_metres(x, TerrainScale(height=height))
    assert out.shape == x.shape and out.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(out), x * np.float32(height), rtol=1e-6)


@bounded(20)
@given(bad=st.sampled_from(["1d", "4d", "scalar", "complex", "text"]))
def test_to_metres_names_heightmaps(bad):
    x = {"1d": np.zeros(4), "4d": np.zeros((1, 1, 4, 4)), "scalar": 0.5, "complex": np.zeros((4, 4), complex),
         "text": "abc"}[bad]
    refused(lambda: to_metres(x), "^heightmaps must be a real array")


@bounded(30)
@given(field=st.sampled_from(["cell_size", "height"]),
       value=st.one_of(st.floats(max_value=0.0, width=32), NON_FINITE))
def test_validate_scale_checks_concrete_jax_scalars(field, value):
    scale = TerrainScale()._replace(**{field: jnp.float32(value)})  # a jax scalar: TerrainScale itself skips it
    refused(lambda: validate_scale(scale), rf"^TerrainScale\.{field}")
    assert jax.jit(lambda s: validate_scale(s).height)(TerrainScale()) == 1.0  # traced fields: unchecked


# ----------------------------------------------------------------------------------------------------------------
# generators: options and keys (the genomes themselves: test_properties)


_PERLIN: list = []


def perlin():
    if not _PERLIN:
        _PERLIN.append(generators.get("perlin", size=16))
    return _PERLIN[0]


BAD_KEYS = st.sampled_from([None, 0, 7, "key", np.zeros(2, np.int32), np.zeros(3, np.uint32),
                            np.zeros((2, 2), np.uint32), jax.random.split(jax.random.key(0), 2), np.float32(1.0)])


@bounded(30)
@given(key=BAD_KEYS, call=st.sampled_from(["sample", "mutate"]), name=st.sampled_from(["perlin", "cppn", "gan"]))
def test_generators_name_a_bad_key(key, call, name):
    """The key is checked first (its static dtype and shape), before the count or the genomes are looked at."""
    g = perlin() if name == "perlin" else generators.get(name, size=16, **(
        {"max_nodes": 8, "max_connections": 8} if name == "cppn" else {}))
    if call == "sample":
        refused(lambda: g.sample(key, 2), rf"^{name}: key must be one JAX PRNG key")
    else:
        refused(lambda: g.mutate(key, None), rf"^{name}: key must be one JAX PRNG key")


@bounded(10)
@given(raw=st.booleans(), seed=st.integers(0, 2**31 - 1))
def test_generators_take_typed_and_raw_keys(raw, seed):
    g = perlin()
    key = jax.random.PRNGKey(seed) if raw else jax.random.key(seed)
    genomes = g.sample(key, 2)
    assert genomes.shape == (2, g.spec.size) and genomes.dtype == jnp.float32
    g.validate(genomes)
    g.validate(g.mutate(key, genomes))


@bounded(20)
@given(name=st.sampled_from(["perlin", "worley", "diamond_square"]),
       options=st.sampled_from([{"bogus": 1}, {"sizes": 16}, {"size": 16, "levels": 3}, {"Size": 16}]))
def test_generators_get_names_unknown_options(name, options):
    refused(lambda: generators.get(name, **options), rf"generators\.get\('{name}'\): unknown option")


@bounded(10)
@given(value=st.sampled_from([[1, 2], {"a": 1}, np.zeros(2)]))
def test_generators_get_names_unhashable_options(value):
    refused(lambda: generators.get("worley", size=16, select=value), r"option values must be hashable")


# ----------------------------------------------------------------------------------------------------------------
# rl: PPOConfig, the normaliser, GAE


@st.composite
def ppo_configs(draw):
    num_envs, num_unrolls = draw(st.integers(1, 64)), draw(st.integers(1, 8))
    divisors = [d for d in range(1, num_envs * num_unrolls + 1) if (num_envs * num_unrolls) % d == 0]
    return rl.PPOConfig(
        num_envs=num_envs, unroll_length=draw(st.integers(1, 20)), num_unrolls=num_unrolls,
        num_minibatches=draw(st.sampled_from(divisors)), update_epochs=draw(st.integers(1, 8)),
        learning_rate=draw(st.floats(1e-6, 1.0)), gamma=draw(st.floats(0.0, 1.0)), gae_lambda=draw(st.floats(0.0, 1.0)),
        clip_eps=draw(st.floats(1e-3, 1.0)), entropy_coef=draw(st.floats(0.0, 1.0)), vf_coef=draw(st.floats(0.0, 2.0)),
        max_grad_norm=draw(st.one_of(st.none(), st.floats(1e-3, 10.0))), reward_scaling=draw(st.floats(1e-3, 10.0)),
        normalize_observations=draw(st.booleans()), update_normaliser=draw(st.booleans()),
        normalize_advantage=draw(st.booleans()),
        policy_hidden=tuple(draw(st.lists(st.integers(1, 64), max_size=4))),
        value_hidden=tuple(draw(st.lists(st.integers(1, 64), min_size=1, max_size=4))),
        activation=draw(st.sampled_from(["swish", "relu", "tanh", "elu"])),
        action_distribution=draw(st.sampled_from(["tanh_normal", "normal"])), min_std=draw(st.floats(0.0, 1.0)),
        init_std=draw(st.floats(1e-3, 3.0)), truncation=draw(st.sampled_from(["mask", "bootstrap"])),
        scan_inputs=draw(st.integers(0, 200)), scan_lr_scale=draw(st.floats(1e-3, 10.0)))


@bounded(40)
@given(config=ppo_configs())
def test_valid_ppo_configs_pass_unchanged_and_survive_their_json_form(config):
    assert rl.validate_config(config) is config
    assert rl.PPOConfig.from_json_dict(config.to_json_dict()) == config


PPO_BREAKS = {
    **{f: st.one_of(st.integers(-3, 0), NOT_INTS) for f in ("num_envs", "unroll_length", "num_unrolls",
                                                           "num_minibatches", "update_epochs")},
    "scan_inputs": st.one_of(st.integers(-3, -1), NOT_INTS),
    **{f: st.one_of(st.floats(max_value=0.0), NON_FINITE, NOT_NUMBERS, st.booleans())
       for f in ("learning_rate", "clip_eps", "reward_scaling", "init_std", "scan_lr_scale")},
    **{f: st.one_of(st.floats(max_value=-1e-9), st.floats(min_value=1.0 + 1e-9), NON_FINITE, NOT_NUMBERS)
       for f in ("gamma", "gae_lambda")},
    **{f: st.one_of(st.floats(max_value=-1e-9), NON_FINITE, NOT_NUMBERS, st.booleans())
       for f in ("entropy_coef", "vf_coef", "min_std")},
    "max_grad_norm": st.one_of(st.floats(max_value=0.0), NON_FINITE, st.sampled_from(["1", [1.0], True])),
    **{f: st.sampled_from([None, 1, 0, "yes", 1.0]) for f in ("normalize_observations", "update_normaliser",
                                                              "normalize_advantage")},
    **{f: st.sampled_from([[32], (0,), (32.0,), (True,), (-1, 4), "32", None]) for f in ("policy_hidden",
                                                                                         "value_hidden")},
    "activation": st.sampled_from(["gelu", None, "", "Swish"]),
    "action_distribution": st.sampled_from(["beta", None, ""]),
    "truncation": st.sampled_from(["none", None, True]),
}


@bounded(120)
@given(field=st.sampled_from(sorted(PPO_BREAKS)), data=st.data())
def test_a_bad_ppo_config_field_is_named(field, data):
    value = data.draw(PPO_BREAKS[field], label=field)
    config = rl.PPOConfig(num_envs=4, num_unrolls=2, num_minibatches=2)._replace(**{field: value})
    refused(lambda: rl.validate_config(config), rf"^PPOConfig\.{field}")


@bounded(10)
@given(value=st.sampled_from([None, {}, (3072, 10), "ppo"]))
def test_validate_config_refuses_what_is_not_a_ppo_config(value):
    refused(lambda: rl.validate_config(value), "config must be an rl.PPOConfig")


@bounded(25)
@given(size=st.sampled_from([1, 4]), lead=st.sampled_from([(), (2, 3)]), seed=st.integers(0, 2**31 - 1),
       wrong=st.integers(1, 7), bad_size=st.one_of(st.integers(-3, 0), NOT_INTS))
def test_the_normaliser_keeps_shapes_and_names_obs(size, lead, seed, wrong, bad_size):
    obs = jnp.asarray(np.random.default_rng(seed).normal(size=lead + (size,)), jnp.float32)
    stats = rl.update_stats(rl.init_stats(size), obs if lead else obs[None])
    assert stats.mean.shape == (size,) and stats.m2.shape == (size,)
    out = rl.normalize(stats, obs)
    assert out.shape == obs.shape and np.isfinite(np.asarray(out)).all()
    assume(wrong != size)
    other = jnp.zeros(lead + (wrong,))
    refused(lambda: rl.normalize(stats, other), rf"^obs must have shape \[\.\.\., O\] with O = {size}")
    refused(lambda: rl.update_stats(stats, other), r"^obs must have shape")
    refused(lambda: rl.init_stats(bad_size), "^observation_size must be an integer >= 1")


@bounded(12)
@given(t=st.sampled_from([1, 3]), b=st.sampled_from([1, 2]),
       bad=st.sampled_from(["rewards", "dones", "truncations", "last_value", "values"]), seed=st.integers(0, 99))
def test_gae_keeps_shapes_and_names_a_mismatch(t, b, bad, seed):
    rng = np.random.default_rng(seed)
    args = dict(rewards=jnp.asarray(rng.normal(size=(t, b)), jnp.float32),
                values=jnp.asarray(rng.normal(size=(t, b)), jnp.float32),
                dones=jnp.asarray(rng.random((t, b)) < 0.3, jnp.float32), last_value=jnp.zeros((b,), jnp.float32),
                truncations=jnp.zeros((t, b), jnp.float32))
    adv, targets = rl.gae(gamma=0.9, lam=0.95, **args)
    assert adv.shape == targets.shape == (t, b) and np.isfinite(np.asarray(adv)).all()
    args[bad] = jnp.zeros((t + 1, b + 1)) if bad != "values" else jnp.zeros(())
    match = rf"^{bad} must have" if bad != "values" else r"^values must have shape \[T, B\]"
    refused(lambda: rl.gae(gamma=0.9, lam=0.95, **args), match)


# ----------------------------------------------------------------------------------------------------------------
# walker: WalkerConfig checked without building an env; small pure helpers


@bounded(30)
@given(h=st.integers(4, 64), w=st.integers(4, 64), robot=st.sampled_from(["humanoid", "ant"]),
       spread=st.floats(0.0, 1.0), frames=st.integers(1, 10), tiles=st.integers(0, 4))
def test_valid_walker_configs_resolve_to_their_robots_defaults(h, w, robot, spread, frames, tiles):
    config = walker.WalkerConfig(terrain_shape=(h, w), robot=robot, start_spread=spread, n_frames=frames, tiles=tiles)
    resolved = walker.resolve_config(config)
    spec = walker.robots.get(robot)
    for f in walker.robots.ROBOT_FIELDS:
        assert getattr(resolved, f) == spec.default(f)
    assert resolved._replace(**{f: None for f in walker.robots.ROBOT_FIELDS}) == config
    terrain = walker.flat_terrain(resolved, 0.25)
    assert terrain.shape == (h, w) and terrain.dtype == jnp.float32 and float(terrain[0, 0]) == 0.25


WALKER_BREAKS = {
    "terrain_shape": st.sampled_from([(2, 32), (32,), (32, 32, 32), (16.5, 16), ("a", "b"), 32, None, (True, 8)]),
    "scale": st.sampled_from([TerrainScale._make((0.04, None)), (0.04, 1.0), None]),
    "solver": st.sampled_from(["sound", None, (4, 16)]),
    "timestep": st.one_of(st.floats(max_value=0.0), NON_FINITE, NOT_NUMBERS),
    "n_frames": st.one_of(st.integers(-3, 0), NOT_INTS),
    "episode_length": st.one_of(st.integers(-3, 0), NOT_INTS),
    **{f: st.one_of(st.floats(max_value=-1e-9), NON_FINITE, st.sampled_from(["0.5", [0.5]]))
       for f in ("start_margin", "goal_margin", "side_margin", "spawn_clearance", "joint_noise", "qvel_noise",
                 "start_spread")},
    "max_qvel": st.one_of(st.floats(max_value=0.0), NON_FINITE, NOT_NUMBERS),
    **{f: st.one_of(NON_FINITE, st.sampled_from(["1", [1.0]])) for f in ("forward_reward_weight", "healthy_reward",
                                                                         "ctrl_cost_weight")},
    "healthy_z_range": st.sampled_from([(2.0, 1.0), (1.0, 1.0), (1.0,), (0.0, math.nan), "12", 5]),
    "observation": st.sampled_from(["yes", 1, None, True, "Perceptive"]),
    "scan_x": st.sampled_from([(0.0,), (0.0, math.nan), "ab", (1.0, 0.0)]),
    "scan_points": st.sampled_from([(0, 5), (8,), (8, 2.5), "85"]),
    "scan_noise": st.one_of(st.floats(max_value=-1e-9), NON_FINITE, NOT_NUMBERS),
    "backend": st.sampled_from(["mjx", None, "JAX"]),
    "tiles": st.one_of(st.integers(-3, -1), st.sampled_from([2.5, "4", True, None])),
    "warp_worlds": st.one_of(st.integers(-3, 0), st.sampled_from([2.5, "8", None])),
    "robot": st.sampled_from(["dog", "", None]),
}


@bounded(150)
@given(field=st.sampled_from(sorted(WALKER_BREAKS)), data=st.data())
def test_a_bad_walker_config_field_is_named_without_building_an_env(field, data):
    value = data.draw(WALKER_BREAKS[field], label=field)
    config = walker.WalkerConfig(terrain_shape=(32, 32))._replace(**{field: value})
    match = {"scale": "scale", "scan_x": "scan_x", "warp_worlds": "warp_worlds"}.get(field, rf"^{field}")
    refused(lambda: walker.resolve_config(config), match)


@bounded(10)
@given(value=st.sampled_from([None, {}, (256, 256), "humanoid"]))
def test_walker_resolve_config_refuses_what_is_not_a_walker_config(value):
    refused(lambda: walker.resolve_config(value), "config must be a walker.WalkerConfig")


@bounded(20)
@given(height=st.one_of(NON_FINITE, NOT_NUMBERS))
def test_flat_terrain_names_height(height):
    refused(lambda: walker.flat_terrain(walker.WalkerConfig(terrain_shape=(8, 8)), height), "^height must be")


@bounded(25)
@given(j=st.integers(1, 8), data=st.data())
def test_job_queue_orders_the_needed_jobs_first(j, data):
    needed = np.asarray(data.draw(st.lists(st.booleans(), min_size=j, max_size=j)))
    priority = np.asarray(data.draw(st.lists(st.floats(-1, 1), min_size=j, max_size=j)), np.float32)
    queue, queued = (np.asarray(a) for a in walker.job_queue(needed, priority))
    assert sorted(queue.tolist()) == list(range(j)) and int(queued) == needed.sum()
    assert needed[queue[:queued]].all()
    refused(lambda: walker.job_queue(np.zeros((2, j), bool)), r"^needed must have shape \[J\]")
    refused(lambda: walker.job_queue(needed, np.zeros(j + 1)), r"^priority must have the shape of needed")


@bounded(20)
@given(lead=st.sampled_from([(), (2,)]), ez=st.floats(0.1, 3.0), seed=st.integers(0, 99),
       bad=st.one_of(st.floats(max_value=0.0), NON_FINITE, NOT_NUMBERS))
def test_metres_to_hfield_flattens_into_unit_range_and_names_elevation(lead, ez, seed, bad):
    t = np.random.default_rng(seed).normal(size=lead + (4, 5)).astype(np.float32)
    data = np.asarray(walker.metres_to_hfield(t, ez))
    assert data.shape == lead + (20,) and (data >= 0).all() and (data <= 1).all()
    refused(lambda: walker.metres_to_hfield(t, bad), r"^elevation_z \(metres\) must be a finite number > 0")
    refused(lambda: walker.metres_to_hfield(np.zeros(4), ez), r"^terrain_m must have shape \[\.\.\., H, W\]")


# ----------------------------------------------------------------------------------------------------------------
# suite: families, cells


@bounded(30)
@given(name=st.sampled_from(suite.family_names()), size=st.sampled_from([16, 24, 32]), data=st.data(),
       seed=st.integers(0, 2**31 - 1))
def test_every_family_builds_a_unit_range_map_at_any_level(name, size, data, seed):
    fam = suite.FAMILIES[name]
    value = data.draw(st.floats(fam.lo, fam.hi) if fam.hi > fam.lo else st.just(fam.lo))
    m = suite.build_terrain(name, value, size, TerrainScale(), np.random.default_rng(seed))
    assert m.shape == (size, size) and m.dtype == np.float32
    assert np.isfinite(m).all() and m.min() >= 0.0 and m.max() <= 1.0


@bounded(50)
@given(field=st.sampled_from(["name", "value", "size", "scale", "rng"]), data=st.data())
def test_bad_family_arguments_are_named(field, data):
    bad = {"name": st.sampled_from(["lava", "", None, 3]),
           "value": st.one_of(st.floats(max_value=-1e-9), NON_FINITE, NOT_NUMBERS, st.booleans()),
           "size": st.one_of(st.integers(-3, 15), NOT_INTS),
           "scale": st.sampled_from([None, (0.04, 1.0), TerrainScale._make((0.04, None))]),
           "rng": st.sampled_from([0, "rng", np.random.RandomState(0)])}[field]
    args = dict(name="waves", value=0.1, size=16, scale=TerrainScale(), rng=None)
    args[field] = data.draw(bad)
    match = {"name": "^family must be", "scale": "scale|TerrainScale"}.get(field, rf"^{field} must be")
    refused(lambda: suite.build_terrain(**args), match)


@bounded(20)
@given(size=st.integers(2, 32), cell=st.floats(0.01, 0.1), bad=st.one_of(st.integers(-3, 1), NOT_INTS))
def test_edge_distance_is_zero_on_the_edge_and_names_size(size, cell, bad):
    d = suite.edge_distance(size, TerrainScale(cell_size=cell))
    assert d.shape == (size, size) and d.min() == pytest.approx(0.0, abs=1e-12)
    assert (d[0] <= 1e-12).all() and (d[:, -1] <= 1e-12).all() and d.max() <= (size - 1) * cell / 2 + 1e-9
    refused(lambda: suite.edge_distance(bad, TerrainScale()), r"^size must be an integer >= 2")


@bounded(30)
@given(kind=st.sampled_from(["family", "level", "cube", "empty", "nan", "text"]), n=st.integers(1, 5))
def test_cell_scores_names_mismatched_or_bad_inputs(kind, n):
    fitness, family, level = np.full((2, n), 0.5), np.array(["a"] * n), np.zeros(n, int)
    if kind == "family":
        family = family[:-1] if n > 1 else np.array(["a", "b"])
    elif kind == "level":
        level = np.zeros(n + 1, int)
    elif kind == "cube":
        fitness = fitness[..., None]
    elif kind == "empty":
        fitness, family, level = np.zeros((2, 0)), family[:0], level[:0]
    elif kind == "nan":
        fitness[1, n - 1] = math.nan
    else:
        fitness = [["x"] * n]
    match = {"family": "^family must have shape", "level": "^level must have shape"}.get(kind, "^fitness must")
    refused(lambda: suite.cell_scores(fitness, family, level), match)


@bounded(15)
@given(levels=st.one_of(st.integers(-3, 0), NOT_INTS))
def test_descriptor_levels_names_levels(levels):
    refused(lambda: suite.descriptor_levels(np.full((1, 32, 32), 0.5, np.float32), levels),
            r"^levels must be an integer >= 1")

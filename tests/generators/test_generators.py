"""Tests of the noise generators (Perlin, diamond-square, Worley) and of every registered vector generator."""

from __future__ import annotations

import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import generators
from jaxterrain.generators import GenomeSpec
from jaxterrain.generators import diamond_square as ds_mod
from jaxterrain.generators import worley as worley_mod

NOISE = ("perlin", "diamond_square", "worley")
# Generic tests run every generator at 64 x 64 with batches of B = 4, so that each generator's jitted render is
# compiled once for the whole file (compiling dominates the CPU run time). The 256 x 256 behaviour is covered by
# the generator-specific tests below.
SIZE = 64
B = 4


def _vector_names() -> list[str]:
    """Registered generators with a vector genome (a GenomeSpec): the noise ones, plus e.g. the GAN if present."""
    out = []
    for name in generators.names():
        if name in NOISE:
            out.append(name)
            continue
        try:
            gen = generators.get(name, size=64)
        except Exception:  # pragma: no cover - a generator that cannot be built at size 64 is tested elsewhere
            continue
        if isinstance(gen.spec, GenomeSpec):
            out.append(name)
    return out


VECTOR = _vector_names()


def _gen(name: str):
    return generators.get(name, size=SIZE)


def _mid_genome(gspec: GenomeSpec) -> np.ndarray:
    mid = (np.asarray(gspec.lower) + np.asarray(gspec.upper)) / 2
    return np.where(gspec.integer, np.floor(mid), mid).astype(np.float32)


# ---------------------------------------------------------------------------------------------------------------
# Generic properties, over every registered vector generator
# ---------------------------------------------------------------------------------------------------------------


def test_noise_generators_registered():
    assert set(NOISE) <= set(generators.names())
    assert generators.get("perlin").spec.names == ("scale", "octaves", "persistence", "lacunarity", "seed")
    assert generators.get("diamond_square").spec.names == ("c00", "c01", "c10", "c11", "Z", "D", "seed")
    assert generators.get("worley").spec.names == ("seed", "N", "D")


MUTATION_PROB = {"gan": 0.07}


@pytest.mark.parametrize("name", VECTOR)
def test_render_range_dtype_shape_and_determinism(name):
    gen = _gen(name)
    genomes = gen.sample(jax.random.PRNGKey(1), B)
    maps = gen.render(genomes)
    assert maps.shape == (B, SIZE, SIZE) and maps.dtype == jnp.float32
    m = np.asarray(maps)
    assert np.isfinite(m).all() and m.min() >= 0.0 and m.max() <= 1.0
    # Not constant, and different genomes give different maps.
    assert (m.reshape(B, -1).std(axis=1) > 1e-3).all()
    assert not np.array_equal(m[0], m[1])
    # Same genome -> bit-identical map (same program), also from a fresh copy of the genomes and in another
    # position of the batch.
    again = np.asarray(gen.render(jnp.array(np.asarray(genomes)[::-1])))
    if name == "gan":
        # Convolutions may sum in another order at another batch position (oneDNN blocking): ulps, not bits.
        np.testing.assert_allclose(m, again[::-1], rtol=0, atol=1e-6)
        np.testing.assert_array_equal(m, np.asarray(gen.render(genomes)))
    else:
        np.testing.assert_array_equal(m, again[::-1])


@pytest.mark.parametrize("name", VECTOR)
def test_genome_errors_name_gene_and_range(name):
    gen = _gen(name)
    gspec = gen.spec
    good = gen.sample(jax.random.PRNGKey(2), B)
    gen.validate(good)  # valid genomes pass
    with pytest.raises(ValueError, match=rf"\[B, {gspec.size}\]"):
        gen.render(np.zeros((2, gspec.size + 1), np.float32))
    with pytest.raises(ValueError, match="shape"):
        gen.render(np.zeros((2, 2, gspec.size), np.float32))
    for j, gene in enumerate(gspec.names):
        lo, hi = gspec.lower[j], gspec.upper[j]
        rng = rf"\[{lo:g}, {hi:g}\]"
        bad = np.array(good, np.float32)
        bad[1, j] = hi + 1.0
        with pytest.raises(ValueError, match=rf"'{gene}'.*{rng}"):
            gen.render(bad)
        bad[1, j] = lo - 1.0
        with pytest.raises(ValueError, match=rf"'{gene}'.*{rng}"):
            gen.render(bad)
        bad[1, j] = np.nan
        with pytest.raises(ValueError, match=rf"'{gene}'.*{rng}"):
            gen.render(bad)
        if gspec.integer[j]:
            bad[1, j] = lo + 0.5
            with pytest.raises(ValueError, match=rf"'{gene}'.*integer.*{rng}"):
                gen.render(bad)


@pytest.mark.parametrize("name", VECTOR)
def test_mutation_statistics(name):
    gen = _gen(name)
    gspec = gen.spec
    n = 4000
    parents = jnp.tile(jnp.asarray(_mid_genome(gspec)), (n, 1))
    children = np.asarray(jax.jit(gen.mutate)(jax.random.PRNGKey(3), parents))
    parents = np.asarray(parents)
    lo, hi = np.asarray(gspec.lower), np.asarray(gspec.upper)
    assert children.shape == parents.shape and children.dtype == np.float32
    assert (children >= lo).all() and (children <= hi).all()
    ints = np.asarray(gspec.integer)
    np.testing.assert_array_equal(children[:, ints], np.round(children[:, ints]))
    gen.validate(children)  # mutated genomes (after any repair) stay valid
    changed = children != parents
    # Continuous genes at mid-range change with probability exactly p (the paper: 0.35 for the noise generators,
    # 0.07 for the GAN's latent); integer genes only when the Gaussian step (sigma = 10 % of the range) rounds to a
    # non-zero integer: p * P(|N(0, sigma)| >= 0.5).
    p = MUTATION_PROB.get(name, 0.35)
    sigma = 0.1 * (hi - lo)
    p_round = np.array([math.erfc(0.5 / (s * math.sqrt(2))) for s in sigma])
    expected = np.where(ints, p * p_round, p)
    tol = 4.5 * np.sqrt(expected * (1 - expected) / n)
    for j, gene in enumerate(gspec.names):
        if name == "worley" and gene == "D":
            continue  # the D <= N / 4 repair also moves D; checked in test_worley_repair
        assert abs(changed[:, j].mean() - expected[j]) < tol[j], (gene, changed[:, j].mean(), expected[j])
    # Over all continuous genes the fraction is 0.35 within statistical tolerance.
    cont = ~ints
    if cont.any():
        frac = changed[:, cont].mean()
        assert abs(frac - p) < 4.5 * np.sqrt(p * (1 - p) / (n * cont.sum()))
    # Step size: the non-zero moves of continuous genes have std ~ sigma (clipping is negligible at mid-range);
    # per gene within 5 standard errors of a std estimate (~1 / sqrt(2 count)), and pooled over genes within 5 %.
    pooled = []
    for j in np.flatnonzero(cont):
        moves = (children - parents)[changed[:, j], j] / sigma[j]
        assert abs(moves.std() - 1.0) < 5 / np.sqrt(2 * moves.size)
        pooled.append(moves)
    if pooled:
        assert abs(np.concatenate(pooled).std() - 1.0) < 0.05


@pytest.mark.parametrize("name", VECTOR)
def test_no_retrace_when_batch_content_changes(name):
    gen = _gen(name)
    traces = []

    @jax.jit
    def f(genomes):
        traces.append(1)  # runs only while tracing
        return jax.vmap(gen.render_one)(genomes)

    first = gen.sample(jax.random.PRNGKey(4), B)
    a = f(first)
    b = f(gen.sample(jax.random.PRNGKey(5), B))
    assert len(traces) == 1
    assert not np.array_equal(np.asarray(a), np.asarray(b))
    # Same program as the public render path.
    np.testing.assert_array_equal(np.asarray(a), np.asarray(gen.render(first)))
    # The public render path (jit inside) does not re-trace either: compare its cache size.
    render_jit = _find_jitted(gen.render)
    if render_jit is not None:
        size_before = render_jit._cache_size()
        gen.render(gen.sample(jax.random.PRNGKey(7), B))
        assert render_jit._cache_size() == size_before


def _find_jitted(fn):
    for cell in getattr(fn, "__closure__", None) or ():
        obj = cell.cell_contents
        if hasattr(obj, "_cache_size"):
            return obj
    return None


def test_default_size_is_256():
    # Worley renders the same code at every size; at 256 it is too slow on CPU (26 M distances per map) for this
    # file, so only its default size is checked here.
    assert generators.get("worley").size == 256
    for name, genome in (
        ("perlin", [40, 5, 0.5, 2, 3]),
        ("diamond_square", [-0.6, 0.2, 0.4, 1.0, 10, 2, 5]),
    ):
        gen = generators.get(name)
        assert gen.size == 256
        m = gen.render(jnp.array([genome] * B, jnp.float32))
        assert m.shape == (B, 256, 256) and m.dtype == jnp.float32
        m = np.asarray(m)
        assert 0.0 <= m.min() and m.max() <= 1.0 and m.std() > 1e-3


# ---------------------------------------------------------------------------------------------------------------
# Perlin
# ---------------------------------------------------------------------------------------------------------------


def _radial_power(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Power spectrum of a square map (Hann-windowed against edge leakage): (radial frequency in cycles / px, power)."""
    n = m.shape[0]
    w = np.hanning(n)
    p = np.abs(np.fft.fft2((m - m.mean()) * (w[:, None] * w[None, :]))) ** 2
    f = np.fft.fftfreq(n)
    r = np.hypot(f[:, None], f[None, :])
    return r.ravel(), p.ravel()


def _perlin256(genomes) -> np.ndarray:
    return np.asarray(generators.get("perlin").render(jnp.array(genomes, jnp.float32)))


def test_perlin_one_octave_power_at_feature_scale():
    maps = _perlin256([[4.0, 1, 0.5, 2.0, 0], [4.0, 1, 0.5, 2.0, 1], [16.0, 1, 0.5, 2.0, 0], [16.0, 1, 0.5, 2.0, 1]])
    bins = np.linspace(0, 0.5, 65)
    for scale, pair in ((4.0, maps[:2]), (16.0, maps[2:])):
        p = 0
        for m in pair:
            r, pm = _radial_power(m)
            p = p + pm
        # Perlin noise with lattice spacing s is band-limited around 1 / s: its radial spectrum peaks near
        # 0.6 / s, most power lies between 1 / (4s) and 2 / s and almost none above 4 / s.
        profile = np.bincount(np.digitize(r, bins), p, minlength=66)[1:65] / np.maximum(
            np.bincount(np.digitize(r, bins), minlength=66)[1:65], 1
        )
        peak = bins[np.argmax(profile)] + 0.5 * (bins[1] - bins[0])
        assert 0.3 / scale < peak < 1.5 / scale, (scale, peak)
        band = (r > 0.25 / scale) & (r < 2.0 / scale)
        assert p[band].sum() / p.sum() > 0.8, scale
        assert p[r > 4.0 / scale].sum() / p.sum() < 1e-3, scale
    # Fixed affine map of noise in [-1, 1]: centred on 0.5, not stretched to [0, 1] per map.
    assert 0.4 < maps.mean() < 0.6
    assert (maps.reshape(4, -1).min(axis=1) > 0.0).all() and (maps.reshape(4, -1).max(axis=1) < 1.0).all()


def test_perlin_octaves_and_normalisation():
    maps = _perlin256([[32.0, o, 0.6, 2.0, seed] for o, seed in ((1, 11), (3, 11), (6, 11), (6, 12))])
    hf = []
    for m in maps[:3]:
        r, p = _radial_power(m)
        hf.append(p[r > 2.0 / 32.0].sum() / p.sum())
    assert hf[0] < 0.01 < hf[1] < hf[2]  # more octaves add high-frequency energy
    rough = [np.abs(np.diff(m, axis=1)).mean() for m in maps[:3]]
    assert rough[0] < rough[1] < rough[2]
    # The first octave keeps its weight (fixed normalisation, octaves masked not re-scaled per map): the coarse
    # structure of the 1-octave map survives in the 3-octave map of the same seed ...
    assert np.corrcoef(maps[0].ravel(), maps[1].ravel())[0, 1] > 0.6
    # ... while another seed gives another lattice.
    assert abs(np.corrcoef(maps[2].ravel(), maps[3].ravel())[0, 1]) < 0.3
    # Octaves have their own lattices: with lacunarity 1 nine octaves average nine independent noises, which
    # shrinks the amplitude, where identical octaves would leave it unchanged.
    one, many = _perlin256([[20, 1, 0.9, 1, 3], [20, 9, 0.9, 1, 3], [20, 9, 0.9, 1, 4], [20, 9, 0.9, 1, 5]])[:2]
    assert (many - 0.5).std() < 0.75 * (one - 0.5).std()


def test_perlin_vmap_mixed_octaves_matches_single():
    gen = _gen("perlin")
    genomes = [[10, 1, 0.5, 2, 0], [50, 9, 0.8, 2.7, 5], [3, 4, 0.3, 1.5, 99], [99, 7, 0.1, 3, 100]]
    genomes = jnp.array(genomes, jnp.float32)
    batch = np.asarray(gen.render(genomes))
    single = jax.jit(gen.render_one)
    for i in range(len(genomes)):
        np.testing.assert_array_equal(batch[i], np.asarray(single(genomes[i])))


# ---------------------------------------------------------------------------------------------------------------
# Diamond-square
# ---------------------------------------------------------------------------------------------------------------

_ds_grid = jax.jit(ds_mod.diamond_square_grid, static_argnums=1)


def test_diamond_square_corners_crop_and_level_d():
    gen = generators.get("diamond_square")
    genome = [-0.8, 0.2, 0.6, -0.4, 10.0, 3.0, 7.0]
    grid = np.asarray(_ds_grid(jnp.array(genome, jnp.float32), 8))
    assert grid.shape == (257, 257)
    np.testing.assert_array_equal(grid[[0, 0, -1, -1], [0, -1, 0, -1]], np.float32(genome[:4]))
    zero = [0.0, 0.0, 0.0, 0.0, 0.0]
    maps = np.asarray(gen.render(jnp.array([genome, zero + [1, 0], zero + [10, 0], zero + [10, 1]], jnp.float32)))
    # Heightmap = the 257-grid without its last row / column, mapped by the fixed affine map (v + 1) / 2.
    np.testing.assert_allclose(maps[0, 0, 0], (-0.8 + 1) / 2, rtol=1e-6)
    np.testing.assert_allclose(maps[0], np.clip((grid[:256, :256] + 1) / 2, 0, 1), atol=1e-6)
    # Larger D shrinks the random offsets faster -> smoother map (same seed, same uniforms).
    rough = [np.abs(np.diff(m, axis=1)).mean() for m in maps[1:]]
    assert rough[1] < 0.5 * rough[0] and rough[2] < 0.5 * rough[0]
    with pytest.raises(ValueError, match="power of two"):
        generators.get("diamond_square", size=100)


def test_diamond_square_two_iterations_by_hand():
    """A 5 x 5 grid (2 iterations) against a direct transcription of the paper's steps."""
    c = np.array([0.5, -0.3, 0.9, 0.1], np.float32)
    for z, d, seed in ((20.0, 2.0, 4), (50.0, 7.0, 0)):
        grid = np.asarray(_ds_grid(jnp.array([*c, z, d, seed], jnp.float32), 2))
        u = np.asarray(jax.random.uniform(jax.random.PRNGKey(seed), (2, 5, 5), jnp.float32))
        p = (z + u[0] * (100 - 2 * z)) / 100  # Z = 50 gives P = 0.5 exactly
        exp = np.full((5, 5), np.nan, np.float32)
        exp[0, 0], exp[0, 4], exp[4, 0], exp[4, 4] = c
        for steps, half in ((0, 2), (1, 1)):
            r = 1.0 / (steps * d + 1.0)  # 1 in the first iteration, then 1 / (D + 1)
            known = lambda i, j: 0 <= i < 5 and 0 <= j < 5 and not np.isnan(exp[i, j])  # noqa: E731
            # Diamond step: square midpoints from the 4 square corners.
            for i in range(half, 5, 2 * half):
                for j in range(half, 5, 2 * half):
                    nb = [exp[i + a, j + b] for a in (-half, half) for b in (-half, half)]
                    exp[i, j] = p[i, j] * np.mean(nb) + r * (u[1, i, j] * 2 - 1)
            # Square step: diamond midpoints from the neighbours that exist (3 on the border, no wrap-around).
            new = {}
            for i in range(0, 5, half):
                for j in range(0, 5, half):
                    if (i // half + j // half) % 2 == 1:
                        steps4 = ((-half, 0), (half, 0), (0, -half), (0, half))
                        nb = [exp[i + a, j + b] for a, b in steps4 if known(i + a, j + b)]
                        assert len(nb) in (3, 4)
                        new[i, j] = p[i, j] * np.mean(nb) + r * (u[1, i, j] * 2 - 1)
            for (i, j), v in new.items():
                exp[i, j] = v
        np.testing.assert_allclose(grid, exp, rtol=1e-5, atol=1e-6)


# ---------------------------------------------------------------------------------------------------------------
# Worley
# ---------------------------------------------------------------------------------------------------------------

_worley_distance = jax.jit(worley_mod.worley_distance, static_argnums=(1, 2))


def _worley_reference(genome, size):
    seed, n, d = (int(v) for v in genome)
    pts = np.asarray(worley_mod.feature_points(jnp.float32(seed), size))[:n]
    yy, xx = np.mgrid[:size, :size].astype(np.float32)
    d2 = (yy[..., None] - pts[None, None, :, 1]) ** 2 + (xx[..., None] - pts[None, None, :, 0]) ** 2
    return np.sqrt(np.sort(d2.astype(np.float32), axis=-1)[..., d])


@pytest.mark.parametrize("select", ["bisect", "sort", "bracket", "tiled", "pallas"])
def test_worley_exact_against_numpy_sort(select):
    # "bracket" / "tiled" are exact except within TOLERANCE (1e-3 px) of a near-tie between two different distances.
    atol = worley_mod.TOLERANCE if select in ("bracket", "tiled") else 0.0
    for genome in ([3, 50, 12], [7, 400, 100], [1, 2, 0], [100, 9, 2]):
        got = np.asarray(_worley_distance(jnp.array(genome, jnp.float32), SIZE, select))
        # Exact selection; the last bit of a squared distance may differ from numpy's where XLA fuses the
        # multiply-add (FMA), hence rtol = 1 ulp-ish rather than bit equality.
        np.testing.assert_allclose(got, _worley_reference(genome, SIZE), rtol=3e-7, atol=atol)


def _kth_reference(dy2, dx2, d):
    """NumPy D-th smallest squared distance per pixel, [H, W]."""
    d2 = np.asarray(dy2)[:, None, :] + np.asarray(dx2)[None, :, :]
    return np.sort(d2, axis=-1)[..., d]


def _check_fast(got_d2, ref_d2, select):
    got, ref = np.sqrt(np.asarray(got_d2, np.float64)), np.sqrt(ref_d2.astype(np.float64))
    if select == "pallas":  # returns the D-th value itself, computed as the reference does: bit for bit
        np.testing.assert_array_equal(np.asarray(got_d2), ref_d2)
    elif select == "bisect":
        np.testing.assert_allclose(got, ref, rtol=3e-7, atol=0)
    else:
        err = np.abs(got - ref)
        assert err.max() < worley_mod.TOLERANCE, err.max()
        assert (err <= 1e-6 * np.maximum(ref, 1.0)).mean() > 0.99  # exact but for near-ties


_kth_jit = {s: jax.jit(worley_mod._KTH[s]) for s in ("bisect", "bracket", "tiled", "pallas")}


@pytest.mark.parametrize("select", ["bisect", "bracket", "tiled", "pallas"])
def test_worley_fast_select_matches_sort_with_ties(select):
    # Point sets built directly (the seeded points are all distinct): duplicated points (D-th value repeated),
    # integer points on the pixel grid (many exact distance ties and zero distances), N = 2 and N = 400, with
    # D = 0 and D = N / 4.
    rng = np.random.default_rng(0)
    pix = np.arange(SIZE, dtype=np.float32)

    def terms(pts, n):
        dx2 = (pix[:, None] - pts[None, :, 0]) ** 2
        dy2 = (pix[:, None] - pts[None, :, 1]) ** 2
        dx2 = np.where(np.arange(len(pts))[None, :] < n, dx2, np.inf).astype(np.float32)
        return dy2.astype(np.float32), dx2

    dup = np.repeat(rng.uniform(0, SIZE, (100, 2)), 4, axis=0).astype(np.float32)  # 400 points, each 4 times
    grid = rng.integers(0, SIZE, (400, 2)).astype(np.float32)  # on pixel centres, with repeats
    uni = rng.uniform(0, SIZE, (400, 2)).astype(np.float32)
    cases = [(dup, 400, 0), (dup, 400, 100), (dup, 400, 37), (grid, 400, 100), (grid, 400, 0), (grid, 40, 10),
             (uni, 2, 0), (uni, 400, 100), (uni, 400, 0), (uni, 3, 0)]
    for pts, n, d in cases:
        dy2, dx2 = terms(pts, n)
        got = _kth_jit[select](jnp.asarray(dy2), jnp.asarray(dx2), jnp.float32(d))
        _check_fast(got, _kth_reference(dy2, dx2, d), select)


@pytest.mark.parametrize("select", ["bisect", "bracket", "tiled"])
def test_worley_fast_select_matches_sort_random_genomes(select):
    gen = _gen("worley")
    genomes = np.asarray(jax.jit(gen.sample, static_argnums=1)(jax.random.PRNGKey(5), 6))
    edges = np.array([[3, 2, 0], [7, 400, 100], [11, 400, 0], [42, 200, 50]], np.float32)
    genomes = jnp.asarray(np.concatenate([edges, genomes]))
    dist = jax.jit(jax.vmap(lambda g: worley_mod.worley_distance(g, SIZE, select)))
    ref = np.asarray(jax.jit(jax.vmap(lambda g: worley_mod.worley_distance(g, SIZE, "sort")))(genomes))
    got = np.asarray(dist(genomes))
    _check_fast(got**2, ref**2, select)
    maps = np.asarray(worley_mod.worley(SIZE, select=select).render(genomes))
    ref_maps = np.asarray(_gen("worley").render(genomes))
    assert np.abs(maps - ref_maps).max() < 1e-4 and (maps.max(axis=(1, 2)) == 1.0).all()


def test_worley_tiled_equals_bracket_and_falls_back_on_overflow(monkeypatch):
    """"tiled" is "bracket" over per-tile candidate lists: the same values, bit for bit. With 8 slots per tile, the
    maps of many points overflow their lists and are redone by "bracket" inside the same vmapped call."""
    genomes = jnp.asarray([[3, 400, 100], [7, 3, 0], [11, 400, 0], [42, 200, 50], [5, 2, 0]], jnp.float32)

    def run(select):
        return np.asarray(jax.jit(jax.vmap(lambda g: worley_mod.worley_distance(g, SIZE, select)))(genomes))

    bracket = run("bracket")
    np.testing.assert_array_equal(run("tiled"), bracket)
    monkeypatch.setattr(worley_mod, "_CAP_GROUPS", (8,))

    def overflow(g):
        dy2, dx2 = worley_mod._separable_d2(g, SIZE)
        lo, hi, _ = worley_mod._bracket_bounds(dy2, dx2, jnp.round(g[2]))
        return worley_mod._tile_lists(dy2, dx2, lo, hi, worley_mod._TILE, 8)[3]

    flags = np.asarray(jax.jit(jax.vmap(overflow))(genomes))  # one compile, not one per operation
    assert flags.any() and not flags.all(), flags  # a mixed batch: both paths are exercised
    np.testing.assert_array_equal(run("tiled"), bracket)


@pytest.mark.slow  # 10-70 s on 2 CPU cores; the default suite keeps under 15 min (2026-11-29)
def testworley_pallas_equals_sort_bit_for_bit(monkeypatch):
    """"pallas" (Pallas's interpreter on CPU) returns the D-th squared distance itself: equal to "sort" bit for bit,
    over random genomes, D = 0, D = N / 4, N = 2 and N = 400, in a batch whose dense maps overflow their tile lists
    at 64 x 64 and are redone by the same kernel over all points; its candidate lists equal the XLA ones."""
    gen = _gen("worley")
    rnd = np.asarray(jax.jit(gen.sample, static_argnums=1)(jax.random.PRNGKey(9), 4))
    genomes = jnp.asarray(np.concatenate([[[3, 400, 100], [7, 3, 0], [11, 400, 0], [5, 2, 0], [8, 60, 15]], rnd]),
                          jnp.float32)

    def run(select):
        return np.asarray(jax.jit(jax.vmap(lambda g: worley_mod.worley_distance(g, SIZE, select)))(genomes))

    np.testing.assert_array_equal(run("pallas"), run("sort"))

    def lists(g, pallas):
        dy2, dx2 = worley_mod._separable_d2(g, SIZE)
        lo, hi, _ = worley_mod._bracket_bounds(dy2, dx2, jnp.round(g[2]))
        return worley_mod._tile_lists(dy2, dx2, lo, hi, worley_mod._TILE, 96, pallas)

    xla, ker = (jax.jit(jax.vmap(lambda g, p=p: lists(g, p)))(genomes) for p in (False, True))  # one compile each
    flags = np.asarray(xla[3])
    assert flags.any() and not flags.all(), flags  # a mixed batch: the fallback and the lists are both exercised
    for a, b in zip(xla[1:], ker[1:]):  # n_cand, inside, overflow
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    used = np.arange(96) < np.minimum(np.asarray(xla[1]), 96)[..., None]
    np.testing.assert_array_equal(np.asarray(xla[0])[used], np.asarray(ker[0])[used])
    # With one sorted slot the kernel must still be exact (more bisections, then the same selection); this run
    # also takes the two-kernel path (lists, then selection) instead of the fused one.
    monkeypatch.setattr(worley_mod.worley_pallas, "TOP_K", 1)
    monkeypatch.setattr(worley_mod.worley_pallas, "FUSED", not worley_mod.worley_pallas.FUSED)
    np.testing.assert_array_equal(run("pallas"), run("sort"))


def test_worley_auto_select_is_bracket_off_gpu():
    assert worley_mod.DEFAULT_SELECT == "auto"
    genomes = jnp.asarray([[3, 400, 100], [7, 30, 5]], jnp.float32)
    cpu = jax.devices("cpu")[0]
    got = {s: np.asarray(jax.jit(jax.vmap(lambda g, s=s: worley_mod.worley_distance(g, SIZE, s)))(
        jax.device_put(genomes, cpu))) for s in ("auto", "bracket")}
    np.testing.assert_array_equal(got["auto"], got["bracket"])


def test_worley_bracket_structure():
    assert worley_mod.bracket_iterations(256) == 14 and worley_mod.bracket_iterations(64) == 14
    assert 2 * 4 * math.sqrt(2) / 2**14 < worley_mod.TOLERANCE  # the final bracket is narrower than TOLERANCE
    with pytest.raises(ValueError, match="select must be one of"):
        worley_mod.worley(SIZE, select="median")
    # The loop must not carry a hoisted [B, H, W, 400] distance tensor (XLA's loop-invariant code motion did, which
    # made each trip re-read it from memory): no while loop in the optimised HLO carries an f32 [4, 64, 64, ...]
    # distance tensor (the points are grouped as 16 x 25 in the reductions).
    for select in ("bisect", "bracket", "tiled"):
        fn = jax.jit(jax.vmap(lambda g, s=select: worley_mod.worley_distance(g, SIZE, s)))
        hlo = fn.lower(jnp.zeros((4, 3), jnp.float32)).compile().as_text()
        loops = [line for line in hlo.splitlines() if " while(" in line]
        assert loops and not any(re.search(r"f32\[4,64,64,(400|16,25)\]", line) for line in loops), select
        # Nor does any buffer of the whole computation hold one: XLA's temp memory is < 1/4 of one such tensor.
        temp = fn.lower(jnp.zeros((4, 3), jnp.float32)).compile().memory_analysis().temp_size_in_bytes
        assert temp < 4 * SIZE * SIZE * 400 * 4 / 4, (select, temp)


def test_worley_normalisation_and_structure():
    gen = _gen("worley")
    genomes = jnp.array([[5, 20, 0], [5, 200, 0], [5, 200, 50], [5, 400, 100]], jnp.float32)
    maps = np.asarray(gen.render(genomes))
    raw = [np.asarray(_worley_distance(g, SIZE, "sort")) for g in genomes]
    for m, rw in zip(maps, raw):
        assert m.max() == 1.0  # divided by its own max
        # rtol for the default select; atol so that the test also holds with DEFAULT_SELECT = "bracket".
        np.testing.assert_allclose(m, rw / rw.max(), rtol=1e-6, atol=worley_mod.TOLERANCE / rw.max())
    assert raw[1].mean() < 0.5 * raw[0].mean()  # more points -> nearer nearest point (~1 / sqrt(N))
    assert raw[2].mean() > 3 * raw[1].mean()  # the 51st nearest is farther than the nearest

    def minima(m):  # F1 has a local minimum near each feature point: more points, more minima
        c = m[1:-1, 1:-1]
        nb = [m[1 + dy : m.shape[0] - 1 + dy, 1 + dx : m.shape[1] - 1 + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
        return int((c <= np.min(nb, axis=0)).sum())

    assert 5 < minima(raw[0]) < minima(raw[1])


def test_worley_repair_and_d_constraint():
    gen = _gen("worley")
    with pytest.raises(ValueError, match=r"'D'.*\[0, floor\(N / 4\)\] = \[0, 2\]"):
        gen.render(jnp.array([[1, 10, 3]], jnp.float32))
    gen.validate(np.array([[1, 10, 2], [0, 400, 100], [0, 3, 0]], np.float32))
    g = np.asarray(jax.jit(gen.sample, static_argnums=1)(jax.random.PRNGKey(8), 2000))
    assert (g[:, 2] <= np.floor(g[:, 1] / 4)).all() and (g[:, 2] >= 0).all()
    assert len(np.unique(g[:, 2])) > 50  # D still covers its range
    gen.validate(g)
    repaired = np.asarray(worley_mod.repair(jnp.array([[1, 10, 7], [1, 400, 100], [1, 2, 0]], jnp.float32)))
    np.testing.assert_array_equal(repaired[:, 2], [2, 100, 0])
    gen.validate(np.asarray(jax.jit(gen.mutate)(jax.random.PRNGKey(9), jnp.asarray(g))))


def test_worley_vmap_mixed_n_matches_single():
    gen = _gen("worley")
    genomes = jnp.array([[0, 2, 0], [0, 400, 100], [17, 33, 8], [99, 150, 1]], jnp.float32)
    batch = np.asarray(gen.render(genomes))
    single = jax.jit(gen.render_one)
    for i in range(len(genomes)):
        np.testing.assert_array_equal(batch[i], np.asarray(single(genomes[i])))
    # The first N points of a seed do not depend on N: F1 with N points is >= F1 with more points.
    few = np.asarray(_worley_distance(jnp.array([3, 10, 0], jnp.float32), SIZE, "sort"))
    more = np.asarray(_worley_distance(jnp.array([3, 40, 0], jnp.float32), SIZE, "sort"))
    assert (more <= few).all() and (more < few).any()


@pytest.mark.parametrize("name, options", [("diamond_square", {}), ("cppn", {"max_nodes": 8, "max_connections": 16})])
def test_render_temporaries_do_not_grow_with_the_batch(name, options):
    """``render`` runs larger batches as lax.map over chunks: XLA's temporaries at 8 chunks are those of one chunk
    (only the output grows). Compile-only (memory_analysis of the lowered program), 32 x 32 maps."""
    gen = generators.get(name, size=32, **options)
    chunk = generators.RENDER_CHUNK if name != "cppn" else generators.cppn.render_chunk(options["max_nodes"])
    proto = gen.sample(jax.random.PRNGKey(0), 1)

    def temp_bytes(b):
        x = jax.tree.map(lambda a: jax.ShapeDtypeStruct((b,) + a.shape[1:], a.dtype), proto)
        stats = jax.jit(gen.render).lower(x).compile().memory_analysis()
        if stats is None:
            pytest.skip("no memory analysis on this backend")
        return stats.temp_size_in_bytes

    one, eight = temp_bytes(chunk), temp_bytes(8 * chunk)
    assert eight <= 1.25 * one + (1 << 20), (one, eight)

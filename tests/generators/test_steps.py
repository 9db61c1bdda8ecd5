"""The ``steps`` generator (vertical structure, issue 64 item 2): faces of the genome's riser height, maps in [0, 1]
within the relief budget, a flat start strip, determinism, jit / vmap, mutation in bounds. Physics-free.

The generic properties of every vector generator (shapes, gene errors, mutation statistics, no re-trace) run on it
in ``test_generators.py``; here the 256 x 256 maps at the default scale (4 cm pixels, 1 m per heightmap unit)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxterrain import features, generators
from jaxterrain.generators import steps as steps_mod
from jaxterrain.terrain import TerrainScale

SCALE = TerrainScale()  # the default: 0.04 m pixels, 1.0 m per heightmap unit
SIZE = 256
STRIP = steps_mod.strip_cells(SIZE)  # 25 pixels = 1.0 m
COURSE = (SIZE - 2 * STRIP) * SCALE.cell_size  # metres along x between the strips
SPEC = steps_mod.STEPS_SPEC
# Float32 rounding of BASE + k * riser (heightmap values near 1): a few ulps, 1e-6; in metres at 1 m per unit.
TOL = 1e-5


def genome(**genes) -> np.ndarray:
    """Mid-range genes, every section off (share 0), no noise, then ``genes``. [21] float32."""
    g = (np.asarray(SPEC.lower) + np.asarray(SPEC.upper)) / 2
    g = np.where(SPEC.integer, np.floor(g), g)
    for name in steps_mod.PRIMITIVES + ("noise",):
        g[SPEC.index(name)] = 0.0
    for name, value in genes.items():
        g[SPEC.index(name)] = value
    return g.astype(np.float32)


@pytest.fixture(scope="module")
def gen():
    return generators.get("steps")


def _jumps(row: np.ndarray) -> np.ndarray:
    """Metres between neighbouring pixels of one row (along +x, the walk). [W - 1]."""
    return np.diff(row.astype(np.float64)) * SCALE.height


def test_registered_with_its_genome(gen):
    assert "steps" in generators.names() and gen.size == SIZE and gen.spec is SPEC and SPEC.size == 21
    ints = {n for n, i in zip(SPEC.names, SPEC.integer) if i}
    assert ints == {"seed", "steps"}
    assert SPEC.lower[SPEC.index("riser")] == 0.02 and SPEC.upper[SPEC.index("riser")] == 0.25
    assert STRIP == 25 and steps_mod.strip_cells(64) == 8 and steps_mod.strip_cells(32) == 4


@pytest.mark.parametrize("riser,tread,steps,sign", [(0.10, 0.30, 4, 0.5), (0.17, 0.25, 8, 1.0), (0.05, 0.5, 3, -0.3),
                                                    (0.23, 0.2, 8, 0.0), (0.02, 0.2, 8, -1.0)])
def test_risers_are_single_pixel_faces_of_the_genome_riser_height(gen, riser, tread, steps, sign):
    """Stairs alone over the whole course: along a row (the walk) and along a column (a turned heading) the only
    height changes are the 2 n risers, each one pixel-to-pixel jump of exactly ``riser`` metres (within TOL, float32
    rounding), up then down for a ridge (sign >= 0), down then up for a well; n = min(steps, floor(0.5 m / riser));
    the first riser one tread in from the course's side."""
    m = np.asarray(gen.render(genome(stairs=1.0, riser=riser, tread=tread, steps=steps, stair_sign=sign, seed=7)))
    n = min(steps, int(np.floor(0.5 / riser + 1e-4)))
    assert 2 * n * tread < COURSE  # the section holds the whole flight
    up = 1.0 if sign >= 0 else -1.0
    # the walker's row, a row 2.4 m in from the course's side (beyond every flight's n * tread), the middle column
    for line in (m[SIZE // 2], m[STRIP + 60], m[:, SIZE // 2]):
        j = _jumps(line)
        faces = np.flatnonzero(np.abs(j) > TOL)
        assert faces.size == 2 * n, faces.size
        np.testing.assert_allclose(np.abs(j[faces]), riser, atol=TOL)
        np.testing.assert_array_equal(np.sign(j[faces]), [up] * n + [-up] * n)
        # first riser at u = tread: between pixels STRIP + floor(tread / cell) - 1 and the next (u lies on the grid)
        assert abs(faces[0] + 1 - (STRIP + tread / SCALE.cell_size)) <= 1
        # the landing at n risers
        np.testing.assert_allclose(line.max() if up > 0 else line.min(), 0.5 + up * n * riser, atol=TOL)
    # step_heights (the descriptor's per-pixel map) reads the same riser at the faces, in metres.
    s = np.asarray(features.step_heights(m)) * SCALE.height
    np.testing.assert_allclose(s[SIZE // 2][s[SIZE // 2] > TOL], riser, atol=TOL)


def test_riser_in_metres_at_another_height_scale():
    """A riser of r metres is a jump of r / height heightmap units: at 0.5 m per unit, 0.1 m is 0.2."""
    half = generators.get("steps", height=0.5)
    m = np.asarray(half.render(genome(stairs=1.0, riser=0.1, tread=0.4, steps=2, stair_sign=1.0)))
    j = np.diff(m[SIZE // 2].astype(np.float64))
    np.testing.assert_allclose(np.abs(j[np.abs(j) > TOL]), [0.2] * 4, atol=TOL)
    with pytest.raises(ValueError, match="height"):
        generators.get("steps", height=0.0)


def test_trenches_stones_boxes_and_ramp_have_their_genome_sizes(gen):
    """One primitive per map over the whole course, measured along the walker's row in metres."""
    g = np.stack([
        genome(trenches=1.0, trench_width=0.4, trench_spacing=1.0, pit_length=10.5, pit_depth=0.3),
        genome(stones=1.0, stone_size=0.6, stone_gap=0.2, pit_depth=0.45),
        genome(boxes=1.0, box_height=0.2, box_size=0.5, box_density=1.0),
        genome(ramp=1.0, grade=0.2),
    ])
    m = np.asarray(gen.render(g)).astype(np.float64) * SCALE.height
    row = SIZE // 2
    base = 0.5 * SCALE.height
    # Trenches: 0.3 m deep, 0.4 m (10 pixels) wide, one every 1.4 m; whole periods only.
    t = m[0, row] < base - TOL
    np.testing.assert_allclose(m[0, row][t], base - 0.3, atol=TOL)
    edges = np.flatnonzero(np.diff(t.astype(int)))
    widths = edges[1::2] - edges[::2]
    # edges on the pixel grid fall either side of a multiple of 0.04 m in float32: within one pixel
    assert len(widths) == int(COURSE / 1.4) and set(widths.tolist()) <= {9, 10, 11}
    assert t[: STRIP + 25].sum() == 0  # 1.0 m of ground before the first
    # pit_length >= the course's width: every trench crosses the whole course.
    np.testing.assert_allclose(m[0, STRIP:SIZE - STRIP][:, t].max(axis=0), base - 0.3, atol=TOL)
    # Stones: gaps 0.45 m deep, stones of 0.6 m (15 pixels) at a 0.8 m pitch along the walker's row or rows of gap.
    s = m[1, STRIP:SIZE - STRIP, STRIP:SIZE - STRIP]
    assert set(np.round(np.unique(s), 5)) == {round(base - 0.45, 5), round(base, 5)}
    region = s[:, :int(COURSE / 0.8) * 20] < base - TOL  # the whole 0.8 m periods (20 pixels each)
    assert 0.15 < region.all(axis=1).mean() < 0.35  # rows of gap across the stones: 0.2 of every 0.8 m
    assert 0.2 <= region.all(axis=0).mean() <= 0.3  # columns of gap: 5 of every 20 pixels
    # Boxes: every box between 0.1 and 0.2 m tall (density 1: every cell of the grid holds one).
    b = m[2, STRIP:SIZE - STRIP, STRIP:SIZE - STRIP] - base
    assert b.min() >= 0.1 - TOL and b.max() <= 0.2 + TOL and np.unique(np.round(b, 5)).size > 10
    # Ramp: 0.2 rise per metre (0.008 per pixel), up to the 0.5 m budget, no face.
    r = _jumps(m[3, row])
    assert np.abs(r).max() == pytest.approx(0.2 * SCALE.cell_size, abs=TOL)
    assert m[3, row].max() == pytest.approx(base + 0.5, abs=TOL)


def test_maps_in_unit_range_within_the_relief_budget_and_traversable(gen):
    """Random, mutated and extreme genomes: maps in [0, 1]; highest minus lowest point at most ROOM = 0.5 m, so
    every map passes Algorithm 1 for the humanoid at the default scale."""
    key = jax.random.PRNGKey(0)
    g = gen.sample(key, 48)
    g = jnp.concatenate([g, gen.mutate(jax.random.PRNGKey(1), g),
                         jnp.asarray([SPEC.lower, SPEC.upper], jnp.float32)])
    extreme = np.asarray(SPEC.upper, np.float32)
    extreme[SPEC.index("stair_sign")] = -1.0  # a well as deep as the budget allows, and every pit
    g = jnp.concatenate([g, jnp.asarray(extreme)[None]])
    m = np.asarray(gen.render(g))
    assert m.min() >= 0.0 and m.max() <= 1.0
    relief = (m.reshape(len(m), -1).max(1) - m.reshape(len(m), -1).min(1)) * SCALE.height
    assert relief.max() <= steps_mod.ROOM + TOL
    assert relief.max() > 0.4  # the budget is used, not left idle
    assert np.asarray(features.is_traversable(m)).all()


def test_start_strip_flat_on_every_edge(gen):
    """The strip of 25 pixels (1.0 m) along every edge is exactly BASE, the course inside is not flat."""
    m = np.asarray(gen.render(gen.sample(jax.random.PRNGKey(3), 16)))
    ring = np.ones((SIZE, SIZE), bool)
    ring[STRIP:SIZE - STRIP, STRIP:SIZE - STRIP] = False
    assert (m[:, ring] == steps_mod.BASE).all()
    assert (m[:, STRIP:SIZE - STRIP, STRIP:SIZE - STRIP].std(axis=(1, 2)) > 1e-3).all()
    # the walker's spawn (0.5 m and 1.0 m from the left edge, a 0.5 m patch) lies on it
    assert STRIP * SCALE.cell_size >= 1.0
    # small maps keep a strip of size // 8
    small = np.asarray(generators.get("steps", size=32).render(gen.sample(jax.random.PRNGKey(3), 4)))
    assert (small[:, :, :4] == steps_mod.BASE).all() and (small[:, :, -4:] == steps_mod.BASE).all()


def test_noise_alone_makes_no_face_and_bends_a_riser_within_its_bound(gen):
    """Noise of amplitude a changes neighbouring pixels by at most 3 a cell / 0.2 m (bilinear on a 0.2 m lattice,
    faded in over one lattice cell): 0.036 m at the largest a = 0.06, under FACE_THRESHOLD; on stairs a riser reads
    riser +- that bound."""
    a = SPEC.upper[SPEC.index("noise")]
    bound = 3 * a * SCALE.cell_size / steps_mod.NOISE_CELL
    keys = range(5)
    m = np.asarray(gen.render(np.stack([genome(noise=a, seed=s) for s in keys]
                                       + [genome(noise=a, stairs=1.0, riser=0.12, tread=0.3, steps=3, seed=9)])))
    s = np.asarray(features.step_heights(m)) * SCALE.height
    assert 0.5 * bound < s[:5].max() <= bound + TOL < features.FACE_THRESHOLD
    assert np.asarray(features.descriptors(m[:5], names=("faces",), window=30, stride=2)).max() == 0.0
    j = _jumps(m[5, SIZE // 2])
    faces = np.abs(j) > features.FACE_THRESHOLD
    assert faces.sum() == 6  # n = min(3, floor((0.5 - 2 a) / 0.12)) = 3 up, 3 down
    assert np.abs(np.abs(j[faces]) - 0.12).max() <= bound + TOL


def test_sections_share_the_course(gen):
    """Sections are ``C * share / max(1, sum)`` long and do not overlap; shares under 1 leave flat ground at the
    end; the order follows the seed."""
    g = genome(stairs=0.2, ramp=0.1, boxes=0.3, trenches=0.1, stones=0.1, seed=11)
    starts, lengths = (np.asarray(a, np.float64) for a in steps_mod.section_bounds(g, COURSE))
    np.testing.assert_allclose(lengths, COURSE * np.array([0.2, 0.1, 0.3, 0.1, 0.1]), rtol=1e-5)
    order = np.argsort(starts)
    np.testing.assert_allclose(np.cumsum(lengths[order])[:-1], starts[order][1:], rtol=1e-5)
    assert starts[order][0] == 0.0 and (starts + lengths).max() == pytest.approx(0.8 * COURSE, rel=1e-5)
    g2 = genome(stairs=1.0, ramp=1.0, boxes=1.0, trenches=1.0, stones=1.0, seed=11)
    s2, l2 = (np.asarray(a) for a in steps_mod.section_bounds(g2, COURSE))
    np.testing.assert_allclose(l2, COURSE / 5, rtol=1e-5)
    orders = {tuple(np.argsort(np.asarray(steps_mod.section_bounds(genome(stairs=1.0, ramp=1.0, boxes=1.0,
                                                                           trenches=1.0, stones=1.0,
                                                                           seed=s), COURSE)[0])))
              for s in range(12)}
    assert len(orders) > 3


def test_deterministic_jit_and_vmap(gen):
    key = jax.random.PRNGKey(5)
    g = gen.sample(key, 6)
    np.testing.assert_array_equal(np.asarray(g), np.asarray(gen.sample(key, 6)))
    a = np.asarray(gen.render(g))
    np.testing.assert_array_equal(a, np.asarray(gen.render(np.asarray(g))))
    np.testing.assert_array_equal(a, np.asarray(jax.jit(jax.vmap(gen.render_one))(g)))
    # one genome, unbatched, and inside a lax.map (a scan)
    np.testing.assert_array_equal(a[2], np.asarray(gen.render(g[2])))
    np.testing.assert_array_equal(a, np.asarray(jax.jit(lambda x: jax.lax.map(gen.render_one, x))(g)))
    # the seed alone changes the map (order and random parts), the genome otherwise equal
    g2 = np.asarray(g).copy()
    g2[:, 0] = (g2[:, 0] + 1) % 101
    assert not np.array_equal(a, np.asarray(gen.render(g2)))


def test_mutation_keeps_genomes_in_bounds_and_switches_sections_off(gen):
    """Twenty generations of mutation from the lower and upper bounds: every gene within its (float32) range, the
    integer genes whole, ``validate`` passes; a share at its lower bound stays exactly 0 (a section switched off)
    with a positive probability, so MAP-Elites can remove a primitive."""
    lo, hi = np.float32(SPEC.lower), np.float32(SPEC.upper)
    g = jnp.asarray(np.concatenate([np.tile(lo, (128, 1)), np.tile(hi, (128, 1))]))
    mutate = jax.jit(gen.mutate)
    for t in range(20):
        g = mutate(jax.random.PRNGKey(100 + t), g)
        x = np.asarray(g)
        assert (x >= lo).all() and (x <= hi).all(), t
        ints = np.asarray(SPEC.integer)
        np.testing.assert_array_equal(x[:, ints], np.round(x[:, ints]))
    gen.validate(x)
    child = np.asarray(gen.mutate(jax.random.PRNGKey(9), np.tile(genome(stairs=0.0), (400, 1))))
    off = (child[:, SPEC.index("stairs")] == 0.0).mean()
    assert 0.75 < off < 0.9  # 1 - p + p / 2 = 0.825: unchanged, or moved below 0 and clipped back
    gen.render(x[:8])  # mutated genomes render


def test_faces_descriptor_sees_stairs_not_ramps(gen):
    """At the archive's window (30, stride 2): stairs give faces > 0 and a max_step of their riser where a window
    holds a face; the steepest ramp (0.024 m per pixel) gives none."""
    m = gen.render(np.stack([genome(stairs=1.0, riser=0.15, tread=0.3, steps=3),
                             genome(ramp=1.0, grade=0.6)]))
    d = np.asarray(features.descriptors(m, names=("faces", "max_step"), window=30, stride=2))
    assert d[0, 0] > 0.005 and d[1, 0] == 0.0
    step_map = np.asarray(features.max_step(m, 30, 2))
    assert step_map[0].max() == pytest.approx(0.15, abs=TOL)
    assert step_map[1].max() == pytest.approx(0.6 * SCALE.cell_size, abs=TOL)  # the ramp's rise per pixel

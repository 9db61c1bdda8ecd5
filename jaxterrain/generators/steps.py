"""Vertical structure: the field's sub-terrains (stairs, ramps, boxes, trenches and pits, stepping stones) composed
into one course along +x, with continuous parameters in metres (issue 64, item 2).

The smooth generators (Perlin, diamond-square, Worley, CPPN, GAN) make no vertical faces; legged_gym, Isaac Lab and
mjlab train on sub-terrains that do. ``steps`` lays five such primitives one after another along the walker's +x
course, each over a share of it, so that MAP-Elites can mix them and grade their sizes.

Genome ``[21]`` float32 (integer genes stored as whole floats), lengths and heights in metres at the generator's
``cell_size`` (default 0.04 m per pixel) and ``height`` (default 1.0 m per heightmap unit, the default
:class:`~jaxterrain.terrain.TerrainScale`):

================  ============  ==================================================================================
gene              range         meaning
================  ============  ==================================================================================
seed              [0, 100]      integer; the order of the five sections and every random part (box heights and
                                placement, pit and stone phases across the course, the noise lattice)
stairs            [0, 1]        share of the course given to a flight of stairs (0: none)
riser             [0.02, 0.25]  m; height of every step
tread             [0.2, 0.6]    m; depth of every step
steps             [1, 8]        integer; risers per flight, capped so the flight fits the relief budget and its
                                section
stair_sign        [-1, 1]       >= 0: up, landing, down (a ridge); < 0: down, landing, up (a well). Continuous, so
                                that mutation can flip it
ramp              [0, 1]        share of the course given to a ramp
grade             [0.05, 0.6]   rise over run of the ramp: up at this grade to at most ``U``, a landing, down
boxes             [0, 1]        share of the course given to boxes (platforms at large sizes)
box_height        [0.02, 0.3]   m; the tallest box; each box is ``box_height * uniform(0.5, 1)`` tall, at most ``U``
box_size          [0.2, 1.2]    m; side of the square grid cells that hold the boxes
box_density       [0.1, 1]      probability that a grid cell holds a box
trenches          [0, 1]        share of the course given to trenches and pits
trench_width      [0.05, 0.8]   m; width of a trench along x
trench_spacing    [0.3, 2.0]    m; ground before each trench along x (and between pits along y)
pit_length        [0.3, 10.5]   m; extent of a pit along y; at or above the course's width a trench crosses it
pit_depth         [0.05, 0.5]   m; depth of the trenches, pits and the gaps between stepping stones (at most
                                ``ROOM - 2 noise``)
stones            [0, 1]        share of the course given to stepping stones
stone_size        [0.25, 1.0]   m; side of a square stone
stone_gap         [0.05, 0.5]   m; gap between stones (``pit_depth`` deep)
noise             [0, 0.06]     m; amplitude of smooth noise over the whole course (bilinear on a 0.2 m lattice,
                                legged_gym's ``random_uniform_terrain``); 0: none
================  ============  ==================================================================================

Layout of a ``size x size`` map (rows along +y, columns along +x, as the hfield; see
:mod:`jaxterrain.terrain.scale`):

* Ground is at ``BASE`` = 0.5 heightmap units (0.5 m at the default height).
* Relief budget: the map's whole relief (its highest point minus its lowest) is at most ``ROOM`` = 0.5 m, so that
  every terrain passes Algorithm 1 for the humanoid at the default scale (a range of at most 1.57 / 3 = 0.523 m in
  any 1.04 m window, :func:`jaxterrain.features.is_traversable`), which an archive applies before walking: with
  0.5 m up AND 0.5 m down allowed, 39 of 64 random and mutated genomes failed it. The noise takes ``2 * noise``;
  the sunk parts take ``D``, the larger of ``pit_depth`` (when trenches or stones have a share) and a well's depth
  (``steps * riser``, capped); what is left, ``U = ROOM - 2 noise - D``, is how high the ridge of stairs, the ramp
  and the boxes may climb. Every part also stays within ``BASE * height`` of the ground (in [0, 1]; the map is
  clipped there).
* A flat strip of :func:`strip_cells` pixels (``START_STRIP`` = 1.0 m at 4 cm; at most ``size // 8`` pixels on small
  maps) along every edge stays at ``BASE`` exactly: the walker spawns 0.5 m (the ant 1.0 m) from the left edge, so
  every terrain starts on flat ground, under every heading of ``difficulty.HEADINGS`` too.
* The course between the strips (``C`` metres along x) holds the five sections in an order drawn from ``seed``,
  section ``k`` being ``C * share_k / max(1, sum(shares))`` long: shares summing to less than 1 leave flat ground
  at the end of the course, larger ones are scaled down to fit. Every section starts and ends at ``BASE``. The
  stairs and the ramp rise from all four sides of their section's rectangle (the section along x, the course's
  width along y), so that a walk along y (the turned headings) meets stairs or a ramp too, never the side of a
  band as a wall; the trenches are bands across the course, the boxes, pits and stones a grid.
* Stairs: flights of ``n = min(steps, floor(room / riser))`` risers (``room`` = ``U`` for a ridge, ``ROOM - 2
  noise`` for a well), each ``tread`` apart, the first one ``tread`` in from the rectangle's side, up to a landing
  (down for a well): ``riser * min(floor(d / tread), n)`` with ``d`` the distance to the nearest side. A section
  shorter than ``2 n tread`` holds fewer steps, a riser taller than ``room`` none. Along the walker's row the flight
  goes up, along the landing and down again; every riser is ONE pixel-to-pixel jump of ``riser / height`` heightmap
  units (a real vertical face; treads are at least 0.2 m, five pixels).
* Ramp: ``min(grade * d, U)``, ``d`` as for the stairs (a truncated pyramid).
* Boxes: a grid of ``box_size`` cells from the section's start (at a random phase across the course); the cells cut
  by the section's ends keep their part.
* Trenches: ``trench_spacing`` of ground then ``trench_width`` of trench, as many whole periods as the section holds;
  along y each trench is cut into pits ``pit_length`` long with ``trench_spacing`` of ground between them (random
  phase), unless ``pit_length`` reaches the map's width.
* Stepping stones: a ``stone_gap`` gap then a ``stone_size`` stone, as many whole periods as fit along x, the same
  pattern across the course (random phase); the gaps are ``pit_depth`` deep.
* Noise fades in over its first lattice cell (0.2 m) inside the course, so the strips stay exact and noise alone
  makes no faces: a step between neighbouring pixels of at most ``3 * noise * cell_size / 0.2`` (0.036 m at the
  largest amplitude and 4 cm), under the ``faces`` descriptor's 0.05 threshold (:mod:`jaxterrain.features.kernels`).

All of it is elementwise arithmetic on ``[size, size]`` arrays (integer hashes for the random parts, as
:mod:`jaxterrain.generators.perlin`): jit / vmap friendly, no value-dependent shapes or control flow. Mutation is the
library's per-gene Gaussian (:func:`jaxterrain.generators.base.gaussian_mutation`, p = 0.35, sigma = 10 % of each
gene's range, clipped, integer genes rounded); the shares reach 0 (a primitive switched off) by clipping.

The layout is not the held-out suite's (:mod:`jaxterrain.suite.families`): those families are rings around the map's
centre at one parameter each; here the primitives are straight bands and grids along one course, mixed, and the
relief stays within 0.5 m (the suite's stairs and slopes climb to 1 m, its gaps and stones are 0.5 m deep).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp

from jaxterrain.generators.base import Generator, mix32, spec, vector_generator
from jaxterrain.generators.registry import register

__all__ = ["STEPS_SPEC", "PRIMITIVES", "BASE", "ROOM", "START_STRIP", "NOISE_CELL", "strip_cells", "section_bounds",
           "render_steps", "steps"]

STEPS_SPEC = spec(
    ("seed", 0.0, 100.0, True),
    ("stairs", 0.0, 1.0, False),
    ("riser", 0.02, 0.25, False),
    ("tread", 0.2, 0.6, False),
    ("steps", 1.0, 8.0, True),
    ("stair_sign", -1.0, 1.0, False),
    ("ramp", 0.0, 1.0, False),
    ("grade", 0.05, 0.6, False),
    ("boxes", 0.0, 1.0, False),
    ("box_height", 0.02, 0.3, False),
    ("box_size", 0.2, 1.2, False),
    ("box_density", 0.1, 1.0, False),
    ("trenches", 0.0, 1.0, False),
    ("trench_width", 0.05, 0.8, False),
    ("trench_spacing", 0.3, 2.0, False),
    ("pit_length", 0.3, 10.5, False),
    ("pit_depth", 0.05, 0.5, False),
    ("stones", 0.0, 1.0, False),
    ("stone_size", 0.25, 1.0, False),
    ("stone_gap", 0.05, 0.5, False),
    ("noise", 0.0, 0.06, False),
)

PRIMITIVES = ("stairs", "ramp", "boxes", "trenches", "stones")
"""The sections of the course, by the name of their share gene."""

BASE = 0.5
"""Heightmap units: the ground (and start strip) level."""

ROOM = 0.5
"""Metres: the relief budget, the most a map's highest point may lie above its lowest (module docstring)."""

START_STRIP = 1.0
"""Metres of flat ground along every edge (``suite.families.START_STRIP``; small maps keep less, see
:func:`strip_cells`)."""

NOISE_CELL = 0.2
"""Metres between the noise lattice points."""

_EPS = 1e-4  # slack for floor() of ratios that are whole numbers in exact arithmetic (0.5 / 0.1 = 4.9999995)


def strip_cells(size: int, cell_size: float = 0.04) -> int:
    """Pixels of the flat strip along each edge: ``round(START_STRIP / cell_size)``, at most ``size // 8``."""
    return int(min(round(START_STRIP / cell_size), size // 8))


def _uniform(ix: jax.Array, iy: jax.Array, salt: jax.Array) -> jax.Array:
    """A uniform number in [0, 1) per integer lattice point ``(ix, iy)`` (int32, broadcast), for a uint32 ``salt``:
    an integer hash (pure arithmetic, no table; fuses with its consumers)."""
    hx = mix32(ix.astype(jnp.uint32) ^ salt)
    h = mix32(hx ^ (iy.astype(jnp.uint32) * jnp.uint32(0x9E3779B1)))
    return (h >> 8).astype(jnp.float32) * jnp.float32(2.0 ** -24)


def section_bounds(genome: jax.Array, course: float):
    """Start and length (metres along the course, from its left end) of each section of :data:`PRIMITIVES`, for
    one genome ``[21]`` and a course of ``course`` metres: ``(starts [5], lengths [5])`` float32, in the order of
    :data:`PRIMITIVES` (laid out in the order ``jax.random.permutation(PRNGKey(seed), 5)``)."""
    g = jnp.asarray(genome, jnp.float32)
    shares = jnp.stack([g[STEPS_SPEC.index(p)] for p in PRIMITIVES])
    lengths = shares * course / jnp.maximum(1.0, jnp.sum(shares))
    order = jax.random.permutation(jax.random.fold_in(jax.random.PRNGKey(jnp.round(g[0]).astype(jnp.int32)), 0), 5)
    ordered = lengths[order]
    starts = jnp.zeros(5, jnp.float32).at[order].set(jnp.cumsum(ordered) - ordered)
    return starts, lengths


def render_steps(genome: jax.Array, size: int = 256, cell_size: float = 0.04, height: float = 1.0) -> jax.Array:
    """One genome ``[21]`` -> heightmap ``[size, size]`` float32 in [0, 1] (see the module docstring). Unchecked;
    jit / vmap friendly."""
    g = jnp.asarray(genome, jnp.float32)

    def gene(name):
        return g[STEPS_SPEC.index(name)]

    seed = jnp.round(gene("seed")).astype(jnp.int32)
    key = jax.random.PRNGKey(seed)
    salts = jax.random.bits(jax.random.fold_in(key, 1), (3,), jnp.uint32)  # box presence, box height, noise
    phases = jax.random.uniform(jax.random.fold_in(key, 2), (3,), jnp.float32)
    # The relief budget (module docstring): noise takes 2 a, the pits / stone gaps and a well their depth, what is
    # left (up) the ridge, the ramp and the boxes.
    noise_amp = gene("noise")
    free = jnp.maximum(ROOM - 2.0 * noise_amp, 0.0)  # metres
    riser, tread = gene("riser"), gene("tread")
    well = gene("stair_sign") < 0.0
    stairs_on, sunk_on = gene("stairs") > 0.0, (gene("trenches") > 0.0) | (gene("stones") > 0.0)
    n_well = jnp.minimum(jnp.round(gene("steps")), jnp.floor(jnp.minimum(free, BASE * height) / riser + _EPS))
    depth = jnp.minimum(gene("pit_depth"), jnp.minimum(free, BASE * height))
    down = jnp.maximum(jnp.where(sunk_on, depth, 0.0), jnp.where(stairs_on & well, n_well * riser, 0.0))
    up = jnp.minimum(free - down, BASE * height)  # metres

    strip = strip_cells(size, cell_size)
    n_course = size - 2 * strip
    course = n_course * cell_size  # metres
    cols = jnp.arange(size, dtype=jnp.float32)
    u = (cols - strip) * cell_size  # [W] metres along the course (x)
    y = (cols - strip) * cell_size  # [H] metres across it, from the course's lower edge
    span_y = course  # metres across the course
    starts, lengths = section_bounds(g, course)

    def local(k):  # [W] metres into section k, and whether u lies in it
        v = u - starts[k]
        return v, (v >= 0.0) & (v < lengths[k])

    # Stairs: flights of n risers up (a well: down) to a landing, rising from the four sides of the section's
    # rectangle (d: metres to its nearest side); the ramp likewise.
    d_y = jnp.minimum(y, span_y - y)[:, None]  # [H, 1]
    v, inside = local(0)
    n = jnp.where(well, n_well, jnp.minimum(jnp.round(gene("steps")), jnp.floor(up / riser + _EPS)))
    d = jnp.minimum(jnp.minimum(v, lengths[0] - v)[None, :], d_y)
    sign = jnp.where(well, -1.0, 1.0)
    stairs = jnp.where(inside[None, :], sign * riser * jnp.minimum(jnp.floor(d / tread), n), 0.0)  # [H, W]

    # Ramp: up at grade to at most `up`, a landing, down.
    v, inside = local(1)
    d = jnp.minimum(jnp.minimum(v, lengths[1] - v)[None, :], d_y)
    ramp = jnp.where(inside[None, :], jnp.minimum(gene("grade") * d, up), 0.0)  # [H, W]

    # Boxes on a grid from the section's start.
    v, inside = local(2)
    size_b = gene("box_size")
    ix = jnp.floor(v / size_b).astype(jnp.int32)[None, :]
    iy = jnp.floor((y + phases[0] * size_b) / size_b).astype(jnp.int32)[:, None]
    present = _uniform(ix, iy, salts[0]) < gene("box_density")
    tall = jnp.minimum(gene("box_height") * (0.5 + 0.5 * _uniform(ix, iy, salts[1])), up)
    boxes = jnp.where(inside[None, :] & present, tall, 0.0)  # [H, W]

    # Trenches (cut into pits along y).
    v, inside = local(3)
    width, gap = gene("trench_width"), gene("trench_spacing")
    period = width + gap
    whole = jnp.floor(lengths[3] / period + _EPS) * period
    in_x = inside & (jnp.mod(v, period) >= gap) & (v < whole)
    pit = gene("pit_length")
    in_y = (pit >= span_y) | (jnp.mod(y + phases[1] * (pit + gap), pit + gap) < pit)
    trenches = jnp.where(in_x[None, :] & in_y[:, None], -depth, 0.0)  # [H, W]

    # Stepping stones: gap, stone, gap, stone, ... as many whole periods as fit; the same across the course.
    v, inside = local(4)
    stone, sgap = gene("stone_size"), gene("stone_gap")
    pitch = stone + sgap
    whole = jnp.floor(lengths[4] / pitch + _EPS) * pitch
    gap_x = inside & (v < whole) & (jnp.mod(v, pitch) < sgap)
    gap_y = jnp.mod(y + phases[2] * pitch, pitch) < sgap
    on_x = inside & (v < whole)
    stones = jnp.where(gap_x[None, :] | (on_x[None, :] & gap_y[:, None]), -depth, 0.0)  # [H, W]

    # Smooth noise: bilinear on a NOISE_CELL lattice, faded in over one lattice cell from the course's edges.
    lx, ly = u / NOISE_CELL, y / NOISE_CELL
    x0, y0 = jnp.floor(lx), jnp.floor(ly)
    fx, fy = (lx - x0)[None, :], (ly - y0)[:, None]
    x0, y0 = x0.astype(jnp.int32)[None, :], y0.astype(jnp.int32)[:, None]

    def corner(dx, dy):
        return 2.0 * _uniform(x0 + dx, y0 + dy, salts[2]) - 1.0

    top = corner(0, 0) + fx * (corner(1, 0) - corner(0, 0))
    bottom = corner(0, 1) + fx * (corner(1, 1) - corner(0, 1))
    edge_x = jnp.minimum(u, course - cell_size - u)  # metres to the course's nearer end (0 on its first pixel)
    edge_y = jnp.minimum(y, span_y - cell_size - y)
    fade = jnp.clip(jnp.minimum(edge_x[None, :], edge_y[:, None]) / NOISE_CELL, 0.0, 1.0)
    noise = noise_amp * fade * (top + fy * (bottom - top))  # [H, W]

    relief = stairs + ramp + boxes + trenches + stones + noise  # metres, [H, W]
    on_course = (cols >= strip) & (cols < size - strip)
    relief = jnp.where(on_course[:, None] & on_course[None, :], relief, 0.0)
    return jnp.clip(BASE + relief / height, 0.0, 1.0)


@register("steps")
def steps(size: int = 256, cell_size: float = 0.04, height: float = 1.0) -> Generator:
    """Vertical-structure generator producing ``[B, size, size]`` float32 maps in [0, 1]; see the module docstring.

    ``cell_size`` and ``height`` (metres per pixel and per heightmap unit) are the :class:`TerrainScale` the
    genome's metres are drawn at; keep them equal to the scale the maps are walked at (the defaults are
    ``TerrainScale()``'s, which every command uses unless told otherwise)."""
    size = int(size)
    if size < 1:
        raise ValueError(f"steps: size must be a positive integer; got {size}")
    for name, value in (("cell_size", cell_size), ("height", height)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise ValueError(f"steps: {name} must be a finite number of metres > 0; got {value!r}")
    cell_size, height = float(cell_size), float(height)

    def render_one(genome: jax.Array) -> jax.Array:
        return render_steps(genome, size, cell_size, height)

    return vector_generator("steps", STEPS_SPEC, render_one, size)

"""Held-out terrain families: the field's sub-terrains (legged_gym's ``terrain.py``, Isaac Lab's ``terrains/``), each
at graded levels of one physical parameter, as heightmaps the walker walks like any other.

A family builds one heightmap from ``(value, size, scale, rng)``: ``value`` in the family's unit (a slope's grade,
a step's height in metres, ...), ``size`` x ``size`` pixels of ``scale.cell_size`` metres, heights in metres divided
by ``scale.height`` and clipped to [0, 1] (so nothing is taller than ``scale.height``, 1 m by default), and ``rng``
a ``numpy.random.Generator`` for the families with random parts. Every family keeps a flat strip of
:data:`START_STRIP` metres along each edge, where the walker starts (``WalkerConfig.start_margin`` = 0.5 m from the
edge), and is laid out around the map's centre, so that a walk along +x crosses it and the four headings of
``difficulty.HEADINGS`` (the map turned by 90 degrees) meet the same terrain.

``d`` below is a point's distance in metres to the nearest map edge (0 at the edge, ``L / 2`` at the centre of a
map ``L = (size - 1) * cell_size`` wide): pyramids rise with ``d``, rings are lines of constant ``d``.

| family | value (level 0 -> 9) | shape |
| --- | --- | --- |
| ``slope_up`` | grade 0.05 -> 0.50 | a pyramid rising at that grade to a 1 m plateau |
| ``slope_down`` | grade 0.05 -> 0.50 | the same, inverted: down into a pit |
| ``stairs_up`` | step 0.03 -> 0.21 m | a pyramid of 0.31 m treads up to 1 m (legged_gym: 0.05 -> 0.23 m) |
| ``stairs_down`` | step 0.03 -> 0.21 m | the same, inverted |
| ``boxes`` | height 0.02 -> 0.20 m | a grid of 0.4 m cells, each at a uniform random height in [0, value] |
| ``obstacles`` | height 0.03 -> 0.25 m | 40 random rectangles of 0.3 - 1.0 m, each +- value from the ground |
| ``stepping_stones`` | gap 0.05 -> 0.50 m | 0.6 m stones on a grid with gaps of that width, 0.5 m deep |
| ``gaps`` | width 0.05 -> 0.60 m | square trenches around the centre every 1.2 m, 0.5 m deep |
| ``waves`` | amplitude 0.02 -> 0.30 m | ``value * (sin(2 pi x / 2 m) + sin(2 pi y / 2 m)) / 2`` |
| ``rough`` | amplitude 0.01 -> 0.10 m | uniform noise in [-value, value] on 0.12 m blocks |
| ``flat`` | - | flat ground (one level) |

A family only shows its levels on a map large enough to hold them: ``Family.extent`` is the ground (metres) it needs
between the start strip and the map's centre, and :func:`room` what a map of ``size`` pixels at ``scale`` has
(``L / 2 - START_STRIP``). A 64-pixel map at 4 cm has 0.26 m: no trench of ``gaps`` starts in it (they begin 0.3 m
in) and ``stairs_up`` is one step. :func:`misfit` says why a family does not fit; ``suite.load`` drops those
families and the suite says so (``Suite.dropped``). :func:`build_terrain` itself builds any family at any size.

| family | extent (m) | what it must hold |
| --- | --- | --- |
| ``flat`` | 0 | - |
| ``slope_up``, ``slope_down`` | 2.0 | the steepest grade's (0.50) whole slope, up to its 1 m plateau (down to its pit) |
| ``stairs_up``, ``stairs_down`` | 0.93 | the tallest step's (0.21 m) whole flight: 4 risers, 3 whole 0.31 m treads |
| ``boxes`` | 0.8 | two 0.4 m boxes |
| ``obstacles`` | 1.0 | the largest (1.0 m) rectangle |
| ``stepping_stones`` | 1.1 | a 0.6 m stone and the widest (0.50 m) gap |
| ``gaps`` | 1.2 | the widest (0.60 m) trench, 0.3 m in, and 0.3 m of ground beyond it |
| ``waves`` | 2.0 | the 1 m fade-in and half a 2 m wavelength at full amplitude |
| ``rough`` | 0.48 | four 0.12 m blocks |

``v1`` (256 pixels at 4 cm: 4.1 m of room) holds every family; so does any map of 160 pixels or more at 4 cm
(2.18 m); 128 pixels (1.54 m) holds all but the slopes and waves.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from jaxterrain.terrain import TerrainScale, validate_scale

__all__ = ["START_STRIP", "Family", "FAMILIES", "FAMILIES_V2", "TABLES", "family_table", "family_names",
           "build_terrain", "edge_distance", "room", "misfit", "V2_STEPS", "V2_GAP", "v2_width"]

START_STRIP = 1.0
"""Metres of flat ground along every edge (the walker spawns 0.5 m from its edge)."""

TREAD = 0.31  # legged_gym's stair tread (m)
TOP = 1.0  # metres: the plateau of the pyramids (the default TerrainScale's full height)
DEEP = 0.5  # metres: the depth of stepping-stone gaps and trenches (the walker cannot climb out)
BOX = 0.4  # metres: the side of a box cell
STONE = 0.6  # metres: the side of a stepping stone
TRENCH_START, TRENCH_EVERY = 0.3, 1.2  # metres past the start strip to the first trench, and between trenches
WAVELENGTH, FADE_IN = 2.0, 1.0  # metres: the waves' wavelength and the ramp over which they fade in
BLOCK = 0.12  # metres: the side of a rough block


class Family(NamedTuple):
    """A terrain family: ``build(value, size, scale, rng) -> [size, size]`` metres, the parameter's ``unit``, its
    values at ``levels`` graded levels from ``lo`` (easiest) to ``hi`` (hardest), evenly spaced; ``extent`` the
    metres of ground it needs between the start strip and the map's centre to show its hardest level, ``holds`` what
    that ground must hold (for :func:`misfit`'s reason)."""

    build: Callable[..., np.ndarray]
    unit: str
    lo: float
    hi: float
    levels: int = 10
    extent: float = 0.0
    holds: str = ""

    def values(self) -> np.ndarray:
        """[levels] float64: the parameter at each level, easiest first."""
        return np.linspace(self.lo, self.hi, self.levels)


def _axes(size: int, scale: TerrainScale) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` [size, size] metres, centred on the map (columns along +x, rows along +y, as the hfield)."""
    half = (size - 1) * float(scale.cell_size) / 2.0
    c = np.linspace(-half, half, size)
    return np.meshgrid(c, c)


def edge_distance(size: int, scale: TerrainScale) -> np.ndarray:
    """``[size, size]`` metres from each pixel to the nearest map edge (``size`` an integer >= 2 pixels)."""
    if not isinstance(size, (int, np.integer)) or isinstance(size, bool) or size < 2:
        raise ValueError(f"size must be an integer >= 2 pixels; got {size!r}")
    scale = validate_scale(scale)
    x, y = _axes(size, scale)
    half = (size - 1) * float(scale.cell_size) / 2.0
    return half - np.maximum(np.abs(x), np.abs(y))


def _inner(size: int, scale: TerrainScale) -> np.ndarray:
    """``[size, size]`` metres into the terrain beyond the flat start strip (0 on the strip)."""
    return np.maximum(edge_distance(size, scale) - START_STRIP, 0.0)


def _strip(size: int, scale: TerrainScale) -> np.ndarray:
    """``[size, size]`` bool: the flat start strip."""
    return edge_distance(size, scale) < START_STRIP


def _slope(grade, size, scale, rng):
    return np.minimum(TOP, grade * _inner(size, scale))


def _stairs(step, size, scale, rng):
    inner = _inner(size, scale)
    steps = np.where(inner > 0, np.floor(inner / TREAD) + 1, 0)
    return np.minimum(steps * step, np.floor(TOP / step) * step)


def _inverted(build):
    def inverted(value, size, scale, rng):
        h = build(value, size, scale, rng)
        return h.max() - h

    return inverted


def _boxes(height, size, scale, rng, cell: float = BOX):
    x, y = _axes(size, scale)
    half = x.max()
    ix, iy = np.floor((x + half) / cell).astype(int), np.floor((y + half) / cell).astype(int)
    n = int(ix.max()) + 1
    heights = rng.uniform(0.0, height, (n, n))
    return np.where(_strip(size, scale), 0.0, heights[iy, ix])


def _obstacles(height, size, scale, rng, count: int = 40, base: float = 0.3):
    x, y = _axes(size, scale)
    half = x.max()
    h = np.full((size, size), base)
    for _ in range(count):
        w, d = rng.uniform(0.3, 1.0, 2)
        cx, cy = rng.uniform(-half, half, 2)
        box = (np.abs(x - cx) < w / 2) & (np.abs(y - cy) < d / 2)
        h = np.where(box, base + rng.choice((-1.0, 1.0)) * height, h)
    return np.where(_strip(size, scale), base, h)


def _stepping_stones(gap, size, scale, rng, stone: float = STONE):
    x, y = _axes(size, scale)
    pitch = stone + gap
    ox, oy = rng.uniform(0.0, pitch, 2)
    on = ((x + ox) % pitch < stone) & ((y + oy) % pitch < stone)
    return np.where(on | _strip(size, scale), DEEP, 0.0)


def _gaps(width, size, scale, rng, every: float = TRENCH_EVERY):
    inner = _inner(size, scale)
    trench = (inner > TRENCH_START) & ((inner - TRENCH_START) % every < width)
    return np.where(trench, 0.0, DEEP)


def _waves(amplitude, size, scale, rng, wavelength: float = WAVELENGTH, base: float = 0.5):
    x, y = _axes(size, scale)
    px, py = rng.uniform(0.0, 2 * np.pi, 2)
    wave = (np.sin(2 * np.pi * x / wavelength + px) + np.sin(2 * np.pi * y / wavelength + py)) / 2
    ramp = np.clip(_inner(size, scale) / FADE_IN, 0.0, 1.0)  # fades in over the first metre past the strip
    return base + amplitude * wave * ramp


def _rough(amplitude, size, scale, rng, block: float = BLOCK, base: float = 0.5):
    x, y = _axes(size, scale)
    half = x.max()
    ix, iy = np.floor((x + half) / block).astype(int), np.floor((y + half) / block).astype(int)
    n = int(ix.max()) + 1
    noise = rng.uniform(-amplitude, amplitude, (n, n))
    return np.where(_strip(size, scale), base, base + noise[iy, ix])


def _flat(value, size, scale, rng):
    return np.zeros((size, size))


_SLOPE = (TOP / 0.50, "the steepest grade's (0.50) whole slope to its 1 m plateau")
_FLIGHT = ((np.floor(TOP / 0.21) - 1) * TREAD, "the tallest step's (0.21 m) whole flight of 4 risers on 0.31 m treads")
FAMILIES: dict[str, Family] = {
    "flat": Family(_flat, "-", 0.0, 0.0, levels=1),
    "slope_up": Family(_slope, "grade", 0.05, 0.50, 10, *_SLOPE),
    "slope_down": Family(_inverted(_slope), "grade", 0.05, 0.50, 10, *_SLOPE),
    "stairs_up": Family(_stairs, "m step", 0.03, 0.21, 10, *_FLIGHT),
    "stairs_down": Family(_inverted(_stairs), "m step", 0.03, 0.21, 10, *_FLIGHT),
    "boxes": Family(_boxes, "m height", 0.02, 0.20, 10, 2 * BOX, "two 0.4 m boxes"),
    "obstacles": Family(_obstacles, "m height", 0.03, 0.25, 10, 1.0, "the largest (1.0 m) rectangle"),
    "stepping_stones": Family(_stepping_stones, "m gap", 0.05, 0.50, 10, STONE + 0.50,
                              "a 0.6 m stone and the widest (0.50 m) gap"),
    "gaps": Family(_gaps, "m width", 0.05, 0.60, 10, TRENCH_START + 0.60 + 0.3,
                   "the widest (0.60 m) trench, 0.3 m in, and 0.3 m of ground beyond it"),
    "waves": Family(_waves, "m amplitude", 0.02, 0.30, 10, FADE_IN + WAVELENGTH / 2,
                    "the 1 m fade-in and half a 2 m wave at full amplitude"),
    "rough": Family(_rough, "m amplitude", 0.01, 0.10, 10, 4 * BLOCK, "four 0.12 m blocks"),
}
"""The held-out families by name, in the order tables list them."""


# --- v2: the same kinds of terrain, re-parametrised so that each family's level 0 is easy and its level 9 hard for a
# robot's base policy (the levels are per robot: heldout.V2_LEVELS), and a terrain's random parts are drawn from
# its seed alone (heldout.load seeds v2's rng without the level), so the level is the only thing that orders them.

V2_STEPS = 5
"""Risers in a v2 flight of stairs: the flight is ``V2_STEPS * riser`` high, so it grows with the level."""

V2_OBSTACLES, V2_OBSTACLE_BASE = 80, 0.5  # rectangles per map; the ground (m) they stand on and sink into


V2_GAP = 0.1
"""Metres: the width of a v2 trench or stepping-stone gap beyond its depth (a gap ``depth`` deep is ``V2_GAP + depth``
wide: :func:`v2_width`)."""


def v2_width(depth: float) -> float:
    """Metres: the width of a v2 trench or stepping-stone gap ``depth`` metres deep, ``V2_GAP + depth``: the
    family's parameter is the depth, which is continuous, and the width grows with it (a heightmap of 4 cm pixels
    only holds widths in whole pixels, so a width alone would grade in 4 cm jumps): a 1 cm deep gap is an 11 cm
    groove, a 0.5 m deep one as wide as v1's widest trench (0.6 m)."""
    return V2_GAP + float(depth)


def _flight(riser, size, scale, rng):
    inner = _inner(size, scale)
    steps = np.where(inner > 0, np.floor(inner / TREAD) + 1, 0)
    return np.minimum(steps, V2_STEPS) * riser


def _v2_obstacles(height, size, scale, rng):
    return _obstacles(height, size, scale, rng, count=V2_OBSTACLES, base=V2_OBSTACLE_BASE)


def _v2_stepping_stones(depth, size, scale, rng, stone: float = STONE):
    x, y = _axes(size, scale)
    pitch = stone + v2_width(depth)
    ux, uy = rng.uniform(0.0, 1.0, 2)  # the seed's offset, in pitches: the same at every level
    on = ((x + ux * pitch) % pitch < stone) & ((y + uy * pitch) % pitch < stone)
    return np.where(on | _strip(size, scale), depth, 0.0)


def _v2_gaps(depth, size, scale, rng, every: float = TRENCH_EVERY):
    return np.where(_gaps(v2_width(depth), size, scale, rng, every) == 0.0, DEEP - depth, DEEP)


FAMILIES_V2: dict[str, Family] = {
    "flat": Family(_flat, "-", 0.0, 0.0, levels=1),
    "slope_up": Family(_slope, "grade", 0.02, 1.0, 10, TOP / 0.5, "a 0.50 grade's slope to its 1 m plateau"),
    "slope_down": Family(_inverted(_slope), "grade", 0.02, 1.0, 10, TOP / 0.5,
                         "a 0.50 grade's slope down to its 1 m pit"),
    "stairs_up": Family(_flight, "m riser", 0.005, TOP / V2_STEPS, 10, (V2_STEPS - 1) * TREAD,
                        f"a flight of {V2_STEPS} risers on 0.31 m treads"),
    "stairs_down": Family(_inverted(_flight), "m riser", 0.005, TOP / V2_STEPS, 10, (V2_STEPS - 1) * TREAD,
                          f"a flight of {V2_STEPS} risers on 0.31 m treads"),
    "boxes": Family(_boxes, "m height", 0.005, 1.0, 10, 2 * BOX, "two 0.4 m boxes"),
    "obstacles": Family(_v2_obstacles, "m height", 0.005, V2_OBSTACLE_BASE, 10, 1.0,
                        "the largest (1.0 m) rectangle"),
    "stepping_stones": Family(_v2_stepping_stones, "m depth", 0.002, DEEP, 10, STONE + V2_GAP + DEEP,
                              "a 0.6 m stone and the deepest gap (0.6 m wide)"),
    "gaps": Family(_v2_gaps, "m depth", 0.002, DEEP, 10, TRENCH_START + V2_GAP + DEEP + 0.3,
                   "the deepest trench (0.6 m wide), 0.3 m in, and 0.3 m of ground beyond it"),
    "waves": Family(_waves, "m amplitude", 0.005, 0.5, 10, FADE_IN + WAVELENGTH / 2,
                    "the 1 m fade-in and half a 2 m wave at full amplitude"),
    "rough": Family(_rough, "m amplitude", 0.002, 0.5, 10, 4 * BLOCK, "four 0.12 m blocks"),
}
"""v2's families: the builders and units; ``lo`` / ``hi`` bound the values a v2 level may take (the calibrated
levels of each robot, ``heldout.V2_LEVELS``, lie inside; ``values()`` is not v2's levels), ``extent`` the room the
largest value needs.

| family | value | shape (what changed from v1) |
| --- | --- | --- |
| ``slope_up``, ``slope_down`` | grade | as v1 |
| ``stairs_up``, ``stairs_down`` | riser (m) | a flight of ``V2_STEPS`` (5) risers on 0.31 m treads to a plateau ``5 x riser`` high (v1: risers up to a 1 m plateau whatever the riser) |
| ``boxes`` | height (m) | as v1 |
| ``obstacles`` | height (m) | 80 rectangles (v1: 40) of 0.3 - 1.0 m, each +- value from ground at 0.5 m (v1: 0.3 m, which capped the pits) |
| ``stepping_stones`` | depth (m) | 0.6 m stones, gaps that deep and ``v2_width(depth)`` = ``0.1 m + depth`` wide (v1: the gap's width, 0.5 m deep at every width) |
| ``gaps`` | depth (m) | trenches every 1.2 m, that deep and ``0.1 m + depth`` wide (v1: the width, 0.5 m deep) |
| ``waves``, ``rough`` | amplitude (m) | as v1 |
"""

TABLES: dict[str, dict[str, Family]] = {"v1": FAMILIES, "v2": FAMILIES_V2}
"""The family table of each suite version."""


def family_table(version: str = "v1") -> dict[str, Family]:
    """The family table of suite ``version`` (:data:`TABLES`); ValueError naming it for an unknown one."""
    if version not in TABLES:
        raise ValueError(f"version must be one of {', '.join(TABLES)}; got {version!r}")
    return TABLES[version]


def family_names() -> tuple[str, ...]:
    """The family names, in table order."""
    return tuple(FAMILIES)


def room(size: int, scale: TerrainScale = TerrainScale()) -> float:
    """Metres of ground between the start strip and the centre of a ``size`` x ``size`` map at ``scale``
    (``(size - 1) * cell_size / 2 - START_STRIP``; negative when the strips overlap)."""
    return (size - 1) * float(validate_scale(scale).cell_size) / 2.0 - START_STRIP


def misfit(name: str, size: int, scale: TerrainScale = TerrainScale(), version: str = "v1") -> str | None:
    """Why family ``name`` of suite ``version`` does not fit a ``size`` x ``size`` map at ``scale`` (its ``extent``
    is more than the map's :func:`room`), in one line; None when it fits."""
    fam, have = family_table(version)[name], room(size, scale)
    if fam.extent <= 0 or have + 1e-9 >= fam.extent:  # a family that needs no room (flat) fits any map
        return None
    cell = float(validate_scale(scale).cell_size)
    return (f"needs {fam.extent:.2f} m inside the start strip for {fam.holds}; {size} pixels of {cell:g} m have "
            f"{max(have, 0.0):.2f} m")


def build_terrain(name: str, value: float, size: int = 256, scale: TerrainScale = TerrainScale(),
                  rng: np.random.Generator | None = None, version: str = "v1") -> np.ndarray:
    """One heightmap ``[size, size]`` float32 in [0, 1] of family ``name`` of suite ``version`` (:data:`TABLES`)
    at parameter ``value`` (metres / scale height, clipped). ValueError naming the parameter for an unknown
    version or family, a size below 16 pixels, a ``value`` that is not a finite number >= 0 (every family's
    parameter is a grade, a height, a width or a depth) or an ``rng`` that is
    not a ``numpy.random.Generator``. A map too small for the family (:func:`misfit`) is built all the same, cut
    down: ``suite.load`` drops such families."""
    table = family_table(version)
    if not isinstance(name, str) or name not in table:
        raise ValueError(f"family must be one of {', '.join(table)}; got {name!r}")
    if not isinstance(size, (int, np.integer)) or isinstance(size, bool) or size < 16:
        raise ValueError(f"size must be an integer >= 16 pixels; got {size!r}")
    if isinstance(value, (bool, str, bytes)) or not isinstance(value, (int, float, np.integer, np.floating)) \
            or not (np.isfinite(value) and value >= 0):
        raise ValueError(f"value must be a finite number >= 0 (the family's {table[name].unit}); got {value!r}")
    scale = validate_scale(scale)
    if rng is not None and not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator or None; got {type(rng).__name__}")
    rng = np.random.default_rng(0) if rng is None else rng
    metres = table[name].build(float(value), int(size), scale, rng)
    return np.clip(metres / float(scale.height), 0.0, 1.0).astype(np.float32)

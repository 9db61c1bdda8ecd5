"""Physical terrain: a heightmap in metres (:class:`TerrainScale`), its exports, and real elevation tiles.

- :mod:`~jaxterrain.terrain.scale`: :class:`TerrainScale` (cell size, height), :func:`to_metres`,
  :func:`hfield_size` (the one home of the heightmap <-> MuJoCo hfield mapping);
- :mod:`~jaxterrain.terrain.export`: 16-bit PNG, ``.npy``, MJCF and OBJ / STL meshes;
- :mod:`~jaxterrain.terrain.dem`: real elevation (DEM) tiles, the GAN's training data.
"""

from jaxterrain.terrain import dem, export, scale
from jaxterrain.terrain.export import (
    load_npy,
    load_png,
    mesh_arrays,
    save_mjcf,
    save_npy,
    save_obj,
    save_png,
    save_stl,
    to_mesh,
)
from jaxterrain.terrain.scale import TerrainScale, hfield_size, to_metres, validate_scale

__all__ = [*scale.__all__, *export.__all__, "dem"]

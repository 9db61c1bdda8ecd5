"""Terrain features (paper section 3.2) and the traversability check (paper Algorithm 1).

- :mod:`~jaxterrain.features.kernels`: TRI, TPI and roughness maps over windows with a stride, equal to GDAL's
  ``gdaldem`` at window 3, the vertical-face maps ``faces`` and ``max_step``, and their means;
- :mod:`~jaxterrain.features.reference`: the same maps by plain NumPy loops (the tests' ground truth);
- :mod:`~jaxterrain.features.registry`: descriptor names -> functions, :func:`descriptors` (``[B, D]``);
- :mod:`~jaxterrain.features.algorithm1`: :func:`is_traversable`, the paper's Algorithm 1.

The learned traversability descriptor (:mod:`jaxterrain.features.learned`) sits later in the flow: it is trained on
the walker's walks, so it imports the walker and :mod:`jaxterrain.difficulty`; importing :mod:`jaxterrain` registers
it as the descriptor ``"traversability"``.
"""

from jaxterrain.features.algorithm1 import HUMANOID_HEIGHT, is_traversable, max_window_range
from jaxterrain.features.kernels import (
    FACE_THRESHOLD,
    HEIGHT_RANGE,
    check_heights,
    faces,
    max_step,
    output_shape,
    roughness,
    step_heights,
    tpi,
    tri,
    window_centre,
)
from jaxterrain.features.reference import reference_maps
from jaxterrain.features.registry import (
    Descriptor,
    descriptor_names,
    descriptors,
    register_descriptor,
    unregister_descriptor,
)

__all__ = [
    "FACE_THRESHOLD",
    "HEIGHT_RANGE",
    "HUMANOID_HEIGHT",
    "check_heights",
    "tri",
    "tpi",
    "roughness",
    "step_heights",
    "faces",
    "max_step",
    "Descriptor",
    "descriptors",
    "register_descriptor",
    "unregister_descriptor",
    "descriptor_names",
    "is_traversable",
    "max_window_range",
    "reference_maps",
    "output_shape",
    "window_centre",
]

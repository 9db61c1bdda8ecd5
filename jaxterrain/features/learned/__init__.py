"""Learned traversability (paper 3.2, item 4): a CNN patch classifier trained on the base policy's own walks.

The paper's fourth descriptor is the mean output of the traversability model of Chavez-Garcia et al. (RA-L 2018): a
small CNN that reads a heightmap patch (heights relative to the patch centre, turned to the robot's heading) and
outputs the probability that the robot advances across it. Their weights are not available; ours is trained the
same way, on our walker's simulated outcomes::

    walks = learned.walk(key, heightmaps, attempts=4, horizon=300)      # Walks: torso x, y per env step
    starts, labels = learned.window_labels(walks)                        # [B, A, K]: 1 / 0 / -1 (none)
    patches = learned.extract_patches(terrain_m, xy)                     # [N, 32, 32] m, relative to centre
    params = learned.train(key, patches, labels)                        # flax params of PatchCNN
    tmap = learned.traversability_map(params, heightmaps)                # [B, 29, 29] probabilities
    d = features.descriptors(heightmaps, ("traversability",))                   # [B, 1]: the map's mean

Choices (:class:`LabelConfig`, :data:`PATCH`, :data:`MAP_STRIDE`):

- Patch: ``PATCH = 32`` pixels = 1.28 m at 0.04 m per pixel, the paper's 1.2 m (60 px at 2 cm) at our resolution;
  about two strides of the humanoid. Heights in metres relative to the centre pixel ``(16, 16)``
  (:func:`jaxterrain.features.window_centre`), rows along y, columns along +x: the walking direction, orientation 0
  as in the paper. The patch of a window is centred on the torso's (x, y) at the window's middle
  (:func:`labelled_centres`), so it covers the ground walked during the window, and a fall's patch is centred where
  the walker fell.
- Label (:func:`window_labels`): windows of ``window = 30`` env steps (0.45 s) start every ``every = 4`` steps from
  step ``warmup = 8``. A window is positive when the walker is still up at its end and its torso advanced more
  than ``threshold = 0.3`` m along +x, negative when the walker fell (or its physics failed) inside the window or
  advanced less; windows that run past the end of a walk that did not fall (goal, time limit, horizon) are not
  labelled. Why these numbers: the base policy runs at about 3.5 m/s on flat ground (2.1 m per 40 steps), so a
  30-step window at speed covers about 1.6 m, a bit more than one patch; it starts from rest and needs about 1 s to
  reach that speed, and the slowest flat-ground advance of a window starting at step 8 is 0.43 m, so 0.3 m passes
  every flat-ground window (a walker that does not fall) while a stumble that loses most of its speed fails it.
  The humanoid's failure mode is falling, not getting stuck (the paper's robot), so most negatives are falls.
- Model (:class:`PatchCNN`): VALID convolutions 4x4/2, 3x3/2, 3x3/2, 3x3/1 and a 1x1 logit, whose receptive field
  is exactly one 32 x 32 patch and whose total stride is 8. Applied to a whole ``[H, W]`` map it gives the logit of
  every patch whose top-left corner is at ``(8 i, 8 j)``: a ``[(H - 32) // 8 + 1, (W - 32) // 8 + 1]`` map (29 x 29
  at 256 x 256) in one pass of convolutions, no loop over patches. The first convolution's kernels are made to sum
  to zero (:class:`ZeroSumConv`), so the network cannot see a height offset: its output on a patch equals its output
  on the same patch relative to its centre, which is why the strided map equals the model applied patch by patch
  (``tests/features/test_traversability.py``).

The shipped model (``jaxterrain/assets/traversability/``, see its ``PROVENANCE.md``) is loaded on the first call of
:func:`descriptor` (never at import). Importing this package (which importing :mod:`jaxterrain` does) registers the ``"traversability"`` descriptor in
:mod:`jaxterrain.features`.
"""


from jaxterrain.features.learned.data import (
    LabelConfig,
    Walks,
    balanced_indices,
    extract_patches,
    extract_patches_batch,
    labelled_centres,
    pixel_of,
    walk,
    walk_fn,
    window_labels,
)
from jaxterrain.features.learned.model import (
    ASSET_DIR,
    MAP_STRIDE,
    Model,
    ModelConfig,
    PATCH,
    PatchCNN,
    ZeroSumConv,
    apply_patches,
    descriptor,
    init_params,
    load,
    logit_map,
    make_descriptor,
    save,
    shipped,
    traversability_map,
)
from jaxterrain.features.learned.training import TrainConfig, accuracy, roc_auc, train

__all__ = ["PATCH", "MAP_STRIDE", "ASSET_DIR", "LabelConfig", "ModelConfig", "TrainConfig", "Walks", "PatchCNN",
           "ZeroSumConv", "walk", "walk_fn", "window_labels", "labelled_centres", "extract_patches",
           "extract_patches_batch", "pixel_of", "balanced_indices", "init_params", "apply_patches", "logit_map",
           "traversability_map", "descriptor", "make_descriptor", "train", "roc_auc", "accuracy", "save", "load",
           "shipped", "Model"]

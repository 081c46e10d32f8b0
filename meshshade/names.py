"""Names a user chooses from or reads in a command's help: the bake's models, the profile's shapes, file names.

This module imports nothing, so the command line builds its parser, choices and help from it before it imports
numpy, numba or scipy (``meshshade --help`` and argument errors answer in about a tenth of a second,
:mod:`meshshade.cli.main`). The code that acts on these names imports them from here too (the transport's
models, ``meshshade.profiles``, the batch runner, the Blender add-on): each list exists once. The measured material
presets, data with their names, are in :mod:`meshshade.material_presets`.
"""

#: the kernels ``auto`` chooses between per entry sample: the names of plan codes 0-3
#: (:class:`meshshade.surface.models.Kernel` 0-3)
KERNEL_NAMES = ("dipole", "curved", "exact-sphere", "fitted")
#: every model :func:`meshshade.transport.baking.bake` accepts (described in :mod:`meshshade.surface.models`)
MODELS = KERNEL_NAMES + ("auto", "volume")
#: the default model of the bake, the CLI, batches, the Blender add-on and compare's first model
DEFAULT_MODEL = "volume"

#: the surfaces ``meshshade profile`` draws on (:class:`meshshade.profiles.Shape`; ``point``: a curvature pair)
PROFILE_SHAPES = ("plane", "sphere", "cylinder", "saddle", "cavity", "bore", "point")
#: Monte Carlo photons per channel of a profile (the ring stderr near the source is then ~1 %)
PROFILE_MC_PHOTONS = 1_000_000

#: the file in a batch's output folder that lists its jobs and their state (:mod:`meshshade.batch.runner`)
BATCH_MANIFEST = "manifest.jsonl"

#: the module name of the Blender add-on file (:func:`meshshade.blender.addon_source`)
ADDON_MODULE = "meshshade_addon"

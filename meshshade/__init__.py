"""meshshade: curvature-aware diffusion shading of translucent meshes.

Public API. Importing has one deliberate side effect: before any module imports numba, it points numba's
on-disk cache (``NUMBA_CACHE_DIR``) at a per-user folder named after a hash of the package's sources, so that an
edit to any source file recompiles every kernel that depends on it (:mod:`meshshade.compiled_cache`; a
``NUMBA_CACHE_DIR`` set by the user is left alone).
"""
from meshshade import compiled_cache

compiled_cache.configure()  # first: the imports below import numba, which reads NUMBA_CACHE_DIR

from meshshade.errors import DiffusionValidityWarning, LightError, MaterialError, MeshshadeError, MeshValidationError, OutputError, UnitsError
from meshshade.materials import JENSEN_2001_PRESETS, Material, material_from_options
from meshshade.units import mm_per_unit

__version__ = "0.1.0"

__all__ = [
    "DiffusionValidityWarning", "LightError", "MaterialError", "MeshshadeError", "MeshValidationError",
    "OutputError", "UnitsError", "JENSEN_2001_PRESETS", "Material", "material_from_options", "mm_per_unit",
]

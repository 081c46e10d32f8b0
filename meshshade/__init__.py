"""meshshade: curvature-aware diffusion shading of translucent meshes.

Public API. Importing has one deliberate side effect: before any module imports numba, it points numba's
on-disk cache (``NUMBA_CACHE_DIR``) at a per-user folder named after a hash of the package's sources, so that an
edit to any source file recompiles every kernel that depends on it (:mod:`meshshade.compiled_cache`; a
``NUMBA_CACHE_DIR`` set by the user is left alone).

``import meshshade`` itself imports neither numpy nor numba: the errors and :func:`mm_per_unit` are imported with
it, ``Material``, ``material_from_options`` (:mod:`meshshade.materials`) and ``JENSEN_2001_PRESETS`` on their first
use (PEP 562), so that ``meshshade --help`` answers in a tenth of a second.
"""
import importlib

from meshshade import compiled_cache

compiled_cache.configure()  # first: numba, imported later by meshshade's modules, reads NUMBA_CACHE_DIR

from meshshade.errors import (DiffusionValidityWarning, LightError, MaterialError, MeshshadeError, MeshValidationError,
                              OutputError, UnitsError)
from meshshade.units import mm_per_unit

__version__ = "0.1.0"

__all__ = [
    "DiffusionValidityWarning", "LightError", "MaterialError", "MeshshadeError", "MeshValidationError",
    "OutputError", "UnitsError", "JENSEN_2001_PRESETS", "Material", "material_from_options", "mm_per_unit",
]

#: public names imported on first use, and the module that holds each (materials imports numpy and numba)
_LAZY = {"JENSEN_2001_PRESETS": "meshshade.material_presets", "Material": "meshshade.materials",
         "material_from_options": "meshshade.materials"}


def __getattr__(name):
    """``meshshade.Material`` and the other names of :data:`_LAZY`, imported on first use (PEP 562)."""
    if name not in _LAZY:
        raise AttributeError(f"module 'meshshade' has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name]), name)
    globals()[name] = value  # the next use is a plain attribute
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))

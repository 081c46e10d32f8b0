"""meshshade: curvature-aware diffusion shading of translucent meshes.

Public API (importing has no side effects).
"""
from meshshade.errors import DiffusionValidityWarning, LightError, MaterialError, MeshshadeError, MeshValidationError, OutputError, UnitsError
from meshshade.materials import JENSEN_2001_PRESETS, Material, material_from_options
from meshshade.units import mm_per_unit

__version__ = "0.1.0"

__all__ = [
    "DiffusionValidityWarning", "LightError", "MaterialError", "MeshshadeError", "MeshValidationError",
    "OutputError", "UnitsError", "JENSEN_2001_PRESETS", "Material", "material_from_options", "mm_per_unit",
]

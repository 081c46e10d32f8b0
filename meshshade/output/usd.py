"""A baked mesh as a USD stage (OpenUSD through ``usd-core``; pure: the stage is built in memory, and
:func:`meshshade.io.write_usd` writes it as ``.usd`` / ``.usdc`` (binary) or ``.usda`` (text)).

What the stage holds:

* the default prim ``/meshshade_bake``, a ``UsdGeom.Mesh`` of triangles, **vertices in the order of the baked
  mesh**, points in the mesh's **source units** with ``metersPerUnit`` set from them (``--units``), so the bake
  overlays the input as the PLY does; ``extent`` authored;
* ``primvars:displayColor`` (color3f, vertex interpolation): the tone-mapped display colour, linear (USD's colours
  are linear);
* ``primvars:meshshade:radiance`` (float3, vertex interpolation): linear radiant exitance, W/mm^2 per unit light
  power;
* ``customData`` on the prim (and the layer's ``customLayerData``): ``meshshade:model``, ``meshshade:material``,
  ``meshshade:lights``, ``meshshade:units`` and the generator.
"""
from __future__ import annotations

import numpy as np

from meshshade import __version__
from meshshade.errors import OutputError

__all__ = ["usd_stage", "RADIANCE_PRIMVAR", "pxr_modules"]

RADIANCE_PRIMVAR = "meshshade:radiance"


def pxr_modules():
    """``(Usd, UsdGeom, Sdf, Vt, Gf)`` from usd-core; a one-line OutputError saying how to install it otherwise."""
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, Vt
    except ImportError:
        raise OutputError("USD output needs the usd-core package: pip install usd-core "
                          "(or pip install 'meshshade[usd]')") from None
    return Usd, UsdGeom, Sdf, Vt, Gf


def usd_stage(vertices, faces, display_linear, radiance, *, mm_per_unit: float, metadata: dict | None = None):
    """An in-memory ``Usd.Stage`` of a baked mesh (module docstring).

    vertices : (n, 3) in the mesh's source units (mm times 1/mm_per_unit); faces : (m, 3); display_linear :
    (n, 3) in [0, 1]; radiance : (n, 3) W/mm^2; mm_per_unit : mm per source unit; metadata : str -> str.
    """
    Usd, UsdGeom, Sdf, Vt, Gf = pxr_modules()
    V = np.ascontiguousarray(vertices, dtype=np.float32)
    F = np.asarray(faces, dtype=np.int64)
    R = np.ascontiguousarray(radiance, dtype=np.float32)
    if not (np.all(np.isfinite(V)) and np.all(np.isfinite(R))):
        raise OutputError("USD: positions and radiance must be finite float32 numbers")
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageMetersPerUnit(stage, float(mm_per_unit) * 1e-3)
    mesh = UsdGeom.Mesh.Define(stage, "/meshshade_bake")
    stage.SetDefaultPrim(mesh.GetPrim())
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(V))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(F.shape[0], 3, dtype=np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(F.ravel(), dtype=np.int32)))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, V.min(axis=0))), Gf.Vec3f(*map(float, V.max(axis=0)))]))
    mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.vertex).Set(
        Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(np.clip(display_linear, 0.0, 1.0), dtype=np.float32)))
    pv = UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar(RADIANCE_PRIMVAR, Sdf.ValueTypeNames.Float3Array,
                                                            UsdGeom.Tokens.vertex)
    pv.Set(Vt.Vec3fArray.FromNumpy(R))
    data = {"meshshade:generator": f"meshshade {__version__}",
            "meshshade:radiance_units": "W/mm^2 per unit light power (linear radiant exitance)",
            **{f"meshshade:{k}": str(v) for k, v in (metadata or {}).items()}}
    prim = mesh.GetPrim()
    for k, v in data.items():
        prim.SetCustomDataByKey(k, v)
    stage.GetRootLayer().customLayerData = data
    return stage

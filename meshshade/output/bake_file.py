"""The bake's files: the baked mesh (PLY, glTF/GLB or USD) with the radiance and tone-mapped vertex colours, and
optionally an NPZ of its arrays.

Builds the content from a :class:`~meshshade.transport.baking.BakeResult`; :mod:`meshshade.io` writes it. The
format follows the extension of ``out`` (:data:`BAKE_FORMATS`):

* ``.ply``: ``radiance_r/g/b`` (float W/mm^2) and ``red/green/blue`` (uchar, sRGB), positions in source units
  (MeshLab, Blender);
* ``.glb`` / ``.gltf``: :mod:`meshshade.output.gltf` (``COLOR_0`` linear display colour, ``_RADIANCE``; metres;
  three.js, game engines, Blender's importer);
* ``.usd`` / ``.usdc`` / ``.usda``: :mod:`meshshade.output.usd` (``primvars:displayColor``,
  ``primvars:meshshade:radiance``; source units with ``metersPerUnit``; film pipelines).

A texture bake (:func:`write_texture`, :mod:`meshshade.output.texture`) writes ``OUT.exr`` (linear RGBA float32,
``meshshade:*`` metadata), ``OUT.png`` (tone-mapped sRGB) and, for an automatic atlas, ``OUT.obj`` (the mesh with
``vt`` and ``f v/vt``); a glTF written with it carries ``TEXCOORD_0`` and the texture as emissive.
"""
from __future__ import annotations

from pathlib import Path

from meshshade import io
from meshshade.io import write_bytes, write_text
from meshshade.errors import OutputError
from meshshade.light.sources import describe_light
from meshshade.output.gltf import glb_bytes, gltf_document, gltf_text
from meshshade.output.texture import encode_png, texture_metadata, texture_rgba
from meshshade.output.tonemap import to_uint8, tonemap_linear
from meshshade.output.usd import pxr_modules, usd_stage
from meshshade.transport.baking import BakeResult

#: extension -> format of :func:`write_bake`
BAKE_FORMATS = {".ply": "ply", ".glb": "glb", ".gltf": "gltf", ".usd": "usd", ".usdc": "usd", ".usda": "usd"}


def bake_format(out) -> str:
    """The format :func:`write_bake` writes to ``out`` (from its extension); OutputError naming the choices."""
    suffix = Path(out).suffix.lower()
    if suffix not in BAKE_FORMATS:
        raise OutputError(f"--out {out}: a bake is written as {', '.join(BAKE_FORMATS)} (from the extension)")
    return BAKE_FORMATS[suffix]


def check_bake_output(out) -> str:
    """Before a bake: the format of ``out``, and for USD that usd-core can be imported (one-line OutputError)."""
    fmt = bake_format(out)
    if fmt == "usd":
        pxr_modules()
    return fmt


def texture_outputs(path, *, atlas: bool) -> dict:
    """The files of a texture bake named ``path`` (.exr): {"exr", "png"} and, with an automatic ``atlas``, "obj"
    (the mesh with the atlas's UVs, so the texture can be used)."""
    p = Path(path)
    out = {"exr": p, "png": p.with_suffix(".png")}
    if atlas:
        out["obj"] = p.with_suffix(".obj")
    return out


def write_texture(tex, mesh, path, *, lights=None) -> list:
    """Write a :class:`~meshshade.output.texture.TextureBake`: the linear RGBA EXR (metadata: units and settings),
    the tone-mapped PNG and, for an automatic atlas, the mesh with its UVs as OBJ (in the source file's units).
    Returns the paths written."""
    files = texture_outputs(path, atlas=tex.uv_source == "xatlas")
    linear, display = texture_rgba(tex)
    lights_text = "; ".join(describe_light(lt, i) for i, lt in enumerate(lights)) if lights else None
    io.write_exr(files["exr"], linear, texture_metadata(tex, lights_text))
    io.write_png(files["png"], display)
    if "obj" in files:
        io.write_obj(files["obj"], mesh.vertices_in_source_units(), mesh.faces, uv=tex.uv,
                     comment=f"meshshade automatic UV atlas (xatlas) of {mesh.source or 'the mesh'}, for "
                             f"{files['exr'].name}; positions in the source file's units")
    return list(files.values())


def write_bake(result: BakeResult, mesh, out, *, npz=None, lights=None, texture=None, texture_path=None) -> None:
    """Write the baked mesh ``out`` in the format of its extension (module docstring; the PLY holds
    radiance_r/g/b float W/mm^2 + uchar red/green/blue, Drago tone-mapped) and, when ``npz`` is given, an NPZ
    with radiance (n, 3) W/mm^2, k1, k2 (n,) 1/mm, d1, d2 (n, 3), vertex_areas (n,) mm^2, cutoff_mm (3,),
    entry_positions (k, 3) mm, entry_power (k,) W, beam_distance (n,) mm (with a beam) and the auto plan's
    auto_kernel (k,) / auto_exact_geodesic (k,) (``model="auto"``). ``lights`` (optional) are recorded in the
    glTF and USD metadata. With ``texture`` (a TextureBake) a glTF binds its tone-mapped texture as emissive and
    names the linear one, ``texture_path``."""
    M = result.radiance
    fmt = bake_format(out)
    display = tonemap_linear(M, operator="drago")
    meta = {"model": result.model, "material": result.material.describe(),
            "units": f"positions: {'m' if fmt in ('glb', 'gltf') else f'{mesh.mm_per_unit!r} mm per unit'}"}
    if lights:
        meta["lights"] = "; ".join(describe_light(lt, i) for i, lt in enumerate(lights))
    if result.plan is not None:
        meta["auto_plan"] = result.plan.describe()
    if mesh.source and Path(mesh.source).exists():
        io.check_output_path(out, [mesh.source])
    if fmt == "ply":
        props = {"radiance_r": M[:, 0], "radiance_g": M[:, 1], "radiance_b": M[:, 2]}
        comments = [f"meshshade model {result.model}", f"meshshade material {result.material.describe()}",
                    "meshshade radiance_r/g/b: linear radiant exitance in W/mm^2 per unit light power/irradiance"]
        if result.plan is not None:
            comments.append(f"meshshade {result.plan.describe()}")
        io.write_mesh_ply(out, mesh, props, to_uint8(display), comments=comments)
    elif fmt in ("glb", "gltf"):
        tex = None
        if texture is not None:
            tex = {"uv": texture.uv, "png": encode_png(texture_rgba(texture)[1]),
                   "linear_uri": Path(texture_path).name if texture_path else None}
        doc, data = gltf_document(mesh.vertices, mesh.faces, display, M, extras=meta, texture=tex)
        if fmt == "glb":
            write_bytes(out, glb_bytes(doc, data))
        else:
            write_text(out, gltf_text(doc, data))
    else:
        io.write_usd(out, usd_stage(mesh.vertices_in_source_units(), mesh.faces, display, M,
                                    mm_per_unit=mesh.mm_per_unit, metadata=meta))
    if npz:
        arrays = dict(radiance=M, k1=result.k1, k2=result.k2, d1=result.d1, d2=result.d2,
                      vertex_areas=mesh.vertex_areas, cutoff_mm=result.cutoff_mm,
                      entry_positions=result.samples.positions, entry_power=result.samples.power)
        if result.beam_distance is not None:
            arrays["beam_distance"] = result.beam_distance
        if result.plan is not None:  # per entry sample: 0 dipole, 1 curved, 2 exact-sphere; exact geodesics
            arrays["auto_kernel"] = result.plan.kernel
            arrays["auto_exact_geodesic"] = result.plan.exact_geodesic
        io.write_npz(npz, **arrays)

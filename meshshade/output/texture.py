"""Texture bakes: the radiant exitance at every covered texel of a UV map (pure arrays; the CLI writes the files).

A texel is a point on the surface: the texel's centre in UV space, mapped by its face's barycentrics to a 3D point
on that face with the interpolated shading normal (:func:`meshshade.geometry.uv.rasterise_uv`). Its exitance is
evaluated there, not interpolated from the mesh's vertex values:

1. **The volume model (the default)** samples the surface on its own where the mesh is coarser than the material
   resolves (:class:`meshshade.volume.surface.SamplingSurface`: long edges split on the facets) and solves there;
   a texel takes that solution P1 within the split triangle holding it (``BakeResult.sample_exitance``). The
   vertex bake reads the same solution at the vertices (vertices of the split surface too): texels and vertices
   are one field, read at points. The mesh itself is not refined, so a texture costs the vertex bake plus the
   texels' lookups.
   **The surface models** are refined instead to what the material resolves: where the mesh's mean edge is longer
   than REFINE_SPACING x half the volume's surface spacing, each triangle is split into n^2 on its own facet
   (same polyhedron, normals of the original interpolated; :mod:`meshshade.geometry.refine`; within
   MAX_REFINED_VERTICES, with a warning where that stops it short) and the bake runs on that surface.
2. **Beams** (point entries) add their near field gathered at the texel's own point
   (:class:`meshshade.output.render.PixelGather`, the same evaluation as ``render --per-pixel``), so a pencil
   beam's peak is as sharp as the texels, not the triangles. The near field of vertex entries (directional and
   point lights: each stands for its vertex's patch) is part of the smooth solution: summed per texel it has a
   ripple at the vertices' spacing (measured 2 / 4 / 7 % r.m.s. r/g/b on a sun-lit 642-vertex ball) that is an
   artefact of the patch discs, not light.
3. **Padding**: texels outside every UV triangle, up to ``padding`` texels away, take the nearest covered texel's
   value (:func:`meshshade.geometry.uv.dilate`), so filtering and mipmaps do not bleed the background in.

A texel at a vertex equals the vertex bake (``TextureBake.vertex_radiance``, the same solve read at the same point):
tools/benchmarks/bench_texel_vertex.py looks the texture up at a UV sphere's vertices.
"""
from __future__ import annotations

import hashlib
import math
import struct
import time
import warnings
import zlib
from dataclasses import dataclass, field, replace

import numpy as np

from meshshade.errors import ParameterError
from meshshade.geometry.refine import refined_location, refined_mesh
from meshshade.geometry.uv import automatic_atlas, check_uv, dilate, rasterise_uv
from meshshade.materials import Material
from meshshade.names import DEFAULT_MODEL
from meshshade.output.render import PixelGather
from meshshade.output.tonemap import to_uint8, tonemap_linear
from meshshade.transport.baking import bake
from meshshade.transport.options import BakeOptions, bake_options_from_keywords
from meshshade.transport.result import BakeResult
from meshshade.volume.resolution import volume_resolution

__all__ = ["TextureBake", "bake_texture", "texture_refinement", "refinement_budget", "REFINE_SPACING", "MAX_REFINE",
           "MAX_REFINED_VERTICES", "check_texture_options"]

#: the surface is refined until its mean edge is at most this many column spacings of the volume mesh
REFINE_SPACING = 2.0
#: at most this many segments per edge (n^2 triangles per face)
MAX_REFINE = 8
#: the automatic refinement keeps the refined surface within this many vertices (a 141k-vertex head bakes in 3.5 min
#: and 2.8 GB on 2 cores: docs/benchmarks.md); beyond it the texture says it is coarser than the material resolves
MAX_REFINED_VERTICES = 250_000
#: texture sizes accepted (texels per side)
MIN_SIZE, MAX_SIZE = 8, 16384


@dataclass(frozen=True)
class TextureBake:
    """The result of :func:`bake_texture`.

    image : (H, W, 3) float64 W/mm^2 linear exitance per texel (padded texels filled, others 0)
    covered : (H, W) bool, texels on the surface; filled : (H, W) bool, covered or padding
    uv : (m, 3, 2) the UV map used (from the mesh or the automatic atlas)
    uv_source : "mesh" or "xatlas"
    refine : segments per edge of the refined surface (1: the mesh as it is)
    vertex_radiance : (n, 3) W/mm^2 at the mesh's vertices (from the same solve as the texels)
    result : the BakeResult on the refined surface; timings, stats
    """

    image: np.ndarray
    covered: np.ndarray
    filled: np.ndarray
    uv: np.ndarray
    uv_source: str
    refine: int
    vertex_radiance: np.ndarray
    result: BakeResult
    timings: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)

    def vertex_result(self) -> BakeResult:
        """The bake at the mesh's own vertices (from the same solve as the texels): a BakeResult to write as a
        PLY, glTF or USD."""
        n = self.vertex_radiance.shape[0]
        r = self.result
        cut = (lambda a: None if a is None else a[:n])
        return replace(r, radiance=self.vertex_radiance, k1=cut(r.k1), k2=cut(r.k2), d1=cut(r.d1), d2=cut(r.d2),
                       beam_distance=None if r.beam_distance is None else r.beam_distance[:n], timings=self.timings,
                       stats=self.stats)

    def describe(self) -> str:
        """One line: the texture, where its UVs came from, the surface it was solved on."""
        H, W = self.covered.shape
        s = self.stats
        uv = (f"automatic atlas ({s.get('uv_charts')} charts)" if self.uv_source == "xatlas" else "the mesh's UVs")
        over = s.get("uv_overlap_texels", 0)
        return (f"texture {W}x{H} from {uv}: {int(self.covered.sum())} texels on the surface"
                + (f" ({over} claimed by overlapping UV islands: the first face kept them)" if over else "")
                + f", padding {s['texture_padding']}; solved on the surface split {self.refine}x{self.refine} "
                f"({s['texture_surface_vertices']} vertices)")

    def __repr__(self) -> str:
        H, W = self.covered.shape
        return (f"<TextureBake {W}x{H}, {int(self.covered.sum())} texels on the surface, UVs from {self.uv_source}, "
                f"surface refined x{self.refine}; {sum(self.timings.values()):.3g} s>")


def check_texture_options(size=2048, padding=16, refine=None) -> tuple[int, int, int | None]:
    """(size, padding, refine) checked: one-line ParameterError otherwise."""
    def whole(value, name, lo, hi):
        integral = isinstance(value, (int, np.integer)) or (isinstance(value, float) and value.is_integer())
        if isinstance(value, bool) or not integral:
            raise ParameterError(f"{name} must be a whole number, got {value!r}")
        if not lo <= int(value) <= hi:
            raise ParameterError(f"{name} must lie in [{lo}, {hi}], got {value!r}")
        return int(value)
    size = whole(size, "texture size", MIN_SIZE, MAX_SIZE)
    padding = whole(padding, "texture padding", 0, size)
    refine = None if refine is None or refine == "auto" else whole(refine, "texture refinement", 1, MAX_REFINE)
    return size, padding, refine


def texture_refinement(mesh, material, model: str = DEFAULT_MODEL) -> int:
    """Segments per edge of the surface the bake runs on: 1 for the volume model (it samples the surface itself:
    module docstring), else so that the mean edge is within :data:`REFINE_SPACING` half surface spacings, at most
    :data:`MAX_REFINE` (see :func:`refinement_budget` for the vertex budget)."""
    if model == "volume":
        return 1
    target = REFINE_SPACING * 0.5 * volume_resolution(material, float(mesh.total_area), mesh.bbox_size_mm).h0
    return int(min(MAX_REFINE, max(1, math.ceil(float(mesh.mean_edge_length) / target - 1e-9))))


def refinement_budget(mesh) -> int:
    """The most segments per edge that keep the refined surface within :data:`MAX_REFINED_VERTICES` (about n^2
    times the vertices), at least 1."""
    return max(1, int(math.isqrt(MAX_REFINED_VERTICES // max(mesh.n_vertices, 1))))


def atlas_key(mesh, size: int, padding: int) -> str:
    """Hex digest naming the automatic atlas of ``mesh`` for a texture of ``size`` with charts ``padding`` apart."""
    h = hashlib.sha256(f"xatlas/1 {int(size)} {int(padding)}".encode())
    for a in (np.ascontiguousarray(mesh.vertices, dtype=np.float64), np.ascontiguousarray(mesh.faces, dtype=np.int64)):
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:32]


def texture_atlas(mesh, size: int, padding: int, cache=None) -> tuple[np.ndarray, dict]:
    """(uv, stats) of the automatic atlas, looked up in and kept in ``cache`` (an object with ``read(key)`` and
    ``write(key, **arrays)``, :class:`meshshade.asset_cache.AssetCache`) when one is given."""
    key = atlas_key(mesh, size, padding) if cache is not None else None
    got = cache.read(key) if cache is not None else None
    if got is not None and "uv" in got and got["uv"].shape == (mesh.n_faces, 3, 2):
        return np.asarray(got["uv"], dtype=np.float64), {"uv_source": "xatlas", "uv_charts": int(got["charts"]),
                                                          "uv_utilisation": float(got["utilisation"]),
                                                          "uv_atlas_cached": True}
    uv, stats = automatic_atlas(mesh.vertices, mesh.faces, size=size, padding=padding)
    if cache is not None:
        cache.write(key, uv=uv, charts=np.int64(stats["uv_charts"]), utilisation=np.float64(stats["uv_utilisation"]))
    return uv, {**stats, "uv_atlas_cached": False}


def bake_texture(mesh, material, lights, options: BakeOptions | None = None, *, uv=None, size: int = 2048,
                 padding: int = 16, refine=None, atlas_cache=None, **deprecated) -> TextureBake:
    """Bake ``mesh`` (mm) into a ``size`` x ``size`` texture of its UV map ``uv`` ((m, 3, 2) per-corner, or None
    for an automatic atlas by xatlas, kept in ``atlas_cache`` when given: :func:`texture_atlas`); module docstring
    for what each texel holds. ``refine``: segments per edge of the surface the transport runs on (None:
    :func:`texture_refinement`); ``options``: the bake's (:class:`~meshshade.transport.options.BakeOptions`; its
    former keyword arguments are accepted with a DeprecationWarning)."""
    options = bake_options_from_keywords(options, deprecated, "bake_texture")
    size, padding, refine = check_texture_options(size, padding, refine)
    timings, stats = {}, {}
    t0 = time.perf_counter()
    if uv is None:
        uv, atlas = texture_atlas(mesh, size, max(2, min(padding, 8)), atlas_cache)
        stats.update(atlas)
        source = "xatlas"
        timings["uv atlas"] = time.perf_counter() - t0
        t0 = time.perf_counter()
    else:
        source = "mesh"
    uv = np.asarray(uv, dtype=np.float64)
    stats.update(check_uv(uv, mesh.n_faces))
    texel, face, bary, rstats = rasterise_uv(uv, size, size)
    stats.update(rstats)
    timings["texture rasterise"] = time.perf_counter() - t0
    n = texture_refinement(mesh, material, options.model) if refine is None else refine
    if refine is None and n > refinement_budget(mesh):
        wanted, n = n, refinement_budget(mesh)
        stats["texture_refine_wanted"] = wanted
        warnings.warn(f"texture: the surface was split {n}x{n}, not the {wanted}x{wanted} the material resolves "
                      f"(that would be about {wanted * wanted * mesh.n_vertices:,} vertices, over "
                      f"{MAX_REFINED_VERTICES:,}): texels between vertices are coarser than the light's scale; "
                      "--texture-refine N asks for more (check --units: the mesh's mean edge is "
                      f"{mesh.mean_edge_length:.3g} mm)", stacklevel=2)
    if n != 1 and not isinstance(material, Material):
        raise ParameterError("a painted material is baked into a texture on the mesh as it is (--texture-refine 1; "
                             "its paint lies on the mesh's own faces)")
    t0 = time.perf_counter()
    surface = refined_mesh(mesh, n)
    timings["texture refine"] = time.perf_counter() - t0
    result = bake(surface, material, lights, options)
    t0 = time.perf_counter()
    sub_face, sub_bary = refined_location(face, bary, n)
    points = np.einsum("ij,ijk->ik", sub_bary, surface.vertices[surface.faces[sub_face]])
    values = np.maximum(PixelGather(surface, result)(points, sub_face, sub_bary), 0.0)
    image = np.zeros((size * size, 3))
    image[texel] = values
    covered = np.zeros(size * size, dtype=bool)
    covered[texel] = True
    image, filled = dilate(image.reshape(size, size, 3), covered.reshape(size, size), padding)
    timings["texture texels"] = time.perf_counter() - t0
    stats.update({"texture_size": size, "texture_padding": padding, "texture_refine": n,
                  "texture_surface_vertices": surface.n_vertices, "uv_source": source})
    all_timings = {**result.timings, **timings}
    return TextureBake(image, covered.reshape(size, size), filled, uv, source, n,
                       np.asarray(result.radiance[:mesh.n_vertices]), result, all_timings,
                       {**result.stats, **stats})


def texture_metadata(tex: TextureBake, lights_text: str | None = None) -> dict:
    """String metadata for the EXR (``meshshade:<key>``): units, the bake's settings and the texture's."""
    r = tex.result
    meta = {"units": "RGB: linear radiant exitance, W/mm^2 per unit light power/irradiance/intensity; "
                     "A: 1 on the surface and its padding, 0 elsewhere",
            "model": r.model, "material": r.material.describe(), "uv_source": tex.uv_source,
            "texture": f"{tex.covered.shape[1]}x{tex.covered.shape[0]}, padding {tex.stats['texture_padding']}, "
                       f"{int(tex.covered.sum())} texels on the surface, surface refined {tex.refine}x{tex.refine}",
            "transport": str(r.stats.get("transport", ""))}
    if lights_text:
        meta["lights"] = lights_text
    return meta


def texture_rgba(tex: TextureBake) -> tuple[np.ndarray, np.ndarray]:
    """(linear RGBA float (H, W, 4), display RGBA uint8 (H, W, 4)): the EXR's and the PNG's pixels (the PNG
    tone-mapped by Drago over the texels on the surface, as the PLY's colours are)."""
    alpha = tex.filled.astype(np.float64)[..., None]
    linear = np.concatenate([tex.image, alpha], axis=2)
    display = tonemap_linear(tex.image.reshape(-1, 3), operator="drago", mask=tex.covered.reshape(-1))
    display = to_uint8(np.clip(display, 0.0, 1.0)).reshape(tex.image.shape)
    return linear, np.concatenate([display, (alpha * 255).astype(np.uint8)], axis=2)


def encode_png(rgba) -> bytes:
    """An 8-bit RGBA PNG of (H, W, 4) uint8 in memory (filter 0 per row, zlib level 6; PNG 1.2)."""
    a = np.ascontiguousarray(rgba, dtype=np.uint8)
    H, W = a.shape[:2]
    raw = np.concatenate([np.zeros((H, 1), dtype=np.uint8), a.reshape(H, W * 4)], axis=1).tobytes()

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, 8, 6, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))

"""Texture bakes (issues 31, 40): texels against the vertex bake, a beam's peak per texel, and the sun-lit ball's
texture against its exact solution.

Reference for the ball (tests/volume/_sun_ball_reference.py, independent of the bake's discretisation and tables):
the exact Robin ball series of the line sources under a continuous sun plus the continuum limit of the near-field
correction, eq. (98), from the public kernels; the texels' points from a rasteriser written here in numpy (texel
centres ((c + 1/2)/N, 1 - (r + 1/2)/N) in each UV triangle, the mesh's barycentric interpolation), not
meshshade.geometry.uv.rasterise_uv.

With the volume model (the default) the mesh is not refined for a texture: the texels read the solution on the
surface the transport samples (long edges split on the facets), P1 within its triangles, and the vertex bake reads
the same field at the vertices (issue 47): a texture looked up at the vertices' UVs (bilinearly between texel
centres, written here) gives the vertex bake back.
"""
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere, spherical_uv, uv_sphere
from meshshade.light import BeamLight, DirectionalLight
from meshshade.materials import Material
from meshshade.output.render import PixelGather
from meshshade.output.texture import bake_texture, texture_refinement
from meshshade.transport.baking import bake
from meshshade.transport import BakeOptions

_spec = importlib.util.spec_from_file_location(
    "sun_ball_reference", Path(__file__).parents[1] / "volume" / "_sun_ball_reference.py")
sun_ball = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(sun_ball)
near_field_ball, near_field_radius_and_rest = sun_ball.near_field_ball, sun_ball.near_field_radius_and_rest

SKIN = Material.preset("skin1")
SUN = [DirectionalLight((0.0, 0.0, -1.0), 1.0)]


@pytest.fixture(scope="module")
def ball_reference():
    """points -> exact exitance of the sun-lit ball (volume series + near-field continuum)."""
    return sun_ball.exact_at()


def texel_points(uv, size):
    """(texel (k,) flat index row * size + col, face (k,), bary (k, 3)) of the texel centres ((col + 1/2)/size,
    1 - (row + 1/2)/size) inside each UV triangle (edges included, the first face keeps a texel), in numpy."""
    owner = -np.ones(size * size, dtype=np.int64)
    bary = np.zeros((size * size, 3))
    px, py = uv[:, :, 0] * size - 0.5, (1.0 - uv[:, :, 1]) * size - 0.5     # texel (row, col) centre at (col, row)
    for f in range(uv.shape[0]):
        x, y = px[f], py[f]
        det = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0])
        c0, c1 = max(math.ceil(x.min()), 0), min(math.floor(x.max()), size - 1)
        r0, r1 = max(math.ceil(y.min()), 0), min(math.floor(y.max()), size - 1)
        if det == 0 or c1 < c0 or r1 < r0:
            continue
        cc, rr = (a.ravel() for a in np.meshgrid(np.arange(c0, c1 + 1), np.arange(r0, r1 + 1)))
        l1 = ((cc - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (rr - y[0])) / det
        l2 = ((x[1] - x[0]) * (rr - y[0]) - (cc - x[0]) * (y[1] - y[0])) / det
        lam = np.stack([1.0 - l1 - l2, l1, l2], axis=1)
        inside = np.all(lam >= -1e-12, axis=1)
        k = rr[inside] * size + cc[inside]
        free = owner[k] < 0
        owner[k[free]] = f
        bary[k[free]] = np.clip(lam[inside][free], 0.0, 1.0)
    texel = np.flatnonzero(owner >= 0)
    return texel, owner[texel], bary[texel] / bary[texel].sum(axis=1, keepdims=True)


def _error(M, ref):
    keep = ref > 1e-3 * ref.max()
    return float(np.mean(np.abs(M[keep] / ref[keep] - 1.0)))


def test_near_field_continuum_is_converged():
    th = np.radians([0.0, 60.0, 90.0, 95.0])
    a = near_field_ball(th, sun_ball.MATERIAL, sun_ball.R)
    b = near_field_ball(th, sun_ball.MATERIAL, sun_ball.R, n_alpha=480, n_phi=160, n_c=128)
    np.testing.assert_allclose(a, b, atol=1e-3 * np.abs(b).max())
    radius, _, rest = near_field_radius_and_rest(sun_ball.MATERIAL)
    radius2, _, rest2 = near_field_radius_and_rest(sun_ball.MATERIAL, n_r=2401)
    assert radius2 == pytest.approx(radius, rel=1e-3)
    np.testing.assert_allclose(rest2, rest, rtol=1e-3)


def _ball_texture(ball_reference, refine):
    V, F = icosphere(sun_ball.R, 3)                                 # 642 vertices, edges about 3.3 mm
    mesh = Mesh.from_arrays(V, F)
    uv = spherical_uv(V, F)
    tex = bake_texture(mesh, sun_ball.MATERIAL, SUN, uv=uv, size=1024, padding=2, refine=refine)
    texel, face, bary = texel_points(uv, 1024)
    assert np.array_equal(np.flatnonzero(tex.covered), texel)       # the same texels on the surface
    points = np.einsum("ij,ijk->ik", bary, V[F[face]])
    return tex, _error(tex.image.reshape(-1, 3)[texel, 0], ball_reference(points))


def test_coarse_ball_texture_matches_the_exact_solution_between_vertices(ball_reference):
    """A 642-vertex ball (edges 3.3 mm) baked into a 1024^2 texture by the default model: no refinement, the
    texels within 8 % of the exact solution on average (measured 6.9 %; the same ball's vertex bake 7.6 %, the
    2562-vertex ball's 2.7 %: tests/volume/test_volume_sun_ball.py). Issue 31's target (within twice the 10k bake's
    vertex error) was met by the tetrahedral model with a refined surface (1.42 %); the lattice model samples this
    ball at its own 5.7 mm and does not (docs/limitations.md)."""
    tex, err = _ball_texture(ball_reference, None)
    assert tex.refine == texture_refinement(Mesh.from_arrays(*icosphere(sun_ball.R, 3)), sun_ball.MATERIAL) == 1
    assert err < 0.08, err


def test_without_refinement_texels_are_the_vertex_bake_where_lights_enter_at_vertices():
    mesh = Mesh.from_arrays(*icosphere(5.0, 4))          # edges of 0.35 mm: finer than h0, the surface not split
    uv = spherical_uv(mesh.vertices, mesh.faces)
    tex = bake_texture(mesh, SKIN, SUN, uv=uv, size=128, padding=0, refine=1)
    plain = bake(mesh, SKIN, SUN)
    assert plain.stats["volume_samples_split"] is False
    np.testing.assert_allclose(tex.vertex_radiance, plain.radiance, rtol=1e-9, atol=1e-15)
    texel, face, bary = texel_points(uv, 128)
    interp = np.maximum(np.einsum("ij,ijk->ik", bary, plain.radiance[mesh.faces[face]]), 0.0)
    np.testing.assert_allclose(tex.image.reshape(-1, 3)[texel], interp, rtol=1e-9, atol=1e-15)
    assert np.all(tex.image.reshape(-1, 3)[~tex.covered.reshape(-1)] == 0.0)     # no padding asked for


def bilinear(image, uv):
    """(k, C) ``image`` (H, W, C) at ``uv`` (k, 2), bilinear between texel centres ((c + 1/2)/W, 1 - (r + 1/2)/H),
    clamped at the border: a renderer's lookup without mipmaps."""
    H, W = image.shape[:2]
    x = np.clip(uv[:, 0] * W - 0.5, 0.0, W - 1.0)
    y = np.clip((1.0 - uv[:, 1]) * H - 0.5, 0.0, H - 1.0)
    x0, y0 = np.minimum(x.astype(np.int64), W - 2), np.minimum(y.astype(np.int64), H - 2)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    return ((1 - fx) * (1 - fy) * image[y0, x0] + fx * (1 - fy) * image[y0, x0 + 1]
            + (1 - fx) * fy * image[y0 + 1, x0] + fx * fy * image[y0 + 1, x0 + 1])


def test_texels_at_the_vertices_uvs_are_the_vertex_bake():
    """Issue 47: the texels of one bake, looked up at the vertices' UVs, give its vertex bake back on a UV sphere
    whose diagonals the sampling surface splits (here 48 x 24 of radius 10 mm, edges 1.3 mm as the issue's 96 x 48
    of 20 mm, skin1, a sun at an angle; a 512^2 texture, 10 texels per face along u): |texel / vertex - 1| within
    0.5 % median and 2 % at the 90th percentile over the vertices above 1e-3 of each channel's peak, and over the
    lit ones (measured 0.12 % / 0.8 %; the issue's 96 x 48 sphere: tools/benchmarks/bench_texel_vertex.py). A
    vertex that took the patch average of eq. (104) instead of the point value was 1.9 % / 11 % off."""
    V, F = uv_sphere(10.0, 24, 48)
    mesh = Mesh.from_arrays(V, F)
    uv = spherical_uv(V, F)
    sun = [DirectionalLight((0.3, -0.4, -0.866), 1.0)]
    tex = bake_texture(mesh, SKIN, sun, uv=uv, size=512, padding=4)
    assert tex.result.stats["volume_samples_split"]                 # the case where the two could differ
    vertex = bake(mesh, SKIN, sun, volume=tex.result.volume).radiance
    corner = bilinear(tex.image, uv.reshape(-1, 2))                  # each corner's UV; a vertex: their mean
    count = np.bincount(F.ravel(), minlength=mesh.n_vertices)[:, None]
    texel = np.stack([np.bincount(F.ravel(), weights=corner[:, c], minlength=mesh.n_vertices)
                      for c in range(3)], axis=1) / count
    lit = np.zeros(mesh.n_vertices, dtype=bool)
    s = tex.result.samples
    lit[s.vertex[(s.vertex >= 0) & (s.vertex < mesh.n_vertices) & (s.power > 0)]] = True
    for keep in (vertex > 1e-3 * vertex.max(axis=0), lit[:, None] & (vertex > 0)):
        d = np.abs(texel[keep] / vertex[keep] - 1.0)
        assert np.median(d) < 5e-3 and np.percentile(d, 90) < 2e-2, (np.median(d), np.percentile(d, 90))


def test_a_beam_peak_is_resolved_per_texel():
    mesh = Mesh.from_arrays(*icosphere(5.0, 3))
    V, F = mesh.vertices, mesh.faces
    centre = V[F[0]].mean(axis=0)                                   # between vertices
    beam = [BeamLight(tuple(2.0 * centre), tuple(-centre / np.linalg.norm(centre)), 1.0)]
    uv = spherical_uv(V, F)
    tex = bake_texture(mesh, SKIN, beam, uv=uv, size=512, padding=0, refine=1)
    r = tex.result
    g = PixelGather(mesh, r)
    vf, vb = _vertex_faces(F, V.shape[0])
    np.testing.assert_allclose(g(V, vf, vb), r.radiance, rtol=1e-9, atol=1e-15)   # equal at the vertices
    img = tex.image.reshape(-1, 3)
    assert np.all(img.max(axis=0) > 1.3 * r.radiance.max(axis=0))   # the peak between vertices: 1.8/1.6/1.4x


def _vertex_faces(F, n):
    """For each vertex a face holding it and the barycentrics that put the point on that vertex."""
    face = np.zeros(n, dtype=np.int64)
    corner = np.zeros(n, dtype=np.int64)
    for k in range(3):
        face[F[:, k]] = np.arange(F.shape[0])
        corner[F[:, k]] = k
    bary = np.zeros((n, 3))
    bary[np.arange(n), corner] = 1.0
    return face, bary


def test_the_automatic_atlas_is_kept_in_the_asset_cache(tmp_path, monkeypatch):
    from meshshade.asset_cache import AssetCache
    from meshshade.output.texture import texture_atlas

    monkeypatch.setenv("MESHSHADE_ASSET_CACHE", str(tmp_path))
    mesh = Mesh.from_arrays(*icosphere(5.0, 2))
    cache = AssetCache("uv-atlas")
    uv1, s1 = texture_atlas(mesh, 128, 4, cache)
    uv2, s2 = texture_atlas(mesh, 128, 4, cache)
    assert (s1["uv_atlas_cached"], s2["uv_atlas_cached"]) == (False, True)
    np.testing.assert_array_equal(uv1, uv2)
    assert s1["uv_charts"] == s2["uv_charts"]
    _, s3 = texture_atlas(mesh, 256, 4, cache)                  # another size: another atlas
    assert not s3["uv_atlas_cached"]


def test_the_automatic_refinement_keeps_to_its_vertex_budget(monkeypatch):
    """A mesh whose edges are far longer than the material resolves (here: a 42-vertex ball at 200 mm, mean edge
    over 100 mm against skin1's 0.9 mm) would ask for 8x8; the budget stops it short and says so."""
    import meshshade.output.texture as texture

    mesh = Mesh.from_arrays(*icosphere(200.0, 1))
    assert texture_refinement(mesh, SKIN, "dipole") == 8
    assert texture_refinement(mesh, SKIN) == 1                     # the volume model samples the surface itself
    monkeypatch.setattr(texture, "MAX_REFINED_VERTICES", 4 * mesh.n_vertices)
    with pytest.warns(UserWarning, match=r"split 2x2, not the 8x8"):
        tex = bake_texture(mesh, SKIN, SUN, BakeOptions(model="dipole"), uv=spherical_uv(mesh.vertices, mesh.faces),
                           size=32, padding=0)
    assert tex.refine == 2 and tex.stats["texture_refine_wanted"] == 8

"""Texture bakes (issue 31): texels against the vertex bake, a beam's peak per texel, and the sun-lit ball's
texture against its exact solution.

Reference for the ball (independent of the bake's discretisation): the exact Robin ball series of the volume's
line sources under a continuous sun (tests/volume/test_volume_sun_ball.py, checked there against mpmath) plus the
continuum limit of the near-field correction, eq. (98) integrated over the exact sphere's lit surface by
Gauss-Legendre in log angle x midpoint rule in azimuth around each receiver, with the signed remainder beyond the
radius at the receiver, as the correction keeps it. The correction's table Delta R itself is the model's
definition (tested against eqs. (93)/(96) in tests/volume and tests/kernels); what is tested here is the mesh,
the refinement and the evaluation at texels.
"""
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere, spherical_uv
from meshshade.geometry.uv import rasterise_uv
from meshshade.kernels.fresnel import fresnel_transmittance_entry, refract_in
from meshshade.light import BeamLight, DirectionalLight
from meshshade.materials import Material
from meshshade.output.render import PixelGather
from meshshade.output.texture import bake_texture, texture_refinement
from meshshade.transport.baking import bake
from meshshade.volume.near_field import _LOG_R, NearFieldCorrection
from meshshade.volume.transport import diffusion_constants

_spec = importlib.util.spec_from_file_location(
    "sun_ball", Path(__file__).parents[1] / "volume" / "test_volume_sun_ball.py")
sun_ball = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(sun_ball)

SKIN = Material.preset("skin1")
SUN = [DirectionalLight((0.0, 0.0, -1.0), 1.0)]


def near_field_ball(theta_p, material, R, n_alpha=240, n_phi=160):
    """Continuum limit of the near-field correction (channel 0) on the exact ball of radius R under a unit sun
    from +z, at polar angles ``theta_p`` (module docstring)."""
    corr = NearFieldCorrection(material)
    t, s = corr.tables[0], float(corr.sigma_t_prime[0])
    Rc, eta = float(corr.radius_mm[0]), float(material.eta)
    logr = _LOG_R[:t.n_r] - math.log(s)
    f = t.f * s * s

    def lookup(r, ct):
        u = np.clip((np.log(r) - logr[0]) / (logr[1] - logr[0]), 0.0, t.n_r - 1 - 1e-9)
        j = u.astype(int)
        w = u - j
        cc = np.clip(ct, t.cos_t[0], t.cos_t[-1])
        k = np.minimum(((cc - t.cos_t[0]) / (t.cos_t[1] - t.cos_t[0])).astype(int), t.cos_t.size - 2)
        fr = (cc - t.cos_t[k]) / (t.cos_t[1] - t.cos_t[0])
        v = (1 - fr) * ((1 - w) * f[k, j] + w * f[k, j + 1]) + fr * ((1 - w) * f[k + 1, j] + w * f[k + 1, j + 1])
        return np.where(r <= Rc, v, 0.0)

    def entry(nq):
        ci = nq[..., 2]
        E = np.where(ci > 0, ci * fresnel_transmittance_entry(np.clip(ci, 1e-12, 1.0), eta), 0.0)
        w = refract_in(np.broadcast_to([0.0, 0.0, -1.0], nq.shape).reshape(-1, 3), nq.reshape(-1, 3), eta)
        return E, np.clip(-np.sum(w.reshape(nq.shape) * nq, axis=-1), 0.0, 1.0)

    a_max = min(2.0 * math.asin(min(1.0, Rc / (2.0 * R))), math.pi / 2)
    x, wx = np.polynomial.legendre.leggauss(n_alpha)
    la0, la1 = math.log(1e-9), math.log(a_max)
    al = np.exp(0.5 * (la1 - la0) * (x + 1) + la0)
    wa = 0.5 * (la1 - la0) * wx * al
    ph = (np.arange(n_phi) + 0.5) * 2 * math.pi / n_phi
    out = np.zeros(len(theta_p))
    for k, th in enumerate(theta_p):
        p = np.array([math.sin(th), 0.0, math.cos(th)])
        e1 = np.array([math.cos(th), 0.0, -math.sin(th)])
        dirs = np.cos(ph)[None, :, None] * e1 + np.sin(ph)[None, :, None] * np.array([0.0, 1.0, 0.0])
        nq = np.cos(al)[:, None, None] * p + np.sin(al)[:, None, None] * dirs
        E, ct = entry(nq)
        r = np.broadcast_to((2 * R * np.sin(al / 2))[:, None], E.shape)
        out[k] = np.sum(lookup(r, ct) * E * (R * R * np.sin(al) * wa)[:, None]) * 2 * math.pi / n_phi
        Ep, ctp = entry(p[None, :])
        out[k] += Ep[0] * np.interp(np.clip(ctp[0], t.cos_t[0], t.cos_t[-1]), t.cos_t, t.rest)
    return out


@pytest.fixture(scope="module")
def ball_reference():
    """theta -> exact exitance of the sun-lit ball (volume series + near-field continuum), on a 1/2 degree grid."""
    theta = np.linspace(0.0, math.pi, 361)
    D, sa, A = diffusion_constants(sun_ball.MATERIAL, 0)
    ref = sun_ball.sun_ball_exitance(theta, D, sa, A) + near_field_ball(theta, sun_ball.MATERIAL, sun_ball.R)

    def at(points):
        th = np.arccos(np.clip(points[:, 2] / np.linalg.norm(points, axis=1), -1.0, 1.0))
        return np.interp(th, theta, ref)
    return at


def _error(M, ref):
    keep = ref > 1e-3 * ref.max()
    return float(np.mean(np.abs(M[keep] / ref[keep] - 1.0)))


def test_near_field_continuum_is_converged():
    th = np.radians([0.0, 60.0, 90.0, 95.0])
    a = near_field_ball(th, sun_ball.MATERIAL, sun_ball.R)
    b = near_field_ball(th, sun_ball.MATERIAL, sun_ball.R, n_alpha=480, n_phi=320)
    np.testing.assert_allclose(a, b, atol=1e-3 * np.abs(b).max())


def _ball_texture(ball_reference, refine):
    V, F = icosphere(sun_ball.R, 3)                                 # 642 vertices, edges about 3.3 mm
    mesh = Mesh.from_arrays(V, F)
    uv = spherical_uv(V, F)
    tex = bake_texture(mesh, sun_ball.MATERIAL, SUN, uv=uv, size=1024, padding=2, refine=refine)
    texel, face, bary, _ = rasterise_uv(uv, 1024, 1024)
    points = np.einsum("ij,ijk->ik", bary, V[F[face]])
    return tex, _error(tex.image.reshape(-1, 3)[texel, 0], ball_reference(points))


def test_coarse_ball_texture_matches_the_exact_solution_between_vertices(ball_reference):
    """Issue 31's target: a 642-vertex ball's 1024^2 texture within 2x the 10k-vertex bake's vertex error. The
    10k bake's error is measured by the slow test below (1.03 % mean): here its bound 2.06 %."""
    tex, err = _ball_texture(ball_reference, None)
    assert tex.refine == texture_refinement(Mesh.from_arrays(*icosphere(sun_ball.R, 3)), sun_ball.MATERIAL) == 3
    assert err < 0.0206, err                                        # measured 1.42 %


@pytest.mark.slow
def test_coarse_ball_texture_is_within_twice_the_fine_vertex_bake(ball_reference):
    fine = Mesh.from_arrays(*icosphere(sun_ball.R, 5))             # 10,242 vertices
    r = bake(fine, sun_ball.MATERIAL, SUN)
    err_fine = _error(r.radiance[:, 0], ball_reference(fine.vertices))
    _, err_tex = _ball_texture(ball_reference, None)
    _, err_plain = _ball_texture(ball_reference, 1)
    assert err_tex <= 2.0 * err_fine, (err_tex, err_fine)           # measured 1.42 % vs 1.03 %
    assert err_plain > 3.0 * err_fine, (err_plain, err_fine)        # without refinement 5.1 %: it is what works


def test_without_refinement_texels_are_the_vertex_bake_where_lights_enter_at_vertices():
    mesh = Mesh.from_arrays(*icosphere(5.0, 3))
    uv = spherical_uv(mesh.vertices, mesh.faces)
    tex = bake_texture(mesh, SKIN, SUN, uv=uv, size=128, padding=0, refine=1)
    plain = bake(mesh, SKIN, SUN)
    np.testing.assert_allclose(tex.vertex_radiance, plain.radiance, rtol=1e-9, atol=1e-15)
    texel, face, bary, _ = rasterise_uv(uv, 128, 128)
    interp = np.maximum(np.einsum("ij,ijk->ik", bary, plain.radiance[mesh.faces[face]]), 0.0)
    np.testing.assert_allclose(tex.image.reshape(-1, 3)[texel], interp, rtol=1e-9, atol=1e-15)
    assert np.all(tex.image.reshape(-1, 3)[~tex.covered.reshape(-1)] == 0.0)     # no padding asked for


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
    assert texture_refinement(mesh, SKIN) == 8
    monkeypatch.setattr(texture, "MAX_REFINED_VERTICES", 4 * mesh.n_vertices)
    with pytest.warns(UserWarning, match=r"split 2x2, not the 8x8"):
        tex = bake_texture(mesh, SKIN, SUN, uv=spherical_uv(mesh.vertices, mesh.faces), size=32, padding=0,
                           model="dipole")
    assert tex.refine == 2 and tex.stats["texture_refine_wanted"] == 8

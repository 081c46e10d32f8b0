"""Texture bakes (issue 31): texels against the vertex bake, a beam's peak per texel, and the sun-lit ball's
texture against its exact solution.

Reference for the ball, independent of the bake's discretisation and of its tables (issue 42):

* the exact Robin ball series of the volume's line sources under a continuous sun
  (tests/volume/test_volume_sun_ball.py, checked there against mpmath), with d'Eon's D and A of eq. (74) computed
  here (Fresnel moments C1, C2 by adaptive quadrature of Born & Wolf's Fresnel reflectance);
* plus the continuum limit of the near-field correction, eq. (98), evaluated from its definition: the public
  kernels R_near (eq. (76)), W (eq. (86)) and M_Robin (eq. (96)) at the Gauss-Laguerre points of eq. (97)
  (numpy's laggauss), not the bake's table of Delta R (1025 log distances x 9 cosines, linear interpolation);
  integrated over the lit surface of the exact sphere facing the receiver's way by Gauss-Legendre in log angle x
  midpoint rule in azimuth, within the radius where the magnitude of Delta R beyond holds 1 % of R_near's total,
  with that remainder's signed energy at the entry point (docs/physics.md §15.1: the model as documented). Both
  computed here from the definition (trapezoid in ln r on 1201 nodes): the radius agrees with the bake's to 0.4 %,
  the correction to 0.3 % of itself. Without the radius (eq. (98) summed everywhere) the reference would be 2-6 %
  higher past the terminator: what the radius costs the model there, not what this test is about;
* the texels' points from a rasteriser written here in numpy (texel centres ((c + 1/2)/N, 1 - (r + 1/2)/N) in
  each UV triangle, the mesh's barycentric interpolation), not meshshade.geometry.uv.rasterise_uv.

What is tested is the mesh, the refinement and the evaluation at texels; the model's own accuracy is tested in
tests/volume and tests/kernels.
"""
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere, spherical_uv
from meshshade.kernels.near_field import incidence_gain, near_field_profile
from meshshade.kernels.robin_halfspace import robin_point_source_exitance
from meshshade.light import BeamLight, DirectionalLight
from meshshade.materials import Material
from meshshade.output.render import PixelGather
from meshshade.output.texture import bake_texture, texture_refinement
from meshshade.transport.baking import bake

_spec = importlib.util.spec_from_file_location(
    "sun_ball", Path(__file__).parents[1] / "volume" / "test_volume_sun_ball.py")
sun_ball = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(sun_ball)

SKIN = Material.preset("skin1")
SUN = [DirectionalLight((0.0, 0.0, -1.0), 1.0)]
#: docs/physics.md §15.1: Delta R is summed within the radius where what lies beyond holds 1 % of R_near's total
NEAR_TAIL = 1e-2


def fresnel(cos_i, n1, n2):
    """Unpolarised Fresnel reflectance from index n1 into n2 (Born & Wolf 1.5.2); 1 past the critical angle."""
    cos_i = np.asarray(cos_i, dtype=np.float64)
    sin2_t = (n1 / n2) ** 2 * (1.0 - cos_i * cos_i)
    cos_t = np.sqrt(np.clip(1.0 - sin2_t, 0.0, None))
    rs = (n1 * cos_i - n2 * cos_t) / (n1 * cos_i + n2 * cos_t)
    rp = (n1 * cos_t - n2 * cos_i) / (n1 * cos_t + n2 * cos_i)
    return np.where(sin2_t >= 1.0, 1.0, 0.5 * (rs * rs + rp * rp))


def deon_constants(albedo, eta):
    """(D, mu, A) in optical units, d'Eon's theory (docs/physics.md eq. (74)): D = (2 - alpha')/3, mu =
    sqrt((1 - alpha')/D), A = (1 + 3 C2)/(1 - 2 C1), C_n = int_0^1 F(mu) mu^n dmu seen from inside."""
    mu_c = math.sqrt(1.0 - 1.0 / eta ** 2)                       # F = 1 below the critical cosine
    c1, c2 = (mu_c ** (n + 1) / (n + 1) + integrate.quad(lambda m: float(fresnel(m, eta, 1.0)) * m ** n, mu_c, 1.0,
                                                          epsabs=1e-14, epsrel=1e-12)[0] for n in (1, 2))
    D = (2.0 - albedo) / 3.0
    return D, math.sqrt((1.0 - albedo) / D), (1.0 + 3.0 * c2) / (1.0 - 2.0 * c1)


def delta_r(r_opt, cos_t, material):
    """Eq. (98) of channel 0, optical units, on the grid r_opt (n,) x cos_t (m,): W(cos_t) R_near(r) - sum_j
    alpha' w_j M_Robin(r; x_j cos_t), (x_j, w_j) the 4-point Gauss-Laguerre rule of eq. (97)."""
    a, eta, g = float(material.albedo_prime[0]), float(material.eta), float(material.g)
    D, mu, A = deon_constants(a, eta)
    x, w = np.polynomial.laguerre.laggauss(4)
    gain = np.array([incidence_gain(albedo_prime=a, eta=eta, g=g, cos_t=float(c)) for c in cos_t])
    near = near_field_profile(r_opt, albedo_prime=a, eta=eta, g=g)
    robin = sum(a * wj * robin_point_source_exitance(r_opt[:, None], xj * cos_t[None, :], D=D, mu=mu, A=A)
                for xj, wj in zip(x, w))
    return gain[None, :] * near[:, None] - robin


def near_field_radius_and_rest(material, n_r=1201, n_c=17):
    """(radius mm, cos_t grid, rest(cos_t)): the radius where the magnitude of Delta R beyond (its largest over
    cos_t) holds NEAR_TAIL of R_near's total, and the signed energy of Delta R beyond it per cos_t (trapezoid in
    ln r on [1e-6, 300] transport lengths, linear in ln r between the nodes; R_near's total by the same rule)."""
    a, eta, g = float(material.albedo_prime[0]), float(material.eta), float(material.g)
    lr = np.linspace(math.log(1e-6), math.log(300.0), n_r)
    r = np.exp(lr)
    cos_t = np.linspace(math.sqrt(1.0 - 1.0 / eta ** 2), 1.0, n_c)
    f = 2.0 * math.pi * r[:, None] ** 2 * delta_r(r, cos_t, material)        # d/d(ln r) of the ring integral

    def beyond(y):                                                  # int_{r_i}^inf y dln r at every node
        seg = 0.5 * (y[1:] + y[:-1]) * np.diff(lr).reshape((-1,) + (1,) * (y.ndim - 1))
        return np.concatenate([np.cumsum(seg[::-1], axis=0)[::-1], np.zeros((1,) + y.shape[1:])])

    near = 2.0 * math.pi * r ** 2 * near_field_profile(r, albedo_prime=a, eta=eta, g=g)
    tail = beyond(np.abs(f).max(axis=1))                            # non-increasing in r
    log_radius = float(np.interp(NEAR_TAIL * beyond(near)[0], tail[::-1], lr[::-1]))
    rest = np.array([np.interp(log_radius, lr, col) for col in beyond(f).T])
    return math.exp(log_radius) / float(material.sigma_t_prime[0]), cos_t, rest


def near_field_ball(theta_p, material, R, n_alpha=240, n_phi=80, n_c=64):
    """Continuum limit of the near-field correction (channel 0) on the exact ball of radius R under a unit sun
    from +z, at polar angles ``theta_p`` (module docstring): per receiver p, the lit points q within the radius
    (normals facing the same way there), each entering cos_i (1 - F) per unit area with its light at cos_t; plus
    the receiver's own entry times the rest beyond the radius."""
    s, eta = float(material.sigma_t_prime[0]), float(material.eta)
    radius, rest_c, rest = near_field_radius_and_rest(material)
    a_max = min(2.0 * math.asin(min(1.0, radius / (2.0 * R))), math.pi / 2)
    x, wx = np.polynomial.legendre.leggauss(n_alpha)
    la0, la1 = math.log(1e-9), math.log(a_max)
    al = np.exp(0.5 * (la1 - la0) * (x + 1) + la0)                   # angle between p and q seen from the centre
    wa = 0.5 * (la1 - la0) * wx * al
    cos_t = np.linspace(math.sqrt(1.0 - 1.0 / eta ** 2), 1.0, n_c)
    table = delta_r(2.0 * R * np.sin(al / 2) * s, cos_t, material) * s * s     # (n_alpha, n_c) per mm^2
    ph = (np.arange(n_phi) + 0.5) * math.pi / n_phi                 # half the azimuths: symmetric about y = 0
    rows = np.arange(n_alpha)[:, None]
    out = np.zeros(len(theta_p))

    def entry(cos_i):
        ci = np.clip(cos_i, 0.0, 1.0)
        return np.where(cos_i > 0, ci * (1.0 - fresnel(ci, 1.0, eta)), 0.0), np.sqrt(1.0 - (1.0 - ci * ci) / eta ** 2)

    for k, th in enumerate(theta_p):
        E, ct = entry(np.cos(al)[:, None] * math.cos(th) - np.sin(al)[:, None] * np.cos(ph)[None, :] * math.sin(th))
        u = (ct - cos_t[0]) / (cos_t[1] - cos_t[0])
        j = np.clip(u.astype(int), 0, n_c - 2)
        v = (1.0 - (u - j)) * table[rows, j] + (u - j) * table[rows, j + 1]
        out[k] = 2.0 * np.sum(v * E * (R * R * np.sin(al) * wa)[:, None]) * math.pi / n_phi
        Ep, ctp = entry(np.array(math.cos(th)))
        out[k] += float(Ep) * float(np.interp(ctp, rest_c, rest))
    return out


@pytest.fixture(scope="module")
def ball_reference():
    """theta -> exact exitance of the sun-lit ball (volume series + near-field continuum), on a 1/2 degree grid."""
    theta = np.linspace(0.0, math.pi, 361)
    m = sun_ball.MATERIAL
    D, _, A = deon_constants(float(m.albedo_prime[0]), float(m.eta))
    s = float(m.sigma_t_prime[0])
    ref = (sun_ball.sun_ball_exitance(theta, D / s, float(m.sigma_a[0]), A)
           + near_field_ball(theta, m, sun_ball.R))

    def at(points):
        th = np.arccos(np.clip(points[:, 2] / np.linalg.norm(points, axis=1), -1.0, 1.0))
        return np.interp(th, theta, ref)
    return at


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
    texel, face, bary = texel_points(uv, 128)
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

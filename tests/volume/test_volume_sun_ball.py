"""The volume solve under a sun, against the ball's exact solution (issue 29's shadow-side target).

A ball of radius 20 mm (icosphere level 5, 10k vertices; sigma_s' = 1, sigma_a = 0.01 /mm, eta 1.3) lit by a sun
along -z. The volume gets the line sources of eq. (97) of every vertex entry sample, placed along the exact
refracted direction (exact sphere normals); the reference is the Robin ball series of eq. (94) for the same
sources of a *continuous* sun (every entry point of the lit hemisphere with power E cos F_t per unit area), summed
over the azimuth by the addition theorem (only m = 0 survives): with i_l(z) = z^l / (2l+1)!! 0F1(; l + 3/2; z^2/4)
no Bessel function is formed, and 2500 terms converge for sources 0.3 mm below the surface. The series
implementation is checked against the mpmath one of test_volume_fem (30 digits).

Measured (default grading): mean |M/ref - 1| 0.95 %, max 7.5 % over vertices above 1e-3 of the peak; past the
terminator (95-180 deg) within +0.5..+0.8 % on average. With the interior no coarser than 0.5/sigma_tr (the
default) the shadow side's bias fell from +1.8 % to +0.7 %. Issue 29's target (mean <= 0.5 %, max <= 2 %) is met in
the mean at level 6 with 0.3 of the shortest length between layers (0.39 %, max 2.7 %; 390k nodes, 142 s to
build), not at the default resolution.
"""
import importlib.util
import math
from pathlib import Path

import numpy as np
from scipy.special import eval_legendre, hyp0f1

from meshshade.geometry.mesh import Mesh
from meshshade.geometry.procedural import icosphere
from meshshade.kernels.fresnel import fresnel_transmittance_entry, refract_in
from meshshade.light import DirectionalLight
from meshshade.light.samples import entry_samples
from meshshade.materials import Material
from meshshade.raycast import make_scene
from meshshade.volume.fem import locate_points, point_source_vector
from meshshade.volume.sources import line_source_rule, line_sources
from meshshade.volume.transport import VolumeTransport, diffusion_constants

_spec = importlib.util.spec_from_file_location("volume_fem_tests", Path(__file__).with_name("test_volume_fem.py"))
fem_tests = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fem_tests)

R = 20.0
MATERIAL = Material([1.0, 1.0, 1.0], [0.01, 0.01, 0.01], eta=1.3)


def _ratio(l, r, kappa, beta, radius=R):
    """(L, S): i_l(kappa r) / (i_l(x) + beta i_l'(x)), x = kappa radius, by the 0F1 form (no overflow or
    underflow)."""
    l = np.asarray(l, dtype=np.float64)[:, None]
    r = np.asarray(r, dtype=np.float64)[None, :]
    x = kappa * radius
    num = np.exp(l * np.log(r / radius)) * hyp0f1(l + 1.5, (kappa * r) ** 2 / 4.0)
    den = hyp0f1(l + 1.5, x * x / 4.0) * (1.0 + beta * l / x) + beta * x / (2.0 * l + 3.0) * hyp0f1(l + 2.5,
                                                                                                     x * x / 4.0)
    return num / den


def ball_point_source(gamma, r_source, D, sigma_a, A, radius, terms=220):
    kappa = math.sqrt(sigma_a / D)
    x, beta = kappa * radius, 2.0 * A * D * kappa
    g = _ratio(np.arange(terms), [r_source], kappa, beta, radius)[:, 0]
    P = np.array([eval_legendre(k, np.cos(gamma)) for k in range(terms)])
    return kappa * beta / (4 * math.pi * D * x * x) * ((2 * np.arange(terms) + 1) * g) @ P / (2.0 * A)


def sun_ball_exitance(theta_o, D, sigma_a, A, terms=2500, n_theta=600):
    """Exitance at polar angles ``theta_o`` of the ball under a unit sun from +z (module docstring)."""
    kappa = math.sqrt(sigma_a / D)
    x, beta = kappa * R, 2.0 * A * D * kappa
    u, wq = np.polynomial.legendre.leggauss(n_theta)
    th, wth = 0.25 * math.pi * (u + 1.0), 0.25 * math.pi * wq
    n = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], axis=1)
    ci = np.cos(th)
    power = 2.0 * math.pi * R * R * np.sin(th) * wth * ci * fresnel_transmittance_entry(ci, MATERIAL.eta)
    w = refract_in(np.tile([0.0, 0.0, -1.0], (th.size, 1)), n, MATERIAL.eta)
    t, W = line_source_rule(float(MATERIAL.albedo_prime[0]))
    pts = (R * n[:, None, :] + (t / float(MATERIAL.sigma_t_prime[0]))[None, :, None] * w[:, None, :]).reshape(-1, 3)
    pw = (power[:, None] * W[None, :]).ravel()
    r = np.linalg.norm(pts, axis=1)
    ct, co = pts[:, 2] / r, np.cos(theta_o)
    out = np.zeros(len(theta_o))
    ps_prev, ps, po_prev, po = np.ones_like(ct), ct, np.ones_like(co), co
    for start in range(0, terms, 100):
        ls = np.arange(start, min(terms, start + 100))
        G = _ratio(ls, r, kappa, beta)
        for k, l in enumerate(ls):
            if l == 0:
                a, b = ps_prev, po_prev
            elif l == 1:
                a, b = ps, po
            else:
                ps_prev, ps = ps, ((2 * l - 1) * ct * ps - (l - 1) * ps_prev) / l
                po_prev, po = po, ((2 * l - 1) * co * po - (l - 1) * po_prev) / l
                a, b = ps, po
            out += (2 * l + 1) * np.sum(pw * G[k] * a) * b
    return kappa * beta / (4 * math.pi * D * x * x) * out / (2.0 * A)


def test_series_matches_the_mpmath_ball():
    gamma = np.linspace(0.2, 1.6, 5)
    ours = ball_point_source(gamma, 4.0, fem_tests.D, fem_tests.SIGMA_A, fem_tests.A, 5.0)
    np.testing.assert_allclose(ours, fem_tests.robin_ball_exitance(gamma, 5.0, 4.0), rtol=1e-10)


def test_sun_lit_ball_keeps_its_shadow_side():
    mesh = Mesh.from_arrays(*icosphere(R, 5))
    vt = VolumeTransport.build(mesh, MATERIAL)
    es = entry_samples(mesh.vertices, mesh.faces, mesh.vertex_normals, mesh.vertex_areas,
                       [DirectionalLight((0.0, 0.0, -1.0), 1.0)], make_scene(mesh.vertices, mesh.faces), MATERIAL.eta)
    exact_n = es.positions / np.linalg.norm(es.positions, axis=1, keepdims=True)
    w = refract_in(es.directions, exact_n, MATERIAL.eta)
    pts, pw = line_sources(es.positions, w, es.power, sigma_t_prime=float(MATERIAL.sigma_t_prime[0]),
                           albedo_prime=float(MATERIAL.albedo_prime[0]))
    tm = vt.tetra
    tet, bary = locate_points(tm.nodes, tm.tets, pts)
    b = point_source_vector(tm.nodes.shape[0], tm.tets, tet, bary, pw)
    D, sa, A = diffusion_constants(MATERIAL, 0)
    M = vt.operator.solve(np.stack([b, b, b], axis=1))[:tm.n_surface, 0] / (2.0 * A)
    V = mesh.vertices[vt.surface_vertices]
    theta = np.arccos(np.clip(V[:, 2] / np.linalg.norm(V, axis=1), -1.0, 1.0))
    ref = sun_ball_exitance(theta, D, sa, A)
    keep = ref > 1e-3 * ref.max()
    e = M[keep] / ref[keep] - 1.0
    assert keep.sum() == mesh.n_vertices            # the whole ball is above 1e-3 of the peak
    shadow = np.degrees(theta[keep]) > 95.0
    assert abs(np.mean(e[shadow])) < 0.010, np.mean(e[shadow])     # +0.7 %; +1.3 % with a coarse interior
    assert np.mean(np.abs(e)) < 0.012 and np.max(np.abs(e)) < 0.09, (np.mean(np.abs(e)), np.max(np.abs(e)))
